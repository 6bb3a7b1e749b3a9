//! DLPack: arrays exported as tensors and tensors imported as arrays without a copy (same
//! address, writes seen both ways), on both ABIs, with strides and component axes, the
//! producer's memory released exactly when the last handle drops, and every mismatch refused
//! with an error naming it. Values are small integers in f32: every comparison is exact.

use crate::host;
// `warp_runtime` directly: the tests turn its `dlpack` feature on, not the facade's.
use warp_lang as wp;
use warp_runtime::dlpack::ffi::{DLDataType, DLDevice, DLDeviceType};
use warp_runtime::dlpack::{legacy, metadata::Dynamic, versioned, DlpackFlags};
use wp::prelude::*;

use std::sync::Arc;

backend_tests!(
    export_import_is_zero_copy,
    producer_released_with_last_handle,
    strided_and_component_layouts,
    dlpack_errors,
    overlapping_and_overflowing_tensors,
);

#[wp::kernel]
fn k_bump(v: Array<Vec3>) {
    let i = tid();
    v[i] = v[i] + vec3(1.0, 2.0, 3.0);
}

#[wp::kernel]
fn k_copy_2d(src: Array<f32, 2>, dst: Array<f32, 2>) {
    let (i, j) = tid();
    dst[(i, j)] = src[(i, j)];
}

fn dl_device(dev: &wp::Device) -> DLDevice {
    match dev.kind() {
        wp::DeviceKind::Cpu => DLDevice::CPU,
        wp::DeviceKind::Cuda { ordinal } => DLDevice::cuda(ordinal as i32),
    }
}

/// Export then import, on both ABIs: the tensor describes the array's own memory (address,
/// `[n, 3]` of float32, strides `[3, 1]`, the device), and the imported array is that memory:
/// a kernel's writes through it are seen by the original.
fn export_import_is_zero_copy(dev: &wp::Device) {
    let xs: Vec<Vec3> = (0..5).map(|i| Vec3::splat(i as f32)).collect();
    let a = wp::Array::from_slice(&xs, dev).unwrap();

    let t: versioned::Dlpack = a.to_dlpack().unwrap();
    {
        let r = t.validate().unwrap();
        assert_eq!(r.shape(), &[5, 3]);
        assert_eq!(r.strides(), Some(&[3i64, 1][..]));
        assert!(r.dtype().matches(DLDataType::F32));
        assert_eq!(r.device(), dl_device(dev));
        assert_eq!(r.data_ptr() as u64 + r.byte_offset(), a.device_ptr());
    }
    // SAFETY: the tensor is this crate's export (valid until its deleter runs).
    let b = unsafe { wp::Array::<Vec3>::from_dlpack(t) }.unwrap();
    assert_eq!(b.device_ptr(), a.device_ptr(), "import is the same memory");
    wp::launch(k_bump, 5, (&b,), dev).unwrap();

    let t: legacy::Dlpack = a.to_dlpack().unwrap();
    // SAFETY: as above.
    let c = unsafe { wp::Array::<Vec3>::from_dlpack(t) }.unwrap();
    assert_eq!(c.device_ptr(), a.device_ptr());
    wp::launch(k_bump, 5, (&c,), dev).unwrap();

    let expect: Vec<Vec3> = xs.iter().map(|x| *x + Vec3::new(2.0, 4.0, 6.0)).collect();
    assert_eq!(host(&a), expect, "both imports wrote the original's memory");
    drop(a);
    // The imports keep the memory alive on their own.
    assert_eq!(host(&b), expect);
}

/// A tensor made by another producer (a `Vec` on the CPU, another array's device memory on a
/// GPU) is released by its deleter exactly when the last handle to the imported memory drops.
fn producer_released_with_last_handle(dev: &wp::Device) {
    let values: Vec<f32> = (0..6).map(|i| i as f32).collect();
    let token = Arc::new(());
    let (ptr, owner): (u64, Box<dyn Send>) = if dev.is_cpu() {
        let v = values.clone();
        (v.as_ptr() as u64, Box::new((v, Arc::clone(&token))))
    } else {
        let g = wp::Array::<f32>::from_slice(&values, dev).unwrap();
        (g.device_ptr(), Box::new((g, Arc::clone(&token))))
    };
    let mut init = Dynamic::new(vec![2i64, 3], vec![3i64, 1])
        .initialize_as::<warp_runtime::dlpack::ffi::DLManagedTensorVersioned>(Box::new(owner))
        .unwrap();
    init.set_data(ptr as usize as *mut std::ffi::c_void)
        .set_dtype(DLDataType::F32)
        .set_device(dl_device(dev));
    // SAFETY: 6 f32 at `ptr`, owned by the context until the deleter runs.
    let t: versioned::Dlpack = unsafe { init.finish() };
    assert_eq!(Arc::strong_count(&token), 2);

    // SAFETY: a valid tensor (above); only this test touches its memory.
    let a = unsafe { wp::Array::<f32, 2>::from_dlpack(t) }.unwrap();
    assert_eq!(a.shape(), [2, 3]);
    assert_eq!(a.device_ptr(), ptr);
    let row = a.row(1).unwrap();
    drop(a);
    assert_eq!(
        Arc::strong_count(&token),
        2,
        "a view still holds the tensor"
    );
    assert_eq!(row.to_vec().unwrap(), [3.0, 4.0, 5.0]);
    drop(row);
    assert_eq!(
        Arc::strong_count(&token),
        1,
        "the deleter ran with the last handle"
    );
}

/// Strides travel in scalars both ways: a transposed view exports strides `[1, 4]` and
/// imports back as the transpose; a `Mat3` array is `[n, 3, 3]` indexed `[k, row, column]`
/// (strides `[9, 1, 3]`: glam stores by column); an `f32` tensor of shape `[4, 3]` imports as
/// four `Vec3`s.
fn strided_and_component_layouts(dev: &wp::Device) {
    let values: Vec<f32> = (0..12).map(|k| (10 * (k / 4) + k % 4) as f32).collect();
    let a = wp::Array::<f32, 2>::from_slice_shape(&values, (3, 4), dev).unwrap();
    let t: versioned::Dlpack = a.transpose().to_dlpack().unwrap();
    assert_eq!(t.validate().unwrap().shape(), &[4, 3]);
    assert_eq!(t.validate().unwrap().strides(), Some(&[1i64, 4][..]));
    // SAFETY: this crate's export.
    let at = unsafe { wp::Array::<f32, 2>::from_dlpack(t) }.unwrap();
    assert_eq!(at.strides(), [1, 4]);
    let out = wp::Array::<f32, 2>::zeros((4, 3), dev).unwrap();
    wp::launch(k_copy_2d, (4, 3), (&at, &out), dev).unwrap();
    let expect: Vec<f32> = (0..12).map(|k| (10 * (k % 3) + k / 3) as f32).collect();
    assert_eq!(host(&out), expect);

    let m = Mat3::from_cols(
        Vec3::new(1.0, 2.0, 3.0),
        Vec3::new(4.0, 5.0, 6.0),
        Vec3::new(7.0, 8.0, 9.0),
    );
    let ms = wp::Array::from_slice(&[m, m * 2.0], dev).unwrap();
    let t: versioned::Dlpack = ms.to_dlpack().unwrap();
    assert_eq!(t.validate().unwrap().shape(), &[2, 3, 3]);
    assert_eq!(t.validate().unwrap().strides(), Some(&[9i64, 1, 3][..]));
    // SAFETY: this crate's export.
    let back = unsafe { wp::Array::<Mat3>::from_dlpack(t) }.unwrap();
    assert_eq!(host(&back), [m, m * 2.0]);

    let flat = wp::Array::<f32, 2>::from_slice_shape(&values, (4, 3), dev).unwrap();
    let t: versioned::Dlpack = flat.to_dlpack().unwrap();
    // SAFETY: this crate's export.
    let v = unsafe { wp::Array::<Vec3>::from_dlpack(t) }.unwrap();
    assert_eq!(v.len(), 4);
    assert_eq!(host(&v)[1], Vec3::new(3.0, 10.0, 11.0));
}

/// Each mismatch is an `InvalidArgument` naming it, and the tensor is released.
fn dlpack_errors(dev: &wp::Device) {
    fn err<T: wp::NdComponents, const N: usize>(t: versioned::Dlpack) -> String
    where
        T::Scalar: warp_runtime::DlpackScalar,
    {
        // SAFETY: this crate's export, or a descriptor the callee rejects before any access.
        match unsafe { wp::Array::<T, N>::from_dlpack(t) } {
            Ok(_) => panic!("imported"),
            Err(e @ wp::Error::InvalidArgument { .. }) => e.to_string(),
            Err(e) => panic!("unexpected error {e:?}"),
        }
    }
    let a = wp::Array::<f32, 2>::zeros((4, 2), dev).unwrap();
    let e = err::<i32, 2>(a.to_dlpack().unwrap());
    assert!(e.contains("dtype is float32") && e.contains("int32"), "{e}");
    let e = err::<f32, 1>(a.to_dlpack().unwrap());
    assert!(e.contains("2 axes"), "{e}");
    let e = err::<Vec3, 1>(a.to_dlpack().unwrap());
    assert!(e.contains("trailing axes have shape [2]"), "{e}");
    // Column-major [4, 3]: the components of a row are 4 scalars apart, not packed.
    let b = wp::Array::<f32, 2>::zeros((3, 4), dev).unwrap();
    let e = err::<Vec3, 1>(b.transpose().to_dlpack().unwrap());
    assert!(e.contains("strides [4]"), "{e}");

    let mut t: versioned::Dlpack = a.to_dlpack().unwrap();
    // SAFETY: marking an export read-only only narrows what consumers may do.
    unsafe { *t.flags_mut() |= DlpackFlags::READ_ONLY };
    let e = err::<f32, 2>(t);
    assert!(e.contains("read-only"), "{e}");

    let mut init = Dynamic::new(vec![2i64], vec![1i64])
        .initialize_as::<warp_runtime::dlpack::ffi::DLManagedTensorVersioned>(Box::new([0f32; 2]))
        .unwrap();
    init.set_data(std::ptr::dangling_mut())
        .set_dtype(DLDataType::F32)
        .set_device(DLDevice {
            device_type: DLDeviceType::VULKAN,
            device_id: 0,
        });
    // SAFETY: rejected by its device before its data is touched.
    let e = err::<f32, 1>(unsafe { init.finish() });
    assert!(e.contains("DLPack device type 7"), "{e}");
    let _ = dev;
}

/// A tensor built by hand over `n` f32 of memory on `dev` (a `Vec` on the CPU, an array's
/// device memory on a GPU), kept alive by the tensor's context, with the given shape,
/// strides (in scalars) and byte offset.
fn hand_built(
    dev: &wp::Device,
    values: &[f32],
    shape: Vec<i64>,
    strides: Vec<i64>,
    byte_offset: u64,
) -> versioned::Dlpack {
    let (ptr, owner): (u64, Box<dyn Send>) = if dev.is_cpu() {
        let v = values.to_vec();
        (v.as_ptr() as u64, Box::new(v))
    } else {
        let g = wp::Array::<f32>::from_slice(values, dev).unwrap();
        (g.device_ptr(), Box::new(g))
    };
    let mut init = Dynamic::new(shape, strides)
        .initialize_as::<warp_runtime::dlpack::ffi::DLManagedTensorVersioned>(Box::new(owner))
        .unwrap();
    init.set_data(ptr as usize as *mut std::ffi::c_void)
        .set_dtype(DLDataType::F32)
        .set_byte_offset(byte_offset)
        .set_device(dl_device(dev));
    // SAFETY: the memory is owned by the context until the deleter runs; the layouts the
    // tests import address it, the others are refused before it is touched.
    unsafe { init.finish() }
}

/// Arrays are writable, so a tensor whose elements alias (a zero stride, as PyTorch's
/// `expand()` makes) is refused, as are strides and offsets whose byte arithmetic overflows
/// (an error, not a wrap to some other address); a transposed, strided, reversed tensor that
/// does not overlap is imported.
fn overlapping_and_overflowing_tensors(dev: &wp::Device) {
    fn err<T: wp::NdComponents, const N: usize>(t: versioned::Dlpack) -> String
    where
        T::Scalar: warp_runtime::DlpackScalar,
    {
        // SAFETY: a hand-built descriptor over live memory, or one the callee rejects before
        // any access.
        match unsafe { wp::Array::<T, N>::from_dlpack(t) } {
            Ok(a) => panic!("imported {:?} with strides {:?}", a.shape(), a.strides()),
            Err(e @ wp::Error::InvalidArgument { .. }) => e.to_string(),
            Err(e) => panic!("unexpected error {e:?}"),
        }
    }
    let values: Vec<f32> = (0..12).map(|k| k as f32).collect();
    // `torch.arange(4.).expand(3, 4)`: shape [3, 4], strides [0, 1].
    let e = err::<f32, 2>(hand_built(dev, &values, vec![3, 4], vec![0, 1], 0));
    assert!(
        e.contains("from_dlpack")
            && e.contains("shape [3, 4]")
            && e.contains("strides [0, 1]")
            && e.contains("more than one index"),
        "{e}"
    );
    // One Vec3 expanded to 5: shape [5, 3], strides [0, 1].
    let e = err::<Vec3, 1>(hand_built(dev, &values, vec![5, 3], vec![0, 1], 0));
    assert!(e.contains("strides [0, 1]"), "{e}");
    // Aliasing without a zero stride: [i, j] at 2i + j ([0, 2] is [1, 0]).
    let e = err::<f32, 2>(hand_built(dev, &values, vec![3, 3], vec![2, 1], 0));
    assert!(e.contains("more than one index"), "{e}");

    // A stride of 2^62 f32 is 2^64 bytes: it wrapped to a zero byte stride before.
    let e = err::<f32, 1>(hand_built(dev, &values, vec![2], vec![1 << 62], 0));
    assert!(e.contains("overflows a byte offset"), "{e}");
    let e = err::<f32, 2>(hand_built(dev, &values, vec![2, 2], vec![i64::MIN, 1], 0));
    assert!(e.contains("overflows a byte offset"), "{e}");
    // A byte offset that wraps the data pointer around the address space.
    let e = err::<f32, 1>(hand_built(dev, &values, vec![2], vec![1], u64::MAX - 3));
    assert!(e.contains("overflows the address space"), "{e}");
    // A huge stride on an axis of one element is never applied: no overflow, no error.
    // SAFETY: a hand-built descriptor over live memory.
    let one = unsafe {
        wp::Array::<f32, 2>::from_dlpack(hand_built(dev, &values, vec![1, 3], vec![i64::MAX, 1], 0))
    }
    .unwrap();
    assert_eq!(host(&one), [0.0, 1.0, 2.0]);

    // Not overlapping: [i, j] at 2i + 6j (a transposed view of every other element), offset
    // by one element.
    // SAFETY: every element lies in the 12 f32 of the tensor's memory.
    let t = unsafe {
        wp::Array::<f32, 2>::from_dlpack(hand_built(dev, &values, vec![3, 2], vec![2, 6], 4))
    }
    .unwrap();
    assert_eq!(t.strides(), [2, 6]);
    assert_eq!(host(&t), [1.0, 7.0, 3.0, 9.0, 5.0, 11.0]);
    let out = wp::Array::<f32, 2>::zeros((3, 2), dev).unwrap();
    wp::launch(k_copy_2d, (3, 2), (&t, &out), dev).unwrap();
    assert_eq!(host(&out), [1.0, 7.0, 3.0, 9.0, 5.0, 11.0]);
    // Rows reversed: element zero is the last of three rows of 4 (byte offset 32).
    // SAFETY: as above.
    let r = unsafe {
        wp::Array::<f32, 2>::from_dlpack(hand_built(dev, &values, vec![3, 4], vec![-4, 1], 32))
    }
    .unwrap();
    assert_eq!(host(&r)[..4], [8.0, 9.0, 10.0, 11.0]);
    assert_eq!(host(&r)[8..], [0.0, 1.0, 2.0, 3.0]);
}

//! Interop: the addresses of arrays, arrays over external host and device memory (zero-copy,
//! strided, with an owner dropped exactly when the last handle drops), and the ndarray
//! conversions. Every comparison is exact: the kernels copy or add small integers in f32.

use crate::host;
use warp_lang as wp;
use wp::prelude::*;

use std::sync::Arc;

backend_tests!(
    wrap_is_zero_copy,
    owner_drops_with_last_handle,
    strided_and_negative_wraps,
    wrap_errors,
    overlapping_wraps_refused,
    ndarray_views,
    from_ndarray,
    external_stream,
    ndarray_components,
    nalgebra_conversions,
);

#[wp::kernel]
fn k_add_index(a: Array<f32>) {
    let i = tid();
    a[i] = a[i] + i as f32;
}

#[wp::kernel]
fn k_copy_2d(src: Array<f32, 2>, dst: Array<f32, 2>) {
    let (i, j) = tid();
    dst[(i, j)] = src[(i, j)];
}

/// Memory on `dev` that the wrapped array does not own: a `Vec` on the CPU, another array's
/// device memory on a GPU (as another CUDA library's buffer would be). Returns the address,
/// the owner to hand over, and a reader of the memory that does not go through the wrap.
#[allow(clippy::type_complexity)]
fn external(
    dev: &wp::Device,
    values: &[f32],
) -> (u64, Box<dyn Send + Sync>, Box<dyn Fn() -> Vec<f32>>) {
    if dev.is_cpu() {
        let v = Arc::new(values.to_vec());
        let ptr = v.as_ptr() as u64;
        let n = values.len();
        let reader = Arc::clone(&v);
        // Reads through the raw pointer: the Vec's memory is written through the wrap.
        let read = move || unsafe { std::slice::from_raw_parts(reader.as_ptr(), n) }.to_vec();
        (ptr, Box::new(v), Box::new(read))
    } else {
        let a = wp::Array::<f32>::from_slice(values, dev).unwrap();
        let ptr = a.device_ptr();
        let other = a.clone();
        (ptr, Box::new(a), Box::new(move || other.to_vec().unwrap()))
    }
}

/// Wraps `ptr` on `dev`: host pointer or device pointer by the device's kind.
unsafe fn wrap<const N: usize>(
    dev: &wp::Device,
    ptr: u64,
    shape: [usize; N],
    byte_strides: Option<[isize; N]>,
    owner: impl Send + Sync + 'static,
) -> wp::Result<wp::Array<f32, N>> {
    unsafe {
        if dev.is_cpu() {
            wp::Array::from_host_ptr(ptr as usize as *mut f32, shape, byte_strides, dev, owner)
        } else {
            wp::Array::from_device_ptr(ptr, shape, byte_strides, dev, owner)
        }
    }
}

/// The wrap addresses the external memory itself: same address, a kernel's writes through the
/// wrap are seen by the memory's other reader.
fn wrap_is_zero_copy(dev: &wp::Device) {
    let (ptr, owner, read) = external(dev, &[10.0, 20.0, 30.0, 40.0]);
    // SAFETY: 4 f32 at `ptr`, kept alive by `owner`; only this test touches them.
    let a = unsafe { wrap(dev, ptr, [4], None, owner) }.unwrap();
    assert_eq!(a.device_ptr(), ptr);
    assert_eq!(a.byte_strides(), [4]);
    assert_eq!(a.to_vec().unwrap(), [10.0, 20.0, 30.0, 40.0]);
    wp::launch(k_add_index, 4, (&a,), dev).unwrap();
    wp::synchronize().unwrap();
    assert_eq!(read(), [10.0, 21.0, 32.0, 43.0]);
    if dev.is_cpu() {
        assert_eq!(a.as_ptr().unwrap() as u64, ptr);
    } else {
        let e = a.as_ptr().unwrap_err().to_string();
        assert!(e.contains("use device_ptr"), "{e}");
    }
}

/// The owner lives exactly as long as the last handle (clones and views included).
fn owner_drops_with_last_handle(dev: &wp::Device) {
    let (ptr, owner, _read) = external(dev, &[1.0; 6]);
    let token = Arc::new(());
    // SAFETY: 6 f32 at `ptr`, kept alive by `owner` (in the tuple).
    let a = unsafe { wrap(dev, ptr, [2, 3], None, (owner, Arc::clone(&token))) }.unwrap();
    assert_eq!(Arc::strong_count(&token), 2);
    let row = a.row(1).unwrap();
    let b = a.clone();
    drop(a);
    drop(b);
    assert_eq!(
        Arc::strong_count(&token),
        2,
        "a view still holds the memory"
    );
    assert_eq!(row.to_vec().unwrap(), [1.0; 3]);
    drop(row);
    assert_eq!(Arc::strong_count(&token), 1, "dropped with the last handle");
}

/// Strides in bytes: a transposed (column-major) wrap and one with a negative stride, both
/// read by a kernel as 2-D arrays.
fn strided_and_negative_wraps(dev: &wp::Device) {
    // Memory: 3 rows of 4, row-major: value 10 * r + c.
    let values: Vec<f32> = (0..12).map(|k| (10 * (k / 4) + k % 4) as f32).collect();
    let (ptr, owner, _read) = external(dev, &values);
    // The transpose: shape 4 x 3, element [c, r] at byte 4 c + 16 r.
    // SAFETY: every element lies in the 12 f32 at `ptr`, kept alive by `owner`.
    let t = unsafe { wrap(dev, ptr, [4, 3], Some([4, 16]), owner) }.unwrap();
    assert!(!t.is_contiguous());
    assert_eq!(t.strides(), [1, 4]);
    let out = wp::Array::<f32, 2>::zeros((4, 3), dev).unwrap();
    wp::launch(k_copy_2d, (4, 3), (&t, &out), dev).unwrap();
    let expect: Vec<f32> = (0..12).map(|k| (10 * (k % 3) + k / 3) as f32).collect();
    assert_eq!(host(&out), expect);
    // Rows in reverse: element zero is the last row, the row stride is -16 bytes.
    let last_row = ptr + 8 * 4;
    let keep = t.clone();
    // SAFETY: rows 2, 1, 0 of the same memory, kept alive by `keep` (which owns it).
    let r = unsafe { wrap(dev, last_row, [3, 4], Some([-16, 4]), keep) }.unwrap();
    assert_eq!(r.device_ptr(), last_row);
    let out = wp::Array::<f32, 2>::zeros((3, 4), dev).unwrap();
    wp::launch(k_copy_2d, (3, 4), (&r, &out), dev).unwrap();
    let expect: Vec<f32> = (0..12).map(|k| (10 * (2 - k / 4) + k % 4) as f32).collect();
    assert_eq!(host(&out), expect);
    assert_eq!(r.to_vec().unwrap(), expect);
}

/// Every checkable mistake is an error naming the argument.
fn wrap_errors(dev: &wp::Device) {
    let (ptr, owner, _read) = external(dev, &[0.0; 8]);
    let owner = Arc::new(owner);
    let err = |r: wp::Result<wp::Array<f32, 2>>| r.expect_err("an error").to_string();
    // SAFETY (all): every call is refused before the memory is used.
    unsafe {
        let e = err(wrap(dev, ptr + 2, [2, 2], None, owner.clone()));
        assert!(
            e.contains("ptr") && e.contains("not aligned to 4 bytes"),
            "{e}"
        );
        let e = err(wrap(dev, 0, [2, 2], None, owner.clone()));
        assert!(e.contains("ptr is null"), "{e}");
        let e = err(wrap(dev, ptr, [2, 2], Some([6, 4]), owner.clone()));
        assert!(
            e.contains("byte_strides[0] = 6 is not a multiple of 4"),
            "{e}"
        );
        // Negative strides reaching below address 0.
        let e = err(wrap(dev, 8, [4, 2], Some([-16, 4]), owner.clone()));
        assert!(e.contains("reach address 0 or below"), "{e}");
        let e = err(wrap(
            dev,
            ptr,
            [usize::MAX / 2, 4],
            Some([16, 4]),
            owner.clone(),
        ));
        assert!(e.contains("too large"), "{e}");
        // The wrong constructor for the device.
        let other = if dev.is_cpu() {
            wp::Array::<f32, 2>::from_device_ptr(ptr, [2, 2], None, dev, ())
        } else {
            wp::Array::<f32, 2>::from_host_ptr(ptr as usize as *mut f32, [2, 2], None, dev, ())
        };
        let e = err(other);
        assert!(
            e.contains("is not a GPU") || e.contains("is not the CPU"),
            "{e}"
        );
        // An empty wrap may have a null pointer.
        let empty = wrap::<2>(dev, 0, [0, 3], None, ()).unwrap();
        assert!(empty.is_empty());
        assert_eq!(empty.to_vec().unwrap(), Vec::<f32>::new());
    }
    assert_eq!(
        Arc::strong_count(&owner),
        1,
        "refused wraps drop their owner"
    );
}

/// A layout that addresses one element from two indices is refused, since every array is
/// writable (there is no read-only array): an ndarray broadcast view (a zero stride, as
/// PyTorch's `expand()`), and non-zero strides that alias. Non-overlapping strided layouts
/// (every other element, transposed, reversed) are still wrapped, and a mutable ndarray view
/// of one is built.
fn overlapping_wraps_refused(dev: &wp::Device) {
    let values: Vec<f32> = (0..12).map(|k| k as f32).collect();
    let (ptr, owner, _read) = external(dev, &values);
    let owner = Arc::new(owner);
    let err = |r: wp::Result<wp::Array<f32, 2>>| match r {
        Ok(a) => panic!("wrapped {:?} with strides {:?}", a.shape(), a.strides()),
        Err(e @ wp::Error::InvalidArgument { .. }) => e.to_string(),
        Err(e) => panic!("unexpected error {e:?}"),
    };
    let call = if dev.is_cpu() {
        "from_host_ptr"
    } else {
        "from_device_ptr"
    };
    // The layout of an ndarray broadcast: a row of 4 repeated 3 times.
    let row = ndarray::Array1::from_iter((0..4).map(|k| k as f32));
    let b = row.broadcast((3, 4)).unwrap();
    let byte_strides = [b.strides()[0] * 4, b.strides()[1] * 4];
    assert_eq!(byte_strides, [0, 4]);
    // SAFETY (all): every layout lies in the 12 f32 at `ptr` (kept alive by `owner`); the
    // refused ones are refused before the memory is used.
    unsafe {
        let e = err(wrap(dev, ptr, [3, 4], Some(byte_strides), owner.clone()));
        assert!(
            e.contains(call)
                && e.contains("shape [3, 4]")
                && e.contains("byte_strides [0, 4]")
                && e.contains("more than one index"),
            "{e}"
        );
        // The host memory of the broadcast view itself, on the CPU.
        if dev.is_cpu() {
            let e = err(wp::Array::<f32, 2>::from_host_ptr(
                b.as_ptr() as *mut f32,
                [3, 4],
                Some(byte_strides),
                dev,
                (),
            ));
            assert!(e.contains("byte_strides [0, 4]"), "{e}");
        }
        // Aliasing without a zero stride: element [i, j] at i + j (so [0, 1] is [1, 0]).
        let e = err(wrap(dev, ptr, [3, 2], Some([4, 4]), owner.clone()));
        assert!(e.contains("shape [3, 2] with byte_strides [4, 4]"), "{e}");
        // A row stride inside the span of a row: [1, 0] is [0, 2].
        let e = err(wrap(dev, ptr, [2, 3], Some([8, 4]), owner.clone()));
        assert!(e.contains("more than one index"), "{e}");
        // Negative and aliasing: [i, j] at element 8 - 2i - j ([0, 2] is [1, 0]).
        let e = err(wrap(dev, ptr + 32, [3, 3], Some([-8, -4]), owner.clone()));
        assert!(e.contains("byte_strides [-8, -4]"), "{e}");

        // A zero stride on an axis of one element, and any layout of no elements, address
        // each element once.
        let one = wrap(dev, ptr, [1, 4], Some([0, 4]), owner.clone()).unwrap();
        assert_eq!(one.to_vec().unwrap(), [0.0, 1.0, 2.0, 3.0]);
        let none = wrap(dev, ptr, [0, 4], Some([0, 0]), owner.clone()).unwrap();
        assert!(none.is_empty());

        // Not overlapping: every other element, transposed ([i, j] at 2i + 6j: 3 x 2 of
        // the even elements), and rows reversed with a gap.
        let mut t = wrap(dev, ptr, [3, 2], Some([8, 24]), owner.clone()).unwrap();
        assert_eq!(t.to_vec().unwrap(), [0.0, 6.0, 2.0, 8.0, 4.0, 10.0]);
        let r = wrap(dev, ptr + 32, [3, 3], Some([-16, 4]), owner.clone()).unwrap();
        assert_eq!(
            r.to_vec().unwrap(),
            [8.0, 9.0, 10.0, 4.0, 5.0, 6.0, 0.0, 1.0, 2.0]
        );
        drop(r);
        if dev.is_cpu() {
            t.as_ndarray_mut().unwrap()[[2, 1]] = -1.0;
            assert_eq!(t.to_vec().unwrap()[5], -1.0);
        }
    }
    assert_eq!(Arc::strong_count(&owner), 1, "every wrap dropped its owner");
}

/// `as_ndarray` views a CPU array in place (strides included); a shared array needs the
/// unsafe form; GPU arrays are refused.
fn ndarray_views(dev: &wp::Device) {
    let mut a = wp::Array::<f32, 2>::from_slice_shape(&[0.0, 1.0, 2.0, 3.0, 4.0, 5.0], (2, 3), dev)
        .unwrap();
    if !dev.is_cpu() {
        let e = a.as_ndarray().unwrap_err().to_string();
        assert!(e.contains("not the CPU"), "{e}");
        return;
    }
    {
        let v = a.as_ndarray().unwrap();
        assert_eq!(v.shape(), [2, 3]);
        assert_eq!(v[[1, 2]], 5.0);
        assert_eq!(v.as_ptr() as u64, a.device_ptr());
    }
    a.as_ndarray_mut().unwrap()[[0, 1]] = 7.0;
    wp::launch(k_copy_2d, (2, 3), (&a, &a), dev).unwrap();
    assert_eq!(a.to_vec().unwrap(), [0.0, 7.0, 2.0, 3.0, 4.0, 5.0]);
    // A transposed view keeps its strides.
    let mut t = a.transpose();
    let e = t.as_ndarray().unwrap_err().to_string();
    assert!(e.contains("shared with a clone or view"), "{e}");
    // SAFETY: nothing writes `a` while the view lives.
    let v = unsafe { t.as_ndarray_unchecked() }.unwrap();
    assert_eq!(v.shape(), [3, 2]);
    assert_eq!(v.strides(), [1, 3]);
    assert_eq!(v[[1, 0]], 7.0);
    assert_eq!(v.t(), ndarray::arr2(&[[0.0, 7.0, 2.0], [3.0, 4.0, 5.0]]));
}

/// `from_ndarray` takes an owned ndarray array over on the CPU (same memory, also for
/// negative strides) and copies on a GPU; `from_ndarray_copy` copies any view.
fn from_ndarray(dev: &wp::Device) {
    let n = ndarray::Array2::from_shape_fn((3, 4), |(r, c)| (10 * r + c) as f32);
    let ptr = n.as_ptr() as u64;
    let mut a = wp::Array::<f32, 2>::from_ndarray(n, dev).unwrap();
    let expect: Vec<f32> = (0..12).map(|k| (10 * (k / 4) + k % 4) as f32).collect();
    assert_eq!(a.to_vec().unwrap(), expect);
    if dev.is_cpu() {
        assert_eq!(a.device_ptr(), ptr, "zero-copy on the CPU");
        a.as_ndarray_mut().unwrap()[[2, 3]] = -1.0;
        assert_eq!(a.to_vec().unwrap()[11], -1.0);
    } else {
        assert_ne!(a.device_ptr(), ptr);
    }
    // Negative strides: rows reversed in place.
    let mut n = ndarray::Array2::from_shape_fn((3, 4), |(r, c)| (10 * r + c) as f32);
    n.invert_axis(ndarray::Axis(0));
    let first = n.as_ptr() as u64;
    let b = wp::Array::<f32, 2>::from_ndarray(n, dev).unwrap();
    if dev.is_cpu() {
        assert_eq!(b.device_ptr(), first);
        assert_eq!(b.strides(), [-4, 1]);
    }
    let expect: Vec<f32> = (0..12).map(|k| (10 * (2 - k / 4) + k % 4) as f32).collect();
    assert_eq!(b.to_vec().unwrap(), expect);
    // A copy of a strided view (every other column): row-major, fresh memory.
    let n = ndarray::Array2::from_shape_fn((2, 4), |(r, c)| (10 * r + c) as f32);
    let view = n.slice(ndarray::s![.., ..;2]);
    let c = wp::Array::<f32, 2>::from_ndarray_copy(&view, dev).unwrap();
    assert!(c.is_contiguous());
    assert_eq!(c.to_vec().unwrap(), [0.0, 2.0, 10.0, 12.0]);
    // Vector elements stay elements (no trailing axis).
    let v = ndarray::Array1::from_vec(vec![glam::Vec3::X, glam::Vec3::Y]);
    let w = wp::Array::<glam::Vec3, 1>::from_ndarray(v, dev).unwrap();
    assert_eq!(w.to_vec().unwrap(), [glam::Vec3::X, glam::Vec3::Y]);
}

/// A stream created elsewhere (here: a stream of this crate, by its raw `CUstream`, as another
/// library would hand one over) takes launches; its owner drops with the last wrapper.
fn external_stream(dev: &wp::Device) {
    if dev.is_cpu() {
        // SAFETY: refused before the pointer is used.
        let e = unsafe { wp::Stream::from_raw(std::ptr::NonNull::dangling().as_ptr(), dev, ()) }
            .unwrap_err()
            .to_string();
        assert!(e.contains("needs a CUDA device"), "{e}");
        return;
    }
    // SAFETY: refused before use.
    let e = unsafe { wp::Stream::from_raw(std::ptr::null_mut(), dev, ()) }
        .unwrap_err()
        .to_string();
    assert!(e.contains("cu_stream is null"), "{e}");
    let other = wp::Stream::new(dev).unwrap();
    let raw = other.cuda_stream().cu_stream().cast::<std::ffi::c_void>();
    let token = Arc::new(());
    // SAFETY: a stream of `dev`'s context, kept alive by `other` (in the owner).
    let s = unsafe { wp::Stream::from_raw(raw, dev, (other, Arc::clone(&token))) }.unwrap();
    assert!(!s.is_default());
    let a = wp::Array::<f32>::full(1024, 1.0, dev).unwrap();
    wp::launch_on(k_add_index, 1024, (&a,), &s).unwrap();
    s.synchronize().unwrap();
    // Exact: 1 + i for i < 1024 in f32.
    assert_eq!(
        a.to_vec().unwrap(),
        (0..1024).map(|i| 1.0 + i as f32).collect::<Vec<_>>()
    );
    let clone = s.clone();
    drop(s);
    assert_eq!(Arc::strong_count(&token), 2);
    drop(clone);
    // The crate's ordering bookkeeping held the stream until the next operation on the
    // default stream: the read-back above, which released it.
    assert_eq!(
        Arc::strong_count(&token),
        1,
        "dropped with the last wrapper"
    );
}

/// Vector and matrix elements as trailing axes, as NumPy has them in Warp: `[.., 3]` for
/// `Vec3`, `[.., row, column]` for matrices (glam stores columns: the strides say so).
fn ndarray_components(dev: &wp::Device) {
    use glam::{Mat2, Vec2, Vec3};
    let values: Vec<Vec3> = (0..4)
        .map(|k| Vec3::new(k as f32, 10.0, 100.0 * k as f32))
        .collect();
    let mut a = wp::Array::<Vec3, 2>::from_slice_shape(&values, (2, 2), dev).unwrap();
    if !dev.is_cpu() {
        let e = a.as_ndarray_components().unwrap_err().to_string();
        assert!(e.contains("not the CPU"), "{e}");
        return;
    }
    {
        let v = a.as_ndarray_components().unwrap();
        assert_eq!(v.shape(), [2, 2, 3]);
        assert_eq!(v.strides(), [6, 3, 1]);
        assert_eq!(v[[1, 1, 2]], 300.0);
        assert_eq!(v[[1, 0, 0]], 2.0);
    }
    a.as_ndarray_components_mut().unwrap()[[0, 1, 1]] = -5.0;
    assert_eq!(a.to_vec().unwrap()[1], Vec3::new(1.0, -5.0, 100.0));
    // A transposed array of vectors keeps its strides (in scalars).
    let mut t = a.transpose();
    drop(a);
    let v = t.as_ndarray_components().unwrap();
    assert_eq!(v.strides(), [3, 6, 1]);
    assert_eq!(v[[1, 0, 1]], -5.0);
    // Matrices: [k, row, column].
    let m = Mat2::from_cols(Vec2::new(1.0, 2.0), Vec2::new(3.0, 4.0));
    let mut b = wp::Array::<Mat2>::from_slice(&[m, m * 2.0], dev).unwrap();
    let v = b.as_ndarray_components().unwrap();
    assert_eq!(v.shape(), [2, 2, 2]);
    assert_eq!(v[[0, 0, 1]], 3.0, "row 0, column 1");
    assert_eq!(v[[1, 1, 0]], 4.0, "row 1, column 0 of 2m");
    // Scalars have no trailing axis.
    let mut c = wp::Array::<f32>::from_slice(&[1.0, 2.0], dev).unwrap();
    assert_eq!(c.as_ndarray_components().unwrap().shape(), [2]);
}

/// nalgebra's glam conversions (the `nalgebra` feature) on array contents: exact, they move
/// the same f32 values.
fn nalgebra_conversions(dev: &wp::Device) {
    let p = nalgebra::Vector3::new(1.0f32, 2.0, 3.0);
    let m = nalgebra::Matrix3::new(1.0f32, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 10.0);
    let a = wp::Array::<glam::Vec3>::from_slice(&[p.into()], dev).unwrap();
    let b = wp::Array::<glam::Mat3>::from_slice(&[m.into()], dev).unwrap();
    let back: nalgebra::Vector3<f32> = a.to_vec().unwrap()[0].into();
    let mb: nalgebra::Matrix3<f32> = b.to_vec().unwrap()[0].into();
    assert_eq!(back, p);
    assert_eq!(mb, m);
    // Row 0, column 1 of nalgebra's matrix is glam's column 1, row 0.
    assert_eq!(b.to_vec().unwrap()[0].col(1).x, 2.0);
}

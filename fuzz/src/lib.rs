//! The fuzz harness: one function per target, each feeding bytes to a reader of untrusted
//! input and checking what it returns. A reader may answer `Ok` or `Err`; a panic, an abort or
//! a broken invariant (an assertion here) is a finding.
//!
//! The cargo-fuzz targets (fuzz/fuzz_targets/) call these functions, and so does the root
//! package's stable test tests/fuzz_corpus.rs (it includes this file as a module), which
//! replays every input under fuzz/corpus/<target>/: the corpus is a regression suite of
//! `cargo test`, and a crash found here is fixed once and stays fixed. This file therefore
//! uses only crates the root package has too (warp_runtime with `obj` and `dlpack`,
//! bytemuck, glam).

use std::sync::Arc;

use warp_runtime::dlpack::ffi::{
    DLDataType, DLDataTypeCode, DLDevice, DLDeviceType, DLManagedTensor, DLManagedTensorVersioned,
};
use warp_runtime::dlpack::{metadata::Dynamic, DlpackFlags, Managed, ManagedTensorBase};
use warp_runtime::objects::nvdb::{read_nvdb, write_nvdb, Codec, GridType, NvdbGrid};
use warp_runtime::objects::{ObjMesh, Volume};
use warp_runtime::{Array, Device, DlpackScalar, NdComponents};

/// The CPU device (every target runs on the host).
fn cpu() -> Device {
    warp_runtime::device::cpu()
}

// ---------------------------------------------------------------------------------------
// NanoVDB

/// `.nvdb` bytes through [`read_nvdb`], and the same bytes as one grid buffer through
/// [`NvdbGrid::from_bytes`] (warp-core's validator). Every grid that comes back must answer
/// every query (it was validated: its offsets stay inside it), write out and read back
/// unchanged with either codec, and open as a CPU [`Volume`] when it holds floats.
/// Returns whether either reader accepted the bytes.
pub fn nvdb(data: &[u8]) -> bool {
    let grid = NvdbGrid::from_bytes(data.to_vec());
    if let Ok(g) = &grid {
        exercise_grid(g);
    }
    let Ok(grids) = read_nvdb(data) else {
        return grid.is_ok();
    };
    for g in &grids {
        exercise_grid(g);
    }
    if grids.is_empty() || grids.len() > u16::MAX as usize {
        return true;
    }
    let refs: Vec<&NvdbGrid> = grids.iter().collect();
    // Deflating a grid of a megabyte or more (Warp's fixtures) takes most of a run's time:
    // large grids round-trip uncompressed only (the ZIP writer is the same for every size).
    let small = grids.iter().map(|g| g.as_bytes().len()).sum::<usize>() <= 1 << 16;
    let codecs: &[Codec] = if small {
        &[Codec::None, Codec::Zip]
    } else {
        &[Codec::None]
    };
    for &codec in codecs {
        let bytes = write_nvdb(&refs, codec).expect("the grids of a file that read write out");
        let back = read_nvdb(&bytes)
            .unwrap_or_else(|e| panic!("a written file ({codec:?}) reads back: {e}"));
        assert!(back == grids, "{codec:?} round trip changed the grids");
    }
    true
}

/// Every query of a validated grid.
fn exercise_grid(g: &NvdbGrid) {
    let _ = g.name();
    let _ = g.transform();
    let bbox = g.index_bbox().expect("a validated grid has a root bbox");
    let _ = g
        .checksum_matches()
        .expect("a validated grid has a checksum field");
    // Storing the checksum makes it match (its own field is not covered).
    let summed = g.clone().with_checksum();
    assert_eq!(summed.checksum_matches().unwrap(), Some(true));
    if g.grid_type() == GridType::Float {
        let (lo, hi) = bbox;
        let mid = [0, 1, 2].map(|k| ((lo[k] as i64 + hi[k] as i64) / 2) as i32);
        for ijk in [lo, hi, mid, [0; 3], [i32::MIN, i32::MAX, -1]] {
            g.value_f32(ijk)
                .unwrap_or_else(|e| panic!("lookup {ijk:?} in a validated grid: {e}"));
        }
        Volume::<f32>::from_grid_bytes(g.as_bytes(), &cpu())
            .unwrap_or_else(|e| panic!("a validated Float grid opens as a Volume<f32>: {e}"));
    } else {
        assert!(
            g.value_f32([0; 3]).is_err(),
            "value_f32 of a {:?} grid",
            g.grid_type()
        );
    }
}

// ---------------------------------------------------------------------------------------
// OBJ

/// OBJ text (bytes that are not UTF-8 replaced) through [`ObjMesh::parse`]: a mesh that comes
/// back has whole triangles whose indices name its points, and builds a CPU [`Mesh`]
/// (a BVH over the points) or says why not. Returns whether both steps succeeded.
///
/// [`Mesh`]: warp_runtime::objects::Mesh
pub fn obj(data: &[u8]) -> bool {
    let text = String::from_utf8_lossy(data);
    let Ok(m) = ObjMesh::parse(&text) else {
        return false;
    };
    assert_eq!(m.indices.len() % 3, 0, "whole triangles");
    assert_eq!(m.triangles(), m.indices.len() / 3);
    for &i in &m.indices {
        assert!(
            i >= 0 && (i as usize) < m.points.len(),
            "index {i} of {} points",
            m.points.len()
        );
    }
    m.to_mesh(&cpu()).is_ok()
}

// ---------------------------------------------------------------------------------------
// DLPack

/// The fuzzer's bytes read as the fields of a descriptor; past the end, zeros.
struct Fields<'a>(&'a [u8]);

impl Fields<'_> {
    fn u8(&mut self) -> u8 {
        let (&b, rest) = self.0.split_first().unwrap_or((&0, &[]));
        self.0 = rest;
        b
    }

    fn raw_i64(&mut self) -> i64 {
        i64::from_le_bytes(std::array::from_fn(|_| self.u8()))
    }

    /// A shape, stride, offset or id: mostly small (one byte, -32 to 159), where layouts
    /// land inside the buffer, else any i64 (the extremes where arithmetic overflows).
    fn value(&mut self) -> i64 {
        match self.u8() {
            t @ 0..=0xbf => t as i64 - 32,
            _ => self.raw_i64(),
        }
    }
}

/// Bytes of the host buffer every fuzzed tensor points into (or near).
const BUFFER: usize = 4096;

/// A DLPack tensor built from fuzzed fields (ABI, flags, shape, strides or none, byte offset,
/// dtype, device, and a data pointer into, near or far from a real host buffer) imported
/// with `Array::from_dlpack` as one of several element types and ranks. The import must
/// return `Ok` or `Err`; it must release the tensor (run its deleter once) either way, when
/// the array's last handle drops; an `Ok` must describe a layout whose extent the importer
/// computed without overflow; and an `Ok` CPU array over a layout inside the buffer must read
/// the buffer's elements where the descriptor puts them. Returns whether the import succeeded.
pub fn dlpack(data: &[u8]) -> bool {
    let mut f = Fields(data);
    let target = f.u8();
    // Each element type and rank the importer is generic over checks its own trailing axes.
    match target % 8 {
        0 => import::<f32, 1>(&mut f),
        1 => import::<f32, 2>(&mut f),
        2 => import::<f32, 3>(&mut f),
        3 => import::<glam::Vec3, 1>(&mut f),
        4 => import::<glam::Vec3, 2>(&mut f),
        5 => import::<glam::Mat3, 1>(&mut f),
        6 => import::<u8, 2>(&mut f),
        _ => import::<i64, 1>(&mut f),
    }
}

fn import<T, const N: usize>(f: &mut Fields) -> bool
where
    T: NdComponents,
    T::Scalar: DlpackScalar,
{
    let mode = f.u8();
    if mode & 1 == 0 {
        import_as::<DLManagedTensorVersioned, T, N>(f, mode)
    } else {
        import_as::<DLManagedTensor, T, N>(f, mode)
    }
}

fn import_as<M: ManagedTensorBase, T, const N: usize>(f: &mut Fields, mode: u8) -> bool
where
    T: NdComponents,
    T::Scalar: DlpackScalar,
{
    let (read_only, no_strides, null_data) = (mode & 2 != 0, mode & 4 != 0, mode & 8 != 0);
    // Mostly the rank and dtype the element type needs, so that imports get past those
    // checks to the layout's.
    let trailing = T::SHAPE.len();
    let ndim = match f.u8() {
        0..=0xcf => N + trailing,
        r => (r % 8) as usize,
    };
    let dtype = match f.u8() {
        0..=0xdf => T::Scalar::DTYPE,
        _ => DLDataType {
            code: DLDataTypeCode(f.u8()),
            bits: f.u8(),
            lanes: f.u8() as u16 | (f.u8() as u16) << 8,
        },
    };
    let device_id = f.value() as i32;
    let device = match f.u8() % 8 {
        0..=3 => DLDevice::CPU,
        4 => DLDevice {
            device_type: DLDeviceType::CUDAHOST,
            device_id: 0,
        },
        5 => DLDevice::cuda(device_id),
        6 => DLDevice {
            device_type: DLDeviceType::CUDAMANAGED,
            device_id,
        },
        _ => DLDevice {
            device_type: DLDeviceType(f.value() as u32),
            device_id,
        },
    };
    let shift = f.value();
    let byte_offset = f.value() as u64;
    let mut shape: Vec<i64> = (0..ndim).map(|_| f.value()).collect();
    // Mostly the trailing axes the element type needs (shape and strides), else fuzzed.
    let mut strides: Vec<i64> = (0..ndim).map(|_| f.value()).collect();
    if f.u8() < 0xc0 && ndim == N + trailing {
        for (k, (&e, &s)) in T::SHAPE.iter().zip(T::STRIDES).enumerate() {
            shape[N + k] = e as i64;
            strides[N + k] = s as i64;
        }
    }

    // The memory: 8-byte aligned, every byte distinct from its neighbours.
    let mut buffer = vec![0u64; BUFFER / 8];
    for (i, b) in bytemuck::cast_slice_mut::<u64, u8>(&mut buffer)
        .iter_mut()
        .enumerate()
    {
        *b = (i * 131 + 7) as u8;
    }
    let base = buffer.as_ptr() as u64;
    let ptr = if null_data {
        0
    } else {
        base.wrapping_add(shift as u64)
    };

    // The deleter's context: its count says whether the tensor was released.
    let token = Arc::new(());
    let Ok(mut init) = Dynamic::new(shape.clone(), strides.clone())
        .initialize_as::<M>(Box::new(Arc::clone(&token)))
    else {
        return false;
    };
    init.set_data(ptr as usize as *mut std::ffi::c_void)
        .set_dtype(dtype)
        .set_device(device)
        .set_byte_offset(byte_offset);
    if no_strides {
        // Compact row-major, DLPack's meaning of no strides (legacy ABI).
        init.tensor_mut().strides = std::ptr::null_mut();
    }
    if read_only {
        // Not settable on the legacy ABI: its descriptor has no flags.
        let _ = init.set_flags(DlpackFlags::READ_ONLY);
    }
    // SAFETY: the descriptor's metadata (shape, strides) lives in the tensor's own allocation,
    // and its data pointer is never dereferenced by this harness unless the layout lies inside
    // `buffer`, which outlives the tensor (it drops at the end of this function, after every
    // array over it). The importer does not read the memory (it checks the descriptor and
    // wraps the pointer); a read here happens only for layouts inside the buffer (below).
    let tensor: Managed<M> = unsafe { init.finish() };
    // SAFETY: as above; nothing else touches `buffer` while the array lives.
    let result = unsafe { Array::<T, N>::from_dlpack(tensor) };
    let Ok(array) = result else {
        drop(result);
        assert_eq!(Arc::strong_count(&token), 1, "a refused tensor is released");
        return false;
    };

    // What an accepted descriptor says, recomputed in i128 (no overflow): compact strides
    // when there are none, the element-zero address, the lowest and highest byte addressed.
    let strides = if no_strides {
        let mut s = vec![1i128; ndim];
        for d in (0..ndim.saturating_sub(1)).rev() {
            s[d] = s[d + 1] * shape[d + 1] as i128;
        }
        s
    } else {
        strides.iter().map(|&s| s as i128).collect()
    };
    let scalar = std::mem::size_of::<T::Scalar>() as i128;
    let start = ptr as i128 + byte_offset as i128;
    let empty = shape[..N].contains(&0);
    let (mut lo, mut hi) = (start, start + std::mem::size_of::<T>() as i128 - 1);
    for d in 0..N {
        let reach = strides[d] * (shape[d] as i128 - 1).max(0) * scalar;
        if reach < 0 {
            lo += reach;
        } else {
            hi += reach;
        }
    }
    assert!(
        empty || (lo > 0 && hi <= u64::MAX as i128),
        "accepted a layout reaching bytes {lo}..={hi} (shape {shape:?}, strides {strides:?}, \
         pointer {ptr:#x} + {byte_offset}): its arithmetic overflowed"
    );
    let dims: Vec<usize> = shape[..N].iter().map(|&d| d as usize).collect();
    assert_eq!(
        &array.shape()[..],
        &dims[..],
        "the array has the tensor's leading shape"
    );

    let inside = lo >= base as i128 && hi < (base as usize + BUFFER) as i128;
    let host = [DLDeviceType::CPU, DLDeviceType::CUDAHOST].contains(&device.device_type);
    if !empty && inside && host {
        // Read every element through the array and compare with the bytes the descriptor
        // puts it at (row-major order over the leading axes).
        let got = array
            .to_vec()
            .expect("a CPU array over the buffer reads back");
        let bytes = bytemuck::cast_slice::<u64, u8>(&buffer);
        let size = std::mem::size_of::<T>();
        for (n, element) in got.iter().enumerate() {
            let (mut rest, mut at) = (n, start);
            for d in (0..N).rev() {
                at += (rest % dims[d]) as i128 * strides[d] * scalar;
                rest /= dims[d];
            }
            let at = (at - base as i128) as usize;
            assert_eq!(
                bytemuck::bytes_of(element),
                &bytes[at..at + size],
                "element {n} of shape {dims:?}, strides {strides:?}"
            );
        }
    }
    drop(array);
    assert_eq!(
        Arc::strong_count(&token),
        1,
        "the tensor is released with the array"
    );
    true
}

//! DLPack: arrays exchanged without a copy with the tensors of other libraries (PyTorch, JAX,
//! CuPy and NumPy through Python; candle, burn and other Rust crates through the `dlpark`
//! crate, re-exported as `wp::dlpack`).
//!
//! Elements map to scalars as NumPy sees Warp's arrays ([`NdComponents`]): an
//! `Array<Vec3, 2>` of shape `[a, b]` is the `float32` tensor of shape `[a, b, 3]`. Devices
//! map as `cpu` ↔ `kDLCPU` (and pinned `kDLCUDAHost` memory on import), `cuda:n` ↔
//! `kDLCUDA` device `n` (and `kDLCUDAManaged` on import).
//!
//! # Streams
//! A DLPack tensor carries no stream. An exported GPU array is ready once the work queued on
//! its device's current stream ([`get_stream`](crate::stream::get_stream)) has run; a
//! consumer on another stream orders itself after that stream (the Python layer,
//! `wp::python`, does that through the `__dlpack__(stream=..)` protocol). An imported tensor
//! must be ready for work queued on that stream: the producer's to arrange.

use super::components::NdComponents;
use super::{Array, Element};
use crate::device::{get_device, Device, DeviceKind};
use crate::error::{Error, Result};
use dlpark::ffi::{DLDataType, DLDataTypeCode, DLDevice, DLDeviceType};
use dlpark::{DlpackFlags, Managed, ManagedTensorBase};
use warp_core::{bf16, f16};

/// A scalar type with a DLPack data type: the components of the elements that arrays
/// exchange through DLPack.
pub trait DlpackScalar: Element {
    /// The DLPack data type (type code, bits, one lane).
    const DTYPE: DLDataType;
}

macro_rules! dlpack_scalars {
    ($($t:ty => $code:ident, $bits:literal);* $(;)?) => {$(
        impl DlpackScalar for $t {
            const DTYPE: DLDataType = DLDataType::scalar(DLDataTypeCode::$code, $bits);
        }
    )*};
}
dlpack_scalars!(
    i8 => INT, 8; i16 => INT, 16; i32 => INT, 32; i64 => INT, 64;
    u8 => UINT, 8; u16 => UINT, 16; u32 => UINT, 32; u64 => UINT, 64;
    f16 => FLOAT, 16; f32 => FLOAT, 32; f64 => FLOAT, 64;
    // kDLBfloat (4): the brain float, as PyTorch exports torch.bfloat16.
    bf16 => BFLOAT, 16;
);

/// The DLPack device of an array's device.
pub(crate) fn dlpack_device(device: &Device) -> DLDevice {
    match device.kind() {
        DeviceKind::Cuda { ordinal } => DLDevice::cuda(ordinal as i32),
        DeviceKind::Cpu => DLDevice::CPU,
    }
}

/// The device whose kernels can address memory of a DLPack device.
pub(crate) fn device_of(what: &str, d: DLDevice) -> Result<Device> {
    match d.device_type {
        // Pinned host memory is host memory to the CPU backend.
        DLDeviceType::CPU | DLDeviceType::CUDAHOST => get_device("cpu"),
        DLDeviceType::CUDA | DLDeviceType::CUDAMANAGED => {
            get_device(&format!("cuda:{}", d.device_id))
        }
        other => Err(Error::invalid(format!(
            "{what}: the tensor is on DLPack device type {} (id {}), which warp-lang cannot \
             address (it runs on kDLCPU, kDLCUDAHost, kDLCUDA and kDLCUDAManaged memory)",
            other.0, d.device_id
        ))),
    }
}

fn dtype_name(t: DLDataType) -> String {
    let code = match t.code {
        DLDataTypeCode::INT => "int",
        DLDataTypeCode::UINT => "uint",
        DLDataTypeCode::FLOAT => "float",
        DLDataTypeCode::BFLOAT => "bfloat",
        DLDataTypeCode::BOOL => "bool",
        DLDataTypeCode::COMPLEX => "complex",
        _ => "code",
    };
    if t.lanes == 1 {
        format!("{code}{}", t.bits)
    } else {
        format!("{code}{}x{}", t.bits, t.lanes)
    }
}

impl<T: NdComponents, const N: usize> Array<T, N>
where
    T::Scalar: DlpackScalar,
{
    /// The array as a DLPack tensor, without a copy: its memory, shape and strides (in
    /// scalars, with the element type's trailing component axes), on its device. The tensor
    /// holds a handle to the memory until its consumer drops it, so the memory outlives
    /// this array if need be. Choose the ABI by the result type: `dlpark::versioned::Dlpack`
    /// (DLPack 1.x) or `dlpark::legacy::Dlpack`.
    ///
    /// The consumer shares the memory: the array's concurrency contract extends to it (no
    /// writes while a kernel reads, nor reads while a kernel writes). On a GPU the data is
    /// ready after the work queued on the device's current stream (see the module's notes).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the layout does not fit DLPack's 64-bit fields (never
    /// for an array this crate allocated).
    pub fn to_dlpack<M: ManagedTensorBase>(&self) -> Result<Managed<M>> {
        let (shape, strides) = self.component_shape_strides();
        // Checked, not `as`: a cast would wrap a value past i64 (none on a 64-bit target).
        let too_large = |v: &dyn std::fmt::Debug| {
            Error::invalid(format!(
                "to_dlpack: the layout (shape {shape:?}, strides {strides:?} in scalars) has \
                 {v:?}, which does not fit DLPack's 64-bit fields"
            ))
        };
        let shape64 = shape
            .iter()
            .map(|&d| i64::try_from(d).map_err(|_| too_large(&d)))
            .collect::<Result<Vec<i64>>>()?;
        let strides64 = strides
            .iter()
            .map(|&s| i64::try_from(s).map_err(|_| too_large(&s)))
            .collect::<Result<Vec<i64>>>()?;
        let (shape, strides) = (shape64, strides64);
        let data = self.device_address() as usize as *mut std::ffi::c_void;
        // The context keeps the memory (not the gradient) alive.
        let owner = Box::new(std::sync::Arc::clone(&self.storage));
        let mut initialized = dlpark::metadata::Dynamic::new(shape, strides)
            .initialize_as::<M>(owner)
            .map_err(|e| Error::invalid(format!("to_dlpack: {e}")))?;
        initialized
            .set_data(data)
            .set_dtype(T::Scalar::DTYPE)
            .set_device(dlpack_device(&self.device));
        // SAFETY: `data` addresses element zero of the array's storage, and every index of
        // the shape and strides (the array's own, with the element's components as trailing
        // axes of in-element strides) addresses a scalar of it; the storage lives while the
        // context (a handle to it) does, until the consumer calls the deleter. No flag is
        // set: the memory is writable and was not copied.
        Ok(unsafe { initialized.finish() })
    }

    /// An array over a DLPack tensor's memory, without a copy; the tensor is released (its
    /// deleter called) when the last handle to the array's memory drops.
    ///
    /// The tensor's dtype must be `T`'s scalar type and its trailing axes `T`'s components
    /// (`[.., 3]` of `float32` for `Vec3`, contiguous within an element); the leading `N` axes
    /// may have any strides that are whole elements, negative included. Pinned host memory
    /// (`kDLCUDAHost`) becomes a CPU array, managed memory a GPU array of its device.
    ///
    /// # Safety
    /// The tensor's producer must follow the DLPack contract: the descriptor's data pointer,
    /// shape and strides address memory that stays valid until the deleter runs. And as for
    /// any shared memory ([`from_host_ptr`](Self::from_host_ptr)): nothing else writes it
    /// while a kernel reads it, or reads it while a kernel writes it. On a GPU, work the
    /// producer queued on its own streams must be ordered before this crate's (the
    /// `__dlpack__(stream=..)` protocol does that in Python).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming what does not match: the dtype, the number of axes,
    /// the trailing axes, a stride that is not a whole element, a layout that overlaps itself
    /// (a zero stride on an axis of more than one element, as of a broadcast or PyTorch's
    /// `expand()`: arrays are writable, and there is no read-only array to import it as;
    /// import a contiguous copy), a stride, offset or size past the address space, a
    /// misaligned pointer, a read-only tensor, a device warp-lang cannot address;
    /// [`Error::NoDevice`] for a GPU that is not available. The tensor is released on error.
    pub unsafe fn from_dlpack<M: ManagedTensorBase>(tensor: Managed<M>) -> Result<Self> {
        let what = "from_dlpack";
        if tensor.flags().contains(DlpackFlags::READ_ONLY) {
            return Err(Error::invalid(format!(
                "{what}: the tensor is read-only (DLPack flag READ_ONLY), and kernels may write \
                 any array; import a writable tensor, or a copy"
            )));
        }
        let t = tensor
            .validate()
            .map_err(|e| Error::invalid(format!("{what}: invalid DLPack tensor: {e}")))?;
        let expected = T::Scalar::DTYPE;
        if !t.dtype().matches(expected) {
            return Err(Error::invalid(format!(
                "{what}: the tensor's dtype is {}, the scalars of {} are {}",
                dtype_name(t.dtype()),
                T::TYPE_NAME,
                dtype_name(expected)
            )));
        }
        let device = device_of(what, t.device())?;
        let shape = t.shape();
        let strides = t
            .strides_or_compact()
            .map_err(|e| Error::invalid(format!("{what}: {e}")))?;
        let trailing = T::SHAPE.len();
        if shape.len() != N + trailing {
            return Err(Error::invalid(format!(
                "{what}: the tensor has {} axes ({shape:?}); an Array<{}, {N}> has {N}{}",
                shape.len(),
                T::TYPE_NAME,
                if trailing == 0 {
                    String::new()
                } else {
                    format!(" and {} trailing of shape {:?}", trailing, T::SHAPE)
                }
            )));
        }
        // Shapes are non-negative (`validate`); the conversion only fails where `usize` is
        // narrower than 64 bits.
        let mut dims = [0usize; N];
        for d in 0..N {
            dims[d] = usize::try_from(shape[d]).map_err(|_| {
                Error::invalid(format!(
                    "{what}: axis {d} of the shape {shape:?} has more elements than an \
                     address space"
                ))
            })?;
        }
        let lead_shape = &shape[..N];
        let empty = lead_shape.contains(&0);
        // The components of one element must sit where `T` keeps them (a vector's contiguous,
        // a matrix's by column); a tensor of no elements has no layout to check.
        let (tail_shape, tail_strides) = (&shape[N..], &strides[N..]);
        let tail_ok = tail_shape
            .iter()
            .zip(T::SHAPE)
            .all(|(&d, &e)| usize::try_from(d) == Ok(e))
            && (empty
                || tail_strides
                    .iter()
                    .zip(T::STRIDES)
                    .zip(T::SHAPE)
                    .all(|((&s, &e), &d)| d == 1 || isize::try_from(s) == Ok(e)));
        if !tail_ok {
            return Err(Error::invalid(format!(
                "{what}: the trailing axes have shape {tail_shape:?} and strides \
                 {tail_strides:?} (in scalars); {} needs shape {:?} with strides {:?}",
                T::TYPE_NAME,
                T::SHAPE,
                T::STRIDES
            )));
        }
        let k = Self::components_per_element() as i64;
        let scalar = std::mem::size_of::<T::Scalar>() as isize;
        let mut element_strides = [0isize; N];
        let mut byte_strides = [0isize; N];
        for d in 0..N {
            let s = strides[d];
            // A stride of a length-1 axis is never applied: any value is as good as another.
            if lead_shape[d] <= 1 {
                continue;
            }
            if s % k != 0 {
                return Err(Error::invalid(format!(
                    "{what}: the stride of axis {d} is {s} scalars, not a whole number of {} \
                     ({k} scalars each); strides are {:?}",
                    T::TYPE_NAME,
                    &strides[..]
                )));
            }
            // Checked: a stride times the scalar size past `isize` must not wrap (in a
            // release build it would, to a small or zero stride that aliases other memory).
            byte_strides[d] = isize::try_from(s)
                .ok()
                .and_then(|s| s.checked_mul(scalar))
                .ok_or_else(|| {
                    Error::invalid(format!(
                        "{what}: the stride of axis {d} is {s} scalars of {} bytes, which \
                         overflows a byte offset; strides are {:?}",
                        scalar,
                        &strides[..]
                    ))
                })?;
            // `s / k`, exact (checked above), and in range (`byte_strides[d]` is).
            element_strides[d] = byte_strides[d] / (k as isize * scalar);
        }
        // Every array is writable (kernels write in place): a tensor whose elements alias (a
        // broadcast, PyTorch's `expand()`) is refused, whatever its flags say.
        if super::interop::layout_overlaps(&dims, &element_strides) {
            return Err(super::interop::overlap_error(
                what,
                &format!(
                    "the tensor's shape {shape:?} with strides {:?} (in scalars)",
                    &strides[..]
                ),
            ));
        }
        let ptr = (t.data_ptr() as u64)
            .checked_add(t.byte_offset())
            .ok_or_else(|| {
                Error::invalid(format!(
                    "{what}: the data pointer {:#x} plus the byte_offset {} overflows the \
                     address space",
                    t.data_ptr() as u64,
                    t.byte_offset()
                ))
            })?;
        // Release the tensor when the array's memory is dropped, whichever ABI it came by.
        let owner = tensor.into_deleter();
        // SAFETY: the caller's contract (the DLPack producer's guarantee that the descriptor
        // addresses live memory until the deleter runs; `owner` runs it when the last
        // handle drops). Shape, strides and alignment are checked by the callee.
        unsafe {
            Self::from_external(
                what,
                ptr,
                dims,
                Some(byte_strides),
                &device,
                Some(Box::new(owner)),
            )
        }
    }
}

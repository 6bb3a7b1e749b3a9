//! Python interop through PyO3 and DLPack: a Python extension module written with this crate
//! takes PyTorch, JAX, CuPy or NumPy tensors as arrays without a copy ([`from_dlpack`]) and
//! hands arrays back the same way ([`to_dlpack`], [`DlpackArray`]); errors become Python
//! exceptions (`From<Error> for PyErr`).
//!
//! Streams are ordered by the protocol: an imported CUDA tensor is asked for on the device's
//! current stream ([`get_stream`](crate::stream::get_stream)), so the producer orders its
//! pending work before this crate's; an exported array's `__dlpack__(stream=s)` makes the
//! consumer's stream `s` wait for the work queued here (on the device, without blocking the
//! host; the legacy default stream, `1` or an omitted stream, included).

mod ops;

pub use ops::{NativeOp, Ops};

use crate::array::{Array, DlpackScalar, NdComponents};
use crate::device::Device;
#[cfg(feature = "cuda")]
use crate::device::DeviceKind;
use crate::error::Error;
use dlpark::ffi::{DLDevice, DLManagedTensor, DLManagedTensorVersioned};
use dlpark::python::consumer::stream as dlstream;
#[cfg(feature = "cuda")]
use dlpark::python::CudaStreamRequest;
use dlpark::python::{
    DlpackExporter, DlpackStream, ExportRequest, ImportRequest, ImportedDlpack, StreamArg,
};
use dlpark::{DlpackFlags, Managed};
use pyo3::exceptions::{PyMemoryError, PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::ffi::c_void;

impl From<Error> for PyErr {
    /// Bad arguments become `ValueError`, memory exhaustion `MemoryError`, the rest
    /// `RuntimeError`; the message is the error's (naming kernel, argument and values).
    fn from(e: Error) -> PyErr {
        let message = e.to_string();
        match e {
            Error::InvalidArgument { .. }
            | Error::DeviceMismatch { .. }
            | Error::ShapeMismatch { .. }
            | Error::InvalidDim { .. } => PyValueError::new_err(message),
            Error::OutOfMemory { .. } => PyMemoryError::new_err(message),
            _ => PyRuntimeError::new_err(message),
        }
    }
}

/// The consumer side of an import: this crate's current stream on the tensor's GPU.
struct ConsumerStream {
    #[cfg(feature = "cuda")]
    stream: Option<crate::stream::Stream>,
}

impl ConsumerStream {
    fn for_device(device: &Device) -> PyResult<ConsumerStream> {
        #[cfg(feature = "cuda")]
        {
            let stream = match device.kind() {
                DeviceKind::Cuda { .. } => Some(crate::stream::get_stream(device)?),
                DeviceKind::Cpu => None,
            };
            Ok(ConsumerStream { stream })
        }
        #[cfg(not(feature = "cuda"))]
        {
            let _ = device;
            Ok(ConsumerStream {})
        }
    }

    #[cfg(feature = "cuda")]
    fn raw(&self) -> Option<*mut c_void> {
        self.stream
            .as_ref()
            .map(|s| s.cuda_stream().cu_stream() as *mut c_void)
    }

    #[cfg(not(feature = "cuda"))]
    fn raw(&self) -> Option<*mut c_void> {
        None
    }
}

// SAFETY: the stream handed to `__dlpack__` is this crate's live stream of the tensor's
// device (held by `self` for the call), encoded by CUDA's convention; CPU tensors get none.
unsafe impl DlpackStream for ConsumerStream {
    fn as_python_arg(&self, _py: Python<'_>, _device: DLDevice) -> PyResult<StreamArg> {
        Ok(match self.raw() {
            Some(raw) => dlstream::cuda(raw),
            None => dlstream::none(),
        })
    }

    unsafe fn wait_for_producer(&self, _device: DLDevice, producer: *mut c_void) -> PyResult<bool> {
        #[cfg(feature = "cuda")]
        if let Some(ours) = &self.stream {
            // SAFETY: the producer's live stream of this device (the caller's contract).
            let theirs = unsafe { stream_from_handle(producer as usize, ours.device())? };
            ours.wait_stream(&theirs)?;
            return Ok(true);
        }
        let _ = producer;
        Ok(false)
    }
}

/// Another library's CUDA stream as a [`Stream`](crate::stream::Stream) of `device`, for
/// [`ScopedStream`](crate::stream::ScopedStream) and [`launch_on`](crate::launch_on): a
/// handle as Python gives it (`torch.cuda.current_stream().cuda_stream`, CuPy's
/// `Stream.ptr`), where `0` is the legacy default stream (as are DLPack's `1`, and `2` the
/// per-thread default stream: valid handles to the driver). Launching on the caller's stream
/// orders this crate's work with the framework's both ways, without blocking the host.
///
/// # Safety
/// `handle` is a live stream of `device`'s primary context (the runtime API's context, the one
/// PyTorch and CuPy use) while the returned stream and its clones are used, or `0`, `1`, `2`.
///
/// # Errors
/// `ValueError` for the CPU; `RuntimeError` when the device cannot start.
#[cfg(feature = "cuda")]
pub unsafe fn stream_from_handle(
    handle: usize,
    device: &Device,
) -> PyResult<crate::stream::Stream> {
    let raw = if handle == 0 { 1 } else { handle };
    // SAFETY: the caller's contract; nothing is destroyed when the wrapper drops.
    Ok(unsafe { crate::stream::Stream::from_raw(raw as *mut c_void, device, ())? })
}

/// An array over a Python object's memory, without a copy: a PyTorch, JAX or CuPy tensor on
/// a GPU, a NumPy array or a CPU tensor: anything with `__dlpack__`, or a DLPack capsule.
/// The array keeps the producer's buffer alive; writes through it (kernels run in place)
/// are seen by the Python object. Vector and matrix elements take the tensor's trailing axes
/// (`Array<Vec3>` from a `float32` tensor of shape `(n, 3)`).
///
/// On a GPU the producer is asked to order its pending work before this crate's current
/// stream on the device. Kernels launched meanwhile on the producer's own streams are not
/// ordered with this crate's later work: synchronize, as with any two libraries' streams.
///
/// # Errors
/// `ValueError` when the tensor does not match `Array<T, N>` (dtype, axes, trailing axes,
/// strides), is read-only, or has a layout that overlaps itself (an `expand()`ed or broadcast
/// tensor: arrays are writable, so pass a contiguous copy, `t.contiguous()`); the producer's
/// exception when it cannot export.
pub fn from_dlpack<T, const N: usize>(obj: &Bound<'_, PyAny>) -> PyResult<Array<T, N>>
where
    T: NdComponents,
    T::Scalar: DlpackScalar,
{
    let request = ImportRequest::new(obj.as_borrowed())?;
    let imported = match request.device() {
        Ok(d) => {
            let device = device_of(d)?;
            let stream = ConsumerStream::for_device(&device)?;
            request.import(Some(&stream), None)?
        }
        // A capsule or a legacy producer: no device to negotiate a stream for.
        Err(_) => request.import(None, None)?,
    };
    // SAFETY: the producer implements DLPack (its contract covers the descriptor), and the
    // stream protocol above ordered its pending work; later concurrent use is the caller's.
    let array = unsafe {
        match imported {
            ImportedDlpack::Legacy(t) => Array::<T, N>::from_dlpack(t),
            ImportedDlpack::Versioned(t) => Array::<T, N>::from_dlpack(t),
        }
    };
    Ok(array?)
}

fn device_of(d: DLDevice) -> PyResult<Device> {
    Ok(crate::array::device_of_dlpack("from_dlpack", d)?)
}

/// An array handed to Python: `torch.from_dlpack(a)`, `jax.dlpack.from_dlpack(a)`,
/// `cupy.from_dlpack(a)` and `numpy.from_dlpack(a)` take it without a copy (through
/// `__dlpack__` and `__dlpack_device__`). The consumer's tensor keeps the memory alive.
#[pyclass(name = "Array", module = "warp_lang", frozen)]
pub struct DlpackArray {
    array: Box<dyn Exported>,
}

/// The array's device, shape and element type (what `describe` says); not its elements.
impl std::fmt::Debug for DlpackArray {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (shape, dtype, _) = self.array.describe();
        f.debug_struct("DlpackArray")
            .field("device", self.array.device())
            .field("shape", &shape)
            .field("dtype", &dtype)
            .finish()
    }
}

/// What an exported array needs from its element type, with the type erased.
trait Exported: Send + Sync {
    fn device(&self) -> &Device;
    fn legacy(&self) -> crate::Result<Managed<DLManagedTensor>>;
    fn versioned(&self) -> crate::Result<Managed<DLManagedTensorVersioned>>;
    fn describe(&self) -> (Vec<usize>, &'static str, u64);
}

impl<T: NdComponents, const N: usize> Exported for Array<T, N>
where
    T::Scalar: DlpackScalar,
{
    fn device(&self) -> &Device {
        Array::device(self)
    }
    fn legacy(&self) -> crate::Result<Managed<DLManagedTensor>> {
        self.to_dlpack()
    }
    fn versioned(&self) -> crate::Result<Managed<DLManagedTensorVersioned>> {
        self.to_dlpack()
    }
    fn describe(&self) -> (Vec<usize>, &'static str, u64) {
        (
            self.component_shape_strides().0,
            T::TYPE_NAME,
            self.device_ptr(),
        )
    }
}

/// Wraps `array` for Python (see [`DlpackArray`]); the wrapper shares the array's memory.
pub fn to_dlpack<'py, T, const N: usize>(
    py: Python<'py>,
    array: &Array<T, N>,
) -> PyResult<Bound<'py, DlpackArray>>
where
    T: NdComponents,
    T::Scalar: DlpackScalar,
{
    Bound::new(
        py,
        DlpackArray {
            array: Box::new(array.clone()),
        },
    )
}

impl DlpackExporter for DlpackArray {
    fn device(&self) -> DLDevice {
        crate::array::dlpack_device(self.array.device())
    }

    fn flags(&self) -> DlpackFlags {
        DlpackFlags::empty()
    }

    fn prepare_export(&self, _py: Python<'_>, request: &ExportRequest<'_>) -> PyResult<()> {
        let device = self.array.device();
        #[cfg(feature = "cuda")]
        if let DeviceKind::Cuda { .. } = device.kind() {
            // CUDA's convention: `-1` no ordering, `1` (or nothing) the legacy default
            // stream, `2` the per-thread default stream, else a stream handle.
            let raw = match request.cuda_stream()? {
                CudaStreamRequest::NoSync => return Ok(()),
                CudaStreamRequest::Omitted | CudaStreamRequest::LegacyDefault => 1usize,
                CudaStreamRequest::PerThreadDefault => 2,
                CudaStreamRequest::Pointer(p) => p,
            };
            let ours = crate::stream::get_stream(device)?;
            if raw != ours.cuda_stream().cu_stream() as usize {
                // SAFETY: the consumer's stream of this device, by the protocol.
                let theirs = unsafe { stream_from_handle(raw, device)? };
                theirs.wait_stream(&ours)?;
            }
        }
        let _ = (device, request);
        Ok(())
    }

    fn export_legacy(&self, _py: Python<'_>) -> PyResult<Managed<DLManagedTensor>> {
        Ok(self.array.legacy()?)
    }

    fn export_versioned(&self, _py: Python<'_>) -> PyResult<Managed<DLManagedTensorVersioned>> {
        Ok(self.array.versioned()?)
    }
}

#[pymethods]
impl DlpackArray {
    /// The DLPack protocol's export: a fresh capsule on each call.
    #[pyo3(signature = (*, stream = None, max_version = None, dl_device = None, copy = None))]
    fn __dlpack__<'py>(
        &self,
        py: Python<'py>,
        stream: Option<&Bound<'py, PyAny>>,
        max_version: Option<(u32, u32)>,
        dl_device: Option<(u32, i32)>,
        copy: Option<bool>,
    ) -> PyResult<Py<PyAny>> {
        let request = ExportRequest::parse(stream, max_version, dl_device, copy)?;
        dlpark::python::export_dlpack(self, py, request)
    }

    /// `(device type, device id)`: `(1, 0)` for the CPU, `(2, n)` for `cuda:n`.
    fn __dlpack_device__(&self) -> (u32, i32) {
        let d = DlpackExporter::device(self);
        (d.device_type.0, d.device_id)
    }

    /// The shape of the scalars (the array's, then the element's component axes).
    #[getter]
    fn shape(&self) -> Vec<usize> {
        self.array.describe().0
    }

    /// The address of element zero (what `tensor.data_ptr()` gives for the same memory).
    #[getter]
    fn ptr(&self) -> u64 {
        self.array.describe().2
    }

    /// The device alias: `"cpu"` or `"cuda:n"`.
    #[getter]
    fn device(&self) -> String {
        self.array.device().to_string()
    }

    fn __repr__(&self) -> String {
        let (shape, ty, _) = self.array.describe();
        format!(
            "warp_lang.Array(shape={shape:?}, element={ty}, device=\"{}\")",
            self.array.device()
        )
    }
}

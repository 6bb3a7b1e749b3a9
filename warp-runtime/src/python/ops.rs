//! Ops as Python callables (issue 36): the glue between an [`Op`](crate::ops::Op) and a
//! Python extension module. [`Ops::new`] installs the embedded pure-Python helper
//! (`warp_lang_ops.py`, as `<module>._warp_lang`); [`Ops::add`] sets `<module>.<op name>` to
//! the helper's `Op` object, which wraps a [`NativeOp`]: `op.numpy(..)`, `op.vjp_numpy(..)`,
//! `op.torch(..)` (a `torch.autograd.Function`) and `op(..)`.
//!
//! The helper allocates every buffer (outputs, gradients, scratch) with the caller's
//! framework; the native side only checks and launches. Tensors become
//! [`Buffer`]s through DLPack, asked for on the stream the op launches on (the caller's), so
//! the import orders nothing and copies nothing. The GIL is released while the op launches.

use super::stream_from_handle;
use crate::device::{Device, DeviceKind};
use crate::ops::{ArgKind, Buffer, CallArg, Dtype, Exec, Given, Op, OpSpec, Role, Value};
use dlpark::ffi::{DLDataType, DLDevice};
use dlpark::python::consumer::stream as dlstream;
use dlpark::python::{DlpackStream, ImportRequest, ImportedDlpack, StreamArg};
use dlpark::DlpackFlags;
use pyo3::exceptions::{PyTypeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyList, PyModule, PyTuple};
use std::ffi::{c_void, CString};
use std::sync::Mutex;

/// The helper's source, compiled into every extension that uses [`Ops`]: helper and native
/// side always match.
const HELPER: &str = include_str!("warp_lang_ops.py");

/// Installs ops into a `#[pymodule]`:
///
/// ```ignore
/// #[pymodule]
/// fn my_module(m: &Bound<'_, PyModule>) -> PyResult<()> {
///     wp::python::Ops::new(m)?.add(Op::kernel("axpy", axpy).outputs(["y"]).build()?)?;
///     Ok(())
/// }
/// ```
pub struct Ops<'py> {
    module: Bound<'py, PyModule>,
    helper: Bound<'py, PyModule>,
}

impl std::fmt::Debug for Ops<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ops")
            .field("module", &self.module.name().map(|n| n.to_string()).ok())
            .finish()
    }
}

impl<'py> Ops<'py> {
    /// Installs the helper as `m._warp_lang` (also in `sys.modules` under that name).
    ///
    /// # Errors
    /// The interpreter's error if the helper does not compile (a bug of this crate).
    pub fn new(m: &Bound<'py, PyModule>) -> PyResult<Self> {
        let py = m.py();
        let name = m.name()?.to_string();
        let full = CString::new(format!("{name}._warp_lang"))?;
        let code = CString::new(HELPER)?;
        // `Py_CompileString` and `PyImport_ExecCodeModuleEx` are both in the limited API, so
        // this works in an abi3 build.
        let helper = PyModule::from_code(py, &code, c"warp_lang_ops.py", &full)?;
        m.add("_warp_lang", &helper)?;
        // The XLA FFI handlers (`op.jax`), as capsules the helper registers with JAX on first
        // use, under targets named after the module: two extension modules (each with its own
        // registry) stay apart.
        let handlers = PyList::empty(py);
        for h in crate::ops::xla_ffi::handlers() {
            // SAFETY: a NULL-named capsule around the function pointer, what
            // `jax.ffi.register_ffi_target` takes (PyO3's `PyCapsule::new` would point at a
            // boxed value instead); the function lives as long as the process.
            let capsule = unsafe {
                Bound::from_owned_ptr_or_err(
                    py,
                    pyo3::ffi::PyCapsule_New(h.handler as *mut c_void, std::ptr::null(), None),
                )?
            };
            handlers.append((h.target, h.platform, capsule))?;
        }
        helper.setattr("_FFI_PREFIX", format!("warp_lang.{name}"))?;
        helper.setattr("_FFI_HANDLERS", handlers)?;
        // Whether every GPU launch waits for its kernel (`config::debug`, a debug build's
        // default): the tests that prove a call does not wait read it.
        helper.setattr("_DEBUG", crate::config::debug())?;
        Ok(Ops {
            module: m.clone(),
            helper,
        })
    }

    /// Registers `op` ([`crate::ops::register`]) and sets `m.<op name>` to the helper's `Op`.
    ///
    /// # Errors
    /// `ValueError` when the module already has an attribute of the op's name (two ops of one
    /// name, or an op shadowing a function).
    pub fn add(&self, op: Op) -> PyResult<&Self> {
        let py = self.module.py();
        let name = op.name().to_string();
        if self.module.hasattr(name.as_str())? {
            return Err(PyValueError::new_err(format!(
                "op {name}: the module {} already has an attribute '{name}' (two ops of one name?)",
                self.module.name()?
            )));
        }
        let id = crate::ops::register(&op);
        let native = Bound::new(
            py,
            NativeOp {
                op,
                id,
                trace: Mutex::new(Vec::new()),
            },
        )?;
        let wrapped = self.helper.getattr("Op")?.call1((native,))?;
        // `add`, not `setattr`: it also lists the op in the module's `__all__`, which the
        // package maturin wraps an extension in re-exports with `from .<module> import *`.
        self.module.add(name.as_str(), wrapped)?;
        Ok(self)
    }
}

/// The native half of an op as Python sees it: its spec, the shape rules, and the forward and
/// backward on DLPack tensors. Made by [`Ops::add`]; Python code uses the helper's `Op`.
#[pyclass(module = "warp_lang", frozen)]
pub struct NativeOp {
    op: Op,
    id: u64,
    /// `(parameter, address)` of every buffer the last call launched on (`grad:` prefixed for
    /// gradients): the no-copy tests compare them with the tensors' own addresses.
    trace: Mutex<Vec<(String, u64)>>,
}

impl std::fmt::Debug for NativeOp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NativeOp")
            .field("op", &self.op)
            .field("id", &self.id)
            .finish()
    }
}

fn role_name(r: Role) -> &'static str {
    match r {
        Role::Input => "input",
        Role::Output => "output",
        Role::Scalar => "scalar",
        Role::Scratch => "scratch",
    }
}

/// The position of parameter `k` in the Python call (outputs and scratch are not passed).
fn call_position(spec: &OpSpec, k: usize) -> usize {
    spec.params[..k]
        .iter()
        .filter(|p| matches!(p.role, Role::Input | Role::Scalar))
        .count()
}

/// The parameter as a message names it: `'x' (0)` for a call argument, `output 'e'` else.
fn param_label(spec: &OpSpec, k: usize) -> String {
    let p = &spec.params[k];
    match p.role {
        Role::Input | Role::Scalar => format!("argument '{}' ({})", p.name, call_position(spec, k)),
        Role::Output => format!("output '{}'", p.name),
        Role::Scratch => format!("scratch '{}'", p.name),
    }
}

fn dtype_of_dlpack(t: DLDataType) -> Option<Dtype> {
    if t.lanes != 1 {
        return None;
    }
    let table = [
        (DLDataType::BOOL, Dtype::Bool),
        (DLDataType::I8, Dtype::I8),
        (DLDataType::I16, Dtype::I16),
        (DLDataType::I32, Dtype::I32),
        (DLDataType::I64, Dtype::I64),
        (DLDataType::U8, Dtype::U8),
        (DLDataType::U16, Dtype::U16),
        (DLDataType::U32, Dtype::U32),
        (DLDataType::U64, Dtype::U64),
        (DLDataType::F16, Dtype::F16),
        (DLDataType::BF16, Dtype::Bf16),
        (DLDataType::F32, Dtype::F32),
        (DLDataType::F64, Dtype::F64),
    ];
    table
        .iter()
        .find(|(d, _)| d.matches(t))
        .map(|(_, dtype)| *dtype)
}

/// The stream an op's tensors are imported on: the one it launches on (the caller's), so the
/// producer orders nothing; CPU tensors get none.
struct CallStream {
    raw: Option<usize>,
}

// SAFETY: `raw` is a live CUDA stream handle of the tensors' device (the caller's stream, or
// this crate's), encoded by CUDA's DLPack convention; CPU tensors get none.
unsafe impl DlpackStream for CallStream {
    fn as_python_arg(&self, _py: Python<'_>, device: DLDevice) -> PyResult<StreamArg> {
        Ok(match (self.raw, device.device_type.0) {
            // The legacy default stream is `1` in DLPack's convention.
            (Some(raw), 2) => dlstream::cuda(if raw == 0 { 1 } else { raw } as *mut c_void),
            _ => dlstream::none(),
        })
    }

    unsafe fn wait_for_producer(&self, device: DLDevice, producer: *mut c_void) -> PyResult<bool> {
        #[cfg(feature = "cuda")]
        if let Some(raw) = self.raw {
            if producer as usize == raw {
                return Ok(true);
            }
            let device = crate::array::device_of_dlpack("op", device)?;
            // SAFETY: both are live streams of the device (the caller's contract and the
            // exchange API's).
            let ours = unsafe { stream_from_handle(raw, &device)? };
            let theirs = unsafe { stream_from_handle(producer as usize, &device)? };
            ours.wait_stream(&theirs)?;
            return Ok(true);
        }
        let _ = (device, producer);
        Ok(false)
    }
}

/// One imported tensor: the descriptor (kept until the call ends: its deleter releases the
/// producer's buffer) and the buffer read from it.
struct Imported {
    _tensor: ImportedDlpack,
    buffer: Buffer,
}

/// The tensors of a call before import: each with its DLPack device.
struct Pending<'py> {
    k: usize,
    request: ImportRequest<'py>,
    device: DLDevice,
    grad: bool,
}

fn dl_device_name(d: DLDevice) -> String {
    match d.device_type.0 {
        1 => "cpu".to_string(),
        2 => format!("cuda:{}", d.device_id),
        t => format!("DLPack device type {t}:{}", d.device_id),
    }
}

impl NativeOp {
    /// Reads a tensor's DLPack device, with the op and parameter in the error.
    fn request<'py>(
        &self,
        obj: &Bound<'py, PyAny>,
        k: usize,
        grad: bool,
    ) -> PyResult<Pending<'py>> {
        let spec = self.op.spec();
        let what = || {
            let label = param_label(spec, k);
            if grad {
                format!("{}: the gradient of {label}", spec.name)
            } else {
                format!("{}: {label}", spec.name)
            }
        };
        let request = ImportRequest::new(obj.as_borrowed()).map_err(|e| {
            PyTypeError::new_err(format!(
                "{}: a {} (no __dlpack__: {e}); the kernel takes {}",
                what(),
                obj.get_type()
                    .name()
                    .map(|n| n.to_string())
                    .unwrap_or_default(),
                spec.params[k].kind.describe()
            ))
        })?;
        let device = request.device().map_err(|e| {
            PyTypeError::new_err(format!(
                "{}: a DLPack capsule or a producer without __dlpack_device__ ({e}); pass the \
                 tensor itself",
                what()
            ))
        })?;
        Ok(Pending {
            k,
            request,
            device,
            grad,
        })
    }

    /// Imports `p` on `stream` and checks its dtype against the spec (a `TypeError` naming
    /// op, parameter and both types; shapes are checked by the op, as `ValueError`s).
    fn import(&self, py: Python<'_>, p: Pending<'_>, stream: &CallStream) -> PyResult<Imported> {
        let spec = self.op.spec();
        let param = &spec.params[p.k];
        let label = match p.grad {
            true => format!("the gradient of {}", param_label(spec, p.k)),
            false => param_label(spec, p.k),
        };
        let tensor = p.request.import(Some(stream), None).map_err(|e| {
            let msg = format!("{}: {label}: the DLPack import failed: {e}", spec.name);
            if e.is_instance_of::<PyTypeError>(py) {
                PyTypeError::new_err(msg)
            } else {
                PyValueError::new_err(msg)
            }
        })?;
        if tensor.flags().contains(DlpackFlags::READ_ONLY) {
            return Err(PyValueError::new_err(format!(
                "{}: {label}: a read-only tensor; the op writes its outputs and gradients and \
                 takes writable inputs (pass a copy)",
                spec.name
            )));
        }
        let t = tensor.validate().map_err(|e| {
            PyValueError::new_err(format!(
                "{}: {label}: invalid DLPack tensor: {e}",
                spec.name
            ))
        })?;
        let (want, describe) = match param.kind {
            ArgKind::Array { dtype, .. } => (dtype, param.kind.describe()),
            ArgKind::Value { .. } => unreachable!("only arrays are imported"),
        };
        let dtype = dtype_of_dlpack(t.dtype());
        if dtype != Some(want) {
            let given = dtype.map(|d| d.name().to_string()).unwrap_or_else(|| {
                format!(
                    "DLPack type {:?} of {} bits x {}",
                    t.dtype().code,
                    t.dtype().bits,
                    t.dtype().lanes
                )
            });
            return Err(PyTypeError::new_err(format!(
                "{}: {label}: a {given} tensor; the kernel takes {describe}",
                spec.name
            )));
        }
        let dims: Vec<usize> = t.shape().iter().map(|&d| d as usize).collect();
        let size = want.size() as isize;
        let byte_strides = t
            .strides()
            .map(|s| s.iter().map(|&s| s as isize * size).collect::<Vec<_>>());
        let ptr = (t.data_ptr() as u64).wrapping_add(t.byte_offset());
        let buffer = Buffer {
            ptr,
            dims,
            byte_strides,
            dtype: want,
        };
        Ok(Imported {
            _tensor: tensor,
            buffer,
        })
    }

    /// Imports every tensor of a call (`args` aligned with the parameters; `grads` too when
    /// given), after checking they are on one device. Returns the device, the imports by
    /// parameter and the gradients' by parameter.
    fn import_all(
        &self,
        py: Python<'_>,
        stream: Option<usize>,
        args: &Bound<'_, PyList>,
        grads: Option<&Bound<'_, PyList>>,
    ) -> PyResult<CallBuffers> {
        let spec = self.op.spec();
        let n = spec.params.len();
        if args.len() != n || grads.is_some_and(|g| g.len() != n) {
            return Err(PyTypeError::new_err(format!(
                "{}: the native call takes {n} arguments and gradient slots (one per parameter: \
                 {}); got {} and {}",
                spec.name,
                spec.params
                    .iter()
                    .map(|p| p.name)
                    .collect::<Vec<_>>()
                    .join(", "),
                args.len(),
                grads.map(|g| g.len()).unwrap_or(n)
            )));
        }
        let mut pending = Vec::new();
        let mut values: Vec<Given> = vec![Given::None; n];
        for (k, p) in spec.params.iter().enumerate() {
            let a = args.get_item(k)?;
            match p.role {
                Role::Scalar => values[k] = self.value(&a, k)?,
                _ => pending.push(self.request(&a, k, false)?),
            }
            if let Some(g) = grads {
                let g = g.get_item(k)?;
                if !g.is_none() {
                    if !p.differentiable {
                        return Err(PyValueError::new_err(format!(
                            "{}: {} ({}) has no gradient, and one was given",
                            spec.name,
                            param_label(spec, k),
                            p.kind.describe()
                        )));
                    }
                    pending.push(self.request(&g, k, true)?);
                }
            }
        }
        let first = pending.first().ok_or_else(|| {
            PyValueError::new_err(format!("{}: the call has no array", spec.name))
        })?;
        let (d0, k0) = (first.device, first.k);
        if let Some(other) = pending.iter().find(|p| {
            p.device.device_type.0 != d0.device_type.0 || p.device.device_id != d0.device_id
        }) {
            return Err(PyValueError::new_err(format!(
                "{}: '{}' is on {}, '{}' on {}",
                spec.name,
                spec.params[k0].name,
                dl_device_name(d0),
                spec.params[other.k].name,
                dl_device_name(other.device)
            )));
        }
        let device = crate::array::device_of_dlpack(&spec.name, d0)?;
        let stream = match device.kind() {
            DeviceKind::Cpu => None,
            DeviceKind::Cuda { .. } => match stream {
                Some(s) => Some(s),
                #[cfg(feature = "cuda")]
                None => Some(
                    crate::stream::get_stream(&device)?
                        .cuda_stream()
                        .cu_stream() as usize,
                ),
                #[cfg(not(feature = "cuda"))]
                None => None,
            },
        };
        let call_stream = CallStream { raw: stream };
        let mut buffers: Vec<Option<Buffer>> = vec![None; n];
        let mut grad_buffers: Vec<Option<Buffer>> = vec![None; n];
        let mut keep = Vec::with_capacity(pending.len());
        let mut trace = Vec::with_capacity(pending.len());
        for p in pending {
            let (k, grad) = (p.k, p.grad);
            let imported = self.import(py, p, &call_stream)?;
            let name = spec.params[k].name;
            trace.push((
                if grad {
                    format!("grad:{name}")
                } else {
                    name.to_string()
                },
                imported.buffer.ptr,
            ));
            match grad {
                true => grad_buffers[k] = Some(imported.buffer.clone()),
                false => buffers[k] = Some(imported.buffer.clone()),
            }
            keep.push(imported);
        }
        *self.trace.lock().unwrap_or_else(|p| p.into_inner()) = trace;
        Ok(CallBuffers {
            device,
            stream: call_stream.raw,
            buffers,
            grads: grad_buffers,
            values,
            _keep: keep,
        })
    }

    /// The value of value parameter `k`: a Python number for a scalar, a sequence of them
    /// (nested as the component axes, or flat; a NumPy array) for a vector, quaternion or
    /// matrix (each number range-checked by the op).
    fn value(&self, v: &Bound<'_, PyAny>, k: usize) -> PyResult<Given> {
        let spec = self.op.spec();
        let ArgKind::Value { element, .. } = spec.params[k].kind else {
            unreachable!("only value parameters have values")
        };
        if element.is_empty() {
            return Ok(Given::One(self.number(v, k)?));
        }
        let count: usize = element.iter().product();
        let mut leaves = Vec::with_capacity(count);
        self.components(v, k, &mut leaves, 0)?;
        if leaves.len() != count {
            return Err(PyValueError::new_err(format!(
                "{}: {}: {} number{}; the kernel takes {} ({count} numbers, nested as {:?} or \
                 flat)",
                spec.name,
                param_label(spec, k),
                leaves.len(),
                if leaves.len() == 1 { "" } else { "s" },
                spec.params[k].kind.describe(),
                element
            )));
        }
        Ok(Given::Components(leaves))
    }

    /// The numbers of `v` (a number, or a sequence of sequences..) into `out`, in order.
    fn components(
        &self,
        v: &Bound<'_, PyAny>,
        k: usize,
        out: &mut Vec<Value>,
        depth: usize,
    ) -> PyResult<()> {
        // A NumPy array as nested lists of Python numbers.
        if v.hasattr("tolist")? && v.hasattr("ndim")? {
            return self.components(&v.call_method0("tolist")?, k, out, depth);
        }
        if depth < 3 && (v.is_instance_of::<PyList>() || v.is_instance_of::<PyTuple>()) {
            for item in v.try_iter()? {
                self.components(&item?, k, out, depth + 1)?;
            }
            return Ok(());
        }
        out.push(self.number(v, k)?);
        Ok(())
    }

    /// A Python number as a value of parameter `k`'s scalar type (range-checked by the op).
    fn number(&self, v: &Bound<'_, PyAny>, k: usize) -> PyResult<Value> {
        let spec = self.op.spec();
        if v.is_instance_of::<PyBool>() {
            return Ok(Value::Bool(v.extract()?));
        }
        if v.is_instance_of::<PyFloat>() {
            return Ok(Value::Float(v.extract()?));
        }
        // Integers, and integer-like objects (NumPy's integer scalars: `__index__`).
        if let Ok(i) = v.extract::<i64>() {
            return Ok(Value::Int(i));
        }
        // Float-like objects (NumPy's float32 scalar: `__float__`), unless array-like.
        if !v.hasattr("__dlpack__")? && !v.hasattr("__len__")? {
            if let Ok(x) = v.extract::<f64>() {
                return Ok(Value::Float(x));
            }
        }
        Err(PyTypeError::new_err(format!(
            "{}: {}: a {}; the kernel takes {} (a Python number)",
            spec.name,
            param_label(spec, k),
            v.get_type()
                .name()
                .map(|n| n.to_string())
                .unwrap_or_default(),
            spec.params[k].kind.describe()
        )))
    }

    /// Runs `f` with the call's [`Exec`], the GIL released; on a stream this crate chose (no
    /// caller stream), waits for the launches before returning.
    fn launch(
        &self,
        py: Python<'_>,
        call: &CallBuffers,
        caller_stream: bool,
        f: impl FnOnce(&Op, &[CallArg<'_>], &Exec<'_>) -> crate::Result<()> + Send,
    ) -> PyResult<()> {
        let args = call_args(&call.buffers, &call.values);
        let op = &self.op;
        match (call.device.kind(), call.stream) {
            (DeviceKind::Cpu, _) | (DeviceKind::Cuda { .. }, None) => {
                let exec = Exec::cpu();
                let _ = caller_stream;
                if !matches!(call.device.kind(), DeviceKind::Cpu) {
                    return Err(pyo3::exceptions::PyRuntimeError::new_err(format!(
                        "{}: CUDA tensors need warp-lang's `cuda` feature",
                        op.name()
                    )));
                }
                py.detach(|| f(op, &args, &exec))?;
            }
            #[cfg(feature = "cuda")]
            (DeviceKind::Cuda { .. }, Some(raw)) => {
                let device = &call.device;
                // SAFETY: `raw` is the caller's live stream of the tensors' device (the
                // helper reads torch's current stream of that device).
                let stream = unsafe {
                    match (caller_stream, op.is_computation()) {
                        // No caller stream: this crate's, in its ordered mode, waited for below.
                        (false, _) => crate::stream::get_stream(device)?,
                        // A body's array operations run on this crate's default stream: the
                        // scoped mode joins the two.
                        (true, true) => stream_from_handle(raw, device)?,
                        // A kernel op: one launch on the caller's stream, joined with nothing
                        // (every buffer is the caller's), so also capturable by the caller.
                        (true, false) => crate::stream::Stream::from_raw_caller_ordered(
                            if raw == 0 { 1 } else { raw } as *mut c_void,
                            device,
                        )?,
                    }
                };
                let exec = Exec::stream(&stream);
                py.detach(|| -> crate::Result<()> {
                    f(op, &args, &exec)?;
                    if !caller_stream {
                        stream.synchronize()?;
                    }
                    Ok(())
                })?;
            }
            #[cfg(not(feature = "cuda"))]
            (DeviceKind::Cuda { .. }, Some(_)) => unreachable!("no CUDA device without `cuda`"),
        }
        Ok(())
    }
}

/// A call's arguments in parameter order: each array's buffer, each value as given.
fn call_args<'a>(buffers: &'a [Option<Buffer>], values: &'a [Given]) -> Vec<CallArg<'a>> {
    buffers
        .iter()
        .zip(values)
        .map(|(b, v)| match b {
            Some(b) => CallArg::Buffer(b),
            None => v.arg(),
        })
        .collect()
}

/// A call's imported tensors (kept alive until the call returns) and values.
struct CallBuffers {
    device: Device,
    stream: Option<usize>,
    buffers: Vec<Option<Buffer>>,
    grads: Vec<Option<Buffer>>,
    values: Vec<Given>,
    _keep: Vec<Imported>,
}

#[pymethods]
impl NativeOp {
    /// The op's name.
    #[getter]
    fn name(&self) -> &str {
        self.op.name()
    }

    /// The id in the process-wide registry.
    #[getter]
    fn id(&self) -> u64 {
        self.id
    }

    /// `"kernel"` or `"computation"`.
    #[getter]
    fn kind(&self) -> &'static str {
        match self.op.is_computation() {
            true => "computation",
            false => "kernel",
        }
    }

    /// The spec as plain Python data: `{'name', 'kind', 'params': [{'name', 'role', 'dtype',
    /// 'rank', 'element', 'type', 'differentiable', 'zeroed'}]}` (rank 0 and no element for a
    /// scalar).
    #[getter]
    fn spec<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let spec = self.op.spec();
        let d = PyDict::new(py);
        d.set_item("name", &spec.name)?;
        d.set_item("kind", self.kind())?;
        let params = PyList::empty(py);
        for p in &spec.params {
            let e = PyDict::new(py);
            e.set_item("name", p.name)?;
            e.set_item("role", role_name(p.role))?;
            match p.kind {
                ArgKind::Array {
                    dtype,
                    rank,
                    element,
                    type_name,
                } => {
                    e.set_item("dtype", dtype.name())?;
                    e.set_item("rank", rank)?;
                    e.set_item("element", element.to_vec())?;
                    e.set_item("type", format!("Array<{type_name}, {rank}>"))?;
                }
                ArgKind::Value {
                    dtype,
                    element,
                    type_name,
                } => {
                    e.set_item("dtype", dtype.name())?;
                    e.set_item("rank", 0)?;
                    e.set_item("element", element.to_vec())?;
                    e.set_item(
                        "type",
                        match element {
                            [] => dtype.name(),
                            _ => type_name,
                        },
                    )?;
                }
            }
            e.set_item("describe", p.kind.describe())?;
            e.set_item("differentiable", p.differentiable)?;
            e.set_item("zeroed", p.zeroed)?;
            params.append(e)?;
        }
        d.set_item("params", params)?;
        Ok(d)
    }

    /// The launch dimensions and the leading shape of each output and scratch array (in
    /// parameter order) for a call whose inputs have `shapes` (full shapes, trailing axes
    /// included; `None` for outputs and scratch) and whose scalars are `values` (aligned with
    /// the parameters; `None` for arrays). Device-free.
    fn _shapes(
        &self,
        shapes: Vec<Option<Vec<usize>>>,
        values: &Bound<'_, PyList>,
    ) -> PyResult<(Vec<usize>, Vec<Vec<usize>>)> {
        let spec = self.op.spec();
        let n = spec.params.len();
        if shapes.len() != n || values.len() != n {
            return Err(PyTypeError::new_err(format!(
                "{}: _shapes takes {n} shapes and {n} values",
                spec.name
            )));
        }
        let mut buffers: Vec<Option<Buffer>> = vec![None; n];
        let mut vals: Vec<Given> = vec![Given::None; n];
        for (k, p) in spec.params.iter().enumerate() {
            match (p.role, p.kind) {
                (Role::Scalar, _) => vals[k] = self.value(&values.get_item(k)?, k)?,
                (Role::Input, ArgKind::Array { dtype, .. }) => {
                    let dims = shapes[k].clone().ok_or_else(|| {
                        PyValueError::new_err(format!(
                            "{}: {}: no shape given",
                            spec.name,
                            param_label(spec, k)
                        ))
                    })?;
                    buffers[k] = Some(Buffer::contiguous(0, &dims, dtype));
                }
                _ => {}
            }
        }
        // Rank and trailing axes first, so that a wrong shape is named before a rule reads it.
        for (k, p) in spec.params.iter().enumerate() {
            if let (Some(b), ArgKind::Array { rank, element, .. }) = (&buffers[k], p.kind) {
                if b.dims.len() != rank + element.len() || b.dims[rank..] != *element {
                    let mut want: Vec<String> = (0..rank).map(|d| format!("d{d}")).collect();
                    want.extend(element.iter().map(|e| e.to_string()));
                    return Err(PyValueError::new_err(format!(
                        "{}: {}: shape {:?}; {} needs ({})",
                        spec.name,
                        param_label(spec, k),
                        b.dims,
                        p.kind.describe(),
                        want.join(", ")
                    )));
                }
            }
        }
        Ok(self.op.shapes(&call_args(&buffers, &vals))?)
    }

    /// The forward: `args` aligned with the parameters (a `__dlpack__` object for each array,
    /// outputs and scratch included, allocated by the caller; a number for each scalar).
    /// `stream`: the CUDA stream handle to launch on (torch's current stream), or `None`
    /// (the CPU; on a GPU, this crate's stream, waited for before returning).
    #[pyo3(signature = (stream, args))]
    fn _forward(
        &self,
        py: Python<'_>,
        stream: Option<usize>,
        args: &Bound<'_, PyList>,
    ) -> PyResult<()> {
        let call = self.import_all(py, stream, args, None)?;
        // SAFETY: every buffer is a live tensor of the call's device, kept alive by its DLPack
        // descriptor until this returns, imported on the launch stream.
        self.launch(py, &call, stream.is_some(), |op, a, e| unsafe {
            op.forward(a, e)
        })
    }

    /// The backward: `args` as for `_forward` (the forward's inputs and, for a kernel op, its
    /// outputs; for a computation op fresh zeroed outputs and scratch), `grads` aligned with
    /// the parameters: zeroed input-gradient tensors, copies of the output gradients (read
    /// and cleared), `None` where no gradient is wanted.
    #[pyo3(signature = (stream, args, grads))]
    fn _backward(
        &self,
        py: Python<'_>,
        stream: Option<usize>,
        args: &Bound<'_, PyList>,
        grads: &Bound<'_, PyList>,
    ) -> PyResult<()> {
        let call = self.import_all(py, stream, args, Some(grads))?;
        let g: Vec<Option<&Buffer>> = call.grads.iter().map(|g| g.as_ref()).collect();
        // SAFETY: as `_forward`, for the gradients too.
        self.launch(py, &call, stream.is_some(), move |op, a, e| unsafe {
            op.backward(a, &g, e)
        })
    }

    /// The operands and results of the op's XLA FFI call in `direction` (`"fwd"` or `"bwd"`),
    /// each `(slot, parameter position)`, slot one of `value`, `cotangent`, `grad`,
    /// `cotangent_copy`, `replay` ([`layout`](crate::ops::xla_ffi::layout)).
    #[allow(clippy::type_complexity)]
    fn _layout(
        &self,
        direction: &str,
    ) -> PyResult<(Vec<(&'static str, usize)>, Vec<(&'static str, usize)>)> {
        use crate::ops::xla_ffi::{layout, Direction, Slot};
        let dir = match direction {
            "fwd" => Direction::Forward,
            "bwd" => Direction::Backward,
            d => {
                return Err(PyValueError::new_err(format!(
                    "{}: _layout takes 'fwd' or 'bwd', not {d:?}",
                    self.op.name()
                )))
            }
        };
        let name = |s: &Slot| match *s {
            Slot::Value(k) => ("value", k),
            Slot::Cotangent(k) => ("cotangent", k),
            Slot::Grad(k) => ("grad", k),
            Slot::CotangentCopy(k) => ("cotangent_copy", k),
            Slot::Replay(k) => ("replay", k),
        };
        let l = layout(&self.op, dir);
        Ok((
            l.operands.iter().map(name).collect(),
            l.results.iter().map(name).collect(),
        ))
    }

    /// Readies the op for calls on GPU `ordinal` from threads that may be capturing
    /// ([`Op::prepare`]: the kernel and its adjoint loaded, `threads` spare fault records);
    /// `None`: the CPU, nothing to do. The helper calls it when JAX traces the op.
    #[pyo3(signature = (ordinal, threads = 8))]
    fn _prepare(&self, py: Python<'_>, ordinal: Option<usize>, threads: usize) -> PyResult<()> {
        let Some(ordinal) = ordinal else {
            return Ok(());
        };
        let device = crate::device::get_device(&format!("cuda:{ordinal}"))?;
        py.detach(|| self.op.prepare(&device, threads))?;
        Ok(())
    }

    /// `[(parameter, address)]` of every buffer the last call on this op launched on
    /// (`grad:<name>` for gradients): what the no-copy tests compare with `data_ptr()`.
    fn _trace_addresses(&self) -> Vec<(String, u64)> {
        self.trace.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    fn __repr__(&self) -> String {
        format!("NativeOp({}, id={})", self.op.name(), self.id)
    }
}

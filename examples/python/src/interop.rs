//! The interop half of `warp_sim` (what the `warp_torch` example had): tensors come in
//! through DLPack without a copy (`wp::python::from_dlpack`), kernels run on them in place, and
//! arrays go back without a copy (`wp::python::to_dlpack`, which `torch.from_dlpack` takes).
//! `energy_forward` and the `backward` of the handle it returns, which records the kernel on a
//! Tape and runs its adjoint, are the two halves of a hand-written `torch.autograd.Function`
//! (test_warp_torch.py has it, checked by `torch.autograd.gradcheck`); the `energy` op
//! (lib.rs) is the same kernel made an op in one line.
//!
//! Streams: each function takes an optional `stream`, a CUDA stream handle
//! (`torch.cuda.current_stream().cuda_stream`). Given one, the kernels run on it, in order with
//! the framework's work both ways and without blocking the host. Without one they run on
//! warp-lang's stream: the import is ordered by the DLPack protocol, and the function waits for
//! its kernels before returning, so that the caller's next read sees their writes.

use pyo3::prelude::*;
use warp_lang as wp;
use wp::prelude::*;

/// One explicit Euler step of particles under gravity, in place: `v += g dt; x += v dt`.
#[wp::kernel]
fn integrate(x: Array<Vec3>, v: Array<Vec3>, gravity: Vec3, dt: f32) {
    let i = tid();
    v[i] += gravity * dt;
    x[i] += v[i] * dt;
}

/// `out[i] = start + i * step`.
#[wp::kernel]
fn fill_ramp(out: Array<f32>, start: f32, step: f32) {
    let i = tid();
    out[i] = start + i as f32 * step;
}

/// A per-particle energy, smooth and non-linear in every coordinate: a spring to the origin
/// of stiffness `k` and a coupling `sin(x) y + z³/3`.
#[wp::kernel]
pub(crate) fn energy(x: Array<DVec3>, k: f64, e: Array<f64>) {
    let i = tid();
    let p = x[i];
    e[i] = 0.5 * k * dot(p, p) + sin(p.x) * p.y + p.z * p.z * p.z / 3.0;
}

/// Runs `work` with warp-lang's launches on `device` queued on the caller's stream when one is
/// given; otherwise on warp-lang's stream, then waits for them.
fn on_stream<R>(
    device: &wp::Device,
    stream: Option<usize>,
    work: impl FnOnce() -> PyResult<R>,
) -> PyResult<R> {
    if device.is_cpu() {
        return work();
    }
    match stream {
        Some(handle) => {
            // SAFETY: the caller passes a live stream of this device (PyTorch's current).
            let s = unsafe { wp::python::stream_from_handle(handle, device)? };
            let _scope = wp::ScopedStream::new(&s)?;
            work()
        }
        None => {
            let r = work()?;
            wp::get_stream(device)?.synchronize()?;
            Ok(r)
        }
    }
}

/// `integrate_(x, v, dt, stream=None)`: `x` and `v` are float32 tensors of shape `(n, 3)` on
/// one device; both are updated in place.
#[pyfunction]
#[pyo3(signature = (x, v, dt, stream = None))]
fn integrate_(
    x: &Bound<'_, PyAny>,
    v: &Bound<'_, PyAny>,
    dt: f32,
    stream: Option<usize>,
) -> PyResult<()> {
    let x: wp::Array<Vec3> = wp::python::from_dlpack(x)?;
    let v: wp::Array<Vec3> = wp::python::from_dlpack(v)?;
    let device = x.device().clone();
    on_stream(&device, stream, || {
        let g = Vec3::new(0.0, 0.0, -9.81);
        wp::launch(integrate, x.len(), (&x, &v, g, dt), &device)?;
        Ok(())
    })
}

/// `ramp(n, start, step, device)`: a new float32 array made by a kernel on `device` (`"cpu"`,
/// `"cuda:0"`), handed to Python without a copy.
#[pyfunction]
#[pyo3(signature = (n, start, step, device, stream = None))]
fn ramp<'py>(
    py: Python<'py>,
    n: usize,
    start: f32,
    step: f32,
    device: &str,
    stream: Option<usize>,
) -> PyResult<Bound<'py, wp::python::DlpackArray>> {
    let device = wp::get_device(device)?;
    let out = on_stream(&device, stream, || {
        let out = wp::Array::<f32>::zeros(n, &device)?;
        wp::launch(fill_ramp, n, (&out, start, step), &device)?;
        Ok(out)
    })?;
    wp::python::to_dlpack(py, &out)
}

/// `as_vec3(t)`: the tensor taken as an array of `Vec3` and handed back: the same memory both
/// ways (the round trip that proves it).
#[pyfunction]
fn as_vec3<'py>(
    py: Python<'py>,
    t: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, wp::python::DlpackArray>> {
    let a: wp::Array<Vec3> = wp::python::from_dlpack(t)?;
    wp::python::to_dlpack(py, &a)
}

/// What the backward pass of `energy` needs: the input (with a gradient) and the parameter.
///
/// PyTorch runs backward on its own threads (one per device), and a [`wp::Tape`] records the
/// launches of the thread it was made on and stays there (it is not `Send`). So the forward
/// pass runs bare, and `backward` records it again on a tape of the calling thread (one more
/// forward launch) and runs the tape's adjoints: the tape lives and dies within one call.
#[pyclass]
struct EnergyTape {
    x: wp::Array<DVec3>,
    k: f64,
    stream: Option<usize>,
}

/// `energy_forward(x, k, stream=None) -> (e, tape)`: per-particle energies of the float64
/// `(n, 3)` tensor `x` (detached: DLPack does not export tensors that require grad), and the
/// handle for `tape.backward(grad_e)`.
#[pyfunction]
#[pyo3(signature = (x, k, stream = None))]
fn energy_forward<'py>(
    py: Python<'py>,
    x: &Bound<'py, PyAny>,
    k: f64,
    stream: Option<usize>,
) -> PyResult<(Bound<'py, wp::python::DlpackArray>, EnergyTape)> {
    let x: wp::Array<DVec3> = wp::python::from_dlpack(x)?;
    let device = x.device().clone();
    let e = on_stream(&device, stream, || {
        let e = wp::Array::<f64>::zeros(x.len(), &device)?;
        wp::launch(energy, x.len(), (&x, k, &e), &device)?;
        Ok(e)
    })?;
    let out = wp::python::to_dlpack(py, &e)?;
    Ok((out, EnergyTape { x, k, stream }))
}

#[pymethods]
impl EnergyTape {
    /// The vector-Jacobian product: `grad_x = (de/dx)ᵀ grad_e`, a new float64 `(n, 3)` array.
    /// May be called again with another `grad_e` (gradcheck does): each call starts from zero.
    fn backward<'py>(
        &self,
        py: Python<'py>,
        grad_e: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, wp::python::DlpackArray>> {
        let g: wp::Array<f64> = wp::python::from_dlpack(grad_e)?;
        let device = self.x.device().clone();
        let n = self.x.len();
        let gx = on_stream(&device, self.stream, || {
            // A fresh gradient for x (the memory stays PyTorch's), and the forward recorded.
            let x = self.x.clone().with_grad()?;
            let e = wp::Array::<f64>::zeros(n, &device)?.with_grad()?;
            let tape = wp::Tape::new();
            {
                let _rec = tape.record();
                wp::launch(energy, n, (&x, self.k, &e), &device)?;
            }
            let no_grad = || pyo3::exceptions::PyRuntimeError::new_err("no gradient");
            let e_grad = e.grad().ok_or_else(no_grad)?;
            let x_grad = x.grad().ok_or_else(no_grad)?;
            e_grad.copy_from(&g)?;
            tape.backward_from_grads()?;
            Ok(x_grad)
        })?;
        wp::python::to_dlpack(py, &gx)
    }
}

/// Adds the interop functions to the module.
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(integrate_, m)?)?;
    m.add_function(wrap_pyfunction!(ramp, m)?)?;
    m.add_function(wrap_pyfunction!(as_vec3, m)?)?;
    m.add_function(wrap_pyfunction!(energy_forward, m)?)?;
    m.add_class::<EnergyTape>()?;
    m.add_class::<wp::python::DlpackArray>()?;
    Ok(())
}

//! The bouncing balls of the Rust `bounce` example as a computation op, and that example's own
//! tape gradient beside it, so that Python can check the op's gradients against pure Rust and
//! train a network through the simulation (train_bounce.py).
//!
//! - `bounce(v0) -> x_final`: launch velocities `(n, 2)` float64 to positions `(n, 2)` after
//!   the scene's 100 steps of 10 ms with the time-of-impact contact (`Contact::Toi`), each ball
//!   launched from the scene's start point. The trajectory is the op's scratch, so its backward
//!   replays the body under a tape (a computation op) and the gradient passes every bounce.
//! - `bounce_reference_gradient(v0, target) -> (loss, dloss/dv0)`: `Balls::gradient`, the Rust
//!   example's tape path, with loss `sum |x_final - target|^2`, on the arrays' device (any
//!   DLPack producer: NumPy, or torch on the CPU or a GPU).
//!
//! Both run the same kernels (`step_toi`) in the same order on the scene's constants
//! (`Setup::default()`), so their gradients agree to rounding of the loss's seed alone.

#[path = "../../common/bounce.rs"]
mod scene;

use std::sync::Arc;

use pyo3::prelude::*;
use scene::{step_toi, Balls, Contact, Setup, GRAVITY};
use warp_lang as wp;
use wp::ops::{Ctx, Op, Shape};
use wp::prelude::*;

/// Each ball's state at launch: at `start`, moving at `v0[i]` (a kernel rather than a copy and
/// a fill, so that one launch sets both and the tape carries the gradient to `v0`).
#[wp::kernel]
fn launch_state(v0: Array<DVec2>, start: DVec2, x: Array<DVec2>, v: Array<DVec2>) {
    let i = tid();
    x[i] = start;
    v[i] = v0[i];
}

/// The op's body: the trajectory into the scratch `xs` / `vs` (one row per step), then its
/// last positions into the output.
fn body(c: &mut Ctx<'_>) -> wp::Result<()> {
    let s = Setup::default();
    let v0 = c.input::<DVec2, 1>("v0")?;
    let (xs, vs) = (c.scratch::<DVec2, 2>("xs")?, c.scratch::<DVec2, 2>("vs")?);
    let out = c.output::<DVec2, 1>("x_final")?;
    let (n, dev) = (v0.len(), c.device());
    let g = DVec2::new(0.0, GRAVITY);
    wp::launch(
        launch_state,
        n,
        (v0, s.start, &xs.row(0)?, &vs.row(0)?),
        dev,
    )?;
    for k in 0..s.steps {
        let (xa, va, xb, vb) = (xs.row(k)?, vs.row(k)?, xs.row(k + 1)?, vs.row(k + 1)?);
        let args = (&xa, &va, &xb, &vb, g, s.radius, s.restitution, s.dt);
        wp::launch(step_toi, n, args, dev)?;
    }
    // Recorded: the backward adds the output's gradient into the last row's.
    wp::copy(out, &xs.row(s.steps)?)
}

/// The op `bounce`.
pub(crate) fn op() -> wp::Result<Op> {
    // Every state of the trajectory: (steps + 1, balls).
    let states = || {
        Shape::Fn(Arc::new(|s| {
            Ok(vec![Setup::default().steps + 1, s.len("v0")?])
        }))
    };
    Op::computation("bounce", body)
        .input::<DVec2, 1>("v0")
        .scratch::<DVec2, 2>("xs", states())
        .scratch::<DVec2, 2>("vs", states())
        .output::<DVec2, 1>("x_final", Shape::Like("v0"))
        .build()
}

/// `bounce_reference_gradient(v0, target, device=None) -> (loss, grad)`: the Rust example's
/// tape gradient (`Balls::gradient(Contact::Toi)`) of `sum |x_final - target|^2` at launch
/// velocities `v0`, both float64 `(n, 2)` on one device (any DLPack producer). It runs on
/// `device` (`"cpu"`, `"cuda:0"`) when given, else on the arrays'; `grad` (`(n, 2)`, on that
/// device) is a DLPack array (`np.from_dlpack`, `torch.from_dlpack`).
#[pyfunction]
#[pyo3(signature = (v0, target, device = None))]
fn bounce_reference_gradient<'py>(
    py: Python<'py>,
    v0: &Bound<'py, PyAny>,
    target: &Bound<'py, PyAny>,
    device: Option<&str>,
) -> PyResult<(f64, Bound<'py, wp::python::DlpackArray>)> {
    let v0: wp::Array<DVec2> = wp::python::from_dlpack(v0)?;
    let target: wp::Array<DVec2> = wp::python::from_dlpack(target)?;
    if target.device() != v0.device() {
        return Err(wp::Error::InvalidArgument {
            what: format!(
                "bounce_reference_gradient: v0 is on {}, target on {}",
                v0.device().name(),
                target.device().name()
            ),
        }
        .into());
    }
    let dev = match device {
        Some(d) => wp::get_device(d)?,
        None => v0.device().clone(),
    };
    let balls = Balls::new(Setup::default(), &v0.to_vec()?, &target.to_vec()?, &dev)?;
    let (loss, grad) = balls.gradient(Contact::Toi, &dev)?;
    wp::python::to_dlpack(py, &wp::Array::from_slice(&grad, &dev)?).map(|g| (loss, g))
}

/// Adds `bounce_reference_gradient` to the module (the op is added with the others).
pub(crate) fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(bounce_reference_gradient, m)?)?;
    Ok(())
}

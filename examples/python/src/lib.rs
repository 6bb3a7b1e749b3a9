//! `warp_sim`: a Python extension module written with warp-lang (see Cargo.toml for the build
//! commands).
//!
//! - **Ops** (`wp::python::Ops`): kernels made Python callables in one line each. `energy`
//!   (float64, a kernel op: per-particle energies of `(n, 3)` positions) and `axpy` (float32,
//!   `out = a x + y`). Each is `ws.energy.numpy(..)`, `ws.energy.vjp_numpy(..)`,
//!   `ws.energy.torch(..)` (a `torch.autograd.Function` whose backward is the kernel's
//!   adjoint) and `ws.energy(..)`; tests/ holds their tests. `affine` (float64, `y = m x + b`)
//!   takes a matrix and a vector as values.
//! - **The ocean scene** (ocean.rs, driven by ocean.py): `ocean` and `ocean64` (a surface of
//!   Gerstner waves with analytic normals, the f32 and f64 instances of one generic kernel)
//!   and `fd_normals` / `fd_normals64` (normals by finite differences).
//! - **Interop** (interop.rs): zero-copy DLPack round trips and a Tape behind a hand-written
//!   autograd.Function, the pattern the ops replace.

mod bounce;
mod interop;
mod ocean;

use pyo3::prelude::*;
use warp_lang as wp;
use wp::ops::Op;
use wp::prelude::*;

/// `out[i] = a x[i] + y[i]`: the smallest op with a scalar, two inputs and an output (the
/// per-call overhead benchmark's workload).
#[wp::kernel]
fn axpy(a: f32, x: Array<f32>, y: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = a * x[i] + y[i];
}

/// `y[i] = m x[i] + b`: an op whose value parameters are a matrix and a vector (from Python:
/// nested sequences, flat ones or NumPy arrays, row-major; under JAX, array attributes).
#[wp::kernel]
fn affine(m: DMat3, b: DVec3, x: Array<DVec3>, y: Array<DVec3>) {
    let i = tid();
    y[i] = m * x[i] + b;
}

/// The module.
#[pymodule]
fn warp_sim(m: &Bound<'_, PyModule>) -> PyResult<()> {
    interop::register(m)?;
    bounce::register(m)?;
    let ops = wp::python::Ops::new(m)?;
    ops.add(
        Op::kernel("energy", interop::energy)
            .outputs(["e"])
            .build()?,
    )?;
    // axpy writes every element of `out`: the framework need not zero it first (at 16 Mi
    // elements that fill is a fifth of the call's memory traffic).
    ops.add(
        Op::kernel("axpy", axpy)
            .outputs(["out"])
            .init("out", wp::ops::Init::Uninit)
            .build()?,
    )?;
    ops.add(Op::kernel("affine", affine).outputs(["y"]).build()?)?;
    for op in ocean::ops()? {
        ops.add(op)?;
    }
    ops.add(bounce::op()?)?;
    Ok(())
}

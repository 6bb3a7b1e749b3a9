//! The conjugate gradient solver with Jacobi preconditioning, driven from the host.
//!
//! Every scalar of the iteration (the dots, alpha, beta, the tolerance) lives on the device and
//! is computed there by the same steps on every backend, so the CPU and a GPU take the same
//! iterations and write the same history. The host queues [`SolveOptions::check_every`]
//! iterations at a time and then reads the control words (a synchronisation); iterations
//! queued after the stop do nothing (each step first reads the stop word), so the result does
//! not depend on `check_every`.

use super::block::{Block, SparseScalar, SquareBlock};
use super::steps::{cg as c, CgScalar, CgVector, JacobiApply, JacobiInv};
use super::{contiguous, dot_partials, dot_raw, invalid, mv_raw, overlap, same_device, Bsr};
use crate::array::Array;
use crate::capturing::Keep;
use crate::dispatch;
use crate::error::Result;
use std::marker::PhantomData;

/// The preconditioner of [`cg`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Precond {
    /// None: `z = r`.
    #[default]
    None,
    /// Block Jacobi: `z = D^-1 r` with `D` the diagonal blocks, each inverted by Gauss-Jordan
    /// elimination with partial pivoting.
    Jacobi,
    /// Point Jacobi: the diagonal scalars alone inverted (Warp's `"diag"` preconditioner; for
    /// 1 x 1 blocks the same as [`Precond::Jacobi`]).
    PointJacobi,
}

/// Options of [`cg`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveOptions {
    /// Stop when `|r| <= max(atol, rtol * |b|)` (default 1e-6).
    pub rtol: f64,
    /// The absolute tolerance (default 0).
    pub atol: f64,
    /// The most iterations (default 1000); reaching it is [`Stop::MaxIterations`].
    pub max_iter: usize,
    /// Iterations queued between two reads of the solver's state by the host (default 10;
    /// at least 1). It changes the work done after a stop, never the result.
    pub check_every: usize,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions {
            rtol: 1e-6,
            atol: 0.0,
            max_iter: 1000,
            check_every: 10,
        }
    }
}

/// Why a solve stopped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Stop {
    /// The residual norm reached the tolerance.
    Converged,
    /// [`SolveOptions::max_iter`] iterations ran without converging.
    MaxIterations,
    /// A NaN or infinity appeared (in the residual, `r . z` or `p . Ap`): the matrix, `b`,
    /// the initial `x` or the preconditioner holds one, or the iteration overflowed.
    NonFinite,
    /// The method broke down: for CG `p . Ap <= 0` (`what` is `"p.Ap"`, `value` its value),
    /// which a symmetric positive definite matrix never gives.
    Breakdown {
        /// The quantity that broke down.
        what: &'static str,
        /// Its value.
        value: f64,
    },
    /// The Jacobi preconditioner could not be made: the diagonal block of `block_row` (the
    /// first such row) is missing, singular or not finite. No iteration ran; `x` is
    /// untouched.
    SingularPreconditioner {
        /// The block row.
        block_row: usize,
    },
}

/// What a solve did.
#[derive(Clone, Debug, PartialEq)]
pub struct SolveReport {
    /// Iterations run.
    pub iterations: usize,
    /// The last residual norm `|r|` of the iteration (the recurrence's residual, which
    /// rounding may move away from the true `|b - A x|`).
    pub residual: f64,
    /// The tolerance `max(atol, rtol * |b|)` as the solver computed it.
    pub tolerance: f64,
    /// `stop == Stop::Converged`.
    pub converged: bool,
    /// Why it stopped.
    pub stop: Stop,
    /// `|r|` before the first iteration and after each: `iterations + 1` entries.
    pub history: Vec<f64>,
}

/// Solves `A x = b` by the conjugate gradient method from the initial guess in `x`, which it
/// overwrites (Warp's `warp.optim.linear.cg`), with `precond`.
///
/// `A` must be symmetric positive definite; `b` and `x` are scalar vectors of `A`'s scalar
/// size (`nrow * B::ROWS`), contiguous, on the matrix's device, not overlapping. The solve
/// stops at convergence (`|r| <= max(atol, rtol |b|)`), after `max_iter` iterations, at a
/// non-finite value, at a breakdown (`p . Ap <= 0`) or, before iterating, at a singular
/// preconditioner; each is an `Ok` report (see [`Stop`]). The iterations, residuals and the
/// result are the same bits on the CPU and a GPU.
///
/// # Errors
/// [`Error::Capture`](crate::Error::Capture) inside a capture (the loop reads back);
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::cg`, the
/// argument and both shapes: a matrix that is not square in blocks, `b` or `x` of another
/// length, arrays that are not contiguous or overlap, `check_every == 0`, `max_iter` above
/// `i32::MAX - 1`, a negative or non-finite tolerance; [`Error::DeviceMismatch`](crate::Error::DeviceMismatch);
/// a fault of the queued work (reported by its read-backs).
pub fn cg<B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    precond: Precond,
    o: &SolveOptions,
) -> Result<SolveReport> {
    const F: &str = "sparse::cg";
    let dev = a.device().clone();
    // The host-driven loop reads the solver's state back: never inside a capture.
    crate::capturing::refuse(Some(&dev), "sparse::cg (a host-driven solve)")?;
    same_device(F, "b", &dev, b.device())?;
    same_device(F, "x", &dev, x.device())?;
    contiguous(F, "b", b)?;
    contiguous(F, "x", x)?;
    let (nr, nc) = a.shape();
    if a.nrow() != a.ncol() {
        return Err(invalid(
            F,
            format!(
                "argument `a` must be square; it has {} x {} blocks ({nr} x {nc} scalars)",
                a.nrow(),
                a.ncol()
            ),
        ));
    }
    for (name, v) in [("b", b), ("x", x)] {
        if v.len() != nr {
            return Err(invalid(
                F,
                format!(
                    "argument `{name}` has shape {:?}, but the matrix is {nr} x {nc} scalars",
                    v.shape()
                ),
            ));
        }
    }
    if overlap(b, x) {
        return Err(invalid(F, "arguments `b` and `x` overlap in memory"));
    }
    if a.overlaps(x) {
        return Err(invalid(F, "argument `x` overlaps the matrix's arrays"));
    }
    if o.check_every == 0 {
        return Err(invalid(F, "`check_every` is 0; it must be at least 1"));
    }
    if o.max_iter > i32::MAX as usize - 1 {
        return Err(invalid(
            F,
            format!("`max_iter` {} is above {}", o.max_iter, i32::MAX - 1),
        ));
    }
    for (name, t) in [("rtol", o.rtol), ("atol", o.atol)] {
        if !(t >= 0.0 && t.is_finite()) {
            return Err(invalid(
                F,
                format!("`{name}` is {t}; it must be finite and >= 0"),
            ));
        }
    }
    type S<B> = <B as Block>::Scalar;
    let n = nr;
    let sz = std::mem::size_of::<S<B>>() as u64;
    let r = Array::<S<B>>::zeros(n, &dev)?;
    let p = Array::<S<B>>::zeros(n, &dev)?;
    let ap = Array::<S<B>>::zeros(n, &dev)?;
    let ctl = Array::from_slice(&[c::STOP_NONE, 0, i32::MAX], &dev)?;
    let scal = Array::<S<B>>::zeros(c::SCAL_LEN, &dev)?;
    let history = Array::<S<B>>::zeros(o.max_iter + 1, &dev)?;
    let partials = dot_partials::<S<B>>(n, &dev)?;
    let s_at = |k: usize| scal.device_address() + k as u64 * sz;
    // (A solve reads back, so it is never inside a capture: nothing to keep.)
    let none = || -> Keep { Box::new(()) };
    let dot = |u: &Array<S<B>>, v: u64, k: usize| {
        dot_raw(&dev, u.device_address(), v, n, &partials, s_at(k), none)
    };
    // r = b - A x.
    r.copy_from(b)?;
    mv_raw(a, x.device_address(), r.device_address(), -1.0, 1.0, none)?;
    // z = M^-1 r (z is r without a preconditioner).
    let pre = match precond {
        Precond::None => None,
        Precond::Jacobi | Precond::PointJacobi => {
            let dinv = Array::<S<B>>::zeros(a.nrow() * B::ROWS * B::ROWS, &dev)?;
            dispatch::object_step(
                &dev,
                &JacobiInv::<B> {
                    offsets: a.offsets().device_address(),
                    columns: a.columns().device_address(),
                    values: a.values().device_address(),
                    dinv: dinv.device_address(),
                    bad: ctl.device_address() + 4 * c::CTL_BAD as u64,
                    nrow: a.nrow() as i32,
                    point: (precond == Precond::PointJacobi) as i32,
                    cap: a.nnz_bound() as i32,
                    pad: 0,
                    block: PhantomData,
                },
            )?;
            Some((dinv, Array::<S<B>>::zeros(n, &dev)?))
        }
    };
    let apply = |z: &Array<S<B>>, dinv: &Array<S<B>>| {
        dispatch::object_step(
            &dev,
            &JacobiApply::<S<B>> {
                dinv: dinv.device_address(),
                r: r.device_address(),
                z: z.device_address(),
                nrow: a.nrow() as i32,
                dim: B::ROWS as i32,
                scalar: PhantomData,
            },
        )
    };
    let z = match &pre {
        Some((dinv, z)) => {
            apply(z, dinv)?;
            z
        }
        None => &r,
    };
    p.copy_from(z)?;
    dot(b, b.device_address(), c::BB)?;
    dot(&r, z.device_address(), c::RZ)?;
    dot(&r, r.device_address(), c::RR)?;
    let scalar_step = |check: bool| {
        let (ctl, scal, history) = (
            ctl.device_address(),
            scal.device_address(),
            history.device_address(),
        );
        let (rtol, atol, max_iter) = (o.rtol, o.atol, o.max_iter as i32);
        if check {
            dispatch::object_step(
                &dev,
                &CgScalar::<S<B>, true> {
                    ctl,
                    scal,
                    history,
                    rtol,
                    atol,
                    max_iter,
                    pad: 0,
                    scalar: PhantomData,
                },
            )
        } else {
            dispatch::object_step(
                &dev,
                &CgScalar::<S<B>, false> {
                    ctl,
                    scal,
                    history,
                    rtol,
                    atol,
                    max_iter,
                    pad: 0,
                    scalar: PhantomData,
                },
            )
        }
    };
    scalar_step(false)?;
    let vec_step = |direction: bool| {
        let (ctl, scal) = (ctl.device_address(), scal.device_address());
        if direction {
            dispatch::object_step(
                &dev,
                &CgVector::<S<B>, true> {
                    ctl,
                    scal,
                    x: 0,
                    r: z.device_address(),
                    p: p.device_address(),
                    ap: 0,
                    n: n as i64,
                    scalar: PhantomData,
                },
            )
        } else {
            dispatch::object_step(
                &dev,
                &CgVector::<S<B>, false> {
                    ctl,
                    scal,
                    x: x.device_address(),
                    r: r.device_address(),
                    p: p.device_address(),
                    ap: ap.device_address(),
                    n: n as i64,
                    scalar: PhantomData,
                },
            )
        }
    };
    let mut queued = 0;
    let mut words = ctl.to_vec()?;
    while words[c::CTL_STOP] == c::STOP_NONE && queued < o.max_iter {
        for _ in 0..o.check_every.min(o.max_iter - queued) {
            mv_raw(a, p.device_address(), ap.device_address(), 1.0, 0.0, none)?;
            dot(&p, ap.device_address(), c::PAP)?;
            vec_step(false)?;
            if let Some((dinv, z)) = &pre {
                apply(z, dinv)?;
            }
            dot(&r, z.device_address(), c::RZ_NEW)?;
            dot(&r, r.device_address(), c::RR)?;
            scalar_step(true)?;
            vec_step(true)?;
            queued += 1;
        }
        words = ctl.to_vec()?;
    }
    let sc = scal.to_vec()?;
    let iterations = words[c::CTL_ITER] as usize;
    let history: Vec<f64> = history.to_vec()?[..=iterations]
        .iter()
        .map(|v| v.to_f64())
        .collect();
    let stop = match words[c::CTL_STOP] {
        c::STOP_CONVERGED => Stop::Converged,
        c::STOP_MAX_ITER => Stop::MaxIterations,
        c::STOP_NON_FINITE => Stop::NonFinite,
        c::STOP_BREAKDOWN => Stop::Breakdown {
            what: "p.Ap",
            value: sc[c::BREAK].to_f64(),
        },
        c::STOP_SINGULAR => Stop::SingularPreconditioner {
            block_row: words[c::CTL_BAD] as usize,
        },
        // The loop ends only at a stop (max_iter bounds it on the device).
        w => {
            return Err(crate::error::Error::invalid(format!(
                "{F}: internal: the solver ended with stop word {w}"
            )))
        }
    };
    Ok(SolveReport {
        iterations,
        residual: history[iterations],
        tolerance: sc[c::TOL].to_f64(),
        converged: stop == Stop::Converged,
        stop,
        history,
    })
}

//! The conjugate gradient solver ([`cg`]) with Jacobi preconditioning.

use super::adjoint::{self, Method};
use super::{
    check_args, drive, report, IntoPrecond, Pre, Precond, Preconditioner, Queued, SolveOptions,
    SolveReport,
};
use crate::array::Array;
use crate::backend::ObjectStep;
use crate::capturing::Keep;
use crate::device::Device;
use crate::dispatch;
use crate::error::Result;
use crate::sparse::block::{Block, SparseScalar, SquareBlock};
use crate::sparse::steps::{cg as c, CgScalar, CgVector, JacobiApply, JacobiInv};
use crate::sparse::{dot_partials, dot_raw, mv_raw, Bsr};
use std::marker::PhantomData;

/// Solves `A x = b` by the conjugate gradient method from the initial guess in `x`, which it
/// overwrites (Warp's `warp.optim.linear.cg`), with `precond`: a built-in [`Precond`] or `&p`
/// for your own [`Preconditioner`] `p` (symmetric positive definite).
///
/// `A` must be symmetric positive definite; `b` and `x` are scalar vectors of `A`'s scalar
/// size (`nrow * B::ROWS`), contiguous, on the matrix's device, not overlapping. The solve
/// stops at convergence (`|r| <= max(atol, rtol |b|)`), after `max_iter` iterations, at a
/// non-finite value, at a breakdown (`p . Ap <= 0` or `r . z <= 0`) or, before iterating, at
/// a singular preconditioner; each is an `Ok` report (see [`Stop`](super::Stop)). The iterations,
/// residuals and the result are the same bits on the CPU and a GPU.
///
/// ```
/// # use warp_runtime as wp;
/// use wp::sparse::{self, Bsr, Precond, SolveOptions, Stop};
/// let dev = wp::cpu();
/// // The 1-D Laplacian, tridiag(-1, 2, -1), of 100 unknowns.
/// let n = 100;
/// let (mut rows, mut cols, mut vals) = (vec![], vec![], vec![]);
/// for i in 0..n as i32 {
///     for (j, v) in [(i - 1, -1.0f64), (i, 2.0), (i + 1, -1.0)] {
///         if (0..n as i32).contains(&j) {
///             rows.push(i);
///             cols.push(j);
///             vals.push(v);
///         }
///     }
/// }
/// let arr = |v: &[i32]| wp::Array::from_slice(v, &dev);
/// let vals = wp::Array::from_slice(&vals, &dev)?;
/// let a = Bsr::from_triplets(n, n, &arr(&rows)?, &arr(&cols)?, &vals)?;
/// let b = wp::Array::from_slice(&vec![1.0f64; n], &dev)?;
/// let x = wp::Array::<f64>::zeros(n, &dev)?;
/// let report = sparse::cg(&a, &b, &x, Precond::Jacobi, &SolveOptions::default())?;
/// assert_eq!(report.stop, Stop::Converged);
/// assert!(report.residual <= report.tolerance);
/// assert_eq!(report.history.len(), report.iterations + 1);
/// # Ok::<(), wp::Error>(())
/// ```
///
/// # Gradients
/// A recording [`Tape`](crate::Tape) records the solve as one step when `x` has a gradient
/// (its own steps, and a user preconditioner's launches, reach no tape). Its backward takes
/// `x̄`, x's gradient, and clears it (the solve wrote x: the initial guess gets no gradient),
/// solves `Aᵀ λ = x̄` from zero by the same method (cg and cr with `A`, which they require
/// symmetric; bicgstab and gmres with a transpose of `A` made then), with the same built-in
/// preconditioner (a user preconditioner is not reused: that adjoint solve runs without one),
/// `rtol` the forward's relative to `|x̄|` (or the relative tolerance the forward's `atol`
/// gave, when its `rtol` is 0) and `atol` 0, then adds `λ` into `b`'s gradient and `-λ_r
/// x_cᵀ` into the gradient of each stored block of `A` (when [`Bsr::with_grad`]), `x` being
/// the solution as the forward left it. `A` and `b` are read when backward runs. Backward
/// through a solve that stopped other than [`Stop::Converged`](super::Stop::Converged), or
/// whose adjoint solve does not converge, is an
/// [`Error::NotDifferentiable`](crate::Error::NotDifferentiable) naming the solver, the stop,
/// the residual and the tolerance: the gradient would be wrong.
///
/// ```
/// # use warp_runtime as wp;
/// use wp::sparse::{self, Bsr, Precond, SolveOptions};
/// let dev = wp::cpu();
/// // A = [[4, 1], [1, 3]], with a gradient for its blocks; a loss L = w . x, so x̄ = w.
/// let arr = |v: &[i32]| wp::Array::from_slice(v, &dev);
/// let vals = wp::Array::from_slice(&[4.0f64, 1.0, 1.0, 3.0], &dev)?;
/// let a = Bsr::from_triplets(2, 2, &arr(&[0, 0, 1, 1])?, &arr(&[0, 1, 0, 1])?, &vals)?
///     .with_grad()?;
/// let b = wp::Array::from_slice(&[1.0f64, 2.0], &dev)?.with_grad()?;
/// let x = wp::Array::<f64>::zeros(2, &dev)?.with_grad()?;
/// let tape = wp::Tape::new();
/// let o = SolveOptions { rtol: 1e-12, ..Default::default() };
/// {
///     let _rec = tape.record();
///     sparse::cg(&a, &b, &x, Precond::None, &o)?;
/// }
/// x.grad().unwrap().copy_from(&wp::Array::from_slice(&[1.0, 0.0], &dev)?)?;
/// tape.backward_from_grads()?;
/// // b̄ = A⁻ᵀ w = [3, -1] / 11.
/// let bg = b.grad().unwrap().to_vec()?;
/// assert!((bg[0] - 3.0 / 11.0).abs() < 1e-10 && (bg[1] + 1.0 / 11.0).abs() < 1e-10);
/// # Ok::<(), wp::Error>(())
/// ```
///
/// # Errors
/// [`Error::Capture`](crate::Error::Capture) inside a capture (the loop reads back);
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::cg`, the
/// argument and both shapes: a matrix that is not square in blocks, `b` or `x` of another
/// length, arrays that are not contiguous or overlap, `check_every == 0`, `max_iter` above
/// `i32::MAX - 1`, a negative or non-finite tolerance;
/// [`Error::DeviceMismatch`](crate::Error::DeviceMismatch); a fault of the queued work
/// (reported by its read-backs).
pub fn cg<'p, B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    precond: impl IntoPrecond<'p, B::Scalar>,
    o: &SolveOptions,
) -> Result<SolveReport> {
    let method = Method {
        name: "sparse::cg",
        transpose: false,
        solve: |a, b, x, p, o| cg(a, b, x, p, o),
    };
    adjoint::solve_recorded(method, a, b, x, precond.into_pre(), o, |pre| {
        solve(a, b, x, pre, o)
    })
}

/// The solve of [`cg`], unrecorded.
fn solve<'p, B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    pre: Pre<'p, B::Scalar>,
    o: &SolveOptions,
) -> Result<SolveReport> {
    const F: &str = "sparse::cg";
    let dev = check_args(F, a, b, x, o)?;
    let nr = a.shape().0;
    type S<B> = <B as Block>::Scalar;
    let n = nr;
    let z = Array::<S<B>>::zeros(n, &dev)?;
    let cg = Cg {
        a,
        dev: dev.clone(),
        n,
        b,
        x,
        r: Array::zeros(n, &dev)?,
        p: Array::zeros(n, &dev)?,
        ap: Array::zeros(n, &dev)?,
        pre: match pre {
            Pre::Builtin(Precond::None) => None,
            Pre::Builtin(p) => Some(Jacobi {
                dinv: Some(Array::zeros(a.nrow() * B::ROWS * B::ROWS, &dev)?),
                z,
                point: p == Precond::PointJacobi,
            }),
            Pre::User(_) => Some(Jacobi {
                dinv: None,
                z,
                point: false,
            }),
        },
        user: match pre {
            Pre::User(u) => Some(u),
            Pre::Builtin(_) => None,
        },
        ctl: Array::zeros(c::CTL_LEN, &dev)?,
        ctl0: Array::from_slice(&[c::STOP_NONE, 0, i32::MAX, 0], &dev)?,
        scal: Array::zeros(c::SCAL_LEN, &dev)?,
        history: Array::zeros(o.max_iter + 1, &dev)?,
        partials: dot_partials::<S<B>>(n, &dev)?,
        o: *o,
    };
    drive(&cg, &dev, o)?;
    cg.report()
}

/// The preconditioner's state: the inverted diagonal blocks (none for a user preconditioner)
/// and `z = M^-1 r`.
struct Jacobi<S: SparseScalar> {
    dinv: Option<Array<S>>,
    z: Array<S>,
    point: bool,
}

/// One CG solve's arrays (all allocated before anything is queued, so that the steps can be
/// captured) and its queued steps.
struct Cg<'a, B: Block> {
    a: &'a Bsr<B>,
    dev: Device,
    n: usize,
    b: &'a Array<B::Scalar>,
    x: &'a Array<B::Scalar>,
    r: Array<B::Scalar>,
    p: Array<B::Scalar>,
    ap: Array<B::Scalar>,
    pre: Option<Jacobi<B::Scalar>>,
    /// The user's preconditioner, if any.
    user: Option<&'a dyn Preconditioner<B::Scalar>>,
    /// The control words (`steps::cg::CTL_*`) and their initial values.
    ctl: Array<i32>,
    ctl0: Array<i32>,
    /// The scalars (`steps::cg::RZ` ..) and `|r|` per iteration.
    scal: Array<B::Scalar>,
    history: Array<B::Scalar>,
    partials: Array<B::Scalar>,
    o: SolveOptions,
}

impl<B: Block> Cg<'_, B> {
    /// What a graph recording the steps keeps alive: every array they address.
    fn keep(&self) -> impl Fn() -> Keep + '_ {
        move || {
            Box::new((
                (self.a.clone(), self.b.clone(), self.x.clone()),
                (self.r.clone(), self.p.clone(), self.ap.clone()),
                self.pre.as_ref().map(|j| (j.dinv.clone(), j.z.clone())),
                (self.ctl.clone(), self.ctl0.clone(), self.scal.clone()),
                (self.history.clone(), self.partials.clone()),
            ))
        }
    }

    /// Queues (or records) an object step of the solve.
    fn step<T: ObjectStep + 'static>(&self, step: T) -> Result<()> {
        dispatch::object_step_keeping(&self.dev, &step, self.keep())
    }

    /// z: the preconditioned residual (r itself without a preconditioner).
    fn z(&self) -> &Array<B::Scalar> {
        self.pre.as_ref().map_or(&self.r, |j| &j.z)
    }

    /// `u . v` into scalar `k`.
    fn dot(&self, u: &Array<B::Scalar>, v: &Array<B::Scalar>, k: usize) -> Result<()> {
        let out = self.scal.device_address() + (k * std::mem::size_of::<B::Scalar>()) as u64;
        let (u, v) = (u.device_address(), v.device_address());
        // SAFETY: u and v are the solve's n-scalar vectors (checked or allocated so), out is
        // scalar k < SCAL_LEN of `scal` (another array), partials are sized for n, and
        // `keep` holds every array of the solve.
        unsafe { dot_raw(&self.dev, u, v, self.n, &self.partials, out, self.keep()) }
    }

    /// `z = M^-1 r` (nothing without a preconditioner).
    fn apply(&self) -> Result<()> {
        match (&self.pre, self.user) {
            (Some(j), Some(u)) => u.apply(&self.r, &j.z),
            (
                Some(Jacobi {
                    dinv: Some(dinv), ..
                }),
                None,
            ) => self.step(JacobiApply::<B::Scalar> {
                dinv: dinv.device_address(),
                r: self.r.device_address(),
                z: self.z().device_address(),
                nrow: self.a.nrow() as i32,
                dim: B::ROWS as i32,
                scalar: PhantomData,
            }),
            _ => Ok(()),
        }
    }

    /// The set-up or a check (one thread).
    fn scalar_step<const CHECK: bool>(&self) -> Result<()> {
        self.step(CgScalar::<B::Scalar, CHECK> {
            ctl: self.ctl.device_address(),
            scal: self.scal.device_address(),
            history: self.history.device_address(),
            rtol: self.o.rtol,
            atol: self.o.atol,
            max_iter: self.o.max_iter as i32,
            pad: 0,
            scalar: PhantomData,
        })
    }

    /// The set-up: control words reset, `r = b - A x`, the preconditioner, `z`, `p = z`, the
    /// dots `b.b`, `r.z`, `r.r`, and the set-up check (tolerance, `history[0]`, a stop before
    /// any iteration).
    fn setup(&self) -> Result<()> {
        let a = self.a;
        self.ctl.copy_from(&self.ctl0)?;
        self.r.copy_from(self.b)?;
        // SAFETY: x and r hold n = nrow * ROWS scalars (the matrix is square in blocks:
        // checked), r is the solve's own array (overlapping neither x nor the matrix: x was
        // checked against the matrix), and `keep` holds every array of the solve.
        unsafe {
            mv_raw(
                a,
                self.x.device_address(),
                self.r.device_address(),
                -1.0,
                1.0,
                self.keep(),
            )?;
        }
        if let Some(Jacobi {
            dinv: Some(dinv),
            point,
            ..
        }) = &self.pre
        {
            self.step(JacobiInv::<B> {
                offsets: a.offsets().device_address(),
                columns: a.columns().device_address(),
                values: a.values().device_address(),
                dinv: dinv.device_address(),
                bad: self.ctl.view(c::CTL_BAD..c::CTL_BAD + 1)?.device_address(),
                nrow: a.nrow() as i32,
                point: *point as i32,
                cap: a.nnz_bound() as i32,
                pad: 0,
                block: PhantomData,
            })?;
        }
        self.apply()?;
        self.p.copy_from(self.z())?;
        self.dot(self.b, self.b, c::BB)?;
        self.dot(&self.r, self.z(), c::RZ)?;
        self.dot(&self.r, &self.r, c::RR)?;
        self.scalar_step::<false>()
    }

    /// One iteration: `Ap`, `p.Ap`, the x/r update, `z`, `r.z`, `r.r`, the check, `p`. Each
    /// step does nothing once a stop is set.
    fn iteration(&self) -> Result<()> {
        let (ctl, scal) = (self.ctl.device_address(), self.scal.device_address());
        // SAFETY: p and ap are the solve's own n-scalar arrays (distinct, not the matrix's),
        // and `keep` holds every array of the solve.
        unsafe {
            mv_raw(
                self.a,
                self.p.device_address(),
                self.ap.device_address(),
                1.0,
                0.0,
                self.keep(),
            )?;
        }
        self.dot(&self.p, &self.ap, c::PAP)?;
        self.step(CgVector::<B::Scalar, false> {
            ctl,
            scal,
            x: self.x.device_address(),
            r: self.r.device_address(),
            p: self.p.device_address(),
            ap: self.ap.device_address(),
            n: self.n as i64,
            scalar: PhantomData,
        })?;
        self.apply()?;
        self.dot(&self.r, self.z(), c::RZ_NEW)?;
        self.dot(&self.r, &self.r, c::RR)?;
        self.scalar_step::<true>()?;
        self.step(CgVector::<B::Scalar, true> {
            ctl,
            scal,
            x: 0,
            r: self.z().device_address(),
            p: self.p.device_address(),
            ap: 0,
            n: self.n as i64,
            scalar: PhantomData,
        })
    }

    /// The report, from the control words, scalars and history (read back).
    fn report(&self) -> Result<SolveReport> {
        let sc = self.scal.to_vec()?;
        report(
            "sparse::cg",
            &self.ctl.to_vec()?,
            sc[c::TOL],
            sc[c::BREAK],
            &self.history,
            |w, _| match w {
                c::STOP_BREAKDOWN => Some("p.Ap"),
                c::STOP_BREAKDOWN_RZ => Some("r.z"),
                _ => None,
            },
        )
    }
}

impl<B: Block> Queued for Cg<'_, B> {
    fn ctl(&self) -> &Array<i32> {
        &self.ctl
    }

    fn setup(&self) -> Result<()> {
        Cg::setup(self)
    }

    fn unit(&self) -> Result<()> {
        self.iteration()
    }
}

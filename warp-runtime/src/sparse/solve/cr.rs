//! The conjugate residual method ([`cr`]) for symmetric, possibly indefinite systems.

use super::adjoint::{self, Method};
use super::steps::kr::{self, *};
use super::work::Work;
use super::{check_args, drive, IntoPrecond, Pre, Queued, SolveOptions, SolveReport};
use crate::array::Array;
use crate::error::Result;
use crate::sparse::block::SquareBlock;
use crate::sparse::Bsr;

/// Solves `A x = b` by the conjugate residual method (Warp's `warp.optim.linear.cr`) from the
/// initial guess in `x`, which it overwrites, with `precond` (`M`, symmetric positive
/// definite). `precond` is a built-in
/// [`Precond`](super::Precond) or `&p` for your own [`Preconditioner`](super::Preconditioner) `p`.
///
/// `A` must be symmetric; unlike [`cg`](super::cg) it may be indefinite. Without a
/// preconditioner CR minimises `|r|` over the Krylov space, so the history does not increase
/// (up to rounding); with one it minimises `|r|` in the `M^-1` norm. Each iteration:
/// `q = M^-1 Ap`, `alpha = (z . Az) / (Ap . q)`, `x += alpha p`, `r -= alpha Ap`,
/// `z = M^-1 r`, `Az = A z`, the check of `|r|`, `beta = (z . Az)_new / (z . Az)`,
/// `p = z + beta p`, `Ap = Az + beta Ap` (one product with `A`).
///
/// It stops at convergence (`|r| <= max(atol, rtol |b|)`), after `max_iter` iterations, at a
/// non-finite value, at a breakdown (`z . Az = 0` for `r != 0`, which an indefinite `A` may
/// give, or `Ap . M^-1 Ap = 0`: [`Stop::Breakdown`] names it) or, before iterating, at a
/// singular preconditioner; each is an `Ok` report. The iterations, residuals and the result
/// are the same bits on the CPU and a GPU, and in both [`Mode`](super::Mode)s. Arguments as
/// [`cg`](super::cg)'s.
///
/// ```
/// # use warp_runtime as wp;
/// use wp::sparse::{self, Bsr, Precond, SolveOptions, Stop};
/// let dev = wp::cpu();
/// // A symmetric indefinite diagonal-plus-coupling matrix: 2 and -3 alternating on the
/// // diagonal, 0.5 between neighbours.
/// let n = 40;
/// let (mut rows, mut cols, mut vals) = (vec![], vec![], vec![]);
/// for i in 0..n as i32 {
///     let d = if i % 2 == 0 { 2.0 } else { -3.0 };
///     for (j, v) in [(i - 1, 0.5f64), (i, d), (i + 1, 0.5)] {
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
/// let report = sparse::cr(&a, &b, &x, Precond::None, &SolveOptions::default())?;
/// assert_eq!(report.stop, Stop::Converged);
/// assert!(report.residual <= report.tolerance);
/// # Ok::<(), wp::Error>(())
/// ```
///
/// [`Stop::Breakdown`]: super::Stop::Breakdown
///
/// # Gradients
/// A recording [`Tape`](crate::Tape) records the solve as one step, differentiable with
/// respect to `b` and `A`'s values as [`cg`](super::cg)'s (its backward solves `Aᵀ λ = x̄`
/// by this method with `A`, symmetric by requirement).
///
/// # Errors
/// As [`cg`](super::cg)'s, naming `sparse::cr`.
pub fn cr<'p, B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    precond: impl IntoPrecond<'p, B::Scalar>,
    o: &SolveOptions,
) -> Result<SolveReport> {
    let method = Method {
        name: "sparse::cr",
        transpose: false,
        solve: |a, b, x, p, o| cr(a, b, x, p, o),
    };
    adjoint::solve_recorded(method, a, b, x, precond.into_pre(), o, |pre| {
        solve(a, b, x, pre, o)
    })
}

/// The solve of [`cr`], unrecorded.
fn solve<'p, B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    pre: Pre<'p, B::Scalar>,
    o: &SolveOptions,
) -> Result<SolveReport> {
    const F: &str = "sparse::cr";
    let dev = check_args(F, a, b, x, o)?;
    let mut w = Work::new(a, &dev, b, x, pre, C_LEN, o)?;
    let n = w.n;
    let pre = w.preconditioned();
    let s = Cr {
        p: w.vector(n)?,
        ap: w.vector(n)?,
        az: w.vector(n)?,
        z: if pre { Some(w.vector(n)?) } else { None },
        q: if pre { Some(w.vector(n)?) } else { None },
        w,
    };
    drive(&s, &dev, o)?;
    s.w.report(F)
}

/// One CR solve: the direction `p`, `Ap`, `Az`, and with a preconditioner `z = M^-1 r` and
/// `q = M^-1 Ap` (else r and Ap themselves).
struct Cr<'a, B: SquareBlock> {
    w: Work<'a, B>,
    p: Array<B::Scalar>,
    ap: Array<B::Scalar>,
    az: Array<B::Scalar>,
    z: Option<Array<B::Scalar>>,
    q: Option<Array<B::Scalar>>,
}

impl<B: SquareBlock> Cr<'_, B> {
    /// The address of z (r without a preconditioner).
    fn z(&self) -> u64 {
        self.z
            .as_ref()
            .map_or(self.w.r.device_address(), |a| a.device_address())
    }
}

impl<B: SquareBlock> Queued for Cr<'_, B> {
    fn ctl(&self) -> &Array<i32> {
        &self.w.ctl
    }

    fn setup(&self) -> Result<()> {
        let w = &self.w;
        w.setup()?;
        let (z, az) = (self.z(), self.az.device_address());
        if let Some(za) = &self.z {
            w.apply(&w.r, za)?;
        }
        match &self.z {
            Some(za) => self.p.copy_from(za)?,
            None => self.p.copy_from(&w.r)?,
        }
        w.mv(z, az, 1.0, 0.0)?;
        self.ap.copy_from(&self.az)?;
        w.dot(z, az, C_ZAZ)?;
        w.scalar::<{ kr::CR }>(0, 0, 0)
    }

    fn unit(&self) -> Result<()> {
        let w = &self.w;
        let (r, x, z) = (w.r.device_address(), w.x.device_address(), self.z());
        let (p, ap, az) = (
            self.p.device_address(),
            self.ap.device_address(),
            self.az.device_address(),
        );
        let q = self.q.as_ref().map_or(ap, |a| a.device_address());
        if let Some(qa) = &self.q {
            w.apply(&self.ap, qa)?;
        }
        w.dot(ap, q, C_APAP)?;
        w.scalar::<{ kr::CR }>(1, 0, 0)?;
        w.vec(OP_AXPY, x, p, 0, C_ALPHA, 0, GATE_RUN)?;
        w.vec(OP_AXMY, r, ap, 0, C_ALPHA, 0, GATE_RUN)?;
        if let Some(za) = &self.z {
            w.apply(&w.r, za)?;
        }
        w.mv(z, az, 1.0, 0.0)?;
        w.dot(z, az, C_ZAZ_NEW)?;
        w.dot(r, r, RR)?;
        w.scalar::<{ kr::CR }>(2, 0, 0)?;
        w.vec(OP_XPAY, p, z, 0, C_BETA, 0, GATE_RUN)?;
        w.vec(OP_XPAY, ap, az, 0, C_BETA, 0, GATE_RUN)
    }
}

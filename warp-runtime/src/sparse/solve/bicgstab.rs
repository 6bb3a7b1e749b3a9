//! BiCGSTAB ([`bicgstab`]), right-preconditioned, for non-symmetric systems.

use super::adjoint::{self, Method};
use super::steps::kr::{self, *};
use super::work::Work;
use super::{check_args, drive, IntoPrecond, Pre, Queued, SolveOptions, SolveReport};
use crate::array::Array;
use crate::error::Result;
use crate::sparse::block::SquareBlock;
use crate::sparse::Bsr;

/// Solves `A x = b` by BiCGSTAB (van der Vorst's stabilised biconjugate gradients; Warp's
/// `warp.optim.linear.bicgstab`) from the initial guess in `x`, which it overwrites, with
/// `precond` applied on the right (`A M^-1 u = b`, `x = M^-1 u`), so the residual it
/// monitors is the true system's. `precond` is a built-in
/// [`Precond`](super::Precond) or `&p` for your own [`Preconditioner`](super::Preconditioner) `p`.
///
/// `A` need not be symmetric. Each iteration takes two products with `A` (and two
/// preconditioner applications): `p̂ = M^-1 p`, `v = A p̂`, `alpha = rho / (r0 . v)`,
/// `x += alpha p̂`, `s = r - alpha v` (the solve stops here, the iteration counted, when
/// `|s|` reaches the tolerance), `ŝ = M^-1 s`, `t = A ŝ`, `omega = (t . s) / (t . t)`,
/// `x += omega ŝ`, `r = s - omega t`, then the check of `|r|` and `beta = (rho_new / rho)
/// (alpha / omega)`, `p = r + beta (p - omega v)`, with `r0` the initial residual (the shadow)
/// and `rho = r0 . r`.
///
/// It stops at convergence (`|r| <= max(atol, rtol |b|)`), after `max_iter` iterations, at a
/// non-finite value, at a breakdown (`r0 . v = 0`, `omega = 0`, `rho = 0`: [`Stop::Breakdown`]
/// names it) or, before iterating, at a singular preconditioner; each is an `Ok` report. The
/// iterations, residuals and the result are the same bits on the CPU and a GPU, and in both
/// [`Mode`](super::Mode)s. Arguments as [`cg`](super::cg)'s.
///
/// ```
/// # use warp_runtime as wp;
/// use wp::sparse::{self, Bsr, Precond, SolveOptions, Stop};
/// let dev = wp::cpu();
/// // A non-symmetric tridiagonal matrix, tridiag(-1.5, 3, -0.5), of 50 unknowns.
/// let n = 50;
/// let (mut rows, mut cols, mut vals) = (vec![], vec![], vec![]);
/// for i in 0..n as i32 {
///     for (j, v) in [(i - 1, -1.5f64), (i, 3.0), (i + 1, -0.5)] {
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
/// let report = sparse::bicgstab(&a, &b, &x, Precond::Jacobi, &SolveOptions::default())?;
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
/// by this method with a transpose of `A`).
///
/// # Errors
/// As [`cg`](super::cg)'s, naming `sparse::bicgstab`.
pub fn bicgstab<'p, B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    precond: impl IntoPrecond<'p, B::Scalar>,
    o: &SolveOptions,
) -> Result<SolveReport> {
    let method = Method {
        name: "sparse::bicgstab",
        transpose: true,
        solve: |a, b, x, p, o| bicgstab(a, b, x, p, o),
    };
    adjoint::solve_recorded(method, a, b, x, precond.into_pre(), o, |pre| {
        solve(a, b, x, pre, o)
    })
}

/// The solve of [`bicgstab`], unrecorded.
fn solve<'p, B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    pre: Pre<'p, B::Scalar>,
    o: &SolveOptions,
) -> Result<SolveReport> {
    const F: &str = "sparse::bicgstab";
    let dev = check_args(F, a, b, x, o)?;
    let mut w = Work::new(a, &dev, b, x, pre, B_LEN, o)?;
    let n = w.n;
    let pre = w.preconditioned();
    let s = BiCgStab {
        r0: w.vector(n)?,
        p: w.vector(n)?,
        v: w.vector(n)?,
        t: w.vector(n)?,
        ph: if pre { Some(w.vector(n)?) } else { None },
        sh: if pre { Some(w.vector(n)?) } else { None },
        w,
    };
    drive(&s, &dev, o)?;
    s.w.report(F)
}

/// One BiCGSTAB solve: the shadow residual `r0`, the direction `p`, `v = A p̂`, `t = A ŝ`, and
/// with a preconditioner `p̂ = M^-1 p` and `ŝ = M^-1 s` (else p and r themselves). `s`
/// overwrites `r`.
struct BiCgStab<'a, B: SquareBlock> {
    w: Work<'a, B>,
    r0: Array<B::Scalar>,
    p: Array<B::Scalar>,
    v: Array<B::Scalar>,
    t: Array<B::Scalar>,
    ph: Option<Array<B::Scalar>>,
    sh: Option<Array<B::Scalar>>,
}

impl<B: SquareBlock> Queued for BiCgStab<'_, B> {
    fn ctl(&self) -> &Array<i32> {
        &self.w.ctl
    }

    fn setup(&self) -> Result<()> {
        let w = &self.w;
        w.setup()?;
        self.r0.copy_from(&w.r)?;
        self.p.copy_from(&w.r)?;
        w.scalar::<{ kr::BICGSTAB }>(0, 0, 0)
    }

    fn unit(&self) -> Result<()> {
        let w = &self.w;
        let (r, x) = (w.r.device_address(), w.x.device_address());
        let (r0, p, v, t) = (
            self.r0.device_address(),
            self.p.device_address(),
            self.v.device_address(),
            self.t.device_address(),
        );
        let ph = self.ph.as_ref().map_or(p, |a| a.device_address());
        let sh = self.sh.as_ref().map_or(r, |a| a.device_address());
        if let Some(pa) = &self.ph {
            w.apply(&self.p, pa)?;
        }
        w.mv(ph, v, 1.0, 0.0)?;
        w.dot(r0, v, B_R0V)?;
        w.scalar::<{ kr::BICGSTAB }>(1, 0, 0)?;
        w.vec(OP_AXPY, x, ph, 0, B_ALPHA, 0, GATE_RUN)?;
        w.vec(OP_AXMY, r, v, 0, B_ALPHA, 0, GATE_RUN)?;
        w.dot(r, r, B_SS)?;
        w.scalar::<{ kr::BICGSTAB }>(2, 0, 0)?;
        if let Some(sa) = &self.sh {
            w.apply(&w.r, sa)?;
        }
        w.mv(sh, t, 1.0, 0.0)?;
        w.dot(t, r, B_TS)?;
        w.dot(t, t, B_TT)?;
        w.scalar::<{ kr::BICGSTAB }>(3, 0, 0)?;
        w.vec(OP_AXPY, x, sh, 0, B_OMEGA, 0, GATE_RUN)?;
        w.vec(OP_AXMY, r, t, 0, B_OMEGA, 0, GATE_RUN)?;
        w.dot(r, r, RR)?;
        w.dot(r0, r, B_RHO_NEW)?;
        w.scalar::<{ kr::BICGSTAB }>(4, 0, 0)?;
        w.vec(OP_P, p, r, v, B_BETA, B_OMEGA, GATE_RUN)
    }
}

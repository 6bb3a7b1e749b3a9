//! Differentiable solves (design §8): each of [`cg`](super::cg), [`cr`](super::cr),
//! [`bicgstab`](super::bicgstab) and [`gmres`](super::gmres)
//! records one step on the tapes recording on its thread (its own steps reach no tape: the
//! solve runs with recording paused), whose backward solves the adjoint system.
//!
//! For `A x = b` and a loss `L(x)` with `x̄ = ∂L/∂x` (x's gradient when backward reaches the
//! solve), `λ = A⁻ᵀ x̄` gives `b̄ += λ` and `Ā = -λ xᵀ`, restricted to A's stored blocks:
//! `Ā_k -= λ_r x_cᵀ` for block `k` at block row `r`, column `c`. The backward:
//! 1. refuses a forward that did not converge ([`Error::NotDifferentiable`] naming the solver,
//!    its stop, residual and tolerance): its `x` is not `A⁻¹ b`, so the formula above would be
//!    a silently wrong gradient;
//! 2. takes `x̄` and clears x's gradient (the solve wrote x: the initial guess gets no
//!    gradient);
//! 3. solves `Aᵀ λ = x̄` from `λ = 0` by the same method: CG and CR with `A` itself (they
//!    require it symmetric), BiCGSTAB and GMRES with [`Bsr::transpose`] of A (made at each
//!    backward, so it has A's values then); the same built-in preconditioner, computed from
//!    the matrix solved (Jacobi of Aᵀ's diagonal blocks); a user preconditioner is not reused
//!    (it applies `M⁻¹`, the adjoint needs `M⁻ᵀ`): that adjoint solve runs unpreconditioned.
//!    Its tolerance is relative to `|x̄|`: the forward's `rtol` (or, when that is 0, the
//!    relative tolerance its `atol` gave, `atol / |b|`), `atol` 0; its other options are the
//!    forward's. An adjoint solve that does not converge is an
//!    [`Error::NotDifferentiable`] naming it;
//! 4. `b̄ += λ` (when b has a gradient) and `Ā_k -= λ_r x_cᵀ` (when A's values have one,
//!    [`Bsr::with_grad`]), with the solution `x` as the forward left it (a copy taken then).
//!
//! `A` and `b` are read when backward runs, as a kernel's adjoint reads its arrays.

use super::{Pre, Precond, SolveOptions, SolveReport, Stop};
use crate::array::Array;
use crate::error::{Error, Result};
use crate::sparse::adjoint::{axpby, outer};
use crate::sparse::block::{Block, SparseScalar, SquareBlock};
use crate::sparse::Bsr;
use crate::tape;

/// The method a record's backward solves with: the solver's name, whether the adjoint solves
/// with A's transpose (BiCGSTAB, GMRES) or A itself (CG, CR: symmetric by requirement), and
/// the solver (the public function, passed in so that this file names none of theirs).
#[derive(Clone, Copy)]
pub(super) struct Method<B: SquareBlock> {
    pub name: &'static str,
    pub transpose: bool,
    pub solve: Solver<B>,
}

/// A solver: `(A, b, x, precond, options)`.
pub(super) type Solver<B> = fn(
    &Bsr<B>,
    &Array<<B as Block>::Scalar>,
    &Array<<B as Block>::Scalar>,
    Precond,
    &SolveOptions,
) -> Result<SolveReport>;

/// The adjoint solve's preconditioner for a forward preconditioned by `p`: the same built-in
/// one, none for a user's.
fn adjoint_precond<S>(p: &Pre<'_, S>) -> Precond {
    match p {
        Pre::Builtin(p) => *p,
        Pre::User(_) => Precond::None,
    }
}

/// A solver's public entry: runs the unrecorded `solve` with this thread's tapes paused (its
/// own steps and a user preconditioner's launches reach no tape), then records the whole solve
/// as one step of `method` ([`record`]).
pub(super) fn solve_recorded<'p, B: SquareBlock>(
    method: Method<B>,
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    pre: Pre<'p, B::Scalar>,
    o: &SolveOptions,
    solve: impl FnOnce(Pre<'p, B::Scalar>) -> Result<SolveReport>,
) -> Result<SolveReport> {
    let adjoint_pre = adjoint_precond(&pre);
    let report = {
        let _paused = tape::pause_recording();
        solve(pre)?
    };
    record(method, a, b, x, adjoint_pre, o, &report)?;
    Ok(report)
}

/// Records the solve `A x = b` by `method`, which stopped with `report`, on the tapes
/// recording on this thread (when one does and `x` has a gradient: without one nothing
/// flows back through x).
fn record<B: SquareBlock>(
    method: Method<B>,
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    precond: Precond,
    o: &SolveOptions,
    report: &SolveReport,
) -> Result<()> {
    if !x.requires_grad() || !tape::recording() {
        return Ok(());
    }
    // The solution as the forward left it (later work may write x in place).
    let solution = Array::<B::Scalar>::zeros(x.len(), x.device())?;
    solution.copy_from(x)?;
    let (a, b, x, o) = (a.clone(), b.clone(), x.clone(), *o);
    let (az, bz, xz) = (a.clone(), b.clone(), x.clone());
    let (stop, residual, tolerance, iterations) = (
        report.stop,
        report.residual,
        report.tolerance,
        report.iterations,
    );
    let name = method.name;
    tape::on_op(
        name,
        move || {
            let Some(xg) = x.grad() else { return Ok(()) };
            if stop != Stop::Converged {
                return Err(Error::NotDifferentiable {
                    kernel: name,
                    reason: format!(
                        "is a solve that stopped at {stop:?} after {iterations} iterations, \
                         residual {residual:e} above its tolerance {tolerance:e}: x is not \
                         A^-1 b, so its gradient would be wrong (solve to convergence: raise \
                         max_iter, or use a preconditioner)"
                    ),
                });
            }
            let _paused = tape::pause_recording();
            let dev = x.device();
            let seed = Array::<B::Scalar>::zeros(x.len(), dev)?;
            seed.copy_from(&xg)?;
            xg.fill(B::Scalar::ZERO)?;
            let lambda = Array::<B::Scalar>::zeros(x.len(), dev)?;
            let adj = adjoint_options(&o, tolerance, &b)?;
            let rep = if method.transpose {
                (method.solve)(&a.transpose()?, &seed, &lambda, precond, &adj)?
            } else {
                (method.solve)(&a, &seed, &lambda, precond, &adj)?
            };
            if !rep.converged {
                return Err(Error::NotDifferentiable {
                    kernel: name,
                    reason: format!(
                        "has an adjoint solve A^T lambda = x.grad (with {precond:?} \
                         preconditioning) that stopped at {:?} after {} iterations, residual \
                         {:e} above its tolerance {:e}: the gradient would be wrong",
                        rep.stop, rep.iterations, rep.residual, rep.tolerance
                    ),
                });
            }
            if let Some(bg) = b.grad() {
                axpby(&bg, 1.0, Some(&lambda), 1.0)?;
            }
            if let Some(ag) = a.values().grad() {
                outer(&a, &ag, -1.0, &lambda, &solution)?;
            }
            Ok(())
        },
        move || {
            az.values().zero_grad()?;
            bz.zero_grad()?;
            xz.zero_grad()
        },
    )
}

/// The adjoint solve's options: the forward's, with `atol` 0 and `rtol` the forward's (or,
/// when that is 0, `tolerance / |b|`, the relative tolerance the forward's atol gave; 1e-6
/// when b is 0).
fn adjoint_options<S: SparseScalar>(
    o: &SolveOptions,
    tolerance: f64,
    b: &Array<S>,
) -> Result<SolveOptions> {
    let rtol = if o.rtol > 0.0 {
        o.rtol
    } else {
        let bn = b
            .to_vec()?
            .iter()
            .map(|v| v.to_f64() * v.to_f64())
            .sum::<f64>()
            .sqrt();
        if bn > 0.0 && tolerance > 0.0 {
            tolerance / bn
        } else {
            SolveOptions::default().rtol
        }
    };
    Ok(SolveOptions {
        rtol,
        atol: 0.0,
        ..*o
    })
}

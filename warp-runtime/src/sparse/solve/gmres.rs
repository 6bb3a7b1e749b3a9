//! Restarted GMRES ([`gmres`]), right-preconditioned, for general systems.

use super::adjoint::{self, Method};
use super::steps::kr::{self, *};
use super::work::{at, Work};
use super::{check_args, drive, IntoPrecond, Pre, Queued, SolveOptions, SolveReport};
use crate::array::Array;
use crate::error::Result;
use crate::sparse::block::SquareBlock;
use crate::sparse::{invalid, Bsr};

/// Solves `A x = b` by restarted GMRES(m), `m = options.restart` (Warp's
/// `warp.optim.linear.gmres`), from the initial guess in `x`, which it overwrites, with
/// `precond` applied on the right (`A M^-1 u = b`, `x = M^-1 u`), so the residual it
/// minimises is the true system's. `precond` is a built-in
/// [`Precond`](super::Precond) or `&p` for your own [`Preconditioner`](super::Preconditioner) `p`.
///
/// `A` need not be symmetric. A cycle starts from `r = b - A x` and builds an orthonormal
/// basis `v_0 = r / |r|`, `v_1`, .. of the Krylov space of `A M^-1` by Arnoldi's process with
/// modified Gram-Schmidt (`w = A M^-1 v_j`, then for `i = 0..=j`: `h_ij = w . v_i`,
/// `w -= h_ij v_i`; `h_(j+1)j = |w|`, `v_(j+1) = w / h_(j+1)j`), one Arnoldi step per
/// iteration. The Hessenberg matrix is reduced by Givens rotations as it grows, which gives
/// the least-squares residual `|g_(j+1)|` of each step without forming x; that estimate is
/// the history's entry and the convergence test. At the cycle's end (m steps, or a stop) a
/// one-thread step solves the triangular system for `y` and `x += M^-1 V y`; the next cycle
/// restarts from the true residual, whose norm then replaces the history's last entry. The
/// small dense work (rotations, back substitution) runs in one device thread, so
/// [`Mode::Graph`](super::Mode::Graph) needs no host round trip.
///
/// It stops at convergence (`|r| <= max(atol, rtol |b|)`), after `max_iter` Arnoldi steps,
/// at a non-finite value (x then holds the last cycle's result), at a breakdown (a zero
/// column of the Hessenberg matrix, `"H_jj"`: x gets the cycle's earlier columns) or, before
/// iterating, at a singular preconditioner; each is an `Ok` report. The iterations, residuals
/// and the result are the same bits on the CPU and a GPU, and in both modes. It keeps
/// `m + 1` basis vectors; each cycle queues about `m^2` dot and update steps (MGS is
/// sequential), so a long restart costs launches. Arguments as [`cg`](super::cg)'s.
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
/// let o = SolveOptions { restart: 10, ..Default::default() };
/// let report = sparse::gmres(&a, &b, &x, Precond::Jacobi, &o)?;
/// assert_eq!(report.stop, Stop::Converged);
/// assert!(report.residual <= report.tolerance);
/// # Ok::<(), wp::Error>(())
/// ```
///
/// # Gradients
/// A recording [`Tape`](crate::Tape) records the solve as one step, differentiable with
/// respect to `b` and `A`'s values as [`cg`](super::cg)'s (its backward solves `Aᵀ λ = x̄`
/// by this method with a transpose of `A`).
///
/// # Errors
/// As [`cg`](super::cg)'s, naming `sparse::gmres`, and `restart` 0 or above 1024 (the
/// Hessenberg matrix, `(m + 1) m` scalars, lives in the one-thread step's reach).
pub fn gmres<'p, B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    precond: impl IntoPrecond<'p, B::Scalar>,
    o: &SolveOptions,
) -> Result<SolveReport> {
    let method = Method {
        name: "sparse::gmres",
        transpose: true,
        solve: |a, b, x, p, o| gmres(a, b, x, p, o),
    };
    adjoint::solve_recorded(method, a, b, x, precond.into_pre(), o, |pre| {
        solve(a, b, x, pre, o)
    })
}

/// The solve of [`gmres`], unrecorded.
fn solve<'p, B: SquareBlock>(
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    pre: Pre<'p, B::Scalar>,
    o: &SolveOptions,
) -> Result<SolveReport> {
    const F: &str = "sparse::gmres";
    let dev = check_args(F, a, b, x, o)?;
    let m = o.restart;
    if !(1..=MAX_RESTART).contains(&m) {
        return Err(invalid(
            F,
            format!("`restart` is {m}; it must be in 1..={MAX_RESTART}"),
        ));
    }
    let mut w = Work::new(a, &dev, b, x, pre, g_len(m), o)?;
    let n = w.n;
    let pre = w.preconditioned();
    let s = Gmres {
        m,
        basis: w.vector((m + 1) * n)?,
        z: if pre { Some(w.vector(n)?) } else { None },
        w,
    };
    drive(&s, &dev, o)?;
    s.w.report(F)
}

/// The largest restart length: the one-thread steps loop over the Hessenberg matrix's
/// `(m + 1) m` entries (m^2 / 2 for the back substitution), which stays small beside the
/// cycle's m^2 / 2 vector steps up to here.
const MAX_RESTART: usize = 1024;

/// One GMRES(m) solve: the basis `V` (`m + 1` vectors of n, one array) and with a
/// preconditioner `z` (`M^-1 v_j`, then `M^-1 V y`).
struct Gmres<'a, B: SquareBlock> {
    w: Work<'a, B>,
    m: usize,
    basis: Array<B::Scalar>,
    z: Option<Array<B::Scalar>>,
}

impl<B: SquareBlock> Gmres<'_, B> {
    /// The address of basis vector `k`.
    fn v(&self, k: usize) -> u64 {
        at(&self.basis, k * self.w.n)
    }
}

impl<B: SquareBlock> Queued for Gmres<'_, B> {
    fn ctl(&self) -> &Array<i32> {
        &self.w.ctl
    }

    fn unit_iterations(&self) -> usize {
        self.m
    }

    fn setup(&self) -> Result<()> {
        self.w.setup()?;
        self.w.scalar::<{ kr::GMRES }>(0, self.m, 0)
    }

    /// A cycle: the Arnoldi steps, the update of x, then the next cycle's start (the true
    /// residual and its check).
    fn unit(&self) -> Result<()> {
        let (w, m) = (&self.w, self.m);
        let (r, x) = (w.r.device_address(), w.x.device_address());
        let g = g_g(m);
        w.vec(OP_DIV, self.v(0), r, 0, g, 0, GATE_ACTIVE)?;
        for j in 0..m {
            let (vj, wv) = (self.v(j), self.v(j + 1));
            let z = match &self.z {
                Some(za) => {
                    let n = w.n;
                    w.apply(&self.basis.view(j * n..(j + 1) * n)?, za)?;
                    za.device_address()
                }
                None => vj,
            };
            // w = A M^-1 v_j into the next basis vector, orthogonalised in place.
            w.mv(z, wv, 1.0, 0.0)?;
            for i in 0..=j {
                let h = G_H + i * m + j;
                w.dot(wv, self.v(i), h)?;
                w.vec(OP_AXMY, wv, self.v(i), 0, h, 0, GATE_ACTIVE)?;
            }
            w.dot(wv, wv, G_HN)?;
            w.scalar::<{ kr::GMRES }>(2, m, j)?;
            w.vec(OP_DIV, wv, wv, 0, G_HN, 0, GATE_ACTIVE)?;
        }
        w.scalar::<{ kr::GMRES }>(3, m, 0)?;
        match &self.z {
            Some(za) => {
                // u = V y into r (free until the next residual), z = M^-1 u, x += z.
                w.comb(r, self.basis.device_address(), m, false)?;
                w.apply(&w.r, za)?;
                w.vec(OP_ADD, x, za.device_address(), 0, 0, 0, GATE_PENDING)?;
            }
            None => w.comb(x, self.basis.device_address(), m, true)?,
        }
        w.scalar::<{ kr::GMRES }>(4, m, 0)?;
        w.residual()?;
        w.dot(r, r, RR)?;
        w.scalar::<{ kr::GMRES }>(1, m, 0)
    }
}

//! The Krylov solvers: conjugate gradients ([`cg`]), conjugate residuals ([`cr`]), BiCGSTAB
//! ([`bicgstab`]) and restarted GMRES ([`gmres`]), each with no, point or block Jacobi
//! preconditioning, driven from the host or captured (`Mode::Graph`).
//!
//! Every scalar of an iteration (the dots, the step lengths, the tolerance) lives on the device
//! and is computed there by the same steps on every backend, so the CPU and a GPU take the same
//! iterations and write the same history. The host queues [`SolveOptions::check_every`]
//! iterations at a time and then reads the control words (a synchronisation); iterations
//! queued after the stop do nothing (each step that writes `x` or the recurrences first reads
//! the stop word), so the result does not depend on `check_every`.
//!
//! The options, the report, the argument checks and the two drivers are shared here; each
//! method's steps are in its own file (`cg.rs`, `bicgstab.rs`, `cr.rs`, `gmres.rs`), and the
//! steps of the last three in `steps.rs` (`wp_sparse.h`'s Krylov section).

// Slice 5: the solves on a tape.
mod adjoint;
mod bicgstab;
mod cg;
mod cr;
mod gmres;
pub(crate) mod steps;
mod work;

pub use bicgstab::bicgstab;
pub use cg::cg;
pub use cr::cr;
pub use gmres::gmres;
pub(crate) use sealed::Pre;

use super::block::{Block, SparseScalar};
use super::steps::cg as c;
use super::{contiguous, invalid, overlap, same_device, Bsr};
use crate::array::Array;
use crate::device::Device;
use crate::error::Result;

/// The built-in preconditioners of a solve. A solver's `precond` argument is one of these or
/// `&p` for your own `p:` [`Preconditioner`] (see [`IntoPrecond`]).
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

/// A user preconditioner: applies `z = M^-1 r` by queuing device work on the solve's device
/// (kernel launches, [`mv`](crate::sparse::mv), array copies). Pass `&p` as a solver's
/// `precond`; a closure `|r: &Array<S>, z: &Array<S>| -> Result<()>` is one.
///
/// The solver calls it with two distinct arrays of the system's scalar length, `r` to read
/// and `z` to write completely (views of the solver's own arrays), each call queued in order
/// with the solver's steps: [`cg`] once in the set-up and once per iteration, [`cr`] once in
/// the set-up and twice per iteration, [`bicgstab`] twice per iteration, [`gmres`] once per
/// Arnoldi step and once per restart cycle. It is also called for the iterations queued after the solve stopped (up to
/// `check_every` of them, and in [`Mode::Graph`] once more before the capture, to load the
/// kernels): those outputs are unused, and their inputs may be stale or non-finite (after
/// [`Stop::NonFinite`]), so it must neither fail on such input (a fault it raises would turn
/// the solve's `Ok` into an error) nor keep state from it. In
/// [`Mode::Graph`] the calls happen inside the solver's capture, so the work it queues is
/// recorded (and replayed each iteration of the captured loop): it must be capturable (no
/// read-back or allocation, which a capture refuses with an error that the solve returns),
/// and it must not depend on host state that changes between calls. `M` must be the same
/// linear operator at every call (the methods are not flexible), symmetric positive
/// definite for [`cg`] and [`cr`]. The same bits on the CPU and a GPU hold only when the
/// operator gives them.
///
/// ```
/// # use warp_runtime as wp;
/// use wp::sparse::{self, Bsr, SolveOptions, Stop};
/// let dev = wp::cpu();
/// // A = diag(1, 2, .., 8) plus 0.25 between neighbours; M^-1 = diag(1, 1/2, ..) as a matrix.
/// let n = 8i32;
/// let (mut r, mut c, mut v) = (vec![], vec![], vec![]);
/// for i in 0..n {
///     for (j, x) in [(i - 1, 0.25f64), (i, (i + 1) as f64), (i + 1, 0.25)] {
///         if (0..n).contains(&j) {
///             r.push(i);
///             c.push(j);
///             v.push(x);
///         }
///     }
/// }
/// let arr = |v: &[i32]| wp::Array::from_slice(v, &dev);
/// let a = Bsr::from_triplets(8, 8, &arr(&r)?, &arr(&c)?, &wp::Array::from_slice(&v, &dev)?)?;
/// let inv: Vec<f64> = (0..n).map(|i| 1.0 / (i + 1) as f64).collect();
/// let ids: Vec<i32> = (0..n).collect();
/// let m = Bsr::from_triplets(8, 8, &arr(&ids)?, &arr(&ids)?, &wp::Array::from_slice(&inv, &dev)?)?;
/// let precond = |r: &wp::Array<f64>, z: &wp::Array<f64>| sparse::mv(1.0, &m, r, 0.0, z);
/// let b = wp::Array::from_slice(&[1.0f64; 8], &dev)?;
/// let x = wp::Array::<f64>::zeros(8, &dev)?;
/// let report = sparse::cg(&a, &b, &x, &precond, &SolveOptions::default())?;
/// assert_eq!(report.stop, Stop::Converged);
/// # Ok::<(), wp::Error>(())
/// ```
pub trait Preconditioner<S: SparseScalar> {
    /// Queues `z = M^-1 r`.
    ///
    /// # Errors
    /// Whatever the queued work returns; the solve stops and returns it.
    fn apply(&self, r: &Array<S>, z: &Array<S>) -> Result<()>;
}

impl<S: SparseScalar, F: Fn(&Array<S>, &Array<S>) -> Result<()>> Preconditioner<S> for F {
    fn apply(&self, r: &Array<S>, z: &Array<S>) -> Result<()> {
        self(r, z)
    }
}

/// What a solver's `precond` argument accepts: a built-in [`Precond`], or `&p` for a user
/// [`Preconditioner`] `p` (a closure included). Sealed.
pub trait IntoPrecond<'p, S: SparseScalar>: sealed::Sealed<'p, S> {}

impl<'p, S: SparseScalar> IntoPrecond<'p, S> for Precond {}
impl<'p, S: SparseScalar, P: Preconditioner<S>> IntoPrecond<'p, S> for &'p P {}

pub(crate) mod sealed {
    use super::{Precond, Preconditioner};
    use crate::sparse::block::SparseScalar;

    /// A solve's preconditioner, resolved.
    pub enum Pre<'p, S> {
        /// A built-in one.
        Builtin(Precond),
        /// The user's.
        User(&'p dyn Preconditioner<S>),
    }

    impl<S> std::fmt::Debug for Pre<'_, S> {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            match self {
                Pre::Builtin(p) => write!(f, "{p:?}"),
                Pre::User(_) => f.write_str("User"),
            }
        }
    }

    /// The conversion behind [`IntoPrecond`](super::IntoPrecond).
    pub trait Sealed<'p, S> {
        fn into_pre(self) -> Pre<'p, S>;
    }

    impl<'p, S: SparseScalar> Sealed<'p, S> for Precond {
        fn into_pre(self) -> Pre<'p, S> {
            Pre::Builtin(self)
        }
    }

    impl<'p, S: SparseScalar, P: Preconditioner<S>> Sealed<'p, S> for &'p P {
        fn into_pre(self) -> Pre<'p, S> {
            Pre::User(self)
        }
    }
}

/// Options of the solvers.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SolveOptions {
    /// Stop when `|r| <= max(atol, rtol * |b|)` (default 1e-6). The test compares squared
    /// norms in the scalar type, so the tolerance must be representable squared: for `f32`,
    /// a tolerance below about 1e-19 squares to 0 (only an exact zero residual converges),
    /// and `|b|` above about 1e19 overflows `b . b` (reported as [`Stop::NonFinite`] or
    /// an infinite tolerance).
    pub rtol: f64,
    /// The absolute tolerance (default 0).
    pub atol: f64,
    /// The most iterations (default 1000); reaching it is [`Stop::MaxIterations`]. For
    /// [`gmres`] an iteration is one Arnoldi step (one product with `A`).
    pub max_iter: usize,
    /// Iterations queued between two reads of the solver's state by the host
    /// ([`Mode::Host`]), or per pass of the captured loop ([`Mode::Graph`]) (default 10; at
    /// least 1). Either way at most `max_iter` are queued at once (a larger value, even
    /// `usize::MAX`, means "check only at the end"). [`gmres`] queues whole restart cycles:
    /// `check_every / restart` of them, at least one. It changes the work done after a stop,
    /// never the result.
    pub check_every: usize,
    /// How the iterations are driven (default [`Mode::Host`]).
    pub mode: Mode,
    /// [`gmres`]'s restart length `m`: Arnoldi steps per cycle, each keeping one more basis
    /// vector (default 30; 1 to 1024). A cycle queues about `6 m + 3 m (m + 1) / 2` steps
    /// (modified Gram-Schmidt: a dot and an update per pair), which a [`Mode::Graph`] solve
    /// records as graph nodes: about 1,500 at 30, 26,000 at 128, 1.6 million at 1024, whose
    /// instantiation takes seconds and much memory. The other methods ignore it.
    pub restart: usize,
}

/// How a solver drives its iterations. Both run the same steps and give the same result,
/// bit for bit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// The host queues [`SolveOptions::check_every`] iterations, then reads the solver's
    /// state (a synchronisation), until a stop.
    #[default]
    Host,
    /// The set-up and a [`capture_while`](crate::capture_while) loop on the device's stop
    /// flag are captured once and the graph launched: no host synchronisation until the
    /// report is read. On a GPU this needs conditional graph nodes (a CUDA 12.4 driver and
    /// the toolkit's `libcudadevrt.a`), else it is an [`Error::Capture`](crate::Error::Capture).
    Graph,
}

impl Default for SolveOptions {
    fn default() -> Self {
        SolveOptions {
            rtol: 1e-6,
            atol: 0.0,
            max_iter: 1000,
            check_every: 10,
            mode: Mode::Host,
            restart: 30,
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
    /// A NaN or infinity appeared (in the residual or a scalar of the iteration): the
    /// matrix, `b`, the initial `x` or the preconditioner holds one, or the iteration
    /// overflowed.
    NonFinite,
    /// The method broke down: a quantity it divides by (or needs positive) is zero (or not
    /// positive). `what` names it, `value` is its value:
    ///
    /// | method | `what` | when |
    /// |---|---|---|
    /// | [`cg`] | `"p.Ap"` | `p . Ap <= 0`: `A` is not positive definite |
    /// | [`cg`] | `"r.z"` | `r . z <= 0` for `r != 0`: the preconditioner is not positive definite |
    /// | [`cr`] | `"z.Az"` | `z . Az == 0` for `r != 0` (`z = M^-1 r`): possible when `A` is indefinite |
    /// | [`cr`] | `"Ap.M^-1Ap"` | `Ap . M^-1 Ap == 0`: `A p = 0`, `A` singular |
    /// | [`bicgstab`] | `"r0.v"` | the shadow residual is orthogonal to `v = A M^-1 p` |
    /// | [`bicgstab`] | `"omega"` | the stabilising step `omega = t.s / t.t` is 0 |
    /// | [`bicgstab`] | `"rho"` | `rho = r0 . r` is 0 for `r != 0` |
    /// | [`gmres`] | `"H_jj"` | a Givens rotation of the Hessenberg matrix meets a zero column: `A M^-1` is singular on the Krylov space |
    ///
    /// `x` holds the last iterate: for cg, a `p . Ap` breakdown leaves it as the iteration
    /// before found it, an `r . z` breakdown after the iteration that computed it; for
    /// the others, the iterate of the last completed step (GMRES: the cycle's columns before
    /// the singular one).
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
    /// rounding may move away from the true `|b - A x|`; GMRES's least-squares estimate).
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

/// The checks every solver makes of its arguments before anything is queued (function `f`).
fn check_args<B: Block>(
    f: &'static str,
    a: &Bsr<B>,
    b: &Array<B::Scalar>,
    x: &Array<B::Scalar>,
    o: &SolveOptions,
) -> Result<Device> {
    let dev = a.device().clone();
    // The host-driven loop reads the solver's state back: never inside a capture.
    crate::capturing::refuse(Some(&dev), &format!("{f} (a host-driven solve)"))?;
    same_device(f, "b", &dev, b.device())?;
    same_device(f, "x", &dev, x.device())?;
    contiguous(f, "b", b)?;
    contiguous(f, "x", x)?;
    let (nr, nc) = a.shape();
    if a.nrow() != a.ncol() {
        return Err(invalid(
            f,
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
                f,
                format!(
                    "argument `{name}` has shape {:?}, but the matrix is {nr} x {nc} scalars",
                    v.shape()
                ),
            ));
        }
    }
    if overlap(b, x) {
        return Err(invalid(f, "arguments `b` and `x` overlap in memory"));
    }
    if a.overlaps(x) {
        return Err(invalid(f, "argument `x` overlaps the matrix's arrays"));
    }
    if o.check_every == 0 {
        return Err(invalid(f, "`check_every` is 0; it must be at least 1"));
    }
    if o.max_iter > i32::MAX as usize - 1 {
        return Err(invalid(
            f,
            format!("`max_iter` {} is above {}", o.max_iter, i32::MAX - 1),
        ));
    }
    for (name, t) in [("rtol", o.rtol), ("atol", o.atol)] {
        if !(t >= 0.0 && t.is_finite()) {
            return Err(invalid(
                f,
                format!("`{name}` is {t}; it must be finite and >= 0"),
            ));
        }
    }
    Ok(dev)
}

/// A solve's queued work, for the two drivers: the set-up, and a unit of iterations (one for
/// cg, cr and BiCGSTAB; a restart cycle of up to `unit_iterations` for GMRES).
trait Queued {
    /// The control words (`CTL_STOP`, .., `CTL_RUN` first).
    fn ctl(&self) -> &Array<i32>;
    /// The most iterations a unit runs.
    fn unit_iterations(&self) -> usize {
        1
    }
    /// Queues (or records) the set-up: the control words reset, the residual, the
    /// preconditioner, the set-up check.
    fn setup(&self) -> Result<()>;
    /// Queues (or records) a unit; each of its steps does nothing once a stop is set.
    fn unit(&self) -> Result<()>;
}

/// Runs a solve to its stop in mode `o.mode`.
fn drive(q: &impl Queued, dev: &Device, o: &SolveOptions) -> Result<()> {
    let per_unit = q.unit_iterations().max(1);
    // Units per check (at least one), and units that reach max_iter (at least one: an empty
    // pass would record nothing).
    let per_check = (o.check_every / per_unit).max(1);
    let max_units = o.max_iter.div_ceil(per_unit);
    match o.mode {
        Mode::Host => {
            q.setup()?;
            let mut queued = 0;
            let mut words = q.ctl().to_vec()?;
            while words[c::CTL_STOP] == c::STOP_NONE && queued < max_units {
                for _ in 0..per_check.min(max_units - queued) {
                    q.unit()?;
                    queued += 1;
                }
                words = q.ctl().to_vec()?;
            }
        }
        Mode::Graph => {
            // Every kernel of the solve runs once before the capture (a GPU loads them at
            // their first use, which a capture refuses): the set-up, then a unit with the
            // control words set to -1, which leaves x alone (each step first reads them).
            q.setup()?;
            q.ctl().fill(-1)?;
            q.unit()?;
            let run = q.ctl().view(c::CTL_RUN..c::CTL_RUN + 1)?;
            // Each pass records its units, so a huge `check_every` (a sensible "never sync"
            // in Host mode) must not be recorded as is: a pass never needs more than the
            // units of `max_iter` iterations, since the checks stop the solve there and every
            // unit after a stop does nothing. So the cap cannot change the result, only the
            // size of the graph.
            let per_pass = per_check.min(max_units.max(1));
            let graph = crate::graph::capture(dev, || {
                q.setup()?;
                crate::graph::capture_while(&run, || {
                    for _ in 0..per_pass {
                        q.unit()?;
                    }
                    Ok(())
                })
            })?;
            graph.launch()?;
        }
    }
    Ok(())
}

/// The report of function `f` from the control words, the tolerance and breakdown value
/// and the history (read back); `breakdown` names a breakdown stop code (given the words).
fn report<S: SparseScalar>(
    f: &'static str,
    words: &[i32],
    tol: S,
    brk: S,
    history: &Array<S>,
    breakdown: impl Fn(i32, &[i32]) -> Option<&'static str>,
) -> Result<SolveReport> {
    let iterations = words[c::CTL_ITER];
    let internal = |what: String| {
        crate::error::Error::invalid(format!("{f}: internal: the solver ended with {what}"))
    };
    // The device caps the count at max_iter; a bad word is an internal error, not a panic.
    let all = history.to_vec()?;
    let history: Vec<f64> = usize::try_from(iterations)
        .ok()
        .and_then(|i| all.get(..=i))
        .ok_or_else(|| internal(format!("iteration count {iterations}")))?
        .iter()
        .map(|v| v.to_f64())
        .collect();
    let iterations = history.len() - 1;
    let stop = match words[c::CTL_STOP] {
        c::STOP_CONVERGED => Stop::Converged,
        c::STOP_MAX_ITER => Stop::MaxIterations,
        c::STOP_NON_FINITE => Stop::NonFinite,
        c::STOP_SINGULAR => Stop::SingularPreconditioner {
            block_row: words[c::CTL_BAD] as usize,
        },
        w => match breakdown(w, words) {
            Some(what) => Stop::Breakdown {
                what,
                value: brk.to_f64(),
            },
            // Both loops end only at a stop (max_iter bounds them on the device).
            None => return Err(internal(format!("stop word {w}"))),
        },
    };
    Ok(SolveReport {
        iterations,
        residual: history[iterations],
        tolerance: tol.to_f64(),
        converged: stop == Stop::Converged,
        stop,
        history,
    })
}

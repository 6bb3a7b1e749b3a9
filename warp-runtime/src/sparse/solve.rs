//! The conjugate gradient solver with Jacobi preconditioning, driven from the host or
//! captured (`Mode::Graph`).
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
use crate::backend::ObjectStep;
use crate::capturing::Keep;
use crate::device::Device;
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
    /// Stop when `|r| <= max(atol, rtol * |b|)` (default 1e-6). The test compares squared
    /// norms in the scalar type, so the tolerance must be representable squared: for `f32`,
    /// a tolerance below about 1e-19 squares to 0 (only an exact zero residual converges),
    /// and `|b|` above about 1e19 overflows `b . b` (reported as [`Stop::NonFinite`] or
    /// an infinite tolerance).
    pub rtol: f64,
    /// The absolute tolerance (default 0).
    pub atol: f64,
    /// The most iterations (default 1000); reaching it is [`Stop::MaxIterations`].
    pub max_iter: usize,
    /// Iterations queued between two reads of the solver's state by the host
    /// ([`Mode::Host`]), or per pass of the captured loop ([`Mode::Graph`]) (default 10; at
    /// least 1). Either way at most `max_iter` are queued at once (a larger value, even
    /// `usize::MAX`, means "check only at the end"). It changes the work done after a stop,
    /// never the result.
    pub check_every: usize,
    /// How the iterations are driven (default [`Mode::Host`]).
    pub mode: Mode,
}

/// How [`cg`] drives its iterations. Both run the same steps and give the same result,
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
    /// which a symmetric positive definite matrix never gives, or `r . z <= 0` for a nonzero
    /// residual (`what` is `"r.z"`), which a symmetric positive definite preconditioner never
    /// gives (a Jacobi preconditioner of a diagonal with a negative entry may). `x` holds the
    /// last iterate: a `p . Ap` breakdown leaves it as the iteration before found it, an
    /// `r . z` breakdown after the iteration that computed it.
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
/// non-finite value, at a breakdown (`p . Ap <= 0` or `r . z <= 0`) or, before iterating, at
/// a singular preconditioner; each is an `Ok` report (see [`Stop`]). The iterations,
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
/// # Errors
/// [`Error::Capture`](crate::Error::Capture) inside a capture (the loop reads back);
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::cg`, the
/// argument and both shapes: a matrix that is not square in blocks, `b` or `x` of another
/// length, arrays that are not contiguous or overlap, `check_every == 0`, `max_iter` above
/// `i32::MAX - 1`, a negative or non-finite tolerance;
/// [`Error::DeviceMismatch`](crate::Error::DeviceMismatch); a fault of the queued work
/// (reported by its read-backs).
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
        pre: match precond {
            Precond::None => None,
            Precond::Jacobi | Precond::PointJacobi => Some(Jacobi {
                dinv: Array::zeros(a.nrow() * B::ROWS * B::ROWS, &dev)?,
                z,
                point: precond == Precond::PointJacobi,
            }),
        },
        ctl: Array::zeros(c::CTL_LEN, &dev)?,
        ctl0: Array::from_slice(&[c::STOP_NONE, 0, i32::MAX, 0], &dev)?,
        scal: Array::zeros(c::SCAL_LEN, &dev)?,
        history: Array::zeros(o.max_iter + 1, &dev)?,
        partials: dot_partials::<S<B>>(n, &dev)?,
        o: *o,
    };
    match o.mode {
        Mode::Host => {
            cg.setup()?;
            let mut queued = 0;
            let mut words = cg.ctl.to_vec()?;
            while words[c::CTL_STOP] == c::STOP_NONE && queued < o.max_iter {
                for _ in 0..o.check_every.min(o.max_iter - queued) {
                    cg.iteration()?;
                    queued += 1;
                }
                words = cg.ctl.to_vec()?;
            }
        }
        Mode::Graph => {
            // Every kernel of the solve runs once before the capture (a GPU loads them at
            // their first use, which a capture refuses): the set-up, then an iteration with
            // the stop word set, which leaves x alone (each step first reads the stop word).
            cg.setup()?;
            cg.ctl.fill(-1)?;
            cg.iteration()?;
            let run = cg.ctl.view(c::CTL_RUN..c::CTL_RUN + 1)?;
            // Each pass records its iterations, so a huge `check_every` (a sensible "never
            // sync" in Host mode) must not be recorded as is: a pass never needs more than
            // `max_iter` iterations, since the check stops the solve at `max_iter` and every
            // iteration after a stop does nothing. So the cap cannot change the result, only
            // the size of the graph (at least 1: an empty body would record nothing).
            let per_pass = o.check_every.min(o.max_iter.max(1));
            let graph = crate::graph::capture(&dev, || {
                cg.setup()?;
                crate::graph::capture_while(&run, || {
                    for _ in 0..per_pass {
                        cg.iteration()?;
                    }
                    Ok(())
                })
            })?;
            graph.launch()?;
        }
    }
    cg.report()
}

/// The block Jacobi preconditioner's state: the inverted diagonal blocks and `z = D^-1 r`.
struct Jacobi<S: SparseScalar> {
    dinv: Array<S>,
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

    /// `z = D^-1 r` (nothing without a preconditioner).
    fn apply(&self) -> Result<()> {
        match &self.pre {
            Some(j) => self.step(JacobiApply::<B::Scalar> {
                dinv: j.dinv.device_address(),
                r: self.r.device_address(),
                z: j.z.device_address(),
                nrow: self.a.nrow() as i32,
                dim: B::ROWS as i32,
                scalar: PhantomData,
            }),
            None => Ok(()),
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
        if let Some(j) = &self.pre {
            self.step(JacobiInv::<B> {
                offsets: a.offsets().device_address(),
                columns: a.columns().device_address(),
                values: a.values().device_address(),
                dinv: j.dinv.device_address(),
                bad: self.ctl.view(c::CTL_BAD..c::CTL_BAD + 1)?.device_address(),
                nrow: a.nrow() as i32,
                point: j.point as i32,
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
        const F: &str = "sparse::cg";
        let words = self.ctl.to_vec()?;
        let sc = self.scal.to_vec()?;
        let iterations = words[c::CTL_ITER];
        let internal = |what: String| {
            crate::error::Error::invalid(format!("{F}: internal: the solver ended with {what}"))
        };
        // The device caps the count at max_iter; a bad word is an internal error, not a panic.
        let all = self.history.to_vec()?;
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
            c::STOP_BREAKDOWN => Stop::Breakdown {
                what: "p.Ap",
                value: sc[c::BREAK].to_f64(),
            },
            c::STOP_BREAKDOWN_RZ => Stop::Breakdown {
                what: "r.z",
                value: sc[c::BREAK].to_f64(),
            },
            c::STOP_SINGULAR => Stop::SingularPreconditioner {
                block_row: words[c::CTL_BAD] as usize,
            },
            // Both loops end only at a stop (max_iter bounds them on the device).
            w => return Err(internal(format!("stop word {w}"))),
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
}

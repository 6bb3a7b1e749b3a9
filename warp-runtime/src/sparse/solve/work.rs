//! What BiCGSTAB, CR and GMRES share: their arrays (all allocated before anything is queued,
//! so that the steps can be captured) and the queueing of their steps over addresses.

use super::steps::{kr, KrComb, KrScalar, KrVec};
use super::{report, Pre, Precond, Preconditioner, SolveOptions, SolveReport};
use crate::array::Array;
use crate::backend::ObjectStep;
use crate::capturing::Keep;
use crate::device::Device;
use crate::dispatch;
use crate::error::Result;
use crate::sparse::block::{Block, SparseScalar};
use crate::sparse::steps::{cg as c, JacobiApply, JacobiInv};
use crate::sparse::{dot_partials, dot_raw, mv_raw, Bsr};
use std::marker::PhantomData;

/// A solve's common state: the matrix, `b`, `x`, the residual `r`, the Jacobi inverse (when
/// preconditioned), the control words, the scalars, the history, the dot's scratch, and the
/// method's own vectors (`vecs`, kept alive by a recording graph).
pub(super) struct Work<'a, B: Block> {
    pub a: &'a Bsr<B>,
    pub dev: Device,
    /// Scalars of each vector.
    pub n: usize,
    pub b: &'a Array<B::Scalar>,
    pub x: &'a Array<B::Scalar>,
    pub r: Array<B::Scalar>,
    /// The inverted diagonal blocks (block or point Jacobi), if any.
    pub dinv: Option<(Array<B::Scalar>, bool)>,
    /// The user's preconditioner, if any.
    user: Option<&'a dyn Preconditioner<B::Scalar>>,
    pub ctl: Array<i32>,
    ctl0: Array<i32>,
    pub scal: Array<B::Scalar>,
    pub history: Array<B::Scalar>,
    partials: Array<B::Scalar>,
    vecs: Vec<Array<B::Scalar>>,
    pub o: SolveOptions,
}

impl<'a, B: Block> Work<'a, B> {
    /// The state of a solve with `scalars` scalars.
    pub fn new(
        a: &'a Bsr<B>,
        dev: &Device,
        b: &'a Array<B::Scalar>,
        x: &'a Array<B::Scalar>,
        precond: Pre<'a, B::Scalar>,
        scalars: usize,
        o: &SolveOptions,
    ) -> Result<Self> {
        let n = b.len();
        let mut ctl0 = vec![0; kr::CTL_LEN];
        ctl0[c::CTL_STOP] = c::STOP_NONE;
        ctl0[c::CTL_BAD] = i32::MAX;
        Ok(Work {
            a,
            dev: dev.clone(),
            n,
            b,
            x,
            r: Array::zeros(n, dev)?,
            dinv: match precond {
                Pre::Builtin(p @ (Precond::Jacobi | Precond::PointJacobi)) => Some((
                    Array::zeros(a.nrow() * B::ROWS * B::ROWS, dev)?,
                    p == Precond::PointJacobi,
                )),
                Pre::Builtin(Precond::None) | Pre::User(_) => None,
            },
            user: match precond {
                Pre::User(u) => Some(u),
                Pre::Builtin(_) => None,
            },
            ctl: Array::zeros(kr::CTL_LEN, dev)?,
            ctl0: Array::from_slice(&ctl0, dev)?,
            scal: Array::zeros(scalars, dev)?,
            history: Array::zeros(o.max_iter + 1, dev)?,
            partials: dot_partials::<B::Scalar>(n, dev)?,
            vecs: vec![],
            o: *o,
        })
    }

    /// A new vector of `len` scalars of the method's (kept alive with the solve's arrays).
    pub fn vector(&mut self, len: usize) -> Result<Array<B::Scalar>> {
        let v = Array::zeros(len, &self.dev)?;
        self.vecs.push(v.clone());
        Ok(v)
    }

    /// What a graph recording the steps keeps alive: every array they address.
    pub fn keep(&self) -> impl Fn() -> Keep + '_ {
        move || {
            Box::new((
                (
                    self.a.clone(),
                    self.b.clone(),
                    self.x.clone(),
                    self.r.clone(),
                ),
                self.dinv.as_ref().map(|d| d.0.clone()),
                (self.ctl.clone(), self.ctl0.clone(), self.scal.clone()),
                (self.history.clone(), self.partials.clone()),
                self.vecs.clone(),
            ))
        }
    }

    /// Queues (or records) an object step of the solve.
    pub fn step<T: ObjectStep + 'static>(&self, step: T) -> Result<()> {
        dispatch::object_step_keeping(&self.dev, &step, self.keep())
    }

    /// The address of scalar slot `k`.
    fn slot(&self, k: usize) -> u64 {
        self.scal.device_address() + (k * std::mem::size_of::<B::Scalar>()) as u64
    }

    /// `u . v` (addresses of n-scalar vectors of the solve) into scalar `k`.
    pub fn dot(&self, u: u64, v: u64, k: usize) -> Result<()> {
        // SAFETY: the callers pass addresses of the solve's n-scalar vectors (b, x, r, or
        // its own arrays of n, or n-scalar slices of its basis); the slot is a scalar of
        // `scal` (another array), the partials are sized for n, and `keep` holds every
        // array of the solve.
        unsafe {
            dot_raw(
                &self.dev,
                u,
                v,
                self.n,
                &self.partials,
                self.slot(k),
                self.keep(),
            )
        }
    }

    /// `y = alpha A x + beta y` over addresses of n-scalar vectors of the solve.
    pub fn mv(&self, x: u64, y: u64, alpha: f64, beta: f64) -> Result<()> {
        // SAFETY: x and y address n = nrow * ROWS scalars (the matrix is square in blocks:
        // checked) of the solve's own distinct arrays, or x of the user's x (checked not to
        // overlap the matrix) with y the solve's r; `keep` holds every array of the solve.
        unsafe { mv_raw(self.a, x, y, alpha, beta, self.keep()) }
    }

    /// `z = M^-1 r` (distinct n-scalar vectors of the solve), with a preconditioner; nothing
    /// without one (the callers then use r for z).
    pub fn apply(&self, r: &Array<B::Scalar>, z: &Array<B::Scalar>) -> Result<()> {
        if let Some(u) = self.user {
            return u.apply(r, z);
        }
        match &self.dinv {
            Some((dinv, _)) => self.step(JacobiApply::<B::Scalar> {
                dinv: dinv.device_address(),
                r: r.device_address(),
                z: z.device_address(),
                nrow: self.a.nrow() as i32,
                dim: B::ROWS as i32,
                scalar: PhantomData,
            }),
            None => Ok(()),
        }
    }

    /// Whether there is a preconditioner.
    pub fn preconditioned(&self) -> bool {
        self.dinv.is_some() || self.user.is_some()
    }

    /// A gated vector update `op` of the n-scalar vectors at y, x, w with scalars `ia`, `ib`.
    #[allow(clippy::too_many_arguments)]
    pub fn vec(
        &self,
        op: i32,
        y: u64,
        x: u64,
        w: u64,
        ia: usize,
        ib: usize,
        gate: i32,
    ) -> Result<()> {
        self.step(KrVec::<B::Scalar> {
            ctl: self.ctl.device_address(),
            scal: self.scal.device_address(),
            y,
            x,
            w,
            n: self.n as i64,
            op,
            ia: ia as i32,
            ib: ib as i32,
            gate,
            scalar: PhantomData,
        })
    }

    /// GMRES's combination of the basis at `v` ((m + 1) n scalars) into `out`.
    pub fn comb(&self, out: u64, v: u64, m: usize, add: bool) -> Result<()> {
        self.step(KrComb::<B::Scalar> {
            ctl: self.ctl.device_address(),
            scal: self.scal.device_address(),
            out,
            v,
            n: self.n as i64,
            iy: kr::g_y(m) as i32,
            add: add as i32,
            m: m as i32,
            pad: 0,
            scalar: PhantomData,
        })
    }

    /// The method's one-thread step of `phase` (GMRES: column `j` of `m`).
    pub fn scalar<const METHOD: u8>(&self, phase: i32, m: usize, j: usize) -> Result<()> {
        self.step(KrScalar::<B::Scalar, METHOD> {
            ctl: self.ctl.device_address(),
            scal: self.scal.device_address(),
            history: self.history.device_address(),
            rtol: self.o.rtol,
            atol: self.o.atol,
            max_iter: self.o.max_iter as i32,
            phase,
            m: m as i32,
            j: j as i32,
            scalar: PhantomData,
        })
    }

    /// The set-up common to the methods: the control words reset, `r = b - A x`, the Jacobi
    /// inverse (a bad block lowers `CTL_BAD`), `b . b` and `r . r`.
    pub fn setup(&self) -> Result<()> {
        let a = self.a;
        self.ctl.copy_from(&self.ctl0)?;
        self.residual()?;
        if let Some((dinv, point)) = &self.dinv {
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
        let (b, r) = (self.b.device_address(), self.r.device_address());
        self.dot(b, b, kr::BB)?;
        self.dot(r, r, kr::RR)
    }

    /// `r = b - A x`.
    pub fn residual(&self) -> Result<()> {
        self.r.copy_from(self.b)?;
        self.mv(self.x.device_address(), self.r.device_address(), -1.0, 1.0)
    }

    /// The report of function `f`, from the control words, scalars and history.
    pub fn report(&self, f: &'static str) -> Result<SolveReport> {
        let sc = self.scal.to_vec()?;
        report(
            f,
            &self.ctl.to_vec()?,
            sc[kr::TOL],
            sc[kr::BREAK],
            &self.history,
            |w, words| {
                (w == c::STOP_BREAKDOWN)
                    .then(|| usize::try_from(words[kr::CTL_WHAT]).ok())
                    .flatten()
                    .and_then(|k| kr::WHATS.get(k).copied())
            },
        )
    }
}

/// The address of scalar `i` of `v`.
pub(super) fn at<S: SparseScalar>(v: &Array<S>, i: usize) -> u64 {
    v.device_address() + (i * std::mem::size_of::<S>()) as u64
}

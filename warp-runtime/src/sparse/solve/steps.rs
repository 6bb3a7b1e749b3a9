//! The steps of BiCGSTAB, CR and GMRES ([`ObjectStep`]s of `wp_sparse.h`'s Krylov section):
//! a generic gated vector update ([`KrVec`]), GMRES's basis combination ([`KrComb`]) and one
//! one-thread scalar step per method ([`KrScalar`], a phase per check of the iteration). Each
//! is a `#[repr(C)]` record laid out as the C++ struct its kernel takes (both sides assert the
//! size; a unit test compares the offsets), and the same step on the CPU with rayon, in the
//! same order of operations, so that the CPU and a GPU give the same bits. The products, dots
//! and Jacobi steps are slice 1's (`sparse/steps.rs`).
//!
//! Addresses are of contiguous arrays on the step's device that the solver allocated or
//! checked (the solvers' comments say how many elements each holds).

use crate::backend::{ObjectLibrary, ObjectStep};
use crate::error::Result;
use crate::sparse::block::SparseScalar;
use crate::sparse::steps::{by_scalar, cg as c, Ptr, LIBRARY};
use rayon::prelude::*;
use std::marker::PhantomData;

/// The control words beyond cg's four (`CTL_STOP`, `CTL_ITER`, `CTL_BAD`, `CTL_RUN`), the
/// scalars' slots, the breakdown codes, the vector operations and their gates
/// (`wp_sparse.h`'s `SPK_*`).
pub(crate) mod kr {
    /// The breakdown's quantity (`WHATS` index) when the stop is `STOP_BREAKDOWN`.
    pub const CTL_WHAT: usize = 4;
    /// GMRES: 1 while the cycle's Arnoldi steps run.
    pub const CTL_ACTIVE: usize = 5;
    /// GMRES: 1 while the cycle's columns are still to be added to x.
    pub const CTL_PENDING: usize = 6;
    /// GMRES: the cycle's columns.
    pub const CTL_K: usize = 7;
    pub const CTL_LEN: usize = 8;

    /// Every method's first scalars.
    pub const TOL: usize = 0;
    pub const TOL2: usize = 1;
    pub const BB: usize = 2;
    pub const RR: usize = 3;
    pub const BREAK: usize = 4;

    pub const WHAT_RHO: i32 = 0;
    pub const WHAT_OMEGA: i32 = 1;
    pub const WHAT_R0V: i32 = 2;
    pub const WHAT_APAP: i32 = 3;
    pub const WHAT_ZAZ: i32 = 4;
    pub const WHAT_HJJ: i32 = 5;
    /// The names of the breakdown codes (`Stop::Breakdown::what`).
    pub const WHATS: [&str; 6] = ["rho", "omega", "r0.v", "Ap.M^-1Ap", "z.Az", "H_jj"];

    /// `y += a x`.
    pub const OP_AXPY: i32 = 0;
    /// `y -= a x`.
    pub const OP_AXMY: i32 = 1;
    /// `y = x + a y`.
    pub const OP_XPAY: i32 = 2;
    /// `y = x + a (y - b w)` (BiCGSTAB's direction).
    pub const OP_P: i32 = 3;
    /// `y = x / a`.
    pub const OP_DIV: i32 = 4;
    /// `y += x`.
    pub const OP_ADD: i32 = 5;

    /// Runs while no stop is set.
    pub const GATE_RUN: i32 = 0;
    /// Runs while no stop is set and the GMRES cycle is active.
    pub const GATE_ACTIVE: i32 = 1;
    /// Runs while a GMRES cycle's update is pending.
    pub const GATE_PENDING: i32 = 2;

    /// BiCGSTAB's scalars.
    pub const B_RHO: usize = 5;
    pub const B_R0V: usize = 6;
    pub const B_ALPHA: usize = 7;
    pub const B_SS: usize = 8;
    pub const B_TS: usize = 9;
    pub const B_TT: usize = 10;
    pub const B_OMEGA: usize = 11;
    pub const B_RHO_NEW: usize = 12;
    pub const B_BETA: usize = 13;
    pub const B_LEN: usize = 14;

    /// CR's scalars.
    pub const C_ZAZ: usize = 5;
    pub const C_ZAZ_NEW: usize = 6;
    pub const C_APAP: usize = 7;
    pub const C_ALPHA: usize = 8;
    pub const C_BETA: usize = 9;
    pub const C_LEN: usize = 10;

    /// GMRES's scalars: `|w|^2` (then `|w|`), then the Hessenberg matrix H ((m + 1) x m,
    /// row-major), the rotations' cosines and sines (m each), the right-hand side g (m + 1)
    /// and the solution y (m) (`spk_g_*` in the header).
    pub const G_HN: usize = 5;
    pub const G_H: usize = 6;
    pub const fn g_cs(m: usize) -> usize {
        G_H + (m + 1) * m
    }
    pub const fn g_sn(m: usize) -> usize {
        g_cs(m) + m
    }
    pub const fn g_g(m: usize) -> usize {
        g_sn(m) + m
    }
    pub const fn g_y(m: usize) -> usize {
        g_g(m) + m + 1
    }
    pub const fn g_len(m: usize) -> usize {
        g_y(m) + m
    }

    /// The methods of [`KrScalar`](super::KrScalar).
    pub const BICGSTAB: u8 = 0;
    pub const CR: u8 = 1;
    pub const GMRES: u8 = 2;
}

use kr::*;

/// Whether a gated step runs (`spk_open`).
fn open(ctl: &[i32], gate: i32) -> bool {
    match gate {
        GATE_RUN => ctl[c::CTL_STOP] == c::STOP_NONE,
        GATE_ACTIVE => ctl[c::CTL_STOP] == c::STOP_NONE && ctl[CTL_ACTIVE] == 1,
        _ => ctl[CTL_PENDING] == 1,
    }
}

/// A vector update gated on the control words (`spk_vec_t`): `op` (`OP_*`) of y, x, w with
/// `a = scal[ia]`, `b = scal[ib]`, when `gate` is open.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct KrVec<S> {
    pub ctl: u64,
    pub scal: u64,
    pub y: u64,
    pub x: u64,
    pub w: u64,
    pub n: i64,
    pub op: i32,
    pub ia: i32,
    pub ib: i32,
    pub gate: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<KrVec<f32>>() == 64);

// SAFETY: `#[repr(C)]`, the layout of `spk_vec_t`; n scalars at y, x, w (x may be y for
// OP_DIV: element-wise, each element read before it is written; w only for OP_P), CTL_LEN
// words at ctl, the solver's scalars at scal (ia, ib in range).
unsafe impl<S: SparseScalar> ObjectStep for KrVec<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = by_scalar::<S>("wp_sparse_kr_vec_f32", "wp_sparse_kr_vec_f64");

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl; the words and scalars are read only.
        let ctl = unsafe { std::slice::from_raw_parts(self.ctl as *const i32, CTL_LEN) };
        if !open(ctl, self.gate) {
            return Ok(());
        }
        // SAFETY: as above; the slots are in range.
        let (a, b) = unsafe {
            let sc = self.scal as *const S;
            (*sc.add(self.ia as usize), *sc.add(self.ib as usize))
        };
        let (y, x, w) = (
            Ptr(self.y as *mut S),
            Ptr(self.x as *mut S),
            Ptr(self.w as *mut S),
        );
        let op = self.op;
        (0..self.len())
            .into_par_iter()
            .with_min_len(4096)
            .for_each(|i| unsafe {
                // SAFETY: each task reads and writes its own element i.
                let v = match op {
                    OP_AXPY => y.get(i).add(a.mul(x.get(i))),
                    OP_AXMY => y.get(i).sub(a.mul(x.get(i))),
                    OP_XPAY => x.get(i).add(a.mul(y.get(i))),
                    OP_P => x.get(i).add(a.mul(y.get(i).sub(b.mul(w.get(i))))),
                    OP_DIV => x.get(i).div(a),
                    _ => y.get(i).add(x.get(i)),
                };
                y.at(i).write(v);
            });
        Ok(())
    }
}

/// GMRES's combination of its basis (`spk_comb_t`), while the update is pending: per element
/// `acc = sum_k y_k V_k` (from 0, k ascending below `ctl[CTL_K]`, `y_k = scal[iy + k]`), then
/// `out += acc` (`add`) or `out = acc`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct KrComb<S> {
    pub ctl: u64,
    pub scal: u64,
    pub out: u64,
    pub v: u64,
    pub n: i64,
    pub iy: i32,
    pub add: i32,
    pub m: i32,
    pub pad: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<KrComb<f32>>() == 56);

// SAFETY: `#[repr(C)]`, the layout of `spk_comb_t`; n scalars at out, (m + 1) n at v (another
// array), CTL_LEN words at ctl, m scalars from iy at scal.
unsafe impl<S: SparseScalar> ObjectStep for KrComb<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = by_scalar::<S>("wp_sparse_kr_comb_f32", "wp_sparse_kr_comb_f64");

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl; read only.
        let ctl = unsafe { std::slice::from_raw_parts(self.ctl as *const i32, CTL_LEN) };
        if !open(ctl, GATE_PENDING) {
            return Ok(());
        }
        let (n, m) = (self.len(), self.m.max(0) as usize);
        let k = (ctl[CTL_K].max(0) as usize).min(m);
        // SAFETY: as above.
        let (y, v) = unsafe {
            (
                std::slice::from_raw_parts((self.scal as *const S).add(self.iy as usize), m),
                std::slice::from_raw_parts(self.v as *const S, (m + 1) * n),
            )
        };
        let out = Ptr(self.out as *mut S);
        let add = self.add != 0;
        (0..n).into_par_iter().with_min_len(4096).for_each(|i| {
            let mut acc = S::ZERO;
            for (kk, &yk) in y[..k].iter().enumerate() {
                acc = acc.add(yk.mul(v[kk * n + i]));
            }
            // SAFETY: each task writes its own element (out is not v).
            unsafe {
                let p = out.at(i);
                p.write(if add { (*p).add(acc) } else { acc });
            }
        });
        Ok(())
    }
}

/// A method's one-thread step (`spk_scalar_t`; `METHOD` is `kr::BICGSTAB`, `CR` or `GMRES`):
/// the check of `phase` (see each method's `*_phase`), for GMRES of column `j` of `m`.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct KrScalar<S, const METHOD: u8> {
    pub ctl: u64,
    pub scal: u64,
    pub history: u64,
    pub rtol: f64,
    pub atol: f64,
    pub max_iter: i32,
    pub phase: i32,
    pub m: i32,
    pub j: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<KrScalar<f32, 0>>() == 56);

/// The tolerance `max(atol, rtol |b|)` and its square into the scalars (cg's `init` order).
fn init_tol<S: SparseScalar>(rtol: f64, atol: f64, sc: &mut [S]) {
    let rt = S::from_f64(rtol).mul(sc[BB].sqrt());
    let at = S::from_f64(atol);
    let tol = if at > rt { at } else { rt };
    sc[TOL] = tol;
    sc[TOL2] = tol.mul(tol);
}

/// A breakdown of quantity `what` with value `v`.
fn breakdown<S: SparseScalar>(ctl: &mut [i32], sc: &mut [S], what: i32, v: S) {
    sc[BREAK] = v;
    ctl[CTL_WHAT] = what;
    ctl[c::CTL_STOP] = c::STOP_BREAKDOWN;
}

/// The stop before any iteration common to BiCGSTAB and CR (`spk_first_stop`): a singular
/// preconditioner, a non-finite residual (or `q`), convergence; `None` to go on.
fn first_stop<S: SparseScalar>(ctl: &[i32], sc: &[S], q: S) -> Option<i32> {
    let rr = sc[RR];
    if ctl[c::CTL_BAD] != i32::MAX {
        Some(c::STOP_SINGULAR)
    } else if !rr.finite() || !q.finite() {
        Some(c::STOP_NON_FINITE)
    } else if rr <= sc[TOL2] {
        Some(c::STOP_CONVERGED)
    } else {
        None
    }
}

impl<S: SparseScalar, const METHOD: u8> KrScalar<S, METHOD> {
    /// BiCGSTAB: 0 the set-up (`rho = r.r`), 1 after `r0.v` (alpha), 2 after `s.s` (an early
    /// convergence counts the iteration), 3 after `t.s`, `t.t` (omega), 4 after `r.r`,
    /// `r0.r` (the iteration's check; beta).
    fn bicgstab(&self, ctl: &mut [i32], sc: &mut [S], hist: &mut [S]) {
        let stop = c::CTL_STOP;
        if self.phase == 0 {
            init_tol(self.rtol, self.atol, sc);
            let rr = sc[RR];
            hist[0] = rr.sqrt();
            ctl[c::CTL_ITER] = 0;
            sc[B_RHO] = rr;
            ctl[stop] = match first_stop(ctl, sc, rr) {
                Some(s) => s,
                None if self.max_iter <= 0 => c::STOP_MAX_ITER,
                None => c::STOP_NONE,
            };
            return;
        }
        if ctl[stop] != c::STOP_NONE {
            return;
        }
        match self.phase {
            1 => {
                let r0v = sc[B_R0V];
                if !r0v.finite() {
                    ctl[stop] = c::STOP_NON_FINITE;
                } else if r0v == S::ZERO {
                    breakdown(ctl, sc, WHAT_R0V, r0v);
                } else {
                    sc[B_ALPHA] = sc[B_RHO].div(r0v);
                }
            }
            2 => {
                let ss = sc[B_SS];
                if !ss.finite() {
                    ctl[stop] = c::STOP_NON_FINITE;
                } else if ss <= sc[TOL2] {
                    let it = ctl[c::CTL_ITER] + 1;
                    ctl[c::CTL_ITER] = it;
                    hist[it as usize] = ss.sqrt();
                    ctl[stop] = c::STOP_CONVERGED;
                }
            }
            3 => {
                let (ts, tt) = (sc[B_TS], sc[B_TT]);
                if !ts.finite() || !tt.finite() {
                    ctl[stop] = c::STOP_NON_FINITE;
                } else if tt == S::ZERO {
                    // t = A M^-1 s = 0: no stabilising step (the check names the breakdown).
                    sc[B_OMEGA] = S::ZERO;
                } else {
                    sc[B_OMEGA] = ts.div(tt);
                }
            }
            _ => {
                let it = ctl[c::CTL_ITER] + 1;
                ctl[c::CTL_ITER] = it;
                let (rr, rho_new, omega) = (sc[RR], sc[B_RHO_NEW], sc[B_OMEGA]);
                hist[it as usize] = rr.sqrt();
                if !rr.finite() || !rho_new.finite() {
                    ctl[stop] = c::STOP_NON_FINITE;
                } else if rr <= sc[TOL2] {
                    ctl[stop] = c::STOP_CONVERGED;
                } else if omega == S::ZERO {
                    breakdown(ctl, sc, WHAT_OMEGA, omega);
                } else if rho_new == S::ZERO {
                    breakdown(ctl, sc, WHAT_RHO, rho_new);
                } else if it >= self.max_iter {
                    ctl[stop] = c::STOP_MAX_ITER;
                } else {
                    sc[B_BETA] = rho_new.div(sc[B_RHO]).mul(sc[B_ALPHA].div(omega));
                    sc[B_RHO] = rho_new;
                }
            }
        }
    }

    /// CR: 0 the set-up, 1 after `Ap . M^-1 Ap` (alpha), 2 after `z.Az`, `r.r` (the
    /// iteration's check; beta).
    fn cr(&self, ctl: &mut [i32], sc: &mut [S], hist: &mut [S]) {
        let stop = c::CTL_STOP;
        if self.phase == 0 {
            init_tol(self.rtol, self.atol, sc);
            let rr = sc[RR];
            hist[0] = rr.sqrt();
            ctl[c::CTL_ITER] = 0;
            let zaz = sc[C_ZAZ];
            match first_stop(ctl, sc, zaz) {
                Some(s) => ctl[stop] = s,
                None if zaz == S::ZERO => breakdown(ctl, sc, WHAT_ZAZ, zaz),
                None if self.max_iter <= 0 => ctl[stop] = c::STOP_MAX_ITER,
                None => ctl[stop] = c::STOP_NONE,
            }
            return;
        }
        if ctl[stop] != c::STOP_NONE {
            return;
        }
        if self.phase == 1 {
            let apap = sc[C_APAP];
            if !apap.finite() {
                ctl[stop] = c::STOP_NON_FINITE;
            } else if apap == S::ZERO {
                breakdown(ctl, sc, WHAT_APAP, apap);
            } else {
                sc[C_ALPHA] = sc[C_ZAZ].div(apap);
            }
            return;
        }
        let it = ctl[c::CTL_ITER] + 1;
        ctl[c::CTL_ITER] = it;
        let (rr, zn) = (sc[RR], sc[C_ZAZ_NEW]);
        hist[it as usize] = rr.sqrt();
        if !rr.finite() || !zn.finite() {
            ctl[stop] = c::STOP_NON_FINITE;
        } else if rr <= sc[TOL2] {
            ctl[stop] = c::STOP_CONVERGED;
        } else if zn == S::ZERO {
            breakdown(ctl, sc, WHAT_ZAZ, zn);
        } else if it >= self.max_iter {
            ctl[stop] = c::STOP_MAX_ITER;
        } else {
            sc[C_BETA] = zn.div(sc[C_ZAZ]);
            sc[C_ZAZ] = zn;
        }
    }

    /// GMRES's cycle start (`spk_gmres_start`): from `|r|^2` in `RR`, the true residual norm
    /// replaces the history's last entry, then a stop (non-finite, converged, max_iter) or
    /// `g = (|r|, 0, ..)` and the cycle active and pending.
    fn gmres_start(&self, ctl: &mut [i32], sc: &mut [S], hist: &mut [S]) {
        let m = self.m as usize;
        ctl[CTL_ACTIVE] = 0;
        ctl[CTL_PENDING] = 0;
        ctl[CTL_K] = 0;
        if ctl[c::CTL_STOP] != c::STOP_NONE {
            return;
        }
        let rr = sc[RR];
        let beta = rr.sqrt();
        let it = ctl[c::CTL_ITER];
        hist[it as usize] = beta;
        if !rr.finite() {
            ctl[c::CTL_STOP] = c::STOP_NON_FINITE;
        } else if rr <= sc[TOL2] {
            ctl[c::CTL_STOP] = c::STOP_CONVERGED;
        } else if it >= self.max_iter {
            ctl[c::CTL_STOP] = c::STOP_MAX_ITER;
        } else {
            let g = g_g(m);
            sc[g] = beta;
            for v in &mut sc[g + 1..=g + m] {
                *v = S::ZERO;
            }
            ctl[CTL_ACTIVE] = 1;
            ctl[CTL_PENDING] = 1;
        }
    }

    /// GMRES's Arnoldi check of column `j` (`spk_gmres_column`): H's new entry `|w|`, the
    /// earlier rotations applied to the column, its own rotation, g rotated, the iteration
    /// counted with `|g_(j+1)|` as its residual; then a stop, or the cycle's end at `j = m - 1`.
    fn gmres_column(&self, ctl: &mut [i32], sc: &mut [S], hist: &mut [S]) {
        if ctl[c::CTL_STOP] != c::STOP_NONE || ctl[CTL_ACTIVE] != 1 {
            return;
        }
        let (m, j) = (self.m as usize, self.j as usize);
        let h = |i: usize| G_H + i * m + j;
        let hn = sc[G_HN].sqrt();
        sc[G_HN] = hn;
        let finite = hn.finite() && (0..=j).all(|i| sc[h(i)].finite());
        if !finite {
            ctl[c::CTL_STOP] = c::STOP_NON_FINITE;
            ctl[CTL_ACTIVE] = 0;
            ctl[CTL_PENDING] = 0;
            return;
        }
        sc[h(j + 1)] = hn;
        let (cs, sn, g) = (g_cs(m), g_sn(m), g_g(m));
        for i in 0..j {
            let (a, b) = (sc[h(i)], sc[h(i + 1)]);
            let (cc, ss) = (sc[cs + i], sc[sn + i]);
            sc[h(i)] = cc.mul(a).add(ss.mul(b));
            sc[h(i + 1)] = cc.mul(b).sub(ss.mul(a));
        }
        let (a, b) = (sc[h(j)], sc[h(j + 1)]);
        let rho = a.mul(a).add(b.mul(b)).sqrt();
        if rho == S::ZERO {
            // The column is zero: H is singular. The cycle's earlier columns still update x.
            breakdown(ctl, sc, WHAT_HJJ, rho);
            ctl[CTL_ACTIVE] = 0;
            return;
        }
        let (cc, ss) = (a.div(rho), b.div(rho));
        sc[cs + j] = cc;
        sc[sn + j] = ss;
        sc[h(j)] = rho;
        sc[h(j + 1)] = S::ZERO;
        let gj = sc[g + j];
        sc[g + j + 1] = S::ZERO.sub(ss.mul(gj));
        sc[g + j] = cc.mul(gj);
        ctl[CTL_K] = j as i32 + 1;
        let it = ctl[c::CTL_ITER] + 1;
        ctl[c::CTL_ITER] = it;
        let gn = sc[g + j + 1];
        let res = if gn < S::ZERO { S::ZERO.sub(gn) } else { gn };
        hist[it as usize] = res;
        if !res.finite() || !rho.finite() {
            ctl[c::CTL_STOP] = c::STOP_NON_FINITE;
            ctl[CTL_PENDING] = 0;
        } else if res <= sc[TOL] {
            ctl[c::CTL_STOP] = c::STOP_CONVERGED;
        } else if it >= self.max_iter {
            ctl[c::CTL_STOP] = c::STOP_MAX_ITER;
        }
        if ctl[c::CTL_STOP] != c::STOP_NONE || j + 1 == m {
            ctl[CTL_ACTIVE] = 0;
        }
    }

    /// GMRES's least-squares solve (`spk_gmres_solve`), while pending: `H y = g` over the
    /// cycle's K columns, H upper triangular after the rotations, by back substitution.
    fn gmres_solve(&self, ctl: &[i32], sc: &mut [S]) {
        if ctl[CTL_PENDING] != 1 {
            return;
        }
        let m = self.m as usize;
        let k = (ctl[CTL_K].max(0) as usize).min(m);
        let (g, y) = (g_g(m), g_y(m));
        for i in (0..k).rev() {
            let mut acc = sc[g + i];
            for l in i + 1..k {
                acc = acc.sub(sc[G_H + i * m + l].mul(sc[y + l]));
            }
            sc[y + i] = acc.div(sc[G_H + i * m + i]);
        }
    }

    /// GMRES: 0 the set-up (tolerance, a singular preconditioner, the first cycle's start),
    /// 1 a cycle's start, 2 column `j`'s check, 3 the solve, 4 the update done.
    fn gmres(&self, ctl: &mut [i32], sc: &mut [S], hist: &mut [S]) {
        match self.phase {
            0 => {
                init_tol(self.rtol, self.atol, sc);
                ctl[c::CTL_ITER] = 0;
                if ctl[c::CTL_BAD] != i32::MAX {
                    ctl[c::CTL_STOP] = c::STOP_SINGULAR;
                    hist[0] = sc[RR].sqrt();
                }
                self.gmres_start(ctl, sc, hist);
            }
            1 => self.gmres_start(ctl, sc, hist),
            2 => self.gmres_column(ctl, sc, hist),
            3 => self.gmres_solve(ctl, sc),
            _ => ctl[CTL_PENDING] = 0,
        }
    }
}

// SAFETY: `#[repr(C)]`, the layout of `spk_scalar_t`; CTL_LEN words at ctl, the method's
// scalars at scal (`B_LEN`, `C_LEN`, `g_len(m)`), max_iter + 1 at history (the solver's
// own arrays).
unsafe impl<S: SparseScalar, const METHOD: u8> ObjectStep for KrScalar<S, METHOD> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = match METHOD {
        BICGSTAB => by_scalar::<S>(
            "wp_sparse_bicgstab_scalar_f32",
            "wp_sparse_bicgstab_scalar_f64",
        ),
        CR => by_scalar::<S>("wp_sparse_cr_scalar_f32", "wp_sparse_cr_scalar_f64"),
        _ => by_scalar::<S>("wp_sparse_gmres_scalar_f32", "wp_sparse_gmres_scalar_f64"),
    };

    fn len(&self) -> usize {
        1
    }

    fn run_cpu(&self) -> Result<()> {
        let len = match METHOD {
            BICGSTAB => B_LEN,
            CR => C_LEN,
            _ => g_len(self.m as usize),
        };
        // SAFETY: see the impl; nothing else touches them during the step.
        let (ctl, sc, hist) = unsafe {
            (
                std::slice::from_raw_parts_mut(self.ctl as *mut i32, CTL_LEN),
                std::slice::from_raw_parts_mut(self.scal as *mut S, len),
                std::slice::from_raw_parts_mut(self.history as *mut S, self.max_iter as usize + 1),
            )
        };
        match METHOD {
            BICGSTAB => self.bicgstab(ctl, sc, hist),
            CR => self.cr(ctl, sc, hist),
            _ => self.gmres(ctl, sc, hist),
        }
        ctl[c::CTL_RUN] = (ctl[c::CTL_STOP] == c::STOP_NONE) as i32;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `wp_sparse.h`, whose Krylov section is the C++ side of every record and constant here.
    const HEADER: &str = include_str!("../../../../warp-cuda/cuda/wp_sparse.h");

    /// Every `constexpr i32 SPK_NAME = value` of the header.
    fn header_constants() -> Vec<(String, i64)> {
        crate::sparse::record_check::header_constants(HEADER, "SPK_")
    }

    /// The header's `SPK_*` constants are Rust's `kr` constants, one for one (the Rust side
    /// addresses the control words and scalars the kernels write, and decodes the breakdown
    /// codes, by its own constants: a change on one side alone would pass every CPU test),
    /// and GMRES's layout functions agree with the header's formulas.
    #[test]
    fn header_constants_are_rusts() {
        let rust: Vec<(&str, i64)> = vec![
            ("SPK_CTL_WHAT", CTL_WHAT as i64),
            ("SPK_CTL_ACTIVE", CTL_ACTIVE as i64),
            ("SPK_CTL_PENDING", CTL_PENDING as i64),
            ("SPK_CTL_K", CTL_K as i64),
            ("SPK_CTL_LEN", CTL_LEN as i64),
            ("SPK_TOL", TOL as i64),
            ("SPK_TOL2", TOL2 as i64),
            ("SPK_BB", BB as i64),
            ("SPK_RR", RR as i64),
            ("SPK_BREAK", BREAK as i64),
            ("SPK_WHAT_RHO", WHAT_RHO as i64),
            ("SPK_WHAT_OMEGA", WHAT_OMEGA as i64),
            ("SPK_WHAT_R0V", WHAT_R0V as i64),
            ("SPK_WHAT_APAP", WHAT_APAP as i64),
            ("SPK_WHAT_ZAZ", WHAT_ZAZ as i64),
            ("SPK_WHAT_HJJ", WHAT_HJJ as i64),
            ("SPK_OP_AXPY", OP_AXPY as i64),
            ("SPK_OP_AXMY", OP_AXMY as i64),
            ("SPK_OP_XPAY", OP_XPAY as i64),
            ("SPK_OP_P", OP_P as i64),
            ("SPK_OP_DIV", OP_DIV as i64),
            ("SPK_OP_ADD", OP_ADD as i64),
            ("SPK_GATE_RUN", GATE_RUN as i64),
            ("SPK_GATE_ACTIVE", GATE_ACTIVE as i64),
            ("SPK_GATE_PENDING", GATE_PENDING as i64),
            ("SPK_B_RHO", B_RHO as i64),
            ("SPK_B_R0V", B_R0V as i64),
            ("SPK_B_ALPHA", B_ALPHA as i64),
            ("SPK_B_SS", B_SS as i64),
            ("SPK_B_TS", B_TS as i64),
            ("SPK_B_TT", B_TT as i64),
            ("SPK_B_OMEGA", B_OMEGA as i64),
            ("SPK_B_RHO_NEW", B_RHO_NEW as i64),
            ("SPK_B_BETA", B_BETA as i64),
            ("SPK_B_LEN", B_LEN as i64),
            ("SPK_C_ZAZ", C_ZAZ as i64),
            ("SPK_C_ZAZ_NEW", C_ZAZ_NEW as i64),
            ("SPK_C_APAP", C_APAP as i64),
            ("SPK_C_ALPHA", C_ALPHA as i64),
            ("SPK_C_BETA", C_BETA as i64),
            ("SPK_C_LEN", C_LEN as i64),
            ("SPK_G_HN", G_HN as i64),
            ("SPK_G_H", G_H as i64),
        ];
        let mut header = header_constants();
        header.sort();
        let mut rust: Vec<(String, i64)> = rust.into_iter().map(|(n, v)| (n.into(), v)).collect();
        rust.sort();
        assert_eq!(header, rust);
        // The control words extend cg's; the breakdown names cover the codes; each method's
        // slots fit its scalars.
        assert_eq!(CTL_WHAT, c::CTL_LEN);
        assert_eq!(WHATS.len() as i32, WHAT_HJJ + 1);
        const { assert!(B_BETA < B_LEN && C_BETA < C_LEN && BREAK < G_HN) };
        // The header's GMRES layout: the same formulas (`spk_g_*`), spelled there as here.
        for (f, want) in [
            (
                "spk_g_cs(i32 m) { return SPK_G_H + (m + 1) * m; }",
                g_cs(3) == G_H + 12,
            ),
            (
                "spk_g_sn(i32 m) { return spk_g_cs(m) + m; }",
                g_sn(3) == g_cs(3) + 3,
            ),
            (
                "spk_g_g(i32 m) { return spk_g_sn(m) + m; }",
                g_g(3) == g_sn(3) + 3,
            ),
            (
                "spk_g_y(i32 m) { return spk_g_g(m) + m + 1; }",
                g_y(3) == g_g(3) + 4,
            ),
        ] {
            assert!(HEADER.contains(f) && want, "{f}");
        }
        assert_eq!(g_len(3), g_y(3) + 3);
    }

    /// Each record's fields sit at the same offsets in Rust and in C++ (g++'s `offsetof`).
    /// Skipped, saying so, without g++.
    #[test]
    fn record_offsets_are_the_headers() {
        let fields = record_layouts![
            KrVec<f32> => "spk_vec_t" { ctl, scal, y, x, w, n, op, ia, ib, gate },
            KrComb<f32> => "spk_comb_t" { ctl, scal, out, v, n, iy, add, m, pad },
            KrScalar<f32, 0> => "spk_scalar_t" {
                ctl, scal, history, rtol, atol, max_iter, phase, m, j
            },
        ];
        crate::sparse::record_check::check_record_offsets(
            "sparse::solve::steps::record_offsets_are_the_headers",
            "wp_sparse.h",
            &fields,
        );
    }

    /// Every Krylov kernel name the Rust side launches is a kernel of the compiled build
    /// library. Needs only libnvrtc (skipped, saying so, without it).
    #[cfg(feature = "cuda")]
    #[test]
    fn every_kernel_name_is_in_the_compiled_library() {
        if let Err(e) = warp_cuda::nvrtc_version() {
            eprintln!("SKIPPED every_kernel_name_is_in_the_compiled_library: {e}");
            return;
        }
        let lib = crate::cuda::objects::compile_library(&LIBRARY, 90).unwrap();
        let has = |name: &str| {
            let pat = format!("{name}\0");
            lib.cubin.windows(pat.len()).any(|w| w == pat.as_bytes())
        };
        let names = [
            KrVec::<f32>::KERNEL,
            KrVec::<f64>::KERNEL,
            KrComb::<f32>::KERNEL,
            KrComb::<f64>::KERNEL,
            KrScalar::<f32, BICGSTAB>::KERNEL,
            KrScalar::<f64, BICGSTAB>::KERNEL,
            KrScalar::<f32, CR>::KERNEL,
            KrScalar::<f64, CR>::KERNEL,
            KrScalar::<f32, GMRES>::KERNEL,
            KrScalar::<f64, GMRES>::KERNEL,
        ];
        let distinct: std::collections::BTreeSet<_> = names.iter().collect();
        assert_eq!(distinct.len(), names.len(), "{names:?}");
        for n in &names {
            assert!(has(n), "{n} is not a kernel of the compiled library");
        }
        assert!(!has("wp_sparse_kr_vec_f16"));
    }
}

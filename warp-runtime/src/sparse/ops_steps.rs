//! The structure operations' steps ([`ObjectStep`]s of the `sparse_ops` build library,
//! `wp_sparse_ops.h`): each a `#[repr(C)]` record laid out as its C++ struct (both sides
//! assert the size; a unit test compares every field's offset), with the same step on the CPU
//! in the same order of operations, so both backends give the same bits. `ops.rs` orders them
//! around the primitives and the triplet pipeline of `mod.rs`.
//!
//! The block shape is a field of each record (`rows`, `cols`, `cm`), so each step has one
//! kernel per scalar type (or one, for the integer steps), whatever the block type.

use super::block::SparseScalar;
use super::steps::{by_scalar, slice, Ptr};
use crate::backend::{ObjectLibrary, ObjectStep, StepFault};
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use rayon::prelude::*;
use std::marker::PhantomData;
use warp_core::{Fault, FaultKind};

/// The structure operations' build library: `wp_sparse_ops.h` with its kernels enabled.
pub(crate) static OPS_LIBRARY: ObjectLibrary = ObjectLibrary::of("sparse_ops");

/// What `from_dense`'s fault is named by.
pub(crate) static DENSE_NAMES: KernelInfo = KernelInfo {
    name: "sparse::from_dense",
    module: "warp_lang::sparse",
    params: &["a"],
    ..KernelInfo::BLANK
};

/// A matrix's block count (`sp_nnz`): `offsets[nrow]` if it is in `0..=cap`, else 0 (the
/// primitives' rule for a device count, which the transpose's sort reads from the same word).
pub(crate) fn nnz_of(offsets: &[i32], nrow: usize, cap: i32) -> usize {
    let c = offsets[nrow];
    if c < 0 || c > cap {
        0
    } else {
        c as usize
    }
}

/// Block row `r`'s blocks, clamped into `0..nnz` (`sp_ops_row`).
fn row(offsets: &[i32], r: usize, nnz: usize) -> std::ops::Range<usize> {
    let lo = (offsets[r].max(0) as usize).min(nnz);
    let hi = (offsets[r + 1].max(0) as usize).clamp(lo, nnz);
    lo..hi
}

/// Entry `(i, j)`'s scalar in a block of `rows x cols` (`sp_ops_at`).
fn at(i: usize, j: usize, rows: usize, cols: usize, cm: bool) -> usize {
    if cm {
        j * rows + i
    } else {
        i * cols + j
    }
}

/// The offsets of a matrix of `nrow` block rows at `addr` (`nrow + 1` of them).
///
/// # Safety
/// `addr` holds `nrow + 1` i32s that nothing writes during the borrow.
unsafe fn offsets<'a>(addr: u64, nrow: i32) -> &'a [i32] {
    slice::<i32>(addr, nrow as usize + 1)
}

// ------------------------------------------------------------------------------------------
// Scale, diagonal, dense
// ------------------------------------------------------------------------------------------

/// `v = alpha v` per stored scalar (`sp_ops_scale_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scale<S> {
    pub offsets: u64,
    pub values: u64,
    pub alpha: f64,
    pub nrow: i32,
    pub cap: i32,
    pub block: i32,
    pub pad: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<Scale<f32>>() == 40);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_scale_t`; a Bsr's offsets (nrow + 1) and values
// (cap blocks of `block` scalars).
unsafe impl<S: SparseScalar> ObjectStep for Scale<S> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str =
        by_scalar::<S>("wp_sparse_ops_scale_f32", "wp_sparse_ops_scale_f64");

    fn len(&self) -> usize {
        self.cap as usize * self.block as usize
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl.
        let off = unsafe { offsets(self.offsets, self.nrow) };
        let n = nnz_of(off, self.nrow as usize, self.cap) * self.block as usize;
        let alpha = S::from_f64(self.alpha);
        let v = Ptr(self.values as *mut S);
        (0..n).into_par_iter().with_min_len(4096).for_each(|i| {
            // SAFETY: each task its own scalar of the first nnz blocks.
            unsafe {
                let p = v.at(i);
                p.write(alpha.mul(*p));
            }
        });
        Ok(())
    }
}

/// The diagonal blocks (`sp_ops_diag_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Diag<S> {
    pub offsets: u64,
    pub columns: u64,
    pub values: u64,
    pub out: u64,
    pub nrow: i32,
    pub ncol: i32,
    pub cap: i32,
    pub block: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<Diag<f32>>() == 48);

/// The stored block of row `r` at column `c`, if any (`sp_ops_find`: the same binary search,
/// step for step, so that even a row whose columns a user overwrote out of order gives the
/// same block on both backends).
fn find(offsets: &[i32], columns: &[i32], nnz: usize, r: usize, c: i32) -> Option<usize> {
    let range = row(offsets, r, nnz);
    let (mut lo, mut hi) = (range.start, range.end);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if columns[mid] < c {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    (lo < range.end && columns[lo] == c).then_some(lo)
}

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_diag_t`; a Bsr's arrays, out of min(nrow, ncol)
// blocks not overlapping them (diag checked).
unsafe impl<S: SparseScalar> ObjectStep for Diag<S> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str = by_scalar::<S>("wp_sparse_ops_diag_f32", "wp_sparse_ops_diag_f64");

    fn len(&self) -> usize {
        self.nrow.min(self.ncol) as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let b = self.block as usize;
        // SAFETY: see the impl.
        let off = unsafe { offsets(self.offsets, self.nrow) };
        let nnz = nnz_of(off, self.nrow as usize, self.cap);
        let (cols, vals) = unsafe {
            (
                slice::<i32>(self.columns, nnz),
                slice::<S>(self.values, nnz * b),
            )
        };
        let out = Ptr(self.out as *mut S);
        (0..self.len()).into_par_iter().for_each(|i| {
            let k = find(off, cols, nnz, i, i as i32);
            for e in 0..b {
                let v = k.map_or(S::ZERO, |k| vals[k * b + e]);
                // SAFETY: each task its own block i.
                unsafe { out.at(i * b + e).write(v) };
            }
        });
        Ok(())
    }
}

/// The block diagonal matrix of `d`, or the identity when `d` is 0 (`sp_ops_set_diag_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct SetDiag<S> {
    pub offsets: u64,
    pub columns: u64,
    pub values: u64,
    pub d: u64,
    pub nrow: i32,
    pub n: i32,
    pub dim: i32,
    pub block: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<SetDiag<f32>>() == 48);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_set_diag_t`; fresh offsets (nrow + 1), columns
// and values (n blocks), d of n blocks (or 0).
unsafe impl<S: SparseScalar> ObjectStep for SetDiag<S> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str =
        by_scalar::<S>("wp_sparse_ops_set_diag_f32", "wp_sparse_ops_set_diag_f64");

    fn len(&self) -> usize {
        self.nrow as usize + 1
    }

    fn run_cpu(&self) -> Result<()> {
        let (b, n, dim) = (self.block as usize, self.n as usize, self.dim as usize);
        let (off, cols, vals) = (
            Ptr(self.offsets as *mut i32),
            Ptr(self.columns as *mut i32),
            Ptr(self.values as *mut S),
        );
        // SAFETY: see the impl.
        let d = (self.d != 0).then(|| unsafe { slice::<S>(self.d, n * b) });
        (0..self.len()).into_par_iter().for_each(|r| {
            // SAFETY: each task its own row r (offset, column, block).
            unsafe {
                off.at(r).write(r.min(n) as i32);
                if r >= n {
                    return;
                }
                cols.at(r).write(r as i32);
                for e in 0..b {
                    let v = match d {
                        Some(d) => d[r * b + e],
                        // The identity's entry (i, i) is scalar i (R + 1) in either layout.
                        None if e % (dim + 1) == 0 => S::ONE,
                        None => S::ZERO,
                    };
                    vals.at(r * b + e).write(v);
                }
            }
        });
        Ok(())
    }
}

/// The dense row-major matrix (`sp_ops_to_dense_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct ToDense<S> {
    pub offsets: u64,
    pub columns: u64,
    pub values: u64,
    pub out: u64,
    pub nrow: i32,
    pub ncol: i32,
    pub cap: i32,
    pub rows: i32,
    pub cols: i32,
    pub cm: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<ToDense<f32>>() == 56);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_to_dense_t`; a Bsr's arrays, out of nrow R x
// ncol C scalars not overlapping them (to_dense checked).
unsafe impl<S: SparseScalar> ObjectStep for ToDense<S> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str =
        by_scalar::<S>("wp_sparse_ops_to_dense_f32", "wp_sparse_ops_to_dense_f64");

    fn len(&self) -> usize {
        self.nrow as usize * self.rows as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let (rr, cc, cm) = (self.rows as usize, self.cols as usize, self.cm != 0);
        let (ncol, width) = (self.ncol, self.ncol as usize * cc);
        // SAFETY: see the impl.
        let off = unsafe { offsets(self.offsets, self.nrow) };
        let nnz = nnz_of(off, self.nrow as usize, self.cap);
        let (cols, vals) = unsafe {
            (
                slice::<i32>(self.columns, nnz),
                slice::<S>(self.values, nnz * rr * cc),
            )
        };
        let out = Ptr(self.out as *mut S);
        (0..self.len()).into_par_iter().for_each(|i| {
            // SAFETY: each task its own dense row i.
            let dst = unsafe { std::slice::from_raw_parts_mut(out.at(i * width), width) };
            dst.fill(S::ZERO);
            let (r, ii) = (i / rr, i % rr);
            for k in row(off, r, nnz) {
                let c = cols[k];
                if !(0..ncol).contains(&c) {
                    continue; // (never in an assembled matrix)
                }
                let b = &vals[k * rr * cc..][..rr * cc];
                for j in 0..cc {
                    dst[c as usize * cc + j] = b[at(ii, j, rr, cc, cm)];
                }
            }
        });
        Ok(())
    }
}

/// `from_dense`'s flags (`GATHER` false: `sp_ops_dense_flags`) and gather (true:
/// `sp_ops_dense_gather`), both over the blocks of a dense matrix (`sp_ops_dense_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Dense<S, const GATHER: bool> {
    pub dense: u64,
    pub pos: u64,
    pub bad: u64,
    pub block_rows: u64,
    pub columns: u64,
    pub values: u64,
    pub nrow: i32,
    pub ncol: i32,
    pub rows: i32,
    pub cols: i32,
    pub cm: i32,
    pub pad: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<Dense<f32, false>>() == 72);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_dense_t`; dense of nrow R x ncol C scalars, pos
// of nrow ncol i32s, bad one i32; the gather's block_rows, columns, values of nrow ncol blocks.
unsafe impl<S: SparseScalar, const GATHER: bool> ObjectStep for Dense<S, GATHER> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str = if GATHER {
        by_scalar::<S>(
            "wp_sparse_ops_dense_gather_f32",
            "wp_sparse_ops_dense_gather_f64",
        )
    } else {
        by_scalar::<S>(
            "wp_sparse_ops_dense_flags_f32",
            "wp_sparse_ops_dense_flags_f64",
        )
    };

    fn len(&self) -> usize {
        self.nrow as usize * self.ncol as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        let (rr, cc, cm) = (self.rows as usize, self.cols as usize, self.cm != 0);
        let (ncol, width) = (self.ncol as usize, self.ncol as usize * cc);
        // SAFETY: see the impl.
        let dense = unsafe { slice::<S>(self.dense, self.nrow as usize * rr * width) };
        let at_dense = |b: usize, i: usize, j: usize| {
            let (br, bc) = (b / ncol, b % ncol);
            dense[(br * rr + i) * width + bc * cc + j]
        };
        if !GATHER {
            let pos = Ptr(self.pos as *mut i32);
            let bad = (0..n)
                .into_par_iter()
                .map(|b| {
                    let mut flag = false;
                    let mut bad = i32::MAX;
                    for i in 0..rr {
                        let mut finite = true;
                        for j in 0..cc {
                            let x = at_dense(b, i, j);
                            flag |= x != S::ZERO;
                            finite &= x.finite();
                        }
                        if !finite {
                            bad = bad.min(((b / ncol) * rr + i) as i32);
                        }
                    }
                    // SAFETY: each task its own flag b.
                    unsafe { pos.at(b).write(flag as i32) };
                    bad
                })
                .min()
                .unwrap_or(i32::MAX);
            // SAFETY: one i32, which nothing else touches now.
            unsafe {
                let p = self.bad as *mut i32;
                p.write((*p).min(bad));
            }
            return Ok(());
        }
        // SAFETY: see the impl; the outputs are written.
        let pos = unsafe { slice::<i32>(self.pos, n) };
        let (brows, cols, vals) = (
            Ptr(self.block_rows as *mut i32),
            Ptr(self.columns as *mut i32),
            Ptr(self.values as *mut S),
        );
        (0..n).into_par_iter().with_min_len(256).for_each(|b| {
            if pos[b] - if b > 0 { pos[b - 1] } else { 0 } != 1 {
                return;
            }
            let k = (pos[b] - 1) as usize;
            // SAFETY: kept block k is written by its block b alone.
            unsafe {
                brows.at(k).write((b / ncol) as i32);
                cols.at(k).write((b % ncol) as i32);
                for i in 0..rr {
                    for j in 0..cc {
                        vals.at(k * rr * cc + at(i, j, rr, cc, cm))
                            .write(at_dense(b, i, j));
                    }
                }
            }
        });
        Ok(())
    }
}

/// `from_dense`'s report (`sp_ops_dense_report_t`): the first non-finite scalar, as a fault.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct DenseReport<S> {
    pub dense: u64,
    pub bad: u64,
    pub width: i64,
    pub fault: StepFault,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<DenseReport<f32>>() == 64);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_dense_report_t`; dense as in Dense (bad names one
// of its rows, or is i32::MAX).
unsafe impl<S: SparseScalar> ObjectStep for DenseReport<S> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str = by_scalar::<S>(
        "wp_sparse_ops_dense_report_f32",
        "wp_sparse_ops_dense_report_f64",
    );

    fn len(&self) -> usize {
        1
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl.
        let row = unsafe { *(self.bad as *const i32) };
        if row == i32::MAX {
            return Ok(());
        }
        let w = self.width as usize;
        // SAFETY: dense row `row` of `width` scalars.
        let r = unsafe { slice::<S>(self.dense + (row as usize * w * size_of::<S>()) as u64, w) };
        let Some(j) = r.iter().position(|x| !x.finite()) else {
            return Ok(());
        };
        Err(Error::Fault(Fault {
            kernel: self.fault.names.name,
            kind: FaultKind::NonFiniteInput {
                arg: self.fault.names.params[0],
                index: row as usize * w + j,
                values: vec![r[j].to_f64()],
            },
            launch: None,
        }))
    }

    fn fault_slot(&mut self) -> Option<&mut StepFault> {
        Some(&mut self.fault)
    }
}

// ------------------------------------------------------------------------------------------
// Transpose
// ------------------------------------------------------------------------------------------

/// Each stored block's row, sort key (its column) and index (`sp_ops_row_keys_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct RowKeys {
    pub offsets: u64,
    pub columns: u64,
    pub block_rows: u64,
    pub keys: u64,
    pub idx: u64,
    pub nrow: i32,
    pub ncol: i32,
    pub cap: i32,
    pub pad: i32,
}
const _: () = assert!(std::mem::size_of::<RowKeys>() == 56);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_row_keys_t`; a Bsr's offsets and columns, and
// cap-element scratch.
unsafe impl ObjectStep for RowKeys {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str = "wp_sparse_ops_row_keys";

    fn len(&self) -> usize {
        self.nrow as usize
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl.
        let off = unsafe { offsets(self.offsets, self.nrow) };
        let nnz = nnz_of(off, self.nrow as usize, self.cap);
        let cols = unsafe { slice::<i32>(self.columns, nnz) };
        let (brows, keys, idx) = (
            Ptr(self.block_rows as *mut i32),
            Ptr(self.keys as *mut u32),
            Ptr(self.idx as *mut i32),
        );
        let ncol = self.ncol;
        (0..self.len()).into_par_iter().for_each(|r| {
            for k in row(off, r, nnz) {
                let c = cols[k];
                // A column out of range (never in an assembled matrix) sorts last.
                let key = if (0..ncol).contains(&c) { c } else { ncol } as u32;
                // SAFETY: k < nnz <= the capacity these arrays hold. The rows' ranges are
                // disjoint while the offsets ascend (an assembled matrix); overwritten ones
                // may make two rows write one k, hence atomic stores (`store_shared`).
                unsafe {
                    brows.store_shared(k, r as i32);
                    keys.store_shared(k, key);
                    idx.store_shared(k, k as i32);
                }
            }
        });
        Ok(())
    }
}

/// The transposed blocks, their columns and the new offsets (`sp_ops_transpose_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Transpose<S> {
    pub offsets: u64,
    pub block_rows: u64,
    pub keys: u64,
    pub idx: u64,
    pub values: u64,
    pub out_offsets: u64,
    pub out_columns: u64,
    pub out_values: u64,
    pub nrow: i32,
    pub ncol: i32,
    pub cap: i32,
    pub rows: i32,
    pub cols: i32,
    pub cm: i32,
    pub cm_t: i32,
    pub pad: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<Transpose<f32>>() == 96);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_transpose_t`; A's offsets and values, cap-element
// scratch (sorted), the transpose's fresh offsets (ncol + 1), columns and values (cap).
unsafe impl<S: SparseScalar> ObjectStep for Transpose<S> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str =
        by_scalar::<S>("wp_sparse_ops_transpose_f32", "wp_sparse_ops_transpose_f64");

    fn len(&self) -> usize {
        (self.cap as usize).max(self.ncol as usize + 1)
    }

    fn run_cpu(&self) -> Result<()> {
        let (rr, cc) = (self.rows as usize, self.cols as usize);
        let (cm, cm_t) = (self.cm != 0, self.cm_t != 0);
        // SAFETY: see the impl.
        let off = unsafe { offsets(self.offsets, self.nrow) };
        let nnz = nnz_of(off, self.nrow as usize, self.cap);
        let (brows, keys, idx, vals) = unsafe {
            (
                slice::<i32>(self.block_rows, nnz),
                slice::<u32>(self.keys, nnz),
                slice::<i32>(self.idx, nnz),
                slice::<S>(self.values, nnz * rr * cc),
            )
        };
        let (oo, oc, ov) = (
            Ptr(self.out_offsets as *mut i32),
            Ptr(self.out_columns as *mut i32),
            Ptr(self.out_values as *mut S),
        );
        let ncol = self.ncol as usize;
        (0..self.len())
            .into_par_iter()
            .with_min_len(256)
            .for_each(|t| {
                // SAFETY: each task its own sorted block t and offset t.
                unsafe {
                    if t < nnz {
                        let k = idx[t] as usize;
                        oc.at(t).write(brows[k]);
                        let a = &vals[k * rr * cc..][..rr * cc];
                        for i in 0..rr {
                            for j in 0..cc {
                                ov.at(t * rr * cc + at(j, i, cc, rr, cm_t))
                                    .write(a[at(i, j, rr, cc, cm)]);
                            }
                        }
                    }
                    if t <= ncol {
                        oo.at(t)
                            .write(keys.partition_point(|&x| x < t as u32) as i32);
                    }
                }
            });
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// Triplets of matrices: axpy and mm
// ------------------------------------------------------------------------------------------

/// A matrix's blocks as triplets, each times `factor`, after `base` others
/// (`sp_ops_to_triplets_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct ToTriplets<S> {
    pub offsets: u64,
    pub columns: u64,
    pub values: u64,
    pub base: u64,
    pub rows: u64,
    pub cols: u64,
    pub vals: u64,
    pub count_out: u64,
    pub factor: f64,
    pub nrow: i32,
    pub cap: i32,
    pub block: i32,
    pub limit: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<ToTriplets<f32>>() == 88);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_to_triplets_t`; a Bsr's arrays, base and
// count_out one i32 each (or 0; distinct), triplet arrays of `limit` triplets not overlapping
// the matrix.
unsafe impl<S: SparseScalar> ObjectStep for ToTriplets<S> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str = by_scalar::<S>(
        "wp_sparse_ops_to_triplets_f32",
        "wp_sparse_ops_to_triplets_f64",
    );

    fn len(&self) -> usize {
        self.nrow as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let b = self.block as usize;
        // SAFETY: see the impl.
        let off = unsafe { offsets(self.offsets, self.nrow) };
        let nnz = nnz_of(off, self.nrow as usize, self.cap);
        let (cols, vals) = unsafe {
            (
                slice::<i32>(self.columns, nnz),
                slice::<S>(self.values, nnz * b),
            )
        };
        // SAFETY: one i32.
        let base = if self.base != 0 {
            unsafe { *(self.base as *const i32) as i64 }
        } else {
            0
        };
        // (Thread 0 writes it in the C++ step: with no block row, nothing does.)
        if self.count_out != 0 && self.nrow > 0 {
            let total = (base + nnz as i64).min(i32::MAX as i64) as i32;
            // SAFETY: one i32, not `base`.
            unsafe { (self.count_out as *mut i32).write(total) };
        }
        let (tr, tc, tv) = (
            Ptr(self.rows as *mut i32),
            Ptr(self.cols as *mut i32),
            Ptr(self.vals as *mut S),
        );
        let (f, limit) = (S::from_f64(self.factor), self.limit as i64);
        (0..self.len()).into_par_iter().for_each(|r| {
            for k in row(off, r, nnz) {
                let t = base + k as i64;
                if t < 0 || t >= limit {
                    continue;
                }
                let t = t as usize;
                // SAFETY: t < limit, the triplet arrays' length. Triplet t is block k's
                // alone while the rows' ranges are disjoint (ascending offsets: an assembled
                // matrix); overwritten ones may make two rows write one t, hence atomic
                // stores (`store_shared`).
                unsafe {
                    tr.store_shared(t, r as i32);
                    tc.store_shared(t, cols[k]);
                    for e in 0..b {
                        tv.store_shared(t * b + e, f.mul(vals[k * b + e]));
                    }
                }
            }
        });
        Ok(())
    }
}

/// Each block row's count of products (`sp_ops_mm_count_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MmCount {
    pub a_offsets: u64,
    pub a_columns: u64,
    pub b_offsets: u64,
    pub counts: u64,
    pub a_nrow: i32,
    pub a_cap: i32,
    pub b_nrow: i32,
    pub b_cap: i32,
}
const _: () = assert!(std::mem::size_of::<MmCount>() == 48);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_mm_count_t`; A's and B's arrays, counts of
// a_nrow + 1 i64s.
unsafe impl ObjectStep for MmCount {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str = "wp_sparse_ops_mm_count";

    fn len(&self) -> usize {
        self.a_nrow as usize + 1
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl.
        let (ao, bo) = unsafe {
            (
                offsets(self.a_offsets, self.a_nrow),
                offsets(self.b_offsets, self.b_nrow),
            )
        };
        let (annz, bnnz) = (
            nnz_of(ao, self.a_nrow as usize, self.a_cap),
            nnz_of(bo, self.b_nrow as usize, self.b_cap),
        );
        let ac = unsafe { slice::<i32>(self.a_columns, annz) };
        let counts = Ptr(self.counts as *mut i64);
        let (a_nrow, b_nrow) = (self.a_nrow as usize, self.b_nrow);
        (0..self.len()).into_par_iter().for_each(|r| {
            let n = if r == a_nrow {
                0
            } else {
                row(ao, r, annz)
                    .filter(|&k| (0..b_nrow).contains(&ac[k]))
                    .map(|k| row(bo, ac[k] as usize, bnnz).len() as i64)
                    .sum()
            };
            // SAFETY: each task its own count.
            unsafe { counts.at(r).write(n) };
        });
        Ok(())
    }
}

/// The product count as an i32 (`sp_ops_mm_total_t`, one thread).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MmTotal {
    pub starts: u64,
    pub count: u64,
    pub a_nrow: i32,
    pub pad: i32,
}
const _: () = assert!(std::mem::size_of::<MmTotal>() == 24);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_mm_total_t`; starts of a_nrow + 1 i64s, one i32.
unsafe impl ObjectStep for MmTotal {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str = "wp_sparse_ops_mm_total";

    fn len(&self) -> usize {
        1
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl.
        unsafe {
            let total = *(self.starts as *const i64).add(self.a_nrow as usize);
            (self.count as *mut i32).write(total.min(i32::MAX as i64) as i32);
        }
        Ok(())
    }
}

/// The products as triplets (`sp_ops_mm_expand_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct MmExpand<S> {
    pub a_offsets: u64,
    pub a_columns: u64,
    pub a_values: u64,
    pub b_offsets: u64,
    pub b_columns: u64,
    pub b_values: u64,
    pub starts: u64,
    pub rows: u64,
    pub cols: u64,
    pub vals: u64,
    pub alpha: f64,
    pub limit: i64,
    pub a_nrow: i32,
    pub a_cap: i32,
    pub b_nrow: i32,
    pub b_cap: i32,
    pub r: i32,
    pub k: i32,
    pub c: i32,
    pub cm_a: i32,
    pub cm_b: i32,
    pub cm_c: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<MmExpand<f32>>() == 136);

// SAFETY: `#[repr(C)]`, the layout of `sp_ops_mm_expand_t`; A's and B's arrays, starts of
// a_nrow + 1 i64s (the exclusive scan of MmCount's), triplet arrays of `limit` triplets.
unsafe impl<S: SparseScalar> ObjectStep for MmExpand<S> {
    const LIBRARY: &'static ObjectLibrary = &OPS_LIBRARY;
    const KERNEL: &'static str =
        by_scalar::<S>("wp_sparse_ops_mm_expand_f32", "wp_sparse_ops_mm_expand_f64");

    fn len(&self) -> usize {
        self.a_nrow as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let (rr, kk, cc) = (self.r as usize, self.k as usize, self.c as usize);
        let (cm_a, cm_b, cm_c) = (self.cm_a != 0, self.cm_b != 0, self.cm_c != 0);
        // SAFETY: see the impl.
        let (ao, bo) = unsafe {
            (
                offsets(self.a_offsets, self.a_nrow),
                offsets(self.b_offsets, self.b_nrow),
            )
        };
        let (annz, bnnz) = (
            nnz_of(ao, self.a_nrow as usize, self.a_cap),
            nnz_of(bo, self.b_nrow as usize, self.b_cap),
        );
        let (ac, av, bc, bv, starts) = unsafe {
            (
                slice::<i32>(self.a_columns, annz),
                slice::<S>(self.a_values, annz * rr * kk),
                slice::<i32>(self.b_columns, bnnz),
                slice::<S>(self.b_values, bnnz * kk * cc),
                slice::<i64>(self.starts, self.a_nrow as usize + 1),
            )
        };
        let (tr, tc, tv) = (
            Ptr(self.rows as *mut i32),
            Ptr(self.cols as *mut i32),
            Ptr(self.vals as *mut S),
        );
        let (alpha, limit, b_nrow) = (S::from_f64(self.alpha), self.limit, self.b_nrow);
        (0..self.len()).into_par_iter().for_each(|r| {
            let mut t = starts[r];
            for k in row(ao, r, annz) {
                let c = ac[k];
                if !(0..b_nrow).contains(&c) {
                    continue; // (as MmCount)
                }
                let a = &av[k * rr * kk..][..rr * kk];
                for l in row(bo, c as usize, bnnz) {
                    if t >= limit {
                        return; // more products than room: the pipeline's count faults
                    }
                    let b = &bv[l * kk * cc..][..kk * cc];
                    let tu = t as usize;
                    // SAFETY: row r's products are triplets starts[r] .. starts[r + 1].
                    unsafe {
                        tr.at(tu).write(r as i32);
                        tc.at(tu).write(bc[l]);
                        for i in 0..rr {
                            for j in 0..cc {
                                let mut acc = S::ZERO;
                                for m in 0..kk {
                                    acc = acc.add(
                                        a[at(i, m, rr, kk, cm_a)].mul(b[at(m, j, kk, cc, cm_b)]),
                                    );
                                }
                                tv.at(tu * rr * cc + at(i, j, rr, cc, cm_c))
                                    .write(alpha.mul(acc));
                            }
                        }
                    }
                    t += 1;
                }
            }
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every kernel name the Rust side launches is a kernel of the compiled `sparse_ops`
    /// library (NVRTC, no GPU; skipped, saying so, without libnvrtc).
    #[cfg(feature = "cuda")]
    #[test]
    fn every_ops_kernel_name_is_in_the_compiled_library() {
        if let Err(e) = warp_cuda::nvrtc_version() {
            eprintln!("SKIPPED every_ops_kernel_name_is_in_the_compiled_library: {e}");
            return;
        }
        // sm_80 (A100) compiles too, without warnings (as every build library must).
        let c80 = crate::cuda::objects::compile_library(&OPS_LIBRARY, 80).unwrap();
        assert!(!c80.log.contains("warning"), "{}", c80.log);
        let c = crate::cuda::objects::compile_library(&OPS_LIBRARY, 90).unwrap();
        assert!(!c.log.contains("warning"), "{}", c.log);
        let has = |name: &str| {
            let pat = format!("{name}\0");
            c.cubin.windows(pat.len()).any(|w| w == pat.as_bytes())
        };
        fn scalar<S: SparseScalar>() -> Vec<&'static str> {
            vec![
                Scale::<S>::KERNEL,
                Diag::<S>::KERNEL,
                SetDiag::<S>::KERNEL,
                ToDense::<S>::KERNEL,
                Dense::<S, false>::KERNEL,
                Dense::<S, true>::KERNEL,
                DenseReport::<S>::KERNEL,
                Transpose::<S>::KERNEL,
                ToTriplets::<S>::KERNEL,
                MmExpand::<S>::KERNEL,
            ]
        }
        let mut names = scalar::<f32>();
        names.extend(scalar::<f64>());
        names.extend([RowKeys::KERNEL, MmCount::KERNEL, MmTotal::KERNEL]);
        // The rectangular blocks' mv (BsrMv picks this library for them).
        use super::super::block::sealed::SealedBlock;
        use super::super::steps::BsrMv;
        use warp_core::*;
        macro_rules! mv {
            ($($t:ty),*) => {
                $(
                    assert_eq!(
                        <BsrMv<$t> as ObjectStep>::LIBRARY.section(),
                        OPS_LIBRARY.section()
                    );
                    names.push(<$t as SealedBlock>::KERNELS.mv);
                )*
            };
        }
        mv!(
            Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64,
            DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63,
            DMat64
        );
        assert_eq!(
            <BsrMv<glam::Mat3> as ObjectStep>::LIBRARY.section(),
            super::super::steps::LIBRARY.section()
        );
        assert_eq!(names.len(), 23 + 24);
        let distinct: std::collections::BTreeSet<_> = names.iter().collect();
        assert_eq!(distinct.len(), names.len(), "a name twice: {names:?}");
        for n in &names {
            assert!(has(n), "{n} is not a kernel of the compiled library");
        }
        assert!(!has("wp_sparse_ops_scale_f16"));
    }

    /// Each record's fields sit at the same offsets in Rust and in C++ (g++'s `offsetof`).
    /// Skipped, saying so, without g++.
    #[test]
    fn ops_record_offsets_are_the_headers() {
        let fields = record_layouts![
            Scale<f32> => "sp_ops_scale_t" { offsets, values, alpha, nrow, cap, block, pad },
            Diag<f32> => "sp_ops_diag_t" {
                offsets, columns, values, out, nrow, ncol, cap, block
            },
            SetDiag<f32> => "sp_ops_set_diag_t" {
                offsets, columns, values, d, nrow, n, dim, block
            },
            ToDense<f32> => "sp_ops_to_dense_t" {
                offsets, columns, values, out, nrow, ncol, cap, rows, cols, cm
            },
            Dense<f32, false> => "sp_ops_dense_t" {
                dense, pos, bad, block_rows, columns, values, nrow, ncol, rows, cols, cm, pad
            },
            DenseReport<f32> => "sp_ops_dense_report_t" { dense, bad, width, fault },
            RowKeys => "sp_ops_row_keys_t" {
                offsets, columns, block_rows, keys, idx, nrow, ncol, cap, pad
            },
            Transpose<f32> => "sp_ops_transpose_t" {
                offsets, block_rows, keys, idx, values, out_offsets, out_columns, out_values,
                nrow, ncol, cap, rows, cols, cm, cm_t, pad
            },
            ToTriplets<f32> => "sp_ops_to_triplets_t" {
                offsets, columns, values, base, rows, cols, vals, count_out, factor, nrow,
                cap, block, limit
            },
            MmCount => "sp_ops_mm_count_t" {
                a_offsets, a_columns, b_offsets, counts, a_nrow, a_cap, b_nrow, b_cap
            },
            MmTotal => "sp_ops_mm_total_t" { starts, count, a_nrow, pad },
            MmExpand<f32> => "sp_ops_mm_expand_t" {
                a_offsets, a_columns, a_values, b_offsets, b_columns, b_values, starts, rows,
                cols, vals, alpha, limit, a_nrow, a_cap, b_nrow, b_cap, r, k, c, cm_a, cm_b,
                cm_c
            },
        ];
        crate::sparse::record_check::check_record_offsets(
            "sparse::ops_steps::ops_record_offsets_are_the_headers",
            "wp_sparse_ops.h",
            &fields,
        );
    }
}

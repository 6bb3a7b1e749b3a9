//! The sparse tier's data-parallel steps ([`ObjectStep`]s): each a `#[repr(C)]` record laid
//! out as the C++ struct its kernel in `wp_sparse.h` takes (both sides assert the size), and
//! the same step on the CPU with rayon, in the same order of operations, so that the CPU and a
//! GPU give the same bits. `mod.rs` and `solve.rs` order them around the primitives.
//!
//! Addresses are of contiguous arrays on the step's device that the caller checked and sized
//! (the callers' comments say how many elements each holds).

use super::block::{at, sealed::SealedBlock, sealed::SealedScalar, Block, SparseScalar, MAX_DIM};
use crate::backend::{ObjectLibrary, ObjectStep, StepFault};
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use rayon::prelude::*;
use std::marker::PhantomData;
use warp_core::{Fault, FaultKind};

/// The sparse tier's build library: `wp_sparse.h` with its kernels enabled.
pub(crate) static LIBRARY: ObjectLibrary = ObjectLibrary::of("sparse");

/// Lanes of a dot product's block (the object-step launcher's block size, which the CUDA dot
/// kernels assume) and elements per chunk; `wp_sparse.h`'s `SP_DOT_LANES`, `SP_DOT_CHUNK`.
pub(crate) const DOT_LANES: usize = 256;
pub(crate) const DOT_CHUNK: usize = 4096;
#[cfg(feature = "cuda")]
const _: () = assert!(crate::cuda::objects::THREADS as usize == DOT_LANES);

/// What `from_triplets`' faults are named by.
pub(crate) static TRIPLET_NAMES: KernelInfo = KernelInfo {
    name: "sparse::from_triplets",
    module: "warp_lang::sparse",
    params: &["rows", "columns", "values", "count"],
    ..KernelInfo::BLANK
};

/// A pointer rayon tasks share, for writes to elements no two tasks share.
#[derive(Clone, Copy)]
pub(super) struct Ptr<T>(pub(super) *mut T);
// SAFETY: every use writes elements no other task touches (see the callers).
unsafe impl<T> Send for Ptr<T> {}
unsafe impl<T> Sync for Ptr<T> {}
impl<T> Ptr<T> {
    /// Element `i` (a method, so that closures capture the `Ptr`).
    pub(super) fn at(self, i: usize) -> *mut T {
        self.0.wrapping_add(i)
    }
}

/// The kernel of a scalar-generic step: `f32_name` or `f64_name` by the scalar's size (the
/// sealed scalars are `f32` and `f64`).
pub(super) const fn by_scalar<S>(f32_name: &'static str, f64_name: &'static str) -> &'static str {
    if std::mem::size_of::<S>() == 8 {
        f64_name
    } else {
        f32_name
    }
}

impl<T: Copy> Ptr<T> {
    /// Reads element `i`.
    ///
    /// # Safety
    /// Element `i` is initialised and no other task writes it.
    pub(super) unsafe fn get(self, i: usize) -> T {
        *self.at(i)
    }

    /// Stores `v` at element `i` by a relaxed atomic store, for steps whose tasks write
    /// disjoint elements only while a matrix's offsets ascend: a user may overwrite them
    /// through [`Bsr::offsets`](super::Bsr::offsets), and then two tasks may write one
    /// element. As atomics that is defined behaviour (one of the values stays, as when the
    /// CUDA step's threads race there); plain writes would be a data race. 4- and 8-byte
    /// elements only (checked at compile time); a relaxed store is a plain store on x86-64
    /// and AArch64.
    ///
    /// # Safety
    /// Element `i` is in bounds of the allocation, aligned, and no task reads it during the
    /// step.
    pub(super) unsafe fn store_shared(self, i: usize, v: T) {
        use std::sync::atomic::{AtomicU32, AtomicU64, Ordering::Relaxed};
        const {
            assert!(std::mem::size_of::<T>() == 4 || std::mem::size_of::<T>() == 8);
        }
        let p = self.at(i);
        if std::mem::size_of::<T>() == 4 {
            // SAFETY: 4 aligned bytes in bounds (the caller), read as the bits of `v`.
            AtomicU32::from_ptr(p.cast()).store(std::mem::transmute_copy(&v), Relaxed);
        } else {
            // SAFETY: as above, 8 bytes (an f64 or i64 element is 8-aligned).
            AtomicU64::from_ptr(p.cast()).store(std::mem::transmute_copy(&v), Relaxed);
        }
    }
}

/// `n` elements at `addr`.
///
/// # Safety
/// `addr` holds `n` initialised `T`s that nothing writes during the borrow.
pub(super) unsafe fn slice<'a, T>(addr: u64, n: usize) -> &'a [T] {
    if n == 0 {
        return &[];
    }
    std::slice::from_raw_parts(addr as *const T, n)
}

/// The triplets a step processes: `n`, or with a device count (`count`, the address of an
/// `i32`, nonzero) its value, or 0 when it is outside `0..=n` (`wp_sparse.h`'s `sp_count`:
/// the primitives' rule for a bad count, so every step and primitive processes nothing; the
/// report step raises the fault).
pub(super) fn count(count: u64, n: i32) -> usize {
    if count == 0 {
        return n.max(0) as usize;
    }
    // SAFETY: a one-element i32 array on the host (from_triplets_n checked it).
    let c = unsafe { *(count as *const i32) };
    if (0..=n).contains(&c) {
        c as usize
    } else {
        0
    }
}

/// Whether triplet `t` is in range.
fn valid(rows: &[i32], cols: &[i32], t: usize, nrow: i32, ncol: i32) -> bool {
    let (r, c) = (rows[t], cols[t]);
    (0..nrow).contains(&r) && (0..ncol).contains(&c)
}

// ------------------------------------------------------------------------------------------
// Triplets
// ------------------------------------------------------------------------------------------

/// Each triplet's sort key and index, and the smallest bad triplets (`sp_tpl_keys_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct TplKeys<S> {
    pub count: u64,
    pub rows: u64,
    pub cols: u64,
    pub values: u64,
    pub n: i32,
    pub nrow: i32,
    pub ncol: i32,
    pub block: i32,
    pub two_pass: i32,
    /// 1: values are not checked (the structure operations' triplets are a matrix's blocks).
    pub no_finite_check: i32,
    pub keys: u64,
    pub idx: u64,
    pub bad: u64,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<TplKeys<f32>>() == 80);

// SAFETY: `#[repr(C)]`, the layout of `sp_tpl_keys_t`; from_triplets passes its n-element
// inputs and scratch, and a 3-element i32 array at `bad`.
unsafe impl<S: SparseScalar> ObjectStep for TplKeys<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = <S as SealedScalar>::KERNELS.tpl_keys;

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = count(self.count, self.n);
        let b = self.block as usize;
        // SAFETY: see the impl.
        let (rows, cols, values) = unsafe {
            (
                slice::<i32>(self.rows, n),
                slice::<i32>(self.cols, n),
                slice::<S>(self.values, n * b),
            )
        };
        let (keys, idx) = (Ptr(self.keys as *mut u32), Ptr(self.idx as *mut i32));
        let (nrow, ncol, two_pass) = (self.nrow, self.ncol, self.two_pass != 0);
        let check = self.no_finite_check == 0;
        // The smallest bad triplet of each kind (a min over threads: order-free).
        let bad = (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .map(|t| {
                let (r, c) = (rows[t], cols[t]);
                let (row_ok, col_ok) = ((0..nrow).contains(&r), (0..ncol).contains(&c));
                let fin = !check || values[t * b..(t + 1) * b].iter().all(|v| v.finite());
                let key = match (row_ok && col_ok, two_pass) {
                    (true, false) => r as u32 * ncol as u32 + c as u32,
                    (true, true) => c as u32,
                    (false, false) => nrow as u32 * ncol as u32,
                    (false, true) => ncol as u32,
                };
                // SAFETY: `n` keys and indices; each task writes its own `t`.
                unsafe {
                    keys.at(t).write(key);
                    idx.at(t).write(t as i32);
                }
                let pick = |ok: bool| if ok { i32::MAX } else { t as i32 };
                [pick(row_ok), pick(col_ok), pick(fin)]
            })
            .reduce(
                || [i32::MAX; 3],
                |a, b| [a[0].min(b[0]), a[1].min(b[1]), a[2].min(b[2])],
            );
        // SAFETY: the 3-element array at `bad`, which nothing else touches now.
        let out = unsafe { std::slice::from_raw_parts_mut(self.bad as *mut i32, 3) };
        for (o, b) in out.iter_mut().zip(bad) {
            *o = (*o).min(b);
        }
        Ok(())
    }
}

/// The keys step's report (`sp_tpl_report_t`): one thread raises the smallest bad triplet.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct TplReport<S> {
    pub count: u64,
    pub bad: u64,
    pub rows: u64,
    pub cols: u64,
    pub values: u64,
    pub n: i32,
    pub nrow: i32,
    pub ncol: i32,
    pub block: i32,
    pub fault: StepFault,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<TplReport<f64>>() == 96);

/// The fault of triplet report `bad` (the smallest bad triplet of each kind), if any: the
/// CPU's error, the same fault the CUDA step raises.
fn triplet_fault<S: SparseScalar>(r: &TplReport<S>, bad: [i32; 3]) -> Option<Fault> {
    // The names the step's fault context carries (`from_triplets`', or an operation's that
    // feeds the pipeline).
    let names = r.fault.names;
    if r.count != 0 {
        // SAFETY: a one-element i32 array.
        let c = unsafe { *(r.count as *const i32) };
        if c < 0 || c > r.n {
            return Some(Fault {
                kernel: names.name,
                kind: FaultKind::OutOfBounds {
                    arg: names.params[3],
                    index: vec![c as i128],
                    shape: vec![r.n as usize + 1],
                },
                launch: None,
            });
        }
    }
    let (which, t) = bad
        .iter()
        .enumerate()
        .filter(|(_, &t)| t != i32::MAX)
        .min_by_key(|(w, &t)| (t, *w))
        .map(|(w, &t)| (w, t as usize))?;
    let n = count(r.count, r.n);
    let kind = if which < 2 {
        // SAFETY: `n` i32s of each (see TplKeys).
        let v = unsafe { slice::<i32>(if which == 0 { r.rows } else { r.cols }, n) }[t];
        FaultKind::OutOfBounds {
            arg: names.params[which],
            index: vec![t as i128, v as i128],
            shape: vec![n, if which == 0 { r.nrow } else { r.ncol } as usize],
        }
    } else {
        let b = r.block as usize;
        // SAFETY: `n` blocks of `b` scalars.
        let v = unsafe { slice::<S>(r.values, n * b) };
        let block = &v[t * b..(t + 1) * b];
        let x = block
            .iter()
            .copied()
            .find(|x| !x.finite())
            .unwrap_or(block[0]);
        FaultKind::NonFiniteInput {
            arg: names.params[2],
            index: t,
            values: vec![x.to_f64()],
        }
    };
    Some(Fault {
        kernel: names.name,
        kind,
        launch: None,
    })
}

// SAFETY: `#[repr(C)]`, the layout of `sp_tpl_report_t`; the addresses are TplKeys'.
unsafe impl<S: SparseScalar> ObjectStep for TplReport<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = <S as SealedScalar>::KERNELS.tpl_report;

    fn len(&self) -> usize {
        1
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: the 3-element array at `bad`.
        let bad = unsafe { slice::<i32>(self.bad, 3) };
        match triplet_fault(self, [bad[0], bad[1], bad[2]]) {
            Some(f) => Err(Error::Fault(f)),
            None => Ok(()),
        }
    }

    fn fault_slot(&mut self) -> Option<&mut StepFault> {
        Some(&mut self.fault)
    }
}

/// The second sort's keys in the two-pass path (`sp_tpl_row_keys_t`): the row of each sorted
/// triplet (`nrow` for one out of range).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct TplRowKeys {
    pub count: u64,
    pub rows: u64,
    pub cols: u64,
    pub idx: u64,
    pub keys: u64,
    pub n: i32,
    pub nrow: i32,
    pub ncol: i32,
    pub pad: i32,
}
const _: () = assert!(std::mem::size_of::<TplRowKeys>() == 56);

// SAFETY: `#[repr(C)]`, the layout of `sp_tpl_row_keys_t`; n-element arrays.
unsafe impl ObjectStep for TplRowKeys {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_sparse_tpl_row_keys";

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = count(self.count, self.n);
        // SAFETY: see the impl; `keys` is written, the others read.
        let (rows, cols, idx) = unsafe {
            (
                slice::<i32>(self.rows, n),
                slice::<i32>(self.cols, n),
                slice::<i32>(self.idx, n),
            )
        };
        let keys = Ptr(self.keys as *mut u32);
        let (nrow, ncol) = (self.nrow, self.ncol);
        (0..n).into_par_iter().with_min_len(4096).for_each(|k| {
            let t = idx[k] as usize;
            let key = if valid(rows, cols, t, nrow, ncol) {
                rows[t] as u32
            } else {
                nrow as u32
            };
            // SAFETY: each task writes its own `k`.
            unsafe { keys.at(k).write(key) };
        });
        Ok(())
    }
}

/// Run heads of the sorted triplets (`sp_tpl_heads_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct TplHeads {
    pub count: u64,
    pub rows: u64,
    pub cols: u64,
    pub idx: u64,
    pub heads: u64,
    pub n: i32,
    pub nrow: i32,
    pub ncol: i32,
    pub pad: i32,
}
const _: () = assert!(std::mem::size_of::<TplHeads>() == 56);

// SAFETY: `#[repr(C)]`, the layout of `sp_tpl_heads_t`; n-element arrays.
unsafe impl ObjectStep for TplHeads {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_sparse_tpl_heads";

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = count(self.count, self.n);
        // SAFETY: see the impl; `heads` is written, the others read.
        let (rows, cols, idx) = unsafe {
            (
                slice::<i32>(self.rows, n),
                slice::<i32>(self.cols, n),
                slice::<i32>(self.idx, n),
            )
        };
        let heads = Ptr(self.heads as *mut i32);
        let (nrow, ncol) = (self.nrow, self.ncol);
        (0..n).into_par_iter().with_min_len(4096).for_each(|k| {
            let t = idx[k] as usize;
            let head = valid(rows, cols, t, nrow, ncol) && {
                // Out-of-range triplets sort last: a valid one's predecessor is valid.
                k == 0 || {
                    let p = idx[k - 1] as usize;
                    rows[p] != rows[t] || cols[p] != cols[t]
                }
            };
            // SAFETY: each task writes its own `k`.
            unsafe { heads.at(k).write(head as i32) };
        });
        Ok(())
    }
}

/// Each run's block (`sp_tpl_sum_t`): row, column, and the sum of its values in sorted order.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct TplSum<S> {
    pub count: u64,
    pub rows: u64,
    pub cols: u64,
    pub values: u64,
    pub idx: u64,
    pub pos: u64,
    pub block_rows: u64,
    pub columns: u64,
    pub out: u64,
    pub n: i32,
    pub nrow: i32,
    pub ncol: i32,
    pub block: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<TplSum<f32>>() == 88);

// SAFETY: `#[repr(C)]`, the layout of `sp_tpl_sum_t`; n-element inputs and scratch, and
// outputs of n blocks (at most n runs).
unsafe impl<S: SparseScalar> ObjectStep for TplSum<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = <S as SealedScalar>::KERNELS.tpl_sum;

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = count(self.count, self.n);
        let b = self.block as usize;
        // SAFETY: see the impl; the outputs are written.
        let (rows, cols, values, idx, pos) = unsafe {
            (
                slice::<i32>(self.rows, n),
                slice::<i32>(self.cols, n),
                slice::<S>(self.values, n * b),
                slice::<i32>(self.idx, n),
                slice::<i32>(self.pos, n),
            )
        };
        let (brows, bcols, out) = (
            Ptr(self.block_rows as *mut i32),
            Ptr(self.columns as *mut i32),
            Ptr(self.out as *mut S),
        );
        let (nrow, ncol) = (self.nrow, self.ncol);
        (0..n).into_par_iter().with_min_len(1024).for_each(|k| {
            let t = idx[k] as usize;
            let prev = if k > 0 { pos[k - 1] } else { 0 };
            if !valid(rows, cols, t, nrow, ncol) || pos[k] - prev != 1 {
                return;
            }
            let blk = (pos[k] - 1) as usize;
            let (r, c) = (rows[t], cols[t]);
            // SAFETY: block `blk` is written by its run's head alone (one head per run).
            unsafe {
                brows.at(blk).write(r);
                bcols.at(blk).write(c);
                let o = out.at(blk * b);
                for e in 0..b {
                    o.add(e).write(values[t * b + e]);
                }
                for &u in &idx[k + 1..] {
                    let u = u as usize;
                    if !valid(rows, cols, u, nrow, ncol) || rows[u] != r || cols[u] != c {
                        break;
                    }
                    for e in 0..b {
                        let p = o.add(e);
                        p.write((*p).add(values[u * b + e]));
                    }
                }
            }
        });
        Ok(())
    }
}

/// Row offsets from the blocks' sorted rows (`sp_bsr_offsets_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct BsrOffsets {
    pub count: u64,
    pub block_rows: u64,
    pub pos: u64,
    pub offsets: u64,
    pub n: i32,
    pub nrow: i32,
}
const _: () = assert!(std::mem::size_of::<BsrOffsets>() == 40);

// SAFETY: `#[repr(C)]`, the layout of `sp_bsr_offsets_t`; `n` positions and block rows,
// `nrow + 1` offsets.
unsafe impl ObjectStep for BsrOffsets {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_sparse_bsr_offsets";

    fn len(&self) -> usize {
        self.nrow as usize + 1
    }

    fn run_cpu(&self) -> Result<()> {
        let n = count(self.count, self.n);
        // SAFETY: see the impl.
        let pos = unsafe { slice::<i32>(self.pos, n) };
        let nnz = pos.last().map_or(0, |&p| p as usize);
        // SAFETY: the first `nnz <= n` block rows were written by TplSum.
        let brows = unsafe { slice::<i32>(self.block_rows, nnz) };
        let offsets = Ptr(self.offsets as *mut i32);
        (0..self.len())
            .into_par_iter()
            .with_min_len(4096)
            .for_each(|r| {
                let first = brows.partition_point(|&x| x < r as i32);
                // SAFETY: each task writes its own `r`.
                unsafe { offsets.at(r).write(first as i32) };
            });
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// Products
// ------------------------------------------------------------------------------------------

/// `y = alpha A x + beta y`, a block row per thread (`sp_bsr_mv_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct BsrMv<B> {
    pub offsets: u64,
    pub columns: u64,
    pub values: u64,
    pub x: u64,
    pub y: u64,
    pub alpha: f64,
    pub beta: f64,
    pub nrow: i32,
    pub ncol: i32,
    pub cap: i32,
    /// Lanes per scalar row (`w`: 1, 2, 4, .., 32): see [`mv_row`].
    pub lanes: i32,
    pub block: PhantomData<B>,
}
const _: () = assert!(std::mem::size_of::<BsrMv<f32>>() == 72);

/// Block row `r`'s blocks, clamped as `sp_row_range` does (offsets a user overwrote never
/// reach outside the arrays; an assembled matrix is unchanged): `nnz` is `offsets[nrow]`
/// clamped into `0..=cap`.
#[inline]
fn row_range(offsets: &[i32], nnz: usize, r: usize) -> std::ops::Range<usize> {
    let lo = (offsets[r].max(0) as usize).min(nnz);
    let hi = (offsets[r + 1].max(0) as usize).clamp(lo, nnz);
    lo..hi
}

/// `offsets[nrow]` clamped into `0..=cap`.
pub(super) fn clamped_nnz(offsets: &[i32], cap: i32) -> usize {
    offsets[offsets.len() - 1].clamp(0, cap.max(0)) as usize
}

/// Block row `r` of `A x` into `acc` (the C++ `sp_bsr_mv_lane` and `sp_bsr_mv_lanes`'
/// order). With `w` lanes, each row scalar's lane `l` sums from 0, over the row's blocks at
/// positions `l, l + w, ..` in storage order and in a block over ascending columns, the
/// products `a_ij * x_j`; the lanes' partials are then added pairwise at strides `w/2, ..,
/// 1` (lane `l` gets `l + stride`), each operation rounded. `w = 1` is the plain sum in
/// storage order.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn mv_row<B: Block>(
    offsets: &[i32],
    columns: &[i32],
    values: &[B::Scalar],
    x: &[B::Scalar],
    ncol: i32,
    r: usize,
    w: usize,
    acc: &mut [B::Scalar; MAX_DIM],
) {
    // (The row's slices and fixed-size chunks of them: the loop over a row's blocks then has
    // no bounds check of its own.)
    let (rr, cc) = (B::ROWS, B::COLS);
    *acc = [B::Scalar::ZERO; MAX_DIM];
    let range = row_range(offsets, columns.len(), r);
    let cols = &columns[range.clone()];
    let vals = &values[range.start * rr * cc..range.end * rr * cc];
    if w <= 1 {
        for (&c, a) in cols.iter().zip(vals.chunks_exact(rr * cc)) {
            if !(0..ncol).contains(&c) {
                continue; // (never in an assembled matrix)
            }
            let xc = &x[c as usize * cc..][..cc];
            for (i, acc) in acc.iter_mut().take(rr).enumerate() {
                for (j, &xj) in xc.iter().enumerate() {
                    *acc = acc.add(a[at::<B>(i, j)].mul(xj));
                }
            }
        }
        return;
    }
    for (i, acc) in acc.iter_mut().take(rr).enumerate() {
        let mut lanes = [B::Scalar::ZERO; MAX_LANES];
        for (n, (&c, a)) in cols.iter().zip(vals.chunks_exact(rr * cc)).enumerate() {
            if !(0..ncol).contains(&c) {
                continue;
            }
            let xc = &x[c as usize * cc..][..cc];
            let s = &mut lanes[n % w];
            for (j, &xj) in xc.iter().enumerate() {
                *s = s.add(a[at::<B>(i, j)].mul(xj));
            }
        }
        let mut stride = w / 2;
        while stride > 0 {
            for l in 0..stride {
                lanes[l] = lanes[l].add(lanes[l + stride]);
            }
            stride /= 2;
        }
        *acc = lanes[0];
    }
}

/// The most lanes per scalar row of `mv` (a warp).
pub(crate) const MAX_LANES: usize = 32;

/// The matrix's offsets, columns and values and x, as the CPU body reads them.
type MvArrays<'a, S> = (&'a [i32], &'a [i32], &'a [S], &'a [S]);

/// Block rows `rows` of `y = alpha A x + beta y` with `w` lanes (`LANES`: `w > 1`; else the
/// one-lane loop, `w` unused), each row scalar as `mv_row` sums it.
#[inline(always)]
fn mv_rows<B: Block, const LANES: bool>(
    (offsets, columns, values, x): MvArrays<'_, B::Scalar>,
    ncol: i32,
    rows: std::ops::Range<usize>,
    w: usize,
    alpha: B::Scalar,
    beta: B::Scalar,
    y: Ptr<B::Scalar>,
) {
    let rr = B::ROWS;
    for r in rows {
        let mut acc = [B::Scalar::ZERO; MAX_DIM];
        let w = if LANES { w } else { 1 };
        mv_row::<B>(offsets, columns, values, x, ncol, r, w, &mut acc);
        for (i, &a) in acc.iter().take(rr).enumerate() {
            // SAFETY: y's scalars of block row r, written by this task alone (y does not
            // overlap x); the caller's contract (`run_cpu`).
            unsafe {
                let p = y.at(r * rr + i);
                let v = if beta == B::Scalar::ZERO {
                    alpha.mul(a)
                } else {
                    alpha.mul(a).add(beta.mul(*p))
                };
                p.write(v);
            }
        }
    }
}

// SAFETY: `#[repr(C)]`, the layout of `sp_bsr_mv_t`; a Bsr's arrays (offsets nrow + 1,
// columns and values at least offsets[nrow] blocks), x of ncol COLS scalars and y of nrow ROWS,
// not overlapping x (mv checked).
unsafe impl<B: Block> ObjectStep for BsrMv<B> {
    // The rectangular blocks' (slice 2) are instantiated in wp_sparse_ops.h's library
    // (ops_steps.rs' OPS_LIBRARY, spelled here: ops_steps imports this file, and files import
    // one way, tests/architecture.rs; a library is its section name, nothing more).
    const LIBRARY: &'static ObjectLibrary = if B::ROWS == B::COLS {
        &LIBRARY
    } else {
        &ObjectLibrary::of("sparse_ops")
    };
    const KERNEL: &'static str = <B as SealedBlock>::KERNELS.mv;

    /// A GPU thread per scalar row (block row and sub-row, `sp_bsr_mv_sub`), times the lanes.
    fn len(&self) -> usize {
        self.nrow as usize * B::ROWS * self.lanes.max(1) as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let nrow = self.nrow as usize;
        let (rr, cc) = (B::ROWS, B::COLS);
        // SAFETY: see the impl. The block count is offsets[nrow] (written by assembly),
        // clamped to the capacity.
        let offsets = unsafe { slice::<i32>(self.offsets, nrow + 1) };
        let nnz = clamped_nnz(offsets, self.cap);
        // SAFETY: as above: `nnz` blocks, x of ncol COLS scalars.
        let (columns, values, x) = unsafe {
            (
                slice::<i32>(self.columns, nnz),
                slice::<B::Scalar>(self.values, nnz * rr * cc),
                slice::<B::Scalar>(self.x, self.ncol as usize * cc),
            )
        };
        let y = Ptr(self.y as *mut B::Scalar);
        let alpha = B::Scalar::from_f64(self.alpha);
        let beta = B::Scalar::from_f64(self.beta);
        let w = (self.lanes.max(1) as usize).min(MAX_LANES);
        // A task per run of MV_ROWS block rows (the benchmark's rows hold 5 to 15 blocks: a
        // task per row spent more on scheduling than on the row). Rows are independent, so
        // the split changes no result.
        const MV_ROWS: usize = 512;
        (0..nrow.div_ceil(MV_ROWS))
            .into_par_iter()
            .for_each(|chunk| {
                let rows = chunk * MV_ROWS..((chunk + 1) * MV_ROWS).min(nrow);
                let (m, ncol) = ((offsets, columns, values, x), self.ncol);
                // (One lane, the default, as a constant: its loop keeps no lane logic.)
                if w <= 1 {
                    mv_rows::<B, false>(m, ncol, rows, 1, alpha, beta, y);
                } else {
                    mv_rows::<B, true>(m, ncol, rows, w, alpha, beta, y);
                }
            });
        Ok(())
    }
}

/// A dot product's step (`sp_dot_t`): `Partials` per chunk, then `Final` over the partials.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Dot<S, const FINAL: bool> {
    pub a: u64,
    pub b: u64,
    pub n: i64,
    pub out: u64,
    pub chunks: i64,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<Dot<f32, false>>() == 40);

/// The lanes' tree (`sp_tree_level` at strides 128 .. 1): the sum ends in `s[0]`.
fn tree<S: SparseScalar>(s: &mut [S; DOT_LANES]) -> S {
    let mut stride = DOT_LANES / 2;
    while stride > 0 {
        for l in 0..stride {
            s[l] = s[l].add(s[l + stride]);
        }
        stride /= 2;
    }
    s[0]
}

/// Chunk `c`'s partial sum of `a . b` (lanes as `sp_dot_lane`, then the tree).
fn chunk_partial<S: SparseScalar>(a: &[S], b: &[S], c: usize) -> S {
    // Lane l sums the products of elements l, l + 256, .. of the chunk in that order: taken
    // a row of 256 at a time, all lanes at once (independent sums, so the compiler may use
    // vector registers; each lane's order is unchanged).
    let mut s = [S::ZERO; DOT_LANES];
    let lo = (c * DOT_CHUNK).min(a.len());
    let hi = (lo + DOT_CHUNK).min(a.len());
    for (ra, rb) in a[lo..hi].chunks(DOT_LANES).zip(b[lo..hi].chunks(DOT_LANES)) {
        for ((s, &x), &y) in s.iter_mut().zip(ra).zip(rb) {
            *s = s.add(x.mul(y));
        }
    }
    tree(&mut s)
}

/// The partials' total (lanes as `sp_dot_final_lane`, then the tree).
fn final_sum<S: SparseScalar>(partials: &[S]) -> S {
    let mut s = [S::ZERO; DOT_LANES];
    for (lane, s) in s.iter_mut().enumerate() {
        let mut acc = S::ZERO;
        for &p in partials.iter().skip(lane).step_by(DOT_LANES) {
            acc = acc.add(p);
        }
        *s = acc;
    }
    tree(&mut s)
}

// SAFETY: `#[repr(C)]`, the layout of `sp_dot_t`; Partials: a and b of n scalars, out of
// `chunks`; Final: `chunks` partials at a, one scalar at out.
unsafe impl<S: SparseScalar, const FINAL: bool> ObjectStep for Dot<S, FINAL> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = if FINAL {
        <S as SealedScalar>::KERNELS.dot_final
    } else {
        <S as SealedScalar>::KERNELS.dot_partials
    };

    fn len(&self) -> usize {
        // A block of DOT_LANES threads per chunk (one block for the final sum).
        if FINAL {
            DOT_LANES
        } else {
            self.chunks as usize * DOT_LANES
        }
    }

    fn run_cpu(&self) -> Result<()> {
        let chunks = self.chunks as usize;
        if FINAL {
            // SAFETY: see the impl.
            let p = unsafe { slice::<S>(self.a, chunks) };
            let v = final_sum(p);
            // SAFETY: one scalar at `out`, not among the partials.
            unsafe { (self.out as *mut S).write(v) };
            return Ok(());
        }
        let n = self.n as usize;
        // SAFETY: see the impl.
        let (a, b) = unsafe { (slice::<S>(self.a, n), slice::<S>(self.b, n)) };
        let out = Ptr(self.out as *mut S);
        (0..chunks).into_par_iter().for_each(|c| {
            let v = chunk_partial(a, b, c);
            // SAFETY: each task writes its own chunk's partial.
            unsafe { out.at(c).write(v) };
        });
        Ok(())
    }
}

/// Chunks of a dot product of `n` elements (at least one: an empty product is 0).
pub(crate) fn dot_chunks(n: usize) -> usize {
    n.div_ceil(DOT_CHUNK).max(1)
}

// ------------------------------------------------------------------------------------------
// Jacobi
// ------------------------------------------------------------------------------------------

/// The inverse of each diagonal block (`sp_jacobi_inv_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct JacobiInv<B> {
    pub offsets: u64,
    pub columns: u64,
    pub values: u64,
    pub dinv: u64,
    pub bad: u64,
    pub nrow: i32,
    pub point: i32,
    pub cap: i32,
    pub pad: i32,
    pub block: PhantomData<B>,
}
const _: () = assert!(std::mem::size_of::<JacobiInv<f32>>() == 56);

/// Block row `r`'s inverse diagonal block, row-major, as `sp_jacobi_inv_row` computes it, or
/// `None` (missing, singular or not finite).
fn jacobi_row<B: Block>(
    offsets: &[i32],
    columns: &[i32],
    values: &[B::Scalar],
    r: usize,
    point: bool,
) -> Option<[[B::Scalar; MAX_DIM]; MAX_DIM]> {
    let n = B::ROWS;
    let (z, one) = (B::Scalar::ZERO, B::Scalar::ONE);
    let k = row_range(offsets, columns.len(), r).find(|&k| columns[k] == r as i32)?;
    let blk = &values[k * n * B::COLS..(k + 1) * n * B::COLS];
    let mut a = [[z; MAX_DIM]; MAX_DIM];
    let mut inv = [[z; MAX_DIM]; MAX_DIM];
    for i in 0..n {
        for j in 0..n {
            a[i][j] = if !point || i == j {
                blk[at::<B>(i, j)]
            } else {
                z
            };
        }
        inv[i][i] = one;
    }
    let abs = |x: B::Scalar| if x < z { z.sub(x) } else { x };
    for col in 0..n {
        let mut p = col;
        for i in col + 1..n {
            if abs(a[i][col]) > abs(a[p][col]) {
                p = i;
            }
        }
        if a[p][col] == z {
            return None;
        }
        a.swap(p, col);
        inv.swap(p, col);
        let piv = a[col][col];
        for j in 0..n {
            a[col][j] = a[col][j].div(piv);
            inv[col][j] = inv[col][j].div(piv);
        }
        for i in 0..n {
            if i == col {
                continue;
            }
            let f = a[i][col];
            for j in 0..n {
                a[i][j] = a[i][j].sub(f.mul(a[col][j]));
                inv[i][j] = inv[i][j].sub(f.mul(inv[col][j]));
            }
        }
    }
    inv[..n]
        .iter()
        .all(|row| row[..n].iter().all(|v| v.finite()))
        .then_some(inv)
}

// SAFETY: `#[repr(C)]`, the layout of `sp_jacobi_inv_t`; a square Bsr's arrays, `nrow` blocks
// of ROWS x ROWS scalars at dinv, one i32 at bad.
unsafe impl<B: Block> ObjectStep for JacobiInv<B> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = <B as SealedBlock>::KERNELS.jacobi_inv;

    fn len(&self) -> usize {
        self.nrow as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let nrow = self.len();
        let n = B::ROWS;
        // SAFETY: see the impl.
        let offsets = unsafe { slice::<i32>(self.offsets, nrow + 1) };
        let nnz = clamped_nnz(offsets, self.cap);
        // SAFETY: `nnz <= cap` blocks.
        let (columns, values) = unsafe {
            (
                slice::<i32>(self.columns, nnz),
                slice::<B::Scalar>(self.values, nnz * n * B::COLS),
            )
        };
        let dinv = Ptr(self.dinv as *mut B::Scalar);
        let point = self.point != 0;
        let bad = (0..nrow)
            .into_par_iter()
            .with_min_len(256)
            .map(|r| {
                let inv = jacobi_row::<B>(offsets, columns, values, r, point);
                for i in 0..n {
                    for j in 0..n {
                        let v = inv.map_or(B::Scalar::ZERO, |m| m[i][j]);
                        // SAFETY: block row r's own entries.
                        unsafe { dinv.at(r * n * n + i * n + j).write(v) };
                    }
                }
                if inv.is_some() {
                    i32::MAX
                } else {
                    r as i32
                }
            })
            .min()
            .unwrap_or(i32::MAX);
        // SAFETY: one i32 at `bad`.
        unsafe {
            let p = self.bad as *mut i32;
            p.write((*p).min(bad));
        }
        Ok(())
    }
}

/// `z = D^-1 r` per block row (`sp_jacobi_apply_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct JacobiApply<S> {
    pub dinv: u64,
    pub r: u64,
    pub z: u64,
    pub nrow: i32,
    pub dim: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<JacobiApply<f32>>() == 32);

// SAFETY: `#[repr(C)]`, the layout of `sp_jacobi_apply_t`; nrow dim x dim blocks at dinv,
// nrow dim scalars at r and z (distinct).
unsafe impl<S: SparseScalar> ObjectStep for JacobiApply<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = <S as SealedScalar>::KERNELS.jacobi_apply;

    fn len(&self) -> usize {
        self.nrow as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let (nrow, d) = (self.len(), self.dim as usize);
        // SAFETY: see the impl.
        let (dinv, r) = unsafe {
            (
                slice::<S>(self.dinv, nrow * d * d),
                slice::<S>(self.r, nrow * d),
            )
        };
        let z = Ptr(self.z as *mut S);
        (0..nrow)
            .into_par_iter()
            .with_min_len(1024)
            .for_each(|row| {
                for i in 0..d {
                    let mut acc = S::ZERO;
                    for j in 0..d {
                        acc = acc.add(dinv[row * d * d + i * d + j].mul(r[row * d + j]));
                    }
                    // SAFETY: block row `row`'s own entries.
                    unsafe { z.at(row * d + i).write(acc) };
                }
            });
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// Conjugate gradient
// ------------------------------------------------------------------------------------------

/// Indices of the CG's control words (`i32`) and scalars (`wp_sparse.h`'s `SP_CTL_*`, `SP_*`).
pub(crate) mod cg {
    pub const CTL_STOP: usize = 0;
    pub const CTL_ITER: usize = 1;
    pub const CTL_BAD: usize = 2;
    /// 1 while no stop is set: the flag of a captured solve's `capture_while`.
    pub const CTL_RUN: usize = 3;
    pub const CTL_LEN: usize = 4;
    pub const STOP_NONE: i32 = 0;
    pub const STOP_CONVERGED: i32 = 1;
    pub const STOP_MAX_ITER: i32 = 2;
    pub const STOP_NON_FINITE: i32 = 3;
    pub const STOP_BREAKDOWN: i32 = 4;
    pub const STOP_SINGULAR: i32 = 5;
    /// A breakdown of `r . z` (`STOP_BREAKDOWN` is one of `p . Ap`).
    pub const STOP_BREAKDOWN_RZ: i32 = 6;
    pub const RZ: usize = 0;
    pub const RZ_NEW: usize = 1;
    pub const PAP: usize = 2;
    pub const RR: usize = 3;
    pub const BB: usize = 4;
    pub const TOL2: usize = 5;
    pub const BETA: usize = 6;
    pub const BREAK: usize = 7;
    pub const TOL: usize = 8;
    pub const SCAL_LEN: usize = 9;
}

/// The CG's one-thread steps (`sp_cg_scalar_t`): `CHECK` false is the set-up (`sp_cg_init`),
/// true the check after an iteration (`sp_cg_check`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct CgScalar<S, const CHECK: bool> {
    pub ctl: u64,
    pub scal: u64,
    pub history: u64,
    pub rtol: f64,
    pub atol: f64,
    pub max_iter: i32,
    pub pad: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<CgScalar<f32, false>>() == 48);

impl<S: SparseScalar, const CHECK: bool> CgScalar<S, CHECK> {
    fn init(&self, ctl: &mut [i32], sc: &mut [S], hist: &mut [S]) {
        use cg::*;
        let rt = S::from_f64(self.rtol).mul(sc[BB].sqrt());
        let at = S::from_f64(self.atol);
        let tol = if at > rt { at } else { rt };
        sc[TOL] = tol;
        sc[TOL2] = tol.mul(tol);
        let rr = sc[RR];
        hist[0] = rr.sqrt();
        ctl[CTL_ITER] = 0;
        let rz = sc[RZ];
        ctl[CTL_STOP] = if ctl[CTL_BAD] != i32::MAX {
            STOP_SINGULAR
        } else if !rr.finite() || !rz.finite() {
            STOP_NON_FINITE
        } else if rr <= sc[TOL2] {
            STOP_CONVERGED
        } else if rz <= S::ZERO {
            // An indefinite preconditioner (r != 0 here, so an SPD one gives r.z > 0).
            sc[BREAK] = rz;
            STOP_BREAKDOWN_RZ
        } else if self.max_iter <= 0 {
            STOP_MAX_ITER
        } else {
            STOP_NONE
        };
        ctl[CTL_RUN] = (ctl[CTL_STOP] == STOP_NONE) as i32;
    }

    fn check(&self, ctl: &mut [i32], sc: &mut [S], hist: &mut [S]) {
        self.check_stop(ctl, sc, hist);
        ctl[cg::CTL_RUN] = (ctl[cg::CTL_STOP] == cg::STOP_NONE) as i32;
    }

    fn check_stop(&self, ctl: &mut [i32], sc: &mut [S], hist: &mut [S]) {
        use cg::*;
        if ctl[CTL_STOP] != STOP_NONE {
            return;
        }
        let pap = sc[PAP];
        if !pap.finite() {
            ctl[CTL_STOP] = STOP_NON_FINITE;
            return;
        }
        if pap <= S::ZERO {
            sc[BREAK] = pap;
            ctl[CTL_STOP] = STOP_BREAKDOWN;
            return;
        }
        let it = ctl[CTL_ITER] + 1;
        ctl[CTL_ITER] = it;
        let rr = sc[RR];
        hist[it as usize] = rr.sqrt();
        if !rr.finite() || !sc[RZ_NEW].finite() {
            ctl[CTL_STOP] = STOP_NON_FINITE;
        } else if rr <= sc[TOL2] {
            ctl[CTL_STOP] = STOP_CONVERGED;
        } else if sc[RZ_NEW] <= S::ZERO {
            sc[BREAK] = sc[RZ_NEW];
            ctl[CTL_STOP] = STOP_BREAKDOWN_RZ;
        } else if it >= self.max_iter {
            ctl[CTL_STOP] = STOP_MAX_ITER;
        } else {
            sc[BETA] = sc[RZ_NEW].div(sc[RZ]);
            sc[RZ] = sc[RZ_NEW];
        }
    }
}

// SAFETY: `#[repr(C)]`, the layout of `sp_cg_scalar_t`; CTL_LEN i32s at ctl, SCAL_LEN scalars
// at scal, max_iter + 1 at history (the solver's own arrays).
unsafe impl<S: SparseScalar, const CHECK: bool> ObjectStep for CgScalar<S, CHECK> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = if CHECK {
        <S as SealedScalar>::KERNELS.cg_check
    } else {
        <S as SealedScalar>::KERNELS.cg_init
    };

    fn len(&self) -> usize {
        1
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: see the impl; nothing else touches them during the step.
        let (ctl, sc, hist) = unsafe {
            (
                std::slice::from_raw_parts_mut(self.ctl as *mut i32, cg::CTL_LEN),
                std::slice::from_raw_parts_mut(self.scal as *mut S, cg::SCAL_LEN),
                std::slice::from_raw_parts_mut(self.history as *mut S, self.max_iter as usize + 1),
            )
        };
        if CHECK {
            self.check(ctl, sc, hist);
        } else {
            self.init(ctl, sc, hist);
        }
        Ok(())
    }
}

/// The CG's vector steps (`sp_cg_vector_t`): `DIRECTION` false is `x += alpha p, r -= alpha
/// ap` (`sp_cg_update`), true is `p = z + beta p` with z at `r` (`sp_cg_direction`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct CgVector<S, const DIRECTION: bool> {
    pub ctl: u64,
    pub scal: u64,
    pub x: u64,
    pub r: u64,
    pub p: u64,
    pub ap: u64,
    pub n: i64,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<CgVector<f32, false>>() == 56);

// SAFETY: `#[repr(C)]`, the layout of `sp_cg_vector_t`; n scalars at x, r, p, ap (distinct
// arrays; `x` unused by the direction step), the solver's ctl and scal.
unsafe impl<S: SparseScalar, const DIRECTION: bool> ObjectStep for CgVector<S, DIRECTION> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = if DIRECTION {
        <S as SealedScalar>::KERNELS.cg_direction
    } else {
        <S as SealedScalar>::KERNELS.cg_update
    };

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        use cg::*;
        let n = self.len();
        // SAFETY: see the impl (read only).
        let (ctl, sc) = unsafe {
            (
                slice::<i32>(self.ctl, CTL_LEN),
                slice::<S>(self.scal, SCAL_LEN),
            )
        };
        if ctl[CTL_STOP] != STOP_NONE {
            return Ok(());
        }
        if DIRECTION {
            let beta = sc[BETA];
            // SAFETY: distinct arrays of n scalars; p is written by index, z read.
            let z = unsafe { slice::<S>(self.r, n) };
            let p = Ptr(self.p as *mut S);
            (0..n)
                .into_par_iter()
                .with_min_len(4096)
                .for_each(|i| unsafe {
                    let q = p.at(i);
                    q.write(z[i].add(beta.mul(*q)));
                });
            return Ok(());
        }
        let pap = sc[PAP];
        if !(pap > S::ZERO && pap.finite()) {
            return Ok(());
        }
        let alpha = sc[RZ].div(pap);
        // SAFETY: as above; x and r written by index, p and ap read.
        let (p, ap) = unsafe { (slice::<S>(self.p, n), slice::<S>(self.ap, n)) };
        let (x, r) = (Ptr(self.x as *mut S), Ptr(self.r as *mut S));
        (0..n)
            .into_par_iter()
            .with_min_len(4096)
            .for_each(|i| unsafe {
                let (xi, ri) = (x.at(i), r.at(i));
                xi.write((*xi).add(alpha.mul(p[i])));
                ri.write((*ri).sub(alpha.mul(ap[i])));
            });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `wp_sparse.h`, which the C++ side of every record and constant here comes from.
    const HEADER: &str = include_str!("../../../warp-cuda/cuda/wp_sparse.h");

    /// Every `constexpr i32|i64 SP_NAME = value` of the header (several per declaration).
    fn header_constants() -> Vec<(String, i64)> {
        crate::sparse::record_check::header_constants(HEADER, "SP_")
    }

    /// The header's `SP_*` constants are Rust's, one for one: the Rust side addresses the
    /// scalars and control words the kernels write, and decodes their stop codes, by its own
    /// constants, so a swap on one side alone would otherwise pass every CPU test.
    #[test]
    fn header_constants_are_rusts() {
        use cg::*;
        let rust: Vec<(&str, i64)> = vec![
            ("SP_DOT_LANES", DOT_LANES as i64),
            ("SP_DOT_CHUNK", DOT_CHUNK as i64),
            ("SP_CTL_STOP", CTL_STOP as i64),
            ("SP_CTL_ITER", CTL_ITER as i64),
            ("SP_CTL_BAD", CTL_BAD as i64),
            ("SP_CTL_RUN", CTL_RUN as i64),
            ("SP_STOP_NONE", STOP_NONE as i64),
            ("SP_STOP_CONVERGED", STOP_CONVERGED as i64),
            ("SP_STOP_MAX_ITER", STOP_MAX_ITER as i64),
            ("SP_STOP_NON_FINITE", STOP_NON_FINITE as i64),
            ("SP_STOP_BREAKDOWN", STOP_BREAKDOWN as i64),
            ("SP_STOP_SINGULAR", STOP_SINGULAR as i64),
            ("SP_STOP_BREAKDOWN_RZ", STOP_BREAKDOWN_RZ as i64),
            ("SP_RZ", RZ as i64),
            ("SP_RZ_NEW", RZ_NEW as i64),
            ("SP_PAP", PAP as i64),
            ("SP_RR", RR as i64),
            ("SP_BB", BB as i64),
            ("SP_TOL2", TOL2 as i64),
            ("SP_BETA", BETA as i64),
            ("SP_BREAK", BREAK as i64),
            ("SP_TOL", TOL as i64),
        ];
        let mut header = header_constants();
        header.sort();
        let mut rust: Vec<(String, i64)> = rust.into_iter().map(|(n, v)| (n.into(), v)).collect();
        rust.sort();
        assert_eq!(header, rust);
        // The indices fit the arrays Rust allocates.
        assert!([RZ, RZ_NEW, PAP, RR, BB, TOL2, BETA, BREAK, TOL]
            .iter()
            .all(|&k| k < SCAL_LEN));
        assert!([CTL_STOP, CTL_ITER, CTL_BAD, CTL_RUN]
            .iter()
            .all(|&k| k < CTL_LEN));
    }

    /// Every kernel name the Rust side launches (each block type's and each scalar's
    /// `KERNELS`) is a kernel of the compiled build library: a wrong tag in `block!` or a
    /// type missing from the header's instantiation list fails here, not at a user's first
    /// call on a GPU. Needs only libnvrtc (skipped, saying so, without it).
    #[cfg(feature = "cuda")]
    #[test]
    fn every_kernel_name_is_in_the_compiled_library() {
        use crate::sparse::block::sealed::{BlockKernels, ScalarKernels};
        use glam::{DMat2, DMat3, DMat4, Mat2, Mat3, Mat4};
        if let Err(e) = warp_cuda::nvrtc_version() {
            eprintln!("SKIPPED every_kernel_name_is_in_the_compiled_library: {e}");
            return;
        }
        let c = crate::cuda::objects::compile_library(&LIBRARY, 90).unwrap();
        let has = |name: &str| {
            let pat = format!("{name}\0");
            c.cubin.windows(pat.len()).any(|w| w == pat.as_bytes())
        };
        let blocks: [BlockKernels; 8] = [
            <f32 as SealedBlock>::KERNELS,
            <f64 as SealedBlock>::KERNELS,
            <Mat2 as SealedBlock>::KERNELS,
            <Mat3 as SealedBlock>::KERNELS,
            <Mat4 as SealedBlock>::KERNELS,
            <DMat2 as SealedBlock>::KERNELS,
            <DMat3 as SealedBlock>::KERNELS,
            <DMat4 as SealedBlock>::KERNELS,
        ];
        let scalars: [ScalarKernels; 2] = [
            <f32 as SealedScalar>::KERNELS,
            <f64 as SealedScalar>::KERNELS,
        ];
        let mut names: Vec<&str> = blocks.iter().flat_map(|k| [k.mv, k.jacobi_inv]).collect();
        for k in scalars {
            names.extend([
                k.tpl_keys,
                k.tpl_report,
                k.tpl_sum,
                k.dot_partials,
                k.dot_final,
                k.jacobi_apply,
                k.cg_init,
                k.cg_check,
                k.cg_update,
                k.cg_direction,
            ]);
        }
        // The scalar-free steps.
        names.extend([TplRowKeys::KERNEL, TplHeads::KERNEL, BsrOffsets::KERNEL]);
        assert_eq!(names.len(), 8 * 2 + 2 * 10 + 3);
        for n in &names {
            assert!(has(n), "{n} is not a kernel of the compiled library");
        }
        // The search can fail: a name of no kernel is absent.
        assert!(!has("wp_sparse_bsr_mv_mat5"));
    }

    /// Each record's fields sit at the same offsets in Rust and in C++ (g++'s `offsetof`): the
    /// sizes are asserted on both sides, but two swapped fields of one size (`rows` and
    /// `cols`) keep the size. Skipped, saying so, without g++.
    #[test]
    fn record_offsets_are_the_headers() {
        let fields = record_layouts![
            TplKeys<f32> => "sp_tpl_keys_t" {
                count, rows, cols, values, n, nrow, ncol, block, two_pass, no_finite_check, keys, idx,
                bad
            },
            TplReport<f32> => "sp_tpl_report_t" {
                count, bad, rows, cols, values, n, nrow, ncol, block, fault
            },
            TplRowKeys => "sp_tpl_row_keys_t" { count, rows, cols, idx, keys, n, nrow, ncol, pad },
            TplHeads => "sp_tpl_heads_t" { count, rows, cols, idx, heads, n, nrow, ncol, pad },
            TplSum<f32> => "sp_tpl_sum_t" {
                count, rows, cols, values, idx, pos, block_rows, columns, out, n, nrow, ncol,
                block
            },
            BsrOffsets => "sp_bsr_offsets_t" { count, block_rows, pos, offsets, n, nrow },
            BsrMv<f32> => "sp_bsr_mv_t" {
                offsets, columns, values, x, y, alpha, beta, nrow, ncol, cap, lanes
            },
            Dot<f32, false> => "sp_dot_t" { a, b, n, out, chunks },
            JacobiInv<f32> => "sp_jacobi_inv_t" {
                offsets, columns, values, dinv, bad, nrow, point, cap, pad
            },
            JacobiApply<f32> => "sp_jacobi_apply_t" { dinv, r, z, nrow, dim },
            CgScalar<f32, false> => "sp_cg_scalar_t" {
                ctl, scal, history, rtol, atol, max_iter, pad
            },
            CgVector<f32, false> => "sp_cg_vector_t" { ctl, scal, x, r, p, ap, n },
        ];
        crate::sparse::record_check::check_record_offsets(
            "sparse::steps::record_offsets_are_the_headers",
            "wp_sparse.h",
            &fields,
        );
    }
}

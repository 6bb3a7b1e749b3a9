//! Block sparse row matrices, kernel side: [`BsrView`] (what a `Bsr<B>` kernel parameter is
//! on the CPU, and field for field what `wp::bsr_t<B>` is on CUDA), the row iteration and the
//! `bsr_*` builtins with the adjoint of [`bsr_block`]. The CUDA library's `wp_bsr.h` takes the
//! same steps in the same order.
//!
//! # The matrix
//!
//! `nrow x ncol` blocks of `B` ([`BsrBlock`]: `f32`, `f64`, glam's `Mat2`..`Mat4`,
//! `DMat2`..`DMat4`, warp-core's `Mat23`..`DMat64`). Block row `r` holds the slots
//! `offsets[r] .. offsets[r + 1]`; slot `k` lies in block column `columns[k]` and holds
//! `values[k]`. The block count is `offsets[nrow]`, read on the device ([`bsr_nnz`]).
//!
//! # Checks
//!
//! A row outside `0..nrow` or a slot outside `0..nnz` is an out-of-bounds fault of the
//! matrix's parameter (index `[r]` against shape `[nrow]`, or `[k]` against `[nnz]`), never a
//! read outside the buffers. `nnz` and each row's range are clamped into the buffers
//! (`0 <= start <= end <= nnz <= capacity`), so a structure a user overwrote through the
//! matrix's array handles gives meaningless slots, never a wild read. A column outside
//! `0..ncol` is no block: [`bsr_block_index`] gives -1 for it.
//!
//! # Values and concurrency
//!
//! Blocks are read, written and added scalar by scalar through relaxed atomics of the
//! scalar's width, in memory order, so concurrent [`bsr_set_block`]s, [`bsr_add_block`]s and
//! reads are not data races (a relaxed load compiles to a plain load). Kernels change values,
//! never the structure (`offsets`, `columns` are only read). [`bsr_add_block`] of the same
//! slot from several threads sums in an order the scheduler picks, as every float atomic.
//!
//! # Gradient
//!
//! A matrix whose values array has a gradient carries it in its view: the adjoint of
//! [`bsr_block`] adds the incoming gradient into `values.grad[k]` (atomically, scalar by
//! scalar). [`bsr_set_block`] and [`bsr_add_block`] are writes without an adjoint: backward
//! through a kernel that makes one is refused by the kernel macro.

use std::sync::atomic::{AtomicU32, AtomicU64, Ordering::Relaxed};

use glam::{DMat2, DMat3, DMat4, Mat2, Mat3, Mat4};

use crate::adjoint::Adjoint;
use crate::builtins::atomic::AtomicElement;
use crate::matrix::{
    DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63, DMat64,
    Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64,
};
use crate::{ArrayView, KResult};

mod sealed {
    pub trait Sealed {}
}

/// The scalar of a block (`f32` or `f64`): loaded and stored as relaxed atomics of its bits,
/// added by the float atomic add. Sealed.
pub trait BsrScalar: AtomicElement + Send + Sync + 'static + sealed::Sealed {
    /// A relaxed atomic load.
    ///
    /// # Safety
    /// `p` addresses a live, aligned scalar, accessed by other threads only atomically.
    unsafe fn load(p: *const Self) -> Self;
    /// A relaxed atomic store.
    ///
    /// # Safety
    /// As [`BsrScalar::load`], and the scalar is writable.
    unsafe fn store(p: *mut Self, v: Self);
}

macro_rules! bsr_scalar {
    ($t:ty, $atomic:ty, $bits:ty) => {
        impl sealed::Sealed for $t {}
        impl BsrScalar for $t {
            #[inline(always)]
            unsafe fn load(p: *const Self) -> Self {
                // SAFETY: the trait's contract (a live, aligned scalar, shared atomically).
                <$t>::from_bits(unsafe { <$atomic>::from_ptr(p as *mut $bits) }.load(Relaxed))
            }
            #[inline(always)]
            unsafe fn store(p: *mut Self, v: Self) {
                // SAFETY: as `load`.
                unsafe { <$atomic>::from_ptr(p.cast::<$bits>()) }.store(v.to_bits(), Relaxed)
            }
        }
    };
}
bsr_scalar!(f32, AtomicU32, u32);
bsr_scalar!(f64, AtomicU64, u64);

/// A block type of a [`BsrView`]: `LEN` scalars of [`BsrBlock::Scalar`] with nothing else in
/// between (asserted per type). Sealed: the block types of the runtime's `sparse::Block`.
pub trait BsrBlock: Copy + Send + Sync + 'static + Adjoint + sealed::Sealed {
    /// `f32` or `f64`.
    type Scalar: BsrScalar;
    /// Scalars in one block (`ROWS * COLS`).
    const LEN: usize;
}

macro_rules! bsr_block {
    ($($t:ty: $s:ty, $n:expr;)*) => {$(
        const _: () = assert!(
            std::mem::size_of::<$t>() == $n * std::mem::size_of::<$s>()
                && std::mem::align_of::<$t>() >= std::mem::align_of::<$s>()
        );
        impl BsrBlock for $t {
            type Scalar = $s;
            const LEN: usize = $n;
        }
    )*};
}
impl sealed::Sealed for Mat2 {}
impl sealed::Sealed for Mat3 {}
impl sealed::Sealed for Mat4 {}
impl sealed::Sealed for DMat2 {}
impl sealed::Sealed for DMat3 {}
impl sealed::Sealed for DMat4 {}
macro_rules! sealed_rect {
    ($($t:ty),*) => {$( impl sealed::Sealed for $t {} )*};
}
sealed_rect!(
    Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64, DMat23,
    DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63, DMat64
);
bsr_block! {
    f32: f32, 1; f64: f64, 1;
    Mat2: f32, 4; Mat3: f32, 9; Mat4: f32, 16;
    DMat2: f64, 4; DMat3: f64, 9; DMat4: f64, 16;
    Mat23: f32, 6; Mat24: f32, 8; Mat26: f32, 12; Mat32: f32, 6; Mat34: f32, 12;
    Mat36: f32, 18; Mat42: f32, 8; Mat43: f32, 12; Mat46: f32, 24; Mat62: f32, 12;
    Mat63: f32, 18; Mat64: f32, 24;
    DMat23: f64, 6; DMat24: f64, 8; DMat26: f64, 12; DMat32: f64, 6; DMat34: f64, 12;
    DMat36: f64, 18; DMat42: f64, 8; DMat43: f64, 12; DMat46: f64, 24; DMat62: f64, 12;
    DMat63: f64, 18; DMat64: f64, 24;
}

/// The block at `p`, scalar by scalar (relaxed atomic loads, memory order).
///
/// # Safety
/// `p` addresses a live, aligned block, shared between threads only through these helpers.
#[inline(always)]
unsafe fn load_block<B: BsrBlock>(p: *const B) -> B {
    let mut out = std::mem::MaybeUninit::<B>::uninit();
    let (src, dst) = (p.cast::<B::Scalar>(), out.as_mut_ptr().cast::<B::Scalar>());
    for i in 0..B::LEN {
        // SAFETY: a block is `LEN` scalars (asserted per type); the caller's contract.
        unsafe { dst.add(i).write(B::Scalar::load(src.add(i))) };
    }
    // SAFETY: every scalar written, and every bit pattern is a float.
    unsafe { out.assume_init() }
}

/// `*p = v`, scalar by scalar (relaxed atomic stores, memory order).
///
/// # Safety
/// As [`load_block`], and the block is writable.
#[inline(always)]
unsafe fn store_block<B: BsrBlock>(p: *mut B, v: B) {
    let (dst, src) = (p.cast::<B::Scalar>(), (&v as *const B).cast::<B::Scalar>());
    for i in 0..B::LEN {
        // SAFETY: as `load_block`; `src` reads `v`'s own scalars.
        unsafe { B::Scalar::store(dst.add(i), src.add(i).read()) };
    }
}

/// `*p += v`, scalar by scalar (a float atomic add each, memory order).
///
/// # Safety
/// As [`store_block`].
#[inline(always)]
unsafe fn add_block<B: BsrBlock>(p: *mut B, v: B) {
    let (dst, src) = (p.cast::<B::Scalar>(), (&v as *const B).cast::<B::Scalar>());
    for i in 0..B::LEN {
        // SAFETY: as `store_block`.
        unsafe { B::Scalar::atomic_add(dst.add(i), src.add(i).read()) };
    }
}

/// A block sparse row matrix as a kernel thread sees it: the row starts (a checked view, whose
/// names its faults carry), the columns, values and (when the values have one) their
/// gradient, the capacity of those three, and the block counts. `Copy`; owns nothing (the
/// runtime keeps the buffers alive for the launch); 96 bytes, so that the row iteration's
/// steps, which take it by value, copy it in registers.
#[derive(Clone, Copy)]
pub struct BsrView<B> {
    offsets: ArrayView<i32, 1>,
    columns: *const i32,
    values: *mut B,
    /// Null when the values have no gradient.
    grad: *mut B,
    /// Elements of `columns`, `values` (and `grad`).
    cap: i32,
    nrow: i32,
    ncol: i32,
}

#[cfg(target_pointer_width = "64")]
const _: () = assert!(std::mem::size_of::<BsrView<f32>>() == 96);

// SAFETY: pointers into buffers the runtime keeps alive for the whole launch; every write is
// a relaxed atomic per scalar.
unsafe impl<B: Send> Send for BsrView<B> {}
unsafe impl<B: Sync> Sync for BsrView<B> {}

impl<B> std::fmt::Debug for BsrView<B> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BsrView")
            .field("nrow", &self.nrow)
            .field("ncol", &self.ncol)
            .field("capacity", &self.cap)
            .field("grad", &!self.grad.is_null())
            .finish()
    }
}

impl<B: BsrBlock> BsrView<B> {
    /// A view of a matrix's buffers: `offsets` (`nrow + 1` row starts, contiguous),
    /// `columns` and `values` (one element per slot of the capacity, contiguous), the
    /// values' gradient if any (as long as `values`, contiguous). Inconsistent contents make
    /// faults or meaningless slots, never undefined behaviour.
    ///
    /// # Panics
    /// When the lengths disagree, `nrow` or `ncol` is negative, the capacity exceeds
    /// `i32::MAX` or an array is not contiguous (the runtime makes matrices that satisfy all
    /// of these; this is a host-side constructor, never called by a kernel thread).
    pub fn new(
        offsets: ArrayView<i32, 1>,
        columns: ArrayView<i32, 1>,
        values: ArrayView<B, 1>,
        grad: Option<ArrayView<B, 1>>,
        nrow: i32,
        ncol: i32,
    ) -> Self {
        let dense = |len: usize, strides: [isize; 1]| len <= 1 || strides == [1];
        assert!(
            nrow >= 0 && ncol >= 0 && offsets.len() == nrow as usize + 1,
            "bsr: {} offsets for {nrow} x {ncol} blocks",
            offsets.len()
        );
        assert!(
            columns.len() == values.len() && values.len() <= i32::MAX as usize,
            "bsr: {} columns for {} values",
            columns.len(),
            values.len()
        );
        assert!(
            dense(offsets.len(), offsets.strides())
                && dense(columns.len(), columns.strides())
                && dense(values.len(), values.strides()),
            "bsr: the arrays must be contiguous"
        );
        if let Some(g) = &grad {
            assert!(
                g.len() == values.len() && dense(g.len(), g.strides()),
                "bsr: a gradient of {} blocks for {} values",
                g.len(),
                values.len()
            );
        }
        BsrView {
            offsets,
            columns: columns.as_ptr(),
            values: values.as_ptr(),
            grad: grad.map_or(std::ptr::null_mut(), |g| g.as_ptr()),
            cap: values.len() as i32,
            nrow,
            ncol,
        }
    }

    /// A matrix of no rows, no columns and no blocks: what an adjoint's placeholder for a
    /// matrix value holds (`Adjoint::adj_zero`); every row and slot faults.
    pub fn empty() -> Self {
        static ZERO: i32 = 0;
        // SAFETY: one element, `ZERO`, only ever read (offsets are never written).
        let offsets =
            unsafe { ArrayView::new((&ZERO as *const i32).cast_mut(), [1], [1], "bsr", "a") };
        BsrView {
            offsets,
            columns: std::ptr::NonNull::dangling().as_ptr(),
            values: std::ptr::NonNull::dangling().as_ptr(),
            grad: std::ptr::null_mut(),
            cap: 0,
            nrow: 0,
            ncol: 0,
        }
    }

    /// `offsets[i]` for `i <= nrow`.
    #[inline(always)]
    fn offset(&self, i: i32) -> i32 {
        debug_assert!(i >= 0 && i <= self.nrow);
        // SAFETY: `new` checked that offsets hold `nrow + 1` elements.
        unsafe { self.offsets.load_unchecked(i as usize) }
    }

    /// The block count `offsets[nrow]`, clamped into `0..=capacity`.
    #[inline(always)]
    pub fn nnz(&self) -> i32 {
        self.offset(self.nrow).clamp(0, self.cap)
    }

    /// Block rows.
    #[inline(always)]
    pub fn nrow(&self) -> i32 {
        self.nrow
    }

    /// Block columns.
    #[inline(always)]
    pub fn ncol(&self) -> i32 {
        self.ncol
    }

    /// Whether the values carry a gradient (what [`adj_bsr_block`] adds into).
    pub fn has_grad(&self) -> bool {
        !self.grad.is_null()
    }

    /// `r` as a row, or the out-of-bounds fault (index `[r]`, shape `[nrow]`).
    #[inline(always)]
    fn row(&self, r: i32) -> KResult<i32> {
        Ok(self.offsets.view_check(r, self.nrow as usize, false)? as i32)
    }

    /// `k` as a slot, or the out-of-bounds fault (index `[k]`, shape `[nnz]`).
    #[inline(always)]
    fn slot(&self, k: i32) -> KResult<usize> {
        self.offsets.view_check(k, self.nnz() as usize, false)
    }

    /// Row `r`'s slots `start..end`, clamped: `0 <= start <= end <= nnz`.
    #[inline(always)]
    fn range(&self, r: i32) -> (i32, i32) {
        let nnz = self.nnz();
        let start = self.offset(r).clamp(0, nnz);
        let end = self.offset(r + 1).clamp(start, nnz);
        (start, end)
    }
}

/// The state of a row's iteration (`for k in bsr_row(a, r)`): the current slot (one before the
/// row's first until the first step) and the row's end. Made by [`bsr_row`], advanced by
/// [`bsr_row_next`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C)]
pub struct BsrRowQuery {
    cur: i32,
    end: i32,
}

/// Warp-lang's `bsr_nrow`: the block rows.
#[inline(always)]
pub fn bsr_nrow<B: BsrBlock>(a: BsrView<B>) -> KResult<i32> {
    Ok(a.nrow)
}

/// Warp-lang's `bsr_ncol`: the block columns.
#[inline(always)]
pub fn bsr_ncol<B: BsrBlock>(a: BsrView<B>) -> KResult<i32> {
    Ok(a.ncol)
}

/// Warp-lang's `bsr_nnz`: the stored blocks, `offsets[nrow]` (clamped into the capacity).
#[inline(always)]
pub fn bsr_nnz<B: BsrBlock>(a: BsrView<B>) -> KResult<i32> {
    Ok(a.nnz())
}

/// Starts the iteration over row `r`'s slots (`for k in bsr_row(a, r)`); a row outside
/// `0..nrow` faults.
#[inline(always)]
pub fn bsr_row<B: BsrBlock>(a: BsrView<B>, r: i32) -> KResult<BsrRowQuery> {
    let r = a.row(r)?;
    let (start, end) = a.range(r);
    Ok(BsrRowQuery {
        cur: start - 1,
        end,
    })
}

/// The iteration at its next slot, or at its end (then [`bsr_row_done`]); done stays done.
#[inline(always)]
pub fn bsr_row_next<B: BsrBlock>(_a: BsrView<B>, q: BsrRowQuery) -> KResult<BsrRowQuery> {
    Ok(BsrRowQuery {
        cur: q.cur.saturating_add(1).min(q.end),
        end: q.end,
    })
}

/// Whether the row has no more slots.
#[inline(always)]
pub fn bsr_row_done(q: BsrRowQuery) -> bool {
    q.cur >= q.end
}

/// The current slot (valid until [`bsr_row_done`]).
#[inline(always)]
pub fn bsr_row_item(q: BsrRowQuery) -> i32 {
    q.cur
}

/// Warp-lang's `bsr_col`: slot `k`'s block column.
#[inline(always)]
pub fn bsr_col<B: BsrBlock>(a: BsrView<B>, k: i32) -> KResult<i32> {
    let k = a.slot(k)?;
    // SAFETY: `k < nnz <= capacity`, the length `new` checked `columns` has.
    Ok(unsafe { a.columns.add(k).read() })
}

/// Warp-lang's `bsr_block`: slot `k`'s block. Differentiable into the values' gradient
/// ([`adj_bsr_block`]).
#[inline(always)]
pub fn bsr_block<B: BsrBlock>(a: BsrView<B>, k: i32) -> KResult<B> {
    let k = a.slot(k)?;
    // SAFETY: `k < capacity`; blocks are shared only through these helpers.
    Ok(unsafe { load_block(a.values.add(k)) })
}

/// Warp-lang's `bsr_set_block`: writes slot `k`'s block (scalar by scalar, relaxed).
#[inline(always)]
pub fn bsr_set_block<B: BsrBlock>(a: BsrView<B>, k: i32, v: B) -> KResult<()> {
    let k = a.slot(k)?;
    // SAFETY: as `bsr_block`.
    unsafe { store_block(a.values.add(k), v) };
    Ok(())
}

/// Warp-lang's `bsr_add_block`: adds `v` into slot `k`'s block, atomically per scalar
/// (assembly into a fixed pattern).
#[inline(always)]
pub fn bsr_add_block<B: BsrBlock>(a: BsrView<B>, k: i32, v: B) -> KResult<()> {
    let k = a.slot(k)?;
    // SAFETY: as `bsr_block`.
    unsafe { add_block(a.values.add(k), v) };
    Ok(())
}

/// Warp-lang's `bsr_block_index`: the slot of block `(r, c)`, or -1 when the row stores no
/// block in column `c` (a column outside `0..ncol` included); a row outside `0..nrow`
/// faults. A binary search of the row's columns, which ascend.
#[inline(always)]
pub fn bsr_block_index<B: BsrBlock>(a: BsrView<B>, r: i32, c: i32) -> KResult<i32> {
    let r = a.row(r)?;
    if c < 0 || c >= a.ncol {
        return Ok(-1);
    }
    let (mut lo, mut hi) = a.range(r);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        // SAFETY: `mid < end <= nnz <= capacity`.
        if unsafe { a.columns.add(mid as usize).read() } < c {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    let (_, end) = a.range(r);
    // SAFETY: as above.
    Ok(
        if lo < end && unsafe { a.columns.add(lo as usize).read() } == c {
            lo
        } else {
            -1
        },
    )
}

/// Warp-lang's `bsr_row_index`: the row that holds slot `k` (the first row whose end is past
/// `k`, by binary search of the offsets), or -1 when none does (a structure overwritten
/// through the offsets' handle); a slot outside `0..nnz` faults.
#[inline(always)]
pub fn bsr_row_index<B: BsrBlock>(a: BsrView<B>, k: i32) -> KResult<i32> {
    let k = a.slot(k)? as i32;
    let (mut lo, mut hi) = (0, a.nrow);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if a.offset(mid + 1) <= k {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    Ok(if lo < a.nrow { lo } else { -1 })
}

/// Adjoint of [`bsr_block`]: adds `adj_ret` into the values' gradient at slot `k` (atomically
/// per scalar), when the values have a gradient.
#[inline(always)]
pub fn adj_bsr_block<B: BsrBlock>(
    a: BsrView<B>,
    k: i32,
    _adj_a: &mut BsrView<B>,
    _adj_k: &mut i32,
    adj_ret: B,
) -> KResult<()> {
    let k = a.slot(k)?;
    if !a.grad.is_null() {
        // SAFETY: `k < capacity`, the gradient's length (`new`).
        unsafe { add_block(a.grad.add(k), adj_ret) };
    }
    Ok(())
}

// Matrix values carry no gradient of their own (a gradient the values have travels inside the
// view); row iteration states carry none either (what depends on them are slot indices).
no_gradient!(
    where [B: BsrBlock] BsrView<B> = BsrView::empty(),
    BsrRowQuery = BsrRowQuery::default(),
);

#[cfg(test)]
mod tests {
    use super::*;

    /// `[[1, 0, 2], [0, 0, 0], [0, 3, 4]]` as 1x1 blocks, room for 6.
    struct M {
        offsets: Vec<i32>,
        columns: Vec<i32>,
        values: Vec<f64>,
        grad: Vec<f64>,
    }

    impl M {
        fn new() -> M {
            M {
                offsets: vec![0, 2, 2, 4],
                columns: vec![0, 2, 1, 2, 0, 0],
                values: vec![1.0, 2.0, 3.0, 4.0, 0.0, 0.0],
                grad: vec![0.0; 6],
            }
        }

        fn view(&mut self) -> BsrView<f64> {
            // SAFETY: the vectors outlive every use of the view in these tests.
            unsafe {
                let i = |d: &mut Vec<i32>| ArrayView::new(d.as_mut_ptr(), [d.len()], [1], "k", "a");
                let f = |d: &mut Vec<f64>| ArrayView::new(d.as_mut_ptr(), [d.len()], [1], "k", "a");
                BsrView::new(
                    i(&mut self.offsets),
                    i(&mut self.columns),
                    f(&mut self.values),
                    Some(f(&mut self.grad)),
                    3,
                    3,
                )
            }
        }
    }

    fn row(a: BsrView<f64>, r: i32) -> Vec<i32> {
        let mut q = bsr_row(a, r).unwrap();
        let mut out = vec![];
        loop {
            q = bsr_row_next(a, q).unwrap();
            if bsr_row_done(q) {
                break;
            }
            out.push(bsr_row_item(q));
        }
        assert!(bsr_row_done(bsr_row_next(a, q).unwrap()), "done stays done");
        out
    }

    #[test]
    fn rows_slots_and_indices() {
        let mut m = M::new();
        let a = m.view();
        assert_eq!(
            (
                bsr_nrow(a).unwrap(),
                bsr_ncol(a).unwrap(),
                bsr_nnz(a).unwrap()
            ),
            (3, 3, 4)
        );
        assert_eq!(row(a, 0), [0, 1]);
        assert!(row(a, 1).is_empty());
        assert_eq!(row(a, 2), [2, 3]);
        assert_eq!(bsr_col(a, 3).unwrap(), 2);
        assert_eq!(bsr_block(a, 2).unwrap(), 3.0);
        for (r, c, k) in [
            (0, 0, 0),
            (0, 2, 1),
            (0, 1, -1),
            (1, 1, -1),
            (2, 1, 2),
            (2, 2, 3),
        ] {
            assert_eq!(bsr_block_index(a, r, c).unwrap(), k, "({r}, {c})");
        }
        assert_eq!(bsr_block_index(a, 0, 3).unwrap(), -1);
        assert_eq!(bsr_block_index(a, 0, -1).unwrap(), -1);
        let rows: Vec<i32> = (0..4).map(|k| bsr_row_index(a, k).unwrap()).collect();
        assert_eq!(rows, [0, 0, 2, 2]);
        bsr_set_block(a, 1, 5.0).unwrap();
        bsr_add_block(a, 1, 0.5).unwrap();
        assert_eq!(m.values[1], 5.5);
    }

    #[test]
    fn out_of_range_rows_and_slots_fault() {
        let mut m = M::new();
        let a = m.view();
        for e in [
            bsr_row(a, 3).unwrap_err(),
            bsr_row(a, -1).unwrap_err(),
            bsr_block_index(a, 3, 0).unwrap_err(),
        ] {
            let s = e.to_string();
            assert!(s.contains("argument `a` of shape [3]"), "{s}");
        }
        // Slots 4 and 5 are capacity, not blocks: out of range as much as -1.
        for k in [4, 5, -1, i32::MAX] {
            let s = bsr_block(a, k).unwrap_err().to_string();
            assert!(s.contains("argument `a` of shape [4]"), "{k}: {s}");
            assert!(bsr_col(a, k).is_err() && bsr_row_index(a, k).is_err());
            assert!(bsr_set_block(a, k, 1.0).is_err() && bsr_add_block(a, k, 1.0).is_err());
        }
        let z = BsrView::<Mat3>::empty();
        assert_eq!(bsr_nnz(z).unwrap(), 0);
        assert!(bsr_row(z, 0).is_err() && bsr_block(z, 0).is_err());
    }

    #[test]
    fn an_overwritten_structure_stays_in_bounds() {
        let mut m = M::new();
        m.offsets = vec![-5, 100, 1, 1000];
        let a = m.view();
        // nnz clamps to the capacity 6; row 0 is 0..6, row 1 is 6..6 (its start clamped to
        // nnz, its end to its start), row 2 is 1..6.
        assert_eq!(bsr_nnz(a).unwrap(), 6);
        assert_eq!(row(a, 0), [0, 1, 2, 3, 4, 5]);
        assert!(row(a, 1).is_empty());
        assert_eq!(row(a, 2), [1, 2, 3, 4, 5]);
    }

    #[test]
    fn the_adjoint_adds_into_the_gradient() {
        let mut m = M::new();
        let a = m.view();
        let (mut adj_a, mut adj_k) = (BsrView::empty(), 0);
        adj_bsr_block(a, 3, &mut adj_a, &mut adj_k, 1.5).unwrap();
        adj_bsr_block(a, 3, &mut adj_a, &mut adj_k, 0.25).unwrap();
        assert_eq!(m.grad, [0.0, 0.0, 0.0, 1.75, 0.0, 0.0]);
        assert!(adj_bsr_block(a, 4, &mut adj_a, &mut adj_k, 1.0).is_err());
    }

    #[test]
    fn blocks_round_trip_scalar_by_scalar() {
        let mut vals = vec![Mat23::default(); 2];
        let mut offs = vec![0, 2];
        let mut cols = vec![0, 1];
        // SAFETY: the vectors outlive the view.
        let a = unsafe {
            BsrView::new(
                ArrayView::new(offs.as_mut_ptr(), [2], [1], "k", "a"),
                ArrayView::new(cols.as_mut_ptr(), [2], [1], "k", "a"),
                ArrayView::new(vals.as_mut_ptr(), [2], [1], "k", "a"),
                None,
                1,
                2,
            )
        };
        let b = Mat23(
            glam::Vec3::new(1.0, 2.0, 3.0),
            glam::Vec3::new(4.0, 5.0, 6.0),
        );
        bsr_set_block(a, 1, b).unwrap();
        bsr_add_block(a, 1, b).unwrap();
        assert_eq!(bsr_block(a, 1).unwrap(), Mat23(b.0 * 2.0, b.1 * 2.0));
        assert_eq!(vals[0], Mat23::default());
        // No gradient: the adjoint adds nothing and does not fault.
        let (mut adj_a, mut adj_k) = (BsrView::empty(), 0);
        adj_bsr_block(a, 0, &mut adj_a, &mut adj_k, b).unwrap();
    }
}

//! The sparse tier on a [`Tape`](crate::Tape) (slice 5): the adjoint steps and the records of
//! the assembly ([`Bsr::from_triplets`]) and of [`mv`](super::mv) /
//! [`mv_transpose`](super::mv_transpose). The solves' records are `solve/adjoint.rs`.
//!
//! The steps follow the tier's rule (`steps.rs`): a `#[repr(C)]` record laid out as its C++
//! struct in `wp_sparse.h`'s adjoint section, a CPU body in the same order of operations, so
//! gradients are the same bits on the CPU and a GPU, and no float atomics: each thread owns
//! the elements it writes (a triplet, a vector element, a stored block).

use super::block::{Block, SparseScalar};
use super::steps::{by_scalar, clamped_nnz, count, slice, Ptr, LIBRARY};
use super::Bsr;
use crate::array::{Array, Element};
use crate::backend::{ObjectLibrary, ObjectStep};
use crate::dispatch;
use crate::error::Result;
use crate::tape;
use rayon::prelude::*;
use std::marker::PhantomData;

// ------------------------------------------------------------------------------------------
// Steps
// ------------------------------------------------------------------------------------------

/// The assembly's adjoint (`sp_adj_tpl_t`), a thread per sorted triplet `k`: when the
/// triplet was assembled (its sorted key below `sentinel`), `tgrad[idx[k]] += vgrad[pos[k] -
/// 1]`, scalar by scalar (`block` per triplet). `idx`, `pos`, `keys` are the assembly's
/// sorted permutation, inclusive scan of the run heads and sorted keys (`mod.rs`); each
/// triplet is one `k`, so no two threads write one element.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct AdjTpl<S> {
    pub count: u64,
    pub idx: u64,
    pub pos: u64,
    pub keys: u64,
    pub vgrad: u64,
    pub tgrad: u64,
    pub n: i32,
    pub block: i32,
    pub sentinel: u32,
    pub pad: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<AdjTpl<f32>>() == 64);

// SAFETY: `#[repr(C)]`, the layout of `sp_adj_tpl_t`; the assembly's n-element scratch (kept
// by the record), the matrix's values gradient and the triplets' of n blocks of `block`
// scalars each.
unsafe impl<S: SparseScalar> ObjectStep for AdjTpl<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = by_scalar::<S>("wp_sparse_adj_tpl_f32", "wp_sparse_adj_tpl_f64");

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = count(self.count, self.n);
        let b = self.block as usize;
        // SAFETY: see the impl; `tgrad` is written, the others read.
        let (idx, pos, keys, vgrad) = unsafe {
            (
                slice::<i32>(self.idx, n),
                slice::<i32>(self.pos, n),
                slice::<u32>(self.keys, n),
                slice::<S>(self.vgrad, n * b),
            )
        };
        let (tgrad, sentinel) = (Ptr(self.tgrad as *mut S), self.sentinel);
        (0..n).into_par_iter().with_min_len(4096).for_each(|k| {
            if keys[k] >= sentinel {
                return; // (out of range: sorted last, no block)
            }
            let (t, blk) = (idx[k] as usize, (pos[k] - 1) as usize);
            for e in 0..b {
                // SAFETY: triplet t is this task's alone (idx is a permutation).
                unsafe {
                    let p = tgrad.at(t * b + e);
                    p.write((*p).add(vgrad[blk * b + e]));
                }
            }
        });
        Ok(())
    }
}

/// `y = a y + b x` element by element (`sp_adj_axpby_t`; `x` 0: `y = a y`), each product and
/// the sum rounded once (`a = 1`, `b = 1`: `y += x`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct AdjAxpby<S> {
    pub y: u64,
    pub x: u64,
    pub a: f64,
    pub b: f64,
    pub n: i64,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<AdjAxpby<f32>>() == 40);

// SAFETY: `#[repr(C)]`, the layout of `sp_adj_axpby_t`; n scalars at y and (unless 0) at x,
// not overlapping.
unsafe impl<S: SparseScalar> ObjectStep for AdjAxpby<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str =
        by_scalar::<S>("wp_sparse_adj_axpby_f32", "wp_sparse_adj_axpby_f64");

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        // SAFETY: see the impl.
        let x = (self.x != 0).then(|| unsafe { slice::<S>(self.x, n) });
        let (a, b) = (S::from_f64(self.a), S::from_f64(self.b));
        let y = Ptr(self.y as *mut S);
        (0..n).into_par_iter().with_min_len(4096).for_each(|i| {
            // SAFETY: element i is this task's alone.
            unsafe {
                let p = y.at(i);
                let ay = a.mul(*p);
                p.write(match x {
                    Some(x) => ay.add(b.mul(x[i])),
                    None => ay,
                });
            }
        });
        Ok(())
    }
}

/// The gradient of a matrix's blocks from an outer product (`sp_adj_outer_t`), a thread per
/// stored block `k < nnz`: with `r` its block row (a binary search of the offsets) and `c`
/// its column, `grad_k(i, j) += alpha (u[r R + i] v[c C + j])`, each product and the sum
/// rounded once (`alpha = -1`: `grad_k -= u_r v_cᵀ`). A column outside `0..ncol` is skipped
/// (never in an assembled matrix), as [`mv`](super::mv) skips it.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct AdjOuter<S> {
    pub offsets: u64,
    pub columns: u64,
    pub grad: u64,
    pub u: u64,
    pub v: u64,
    pub alpha: f64,
    pub nrow: i32,
    pub ncol: i32,
    pub cap: i32,
    pub rows: i32,
    pub cols: i32,
    pub cm: i32,
    pub scalar: PhantomData<S>,
}
const _: () = assert!(std::mem::size_of::<AdjOuter<f32>>() == 72);

/// The block row of stored block `k` (`sp_adj_block_row`): the last `r < nrow` with
/// `offsets[r] <= k` by binary search over `1..nrow` (the offsets ascend in an assembled
/// matrix; overwritten ones give some row in range, never a read outside). `nrow >= 1`.
fn block_row(offsets: &[i32], nrow: usize, k: i32) -> usize {
    let (mut lo, mut hi) = (1usize, nrow);
    while lo < hi {
        let mid = lo + (hi - lo) / 2;
        if offsets[mid] <= k {
            lo = mid + 1;
        } else {
            hi = mid;
        }
    }
    lo - 1
}

// SAFETY: `#[repr(C)]`, the layout of `sp_adj_outer_t`; a matrix's offsets (nrow + 1),
// columns and values gradient (cap blocks of rows x cols scalars), u of nrow rows scalars,
// v of ncol cols scalars, the gradient overlapping neither.
unsafe impl<S: SparseScalar> ObjectStep for AdjOuter<S> {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str =
        by_scalar::<S>("wp_sparse_adj_outer_f32", "wp_sparse_adj_outer_f64");

    fn len(&self) -> usize {
        self.cap.max(0) as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let (nrow, ncol) = (self.nrow.max(0) as usize, self.ncol);
        if nrow == 0 {
            return Ok(());
        }
        let (rr, cc) = (self.rows as usize, self.cols as usize);
        // SAFETY: see the impl (read only but for `grad`).
        let offsets = unsafe { slice::<i32>(self.offsets, nrow + 1) };
        let nnz = clamped_nnz(offsets, self.cap);
        // SAFETY: as above.
        let (columns, u, v) = unsafe {
            (
                slice::<i32>(self.columns, nnz),
                slice::<S>(self.u, nrow * rr),
                slice::<S>(self.v, ncol.max(0) as usize * cc),
            )
        };
        let (grad, alpha, cm) = (Ptr(self.grad as *mut S), S::from_f64(self.alpha), self.cm);
        (0..nnz).into_par_iter().with_min_len(256).for_each(|k| {
            let r = block_row(offsets, nrow, k as i32);
            let c = columns[k];
            if !(0..ncol).contains(&c) {
                return;
            }
            let c = c as usize;
            for i in 0..rr {
                for j in 0..cc {
                    let e = if cm != 0 { j * rr + i } else { i * cc + j };
                    let prod = alpha.mul(u[r * rr + i].mul(v[c * cc + j]));
                    // SAFETY: block k is this task's alone.
                    unsafe {
                        let p = grad.at(k * rr * cc + e);
                        p.write((*p).add(prod));
                    }
                }
            }
        });
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// Queueing the steps
// ------------------------------------------------------------------------------------------

/// `y = a y + b x` (`x` `None`: `y = a y`) over two scalar arrays of one length on one
/// device.
pub(crate) fn axpby<S: SparseScalar>(
    y: &Array<S>,
    a: f64,
    x: Option<&Array<S>>,
    b: f64,
) -> Result<()> {
    if let Some(x) = x {
        debug_assert_eq!(x.len(), y.len());
    }
    dispatch::object_step(
        y.device(),
        &AdjAxpby::<S> {
            y: y.device_address(),
            x: x.map_or(0, |x| x.device_address()),
            a,
            b,
            n: y.len() as i64,
            scalar: PhantomData,
        },
    )
}

/// `grad_k += alpha u_r v_cᵀ` over `a`'s stored blocks, `grad` the gradient of its values,
/// `u` of the matrix's scalar rows, `v` of its scalar columns (contiguous, on its device).
pub(crate) fn outer<B: Block>(
    a: &Bsr<B>,
    grad: &Array<B>,
    alpha: f64,
    u: &Array<B::Scalar>,
    v: &Array<B::Scalar>,
) -> Result<()> {
    let (nr, nc) = a.shape();
    debug_assert!(u.len() == nr && v.len() == nc && grad.len() == a.nnz_bound());
    dispatch::object_step(
        a.device(),
        &AdjOuter::<B::Scalar> {
            offsets: a.offsets().device_address(),
            columns: a.columns().device_address(),
            grad: grad.device_address(),
            u: u.device_address(),
            v: v.device_address(),
            alpha,
            nrow: a.nrow() as i32,
            ncol: a.ncol() as i32,
            cap: a.nnz_bound() as i32,
            rows: B::ROWS as i32,
            cols: B::COLS as i32,
            cm: B::COL_MAJOR as i32,
            scalar: PhantomData,
        },
    )
}

/// The scalars of a vector of blocks' elements (`Vec3` -> `f32`), sharing its memory.
fn scalars<T: Element, S: SparseScalar>(v: &Array<T>) -> Result<Array<S>> {
    v.reinterpret::<S>()
}

// ------------------------------------------------------------------------------------------
// The assembly's record
// ------------------------------------------------------------------------------------------

/// What the assembly's adjoint needs of its scratch: the sorted keys and permutation, the
/// scan of the run heads, the device count (if any), the triplet capacity `n` and the keys'
/// sentinel (`nrow * ncol`, or `nrow` in the two-pass path).
pub(super) struct Sorted {
    pub keys: Array<u32>,
    pub idx: Array<i32>,
    pub pos: Array<i32>,
    pub count: Option<Array<i32>>,
    pub n: usize,
    pub sentinel: u32,
}

/// Records the assembly of `m` from the triplet values `values` (both with a gradient) on
/// the tapes recording on this thread. Backward: `values.grad[t] += m.values.grad[block of
/// t]` for each assembled triplet, then `m`'s values gradient is cleared (the assembly wrote
/// the values).
pub(super) fn record_assembly<B: Block>(m: &Bsr<B>, values: &Array<B>, s: Sorted) -> Result<()> {
    let (blocks, tv) = (m.values().clone(), values.clone());
    let (bz, tz) = (blocks.clone(), tv.clone());
    tape::on_op(
        "sparse::from_triplets",
        move || {
            let (Some(vg), Some(tg)) = (blocks.grad(), tv.grad()) else {
                return Ok(());
            };
            dispatch::object_step(
                blocks.device(),
                &AdjTpl::<B::Scalar> {
                    count: s.count.as_ref().map_or(0, |c| c.device_address()),
                    idx: s.idx.device_address(),
                    pos: s.pos.device_address(),
                    keys: s.keys.device_address(),
                    vgrad: vg.device_address(),
                    tgrad: tg.device_address(),
                    n: s.n as i32,
                    block: (B::ROWS * B::COLS) as i32,
                    sentinel: s.sentinel,
                    pad: 0,
                    scalar: PhantomData,
                },
            )?;
            blocks.zero_grad()
        },
        move || {
            bz.zero_grad()?;
            tz.zero_grad()
        },
    )
}

// ------------------------------------------------------------------------------------------
// mv's record
// ------------------------------------------------------------------------------------------

/// Records `y = alpha op(A) x + beta y` (`op(A)` = `A`, or `Aᵀ` when `transposed`) on the
/// tapes recording on this thread, when `y` has a gradient. Backward, with `ȳ = y.grad`:
/// `x̄ += alpha op(A)ᵀ ȳ` (when `x` has a gradient; a transpose of `A` for `mv`, `A` itself
/// for `mv_transpose`), `Ā_k += alpha ȳ_r x_cᵀ` (`alpha x_r ȳ_cᵀ` transposed; when `A`'s
/// values have one), then `ȳ = beta ȳ` (`y` was read scaled by `beta`, and written). `x`
/// and `A` are read at backward time, as a kernel's adjoint reads its arrays.
pub(super) fn record_mv<B: Block, X: Element, Y: Element>(
    alpha: f64,
    a: &Bsr<B>,
    x: &Array<X>,
    beta: f64,
    y: &Array<Y>,
    transposed: bool,
) -> Result<()> {
    if !y.requires_grad() || !tape::recording() {
        return Ok(());
    }
    let name = if transposed {
        "sparse::mv_transpose"
    } else {
        "sparse::mv"
    };
    let (a, x, y) = (a.clone(), x.clone(), y.clone());
    let (az, xz, yz) = (a.clone(), x.clone(), y.clone());
    tape::on_op(
        name,
        move || {
            let Some(yg) = y.grad() else { return Ok(()) };
            let _paused = tape::pause_recording();
            let ys = scalars::<Y, B::Scalar>(&yg)?;
            if let Some(ag) = a.values().grad() {
                let xs = scalars::<X, B::Scalar>(&x)?;
                // A's scalar rows are y's for mv, x's for mv_transpose.
                let (u, v) = if transposed { (&xs, &ys) } else { (&ys, &xs) };
                outer(&a, &ag, alpha, u, v)?;
            }
            if let Some(xg) = x.grad() {
                let xs = scalars::<X, B::Scalar>(&xg)?;
                // x̄ += alpha op(A)ᵀ ȳ: one product into x̄ with beta 1.
                if transposed {
                    super::mv_scalars(&a, &ys, &xs, alpha, 1.0)?;
                } else {
                    super::mv_scalars(&a.transpose()?, &ys, &xs, alpha, 1.0)?;
                }
            }
            if beta == 0.0 {
                ys.fill(B::Scalar::ZERO)
            } else {
                axpby(&ys, beta, None, 0.0)
            }
        },
        move || {
            az.values().zero_grad()?;
            xz.zero_grad()?;
            yz.zero_grad()
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The block row of each stored block, empty rows included (rows 0 and 2 here), and the
    /// last row's blocks.
    #[test]
    fn block_row_finds_each_blocks_row() {
        let offsets = [0, 0, 2, 2, 5];
        let rows: Vec<usize> = (0..5).map(|k| block_row(&offsets, 4, k)).collect();
        assert_eq!(rows, [1, 1, 3, 3, 3]);
        // One row: every block is row 0.
        assert_eq!(block_row(&[0, 3], 1, 2), 0);
        // Overwritten (descending) offsets still give a row in range.
        assert!(block_row(&[0, 9, 1, 0], 3, 4) < 3);
    }

    /// Each record's fields sit at the C++ struct's offsets (g++'s `offsetof`; skipped,
    /// saying so, without g++).
    #[test]
    fn record_offsets_are_the_headers() {
        let fields = record_layouts![
            AdjTpl<f32> => "sp_adj_tpl_t" {
                count, idx, pos, keys, vgrad, tgrad, n, block, sentinel, pad
            },
            AdjAxpby<f32> => "sp_adj_axpby_t" { y, x, a, b, n },
            AdjOuter<f32> => "sp_adj_outer_t" {
                offsets, columns, grad, u, v, alpha, nrow, ncol, cap, rows, cols, cm
            },
        ];
        crate::sparse::record_check::check_record_offsets(
            "sparse::adjoint::record_offsets_are_the_headers",
            "wp_sparse.h",
            &fields,
        );
    }

    /// The adjoint kernels the Rust side names are kernels of the compiled build library.
    /// Needs only libnvrtc (skipped, saying so, without it).
    #[cfg(feature = "cuda")]
    #[test]
    fn kernel_names_are_in_the_compiled_library() {
        if let Err(e) = warp_cuda::nvrtc_version() {
            eprintln!("SKIPPED kernel_names_are_in_the_compiled_library: {e}");
            return;
        }
        let c = crate::cuda::objects::compile_library(&LIBRARY, 90).unwrap();
        let has = |name: &str| {
            let pat = format!("{name}\0");
            c.cubin.windows(pat.len()).any(|w| w == pat.as_bytes())
        };
        for n in [
            AdjTpl::<f32>::KERNEL,
            AdjTpl::<f64>::KERNEL,
            AdjAxpby::<f32>::KERNEL,
            AdjAxpby::<f64>::KERNEL,
            AdjOuter::<f32>::KERNEL,
            AdjOuter::<f64>::KERNEL,
        ] {
            assert!(has(n), "{n} is not a kernel of the compiled library");
        }
    }
}

//! Block sparse matrices and the conjugate gradient solver (cargo feature `sparse`), in the
//! style of Warp's `warp.sparse` and `warp.optim.linear`.
//!
//! A [`Bsr<B>`] is a matrix of `nrow x ncol` blocks of type `B` ([`Block`]: `f32`, `f64`,
//! glam's `Mat2`..`Mat4`, `DMat2`..`DMat4`) in block sparse row form: `offsets` (`nrow + 1`
//! row starts), `columns` (one block column per stored block) and `values` (the blocks). It
//! is made from triplets ([`Bsr::from_triplets`], duplicates summed), multiplies vectors
//! ([`mv`]) and is solved with [`cg`] (conjugate gradients with Jacobi preconditioning,
//! driven from the host or captured into one graph: [`Mode`]).
//!
//! # Same bits on every device
//! Every operation here gives the same bits on the CPU and on a GPU: each step runs the same
//! arithmetic in the same order on both (the CUDA steps spell every float operation with a
//! rounded intrinsic, so FMA contraction never changes them), duplicates are summed in
//! ascending triplet order after a stable sort, and [`dot`] reduces in a fixed tree (not
//! [`array_sum`](crate::array_sum)'s blocked sums). So a CG solve takes the same iterations and
//! residual history on both.
//!
//! # Structure operations
//! [`Bsr::scale`], [`diag`], [`set_diag`], [`Bsr::from_diag`], [`Bsr::identity`], dense
//! matrices both ways ([`Bsr::to_dense`], [`Bsr::from_dense`]), [`Bsr::transpose`], [`axpy`]
//! (`y = alpha x + beta y` on the union of the structures), [`mm`] (`C = alpha A B + beta
//! C`, one triplet per product of blocks, then the assembly's sort and ordered sums) and
//! [`mv_transpose`]. These
//! also take warp-core's rectangular blocks (`Mat23` .. `DMat64`, row-major), as [`mv`] does;
//! [`BlockMul`] says which block types multiply. The same-bits rule holds for each.
//!
//! # Graph colouring
//! [`Adjacency`] (a graph's symmetric pattern, from edges or from constraints that share a
//! particle) and [`Coloring`] (Jones-Plassmann on the device with hashed priorities) split
//! constraints into sets that touch disjoint particles, so a Gauss-Seidel sweep (XPBD, a
//! smoother) runs a thread per constraint of a set. Each round reads the last round's colours
//! and writes new ones, so the colours depend on the graph and the seed alone: the same on
//! the CPU, at any thread count, and on a GPU.
//!
//! # Gradients
//! The tier works with a recording [`Tape`](crate::Tape): a solve ([`cg`], [`cr`],
//! [`bicgstab`], [`gmres`]) is one step whose backward solves the adjoint system `Aᵀ λ =
//! x̄` and adds `λ` into `b`'s gradient and `-λ_r x_cᵀ` into the gradient of each stored block
//! of `A` ([`Bsr::with_grad`]); [`Bsr::from_triplets`] of values with a gradient hands each
//! block's gradient back to its triplets; [`mv`] and [`mv_transpose`] are recorded too. So an
//! assembly, a solve and a loss differentiate end to end. Backward through a solve that did
//! not converge is an [`Error::NotDifferentiable`]: its gradient would be wrong.
//!
//! # Errors
//! Shapes, lengths and devices are checked on the host before anything is queued: a mismatch
//! is an [`Error::InvalidArgument`] naming the function, the argument and both shapes. Bad
//! values in the data (a triplet index out of range, a NaN) are found where the data is: a
//! fault of `sparse::from_triplets`, returned at once on the CPU and reported at the next
//! synchronisation on a GPU.
//!
//! ```
//! # use warp_runtime as wp;
//! use wp::sparse::{self, Bsr};
//! let dev = wp::cpu();
//! let rows = wp::Array::from_slice(&[0, 1, 1, 0], &dev)?;
//! let cols = wp::Array::from_slice(&[0, 1, 1, 1], &dev)?;
//! let vals = wp::Array::from_slice(&[2.0f32, 3.0, 1.0, -1.0], &dev)?;
//! let a = Bsr::from_triplets(2, 2, &rows, &cols, &vals)?; // [[2, -1], [0, 4]]
//! let x = wp::Array::from_slice(&[1.0f32, 1.0], &dev)?;
//! let y = wp::Array::<f32>::zeros(2, &dev)?;
//! sparse::mv(1.0, &a, &x, 0.0, &y)?;
//! assert_eq!(y.to_vec()?, [1.0, 4.0]);
//! # Ok::<(), wp::Error>(())
//! ```

#[cfg(test)]
#[macro_use]
mod record_check;
// Slice 5: the tier on a tape (the adjoint steps; the assembly's and mv's records).
mod adjoint;
mod block;
// Slice 4: the matrix as a kernel parameter (`HostObject`).
mod kernel_arg;
mod solve;
mod steps;
// Slice 2: the structure operations (scale, diag, dense, transpose, axpy, mm).
mod ops;
mod ops_steps;
// Slice 6: graph colouring (adjacency, Jones-Plassmann).
mod color;
mod color_steps;

pub use block::{Block, BlockMul, SparseScalar, SquareBlock};
pub use color::{Adjacency, Coloring};
pub use kernel_arg::CudaBsr;
pub use ops::{axpy, diag, mm, mv_transpose, set_diag, MmWork};
pub use solve::{
    bicgstab, cg, cr, gmres, IntoPrecond, Mode, Precond, Preconditioner, SolveOptions, SolveReport,
    Stop,
};

use crate::array::{Array, Element};
use crate::backend::StepFault;
use crate::capturing::Keep;
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use crate::primitives::{array_scan_n, overlap, radix_sort_pairs, Check, Count};
use std::marker::PhantomData;
use steps::{
    BsrMv, BsrOffsets, Dot, TplHeads, TplKeys, TplReport, TplRowKeys, TplSum, TRIPLET_NAMES,
};

/// A block sparse row matrix of `nrow x ncol` blocks of `B` on one device.
///
/// Block row `r` holds blocks `offsets[r] .. offsets[r + 1]`; block `k` lies in block column
/// `columns[k]` and is `values[k]`. Within a row, columns ascend and appear once. The exact
/// block count `offsets[nrow]` lives on the device (a GPU assembly reads nothing back); the
/// host knows an upper bound, the capacity of `columns` and `values`
/// ([`Bsr::nnz_bound`]), and [`Bsr::nnz`] reads the exact count.
///
/// The arrays are handles, as every [`Array`]: a kernel or copy may change the blocks'
/// `values` in place (the structure stays), but `offsets` and `columns` are the structure
/// and are meant to be read; overwriting them gives meaningless results (never a read
/// outside the arrays: the steps clamp). Cloning a `Bsr` clones its array handles: the clone
/// shares the memory.
#[derive(Clone, Debug)]
pub struct Bsr<B: Block> {
    nrow: usize,
    ncol: usize,
    offsets: Array<i32>,
    columns: Array<i32>,
    values: Array<B>,
}

/// `function: message`, as an [`Error::InvalidArgument`].
fn invalid(func: &str, what: impl std::fmt::Display) -> Error {
    Error::invalid(format!("{func}: {what}"))
}

/// `a` is contiguous (the primitives' check, naming the function).
fn contiguous<T: Element>(func: &'static str, name: &str, a: &Array<T>) -> Result<()> {
    Check { func }.contiguous(name, a)
}

/// `other` is on `dev` (the primitives' check).
fn same_device(func: &'static str, arg: &'static str, dev: &Device, other: &Device) -> Result<()> {
    Check { func }.same_device(("", dev), (arg, other))
}

/// Bits of a radix key whose largest value is `max`.
fn key_bits(max: u64) -> u32 {
    (u64::BITS - max.leading_zeros()).max(1)
}

impl<B: Block> Bsr<B> {
    /// The matrix whose blocks are the sums of the triplets `(rows[t], columns[t],
    /// values[t])` sharing a position: Warp's `bsr_from_triplets`, with the duplicates of a
    /// position summed in ascending `t` (a stable sort of the positions, then each run summed
    /// in order), so the sums are the same bits on every device. A position with no triplet
    /// has no block; blocks that sum to zero are kept (the structure never depends on values).
    /// That order makes each position's sum serial: one thread adds all its duplicates, so a
    /// position with a million duplicates costs a million dependent adds on one GPU thread.
    ///
    /// `nrow` and `ncol` count blocks. The three arrays have one element per triplet, on one
    /// device, contiguous. The result is on their device, with room for one block per
    /// triplet ([`Bsr::nnz_bound`]).
    ///
    /// When `values` has a gradient ([`Array::with_grad`]), so have the matrix's values, and
    /// a recording [`Tape`](crate::Tape) records the assembly: its backward adds each
    /// block's gradient into the gradients of the triplets summed into it (and clears the
    /// block's: the assembly wrote it).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming `sparse::from_triplets` and the argument: arrays of
    /// different lengths or not contiguous, `nrow` or `ncol` above `i32::MAX - 1`, more than
    /// `i32::MAX` triplets; [`Error::DeviceMismatch`]. A triplet whose row is outside
    /// `0..nrow` or column outside `0..ncol` is an [`Error::Fault`] of
    /// `sparse::from_triplets`: out of bounds on argument `rows` (or `columns`) with index
    /// `[t, value]` for shape `[triplets, nrow]` (or `ncol`); a block with a NaN or infinite
    /// scalar is a fault `NonFiniteInput` on `values` at index `t` (the smallest bad `t`; rows
    /// before columns before values at one `t`). On the CPU the fault is returned at once; on
    /// a GPU it is reported at the next synchronisation (the matrix then holds the in-range
    /// triplets' sums, a non-finite value included).
    pub fn from_triplets(
        nrow: usize,
        ncol: usize,
        rows: &Array<i32>,
        columns: &Array<i32>,
        values: &Array<B>,
    ) -> Result<Self> {
        Self::assemble(
            nrow,
            ncol,
            rows,
            columns,
            values,
            Count::Host(values.len()),
            true,
        )
    }

    /// [`Bsr::from_triplets`] of the first `count` triplets: a `usize`, or a 1-element
    /// `Array<i32>` on the arrays' device whose value is read where the work runs (no host
    /// synchronisation on a GPU: a count computed by an earlier kernel feeds the assembly
    /// directly). With a device count the matrix has room for as many blocks as the arrays
    /// hold triplets, and the arrays must hold at least as many as the count may reach.
    ///
    /// # Errors
    /// As [`Bsr::from_triplets`]; a host count larger than the arrays is an
    /// [`Error::InvalidArgument`]; a device count outside `0..=len` is a fault of
    /// `sparse::from_triplets`, out of bounds on argument `count` (index `[count]`, shape
    /// `[len + 1]`; then no triplet is assembled).
    pub fn from_triplets_n<'c>(
        nrow: usize,
        ncol: usize,
        rows: &Array<i32>,
        columns: &Array<i32>,
        values: &Array<B>,
        count: impl Into<Count<'c>>,
    ) -> Result<Self> {
        Self::assemble(nrow, ncol, rows, columns, values, count.into(), false)
    }

    /// The assembly of both: `whole` when the count is the arrays' length (the lengths must
    /// then agree; else the count must fit each). With differentiable `values` the matrix's
    /// values get a gradient, and a recording tape records the assembly's adjoint.
    fn assemble(
        nrow: usize,
        ncol: usize,
        rows: &Array<i32>,
        columns: &Array<i32>,
        values: &Array<B>,
        count: Count<'_>,
        whole: bool,
    ) -> Result<Self> {
        let (m, sorted) = Self::assemble_sorted(
            nrow,
            ncol,
            rows,
            columns,
            values,
            count,
            whole,
            &TRIPLET_NAMES,
            true,
        )?;
        if !values.requires_grad() {
            return Ok(m);
        }
        let m = m.with_grad()?;
        if let (Some(sorted), true) = (sorted, crate::tape::recording()) {
            adjoint::record_assembly(&m, values, sorted)?;
        }
        Ok(m)
    }

    /// [`Bsr::assemble`] with the names its errors and faults carry (`names.name` the
    /// function, `names.params` the arguments rows, columns, values, count) and whether the
    /// values are checked for finiteness: the structure operations (`ops.rs`) feed the
    /// pipeline a matrix's blocks, whose values are data, not input to check.
    #[allow(clippy::too_many_arguments)]
    pub(super) fn assemble_with(
        nrow: usize,
        ncol: usize,
        rows: &Array<i32>,
        columns: &Array<i32>,
        values: &Array<B>,
        count: Count<'_>,
        whole: bool,
        names: &'static KernelInfo,
        check_finite: bool,
    ) -> Result<Self> {
        Self::assemble_sorted(
            nrow,
            ncol,
            rows,
            columns,
            values,
            count,
            whole,
            names,
            check_finite,
        )
        .map(|(m, _)| m)
    }

    /// [`Bsr::assemble_with`], also handing back the sort's scratch (`None` when nothing was
    /// sorted) for the assembly's adjoint.
    #[allow(clippy::too_many_arguments)]
    fn assemble_sorted(
        nrow: usize,
        ncol: usize,
        rows: &Array<i32>,
        columns: &Array<i32>,
        values: &Array<B>,
        count: Count<'_>,
        whole: bool,
        names: &'static KernelInfo,
        check_finite: bool,
    ) -> Result<(Self, Option<adjoint::Sorted>)> {
        let func = names.name;
        let dev = values.device().clone();
        same_device(func, "rows", &dev, rows.device())?;
        same_device(func, "columns", &dev, columns.device())?;
        contiguous(func, "rows", rows)?;
        contiguous(func, "columns", columns)?;
        contiguous(func, "values", values)?;
        let len = rows.len().min(columns.len()).min(values.len());
        if whole && (rows.len() != values.len() || columns.len() != values.len()) {
            return Err(invalid(
                func,
                format!(
                    "arguments `rows`, `columns` and `values` must have one element per \
                     triplet; their shapes are {:?}, {:?} and {:?}",
                    rows.shape(),
                    columns.shape(),
                    values.shape()
                ),
            ));
        }
        // The triplets the steps may process (`n`), and the device count's address.
        let (n, count_addr) = match count {
            Count::Host(c) if c <= len => (c, 0),
            Count::Host(c) => {
                return Err(invalid(
                    func,
                    format!(
                        "count {c} is larger than the triplet arrays (shapes {:?}, {:?} and \
                         {:?})",
                        rows.shape(),
                        columns.shape(),
                        values.shape()
                    ),
                ))
            }
            Count::Device(c) => {
                same_device(func, "count", &dev, c.device())?;
                if c.len() != 1 {
                    return Err(invalid(
                        func,
                        format!(
                            "argument `count` must be a 1-element array, got shape {:?}",
                            c.shape()
                        ),
                    ));
                }
                (len, c.device_address())
            }
        };
        let limit = i32::MAX as usize - 1;
        if nrow > limit || ncol > limit {
            return Err(invalid(
                func,
                format!("`nrow` {nrow} and `ncol` {ncol} must be at most {limit} (i32 indices)"),
            ));
        }
        if n > i32::MAX as usize {
            return Err(invalid(
                func,
                format!("{n} triplets, more than the {} this counts", i32::MAX),
            ));
        }
        let m = Bsr {
            nrow,
            ncol,
            offsets: Array::zeros(nrow + 1, &dev)?,
            columns: Array::zeros(n, &dev)?,
            values: Array::zeros(n, &dev)?,
        };
        // (A device count is read and checked by the steps, even with no room for a triplet.)
        if n == 0 && count_addr == 0 {
            return Ok((m, None));
        }
        // What the primitives process: the same count.
        let prim: Count<'_> = match count {
            Count::Host(_) => Count::Host(n),
            Count::Device(c) => Count::Device(c),
        };
        // Scratch: the sort's keys and permutation, the heads' scan, the blocks' rows, and
        // the smallest bad triplet of each kind.
        let keys = Array::<u32>::zeros(n, &dev)?;
        let idx = Array::<i32>::zeros(n, &dev)?;
        let pos = Array::<i32>::zeros(n, &dev)?;
        let block_rows = Array::<i32>::zeros(n, &dev)?;
        let bad = Array::<i32>::zeros(3, &dev)?;
        bad.fill(i32::MAX)?;
        // One sort by row * ncol + col when that (and the sentinel ncol * nrow past it) fits
        // 32 bits; else by column, then stably by row.
        let cells = nrow as u64 * ncol as u64;
        let two_pass = cells > u32::MAX as u64;
        let (ni, nr, nc, blk) = (
            n as i32,
            nrow as i32,
            ncol as i32,
            (B::ROWS * B::COLS) as i32,
        );
        let (r_a, c_a, v_a) = (
            rows.device_address(),
            columns.device_address(),
            values.device_address(),
        );
        dispatch::object_step(
            &dev,
            &TplKeys::<B::Scalar> {
                count: count_addr,
                rows: r_a,
                cols: c_a,
                values: v_a,
                n: ni,
                nrow: nr,
                ncol: nc,
                block: blk,
                two_pass: two_pass as i32,
                no_finite_check: !check_finite as i32,
                keys: keys.device_address(),
                idx: idx.device_address(),
                bad: bad.device_address(),
                scalar: PhantomData,
            },
        )?;
        dispatch::object_step(
            &dev,
            &TplReport::<B::Scalar> {
                count: count_addr,
                bad: bad.device_address(),
                rows: r_a,
                cols: c_a,
                values: v_a,
                n: ni,
                nrow: nr,
                ncol: nc,
                block: blk,
                fault: StepFault::new(names),
                scalar: PhantomData,
            },
        )?;
        if two_pass {
            radix_sort_pairs(&keys, &idx, prim, Some(key_bits(ncol as u64)))?;
            dispatch::object_step(
                &dev,
                &TplRowKeys {
                    count: count_addr,
                    rows: r_a,
                    cols: c_a,
                    idx: idx.device_address(),
                    keys: keys.device_address(),
                    n: ni,
                    nrow: nr,
                    ncol: nc,
                    pad: 0,
                },
            )?;
            radix_sort_pairs(&keys, &idx, prim, Some(key_bits(nrow as u64)))?;
        } else {
            radix_sort_pairs(&keys, &idx, prim, Some(key_bits(cells)))?;
        }
        dispatch::object_step(
            &dev,
            &TplHeads {
                count: count_addr,
                rows: r_a,
                cols: c_a,
                idx: idx.device_address(),
                heads: pos.device_address(),
                n: ni,
                nrow: nr,
                ncol: nc,
                pad: 0,
            },
        )?;
        array_scan_n(&pos, &pos, prim, true)?;
        dispatch::object_step(
            &dev,
            &TplSum::<B::Scalar> {
                count: count_addr,
                rows: r_a,
                cols: c_a,
                values: v_a,
                idx: idx.device_address(),
                pos: pos.device_address(),
                block_rows: block_rows.device_address(),
                columns: m.columns.device_address(),
                out: m.values.device_address(),
                n: ni,
                nrow: nr,
                ncol: nc,
                block: blk,
                scalar: PhantomData,
            },
        )?;
        dispatch::object_step(
            &dev,
            &BsrOffsets {
                count: count_addr,
                block_rows: block_rows.device_address(),
                pos: pos.device_address(),
                offsets: m.offsets.device_address(),
                n: ni,
                nrow: nr,
            },
        )?;
        // The scratch is freed after the queued steps (array memory orders its free), or
        // kept by the assembly's adjoint. The sorted keys of triplets out of range are
        // `nrow * ncol` (one pass) or `nrow` (the second pass's row keys).
        let sorted = adjoint::Sorted {
            keys,
            idx,
            pos,
            count: match count {
                Count::Device(c) => Some(c.clone()),
                Count::Host(_) => None,
            },
            n,
            sentinel: if two_pass { nrow as u32 } else { cells as u32 },
        };
        Ok((m, Some(sorted)))
    }

    /// `"N x M blocks of R x C (NR x MC scalars)"`, for messages.
    fn describe(&self) -> String {
        let (r, c) = self.shape();
        format!(
            "{} x {} blocks of {} x {} ({r} x {c} scalars)",
            self.nrow,
            self.ncol,
            B::ROWS,
            B::COLS
        )
    }

    /// Whether `v`'s elements share memory with the matrix's arrays.
    fn overlaps<T: Element>(&self, v: &Array<T>) -> bool {
        overlap(v, &self.offsets) || overlap(v, &self.columns) || overlap(v, &self.values)
    }

    /// Block rows.
    pub fn nrow(&self) -> usize {
        self.nrow
    }

    /// Block columns.
    pub fn ncol(&self) -> usize {
        self.ncol
    }

    /// The shape in scalars: `(nrow * B::ROWS, ncol * B::COLS)`.
    pub fn shape(&self) -> (usize, usize) {
        (self.nrow * B::ROWS, self.ncol * B::COLS)
    }

    /// An upper bound of the block count: the capacity of [`Bsr::columns`] and
    /// [`Bsr::values`].
    pub fn nnz_bound(&self) -> usize {
        self.values.len()
    }

    /// The block count, `offsets[nrow]`, read from the device (a synchronisation of that one
    /// element), clamped into `0..=nnz_bound()` as the steps clamp it: an assembled matrix's
    /// count is in range, and one whose offsets were overwritten still gives a count that
    /// indexes [`Bsr::columns`] and [`Bsr::values`].
    ///
    /// # Errors
    /// A fault of the queued work, or a read-back inside a capture.
    pub fn nnz(&self) -> Result<usize> {
        let v = self.offsets.view(self.nrow..self.nrow + 1)?.to_vec()?[0];
        Ok(v.clamp(0, self.nnz_bound() as i32) as usize)
    }

    /// The row offsets (`nrow + 1`).
    pub fn offsets(&self) -> &Array<i32> {
        &self.offsets
    }

    /// The block columns (the first [`Bsr::nnz`] are the matrix's).
    pub fn columns(&self) -> &Array<i32> {
        &self.columns
    }

    /// The blocks (the first [`Bsr::nnz`] are the matrix's).
    pub fn values(&self) -> &Array<B> {
        &self.values
    }

    /// The device holding the matrix.
    pub fn device(&self) -> &Device {
        self.values.device()
    }
}

/// Queues `y = alpha A x + beta y` over scalar addresses. Inside a capture the step is
/// recorded, and the graph keeps `uses()` (the arrays the addresses point into) alive.
///
/// # Safety
/// `x` and `y` are addresses of contiguous memory on `a`'s device holding `a.ncol() *
/// B::COLS` and `a.nrow() * B::ROWS` scalars, alive until the step has run (or, captured,
/// kept alive by `uses()`); `y` overlaps neither `x` nor the matrix's arrays. The step reads
/// and writes them with no bounds check.
unsafe fn mv_raw<B: Block>(
    a: &Bsr<B>,
    x: u64,
    y: u64,
    alpha: f64,
    beta: f64,
    uses: impl FnOnce() -> Keep,
) -> Result<()> {
    dispatch::object_step_keeping(
        a.device(),
        &BsrMv::<B> {
            offsets: a.offsets.device_address(),
            columns: a.columns.device_address(),
            values: a.values.device_address(),
            x,
            y,
            alpha,
            beta,
            nrow: a.nrow as i32,
            ncol: a.ncol as i32,
            cap: a.nnz_bound() as i32,
            lanes: mv_lanes() as i32,
            block: PhantomData,
        },
        uses,
    )
}

thread_local! {
    /// Lanes per scalar row of the calling thread's [`mv`]s ([`set_mv_lanes`]; 0: the
    /// default, 1). Per thread: a setting changes results in the last bits, so it must not
    /// reach other threads' work (tests running side by side).
    static MV_LANES: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// The lanes per scalar row of the calling thread's [`mv`]s from now on (and of the solvers'
/// products it queues): `Some(w)` with `w` in 1, 2, 4, 8, 16, 32, or `None` for the default
/// (1). For benchmarks and tuning.
///
/// With `w` lanes, each scalar of `y` sums its row's blocks in `w` interleaved partial sums
/// (lane `l` takes the blocks at positions `l, l + w, ..` of the row), added pairwise at
/// strides `w/2, .., 1`; a GPU runs the lanes as `w` threads of a warp: more threads and
/// coalesced loads for long rows. The order of the sums depends on `w`, so results differ in
/// the last bits between settings; for one setting they are the same bits on the CPU and a
/// GPU, as always. The setting is read when the work is queued (a capture keeps it).
///
/// # Errors
/// [`Error::InvalidArgument`] naming `sparse::set_mv_lanes` for another `w`.
pub fn set_mv_lanes(lanes: Option<usize>) -> Result<()> {
    let w = lanes.unwrap_or(0);
    if lanes.is_some() && !(w.is_power_of_two() && w <= steps::MAX_LANES) {
        return Err(invalid(
            "sparse::set_mv_lanes",
            format!("`lanes` is {w}; it must be 1, 2, 4, 8, 16 or 32"),
        ));
    }
    MV_LANES.with(|c| c.set(w));
    Ok(())
}

/// The lanes per scalar row of the calling thread's next [`mv`].
fn mv_lanes() -> usize {
    MV_LANES.with(|c| c.get()).max(1)
}

/// `y = alpha A x + beta y` (Warp's `bsr_mv`), a thread per scalar row on a GPU (`w` per row
/// with [`set_mv_lanes`]).
///
/// Each scalar of `y` is `alpha * acc + beta * y`, where `acc` sums from zero, over the row's
/// blocks in storage order and within a block over ascending columns, the products
/// `a_ij * x_j`, each rounded (with `w` lanes, in the order [`set_mv_lanes`] describes): the
/// same bits on every device. When `beta == 0`, `y` is not
/// read (it may hold NaN).
///
/// `x` has `ncol` elements (`B::In`: `Vec3` for `Mat3` blocks), `y` has `nrow` (`B::Out`);
/// both contiguous, on the matrix's device, `y` overlapping neither `x` nor the matrix.
///
/// A [capture](crate::capture) records it (each replay multiplies the arrays' contents at
/// that time); on a GPU, call it once for the block type before capturing (its first call
/// loads the CUDA library).
///
/// A recording [`Tape`](crate::Tape) records it when `y` has a gradient: backward adds
/// `alpha Aᵀ ȳ` into `x`'s gradient (when it has one; through a transpose of `A`), `alpha ȳ_r
/// x_cᵀ` into the gradient of each stored block (when [`Bsr::with_grad`]), then scales `ȳ`
/// by `beta` (`y` was read scaled by `beta`, and written). `x` and `A` are read when
/// backward runs, as a kernel's adjoint reads its arrays.
///
/// # Errors
/// [`Error::InvalidArgument`] naming `sparse::mv`, the argument and both shapes when a length
/// differs; for arrays that are not contiguous or overlap; [`Error::DeviceMismatch`].
pub fn mv<B: Block>(
    alpha: B::Scalar,
    a: &Bsr<B>,
    x: &Array<B::In>,
    beta: B::Scalar,
    y: &Array<B::Out>,
) -> Result<()> {
    mv_unrecorded(alpha, a, x, beta, y)?;
    adjoint::record_mv(alpha.to_f64(), a, x, beta.to_f64(), y, false)
}

/// [`mv`] without its tape record.
fn mv_unrecorded<B: Block>(
    alpha: B::Scalar,
    a: &Bsr<B>,
    x: &Array<B::In>,
    beta: B::Scalar,
    y: &Array<B::Out>,
) -> Result<()> {
    const F: &str = "sparse::mv";
    let dev = a.device();
    same_device(F, "x", dev, x.device())?;
    same_device(F, "y", dev, y.device())?;
    contiguous(F, "x", x)?;
    contiguous(F, "y", y)?;
    if x.len() != a.ncol {
        return Err(invalid(
            F,
            format!(
                "argument `x` has shape {:?} of {}, but the matrix has {}: `x` needs {} {} \
                 elements",
                x.shape(),
                B::In::TYPE_NAME,
                a.describe(),
                a.ncol,
                B::In::TYPE_NAME
            ),
        ));
    }
    if y.len() != a.nrow {
        return Err(invalid(
            F,
            format!(
                "argument `y` has shape {:?} of {}, but the matrix has {}: `y` needs {} {} \
                 elements",
                y.shape(),
                B::Out::TYPE_NAME,
                a.describe(),
                a.nrow,
                B::Out::TYPE_NAME
            ),
        ));
    }
    if overlap(x, y) {
        return Err(invalid(F, "arguments `x` and `y` overlap in memory"));
    }
    if a.overlaps(y) {
        return Err(invalid(F, "argument `y` overlaps the matrix's arrays"));
    }
    // SAFETY: x and y are contiguous on a's device with the lengths checked above, y
    // overlaps neither x nor the matrix (checked), and the arrays are kept by `uses`.
    unsafe {
        mv_raw(
            a,
            x.device_address(),
            y.device_address(),
            alpha.to_f64(),
            beta.to_f64(),
            || Box::new((a.clone(), x.clone(), y.clone())),
        )
    }
}

/// `y = alpha A x + beta y` over scalar vectors (`x` of A's scalar columns, `y` of its rows,
/// contiguous, on its device, `y` overlapping neither), unrecorded: the adjoints' products.
fn mv_scalars<B: Block>(
    a: &Bsr<B>,
    x: &Array<B::Scalar>,
    y: &Array<B::Scalar>,
    alpha: f64,
    beta: f64,
) -> Result<()> {
    let (nr, nc) = a.shape();
    if x.len() != nc || y.len() != nr || overlap(x, y) || a.overlaps(y) {
        return Err(Error::invalid(format!(
            "sparse: internal: an adjoint's product with {} got x of {} and y of {} scalars",
            a.describe(),
            x.len(),
            y.len()
        )));
    }
    // SAFETY: x and y are contiguous (reinterpreted gradients) scalar vectors of the lengths
    // checked above on the matrix's device, y overlapping neither x nor the matrix; the
    // arrays are kept by `uses`.
    unsafe {
        mv_raw(
            a,
            x.device_address(),
            y.device_address(),
            alpha,
            beta,
            || Box::new((a.clone(), x.clone(), y.clone())),
        )
    }
}

/// Scratch of [`dot_raw`]: one partial per chunk.
fn dot_partials<S: SparseScalar>(n: usize, dev: &Device) -> Result<Array<S>> {
    Array::zeros(steps::dot_chunks(n), dev)
}

/// Queues the dot product of `n` scalars at `a` and `b` into the scalar at `out` (recorded
/// inside a capture, which keeps `uses()` and the partials alive).
///
/// # Safety
/// `a` and `b` address `n` contiguous scalars each and `out` one, on `dev`, alive until the
/// steps have run (or, captured, kept alive by `uses()`); `out` overlaps neither input;
/// `partials` holds `dot_partials(n)`'s length. The steps read and write them with no bounds
/// check.
unsafe fn dot_raw<S: SparseScalar>(
    dev: &Device,
    a: u64,
    b: u64,
    n: usize,
    partials: &Array<S>,
    out: u64,
    uses: impl Fn() -> Keep,
) -> Result<()> {
    let chunks = steps::dot_chunks(n) as i64;
    let p = partials.device_address();
    let keep = || -> Keep { Box::new((uses(), partials.clone())) };
    dispatch::object_step_keeping(
        dev,
        &Dot::<S, false> {
            a,
            b,
            n: n as i64,
            out: p,
            chunks,
            scalar: PhantomData,
        },
        keep,
    )?;
    dispatch::object_step_keeping(
        dev,
        &Dot::<S, true> {
            a: p,
            b: 0,
            n: chunks,
            out,
            chunks,
            scalar: PhantomData,
        },
        keep,
    )
}

/// The dot product `a . b` into `out[0]`, reduced in a fixed tree, so the result is the
/// same bits on every device (unlike [`array_sum`](crate::array_sum)'s blocked float sums).
///
/// The order: chunks of 4096 elements; in a chunk, lane `l` of 256 sums from zero the products
/// of elements `l, l + 256, ..` in order, then the lanes are added pairwise at strides 128,
/// 64, .., 1 (lane `l` gets `l + stride`); the chunks' partials are reduced the same way
/// (lane `l` sums partials `l, l + 256, ..`, then the tree).
///
/// It allocates its scratch (a partial sum per chunk), so it cannot be recorded by a
/// [capture](crate::capture) (an [`Error::Capture`] there).
///
/// # Errors
/// [`Error::Capture`] inside a capture; [`Error::InvalidArgument`] naming `sparse::dot` when
/// the lengths differ, `out` is not one element or overlaps an input, or an array is not
/// contiguous; [`Error::DeviceMismatch`].
pub fn dot<S: SparseScalar>(a: &Array<S>, b: &Array<S>, out: &Array<S>) -> Result<()> {
    const F: &str = "sparse::dot";
    let dev = a.device();
    same_device(F, "b", dev, b.device())?;
    same_device(F, "out", dev, out.device())?;
    contiguous(F, "a", a)?;
    contiguous(F, "b", b)?;
    if a.len() != b.len() {
        return Err(invalid(
            F,
            format!(
                "arguments `a` and `b` differ in length: shapes {:?} and {:?}",
                a.shape(),
                b.shape()
            ),
        ));
    }
    if out.len() != 1 {
        return Err(invalid(
            F,
            format!(
                "argument `out` must have one element, got shape {:?}",
                out.shape()
            ),
        ));
    }
    if overlap(out, a) || overlap(out, b) {
        return Err(invalid(F, "argument `out` overlaps `a` or `b`"));
    }
    let partials = dot_partials::<S>(a.len(), dev)?;
    // SAFETY: a and b are contiguous on dev with a.len() scalars each, out is one scalar not
    // overlapping them (checked above), the partials are sized for a.len(), and the arrays
    // are kept by `uses`.
    unsafe {
        dot_raw(
            dev,
            a.device_address(),
            b.device_address(),
            a.len(),
            &partials,
            out.device_address(),
            || Box::new((a.clone(), b.clone(), out.clone())),
        )
    }
}

//! The structure operations (slice 2): scaling, the block diagonal, dense matrices both ways,
//! the transpose, `axpy` and `mm`. Each runs the steps of `ops_steps.rs` (the `sparse_ops`
//! build library) and, for `axpy` and `mm`, the triplet pipeline of `mod.rs`, which sums a
//! position's contributions in ascending triplet order: so every result is the same bits on
//! the CPU and on a GPU.

use super::block::{Block, BlockMul, SparseScalar, SquareBlock};
use super::ops_steps::{
    DenseReport, Diag, MmCount, MmExpand, MmTotal, RowKeys, Scale, SetDiag, ToDense, ToTriplets,
    Transpose, DENSE_NAMES,
};
use super::steps::BsrOffsets;
use super::{contiguous, invalid, key_bits, same_device, Bsr};
use crate::array::Array;
use crate::backend::{ObjectStep, StepFault};
use crate::capturing::Keep;
use crate::device::Device;
use crate::dispatch;
use crate::error::Result;
use crate::kernel::KernelInfo;
use crate::primitives::{array_scan_n, radix_sort_pairs, Count};
use std::marker::PhantomData;

/// What `axpy`'s pipeline faults are named by (only a matrix whose structure a user
/// overwrote can fault there: a column out of range).
static AXPY_NAMES: KernelInfo = KernelInfo {
    name: "sparse::axpy",
    module: "warp_lang::sparse",
    params: &["rows", "columns", "values", "count"],
    ..KernelInfo::BLANK
};

/// What `mm`'s pipeline faults are named by: argument 3, `products`, is the product count
/// when it exceeds a fixed [`MmWork`]'s capacity.
static MM_NAMES: KernelInfo = KernelInfo {
    name: "sparse::mm",
    module: "warp_lang::sparse",
    params: &["rows", "columns", "values", "products"],
    ..KernelInfo::BLANK
};

/// Queues `step` (recorded inside a capture, keeping `uses()`), unless it has no thread.
fn step<S: ObjectStep + 'static>(dev: &Device, s: &S, uses: impl FnOnce() -> Keep) -> Result<()> {
    if s.len() == 0 {
        return Ok(());
    }
    dispatch::object_step_keeping(dev, s, uses)
}

/// Queues `step`, refused inside a capture (its callers allocate), unless it has no thread.
fn step_now<S: ObjectStep>(dev: &Device, s: &S) -> Result<()> {
    if s.len() == 0 {
        return Ok(());
    }
    dispatch::object_step(dev, s)
}

/// A finite scalar argument, else an `Err` naming it.
fn finite<S: SparseScalar>(func: &str, name: &str, v: S) -> Result<()> {
    if v.finite() {
        return Ok(());
    }
    Err(invalid(
        func,
        format!("argument `{name}` is {v:?}; it must be finite"),
    ))
}

/// `nrow` and `ncol` fit the i32 indices (as in `from_triplets`).
fn dims(func: &str, nrow: usize, ncol: usize) -> Result<()> {
    let limit = i32::MAX as usize - 1;
    if nrow > limit || ncol > limit {
        return Err(invalid(
            func,
            format!("`nrow` {nrow} and `ncol` {ncol} must be at most {limit} (i32 indices)"),
        ));
    }
    Ok(())
}

/// `n` fits an i32 block count.
fn fits(func: &str, what: &str, n: usize) -> Result<i32> {
    i32::try_from(n).map_err(|_| {
        invalid(
            func,
            format!(
                "{what}: {n}, more than the {} an i32 index counts",
                i32::MAX
            ),
        )
    })
}

impl<B: Block> Bsr<B> {
    /// The matrix of `nrow x ncol` blocks with no stored block (all zero), on `dev`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::zeros` when
    /// `nrow` or `ncol` is above `i32::MAX - 1`; an allocation's error.
    pub fn zeros(nrow: usize, ncol: usize, dev: &Device) -> Result<Self> {
        dims("sparse::zeros", nrow, ncol)?;
        Ok(Bsr {
            nrow,
            ncol,
            offsets: Array::zeros(nrow + 1, dev)?,
            columns: Array::zeros(0, dev)?,
            values: Array::zeros(0, dev)?,
        })
    }

    /// `A = alpha A`: each stored scalar times `alpha`, rounded once (the same bits on every
    /// device). The structure stays (a block scaled to zero is kept). In place, as a kernel
    /// writes values: clones of the matrix share its values and see the change. A
    /// [capture](crate::capture) records it.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::scale` when
    /// `alpha` is NaN or infinite.
    pub fn scale(&mut self, alpha: B::Scalar) -> Result<()> {
        finite("sparse::scale", "alpha", alpha)?;
        let m = self.clone();
        step(
            self.device(),
            &Scale::<B::Scalar> {
                offsets: self.offsets.device_address(),
                values: self.values.device_address(),
                alpha: alpha.to_f64(),
                nrow: self.nrow as i32,
                cap: self.nnz_bound() as i32,
                block: (B::ROWS * B::COLS) as i32,
                pad: 0,
                scalar: PhantomData,
            },
            || Box::new(m),
        )
    }

    /// Writes the matrix into `out` as a dense matrix: `out[[i, j]]` is scalar entry `(i, j)`,
    /// so `out` is row-major with shape `[nrow * B::ROWS, ncol * B::COLS]` (block `(r, c)`'s
    /// entry `(p, q)` at `[r * B::ROWS + p, c * B::COLS + q]`, whatever the block type's own
    /// layout). Entries outside the stored blocks are zero. A thread per scalar row; every
    /// scalar is copied unchanged. A [capture](crate::capture) records it.
    ///
    /// `out` is an array on the matrix's device (on the CPU a host array), contiguous, not
    /// overlapping the matrix.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::to_dense`
    /// and both shapes when `out`'s shape differs, or when it is not contiguous or overlaps
    /// the matrix; [`Error::DeviceMismatch`](crate::Error::DeviceMismatch).
    pub fn to_dense(&self, out: &Array<B::Scalar, 2>) -> Result<()> {
        const F: &str = "sparse::to_dense";
        let (r, c) = self.shape();
        same_device(F, "out", self.device(), out.device())?;
        if out.shape() != [r, c] {
            return Err(invalid(
                F,
                format!(
                    "argument `out` has shape {:?}, but the matrix has {}: `out` needs shape \
                     [{r}, {c}]",
                    out.shape(),
                    self.describe()
                ),
            ));
        }
        if !out.is_contiguous() {
            return Err(invalid(
                F,
                format!(
                    "`out` is not contiguous (shape {:?}, strides {:?}); copy it into a new \
                     array first",
                    out.shape(),
                    out.strides()
                ),
            ));
        }
        let flat = out.reshape(r * c)?;
        if self.overlaps(&flat) {
            return Err(invalid(F, "argument `out` overlaps the matrix's arrays"));
        }
        let (m, o) = (self.clone(), out.clone());
        step(
            self.device(),
            &ToDense::<B::Scalar> {
                offsets: self.offsets.device_address(),
                columns: self.columns.device_address(),
                values: self.values.device_address(),
                out: out.device_address(),
                nrow: self.nrow as i32,
                ncol: self.ncol as i32,
                cap: self.nnz_bound() as i32,
                rows: B::ROWS as i32,
                cols: B::COLS as i32,
                cm: B::COL_MAJOR as i32,
                scalar: PhantomData,
            },
            || Box::new((m, o)),
        )
    }

    /// The block sparse matrix of the dense row-major matrix `a` (the layout of
    /// [`Bsr::to_dense`]): `a`'s shape is `[nrow * B::ROWS, ncol * B::COLS]`, and block `(r,
    /// c)` is stored when any of its scalars is nonzero (a NaN counts as nonzero), in the
    /// order of the blocks. The result is on `a`'s device, with room for every block
    /// (`nrow * ncol`: [`Bsr::nnz_bound`]). Scalars are copied unchanged.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::from_dense`
    /// when `a`'s shape is not a multiple of the block's, has more than `i32::MAX` blocks or
    /// rows, or `a` is not contiguous. A NaN or infinite scalar is an
    /// [`Error::Fault`](crate::Error::Fault) of `sparse::from_dense`, `NonFiniteInput` on
    /// argument `a` whose index is the first such scalar's in row-major order (`i * width +
    /// j`): returned at once on the CPU, reported at the next synchronisation on a GPU (the
    /// matrix then holds the blocks, the non-finite ones included).
    pub fn from_dense(a: &Array<B::Scalar, 2>) -> Result<Self> {
        const F: &str = "sparse::from_dense";
        let [n, m] = a.shape();
        let dev = a.device().clone();
        if n % B::ROWS != 0 || m % B::COLS != 0 {
            return Err(invalid(
                F,
                format!(
                    "argument `a` has shape [{n}, {m}], not a whole number of {} x {} blocks",
                    B::ROWS,
                    B::COLS
                ),
            ));
        }
        if !a.is_contiguous() {
            return Err(invalid(
                F,
                format!(
                    "`a` is not contiguous (shape {:?}, strides {:?}); copy it into a new \
                     array first",
                    a.shape(),
                    a.strides()
                ),
            ));
        }
        let (nrow, ncol) = (n / B::ROWS, m / B::COLS);
        dims(F, nrow, ncol)?;
        fits(F, "`a`'s rows", n)?;
        let nb = fits(F, "`a`'s blocks", nrow * ncol)? as usize;
        let out = Bsr {
            nrow,
            ncol,
            offsets: Array::zeros(nrow + 1, &dev)?,
            columns: Array::zeros(nb, &dev)?,
            values: Array::zeros(nb, &dev)?,
        };
        if nb == 0 {
            return Ok(out);
        }
        let pos = Array::<i32>::zeros(nb, &dev)?;
        let block_rows = Array::<i32>::zeros(nb, &dev)?;
        let bad = Array::from_slice(&[i32::MAX], &dev)?;
        let dense = super::ops_steps::Dense::<B::Scalar, false> {
            dense: a.device_address(),
            pos: pos.device_address(),
            bad: bad.device_address(),
            block_rows: block_rows.device_address(),
            columns: out.columns.device_address(),
            values: out.values.device_address(),
            nrow: nrow as i32,
            ncol: ncol as i32,
            rows: B::ROWS as i32,
            cols: B::COLS as i32,
            cm: B::COL_MAJOR as i32,
            pad: 0,
            scalar: PhantomData,
        };
        step_now(&dev, &dense)?;
        step_now(
            &dev,
            &DenseReport::<B::Scalar> {
                dense: a.device_address(),
                bad: bad.device_address(),
                width: m as i64,
                fault: StepFault::new(&DENSE_NAMES),
                scalar: PhantomData,
            },
        )?;
        array_scan_n(&pos, &pos, nb, true)?;
        let gather = super::ops_steps::Dense::<B::Scalar, true> {
            dense: dense.dense,
            pos: dense.pos,
            bad: dense.bad,
            block_rows: dense.block_rows,
            columns: dense.columns,
            values: dense.values,
            nrow: dense.nrow,
            ncol: dense.ncol,
            rows: dense.rows,
            cols: dense.cols,
            cm: dense.cm,
            pad: 0,
            scalar: PhantomData,
        };
        step_now(&dev, &gather)?;
        step_now(
            &dev,
            &BsrOffsets {
                count: 0,
                block_rows: block_rows.device_address(),
                pos: pos.device_address(),
                offsets: out.offsets.device_address(),
                n: nb as i32,
                nrow: nrow as i32,
            },
        )?;
        Ok(out)
    }

    /// The transpose: `ncol x nrow` blocks of [`Block::Transpose`] (for a square block type,
    /// the same type, each block transposed), block `(c, r)` the transpose of block `(r, c)`.
    /// The structure is computed on the device (a stable radix sort of the blocks by column,
    /// which keeps each column's rows in order), nothing is read back, and every scalar is
    /// copied unchanged: the same bits on every device. The result has the matrix's capacity.
    ///
    /// # Errors
    /// An allocation's error (so [`Error::Capture`](crate::Error::Capture) inside a capture:
    /// the result is new memory).
    pub fn transpose(&self) -> Result<Bsr<B::Transpose>> {
        let dev = self.device().clone();
        let cap = self.nnz_bound();
        let t = Bsr::<B::Transpose> {
            nrow: self.ncol,
            ncol: self.nrow,
            offsets: Array::zeros(self.ncol + 1, &dev)?,
            columns: Array::zeros(cap, &dev)?,
            values: Array::zeros(cap, &dev)?,
        };
        if cap == 0 || self.nrow == 0 {
            return Ok(t);
        }
        let block_rows = Array::<i32>::zeros(cap, &dev)?;
        let keys = Array::<u32>::zeros(cap, &dev)?;
        let idx = Array::<i32>::zeros(cap, &dev)?;
        let (nr, nc, ca) = (self.nrow as i32, self.ncol as i32, cap as i32);
        step_now(
            &dev,
            &RowKeys {
                offsets: self.offsets.device_address(),
                columns: self.columns.device_address(),
                block_rows: block_rows.device_address(),
                keys: keys.device_address(),
                idx: idx.device_address(),
                nrow: nr,
                ncol: nc,
                cap: ca,
                pad: 0,
            },
        )?;
        // The block count is offsets[nrow], read where the sort runs (a device count).
        let count = self.offsets.view(self.nrow..self.nrow + 1)?;
        radix_sort_pairs(
            &keys,
            &idx,
            Count::Device(&count),
            Some(key_bits(self.ncol as u64)),
        )?;
        step_now(
            &dev,
            &Transpose::<B::Scalar> {
                offsets: self.offsets.device_address(),
                block_rows: block_rows.device_address(),
                keys: keys.device_address(),
                idx: idx.device_address(),
                values: self.values.device_address(),
                out_offsets: t.offsets.device_address(),
                out_columns: t.columns.device_address(),
                out_values: t.values.device_address(),
                nrow: nr,
                ncol: nc,
                cap: ca,
                rows: B::ROWS as i32,
                cols: B::COLS as i32,
                cm: B::COL_MAJOR as i32,
                cm_t: <B::Transpose as Block>::COL_MAJOR as i32,
                pad: 0,
                scalar: PhantomData,
            },
        )?;
        Ok(t)
    }

    /// The matrix's blocks as triplets into `rows`, `cols`, `vals` (of `limit` triplets),
    /// each block times `factor`, after the `*base` triplets before them (`base`: the address
    /// of an i32, or 0), writing `*base` + the block count to `count_out`.
    fn to_triplets(
        &self,
        factor: f64,
        base: u64,
        (rows, cols, vals): (&Array<i32>, &Array<i32>, &Array<B>),
        count_out: u64,
    ) -> Result<()> {
        step_now(
            self.device(),
            &ToTriplets::<B::Scalar> {
                offsets: self.offsets.device_address(),
                columns: self.columns.device_address(),
                values: self.values.device_address(),
                base,
                rows: rows.device_address(),
                cols: cols.device_address(),
                vals: vals.device_address(),
                count_out,
                factor,
                nrow: self.nrow as i32,
                cap: self.nnz_bound() as i32,
                block: (B::ROWS * B::COLS) as i32,
                limit: vals.len() as i32,
                scalar: PhantomData,
            },
        )
    }
}

/// The address of element `i` of a 1-D i32 array.
fn addr_of(a: &Array<i32>, i: usize) -> u64 {
    a.device_address() + (i * std::mem::size_of::<i32>()) as u64
}

impl<B: SquareBlock> Bsr<B> {
    /// The block diagonal matrix of `nrow x ncol` blocks whose block `(i, i)` is `d[i]`, for
    /// `i < min(nrow, ncol)` (every diagonal block stored, zero or not), on `d`'s device. The
    /// blocks are copied unchanged (values are data: a NaN is kept, as a kernel may write one).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::from_diag`
    /// when `d` does not have `min(nrow, ncol)` elements or is not contiguous, or the
    /// dimensions exceed the i32 indices.
    pub fn from_diag(nrow: usize, ncol: usize, d: &Array<B>) -> Result<Self> {
        Self::diagonal("sparse::from_diag", nrow, ncol, Some(d), d.device())
    }

    /// The `n x n` block identity (`B`'s identity on the diagonal), on `dev`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::identity`
    /// when `n` exceeds the i32 indices.
    pub fn identity(n: usize, dev: &Device) -> Result<Self> {
        Self::diagonal("sparse::identity", n, n, None, dev)
    }

    /// The block diagonal matrix of `d`, or the identity.
    fn diagonal(
        func: &'static str,
        nrow: usize,
        ncol: usize,
        d: Option<&Array<B>>,
        dev: &Device,
    ) -> Result<Self> {
        dims(func, nrow, ncol)?;
        let n = nrow.min(ncol);
        if let Some(d) = d {
            contiguous(func, "d", d)?;
            if d.len() != n {
                return Err(invalid(
                    func,
                    format!(
                        "argument `d` has shape {:?} of {}, but a matrix of {nrow} x {ncol} \
                         blocks has {n} diagonal blocks",
                        d.shape(),
                        B::TYPE_NAME
                    ),
                ));
            }
        }
        let m = Bsr {
            nrow,
            ncol,
            offsets: Array::zeros(nrow + 1, dev)?,
            columns: Array::zeros(n, dev)?,
            values: Array::zeros(n, dev)?,
        };
        step_now(
            dev,
            &SetDiag::<B::Scalar> {
                offsets: m.offsets.device_address(),
                columns: m.columns.device_address(),
                values: m.values.device_address(),
                d: d.map_or(0, |d| d.device_address()),
                nrow: nrow as i32,
                n: n as i32,
                dim: B::ROWS as i32,
                block: (B::ROWS * B::COLS) as i32,
                scalar: PhantomData,
            },
        )?;
        Ok(m)
    }
}

/// The diagonal blocks of `a` into `out`: `out[i]` is block `(i, i)`, or zero where none is
/// stored, for `i < min(nrow, ncol)`. A thread per diagonal block (a binary search of its
/// row); blocks are copied unchanged. A [capture](crate::capture) records it.
///
/// # Errors
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::diag` when `out`
/// does not have `min(nrow, ncol)` elements, is not contiguous or overlaps the matrix;
/// [`Error::DeviceMismatch`](crate::Error::DeviceMismatch).
pub fn diag<B: SquareBlock>(a: &Bsr<B>, out: &Array<B>) -> Result<()> {
    const F: &str = "sparse::diag";
    same_device(F, "out", a.device(), out.device())?;
    contiguous(F, "out", out)?;
    let n = a.nrow.min(a.ncol);
    if out.len() != n {
        return Err(invalid(
            F,
            format!(
                "argument `out` has shape {:?} of {}, but the matrix has {}: `out` needs {n} \
                 elements",
                out.shape(),
                B::TYPE_NAME,
                a.describe()
            ),
        ));
    }
    if a.overlaps(out) {
        return Err(invalid(F, "argument `out` overlaps the matrix's arrays"));
    }
    let (m, o) = (a.clone(), out.clone());
    step(
        a.device(),
        &Diag::<B::Scalar> {
            offsets: a.offsets.device_address(),
            columns: a.columns.device_address(),
            values: a.values.device_address(),
            out: out.device_address(),
            nrow: a.nrow as i32,
            ncol: a.ncol as i32,
            cap: a.nnz_bound() as i32,
            block: (B::ROWS * B::COLS) as i32,
            scalar: PhantomData,
        },
        || Box::new((m, o)),
    )
}

/// Makes `a` the block diagonal matrix of `d` (Warp's `bsr_set_diag`): its dimensions stay,
/// its structure becomes the diagonal (every block `(i, i)`, `i < min(nrow, ncol)`, stored),
/// with new arrays (clones of the old matrix keep the old ones). `d` may be `a`'s own
/// diagonal (read by [`diag`]).
///
/// # Errors
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::set_diag` when
/// `d` does not have `min(nrow, ncol)` elements or is not contiguous;
/// [`Error::DeviceMismatch`](crate::Error::DeviceMismatch).
pub fn set_diag<B: SquareBlock>(a: &mut Bsr<B>, d: &Array<B>) -> Result<()> {
    const F: &str = "sparse::set_diag";
    same_device(F, "d", a.device(), d.device())?;
    *a = Bsr::diagonal(F, a.nrow, a.ncol, Some(d), a.device())?;
    Ok(())
}

/// `y = alpha x + beta y` (Warp's `bsr_axpy`): the result's structure is the union of both
/// structures, and each block is `alpha * x_b + beta * y_b`, computed as the triplet
/// pipeline sums `alpha x`'s blocks then `beta y`'s (each scalar product rounded, then one
/// rounded add where both have the block): the same bits on every device. `y` gets new
/// arrays (clones of the old `y` keep the old ones) with room for both matrices' blocks:
/// its capacity ([`Bsr::nnz_bound`]) becomes the sum of both capacities, whatever the union
/// holds, so in a loop of `axpy` into one `y` the capacity (and the work of the steps that
/// run over it) grows by `x`'s each call; rebuild `y` (say with [`axpy`] into a fresh
/// matrix, or [`Bsr::from_triplets`]) when that matters. Nothing is read back. `y`'s values are read whatever `beta` is (`0 * NaN` is NaN).
///
/// # Errors
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::axpy` when the
/// matrices' dimensions differ (both shapes named), `alpha` or `beta` is not finite, or the
/// two capacities together exceed `i32::MAX`; [`Error::DeviceMismatch`](crate::Error::DeviceMismatch);
/// an allocation's error (so [`Error::Capture`](crate::Error::Capture) inside a capture).
pub fn axpy<B: Block>(alpha: B::Scalar, x: &Bsr<B>, beta: B::Scalar, y: &mut Bsr<B>) -> Result<()> {
    const F: &str = "sparse::axpy";
    let dev = y.device().clone();
    same_device(F, "x", &dev, x.device())?;
    if (x.nrow, x.ncol) != (y.nrow, y.ncol) {
        return Err(invalid(
            F,
            format!(
                "`x` is {} and `y` is {}: the dimensions must be equal",
                x.describe(),
                y.describe()
            ),
        ));
    }
    finite(F, "alpha", alpha)?;
    finite(F, "beta", beta)?;
    let n = fits(
        F,
        "the two matrices' capacities together",
        x.nnz_bound() + y.nnz_bound(),
    )? as usize;
    let rows = Array::<i32>::zeros(n, &dev)?;
    let cols = Array::<i32>::zeros(n, &dev)?;
    let vals = Array::<B>::zeros(n, &dev)?;
    // counts[0]: x's block count; counts[1]: both.
    let counts = Array::<i32>::zeros(2, &dev)?;
    let t = (&rows, &cols, &vals);
    x.to_triplets(alpha.to_f64(), 0, t, addr_of(&counts, 0))?;
    y.to_triplets(beta.to_f64(), addr_of(&counts, 0), t, addr_of(&counts, 1))?;
    let count = counts.view(1..2)?;
    *y = Bsr::assemble_with(
        y.nrow,
        y.ncol,
        &rows,
        &cols,
        &vals,
        Count::Device(&count),
        false,
        &AXPY_NAMES,
        false,
    )?;
    Ok(())
}

/// `y = alpha Aᵀ x + beta y`: [`mv`](super::mv) of [`Bsr::transpose`] (so the same bits on
/// every device). Scalar `j` of block column `c` of `y` is `alpha * acc + beta * y` with
/// `acc` summed from 0 over A's blocks of column `c` in ascending block row, and in a block
/// over ascending row `i`, of `a_ij * x_i`; `y` is not read when `beta == 0`.
///
/// `x` has `nrow` elements (`B::Out`), `y` has `ncol` (`B::In`); both contiguous, on the
/// matrix's device, `y` overlapping neither `x` nor the matrix. Each call transposes the
/// matrix (a sort on the device, new arrays: not recorded by a capture; for repeated
/// products, transpose once and call [`mv`](super::mv)). A recording
/// [`Tape`](crate::Tape) records it as it records [`mv`](super::mv) (backward: `alpha A ȳ`
/// into `x`'s gradient, `alpha x_r ȳ_cᵀ` into each stored block's, `ȳ` scaled by `beta`).
///
/// # Errors
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming
/// `sparse::mv_transpose`, the argument and both shapes when a length differs; for arrays
/// that are not contiguous or overlap; [`Error::DeviceMismatch`](crate::Error::DeviceMismatch);
/// an allocation's error ([`Error::Capture`](crate::Error::Capture) inside a capture).
pub fn mv_transpose<B: Block>(
    alpha: B::Scalar,
    a: &Bsr<B>,
    x: &Array<B::Out>,
    beta: B::Scalar,
    y: &Array<B::In>,
) -> Result<()> {
    const F: &str = "sparse::mv_transpose";
    let dev = a.device();
    same_device(F, "x", dev, x.device())?;
    same_device(F, "y", dev, y.device())?;
    contiguous(F, "x", x)?;
    contiguous(F, "y", y)?;
    for (name, len, want, ty) in [
        (
            "x",
            x.len(),
            a.nrow,
            <B::Out as crate::array::Element>::TYPE_NAME,
        ),
        (
            "y",
            y.len(),
            a.ncol,
            <B::In as crate::array::Element>::TYPE_NAME,
        ),
    ] {
        if len != want {
            return Err(invalid(
                F,
                format!(
                    "argument `{name}` has {len} {ty} elements, but the matrix has {}: its \
                     transpose needs {want} {ty} elements for `{name}`",
                    a.describe()
                ),
            ));
        }
    }
    if crate::primitives::overlap(x, y) {
        return Err(invalid(F, "arguments `x` and `y` overlap in memory"));
    }
    if a.overlaps(y) {
        return Err(invalid(F, "argument `y` overlaps the matrix's arrays"));
    }
    super::mv_unrecorded(alpha, &a.transpose()?, x, beta, y)?;
    super::adjoint::record_mv(alpha.to_f64(), a, x, beta.to_f64(), y, true)
}

/// The triplet arrays of [`mm`]'s products, kept between calls.
///
/// [`MmWork::new`] sizes them on each call to the product count, which it reads back from
/// the device (one synchronisation, as Warp's `bsr_mm`). [`MmWork::with_capacity`] never
/// reads back: a product count above its capacity is a fault of `sparse::mm`, out of bounds
/// on argument `products` (index `[count]`, shape `[capacity + 1]`), returned at once on the
/// CPU, where `c` keeps its value, and reported at the next synchronisation on a GPU, where
/// the product is left empty.
#[derive(Debug)]
pub struct MmWork<B: Block> {
    fixed: Option<usize>,
    arrays: Option<(Array<i32>, Array<i32>, Array<B>)>,
}

impl<B: Block> Default for MmWork<B> {
    fn default() -> Self {
        Self::new()
    }
}

impl<B: Block> MmWork<B> {
    /// Work that grows to each product's count (read back once per [`mm`]).
    pub fn new() -> Self {
        MmWork {
            fixed: None,
            arrays: None,
        }
    }

    /// Work of room for `capacity` block products (plus `C`'s blocks when `beta != 0`),
    /// never read back; more is a fault (see [`MmWork`]).
    pub fn with_capacity(capacity: usize) -> Self {
        MmWork {
            fixed: Some(capacity),
            arrays: None,
        }
    }

    /// The triplet arrays, of at least `n` triplets on `dev`.
    fn arrays(&mut self, n: usize, dev: &Device) -> Result<(Array<i32>, Array<i32>, Array<B>)> {
        if let Some((r, c, v)) = &self.arrays {
            if v.len() >= n && v.device() == dev {
                return Ok((r.clone(), c.clone(), v.clone()));
            }
        }
        let a = (
            Array::zeros(n, dev)?,
            Array::zeros(n, dev)?,
            Array::zeros(n, dev)?,
        );
        self.arrays = Some(a.clone());
        Ok(a)
    }
}

/// `C = alpha A B + beta C` (Warp's `bsr_mm`), with one triplet per product of blocks
/// `A_rk B_kc`, fed to the triplet pipeline: the result's structure is every position some
/// product reaches (and `C`'s own when `beta != 0`); block `(r, c)` sums `alpha (A_rk B_kc)`
/// over A's blocks of row r in storage order, B's of row k in storage order, then adds `beta
/// C_rc`. Each block product's entry sums `a_im b_mj` from 0 over ascending m, each
/// operation rounded: the same bits on every device.
///
/// `C` must have `A`'s block rows and `B`'s block columns; it gets new arrays (clones of the
/// old `C` keep the old ones), of `work`'s capacity. The products' triplets live in `work`
/// (see [`MmWork`]); `mm` allocates (so it is not recorded by a capture).
///
/// ```
/// # use warp_runtime as wp;
/// use wp::sparse::{self, Bsr, MmWork};
/// let dev = wp::cpu();
/// let a = Bsr::from_triplets(
///     2,
///     2,
///     &wp::Array::from_slice(&[0, 0, 1], &dev)?,
///     &wp::Array::from_slice(&[0, 1, 1], &dev)?,
///     &wp::Array::from_slice(&[1.0f64, 2.0, 3.0], &dev)?,
/// )?; // [[1, 2], [0, 3]]
/// let at = a.transpose()?; // [[1, 0], [2, 3]]
/// let mut c = Bsr::zeros(2, 2, &dev)?;
/// sparse::mm(1.0, &at, &a, 0.0, &mut c, &mut MmWork::new())?; // A^T A
/// let d = wp::Array::<f64, 2>::zeros([2, 2], &dev)?;
/// c.to_dense(&d)?;
/// assert_eq!(d.to_vec()?, [1.0, 2.0, 2.0, 13.0]);
/// # Ok::<(), wp::Error>(())
/// ```
///
/// # Errors
/// [`Error::InvalidArgument`](crate::Error::InvalidArgument) naming `sparse::mm` when `A`'s
/// block columns differ from `B`'s block rows or `C`'s dimensions from the product's (the
/// shapes named), `alpha` or `beta` is not finite, or the product count exceeds `i32::MAX`;
/// [`Error::DeviceMismatch`](crate::Error::DeviceMismatch); with a fixed [`MmWork`], the
/// fault above.
pub fn mm<A: BlockMul<B>, B: Block<Scalar = A::Scalar>>(
    alpha: A::Scalar,
    a: &Bsr<A>,
    b: &Bsr<B>,
    beta: A::Scalar,
    c: &mut Bsr<A::Output>,
    work: &mut MmWork<A::Output>,
) -> Result<()> {
    const F: &str = "sparse::mm";
    let dev = a.device().clone();
    same_device(F, "b", &dev, b.device())?;
    same_device(F, "c", &dev, c.device())?;
    if a.ncol != b.nrow {
        return Err(invalid(
            F,
            format!(
                "`a` is {} and `b` is {}: `a`'s {} block columns must equal `b`'s {} block rows",
                a.describe(),
                b.describe(),
                a.ncol,
                b.nrow
            ),
        ));
    }
    if (c.nrow, c.ncol) != (a.nrow, b.ncol) {
        return Err(invalid(
            F,
            format!(
                "`c` is {}, but the product of `a` ({}) and `b` ({}) has {} x {} blocks",
                c.describe(),
                a.describe(),
                b.describe(),
                a.nrow,
                b.ncol
            ),
        ));
    }
    finite(F, "alpha", alpha)?;
    finite(F, "beta", beta)?;
    let with_c = beta != A::Scalar::ZERO;
    // Each row's product count, scanned in place: each row's first triplet, the total last.
    let starts = Array::<i64>::zeros(a.nrow + 1, &dev)?;
    step_now(
        &dev,
        &MmCount {
            a_offsets: a.offsets.device_address(),
            a_columns: a.columns.device_address(),
            b_offsets: b.offsets.device_address(),
            counts: starts.device_address(),
            a_nrow: a.nrow as i32,
            a_cap: a.nnz_bound() as i32,
            b_nrow: b.nrow as i32,
            b_cap: b.nnz_bound() as i32,
        },
    )?;
    array_scan_n(&starts, &starts, a.nrow + 1, false)?;
    // cells[0]: the product count (an i32 count); cells[1]: with C's blocks.
    let cells = Array::<i32>::zeros(2, &dev)?;
    step_now(
        &dev,
        &MmTotal {
            starts: starts.device_address(),
            count: cells.device_address(),
            a_nrow: a.nrow as i32,
            pad: 0,
        },
    )?;
    let n = match work.fixed {
        // Room for the products the caller named, and for C's blocks (their bound: known
        // on the host, nothing read back) when they join the products.
        Some(n) => n + if with_c { c.nnz_bound() } else { 0 },
        None => {
            let products = starts.view(a.nrow..a.nrow + 1)?.to_vec()?[0].max(0) as usize;
            let own = if with_c { c.nnz()? } else { 0 };
            products + own
        }
    };
    let n = fits(F, "the block products (and `c`'s blocks)", n)? as usize;
    let (rows, cols, vals) = work.arrays(n, &dev)?;
    // Exactly `n` triplets: the pipeline's capacity, so a count past it is its fault.
    let (rows, cols, vals) = (rows.view(0..n)?, cols.view(0..n)?, vals.view(0..n)?);
    step_now(
        &dev,
        &MmExpand::<A::Scalar> {
            a_offsets: a.offsets.device_address(),
            a_columns: a.columns.device_address(),
            a_values: a.values.device_address(),
            b_offsets: b.offsets.device_address(),
            b_columns: b.columns.device_address(),
            b_values: b.values.device_address(),
            starts: starts.device_address(),
            rows: rows.device_address(),
            cols: cols.device_address(),
            vals: vals.device_address(),
            alpha: alpha.to_f64(),
            limit: n as i64,
            a_nrow: a.nrow as i32,
            a_cap: a.nnz_bound() as i32,
            b_nrow: b.nrow as i32,
            b_cap: b.nnz_bound() as i32,
            r: A::ROWS as i32,
            k: A::COLS as i32,
            c: B::COLS as i32,
            cm_a: A::COL_MAJOR as i32,
            cm_b: B::COL_MAJOR as i32,
            cm_c: <A::Output as Block>::COL_MAJOR as i32,
            scalar: PhantomData,
        },
    )?;
    let count = if with_c {
        let t = (&rows, &cols, &vals);
        c.to_triplets(beta.to_f64(), addr_of(&cells, 0), t, addr_of(&cells, 1))?;
        cells.view(1..2)?
    } else {
        cells.view(0..1)?
    };
    *c = Bsr::assemble_with(
        a.nrow,
        b.ncol,
        &rows,
        &cols,
        &vals,
        Count::Device(&count),
        false,
        &MM_NAMES,
        false,
    )?;
    Ok(())
}

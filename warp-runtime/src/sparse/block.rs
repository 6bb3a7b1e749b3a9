//! The block types of [`Bsr`](super::Bsr) matrices and their scalars.
//!
//! A block is `ROWS x COLS` scalars of one [`SparseScalar`] (`f32` or `f64`), stored as the
//! type stores them: a scalar alone, or glam's column-major square matrices. The traits are
//! sealed: the device steps of `wp_sparse.h` are instantiated for exactly these types.

use crate::array::Element;
use glam::{DMat2, DMat3, DMat4, DVec2, DVec3, DVec4, Mat2, Mat3, Mat4, Vec2, Vec3, Vec4};

pub(crate) mod sealed {
    /// The CUDA kernels of a block type (`wp_sparse.h`'s `WP_SP_BLOCK_KERNELS` names the same).
    #[derive(Clone, Copy, Debug)]
    pub struct BlockKernels {
        /// `y = alpha A x + beta y`.
        pub mv: &'static str,
        /// The inverse of each diagonal block.
        pub jacobi_inv: &'static str,
    }

    /// The CUDA kernels of a scalar type (`WP_SP_SCALAR_KERNELS`).
    #[derive(Clone, Copy, Debug)]
    pub struct ScalarKernels {
        pub tpl_keys: &'static str,
        pub tpl_report: &'static str,
        pub tpl_sum: &'static str,
        pub dot_partials: &'static str,
        pub dot_final: &'static str,
        pub jacobi_apply: &'static str,
        pub cg_init: &'static str,
        pub cg_check: &'static str,
        pub cg_update: &'static str,
        pub cg_direction: &'static str,
    }

    /// What only this crate implements (the block types `wp_sparse.h` instantiates).
    pub trait SealedBlock {
        const KERNELS: BlockKernels;
    }

    /// The scalar types `wp_sparse.h` instantiates, and the arithmetic of the CPU steps:
    /// each operation rounds once, as the CUDA steps' `sp_add`, `sp_mul`, .. do. (Here, not
    /// in the public trait: a user importing it and `std::ops::Add` would otherwise get an
    /// ambiguous `x.add(y)`.)
    pub trait SealedScalar: Sized {
        const KERNELS: ScalarKernels;
        /// `self + b`, rounded once.
        fn add(self, b: Self) -> Self;
        /// `self - b`, rounded once.
        fn sub(self, b: Self) -> Self;
        /// `self * b`, rounded once.
        fn mul(self, b: Self) -> Self;
        /// `self / b`, rounded once.
        fn div(self, b: Self) -> Self;
    }
}

/// The scalar of a block: `f32` or `f64`. The CPU bodies of the sparse steps round each
/// operation once, as the CUDA steps do, so both backends give the same bits.
pub trait SparseScalar:
    Element + Default + Copy + PartialOrd + std::fmt::Debug + sealed::SealedScalar
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// The square root, correctly rounded.
    fn sqrt(self) -> Self;
    /// Neither NaN nor infinite.
    fn finite(self) -> bool;
    /// `x as Self` (round to nearest even, as C++'s conversion).
    fn from_f64(x: f64) -> Self;
    /// `self as f64` (exact).
    fn to_f64(self) -> f64;
}

macro_rules! scalar {
    ($t:ty, $tag:literal) => {
        impl sealed::SealedScalar for $t {
            const KERNELS: sealed::ScalarKernels = sealed::ScalarKernels {
                tpl_keys: concat!("wp_sparse_tpl_keys_", $tag),
                tpl_report: concat!("wp_sparse_tpl_report_", $tag),
                tpl_sum: concat!("wp_sparse_tpl_sum_", $tag),
                dot_partials: concat!("wp_sparse_dot_partials_", $tag),
                dot_final: concat!("wp_sparse_dot_final_", $tag),
                jacobi_apply: concat!("wp_sparse_jacobi_apply_", $tag),
                cg_init: concat!("wp_sparse_cg_init_", $tag),
                cg_check: concat!("wp_sparse_cg_check_", $tag),
                cg_update: concat!("wp_sparse_cg_update_", $tag),
                cg_direction: concat!("wp_sparse_cg_direction_", $tag),
            };
            #[inline]
            fn add(self, b: Self) -> Self {
                self + b
            }
            #[inline]
            fn sub(self, b: Self) -> Self {
                self - b
            }
            #[inline]
            fn mul(self, b: Self) -> Self {
                self * b
            }
            #[inline]
            fn div(self, b: Self) -> Self {
                self / b
            }
        }

        impl SparseScalar for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            #[inline]
            fn sqrt(self) -> Self {
                <$t>::sqrt(self)
            }
            #[inline]
            fn finite(self) -> bool {
                self.is_finite()
            }
            #[inline]
            fn from_f64(x: f64) -> Self {
                x as $t
            }
            #[inline]
            fn to_f64(self) -> f64 {
                self as f64
            }
        }
    };
}

scalar!(f32, "f32");
scalar!(f64, "f64");

/// A block of a [`Bsr`](super::Bsr) matrix: `f32`, `f64` (1 x 1), glam's `Mat2`, `Mat3`,
/// `Mat4` and `DMat2`, `DMat3`, `DMat4`.
///
/// `In` is the element of the vectors a matrix multiplies (`COLS` scalars: `Vec3` for
/// `Mat3`), `Out` the element of its products (`ROWS` scalars). The traits are sealed: the
/// steps' CUDA kernels are instantiated for these types (the non-square and spatial matrices
/// of the design come in a later slice).
///
/// # Safety
/// (For this crate, which alone implements it.) `Self` is exactly `ROWS * COLS` scalars of
/// `Scalar` in the layout `COL_MAJOR` says, `In` exactly `COLS` and `Out` `ROWS` of them.
pub unsafe trait Block: Element + Default + sealed::SealedBlock {
    /// `f32` or `f64`.
    type Scalar: SparseScalar;
    /// The element of a vector `x` in `A x` (`COLS` scalars).
    type In: Element;
    /// The element of `A x` (`ROWS` scalars).
    type Out: Element;
    /// The block of the transposed matrix ([`Bsr::transpose`](super::Bsr::transpose)):
    /// `COLS x ROWS` scalars (`Self` for a square block).
    type Transpose: Block<Scalar = Self::Scalar, In = Self::Out, Out = Self::In>;
    /// Scalar rows of a block.
    const ROWS: usize;
    /// Scalar columns of a block.
    const COLS: usize;
    /// Whether entry `(i, j)` is scalar `j * ROWS + i` (glam's matrices) rather than
    /// `i * COLS + j`.
    const COL_MAJOR: bool;
}

/// A square block (`ROWS == COLS`, `In == Out`): what the solvers and the Jacobi
/// preconditioner take.
pub trait SquareBlock: Block<In = <Self as Block>::Out> {}

/// The largest block dimension: the CPU steps size their per-row buffers by it (the macro
/// below asserts it of every block type; a larger block, as slice 2's 6 x 6, raises it).
pub(crate) const MAX_DIM: usize = 4;

macro_rules! block {
    ($t:ty, $s:ty, $in:ty, $n:literal, $cm:literal, $tag:literal) => {
        impl sealed::SealedBlock for $t {
            const KERNELS: sealed::BlockKernels = sealed::BlockKernels {
                mv: concat!("wp_sparse_bsr_mv_", $tag),
                jacobi_inv: concat!("wp_sparse_jacobi_inv_", $tag),
            };
        }

        // SAFETY: the sizes are asserted below; glam's matrices are column-major arrays of
        // their scalar (`Mat3` is 9 f32s, not `Mat3A`), its vectors arrays of it.
        unsafe impl Block for $t {
            type Scalar = $s;
            type In = $in;
            type Out = $in;
            type Transpose = $t;
            const ROWS: usize = $n;
            const COLS: usize = $n;
            const COL_MAJOR: bool = $cm;
        }

        impl SquareBlock for $t {}

        const _: () = assert!(
            std::mem::size_of::<$t>() == $n * $n * std::mem::size_of::<$s>()
                && std::mem::size_of::<$in>() == $n * std::mem::size_of::<$s>()
                && $n <= MAX_DIM
        );
    };
}

block!(f32, f32, f32, 1, false, "f32");
block!(f64, f64, f64, 1, false, "f64");
block!(Mat2, f32, Vec2, 2, true, "mat2");
block!(Mat3, f32, Vec3, 3, true, "mat3");
block!(Mat4, f32, Vec4, 4, true, "mat4");
block!(DMat2, f64, DVec2, 2, true, "dmat2");
block!(DMat3, f64, DVec3, 3, true, "dmat3");
block!(DMat4, f64, DVec4, 4, true, "dmat4");

/// Entry `(i, j)`'s scalar index in a block of `B`.
#[inline]
pub(crate) fn at<B: Block>(i: usize, j: usize) -> usize {
    if B::COL_MAJOR {
        j * B::ROWS + i
    } else {
        i * B::COLS + j
    }
}

// ------------------------------------------------------------------------------------------
// Products of blocks (slice 2: `mm`)
// ------------------------------------------------------------------------------------------

/// Blocks whose product `Self x Rhs` is a block: `Self::COLS == Rhs::ROWS`, one scalar type.
/// [`mm`](super::mm) multiplies matrices of such blocks; other pairs do not compile.
#[diagnostic::on_unimplemented(
    message = "`sparse::mm`: blocks of `{Self}` times blocks of `{Rhs}` have no product block \
               (the inner dimensions or the scalar types differ)",
    label = "no block product `{Self}` x `{Rhs}`"
)]
pub trait BlockMul<Rhs: Block>: Block {
    /// The product's block (`Self::ROWS x Rhs::COLS`).
    type Output: Block<Scalar = Self::Scalar>;
}

macro_rules! block_mul {
    ($($t:ty),*) => {
        $(impl BlockMul<$t> for $t {
            type Output = $t;
        })*
    };
}

block_mul!(f32, f64, Mat2, Mat3, Mat4, DMat2, DMat3, DMat4);

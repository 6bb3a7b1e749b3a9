//! The block types of [`Bsr`](super::Bsr) matrices and their scalars.
//!
//! A block is `ROWS x COLS` scalars of one [`SparseScalar`] (`f32` or `f64`), stored as the
//! type stores them: a scalar alone, glam's column-major square matrices, or warp-core's
//! row-major rectangular ones (`Mat23` .. `Mat64`, `DMat23` .. `DMat64`). The traits are
//! sealed: the device steps of `wp_sparse.h` and `wp_sparse_ops.h` are instantiated for
//! exactly these types.

use crate::array::Element;
use glam::{DMat2, DMat3, DMat4, DVec2, DVec3, DVec4, Mat2, Mat3, Mat4, Vec2, Vec3, Vec4};
use warp_core::{
    DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63, DMat64,
    DSpatialVector, Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63,
    Mat64, SpatialVector,
};

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
/// `Mat4` and `DMat2`, `DMat3`, `DMat4`, and the rectangular `Mat23`, `Mat24`, `Mat26`,
/// `Mat32`, .., `Mat64` with their `f64` twins `DMat23` .. `DMat64` (every shape `R x C`,
/// `R != C` in {2, 3, 4, 6}).
///
/// `In` is the element of the vectors a matrix multiplies (`COLS` scalars: `Vec3` for
/// `Mat3` and `Mat23`, `SpatialVector` for `Mat26`), `Out` the element of its products
/// (`ROWS` scalars: `Vec2` for `Mat23`). The traits are sealed: the steps' CUDA kernels are
/// instantiated for these types (the spatial matrices of the design are no block type yet).
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

/// A square block (`ROWS == COLS`, `In == Out`, its own transpose): what the solvers and the
/// Jacobi preconditioner take (a solve's adjoint solves with the transposed matrix).
pub trait SquareBlock: Block<In = <Self as Block>::Out, Transpose = Self> {}

/// The largest block dimension: the CPU steps size their per-row buffers by it (the macros
/// below assert it of every block type; slice 2's rectangular blocks have 6 rows or columns).
pub(crate) const MAX_DIM: usize = 6;

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
    ($($a:ty, $b:ty => $o:ty);* $(;)?) => {
        $(impl BlockMul<$b> for $a {
            type Output = $o;
        })*
    };
}

block_mul!(f32, f64, Mat2, Mat3, Mat4, DMat2, DMat3, DMat4);

// Every product of a rectangular block with a rectangular or square one whose result is a
// block type (not 6 x 6: the spatial matrices are no block type yet).
block_mul!(
    Mat2, Mat23 => Mat23;
    Mat2, Mat24 => Mat24;
    Mat2, Mat26 => Mat26;
    Mat23, Mat32 => Mat2;
    Mat23, Mat3 => Mat23;
    Mat23, Mat34 => Mat24;
    Mat23, Mat36 => Mat26;
    Mat24, Mat42 => Mat2;
    Mat24, Mat43 => Mat23;
    Mat24, Mat4 => Mat24;
    Mat24, Mat46 => Mat26;
    Mat26, Mat62 => Mat2;
    Mat26, Mat63 => Mat23;
    Mat26, Mat64 => Mat24;
    Mat32, Mat2 => Mat32;
    Mat32, Mat23 => Mat3;
    Mat32, Mat24 => Mat34;
    Mat32, Mat26 => Mat36;
    Mat3, Mat32 => Mat32;
    Mat3, Mat34 => Mat34;
    Mat3, Mat36 => Mat36;
    Mat34, Mat42 => Mat32;
    Mat34, Mat43 => Mat3;
    Mat34, Mat4 => Mat34;
    Mat34, Mat46 => Mat36;
    Mat36, Mat62 => Mat32;
    Mat36, Mat63 => Mat3;
    Mat36, Mat64 => Mat34;
    Mat42, Mat2 => Mat42;
    Mat42, Mat23 => Mat43;
    Mat42, Mat24 => Mat4;
    Mat42, Mat26 => Mat46;
    Mat43, Mat32 => Mat42;
    Mat43, Mat3 => Mat43;
    Mat43, Mat34 => Mat4;
    Mat43, Mat36 => Mat46;
    Mat4, Mat42 => Mat42;
    Mat4, Mat43 => Mat43;
    Mat4, Mat46 => Mat46;
    Mat46, Mat62 => Mat42;
    Mat46, Mat63 => Mat43;
    Mat46, Mat64 => Mat4;
    Mat62, Mat2 => Mat62;
    Mat62, Mat23 => Mat63;
    Mat62, Mat24 => Mat64;
    Mat63, Mat32 => Mat62;
    Mat63, Mat3 => Mat63;
    Mat63, Mat34 => Mat64;
    Mat64, Mat42 => Mat62;
    Mat64, Mat43 => Mat63;
    Mat64, Mat4 => Mat64;
    DMat2, DMat23 => DMat23;
    DMat2, DMat24 => DMat24;
    DMat2, DMat26 => DMat26;
    DMat23, DMat32 => DMat2;
    DMat23, DMat3 => DMat23;
    DMat23, DMat34 => DMat24;
    DMat23, DMat36 => DMat26;
    DMat24, DMat42 => DMat2;
    DMat24, DMat43 => DMat23;
    DMat24, DMat4 => DMat24;
    DMat24, DMat46 => DMat26;
    DMat26, DMat62 => DMat2;
    DMat26, DMat63 => DMat23;
    DMat26, DMat64 => DMat24;
    DMat32, DMat2 => DMat32;
    DMat32, DMat23 => DMat3;
    DMat32, DMat24 => DMat34;
    DMat32, DMat26 => DMat36;
    DMat3, DMat32 => DMat32;
    DMat3, DMat34 => DMat34;
    DMat3, DMat36 => DMat36;
    DMat34, DMat42 => DMat32;
    DMat34, DMat43 => DMat3;
    DMat34, DMat4 => DMat34;
    DMat34, DMat46 => DMat36;
    DMat36, DMat62 => DMat32;
    DMat36, DMat63 => DMat3;
    DMat36, DMat64 => DMat34;
    DMat42, DMat2 => DMat42;
    DMat42, DMat23 => DMat43;
    DMat42, DMat24 => DMat4;
    DMat42, DMat26 => DMat46;
    DMat43, DMat32 => DMat42;
    DMat43, DMat3 => DMat43;
    DMat43, DMat34 => DMat4;
    DMat43, DMat36 => DMat46;
    DMat4, DMat42 => DMat42;
    DMat4, DMat43 => DMat43;
    DMat4, DMat46 => DMat46;
    DMat46, DMat62 => DMat42;
    DMat46, DMat63 => DMat43;
    DMat46, DMat64 => DMat4;
    DMat62, DMat2 => DMat62;
    DMat62, DMat23 => DMat63;
    DMat62, DMat24 => DMat64;
    DMat63, DMat32 => DMat62;
    DMat63, DMat3 => DMat63;
    DMat63, DMat34 => DMat64;
    DMat64, DMat42 => DMat62;
    DMat64, DMat43 => DMat63;
    DMat64, DMat4 => DMat64;
);

// ------------------------------------------------------------------------------------------
// Rectangular blocks (slice 2): warp-core's row-major `Mat23` .. `Mat64`, `DMat23` .. `DMat64`
// ------------------------------------------------------------------------------------------

macro_rules! rect_block {
    ($($t:ident: $s:ty, $r:literal x $c:literal, in $in:ty, out $out:ty, transpose $tt:ident, $tag:literal;)*) => {
        $(
            impl sealed::SealedBlock for $t {
                const KERNELS: sealed::BlockKernels = sealed::BlockKernels {
                    // (in wp_sparse_ops.h's library: see `BsrMv`)
                    mv: concat!("wp_sparse_bsr_mv_", $tag),
                    // No Jacobi: only square blocks (`SquareBlock`) are solved.
                    jacobi_inv: "",
                };
            }

            // SAFETY: the sizes are asserted below; warp-core's non-square matrices are
            // `#[repr(C)]` rows of `$c` scalars each, no padding (row-major), its vectors
            // (glam's and the spatial vector) arrays of their scalar.
            unsafe impl Block for $t {
                type Scalar = $s;
                type In = $in;
                type Out = $out;
                type Transpose = $tt;
                const ROWS: usize = $r;
                const COLS: usize = $c;
                const COL_MAJOR: bool = false;
            }

            const _: () = assert!(
                std::mem::size_of::<$t>() == $r * $c * std::mem::size_of::<$s>()
                    && std::mem::size_of::<$in>() == $c * std::mem::size_of::<$s>()
                    && std::mem::size_of::<$out>() == $r * std::mem::size_of::<$s>()
                    && $r <= MAX_DIM
                    && $c <= MAX_DIM
            );
        )*
    };
}

rect_block! {
    Mat23: f32, 2 x 3, in Vec3, out Vec2, transpose Mat32, "mat23";
    Mat24: f32, 2 x 4, in Vec4, out Vec2, transpose Mat42, "mat24";
    Mat26: f32, 2 x 6, in SpatialVector, out Vec2, transpose Mat62, "mat26";
    Mat32: f32, 3 x 2, in Vec2, out Vec3, transpose Mat23, "mat32";
    Mat34: f32, 3 x 4, in Vec4, out Vec3, transpose Mat43, "mat34";
    Mat36: f32, 3 x 6, in SpatialVector, out Vec3, transpose Mat63, "mat36";
    Mat42: f32, 4 x 2, in Vec2, out Vec4, transpose Mat24, "mat42";
    Mat43: f32, 4 x 3, in Vec3, out Vec4, transpose Mat34, "mat43";
    Mat46: f32, 4 x 6, in SpatialVector, out Vec4, transpose Mat64, "mat46";
    Mat62: f32, 6 x 2, in Vec2, out SpatialVector, transpose Mat26, "mat62";
    Mat63: f32, 6 x 3, in Vec3, out SpatialVector, transpose Mat36, "mat63";
    Mat64: f32, 6 x 4, in Vec4, out SpatialVector, transpose Mat46, "mat64";
    DMat23: f64, 2 x 3, in DVec3, out DVec2, transpose DMat32, "dmat23";
    DMat24: f64, 2 x 4, in DVec4, out DVec2, transpose DMat42, "dmat24";
    DMat26: f64, 2 x 6, in DSpatialVector, out DVec2, transpose DMat62, "dmat26";
    DMat32: f64, 3 x 2, in DVec2, out DVec3, transpose DMat23, "dmat32";
    DMat34: f64, 3 x 4, in DVec4, out DVec3, transpose DMat43, "dmat34";
    DMat36: f64, 3 x 6, in DSpatialVector, out DVec3, transpose DMat63, "dmat36";
    DMat42: f64, 4 x 2, in DVec2, out DVec4, transpose DMat24, "dmat42";
    DMat43: f64, 4 x 3, in DVec3, out DVec4, transpose DMat34, "dmat43";
    DMat46: f64, 4 x 6, in DSpatialVector, out DVec4, transpose DMat64, "dmat46";
    DMat62: f64, 6 x 2, in DVec2, out DSpatialVector, transpose DMat26, "dmat62";
    DMat63: f64, 6 x 3, in DVec3, out DSpatialVector, transpose DMat36, "dmat63";
    DMat64: f64, 6 x 4, in DVec4, out DSpatialVector, transpose DMat46, "dmat64";
}

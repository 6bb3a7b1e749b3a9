//! Non-square matrices: `Mat23`, `Mat32`, .., `Mat63` and their `f64` twins (`DMat23`, ..),
//! NVIDIA Warp's `wp.types.matrix(shape=(R, C), dtype=float)` for every `R != C` in
//! `{2, 3, 4, 6}`.
//!
//! glam has square matrices only, and warp-core's spatial matrices are 6x6; these fill in
//! the other shapes Warp programs use (`mat23`-style Jacobians, 6x3 and 3x6 blocks of a
//! spatial matrix). A shape is named by its row and column counts: `Mat23` has 2 rows and 3
//! columns, and maps a 3-vector to a 2-vector (`m * v`).
//!
//! # Layout and design
//!
//! A matrix is a `#[repr(C)]` tuple struct of its rows, each the kernel language's own vector
//! of the column count: `Vec2`, `Vec3`, `Vec4` (glam) or a [`SpatialVector`] for six columns
//! (`f64`: `DVec*`, [`DSpatialVector`]). So its memory is Warp's row-major `mat_t<R, C>`
//! (`R * C` scalars, no padding; `f32` matrices with 4 columns are 16-byte aligned, as glam's
//! `Vec4`), it is [`bytemuck::Pod`], and a kernel's `m[i]` is a row of a type every vector
//! builtin takes. Concrete types (rather than one `Matrix<T, R, C>` with const generics) because
//! the row's type depends on the column count, and because the operators `m * s`, `m * v` and
//! `m * n` must all be `Mul` impls of one left type, which Rust's coherence only allows for
//! concrete right-hand types. The types are the kernel language's as they are Rust's: a
//! literal lane `m[(1, 2)]` in a kernel is the tuple field `m.1.z` here and `m.f1.z` in the
//! CUDA library (`wp::Mat23`, `warp-cuda/cuda/wp_matrix.h`).
//!
//! # Operations, and their order of evaluation
//!
//! Every sum is evaluated left to right in ascending index, so that the CUDA library, which
//! writes the same steps, gives the same bits where neither side contracts to FMA:
//!
//! * `a + b`, `a - b`, `-a`, `a * s`, `s * a`, `a / s`: lane by lane;
//! * `m * x` (`x` a vector of the column count): lane `i` is `Σ_k m[i][k] x[k]`;
//! * `a * b` with `a`'s column count `b`'s row count, either of them a glam square matrix or
//!   a spatial matrix too: entry `(i, j)` is `Σ_k a[i][k] b[k][j]`; the result is the
//!   matrix of that shape (`Mat23 * Mat32` is a glam `Mat2`, `Mat63 * Mat36` a
//!   `SpatialMatrix`);
//! * [`transpose`](Mat23::transpose) (a `Mat32` for a `Mat23`), `outer(a, b)` of vectors of
//!   different lengths (entry `(i, j)` is `a[i] b[j]`, shape `(len a, len b)` as Warp's),
//!   `ddot(a, b)` (`Σ a[i][j] b[i][j]`, row by row).

use core::fmt;
use core::ops::{Add, AddAssign, Div, Index, IndexMut, Mul, Neg, Sub, SubAssign};

use glam::{DMat2, DMat3, DMat4, DVec2, DVec3, DVec4, Mat2, Mat3, Mat4, Vec2, Vec3, Vec4};

use crate::spatial::{DSpatialMatrix, DSpatialVector, SpatialMatrix, SpatialVector};

/// The scalars matrices are made of: `f32`, `f64`.
pub trait MatScalar:
    Copy
    + Default
    + PartialEq
    + fmt::Debug
    + fmt::Display
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
{
    /// Whether the value is finite.
    fn finite(self) -> bool;
}
impl MatScalar for f32 {
    #[inline(always)]
    fn finite(self) -> bool {
        self.is_finite()
    }
}
impl MatScalar for f64 {
    #[inline(always)]
    fn finite(self) -> bool {
        self.is_finite()
    }
}

/// A vector as its `N` lanes (glam's float vectors, the spatial vectors).
pub trait VecLanes<S, const N: usize>: Copy {
    /// The lanes, in order.
    fn to_lanes(self) -> [S; N];
    /// The vector with lanes `a`.
    fn from_lanes(a: [S; N]) -> Self;
}

/// A matrix as its entries `[row][col]`: the non-square matrices, glam's square ones (whose
/// memory is column-major) and the spatial matrices.
pub trait RowMajor<S, const R: usize, const C: usize>: Copy {
    /// The entries, `[row][col]`.
    fn to_rc(self) -> [[S; C]; R];
    /// The matrix with entries `a[row][col]`.
    fn from_rc(a: [[S; C]; R]) -> Self;
}

/// The matrix type of shape `R x C` of a scalar: glam's `Mat2-4` for the square shapes up to
/// 4, `SpatialMatrix` for 6x6, this module's types otherwise.
pub trait Shape<const R: usize, const C: usize>: Sized {
    /// The matrix.
    type M: RowMajor<Self, R, C>;
}

/// The vector type of length `N` of a scalar: glam's `Vec2-4`, `SpatialVector` for 6.
pub trait VecOf<const N: usize>: Sized {
    /// The vector.
    type V: VecLanes<Self, N>;
}

macro_rules! vec_lanes {
    ($($v:ident: $s:ident, $n:literal);* $(;)?) => {$(
        impl VecLanes<$s, $n> for $v {
            #[inline(always)]
            fn to_lanes(self) -> [$s; $n] {
                self.to_array()
            }
            #[inline(always)]
            fn from_lanes(a: [$s; $n]) -> Self {
                $v::from_array(a)
            }
        }
        impl VecOf<$n> for $s {
            type V = $v;
        }
    )*};
}
vec_lanes!(
    Vec2: f32, 2; Vec3: f32, 3; Vec4: f32, 4; SpatialVector: f32, 6;
    DVec2: f64, 2; DVec3: f64, 3; DVec4: f64, 4; DSpatialVector: f64, 6;
);

macro_rules! square_row_major {
    ($($m:ident: $s:ident, $n:literal);* $(;)?) => {$(
        impl RowMajor<$s, $n, $n> for $m {
            #[inline(always)]
            fn to_rc(self) -> [[$s; $n]; $n] {
                core::array::from_fn(|i| core::array::from_fn(|j| self.col(j)[i]))
            }
            #[inline(always)]
            fn from_rc(a: [[$s; $n]; $n]) -> Self {
                $m::from_cols_array_2d(&core::array::from_fn(|j| core::array::from_fn(|i| a[i][j])))
            }
        }
        impl Shape<$n, $n> for $s {
            type M = $m;
        }
    )*};
}
square_row_major!(
    Mat2: f32, 2; Mat3: f32, 3; Mat4: f32, 4;
    DMat2: f64, 2; DMat3: f64, 3; DMat4: f64, 4;
);

macro_rules! spatial_row_major {
    ($($m:ident: $s:ident);*) => {$(
        impl RowMajor<$s, 6, 6> for $m {
            #[inline(always)]
            fn to_rc(self) -> [[$s; 6]; 6] {
                self.to_rows_array()
            }
            #[inline(always)]
            fn from_rc(a: [[$s; 6]; 6]) -> Self {
                $m::from_rows_array(a)
            }
        }
        impl Shape<6, 6> for $s {
            type M = $m;
        }
    )*};
}
spatial_row_major!(SpatialMatrix: f32; DSpatialMatrix: f64);

/// `a * b` of entry arrays: entry `(i, j)` is `Σ_k a[i][k] b[k][j]`, `k` ascending.
#[inline(always)]
pub fn matmul<S: MatScalar, const R: usize, const K: usize, const C: usize>(
    a: [[S; K]; R],
    b: [[S; C]; K],
) -> [[S; C]; R] {
    core::array::from_fn(|i| {
        core::array::from_fn(|j| {
            let mut acc = a[i][0] * b[0][j];
            for k in 1..K {
                acc += a[i][k] * b[k][j];
            }
            acc
        })
    })
}

/// `m * x`: lane `i` is `Σ_k m[i][k] x[k]`, `k` ascending.
#[inline(always)]
pub fn matvec<S: MatScalar, const R: usize, const C: usize>(m: [[S; C]; R], x: [S; C]) -> [S; R] {
    core::array::from_fn(|i| {
        let mut acc = m[i][0] * x[0];
        for k in 1..C {
            acc += m[i][k] * x[k];
        }
        acc
    })
}

/// The transpose of an entry array.
#[inline(always)]
pub fn transpose_rc<S: Copy, const R: usize, const C: usize>(m: [[S; C]; R]) -> [[S; R]; C] {
    core::array::from_fn(|j| core::array::from_fn(|i| m[i][j]))
}

/// Declares one non-square matrix type: its rows' type (the vector of the column count),
/// the vector `m * x` returns (of the row count), its transpose's type and its entries.
macro_rules! nonsquare {
    (
        $(#[$doc:meta])*
        $m:ident { $($rn:ident: $rf:ident),+ }, $s:ident, $r:literal x $c:literal,
        row: $rt:ident, col: $vr:ident, transpose: $t:ident
    ) => {
        $(#[$doc])*
        #[repr(C)]
        #[derive(Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $m($(pub $rf),+);

        impl $m {
            /// Every entry zero.
            pub const ZERO: Self = Self($($rf::ZERO),+);

            /// The matrix with these rows (`Mat23::from_rows(r0, r1)` in kernels too).
            #[inline(always)]
            pub const fn from_rows($($rn: $rf),+) -> Self {
                Self($($rn),+)
            }

            /// The matrix with the rows of `r`.
            #[inline(always)]
            pub fn from_row_array(r: [$rt; $r]) -> Self {
                bytemuck::cast(r)
            }

            /// The rows.
            #[inline(always)]
            pub fn to_rows(self) -> [$rt; $r] {
                bytemuck::cast(self)
            }

            /// The matrix with entries `a[row][col]` (Warp's scalar constructor, in its
            /// row-major order).
            #[inline]
            pub fn from_rows_array(a: [[$s; $c]; $r]) -> Self {
                Self::from_row_array(a.map(<$rt as VecLanes<$s, $c>>::from_lanes))
            }

            /// The entries, `[row][col]`.
            #[inline]
            pub fn to_rows_array(self) -> [[$s; $c]; $r] {
                self.to_rows().map(<$rt as VecLanes<$s, $c>>::to_lanes)
            }

            /// Row `i` (panics past the last row).
            #[inline]
            pub fn row(self, i: usize) -> $rt {
                self.to_rows()[i]
            }

            /// Column `j` (panics past the last column).
            #[inline]
            pub fn col(self, j: usize) -> $vr {
                <$vr as VecLanes<$s, $r>>::from_lanes(self.to_rows_array().map(|r| r[j]))
            }

            /// The transpose.
            #[inline]
            pub fn transpose(self) -> $t {
                $t::from_rows_array(transpose_rc(self.to_rows_array()))
            }

            /// Whether every entry is finite.
            #[inline]
            pub fn is_finite(self) -> bool {
                self.to_rows_array().iter().flatten().all(|x| x.is_finite())
            }

            #[inline(always)]
            fn map(self, f: impl Fn($s) -> $s) -> Self {
                Self::from_rows_array(self.to_rows_array().map(|r| r.map(&f)))
            }

            #[inline(always)]
            fn zip(self, b: Self, f: impl Fn($s, $s) -> $s) -> Self {
                let (a, b) = (self.to_rows_array(), b.to_rows_array());
                Self::from_rows_array(core::array::from_fn(|i| {
                    core::array::from_fn(|j| f(a[i][j], b[i][j]))
                }))
            }
        }

        impl RowMajor<$s, $r, $c> for $m {
            #[inline(always)]
            fn to_rc(self) -> [[$s; $c]; $r] {
                self.to_rows_array()
            }
            #[inline(always)]
            fn from_rc(a: [[$s; $c]; $r]) -> Self {
                Self::from_rows_array(a)
            }
        }
        impl Shape<$r, $c> for $s {
            type M = $m;
        }

        impl Index<usize> for $m {
            type Output = $rt;
            /// Row `i` (panics past the last row).
            #[inline]
            fn index(&self, i: usize) -> &$rt {
                &bytemuck::cast_ref::<$m, [$rt; $r]>(self)[i]
            }
        }
        impl IndexMut<usize> for $m {
            #[inline]
            fn index_mut(&mut self, i: usize) -> &mut $rt {
                &mut bytemuck::cast_mut::<$m, [$rt; $r]>(self)[i]
            }
        }
        impl Index<(usize, usize)> for $m {
            type Output = $s;
            /// Entry `(row, col)`.
            #[inline]
            fn index(&self, (i, j): (usize, usize)) -> &$s {
                &bytemuck::cast_ref::<$m, [[$s; $c]; $r]>(self)[i][j]
            }
        }
        impl IndexMut<(usize, usize)> for $m {
            #[inline]
            fn index_mut(&mut self, (i, j): (usize, usize)) -> &mut $s {
                &mut bytemuck::cast_mut::<$m, [[$s; $c]; $r]>(self)[i][j]
            }
        }

        impl fmt::Debug for $m {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}({:?})", stringify!($m), self.to_rows_array())
            }
        }
        impl fmt::Display for $m {
            /// `[[a, b, c], [d, e, f]]`: the rows.
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("[")?;
                for (i, r) in self.to_rows_array().iter().enumerate() {
                    if i > 0 {
                        f.write_str(", ")?;
                    }
                    f.write_str("[")?;
                    for (j, x) in r.iter().enumerate() {
                        if j > 0 {
                            f.write_str(", ")?;
                        }
                        write!(f, "{x}")?;
                    }
                    f.write_str("]")?;
                }
                f.write_str("]")
            }
        }

        impl Add for $m {
            type Output = $m;
            #[inline]
            fn add(self, b: $m) -> $m {
                self.zip(b, |x, y| x + y)
            }
        }
        impl Sub for $m {
            type Output = $m;
            #[inline]
            fn sub(self, b: $m) -> $m {
                self.zip(b, |x, y| x - y)
            }
        }
        impl Neg for $m {
            type Output = $m;
            #[inline]
            fn neg(self) -> $m {
                self.map(|x| -x)
            }
        }
        impl Mul<$s> for $m {
            type Output = $m;
            #[inline]
            fn mul(self, s: $s) -> $m {
                self.map(|x| x * s)
            }
        }
        impl Mul<$m> for $s {
            type Output = $m;
            /// `s * a[i][j]` lane by lane.
            #[inline]
            fn mul(self, a: $m) -> $m {
                a.map(|x| self * x)
            }
        }
        impl Div<$s> for $m {
            type Output = $m;
            #[inline]
            fn div(self, s: $s) -> $m {
                self.map(|x| x / s)
            }
        }
        impl Mul<$rt> for $m {
            type Output = $vr;
            /// Lane `i` is `Σ_k self[i][k] x[k]`.
            #[inline]
            fn mul(self, x: $rt) -> $vr {
                <$vr as VecLanes<$s, $r>>::from_lanes(matvec(self.to_rows_array(), x.to_lanes()))
            }
        }
        impl AddAssign for $m {
            #[inline]
            fn add_assign(&mut self, b: $m) {
                *self = *self + b;
            }
        }
        impl SubAssign for $m {
            #[inline]
            fn sub_assign(&mut self, b: $m) {
                *self = *self - b;
            }
        }

        // A literal of a matrix (what `lit_like` makes where the macro cannot see a value's
        // type) is every entry, as a spatial matrix's.
        impl crate::ops::FromLiteral for $m {
            #[inline(always)]
            fn from_f64(v: f64) -> Self {
                Self::from_rows_array([[v as $s; $c]; $r])
            }
            #[inline(always)]
            fn from_i64(v: i64) -> Self {
                Self::from_rows_array([[v as $s; $c]; $r])
            }
        }

        // Gradients of arrays of them: every entry adds atomically on its own.
        impl crate::grad::GradElement for $m {
            #[inline(always)]
            unsafe fn grad_add(ptr: *mut Self, v: Self) {
                let base = ptr as *mut $s;
                for (k, x) in v.to_rows_array().iter().flatten().enumerate() {
                    // SAFETY: entry k of a live, aligned element (forwarded contract); the
                    // type is R * C consecutive scalars.
                    unsafe { <$s as crate::grad::GradElement>::grad_add(base.add(k), *x) };
                }
            }
        }

        impl crate::func_grad::GradSeed for $m {
            #[inline(always)]
            fn grad_seed() -> Self {
                Self::from_rows_array([[1.0; $c]; $r])
            }
        }

        const _: () = {
            assert!(core::mem::size_of::<$m>() == $r * $c * core::mem::size_of::<$s>());
        };
    };
}

// The shapes: every R x C with R != C in {2, 3, 4, 6}, f32 then f64.
nonsquare!(
    /// A 2x3 matrix in `f32` (Warp's `mat23`-style `matrix(shape=(2, 3))`): two `Vec3` rows.
    ///
    /// ```
    /// use warp_core::Mat23;
    /// use glam::{Vec2, Vec3};
    /// let m = Mat23::from_rows(Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0));
    /// assert_eq!(m * Vec3::ONE, Vec2::new(6.0, 15.0));
    /// assert_eq!(m[(1, 2)], 6.0);
    /// assert_eq!(m.transpose().row(2), Vec2::new(3.0, 6.0));
    /// ```
    Mat23 { r0: Vec3, r1: Vec3 }, f32, 2 x 3, row: Vec3, col: Vec2, transpose: Mat32
);
nonsquare!(
    /// A 2x4 matrix in `f32`: two `Vec4` rows.
    Mat24 { r0: Vec4, r1: Vec4 }, f32, 2 x 4, row: Vec4, col: Vec2, transpose: Mat42
);
nonsquare!(
    /// A 2x6 matrix in `f32`: two `SpatialVector` rows.
    Mat26 { r0: SpatialVector, r1: SpatialVector }, f32, 2 x 6, row: SpatialVector, col: Vec2, transpose: Mat62
);
nonsquare!(
    /// A 3x2 matrix in `f32`: three `Vec2` rows.
    Mat32 { r0: Vec2, r1: Vec2, r2: Vec2 }, f32, 3 x 2, row: Vec2, col: Vec3, transpose: Mat23
);
nonsquare!(
    /// A 3x4 matrix in `f32`: three `Vec4` rows.
    Mat34 { r0: Vec4, r1: Vec4, r2: Vec4 }, f32, 3 x 4, row: Vec4, col: Vec3, transpose: Mat43
);
nonsquare!(
    /// A 3x6 matrix in `f32`: three `SpatialVector` rows.
    Mat36 { r0: SpatialVector, r1: SpatialVector, r2: SpatialVector }, f32, 3 x 6,
    row: SpatialVector, col: Vec3, transpose: Mat63
);
nonsquare!(
    /// A 4x2 matrix in `f32`: four `Vec2` rows.
    Mat42 { r0: Vec2, r1: Vec2, r2: Vec2, r3: Vec2 }, f32, 4 x 2, row: Vec2, col: Vec4, transpose: Mat24
);
nonsquare!(
    /// A 4x3 matrix in `f32`: four `Vec3` rows.
    Mat43 { r0: Vec3, r1: Vec3, r2: Vec3, r3: Vec3 }, f32, 4 x 3, row: Vec3, col: Vec4, transpose: Mat34
);
nonsquare!(
    /// A 4x6 matrix in `f32`: four `SpatialVector` rows.
    Mat46 { r0: SpatialVector, r1: SpatialVector, r2: SpatialVector, r3: SpatialVector },
    f32, 4 x 6, row: SpatialVector, col: Vec4, transpose: Mat64
);
nonsquare!(
    /// A 6x2 matrix in `f32`: six `Vec2` rows.
    Mat62 { r0: Vec2, r1: Vec2, r2: Vec2, r3: Vec2, r4: Vec2, r5: Vec2 }, f32, 6 x 2,
    row: Vec2, col: SpatialVector, transpose: Mat26
);
nonsquare!(
    /// A 6x3 matrix in `f32` (Warp's `matrix(shape=(6, 3))`): six `Vec3` rows.
    Mat63 { r0: Vec3, r1: Vec3, r2: Vec3, r3: Vec3, r4: Vec3, r5: Vec3 }, f32, 6 x 3,
    row: Vec3, col: SpatialVector, transpose: Mat36
);
nonsquare!(
    /// A 6x4 matrix in `f32`: six `Vec4` rows.
    Mat64 { r0: Vec4, r1: Vec4, r2: Vec4, r3: Vec4, r4: Vec4, r5: Vec4 }, f32, 6 x 4,
    row: Vec4, col: SpatialVector, transpose: Mat46
);
nonsquare!(
    /// A 2x3 matrix in `f64`: two `DVec3` rows.
    DMat23 { r0: DVec3, r1: DVec3 }, f64, 2 x 3, row: DVec3, col: DVec2, transpose: DMat32
);
nonsquare!(
    /// A 2x4 matrix in `f64`.
    DMat24 { r0: DVec4, r1: DVec4 }, f64, 2 x 4, row: DVec4, col: DVec2, transpose: DMat42
);
nonsquare!(
    /// A 2x6 matrix in `f64`.
    DMat26 { r0: DSpatialVector, r1: DSpatialVector }, f64, 2 x 6, row: DSpatialVector, col: DVec2,
    transpose: DMat62
);
nonsquare!(
    /// A 3x2 matrix in `f64`.
    DMat32 { r0: DVec2, r1: DVec2, r2: DVec2 }, f64, 3 x 2, row: DVec2, col: DVec3, transpose: DMat23
);
nonsquare!(
    /// A 3x4 matrix in `f64`.
    DMat34 { r0: DVec4, r1: DVec4, r2: DVec4 }, f64, 3 x 4, row: DVec4, col: DVec3, transpose: DMat43
);
nonsquare!(
    /// A 3x6 matrix in `f64`.
    DMat36 { r0: DSpatialVector, r1: DSpatialVector, r2: DSpatialVector }, f64, 3 x 6,
    row: DSpatialVector, col: DVec3, transpose: DMat63
);
nonsquare!(
    /// A 4x2 matrix in `f64`.
    DMat42 { r0: DVec2, r1: DVec2, r2: DVec2, r3: DVec2 }, f64, 4 x 2, row: DVec2, col: DVec4,
    transpose: DMat24
);
nonsquare!(
    /// A 4x3 matrix in `f64`.
    DMat43 { r0: DVec3, r1: DVec3, r2: DVec3, r3: DVec3 }, f64, 4 x 3, row: DVec3, col: DVec4,
    transpose: DMat34
);
nonsquare!(
    /// A 4x6 matrix in `f64`.
    DMat46 { r0: DSpatialVector, r1: DSpatialVector, r2: DSpatialVector, r3: DSpatialVector },
    f64, 4 x 6, row: DSpatialVector, col: DVec4, transpose: DMat64
);
nonsquare!(
    /// A 6x2 matrix in `f64`.
    DMat62 { r0: DVec2, r1: DVec2, r2: DVec2, r3: DVec2, r4: DVec2, r5: DVec2 }, f64, 6 x 2,
    row: DVec2, col: DSpatialVector, transpose: DMat26
);
nonsquare!(
    /// A 6x3 matrix in `f64` (Warp's `matrix(shape=(6, 3), dtype=float64)`).
    DMat63 { r0: DVec3, r1: DVec3, r2: DVec3, r3: DVec3, r4: DVec3, r5: DVec3 }, f64, 6 x 3,
    row: DVec3, col: DSpatialVector, transpose: DMat36
);
nonsquare!(
    /// A 6x4 matrix in `f64`.
    DMat64 { r0: DVec4, r1: DVec4, r2: DVec4, r3: DVec4, r4: DVec4, r5: DVec4 }, f64, 6 x 4,
    row: DVec4, col: DSpatialVector, transpose: DMat46
);

/// The products of one left type with a list of right types of its column count `$k`:
/// `Mul` here, `AdjMul` in `adjoint/matrix.rs` (the same list, through
/// [`for_each_product`]).
macro_rules! mul_impls {
    ($s:ident, $k:literal, $l:ident, $r:literal; [$($b:ident: $c:literal),*]) => {$(
        impl Mul<$b> for $l {
            type Output = <$s as Shape<$r, $c>>::M;
            /// Entry `(i, j)` is `Σ_k self[i][k] b[k][j]`, `k` ascending.
            #[inline]
            fn mul(self, b: $b) -> Self::Output {
                RowMajor::from_rc(matmul::<$s, $r, $k, $c>(
                    <$l as RowMajor<$s, $r, $k>>::to_rc(self),
                    <$b as RowMajor<$s, $k, $c>>::to_rc(b),
                ))
            }
        }
    )*};
}

/// Calls `$mac!(scalar, k, Left, rows; [Right: cols, ..])` for every matrix product of the
/// kernel language that involves a non-square matrix: per inner dimension `k`, each
/// non-square left type of `k` columns with every right type of `k` rows, and the square
/// type of size `k` with the non-square right types (square times square is glam's or the
/// spatial matrices' own).
macro_rules! for_each_product {
    ($mac:ident) => {
        for_each_product!(@k $mac, f32, 2, [Mat32: 3, Mat42: 4, Mat62: 6], Mat2,
            [Mat23: 3, Mat24: 4, Mat26: 6]);
        for_each_product!(@k $mac, f32, 3, [Mat23: 2, Mat43: 4, Mat63: 6], Mat3,
            [Mat32: 2, Mat34: 4, Mat36: 6]);
        for_each_product!(@k $mac, f32, 4, [Mat24: 2, Mat34: 3, Mat64: 6], Mat4,
            [Mat42: 2, Mat43: 3, Mat46: 6]);
        for_each_product!(@k $mac, f32, 6, [Mat26: 2, Mat36: 3, Mat46: 4], SpatialMatrix,
            [Mat62: 2, Mat63: 3, Mat64: 4]);
        for_each_product!(@k $mac, f64, 2, [DMat32: 3, DMat42: 4, DMat62: 6], DMat2,
            [DMat23: 3, DMat24: 4, DMat26: 6]);
        for_each_product!(@k $mac, f64, 3, [DMat23: 2, DMat43: 4, DMat63: 6], DMat3,
            [DMat32: 2, DMat34: 4, DMat36: 6]);
        for_each_product!(@k $mac, f64, 4, [DMat24: 2, DMat34: 3, DMat64: 6], DMat4,
            [DMat42: 2, DMat43: 3, DMat46: 6]);
        for_each_product!(@k $mac, f64, 6, [DMat26: 2, DMat36: 3, DMat46: 4], DSpatialMatrix,
            [DMat62: 2, DMat63: 3, DMat64: 4]);
    };
    (@k $mac:ident, $s:ident, $k:literal, [$($l:ident: $r:literal),*], $sq:ident,
        $rights:tt) => {
        $(
            $mac!($s, $k, $l, $r; [$sq: $k]);
            $mac!($s, $k, $l, $r; $rights);
        )*
        $mac!($s, $k, $sq, $k; $rights);
    };
}
pub(crate) use for_each_product;

for_each_product!(mul_impls);

/// Calls `$mac!(scalar, A: n, [B: m, ..])` for every pair of vector types of different
/// lengths (`outer(a, b)` of them is a non-square matrix).
macro_rules! for_each_outer {
    ($mac:ident) => {
        $mac!(f32, Vec2: 2, [Vec3: 3, Vec4: 4, SpatialVector: 6]);
        $mac!(f32, Vec3: 3, [Vec2: 2, Vec4: 4, SpatialVector: 6]);
        $mac!(f32, Vec4: 4, [Vec2: 2, Vec3: 3, SpatialVector: 6]);
        $mac!(f32, SpatialVector: 6, [Vec2: 2, Vec3: 3, Vec4: 4]);
        $mac!(f64, DVec2: 2, [DVec3: 3, DVec4: 4, DSpatialVector: 6]);
        $mac!(f64, DVec3: 3, [DVec2: 2, DVec4: 4, DSpatialVector: 6]);
        $mac!(f64, DVec4: 4, [DVec2: 2, DVec3: 3, DSpatialVector: 6]);
        $mac!(f64, DSpatialVector: 6, [DVec2: 2, DVec3: 3, DVec4: 4]);
    };
}
pub(crate) use for_each_outer;

/// Every non-square type with its scalar and shape: `$mac!(M, scalar, rows, cols)`.
macro_rules! for_each_nonsquare {
    ($mac:ident) => {
        $mac!(
            Mat23, f32, 2, 3; Mat24, f32, 2, 4; Mat26, f32, 2, 6; Mat32, f32, 3, 2;
            Mat34, f32, 3, 4; Mat36, f32, 3, 6; Mat42, f32, 4, 2; Mat43, f32, 4, 3;
            Mat46, f32, 4, 6; Mat62, f32, 6, 2; Mat63, f32, 6, 3; Mat64, f32, 6, 4;
            DMat23, f64, 2, 3; DMat24, f64, 2, 4; DMat26, f64, 2, 6; DMat32, f64, 3, 2;
            DMat34, f64, 3, 4; DMat36, f64, 3, 6; DMat42, f64, 4, 2; DMat43, f64, 4, 3;
            DMat46, f64, 4, 6; DMat62, f64, 6, 2; DMat63, f64, 6, 3; DMat64, f64, 6, 4
        );
    };
}
pub(crate) use for_each_nonsquare;

// The builtins of the "linalg" section that take non-square matrices (warp-core `builtins`'
// generic `transpose`, `ddot` and `outer` dispatch through these traits).
macro_rules! builtin_impls {
    ($($m:ident, $s:ident, $r:literal, $c:literal);* $(;)?) => {$(
        impl crate::builtins::Transpose for $m {
            type T = <$s as Shape<$c, $r>>::M;
            #[inline(always)]
            fn w_transposed(self) -> Self::T {
                self.transpose()
            }
        }
        impl crate::builtins::Ddot for $m {
            type S = $s;
            /// `Σ a[i][j] b[i][j]`, row by row, left to right.
            #[inline(always)]
            fn w_ddot_of(self, b: Self) -> $s {
                let (a, b) = (self.to_rows_array(), b.to_rows_array());
                let mut acc = a[0][0] * b[0][0];
                for k in 1..$r * $c {
                    acc += a[k / $c][k % $c] * b[k / $c][k % $c];
                }
                acc
            }
        }
        impl crate::local_array::Lanes for $m {
            type Lane = <$s as VecOf<$c>>::V;
            #[inline(always)]
            fn lanes(&self) -> &[Self::Lane] {
                bytemuck::cast_ref::<$m, [Self::Lane; $r]>(self)
            }
            #[inline(always)]
            fn lanes_mut(&mut self) -> &mut [Self::Lane] {
                bytemuck::cast_mut::<$m, [Self::Lane; $r]>(self)
            }
        }
    )*};
}
for_each_nonsquare!(builtin_impls);

/// `outer(a, b)` of vectors of different lengths: entry `(i, j)` is `a[i] b[j]`.
macro_rules! outer_impls {
    ($s:ident, $a:ident: $n:literal, [$($b:ident: $m:literal),*]) => {$(
        impl crate::builtins::Outer<$b> for $a {
            type Mat = <$s as Shape<$n, $m>>::M;
            #[inline(always)]
            fn w_outer_of(self, b: $b) -> Self::Mat {
                let (x, y) = (self.to_lanes(), b.to_lanes());
                RowMajor::from_rc(core::array::from_fn(|i| core::array::from_fn(|j| x[i] * y[j])))
            }
        }
    )*};
}
for_each_outer!(outer_impls);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_rows_and_indexing() {
        let m = Mat23::from_rows_array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
        assert_eq!(
            bytemuck::cast::<_, [f32; 6]>(m),
            [1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
            "row-major"
        );
        assert_eq!(m[1], Vec3::new(4.0, 5.0, 6.0));
        assert_eq!(m[(0, 2)], 3.0);
        assert_eq!(m.1.z, 6.0);
        assert_eq!(m.col(1), Vec2::new(2.0, 5.0));
        let mut n = m;
        n[(1, 0)] = -1.0;
        n[0] = Vec3::ZERO;
        assert_eq!(n.to_rows_array(), [[0.0, 0.0, 0.0], [-1.0, 5.0, 6.0]]);
        assert_eq!(format!("{m}"), "[[1, 2, 3], [4, 5, 6]]");
        assert_eq!(Mat23::default(), Mat23::ZERO);
        assert_eq!(core::mem::align_of::<Mat24>(), 16, "Vec4 rows");
        assert_eq!(core::mem::size_of::<Mat63>(), 72);
        assert_eq!(core::mem::size_of::<DMat36>(), 144);
        assert!(m.is_finite() && !(m * f32::NAN).is_finite());
    }

    #[test]
    fn products_match_the_definitions() {
        let a = DMat23::from_rows_array([[1.0, -2.0, 0.5], [3.0, 0.25, -1.5]]);
        let b = DMat32::from_rows_array([[0.3, 0.7], [-1.1, 2.0], [-0.5, 0.9]]);
        let ab: DMat2 = a * b;
        for i in 0..2 {
            for j in 0..2 {
                let want: f64 = (0..3).map(|k| a[(i, k)] * b[(k, j)]).sum();
                assert!((ab.col(j)[i] - want).abs() < 1e-15);
            }
        }
        // Square glam on either side: glam's column-major entries.
        let s = DMat3::from_cols_array(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.5]);
        let as_: DMat23 = a * s;
        let sb: DMat32 = s * b;
        for i in 0..2 {
            for j in 0..3 {
                let want: f64 = (0..3).map(|k| a[(i, k)] * s.col(j)[k]).sum();
                assert!((as_[(i, j)] - want).abs() < 1e-14);
            }
        }
        assert!(
            ((sb.transpose() - b.transpose() * s.transpose()).to_rows_array())
                .iter()
                .flatten()
                .all(|e| e.abs() < 1e-14)
        );
        // (a b) x = a (b x); transpose round trip; 6x3 times 3x6 is a spatial matrix.
        let x = DVec2::new(0.4, -0.7);
        let (l, r) = ((a * b) * x, a * (b * x));
        assert!((l - r).length() < 1e-14);
        assert_eq!(a.transpose().transpose(), a);
        let m63 = DMat63::from_rows_array(core::array::from_fn(|i| {
            core::array::from_fn(|j| (i * 3 + j) as f64)
        }));
        let sm: DSpatialMatrix = m63 * m63.transpose();
        assert_eq!(
            sm[(2, 5)],
            (6..9).zip(15..18).map(|(p, q)| (p * q) as f64).sum()
        );
        assert_eq!((a * 2.0) / 2.0, a);
        assert_eq!(2.0 * a, a + a);
        assert_eq!(-a + a, DMat23::ZERO);
    }
}

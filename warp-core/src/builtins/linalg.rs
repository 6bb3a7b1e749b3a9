//! Vector, matrix and quaternion builtins (CPU side of the table's "linalg" section).
//!
//! Where glam has the operation with the meaning Warp gives it, the builtin calls glam
//! (`transpose`, `determinant`, `inverse`, `Mat3::from_quat`, `Quat::from_axis_angle`,
//! `Quat::from_mat3`, `q * v`, `conjugate`), and the CUDA library reproduces glam's
//! evaluation order (for `Mat2`, `Mat4` and `Quat` the order of glam's SSE2 code, lane by
//! lane), so both backends agree bit for bit on the same IEEE arithmetic. Where glam has no
//! such method, or its meaning differs from Warp's, the order is written here:
//!
//! * `length_sq(v) = dot(v, v)` (left to right, wrapping for integer vectors);
//! * `outer(a, b) = a bᵀ`: column `j` is `a * b[j]` (exact products, no sums);
//! * `cw_mul`, `cw_div`: componentwise `*` and `/` (vectors: glam's `*`, `/`; matrices column
//!   by column);
//! * `trace(m) = m00 + m11 (+ m22 (+ m33))`, left to right;
//! * `ddot(a, b)`: the sum of `a[k] * b[k]` over the lanes in column-major order, left to right;
//! * `diag(v)`: `Mat::from_diagonal(v)`; `skew(v)`: the matrix with `skew(v) * w == cross(v, w)`
//!   (columns `(0, z, -y)`, `(-z, 0, x)`, `(y, -x, 0)`);
//! * `inverse(m)`: the zero matrix when `determinant(m) == 0` (Warp's rule: its `kEps` is 0),
//!   else glam's `inverse` (so a NaN determinant gives NaNs, as glam does). glam alone would
//!   give infinities and NaNs for a singular matrix;
//! * quaternion `dot`, `length`, `length_sq`: lanes `x, y, z, w` left to right (as vectors,
//!   not glam's SIMD order); `normalize(q)` is `q / length(q)` lane by lane, or the identity
//!   quaternion when the length is not positive (Warp's rule; glam gives NaN); `length` and
//!   `normalize` scale by a power of two first, as the vectors' do (`builtins/norm.rs`);
//! * `inverse(q)` and `quat_inverse(q)`: the conjugate `(-x, -y, -z, w)` (Warp and glam: exact
//!   for unit quaternions, no normalization);
//! * `quat_rotate(q, v)` is glam's `q * v`, `quat_rotate_inv(q, v)` is `conjugate(q) * v`: for
//!   a non-unit `q` both scale by `|q|²` (Warp's formula assumes a unit `q` instead);
//! * `quat_to_matrix(q)` is glam's `Mat3::from_quat` (exact for unit `q`);
//! * `quat_from_matrix(m)` is glam's `Quat::from_mat3` (DirectXMath's branch on the diagonal,
//!   not normalized afterwards; Warp normalizes and may return `-q` for the same rotation);
//! * `quat_from_axis_angle(axis, angle)`: `(axis * sin(angle/2), cos(angle/2))`, glam's (the
//!   axis is not normalized, as in Warp);
//! * `quat_slerp(q0, q1, t)`: Warp's definition `q0 * from_axis_angle(axis, t * angle)` where
//!   `(axis, angle)` is the axis-angle of `conjugate(q0) * q1` (`axis = ±normalize(xyz)`, the
//!   sign of `w`; `angle = 2 atan2(length(xyz), |w|)`), so it takes the short path and
//!   `slerp(q, q, t) == q` when `conjugate(q) * q` has a zero vector part. glam's `slerp`
//!   uses an approximate `acos` and SIMD `sin`, which a GPU could not reproduce.

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, Mat2, Mat3, Mat4, Quat, Vec2, Vec3, Vec4,
};

use super::math::{Float, FloatVec, Signed, VecOps};

// ------------------------------------------------------------------------------------------
// Traits
// ------------------------------------------------------------------------------------------

/// Float vectors and their square matrices (`outer`, `diag`): `Vec2-4`, `DVec2-4`.
pub trait VecMat: Copy {
    /// The square matrix of the vector's size and scalar.
    type Mat: Copy;
    /// `self bᵀ`.
    fn w_outer(self, b: Self) -> Self::Mat;
    /// The diagonal matrix with diagonal `self`.
    fn w_diag(self) -> Self::Mat;
}

/// Componentwise `*` and `/`: float vectors and matrices.
pub trait Cw: Copy {
    /// `self[k] * b[k]` per lane.
    fn w_cw_mul(self, b: Self) -> Self;
    /// `self[k] / b[k]` per lane.
    fn w_cw_div(self, b: Self) -> Self;
}

/// Square float matrices: `Mat2-4`, `DMat2-4`.
pub trait SquareMat: Copy {
    /// The scalar.
    type S: Float;
    /// The transpose (glam's).
    fn w_transpose(self) -> Self;
    /// The determinant (glam's).
    fn w_determinant(self) -> Self::S;
    /// The sum of the diagonal, left to right.
    fn w_trace(self) -> Self::S;
    /// The sum of the lane products, column-major, left to right.
    fn w_ddot(self, b: Self) -> Self::S;
}

/// `inverse`: matrices (zero when singular) and quaternions (the conjugate).
pub trait Inverse: Copy {
    /// The inverse.
    fn w_inverse(self) -> Self;
}

/// `skew`: `Vec3`, `DVec3`.
pub trait Skew: Copy {
    /// The 3x3 matrix type.
    type Mat: Copy;
    /// The cross-product matrix of `self`.
    fn w_skew(self) -> Self::Mat;
}

/// The quaternion builtins: `Quat`, `DQuat`.
pub trait QuatOps: Copy {
    /// The scalar.
    type S: Float;
    /// The 3-vector.
    type V3: Copy;
    /// The 3x3 matrix.
    type M3: Copy;
    /// `(axis * sin(angle/2), cos(angle/2))`.
    fn w_from_axis_angle(axis: Self::V3, angle: Self::S) -> Self;
    /// glam's `q * v`.
    fn w_rotate(self, v: Self::V3) -> Self::V3;
    /// `conjugate(q) * v`.
    fn w_rotate_inv(self, v: Self::V3) -> Self::V3;
    /// The conjugate.
    fn w_conjugate(self) -> Self;
    /// glam's `Mat3::from_quat`.
    fn w_to_matrix(self) -> Self::M3;
    /// glam's `Quat::from_mat3`.
    fn w_from_matrix(m: Self::M3) -> Self;
    /// Warp's slerp (see the module documentation).
    fn w_slerp(self, q1: Self, t: Self::S) -> Self;
}

// ------------------------------------------------------------------------------------------
// Public builtins
// ------------------------------------------------------------------------------------------

/// `dot(v, v)`, left to right (wrapping for integer vectors); quaternions too.
#[inline(always)]
pub fn length_sq<V: VecOps>(v: V) -> V::Scalar {
    v.w_dot(v)
}

/// `outer`: the float vectors (through [`VecMat`]) and the spatial vectors, and any two of
/// them of one scalar and different lengths (a non-square matrix, `crate::matrix`).
pub trait Outer<B = Self>: Copy {
    /// The matrix of shape `(len self, len b)` of the vectors' scalar.
    type Mat: Copy;
    /// `self bᵀ`.
    fn w_outer_of(self, b: B) -> Self::Mat;
}

/// `transpose`: the square glam matrices (through [`SquareMat`]), the spatial matrices and
/// the non-square matrices.
pub trait Transpose: Copy {
    /// The transpose's type: `Self` for a square matrix, `Mat32` for a `Mat23`.
    type T: Copy;
    /// The transpose.
    fn w_transposed(self) -> Self::T;
}

/// `ddot`: the square glam matrices (through [`SquareMat`]) and the non-square matrices.
pub trait Ddot: Copy {
    /// The scalar.
    type S: Copy;
    /// The sum of the entry products (see [`ddot`]).
    fn w_ddot_of(self, b: Self) -> Self::S;
}

impl<M: SquareMat> Ddot for M {
    type S = M::S;
    #[inline(always)]
    fn w_ddot_of(self, b: Self) -> M::S {
        self.w_ddot(b)
    }
}

/// The outer product `a bᵀ` (column `j` is `a * b[j]`; entry `(i, j)` is `a[i] b[j]`), of
/// shape `(len a, len b)`.
#[inline(always)]
pub fn outer<A: Outer<B>, B>(a: A, b: B) -> A::Mat {
    a.w_outer_of(b)
}

/// The diagonal matrix with diagonal `v`.
#[inline(always)]
pub fn diag<V: VecMat>(v: V) -> V::Mat {
    v.w_diag()
}

/// Componentwise product.
#[inline(always)]
pub fn cw_mul<T: Cw>(a: T, b: T) -> T {
    a.w_cw_mul(b)
}

/// Componentwise quotient.
#[inline(always)]
pub fn cw_div<T: Cw>(a: T, b: T) -> T {
    a.w_cw_div(b)
}

/// The transpose of a matrix (glam's, a spatial matrix's, a non-square one's).
#[inline(always)]
pub fn transpose<M: Transpose>(m: M) -> M::T {
    m.w_transposed()
}

/// The determinant (glam's evaluation order).
#[inline(always)]
pub fn determinant<M: SquareMat>(m: M) -> M::S {
    m.w_determinant()
}

/// The sum of the diagonal.
#[inline(always)]
pub fn trace<M: SquareMat>(m: M) -> M::S {
    m.w_trace()
}

/// The double contraction `sum a[i][j] * b[i][j]` (square glam matrices column-major,
/// non-square ones row by row, left to right).
#[inline(always)]
pub fn ddot<M: Ddot>(a: M, b: M) -> M::S {
    a.w_ddot_of(b)
}

/// The inverse: of a matrix (the zero matrix when its determinant is 0), or of a quaternion
/// (its conjugate).
#[inline(always)]
pub fn inverse<T: Inverse>(x: T) -> T {
    x.w_inverse()
}

/// The cross-product matrix: `skew(v) * w == cross(v, w)`.
#[inline(always)]
pub fn skew<V: Skew>(v: V) -> V::Mat {
    v.w_skew()
}

/// The rotation by `angle` radians about `axis` (not normalized here).
#[inline(always)]
pub fn quat_from_axis_angle<Q: QuatOps>(axis: Q::V3, angle: Q::S) -> Q {
    Q::w_from_axis_angle(axis, angle)
}

/// `v` rotated by `q` (glam's `q * v`).
#[inline(always)]
pub fn quat_rotate<Q: QuatOps>(q: Q, v: Q::V3) -> Q::V3 {
    q.w_rotate(v)
}

/// `v` rotated by the inverse of the unit quaternion `q` (`conjugate(q) * v`).
#[inline(always)]
pub fn quat_rotate_inv<Q: QuatOps>(q: Q, v: Q::V3) -> Q::V3 {
    q.w_rotate_inv(v)
}

/// The conjugate `(-x, -y, -z, w)`, the inverse of a unit quaternion.
#[inline(always)]
pub fn quat_inverse<Q: QuatOps>(q: Q) -> Q {
    q.w_conjugate()
}

/// The rotation matrix of a unit quaternion (glam's `Mat3::from_quat`).
#[inline(always)]
pub fn quat_to_matrix<Q: QuatOps>(q: Q) -> Q::M3 {
    q.w_to_matrix()
}

/// The quaternion of a rotation matrix (glam's `Quat::from_mat3`).
#[inline(always)]
pub fn quat_from_matrix<Q: QuatOps>(m: Q::M3) -> Q {
    Q::w_from_matrix(m)
}

/// Spherical interpolation from `q0` (`t = 0`) to `q1` (`t = 1`) along the short path.
#[inline(always)]
pub fn quat_slerp<Q: QuatOps>(q0: Q, q1: Q, t: Q::S) -> Q {
    q0.w_slerp(q1, t)
}

// ------------------------------------------------------------------------------------------
// Implementations
// ------------------------------------------------------------------------------------------

macro_rules! vec_mat {
    ($($v:ident: $m:ident, $s:ident, [$($c:ident),*]);* $(;)?) => {$(
        impl VecMat for $v {
            type Mat = $m;
            #[inline(always)]
            fn w_outer(self, b: Self) -> $m {
                $m::from_cols($(self * b.$c),*)
            }
            #[inline(always)]
            fn w_diag(self) -> $m {
                $m::from_diagonal(self)
            }
        }
        impl Outer for $v {
            type Mat = $m;
            #[inline(always)]
            fn w_outer_of(self, b: Self) -> $m {
                <$v as VecMat>::w_outer(self, b)
            }
        }
        impl Transpose for $m {
            type T = $m;
            #[inline(always)]
            fn w_transposed(self) -> Self {
                self.transpose()
            }
        }
        impl Cw for $v {
            #[inline(always)]
            fn w_cw_mul(self, b: Self) -> Self {
                self * b
            }
            #[inline(always)]
            fn w_cw_div(self, b: Self) -> Self {
                self / b
            }
        }
        impl Cw for $m {
            #[inline(always)]
            fn w_cw_mul(self, b: Self) -> Self {
                $m::from_cols($(self.$c() * b.$c()),*)
            }
            #[inline(always)]
            fn w_cw_div(self, b: Self) -> Self {
                $m::from_cols($(self.$c() / b.$c()),*)
            }
        }
        impl SquareMat for $m {
            type S = $s;
            #[inline(always)]
            fn w_transpose(self) -> Self {
                self.transpose()
            }
            #[inline(always)]
            fn w_determinant(self) -> $s {
                self.determinant()
            }
            #[inline(always)]
            fn w_trace(self) -> $s {
                let d: [$s; $v::ZERO.to_array().len()] = core::array::from_fn(|i| self.col(i)[i]);
                let mut acc = d[0];
                for x in &d[1..] {
                    acc += *x;
                }
                acc
            }
            #[inline(always)]
            fn w_ddot(self, b: Self) -> $s {
                let (a, b) = (self.to_cols_array(), b.to_cols_array());
                let mut acc: $s = 0.0;
                for k in 0..a.len() {
                    acc += a[k] * b[k];
                }
                acc
            }
        }
        impl Inverse for $m {
            #[inline(always)]
            fn w_inverse(self) -> Self {
                if self.determinant() == 0.0 {
                    $m::ZERO
                } else {
                    self.inverse()
                }
            }
        }
    )*};
}

// `b.x` etc. for vectors; the same names as column accessors on matrices would clash, so
// matrices go through small helper traits giving `x()`, `y()`, ... columns.
trait Cols2<V> {
    fn x(&self) -> V;
    fn y(&self) -> V;
}
trait Cols3<V>: Cols2<V> {
    fn z(&self) -> V;
}
trait Cols4<V>: Cols3<V> {
    fn w(&self) -> V;
}
macro_rules! cols {
    ($($m:ident: $v:ident, $n:tt);*) => {$(
        cols!(@$n $m, $v);
    )*};
    (@2 $m:ident, $v:ident) => {
        impl Cols2<$v> for $m {
            fn x(&self) -> $v { self.x_axis }
            fn y(&self) -> $v { self.y_axis }
        }
    };
    (@3 $m:ident, $v:ident) => {
        cols!(@2 $m, $v);
        impl Cols3<$v> for $m {
            fn z(&self) -> $v { self.z_axis }
        }
    };
    (@4 $m:ident, $v:ident) => {
        cols!(@3 $m, $v);
        impl Cols4<$v> for $m {
            fn w(&self) -> $v { self.w_axis }
        }
    };
}
cols!(Mat2: Vec2, 2; Mat3: Vec3, 3; Mat4: Vec4, 4; DMat2: DVec2, 2; DMat3: DVec3, 3; DMat4: DVec4, 4);

vec_mat!(
    Vec2: Mat2, f32, [x, y];
    Vec3: Mat3, f32, [x, y, z];
    Vec4: Mat4, f32, [x, y, z, w];
    DVec2: DMat2, f64, [x, y];
    DVec3: DMat3, f64, [x, y, z];
    DVec4: DMat4, f64, [x, y, z, w];
);

macro_rules! skew {
    ($($v:ident: $m:ident),*) => {$(
        impl Skew for $v {
            type Mat = $m;
            #[inline(always)]
            fn w_skew(self) -> $m {
                let z = 0.0;
                $m::from_cols(
                    $v::new(z, self.z, -self.y),
                    $v::new(-self.z, z, self.x),
                    $v::new(self.y, -self.x, z),
                )
            }
        }
    )*};
}
skew!(Vec3: Mat3, DVec3: DMat3);

macro_rules! quat_impl {
    ($($q:ident: $v3:ident, $m3:ident, $s:ident);*) => {$(
        impl VecOps for $q {
            type Scalar = $s;
            #[inline(always)]
            fn w_dot(self, o: Self) -> $s {
                ((self.x * o.x + self.y * o.y) + self.z * o.z) + self.w * o.w
            }
        }
        impl FloatVec for $q {
            // Rescaled where the squares would overflow or underflow (see `norm`); the
            // identity where the length is not positive.
            #[inline(always)]
            fn w_length(self) -> $s {
                super::norm::length(self)
            }
            #[inline(always)]
            fn w_normalize(self) -> Self {
                super::norm::normalize(self)
            }
        }
        impl Inverse for $q {
            #[inline(always)]
            fn w_inverse(self) -> Self {
                self.conjugate()
            }
        }
        impl QuatOps for $q {
            type S = $s;
            type V3 = $v3;
            type M3 = $m3;
            #[inline(always)]
            fn w_from_axis_angle(axis: $v3, angle: $s) -> Self {
                $q::from_axis_angle(axis, angle)
            }
            #[inline(always)]
            fn w_rotate(self, v: $v3) -> $v3 {
                self * v
            }
            #[inline(always)]
            fn w_rotate_inv(self, v: $v3) -> $v3 {
                self.conjugate() * v
            }
            #[inline(always)]
            fn w_conjugate(self) -> Self {
                self.conjugate()
            }
            #[inline(always)]
            fn w_to_matrix(self) -> $m3 {
                $m3::from_quat(self)
            }
            #[inline(always)]
            fn w_from_matrix(m: $m3) -> Self {
                $q::from_mat3(&m)
            }
            #[inline(always)]
            fn w_slerp(self, q1: Self, t: $s) -> Self {
                let d = self.conjugate() * q1;
                let v = $v3::new(d.x, d.y, d.z);
                let n = v.w_normalize();
                let axis = if d.w < 0.0 { -n } else { n };
                let angle = 2.0 * v.w_length().w_atan2(d.w.w_abs());
                self * $q::from_axis_angle(axis, t * angle)
            }
        }
    )*};
}
quat_impl!(Quat: Vec3, Mat3, f32; DQuat: DVec3, DMat3, f64);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn singular_inverse_is_zero() {
        let m = Mat3::from_cols(Vec3::X, Vec3::Y, Vec3::X);
        assert_eq!(inverse(m), Mat3::ZERO);
        assert_eq!(inverse(Mat2::ZERO), Mat2::ZERO);
        assert_eq!(inverse(DMat4::ZERO), DMat4::ZERO);
        let m = Mat4::from_diagonal(vec4(2.0, 4.0, 0.5, 1.0));
        assert_eq!(inverse(m), Mat4::from_diagonal(vec4(0.5, 0.25, 2.0, 1.0)));
    }

    use glam::vec4;

    #[test]
    fn skew_is_cross() {
        let (a, b) = (Vec3::new(1.0, -2.0, 3.0), Vec3::new(0.5, 4.0, -1.0));
        assert_eq!(skew(a) * b, a.cross(b));
        assert_eq!(outer(a, b).col(1), a * b.y);
        assert_eq!(trace(Mat3::from_diagonal(a)), 2.0);
    }

    #[test]
    fn quat_edges() {
        assert_eq!(
            super::super::math::normalize(Quat::from_xyzw(0.0, 0.0, 0.0, 0.0)),
            Quat::IDENTITY
        );
        let q = Quat::from_axis_angle(Vec3::new(0.0, 0.6, 0.8), 1.2);
        assert_eq!(quat_slerp(q, q, 0.3), q);
        let m = Mat3::from_diagonal(Vec3::new(1.0, -1.0, -1.0));
        assert_eq!(
            quat_from_matrix::<Quat>(m),
            Quat::from_xyzw(1.0, 0.0, 0.0, 0.0)
        );
    }
}

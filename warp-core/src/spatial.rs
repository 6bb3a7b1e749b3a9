//! Spatial vectors and matrices: [`SpatialVector`] / [`DSpatialVector`] (6 lanes) and
//! [`SpatialMatrix`] / [`DSpatialMatrix`] (6x6, row-major), NVIDIA Warp's `spatial_vector`,
//! `spatial_vectord`, `spatial_matrix` and `spatial_matrixd`.
//!
//! A spatial vector is a twist `(w, v)` (angular velocity on top, linear velocity below) or a
//! wrench `(τ, f)` (torque on top, force below), Featherstone's convention as Warp uses it.
//! glam's vectors and matrices stop at 4, so these live here, with the same operations on the
//! host (plain Rust methods and operators) as in kernels (the builtins of the table's
//! "spatial" section, on both backends).
//!
//! # Layout
//!
//! Both are `#[repr(C)]` and [`bytemuck::Pod`] with no padding: a spatial vector is 6
//! consecutive scalars (24 bytes in `f32`, 48 in `f64`), a spatial matrix 6 spatial vectors, its
//! rows (144 and 288 bytes), as Warp's `vec_t<6>` and `mat_t<6, 6>` (row-major). The CUDA
//! library mirrors them (`wp::SpatialVector`, .. in `warp-cuda/cuda/wp_core.h`, checked there
//! by `static_assert`). They are tuple structs so that kernels name a lane as Rust names a
//! tuple field: `v[3]` in a kernel is `v.3` here and `v.f3` in C++, `m[i][j]` is `m.i.j`.
//!
//! # Operations (Warp's definitions), and their order of evaluation
//!
//! Every sum is evaluated left to right in ascending index, so that the CUDA library, which
//! writes the same steps, gives the same bits where neither side contracts to FMA:
//!
//! * `a + b`, `a - b`, `-a`, `a * s`, `s * a`, `a / s`: lane by lane (matrices too);
//! * [`dot`](SpatialVector::dot): `((((a0 b0 + a1 b1) + a2 b2) + a3 b3) + a4 b4) + a5 b5`;
//! * `m * x`: lane `i` is `m[i].dot(x)`; `a * b` (matrices): entry `(i, j)` is
//!   `Σ_k a[i][k] b[k][j]`, `k` ascending; [`transpose`](SpatialMatrix::transpose);
//! * [`cross`](SpatialVector::cross) (`spatial_cross`, the motion cross product `a ×`):
//!   `(wa × wb, va × wb + wa × vb)`; [`cross_dual`](SpatialVector::cross_dual)
//!   (`spatial_cross_dual`, the force cross product `a ×*`): `(wa × wb + va × vb, wa × vb)`,
//!   each `×` glam's `Vec3::cross`;
//! * [`outer`](SpatialVector::outer): entry `(i, j)` is `a[i] b[j]`;
//! * [`SpatialMatrix::adjoint`] (`spatial_adjoint(r, s)`): `[[r, 0], [s, r]]` in 3x3 blocks;
//! * [`transform_twist`](SpatialVector::transform_twist) and
//!   [`transform_wrench`](SpatialVector::transform_wrench) in the transform's frame (see
//!   their documentation).

use core::fmt;
use core::ops::{Add, AddAssign, Div, Index, IndexMut, Mul, Neg, Sub, SubAssign};

use glam::{DMat3, DVec3, Mat3, Vec3};

use crate::transform::{DTransform, Transform};

macro_rules! spatial_types {
    (
        $(#[$vdoc:meta])*
        $v:ident,
        $(#[$mdoc:meta])*
        $m:ident, $s:ident, $v3:ident, $m3:ident, $x:ident,
        vname: $vname:literal, mname: $mname:literal
    ) => {
        $(#[$vdoc])*
        #[repr(C)]
        #[derive(Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $v(pub $s, pub $s, pub $s, pub $s, pub $s, pub $s);

        $(#[$mdoc])*
        #[repr(C)]
        #[derive(Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
        pub struct $m(pub $v, pub $v, pub $v, pub $v, pub $v, pub $v);

        impl $v {
            /// Every lane zero.
            pub const ZERO: Self = Self(0.0, 0.0, 0.0, 0.0, 0.0, 0.0);

            /// The spatial vector with top `w` and bottom `v` (Warp's `spatial_vector(w, v)`).
            #[inline(always)]
            pub const fn new(w: $v3, v: $v3) -> Self {
                Self(w.x, w.y, w.z, v.x, v.y, v.z)
            }

            /// The spatial vector with lanes `a` (Warp's six-scalar `spatial_vector`).
            #[inline(always)]
            pub const fn from_array(a: [$s; 6]) -> Self {
                Self(a[0], a[1], a[2], a[3], a[4], a[5])
            }

            /// The six lanes.
            #[inline(always)]
            pub const fn to_array(self) -> [$s; 6] {
                [self.0, self.1, self.2, self.3, self.4, self.5]
            }

            /// The top 3-vector, lanes 0 to 2 (Warp's `spatial_top`: the angular part).
            #[inline(always)]
            pub const fn top(self) -> $v3 {
                $v3::new(self.0, self.1, self.2)
            }

            /// The bottom 3-vector, lanes 3 to 5 (Warp's `spatial_bottom`: the linear part).
            #[inline(always)]
            pub const fn bottom(self) -> $v3 {
                $v3::new(self.3, self.4, self.5)
            }

            /// The dot product, summed left to right (Warp's `spatial_dot`).
            #[inline]
            pub fn dot(self, b: Self) -> $s {
                let (a, b) = (self.to_array(), b.to_array());
                let mut r = a[0] * b[0];
                for k in 1..6 {
                    r += a[k] * b[k];
                }
                r
            }

            /// The motion cross product `self × b` (Warp's `spatial_cross`):
            /// `(wa × wb, va × wb + wa × vb)`.
            #[inline]
            pub fn cross(self, b: Self) -> Self {
                let (wa, va, wb, vb) = (self.top(), self.bottom(), b.top(), b.bottom());
                Self::new(wa.cross(wb), va.cross(wb) + wa.cross(vb))
            }

            /// The force cross product `self ×* b` (Warp's `spatial_cross_dual`):
            /// `(wa × wb + va × vb, wa × vb)`.
            #[inline]
            pub fn cross_dual(self, b: Self) -> Self {
                let (wa, va, wb, vb) = (self.top(), self.bottom(), b.top(), b.bottom());
                Self::new(wa.cross(wb) + va.cross(vb), wa.cross(vb))
            }

            /// The outer product: entry `(i, j)` is `self[i] * b[j]`.
            #[inline]
            pub fn outer(self, b: Self) -> $m {
                let (a, b) = (self.to_array(), b.to_array());
                $m::from_rows_array(core::array::from_fn(|i| core::array::from_fn(|j| a[i] * b[j])))
            }

            /// The linear velocity of the point at offset `r` from the origin of the twist
            /// `self = (w, v)` (Warp's `velocity_at_point`): `v + w × r`, summed in that
            /// order.
            #[inline]
            pub fn velocity_at_point(self, r: $v3) -> $v3 {
                self.bottom() + self.top().cross(r)
            }

            /// The twist `self = (w, v)` seen in the frame `t` maps into (Warp's
            /// `transform_twist`): `w' = q w`, `v' = q v + p × w'` (each rotation glam's
            /// `q * x`, as `transform_vector`).
            #[inline]
            pub fn transform_twist(self, t: $x) -> Self {
                let w = t.q * self.top();
                let v = t.q * self.bottom() + t.p.cross(w);
                Self::new(w, v)
            }

            /// The wrench `self = (τ, f)` seen in the frame `t` maps into (Warp's
            /// `transform_wrench`): `f' = q f`, `τ' = q τ + p × f'`. With
            /// [`transform_twist`](Self::transform_twist) it keeps power:
            /// `twist(t, m).dot(wrench(t, f)) == m.dot(f)` for a rigid `t`.
            #[inline]
            pub fn transform_wrench(self, t: $x) -> Self {
                let f = t.q * self.bottom();
                let tau = t.q * self.top() + t.p.cross(f);
                Self::new(tau, f)
            }

            /// Whether every lane is finite.
            #[inline]
            pub fn is_finite(self) -> bool {
                self.to_array().iter().all(|x| x.is_finite())
            }

            #[inline(always)]
            fn map(self, f: impl Fn($s) -> $s) -> Self {
                Self::from_array(self.to_array().map(f))
            }

            #[inline(always)]
            fn zip(self, b: Self, f: impl Fn($s, $s) -> $s) -> Self {
                let (a, b) = (self.to_array(), b.to_array());
                Self::from_array(core::array::from_fn(|k| f(a[k], b[k])))
            }
        }

        impl $m {
            /// Every entry zero.
            pub const ZERO: Self = Self($v::ZERO, $v::ZERO, $v::ZERO, $v::ZERO, $v::ZERO, $v::ZERO);

            /// The identity.
            pub const IDENTITY: Self = Self(
                $v(1.0, 0.0, 0.0, 0.0, 0.0, 0.0),
                $v(0.0, 1.0, 0.0, 0.0, 0.0, 0.0),
                $v(0.0, 0.0, 1.0, 0.0, 0.0, 0.0),
                $v(0.0, 0.0, 0.0, 1.0, 0.0, 0.0),
                $v(0.0, 0.0, 0.0, 0.0, 1.0, 0.0),
                $v(0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
            );

            /// The matrix with these rows (`SpatialMatrix::from_rows(r0, .., r5)` in kernels too).
            #[inline(always)]
            pub const fn from_rows(r0: $v, r1: $v, r2: $v, r3: $v, r4: $v, r5: $v) -> Self {
                Self(r0, r1, r2, r3, r4, r5)
            }

            /// The matrix with the rows of `r`.
            #[inline(always)]
            pub const fn from_row_array(r: [$v; 6]) -> Self {
                Self(r[0], r[1], r[2], r[3], r[4], r[5])
            }

            /// The rows.
            #[inline(always)]
            pub const fn to_rows(self) -> [$v; 6] {
                [self.0, self.1, self.2, self.3, self.4, self.5]
            }

            /// The matrix with entries `a[row][col]` (Warp's 36-scalar `spatial_matrix`, in
            /// its row-major order).
            #[inline]
            pub fn from_rows_array(a: [[$s; 6]; 6]) -> Self {
                Self::from_row_array(a.map($v::from_array))
            }

            /// The entries, `[row][col]`.
            #[inline]
            pub fn to_rows_array(self) -> [[$s; 6]; 6] {
                self.to_rows().map($v::to_array)
            }

            /// Column `j`.
            #[inline]
            pub fn col(self, j: usize) -> $v {
                $v::from_array(self.to_rows().map(|r| r[j]))
            }

            /// The transpose.
            #[inline]
            pub fn transpose(self) -> Self {
                Self::from_row_array(core::array::from_fn(|j| self.col(j)))
            }

            /// Warp's `spatial_adjoint(r, s)`: `r` in both diagonal 3x3 blocks, `s` in the
            /// lower-left one, zero in the upper-right (entry `(i, j)` of a block is row `i`,
            /// column `j` of the 3x3 matrix: glam's `r.col(j)[i]`). With `r` a rotation and
            /// `s = skew(p) r` it is the motion transform of the rigid transform `(r, p)`.
            #[inline]
            pub fn adjoint(r: $m3, s: $m3) -> Self {
                let mut a = [[0.0; 6]; 6];
                for i in 0..3 {
                    for j in 0..3 {
                        a[i][j] = r.col(j)[i];
                        a[i + 3][j + 3] = r.col(j)[i];
                        a[i + 3][j] = s.col(j)[i];
                    }
                }
                Self::from_rows_array(a)
            }

            /// Whether every entry is finite.
            #[inline]
            pub fn is_finite(self) -> bool {
                self.to_rows().iter().all(|r| r.is_finite())
            }

            #[inline(always)]
            fn map_rows(self, f: impl Fn($v) -> $v) -> Self {
                Self::from_row_array(self.to_rows().map(f))
            }

            #[inline(always)]
            fn zip_rows(self, b: Self, f: impl Fn($v, $v) -> $v) -> Self {
                let (a, b) = (self.to_rows(), b.to_rows());
                Self::from_row_array(core::array::from_fn(|k| f(a[k], b[k])))
            }
        }

        impl Index<usize> for $v {
            type Output = $s;
            /// Lane `k` (panics past 5, as an array does).
            #[inline]
            fn index(&self, k: usize) -> &$s {
                &bytemuck::cast_ref::<$v, [$s; 6]>(self)[k]
            }
        }

        impl IndexMut<usize> for $v {
            #[inline]
            fn index_mut(&mut self, k: usize) -> &mut $s {
                &mut bytemuck::cast_mut::<$v, [$s; 6]>(self)[k]
            }
        }

        impl Index<usize> for $m {
            type Output = $v;
            /// Row `i` (panics past 5).
            #[inline]
            fn index(&self, i: usize) -> &$v {
                &bytemuck::cast_ref::<$m, [$v; 6]>(self)[i]
            }
        }

        impl IndexMut<usize> for $m {
            #[inline]
            fn index_mut(&mut self, i: usize) -> &mut $v {
                &mut bytemuck::cast_mut::<$m, [$v; 6]>(self)[i]
            }
        }

        impl Index<(usize, usize)> for $m {
            type Output = $s;
            /// Entry `(row, col)`.
            #[inline]
            fn index(&self, (i, j): (usize, usize)) -> &$s {
                &self[i][j]
            }
        }

        impl IndexMut<(usize, usize)> for $m {
            #[inline]
            fn index_mut(&mut self, (i, j): (usize, usize)) -> &mut $s {
                &mut self[i][j]
            }
        }

        impl fmt::Debug for $v {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}({:?})", $vname, self.to_array())
            }
        }

        impl fmt::Display for $v {
            /// `[a, b, c, d, e, f]` (glam's vector style).
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "[{}, {}, {}, {}, {}, {}]", self.0, self.1, self.2, self.3, self.4, self.5)
            }
        }

        impl fmt::Debug for $m {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}({:?})", $mname, self.to_rows_array())
            }
        }

        impl fmt::Display for $m {
            /// `[row0, .., row5]`, each row as a spatial vector prints.
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "[{}, {}, {}, {}, {}, {}]", self.0, self.1, self.2, self.3, self.4, self.5)
            }
        }

        impl Add for $v {
            type Output = $v;
            #[inline]
            fn add(self, b: $v) -> $v {
                self.zip(b, |x, y| x + y)
            }
        }
        impl Sub for $v {
            type Output = $v;
            #[inline]
            fn sub(self, b: $v) -> $v {
                self.zip(b, |x, y| x - y)
            }
        }
        impl Neg for $v {
            type Output = $v;
            #[inline]
            fn neg(self) -> $v {
                self.map(|x| -x)
            }
        }
        impl Mul<$s> for $v {
            type Output = $v;
            #[inline]
            fn mul(self, s: $s) -> $v {
                self.map(|x| x * s)
            }
        }
        impl Mul<$v> for $s {
            type Output = $v;
            /// `s * a[k]` lane by lane.
            #[inline]
            fn mul(self, a: $v) -> $v {
                a.map(|x| self * x)
            }
        }
        impl Div<$s> for $v {
            type Output = $v;
            #[inline]
            fn div(self, s: $s) -> $v {
                self.map(|x| x / s)
            }
        }
        impl AddAssign for $v {
            #[inline]
            fn add_assign(&mut self, b: $v) {
                *self = *self + b;
            }
        }
        impl SubAssign for $v {
            #[inline]
            fn sub_assign(&mut self, b: $v) {
                *self = *self - b;
            }
        }

        impl Add for $m {
            type Output = $m;
            #[inline]
            fn add(self, b: $m) -> $m {
                self.zip_rows(b, |x, y| x + y)
            }
        }
        impl Sub for $m {
            type Output = $m;
            #[inline]
            fn sub(self, b: $m) -> $m {
                self.zip_rows(b, |x, y| x - y)
            }
        }
        impl Neg for $m {
            type Output = $m;
            #[inline]
            fn neg(self) -> $m {
                self.map_rows(|r| -r)
            }
        }
        impl Mul<$s> for $m {
            type Output = $m;
            #[inline]
            fn mul(self, s: $s) -> $m {
                self.map_rows(|r| r * s)
            }
        }
        impl Mul<$m> for $s {
            type Output = $m;
            #[inline]
            fn mul(self, a: $m) -> $m {
                a.map_rows(|r| self * r)
            }
        }
        impl Div<$s> for $m {
            type Output = $m;
            #[inline]
            fn div(self, s: $s) -> $m {
                self.map_rows(|r| r / s)
            }
        }
        impl Mul<$v> for $m {
            type Output = $v;
            /// Lane `i` is `self[i].dot(x)`.
            #[inline]
            fn mul(self, x: $v) -> $v {
                $v::from_array(self.to_rows().map(|r| r.dot(x)))
            }
        }
        impl Mul for $m {
            type Output = $m;
            /// Entry `(i, j)` is `Σ_k self[i][k] b[k][j]`, `k` ascending.
            #[inline]
            fn mul(self, b: $m) -> $m {
                let (a, b) = (self.to_rows_array(), b.to_rows_array());
                $m::from_rows_array(core::array::from_fn(|i| {
                    core::array::from_fn(|j| {
                        let mut r = a[i][0] * b[0][j];
                        for k in 1..6 {
                            r += a[i][k] * b[k][j];
                        }
                        r
                    })
                }))
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

        // A literal of a spatial type (what `lit_like` makes where the macro cannot see a
        // value's type: a func's result, a struct field) is every lane, as a glam vector's.
        impl crate::ops::FromLiteral for $v {
            #[inline(always)]
            fn from_f64(v: f64) -> Self {
                Self::from_array([v as $s; 6])
            }
            #[inline(always)]
            fn from_i64(v: i64) -> Self {
                Self::from_array([v as $s; 6])
            }
        }
        impl crate::ops::FromLiteral for $m {
            #[inline(always)]
            fn from_f64(v: f64) -> Self {
                Self::from_rows_array([[v as $s; 6]; 6])
            }
            #[inline(always)]
            fn from_i64(v: i64) -> Self {
                Self::from_rows_array([[v as $s; 6]; 6])
            }
        }

        // Gradients of arrays of them: every lane adds atomically on its own.
        impl crate::grad::GradElement for $v {
            #[inline(always)]
            unsafe fn grad_add(ptr: *mut Self, v: Self) {
                let base = ptr as *mut $s;
                for (k, x) in v.to_array().into_iter().enumerate() {
                    // SAFETY: lane k of a live, aligned element (forwarded contract); the type
                    // is six consecutive scalars.
                    unsafe { <$s as crate::grad::GradElement>::grad_add(base.add(k), x) };
                }
            }
        }
        impl crate::grad::GradElement for $m {
            #[inline(always)]
            unsafe fn grad_add(ptr: *mut Self, v: Self) {
                let base = ptr as *mut $v;
                for (k, r) in v.to_rows().into_iter().enumerate() {
                    // SAFETY: row k of a live, aligned element (forwarded contract).
                    unsafe { <$v as crate::grad::GradElement>::grad_add(base.add(k), r) };
                }
            }
        }

        const _: () = {
            assert!(core::mem::size_of::<$v>() == 6 * core::mem::size_of::<$s>());
            assert!(core::mem::size_of::<$m>() == 36 * core::mem::size_of::<$s>());
            assert!(core::mem::align_of::<$v>() == core::mem::align_of::<$s>());
            assert!(core::mem::align_of::<$m>() == core::mem::align_of::<$s>());
        };
    };
}

spatial_types!(
    /// A spatial vector in `f32` (Warp's `spatial_vector`): six lanes, a twist `(w, v)` or a
    /// wrench `(τ, f)`, angular part on top. 24 bytes, no padding (see the
    /// [module documentation](self)).
    ///
    /// ```
    /// use warp_core::SpatialVector;
    /// use glam::Vec3;
    /// let a = SpatialVector::new(Vec3::Z, Vec3::ZERO);
    /// let b = SpatialVector::new(Vec3::ZERO, Vec3::X);
    /// assert_eq!(a.cross(b).bottom(), Vec3::Y);
    /// assert_eq!(a[2], 1.0);
    /// ```
    SpatialVector,
    /// A 6x6 spatial matrix in `f32` (Warp's `spatial_matrix`), row-major: six
    /// [`SpatialVector`] rows, 144 bytes.
    ///
    /// ```
    /// use warp_core::{SpatialMatrix, SpatialVector};
    /// let x = SpatialVector::from_array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    /// assert_eq!(SpatialMatrix::IDENTITY * x, x);
    /// assert_eq!(x.outer(x)[(1, 2)], 6.0);
    /// ```
    SpatialMatrix, f32, Vec3, Mat3, Transform,
    vname: "SpatialVector", mname: "SpatialMatrix"
);

spatial_types!(
    /// A spatial vector in `f64` (Warp's `spatial_vectord`); 48 bytes.
    DSpatialVector,
    /// A 6x6 spatial matrix in `f64` (Warp's `spatial_matrixd`), row-major; 288 bytes.
    DSpatialMatrix, f64, DVec3, DMat3, DTransform,
    vname: "DSpatialVector", mname: "DSpatialMatrix"
);

impl SpatialVector {
    /// The `f64` spatial vector with the same lanes.
    pub fn as_dspatial(self) -> DSpatialVector {
        DSpatialVector::from_array(self.to_array().map(f64::from))
    }
}

impl DSpatialVector {
    /// The `f32` spatial vector with the lanes rounded to `f32`.
    pub fn as_spatial(self) -> SpatialVector {
        SpatialVector::from_array(self.to_array().map(|x| x as f32))
    }
}

impl SpatialMatrix {
    /// The `f64` spatial matrix with the same entries.
    pub fn as_dspatial(self) -> DSpatialMatrix {
        DSpatialMatrix::from_row_array(self.to_rows().map(SpatialVector::as_dspatial))
    }
}

impl DSpatialMatrix {
    /// The `f32` spatial matrix with the entries rounded to `f32`.
    pub fn as_spatial(self) -> SpatialMatrix {
        SpatialMatrix::from_row_array(self.to_rows().map(DSpatialVector::as_spatial))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::DQuat;

    fn sv(a: [f64; 6]) -> DSpatialVector {
        DSpatialVector::from_array(a)
    }

    fn rigid() -> DTransform {
        DTransform::new(
            DVec3::new(0.5, -1.0, 2.0),
            DQuat::from_axis_angle(DVec3::new(1.0, 2.0, -0.5).normalize(), 0.7),
        )
    }

    /// `skew(p) x = p × x`, as a glam matrix.
    fn skew(p: DVec3) -> DMat3 {
        DMat3::from_cols(
            DVec3::new(0.0, p.z, -p.y),
            DVec3::new(-p.z, 0.0, p.x),
            DVec3::new(p.y, -p.x, 0.0),
        )
    }

    #[test]
    fn lanes_layout_and_indexing() {
        let a = SpatialVector::from_array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
        assert_eq!(
            bytemuck::cast::<_, [f32; 6]>(a),
            [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
        );
        assert_eq!(a.top(), Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(a.bottom(), Vec3::new(4.0, 5.0, 6.0));
        assert_eq!(SpatialVector::new(a.top(), a.bottom()), a);
        assert_eq!(a[4], 5.0);
        let mut b = a;
        b[0] = -1.0;
        assert_eq!(b.0, -1.0);
        let mut m = a.outer(a);
        assert_eq!(m[(2, 3)], 12.0);
        assert_eq!(m[2][3], 12.0);
        m[(5, 0)] = 0.5;
        assert_eq!(m.5 .0, 0.5);
        assert_eq!(
            bytemuck::cast::<_, [SpatialVector; 6]>(m)[5].0,
            0.5,
            "row-major"
        );
        assert_eq!(format!("{a}"), "[1, 2, 3, 4, 5, 6]");
        assert_eq!(SpatialMatrix::default(), SpatialMatrix::ZERO);
        assert_eq!(a.as_dspatial().as_spatial(), a);
        assert_eq!(m.as_dspatial().as_spatial(), m);
        assert!(a.is_finite() && !(a * f32::INFINITY).is_finite());
    }

    #[test]
    fn arithmetic_and_products() {
        let a = sv([1.0, -2.0, 0.5, 3.0, 0.25, -1.5]);
        let b = sv([0.3, 0.7, -1.1, 2.0, -0.5, 0.9]);
        assert_eq!((a + b)[3], 5.0);
        assert_eq!((a - a), DSpatialVector::ZERO);
        assert_eq!(-a + a, DSpatialVector::ZERO);
        assert_eq!((a * 2.0), (2.0 * a));
        assert_eq!((a * 2.0) / 2.0, a);
        let dot: f64 = (0..6).map(|k| a[k] * b[k]).sum();
        assert!((a.dot(b) - dot).abs() < 1e-15);
        let m = a.outer(b) + DSpatialMatrix::IDENTITY;
        // (a bᵀ + I) x = a (b·x) + x.
        let x = sv([0.1, 0.2, 0.3, -0.4, 0.5, -0.6]);
        let y = m * x;
        let want = a * b.dot(x) + x;
        for k in 0..6 {
            assert!((y[k] - want[k]).abs() < 1e-14);
        }
        // (m n)ᵀ = nᵀ mᵀ; (m n) x = m (n x).
        let n = b.outer(x) - DSpatialMatrix::IDENTITY * 0.5;
        let l = (m * n).transpose();
        let r = n.transpose() * m.transpose();
        let (mx, nx) = ((m * n) * x, m * (n * x));
        for i in 0..6 {
            assert!((mx[i] - nx[i]).abs() < 1e-13);
            for j in 0..6 {
                assert!((l[(i, j)] - r[(i, j)]).abs() < 1e-14);
            }
        }
        assert_eq!(m.transpose().transpose(), m);
        assert_eq!((m * 2.0) / 2.0, m);
        assert_eq!(-m + m, DSpatialMatrix::ZERO);
    }

    #[test]
    fn cross_products_are_the_closed_forms() {
        // Motion cross: [wa×  0; va×  wa×] b; force cross: [wa× va×; 0 wa×] b.
        let a = sv([1.0, -2.0, 0.5, 3.0, 0.25, -1.5]);
        let b = sv([0.3, 0.7, -1.1, 2.0, -0.5, 0.9]);
        let (wa, va) = (skew(a.top()), skew(a.bottom()));
        let c = a.cross(b);
        let want_top = wa * b.top();
        let want_bottom = va * b.top() + wa * b.bottom();
        assert!((c.top() - want_top).length() < 1e-14);
        assert!((c.bottom() - want_bottom).length() < 1e-14);
        let d = a.cross_dual(b);
        assert!((d.top() - (wa * b.top() + va * b.bottom())).length() < 1e-14);
        assert!((d.bottom() - wa * b.bottom()).length() < 1e-14);
        // ×* is -(×)ᵀ: (a ×* f) · m = -f · (a × m).
        let m = sv([0.4, -0.1, 0.8, -0.3, 1.2, 0.05]);
        assert!((a.cross_dual(b).dot(m) + b.dot(a.cross(m))).abs() < 1e-14);
    }

    #[test]
    fn twist_and_wrench_keep_power() {
        let t = rigid();
        let m = sv([0.4, -0.1, 0.8, -0.3, 1.2, 0.05]);
        let f = sv([1.0, -2.0, 0.5, 3.0, 0.25, -1.5]);
        let p = m.transform_twist(t).dot(f.transform_wrench(t));
        assert!((p - m.dot(f)).abs() < 1e-14, "{p} vs {}", m.dot(f));
        // The twist map is spatial_adjoint(R, skew(p) R), and the wrench map its inverse
        // transpose.
        let r = DMat3::from_quat(t.q);
        let x = DSpatialMatrix::adjoint(r, skew(t.p) * r);
        let (tw, xm) = (m.transform_twist(t), x * m);
        assert!((tw - xm).to_array().iter().all(|e| e.abs() < 1e-14));
        let ti = t.inverse();
        let xi =
            DSpatialMatrix::adjoint(DMat3::from_quat(ti.q), skew(ti.p) * DMat3::from_quat(ti.q));
        let (wr, xf) = (f.transform_wrench(t), xi.transpose() * f);
        assert!((wr - xf).to_array().iter().all(|e| e.abs() < 1e-14));
        // adjoint's blocks.
        assert_eq!(x[(0, 1)], r.col(1)[0]);
        assert_eq!(x[(4, 5)], r.col(2)[1]);
        assert_eq!(x[(1, 4)], 0.0);
        assert_eq!(x[(5, 0)], (skew(t.p) * r).col(0)[2]);
    }
}

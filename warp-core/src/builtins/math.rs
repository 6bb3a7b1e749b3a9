//! Scalar, componentwise and vector math builtins.
//!
//! Semantics follow Warp's CUDA builtins, not Rust's `std` where the two differ:
//!
//! * integer arithmetic inside builtins (`dot`, `cross`, `abs`) wraps, as CUDA does;
//! * float `min`/`max` are IEEE `fmin`/`fmax`: if one operand is NaN the other is returned;
//! * `sign(x)` is `-1` if `x < 0`, else `+1` (so `sign(0) = sign(-0.0) = sign(NaN) = 1`);
//! * `clamp(x, lo, hi)` is `min(max(x, lo), hi)` and never panics, even when `lo > hi`;
//! * `normalize` of a zero-length vector is the zero vector, never NaN;
//! * `length` and `normalize` scale the vector by the power of two of its largest component
//!   first, so that they stay accurate where the squares would overflow or underflow
//!   (`builtins/norm.rs`);
//! * `lerp(a, b, t)` is `a * (1 - t) + b * t`;
//! * `asin`/`acos` clamp their argument to `[-1, 1]` first (Warp's rule, so a dot product
//!   rounded to `1.0000001` still has an angle); NaN stays NaN;
//! * `round` rounds half away from zero (C `round`, Rust `f32::round`), `rint` half to even
//!   (C `rint`, Rust `round_ties_even`); `frac(x)` is `x - trunc(x)` (Rust's `fract`);
//! * `step(x)` is `1` if `x < 0`, else `0` (Warp's definition, the reverse of GLSL's);
//!   `smoothstep(e0, e1, x)` is `t * t * (3 - 2 * t)` with `t = clamp((x - e0) / (e1 - e0),
//!   0, 1)`, so with `e0 == e1` it is `0` for `x <= e0` and `1` above;
//! * `degrees`/`radians` multiply by `180/π` and `π/180` rounded to the type, exactly Rust's
//!   `to_degrees`/`to_radians` (Warp's f32 versions multiply in double);
//! * `isfinite`, `isnan`, `isinf` of a vector: all components finite, any NaN, any infinite;
//! * `erf`, `erfc`, `erfinv`, `erfcinv` are implemented here ([`special`]);
//! * vector `dot` sums the component products left to right (`x`, then `y`, ...), never in
//!   the SIMD order `glam` may use, so that results do not depend on the vector's backing.
//!
//! Vector operations are written componentwise here rather than delegated to `glam`, because
//! `glam`'s SIMD `min`/`max` do not have `fmin` NaN semantics and its integer `abs`/`dot`
//! panic on overflow in debug builds.

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};

use super::special;

pub use super::traits::{Classify, Cross, Float, FloatVec, Lerp, MinMax, Scalar, Signed, VecOps};

// ------------------------------------------------------------------------------------------
// Public builtins
// ------------------------------------------------------------------------------------------

/// The smaller of `a` and `b`, componentwise for vectors; IEEE `fmin` for floats.
#[inline(always)]
pub fn min<T: MinMax>(a: T, b: T) -> T {
    a.w_min(b)
}

/// The larger of `a` and `b`, componentwise for vectors; IEEE `fmax` for floats.
#[inline(always)]
pub fn max<T: MinMax>(a: T, b: T) -> T {
    a.w_max(b)
}

/// `min(max(x, lo), hi)`; never panics, also when `lo > hi` (the result is then `hi`).
#[inline(always)]
pub fn clamp<T: MinMax>(x: T, lo: T, hi: T) -> T {
    x.w_max(lo).w_min(hi)
}

/// Absolute value, componentwise for vectors; wrapping for integers.
#[inline(always)]
pub fn abs<T: Signed>(x: T) -> T {
    x.w_abs()
}

/// `-1` if `x < 0`, else `+1`, componentwise for vectors.
#[inline(always)]
pub fn sign<T: Signed>(x: T) -> T {
    x.w_sign()
}

/// Round toward negative infinity.
#[inline(always)]
pub fn floor<F: Float>(x: F) -> F {
    x.w_floor()
}

/// Round toward positive infinity.
#[inline(always)]
pub fn ceil<F: Float>(x: F) -> F {
    x.w_ceil()
}

/// Square root.
#[inline(always)]
pub fn sqrt<F: Float>(x: F) -> F {
    x.w_sqrt()
}

/// Exponential, `e^x`.
#[inline(always)]
pub fn exp<F: Float>(x: F) -> F {
    x.w_exp()
}

/// Natural logarithm.
#[inline(always)]
pub fn log<F: Float>(x: F) -> F {
    x.w_log()
}

/// Sine (radians).
#[inline(always)]
pub fn sin<F: Float>(x: F) -> F {
    x.w_sin()
}

/// Cosine (radians).
#[inline(always)]
pub fn cos<F: Float>(x: F) -> F {
    x.w_cos()
}

/// Tangent (radians).
#[inline(always)]
pub fn tan<F: Float>(x: F) -> F {
    x.w_tan()
}

/// Four-quadrant arctangent of `y / x`.
#[inline(always)]
pub fn atan2<F: Float>(y: F, x: F) -> F {
    y.w_atan2(x)
}

/// `x` raised to the power `y`.
#[inline(always)]
pub fn pow<F: Float>(x: F, y: F) -> F {
    x.w_pow(y)
}

/// Arcsine (radians) of `x` clamped to `[-1, 1]`; NaN for NaN.
#[inline(always)]
pub fn asin<F: Float>(x: F) -> F {
    x.w_asin()
}

/// Arccosine (radians) of `x` clamped to `[-1, 1]`; NaN for NaN.
#[inline(always)]
pub fn acos<F: Float>(x: F) -> F {
    x.w_acos()
}

/// Arctangent (radians).
#[inline(always)]
pub fn atan<F: Float>(x: F) -> F {
    x.w_atan()
}

/// Hyperbolic sine.
#[inline(always)]
pub fn sinh<F: Float>(x: F) -> F {
    x.w_sinh()
}

/// Hyperbolic cosine.
#[inline(always)]
pub fn cosh<F: Float>(x: F) -> F {
    x.w_cosh()
}

/// Hyperbolic tangent.
#[inline(always)]
pub fn tanh<F: Float>(x: F) -> F {
    x.w_tanh()
}

/// `2^x`.
#[inline(always)]
pub fn exp2<F: Float>(x: F) -> F {
    x.w_exp2()
}

/// Base-2 logarithm.
#[inline(always)]
pub fn log2<F: Float>(x: F) -> F {
    x.w_log2()
}

/// Base-10 logarithm.
#[inline(always)]
pub fn log10<F: Float>(x: F) -> F {
    x.w_log10()
}

/// Cube root.
#[inline(always)]
pub fn cbrt<F: Float>(x: F) -> F {
    x.w_cbrt()
}

/// Error function (see [`special`] for the accuracy).
#[inline(always)]
pub fn erf<F: Float>(x: F) -> F {
    x.w_erf()
}

/// Complementary error function `1 - erf(x)`, accurate for large `x`.
#[inline(always)]
pub fn erfc<F: Float>(x: F) -> F {
    x.w_erfc()
}

/// Inverse error function: `±inf` at `±1`, NaN outside `[-1, 1]`.
#[inline(always)]
pub fn erfinv<F: Float>(x: F) -> F {
    x.w_erfinv()
}

/// Inverse complementary error function: `+inf` at 0, `-inf` at 2, NaN outside `[0, 2]`.
#[inline(always)]
pub fn erfcinv<F: Float>(x: F) -> F {
    x.w_erfcinv()
}

/// Round to the nearest integer, halfway cases away from zero.
#[inline(always)]
pub fn round<F: Float>(x: F) -> F {
    x.w_round()
}

/// Round to the nearest integer, halfway cases to even.
#[inline(always)]
pub fn rint<F: Float>(x: F) -> F {
    x.w_rint()
}

/// Round toward zero.
#[inline(always)]
pub fn trunc<F: Float>(x: F) -> F {
    x.w_trunc()
}

/// Radians to degrees: `x * (180/π)`, Rust's `to_degrees`.
#[inline(always)]
pub fn degrees<F: Float>(x: F) -> F {
    x.w_degrees()
}

/// Degrees to radians: `x * (π/180)`, Rust's `to_radians`.
#[inline(always)]
pub fn radians<F: Float>(x: F) -> F {
    x.w_radians()
}

/// The fractional part `x - trunc(x)` (Rust's `fract`; negative for negative `x`).
#[inline(always)]
pub fn frac<F: Float>(x: F) -> F {
    x.s_sub(x.w_trunc())
}

/// Warp's `step`: `1` if `x < 0`, else `0` (so `0` for NaN, and always `0` for unsigned).
#[inline(always)]
pub fn step<T: Scalar>(x: T) -> T {
    if x < T::ZERO {
        T::ONE
    } else {
        T::ZERO
    }
}

/// Hermite smoothstep: with `t = clamp((x - e0) / (e1 - e0), 0, 1)`, `t * t * (3 - 2 * t)`.
/// With `e0 == e1` the quotient is infinite or NaN and the clamp gives `0` for `x <= e0`
/// (NaN loses to 0 in the clamp) and `1` above.
#[inline(always)]
pub fn smoothstep<F: Float>(e0: F, e1: F, x: F) -> F {
    e0.w_smoothstep(e1, x)
}

/// `x` is finite (vectors: every component).
#[inline(always)]
pub fn isfinite<T: Classify>(x: T) -> bool {
    x.w_isfinite()
}

/// `x` is NaN (vectors: some component).
#[inline(always)]
pub fn isnan<T: Classify>(x: T) -> bool {
    x.w_isnan()
}

/// `x` is infinite (vectors: some component).
#[inline(always)]
pub fn isinf<T: Classify>(x: T) -> bool {
    x.w_isinf()
}

/// Linear interpolation `a * (1 - t) + b * t` (Warp's form).
#[inline(always)]
pub fn lerp<T: Lerp>(a: T, b: T, t: T::Scalar) -> T {
    a.w_lerp(b, t)
}

/// Dot product, summed left to right; wrapping for integer vectors.
#[inline(always)]
pub fn dot<V: VecOps>(a: V, b: V) -> V::Scalar {
    a.w_dot(b)
}

/// Euclidean length, `sqrt(dot(v, v))`.
#[inline(always)]
pub fn length<V: FloatVec>(v: V) -> V::Scalar {
    v.w_length()
}

/// `v / length(v)`, or the zero vector when `length(v)` is zero (never NaN from a zero vector).
#[inline(always)]
pub fn normalize<V: FloatVec>(v: V) -> V {
    v.w_normalize()
}

/// Cross product of two 3-vectors.
#[inline(always)]
pub fn cross<V: Cross>(a: V, b: V) -> V {
    a.w_cross(b)
}

// ------------------------------------------------------------------------------------------
// Scalar implementations
// ------------------------------------------------------------------------------------------

macro_rules! int_scalar {
    ($($t:ty),*) => {$(
        impl Scalar for $t {
            const ZERO: Self = 0;
            const ONE: Self = 1;
            #[inline(always)] fn s_add(self, o: Self) -> Self { self.wrapping_add(o) }
            #[inline(always)] fn s_sub(self, o: Self) -> Self { self.wrapping_sub(o) }
            #[inline(always)] fn s_mul(self, o: Self) -> Self { self.wrapping_mul(o) }
            #[inline(always)] fn s_neg(self) -> Self { self.wrapping_neg() }
        }
        impl MinMax for $t {
            #[inline(always)] fn w_min(self, o: Self) -> Self { Ord::min(self, o) }
            #[inline(always)] fn w_max(self, o: Self) -> Self { Ord::max(self, o) }
        }
    )*};
}
int_scalar!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);

macro_rules! signed_int {
    ($($t:ty),*) => {$(
        impl Signed for $t {
            #[inline(always)] fn w_abs(self) -> Self { self.wrapping_abs() }
            #[inline(always)] fn w_sign(self) -> Self { if self < 0 { -1 } else { 1 } }
        }
    )*};
}
signed_int!(i8, i16, i32, i64, isize);

/// `x` clamped to `[-1, 1]` by comparisons, so that NaN passes through (`f32::clamp` would
/// too, but `max(min(..))` would not).
#[inline(always)]
fn unit_clamp<F: Float>(x: F) -> F {
    let one = F::ONE;
    let minus_one = F::ZERO.s_sub(one);
    if x < minus_one {
        minus_one
    } else if x > one {
        one
    } else {
        x
    }
}

macro_rules! float_scalar {
    ($($t:ident),*) => {$(
        impl Scalar for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            #[inline(always)] fn s_add(self, o: Self) -> Self { self + o }
            #[inline(always)] fn s_sub(self, o: Self) -> Self { self - o }
            #[inline(always)] fn s_mul(self, o: Self) -> Self { self * o }
            #[inline(always)] fn s_neg(self) -> Self { -self }
        }
        impl MinMax for $t {
            // `f32::min`/`max` are IEEE minNum/maxNum (C's fminf/fmaxf): NaN loses.
            #[inline(always)] fn w_min(self, o: Self) -> Self { $t::min(self, o) }
            #[inline(always)] fn w_max(self, o: Self) -> Self { $t::max(self, o) }
        }
        impl Signed for $t {
            #[inline(always)] fn w_abs(self) -> Self { $t::abs(self) }
            #[inline(always)] fn w_sign(self) -> Self { if self < 0.0 { -1.0 } else { 1.0 } }
        }
        impl Float for $t {
            #[inline(always)] fn w_floor(self) -> Self { $t::floor(self) }
            #[inline(always)] fn w_ceil(self) -> Self { $t::ceil(self) }
            #[inline(always)] fn w_sqrt(self) -> Self { $t::sqrt(self) }
            #[inline(always)] fn w_exp(self) -> Self { $t::exp(self) }
            #[inline(always)] fn w_log(self) -> Self { $t::ln(self) }
            #[inline(always)] fn w_sin(self) -> Self { $t::sin(self) }
            #[inline(always)] fn w_cos(self) -> Self { $t::cos(self) }
            #[inline(always)] fn w_tan(self) -> Self { $t::tan(self) }
            #[inline(always)] fn w_atan2(self, x: Self) -> Self { $t::atan2(self, x) }
            #[inline(always)] fn w_pow(self, y: Self) -> Self { $t::powf(self, y) }
            #[inline(always)] fn w_asin(self) -> Self { unit_clamp(self).asin() }
            #[inline(always)] fn w_acos(self) -> Self { unit_clamp(self).acos() }
            #[inline(always)] fn w_atan(self) -> Self { $t::atan(self) }
            #[inline(always)] fn w_sinh(self) -> Self { $t::sinh(self) }
            #[inline(always)] fn w_cosh(self) -> Self { $t::cosh(self) }
            #[inline(always)] fn w_tanh(self) -> Self { $t::tanh(self) }
            #[inline(always)] fn w_exp2(self) -> Self { $t::exp2(self) }
            #[inline(always)] fn w_log2(self) -> Self { $t::log2(self) }
            #[inline(always)] fn w_log10(self) -> Self { $t::log10(self) }
            #[inline(always)] fn w_cbrt(self) -> Self { $t::cbrt(self) }
            #[inline(always)] fn w_erf(self) -> Self { special::erf(self as f64) as $t }
            #[inline(always)] fn w_erfc(self) -> Self { special::erfc(self as f64) as $t }
            #[inline(always)] fn w_erfinv(self) -> Self { special::erfinv(self as f64) as $t }
            #[inline(always)] fn w_erfcinv(self) -> Self { special::erfcinv(self as f64) as $t }
            #[inline(always)] fn w_round(self) -> Self { $t::round(self) }
            #[inline(always)] fn w_rint(self) -> Self { $t::round_ties_even(self) }
            #[inline(always)] fn w_trunc(self) -> Self { $t::trunc(self) }
            #[inline(always)] fn w_degrees(self) -> Self { $t::to_degrees(self) }
            #[inline(always)] fn w_radians(self) -> Self { $t::to_radians(self) }
            #[inline(always)] fn w_isfinite(self) -> bool { $t::is_finite(self) }
            #[inline(always)] fn w_isnan(self) -> bool { $t::is_nan(self) }
            #[inline(always)] fn w_isinf(self) -> bool { $t::is_infinite(self) }
            #[inline(always)]
            fn w_smoothstep(self, e1: Self, x: Self) -> Self {
                let t = clamp((x - self) / (e1 - self), 0.0, 1.0);
                t * t * (3.0 - 2.0 * t)
            }
        }
        impl Classify for $t {
            #[inline(always)] fn w_isfinite(self) -> bool { $t::is_finite(self) }
            #[inline(always)] fn w_isnan(self) -> bool { $t::is_nan(self) }
            #[inline(always)] fn w_isinf(self) -> bool { $t::is_infinite(self) }
        }
        impl Lerp for $t {
            type Scalar = $t;
            #[inline(always)]
            fn w_lerp(self, b: Self, t: Self) -> Self { self * (1.0 - t) + b * t }
        }
    )*};
}
float_scalar!(f32, f64);

// ------------------------------------------------------------------------------------------
// Vector implementations
// ------------------------------------------------------------------------------------------

/// Componentwise access to a `glam` vector through its component array.
trait Lanes: Copy {
    type S: Scalar;
    fn lane_map(self, f: impl Fn(Self::S) -> Self::S) -> Self;
    fn lane_zip(self, o: Self, f: impl Fn(Self::S, Self::S) -> Self::S) -> Self;
    /// `f(... f(f(init, a.x, b.x), a.y, b.y) ..., a.last, b.last)`.
    fn lane_fold2(
        self,
        o: Self,
        init: Self::S,
        f: impl Fn(Self::S, Self::S, Self::S) -> Self::S,
    ) -> Self::S;
}

/// Lanes plus the operations every vector supports (`min`, `max`, `dot`).
macro_rules! vec_common {
    ($($v:ident: $s:ident),*) => {$(
        impl Lanes for $v {
            type S = $s;
            #[inline(always)]
            fn lane_map(self, f: impl Fn($s) -> $s) -> Self {
                $v::from_array(self.to_array().map(f))
            }
            #[inline(always)]
            fn lane_zip(self, o: Self, f: impl Fn($s, $s) -> $s) -> Self {
                let (a, b) = (self.to_array(), o.to_array());
                $v::from_array(core::array::from_fn(|i| f(a[i], b[i])))
            }
            #[inline(always)]
            fn lane_fold2(self, o: Self, init: $s, f: impl Fn($s, $s, $s) -> $s) -> $s {
                let (a, b) = (self.to_array(), o.to_array());
                let mut acc = init;
                for i in 0..a.len() {
                    acc = f(acc, a[i], b[i]);
                }
                acc
            }
        }
        impl MinMax for $v {
            #[inline(always)] fn w_min(self, o: Self) -> Self { self.lane_zip(o, <$s as MinMax>::w_min) }
            #[inline(always)] fn w_max(self, o: Self) -> Self { self.lane_zip(o, <$s as MinMax>::w_max) }
        }
        impl VecOps for $v {
            type Scalar = $s;
            #[inline(always)]
            fn w_dot(self, o: Self) -> $s {
                self.lane_fold2(o, <$s as Scalar>::ZERO, |acc, x, y| acc.s_add(x.s_mul(y)))
            }
        }
    )*};
}
vec_common!(
    Vec2: f32, Vec3: f32, Vec4: f32,
    DVec2: f64, DVec3: f64, DVec4: f64,
    IVec2: i32, IVec3: i32, IVec4: i32,
    UVec2: u32, UVec3: u32, UVec4: u32
);

macro_rules! vec_signed {
    ($($v:ident: $s:ident),*) => {$(
        impl Signed for $v {
            #[inline(always)] fn w_abs(self) -> Self { self.lane_map(<$s as Signed>::w_abs) }
            #[inline(always)] fn w_sign(self) -> Self { self.lane_map(<$s as Signed>::w_sign) }
        }
    )*};
}
vec_signed!(
    Vec2: f32, Vec3: f32, Vec4: f32,
    DVec2: f64, DVec3: f64, DVec4: f64,
    IVec2: i32, IVec3: i32, IVec4: i32
);

macro_rules! vec_float {
    ($($v:ident: $s:ident),*) => {$(
        impl Lerp for $v {
            type Scalar = $s;
            #[inline(always)]
            fn w_lerp(self, b: Self, t: $s) -> Self {
                self.lane_zip(b, |x, y| x.w_lerp(y, t))
            }
        }
        impl FloatVec for $v {
            // Rescaled where the squares would overflow or underflow (see `norm`).
            #[inline(always)]
            fn w_length(self) -> $s {
                super::norm::length(self)
            }
            #[inline(always)]
            fn w_normalize(self) -> Self {
                super::norm::normalize(self)
            }
        }
    )*};
}
vec_float!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64);

// `lerp` of square matrices (lane by lane, column-major as glam stores them) and quaternions
// (lane by lane, `x, y, z, w`, not renormalized: Warp's, unlike glam's `Quat::lerp`).
macro_rules! lanes_lerp {
    ($($t:ident: $s:ident, $to:ident, $from:expr);* $(;)?) => {$(
        impl Lerp for $t {
            type Scalar = $s;
            #[inline(always)]
            fn w_lerp(self, b: Self, t: $s) -> Self {
                let (x, y) = (self.$to(), b.$to());
                let from: fn(_) -> Self = $from;
                from(core::array::from_fn(|k| x[k].w_lerp(y[k], t)))
            }
        }
    )*};
}
lanes_lerp!(
    Mat2: f32, to_cols_array, |a| Mat2::from_cols_array(&a);
    Mat3: f32, to_cols_array, |a| Mat3::from_cols_array(&a);
    Mat4: f32, to_cols_array, |a| Mat4::from_cols_array(&a);
    DMat2: f64, to_cols_array, |a| DMat2::from_cols_array(&a);
    DMat3: f64, to_cols_array, |a| DMat3::from_cols_array(&a);
    DMat4: f64, to_cols_array, |a| DMat4::from_cols_array(&a);
    Quat: f32, to_array, Quat::from_array;
    DQuat: f64, to_array, DQuat::from_array;
);

macro_rules! vec_classify {
    ($($v:ident),*) => {$(
        impl Classify for $v {
            #[inline(always)] fn w_isfinite(self) -> bool { self.to_array().iter().all(|x| x.is_finite()) }
            #[inline(always)] fn w_isnan(self) -> bool { self.to_array().iter().any(|x| x.is_nan()) }
            #[inline(always)] fn w_isinf(self) -> bool { self.to_array().iter().any(|x| x.is_infinite()) }
        }
    )*};
}
vec_classify!(Vec2, Vec3, Vec4, DVec2, DVec3, DVec4);

macro_rules! vec_cross {
    ($($v:ident),*) => {$(
        impl Cross for $v {
            #[inline(always)]
            fn w_cross(self, o: Self) -> Self {
                let (a, b) = (self, o);
                $v::new(
                    a.y.s_mul(b.z).s_sub(a.z.s_mul(b.y)),
                    a.z.s_mul(b.x).s_sub(a.x.s_mul(b.z)),
                    a.x.s_mul(b.y).s_sub(a.y.s_mul(b.x)),
                )
            }
        }
    )*};
}
vec_cross!(Vec3, DVec3, IVec3);

// ------------------------------------------------------------------------------------------
// Tests
// ------------------------------------------------------------------------------------------

#[cfg(test)]
mod tests {
    use super::*;

    fn same_f32(a: f32, b: f32) -> bool {
        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())
    }

    #[test]
    fn min_max_ints() {
        assert_eq!(min(3i8, -4), -4);
        assert_eq!(max(3i16, -4), 3);
        assert_eq!(min(i32::MIN, i32::MAX), i32::MIN);
        assert_eq!(max(i64::MIN, 0), 0);
        assert_eq!(min(7u8, 200), 7);
        assert_eq!(max(7u16, 200), 200);
        assert_eq!(min(u32::MAX, 0), 0);
        assert_eq!(max(u64::MAX, 1), u64::MAX);
        // usize: what tid() returns.
        assert_eq!(min(7usize, 3), 3);
        assert_eq!(clamp(-5isize, -2, 2), -2);
        assert_eq!(abs(-5isize), 5);
    }

    #[test]
    fn min_max_floats_nan() {
        assert_eq!(min(1.5f32, -2.0), -2.0);
        assert_eq!(max(1.5f64, -2.0), 1.5);
        assert_eq!(min(f32::NAN, 2.0), 2.0);
        assert_eq!(min(2.0f32, f32::NAN), 2.0);
        assert_eq!(max(f32::NAN, 2.0), 2.0);
        assert_eq!(max(2.0f64, f64::NAN), 2.0);
        assert!(min(f64::NAN, f64::NAN).is_nan());
        assert_eq!(min(f32::NEG_INFINITY, 0.0), f32::NEG_INFINITY);
        assert_eq!(max(f64::INFINITY, 0.0), f64::INFINITY);
    }

    #[test]
    fn min_max_vectors() {
        // Vec4 is SIMD-backed on x86_64: NaN must still lose, componentwise.
        let a = Vec4::new(f32::NAN, 1.0, -3.0, 5.0);
        let b = Vec4::new(2.0, f32::NAN, -4.0, 6.0);
        assert_eq!(min(a, b), Vec4::new(2.0, 1.0, -4.0, 5.0));
        assert_eq!(max(a, b), Vec4::new(2.0, 1.0, -3.0, 6.0));
        assert_eq!(min(Vec2::new(1.0, 2.0), Vec2::new(2.0, 1.0)), Vec2::ONE);
        assert_eq!(
            max(Vec3::new(1.0, f32::NAN, 0.0), Vec3::ZERO),
            Vec3::new(1.0, 0.0, 0.0)
        );
        assert_eq!(
            min(DVec3::new(1.0, -2.0, f64::NAN), DVec3::ZERO),
            DVec3::new(0.0, -2.0, 0.0)
        );
        assert_eq!(
            max(DVec2::new(1.0, -2.0), DVec2::ZERO),
            DVec2::new(1.0, 0.0)
        );
        assert_eq!(max(DVec4::splat(-1.0), DVec4::ZERO), DVec4::ZERO);
        assert_eq!(
            min(IVec3::new(i32::MIN, 5, 0), IVec3::new(0, -5, 0)),
            IVec3::new(i32::MIN, -5, 0)
        );
        assert_eq!(max(IVec2::new(1, -1), IVec2::ZERO), IVec2::new(1, 0));
        assert_eq!(
            max(IVec4::new(1, -1, 3, -3), IVec4::ZERO),
            IVec4::new(1, 0, 3, 0)
        );
        assert_eq!(
            min(UVec3::new(u32::MAX, 5, 0), UVec3::splat(4)),
            UVec3::new(4, 4, 0)
        );
        assert_eq!(max(UVec2::new(1, 9), UVec2::splat(4)), UVec2::new(4, 9));
        assert_eq!(
            max(UVec4::new(1, 9, 4, 0), UVec4::splat(4)),
            UVec4::new(4, 9, 4, 4)
        );
    }

    #[test]
    fn clamp_never_panics() {
        assert_eq!(clamp(5i32, 0, 3), 3);
        assert_eq!(clamp(-5i32, 0, 3), 0);
        assert_eq!(clamp(2u8, 0, 3), 2);
        // lo > hi: min(max(x, lo), hi) == hi.
        assert_eq!(clamp(1i32, 10, 0), 0);
        assert_eq!(clamp(1.0f32, 10.0, 0.0), 0.0);
        assert_eq!(clamp(0.5f64, 0.0, 1.0), 0.5);
        // NaN input: max(NaN, lo) = lo.
        assert_eq!(clamp(f32::NAN, 0.0, 1.0), 0.0);
        assert_eq!(
            clamp(Vec3::new(-1.0, 0.5, 2.0), Vec3::ZERO, Vec3::ONE),
            Vec3::new(0.0, 0.5, 1.0)
        );
        assert_eq!(
            clamp(IVec2::new(-7, 7), IVec2::splat(5), IVec2::splat(-5)),
            IVec2::splat(-5)
        );
        assert_eq!(
            clamp(UVec4::new(0, 3, 9, 5), UVec4::splat(2), UVec4::splat(5)),
            UVec4::new(2, 3, 5, 5)
        );
    }

    #[test]
    fn abs_and_sign() {
        assert_eq!(abs(i32::MIN), i32::MIN);
        assert_eq!(abs(i8::MIN), i8::MIN);
        assert_eq!(abs(-5i16), 5);
        assert_eq!(abs(-5i64), 5);
        assert_eq!(abs(-0.0f32).to_bits(), 0.0f32.to_bits());
        assert_eq!(abs(-2.5f64), 2.5);
        assert!(abs(f32::NAN).is_nan());
        assert_eq!(abs(IVec3::new(i32::MIN, -1, 2)), IVec3::new(i32::MIN, 1, 2));
        assert_eq!(
            abs(Vec4::new(-1.0, 2.0, -0.0, -3.0)),
            Vec4::new(1.0, 2.0, 0.0, 3.0)
        );
        assert_eq!(abs(DVec2::new(-1.0, 2.0)), DVec2::new(1.0, 2.0));

        assert_eq!(sign(0i32), 1);
        assert_eq!(sign(-3i8), -1);
        assert_eq!(sign(i64::MIN), -1);
        assert_eq!(sign(7i16), 1);
        assert_eq!(sign(0.0f32), 1.0);
        assert_eq!(sign(-0.0f32), 1.0);
        assert_eq!(sign(-0.0f64), 1.0);
        assert_eq!(sign(f32::NAN), 1.0);
        assert_eq!(sign(-1e-30f32), -1.0);
        assert_eq!(sign(f64::NEG_INFINITY), -1.0);
        assert_eq!(sign(Vec3::new(-2.0, 0.0, 3.0)), Vec3::new(-1.0, 1.0, 1.0));
        assert_eq!(
            sign(DVec4::new(-2.0, -0.0, 3.0, f64::NAN)),
            DVec4::new(-1.0, 1.0, 1.0, 1.0)
        );
        assert_eq!(sign(IVec2::new(-9, 0)), IVec2::new(-1, 1));
    }

    #[test]
    fn float_functions() {
        let xs32 = [0.0f32, -0.0, 0.5, -1.5, 2.0, 10.25, f32::INFINITY, f32::NAN];
        for &x in &xs32 {
            assert!(same_f32(floor(x), x.floor()));
            assert!(same_f32(ceil(x), x.ceil()));
            assert!(same_f32(sqrt(x), x.sqrt()));
            assert!(same_f32(exp(x), x.exp()));
            assert!(same_f32(log(x), x.ln()));
            assert!(same_f32(sin(x), x.sin()));
            assert!(same_f32(cos(x), x.cos()));
            assert!(same_f32(tan(x), x.tan()));
            assert!(same_f32(atan2(x, 1.5), x.atan2(1.5)));
            assert!(same_f32(pow(x, 3.0), x.powf(3.0)));
        }
        assert_eq!(floor(-1.5f64), -2.0);
        assert_eq!(ceil(-1.5f64), -1.0);
        assert_eq!(sqrt(16.0f64), 4.0);
        assert!(sqrt(-1.0f64).is_nan());
        assert_eq!(exp(0.0f64), 1.0);
        assert_eq!(log(1.0f64), 0.0);
        assert_eq!(log(0.0f64), f64::NEG_INFINITY);
        assert_eq!(log(std::f64::consts::E), 1.0);
        assert_eq!(sin(0.0f64), 0.0);
        assert_eq!(cos(0.0f64), 1.0);
        assert_eq!(tan(0.0f64), 0.0);
        assert_eq!(atan2(1.0f64, 0.0), std::f64::consts::FRAC_PI_2);
        assert_eq!(atan2(0.0f64, -1.0), std::f64::consts::PI);
        assert_eq!(pow(2.0f64, 10.0), 1024.0);
        assert_eq!(pow(0.0f64, 0.0), 1.0);
    }

    #[test]
    fn lerp_warp_form() {
        assert_eq!(lerp(2.0f32, 6.0, 0.25), 3.0);
        assert_eq!(lerp(2.0f64, 6.0, 0.0), 2.0);
        assert_eq!(lerp(2.0f64, 6.0, 1.0), 6.0);
        // Warp's form a*(1-t) + b*t, not a + (b-a)*t.
        let (a, b, t) = (1e8f32, 1.0f32, 0.3f32);
        assert_eq!(lerp(a, b, t).to_bits(), (a * (1.0 - t) + b * t).to_bits());
        assert_eq!(
            lerp(Vec2::ZERO, Vec2::new(2.0, 4.0), 0.5),
            Vec2::new(1.0, 2.0)
        );
        assert_eq!(
            lerp(Vec3::ZERO, Vec3::new(2.0, 4.0, 8.0), 0.5),
            Vec3::new(1.0, 2.0, 4.0)
        );
        assert_eq!(lerp(Vec4::ONE, Vec4::splat(3.0), 0.5), Vec4::splat(2.0));
        assert_eq!(lerp(DVec2::ONE, DVec2::splat(3.0), 0.5), DVec2::splat(2.0));
        assert_eq!(lerp(DVec3::ONE, DVec3::splat(3.0), 0.5), DVec3::splat(2.0));
        assert_eq!(lerp(DVec4::ONE, DVec4::splat(3.0), 2.0), DVec4::splat(5.0));
    }

    #[test]
    fn dot_length_normalize_cross() {
        assert_eq!(dot(Vec2::new(1.0, 2.0), Vec2::new(3.0, 4.0)), 11.0);
        assert_eq!(
            dot(Vec3::new(1.0, 2.0, 3.0), Vec3::new(4.0, 5.0, 6.0)),
            32.0
        );
        assert_eq!(dot(Vec4::new(1.0, 2.0, 3.0, 4.0), Vec4::ONE), 10.0);
        // Left-to-right summation order.
        let a = Vec4::new(1e8, 1.0, -1e8, 1.0);
        assert_eq!(dot(a, Vec4::ONE), ((1e8f32 + 1.0) + -1e8) + 1.0);
        assert_eq!(dot(DVec3::new(1.0, 2.0, 3.0), DVec3::ONE), 6.0);
        assert_eq!(dot(DVec2::new(1.0, 2.0), DVec2::ONE), 3.0);
        assert_eq!(dot(DVec4::new(1.0, 2.0, 3.0, 4.0), DVec4::ONE), 10.0);
        assert_eq!(dot(IVec3::new(1, -2, 3), IVec3::new(4, 5, 6)), 12);
        // Integer dot wraps like CUDA instead of panicking.
        assert_eq!(
            dot(IVec2::new(i32::MAX, 1), IVec2::new(2, 0)),
            i32::MAX.wrapping_mul(2)
        );
        assert_eq!(dot(IVec4::ONE, IVec4::ONE), 4);
        assert_eq!(dot(UVec2::new(u32::MAX, 1), UVec2::new(1, 1)), 0);
        assert_eq!(dot(UVec3::new(1, 2, 3), UVec3::ONE), 6);
        assert_eq!(dot(UVec4::new(1, 2, 3, 4), UVec4::ONE), 10);

        assert_eq!(length(Vec2::new(3.0, 4.0)), 5.0);
        assert_eq!(length(DVec3::new(2.0, 3.0, 6.0)), 7.0);
        assert_eq!(length(Vec4::ZERO), 0.0);

        assert_eq!(normalize(Vec3::ZERO), Vec3::ZERO);
        assert_eq!(normalize(Vec2::ZERO), Vec2::ZERO);
        assert_eq!(normalize(Vec4::ZERO), Vec4::ZERO);
        assert_eq!(normalize(DVec3::ZERO), DVec3::ZERO);
        assert_eq!(normalize(DVec2::ZERO), DVec2::ZERO);
        assert_eq!(normalize(DVec4::ZERO), DVec4::ZERO);
        assert_eq!(
            normalize(Vec3::new(0.0, 3.0, 4.0)),
            Vec3::new(0.0, 0.6, 0.8)
        );
        assert_eq!(normalize(DVec2::new(0.0, -2.0)), DVec2::new(0.0, -1.0));
        let v = Vec4::new(1.0, 2.0, 3.0, 4.0);
        let l = (1.0f32 + 4.0 + 9.0 + 16.0).sqrt();
        assert_eq!(normalize(v), Vec4::new(1.0 / l, 2.0 / l, 3.0 / l, 4.0 / l));
        // The squared norm overflows (and underflows) here; the rescaled path still gives
        // the exact results (see `norm`).
        assert_eq!(normalize(Vec2::new(f32::MAX, 0.0)), Vec2::X);
        assert_eq!(length(Vec2::new(f32::MAX, 0.0)), f32::MAX);
        assert_eq!(normalize(Vec3::new(0.0, -1e-40, 0.0)), Vec3::NEG_Y);
        assert_eq!(length(Vec2::new(3e-30, 4e-30)), 5e-30);
        let p = 2f64.powi(600);
        assert_eq!(length(DVec2::new(3.0 * p, -4.0 * p)), 5.0 * p);
        // An infinite component: the plain formula's IEEE results.
        assert_eq!(length(Vec2::new(f32::INFINITY, 1.0)), f32::INFINITY);
        assert!(length(Vec2::new(f32::INFINITY, f32::NAN)).is_nan());

        assert_eq!(cross(Vec3::X, Vec3::Y), Vec3::Z);
        assert_eq!(cross(DVec3::Y, DVec3::X), -DVec3::Z);
        assert_eq!(
            cross(IVec3::new(1, 2, 3), IVec3::new(4, 5, 6)),
            IVec3::new(-3, 6, -3)
        );
        assert_eq!(
            cross(IVec3::new(i32::MAX, 0, 0), IVec3::new(0, 2, 0)),
            IVec3::new(0, 0, i32::MAX.wrapping_mul(2))
        );
    }
}

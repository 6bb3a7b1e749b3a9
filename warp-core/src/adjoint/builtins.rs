//! Adjoints of the builtins (the entries of the builtin table with `Grad::Adjoint`, plus
//! no-op adjoints for the piecewise-constant `floor`, `ceil` and `sign`).
//!
//! `adj_<name>(<the builtin's arguments>, <one &mut adjoint per argument>, adj_ret)`: each
//! accumulates (`+=`) into the argument adjoints. The rules at non-differentiable points
//! follow what the forward builtin in [`crate::builtins::math`] returned:
//!
//! * `min`/`max`: the whole adjoint goes to the operand the forward returned; on ties to the
//!   first; with exactly one NaN operand to the other (IEEE `fmin`/`fmax`); with two NaNs to
//!   the first. Componentwise for vectors.
//! * `clamp(x, lo, hi) = min(max(x, lo), hi)`: the `min` rule, then the `max` rule, so the
//!   adjoint goes to `x` when `lo <= x <= hi` (bounds included), else to the bound returned.
//! * `abs`: `sign(x)` with `sign(0) = sign(-0) = +1`.
//! * `length`, `normalize`: zero gradient at the zero vector (where the forward returns 0).
//! * `pow(x, y)`: `d/dx` is skipped when `y == 0`; `d/dy` only when `x > 0` (see
//!   [`adj_pow`]).
//! * `atan2`: zero gradient at `(0, 0)`.
//! * `sqrt` at `0` and `log` at `0`: infinite, as in Warp (`inf * adj_ret`); likewise
//!   `cbrt`, `log2`, `log10` at 0, `erfinv` at `±1`, `erfcinv` at 0 and 2.
//! * `asin`/`acos`: nothing at `|x| >= 1`, where the forward's clamp is flat.
//! * `smoothstep`: nothing outside `0 < t < 1` (clamped), nor when `e0 == e1`.
//! * `frac`: slope 1; `round`, `rint`, `trunc`, `step`: no-ops; `isfinite`, `isnan`, `isinf`
//!   return `bool` and have no adjoint.
//!
//! Integer operands (scalars and vectors) have no-op adjoints.

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};

use super::lanes::{l_abs, l_lerp, l_max, l_min, map1, zip_vv};
use super::{AdjFloat, Adjoint};
use crate::builtins::math::{Cross, FloatVec, Lerp, MinMax, Signed, VecOps};
use crate::spatial::{DSpatialMatrix, DSpatialVector, SpatialMatrix, SpatialVector};

// ------------------------------------------------------------------------------------------
// min, max, clamp
// ------------------------------------------------------------------------------------------

/// Adjoints of `min` and `max` (and so `clamp`): all integer and float scalars and the glam
/// vectors, like [`MinMax`]; no-ops for integers.
pub trait AdjMinMax: MinMax + Adjoint {
    /// The adjoint of `min(a, b)` (see [`adj_min`]).
    fn adj_min(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self);
    /// The adjoint of `max(a, b)` (see [`adj_max`]).
    fn adj_max(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self);
}

/// Adjoint of `min(a, b)`, componentwise: `adj_ret` goes whole to the operand returned
/// (`a` if `a <= b` or `b` alone is NaN or both are NaN, else `b`).
#[inline(always)]
pub fn adj_min<T: AdjMinMax>(a: T, b: T, adj_a: &mut T, adj_b: &mut T, adj_ret: T) {
    T::adj_min(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `max(a, b)`, componentwise: `adj_ret` goes whole to the operand returned
/// (`a` if `a >= b` or `b` alone is NaN or both are NaN, else `b`).
#[inline(always)]
pub fn adj_max<T: AdjMinMax>(a: T, b: T, adj_a: &mut T, adj_b: &mut T, adj_ret: T) {
    T::adj_max(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoint of `clamp(x, lo, hi) = min(max(x, lo), hi)`, componentwise, through the [`adj_min`]
/// and [`adj_max`] rules in reverse evaluation order: `adj_ret` goes to `x` when
/// `lo <= x <= hi`, else to the bound the forward returned (`hi` whenever `lo > hi`; `lo`
/// when `x` is NaN and `lo <= hi`).
#[inline(always)]
pub fn adj_clamp<T: AdjMinMax>(
    x: T,
    lo: T,
    hi: T,
    adj_x: &mut T,
    adj_lo: &mut T,
    adj_hi: &mut T,
    adj_ret: T,
) {
    let m = x.w_max(lo);
    let mut adj_m = T::adj_zero();
    T::adj_min(m, hi, &mut adj_m, adj_hi, adj_ret);
    T::adj_max(x, lo, adj_x, adj_lo, adj_m);
}

macro_rules! noop_minmax {
    ($($t:ty),*) => {$(
        impl AdjMinMax for $t {
            #[inline(always)]
            fn adj_min(_a: $t, _b: $t, _adj_a: &mut $t, _adj_b: &mut $t, _adj_ret: $t) {}
            #[inline(always)]
            fn adj_max(_a: $t, _b: $t, _adj_a: &mut $t, _adj_b: &mut $t, _adj_ret: $t) {}
        }
    )*};
}
noop_minmax!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);
noop_minmax!(IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);

macro_rules! float_minmax {
    ($($t:ident),*) => {$(
        impl AdjMinMax for $t {
            #[inline(always)]
            fn adj_min(a: $t, b: $t, adj_a: &mut $t, adj_b: &mut $t, adj_ret: $t) {
                l_min(a, b, adj_a, adj_b, adj_ret)
            }
            #[inline(always)]
            fn adj_max(a: $t, b: $t, adj_a: &mut $t, adj_b: &mut $t, adj_ret: $t) {
                l_max(a, b, adj_a, adj_b, adj_ret)
            }
        }
    )*};
}
float_minmax!(f32, f64);

macro_rules! fvec_minmax {
    ($($t:ident),*) => {$(
        impl AdjMinMax for $t {
            #[inline(always)]
            fn adj_min(a: $t, b: $t, adj_a: &mut $t, adj_b: &mut $t, adj_ret: $t) {
                zip_vv(a, b, adj_a, adj_b, adj_ret, l_min)
            }
            #[inline(always)]
            fn adj_max(a: $t, b: $t, adj_a: &mut $t, adj_b: &mut $t, adj_ret: $t) {
                zip_vv(a, b, adj_a, adj_b, adj_ret, l_max)
            }
        }
    )*};
}
fvec_minmax!(Vec2, Vec3, Vec4, DVec2, DVec3, DVec4);

// ------------------------------------------------------------------------------------------
// abs, sign, floor, ceil
// ------------------------------------------------------------------------------------------

/// Adjoint of `abs`: signed integers, floats, `Vec2-4`, `DVec2-4`, `IVec2-4`, like
/// [`Signed`]; a no-op for integers.
pub trait AdjSigned: Signed + Adjoint {
    /// The adjoint of `abs(x)` (see [`adj_abs`]).
    fn adj_abs(x: Self, adj_x: &mut Self, adj_ret: Self);
}

/// Adjoint of `abs(x)`, componentwise: `adj_x += adj_ret * sign(x)`, where `sign(x)` is `-1`
/// if `x < 0`, else `+1` (so `+1` at `0`, `-0.0` and NaN, as the forward `sign`).
#[inline(always)]
pub fn adj_abs<T: AdjSigned>(x: T, adj_x: &mut T, adj_ret: T) {
    T::adj_abs(x, adj_x, adj_ret)
}

/// Adjoint of `sign(x)`: piecewise constant, so nothing to accumulate (a no-op).
#[inline(always)]
pub fn adj_sign<T: Signed + Adjoint>(_x: T, _adj_x: &mut T, _adj_ret: T) {}

/// Adjoint of `floor(x)`: piecewise constant, so nothing to accumulate (a no-op).
#[inline(always)]
pub fn adj_floor<F: AdjFloat>(_x: F, _adj_x: &mut F, _adj_ret: F) {}

/// Adjoint of `ceil(x)`: piecewise constant, so nothing to accumulate (a no-op).
#[inline(always)]
pub fn adj_ceil<F: AdjFloat>(_x: F, _adj_x: &mut F, _adj_ret: F) {}

macro_rules! noop_signed {
    ($($t:ty),*) => {$(
        impl AdjSigned for $t {
            #[inline(always)]
            fn adj_abs(_x: $t, _adj_x: &mut $t, _adj_ret: $t) {}
        }
    )*};
}
noop_signed!(i8, i16, i32, i64, isize, IVec2, IVec3, IVec4);

impl AdjSigned for f32 {
    #[inline(always)]
    fn adj_abs(x: f32, adj_x: &mut f32, adj_ret: f32) {
        l_abs(x, adj_x, adj_ret)
    }
}
impl AdjSigned for f64 {
    #[inline(always)]
    fn adj_abs(x: f64, adj_x: &mut f64, adj_ret: f64) {
        l_abs(x, adj_x, adj_ret)
    }
}

macro_rules! fvec_signed {
    ($($t:ident),*) => {$(
        impl AdjSigned for $t {
            #[inline(always)]
            fn adj_abs(x: $t, adj_x: &mut $t, adj_ret: $t) {
                map1(x, adj_x, adj_ret, l_abs)
            }
        }
    )*};
}
fvec_signed!(Vec2, Vec3, Vec4, DVec2, DVec3, DVec4);

// ------------------------------------------------------------------------------------------
// Float scalar functions
// ------------------------------------------------------------------------------------------

/// Adjoint of `sqrt(x)`: `adj_x += adj_ret * (0.5 / sqrt(x))`. Infinite at `x = 0` (so
/// `inf * adj_ret`, which is NaN when `adj_ret` is 0), NaN for `x < 0`, as in Warp.
#[inline(always)]
pub fn adj_sqrt<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    let half = F::ONE / (F::ONE + F::ONE);
    *adj_x += adj_ret * (half / x.w_sqrt());
}

/// Adjoint of `exp(x)`: `adj_x += adj_ret * exp(x)`.
#[inline(always)]
pub fn adj_exp<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret * x.w_exp();
}

/// Adjoint of `log(x)` (natural logarithm): `adj_x += adj_ret / x` (infinite at `x = 0`).
#[inline(always)]
pub fn adj_log<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret / x;
}

/// Adjoint of `sin(x)`: `adj_x += adj_ret * cos(x)`.
#[inline(always)]
pub fn adj_sin<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret * x.w_cos();
}

/// Adjoint of `cos(x)`: `adj_x -= adj_ret * sin(x)`.
#[inline(always)]
pub fn adj_cos<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x -= adj_ret * x.w_sin();
}

/// Adjoint of `tan(x)`: `c = cos(x); adj_x += adj_ret / (c * c)`.
#[inline(always)]
pub fn adj_tan<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    let c = x.w_cos();
    *adj_x += adj_ret / (c * c);
}

/// Adjoint of `atan2(y, x)`: with `d = x * x + y * y`, `adj_y += adj_ret * (x / d)` and
/// `adj_x -= adj_ret * (y / d)`; nothing when `x == 0 && y == 0`, where `atan2` has no
/// derivative (so that the origin never produces NaN).
#[inline(always)]
pub fn adj_atan2<F: AdjFloat>(y: F, x: F, adj_y: &mut F, adj_x: &mut F, adj_ret: F) {
    if x == F::ZERO && y == F::ZERO {
        return;
    }
    let d = x * x + y * y;
    *adj_y += adj_ret * (x / d);
    *adj_x -= adj_ret * (y / d);
}

/// Adjoint of `pow(x, y) = x^y`.
///
/// * `adj_x += adj_ret * (y * pow(x, y - 1))`, except when `y == 0`: `x^0 = 1` for every `x`
///   (NaN and 0 included), so its derivative is exactly 0, where the formula would give
///   `0 * inf = NaN` at `x = 0`.
/// * `adj_y += adj_ret * (pow(x, y) * log(x))` **only when `x > 0`**. For `x = 0` the
///   derivative in `y` is 0 wherever `0^y` is finite (`y > 0`), the limit of `x^y ln x`; for
///   `x < 0`, `x^y` is real only at integer `y` and has no derivative in `y`. So for `x <= 0`
///   (and NaN `x`) `adj_y` receives nothing, and is never made NaN by a zero `adj_ret`.
#[inline(always)]
pub fn adj_pow<F: AdjFloat>(x: F, y: F, adj_x: &mut F, adj_y: &mut F, adj_ret: F) {
    if y != F::ZERO {
        *adj_x += adj_ret * (y * x.w_pow(y - F::ONE));
    }
    if x > F::ZERO {
        *adj_y += adj_ret * (x.w_pow(y) * x.w_log());
    }
}

/// Adjoint of `asin(x)` (argument clamped to `[-1, 1]`): with `d = sqrt(1 - x * x)`,
/// `adj_x += adj_ret / d` when `d > 0`; nothing at `|x| >= 1` (the clamp is flat there, and
/// the derivative at `±1` is infinite) nor for NaN.
#[inline(always)]
pub fn adj_asin<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    let d = (F::ONE - x * x).w_sqrt();
    if d > F::ZERO {
        *adj_x += adj_ret / d;
    }
}

/// Adjoint of `acos(x)`: with `d = sqrt(1 - x * x)`, `adj_x -= adj_ret / d` when `d > 0`
/// (as [`adj_asin`]).
#[inline(always)]
pub fn adj_acos<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    let d = (F::ONE - x * x).w_sqrt();
    if d > F::ZERO {
        *adj_x -= adj_ret / d;
    }
}

/// Adjoint of `atan(x)`: `adj_x += adj_ret / (x * x + 1)`.
#[inline(always)]
pub fn adj_atan<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret / (x * x + F::ONE);
}

/// Adjoint of `sinh(x)`: `adj_x += adj_ret * cosh(x)`.
#[inline(always)]
pub fn adj_sinh<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret * x.w_cosh();
}

/// Adjoint of `cosh(x)`: `adj_x += adj_ret * sinh(x)`.
#[inline(always)]
pub fn adj_cosh<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret * x.w_sinh();
}

/// Adjoint of `tanh(x)`: `t = tanh(x); adj_x += adj_ret * (1 - t * t)`.
#[inline(always)]
pub fn adj_tanh<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    let t = x.w_tanh();
    *adj_x += adj_ret * (F::ONE - t * t);
}

/// Adjoint of `exp2(x)`: `adj_x += adj_ret * (exp2(x) * ln 2)`.
#[inline(always)]
pub fn adj_exp2<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret * (x.w_exp2() * F::LN_2);
}

/// Adjoint of `log2(x)`: `adj_x += adj_ret / (x * ln 2)` (infinite at `x = 0`).
#[inline(always)]
pub fn adj_log2<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret / (x * F::LN_2);
}

/// Adjoint of `log10(x)`: `adj_x += adj_ret / (x * ln 10)` (infinite at `x = 0`).
#[inline(always)]
pub fn adj_log10<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret / (x * F::LN_10);
}

/// Adjoint of `cbrt(x)`: `c = cbrt(x); adj_x += adj_ret / (3 * (c * c))` (infinite at `x = 0`,
/// as `sqrt`'s).
#[inline(always)]
pub fn adj_cbrt<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    let c = x.w_cbrt();
    let three = F::ONE + F::ONE + F::ONE;
    *adj_x += adj_ret / (three * (c * c));
}

/// Adjoint of `erf(x)`: `adj_x += adj_ret * (2/√π * exp(-(x * x)))`.
#[inline(always)]
pub fn adj_erf<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret * (F::FRAC_2_SQRT_PI * (-(x * x)).w_exp());
}

/// Adjoint of `erfc(x)`: `adj_x -= adj_ret * (2/√π * exp(-(x * x)))`.
#[inline(always)]
pub fn adj_erfc<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x -= adj_ret * (F::FRAC_2_SQRT_PI * (-(x * x)).w_exp());
}

/// Adjoint of `erfinv(x)`: `r = erfinv(x); adj_x += adj_ret * (√π/2 * exp(r * r))` (infinite
/// at `±1`).
#[inline(always)]
pub fn adj_erfinv<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    let r = x.w_erfinv();
    *adj_x += adj_ret * (F::SQRT_PI_2 * (r * r).w_exp());
}

/// Adjoint of `erfcinv(x)`: `r = erfcinv(x); adj_x -= adj_ret * (√π/2 * exp(r * r))`
/// (infinite at 0 and 2).
#[inline(always)]
pub fn adj_erfcinv<F: AdjFloat>(x: F, adj_x: &mut F, adj_ret: F) {
    let r = x.w_erfcinv();
    *adj_x -= adj_ret * (F::SQRT_PI_2 * (r * r).w_exp());
}

/// Adjoint of `round(x)`: piecewise constant, a no-op.
#[inline(always)]
pub fn adj_round<F: AdjFloat>(_x: F, _adj_x: &mut F, _adj_ret: F) {}

/// Adjoint of `rint(x)`: piecewise constant, a no-op.
#[inline(always)]
pub fn adj_rint<F: AdjFloat>(_x: F, _adj_x: &mut F, _adj_ret: F) {}

/// Adjoint of `trunc(x)`: piecewise constant, a no-op.
#[inline(always)]
pub fn adj_trunc<F: AdjFloat>(_x: F, _adj_x: &mut F, _adj_ret: F) {}

/// Adjoint of `frac(x) = x - trunc(x)`: `adj_x += adj_ret` (slope 1 between integers; Warp's
/// own `adj_frac` leaves this out).
#[inline(always)]
pub fn adj_frac<F: AdjFloat>(_x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret;
}

/// Adjoint of `step(x)`: piecewise constant, a no-op (integers included).
#[inline(always)]
pub fn adj_step<T: crate::builtins::math::Scalar + Adjoint>(_x: T, _adj_x: &mut T, _adj_ret: T) {}

/// Adjoint of `degrees(x)`: `adj_x += adj_ret * degrees(1)` (the same constant as the forward).
#[inline(always)]
pub fn adj_degrees<F: AdjFloat>(_x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret * F::ONE.w_degrees();
}

/// Adjoint of `radians(x)`: `adj_x += adj_ret * radians(1)`.
#[inline(always)]
pub fn adj_radians<F: AdjFloat>(_x: F, adj_x: &mut F, adj_ret: F) {
    *adj_x += adj_ret * F::ONE.w_radians();
}

/// Adjoint of `smoothstep(e0, e1, x)`: with `d = e1 - e0` and `t = (x - e0) / d`, only when
/// `0 < t < 1` (elsewhere, at the clamp, for `e0 == e1` and for NaN the result is constant):
/// `g = adj_ret * (6 * t * (1 - t) / d)`, then `adj_x += g`, `adj_e0 += g * (t - 1)`,
/// `adj_e1 -= g * t`.
#[inline(always)]
pub fn adj_smoothstep<F: AdjFloat>(
    e0: F,
    e1: F,
    x: F,
    adj_e0: &mut F,
    adj_e1: &mut F,
    adj_x: &mut F,
    adj_ret: F,
) {
    let d = e1 - e0;
    let t = (x - e0) / d;
    if t > F::ZERO && t < F::ONE {
        let six = (F::ONE + F::ONE + F::ONE) * (F::ONE + F::ONE);
        let g = adj_ret * (six * t * (F::ONE - t) / d);
        *adj_x += g;
        *adj_e0 += g * (t - F::ONE);
        *adj_e1 -= g * t;
    }
}

// ------------------------------------------------------------------------------------------
// lerp
// ------------------------------------------------------------------------------------------

/// Adjoint of `lerp`: `f32`, `f64`, `Vec2-4` (with `f32`), `DVec2-4` (with `f64`), matrices,
/// quaternions, transforms and spatial types, like
/// [`Lerp`].
pub trait AdjLerp: Lerp<Scalar: AdjFloat> + Adjoint {
    /// The adjoint of `lerp(a, b, t)` (see [`adj_lerp`]).
    fn adj_lerp(
        a: Self,
        b: Self,
        t: Self::Scalar,
        adj_a: &mut Self,
        adj_b: &mut Self,
        adj_t: &mut Self::Scalar,
        adj_ret: Self,
    );
}

/// Adjoint of `lerp(a, b, t) = a * (1 - t) + b * t`, per component `i`:
/// `adj_a[i] += g[i] * (1 - t)`, `adj_b[i] += g[i] * t`, `adj_t += g[i] * (b[i] - a[i])`
/// (the components in order `x, y, ...`).
#[inline(always)]
pub fn adj_lerp<T: AdjLerp>(
    a: T,
    b: T,
    t: T::Scalar,
    adj_a: &mut T,
    adj_b: &mut T,
    adj_t: &mut T::Scalar,
    adj_ret: T,
) {
    T::adj_lerp(a, b, t, adj_a, adj_b, adj_t, adj_ret)
}

impl AdjLerp for f32 {
    #[inline(always)]
    fn adj_lerp(a: f32, b: f32, t: f32, aa: &mut f32, ab: &mut f32, at: &mut f32, g: f32) {
        l_lerp(a, b, t, aa, ab, at, g)
    }
}
impl AdjLerp for f64 {
    #[inline(always)]
    fn adj_lerp(a: f64, b: f64, t: f64, aa: &mut f64, ab: &mut f64, at: &mut f64, g: f64) {
        l_lerp(a, b, t, aa, ab, at, g)
    }
}

macro_rules! fvec_lerp {
    ($($v:ident: $s:ident),*) => {$(
        impl AdjLerp for $v {
            #[inline(always)]
            fn adj_lerp(a: $v, b: $v, t: $s, aa: &mut $v, ab: &mut $v, at: &mut $s, g: $v) {
                zip_vv(a, b, aa, ab, g, |x, y, ax: &mut $s, ay: &mut $s, gi| {
                    l_lerp(x, y, t, ax, ay, at, gi)
                })
            }
        }
    )*};
}
fvec_lerp!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64);
// Matrices, quaternions, spatial vectors and matrices: the same lane rule in their lane order
// (`Lanes`: glam's column-major matrices, `x, y, z, w`, spatial matrices row-major).
fvec_lerp!(
    Mat2: f32, Mat3: f32, Mat4: f32, DMat2: f64, DMat3: f64, DMat4: f64, Quat: f32, DQuat: f64,
    SpatialVector: f32, SpatialMatrix: f32, DSpatialVector: f64, DSpatialMatrix: f64
);

// ------------------------------------------------------------------------------------------
// dot, length, normalize, cross
// ------------------------------------------------------------------------------------------

/// Adjoint of `dot`: the glam vectors, like [`VecOps`]; a no-op for integer vectors.
pub trait AdjDot: VecOps<Scalar: Adjoint> + Adjoint {
    /// The adjoint of `dot(a, b)` (see [`adj_dot`]).
    fn adj_dot(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self::Scalar);
}

/// Adjoint of `dot(a, b)`, per component `i`: `adj_a[i] += g * b[i]`, `adj_b[i] += g * a[i]`.
#[inline(always)]
pub fn adj_dot<V: AdjDot>(a: V, b: V, adj_a: &mut V, adj_b: &mut V, adj_ret: V::Scalar) {
    V::adj_dot(a, b, adj_a, adj_b, adj_ret)
}

/// Adjoints of `length` and `normalize`: the float vectors, like [`FloatVec`].
pub trait AdjFloatVec: FloatVec<Scalar: AdjFloat> + Adjoint {
    /// The adjoint of `length(v)` (see [`adj_length`]).
    fn adj_length(v: Self, adj_v: &mut Self, adj_ret: Self::Scalar);
    /// The adjoint of `normalize(v)` (see [`adj_normalize`]).
    fn adj_normalize(v: Self, adj_v: &mut Self, adj_ret: Self);
}

/// Adjoint of `length(v) = sqrt(dot(v, v))`: with `l = length(v)`, per component
/// `adj_v[i] += v[i] * (g / l)` when `l > 0`; nothing at the zero vector (zero gradient).
/// Where `dot(v, v)` would overflow or underflow, `v` and `l` are first scaled by the same
/// exact power of two (the ratio `v / l` is unchanged), as the forward is.
#[inline(always)]
pub fn adj_length<V: AdjFloatVec>(v: V, adj_v: &mut V, adj_ret: V::Scalar) {
    V::adj_length(v, adj_v, adj_ret)
}

/// Adjoint of `normalize(v)`: with `l = length(v)`, `n[i] = v[i] / l` (the forward result)
/// and `d = dot(n, g)` (left to right), per component `adj_v[i] += (g[i] - n[i] * d) / l`
/// when `l > 0` (the projection of `g` orthogonal to `n`, over `l`); nothing at the zero
/// vector, where the forward returns the zero vector (zero gradient). Where `dot(v, v)` would
/// overflow or underflow, `n` and `1 / l` come from `v` scaled by an exact power of two `k`:
/// `adj_v[i] += ((g[i] - n[i] * d) / |k v|) * k`.
#[inline(always)]
pub fn adj_normalize<V: AdjFloatVec>(v: V, adj_v: &mut V, adj_ret: V) {
    V::adj_normalize(v, adj_v, adj_ret)
}

/// Adjoint of `cross`: `Vec3`, `DVec3`, `IVec3`, like [`Cross`]; a no-op for `IVec3`.
pub trait AdjCross: Cross + Adjoint {
    /// The adjoint of `cross(a, b)` (see [`adj_cross`]).
    fn adj_cross(a: Self, b: Self, adj_a: &mut Self, adj_b: &mut Self, adj_ret: Self);
}

/// Adjoint of `cross(a, b) = a × b`: `adj_a += b × g`, `adj_b += g × a` (the builtin's
/// `cross`).
#[inline(always)]
pub fn adj_cross<V: AdjCross>(a: V, b: V, adj_a: &mut V, adj_b: &mut V, adj_ret: V) {
    V::adj_cross(a, b, adj_a, adj_b, adj_ret)
}

macro_rules! noop_dot {
    ($($v:ty),*) => {$(
        impl AdjDot for $v {
            #[inline(always)]
            fn adj_dot(
                _a: $v,
                _b: $v,
                _adj_a: &mut $v,
                _adj_b: &mut $v,
                _adj_ret: <$v as VecOps>::Scalar,
            ) {
            }
        }
    )*};
}
noop_dot!(IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);

impl AdjCross for IVec3 {
    #[inline(always)]
    fn adj_cross(_a: IVec3, _b: IVec3, _adj_a: &mut IVec3, _adj_b: &mut IVec3, _g: IVec3) {}
}

macro_rules! fvec_ops {
    ($($v:ident: $s:ident),*) => {$(
        impl AdjDot for $v {
            #[inline(always)]
            fn adj_dot(a: $v, b: $v, adj_a: &mut $v, adj_b: &mut $v, adj_ret: $s) {
                let (a, b) = (a.to_array(), b.to_array());
                let (mut aa, mut ab) = (adj_a.to_array(), adj_b.to_array());
                for (i, (aa, ab)) in aa.iter_mut().zip(ab.iter_mut()).enumerate() {
                    *aa += adj_ret * b[i];
                    *ab += adj_ret * a[i];
                }
                *adj_a = $v::from_array(aa);
                *adj_b = $v::from_array(ab);
            }
        }
        impl AdjFloatVec for $v {
            // Rescaled like the forward where the squares would overflow or underflow
            // (`builtins::norm`).
            #[inline(always)]
            fn adj_length(v: $v, adj_v: &mut $v, adj_ret: $s) {
                crate::builtins::norm::adj_length(v, adj_v, adj_ret)
            }
            #[inline(always)]
            fn adj_normalize(v: $v, adj_v: &mut $v, adj_ret: $v) {
                crate::builtins::norm::adj_normalize(v, adj_v, adj_ret)
            }
        }
    )*};
}
fvec_ops!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64);

macro_rules! fvec_cross {
    ($($v:ident),*) => {$(
        impl AdjCross for $v {
            #[inline(always)]
            fn adj_cross(a: $v, b: $v, adj_a: &mut $v, adj_b: &mut $v, adj_ret: $v) {
                *adj_a += b.w_cross(adj_ret);
                *adj_b += adj_ret.w_cross(a);
            }
        }
    )*};
}
fvec_cross!(Vec3, DVec3);

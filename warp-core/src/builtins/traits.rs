//! The traits the builtins dispatch through: every builtin is a generic free function over
//! one of them, and `math` implements them for exactly the supported types.
//!
//! A leaf module, so that nothing imports in a circle: `math` implements `FloatVec` with the
//! rescaled norms of `norm`, and `norm` is written over `Float` and `FloatVec`. Their public
//! path is `builtins::math::*` (and `builtins::*`), re-exported there.

/// A primitive numeric type usable as a builtin operand or vector component:
/// `i8`..`i64`, `u8`..`u64`, `f32`, `f64`.
///
/// The arithmetic helpers wrap for integers (CUDA semantics) and are IEEE for floats.
pub trait Scalar: Copy + PartialOrd + Send + Sync + 'static {
    /// Zero.
    const ZERO: Self;
    /// One.
    const ONE: Self;
    /// `self + o` (wrapping for integers).
    fn s_add(self, o: Self) -> Self;
    /// `self - o` (wrapping for integers).
    fn s_sub(self, o: Self) -> Self;
    /// `self * o` (wrapping for integers).
    fn s_mul(self, o: Self) -> Self;
    /// `-self`: wrapping for integers (`MIN` stays `MIN`, unsigned `0 - self`), the sign bit
    /// flipped for floats (`-0.0` from `+0.0`, NaN stays NaN).
    fn s_neg(self) -> Self;
}

/// `min`, `max` (and so `clamp`): all [`Scalar`]s and the `glam` vectors `Vec2/3/4`,
/// `DVec2/3/4`, `IVec2/3/4`, `UVec2/3/4` (componentwise). Floats use IEEE `fmin`/`fmax`.
pub trait MinMax: Copy {
    /// The smaller of `self` and `o` (for floats: the non-NaN one if exactly one is NaN).
    fn w_min(self, o: Self) -> Self;
    /// The larger of `self` and `o` (for floats: the non-NaN one if exactly one is NaN).
    fn w_max(self, o: Self) -> Self;
}

/// `abs`, `sign`: signed integers, `f32`, `f64`, and `Vec2/3/4`, `DVec2/3/4`, `IVec2/3/4`
/// (componentwise).
pub trait Signed: Copy {
    /// Absolute value; wrapping for integers (`abs(i32::MIN) == i32::MIN`, as in CUDA).
    fn w_abs(self) -> Self;
    /// `-1` if `self < 0`, else `+1` (Warp's definition).
    fn w_sign(self) -> Self;
}

/// The transcendental and rounding builtins: `f32`, `f64`.
pub trait Float: Scalar + MinMax + Signed {
    /// Round toward negative infinity.
    fn w_floor(self) -> Self;
    /// Round toward positive infinity.
    fn w_ceil(self) -> Self;
    /// Square root (NaN for negative inputs).
    fn w_sqrt(self) -> Self;
    /// `e^self`.
    fn w_exp(self) -> Self;
    /// Natural logarithm.
    fn w_log(self) -> Self;
    /// Sine (radians).
    fn w_sin(self) -> Self;
    /// Cosine (radians).
    fn w_cos(self) -> Self;
    /// Tangent (radians).
    fn w_tan(self) -> Self;
    /// Four-quadrant arctangent of `self / x` (`self` is `y`).
    fn w_atan2(self, x: Self) -> Self;
    /// `self` raised to the power `y`.
    fn w_pow(self, y: Self) -> Self;
    /// Arcsine of `self` clamped to `[-1, 1]` (NaN stays NaN).
    fn w_asin(self) -> Self;
    /// Arccosine of `self` clamped to `[-1, 1]` (NaN stays NaN).
    fn w_acos(self) -> Self;
    /// Arctangent.
    fn w_atan(self) -> Self;
    /// Hyperbolic sine.
    fn w_sinh(self) -> Self;
    /// Hyperbolic cosine.
    fn w_cosh(self) -> Self;
    /// Hyperbolic tangent.
    fn w_tanh(self) -> Self;
    /// `2^self`.
    fn w_exp2(self) -> Self;
    /// Base-2 logarithm.
    fn w_log2(self) -> Self;
    /// Base-10 logarithm.
    fn w_log10(self) -> Self;
    /// Cube root.
    fn w_cbrt(self) -> Self;
    /// Error function.
    fn w_erf(self) -> Self;
    /// Complementary error function.
    fn w_erfc(self) -> Self;
    /// Inverse error function.
    fn w_erfinv(self) -> Self;
    /// Inverse complementary error function.
    fn w_erfcinv(self) -> Self;
    /// Round to nearest, half away from zero.
    fn w_round(self) -> Self;
    /// Round to nearest, half to even.
    fn w_rint(self) -> Self;
    /// Round toward zero.
    fn w_trunc(self) -> Self;
    /// `self * (180/π)` (Rust's `to_degrees`).
    fn w_degrees(self) -> Self;
    /// `self * (π/180)` (Rust's `to_radians`).
    fn w_radians(self) -> Self;
    /// Not infinite and not NaN.
    fn w_isfinite(self) -> bool;
    /// NaN.
    fn w_isnan(self) -> bool;
    /// Positive or negative infinity.
    fn w_isinf(self) -> bool;
    /// `smoothstep(self, e1, x)` (see [`smoothstep`](crate::builtins::smoothstep)).
    fn w_smoothstep(self, e1: Self, x: Self) -> Self;
}

/// `isfinite`, `isnan`, `isinf`: `f32`, `f64`, and the float vectors (all components finite,
/// any component NaN, any component infinite).
pub trait Classify: Copy {
    /// Every component is finite.
    fn w_isfinite(self) -> bool;
    /// Some component is NaN.
    fn w_isnan(self) -> bool;
    /// Some component is infinite.
    fn w_isinf(self) -> bool;
}

/// `lerp`: `f32`, `f64`, `Vec2/3/4` (with `f32`), `DVec2/3/4` (with `f64`), square matrices,
/// quaternions, transforms, spatial vectors and matrices (lane by lane).
pub trait Lerp: Copy {
    /// The type of the interpolation parameter.
    type Scalar: Float;
    /// `self * (1 - t) + b * t`.
    fn w_lerp(self, b: Self, t: Self::Scalar) -> Self;
}

/// Vector operations shared by float and integer vectors (`dot`): `Vec2/3/4`, `DVec2/3/4`,
/// `IVec2/3/4`, `UVec2/3/4`.
pub trait VecOps: Copy {
    /// The component type.
    type Scalar: Scalar;
    /// Sum of the componentwise products, left to right (wrapping for integer vectors).
    fn w_dot(self, o: Self) -> Self::Scalar;
}

/// Float-vector operations (`length`, `normalize`): `Vec2/3/4`, `DVec2/3/4`.
pub trait FloatVec: VecOps<Scalar: Float> {
    /// `sqrt(dot(self, self))`.
    fn w_length(self) -> Self::Scalar;
    /// `self / length(self)`, or the zero vector when the length is zero.
    fn w_normalize(self) -> Self;
}

/// `cross`: `Vec3`, `DVec3`, `IVec3` (wrapping for `IVec3`).
pub trait Cross: Copy {
    /// The cross product `self × o`.
    fn w_cross(self, o: Self) -> Self;
}

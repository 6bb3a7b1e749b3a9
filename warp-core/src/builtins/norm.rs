//! Euclidean norms that neither overflow nor underflow: `length`, `normalize` and their
//! adjoints for the float vectors and quaternions (the CUDA library's `wp_vector.h`,
//! `wp_linalg.h` and adjoint headers do the same, operation for operation).
//!
//! # Why
//!
//! `sqrt(dot(v, v))` squares the components: in f32 a component above about 1.8e19 overflows
//! the square to infinity, and components below about 1e-19 leave squares that are subnormal
//! (imprecise) or zero, so the length is `inf` or `0` (and `normalize` gives the zero vector)
//! where the true value is an ordinary number. f64 has the same problem beyond 1e154 and below
//! 1e-154.
//!
//! # How
//!
//! Every call multiplies the vector by the power of two `k` that brings its largest
//! `|component|` into `[1, 2)` (clamped to `2^±126`, f64 `2^±1022`, so that `1/k` is a normal
//! number too), then applies the plain formulas to `w = k v` and undoes the scale:
//!
//! * `length(v) = sqrt(dot(w, w)) * (1/k)`;
//! * `normalize(v) = w / sqrt(dot(w, w))` (scale-invariant: no `k`);
//! * `d length / dv = v / |v| = w / |w|`, so `adj_v += w * (g / |w|)`;
//! * `d normalize / dv` applied to `g` is `(g - n dot(n, g)) / |v|` with `n = w / |w|`, and
//!   `1 / |v| = k / |w|`: `adj_v += ((g - n d) / |w|) * k`.
//!
//! Multiplying by a power of two is exact, and every operation of the plain formula (products,
//! sums, `sqrt` of `k² s`, quotients) rounds identically at any scale where nothing overflows
//! or leaves the normal range. So wherever the plain formula was accurate these are its results
//! bit for bit; elsewhere the scaled squared norm lies in `[1, 4 N)` and cannot over- or
//! underflow. (A lane more than `2^126` times smaller than the largest one may lose bits when
//! scaled; it cannot change the sum.)
//!
//! # Why always, and not only when `dot(v, v)` left the safe range
//!
//! A branch to a rarely taken slow path is free in scalar code, but it stops LLVM from
//! vectorising the CPU executor's loop over a kernel's threads: measured on a 1M-element kernel
//! calling `length` and `normalize`, a cold out-of-line slow path made the launch 4.5x slower
//! (15.8 against 3.5 ms). The scale is branch-free instead: a maximum over the lanes, a few
//! integer operations on its exponent and one multiply per lane, which vectorise (measured:
//! the same kernel within a few percent of the plain formula).
//!
//! Zero, NaN and infinite inputs keep the plain formula's IEEE results without a special case:
//! the zero vector has length `0` (`normalize` gives the zero vector, quaternions the
//! identity); an infinite lane scales to infinity, so the length is `inf` and `normalize`
//! divides it to NaN and the finite lanes to `0`; the largest magnitude is taken by `>` from 0,
//! skipping NaN lanes, which still reach the result through `dot(w, w)`: length NaN,
//! `normalize` the zero vector (or identity), as `l > 0` fails. The adjoints give nothing where
//! the length is not positive.

use glam::{DQuat, DVec2, DVec3, DVec4, Quat, Vec2, Vec3, Vec4};

use super::traits::{Float, FloatVec, Scalar, Signed};

/// The scalar facts the rescaled norms need: `f32`, `f64`.
pub(crate) trait NormScalar: Float + core::ops::Div<Output = Self> {
    /// For `m >= 0` (not NaN): the power of two `k` with `m * k` in `[1, 2)`, clamped to
    /// `2^±126` (f64 `2^±1022`), and its inverse `1/k` (also exact). Branch-free; `m = 0`
    /// gives the largest `k` and infinity the smallest, which leave those values as they are.
    fn pow2_pair(m: Self) -> (Self, Self);
}

// `m` is clamped to `[2^-126, 2^126]` (f64 `[2^-1022, 2^1022]`) by selects (`maxps`/`minps`;
// `m` is never NaN), then its exponent bits `eb` give `1/k` directly (`m` with the mantissa
// cleared) and `k` as the exponent `254 - E` (f64 `2046 - E`), both normal numbers.

impl NormScalar for f32 {
    #[inline(always)]
    fn pow2_pair(m: f32) -> (f32, f32) {
        let (lo, hi) = (f32::from_bits(1 << 23), f32::from_bits(253 << 23));
        let m = if m > lo { m } else { lo };
        let m = if m < hi { m } else { hi };
        let eb = m.to_bits() & 0x7f80_0000;
        (f32::from_bits(0x7f00_0000 - eb), f32::from_bits(eb))
    }
}

impl NormScalar for f64 {
    #[inline(always)]
    fn pow2_pair(m: f64) -> (f64, f64) {
        let (lo, hi) = (f64::from_bits(1 << 52), f64::from_bits(2045 << 52));
        let m = if m > lo { m } else { lo };
        let m = if m < hi { m } else { hi };
        let eb = m.to_bits() & 0x7ff0_0000_0000_0000;
        (
            f64::from_bits(0x7fe0_0000_0000_0000 - eb),
            f64::from_bits(eb),
        )
    }
}

/// The lanes of a float vector or quaternion (x, y, z, w order), for the rescaled norms.
pub(crate) trait NormLanes: FloatVec<Scalar: NormScalar> {
    /// `[Scalar; N]`.
    type Lanes: Copy + AsRef<[Self::Scalar]> + AsMut<[Self::Scalar]>;
    /// What `normalize` returns where the length is not positive: the zero vector, or the
    /// identity quaternion.
    const AT_ZERO: Self;
    /// The lanes.
    fn lanes(self) -> Self::Lanes;
    /// The value with these lanes.
    fn from_lanes(l: Self::Lanes) -> Self;
}

macro_rules! norm_lanes {
    ($($v:ident: $s:ident, $n:literal, $zero:ident);*) => {$(
        impl NormLanes for $v {
            type Lanes = [$s; $n];
            const AT_ZERO: Self = $v::$zero;
            #[inline(always)]
            fn lanes(self) -> [$s; $n] {
                self.to_array()
            }
            #[inline(always)]
            fn from_lanes(l: [$s; $n]) -> Self {
                $v::from_array(l)
            }
        }
    )*};
}
norm_lanes!(
    Vec2: f32, 2, ZERO; Vec3: f32, 3, ZERO; Vec4: f32, 4, ZERO;
    DVec2: f64, 2, ZERO; DVec3: f64, 3, ZERO; DVec4: f64, 4, ZERO;
    Quat: f32, 4, IDENTITY; DQuat: f64, 4, IDENTITY
);

/// `v` with every lane mapped by `f`.
#[inline(always)]
fn map<V: NormLanes>(v: V, f: impl Fn(V::Scalar) -> V::Scalar) -> V {
    let mut l = v.lanes();
    for x in l.as_mut() {
        *x = f(*x);
    }
    V::from_lanes(l)
}

/// The scaled vector and its parts: `(w, |w|, k, 1/k)` with `w = k v` for the power of two
/// `k` of the largest `|component|` (see the module docs).
#[inline(always)]
fn scaled<V: NormLanes>(v: V) -> (V, V::Scalar, V::Scalar, V::Scalar) {
    // The largest magnitude, by `>` from 0 (a select, as x86's `maxps`): NaN lanes are
    // skipped.
    let mut m = V::Scalar::ZERO;
    for &x in v.lanes().as_ref() {
        let a = x.w_abs();
        m = if a > m { a } else { m };
    }
    let (k, inv) = V::Scalar::pow2_pair(m);
    let w = map(v, |x| x.s_mul(k));
    (w, w.w_dot(w).w_sqrt(), k, inv)
}

/// `length(v)`: `sqrt(dot(w, w)) * (1/k)` (module docs).
#[inline(always)]
pub(crate) fn length<V: NormLanes>(v: V) -> V::Scalar {
    let (_, l, _, inv) = scaled(v);
    l.s_mul(inv)
}

/// `normalize(v)`: `w / |w|`, or [`NormLanes::AT_ZERO`] where the length is not positive.
#[inline(always)]
pub(crate) fn normalize<V: NormLanes>(v: V) -> V {
    let (w, l, _, _) = scaled(v);
    if l > V::Scalar::ZERO {
        map(w, |x| x / l)
    } else {
        V::AT_ZERO
    }
}

/// The adjoint of `length`: `adj_v[i] += w[i] * (g / |w|)` where `|w| > 0` (the rule
/// `v * (g / l)`, scaled).
#[inline(always)]
pub(crate) fn adj_length<V: NormLanes>(v: V, adj_v: &mut V, g: V::Scalar) {
    let (w, l, _, _) = scaled(v);
    if l > V::Scalar::ZERO {
        let gl = g / l;
        let mut a = adj_v.lanes();
        for (a, &x) in a.as_mut().iter_mut().zip(w.lanes().as_ref()) {
            *a = a.s_add(x.s_mul(gl));
        }
        *adj_v = V::from_lanes(a);
    }
}

/// The adjoint of `normalize`: with `n = w / |w|` and `d = dot(n, g)`,
/// `adj_v[i] += ((g[i] - n[i] d) / |w|) * k` where `|w| > 0` (the rule
/// `(g[i] - n[i] d) / l`, scaled).
#[inline(always)]
pub(crate) fn adj_normalize<V: NormLanes>(v: V, adj_v: &mut V, g: V) {
    let (w, l, k, _) = scaled(v);
    if l > V::Scalar::ZERO {
        let n = map(w, |x| x / l);
        let d = n.w_dot(g);
        let (gl, nl) = (g.lanes(), n.lanes());
        let mut a = adj_v.lanes();
        for (i, a) in a.as_mut().iter_mut().enumerate() {
            *a = a.s_add(((gl.as_ref()[i].s_sub(nl.as_ref()[i].s_mul(d))) / l).s_mul(k));
        }
        *adj_v = V::from_lanes(a);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pow2_pairs_are_exact_inverse_powers_of_two() {
        assert_eq!(f32::pow2_pair(1.0), (1.0, 1.0));
        assert_eq!(f32::pow2_pair(3.0), (0.5, 2.0));
        assert_eq!(f32::pow2_pair(0.75), (2.0, 0.5));
        let (k, inv) = f32::pow2_pair(1e38);
        assert!((1.0..2.0).contains(&(1e38 * k)) && k * inv == 1.0);
        // Zero, subnormals and the top binade: clamped so that both stay normal.
        let (big, small) = (2f32.powi(126), 2f32.powi(-126));
        assert_eq!(f32::pow2_pair(1e-40), (big, small));
        assert_eq!(f32::pow2_pair(0.0), (big, small));
        assert_eq!(f32::pow2_pair(f32::MAX), (small, big));
        assert_eq!(f32::pow2_pair(f32::INFINITY), (small, big));
        let (k, inv) = f64::pow2_pair(1e-300);
        assert!((1.0..2.0).contains(&(1e-300 * k)) && k * inv == 1.0);
        assert_eq!(f64::pow2_pair(5e-324).0, 2f64.powi(1022));
        assert_eq!(f64::pow2_pair(f64::INFINITY).0, 2f64.powi(-1022));
    }

    #[test]
    fn plain_formula_bits_where_it_was_accurate() {
        // Ordinary magnitudes: exactly `sqrt(dot(v, v))` and `v / that`.
        let mut x = 0.37f32;
        for _ in 0..1000 {
            x = (x * 3.7 + 0.11).fract();
            let v = Vec3::new(x * 8.0 - 4.0, (x * 17.0).fract() - 0.5, x * 1e3);
            let l = super::super::math::dot(v, v).sqrt();
            assert_eq!(length(v).to_bits(), l.to_bits());
            assert_eq!(normalize(v), Vec3::new(v.x / l, v.y / l, v.z / l));
        }
    }
}

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
//! The fast path is the plain formula, unchanged: the squared norm `s = dot(v, v)`, then
//! `sqrt(s)`. It is taken when `s` lies in `[2^-100, MAX]` (f64: `[2^-1000, MAX]`), where the
//! formula is accurate: no square overflowed, and a square that fell among the subnormals
//! carries an absolute error of at most half the smallest subnormal (`2^-150`), which is below
//! `2^-48` of `s` (f64: `2^-73`). One comparison pair, predicted taken, is all the common path
//! pays.
//!
//! Otherwise (and only then) the vector is multiplied by the power of two `k` that brings its
//! largest `|component|` into `[1, 2)` (clamped to `2^±126`, f64 `2^±1022`, so that `1/k` is a
//! normal number too). Multiplying by a power of two is exact (a component that lands below
//! the normal range loses bits there, but it is then below `2^-126` of the largest one and
//! cannot matter), the scaled squared norm lies in `[1, 4 N)`, and the results follow from
//! scale invariance:
//!
//! * `length(v) = sqrt(dot(w, w)) * (1/k)` with `w = k v`;
//! * `normalize(v) = w / length(w)`;
//! * `d length / dv = v / |v| = w / |w|`, so `adj_v += w * (g / |w|)`;
//! * `d normalize / dv` applied to `g` is `(g - n dot(n, g)) / |v|` with `n = w / |w|`, and
//!   `1 / |v| = k / |w|`: `adj_v += ((g - n d) / |w|) * k`.
//!
//! Zero, NaN and infinite inputs keep the plain formula's IEEE results (they take the slow
//! path, find no finite nonzero largest component, and use `k = 1`): `length` is `0` for the
//! zero vector, `inf` with an infinite component, NaN with a NaN one; `normalize` gives the
//! zero vector (quaternions: the identity) unless the length is positive, so zero and NaN
//! vectors give it too, and an infinite component divides to NaN (its own lane) and zeros.
//! The adjoints give nothing where the forward returned the zero vector or the identity.

use glam::{DQuat, DVec2, DVec3, DVec4, Quat, Vec2, Vec3, Vec4};

use super::math::{Float, FloatVec, Scalar, Signed};

/// The scalar facts the rescaled norms need: `f32`, `f64`.
pub(crate) trait NormScalar: Float + core::ops::Div<Output = Self> {
    /// Whether a squared norm `s` lies in the range where `sqrt(s)` is accurate (see the
    /// module docs): `[2^-100, f32::MAX]`, f64 `[2^-1000, f64::MAX]`. False for NaN.
    fn norm_sq_is_safe(self) -> bool;
    /// For a finite `m > 0`: the power of two `k` with `m * k` in `[1, 2)`, clamped to
    /// `2^±126` (f64 `2^±1022`), and its inverse `1/k` (also exact). `None` for zero, NaN and
    /// infinity.
    fn pow2_pair(m: Self) -> Option<(Self, Self)>;
}

impl NormScalar for f32 {
    #[inline(always)]
    fn norm_sq_is_safe(self) -> bool {
        // 2^-100: exponent field 27.
        self >= f32::from_bits(27 << 23) && self <= f32::MAX
    }
    #[inline(always)]
    fn pow2_pair(m: f32) -> Option<(f32, f32)> {
        if !(m > 0.0 && m <= f32::MAX) {
            return None;
        }
        // A subnormal `m` has exponent field 0, read as 2^-127, and gets the clamped 2^126.
        let e = ((m.to_bits() >> 23) & 0xff) as i32 - 127;
        let k = (-e).clamp(-126, 126);
        Some((
            f32::from_bits(((127 + k) as u32) << 23),
            f32::from_bits(((127 - k) as u32) << 23),
        ))
    }
}

impl NormScalar for f64 {
    #[inline(always)]
    fn norm_sq_is_safe(self) -> bool {
        // 2^-1000: exponent field 23.
        self >= f64::from_bits(23 << 52) && self <= f64::MAX
    }
    #[inline(always)]
    fn pow2_pair(m: f64) -> Option<(f64, f64)> {
        if !(m > 0.0 && m <= f64::MAX) {
            return None;
        }
        let e = ((m.to_bits() >> 52) & 0x7ff) as i64 - 1023;
        let k = (-e).clamp(-1022, 1022);
        Some((
            f64::from_bits(((1023 + k) as u64) << 52),
            f64::from_bits(((1023 - k) as u64) << 52),
        ))
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

/// The slow path's scaled vector: `(w, |w|, k, 1/k)` with `w = k v` for the power of two `k`
/// of the largest `|component|` (see the module docs), or `(v, sqrt(s), 1, 1)` when that is
/// zero, infinite or NaN (the plain formula's values; multiplying by 1 changes nothing).
#[inline(always)]
fn rescaled<V: NormLanes>(v: V, s: V::Scalar) -> (V, V::Scalar, V::Scalar, V::Scalar) {
    // The largest magnitude, by `>` from 0: NaN lanes are skipped (a NaN lane still reaches
    // the result through `dot(w, w)`), an infinite one makes `pow2_pair` refuse.
    let mut m = V::Scalar::ZERO;
    for &x in v.lanes().as_ref() {
        let a = x.w_abs();
        if a > m {
            m = a;
        }
    }
    match V::Scalar::pow2_pair(m) {
        Some((k, inv)) => {
            let w = map(v, |x| x.s_mul(k));
            (w, w.w_dot(w).w_sqrt(), k, inv)
        }
        None => (v, s.w_sqrt(), V::Scalar::ONE, V::Scalar::ONE),
    }
}

/// `length(v)`: `sqrt(dot(v, v))` where that is accurate, else rescaled (module docs).
#[inline(always)]
pub(crate) fn length<V: NormLanes>(v: V) -> V::Scalar {
    let s = v.w_dot(v);
    if s.norm_sq_is_safe() {
        s.w_sqrt()
    } else {
        length_rescaled(v, s)
    }
}

#[cold]
#[inline(never)]
fn length_rescaled<V: NormLanes>(v: V, s: V::Scalar) -> V::Scalar {
    let (_, l, _, inv) = rescaled(v, s);
    l.s_mul(inv)
}

/// `normalize(v)`: `v / sqrt(dot(v, v))` where that is accurate, else `w / |w|` for the
/// rescaled `w`; [`NormLanes::AT_ZERO`] where the length is not positive.
#[inline(always)]
pub(crate) fn normalize<V: NormLanes>(v: V) -> V {
    let s = v.w_dot(v);
    if s.norm_sq_is_safe() {
        let l = s.w_sqrt();
        map(v, |x| x / l)
    } else {
        normalize_rescaled(v, s)
    }
}

#[cold]
#[inline(never)]
fn normalize_rescaled<V: NormLanes>(v: V, s: V::Scalar) -> V {
    let (w, l, _, _) = rescaled(v, s);
    if l > V::Scalar::ZERO {
        map(w, |x| x / l)
    } else {
        V::AT_ZERO
    }
}

/// The adjoint of `length`: `adj_v[i] += w[i] * (g / |w|)` where `|w| > 0`, with `w = v` on
/// the fast path (the rule `v * (g / l)`), else the rescaled vector.
#[inline(always)]
pub(crate) fn adj_length<V: NormLanes>(v: V, adj_v: &mut V, g: V::Scalar) {
    let s = v.w_dot(v);
    if s.norm_sq_is_safe() {
        accumulate_length(v, s.w_sqrt(), adj_v, g);
    } else {
        adj_length_rescaled(v, s, adj_v, g);
    }
}

#[cold]
#[inline(never)]
fn adj_length_rescaled<V: NormLanes>(v: V, s: V::Scalar, adj_v: &mut V, g: V::Scalar) {
    let (w, l, _, _) = rescaled(v, s);
    accumulate_length(w, l, adj_v, g);
}

#[inline(always)]
fn accumulate_length<V: NormLanes>(w: V, l: V::Scalar, adj_v: &mut V, g: V::Scalar) {
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
/// `adj_v[i] += ((g[i] - n[i] d) / |w|) * k` where `|w| > 0` (`w = v`, no `* k`, on the fast
/// path: the rule `(g[i] - n[i] d) / l`).
#[inline(always)]
pub(crate) fn adj_normalize<V: NormLanes>(v: V, adj_v: &mut V, g: V) {
    let s = v.w_dot(v);
    if s.norm_sq_is_safe() {
        let l = s.w_sqrt();
        let n = map(v, |x| x / l);
        let d = n.w_dot(g);
        let (gl, nl) = (g.lanes(), n.lanes());
        let mut a = adj_v.lanes();
        for (i, a) in a.as_mut().iter_mut().enumerate() {
            *a = a.s_add((gl.as_ref()[i].s_sub(nl.as_ref()[i].s_mul(d))) / l);
        }
        *adj_v = V::from_lanes(a);
    } else {
        adj_normalize_rescaled(v, s, adj_v, g);
    }
}

#[cold]
#[inline(never)]
fn adj_normalize_rescaled<V: NormLanes>(v: V, s: V::Scalar, adj_v: &mut V, g: V) {
    let (w, l, k, _) = rescaled(v, s);
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
        assert_eq!(f32::pow2_pair(1.0), Some((1.0, 1.0)));
        assert_eq!(f32::pow2_pair(3.0), Some((0.5, 2.0)));
        assert_eq!(f32::pow2_pair(0.75), Some((2.0, 0.5)));
        let (k, inv) = f32::pow2_pair(1e38).unwrap();
        assert!((1.0..2.0).contains(&(1e38 * k)) && k * inv == 1.0);
        // Subnormal and the top binade: clamped so that both stay normal.
        assert_eq!(
            f32::pow2_pair(1e-40),
            Some((2f32.powi(126), 2f32.powi(-126)))
        );
        assert_eq!(f32::pow2_pair(f32::MAX), Some((2f32.powi(-126), 2f32.powi(126))));
        for bad in [0.0, -1.0, f32::INFINITY, f32::NAN] {
            assert_eq!(f32::pow2_pair(bad), None);
        }
        let (k, inv) = f64::pow2_pair(1e-300).unwrap();
        assert!((1.0..2.0).contains(&(1e-300 * k)) && k * inv == 1.0);
        assert_eq!(f64::pow2_pair(5e-324).unwrap().0, 2f64.powi(1022));
        assert_eq!(f64::pow2_pair(f64::INFINITY), None);
    }

    #[test]
    fn safe_range_bounds() {
        assert!(2f32.powi(-100).norm_sq_is_safe());
        assert!(!(2f32.powi(-100) * 0.75).norm_sq_is_safe());
        assert!(f32::MAX.norm_sq_is_safe());
        assert!(!f32::INFINITY.norm_sq_is_safe() && !f32::NAN.norm_sq_is_safe());
        assert!(2f64.powi(-1000).norm_sq_is_safe());
        assert!(!(2f64.powi(-1000) * 0.75).norm_sq_is_safe());
        assert!(!0f64.norm_sq_is_safe());
    }
}

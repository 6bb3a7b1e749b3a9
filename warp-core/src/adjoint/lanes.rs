//! Componentwise plumbing: float vectors, matrices (column-major) and quaternions seen as
//! arrays of float lanes, and the scalar lane adjoints every componentwise operation reduces
//! to.

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, Mat2, Mat3, Mat4, Quat, Vec2, Vec3, Vec4,
};

use super::AdjFloat;

/// A float glam type as an array of lanes (vectors: `x, y, ...`; matrices: column-major;
/// quaternions: `x, y, z, w`).
pub(crate) trait Lanes: Copy {
    /// The lane type.
    type S: AdjFloat;
    /// The lane array.
    type A: AsRef<[Self::S]> + AsMut<[Self::S]>;
    /// The lanes of `self`.
    fn lanes(self) -> Self::A;
    /// The value with lanes `a`.
    fn from_lanes(a: Self::A) -> Self;
}

macro_rules! lanes_vec {
    ($($v:ident: $s:ident, $n:literal);* $(;)?) => {$(
        impl Lanes for $v {
            type S = $s;
            type A = [$s; $n];
            #[inline(always)]
            fn lanes(self) -> [$s; $n] {
                self.to_array()
            }
            #[inline(always)]
            fn from_lanes(a: [$s; $n]) -> Self {
                $v::from_array(a)
            }
        }
    )*};
}
lanes_vec!(
    Vec2: f32, 2; Vec3: f32, 3; Vec4: f32, 4;
    DVec2: f64, 2; DVec3: f64, 3; DVec4: f64, 4;
    Quat: f32, 4; DQuat: f64, 4;
);

macro_rules! lanes_mat {
    ($($m:ident: $s:ident, $n:literal);* $(;)?) => {$(
        impl Lanes for $m {
            type S = $s;
            type A = [$s; $n];
            #[inline(always)]
            fn lanes(self) -> [$s; $n] {
                self.to_cols_array()
            }
            #[inline(always)]
            fn from_lanes(a: [$s; $n]) -> Self {
                $m::from_cols_array(&a)
            }
        }
    )*};
}
lanes_mat!(
    Mat2: f32, 4; Mat3: f32, 9; Mat4: f32, 16;
    DMat2: f64, 4; DMat3: f64, 9; DMat4: f64, 16;
);

/// A binary lane adjoint: `(a, b, adj_a, adj_b, adj_ret)`.
pub(crate) trait Lane2<S>: FnMut(S, S, &mut S, &mut S, S) {}
impl<S, F: FnMut(S, S, &mut S, &mut S, S)> Lane2<S> for F {}

/// `v op v`, lane by lane.
#[inline(always)]
pub(crate) fn zip_vv<V: Lanes>(
    a: V,
    b: V,
    adj_a: &mut V,
    adj_b: &mut V,
    g: V,
    mut f: impl Lane2<V::S>,
) {
    let (a, b, g) = (a.lanes(), b.lanes(), g.lanes());
    let (mut aa, mut ab) = (adj_a.lanes(), adj_b.lanes());
    let (a, b, g) = (a.as_ref(), b.as_ref(), g.as_ref());
    {
        let (la, lb) = (aa.as_mut(), ab.as_mut());
        for i in 0..a.len() {
            f(a[i], b[i], &mut la[i], &mut lb[i], g[i]);
        }
    }
    *adj_a = V::from_lanes(aa);
    *adj_b = V::from_lanes(ab);
}

/// `v op s`, lane by lane (`s`'s adjoint collects the lanes' contributions in lane order).
#[inline(always)]
pub(crate) fn zip_vs<V: Lanes>(
    a: V,
    s: V::S,
    adj_a: &mut V,
    adj_s: &mut V::S,
    g: V,
    mut f: impl Lane2<V::S>,
) {
    let (a, g) = (a.lanes(), g.lanes());
    let mut aa = adj_a.lanes();
    let (a, g) = (a.as_ref(), g.as_ref());
    {
        let la = aa.as_mut();
        for i in 0..a.len() {
            f(a[i], s, &mut la[i], adj_s, g[i]);
        }
    }
    *adj_a = V::from_lanes(aa);
}

/// `s op v`, lane by lane (`s`'s adjoint collects the lanes' contributions in lane order).
#[inline(always)]
pub(crate) fn zip_sv<V: Lanes>(
    s: V::S,
    b: V,
    adj_s: &mut V::S,
    adj_b: &mut V,
    g: V,
    mut f: impl Lane2<V::S>,
) {
    let (b, g) = (b.lanes(), g.lanes());
    let mut ab = adj_b.lanes();
    let (b, g) = (b.as_ref(), g.as_ref());
    {
        let lb = ab.as_mut();
        for i in 0..b.len() {
            f(s, b[i], adj_s, &mut lb[i], g[i]);
        }
    }
    *adj_b = V::from_lanes(ab);
}

/// A unary componentwise function, lane by lane: `f(x, adj_x, adj_ret)`.
#[inline(always)]
pub(crate) fn map1<V: Lanes>(x: V, adj_x: &mut V, g: V, mut f: impl FnMut(V::S, &mut V::S, V::S)) {
    let (x, g) = (x.lanes(), g.lanes());
    let mut ax = adj_x.lanes();
    let (x, g) = (x.as_ref(), g.as_ref());
    {
        let lx = ax.as_mut();
        for i in 0..x.len() {
            f(x[i], &mut lx[i], g[i]);
        }
    }
    *adj_x = V::from_lanes(ax);
}

// ------------------------------------------------------------------------------------------
// Scalar lane adjoints
// ------------------------------------------------------------------------------------------

/// `a + b`: `adj_a += g; adj_b += g`.
#[inline(always)]
pub(crate) fn l_add<F: AdjFloat>(_a: F, _b: F, adj_a: &mut F, adj_b: &mut F, g: F) {
    *adj_a += g;
    *adj_b += g;
}

/// `a - b`: `adj_a += g; adj_b -= g`.
#[inline(always)]
pub(crate) fn l_sub<F: AdjFloat>(_a: F, _b: F, adj_a: &mut F, adj_b: &mut F, g: F) {
    *adj_a += g;
    *adj_b -= g;
}

/// `a * b`: `adj_a += g * b; adj_b += g * a`.
#[inline(always)]
pub(crate) fn l_mul<F: AdjFloat>(a: F, b: F, adj_a: &mut F, adj_b: &mut F, g: F) {
    *adj_a += g * b;
    *adj_b += g * a;
}

/// `a / b`: `gb = g / b; adj_a += gb; adj_b -= gb * (a / b)` (that is `g * a / b²`, written
/// so that `b²` cannot overflow or underflow on its own).
#[inline(always)]
pub(crate) fn l_div<F: AdjFloat>(a: F, b: F, adj_a: &mut F, adj_b: &mut F, g: F) {
    let gb = g / b;
    *adj_a += gb;
    *adj_b -= gb * (a / b);
}

/// Rust's float `%` (C's `fmod`: `a - trunc(a / b) * b`): `adj_a += g;
/// adj_b -= g * trunc(a / b)`.
#[inline(always)]
pub(crate) fn l_rem_trunc<F: AdjFloat>(a: F, b: F, adj_a: &mut F, adj_b: &mut F, g: F) {
    *adj_a += g;
    *adj_b -= g * (a / b).adj_trunc();
}

/// A floored modulo `a - floor(a / b) * b`: `adj_a += g; adj_b -= g * floor(a / b)`.
#[inline(always)]
pub(crate) fn l_rem_floor<F: AdjFloat>(a: F, b: F, adj_a: &mut F, adj_b: &mut F, g: F) {
    *adj_a += g;
    *adj_b -= g * (a / b).w_floor();
}

/// Whether glam's `Vec4 % Vec4` is the floored modulo `a - floor(a / b) * b` (its SSE2, NEON
/// and wasm32 backings) rather than Rust's `%` per lane (its scalar and core-simd backings).
/// Asked of glam itself, so the adjoint follows whichever backing this build uses.
#[inline(always)]
pub(crate) fn vec4_rem_is_floored() -> bool {
    (Vec4::splat(-1.0) % Vec4::splat(3.0)).x > 0.0
}

/// glam's `Vec4` `%` lane (see [`vec4_rem_is_floored`]).
#[inline(always)]
pub(crate) fn l_rem_vec4(a: f32, b: f32, adj_a: &mut f32, adj_b: &mut f32, g: f32) {
    if vec4_rem_is_floored() {
        l_rem_floor(a, b, adj_a, adj_b, g)
    } else {
        l_rem_trunc(a, b, adj_a, adj_b, g)
    }
}

/// Whether the float `min(a, b)` returned `a`: yes if `a <= b` (ties go to the first
/// operand), or if `b` alone is NaN; if both are NaN, also yes.
#[inline(always)]
pub(crate) fn min_takes_first<F: AdjFloat>(a: F, b: F) -> bool {
    if a.adj_is_nan() {
        b.adj_is_nan()
    } else {
        b.adj_is_nan() || a <= b
    }
}

/// Whether the float `max(a, b)` returned `a` (as [`min_takes_first`], with `a >= b`).
#[inline(always)]
pub(crate) fn max_takes_first<F: AdjFloat>(a: F, b: F) -> bool {
    if a.adj_is_nan() {
        b.adj_is_nan()
    } else {
        b.adj_is_nan() || a >= b
    }
}

/// `min(a, b)`: the whole of `g` to the operand returned ([`min_takes_first`]).
#[inline(always)]
pub(crate) fn l_min<F: AdjFloat>(a: F, b: F, adj_a: &mut F, adj_b: &mut F, g: F) {
    if min_takes_first(a, b) {
        *adj_a += g;
    } else {
        *adj_b += g;
    }
}

/// `max(a, b)`: the whole of `g` to the operand returned ([`max_takes_first`]).
#[inline(always)]
pub(crate) fn l_max<F: AdjFloat>(a: F, b: F, adj_a: &mut F, adj_b: &mut F, g: F) {
    if max_takes_first(a, b) {
        *adj_a += g;
    } else {
        *adj_b += g;
    }
}

/// `abs(x)`: `adj_x += g * sign(x)`, with `sign(x) = -1` if `x < 0`, else `+1` (so `+1` at
/// `0`, `-0` and NaN).
#[inline(always)]
pub(crate) fn l_abs<F: AdjFloat>(x: F, adj_x: &mut F, g: F) {
    *adj_x += g * x.w_sign();
}

/// `lerp(a, b, t) = a * (1 - t) + b * t`: `adj_a += g * (1 - t); adj_b += g * t;
/// adj_t += g * (b - a)`.
#[inline(always)]
pub(crate) fn l_lerp<F: AdjFloat>(
    a: F,
    b: F,
    t: F,
    adj_a: &mut F,
    adj_b: &mut F,
    adj_t: &mut F,
    g: F,
) {
    *adj_a += g * (F::ONE - t);
    *adj_b += g * t;
    *adj_t += g * (b - a);
}

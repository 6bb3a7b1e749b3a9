//! Every adjoint against central differences (f64), every f32 adjoint against its f64
//! counterpart, and the edge rules.
//!
//! Tolerances:
//!
//! * **Central differences (f64).** The step is `h = 1e-6 * max(1, |x|)` (the difference
//!   actually taken, `(x + h) - (x - h)`, is used as the divisor). The truncation error is
//!   `h² |f'''| / 6 ≈ 2e-13 |f'''|`, negligible at the points used (away from poles and
//!   kinks). The rounding error of the quotient is about `ε · S / h`, with `ε = 1.1e-16` and
//!   `S = Σ |g_i f_i|` the magnitude of the differenced quantity `<g, f>`: about
//!   `1e-10 · S / max(1, |x|)`. So an adjoint component `ana` passes when
//!   `|num - ana| <= 1e-7 |ana| + 1e-9 (1 + S) / max(1, |x|)`: the brief's relative error
//!   bound of 1e-7, plus an absolute allowance ten times the rounding estimate for components
//!   that are near zero by cancellation. A wrong formula is off by O(1).
//! * **f32 against f64.** Same inputs (all generated as f32 values, so exactly representable
//!   in both), adjoints computed in f32 and in f64. Each f32 adjoint component is a short
//!   formula (at most about 20 roundings, e.g. the quaternion rotation) over inputs of
//!   magnitude <= 3 and adjoints <= 1.5, whose terms are at most a few tens in magnitude; with
//!   the f32 unit roundoff `u = 2^-24 ≈ 6e-8` the error is bounded by roughly
//!   `20 · u · 30 ≈ 4e-5` in the worst case and is typically `< 1e-6`. We allow
//!   `|a32 - a64| <= 3e-5 · max(1, |a64|)` (observed maxima are far below; see
//!   `f32_tolerance_is_not_slack`), which still rejects any formula error.

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};

use super::*;
use crate::builtins::math as m;

// ------------------------------------------------------------------------------------------
// Harness
// ------------------------------------------------------------------------------------------

/// xorshift64*: deterministic, no dependency.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in `[lo, hi)`, rounded to an f32 value.
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        let u = (self.next() >> 11) as f64 / (1u64 << 53) as f64;
        (lo + (hi - lo) * u) as f32 as f64
    }
    /// Magnitude in `[lo, hi)` with a random sign, an f32 value.
    fn mag(&mut self, lo: f64, hi: f64) -> f64 {
        let v = self.range(lo, hi);
        if self.next() & 1 == 0 {
            v
        } else {
            -v
        }
    }
}

/// An f64 test type as a flat array of components.
trait Flat: Copy + std::fmt::Debug {
    const N: usize;
    fn flat(self) -> Vec<f64>;
    fn unflat(v: &[f64]) -> Self;
}

impl Flat for f64 {
    const N: usize = 1;
    fn flat(self) -> Vec<f64> {
        vec![self]
    }
    fn unflat(v: &[f64]) -> Self {
        v[0]
    }
}

macro_rules! flat_vec {
    ($($t:ident: $n:literal),*) => {$(
        impl Flat for $t {
            const N: usize = $n;
            fn flat(self) -> Vec<f64> {
                self.to_array().to_vec()
            }
            fn unflat(v: &[f64]) -> Self {
                $t::from_slice(v)
            }
        }
    )*};
}
flat_vec!(DVec2: 2, DVec3: 3, DVec4: 4, DQuat: 4);

macro_rules! flat_mat {
    ($($t:ident: $n:literal),*) => {$(
        impl Flat for $t {
            const N: usize = $n;
            fn flat(self) -> Vec<f64> {
                self.to_cols_array().to_vec()
            }
            fn unflat(v: &[f64]) -> Self {
                $t::from_cols_slice(v)
            }
        }
    )*};
}
flat_mat!(DMat2: 4, DMat3: 9, DMat4: 16);

/// The f32 counterpart of an f64 test type.
trait Wide: Flat {
    type N: Copy;
    fn narrow(self) -> Self::N;
    fn widen(n: Self::N) -> Self;
}

impl Wide for f64 {
    type N = f32;
    fn narrow(self) -> f32 {
        self as f32
    }
    fn widen(n: f32) -> f64 {
        n as f64
    }
}

macro_rules! wide {
    ($($d:ident => $s:ident, $to:ident, $back:ident);*) => {$(
        impl Wide for $d {
            type N = $s;
            fn narrow(self) -> $s {
                self.$to()
            }
            fn widen(n: $s) -> $d {
                n.$back()
            }
        }
    )*};
}
wide!(
    DVec2 => Vec2, as_vec2, as_dvec2; DVec3 => Vec3, as_vec3, as_dvec3;
    DVec4 => Vec4, as_vec4, as_dvec4; DMat2 => Mat2, as_mat2, as_dmat2;
    DMat3 => Mat3, as_mat3, as_dmat3; DMat4 => Mat4, as_mat4, as_dmat4;
    DQuat => Quat, as_quat, as_dquat
);

/// A random value whose components have magnitudes in `[lo, hi)` and random signs.
fn rnd<T: Flat>(rng: &mut Rng, lo: f64, hi: f64) -> T {
    let v: Vec<f64> = (0..T::N).map(|_| rng.mag(lo, hi)).collect();
    T::unflat(&v)
}

/// A random value with components uniform in `[lo, hi)`.
fn uni<T: Flat>(rng: &mut Rng, lo: f64, hi: f64) -> T {
    let v: Vec<f64> = (0..T::N).map(|_| rng.range(lo, hi)).collect();
    T::unflat(&v)
}

/// A flattened adjoint: `(inputs, result adjoint, input adjoints to accumulate into)`.
type FlatAdj<'a> = &'a dyn Fn(&[f64], &[f64], &mut [f64]);

/// Checks an adjoint against central differences; see the module docs for the tolerance.
/// `f` maps the flattened inputs to the flattened result; `adj` accumulates into the
/// flattened input adjoints given the flattened result adjoint.
fn fd_check(name: &str, x: &[f64], f: &dyn Fn(&[f64]) -> Vec<f64>, adj: FlatAdj, rng: &mut Rng) {
    let y = f(x);
    let g: Vec<f64> = y.iter().map(|_| rng.mag(0.25, 1.5)).collect();
    // Start from non-zero adjoints: the functions must accumulate, not overwrite.
    let init: Vec<f64> = x.iter().map(|_| rng.mag(0.5, 1.0)).collect();
    let mut acc = init.clone();
    adj(x, &g, &mut acc);
    let s: f64 = g.iter().zip(&y).map(|(g, y)| (g * y).abs()).sum();
    let gdot = |v: Vec<f64>| v.iter().zip(&g).map(|(a, b)| a * b).sum::<f64>();
    for k in 0..x.len() {
        let scale = x[k].abs().max(1.0);
        let h = 1e-6 * scale;
        let (mut xp, mut xm) = (x.to_vec(), x.to_vec());
        xp[k] += h;
        xm[k] -= h;
        let num = (gdot(f(&xp)) - gdot(f(&xm))) / (xp[k] - xm[k]);
        let ana = acc[k] - init[k];
        let tol = 1e-7 * ana.abs() + 1e-9 * (1.0 + s) / scale;
        assert!(
            (num - ana).abs() <= tol,
            "{name}: d/dx[{k}] at x = {x:?}, g = {g:?}: adjoint {ana}, central difference {num} \
             (|diff| {} > tol {tol})",
            (num - ana).abs()
        );
    }
}

fn check1<A: Flat, C: Flat>(
    name: &str,
    a: A,
    f: impl Fn(A) -> C,
    adj: impl Fn(A, &mut A, C),
    rng: &mut Rng,
) {
    fd_check(
        name,
        &a.flat(),
        &|x| f(A::unflat(x)).flat(),
        &|x, g, acc| {
            let mut aa = A::unflat(acc);
            adj(A::unflat(x), &mut aa, C::unflat(g));
            acc.copy_from_slice(&aa.flat());
        },
        rng,
    );
}

fn check2<A: Flat, B: Flat, C: Flat>(
    name: &str,
    a: A,
    b: B,
    f: impl Fn(A, B) -> C,
    adj: impl Fn(A, B, &mut A, &mut B, C),
    rng: &mut Rng,
) {
    let na = A::N;
    fd_check(
        name,
        &[a.flat(), b.flat()].concat(),
        &|x| f(A::unflat(&x[..na]), B::unflat(&x[na..])).flat(),
        &|x, g, acc| {
            let (mut aa, mut ab) = (A::unflat(&acc[..na]), B::unflat(&acc[na..]));
            adj(
                A::unflat(&x[..na]),
                B::unflat(&x[na..]),
                &mut aa,
                &mut ab,
                C::unflat(g),
            );
            acc.copy_from_slice(&[aa.flat(), ab.flat()].concat());
        },
        rng,
    );
}

#[allow(clippy::type_complexity)]
fn check3<A: Flat, B: Flat, T: Flat, C: Flat>(
    name: &str,
    (a, b, t): (A, B, T),
    f: impl Fn(A, B, T) -> C,
    adj: impl Fn(A, B, T, &mut A, &mut B, &mut T, C),
    rng: &mut Rng,
) {
    let (na, nb) = (A::N, A::N + B::N);
    fd_check(
        name,
        &[a.flat(), b.flat(), t.flat()].concat(),
        &|x| {
            f(
                A::unflat(&x[..na]),
                B::unflat(&x[na..nb]),
                T::unflat(&x[nb..]),
            )
            .flat()
        },
        &|x, g, acc| {
            let (mut aa, mut ab, mut at) = (
                A::unflat(&acc[..na]),
                B::unflat(&acc[na..nb]),
                T::unflat(&acc[nb..]),
            );
            adj(
                A::unflat(&x[..na]),
                B::unflat(&x[na..nb]),
                T::unflat(&x[nb..]),
                &mut aa,
                &mut ab,
                &mut at,
                C::unflat(g),
            );
            acc.copy_from_slice(&[aa.flat(), ab.flat(), at.flat()].concat());
        },
        rng,
    );
}

/// The f32 tolerance (see the module docs).
const TOL32: f64 = 3e-5;

/// Largest `|a32 - a64| / max(1, |a64|)` seen, in units of 1e-9 (for
/// `f32_tolerance_is_not_slack`).
static MAX_ERR32: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

fn close32<T: Wide>(name: &str, what: &str, got32: T::N, want64: T) {
    let (g, w) = (T::widen(got32).flat(), want64.flat());
    for k in 0..g.len() {
        let err = (g[k] - w[k]).abs() / w[k].abs().max(1.0);
        MAX_ERR32.fetch_max((err * 1e9) as u64, std::sync::atomic::Ordering::Relaxed);
        assert!(
            err <= TOL32,
            "{name}: f32 {what}[{k}] = {} but f64 gives {} (rel err {err})",
            g[k],
            w[k]
        );
    }
}

fn cmp1<A: Wide, C: Wide>(
    name: &str,
    a: A,
    adj64: impl Fn(A, &mut A, C),
    adj32: impl Fn(A::N, &mut A::N, C::N),
    rng: &mut Rng,
) {
    let g: C = rnd(rng, 0.25, 1.5);
    let mut a64 = A::unflat(&vec![0.0; A::N]);
    let mut a32 = a64.narrow();
    adj64(a, &mut a64, g);
    adj32(a.narrow(), &mut a32, g.narrow());
    close32(name, "adj_a", a32, a64);
}

fn cmp2<A: Wide, B: Wide, C: Wide>(
    name: &str,
    a: A,
    b: B,
    adj64: impl Fn(A, B, &mut A, &mut B, C),
    adj32: impl Fn(A::N, B::N, &mut A::N, &mut B::N, C::N),
    rng: &mut Rng,
) {
    let g: C = rnd(rng, 0.25, 1.5);
    let (mut a64, mut b64) = (A::unflat(&vec![0.0; A::N]), B::unflat(&vec![0.0; B::N]));
    let (mut a32, mut b32) = (a64.narrow(), b64.narrow());
    adj64(a, b, &mut a64, &mut b64, g);
    adj32(a.narrow(), b.narrow(), &mut a32, &mut b32, g.narrow());
    close32(name, "adj_a", a32, a64);
    close32(name, "adj_b", b32, b64);
}

#[allow(clippy::type_complexity)]
fn cmp3<A: Wide, B: Wide, T: Wide, C: Wide>(
    name: &str,
    (a, b, t): (A, B, T),
    adj64: impl Fn(A, B, T, &mut A, &mut B, &mut T, C),
    adj32: impl Fn(A::N, B::N, T::N, &mut A::N, &mut B::N, &mut T::N, C::N),
    rng: &mut Rng,
) {
    let g: C = rnd(rng, 0.25, 1.5);
    let mut a64 = A::unflat(&vec![0.0; A::N]);
    let mut b64 = B::unflat(&vec![0.0; B::N]);
    let mut t64 = T::unflat(&vec![0.0; T::N]);
    let (mut a32, mut b32, mut t32) = (a64.narrow(), b64.narrow(), t64.narrow());
    adj64(a, b, t, &mut a64, &mut b64, &mut t64, g);
    adj32(
        a.narrow(),
        b.narrow(),
        t.narrow(),
        &mut a32,
        &mut b32,
        &mut t32,
        g.narrow(),
    );
    close32(name, "adj_a", a32, a64);
    close32(name, "adj_b", b32, b64);
    close32(name, "adj_t", t32, t64);
}

/// Points per checked combination.
const POINTS: usize = 12;

/// `frac(|a / b|)` lane by lane (broadcasting a one-lane side) is in `[0.1, 0.9]`: `%` is
/// smooth there, and f32 and f64 agree on the integer part of the quotient.
fn rem_ok(a: &[f64], b: &[f64]) -> bool {
    let n = a.len().max(b.len());
    (0..n).all(|i| {
        let q = (a[i.min(a.len() - 1)] / b[i.min(b.len() - 1)]).abs();
        let f = q - q.floor();
        (0.1..=0.9).contains(&f)
    })
}

/// Random operands for `op`: divisors have magnitude >= 0.5; `%` operands are kept away
/// from the discontinuities of the quotient.
fn operands<A: Flat, B: Flat>(rng: &mut Rng, op: &str) -> (A, B) {
    loop {
        let a: A = rnd(rng, 0.1, 3.0);
        let b: B = rnd(rng, 0.5, 2.0);
        if op != "%" || rem_ok(&a.flat(), &b.flat()) {
            return (a, b);
        }
    }
}

/// Every binary operator combination `A op B` (f64 types), checked against central
/// differences of glam's own operator, and its f32 counterpart against it.
macro_rules! bin {
    ($rng:expr; $($a:ty, $op:tt, $b:ty => $adj:ident);* $(;)?) => {$(
        for _ in 0..POINTS {
            let name = concat!(stringify!($a), " ", stringify!($op), " ", stringify!($b));
            let (a, b) = operands::<$a, $b>($rng, stringify!($op));
            check2(name, a, b, |a: $a, b: $b| a $op b, $adj::<$a, $b>, $rng);
            cmp2(
                name,
                a,
                b,
                $adj::<$a, $b>,
                $adj::<<$a as Wide>::N, <$b as Wide>::N>,
                $rng,
            );
        }
    )*};
}

// ------------------------------------------------------------------------------------------
// Adjoint trait
// ------------------------------------------------------------------------------------------

#[test]
fn zero_and_accumulate() {
    assert_eq!(zero::<f32>(), 0.0);
    assert_eq!(zero::<i64>(), 0);
    assert!(!zero::<bool>());
    assert_eq!(zero::<Vec3>(), Vec3::ZERO);
    assert_eq!(zero::<DMat4>(), DMat4::ZERO);
    assert_eq!(zero::<UVec2>(), UVec2::ZERO);
    // The zero adjoint of a quaternion is (0, 0, 0, 0), not the identity.
    assert_eq!(zero::<Quat>().to_array(), [0.0; 4]);
    assert_eq!(zero::<DQuat>().to_array(), [0.0; 4]);

    let mut q = DQuat::from_xyzw(1.0, 2.0, 3.0, 4.0);
    q.adj_accum(DQuat::from_xyzw(0.5, 0.5, 0.5, 0.5));
    assert_eq!(q.to_array(), [1.5, 2.5, 3.5, 4.5]);
    let mut m3 = Mat3::IDENTITY;
    m3.adj_accum(Mat3::IDENTITY);
    assert_eq!(m3, Mat3::IDENTITY * 2.0);
    let mut x = 1.5f64;
    x.adj_accum(2.0);
    assert_eq!(x, 3.5);
    // Integer adjoints are always zero: accumulation is a no-op.
    let mut i = 3i32;
    i.adj_accum(4);
    assert_eq!(i, 3);
    let mut v = IVec3::ONE;
    v.adj_accum(IVec3::ONE);
    assert_eq!(v, IVec3::ONE);
    let mut b = false;
    b.adj_accum(true);
    assert!(!b);
}

// ------------------------------------------------------------------------------------------
// Operators
// ------------------------------------------------------------------------------------------

#[test]
fn scalar_operators() {
    let rng = &mut Rng(0x1234_5678);
    bin!(rng;
        f64, +, f64 => adj_add; f64, -, f64 => adj_sub; f64, *, f64 => adj_mul;
        f64, /, f64 => adj_div; f64, %, f64 => adj_rem;
    );
    for _ in 0..POINTS {
        let a: f64 = rnd(rng, 0.1, 3.0);
        check1("-f64", a, |a: f64| -a, adj_neg::<f64>, rng);
        cmp1("-f64", a, adj_neg::<f64>, adj_neg::<f32>, rng);
    }
}

#[test]
fn vector_operators() {
    let rng = &mut Rng(0x2345_6789);
    bin!(rng;
        DVec2, +, DVec2 => adj_add; DVec2, -, DVec2 => adj_sub; DVec2, *, DVec2 => adj_mul;
        DVec2, /, DVec2 => adj_div; DVec2, %, DVec2 => adj_rem;
        DVec3, +, DVec3 => adj_add; DVec3, -, DVec3 => adj_sub; DVec3, *, DVec3 => adj_mul;
        DVec3, /, DVec3 => adj_div; DVec3, %, DVec3 => adj_rem;
        DVec2, +, f64 => adj_add; DVec2, -, f64 => adj_sub; DVec2, *, f64 => adj_mul;
        DVec2, /, f64 => adj_div; DVec2, %, f64 => adj_rem;
        DVec3, +, f64 => adj_add; DVec3, -, f64 => adj_sub; DVec3, *, f64 => adj_mul;
        DVec3, /, f64 => adj_div; DVec3, %, f64 => adj_rem;
        f64, +, DVec2 => adj_add; f64, -, DVec2 => adj_sub; f64, *, DVec2 => adj_mul;
        f64, /, DVec2 => adj_div; f64, %, DVec2 => adj_rem;
        f64, +, DVec3 => adj_add; f64, -, DVec3 => adj_sub; f64, *, DVec3 => adj_mul;
        f64, /, DVec3 => adj_div; f64, %, DVec3 => adj_rem;
    );
    // DVec4 `%` is Rust's `%` per lane, but glam's SSE2 Vec4 `%` is floored: the f32
    // counterpart is checked separately (`vec4_rem_follows_glam`).
    bin!(rng;
        DVec4, +, DVec4 => adj_add; DVec4, -, DVec4 => adj_sub; DVec4, *, DVec4 => adj_mul;
        DVec4, /, DVec4 => adj_div;
        DVec4, +, f64 => adj_add; DVec4, -, f64 => adj_sub; DVec4, *, f64 => adj_mul;
        DVec4, /, f64 => adj_div;
        f64, +, DVec4 => adj_add; f64, -, DVec4 => adj_sub; f64, *, DVec4 => adj_mul;
        f64, /, DVec4 => adj_div;
    );
    for _ in 0..POINTS {
        let (a, b) = operands::<DVec4, DVec4>(rng, "%");
        check2(
            "DVec4 % DVec4",
            a,
            b,
            |a, b| a % b,
            adj_rem::<DVec4, DVec4>,
            rng,
        );
        let (a, s) = operands::<DVec4, f64>(rng, "%");
        check2(
            "DVec4 % f64",
            a,
            s,
            |a, b| a % b,
            adj_rem::<DVec4, f64>,
            rng,
        );
        let (s, b) = operands::<f64, DVec4>(rng, "%");
        check2(
            "f64 % DVec4",
            s,
            b,
            |a, b| a % b,
            adj_rem::<f64, DVec4>,
            rng,
        );
    }
    for _ in 0..POINTS {
        let (a2, a3, a4) = (rnd(rng, 0.1, 3.0), rnd(rng, 0.1, 3.0), rnd(rng, 0.1, 3.0));
        check1("-DVec2", a2, |a: DVec2| -a, adj_neg::<DVec2>, rng);
        check1("-DVec3", a3, |a: DVec3| -a, adj_neg::<DVec3>, rng);
        check1("-DVec4", a4, |a: DVec4| -a, adj_neg::<DVec4>, rng);
        cmp1("-Vec2", a2, adj_neg::<DVec2>, adj_neg::<Vec2>, rng);
        cmp1("-Vec3", a3, adj_neg::<DVec3>, adj_neg::<Vec3>, rng);
        cmp1("-Vec4", a4, adj_neg::<DVec4>, adj_neg::<Vec4>, rng);
    }
}

/// glam's `Vec4 % Vec4` (and so `Vec4 % f32`, `f32 % Vec4`, which splat) is the floored
/// modulo on SSE2: the adjoint must follow glam's forward, checked here by f32 central
/// differences of glam's own operator. `%` is piecewise linear, so a large exact step
/// (`2^-8`) that stays inside one linear piece gives the slope up to f32 rounding:
/// `|num - ana| <= 1e-3` (rounding about `4 ulp(3) / 2h ≈ 2e-4`).
#[test]
fn vec4_rem_follows_glam() {
    let rng = &mut Rng(0x3456_789A);
    let h = 1.0f32 / 256.0;
    // The quotient's integer part for a negative quotient tells the two semantics apart.
    let floored = (Vec4::splat(-1.0) % Vec4::splat(3.0)).x == 2.0;
    let mut negative_quotients = 0;
    let mut scalar_sides = 0;
    for _ in 0..200 {
        let (a, b) = operands::<DVec4, DVec4>(rng, "%");
        let (a, b) = (a.as_vec4(), b.as_vec4());
        let g = Vec4::new(0.5, -1.25, 1.0, 0.75);
        let (mut aa, mut ab) = (Vec4::ZERO, Vec4::ZERO);
        adj_rem(a, b, &mut aa, &mut ab, g);
        for i in 0..4 {
            let e = Vec4::AXES[i];
            let fa = ((a + e * h) % b - (a - e * h) % b)[i] / (2.0 * h) * g[i];
            let fb = (a % (b + e * h) - a % (b - e * h))[i] / (2.0 * h) * g[i];
            assert!(
                (fa - aa[i]).abs() <= 1e-3,
                "Vec4 % d/da[{i}]: {fa} vs {}",
                aa[i]
            );
            assert!(
                (fb - ab[i]).abs() <= 1e-3,
                "Vec4 % d/db[{i}]: {fb} vs {}",
                ab[i]
            );
            let q = a[i] / b[i];
            if q < 0.0 {
                negative_quotients += 1;
                let n = if floored { q.floor() } else { q.trunc() };
                assert_eq!(ab[i], -g[i] * n);
            }
        }
        // With a scalar on either side (4 lanes summed: tolerance 4e-3).
        let s = b.x;
        if rem_ok(&a.as_dvec4().to_array(), &[s as f64]) {
            let (mut aa, mut as_) = (Vec4::ZERO, 0.0f32);
            adj_rem(a, s, &mut aa, &mut as_, g);
            let fs = ((a % (s + h) - a % (s - h)) / (2.0 * h) * g).element_sum();
            assert!((fs - as_).abs() <= 4e-3, "Vec4 % f32: {fs} vs {as_}");
            assert_eq!(aa, g);
            scalar_sides += 1;
        }
        let s = a.x;
        if rem_ok(&[s as f64], &b.as_dvec4().to_array()) {
            let (mut as_, mut ab) = (0.0f32, Vec4::ZERO);
            adj_rem(s, b, &mut as_, &mut ab, g);
            let fs = ((s + h) % b - (s - h) % b) / (2.0 * h) * g;
            assert!((fs.element_sum() - as_).abs() <= 4e-3, "f32 % Vec4");
            for i in 0..4 {
                let fb = (s % (b + Vec4::AXES[i] * h) - s % (b - Vec4::AXES[i] * h))[i] / (2.0 * h);
                assert!((fb * g[i] - ab[i]).abs() <= 1e-3, "f32 % Vec4 d/db[{i}]");
            }
            scalar_sides += 1;
        }
    }
    assert!(scalar_sides > 20, "{scalar_sides}");
    assert!(negative_quotients > 100);
}

#[test]
fn matrix_operators() {
    let rng = &mut Rng(0x4567_89AB);
    bin!(rng;
        DMat2, +, DMat2 => adj_add; DMat2, -, DMat2 => adj_sub; DMat2, *, DMat2 => adj_mul;
        DMat3, +, DMat3 => adj_add; DMat3, -, DMat3 => adj_sub; DMat3, *, DMat3 => adj_mul;
        DMat4, +, DMat4 => adj_add; DMat4, -, DMat4 => adj_sub; DMat4, *, DMat4 => adj_mul;
        DMat2, *, DVec2 => adj_mul; DMat3, *, DVec3 => adj_mul; DMat4, *, DVec4 => adj_mul;
        DMat2, *, f64 => adj_mul; DMat3, *, f64 => adj_mul; DMat4, *, f64 => adj_mul;
        DMat2, /, f64 => adj_div; DMat3, /, f64 => adj_div; DMat4, /, f64 => adj_div;
        f64, *, DMat2 => adj_mul; f64, *, DMat3 => adj_mul; f64, *, DMat4 => adj_mul;
        // glam 0.30: `s / M` computes `M / s`; the central differences are of glam's own `/`.
        f64, /, DMat2 => adj_div; f64, /, DMat3 => adj_div; f64, /, DMat4 => adj_div;
    );
    for _ in 0..POINTS {
        let (a2, a3, a4) = (rnd(rng, 0.1, 3.0), rnd(rng, 0.1, 3.0), rnd(rng, 0.1, 3.0));
        check1("-DMat2", a2, |a: DMat2| -a, adj_neg::<DMat2>, rng);
        check1("-DMat3", a3, |a: DMat3| -a, adj_neg::<DMat3>, rng);
        check1("-DMat4", a4, |a: DMat4| -a, adj_neg::<DMat4>, rng);
        cmp1("-Mat2", a2, adj_neg::<DMat2>, adj_neg::<Mat2>, rng);
        cmp1("-Mat3", a3, adj_neg::<DMat3>, adj_neg::<Mat3>, rng);
        cmp1("-Mat4", a4, adj_neg::<DMat4>, adj_neg::<Mat4>, rng);
    }
}

#[test]
fn quaternion_operators() {
    let rng = &mut Rng(0x5678_9ABC);
    // Random quaternions are not unit: glam's formulas (and the adjoints) hold for any.
    bin!(rng;
        DQuat, +, DQuat => adj_add; DQuat, -, DQuat => adj_sub; DQuat, *, DQuat => adj_mul;
        DQuat, *, DVec3 => adj_mul; DQuat, *, f64 => adj_mul; DQuat, /, f64 => adj_div;
    );
    for _ in 0..POINTS {
        // Unit quaternions too (rotations), where q * v preserves length.
        let q = DQuat::from_axis_angle(
            rnd::<DVec3>(rng, 0.1, 1.0).normalize(),
            rng.range(-3.0, 3.0),
        );
        let v: DVec3 = rnd(rng, 0.1, 3.0);
        check2(
            "unit DQuat * DVec3",
            q,
            v,
            |q, v| q * v,
            adj_mul::<DQuat, DVec3>,
            rng,
        );
        cmp2(
            "unit Quat * Vec3",
            q,
            v,
            adj_mul::<DQuat, DVec3>,
            adj_mul::<Quat, Vec3>,
            rng,
        );
        let a: DQuat = rnd(rng, 0.1, 3.0);
        check1("-DQuat", a, |a: DQuat| -a, adj_neg::<DQuat>, rng);
        cmp1("-Quat", a, adj_neg::<DQuat>, adj_neg::<Quat>, rng);
    }
}

/// Integer operands: every combination the language allows type-checks, and leaves the
/// (always zero) adjoints alone.
#[test]
fn integer_operators_are_no_ops() {
    macro_rules! noop {
        ($($a:expr, $b:expr, $g:expr);* $(;)?) => {$(
            let (a, b, g) = ($a, $b, $g);
            let (mut aa, mut ab) = (a, b);
            adj_add(a, b, &mut aa, &mut ab, g);
            adj_sub(a, b, &mut aa, &mut ab, g);
            adj_mul(a, b, &mut aa, &mut ab, g);
            adj_div(a, b, &mut aa, &mut ab, g);
            adj_rem(a, b, &mut aa, &mut ab, g);
            assert!(aa == a && ab == b, "{:?}", (a, b));
        )*};
    }
    noop!(
        3i8, 2i8, 1i8; 3i16, 2i16, 1i16; 3i32, 2i32, 1i32; 3i64, 2i64, 1i64;
        3isize, 2isize, 1isize; 3u8, 2u8, 1u8; 3u16, 2u16, 1u16; 3u32, 2u32, 1u32;
        3u64, 2u64, 1u64; 3usize, 2usize, 1usize;
        IVec2::ONE, IVec2::ONE, IVec2::ONE; IVec2::ONE, 2i32, IVec2::ONE;
        2i32, IVec2::ONE, IVec2::ONE;
        IVec3::ONE, IVec3::ONE, IVec3::ONE; IVec3::ONE, 2i32, IVec3::ONE;
        2i32, IVec3::ONE, IVec3::ONE;
        IVec4::ONE, IVec4::ONE, IVec4::ONE; IVec4::ONE, 2i32, IVec4::ONE;
        2i32, IVec4::ONE, IVec4::ONE;
        UVec2::ONE, UVec2::ONE, UVec2::ONE; UVec2::ONE, 2u32, UVec2::ONE;
        2u32, UVec2::ONE, UVec2::ONE;
        UVec3::ONE, UVec3::ONE, UVec3::ONE; UVec3::ONE, 2u32, UVec3::ONE;
        2u32, UVec3::ONE, UVec3::ONE;
        UVec4::ONE, UVec4::ONE, UVec4::ONE; UVec4::ONE, 2u32, UVec4::ONE;
        2u32, UVec4::ONE, UVec4::ONE;
    );
    macro_rules! noop_neg {
        ($($a:expr),*) => {$(
            let a = $a;
            let mut aa = a;
            adj_neg(a, &mut aa, a);
            assert_eq!(aa, a);
        )*};
    }
    noop_neg!(3i8, 3i16, 3i32, 3i64, 3isize, 3u8, 3u16, 3u32, 3u64, 3usize);
    noop_neg!(
        IVec2::ONE,
        IVec3::ONE,
        IVec4::ONE,
        UVec2::ONE,
        UVec3::ONE,
        UVec4::ONE
    );
}

#[test]
fn hand_checked_operator_values() {
    // c = a / b: adj_a += g / b, adj_b -= g a / b².
    let (mut aa, mut ab) = (0.0, 0.0);
    adj_div(3.0f64, 2.0, &mut aa, &mut ab, 1.0);
    assert_eq!((aa, ab), (0.5, -0.75));
    // Rust's `%` truncates: -7 % 2 = -1 = -7 - (-3) * 2, so d/db = 3.
    let (mut aa, mut ab) = (0.0, 0.0);
    adj_rem(-7.0f64, 2.0, &mut aa, &mut ab, 1.0);
    assert_eq!((aa, ab), (1.0, 3.0));
    // M * v: adj_M = g vᵀ (column j is g * v[j]), adj_v = Mᵀ g.
    let mm = DMat2::from_cols(DVec2::new(1.0, 2.0), DVec2::new(3.0, 4.0));
    let (mut am, mut av) = (DMat2::ZERO, DVec2::ZERO);
    adj_mul(
        mm,
        DVec2::new(5.0, 6.0),
        &mut am,
        &mut av,
        DVec2::new(1.0, -1.0),
    );
    assert_eq!(am.x_axis, DVec2::new(5.0, -5.0));
    assert_eq!(am.y_axis, DVec2::new(6.0, -6.0));
    assert_eq!(av, DVec2::new(-1.0, -1.0));
    // s / M is M / s in glam 0.30.
    let (mut as_, mut am) = (0.0, DMat2::ZERO);
    adj_div(2.0f64, mm, &mut as_, &mut am, DMat2::IDENTITY);
    assert_eq!(am, DMat2::IDENTITY * 0.5);
    assert_eq!(as_, -(1.0 + 4.0) / 4.0);
    // Rotation of x by 90° about z: y. d/dv is the rotation's transpose.
    let q = DQuat::from_rotation_z(std::f64::consts::FRAC_PI_2);
    let (mut aq, mut av) = (zero::<DQuat>(), DVec3::ZERO);
    adj_mul(q, DVec3::X, &mut aq, &mut av, DVec3::Y);
    assert!((av - DVec3::X).length() < 1e-15, "{av}");
}

// ------------------------------------------------------------------------------------------
// Builtins
// ------------------------------------------------------------------------------------------

/// A float scalar builtin `f(x)` with its adjoint, at points from `gen`.
macro_rules! unary_scalar {
    ($rng:expr; $($f:ident, $adj:ident, $lo:expr, $hi:expr, $signed:expr);* $(;)?) => {$(
        for _ in 0..POINTS {
            let x = if $signed { $rng.mag($lo, $hi) } else { $rng.range($lo, $hi) };
            check1(stringify!($f), x, m::$f::<f64>, $adj::<f64>, $rng);
            cmp1(stringify!($f), x, $adj::<f64>, $adj::<f32>, $rng);
        }
    )*};
}

#[test]
fn scalar_builtins() {
    let rng = &mut Rng(0x6789_ABCD);
    unary_scalar!(rng;
        sqrt, adj_sqrt, 0.1, 4.0, false;
        exp, adj_exp, -3.0, 3.0, false;
        log, adj_log, 0.1, 4.0, false;
        sin, adj_sin, -4.0, 4.0, false;
        cos, adj_cos, -4.0, 4.0, false;
        tan, adj_tan, -1.3, 1.3, false;
        abs, adj_abs, 0.1, 3.0, true;
        floor, adj_floor, 0.1, 3.0, true;
        ceil, adj_ceil, 0.1, 3.0, true;
        sign, adj_sign, 0.1, 3.0, true;
    );
    for _ in 0..POINTS {
        // floor/ceil/sign: FD of a step away from the step is 0, and so are these; check the
        // others are not trivially zero by hand below.
        let (y, x) = (rng.mag(0.1, 3.0), rng.mag(0.1, 3.0));
        check2("atan2", y, x, m::atan2::<f64>, adj_atan2::<f64>, rng);
        cmp2("atan2", y, x, adj_atan2::<f64>, adj_atan2::<f32>, rng);
        let (x, y) = (rng.range(0.2, 3.0), rng.range(-3.0, 3.0));
        check2("pow", x, y, m::pow::<f64>, adj_pow::<f64>, rng);
        cmp2("pow", x, y, adj_pow::<f64>, adj_pow::<f32>, rng);
        // min/max at distinct operands.
        let (a, b) = loop {
            let (a, b) = (rng.mag(0.1, 3.0), rng.mag(0.1, 3.0));
            if (a - b).abs() > 1e-3 {
                break (a, b);
            }
        };
        check2("min", a, b, m::min::<f64>, adj_min::<f64>, rng);
        check2("max", a, b, m::max::<f64>, adj_max::<f64>, rng);
        cmp2("min", a, b, adj_min::<f64>, adj_min::<f32>, rng);
        cmp2("max", a, b, adj_max::<f64>, adj_max::<f32>, rng);
        let p = (rng.mag(0.1, 3.0), rng.mag(0.1, 3.0), rng.range(-0.5, 1.5));
        check3("lerp", p, m::lerp::<f64>, adj_lerp::<f64>, rng);
        cmp3("lerp", p, adj_lerp::<f64>, adj_lerp::<f32>, rng);
    }
    // pow with x < 0 and an integer exponent: d/dx exists (d/dy does not and is left 0).
    for y in [-3.0, -2.0, -1.0, 1.0, 2.0, 3.0] {
        let x = rng.range(-3.0, -0.2);
        check1(
            "pow(x < 0, integer y)",
            x,
            |x| m::pow(x, y),
            |x, ax, g| adj_pow(x, y, ax, &mut 0.0, g),
            rng,
        );
    }
}

#[test]
fn more_scalar_builtins() {
    let rng = &mut Rng(0x5EED_0F5C);
    unary_scalar!(rng;
        asin, adj_asin, -0.95, 0.95, false;
        acos, adj_acos, -0.95, 0.95, false;
        atan, adj_atan, -4.0, 4.0, false;
        sinh, adj_sinh, -3.0, 3.0, false;
        cosh, adj_cosh, -3.0, 3.0, false;
        tanh, adj_tanh, -3.0, 3.0, false;
        exp2, adj_exp2, -3.0, 3.0, false;
        log2, adj_log2, 0.1, 4.0, false;
        log10, adj_log10, 0.1, 4.0, false;
        cbrt, adj_cbrt, 0.1, 4.0, true;
        erf, adj_erf, -2.5, 2.5, false;
        erfc, adj_erfc, -2.5, 2.5, false;
        erfinv, adj_erfinv, -0.95, 0.95, false;
        erfcinv, adj_erfcinv, 0.05, 1.95, false;
        degrees, adj_degrees, -4.0, 4.0, false;
        radians, adj_radians, -400.0, 400.0, false;
        frac, adj_frac, 0.1, 0.9, true;
        round, adj_round, 0.1, 0.4, true;
        rint, adj_rint, 0.1, 0.4, true;
        trunc, adj_trunc, 0.1, 0.9, true;
        step, adj_step, 0.1, 3.0, true;
    );
    // smoothstep inside (0 < t < 1), both edge orders.
    for _ in 0..POINTS {
        let (e0, e1) = (rng.range(-2.0, -1.0), rng.range(1.0, 2.0));
        let x = rng.range(-0.9, 0.9);
        check3(
            "smoothstep",
            (e0, e1, x),
            m::smoothstep::<f64>,
            adj_smoothstep::<f64>,
            rng,
        );
        check3(
            "smoothstep reversed",
            (e1, e0, x),
            m::smoothstep::<f64>,
            adj_smoothstep::<f64>,
            rng,
        );
        cmp3(
            "smoothstep",
            (e0, e1, x),
            adj_smoothstep::<f64>,
            adj_smoothstep::<f32>,
            rng,
        );
    }
    // Flat places give exactly nothing: asin/acos outside [-1, 1] (clamped) and at ±1,
    // smoothstep outside its ramp and with equal edges.
    for x in [-2.0, -1.0, 1.0, 3.0, f64::NAN] {
        let (mut a, mut b) = (0.25, 0.25);
        adj_asin(x, &mut a, 1.0);
        adj_acos(x, &mut b, 1.0);
        assert_eq!((a, b), (0.25, 0.25), "asin/acos at {x}");
    }
    for (e0, e1, x) in [
        (0.0, 1.0, -0.5),
        (0.0, 1.0, 1.5),
        (1.0, 1.0, 1.0),
        (1.0, 1.0, 0.0),
    ] {
        let mut adj = [0.5f64; 3];
        let [a0, a1, ax] = &mut adj;
        adj_smoothstep(e0, e1, x, a0, a1, ax, 1.0);
        assert_eq!(adj, [0.5; 3], "smoothstep({e0}, {e1}, {x})");
    }
    // Infinite slopes where Warp's are: erfinv at ±1, cbrt at 0.
    let mut a = 0.0;
    adj_erfinv(1.0f64, &mut a, 1.0);
    assert_eq!(a, f64::INFINITY);
    let mut a = 0.0;
    adj_cbrt(0.0f64, &mut a, 1.0);
    assert_eq!(a, f64::INFINITY);
}

#[test]
fn clamp_builtin() {
    let rng = &mut Rng(0x789A_BCDE);
    let away = |a: f64, b: f64| (a - b).abs() > 1e-3;
    for _ in 0..4 * POINTS {
        // x inside, below and above [lo, hi]; and lo > hi.
        let p = loop {
            let (x, lo, hi) = (
                rng.range(-3.0, 3.0),
                rng.range(-2.0, 1.0),
                rng.range(-1.0, 2.0),
            );
            if away(x, lo) && away(x, hi) && away(lo, hi) {
                break (x, lo, hi);
            }
        };
        check3("clamp", p, m::clamp::<f64>, adj_clamp::<f64>, rng);
        cmp3("clamp", p, adj_clamp::<f64>, adj_clamp::<f32>, rng);
        let p = loop {
            let (x, lo, hi): (DVec3, DVec3, DVec3) = (
                uni(rng, -3.0, 3.0),
                uni(rng, -2.0, 1.0),
                uni(rng, -1.0, 2.0),
            );
            if (0..3).all(|i| away(x[i], lo[i]) && away(x[i], hi[i]) && away(lo[i], hi[i])) {
                break (x, lo, hi);
            }
        };
        check3("clamp DVec3", p, m::clamp::<DVec3>, adj_clamp::<DVec3>, rng);
        cmp3("clamp Vec3", p, adj_clamp::<DVec3>, adj_clamp::<Vec3>, rng);
    }
}

/// Componentwise builtins on every float vector size.
macro_rules! vec_builtins {
    ($rng:expr; $($v:ident: $f:ident),*) => {$(
        for _ in 0..POINTS {
            let name = stringify!($v);
            let (a, b) = loop {
                let (a, b): ($v, $v) = (rnd($rng, 0.1, 3.0), rnd($rng, 0.1, 3.0));
                if (a - b).abs().min_element() > 1e-3 {
                    break (a, b);
                }
            };
            check2(name, a, b, m::min::<$v>, adj_min::<$v>, $rng);
            check2(name, a, b, m::max::<$v>, adj_max::<$v>, $rng);
            cmp2(name, a, b, adj_min::<$v>, adj_min::<$f>, $rng);
            cmp2(name, a, b, adj_max::<$v>, adj_max::<$f>, $rng);
            check1(name, a, m::abs::<$v>, adj_abs::<$v>, $rng);
            cmp1(name, a, adj_abs::<$v>, adj_abs::<$f>, $rng);
            check2(name, a, b, m::dot::<$v>, adj_dot::<$v>, $rng);
            cmp2(name, a, b, adj_dot::<$v>, adj_dot::<$f>, $rng);
            check1(name, a, m::length::<$v>, adj_length::<$v>, $rng);
            cmp1(name, a, adj_length::<$v>, adj_length::<$f>, $rng);
            check1(name, a, m::normalize::<$v>, adj_normalize::<$v>, $rng);
            cmp1(name, a, adj_normalize::<$v>, adj_normalize::<$f>, $rng);
            let p = (a, b, $rng.range(-0.5, 1.5));
            check3(name, p, m::lerp::<$v>, adj_lerp::<$v>, $rng);
            cmp3(name, p, adj_lerp::<$v>, adj_lerp::<$f>, $rng);
        }
    )*};
}

#[test]
fn vector_builtins() {
    let rng = &mut Rng(0x89AB_CDEF);
    vec_builtins!(rng; DVec2: Vec2, DVec3: Vec3, DVec4: Vec4);
    for _ in 0..POINTS {
        let (a, b): (DVec3, DVec3) = (rnd(rng, 0.1, 3.0), rnd(rng, 0.1, 3.0));
        check2("cross", a, b, m::cross::<DVec3>, adj_cross::<DVec3>, rng);
        cmp2("cross", a, b, adj_cross::<DVec3>, adj_cross::<Vec3>, rng);
    }
}

#[test]
fn integer_builtins_are_no_ops() {
    let (mut a, mut b, mut c) = (IVec3::ONE, IVec3::ONE, IVec3::ONE);
    adj_min(IVec3::ZERO, IVec3::ONE, &mut a, &mut b, IVec3::ONE);
    adj_max(IVec3::ZERO, IVec3::ONE, &mut a, &mut b, IVec3::ONE);
    adj_clamp(
        IVec3::ZERO,
        IVec3::ONE,
        IVec3::ONE,
        &mut a,
        &mut b,
        &mut c,
        IVec3::ONE,
    );
    adj_abs(IVec3::NEG_ONE, &mut a, IVec3::ONE);
    adj_sign(IVec3::NEG_ONE, &mut a, IVec3::ONE);
    adj_dot(IVec3::ONE, IVec3::ONE, &mut a, &mut b, 5);
    adj_cross(IVec3::X, IVec3::Y, &mut a, &mut b, IVec3::ONE);
    assert_eq!((a, b, c), (IVec3::ONE, IVec3::ONE, IVec3::ONE));
    let (mut a, mut b) = (UVec4::ONE, UVec4::ONE);
    adj_min(UVec4::ZERO, UVec4::ONE, &mut a, &mut b, UVec4::ONE);
    adj_dot(UVec4::ONE, UVec4::ONE, &mut a, &mut b, 5);
    assert_eq!((a, b), (UVec4::ONE, UVec4::ONE));
    let (mut x, mut y, mut z) = (7i64, 7i64, 7i64);
    adj_max(1i64, 2, &mut x, &mut y, 3);
    adj_clamp(1i64, 2, 3, &mut x, &mut y, &mut z, 3);
    adj_abs(-1i64, &mut x, 3);
    assert_eq!((x, y, z), (7, 7, 7));
    let (mut x, mut y) = (7usize, 7usize);
    adj_min(1usize, 2, &mut x, &mut y, 3);
    assert_eq!((x, y), (7, 7));
}

// ------------------------------------------------------------------------------------------
// Edge rules
// ------------------------------------------------------------------------------------------

type Adj2 = fn(f64, f64, &mut f64, &mut f64, f64);
type Fwd2 = fn(f64, f64) -> f64;

/// `(adj_a, adj_b)` of `min`/`max` from zero with `adj_ret = 1`.
fn split(f: Adj2, a: f64, b: f64) -> (f64, f64) {
    let (mut aa, mut ab) = (0.0, 0.0);
    f(a, b, &mut aa, &mut ab, 1.0);
    (aa, ab)
}

#[test]
fn min_max_ties_and_nan() {
    let nan = f64::NAN;
    for f in [adj_min::<f64> as Adj2, adj_max::<f64>] {
        // Ties go to the first operand (also +0 against -0).
        assert_eq!(split(f, 1.5, 1.5), (1.0, 0.0));
        assert_eq!(split(f, 0.0, -0.0), (1.0, 0.0));
        assert_eq!(split(f, -0.0, 0.0), (1.0, 0.0));
        // Exactly one NaN: to the other operand, which fmin/fmax return.
        assert_eq!(split(f, nan, 2.0), (0.0, 1.0));
        assert_eq!(split(f, 2.0, nan), (1.0, 0.0));
        // Two NaNs: to the first.
        assert_eq!(split(f, nan, nan), (1.0, 0.0));
    }
    assert_eq!(split(adj_min::<f64>, 1.0, 2.0), (1.0, 0.0));
    assert_eq!(split(adj_min::<f64>, 2.0, 1.0), (0.0, 1.0));
    assert_eq!(split(adj_max::<f64>, 1.0, 2.0), (0.0, 1.0));
    assert_eq!(split(adj_max::<f64>, 2.0, 1.0), (1.0, 0.0));
    // The adjoint always goes to the operand the forward returned.
    let vals = [
        nan,
        -2.0,
        -0.0,
        0.0,
        1.0,
        1.0,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for &a in &vals {
        for &b in &vals {
            let pairs: [(Fwd2, Adj2); 2] = [
                (m::min::<f64>, adj_min::<f64>),
                (m::max::<f64>, adj_max::<f64>),
            ];
            for (fwd, adj) in pairs {
                let r = fwd(a, b);
                let (aa, ab) = split(adj, a, b);
                assert_eq!(aa + ab, 1.0);
                let returned = if aa == 1.0 { a } else { b };
                assert!(
                    returned == r || (returned.is_nan() && r.is_nan()),
                    "{a} {b}: forward {r}, adjoint to {returned}"
                );
            }
        }
    }
    // f32 and vectors componentwise, NaN lanes included.
    let (mut aa, mut ab) = (0.0f32, 0.0f32);
    adj_min(f32::NAN, 1.0, &mut aa, &mut ab, 1.0);
    assert_eq!((aa, ab), (0.0, 1.0));
    let a = Vec4::new(f32::NAN, 1.0, 3.0, 2.0);
    let b = Vec4::new(2.0, f32::NAN, 1.0, 2.0);
    let (mut aa, mut ab) = (Vec4::ZERO, Vec4::ZERO);
    adj_max(a, b, &mut aa, &mut ab, Vec4::ONE);
    assert_eq!(aa, Vec4::new(0.0, 1.0, 1.0, 1.0));
    assert_eq!(ab, Vec4::new(1.0, 0.0, 0.0, 0.0));
    let (mut aa, mut ab) = (DVec3::ZERO, DVec3::ZERO);
    adj_min(
        DVec3::new(1.0, 5.0, nan),
        DVec3::new(2.0, 4.0, 0.0),
        &mut aa,
        &mut ab,
        DVec3::new(1.0, 2.0, 3.0),
    );
    assert_eq!(aa, DVec3::new(1.0, 0.0, 0.0));
    assert_eq!(ab, DVec3::new(0.0, 2.0, 3.0));
}

#[test]
fn clamp_at_bounds() {
    let run = |x: f64, lo: f64, hi: f64| {
        let (mut ax, mut al, mut ah) = (0.0, 0.0, 0.0);
        adj_clamp(x, lo, hi, &mut ax, &mut al, &mut ah, 1.0);
        (ax, al, ah)
    };
    assert_eq!(run(0.5, 0.0, 1.0), (1.0, 0.0, 0.0));
    // At either bound (inclusive), to x.
    assert_eq!(run(0.0, 0.0, 1.0), (1.0, 0.0, 0.0));
    assert_eq!(run(1.0, 0.0, 1.0), (1.0, 0.0, 0.0));
    // Outside, to the bound returned.
    assert_eq!(run(-1.0, 0.0, 1.0), (0.0, 1.0, 0.0));
    assert_eq!(run(2.0, 0.0, 1.0), (0.0, 0.0, 1.0));
    // lo > hi: the forward returns hi.
    assert_eq!(m::clamp(0.5, 2.0, 1.0), 1.0);
    assert_eq!(run(0.5, 2.0, 1.0), (0.0, 0.0, 1.0));
    assert_eq!(run(3.0, 2.0, 1.0), (0.0, 0.0, 1.0));
    // lo == hi == x: to x.
    assert_eq!(run(1.0, 1.0, 1.0), (1.0, 0.0, 0.0));
    // NaN x: max(NaN, lo) = lo.
    assert_eq!(run(f64::NAN, 0.0, 1.0), (0.0, 1.0, 0.0));
    // Componentwise.
    let (mut ax, mut al, mut ah) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    adj_clamp(
        Vec3::new(-1.0, 0.5, 2.0),
        Vec3::ZERO,
        Vec3::ONE,
        &mut ax,
        &mut al,
        &mut ah,
        Vec3::new(1.0, 2.0, 3.0),
    );
    assert_eq!(ax, Vec3::new(0.0, 2.0, 0.0));
    assert_eq!(al, Vec3::new(1.0, 0.0, 0.0));
    assert_eq!(ah, Vec3::new(0.0, 0.0, 3.0));
}

#[test]
fn zero_vector_length_and_normalize() {
    let mut a = DVec3::ONE;
    adj_length(DVec3::ZERO, &mut a, 1.0);
    assert_eq!(a, DVec3::ONE);
    adj_normalize(DVec3::ZERO, &mut a, DVec3::new(1.0, 2.0, 3.0));
    assert_eq!(a, DVec3::ONE);
    let mut a = Vec4::ZERO;
    adj_length(Vec4::ZERO, &mut a, 1.0);
    adj_normalize(Vec4::ZERO, &mut a, Vec4::ONE);
    assert_eq!(a, Vec4::ZERO);
    let mut a = Vec2::ZERO;
    adj_normalize(Vec2::new(-0.0, 0.0), &mut a, Vec2::ONE);
    assert_eq!(a, Vec2::ZERO);
    // Just off zero the gradient exists (and is large for normalize).
    let mut a = DVec2::ZERO;
    adj_normalize(DVec2::new(1e-3, 0.0), &mut a, DVec2::new(0.0, 1.0));
    assert!((a - DVec2::new(0.0, 1e3)).length() < 1e-9, "{a}");
    // The gradient of normalize is orthogonal to the vector.
    let mut a = DVec3::ZERO;
    let v = DVec3::new(1.0, -2.0, 0.5);
    adj_normalize(v, &mut a, DVec3::new(0.3, 0.1, -0.7));
    assert!(a.dot(v).abs() < 1e-15);
    assert!(a.length() > 0.1);
}

#[test]
fn abs_sign_floor_ceil_edges() {
    let run = |x: f64| {
        let mut a = 0.0;
        adj_abs(x, &mut a, 2.0);
        a
    };
    assert_eq!(run(0.0), 2.0);
    assert_eq!(run(-0.0), 2.0);
    assert_eq!(run(-1e-300), -2.0);
    assert_eq!(run(3.0), 2.0);
    assert_eq!(run(-3.0), -2.0);
    let mut a = Vec3::ZERO;
    adj_abs(Vec3::new(-1.0, 0.0, 1.0), &mut a, Vec3::ONE);
    assert_eq!(a, Vec3::new(-1.0, 1.0, 1.0));
    // Piecewise constant: nothing accumulates.
    let mut a = 1.0f64;
    adj_floor(2.5, &mut a, 1.0);
    adj_ceil(2.5, &mut a, 1.0);
    adj_sign(-2.5, &mut a, 1.0);
    assert_eq!(a, 1.0);
    let mut v = DVec3::ONE;
    adj_sign(DVec3::NEG_ONE, &mut v, DVec3::ONE);
    assert_eq!(v, DVec3::ONE);
}

#[test]
fn pow_sqrt_log_atan2_edges() {
    let run = |x: f64, y: f64, g: f64| {
        let (mut ax, mut ay) = (0.0, 0.0);
        adj_pow(x, y, &mut ax, &mut ay, g);
        (ax, ay)
    };
    // x > 0: both partials.
    let (ax, ay) = run(2.0, 3.0, 1.0);
    assert_eq!(ax, 12.0);
    assert!((ay - 8.0 * 2f64.ln()).abs() < 1e-14);
    // x < 0, integer y: d/dx only; d/dy is left alone (not NaN).
    assert_eq!(run(-2.0, 3.0, 1.0), (12.0, 0.0));
    assert_eq!(run(-2.0, 2.0, 0.0), (0.0, 0.0));
    // x = 0: 0^2 has derivative 0 in x and in y.
    assert_eq!(run(0.0, 2.0, 1.0), (0.0, 0.0));
    assert_eq!(run(0.0, 1.0, 1.0), (1.0, 0.0));
    // y = 0: x^0 = 1 everywhere, derivative 0, also at x = 0 (no 0 * inf).
    assert_eq!(run(0.0, 0.0, 1.0), (0.0, 0.0));
    assert_eq!(run(-1.5, 0.0, 1.0), (0.0, 0.0));
    // x = 0, 0 < y < 1: infinite slope.
    assert_eq!(run(0.0, 0.5, 1.0).0, f64::INFINITY);
    // x < 0, non-integer y: the forward is NaN; d/dy stays untouched.
    let (ax, ay) = run(-2.0, 0.5, 1.0);
    assert!(ax.is_nan() && ay == 0.0);

    // sqrt: infinite at 0 (as Warp), 0.5 / sqrt(x) elsewhere.
    let mut a = 0.0f64;
    adj_sqrt(0.0, &mut a, 1.0);
    assert_eq!(a, f64::INFINITY);
    let mut a = 0.0f32;
    adj_sqrt(4.0, &mut a, 2.0);
    assert_eq!(a, 0.5);
    // log: 1 / x.
    let mut a = 0.0f64;
    adj_log(0.25, &mut a, 1.0);
    assert_eq!(a, 4.0);
    // atan2 at the origin: zero gradient, never NaN.
    let (mut ay, mut ax) = (1.0f64, 1.0f64);
    adj_atan2(0.0, 0.0, &mut ay, &mut ax, 1.0);
    assert_eq!((ay, ax), (1.0, 1.0));
    let (mut ay, mut ax) = (0.0f64, 0.0f64);
    adj_atan2(0.0, -2.0, &mut ay, &mut ax, 1.0);
    assert_eq!((ay, ax), (-0.5, 0.0));
}

// ------------------------------------------------------------------------------------------
// Casts
// ------------------------------------------------------------------------------------------

#[test]
fn casts() {
    let mut a = 1.0f64;
    adj_cast(&mut a, 0.5f32);
    assert_eq!(a, 1.5);
    let mut a = 1.0f32;
    adj_cast(&mut a, 0.25f64);
    assert_eq!(a, 1.25);
    // Rounded to the source type.
    let mut a = 0.0f32;
    adj_cast(&mut a, 0.1f64);
    assert_eq!(a, 0.1f32);
    let mut a = 1.0f64;
    adj_cast(&mut a, 2.0f64);
    assert_eq!(a, 3.0);
    let mut a = 1.0f32;
    adj_cast(&mut a, 2.0f32);
    assert_eq!(a, 3.0);
    // Anything integer or bool: no-op.
    let mut a = 1.0f32;
    adj_cast(&mut a, 5i32);
    adj_cast(&mut a, 5u8);
    adj_cast(&mut a, true);
    assert_eq!(a, 1.0);
    let mut a = 1.0f64;
    adj_cast(&mut a, 5usize);
    assert_eq!(a, 1.0);
    let mut i = 3i32;
    adj_cast(&mut i, 2.5f32);
    adj_cast(&mut i, 2.5f64);
    adj_cast(&mut i, 7i64);
    assert_eq!(i, 3);
    let mut u = 3usize;
    adj_cast(&mut u, 2.5f64);
    assert_eq!(u, 3);
    let mut b = false;
    adj_cast(&mut b, 1u8);
    assert!(!b);
}

/// Every pair of the 13 scalar types has a cast adjoint (a compile-time check).
#[test]
fn every_scalar_cast_pair_exists() {
    fn has<F: AdjCast<T>, T>() {}
    macro_rules! row {
        ($f:ty) => {
            has::<$f, bool>();
            has::<$f, i8>();
            has::<$f, i16>();
            has::<$f, i32>();
            has::<$f, i64>();
            has::<$f, isize>();
            has::<$f, u8>();
            has::<$f, u16>();
            has::<$f, u32>();
            has::<$f, u64>();
            has::<$f, usize>();
            has::<$f, f32>();
            has::<$f, f64>();
        };
    }
    row!(bool);
    row!(i8);
    row!(i16);
    row!(i32);
    row!(i64);
    row!(isize);
    row!(u8);
    row!(u16);
    row!(u32);
    row!(u64);
    row!(usize);
    row!(f32);
    row!(f64);
}

/// The f32 tolerance is not so loose that it could hide a formula error: the comparisons
/// above pass with a large margin (run the operator and builtin checks again here and look
/// at the largest error seen).
#[test]
fn f32_tolerance_is_not_slack() {
    scalar_operators();
    vector_operators();
    matrix_operators();
    quaternion_operators();
    scalar_builtins();
    clamp_builtin();
    vector_builtins();
    let max = MAX_ERR32.load(std::sync::atomic::Ordering::Relaxed) as f64 * 1e-9;
    eprintln!("largest f32 vs f64 relative adjoint error: {max:e}");
    assert!(max > 0.0, "the f32 comparisons did compare something");
    assert!(
        max < TOL32 / 3.0,
        "f32 error {max:e} is too close to the tolerance"
    );
}

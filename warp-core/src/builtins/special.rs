//! The error function family in plain Rust (std has no `erf`): `erf`, `erfc`, `erfinv`,
//! `erfcinv`, computed in f64; the f32 builtins evaluate these on the widened argument and
//! round once.
//!
//! The CUDA library calls CUDA's own `erf`/`erfc`/`erfinv`/`erfcinv` on the GPU; on the host
//! (where glibc has no `erfinv`) it runs a C++ transcription of this file, operation for
//! operation, so that `tests/cuda_host_cpp.rs` can compare the two bit for bit. A change here
//! must be made there too (`warp-cuda/cuda/wp_scalar.h`, namespace `wp::detail::special`).
//!
//! # Method
//!
//! * `exp(-x²)` is taken as `exp(-p) * (1 - e)` where `p + e == x * x` exactly (`e` from an
//!   FMA), so the rounding of `x * x` (relative `2⁻⁵³`, but absolute up to `1e-13` when
//!   `x² ≈ 700`) does not reach the result.
//! * `|x| < 1`: `erf(x) = 2/√π · exp(-x²) · Σₙ 2ⁿ x²ⁿ⁺¹ / (1·3·5···(2n+1))`, a series of
//!   positive terms (no cancellation), at most ~20 terms.
//! * `x >= 1`: `erfc(x) = exp(-x²) / (√π · F(x))` with the continued fraction
//!   `F(x) = x + (1/2)/(x + (2/2)/(x + (3/2)/(x + ...)))`, evaluated bottom-up from a depth
//!   `10 + 240/x²` (at most 250), which converges to below `1e-17` relative for `x >= 1`.
//!   `erf = 1 - erfc` there, `erfc = 1 - erf` for `|x| < 1` (the cancellation is at most a
//!   factor `erf(1)/erfc(1) ≈ 5.4`), and `erfc(-x) = 2 - erfc(x)`.
//! * The inverses start from Winitzki's closed-form approximation (relative error < 2e-3),
//!   then refine: `erfinv` on `|y| <= 0.5` by three Halley steps on `erf(x) - y`; the tails
//!   (`erfcinv(z)` for `z < 0.5`, and so `erfinv(y)` for `|y| > 0.5` through
//!   `erfcinv(1 - |y|)`, exact by Sterbenz) by five Newton steps on
//!   `ln(erfc(x)) - ln(z)`, where `ln(erfc(x)) = -x² - ln(√π F(x))` never underflows, so
//!   `erfcinv` is accurate down to the smallest subnormal.
//!
//! # Accuracy (measured against 50-digit mpmath values, `tests` below)
//!
//! * f64, with `ε = 2⁻⁵² ≈ 2.2e-16`: `erf`, `erfinv` and `erfcinv` within `4ε ≈ 9e-16`
//!   relative (measured worst: 2.6ε); `erfc` within `4ε` except on `-1 < x < 1`, where it is
//!   `1 - erf(x)` and the cancellation allows `10ε ≈ 2.2e-15` (measured worst: 6.8ε, near
//!   `x = 0.9`). Results below the normal range are measured against `f64::MIN_POSITIVE`.
//! * f32: the f64 result rounded once: within 1 ulp of the correctly rounded result (0.5 ulp
//!   plus the f64 error), for all four.
//!
//! # Special values (as CUDA's)
//!
//! `erf(±0) = ±0`, `erf(±∞) = ±1`, `erfc(+∞) = 0`, `erfc(-∞) = 2`; `erfinv(±1) = ±∞`,
//! `erfinv(±0) = ±0`, NaN outside `[-1, 1]`; `erfcinv(0) = +∞`, `erfcinv(2) = -∞`, NaN
//! outside `[0, 2]`; NaN in, NaN out.

/// `2/√π`.
const TWO_OVER_SQRT_PI: f64 = core::f64::consts::FRAC_2_SQRT_PI;
/// `√π`.
const SQRT_PI: f64 = 1.772_453_850_905_516;
/// Above this, `erfc(x)` is below half the smallest subnormal: 0.
const ERFC_ZERO_AT: f64 = 28.0;

/// `x * x` as an unevaluated sum `p + e` (exact).
#[inline]
fn square(x: f64) -> (f64, f64) {
    let p = x * x;
    (p, x.mul_add(x, -p))
}

/// `exp(-x²)`, with the rounding error of `x²` compensated to first order.
#[inline]
fn exp_neg_sq(x: f64) -> f64 {
    let (p, e) = square(x);
    (-p).exp() * (1.0 - e)
}

/// The continued fraction `F(x)` of `erfc(x) = exp(-x²) / (√π F(x))`, for `1 <= x < 28`.
#[inline]
fn erfc_cf(x: f64) -> f64 {
    let depth = (10.0 + 240.0 / (x * x)) as u32;
    let mut f = x;
    let mut n = depth;
    while n > 0 {
        f = x + (n as f64 * 0.5) / f;
        n -= 1;
    }
    f
}

/// `erf(x)` for `|x| < 1`, by the series of positive terms.
#[inline]
fn erf_series(x: f64) -> f64 {
    let two_x2 = 2.0 * (x * x);
    let mut term = x;
    let mut sum = x;
    let mut n = 1u32;
    loop {
        term = term * two_x2 / (2 * n + 1) as f64;
        let next = sum + term;
        if next == sum {
            break;
        }
        sum = next;
        n += 1;
    }
    TWO_OVER_SQRT_PI * sum * exp_neg_sq(x)
}

/// `erfc(x)` for `x >= 1` (0 from 28 on, and for +inf).
#[inline]
fn erfc_tail(x: f64) -> f64 {
    if x >= ERFC_ZERO_AT {
        return 0.0;
    }
    exp_neg_sq(x) / (SQRT_PI * erfc_cf(x))
}

/// The error function `erf(x) = 2/√π ∫₀ˣ exp(-t²) dt`.
pub fn erf(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    if x.abs() < 1.0 {
        return erf_series(x);
    }
    let r = 1.0 - erfc_tail(x.abs());
    if x < 0.0 {
        -r
    } else {
        r
    }
}

/// The complementary error function `erfc(x) = 1 - erf(x)`, accurate where it is small.
pub fn erfc(x: f64) -> f64 {
    if x.is_nan() {
        return x;
    }
    if x >= 1.0 {
        erfc_tail(x)
    } else if x > -1.0 {
        1.0 - erf_series(x)
    } else {
        2.0 - erfc_tail(-x)
    }
}

/// Winitzki's approximation of `erfinv` from `w = ln(1 - y²)` (`w < 0`): positive, within
/// 2e-3 relative.
#[inline]
fn winitzki(w: f64) -> f64 {
    const A: f64 = 0.147;
    let t = 2.0 / (core::f64::consts::PI * A) + 0.5 * w;
    ((t * t - w / A).sqrt() - t).sqrt()
}

/// `erfinv(y)` for `0 < |y| <= 0.5`: Halley's method on `erf(x) - y`.
#[inline]
fn erfinv_central(y: f64) -> f64 {
    let a = y.abs();
    let mut x = winitzki(((1.0 - a) * (1.0 + a)).ln());
    for _ in 0..3 {
        // u = f/f'; Halley's step with f'' = -2x f' is u / (1 + x u).
        let u = (erf(x) - a) / (TWO_OVER_SQRT_PI * exp_neg_sq(x));
        x -= u / (1.0 + x * u);
    }
    if y < 0.0 {
        -x
    } else {
        x
    }
}

/// `erfcinv(z)` for `0 < z < 0.5` (so the result is above 0.47): Newton's method on
/// `h(x) = ln(erfc(x)) - ln(z)`.
#[inline]
fn erfcinv_tail(z: f64) -> f64 {
    let lnz = z.ln();
    let mut x = winitzki((z * (2.0 - z)).ln());
    for _ in 0..5 {
        let (h, dh) = if x >= 1.0 {
            // ln(erfc(x)) = -(p + e) - ln(√π F); h' = erfc'/erfc = -2 F.
            let (p, e) = square(x);
            let f = erfc_cf(x);
            (-p - e - (SQRT_PI * f).ln() - lnz, -2.0 * f)
        } else {
            let c = erfc(x);
            (c.ln() - lnz, -(TWO_OVER_SQRT_PI * exp_neg_sq(x)) / c)
        };
        x -= h / dh;
    }
    x
}

/// The inverse error function: `erf(erfinv(y)) = y` for `y` in `[-1, 1]`.
pub fn erfinv(y: f64) -> f64 {
    let a = y.abs();
    if a.is_nan() || a > 1.0 {
        return f64::NAN;
    }
    if a == 1.0 {
        return if y < 0.0 {
            f64::NEG_INFINITY
        } else {
            f64::INFINITY
        };
    }
    if a == 0.0 {
        return y;
    }
    if a <= 0.5 {
        return erfinv_central(y);
    }
    let x = erfcinv_tail(1.0 - a);
    if y < 0.0 {
        -x
    } else {
        x
    }
}

/// The inverse complementary error function: `erfc(erfcinv(z)) = z` for `z` in `[0, 2]`.
pub fn erfcinv(z: f64) -> f64 {
    if z.is_nan() || !(0.0..=2.0).contains(&z) {
        return f64::NAN;
    }
    if z == 0.0 {
        return f64::INFINITY;
    }
    if z == 2.0 {
        return f64::NEG_INFINITY;
    }
    if z < 0.5 {
        erfcinv_tail(z)
    } else if z <= 1.5 {
        // 1 - z is exact here (Sterbenz); 1 - z == 0 at z == 1 gives 0.
        let y = 1.0 - z;
        if y == 0.0 {
            0.0
        } else {
            erfinv_central(y)
        }
    } else {
        -erfcinv_tail(2.0 - z)
    }
}

#[cfg(test)]
#[path = "special_ref.rs"]
mod reference;

#[cfg(test)]
mod tests {
    use super::reference::{ERFCINV_REF, ERFINV_REF, ERF_REF};
    use super::*;

    /// Relative error of `got` against `want` (both finite), with results below the normal
    /// range measured against the smallest normal (where relative error stops meaning much).
    fn rel(got: f64, want: f64) -> f64 {
        if got == want {
            return 0.0;
        }
        (got - want).abs() / want.abs().max(f64::MIN_POSITIVE)
    }

    fn ulps32(a: f32, b: f32) -> u32 {
        let o = |x: f32| {
            let i = x.to_bits() as i32;
            if i < 0 {
                -((i & 0x7fff_ffff) as i64)
            } else {
                i as i64
            }
        };
        (o(a) - o(b)).unsigned_abs() as u32
    }

    /// The accuracy the module documents: f64 within 4ε relative (`erfc` on `(-1, 1)`: 10ε),
    /// f32 within 1 ulp.
    const REL64: f64 = 4.0 * f64::EPSILON;
    const REL64_ERFC_MID: f64 = 10.0 * f64::EPSILON;

    #[test]
    fn erf_and_erfc_against_mpmath() {
        let (mut worst_erf, mut worst_erfc) = (0.0f64, 0.0f64);
        for &(x, e, c) in ERF_REF {
            let (ge, gc) = (erf(x), erfc(x));
            worst_erf = worst_erf.max(rel(ge, e));
            worst_erfc = worst_erfc.max(rel(gc, c));
            assert!(rel(ge, e) <= REL64, "erf({x:e}) = {ge:e}, want {e:e}");
            let tol_c = if x.abs() < 1.0 { REL64_ERFC_MID } else { REL64 };
            assert!(rel(gc, c) <= tol_c, "erfc({x:e}) = {gc:e}, want {c:e}");
            // f32: the f64 result rounded once (the reference rounded to f32 may differ from
            // the correctly rounded f32 by a double rounding, hence 1 ulp).
            let x32 = x as f32;
            if x32 as f64 == x {
                assert!(ulps32(erf(x) as f32, e as f32) <= 1, "erf f32 at {x}");
                assert!(ulps32(erfc(x) as f32, c as f32) <= 1, "erfc f32 at {x}");
            }
        }
        assert!(worst_erf <= REL64 && worst_erfc <= REL64_ERFC_MID);
    }

    #[test]
    fn inverses_against_mpmath() {
        for &(y, want) in ERFINV_REF {
            let got = erfinv(y);
            assert!(
                rel(got, want) <= REL64,
                "erfinv({y:e}) = {got:e}, want {want:e}"
            );
        }
        for &(z, want) in ERFCINV_REF {
            let got = erfcinv(z);
            assert!(
                rel(got, want) <= REL64,
                "erfcinv({z:e}) = {got:e}, want {want:e}"
            );
        }
    }

    #[test]
    fn round_trips() {
        // erf(erfinv(y)) = y up to erf's conditioning; many y, both signs.
        let mut y = -0.999_999;
        while y < 1.0 {
            let x = erfinv(y);
            let slope = TWO_OVER_SQRT_PI * (-x * x).exp();
            let tol = 4.0 * f64::EPSILON * (y.abs() + slope * x.abs());
            assert!((erf(x) - y).abs() <= tol, "erf(erfinv({y}))");
            y += 0.012_345_6;
        }
        let mut z = 1e-300;
        while z < 2.0 {
            let x = erfcinv(z);
            assert!(
                rel(erfc(x), z) <= 1e-13 * (1.0 + x * x),
                "erfc(erfcinv({z:e}))"
            );
            z *= 3.7;
        }
    }

    #[test]
    fn special_values() {
        assert_eq!(erf(0.0).to_bits(), 0.0f64.to_bits());
        assert_eq!(erf(-0.0).to_bits(), (-0.0f64).to_bits());
        assert_eq!(erf(f64::INFINITY), 1.0);
        assert_eq!(erf(f64::NEG_INFINITY), -1.0);
        assert_eq!(erfc(f64::INFINITY), 0.0);
        assert_eq!(erfc(f64::NEG_INFINITY), 2.0);
        assert_eq!(erfc(1e300), 0.0);
        assert_eq!(erf(-1e300), -1.0);
        assert_eq!(erfc(0.0), 1.0);
        assert!(erf(f64::NAN).is_nan() && erfc(f64::NAN).is_nan());
        assert_eq!(erfinv(1.0), f64::INFINITY);
        assert_eq!(erfinv(-1.0), f64::NEG_INFINITY);
        assert_eq!(erfinv(-0.0).to_bits(), (-0.0f64).to_bits());
        assert!(erfinv(1.0 + f64::EPSILON).is_nan());
        assert!(erfinv(-2.0).is_nan() && erfinv(f64::NAN).is_nan());
        assert_eq!(erfcinv(0.0), f64::INFINITY);
        assert_eq!(erfcinv(2.0), f64::NEG_INFINITY);
        assert_eq!(erfcinv(1.0), 0.0);
        assert!(erfcinv(-1e-300).is_nan() && erfcinv(2.5).is_nan());
        assert!(erfcinv(f64::NAN).is_nan());
        // The smallest subnormal has a finite inverse.
        let x = erfcinv(f64::from_bits(1));
        assert!(x > 27.0 && x < 27.5, "{x}");
    }
}

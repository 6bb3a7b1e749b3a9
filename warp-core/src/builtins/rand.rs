//! Random numbers (CPU side of the table's "rand" section): NVIDIA Warp's generator, so that a
//! seed gives the sequence Warp's definitions give.
//!
//! The state is a `u32`. [`rand_pcg`] is the PCG hash of Jarzynski and Olano ("Hash Functions
//! for GPU Rendering", JCGT 2020), used both to seed ([`rand_init`], [`rand_init_offset`]) and
//! to advance: every draw replaces the state by `rand_pcg(state)` and reads the new state.
//!
//! In a kernel, `randf(&mut state)` advances `state` in place. The macro lowers it into pure
//! operations: the result is the function here of the state *before* the draw (`randf(s)` is
//! the value that `randf(&mut s)` returns), and the state is then replaced by [`rand_pcg`]
//! applied once per uniform draw the builtin consumes ([`DRAWS`] lists them). So the IR stays
//! pure and the adjoint's replay recomputes the same draws.
//!
//! Each function here is the exact arithmetic the CUDA library (`wp_rand.h`) performs, in the
//! same order:
//!
//! * a uniform draw `u` is the state's top 24 bits times `2^-24`: `[0, 1 - 2^-24]`, exact;
//! * `randf_range(s, lo, hi) = (hi - lo) * u + lo`, one rounding per operation (the CUDA side
//!   spells it `__fmul_rn`/`__fadd_rn`, which NVRTC never contracts into an FMA), so it
//!   matches bit for bit;
//! * `randn` is Box-Muller: `sqrt(-2 ln(u1 + 5.96e-8)) * cos(2π u2)`, the first draw for the
//!   radius (Warp's C++ leaves the order of its two draws to the compiler; here it is fixed);
//! * the samplers draw in the order Warp's code lists them. Those that call `sqrt` only
//!   (`sample_triangle`, `sample_unit_square`, `sample_unit_cube`) are exact on both backends;
//!   those that call `ln`, `cos`, `sin`, `acos` or `powf` use the platform's libm here and
//!   CUDA's math library on the GPU (documented to 1 to 4 ulp), so they agree to a few ulp.
//!
//! Every one of them is f32, as in Warp. All are non-differentiable (zero gradient).

/// How many uniform draws (state steps) each state-advancing builtin consumes; `poisson`
/// consumes a variable number (see [`poisson_state`]). The macro's builtin table states the
/// same counts in its rows (`draws` in `warp-macros/src/builtins/rows/rand.rs`; the macro
/// lowers the draws), and a test there compares the two; `tests` here check these against the
/// functions.
pub const DRAWS: &[(&str, u32)] = &[
    ("randi", 1),
    ("randu", 1),
    ("randf", 1),
    ("randn", 2),
    ("sample_triangle", 2),
    ("sample_unit_ring", 1),
    ("sample_unit_disk", 2),
    ("sample_unit_square", 2),
    ("sample_unit_cube", 3),
    ("sample_unit_sphere_surface", 2),
    ("sample_unit_sphere", 3),
    ("sample_unit_hemisphere_surface", 2),
    ("sample_unit_hemisphere", 3),
];

use glam::{Vec2, Vec3};

/// `2^-24`: the spacing of uniform draws.
pub(crate) const UNIT: f32 = 1.0 / 16_777_216.0;
/// Added to the radius draw of `randn` so that its logarithm is finite (Warp's
/// `RANDN_EPSILON`, about `2^-24`).
pub(crate) const RANDN_EPSILON: f32 = 5.96e-8;
/// `2π` rounded to f32 (`2 * PI`, which is exact in binary).
const TWO_PI: f32 = 2.0 * core::f32::consts::PI;

/// The PCG hash: one step of the generator.
#[inline(always)]
pub fn rand_pcg(state: u32) -> u32 {
    let b = state.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let c = ((b >> ((b >> 28) + 4)) ^ b).wrapping_mul(277_803_737);
    (c >> 22) ^ c
}

/// `rand_init(seed)`: the state for a seed (the seed's bits, hashed).
#[inline(always)]
pub fn rand_init(seed: i32) -> u32 {
    rand_pcg(seed as u32)
}

/// `rand_init(seed, offset)`: independent streams from one seed, one per offset (typically
/// the thread index): `rand_pcg(seed + rand_pcg(offset))`, wrapping.
#[inline(always)]
pub fn rand_init_offset(seed: i32, offset: i32) -> u32 {
    rand_pcg((seed as u32).wrapping_add(rand_pcg(offset as u32)))
}

/// The uniform float of an (already advanced) state: its top 24 bits times `2^-24`.
#[inline(always)]
fn unit(state: u32) -> f32 {
    (state >> 8) as f32 * UNIT
}

/// Successive uniform draws from a state, as the builtins consume them.
struct Draws(u32);

impl Draws {
    #[inline(always)]
    fn f(&mut self) -> f32 {
        self.0 = rand_pcg(self.0);
        unit(self.0)
    }
    /// `(hi - lo) * u + lo`.
    #[inline(always)]
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        (hi - lo) * self.f() + lo
    }
}

/// `randf(&mut state)`: uniform in `[0, 1)` (multiples of `2^-24`), from the state before the
/// draw.
#[inline(always)]
pub fn randf(state: u32) -> f32 {
    Draws(state).f()
}

/// `randf(&mut state, lo, hi)`: `(hi - lo) * u + lo`, from the state before the draw.
#[inline(always)]
pub fn randf_range(state: u32, lo: f32, hi: f32) -> f32 {
    Draws(state).range(lo, hi)
}

/// `randn(&mut state)`: standard normal by Box-Muller (two draws), from the state before them.
#[inline(always)]
pub fn randn(state: u32) -> f32 {
    let mut d = Draws(state);
    let r = d.f();
    let t = d.f();
    (-2.0 * (r + RANDN_EPSILON).ln()).sqrt() * (TWO_PI * t).cos()
}

/// `sample_triangle(&mut state)`: barycentric coordinates `(u, v)` uniform over a triangle
/// (`u, v >= 0`, `u + v <= 1`).
#[inline(always)]
pub fn sample_triangle(state: u32) -> Vec2 {
    let mut d = Draws(state);
    let r = d.f().sqrt();
    let u = 1.0 - r;
    let v = d.f() * r;
    Vec2::new(u, v)
}

/// `sample_unit_ring(&mut state)`: uniform on the unit circle.
#[inline(always)]
pub fn sample_unit_ring(state: u32) -> Vec2 {
    let theta = Draws(state).range(0.0, TWO_PI);
    Vec2::new(theta.cos(), theta.sin())
}

/// `sample_unit_disk(&mut state)`: uniform over the unit disk.
#[inline(always)]
pub fn sample_unit_disk(state: u32) -> Vec2 {
    let mut d = Draws(state);
    let r = d.f().sqrt();
    let theta = d.range(0.0, TWO_PI);
    Vec2::new(r * theta.cos(), r * theta.sin())
}

/// `sample_unit_square(&mut state)`: uniform over `[-0.5, 0.5)²`.
#[inline(always)]
pub fn sample_unit_square(state: u32) -> Vec2 {
    let mut d = Draws(state);
    let x = d.f() - 0.5;
    let y = d.f() - 0.5;
    Vec2::new(x, y)
}

/// `sample_unit_cube(&mut state)`: uniform over `[-0.5, 0.5)³`.
#[inline(always)]
pub fn sample_unit_cube(state: u32) -> Vec3 {
    let mut d = Draws(state);
    let x = d.f() - 0.5;
    let y = d.f() - 0.5;
    let z = d.f() - 0.5;
    Vec3::new(x, y, z)
}

/// The point at polar angle `phi` and azimuth `theta`, times `r`, as Warp writes it:
/// `(r cos θ sin φ, r sin θ sin φ, r cos φ)`, products left to right.
#[inline(always)]
fn spherical(r: Option<f32>, phi: f32, theta: f32) -> Vec3 {
    let (ct, st, sp, cp) = (theta.cos(), theta.sin(), phi.sin(), phi.cos());
    match r {
        None => Vec3::new(ct * sp, st * sp, cp),
        Some(r) => Vec3::new(r * ct * sp, r * st * sp, r * cp),
    }
}

/// `sample_unit_sphere_surface(&mut state)`: uniform on the unit sphere.
#[inline(always)]
pub fn sample_unit_sphere_surface(state: u32) -> Vec3 {
    let mut d = Draws(state);
    let phi = (1.0 - 2.0 * d.f()).acos();
    let theta = d.range(0.0, TWO_PI);
    spherical(None, phi, theta)
}

/// `sample_unit_sphere(&mut state)`: uniform over the unit ball.
#[inline(always)]
pub fn sample_unit_sphere(state: u32) -> Vec3 {
    let mut d = Draws(state);
    let phi = (1.0 - 2.0 * d.f()).acos();
    let theta = d.range(0.0, TWO_PI);
    let r = d.f().powf(1.0 / 3.0);
    spherical(Some(r), phi, theta)
}

/// `sample_unit_hemisphere_surface(&mut state)`: uniform on the unit hemisphere `z >= 0`.
#[inline(always)]
pub fn sample_unit_hemisphere_surface(state: u32) -> Vec3 {
    let mut d = Draws(state);
    let phi = (1.0 - d.f()).acos();
    let theta = d.range(0.0, TWO_PI);
    spherical(None, phi, theta)
}

/// `sample_unit_hemisphere(&mut state)`: uniform over the unit half-ball `z >= 0`.
#[inline(always)]
pub fn sample_unit_hemisphere(state: u32) -> Vec3 {
    let mut d = Draws(state);
    let phi = (1.0 - d.f()).acos();
    let theta = d.range(0.0, TWO_PI);
    let r = d.f().powf(1.0 / 3.0);
    spherical(Some(r), phi, theta)
}

// ------------------------------------------------------------------------------------------
// Poisson
// ------------------------------------------------------------------------------------------

/// The most draws one `poisson` call makes. Warp's loops are unbounded; both of its methods
/// end after a handful of draws almost surely (the multiplication method after about
/// `lam + 1`, the rejection method after about 1.2 rounds of two), but the hash's orbit is not
/// random, so a bound keeps every thread finite. Reaching it returns the last candidate.
pub const POISSON_MAX_DRAWS: u32 = 1024;

/// `ln Γ(x)` for `x >= 1`, f32: Stirling's series with the coefficients of Zhang and Jin
/// ("Computation of Special Functions", 1996), shifted up to `x >= 7` (Warp's
/// `random_loggam`).
#[allow(clippy::excessive_precision)] // the published decimals, rounded once to f32
fn loggam(x: f32) -> f32 {
    const A: [f32; 10] = [
        8.333333333333333e-02,
        -2.777777777777778e-03,
        7.936507936507937e-04,
        -5.952380952380952e-04,
        8.417508417508418e-04,
        -1.917526917526918e-03,
        6.410256410256410e-03,
        -2.955065359477124e-02,
        1.796443723688307e-01,
        -1.39243221690590e+00,
    ];
    if x == 1.0 || x == 2.0 {
        return 0.0;
    }
    let n: u32 = if x < 7.0 { (7.0 - x) as u32 } else { 0 };
    let mut x0 = x + n as f32;
    let x2 = (1.0 / x0) * (1.0 / x0);
    let lg2pi: f32 = 1.8378770664093453; // ln(2π)
    let mut gl0 = A[9];
    for k in (0..9).rev() {
        gl0 *= x2;
        gl0 += A[k];
    }
    let mut gl = gl0 / x0 + 0.5 * lg2pi + (x0 - 0.5) * x0.ln() - x0;
    if x < 7.0 {
        for _ in 0..n {
            gl -= (x0 - 1.0).ln();
            x0 -= 1.0;
        }
    }
    gl
}

/// One Poisson draw: `(value, state after)`.
fn poisson_draw(state: u32, lam: f32) -> (u32, u32) {
    let mut d = Draws(state);
    if lam >= 10.0 {
        // Hörmann's transformed rejection (PTRS), "The transformed rejection method for
        // generating Poisson random variables", Insurance: Mathematics and Economics 12, 1993.
        let slam = lam.sqrt();
        let loglam = lam.ln();
        let b = 0.931 + 2.53 * slam;
        let a = -0.059 + 0.02483 * b;
        let invalpha = 1.1239 + 1.1328 / (b - 3.4);
        let vr = 0.9277 - 3.6224 / (b - 2.0);
        let mut k = 0u32;
        let mut draws = 0;
        while draws < POISSON_MAX_DRAWS {
            draws += 2;
            let u = d.f() - 0.5;
            let v = d.f();
            let us = 0.5 - u.abs();
            let kf = ((2.0 * a / us + b) * u + lam + 0.43).floor();
            k = kf as u32;
            if us >= 0.07 && v <= vr {
                return (k, d.0);
            }
            // A negative candidate is rejected (NumPy's rule, which Warp's unsigned `k`
            // lost: its conversion of a negative float is undefined behaviour).
            if kf < 0.0 || (us < 0.013 && v > us) {
                continue;
            }
            let lhs = v.ln() + invalpha.ln() - (a / (us * us) + b).ln();
            let rhs = -lam + k as f32 * loglam - loggam(k as f32 + 1.0);
            if lhs <= rhs {
                return (k, d.0);
            }
        }
        (k, d.0)
    } else if lam == 0.0 {
        (0, state)
    } else {
        // Multiplication method: count uniforms until their product falls to exp(-lam).
        let enlam = (-lam).exp();
        let mut x = 0u32;
        let mut prod = 1.0f32;
        for _ in 0..POISSON_MAX_DRAWS {
            prod *= d.f();
            if prod > enlam {
                x += 1;
            } else {
                break;
            }
        }
        (x, d.0)
    }
}

/// `poisson(&mut state, lam)`: a Poisson-distributed count with mean `lam` (Warp's methods:
/// multiplication below 10, transformed rejection from 10; `lam == 0` gives 0 without a draw,
/// negative or NaN `lam` gives 0 after one draw), from the state before the draw. The number
/// of draws varies: [`poisson_state`] is the state after.
pub fn poisson(state: u32, lam: f32) -> u32 {
    poisson_draw(state, lam).0
}

/// The state after `poisson(&mut state, lam)`, from the state before (what the macro writes
/// back).
pub fn poisson_state(state: u32, lam: f32) -> u32 {
    poisson_draw(state, lam).1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pcg_matches_warps_reference_values() {
        // rand_pcg computed by hand from the hash's definition for small inputs.
        let h = |s: u32| {
            let b = (s as u64 * 747_796_405 + 2_891_336_453) as u32;
            let c = (((b >> ((b >> 28) + 4)) ^ b) as u64 * 277_803_737) as u32;
            (c >> 22) ^ c
        };
        for s in [0u32, 1, 2, 42, 0xdead_beef, u32::MAX] {
            assert_eq!(rand_pcg(s), h(s));
        }
        assert_eq!(rand_init(-1), rand_pcg(u32::MAX));
        assert_eq!(
            rand_init_offset(7, 3),
            rand_pcg(7u32.wrapping_add(rand_pcg(3)))
        );
    }

    #[test]
    fn draws_consume_the_documented_number_of_steps() {
        // Each sampler's result depends on exactly its first DRAWS states: changing the
        // state that follows them does not matter, and the last one does.
        let s = rand_init_offset(11, 5);
        let mut after = s;
        for _ in 0..2 {
            after = rand_pcg(after);
        }
        assert_eq!(randn(s), {
            let r = unit(rand_pcg(s));
            let t = unit(after);
            (-2.0 * (r + RANDN_EPSILON).ln()).sqrt() * (TWO_PI * t).cos()
        });
        let u = unit(rand_pcg(s));
        assert_eq!(randf(s), u);
        assert_eq!(randf_range(s, -2.0, 6.0), 8.0 * u - 2.0);
        assert_eq!(
            DRAWS.iter().find(|d| d.0 == "sample_unit_cube").unwrap().1,
            3
        );
    }

    #[test]
    fn uniform_draws_are_in_range_and_on_the_grid() {
        let mut s = rand_init(3);
        for _ in 0..10_000 {
            let u = randf(s);
            s = rand_pcg(s);
            assert!((0.0..1.0).contains(&u));
            assert_eq!((u * 16_777_216.0).fract(), 0.0);
        }
        assert_eq!(unit(u32::MAX), 1.0 - UNIT);
        assert_eq!(unit(255), 0.0);
    }

    #[test]
    fn poisson_is_finite_for_every_lambda() {
        let s = rand_init(9);
        assert_eq!(poisson(s, 0.0), 0);
        assert_eq!(poisson_state(s, 0.0), s);
        assert_eq!(poisson(s, -1.0), 0);
        assert_eq!(poisson(s, f32::NAN), 0);
        assert_eq!(poisson_state(s, f32::NAN), rand_pcg(s));
        // Huge or infinite means end (at the draw bound at worst) with a saturated count.
        let _ = poisson(s, f32::INFINITY);
        let _ = poisson(s, 1e30);
        // Means near the switch between methods.
        let mean = |lam: f32| {
            let mut st = rand_init(1);
            let n = 20_000;
            let mut sum = 0u64;
            for _ in 0..n {
                sum += poisson(st, lam) as u64;
                st = poisson_state(st, lam);
            }
            sum as f64 / n as f64
        };
        for lam in [0.5f32, 3.0, 9.5, 10.0, 40.0] {
            // Standard error sqrt(lam / n); 5 of them.
            let tol = 5.0 * (lam as f64 / 20_000.0).sqrt();
            assert!(
                (mean(lam) - lam as f64).abs() < tol,
                "lam {lam}: {}",
                mean(lam)
            );
        }
        // ln Γ at integers: ln((k-1)!).
        for k in 1..12u32 {
            let want: f64 = (1..k).map(|j| (j as f64).ln()).sum();
            assert!((loggam(k as f32) as f64 - want).abs() < 1e-5 * want.max(1.0));
        }
    }
}

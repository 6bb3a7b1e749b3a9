//! Numerical stability on stiff and extreme cases: NaN/Inf detection (`verify_fp` and the
//! divergence guard), the stability limit of symplectic Euler, IEEE edge cases the language
//! documents, compensated summation, the stiff mass-spring chain of the `springs` scene
//! (its very kernels, included from examples/common/springs.rs), and the convergence of the
//! `finite_difference` example's kernels (examples/common/finite_difference.rs).

use crate::{arr, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::Error;

backend_tests!(
    verify_fp_names_kernel_argument_and_index,
    verify_fp_sees_tile_stores,
    symplectic_euler_stability_limit,
    ieee_edge_cases,
    compensated_summation,
    stiff_chain_xpbd_bounded_euler_detected,
    colored_xpbd_chain,
    finite_differences_converge,
);

#[path = "../../examples/common/springs.rs"]
mod springs;
// The sparse tier, for common/springs.rs (its coloured XPBD series).
use warp_runtime::sparse;

#[path = "../../examples/common/finite_difference.rs"]
mod finite_difference;

#[wp::kernel]
fn k_recip(x: Array<f32>, y: Array<f32, 2>) {
    let i = tid();
    y[(i / 2, i % 2)] = 1.0 / x[i];
}

/// With `verify_fp` a launch that writes 1/0 is an error naming kernel, argument and index;
/// without it the infinity is written and the divergence guard finds it.
fn verify_fp_names_kernel_argument_and_index(dev: &wp::Device) {
    let x = arr(&[1.0f32, 2.0, 0.0, 4.0], dev);
    let y = zeros::<f32, 2>((2, 2), dev);
    wp::config::set_verify_fp_for_thread(Some(true));
    let r = wp::launch(k_recip, 4, (&x, &y), dev);
    wp::config::set_verify_fp_for_thread(None);
    match r {
        Err(e @ Error::NonFinite { .. }) => assert_eq!(
            e.to_string(),
            "kernel `k_recip` wrote a non-finite value to `y` at index [1, 0]: inf"
        ),
        other => panic!("expected NonFinite, got {other:?}"),
    }
    wp::launch(k_recip, 4, (&x, &y), dev).unwrap();
    let e = y.check_finite("reciprocals").unwrap_err();
    assert_eq!(
        e.to_string(),
        "reciprocals diverged: non-finite value at index [1, 0]: inf"
    );
    let ok = arr(&[1.0f32, 2.0], dev);
    ok.check_finite("fine").unwrap();
}

#[wp::kernel]
fn k_tile_recip(x: Array<f32>, y: Array<f32>) {
    let t = tile_load::<4>(x, 0);
    tile_store(y, tile_map(div, tile_ones::<f32, 4>(), t), 0);
}

/// `verify_fp` checks the arrays a tiled kernel writes through `tile_store` too.
fn verify_fp_sees_tile_stores(dev: &wp::Device) {
    let x = arr(&[1.0f32, 0.0, 2.0, 4.0], dev);
    let y = zeros::<f32, 1>(4, dev);
    wp::config::set_verify_fp_for_thread(Some(true));
    let r = wp::launch_tiled(k_tile_recip, 1, (&x, &y), 4, dev);
    wp::config::set_verify_fp_for_thread(None);
    match r {
        Err(e @ Error::NonFinite { .. }) => assert_eq!(
            e.to_string(),
            "kernel `k_tile_recip` wrote a non-finite value to `y` at index [1]: inf"
        ),
        other => panic!("expected NonFinite, got {other:?}"),
    }
}

/// `steps` steps of symplectic Euler for x'' = -omega^2 x, one oscillator per thread.
#[wp::kernel]
fn k_spring(x: Array<f32>, v: Array<f32>, omega: f32, dt: f32, steps: i32, peak: Array<f32>) {
    let i = tid();
    let mut xi = x[i];
    let mut vi = v[i];
    let mut p = peak[i];
    for _s in 0..steps {
        vi += -omega * omega * xi * dt;
        xi += vi * dt;
        p = max(p, abs(xi));
    }
    x[i] = xi;
    v[i] = vi;
    peak[i] = p;
}

/// Symplectic Euler is stable for omega * dt < 2: at 1.99 the amplitude stays bounded (by
/// 1 / sqrt(1 - (omega dt / 2)^2) ~ 10 of the initial one), at 2.01 it grows by ~1.22 per step,
/// overflows f32 within a few hundred steps, and the divergence guard reports it.
fn symplectic_euler_stability_limit(dev: &wp::Device) {
    let omega = 10.0f32;
    for (h, stable) in [(1.99f32, true), (2.01, false)] {
        let x = arr(&[1.0f32], dev);
        let v = arr(&[0.0f32], dev);
        let peak = arr(&[0.0f32], dev);
        let mut diverged_at = None;
        for chunk in 0..100 {
            wp::launch(k_spring, 1, (&x, &v, omega, h / omega, 100, &peak), dev).unwrap();
            if x.check_finite("spring").is_err() {
                diverged_at = Some((chunk + 1) * 100);
                break;
            }
        }
        if stable {
            assert_eq!(diverged_at, None);
            let p = peak.to_vec().unwrap()[0];
            assert!(p < 11.0, "peak {p}");
        } else {
            let at = diverged_at.expect("omega dt = 2.01 must blow up");
            // |lambda| = 1.2214 per step: f32 overflows (3.4e38) after about 430 steps.
            assert!(at <= 600, "diverged only after {at} steps");
        }
    }
}

#[wp::kernel]
fn k_edges(out: Array<f32>) {
    out[0] = normalize(vec3(0.0, 0.0, 0.0)).x;
    out[1] = length(vec3(1.0e-30, 0.0, 0.0));
    out[2] = length(vec3(1.0e30, 0.0, 0.0));
    let z = out[9];
    out[3] = 1.0 / z;
    out[4] = z / z;
    out[5] = 3.0e38 * 10.0;
    let d = 1.0e-40;
    out[6] = d * 0.5;
    out[7] = sqrt(-1.0);
    out[8] = max(z / z, 2.0);
}

/// The language's documented IEEE behaviour (ARCHITECTURE.md, "The kernel language"), the
/// same on both backends: normalize(0) = 0; length scales by a power of two first, so it
/// neither underflows for (1e-30, 0, 0) nor overflows for (1e30, 0, 0) in f32 (the squares
/// would: tests/suite/extreme.rs covers every scale); float
/// division by zero gives inf and 0/0 NaN; overflow gives inf; denormals are kept (no
/// flush-to-zero); max with a NaN returns the other operand.
fn ieee_edge_cases(dev: &wp::Device) {
    let out = zeros::<f32, 1>(10, dev);
    wp::launch(k_edges, 1, (&out,), dev).unwrap();
    let o = out.to_vec().unwrap();
    assert_eq!(o[0], 0.0);
    assert_eq!(o[1], 1.0e-30);
    assert_eq!(o[2], 1.0e30);
    assert_eq!(o[3], f32::INFINITY);
    assert!(o[4].is_nan());
    assert_eq!(o[5], f32::INFINITY);
    assert_eq!(o[6], 1.0e-40f32 * 0.5);
    assert!(o[6] > 0.0 && !o[6].is_normal());
    assert!(o[7].is_nan());
    assert_eq!(o[8], 2.0);
}

#[wp::kernel]
fn k_sums(n: i32, x: f32, out: Array<f32>) {
    let mut naive = 0.0;
    let mut sum = 0.0;
    let mut c = 0.0;
    for _k in 0..n {
        naive += x;
        let y = x - c;
        let t = sum + y;
        c = (t - sum) - y;
        sum = t;
    }
    out[0] = naive;
    out[1] = sum;
}

/// Adding 1e-3 a million times in f32: the plain sum drifts by about 1e-2 relative (reported),
/// the compensated (Kahan) sum stays within 1e-6 of the exact 1000.
fn compensated_summation(dev: &wp::Device) {
    let out = zeros::<f32, 1>(2, dev);
    wp::launch(k_sums, 1, (1_000_000, 1.0e-3f32, &out), dev).unwrap();
    let o = out.to_vec().unwrap();
    // The exact sum of a million copies of the f32 nearest 1e-3.
    let exact = 1.0e6 * (1.0e-3f32 as f64);
    let (naive, kahan) = (
        ((o[0] as f64 - exact) / exact).abs(),
        ((o[1] as f64 - exact) / exact).abs(),
    );
    eprintln!(
        "f32 sum of 1e-3 x 1e6 on {dev}: plain rel. error {naive:.2e}, compensated {kahan:.2e}"
    );
    assert!(
        naive > 1e-4,
        "the plain f32 sum is expected to drift: {naive:e}"
    );
    assert!(kahan <= 1e-6, "{kahan:e}");
}

/// The springs scene's chain at k = 1e7 N/m with 60 Hz steps for 2 s: XPBD (10 substeps of
/// one sweep) stays bounded, while semi-implicit Euler (stable only below dt = 2 / omega_max
/// = 7.1e-5 s, 235 times smaller) blows up and the divergence guard reports it.
fn stiff_chain_xpbd_bounded_euler_detected(dev: &wp::Device) {
    let (k, dt) = (1e7f32, 1.0 / 60.0);
    let length = (springs::SEGMENTS as f64 * springs::REST) as f32;
    let xpbd = springs::Solver::Xpbd {
        substeps: 10,
        iterations: 1,
    };
    let mut chains = springs::Chains::new(2, dev).unwrap();
    let mut farthest = 0.0f32;
    for _ in 0..120 {
        chains.step(xpbd, k, dt, dev).unwrap();
        chains.x.check_finite("x").unwrap();
        let x = chains.x.to_vec().unwrap();
        farthest = x.iter().map(|p| p.length()).fold(farthest, f32::max);
    }
    // Bounded: no particle gets farther from the pin than the chain's length plus the
    // stretch its unconverged sweeps leave (2.4% on the CPU when written; the bound allows
    // 50%, a blow-up goes far past it).
    println!(
        "XPBD k = 1e7, 60 Hz, 2 s: farthest particle {farthest} m from the pin (chain {length} m)"
    );
    assert!(farthest < 1.5 * length, "farthest particle at {farthest} m");
    assert!(
        farthest > 0.99 * length,
        "the chain did fall and swing out: {farthest}"
    );

    let mut chains = springs::Chains::new(2, dev).unwrap();
    let mut blew_up = None;
    for step in 1..=120 {
        chains.step(springs::Solver::Euler, k, dt, dev).unwrap();
        if let Err(e) = chains.x.check_finite("x") {
            blew_up = Some((step, e));
            break;
        }
    }
    let (step, e) = blew_up.expect("semi-implicit Euler at 235x its stable step must blow up");
    assert!(matches!(e, Error::Diverged { .. }), "{e}");
    assert!(e.to_string().contains("x diverged"), "{e}");
    assert!(step < 60, "blew up only at step {step}");
}

/// The springs scene's coloured XPBD series (`Solver::XpbdColored`: the springs coloured on
/// the device by `Adjacency::of_constraints` and `Coloring`, a thread per spring of a colour):
/// - the colouring of 3 chains splits each chain's 20 springs into 2 or 3 colours (a path under
///   Jones-Plassmann), and no two springs of a colour share a particle;
/// - against the RK4 reference (as the scene measures it) at k = 1e3 N/m, dt = 1/240 s and at
///   k = 1e5, dt = 1/60 s for 0.5 s, its error is within 25% of the chain sweep's (`Xpbd`):
///   the two differ only in the order of the constraint projections (Gauss-Seidel across
///   colours, Jacobi within one, against one sweep down the chain), which changes the
///   unresolved stretch, not the time discretisation that dominates both errors (5.8e-3 and
///   9.9e-2 m for both on the CPU when written, within 1%); at k = 1e3 both are below 1 cm;
/// - at k = 1e7 N/m with 60 Hz steps for 2 s it stays bounded as `Xpbd` does (the chain's
///   length plus at most 50% stretch), and swings out to its length.
fn colored_xpbd_chain(dev: &wp::Device) {
    let n_chains = 3;
    let mut chains = springs::Chains::new(n_chains, dev).unwrap();
    let (order, ranges) = chains.colouring(dev).unwrap().clone();
    let order = order.to_vec().unwrap();
    assert!((2..=3).contains(&ranges.len()), "{} colours", ranges.len());
    assert_eq!(order.len(), n_chains * springs::SEGMENTS);
    let c = springs::constraints(n_chains);
    for r in &ranges {
        let mut seen = std::collections::BTreeSet::new();
        for &s in &order[r.clone()] {
            let e = c[s as usize];
            assert!(
                seen.insert(e.x) && seen.insert(e.y),
                "spring {s} shares a particle"
            );
        }
    }
    let (sweep, colored) = (
        springs::Solver::Xpbd {
            substeps: 10,
            iterations: 1,
        },
        springs::Solver::XpbdColored {
            substeps: 10,
            iterations: 1,
        },
    );
    let run = |solver, k: f64, dt: f64, t_end: f64| {
        let mut ch = springs::Chains::new(2, dev).unwrap();
        for _ in 0..(t_end / dt).round() as usize {
            ch.step(solver, k as f32, dt as f32, dev).unwrap();
        }
        ch.x.check_finite("x").unwrap();
        ch
    };
    for (k, dt, bound) in [
        (1e3f64, 1.0 / 240.0, 1e-2),
        (1e5, 1.0 / 60.0, f64::INFINITY),
    ] {
        let reference = springs::reference(k, 0.5, (0.05 / springs::omega_max(k)).min(1e-4));
        let error = |solver| {
            let (x, _) = run(solver, k, dt, 0.5).first().unwrap();
            x.iter()
                .zip(&reference)
                .map(|(a, b)| a.distance(*b))
                .fold(0.0f64, f64::max)
        };
        let (e_sweep, e_colored) = (error(sweep), error(colored));
        println!("k = {k:e}, dt = {dt:.4}: XPBD error {e_sweep:.3e} m, colored {e_colored:.3e} m");
        assert!(
            (e_colored - e_sweep).abs() <= 0.25 * e_sweep,
            "k = {k:e}: colored {e_colored:e} against {e_sweep:e}"
        );
        assert!(
            e_colored < bound && e_sweep < bound,
            "{e_colored:e} {e_sweep:e}"
        );
    }
    let length = (springs::SEGMENTS as f64 * springs::REST) as f32;
    let mut ch = springs::Chains::new(2, dev).unwrap();
    let mut farthest = 0.0f32;
    for _ in 0..120 {
        ch.step(colored, 1e7, 1.0 / 60.0, dev).unwrap();
        ch.x.check_finite("x").unwrap();
        let x = ch.x.to_vec().unwrap();
        farthest = x.iter().map(|p| p.length()).fold(farthest, f32::max);
    }
    println!("XPBD colored k = 1e7, 60 Hz, 2 s: farthest particle {farthest} m (chain {length} m)");
    assert!(farthest < 1.5 * length, "farthest particle at {farthest} m");
    assert!(
        farthest > 0.99 * length,
        "the chain did fall and swing out: {farthest}"
    );
}

/// The `finite_difference` example's kernels, forward and adjoint, in f32 and f64:
/// - each result equals the host's formula bit for bit, on both backends: a subtraction
///   and a product by 1/h or 1/(2h), powers of two (exact), leave no room for an FMA or
///   another rounding;
/// - the largest error against u' = 2 pi cos(2 pi x) is within the truncation bound plus
///   the rounding bound (module docs of the example's file) taken twice, since the samples
///   are within one ulp, not half (libm's sin is not correctly rounded), plus 16 eps for
///   the rounding of the subtraction (eps/2 of a result of at most 2 pi);
/// - in f64, where rounding is 1e-12 of the error at these sizes, the observed order from
///   n = 1024 to 4096 is 1 or 2 within 0.02 (the next Taylor term moves the error ratio by
///   about 2 pi h, under 1%, which moves the order by under 0.005).
fn finite_differences_converge(dev: &wp::Device) {
    use finite_difference::{Order, Real};

    fn check<T: Real + PartialEq + std::fmt::Debug>(order: Order, dev: &wp::Device) -> Vec<f64> {
        let mut errors = Vec::new();
        for n in [64usize, 1024, 4096] {
            let u_host = finite_difference::samples::<T>(n);
            let u = wp::Array::from_slice(&u_host, dev).unwrap();
            let du = wp::Array::<T>::zeros(n, dev).unwrap();
            T::launch(order, &u, &du, dev).unwrap();
            let du = du.to_vec().unwrap();
            let want = order.host(&u_host);
            if let Some(i) = (0..n).find(|&i| du[i] != want[i]) {
                panic!(
                    "{} {}, n = {n}: du[{i}] = {:?}, the host's formula {:?}",
                    order.name(),
                    T::NAME,
                    du[i],
                    want[i]
                );
            }
            let err = finite_difference::max_error(&du);
            let bound =
                order.truncation_bound(n) + 2.0 * order.rounding_bound(n, T::EPS) + 16.0 * T::EPS;
            assert!(
                err <= bound,
                "{} {}, n = {n}: error {err:e} above the bound {bound:e}",
                order.name(),
                T::NAME
            );
            errors.push(err);
        }
        errors
    }

    for order in Order::ALL {
        check::<f32>(order, dev);
        let e = check::<f64>(order, dev);
        let p = (e[1] / e[2]).ln() / 4f64.ln();
        println!(
            "{} on {dev}: f64 errors {:.3e}, {:.3e}, {:.3e} at n = 64, 1024, 4096; order {p:.4}",
            order.name(),
            e[0],
            e[1],
            e[2]
        );
        assert!(
            (p - order.p() as f64).abs() < 0.02,
            "{}: observed order {p}",
            order.name()
        );
        // The adjoint: dL/du = D^T w against -w', the same bound.
        let n = 4096;
        let (err, _) = finite_difference::adjoint_error(order, n, dev).unwrap();
        let bound =
            order.truncation_bound(n) + 2.0 * order.rounding_bound(n, f64::EPS) + 16.0 * f64::EPS;
        assert!(
            err <= bound,
            "{} adjoint, n = {n}: error {err:e} above the bound {bound:e}",
            order.name()
        );
    }
}

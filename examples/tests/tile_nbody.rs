//! The tile_nbody example's kernels (`examples/common/tile_nbody.rs`), checked directly: the
//! tiled kernel against the scalar one and against float64 at block sizes that do and do not
//! divide the body count, the leapfrog's second order, the range probes (coincident bodies,
//! tiny and huge masses), and the errors of bad arguments. On the CPU always; on `cuda:0` too
//! when there is one (else SKIPPED).
//!
//! Tolerances: accelerations within `(n + 16) u` of the terms' summed lengths (u = 2^-24), the
//! bound of an f32 sum of n terms (`tile_nbody::error_bound` says why); on the CPU the two kernels
//! sum in the same order with the same operations, so they must agree bit for bit.

#[path = "../common/tile_nbody.rs"]
mod tile_nbody;

use glam::DVec3;
use tile_nbody::{Kernel, Sim, SOFTENING};
use warp_lang as wp;

fn cpu() -> wp::Device {
    wp::init();
    wp::get_device("cpu").expect("the CPU device")
}

/// `cuda:0`, or None (saying SKIPPED) without one.
fn gpu(test: &str) -> Option<wp::Device> {
    wp::init();
    match wp::get_device("cuda:0") {
        Ok(d) => Some(d),
        Err(e) => {
            eprintln!("SKIPPED tile_nbody::{test}: no CUDA device ({e})");
            None
        }
    }
}

/// The first step's accelerations (at the start state) of `kernel`.
fn first_accelerations(
    kernel: Kernel,
    x: &[DVec3],
    v: &[DVec3],
    m: &[f64],
    dev: &wp::Device,
) -> Vec<DVec3> {
    let mut sim = Sim::new(kernel, x, v, m, SOFTENING, 0.005, dev).expect("Sim::new");
    sim.step().expect("step");
    sim.check_finite().expect("finite");
    sim.accelerations().expect("accelerations")
}

/// 130 bodies (two full 64-body tiles and a ragged one), blocks of 1, 37, 64 and 128 threads
/// (bodies past the end in the last block): every acceleration within the f32 sum's bound of
/// float64. On the CPU the tiled and scalar kernels give the same bits; on a GPU each is within
/// the bound (the compiler may contract the two loops' arithmetic differently).
fn tiled_agrees(dev: &wp::Device, same_bits: bool) {
    let n = 130;
    let (x, v, m) = tile_nbody::start(n, 11);
    let all: Vec<usize> = (0..n).collect();
    let bound = tile_nbody::error_bound(n);
    let scalar = first_accelerations(Kernel::Scalar, &x, &v, &m, dev);
    let e = tile_nbody::acceleration_error(&scalar, &x, &m, SOFTENING, &all);
    assert!(e <= bound, "scalar on {dev}: error {e:e} > {bound:e}");
    for block_dim in [1, 37, 64, 128] {
        let tiled = first_accelerations(Kernel::Tiled { block_dim }, &x, &v, &m, dev);
        let e = tile_nbody::acceleration_error(&tiled, &x, &m, SOFTENING, &all);
        assert!(
            e <= bound,
            "tiled, block {block_dim} on {dev}: error {e:e} > {bound:e}"
        );
        if same_bits {
            assert_eq!(tiled, scalar, "tiled, block {block_dim} on {dev}");
        }
    }
}

#[test]
fn tiled_matches_scalar_and_float64_on_the_cpu() {
    tiled_agrees(&cpu(), true);
}

#[test]
fn tiled_matches_scalar_and_float64_on_a_gpu() {
    if let Some(dev) = gpu("tiled_matches_scalar_and_float64_on_a_gpu") {
        tiled_agrees(&dev, false);
    }
}

/// Relative energy drift of `kernel` over t = 1 at step `dt`.
fn drift(kernel: Kernel, dt: f64, dev: &wp::Device) -> f64 {
    let (x0, v0, m) = tile_nbody::start(128, 3);
    let e0 = tile_nbody::energy(&x0, &v0, &m, SOFTENING);
    let vh = tile_nbody::half_kick(&x0, &v0, &m, SOFTENING, -0.5 * dt);
    let mut sim = Sim::new(kernel, &x0, &vh, &m, SOFTENING, dt, dev).expect("Sim::new");
    for _ in 0..(1.0 / dt).round() as usize {
        sim.step().expect("step");
    }
    sim.check_finite().expect("finite");
    let (x, m) = sim.bodies().expect("bodies");
    let v = tile_nbody::half_kick(&x, &sim.velocities().expect("v"), &m, SOFTENING, 0.5 * dt);
    ((tile_nbody::energy(&x, &v, &m, SOFTENING) - e0) / e0).abs()
}

/// The staggered leapfrog is second order: halving dt divides the energy drift by about 4 (a
/// first-order integrator, or a kick with the wrong acceleration, by about 2 or not at all).
/// Measured on the CPU: 9.9e-5 at dt = 0.02, 2.2e-5 at 0.01 (ratio 4.5), far above the f32
/// rounding floor (about 1e-6); the test allows ratios 3 to 8.
#[test]
fn leapfrog_is_second_order() {
    let dev = cpu();
    for kernel in [Kernel::Tiled { block_dim: 64 }, Kernel::Scalar] {
        let (coarse, fine) = (drift(kernel, 0.02, &dev), drift(kernel, 0.01, &dev));
        let ratio = coarse / fine;
        assert!(
            (3.0..8.0).contains(&ratio),
            "{kernel:?}: drift {coarse:e} at dt 0.02, {fine:e} at 0.01 (ratio {ratio})"
        );
    }
}

/// The range probes (`tile_nbody::cases`): two coincident bodies and masses from 1e-40 to 1e30
/// give finite accelerations within the bound, and the coincident pair's pull on each other is
/// exactly zero (the two get the same acceleration, the third body's pull); masses past
/// `f32::MAX eps^3` are reported as a divergence naming the kernel's accelerations.
fn probes(dev: &wp::Device) {
    for case in tile_nbody::cases() {
        for kernel in [
            Kernel::Tiled { block_dim: 1 },
            Kernel::Tiled { block_dim: 64 },
            Kernel::Scalar,
        ] {
            let got = tile_nbody::stability(&case, kernel, dev);
            let what = format!("{} with {kernel:?} on {dev}", case.name);
            if case.finite {
                let e = got.unwrap_or_else(|e| panic!("{what}: {e}"));
                let bound = tile_nbody::error_bound(case.x.len());
                assert!(e <= bound, "{what}: error {e:e} > {bound:e}");
            } else {
                match got {
                    Err(wp::Error::Diverged { what: w, .. }) => assert_eq!(
                        w,
                        format!("{} n-body accelerations", kernel.name()),
                        "{what}"
                    ),
                    other => panic!("{what}: expected a divergence report, got {other:?}"),
                }
            }
        }
    }
    // The coincident pair: the same acceleration, bit for bit, and it is the third body's pull.
    let case = &tile_nbody::cases()[0];
    let v = vec![DVec3::ZERO; 3];
    for kernel in [Kernel::Tiled { block_dim: 32 }, Kernel::Scalar] {
        let a = first_accelerations(kernel, &case.x, &v, &case.m, dev);
        assert_eq!(a[0], a[1], "{kernel:?} on {dev}");
        let d = case.x[2] - case.x[0];
        let r2 = d.length_squared() + SOFTENING * SOFTENING;
        let want = d / (r2 * r2.sqrt());
        let err = (a[0] - want).abs().max_element() / want.length();
        assert!(
            err <= tile_nbody::error_bound(3),
            "{kernel:?} on {dev}: {err:e}"
        );
    }
}

#[test]
fn range_probes_on_the_cpu() {
    probes(&cpu());
}

#[test]
fn range_probes_on_a_gpu() {
    if let Some(dev) = gpu("range_probes_on_a_gpu") {
        probes(&dev);
    }
}

/// Bad arguments are errors naming the call, the argument and the values, not panics.
#[test]
fn bad_arguments_are_named() {
    let dev = cpu();
    let (x, v, m) = tile_nbody::start(4, 1);
    let err = |r: wp::Result<Sim>| match r {
        Err(e) => e.to_string(),
        Ok(_) => panic!("accepted"),
    };
    let tiled = Kernel::Tiled { block_dim: 64 };
    let e = err(Sim::new(tiled, &x, &v, &m, 0.0, 0.01, &dev));
    assert!(
        e.contains("Sim::new") && e.contains("softening") && e.contains("0"),
        "{e}"
    );
    let e = err(Sim::new(tiled, &x, &v, &m, f64::NAN, 0.01, &dev));
    assert!(e.contains("softening") && e.contains("NaN"), "{e}");
    // A softening whose square underflows f32 is none at all.
    let e = err(Sim::new(Kernel::Scalar, &x, &v, &m, 1e-30, 0.01, &dev));
    assert!(e.contains("softening") && e.contains("1e-30"), "{e}");
    let e = err(Sim::new(tiled, &x, &v[..3], &m, SOFTENING, 0.01, &dev));
    assert!(
        e.contains("same positive length") && e.contains("got 4, 3, 4"),
        "{e}"
    );
    let e = err(Sim::new(tiled, &[], &[], &[], SOFTENING, 0.01, &dev));
    assert!(e.contains("got 0, 0, 0"), "{e}");
    let e = err(Sim::new(tiled, &x, &v, &m, SOFTENING, f64::INFINITY, &dev));
    assert!(e.contains("dt") && e.contains("inf"), "{e}");
    let e = err(Sim::new(
        Kernel::Tiled { block_dim: 0 },
        &x,
        &v,
        &m,
        SOFTENING,
        0.01,
        &dev,
    ));
    assert!(e.contains("block_dim") && e.contains("got 0"), "{e}");
    // Past the launch's limit: the library's own error, naming the block size.
    let mut sim = Sim::new(
        Kernel::Tiled { block_dim: 4096 },
        &x,
        &v,
        &m,
        SOFTENING,
        0.01,
        &dev,
    )
    .expect("Sim::new");
    let e = sim.step().expect_err("block of 4096").to_string();
    assert!(e.contains("4096"), "{e}");
}

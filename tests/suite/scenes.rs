//! The differentiable scenes' claims, on every backend: the bouncing ball's time-of-impact
//! gradient is the derivative of the motion (it matches central differences of the TOI
//! program), and the naive contact's gradient, though the exact derivative of its own program,
//! has the wrong sign against it (examples/bounce.rs); and the finite-element scene's
//! (examples/fem_poisson.rs, kernels in examples/common/fem.rs): P1 Poisson in 2-D and 3-D
//! and linear elasticity on `Bsr<DMat3>`, assembled from triplets and solved by captured CG,
//! converge at order 2 in L2 at small sizes, with errors beside the interpolant's.

use warp_lang as wp;
use wp::prelude::*;

#[path = "../../examples/common/bounce.rs"]
mod bounce;
#[path = "../../examples/common/fem.rs"]
mod fem;
#[path = "../../examples/common/implicit_cloth.rs"]
mod implicit_cloth;

use bounce::{Balls, Contact, Setup};
// `fem` reaches the sparse tier as `super::sparse` (the example: `wp::sparse`).
use warp_runtime::sparse;

backend_tests!(
    bounce_gradients,
    fem_poisson_order,
    fem_elasticity_order,
    implicit_cloth_explore,
);

/// One ball launched at (1, 3) m/s aiming where a launch at (2, -1) m/s is at T (the scene's
/// ball 0), plus one at (1, 0) m/s aiming at the same point: the bounce then comes in the
/// first half of the flight. In f64 with h = 1e-6 a central difference of these O(1) losses
/// is good to about 1e-9 relative (truncation h^2 |L'''| ~ 1e-12, rounding eps |L| / h ~ 1e-10),
/// so the TOI tape must agree to 1e-6 (a margin for FMA contraction on a GPU), and so must the
/// naive tape with the naive program's differences. The naive program's dL/dv_y has the wrong
/// sign at both launches (+0.479 against -0.238, and -0.0029 against +0.0717).
fn bounce_gradients(dev: &wp::Device) {
    let setup = Setup::default();
    let aim = Balls::new(setup, &[DVec2::new(2.0, -1.0); 2], &[DVec2::ZERO; 2], dev).unwrap();
    aim.forward(Contact::Toi, dev).unwrap();
    let targets = aim.final_positions().unwrap();
    let balls = Balls::new(
        setup,
        &[DVec2::new(1.0, 3.0), DVec2::new(1.0, 0.0)],
        &targets,
        dev,
    )
    .unwrap();
    let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-3);
    let (_, toi) = balls.gradient(Contact::Toi, dev).unwrap();
    balls.vs[0].zero_grad().unwrap();
    let (_, naive) = balls.gradient(Contact::Naive, dev).unwrap();
    balls.vs[0].zero_grad().unwrap();
    for c in 0..2 {
        let truth = balls
            .central_difference(Contact::Toi, c, 1e-6, dev)
            .unwrap();
        let own = balls
            .central_difference(Contact::Naive, c, 1e-6, dev)
            .unwrap();
        for b in 0..2 {
            assert!(
                rel(toi[b][c], truth[b]) < 1e-6,
                "ball {b}, component {c}: TOI tape {} against central difference {}",
                toi[b][c],
                truth[b]
            );
            assert!(
                rel(naive[b][c], own[b]) < 1e-6,
                "ball {b}, component {c}: naive tape {} against its program's difference {}",
                naive[b][c],
                own[b]
            );
            if c == 1 {
                assert!(
                    naive[b][c] * truth[b] < 0.0,
                    "ball {b}: the naive dL/dv_y {} should have the wrong sign against {}",
                    naive[b][c],
                    truth[b]
                );
            }
        }
    }
    // Without friction the horizontal derivative is the same for both: -2 (x_T - target_x) T.
    assert!((toi[0].x - naive[0].x).abs() < 1e-12);
}

/// Solves `problem` at `ns` cells per side (CG to rtol 1e-10, captured) and checks the
/// scene's claims at these small sizes:
/// - every solve converged;
/// - the observed L2 order `log2(e_h / e_{h/2})` between the two finest levels is at least
///   1.9 (the scene's criterion; P1's order is 2), and at least `coarse_order` between the
///   coarser ones (pre-asymptotic there);
/// - the Galerkin solution's L2 error is within a factor [1, 2] of the nodal interpolant's
///   (both O(h^2), computed by the same quadrature; no solve in the latter; measured ratio
///   1.36 to 1.48 for Poisson, 1.64 to 1.71 for elasticity);
/// - each error equals the value this test recorded on the CPU (`want`) within 1e-8 relative:
///   the solve's algebraic error moves `u_h` by at most about rtol / (d π^2) ≈ 5e-12 in L2
///   against errors above 5e-3 (1e-9 relative), and a GPU's FMA contraction and `sin` change
///   the assembly by about 1e-15 relative.
fn fem_check(
    problem: fem::Problem,
    ns: &[usize],
    want: &[f64],
    coarse_order: f64,
    dev: &wp::Device,
) {
    let o = fem::options(1e-10, 10_000);
    let levels: Vec<fem::Level> = ns
        .iter()
        .map(|&n| fem::solve_level(problem, n, &o, dev).unwrap())
        .collect();
    for (l, &w) in levels.iter().zip(want) {
        let what = format!("{} at h = 1/{}", problem.name(), l.n);
        assert_eq!(l.stop, sparse::Stop::Converged, "{what}: {l:?}");
        assert!(
            (l.error - w).abs() <= 1e-8 * w,
            "{what}: L2 error {:e}, recorded {w:e} (relative tolerance 1e-8)",
            l.error
        );
        let ratio = l.error / l.interp_error;
        assert!(
            (1.0..=2.0).contains(&ratio),
            "{what}: L2 error {:e} against the interpolant's {:e}: ratio {ratio} outside [1, 2]",
            l.error,
            l.interp_error
        );
    }
    for (k, w) in levels.windows(2).enumerate() {
        let order = fem::order(w[0].error, w[1].error);
        let least = if k + 2 == levels.len() {
            1.9
        } else {
            coarse_order
        };
        assert!(
            order >= least,
            "{}: order {order} between h = 1/{} and 1/{} (want >= {least})",
            problem.name(),
            w[0].n,
            w[1].n
        );
    }
}

/// Poisson's equation, P1: triangles at h = 1/8, 1/16, 1/32 (orders 1.974, 1.993), tetrahedra
/// at 1/4, 1/8, 1/16 (orders 1.829, 1.953).
fn fem_poisson_order(dev: &wp::Device) {
    fem_check(
        fem::Problem::Poisson2,
        &[8, 16, 32],
        &[
            0.021132772788698576,
            0.005377434999491251,
            0.0013504362483865917,
        ],
        1.9,
        dev,
    );
    fem_check(
        fem::Problem::Poisson3,
        &[4, 8, 16],
        &[
            0.08718483932944314,
            0.024542335021116603,
            0.006337498738376774,
        ],
        1.8,
        dev,
    );
    // A level whose triplet indices would overflow the kernels' i32 is refused before any
    // allocation (281 cells per side: 6 · 281³ tetrahedra · 16 + 282³ nodes > i32::MAX; 280 fit).
    let e = fem::solve_level(fem::Problem::Poisson3, 281, &fem::options(1e-10, 10), dev)
        .expect_err("too fine a level");
    let text = e.to_string();
    assert!(
        text.contains("fem::solve_level") && text.contains("281"),
        "{text}"
    );
}

/// Linear elasticity on tetrahedra (`Bsr<DMat3>`) at h = 1/4, 1/8, 1/16 (orders 1.747, 1.913).
fn fem_elasticity_order(dev: &wp::Device) {
    fem_check(
        fem::Problem::Elasticity,
        &[4, 8, 16],
        &[
            0.10631647631288836,
            0.031665660046517975,
            0.008406419322281828,
        ],
        1.7,
        dev,
    );
}

fn implicit_cloth_explore(dev: &wp::Device) {
    use implicit_cloth::{simulate, Params, Series};
    let t_end = 0.25;
    for k in [1e2, 1e3] {
        let p = Params { n: 5, k, kd: 0.0 };
        let w = p.omega_max();
        let t = std::time::Instant::now();
        let (xr, _) = p.reference(t_end, 2.0 / w / 16.0);
        println!("k {k}: omega {w}, bound {}, ref {:.2}s", 2.0 / w, t.elapsed().as_secs_f64());
        let be = Series::BackwardEuler { newton: 3, rtol: 1e-6, max_iter: 500 };
        for s in [Series::Euler, Series::XpbdColored { substeps: 4, iterations: 1 }, be] {
            for j in 0..6 {
                let dt = 1.0 / 30.0 / 2f64.powi(j);
                let t = std::time::Instant::now();
                let o = simulate(p, s, dt, t_end, 5, j == 0, dev).unwrap();
                println!(
                    "  {} dt {dt:.5}: stable {} {} err {:.3e} drift {:.3e} cg {:.1} unconv {} {:.2}s res {:?}",
                    s.name(), o.stable, o.why, o.error(&xr), o.drift(), o.mean_cg(), o.cg_unconverged,
                    t.elapsed().as_secs_f64(), o.residuals.first()
                );
            }
        }
    }
}

//! The differentiable scenes' claims, on every backend: the bouncing ball's time-of-impact
//! gradient is the derivative of the motion (it matches central differences of the TOI
//! program), and the naive contact's gradient, though the exact derivative of its own program,
//! has the wrong sign against it (examples/bounce.rs); and the finite-element scene's
//! (examples/fem_poisson.rs, kernels in examples/common/fem.rs): P1 Poisson in 2-D and 3-D
//! and linear elasticity on `Bsr<DMat3>`, assembled from triplets and solved by captured CG,
//! converge at order 2 in L2 at small sizes, with errors beside the interpolant's; and the
//! implicit cloth's (examples/implicit_cloth.rs, kernels in examples/common/implicit_cloth.rs):
//! backward Euler by Newton on a `Bsr<Mat3>` with CG holds where semi-implicit Euler blows up,
//! its Newton residual falls, and both converge at first order against an f64 RK4 reference.

use warp_lang as wp;
use wp::prelude::*;

#[path = "../../examples/common/bounce.rs"]
mod bounce;
#[path = "../../examples/common/fem.rs"]
mod fem;
#[path = "../../examples/common/implicit_cloth.rs"]
mod implicit_cloth;

use bounce::{Balls, Contact, Setup};
// `fem` and `implicit_cloth` reach the sparse tier as `super::sparse` (the examples:
// `wp::sparse`).
use warp_runtime::sparse;

backend_tests!(
    bounce_gradients,
    fem_poisson_order,
    fem_elasticity_order,
    implicit_cloth_stability,
    implicit_cloth_order,
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

/// The implicit cloth's solver settings in the tests: 3 Newton iterations, CG to 1e-6 relative
/// (f32: about 10 ulps of the residual's scale, which the Newton residuals below reach).
const CLOTH_BE: implicit_cloth::Series = implicit_cloth::Series::BackwardEuler {
    newton: 3,
    rtol: 1e-6,
    max_iter: 500,
    graph: false,
};

/// On a GPU the same run on the CPU, and the final positions compared: the two backends run
/// the same kernels and the same CG steps, differing by the GPU's FMA contraction (about 1e-7
/// relative per operation in f32), which the damped (backward Euler) or neutrally stable
/// (semi-implicit Euler below its bound) maps carry to t_end without growth; 1e-4 m is 10x
/// below the smallest error the order checks compare.
fn cloth_same_on_cpu(
    params: implicit_cloth::Params,
    series: implicit_cloth::Series,
    dt: f64,
    t_end: f64,
    got: &implicit_cloth::Outcome,
    dev: &wp::Device,
) {
    if !dev.is_cuda() {
        return;
    }
    let cpu = implicit_cloth::simulate(params, series, dt, t_end, 1, false, &wp::cpu()).unwrap();
    let diff = cpu
        .x
        .iter()
        .zip(&got.x)
        .map(|(a, b)| a.distance(*b))
        .fold(0.0f64, f64::max);
    assert!(
        diff <= 1e-4,
        "{} at dt = {dt}: CPU and {dev} positions differ by {diff:e} m (tolerance 1e-4)",
        series.name()
    );
}

/// A 5 x 5 cloth at k = 1e3 N/m (explicit bound 2/ω_max = 2.1 ms) stepped at 1/60 s for
/// 0.25 s: semi-implicit Euler blows up (a spring past 2 rest lengths), backward Euler and
/// XPBD by colour do not; each backward Euler step's Newton residual after its third
/// iteration is at most 1/100 of the residual after its first, or at f32's floor (1e-5: the
/// residual's scale is h |f| ~ 1e-2 N s, and the CG tolerance 1e-6 of it).
fn implicit_cloth_stability(dev: &wp::Device) {
    use implicit_cloth::{simulate, Params, Series};
    let p = Params {
        n: 5,
        k: 1e3,
        kd: 0.0,
    };
    let (dt, t_end) = (1.0 / 60.0, 0.25);
    assert!(
        2.0 / p.omega_max() < dt / 4.0,
        "the step is not past the bound"
    );
    let euler = simulate(p, Series::Euler, dt, t_end, 5, false, dev).unwrap();
    assert!(
        !euler.stable,
        "semi-implicit Euler stayed stable at 1/60 s: {euler:?}"
    );
    let be = simulate(p, CLOTH_BE, dt, t_end, 5, true, dev).unwrap();
    assert!(be.stable, "backward Euler unstable: {}", be.why);
    assert_eq!(be.cg_unconverged, 0, "a CG solve did not converge");
    for (s, r) in be.residuals.iter().enumerate() {
        assert_eq!(r.len(), 4, "step {s}: {r:?}");
        assert!(
            r[3] <= 1e-2 * r[1] || r[3] <= 1e-5,
            "step {s}: Newton residuals {r:?} (before, after 1, 2, 3 iterations)"
        );
    }
    let stretch = p.max_stretch(&p.springs(), &be.x);
    assert!(
        stretch < 1.2,
        "backward Euler: a spring at {stretch} rest lengths"
    );
    let xpbd = Series::XpbdColored {
        substeps: 4,
        iterations: 1,
    };
    let x = simulate(p, xpbd, dt, t_end, 5, false, dev).unwrap();
    assert!(x.stable, "XPBD by colour unstable: {}", x.why);
    cloth_same_on_cpu(p, CLOTH_BE, dt, t_end, &be, dev);
    // The solves as captured graphs (`Mode::Graph`): the same steps, so the same bits.
    let graph = Series::BackwardEuler {
        newton: 3,
        rtol: 1e-6,
        max_iter: 500,
        graph: true,
    };
    let g = simulate(p, graph, dt, t_end, 5, false, dev).unwrap();
    assert_eq!(
        g.x, be.x,
        "backward Euler: captured solves against host-driven ones"
    );
    assert_eq!(g.cg_iterations, be.cg_iterations);
}

/// A 5 x 5 cloth at k = 1e2 N/m for 0.25 s, backward Euler at dt = 1/120, 1/240, 1/480 s
/// (h ω_max from 2.5 to 0.6) and semi-implicit Euler at 1/240, 1/480, 1/960 s, against RK4 in
/// f64 at 1/16 of the explicit bound (its own error below 1e-9 m): backward Euler's and
/// semi-implicit Euler's errors fall at first order, the observed order `log2(e_h / e_{h/2})`
/// within [0.85, 1.15] (measured on the CPU: 0.99 and 1.00 for both);
/// and backward Euler again with damping 0.05 N s/m along the springs (against a damped
/// reference; orders 0.99, 1.00).
fn implicit_cloth_order(dev: &wp::Device) {
    use implicit_cloth::{order, simulate, Params, Series};
    let t_end = 0.25;
    let undamped = Params {
        n: 5,
        k: 1e2,
        kd: 0.0,
    };
    // Damped along the springs: the damping force in the residual, `kd u uᵀ` in the matrix.
    let damped = Params {
        kd: 0.05,
        ..undamped
    };
    // Semi-implicit Euler a halving further down: 1/120 s is past its bound (6.8 ms).
    for (p, series, first) in [
        (undamped, CLOTH_BE, 120.0),
        (undamped, Series::Euler, 240.0),
        (damped, CLOTH_BE, 120.0),
    ] {
        let (reference, _) = p.reference(t_end, 2.0 / p.omega_max() / 16.0);
        let mut errors = Vec::new();
        for dt in [1.0 / first, 0.5 / first, 0.25 / first] {
            let o = simulate(p, series, dt, t_end, 2, false, dev).unwrap();
            assert!(o.stable, "{} at dt = {dt}: {}", series.name(), o.why);
            errors.push(o.error(&reference));
            cloth_same_on_cpu(p, series, dt, t_end, &o, dev);
        }
        println!("{} (kd = {}): errors {errors:?}", series.name(), p.kd);
        for w in errors.windows(2) {
            let q = order(w[0], w[1]);
            assert!(
                (0.85..=1.15).contains(&q),
                "{} (kd = {}): errors {errors:?}, order {q} outside [0.85, 1.15]",
                series.name(),
                p.kd
            );
        }
    }
}

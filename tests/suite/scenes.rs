//! The differentiable scenes' claims, on every backend: the bouncing ball's time-of-impact
//! gradient is the derivative of the motion (it matches central differences of the TOI
//! program), and the naive contact's gradient, though the exact derivative of its own program,
//! has the wrong sign against it (examples/bounce.rs).

use warp_lang as wp;
use wp::prelude::*;

#[path = "../../examples/common/bounce.rs"]
mod bounce;

use bounce::{Balls, Contact, Setup};

backend_tests!(bounce_gradients);

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

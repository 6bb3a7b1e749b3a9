//! Differentiating through a contact: a ball launched from 1 m must be at a target at
//! T = 1 s after bouncing once on the floor; the launch velocity is found by gradient descent
//! through the bounce.
//!
//! ```text
//! cargo run --release --example bounce -- [--device cpu|cuda:0] [--balls N]
//!     [--iterations 400] [--lr 0.05] [--tol 1e-3] [--plot-dir DIR]
//! ```
//! Each ball (radius 5 cm, restitution 0.8, no friction) is integrated by semi-implicit
//! Euler for 100 steps of 10 ms in f64, a thread per ball and a launch per step, recorded on a
//! tape; loss = sum over balls of |x_T - target|^2. Ball 0 starts at launch velocity (1, 3) m/s
//! and its target is where a ball launched at (2, -1) m/s is at T; the other balls (`--balls`,
//! 64 by default on the CPU, 4096 on a GPU) start at the same guess and aim at targets of
//! launch velocities spread over [1.5, 3] x [-2, 1] m/s.
//!
//! Two contact treatments (see `common/bounce.rs`): the naive one reflects the velocity
//! after a step that ended beneath the floor, the time-of-impact (TOI) one splits that step at
//! the contact. The scene prints, at the start:
//! - the tape gradients of both against central differences of their own forward programs
//!   (each tape differentiates its program exactly);
//! - the naive gradient against the true one (central differences of the TOI program, whose
//!   final state is continuous in the launch velocity): the naive program's derivative is the
//!   slope of a sawtooth, wrong in size and for many balls in sign; a wide central difference
//!   (h = 0.05 m/s, many teeth) of the naive program follows the physical slope instead.
//!
//! Then Adam runs with the TOI gradient until every ball is within `--tol` (1 mm) of its
//! target, and from the same start with the naive gradient for as many iterations (reported,
//! not required to converge: it stalls or goes the wrong way). Both losses are the physical
//! (TOI) loss. Table, plot `<plot-dir>/bounce.svg`, and a verdict line: the exit status is 1
//! when the TOI gradient disagrees with central differences or the TOI run does not converge.

#[path = "common/bounce.rs"]
mod bounce;
mod common;

use bounce::{Balls, Contact, Setup};
use clap::Parser;
use rand::Rng as _;
use warp_lang as wp;
use warp_report::frame::{Camera, Frame, Lines, Points};
use warp_report::{sci, Table};
use wp::prelude::*;

/// Central-difference step for the gradient check: in f64 with a loss of order 1 and
/// derivatives of order 1-10, the truncation error h^2 |L'''| / 6 is about 1e-12 and the
/// rounding error eps |L| / h about 1e-10, so the tape and the difference agree to about
/// 1e-9 relative; TOL_FD leaves a margin for the GPU's fused multiply-adds.
const H_FD: f64 = 1e-6;
const TOL_FD: f64 = 1e-6;
/// Errors are relative to the derivative, or absolute below this size (derivatives of these
/// losses are of order 0.01 to 10 m/(m/s); one about 0 has no relative error).
const FLOOR: f64 = 1e-3;
/// A wide step that spans many of the naive program's sawtooth teeth (the impact time
/// moves by about a step, 10 ms, per 0.05 m/s).
const H_WIDE: f64 = 0.05;

/// Launch velocities whose trajectories define the targets: ball 0's, then a deterministic
/// spread.
fn aims(balls: usize) -> Vec<DVec2> {
    let mut rng = common::rng(7);
    (0..balls)
        .map(|b| {
            if b == 0 {
                DVec2::new(2.0, -1.0)
            } else {
                DVec2::new(
                    1.5 + 1.5 * rng.random::<f64>(),
                    -2.0 + 3.0 * rng.random::<f64>(),
                )
            }
        })
        .collect()
}

fn norm(g: &[DVec2]) -> f64 {
    g.iter().map(|v| v.length_squared()).sum::<f64>().sqrt()
}

/// Largest distance of a ball from its target at T (by the TOI program, the physical one).
fn max_miss(balls: &Balls, dev: &wp::Device) -> wp::Result<f64> {
    let v = balls.vs[0].to_vec()?;
    let l = balls.losses_at(Contact::Toi, &v, dev)?;
    Ok(l.iter().fold(0.0f64, |m, &x| m.max(x.sqrt())))
}

/// Runs Adam from `guess` with `contact`'s gradient for up to `iterations`, stopping once every
/// ball is within `tol`; returns (iterations run, the largest final miss).
#[allow(clippy::too_many_arguments)]
fn optimise(
    balls: &Balls,
    contact: Contact,
    guess: &[DVec2],
    (iterations, lr, tol): (usize, f64, f64),
    log: &mut common::OptLog,
    dev: &wp::Device,
) -> wp::Result<(usize, f64)> {
    balls.vs[0].copy_from(&wp::Array::from_slice(guess, dev)?)?;
    let mut adam = wp::optim::Adam::new(lr);
    adam.add(&balls.vs[0])?;
    log.restart_clock();
    let series = contact.name();
    for it in 1..=iterations {
        let (_, g) = balls.gradient(contact, dev)?;
        adam.step()?;
        adam.zero_grad()?;
        // The physical loss and miss at the updated velocities (a forward of the TOI program).
        let v = balls.vs[0].to_vec()?;
        let per = balls.losses_at(Contact::Toi, &v, dev)?;
        let loss: f64 = per.iter().sum();
        let miss = per.iter().fold(0.0f64, |m, &x| m.max(x.sqrt()));
        let done = miss < tol;
        log.record(
            series,
            it,
            loss,
            norm(&g),
            &[sci(miss)],
            done || it == iterations,
        );
        if done {
            return Ok((it, miss));
        }
    }
    Ok((iterations, max_miss(balls, dev)?))
}

/// Differentiating through a contact: balls bounce once on the floor, and Adam with the
/// time-of-impact gradient finds the launch velocities that put each at its target.
#[derive(Parser)]
struct Cli {
    /// Balls, each with its own target [default: 4096 on a GPU, 64 on the CPU]
    #[arg(long, value_name = "N", value_parser = common::num::<usize>)]
    balls: Option<usize>,
    /// Most Adam iterations
    #[arg(long, default_value_t = 400, value_parser = common::num::<usize>)]
    iterations: usize,
    /// Adam's learning rate
    #[arg(long, default_value_t = 0.05)]
    lr: f64,
    /// Converged when every ball is within this distance of its target (m)
    #[arg(long, default_value_t = 1e-3)]
    tol: f64,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    let dev = cli.scene.init()?;
    let n = cli.balls.unwrap_or(if dev.is_cuda() { 4096 } else { 64 });
    let (iterations, lr, tol) = (cli.iterations, cli.lr, cli.tol);
    if n == 0 {
        eprintln!("--balls must be at least 1");
        std::process::exit(2);
    }
    let setup = Setup::default();
    let guess = vec![DVec2::new(1.0, 3.0); n];
    println!(
        "bounce: {n} ball(s) on \"{dev}\", f64, {} steps of {} s, radius {} m, restitution {}; \
         launched from ({}, {}) m at the guess (1, 3) m/s; loss = sum |x_T - target|^2",
        setup.steps, setup.dt, setup.radius, setup.restitution, setup.start.x, setup.start.y
    );

    // Targets: where the aimed launches are at T (the TOI program).
    let aimed = Balls::new(setup, &aims(n), &vec![DVec2::ZERO; n], &dev)?;
    aimed.forward(Contact::Toi, &dev)?;
    let targets = aimed.final_positions()?;
    drop(aimed);
    println!(
        "ball 0's target: ({:.4}, {:.4}) m (where a launch at (2, -1) m/s is at T)",
        targets[0].x, targets[0].y
    );
    let balls = Balls::new(setup, &guess, &targets, &dev)?;

    // The gradient check at the guess.
    let mut grads = Vec::new();
    for contact in [Contact::Toi, Contact::Naive] {
        let (_, g) = balls.gradient(contact, &dev)?;
        balls.vs[0].zero_grad()?;
        let fd = [
            balls.central_difference(contact, 0, H_FD, &dev)?,
            balls.central_difference(contact, 1, H_FD, &dev)?,
        ];
        grads.push((g, fd));
    }
    let wide = balls.central_difference(Contact::Naive, 1, H_WIDE, &dev)?;
    let (toi_tape, toi_fd) = &grads[0];
    let (naive_tape, naive_fd) = &grads[1];
    println!(
        "\ngradient of ball 0's loss at the guess (central differences with h = {}; \
         the true gradient is that of the TOI program)",
        sci(H_FD)
    );
    let mut t = Table::new([
        "dL/dv0",
        "true (FD of TOI)",
        "TOI tape",
        "rel. error",
        "naive tape",
        "FD of naive",
        "rel. error",
        "wide FD of naive (h = 0.05)",
    ]);
    for (c, name) in ["x", "y"].iter().enumerate() {
        let (a, b) = (toi_tape[0][c], toi_fd[c][0]);
        let (na, nb) = (naive_tape[0][c], naive_fd[c][0]);
        t.push([
            name.to_string(),
            format!("{b:.6}"),
            format!("{a:.6}"),
            sci(common::rel_err(a, b, FLOOR)),
            format!("{na:.6}"),
            format!("{nb:.6}"),
            sci(common::rel_err(na, nb, FLOOR)),
            if c == 1 {
                format!("{:.6}", wide[0])
            } else {
                "-".into()
            },
        ]);
    }
    print!("{t}");
    // Every ball: the worst agreement of each tape with its own program, and how often the
    // naive y-derivative has the wrong sign against the true one.
    let worst = |tape: &[DVec2], fd: &[Vec<f64>; 2]| -> f64 {
        (0..n)
            .flat_map(|b| (0..2).map(move |c| (b, c)))
            .map(|(b, c)| common::rel_err(tape[b][c], fd[c][b], FLOOR))
            .fold(0.0, f64::max)
    };
    let toi_err = worst(toi_tape, toi_fd);
    let naive_err = worst(naive_tape, naive_fd);
    let wrong_sign = (0..n)
        .filter(|&b| naive_tape[b].y * toi_fd[1][b] < 0.0)
        .count();
    let mut ratio: Vec<f64> = (0..n)
        .map(|b| (naive_tape[b].y / toi_fd[1][b]).abs())
        .collect();
    ratio.sort_by(f64::total_cmp);
    let median_ratio = ratio[n / 2];
    println!(
        "all {n} balls: TOI tape vs FD of the TOI program: max rel. error {} (tolerance {}); \
         naive tape vs FD of the naive program: {} (the tape differentiates the program it \
         ran); naive tape against the true dL/dv0_y: wrong sign for {wrong_sign} of {n} \
         balls, median |naive / true| {}",
        sci(toi_err),
        sci(TOL_FD),
        sci(naive_err),
        sci(median_ratio)
    );
    let check_ok = toi_err < TOL_FD;

    // Optimisation: the TOI gradient, then the naive one from the same guess.
    let mut log = common::OptLog::new(
        &format!("bounce: Adam (lr {lr}) on {n} launch velocities, physical loss, on {dev}"),
        "loss",
        &["max miss (m)"],
        25,
    )
    // The TOI gradient's iterations, then the naive one's (at most as many).
    .progress(2 * iterations as u64);
    let (toi_its, toi_miss) = optimise(
        &balls,
        Contact::Toi,
        &guess,
        (iterations, lr, tol),
        &mut log,
        &dev,
    )?;
    let converged = toi_miss < tol;
    let v_toi = balls.vs[0].to_vec()?;
    let (naive_its, naive_miss) = optimise(
        &balls,
        Contact::Naive,
        &guess,
        (toi_its, lr, tol),
        &mut log,
        &dev,
    )?;
    let naive_own: f64 = balls
        .losses_at(Contact::Naive, &balls.vs[0].to_vec()?, &dev)?
        .iter()
        .sum();
    log.finish("bounce");
    println!(
        "\nTOI gradient: {} in {toi_its} iterations, largest miss {} m; ball 0 launched at \
         ({:.4}, {:.4}) m/s",
        if converged {
            "every ball on target"
        } else {
            "NOT converged"
        },
        sci(toi_miss),
        v_toi[0].x,
        v_toi[0].y
    );
    println!(
        "naive gradient: after {naive_its} iterations from the same guess the largest miss is \
         {} m (the naive program's own loss is {}: it optimises the sawtooth, not the motion)",
        sci(naive_miss),
        sci(naive_own)
    );
    // The frame: the TOI solution's trajectories (up to 12 balls), the floor and the targets.
    balls.vs[0].copy_from(&wp::Array::from_slice(&v_toi, &dev)?)?;
    balls.forward(Contact::Toi, &dev)?;
    let shown = n.min(12);
    let at = |p: DVec2| [p.x, p.y, 0.0];
    let mut paths = vec![Vec::new(); shown];
    for x in &balls.xs {
        for (b, p) in x.to_vec()?.iter().take(shown).enumerate() {
            paths[b].push(at(*p));
        }
    }
    let targets = balls.target.to_vec()?;
    let ends: Vec<[f64; 3]> = paths.iter().filter_map(|p| p.last().copied()).collect();
    let all: Vec<[f64; 3]> = paths.iter().flatten().copied().collect();
    let (lo, hi) = common::bounds(&all);
    let mut frame = Frame::new(
        format!(
            "bounce: {shown} of {n} balls launched with the TOI gradient's velocities, {} s",
            setup.steps as f64 * setup.dt
        ),
        Camera::orthographic([0.0, 0.0, 1.0], [0.0; 3], [0.0, 1.0, 0.0]),
    )
    .size(800, 480)
    .note("the floor y = 0 (restitution 0.8); pale discs: the targets; red dots: where the balls are at T")
    .lines(Lines::new([[[lo[0] - 0.1, 0.0, 0.0], [hi[0] + 0.1, 0.0, 0.0]]]).width(2.0));
    for path in &paths {
        frame = frame.lines(Lines::polyline(path).colour([90, 120, 180]).width(1.0));
    }
    let frame = frame
        .points(
            Points::new(
                targets.iter().take(shown).map(|&p| at(p)),
                1.6 * setup.radius,
            )
            .colour([235, 200, 200]),
        )
        .points(Points::new(ends, setup.radius).colour([200, 40, 40]));
    common::write_frame("bounce", &frame);
    cli.scene.record_last("bounce", &frame);
    common::print_compiled();
    common::verdict(
        "bounce",
        check_ok && converged,
        &format!(
            "TOI tape gradient within {} of central differences: {}; every ball within {} m of \
             its target with the TOI gradient in at most {iterations} iterations: {}",
            sci(TOL_FD),
            if check_ok { "yes" } else { "no" },
            sci(tol),
            if converged { "yes" } else { "no" }
        ),
    );
    Ok(())
}

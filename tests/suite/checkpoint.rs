//! Checkpointed rollouts (`wp::Checkpointed`) against full tapes over the same steps.
//!
//! Per-element gradients (dL/dx0, dL/dv0, a per-particle parameter) are compared bit for bit
//! on every backend: a checkpointed backward runs the same adjoint launches in the same order
//! on the same inputs as a full tape (recomputed states come from the same kernel on the same
//! values, so they are the same bits, FMA contraction included), and each element's gradient
//! is written by one thread, so nothing depends on the order of threads. A gradient or loss
//! summed over particles with `atomic_add` is the exception: the order of the atomic
//! additions may differ between two runs, so those are compared with a tolerance derived
//! below.

use crate::{arr, zeros};
use std::cell::Cell;
use warp_lang as wp;
use wp::prelude::*;
use wp::Error;

#[path = "../../examples/common/seed_ad.rs"]
mod seed_ad;
use seed_ad::{step, sum_sq};

backend_tests!(
    seed_program_matches_full_tape,
    parameters_match_full_tape,
    running_loss_matches_full_tape,
    errors_and_misuse,
    report_of_a_thousand_steps,
);

const B: f32 = 0.05;
const MASS: f32 = 0.1;
const DT: f32 = 0.01;
const GRAVITY: Vec3 = Vec3::new(0.0, 0.0, -9.81);

/// The seed program's initial positions and velocities (as in `particle_gradients`).
fn initial(n: usize) -> (Vec<Vec3>, Vec<Vec3>) {
    let x0 = (0..n)
        .map(|i| Vec3::new((i % 100) as f32 * 0.01, (i % 7) as f32 * 0.1, 1.0))
        .collect();
    let v0 = (0..n)
        .map(|i| Vec3::new(1.0, (i % 3) as f32 - 1.0, 0.0))
        .collect();
    (x0, v0)
}

/// The components' bits, for bit-for-bit comparisons.
fn bits(v: &[Vec3]) -> Vec<[u32; 3]> {
    v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
}

fn grad_of<T: wp::Element>(a: &wp::Array<T>) -> Vec<T> {
    a.grad().expect("with_grad").to_vec().unwrap()
}

/// The seed program on a full tape, `passes` times over the same arrays (gradients
/// accumulate): (dL/dx0, dL/dv0, x_T) for L = sum |x_T|^2.
fn full_tape(
    n: usize,
    steps: usize,
    passes: usize,
    dev: &wp::Device,
) -> (Vec<Vec3>, Vec<Vec3>, Vec<Vec3>) {
    let (x0, v0) = initial(n);
    let mut xs = vec![arr(&x0, dev).with_grad().unwrap()];
    let mut vs = vec![arr(&v0, dev).with_grad().unwrap()];
    for _ in 0..steps {
        xs.push(zeros::<Vec3, 1>(n, dev).with_grad().unwrap());
        vs.push(zeros::<Vec3, 1>(n, dev).with_grad().unwrap());
    }
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    for _ in 0..passes {
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            for t in 0..steps {
                let args = (&xs[t], &vs[t], &xs[t + 1], &vs[t + 1], B, MASS, GRAVITY, DT);
                wp::launch(step, n, args, dev).unwrap();
            }
            wp::launch(sum_sq, n, (&xs[steps], &loss), dev).unwrap();
        }
        tape.backward(&loss).unwrap();
    }
    (
        grad_of(&xs[0]),
        grad_of(&vs[0]),
        xs[steps].to_vec().unwrap(),
    )
}

/// The seed program through a checkpointed rollout with `budget` snapshots, run `passes`
/// times (gradients accumulate): (dL/dx0, dL/dv0, x_T, the step function's calls, the
/// report's recomputed steps, what the last backward recomputed).
#[allow(clippy::type_complexity)]
fn checkpointed(
    n: usize,
    steps: usize,
    budget: usize,
    passes: usize,
    dev: &wp::Device,
) -> (Vec<Vec3>, Vec<Vec3>, Vec<Vec3>, usize, u64, u64) {
    let (x0, v0) = initial(n);
    let s0 = (
        arr(&x0, dev).with_grad().unwrap(),
        arr(&v0, dev).with_grad().unwrap(),
    );
    let calls = Cell::new(0usize);
    let mut roll = wp::Checkpointed::new(&s0, steps, budget, |_t, (x0, v0), (x1, v1)| {
        calls.set(calls.get() + 1);
        wp::launch(step, n, (x0, v0, x1, v1, B, MASS, GRAVITY, DT), dev)
    })
    .unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let mut x_t = Vec::new();
    for _ in 0..passes {
        let tape = wp::Tape::new();
        {
            let (x, _) = roll.forward().unwrap();
            x_t = x.to_vec().unwrap();
            let _rec = tape.record();
            wp::launch(sum_sq, n, (x, &loss), dev).unwrap();
        }
        tape.backward(&loss).unwrap();
        roll.backward().unwrap();
    }
    let (recomputed, last) = (roll.report().recomputed_steps, roll.recomputed());
    // Its `Debug` shows the rollout's length and report, for a user logging it.
    let d = format!("{roll:?}");
    assert!(
        d.starts_with("Checkpointed") && d.contains(&format!("steps: {steps}")),
        "{d}"
    );
    drop(roll);
    (
        grad_of(&s0.0),
        grad_of(&s0.1),
        x_t,
        calls.get(),
        recomputed,
        last,
    )
}

/// dL/dx0 and dL/dv0 of the seed program equal the full tape's bit for bit for budgets of
/// none, one, a few, the square-root default and more than the steps; the step function runs
/// T (forward) + the recomputed steps + T (recording) times; a second pass accumulates as a
/// second full tape does.
fn seed_program_matches_full_tape(dev: &wp::Device) {
    let n = 200;
    let cases = [
        (1, 0),
        (2, 0),
        (2, 1),
        (7, 0),
        (7, 1),
        (12, 2),
        (16, 3),
        (25, 100),
        (40, wp::Checkpointed::<wp::Array<f32>>::sqrt_budget(40)),
        (64, 5),
    ];
    for (steps, budget) in cases {
        let (gx, gv, xt) = full_tape(n, steps, 1, dev);
        let (cx, cv, ct, calls, recomputed, last) = checkpointed(n, steps, budget, 1, dev);
        let what = format!("{steps} steps, budget {budget}");
        assert_eq!(bits(&ct), bits(&xt), "{what}: x_T");
        assert_eq!(bits(&cx), bits(&gx), "{what}: dL/dx0");
        assert_eq!(bits(&cv), bits(&gv), "{what}: dL/dv0");
        assert_eq!(last, recomputed, "{what}: recomputed as scheduled");
        assert_eq!(calls, 2 * steps + recomputed as usize, "{what}: step calls");
        if budget >= steps {
            assert_eq!(recomputed, 0, "{what}: a snapshot of every state");
        }
    }
    // Enough particles that the CPU runs each launch in parallel chunks.
    let (gx, gv, _) = full_tape(20_000, 10, 1, dev);
    let (cx, cv, ..) = checkpointed(20_000, 10, 1, 1, dev);
    assert_eq!(bits(&cx), bits(&gx), "20,000 particles: dL/dx0");
    assert_eq!(bits(&cv), bits(&gv), "20,000 particles: dL/dv0");
    // Two passes accumulate as two backward passes of full tapes over the same arrays do
    // (the second adds each of step 0's contributions to what the first left, in order).
    let (gx, gv, _) = full_tape(n, 12, 2, dev);
    let (cx, cv, ..) = checkpointed(n, 12, 2, 2, dev);
    assert_eq!(bits(&cx), bits(&gx), "two passes accumulate dL/dx0");
    assert_eq!(bits(&cv), bits(&gv), "two passes accumulate dL/dv0");
}

/// The seed step with its parameters as arrays with gradients: a scalar drag `b[0]` and a
/// per-particle inverse mass.
#[wp::kernel]
fn step_params(
    x0: Array<Vec3>,
    v0: Array<Vec3>,
    x1: Array<Vec3>,
    v1: Array<Vec3>,
    b: Array<f32>,
    inv_mass: Array<f32>,
    gravity: Vec3,
    dt: f32,
) {
    let i = tid();
    let a = -b[0] * v0[i] * inv_mass[i] + gravity;
    let v = v0[i] + a * dt;
    v1[i] = v;
    x1[i] = x0[i] + v * dt;
}

/// Positions and velocities with every component positive, and no gravity: every state stays
/// positive (the drag only slows), so every term of dL/db has one sign (see
/// `parameters_match_full_tape`).
fn positive_initial(n: usize) -> (Vec<Vec3>, Vec<Vec3>, Vec<f32>) {
    let x0 = (0..n)
        .map(|i| Vec3::new(0.1 + (i % 10) as f32 * 0.01, 0.5, 1.0))
        .collect();
    let v0 = (0..n)
        .map(|i| Vec3::new(1.0 + (i % 5) as f32 * 0.1, 0.5, 0.25))
        .collect();
    let inv_mass = (0..n).map(|i| 10.0 + (i % 3) as f32).collect();
    (x0, v0, inv_mass)
}

/// Gradients of a per-particle parameter (bit for bit, as the states') and of a scalar one.
///
/// dL/db sums n T terms (one per particle and step) with `atomic_add`, in an order that may
/// differ between the two runs. All terms have one sign (see `positive_initial`), so each
/// order's sum is within gamma_N = N u of the exact sum relative to the sum itself
/// (u = 2^-24, N = n T = 100 x 20 = 2000: 1.2e-4); the two runs are within twice that:
/// 2.5e-4 relative. (On the CPU, launches this small run serially and the sums agree exactly.)
fn parameters_match_full_tape(dev: &wp::Device) {
    let (n, steps) = (100, 20);
    let (x0, v0, im) = positive_initial(n);
    let zero_g = Vec3::ZERO;
    // Full tape.
    let b = arr(&[0.5f32], dev).with_grad().unwrap();
    let inv_mass = arr(&im, dev).with_grad().unwrap();
    let mut xs = vec![arr(&x0, dev).with_grad().unwrap()];
    let mut vs = vec![arr(&v0, dev).with_grad().unwrap()];
    for _ in 0..steps {
        xs.push(zeros::<Vec3, 1>(n, dev).with_grad().unwrap());
        vs.push(zeros::<Vec3, 1>(n, dev).with_grad().unwrap());
    }
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        for t in 0..steps {
            let args = (
                &xs[t],
                &vs[t],
                &xs[t + 1],
                &vs[t + 1],
                &b,
                &inv_mass,
                zero_g,
                DT,
            );
            wp::launch(step_params, n, args, dev).unwrap();
        }
        wp::launch(sum_sq, n, (&xs[steps], &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    let want = (
        grad_of(&xs[0]),
        grad_of(&vs[0]),
        grad_of(&inv_mass),
        grad_of(&b)[0],
    );
    for budget in [0, 3, 19] {
        let cb = arr(&[0.5f32], dev).with_grad().unwrap();
        let cm = arr(&im, dev).with_grad().unwrap();
        let s0 = (
            arr(&x0, dev).with_grad().unwrap(),
            arr(&v0, dev).with_grad().unwrap(),
        );
        let mut roll = wp::Checkpointed::new(&s0, steps, budget, |_t, (x0, v0), (x1, v1)| {
            let args = (x0, v0, x1, v1, &cb, &cm, zero_g, DT);
            wp::launch(step_params, n, args, dev)
        })
        .unwrap();
        let closs = zeros::<f32, 1>(1, dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let (x, _) = roll.forward().unwrap();
            let _rec = tape.record();
            wp::launch(sum_sq, n, (x, &closs), dev).unwrap();
        }
        tape.backward(&closs).unwrap();
        roll.backward().unwrap();
        drop(roll);
        let what = format!("budget {budget}");
        assert_eq!(bits(&grad_of(&s0.0)), bits(&want.0), "{what}: dL/dx0");
        assert_eq!(bits(&grad_of(&s0.1)), bits(&want.1), "{what}: dL/dv0");
        let gm = grad_of(&cm);
        assert_eq!(
            gm.iter().map(|g| g.to_bits()).collect::<Vec<_>>(),
            want.2.iter().map(|g| g.to_bits()).collect::<Vec<_>>(),
            "{what}: dL/d inv_mass"
        );
        let gb = grad_of(&cb)[0];
        assert!(want.3 < 0.0, "every term of dL/db is negative: {}", want.3);
        crate::assert_close_f32(gb, want.3, 2.5e-4, &format!("{what}: dL/db"));
    }
}

/// A loss accumulated by the step function (L = sum over steps of sum |x_{t+1}|^2), seeded by
/// `backward_seeded`: the gradients equal a full tape's bit for bit; the loss after the
/// forward pass equals the full tape's within 2.5e-4 relative (a sum of n T = 2000 positive
/// terms by `atomic_add` in either order: twice gamma_2000, as for dL/db above).
fn running_loss_matches_full_tape(dev: &wp::Device) {
    let (n, steps) = (100, 20);
    let (x0, v0) = initial(n);
    let mut xs = vec![arr(&x0, dev).with_grad().unwrap()];
    let mut vs = vec![arr(&v0, dev).with_grad().unwrap()];
    for _ in 0..steps {
        xs.push(zeros::<Vec3, 1>(n, dev).with_grad().unwrap());
        vs.push(zeros::<Vec3, 1>(n, dev).with_grad().unwrap());
    }
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        for t in 0..steps {
            let args = (&xs[t], &vs[t], &xs[t + 1], &vs[t + 1], B, MASS, GRAVITY, DT);
            wp::launch(step, n, args, dev).unwrap();
            wp::launch(sum_sq, n, (&xs[t + 1], &loss), dev).unwrap();
        }
    }
    let want_loss = loss.to_vec().unwrap()[0];
    tape.backward(&loss).unwrap();
    for budget in [0, 2, 30] {
        let s0 = (
            arr(&x0, dev).with_grad().unwrap(),
            arr(&v0, dev).with_grad().unwrap(),
        );
        let closs = zeros::<f32, 1>(1, dev).with_grad().unwrap();
        let mut roll = wp::Checkpointed::new(&s0, steps, budget, |_t, (x0, v0), (x1, v1)| {
            wp::launch(step, n, (x0, v0, x1, v1, B, MASS, GRAVITY, DT), dev)?;
            wp::launch(sum_sq, n, (x1, &closs), dev)
        })
        .unwrap();
        roll.forward().unwrap();
        let got_loss = closs.to_vec().unwrap()[0];
        roll.backward_seeded(&closs).unwrap();
        drop(roll);
        let what = format!("budget {budget}");
        crate::assert_close_f32(got_loss, want_loss, 2.5e-4, &format!("{what}: loss"));
        assert_eq!(grad_of(&closs), vec![1.0], "{what}: the seed");
        assert_eq!(
            bits(&grad_of(&s0.0)),
            bits(&grad_of(&xs[0])),
            "{what}: dL/dx0"
        );
        assert_eq!(
            bits(&grad_of(&s0.1)),
            bits(&grad_of(&vs[0])),
            "{what}: dL/dv0"
        );
    }
}

/// A state whose `alloc_like` gets the shape wrong (a user implementation's bug).
struct Shrinking(wp::Array<f32>);

impl wp::CheckpointState for Shrinking {
    fn alloc_like(&self, grad: bool) -> wp::Result<Self> {
        let a = wp::Array::zeros(self.0.len() - 1, self.0.device())?;
        Ok(Shrinking(if grad { a.with_grad()? } else { a }))
    }
    fn copy_values_from(&self, src: &Self) -> wp::Result<()> {
        self.0.copy_values_from(&src.0)
    }
    fn zero_grads(&self) -> wp::Result<()> {
        self.0.zero_grads()
    }
    fn value_bytes(&self) -> usize {
        self.0.value_bytes()
    }
    fn has_grads(&self) -> bool {
        self.0.has_grads()
    }
    fn layout_mismatch(&self, other: &Self) -> Option<String> {
        self.0.layout_mismatch(&other.0)
    }
    fn devices(&self, out: &mut Vec<wp::Device>) {
        self.0.devices(out)
    }
}

/// Errors, never panics: zero steps, layouts and devices that do not match, backward before
/// forward or twice, the step function's error naming its step and pass; tapes recording
/// around a pass record none of its steps.
fn errors_and_misuse(dev: &wp::Device) {
    let n = 16;
    let (x0, v0) = initial(n);
    let s0 = (
        arr(&x0, dev).with_grad().unwrap(),
        arr(&v0, dev).with_grad().unwrap(),
    );
    type State = (wp::Array<Vec3>, wp::Array<Vec3>);
    let launch_step = |dim: usize, from: &State, to: &State| {
        let (x0, v0) = from;
        let (x1, v1) = to;
        wp::launch(step, dim, (x0, v0, x1, v1, B, MASS, GRAVITY, DT), dev)
    };
    let e = wp::Checkpointed::new(&s0, 0, 3, |_, f, t| launch_step(n, f, t))
        .expect_err("zero steps refused")
        .to_string();
    assert!(e.contains("zero steps"), "{e}");

    let bad = Shrinking(arr(&[1.0f32, 2.0, 3.0, 4.0], dev).with_grad().unwrap());
    let e = wp::Checkpointed::new(&bad, 5, 1, |_, _, _| Ok(()))
        .expect_err("a layout mismatch refused")
        .to_string();
    assert!(e.contains("shape [4] against [3]"), "{e}");

    if let (false, Ok(gpu)) = (dev.is_cpu(), wp::get_device("cuda:0")) {
        let mixed = (
            arr(&x0, &wp::cpu()).with_grad().unwrap(),
            arr(&v0, &gpu).with_grad().unwrap(),
        );
        let e = wp::Checkpointed::new(&mixed, 5, 1, |_, _, _| Ok(()))
            .expect_err("parts on two devices refused")
            .to_string();
        assert!(e.contains("different devices"), "{e}");
    }

    let mut roll = wp::Checkpointed::new(&s0, 6, 1, |_, f, t| launch_step(n, f, t)).unwrap();
    let e = roll.backward().unwrap_err().to_string();
    assert!(e.contains("before forward"), "{e}");
    assert!(roll.final_state().is_err());
    // A tape recording around the passes records none of their steps.
    let outer = wp::Tape::new();
    {
        let _rec = outer.record();
        roll.forward().unwrap();
        roll.backward().unwrap();
    }
    assert_eq!(
        outer.len(),
        0,
        "the passes' launches stay off the caller's tape"
    );
    let e = roll.backward().unwrap_err().to_string();
    assert!(e.contains("a second time"), "{e}");
    let loss = zeros::<f32, 1>(1, dev);
    roll.forward().unwrap();
    let e = roll.backward_seeded(&loss).unwrap_err().to_string();
    assert!(e.contains("no gradient"), "{e}");
    drop(roll);

    // A step that faults at t = 3 (one thread past the arrays), in the forward pass.
    let mut roll = wp::Checkpointed::new(&s0, 6, 1, |t, f, to| {
        launch_step(if t == 3 { n + 1 } else { n }, f, to)
    })
    .unwrap();
    match roll.forward() {
        Err(Error::Step {
            step: t,
            pass,
            source,
        }) => {
            assert_eq!((t, pass), (3, "forward"));
            assert!(matches!(*source, Error::Fault(_)), "{source:?}");
        }
        other => panic!("expected a step error, got {:?}", other.map(|_| ())),
    }
    let e = roll.backward().unwrap_err().to_string();
    assert!(e.contains("after a failed forward or backward pass"), "{e}");
    drop(roll);

    // A step that fails at t = 2 only after the forward pass: with a snapshot of every state
    // nothing is recomputed, so the failing call is the backward pass's recording of step 2.
    let fail = Cell::new(false);
    let mut roll = wp::Checkpointed::new(&s0, 5, 10, |t, f, to| {
        if fail.get() && t == 2 {
            return Err(Error::InvalidArgument {
                what: "the test's failure".into(),
            });
        }
        launch_step(n, f, to)
    })
    .unwrap();
    roll.forward().unwrap();
    fail.set(true);
    let e = roll.backward().unwrap_err();
    assert!(
        matches!(
            e,
            Error::Step {
                step: 2,
                pass: "backward",
                ..
            }
        ),
        "{e:?}"
    );
    let again = roll.backward().unwrap_err().to_string();
    assert!(again.contains("after a failed"), "{again}");
    // The message names the step; the step's error is its source, not repeated in it.
    let msg = e.to_string();
    assert!(
        msg.contains("step 2 of a checkpointed rollout (backward pass)")
            && !msg.contains("the test's failure"),
        "{msg}"
    );
    let source = std::error::Error::source(&e)
        .expect("the step's error")
        .to_string();
    assert!(source.contains("the test's failure"), "{source}");
}

/// The square-root default at the size (1,000 steps): at most floor(sqrt(1000)) = 31
/// states held against a full tape's 1001, in bytes too; the report prints both.
fn report_of_a_thousand_steps(dev: &wp::Device) {
    let n = 1000;
    let (x0, v0) = initial(n);
    let s0 = (
        arr(&x0, dev).with_grad().unwrap(),
        arr(&v0, dev).with_grad().unwrap(),
    );
    let roll = wp::Checkpointed::sqrt_memory(&s0, 1000, |_, _, _| Ok(())).unwrap();
    let r = roll.report().clone();
    let state = 2 * n * std::mem::size_of::<Vec3>();
    assert_eq!(r.state_bytes, state);
    assert!(r.states_held <= 31, "{r:?}");
    assert_eq!(r.states_held, 3 + r.snapshots);
    assert_eq!(r.states_with_grads, 3);
    assert_eq!(r.bytes_held, state * (r.states_held + 3));
    assert_eq!(
        (r.full_tape_states, r.full_tape_bytes),
        (1001, 2 * 1001 * state)
    );
    assert!(r.recomputed_steps <= 3 * 1000, "{r:?}");
    let text = r.to_string();
    assert!(
        text.contains("1001 states with gradients") && text.contains("31 states held"),
        "{text}"
    );
}

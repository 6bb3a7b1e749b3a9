//! Port of Warp's `warp/tests/test_smoothstep.py`: `smoothstep(a, b, t)` on f32, its value and
//! its gradients with respect to all three arguments through a Tape, on Warp's four cases
//! (inside the interval with `a < b`, a negative `t`, and both clamped ends).
//!
//! Ported: `test_smoothstep` -> [`smoothstep_values_and_gradients`], with Warp's data and
//! its absolute tolerance `1e-6` for the value and each gradient (values of size <= 1.5,
//! a few roundings of f32: exact on the CPU, an FMA's last bit on CUDA, both far inside).
//! Nothing of the file is left out (Warp's table has only the f32 rows).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(smoothstep_values_and_gradients);

#[wp::kernel]
fn k_smoothstep(a: Array<f32>, b: Array<f32>, t: Array<f32>, out: Array<f32>) {
    out[0] = smoothstep(a[0], b[0], t[0]);
}

/// Warp's `TEST_DATA[wp.float32]`: (a, b, t, value, d/da, d/db, d/dt).
const CASES: [[f32; 7]; 4] = [
    [1.0, 2.0, 1.5, 0.5, -0.75, -0.75, 1.5],
    [-1.0, 2.0, -0.25, 0.15625, -0.28125, -0.09375, 0.375],
    [0.0, 1.0, 9.9, 1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, -9.9, 0.0, 0.0, 0.0, 0.0],
];

#[track_caller]
fn near(got: f32, want: f32, what: &str) {
    assert!(
        (got - want).abs() <= 1e-6,
        "{what}: got {got:e}, want {want:e} (Warp's absolute tolerance 1e-6)"
    );
}

fn smoothstep_values_and_gradients(dev: &wp::Device) {
    for [a0, b0, t0, want, da, db, dt] in CASES {
        let a = arr(&[a0], dev).with_grad().unwrap();
        let b = arr(&[b0], dev).with_grad().unwrap();
        let t = arr(&[t0], dev).with_grad().unwrap();
        let out = zeros::<f32, 1>(1, dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch(k_smoothstep, 1, (&a, &b, &t, &out), dev).unwrap();
        }
        let case = format!("smoothstep({a0}, {b0}, {t0})");
        near(host(&out)[0], want, &case);
        tape.backward(&out).unwrap();
        near(host(&a.grad().unwrap())[0], da, &format!("d/da of {case}"));
        near(host(&b.grad().unwrap())[0], db, &format!("d/db of {case}"));
        near(host(&t.grad().unwrap())[0], dt, &format!("d/dt of {case}"));
    }
}

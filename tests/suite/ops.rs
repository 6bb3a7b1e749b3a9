//! Kernels as framework ops (issue 36, `warp_runtime::ops`, the facade's `ops` feature; the
//! suite's dev-dependency turns it on), and the runtime pieces under them: gradients in
//! memory the caller gives (`Array::with_grad_array`), the adjoint launched on its own
//! (`launch_adjoint`, Warp's `wp.launch(adjoint=True)`), and on a GPU the caller-ordered
//! stream (`Stream::from_raw_caller_ordered`) under a CUDA graph capture of the caller's
//! stream.
//!
//! Tolerances: a gradient every thread owns (one thread adds into one element) is the same
//! arithmetic in the same order whichever way the adjoint is launched, so it is compared bit
//! for bit; a gradient that threads add into together (a shared parameter) is summed in an
//! order the launch does not fix (the CPU's chunks, a GPU's atomics), so it is compared to
//! 1e-12 relative in f64 (a sum of 1000 terms of order 1 with unit roundoff 1.1e-16 errs by at
//! most about 1e-13 relative).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    launch_adjoint_matches_tape,
    launch_adjoint_shared_gradient,
    launch_adjoint_records_nothing,
    launch_adjoint_refuses_kernels_without_adjoint,
    with_grad_array_is_the_gradient,
    with_grad_array_errors,
);

/// Two outputs, every gradient thread-owned.
#[wp::kernel]
fn k_own(x: Array<f64>, s: f64, y: Array<f64>, z: Array<f64>) {
    let i = tid();
    y[i] = x[i] * x[i] * s + sin(x[i]);
    z[i] = x[i] * s - cos(x[i]);
}

/// `amp`'s gradient is every thread's: added together.
#[wp::kernel]
fn k_shared(x: Array<f64>, amp: Array<f64>, y: Array<f64>) {
    let i = tid();
    y[i] = amp[0] * sin(x[i]) + amp[1] * x[i];
}

#[wp::kernel(enable_backward = false)]
fn k_no_adjoint(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    y[i] = x[i];
}

const N: usize = 1000;

fn xs() -> Vec<f64> {
    (0..N).map(|i| 0.01 * i as f64 - 3.0).collect()
}

fn seeds(k: f64) -> Vec<f64> {
    (0..N).map(|i| k + 0.5 * ((i % 7) as f64)).collect()
}

/// An array of `data` with a zeroed gradient given as an array of its own (as a framework's
/// `zeros_like` would be), rather than `with_grad`'s.
fn given_grad(data: &[f64], dev: &wp::Device) -> wp::Array<f64> {
    arr(data, dev)
        .with_grad_array(zeros::<f64, 1>(data.len(), dev))
        .unwrap()
}

fn launch_adjoint_matches_tape(dev: &wp::Device) {
    let (xh, gy, gz, s) = (xs(), seeds(1.0), seeds(-2.0), 0.75);
    // The reference: a tape's backward of the same launch.
    let x1 = arr(&xh, dev).with_grad().unwrap();
    let y1 = zeros::<f64, 1>(N, dev).with_grad().unwrap();
    let z1 = zeros::<f64, 1>(N, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _r = tape.record();
        wp::launch(k_own, N, (&x1, s, &y1, &z1), dev).unwrap();
    }
    y1.grad().unwrap().copy_from(&arr(&gy, dev)).unwrap();
    z1.grad().unwrap().copy_from(&arr(&gz, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    // The adjoint alone, on the forward's values, with given gradient memory.
    let x2 = given_grad(&xh, dev);
    let (y2, z2) = (given_grad(&host(&y1), dev), given_grad(&host(&z1), dev));
    y2.grad().unwrap().copy_from(&arr(&gy, dev)).unwrap();
    z2.grad().unwrap().copy_from(&arr(&gz, dev)).unwrap();
    wp::launch_adjoint(k_own, N, (&x2, s, &y2, &z2), dev).unwrap();
    let (g1, g2) = (host(&x1.grad().unwrap()), host(&x2.grad().unwrap()));
    for i in 0..N {
        assert_eq!(g1[i].to_bits(), g2[i].to_bits(), "x.grad[{i}]");
    }
    // Closed form: dy/dx = 2 s x + cos x, dz/dx = s + sin x (to 1e-12: a few roundings).
    for i in 0..N {
        let x = xh[i];
        let want = gy[i] * (2.0 * s * x + x.cos()) + gz[i] * (s + x.sin());
        assert!(
            (g2[i] - want).abs() <= 1e-12 * want.abs().max(1.0),
            "{i}: {}",
            g2[i]
        );
    }
    // The outputs' gradients were taken (read and cleared), as by the tape.
    assert!(host(&y2.grad().unwrap()).iter().all(|&v| v == 0.0));
    assert!(host(&z2.grad().unwrap()).iter().all(|&v| v == 0.0));
    assert!(host(&y1.grad().unwrap()).iter().all(|&v| v == 0.0));
    // The primal arrays are not written.
    assert_eq!(host(&x2), xh);
    assert_eq!(host(&y2), host(&y1));

    // On a GPU, the same on a stream of the caller's (a second stream), bit for bit.
    #[cfg(feature = "cuda")]
    if !dev.is_cpu() {
        let x3 = given_grad(&xh, dev);
        let (y3, z3) = (given_grad(&host(&y1), dev), given_grad(&host(&z1), dev));
        y3.grad().unwrap().copy_from(&arr(&gy, dev)).unwrap();
        z3.grad().unwrap().copy_from(&arr(&gz, dev)).unwrap();
        let stream = wp::Stream::new(dev).unwrap();
        wp::launch_adjoint_on(k_own, N, (&x3, s, &y3, &z3), &stream).unwrap();
        stream.synchronize().unwrap();
        let g3 = host(&x3.grad().unwrap());
        for i in 0..N {
            assert_eq!(g1[i].to_bits(), g3[i].to_bits(), "on a stream: x.grad[{i}]");
        }
    }
}

fn launch_adjoint_shared_gradient(dev: &wp::Device) {
    let (xh, gy, amp) = (xs(), seeds(0.25), [1.5, -0.5]);
    let x1 = arr(&xh, dev).with_grad().unwrap();
    let a1 = arr(&amp, dev).with_grad().unwrap();
    let y1 = zeros::<f64, 1>(N, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _r = tape.record();
        wp::launch(k_shared, N, (&x1, &a1, &y1), dev).unwrap();
    }
    y1.grad().unwrap().copy_from(&arr(&gy, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    let x2 = given_grad(&xh, dev);
    let a2 = given_grad(&amp, dev);
    let y2 = given_grad(&host(&y1), dev);
    y2.grad().unwrap().copy_from(&arr(&gy, dev)).unwrap();
    wp::launch_adjoint(k_shared, N, (&x2, &a2, &y2), dev).unwrap();
    // Thread-owned: bit for bit.
    let (gx1, gx2) = (host(&x1.grad().unwrap()), host(&x2.grad().unwrap()));
    assert!(gx1
        .iter()
        .zip(&gx2)
        .all(|(a, b)| a.to_bits() == b.to_bits()));
    // Shared: the order of the adds is not fixed; 1e-12 relative (the header), and against
    // the closed form sum_i gy_i sin(x_i), sum_i gy_i x_i.
    let (ga1, ga2) = (host(&a1.grad().unwrap()), host(&a2.grad().unwrap()));
    let want = [
        (0..N).map(|i| gy[i] * xh[i].sin()).sum::<f64>(),
        (0..N).map(|i| gy[i] * xh[i]).sum::<f64>(),
    ];
    for k in 0..2 {
        assert!(
            (ga1[k] - ga2[k]).abs() <= 1e-12 * ga1[k].abs(),
            "{ga1:?} {ga2:?}"
        );
        assert!(
            (ga2[k] - want[k]).abs() <= 1e-12 * want[k].abs(),
            "{ga2:?} {want:?}"
        );
    }
}

fn launch_adjoint_records_nothing(dev: &wp::Device) {
    let x = given_grad(&xs(), dev);
    let y = given_grad(&vec![0.0; N], dev);
    let z = given_grad(&vec![0.0; N], dev);
    let tape = wp::Tape::new();
    {
        let _r = tape.record();
        wp::launch_adjoint(k_own, N, (&x, 1.0, &y, &z), dev).unwrap();
    }
    assert!(tape.is_empty(), "{:?}", tape.steps());
    // Checked as a launch is: a dim the arrays do not cover.
    let e = wp::launch_adjoint(k_own, N + 1, (&x, 1.0, &y, &z), dev).unwrap_err();
    assert!(e.to_string().contains("k_own"), "{e}");
}

fn launch_adjoint_refuses_kernels_without_adjoint(dev: &wp::Device) {
    let x = given_grad(&[1.0], dev);
    let y = given_grad(&[0.0], dev);
    let e = wp::launch_adjoint(k_no_adjoint, 1, (&x, &y), dev).unwrap_err();
    assert!(matches!(e, wp::Error::NotDifferentiable { .. }), "{e:?}");
    assert!(e.to_string().contains("k_no_adjoint"), "{e}");
}

fn with_grad_array_is_the_gradient(dev: &wp::Device) {
    let g = zeros::<f64, 2>((2, 3), dev);
    let a = zeros::<f64, 2>((2, 3), dev)
        .with_grad_array(g.clone())
        .unwrap();
    assert!(a.requires_grad());
    assert!(a.grad().unwrap().shares_storage_with(&g));
    // A row of the array has the row of the given gradient.
    a.row(1).unwrap().grad().unwrap().fill(2.0).unwrap();
    assert_eq!(host(&g.reshape(6).unwrap()), [0.0, 0.0, 0.0, 2.0, 2.0, 2.0]);
    // Replacing a gradient: the new memory, the old array's clones keep theirs.
    let b = arr(&[1.0, 2.0], dev).with_grad().unwrap();
    let old = b.clone();
    let b = b.with_grad_array(arr(&[5.0, 6.0], dev)).unwrap();
    assert_eq!(host(&b.grad().unwrap()), [5.0, 6.0]);
    assert_eq!(host(&old.grad().unwrap()), [0.0, 0.0]);
    // Empty arrays: only the shapes must agree.
    let e0 = zeros::<f64, 1>(0, dev);
    assert!(e0.with_grad_array(zeros::<f64, 1>(0, dev)).is_ok());
}

fn with_grad_array_errors(dev: &wp::Device) {
    let msg = |r: wp::Result<wp::Array<f64, 2>>| r.unwrap_err().to_string();
    let a = zeros::<f64, 2>((2, 3), dev);
    // Shape.
    let e = msg(a.clone().with_grad_array(zeros::<f64, 2>((3, 2), dev)));
    assert!(
        e.contains("shape [3, 2]") && e.contains("shape [2, 3]"),
        "{e}"
    );
    assert!(e.contains("with_grad_array (Array<f64, 2>)"), "{e}");
    // Strides: a transposed (3, 2) has the shape but not the layout.
    let e = msg(a
        .clone()
        .with_grad_array(zeros::<f64, 2>((3, 2), dev).transpose()));
    assert!(
        e.contains("strides [1, 2]") && e.contains("strides [3, 1]"),
        "{e}"
    );
    // Byte offset: a row of a bigger array against fresh memory.
    let big = zeros::<f64, 2>((4, 3), dev);
    let view = big.view(2..4).unwrap();
    let e = msg(view.with_grad_array(zeros::<f64, 2>((2, 3), dev)));
    assert!(
        e.contains("byte offset 0") && e.contains("byte offset 48"),
        "{e}"
    );
    // Less memory than the array's: a view's layout over a smaller allocation.
    let small = zeros::<f64, 2>((3, 3), dev).view(1..3).unwrap();
    let e = msg(big.view(1..3).unwrap().with_grad_array(small));
    assert!(
        e.contains("in 72 bytes") && e.contains("in 96 bytes"),
        "{e}"
    );
    // The array's own memory.
    let e = msg(a.clone().with_grad_array(a.clone()));
    assert!(e.contains("shares the array's memory"), "{e}");
    // Another device.
    if !dev.is_cpu() {
        let e = msg(a.with_grad_array(wp::Array::zeros((2, 3), &wp::cpu()).unwrap()));
        assert!(
            e.contains("\"cpu\"") && e.contains(&format!("\"{dev}\"")),
            "{e}"
        );
    }
}

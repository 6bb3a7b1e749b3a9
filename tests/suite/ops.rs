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
use std::sync::Arc;
use warp_lang as wp;
use warp_runtime::ops::{Buffer, CallArg, Dtype, Exec, LaunchDims, Op, Role, Shape, Value, Vmap};
use wp::prelude::*;

backend_tests!(
    launch_adjoint_matches_tape,
    launch_adjoint_shared_gradient,
    launch_adjoint_records_nothing,
    launch_adjoint_refuses_kernels_without_adjoint,
    with_grad_array_is_the_gradient,
    with_grad_array_errors,
    kernel_op_forward_matches_launch,
    kernel_op_backward_matches_tape,
    kernel_op_generic_instance,
    kernel_op_vector_and_matrix_values,
    kernel_op_spec,
    kernel_op_build_errors,
    kernel_op_call_errors,
    kernel_op_registry,
    batched_calls_match_a_loop,
    batched_call_errors,
    computation_op_forward_and_backward,
    computation_op_errors,
    computation_op_escape_aborts,
    caller_ordered_capture_replays,
    scoped_launch_in_a_capture_is_refused,
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

/// `y = a x + y`, any float type (the generic-instance case).
#[wp::kernel]
fn k_axpy<T: Float>(a: T, x: Array<T>, y: Array<T>) {
    let i = tid();
    y[i] = a * x[i] + y[i];
}

/// A framework's buffer over `a`'s memory (the op call's view of a tensor).
fn buf<T: wp::Element, const M: usize>(a: &wp::Array<T, M>, dtype: Dtype) -> Buffer {
    let ptr = if a.device().is_cpu() {
        a.as_mut_ptr().unwrap() as u64
    } else {
        a.device_ptr()
    };
    Buffer::contiguous(ptr, &a.shape(), dtype)
}

/// Runs `f` with where a call's launches go on `dev`: the CPU, or a stream of the caller's
/// wrapped as caller-ordered (the arrays were written on the default stream: synchronised
/// first, as the mode's contract asks; the stream is synchronised after).
fn with_exec(dev: &wp::Device, f: impl FnOnce(&Exec<'_>)) {
    with_exec_mode(dev, true, f)
}

/// [`with_exec`], with the stream caller-ordered (kernel ops) or wrapped by `from_raw`
/// (computation ops: joined with the default stream).
fn with_exec_mode(dev: &wp::Device, caller_ordered: bool, f: impl FnOnce(&Exec<'_>)) {
    if dev.is_cpu() {
        return f(&Exec::cpu());
    }
    #[cfg(feature = "cuda")]
    {
        wp::synchronize().unwrap();
        let owner = wp::Stream::new(dev).unwrap();
        // SAFETY: `owner` is a live stream of the device for the whole call, and the arrays
        // were synchronised above.
        let raw = owner.cuda_stream().cu_stream().cast();
        let s = match caller_ordered {
            true => unsafe { wp::Stream::from_raw_caller_ordered(raw, dev) },
            false => unsafe { wp::Stream::from_raw(raw, dev, ()) },
        }
        .unwrap();
        assert_eq!(s.is_caller_ordered(), caller_ordered);
        assert!(!owner.is_caller_ordered());
        f(&Exec::stream(&s));
        s.synchronize().unwrap();
    }
}

fn own_op() -> Op {
    Op::kernel("own", k_own)
        .outputs(["y", "z"])
        .build()
        .unwrap()
}

fn kernel_op_forward_matches_launch(dev: &wp::Device) {
    let (xh, s) = (xs(), 0.75);
    let x = arr(&xh, dev);
    let (y1, z1) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
    wp::launch(k_own, N, (&x, s, &y1, &z1), dev).unwrap();
    let (y2, z2) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
    let op = own_op();
    let (bx, by, bz) = (
        buf(&x, Dtype::F64),
        buf(&y2, Dtype::F64),
        buf(&z2, Dtype::F64),
    );
    let args = [
        CallArg::Buffer(&bx),
        CallArg::Value(Value::Float(s)),
        CallArg::Buffer(&by),
        CallArg::Buffer(&bz),
    ];
    // The shapes a framework allocates by: the launch dims (x's), outputs like them.
    let (dims, outs) = op
        .shapes(&[args[0], args[1], CallArg::Absent, CallArg::Absent])
        .unwrap();
    assert_eq!((dims, outs), (vec![N], vec![vec![N], vec![N]]));
    // SAFETY: the buffers are the arrays' memory, alive for the call.
    with_exec(dev, |e| unsafe { op.forward(&args, e) }.unwrap());
    let bits = |a: &wp::Array<f64>| host(a).iter().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&y1), bits(&y2));
    assert_eq!(bits(&z1), bits(&z2));
}

fn kernel_op_backward_matches_tape(dev: &wp::Device) {
    let (xh, gy, gz, s) = (xs(), seeds(1.0), seeds(-2.0), 0.75);
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
    // The op's backward on the forward's values, with the framework's gradient memory.
    let (x, y, z) = (arr(&xh, dev), arr(&host(&y1), dev), arr(&host(&z1), dev));
    let (gx, gyb, gzb) = (zeros::<f64, 1>(N, dev), arr(&gy, dev), arr(&gz, dev));
    let op = own_op();
    let b = |a: &wp::Array<f64>| buf(a, Dtype::F64);
    let (bx, by, bz, bgx, bgy, bgz) = (b(&x), b(&y), b(&z), b(&gx), b(&gyb), b(&gzb));
    let args = [
        CallArg::Buffer(&bx),
        CallArg::Value(Value::Float(s)),
        CallArg::Buffer(&by),
        CallArg::Buffer(&bz),
    ];
    let grads = [Some(&bgx), None, Some(&bgy), Some(&bgz)];
    // SAFETY: as in the forward test.
    with_exec(dev, |e| unsafe { op.backward(&args, &grads, e) }.unwrap());
    let (g1, g2) = (host(&x1.grad().unwrap()), host(&gx));
    assert!(
        g1.iter().zip(&g2).all(|(a, b)| a.to_bits() == b.to_bits()),
        "thread-owned gradients bit for bit"
    );
    // Output gradients taken; primal values untouched.
    assert!(host(&gyb).iter().chain(&host(&gzb)).all(|&v| v == 0.0));
    assert_eq!(host(&x), xh);
    assert_eq!(host(&y), host(&y1));

    // A shared gradient (amp): 1e-12 relative (the header).
    let amp = [1.5, -0.5];
    let (x1, a1) = (
        arr(&xh, dev).with_grad().unwrap(),
        arr(&amp, dev).with_grad().unwrap(),
    );
    let y1 = zeros::<f64, 1>(N, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _r = tape.record();
        wp::launch(k_shared, N, (&x1, &a1, &y1), dev).unwrap();
    }
    y1.grad().unwrap().copy_from(&arr(&gy, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    let op = Op::kernel("shared", k_shared)
        .outputs(["y"])
        .build()
        .unwrap();
    let (x, a, y) = (arr(&xh, dev), arr(&amp, dev), arr(&host(&y1), dev));
    let (gx, ga, gyb) = (
        zeros::<f64, 1>(N, dev),
        zeros::<f64, 1>(2, dev),
        arr(&gy, dev),
    );
    let (bx, ba, by, bga, bgy) = (b(&x), b(&a), b(&y), b(&ga), b(&gyb));
    let args = [
        CallArg::Buffer(&bx),
        CallArg::Buffer(&ba),
        CallArg::Buffer(&by),
    ];
    // x's gradient not asked for (torch's needs_input_grad false): only amp's.
    let grads = [None, Some(&bga), Some(&bgy)];
    // SAFETY: as above.
    with_exec(dev, |e| unsafe { op.backward(&args, &grads, e) }.unwrap());
    let (ga1, ga2) = (host(&a1.grad().unwrap()), host(&ga));
    for k in 0..2 {
        assert!(
            (ga1[k] - ga2[k]).abs() <= 1e-12 * ga1[k].abs(),
            "{ga1:?} {ga2:?}"
        );
    }
    assert!(host(&gx).iter().all(|&v| v == 0.0));
}

fn kernel_op_generic_instance(dev: &wp::Device) {
    // A generic kernel is named as a value only as the whole set of instances: the instance
    // is picked by its owned argument types.
    let op = Op::instance::<_, (f64, wp::Array<f64>, wp::Array<f64>)>("axpy64", k_axpy)
        .outputs(["y"])
        .build()
        .unwrap();
    assert_eq!(
        op.spec().params[0].kind,
        warp_runtime::ops::ArgKind::scalar_value(Dtype::F64)
    );
    let x = arr(&[1.0, 2.0, 3.0], dev);
    let y = arr(&[0.5, 0.25, 0.125], dev);
    let (bx, by) = (buf(&x, Dtype::F64), buf(&y, Dtype::F64));
    let args = [
        CallArg::Value(Value::Int(2)),
        CallArg::Buffer(&bx),
        CallArg::Buffer(&by),
    ];
    // SAFETY: as above.
    with_exec(dev, |e| unsafe { op.forward(&args, e) }.unwrap());
    // Exact: small dyadic values.
    assert_eq!(host(&y), [2.5, 4.25, 6.125]);
    let op32 = Op::instance::<_, (f32, wp::Array<f32>, wp::Array<f32>)>("axpy32", k_axpy)
        .outputs(["y"])
        .build()
        .unwrap();
    let e = unsafe { op32.forward(&args, &Exec::cpu()) }
        .unwrap_err()
        .to_string();
    assert!(e.contains("axpy32: argument 'x': a float64 buffer"), "{e}");
}

/// Values of vector, matrix, quaternion and integer-vector types: `y = m x + b` rotated by
/// `q`, shifted by `shift`'s components.
#[wp::kernel]
fn k_values(m: DMat3, b: DVec3, q: DQuat, shift: IVec2, x: Array<DVec3>, y: Array<DVec3>) {
    let i = tid();
    let s = DVec3::new(shift.x as f64, shift.y as f64, 0.0);
    y[i] = q * (m * x[i] + b) + s;
}

fn kernel_op_vector_and_matrix_values(dev: &wp::Device) {
    let op = Op::kernel("values", k_values)
        .outputs(["y"])
        .build()
        .unwrap();
    let p = &op.spec().params;
    assert_eq!(
        p[0].kind,
        warp_runtime::ops::ArgKind::Value {
            dtype: Dtype::F64,
            element: &[3, 3],
            type_name: "DMat3"
        }
    );
    assert_eq!(
        p[3].kind.describe(),
        "a static IVec2 (2 components of int32, shape [2])"
    );
    assert_eq!(p[0].role, Role::Scalar);
    let xs: Vec<glam::DVec3> = (0..50)
        .map(|i| glam::DVec3::new(i as f64 * 0.25, 1.0 - i as f64 * 0.5, 2.0))
        .collect();
    let x = arr(&xs, dev);
    let y = zeros::<glam::DVec3, 1>(xs.len(), dev);
    // Buffers of shape (50, 3): the vectors' components as a trailing axis.
    let buf3 = |a: &wp::Array<glam::DVec3>| {
        let b = buf(a, Dtype::F64);
        Buffer::contiguous(b.ptr, &[xs.len(), 3], Dtype::F64)
    };
    let (bx, by) = (buf3(&x), buf3(&y));
    // Row-major components: m's row 0 is (1, 2, 0); a quarter turn about z; integer shift.
    let m = [1.0, 2.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 3.0].map(Value::Float);
    let b = [0.5, 0.0, -1.0].map(Value::Float);
    let h = std::f64::consts::FRAC_1_SQRT_2;
    let q = [0.0, 0.0, h, h].map(Value::Float);
    let shift = [Value::Int(3), Value::Int(-4)];
    let args = [
        CallArg::Values(&m),
        CallArg::Values(&b),
        CallArg::Values(&q),
        CallArg::Values(&shift),
        CallArg::Buffer(&bx),
        CallArg::Buffer(&by),
    ];
    // SAFETY: the buffers are the arrays' memory, which outlives the call.
    with_exec(dev, |e| unsafe { op.forward(&args, e) }.unwrap());
    let mm = glam::DMat3::from_cols_array(&[1.0, 0.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0, 3.0]);
    let qq = glam::DQuat::from_xyzw(0.0, 0.0, h, h);
    for (got, x) in host(&y).iter().zip(&xs) {
        let want =
            qq * (mm * *x + glam::DVec3::new(0.5, 0.0, -1.0)) + glam::DVec3::new(3.0, -4.0, 0.0);
        // The quaternion rotation's few f64 products and adds: 1e-14 on values of order 10.
        assert!(
            (*got - want).abs().max_element() <= 1e-13,
            "{got} vs {want}"
        );
    }
    // Wrong counts and kinds name the parameter, what was given and the type.
    let short = [Value::Float(1.0); 2];
    let e = unsafe {
        op.forward(
            &[
                CallArg::Values(&m),
                CallArg::Values(&short),
                CallArg::Values(&q),
                CallArg::Values(&shift),
                CallArg::Buffer(&bx),
                CallArg::Buffer(&by),
            ],
            &Exec::cpu(),
        )
    }
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("'b'") && e.contains("the 2 values [1.0, 1.0]") && e.contains("DVec3"),
        "{e}"
    );
    let e = unsafe {
        op.forward(
            &[
                CallArg::Values(&m),
                CallArg::Value(Value::Float(1.0)),
                CallArg::Values(&q),
                CallArg::Values(&shift),
                CallArg::Buffer(&bx),
                CallArg::Buffer(&by),
            ],
            &Exec::cpu(),
        )
    }
    .unwrap_err()
    .to_string();
    assert!(e.contains("'b'") && e.contains("the value 1.0"), "{e}");
    let fractional = [Value::Float(0.5), Value::Int(1)];
    let e = unsafe {
        op.forward(
            &[
                CallArg::Values(&m),
                CallArg::Values(&b),
                CallArg::Values(&q),
                CallArg::Values(&fractional),
                CallArg::Buffer(&bx),
                CallArg::Buffer(&by),
            ],
            &Exec::cpu(),
        )
    }
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("'shift'") && e.contains("0.5") && e.contains("int32"),
        "{e}"
    );
}

fn kernel_op_spec(_dev: &wp::Device) {
    let op = own_op();
    assert_eq!(op.name(), "own");
    let p = &op.spec().params;
    let names: Vec<_> = p
        .iter()
        .map(|p| (p.name, p.role, p.differentiable))
        .collect();
    assert_eq!(
        names,
        [
            ("x", Role::Input, true),
            ("s", Role::Scalar, false),
            ("y", Role::Output, true),
            ("z", Role::Output, true)
        ]
    );
    assert_eq!(
        p[0].kind.describe(),
        "Array<f64, 1> (float64)",
        "how messages name the type"
    );
    assert!(p[2].zeroed);
    let op = Op::kernel("own", k_own)
        .outputs(["y", "z"])
        .init("z", warp_runtime::ops::Init::Uninit)
        .build()
        .unwrap();
    assert!(op.spec().params[2].zeroed && !op.spec().params[3].zeroed);
}

fn kernel_op_build_errors(_dev: &wp::Device) {
    let err = |r: wp::Result<Op>| r.unwrap_err().to_string();
    let e = err(Op::kernel("own", k_own).outputs(["nrm"]).build());
    assert!(
        e.contains("op own (kernel `k_own`): output 'nrm' is not a parameter"),
        "{e}"
    );
    assert!(e.contains("x, s, y, z"), "{e}");
    let e = err(Op::kernel("own", k_own).outputs(["s"]).build());
    assert!(e.contains("output 's' is a value"), "{e}");
    let e = err(Op::kernel("own", k_own).build());
    assert!(e.contains("names no output"), "{e}");
    let e = err(Op::kernel("own", k_own).outputs(["y", "y"]).build());
    assert!(e.contains("'y' is named twice"), "{e}");
    let e = err(Op::kernel("own", k_own)
        .outputs(["y", "z"])
        .shape("x", Shape::Dims)
        .build());
    assert!(
        e.contains("a shape is given for 'x', which is not an output"),
        "{e}"
    );
    let e = err(Op::kernel("own", k_own)
        .outputs(["y", "z"])
        .dims(LaunchDims::Like("y"))
        .build());
    assert!(e.contains("like 'y', which is not an input array"), "{e}");
    let e = err(Op::kernel("own", k_own)
        .outputs(["y", "z"])
        .shape("y", Shape::Like("s"))
        .build());
    assert!(e.contains("output 'y' is shaped like 's'"), "{e}");
    let e = err(Op::kernel("allout", k_shared)
        .outputs(["x", "amp", "y"])
        .build());
    assert!(
        e.contains("no input array to take the launch dimensions from"),
        "{e}"
    );
}

fn kernel_op_call_errors(dev: &wp::Device) {
    let op = own_op();
    let x = arr(&xs(), dev);
    let y = zeros::<f64, 1>(N, dev);
    let short = zeros::<f64, 1>(N - 1, dev);
    let x32 = zeros::<f32, 1>(N, dev);
    let m = zeros::<f64, 2>((N, 1), dev);
    let b = |a: &wp::Array<f64>| buf(a, Dtype::F64);
    let (bx, by, bs, b32, bm) = (
        b(&x),
        b(&y),
        b(&short),
        buf(&x32, Dtype::F32),
        buf(&m, Dtype::F64),
    );
    let s = CallArg::Value(Value::Float(1.0));
    let call = |args: &[CallArg<'_>]| {
        let mut out = String::new();
        with_exec(dev, |e| {
            // SAFETY: every buffer is an array's memory, alive for the call.
            out = unsafe { op.forward(args, e) }.unwrap_err().to_string()
        });
        out
    };
    let e = call(&[
        CallArg::Buffer(&b32),
        s,
        CallArg::Buffer(&by),
        CallArg::Buffer(&by),
    ]);
    assert!(
        e.contains(
            "own: argument 'x': a float32 buffer; the kernel takes Array<f64, 1> of float64"
        ),
        "{e}"
    );
    let e = call(&[
        CallArg::Buffer(&bm),
        s,
        CallArg::Buffer(&by),
        CallArg::Buffer(&by),
    ]);
    assert!(
        e.contains("own: argument 'x': shape [1000, 1]; Array<f64, 1>"),
        "{e}"
    );
    let e = call(&[s, s, CallArg::Buffer(&by), CallArg::Buffer(&by)]);
    assert!(
        e.contains("own: argument 'x' (0): the value 1.0; the kernel takes Array<f64, 1>"),
        "{e}"
    );
    let e = call(&[
        CallArg::Buffer(&bx),
        CallArg::Value(Value::Bool(true)),
        CallArg::Buffer(&by),
        CallArg::Buffer(&by),
    ]);
    assert!(
        e.contains("own: argument 's': true is not a float64"),
        "{e}"
    );
    let e = call(&[CallArg::Buffer(&bx), s, CallArg::Buffer(&by)]);
    assert!(
        e.contains("own: called with 3 arguments; the op takes 4 (x, s, y, z)"),
        "{e}"
    );
    let e = call(&[
        CallArg::Buffer(&bx),
        s,
        CallArg::Buffer(&by),
        CallArg::Buffer(&bs),
    ]);
    assert!(
        e.contains("own: output 'z': a buffer of shape [999]; its shape rule gives [1000]"),
        "{e}"
    );
    // A gradient for a value.
    let mut e = String::new();
    with_exec(dev, |ex| {
        // SAFETY: as above.
        e = unsafe {
            op.backward(
                &[
                    CallArg::Buffer(&bx),
                    s,
                    CallArg::Buffer(&by),
                    CallArg::Buffer(&by),
                ],
                &[None, Some(&by), None, None],
                ex,
            )
        }
        .unwrap_err()
        .to_string()
    });
    assert!(
        e.contains("own: argument 's' (a static float64) has no gradient"),
        "{e}"
    );
    // Integer values are range-checked.
    let op = Op::instance::<_, (i32, wp::Array<i32>, wp::Array<i32>)>("axpyi", k_axpy_int)
        .outputs(["y"])
        .build()
        .unwrap();
    let yi = zeros::<i32, 1>(2, dev);
    let byi = buf(&yi, Dtype::I32);
    let mut e = String::new();
    with_exec(dev, |ex| {
        // SAFETY: as above.
        e = unsafe {
            op.forward(
                &[
                    CallArg::Value(Value::Int(1 << 40)),
                    CallArg::Buffer(&byi),
                    CallArg::Buffer(&byi),
                ],
                ex,
            )
        }
        .unwrap_err()
        .to_string()
    });
    assert!(
        e.contains("axpyi: argument 'a': 1099511627776 is not a int32"),
        "{e}"
    );
}

/// An integer `axpy` (the range check of integer values).
#[wp::kernel]
fn k_axpy_int<T: Int>(a: T, x: Array<T>, y: Array<T>) {
    let i = tid();
    y[i] = a * x[i] + y[i];
}

fn kernel_op_registry(_dev: &wp::Device) {
    let op = own_op();
    let id = warp_runtime::ops::register(&op);
    assert_eq!(warp_runtime::ops::registered(id).unwrap().name(), "own");
    let id2 = warp_runtime::ops::register(&op);
    assert_ne!(id, id2);
    let e = warp_runtime::ops::registered(u64::MAX)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no op is registered under id 18446744073709551615"),
        "{e}"
    );
}

/// The reason the caller-ordered mode exists: a kernel op's launch inside a CUDA graph capture
/// of the caller's stream (as torch's CUDA graphs and XLA's command buffers make), replayed
/// with new input values.
fn caller_ordered_capture_replays(dev: &wp::Device) {
    if dev.is_cpu() {
        // CPU launches finish before they return: there is no stream to wrap.
        #[cfg(feature = "cuda")]
        {
            let mut h = 0u8;
            // SAFETY: refused before the handle is used.
            let e = unsafe { wp::Stream::from_raw_caller_ordered((&mut h as *mut u8).cast(), dev) }
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("Stream::from_raw_caller_ordered needs a CUDA device"),
                "{e}"
            );
        }
        return;
    }
    #[cfg(feature = "cuda")]
    {
        let op = Op::instance::<_, (f64, wp::Array<f64>, wp::Array<f64>)>("axpy64", k_axpy)
            .outputs(["y"])
            .build()
            .unwrap();
        let x = arr(&[1.0, 2.0, 3.0], dev);
        let y = zeros::<f64, 1>(3, dev);
        let (bx, by) = (buf(&x, Dtype::F64), buf(&y, Dtype::F64));
        let args = [
            CallArg::Value(Value::Float(2.0)),
            CallArg::Buffer(&bx),
            CallArg::Buffer(&by),
        ];
        wp::synchronize().unwrap();
        let owner = wp::Stream::new(dev).unwrap();
        let raw = owner.cuda_stream();
        // SAFETY: a live stream of the device; the arrays were synchronised above.
        let s =
            unsafe { wp::Stream::from_raw_caller_ordered(raw.cu_stream().cast(), dev) }.unwrap();
        // The first launch compiles and loads the kernel and makes this thread's fault record
        // (an allocation), which a capture in thread-local mode forbids: warm up first, as a
        // framework's eager first call does. Then zero the output again.
        // SAFETY: as below.
        unsafe { op.forward(&args, &Exec::stream(&s)) }.unwrap();
        s.synchronize().unwrap();
        y.fill(0.0).unwrap();
        wp::synchronize().unwrap();
        // Debug mode (the suite's for GPU tests) waits after each launch: on a caller-ordered
        // stream for that stream alone, and not while its owner captures it (CUDA refuses a
        // synchronisation inside a capture, and nothing has run).
        wp::config::set_debug(true);
        raw.begin_capture().unwrap();
        // SAFETY: as above.
        let r = unsafe { op.forward(&args, &Exec::stream(&s)) };
        let gpu = warp_cuda::Gpu::open(raw.ordinal()).unwrap();
        let graph = raw.end_capture(&gpu);
        r.unwrap();
        let graph = graph.unwrap();
        // Nothing ran at capture.
        assert_eq!(host(&y), [0.0; 3]);
        graph.launch(raw).unwrap();
        raw.synchronize().unwrap();
        assert_eq!(host(&y), [2.0, 4.0, 6.0]);
        // New values in the same memory: the replay reads them.
        x.copy_from(&arr(&[10.0, 20.0, 30.0], dev)).unwrap();
        wp::synchronize().unwrap();
        graph.launch(raw).unwrap();
        raw.synchronize().unwrap();
        assert_eq!(host(&y), [22.0, 44.0, 66.0]);
    }
}

/// A launch on a stream wrapped by `from_raw` (the scoped mode: joined with this crate's
/// default stream) inside its owner's capture is refused, naming the caller-ordered mode.
fn scoped_launch_in_a_capture_is_refused(dev: &wp::Device) {
    if dev.is_cpu() {
        return;
    }
    #[cfg(feature = "cuda")]
    {
        let x = arr(&[1.0, 2.0, 3.0], dev);
        let y = zeros::<f64, 1>(3, dev);
        wp::synchronize().unwrap();
        let owner = wp::Stream::new(dev).unwrap();
        let raw = owner.cuda_stream();
        // SAFETY: a live stream of the device, alive longer than the wrapper.
        let s = unsafe { wp::Stream::from_raw(raw.cu_stream().cast(), dev, ()) }.unwrap();
        // Warm up (compile, load, this thread's fault record) outside the capture: the refusal
        // under test is this crate's, not CUDA's of a first launch's allocations.
        wp::launch_on(k_axpy, 3, (2.0, &x, &y), &s).unwrap();
        s.synchronize().unwrap();
        y.fill(0.0).unwrap();
        wp::config::set_debug(false);
        raw.begin_capture().unwrap();
        let r = wp::launch_on(k_axpy, 3, (2.0, &x, &y), &s);
        let gpu = warp_cuda::Gpu::open(raw.ordinal()).unwrap();
        let ended = raw.end_capture(&gpu);
        wp::config::set_debug(true);
        let e = r.unwrap_err().to_string();
        assert!(e.contains("another library is capturing"), "{e}");
        assert!(e.contains("from_raw_caller_ordered"), "{e}");
        // The refused launch queued nothing into the capture.
        drop(ended);
        // And outside a capture the same launch runs.
        wp::launch_on(k_axpy, 3, (2.0, &x, &y), &s).unwrap();
        s.synchronize().unwrap();
        assert_eq!(host(&y), [2.0, 4.0, 6.0]);
    }
}

/// One step of a pendulum-like rollout (semi-implicit Euler), every gradient thread-owned.
#[wp::kernel]
fn k_step(x0: Array<f64>, v0: Array<f64>, dt: f64, x1: Array<f64>, v1: Array<f64>) {
    let i = tid();
    v1[i] = v0[i] - dt * sin(x0[i]);
    x1[i] = x0[i] + dt * v1[i];
}

/// The rollout: rows of `xs`/`vs` are the states; `out` the last positions.
fn rollout(
    (x0, v0): (&wp::Array<f64>, &wp::Array<f64>),
    (xs, vs): (&wp::Array<f64, 2>, &wp::Array<f64, 2>),
    out: &wp::Array<f64>,
    dt: f64,
    steps: usize,
    dev: &wp::Device,
) -> wp::Result<()> {
    wp::copy(&xs.row(0)?, x0)?;
    wp::copy(&vs.row(0)?, v0)?;
    for k in 0..steps {
        let n = x0.len();
        let (xa, va, xb, vb) = (xs.row(k)?, vs.row(k)?, xs.row(k + 1)?, vs.row(k + 1)?);
        wp::launch(k_step, n, (&xa, &va, dt, &xb, &vb), dev)?;
    }
    wp::copy(out, &xs.row(steps)?)
}

fn rollout_op() -> Op {
    let states = || {
        Shape::Fn(Arc::new(|s| {
            Ok(vec![s.scalar::<i64>("steps")? as usize + 1, s.len("x0")?])
        }))
    };
    Op::computation("rollout", |c| {
        let (x0, v0) = (c.input::<f64, 1>("x0")?, c.input::<f64, 1>("v0")?);
        let (xs, vs) = (c.scratch::<f64, 2>("xs")?, c.scratch::<f64, 2>("vs")?);
        let out = c.output::<f64, 1>("x_final")?;
        let (dt, steps) = (c.scalar::<f64>("dt")?, c.scalar::<i64>("steps")? as usize);
        rollout((x0, v0), (xs, vs), out, dt, steps, c.device())
    })
    .input::<f64, 1>("x0")
    .input::<f64, 1>("v0")
    .scalar::<f64>("dt")
    .scalar::<i64>("steps")
    .scratch::<f64, 2>("xs", states())
    .scratch::<f64, 2>("vs", states())
    .output::<f64, 1>("x_final", Shape::Like("x0"))
    .build()
    .unwrap()
}

fn computation_op_forward_and_backward(dev: &wp::Device) {
    let (n, steps, dt) = (64usize, 20usize, 0.05);
    let x0h: Vec<f64> = (0..n).map(|i| 0.1 * i as f64 - 2.0).collect();
    let v0h: Vec<f64> = (0..n).map(|i| 0.5 - 0.02 * i as f64).collect();
    let seed: Vec<f64> = (0..n).map(|i| 1.0 + (i % 3) as f64).collect();
    // The reference: the rollout recorded on a tape by hand.
    let x0 = arr(&x0h, dev).with_grad().unwrap();
    let v0 = arr(&v0h, dev).with_grad().unwrap();
    let xs = zeros::<f64, 2>((steps + 1, n), dev).with_grad().unwrap();
    let vs = zeros::<f64, 2>((steps + 1, n), dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _r = tape.record();
        rollout((&x0, &v0), (&xs, &vs), &out, dt, steps, dev).unwrap();
    }
    out.grad().unwrap().copy_from(&arr(&seed, dev)).unwrap();
    tape.backward_from_grads().unwrap();

    let op = rollout_op();
    let roles: Vec<_> = op.spec().params.iter().map(|p| p.role).collect();
    assert_eq!(
        roles,
        [
            Role::Input,
            Role::Input,
            Role::Scalar,
            Role::Scalar,
            Role::Scratch,
            Role::Scratch,
            Role::Output
        ]
    );
    let (ix, iv) = (arr(&x0h, dev), arr(&v0h, dev));
    let b1 = |a: &wp::Array<f64>| buf(a, Dtype::F64);
    let b2 = |a: &wp::Array<f64, 2>| buf(a, Dtype::F64);
    let (bx, bv) = (b1(&ix), b1(&iv));
    let (dtv, stv) = (
        CallArg::Value(Value::Float(dt)),
        CallArg::Value(Value::Int(steps as i64)),
    );
    let absent = CallArg::Absent;
    let (_, shapes) = op
        .shapes(&[
            CallArg::Buffer(&bx),
            CallArg::Buffer(&bv),
            dtv,
            stv,
            absent,
            absent,
            absent,
        ])
        .unwrap();
    assert_eq!(shapes, [vec![steps + 1, n], vec![steps + 1, n], vec![n]]);
    // Forward: the framework's zeroed scratch and output.
    let (sx, sv, o) = (
        zeros::<f64, 2>((steps + 1, n), dev),
        zeros::<f64, 2>((steps + 1, n), dev),
        zeros::<f64, 1>(n, dev),
    );
    let (bsx, bsv, bo) = (b2(&sx), b2(&sv), b1(&o));
    let args = [
        CallArg::Buffer(&bx),
        CallArg::Buffer(&bv),
        dtv,
        stv,
        CallArg::Buffer(&bsx),
        CallArg::Buffer(&bsv),
        CallArg::Buffer(&bo),
    ];
    // SAFETY: every buffer is an array's memory, alive for the call.
    with_exec_mode(dev, false, |e| unsafe { op.forward(&args, e) }.unwrap());
    let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(host(&o)), bits(host(&out)), "forward bit for bit");
    // Backward: fresh zeroed scratch and output again, zeroed input gradients, the output's
    // gradient (the scratch's gradients are the op's own).
    let (sx, sv, o) = (
        zeros::<f64, 2>((steps + 1, n), dev),
        zeros::<f64, 2>((steps + 1, n), dev),
        zeros::<f64, 1>(n, dev),
    );
    let (gx, gv, go) = (
        zeros::<f64, 1>(n, dev),
        zeros::<f64, 1>(n, dev),
        arr(&seed, dev),
    );
    let (bsx, bsv, bo, bgx, bgv, bgo) = (b2(&sx), b2(&sv), b1(&o), b1(&gx), b1(&gv), b1(&go));
    let args = [
        CallArg::Buffer(&bx),
        CallArg::Buffer(&bv),
        dtv,
        stv,
        CallArg::Buffer(&bsx),
        CallArg::Buffer(&bsv),
        CallArg::Buffer(&bo),
    ];
    let grads = [Some(&bgx), Some(&bgv), None, None, None, None, Some(&bgo)];
    // SAFETY: as above.
    with_exec_mode(dev, false, |e| {
        unsafe { op.backward(&args, &grads, e) }.unwrap()
    });
    // The same launches and copies in the same order: bit for bit.
    assert_eq!(bits(host(&gx)), bits(host(&x0.grad().unwrap())));
    assert_eq!(bits(host(&gv)), bits(host(&v0.grad().unwrap())));
    assert!(host(&gx).iter().any(|&g| g != 0.0));
    // The inputs are untouched.
    assert_eq!(host(&ix), x0h);
}

fn computation_op_errors(dev: &wp::Device) {
    let err = |r: wp::Result<Op>| r.unwrap_err().to_string();
    let ok = |_: &mut warp_runtime::ops::Ctx<'_>| Ok(());
    let e = err(Op::computation("c", ok).input::<f64, 1>("a").build());
    assert!(
        e.contains("op c (a computation): declares no output"),
        "{e}"
    );
    let e = err(Op::computation("c", ok)
        .input::<f64, 1>("a")
        .output::<f64, 1>("a", Shape::Like("a"))
        .build());
    assert!(e.contains("'a' is declared twice"), "{e}");
    let e = err(Op::computation("c", ok)
        .input::<f64, 1>("a")
        .output::<f64, 1>("b", Shape::Dims)
        .build());
    assert!(e.contains("'b' is shaped by the launch dimensions"), "{e}");
    let e = err(Op::computation("c", ok)
        .scalar::<f64>("s")
        .output::<f64, 1>("b", Shape::Like("s"))
        .build());
    assert!(
        e.contains("'b' is shaped like 's', which is not an input array"),
        "{e}"
    );
    // A body's errors: a name it does not declare, a wrong type, a panic.
    let run = |body: fn(&mut warp_runtime::ops::Ctx<'_>) -> wp::Result<()>| {
        let op = Op::computation("c", body)
            .input::<f64, 1>("a")
            .output::<f64, 1>("b", Shape::Like("a"))
            .build()
            .unwrap();
        let (a, b) = (zeros::<f64, 1>(2, dev), zeros::<f64, 1>(2, dev));
        let (ba, bb) = (buf(&a, Dtype::F64), buf(&b, Dtype::F64));
        let mut out = String::new();
        with_exec_mode(dev, false, |e| {
            // SAFETY: the arrays' memory, alive for the call.
            out = unsafe { op.forward(&[CallArg::Buffer(&ba), CallArg::Buffer(&bb)], e) }
                .unwrap_err()
                .to_string()
        });
        out
    };
    let e = run(|c| c.input::<f64, 1>("zz").map(|_| ()));
    assert!(
        e.contains("c: the body asks for Input 'zz', which the op does not declare"),
        "{e}"
    );
    let e = run(|c| c.input::<f32, 1>("a").map(|_| ()));
    assert!(
        e.contains("asks for 'a' as Array<f32, 1>; it is declared as Array<f64, 1>"),
        "{e}"
    );
    let e = run(|_| panic!("boom"));
    assert!(e.contains("c: the body panicked: boom"), "{e}");
    // A caller-ordered stream is refused (the body's array operations are not ordered with it).
    #[cfg(feature = "cuda")]
    if !dev.is_cpu() {
        let op = rollout_op();
        let mut e = String::new();
        with_exec(dev, |ex| {
            let a = zeros::<f64, 1>(2, dev);
            let ba = buf(&a, Dtype::F64);
            let v = CallArg::Value(Value::Int(1));
            let b = CallArg::Buffer(&ba);
            // SAFETY: refused before any buffer is used.
            e = unsafe { op.forward(&[b, b, v, v, b, b, b], ex) }
                .unwrap_err()
                .to_string();
        });
        assert!(e.contains("not a caller-ordered one"), "{e}");
    }
}

/// `expand_dims` batching: a batch of 3 against 3 unbatched calls on the rows, bit for bit (the
/// same launches on the same data); an unbatched operand (extent 1) is read by every element;
/// `Vmap::Fold` (one launch) gives the same bits for a row-wise kernel and falls back to the
/// loop when an operand is unbatched.
fn batched_calls_match_a_loop(dev: &wp::Device) {
    let (nb, n, s) = (3usize, 100usize, 0.5);
    let xh: Vec<f64> = (0..nb * n).map(|i| 0.01 * i as f64 - 1.0).collect();
    let x = wp::Array::from_slice_shape(&xh, (nb, n), dev).unwrap();
    let b2 = |a: &wp::Array<f64, 2>| buf(a, Dtype::F64);
    let b1 = |a: &wp::Array<f64>| buf(a, Dtype::F64);
    let sv = CallArg::Value(Value::Float(s));
    // Reference: one unbatched call per row.
    let (yr, zr) = (zeros::<f64, 2>((nb, n), dev), zeros::<f64, 2>((nb, n), dev));
    let op = own_op();
    for k in 0..nb {
        let (xk, yk, zk) = (x.row(k).unwrap(), yr.row(k).unwrap(), zr.row(k).unwrap());
        let (bx, by, bz) = (b1(&xk), b1(&yk), b1(&zk));
        let args = [
            CallArg::Buffer(&bx),
            sv,
            CallArg::Buffer(&by),
            CallArg::Buffer(&bz),
        ];
        // SAFETY: the arrays' memory, alive for the call.
        with_exec(dev, |e| unsafe { op.forward(&args, e) }.unwrap());
    }
    let bits = |v: Vec<f64>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for fold in [false, true] {
        let op = match fold {
            false => own_op(),
            true => Op::kernel("own", k_own)
                .outputs(["y", "z"])
                .vmap(Vmap::Fold)
                .build()
                .unwrap(),
        };
        let (y, z) = (zeros::<f64, 2>((nb, n), dev), zeros::<f64, 2>((nb, n), dev));
        let (bx, by, bz) = (b2(&x), b2(&y), b2(&z));
        let args = [
            CallArg::Buffer(&bx),
            sv,
            CallArg::Buffer(&by),
            CallArg::Buffer(&bz),
        ];
        // SAFETY: as above.
        with_exec(dev, |e| unsafe { op.forward_batched(&args, e) }.unwrap());
        assert_eq!(bits(host(&y)), bits(host(&yr)), "fold {fold}");
        assert_eq!(bits(host(&z)), bits(host(&zr)), "fold {fold}");
    }
    // An unbatched amplitude (batch extent 1) beside a batched x; forward and backward.
    let amp = wp::Array::from_slice_shape(&[1.5, -0.5], (1, 2), dev).unwrap();
    let gyh: Vec<f64> = (0..nb * n).map(|i| 1.0 + (i % 5) as f64).collect();
    for vmap in [Vmap::Loop, Vmap::Fold] {
        let op = Op::kernel("shared", k_shared)
            .outputs(["y"])
            .vmap(vmap)
            .build()
            .unwrap();
        let y = zeros::<f64, 2>((nb, n), dev);
        let (bx, ba, by) = (b2(&x), b2(&amp), b2(&y));
        let args = [
            CallArg::Buffer(&bx),
            CallArg::Buffer(&ba),
            CallArg::Buffer(&by),
        ];
        // SAFETY: as above.
        with_exec(dev, |e| unsafe { op.forward_batched(&args, e) }.unwrap());
        // Backward: per-element gradients of every input (amp's too: (3, 2)).
        let (gx, ga) = (zeros::<f64, 2>((nb, n), dev), zeros::<f64, 2>((nb, 2), dev));
        let gy = wp::Array::from_slice_shape(&gyh, (nb, n), dev).unwrap();
        let (bgx, bga, bgy) = (b2(&gx), b2(&ga), b2(&gy));
        // SAFETY: as above.
        with_exec(dev, |e| {
            unsafe { op.backward_batched(&args, &[Some(&bgx), Some(&bga), Some(&bgy)], e) }.unwrap()
        });
        let (yv, gxv, gav) = (host(&y), host(&gx), host(&ga));
        for k in 0..nb {
            // Each element against an unbatched call on its row.
            let (xk, yk) = (x.row(k).unwrap(), zeros::<f64, 1>(n, dev));
            let a1 = arr(&[1.5, -0.5], dev);
            let (bxk, bak, byk) = (b1(&xk), b1(&a1), b1(&yk));
            let one = [
                CallArg::Buffer(&bxk),
                CallArg::Buffer(&bak),
                CallArg::Buffer(&byk),
            ];
            // SAFETY: as above.
            with_exec(dev, |e| unsafe { op.forward(&one, e) }.unwrap());
            assert_eq!(
                bits(host(&yk)),
                bits(yv[k * n..(k + 1) * n].to_vec()),
                "{vmap:?} y[{k}]"
            );
            let (gxk, gak) = (zeros::<f64, 1>(n, dev), zeros::<f64, 1>(2, dev));
            let gyk = arr(&gyh[k * n..(k + 1) * n], dev);
            let (bgxk, bgak, bgyk) = (b1(&gxk), b1(&gak), b1(&gyk));
            // SAFETY: as above.
            with_exec(dev, |e| {
                unsafe { op.backward(&one, &[Some(&bgxk), Some(&bgak), Some(&bgyk)], e) }.unwrap()
            });
            assert_eq!(bits(host(&gxk)), bits(gxv[k * n..(k + 1) * n].to_vec()));
            // amp's gradient is a sum over the row's threads: 1e-12 relative (the header).
            let gak = host(&gak);
            for j in 0..2 {
                let (a, b) = (gak[j], gav[k * 2 + j]);
                assert!(
                    (a - b).abs() <= 1e-12 * a.abs(),
                    "{vmap:?} amp[{k}][{j}]: {a} {b}"
                );
            }
        }
    }
}

fn batched_call_errors(dev: &wp::Device) {
    let op = own_op();
    let x = zeros::<f64, 2>((3, 4), dev);
    let y = zeros::<f64, 1>(4, dev);
    let y2 = zeros::<f64, 2>((2, 4), dev);
    let (bx, by, by2) = (
        buf(&x, Dtype::F64),
        buf(&y, Dtype::F64),
        buf(&y2, Dtype::F64),
    );
    let sv = CallArg::Value(Value::Float(1.0));
    let call = |args: &[CallArg<'_>]| {
        let mut out = String::new();
        with_exec(dev, |e| {
            // SAFETY: refused before any buffer is used.
            out = unsafe { op.forward_batched(args, e) }
                .unwrap_err()
                .to_string()
        });
        out
    };
    let e = call(&[
        CallArg::Buffer(&bx),
        sv,
        CallArg::Buffer(&by),
        CallArg::Buffer(&bx),
    ]);
    assert!(
        e.contains("own: batched call: 'x' has 1 leading batch axes and 'y' has 0"),
        "{e}"
    );
    let e = call(&[
        CallArg::Buffer(&bx),
        sv,
        CallArg::Buffer(&by2),
        CallArg::Buffer(&bx),
    ]);
    assert!(
        e.contains("own: batched call: 'y' has extent 2 on batch axis 0; the batch has 3"),
        "{e}"
    );
}

/// A body that keeps a handle to a call's array past the call aborts the process, naming the
/// op and the array (an error could not take back a later read of freed memory). Run in a
/// child process: this test's binary again, on this test alone, with a variable set.
fn computation_op_escape_aborts(dev: &wp::Device) {
    const CHILD: &str = "WARP_LANG_TEST_OPS_ESCAPE";
    static KEPT: std::sync::Mutex<Option<wp::Array<f64>>> = std::sync::Mutex::new(None);
    if !dev.is_cpu() {
        return; // The check is the same on every device; the CPU's child needs no GPU.
    }
    if std::env::var_os(CHILD).is_some() {
        let op = Op::computation("keeper", |c| {
            *KEPT.lock().unwrap() = Some(c.input::<f64, 1>("a")?.clone());
            Ok(())
        })
        .input::<f64, 1>("a")
        .output::<f64, 1>("b", Shape::Like("a"))
        .build()
        .unwrap();
        let (a, b) = (zeros::<f64, 1>(2, dev), zeros::<f64, 1>(2, dev));
        let (ba, bb) = (buf(&a, Dtype::F64), buf(&b, Dtype::F64));
        // SAFETY: the arrays' memory, alive for the call.
        let _ = unsafe { op.forward(&[CallArg::Buffer(&ba), CallArg::Buffer(&bb)], &Exec::cpu()) };
        unreachable!("the escape check aborts");
    }
    let module = module_path!()
        .split_once("::")
        .map_or(module_path!(), |(_, m)| m);
    let name = format!("{module}::cpu_backend::computation_op_escape_aborts");
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args([name.as_str(), "--exact", "--nocapture", "--test-threads=1"])
        .env(CHILD, "1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the child did not abort: {err}");
    assert!(
        err.contains("op keeper: the body kept a handle to array 'a' past the call"),
        "{err}"
    );
}

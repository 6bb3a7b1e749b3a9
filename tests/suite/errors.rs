//! Run-time errors: every one an `Err` from `wp::launch`, never a panic, with a message that
//! names the kernel, the argument, the index and the shape.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::{Error, Fault, FaultKind};

backend_tests!(
    out_of_bounds_read,
    out_of_bounds_write_2d,
    negative_index,
    out_of_bounds_in_parallel_launch,
    out_of_bounds_in_func,
    out_of_bounds_in_loop,
    integer_division_by_zero,
    zero_step,
    zero_launch_dim,
    tid_dims_mismatch,
    same_shape_arrays,
    same_shape_dim,
    usable_after_fault,
    tape_misuse,
    out_of_memory_then_usable,
);

/// The fault of a failed launch, or a panic naming what came instead. The fault must name the
/// launch that raised it (the calling thread's latest: debug mode reports a GPU's fault at the
/// launch, as the CPU does); it is returned without it, and its message without the launch's
/// " (launch #N)", so that the tests compare the rest exactly.
#[track_caller]
fn fault_of(r: wp::Result<()>) -> (Fault, String) {
    match r {
        Err(e @ Error::Fault(_)) => {
            let msg = e.to_string();
            let Error::Fault(mut f) = e else {
                unreachable!()
            };
            let launch = f.launch.take().expect("a fault names its launch");
            assert_eq!(Some(launch), wp::last_launch_id(), "{msg}");
            let msg = msg
                .strip_suffix(&format!(" ({launch})"))
                .unwrap_or_else(|| panic!("`{msg}` ends with ({launch})"))
                .to_string();
            (f, msg)
        }
        other => panic!("expected a kernel fault, got {other:?}"),
    }
}

#[wp::kernel]
fn k_oob_read(a: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = a[i + 1];
}

fn out_of_bounds_read(dev: &wp::Device) {
    let (a, out) = (arr(&[1.0f32, 2.0, 3.0, 4.0], dev), zeros::<f32, 1>(4, dev));
    let (f, msg) = fault_of(wp::launch(k_oob_read, 4, (&a, &out), dev));
    assert_eq!(
        f,
        Fault {
            kernel: "k_oob_read",
            kind: FaultKind::OutOfBounds {
                arg: "a",
                index: vec![4],
                shape: vec![4]
            },
            launch: None,
        }
    );
    assert_eq!(
        msg,
        "kernel `k_oob_read`: index [4] is out of bounds for argument `a` of shape [4]"
    );
}

/// Sums `a[lo..hi]`, stopping before index `stop` (a loop whose accesses are checked once
/// for the whole range on the GPU when the range is inside the array).
#[wp::kernel]
fn k_loop_sum(a: Array<f32>, lo: i32, hi: i32, stop: i32, out: Array<f32>) {
    let i = tid();
    let mut s = 0.0;
    for j in lo..hi {
        if j == stop {
            break;
        }
        s += a[j];
    }
    out[i] = s;
}

/// A loop range that runs past the array faults at the first index outside it, with the
/// loop's earlier iterations done; a loop that leaves before the bad index does not fault.
fn out_of_bounds_in_loop(dev: &wp::Device) {
    let a = arr(&[1.0f32, 2.0, 4.0, 8.0], dev);
    let out = zeros::<f32, 1>(2, dev);
    let sum = |lo: i32, hi: i32, stop: i32| {
        wp::launch(k_loop_sum, 2, (&a, lo, hi, stop, &out), dev)
            .and_then(|_| out.to_vec())
            .map(|v| v[0])
    };
    assert_eq!(sum(0, 4, -1).unwrap(), 15.0);
    assert_eq!(sum(1, 3, -1).unwrap(), 6.0);
    assert_eq!(sum(3, 1, -1).unwrap(), 0.0);
    // The range passes the end, but the loop breaks before it gets there.
    assert_eq!(sum(0, 9, 4).unwrap(), 15.0);
    assert_eq!(sum(2, 9, 3).unwrap(), 4.0);
    for (lo, hi, bad) in [(0, 5, 4i128), (-2, 3, -2), (3, 7, 4)] {
        let (f, _) = fault_of(sum(lo, hi, -1).map(|_| ()));
        assert_eq!(
            f.kind,
            FaultKind::OutOfBounds {
                arg: "a",
                index: vec![bad],
                shape: vec![4]
            },
            "range {lo}..{hi}"
        );
    }
}

#[wp::kernel]
fn k_oob_write(out: Array<f32, 2>) {
    let (i, j) = tid();
    out[(i, j + 1)] = 1.0;
}

fn out_of_bounds_write_2d(dev: &wp::Device) {
    let out = zeros::<f32, 2>((1, 3), dev);
    let (f, msg) = fault_of(wp::launch(k_oob_write, (1, 3), (&out,), dev));
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "out",
            index: vec![0, 3],
            shape: vec![1, 3]
        }
    );
    assert_eq!(
        msg,
        "kernel `k_oob_write`: index [0, 3] is out of bounds for argument `out` of shape [1, 3]"
    );
}

#[wp::kernel]
fn k_negative(a: Array<i32>, out: Array<i32>) {
    let i = tid();
    let j = i as i32 - 1;
    out[i] = a[j];
}

fn negative_index(dev: &wp::Device) {
    let (a, out) = (arr(&[5, 6, 7], dev), zeros::<i32, 1>(3, dev));
    let (f, msg) = fault_of(wp::launch(k_negative, 3, (&a, &out), dev));
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "a",
            index: vec![-1],
            shape: vec![3]
        }
    );
    assert_eq!(
        msg,
        "kernel `k_negative`: index [-1] is out of bounds for argument `a` of shape [3]"
    );
}

#[wp::kernel]
fn k_tail_oob(a: Array<f32>, limit: usize) {
    let i = tid();
    if i + 1 == limit {
        a[i + 7] = 1.0;
    } else {
        a[i] = 2.0;
    }
}

/// One faulting thread among many, in the chunked (parallel) CPU path.
fn out_of_bounds_in_parallel_launch(dev: &wp::Device) {
    let n = 10_000;
    let a = zeros::<f32, 1>(n, dev);
    let (f, _) = fault_of(wp::launch(k_tail_oob, n, (&a, n), dev));
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "a",
            index: vec![n as i128 + 6],
            shape: vec![n]
        }
    );
}

#[wp::func]
fn fetch(a: Array<f32>, i: usize) -> f32 {
    a[i]
}

#[wp::kernel]
fn k_oob_func(a: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = fetch(a, i * 3);
}

/// An index fault inside a func names the kernel's argument the array came from.
fn out_of_bounds_in_func(dev: &wp::Device) {
    let (a, out) = (arr(&[1.0f32, 2.0, 3.0], dev), zeros::<f32, 1>(2, dev));
    let (f, msg) = fault_of(wp::launch(k_oob_func, 2, (&a, &out), dev));
    assert_eq!(
        f.kind,
        FaultKind::OutOfBounds {
            arg: "a",
            index: vec![3],
            shape: vec![3]
        }
    );
    assert_eq!(f.kernel, "k_oob_func");
    assert_eq!(
        msg,
        "kernel `k_oob_func`: index [3] is out of bounds for argument `a` of shape [3]"
    );
}

#[wp::kernel]
fn k_div(a: Array<i32>, b: Array<i32>, out: Array<i32>) {
    let i = tid();
    out[i] = a[i] / b[i];
}

#[wp::kernel]
fn k_rem(a: Array<u8>, b: Array<u8>, out: Array<u8>) {
    let i = tid();
    out[i] = a[i] % b[i];
}

#[wp::kernel]
fn k_div_assign(a: Array<i64>, d: i64) {
    let i = tid();
    a[i] /= d;
}

fn integer_division_by_zero(dev: &wp::Device) {
    let out = zeros::<i32, 1>(3, dev);
    let (f, msg) = fault_of(wp::launch(
        k_div,
        3,
        (&arr(&[1, 2, 3], dev), &arr(&[1, 0, 1], dev), &out),
        dev,
    ));
    assert_eq!(
        f,
        Fault {
            kernel: "k_div",
            kind: FaultKind::DivisionByZero,
            launch: None,
        }
    );
    assert_eq!(msg, "kernel `k_div`: integer division by zero");
    let out8 = zeros::<u8, 1>(2, dev);
    let (f, _) = fault_of(wp::launch(
        k_rem,
        2,
        (&arr(&[1u8, 2], dev), &arr(&[0u8, 3], dev), &out8),
        dev,
    ));
    assert_eq!(
        f,
        Fault {
            kernel: "k_rem",
            kind: FaultKind::DivisionByZero,
            launch: None,
        }
    );
    let a = arr(&[10i64, 20], dev);
    let (f, _) = fault_of(wp::launch(k_div_assign, 2, (&a, 0), dev));
    assert_eq!(f.kind, FaultKind::DivisionByZero);
    // Nonzero divisors work, and i32::MIN / -1 wraps instead of faulting.
    wp::launch(
        k_div,
        2,
        (&arr(&[i32::MIN, 7], dev), &arr(&[-1, 2], dev), &out),
        dev,
    )
    .unwrap();
    assert_eq!(&host(&out)[..2], [i32::MIN, 3]);
}

#[wp::kernel]
fn k_zero_step(k: i32, out: Array<i32>) {
    let mut s = 0;
    for j in (0..10).step_by(k) {
        s += j;
    }
    out[0] = s;
}

fn zero_step(dev: &wp::Device) {
    let out = zeros::<i32, 1>(1, dev);
    let (f, msg) = fault_of(wp::launch(k_zero_step, 1, (0, &out), dev));
    assert_eq!(
        f,
        Fault {
            kernel: "k_zero_step",
            kind: FaultKind::BadStep { step: 0 },
            launch: None,
        }
    );
    assert_eq!(
        msg,
        "kernel `k_zero_step`: step_by(0) in a range loop: the step must be positive"
    );
    wp::launch(k_zero_step, 1, (3, &out), dev).unwrap();
    assert_eq!(host(&out), vec![(0..10).step_by(3).sum::<i32>()]);
}

#[wp::kernel]
fn k_one_d(out: Array<i32>) {
    let i = tid();
    out[i] = 1;
}

#[wp::kernel]
fn k_two_d(out: Array<i32, 2>) {
    let (i, j) = tid();
    out[(i, j)] = 1;
}

fn zero_launch_dim(dev: &wp::Device) {
    let out = zeros::<i32, 1>(4, dev);
    let err = wp::launch(k_one_d, 0, (&out,), dev).unwrap_err();
    assert!(
        matches!(&err, Error::InvalidDim { kernel: "k_one_d", dim, .. } if dim == &vec![0]),
        "{err:?}"
    );
    assert_eq!(
        err.to_string(),
        "kernel `k_one_d`: invalid launch dim [0]: a launch dim of zero (dimension 0)"
    );
    let out2 = zeros::<i32, 2>((2, 2), dev);
    let err = wp::launch(k_two_d, (2, 0), (&out2,), dev).unwrap_err();
    assert!(
        matches!(&err, Error::InvalidDim { kernel: "k_two_d", dim, .. } if dim == &vec![2, 0]),
        "{err:?}"
    );
    assert_eq!(host(&out), vec![0; 4], "nothing ran");
}

fn tid_dims_mismatch(dev: &wp::Device) {
    let out2 = zeros::<i32, 2>((2, 2), dev);
    let err = wp::launch(k_two_d, 4, (&out2,), dev).unwrap_err();
    assert_eq!(
        err,
        Error::TidMismatch {
            kernel: "k_two_d",
            tid_ndim: 2,
            launch_ndim: 1
        }
    );
    assert_eq!(err.to_string(), "kernel `k_two_d`: tid() is destructured into 2 dimension(s) but the kernel was launched with 1 dimension(s)");
    let out = zeros::<i32, 1>(4, dev);
    let err = wp::launch(k_one_d, (2, 2), (&out,), dev).unwrap_err();
    assert_eq!(
        err,
        Error::TidMismatch {
            kernel: "k_one_d",
            tid_ndim: 1,
            launch_ndim: 2
        }
    );
    assert_eq!(host(&out2), vec![0; 4], "nothing ran");
}

#[wp::kernel(same_shape(a, b))]
fn k_same(a: Array<f32>, b: Array<f32>) {
    let i = tid();
    b[i] = a[i];
}

fn same_shape_arrays(dev: &wp::Device) {
    let (a, b) = (arr(&[1.0f32, 2.0, 3.0], dev), zeros::<f32, 1>(4, dev));
    let err = wp::launch(k_same, 3, (&a, &b), dev).unwrap_err();
    assert_eq!(
        err,
        Error::ShapeMismatch {
            kernel: "k_same",
            args: vec!["a".into(), "b".into()],
            shapes: vec![vec![3], vec![4]]
        }
    );
    assert_eq!(err.to_string(), "kernel `k_same`: arguments declared same_shape differ in shape: `a` has shape [3], `b` has shape [4]");
    let b = zeros::<f32, 1>(3, dev);
    wp::launch(k_same, 3, (&a, &b), dev).unwrap();
    assert_eq!(host(&b), vec![1.0, 2.0, 3.0]);
}

#[wp::kernel(same_shape(a, dim))]
fn k_same_dim(a: Array<f32, 2>) {
    let (i, j) = tid();
    a[(i, j)] = 1.0;
}

fn same_shape_dim(dev: &wp::Device) {
    let a = zeros::<f32, 2>((2, 3), dev);
    let err = wp::launch(k_same_dim, (3, 2), (&a,), dev).unwrap_err();
    assert_eq!(
        err,
        Error::ShapeMismatch {
            kernel: "k_same_dim",
            args: vec!["a".into(), "dim".into()],
            shapes: vec![vec![2, 3], vec![3, 2]]
        }
    );
    let err = wp::launch(k_same_dim, (2, 2), (&a,), dev).unwrap_err();
    assert!(matches!(err, Error::ShapeMismatch { .. }), "{err:?}");
    wp::launch(k_same_dim, (2, 3), (&a,), dev).unwrap();
    assert_eq!(host(&a), vec![1.0; 6]);
    // An array on another device (Error::DeviceMismatch) cannot be constructed in this build:
    // arrays can only be allocated on the CPU, and launches run on the array's device.
}

/// A faulted launch leaves the arrays and the runtime usable.
fn usable_after_fault(dev: &wp::Device) {
    let (a, out) = (arr(&[1.0f32, 2.0, 3.0, 4.0], dev), zeros::<f32, 1>(4, dev));
    assert!(wp::launch(k_oob_read, 4, (&a, &out), dev).is_err());
    wp::launch(k_oob_read, 3, (&a, &out), dev).unwrap();
    assert_eq!(&host(&out)[..3], [2.0, 3.0, 4.0]);
}

#[wp::kernel]
fn tape_square(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    y[i] = x[i] * x[i];
}

/// Misusing a tape is an `Err`, never a panic: backward while the tape records, backward from
/// an array without a gradient, and a `record_func` step that launches into (or records on)
/// the tape it is replayed from; the tape still works afterwards.
fn tape_misuse(dev: &wp::Device) {
    let x = wp::Array::from_slice(&[1.0f32, 2.0], dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let y = wp::Array::<f32>::zeros(2, dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let tape = std::rc::Rc::new(wp::Tape::new());
    {
        let _rec = tape.record();
        wp::launch(tape_square, 2, (&x, &y), dev).unwrap();
        let e = tape.backward(&y).unwrap_err().to_string();
        assert!(e.contains("while it is recording"), "{e}");
    }
    let plain = wp::Array::<f32>::zeros(2, dev).unwrap();
    let e = tape.backward(&plain).unwrap_err().to_string();
    assert!(e.contains("no gradient"), "{e}");
    // A step that records on its own tape while that tape runs backward.
    let (t2, x2, y2, d2) = (tape.clone(), x.clone(), y.clone(), dev.clone());
    tape.record_func(move || {
        let _rec = t2.record();
        wp::launch(tape_square, 2, (&x2, &y2), &d2)
    })
    .unwrap();
    let e = tape.backward(&y).unwrap_err().to_string();
    assert!(e.contains("runs backward"), "{e}");
    // Steps that reset or reconfigure their own tape during its backward (these panicked
    // before issue 35): errors, and the tape keeps its steps.
    let other = std::rc::Rc::new(wp::Tape::new());
    {
        let _rec = other.record();
        wp::launch(tape_square, 2, (&x, &y), dev).unwrap();
    }
    let t3 = std::rc::Rc::downgrade(&other);
    other
        .record_func(move || t3.upgrade().expect("alive").reset())
        .unwrap();
    let e = other.backward(&y).unwrap_err().to_string();
    assert!(e.contains("reset on a tape that runs backward"), "{e}");
    let t4 = std::rc::Rc::downgrade(&other);
    other
        .record_func(move || t4.upgrade().expect("alive").set_adstack_bytes(None))
        .unwrap();
    let e = other.backward(&y).unwrap_err().to_string();
    assert!(e.contains("set_adstack_bytes(None) on a tape"), "{e}");
    assert_eq!(other.steps(), vec!["tape_square", "custom", "custom"]);
    other.reset().unwrap();
    assert!(other.is_empty());
    // The tape is not broken: without the bad step, backward works.
    let fresh = wp::Tape::new();
    x.zero_grad().unwrap();
    {
        let _rec = fresh.record();
        wp::launch(tape_square, 2, (&x, &y), dev).unwrap();
    }
    fresh.backward(&y).unwrap();
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![2.0, 4.0]);
    assert_eq!(tape.steps(), vec!["tape_square", "custom"]);
}

/// More bytes than `dev` has: 2^62 on the CPU (4 EiB: past any machine's address space, so
/// the allocator returns null even where the kernel overcommits memory), twice the GPU's
/// memory on a GPU.
fn impossible_bytes(dev: &wp::Device) -> usize {
    match dev.kind() {
        wp::DeviceKind::Cuda { ordinal } => {
            let gpus = warp_cuda::probe().expect("a CUDA device to probe");
            2 * gpus[ordinal].total_memory as usize
        }
        _ => 1 << 62,
    }
}

/// An allocation the device cannot give is `Error::OutOfMemory` naming the device and the
/// size (on the CPU too: an `Err`, not the allocator's abort); on a GPU the driver's error is
/// its source. Arrays made before it are intact, and the device still allocates and
/// launches afterwards.
fn out_of_memory_then_usable(dev: &wp::Device) {
    let before = arr(&[1.0f32, 2.0, 3.0, 4.0], dev);
    let bytes = impossible_bytes(dev);
    let err = wp::Array::<f32>::zeros(bytes / 4, dev).unwrap_err();
    let Error::OutOfMemory {
        device, bytes: b, ..
    } = &err
    else {
        panic!("expected OutOfMemory, got {err:?}");
    };
    assert_eq!((device.as_str(), *b), (dev.alias(), bytes), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("out of memory") && msg.contains(&bytes.to_string()),
        "{msg}"
    );
    let source = std::error::Error::source(&err);
    if dev.is_cuda() {
        let cuda = source
            .and_then(|s| s.downcast_ref::<warp_cuda::CudaError>())
            .unwrap_or_else(|| panic!("the driver's error as the source of {err:?}"));
        assert!(cuda.is_out_of_memory(), "{cuda}");
    } else {
        assert!(source.is_none(), "{source:?}");
    }
    // The device still works: the old array, a new one, a launch.
    let out = zeros::<f32, 1>(4, dev);
    wp::launch(k_oob_read, 3, (&before, &out), dev).unwrap();
    assert_eq!(&host(&out)[..3], [2.0, 3.0, 4.0]);
}

/// A shape whose byte count overflows `usize` is `InvalidArgument` (no allocation is asked
/// for), and one past `isize::MAX` bytes (representable, but more than any Rust allocation
/// may be) is `OutOfMemory`; neither aborts.
#[test]
fn impossible_cpu_allocations_are_errors() {
    let cpu = wp::cpu();
    let e = wp::Array::<f32, 2>::zeros((usize::MAX / 2, 4), &cpu).unwrap_err();
    assert!(
        matches!(&e, Error::InvalidArgument { what } if what.contains("too large")),
        "{e:?}"
    );
    let e = wp::Array::<u8>::zeros(1 << 63, &cpu).unwrap_err();
    assert!(
        matches!(&e, Error::OutOfMemory { device, bytes, .. } if device == "cpu" && *bytes == 1 << 63),
        "{e:?}"
    );
    // The host allocator itself refusing (2^62 bytes is below isize::MAX).
    let e = wp::Array::<f32>::zeros(1 << 60, &cpu).unwrap_err();
    assert!(
        matches!(&e, Error::OutOfMemory { bytes, .. } if *bytes == 1 << 62),
        "{e:?}"
    );
}

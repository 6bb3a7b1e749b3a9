//! Assertions in kernels: `assert!`, `assert_eq!`, `assert_ne!` (always checked), their
//! `debug_` forms (checked in debug mode, `wp::config::set_debug`), and Warp's expectations `expect_eq`, `expect_neq`, `expect_near`.
//! A failed one is a fault naming the kernel, the line, the message and the thread; backward
//! does not check them again.

use crate::{arr, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::{Error, Fault, FaultKind};

backend_tests!(
    assert_holds_and_fails,
    assert_with_message,
    assert_in_func,
    debug_assert_follows_debug_mode,
    expectations_hold,
    expectations_fail,
    backward_does_not_check_again,
    tangent_kernel_does_not_check,
    assert_eq_and_ne,
);

/// The fault of a failed launch (without its launch number), or a panic naming what came
/// instead.
#[track_caller]
fn fault_of(r: wp::Result<()>) -> Fault {
    match r {
        Err(Error::Fault(mut f)) => {
            assert!(f.launch.take().is_some(), "a fault names its launch");
            f
        }
        other => panic!("expected a kernel fault, got {other:?}"),
    }
}

/// The line of the `assert!` in `k_positive` (two lines below this constant's line + 4).
const K_POSITIVE_LINE: u32 = line!() + 4;
#[wp::kernel]
fn k_positive(a: Array<f32>) {
    let i = tid();
    assert!(a[i] > 0.0);
}

fn assert_holds_and_fails(dev: &wp::Device) {
    let a = arr(&[1.0f32, 2.0, 3.0, 4.0], dev);
    wp::launch(k_positive, 4, (&a,), dev).unwrap();
    // Only thread 2 fails, so the fault is its own whatever the threads' order.
    let a = arr(&[1.0f32, 2.0, -3.0, 4.0], dev);
    let f = fault_of(wp::launch(k_positive, 4, (&a,), dev));
    assert_eq!(
        f,
        Fault {
            kernel: "k_positive",
            kind: FaultKind::AssertionFailed {
                line: K_POSITIVE_LINE,
                message: "assertion failed: a[i] > 0.0",
                thread: Some(2),
            },
            launch: None,
        }
    );
    assert_eq!(
        f.to_string(),
        format!(
            "kernel `k_positive`: assertion failed: a[i] > 0.0 (line {K_POSITIVE_LINE}, thread 2)"
        )
    );
}

const K_MESSAGE_LINE: u32 = line!() + 6;
#[rustfmt::skip]
#[wp::kernel]
fn k_message(a: Array<i32, 2>, limit: i32) {
    let (i, j) = tid();
    // Two assertions on one line: the GPU record tells them apart by their column.
    assert!(a[(i, j)] >= 0, "negative {{entry}}"); assert!(a[(i, j)] < limit, "past the limit");
}

fn assert_with_message(dev: &wp::Device) {
    let a = wp::Array::<i32, 2>::from_slice_shape(&[0, 1, 2, 3, 4, 5], (2, 3), dev).unwrap();
    wp::launch(k_message, (2, 3), (&a, 6), dev).unwrap();
    // Only element (1, 2) fails the second assertion (so the fault is its own whatever the
    // threads' order): flat thread index 1 * 3 + 2.
    let f = fault_of(wp::launch(k_message, (2, 3), (&a, 5), dev));
    assert_eq!(
        f.kind,
        FaultKind::AssertionFailed {
            line: K_MESSAGE_LINE,
            message: "past the limit",
            thread: Some(5),
        }
    );
    let a = wp::Array::<i32, 2>::from_slice_shape(&[0, 1, 2, 3, 4, -5], (2, 3), dev).unwrap();
    let f = fault_of(wp::launch(k_message, (2, 3), (&a, 6), dev));
    assert_eq!(
        f.kind,
        FaultKind::AssertionFailed {
            line: K_MESSAGE_LINE,
            message: "negative {entry}",
            thread: Some(5),
        }
    );
}

const CHECKED_LINE: u32 = line!() + 3;
#[wp::func]
fn checked(x: f32) -> f32 {
    assert!(x.is_finite(), "not finite");
    x * 2.0
}

#[wp::kernel]
fn k_func_assert(a: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = checked(a[i]);
}

/// An assertion in a func: the func does not know the thread. The CPU names the func, a GPU
/// the kernel (as for the other faults raised in a func).
fn assert_in_func(dev: &wp::Device) {
    let (a, out) = (arr(&[1.0f32, 2.0, 3.0], dev), zeros::<f32, 1>(3, dev));
    wp::launch(k_func_assert, 3, (&a, &out), dev).unwrap();
    assert_eq!(out.to_vec().unwrap(), vec![2.0, 4.0, 6.0]);
    let a = arr(&[1.0f32, f32::NAN, 3.0], dev);
    let f = fault_of(wp::launch(k_func_assert, 3, (&a, &out), dev));
    let kernel = if dev.is_cpu() {
        "checked"
    } else {
        "k_func_assert"
    };
    assert_eq!(
        f,
        Fault {
            kernel,
            kind: FaultKind::AssertionFailed {
                line: CHECKED_LINE,
                message: "not finite",
                thread: None,
            },
            launch: None,
        }
    );
    assert_eq!(
        f.to_string(),
        format!("kernel `{kernel}`: not finite (line {CHECKED_LINE})")
    );
}

const K_DEBUG_LINE: u32 = line!() + 6;
/// `debug_assert!` whose condition reads past the end of `a` when `far`: computing it is an
/// out-of-bounds fault, so a launch that does not fault did not compute it.
#[wp::kernel]
fn k_debug(a: Array<f32>, far: usize) {
    let i = tid();
    debug_assert!(a[i + far] > 0.0);
}

fn debug_assert_follows_debug_mode(dev: &wp::Device) {
    // Debug mode is process-wide: hold the lock the GPU tests set it under (they hold it
    // already on a GPU).
    let _lock = dev.is_cpu().then(crate::gpu_lock);
    let was = wp::config::debug();
    let a = arr(&[1.0f32, -2.0], dev);
    wp::config::set_debug(false);
    // Off: neither the failing condition nor the out-of-bounds one is computed.
    let off = (
        wp::launch(k_debug, 2, (&a, 0usize), dev),
        wp::launch(k_debug, 2, (&a, 5usize), dev),
        wp::synchronize(),
    );
    wp::config::set_debug(true);
    let on_fail = wp::launch(k_debug, 2, (&a, 0usize), dev);
    let on_oob = wp::launch(k_debug, 1, (&a, 5usize), dev);
    wp::config::set_debug(was);
    off.0.unwrap();
    off.1.unwrap();
    off.2.unwrap();
    assert_eq!(
        fault_of(on_fail).kind,
        FaultKind::AssertionFailed {
            line: K_DEBUG_LINE,
            message: "assertion failed: a[i + far] > 0.0",
            thread: Some(1),
        }
    );
    assert!(matches!(
        fault_of(on_oob).kind,
        FaultKind::OutOfBounds { arg: "a", .. }
    ));
}

#[wp::kernel]
fn k_expect(x: Array<f32>, v: Array<Vec3>, n: Array<i32>, tol: f32) {
    let i = tid();
    expect_eq(n[i], i as i32);
    expect_neq(x[i], 0.0);
    expect_near(x[i], 0.5 * (i as f32 + 1.0), tol);
    expect_near(v[i], vec3(1.0, 2.0, 3.0), tol);
    wp::expect_eq(v[i].x, 1.0);
}

fn expect_inputs(
    dev: &wp::Device,
    x1: f32,
    v1: Vec3,
    n1: i32,
) -> (wp::Array<f32>, wp::Array<Vec3>, wp::Array<i32>) {
    let x = arr(&[0.5f32, x1], dev);
    let v = arr(&[Vec3::new(1.0, 2.0, 3.0), v1], dev);
    let n = arr(&[0i32, n1], dev);
    (x, v, n)
}

/// Tolerances are exact binary fractions and values lie exactly on them or off by more, so
/// no rounding decides a case.
fn expectations_hold(dev: &wp::Device) {
    let (x, v, n) = expect_inputs(dev, 1.25, Vec3::new(1.0, 2.25, 2.75), 1);
    wp::launch(k_expect, 2, (&x, &v, &n, 0.25f32), dev).unwrap();
}

fn expectations_fail(dev: &wp::Device) {
    let line = |message: &'static str, f: Fault| match f.kind {
        FaultKind::AssertionFailed {
            message: m, thread, ..
        } => {
            assert_eq!((m, thread), (message, Some(1)));
        }
        other => panic!("expected an assertion fault, got {other:?}"),
    };
    let cases: [(f32, Vec3, i32, &str); 4] = [
        (
            1.0,
            Vec3::new(1.0, 2.0, 3.0),
            2,
            "expectation failed: expect_eq(n[i], i as i32)",
        ),
        (
            0.0,
            Vec3::new(1.0, 2.0, 3.0),
            1,
            "expectation failed: expect_neq(x[i], 0.0)",
        ),
        (
            1.5,
            Vec3::new(1.0, 2.0, 3.0),
            1,
            "expectation failed: expect_near(x[i], 0.5 * (i as f32 + 1.0), tol)",
        ),
        (
            1.0,
            Vec3::new(1.0, 2.0, 3.5),
            1,
            "expectation failed: expect_near(v[i], vec3(1.0, 2.0, 3.0), tol)",
        ),
    ];
    for (x1, v1, n1, message) in cases {
        let (x, v, n) = expect_inputs(dev, x1, v1, n1);
        line(
            message,
            fault_of(wp::launch(k_expect, 2, (&x, &v, &n, 0.25f32), dev)),
        );
    }
    // A NaN is near nothing.
    let (x, v, n) = expect_inputs(dev, 1.0, Vec3::new(1.0, f32::NAN, 3.0), 1);
    line(
        "expectation failed: expect_near(v[i], vec3(1.0, 2.0, 3.0), tol)",
        fault_of(wp::launch(k_expect, 2, (&x, &v, &n, 0.25f32), dev)),
    );
}

#[wp::kernel]
fn k_square_positive(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    assert!(x[i] > 0.0);
    y[i] = x[i] * x[i];
}

/// The forward launch checks the assertion; backward's replay does not: inputs changed after
/// the forward (which a tape allows, at the user's risk) fail it, yet backward runs.
fn backward_does_not_check_again(dev: &wp::Device) {
    let x = arr(&[1.0f32, 2.0], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_square_positive, 2, (&x, &y), dev).unwrap();
    }
    x.fill(-3.0).unwrap();
    tape.backward(&y).unwrap();
    // d(x^2)/dx at the values backward read: 2 * -3, exact.
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![-6.0, -6.0]);
}

/// Forward mode's tangent kernel drops assertions: `wp::jvp` on inputs that fail the forward
/// kernel's runs, and gives the tangent `2 x v` (exact: one product of small integers).
fn tangent_kernel_does_not_check(dev: &wp::Device) {
    let x = arr(&[-1.0f32, 2.0], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&[3.0f32, -1.0], dev), zeros::<f32, 1>(2, dev));
    assert!(matches!(
        wp::launch(k_square_positive, 2, (&x, &y), dev),
        Err(Error::Fault(_))
    ));
    wp::jvp(k_square_positive, 2, (&x, &y), (&v, &y_dot), dev).unwrap();
    assert_eq!(y_dot.to_vec().unwrap(), vec![-6.0, -4.0]);
}

/// The lines of `k_cmp`'s three assertions.
const K_CMP_LINE: u32 = line!() + 4;
#[wp::kernel]
fn k_cmp(n: Array<i32>, v: Array<Vec3>, same: Array<Vec3>) {
    let i = tid();
    assert_eq!(v[i], same[i]);
    assert_ne!(n[i], 0, "n is zero");
    debug_assert_eq!(n[i] * 2, n[i] + n[i]);
}

/// `assert_eq!`/`assert_ne!` compare as `expect_eq`/`expect_neq` (vectors componentwise) and
/// fail with Rust's message, the operands as written (or the message given).
fn assert_eq_and_ne(dev: &wp::Device) {
    let v = arr(&[Vec3::ONE, Vec3::new(1.0, 2.0, 3.0)], dev);
    let n = arr(&[1i32, 2], dev);
    wp::launch(k_cmp, 2, (&n, &v, &v), dev).unwrap();
    // Only thread 1's vectors differ (in one component).
    let other = arr(&[Vec3::ONE, Vec3::new(1.0, 2.0, 3.5)], dev);
    let f = fault_of(wp::launch(k_cmp, 2, (&n, &v, &other), dev));
    assert_eq!(
        f.kind,
        FaultKind::AssertionFailed {
            line: K_CMP_LINE,
            message: "assertion `left == right` failed: v[i] == same[i]",
            thread: Some(1),
        }
    );
    let zero = arr(&[3i32, 0], dev);
    let f = fault_of(wp::launch(k_cmp, 2, (&zero, &v, &v), dev));
    assert_eq!(
        f.kind,
        FaultKind::AssertionFailed {
            line: K_CMP_LINE + 1,
            message: "n is zero",
            thread: Some(1),
        }
    );
}

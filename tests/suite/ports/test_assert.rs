//! Port of Warp's `warp/tests/test_assert.py`: assertions in kernels and funcs, checked only in
//! debug mode. Warp's `assert` statement is compiled in `wp.config.mode = "debug"` only; its
//! equivalent here is `debug_assert!`, checked while the runtime's debug mode is on
//! (`wp::config::set_debug`). Where Warp aborts the process (CPU) or leaves the CUDA context
//! unusable, and so runs each failing case in a subprocess and matches its stderr, a failed
//! assertion here is a fault the launch returns (`FaultKind::AssertionFailed`), so the ports
//! check the fault's message and thread in-process, and the device stays usable.
//!
//! Ported (Warp test -> here): `TestAssertRelease.test_basic_assert_false_condition`,
//! `test_basic_assert_with_msg`, `test_compound_assert_false_condition` and
//! `test_basic_assert_false_condition_function` -> [`release_mode_does_not_check`] (one launch
//! each, no fault; Warp checks that nothing is printed, here that nothing faults);
//! `TestAssertDebug.test_basic_assert_false_condition` -> [`debug_basic_assert_false`],
//! `test_basic_assert_true_condition` -> [`debug_basic_assert_true`],
//! `test_basic_assert_with_msg` -> [`debug_assert_with_msg`],
//! `test_compound_assert_true_condition` -> [`debug_compound_assert_true`],
//! `test_compound_assert_false_condition` -> [`debug_compound_assert_false`],
//! `test_basic_assert_false_condition_function` -> [`debug_assert_in_function`];
//! `TestAssertModeSwitch.test_switch_to_debug_mode` -> [`mode_switch`].
//!
//! Adapted: Warp's message carries the condition and the message (`assert a[i] == 1, "Array
//! element must be 1"`); here the message is the one given, or `assertion failed: ` and the
//! condition when there is none, as Rust's. Python's `and` is `&&`. Warp's mode switch needs
//! a newly defined kernel (a kernel is compiled for one mode); here the mode is read at each
//! launch, so the port launches the same kernel in both modes, then Warp's second kernel too.
//! Nothing of the file is left out.

use crate::arr;
use warp_lang as wp;
use wp::prelude::*;
use wp::{Error, FaultKind};

backend_tests!(
    release_mode_does_not_check,
    debug_basic_assert_false,
    debug_basic_assert_true,
    debug_assert_with_msg,
    debug_compound_assert_true,
    debug_compound_assert_false,
    debug_assert_in_function,
    mode_switch,
);

#[wp::kernel]
fn expect_ones(a: Array<i32>) {
    let i = tid();
    debug_assert!(a[i] == 1);
}

#[wp::kernel]
fn expect_ones_with_msg(a: Array<i32>) {
    let i = tid();
    debug_assert!(a[i] == 1, "Array element must be 1");
}

#[wp::kernel]
fn expect_ones_compound(a: Array<i32>) {
    let i = tid();
    debug_assert!(a[i] > 0 && a[i] < 2);
}

#[wp::func]
fn expect_ones_function(value: i32) {
    debug_assert!(value == 1, "Array element must be 1");
}

#[wp::kernel]
fn expect_ones_call_function(a: Array<i32>) {
    let i = tid();
    expect_ones_function(a[i]);
}

/// Warp's second kernel of the mode switch, defined after switching to debug mode.
#[wp::kernel]
fn expect_ones_debug(a: Array<i32>) {
    let i = tid();
    debug_assert!(a[i] == 1);
}

/// Runs `f` in the given debug mode and restores the previous one. The mode is process-wide:
/// on the CPU this holds the lock the GPU instances run under (they hold it already).
fn in_mode<R>(dev: &wp::Device, debug: bool, f: impl FnOnce() -> R) -> R {
    let _lock = dev.is_cpu().then(crate::gpu_lock);
    let was = wp::config::debug();
    wp::config::set_debug(debug);
    let r = f();
    wp::config::set_debug(was);
    r
}

/// The message and thread of the assertion fault `r` must be.
#[track_caller]
fn assertion(r: wp::Result<()>) -> (&'static str, Option<usize>) {
    match r {
        Err(Error::Fault(f)) => match f.kind {
            FaultKind::AssertionFailed {
                message, thread, ..
            } => (message, thread),
            other => panic!("expected an assertion fault, got {other:?}"),
        },
        other => panic!("expected an assertion fault, got {other:?}"),
    }
}

fn release_mode_does_not_check(dev: &wp::Device) {
    let zeros = arr(&[0i32], dev);
    let threes = arr(&[3i32], dev);
    let r = in_mode(dev, false, || {
        [
            wp::launch(expect_ones, 1, (&zeros,), dev),
            wp::launch(expect_ones_with_msg, 1, (&zeros,), dev),
            wp::launch(expect_ones_compound, 1, (&threes,), dev),
            wp::launch(expect_ones_call_function, 1, (&threes,), dev),
            wp::synchronize(),
        ]
    });
    for (k, r) in r.into_iter().enumerate() {
        r.unwrap_or_else(|e| panic!("launch {k} in release mode: {e}"));
    }
}

fn debug_basic_assert_false(dev: &wp::Device) {
    let a = arr(&[0i32], dev);
    let r = in_mode(dev, true, || wp::launch(expect_ones, 1, (&a,), dev));
    assert_eq!(assertion(r), ("assertion failed: a[i] == 1", Some(0)));
}

fn debug_basic_assert_true(dev: &wp::Device) {
    let a = arr(&[1i32], dev);
    in_mode(dev, true, || wp::launch(expect_ones, 1, (&a,), dev)).unwrap();
}

fn debug_assert_with_msg(dev: &wp::Device) {
    let a = arr(&[0i32], dev);
    let r = in_mode(dev, true, || {
        wp::launch(expect_ones_with_msg, 1, (&a,), dev)
    });
    assert_eq!(assertion(r), ("Array element must be 1", Some(0)));
}

fn debug_compound_assert_true(dev: &wp::Device) {
    let a = arr(&[1i32], dev);
    in_mode(dev, true, || {
        wp::launch(expect_ones_compound, 1, (&a,), dev)
    })
    .unwrap();
}

fn debug_compound_assert_false(dev: &wp::Device) {
    let a = arr(&[3i32], dev);
    let r = in_mode(dev, true, || {
        wp::launch(expect_ones_compound, 1, (&a,), dev)
    });
    assert_eq!(
        assertion(r),
        ("assertion failed: a[i] > 0 && a[i] < 2", Some(0))
    );
}

fn debug_assert_in_function(dev: &wp::Device) {
    let a = arr(&[3i32], dev);
    let r = in_mode(dev, true, || {
        wp::launch(expect_ones_call_function, 1, (&a,), dev)
    });
    // An assertion in a func names no thread (the func does not know it).
    assert_eq!(assertion(r), ("Array element must be 1", None));
}

fn mode_switch(dev: &wp::Device) {
    let a = arr(&[0i32], dev);
    let (release, debug_same, debug_new) = in_mode(dev, false, || {
        let release = (wp::launch(expect_ones, 1, (&a,), dev), wp::synchronize());
        wp::config::set_debug(true);
        (
            release,
            wp::launch(expect_ones, 1, (&a,), dev),
            wp::launch(expect_ones_debug, 1, (&a,), dev),
        )
    });
    release.0.unwrap();
    release.1.unwrap();
    assert_eq!(assertion(debug_same).0, "assertion failed: a[i] == 1");
    assert_eq!(assertion(debug_new).0, "assertion failed: a[i] == 1");
}

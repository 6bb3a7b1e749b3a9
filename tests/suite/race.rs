//! The write-race check of CPU launches (`wp::config::set_race_check`): two threads of one
//! launch writing one element without an atomic is a `FaultKind::WriteRace` naming the kernel,
//! the argument, the index and both threads; distinct elements and atomics are not races.
//!
//! CPU only: the check does not exist on the GPU (GPU launches ignore the switch). Each test
//! turns the check on for its own thread with `ScopedRaceCheck`, which restores the previous
//! setting when dropped, so the suite's other tests, running in parallel on other threads,
//! are not checked. Tests that run a racy kernel without the check launch fewer threads than
//! `wp::config::cpu_min_chunk()`, so that the launch runs its threads one after another on the
//! calling thread: the "race" is then only in the kernel's logic, never a data race of this
//! process (which would be undefined behaviour).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::config::ScopedRaceCheck;
use wp::prelude::*;
use wp::{Error, FaultKind};

/// More threads than one rayon task runs (`DEFAULT_CPU_MIN_CHUNK` is 4096): the launch is
/// split into chunks that run on the pool in parallel.
const PARALLEL: usize = 100_000;
/// Few enough threads to run serially on the calling thread.
const SERIAL: usize = 64;

#[wp::kernel]
fn k_all_write_zero(out: Array<i32>) {
    let i = tid();
    out[0] = i as i32;
}

#[wp::kernel]
fn k_own_element(out: Array<i32>) {
    let i = tid();
    out[i] = i as i32 * 2;
}

#[wp::kernel]
fn k_atomic_count(out: Array<i32>) {
    atomic_add(out, 0, 1);
}

#[wp::kernel]
fn k_column_zero(out: Array<i32, 2>) {
    let (i, j) = tid();
    out[(0, j)] = i as i32;
}

/// Writes `a[i]`, and `b[i - 1]`: a race only when `a` and `b` are the same array (thread
/// `i` and thread `i - 1` then both write element `i - 1`).
#[wp::kernel]
fn k_shifted(a: Array<i32>, b: Array<i32>) {
    let i = tid();
    a[i] = 1;
    if i > 0 {
        b[i - 1] = 2;
    }
}

/// The race fault of `r`: kernel, argument, index and the two threads.
#[track_caller]
fn write_race(r: wp::Result<()>) -> (&'static str, &'static str, Vec<i128>, (usize, usize)) {
    match r {
        Err(Error::Fault(f)) => match f.kind {
            FaultKind::WriteRace {
                arg,
                index,
                threads,
            } => (f.kernel, arg, index, threads),
            other => panic!("expected a write race, got {other:?}"),
        },
        other => panic!("expected a write race fault, got {other:?}"),
    }
}

/// All threads write element 0: the launch fails naming kernel, argument, index and two
/// different threads of the launch, whether it runs in parallel or serially.
#[test]
fn all_threads_writing_one_element_is_a_race() {
    let dev = wp::cpu();
    let _check = ScopedRaceCheck::new(true);
    for n in [PARALLEL, SERIAL] {
        let out = zeros::<i32, 1>(4, &dev);
        let (kernel, arg, index, (a, b)) =
            write_race(wp::launch(k_all_write_zero, n, (&out,), &dev));
        assert_eq!((kernel, arg, index), ("k_all_write_zero", "out", vec![0]));
        assert!(a != b && a < n && b < n, "threads {a} and {b} of {n}");
        // The second write did not happen: element 0 holds the first writer's value.
        assert_eq!(host(&out)[0], a as i32);
    }
    // The message says it all.
    let out = zeros::<i32, 1>(1, &dev);
    let msg = wp::launch(k_all_write_zero, SERIAL, (&out,), &dev)
        .unwrap_err()
        .to_string();
    for part in [
        "k_all_write_zero",
        "`out`",
        "[0]",
        "threads 0 and 1",
        "data race",
    ] {
        assert!(msg.contains(part), "{part:?} missing from: {msg}");
    }
}

/// Threads writing their own elements (thread-indexed stores, whose per-thread bounds
/// checks the check turns back on) are not a race; nor is one thread writing its element
/// twice, nor a second launch writing the same elements again.
#[test]
fn distinct_elements_are_not_a_race() {
    let dev = wp::cpu();
    let _check = ScopedRaceCheck::new(true);
    let out = zeros::<i32, 1>(PARALLEL, &dev);
    wp::launch(k_own_element, PARALLEL, (&out,), &dev).unwrap();
    wp::launch(k_own_element, PARALLEL, (&out,), &dev).unwrap();
    let want: Vec<i32> = (0..PARALLEL as i32).map(|i| i * 2).collect();
    assert_eq!(host(&out), want);
    // The same array as two arguments, each thread writing only its own element.
    let x = zeros::<i32, 1>(SERIAL, &dev);
    let y = zeros::<i32, 1>(SERIAL, &dev);
    wp::launch(k_shifted, SERIAL, (&x, &y), &dev).unwrap();
}

/// Atomics are not races: every thread adds to element 0.
#[test]
fn atomics_are_not_a_race() {
    let dev = wp::cpu();
    let _check = ScopedRaceCheck::new(true);
    let out = zeros::<i32, 1>(1, &dev);
    wp::launch(k_atomic_count, PARALLEL, (&out,), &dev).unwrap();
    assert_eq!(host(&out), vec![PARALLEL as i32]);
}

/// A 2-D launch: threads (i, j) and (i', j) write element (0, j); the fault gives the
/// element's 2-D index and flat launch indices in the same column.
#[test]
fn two_dimensional_race() {
    let dev = wp::cpu();
    let _check = ScopedRaceCheck::new(true);
    let out = zeros::<i32, 2>((1, 8), &dev);
    let (_, arg, index, (a, b)) = write_race(wp::launch(k_column_zero, (300, 8), (&out,), &dev));
    assert_eq!(arg, "out");
    assert_eq!(index.len(), 2);
    assert_eq!(index[0], 0);
    // Flat index = i * 8 + j: both threads are in column j.
    assert_eq!(a % 8, index[1] as usize);
    assert_eq!(b % 8, index[1] as usize);
    assert_ne!(a, b);
}

/// The check compares addresses, not arguments: the same array passed as `a` and `b` makes
/// thread `i`'s `b[i - 1]` and thread `i - 1`'s `a[i - 1]` one element.
#[test]
fn aliasing_arguments_race() {
    let dev = wp::cpu();
    let _check = ScopedRaceCheck::new(true);
    let x = zeros::<i32, 1>(PARALLEL, &dev);
    let (_, arg, index, (a, b)) = write_race(wp::launch(k_shifted, PARALLEL, (&x, &x), &dev));
    assert!(arg == "a" || arg == "b", "{arg}");
    let k = index[0] as usize;
    // The writers of element k: thread k (through `a`) and thread k + 1 (through `b`).
    let mut t = [a, b];
    t.sort();
    assert_eq!(t, [k, k + 1]);
}

/// Without the check a racy kernel runs and returns `Ok` (here serially, see the module docs:
/// in parallel it would be a data race, undefined behaviour, which is what the check exists
/// to find). The switch is per thread: this thread's setting does not leak into other tests.
#[test]
fn check_off_lets_the_racy_kernel_run() {
    let dev = wp::cpu();
    assert!(SERIAL <= wp::config::cpu_min_chunk());
    let _off = ScopedRaceCheck::new(false);
    let out = zeros::<i32, 1>(1, &dev);
    wp::launch(k_all_write_zero, SERIAL, (&out,), &dev).unwrap();
    // Serial threads: the last one wrote last.
    assert_eq!(host(&out), vec![SERIAL as i32 - 1]);
    {
        let _on = ScopedRaceCheck::new(true);
        assert!(wp::config::race_check());
        write_race(wp::launch(k_all_write_zero, SERIAL, (&out,), &dev));
    }
    // Dropping the inner guard restored this thread's `false`.
    assert!(!wp::config::race_check());
    wp::launch(k_all_write_zero, SERIAL, (&out,), &dev).unwrap();
}

#[wp::kernel]
fn k_square(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    y[i] = x[i] * x[i];
}

#[wp::kernel]
fn k_sum_into(y: Array<f32>, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, 0, y[i]);
}

#[wp::kernel]
fn k_last_wins(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[0] = x[i];
}

/// Adjoint launches are checked too: a race-free backward (atomic accumulation into `x`'s
/// gradient, each thread taking its own element of `y`'s) passes and gives the right
/// gradient; the backward of a racy write (every thread takes `out`'s gradient at 0, a plain
/// read-and-clear) is a race on the gradient of `out`.
#[test]
fn adjoint_launches_are_checked() {
    let dev = wp::cpu();
    let n = 5000;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.5).collect();
    let x = arr(&xs, &dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(n, &dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, &dev).with_grad().unwrap();
    let _check = ScopedRaceCheck::new(true);
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_square, n, (&x, &y), &dev).unwrap();
        wp::launch(k_sum_into, n, (&y, &loss), &dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    // d(sum x^2)/dx = 2x: exact (a power of two times a multiple of 0.5, all below 2^24).
    let want: Vec<f32> = xs.iter().map(|v| 2.0 * v).collect();
    assert_eq!(host(&x.grad().unwrap()), want);

    // The racy forward runs serially without the check; its backward is checked.
    let x = arr(&xs[..SERIAL], &dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(1, &dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _off = ScopedRaceCheck::new(false);
        let _rec = tape.record();
        wp::launch(k_last_wins, SERIAL, (&x, &out), &dev).unwrap();
    }
    let (kernel, arg, index, (a, b)) = write_race(tape.backward(&out));
    assert_eq!((kernel, arg, index), ("k_last_wins", "out", vec![0]));
    assert!(a != b && a < SERIAL && b < SERIAL);
}

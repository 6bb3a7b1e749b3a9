//! Graphs (`wp::capture`, `ScopedCapture`, `Graph`): a replay gives what the same launches
//! give plainly, on every backend (primitives and object builds: `graph_builds.rs`); what a capture cannot record is an `Error::Capture` at
//! the call that tried (and the device works normally afterwards); a graph keeps its arrays;
//! tapes record captured launches, and a backward pass can be captured too. Launch objects
//! (`wp::Launch`) give what plain launches give, and check changed arguments again.

use crate::{arr, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    replay_matches_plain_launches,
    graph_keeps_its_arrays,
    what_a_capture_refuses,
    compiling_inside_a_capture_is_refused,
    captured_forward_and_backward,
    capture_on_a_stream,
    launch_objects_match_plain_launches,
    conditional_loops_agree_with_the_host_loop,
    conditional_branches,
);

/// One substep of a damped oscillator, in two kernels, as a scene's loop would be.
#[wp::kernel]
fn g_velocity(x: Array<f32>, v: Array<f32>, k: f32, dt: f32) {
    let i = tid();
    v[i] = v[i] * 0.999 - k * x[i] * dt;
}

#[wp::kernel]
fn g_position(x: Array<f32>, v: Array<f32>, dt: f32) {
    let i = tid();
    x[i] += v[i] * dt;
}

/// `out[i] += a[i]`.
#[wp::kernel]
fn g_accumulate(a: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] += a[i];
}

/// `loss[0] += x[i]^2` (for the tape test).
#[wp::kernel]
fn g_square_sum(x: Array<f32>, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, 0, x[i] * x[i]);
}

/// Launched only by `compiling_inside_a_capture_is_refused`, so that it is not loaded before.
#[wp::kernel]
fn g_first_in_capture(a: Array<f32>) {
    let i = tid();
    a[i] = a[i] + 1.0;
}

/// `x *= 0.5` (a relaxation step of the conditional-loop tests).
#[wp::kernel]
fn g_halve(x: Array<f32>) {
    let i = tid();
    x[i] = x[i] * 0.5;
}

/// One thread: `flag = x[0] > tol`, and counts the iterations.
#[wp::kernel]
fn g_check(x: Array<f32>, tol: f32, flag: Array<i32>, iterations: Array<i32>) {
    let _i = tid();
    flag[0] = if x[0] > tol { 1 } else { 0 };
    iterations[0] += 1;
}

/// `a[i] += v`.
#[wp::kernel]
fn g_add(a: Array<f32>, v: f32) {
    let i = tid();
    a[i] += v;
}

/// On a GPU nothing compiles inside a capture: the kernels the tests capture, loaded first.
fn load_all(dev: &wp::Device) {
    wp::load(
        &[
            wp::kernel_info(g_velocity),
            wp::kernel_info(g_position),
            wp::kernel_info(g_accumulate),
            wp::kernel_info(g_halve),
            wp::kernel_info(g_check),
            wp::kernel_info(g_add),
        ],
        dev,
    )
    .unwrap();
    wp::load_with_adjoints(&[wp::kernel_info(g_square_sum)], dev).unwrap();
}

fn initial(n: usize) -> Vec<f32> {
    (0..n)
        .map(|i| ((i * 37) % 101) as f32 / 101.0 - 0.5)
        .collect()
}

/// 50 replays of a 10-substep graph (20 launches, a fill and a copy) against the same 500
/// substeps launched plainly: bit for bit (the same kernels on the same device, in the same
/// order, compute the same floats).
fn replay_matches_plain_launches(dev: &wp::Device) {
    load_all(dev);
    let n = 10_000;
    let (k, dt) = (40.0f32, 1e-3f32);
    let run_plain = |x: &wp::Array<f32>, v: &wp::Array<f32>, trace: &wp::Array<f32>| {
        for _ in 0..50 {
            trace.fill(0.0).unwrap();
            for _ in 0..10 {
                wp::launch(g_velocity, n, (v, x, k, dt), dev).unwrap();
                wp::launch(g_position, n, (x, v, dt), dev).unwrap();
            }
            wp::launch(g_accumulate, n, (x, trace), dev).unwrap();
        }
    };
    let (x0, v0) = (arr(&initial(n), dev), zeros::<f32, 1>(n, dev));
    let trace0 = zeros::<f32, 1>(n, dev);
    run_plain(&x0, &v0, &trace0);

    let (x1, v1) = (arr(&initial(n), dev), zeros::<f32, 1>(n, dev));
    let trace1 = zeros::<f32, 1>(n, dev);
    let last_x = zeros::<f32, 1>(n, dev);
    let graph = wp::capture(dev, || {
        trace1.fill(0.0)?;
        for _ in 0..10 {
            wp::launch(g_velocity, n, (&v1, &x1, k, dt), dev)?;
            wp::launch(g_position, n, (&x1, &v1, dt), dev)?;
        }
        wp::launch(g_accumulate, n, (&x1, &trace1), dev)?;
        last_x.copy_from(&x1)
    })
    .unwrap();
    assert_eq!(graph.launches(), 21);
    assert!(graph.node_count() >= 23, "{graph:?}");
    assert_eq!(graph.device(), dev);
    // Nothing ran at capture.
    assert_eq!(x1.to_vec().unwrap(), initial(n));
    for _ in 0..50 {
        graph.launch().unwrap();
    }
    assert_eq!(x1.to_vec().unwrap(), x0.to_vec().unwrap());
    assert_eq!(v1.to_vec().unwrap(), v0.to_vec().unwrap());
    assert_eq!(trace1.to_vec().unwrap(), trace0.to_vec().unwrap());
    assert_eq!(last_x.to_vec().unwrap(), x0.to_vec().unwrap());
}

/// The graph holds the arrays its work uses: dropped by their owner after the capture, a
/// scratch array is still there at every replay (never a replay into freed memory).
fn graph_keeps_its_arrays(dev: &wp::Device) {
    load_all(dev);
    let n = 4096;
    let out = zeros::<f32, 1>(n, dev);
    let graph = {
        let scratch = zeros::<f32, 1>(n, dev);
        let ones = arr(&vec![1.0f32; n], dev);
        wp::capture(dev, || {
            scratch.fill(2.0)?;
            wp::launch(g_accumulate, n, (&ones, &scratch), dev)?;
            wp::launch(g_accumulate, n, (&scratch, &out), dev)
        })
        .unwrap()
        // `scratch` and `ones` are dropped here.
    };
    // Allocations of the same size now must not land on the graph's memory.
    let decoys: Vec<_> = (0..4).map(|_| arr(&vec![-7.0f32; n], dev)).collect();
    for _ in 0..3 {
        graph.launch().unwrap();
    }
    // Exact: small integers.
    assert!(out.to_vec().unwrap().iter().all(|&x| x == 9.0));
    for d in &decoys {
        assert!(d.to_vec().unwrap().iter().all(|&x| x == -7.0));
    }
    drop(graph);
    assert!(out.to_vec().unwrap().iter().all(|&x| x == 9.0));
}

/// Asserts that `r` is an `Error::Capture` whose message contains `needle`.
#[track_caller]
pub(crate) fn assert_refused<T: std::fmt::Debug>(r: wp::Result<T>, needle: &str) {
    match r {
        Err(e @ wp::Error::Capture { .. }) => {
            let s = e.to_string();
            assert!(s.contains(needle), "{s:?} lacks {needle:?}");
        }
        other => panic!("expected Error::Capture ({needle}), got {other:?}"),
    }
}

/// Each operation a graph cannot replay is refused where it is called, the same on every
/// backend; the refusal ends nothing by itself, and after the capture is dropped the device
/// works as before.
fn what_a_capture_refuses(dev: &wp::Device) {
    load_all(dev);
    let n = 256;
    let a = arr(&vec![1.0f32; n], dev);
    let b = zeros::<f32, 1>(n, dev);
    let (m, m2) = (zeros::<f32, 2>((4, 8), dev), zeros::<f32, 2>((4, 8), dev));
    // A condition flag on another device than a GPU capture's.
    let host_flag = wp::Array::<i32>::zeros(1, &wp::cpu()).unwrap();
    let graph = {
        let scope = wp::ScopedCapture::new(dev).unwrap();
        assert_refused(wp::Array::<f32>::zeros(n, dev), "an allocation");
        assert_refused(wp::Array::from_vec(vec![1.0f32; 4], dev), "an allocation");
        assert_refused(a.to_vec(), "read-back");
        assert_refused(a.check_finite("a"), "read-back");
        assert_refused(wp::synchronize(), "synchronisation");
        assert_refused(wp::ScopedCapture::new(dev), "a capture inside a capture");
        assert_refused(wp::capture(dev, || Ok(())), "a capture inside a capture");
        if dev.is_cuda() {
            // Work on another device than the capture's.
            let host = wp::Array::<f32>::zeros(n, &wp::cpu()).unwrap();
            assert_refused(
                wp::launch(g_accumulate, n, (&host, &host), &wp::cpu()),
                &format!("inside a capture on \"{}\"", dev.alias()),
            );
            assert_refused(
                b.copy_from(&host),
                &format!("inside a capture on \"{}\"", dev.alias()),
            );
            assert_refused(
                wp::capture_while(&host_flag, || Ok(())),
                &format!("inside a capture on \"{}\"", dev.alias()),
            );
            assert_refused(
                m.transpose().copy_from(&m2.transpose()),
                "strided or overlapping",
            );
            // Another stream than the capturing one.
            let s = wp::Stream::new(dev).unwrap();
            assert_refused(
                wp::launch_on(g_accumulate, n, (&a, &b), &s),
                "another stream",
            );
        }
        // After all those refusals the capture still records.
        wp::launch(g_accumulate, n, (&a, &b), dev).unwrap();
        scope.finish().unwrap()
    };
    assert_eq!(graph.launches(), 1);
    // A graph launched inside a capture.
    {
        let _scope = wp::ScopedCapture::new(dev).unwrap();
        assert_refused(graph.launch(), "inside a capture");
        // Dropped without finish: the capture is discarded.
    }
    graph.launch().unwrap();
    graph.launch().unwrap();
    assert!(b.to_vec().unwrap().iter().all(|&x| x == 2.0));
    // A failing body discards its capture; plain work goes on.
    let e = wp::capture(dev, || {
        wp::launch(g_accumulate, n, (&a, &b), dev)?;
        a.to_vec().map(drop)
    });
    assert_refused(e, "read-back");
    wp::launch(g_accumulate, n, (&a, &b), dev).unwrap();
    assert!(b.to_vec().unwrap().iter().all(|&x| x == 3.0));
}

/// On a GPU a kernel compiles at its first launch, which cannot happen inside a capture: the
/// launch is refused with the `wp::load` call that fixes it, and after that call the same
/// capture works. On the CPU nothing compiles at run time: the capture records it.
fn compiling_inside_a_capture_is_refused(dev: &wp::Device) {
    let n = 64;
    let a = zeros::<f32, 1>(n, dev);
    let body = || wp::launch(g_first_in_capture, n, (&a,), dev);
    if dev.is_cuda() {
        assert_refused(
            wp::capture(dev, body),
            "wp::load(&[wp::kernel_info(g_first_in_capture)], &device)",
        );
        wp::load(&[wp::kernel_info(g_first_in_capture)], dev).unwrap();
    }
    let graph = wp::capture(dev, body).unwrap();
    graph.launch().unwrap();
    graph.launch().unwrap();
    assert!(a.to_vec().unwrap().iter().all(|&x| x == 2.0));
}

/// A tape recording during a capture records the captured launches; its backward, run
/// plainly after replays or captured into a graph of its own, gives the plain gradient.
fn captured_forward_and_backward(dev: &wp::Device) {
    load_all(dev);
    let xs: Vec<f32> = (0..1000).map(|i| (i % 17) as f32 * 0.25 - 2.0).collect();
    let n = xs.len();
    let x = arr(&xs, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    let forward = {
        let _rec = tape.record();
        wp::capture(dev, || {
            loss.fill(0.0)?;
            wp::launch(g_square_sum, n, (&x, &loss), dev)
        })
        .unwrap()
    };
    assert_eq!(tape.steps(), vec!["g_square_sum"]);
    forward.launch().unwrap();
    tape.backward(&loss).unwrap();
    let want: Vec<f32> = xs.iter().map(|v| 2.0 * v).collect();
    // Exact: 2x of a multiple of 0.25 is exact, and each element's gradient has one term.
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), want);
    // Sum of squares of multiples of 0.25 below 16: exact in f32 in any order (< 2^24/16).
    let sum: f32 = xs.iter().map(|v| v * v).sum();
    assert_eq!(loss.to_vec().unwrap(), vec![sum]);
    // The backward pass as a graph: zero the gradients, seed, adjoints.
    let backward = wp::capture(dev, || {
        tape.zero()?;
        tape.backward(&loss)
    })
    .unwrap();
    assert_eq!(backward.launches(), 1);
    for _ in 0..3 {
        forward.launch().unwrap();
        backward.launch().unwrap();
    }
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), want);
}

/// On a GPU a capture can record a given stream and the graph replay on any stream of its
/// device; on the CPU there are no streams.
fn capture_on_a_stream(dev: &wp::Device) {
    if dev.is_cpu() {
        assert!(wp::Stream::new(dev).is_err());
        return;
    }
    load_all(dev);
    let n = 1 << 16;
    let a = arr(&vec![1.0f32; n], dev);
    let out = zeros::<f32, 1>(n, dev);
    let s = wp::Stream::new(dev).unwrap();
    let graph = wp::capture(&s, || wp::launch(g_accumulate, n, (&a, &out), dev)).unwrap();
    let other = wp::Stream::new(dev).unwrap();
    graph.launch_on(&other).unwrap();
    // Replays on two streams are ordered like launches: by the streams.
    s.wait_stream(&other).unwrap();
    graph.launch_on(&s).unwrap();
    // And a plain replay after both (the default stream waits for the user streams).
    graph.launch().unwrap();
    // Exact: small integers.
    assert!(out.to_vec().unwrap().iter().all(|&x| x == 3.0));
    // The default stream cannot capture.
    let default = wp::get_stream(dev).unwrap();
    assert_refused(wp::ScopedCapture::new(&default), "default stream");
}

/// A launch object bound once and launched again gives what plain launches give; values and
/// arrays changed through `args_mut` are used (and checked again) at the next launch; a
/// recording tape records its launches.
fn launch_objects_match_plain_launches(dev: &wp::Device) {
    load_all(dev);
    let n = 5000;
    let (k, dt) = (40.0f32, 1e-3f32);
    let (x0, v0) = (arr(&initial(n), dev), zeros::<f32, 1>(n, dev));
    let (x1, v1) = (arr(&initial(n), dev), zeros::<f32, 1>(n, dev));
    let mut vel = wp::Launch::new(g_velocity, n, (&v1, &x1, k, dt), dev).unwrap();
    let mut pos = wp::Launch::new(g_position, n, (&x1, &v1, dt), dev).unwrap();
    assert_eq!(vel.dim().as_slice(), &[n]);
    for step in 0..100 {
        let dt_now = if step < 50 { dt } else { 0.5 * dt };
        if step == 50 {
            vel.args_mut().3 = dt_now;
            pos.args_mut().2 = dt_now;
        }
        wp::launch(g_velocity, n, (&v0, &x0, k, dt_now), dev).unwrap();
        wp::launch(g_position, n, (&x0, &v0, dt_now), dev).unwrap();
        vel.launch().unwrap();
        pos.launch().unwrap();
    }
    // Bit for bit: the same kernels with the same values.
    assert_eq!(x1.to_vec().unwrap(), x0.to_vec().unwrap());
    assert_eq!(v1.to_vec().unwrap(), v0.to_vec().unwrap());
    // An array swapped in: used by the next launch.
    let out = zeros::<f32, 1>(n, dev);
    let ones = arr(&vec![1.0f32; n], dev);
    let mut acc = wp::Launch::new(g_accumulate, n, (&ones, &out), dev).unwrap();
    acc.launch().unwrap();
    let other = zeros::<f32, 1>(n, dev);
    acc.args_mut().1 = other.clone();
    acc.launch().unwrap();
    acc.launch().unwrap();
    assert!(out.to_vec().unwrap().iter().all(|&x| x == 1.0));
    assert!(other.to_vec().unwrap().iter().all(|&x| x == 2.0));
    // A dim the arrays do not cover: checked again, an error naming the kernel.
    acc.set_dim(n + 1);
    let e = acc.launch().unwrap_err().to_string();
    assert!(e.contains("g_accumulate"), "{e}");
    // (A faulting launch stops at its fault; threads before it may have run.)
    other.fill(2.0).unwrap();
    acc.set_dim(n);
    // A CPU array bound to a GPU launch: refused at the next launch.
    if dev.is_cuda() {
        acc.args_mut().1 = wp::Array::<f32>::zeros(n, &wp::cpu()).unwrap();
        let e = acc.launch().unwrap_err();
        assert!(matches!(e, wp::Error::DeviceMismatch { .. }), "{e}");
        acc.args_mut().1 = other.clone();
    }
    acc.launch().unwrap();
    assert!(other.to_vec().unwrap().iter().all(|&x| x == 3.0));
    // Recorded on a tape like a plain launch.
    let x = arr(&[1.0f32, -2.0, 3.0], dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    let mut sq = wp::Launch::new(g_square_sum, 3, (&x, &loss), dev).unwrap();
    {
        let _rec = tape.record();
        sq.launch().unwrap();
    }
    tape.backward(&loss).unwrap();
    assert_eq!(loss.to_vec().unwrap(), vec![14.0]);
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![2.0, -4.0, 6.0]);
}

/// `capture_while` halving until the first element is at most 1: the host loop (outside a
/// capture) and the captured loop (a CUDA `while` node on a GPU, a recorded loop on the CPU)
/// run the same iterations and end with the same values, replay after replay; a flag that
/// starts at zero runs no iteration.
fn conditional_loops_agree_with_the_host_loop(dev: &wp::Device) {
    load_all(dev);
    let n = 1000;
    let (x, flag, iterations) = (
        zeros::<f32, 1>(n, dev),
        zeros::<i32, 1>(1, dev),
        zeros::<i32, 1>(1, dev),
    );
    let body = || -> wp::Result<()> {
        wp::launch(g_halve, n, (&x,), dev)?;
        wp::launch(g_check, 1, (&x, 1.0f32, &flag, &iterations), dev)
    };
    let reset = |start: f32, go: i32| -> wp::Result<()> {
        x.fill(start)?;
        flag.fill(go)?;
        iterations.fill(0)
    };
    // The host loop: 1000 / 2^10 < 1 after 10 halvings (exact powers of two).
    reset(1000.0, 1).unwrap();
    wp::capture_while(&flag, body).unwrap();
    assert_eq!(iterations.to_vec().unwrap(), vec![10]);
    assert!(x.to_vec().unwrap().iter().all(|&v| v == 1000.0 / 1024.0));
    // Captured, the reset inside the graph.
    let graph = wp::capture(dev, || {
        reset(1000.0, 1)?;
        wp::capture_while(&flag, body)
    })
    .unwrap();
    for _ in 0..3 {
        graph.launch().unwrap();
        assert_eq!(iterations.to_vec().unwrap(), vec![10]);
        assert!(x.to_vec().unwrap().iter().all(|&v| v == 1000.0 / 1024.0));
    }
    // The flag decides at run time: a graph whose reset leaves it at zero, and one whose
    // start value needs another count of iterations (set outside the graph).
    let no_loop = wp::capture(dev, || {
        reset(1000.0, 0)?;
        wp::capture_while(&flag, body)
    })
    .unwrap();
    no_loop.launch().unwrap();
    assert_eq!(iterations.to_vec().unwrap(), vec![0]);
    assert!(x.to_vec().unwrap().iter().all(|&v| v == 1000.0));
    let looping = wp::capture(dev, || wp::capture_while(&flag, body)).unwrap();
    reset(64.0, 1).unwrap();
    looping.launch().unwrap();
    // 64 / 2^6 = 1 is not > 1: six iterations.
    assert_eq!(iterations.to_vec().unwrap(), vec![6]);
    assert!(x.to_vec().unwrap().iter().all(|&v| v == 1.0));
    // An empty condition array is refused.
    let empty = zeros::<i32, 1>(4, dev).view(2..2).unwrap();
    let e = wp::capture_while(&empty, || Ok(()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("empty"), "{e}");
}

/// `capture_if` takes the branch the flag names when the graph runs, with one read of the
/// flag for both branches (the true branch clearing it does not run the false one too).
fn conditional_branches(dev: &wp::Device) {
    load_all(dev);
    let n = 64;
    let (a, flag) = (zeros::<f32, 1>(n, dev), zeros::<i32, 1>(1, dev));
    let graph = wp::capture(dev, || {
        wp::capture_if(
            &flag,
            || {
                wp::launch(g_add, n, (&a, 1.0f32), dev)?;
                flag.fill(0)
            },
            || wp::launch(g_add, n, (&a, 100.0f32), dev),
        )
    })
    .unwrap();
    flag.fill(1).unwrap();
    graph.launch().unwrap();
    assert!(a.to_vec().unwrap().iter().all(|&v| v == 1.0));
    assert_eq!(flag.to_vec().unwrap(), vec![0]);
    graph.launch().unwrap();
    assert!(a.to_vec().unwrap().iter().all(|&v| v == 101.0));
    // Outside a capture the same call branches on the host.
    flag.fill(1).unwrap();
    wp::capture_if(
        &flag,
        || wp::launch(g_add, n, (&a, 1.0f32), dev),
        || wp::launch(g_add, n, (&a, 100.0f32), dev),
    )
    .unwrap();
    assert!(a.to_vec().unwrap().iter().all(|&v| v == 102.0));
}

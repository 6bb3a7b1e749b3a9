//! Streams and events: ordering between streams, `ScopedStream`, timing, faults reported at a
//! stream's synchronisation, and arrays dropped while a kernel on another stream still reads
//! them. On the CPU (no streams) the same tests check that asking for one is a clear error.

use crate::{arr, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    streams_are_ordered_by_events,
    scoped_stream_is_current,
    arrays_outlive_kernels_of_other_streams,
    stream_synchronize_reports_faults,
    pinned_copies,
);

/// Pinned memory: upload, a kernel and a download all queued on a user stream; the result
/// is read through the pinned vector (which waits). Mismatched arrays are errors.
fn pinned_copies(dev: &wp::Device) {
    if dev.is_cpu() {
        let e = wp::PinnedVec::<f32>::zeros(4, dev).unwrap_err().to_string();
        assert!(e.contains("pairs with a CUDA device"), "{e}");
        return;
    }
    wp::config::set_debug(false);
    let n = 1 << 18;
    let host: Vec<f32> = (0..n).map(|i| i as f32).collect();
    let mut up = wp::PinnedVec::from_slice(&host, dev).unwrap();
    let mut down = wp::PinnedVec::<f32>::zeros(n, dev).unwrap();
    let a = zeros::<f32, 1>(n, dev);
    let s = wp::Stream::new(dev).unwrap();
    {
        let _scope = wp::ScopedStream::new(&s).unwrap();
        a.copy_from_pinned_async(&mut up).unwrap();
        wp::launch(k_scale, n, (&a, 2.0), dev).unwrap();
        a.copy_to_pinned_async(&mut down).unwrap();
    }
    // Exact: i * 2 for i < 2^18 is exact in f32.
    assert!(down
        .as_slice()
        .iter()
        .enumerate()
        .all(|(i, &x)| x == 2.0 * i as f32));
    assert_eq!(up.as_slice(), &host[..]);
    // Wrong length, strided array, CPU array: errors naming the problem.
    let short = zeros::<f32, 1>(n - 1, dev);
    let e = short
        .copy_from_pinned_async(&mut up)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains(&format!("contiguous array of {n} elements")),
        "{e}"
    );
    let cpu = wp::Array::<f32>::zeros(n, &wp::cpu()).unwrap();
    assert!(cpu.copy_to_pinned_async(&mut down).is_err());
    let m = zeros::<f32, 2>((2, 3), dev).transpose();
    let mut six = wp::PinnedVec::<f32>::zeros(6, dev).unwrap();
    let e = m.copy_to_pinned_async(&mut six).unwrap_err().to_string();
    assert!(e.contains("strided"), "{e}");
    wp::config::set_debug(true);
}

#[wp::kernel]
fn k_add(a: Array<f32>, v: f32) {
    let i = tid();
    a[i] += v;
}

#[wp::kernel]
fn k_scale(a: Array<f32>, s: f32) {
    let i = tid();
    a[i] *= s;
}

/// Streams exist on GPUs only: on the CPU, creating one is an error naming the device.
fn no_streams_on_the_cpu(dev: &wp::Device) -> bool {
    if dev.is_cuda() {
        return false;
    }
    let e = wp::Stream::new(dev).unwrap_err().to_string();
    assert!(
        e.contains("needs a CUDA device") && e.contains("\"cpu\""),
        "{e}"
    );
    assert!(wp::get_stream(dev).is_err());
    assert!(wp::Event::new(dev, true).is_err());
    true
}

/// Work on one stream, an event, another stream waiting for it: the result is the ordered
/// one (adds then scale), and the event pair times the work.
fn streams_are_ordered_by_events(dev: &wp::Device) {
    if no_streams_on_the_cpu(dev) {
        return;
    }
    wp::config::set_debug(false);
    let n = 1 << 20;
    let a = zeros::<f32, 1>(n, dev);
    let (s1, s2) = (wp::Stream::new(dev).unwrap(), wp::Stream::new(dev).unwrap());
    assert!(!s1.is_default() && wp::get_stream(dev).unwrap().is_default());
    let start = s1.record_event().unwrap();
    for _ in 0..10 {
        wp::launch_on(k_add, n, (&a, 1.0), &s1).unwrap();
    }
    let done = s1.record_event().unwrap();
    s2.wait_event(&done).unwrap();
    wp::launch_on(k_scale, n, (&a, 2.0), &s2).unwrap();
    s2.synchronize().unwrap();
    assert!(done.is_complete().unwrap());
    let ms = start.elapsed_ms(&done).unwrap();
    assert!(ms >= 0.0 && ms.is_finite(), "{ms}");
    // Exact: small integers in f32.
    assert!(a.to_vec().unwrap().iter().all(|&x| x == 20.0));
    // wait_stream orders the same way without an explicit event.
    wp::launch_on(k_add, n, (&a, 1.0), &s1).unwrap();
    s2.wait_stream(&s1).unwrap();
    wp::launch_on(k_scale, n, (&a, 0.5), &s2).unwrap();
    assert!(a.to_vec().unwrap().iter().all(|&x| x == 10.5));
    wp::config::set_debug(true);
}

/// Inside a `ScopedStream`, plain launches go to its stream; scopes nest and restore.
fn scoped_stream_is_current(dev: &wp::Device) {
    if no_streams_on_the_cpu(dev) {
        return;
    }
    wp::config::set_debug(false);
    let a = arr(&[1.0f32, 2.0, 3.0], dev);
    let (s1, s2) = (wp::Stream::new(dev).unwrap(), wp::Stream::new(dev).unwrap());
    let current = || wp::get_stream(dev).unwrap();
    {
        let _outer = wp::ScopedStream::new(&s1).unwrap();
        assert!(current().cuda_stream().is(s1.cuda_stream()));
        wp::launch(k_add, 3, (&a, 1.0), dev).unwrap();
        {
            let _inner = wp::ScopedStream::new(&s2).unwrap();
            assert!(current().cuda_stream().is(s2.cuda_stream()));
            // Entering the inner scope made s2 wait for s1: the add comes first.
            wp::launch(k_scale, 3, (&a, 3.0), dev).unwrap();
        }
        assert!(current().cuda_stream().is(s1.cuda_stream()));
    }
    assert!(current().is_default());
    assert_eq!(a.to_vec().unwrap(), vec![6.0, 9.0, 12.0]);
    wp::config::set_debug(true);
}

/// A slow kernel reads `src` on a user stream; `src` is dropped right after the launch and
/// new arrays are allocated and filled. Its memory must not be reused before the kernel is
/// done: the result is exactly the sum over the original values.
#[wp::kernel]
fn k_slow_sum(src: Array<f32>, out: Array<f32>, reps: i32) {
    let i = tid();
    let mut s = 0.0;
    for _r in 0..reps {
        s += src[i];
    }
    out[i] = s;
}

fn arrays_outlive_kernels_of_other_streams(dev: &wp::Device) {
    if no_streams_on_the_cpu(dev) {
        return;
    }
    wp::config::set_debug(false);
    let n = 1 << 20;
    let reps = 2000;
    let s = wp::Stream::new(dev).unwrap();
    let out = zeros::<f32, 1>(n, dev);
    for round in 0..3 {
        let src = wp::Array::full(n, 0.25f32, dev).unwrap();
        wp::launch_on(k_slow_sum, n, (&src, &out, reps), &s).unwrap();
        drop(src);
        // Likely to land in the freed block if the free were not ordered after the kernel.
        let junk: Vec<wp::Array<f32>> = (0..4)
            .map(|_| wp::Array::full(n, 1e30f32, dev).unwrap())
            .collect();
        // 0.25 added 2000 times is exact in f32 (500 = 2000 quarters, all partial sums exact).
        let v = out.to_vec().unwrap();
        assert!(
            v.iter().all(|&x| x == 500.0),
            "round {round}: {:?}",
            &v[..4]
        );
        drop(junk);
    }
    wp::config::set_debug(true);
}

#[wp::kernel]
fn k_oob(a: Array<f32>) {
    let i = tid();
    a[i + 1] = 1.0;
}

/// Without debug mode a fault on a user stream is reported by that stream's synchronize.
fn stream_synchronize_reports_faults(dev: &wp::Device) {
    if no_streams_on_the_cpu(dev) {
        return;
    }
    wp::config::set_debug(false);
    let a = zeros::<f32, 1>(8, dev);
    let s = wp::Stream::new(dev).unwrap();
    wp::launch_on(k_oob, 8, (&a,), &s).unwrap();
    let e = s.synchronize().unwrap_err();
    assert!(
        e.to_string()
            .contains("index [8] is out of bounds for argument `a` of shape [8]"),
        "{e}"
    );
    // Reported once: the device is usable again.
    s.synchronize().unwrap();
    wp::synchronize().unwrap();
    wp::config::set_debug(true);
}

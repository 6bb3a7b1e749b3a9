//! `#[kernel(deterministic)]`: float accumulations give the same bits on every run, equal to
//! the documented order (each element's value before the launch, then its records in
//! ascending flat thread index, then program order within a thread), computed here on the
//! host with the same additions. Comparisons are exact: the order is the point, and the CPU
//! and a GPU add the same records in the same order with the same IEEE operations, so
//! [`cpu_and_gpu_agree_bit_for_bit`] and the gradient tests compare backends bit for bit.
//!
//! On a GPU the records are ordered by two radix sorts and added after the launch
//! (warp-runtime's cuda/deterministic.rs); [`ordinary_may_differ_deterministic_does_not`]
//! shows what that buys over plain atomics. [`nvrtc_compiles_the_deterministic_units`]
//! checks the generated CUDA of every kernel here without a GPU.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    contended_sum_same_bits_every_run,
    old_value_then_thread_then_program_order,
    vectors_f64_and_f16,
    record_limit_is_a_fault,
    loop_default_limit,
    funcs_with_float_atomics_refused,
    integer_and_extreme_atomics_unchanged,
    gradients_through_a_tape,
    shared_read_gradients_in_order,
    stored_arrays_keep_their_gradients,
    struct_gradients_in_order,
    adjoint_record_limit_is_a_fault,
    captured_and_replayed,
    tangents_in_order,
    cpu_and_gpu_agree_bit_for_bit,
    ordinary_may_differ_deterministic_does_not,
);

/// Whether the launch `r` ran: every deterministic launch runs on every backend now; an
/// error fails the test, naming the device.
fn ran(dev: &wp::Device, r: wp::Result<()>) -> bool {
    match r {
        Ok(()) => true,
        Err(e) => panic!("launch on {dev}: {e}"),
    }
}

/// Values of many magnitudes and both signs, so that the sum's rounding depends on the order.
fn values(n: usize) -> Vec<f32> {
    let mut s = 0x2545_f491_u32;
    (0..n)
        .map(|i| {
            s ^= s << 13;
            s ^= s >> 17;
            s ^= s << 5;
            let m = (s >> 8) as f32 / (1u32 << 24) as f32 - 0.5;
            m * [1e-3f32, 1.0, 1e3, 1e6][i % 7 % 4]
        })
        .collect()
}

#[wp::kernel(deterministic)]
fn k_bins(x: Array<f32>, bins: Array<f32>) {
    let i = tid();
    atomic_add(bins, i % 4, x[i]);
}

/// The documented order on the host: each bin from its old value, threads ascending.
fn bins_reference(old: &[f32], x: &[f32]) -> Vec<f32> {
    let mut acc = old.to_vec();
    for (i, v) in x.iter().enumerate() {
        acc[i % 4] += v;
    }
    acc
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// 300,000 threads (many CPU chunks) into 4 bins: the same bits over repeated runs, equal to
/// the host's sum in the documented order.
fn contended_sum_same_bits_every_run(dev: &wp::Device) {
    let n = 300_000;
    let xs = values(n);
    let x = arr(&xs, dev);
    let want = bits(&bins_reference(&[0.0; 4], &xs));
    for _ in 0..5 {
        let bins = zeros::<f32, 1>(4, dev);
        if !ran(dev, wp::launch(k_bins, n, (&x, &bins), dev)) {
            return;
        }
        assert_eq!(bits(&host(&bins)), want);
    }
}

#[wp::kernel(deterministic)]
fn k_add_sub(x: Array<f32>, y: Array<f32>, out: Array<f32>) {
    let i = tid();
    atomic_add(out, i % 3, x[i]);
    atomic_sub(out, i % 3, y[i]);
    atomic_add(out, (i + 1) % 3, y[i]);
}

/// An element starts from its value before the launch, and one thread's records keep their
/// program order: large old values and small records make any other order round differently.
fn old_value_then_thread_then_program_order(dev: &wp::Device) {
    let n = 20_000;
    let xs = values(n);
    let ys: Vec<f32> = values(n + 3)[3..].iter().map(|v| v * 0.37).collect();
    let old = [1.0e7f32, -3.5e6, 0.25];
    let (x, y, out) = (arr(&xs, dev), arr(&ys, dev), arr(&old, dev));
    if !ran(dev, wp::launch(k_add_sub, n, (&x, &y, &out), dev)) {
        return;
    }
    let mut want = old.to_vec();
    for i in 0..n {
        want[i % 3] += xs[i];
        want[i % 3] -= ys[i];
        want[(i + 1) % 3] += ys[i];
    }
    assert_eq!(bits(&host(&out)), bits(&want));
}

#[wp::kernel(deterministic)]
fn k_kinds(v: Array<Vec3>, d: Array<f64>, h: Array<f16>, x: Array<f32>) {
    let i = tid();
    let s = x[i];
    atomic_add(v, i % 2, Vec3::new(s, -s, s * 0.5));
    atomic_sub(d, 0, s as f64 * 1.0e-3);
    atomic_add(h, i % 2, (s * 1.0e-6) as f16);
}

/// Float vectors (componentwise), f64 and f16 take the same order.
fn vectors_f64_and_f16(dev: &wp::Device) {
    let n = 9_000;
    let xs = values(n);
    let v = zeros::<Vec3, 1>(2, dev);
    let d = arr(&[2.0f64], dev);
    let h = zeros::<f16, 1>(2, dev);
    let x = arr(&xs, dev);
    if !ran(dev, wp::launch(k_kinds, n, (&v, &d, &h, &x), dev)) {
        return;
    }
    let mut wv = [Vec3::ZERO; 2];
    let mut wd = 2.0f64;
    let mut wh = [f16::ZERO; 2];
    for (i, &s) in xs.iter().enumerate() {
        wv[i % 2] += Vec3::new(s, -s, s * 0.5);
        wd -= s as f64 * 1.0e-3;
        wh[i % 2] += f16::from_f32(s * 1.0e-6);
    }
    let gv = host(&v);
    for k in 0..2 {
        assert_eq!(
            gv[k].to_array().map(f32::to_bits),
            wv[k].to_array().map(f32::to_bits)
        );
    }
    assert_eq!(host(&d)[0].to_bits(), wd.to_bits());
    assert_eq!(
        host(&h).iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        wh.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
}

#[wp::kernel(deterministic(max_records = 4))]
fn k_limited(out: Array<f32>, n: i32) {
    let _i = tid();
    for _k in 0..n {
        atomic_add(out, 0, 1.0);
    }
}

/// A thread that accumulates more often than its limit faults, naming the thread and the
/// limit; at the limit the launch runs.
fn record_limit_is_a_fault(dev: &wp::Device) {
    let out = zeros::<f32, 1>(1, dev);
    if !ran(dev, wp::launch(k_limited, 3, (&out, 4), dev)) {
        return;
    }
    assert_eq!(host(&out), [12.0]);
    let err = wp::launch(k_limited, 3, (&out, 5), dev)
        .and_then(|()| wp::synchronize())
        .expect_err("5 records against a limit of 4");
    match err {
        wp::Error::Fault(f) => match f.kind {
            wp::FaultKind::DeterministicRecords { thread, limit } => {
                assert!(thread < 3, "thread {thread}");
                assert_eq!(limit, 4);
            }
            other => panic!("wrong fault: {other:?}"),
        },
        other => panic!("not a fault: {other}"),
    }
}

#[wp::kernel(deterministic)]
fn k_looped(out: Array<f64>, n: i32) {
    for _k in 0..n {
        atomic_add(out, tid(), 0.5);
    }
}

/// An accumulation in a loop without `max_records` has the documented default limit (64).
fn loop_default_limit(dev: &wp::Device) {
    let out = zeros::<f64, 1>(2, dev);
    if !ran(dev, wp::launch(k_looped, 2, (&out, 64), dev)) {
        return;
    }
    assert_eq!(host(&out), [32.0, 32.0]);
    let err = wp::launch(k_looped, 2, (&out, 65), dev)
        .and_then(|()| wp::synchronize())
        .expect_err("65 records against the default limit");
    assert!(err.to_string().contains("more than 64"), "{err}");
}

#[wp::func]
fn f_accumulate(a: Array<f32>, i: usize, v: f32) {
    atomic_add(a, i, v);
}

#[wp::kernel(deterministic)]
fn k_calls_accumulating_func(a: Array<f32>) {
    f_accumulate(a, 0, 1.0);
}

/// A func's accumulations cannot be recorded: the launch is refused, naming the func, on
/// every backend.
fn funcs_with_float_atomics_refused(dev: &wp::Device) {
    let a = zeros::<f32, 1>(1, dev);
    let err = wp::launch(k_calls_accumulating_func, 8, (&a,), dev).expect_err("refused");
    assert!(
        matches!(&err, wp::Error::Deterministic { why, .. } if why.contains("f_accumulate")),
        "{err}"
    );
    assert_eq!(host(&a), [0.0]);
}

#[wp::kernel(deterministic)]
fn k_mixed(x: Array<f32>, count: Array<i32>, slots: Array<i32>, hi: Array<f32>) {
    let i = tid();
    // An integer counter's old value may be used (its final value is exact in any order).
    let s = atomic_add(count, 0, 1);
    slots[i] = s;
    atomic_max(hi, 0, x[i]);
}

/// Integer atomics and float min/max are left as they are: the counter counts, every slot is
/// handed out once, the maximum is the maximum.
fn integer_and_extreme_atomics_unchanged(dev: &wp::Device) {
    let n = 10_000;
    let xs = values(n);
    let x = arr(&xs, dev);
    let count = zeros::<i32, 1>(1, dev);
    let slots = zeros::<i32, 1>(n, dev);
    let hi = arr(&[f32::MIN], dev);
    if !ran(dev, wp::launch(k_mixed, n, (&x, &count, &slots, &hi), dev)) {
        return;
    }
    assert_eq!(host(&count), [n as i32]);
    let mut s = host(&slots);
    s.sort_unstable();
    assert_eq!(s, (0..n as i32).collect::<Vec<_>>());
    let max = xs.iter().copied().fold(f32::MIN, f32::max);
    assert_eq!(host(&hi), [max]);
}

#[wp::kernel(deterministic)]
fn k_square_bins(x: Array<f32>, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, i % 3, x[i] * x[i]);
}

/// Backward through a deterministic kernel: the adjoint of a recorded `atomic_add` reads its
/// element's gradient (no atomic), so `x.grad[i] = 2 x[i] g[i % 3]`, exact for these values.
fn gradients_through_a_tape(dev: &wp::Device) {
    let n = 5_000;
    let xs: Vec<f32> = (0..n).map(|i| (i % 17) as f32 * 0.25 - 2.0).collect();
    let x = arr(&xs, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        if !ran(dev, wp::launch(k_square_bins, n, (&x, &loss), dev)) {
            return;
        }
    }
    let mut want = [0.0f32; 3];
    for (i, v) in xs.iter().enumerate() {
        want[i % 3] += v * v;
    }
    assert_eq!(bits(&host(&loss)), bits(&want));
    let seed = [1.0f32, 2.0, 0.5];
    loss.grad().unwrap().copy_from(&arr(&seed, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    let g = host(&x.grad().unwrap());
    for (i, v) in xs.iter().enumerate() {
        assert_eq!(g[i], 2.0 * v * seed[i % 3], "x.grad[{i}]");
    }
}

#[wp::kernel(deterministic)]
fn k_gather(x: Array<f32>, w: Array<f32>, out: Array<f32>) {
    let i = tid();
    atomic_add(out, i, x[i % 7] * w[i]);
}

/// Backward through reads that many threads share: `x.grad[j]` gathers `w[i] g[i]` from every
/// thread `i` with `i % 7 == j`, recorded and added in ascending `i` (values of many
/// magnitudes, so another order rounds differently), the same bits on every run.
fn shared_read_gradients_in_order(dev: &wp::Device) {
    let n = 60_000;
    let ws = values(n);
    let gs: Vec<f32> = values(n + 11)[11..].iter().map(|v| v + 0.125).collect();
    let x = arr(&[0.5f32, -1.0, 2.0, 3.0, -4.0, 0.25, 1.5], dev)
        .with_grad()
        .unwrap();
    let w = arr(&ws, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(n, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        if !ran(dev, wp::launch(k_gather, n, (&x, &w, &out), dev)) {
            return;
        }
    }
    let mut want = [0.0f32; 7];
    for i in 0..n {
        want[i % 7] += ws[i] * gs[i];
    }
    for _ in 0..3 {
        x.zero_grad().unwrap();
        out.grad().unwrap().copy_from(&arr(&gs, dev)).unwrap();
        tape.backward_from_grads().unwrap();
        assert_eq!(bits(&host(&x.grad().unwrap())), bits(&want));
    }
}

#[wp::kernel(deterministic)]
fn k_store_then_read(x: Array<f32>, y: Array<f32>, loss: Array<f32>) {
    let i = tid();
    y[i] = x[i] * 2.0;
    atomic_add(loss, 0, y[i] * y[i]);
}

/// An array the kernel stores into keeps its gradients immediate (the store's adjoint takes
/// the gradient its later reads accumulated): `x.grad = 8 x`, exact for these values.
fn stored_arrays_keep_their_gradients(dev: &wp::Device) {
    let xs: Vec<f32> = (0..1000).map(|i| (i % 13) as f32 * 0.5 - 3.0).collect();
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(xs.len(), dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        if !ran(
            dev,
            wp::launch(k_store_then_read, xs.len(), (&x, &y, &loss), dev),
        ) {
            return;
        }
    }
    tape.backward(&loss).unwrap();
    let g = host(&x.grad().unwrap());
    for (i, v) in xs.iter().enumerate() {
        assert_eq!(g[i], 8.0 * v, "x.grad[{i}]");
    }
}

/// A deterministic launch captured into a graph runs the same path at every replay (on a
/// GPU, refused for now with `Error::Deterministic`: its record buffer may have to grow
/// inside the capture).
fn captured_and_replayed(dev: &wp::Device) {
    let n = 50_000;
    let xs = values(n);
    let x = arr(&xs, dev);
    let bins = zeros::<f32, 1>(4, dev);
    if dev.is_cuda() {
        let r = wp::capture(dev, || wp::launch(k_bins, n, (&x, &bins), dev)).map(|_| ());
        match r {
            Err(wp::Error::Deterministic { why, .. }) => assert!(why.contains("graph"), "{why}"),
            other => panic!("a deterministic launch captured on {dev}: {other:?}"),
        }
        assert_eq!(host(&bins), [0.0; 4]);
        return;
    }
    let graph = wp::capture(dev, || wp::launch(k_bins, n, (&x, &bins), dev)).unwrap();
    let once = bins_reference(&[0.0; 4], &xs);
    for replays in 1..=3 {
        graph.launch().unwrap();
        wp::synchronize().unwrap();
        if replays == 1 {
            assert_eq!(bits(&host(&bins)), bits(&once));
        }
    }
    // Three replays: three more passes over the records, each in the same order.
    let mut acc = [0.0f32; 4];
    for _ in 0..3 {
        let next = bins_reference(&acc, &xs);
        acc.copy_from_slice(&next);
    }
    assert_eq!(bits(&host(&bins)), bits(&acc));
}

/// Forward mode: the tangent kernel of a deterministic kernel records the tangents' adds too,
/// in the same order.
fn tangents_in_order(dev: &wp::Device) {
    let n = 40_000;
    let xs = values(n);
    let vs: Vec<f32> = values(n + 5)[5..].to_vec();
    let x = arr(&xs, dev);
    let bins = zeros::<f32, 1>(4, dev);
    let (v, bins_dot) = (arr(&vs, dev), zeros::<f32, 1>(4, dev));
    if !ran(dev, wp::jvp(k_bins, n, (&x, &bins), (&v, &bins_dot), dev)) {
        return;
    }
    assert_eq!(bits(&host(&bins)), bits(&bins_reference(&[0.0; 4], &xs)));
    assert_eq!(
        bits(&host(&bins_dot)),
        bits(&bins_reference(&[0.0; 4], &vs))
    );
}

/// The same launches on the CPU and on `dev` give the same bits (on the CPU instance: the
/// CPU against itself, a second run): an f32 contended sum with old values, the Vec3, f64
/// and f16 kernel, and a backward pass's shared-read gradients.
fn cpu_and_gpu_agree_bit_for_bit(dev: &wp::Device) {
    let n = 100_000;
    let xs = values(n);
    let cpu = wp::cpu();
    let on = |d: &wp::Device| -> Vec<u64> {
        let mut out = Vec::new();
        let x = arr(&xs, d);
        let bins = arr(&[0.5f32, -0.5, 1e6, 0.0], d);
        ran(d, wp::launch(k_bins, n, (&x, &bins), d));
        out.extend(host(&bins).iter().map(|v| u64::from(v.to_bits())));
        let v = zeros::<Vec3, 1>(2, d);
        let dd = arr(&[2.0f64], d);
        let h = zeros::<f16, 1>(2, d);
        ran(d, wp::launch(k_kinds, n, (&v, &dd, &h, &x), d));
        out.extend(
            host(&v)
                .iter()
                .flat_map(|v| v.to_array())
                .map(|c| u64::from(c.to_bits())),
        );
        out.extend(host(&dd).iter().map(|v| v.to_bits()));
        out.extend(host(&h).iter().map(|v| u64::from(v.to_bits())));
        let g = arr(&xs[..7], d).with_grad().unwrap();
        let w = arr(&xs, d).with_grad().unwrap();
        let o = zeros::<f32, 1>(n, d).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            ran(d, wp::launch(k_gather, n, (&g, &w, &o), d));
        }
        o.grad().unwrap().copy_from(&arr(&xs, d)).unwrap();
        tape.backward_from_grads().unwrap();
        out.extend(
            host(&g.grad().unwrap())
                .iter()
                .map(|v| u64::from(v.to_bits())),
        );
        out
    };
    assert_eq!(on(dev), on(&cpu), "{dev} against the CPU");
}

#[wp::kernel]
fn k_bins_plain(x: Array<f32>, bins: Array<f32>) {
    let i = tid();
    atomic_add(bins, i % 4, x[i]);
}

/// The ordinary kernel's atomics add in whatever order the threads arrive, so its sums may
/// differ from run to run (on a GPU they usually do; on the CPU as the chunks race); the
/// deterministic kernel's are the same bits on every run, equal to the documented order. The
/// number of distinct ordinary results is reported, not asserted: differing is allowed, not
/// promised.
fn ordinary_may_differ_deterministic_does_not(dev: &wp::Device) {
    let n = 1 << 20;
    let xs = values(n);
    let x = arr(&xs, dev);
    let want = bits(&bins_reference(&[0.0; 4], &xs));
    let mut ordinary = std::collections::BTreeSet::new();
    for _ in 0..8 {
        let bins = zeros::<f32, 1>(4, dev);
        ran(dev, wp::launch(k_bins_plain, n, (&x, &bins), dev));
        ordinary.insert(bits(&host(&bins)));
        let bins = zeros::<f32, 1>(4, dev);
        ran(dev, wp::launch(k_bins, n, (&x, &bins), dev));
        assert_eq!(bits(&host(&bins)), want, "a deterministic run on {dev}");
    }
    eprintln!(
        "{dev}: 8 ordinary runs gave {} distinct results, 8 deterministic runs 1",
        ordinary.len()
    );
}

#[derive(Clone, Copy, Debug, Default, PartialEq, wp::Struct)]
#[repr(C)]
struct Body {
    m: f32,
    v: Vec3,
    w: [f64; 2],
}

#[wp::kernel(deterministic)]
fn k_struct_reads(b: Array<Body>, out: Array<f32>) {
    let i = tid();
    let s = b[i % 5];
    atomic_add(out, i, s.m * s.v.y + (s.w[1] as f32));
}

/// Gradients into a struct array that many threads read: each lane's records (an f32, a Vec3,
/// two f64) are added in thread order, the same bits on every run and backend. The reference
/// is the host's sum in that order.
fn struct_gradients_in_order(dev: &wp::Device) {
    let n = 20_000;
    let xs = values(n);
    let bodies: Vec<Body> = (0..5)
        .map(|k| Body {
            m: 0.5 + k as f32,
            v: Vec3::new(1.0, -2.0 + k as f32, 0.25),
            w: [3.0, -1.5 * k as f64],
        })
        .collect();
    let b = arr(&bodies, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(n, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        ran(dev, wp::launch(k_struct_reads, n, (&b, &out), dev));
    }
    out.grad().unwrap().copy_from(&arr(&xs, dev)).unwrap();
    tape.backward_from_grads().unwrap();
    let g = host(&b.grad().unwrap());
    let mut want = [Body::default(); 5];
    for (i, gi) in xs.iter().enumerate() {
        let (s, w) = (bodies[i % 5], &mut want[i % 5]);
        w.m += s.v.y * gi;
        w.v.y += s.m * gi;
        w.w[1] += f64::from(*gi);
    }
    for k in 0..5 {
        assert_eq!(g[k].m.to_bits(), want[k].m.to_bits(), "m of {k}");
        assert_eq!(
            g[k].v.to_array().map(f32::to_bits),
            want[k].v.to_array().map(f32::to_bits),
            "v of {k}"
        );
        assert_eq!(
            g[k].w.map(f64::to_bits),
            want[k].w.map(f64::to_bits),
            "w of {k}"
        );
    }
}

#[wp::kernel(deterministic(max_records = 3))]
fn k_reads_in_loop(x: Array<f32>, out: Array<f32>, n: i32) {
    let i = tid();
    let mut s = 0.0;
    for k in 0..n {
        s += x[(i + k as usize) % 4];
    }
    atomic_add(out, 0, s);
}

/// A backward launch records one gradient accumulation per recorded read: past the adjoint's
/// limit (here the forward's `max_records`, reads being in a loop) it faults like the
/// forward, on every backend.
fn adjoint_record_limit_is_a_fault(dev: &wp::Device) {
    let info = wp::kernel_info(k_reads_in_loop).deterministic.unwrap();
    assert_eq!(
        (info.max_records, info.adjoint_records, info.lanes),
        (3, 3, 1)
    );
    let backward = |n: i32| -> wp::Result<()> {
        let x = arr(&[1.0f32, 2.0, 3.0, 4.0], dev).with_grad().unwrap();
        let out = zeros::<f32, 1>(1, dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            ran(dev, wp::launch(k_reads_in_loop, 2, (&x, &out, n), dev));
        }
        tape.backward(&out)?;
        wp::synchronize()?;
        assert_eq!(host(&x.grad().unwrap()), [1.0, 2.0, 2.0, 1.0]);
        Ok(())
    };
    backward(3).unwrap();
    match backward(4) {
        Err(wp::Error::Fault(f)) => assert!(
            matches!(f.kind, wp::FaultKind::DeterministicRecords { limit: 3, .. }),
            "{f}"
        ),
        other => panic!("4 gradient records against a limit of 3: {other:?}"),
    }
}

/// NVRTC accepts the generated CUDA of every deterministic kernel here, forward and adjoint
/// units (with the ordering entries), for sm_90 (H100, H200) and sm_80: needs libnvrtc, no
/// GPU; skipped, saying so, without it.
#[test]
fn nvrtc_compiles_the_deterministic_units() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED deterministic::nvrtc_compiles_the_deterministic_units: {e}");
        return;
    }
    let kernels = [
        wp::aot::kernel(k_bins),
        wp::aot::kernel(k_add_sub),
        wp::aot::kernel(k_kinds),
        wp::aot::kernel(k_limited),
        wp::aot::kernel(k_looped),
        wp::aot::kernel(k_mixed),
        wp::aot::kernel(k_square_bins),
        wp::aot::kernel(k_gather),
        wp::aot::kernel(k_store_then_read),
        wp::aot::kernel(k_struct_reads),
        wp::aot::kernel(k_reads_in_loop),
    ];
    let dir = std::env::temp_dir().join(format!("wp_det_nvrtc_{}", std::process::id()));
    for arch in [90, 80] {
        let built = wp::aot::compile_with_adjoints(&kernels, &[arch], &dir)
            .unwrap_or_else(|e| panic!("sm_{arch}: {e}"));
        // Two layouts each of forward and adjoint.
        assert_eq!(built.len(), kernels.len() * 4);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

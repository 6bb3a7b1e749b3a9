//! Compare-and-swap, exchange and bitwise atomics: contended updates from every thread must
//! lose nothing (each test's result is exact, so a non-atomic update would fail it), and
//! backward through kernels that use them works where it can and is refused where it cannot.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    cas_counter_i32_and_f32,
    cas_compares_float_bits,
    exch_is_a_permutation,
    bitwise_atomics,
    atomics_on_2d_arrays,
    backward_through_integer_flags,
    backward_refused_for_float_exch,
    backward_refused_for_used_atomic_results,
    capabilities_are_recorded_and_loaded,
);

/// Every thread adds one through a compare-and-swap loop (the classic lock-free update).
#[wp::kernel]
fn k_cas_count(ci: Array<i32>, cf: Array<f32>) {
    let _i = tid();
    // A compare that matches stores the same value: an atomic read.
    let mut cur = atomic_cas(ci, 0, 0, 0);
    loop {
        let seen = atomic_cas(ci, 0, cur, cur + 1);
        if seen == cur {
            break;
        }
        cur = seen;
    }
    let mut curf = atomic_cas(cf, 0, 0.0, 0.0);
    loop {
        let seen = atomic_cas(cf, 0, curf, curf + 1.0);
        // Bitwise equality is float equality for these integer-valued, non-zero-signed values.
        if seen == curf {
            break;
        }
        curf = seen;
    }
}

fn cas_counter_i32_and_f32(dev: &wp::Device) {
    let n = 4096;
    let ci = zeros::<i32, 1>(1, dev);
    let cf = zeros::<f32, 1>(1, dev);
    wp::launch(k_cas_count, n, (&ci, &cf), dev).unwrap();
    assert_eq!(host(&ci), [n as i32]);
    // Integers up to 2^24 are exact in f32.
    assert_eq!(host(&cf), [n as f32]);
}

#[wp::kernel]
fn k_cas_bits(a: Array<f32>, b: Array<f64>, old: Array<f64>) {
    // a[0] = 0.0: a compare with -0.0 does not match; b[0] = NaN: the same NaN bits match.
    old[0] = atomic_cas(a, 0, -0.0, 5.0) as f64;
    old[1] = atomic_cas(b, 0, b[0], 7.0);
}

fn cas_compares_float_bits(dev: &wp::Device) {
    let a = arr(&[0.0f32], dev);
    let b = arr(&[f64::NAN], dev);
    let old = zeros::<f64, 1>(2, dev);
    wp::launch(k_cas_bits, 1, (&a, &b, &old), dev).unwrap();
    assert_eq!(host(&a), [0.0]);
    assert_eq!(host(&old)[0], 0.0);
    assert_eq!(host(&b), [7.0]);
    assert!(host(&old)[1].is_nan());
}

/// Each thread swaps its own id into one slot and keeps what it took out.
#[wp::kernel]
fn k_exch(slot: Array<i64>, slotf: Array<f64>, took: Array<i64>, tookf: Array<f64>) {
    let i = tid();
    took[i] = atomic_exch(slot, 0, i as i64);
    tookf[i] = atomic_exch(slotf, 0, i as f64 + 0.5);
}

fn exch_is_a_permutation(dev: &wp::Device) {
    let n = 2048usize;
    let slot = arr(&[-1i64], dev);
    let slotf = arr(&[-1.0f64], dev);
    let took = zeros::<i64, 1>(n, dev);
    let tookf = zeros::<f64, 1>(n, dev);
    wp::launch(k_exch, n, (&slot, &slotf, &took, &tookf), dev).unwrap();
    // What was taken out plus what is left is exactly what was put in: -1 and every id once.
    let mut all = host(&took);
    all.push(host(&slot)[0]);
    all.sort();
    assert_eq!(all, (-1..n as i64).collect::<Vec<_>>());
    let mut allf = host(&tookf);
    allf.push(host(&slotf)[0]);
    allf.sort_by(f64::total_cmp);
    let mut want: Vec<f64> = (0..n).map(|i| i as f64 + 0.5).collect();
    want.insert(0, -1.0);
    assert_eq!(allf, want);
}

#[wp::kernel]
fn k_bits(or32: Array<u32>, and64: Array<i64>, xor64: Array<u64>, xor_i: Array<i32>) {
    let i = tid();
    atomic_or(or32, 0, 1u32 << (i % 32) as u32);
    atomic_and(and64, 0, !(1i64 << (i % 64) as i64));
    // Every bit toggled twice over 128 threads: back to the start.
    atomic_xor(xor64, 0, 1u64 << (i % 64) as u64);
    // Bits 0..6 toggled by thread i: the xor of 0..128 is 0; of 0..100 below.
    if i < 100 {
        atomic_xor(xor_i, 0, i as i32);
    }
}

fn bitwise_atomics(dev: &wp::Device) {
    let or32 = arr(&[0u32], dev);
    let and64 = arr(&[-1i64], dev);
    let xor64 = arr(&[0xdead_beefu64], dev);
    let xor_i = arr(&[0i32], dev);
    wp::launch(k_bits, 128, (&or32, &and64, &xor64, &xor_i), dev).unwrap();
    assert_eq!(host(&or32), [u32::MAX]);
    assert_eq!(host(&and64), [0]);
    assert_eq!(host(&xor64), [0xdead_beef]);
    assert_eq!(host(&xor_i), [(0..100).fold(0, |a, b| a ^ b)]);
}

#[wp::kernel]
fn k_2d(a: Array<u64, 2>, old: Array<u64, 2>) {
    let (i, j) = tid();
    old[(i, j)] = atomic_cas(a, (i, j), (i * 10 + j) as u64, 99);
    atomic_or(a, (0, 0), 1u64 << 40);
}

fn atomics_on_2d_arrays(dev: &wp::Device) {
    let init: Vec<u64> = (0..2)
        .flat_map(|i| (0..3).map(move |j| i * 10 + j))
        .collect();
    let a = wp::Array::from_vec(init.clone(), dev)
        .unwrap()
        .reshape::<2>([2, 3])
        .unwrap();
    let old = zeros::<u64, 2>([2, 3], dev);
    wp::launch(k_2d, [2, 3], (&a, &old), dev).unwrap();
    assert_eq!(host(&old), init);
    let got = host(&a);
    assert_eq!(got[0], 99 | (1 << 40));
    assert!(got[1..].iter().all(|v| *v == 99));
}

/// An integer flag array updated with atomic_or (result unused) beside a float computation:
/// backward works and gives the float's gradient.
#[wp::kernel]
fn k_flagged(x: Array<f64>, y: Array<f64>, flags: Array<u32>) {
    let i = tid();
    y[i] = x[i] * x[i];
    if x[i] < 0.0 {
        atomic_or(flags, 0, 1u32);
    }
}

fn backward_through_integer_flags(dev: &wp::Device) {
    let x = arr(&[1.5f64, -2.0, 0.25], dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let flags = zeros::<u32, 1>(1, dev);
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_flagged, 3, (&x, &y, &flags), dev).unwrap();
    }
    tape.backward(&y).unwrap();
    assert_eq!(host(&flags), [1]);
    // d(x^2)/dx = 2x, exact.
    assert_eq!(host(&x.grad().unwrap()), [3.0, -4.0, 0.5]);
}

#[wp::kernel]
fn k_float_exch(x: Array<f32>, slot: Array<f32>) {
    let i = tid();
    atomic_exch(slot, 0, x[i] * 2.0);
}

fn backward_refused_for_float_exch(dev: &wp::Device) {
    let x = arr(&[1.0f32, 2.0], dev).with_grad().unwrap();
    let slot = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_float_exch, 2, (&x, &slot), dev).unwrap();
    }
    let err = tape.backward(&slot).unwrap_err().to_string();
    assert!(
        err.contains("k_float_exch") && err.contains("atomic_exch"),
        "{err}"
    );
}

/// A slot taken from a counter: the replay would not know which slot, so backward says so
/// instead of sending every gradient to slot 0.
#[wp::kernel]
fn k_compact(x: Array<f32>, count: Array<i32>, out: Array<f32>) {
    let i = tid();
    if x[i] > 0.0 {
        let slot = atomic_add(count, 0, 1);
        out[slot] = x[i] * 2.0;
    }
}

fn backward_refused_for_used_atomic_results(dev: &wp::Device) {
    let x = arr(&[1.0f32, -1.0, 3.0], dev).with_grad().unwrap();
    let count = zeros::<i32, 1>(1, dev);
    let out = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_compact, 3, (&x, &count, &out), dev).unwrap();
    }
    assert_eq!(host(&count), [2]);
    let err = tape.backward(&out).unwrap_err().to_string();
    assert!(
        err.contains("k_compact") && err.contains("atomic_add"),
        "{err}"
    );
}

#[wp::func]
fn add_f64(s: Array<f64>, v: f64) {
    atomic_add(s, 0, v);
}

#[wp::kernel]
fn k_sum_f64(a: Array<f64>, s: Array<f64>) {
    let i = tid();
    add_f64(s, a[i]);
    atomic_sub(s, 1, a[i]);
}

/// The validator records what a kernel's code needs of its target (the capability table,
/// `wp::capability`): 64-bit integer bitwise atomics, f64 atomic adds (here through a func,
/// which records its own and the runtime adds to its callers' at load). Loading checks them
/// against the GPU's architecture: each of these GPUs has them, so the kernels run, exactly.
fn capabilities_are_recorded_and_loaded(dev: &wp::Device) {
    use wp::capability::{first_missing, Capability, Target};
    assert_eq!(
        wp::kernel_info(k_bits).requires,
        [Capability::AtomicMinMaxBits64]
    );
    assert!(wp::kernel_info(k_cas_count).requires.is_empty());
    // The kernel's own `atomic_sub` on f64 (the func's add is the func's to record).
    assert_eq!(
        wp::kernel_info(k_sum_f64).requires,
        [Capability::AtomicAddF64]
    );
    assert!(first_missing(&[Capability::AtomicMinMaxBits64], Target::Cuda { arch: 35 }).is_some());
    assert!(first_missing(&[Capability::AtomicMinMaxBits64], Target::Cpu).is_none());
    let n = 1000;
    let a = wp::Array::from_vec((0..n).map(|i| i as f64).collect(), dev).unwrap();
    let s = zeros::<f64, 1>(2, dev);
    wp::launch(k_sum_f64, n, (&a, &s), dev).unwrap();
    // Sums of integers below 2^53 are exact in any order.
    let want = (n * (n - 1) / 2) as f64;
    assert_eq!(host(&s), [want, -want]);
}

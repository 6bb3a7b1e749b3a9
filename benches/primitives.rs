//! The CPU primitives against plain rayon (or std) baselines, measured in the same run, on
//! 1M elements:
//!
//! | primitive | baseline |
//! |---|---|
//! | `array_scan` (i32, inclusive) | a serial `for` loop (rayon has no scan) |
//! | `array_sum` (f32) | `par_iter().sum()` (a rayon fold) |
//! | `array_min` (f32) | `par_iter().copied().reduce(.., f32::min)` |
//! | `radix_sort_pairs` (u32 keys, u32 values) | `par_sort_unstable_by_key` and the stable `par_sort_by_key` on `(key, value)` pairs |
//! | `radix_sort_pairs` (f32 keys) | `par_sort_unstable_by(total_cmp)` on pairs |
//! | `compact` (f32, half kept) | `par_extend` of `par_iter().zip(flags).filter()` |
//!
//! ```text
//! cargo bench --bench primitives
//! ```
//!
//! Criterion prints its statistics for each; at the end the bench prints a table of medians
//! taken in this process and the ratio warp / baseline, and checks that each primitive's
//! result equals the baseline's. The sorts time only the sort: the unsorted input is copied
//! in before each run, outside the timing.
use criterion::{black_box, Criterion};
use rayon::prelude::*;
use std::time::Duration;
use warp_lang as wp;

mod common;

use common::{median_after, median_on};
use rand::Rng as _;

const N: usize = 1_000_000;

fn serial_scan(x: &[i32], out: &mut [i32]) {
    let mut acc = 0i32;
    for (o, &v) in out.iter_mut().zip(x) {
        acc = acc.wrapping_add(v);
        *o = acc;
    }
}

fn main() {
    let dev = wp::cpu();
    let mut rng = common::rng(0x9e37_79b9_7f4a_7c15);
    let ints: Vec<i32> = (0..N)
        .map(|_| (rng.random::<u64>() % 2001) as i32 - 1000)
        .collect();
    let floats: Vec<f32> = (0..N)
        .map(|_| (rng.random::<u64>() % 2_000_001) as f32 * 1e-6 - 1.0)
        .collect();
    let keys: Vec<u32> = (0..N).map(|_| rng.random::<u64>() as u32).collect();
    let idx: Vec<u32> = (0..N as u32).collect();
    let flags: Vec<i32> = (0..N).map(|_| (rng.random::<u64>() % 2) as i32).collect();
    let pairs: Vec<(u32, u32)> = keys.iter().copied().zip(idx.iter().copied()).collect();
    let fpairs: Vec<(f32, u32)> = floats.iter().copied().zip(idx.iter().copied()).collect();

    let a_ints = wp::Array::from_slice(&ints, &dev).unwrap();
    let a_scan = wp::Array::<i32>::zeros(N, &dev).unwrap();
    let a_floats = wp::Array::from_slice(&floats, &dev).unwrap();
    let a_out = wp::Array::<f32>::zeros(1, &dev).unwrap();
    let src_keys = wp::Array::from_slice(&keys, &dev).unwrap();
    let src_fkeys = wp::Array::from_slice(&floats, &dev).unwrap();
    let src_idx = wp::Array::from_slice(&idx, &dev).unwrap();
    let a_keys = wp::Array::<u32>::zeros(N, &dev).unwrap();
    let a_fkeys = wp::Array::<f32>::zeros(N, &dev).unwrap();
    let a_vals = wp::Array::<u32>::zeros(N, &dev).unwrap();
    let a_flags = wp::Array::from_slice(&flags, &dev).unwrap();
    let a_kept = wp::Array::<f32>::zeros(N, &dev).unwrap();
    let a_count = wp::Array::<i32>::zeros(1, &dev).unwrap();
    let mut scan_out = vec![0i32; N];
    let mut sorted = pairs.clone();
    let mut fsorted = fpairs.clone();
    let mut kept: Vec<f32> = Vec::with_capacity(N);

    let load = |k: &wp::Array<u32>, v: &wp::Array<u32>| {
        k.copy_from(&src_keys).unwrap();
        v.copy_from(&src_idx).unwrap();
    };
    let load_f = |k: &wp::Array<f32>, v: &wp::Array<u32>| {
        k.copy_from(&src_fkeys).unwrap();
        v.copy_from(&src_idx).unwrap();
    };
    let warp_compact = || wp::compact(&a_floats, &a_flags, &a_kept, &a_count).unwrap();
    let rayon_compact = |kept: &mut Vec<f32>| {
        kept.clear();
        kept.par_extend(
            floats
                .par_iter()
                .zip(&flags)
                .filter(|(_, &f)| f != 0)
                .map(|(&x, _)| x),
        )
    };

    let mut c = Criterion::default()
        .configure_from_args()
        .warm_up_time(Duration::from_millis(500));
    let mut g = c.benchmark_group("primitives_1M");
    g.bench_function("scan_i32/warp", |b| {
        b.iter(|| wp::array_scan(&a_ints, &a_scan, true).unwrap())
    });
    g.bench_function("scan_i32/serial", |b| {
        b.iter(|| serial_scan(black_box(&ints), black_box(&mut scan_out)))
    });
    g.bench_function("sum_f32/warp", |b| {
        b.iter(|| wp::array_sum(&a_floats, &a_out).unwrap())
    });
    g.bench_function("sum_f32/rayon", |b| {
        b.iter(|| black_box(&floats).par_iter().sum::<f32>())
    });
    g.bench_function("min_f32/warp", |b| {
        b.iter(|| wp::array_min(&a_floats, &a_out).unwrap())
    });
    g.bench_function("min_f32/rayon", |b| {
        b.iter(|| {
            black_box(&floats)
                .par_iter()
                .copied()
                .reduce(|| f32::INFINITY, f32::min)
        })
    });
    g.bench_function("sort_u32/warp", |b| {
        b.iter_batched(
            || load(&a_keys, &a_vals),
            |()| wp::radix_sort_pairs(&a_keys, &a_vals, N, None).unwrap(),
            criterion::BatchSize::PerIteration,
        )
    });
    g.bench_function("sort_u32/rayon_unstable", |b| {
        b.iter_batched(
            || pairs.clone(),
            |mut p| p.par_sort_unstable_by_key(|e| e.0),
            criterion::BatchSize::LargeInput,
        )
    });
    g.bench_function("sort_u32/rayon_stable", |b| {
        b.iter_batched(
            || pairs.clone(),
            |mut p| p.par_sort_by_key(|e| e.0),
            criterion::BatchSize::LargeInput,
        )
    });
    g.bench_function("sort_f32/warp", |b| {
        b.iter_batched(
            || load_f(&a_fkeys, &a_vals),
            |()| wp::radix_sort_pairs(&a_fkeys, &a_vals, N, None).unwrap(),
            criterion::BatchSize::PerIteration,
        )
    });
    g.bench_function("sort_f32/rayon_unstable", |b| {
        b.iter_batched(
            || fpairs.clone(),
            |mut p| p.par_sort_unstable_by(|a, b| a.0.total_cmp(&b.0)),
            criterion::BatchSize::LargeInput,
        )
    });
    g.bench_function("compact_f32/warp", |b| b.iter(warp_compact));
    g.bench_function("compact_f32/rayon", |b| {
        b.iter(|| rayon_compact(black_box(&mut kept)))
    });
    g.finish();

    // The ratio table, from medians taken here in the same process.
    let runs = 21;
    let nothing = || {};
    // Timed once, compared with both baselines.
    let warp_sort_u32 = median_after(
        runs,
        || load(&a_keys, &a_vals),
        || wp::radix_sort_pairs(&a_keys, &a_vals, N, None).unwrap(),
    );
    let rows = [
        (
            "scan i32 (inclusive)",
            "serial loop",
            median_after(runs, nothing, || {
                wp::array_scan(&a_ints, &a_scan, true).unwrap()
            }),
            median_after(runs, nothing, || serial_scan(&ints, &mut scan_out)),
        ),
        (
            "sum f32",
            "rayon sum",
            median_after(runs, nothing, || wp::array_sum(&a_floats, &a_out).unwrap()),
            median_after(runs, nothing, || {
                black_box(floats.par_iter().sum::<f32>());
            }),
        ),
        (
            "min f32",
            "rayon reduce",
            median_after(runs, nothing, || wp::array_min(&a_floats, &a_out).unwrap()),
            median_after(runs, nothing, || {
                black_box(
                    floats
                        .par_iter()
                        .copied()
                        .reduce(|| f32::INFINITY, f32::min),
                );
            }),
        ),
        (
            "sort u32 pairs",
            "par_sort_unstable",
            warp_sort_u32,
            median_on(
                runs,
                &mut sorted,
                |v| v.copy_from_slice(&pairs),
                |v| v.par_sort_unstable_by_key(|e| e.0),
            ),
        ),
        (
            "sort u32 pairs",
            "par_sort (stable)",
            warp_sort_u32,
            median_on(
                runs,
                &mut sorted,
                |v| v.copy_from_slice(&pairs),
                |v| v.par_sort_by_key(|e| e.0),
            ),
        ),
        (
            "sort f32 pairs",
            "par_sort_unstable",
            median_after(
                runs,
                || load_f(&a_fkeys, &a_vals),
                || wp::radix_sort_pairs(&a_fkeys, &a_vals, N, None).unwrap(),
            ),
            median_on(
                runs,
                &mut fsorted,
                |v| v.copy_from_slice(&fpairs),
                |v| v.par_sort_unstable_by(|a, b| a.0.total_cmp(&b.0)),
            ),
        ),
        (
            "compact f32 (1/2 kept)",
            "rayon filter",
            median_after(runs, nothing, warp_compact),
            median_after(runs, nothing, || rayon_compact(&mut kept)),
        ),
    ];
    println!();
    println!(
        "CPU primitives, {N} elements, {} rayon threads (medians of {runs})",
        rayon::current_num_threads()
    );
    println!("| primitive | warp | baseline | time | warp / baseline |");
    println!("|---|---|---|---|---|");
    for (what, base, tw, tb) in rows {
        println!(
            "| {what} | {:.3} ms | {base} | {:.3} ms | {:.2}x |",
            tw.as_secs_f64() * 1e3,
            tb.as_secs_f64() * 1e3,
            tw.as_secs_f64() / tb.as_secs_f64()
        );
    }

    // The results agree with the baselines'.
    wp::array_scan(&a_ints, &a_scan, true).unwrap();
    serial_scan(&ints, &mut scan_out);
    assert_eq!(a_scan.to_vec().unwrap(), scan_out, "scan");
    load(&a_keys, &a_vals);
    wp::radix_sort_pairs(&a_keys, &a_vals, N, None).unwrap();
    sorted.copy_from_slice(&pairs);
    sorted.par_sort_by_key(|e| e.0);
    let (sk, sv): (Vec<u32>, Vec<u32>) = sorted.iter().copied().unzip();
    assert_eq!(a_keys.to_vec().unwrap(), sk, "sorted keys");
    assert_eq!(a_vals.to_vec().unwrap(), sv, "sorted values (stable)");
    warp_compact();
    rayon_compact(&mut kept);
    assert_eq!(
        a_count.to_vec().unwrap()[0] as usize,
        kept.len(),
        "compacted count"
    );
    assert_eq!(
        a_kept.to_vec().unwrap()[..kept.len()],
        kept[..],
        "compacted values"
    );
    wp::array_min(&a_floats, &a_out).unwrap();
    let m = floats.iter().copied().fold(f32::INFINITY, f32::min);
    assert_eq!(a_out.to_vec().unwrap()[0], m, "min");
    println!(
        "results: scan, sort (keys and values, stable), compaction and min equal the baselines'"
    );
}

//! GPU benchmark of neighbour search and its parallel primitives, against PyTorch and NVIDIA
//! Warp timed on the same GPU in the same run (their sides are the Python scripts in
//! `benches/py/`, run by this binary; a side that cannot run is reported and skipped).
//!
//! ```text
//! cargo bench --bench spatial                  # needs a CUDA device; SKIPPED otherwise
//! # on the GPU machine, with Warp unpacked by ../shared/tools/warp-bundle:
//! PYTHONPATH=/root/warp-lang .gpu/bin/spatial-*
//! ```
//!
//! Hash grid (Warp: `benches/py/warp_hash_grid.py`, Warp 1.19's `HashGrid` on the same GPU):
//! 1M points uniform in a 10^3 box, a 128^3 grid, radius 0.2: the build, and a count of the
//! neighbours within the radius with a thread per point in point order and in the grid's cell
//! order; the counts are checked against the CPU backend's, point for point. On the CPU: 100K
//! points at the same density, against Warp's single-threaded CPU figures in
//! shared/DESIGN.md (measured on the same kind of GPU machine's CPU; Warp's CPU compiler is
//! not in the bundle, so they cannot be timed in this run).
//!
//! Primitives (PyTorch: torch.sort with stable=True and a gather of the values, torch.cumsum,
//! torch.sum; CuPy, where it is installed: argsort, CUB's radix sort through Thrust, and two
//! gathers): a stable key/value radix sort (i32 and f32 keys), inclusive scans and a sum, at
//! 1M and 16M elements. Each figure is a median of timed repetitions after a warm-up
//! (compilation excluded); every result is checked against the CPU backend's. Sorts, scans
//! and sums are timed by CUDA events around the call, as the PyTorch side times its own (sorts
//! on random keys restored before each repetition). Then the GPU sort's kernel configurations
//! (`SortConfig`) are timed side by side on random i32 keys and on 21-bit keys (the hash
//! grid's), and the GPU scan's algorithms (`ScanAlgorithm`: three-phase and single-pass) in
//! several block shapes (`Tile`) beside `torch.cumsum`, with the sum beside `torch.sum`.
//!
//! ```text
//! .gpu/bin/spatial-* --primitives              # the primitives and sort kernels only
//! ```

use warp_lang as wp;
use wp::prelude::*;

mod common;

use common::{
    event_ms, json_number, median_ms, median_of, python_side, ratio, size_section, uniform_points,
    REPS,
};
use rand::Rng as _;

/// Neighbours of each point within `r`, a thread per point in point order.
#[wp::kernel]
fn count_point_order(grid: HashGrid, x: Array<Vec3>, r: f32, out: Array<i32>) {
    let i = tid();
    let p = x[i];
    let mut c = 0;
    for j in hash_grid_query(grid, p, r) {
        if length(p - x[j]) <= r {
            c += 1;
        }
    }
    out[i] = c;
}

/// The same count, threads in the grid's cell order (neighbouring threads, neighbouring
/// points: the order Warp's examples use).
#[wp::kernel]
fn count_cell_order(grid: HashGrid, x: Array<Vec3>, r: f32, out: Array<i32>) {
    let i = hash_grid_point_id(grid, tid());
    let p = x[i];
    let mut c = 0;
    for j in hash_grid_query(grid, p, r) {
        if length(p - x[j]) <= r {
            c += 1;
        }
    }
    out[i] = c;
}

fn main() -> wp::Result<()> {
    wp::init();
    let dev = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            println!("spatial bench SKIPPED: no CUDA device ({e})");
            return Ok(());
        }
    };
    println!("spatial bench on {dev}");
    // `--primitives`: only the primitives' section (and the sort kernels' comparison).
    if !std::env::args().any(|a| a == "--primitives") {
        hash_grid(&dev)?;
    }
    primitives(&dev)
}

fn hash_grid(dev: &wp::Device) -> wp::Result<()> {
    let (n, side, r) = (1_000_000usize, 10.0f32, 0.2f32);
    let warp = python_side("benches/py/warp_hash_grid.py", &[n.to_string()]);
    match &warp {
        Ok(_) => println!("Warp side: ran in this process's run"),
        Err(e) => println!("Warp side not run: {e}"),
    }
    let theirs = |k: &str| warp.as_ref().ok().and_then(|t| json_number(t, k));
    let pts = uniform_points(n, side, 0x9e37_79b9);
    let x = wp::Array::from_slice(&pts, dev)?;
    let out = wp::Array::<i32>::zeros(n, dev)?;
    let mut grid = wp::HashGrid::new(128, 128, 128, dev)?;
    let build = median_ms(|| grid.build(&x, r))?;
    // The device's share of a build (CUDA events, both sides): what is left of the host-timed
    // figure is launch and synchronisation overhead.
    let build_events = event_ms(dev, || grid.build(&x, r))?;
    let point = median_ms(|| wp::launch(count_point_order, n, (&grid, &x, r, &out), dev))?;
    let counts = out.to_vec()?;
    let cell = median_ms(|| wp::launch(count_cell_order, n, (&grid, &x, r, &out), dev))?;
    assert_eq!(
        out.to_vec()?,
        counts,
        "cell order and point order counts differ"
    );
    // The CPU backend's counts, point for point.
    let cpu = wp::get_device("cpu")?;
    let xc = wp::Array::from_slice(&pts, &cpu)?;
    let oc = wp::Array::<i32>::zeros(n, &cpu)?;
    let mut gc = wp::HashGrid::new(128, 128, 128, &cpu)?;
    gc.build(&xc, r)?;
    wp::launch(count_point_order, n, (&gc, &xc, r, &oc), &cpu)?;
    // Equal except at pairs whose distance rounds across r differently: NVRTC contracts the
    // distance's products into FMAs (wp::config::set_cuda_fmad(false) makes them equal).
    let cpu_counts = oc.to_vec()?;
    let differ = cpu_counts
        .iter()
        .zip(&counts)
        .filter(|(a, b)| a != b)
        .count();
    let worst = cpu_counts
        .iter()
        .zip(&counts)
        .map(|(a, b)| (a - b).abs())
        .max()
        .unwrap_or(0);
    assert!(
        differ * 10_000 <= n && worst <= 2,
        "GPU and CPU neighbour counts differ at {differ} points (by up to {worst})"
    );
    let mean = counts.iter().map(|&c| c as f64).sum::<f64>() / n as f64;
    // Expected: 4/3 pi r^3 times the density, less what the box's faces cut off, plus the
    // point itself.
    println!(
        "hash grid, {n} points in a {side}^3 box, r = {r}: mean neighbours {mean:.2} (Warp's \
         points: {}); the CPU backend's counts differ at {differ} points, by at most {worst} \
         (borderline distances: FMA contraction on the GPU)",
        theirs("mean_neighbours_point_order").map_or("-".into(), |m| format!("{m:.2}"))
    );
    println!(
        "{:<28} {build:7.3} ms   {}",
        "build",
        ratio(build, theirs("build_ms"))
    );
    println!(
        "{:<28} {build_events:7.3} ms   {}",
        "build (GPU, CUDA events)",
        ratio(build_events, theirs("build_events_ms"))
    );
    println!(
        "{:<28} {point:7.3} ms   {}",
        "count, point order",
        ratio(point, theirs("query_point_order_ms"))
    );
    println!(
        "{:<28} {cell:7.3} ms   {}",
        "count, cell order",
        ratio(cell, theirs("query_cell_order_ms"))
    );
    // The CPU backend at the same density, against Warp's single-threaded CPU backend timed
    // in the same run (DESIGN.md's figure when Warp did not run), on one thread and on all.
    let (nc, sc) = (100_000usize, side * 0.1f32.cbrt());
    let pc = uniform_points(nc, sc, 0x5851_f42d);
    let xc = wp::Array::from_slice(&pc, &cpu)?;
    let oc = wp::Array::<i32>::zeros(nc, &cpu)?;
    let mut gc = wp::HashGrid::new(128, 128, 128, &cpu)?;
    let (wb, wq, source) = match (theirs("cpu_build_ms"), theirs("cpu_query_point_order_ms")) {
        (Some(b), Some(q)) => (b, q, "this run"),
        _ => (4.66, 201.0, "DESIGN.md, H100 machine"),
    };
    let all = rayon_threads();
    for threads in [1, all] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| wp::Error::InvalidArgument {
                what: format!("a rayon pool of {threads} threads: {e}"),
            })?;
        let (b, q) = pool.install(|| -> wp::Result<(f64, f64)> {
            let b = median_ms(|| gc.build(&xc, r))?;
            let q = median_ms(|| wp::launch(count_point_order, nc, (&gc, &xc, r, &oc), &cpu))?;
            Ok((b, q))
        })?;
        println!(
            "CPU ({threads:>2} threads), {nc} points: build {b:6.2} ms, count {q:7.2} ms; Warp 1.19 \
             single-threaded CPU ({source}): {wb:.2} / {wq:.1} ms: speed-up {:.1}x / {:.1}x, \
             build + count {:.1}x (goal >= 10x on 16 cores)",
            wb / b,
            wq / q,
            (wb + wq) / (b + q)
        );
    }
    Ok(())
}

fn rayon_threads() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

fn primitives(dev: &wp::Device) -> wp::Result<()> {
    let sizes = [1usize << 20, 1 << 24];
    let torch = python_side(
        "benches/py/torch_primitives.py",
        &sizes.iter().map(|n| n.to_string()).collect::<Vec<_>>(),
    );
    match &torch {
        Ok(_) => println!("PyTorch side: ran in this process's run"),
        Err(e) => println!("PyTorch side not run: {e}"),
    }
    let cpu = wp::get_device("cpu")?;
    println!(
        "{:<28} {:>10}   {:>31}",
        "primitive (n)", "warp-lang", "PyTorch, ratio warp / torch"
    );
    for n in sizes {
        let section = torch.as_ref().ok().and_then(|t| size_section(t, n));
        let theirs = |k: &str| section.and_then(|s| json_number(s, k));
        let mut r = common::rng(0x2545_f491);
        let ki: Vec<i32> = (0..n).map(|_| (r.random::<u64>() >> 33) as i32).collect();
        let kf: Vec<f32> = (0..n).map(|_| r.random::<f32>()).collect();
        let vals: Vec<i32> = (0..n as i32).collect();
        let small: Vec<i32> = (0..n).map(|_| (r.random::<u64>() % 100) as i32).collect();

        let ms = sort_case(&ki, &vals, None, dev, &cpu)?;
        println!(
            "{:<28} {ms:7.3} ms   {}   CuPy {}",
            format!("sort pairs i32 ({n})"),
            ratio(ms, theirs("sort_pairs_i32_ms")),
            ratio(ms, theirs("cupy_sort_pairs_i32_ms"))
        );
        let ms = sort_case(&kf, &vals, None, dev, &cpu)?;
        println!(
            "{:<28} {ms:7.3} ms   {}   CuPy {}",
            format!("sort pairs f32 ({n})"),
            ratio(ms, theirs("sort_pairs_f32_ms")),
            ratio(ms, theirs("cupy_sort_pairs_f32_ms"))
        );

        let a = wp::Array::from_slice(&small, dev)?;
        let out = wp::Array::<i32>::zeros(n, dev)?;
        wp::array_scan(&a, &out, true)?;
        let want: Vec<i32> = small
            .iter()
            .scan(0i32, |acc, x| {
                *acc = acc.wrapping_add(*x);
                Some(*acc)
            })
            .collect();
        assert_eq!(out.to_vec()?, want, "scan i32");
        let ms = event_ms(dev, || wp::array_scan(&a, &out, true))?;
        println!(
            "{:<28} {ms:7.3} ms   {}",
            format!("inclusive scan i32 ({n})"),
            ratio(ms, theirs("cumsum_i32_ms"))
        );

        let f = wp::Array::from_slice(&kf, dev)?;
        let fout = wp::Array::<f32>::zeros(n, dev)?;
        let ms = event_ms(dev, || wp::array_scan(&f, &fout, true))?;
        let last = fout.to_vec()?[n - 1] as f64;
        let exact: f64 = kf.iter().map(|&x| x as f64).sum();
        println!(
            "{:<28} {ms:7.3} ms   {}   last element rel err vs f64 {:.1e}",
            format!("inclusive scan f32 ({n})"),
            ratio(ms, theirs("cumsum_f32_ms")),
            ((last - exact) / exact).abs()
        );

        let sum = wp::Array::<f32>::zeros(1, dev)?;
        let ms = event_ms(dev, || wp::array_sum(&f, &sum))?;
        let got = sum.to_vec()?[0] as f64;
        println!(
            "{:<28} {ms:7.3} ms   {}   rel err vs f64 {:.1e}",
            format!("sum f32 ({n})"),
            ratio(ms, theirs("sum_f32_ms")),
            ((got - exact) / exact).abs()
        );
    }
    sort_kernels(dev, torch.as_ref().ok())?;
    scan_algorithms(dev, torch.as_ref().ok())
}

/// The GPU scan's algorithms (`wp::primitives::plan::ScanAlgorithm`: the three-phase scan, the
/// default of f64, f16 and bf16, and the single-pass decoupled look-back, that of the integers
/// and f32) and block shapes
/// (`plan::Tile`, each a module of its own), timed one after the other in this process by
/// CUDA events: inclusive scans of i32 (0..100, as PyTorch's) and f32 (uniform in [0, 1))
/// beside `torch.cumsum`, and the f32 sum beside `torch.sum`: the run that decides the
/// defaults (`plan::default_gpu_scan`). The i32 results are checked against the CPU's, the
/// f32 ones by the last prefix's error against an f64 sum.
fn scan_algorithms(dev: &wp::Device, torch: Option<&serde_json::Value>) -> wp::Result<()> {
    use wp::primitives::plan::{self, ScanAlgorithm, Tile};
    println!("scans (GPU ms between CUDA events; the PyTorch column as above):");
    let tile = |threads, items| Tile { threads, items };
    let tiles = [
        plan::GPU_TILE,
        tile(256, 16),
        tile(512, 8),
        tile(512, 16),
        tile(1024, 8),
        tile(128, 16),
    ];
    for n in [1usize << 20, 1 << 24] {
        let section = torch.and_then(|t| size_section(t, n));
        let theirs = |k: &str| section.and_then(|s| json_number(s, k));
        let mut r = common::rng(0x5ca9 ^ n as u64);
        let small: Vec<i32> = (0..n).map(|_| (r.random::<u64>() % 100) as i32).collect();
        let kf: Vec<f32> = (0..n).map(|_| r.random::<f32>()).collect();
        let want: Vec<i32> = small
            .iter()
            .scan(0i32, |acc, x| {
                *acc = acc.wrapping_add(*x);
                Some(*acc)
            })
            .collect();
        let exact: f64 = kf.iter().map(|&x| x as f64).sum();
        let (a, out) = (
            wp::Array::from_slice(&small, dev)?,
            wp::Array::<i32>::zeros(n, dev)?,
        );
        let (f, fout) = (
            wp::Array::from_slice(&kf, dev)?,
            wp::Array::<f32>::zeros(n, dev)?,
        );
        for t in tiles {
            plan::set_gpu_scan_tile(Some(t))?;
            let shape = format!("{}x{}", t.threads, t.items);
            for alg in [ScanAlgorithm::ThreePass, ScanAlgorithm::OnePass] {
                plan::set_gpu_scan_algorithm(Some(alg));
                let name = format!("{alg:?} {shape}");
                let ms = event_ms(dev, || wp::array_scan(&a, &out, true))?;
                assert_eq!(out.to_vec()?, want, "{name} scan i32 ({n})");
                println!(
                    "  {name:<18} inclusive scan i32 ({n:>8}) {ms:7.3} ms   {}",
                    ratio(ms, theirs("cumsum_i32_ms"))
                );
                let ms = event_ms(dev, || wp::array_scan(&f, &fout, true))?;
                let last = fout.to_vec()?[n - 1] as f64;
                println!(
                    "  {name:<18} inclusive scan f32 ({n:>8}) {ms:7.3} ms   {}   last element rel \
                     err vs f64 {:.1e}",
                    ratio(ms, theirs("cumsum_f32_ms")),
                    ((last - exact) / exact).abs()
                );
            }
            plan::set_gpu_scan_algorithm(None);
            let sum = wp::Array::<f32>::zeros(1, dev)?;
            let ms = event_ms(dev, || wp::array_sum(&f, &sum))?;
            let got = sum.to_vec()?[0] as f64;
            println!(
                "  {:<18} sum f32            ({n:>8}) {ms:7.3} ms   {}   rel err vs f64 {:.1e}",
                shape,
                ratio(ms, theirs("sum_f32_ms")),
                ((got - exact) / exact).abs()
            );
        }
        plan::set_gpu_scan_tile(None)?;
    }
    Ok(())
}

/// A stable key/value sort on the GPU by `key_bits` (None: all), checked against the CPU
/// backend's, then timed: GPU milliseconds between CUDA events around the sort alone (as
/// PyTorch's side times its own), median of `REPS` after a warm-up. Before each repetition the
/// random input is copied back from pristine arrays (outside the timed span), so that every
/// repetition sorts the same random order: sorting sorted keys again would scatter in long
/// coalesced runs and time less than PyTorch's random keys.
fn sort_case<K: wp::primitives::SortKey>(
    keys: &[K],
    vals: &[i32],
    key_bits: Option<u32>,
    dev: &wp::Device,
    cpu: &wp::Device,
) -> wp::Result<f64> {
    let n = keys.len();
    let (k0, v0) = (
        wp::Array::from_slice(keys, dev)?,
        wp::Array::from_slice(vals, dev)?,
    );
    let (k, v) = (
        wp::Array::<K>::zeros(n, dev)?,
        wp::Array::<i32>::zeros(n, dev)?,
    );
    let (kc, vc) = (
        wp::Array::from_slice(keys, cpu)?,
        wp::Array::from_slice(vals, cpu)?,
    );
    wp::radix_sort_pairs(&kc, &vc, n, key_bits)?;
    let stream = wp::get_stream(dev)?;
    let mut times = Vec::with_capacity(REPS + 1);
    for rep in 0..=REPS {
        k.copy_from(&k0)?;
        v.copy_from(&v0)?;
        let start = stream.record_event()?;
        wp::radix_sort_pairs(&k, &v, n, key_bits)?;
        let end = stream.record_event()?;
        times.push(start.elapsed_ms(&end)? as f64);
        if rep == 0 {
            // The warm-up (compilation, scratch growth) is checked, not timed.
            assert_eq!(v.to_vec()?, vc.to_vec()?, "GPU and CPU sorts disagree");
            times.clear();
        }
    }
    Ok(median_of(times))
}

/// The GPU sort's kernel configurations, timed one after another in this process (each is its
/// own module: `wp::primitives::plan::SortConfig`): the default first, then the alternatives
/// worth measuring against it, and the first kernel (4-bit counting passes) for reference.
fn sort_kernels(dev: &wp::Device, torch: Option<&serde_json::Value>) -> wp::Result<()> {
    use wp::primitives::plan::{self, SortConfig, SortVariant, Tile};
    let cpu = wp::get_device("cpu")?;
    let with = |variant, threads, items, min_blocks| SortConfig {
        variant,
        tile: Tile { threads, items },
        min_blocks,
    };
    let configs = [
        plan::GPU_SORT,
        with(SortVariant::MatchAny, 256, 16, 3),
        with(SortVariant::Ballot, 384, 12, 2),
        with(SortVariant::Ballot, 512, 8, 2),
        with(SortVariant::Ballot, 256, 16, 4),
        with(SortVariant::Ballot, 256, 12, 4),
        with(SortVariant::Ballot, 256, 8, 4),
        with(SortVariant::Ballot, 128, 16, 6),
        with(SortVariant::Nibbles, 256, 16, 4),
    ];
    println!(
        "sort kernels (GPU ms between CUDA events, random keys; the PyTorch column as above):"
    );
    for n in [1usize << 20, 1 << 24] {
        let section = torch.and_then(|t| size_section(t, n));
        let theirs = section.and_then(|s| json_number(s, "sort_pairs_i32_ms"));
        let mut r = common::rng(0x5eed ^ n as u64);
        let ki: Vec<i32> = (0..n).map(|_| (r.random::<u64>() >> 33) as i32).collect();
        // The hash grid's keys: cells of a 128^3 grid, 21 bits.
        let cells: Vec<i32> = (0..n).map(|_| r.random_range(0..1 << 21)).collect();
        let vals: Vec<i32> = (0..n as i32).collect();
        for c in configs {
            wp::primitives::plan::set_gpu_sort_config(Some(c))?;
            let all = sort_case(&ki, &vals, None, dev, &cpu)?;
            let grid = sort_case(&cells, &vals, Some(21), dev, &cpu)?;
            println!(
                "  {:<10} {:>3}x{:<2} {} blocks/SM  n {n:>8}: i32 {all:7.3} ms   {}   21-bit \
                 {grid:7.3} ms",
                format!("{:?}", c.variant),
                c.tile.threads,
                c.tile.items,
                c.min_blocks,
                ratio(all, theirs)
            );
        }
    }
    wp::primitives::plan::set_gpu_sort_config(None)
}

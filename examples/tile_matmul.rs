//! A tiled GEMM, C = A B, with block-cooperative tiles (`tile_load`, `tile_matmul`,
//! `tile_store`, launched with `wp::launch_tiled`), against the same product written as a plain
//! kernel (one thread per output) in the same run: time per GEMM, GFLOP/s, the ratio of the two,
//! and each one's error against a float64 reference.
//!
//! ```text
//! cargo run --release --example tile_matmul -- [--device cpu|cuda:0] [--size 512]
//!     [--m M --n N --k K] [--f64] [--reps 5] [--block-dim 256]
//! cargo run --release --example tile_matmul -- --device cuda:0 --size 4096
//! ```
//! A and B are uniform in [-1, 1) (ChaCha8, fixed seed). Each block of the tiled kernel owns a
//! `BM x BN` tile of C and walks k in steps of `BK`: it loads a `BM x BK` tile of A and a
//! `BK x BN` tile of B into shared memory and accumulates their product (each output one FMA
//! chain over k ascending). Sizes need not be multiples of the tiles: loads past an edge read
//! zeros and stores past it are skipped.
//!
//! The error of an entry is |c - c64| / sum_p |a_ip| |b_pj|, c64 the product of the same
//! inputs by a compensated float64 dot product (as accurate as twice float64's precision): the
//! rounding error of a dot product relative to its magnitude, which a k-term chain of FMAs
//! keeps below k u (u = 2^-24 in f32, 2^-53 in f64), the bound the verdict checks. Plain
//! relative error |c - c64| / |c64| would be unbounded where an entry of C cancels to about 0.
//! Every entry is checked for products of up to 2^28 multiply-adds, a seeded sample above.
//!
//! Slice 1 of the tiles: FMA in shared memory, no tensor cores. The times are honest numbers of
//! that, far from a vendor BLAS (benches/gpu.rs times cuBLAS and Warp beside it).

mod common;
#[path = "common/tile_gemm.rs"]
mod tile_gemm;

use clap::Parser;
use rand::Rng as _;
use std::time::Instant;

use common::{num, DeviceArg};
use tile_gemm::{gemm_plain, gemm_tiled_f32, gemm_tiled_f64, BK, BK64, BM, BN};
use warp_lang as wp;

/// A tiled GEMM C = A B (tile_load / tile_matmul / tile_store) against a plain one-thread-per-
/// output kernel: time, GFLOP/s and the error against float64.
#[derive(Parser, Debug)]
struct Args {
    #[command(flatten)]
    device: DeviceArg,
    /// m = n = k (each of --m, --n, --k overrides its own)
    #[arg(long, default_value = "512", value_parser = num::<usize>)]
    size: usize,
    /// Rows of A and C
    #[arg(long, value_parser = num::<usize>)]
    m: Option<usize>,
    /// Columns of B and C
    #[arg(long, value_parser = num::<usize>)]
    n: Option<usize>,
    /// Columns of A, rows of B
    #[arg(long, value_parser = num::<usize>)]
    k: Option<usize>,
    /// Multiply in f64 (default f32)
    #[arg(long)]
    f64: bool,
    /// Timed GEMMs of each kernel after a warm-up; the median is printed
    #[arg(long, default_value = "5", value_parser = num::<usize>)]
    reps: usize,
    /// Threads per block of the tiled kernel
    #[arg(long, default_value = "256", value_parser = num::<usize>)]
    block_dim: usize,
    /// Entries of C checked against float64 when the product is too large to check them all
    #[arg(long, default_value = "4096", value_parser = num::<usize>)]
    samples: usize,
}

/// The element types of the run: f32 or f64, with the tiled kernel of each.
trait Elem: wp::Element + Copy + Into<f64> {
    const NAME: &'static str;
    /// The unit roundoff (half the machine epsilon).
    const U: f64;
    fn from_f64(x: f64) -> Self;
    fn launch_tiled(
        a: &wp::Array<Self, 2>,
        b: &wp::Array<Self, 2>,
        c: &wp::Array<Self, 2>,
        block_dim: usize,
        dev: &wp::Device,
    ) -> wp::Result<()>;
    fn launch_plain(
        a: &wp::Array<Self, 2>,
        b: &wp::Array<Self, 2>,
        c: &wp::Array<Self, 2>,
        dev: &wp::Device,
    ) -> wp::Result<()>;
}

impl Elem for f32 {
    const NAME: &'static str = "f32";
    const U: f64 = f32::EPSILON as f64 / 2.0;
    fn from_f64(x: f64) -> f32 {
        x as f32
    }
    fn launch_tiled(
        a: &wp::Array<f32, 2>,
        b: &wp::Array<f32, 2>,
        c: &wp::Array<f32, 2>,
        block_dim: usize,
        dev: &wp::Device,
    ) -> wp::Result<()> {
        let [m, n] = c.shape();
        let blocks = (m.div_ceil(BM), n.div_ceil(BN));
        wp::launch_tiled(gemm_tiled_f32, blocks, (a, b, c), block_dim, dev)
    }
    fn launch_plain(
        a: &wp::Array<f32, 2>,
        b: &wp::Array<f32, 2>,
        c: &wp::Array<f32, 2>,
        dev: &wp::Device,
    ) -> wp::Result<()> {
        wp::launch(gemm_plain, c.shape(), (a, b, c), dev)
    }
}

impl Elem for f64 {
    const NAME: &'static str = "f64";
    const U: f64 = f64::EPSILON / 2.0;
    fn from_f64(x: f64) -> f64 {
        x
    }
    fn launch_tiled(
        a: &wp::Array<f64, 2>,
        b: &wp::Array<f64, 2>,
        c: &wp::Array<f64, 2>,
        block_dim: usize,
        dev: &wp::Device,
    ) -> wp::Result<()> {
        let [m, n] = c.shape();
        let blocks = (m.div_ceil(BM), n.div_ceil(BN));
        wp::launch_tiled(gemm_tiled_f64, blocks, (a, b, c), block_dim, dev)
    }
    fn launch_plain(
        a: &wp::Array<f64, 2>,
        b: &wp::Array<f64, 2>,
        c: &wp::Array<f64, 2>,
        dev: &wp::Device,
    ) -> wp::Result<()> {
        wp::launch(gemm_plain, c.shape(), (a, b, c), dev)
    }
}

/// Median milliseconds of `reps` runs of `f` after one warm-up run (which also compiles the
/// kernel on a GPU), the device synchronised around each run (GPU launches are asynchronous).
fn median_ms(reps: usize, mut f: impl FnMut() -> wp::Result<()>) -> wp::Result<(f64, f64)> {
    let t = Instant::now();
    f()?;
    wp::synchronize()?;
    let first = t.elapsed().as_secs_f64() * 1e3;
    let mut times = Vec::with_capacity(reps);
    for _ in 0..reps {
        let t = Instant::now();
        f()?;
        wp::synchronize()?;
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    times.sort_by(f64::total_cmp);
    Ok((times[times.len() / 2], first))
}

/// The entries of C checked against float64: all of them for a product of up to 2^28
/// multiply-adds, else `samples` seeded picks (always including the last corner, where the
/// ragged tiles are).
fn checked_entries(m: usize, n: usize, k: usize, samples: usize) -> Vec<(usize, usize)> {
    if (m * n).saturating_mul(k) <= 1 << 28 || m * n <= samples {
        return (0..m).flat_map(|i| (0..n).map(move |j| (i, j))).collect();
    }
    let mut r = common::rng(31);
    let mut picks: Vec<(usize, usize)> = (0..samples.saturating_sub(1))
        .map(|_| (r.random_range(0..m), r.random_range(0..n)))
        .collect();
    picks.push((m - 1, n - 1));
    picks
}

/// max over `entries` of |c - c64| / sum_p |a_ip b_pj| (see the module's doc). The reference
/// c64 is a compensated float64 dot product of the same (rounded) inputs (Ogita, Rump and
/// Oishi's Dot2: each product's rounding error by an FMA, each sum's by TwoSum), about as
/// accurate as float64 with twice the precision, so that it is a reference for `--f64` too.
fn max_error<T: Elem>(
    c: &[T],
    a: &[T],
    b: &[T],
    (n, k): (usize, usize),
    entries: &[(usize, usize)],
) -> f64 {
    let mut worst = 0.0f64;
    for &(i, j) in entries {
        let (mut s, mut comp, mut mag) = (0.0f64, 0.0f64, 0.0f64);
        for p in 0..k {
            let (x, y) = (a[i * k + p].into(), b[p * n + j].into());
            let prod = x * y;
            let prod_err = x.mul_add(y, -prod);
            let t = s + prod;
            let z = t - s;
            comp += (s - (t - z)) + (prod - z) + prod_err;
            s = t;
            mag += prod.abs();
        }
        let err = (c[i * n + j].into() - (s + comp)).abs();
        // An all-zero row or column: the product is exactly zero, any error is absolute.
        worst = worst.max(if mag > 0.0 { err / mag } else { err });
    }
    worst
}

fn run<T: Elem>(args: &Args, dev: &wp::Device) -> wp::Result<bool> {
    let m = args.m.unwrap_or(args.size);
    let n = args.n.unwrap_or(args.size);
    let k = args.k.unwrap_or(args.size);
    println!(
        "C = A B in {}: {m} x {k} times {k} x {n}; tiles {BM} x {BN}, k-step {}, {} threads per \
         block, {} x {} blocks",
        T::NAME,
        if T::NAME == "f64" { BK64 } else { BK },
        args.block_dim,
        m.div_ceil(BM),
        n.div_ceil(BN),
    );
    let mut r = common::rng(2026);
    let mut uniform = |len: usize| -> Vec<T> {
        (0..len)
            .map(|_| T::from_f64(r.random::<f64>() * 2.0 - 1.0))
            .collect()
    };
    let (ah, bh) = (uniform(m * k), uniform(k * n));
    let a = wp::Array::from_slice_shape(&ah, (m, k), dev)?;
    let b = wp::Array::from_slice_shape(&bh, (k, n), dev)?;
    let c_tiled = wp::Array::<T, 2>::zeros((m, n), dev)?;
    let c_plain = wp::Array::<T, 2>::zeros((m, n), dev)?;

    let (t_tiled, first_tiled) = median_ms(args.reps, || {
        T::launch_tiled(&a, &b, &c_tiled, args.block_dim, dev)
    })?;
    let (t_plain, first_plain) = median_ms(args.reps, || T::launch_plain(&a, &b, &c_plain, dev))?;

    let entries = checked_entries(m, n, k, args.samples);
    let (got_tiled, got_plain) = (c_tiled.to_vec()?, c_plain.to_vec()?);
    let err_tiled = max_error(&got_tiled, &ah, &bh, (n, k), &entries);
    let err_plain = max_error(&got_plain, &ah, &bh, (n, k), &entries);
    let diff = got_tiled
        .iter()
        .zip(&got_plain)
        .map(|(&x, &y)| (x.into() - y.into()).abs())
        .fold(0.0, f64::max);
    let bound = k as f64 * T::U;
    let which = if entries.len() == m * n {
        format!("all {} entries", entries.len())
    } else {
        format!("{} sampled entries", entries.len())
    };
    let gflops = |ms: f64| 2.0 * (m * n * k) as f64 / (ms * 1e-3) / 1e9;

    println!(
        "\n{:<8} {:>12} {:>10} {:>14}   max |c - c64| / sum |a||b| ({which})",
        "kernel", "ms / GEMM", "GFLOP/s", "first run ms"
    );
    for (name, t, first, err) in [
        ("tiled", t_tiled, first_tiled, err_tiled),
        ("plain", t_plain, first_plain, err_plain),
    ] {
        println!(
            "{name:<8} {t:>12.3} {:>10.2} {first:>14.1}   {err:.2e}",
            gflops(t)
        );
    }
    println!(
        "\ntiled / plain time: {:.3} ({:.2}x {} than one thread per output); median of {} runs \
         after a warm-up (the first run includes compiling on a GPU)",
        t_tiled / t_plain,
        if t_tiled <= t_plain {
            t_plain / t_tiled
        } else {
            t_tiled / t_plain
        },
        if t_tiled <= t_plain {
            "faster"
        } else {
            "slower"
        },
        args.reps
    );
    println!(
        "max |tiled - plain| {diff:.2e} (each output one FMA chain in the tiled kernel; the plain \
         kernel's multiply-adds are fused or not as the backend's compiler decides)"
    );
    let ok = err_tiled <= bound && err_plain <= bound;
    common::verdict(
        "tile_matmul",
        ok,
        &format!("both errors <= k u = {bound:.2e}"),
    );
    Ok(ok)
}

fn main() -> wp::Result<()> {
    let args = Args::parse();
    let sizes = [args.m, args.n, args.k].map(|d| d.unwrap_or(args.size));
    if sizes.contains(&0) || args.reps == 0 || args.block_dim == 0 {
        // Refused before any device work, with clap's status for a bad command line.
        eprintln!(
            "tile_matmul: --m, --n, --k (or --size), --reps and --block-dim must be at least 1 \
             (got m, n, k = {sizes:?}, --reps {}, --block-dim {})",
            args.reps, args.block_dim
        );
        std::process::exit(2);
    }
    let dev = args.device.get()?;
    if args.f64 {
        run::<f64>(&args, &dev)?;
    } else {
        run::<f32>(&args, &dev)?;
    }
    common::print_compiled();
    Ok(())
}

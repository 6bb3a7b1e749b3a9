//! NVIDIA Warp's kernel-cache walkthrough, in Rust: a finite-difference kernel run with the
//! kernel cache moved to a chosen directory, then "edited" to a second-order difference,
//! which gives it a new cache key, so it is compiled again.
//!
//! ```text
//! cargo run --release --example finite_difference -- [--cache-dir DIR] [--n-max 4194304]
//!     [--device cpu|cuda:N] [--plot-dir DIR]
//! ```
//! The kernels (examples/common/finite_difference.rs) differentiate u(x) = sin(2 pi x) on the
//! periodic grid of n points of [0, 1): `first_order::finite_difference` by the forward
//! difference, `second_order::finite_difference` by the central one. Both have the same name
//! and signature, as in Warp's tutorial, where the kernel's body is edited between two runs.
//! For n = 64, 256, .. up to `--n-max`, in f32 and f64, the scene prints the largest error
//! against 2 pi cos(2 pi x) next to the time per launch, the truncation and rounding bounds,
//! and the observed order (about 1 and 2 until rounding, about eps/h, takes over: in f32
//! early, in f64 only for the second order near a million points); then the same check of the
//! kernels' adjoints (backward through a Tape).
//!
//! On a GPU it then prints what each kernel's first launch did, in the form of Warp's log
//! line (`Module .. load on device 'cuda:0' took 305.15 ms (compiled)`): compiled by NVRTC,
//! read from the disk cache, or an ahead-of-time cubin; the cache key (a hash of the generated
//! source, which includes the kernel's body and its file and lines, of the NVRTC options, the
//! architecture and the versions) and the entry's file; then every file in the cache
//! directory. The first run compiles each kernel variant; run it again and each is a cache
//! hit. The two orders' keys differ: a new body is a new key. (Warp compiles a Python
//! module, all its kernels forward and backward, into one binary with one hash; warp-lang
//! compiles each kernel variant on its own, the forward at its first launch and the adjoint
//! at the first backward through it, so there is a line, a key and a file per variant.)
//!
//! `--cache-dir` sets the directory (`warp_cuda::set_cache_dir`; default
//! `target/finite_difference_cache`, where the user-wide cache is
//! `~/.cache/warp-lang/<version>`); the environment variable `WARP_LANG_CACHE_DIR`, when set,
//! wins over both. Delete the directory to start cold.
//!
//! On the CPU there is no kernel cache: cargo compiled the kernels into this program, both
//! orders, both precisions, and their adjoints. The table is the same; the cache lines apply
//! to CUDA devices.

mod common;
#[path = "common/finite_difference.rs"]
mod fd;

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Parser;
use fd::{Order, Real};
use warp_lang as wp;
use warp_report::{sci, Run, Sweep, Table};

/// Warp's kernel-cache walkthrough: derivatives of sin(2 pi x) by forward and central
/// differences, in f32 and f64, their error as the grid is refined, and what each kernel's
/// first launch did (compiled, cache hit or ahead-of-time cubin).
#[derive(Parser)]
struct Cli {
    /// The kernel cache's directory on a GPU [default: target/finite_difference_cache]
    #[arg(long, value_name = "DIR")]
    cache_dir: Option<PathBuf>,
    /// The largest grid
    #[arg(long, value_name = "N", default_value = "4194304", value_parser = common::num::<usize>)]
    n_max: usize,
    #[command(flatten)]
    scene: common::SceneArgs,
}

fn main() -> wp::Result<()> {
    let cli = Cli::parse();
    cli.scene.no_recording("finite_difference");
    let dev = cli.scene.init()?;
    let n_max = cli.n_max;
    // The cache directory is set before the first launch (the first compile reads it).
    let cache_dir = cache_setup(&dev, cli.cache_dir);
    let sizes: Vec<usize> = (0..)
        .map(|k| 64usize << (2 * k))
        .take_while(|&n| n <= n_max.max(64))
        .collect();
    println!(
        "du/dx of u = sin(2 pi x) on periodic grids of {} to {} points, on \"{dev}\"",
        sizes[0],
        sizes[sizes.len() - 1]
    );

    let mut sweep = Sweep::new(
        format!(
            "finite differences on {dev}: max |du - 2 pi cos(2 pi x)|; time = `steps` launches"
        ),
        "n",
    )
    .with_extras(&["us/launch", "truncation bound", "rounding bound", "order"])
    .progress((4 * sizes.len()) as u64);
    for order in Order::ALL {
        series::<f32>(&mut sweep, order, &sizes, &dev)?;
        series::<f64>(&mut sweep, order, &sizes, &dev)?;
    }
    common::finish(&sweep, "finite_difference");
    print_orders(&sweep);
    adjoints(&dev)?;

    match cache_dir {
        Some(dir) => print_cache(&dev, &dir),
        None => println!(
            "\nkernel cache: none on the CPU. Cargo compiled these kernels (both orders, f32 \
             and f64, forward and adjoint) into this program; the cache lines (NVRTC compile \
             or disk-cache hit, cache key, entry files) apply to CUDA devices: run with \
             --device cuda:0 on a machine with a GPU."
        ),
    }
    common::print_compiled();
    Ok(())
}

/// On a CUDA device, points the kernel cache at `--cache-dir` (or the default) and returns
/// the directory in effect; on the CPU, `None`.
fn cache_setup(dev: &wp::Device, asked: Option<PathBuf>) -> Option<PathBuf> {
    if dev.is_cpu() {
        if let Some(d) = asked {
            println!(
                "--cache-dir {}: not used on the CPU (no kernel cache there)",
                d.display()
            );
        }
        return None;
    }
    let asked = asked.unwrap_or_else(|| "target/finite_difference_cache".into());
    warp_cuda::set_cache_dir(Some(asked.clone()));
    let dir = warp_cuda::cache_dir();
    if dir != asked {
        println!(
            "note: {} = {} wins over --cache-dir {}",
            warp_cuda::CACHE_DIR_ENV,
            dir.display(),
            asked.display()
        );
    }
    let before = files(&dir).len();
    println!(
        "kernel cache: {} ({before} file(s) there before this run)",
        dir.display()
    );
    Some(dir)
}

/// Runs `order`'s kernel in precision T at each size and records the error and the time.
fn series<T: Real>(
    sweep: &mut Sweep,
    order: Order,
    sizes: &[usize],
    dev: &wp::Device,
) -> wp::Result<()> {
    let name = format!("{} {}", order.name(), T::NAME);
    let mut prev: Option<(usize, f64)> = None;
    for &n in sizes {
        let u = wp::Array::from_slice(&fd::samples::<T>(n), dev)?;
        let du = wp::Array::<T>::zeros(n, dev)?;
        // Warm-up, outside the timing (on a GPU the first launch compiles or reads the cache).
        T::launch(order, &u, &du, dev)?;
        wp::synchronize()?;
        let launches = ((1usize << 24) / n).clamp(4, 1000);
        let t = Instant::now();
        for _ in 0..launches {
            T::launch(order, &u, &du, dev)?;
        }
        wp::synchronize()?;
        let seconds = t.elapsed().as_secs_f64();
        let err = fd::max_error(&du.to_vec()?);
        let mut run = Run::stable(launches as u64, err, seconds)
            .extra(seconds / launches as f64 * 1e6)
            .extra(order.truncation_bound(n))
            .extra(order.rounding_bound(n, T::EPS));
        if let Some((n0, e0)) = prev {
            run = run.extra((e0 / err).ln() / (n as f64 / n0 as f64).ln());
        }
        sweep.record(&name, n as f64, run);
        prev = Some((n, err));
    }
    Ok(())
}

/// Per series: the order fitted where truncation dominates, and the smallest error reached.
fn print_orders(sweep: &Sweep) {
    println!(
        "\nobserved order (log error against log n, over the sizes where the truncation \
         bound is at least 10x the rounding bound), and the smallest error:"
    );
    for name in sweep.series() {
        let rows: Vec<_> = sweep.rows().iter().filter(|r| r.series == name).collect();
        let clean: Vec<_> = rows
            .iter()
            .filter(|r| r.run.extras[1] >= 10.0 * r.run.extras[2])
            .collect();
        let fit = match (clean.first(), clean.last()) {
            (Some(a), Some(b)) if b.param > a.param => format!(
                "{:.2} over n = {}..{}",
                (a.run.error / b.run.error).ln() / (b.param / a.param).ln(),
                a.param,
                b.param
            ),
            _ => "- (rounding dominates from the start)".into(),
        };
        let best = rows
            .iter()
            .min_by(|a, b| a.run.error.total_cmp(&b.run.error))
            .expect("rows");
        let floor = if best.param < rows[rows.len() - 1].param {
            "; finer grids err more: rounding, about eps/h, grows as h shrinks"
        } else {
            ""
        };
        println!(
            "  {name:<14} {fit:<26} smallest error {} at n = {}{floor}",
            sci(best.run.error),
            best.param
        );
    }
    println!(
        "The error floor is rounding: the samples of u are stored to half an ulp (eps/2, eps = \
         {} in f32, {} in f64), and their difference over h carries up to eps/h (first \
         order) or eps/(2h) (second), the `rounding bound` column, which grows as the grid is \
         refined. Each series' error is smallest near the n where the two bounds meet: in \
         f32 around a thousand points (second order) or ten thousand (first); in f64 the \
         second order's near a million, the first order's beyond 4M (near 3e8).",
        sci(f32::EPSILON as f64),
        sci(f64::EPSILON)
    );
}

/// The kernels' adjoints: backward through a Tape with the seed cos(2 pi x), whose exact
/// answer is 2 pi sin(2 pi x) (see `fd::adjoint_error`), in f64.
fn adjoints(dev: &wp::Device) -> wp::Result<()> {
    let mut t = Table::new([
        "kernel",
        "n",
        "error of dL/du",
        "truncation bound",
        "order",
        "backward (ms)",
    ]);
    for order in Order::ALL {
        // Warm-up: on a GPU the first backward compiles (or reads) the adjoint.
        fd::adjoint_error(order, 64, dev)?;
        let mut prev: Option<(usize, f64)> = None;
        for n in [4096usize, 16384] {
            let (err, seconds) = fd::adjoint_error(order, n, dev)?;
            let p = prev.map_or("-".to_string(), |(n0, e0)| {
                format!("{:.2}", (e0 / err).ln() / (n as f64 / n0 as f64).ln())
            });
            t.push([
                format!("{} f64, adjoint", order.name()),
                n.to_string(),
                sci(err),
                sci(order.truncation_bound(n)),
                p,
                format!("{:.3}", seconds * 1e3),
            ]);
            prev = Some((n, err));
        }
    }
    println!(
        "\nbackward (the adjoint kernels, f64): L = sum w_i du_i with w = cos(2 pi x), so \
         dL/du = D^T w (D: the difference matrix), which approximates -w' = 2 pi sin(2 pi x) \
         to the same order; error = max |dL/du - 2 pi sin(2 pi x)|\n\n{t}"
    );
    Ok(())
}

/// The files in `dir`, sorted by name, with their sizes (none when it does not exist).
fn files(dir: &Path) -> Vec<(String, u64)> {
    let mut v: Vec<(String, u64)> = std::fs::read_dir(dir)
        .map(|it| {
            it.flatten()
                .map(|e| {
                    let size = e.metadata().map_or(0, |m| m.len());
                    (e.file_name().to_string_lossy().into_owned(), size)
                })
                .collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// `fd::first_order::finite_difference<f64>`: the report's kernel below the example's crate.
#[cfg(feature = "cuda")]
fn kernel_name(r: &wp::CompileReport) -> String {
    match r.module.split_once("::") {
        Some((_, inner)) => format!("{inner}::{}", r.kernel),
        None => r.kernel.to_string(),
    }
}

/// What each kernel variant's first launch did on `dev`, as Warp's log line, with its cache
/// key and entry; then the cache directory's files.
#[cfg(feature = "cuda")]
fn print_cache(dev: &wp::Device, dir: &Path) {
    let device = dev.alias();
    let reports: Vec<wp::CompileReport> = wp::compile_reports()
        .into_iter()
        .filter(|r| {
            r.device == device
                && Order::ALL
                    .iter()
                    .any(|o| r.module.ends_with(&format!("::{}", o.module())))
        })
        .collect();
    println!("\nkernel cache on {device}: what each kernel's first launch did");
    for r in &reports {
        let how = if r.aot {
            "ahead-of-time"
        } else if r.cache_hit {
            "cached"
        } else {
            "compiled"
        };
        let key = format!("{:032x}", r.cache_key);
        println!(
            "Module {} {} load on device '{device}' took {:.2} ms ({how})",
            kernel_name(r),
            &key[..7],
            r.total_ms
        );
        let entry = r.cache_entry.as_ref().map_or_else(
            || "not written (the directory is not writable)".to_string(),
            |p| match p.file_name() {
                // An ahead-of-time cubin is in its own directory, not the cache's.
                Some(f) if !r.aot => f.to_string_lossy().into_owned(),
                _ => p.display().to_string(),
            },
        );
        let nvrtc = if r.cache_hit {
            String::new()
        } else {
            format!(", NVRTC {:.1} ms", r.compile_ms)
        };
        println!(
            "    {}, {} variant, {} bytes of CUDA{nvrtc}; key {key}; entry {entry}",
            if r.adjoint { "adjoint" } else { "forward" },
            if r.contiguous {
                "contiguous"
            } else {
                "strided"
            },
            r.source_bytes
        );
    }
    let (first, second) = (
        key_of(&reports, Order::First),
        key_of(&reports, Order::Second),
    );
    if let (Some(a), Some(b)) = (first, second) {
        println!(
            "first_order and second_order both define `finite_difference<f64>`; their bodies \
             differ, so their sources and keys do ({:07x}.. and {:07x}..): the second order \
             has its own entry, and neither overwrote the other.",
            a >> 100,
            b >> 100
        );
    }
    if reports.iter().any(|r| !r.cache_hit) {
        println!("Run again: each line then says (cached).");
    }

    let mut t = Table::new(["file", "bytes", "what"]);
    for (name, size) in files(dir) {
        let used = reports.iter().find(|r| {
            r.cache_entry
                .as_ref()
                .and_then(|p| p.file_name())
                .is_some_and(|f| f.to_string_lossy() == name)
        });
        let what = match used {
            Some(r) => format!(
                "{}, {} ({} this run)",
                kernel_name(r),
                if r.adjoint { "adjoint" } else { "forward" },
                if r.cache_hit { "read" } else { "written" }
            ),
            None if name == "nvrtc-version" => {
                "the NVRTC version that last compiled here (warm hits need not load NVRTC)".into()
            }
            None => "not one of this run's kernel variants (another kernel, an earlier body, \
                 another NVRTC or crate version)"
                .into(),
        };
        t.push([name, size.to_string(), what]);
    }
    println!("\nfiles in {} after the run:\n\n{t}", dir.display());
}

#[cfg(feature = "cuda")]
fn key_of(reports: &[wp::CompileReport], order: Order) -> Option<u128> {
    reports
        .iter()
        .find(|r| {
            r.module.ends_with(&format!("::{}", order.module()))
                && r.kernel.contains("f64")
                && !r.adjoint
        })
        .map(|r| r.cache_key)
}

#[cfg(not(feature = "cuda"))]
fn print_cache(dev: &wp::Device, dir: &Path) {
    println!(
        "\nkernel cache on {dev}: this build has no `cuda` feature, so no compile reports \
         ({} not read)",
        dir.display()
    );
}

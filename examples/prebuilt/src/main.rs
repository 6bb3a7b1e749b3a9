//! Build-time compilation, end to end: `build.rs` compiled this crate's kernels (the autodiff
//! example's, forward and adjoint, both launch variants) to cubins; the binary points the
//! runtime at them (`wp::aot::set_aot_dir`) and runs the autodiff example's computation
//! without NVRTC: the seed function's value and derivative (the first result, against the
//! closed form), then the particle program's gradient.
//!
//! ```text
//! WARP_LANG_AOT_ARCHS=90 cargo run --release --manifest-path examples/prebuilt/Cargo.toml -- [--n 1000000] [--steps 100]
//! ```
//!
//! It prints the time from the start of `main` to the first result, the machine-readable
//! `cold_start ...` line (`benches/cold_start.rs` reads it: what loading the kernels cost, and
//! how many came from the cubins, the kernel cache or NVRTC) and the compile summary.
//!
//! - `--no-aot` ignores the cubins: a cold or warm start through NVRTC and the kernel cache,
//!   for comparison.
//! - `--check` only says whether the cubin directory holds every entry the launches will
//!   look for (forward and adjoint, both variants, each built architecture: the keys computed
//!   as the runtime computes them), without a GPU; it fails when the build compiled cubins
//!   and some are missing.
//! - `--first-result-only` stops after the first result.
//!
//! A shipped binary carries the cubin directory beside it as `prebuilt-cubins/` (or anywhere,
//! named by `WARP_LANG_AOT_DIR`, which wins); without one it uses the build's output directory.
//! On a GPU none of the built architectures serves (the same major version, equal or lower
//! minor), the kernels are compiled at first launch as usual.

#[path = "../../common/cli.rs"]
mod cli;
mod kernels;

use clap::Parser;
use kernels::seed_ad;
use std::path::PathBuf;
use std::time::Instant;
use warp_lang as wp;

/// The autodiff example's computation with its kernels compiled to cubins at `cargo build`:
/// the first result (the seed function and its derivative), then the particle gradient.
#[derive(Parser)]
struct Cli {
    /// Particles in the gradient run
    #[arg(long, default_value = "1_000_000", value_parser = cli::num::<usize>)]
    n: usize,
    /// Steps in the gradient run
    #[arg(long, default_value_t = 100, value_parser = cli::num::<usize>)]
    steps: usize,
    /// Ignore the cubins: a cold or warm start through NVRTC and the kernel cache
    #[arg(long)]
    no_aot: bool,
    /// Only say whether the cubin directory holds every entry the launches will look for
    /// (no GPU needed); fails when the build compiled cubins and some are missing
    #[arg(long)]
    check: bool,
    /// Stop after the first result
    #[arg(long)]
    first_result_only: bool,
    #[command(flatten)]
    device: cli::DeviceArg,
}

/// The cubin directory: `prebuilt-cubins` beside the binary (where a shipped binary carries
/// it), else the build's output directory.
fn cubin_dir() -> PathBuf {
    std::env::current_exe()
        .ok()
        .and_then(|p| p.parent().map(|d| d.join("prebuilt-cubins")))
        .filter(|d| d.is_dir())
        .unwrap_or_else(|| PathBuf::from(env!("PREBUILT_AOT_DIR")))
}

/// `--check`: whether the directory holds every entry, for each built architecture.
fn check() -> std::process::ExitCode {
    let dir = wp::aot::aot_dir().unwrap_or_else(cubin_dir);
    let archs: Vec<u32> = env!("PREBUILT_AOT_ARCHS")
        .split(',')
        .filter_map(|a| a.parse().ok())
        .collect();
    let checks = wp::aot::verify(&kernels::all(), &archs, &dir, true);
    let found = checks.iter().filter(|c| c.found).count();
    println!(
        "{found} of {} ahead-of-time entries found in {} (sm_{archs:?}; the build {} them)",
        checks.len(),
        dir.display(),
        if env!("PREBUILT_AOT_BUILT") == "1" {
            "compiled"
        } else {
            "did not compile"
        }
    );
    let built = env!("PREBUILT_AOT_BUILT") == "1";
    // (Without NVRTC at build time every entry is missing: nothing to list.)
    for c in checks.iter().filter(|c| built && !c.found).take(12) {
        println!(
            "  missing: {} {} {} sm_{}: {}",
            c.kernel,
            if c.adjoint { "adjoint" } else { "forward" },
            if c.contiguous {
                "contiguous"
            } else {
                "strided"
            },
            c.arch,
            c.path.display()
        );
    }
    if built && found < checks.len() {
        std::process::ExitCode::FAILURE
    } else {
        std::process::ExitCode::SUCCESS
    }
}

fn main() -> wp::Result<std::process::ExitCode> {
    let start = Instant::now();
    let cli = Cli::parse();
    if cli.check {
        return Ok(check());
    }
    if !cli.no_aot {
        wp::aot::set_aot_dir(Some(cubin_dir()));
    }
    let dev = cli.device.get()?;

    // 1. The seed function: the first result.
    let (f, df) = seed_ad::first_result(&dev)?;
    let line = seed_ad::cold_start_line(start, &dev, df);
    println!(
        "first result after {:.1} ms (from the start of main) on \"{dev}\"",
        start.elapsed().as_secs_f64() * 1e3
    );
    println!("{line}");
    let (want_f, want_df) = seed_ad::seed_closed_form(0.5);
    let (err_f, err_df) = (
        ((f - want_f) / want_f).abs(),
        ((df - want_df) / want_df).abs(),
    );
    println!(
        "f(0.5) = {f:.12} (relative error {err_f:.1e}), f'(0.5) = {df:.12} (relative error \
         {err_df:.1e})"
    );
    // f64 throughout: a relative error above 1e-12 (a few thousand ulps) is a wrong kernel.
    if err_f > 1e-12 || err_df > 1e-12 {
        eprintln!("the result disagrees with the closed form");
        return Ok(std::process::ExitCode::FAILURE);
    }
    println!(
        "ahead-of-time directory: {}",
        wp::aot::aot_dir().map_or("none (--no-aot)".into(), |d| d.display().to_string())
    );

    // 2. Gradients through the particle program.
    if !cli.first_result_only {
        seed_ad::particle_gradients(cli.n, cli.steps, &dev)?;
    }
    print!("{}", wp::compile_summary());
    Ok(std::process::ExitCode::SUCCESS)
}

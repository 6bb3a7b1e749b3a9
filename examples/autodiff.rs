//! Reverse-mode AD of the seed function f(x) = sin(x^2) ln x + x^3 / sqrt(1 - x^2) at
//! x = 0.5, where f'(0.5) = 0.7854595 (closed form in `common/seed_ad.rs`), plus the
//! 1M-particle gradient of the seed program's final positions: dL/dx0 = 2 x_T and
//! dL/dv0 = 2 c x_T for L = sum |x_T|^2, with r = 1 - b dt / m and c = dt (r + r^2 + ... + r^T).
//!
//! ```text
//! cargo run --release --example autodiff -- [--n 1000000] [--steps 100] [--device cpu|cuda:0] [--load]
//! ```
//! Runs on the GPU when there is one. `--load` compiles the three kernels and their adjoints
//! up front (`wp::load_with_adjoints`) instead of one by one at first launch; the time to the
//! first result is printed either way (cold: with an empty kernel cache), also as the
//! machine-readable `cold_start ...` line that `benches/cold_start.rs` reads. The same
//! computation with its kernels compiled at `cargo build`: `examples/prebuilt`.

#[path = "common/cli.rs"]
mod cli;
#[path = "common/seed_ad.rs"]
mod seed_ad;

use clap::Parser;
use seed_ad::{seed, step, sum_sq};
use std::time::Instant;
use warp_lang as wp;

/// Reverse-mode AD of the seed function against its closed-form derivative, then the
/// gradient of the particle program's loss with respect to the start state.
#[derive(Parser)]
struct Cli {
    /// Particles in the gradient run
    #[arg(long, default_value = "1_000_000", value_parser = cli::num::<usize>)]
    n: usize,
    /// Steps in the gradient run
    #[arg(long, default_value_t = 100, value_parser = cli::num::<usize>)]
    steps: usize,
    /// Compile the kernels and their adjoints up front (`wp::load_with_adjoints`) instead of
    /// at first launch
    #[arg(long)]
    load: bool,
    #[command(flatten)]
    device: cli::DeviceArg,
}

fn main() -> wp::Result<()> {
    let start = Instant::now();
    let cli = Cli::parse();
    let dev = cli.device.get()?;
    // The wall time of the up-front load (its units may compile side by side, so the sum of
    // their times is not it).
    let mut load_wall_ms = None;
    if cli.load {
        let kernels = [
            wp::kernel_info(seed),
            wp::kernel_info(step),
            wp::kernel_info(sum_sq),
        ];
        let t = Instant::now();
        wp::load_with_adjoints(&kernels, &dev)?;
        load_wall_ms = Some(t.elapsed().as_secs_f64() * 1e3);
    }

    // 1. The seed function.
    let (f, g) = seed_ad::first_result(&dev)?;
    let mut line = seed_ad::cold_start_line(start, &dev, g);
    if let Some(ms) = load_wall_ms {
        line.push_str(&format!(" load_wall_ms={ms:.1}"));
    }
    println!(
        "first result after {:.0} ms (from the start of main)",
        start.elapsed().as_secs_f64() * 1e3
    );
    println!("{line}");
    let (_, want) = seed_ad::seed_closed_form(0.5);
    println!("f(0.5)  = {f:.7}");
    println!(
        "f'(0.5) = {g:.7} (tape)   {want:.7} (closed form)   relative error {:.1e}",
        ((g - want) / want).abs()
    );

    // 2. Gradients through the particle program.
    seed_ad::particle_gradients(cli.n, cli.steps, &dev)?;
    // On a GPU: the forward kernels and, because backward ran, their adjoints.
    print!("{}", wp::compile_summary());
    Ok(())
}

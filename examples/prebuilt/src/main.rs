//! Build-time compilation, end to end: `build.rs` compiled this crate's kernels to cubins;
//! the binary points the runtime at them (`wp::aot::set_aot_dir`) and its first result
//! compiles nothing. It prints the time from the start of `main` to the first result (the
//! value and derivative of the autodiff example's seed function, against the closed form)
//! and what loading the kernels cost.
//!
//! ```text
//! WARP_LANG_AOT_ARCHS=90 cargo run --release --manifest-path examples/prebuilt/Cargo.toml
//! ```
//!
//! `--no-aot` ignores the cubins (a cold or warm start through NVRTC and the kernel cache,
//! for comparison). A shipped binary carries the cubin directory beside it as
//! `prebuilt-cubins/` (or anywhere, named by `WARP_LANG_AOT_DIR`, which wins); without one it
//! uses the build's output directory.

mod kernels;

use std::time::Instant;
use warp_lang as wp;

fn closed_form(x: f64) -> (f64, f64) {
    let s = (1.0 - x * x).sqrt();
    let f = (x * x).sin() * x.ln() + x * x * x / s;
    let df = 2.0 * x * (x * x).cos() * x.ln()
        + (x * x).sin() / x
        + (3.0 * x * x * s + x * x * x * x / s) / (1.0 - x * x);
    (f, df)
}

fn main() -> wp::Result<()> {
    let start = Instant::now();
    if !std::env::args().any(|a| a == "--no-aot") {
        // A `prebuilt-cubins` directory beside the binary (where a shipped binary carries
        // them), else the build's own output directory.
        let beside = std::env::current_exe()
            .ok()
            .and_then(|p| p.parent().map(|d| d.join("prebuilt-cubins")))
            .filter(|d| d.is_dir());
        let built = std::path::PathBuf::from(env!("PREBUILT_AOT_DIR"));
        wp::aot::set_aot_dir(Some(beside.unwrap_or(built)));
    }
    wp::config::set_quiet(true);
    let dev = wp::get_preferred_device();
    let x = wp::Array::from_slice(&[0.5f64], &dev)?.with_grad()?;
    let y = wp::Array::<f64>::zeros(1, &dev)?.with_grad()?;
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(kernels::seed, 1, (&x, &y), &dev)?;
    }
    tape.backward(&y)?;
    let (f, df) = (y.to_vec()?[0], x.grad().expect("with_grad").to_vec()?[0]);
    let first_ms = start.elapsed().as_secs_f64() * 1e3;
    let (want_f, want_df) = closed_form(0.5);
    let (err_f, err_df) = (
        (f - want_f).abs() / want_f.abs(),
        (df - want_df).abs() / want_df.abs(),
    );
    println!("first result after {first_ms:.1} ms (from the start of main) on \"{dev}\"");
    println!("f(0.5) = {f:.12} (error {err_f:.1e}), f'(0.5) = {df:.12} (error {err_df:.1e})");
    // f64 throughout: a relative error above 1e-12 (a few thousand ulps) is a wrong kernel.
    if err_f > 1e-12 || err_df > 1e-12 {
        eprintln!("the result disagrees with the closed form");
        std::process::exit(1);
    }
    let reports = wp::compile_reports();
    let load_ms: f64 = 0.0 + reports.iter().map(|r| r.total_ms).sum::<f64>();
    println!(
        "kernel loading: {load_ms:.2} ms for {} variant(s) (ahead-of-time dir {})",
        reports.len(),
        wp::aot::aot_dir().map_or("none".into(), |d| d.display().to_string())
    );
    print!("{}", wp::compile_summary());
    Ok(())
}

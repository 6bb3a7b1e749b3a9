//! GPU benchmark of first results: how long a fresh process takes to its first result when
//! the kernels come from NVRTC (an empty kernel cache), from the disk cache, and from cubins
//! compiled at `cargo build` (`examples/prebuilt`, whose build script compiles its kernels);
//! beside NVIDIA Warp 1.19 cold and warm in the same run (`benches/py/warp_cold_start.py`).
//! Each start is a new process; the computation is the autodiff example's seed function and
//! its derivative (one kernel, forward and adjoint), checked against the closed form.
//!
//! ```text
//! cargo build --release --example autodiff
//! WARP_LANG_AOT_ARCHS=90 cargo build --release --manifest-path examples/prebuilt/Cargo.toml
//! cargo bench --bench cold_start       # needs a CUDA device; SKIPPED otherwise
//! ```
//!
//! The binaries are looked for beside this one (as `.gpu/bin` holds them), in
//! `target/release/examples` and `examples/prebuilt/target/release`, or named by
//! `COLD_START_AUTODIFF` and `COLD_START_PREBUILT`.

use std::path::{Path, PathBuf};
use std::process::Command;
use warp_lang as wp;

mod common;
use common::{json_number, python_side};

/// The first existing path of `env` (when set), `names` beside this binary, and `fallbacks`.
fn find(env: &str, names: &[&str], fallbacks: &[&str]) -> Option<PathBuf> {
    if let Some(p) = std::env::var_os(env) {
        return Some(PathBuf::from(p)).filter(|p| p.is_file());
    }
    let here = std::env::current_exe().ok()?.parent()?.to_path_buf();
    names
        .iter()
        .map(|n| here.join(n))
        .chain(fallbacks.iter().map(PathBuf::from))
        .find(|p| p.is_file())
}

/// Runs `bin` with `args` and the kernel cache in `cache`; the numbers after `key` in the
/// lines that start with it.
fn run(bin: &Path, args: &[&str], cache: &Path, keys: &[&str]) -> Result<Vec<f64>, String> {
    let out = Command::new(bin)
        .args(args)
        .env("WARP_LANG_CACHE_DIR", cache)
        .env_remove("WARP_LANG_AOT_DIR")
        .output()
        .map_err(|e| format!("{}: {e}", bin.display()))?;
    let text = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        return Err(format!(
            "{} failed: {}",
            bin.display(),
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    keys.iter()
        .map(|key| {
            text.lines()
                .find_map(|l| l.trim_start().strip_prefix(key))
                .and_then(|rest| rest.split_whitespace().next())
                .and_then(|n| n.parse().ok())
                .ok_or_else(|| format!("no \"{key}\" line in the output of {}", bin.display()))
        })
        .collect()
}

fn main() {
    if let Err(e) = wp::get_device("cuda:0") {
        println!("cold_start bench SKIPPED: no CUDA device ({e})");
        return;
    }
    let autodiff = find(
        "COLD_START_AUTODIFF",
        &["autodiff"],
        &["target/release/examples/autodiff"],
    );
    let prebuilt = find(
        "COLD_START_PREBUILT",
        &["warp-prebuilt-example", "prebuilt"],
        &["examples/prebuilt/target/release/warp-prebuilt-example"],
    );
    let tmp = std::env::temp_dir().join(format!("wp-cold-start-{}", std::process::id()));
    let fresh = |name: &str| {
        let d = tmp.join(name);
        let _ = std::fs::remove_dir_all(&d);
        d
    };
    println!("first result in a fresh process (ms), the seed function and its derivative:");
    let first = "first result after";
    if let Some(bin) = &prebuilt {
        let cache = fresh("prebuilt");
        let keys = [first, "kernel loading:"];
        for (what, args) in [
            ("cold (NVRTC, empty cache)", &["--no-aot"][..]),
            ("warm (disk cache)", &["--no-aot"][..]),
            ("build-time cubins", &[][..]),
        ] {
            match run(bin, args, &cache, &keys) {
                Ok(v) => println!(
                    "  warp-lang {what:<28} first result {:8.1} ms   kernel loading {:8.2} ms",
                    v[0], v[1]
                ),
                Err(e) => println!("  warp-lang {what}: {e}"),
            }
        }
    } else {
        println!("  warp-lang (examples/prebuilt): its binary was not found; build it first");
    }
    if let Some(bin) = &autodiff {
        let cache = fresh("autodiff");
        for what in ["cold", "warm"] {
            match run(bin, &["--n", "1000", "--steps", "2"], &cache, &[first]) {
                Ok(v) => println!(
                    "  autodiff example, {what:<22} first result {:8.1} ms (six kernel variants by \
                     the end)",
                    v[0]
                ),
                Err(e) => println!("  autodiff example, {what}: {e}"),
            }
        }
    }
    let cache = fresh("warp");
    let dir = cache.display().to_string();
    for what in ["cold", "warm"] {
        match python_side("benches/py/warp_cold_start.py", std::slice::from_ref(&dir)) {
            Ok(j) => println!(
                "  Warp 1.19 {what:<28} first result {:8.1} ms   after wp.init() {:8.1} ms \
                 (init {:.0} ms)",
                json_number(&j, "first_result_ms").unwrap_or(f64::NAN),
                json_number(&j, "after_init_ms").unwrap_or(f64::NAN),
                json_number(&j, "init_ms").unwrap_or(f64::NAN)
            ),
            Err(e) => println!("  Warp 1.19 {what}: not run ({e})"),
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    println!(
        "(goals: cold no slower than Warp's first module, warm under 10 ms and build-time \
         cubins under 5 ms of kernel loading)"
    );
}

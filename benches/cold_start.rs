//! GPU benchmark of first results: how long a fresh process takes to its first result when
//! the kernels come from NVRTC (an empty kernel cache: cold), from the disk cache (warm), and
//! from cubins compiled at `cargo build` (`examples/prebuilt`, whose build script compiles
//! its kernels); beside NVIDIA Warp 1.19 cold and warm in the same run
//! (`benches/py/warp_cold_start.py`). Every start is a new process; the computation is the
//! autodiff example's first result: the seed function and its derivative through a tape (one
//! kernel, forward and adjoint), checked against the closed form by the example.
//!
//! ```text
//! cargo build --release --example autodiff
//! WARP_LANG_AOT_ARCHS=90 cargo build --release --manifest-path examples/prebuilt/Cargo.toml
//! cargo bench --bench cold_start       # needs a CUDA device; SKIPPED otherwise
//! ```
//!
//! The binaries are looked for beside this one (as `.gpu/bin` holds them: the prebuilt binary
//! with its `prebuilt-cubins/` directory), in `target/release/examples` and
//! `examples/prebuilt/target/release`, or named by `COLD_START_AUTODIFF` and
//! `COLD_START_PREBUILT`. `COLD_START_REPS` (default 3) starts per case; the medians are
//! printed. Warp's side needs `import warp` to work (`PYTHONPATH`); without it, that row says
//! why it did not run.
//!
//! Per case: the time from the child's `main` to its first result and from spawning it (both
//! include creating the CUDA context), the derivative's relative error against the closed form,
//! and what loading the kernels cost inside it (from each variant's first launch to a loaded
//! module, summed: NVRTC, or a cache or ahead-of-time file read, and the module load), the
//! slowest unit's NVRTC time, how many units the variants came in (a kernel's forward and
//! adjoint compiled as one unit count once) and where they came from, and each unit NVRTC
//! compiled with its time. The autodiff example's first start runs before its cases and is
//! printed apart (on a machine just booted it also reads libnvrtc from disk); its `--load`
//! case prints the load's wall time too, which its goal compares with the slowest unit. The
//! goals of the cold start follow the table.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;
use warp_lang as wp;

mod common;
use common::{json_number, python_side};
#[path = "../examples/common/seed_ad.rs"]
mod seed_ad;

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

/// One start: the child's `cold_start` line, and when it arrived after the spawn.
#[derive(Clone, Debug, Default)]
struct Start {
    first_ms: f64,
    spawn_ms: f64,
    rel_error: f64,
    loading_ms: f64,
    nvrtc_ms: f64,
    nvrtc_max_ms: f64,
    variants: f64,
    units: f64,
    nvrtc: f64,
    cache_hits: f64,
    aot: f64,
    /// Each unit NVRTC compiled: `kernel:halves:ms`, comma-separated.
    unit_ms: String,
    /// The wall time of `wp::load_with_adjoints` (the example's `--load`), NaN without it.
    load_wall_ms: f64,
}

/// The text after `key=` in a `cold_start ...` line.
fn text_field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
}

/// The number after `key=` in a `cold_start ...` line.
fn field(line: &str, key: &str) -> Option<f64> {
    text_field(line, key).and_then(|v| v.parse().ok())
}

/// Runs `bin` with `args`, the kernel cache in `cache` and the ahead-of-time directory unset
/// in its environment (the prebuilt binary sets its own unless `--no-aot`).
fn start(bin: &Path, args: &[&str], cache: &Path) -> Result<Start, String> {
    let t0 = Instant::now();
    let mut child = Command::new(bin)
        .args(args)
        .env("WARP_LANG_CACHE_DIR", cache)
        .env_remove("WARP_LANG_AOT_DIR")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| format!("{}: {e}", bin.display()))?;
    let stdout = child.stdout.take().expect("piped");
    let mut found = None;
    for line in BufReader::new(stdout).lines() {
        let Ok(line) = line else { break };
        if found.is_none() && line.starts_with("cold_start ") {
            let spawn_ms = t0.elapsed().as_secs_f64() * 1e3;
            let f = |k| field(&line, k).unwrap_or(f64::NAN);
            found = Some(Start {
                first_ms: f("first_result_ms"),
                spawn_ms,
                rel_error: f("rel_error"),
                loading_ms: f("kernel_loading_ms"),
                nvrtc_ms: f("nvrtc_ms"),
                nvrtc_max_ms: f("nvrtc_max_ms"),
                variants: f("variants"),
                units: f("units"),
                nvrtc: f("nvrtc"),
                cache_hits: f("cache_hits"),
                aot: f("aot"),
                unit_ms: text_field(&line, "unit_ms").unwrap_or("?").to_string(),
                load_wall_ms: f("load_wall_ms"),
            });
        }
    }
    let out = child
        .wait_with_output()
        .map_err(|e| format!("{}: {e}", bin.display()))?;
    if !out.status.success() {
        return Err(format!(
            "{} failed: {}",
            bin.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        ));
    }
    found.ok_or_else(|| format!("no cold_start line in the output of {}", bin.display()))
}

/// `reps` starts; `cache(k)` is the cache directory of start `k`. The medians, and the
/// counts of the last start.
fn case(
    bin: &Path,
    args: &[&str],
    reps: usize,
    cache: impl Fn(usize) -> PathBuf,
) -> Result<Start, String> {
    let runs = (0..reps)
        .map(|k| start(bin, args, &cache(k)))
        .collect::<Result<Vec<_>, _>>()?;
    let m = |f: fn(&Start) -> f64| common::median_of(runs.iter().map(f).collect());
    Ok(Start {
        first_ms: m(|s| s.first_ms),
        spawn_ms: m(|s| s.spawn_ms),
        loading_ms: m(|s| s.loading_ms),
        nvrtc_ms: m(|s| s.nvrtc_ms),
        nvrtc_max_ms: m(|s| s.nvrtc_max_ms),
        load_wall_ms: m(|s| s.load_wall_ms),
        rel_error: runs.iter().map(|s| s.rel_error).fold(0.0, f64::max),
        ..runs.last().expect("reps > 0").clone()
    })
}

/// One row of the table (and, when NVRTC compiled units, the units with their times); the
/// case's figures for the goals.
fn print_case(what: &str, r: &Result<Start, String>) -> Option<Start> {
    match r {
        Ok(s) => {
            println!(
                "  {what:<44} {:8.1} {:8.1} {:10.2} {:8.1} {:8.1} {:>9.1e}   {} variants in {} \
                 units: {} NVRTC, {} cache, {} ahead-of-time",
                s.first_ms,
                s.spawn_ms,
                s.loading_ms,
                s.nvrtc_ms,
                s.nvrtc_max_ms,
                s.rel_error,
                s.variants,
                s.units,
                s.nvrtc,
                s.cache_hits,
                s.aot
            );
            if s.nvrtc > 0.0 {
                println!("  {:<44} NVRTC per unit (ms): {}", "", s.unit_ms);
            }
            Some(s.clone())
        }
        Err(e) => {
            println!("  {what}: {e}");
            None
        }
    }
}

fn main() {
    let dev = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            println!("cold_start bench SKIPPED: no CUDA device ({e})");
            return;
        }
    };
    let reps: usize = std::env::var("COLD_START_REPS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(3)
        .max(1);
    let autodiff = find(
        "COLD_START_AUTODIFF",
        &["autodiff"],
        &["target/release/examples/autodiff"],
    );
    let prebuilt = find(
        "COLD_START_PREBUILT",
        &["warp-prebuilt-example"],
        &["examples/prebuilt/target/release/warp-prebuilt-example"],
    );
    let tmp = std::env::temp_dir().join(format!("wp-cold-start-{}", std::process::id()));
    let fresh = |name: String| {
        let d = tmp.join(name);
        let _ = std::fs::remove_dir_all(&d);
        d
    };
    println!(
        "first result in a fresh process on {dev} (the seed function and its derivative; \
         medians of {reps} starts):"
    );
    println!(
        "  {:<44} {:>8} {:>8} {:>10} {:>8} {:>8} {:>9}",
        "", "main ms", "spawn ms", "loading ms", "NVRTC ms", "max unit", "rel. err"
    );
    let (mut cold, mut warm, mut aot) = (None, None, None);
    if let Some(bin) = &prebuilt {
        let args = ["--first-result-only"];
        let no_aot = ["--first-result-only", "--no-aot"];
        let cold_dir = |k: usize| fresh(format!("prebuilt-cold-{k}"));
        cold = print_case(
            "warp-lang cold (NVRTC, empty cache)",
            &case(bin, &no_aot, reps, cold_dir),
        )
        .map(|s| s.loading_ms);
        // The cache the last cold start filled.
        let warm_dir = tmp.join(format!("prebuilt-cold-{}", reps - 1));
        warm = print_case(
            "warp-lang warm (disk cache)",
            &case(bin, &no_aot, reps, |_| warm_dir.clone()),
        )
        .map(|s| s.loading_ms);
        let r = case(bin, &args, reps, |k| fresh(format!("prebuilt-aot-{k}")));
        aot = print_case("warp-lang build-time cubins (empty cache)", &r).map(|s| s.loading_ms);
        if let Ok(s) = &r {
            if s.nvrtc > 0.0 || s.aot < s.variants {
                println!(
                    "    ({} of {} variants did not come from the cubins: built for another \
                     architecture than this GPU's? `{} --check` says what is there)",
                    s.variants - s.aot,
                    s.variants,
                    bin.display()
                );
            }
        }
    } else {
        println!(
            "  warp-lang (examples/prebuilt): its binary was not found; build it first \
             (cargo build --release --manifest-path examples/prebuilt/Cargo.toml)"
        );
    }
    let (mut example_cold, mut example_load) = (None, None);
    if let Some(bin) = &autodiff {
        let small = ["--n", "1000", "--steps", "2"];
        // A first start after the machine booted also reads libnvrtc and the driver's
        // libraries from disk (250-450 ms more on the H200 machines): shown apart, so the
        // medians are of starts that find them in the OS's cache, as later runs do.
        print_case(
            "autodiff example, first start alone, cold",
            &start(bin, &small, &fresh("autodiff-first".into())),
        );
        let cold_dir = |k: usize| fresh(format!("autodiff-cold-{k}"));
        example_cold = print_case("autodiff example, cold", &case(bin, &small, reps, cold_dir));
        // The cache the last cold start filled.
        let warm_dir = tmp.join(format!("autodiff-cold-{}", reps - 1));
        print_case(
            "autodiff example, warm",
            &case(bin, &small, reps, |_| warm_dir.clone()),
        );
        let load = ["--n", "1000", "--steps", "2", "--load"];
        let r = case(bin, &load, reps, |k| fresh(format!("autodiff-load-{k}")));
        example_load = print_case("autodiff example --load (six variants), cold", &r);
        if let Some(s) = example_load.as_ref().filter(|s| s.load_wall_ms.is_finite()) {
            println!(
                "  {:<44} the load's wall time {:.1} ms (the loading column sums each \
                 variant's wait)",
                "", s.load_wall_ms
            );
        }
    }
    let warp_dir = fresh("warp".into()).display().to_string();
    let mut warp_cold = None;
    for what in ["cold", "warm"] {
        match python_side(
            "benches/py/warp_cold_start.py",
            std::slice::from_ref(&warp_dir),
        ) {
            Ok(j) => {
                let n = |k| json_number(&j, k).unwrap_or(f64::NAN);
                let (_, want) = seed_ad::seed_closed_form(0.5);
                println!(
                    "  {:<44} {:8.1} {:>8} {:10.2} {:>8} {:>8} {:>9.1e}   one module, forward \
                     and backward (import warp {:.0} ms, wp.init() {:.0} ms; main ms: from after \
                     wp.init(), {:.0} ms from the start of the process)",
                    format!("Warp 1.19 {what}"),
                    n("after_init_ms"),
                    "-",
                    n("load_ms"),
                    "-",
                    "-",
                    ((n("grad") - want) / want).abs(),
                    n("import_ms"),
                    n("init_ms"),
                    n("first_result_ms")
                );
                if what == "cold" {
                    warp_cold = Some(n("load_ms"));
                }
            }
            Err(e) => println!("  Warp 1.19 {what}: not run ({e})"),
        }
    }
    let _ = std::fs::remove_dir_all(&tmp);
    let verdict = |ok: Option<bool>| match ok {
        Some(true) => "met",
        Some(false) => "NOT met",
        None => "not measured",
    };
    println!(
        "goals: cold kernel loading no slower than Warp's first module ({}), warm under 10 ms \
         ({}), build-time cubins under 5 ms ({})",
        verdict(cold.zip(warp_cold).map(|(c, w)| c <= w)),
        verdict(warm.map(|w| w < 10.0)),
        verdict(aot.map(|a| a < 5.0))
    );
    // The cold start's own: the autodiff example's first result from an empty cache, NVRTC
    // per unit, and a load of several units in about its slowest unit's time (a fifth more,
    // for the module loads and the copies of NVRTC).
    let load_ratio = example_load
        .as_ref()
        .filter(|s| s.nvrtc_max_ms > 0.0 && s.load_wall_ms.is_finite())
        .map(|s| s.load_wall_ms / s.nvrtc_max_ms);
    println!(
        "goals: autodiff example's first result cold at most 300 ms ({}), at most 100 ms of \
         NVRTC a unit ({}), its --load of {} units in at most 1.2 times its slowest unit ({}{})",
        verdict(example_cold.as_ref().map(|s| s.first_ms <= 300.0)),
        verdict(
            example_cold
                .iter()
                .chain(&example_load)
                .map(|s| s.nvrtc_max_ms <= 100.0)
                .reduce(|a, b| a && b)
        ),
        example_load.as_ref().map_or(f64::NAN, |s| s.units),
        verdict(load_ratio.map(|r| r <= 1.2)),
        load_ratio.map_or(String::new(), |r| format!(": {r:.2}x"))
    );
}

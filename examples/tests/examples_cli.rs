//! Every example's command line (clap): `--help` prints its usage and exits 0, an unknown
//! option is refused with exit status 2. `cargo test` builds the examples before it runs the
//! tests, into `target/<profile>/examples/`, beside this test's own `deps/` directory; the
//! test runs those binaries (a few milliseconds each: neither path initialises a device).
//! A binary that is missing (`cargo test --test examples_cli` alone builds no example) or
//! older than its sources is skipped, saying so.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::SystemTime;

/// The examples: `examples/<name>.rs` (every file there is one; this crate's folder).
fn example_names() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .expect("the examples directory")
        .filter_map(|e| {
            let path = e.ok()?.path();
            (path.extension()? == "rs").then(|| path.file_stem()?.to_str().map(String::from))?
        })
        .collect();
    names.sort();
    names
}

/// Where cargo put the examples of this test's profile: this binary is
/// `target/<profile>/deps/examples_cli-<hash>`.
fn examples_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("the test binary's path");
    exe.parent()
        .and_then(Path::parent)
        .expect("target/<profile>/deps")
        .join("examples")
}

fn modified(path: &Path) -> Option<SystemTime> {
    std::fs::metadata(path).ok()?.modified().ok()
}

/// The newest modification time of the example's own sources under `examples/`: those that
/// cargo's dep-info file beside the binary (`<name>.d`: `binary: source source ..`) lists,
/// else the example's file alone.
fn sources_modified(name: &str, bin_dir: &Path) -> Option<SystemTime> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut newest = modified(&root.join(format!("{name}.rs")))?;
    if let Ok(dep_info) = std::fs::read_to_string(bin_dir.join(format!("{name}.d"))) {
        let sources = dep_info.split_once(": ").map_or("", |(_, s)| s);
        // (A path with a space is escaped as `\ ` and split here: none under examples/ has one.)
        for src in sources.split_whitespace().map(Path::new) {
            if src.starts_with(root) {
                newest = newest.max(modified(src).unwrap_or(newest));
            }
        }
    }
    Some(newest)
}

/// The example's binary, or None (printing SKIPPED and why) when it is missing or older than
/// its sources.
fn fresh_binary(name: &str, dir: &Path) -> Option<PathBuf> {
    let bin = dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
    let Some(built) = modified(&bin) else {
        eprintln!(
            "SKIPPED examples_cli {name}: {} not built (cargo test builds the examples; \
             `--test examples_cli` alone does not)",
            bin.display()
        );
        return None;
    };
    if sources_modified(name, dir).is_some_and(|src| src > built) {
        eprintln!(
            "SKIPPED examples_cli {name}: {} is older than its sources",
            bin.display()
        );
        return None;
    }
    Some(bin)
}

/// A fresh folder under the target directory for one test's files.
fn scratch(test: &str) -> PathBuf {
    let dir = examples_dir().join(format!("{test}-scratch"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create the scratch folder");
    dir
}

/// particles with `--rerun <file>` on the CPU, small: 1000 particles, 20 steps, no sweep.
fn run_particles_recording(bin: &Path, dir: &Path, rrd: &Path) -> std::process::Output {
    Command::new(bin)
        .args([
            "--device",
            "cpu",
            "--n",
            "1000",
            "--steps",
            "20",
            "--sweep-n",
            "0",
        ])
        .arg("--plot-dir")
        .arg(dir)
        .arg("--rerun")
        .arg(rrd)
        .output()
        .expect("run particles --rerun")
}

/// Without the `rerun` feature, `--rerun` is refused (exit status 2) with the way to get it,
/// before anything runs: no file appears.
#[cfg(not(feature = "rerun"))]
#[test]
fn rerun_option_without_the_feature_is_refused() {
    let dir = examples_dir();
    let Some(bin) = fresh_binary("particles", &dir) else {
        return;
    };
    let scratch = scratch("rerun_refused");
    let rrd = scratch.join("particles.rrd");
    let out = run_particles_recording(&bin, &scratch, &rrd);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--rerun") && err.contains("--features rerun"),
        "the error does not say how to get --rerun:\n{err}"
    );
    assert!(!rrd.exists(), "{} was written", rrd.display());
}

/// With the `rerun` feature: particles records its 20 steps (a frame a step: 21 frames with
/// the start) and the file reads back through rerun's own decoder, every frame of the
/// particles and their box present on the `frame` timeline.
#[cfg(feature = "rerun")]
#[test]
fn rerun_recording_reads_back_with_every_frame() {
    use rerun::external::re_log_encoding::DecoderApp;
    use rerun::log::{Chunk, LogMsg};
    use std::collections::{BTreeMap, BTreeSet};

    let dir = examples_dir();
    let Some(bin) = fresh_binary("particles", &dir) else {
        return;
    };
    let scratch = scratch("rerun_recording");
    let rrd = scratch.join("particles.rrd");
    let out = run_particles_recording(&bin, &scratch, &rrd);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "particles --rerun: {:?}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("(21 frames"), "{stdout}");
    let size = std::fs::metadata(&rrd).map(|m| m.len()).unwrap_or(0);
    assert!(size > 0, "{} is missing or empty", rrd.display());

    // Entity path -> the `frame` indices its chunks hold.
    let mut frames: BTreeMap<String, BTreeSet<i64>> = BTreeMap::new();
    let file = std::fs::File::open(&rrd).expect("open the recording");
    for msg in DecoderApp::decode_lazy(std::io::BufReader::new(file)) {
        let msg = msg.unwrap_or_else(|e| panic!("decoding {}: {e}", rrd.display()));
        if let LogMsg::ArrowMsg(_, arrow) = msg {
            let chunk = Chunk::from_arrow_msg(&arrow).expect("a chunk");
            let indices = frames.entry(chunk.entity_path().to_string()).or_default();
            for (name, column) in chunk.timelines() {
                if name.as_str() == "frame" {
                    indices.extend(column.times_raw().iter().copied());
                }
            }
        }
    }
    let all: BTreeSet<i64> = (0..=20).collect();
    for entity in [
        "/particles/points/0",
        "/particles/lines/0",
        "/particles/caption",
    ] {
        assert_eq!(
            frames.get(entity),
            Some(&all),
            "{entity}'s frames in {} (entities: {:?})",
            rrd.display(),
            frames.keys().collect::<Vec<_>>()
        );
    }
}

#[test]
fn every_example_has_help_and_refuses_unknown_options() {
    let names = example_names();
    assert!(names.len() >= 10, "found only {names:?} in examples/");
    let dir = examples_dir();
    let mut checked = Vec::new();
    for name in &names {
        let Some(bin) = fresh_binary(name, &dir) else {
            continue;
        };

        let help = Command::new(&bin)
            .arg("--help")
            .output()
            .expect("run --help");
        let out = String::from_utf8_lossy(&help.stdout);
        assert!(
            help.status.success(),
            "{name} --help: {:?}\n{out}",
            help.status
        );
        // The multi-GPU examples pick their devices by count (`--gpus`), the others by name.
        let device_option = if name.starts_with("multi_gpu_") {
            "--gpus <GPUS>"
        } else {
            "--device <NAME>"
        };
        assert!(
            out.contains("Usage:") && out.contains(device_option),
            "{name} --help does not list its usage and {device_option}:\n{out}"
        );
        // The struct's doc comment is the first line of the help: every example says what it does.
        assert!(
            !out.starts_with("Usage:"),
            "{name} --help has no description:\n{out}"
        );

        let bad = Command::new(&bin)
            .arg("--no-such-option")
            .output()
            .expect("run --no-such-option");
        let err = String::from_utf8_lossy(&bad.stderr);
        assert_eq!(
            bad.status.code(),
            Some(2),
            "{name} --no-such-option: {:?}\n{err}",
            bad.status
        );
        assert!(
            err.contains("--no-such-option"),
            "{name}: the error does not name the option:\n{err}"
        );
        checked.push(name.as_str());
    }
    eprintln!(
        "examples_cli: checked {} of {} examples: {checked:?}",
        checked.len(),
        names.len()
    );
}

/// Every `examples/<name>.rs` is an example of this crate: cargo looks for a package's
/// examples in `<package>/examples/`, so this crate lists its own (`[[example]]` in its
/// Cargo.toml), and a file left out of the list would be built by nobody.
#[test]
fn every_example_file_is_listed_in_the_manifest() {
    let manifest =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("Cargo.toml"))
            .expect("examples/Cargo.toml");
    let listed: Vec<&str> = manifest
        .lines()
        .filter_map(|l| l.trim().strip_prefix("path = \""))
        .filter_map(|p| p.strip_suffix(".rs\""))
        .collect();
    let missing: Vec<String> = example_names()
        .into_iter()
        .filter(|n| !listed.contains(&n.as_str()))
        .collect();
    assert!(
        missing.is_empty(),
        "examples/*.rs not listed as [[example]] in examples/Cargo.toml: {missing:?}"
    );
}

/// tile_mlp on the CPU, a few steps: the tiled network's first-step gradients agree with the
/// plain network's, the loss is printed, and with a loose tolerance the verdict passes.
#[test]
fn tile_mlp_trains_briefly_on_the_cpu() {
    let dir = examples_dir();
    let Some(bin) = fresh_binary("tile_mlp", &dir) else {
        return;
    };
    let out = Command::new(&bin)
        .args([
            "--device",
            "cpu",
            "--samples",
            "256",
            "--iterations",
            "20",
            "--tol",
            "10",
        ])
        .output()
        .expect("run tile_mlp");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "tile_mlp: {:?}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    for want in ["first-step gradients", "step     20: loss", "verdict: PASS"] {
        assert!(stdout.contains(want), "no {want:?} in:\n{stdout}");
    }
}

/// tile_cholesky on the CPU, a small batch: its verdict (the backward error within 4 N eps)
/// is yes, exit status 0.
#[test]
fn tile_cholesky_solves_a_small_batch_on_the_cpu() {
    let dir = examples_dir();
    let Some(bin) = fresh_binary("tile_cholesky", &dir) else {
        return;
    };
    let out = Command::new(&bin)
        .args(["--device", "cpu", "--batch", "8", "--reps", "1"])
        .output()
        .expect("run tile_cholesky");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "tile_cholesky: {:?}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("converged: yes"), "{stdout}");
}

/// tile_fft on the CPU, a small batch: its verdict (the error against a float64 DFT within
/// 4 eps log2 N) is yes, exit status 0.
#[test]
fn tile_fft_transforms_a_small_batch_on_the_cpu() {
    let dir = examples_dir();
    let Some(bin) = fresh_binary("tile_fft", &dir) else {
        return;
    };
    let out = Command::new(&bin)
        .args(["--device", "cpu", "--rows", "64", "--reps", "1"])
        .output()
        .expect("run tile_fft");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "tile_fft: {:?}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("converged: yes"), "{stdout}");
}

/// tile_matmul on the CPU, small and ragged (70 is not a multiple of the 64-wide tiles): it
/// runs the tiled and the plain GEMM, prints both rows with their errors and the ratio, and its
/// verdict (the errors within the FMA bound k u) is yes, exit status 0.
#[test]
fn tile_matmul_runs_small_on_the_cpu() {
    let dir = examples_dir();
    let Some(bin) = fresh_binary("tile_matmul", &dir) else {
        return;
    };
    let out = Command::new(&bin)
        .args([
            "--device", "cpu", "--m", "70", "--n", "33", "--k", "45", "--reps", "1",
        ])
        .output()
        .expect("run tile_matmul");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "tile_matmul: {:?}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    for want in [
        "all 2310 entries",
        "\ntiled ",
        "\nplain ",
        "tiled / plain time",
        "converged: yes",
    ] {
        assert!(stdout.contains(want), "no {want:?} in:\n{stdout}");
    }

    // A zero size is refused before any work, naming the options.
    let bad = Command::new(&bin)
        .args(["--device", "cpu", "--size", "0"])
        .output()
        .expect("run tile_matmul --size 0");
    let err = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(bad.status.code(), Some(2), "{err}");
    assert!(err.contains("--size") && err.contains("[0, 0, 0]"), "{err}");
}

/// tile_nbody on the CPU, small and ragged (130 bodies: not a multiple of the 64-body tiles nor
/// of the 48-thread blocks): both kernels' rows, the same bits from both, the range probes
/// finite or reported, and its verdict (the accelerations within (n + 16) u of float64) yes,
/// exit status 0. A zero body count is refused before any work, naming the options.
#[test]
fn tile_nbody_runs_small_on_the_cpu() {
    let dir = examples_dir();
    let Some(bin) = fresh_binary("tile_nbody", &dir) else {
        return;
    };
    let out = Command::new(&bin)
        .args([
            "--device",
            "cpu",
            "--n",
            "130",
            "--steps",
            "3",
            "--block-dim",
            "48",
        ])
        .output()
        .expect("run tile_nbody");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "tile_nbody: {:?}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    for want in [
        "\ntiled ",
        "\nscalar ",
        "tiled / scalar time",
        "the same bits for all 130 bodies",
        "two coincident bodies and a third",
        "reported: tiled n-body accelerations diverged",
        "reported: scalar n-body accelerations diverged",
        "converged: yes",
    ] {
        assert!(stdout.contains(want), "no {want:?} in:\n{stdout}");
    }

    let bad = Command::new(&bin)
        .args(["--device", "cpu", "--n", "0"])
        .output()
        .expect("run tile_nbody --n 0");
    let err = String::from_utf8_lossy(&bad.stderr);
    assert_eq!(bad.status.code(), Some(2), "{err}");
    assert!(err.contains("--n") && err.contains("Some(0)"), "{err}");
}

//! Every example's command line (clap): `--help` prints its usage and exits 0, an unknown
//! option is refused with exit status 2. `cargo test` builds the examples before it runs the
//! tests, into `target/<profile>/examples/`, beside this test's own `deps/` directory; the
//! test runs those binaries (a few milliseconds each: neither path initialises a device).
//! A binary that is missing (`cargo test --test examples_cli` alone builds no example) or
//! older than its sources is skipped, saying so.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::SystemTime;

/// The examples: `examples/<name>.rs` (every file there is one).
fn example_names() -> Vec<String> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
    let mut names: Vec<String> = std::fs::read_dir(&dir)
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
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("examples");
    let mut newest = modified(&root.join(format!("{name}.rs")))?;
    if let Ok(dep_info) = std::fs::read_to_string(bin_dir.join(format!("{name}.d"))) {
        let sources = dep_info.split_once(": ").map_or("", |(_, s)| s);
        // (A path with a space is escaped as `\ ` and split here: none under examples/ has one.)
        for src in sources.split_whitespace().map(Path::new) {
            if src.starts_with(&root) {
                newest = newest.max(modified(src).unwrap_or(newest));
            }
        }
    }
    Some(newest)
}

#[test]
fn every_example_has_help_and_refuses_unknown_options() {
    let names = example_names();
    assert!(names.len() >= 10, "found only {names:?} in examples/");
    let dir = examples_dir();
    let mut checked = Vec::new();
    for name in &names {
        let bin = dir.join(format!("{name}{}", std::env::consts::EXE_SUFFIX));
        let Some(built) = modified(&bin) else {
            eprintln!(
                "SKIPPED examples_cli {name}: {} not built (cargo test builds the examples; \
                 `--test examples_cli` alone does not)",
                bin.display()
            );
            continue;
        };
        if sources_modified(name, &dir).is_some_and(|src| src > built) {
            eprintln!(
                "SKIPPED examples_cli {name}: {} is older than its sources",
                bin.display()
            );
            continue;
        }

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
        assert!(
            out.contains("Usage:") && out.contains("--device <NAME>"),
            "{name} --help does not list its usage and --device:\n{out}"
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

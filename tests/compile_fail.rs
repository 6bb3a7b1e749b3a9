//! The language's compile-time errors: constructs outside the kernel subset, type errors and
//! wrong launch arguments fail at `cargo build`, pointing at the user's own code.
//! Regenerate the expected output with `TRYBUILD=overwrite cargo test --test compile_fail`.
//!
//! The expected output is rustc's, verbatim, and rustc's wording and layout change between
//! releases (under 1.88, 23 of the 29 cases differ from 1.95's: a lint note, how trait-bound
//! failures and const-evaluation panics are rendered, the line-number gutter). So the snapshots
//! belong to one release, the one rust-toolchain.toml pins; under it they are compared. Under
//! any other rustc (the MSRV run in .ci/run, a user's `cargo +stable test`) every case must
//! still fail to compile, but its message is not compared.

use std::path::{Path, PathBuf};
use std::process::Command;

/// `major.minor` of a version such as "1.95.0" or "1.96.0-nightly".
fn release(version: &str) -> Option<String> {
    let mut parts = version.split(['.', '-']);
    Some(format!("{}.{}", parts.next()?, parts.next()?))
}

/// The release the snapshots were written by: rust-toolchain.toml's `channel`.
fn snapshot_release() -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("rust-toolchain.toml");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    let channel = text
        .lines()
        .filter_map(|l| l.trim().strip_prefix("channel"))
        .filter_map(|rest| rest.trim().strip_prefix('='))
        .map(|v| v.trim().trim_matches('"'))
        .next()
        .unwrap_or_else(|| panic!("no `channel = \"...\"` in {}", path.display()));
    release(channel).unwrap_or_else(|| panic!("channel {channel:?} is not a version"))
}

/// The release of the rustc that trybuild's cargo will run (rustup passes `+toolchain` on
/// to child processes through RUSTUP_TOOLCHAIN), e.g. "1.88" from "rustc 1.88.0 (...)".
fn running_release() -> Option<String> {
    let out = Command::new("rustc").arg("--version").output().ok()?;
    let text = String::from_utf8(out.stdout).ok()?;
    release(text.split_whitespace().nth(1)?)
}

#[test]
fn compile_fail() {
    // trybuild drives cargo; a machine with the test binary but no toolchain (the GPU host)
    // cannot run it.
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    if Command::new(&cargo).arg("--version").output().is_err() {
        eprintln!("SKIPPED compile_fail: no cargo on this machine");
        return;
    }
    let want = snapshot_release();
    let running = running_release();
    if running.as_deref() == Some(want.as_str()) {
        let t = trybuild::TestCases::new();
        t.compile_fail("tests/ui/*.rs");
        return;
    }
    eprintln!(
        "compile_fail: rustc {} is not {want}, the release the snapshots are of \
         (rust-toolchain.toml): checking that every case fails to compile, not the messages",
        running.as_deref().unwrap_or("(unknown)")
    );
    // The cases copied without their .stderr files, and trybuild told to write rather than
    // compare: it still fails a case that compiles.
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("compile_fail_any_rustc");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let ui = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/ui");
    let mut cases = 0;
    for entry in std::fs::read_dir(&ui).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "rs") {
            std::fs::copy(&path, dir.join(path.file_name().unwrap())).unwrap();
            cases += 1;
        }
    }
    assert!(cases > 0, "no cases in {}", ui.display());
    // SAFETY (of the environment write): the only test of this binary; trybuild reads it below.
    std::env::set_var("TRYBUILD", "overwrite");
    let t = trybuild::TestCases::new();
    t.compile_fail(dir.join("*.rs"));
}

//! The block emulator's warp-synchronous operations (`warp-cuda/cuda/tests/wp_prim_emu.h`:
//! `__syncwarp`, the shuffles, `__ballot_sync`, `__match_any_sync`), which the host tests of
//! the tile headers and the primitives rely on to show races the GPU could have: a driver
//! (`warp-cuda/cuda/tests/wp_warp_emu_driver.cpp`) runs small kernels of two warps and prints
//! what they saw. A shared-memory exchange between lanes with its `__syncwarp` missing must show
//! stale reads; with it, none; a warp must get through its own barriers while the other waits at
//! `__syncthreads`; and the misuses a GPU would hang on abort.
//!
//! Skipped, saying so, without g++.

#[path = "common/host_cpp.rs"]
mod host_cpp;

use std::process::{Command, Output};
use std::sync::OnceLock;

/// The driver, compiled once per process.
fn driver() -> &'static std::path::Path {
    static EXE: OnceLock<std::path::PathBuf> = OnceLock::new();
    EXE.get_or_init(|| {
        host_cpp::compile_driver(
            "warp_emu",
            include_str!("../warp-cuda/cuda/tests/wp_warp_emu_driver.cpp"),
            &[],
        )
        .1
    })
}

fn run(case: &str) -> Output {
    Command::new(driver()).arg(case).output().unwrap()
}

/// The case's one line of output, which must have exited cleanly.
fn line(case: &str) -> String {
    let out = run(case);
    assert!(
        out.status.success(),
        "{case}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap().trim().to_string()
}

fn skip() -> bool {
    let no = !host_cpp::gpp();
    if no {
        eprintln!("SKIPPED cuda_warp_emu_host: no g++ on this machine");
    }
    no
}

#[test]
fn a_missing_syncwarp_shows_as_stale_reads() {
    if skip() {
        return;
    }
    // Lanes run in a shuffled order between warp barriers: some read their neighbour's slot
    // before it is written (64 reads; all in order would be a 1 in 32! chance per warp).
    let race = line("race");
    let stale: usize = race.strip_prefix("stale ").unwrap().parse().unwrap();
    assert!(stale > 0, "no stale read without __syncwarp: {race}");
    assert_eq!(line("synced"), "stale 0");
}

#[test]
fn warps_pass_their_own_barriers_independently() {
    if skip() {
        return;
    }
    // Five warp-barrier exchanges in warp 1 while warp 0 waits; one block barrier in all.
    assert_eq!(line("independent"), "ok 1");
}

#[test]
fn shuffles_exchange_within_a_warp() {
    if skip() {
        return;
    }
    assert_eq!(line("shfl"), "ok");
}

#[test]
fn votes_and_matches_within_a_warp() {
    if skip() {
        return;
    }
    assert_eq!(line("vote"), "ok");
}

#[test]
fn misused_warp_barriers_abort() {
    if skip() {
        return;
    }
    for (case, says) in [
        ("divergent", "incomplete __syncwarp"),
        ("exited", "a lane of the mask has left the kernel"),
        (
            "mixed",
            "lanes of one mask are in different warp collectives",
        ),
        (
            "past_block",
            "__ballot_sync with a mask past the block's end",
        ),
        ("up_outside", "__shfl_up_sync reads a lane outside the mask"),
    ] {
        let out = run(case);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{case} finished: {err}");
        assert!(err.contains(says), "{case}: {err}");
    }
}

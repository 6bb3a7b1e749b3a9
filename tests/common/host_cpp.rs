//! Compiling a CUDA library driver as host C++, for the tests that run the library's headers
//! on the CPU and compare them with warp-core bit for bit (geometry, volumes, their builds,
//! marching cubes): one set of g++ flags for all of them (C++17, warnings as errors, no FMA
//! contraction, so the host arithmetic rounds as NVRTC's `--fmad=false` and as Rust do).

use std::path::PathBuf;
use std::process::Command;

/// Whether g++ is on this machine (the tests skip, loudly, without it).
pub fn gpp() -> bool {
    Command::new("g++").arg("--version").output().is_ok()
}

/// Writes `source` to a fresh directory under the temp dir named after `name` and the
/// process, compiles it with the library's headers, the test headers beside them
/// (`cuda/tests/`: the block emulator) and `defines` (`-DNAME=1` for a bare `NAME`,
/// `-DNAME=VALUE` as given), and returns the directory and the executable.
///
/// # Panics
/// When g++ fails, with its messages.
pub fn compile_driver(name: &str, source: &str, defines: &[&str]) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("wp_{name}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (cpp, exe) = (dir.join(format!("{name}.cpp")), dir.join(name));
    std::fs::write(&cpp, source).unwrap();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let out = Command::new("g++")
        .args([
            "-std=c++17",
            "-O1",
            "-ffp-contract=off",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-Wdouble-promotion",
        ])
        .args(defines.iter().map(|d| match d.contains('=') {
            true => format!("-D{d}"),
            false => format!("-D{d}=1"),
        }))
        .args(["-I", include, "-I", &format!("{include}/tests")])
        .arg(&cpp)
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "g++: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (dir, exe)
}

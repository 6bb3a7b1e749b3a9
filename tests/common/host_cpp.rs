//! Compiling a CUDA library driver as host C++, for the tests that run the library's headers
//! on the CPU and compare them with warp-core bit for bit (geometry, volumes, their builds,
//! marching cubes): one set of g++ flags for all of them (C++17, warnings as errors, no FMA
//! contraction, so the host arithmetic rounds as NVRTC's `--fmad=false` and as Rust do).
//! `run_unit` also runs a scene's generated kernel units (fem, the implicit cloth) the same way.

// Each test that includes this module uses part of it.
#![allow(dead_code)]

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
    let flags = ["-Wall", "-Wextra", "-Werror", "-Wdouble-promotion"]
        .map(String::from)
        .into_iter()
        .chain(defines.iter().map(|d| match d.contains('=') {
            true => format!("-D{d}"),
            false => format!("-D{d}=1"),
        }))
        .collect::<Vec<_>>();
    compile(name, source, &flags)
}

/// g++ with the flags every host build shares (C++17, -O1, no FMA contraction, the library's
/// and the test headers' folders) and `flags`, on `source` written to a fresh directory.
fn compile(name: &str, source: &str, flags: &[String]) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("wp_{name}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (cpp, exe) = (dir.join(format!("{name}.cpp")), dir.join(name));
    std::fs::write(&cpp, source).unwrap();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let out = Command::new("g++")
        .args(["-std=c++17", "-O1", "-ffp-contract=off"])
        .args(flags)
        .args(["-I", include, "-I", &format!("{include}/tests")])
        .arg(&cpp)
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "g++ ({name}): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (dir, exe)
}

/// Runs a kernel's CUDA translation unit (`unit`: the text the runtime assembles for NVRTC,
/// whose thread function is `thread`) as host C++ over the flat indices `0..dim`, for the
/// tests that hold a scene's generated kernels to the CPU backend. `decl` declares the
/// thread function's arguments `p0`, `p1`, .. (`nargs` of them) and their storage; after the
/// threads, `print` prints the outputs one number a line, which come back parsed as `T`.
/// The unit is compiled as the runtime compiles a contiguous variant (`WP_CONTIGUOUS`), with
/// unused-variable warnings allowed (generated code leaves temporaries unread).
///
/// # Panics
/// When g++ fails, or when a thread raises a fault (the fault's kind is in the message).
pub fn run_unit<T: std::str::FromStr>(
    name: &str,
    unit: &str,
    thread: &str,
    nargs: usize,
    decl: &str,
    print: &str,
    dim: usize,
) -> Vec<T>
where
    T::Err: std::fmt::Debug,
{
    let params: Vec<String> = (0..nargs).map(|k| format!("p{k}")).collect();
    let program = format!(
        "#include <cstring>\n#include <cstdio>\n{unit}\nint main() {{\n{decl}\n\
         wp::fault_t fault = {{}}; unsigned int flag = 0;\n\
         wp::launch_ctx_t rec = wp::launch_ctx_make(&fault, &flag);\n\
         wp::ctx_t ctx = wp::ctx_make(&rec);\n\
         wp::launch_t launch = {{{{{dim}, 1, 1, 1}}, {dim}, 1, 1}};\n\
         for (wp::i64 flat = 0; flat < {dim}; ++flat) {thread}({params}, launch, flat, &ctx);\n\
         if (flag) {{ printf(\"fault %d\\n\", fault.kind); return 1; }}\n{print}\nreturn 0;\n}}\n",
        params = params.join(", ")
    );
    let flags = ["-Wno-unused", "-DWP_CONTIGUOUS=1"].map(String::from);
    let (_, exe) = compile(name, &program, &flags);
    let run = Command::new(&exe).output().unwrap();
    assert!(
        run.status.success(),
        "{name}: {}",
        String::from_utf8_lossy(&run.stdout)
    );
    String::from_utf8(run.stdout)
        .unwrap()
        .lines()
        .map(|l| l.parse().unwrap())
        .collect()
}

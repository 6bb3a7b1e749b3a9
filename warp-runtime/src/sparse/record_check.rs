//! Tests only: the step records' layouts and the constants against their C++ side. The sizes
//! are asserted on both sides at compile time, but two swapped fields of one size (`rows` and
//! `cols`) keep the size; g++'s `offsetof` of every field catches them.

/// `(C++ struct, field, Rust offset)` of every listed field of every record:
/// `record_layouts![Rust<T> => "c_struct_t" { field, .. }, ..]`.
macro_rules! record_layouts {
    ($($rust:ty => $c:literal { $($f:ident),* $(,)? }),* $(,)?) => {
        vec![$($(($c, stringify!($f), std::mem::offset_of!($rust, $f))),*),*]
    };
}

/// Compiles `header` (a file of warp-cuda/cuda, included as the block-emulator tests include
/// it) with a program printing `offsetof` of each field, and compares its output with the
/// Rust offsets. Skipped, saying so (naming `test`), without g++.
pub(super) fn check_record_offsets(test: &str, header: &str, fields: &[(&str, &str, usize)]) {
    const CUDA_DIR: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../warp-cuda/cuda");
    if std::process::Command::new("g++")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("SKIPPED {test}: no g++ on this machine");
        return;
    }
    let mut src = format!(
        "#include <cstddef>\n#include <cstdio>\n#include \"wp_prim_emu.h\"\n\
         #define __global__\n#define __device__ inline\n#define __shared__ static\n\
         #include \"{header}\"\nusing namespace wp;\n\
         #define P(T, f) printf(\"%s %s %zu\\n\", #T, #f, offsetof(T, f))\n\
         int main() {{\n"
    );
    for (c, f, _) in fields {
        src += &format!("  P({c}, {f});\n");
    }
    src += "  return 0;\n}\n";
    // A directory per test and process: the tests run in parallel threads.
    let dir = std::env::temp_dir().join(format!("wp_{test}_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (cpp, exe) = (dir.join("offsets.cpp"), dir.join("offsets"));
    std::fs::write(&cpp, src).unwrap();
    let out = std::process::Command::new("g++")
        .args([
            "-std=c++17",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-I",
            CUDA_DIR,
            "-I",
        ])
        .arg(format!("{CUDA_DIR}/tests"))
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
    let out = std::process::Command::new(&exe).output().unwrap();
    let got = String::from_utf8(out.stdout).unwrap();
    let want: String = fields
        .iter()
        .map(|(c, f, o)| format!("{c} {f} {o}\n"))
        .collect();
    assert_eq!(got, want);
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every `constexpr i32|i64 NAME = value` of `header` whose name starts with `prefix` (several
/// per declaration), for the tests that compare them with Rust's constants.
pub(super) fn header_constants(header: &str, prefix: &str) -> Vec<(String, i64)> {
    let mut out = vec![];
    for decl in header.split("constexpr ").skip(1) {
        let decl = &decl[..decl.find(';').expect("a declaration ends with `;`")];
        let Some(rest) = decl
            .strip_prefix("i32 ")
            .or_else(|| decl.strip_prefix("i64 "))
        else {
            continue;
        };
        for item in rest.split(',') {
            let (name, value) = item.split_once('=').expect("NAME = value");
            let name = name.trim();
            if name.starts_with(prefix) {
                out.push((name.to_string(), value.trim().parse().expect("an integer")));
            }
        }
    }
    out
}

//! Compiles the crate's kernels to cubins at `cargo build`, for the architectures in
//! `WARP_LANG_AOT_ARCHS` (`90,80`, ..) or `warp_lang::aot::DEFAULT_ARCHS`, with their adjoints
//! (the binary differentiates). Needs NVRTC (`libnvrtc.so`) on the build machine, not a GPU;
//! without it the build goes on with a warning and the binary compiles at first launch.

use std::path::PathBuf;
use warp_lang as wp;

#[path = "src/kernels.rs"]
mod kernels;

fn main() {
    println!("cargo:rerun-if-changed=src/kernels.rs");
    println!("cargo:rerun-if-env-changed={}", wp::aot::ARCHS_ENV);
    let dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("cubins");
    println!("cargo:rustc-env=PREBUILT_AOT_DIR={}", dir.display());
    let archs = match wp::aot::archs_from_env() {
        Ok(a) => a,
        Err(e) => panic!("{e}"),
    };
    // A fresh directory: entries of kernels since changed would only take space.
    let _ = std::fs::remove_dir_all(&dir);
    match wp::aot::compile_with_adjoints(&kernels::all(), &archs, &dir) {
        Ok(entries) => {
            let ms: f64 = entries.iter().map(|e| e.compile_ms).sum();
            println!(
                "cargo:warning=prebuilt: {} cubins for sm_{:?} in {:.0} ms of NVRTC",
                entries.len(),
                archs,
                ms
            );
        }
        Err(e) => println!(
            "cargo:warning=prebuilt: kernels not compiled at build time ({e}); the binary \
             will compile them at first launch"
        ),
    }
}

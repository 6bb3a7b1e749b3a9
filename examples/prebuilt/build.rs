//! Compiles the crate's kernels to cubins at `cargo build`, for the architectures in
//! `WARP_LANG_AOT_ARCHS` (`90,80`, ..) or `warp_lang::aot::DEFAULT_ARCHS`, with their adjoints
//! (the binary differentiates), into `$OUT_DIR/cubins`, which the binary finds through
//! `PREBUILT_AOT_DIR`. Needs NVRTC (`libnvrtc.so`) on the build machine, not a GPU; without
//! it the build goes on with a warning and the binary compiles its kernels at first launch.

use std::path::PathBuf;
use warp_lang as wp;

// The build script compiles the kernels' Rust definitions itself (a build script can only
// call code it is built with).
#[path = "src/kernels.rs"]
mod kernels;

fn main() {
    println!("cargo:rerun-if-changed=src/kernels.rs");
    println!("cargo:rerun-if-changed=../common/seed_ad.rs");
    println!("cargo:rerun-if-env-changed={}", wp::aot::ARCHS_ENV);
    // Where NVRTC is found: a build without it is run again once it is there.
    println!("cargo:rerun-if-env-changed=LD_LIBRARY_PATH");
    let dir = PathBuf::from(std::env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("cubins");
    println!("cargo:rustc-env=PREBUILT_AOT_DIR={}", dir.display());
    // Entries of an earlier build (other architectures, older kernels) go.
    let _ = std::fs::remove_dir_all(&dir);
    let archs = match wp::aot::archs_from_env() {
        Ok(a) => a,
        Err(e) => panic!("{e}"),
    };
    let list = archs
        .iter()
        .map(u32::to_string)
        .collect::<Vec<_>>()
        .join(",");
    println!("cargo:rustc-env=PREBUILT_AOT_ARCHS={list}");
    let t = std::time::Instant::now();
    match wp::aot::compile_with_adjoints(&kernels::all(), &archs, &dir) {
        Ok(entries) => {
            let ms: f64 = entries.iter().map(|e| e.compile_ms).sum();
            println!("cargo:rustc-env=PREBUILT_AOT_BUILT=1");
            println!(
                "cargo:warning=prebuilt: {} cubins for sm_{{{list}}} ({:.0} ms of NVRTC in \
                 {:.1} s)",
                entries.len(),
                ms,
                t.elapsed().as_secs_f64()
            );
        }
        Err(e) => {
            println!("cargo:rustc-env=PREBUILT_AOT_BUILT=0");
            println!(
                "cargo:warning=prebuilt: kernels not compiled at build time ({e}); the binary \
                 will compile them with NVRTC at first launch"
            );
        }
    }
}

//! A machine with a GPU driver but no NVRTC (the CUDA toolkit's runtime compiler): the
//! preferred device is the CPU, with a reason naming NVRTC, while `get_device("cuda:0")` still
//! opens the GPU and a launch there that needs a compile is an error naming NVRTC.
//!
//! `WARP_LANG_NO_NVRTC=1` makes the NVRTC probe fail on a machine that has it, so this runs on
//! the GPU machine too. A test binary of its own: the probe runs once per process, and the
//! variable must be set before it (one `#[test]`, so no other thread runs meanwhile).

use warp_lang as wp;
use wp::prelude::*;

#[wp::kernel]
fn add_one(a: Array<f32>) {
    let i = tid();
    a[i] = a[i] + 1.0;
}

#[test]
fn without_nvrtc_the_preferred_device_is_the_cpu() {
    // SAFETY (of the environment writes): the only test of this binary, before any thread of
    // ours reads the environment.
    std::env::set_var(warp_cuda::NO_NVRTC_ENV, "1");
    // A fresh, empty kernel cache: a cubin cached by an earlier run needs no NVRTC and would
    // let the GPU launch below succeed.
    let cache = std::env::temp_dir().join(format!("warp-lang-no-nvrtc-{}", std::process::id()));
    std::env::set_var("WARP_LANG_CACHE_DIR", &cache);
    std::env::remove_var("WARP_LANG_AOT_DIR");

    let why = warp_cuda::nvrtc_version().unwrap_err().to_string();
    assert!(
        why.contains("NVRTC turned off by WARP_LANG_NO_NVRTC"),
        "{why}"
    );

    // The preferred device is the CPU, whether or not there is a GPU; and it works.
    let preferred = wp::get_preferred_device();
    assert!(preferred.is_cpu(), "{preferred}");
    let a = wp::Array::<f32>::zeros(8, &preferred).unwrap();
    wp::launch(add_one, 8, (&a,), &preferred).unwrap();
    assert_eq!(a.to_vec().unwrap(), vec![1.0; 8]);

    let gpu = match wp::get_device("cuda:0") {
        Ok(gpu) => gpu,
        Err(e) => {
            // No GPU: nothing was skipped for NVRTC's sake, so there is no reason to give.
            assert_eq!(wp::cpu_fallback_reason(), None);
            eprintln!("SKIPPED no_nvrtc (GPU half): no CUDA device ({e})");
            let _ = std::fs::remove_dir_all(&cache);
            return;
        }
    };
    let reason = wp::cpu_fallback_reason().expect("a GPU is present but not preferred");
    assert_eq!(reason, "no NVRTC: NVRTC turned off by WARP_LANG_NO_NVRTC");

    // The GPU itself still works (memory, copies) ...
    let b = wp::Array::<f32>::zeros(8, &gpu).unwrap();
    assert_eq!(b.to_vec().unwrap(), vec![0.0; 8]);
    // ... but a kernel compiled at first launch cannot be: an error naming NVRTC, no panic.
    // The chain (as anyhow prints it): the message names the device, its source NVRTC.
    let err = wp::launch(add_one, 8, (&b,), &gpu).unwrap_err();
    let mut source: Option<&dyn std::error::Error> = Some(&err);
    let mut text = Vec::new();
    while let Some(s) = source {
        text.push(s.to_string());
        source = s.source();
    }
    let err = text.join(": ");
    assert!(err.contains("NVRTC"), "{err}");
    assert!(err.contains("cuda:0"), "{err}");
    let _ = std::fs::remove_dir_all(&cache);
}

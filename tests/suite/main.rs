//! The runtime test suite of warp-lang: every construct of the kernel language, run on every
//! backend and compared with the same computation written in plain Rust on the host.
//!
//! Each test is a plain function `fn name(dev: &wp::Device)`. A module lists its tests once,
//! in `backend_tests!(..)`, which instantiates every one of them for every backend:
//! `module::cpu_backend::name` runs it on the CPU, `module::cuda_backend::name` on `cuda:0`
//! (or the GPU named by `WARP_TEST_CUDA_DEVICE`, e.g. `cuda:1`, to run the whole suite on
//! another GPU of a multi-GPU machine), or prints `SKIPPED` when there is no such device.
//!
//! Numeric comparisons are exact wherever the operation is exact or deterministic. On the CPU
//! a kernel runs exactly the Rust arithmetic the host reference runs (rustc never contracts
//! `a * b + c` into an FMA), so even multi-step float results are compared bit for bit there;
//! on CUDA the compiler may contract into FMAs and the transcendental functions are not the
//! host's, so [`fma_rel`] and [`math_rel`] give a relative tolerance there (see each).

use warp_lang as wp;

/// Instantiates the listed test functions of the calling module for every backend. A test may
/// carry attributes (`#[ignore = "macro bug: .."]`), which both instances get.
macro_rules! backend_tests {
    ($($(#[$attr:meta])* $name:ident),* $(,)?) => {
        /// The module's tests on the CPU backend.
        mod cpu_backend {
            $(
                #[test]
                $(#[$attr])*
                fn $name() {
                    super::$name(&::warp_lang::cpu());
                }
            )*
        }

        /// The module's tests on the first CUDA device (or `WARP_TEST_CUDA_DEVICE`); each prints
        /// that it skipped when there is none.
        mod cuda_backend {
            $(
                #[test]
                $(#[$attr])*
                fn $name() {
                    match ::warp_lang::get_device(&crate::test_gpu()) {
                        Ok(dev) => {
                            // One test at a time on the GPU: some exhaust its memory
                            // (`out_of_memory_then_usable`) or time it. (Faults need no lock:
                            // each thread has its own fault record.) Debug mode makes each
                            // launch report its own faults (as on the CPU).
                            let _gpu = crate::gpu_lock();
                            ::warp_lang::config::set_debug(true);
                            super::$name(&dev)
                        }
                        Err(e) => eprintln!(
                            "SKIPPED {}::{}: no CUDA device ({e})",
                            module_path!(),
                            stringify!($name)
                        ),
                    }
                }
            )*
        }
    };
}

/// An error and its sources, as anyhow's `{:#}` prints them: messages that moved into a
/// source (the API guidelines' rule: a message does not repeat its source) are still found.
fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        text += &format!(": {s}");
        source = s.source();
    }
    text
}

/// The GPU the CUDA instances run on: `WARP_TEST_CUDA_DEVICE`, else `cuda:0`.
fn test_gpu() -> String {
    std::env::var("WARP_TEST_CUDA_DEVICE").unwrap_or_else(|_| "cuda:0".to_string())
}

/// Serialises the CUDA instances of the tests (see `backend_tests!`).
fn gpu_lock() -> std::sync::MutexGuard<'static, ()> {
    static LOCK: std::sync::Mutex<()> = std::sync::Mutex::new(());
    // A failed test poisons the lock; the next test still gets the GPU.
    LOCK.lock().unwrap_or_else(|p| p.into_inner())
}

mod arith;
mod arrays;
mod asserts;
mod atomics;
mod bf16;
mod bsr;
mod builtins;
mod bvh;
mod checkpoint;
mod coloring;
mod control;
mod decomp;
mod deterministic;
mod dlpack;
mod errors;
mod euler;
mod extreme;
mod f16;
mod func_grad;
mod funcs;
mod generics;
mod grad;
mod graph;
mod graph_builds;
mod hash_grid;
mod host_objects;
mod interop;
mod jvp;
mod lanes;
mod launch;
mod lbvh;
mod lerp;
mod local_arrays;
mod mesh;
mod misc;
mod nonsquare;
mod ops;
mod ops_xla;
mod optim;
mod overloads;
mod params;
mod ports;
mod primitives;
mod race;
mod refs_tuples;
mod rng;
mod scenes;
mod sparse;
mod sparse_grad;
mod spatial;
mod stability;
mod streams;
mod structs;
mod tile_convert;
mod tile_fft;
mod tile_funcs;
mod tile_grad;
mod tile_grad_adj;
mod tile_grad_linalg;
mod tile_linalg;
mod tile_sort;
mod tile_views;
mod tiles;
mod tiles_f16;
mod tiles_nd;
mod transforms;
mod views;
mod volume;

/// A 1-D array holding `data` on `dev`.
fn arr<T: wp::Element>(data: &[T], dev: &wp::Device) -> wp::Array<T> {
    wp::Array::from_slice(data, dev).expect("array from slice")
}

/// A zero-filled array of the given shape on `dev`.
fn zeros<T: wp::Element, const N: usize>(
    shape: impl wp::IntoShape<N>,
    dev: &wp::Device,
) -> wp::Array<T, N> {
    wp::Array::zeros(shape, dev).expect("zeros")
}

/// The elements of `a`, row-major.
fn host<T: wp::Element, const N: usize>(a: &wp::Array<T, N>) -> Vec<T> {
    a.to_vec().expect("to_vec")
}

/// Relative tolerance for f32 results of several roundings (`a * b + c`, matrix products, dot
/// products). The CPU kernel runs the very same Rust arithmetic as the host reference: 0, i.e.
/// bit-exact. CUDA may contract a multiply and an add into an FMA, which changes the last bits:
/// 1e-6 relative.
fn fma_rel(dev: &wp::Device) -> f32 {
    if dev.is_cpu() {
        0.0
    } else {
        1e-6
    }
}

/// Relative tolerance for f32 transcendental functions (sin, exp, pow, ...). The CPU builtins
/// call the same `std` functions as the host reference: 0, bit-exact. CUDA's `sinf`, `expf`,
/// `powf`, ... are within a few ulp of the correctly rounded result, and FMA contraction may
/// add another: 1e-5 relative.
fn math_rel(dev: &wp::Device) -> f32 {
    if dev.is_cpu() {
        0.0
    } else {
        1e-5
    }
}

/// [`fma_rel`] for f64 results: 0 on the CPU, 1e-15 relative on CUDA (FMA contraction).
fn fma_rel64(dev: &wp::Device) -> f64 {
    if dev.is_cpu() {
        0.0
    } else {
        1e-15
    }
}

/// `got` equals `want` within `rel` relative to the larger magnitude (NaN equals NaN; `rel = 0`
/// asks for bit-exact equality up to the sign of zero).
#[track_caller]
fn assert_close_f32(got: f32, want: f32, rel: f32, what: &str) {
    let ok = got == want
        || (got.is_nan() && want.is_nan())
        || (got - want).abs() <= rel * got.abs().max(want.abs());
    assert!(
        ok,
        "{what}: got {got:e}, want {want:e} (relative tolerance {rel:e})"
    );
}

/// [`assert_close_f32`] for f64.
#[track_caller]
fn assert_close_f64(got: f64, want: f64, rel: f64, what: &str) {
    let ok = got == want
        || (got.is_nan() && want.is_nan())
        || (got - want).abs() <= rel * got.abs().max(want.abs());
    assert!(
        ok,
        "{what}: got {got:e}, want {want:e} (relative tolerance {rel:e})"
    );
}

/// Compares two vectors (or matrices) of f32 components normwise: each component within
/// `rel` times the largest magnitude in `want`. Componentwise relative error is the wrong
/// measure for sums of products: a component that cancels to almost zero carries an error of
/// the size of its terms (about one ulp of the vector's norm), which FMA contraction changes.
#[track_caller]
fn assert_close_slice(got: &[f32], want: &[f32], rel: f32, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    let scale = want.iter().fold(0.0f32, |m, w| m.max(w.abs()));
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        let ok = g == w || (g.is_nan() && w.is_nan()) || (g - w).abs() <= rel * scale;
        assert!(ok, "{what} [component {k}]: got {g:e}, want {w:e} (tolerance {rel:e} x max |want| = {scale:e})");
    }
}

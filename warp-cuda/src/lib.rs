//! CUDA backend of warp-lang: the driver layer.
//!
//! Built on [cudarc]'s driver and NVRTC bindings, loaded with dlopen at run time, so this crate
//! builds and runs on machines without CUDA: there, [`probe`] returns the reason and every
//! fallible call returns [`CudaError::NotAvailable`]. Nothing panics when CUDA is missing.
//!
//! Layout (as in cudarc):
//! - [`error`]: [`CudaError`], [`Result`];
//! - [`device`]: [`probe`], [`GpuInfo`], [`Gpu`] (primary context + default stream),
//!   [`Stream`], [`Event`];
//! - [`memory`]: [`DeviceBuffer`] (untyped, stream-ordered), [`PinnedBuffer`];
//! - [`compile`](mod@compile): NVRTC to cubin ([`compile()`], [`CompileOptions`], [`nvrtc_version`]);
//! - [`cache`]: the on-disk kernel cache ([`compile_cached`], [`KernelCache`]);
//! - [`launch`]: [`Module`], [`Function`], [`Gpu::launch_raw`];
//! - [`nccl`]: NCCL communicators and collectives, loaded at run time ([`nccl::Comm`]);
//! - [`graph`]: stream capture ([`Stream::begin_capture`]) and replay ([`Graph`]).
//!
//! Diagnostics go to the `log` facade, with the module as target: `warp_cuda::device` (what
//! the probe found, or why not), `warp_cuda::compile` (each NVRTC compile and its time),
//! `warp_cuda::cache` (hits and misses at debug level, damaged or unwritable entries as
//! warnings). warp-runtime's `config` module lists every target and level.
//!
//! The CUDA C++ builtin library (the `.cuh` sections named in the builtin table) lives in
//! `cuda/` and is embedded by the code generator.

#![warn(missing_docs)]

pub mod cache;
pub mod compile;
pub mod device;
pub mod error;
pub mod graph;
pub mod launch;
pub mod memory;
pub mod nccl;

#[cfg(test)]
mod gpu_tests;

pub use cache::{
    aot_key, cache_dir, cache_key, clear_kernel_cache, compile_cached, set_cache_dir, CacheLookup,
    CacheOutcome, KernelCache, CACHE_DIR_ENV,
};
pub use compile::{
    compile, cudadevrt_path, nvrtc_supported_archs, nvrtc_version, CompileOptions, Compiled,
    CUDADEVRT_ENV,
};
pub use device::{driver_version, probe, Event, Gpu, GpuInfo, Stream, MIN_DRIVER_VERSION};
pub use error::{CudaError, Result};
pub use graph::{Conditional, Graph, CONDITIONAL_DRIVER_VERSION};
pub use launch::{Function, Module};
pub use memory::{DeviceBuffer, PinnedBuffer};

/// The raw bindings, for callers that need a driver call this crate does not wrap.
pub use cudarc;

/// The CUDA builtin library, embedded: `(name, contents)` pairs to hand to NVRTC as in-memory
/// headers. `wp_core.h` is always needed; the others are the sections of the builtin table.
pub const HEADERS: &[(&str, &str)] = &[
    ("wp_core.h", include_str!("../cuda/wp_core.h")),
    ("wp_scalar.h", include_str!("../cuda/wp_scalar.h")),
    ("wp_vector.h", include_str!("../cuda/wp_vector.h")),
    ("wp_linalg.h", include_str!("../cuda/wp_linalg.h")),
    ("wp_transform.h", include_str!("../cuda/wp_transform.h")),
    ("wp_svd.h", include_str!("../cuda/wp_svd.h")),
    ("wp_misc.h", include_str!("../cuda/wp_misc.h")),
    ("wp_atomic.h", include_str!("../cuda/wp_atomic.h")),
    ("wp_rand.h", include_str!("../cuda/wp_rand.h")),
    ("wp_hash_grid.h", include_str!("../cuda/wp_hash_grid.h")),
    (
        "wp_marching_cubes.h",
        include_str!("../cuda/wp_marching_cubes.h"),
    ),
    ("wp_bvh_build.h", include_str!("../cuda/wp_bvh_build.h")),
    (
        "wp_volume_build.h",
        include_str!("../cuda/wp_volume_build.h"),
    ),
    ("wp_geometry.h", include_str!("../cuda/wp_geometry.h")),
    ("wp_bvh.h", include_str!("../cuda/wp_bvh.h")),
    ("wp_mesh.h", include_str!("../cuda/wp_mesh.h")),
    ("wp_volume.h", include_str!("../cuda/wp_volume.h")),
    ("wp_print.h", include_str!("../cuda/wp_print.h")),
    ("wp_primitives.h", include_str!("../cuda/wp_primitives.h")),
    ("wp_adjoint.h", include_str!("../cuda/wp_adjoint.h")),
    (
        "wp_adjoint_core.h",
        include_str!("../cuda/wp_adjoint_core.h"),
    ),
    (
        "wp_adjoint_builtins.h",
        include_str!("../cuda/wp_adjoint_builtins.h"),
    ),
    (
        "wp_adjoint_linalg.h",
        include_str!("../cuda/wp_adjoint_linalg.h"),
    ),
    (
        "wp_adjoint_transform.h",
        include_str!("../cuda/wp_adjoint_transform.h"),
    ),
    ("wp_adjoint_svd.h", include_str!("../cuda/wp_adjoint_svd.h")),
    (
        "wp_adjoint_misc.h",
        include_str!("../cuda/wp_adjoint_misc.h"),
    ),
    (
        "wp_adjoint_rand.h",
        include_str!("../cuda/wp_adjoint_rand.h"),
    ),
    (
        "wp_adjoint_geometry.h",
        include_str!("../cuda/wp_adjoint_geometry.h"),
    ),
    (
        "wp_adjoint_mesh.h",
        include_str!("../cuda/wp_adjoint_mesh.h"),
    ),
    (
        "wp_adjoint_volume.h",
        include_str!("../cuda/wp_adjoint_volume.h"),
    ),
];

#[cfg(test)]
mod header_tests {
    /// Every library header on disk is embedded (NVRTC sees only what `HEADERS` hands it, so
    /// a header that is on disk but not embedded would compile on the host and fail on a GPU).
    #[test]
    fn every_header_is_embedded() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/cuda");
        for e in std::fs::read_dir(dir).unwrap() {
            let name = e.unwrap().file_name().into_string().unwrap();
            if name.ends_with(".h") && name != "wp.h" {
                assert!(
                    super::HEADERS.iter().any(|(n, _)| *n == name),
                    "{name} is not in warp_cuda::HEADERS"
                );
            }
        }
    }
}

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
//! - [`compile`](mod@compile): NVRTC to cubin ([`compile()`], [`CompileOptions`], [`nvrtc_version`]),
//!   compiles that overlap each in a copy of libnvrtc of its own (`nvrtc_pool`,
//!   [`NVRTC_THREADS_ENV`]);
//! - [`cache`]: the on-disk kernel cache ([`compile_cached`], [`KernelCache`]);
//! - [`launch`]: [`Module`], [`Function`], [`Gpu::launch_raw`];
//! - [`library`]: the CUDA C++ library's sections, one row each ([`library::SECTIONS`]), and
//!   [`HEADERS`], the headers embedded for NVRTC;
//! - [`nccl`]: NCCL communicators and collectives, loaded at run time ([`nccl::Comm`]);
//! - [`graph`]: stream capture ([`Stream::begin_capture`]) and replay ([`Graph`]).
//!
//! Diagnostics go to the `log` facade, with the module as target: `warp_cuda::device` (what
//! the probe found, or why not), `warp_cuda::compile` (each NVRTC compile and its time),
//! `warp_cuda::cache` (hits and misses at debug level, damaged or unwritable entries as
//! warnings). warp-runtime's `config` module lists every target and level.
//!
//! The CUDA C++ builtin library (the `wp_<section>.h` headers named in the builtin table) lives
//! in `cuda/` and is embedded here ([`library`]).

#![warn(missing_docs)]
// Every public type can be printed in a test or a log line; manual impls keep buffers out.
#![warn(missing_debug_implementations)]

pub mod cache;
pub mod compile;
pub mod device;
pub mod error;
pub mod graph;
pub mod launch;
pub mod library;
pub mod memory;
pub mod nccl;
mod nvrtc_pool;

#[cfg(test)]
mod gpu_tests;

pub use cache::{
    aot_key, cache_dir, cache_key, cache_max_bytes, clear_kernel_cache, compile_cached,
    set_cache_dir, set_cache_max_bytes, CacheLookup, CacheOutcome, KernelCache, CACHE_DIR_ENV,
    CACHE_MAX_BYTES_ENV, DEFAULT_CACHE_MAX_BYTES,
};
pub use compile::{
    compile, cudadevrt_path, nvrtc_supported_archs, nvrtc_version, CompileOptions, Compiled,
    CUDADEVRT_ENV, MAX_NVRTC_THREADS, NO_NVRTC_ENV, NVRTC_THREADS_ENV,
};
pub use device::{driver_version, probe, Event, Gpu, GpuInfo, Stream, MIN_DRIVER_VERSION};
pub use error::{CudaError, Result};
pub use graph::{Conditional, Graph, CONDITIONAL_DRIVER_VERSION};
pub use launch::{Function, Module};
pub use memory::{pointer_device_ordinal, DeviceBuffer, PinnedBuffer};

/// The raw bindings, for callers that need a driver call this crate does not wrap.
pub use cudarc;

pub use library::HEADERS;

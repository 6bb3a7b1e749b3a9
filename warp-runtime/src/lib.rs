//! Runtime of warp-lang: devices, arrays, typed launch, the CPU executor and configuration.
//!
//! - [`device`]: `"cpu"` and `"cuda:N"` devices, [`init`] and its banner. Without a usable GPU
//!   (or without the `cuda` feature) asking for one is an [`Error::NoDevice`], not a panic.
//! - [`array`](mod@array): [`Array<T, N>`], a cheap-to-clone handle to shaped, strided memory with
//!   zero-copy views, reshapes and reinterpretations.
//! - [`launch()`]: checks a launch against what the kernel declared and runs it, on the CPU
//!   in rayon chunks, on a GPU through `cuda` (compiled at first launch).
//! - `stream` (with `cuda`): streams, events, `ScopedStream`, `launch_on`, and the ordering
//!   rules between streams and array operations.
//! - [`kernel`]: the traits that `#[kernel]` implements (`params.rs`: the launch-argument
//!   conversions, once for every tuple of parameter types).
//! - [`objects`]: kernel-visible host objects ([`HashGrid`], [`Bvh`], [`Mesh`], [`Volume`]),
//!   passed as typed parameters through one trait, [`objects::HostObject`].
//! - The backends: `cpu/` and [`cuda`], each implementing the crate-private `Backend` and
//!   `Buffer` traits (`backend.rs`); `dispatch.rs` picks a device's backend and is the only
//!   place that names them all.
//! - [`primitives`]: scan, reductions, radix sort and stream compaction on arrays.
//! - [`graph`]: work recorded once and replayed ([`capture`], [`Graph`]): CUDA graphs on a
//!   GPU, the list of recorded operations on the CPU.
//! - `ops` (feature `ops`): kernels as framework ops on a call's raw buffers, the pure-Rust
//!   half of the PyTorch and JAX ops.
//! - [`config`]: process-wide settings (debug mode, CPU chunk size), and what
//!   warp-lang sends to the `log` facade ([targets and levels](config#logging)).
//!
//! Kernel threads never panic on bad input: an out-of-bounds index or an integer division by
//! zero becomes an [`Error::Fault`] naming the kernel, the argument and the values.

// docs.rs (`--cfg docsrs`, nightly): label feature-gated items with the feature they need.
#![cfg_attr(docsrs, feature(doc_cfg))]
#![warn(missing_docs)]
// Every public type can be printed in a test or a log line; manual impls keep buffers out.
#![warn(missing_debug_implementations)]

pub mod array;
pub mod autograd;
mod backend;
mod capturing;
pub mod checkpoint;
pub mod config;
mod cpp_table;
mod cpu;
pub mod cuda;
pub mod device;
mod dispatch;
pub mod error;
pub mod graph;
pub mod kernel;
pub mod launch;
mod launch_id;
pub mod objects;
#[cfg(feature = "ops")]
pub mod ops;
mod params;
pub mod primitives;
#[cfg(feature = "sparse")]
pub mod sparse;
pub mod tape;

// The CUDA backend's public modules, at the paths they had before they moved into `cuda/`.
#[cfg(feature = "cuda")]
pub use cuda::aot;
#[cfg(feature = "cuda")]
pub use cuda::distributed;
#[cfg(feature = "cuda")]
pub use cuda::pinned;
#[cfg(feature = "cuda")]
pub use cuda::source as cuda_source;
#[cfg(feature = "cuda")]
pub use cuda::stream;

#[cfg(feature = "dlpack")]
pub use array::DlpackScalar;
pub use array::NdComponents;
#[cfg(feature = "python")]
pub mod python;
pub use array::{Array, Element, IntoShape};
pub use autograd::{gradcheck, hvp, jacobian, jacobian_fd, jvp, GradcheckOptions, GradcheckReport};
pub use bytemuck::cast_slice;
pub use checkpoint::{CheckpointReport, CheckpointState, Checkpointed};
pub use device::{
    cpu, cpu_fallback_reason, devices, get_device, get_preferred_device, init, Device, DeviceKind,
    MemoryInfo, Runtime,
};
/// The DLPack crate (`dlpark`) that [`Array::to_dlpack`] and [`Array::from_dlpack`] speak.
#[cfg(feature = "dlpack")]
pub use dlpark as dlpack;
pub use error::{Error, Result};
pub use graph::{capture, capture_if, capture_while, CaptureOn, Graph, ScopedCapture};
pub use kernel::{
    kernel_info, ArgCtx, CudaArray, CudaConst, CudaStruct, DeterministicInfo, Forward,
    GenericKernel, Kernel, KernelArg, KernelInfo, KernelParams, Launchable, TileInfo,
};
pub use launch::{
    launch, launch_adjoint, launch_tiled, load, load_tiled, load_with_adjoints, synchronize, Dim,
    Launch, OwnedArgsOf, MAX_BLOCK_DIM,
};
#[cfg(feature = "cuda")]
pub use launch::{launch_adjoint_on, launch_on, launch_tiled_on};
pub use launch_id::{last_launch_id, LaunchId};
/// What generated code of a `#[kernel(deterministic)]` kernel calls on the CPU (its float
/// `atomic_add`/`atomic_sub`); not an API.
#[doc(hidden)]
pub mod __deterministic {
    pub use crate::cpu::deterministic::{add, grad_add, sub};
}
pub use objects::exports::*;
#[cfg(feature = "cuda")]
pub use pinned::PinnedVec;
pub use primitives::{
    array_max, array_max_n, array_min, array_min_n, array_scan, array_scan_n, array_sum,
    array_sum_n, compact, compact_n, radix_sort_pairs, Count,
};
#[cfg(feature = "cuda")]
pub use stream::{get_stream, Event, ScopedStream, Stream};
pub use tape::{copy, Recording, Seed, Tape};

/// What this process compiled at run time, one line per kernel variant, for scenes and
/// benchmarks to print beside their results: the kernel, forward or adjoint, the contiguous
/// variant or not, bytes of generated CUDA, NVRTC time and whether the cache or the
/// ahead-of-time directory served it.
///
/// Kernels are compiled when first launched, adjoints when a backward pass first needs them
/// (or with the forward, in one unit, when a recording tape or `load_with_adjoints` says
/// backward will need them), so the list is also the proof that a scene compiled nothing it
/// did not run or record for backward. On the CPU
/// nothing is compiled at run time (kernels are Rust, built by cargo), and the summary says so.
pub fn compile_summary() -> String {
    #[cfg(feature = "cuda")]
    {
        let reports = cuda::compile_reports();
        if !reports.is_empty() {
            return cuda::format_compile_reports(&reports);
        }
    }
    "compiled at run time: nothing (CPU kernels are Rust code built by cargo)\n".to_string()
}

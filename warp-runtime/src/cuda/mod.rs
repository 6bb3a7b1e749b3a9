//! The CUDA backend: kernels compiled from their CUDA C++ templates by NVRTC at first launch
//! and launched asynchronously on a GPU's streams; arrays in GPU memory.
//!
//! - `source`: assembles a kernel's translation unit (its sections from
//!   `warp_cuda::library`; the host tests compile generated units with g++).
//! - `options`, `aot`, `module`: how a unit is compiled (NVRTC options), ahead-of-time cubins,
//!   and the per-GPU cache of loaded kernels with what compiling them cost.
//! - `gpu`: per-GPU state and the stream ordering model; `fault`: the fault records kernels
//!   write and synchronisations read (it imports nothing from `gpu`).
//! - `launch`: a launch's parameter block and `cuLaunchKernel`.
//! - `primitives`: the launch plans of the parallel primitives (`wp_primitives.h`), run.
//! - `deterministic`: a `#[kernel(deterministic)]` launch's record slots, their ordering
//!   (two of the primitives' radix sorts) and ordered addition.
//! - `objects`: the build kernels of host objects (the hash grid's, `wp_hash_grid.h`).
//! - `capture`: what graph capture means on a GPU (the thread's capture stream, onto which
//!   every enqueue of the thread goes) and graph replay.
//! - `distributed`: several GPUs: NCCL communicators and collectives on arrays, peer access.
//! - `memory`: GPU memory for arrays. `stream`, `pinned`: the public streams, events and
//!   pinned host memory.
//! - `backend`: `Cuda`, the backend (see the crate's `backend.rs`) that the runtime
//!   dispatches to for `"cuda:N"`.

#[cfg(feature = "cuda")]
pub mod source;

#[cfg(feature = "cuda")]
pub mod aot;
#[cfg(feature = "cuda")]
mod backend;
#[cfg(feature = "cuda")]
pub(crate) mod capture;
#[cfg(feature = "cuda")]
pub(crate) mod deterministic;
#[cfg(feature = "cuda")]
pub mod distributed;
#[cfg(feature = "cuda")]
mod fault;
#[cfg(feature = "cuda")]
mod gpu;
#[cfg(feature = "cuda")]
pub(crate) mod launch;
#[cfg(feature = "cuda")]
pub(crate) mod memory;
#[cfg(feature = "cuda")]
mod module;
#[cfg(feature = "cuda")]
pub(crate) mod objects;
#[cfg(feature = "cuda")]
mod options;
#[cfg(feature = "cuda")]
pub mod pinned;
#[cfg(feature = "cuda")]
pub(crate) mod primitives;
#[cfg(feature = "cuda")]
pub mod stream;

// The XLA handlers (`ops::xla_ffi`) reach a GPU's state directly.
#[cfg(all(feature = "cuda", feature = "ops"))]
pub(crate) use gpu::{err as gpu_err, state as gpu_state};
#[cfg(feature = "cuda")]
pub(crate) use module::format_compile_reports;
#[cfg(feature = "cuda")]
pub use module::{compile_reports, CompileReport};

#[cfg(feature = "cuda")]
pub(crate) use backend::Cuda;

/// Makes sure GPU `device` holds at least `n` spare fault records, so that the first launch of
/// up to `n` new threads there allocates nothing (see `RecordPool::reserve`).
#[cfg(all(feature = "cuda", feature = "ops"))]
pub(crate) fn reserve_fault_records(device: &crate::device::Device, n: usize) -> crate::Result<()> {
    if let crate::device::DeviceKind::Cuda { ordinal } = device.kind() {
        gpu::state(device, ordinal)?.faults.reserve(n)?;
    }
    Ok(())
}

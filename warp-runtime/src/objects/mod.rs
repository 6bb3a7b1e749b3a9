//! Kernel-visible host objects: types that own buffers on one device, are built on the host's
//! call, and are passed to kernels as typed parameters (`grid: HashGrid`), where the kernel
//! sees a checked view and calls their queries (ARCHITECTURE.md, "A new kernel-visible host
//! object").
//!
//! - [`hash_grid`]: [`HashGrid`], Warp's hash grid for neighbour queries.

pub mod bvh_build;
pub mod hash_grid;

pub use hash_grid::{CudaHashGrid, HashGrid};

/// Compiles the hash grid's build kernels with NVRTC (no GPU needed): for tests.
#[cfg(feature = "cuda")]
#[doc(hidden)]
pub use crate::cuda::objects::compile_hash_grid_build;

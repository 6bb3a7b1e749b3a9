//! CUDA backend of warp-lang — a skeleton.
//!
//! This crate will hold the CUDA side of the runtime, layered as cudarc is:
//! - `sys`: cudarc's driver and NVRTC bindings, loaded dynamically so that everything builds
//!   and runs without CUDA installed;
//! - `result`: thin fallible wrappers (context, module load, launch, memory);
//! - `safe`: devices, streams, events, device buffers, the NVRTC-to-cubin compiler and the
//!   on-disk kernel cache;
//! - the CUDA C++ builtin library (`.cuh` files embedded with `include_str!`), layout-identical
//!   to the Rust types (glam matrices are column-major).
//!
//! The kernel IR in `warp-macros` is already shaped for its CUDA emitter: three-address
//! statements with types, structured control flow, spans for `#line` directives, and a
//! builtin table that names each builtin's CUDA function and library section.

/// The CUDA library sections a kernel can need, as named in the builtin table.
pub const SECTIONS: &[&str] = &["scalar", "vector", "atomic"];

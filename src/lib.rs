//! # warp-lang
//!
//! GPU and CPU kernels written as plain Rust functions, in the spirit of NVIDIA Warp.
//!
//! ```
//! use warp_lang as wp;
//! use wp::prelude::*;
//!
//! #[wp::kernel]
//! fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
//!     let i = tid();
//!     let a = -b * v[i] / mass + gravity;
//!     v[i] += a * dt;
//!     x[i] += v[i] * dt;
//! }
//!
//! fn main() -> wp::Result<()> {
//!     let dev = wp::get_preferred_device();
//!     let x = wp::Array::from_slice(&[Vec3::ZERO; 4], &dev)?;
//!     let v = wp::Array::from_slice(&[Vec3::X; 4], &dev)?;
//!     for _ in 0..10 {
//!         wp::launch(integrate, 4, (&x, &v, 0.05, 0.1, Vec3::new(0.0, 0.0, -9.81), 0.01), &dev)?;
//!     }
//!     assert!(x.to_vec()?[0].x > 0.0);
//!     Ok(())
//! }
//! ```
//!
//! Gradients: give arrays a gradient, record launches on a [`Tape`], run backward.
//!
//! ```
//! use warp_lang as wp;
//! use wp::prelude::*;
//!
//! #[wp::kernel]
//! fn square_sum(x: Array<f32>, loss: Array<f32>) {
//!     let i = tid();
//!     atomic_add(loss, 0, x[i] * x[i]);
//! }
//!
//! let dev = wp::cpu();
//! let x = wp::Array::from_slice(&[1.0f32, 2.0, 3.0], &dev).unwrap().with_grad().unwrap();
//! let loss = wp::Array::<f32>::zeros(1, &dev).unwrap().with_grad().unwrap();
//! let tape = wp::Tape::new();
//! {
//!     let _rec = tape.record();
//!     wp::launch(square_sum, 3, (&x, &loss), &dev).unwrap();
//! }
//! tape.backward(&loss).unwrap();
//! assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![2.0, 4.0, 6.0]);
//! ```
//!
//! - `#[kernel]` turns a function into a kernel launched over a 1-D to 4-D grid with
//!   [`launch()`]; `#[func]` makes a function callable from kernels; `#[derive(Struct)]` makes a
//!   `#[repr(C)]` struct a kernel argument and array element.
//! - Kernel arguments are checked at compile time: an `Array<f32>` where the kernel takes
//!   `Array<Vec3>` does not compile.
//! - Kernel threads never panic: an out-of-bounds index or an integer division by zero
//!   returns an [`Error`] naming the kernel, the argument and the values.
//! - [`HashGrid`] (Warp's hash grid) is a kernel parameter `grid: HashGrid`; kernels iterate
//!   its neighbour candidates with `for j in hash_grid_query(grid, p, radius) { .. }` and
//!   test the distance themselves:
//!
//! ```
//! use warp_lang as wp;
//! use wp::prelude::*;
//!
//! #[wp::kernel]
//! fn count_neighbours(grid: HashGrid, x: Array<Vec3>, r: f32, counts: Array<i32>) {
//!     let i = tid();
//!     let mut n = 0;
//!     for j in hash_grid_query(grid, x[i], r) {
//!         if j != i && length(x[j] - x[i]) <= r {
//!             n += 1;
//!         }
//!     }
//!     counts[i] = n;
//! }
//!
//! let dev = wp::cpu();
//! let x = wp::Array::from_slice(&[Vec3::ZERO, Vec3::X * 0.5, Vec3::X * 3.0], &dev).unwrap();
//! let counts = wp::Array::<i32>::zeros(3, &dev).unwrap();
//! let mut grid = wp::HashGrid::new(8, 8, 8, &dev).unwrap();
//! grid.build(&x, 1.0).unwrap();
//! wp::launch(count_neighbours, 3, (&grid, &x, 1.0, &counts), &dev).unwrap();
//! assert_eq!(counts.to_vec().unwrap(), vec![1, 1, 0]);
//! ```
//!
//! ## Kernels and data races
//!
//! A kernel's threads run at once (rayon tasks on the CPU, GPU threads), so what they may do
//! to one array is a contract, the same on both backends:
//! - **Guaranteed by the runtime:** no access touches memory outside its array (every index is
//!   checked, or proven in range); the arrays a launch was given stay allocated until it has
//!   finished; a fault is a value ([`Error`]), never a panic unwinding through kernel code; a
//!   gradient, which the user never writes, is accumulated without races (atomically where
//!   threads may share it).
//! - **Safe for kernels:** each thread writing only its own elements (`a[tid()] = ..`), any
//!   number of threads reading an element nobody writes in that launch, and `atomic_*`
//!   builtins among themselves.
//! - **A data race, as in CUDA and in Rust's memory model:** two threads of one launch writing
//!   one element without an atomic, one writing while another reads it, or a plain access racing
//!   an atomic one. The language cannot rule these out at compile time (the index is a run-time
//!   value), so they are the kernel author's to avoid; the result is then unspecified.
//! - **The opt-in check:** [`config::set_race_check`] (or `WARP_RACE_CHECK=1`) makes CPU launches
//!   log every store and turn a second thread's write to an element into
//!   [`FaultKind::WriteRace`] naming the kernel, argument, index and both threads. It covers
//!   write-write races of one CPU launch; not read-write races, atomics, host objects' buffers,
//!   races between launches on different threads or streams, or the GPU (run the kernel on the
//!   CPU with the check to find them).
//!
//! The kernel language (types, the literal rule, builtins) is described in [`docs::language`]
//! (ARCHITECTURE.md), its builtins in [`docs::builtins`], and the macros in the docs of
//! [`kernel`].

// docs.rs (`--cfg docsrs`, nightly): label feature-gated items with the feature they need.
#![cfg_attr(docsrs, feature(doc_cfg))]
// Every public type can be printed in a test or a log line.
#![warn(missing_debug_implementations)]

pub use glam;
/// nalgebra, whose `From` conversions to and from glam (the element types of arrays) the
/// `nalgebra` feature turns on.
#[cfg(feature = "nalgebra")]
pub use nalgebra;
/// Brain float (Warp's `bfloat16`): the `half` crate's type, a scalar of the kernel language
/// and a tile element (see `warp_core::bfloat16` for its arithmetic, casts and builtins).
pub use warp_core::bf16;
/// Half precision (Warp's `float16`): the `half` crate's type, a scalar of the kernel language
/// (see `warp_core::float16` for its arithmetic, casts and builtins).
pub use warp_core::capability;
pub use warp_core::f16;
/// Non-square matrices (Warp's `matrix(shape=(R, C))` for `R != C` in {2, 3, 4, 6}): `Mat23`
/// has 2 rows of `Vec3` (see `warp_core::matrix`).
pub use warp_core::{
    DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63, DMat64,
    Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64,
};
/// Spatial vectors and 6x6 spatial matrices (Warp's `spatial_vector`, `spatial_matrix`).
pub use warp_core::{DSpatialMatrix, DSpatialVector, SpatialMatrix, SpatialVector};
pub use warp_core::{DTransform, Fault, FaultKind, Float, Int, LaunchId, Transform, Vector};
/// The kernel cache: where it lives (`WARP_LANG_CACHE_DIR` wins over `set_cache_dir`), its
/// size bound (`WARP_LANG_CACHE_MAX_BYTES` wins over `set_cache_max_bytes`; least recently
/// used entries go first) and emptying it.
#[cfg(feature = "cuda")]
pub use warp_cuda::{
    cache_dir, cache_max_bytes, clear_kernel_cache, set_cache_dir, set_cache_max_bytes,
};
pub use warp_macros::{func, kernel, Struct};
/// Work-precision sweeps: tables, SVG plots and progress (the `report` feature).
#[cfg(feature = "report")]
pub use warp_report as report;
#[cfg(feature = "cuda")]
pub use warp_runtime::aot;
#[cfg(feature = "cuda")]
pub use warp_runtime::cuda::{compile_reports, CompileReport};
#[cfg(feature = "cuda")]
pub use warp_runtime::cuda_source;
/// Several GPUs: NCCL collectives on arrays (`Communicator`, `group`), peer access.
#[cfg(feature = "cuda")]
pub use warp_runtime::distributed;
pub mod docs;
/// The trailing axes that vector and matrix elements have in `Array::as_ndarray_components`
/// and in DLPack tensors.
pub use warp_runtime::NdComponents;
pub mod optim;
mod overload;
/// DLPack, the tensor exchange format: the `dlpark` crate, whose `Managed` tensors
/// [`Array::to_dlpack`] makes and [`Array::from_dlpack`] takes (the `dlpack` feature).
#[cfg(feature = "dlpack")]
pub use warp_runtime::dlpack;
/// Kernels as framework ops on raw buffers ([`ops::Op`]): the pure-Rust half of the PyTorch
/// and JAX ops (the `ops` feature).
#[cfg(feature = "ops")]
pub use warp_runtime::ops;
/// Python extension modules: PyTorch, JAX, CuPy and NumPy tensors in and out without a copy
/// (the `python` feature).
#[cfg(feature = "python")]
pub use warp_runtime::python;
/// Block sparse matrices ([`sparse::Bsr`]), their products with vectors and the conjugate
/// gradient solver (the `sparse` feature).
#[cfg(feature = "sparse")]
pub use warp_runtime::sparse;
/// The scalar types that DLPack exchanges (the `dlpack` feature).
#[cfg(feature = "dlpack")]
pub use warp_runtime::DlpackScalar;

/// Graphs: work recorded once and replayed ([`capture`], [`ScopedCapture`], [`Graph`]).
pub use warp_runtime::graph;
/// Kernel-visible host objects: [`HashGrid`], [`Bvh`], [`Mesh`], [`Volume`] (also at the crate
/// root and in the prelude).
pub use warp_runtime::objects;
/// Parallel primitives: scan, reductions, radix sort, stream compaction (the functions are
/// also at the crate root: `wp::array_scan`, ...).
pub use warp_runtime::primitives;
pub use warp_runtime::primitives::{
    array_max, array_max_n, array_min, array_min_n, array_scan, array_scan_n, array_sum,
    array_sum_n, compact, compact_n, radix_sort_pairs, Count,
};
// The host objects' types and constants (HashGrid, Bvh, Mesh, Volume, MarchingCubes, ..),
// listed once in `objects::exports`.
pub use warp_runtime::objects::exports::*;
// Forward mode (the `forward-mode` feature): Jacobian- and Hessian-vector products.
pub use warp_runtime::{
    autograd, gradcheck, jacobian, jacobian_fd, GradcheckOptions, GradcheckReport,
};
pub use warp_runtime::{capture, capture_if, capture_while, CaptureOn, Graph, ScopedCapture};
pub use warp_runtime::{
    cast_slice, compile_summary, config, copy, cpu, cpu_fallback_reason, devices, get_device,
    get_preferred_device, init, kernel_info, last_launch_id, launch, launch_adjoint, launch_tiled,
    load, load_tiled, load_with_adjoints, synchronize, ArgCtx, Array, Device, DeviceKind, Dim,
    Element, Error, GenericKernel, IntoShape, Kernel, KernelArg, KernelInfo, KernelParams, Launch,
    Launchable, MemoryInfo, OwnedArgsOf, Recording, Result, Runtime, Seed, Tape, TileInfo,
    MAX_BLOCK_DIM,
};
#[cfg(feature = "cuda")]
pub use warp_runtime::{
    get_stream, launch_adjoint_on, launch_on, launch_tiled_on, Event, PinnedVec, ScopedStream,
    Stream,
};
pub use warp_runtime::{hvp, jvp, Forward};
pub use warp_runtime::{CheckpointReport, CheckpointState, Checkpointed};

/// Declares a set of overloaded funcs: `wp::overloads!(pub combine);`, then each overload is
/// a `#[wp::func(overload)] fn combine(..)` (several may share the name). A call
/// `combine(a, b)` runs the overload whose parameter types the arguments have, as Warp
/// resolves its overloads; `combine::<i32>(a, b)` names the overloads of first parameter type
/// `i32` (in a generic kernel `combine::<T>(a, b)`: each instance's own). A call that no
/// overload takes fails to compile at the call.
#[macro_export]
macro_rules! overloads {
    ($(#[$m:meta])* $vis:vis $name:ident) => {
        $crate::__private::overload_set! { $(#[$m])* $vis $name }
    };
}

/// Everything a kernel file needs: `use warp_lang::prelude::*;`.
pub mod prelude {
    pub use crate::{
        bf16, f16, func, kernel, Array, DSpatialMatrix, DSpatialVector, DTransform, Element, Float,
        Int, SpatialMatrix, SpatialVector, Struct, Transform, Vector,
    };
    pub use crate::{
        DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63,
        DMat64, Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64,
    };
    pub use glam::{
        dvec2, dvec3, dvec4, ivec2, ivec3, ivec4, uvec2, uvec3, uvec4, vec2, vec3, vec4, DMat2,
        DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
        UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
    };
    pub use warp_runtime::objects::prelude::*;
}

/// Names that generated code refers to. Not part of the public API.
#[doc(hidden)]
pub mod __private {
    pub use crate::overload::{resolves, Callee, FuncRet, Resolve, RetOf, Unresolved};
    pub use bytemuck;
    pub use glam;
    pub use warp_core::{
        adj_atomic_extreme, adjoint, bf16, block, builtins, f16, first_error, local_array,
        max_depth, objects, ops, tile, with_grad_stack, zero_like, AdStack, ArrayView, AssertSite,
        Capability, ConstLiteral, DSpatialMatrix, DSpatialVector, DTransform, Fault, FuncInfo,
        GradElement, GradSeed, GradView, Grid, KResult, RangeProg, SpatialMatrix, SpatialVector,
        Transform,
    };
    pub use warp_core::{
        DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63,
        DMat64, Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64,
    };
    pub use warp_macros::__object_rows;
    pub use warp_macros::__overload_set as overload_set;
    pub use warp_runtime::__deterministic as deterministic;
    /// The per-thread adjoint stack capacity (`wp::config::adstack_bytes`): a `wp::grad`
    /// call's stack takes it.
    pub use warp_runtime::config::adstack_bytes;
    /// Whether `debug_assert!` is checked: the runtime's debug mode (`wp::config::debug`).
    pub use warp_runtime::config::debug as debug_mode;
    pub use warp_runtime::kernel::{ArgsOf, CpuGradsOf, CpuParamsOf, Forward};
    pub use warp_runtime::{
        ArgCtx, CudaConst, CudaStruct, DeterministicInfo, Device, Element, GenericKernel, Kernel,
        KernelArg, KernelInfo, KernelParams, Launchable, Result, TileInfo,
    };
}

// The book (docs/book, mdBook): each chapter is the documentation of an item here, so
// `cargo test --doc` compiles and runs its Rust blocks against this crate as a user's code
// would see it (`mdbook test` cannot link the crate). tests/docs.rs fails when a chapter is
// missing from this list, so a new chapter's code cannot go uncompiled.
#[cfg(doctest)]
mod book {
    #[doc = include_str!("../README.md")]
    struct Readme;
    #[doc = include_str!("../docs/book/src/autodiff.md")]
    struct Autodiff;
    #[doc = include_str!("../docs/book/src/builtins-edge-cases.md")]
    struct BuiltinsEdgeCases;
    #[doc = include_str!("../docs/book/src/builtins.md")]
    struct Builtins;
    #[doc = include_str!("../docs/book/src/cache-env.md")]
    struct CacheEnv;
    #[doc = include_str!("../docs/book/src/deterministic.md")]
    struct Deterministic;
    #[doc = include_str!("../docs/book/src/devices.md")]
    struct Devices;
    #[doc = include_str!("../docs/book/src/getting-started.md")]
    struct GettingStarted;
    #[doc = include_str!("../docs/book/src/graphs.md")]
    struct Graphs;
    #[doc = include_str!("../docs/book/src/interop.md")]
    struct Interop;
    #[doc = include_str!("../docs/book/src/introduction.md")]
    struct Introduction;
    #[doc = include_str!("../docs/book/src/kernels.md")]
    struct Kernels;
    #[doc = include_str!("../docs/book/src/multi-gpu.md")]
    struct MultiGpu;
    #[doc = include_str!("../docs/book/src/nanovdb.md")]
    struct Nanovdb;
    #[doc = include_str!("../docs/book/src/numerics.md")]
    struct Numerics;
    #[doc = include_str!("../docs/book/src/performance.md")]
    struct Performance;
    #[doc = include_str!("../docs/book/src/primitives.md")]
    struct Primitives;
    #[doc = include_str!("../docs/book/src/python-ops.md")]
    struct PythonOps;
    #[doc = include_str!("../docs/book/src/scenes.md")]
    struct Scenes;
    #[doc = include_str!("../docs/book/src/spatial.md")]
    struct Spatial;
    #[doc = include_str!("../docs/book/src/sparse.md")]
    struct Sparse;
    #[doc = include_str!("../docs/book/src/tiles.md")]
    struct Tiles;
    #[doc = include_str!("../docs/book/src/testing.md")]
    struct Testing;
}

// Lets the crate's own unit tests and doc tests use the macros, which name `::warp_lang`.
extern crate self as warp_lang;

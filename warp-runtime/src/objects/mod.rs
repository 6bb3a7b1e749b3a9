//! Kernel-visible host objects: types that own buffers on one device, are built on the host's
//! call, and are passed to kernels as typed parameters (`grid: HashGrid`), where the kernel
//! sees a checked view and calls their queries (ARCHITECTURE.md, "A new kernel-visible host
//! object").
//!
//! - [`hash_grid`]: [`HashGrid`], Warp's hash grid for neighbour queries.
//! - [`bvh`]: [`Bvh`], Warp's BVH over boxes (box and ray queries).
//! - [`mesh`]: [`Mesh`], Warp's triangle mesh (closest point, ray, box queries).
//! - [`marching_cubes`]: [`MarchingCubes`], Warp's marching cubes (a field's isosurface as a
//!   triangle mesh).
//! - [`geometry_abi`]: the CUDA parameter layouts of both ([`CudaBvh`], [`CudaMesh`]).
//! - `obj` (cargo feature `obj`): `ObjMesh`, a triangle mesh read from a Wavefront OBJ file.
//! - [`volume`]: [`Volume`], Warp's sparse volume (a NanoVDB grid), on the `nvdb` file layer;
//!   `volume_build` builds its grids from tiles, voxels or points on their device.

pub mod bvh;
pub mod bvh_build;
pub mod geometry_abi;
pub mod hash_grid;
mod hash_grid_steps;
#[doc(hidden)]
pub mod lbvh;
pub mod marching_cubes;
pub mod mesh;
#[doc(hidden)]
pub mod nvdb;
#[cfg(feature = "obj")]
pub mod obj;
pub mod volume;
mod volume_build;

pub use crate::backend::ObjectLibrary;
pub use bvh::Bvh;
pub use geometry_abi::{CudaBvh, CudaBvhTree, CudaMesh};
pub use hash_grid::{CudaHashGrid, HashGrid};
pub use marching_cubes::MarchingCubes;
pub use mesh::Mesh;
#[cfg(feature = "obj")]
pub use obj::ObjMesh;
pub use volume::{Volume, VOLUME_CLOSEST, VOLUME_LINEAR};

/// Every host object's CUDA build library (each compiled the first time a GPU runs one of
/// its steps): the library sections that have one (`warp_cuda::library::SECTIONS`).
#[cfg(feature = "cuda")]
pub fn build_libraries() -> impl Iterator<Item = ObjectLibrary> {
    warp_cuda::library::SECTIONS
        .iter()
        .filter(|s| s.build.is_some())
        .map(|s| ObjectLibrary::of(s.name))
}

/// Compiles a build library with NVRTC for `sm_{arch}` with the runtime's options (no GPU
/// needed): how the tests check that NVRTC accepts each on machines without a GPU.
#[cfg(feature = "cuda")]
#[doc(hidden)]
pub use crate::cuda::objects::compile_library;

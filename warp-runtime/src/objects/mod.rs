//! Kernel-visible host objects: types that own buffers on one device, are built on the host's
//! call, and are passed to kernels as typed parameters (`grid: HashGrid`), where the kernel
//! sees a checked view and calls their queries (ARCHITECTURE.md, "A new kernel-visible host
//! object").
//!
//! - [`host_object`]: [`HostObject`], the seam: an object gives its device, its CPU view and
//!   its CUDA record, and is a kernel argument by that alone.
//! - [`hash_grid`]: [`HashGrid`], Warp's hash grid for neighbour queries.
//! - [`bvh`]: [`Bvh`], Warp's BVH over boxes (box and ray queries).
//! - [`mesh`]: [`Mesh`], Warp's triangle mesh (closest point, ray, box queries).
//! - [`marching_cubes`]: [`MarchingCubes`], Warp's marching cubes (a field's isosurface as a
//!   triangle mesh): a host builder, not a kernel argument.
//! - [`geometry_abi`]: the CUDA parameter layouts of both ([`CudaBvh`], [`CudaMesh`]).
//! - `obj` (cargo feature `obj`): `ObjMesh`, a triangle mesh read from a Wavefront OBJ file.
//! - [`volume`]: [`Volume`], Warp's sparse volume (a NanoVDB grid), on the `nvdb` file layer;
//!   `volume_build` builds its grids from tiles, voxels or points on their device.
//!
//! An object's public names are listed once, in [`prelude`] (what kernel files name) or
//! [`exports`] (the host-side rest): the crate roots and the facade's prelude re-export those
//! modules whole, so a new object edits no other list.

pub mod bvh;
pub mod bvh_build;
pub mod geometry_abi;
pub mod hash_grid;
mod hash_grid_steps;
pub mod host_object;
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
pub use host_object::HostObject;
pub use marching_cubes::MarchingCubes;
pub use mesh::Mesh;
#[cfg(feature = "obj")]
pub use obj::ObjMesh;
pub use volume::{Volume, VOLUME_CLOSEST, VOLUME_LINEAR};
// The sparse tier's matrix is a kernel parameter too (its module is `sparse`, behind the
// feature; kernels name it `Bsr<B>`).
#[cfg(feature = "sparse")]
pub use crate::sparse::Bsr;
pub use warp_core::objects::nanovdb::Map as VolumeMap;
pub use warp_core::objects::VoxelIndex;

/// The names a kernel file uses: the objects' parameter types and what their builtins take
/// (`warp_lang::prelude` re-exports this module whole).
pub mod prelude {
    #[cfg(feature = "sparse")]
    pub use super::Bsr;
    pub use super::{Bvh, HashGrid, Mesh, Volume, VoxelIndex, VOLUME_CLOSEST, VOLUME_LINEAR};
}

/// Every object name the crate roots re-export (`warp_runtime::HashGrid`, `wp::HashGrid`):
/// the [`prelude`]'s and the host-side ones.
pub mod exports {
    pub use super::prelude::*;
    pub use super::{MarchingCubes, VolumeMap};
}

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

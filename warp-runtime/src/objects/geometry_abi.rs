//! The CUDA kernel-parameter layouts of the BVH and the mesh, in one place: what a `Bvh` or
//! `Mesh` kernel parameter is when a CUDA kernel receives it (`wp::bvh_t`, `wp::mesh_t` in
//! `warp-cuda/cuda/wp_bvh.h` and `wp_mesh.h`).
//!
//! Each is a field-for-field mirror of the CPU view of warp-core (`BvhView`, `MeshView`, in
//! their field order), with device addresses as `u64`, counts as `i32`, and the kernel
//! parameter's index `arg` (reported in out-of-bounds faults, as `CudaHashGrid` does) where the
//! CPU view carries the kernel's and parameter's names. The shared part, the tree
//! ([`CudaBvhTree`], the mirror of `BvhTree`), comes first in both, so device code can read
//! the tree of either through the same `wp::bvh_tree_t` prefix.
//!
//! The tree's buffers are in the layout of `warp_core::objects::bvh` (32-byte nodes, root at
//! node 0, `parents` with -1 at the root, `prim_ids` grouped by leaf). Byte offsets (each
//! asserted below, with the sizes):
//!
//! `CudaBvhTree`, 32 bytes:
//!
//! | offset | field | type |
//! |---|---|---|
//! | 0 | `nodes` | `u64` (device address of `num_nodes` `BvhNode`s, 32 bytes each, 16-aligned) |
//! | 8 | `parents` | `u64` (`num_nodes` `i32`) |
//! | 16 | `prim_ids` | `u64` (`num_prims` `i32`) |
//! | 24 | `num_nodes` | `i32` (at least 1) |
//! | 28 | `num_prims` | `i32` |
//!
//! `CudaBvh` (`wp::bvh_t`), 56 bytes, 8-aligned:
//!
//! | offset | field | type |
//! |---|---|---|
//! | 0 | `tree` | `CudaBvhTree` |
//! | 32 | `lowers` | `u64` (`num_prims` `vec3`, 12 bytes each) |
//! | 40 | `uppers` | `u64` (`num_prims` `vec3`) |
//! | 48 | `arg` | `i32` |
//! | 52 | `pad` | `i32` (0) |
//!
//! `CudaMesh` (`wp::mesh_t`), 64 bytes, 8-aligned:
//!
//! | offset | field | type |
//! |---|---|---|
//! | 0 | `tree` | `CudaBvhTree` (one primitive per triangle) |
//! | 32 | `points` | `u64` (`num_points` `vec3`) |
//! | 40 | `velocities` | `u64` (`num_points` `vec3`, or 0 when the mesh has none) |
//! | 48 | `indices` | `u64` (`3 * num_prims` `i32`) |
//! | 56 | `num_points` | `i32` |
//! | 60 | `arg` | `i32` |

use std::mem::{offset_of, size_of};

/// The tree part of a BVH or mesh kernel parameter (mirror of warp-core's `BvhTree`;
/// `wp::bvh_tree_t`). See the module docs for the offsets.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CudaBvhTree {
    /// Device address of the nodes.
    pub nodes: u64,
    /// Device address of each node's parent (-1 for the root).
    pub parents: u64,
    /// Device address of the primitive ids grouped by leaf.
    pub prim_ids: u64,
    /// Nodes in the tree (at least 1: the empty tree is one empty leaf).
    pub num_nodes: i32,
    /// Primitives in the tree.
    pub num_prims: i32,
}

/// A `Bvh` kernel parameter as CUDA kernels receive it (`wp::bvh_t`): the mirror of
/// warp-core's `BvhView` (module docs: 56 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CudaBvh {
    /// The tree.
    pub tree: CudaBvhTree,
    /// Device address of the primitives' lower corners (the user's `lowers`).
    pub lowers: u64,
    /// Device address of the primitives' upper corners (the user's `uppers`).
    pub uppers: u64,
    /// The kernel parameter's index (reported in out-of-bounds faults).
    pub arg: i32,
    /// Padding to 8 bytes (0).
    pub pad: i32,
}

/// A `Mesh` kernel parameter as CUDA kernels receive it (`wp::mesh_t`): the mirror of
/// warp-core's `MeshView` (module docs: 64 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CudaMesh {
    /// The tree over the triangles (primitive `f` is face `f`).
    pub tree: CudaBvhTree,
    /// Device address of the points (the user's array).
    pub points: u64,
    /// Device address of the per-point velocities, 0 when the mesh has none.
    pub velocities: u64,
    /// Device address of the vertex indices, three per face.
    pub indices: u64,
    /// Points in the mesh.
    pub num_points: i32,
    /// The kernel parameter's index (reported in out-of-bounds faults).
    pub arg: i32,
}

const _: () = {
    assert!(size_of::<CudaBvhTree>() == 32);
    assert!(offset_of!(CudaBvhTree, nodes) == 0);
    assert!(offset_of!(CudaBvhTree, parents) == 8);
    assert!(offset_of!(CudaBvhTree, prim_ids) == 16);
    assert!(offset_of!(CudaBvhTree, num_nodes) == 24);
    assert!(offset_of!(CudaBvhTree, num_prims) == 28);

    assert!(size_of::<CudaBvh>() == 56);
    assert!(offset_of!(CudaBvh, tree) == 0);
    assert!(offset_of!(CudaBvh, lowers) == 32);
    assert!(offset_of!(CudaBvh, uppers) == 40);
    assert!(offset_of!(CudaBvh, arg) == 48);
    assert!(offset_of!(CudaBvh, pad) == 52);

    assert!(size_of::<CudaMesh>() == 64);
    assert!(offset_of!(CudaMesh, tree) == 0);
    assert!(offset_of!(CudaMesh, points) == 32);
    assert!(offset_of!(CudaMesh, velocities) == 40);
    assert!(offset_of!(CudaMesh, indices) == 48);
    assert!(offset_of!(CudaMesh, num_points) == 56);
    assert!(offset_of!(CudaMesh, arg) == 60);
};

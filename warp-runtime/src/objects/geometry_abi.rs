//! The CUDA kernel-parameter layouts of the BVH and the mesh, in one place: what a `Bvh` or
//! `Mesh` kernel parameter is when a CUDA kernel receives it (`wp::bvh_t`, `wp::mesh_t` in
//! `warp-cuda/cuda/wp_bvh.h` and `wp_mesh.h`).
//!
//! The shared part, the tree ([`CudaBvhTree`], `wp::bvh_tree_t`, with the kernel parameter's
//! index `arg` reported in out-of-bounds faults, as `CudaHashGrid` does), comes first in both,
//! so device code reads the tree of either through the same prefix. Device addresses are
//! `u64`, counts `i32`. The headers assert the same sizes (`tests/cuda_geometry_host.rs`
//! checks the C++ offsets).
//!
//! The tree's buffers are in the layout of `warp_core::objects::bvh` (32-byte nodes, root at
//! node 0, `parents` the links: each node's parent, -1 at the root, then each node's escape,
//! `prim_ids` grouped by leaf). Byte offsets (each
//! asserted below, with the sizes):
//!
//! `CudaBvhTree` (`wp::bvh_tree_t`), 40 bytes:
//!
//! | offset | field | type |
//! |---|---|---|
//! | 0 | `nodes` | `u64` (device address of `num_nodes` `BvhNode`s, 32 bytes each, 16-aligned) |
//! | 8 | `parents` | `u64` (`2 * num_nodes` `i32`: parents, then escapes) |
//! | 16 | `prim_ids` | `u64` (`num_prims` `i32`) |
//! | 24 | `num_nodes` | `i32` (at least 1) |
//! | 28 | `num_prims` | `i32` |
//! | 32 | `arg` | `i32` (the kernel parameter's index) |
//! | 36 | `pad` | `i32` (0) |
//!
//! `CudaBvh` (`wp::bvh_t`), 56 bytes, 8-aligned:
//!
//! | offset | field | type |
//! |---|---|---|
//! | 0 | `tree` | `CudaBvhTree` |
//! | 40 | `lowers` | `u64` (`num_prims` `vec3`, 12 bytes each) |
//! | 48 | `uppers` | `u64` (`num_prims` `vec3`) |
//!
//! `CudaMesh` (`wp::mesh_t`), 80 bytes, 8-aligned:
//!
//! | offset | field | type |
//! |---|---|---|
//! | 0 | `tree` | `CudaBvhTree` (one primitive per triangle) |
//! | 40 | `points` | `u64` (`num_points` `vec3`) |
//! | 48 | `velocities` | `u64` (`num_points` `vec3`, or 0 when the mesh has none) |
//! | 56 | `indices` | `u64` (`3 * num_prims` `i32`) |
//! | 64 | `num_points` | `i32` |
//! | 68 | `pad` | `i32` (0) |
//! | 72 | `leaf_tris` | `u64` (`3 * num_prims` `vec4`, 16-aligned: the triangles in leaf order) |

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
    /// The kernel parameter's index (reported in out-of-bounds faults).
    pub arg: i32,
    /// Padding to 8 bytes (0).
    pub pad: i32,
}

/// A `Bvh` kernel parameter as CUDA kernels receive it (`wp::bvh_t`; module docs: 56 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CudaBvh {
    /// The tree.
    pub tree: CudaBvhTree,
    /// Device address of the primitives' lower corners (the user's `lowers`).
    pub lowers: u64,
    /// Device address of the primitives' upper corners (the user's `uppers`).
    pub uppers: u64,
}

/// A `Mesh` kernel parameter as CUDA kernels receive it (`wp::mesh_t`; module docs: 80
/// bytes).
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
    /// Padding to 8 bytes (0).
    pub pad: i32,
    /// Device address of the triangles in leaf order: three corners `{x, y, z, 0}` per
    /// position of the tree's `prim_ids` (`warp_core::objects::mesh::write_leaf_triangles`),
    /// written at the build and every refit; 16-byte aligned.
    pub leaf_tris: u64,
}

const _: () = {
    assert!(size_of::<CudaBvhTree>() == 40);
    assert!(offset_of!(CudaBvhTree, nodes) == 0);
    assert!(offset_of!(CudaBvhTree, parents) == 8);
    assert!(offset_of!(CudaBvhTree, prim_ids) == 16);
    assert!(offset_of!(CudaBvhTree, num_nodes) == 24);
    assert!(offset_of!(CudaBvhTree, num_prims) == 28);
    assert!(offset_of!(CudaBvhTree, arg) == 32);

    assert!(size_of::<CudaBvh>() == 56);
    assert!(offset_of!(CudaBvh, lowers) == 40);
    assert!(offset_of!(CudaBvh, uppers) == 48);

    assert!(size_of::<CudaMesh>() == 80);
    assert!(offset_of!(CudaMesh, points) == 40);
    assert!(offset_of!(CudaMesh, velocities) == 48);
    assert!(offset_of!(CudaMesh, indices) == 56);
    assert!(offset_of!(CudaMesh, num_points) == 64);
    assert!(offset_of!(CudaMesh, leaf_tris) == 72);
};

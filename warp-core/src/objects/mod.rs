//! Kernel-side views of host objects (Warp's hash grid, BVH, mesh and sparse volume).
//!
//! A host object (`warp_runtime::HashGrid`) owns its buffers on one device; a kernel thread
//! sees it through a `Copy` view made of [`ArrayView`](crate::ArrayView)s and sizes, which
//! owns nothing and checks every access (a bad index is a [`Fault`](crate::Fault) naming the
//! kernel and the parameter, never undefined behaviour). Queries are plain functions; an
//! iterating query is a small `Copy` state and a pure `next(view, state) -> state`, which the
//! kernel macro lowers `for j in query(..)` into, so the adjoint replays it like any other
//! value. The CUDA library mirrors each view and query step by step (`wp_<object>.h`).
//!
//! - [`bsr`]: block sparse row matrices (the `sparse` tier's `Bsr<B>`): row iteration, block
//!   reads, writes and atomic adds, block and row lookups, the gradient through block reads.
//! - [`hash_grid`]: Warp's hash grid: points bucketed into a wrapping uniform grid of cells.
//! - [`geometry`]: the triangle, ray and box tests the BVH and mesh queries are made of.
//! - [`bvh`]: Warp's BVH over boxes: the node layout every builder produces, the box and ray
//!   queries.
//! - [`mesh`]: Warp's triangle mesh: closest and furthest points, signed; ray hits; faces in a
//!   box; evaluation at barycentrics.
//! - [`nanovdb`]: the NanoVDB format facts (grid types, per-type layout, root key, map), the
//!   validator and the CPU grid builder.
//! - [`volume`]: Warp's sparse volumes (NanoVDB grids): lookups, sampling, stores,
//!   transforms, index variants and their adjoints. Unlike the views above, a
//!   [`VolumeView`] reads a grid that `nanovdb::validate` proved well formed, without checks.

/// The adjoint placeholder of an object's view or query state, which carry no gradient (what
/// depends on them are indices, and a gradient an object has travels inside its view): zero
/// is the given empty value, accumulation does nothing. One row per type:
/// `no_gradient!(HashGridView = HashGridView::empty())`, and for a generic view
/// `no_gradient!(where [T: VolumeGrid] VolumeView<T> = VolumeView::empty())`.
/// The C++ side's counterpart is the `wp_object_tag` member type (`wp_adjoint_core.h`).
macro_rules! no_gradient {
    ($($(where [$($g:tt)*])? $t:ty = $zero:expr),* $(,)?) => {$(
        impl<$($($g)*)?> crate::adjoint::Adjoint for $t {
            #[inline(always)]
            fn adj_zero() -> Self {
                $zero
            }
            #[inline(always)]
            fn adj_accum(&mut self, _: Self) {}
        }
    )*};
}

pub mod bsr;
pub mod bvh;
pub mod geometry;
pub mod hash_grid;
pub mod mesh;
pub mod nanovdb;
pub mod volume;

/// The builtins that live with their object's view, which [`builtins`](crate::builtins)
/// re-exports whole (generated code calls `builtins::NAME`): an object whose builtins are
/// written in its own module lists them here, and edits no other list.
pub mod builtins {
    pub use super::bsr::{
        bsr_add_block, bsr_block, bsr_block_index, bsr_col, bsr_ncol, bsr_nnz, bsr_nrow, bsr_row,
        bsr_row_done, bsr_row_index, bsr_row_item, bsr_row_next, bsr_set_block,
    };
    pub use super::hash_grid::{
        hash_grid_point_id, hash_grid_query, hash_grid_query_done, hash_grid_query_next,
        hash_grid_query_point,
    };
}

pub use bsr::{BsrBlock, BsrRowQuery, BsrScalar, BsrView};
pub use bvh::{BvhNode, BvhQueryAabb, BvhQueryRay, BvhTree, BvhView};
pub use hash_grid::{HashGridQuery, HashGridView};
pub use mesh::{MeshQueryAabb, MeshQueryPoint, MeshQueryRay, MeshView};
pub use volume::{VolumeGrid, VolumeSample, VolumeValue, VolumeView, VoxelIndex};

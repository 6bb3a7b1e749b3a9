//! Adjoints of the sparse volume's builtins ([`crate::builtins::volume`]), from
//! [`objects::volume`](crate::objects::volume), which documents their arithmetic:
//!
//! * `volume_sample`, `volume_sample_grad`: the position's adjoint (LINEAR; CLOSEST has
//!   none), and when the view has a gradient grid the values' (atomically added into it at
//!   the byte offset each value was read from).
//! * `volume_lookup`: the value's, into the gradient grid.
//! * the four transforms: `Mᵀ adj` (resp. `M⁻ᵀ adj`), for positions and directions.
//! * `volume_sample_index`, `volume_sample_grad_index`: the position's only (for now).
//!
//! `volume_store` and `volume_lookup_index` have no adjoint (Warp: zero gradient).

pub use crate::objects::volume::{
    adj_volume_index_to_world, adj_volume_index_to_world_dir, adj_volume_lookup, adj_volume_sample,
    adj_volume_sample_grad, adj_volume_sample_grad_index, adj_volume_sample_index,
    adj_volume_world_to_index, adj_volume_world_to_index_dir,
};

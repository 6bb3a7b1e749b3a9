//! The sparse volume's builtins (section "volume" of the builtin table), under their builtin
//! names. The algorithms, the exact arithmetic the CUDA mirror follows, and the view they
//! read ([`VolumeView`](crate::objects::VolumeView)) are in
//! [`objects::volume`](crate::objects::volume); the adjoints are re-exported from
//! [`crate::adjoint`].
//!
//! Every builtin takes the view by value and returns a `KResult` (the sampling builtins
//! fault on a NaN or infinite position; the index variants on an index beyond their value
//! array). Sampling modes: [`VOLUME_CLOSEST`] (0) and [`VOLUME_LINEAR`] (1; any mode but 0
//! samples this way).

pub use crate::objects::volume::{
    volume_index_to_world, volume_index_to_world_dir, volume_lookup, volume_lookup_index,
    volume_sample, volume_sample_grad, volume_sample_grad_index, volume_sample_index, volume_store,
    volume_world_to_index, volume_world_to_index_dir, CLOSEST as VOLUME_CLOSEST,
    LINEAR as VOLUME_LINEAR,
};

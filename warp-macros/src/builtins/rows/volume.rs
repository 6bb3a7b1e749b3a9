//! Sparse volumes (section "volume").

use super::*;

/// The volume reads, stores and transforms.
pub(super) const ROWS: &[Builtin] = rows! {
    // Warp's sparse volumes (warp-core `objects::volume` through `builtins::volume`;
    // wp_volume.h). The volume is a typed parameter, `Volume<T>`, so the value type is checked
    // at compile time where Warp checks it at run time (its `volume_sample_f/v/i` and `dtype=`
    // are one row here, typed by the volume). Modes: `VOLUME_CLOSEST` (0), `VOLUME_LINEAR`.
    // Positions are in index space (the transforms map world points there); a NaN or infinite
    // coordinate faults. Gradients flow to the sample position (LINEAR) and, for a volume
    // made with a gradient grid, into the stored values read.
    "volume_sample": VOL_FLOAT, (VolumeOfT, VEC3, I32) -> T, "volume", Adjoint, no_tangent;
    "volume_sample_grad": VOL_FLOAT, (VolumeOfT, VEC3, I32) -> Tuple(&[T, VolumeGradOfT]),
        "volume", Adjoint, no_tangent, results("(value, grad)");
    "volume_lookup": VOL_VALUE, (VolumeOfT, I32, I32, I32) -> T, "volume", Adjoint, no_tangent;
    "volume_store": VOL_VALUE, (VolumeOfT, I32, I32, I32, T) -> Unit, "volume", Effect, no_tangent;
    "volume_index_to_world": NO_T, (AnyVolume, VEC3) -> VEC3, "volume", Adjoint, no_tangent;
    "volume_world_to_index": NO_T, (AnyVolume, VEC3) -> VEC3, "volume", Adjoint, no_tangent;
    "volume_index_to_world_dir": NO_T, (AnyVolume, VEC3) -> VEC3, "volume", Adjoint, no_tangent;
    "volume_world_to_index_dir": NO_T, (AnyVolume, VEC3) -> VEC3, "volume", Adjoint, no_tangent;
    "volume_sample_index": VOL_FLOAT, (AnyVolume, VEC3, I32, ArrayOfT, T) -> T, "volume",
        Adjoint, no_tangent;
    "volume_sample_grad_index": VOL_FLOAT, (AnyVolume, VEC3, I32, ArrayOfT, T)
        -> Tuple(&[T, VolumeGradOfT]), "volume", Adjoint, no_tangent, results("(value, grad)");
    "volume_lookup_index": NO_T, (AnyVolume, I32, I32, I32) -> I32, "volume", Zero;
};

//! Rigid transforms (section "transform", wp_transform.h, warp-core `builtins::transform`).

use super::*;

/// The rigid transforms.
pub(super) const ROWS: &[Builtin] = rows! {
    // Rigid transforms (wp_transform.h, warp-core builtins::transform).
    "transformation": FVEC3, (T, QuatOfT) -> XformOfT, "transform", Adjoint,
        no_tangent, ctor(Transform, "new");
    "transform_get_translation": XFORM, (T) -> Vec3OfT, "transform", Adjoint, no_tangent;
    "transform_get_rotation": XFORM, (T) -> QuatOfT, "transform", Adjoint, no_tangent;
    "transform_multiply": XFORM, (T, T) -> T, "transform", Adjoint, no_tangent;
    "transform_point": XFORM_OR_MAT4, (T, Vec3OfT) -> Vec3OfT, "transform", Adjoint, no_tangent,
        method, aliases(&["transform_point3"]);
    "transform_vector": XFORM_OR_MAT4, (T, Vec3OfT) -> Vec3OfT, "transform", Adjoint, no_tangent,
        method, aliases(&["transform_vector3"]);
    "transform_inverse": XFORM, (T) -> T, "transform", Adjoint, no_tangent;
    "transform_to_matrix": XFORM, (T) -> MatOfT, "transform", Adjoint, no_tangent;
    "transform_from_matrix": &[Matrix4], (T) -> XformOfT, "transform", Adjoint, no_tangent,
        ctor(Transform, "from_matrix");
};

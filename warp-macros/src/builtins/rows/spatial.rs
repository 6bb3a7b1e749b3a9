//! Spatial vectors and matrices (section "spatial", wp_spatial.h, warp-core
//! `builtins::spatial`). `transpose` and `outer` of spatial types are the linalg rows'.

use super::*;

/// Warp's Spatial Math group.
pub(super) const ROWS: &[Builtin] = rows! {
    // The constructors are linear in their arguments together, which no rule of one argument
    // states (a sum of two calls would add the other argument twice): no forward rule.
    "spatial_vector": FVEC3, (T, T) -> SVecOfT, "spatial", Adjoint,
        no_tangent, ctor(SpatialVector, "new");
    "spatial_vector_scalars": SPATIAL_SCALAR, (T, T, T, T, T, T) -> SVecOfT, "spatial", Adjoint,
        no_tangent, overload("spatial_vector", 6), internal;
    "spatial_top": SVEC, (T) -> Vec3OfT, "spatial", Adjoint, tangent(LINEAR);
    "spatial_bottom": SVEC, (T) -> Vec3OfT, "spatial", Adjoint, tangent(LINEAR);
    "spatial_dot": SVEC, (T, T) -> ScalarOfT, "spatial", Adjoint, tangent(BILINEAR);
    "spatial_cross": SVEC, (T, T) -> T, "spatial", Adjoint, tangent(BILINEAR);
    "spatial_cross_dual": SVEC, (T, T) -> T, "spatial", Adjoint, tangent(BILINEAR);
    "spatial_adjoint": &[Matrix3], (T, T) -> SMatOfT, "spatial", Adjoint, no_tangent;
    // Warp's `@wp.func`s of math.py; transforms carry no tangents yet.
    "transform_twist": XFORM, (T, SVecOfT) -> SVecOfT, "spatial", Adjoint, no_tangent;
    "transform_wrench": XFORM, (T, SVecOfT) -> SVecOfT, "spatial", Adjoint, no_tangent;
    // Warp's `@wp.func` of math.py: `v + w × r` of the twist `(w, v)`. Linear in the twist,
    // so its tangent is the builtin of the twist's tangent plus `w × r'`.
    "velocity_at_point": SVEC, (T, Vec3OfT) -> Vec3OfT, "spatial", Adjoint,
        tangent(Tangent::Rule(Add(
            &This(&[D0, A1]),
            &Call("cross", &[Call("spatial_top", &[A0]), D1]),
        ))),
        method;
};

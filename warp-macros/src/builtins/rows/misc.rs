//! More vector, quaternion and transform builtins (section "misc").

use super::*;

/// Warp's miscellaneous builtins.
pub(super) const ROWS: &[Builtin] = rows! {
    // More vector, quaternion and transform builtins (warp-core `builtins::misc`, wp_misc.h).
    // `min(v)`/`max(v)` of one vector are `min_element`/`max_element` (glam's names), and
    // `lower_bound(a, lo, hi, v)` is `lower_bound_range` (overloads by arity); the norms'
    // `delta` defaults to 1 as in Warp.
    "copysign":   FLOAT,          (T, T) -> T,              "misc", Adjoint, no_tangent, method;
    "nonzero":    NUMBER,         (T) -> T,                 "misc", Zero;
    "block_dim":  NO_T,           () -> I32,                "misc", Zero;
    "min_element": VECS, (T) -> ScalarOfT, "misc", Adjoint, no_tangent, method, overload("min", 1);
    "max_element": VECS, (T) -> ScalarOfT, "misc", Adjoint, no_tangent, method, overload("max", 1);
    "argmin":     VECS,           (T) -> U32,               "misc", Zero;
    "argmax":     VECS,           (T) -> U32,               "misc", Zero;
    "get_diag":   MAT,            (T) -> VecOfT,            "misc", Adjoint,
        tangent(LINEAR);
    "norm_l1":    FVEC,           (T) -> ScalarOfT,         "misc", Adjoint, no_tangent;
    "norm_l2":    FVEC,           (T) -> ScalarOfT,         "misc", Adjoint,
        tangent(linalg::LENGTH);
    "norm_huber": FVEC,           (T, ScalarOfT) -> ScalarOfT, "misc", Adjoint,
        no_tangent, default_last("1.0");
    "norm_pseudo_huber": FVEC, (T, ScalarOfT) -> ScalarOfT, "misc", Adjoint,
        no_tangent, default_last("1.0");
    "smooth_normalize": FVEC, (T, ScalarOfT) -> T, "misc", Adjoint,
        no_tangent, default_last("1.0");
    "quat_to_axis_angle": QUAT, (T) -> Tuple(&[Vec3OfT, ScalarOfT]), "misc", Adjoint, no_tangent,
        results("(axis, angle)");
    "quat_rpy":   FLOAT,          (T, T, T) -> QuatOfT,     "misc", Adjoint, no_tangent;
    "quat_to_rpy": QUAT, (T) -> VecOfT, "misc", Adjoint, no_tangent;
    "quat_twist": FVEC3,          (T, QuatOfT) -> QuatOfT,  "misc", Adjoint, no_tangent;
    "quat_twist_angle": FVEC3, (T, QuatOfT) -> ScalarOfT, "misc", Adjoint, no_tangent;
    "quat_twist_angle_signed": FVEC3, (T, QuatOfT) -> ScalarOfT, "misc", Adjoint, no_tangent;
    "transform_compose": FVEC3, (T, QuatOfT, T) -> Mat4OfT, "misc", Adjoint, no_tangent;
    "transform_decompose": &[Matrix4], (T) -> Tuple(&[Vec3OfT, QuatOfT, Vec3OfT]), "misc", Adjoint,
        no_tangent,
        results("(p, q, s)");
    "lower_bound": NUMBER, (ArrayOfT, T) -> I32, "misc", Zero;
    "lower_bound_range": NUMBER, (ArrayOfT, I32, I32, T) -> I32, "misc", Zero,
        overload("lower_bound", 4), internal;
    // Warp's test expectations (warp-core `builtins::expect`): each row is the check, true when
    // the expectation holds. Written as a statement (`expect_eq(a, b);`, the only way the front
    // end takes them, `front/lower/asserts.rs`), a false one is a fault naming the line.
    "expect_eq":  EXPECT,         (T, T) -> BOOL,           "misc", Zero;
    "expect_neq": EXPECT,         (T, T) -> BOOL,           "misc", Zero;
    "expect_near": NEAR,          (T, T, ScalarOfT) -> BOOL, "misc", Zero;
};

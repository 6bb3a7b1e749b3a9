//! Vector, matrix and quaternion builtins (sections "vector", "linalg", "svd"; warp-core
//! `builtins::{vector, linalg, svd}`).

use super::*;

/// Vectors, matrices and quaternions.
pub(super) const ROWS: &[Builtin] = rows! {
    // dot, length and normalize take quaternions too, whose versions are in "linalg" (which
    // includes "vector").
    "dot":        VEC_OR_QUAT,    (T, T) -> ScalarOfT,      "linalg", Adjoint,
        tangent(BILINEAR), method;
    "cross":      &[Vector3],     (T, T) -> T,              "vector", Adjoint,
        tangent(BILINEAR), method;
    // |a|' = (a / |a|) . a' (zero at a = 0, where normalize gives zero).
    "length":     FVEC_OR_QUAT,   (T) -> ScalarOfT,         "linalg", Adjoint,
        tangent(LENGTH), method;
    "normalize":  FVEC_OR_QUAT,   (T) -> T,                 "linalg", Adjoint,
        tangent(Tangent::RuleFor(FVEC, NORMALIZE)), method;
    "length_sq":  VEC_OR_QUAT,    (T) -> ScalarOfT,         "linalg", Adjoint,
        tangent(Tangent::Rule(Add(&Call("dot", &[D0, A0]), &Call("dot", &[D0, A0])))),
        aliases(&["length_squared"]);
    // Of two vectors of one scalar, any lengths: shape `(len a, len b)`, Warp's.
    "outer":      FVEC_OR_SVEC,   (T, AnyVecOfT) -> OuterOfT, "linalg", Adjoint,
        tangent(BILINEAR);
    "diag":       FVEC,           (T) -> MatOfT,            "linalg", Adjoint,
        tangent(LINEAR);
    "cw_mul":     FVEC_OR_MAT,    (T, T) -> T,              "linalg", Adjoint,
        tangent(BILINEAR);
    // cw_div(a, b)' = cw_div(a', b) - cw_mul(cw_div(a, b), cw_div(b', b))
    "cw_div":     FVEC_OR_MAT,    (T, T) -> T,              "linalg", Adjoint,
        tangent(Tangent::Rule(Sub(
            &This(&[D0, A1]),
            &Call("cw_mul", &[OUT, This(&[D1, A1])]),
        )));
    "transpose":  ANY_MAT,        (T) -> TransposeOfT,      "linalg", Adjoint,
        tangent(LINEAR), method;
    // det(A)' = det(A) tr(A^-1 A')
    "determinant": MAT,           (T) -> ScalarOfT,         "linalg", Adjoint,
        tangent(Tangent::Rule(Mul(
            &OUT,
            &Call("trace", &[Mul(&Call("inverse", &[A0]), &D0)]),
        ))),
        method;
    // inverse(A)' = -A^-1 A' A^-1 (matrices only, so far).
    "inverse":    MAT_QUAT_XFORM, (T) -> T,                 "linalg", Adjoint,
        tangent(Tangent::RuleFor(MAT, Neg(&Mul(&Mul(&OUT, &D0), &OUT)))), method;
    "trace":      MAT,            (T) -> ScalarOfT,         "linalg", Adjoint,
        tangent(LINEAR);
    "ddot":       MAT_OR_NONSQUARE, (T, T) -> ScalarOfT,    "linalg", Adjoint,
        tangent(BILINEAR);
    "skew":       FVEC3,          (T) -> MatOfT,            "linalg", Adjoint,
        tangent(LINEAR);
    "quat_from_axis_angle": FVEC3, (T, ScalarOfT) -> QuatOfT, "linalg", Adjoint, no_tangent,
        ctor(Quaternion, "from_axis_angle");
    "quat_rotate": QUAT, (T, VecOfT) -> VecOfT, "linalg", Adjoint, no_tangent;
    "quat_rotate_inv": QUAT, (T, VecOfT) -> VecOfT, "linalg", Adjoint, no_tangent;
    "quat_inverse": QUAT, (T) -> T, "linalg", Adjoint, no_tangent, aliases(&["conjugate"]);
    "quat_to_matrix": QUAT, (T) -> MatOfT, "linalg", Adjoint, no_tangent,
        ctor(Matrix3, "from_quat");
    "quat_from_matrix": &[Matrix3], (T) -> QuatOfT, "linalg", Adjoint, no_tangent;
    "quat_slerp": QUAT,           (T, T, ScalarOfT) -> T,   "linalg", Adjoint, no_tangent;
    // Warp's `@wp.func`s of math.py (warp-core `builtins/euler.rs`): the axis sequence is
    // three run-time indices, 0 = x, 1 = y, 2 = z.
    "quat_from_euler": FVEC3, (T, I32, I32, I32) -> QuatOfT, "linalg", Adjoint, no_tangent;
    "quat_to_euler": QUAT, (T, I32, I32, I32) -> VecOfT, "linalg", Adjoint, no_tangent;
};

/// The decompositions (after the transforms in the table, as in docs/book/src/builtins.md).
pub(super) const DECOMPOSITIONS: &[Builtin] = rows! {
    // Decompositions: tuples in the order of Warp's output arguments, only bound by a
    // destructuring `let` (see `front::lower::statements`). Forward mode does not follow
    // tuples yet.
    "svd3":       &[Matrix3],     (T) -> Tuple(&[T, VecOfT, T]), "svd", Adjoint, no_tangent,
        results("(u, sigma, v)");
    "svd2":       &[Matrix2],     (T) -> Tuple(&[T, VecOfT, T]), "svd", Adjoint, no_tangent,
        results("(u, sigma, v)");
    "qr3":        &[Matrix3],     (T) -> Tuple(&[T, T]),    "svd", Adjoint, no_tangent,
        results("(q, r)");
    "eig3":       &[Matrix3],     (T) -> Tuple(&[T, VecOfT]), "svd", Adjoint, no_tangent,
        results("(q, d)");
};

/// `length`'s and `norm_l2`'s rule: `normalize(a) . a'`.
pub(super) const LENGTH: Tangent = Tangent::Rule(Call("dot", &[D0, Call("normalize", &[A0])]));

/// `normalize(a)' = (a' - n (n . a')) / |a|`, and zero at `a = 0` (where normalize gives zero,
/// and so does reverse mode): the division is by `|a| + (1 - nonzero(|a|))` and the quotient
/// is scaled by `nonzero(|a|)`, both exact where `|a| != 0`.
const NORMALIZE: Dx = Mul(
    &Div(
        &Sub(&D0, &Mul(&OUT, &Call("dot", &[OUT, D0]))),
        &Add(&NORM, &Sub(&Const(1.0), &NONZERO_NORM)),
    ),
    &NONZERO_NORM,
);
const NORM: Dx = Call("length", &[A0]);
const NONZERO_NORM: Dx = Call("nonzero", &[NORM]);

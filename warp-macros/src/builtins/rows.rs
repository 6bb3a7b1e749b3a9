//! The table's rows, one file per group of sections, and [`BUILTINS`], their concatenation in
//! the order docs/book/src/builtins.md lists them. A row is written with [`rows!`]; this module holds
//! the shorthands the rows share (sets of classes, fixed positions).

use super::tangent::{
    chain, quotient, Dx, Dx::*, Pick, Tangent, A0, A1, A2, BILINEAR, D0, D1, D2, LINEAR, OUT,
};
use super::{Builtin, Class, Grad, Pos};
use crate::operators::BinOp;
use crate::types::{ObjectKind, Scalar};
use std::f64::consts::{FRAC_2_SQRT_PI, LN_10, LN_2};

/// Rows: `"name": classes, (params) -> result, "section", grad` and then the facts in which
/// the row differs from [`Builtin::row`]'s defaults, each the name of a builder method with
/// its arguments (`method`, `aliases(&["powf"])`, `draws(2)`, ...). A row with a gradient
/// states its forward-mode rule first among them: `tangent(rule)` or `no_tangent`. The CPU
/// function is `warp_core::builtins::<name>`, the CUDA one `wp::<name>`.
macro_rules! rows {
    ($( $name:literal : $classes:expr, ($($p:expr),*) -> $ret:expr, $sec:literal, $g:ident
        $(, $fact:ident $(( $($arg:expr),* ))? )* ; )*) => {
        &[$(
            Builtin::row($name, concat!("wp::", $name), $classes, &[$($p),*], $ret, $sec, Grad::$g)
                $( .$fact( $( $($arg),* )? ) )*,
        )*]
    };
}

mod atomic;
mod bsr;
mod geometry;
mod linalg;
mod misc;
mod rand;
mod scalar;
mod spatial;
mod tile;
mod transform;
mod volume;

/// The sections in the table's order.
const SECTIONS: &[&[Builtin]] = &[
    scalar::ROWS,
    linalg::ROWS,
    transform::ROWS,
    spatial::ROWS,
    linalg::DECOMPOSITIONS,
    atomic::ROWS,
    rand::ROWS,
    misc::ROWS,
    geometry::ROWS,
    volume::ROWS,
    bsr::ROWS,
    tile::ROWS,
];

const COUNT: usize = {
    let (mut n, mut s) = (0, 0);
    while s < SECTIONS.len() {
        n += SECTIONS[s].len();
        s += 1;
    }
    n
};

/// The sections' rows in one array (a constant, so a row is never built at run time).
const fn concat() -> [Builtin; COUNT] {
    let none = Builtin::row("", "", &[], &[], Pos::Unit, "", Grad::Zero);
    let mut rows = [none; COUNT];
    let (mut k, mut s) = (0, 0);
    while s < SECTIONS.len() {
        let mut r = 0;
        while r < SECTIONS[s].len() {
            rows[k] = SECTIONS[s][r];
            k += 1;
            r += 1;
        }
        s += 1;
    }
    rows
}

static ROWS: [Builtin; COUNT] = concat();

/// Every builtin.
pub static BUILTINS: &[Builtin] = &ROWS;

use Class::*;
use Pos::*;

const NUM_OR_VEC: &[Class] = &[Number, FloatVector, IntVector];
const SIGNED: &[Class] = &[SignedNumber, SignedVector];
const FLOAT: &[Class] = &[Float];
/// `isfinite`, `isnan`, `isinf`: float scalars, vectors, quaternions, matrices.
const CLASSIFY: &[Class] = &[Float, FloatVector, Quaternion, Matrix];
/// Float and integer vectors (the one-vector reductions).
const VECS: &[Class] = &[FloatVector, IntVector];
const FVEC: &[Class] = &[FloatVector];
const NUMBER: &[Class] = &[Number];
/// `expect_eq`, `expect_neq`: every type with `==` but bool and the tuples.
const EXPECT: &[Class] = &[Number, FloatVector, IntVector, Quaternion, Matrix];
/// `expect_near`: float scalars and vectors (the tolerance is a lane's).
const NEAR: &[Class] = &[Float, FloatVector];
const VEC_OR_QUAT: &[Class] = &[FloatVector, IntVector, Quaternion];
const FVEC_OR_QUAT: &[Class] = &[FloatVector, Quaternion];
const FVEC_OR_MAT: &[Class] = &[FloatVector, Matrix];
const MAT: &[Class] = &[Matrix];
/// `transpose`: glam's square matrices, the spatial and the non-square matrices.
const ANY_MAT: &[Class] = &[Matrix, SpatialMatrix, NonSquare];
/// `ddot`: glam's square matrices and the non-square matrices.
const MAT_OR_NONSQUARE: &[Class] = &[Matrix, NonSquare];
/// `outer`: float vectors and spatial vectors.
const FVEC_OR_SVEC: &[Class] = &[FloatVector, SpatialVector];
const SVEC: &[Class] = &[SpatialVector];
const SPATIAL_SCALAR: &[Class] = &[SpatialScalar];
const MAT_QUAT_XFORM: &[Class] = &[Matrix, Quaternion, Transform];
/// `lerp`: float scalars and vectors, square matrices, quaternions, transforms, spatial
/// vectors and matrices.
const LERP: &[Class] = &[
    Float,
    FloatVector,
    Matrix,
    Quaternion,
    Transform,
    SpatialVector,
    SpatialMatrix,
];
const XFORM: &[Class] = &[Transform];
const XFORM_OR_MAT4: &[Class] = &[Transform, Matrix4];
const QUAT: &[Class] = &[Quaternion];
const FVEC3: &[Class] = &[FloatVector3];
/// The classes of a builtin whose signature does not mention `T` (every type is fixed).
const NO_T: &[Class] = &[];
const NOISE: &[Class] = &[Noise];
const U32: Pos = Fixed(Scalar::U32);
const I32: Pos = Fixed(Scalar::I32);
const F32: Pos = Fixed(Scalar::F32);
const VEC2: Pos = FixedVec(Scalar::F32, 2);
const VEC3: Pos = FixedVec(Scalar::F32, 3);
const USIZE: Pos = Fixed(Scalar::Usize);
pub(super) const BOOL: Pos = Fixed(Scalar::Bool);
const GRID: Pos = Object(ObjectKind::HashGrid);
pub(super) const GRID_QUERY: Pos = Object(ObjectKind::HashGridQuery);
const BVH: Pos = Object(ObjectKind::Bvh);
pub(super) const BVH_AABB: Pos = Object(ObjectKind::BvhQueryAabb);
pub(super) const BVH_RAY: Pos = Object(ObjectKind::BvhQueryRay);
const MESH: Pos = Object(ObjectKind::Mesh);
pub(super) const MESH_AABB: Pos = Object(ObjectKind::MeshQueryAabb);
const VOL_VALUE: &[Class] = &[Class::VolumeValue];
const VOL_FLOAT: &[Class] = &[Class::VolumeFloat];
const BSR_BLOCK: &[Class] = &[Class::BsrBlock];
pub(super) const BSR_ROW: Pos = Object(ObjectKind::BsrRow);
/// A point query's result: `(result, sign, face, u, v)` (Warp's `mesh_query_point_t`).
const POINT_RESULT: Pos = Tuple(&[BOOL, F32, I32, F32, F32]);
/// A ray query's result: `(result, sign, face, t, u, v, normal)` (Warp's `mesh_query_ray_t`).
const RAY_RESULT: Pos = Tuple(&[BOOL, F32, I32, F32, F32, F32, VEC3]);

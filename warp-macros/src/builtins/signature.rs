//! The vocabulary of a builtin's signature: which types the type variable `T` may take
//! ([`Class`]) and the positions of a signature in terms of `T` ([`Pos`]). A leaf: the row
//! (`row.rs`), the forward-mode rules (`tangent.rs`) and the matcher (`matcher.rs`) all speak
//! it, and it names none of them.

use crate::types::{ObjectKind, Scalar, Ty};

/// Which types the type variable `T` of a builtin may take.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Class {
    /// f32, f64, f16 (f16: the f32 builtin on the widened arguments, rounded once).
    Float,
    /// Any integer or float scalar.
    Number,
    /// Signed integers and floats.
    SignedNumber,
    /// Float vectors (Vec2-4, DVec2-4).
    FloatVector,
    /// Integer vectors (IVec2-4, UVec2-4).
    IntVector,
    /// Signed vectors (float vectors and IVec2-4).
    SignedVector,
    /// Vec3, DVec3, IVec3 (cross).
    Vector3,
    /// Types CPU and GPU atomics exist for: i32, u32, i64, u64, f32, f64, f16, bf16 and float
    /// vectors.
    Atomic,
    /// Float square matrices (Mat2-4, DMat2-4).
    Matrix,
    /// Mat3, DMat3 (quat_from_matrix, svd3, eig3, qr3).
    Matrix3,
    /// Mat2, DMat2 (svd2).
    Matrix2,
    /// Vec3, DVec3 (skew, quat_from_axis_angle).
    FloatVector3,
    /// Quat, DQuat.
    Quaternion,
    /// Integer types with CPU and GPU atomics: i32, u32, i64, u64 (atomic_and/or/xor).
    AtomicInt,
    /// Scalars with CPU and GPU atomics: i32, u32, i64, u64, f32, f64 (atomic_cas/exch).
    AtomicScalar,
    /// f32, Vec2, Vec3, Vec4 (Perlin noise: f32 only, as in Warp).
    Noise,
    /// Transform, DTransform.
    Transform,
    /// Mat4, DMat4 (the matrix overloads of transform_point, transform_vector).
    Matrix4,
    /// SpatialVector, DSpatialVector.
    SpatialVector,
    /// SpatialMatrix, DSpatialMatrix.
    SpatialMatrix,
    /// The non-square matrices (Mat23 .. Mat64, DMat23 .. DMat64).
    NonSquare,
    /// f32, f64: the scalars spatial vectors are made of (the six-scalar `spatial_vector`).
    SpatialScalar,
    /// The values a `Volume<T>` holds: f32, f64, i32, Vec3, DVec3 (lookups, stores).
    VolumeValue,
    /// The values a volume interpolates: f32, f64, Vec3, DVec3 (sampling).
    VolumeFloat,
    /// The block types of a `Bsr<B>`: f32, f64, Mat2-4, DMat2-4, Mat23 .. DMat64.
    BsrBlock,
}

impl Class {
    pub fn admits(self, ty: &Ty) -> bool {
        match (self, ty) {
            (Class::Float, Ty::Scalar(s)) => s.is_float(),
            (Class::Number, Ty::Scalar(s)) => *s != Scalar::Bool,
            (Class::SignedNumber, Ty::Scalar(s)) => s.is_float() || s.is_signed_int(),
            (Class::FloatVector, Ty::Vector(s, _)) => s.is_float(),
            (Class::IntVector, Ty::Vector(s, _)) => !s.is_float(),
            (Class::SignedVector, Ty::Vector(s, _)) => *s != Scalar::U32,
            // Not UVec3: glam has no cross product for it (its result would wrap).
            (Class::Vector3, Ty::Vector(s, 3)) => *s != Scalar::U32,
            (Class::Atomic, Ty::Scalar(s)) => {
                matches!(
                    s,
                    Scalar::I32
                        | Scalar::U32
                        | Scalar::I64
                        | Scalar::U64
                        | Scalar::F32
                        | Scalar::F64
                        | Scalar::F16
                        | Scalar::BF16
                )
            }
            (Class::Atomic, Ty::Vector(s, _)) => s.is_float(),
            (Class::Matrix, Ty::Matrix(..)) => true,
            (Class::Matrix3, Ty::Matrix(_, 3)) => true,
            (Class::Matrix2, Ty::Matrix(_, 2)) => true,
            (Class::FloatVector3, Ty::Vector(s, 3)) => s.is_float(),
            (Class::Quaternion, Ty::Quat(_)) => true,
            (Class::AtomicInt, Ty::Scalar(s)) => {
                matches!(s, Scalar::I32 | Scalar::U32 | Scalar::I64 | Scalar::U64)
            }
            (Class::AtomicScalar, Ty::Scalar(s)) => matches!(
                s,
                Scalar::I32 | Scalar::U32 | Scalar::I64 | Scalar::U64 | Scalar::F32 | Scalar::F64
            ),
            (Class::Noise, Ty::Scalar(Scalar::F32)) => true,
            (Class::Noise, Ty::Vector(Scalar::F32, _)) => true,
            (Class::Transform, Ty::Transform(_)) => true,
            (Class::Matrix4, Ty::Matrix(_, 4)) => true,
            (Class::SpatialVector, Ty::SpatialVector(_)) => true,
            (Class::SpatialMatrix, Ty::SpatialMatrix(_)) => true,
            (Class::NonSquare, Ty::MatRC(..)) => true,
            (Class::SpatialScalar, Ty::Scalar(s)) => matches!(s, Scalar::F32 | Scalar::F64),
            (Class::VolumeValue, t) => crate::types::VolumeElem::of(t).is_some(),
            (Class::VolumeFloat, t) => {
                crate::types::VolumeElem::of(t).is_some() && *t != Ty::Scalar(Scalar::I32)
            }
            (Class::BsrBlock, t) => crate::types::BlockElem::of(t).is_some(),
            _ => false,
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Class::Float => "f32, f64, f16 or bf16",
            Class::Number => "an integer or float scalar",
            Class::SignedNumber => "a signed integer or float scalar",
            Class::FloatVector => "a float vector (Vec2-4, DVec2-4)",
            Class::IntVector => "an integer vector (IVec2-4, UVec2-4)",
            Class::SignedVector => "a signed vector (Vec2-4, DVec2-4, IVec2-4)",
            Class::Vector3 => "a 3-vector (Vec3, DVec3, IVec3)",
            Class::Atomic => "i32, u32, i64, u64, f32, f64, f16, bf16 or a float vector",
            Class::Matrix => "a matrix (Mat2-4, DMat2-4)",
            Class::Matrix3 => "a 3x3 matrix (Mat3, DMat3)",
            Class::Matrix2 => "a 2x2 matrix (Mat2, DMat2)",
            Class::FloatVector3 => "a float 3-vector (Vec3, DVec3)",
            Class::Quaternion => "a quaternion (Quat, DQuat)",
            Class::AtomicInt => "i32, u32, i64 or u64",
            Class::AtomicScalar => "i32, u32, i64, u64, f32 or f64",
            Class::Noise => "f32, Vec2, Vec3 or Vec4",
            Class::Transform => "a transform (Transform, DTransform)",
            Class::Matrix4 => "a 4x4 matrix (Mat4, DMat4)",
            Class::SpatialVector => "a spatial vector (SpatialVector, DSpatialVector)",
            Class::SpatialMatrix => "a spatial matrix (SpatialMatrix, DSpatialMatrix)",
            Class::NonSquare => "a non-square matrix (Mat23 .. Mat64, DMat23 .. DMat64)",
            Class::SpatialScalar => "f32 or f64",
            Class::VolumeValue => "a volume value (f32, f64, i32, Vec3, DVec3)",
            Class::VolumeFloat => "a float volume value (f32, f64, Vec3, DVec3)",
            Class::BsrBlock => {
                "a sparse matrix block (f32, f64, Mat2-4, DMat2-4, Mat23 .. Mat64, DMat23 .. DMat64)"
            }
        }
    }
}

/// A parameter or result position in a signature.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pos {
    /// The type variable itself.
    T,
    /// The scalar `T` is made of.
    ScalarOfT,
    /// An `Array<T, N>` (any N).
    ArrayOfT,
    /// An index into the preceding array: an integer, or a tuple for N > 1.
    Index,
    /// `bool` (the result of the classification builtins `isfinite`, `isnan`, `isinf`).
    Bool,
    /// The square matrix of `T`'s scalar whose size is `T`'s: `Mat3` for `Vec3` (`outer`,
    /// `diag`, `skew`), `Mat3` for `Quat` (`quat_to_matrix`), `Mat4` for `Transform`
    /// (`transform_to_matrix`), `SpatialMatrix` for `SpatialVector` (`outer`).
    MatOfT,
    /// The vector `T` acts on: a matrix's column type; `Vec3` for `Quat` (`quat_rotate`).
    VecOfT,
    /// The quaternion of `T`'s scalar (`quat_from_axis_angle`, `quat_from_matrix`).
    QuatOfT,
    /// `i32` for a scalar `T`, the `i32` vector of `T`'s size for a vector (`pnoise`'s
    /// periods).
    IntOfT,
    /// A fixed scalar type, whatever `T` is (the RNG's `u32` state, `i32` seeds, `f32` draws).
    Fixed(Scalar),
    /// A fixed vector type (the samplers' `Vec2`, `Vec3`).
    FixedVec(Scalar, u8),
    /// The 3-vector of `T`'s scalar (`transform_point`, `transform_get_translation`).
    Vec3OfT,
    /// The transform of `T`'s scalar (`transformation`, `transform_from_matrix`).
    XformOfT,
    /// The spatial vector of `T`'s scalar (`spatial_vector`, `transform_twist`).
    SVecOfT,
    /// The spatial matrix of `T`'s scalar (`spatial_adjoint`).
    SMatOfT,
    /// The transpose of the matrix `T`: `T` itself for a square one, `Mat32` for `Mat23`.
    TransposeOfT,
    /// A float vector of `T`'s scalar of any length (`outer`'s second argument): the
    /// argument's own type.
    AnyVecOfT,
    /// The matrix of `T`'s scalar of shape `(len T, len b)`, `b` the [`Pos::AnyVecOfT`]
    /// argument (`outer(a, b)`; results only).
    OuterOfT,
    /// A tuple of these (results only: the decompositions, `svd3(a) -> (T, VecOfT, T)`).
    Tuple(&'static [Pos]),
    /// The 4x4 matrix of `T`'s scalar (`transform_compose`).
    Mat4OfT,
    /// A host object or a query state of that kind, whatever `T` is (`hash_grid_query`'s
    /// grid).
    Object(ObjectKind),
    /// A `Volume<T>`: binds `T` to the volume's value type (`volume_sample(v, ..) -> T`).
    VolumeOfT,
    /// A `Volume` of any element, index grids included (the transforms, the index reads).
    AnyVolume,
    /// The gradient of a `T` sample: `Vec3` of `T`'s scalar for a scalar, the 3x3 matrix of
    /// its scalar (row `c`: component `c`'s gradient) for a 3-vector.
    VolumeGradOfT,
    /// A `Bsr<T>`: binds `T` to the matrix's block type (`bsr_block(a, k) -> T`).
    BsrOfT,
    /// A `Bsr` of any block type (the structure's queries).
    AnyBsr,
    /// `()`: the builtin is a statement (`volume_store`).
    Unit,
    /// A tile of `T` (its shape is the tile typer's business: `front::lower::tiles`).
    Tile,
    /// A tile's shape, written as a turbofish, Warp's tuple or the `let` annotation.
    TileShape,
    /// A tile's offsets into an array: one signed integer per array dimension.
    Offsets,
    /// The function `tile_map` applies (a builtin's name).
    TileFn,
}

impl Pos {
    /// Whether the position's type does not depend on `T`.
    pub fn fixed(&self) -> bool {
        match self {
            Pos::Fixed(_)
            | Pos::FixedVec(..)
            | Pos::Bool
            | Pos::Index
            | Pos::Object(_)
            | Pos::AnyVolume
            | Pos::AnyBsr
            | Pos::Unit => true,
            // A tuple of fixed types (the mesh queries' results).
            Pos::Tuple(ps) => ps.iter().all(Pos::fixed),
            _ => false,
        }
    }
}

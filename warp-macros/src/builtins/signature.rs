//! A builtin's signature and the matcher: which types the type variable `T` may take
//! ([`Class`]), the positions of a signature in terms of `T` ([`Pos`]), and the matching of a
//! call's argument types against a row's signature ([`Builtin::resolve`]).
//!
//! Matching binds `T` from the first argument whose type is known and fixed by `T` (a `T` or
//! `Array<T>` position); literal arguments are then typed from `T`, which is the one literal
//! rule both backends share (see `front::lower::typing`).

use super::Builtin;
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
    /// Types CPU and GPU atomics exist for: i32, u32, i64, u64, f32, f64, f16 and float
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
    /// The values a `Volume<T>` holds: f32, f64, i32, Vec3, DVec3 (lookups, stores).
    VolumeValue,
    /// The values a volume interpolates: f32, f64, Vec3, DVec3 (sampling).
    VolumeFloat,
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
            (Class::VolumeValue, t) => crate::types::VolumeElem::of(t).is_some(),
            (Class::VolumeFloat, t) => {
                crate::types::VolumeElem::of(t).is_some() && *t != Ty::Scalar(Scalar::I32)
            }
            _ => false,
        }
    }

    pub fn describe(self) -> &'static str {
        match self {
            Class::Float => "f32, f64 or f16",
            Class::Number => "an integer or float scalar",
            Class::SignedNumber => "a signed integer or float scalar",
            Class::FloatVector => "a float vector (Vec2-4, DVec2-4)",
            Class::IntVector => "an integer vector (IVec2-4, UVec2-4)",
            Class::SignedVector => "a signed vector (Vec2-4, DVec2-4, IVec2-4)",
            Class::Vector3 => "a 3-vector (Vec3, DVec3, IVec3)",
            Class::Atomic => "i32, u32, i64, u64, f32, f64, f16 or a float vector",
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
            Class::VolumeValue => "a volume value (f32, f64, i32, Vec3, DVec3)",
            Class::VolumeFloat => "a float volume value (f32, f64, Vec3, DVec3)",
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
    /// (`transform_to_matrix`).
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
    /// `()`: the builtin is a statement (`volume_store`).
    Unit,
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
            | Pos::Unit => true,
            // A tuple of fixed types (the mesh queries' results).
            Pos::Tuple(ps) => ps.iter().all(Pos::fixed),
            _ => false,
        }
    }
}

/// An argument as the matcher sees it.
#[derive(Clone, Debug)]
pub enum ArgTy {
    /// A value of known (possibly deferred) type.
    Known(Ty),
    /// An unsuffixed numeric literal, typed by the signature.
    Literal { float: bool },
}

/// The outcome of matching a call against a builtin's signature.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    /// The type each argument takes (literals included); `Deferred` where unknown.
    pub params: Vec<Ty>,
    pub ret: Ty,
}

impl Builtin {
    /// Matches argument types against the signature, binding `T`.
    pub fn resolve(&self, args: &[ArgTy]) -> Result<Resolved, String> {
        if args.len() != self.params.len() {
            return Err(format!(
                "`{}` takes {} argument{}, found {}",
                self.name,
                self.params.len(),
                if self.params.len() == 1 { "" } else { "s" },
                args.len()
            ));
        }
        // Bind T from the first known argument in a T or Array<T> position.
        let mut t: Option<Ty> = None;
        let mut array_ndim = 1u8;
        for (pos, arg) in self.params.iter().zip(args) {
            match (pos, arg) {
                (Pos::T, ArgTy::Known(ty)) if !ty.is_deferred() && t.is_none() => {
                    t = Some(ty.clone())
                }
                (Pos::ArrayOfT, ArgTy::Known(Ty::Array(elem, n))) => {
                    array_ndim = *n;
                    if t.is_none() {
                        t = Some((**elem).clone());
                    }
                }
                (Pos::ArrayOfT, ArgTy::Known(ty)) if !ty.is_deferred() => {
                    return Err(format!(
                        "`{}` expects an array as its first argument, found `{ty}`",
                        self.name
                    ))
                }
                (Pos::VolumeOfT, ArgTy::Known(Ty::Object(ObjectKind::Volume(e)))) => match e.ty() {
                    Some(v) if t.is_none() => t = Some(v),
                    Some(_) => {}
                    None => {
                        return Err(format!(
                            "`{}` reads the values of a `Volume<T>`; a \
                                 `Volume<VoxelIndex>` holds indices: use `volume_sample_index`",
                            self.name
                        ))
                    }
                },
                (Pos::VolumeOfT | Pos::AnyVolume, ArgTy::Known(ty))
                    if !ty.is_deferred() && !matches!(ty, Ty::Object(ObjectKind::Volume(_))) =>
                {
                    return Err(format!(
                        "`{}` expects a `Volume<T>` as its first argument, found `{ty}`",
                        self.name
                    ))
                }
                _ => {}
            }
        }
        // Only literals in T positions: the literal rule's defaults (f32, else i32).
        if t.is_none() {
            let t_lits: Vec<bool> = self
                .params
                .iter()
                .zip(args)
                .filter_map(|(p, a)| match (p, a) {
                    (Pos::T, ArgTy::Literal { float }) => Some(*float),
                    _ => None,
                })
                .collect();
            let deferred = args
                .iter()
                .any(|a| matches!(a, ArgTy::Known(t) if t.is_deferred()));
            if !t_lits.is_empty() && !deferred {
                t = Some(if t_lits.contains(&true) {
                    crate::types::F32
                } else {
                    crate::types::I32
                });
            }
        }
        let mentions_t = self.params.iter().chain([&self.ret]).any(|p| !p.fixed());
        let t = match t {
            // Every position fixed: nothing to bind (the classes are empty).
            None if !mentions_t => Some(Ty::Deferred),
            t => t,
        };
        let Some(t) = t else {
            // Nothing known: leave typing to the target compiler.
            let params = self.params.iter().map(|_| Ty::Deferred).collect();
            let ret = match self.ret {
                Pos::Tuple(ps) => Ty::Tuple(vec![Ty::Deferred; ps.len()]),
                _ => Ty::Deferred,
            };
            return Ok(Resolved { params, ret });
        };
        if mentions_t && !self.classes.iter().any(|c| c.admits(&t)) {
            let want: Vec<_> = self.classes.iter().map(|c| c.describe()).collect();
            return Err(format!(
                "`{}` is not defined for `{t}`: it takes {}",
                self.name,
                want.join(", or ")
            ));
        }
        let scalar = t.scalar().map(Ty::Scalar).unwrap_or(Ty::Deferred);
        let index_ty = if array_ndim == 1 {
            crate::types::USIZE
        } else {
            Ty::TidTuple(array_ndim)
        };
        let want = |p: &Pos| match p {
            Pos::T => t.clone(),
            Pos::ScalarOfT => scalar.clone(),
            Pos::ArrayOfT => Ty::Array(Box::new(t.clone()), array_ndim),
            Pos::Index => index_ty.clone(),
            Pos::Bool => crate::types::BOOL,
            Pos::MatOfT => match &t {
                Ty::Vector(s, n) => Ty::Matrix(*s, *n),
                Ty::Quat(s) => Ty::Matrix(*s, 3),
                Ty::Transform(s) => Ty::Matrix(*s, 4),
                _ => Ty::Deferred,
            },
            Pos::VecOfT => match &t {
                Ty::Matrix(s, n) => Ty::Vector(*s, *n),
                Ty::Quat(s) => Ty::Vector(*s, 3),
                _ => Ty::Deferred,
            },
            Pos::QuatOfT => scalar.scalar().map(Ty::Quat).unwrap_or(Ty::Deferred),
            Pos::IntOfT => match &t {
                Ty::Scalar(_) => crate::types::I32,
                Ty::Vector(_, n) => Ty::Vector(Scalar::I32, *n),
                _ => Ty::Deferred,
            },
            Pos::Fixed(s) => Ty::Scalar(*s),
            Pos::FixedVec(s, n) => Ty::Vector(*s, *n),
            Pos::Vec3OfT => scalar
                .scalar()
                .map(|s| Ty::Vector(s, 3))
                .unwrap_or(Ty::Deferred),
            Pos::XformOfT => scalar.scalar().map(Ty::Transform).unwrap_or(Ty::Deferred),
            Pos::Mat4OfT => scalar
                .scalar()
                .map(|s| Ty::Matrix(s, 4))
                .unwrap_or(Ty::Deferred),
            Pos::Object(k) => Ty::Object(*k),
            Pos::VolumeOfT => crate::types::VolumeElem::of(&t)
                .map(|e| Ty::Object(ObjectKind::Volume(e)))
                .unwrap_or(Ty::Deferred),
            // Any element: the argument's own type (checked above).
            Pos::AnyVolume => Ty::Deferred,
            Pos::VolumeGradOfT => match &t {
                Ty::Scalar(s) => Ty::Vector(*s, 3),
                Ty::Vector(s, 3) => Ty::Matrix(*s, 3),
                _ => Ty::Deferred,
            },
            Pos::Unit => Ty::Unit,
            // Results only (below).
            Pos::Tuple(_) => Ty::Deferred,
        };
        let mut params = Vec::new();
        for (i, (pos, arg)) in self.params.iter().zip(args).enumerate() {
            let w = want(pos);
            match arg {
                ArgTy::Known(ty) if ty.is_deferred() => {}
                ArgTy::Known(ty) if *pos == Pos::Index => {
                    let ok = (array_ndim == 1 && ty.is_int_scalar())
                        || matches!(ty, Ty::TidTuple(n) if *n == array_ndim);
                    if !ok {
                        return Err(format!(
                            "argument {} of `{}` must be an index, found `{ty}`",
                            i + 1,
                            self.name
                        ));
                    }
                }
                ArgTy::Known(Ty::Array(e, _)) if *pos == Pos::ArrayOfT && **e != t => {
                    return Err(format!(
                        "`{}`: array of `{e}` where `{t}` was expected",
                        self.name
                    ));
                }
                ArgTy::Known(_) if *pos == Pos::ArrayOfT => {}
                ArgTy::Known(_) if *pos == Pos::AnyVolume => {}
                ArgTy::Known(ty) if *ty != w => {
                    return Err(format!(
                        "mismatched types in `{}`: argument {} is `{ty}`, expected `{w}`",
                        self.name,
                        i + 1
                    ))
                }
                ArgTy::Literal { float: true }
                    if !matches!(w, Ty::Scalar(s) if s.is_float()) && !w.is_deferred() =>
                {
                    return Err(format!(
                        "argument {} of `{}` is a float literal where `{w}` is expected",
                        i + 1,
                        self.name
                    ))
                }
                _ => {}
            }
            let ty = match (arg, pos) {
                (ArgTy::Known(ty), Pos::Index | Pos::AnyVolume) => ty.clone(),
                _ => w,
            };
            params.push(ty);
        }
        let ret = match self.ret {
            Pos::Tuple(ps) => Ty::Tuple(ps.iter().map(&want).collect()),
            p => want(&p),
        };
        Ok(Resolved { params, ret })
    }
}

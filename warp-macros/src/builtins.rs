//! The builtin table: one row per builtin, holding every fact about it.
//!
//! A row gives the builtin's name, which types its type variable `T` may take, its signature
//! in terms of `T`, the section of the CUDA builtin library it needs and how it is
//! differentiated, then each fact in which it differs from the defaults: method syntax
//! (`v.dot(w)`) and Rust's method aliases (`x.powf(y)`), glam's constructor spelling
//! (`Quat::from_axis_angle`), Warp's overload by arity it is (`min(v)`), Warp's keyword
//! default, how a random draw advances the generator state, the names of a tuple result,
//! whether user code may name it, whether it is an extension of Warp's set, and whether it
//! reaches the emitters as a call or as something else (`mod` is `%`). The CPU function is
//! `warp_core::builtins::<name>`, the CUDA one `wp::<name>`. Adding a builtin is one row
//! here plus the two implementations and their tests, and its line in docs/builtins.md, which
//! a test holds to this table (`doc` below).
//!
//! Signature matching binds `T` from the first argument whose type is known and fixed by `T`
//! (a `T` or `Array<T>` position); literal arguments are then typed from `T`, which is the
//! one literal rule both backends share (see `front::lower::typing`).

use crate::operators::BinOp;
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

/// How a `for` loop iterates a query row's result (`for j in hash_grid_query(grid, p, r)`,
/// lowered by `front::lower::query`): the rows of its steps, each a pure function, every one
/// internal.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Iterate {
    /// `(object, state) -> state`: the state at the next candidate, or at the end.
    pub next: &'static str,
    /// `(state) -> bool`: whether the state is at the end.
    pub done: &'static str,
    /// `(state) -> item`: the candidate the loop variable takes.
    pub item: &'static str,
}

/// How a builtin is differentiated (used by the adjoint transform).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Grad {
    /// Through `adj_<name>` in both libraries.
    Adjoint,
    /// Piecewise constant or not a float: zero gradient (floor, ceil, sign, round, step,
    /// isnan, ...).
    Zero,
    /// Atomics: special rules in the adjoint transform.
    Atomic,
    /// A write into an object (`volume_store`): not replayed by the adjoint, and backward
    /// through a kernel that makes one is refused (the stored value's gradient would be lost;
    /// see `analysis::atomic_without_adjoint`).
    Effect,
    /// Atomics without an adjoint (cas, exch, and, or, xor; Warp has none either): not
    /// replayed, and backward through a kernel is refused where one would lose a gradient or
    /// where the replay would need the old value it returned (see
    /// `analysis::atomic_without_adjoint`).
    AtomicNone,
}

/// How a draw `name(&mut state, ..)` advances the generator state (`front::lower::rng`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Draw {
    /// By this many generator steps (`rand_pcg`), one per uniform draw the builtin consumes.
    /// warp-core's `builtins::rand::DRAWS` states the same counts for its functions; a test
    /// in `front::lower::rng` holds the two together.
    Steps(u32),
    /// To the value of the named row at the state before the draw (`poisson_state`: Poisson
    /// sampling consumes a variable number of draws).
    NextState(&'static str),
}

/// How a call of a builtin reaches the emitters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Emit {
    /// An `Op::Builtin`: the emitters call the row's `rust` and `cuda` functions.
    Call,
    /// The binary operator (`mod` is `%`: the same faults, float semantics and adjoint); the
    /// row's `rust` and `cuda` names are never emitted.
    Operator(BinOp),
    /// Written out by the front end in other operations (`randi`: a `rand_pcg` step and
    /// integer operators, see `front::lower::rng`); no function of that name exists.
    Lowered,
}

/// One builtin: every fact about it is a field of its row in [`BUILTINS`].
#[derive(Debug)]
pub struct Builtin {
    pub name: &'static str,
    /// The classes `T` may belong to (any of them).
    pub classes: &'static [Class],
    pub params: &'static [Pos],
    pub ret: Pos,
    /// Method syntax allowed: `x.sqrt()`, `v.dot(w)`.
    pub method: bool,
    /// Rust method names that mean this builtin under another name (`x.powf(y)` is
    /// `pow(x, y)`), callable whatever `method` says. Each has Rust's meaning exactly:
    /// `round_ties_even` is `rint`, `fract` is `x - trunc(x)` like `frac`,
    /// `to_degrees`/`to_radians` multiply by the same constants as `degrees`/`radians`.
    /// (`signum` is not an alias of `sign`: Rust's gives NaN for NaN and -1 for -0.0, Warp's
    /// `sign` +1 for both.)
    pub aliases: &'static [&'static str],
    /// glam's constructor spelling: `(class, f)` makes `Ty::f(..)`, for a type `Ty` of
    /// `class`, this builtin (`Quat::from_axis_angle(axis, angle)`, `Transform::new(p, q)`).
    pub ctor: Option<(Class, &'static str)>,
    /// Warp's overload by arity that this row is: `(name, n)` means a call of `name` with
    /// `n` arguments is this row (`min(v)` of one vector is `min_element`). That is also the
    /// row's name in Warp ([`Builtin::warp_name`]).
    pub overload: Option<(&'static str, usize)>,
    /// A piece or an overload of another builtin (the RNG's `rand_pcg`, `lower_bound_range`):
    /// user code cannot name it.
    pub internal: bool,
    /// Warp's keyword default of the last argument, as a literal the call gets when it leaves
    /// that argument out (the norms' `delta = 1.0`).
    pub default_last: Option<&'static str>,
    /// A state-advancing draw (`randf(&mut state)`): how it advances the state.
    pub draw: Option<Draw>,
    /// The names of a tuple result's parts, in the order of Warp's output arguments, as a
    /// destructuring pattern (`"(u, sigma, v)"`); error messages show it.
    pub results: Option<&'static str>,
    /// Not a Warp builtin: an extension of warp-lang's (docs/builtins.md lists it there).
    pub extension: bool,
    /// A query that only a `for` loop iterates (`for j in hash_grid_query(..)`), by these
    /// steps; user code cannot bind its result otherwise.
    pub iterate: Option<Iterate>,
    pub emit: Emit,
    /// Function in `warp_core::builtins`.
    pub rust: &'static str,
    /// Function in the CUDA builtin library (namespace `wp`).
    #[allow(dead_code)] // read by the CUDA emitter
    pub cuda: &'static str,
    /// Section of the CUDA builtin library that defines it.
    #[allow(dead_code)] // read by the CUDA emitter
    pub section: &'static str,
    pub grad: Grad,
    /// Block-cooperative (a tile operation): every thread of the block must make the call
    /// together, so it must not be under control flow that depends on the thread (the
    /// validator's uniformity rule, `valid::uniformity`).
    pub cooperative: bool,
}

/// The row builder: [`Builtin::row`] gives a row every default (a user-callable builtin in
/// function syntax only, emitted as a call of the functions named after it), and each method
/// below states one fact that differs; [`table!`] writes them after the row's signature.
impl Builtin {
    const fn row(
        name: &'static str,
        cuda: &'static str,
        classes: &'static [Class],
        params: &'static [Pos],
        ret: Pos,
        section: &'static str,
        grad: Grad,
    ) -> Builtin {
        Builtin {
            name,
            classes,
            params,
            ret,
            method: false,
            aliases: &[],
            ctor: None,
            overload: None,
            internal: false,
            default_last: None,
            draw: None,
            results: None,
            extension: false,
            iterate: None,
            emit: Emit::Call,
            rust: name,
            cuda,
            section,
            grad,
            cooperative: false,
        }
    }

    /// The tile rows will set it; until then only the validator's tests do.
    #[cfg_attr(not(test), allow(dead_code))]
    pub(crate) const fn cooperative(self) -> Builtin {
        Builtin {
            cooperative: true,
            ..self
        }
    }

    const fn method(self) -> Builtin {
        Builtin {
            method: true,
            ..self
        }
    }

    const fn aliases(self, aliases: &'static [&'static str]) -> Builtin {
        Builtin { aliases, ..self }
    }

    const fn ctor(self, class: Class, f: &'static str) -> Builtin {
        Builtin {
            ctor: Some((class, f)),
            ..self
        }
    }

    const fn overload(self, name: &'static str, arity: usize) -> Builtin {
        Builtin {
            overload: Some((name, arity)),
            ..self
        }
    }

    const fn internal(self) -> Builtin {
        Builtin {
            internal: true,
            ..self
        }
    }

    const fn default_last(self, literal: &'static str) -> Builtin {
        Builtin {
            default_last: Some(literal),
            ..self
        }
    }

    const fn draws(self, steps: u32) -> Builtin {
        Builtin {
            draw: Some(Draw::Steps(steps)),
            ..self
        }
    }

    const fn next_state(self, row: &'static str) -> Builtin {
        Builtin {
            draw: Some(Draw::NextState(row)),
            ..self
        }
    }

    const fn results(self, pattern: &'static str) -> Builtin {
        Builtin {
            results: Some(pattern),
            ..self
        }
    }

    const fn extension(self) -> Builtin {
        Builtin {
            extension: true,
            ..self
        }
    }

    const fn iterate(self, next: &'static str, done: &'static str, item: &'static str) -> Builtin {
        Builtin {
            iterate: Some(Iterate { next, done, item }),
            ..self
        }
    }

    const fn operator(self, op: BinOp) -> Builtin {
        Builtin {
            emit: Emit::Operator(op),
            ..self
        }
    }

    const fn lowered(self) -> Builtin {
        Builtin {
            emit: Emit::Lowered,
            ..self
        }
    }
}

impl Builtin {
    /// An atomic read-modify-write of an array element (`atomic_add`, `atomic_cas`, ...): it
    /// has a side effect, is not replayed by adjoints, and its arguments are the array, the
    /// index (one variable per dimension) and [`Builtin::atomic_values`] values.
    pub fn is_atomic(&self) -> bool {
        matches!(self.grad, Grad::Atomic | Grad::AtomicNone)
    }

    /// How many value arguments follow an atomic's index: 2 for `atomic_cas` (compare,
    /// value), 1 for the others.
    pub fn atomic_values(&self) -> usize {
        let at = self
            .params
            .iter()
            .position(|p| *p == Pos::Index)
            .unwrap_or(self.params.len());
        self.params.len().saturating_sub(at + 1)
    }

    /// Whether the builtin takes an array among its values (not an atomic): its CPU function
    /// gets the view by reference and returns a `KResult` (its reads are checked), its CUDA
    /// function takes the fault context last (`lower_bound`). Read off the signature, so no
    /// row can say otherwise.
    pub fn reads_array(&self) -> bool {
        !self.is_atomic() && self.params.contains(&Pos::ArrayOfT)
    }

    /// Whether the builtin takes a host object (`hash_grid_query(grid, ..)`): like
    /// [`Builtin::reads_array`], its CPU function returns a `KResult` (the object's buffers are
    /// read through checked views) and its CUDA function takes the fault context last; the
    /// object is passed by value (a view). Read off the signature.
    pub fn reads_object(&self) -> bool {
        self.params.iter().any(|p| {
            matches!(p, Pos::Object(k) if k.row().param)
                || matches!(p, Pos::VolumeOfT | Pos::AnyVolume)
        })
    }

    /// Whether a call may fault ([`Builtin::reads_array`] or [`Builtin::reads_object`]): the
    /// CPU call is followed by `?`, the CUDA call takes `__ctx`.
    pub fn faults(&self) -> bool {
        self.reads_array() || self.reads_object()
    }

    /// The builtin's name in Warp: its own, or that of the builtin it is an overload of
    /// (`min_element` is Warp's `min` of one vector). None for an extension.
    #[allow(dead_code)] // read by the docs/builtins.md check
    pub fn warp_name(&self) -> Option<&'static str> {
        if self.extension {
            return None;
        }
        Some(self.overload.map_or(self.name, |(name, _)| name))
    }
}

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
const VEC_OR_QUAT: &[Class] = &[FloatVector, IntVector, Quaternion];
const FVEC_OR_QUAT: &[Class] = &[FloatVector, Quaternion];
const FVEC_OR_MAT: &[Class] = &[FloatVector, Matrix];
const MAT: &[Class] = &[Matrix];
const MAT_QUAT_XFORM: &[Class] = &[Matrix, Quaternion, Transform];
const LERP: &[Class] = &[Float, FloatVector, Transform];
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
const BOOL: Pos = Fixed(Scalar::Bool);
const GRID: Pos = Object(ObjectKind::HashGrid);
const GRID_QUERY: Pos = Object(ObjectKind::HashGridQuery);
const BVH: Pos = Object(ObjectKind::Bvh);
const BVH_AABB: Pos = Object(ObjectKind::BvhQueryAabb);
const BVH_RAY: Pos = Object(ObjectKind::BvhQueryRay);
const MESH: Pos = Object(ObjectKind::Mesh);
const MESH_AABB: Pos = Object(ObjectKind::MeshQueryAabb);
const VOL_VALUE: &[Class] = &[Class::VolumeValue];
const VOL_FLOAT: &[Class] = &[Class::VolumeFloat];
/// A point query's result: `(result, sign, face, u, v)` (Warp's `mesh_query_point_t`).
const POINT_RESULT: Pos = Tuple(&[BOOL, F32, I32, F32, F32]);
/// A ray query's result: `(result, sign, face, t, u, v, normal)` (Warp's `mesh_query_ray_t`).
const RAY_RESULT: Pos = Tuple(&[BOOL, F32, I32, F32, F32, F32, VEC3]);

/// The table's rows: `"name": classes, (params) -> result, "section", grad` and then the
/// facts in which the row differs from [`Builtin::row`]'s defaults, each the name of a
/// builder method with its arguments (`method`, `aliases(&["powf"])`, `draws(2)`, ...).
/// The CPU function is `warp_core::builtins::<name>`, the CUDA one `wp::<name>`.
macro_rules! table {
    ($( $name:literal : $classes:expr, ($($p:expr),*) -> $ret:expr, $sec:literal, $g:ident
        $(, $fact:ident $(( $($arg:expr),* ))? )* ; )*) => {
        /// Every builtin.
        pub static BUILTINS: &[Builtin] = &[$(
            Builtin::row($name, concat!("wp::", $name), $classes, &[$($p),*], $ret, $sec, Grad::$g)
                $( .$fact( $( $($arg),* )? ) )*,
        )*];
    };
}

table! {
    "min":        NUM_OR_VEC,     (T, T) -> T,              "scalar", Adjoint, method;
    "max":        NUM_OR_VEC,     (T, T) -> T,              "scalar", Adjoint, method;
    "abs":        SIGNED,         (T) -> T,                 "scalar", Adjoint, method;
    "sign":       SIGNED,         (T) -> T,                 "scalar", Zero;
    "clamp":      NUM_OR_VEC,     (T, T, T) -> T,           "scalar", Adjoint, method;
    "floor":      FLOAT,          (T) -> T,                 "scalar", Zero, method;
    "ceil":       FLOAT,          (T) -> T,                 "scalar", Zero, method;
    "sqrt":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "exp":        FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "pow":        FLOAT,          (T, T) -> T,              "scalar", Adjoint, aliases(&["powf"]);
    "log":        FLOAT,          (T) -> T,                 "scalar", Adjoint, aliases(&["ln"]);
    "sin":        FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "cos":        FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "tan":        FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "atan2":      FLOAT,          (T, T) -> T,              "scalar", Adjoint, method;
    "asin":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "acos":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "atan":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "sinh":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "cosh":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "tanh":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "exp2":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method, extension;
    "log2":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "log10":      FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "cbrt":       FLOAT,          (T) -> T,                 "scalar", Adjoint, method;
    "erf":        FLOAT,          (T) -> T,                 "scalar", Adjoint;
    "erfc":       FLOAT,          (T) -> T,                 "scalar", Adjoint;
    "erfinv":     FLOAT,          (T) -> T,                 "scalar", Adjoint;
    "erfcinv":    FLOAT,          (T) -> T,                 "scalar", Adjoint;
    "round":      FLOAT,          (T) -> T,                 "scalar", Zero, method;
    "rint":       FLOAT,          (T) -> T, "scalar", Zero, aliases(&["round_ties_even"]);
    "trunc":      FLOAT,          (T) -> T,                 "scalar", Zero, method;
    "frac":       FLOAT,          (T) -> T,                 "scalar", Adjoint, aliases(&["fract"]);
    "step":       NUMBER,         (T) -> T,                 "scalar", Zero;
    "smoothstep": FLOAT,          (T, T, T) -> T,           "scalar", Adjoint;
    "degrees":    FLOAT,          (T) -> T, "scalar", Adjoint, aliases(&["to_degrees"]);
    "radians":    FLOAT,          (T) -> T, "scalar", Adjoint, aliases(&["to_radians"]);
    "isfinite":   CLASSIFY,       (T) -> Bool,              "scalar", Zero, aliases(&["is_finite"]);
    "isnan":      CLASSIFY,       (T) -> Bool,              "scalar", Zero, aliases(&["is_nan"]);
    "isinf":      CLASSIFY,       (T) -> Bool, "scalar", Zero, aliases(&["is_infinite"]);
    // `mod(a, b)` (`r#mod` in Rust source, as `mod` is a keyword) is lowered to the `%`
    // operator: truncated remainder for integers (a fault on zero), C `fmod` for floats, and
    // `%`'s adjoint.
    "mod":        NUMBER,         (T, T) -> T,              "scalar", Adjoint, operator(BinOp::Rem);
    // lerp and inverse take transforms too (wp_transform.h: the emitter adds the section where
    // a value is a transform).
    "lerp":       LERP,           (T, T, ScalarOfT) -> T,   "scalar", Adjoint, method;
    // dot, length and normalize take quaternions too, whose versions are in "linalg" (which
    // includes "vector").
    "dot":        VEC_OR_QUAT,    (T, T) -> ScalarOfT,      "linalg", Adjoint, method;
    "cross":      &[Vector3],     (T, T) -> T,              "vector", Adjoint, method;
    "length":     FVEC_OR_QUAT,   (T) -> ScalarOfT,         "linalg", Adjoint, method;
    "normalize":  FVEC_OR_QUAT,   (T) -> T,                 "linalg", Adjoint, method;
    "length_sq":  VEC_OR_QUAT,    (T) -> ScalarOfT, "linalg", Adjoint, aliases(&["length_squared"]);
    "outer":      FVEC,           (T, T) -> MatOfT,         "linalg", Adjoint;
    "diag":       FVEC,           (T) -> MatOfT,            "linalg", Adjoint;
    "cw_mul":     FVEC_OR_MAT,    (T, T) -> T,              "linalg", Adjoint;
    "cw_div":     FVEC_OR_MAT,    (T, T) -> T,              "linalg", Adjoint;
    "transpose":  MAT,            (T) -> T,                 "linalg", Adjoint, method;
    "determinant": MAT, (T) -> ScalarOfT, "linalg", Adjoint, method;
    "inverse":    MAT_QUAT_XFORM, (T) -> T,                 "linalg", Adjoint, method;
    "trace":      MAT,            (T) -> ScalarOfT,         "linalg", Adjoint;
    "ddot":       MAT,            (T, T) -> ScalarOfT,      "linalg", Adjoint;
    "skew":       FVEC3,          (T) -> MatOfT,            "linalg", Adjoint;
    "quat_from_axis_angle": FVEC3, (T, ScalarOfT) -> QuatOfT, "linalg", Adjoint,
        ctor(Quaternion, "from_axis_angle");
    "quat_rotate": QUAT, (T, VecOfT) -> VecOfT, "linalg", Adjoint;
    "quat_rotate_inv": QUAT, (T, VecOfT) -> VecOfT, "linalg", Adjoint;
    "quat_inverse": QUAT, (T) -> T, "linalg", Adjoint, aliases(&["conjugate"]);
    "quat_to_matrix": QUAT, (T) -> MatOfT, "linalg", Adjoint, ctor(Matrix3, "from_quat");
    "quat_from_matrix": &[Matrix3], (T) -> QuatOfT, "linalg", Adjoint;
    "quat_slerp": QUAT,           (T, T, ScalarOfT) -> T,   "linalg", Adjoint;
    // Rigid transforms (wp_transform.h, warp-core builtins::transform).
    "transformation": FVEC3, (T, QuatOfT) -> XformOfT, "transform", Adjoint, ctor(Transform, "new");
    "transform_get_translation": XFORM, (T) -> Vec3OfT, "transform", Adjoint;
    "transform_get_rotation": XFORM, (T) -> QuatOfT, "transform", Adjoint;
    "transform_multiply": XFORM, (T, T) -> T, "transform", Adjoint;
    "transform_point": XFORM_OR_MAT4, (T, Vec3OfT) -> Vec3OfT, "transform", Adjoint,
        method, aliases(&["transform_point3"]);
    "transform_vector": XFORM_OR_MAT4, (T, Vec3OfT) -> Vec3OfT, "transform", Adjoint,
        method, aliases(&["transform_vector3"]);
    "transform_inverse": XFORM, (T) -> T, "transform", Adjoint;
    "transform_to_matrix": XFORM, (T) -> MatOfT, "transform", Adjoint;
    "transform_from_matrix": &[Matrix4], (T) -> XformOfT, "transform", Adjoint,
        ctor(Transform, "from_matrix");
    // Decompositions: tuples in the order of Warp's output arguments, only bound by a
    // destructuring `let` (see `front::lower::statements`).
    "svd3":       &[Matrix3],     (T) -> Tuple(&[T, VecOfT, T]), "svd", Adjoint,
        results("(u, sigma, v)");
    "svd2":       &[Matrix2],     (T) -> Tuple(&[T, VecOfT, T]), "svd", Adjoint,
        results("(u, sigma, v)");
    "qr3":        &[Matrix3],     (T) -> Tuple(&[T, T]),    "svd", Adjoint, results("(q, r)");
    "eig3":       &[Matrix3],     (T) -> Tuple(&[T, VecOfT]), "svd", Adjoint, results("(q, d)");
    "atomic_add": &[Atomic],      (ArrayOfT, Index, T) -> T, "atomic", Atomic;
    "atomic_sub": &[Atomic],      (ArrayOfT, Index, T) -> T, "atomic", Atomic;
    "atomic_min": &[Atomic],      (ArrayOfT, Index, T) -> T, "atomic", Atomic;
    "atomic_max": &[Atomic],      (ArrayOfT, Index, T) -> T, "atomic", Atomic;
    "atomic_cas": &[AtomicScalar], (ArrayOfT, Index, T, T) -> T, "atomic", AtomicNone;
    "atomic_exch": &[AtomicScalar], (ArrayOfT, Index, T) -> T, "atomic", AtomicNone;
    "atomic_and": &[AtomicInt],   (ArrayOfT, Index, T) -> T, "atomic", AtomicNone;
    "atomic_or":  &[AtomicInt],   (ArrayOfT, Index, T) -> T, "atomic", AtomicNone;
    "atomic_xor": &[AtomicInt],   (ArrayOfT, Index, T) -> T, "atomic", AtomicNone;
    // Random numbers and Perlin noise (warp-core `builtins::{rand, noise}`, wp_rand.h). A draw
    // `randf(&mut s, ..)` is not a call of one row: `front::lower::rng` lowers it into the
    // row's pure function of the state before the draw and the write-back of the advanced
    // state (`draws(k)`: `rand_pcg` once per uniform draw; `next_state`: `poisson_state` for
    // `poisson`); `randi`/`randu` are the advanced state itself, in integer operators. The
    // internal rows are those pieces (`randf_range` is `randf` with a range) and overloads by
    // arity; user code cannot name them.
    "rand_init":  NO_T,           (I32) -> U32,             "rand", Zero;
    "rand_init_offset": NO_T, (I32, I32) -> U32, "rand", Zero, overload("rand_init", 2), internal;
    "rand_pcg":   NO_T,           (U32) -> U32,             "rand", Zero, internal;
    "randi":      NO_T,           (U32) -> I32,             "rand", Zero, draws(1), lowered;
    "randu":      NO_T,           (U32) -> U32,             "rand", Zero, draws(1), lowered;
    "randf":      NO_T,           (U32) -> F32,             "rand", Zero, draws(1);
    "randf_range": NO_T, (U32, F32, F32) -> F32, "rand", Zero, internal;
    "randn":      NO_T,           (U32) -> F32,             "rand", Zero, draws(2);
    "sample_triangle": NO_T, (U32) -> VEC2, "rand", Zero, draws(2);
    "sample_unit_ring": NO_T, (U32) -> VEC2, "rand", Zero, draws(1);
    "sample_unit_disk": NO_T, (U32) -> VEC2, "rand", Zero, draws(2);
    "sample_unit_square": NO_T, (U32) -> VEC2, "rand", Zero, draws(2);
    "sample_unit_cube": NO_T, (U32) -> VEC3, "rand", Zero, draws(3);
    "sample_unit_sphere_surface": NO_T, (U32) -> VEC3, "rand", Zero, draws(2);
    "sample_unit_sphere": NO_T, (U32) -> VEC3, "rand", Zero, draws(3);
    "sample_unit_hemisphere_surface": NO_T, (U32) -> VEC3, "rand", Zero, draws(2);
    "sample_unit_hemisphere": NO_T, (U32) -> VEC3, "rand", Zero, draws(3);
    "poisson":    NO_T,           (U32, F32) -> U32, "rand", Zero, next_state("poisson_state");
    "poisson_state": NO_T, (U32, F32) -> U32, "rand", Zero, internal;
    "noise":      NOISE,          (U32, T) -> F32,          "rand", Adjoint;
    "pnoise":     NOISE,          (U32, T, IntOfT) -> F32,  "rand", Adjoint;
    // More vector, quaternion and transform builtins (warp-core `builtins::misc`, wp_misc.h).
    // `min(v)`/`max(v)` of one vector are `min_element`/`max_element` (glam's names), and
    // `lower_bound(a, lo, hi, v)` is `lower_bound_range` (overloads by arity); the norms'
    // `delta` defaults to 1 as in Warp.
    "copysign":   FLOAT,          (T, T) -> T,              "misc", Adjoint, method;
    "nonzero":    NUMBER,         (T) -> T,                 "misc", Zero;
    "block_dim":  NO_T,           () -> I32,                "misc", Zero;
    "min_element": VECS, (T) -> ScalarOfT, "misc", Adjoint, method, overload("min", 1);
    "max_element": VECS, (T) -> ScalarOfT, "misc", Adjoint, method, overload("max", 1);
    "argmin":     VECS,           (T) -> U32,               "misc", Zero;
    "argmax":     VECS,           (T) -> U32,               "misc", Zero;
    "get_diag":   MAT,            (T) -> VecOfT,            "misc", Adjoint;
    "norm_l1":    FVEC,           (T) -> ScalarOfT,         "misc", Adjoint;
    "norm_l2":    FVEC,           (T) -> ScalarOfT,         "misc", Adjoint;
    "norm_huber": FVEC,           (T, ScalarOfT) -> ScalarOfT, "misc", Adjoint, default_last("1.0");
    "norm_pseudo_huber": FVEC, (T, ScalarOfT) -> ScalarOfT, "misc", Adjoint, default_last("1.0");
    "smooth_normalize": FVEC, (T, ScalarOfT) -> T, "misc", Adjoint, default_last("1.0");
    "quat_to_axis_angle": QUAT, (T) -> Tuple(&[Vec3OfT, ScalarOfT]), "misc", Adjoint,
        results("(axis, angle)");
    "quat_rpy":   FLOAT,          (T, T, T) -> QuatOfT,     "misc", Adjoint;
    "quat_to_rpy": QUAT, (T) -> VecOfT, "misc", Adjoint;
    "quat_twist": FVEC3,          (T, QuatOfT) -> QuatOfT,  "misc", Adjoint;
    "quat_twist_angle": FVEC3, (T, QuatOfT) -> ScalarOfT, "misc", Adjoint;
    "quat_twist_angle_signed": FVEC3, (T, QuatOfT) -> ScalarOfT, "misc", Adjoint;
    "transform_compose": FVEC3, (T, QuatOfT, T) -> Mat4OfT, "misc", Adjoint;
    "transform_decompose": &[Matrix4], (T) -> Tuple(&[Vec3OfT, QuatOfT, Vec3OfT]), "misc", Adjoint,
        results("(p, q, s)");
    "lower_bound": NUMBER, (ArrayOfT, T) -> I32, "misc", Zero;
    "lower_bound_range": NUMBER, (ArrayOfT, I32, I32, T) -> I32, "misc", Zero,
        overload("lower_bound", 4), internal;
    // Warp's hash grid (warp-core `objects::hash_grid`, wp_hash_grid.h). A query is iterated
    // where it is made, `for j in hash_grid_query(grid, p, r) { .. }`, which
    // `front::lower::query` lowers to the query's state and its steps (Warp's
    // `hash_grid_query_next` is the loop): `next` is a pure function of the grid and the state,
    // written back to the state each iteration, so the adjoint replays the loop like any other
    // and the body's reads get their gradients. Indices are `usize` (Warp's `int`).
    "hash_grid_query": NO_T, (GRID, VEC3, F32) -> GRID_QUERY, "hash_grid", Zero,
        iterate("hash_grid_query_next", "hash_grid_query_done", "hash_grid_query_point");
    "hash_grid_query_next": NO_T, (GRID, GRID_QUERY) -> GRID_QUERY, "hash_grid", Zero, internal;
    "hash_grid_query_done": NO_T, (GRID_QUERY) -> BOOL, "hash_grid", Zero, internal;
    "hash_grid_query_point": NO_T, (GRID_QUERY) -> USIZE, "hash_grid", Zero, internal;
    "hash_grid_point_id": NO_T, (GRID, Index) -> USIZE, "hash_grid", Zero;
    // Warp's BVH and mesh (warp-core `objects::{bvh, mesh}` through `builtins::geometry`;
    // wp_bvh.h, wp_mesh.h). The iterating queries are `for` loops as the hash grid's; their
    // items, like every primitive and face index here, are `i32` (Warp's `int`). Results Warp
    // returns as a struct are tuples in its field order, bound by a destructuring `let`. The
    // point queries' adjoints give the query point's gradient through `u`, `v`; the
    // evaluations' give `u`'s and `v`'s; the objects get none.
    "bvh_query_aabb": NO_T, (BVH, VEC3, VEC3) -> BVH_AABB, "bvh", Zero,
        iterate("bvh_query_aabb_next", "bvh_query_aabb_done", "bvh_query_aabb_item");
    "bvh_query_aabb_next": NO_T, (BVH, BVH_AABB) -> BVH_AABB, "bvh", Zero, internal;
    "bvh_query_aabb_done": NO_T, (BVH_AABB) -> BOOL, "bvh", Zero, internal;
    "bvh_query_aabb_item": NO_T, (BVH_AABB) -> I32, "bvh", Zero, internal;
    "bvh_query_ray": NO_T, (BVH, VEC3, VEC3) -> BVH_RAY, "bvh", Zero,
        iterate("bvh_query_ray_next", "bvh_query_ray_done", "bvh_query_ray_item");
    "bvh_query_ray_next": NO_T, (BVH, BVH_RAY) -> BVH_RAY, "bvh", Zero, internal;
    "bvh_query_ray_done": NO_T, (BVH_RAY) -> BOOL, "bvh", Zero, internal;
    "bvh_query_ray_item": NO_T, (BVH_RAY) -> I32, "bvh", Zero, internal;
    "mesh_query_aabb": NO_T, (MESH, VEC3, VEC3) -> MESH_AABB, "mesh", Zero,
        iterate("mesh_query_aabb_next", "mesh_query_aabb_done", "mesh_query_aabb_item");
    "mesh_query_aabb_next": NO_T, (MESH, MESH_AABB) -> MESH_AABB, "mesh", Zero, internal;
    "mesh_query_aabb_done": NO_T, (MESH_AABB) -> BOOL, "mesh", Zero, internal;
    "mesh_query_aabb_item": NO_T, (MESH_AABB) -> I32, "mesh", Zero, internal;
    "mesh_query_point": NO_T, (MESH, VEC3, F32) -> POINT_RESULT, "mesh", Adjoint,
        results("(result, sign, face, u, v)");
    "mesh_query_point_no_sign": NO_T, (MESH, VEC3, F32) -> POINT_RESULT, "mesh", Adjoint,
        results("(result, sign, face, u, v)");
    "mesh_query_furthest_point_no_sign": NO_T, (MESH, VEC3, F32) -> POINT_RESULT, "mesh", Zero,
        results("(result, sign, face, u, v)");
    "mesh_query_ray": NO_T, (MESH, VEC3, VEC3, F32) -> RAY_RESULT, "mesh", Zero,
        results("(result, sign, face, t, u, v, normal)");
    "mesh_eval_position": NO_T, (MESH, Index, F32, F32) -> VEC3, "mesh", Adjoint;
    "mesh_eval_velocity": NO_T, (MESH, Index, F32, F32) -> VEC3, "mesh", Adjoint;
    "mesh_eval_face_normal": NO_T, (MESH, Index) -> VEC3, "mesh", Zero;
    // Triangle geometry (warp-core `objects::geometry`, wp_geometry.h): no object needed.
    "closest_point_triangle": NO_T, (VEC3, VEC3, VEC3, VEC3) -> VEC3, "geometry", Adjoint,
        extension;
    "intersect_tri_tri": NO_T, (VEC3, VEC3, VEC3, VEC3, VEC3, VEC3) -> BOOL, "geometry", Zero;
    // Warp's sparse volumes (warp-core `objects::volume` through `builtins::volume`;
    // wp_volume.h). The volume is a typed parameter, `Volume<T>`, so the value type is checked
    // at compile time where Warp checks it at run time (its `volume_sample_f/v/i` and `dtype=`
    // are one row here, typed by the volume). Modes: `VOLUME_CLOSEST` (0), `VOLUME_LINEAR`.
    // Positions are in index space (the transforms map world points there); a NaN or infinite
    // coordinate faults. Gradients flow to the sample position (LINEAR) and, for a volume
    // made with a gradient grid, into the stored values read.
    "volume_sample": VOL_FLOAT, (VolumeOfT, VEC3, I32) -> T, "volume", Adjoint;
    "volume_sample_grad": VOL_FLOAT, (VolumeOfT, VEC3, I32) -> Tuple(&[T, VolumeGradOfT]),
        "volume", Adjoint, results("(value, grad)");
    "volume_lookup": VOL_VALUE, (VolumeOfT, I32, I32, I32) -> T, "volume", Adjoint;
    "volume_store": VOL_VALUE, (VolumeOfT, I32, I32, I32, T) -> Unit, "volume", Effect;
    "volume_index_to_world": NO_T, (AnyVolume, VEC3) -> VEC3, "volume", Adjoint;
    "volume_world_to_index": NO_T, (AnyVolume, VEC3) -> VEC3, "volume", Adjoint;
    "volume_index_to_world_dir": NO_T, (AnyVolume, VEC3) -> VEC3, "volume", Adjoint;
    "volume_world_to_index_dir": NO_T, (AnyVolume, VEC3) -> VEC3, "volume", Adjoint;
    "volume_sample_index": VOL_FLOAT, (AnyVolume, VEC3, I32, ArrayOfT, T) -> T, "volume",
        Adjoint;
    "volume_sample_grad_index": VOL_FLOAT, (AnyVolume, VEC3, I32, ArrayOfT, T)
        -> Tuple(&[T, VolumeGradOfT]), "volume", Adjoint, results("(value, grad)");
    "volume_lookup_index": NO_T, (AnyVolume, I32, I32, I32) -> I32, "volume", Zero;
}

/// Looks a builtin up by name (internal rows included).
pub fn lookup(name: &str) -> Option<&'static Builtin> {
    BUILTINS.iter().find(|b| b.name == name)
}

/// Looks up a builtin that user code may call by name (not an internal row).
pub fn lookup_user(name: &str) -> Option<&'static Builtin> {
    lookup(name).filter(|b| !b.internal)
}

/// Looks a builtin up by method name (aliases included).
pub fn lookup_method(name: &str) -> Option<&'static Builtin> {
    match BUILTINS.iter().find(|b| b.aliases.contains(&name)) {
        Some(b) => Some(b),
        None => lookup(name).filter(|b| b.method),
    }
}

/// The row a call of Warp's `name` with `arity` arguments is, where that overload is a row of
/// its own (`min(v)` is `min_element`, `lower_bound(a, lo, hi, v)` is `lower_bound_range`).
pub fn lookup_overload(name: &str, arity: usize) -> Option<&'static Builtin> {
    BUILTINS.iter().find(|b| b.overload == Some((name, arity)))
}

/// The builtin that glam's constructor `ty::f(..)` is (`Quat::from_axis_angle`).
pub fn lookup_ctor(ty: &Ty, f: &str) -> Option<&'static Builtin> {
    BUILTINS
        .iter()
        .find(|b| matches!(b.ctor, Some((class, g)) if g == f && class.admits(ty)))
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::{F32, I32};

    fn k(t: Ty) -> ArgTy {
        ArgTy::Known(t)
    }

    #[test]
    fn every_entry_is_unique_and_well_formed() {
        for (i, b) in BUILTINS.iter().enumerate() {
            assert!(
                BUILTINS[..i].iter().all(|o| o.name != b.name),
                "duplicate {}",
                b.name
            );
            let binds_t = b.params.contains(&Pos::T)
                || b.params.contains(&Pos::ArrayOfT)
                || b.params.contains(&Pos::VolumeOfT);
            let all_fixed = b.params.iter().chain([&b.ret]).all(Pos::fixed);
            assert!(binds_t || all_fixed, "{} cannot bind T", b.name);
            assert_eq!(b.classes.is_empty(), all_fixed, "{}: classes", b.name);
            // The facts beyond the signature agree with it and with the other rows.
            for a in b.aliases {
                assert!(
                    lookup(a).is_none(),
                    "{}: alias {a} is a builtin's name",
                    b.name
                );
                assert_eq!(lookup_method(a).map(|m| m.name), Some(b.name), "{a}");
            }
            if let Some((name, arity)) = b.overload {
                assert_eq!(b.params.len(), arity, "{}: overload's arity", b.name);
                let base = lookup_user(name).expect("an overload of a builtin");
                assert_ne!(base.params.len(), arity, "{}", b.name);
                assert_eq!(lookup_overload(name, arity).map(|o| o.name), Some(b.name));
            }
            if let Some(lit) = b.default_last {
                assert!(syn::parse_str::<syn::Lit>(lit).is_ok(), "{}: {lit}", b.name);
            }
            if let Some(draw) = b.draw {
                assert_eq!(
                    b.params.first(),
                    Some(&Pos::Fixed(Scalar::U32)),
                    "{}",
                    b.name
                );
                if let Draw::NextState(row) = draw {
                    let next = lookup(row).expect("the next-state row");
                    assert!(next.internal && next.params == b.params, "{}", b.name);
                }
            }
            match (b.ret, b.results) {
                (Pos::Tuple(parts), Some(names)) => {
                    assert_eq!(names.split(',').count(), parts.len(), "{}", b.name)
                }
                (Pos::Tuple(_), None) => panic!("{}: a tuple result needs its names", b.name),
                (_, results) => assert!(results.is_none(), "{}", b.name),
            }
            if let Emit::Operator(_) = b.emit {
                assert_eq!(b.params.len(), 2, "{}: a binary operator", b.name);
            }
            assert!(
                !(b.internal && (b.method || !b.aliases.is_empty() || b.ctor.is_some())),
                "{}: internal rows have no other spelling",
                b.name
            );
            if let Some(it) = b.iterate {
                // The steps: internal rows of the query's state, `next` taking the object the
                // query takes first.
                let Pos::Object(state) = b.ret else {
                    panic!("{}: a query returns its state", b.name)
                };
                let st = Pos::Object(state);
                let (next, done, item) = (
                    lookup(it.next).expect("next"),
                    lookup(it.done).expect("done"),
                    lookup(it.item).expect("item"),
                );
                assert!(
                    next.internal && done.internal && item.internal,
                    "{}",
                    b.name
                );
                assert_eq!(next.params, &[b.params[0], st], "{}", b.name);
                assert_eq!(next.ret, st, "{}", b.name);
                assert_eq!((done.params, done.ret), (&[st][..], BOOL), "{}", b.name);
                assert_eq!(item.params, &[st], "{}", b.name);
                assert!(b.reads_object() && next.reads_object(), "{}", b.name);
            }
            // A query state is made by its query and consumed by its steps only.
            if [GRID_QUERY, BVH_AABB, BVH_RAY, MESH_AABB].contains(&b.ret) {
                assert!(b.iterate.is_some() || b.internal, "{}", b.name);
            }
        }
        for name in [
            "min",
            "max",
            "abs",
            "sign",
            "clamp",
            "floor",
            "ceil",
            "sqrt",
            "exp",
            "log",
            "sin",
            "cos",
            "tan",
            "atan2",
            "pow",
            "dot",
            "cross",
            "length",
            "normalize",
            "lerp",
            "atomic_add",
            "atomic_sub",
            "atomic_min",
            "atomic_max",
            "asin",
            "acos",
            "atan",
            "sinh",
            "cosh",
            "tanh",
            "exp2",
            "log2",
            "log10",
            "cbrt",
            "erf",
            "erfc",
            "erfinv",
            "erfcinv",
            "round",
            "rint",
            "trunc",
            "frac",
            "step",
            "smoothstep",
            "degrees",
            "radians",
            "isfinite",
            "isnan",
            "isinf",
            "mod",
        ] {
            assert!(lookup(name).is_some(), "{name} missing");
        }
    }

    #[test]
    fn literals_take_the_bound_type() {
        let max = lookup("max").unwrap();
        let r = max
            .resolve(&[k(Ty::Scalar(Scalar::F64)), ArgTy::Literal { float: true }])
            .unwrap();
        assert_eq!(r.params, vec![Ty::Scalar(Scalar::F64); 2]);
        assert_eq!(r.ret, Ty::Scalar(Scalar::F64));
        // An integer literal next to a float is typed as the float.
        let r = max
            .resolve(&[ArgTy::Literal { float: false }, k(F32)])
            .unwrap();
        assert_eq!(r.params, vec![F32, F32]);
    }

    #[test]
    fn vector_builtins() {
        let v3 = Ty::Vector(Scalar::F32, 3);
        let dot = lookup_method("dot").unwrap();
        assert_eq!(
            dot.resolve(&[k(v3.clone()), k(v3.clone())]).unwrap().ret,
            F32
        );
        let lerp = lookup("lerp").unwrap();
        let r = lerp
            .resolve(&[k(v3.clone()), k(v3.clone()), ArgTy::Literal { float: true }])
            .unwrap();
        assert_eq!(r.params[2], F32);
        assert!(lookup("length")
            .unwrap()
            .resolve(&[k(Ty::Vector(Scalar::I32, 3))])
            .is_err());
        assert!(lookup("cross")
            .unwrap()
            .resolve(&[k(Ty::Vector(Scalar::F32, 2)), k(Ty::Vector(Scalar::F32, 2))])
            .is_err());
    }

    #[test]
    fn mismatches_are_reported() {
        let min = lookup("min").unwrap();
        let e = min
            .resolve(&[k(F32), k(Ty::Scalar(Scalar::F64))])
            .unwrap_err();
        assert!(e.contains("mismatched"), "{e}");
        assert!(lookup("sqrt")
            .unwrap()
            .resolve(&[k(I32)])
            .unwrap_err()
            .contains("not defined for `i32`"));
        assert!(lookup("sqrt")
            .unwrap()
            .resolve(&[k(F32), k(F32)])
            .unwrap_err()
            .contains("takes 1 argument"));
        // Literal-only calls follow the literal rule's defaults.
        assert_eq!(
            lookup("sqrt")
                .unwrap()
                .resolve(&[ArgTy::Literal { float: true }])
                .unwrap()
                .ret,
            F32
        );
        assert!(lookup("sqrt")
            .unwrap()
            .resolve(&[ArgTy::Literal { float: false }])
            .unwrap_err()
            .contains("i32"));
        assert_eq!(
            lookup("max")
                .unwrap()
                .resolve(&[
                    ArgTy::Literal { float: false },
                    ArgTy::Literal { float: false }
                ])
                .unwrap()
                .ret,
            I32
        );
        assert!(lookup("sqrt")
            .unwrap()
            .resolve(&[k(Ty::Deferred)])
            .unwrap()
            .ret
            .is_deferred());
    }

    #[test]
    fn atomics_bind_from_the_array() {
        let add = lookup("atomic_add").unwrap();
        let arr = Ty::Array(Box::new(F32), 1);
        let r = add
            .resolve(&[k(arr.clone()), k(I32), ArgTy::Literal { float: false }])
            .unwrap();
        assert_eq!(r.params, vec![arr, I32, F32]);
        assert_eq!(r.ret, F32);
        let arr2 = Ty::Array(Box::new(F32), 2);
        assert!(
            add.resolve(&[k(arr2), k(I32), k(F32)]).is_err(),
            "1-D index into 2-D array"
        );
        let bad = Ty::Array(Box::new(Ty::Scalar(Scalar::I8)), 1);
        assert!(add
            .resolve(&[k(bad), k(I32), k(Ty::Scalar(Scalar::I8))])
            .is_err());
    }

    #[test]
    fn decompositions_return_tuples() {
        let m3 = Ty::Matrix(Scalar::F32, 3);
        let v3 = Ty::Vector(Scalar::F32, 3);
        let r = lookup("svd3").unwrap().resolve(&[k(m3.clone())]).unwrap();
        assert_eq!(r.ret, Ty::Tuple(vec![m3.clone(), v3.clone(), m3.clone()]));
        let r = lookup("eig3").unwrap().resolve(&[k(m3.clone())]).unwrap();
        assert_eq!(r.ret, Ty::Tuple(vec![m3.clone(), v3]));
        let r = lookup("qr3").unwrap().resolve(&[k(m3.clone())]).unwrap();
        assert_eq!(r.ret, Ty::Tuple(vec![m3.clone(), m3.clone()]));
        let m2 = Ty::Matrix(Scalar::F64, 2);
        let r = lookup("svd2").unwrap().resolve(&[k(m2.clone())]).unwrap();
        assert_eq!(
            r.ret,
            Ty::Tuple(vec![m2.clone(), Ty::Vector(Scalar::F64, 2), m2.clone()])
        );
        assert!(lookup("svd3").unwrap().resolve(&[k(m2.clone())]).is_err());
        assert!(lookup("svd2").unwrap().resolve(&[k(m3)]).is_err());
        // Deferred argument: the tuple's arity is still known.
        let r = lookup("svd3").unwrap().resolve(&[k(Ty::Deferred)]).unwrap();
        assert_eq!(r.ret, Ty::Tuple(vec![Ty::Deferred; 3]));
        assert!(lookup_method("svd3").is_none(), "function syntax only");
    }

    #[test]
    fn glam_constructors_and_overloads() {
        let ctor = |ty: Ty, f: &str| lookup_ctor(&ty, f).map(|b| b.name);
        assert_eq!(
            ctor(Ty::Quat(Scalar::F64), "from_axis_angle"),
            Some("quat_from_axis_angle")
        );
        assert_eq!(
            ctor(Ty::Matrix(Scalar::F32, 3), "from_quat"),
            Some("quat_to_matrix")
        );
        assert_eq!(ctor(Ty::Matrix(Scalar::F32, 4), "from_quat"), None);
        assert_eq!(
            ctor(Ty::Transform(Scalar::F32), "new"),
            Some("transformation")
        );
        assert_eq!(ctor(Ty::Vector(Scalar::F32, 3), "new"), None);
        assert_eq!(
            lookup_overload("min", 1).map(|b| b.name),
            Some("min_element")
        );
        assert!(lookup_overload("min", 2).is_none());
        assert_eq!(lookup("min_element").unwrap().warp_name(), Some("min"));
        assert_eq!(lookup("exp2").unwrap().warp_name(), None);
        assert_eq!(lookup("sqrt").unwrap().warp_name(), Some("sqrt"));
    }

    #[test]
    fn method_aliases() {
        assert_eq!(lookup_method("powf").unwrap().name, "pow");
        assert_eq!(lookup_method("ln").unwrap().name, "log");
        assert!(
            lookup_method("log").is_none(),
            "x.log(base) means something else in Rust"
        );
        assert!(lookup_method("pow").is_none());
        for (alias, name) in [
            ("round_ties_even", "rint"),
            ("fract", "frac"),
            ("to_degrees", "degrees"),
            ("to_radians", "radians"),
            ("is_finite", "isfinite"),
            ("is_nan", "isnan"),
            ("is_infinite", "isinf"),
        ] {
            assert_eq!(lookup_method(alias).unwrap().name, name);
        }
        for m in ["asin", "tanh", "cbrt", "exp2", "log10", "round", "trunc"] {
            assert_eq!(lookup_method(m).unwrap().name, m);
        }
        // Warp's names without a Rust method of that meaning are function syntax only.
        for m in ["frac", "rint", "erf", "isnan", "degrees", "signum", "mod"] {
            assert!(lookup_method(m).is_none(), "{m}");
        }
    }

    #[test]
    fn rand_rows_have_fixed_types() {
        let u32t = Ty::Scalar(Scalar::U32);
        // Fixed signatures: literals take the parameter's type, other types are mismatches.
        let init = lookup("rand_init").unwrap();
        let r = init.resolve(&[ArgTy::Literal { float: false }]).unwrap();
        assert_eq!((r.params, r.ret.clone()), (vec![I32], u32t.clone()));
        assert!(init
            .resolve(&[k(Ty::Scalar(Scalar::Usize))])
            .unwrap_err()
            .contains("expected `i32`"));
        let range = lookup("randf_range").unwrap();
        let r = range
            .resolve(&[
                k(u32t.clone()),
                ArgTy::Literal { float: false },
                ArgTy::Literal { float: true },
            ])
            .unwrap();
        assert_eq!(r.params, vec![u32t.clone(), F32, F32]);
        assert_eq!(
            lookup("sample_unit_disk")
                .unwrap()
                .resolve(&[k(u32t.clone())])
                .unwrap()
                .ret,
            Ty::Vector(Scalar::F32, 2)
        );
        // Noise: T is the position (f32 only), the periods follow its size.
        let pn = lookup("pnoise").unwrap();
        let v3 = Ty::Vector(Scalar::F32, 3);
        let r = pn
            .resolve(&[
                k(u32t.clone()),
                k(v3.clone()),
                k(Ty::Vector(Scalar::I32, 3)),
            ])
            .unwrap();
        assert_eq!(r.ret, F32);
        assert!(pn
            .resolve(&[k(u32t.clone()), k(v3), k(Ty::Vector(Scalar::I32, 2))])
            .is_err());
        assert!(lookup("noise")
            .unwrap()
            .resolve(&[k(u32t.clone()), k(Ty::Scalar(Scalar::F64))])
            .unwrap_err()
            .contains("f32, Vec2, Vec3 or Vec4"));
        // Internal rows exist and are hidden from user code.
        for b in BUILTINS.iter().filter(|b| b.internal) {
            assert!(lookup_user(b.name).is_none(), "{}", b.name);
        }
        assert!(lookup_user("rand_pcg").is_none());
        assert!(lookup_user("randn").is_some());
    }

    #[test]
    fn transform_builtins() {
        let (x, d) = (Ty::Transform(Scalar::F32), Ty::Transform(Scalar::F64));
        let v3 = Ty::Vector(Scalar::F32, 3);
        let q = Ty::Quat(Scalar::F32);
        let r = lookup("transformation")
            .unwrap()
            .resolve(&[k(v3.clone()), k(q.clone())])
            .unwrap();
        assert_eq!(r.ret, x);
        assert!(lookup("transformation")
            .unwrap()
            .resolve(&[k(v3.clone()), k(Ty::Quat(Scalar::F64))])
            .is_err());
        let tp = lookup_method("transform_point").unwrap();
        assert_eq!(tp.resolve(&[k(x.clone()), k(v3.clone())]).unwrap().ret, v3);
        let m4 = Ty::Matrix(Scalar::F64, 4);
        assert_eq!(
            lookup_method("transform_point3")
                .unwrap()
                .resolve(&[k(m4.clone()), k(Ty::Vector(Scalar::F64, 3))])
                .unwrap()
                .ret,
            Ty::Vector(Scalar::F64, 3)
        );
        assert!(tp
            .resolve(&[k(Ty::Matrix(Scalar::F32, 3)), k(v3.clone())])
            .is_err());
        assert_eq!(
            lookup("transform_to_matrix")
                .unwrap()
                .resolve(&[k(d.clone())])
                .unwrap()
                .ret,
            m4
        );
        assert_eq!(
            lookup("transform_from_matrix")
                .unwrap()
                .resolve(&[k(m4)])
                .unwrap()
                .ret,
            d
        );
        assert_eq!(
            lookup_method("inverse")
                .unwrap()
                .resolve(&[k(x.clone())])
                .unwrap()
                .ret,
            x
        );
        let lerp = lookup_method("lerp").unwrap();
        let r = lerp
            .resolve(&[k(d.clone()), k(d.clone()), ArgTy::Literal { float: true }])
            .unwrap();
        assert_eq!(r.params[2], Ty::Scalar(Scalar::F64));
        assert_eq!(
            lookup("transform_get_rotation")
                .unwrap()
                .resolve(&[k(d)])
                .unwrap()
                .ret,
            Ty::Quat(Scalar::F64)
        );
    }

    #[test]
    fn misc_rows() {
        let (v3, d3) = (Ty::Vector(Scalar::F32, 3), Ty::Vector(Scalar::F64, 3));
        let (q, dq) = (Ty::Quat(Scalar::F32), Ty::Quat(Scalar::F64));
        let r = lookup("transform_compose")
            .unwrap()
            .resolve(&[k(d3.clone()), k(dq.clone()), k(d3.clone())])
            .unwrap();
        assert_eq!(r.ret, Ty::Matrix(Scalar::F64, 4));
        let r = lookup("transform_decompose")
            .unwrap()
            .resolve(&[k(Ty::Matrix(Scalar::F32, 4))])
            .unwrap();
        assert_eq!(r.ret, Ty::Tuple(vec![v3.clone(), q.clone(), v3.clone()]));
        let r = lookup("quat_to_axis_angle")
            .unwrap()
            .resolve(&[k(dq)])
            .unwrap();
        assert_eq!(r.ret, Ty::Tuple(vec![d3, Ty::Scalar(Scalar::F64)]));
        let r = lookup("quat_rpy")
            .unwrap()
            .resolve(&[
                ArgTy::Literal { float: true },
                ArgTy::Literal { float: true },
                ArgTy::Literal { float: true },
            ])
            .unwrap();
        assert_eq!(r.ret, q);
        let iv = Ty::Vector(Scalar::I32, 4);
        assert_eq!(
            lookup_method("min_element")
                .unwrap()
                .resolve(&[k(iv.clone())])
                .unwrap()
                .ret,
            I32
        );
        assert_eq!(
            lookup("argmax").unwrap().resolve(&[k(iv)]).unwrap().ret,
            Ty::Scalar(Scalar::U32)
        );
        assert!(lookup("get_diag")
            .unwrap()
            .resolve(&[k(v3.clone())])
            .is_err());
        let arr = Ty::Array(Box::new(Ty::Scalar(Scalar::I64)), 1);
        let r = lookup("lower_bound")
            .unwrap()
            .resolve(&[k(arr), ArgTy::Literal { float: false }])
            .unwrap();
        assert_eq!(r.params[1], Ty::Scalar(Scalar::I64));
        assert!(lookup("lower_bound_range").unwrap().reads_array());
        assert!(!lookup("atomic_add").unwrap().reads_array());
        assert!(lookup_user("lower_bound_range").is_none());
        for name in ["isfinite", "isnan", "isinf"] {
            let b = lookup(name).unwrap();
            assert!(b.resolve(&[k(Ty::Matrix(Scalar::F64, 2))]).is_ok());
            assert!(b.resolve(&[k(Ty::Quat(Scalar::F32))]).is_ok());
        }
        for b in BUILTINS.iter().filter(|b| b.default_last.is_some()) {
            assert_eq!(b.params.len(), 2, "{}", b.name);
        }
    }

    #[test]
    fn volume_rows_take_their_type_from_the_volume() {
        use crate::types::VolumeElem;
        let vol = |e| k(Ty::Object(ObjectKind::Volume(e)));
        let v3 = Ty::Vector(Scalar::F32, 3);
        let sample = lookup_user("volume_sample").unwrap();
        let r = sample
            .resolve(&[vol(VolumeElem::Vec3), k(v3.clone()), k(I32)])
            .unwrap();
        assert_eq!(r.ret, v3);
        assert!(sample.faults());
        let r = sample
            .resolve(&[vol(VolumeElem::F64), k(v3.clone()), k(I32)])
            .unwrap();
        assert_eq!(r.ret, Ty::Scalar(Scalar::F64));
        // Integer grids are looked up, not interpolated; index grids hold no values.
        let e = sample
            .resolve(&[vol(VolumeElem::I32), k(v3.clone()), k(I32)])
            .unwrap_err();
        assert!(e.contains("is not defined for `i32`"), "{e}");
        let e = sample
            .resolve(&[vol(VolumeElem::Index), k(v3.clone()), k(I32)])
            .unwrap_err();
        assert!(e.contains("volume_sample_index"), "{e}");
        let e = sample
            .resolve(&[k(F32), k(v3.clone()), k(I32)])
            .unwrap_err();
        assert!(e.contains("expects a `Volume<T>`"), "{e}");
        let grad = lookup_user("volume_sample_grad").unwrap();
        let r = grad
            .resolve(&[vol(VolumeElem::Vec3), k(v3.clone()), k(I32)])
            .unwrap();
        assert_eq!(
            r.ret,
            Ty::Tuple(vec![v3.clone(), Ty::Matrix(Scalar::F32, 3)])
        );
        let r = grad
            .resolve(&[vol(VolumeElem::F32), k(v3.clone()), k(I32)])
            .unwrap();
        assert_eq!(r.ret, Ty::Tuple(vec![F32, v3.clone()]));
        let store = lookup_user("volume_store").unwrap();
        let r = store
            .resolve(&[vol(VolumeElem::I32), k(I32), k(I32), k(I32), k(I32)])
            .unwrap();
        assert_eq!(r.ret, Ty::Unit);
        let e = store
            .resolve(&[vol(VolumeElem::F32), k(I32), k(I32), k(I32), k(v3.clone())])
            .unwrap_err();
        assert!(e.contains("mismatched types"), "{e}");
        // The index reads take any volume and type `T` from the data array.
        let index = lookup_user("volume_sample_index").unwrap();
        let arr = k(Ty::Array(Box::new(v3.clone()), 1));
        let r = index
            .resolve(&[
                vol(VolumeElem::Index),
                k(v3.clone()),
                k(I32),
                arr,
                k(v3.clone()),
            ])
            .unwrap();
        assert_eq!(r.ret, v3);
        assert!(index.reads_array() && index.faults());
        let w = lookup_user("volume_world_to_index").unwrap();
        assert!(w.resolve(&[vol(VolumeElem::Index), k(v3.clone())]).is_ok());
    }

    #[test]
    fn bvh_and_mesh_rows() {
        let mesh = Ty::Object(ObjectKind::Mesh);
        let bvh = Ty::Object(ObjectKind::Bvh);
        let v3 = Ty::Vector(Scalar::F32, 3);
        let b = Ty::Scalar(Scalar::Bool);
        // The point queries' tuples, whatever the literal.
        for name in [
            "mesh_query_point",
            "mesh_query_point_no_sign",
            "mesh_query_furthest_point_no_sign",
        ] {
            let q = lookup_user(name).unwrap();
            let r = q
                .resolve(&[
                    k(mesh.clone()),
                    k(v3.clone()),
                    ArgTy::Literal { float: true },
                ])
                .unwrap();
            assert_eq!(r.params, vec![mesh.clone(), v3.clone(), F32], "{name}");
            assert_eq!(
                r.ret,
                Ty::Tuple(vec![b.clone(), F32, I32, F32, F32]),
                "{name}"
            );
            assert!(q.faults(), "{name}");
            // A BVH is not a mesh.
            let e = q
                .resolve(&[k(bvh.clone()), k(v3.clone()), k(F32)])
                .unwrap_err();
            assert!(e.contains("expected `Mesh`"), "{e}");
        }
        let r = lookup_user("mesh_query_ray")
            .unwrap()
            .resolve(&[k(mesh.clone()), k(v3.clone()), k(v3.clone()), k(F32)])
            .unwrap();
        assert_eq!(
            r.ret,
            Ty::Tuple(vec![b.clone(), F32, I32, F32, F32, F32, v3.clone()])
        );
        // Faces of any integer type.
        let ev = lookup_user("mesh_eval_position").unwrap();
        for t in [I32, Ty::Scalar(Scalar::Usize)] {
            let r = ev
                .resolve(&[k(mesh.clone()), k(t.clone()), k(F32), k(F32)])
                .unwrap();
            assert_eq!((r.params[1].clone(), r.ret), (t, v3.clone()));
        }
        // The loops' items are i32.
        for (q, item) in [
            ("bvh_query_aabb", "bvh_query_aabb_item"),
            ("bvh_query_ray", "bvh_query_ray_item"),
            ("mesh_query_aabb", "mesh_query_aabb_item"),
        ] {
            assert_eq!(lookup_user(q).unwrap().iterate.unwrap().item, item);
            assert_eq!(lookup(item).unwrap().ret, Pos::Fixed(Scalar::I32));
            assert!(lookup_user(item).is_none());
        }
        let r = lookup_user("closest_point_triangle")
            .unwrap()
            .resolve(&[k(v3.clone()), k(v3.clone()), k(v3.clone()), k(v3.clone())])
            .unwrap();
        assert_eq!(r.ret, v3);
        assert!(!lookup("closest_point_triangle").unwrap().faults());
    }

    #[test]
    fn hash_grid_rows() {
        let grid = Ty::Object(ObjectKind::HashGrid);
        let state = Ty::Object(ObjectKind::HashGridQuery);
        let v3 = Ty::Vector(Scalar::F32, 3);
        let q = lookup_user("hash_grid_query").unwrap();
        let r = q
            .resolve(&[
                k(grid.clone()),
                k(v3.clone()),
                ArgTy::Literal { float: true },
            ])
            .unwrap();
        assert_eq!(r.params, vec![grid.clone(), v3.clone(), F32]);
        assert_eq!(r.ret, state);
        // A wrong object or point type is a mismatch naming the types.
        let e = q
            .resolve(&[k(Ty::Array(Box::new(v3.clone()), 1)), k(v3.clone()), k(F32)])
            .unwrap_err();
        assert!(e.contains("expected `HashGrid`"), "{e}");
        assert!(q
            .resolve(&[k(grid.clone()), k(Ty::Vector(Scalar::F64, 3)), k(F32)])
            .is_err());
        // point_id takes any integer index.
        let pid = lookup_user("hash_grid_point_id").unwrap();
        for t in [I32, Ty::Scalar(Scalar::Usize), Ty::Scalar(Scalar::U64)] {
            let r = pid.resolve(&[k(grid.clone()), k(t.clone())]).unwrap();
            assert_eq!(r.params[1], t);
            assert_eq!(r.ret, Ty::Scalar(Scalar::Usize));
        }
        assert!(pid.resolve(&[k(grid.clone()), k(F32)]).is_err());
        assert!(pid.faults() && q.faults() && !lookup("hash_grid_query_done").unwrap().faults());
        for step in [
            "hash_grid_query_next",
            "hash_grid_query_done",
            "hash_grid_query_point",
        ] {
            assert!(lookup_user(step).is_none(), "{step}");
        }
    }

    #[test]
    fn classification_returns_bool() {
        let isnan = lookup("isnan").unwrap();
        assert_eq!(isnan.resolve(&[k(F32)]).unwrap().ret, crate::types::BOOL);
        let v3 = Ty::Vector(Scalar::F64, 3);
        assert_eq!(isnan.resolve(&[k(v3)]).unwrap().ret, crate::types::BOOL);
        assert!(isnan.resolve(&[k(I32)]).is_err());
        // step takes integers too (Warp's); smoothstep only floats.
        assert_eq!(lookup("step").unwrap().resolve(&[k(I32)]).unwrap().ret, I32);
        assert!(lookup("smoothstep")
            .unwrap()
            .resolve(&[k(I32), k(I32), k(I32)])
            .is_err());
    }
}

#[cfg(test)]
mod doc;

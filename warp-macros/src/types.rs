//! The kernel language's types, and how Rust type syntax maps onto them.
//!
//! The macro knows the types of parameters, literals, builtins, vectors and matrices. What it
//! cannot see from inside one function (a user func's return type, a user struct's fields) is
//! `Ty::Deferred`: such values pass through unchecked here and are typed by the target
//! compiler (rustc for the CPU, nvcc-style `auto` for CUDA), with the literal rule below
//! applied the same way on both.

use std::fmt;

/// Scalar types.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Scalar {
    Bool,
    I8,
    I16,
    I32,
    I64,
    Isize,
    U8,
    U16,
    U32,
    U64,
    Usize,
    F32,
    F64,
    /// Half precision (Warp's `float16`, the `half` crate's `f16`): every operation computes
    /// in f32 and rounds once. No vectors, matrices or generic instances are made of it.
    F16,
    /// Brain float (Warp's `bfloat16`, the `half` crate's `bf16`): f32's exponent range, 8
    /// significant bits; as `F16`, every operation computes in f32 and rounds once, and no
    /// vectors, matrices or generic instances are made of it.
    BF16,
}

impl Scalar {
    pub const ALL: [Scalar; 15] = [
        Scalar::Bool,
        Scalar::I8,
        Scalar::I16,
        Scalar::I32,
        Scalar::I64,
        Scalar::Isize,
        Scalar::U8,
        Scalar::U16,
        Scalar::U32,
        Scalar::U64,
        Scalar::Usize,
        Scalar::F32,
        Scalar::F64,
        Scalar::F16,
        Scalar::BF16,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Scalar::Bool => "bool",
            Scalar::I8 => "i8",
            Scalar::I16 => "i16",
            Scalar::I32 => "i32",
            Scalar::I64 => "i64",
            Scalar::Isize => "isize",
            Scalar::U8 => "u8",
            Scalar::U16 => "u16",
            Scalar::U32 => "u32",
            Scalar::U64 => "u64",
            Scalar::Usize => "usize",
            Scalar::F32 => "f32",
            Scalar::F64 => "f64",
            Scalar::F16 => "f16",
            Scalar::BF16 => "bf16",
        }
    }

    pub fn from_name(s: &str) -> Option<Scalar> {
        Scalar::ALL.into_iter().find(|k| k.name() == s)
    }

    pub fn is_float(self) -> bool {
        matches!(self, Scalar::F32 | Scalar::F64 | Scalar::F16 | Scalar::BF16)
    }

    pub fn is_int(self) -> bool {
        !self.is_float() && self != Scalar::Bool
    }

    pub fn is_signed_int(self) -> bool {
        matches!(
            self,
            Scalar::I8 | Scalar::I16 | Scalar::I32 | Scalar::I64 | Scalar::Isize
        )
    }
}

/// The bit pattern of `v` rounded to the nearest `f16`, ties to even (Rust's `v as f16`;
/// the same rounding as `warp_core::float16::f16_from_f64`): how `f16` literals are emitted.
pub fn f16_bits(v: f64) -> u16 {
    let bits = v.to_bits();
    let sign = ((bits >> 48) & 0x8000) as u16;
    let a = v.abs();
    if a.is_nan() {
        return sign | 0x7E00 | ((bits >> 42) & 0x3FF) as u16;
    }
    if a >= 65520.0 {
        return sign | 0x7C00;
    }
    let pow2 = |k: i32| f64::from_bits(((1023 + k) as u64) << 52);
    let e = ((bits >> 52) & 0x7FF) as i32 - 1023;
    let ulp = e.max(-14) - 10;
    // `r` is an f16 value: subnormal (a multiple of 2^-24 below 2^-14) or normal.
    let r = (a * pow2(-ulp)).round_ties_even() * pow2(ulp);
    if r == 0.0 {
        return sign;
    }
    let rb = r.to_bits();
    let re = ((rb >> 52) & 0x7FF) as i32 - 1023;
    let mag = if re < -14 {
        (r * pow2(24)) as u16
    } else {
        (((re + 15) as u16) << 10) | ((rb >> 42) & 0x3FF) as u16
    };
    sign | mag
}

/// The bit pattern of `v` rounded once to the nearest `bf16`, ties to even (the same rounding
/// as `warp_core::bfloat16::bf16_from_f64`): how `bf16` literals are emitted.
pub fn bf16_bits(v: f64) -> u16 {
    let bits = v.to_bits();
    let sign = ((bits >> 48) & 0x8000) as u16;
    let a = v.abs();
    if a.is_nan() {
        // A quiet NaN of `v`'s sign (literals are never NaN; `f32::NAN`-like constants are).
        return sign | 0x7FC0;
    }
    let pow2 = |k: i32| f64::from_bits(((1023 + k) as u64) << 52);
    if a >= (2.0 - pow2(-8)) * pow2(127) {
        return sign | 0x7F80;
    }
    let e = ((bits >> 52) & 0x7FF) as i32 - 1023;
    let ulp = e.max(-126) - 7;
    // `r` is a bf16 value, exact in f32: its top 16 bits are the bf16's.
    let r = (a * pow2(-ulp)).round_ties_even() * pow2(ulp);
    sign | ((r as f32).to_bits() >> 16) as u16
}

/// Declares the object kinds: one row per kind makes both the [`ObjectKind`] variant and its
/// [`ObjectRow`] in [`OBJECTS`], and the element plumbing of a kind generic over its element
/// (`Volume(VolumeElem)`). A row reads
/// `Kind: param|state, "RustView", "wp::cpp_t", "section";` (see [`ObjectRow`]).
macro_rules! object_kinds {
    ($(
        $(#[doc = $doc:literal])*
        $kind:ident $(($elem:ident))?: $role:ident, $rust:literal, $cuda:literal, $section:literal;
    )*) => {
        /// The kinds of kernel-visible host object (Warp's hash grid, BVH, mesh and volume),
        /// and the values their queries carry between steps: one row each in [`OBJECTS`].
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum ObjectKind {
            $( $(#[doc = $doc])* $kind $(($elem))?, )*
        }

        /// The object kinds' rows (a kind generic over its element has one row, made with
        /// [`VolumeElem::ROW`]).
        pub static OBJECTS: &[ObjectRow] = &[$(
            ObjectRow {
                kind: ObjectKind::$kind $(($elem::ROW))?,
                name: stringify!($kind),
                param: object_kinds!(@param $role),
                elem: object_kinds!(@elem $($elem)?),
                rust: $rust,
                cuda: $cuda,
                section: $section,
            },
        )*];

        impl ObjectKind {
            /// The view's or C++ type's generic argument, where the kind has one
            /// (`Volume<T>`'s `T`, `Bsr<B>`'s `B`).
            pub fn elem(self) -> Option<Elem> {
                match self {
                    $( object_kinds!(@pat e $kind $($elem)?) => object_kinds!(@get e $($elem)?), )*
                }
            }

            /// This kind with element `e` (itself for kinds without one, or whose element is
            /// of another kind than `e`).
            pub fn with_elem(self, e: Elem) -> ObjectKind {
                let _ = e;
                match self {
                    $( object_kinds!(@pat _old $kind $($elem)?) => object_kinds!(@set e self $kind $($elem)?), )*
                }
            }
        }
    };
    (@param param) => { true };
    (@param state) => { false };
    (@elem) => { false };
    (@elem $e:ident) => { true };
    // The element plumbing: `$x` is the binding, named by the caller (macro hygiene).
    (@pat $x:ident $kind:ident) => { ObjectKind::$kind };
    (@pat $x:ident $kind:ident $elem:ident) => { ObjectKind::$kind($x) };
    (@get $x:ident) => { None };
    (@get $x:ident $elem:ident) => { Some(Elem::from($x)) };
    (@set $x:ident $me:ident $kind:ident) => { ObjectKind::$kind };
    (@set $x:ident $me:ident $kind:ident $elem:ident) => {
        match $elem::try_from($x) {
            Ok(e) => ObjectKind::$kind(e),
            Err(()) => $me,
        }
    };
}

object_kinds! {
    /// `HashGrid`: a kernel parameter (the runtime's host type); its CPU view is
    /// `warp_core::objects::HashGridView`, its CUDA type `wp::hash_grid_t`.
    HashGrid: param, "HashGridView", "wp::hash_grid_t", "hash_grid";
    /// The state of a neighbour query, made and advanced only by the loop
    /// `for j in hash_grid_query(..)` lowers to; users never name it.
    HashGridQuery: state, "HashGridQuery", "wp::hash_grid_query_t", "hash_grid";
    /// `Bvh`: a kernel parameter; its CPU view is `warp_core::objects::BvhView`, its CUDA type
    /// `wp::bvh_t`.
    Bvh: param, "BvhView", "wp::bvh_t", "bvh";
    /// The state of a box query over a BVH (`for i in bvh_query_aabb(..)`).
    BvhQueryAabb: state, "BvhQueryAabb", "wp::bvh_query_aabb_t", "bvh";
    /// The state of a ray query over a BVH (`for i in bvh_query_ray(..)`).
    BvhQueryRay: state, "BvhQueryRay", "wp::bvh_query_ray_t", "bvh";
    /// `Mesh`: a kernel parameter; its CPU view is `warp_core::objects::MeshView`, its CUDA
    /// type `wp::mesh_t`.
    Mesh: param, "MeshView", "wp::mesh_t", "mesh";
    /// The state of a box query over a mesh's faces (`for f in mesh_query_aabb(..)`).
    MeshQueryAabb: state, "MeshQueryAabb", "wp::mesh_query_aabb_t", "mesh";
    /// `Volume<T>`: a kernel parameter, a NanoVDB grid of `T` values (or of voxel indices);
    /// its CPU view is `warp_core::objects::VolumeView<T>`, its CUDA type `wp::volume_t<T>`.
    /// The element is part of the type, so a grid of one type where another is declared does
    /// not compile (the runtime's `Volume<T>` is the launch argument's type).
    Volume(VolumeElem): param, "VolumeView", "wp::volume_t", "volume";
    /// `Bsr<B>`: a kernel parameter, a block sparse row matrix of `B` blocks (the `sparse`
    /// tier's); its CPU view is `warp_core::objects::BsrView<B>`, its CUDA type
    /// `wp::bsr_t<B>`. Kernels read its structure and read and write its values.
    Bsr(BlockElem): param, "BsrView", "wp::bsr_t", "bsr";
    /// The state of a row's iteration (`for k in bsr_row(a, r)`).
    BsrRow: state, "BsrRowQuery", "wp::bsr_row_query_t", "bsr";
}

/// The element of an object generic over one: a volume's value type or a matrix's block.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Elem {
    Volume(VolumeElem),
    Block(BlockElem),
}

impl From<VolumeElem> for Elem {
    fn from(e: VolumeElem) -> Elem {
        Elem::Volume(e)
    }
}

impl From<BlockElem> for Elem {
    fn from(e: BlockElem) -> Elem {
        Elem::Block(e)
    }
}

impl TryFrom<Elem> for VolumeElem {
    type Error = ();
    fn try_from(e: Elem) -> Result<VolumeElem, ()> {
        match e {
            Elem::Volume(v) => Ok(v),
            Elem::Block(_) => Err(()),
        }
    }
}

impl TryFrom<Elem> for BlockElem {
    type Error = ();
    fn try_from(e: Elem) -> Result<BlockElem, ()> {
        match e {
            Elem::Block(b) => Ok(b),
            Elem::Volume(_) => Err(()),
        }
    }
}

impl Elem {
    /// The element's type (`None` for an index grid's, which has none).
    pub fn ty(self) -> Option<Ty> {
        match self {
            Elem::Volume(v) => v.ty(),
            Elem::Block(b) => Some(b.ty()),
        }
    }
}

/// What a `Bsr<B>` holds: `rows x cols` scalars of `f32` or `f64` (the sparse tier's block
/// types): `1 x 1` is the scalar itself, a square `2..4` glam's `Mat2`..`DMat4`, and `R != C`
/// in {2, 3, 4, 6} warp-core's `Mat23`..`DMat64`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BlockElem {
    pub scalar: Scalar,
    pub rows: u8,
    pub cols: u8,
}

impl BlockElem {
    /// The element of the row `Bsr(BlockElem)` is written with (its kinds share the row).
    pub const ROW: BlockElem = BlockElem {
        scalar: Scalar::F32,
        rows: 1,
        cols: 1,
    };

    /// The block of a value type, if it is one.
    pub fn of(t: &Ty) -> Option<BlockElem> {
        let (scalar, rows, cols) = match t {
            Ty::Scalar(s) => (*s, 1, 1),
            Ty::Matrix(s, n) => (*s, *n, *n),
            Ty::MatRC(s, r, c) => (*s, *r, *c),
            _ => return None,
        };
        let dims = [2, 3, 4, 6];
        let ok = matches!(scalar, Scalar::F32 | Scalar::F64)
            && ((rows, cols) == (1, 1)
                || (rows == cols && (2..=4).contains(&rows))
                || (rows != cols && dims.contains(&rows) && dims.contains(&cols)));
        ok.then_some(BlockElem { scalar, rows, cols })
    }

    /// The block's value type.
    pub fn ty(self) -> Ty {
        match (self.rows, self.cols) {
            (1, 1) => Ty::Scalar(self.scalar),
            (r, c) if r == c => Ty::Matrix(self.scalar, r),
            (r, c) => Ty::MatRC(self.scalar, r, c),
        }
    }

    /// The block types, as messages list them.
    pub const DESCRIBE: &'static str =
        "f32, f64, Mat2-4, DMat2-4, Mat23 .. Mat64 or DMat23 .. DMat64";
}

/// What a `Volume<T>` holds: the value types a kernel can sample, or voxel indices (Warp's
/// index grids, read through `volume_sample_index` and its kin).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum VolumeElem {
    F32,
    F64,
    I32,
    Vec3,
    DVec3,
    /// `Volume<VoxelIndex>`: an index grid.
    Index,
}

impl VolumeElem {
    /// The element of the row `Volume(VolumeElem)` is written with (its kinds share the row).
    pub const ROW: VolumeElem = VolumeElem::F32;

    /// Every element, in the order messages list them.
    pub const ALL: [VolumeElem; 6] = [
        VolumeElem::F32,
        VolumeElem::F64,
        VolumeElem::I32,
        VolumeElem::Vec3,
        VolumeElem::DVec3,
        VolumeElem::Index,
    ];

    /// The value type (`None` for an index grid, which has none).
    pub fn ty(self) -> Option<Ty> {
        Some(match self {
            VolumeElem::F32 => Ty::Scalar(Scalar::F32),
            VolumeElem::F64 => Ty::Scalar(Scalar::F64),
            VolumeElem::I32 => Ty::Scalar(Scalar::I32),
            VolumeElem::Vec3 => Ty::Vector(Scalar::F32, 3),
            VolumeElem::DVec3 => Ty::Vector(Scalar::F64, 3),
            VolumeElem::Index => return None,
        })
    }

    /// The element of a value type.
    pub fn of(t: &Ty) -> Option<VolumeElem> {
        VolumeElem::ALL
            .into_iter()
            .find(|e| e.ty().as_ref() == Some(t))
    }

    /// The type argument as written (`f32`, `Vec3`, `VoxelIndex`).
    pub fn name(self) -> String {
        self.ty()
            .map_or_else(|| "VoxelIndex".into(), |t| t.to_string())
    }
}

/// One row per object kind: every fact the front end and the emitters need about it
/// (written by `object_kinds!`).
#[derive(Debug)]
pub struct ObjectRow {
    pub kind: ObjectKind,
    /// The type's name in kernel signatures and messages: the kind's own name.
    pub name: &'static str,
    /// Whether a kernel or func parameter may have this type (`param`: the host object itself,
    /// a type the runtime implements `HostObject` for; `state`: a query state, only ever a
    /// local).
    pub param: bool,
    /// Whether the type takes its element as a type argument (`Volume<f32>`): the element is
    /// then part of the kind, the view's and the C++ type's generic argument.
    pub elem: bool,
    /// The Rust type of a value of this kind inside generated CPU code, under the facade's
    /// `__private::objects` (warp-core's `objects`): the object's view, or the state itself.
    pub rust: &'static str,
    /// The C++ type (`wp::hash_grid_t`).
    pub cuda: &'static str,
    /// The CUDA library section that defines the type and its builtins (`wp_<section>.h`).
    pub section: &'static str,
}

impl ObjectKind {
    /// This kind's row.
    pub fn row(self) -> &'static ObjectRow {
        // Kinds that differ only in their element (`Volume<f32>`, `Volume<Vec3>`) share a row.
        OBJECTS
            .iter()
            .find(|r| std::mem::discriminant(&r.kind) == std::mem::discriminant(&self))
            .expect("every object kind has a row")
    }
}

impl ObjectRow {
    /// The row of the object a parameter type names (`HashGrid`, `Volume`), if any.
    pub fn param_named(name: &str) -> Option<&'static ObjectRow> {
        OBJECTS.iter().find(|r| r.param && r.name == name)
    }
}

/// `callback! { (Name, param|state, elem|plain, RustView, "wp::cpp_t", "section") .. }` for
/// every row of [`OBJECTS`] (the `__object_rows!` macro's expansion).
pub fn object_rows_callback(callback: proc_macro2::TokenStream) -> proc_macro2::TokenStream {
    let rows = OBJECTS.iter().map(|r| {
        let name = quote::format_ident!("{}", r.name);
        let role = quote::format_ident!("{}", if r.param { "param" } else { "state" });
        let elem = quote::format_ident!("{}", if r.elem { "elem" } else { "plain" });
        let rust = quote::format_ident!("{}", r.rust);
        let (cuda, section) = (r.cuda, r.section);
        quote::quote!((#name, #role, #elem, #rust, #cuda, #section))
    });
    quote::quote!(#callback! { #(#rows)* })
}

/// A kernel-language type.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Ty {
    Scalar(Scalar),
    /// glam vectors: Vec2-4 (f32), DVec2-4 (f64), IVec2-4 (i32), UVec2-4 (u32).
    Vector(Scalar, u8),
    /// glam column-major matrices: Mat2-4 (f32), DMat2-4 (f64).
    Matrix(Scalar, u8),
    /// glam quaternions: Quat (f32), DQuat (f64).
    Quat(Scalar),
    /// Rigid transforms (warp-core's, not glam's): Transform (f32), DTransform (f64); fields
    /// `p` (the 3-vector) and `q` (the quaternion).
    Transform(Scalar),
    /// Spatial vectors (warp-core's, not glam's): SpatialVector (f32), DSpatialVector (f64);
    /// six lanes, members `"0"` to `"5"` (a kernel's `v[k]`, Rust's `v.k`, C++'s `v.fk`).
    SpatialVector(Scalar),
    /// 6x6 spatial matrices: SpatialMatrix (f32), DSpatialMatrix (f64); row-major, members
    /// `"0"` to `"5"` are the rows (`m[i][j]`).
    SpatialMatrix(Scalar),
    /// Non-square matrices (warp-core's `Mat23` .. `Mat64`, `DMat23` ..): rows, columns, every
    /// `R != C` in {2, 3, 4, 6} (the square shapes are `Matrix` and `SpatialMatrix`: one type
    /// per shape, made by [`Ty::mat_of`]). Row-major, members `"0"` to `"R-1"` are the rows,
    /// each the vector of the column count ([`Ty::vec_of`]).
    MatRC(Scalar, u8, u8),
    /// `Array<T, N>`.
    Array(Box<Ty>, u8),
    /// A fixed-size local array (`[f32; 8]`, `[Vec3; N]`): a value (copied, passed and
    /// returned whole), its element and its length (a literal, or a module-level `const`).
    /// Elements are read and written at dynamic indices, checked against the length.
    LocalArray(Box<Ty>, Dim),
    /// A user struct (made kernel-ready by the derive), by its last path segment.
    Struct(String),
    /// The tuple `tid()` returns for 2-D to 4-D launches.
    TidTuple(u8),
    /// A tuple of 2 to 7 values: what a decomposition returns (`svd3`: `(Mat3, Vec3, Mat3)`),
    /// a tuple local or literal (`(a, b)`), a func's declared tuple result. Its elements are
    /// members `"0"`, `"1"`, .. (`t.0`); an element may be `Deferred` (a func's result).
    Tuple(Vec<Ty>),
    /// A host object a kernel takes as a parameter (`HashGrid`), or the state of one of its
    /// queries; kernels see objects only through builtin rows.
    Object(ObjectKind),
    /// A block-cooperative tile (`Tile<f32, 16, 8>`): its element (a scalar) and its shape,
    /// rank 1 to 4. Only kernels launched with `launch_tiled` hold tiles.
    Tile(Box<Ty>, Vec<Dim>),
    /// `()`.
    Unit,
    /// Not knowable from inside this function; typed by the target compiler.
    Deferred,
}

/// One dimension of a tile's shape: an integer literal, or a module-level `const` named by its
/// path (SCREAMING_CASE), whose value only rustc knows.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum Dim {
    Lit(u32),
    /// The path as written, segments joined by `::`.
    Const(String),
}

impl Dim {
    /// Whether two dims are equal: `Some(true)` or `Some(false)` when the macro can tell (two
    /// literals, or the same const), `None` when only rustc can (a const against a literal or
    /// another const): such a rule becomes a `const` assertion in the generated code.
    pub fn same(&self, o: &Dim) -> Option<bool> {
        match (self, o) {
            (Dim::Lit(a), Dim::Lit(b)) => Some(a == b),
            (Dim::Const(a), Dim::Const(b)) if a == b => Some(true),
            _ => None,
        }
    }

    /// The dim as a Rust `usize` constant expression (`16`, `{ TM as usize }`).
    pub fn rust_tokens(&self) -> proc_macro2::TokenStream {
        match self {
            Dim::Lit(n) => {
                let n = proc_macro2::Literal::usize_unsuffixed(*n as usize);
                quote::quote!(#n)
            }
            Dim::Const(p) => {
                let p: syn::Path = syn::parse_str(p).expect("a const path");
                quote::quote!({ #p as usize })
            }
        }
    }
}

impl fmt::Display for Dim {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Dim::Lit(n) => write!(f, "{n}"),
            Dim::Const(p) => f.write_str(p),
        }
    }
}

pub const F32: Ty = Ty::Scalar(Scalar::F32);
pub const BOOL: Ty = Ty::Scalar(Scalar::Bool);
pub const USIZE: Ty = Ty::Scalar(Scalar::Usize);
pub const I32: Ty = Ty::Scalar(Scalar::I32);

impl Ty {
    /// Whether a value of this type may hold a float (and so carry a gradient): a float
    /// value, an array or tuple with one, and what the macro cannot see into (a struct, a
    /// deferred type, an object, whose element may be a float).
    pub fn may_hold_float(&self) -> bool {
        match self {
            Ty::Array(e, _) | Ty::LocalArray(e, _) | Ty::Tile(e, _) => e.may_hold_float(),
            Ty::Tuple(ts) => ts.iter().any(Ty::may_hold_float),
            Ty::Struct(_) | Ty::Deferred | Ty::Object(_) => true,
            Ty::TidTuple(_) | Ty::Unit => false,
            t => t.scalar().is_some_and(|s| s.is_float()),
        }
    }

    /// The scalar a value of this type is made of (`None` for arrays, structs, unit).
    pub fn scalar(&self) -> Option<Scalar> {
        match self {
            Ty::Scalar(s)
            | Ty::Vector(s, _)
            | Ty::Matrix(s, _)
            | Ty::Quat(s)
            | Ty::Transform(s)
            | Ty::SpatialVector(s)
            | Ty::SpatialMatrix(s)
            | Ty::MatRC(s, ..) => Some(*s),
            _ => None,
        }
    }

    /// The float vector of length `n` of scalar `s`: glam's `Vec2-4`, a spatial vector for 6.
    pub fn vec_of(s: Scalar, n: u8) -> Option<Ty> {
        match n {
            _ if !matches!(s, Scalar::F32 | Scalar::F64) => None,
            2..=4 => Some(Ty::Vector(s, n)),
            6 => Some(Ty::SpatialVector(s)),
            _ => None,
        }
    }

    /// The matrix of shape `r x c` of scalar `s` (f32, f64; each size in {2, 3, 4, 6}): glam's
    /// square `Mat2-4`, the spatial matrix for 6x6, a non-square matrix otherwise.
    pub fn mat_of(s: Scalar, r: u8, c: u8) -> Option<Ty> {
        Ty::vec_of(s, r)?;
        Ty::vec_of(s, c)?;
        Some(match (r, c) {
            (6, 6) => Ty::SpatialMatrix(s),
            _ if r == c => Ty::Matrix(s, r),
            _ => Ty::MatRC(s, r, c),
        })
    }

    /// A float matrix's scalar, rows and columns (glam's, spatial, non-square).
    pub fn mat_shape(&self) -> Option<(Scalar, u8, u8)> {
        match self {
            Ty::Matrix(s, n) => Some((*s, *n, *n)),
            Ty::SpatialMatrix(s) => Some((*s, 6, 6)),
            Ty::MatRC(s, r, c) => Some((*s, *r, *c)),
            _ => None,
        }
    }

    /// A float vector's scalar and length (glam's float vectors, spatial vectors).
    pub fn vec_shape(&self) -> Option<(Scalar, u8)> {
        match self {
            Ty::Vector(s, n) if s.is_float() => Some((*s, *n)),
            Ty::SpatialVector(s) => Some((*s, 6)),
            _ => None,
        }
    }

    pub fn is_deferred(&self) -> bool {
        matches!(self, Ty::Deferred)
    }

    /// Whether this is a tile element: an integer or float scalar, or a 2-vector of floats
    /// (`Vec2`, `DVec2`: the complex values of `tile_fft`).
    pub fn is_tile_elem(&self) -> bool {
        matches!(self, Ty::Scalar(s) if *s != Scalar::Bool) || self.is_vec2_float()
    }

    /// `Vec2` or `DVec2`.
    pub fn is_vec2_float(&self) -> bool {
        matches!(self, Ty::Vector(Scalar::F32 | Scalar::F64, 2))
    }

    /// A tile of `Vec2` or `DVec2` elements.
    pub fn is_vector_tile(&self) -> bool {
        matches!(self, Ty::Tile(e, _) if e.is_vec2_float())
    }

    pub fn is_tile(&self) -> bool {
        matches!(self, Ty::Tile(..))
    }

    /// A fixed-size local array's element type and length.
    pub fn local_array(&self) -> Option<(&Ty, &Dim)> {
        match self {
            Ty::LocalArray(e, n) => Some((e, n)),
            _ => None,
        }
    }

    pub fn is_int_scalar(&self) -> bool {
        matches!(self, Ty::Scalar(s) if s.is_int())
    }

    /// The glam name of a vector, matrix or quaternion type; for transforms, warp-core's name
    /// (`Transform`, `DTransform`), which the CUDA library uses too.
    pub fn glam_name(&self) -> Option<String> {
        let prefix = |s: Scalar| match s {
            Scalar::F32 => Some(""),
            Scalar::F64 => Some("D"),
            Scalar::I32 => Some("I"),
            Scalar::U32 => Some("U"),
            _ => None,
        };
        match self {
            Ty::Vector(s, n) => Some(format!("{}Vec{}", prefix(*s)?, n)),
            Ty::Matrix(s, n) => Some(format!("{}Mat{}", prefix(*s)?, n)),
            Ty::Quat(s) => Some(format!("{}Quat", prefix(*s)?)),
            Ty::Transform(s) if s.is_float() => Some(format!("{}Transform", prefix(*s)?)),
            Ty::SpatialVector(s) if s.is_float() => Some(format!("{}SpatialVector", prefix(*s)?)),
            Ty::SpatialMatrix(s) if s.is_float() => Some(format!("{}SpatialMatrix", prefix(*s)?)),
            Ty::MatRC(s, r, c) if s.is_float() => Some(format!("{}Mat{r}{c}", prefix(*s)?)),
            _ => None,
        }
    }

    /// Parses a glam type name (`Vec3`, `DMat4`, `Quat`, ...) or a transform's (`Transform`,
    /// `DTransform`).
    pub fn from_glam_name(name: &str) -> Option<Ty> {
        let (scalar, rest) = if let Some(r) = name.strip_prefix('D') {
            (Scalar::F64, r)
        } else if let Some(r) = name.strip_prefix('I') {
            (Scalar::I32, r)
        } else if let Some(r) = name.strip_prefix('U') {
            (Scalar::U32, r)
        } else {
            (Scalar::F32, name)
        };
        if rest == "Quat" {
            return scalar.is_float().then_some(Ty::Quat(scalar));
        }
        if rest == "Transform" {
            return scalar.is_float().then_some(Ty::Transform(scalar));
        }
        if rest == "SpatialVector" {
            return scalar.is_float().then_some(Ty::SpatialVector(scalar));
        }
        if rest == "SpatialMatrix" {
            return scalar.is_float().then_some(Ty::SpatialMatrix(scalar));
        }
        // `Mat23`: two digits, a non-square shape of float scalars.
        if let Some(rc) = rest.strip_prefix("Mat").filter(|d| d.len() == 2) {
            let d: Vec<u8> = rc.bytes().map(|b| b.wrapping_sub(b'0')).collect();
            return match Ty::mat_of(scalar, d[0], d[1])? {
                t @ Ty::MatRC(..) => Some(t),
                _ => None,
            };
        }
        let (kind, n) = rest.split_at(rest.len().checked_sub(1)?);
        let n: u8 = n.parse().ok().filter(|n| (2..=4).contains(n))?;
        match kind {
            "Vec" => Some(Ty::Vector(scalar, n)),
            "Mat" if scalar.is_float() => Some(Ty::Matrix(scalar, n)),
            _ => None,
        }
    }

    /// Field names of vectors, quaternions and transforms, and the column names of matrices.
    pub fn member_ty(&self, name: &str) -> Option<Ty> {
        match self {
            Ty::Vector(s, n) => {
                let idx = ["x", "y", "z", "w"].iter().position(|c| *c == name)?;
                (idx < *n as usize).then_some(Ty::Scalar(*s))
            }
            Ty::Quat(s) => ["x", "y", "z", "w"]
                .contains(&name)
                .then_some(Ty::Scalar(*s)),
            Ty::Matrix(s, n) => {
                let idx = ["x_axis", "y_axis", "z_axis", "w_axis"]
                    .iter()
                    .position(|c| *c == name)?;
                (idx < *n as usize).then_some(Ty::Vector(*s, *n))
            }
            Ty::Transform(s) => match name {
                "p" => Some(Ty::Vector(*s, 3)),
                "q" => Some(Ty::Quat(*s)),
                _ => None,
            },
            Ty::SpatialVector(s) => spatial_lane(name).then_some(Ty::Scalar(*s)),
            Ty::SpatialMatrix(s) => spatial_lane(name).then_some(Ty::SpatialVector(*s)),
            Ty::MatRC(s, r, c) => name
                .parse::<u8>()
                .ok()
                .filter(|i| i < r && name == i.to_string())
                .and_then(|_| Ty::vec_of(*s, *c)),
            Ty::Tuple(ts) => name.parse::<usize>().ok().and_then(|k| ts.get(k).cloned()),
            _ => None,
        }
    }
}

impl Ty {
    /// What a run-time index reaches in a value with lanes (Warp's `v[i]`): the element type
    /// and how many there are. A vector's or quaternion's lanes (x, y, z, w, glam's order)
    /// and a spatial vector's six are scalars; a glam matrix's elements are its columns (its
    /// storage: `m[(i, j)]` is lane i of column j) and a spatial matrix's its rows (`m[(i,
    /// j)]` is lane j of row i).
    pub fn lane_elems(&self) -> Option<(Ty, usize)> {
        match self {
            Ty::Vector(s, n) => Some((Ty::Scalar(*s), *n as usize)),
            Ty::Quat(s) => Some((Ty::Scalar(*s), 4)),
            Ty::Matrix(s, n) => Some((Ty::Vector(*s, *n), *n as usize)),
            Ty::SpatialVector(s) => Some((Ty::Scalar(*s), 6)),
            Ty::SpatialMatrix(s) => Some((Ty::SpatialVector(*s), 6)),
            Ty::MatRC(s, r, c) => Some((Ty::vec_of(*s, *c)?, *r as usize)),
            _ => None,
        }
    }

    /// The member that element `k` of [`Ty::lane_elems`] is (`"y"`, `"x_axis"`, `"3"`): a
    /// literal index is a field on both back ends, checked when the macro runs.
    pub fn lane_member(&self, k: usize) -> Option<String> {
        let named = |names: &[&str], n: usize| (k < n).then(|| names[k].to_string());
        match self {
            Ty::Vector(_, n) => named(&["x", "y", "z", "w"], *n as usize),
            Ty::Quat(_) => named(&["x", "y", "z", "w"], 4),
            Ty::Matrix(_, n) => named(&["x_axis", "y_axis", "z_axis", "w_axis"], *n as usize),
            Ty::SpatialVector(_) | Ty::SpatialMatrix(_) => (k < 6).then(|| k.to_string()),
            Ty::MatRC(_, r, _) => (k < *r as usize).then(|| k.to_string()),
            _ => None,
        }
    }
}

/// Whether `name` is a lane of a spatial vector or a row of a spatial matrix: `"0"` to `"5"`.
fn spatial_lane(name: &str) -> bool {
    matches!(name, "0" | "1" | "2" | "3" | "4" | "5")
}

impl fmt::Display for Ty {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Ty::Scalar(s) => f.write_str(s.name()),
            Ty::Vector(..)
            | Ty::Matrix(..)
            | Ty::Quat(_)
            | Ty::Transform(_)
            | Ty::SpatialVector(_)
            | Ty::SpatialMatrix(_)
            | Ty::MatRC(..) => f.write_str(&self.glam_name().unwrap_or_else(|| "?".into())),
            Ty::Array(t, 1) => write!(f, "Array<{t}>"),
            Ty::Array(t, n) => write!(f, "Array<{t}, {n}>"),
            Ty::LocalArray(t, n) => write!(f, "[{t}; {n}]"),
            Ty::Struct(name) => f.write_str(name),
            Ty::TidTuple(n) => write!(f, "({})", vec!["usize"; *n as usize].join(", ")),
            Ty::Tuple(ts) => {
                let ts: Vec<String> = ts.iter().map(|t| t.to_string()).collect();
                write!(f, "({})", ts.join(", "))
            }
            Ty::Object(ObjectKind::Volume(e)) => write!(f, "Volume<{}>", e.name()),
            Ty::Object(ObjectKind::Bsr(e)) => write!(f, "Bsr<{}>", e.ty()),
            Ty::Object(k) => f.write_str(k.row().name),
            Ty::Tile(e, dims) => {
                write!(f, "Tile<{e}")?;
                for d in dims {
                    write!(f, ", {d}")?;
                }
                f.write_str(">")
            }
            Ty::Unit => f.write_str("()"),
            Ty::Deferred => f.write_str("_"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn glam_names_round_trip() {
        for name in [
            "Vec2",
            "Vec3",
            "Vec4",
            "DVec3",
            "IVec2",
            "UVec4",
            "Mat3",
            "DMat4",
            "Quat",
            "DQuat",
            "Transform",
            "DTransform",
            "SpatialVector",
            "DSpatialMatrix",
            "Mat23",
            "DMat63",
            "Mat46",
        ] {
            let ty = Ty::from_glam_name(name).unwrap();
            assert_eq!(ty.glam_name().unwrap(), name);
        }
        for bad in [
            "Vec5",
            "IMat3",
            "IQuat",
            "Vec",
            "Foo",
            "ITransform",
            "UTransform",
            "ISpatialVector",
            "Mat33",
            "Mat66",
            "Mat25",
            "IMat23",
            "Mat2x",
        ] {
            assert_eq!(Ty::from_glam_name(bad), None, "{bad}");
        }
    }

    #[test]
    fn bf16_literal_bits() {
        assert_eq!(bf16_bits(1.0), 0x3F80);
        assert_eq!(bf16_bits(-2.0), 0xC000);
        assert_eq!(bf16_bits(0.1), 0x3DCD);
        assert_eq!(bf16_bits(1.0 + 2f64.powi(-8)), 0x3F80); // tie to even
        assert_eq!(bf16_bits(1.0 + 3.0 * 2f64.powi(-8)), 0x3F82);
        assert_eq!(bf16_bits(1.0 + 2f64.powi(-8) + 2f64.powi(-40)), 0x3F81);
        assert_eq!(bf16_bits(3.39e38), 0x7F7F); // MAX (3.3895e38); the tie above is 3.3962e38
        assert_eq!(bf16_bits(3.4e38), 0x7F80);
        assert_eq!(bf16_bits(1e39), 0x7F80);
        assert_eq!(bf16_bits(-0.0), 0x8000);
        assert_eq!(bf16_bits(2f64.powi(-133)), 0x0001);
        assert_eq!(bf16_bits(2f64.powi(-134)), 0x0000);
        assert_eq!(bf16_bits(std::f64::consts::PI), 0x4049);
    }

    #[test]
    fn f16_literal_bits() {
        assert_eq!(f16_bits(1.0), 0x3C00);
        assert_eq!(f16_bits(-2.0), 0xC000);
        assert_eq!(f16_bits(0.1), 0x2E66);
        assert_eq!(f16_bits(65504.0), 0x7BFF);
        assert_eq!(f16_bits(65519.0), 0x7BFF);
        assert_eq!(f16_bits(65520.0), 0x7C00);
        assert_eq!(f16_bits(1e10), 0x7C00);
        assert_eq!(f16_bits(f64::NEG_INFINITY), 0xFC00);
        assert_eq!(f16_bits(f64::NAN), 0x7E00);
        assert_eq!(f16_bits(-0.0), 0x8000);
        assert_eq!(f16_bits(2f64.powi(-24)), 0x0001);
        assert_eq!(f16_bits(2f64.powi(-25)), 0x0000);
        assert_eq!(f16_bits(3.0 * 2f64.powi(-25)), 0x0002);
        assert_eq!(f16_bits(2f64.powi(-14)), 0x0400);
        assert_eq!(f16_bits(1023.0 * 2f64.powi(-24)), 0x03FF);
        assert_eq!(f16_bits(1.0 + 2f64.powi(-11)), 0x3C00); // tie to even
        assert_eq!(f16_bits(1.0 + 3.0 * 2f64.powi(-11)), 0x3C02);
        assert_eq!(f16_bits(1.0 + 2f64.powi(-11) + 2f64.powi(-40)), 0x3C01);
        assert_eq!(f16_bits(std::f64::consts::PI), 0x4248);
    }

    #[test]
    fn object_rows() {
        for (i, r) in OBJECTS.iter().enumerate() {
            assert_eq!(r.kind.row().name, r.name);
            assert!(OBJECTS[..i]
                .iter()
                .all(|o| o.kind != r.kind && o.name != r.name));
            assert!(r.cuda.starts_with("wp::"), "{}", r.name);
            // Only a parameter type takes an element; a state is a local the macro types.
            assert!(r.param || !r.elem, "{}", r.name);
            assert_eq!(r.elem, r.kind.elem().is_some(), "{}", r.name);
        }
        let named = |n| ObjectRow::param_named(n).map(|r| (r.kind, r.elem));
        assert_eq!(named("HashGrid"), Some((ObjectKind::HashGrid, false)));
        // A query state is no parameter type.
        assert_eq!(named("HashGridQuery"), None);
        assert_eq!(Ty::Object(ObjectKind::HashGrid).to_string(), "HashGrid");
        // `Volume` takes its element.
        assert_eq!(
            named("Volume"),
            Some((ObjectKind::Volume(VolumeElem::ROW), true))
        );
        let v3 = ObjectKind::Volume(VolumeElem::Vec3);
        assert_eq!(v3.row().name, "Volume");
        assert_eq!(v3.elem(), Some(VolumeElem::Vec3.into()));
        assert_eq!(
            v3.with_elem(VolumeElem::Index.into()).elem(),
            Some(VolumeElem::Index.into())
        );
        // A volume given a block keeps its own element; a matrix takes a block.
        let m = BlockElem::of(&Ty::MatRC(Scalar::F64, 2, 6)).unwrap();
        assert_eq!(v3.with_elem(m.into()), v3);
        let bsr = ObjectKind::Bsr(BlockElem::ROW).with_elem(m.into());
        assert_eq!(bsr.elem(), Some(m.into()));
        assert_eq!(bsr.row().name, "Bsr");
        assert_eq!(Ty::Object(bsr).to_string(), "Bsr<DMat26>");
        assert_eq!(BlockElem::of(&Ty::Matrix(Scalar::F16, 3)), None);
        assert_eq!(BlockElem::of(&Ty::SpatialMatrix(Scalar::F32)), None);
        assert_eq!(BlockElem::of(&Ty::Scalar(Scalar::I32)), None);
        assert_eq!(
            ObjectKind::Bvh.with_elem(VolumeElem::F64.into()),
            ObjectKind::Bvh
        );
        assert_eq!(ObjectKind::Bvh.elem(), None);
        assert_eq!(Ty::Object(v3).to_string(), "Volume<Vec3>");
        for e in VolumeElem::ALL {
            if let Some(t) = e.ty() {
                assert_eq!(VolumeElem::of(&t), Some(e));
            }
        }
    }

    #[test]
    fn members() {
        let v3 = Ty::Vector(Scalar::F32, 3);
        assert_eq!(v3.member_ty("z"), Some(F32));
        assert_eq!(v3.member_ty("w"), None);
        assert_eq!(
            Ty::Matrix(Scalar::F64, 2).member_ty("y_axis"),
            Some(Ty::Vector(Scalar::F64, 2))
        );
        let t = Ty::Transform(Scalar::F64);
        assert_eq!(t.member_ty("p"), Some(Ty::Vector(Scalar::F64, 3)));
        assert_eq!(t.member_ty("q"), Some(Ty::Quat(Scalar::F64)));
        assert_eq!(t.member_ty("x"), None);
        assert_eq!(t.to_string(), "DTransform");
        let (v, m) = (
            Ty::SpatialVector(Scalar::F32),
            Ty::SpatialMatrix(Scalar::F64),
        );
        assert_eq!(v.member_ty("5"), Some(F32));
        assert_eq!(v.member_ty("6"), None);
        assert_eq!(v.member_ty("x"), None);
        assert_eq!(m.member_ty("0"), Some(Ty::SpatialVector(Scalar::F64)));
        assert_eq!(m.to_string(), "DSpatialMatrix");
        let n = Ty::MatRC(Scalar::F32, 2, 3);
        assert_eq!(n.member_ty("1"), Some(Ty::Vector(Scalar::F32, 3)));
        assert_eq!(n.member_ty("2"), None);
        assert_eq!(n.member_ty("01"), None);
        assert_eq!(n.lane_elems(), Some((Ty::Vector(Scalar::F32, 3), 2)));
        assert_eq!(
            Ty::MatRC(Scalar::F64, 3, 6).lane_elems(),
            Some((Ty::SpatialVector(Scalar::F64), 3))
        );
        assert_eq!(
            Ty::mat_of(Scalar::F32, 3, 3),
            Some(Ty::Matrix(Scalar::F32, 3))
        );
        assert_eq!(
            Ty::mat_of(Scalar::F64, 6, 6),
            Some(Ty::SpatialMatrix(Scalar::F64))
        );
        assert_eq!(Ty::mat_of(Scalar::F32, 5, 2), None);
        assert_eq!(Ty::mat_of(Scalar::I32, 2, 3), None);
    }
}

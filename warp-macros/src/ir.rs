//! The one IR that every emitter walks.
//!
//! A kernel or func body is lowered to three-address statements over typed variables: every
//! operation reads variables and writes one, so an emitter handles one operation at a time,
//! and the adjoint transform (reverse mode) can pair each forward statement with its adjoint
//! statement. Control flow stays structured (`If`, `For`, `Loop`, `Break`, `Continue`,
//! `Return`), which maps directly onto Rust and CUDA C++ and tells the adjoint where loops
//! carry values. Short-circuit `&&`/`||`, `if` expressions and `while` are lowered to these.
//!
//! Every statement keeps the span of the user's code it came from, for rustc errors and (in
//! the CUDA emitter) `#line` directives.

use crate::builtins::Builtin;
pub use crate::operators::{BinOp, UnOp};
use crate::types::Ty;
use proc_macro2::Span;

/// Index of a variable in [`Body::vars`].
pub type VarId = usize;

/// A variable: a kernel parameter, a user `let`, or a temporary made by lowering.
#[derive(Clone, Debug)]
pub struct Var {
    /// User name (`None` for temporaries).
    pub name: Option<String>,
    pub ty: Ty,
    /// Assigned more than once (user `let mut`, or a lowering result variable).
    pub mutable: bool,
}

/// What the function is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FnKind {
    Kernel,
    Func,
}

/// A parameter.
#[derive(Clone, Debug)]
pub struct Param {
    pub name: String,
    pub var: VarId,
    pub ty: Ty,
    /// The type as the user wrote it (resolved in the user's scope by rustc); for a `&mut`
    /// parameter, the type it refers to.
    pub syn_ty: syn::Type,
    /// A func's `&mut` parameter (`acc: &mut f32`): in the IR a mutable value, whose final
    /// value the func returns after its result (see `Function::ret`); callers write it back.
    pub by_ref: bool,
}

/// A call of a user func: which of its arguments are `&mut` (bit `k`: argument `k`). The macro
/// cannot see the func's signature, so `expand` checks this against the func's
/// `__WP_MUT_PARAMS` with a `const` assertion spanned at the call.
#[derive(Clone, Debug)]
pub struct CallCheck {
    pub span: Span,
    pub path: syn::Path,
    pub mut_args: u64,
}

/// The index of `p` in `callees` (a function's `@@F<k>@@` list), appended if absent.
pub fn push_callee(callees: &mut Vec<syn::Path>, p: &syn::Path) -> usize {
    match callees.iter().position(|c| c == p) {
        Some(k) => k,
        None => {
            callees.push(p.clone());
            callees.len() - 1
        }
    }
}

/// A lowered kernel or func.
#[derive(Clone, Debug)]
pub struct Function {
    #[allow(dead_code)] // read by the CUDA emitter and the adjoint transform
    pub kind: FnKind,
    pub name: String,
    pub params: Vec<Param>,
    /// The return type (`Ty::Unit` for kernels). A func with `&mut` parameters returns the
    /// tuple of its declared result (`()` if none) and those parameters' final values, in
    /// order: `fn f(a: &mut f32, x: f32) -> Vec3` returns `(Vec3, f32)`.
    #[allow(dead_code)] // read by the CUDA emitter and the adjoint transform
    pub ret: Ty,
    /// The Rust type of `ret` (`None`: unit).
    pub ret_syn: Option<syn::Type>,
    pub vars: Vec<Var>,
    pub body: Block,
    /// How many dimensions `tid()` was destructured into (`None` if never called).
    pub tid_ndim: Option<u8>,
    /// User funcs called (paths as written), for dependency tracking.
    pub callees: Vec<syn::Path>,
    /// The module-level consts the function reads, in the order of its `@@K<k>@@`
    /// placeholders (tile dims that name consts included).
    pub consts: Vec<syn::Path>,
    /// A block-cooperative kernel (launched with `launch_tiled`): it holds tiles, calls
    /// `lane()`, or says `#[kernel(block_dim = N)]`.
    pub tiled: Option<Tiled>,
    /// Every call of a user func, with its `&mut` arguments (see [`CallCheck`]).
    pub call_checks: Vec<CallCheck>,
    /// Tile shape rules the macro could not decide (a const against a literal or another
    /// const): `expand` makes each a `const` assertion spanned at the call, which rustc
    /// evaluates at `cargo check`.
    pub shape_obligations: Vec<ShapeObligation>,
    /// `#[kernel(deterministic)]`: the per-thread record limit of its float accumulations
    /// (`valid::deterministic`), which the emitters record instead of adding atomically.
    pub deterministic: Option<u32>,
    /// A func with a custom replay (`#[func(replay = r)]`): callers' adjoints rerun `r`
    /// instead of its replay, so its own body may use an atomic's old value when nothing it
    /// takes or returns carries a float (its adjoint then adds nothing anywhere).
    pub custom_replay: bool,
}

/// A tile dim that must equal another, checked by rustc (see `Function::shape_obligations`).
#[derive(Clone, Debug)]
pub struct ShapeObligation {
    /// The call that needs it.
    pub span: Span,
    pub lhs: crate::types::Dim,
    pub rhs: crate::types::Dim,
    /// The error when they differ.
    pub msg: String,
    /// `lhs` may also be 1 (a broadcast's source dim).
    pub or_one: bool,
    /// `lhs` must be a power of two (`tile_fft`'s length; `rhs` is not read).
    pub pow2: bool,
}

/// What makes a kernel tiled.
#[derive(Clone, Debug, Default)]
pub struct Tiled {
    /// The block size `#[kernel(block_dim = N)]` fixes: the width of `tile(x)`, and the only
    /// `block_dim` the kernel may be launched with.
    pub width: Option<crate::types::Dim>,
}

pub type Block = Vec<Stmt>;

/// A statement and the user span it came from.
#[derive(Clone, Debug)]
pub struct Stmt {
    pub kind: StmtKind,
    pub span: Span,
}

#[derive(Clone, Debug)]
pub enum StmtKind {
    /// Declares `var` without a value (a result variable assigned in both branches of an if).
    Declare {
        var: VarId,
    },
    /// `dst = op`. `define` marks the statement that introduces `dst`.
    Assign {
        dst: VarId,
        op: Op,
        define: bool,
    },
    /// `array[index] = value`.
    Store {
        array: VarId,
        index: Vec<VarId>,
        value: VarId,
    },
    /// `var.m1.m2 = value` on a local.
    SetMember {
        var: VarId,
        path: Vec<String>,
        value: VarId,
    },
    /// `var[index] = value` on a local array (`Ty::LocalArray`) or a value with lanes
    /// (`Ty::lane_elems`: `v[i] = x`, a glam matrix's column `index`): an overwrite of the
    /// variable (the adjoint treats it as `var = var with element index set`), checked
    /// against the length: an index outside it is a `LocalIndex` fault naming the line.
    SetElem {
        var: VarId,
        index: VarId,
        value: VarId,
    },
    If {
        cond: VarId,
        then: Block,
        els: Block,
    },
    /// `for var in range`: the range is an arithmetic progression (see `RangeSpec`).
    For {
        var: VarId,
        range: RangeSpec,
        body: Block,
    },
    /// `loop { .. }` (also what `while` lowers to).
    Loop {
        body: Block,
    },
    Break,
    Continue,
    Return {
        value: Option<VarId>,
    },
    /// Leaves the enclosing loop if any of `flags` is set. Made only by the adjoint's jump
    /// removal (`middle::adjoint_prep`), always as a loop body's first statement, where leaving
    /// happens before the iteration does anything.
    ExitIf {
        flags: Vec<VarId>,
    },
    /// `print!` / `println!` from a kernel: `{}` and `{:?}` placeholders only.
    Print {
        pieces: Vec<FmtPiece>,
        newline: bool,
    },
    /// `assert!(cond)`, `debug_assert!(cond)`, `expect_eq(a, b);` and the other expectations:
    /// when `cond` (a bool) is false the thread faults (`FaultKind::AssertionFailed`) with
    /// `message` and the statement's line. A `debug_assert!` is this statement inside
    /// `if debug { .. }` ([`Op::DebugMode`]), so that its condition is not computed while
    /// debug mode is off. An adjoint's replay and a tangent kernel drop it (the forward
    /// launch checked it).
    Assert {
        cond: VarId,
        message: String,
    },
}

/// A piece of a print format.
#[derive(Clone, Debug, PartialEq)]
pub enum FmtPiece {
    Text(String),
    Arg { var: VarId, debug: bool },
}

/// `start..end` or `start..=end`, then `.rev()` and `.step_by(k)` in the order written.
#[derive(Clone, Debug)]
pub struct RangeSpec {
    pub start: VarId,
    pub end: VarId,
    pub inclusive: bool,
    pub adapters: Vec<RangeAdapter>,
}

#[derive(Clone, Debug)]
pub enum RangeAdapter {
    Rev,
    StepBy(VarId),
}

/// The function `tile_map` and `tile_reduce` apply: a builtin (its `T` is the tiles' element
/// type), an arithmetic operator by Warp's name (`add`, `sub`, `mul`, `div`), or a user
/// `#[func]` of scalars, by its index in [`Function::callees`].
#[derive(Clone, Copy, Debug)]
pub enum TileFn {
    Builtin(&'static Builtin),
    Op(BinOp),
    Func(usize),
}

/// A literal value with its final type.
#[derive(Clone, Debug, PartialEq)]
pub enum Lit {
    Bool(bool),
    /// An integer literal; `ty` is its scalar type, or `Deferred`.
    Int(i128),
    Float(f64),
}

/// How a vector, matrix, quaternion or local array value is built.
#[derive(Clone, Debug, PartialEq)]
pub enum Ctor {
    /// `Vec3::new(x, y, z)`, `vec3(x, y, z)`, `Quat::from_xyzw(..)`, `Mat3::from_cols(..)`;
    /// a local array's literal `[x, y, z]`.
    Components,
    /// `Vec3::splat(s)`, `Mat3::from_diagonal(v)`; a local array's repeat `[s; N]`.
    Splat,
    /// `Vec3::ZERO`, `Mat3::IDENTITY`, ...: the associated constant's name.
    Const(String),
    /// A user struct's literal (`Ty::Struct`), `Particle { x: p, v, m: 1.0 }`: the path as
    /// written and the fields named, in the order written, one argument each; with `base`
    /// (`Particle { m: 2.0, ..q }`), one more argument last, the value the other fields are
    /// copied from. rustc checks the fields (missing, unknown, repeated) on the CPU code.
    Fields {
        path: syn::Path,
        names: Vec<syn::Ident>,
        base: bool,
    },
}

/// What an [`Op::LitLike`] literal takes from the variable it is modelled on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Like {
    /// The variable's type: `x * 2.0` with `x` a func's vector result splats the literal.
    Value,
    /// The variable's lane type (the type itself for a scalar): the scalar position beside
    /// it in a builtin, `lerp(a, b, 0.5)` or `expect_near(x, 9.84, 1e-6)` with `a`, `x` a
    /// func's result. Without it the C++ literal would be a `double` beside `float`s.
    Scalar,
}

/// An operation producing one value.
#[derive(Clone, Debug)]
pub enum Op {
    Lit(Lit),
    /// A literal typed from the variable (whose type the macro cannot see): an unsuffixed
    /// literal next to a user func's result or a struct field. [`Like`] says whether it takes
    /// the variable's type or its lane type.
    LitLike(Lit, VarId, Like),
    /// Zero of the variable's type, whatever it is (a matrix, a quaternion, a struct): a
    /// tangent where the macro cannot see the type and no literal would do (`lit_like` splats
    /// a literal into scalars and vectors only).
    ZeroLike(VarId),
    Copy(VarId),
    Unary(UnOp, VarId),
    Binary(BinOp, VarId, VarId),
    Cast(VarId, Ty),
    Builtin {
        builtin: &'static Builtin,
        args: Vec<VarId>,
    },
    /// A call of a user `#[func]`, by the path written at the call site.
    Func {
        path: syn::Path,
        args: Vec<VarId>,
    },
    /// `array[index]`: one index variable per dimension.
    Load {
        array: VarId,
        index: Vec<VarId>,
    },
    /// `v.x`, `m.x_axis`, `s.field`; element `k` of a tuple is the member `"k"` (`t.0`).
    Member(VarId, String),
    /// A tuple of the values, in order (`(a, b)`, Rust's `(a, b)`, C++'s `wp::tuple_t`); with
    /// no values, the unit value `()` (C++'s `wp::unit_t`). A func with `&mut` parameters
    /// returns one: its result, then each such parameter's final value (see `front/lower.rs`).
    Tuple(Vec<VarId>),
    /// `a[index]` of a local array (`Ty::LocalArray`, or `Deferred`: a struct's array field,
    /// `s.w[k]`) or of a value with lanes (`Ty::lane_elems`: a vector's lane, a glam
    /// matrix's column), checked against its length (a `LocalIndex` fault naming the line).
    Index {
        array: VarId,
        index: VarId,
    },
    Construct {
        ty: Ty,
        ctor: Ctor,
        args: Vec<VarId>,
    },
    /// Component `k` of the thread index (of the block index, in a tiled kernel).
    Tid(u8),
    /// `lane()`: the thread's index in its block (`usize`), in a tiled kernel.
    Lane,
    /// Whether the runtime's debug mode is on for this launch (`bool`, the same for every
    /// thread): the guard of a `debug_assert!`.
    DebugMode,
    /// `tile_map(f, a)`, `tile_map(f, a, b)`: `f` on every element.
    TileMap {
        f: TileFn,
        args: Vec<VarId>,
    },
    /// `tile_reduce(f, t)`: the elements combined with the binary `f`, in the reductions'
    /// order (a `Tile<T, 1>`).
    TileReduce {
        f: TileFn,
        arg: VarId,
    },
    /// `array.shape()[k]` (usize).
    Extent(VarId, u8),
    /// `array.len()` (usize); also of a local array whose type the macro cannot see (a
    /// struct's array field, `s.w.len()`), a constant.
    Len(VarId),
    /// A module-level `const` (Warp's `wp.constant`), by the path written: its type is the
    /// const's, which the macro cannot see (`Deferred`); the CUDA value comes from the const
    /// itself at assembly (`Function::consts`, `@@K<k>@@`).
    Const(syn::Path),
    /// The bounds check of an in-kernel view (`a.view(lo..hi)`, see `front/lower/views.rs`):
    /// `index` (any integer) as a usize, after checking `index < bound` (`<=` when
    /// `inclusive`); a failed check is an out-of-bounds fault of `array`'s parameter with the
    /// index and the bound as its shape. Accesses through views become accesses of the
    /// viewed array, so this is the only operation views add.
    ViewCheck {
        array: VarId,
        index: VarId,
        bound: VarId,
        inclusive: bool,
    },
}

impl Op {
    /// Calls `f` with every variable the operation reads.
    pub fn for_each_read(&self, f: &mut dyn FnMut(VarId)) {
        match self {
            Op::Copy(v)
            | Op::Unary(_, v)
            | Op::Cast(v, _)
            | Op::Member(v, _)
            | Op::LitLike(_, v, _)
            | Op::ZeroLike(v)
            | Op::TileReduce { arg: v, .. }
            | Op::Extent(v, _)
            | Op::Len(v) => f(*v),
            Op::Binary(_, a, b) => {
                f(*a);
                f(*b)
            }
            Op::Builtin { args, .. }
            | Op::Func { args, .. }
            | Op::Tuple(args)
            | Op::Construct { args, .. }
            | Op::TileMap { args, .. } => args.iter().for_each(|v| f(*v)),
            Op::Load { array, index } => {
                f(*array);
                index.iter().for_each(|v| f(*v))
            }
            Op::Index { array, index } => {
                f(*array);
                f(*index)
            }
            Op::ViewCheck {
                array,
                index,
                bound,
                ..
            } => {
                f(*array);
                f(*index);
                f(*bound)
            }
            Op::Lit(_) | Op::Tid(_) | Op::Lane | Op::DebugMode | Op::Const(_) => {}
        }
    }
}

impl StmtKind {
    /// Calls `f` with every variable the statement itself reads (not those of nested blocks).
    pub fn for_each_read(&self, f: &mut dyn FnMut(VarId)) {
        match self {
            StmtKind::Assign { op, .. } => op.for_each_read(f),
            StmtKind::Store {
                array,
                index,
                value,
            } => {
                f(*array);
                index.iter().for_each(|v| f(*v));
                f(*value)
            }
            StmtKind::SetMember { var, value, .. } => {
                f(*var);
                f(*value)
            }
            StmtKind::SetElem { var, index, value } => {
                f(*var);
                f(*index);
                f(*value)
            }
            StmtKind::If { cond, .. } => f(*cond),
            StmtKind::For { range, .. } => {
                f(range.start);
                f(range.end);
                for a in &range.adapters {
                    if let RangeAdapter::StepBy(k) = a {
                        f(*k)
                    }
                }
            }
            StmtKind::Return { value: Some(v) } => f(*v),
            StmtKind::Assert { cond, .. } => f(*cond),
            StmtKind::ExitIf { flags } => flags.iter().for_each(|v| f(*v)),
            StmtKind::Print { pieces, .. } => {
                for p in pieces {
                    if let FmtPiece::Arg { var, .. } = p {
                        f(*var)
                    }
                }
            }
            StmtKind::Declare { .. }
            | StmtKind::Loop { .. }
            | StmtKind::Break
            | StmtKind::Continue
            | StmtKind::Return { value: None } => {}
        }
    }
}

impl Function {
    pub fn ty(&self, v: VarId) -> &Ty {
        &self.vars[v].ty
    }

    /// The tile variables that some statement sets, in variable order: each has a slot of the
    /// block's shared memory on CUDA (`back::cuda_tile`), and `TileInfo` counts them.
    pub fn tile_vars(&self) -> Vec<VarId> {
        let mut set = vec![false; self.vars.len()];
        walk_stmts(&self.body, &mut |s| {
            if let StmtKind::Assign { dst, .. } = &s.kind {
                set[*dst] = true;
            }
        });
        (0..self.vars.len())
            .filter(|v| set[*v] && self.vars[*v].ty.is_tile())
            .collect()
    }

    /// Whether `s` is block-cooperative (every thread of the block must run it together): a
    /// cooperative row (the tile operations), `tile_map`, or anything else that sets a tile
    /// (a copy or an operator: each thread computes its part of the tile).
    pub fn is_cooperative(&self, s: &Stmt) -> bool {
        match &s.kind {
            StmtKind::Assign { dst, op, .. } => self.is_cooperative_op(*dst, op),
            _ => false,
        }
    }

    /// Whether `dst = op` is cooperative (see [`Function::is_cooperative`]).
    pub fn is_cooperative_op(&self, dst: VarId, op: &Op) -> bool {
        self.vars[dst].ty.is_tile()
            || matches!(op, Op::TileMap { .. } | Op::TileReduce { .. })
            || matches!(op, Op::Builtin { builtin, .. } if builtin.cooperative)
    }
}

/// Visits every statement of a block, depth first.
pub fn walk_stmts<'a>(block: &'a [Stmt], f: &mut dyn FnMut(&'a Stmt)) {
    for s in block {
        f(s);
        match &s.kind {
            StmtKind::If { then, els, .. } => {
                walk_stmts(then, f);
                walk_stmts(els, f);
            }
            StmtKind::For { body, .. } | StmtKind::Loop { body } => walk_stmts(body, f),
            _ => {}
        }
    }
}

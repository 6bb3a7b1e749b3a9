//! The adjoint IR: what [`build`](super::build) decides and the printers spell.
//!
//! Every statement names its operands explicitly (which adjoint, which temporary, which
//! gradient element, whether atomically), so that `back/rust_adjoint.rs` and
//! `back/cuda_adjoint.rs` map each one to their target's syntax and decide nothing. The
//! generated names it implies are fixed: `adj_<var>` (a variable's adjoint, or an array's
//! gradient), `__r` (the seed of the innermost [`AKind::Scope`]), `__g<k>` (a temporary),
//! `__adj_ret` and `__adj_out<k>` (a func's adjoint
//! of its result and of its value parameter `k`), `__FAST` (the launch's thread-owned arrays
//! cover the grid) and `__tid` (the thread index).
//!
//! A local array's adjoint is a local array of the same type (`adj_<var>`), its elements
//! named at the index variable the forward access used: the replay checked those indices
//! (a faulting CUDA thread goes on, so the printers' element accesses stay in bounds
//! whatever the index).

use crate::ir::{Function, Op, RangeSpec, TileFn, VarId};
use crate::types::Ty;
use proc_macro2::Span;

/// A user func the adjoint calls: its index in [`Adjoint::f`]'s `callees` (CUDA's
/// `@@F<k>@@`).
pub type Callee = usize;

/// The adjoint of one kernel or func.
pub struct Adjoint {
    /// The function after jump removal, with the variables the pass added (recorded branch
    /// decisions, values read for an atomic's adjoint, the elements whose adjoints gather a
    /// thread-owned array's gradient) and, for custom gradients, the gradient funcs appended
    /// to its callees: what the statements refer to.
    pub f: Function,
    /// Every variable to declare at the top (not the parameters, not arrays), in the order of
    /// first definition.
    pub decls: Vec<Decl>,
    /// The variables with an adjoint (`adj_<var>`, declared zero after `decls`), parameters
    /// included.
    pub adjs: Vec<VarId>,
    /// What the adjoint takes after the forward parameters, in order.
    pub grad_params: Vec<GradParam>,
    /// The forward replay, the seed of a func's result, the reverse sweep, then what happens
    /// once at the end of the thread.
    pub body: Vec<AStmt>,
    /// Whether anything may be pushed on the adjoint stack (a callee may push too).
    pub uses_stack: bool,
}

/// A gradient parameter of an adjoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GradParam {
    /// The gradient `adj_<array>` of an array parameter (kernels and funcs).
    Array(VarId),
    /// A func's `__adj_out<k>`: a reference to its caller's adjoint of value parameter `k`
    /// (whose variable is `var`), accumulated into at the end.
    Out { k: usize, var: VarId },
}

/// A variable declared at the top of the adjoint.
pub struct Decl {
    pub var: VarId,
    /// Where the variable's type comes from when its IR type cannot be spelt (`Deferred`, or a
    /// type the target cannot name): its first definition. `None` only for a variable never
    /// assigned.
    pub def: Option<TypeOf>,
}

/// The type of a declared variable, as the type of something declared before it.
#[derive(Clone, Debug)]
pub enum TypeOf {
    /// The value of the variable's first assignment (its operands are declared earlier).
    Value(Value),
    /// The type of another variable: a loop variable has its end bound's type.
    Var(VarId),
}

/// The value an assignment stores.
#[derive(Clone, Debug)]
pub enum Value {
    /// The forward operation (a user func through its replay).
    Op(Op),
    /// Zero of the operation's result type: an atomic, not redone. `like` is an operand of
    /// that type (the atomic's value), for targets that cannot infer the type.
    Zero { like: VarId },
}

/// A statement of the adjoint IR and the user span it came from.
#[derive(Clone, Debug)]
pub struct AStmt {
    pub kind: AKind,
    pub span: Span,
}

/// The condition of an [`AKind::If`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cond {
    /// A variable's value.
    Var(VarId),
    /// A decision the replay pushed, popped from the stack.
    Popped,
    /// `__FAST`: the launch checked that its thread-owned arrays cover the grid.
    Fast,
}

/// An array element: at an index, or the element the thread owns.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Index {
    /// At these variables, one per dimension.
    At(Vec<VarId>),
    /// At the thread index (`__tid`, this many dimensions).
    Thread(u8),
}

/// An adjoint accumulated into.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum AdjOf {
    /// `adj_<var>`, or a member of it (`path`, outermost first; empty: the whole).
    Var { var: VarId, path: Vec<String> },
    /// A func's `__adj_out<k>`.
    Out(usize),
    /// `adj_<var>[index]`, an element of a local array's adjoint.
    Elem { var: VarId, index: VarId },
}

/// A gradient value.
#[derive(Clone, Debug)]
pub enum GradSrc {
    /// The seed `__r`.
    Seed,
    /// A lane of the seed: `__r.x`, `__r.y_axis`.
    SeedLane(String),
    /// The sum of lanes of the seed (the adjoint of a splat).
    LaneSum(Vec<String>),
    /// The vector of type `vector` made of the seed's `(column, lane)` entries (the adjoint
    /// of `from_diagonal`).
    Diagonal {
        vector: Ty,
        entries: Vec<(String, String)>,
    },
    /// The temporary `__g<k>`.
    Temp(usize),
    /// The adjoint of a func's result, passed by its caller (`__adj_ret`).
    AdjRet,
    /// `adj_<var>`, or a member of it.
    Adj { var: VarId, path: Vec<String> },
    /// `adj_<var>[index]`, an element of a local array's adjoint.
    AdjElem { var: VarId, index: VarId },
    /// Element `k` of the seed, a local array (the adjoint of a local array's literal).
    SeedElem(usize),
    /// The sum of the seed's elements, a local array (the adjoint of a repeat `[v; N]`).
    ElemSum,
    /// Zero of `like`'s type.
    Zero(VarId),
    /// The gradient of `array` at `index`, which is then cleared (zero of `like`'s type when
    /// the array has none).
    Take {
        array: VarId,
        index: Index,
        like: VarId,
    },
    /// The gradient of `array` at `index`, left as it is.
    Get {
        array: VarId,
        index: Index,
        like: VarId,
    },
    /// A custom gradient: `func(args.., __adj_ret)`, a user func (its CPU body on the CPU).
    Custom { func: Callee, args: Vec<VarId> },
}

/// A value passed to a library adjoint.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Arg {
    Value(VarId),
    /// An array (its data: `volume_sample_index`'s).
    Array(VarId),
}

/// An adjoint passed to be accumulated into.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum GradArg {
    /// The temporary `__g<k>`.
    Temp(usize),
    /// `adj_<var>` itself (where the operand appears once).
    Adj(VarId),
    /// An array's gradient `adj_<array>`.
    ArrayGrad(VarId),
}

/// The type of a temporary, as that of a variable.
#[derive(Clone, Debug)]
pub enum TempLike {
    Var(VarId),
    /// The type of parameter `k` of user func `func` (a temporary for its adjoint, which an
    /// argument's type may differ from: a literal's), which `arg` is passed as.
    Param {
        func: Callee,
        k: usize,
        arg: VarId,
    },
}

#[derive(Clone, Debug)]
pub enum AKind {
    // ---- The forward replay ----
    /// `dst = value`.
    Assign { dst: VarId, value: Value },
    /// `var.path = value`.
    SetMember {
        var: VarId,
        path: Vec<String>,
        value: VarId,
    },
    /// `var[index] = value` on a local array, checked as the forward statement is.
    SetElem {
        var: VarId,
        index: VarId,
        value: VarId,
    },
    /// Pushes `var`'s current value (`line`: the user's line, for the overflow fault).
    Push { var: VarId, line: u32 },
    /// A loop that counts its iterations (`__count`) and pushes the count after the loop: over
    /// `range` (a `for`), or until it leaves (a `loop`: a flag in `exit`). Each iteration
    /// first leaves if any of `exit` is set (before it does anything, so a left iteration is
    /// not counted), then runs `body`, which for a `for` sets the loop's variable
    /// ([`AKind::StepVar`]).
    Loop {
        range: Option<RangeSpec>,
        exit: Vec<VarId>,
        body: Vec<AStmt>,
        line: u32,
    },
    /// `var =` the enclosing loop's progression over its range at this iteration (of `end`'s type when the
    /// target cannot spell `var`'s).
    StepVar { var: VarId, end: VarId },

    // ---- Both ----
    /// `if cond { then } else { els }`.
    If {
        cond: Cond,
        then: Vec<AStmt>,
        els: Vec<AStmt>,
    },

    // ---- The reverse sweep ----
    /// A block: the seed and temporaries live in it.
    Scope(Vec<AStmt>),
    /// `__r = from`: the seed of the rest of the scope.
    Seed(GradSrc),
    /// `adj_var.path = 0` (zero of `var.path`'s type).
    ClearAdj { var: VarId, path: Vec<String> },
    /// `adj_var[index] = 0`, of a local array's adjoint.
    ClearAdjElem { var: VarId, index: VarId },
    /// Restores `var`'s value from the stack.
    Pop { var: VarId },
    /// `to += from`.
    Accum { to: AdjOf, from: GradSrc },
    /// `__g<k> = 0`, of `like`'s type.
    ZeroTemp { k: usize, like: TempLike },
    /// The library adjoint `func(values.., grads.., __r)`, which accumulates into `grads`.
    AdjCall {
        func: String,
        values: Vec<Arg>,
        grads: Vec<GradArg>,
        /// The adjoint reads an array or an object's buffers (a builtin that `faults()`, like
        /// `mesh_query_point`), so it may fault, as its forward call may.
        faults: bool,
    },
    /// The adjoint of user func `func` at `values` with seed `__r`, accumulating into `grads`
    /// (one per argument), which replays and reverses the func's body on the same stack.
    FuncAdj {
        func: Callee,
        values: Vec<VarId>,
        grads: Vec<GradArg>,
    },
    /// `from` into `array`'s gradient at `index`: atomically and checked, or (`own`, only
    /// under [`Cond::Fast`]) as the element's only user in this launch, without a bounds check
    /// (without atomics when the runtime says nothing else adds into the gradient meanwhile:
    /// on the CPU no other adjoint launch, on CUDA a launch that runs alone, `LAUNCH_ALONE`;
    /// and no other argument viewing the same gradient differently, `grads_alias`).
    GradAccum {
        array: VarId,
        index: Index,
        from: GradSrc,
        own: bool,
    },
    /// Clears `array`'s gradient at `index`, as the element's only user (under
    /// [`Cond::Fast`]).
    GradClearOwn { array: VarId, index: Index },
    /// Pops a trip count and runs `body` that many times.
    RevLoop { body: Vec<AStmt> },
    /// The adjoint of `dst = tile_map(f, values..)` with seed `__r` (a tile of `dst`'s type):
    /// on each element, the scalar adjoint of `f` (a user func's own adjoint, on the stack),
    /// into `grads` (the tiles' adjoints).
    TileMapAdj {
        f: TileFn,
        values: Vec<VarId>,
        grads: Vec<GradArg>,
        dst: VarId,
    },
    /// Between a tile and per-lane values, the block together: `adj_tile_lanes` (the reverse of
    /// `tile = tile(lanes)`: each lane's adjoint of `lanes` gains its element of `tile`'s
    /// adjoint) or `adj_untile` (the reverse of `lanes = untile(tile)`: the other way).
    LaneAdj {
        func: &'static str,
        lanes: VarId,
        tile: VarId,
    },
}

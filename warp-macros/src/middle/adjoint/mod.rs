//! Reverse mode as one middle-end pass: a lowered kernel or func to its *adjoint IR*, which
//! `back/rust_adjoint.rs` (CPU) and `back/cuda_adjoint.rs` (CUDA C++) print statement by
//! statement. Every decision of the scheme is made here, once for both targets: what the
//! replay runs, what is pushed on the adjoint stack and when, which branch decisions and trip
//! counts are recorded, and how each statement's adjoint flows into its operands'.
//!
//! The scheme is Warp's, with loops made right:
//! 1. a *forward replay* runs the body again without its stores, prints and atomics (an
//!    atomic's effect happened in the forward launch: its result is replaced by zero, and
//!    `analysis::atomic_without_adjoint` refuses kernels that read it). Before a statement
//!    overwrites a value the reverse sweep will need (a `mut` variable, anything assigned inside
//!    a loop, a loop's own variable), the old value is pushed on the thread's adjoint stack;
//!    after an `if` inside a loop (or on a condition that changes) the branch taken is pushed,
//!    after a loop its trip count;
//! 2. the *reverse sweep* walks the statements backwards. For `d = op(a, b)` it takes `d`'s
//!    adjoint (the *seed*, `__r`), zeroes it, pops `d`'s old value where one was pushed, and
//!    accumulates into the adjoints of `a` and `b` through the library's `adj_<op>` (into fresh
//!    temporaries `__g<k>` first: an operand may appear twice, `x * x`). The invariant: when
//!    the sweep reaches a statement, every variable holds the value it had just after that
//!    statement ran.
//!
//! Jumps (`break`, `continue`, early `return`) are first rewritten into flags by
//! [`adjoint_prep`](super::adjoint_prep), so the sweep follows `if` decisions and trip counts
//! only. A func call replays through the func's replay and reverses through its adjoint, on
//! the same stack.
//!
//! Arrays: reading `a[i]` accumulates the seed into `a`'s gradient atomically; writing
//! `a[i] = v` hands the gradient at `i` to `v` and clears it; `atomic_add`/`atomic_sub` pass
//! the gradient at the index to the value (negated for sub); `atomic_min`/`atomic_max` pass
//! it to the value that won. Arrays a kernel accesses only at the thread index are *thread
//! owned* under `__FAST` (the launch checked that they cover the grid): no other thread
//! touches their elements, so their gradients need no atomics, and the [`Policy`] of the
//! target picks how to exploit that ([`AccumMode`], [`TakeMode`]).
//!
//! Variables: every variable the sweep uses is declared once at the top of the adjoint (the
//! sweep needs values from every block), with the [`TypeOf`] its type can be spelt from where
//! the IR type is not enough (a user func's result, a const, a struct field, a loop over such
//! a bound): declarations come in the order of first definition, so a printer may declare a
//! variable with the type of its defining expression over variables declared before it.

use super::adjoint_prep::without_jumps;
use crate::builtins::Grad;
use crate::ir::*;
use crate::types::Ty;
use proc_macro2::Span;

/// How a target exploits thread-owned arrays (see the module docs). The CPU accumulates their
/// gradients without atomics in place; CUDA also keeps every store away from the thread's
/// gradient loads, which measured 5x faster on the particle adjoint.
#[derive(Clone, Copy, Debug)]
pub struct Policy {
    /// A read-only thread-owned array's gradient is gathered in a register (`__acc_<array>`)
    /// and added once at the end of the thread.
    pub gather_read_only: bool,
    /// A write-only thread-owned array's gradient is read where a write is reversed and
    /// cleared once at the end of the thread.
    pub defer_write_only_clear: bool,
}

impl Policy {
    /// The CPU: gradients of thread-owned arrays accumulate in place, without atomics.
    pub const CPU: Policy = Policy {
        gather_read_only: false,
        defer_write_only_clear: false,
    };
    /// CUDA: gathered reads and deferred clears as well.
    pub const CUDA: Policy = Policy {
        gather_read_only: true,
        defer_write_only_clear: true,
    };
}

/// The adjoint of one kernel or func.
pub struct Adjoint {
    /// The function after jump removal: the variables (names, types, parameters) the
    /// statements refer to.
    pub f: Function,
    /// Every variable to declare at the top (not the parameters, not arrays), in the order of
    /// first definition.
    pub decls: Vec<Decl>,
    /// The variables with an adjoint (`adj_<var>`, declared zero after `decls`), parameters
    /// included.
    pub adjs: Vec<VarId>,
    /// Arrays whose gradient contributions gather in a register (`__acc_<array>`, declared
    /// zero with `adjs`) until [`AKind::FlushGathered`].
    pub gathered: Vec<VarId>,
    /// The forward replay, the seed of a func's result, the reverse sweep, then what happens
    /// once at the end of the thread.
    pub body: Vec<AStmt>,
    /// Whether anything may be pushed on the adjoint stack (a callee may push too).
    pub uses_stack: bool,
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

/// The value a replayed assignment stores.
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

/// How the seed of a read of a thread-owned array reaches its gradient.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AccumMode {
    /// Atomically (any array, and every array when the launch is not `__FAST`).
    Atomic,
    /// Under `__FAST`, an unchecked add into the element the thread owns: plain on the CPU
    /// (which turns `__FAST` off while another adjoint launch runs), atomic on a GPU (where
    /// launches on other streams may share the gradient).
    OwnWhenFast,
    /// Under `__FAST`, into the array's register (`__acc_<array>`), flushed at the end.
    GatherWhenFast,
}

/// How the reverse of a write takes the gradient at the written element.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TakeMode {
    /// Read and clear it.
    Take,
    /// Under `__FAST`, only read it: [`AKind::ClearOwn`] clears it at the end of the thread.
    GetWhenFast,
}

/// The adjoint of an atomic update of `array[index]` by `value`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AtomicKind {
    /// `atomic_add`: the gradient at the index goes to the value.
    Add,
    /// `atomic_sub`: negated.
    Sub,
    /// `atomic_min`/`atomic_max`: to the value if it won (the array's value after the launch).
    Extreme,
}

/// What a func's adjoint takes for one argument of a call.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FuncArgAdj {
    /// An array: its gradient.
    ArrayGrad,
    /// A value: a fresh zero temporary `__g<k>` (k: the argument's position) of the func's
    /// parameter type (which an argument's type may differ from: a literal's), into which the
    /// func accumulates the argument's adjoint.
    Temp,
}

/// A gradient value to accumulate.
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
    /// The temporary `__g<k>` of the last [`AKind::AdjCall`], [`AKind::AdjCast`] or
    /// [`AKind::FuncAdj`].
    Temp(usize),
    /// The adjoint of a func's result, passed by its caller (`__adj_ret`).
    AdjRet,
    /// The gradient of `array` at `index`, taken as `mode` says (zero of `like`'s type when
    /// the array has none).
    Take {
        array: VarId,
        index: Vec<VarId>,
        like: VarId,
        mode: TakeMode,
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
    /// Pushes `var`'s current value (`line`: the user's line, for the overflow fault).
    Push { var: VarId, line: u32 },
    /// `if cond { then } else { els }`; when `record`, the decision is pushed after both
    /// branches (after their own pushes, so that the sweep pops it first).
    If {
        cond: VarId,
        then: Vec<AStmt>,
        els: Vec<AStmt>,
        record: bool,
    },
    /// A loop over `range` that counts its iterations and pushes the count after the loop.
    /// Each iteration first leaves if any of `exit` is set (before it does anything, so a left
    /// iteration is not counted), then runs `body`, which sets the loop's variable
    /// ([`AKind::StepVar`]).
    For {
        range: RangeSpec,
        exit: Vec<VarId>,
        body: Vec<AStmt>,
        line: u32,
    },
    /// The `loop` counterpart of `For`.
    Loop {
        exit: Vec<VarId>,
        body: Vec<AStmt>,
        line: u32,
    },
    /// `var =` the enclosing `For`'s progression at this iteration (of `end`'s type when the
    /// macro cannot see `var`'s).
    StepVar { var: VarId, end: VarId },

    // ---- The reverse sweep ----
    /// A block: the seed and temporaries live in it.
    Scope(Vec<AStmt>),
    /// `__r = adj_var; adj_var = 0`.
    Seed { var: VarId },
    /// `__r = adj_var.path; adj_var.path = 0`.
    SeedMember { var: VarId, path: Vec<String> },
    /// `__r = 0` of `like`'s type (a call whose result carries no gradient still reverses).
    SeedZero { like: VarId },
    /// `adj_var = 0` (an assignment whose operands get nothing).
    ClearAdj { var: VarId },
    /// Restores `var`'s value from the stack.
    Pop { var: VarId },
    /// `adj_var[.member] += from`.
    Accum {
        var: VarId,
        member: Option<String>,
        from: GradSrc,
    },
    /// `__g<k> = 0` like each input, then `adj_<func>(inputs.., __g0.., __r)`.
    AdjCall {
        func: String,
        inputs: Vec<VarId>,
        /// The adjoint reads an array or an object's buffers (a builtin that `faults()`, like
        /// `mesh_query_point`): the CPU call returns a `KResult` (followed by `?`), the CUDA
        /// call takes `__ctx` last.
        faults: bool,
    },
    /// `__g0 = 0` like `from`, then `adj_cast(__g0, __r)`.
    AdjCast { from: VarId },
    /// The reverse of a user func's call `path(args..)` with seed `__r`: temporaries for the
    /// value arguments, then the func's adjoint (which replays and reverses its own body on the
    /// same stack).
    FuncAdj {
        path: syn::Path,
        args: Vec<(VarId, FuncArgAdj)>,
    },
    /// The adjoint of an atomic update (see [`AtomicKind`]).
    AtomicAdj {
        kind: AtomicKind,
        array: VarId,
        index: Vec<VarId>,
        value: VarId,
    },
    /// The seed into `array`'s gradient at `index`.
    GradAccum {
        array: VarId,
        index: Vec<VarId>,
        mode: AccumMode,
    },
    /// `if` in reverse: on `cond`, or (`None`) on the decision popped from the stack.
    RevIf {
        cond: Option<VarId>,
        then: Vec<AStmt>,
        els: Vec<AStmt>,
    },
    /// Pops a trip count and runs `body` that many times.
    RevLoop { body: Vec<AStmt> },

    // ---- Once, at the end ----
    /// Under `__FAST`, adds `__acc_<array>` into the gradient at the thread index.
    FlushGathered { array: VarId },
    /// Under `__FAST`, clears the gradient at the thread index (see [`TakeMode::GetWhenFast`]).
    ClearOwn { array: VarId },
    /// A func's `__adj_out<k>` (its caller's temporary for parameter `k`) `+= adj_var`.
    AccumOut { k: usize, var: VarId },
    /// A custom gradient: `__adj_out<k> += func(params.., __adj_ret)`.
    CustomGrad { k: usize, func: syn::Path },
}

/// Whether a value of this type carries a gradient (`Deferred`, unknown to the macro: yes; the
/// adjoint functions are no-ops for integer types).
fn differentiable(t: &Ty) -> bool {
    match t {
        Ty::Scalar(s) | Ty::Vector(s, _) => s.is_float(),
        Ty::Matrix(..) | Ty::Quat(_) => true,
        // Objects and query states: indices and buffers, no gradient.
        Ty::Array(..) | Ty::Object(_) | Ty::Unit => false,
        _ => true,
    }
}

/// A func's body without its final `return value` (its result, which the adjoint seeds with
/// the caller's adjoint), and that value; a kernel's whole body and `None`.
fn split_tail(f: &Function) -> (&[Stmt], Option<VarId>) {
    match f.body.last() {
        Some(Stmt {
            kind: StmtKind::Return { value },
            ..
        }) if f.kind == FnKind::Func => (&f.body[..f.body.len() - 1], *value),
        _ => (&f.body[..], None),
    }
}

/// The adjoint of `f` for a target with `policy`, or why there is none.
pub fn build(f: &Function, policy: Policy) -> Result<Adjoint, String> {
    if let Some(why) = crate::analysis::atomic_without_adjoint(f) {
        return Err(why);
    }
    let g = without_jumps(f);
    let tid = crate::analysis::tid_components(&g);
    let own = crate::analysis::tid_only_params(&g, &tid);
    let kernel = g.kind == FnKind::Kernel;
    let mut stored = Vec::new();
    let mut loaded = Vec::new();
    walk_stmts(&g.body, &mut |s| match &s.kind {
        StmtKind::Store { array, .. } => stored.push(*array),
        StmtKind::Assign { op, .. } => op.for_each_read(&mut |v| loaded.push(v)),
        _ => {}
    });
    // Read-only thread-owned arrays: every access is at the thread's own index, and no store
    // needs the gradient handed over in between.
    let gathered: Vec<VarId> = if kernel && policy.gather_read_only {
        own.iter()
            .copied()
            .filter(|a| !stored.contains(a))
            .collect()
    } else {
        Vec::new()
    };
    // Write-only thread-owned arrays: no read adds to the gradient a write hands over.
    let deferred_clear: Vec<VarId> = if kernel && policy.defer_write_only_clear {
        own.iter()
            .copied()
            .filter(|a| !loaded.contains(a))
            .collect()
    } else {
        Vec::new()
    };
    let (body, tail) = split_tail(&g);
    check(body)?;
    let cx = Cx {
        f: &g,
        tid,
        own,
        gathered: gathered.clone(),
        deferred_clear: deferred_clear.clone(),
        overwritten: overwritten_vars(&g),
    };
    let mut out = cx.forward(body, false);
    if let Some(v) = tail {
        // The func's result: its adjoint is what the caller passed.
        cx.accum(&mut out, v, None, GradSrc::AdjRet, Span::call_site());
    }
    out.extend(cx.reverse(body, false));
    let end = Span::call_site();
    for &array in &gathered {
        out.push(at(AKind::FlushGathered { array }, end));
    }
    for &array in &deferred_clear {
        out.push(at(AKind::ClearOwn { array }, end));
    }
    if !kernel {
        for (k, p) in g.params.iter().enumerate() {
            if cx.diff(p.var) {
                out.push(at(AKind::AccumOut { k, var: p.var }, end));
            }
        }
    }
    let uses_stack = !g.callees.is_empty() || pushes(&out);
    let decls = declarations(&g);
    let adjs = (0..g.vars.len()).filter(|v| cx.diff(*v)).collect();
    Ok(Adjoint {
        decls,
        adjs,
        gathered,
        body: out,
        uses_stack,
        f: g,
    })
}

/// The adjoint of a func with custom gradients `grads` (parameter, gradient func): each named
/// parameter's adjoint is what its gradient func returns for (params.., adjoint of the
/// result); the body is not differentiated.
pub fn custom(f: &Function, grads: &[(syn::Ident, syn::Path)]) -> Result<Adjoint, String> {
    let mut body = Vec::new();
    for (param, func) in grads {
        let k = f
            .params
            .iter()
            .position(|p| *param == p.name)
            .ok_or_else(|| format!("`{param}` is not a parameter of this func"))?;
        body.push(at(
            AKind::CustomGrad {
                k,
                func: func.clone(),
            },
            func_span(func),
        ));
    }
    Ok(Adjoint {
        f: f.clone(),
        decls: Vec::new(),
        adjs: Vec::new(),
        gathered: Vec::new(),
        body,
        uses_stack: !f.callees.is_empty(),
    })
}

fn func_span(p: &syn::Path) -> Span {
    syn::spanned::Spanned::span(p)
}

/// `f` as an adjoint's replay of a func runs it: without stores and prints (they are not
/// needed to recompute its result, and must not be redone). Atomics are not redone either: the
/// printers' replay mode writes zero for them, as for [`Value::Zero`].
pub fn replay_of(f: &Function) -> Function {
    fn strip(b: &Block) -> Block {
        b.iter()
            .filter(|s| !matches!(s.kind, StmtKind::Store { .. } | StmtKind::Print { .. }))
            .map(|s| Stmt {
                span: s.span,
                kind: match &s.kind {
                    StmtKind::If { cond, then, els } => StmtKind::If {
                        cond: *cond,
                        then: strip(then),
                        els: strip(els),
                    },
                    StmtKind::For { var, range, body } => StmtKind::For {
                        var: *var,
                        range: range.clone(),
                        body: strip(body),
                    },
                    StmtKind::Loop { body } => StmtKind::Loop { body: strip(body) },
                    k => k.clone(),
                },
            })
            .collect()
    }
    let mut g = f.clone();
    g.body = strip(&f.body);
    g
}

fn at(kind: AKind, span: Span) -> AStmt {
    AStmt { kind, span }
}

/// Pushes `var`'s value before the statement at `sp` overwrites it.
fn push(var: VarId, sp: Span) -> AStmt {
    let line = sp.start().line as u32;
    at(AKind::Push { var, line }, sp)
}

fn pop(var: VarId, sp: Span) -> AStmt {
    at(AKind::Pop { var }, sp)
}

/// Rejects what the reverse sweep does not handle.
fn check(b: &[Stmt]) -> Result<(), String> {
    for s in b {
        match &s.kind {
            StmtKind::Break | StmtKind::Continue | StmtKind::Return { .. } => {
                return Err("internal: a jump survived jump removal".into())
            }
            StmtKind::If { then, els, .. } => {
                check(then)?;
                check(els)?;
            }
            StmtKind::For { body, .. } | StmtKind::Loop { body } => check(body)?,
            _ => {}
        }
    }
    Ok(())
}

/// Variables that may be assigned more than once in one thread: `mut` ones and everything
/// assigned inside a loop (including loop variables). Their old values go on the stack.
fn overwritten_vars(f: &Function) -> Vec<bool> {
    let mut out: Vec<bool> = f.vars.iter().map(|v| v.mutable).collect();
    fn walk(b: &Block, in_loop: bool, out: &mut Vec<bool>) {
        for s in b {
            match &s.kind {
                StmtKind::Assign { dst, .. } if in_loop => out[*dst] = true,
                StmtKind::SetMember { var, .. } => out[*var] = true,
                StmtKind::If { then, els, .. } => {
                    walk(then, in_loop, out);
                    walk(els, in_loop, out);
                }
                StmtKind::For { var, body, .. } => {
                    out[*var] = true;
                    walk(body, true, out);
                }
                StmtKind::Loop { body } => walk(body, true, out),
                _ => {}
            }
        }
    }
    walk(&f.body, false, &mut out);
    out
}

/// What the replay stores for `op`.
fn replay_value(op: &Op) -> Value {
    match op {
        Op::Builtin { builtin, args } if builtin.is_atomic() => Value::Zero {
            like: args[args.len() - 1],
        },
        op => Value::Op(op.clone()),
    }
}

/// Every variable but the parameters and arrays, in the order of first definition (a loop
/// variable at its loop, after the bounds), with its definition; variables never assigned
/// first.
fn declarations(f: &Function) -> Vec<Decl> {
    let skip = |v: VarId| f.params.iter().any(|p| p.var == v) || matches!(f.ty(v), Ty::Array(..));
    let mut defined: Vec<Option<TypeOf>> = vec![None; f.vars.len()];
    let mut order = Vec::new();
    walk_stmts(&f.body, &mut |s| {
        let (v, def) = match &s.kind {
            StmtKind::Assign { dst, op, .. } => (*dst, TypeOf::Value(replay_value(op))),
            StmtKind::For { var, range, .. } => (*var, TypeOf::Var(range.end)),
            _ => return,
        };
        if defined[v].is_none() {
            defined[v] = Some(def);
            order.push(v);
        }
    });
    let never: Vec<VarId> = (0..f.vars.len())
        .filter(|v| defined[*v].is_none())
        .collect();
    never
        .into_iter()
        .chain(order)
        .filter(|v| !skip(*v))
        .map(|var| Decl {
            var,
            def: defined[var].take(),
        })
        .collect()
}

/// Whether the statements push anything.
fn pushes(b: &[AStmt]) -> bool {
    b.iter().any(|s| match &s.kind {
        AKind::Push { .. } | AKind::For { .. } | AKind::Loop { .. } => true,
        AKind::If {
            record, then, els, ..
        } => *record || pushes(then) || pushes(els),
        _ => false,
    })
}

struct Cx<'a> {
    f: &'a Function,
    tid: Vec<Option<u8>>,
    /// Array parameters accessed only at the thread index.
    own: Vec<VarId>,
    gathered: Vec<VarId>,
    deferred_clear: Vec<VarId>,
    overwritten: Vec<bool>,
}

impl Cx<'_> {
    /// Whether `v` has an adjoint variable.
    fn diff(&self, v: VarId) -> bool {
        differentiable(self.f.ty(v))
    }

    fn is_array(&self, v: VarId) -> bool {
        matches!(self.f.ty(v), Ty::Array(..))
    }

    /// `adj_v[.member] += from`, where `v` carries a gradient.
    fn accum(
        &self,
        out: &mut Vec<AStmt>,
        v: VarId,
        member: Option<String>,
        from: GradSrc,
        sp: Span,
    ) {
        if self.diff(v) {
            out.push(at(
                AKind::Accum {
                    var: v,
                    member,
                    from,
                },
                sp,
            ));
        }
    }

    /// The forward replay of `b`.
    fn forward(&self, b: &[Stmt], in_loop: bool) -> Vec<AStmt> {
        let mut out = Vec::new();
        for s in b {
            let sp = s.span;
            match &s.kind {
                StmtKind::Assign { dst, op, .. } => {
                    if self.overwritten[*dst] {
                        out.push(push(*dst, sp));
                    }
                    out.push(at(
                        AKind::Assign {
                            dst: *dst,
                            value: replay_value(op),
                        },
                        sp,
                    ));
                }
                StmtKind::SetMember { var, path, value } => {
                    out.push(push(*var, sp));
                    out.push(at(
                        AKind::SetMember {
                            var: *var,
                            path: path.clone(),
                            value: *value,
                        },
                        sp,
                    ));
                }
                StmtKind::If { cond, then, els } => out.push(at(
                    AKind::If {
                        cond: *cond,
                        then: self.forward(then, in_loop),
                        els: self.forward(els, in_loop),
                        record: self.records(*cond, in_loop),
                    },
                    sp,
                )),
                StmtKind::For { var, range, body } => {
                    let (exit, body) = split_exit(body);
                    // The variable's old value, then its value at this step.
                    let step = AKind::StepVar {
                        var: *var,
                        end: range.end,
                    };
                    let mut b = vec![push(*var, sp), at(step, sp)];
                    b.extend(self.forward(body, true));
                    out.push(at(
                        AKind::For {
                            range: range.clone(),
                            exit,
                            body: b,
                            line: sp.start().line as u32,
                        },
                        sp,
                    ));
                }
                StmtKind::Loop { body } => {
                    let (exit, body) = split_exit(body);
                    out.push(at(
                        AKind::Loop {
                            exit,
                            body: self.forward(body, true),
                            line: sp.start().line as u32,
                        },
                        sp,
                    ));
                }
                // Stores and prints are not redone; declarations are at the top; jumps were
                // removed (`check`).
                _ => {}
            }
        }
        out
    }

    /// Whether the decision of an `if` on `cond` is recorded: inside a loop (each iteration
    /// may decide differently) or when `cond` may have changed by the time the sweep reaches
    /// the `if`.
    fn records(&self, cond: VarId, in_loop: bool) -> bool {
        in_loop || self.overwritten[cond]
    }

    /// The reverse sweep of `b`.
    fn reverse(&self, b: &[Stmt], in_loop: bool) -> Vec<AStmt> {
        let mut out = Vec::new();
        for s in b.iter().rev() {
            let sp = s.span;
            match &s.kind {
                StmtKind::Assign { dst, op, .. } => self.reverse_assign(&mut out, *dst, op, sp),
                StmtKind::Store {
                    array,
                    index,
                    value,
                } => {
                    let mode =
                        if self.deferred_clear.contains(array) && self.tid_access(*array, index) {
                            TakeMode::GetWhenFast
                        } else {
                            TakeMode::Take
                        };
                    let from = GradSrc::Take {
                        array: *array,
                        index: index.clone(),
                        like: *value,
                        mode,
                    };
                    self.accum(&mut out, *value, None, from, sp);
                }
                StmtKind::SetMember { var, path, value } => {
                    let mut b = vec![at(
                        AKind::SeedMember {
                            var: *var,
                            path: path.clone(),
                        },
                        sp,
                    )];
                    self.accum(&mut b, *value, None, GradSrc::Seed, sp);
                    b.push(pop(*var, sp));
                    out.push(at(AKind::Scope(b), sp));
                }
                StmtKind::If { cond, then, els } => out.push(at(
                    AKind::RevIf {
                        cond: (!self.records(*cond, in_loop)).then_some(*cond),
                        then: self.reverse(then, in_loop),
                        els: self.reverse(els, in_loop),
                    },
                    sp,
                )),
                StmtKind::For { body, .. } | StmtKind::Loop { body } => {
                    let (_, body) = split_exit(body);
                    let mut b = self.reverse(body, true);
                    // A `for` restores its variable after each reversed iteration.
                    if let StmtKind::For { var, .. } = &s.kind {
                        b.push(pop(*var, sp));
                    }
                    out.push(at(AKind::RevLoop { body: b }, sp));
                }
                _ => {}
            }
        }
        out
    }

    /// Reverse of `dst = op`: take `dst`'s adjoint, restore `dst`'s old value, accumulate the
    /// operands' adjoints.
    fn reverse_assign(&self, out: &mut Vec<AStmt>, dst: VarId, op: &Op, sp: Span) {
        let restore = self.overwritten[dst].then(|| pop(dst, sp));
        if let Op::Func { path, args } = op {
            // The func's adjoint runs even when its result carries no gradient: it may have
            // read arrays.
            let seed = if self.diff(dst) {
                AKind::Seed { var: dst }
            } else {
                AKind::SeedZero { like: dst }
            };
            let mut b = vec![at(seed, sp)];
            b.extend(restore);
            let args: Vec<(VarId, FuncArgAdj)> = args
                .iter()
                .map(|a| {
                    let how = if self.is_array(*a) {
                        FuncArgAdj::ArrayGrad
                    } else {
                        FuncArgAdj::Temp
                    };
                    (*a, how)
                })
                .collect();
            b.push(at(
                AKind::FuncAdj {
                    path: path.clone(),
                    args: args.clone(),
                },
                sp,
            ));
            for (k, (a, how)) in args.iter().enumerate() {
                if *how == FuncArgAdj::Temp {
                    self.accum(&mut b, *a, None, GradSrc::Temp(k), sp);
                }
            }
            out.push(at(AKind::Scope(b), sp));
            return;
        }
        if !self.diff(dst) {
            out.extend(restore);
            return;
        }
        let acc = self.accumulate(op, sp);
        if acc.is_empty() {
            out.push(at(AKind::ClearAdj { var: dst }, sp));
            out.extend(restore);
            return;
        }
        let mut b = vec![at(AKind::Seed { var: dst }, sp)];
        b.extend(restore);
        b.extend(acc);
        out.push(at(AKind::Scope(b), sp));
    }

    fn tid_access(&self, array: VarId, index: &[VarId]) -> bool {
        crate::analysis::is_tid_access(self.f, &self.tid, array, index)
    }

    /// `adj_<func>(inputs.., __g.., __r)`, then each temporary into its input's adjoint.
    fn call(&self, out: &mut Vec<AStmt>, func: String, inputs: &[VarId], sp: Span) {
        self.call_faulting(out, func, inputs, false, sp)
    }

    /// [`Self::call`], of an adjoint that may fault (`faults`: see [`AKind::AdjCall`]).
    fn call_faulting(
        &self,
        out: &mut Vec<AStmt>,
        func: String,
        inputs: &[VarId],
        faults: bool,
        sp: Span,
    ) {
        out.push(at(
            AKind::AdjCall {
                func,
                inputs: inputs.to_vec(),
                faults,
            },
            sp,
        ));
        for (k, v) in inputs.iter().enumerate() {
            self.accum(out, *v, None, GradSrc::Temp(k), sp);
        }
    }

    /// Adds the seed (the adjoint of `op`'s result) into the adjoints of `op`'s operands.
    fn accumulate(&self, op: &Op, sp: Span) -> Vec<AStmt> {
        let mut out = Vec::new();
        match op {
            Op::Copy(a) => self.accum(&mut out, *a, None, GradSrc::Seed, sp),
            Op::Unary(UnOp::Neg, a) => self.call(&mut out, "adj_neg".into(), &[*a], sp),
            Op::Binary(o, a, b) => {
                if let Some(f) = o.adjoint_fn() {
                    self.call(&mut out, f.into(), &[*a, *b], sp);
                }
            }
            Op::Cast(a, _) => {
                if self.diff(*a) {
                    out.push(at(AKind::AdjCast { from: *a }, sp));
                    self.accum(&mut out, *a, None, GradSrc::Temp(0), sp);
                }
            }
            Op::Builtin { builtin, args } => match builtin.grad {
                // AtomicNone: only integer updates whose result is unused get here
                // (`analysis::atomic_without_adjoint`): nothing to propagate.
                Grad::Zero | Grad::AtomicNone | Grad::Effect => {}
                Grad::Adjoint => self.call_faulting(
                    &mut out,
                    format!("adj_{}", builtin.name),
                    args,
                    builtin.faults(),
                    sp,
                ),
                Grad::Atomic => {
                    // atomic_<op>(a, idx.., v): the value's adjoint comes from the gradient at idx.
                    let value = args[args.len() - 1];
                    if self.diff(value) {
                        let kind = match builtin.name {
                            "atomic_add" => AtomicKind::Add,
                            "atomic_sub" => AtomicKind::Sub,
                            _ => AtomicKind::Extreme,
                        };
                        out.push(at(
                            AKind::AtomicAdj {
                                kind,
                                array: args[0],
                                index: args[1..args.len() - 1].to_vec(),
                                value,
                            },
                            sp,
                        ));
                    }
                }
            },
            Op::Load { array, index } => {
                let tid_access = self.tid_access(*array, index);
                let mode = if self.gathered.contains(array) && tid_access {
                    AccumMode::GatherWhenFast
                } else if self.own.contains(array) && tid_access {
                    AccumMode::OwnWhenFast
                } else {
                    AccumMode::Atomic
                };
                out.push(at(
                    AKind::GradAccum {
                        array: *array,
                        index: index.clone(),
                        mode,
                    },
                    sp,
                ));
            }
            Op::Member(v, m) => self.accum(&mut out, *v, Some(m.clone()), GradSrc::Seed, sp),
            Op::Construct { ty, ctor, args } => {
                let lanes: &[&str] = match ty {
                    Ty::Vector(..) | Ty::Quat(_) => &["x", "y", "z", "w"],
                    Ty::Matrix(..) => &["x_axis", "y_axis", "z_axis", "w_axis"],
                    _ => &[],
                };
                match (ctor, ty) {
                    (Ctor::Components, _) => {
                        for (v, l) in args.iter().zip(lanes) {
                            self.accum(&mut out, *v, None, GradSrc::SeedLane(l.to_string()), sp);
                        }
                    }
                    // from_diagonal(v): the diagonal of the adjoint.
                    (Ctor::Splat, Ty::Matrix(_, n)) => {
                        let s = args[0];
                        if matches!(self.f.ty(s), Ty::Vector(..)) {
                            let comps = ["x", "y", "z", "w"];
                            let entries = (0..*n as usize)
                                .map(|k| (lanes[k].to_string(), comps[k].to_string()))
                                .collect();
                            let vector = self.f.ty(s).clone();
                            self.accum(
                                &mut out,
                                s,
                                None,
                                GradSrc::Diagonal { vector, entries },
                                sp,
                            );
                        }
                    }
                    // splat(s): the sum of the adjoint's lanes.
                    (Ctor::Splat, Ty::Vector(_, n)) => {
                        let sum = lanes[..*n as usize].iter().map(|l| l.to_string()).collect();
                        self.accum(&mut out, args[0], None, GradSrc::LaneSum(sum), sp);
                    }
                    _ => {}
                }
            }
            Op::Lit(_)
            | Op::LitLike(..)
            | Op::Unary(UnOp::Not, _)
            | Op::Tid(_)
            | Op::Extent(..)
            | Op::Len(_)
            | Op::ViewCheck { .. }
            | Op::Const(_)
            | Op::Func { .. } => {}
        }
        out
    }
}

/// A loop body's leading exit check (its flags) and the rest of the body.
fn split_exit(body: &[Stmt]) -> (Vec<VarId>, &[Stmt]) {
    match body.first() {
        Some(Stmt {
            kind: StmtKind::ExitIf { flags },
            ..
        }) => (flags.clone(), &body[1..]),
        _ => (Vec::new(), body),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use syn::parse_quote;

    fn kernel(item: syn::ItemFn) -> Function {
        crate::front::lower::lower_fn(&item, FnKind::Kernel).unwrap()
    }

    fn name(f: &Function, v: VarId) -> String {
        f.vars[v].name.clone().unwrap_or_else(|| format!("t{v}"))
    }

    /// Every statement, depth first.
    fn all(b: &[AStmt]) -> Vec<&AStmt> {
        let mut out = Vec::new();
        for s in b {
            out.push(s);
            match &s.kind {
                AKind::If { then, els, .. } | AKind::RevIf { then, els, .. } => {
                    out.extend(all(then));
                    out.extend(all(els));
                }
                AKind::For { body, .. }
                | AKind::Loop { body, .. }
                | AKind::RevLoop { body }
                | AKind::Scope(body) => out.extend(all(body)),
                _ => {}
            }
        }
        out
    }

    #[test]
    fn thread_owned_arrays_follow_the_policy() {
        let f = kernel(parse_quote! {
            fn k(x: Array<f32>, y: Array<f32>, z: Array<f32>, j: i32) {
                let i = tid();
                y[i] = x[i] * z[j];
            }
        });
        let modes = |p: Policy| {
            let a = build(&f, p).unwrap();
            let mut accum = Vec::new();
            let mut take = Vec::new();
            let mut end = Vec::new();
            for s in all(&a.body) {
                match &s.kind {
                    AKind::GradAccum { array, mode, .. } => accum.push((name(&a.f, *array), *mode)),
                    AKind::Accum {
                        from: GradSrc::Take { array, mode, .. },
                        ..
                    } => take.push((name(&a.f, *array), *mode)),
                    AKind::FlushGathered { array } => {
                        end.push(format!("flush {}", name(&a.f, *array)))
                    }
                    AKind::ClearOwn { array } => end.push(format!("clear {}", name(&a.f, *array))),
                    _ => {}
                }
            }
            accum.sort_by(|a, b| a.0.cmp(&b.0));
            (accum, take, end, a.gathered.len())
        };
        // z is read at another index: atomic on every target.
        let (accum, take, end, gathered) = modes(Policy::CPU);
        assert_eq!(
            accum,
            vec![
                ("x".into(), AccumMode::OwnWhenFast),
                ("z".into(), AccumMode::Atomic)
            ]
        );
        assert_eq!(take, vec![("y".into(), TakeMode::Take)]);
        assert!(end.is_empty() && gathered == 0);
        let (accum, take, end, gathered) = modes(Policy::CUDA);
        assert_eq!(
            accum,
            vec![
                ("x".into(), AccumMode::GatherWhenFast),
                ("z".into(), AccumMode::Atomic)
            ]
        );
        assert_eq!(take, vec![("y".into(), TakeMode::GetWhenFast)]);
        assert_eq!(end, vec!["flush x", "clear y"]);
        assert_eq!(gathered, 1);
    }

    #[test]
    fn loops_push_restore_and_record() {
        let f = kernel(parse_quote! {
            fn k(x: Array<f64>, out: Array<f64>) {
                let mut p: f64 = 1.0;
                for i in 0..N {
                    for j in 0..i {
                        if x[j] > 0.0 { p = p * x[j]; }
                    }
                }
                out[0] = p;
            }
        });
        let a = build(&f, Policy::CPU).unwrap();
        assert!(a.uses_stack);
        // The loop variables have the type of their bounds (the const's, for the outer one),
        // and are declared after them.
        let pos = |n: &str| a.decls.iter().position(|d| name(&a.f, d.var) == n).unwrap();
        for (var, end) in [("i", None), ("j", Some("i"))] {
            let d = &a.decls[pos(var)];
            let Some(TypeOf::Var(e)) = &d.def else {
                panic!("{var}: {:?}", d.def)
            };
            if let Some(end) = end {
                assert_eq!(name(&a.f, *e), end);
            }
            assert!(a
                .decls
                .iter()
                .position(|d| d.var == *e)
                .is_none_or(|k| k < pos(var)));
        }
        // Each reversed `for` iteration ends by restoring its variable; the `if` inside the
        // loops pops its recorded decision.
        let stmts = all(&a.body);
        let rev_loops: Vec<&Vec<AStmt>> = stmts
            .iter()
            .filter_map(|s| match &s.kind {
                AKind::RevLoop { body } => Some(body),
                _ => None,
            })
            .collect();
        assert_eq!(rev_loops.len(), 2);
        for b in rev_loops {
            assert!(matches!(b.last().map(|s| &s.kind), Some(AKind::Pop { .. })));
        }
        assert!(stmts
            .iter()
            .any(|s| matches!(&s.kind, AKind::If { record: true, .. })));
        assert!(stmts
            .iter()
            .any(|s| matches!(&s.kind, AKind::RevIf { cond: None, .. })));
    }

    #[test]
    fn atomics_replay_as_zero() {
        let f = kernel(parse_quote! {
            fn k(x: Array<f32>, sum: Array<f32>) {
                let i = tid();
                atomic_sub(sum, 0, x[i] * 2.0);
            }
        });
        let a = build(&f, Policy::CUDA).unwrap();
        let stmts = all(&a.body);
        assert!(stmts.iter().any(|s| matches!(
            &s.kind,
            AKind::Assign {
                value: Value::Zero { .. },
                ..
            }
        )));
        assert!(stmts.iter().any(|s| matches!(
            &s.kind,
            AKind::AtomicAdj {
                kind: AtomicKind::Sub,
                ..
            }
        )));
        // Nothing is pushed: a kernel without loops or calls needs no stack.
        assert!(!a.uses_stack);
    }
}

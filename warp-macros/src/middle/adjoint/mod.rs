//! Reverse mode as one middle-end pass: a lowered kernel or func to its *adjoint IR*
//! ([`ir`]), which `back/rust_adjoint.rs` (CPU) and `back/cuda_adjoint.rs` (CUDA C++) print
//! statement by statement. Every decision of the scheme is made here, once for both targets:
//! what the replay runs, what is pushed on the adjoint stack and when, which branch decisions
//! and trip counts are recorded, how each statement's adjoint flows into its operands', which
//! temporaries hold what, and which gradient updates are atomic.
//!
//! The scheme is Warp's, with loops made right:
//! 1. a *forward replay* ([`replay`]) runs the body again without its stores, prints and
//!    atomics (an atomic's effect happened in the forward launch: its result is replaced by
//!    zero, and `analysis::atomic_without_adjoint` refuses kernels that read it). Before a
//!    statement overwrites a value the reverse sweep will need (a `mut` variable, anything
//!    assigned inside a loop, a loop's own variable), the old value is pushed on the thread's
//!    adjoint stack; after an `if` inside a loop (or on a condition that changes) the branch
//!    taken is pushed, after a loop its trip count;
//! 2. the *reverse sweep* ([`sweep`]) walks the statements backwards. For `d = op(a, b)` it
//!    takes `d`'s adjoint (the *seed*, `__r`), zeroes it, pops `d`'s old value where one was
//!    pushed, and accumulates into the adjoints of `a` and `b` through the library's
//!    `adj_<op>` (into fresh temporaries `__g<k>` first: an operand may appear twice, `x * x`).
//!    The invariant: when the sweep reaches a statement, every variable holds the value it had
//!    just after that statement ran.
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
//! target picks how to exploit that.
//!
//! Variables: every variable the sweep uses is declared once at the top of the adjoint (the
//! sweep needs values from every block), with the [`TypeOf`] its type can be spelt from where
//! the IR type is not enough (a user func's result, a const, a struct field, a loop over such
//! a bound): declarations come in the order of first definition, so a printer may declare a
//! variable with the type of its defining expression over variables declared before it.

mod ir;
mod replay;
mod sweep;
#[cfg(test)]
mod tests;

pub use ir::*;
pub use replay::replay_of;

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
    /// A read-only thread-owned array's gradient is gathered in a register and added once at
    /// the end of the thread.
    pub gather_read_only: bool,
    /// A write-only thread-owned array's gradient is read where a write is reversed and
    /// cleared once at the end of the thread.
    pub defer_write_only_clear: bool,
}

impl Policy {
    /// The CPU: gradients of thread-owned arrays accumulate in place.
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

/// The gradient parameters of `f`'s adjoint, in the order of the parameters: each array's
/// gradient, and for a func each value parameter's `__adj_out<k>`.
fn grad_params(f: &Function) -> Vec<GradParam> {
    let func = f.kind == FnKind::Func;
    let each = f.params.iter().enumerate().filter_map(|(k, p)| match p.ty {
        Ty::Array(..) => Some(GradParam::Array(p.var)),
        _ => func.then_some(GradParam::Out { k, var: p.var }),
    });
    each.collect()
}

/// The adjoint of `f` for a target with `policy`, or why there is none.
/// Why a tiled kernel has no adjoint (nor tangent) yet.
pub const TILE_ADJOINT: &str =
    "uses tiles, and backward through tile operations is not supported yet";

pub fn build(f: &Function, policy: Policy) -> Result<Adjoint, String> {
    // A builtin with no adjoint yet: refused by name (before the tiles' general reason, which
    // will go once tile adjoints exist, while these rows still have none).
    let mut not_yet = None;
    walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Assign {
            op: Op::Builtin { builtin, .. },
            ..
        } = &s.kind
        {
            if builtin.grad == Grad::NotYet && not_yet.is_none() {
                not_yet = Some(builtin.name);
            }
        }
    });
    if let Some(name) = not_yet {
        return Err(format!(
            "calls `{name}`, which has no adjoint yet (Warp differentiates it; warp-lang does not yet)"
        ));
    }
    // Tile operations have no adjoints yet; the sweep's arms for them are never reached.
    if f.tiled.is_some() {
        return Err(TILE_ADJOINT.into());
    }
    if let Some(why) = crate::analysis::atomic_without_adjoint(f) {
        return Err(why);
    }
    let mut g = without_jumps(f);
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
    let gathered = |a: &VarId| kernel && policy.gather_read_only && !stored.contains(a);
    let gathered: Vec<VarId> = own.iter().copied().filter(gathered).collect();
    // Write-only thread-owned arrays: no read adds to the gradient a write hands over.
    let deferred = |a: &VarId| kernel && policy.defer_write_only_clear && !loaded.contains(a);
    let deferred_clear: Vec<VarId> = own.iter().copied().filter(deferred).collect();
    let (body, tail) = split_tail(&g);
    replay::check(body)?;
    let mut cx = Cx {
        f: &g,
        tid,
        own,
        registers: Vec::new(),
        deferred_clear: deferred_clear.clone(),
        overwritten: replay::overwritten_vars(&g),
        fresh: Vec::new(),
        error: None,
    };
    // A gathered array's register is the adjoint of a variable of the pass, of its element
    // type, that stands for the thread's element.
    for &array in &gathered {
        if let Ty::Array(elem, _) = g.ty(array) {
            let reg = cx.fresh((**elem).clone(), None);
            cx.registers.push((array, reg));
        }
    }
    let mut out = cx.forward(body, false);
    let end = Span::call_site();
    if let Some(v) = tail {
        // The func's result: its adjoint is what the caller passed.
        cx.accum(&mut out, v, Vec::new(), GradSrc::AdjRet, end);
    }
    out.extend(cx.reverse(body, false));
    // Once at the end of the thread, under `__FAST`: the registers go to the elements the
    // thread owns, and the gradients its deferred writes read are cleared.
    let fast = |then: AKind| at(if_fast(vec![at(then, end)], Vec::new()), end);
    for &(array, reg) in &cx.registers {
        let (index, own) = (cx.thread_index(array)?, true);
        if cx.diff(reg) {
            let from = GradSrc::Adj {
                var: reg,
                path: vec![],
            };
            let accum = AKind::GradAccum {
                array,
                index,
                from,
                own,
            };
            out.push(fast(accum));
        }
    }
    for &array in &deferred_clear {
        let index = cx.thread_index(array)?;
        out.push(fast(AKind::GradClearOwn { array, index }));
    }
    let grad_params = grad_params(&g);
    for gp in &grad_params {
        if let GradParam::Out { k, var } = *gp {
            if cx.diff(var) {
                let (to, from) = (AdjOf::Out(k), GradSrc::Adj { var, path: vec![] });
                out.push(at(AKind::Accum { to, from }, end));
            }
        }
    }
    if let Some(why) = cx.error.take() {
        return Err(why);
    }
    let regs = cx.registers.iter().map(|r| r.1);
    let adjs = (0..g.vars.len())
        .chain(regs)
        .filter(|v| cx.diff(*v))
        .collect();
    let fresh = std::mem::take(&mut cx.fresh);
    let mut decls = replay::declarations(&g);
    for (var, def) in fresh {
        decls.push(Decl {
            var: g.vars.len(),
            def,
        });
        g.vars.push(var);
    }
    Ok(Adjoint {
        decls,
        adjs,
        grad_params,
        uses_stack: !g.callees.is_empty() || replay::pushes(&out),
        body: out,
        f: g,
    })
}

/// The adjoint of a func with custom gradients `grads` (parameter, gradient func): each named
/// parameter's adjoint is what its gradient func returns for (params.., adjoint of the
/// result); the body is not differentiated.
pub fn custom(f: &Function, grads: &[(syn::Ident, syn::Path)]) -> Result<Adjoint, String> {
    let mut g = f.clone();
    let mut body = Vec::new();
    let args: Vec<VarId> = f.params.iter().map(|p| p.var).collect();
    for (param, func) in grads {
        let k = f
            .params
            .iter()
            .position(|p| *param == p.name)
            .ok_or_else(|| format!("`{param}` is not a parameter of this func"))?;
        if !g.callees.contains(func) {
            g.callees.push(func.clone());
        }
        let callee = g.callees.iter().position(|p| p == func);
        let from = GradSrc::Custom {
            func: callee.ok_or("internal: a gradient func missing from the callees")?,
            args: args.clone(),
        };
        let sp = syn::spanned::Spanned::span(func);
        body.push(at(
            AKind::Accum {
                to: AdjOf::Out(k),
                from,
            },
            sp,
        ));
    }
    Ok(Adjoint {
        f: g,
        decls: Vec::new(),
        adjs: Vec::new(),
        grad_params: grad_params(f),
        body,
        // The gradient funcs run forward; the body's callees are the ones whose adjoints push.
        uses_stack: !f.callees.is_empty(),
    })
}

/// `if __FAST { then } else { els }`.
fn if_fast(then: Vec<AStmt>, els: Vec<AStmt>) -> AKind {
    let cond = Cond::Fast;
    AKind::If { cond, then, els }
}

fn at(kind: AKind, span: Span) -> AStmt {
    AStmt { kind, span }
}

/// The user's line at `sp`, which a push names in the overflow fault.
fn line(sp: Span) -> u32 {
    sp.start().line as u32
}

/// Pushes `var`'s value before the statement at `sp` overwrites it.
fn push(var: VarId, sp: Span) -> AStmt {
    at(
        AKind::Push {
            var,
            line: line(sp),
        },
        sp,
    )
}

fn pop(var: VarId, sp: Span) -> AStmt {
    at(AKind::Pop { var }, sp)
}

/// The state of one [`build`].
struct Cx<'a> {
    f: &'a Function,
    tid: Vec<Option<u8>>,
    /// Array parameters accessed only at the thread index.
    own: Vec<VarId>,
    /// Each gathered array (`Policy::gather_read_only`) and the variable whose adjoint is its
    /// register.
    registers: Vec<(VarId, VarId)>,
    deferred_clear: Vec<VarId>,
    overwritten: Vec<bool>,
    /// Variables the pass adds (numbered after `f`'s), with the definitions of their types.
    fresh: Vec<(Var, Option<TypeOf>)>,
    /// Why the adjoint cannot be built, found on the way.
    error: Option<String>,
}

impl Cx<'_> {
    /// Whether `v` has an adjoint variable.
    fn diff(&self, v: VarId) -> bool {
        let n = self.f.vars.len();
        differentiable(match self.fresh.get(v.wrapping_sub(n)) {
            Some((var, _)) if v >= n => &var.ty,
            _ => self.f.ty(v),
        })
    }

    fn is_array(&self, v: VarId) -> bool {
        matches!(self.f.ty(v), Ty::Array(..))
    }

    /// A new variable of type `ty`, declared with the rest (`def`: its first definition).
    fn fresh(&mut self, ty: Ty, def: Option<TypeOf>) -> VarId {
        let id = self.f.vars.len() + self.fresh.len();
        let var = Var {
            name: None,
            ty,
            mutable: true,
        };
        self.fresh.push((var, def));
        id
    }

    /// The index of user func `path` in the callees.
    fn callee(&mut self, path: &syn::Path) -> Callee {
        let k = self.f.callees.iter().position(|p| p == path);
        if k.is_none() {
            self.error = Some("internal: a called func missing from the callees".into());
        }
        k.unwrap_or(0)
    }

    /// The index of the element of `array` the thread owns.
    fn thread_index(&self, array: VarId) -> Result<Index, String> {
        match self.f.ty(array) {
            Ty::Array(_, n) => Ok(Index::Thread(*n)),
            _ => Err("internal: a thread-owned array that is no array".into()),
        }
    }

    /// `adj_v.path += from`, where `v` carries a gradient.
    fn accum(&self, out: &mut Vec<AStmt>, v: VarId, path: Vec<String>, from: GradSrc, sp: Span) {
        if self.diff(v) {
            let to = AdjOf::Var { var: v, path };
            out.push(at(AKind::Accum { to, from }, sp));
        }
    }
}

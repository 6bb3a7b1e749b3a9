//! The forward replay: the body run again before the reverse sweep, without its effects, with
//! the pushes the sweep will pop. Also what the sweep needs to know about the body (which
//! variables are overwritten, what is declared).

use super::{at, line, push, AKind, AStmt, Cond, Cx, Decl, TypeOf, Value};
use crate::ir::*;
use crate::types::{Ty, BOOL};

impl Cx<'_> {
    /// The forward replay of `b`.
    pub(super) fn forward(&mut self, b: &[Stmt], in_loop: bool) -> Vec<AStmt> {
        let mut out = Vec::new();
        for s in b {
            let sp = s.span;
            match &s.kind {
                // A tile store, like any store, is not redone; nor is a tile atomic (the
                // forward launch did it), whose tile of old values nothing reads
                // (`analysis::atomic_without_adjoint` refuses a kernel that does): it keeps
                // its declaration's zeros.
                StmtKind::Assign {
                    op: Op::Builtin { builtin, .. },
                    ..
                } if builtin.name == "tile_store" || (builtin.is_tile() && builtin.is_atomic()) => {
                }
                StmtKind::Assign { dst, op, .. } => {
                    if self.overwritten[*dst] {
                        out.push(push(*dst, sp));
                    }
                    let value = replay_value(op);
                    out.push(at(AKind::Assign { dst: *dst, value }, sp));
                }
                StmtKind::SetMember { var, path, value } => {
                    out.push(push(*var, sp));
                    let (var, path, value) = (*var, path.clone(), *value);
                    out.push(at(AKind::SetMember { var, path, value }, sp));
                }
                // An element store overwrites the whole array (a value): its old value is
                // pushed, as any overwritten variable's.
                StmtKind::SetElem { var, index, value } => {
                    out.push(push(*var, sp));
                    let (var, index, value) = (*var, *index, *value);
                    out.push(at(AKind::SetElem { var, index, value }, sp));
                }
                StmtKind::If { cond, then, els } => {
                    let (then, els) = (self.forward(then, in_loop), self.forward(els, in_loop));
                    if !self.records(*cond, in_loop) {
                        let cond = Cond::Var(*cond);
                        out.push(at(AKind::If { cond, then, els }, sp));
                        continue;
                    }
                    // The decision, taken before the branches may change `cond`, is pushed
                    // after both (after their own pushes, so that the sweep pops it first).
                    let copy = Value::Op(Op::Copy(*cond));
                    let c = self.fresh(BOOL, Some(TypeOf::Value(copy.clone())));
                    out.push(at(
                        AKind::Assign {
                            dst: c,
                            value: copy,
                        },
                        sp,
                    ));
                    let cond = Cond::Var(c);
                    out.push(at(AKind::If { cond, then, els }, sp));
                    out.push(at(
                        AKind::Push {
                            var: c,
                            line: line(sp),
                        },
                        sp,
                    ));
                }
                StmtKind::For { var, range, body } => {
                    let (exit, body) = split_exit(body);
                    // The variable's old value, then its value at this step.
                    let (var, end) = (*var, range.end);
                    let mut b = vec![push(var, sp), at(AKind::StepVar { var, end }, sp)];
                    b.extend(self.forward(body, true));
                    let (range, line) = (Some(range.clone()), line(sp));
                    out.push(at(
                        AKind::Loop {
                            range,
                            exit,
                            body: b,
                            line,
                        },
                        sp,
                    ));
                }
                StmtKind::Loop { body } => {
                    let (exit, body) = split_exit(body);
                    let (range, body, line) = (None, self.forward(body, true), line(sp));
                    out.push(at(
                        AKind::Loop {
                            range,
                            exit,
                            body,
                            line,
                        },
                        sp,
                    ));
                }
                // Stores, prints and assertions are not redone (the forward launch checked
                // the assertions); declarations are at the top; jumps were removed (`check`).
                _ => {}
            }
        }
        out
    }

    /// Whether the decision of an `if` on `cond` is recorded: inside a loop (each iteration
    /// may decide differently) or when `cond` may have changed by the time the sweep reaches
    /// the `if`.
    pub(super) fn records(&self, cond: VarId, in_loop: bool) -> bool {
        in_loop || self.overwritten[cond]
    }
}

/// `f` as an adjoint's replay of a func runs it: without stores, prints and assertions (they
/// are not needed to recompute its result, and must not be redone: the forward launch checked
/// the assertions). Atomics are not redone either: the
/// printers' replay mode writes zero for them, as for [`Value::Zero`].
pub fn replay_of(f: &Function) -> Function {
    fn strip(b: &Block) -> Block {
        b.iter()
            .filter(|s| {
                !matches!(
                    s.kind,
                    StmtKind::Store { .. } | StmtKind::Print { .. } | StmtKind::Assert { .. }
                )
            })
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

/// Rejects what the reverse sweep does not handle.
pub(super) fn check(b: &[Stmt]) -> Result<(), String> {
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
pub(super) fn overwritten_vars(f: &Function) -> Vec<bool> {
    let mut out: Vec<bool> = f.vars.iter().map(|v| v.mutable).collect();
    fn walk(b: &Block, in_loop: bool, out: &mut Vec<bool>) {
        for s in b {
            match &s.kind {
                StmtKind::Assign { dst, .. } if in_loop => out[*dst] = true,
                StmtKind::SetMember { var, .. } | StmtKind::SetElem { var, .. } => out[*var] = true,
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
    for (v, inv) in invariant_vars(f).into_iter().enumerate() {
        out[v] &= !inv;
    }
    out
}

/// Variables that hold the same value whenever they are assigned: assigned once, not `mut`,
/// by an operation without side effects or memory reads whose operands are parameters never
/// reassigned or such variables themselves (`let off = i * 16;`, a const, in a loop). Restoring one would
/// restore what it already holds, so its history is not pushed: a k-loop's index arithmetic
/// costs no stack.
fn invariant_vars(f: &Function) -> Vec<bool> {
    let n = f.vars.len();
    let mut assigned = vec![0usize; n];
    let mut defs: Vec<Option<&Op>> = vec![None; n];
    walk_stmts(&f.body, &mut |s| match &s.kind {
        StmtKind::Assign { dst, op, .. } => {
            assigned[*dst] += 1;
            defs[*dst] = Some(op);
        }
        StmtKind::For { var, .. }
        | StmtKind::SetMember { var, .. }
        | StmtKind::SetElem { var, .. } => assigned[*var] += 2,
        _ => {}
    });
    let param = |v: VarId| f.params.iter().any(|p| p.var == v);
    let mut inv = vec![false; n];
    // Operands come before their uses, so a pass per nesting level settles it; iterate to a
    // fixed point for safety.
    loop {
        let mut changed = false;
        for v in 0..n {
            if inv[v] || assigned[v] != 1 || f.vars[v].mutable || param(v) {
                continue;
            }
            let pure = matches!(
                defs[v],
                Some(
                    Op::Lit(_)
                        | Op::LitLike(..)
                        | Op::ZeroLike(_)
                        | Op::Const(_)
                        | Op::Copy(_)
                        | Op::Unary(..)
                        | Op::Binary(..)
                        | Op::Cast(..)
                        | Op::Member(..)
                        | Op::Index { .. }
                        | Op::Construct { .. }
                        | Op::Tid(_)
                        | Op::Lane
                        | Op::DebugMode
                        | Op::Extent(..)
                        | Op::Len(_)
                )
            );
            if !pure {
                continue;
            }
            let mut ok = true;
            if let Some(op) = defs[v] {
                op.for_each_read(&mut |a| ok &= inv[a] || (param(a) && assigned[a] == 0));
            }
            if ok {
                inv[v] = true;
                changed = true;
            }
        }
        if !changed {
            return inv;
        }
    }
}

/// What the replay stores for `op`.
fn replay_value(op: &Op) -> Value {
    match op {
        // A tile atomic's result is a tile like its value operand, `(array, tile, offsets..)`.
        Op::Builtin { builtin, args } if builtin.is_atomic() && builtin.is_tile() => {
            Value::Zero { like: args[1] }
        }
        Op::Builtin { builtin, args } if builtin.is_atomic() => Value::Zero {
            like: args[args.len() - 1],
        },
        op => Value::Op(op.clone()),
    }
}

/// Every variable but the parameters and arrays, in the order of first definition (a loop
/// variable at its loop, after the bounds), with its definition; variables never assigned
/// first.
pub(super) fn declarations(f: &Function) -> Vec<Decl> {
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
pub(super) fn pushes(b: &[AStmt]) -> bool {
    b.iter().any(|s| match &s.kind {
        AKind::Push { .. } | AKind::Loop { .. } => true,
        AKind::If { then, els, .. } => pushes(then) || pushes(els),
        AKind::Scope(b) => pushes(b),
        _ => false,
    })
}

/// A loop body's leading exit check (its flags) and the rest of the body.
pub(super) fn split_exit(body: &[Stmt]) -> (Vec<VarId>, &[Stmt]) {
    match body.first() {
        Some(Stmt {
            kind: StmtKind::ExitIf { flags },
            ..
        }) => (flags.clone(), &body[1..]),
        _ => (Vec::new(), body),
    }
}

//! Prepares a function for the adjoint transform: jumps become flags.
//!
//! The reverse sweep needs, for every loop iteration, to know which statements ran. Structured
//! code without jumps tells it through `if` decisions alone, so `break`, `continue` and early
//! `return` are rewritten:
//! - a jump sets a flag (`__brk`/`__cont` of its loop, `__ret` of the function; a `return v`
//!   of a func also stores `v` in `__retval`);
//! - the statements after one that may have jumped run under `if !(flags) { .. }`;
//! - a loop whose body may jump starts each iteration with `ExitIf { flags }` (leave when a
//!   `break` or `return` flag is set) and clears its `continue` flag.
//!
//! The result computes exactly what the original does; it is the input of the adjoint pass
//! (`middle::adjoint`), never of the forward emitters.

use crate::ir::*;
use crate::types::{Ty, BOOL};

/// `f` with its jumps turned into flags (a copy; `f` itself is untouched).
pub fn without_jumps(f: &Function) -> Function {
    let mut g = f.clone();
    let (body, tail) = match g.body.last() {
        Some(Stmt {
            kind: StmtKind::Return { .. },
            ..
        }) if g.kind == FnKind::Func => {
            let mut b = g.body.clone();
            let t = b.pop();
            (b, t)
        }
        _ => (g.body.clone(), None),
    };
    let has_return = contains(&body, &|s| matches!(s, StmtKind::Return { .. }), true);
    let mut cx = Cx {
        g: &mut g,
        ret: None,
        retval: None,
    };
    if has_return {
        cx.ret = Some(cx.flag("__ret"));
        if !matches!(f.ret, Ty::Unit) && f.kind == FnKind::Func {
            let v = cx.g.vars.len();
            cx.g.vars.push(Var {
                name: Some("__retval".into()),
                ty: f.ret.clone(),
                mutable: true,
            });
            cx.retval = Some(v);
        }
    }
    let span = tail
        .as_ref()
        .map(|t| t.span)
        .unwrap_or_else(proc_macro2::Span::call_site);
    let mut out = Vec::new();
    if let Some(r) = cx.ret {
        out.push(cx.set(r, false, span));
    }
    out.extend(cx.block(&body, None));
    if let Some(t) = tail {
        match (cx.retval, &t.kind, cx.ret) {
            (Some(rv), StmtKind::Return { value: Some(v) }, Some(r)) => {
                // The tail value only when no early return set the result.
                let not_ret = cx.not_any(&[r], span, &mut out);
                let copy = Stmt {
                    kind: StmtKind::Assign {
                        dst: rv,
                        op: Op::Copy(*v),
                        define: false,
                    },
                    span,
                };
                out.push(Stmt {
                    kind: StmtKind::If {
                        cond: not_ret,
                        then: vec![copy],
                        els: vec![],
                    },
                    span,
                });
                out.push(Stmt {
                    kind: StmtKind::Return { value: Some(rv) },
                    span: t.span,
                });
            }
            _ => out.push(t),
        }
    }
    g.body = out;
    g
}

/// Whether `b` holds a statement satisfying `p`, not counting nested loops unless `deep`.
fn contains(b: &[Stmt], p: &dyn Fn(&StmtKind) -> bool, deep: bool) -> bool {
    b.iter().any(|s| {
        p(&s.kind)
            || match &s.kind {
                StmtKind::If { then, els, .. } => contains(then, p, deep) || contains(els, p, deep),
                StmtKind::For { body, .. } | StmtKind::Loop { body } => {
                    deep && contains(body, p, deep)
                }
                _ => false,
            }
    })
}

struct Cx<'a> {
    g: &'a mut Function,
    ret: Option<VarId>,
    retval: Option<VarId>,
}

/// The flags of the loop a statement is in: (break, continue).
type LoopFlags = Option<(VarId, VarId)>;

impl Cx<'_> {
    fn flag(&mut self, name: &str) -> VarId {
        self.g.vars.push(Var {
            name: Some(name.into()),
            ty: BOOL,
            mutable: true,
        });
        self.g.vars.len() - 1
    }

    fn temp(&mut self) -> VarId {
        self.g.vars.push(Var {
            name: None,
            ty: BOOL,
            mutable: false,
        });
        self.g.vars.len() - 1
    }

    fn set(&self, v: VarId, b: bool, span: proc_macro2::Span) -> Stmt {
        Stmt {
            kind: StmtKind::Assign {
                dst: v,
                op: Op::Lit(Lit::Bool(b)),
                define: false,
            },
            span,
        }
    }

    /// Appends statements computing `!(f0 || f1 || ..)` and returns its variable.
    fn not_any(&mut self, flags: &[VarId], span: proc_macro2::Span, out: &mut Vec<Stmt>) -> VarId {
        let mut acc = flags[0];
        for &f in &flags[1..] {
            let t = self.temp();
            out.push(Stmt {
                kind: StmtKind::Assign {
                    dst: t,
                    op: Op::Binary(BinOp::BitOr, acc, f),
                    define: true,
                },
                span,
            });
            acc = t;
        }
        let n = self.temp();
        out.push(Stmt {
            kind: StmtKind::Assign {
                dst: n,
                op: Op::Unary(UnOp::Not, acc),
                define: true,
            },
            span,
        });
        n
    }

    /// Whether `s` may jump out of the block it is in (to its loop, or out of the function).
    fn may_jump(&self, s: &StmtKind) -> bool {
        let jump = |k: &StmtKind| matches!(k, StmtKind::Break | StmtKind::Continue);
        jump(s)
            || matches!(s, StmtKind::Return { .. })
            || match s {
                StmtKind::If { then, els, .. } => {
                    contains(then, &jump, false)
                        || contains(els, &jump, false)
                        || contains(then, &|k| matches!(k, StmtKind::Return { .. }), true)
                        || contains(els, &|k| matches!(k, StmtKind::Return { .. }), true)
                }
                StmtKind::For { body, .. } | StmtKind::Loop { body } => {
                    contains(body, &|k| matches!(k, StmtKind::Return { .. }), true)
                }
                _ => false,
            }
    }

    fn block(&mut self, b: &[Stmt], lf: LoopFlags) -> Vec<Stmt> {
        let mut out = Vec::new();
        for (k, s) in b.iter().enumerate() {
            let jumps = self.may_jump(&s.kind);
            out.extend(self.stmt(s, lf));
            let rest = &b[k + 1..];
            if jumps && !rest.is_empty() {
                let mut flags: Vec<VarId> = Vec::new();
                if let Some((brk, cont)) = lf {
                    flags.extend([brk, cont]);
                }
                flags.extend(self.ret);
                let rest = self.block(rest, lf);
                if flags.is_empty() || rest.is_empty() {
                    out.extend(rest);
                    break;
                }
                let span = b[k + 1].span;
                let cond = self.not_any(&flags, span, &mut out);
                out.push(Stmt {
                    kind: StmtKind::If {
                        cond,
                        then: rest,
                        els: vec![],
                    },
                    span,
                });
                break;
            }
        }
        out
    }

    fn stmt(&mut self, s: &Stmt, lf: LoopFlags) -> Vec<Stmt> {
        let span = s.span;
        match &s.kind {
            StmtKind::Break => vec![self.set(lf.expect("break inside a loop").0, true, span)],
            StmtKind::Continue => vec![self.set(lf.expect("continue inside a loop").1, true, span)],
            StmtKind::Return { value } => {
                let mut v = Vec::new();
                if let (Some(rv), Some(x)) = (self.retval, value) {
                    v.push(Stmt {
                        kind: StmtKind::Assign {
                            dst: rv,
                            op: Op::Copy(*x),
                            define: false,
                        },
                        span,
                    });
                }
                v.push(self.set(self.ret.expect("return flag"), true, span));
                v
            }
            StmtKind::If { cond, then, els } => vec![Stmt {
                kind: StmtKind::If {
                    cond: *cond,
                    then: self.block(then, lf),
                    els: self.block(els, lf),
                },
                span,
            }],
            StmtKind::For { body, .. } | StmtKind::Loop { body } => {
                let jumps = contains(
                    body,
                    &|k| matches!(k, StmtKind::Break | StmtKind::Continue),
                    false,
                ) || contains(body, &|k| matches!(k, StmtKind::Return { .. }), true);
                if !jumps {
                    let body = self.block(body, lf);
                    return vec![Stmt {
                        kind: with_body(&s.kind, body),
                        span,
                    }];
                }
                let (brk, cont) = (self.flag("__brk"), self.flag("__cont"));
                let mut exit = vec![brk];
                exit.extend(self.ret);
                let mut new_body = vec![
                    Stmt {
                        kind: StmtKind::ExitIf { flags: exit },
                        span,
                    },
                    self.set(cont, false, span),
                ];
                new_body.extend(self.block(body, Some((brk, cont))));
                vec![
                    self.set(brk, false, span),
                    self.set(cont, false, span),
                    Stmt {
                        kind: with_body(&s.kind, new_body),
                        span,
                    },
                ]
            }
            _ => vec![s.clone()],
        }
    }
}

/// A `For` or `Loop` with another body.
fn with_body(k: &StmtKind, body: Block) -> StmtKind {
    match k {
        StmtKind::For { var, range, .. } => StmtKind::For {
            var: *var,
            range: range.clone(),
            body,
        },
        _ => StmtKind::Loop { body },
    }
}

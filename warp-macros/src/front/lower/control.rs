//! Control flow: `if` as a statement and as a value (a variable both branches assign),
//! `while` (a `loop` that breaks on the negated condition), `for` over integer ranges with
//! `.rev()` and `.step_by(k)` (and over host objects' queries, `query.rs`), and the
//! short-circuit `&&` and `||` (an `if` around the right operand). That `break` and `continue`
//! are inside a loop is the validator's check (`valid::wellformed`).

use super::typing::flex_value;
use super::*;

impl Lowerer {
    pub(super) fn loop_body<T>(&mut self, f: impl FnOnce(&mut Self) -> R<T>) -> R<(Block, T)> {
        self.in_block(f)
    }

    pub(super) fn while_loop(&mut self, w: &syn::ExprWhile) -> R<()> {
        if w.label.is_some() {
            return err(w.span(), "loop labels are not supported in kernels");
        }
        if matches!(&*w.cond, Expr::Let(_)) {
            return err(w.cond.span(), "`while let` is not supported in kernels");
        }
        let (body, _) = self.loop_body(|cx| {
            let c = cx.expr(&w.cond, Some(&BOOL))?;
            cx.expect_bool(c, w.cond.span())?;
            let not = cx.def(Op::Unary(UnOp::Not, c), BOOL, w.cond.span());
            cx.push(
                StmtKind::If {
                    cond: not,
                    then: vec![Stmt {
                        kind: StmtKind::Break,
                        span: w.cond.span(),
                    }],
                    els: vec![],
                },
                w.cond.span(),
            );
            cx.block_stmts(&w.body.stmts, None, false)
        })?;
        self.push(StmtKind::Loop { body }, w.span());
        Ok(())
    }

    pub(super) fn for_loop(&mut self, f: &syn::ExprForLoop) -> R<()> {
        if f.label.is_some() {
            return err(f.span(), "loop labels are not supported in kernels");
        }
        // A loop over a host object's query (`query.rs`).
        if let Some((call, row)) = Self::query_call(&f.expr) {
            return self.query_loop(f, call, row);
        }
        // Peel `.rev()` / `.step_by(k)` adapters, outermost last.
        let mut adapters_rev: Vec<(&str, Option<&Expr>, Span)> = Vec::new();
        let mut cur = strip(&f.expr);
        loop {
            match cur {
                Expr::MethodCall(m) if m.method == "rev" && m.args.is_empty() => {
                    adapters_rev.push(("rev", None, m.method.span()));
                    cur = strip(&m.receiver);
                }
                Expr::MethodCall(m) if m.method == "step_by" && m.args.len() == 1 => {
                    adapters_rev.push(("step_by", Some(&m.args[0]), m.method.span()));
                    cur = strip(&m.receiver);
                }
                Expr::MethodCall(m) => {
                    return err(
                        m.method.span(),
                        format!(
                            "`.{}()` is not supported on loop ranges: use .rev() and .step_by(k)",
                            m.method
                        ),
                    )
                }
                _ => break,
            }
        }
        let Expr::Range(range) = cur else {
            return err(
                f.expr.span(),
                "kernels loop over integer ranges: `for i in 0..n`, with .rev() and .step_by(k)",
            );
        };
        let (Some(start), Some(end)) = (&range.start, &range.end) else {
            return err(range.span(), "loop ranges need a start and an end");
        };
        let inclusive = matches!(range.limits, syn::RangeLimits::Closed(_));
        let (s, e) = self.operand_pair(start, end, None, BinOp::Lt)?;
        let st = self.ty(s);
        let et = self.ty(e);
        let ty = if st.is_deferred() {
            et.clone()
        } else {
            st.clone()
        };
        if !st.is_deferred() && !et.is_deferred() && st != et {
            return err(
                range.span(),
                format!("mismatched range bounds: `{st}` and `{et}`"),
            );
        }
        if !ty.is_deferred() && !ty.is_int_scalar() {
            return err(
                range.span(),
                format!("loop ranges are over integers, found `{ty}`"),
            );
        }
        let mut adapters = Vec::new();
        for (name, arg, span) in adapters_rev.into_iter().rev() {
            match (name, arg) {
                ("rev", _) => adapters.push(RangeAdapter::Rev),
                (_, Some(a)) => {
                    let k = self.expr(a, Some(&USIZE))?;
                    let kt = self.ty(k);
                    if !kt.is_deferred() && !kt.is_int_scalar() {
                        return err(span, format!("step_by takes an integer, found `{kt}`"));
                    }
                    adapters.push(RangeAdapter::StepBy(k));
                }
                _ => unreachable!("adapters are rev or step_by"),
            }
        }
        let (pat_name, mutable) = match &*f.pat {
            Pat::Ident(pi) if pi.subpat.is_none() && pi.by_ref.is_none() => {
                (Some(pi.ident.to_string()), pi.mutability.is_some())
            }
            Pat::Wild(_) => (None, false),
            p => return err(p.span(), "loop variables must be plain names"),
        };
        let var = self.new_var(pat_name.clone(), ty, mutable);
        let (body, _) = self.loop_body(|cx| {
            if let Some(n) = &pat_name {
                cx.scopes.last_mut().expect("scope").insert(n.clone(), var);
            }
            cx.block_stmts(&f.body.stmts, None, false)
        })?;
        self.push(
            StmtKind::For {
                var,
                range: RangeSpec {
                    start: s,
                    end: e,
                    inclusive,
                    adapters,
                },
                body,
            },
            f.span(),
        );
        Ok(())
    }

    /// `if`; with `value`, both branches must yield a value of one type.
    pub(super) fn if_expr(
        &mut self,
        i: &syn::ExprIf,
        value: bool,
        want: Option<&Ty>,
    ) -> R<Option<VarId>> {
        if matches!(&*i.cond, Expr::Let(_)) {
            return err(i.cond.span(), "`if let` is not supported in kernels");
        }
        let c = self.expr(&i.cond, Some(&BOOL))?;
        self.expect_bool(c, i.cond.span())?;
        if !value {
            let (then, _) =
                self.in_block(|cx| cx.block_stmts(&i.then_branch.stmts, None, false))?;
            let els = match &i.else_branch {
                None => vec![],
                Some((_, e)) => self.in_block(|cx| cx.stmt_expr(e))?.0,
            };
            self.push(StmtKind::If { cond: c, then, els }, i.span());
            return Ok(None);
        }
        let Some((_, else_e)) = &i.else_branch else {
            return err(i.span(), "an `if` used as a value needs an `else`");
        };
        let result = self.new_var(None, want.cloned().unwrap_or(Ty::Deferred), true);
        let decl_at = self.blocks.last().expect("block").len();
        let (then, tv) = self.in_block(|cx| {
            let v = cx.block_stmts(&i.then_branch.stmts, want, true)?;
            let Some(v) = v else {
                return err(i.then_branch.span(), "this branch yields no value");
            };
            Ok(v)
        })?;
        let tt = self.ty(tv);
        let want2 = if tt.is_deferred() {
            want.cloned()
        } else {
            Some(tt.clone())
        };
        // Beside a `then` value the macro cannot type, a literal `else` is left unsuffixed:
        // rustc types it from the result variable both branches assign.
        let want2 = match want2 {
            None if tt.is_deferred() && flex_value(else_e).is_some() => Some(Ty::Deferred),
            w => w,
        };
        let (mut els, ev) = self.in_block(|cx| cx.expr(else_e, want2.as_ref()))?;
        let et = self.ty(ev);
        if !tt.is_deferred() && !et.is_deferred() && tt != et {
            return err(
                else_e.span(),
                format!("`if` and `else` have different types: `{tt}` and `{et}`"),
            );
        }
        // If either side is deferred, so is the result: the target compiler checks the other.
        self.vars[result].ty = if tt.is_deferred() || et.is_deferred() {
            Ty::Deferred
        } else {
            tt
        };
        let mut then = then;
        then.push(Stmt {
            kind: StmtKind::Assign {
                dst: result,
                op: Op::Copy(tv),
                define: false,
            },
            span: i.then_branch.span(),
        });
        els.push(Stmt {
            kind: StmtKind::Assign {
                dst: result,
                op: Op::Copy(ev),
                define: false,
            },
            span: else_e.span(),
        });
        self.blocks.last_mut().expect("block").insert(
            decl_at,
            Stmt {
                kind: StmtKind::Declare { var: result },
                span: i.span(),
            },
        );
        self.push(StmtKind::If { cond: c, then, els }, i.span());
        Ok(Some(result))
    }

    pub(super) fn short_circuit(&mut self, b: &syn::ExprBinary) -> R<VarId> {
        let is_and = matches!(b.op, syn::BinOp::And(_));
        let l = self.expr(&b.left, Some(&BOOL))?;
        self.expect_bool(l, b.left.span())?;
        let result = self.new_var(None, BOOL, true);
        self.push(
            StmtKind::Assign {
                dst: result,
                op: Op::Copy(l),
                define: true,
            },
            b.left.span(),
        );
        let (rblock, rv) = self.in_block(|cx| {
            let rv = cx.expr(&b.right, Some(&BOOL))?;
            cx.expect_bool(rv, b.right.span())?;
            cx.push(
                StmtKind::Assign {
                    dst: result,
                    op: Op::Copy(rv),
                    define: false,
                },
                b.right.span(),
            );
            Ok(rv)
        })?;
        let _ = rv;
        let (then, els) = if is_and {
            (rblock, vec![])
        } else {
            (vec![], rblock)
        };
        self.push(StmtKind::If { cond: l, then, els }, b.span());
        Ok(result)
    }
}

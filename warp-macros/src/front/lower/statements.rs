//! Statements: blocks (errors gathered one per statement, so that many are reported at
//! once), `let` and its patterns (a name, `let (i, j) = tid();`, a decomposition's tuple
//! `let (u, sigma, v) = svd3(a);`), expression statements (`loop`, `break`, `continue` among
//! them), `return`, and `print!`/`println!` with their format strings.

use super::expressions::{is_compound_assign, map_binop};
use super::typing::flex_literal;
use super::*;

fn is_tid_call(e: &Expr) -> bool {
    match strip(e) {
        Expr::Call(c) => match strip(&c.func) {
            Expr::Path(p) => {
                p.path.segments.last().is_some_and(|s| s.ident == "tid") && c.args.is_empty()
            }
            _ => false,
        },
        _ => false,
    }
}

/// Statement-like expressions (`if` without a value, loops) at the end of a block.
fn is_block_like(e: &Expr) -> bool {
    matches!(
        e,
        Expr::If(_)
            | Expr::While(_)
            | Expr::ForLoop(_)
            | Expr::Loop(_)
            | Expr::Block(_)
            | Expr::Assign(_)
            | Expr::Macro(_)
            | Expr::Return(_)
            | Expr::Break(_)
            | Expr::Continue(_)
    ) || matches!(e, Expr::Binary(b) if is_compound_assign(&b.op))
}

/// A block-like tail that yields a value when the context wants one (`if` with `else`, `{..}`).
fn is_value_block(e: &Expr) -> bool {
    matches!(e, Expr::If(i) if i.else_branch.is_some()) || matches!(e, Expr::Block(_))
}

impl Lowerer {
    /// Lowers statements; returns the tail expression's value, if any. Errors inside single
    /// statements are recorded and lowering goes on, so that many are reported at once.
    pub(super) fn block_stmts(
        &mut self,
        stmts: &[syn::Stmt],
        want: Option<&Ty>,
        value: bool,
    ) -> R<Option<VarId>> {
        let mut tail = None;
        for (i, st) in stmts.iter().enumerate() {
            let last = i + 1 == stmts.len();
            let r = match st {
                syn::Stmt::Local(local) => self.local(local),
                syn::Stmt::Item(item) => err(
                    item.span(),
                    "items (fn, struct, use, ...) cannot be declared inside kernels",
                ),
                syn::Stmt::Macro(m) => self.macro_stmt(&m.mac),
                // A lone `;` (syn's empty verbatim expression): Rust's empty statement, which
                // does nothing.
                syn::Stmt::Expr(Expr::Verbatim(t), Some(_)) if t.is_empty() => Ok(()),
                syn::Stmt::Expr(e, None)
                    if last && (!is_block_like(e) || (value && is_value_block(e))) =>
                {
                    // A failed tail is the block's failure: report it once, through the caller.
                    tail = Some(self.expr(e, want)?);
                    Ok(())
                }
                syn::Stmt::Expr(e, _) => self.stmt_expr(e),
            };
            if let Err(e) = r {
                self.errors.push(e);
            }
        }
        Ok(tail)
    }

    fn local(&mut self, local: &syn::Local) -> R<()> {
        let span = local.span();
        let Some(init) = &local.init else {
            return err(span, "`let` needs a value in kernels: `let x = ...;`");
        };
        if init.diverge.is_some() {
            return err(span, "`let ... else` is not supported in kernels");
        }
        let (pat, annot) = match &local.pat {
            Pat::Type(pt) => (&*pt.pat, Some(parse_type(&pt.ty)?)),
            p => (p, None),
        };
        if let Pat::Tuple(tuple) = pat {
            if !is_tid_call(&init.expr) {
                let value = self.expr(&init.expr, annot.as_ref())?;
                return self.bind_tuple(tuple, value, annot.as_ref(), span);
            }
            // `let (i, j) = tid();`
            let n = tuple.elems.len();
            if !(2..=4).contains(&n) {
                return err(pat.span(), "tid() destructures into 2 to 4 indices");
            }
            if let Some(a) = &annot {
                if *a != Ty::Tuple(vec![USIZE; n]) {
                    return err(
                        local.pat.span(),
                        format!(
                            "mismatched types: `tid()` gives `{}`, not `{a}`",
                            Ty::TidTuple(n as u8)
                        ),
                    );
                }
            }
            self.use_tid(n as u8, init.expr.span())?;
            for (k, el) in tuple.elems.iter().enumerate() {
                let v = self.def(Op::Tid(k as u8), USIZE, el.span());
                self.bind_pat(el, v, span)?;
            }
            return Ok(());
        }
        // `let mut acc = 1.0;`: typed as its uses want it, where an earlier pass learned that.
        let literal_let = (annot.is_none()
            && matches!(pat, Pat::Ident(pi) if pi.by_ref.is_none() && pi.subpat.is_none())
            && flex_literal(&init.expr).is_some())
        .then(|| self.defaults.meet());
        let hint = annot
            .clone()
            .or_else(|| literal_let.as_ref().and_then(|(_, t)| t.clone()));
        let mut value = self.expr(&init.expr, hint.as_ref())?;
        if let Some(a) = &annot {
            let vt = self.ty(value);
            if !vt.is_deferred() && vt != *a {
                self.learn_literal_type(value, a);
                return err(
                    init.expr.span(),
                    format!("mismatched types: expected `{a}`, found `{vt}`"),
                );
            }
            // A value the macro cannot type (a struct field, a func's result: a local array, a
            // spatial vector) takes the annotation's type, which the target compilers check, so
            // that `let v: SpatialVector = b.twist;` can be indexed and the elements of
            // `let b: [f32; 8] = f(a);` read and written.
            if vt.is_deferred() && !a.is_deferred() {
                value = self.def(Op::Copy(value), a.clone(), init.expr.span());
            }
        }
        self.bind_pat(pat, value, span)?;
        if let (Some((key, _)), Pat::Ident(pi)) = (literal_let, pat) {
            if let Some(v) = self.lookup(&pi.ident.to_string()) {
                self.defaults.bound(v, key);
            }
        }
        Ok(())
    }

    /// `let (a, b) = value;` (`value` a tuple: a decomposition's, a func's, a local, a
    /// literal): one member read per bound name, `_` skipped, a nested pattern destructured in
    /// turn. A func's result has a type the macro cannot see: it is copied into a variable
    /// whose type states the pattern's length (`(_, _)`, or the annotation's), which rustc
    /// then checks.
    fn bind_tuple(
        &mut self,
        tuple: &syn::PatTuple,
        mut value: VarId,
        annot: Option<&Ty>,
        span: Span,
    ) -> R<()> {
        let n = tuple.elems.len();
        let tys = match self.ty(value) {
            Ty::Tuple(tys) if tys.len() == n => tys,
            Ty::Deferred => {
                let ty = match annot {
                    Some(a @ Ty::Tuple(w)) if w.len() == n => a.clone(),
                    _ => Ty::Tuple(vec![Ty::Deferred; n]),
                };
                value = self.def(Op::Copy(value), ty.clone(), tuple.span());
                let Ty::Tuple(tys) = ty else { unreachable!("a tuple") };
                tys
            }
            t @ Ty::Tuple(_) => {
                // A decomposition's parts have names (Warp's output arguments).
                let hint = match self.blocks.last().and_then(|b| b.last()) {
                    Some(Stmt {
                        kind:
                            StmtKind::Assign {
                                dst,
                                op: Op::Builtin { builtin, .. },
                                ..
                            },
                        ..
                    }) if *dst == value => builtin
                        .results
                        .map(|r| format!(": `let {r} = {}(..);`", builtin.name)),
                    _ => None,
                };
                return err(
                    tuple.span(),
                    format!(
                        "this pattern binds {n} value(s), but the value is a `{t}`{}",
                        hint.unwrap_or_default()
                    ),
                );
            }
            t => {
                return err(
                    tuple.span(),
                    format!("a tuple pattern destructures a tuple (a func's or a decomposition's result, `(a, b)`), found `{t}`"),
                )
            }
        };
        let annots: Vec<Option<&Ty>> = match annot {
            Some(a @ Ty::Tuple(w)) => {
                let ok = w.len() == n && w.iter().zip(&tys).all(|(w, t)| t.is_deferred() || w == t);
                if !ok {
                    return err(
                        tuple.span(),
                        format!(
                            "mismatched types: expected `{a}`, found `{}`",
                            self.ty(value)
                        ),
                    );
                }
                w.iter().map(Some).collect()
            }
            Some(a) => {
                return err(
                    tuple.span(),
                    format!("mismatched types: expected `{a}`, found a tuple pattern"),
                )
            }
            None => vec![None; n],
        };
        for (k, (el, ty)) in tuple.elems.iter().zip(tys).enumerate() {
            let el = match el {
                Pat::Paren(p) => &*p.pat,
                el => el,
            };
            if matches!(el, Pat::Wild(_)) {
                continue;
            }
            let v = self.def(Op::Member(value, k.to_string()), ty, el.span());
            match el {
                Pat::Tuple(inner) => self.bind_tuple(inner, v, annots[k], span)?,
                el => self.bind_pat(el, v, span)?,
            }
        }
        Ok(())
    }

    /// Binds a pattern (a name, `mut name` or `_`) to a value by copying it into a new variable.
    fn bind_pat(&mut self, pat: &Pat, value: VarId, span: Span) -> R<()> {
        match pat {
            Pat::Ident(pi) if pi.by_ref.is_none() && pi.subpat.is_none() && self.is_view(value) => {
                // A view is a name for part of an array, not a value: bind the name to it.
                if pi.mutability.is_some() {
                    return err(pi.span(), "views are immutable: `let v = a.row(i);`");
                }
                let name = pi.ident.to_string();
                self.scopes.last_mut().expect("scope").insert(name, value);
                Ok(())
            }
            Pat::Ident(pi) if pi.by_ref.is_none() && pi.subpat.is_none() => {
                let ty = self.ty(value);
                let name = pi.ident.to_string();
                let v = self.new_var(Some(name.clone()), ty.clone(), pi.mutability.is_some());
                // A tile made by the statement just before: that statement makes it in the
                // named variable. A copy would cost a second shared-memory slot and a pass
                // over the tile.
                if ty.is_tile() && self.vars[value].name.is_none() {
                    if let Some(Stmt {
                        kind:
                            StmtKind::Assign {
                                dst, define: true, ..
                            },
                        ..
                    }) = self.blocks.last_mut().expect("block").last_mut()
                    {
                        if *dst == value {
                            *dst = v;
                            self.scopes.last_mut().expect("scope").insert(name, v);
                            return Ok(());
                        }
                    }
                }
                self.push(
                    StmtKind::Assign {
                        dst: v,
                        op: Op::Copy(value),
                        define: true,
                    },
                    span,
                );
                self.scopes.last_mut().expect("scope").insert(name, v);
                Ok(())
            }
            Pat::Wild(_) => Ok(()),
            Pat::Ident(pi) if pi.by_ref.is_some() => {
                err(pi.span(), "`ref` bindings are not supported in kernels")
            }
            other => err(
                other.span(),
                "only plain names, `_` and tuple patterns (`let (a, b) = f(x);`) can be bound in kernels",
            ),
        }
    }

    pub(super) fn use_tid(&mut self, n: u8, span: Span) -> R<()> {
        if self.kind == FnKind::Func {
            return err(
                span,
                "tid() is only available in kernels: pass the index to the func",
            );
        }
        match self.tid_ndim {
            Some(m) if m != n => err(
                span,
                format!("tid() is used with {m} and with {n} dimensions in one kernel"),
            ),
            _ => {
                self.tid_ndim = Some(n);
                Ok(())
            }
        }
    }

    /// An expression in statement position (its value, if any, is dropped).
    pub(super) fn stmt_expr(&mut self, e: &Expr) -> R<()> {
        let span = e.span();
        match e {
            Expr::Assign(a) => self.assign(&a.left, None, &a.right, span),
            Expr::Binary(b) if is_compound_assign(&b.op) => {
                let op = map_binop(&b.op).expect("compound op");
                self.assign(&b.left, Some(op), &b.right, span)
            }
            Expr::If(i) => self.if_expr(i, false, None).map(|_| ()),
            Expr::While(w) => self.while_loop(w),
            Expr::ForLoop(f) => self.for_loop(f),
            Expr::Loop(l) => {
                if let Some(label) = &l.label {
                    return err(label.span(), "loop labels are not supported in kernels");
                }
                let (body, _) = self.loop_body(|cx| cx.block_stmts(&l.body.stmts, None, false))?;
                self.push(StmtKind::Loop { body }, span);
                Ok(())
            }
            Expr::Block(b) => {
                if b.label.is_some() {
                    return err(span, "block labels are not supported in kernels");
                }
                let (block, _) = self.in_block(|cx| cx.block_stmts(&b.block.stmts, None, false))?;
                self.blocks.last_mut().expect("block").extend(block);
                Ok(())
            }
            Expr::Break(b) => {
                if b.label.is_some() || b.expr.is_some() {
                    return err(
                        span,
                        "`break` with a label or a value is not supported in kernels",
                    );
                }
                // Outside of a loop: the validator's error (`valid::wellformed`).
                self.push(StmtKind::Break, span);
                Ok(())
            }
            Expr::Continue(c) => {
                if c.label.is_some() {
                    return err(span, "`continue` with a label is not supported in kernels");
                }
                self.push(StmtKind::Continue, span);
                Ok(())
            }
            Expr::Return(r) => self.ret_stmt(r),
            Expr::Macro(m) => self.macro_stmt(&m.mac),
            _ if super::asserts::expectation_call(e).is_some() => {
                let (c, name) = super::asserts::expectation_call(e).expect("matched");
                self.expectation(c, name)
            }
            _ => {
                self.expr(e, None)?;
                Ok(())
            }
        }
    }

    fn ret_stmt(&mut self, r: &syn::ExprReturn) -> R<()> {
        let span = r.span();
        let value = match (&r.expr, self.kind) {
            (Some(e), FnKind::Kernel) => {
                return err(
                    e.span(),
                    "kernels return nothing: `return;` ends the thread",
                )
            }
            (Some(e), FnKind::Func) => {
                let ret = self.ret.clone();
                let v = self.expr(e, Some(&ret))?;
                let vt = self.ty(v);
                if !vt.is_deferred() && !ret.is_deferred() && vt != ret {
                    self.learn_literal_type(v, &ret);
                    return err(
                        e.span(),
                        format!("mismatched types: the func returns `{ret}`, found `{vt}`"),
                    );
                }
                Some(v)
            }
            (None, FnKind::Func) if !matches!(self.ret, Ty::Unit) => {
                return err(
                    span,
                    format!("`return;` in a func returning `{}`", self.ret),
                )
            }
            (None, _) => None,
        };
        self.push_return(value, span);
        Ok(())
    }

    fn macro_stmt(&mut self, mac: &syn::Macro) -> R<()> {
        let name = mac
            .path
            .segments
            .last()
            .map(|s| s.ident.to_string())
            .unwrap_or_default();
        let newline = match name.as_str() {
            "println" => true,
            "print" => false,
            "assert" | "debug_assert" | "assert_eq" | "assert_ne" | "debug_assert_eq"
            | "debug_assert_ne" => return self.assert_macro(mac, &name),
            _ => {
                return err(
                    mac.path.span(),
                    format!(
                        "macro `{name}!` is not supported in kernels (print!, println!, \
                         assert!, assert_eq!, assert_ne! and their debug_ forms are)"
                    ),
                )
            }
        };
        let args: syn::punctuated::Punctuated<Expr, syn::Token![,]> =
            mac.parse_body_with(syn::punctuated::Punctuated::parse_terminated)?;
        let mut it = args.iter();
        let fmt = match it.next() {
            None => String::new(),
            Some(Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Str(s),
                ..
            })) => s.value(),
            Some(other) => {
                return err(
                    other.span(),
                    "the first argument of print! must be a format string",
                )
            }
        };
        let fmt_span = mac.tokens.span();
        let mut values = Vec::new();
        for a in it {
            // `println!("{}", acc)` prints the value a `&mut` parameter refers to, as in Rust.
            values.push(self.base_expr(a)?);
        }
        let pieces = self.parse_format(&fmt, &values, fmt_span)?;
        self.push(StmtKind::Print { pieces, newline }, mac.span());
        Ok(())
    }

    fn parse_format(&mut self, fmt: &str, values: &[VarId], span: Span) -> R<Vec<FmtPiece>> {
        let mut pieces = Vec::new();
        let mut text = String::new();
        let mut next = 0;
        let mut chars = fmt.chars().peekable();
        while let Some(c) = chars.next() {
            match c {
                '{' if chars.peek() == Some(&'{') => {
                    chars.next();
                    text.push('{');
                }
                '}' if chars.peek() == Some(&'}') => {
                    chars.next();
                    text.push('}');
                }
                '{' => {
                    let mut spec = String::new();
                    for c in chars.by_ref() {
                        if c == '}' {
                            break;
                        }
                        spec.push(c);
                    }
                    let (name, debug) = match spec.split_once(':') {
                        None => (spec.as_str(), false),
                        Some((n, "?")) => (n, true),
                        Some(_) => return err(span, format!("format spec `{{{spec}}}` is not supported in kernels: use {{}} or {{:?}}")),
                    };
                    let var = if name.is_empty() {
                        let v = *values.get(next).ok_or_else(|| {
                            syn::Error::new(span, "more {} placeholders than arguments")
                        })?;
                        next += 1;
                        v
                    } else {
                        self.lookup(name).ok_or_else(|| {
                            syn::Error::new(span, format!("no variable `{name}` to print"))
                        })?
                    };
                    if let Ty::Object(k) = self.ty(var) {
                        return err(
                            span,
                            format!("a `{}` cannot be printed in kernels", k.row().name),
                        );
                    }
                    if let t @ Ty::Tuple(_) = self.ty(var) {
                        return err(
                            span,
                            format!(
                                "a tuple (`{t}`) cannot be printed in kernels: print its elements"
                            ),
                        );
                    }
                    if let t @ Ty::LocalArray(..) = self.ty(var) {
                        return err(
                            span,
                            format!("a local array (`{t}`) cannot be printed in kernels: print its elements"),
                        );
                    }
                    if !text.is_empty() {
                        pieces.push(FmtPiece::Text(std::mem::take(&mut text)));
                    }
                    pieces.push(FmtPiece::Arg { var, debug });
                }
                '}' => return err(span, "unmatched `}` in format string (write `}}`)"),
                c => text.push(c),
            }
        }
        if next != values.len() {
            return err(
                span,
                format!("{} arguments but {} placeholders", values.len(), next),
            );
        }
        if !text.is_empty() {
            pieces.push(FmtPiece::Text(text));
        }
        Ok(pieces)
    }
}

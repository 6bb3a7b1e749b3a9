//! Fixed-size local arrays (`[f32; 8]`, Warp's in-kernel `wp.zeros`): literals `[x, y, z]`,
//! repeats `[v; N]` (a literal length or a module const), reads and writes of elements at
//! dynamic indices (`Op::Index`, `StmtKind::SetElem`, both checked against the length) and
//! `len()`. A local array is a value: copied, passed to funcs and returned whole; writing an
//! element is an overwrite of the array variable, which is how the adjoint keeps its history.

use super::typing::flex_literal;
use super::*;
use crate::front::signature::{
    local_array_elem_error as bad_elem, local_array_length as length_of,
};
use crate::types::Dim;

impl Lowerer {
    /// The element type of local array `v`, or of a value with lanes (`Ty::lane_elems`: a
    /// vector's scalar, a glam matrix's column); `Deferred` for anything else.
    pub(super) fn local_elem_ty(&self, v: VarId) -> Ty {
        match self.ty(v) {
            Ty::LocalArray(e, _) => *e,
            t => t.lane_elems().map_or(Ty::Deferred, |(e, _)| e),
        }
    }

    /// The index of a local array's element: one integer.
    pub(super) fn local_index(&mut self, e: &Expr) -> R<VarId> {
        if let Expr::Tuple(_) = strip(e) {
            return err(
                e.span(),
                "a local array has one dimension: index an array of arrays as `a[i][j]` \
                 (a matrix whose type the macro cannot see, a struct's field or a func's result, \
                 takes `m[(i, j)]` once bound with its type: `let m: Mat3 = s.m;`)",
            );
        }
        let v = self.expr(e, Some(&USIZE))?;
        let t = self.ty(v);
        if !(t.is_deferred() || t.is_int_scalar()) {
            return err(e.span(), format!("array indices are integers, found `{t}`"));
        }
        Ok(v)
    }

    /// `a.len()` of a local array: its length, a constant (`usize`).
    pub(super) fn local_len(&mut self, array: VarId, span: Span) -> VarId {
        match self.ty(array) {
            Ty::LocalArray(_, Dim::Const(p)) => {
                let p: syn::Path = syn::parse_str(&p).expect("a const path");
                let c = self.user_const(&p, span);
                self.def(Op::Cast(c, USIZE), USIZE, span)
            }
            Ty::LocalArray(_, Dim::Lit(n)) => self.def(Op::Lit(Lit::Int(n as i128)), USIZE, span),
            _ => unreachable!("`local_len` of a local array"),
        }
    }

    /// `[x, y, z]`: the elements typed as `want`'s element (an annotation), else as the first
    /// element that is not an unsuffixed literal (literals have no effects, so lowering them
    /// after the others changes nothing), else by the literal rule.
    pub(super) fn array_literal(
        &mut self,
        a: &syn::ExprArray,
        want: Option<&Ty>,
        span: Span,
    ) -> R<VarId> {
        if a.elems.is_empty() {
            return err(span, "a local array holds at least one element");
        }
        let mut elem = want.and_then(|w| w.local_array()).map(|(e, _)| e.clone());
        let mut args = vec![None; a.elems.len()];
        let literal = |e: &Expr| flex_literal(e).is_some();
        for pass_literals in [false, true] {
            for (k, e) in a.elems.iter().enumerate() {
                if literal(e) != pass_literals {
                    continue;
                }
                let v = self.expr(e, elem.as_ref())?;
                let t = self.ty(v);
                match &elem {
                    Some(w) if !t.is_deferred() && !w.is_deferred() && t != *w => {
                        return err(
                            e.span(),
                            format!(
                                "mismatched types: the array's elements are `{w}`, this is `{t}`"
                            ),
                        )
                    }
                    Some(w) if !w.is_deferred() => {}
                    _ => elem = Some(t),
                }
                args[k] = Some(v);
            }
        }
        let elem = elem.expect("at least one element");
        if let Some(why) = bad_elem(&elem) {
            return err(span, why);
        }
        let n =
            u32::try_from(args.len()).map_err(|_| syn::Error::new(span, "too many elements"))?;
        let ty = Ty::LocalArray(Box::new(elem), Dim::Lit(n));
        let args = args.into_iter().map(|v| v.expect("lowered")).collect();
        let ctor = Ctor::Components;
        Ok(self.def(
            Op::Construct {
                ty: ty.clone(),
                ctor,
                args,
            },
            ty,
            span,
        ))
    }

    /// `[v; N]`: Warp's `wp.zeros(N, dtype)` is `[0.0f32; N]`.
    pub(super) fn array_repeat(
        &mut self,
        r: &syn::ExprRepeat,
        want: Option<&Ty>,
        span: Span,
    ) -> R<VarId> {
        let n = length_of(&r.len)?;
        let elem = want.and_then(|w| w.local_array()).map(|(e, _)| e.clone());
        let v = self.expr(&r.expr, elem.as_ref())?;
        let t = self.ty(v);
        let elem = match elem {
            Some(w) if !t.is_deferred() && t != w => {
                return err(
                    r.expr.span(),
                    format!("mismatched types: the array's elements are `{w}`, this is `{t}`"),
                )
            }
            Some(w) => w,
            None => t,
        };
        if let Some(why) = bad_elem(&elem) {
            return err(r.expr.span(), why);
        }
        if let Dim::Const(p) = &n {
            self.note_const(&syn::parse_str(p).expect("a const path"));
        }
        let ty = Ty::LocalArray(Box::new(elem), n);
        let (ctor, args) = (Ctor::Splat, vec![v]);
        Ok(self.def(
            Op::Construct {
                ty: ty.clone(),
                ctor,
                args,
            },
            ty,
            span,
        ))
    }

    /// The span of the first statement that makes a local array, if any.
    pub(super) fn local_array_span(&self) -> Option<Span> {
        let mut found = None;
        walk_stmts(self.blocks.first()?, &mut |s| {
            if let StmtKind::Assign { dst, .. } = &s.kind {
                if found.is_none() && matches!(self.vars[*dst].ty, Ty::LocalArray(..)) {
                    found = Some(s.span);
                }
            }
        });
        found
    }

    /// Records a module const the function reads (`Function::consts`), once.
    pub(super) fn note_const(&mut self, p: &syn::Path) {
        if !self.consts.contains(p) {
            self.consts.push(p.clone());
        }
    }

    /// Registers the consts that local array lengths in the function's types name (a
    /// parameter's `[f32; N]` included), so that the CUDA template can spell them.
    pub(super) fn note_length_consts(&mut self) {
        fn walk(t: &Ty, out: &mut Vec<syn::Path>) {
            if let Ty::LocalArray(e, n) = t {
                if let Dim::Const(p) = n {
                    out.push(syn::parse_str(p).expect("a const path"));
                }
                walk(e, out);
            }
        }
        let mut paths = Vec::new();
        for v in &self.vars {
            walk(&v.ty, &mut paths);
        }
        walk(&self.ret.clone(), &mut paths);
        for p in paths {
            self.note_const(&p);
        }
    }
}

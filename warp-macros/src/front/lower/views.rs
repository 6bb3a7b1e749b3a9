//! In-kernel views: `let r = a.row(i);` (the sub-array at a leading index, one dimension
//! fewer), `let v = a.view(lo..hi);` (a range of the leading dimension) and
//! `let g = a.indexed(idx);` (the leading dimension gathered through an index array: `g[k]` is
//! `a[idx[k]]`, Warp's indexed arrays), in kernels and funcs, of arrays and of other views.
//!
//! A view is resolved while lowering, not represented at run time: it is a variable that is
//! never assigned, with a [`ViewDef`] saying which elements of which array it stands for, and
//! every use of it is rewritten into a use of that array (`r[j]` is `a[(i, j)]`, `v[k]` is
//! `a[lo + k]`). So the back ends, the analyses (which arrays a kernel writes, which accesses
//! are indexed by the thread index) and both adjoints see ordinary array accesses, and
//! gradients through views need nothing of their own. What a view adds is its bounds: the
//! range of `view` is checked when the view is made (`lo <= hi <= len`, as Rust slicing
//! panics) and each index into it against its length (`Op::ViewCheck`); an index fixed by
//! `row` is checked by the access itself, as part of the full index into the array. A use of a
//! view that is not rewritten (passed to a func, printed, copied into an `if` value) reads its
//! never-defined variable: the validator reports it (`valid::wellformed`).

use super::*;

/// What a view variable stands for.
#[derive(Clone, Debug)]
pub(super) struct ViewDef {
    /// The viewed array (a parameter, or a func's array argument).
    pub base: VarId,
    /// Leading indices fixed by `row`, outermost first (any integer type).
    pub prefix: Vec<VarId>,
    /// How the first free dimension is mapped.
    pub lead: Lead,
}

/// The mapping of a view's first free dimension onto the viewed array's.
#[derive(Clone, Copy, Debug)]
pub(super) enum Lead {
    /// As it is.
    All,
    /// `view(lo..hi)`: start and length (usize).
    Range(VarId, VarId),
    /// `indexed(idx)`: index `k` is `idx[k]` (a 1-D integer array).
    Gather(VarId),
}

impl Lowerer {
    pub(super) fn is_view(&self, v: VarId) -> bool {
        self.views.contains_key(&v)
    }

    /// The view `a` stands for; an array stands for all of itself.
    fn view_of(&self, a: VarId) -> ViewDef {
        self.views.get(&a).cloned().unwrap_or(ViewDef {
            base: a,
            prefix: Vec::new(),
            lead: Lead::All,
        })
    }

    /// `recv.row(i)` or `recv.view(range)` when `recv` is an array or a view; `None` for any
    /// other method.
    pub(super) fn view_method(&mut self, m: &syn::ExprMethodCall) -> R<Option<VarId>> {
        let name = m.method.to_string();
        if !(name == "row" || name == "view" || name == "indexed") || m.args.len() != 1 {
            return Ok(None);
        }
        let span = m.span();
        let a = self.expr(&m.receiver, None)?;
        let Ty::Array(elem, n) = self.ty(a) else {
            return Ok(None);
        };
        let d = self.view_of(a);
        let arg = &m.args[0];
        let view = if name == "row" {
            if n < 2 {
                return err(
                    span,
                    "`row` of a 1-D array would be an element: index it, `a[i]`",
                );
            }
            let i = self.index_value(arg)?;
            // The index as it is now: `r` keeps naming this row if `i` changes later.
            let i = self.def(Op::Copy(i), self.ty(i), span);
            let i = self.map_lead(&d, i, span);
            let mut prefix = d.prefix;
            prefix.push(i);
            let v = self.new_var(None, Ty::Array(elem, n - 1), false);
            self.views.insert(
                v,
                ViewDef {
                    base: d.base,
                    prefix,
                    lead: Lead::All,
                },
            );
            v
        } else if name == "indexed" {
            if !matches!(d.lead, Lead::All) {
                return err(
                    span,
                    "`indexed` of a `view` or of an `indexed` view is not supported: index the array",
                );
            }
            let idx = self.expr(arg, None)?;
            if self.is_view(idx) {
                return err(
                    arg.span(),
                    "the index array of `indexed` must be an array, not a view",
                );
            }
            match self.ty(idx) {
                Ty::Array(t, 1) if t.is_int_scalar() => {}
                t => {
                    return err(
                        arg.span(),
                        format!("`indexed` takes a 1-D array of integers, found `{t}`"),
                    )
                }
            }
            let v = self.new_var(None, Ty::Array(elem, n), false);
            self.views.insert(
                v,
                ViewDef {
                    base: d.base,
                    prefix: d.prefix,
                    lead: Lead::Gather(idx),
                },
            );
            v
        } else {
            if matches!(d.lead, Lead::Gather(_)) {
                return err(
                    span,
                    "`view` of an `indexed` view is not supported: view the index array",
                );
            }
            let Expr::Range(r) = strip(arg) else {
                return err(
                    arg.span(),
                    "`view` takes a range of the leading dimension: `a.view(lo..hi)`",
                );
            };
            let extent = self.free_extent(&d, 0, span);
            let hi = match &r.end {
                None => extent,
                Some(e) => {
                    let hi = self.index_value(e)?;
                    if matches!(r.limits, syn::RangeLimits::Closed(_)) {
                        // `lo..=hi`: hi itself must be an index, then one past it.
                        let hi = self.view_check(d.base, hi, extent, false, span);
                        let one = self.def(Op::Lit(Lit::Int(1)), USIZE, span);
                        self.def(Op::Binary(BinOp::Add, hi, one), USIZE, span)
                    } else {
                        self.view_check(d.base, hi, extent, true, span)
                    }
                }
            };
            let lo = match &r.start {
                None => self.def(Op::Lit(Lit::Int(0)), USIZE, span),
                Some(e) => {
                    let lo = self.index_value(e)?;
                    self.view_check(d.base, lo, hi, true, span)
                }
            };
            let count = self.def(Op::Binary(BinOp::Sub, hi, lo), USIZE, span);
            let start = match d.lead {
                Lead::Range(lo0, _) => self.def(Op::Binary(BinOp::Add, lo0, lo), USIZE, span),
                _ => lo,
            };
            let v = self.new_var(None, Ty::Array(elem, n), false);
            self.views.insert(
                v,
                ViewDef {
                    base: d.base,
                    prefix: d.prefix,
                    lead: Lead::Range(start, count),
                },
            );
            v
        };
        Ok(Some(view))
    }

    /// An index expression (any integer type), lowered.
    fn index_value(&mut self, e: &Expr) -> R<VarId> {
        let v = self.expr(e, Some(&USIZE))?;
        let t = self.ty(v);
        if !(t.is_deferred() || t.is_int_scalar()) {
            return err(e.span(), format!("array indices are integers, found `{t}`"));
        }
        Ok(v)
    }

    fn view_check(
        &mut self,
        array: VarId,
        index: VarId,
        bound: VarId,
        inclusive: bool,
        span: Span,
    ) -> VarId {
        self.def(
            Op::ViewCheck {
                array,
                index,
                bound,
                inclusive,
            },
            USIZE,
            span,
        )
    }

    /// Index `i` of the view's first free dimension as an index of the viewed array's: `lo + i`
    /// after checking `i < count` for a range, `idx[i]` (a checked load) for a gather.
    fn map_lead(&mut self, d: &ViewDef, i: VarId, span: Span) -> VarId {
        match d.lead {
            Lead::All => i,
            Lead::Range(lo, count) => {
                let i = self.view_check(d.base, i, count, false, span);
                self.def(Op::Binary(BinOp::Add, lo, i), USIZE, span)
            }
            Lead::Gather(idx) => {
                let t = match self.ty(idx) {
                    Ty::Array(t, _) => *t,
                    _ => unreachable!("checked when the view was made"),
                };
                self.def(
                    Op::Load {
                        array: idx,
                        index: vec![i],
                    },
                    t,
                    span,
                )
            }
        }
    }

    /// The extent of free dimension `k` of the view `d` (usize).
    fn free_extent(&mut self, d: &ViewDef, k: u8, span: Span) -> VarId {
        match d.lead {
            Lead::Range(_, count) if k == 0 => count,
            Lead::Gather(idx) if k == 0 => self.def(Op::Len(idx), USIZE, span),
            _ => self.def(Op::Extent(d.base, d.prefix.len() as u8 + k), USIZE, span),
        }
    }

    /// An access `a[index]` as an access of the viewed array (unchanged when `a` is not a
    /// view).
    pub(super) fn resolve_view(
        &mut self,
        a: VarId,
        mut index: Vec<VarId>,
        span: Span,
    ) -> (VarId, Vec<VarId>) {
        let Some(d) = self.views.get(&a).cloned() else {
            return (a, index);
        };
        if let Some(first) = index.first().copied() {
            index[0] = self.map_lead(&d, first, span);
        }
        let mut full = d.prefix;
        full.extend(index);
        (d.base, full)
    }

    /// `v.len()` of a view: the product of its extents.
    pub(super) fn view_len(&mut self, a: VarId, span: Span) -> VarId {
        let d = self.view_of(a);
        let Ty::Array(_, n) = self.ty(a) else {
            unreachable!("views are arrays")
        };
        let mut len = self.free_extent(&d, 0, span);
        for k in 1..n {
            let e = self.free_extent(&d, k, span);
            len = self.def(Op::Binary(BinOp::Mul, len, e), USIZE, span);
        }
        len
    }

    /// `v.shape()[k]` of a view.
    pub(super) fn view_extent(&mut self, a: VarId, k: u8, span: Span) -> VarId {
        let d = self.view_of(a);
        self.free_extent(&d, k, span)
    }
}

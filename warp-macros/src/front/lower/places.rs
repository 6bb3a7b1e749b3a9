//! Places: what can be assigned (a local, an array element, and a field path of either), `=`
//! and the compound assignments, reading and writing a place (writing a field of an array
//! element loads, sets and stores the element), the types of members, and array indexing
//! with one index variable per dimension.

use super::typing::flex_literal;
use super::*;
use crate::operators::binary_result;

/// An assignable place: a local (with a member path) or an array element (with a member path).
pub(super) enum Place {
    Local {
        var: VarId,
        path: Vec<String>,
    },
    Elem {
        array: VarId,
        index: Vec<VarId>,
        path: Vec<String>,
    },
}

impl Lowerer {
    pub(super) fn assign(
        &mut self,
        lhs: &Expr,
        op: Option<BinOp>,
        rhs: &Expr,
        span: Span,
    ) -> R<()> {
        let place = self.place(lhs)?;
        let place_ty = self.place_ty(&place, lhs.span())?;
        // Current value, for compound assignment.
        let value = match op {
            None => {
                let v = self.expr(rhs, Some(&place_ty))?;
                let vt = self.ty(v);
                if !vt.is_deferred() && !place_ty.is_deferred() && vt != place_ty {
                    return err(
                        rhs.span(),
                        format!("mismatched types: expected `{place_ty}`, found `{vt}`"),
                    );
                }
                v
            }
            Some(op) => {
                let old = self.read_place(&place, place_ty.clone(), lhs.span());
                let r = if flex_literal(rhs).is_some() && !matches!(op, BinOp::Shl | BinOp::Shr) {
                    self.literal_next_to(rhs, old, op)?
                } else {
                    self.expr(rhs, None)?
                };
                let rt = self.ty(r);
                let res =
                    binary_result(op, &place_ty, &rt).map_err(|m| syn::Error::new(span, m))?;
                if !res.is_deferred() && !place_ty.is_deferred() && res != place_ty {
                    return err(
                        span,
                        format!(
                            "`{}=` would change the type of `{place_ty}` to `{res}`",
                            op.symbol()
                        ),
                    );
                }
                self.def(Op::Binary(op, old, r), place_ty.clone(), span)
            }
        };
        self.write_place(place, value, span);
        Ok(())
    }

    pub(super) fn place(&mut self, e: &Expr) -> R<Place> {
        match strip(e) {
            Expr::Path(p) if p.path.get_ident().is_some() => {
                let name = p.path.get_ident().expect("ident").to_string();
                let Some(var) = self.lookup(&name) else {
                    return err(
                        p.span(),
                        format!("cannot assign to `{name}`: no such variable"),
                    );
                };
                if !self.vars[var].mutable {
                    return err(p.span(), format!("cannot assign to immutable variable `{name}`: declare it `let mut {name}`"));
                }
                if matches!(self.vars[var].ty, Ty::Array(..)) {
                    return err(
                        p.span(),
                        "arrays cannot be reassigned in kernels: write to their elements",
                    );
                }
                Ok(Place::Local { var, path: vec![] })
            }
            Expr::Field(f) => {
                let syn::Member::Named(m) = &f.member else {
                    return err(f.member.span(), "tuple fields are not supported in kernels");
                };
                let mut inner = self.place(&f.base)?;
                match &mut inner {
                    Place::Local { path, .. } | Place::Elem { path, .. } => {
                        path.push(m.to_string())
                    }
                }
                Ok(inner)
            }
            Expr::Index(ix) => {
                // `v[3] = x`, `m[i][j] += x`: members of a spatial value in a place.
                if let Some(bt) = self.peek_place_ty(&ix.expr) {
                    if let Some(lanes) = spatial_index(&bt, &ix.index)? {
                        let mut inner = self.place(&ix.expr)?;
                        match &mut inner {
                            Place::Local { path, .. } | Place::Elem { path, .. } => {
                                path.extend(lanes)
                            }
                        }
                        return Ok(inner);
                    }
                }
                let (array, index) = self.array_index(ix)?;
                Ok(Place::Elem {
                    array,
                    index,
                    path: vec![],
                })
            }
            other => err(other.span(), "cannot assign to this expression"),
        }
    }

    pub(super) fn member_ty(&self, base: &Ty, name: &str, span: Span) -> R<Ty> {
        match base {
            Ty::Deferred | Ty::Struct(_) => Ok(Ty::Deferred),
            t => t
                .member_ty(name)
                .ok_or_else(|| syn::Error::new(span, format!("`{t}` has no field `{name}`"))),
        }
    }

    pub(super) fn place_ty(&self, p: &Place, span: Span) -> R<Ty> {
        let (mut t, path) = match p {
            Place::Local { var, path } => (self.ty(*var), path),
            Place::Elem { array, path, .. } => match self.ty(*array) {
                Ty::Array(e, _) => (*e, path),
                _ => (Ty::Deferred, path),
            },
        };
        for m in path {
            t = self.member_ty(&t, m, span)?;
        }
        Ok(t)
    }

    pub(super) fn read_place(&mut self, p: &Place, ty: Ty, span: Span) -> VarId {
        let (mut v, path) = match p {
            Place::Local { var, path } => (*var, path.clone()),
            Place::Elem { array, index, path } => {
                let elem = match self.ty(*array) {
                    Ty::Array(e, _) => *e,
                    _ => Ty::Deferred,
                };
                (
                    self.def(
                        Op::Load {
                            array: *array,
                            index: index.clone(),
                        },
                        elem,
                        span,
                    ),
                    path.clone(),
                )
            }
        };
        let n = path.len();
        for (k, m) in path.into_iter().enumerate() {
            let t = if k + 1 == n {
                ty.clone()
            } else {
                self.member_ty(&self.ty(v), &m, span)
                    .unwrap_or(Ty::Deferred)
            };
            v = self.def(Op::Member(v, m), t, span);
        }
        v
    }

    pub(super) fn write_place(&mut self, p: Place, value: VarId, span: Span) {
        match p {
            Place::Local { var, path } if path.is_empty() => self.push(
                StmtKind::Assign {
                    dst: var,
                    op: Op::Copy(value),
                    define: false,
                },
                span,
            ),
            Place::Local { var, path } => self.push(StmtKind::SetMember { var, path, value }, span),
            Place::Elem { array, index, path } if path.is_empty() => self.push(
                StmtKind::Store {
                    array,
                    index,
                    value,
                },
                span,
            ),
            Place::Elem { array, index, path } => {
                let elem = match self.ty(array) {
                    Ty::Array(e, _) => *e,
                    _ => Ty::Deferred,
                };
                let old = self.def(
                    Op::Load {
                        array,
                        index: index.clone(),
                    },
                    elem.clone(),
                    span,
                );
                let tmp = self.new_var(None, elem, true);
                self.push(
                    StmtKind::Assign {
                        dst: tmp,
                        op: Op::Copy(old),
                        define: true,
                    },
                    span,
                );
                self.push(
                    StmtKind::SetMember {
                        var: tmp,
                        path,
                        value,
                    },
                    span,
                );
                self.push(
                    StmtKind::Store {
                        array,
                        index,
                        value: tmp,
                    },
                    span,
                );
            }
        }
    }

    /// The type of a place expression as far as locals, fields and indices show it, without
    /// lowering anything (how `place` tells `v[3] = x` of a spatial value from an array store).
    fn peek_place_ty(&self, e: &Expr) -> Option<Ty> {
        match strip(e) {
            Expr::Path(p) => Some(self.ty(self.lookup(&p.path.get_ident()?.to_string())?)),
            Expr::Field(f) => match &f.member {
                syn::Member::Named(m) => self.peek_place_ty(&f.base)?.member_ty(&m.to_string()),
                syn::Member::Unnamed(_) => None,
            },
            Expr::Index(ix) => match self.peek_place_ty(&ix.expr)? {
                Ty::Array(e, _) => Some(*e),
                t => spatial_index(&t, &ix.index)
                    .ok()??
                    .iter()
                    .try_fold(t, |t, m| t.member_ty(m)),
            },
            _ => None,
        }
    }

    /// `a[i]`, `a[(i, j)]`: the array variable and one index variable per dimension.
    pub(super) fn array_index(&mut self, ix: &syn::ExprIndex) -> R<(VarId, Vec<VarId>)> {
        let array = self.expr(&ix.expr, None)?;
        self.array_index_at(array, ix)
    }

    /// [`Lowerer::array_index`] of the already lowered `array` (`ix.expr`).
    pub(super) fn array_index_at(
        &mut self,
        array: VarId,
        ix: &syn::ExprIndex,
    ) -> R<(VarId, Vec<VarId>)> {
        let at = self.ty(array);
        let ndim = match &at {
            Ty::Array(_, n) => *n,
            Ty::Deferred => return err(ix.expr.span(), "only arrays can be indexed"),
            t @ (Ty::Vector(..) | Ty::Quat(_)) => {
                return err(
                    ix.expr.span(),
                    format!("`{t}` cannot be indexed: vectors use .x .y .z .w"),
                )
            }
            t => return err(ix.expr.span(), format!("`{t}` cannot be indexed")),
        };
        let index = self.index_vars(&ix.index, ndim)?;
        Ok(self.resolve_view(array, index, ix.span()))
    }

    pub(super) fn index_vars(&mut self, e: &Expr, ndim: u8) -> R<Vec<VarId>> {
        let parts: Vec<&Expr> = match strip(e) {
            Expr::Tuple(t) => t.elems.iter().collect(),
            other => vec![other],
        };
        if parts.len() != ndim as usize {
            let example = ["i", "(i, j)", "(i, j, k)", "(i, j, k, l)"][ndim as usize - 1];
            return err(
                e.span(),
                format!("this array has {ndim} dimension(s): index it as a[{example}]"),
            );
        }
        let mut out = Vec::new();
        for p in parts {
            let v = self.expr(p, Some(&USIZE))?;
            let t = self.ty(v);
            if !(t.is_deferred() || t.is_int_scalar()) {
                return err(p.span(), format!("array indices are integers, found `{t}`"));
            }
            out.push(v);
        }
        Ok(out)
    }
}

/// The members `base[index]` names where `base` is a spatial value: lane `k` of a spatial
/// vector (`v[k]`: `["k"]`), row `i` of a spatial matrix (`m[i]`) or its entry (`m[(i, j)]`:
/// `["i", "j"]`; `m[i][j]` is the row's lane). Indices are integer literals, checked here: a
/// lane is a field of the type on both back ends, so no index is checked at run time. `None`
/// for a base of another type.
pub(super) fn spatial_index(base: &Ty, index: &Expr) -> R<Option<Vec<String>>> {
    let (what, parts) = match base {
        Ty::SpatialVector(_) => ("a spatial vector's lane", 1),
        Ty::SpatialMatrix(_) => ("a spatial matrix's row", 2),
        _ => return Ok(None),
    };
    let elems: Vec<&Expr> = match strip(index) {
        Expr::Tuple(t) if parts == 2 => t.elems.iter().collect(),
        e => vec![e],
    };
    if elems.len() > parts {
        return err(
            index.span(),
            "a spatial matrix takes two indices, `m[(i, j)]`",
        );
    }
    let mut lanes = Vec::new();
    for e in elems {
        let k = match strip(e) {
            Expr::Lit(syn::ExprLit {
                lit: syn::Lit::Int(i),
                ..
            }) => i.base10_parse::<u64>().ok(),
            _ => None,
        };
        match k {
            Some(k) if k < 6 => lanes.push(k.to_string()),
            Some(k) => {
                return err(
                    e.span(),
                    format!("index {k} is out of range: {what} is 0 to 5"),
                )
            }
            None => {
                return err(
                    e.span(),
                    format!("{what} is indexed by an integer literal, 0 to 5 (`v[3]`, `m[(1, 2)]`): a run-time index is not supported"),
                )
            }
        }
    }
    Ok(Some(lanes))
}

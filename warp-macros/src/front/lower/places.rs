//! Places: what can be assigned (a local, an array element, and a path of fields and local
//! array elements of either), `=` and the compound assignments, reading and writing a place
//! (writing a field of an array element loads, sets and stores the element; writing inside
//! an element of a local array reads, sets and writes back the element), the types of
//! members, array indexing with one index variable per dimension, and the lanes of vectors,
//! quaternions and matrices (`v[i]`, `m[(i, j)]`: members at literal indices, elements at
//! run-time ones, as a local array's).

use super::typing::flex_literal;

/// The field names of a path of fields.
fn fields(path: &[Step]) -> Vec<String> {
    let name = |s: &Step| match s {
        Step::Field(m) => Some(m.clone()),
        Step::Elem(_) => None,
    };
    path.iter().filter_map(name).collect()
}
use super::*;
use crate::operators::binary_result;

/// What `a[i]` indexes.
pub(super) enum Indexed {
    /// An array (after resolving views), one index variable per dimension.
    View(VarId, Vec<VarId>),
    /// A local array and the index.
    Local(VarId, VarId),
}

/// A step of a local's place: a field, or an element of a local array.
#[derive(Clone)]
pub(super) enum Step {
    Field(String),
    Elem(VarId),
}

/// An assignable place: a local or an array element, with a path of fields and local array
/// elements (a struct's array field, `ps[i].w[k]`).
pub(super) enum Place {
    Local {
        var: VarId,
        path: Vec<Step>,
    },
    Elem {
        array: VarId,
        index: Vec<VarId>,
        path: Vec<Step>,
    },
}

impl Place {
    fn path_mut(&mut self) -> &mut Vec<Step> {
        match self {
            Place::Local { path, .. } | Place::Elem { path, .. } => path,
        }
    }
}

impl Lowerer {
    pub(super) fn assign(
        &mut self,
        lhs: &Expr,
        op: Option<BinOp>,
        rhs: &Expr,
        span: Span,
    ) -> R<()> {
        // `(a, b) = (b, a)`, `(*x, *y) = f(..)`: Rust's destructuring assignment.
        if let Expr::Tuple(t) = strip(lhs) {
            if op.is_some() {
                return err(
                    span,
                    "a tuple cannot be the target of a compound assignment",
                );
            }
            let value = self.expr(rhs, None)?;
            let mut leaves = Vec::new();
            self.tuple_leaves(t, value, &mut leaves)?;
            // Every element is read before any place is written, as Rust evaluates the
            // right-hand side whole first: `(t.1, t.0) = t` swaps.
            for (target, v) in leaves {
                self.store_value(target, v, span)?;
            }
            return Ok(());
        }
        if let Some(v) = self.ref_param(lhs) {
            let name = self.vars[v].name.clone().unwrap_or_default();
            return err(
                lhs.span(),
                format!(
                    "`{name}` is a `&mut {}`: assign through it, `*{name} = ..`",
                    self.ty(v)
                ),
            );
        }
        let place = self.place(lhs)?;
        let place_ty = self.place_ty(&place, lhs.span())?;
        // Current value, for compound assignment.
        let value = match op {
            None => {
                let v = self.expr(rhs, Some(&place_ty))?;
                let vt = self.ty(v);
                if !vt.is_deferred() && !place_ty.is_deferred() && vt != place_ty {
                    self.learn_for_place(&place, &vt);
                    self.learn_literal_type(v, &place_ty);
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
                let res = binary_result(op, &place_ty, &rt);
                if !matches!(&res, Ok(t) if t.is_deferred() || place_ty.is_deferred() || *t == place_ty)
                {
                    self.learn_for_place(&place, &rt);
                    self.learn_literal_type(r, &place_ty);
                }
                let res = res.map_err(|m| syn::Error::new(span, m))?;
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

    /// The places of a destructuring assignment's tuple `t` with the elements of `value`
    /// they receive (read now, in order), `_` skipped, nested tuples in turn. A value the
    /// macro cannot type (a func's result) is copied into a tuple of the pattern's length,
    /// which rustc then checks.
    fn tuple_leaves<'e>(
        &mut self,
        t: &'e syn::ExprTuple,
        mut value: VarId,
        leaves: &mut Vec<(&'e Expr, VarId)>,
    ) -> R<()> {
        let n = t.elems.len();
        let tys = match self.ty(value) {
            Ty::Tuple(tys) if tys.len() == n => tys,
            Ty::Deferred => {
                let ty = Ty::Tuple(vec![Ty::Deferred; n]);
                value = self.def(Op::Copy(value), ty, t.span());
                vec![Ty::Deferred; n]
            }
            other => {
                return err(
                    t.span(),
                    format!(
                        "this assignment destructures {n} value(s), but the value is a `{other}`"
                    ),
                )
            }
        };
        for (k, (el, ty)) in t.elems.iter().zip(tys).enumerate() {
            let el = strip(el);
            if matches!(el, Expr::Infer(_)) {
                continue;
            }
            let v = self.def(Op::Member(value, k.to_string()), ty, el.span());
            match el {
                Expr::Tuple(inner) => self.tuple_leaves(inner, v, leaves)?,
                el => leaves.push((el, v)),
            }
        }
        Ok(())
    }

    /// `target = value` for a value already lowered (an element of a destructuring
    /// assignment): the place, its type checked against the value's.
    fn store_value(&mut self, target: &Expr, value: VarId, span: Span) -> R<()> {
        if let Some(v) = self.ref_param(target) {
            let name = self.vars[v].name.clone().unwrap_or_default();
            return err(
                target.span(),
                format!(
                    "`{name}` is a `&mut {}`: assign through it, `*{name}`",
                    self.ty(v)
                ),
            );
        }
        let place = self.place(target)?;
        let place_ty = self.place_ty(&place, target.span())?;
        let vt = self.ty(value);
        if !vt.is_deferred() && !place_ty.is_deferred() && vt != place_ty {
            self.learn_for_place(&place, &vt);
            self.learn_literal_type(value, &place_ty);
            return err(
                target.span(),
                format!("mismatched types: expected `{place_ty}`, found `{vt}`"),
            );
        }
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
            // `*acc`: a func's `&mut` parameter.
            Expr::Unary(u) if matches!(u.op, syn::UnOp::Deref(_)) => match self.ref_param(&u.expr) {
                Some(var) => Ok(Place::Local { var, path: vec![] }),
                None => err(
                    u.span(),
                    "`*` dereferences a func's `&mut` parameter only (`*acc`): kernels have no other references",
                ),
            },
            Expr::Field(f) => {
                // `t.0`: an element of a tuple.
                let m = match &f.member {
                    syn::Member::Named(m) => m.to_string(),
                    syn::Member::Unnamed(i) => i.index.to_string(),
                };
                let mut inner = self.place(&f.base)?;
                inner.path_mut().push(Step::Field(m));
                Ok(inner)
            }
            Expr::Index(ix) => {
                let base = self.peek_place_ty(&ix.expr);
                // `v[i] = x`, `m[(i, j)] += x`, `a[k][3] = x`: lanes of a vector, quaternion
                // or matrix in a place (members at literal indices, elements at others).
                if let Some(t) = base.as_ref().filter(|t| t.lane_elems().is_some()) {
                    let mut inner = self.place(&ix.expr)?;
                    let steps = self.lane_steps(t, &ix.index)?;
                    inner.path_mut().extend(steps);
                    return Ok(inner);
                }
                // An element of a local array (or of a struct's array field, whose type only
                // the target compilers see): a step of the array's own place.
                if let Some(Ty::LocalArray(..) | Ty::Deferred) = base {
                    let mut inner = self.place(&ix.expr)?;
                    let i = self.local_index(&ix.index)?;
                    inner.path_mut().push(Step::Elem(i));
                    return Ok(inner);
                }
                match self.array_index(ix)? {
                    Indexed::View(array, index) => Ok(Place::Elem {
                        array,
                        index,
                        path: vec![],
                    }),
                    Indexed::Local(..) => err(
                        ix.expr.span(),
                        "cannot assign to an element of this array: it is a temporary value, \
                         bind it with `let mut` first",
                    ),
                }
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
            Place::Local { var, path } => (self.ty(*var), path.clone()),
            Place::Elem { array, path, .. } => match self.ty(*array) {
                Ty::Array(e, _) => (*e, path.clone()),
                _ => (Ty::Deferred, path.clone()),
            },
        };
        for step in &path {
            t = match step {
                Step::Field(m) => self.member_ty(&t, m, span)?,
                Step::Elem(_) => match t {
                    Ty::LocalArray(e, _) => *e,
                    Ty::Deferred => Ty::Deferred,
                    t => match t.lane_elems() {
                        Some((e, _)) => e,
                        None => return err(span, format!("`{t}` cannot be indexed")),
                    },
                },
            };
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
        for (k, step) in path.into_iter().enumerate() {
            let t = if k + 1 == n {
                ty.clone()
            } else {
                match &step {
                    Step::Field(m) => self.member_ty(&self.ty(v), m, span),
                    Step::Elem(_) => Ok(self.local_elem_ty(v)),
                }
                .unwrap_or(Ty::Deferred)
            };
            let op = match step {
                Step::Field(m) => Op::Member(v, m),
                Step::Elem(index) => Op::Index { array: v, index },
            };
            v = self.def(op, t, span);
        }
        v
    }

    pub(super) fn write_place(&mut self, p: Place, value: VarId, span: Span) {
        match p {
            Place::Local { var, path } => self.write_local(var, &path, value, span),
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
                self.write_local(tmp, &path, value, span);
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
    /// lowering anything: how `place` tells a spatial value's lane (`v[3] = x`) and a local
    /// array's element (`a[i] = x`, `a[i][3] = x`) from an array store.
    fn peek_place_ty(&self, e: &Expr) -> Option<Ty> {
        match strip(e) {
            Expr::Path(p) => Some(self.ty(self.lookup(&p.path.get_ident()?.to_string())?)),
            Expr::Unary(u) if matches!(u.op, syn::UnOp::Deref(_)) => {
                self.ref_param(&u.expr).map(|v| self.ty(v))
            }
            Expr::Field(f) => match (&f.member, self.peek_place_ty(&f.base)?) {
                // A struct's field: its type is the target compilers' to see.
                (syn::Member::Named(_), Ty::Struct(_) | Ty::Deferred) => Some(Ty::Deferred),
                (syn::Member::Named(m), t) => t.member_ty(&m.to_string()),
                (syn::Member::Unnamed(i), t) => t.member_ty(&i.index.to_string()),
            },
            Expr::Index(ix) => match self.peek_place_ty(&ix.expr)? {
                Ty::Array(e, _) | Ty::LocalArray(e, _) => Some(*e),
                Ty::Deferred => Some(Ty::Deferred),
                t => lane_index(&t, &ix.index)
                    .ok()??
                    .iter()
                    .try_fold(t, |t, step| match step {
                        LaneStep::Member(m) => t.member_ty(m),
                        LaneStep::Dyn(_) => t.lane_elems().map(|(e, _)| e),
                    }),
            },
            _ => None,
        }
    }

    /// `var.path = value` for a local: an assignment, a member path, or (for a path through a
    /// local array's element) the element read, written at the rest of the path, and set
    /// back; an array reached through fields (a struct's array field, `s.w[k] = v`) is read,
    /// its element written, and set back.
    fn write_local(&mut self, var: VarId, path: &[Step], value: VarId, span: Span) {
        let Some(k) = path.iter().position(|s| matches!(s, Step::Elem(_))) else {
            let path = fields(path);
            let kind = match path.is_empty() {
                true => StmtKind::Assign {
                    dst: var,
                    op: Op::Copy(value),
                    define: false,
                },
                false => StmtKind::SetMember { var, path, value },
            };
            return self.push(kind, span);
        };
        if k > 0 {
            let inner = Place::Local {
                var,
                path: path[..k].to_vec(),
            };
            let ty = self.place_ty(&inner, span).unwrap_or(Ty::Deferred);
            let old = self.read_place(&inner, ty.clone(), span);
            let tmp = self.new_var(None, ty, true);
            let copy = StmtKind::Assign {
                dst: tmp,
                op: Op::Copy(old),
                define: true,
            };
            self.push(copy, span);
            self.write_local(tmp, &path[k..], value, span);
            let path = fields(&path[..k]);
            return self.push(
                StmtKind::SetMember {
                    var,
                    path,
                    value: tmp,
                },
                span,
            );
        }
        let Step::Elem(index) = path[k] else {
            unreachable!("found above")
        };
        let rest = &path[k + 1..];
        let value = if rest.is_empty() {
            value
        } else {
            let elem = self.local_elem_ty(var);
            let old = self.def(Op::Index { array: var, index }, elem.clone(), span);
            let tmp = self.new_var(None, elem, true);
            let copy = StmtKind::Assign {
                dst: tmp,
                op: Op::Copy(old),
                define: true,
            };
            self.push(copy, span);
            self.write_local(tmp, rest, value, span);
            tmp
        };
        self.push(StmtKind::SetElem { var, index, value }, span);
    }

    /// `a[i]`, `a[(i, j)]`: the array variable and one index variable per dimension; or a
    /// local array and its index (`a[i]`). The lanes of a vector, quaternion or matrix
    /// (`v[i]`) are resolved by the callers through [`Lowerer::lane_steps`] before.
    pub(super) fn array_index(&mut self, ix: &syn::ExprIndex) -> R<Indexed> {
        let array = self.expr(&ix.expr, None)?;
        self.array_index_at(array, ix)
    }

    /// [`Lowerer::array_index`] of the already lowered `array` (`ix.expr`).
    pub(super) fn array_index_at(&mut self, array: VarId, ix: &syn::ExprIndex) -> R<Indexed> {
        let at = self.ty(array);
        let ndim = match &at {
            Ty::Array(_, n) => *n,
            Ty::LocalArray(..) => {
                return Ok(Indexed::Local(array, self.local_index(&ix.index)?));
            }
            // A struct's array field or a func's array result: a local array whose type
            // only the target compilers see (rustc refuses any other value there).
            Ty::Deferred => {
                return Ok(Indexed::Local(array, self.local_index(&ix.index)?));
            }
            t => return err(ix.expr.span(), format!("`{t}` cannot be indexed")),
        };
        let index = self.index_vars(&ix.index, ndim)?;
        let (array, index) = self.resolve_view(array, index, ix.span());
        Ok(Indexed::View(array, index))
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

/// One step of `base[index]` into a value with lanes: a member (a literal index, checked when
/// the macro runs) or an element at a run-time index (its expression, checked when it runs).
pub(super) enum LaneStep<'e> {
    Member(String),
    Dyn(&'e Expr),
}

/// The steps `base[index]` takes where `base` is a value with lanes ([`Ty::lane_elems`]):
/// `v[i]` of a vector, quaternion or spatial vector (lane i; a quaternion's in glam's x, y, z,
/// w order); `m[(i, j)]` of a matrix, row i and column j (Warp's `m[i, j]`: for glam's
/// column-major matrices column j then its lane i, for a spatial matrix row i then its lane
/// j); `m[i]` of a spatial matrix (row i, as Warp's and warp-core's `Index`). A glam matrix
/// takes no single index: glam's `m[i]` is column i and Warp's `m[i]` row i, and a port that
/// silently took either would be wrong half the time. `None` for a base of another type.
pub(super) fn lane_index<'e>(base: &Ty, index: &'e Expr) -> R<Option<Vec<LaneStep<'e>>>> {
    if base.lane_elems().is_none() {
        return Ok(None);
    }
    let parts: Vec<&Expr> = match strip(index) {
        Expr::Tuple(t) => t.elems.iter().collect(),
        e => vec![e],
    };
    let parts = match (base, parts.len()) {
        (Ty::Matrix(..), 1) => {
            return err(
                index.span(),
                format!(
                    "`{base}` takes two indices: write `m[(i, j)]` for row i, column j (Warp's \
                     `m[i, j]`), or name a column, `m.x_axis`; a single index is not supported, \
                     as glam's `m[i]` is column i and Warp's `m[i]` is row i"
                ),
            )
        }
        // Column-major: the column first.
        (Ty::Matrix(..), 2) => vec![parts[1], parts[0]],
        (Ty::SpatialMatrix(_) | Ty::MatRC(..), 1 | 2) | (_, 1) => parts,
        (Ty::Matrix(..), _) => {
            return err(
                index.span(),
                format!("`{base}` takes two indices, `m[(i, j)]`: row i, column j"),
            )
        }
        (Ty::SpatialMatrix(_) | Ty::MatRC(..), _) => {
            return err(
                index.span(),
                format!("`{base}` takes one or two indices, `m[i]` (a row) or `m[(i, j)]`"),
            )
        }
        _ => return err(index.span(), format!("`{base}` takes one index, `v[i]`")),
    };
    let mut ty = base.clone();
    let mut steps = Vec::new();
    for e in parts {
        let (elem, n) = ty.lane_elems().expect("a value with lanes");
        let step = match literal_index(e) {
            Some(k) if (0..n as i128).contains(&k) => {
                LaneStep::Member(ty.lane_member(k as usize).expect("in range"))
            }
            Some(k) => {
                return err(
                    e.span(),
                    format!(
                        "index {k} is out of range: `{base}` is indexed 0 to {}",
                        n - 1
                    ),
                )
            }
            None => LaneStep::Dyn(e),
        };
        steps.push(step);
        ty = elem;
    }
    Ok(Some(steps))
}

/// An integer literal index, negated or not (`3`, `-1`).
fn literal_index(e: &Expr) -> Option<i128> {
    match strip(e) {
        Expr::Lit(syn::ExprLit {
            lit: syn::Lit::Int(i),
            ..
        }) => i.base10_parse::<i128>().ok(),
        Expr::Unary(u) if matches!(u.op, syn::UnOp::Neg(_)) => literal_index(&u.expr).map(|k| -k),
        _ => None,
    }
}

impl Lowerer {
    /// [`lane_index`] lowered: the steps of a place (or a read) into `base[index]`, the
    /// run-time indices lowered in source order (`m[(i, j)]` reads `i` first, as Rust
    /// evaluates a tuple, though a glam matrix is stepped into by `j` first).
    pub(super) fn lane_steps(&mut self, base: &Ty, index: &Expr) -> R<Vec<Step>> {
        let lanes = lane_index(base, index)?.expect("a value with lanes");
        let mut dyns: Vec<(usize, &Expr)> = lanes
            .iter()
            .enumerate()
            .filter_map(|(k, s)| match s {
                LaneStep::Dyn(e) => Some((k, *e)),
                LaneStep::Member(_) => None,
            })
            .collect();
        if matches!(base, Ty::Matrix(..)) {
            dyns.reverse();
        }
        let mut index_of = vec![None; lanes.len()];
        for (k, e) in dyns {
            index_of[k] = Some(self.local_index(e)?);
        }
        Ok(lanes
            .into_iter()
            .zip(index_of)
            .map(|(s, i)| match s {
                LaneStep::Member(m) => Step::Field(m),
                LaneStep::Dyn(_) => Step::Elem(i.expect("lowered")),
            })
            .collect())
    }
}

//! Expressions other than calls and control flow: unary and binary operators, casts,
//! fields, indexing and `.shape()[k]`, blocks, paths (locals, Rust's and glam's constants,
//! module-level `const`s), and the refusal, with its reason, of each expression outside the
//! language.

use super::typing::int_range;
use super::*;
use crate::operators::binary_result;

pub(super) fn map_binop(op: &syn::BinOp) -> Option<BinOp> {
    use syn::BinOp as B;
    Some(match op {
        B::Add(_) | B::AddAssign(_) => BinOp::Add,
        B::Sub(_) | B::SubAssign(_) => BinOp::Sub,
        B::Mul(_) | B::MulAssign(_) => BinOp::Mul,
        B::Div(_) | B::DivAssign(_) => BinOp::Div,
        B::Rem(_) | B::RemAssign(_) => BinOp::Rem,
        B::BitAnd(_) | B::BitAndAssign(_) => BinOp::BitAnd,
        B::BitOr(_) | B::BitOrAssign(_) => BinOp::BitOr,
        B::BitXor(_) | B::BitXorAssign(_) => BinOp::BitXor,
        B::Shl(_) | B::ShlAssign(_) => BinOp::Shl,
        B::Shr(_) | B::ShrAssign(_) => BinOp::Shr,
        B::Eq(_) => BinOp::Eq,
        B::Ne(_) => BinOp::Ne,
        B::Lt(_) => BinOp::Lt,
        B::Le(_) => BinOp::Le,
        B::Gt(_) => BinOp::Gt,
        B::Ge(_) => BinOp::Ge,
        _ => return None,
    })
}

pub(super) fn is_compound_assign(op: &syn::BinOp) -> bool {
    use syn::BinOp as B;
    matches!(
        op,
        B::AddAssign(_)
            | B::SubAssign(_)
            | B::MulAssign(_)
            | B::DivAssign(_)
            | B::RemAssign(_)
            | B::BitAndAssign(_)
            | B::BitOrAssign(_)
            | B::BitXorAssign(_)
            | B::ShlAssign(_)
            | B::ShrAssign(_)
    )
}

/// Constants reachable as paths: `f32::MAX`, `std::f64::consts::PI`, `i32::MIN`, ...
fn path_constant(segments: &[String]) -> Option<(Scalar, f64, Option<i128>)> {
    let scalar_pos = segments
        .iter()
        .position(|s| Scalar::from_name(s).is_some())?;
    let s = Scalar::from_name(&segments[scalar_pos])?;
    let rest: Vec<&str> = segments[scalar_pos + 1..]
        .iter()
        .map(|x| x.as_str())
        .collect();
    let name = match rest.as_slice() {
        [n] => *n,
        ["consts", n] => *n,
        _ => return None,
    };
    if matches!(s, Scalar::F16 | Scalar::BF16) {
        // `half`'s constants (`f16::MAX`, `bf16::PI`, ...); the value is rounded to the type
        // where it is emitted.
        let bf = s == Scalar::BF16;
        let bf16_max = (2.0 - 2f64.powi(-7)) * 2f64.powi(127);
        let v = match name {
            "MAX" if bf => bf16_max,
            "MIN" if bf => -bf16_max,
            "EPSILON" if bf => 2f64.powi(-7),
            "MIN_POSITIVE" if bf => 2f64.powi(-126),
            "MIN_POSITIVE_SUBNORMAL" if bf => 2f64.powi(-133),
            "MAX" => 65504.0,
            "MIN" => -65504.0,
            "EPSILON" => 2f64.powi(-10),
            "MIN_POSITIVE" => 2f64.powi(-14),
            "MIN_POSITIVE_SUBNORMAL" => 2f64.powi(-24),
            "ZERO" => 0.0,
            "NEG_ZERO" => -0.0,
            "ONE" => 1.0,
            "NEG_ONE" => -1.0,
            _ => {
                return path_constant(&["f64".to_string(), name.to_string()])
                    .map(|(_, v, _)| (s, v, None))
            }
        };
        return Some((s, v, None));
    }
    if s.is_float() {
        let f32 = s == Scalar::F32;
        let v = match name {
            "MAX" => {
                if f32 {
                    f32::MAX as f64
                } else {
                    f64::MAX
                }
            }
            "MIN" => {
                if f32 {
                    f32::MIN as f64
                } else {
                    f64::MIN
                }
            }
            "EPSILON" => {
                if f32 {
                    f32::EPSILON as f64
                } else {
                    f64::EPSILON
                }
            }
            "MIN_POSITIVE" => {
                if f32 {
                    f32::MIN_POSITIVE as f64
                } else {
                    f64::MIN_POSITIVE
                }
            }
            "INFINITY" => f64::INFINITY,
            "NEG_INFINITY" => f64::NEG_INFINITY,
            "NAN" => f64::NAN,
            "PI" => std::f64::consts::PI,
            "TAU" => std::f64::consts::TAU,
            "E" => std::f64::consts::E,
            "FRAC_PI_2" => std::f64::consts::FRAC_PI_2,
            "FRAC_PI_4" => std::f64::consts::FRAC_PI_4,
            "SQRT_2" => std::f64::consts::SQRT_2,
            "LN_2" => std::f64::consts::LN_2,
            "LN_10" => std::f64::consts::LN_10,
            _ => return None,
        };
        Some((s, v, None))
    } else if s.is_int() {
        let (min, max) = int_range(s);
        match name {
            "MAX" => Some((s, 0.0, Some(max))),
            "MIN" => Some((s, 0.0, Some(min))),
            _ => None,
        }
    } else {
        None
    }
}

/// A `const`'s name by Rust's convention: SCREAMING_SNAKE_CASE, with a letter.
fn is_const_name(s: &str) -> bool {
    s.chars().any(|c| c.is_ascii_uppercase())
        && s.chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
}

impl Lowerer {
    /// Lowers an expression to a variable holding its value. `want` is the type the context
    /// expects (it types literals; mismatches are reported by the caller).
    pub(super) fn expr(&mut self, e: &Expr, want: Option<&Ty>) -> R<VarId> {
        let span = e.span();
        match e {
            Expr::Lit(l) => self.literal(&l.lit, false, want, span),
            Expr::Paren(p) => self.expr(&p.expr, want),
            Expr::Group(g) => self.expr(&g.expr, want),
            Expr::Unary(u) => match u.op {
                syn::UnOp::Neg(_) => {
                    if let Expr::Lit(l) = strip(&u.expr) {
                        if matches!(l.lit, syn::Lit::Int(_) | syn::Lit::Float(_)) {
                            return self.literal(&l.lit, true, want, span);
                        }
                    }
                    let v = self.expr(&u.expr, want)?;
                    let t = self.ty(v);
                    let ok = match &t {
                        Ty::Scalar(s) => s.is_float() || s.is_signed_int(),
                        Ty::Vector(s, _) => *s != Scalar::U32,
                        Ty::Matrix(..)
                        | Ty::Quat(_)
                        | Ty::Transform(_)
                        | Ty::SpatialVector(_)
                        | Ty::SpatialMatrix(_)
                        | Ty::MatRC(..)
                        | Ty::Deferred => true,
                        Ty::Tile(e, _) => {
                            matches!(**e, Ty::Scalar(s) if s.is_float() || s.is_signed_int())
                        }
                        _ => false,
                    };
                    if !ok {
                        return err(span, format!("cannot negate `{t}`"));
                    }
                    Ok(self.def(Op::Unary(UnOp::Neg, v), t, span))
                }
                syn::UnOp::Not(_) => {
                    let v = self.expr(&u.expr, want)?;
                    let t = self.ty(v);
                    let int_or_bool =
                        |t: &Ty| matches!(t, Ty::Scalar(s) | Ty::Vector(s, _) if !s.is_float());
                    if !(t.is_deferred() || int_or_bool(&t)) {
                        return err(span, format!("cannot apply `!` to `{t}`"));
                    }
                    Ok(self.def(Op::Unary(UnOp::Not, v), t, span))
                }
                // `*acc`: the value of a func's `&mut` parameter.
                syn::UnOp::Deref(_) => match self.ref_param(&u.expr) {
                    Some(v) => Ok(v),
                    None => err(
                        span,
                        "`*` dereferences a func's `&mut` parameter only (`*acc`): kernels have no other references",
                    ),
                },
                _ => err(span, "this operator is not supported in kernels"),
            },
            Expr::Binary(b) => {
                if is_compound_assign(&b.op) {
                    return err(span, "compound assignment is a statement, not a value");
                }
                match b.op {
                    syn::BinOp::And(_) | syn::BinOp::Or(_) => self.short_circuit(b),
                    _ => {
                        let op = map_binop(&b.op)
                            .ok_or_else(|| syn::Error::new(span, "unsupported operator"))?;
                        let hint = if op.is_comparison() { None } else { want };
                        let (l, r) = self.operand_pair(&b.left, &b.right, hint, op)?;
                        let res = match binary_result(op, &self.ty(l), &self.ty(r)) {
                            Ok(res) => res,
                            Err(m) => {
                                self.learn_from_pair(l, r);
                                return err(b.op.span(), m);
                            }
                        };
                        // Tile shapes the macro cannot compare: rustc's.
                        if let (Ty::Tile(_, dl), Ty::Tile(_, dr)) = (self.ty(l), self.ty(r)) {
                            let msg = format!(
                                "`{}` on tiles of different shapes: `{}` and `{}`",
                                op.symbol(),
                                self.ty(l),
                                self.ty(r)
                            );
                            self.same_shapes(&dl, &dr, b.op.span(), msg)?;
                        }
                        Ok(self.def(Op::Binary(op, l, r), res, span))
                    }
                }
            }
            Expr::Path(p) => self.path_expr(p, span),
            Expr::Cast(c) => {
                let target = parse_type(&c.ty)?;
                let Ty::Scalar(ts) = target else {
                    return err(c.ty.span(), "`as` casts are between scalar types only");
                };
                let v = self.expr(&c.expr, None)?;
                let t = self.ty(v);
                let ok = match &t {
                    Ty::Deferred => true,
                    Ty::Scalar(s) => *s != Scalar::Bool || ts.is_int(),
                    _ => false,
                };
                if !ok {
                    return err(span, format!("cannot cast `{t}` as `{target}`"));
                }
                Ok(self.def(Op::Cast(v, target.clone()), target, span))
            }
            Expr::Call(c) => self.call(c, want),
            Expr::MethodCall(m) => self.method_call(m, want),
            Expr::Field(f) => {
                let (name, name_span) = match &f.member {
                    syn::Member::Named(n) => (n.to_string(), n.span()),
                    // `t.0`: an element of a tuple (a func's tuple result is one, unseen).
                    syn::Member::Unnamed(i) => (i.index.to_string(), i.span),
                };
                let base = self.base_expr(&f.base)?;
                let bt = self.ty(base);
                if matches!(bt, Ty::Array(..) | Ty::LocalArray(..)) {
                    return err(span, "arrays have no fields: index them, `a[i]`");
                }
                if matches!(f.member, syn::Member::Unnamed(_))
                    && !matches!(bt, Ty::Tuple(_) | Ty::Deferred | Ty::Struct(_))
                {
                    return err(name_span, format!("`{bt}` is no tuple: `.{name}` reads a tuple's element"));
                }
                let t = self.member_ty(&bt, &name, name_span)?;
                Ok(self.def(Op::Member(base, name), t, span))
            }
            Expr::Index(ix) => {
                if let Expr::MethodCall(m) = strip(&ix.expr) {
                    if m.method == "shape" && m.args.is_empty() {
                        let a = self.expr(&m.receiver, None)?;
                        let Ty::Array(_, n) = self.ty(a) else {
                            return err(m.receiver.span(), "`.shape()` is defined on arrays");
                        };
                        let k = match strip(&ix.index) {
                            Expr::Lit(syn::ExprLit {
                                lit: syn::Lit::Int(i),
                                ..
                            }) => i.base10_parse::<u8>()?,
                            other => {
                                return err(
                                    other.span(),
                                    "index `.shape()` with a literal dimension",
                                )
                            }
                        };
                        if k >= n {
                            return err(ix.index.span(), format!("the array has {n} dimension(s)"));
                        }
                        if self.is_view(a) {
                            return Ok(self.view_extent(a, k, span));
                        }
                        return Ok(self.def(Op::Extent(a, k), USIZE, span));
                    }
                }
                // `t[i]` of a tile variable.
                if let Expr::Path(p) = strip(&ix.expr) {
                    let tile = p
                        .path
                        .get_ident()
                        .and_then(|i| self.lookup(&i.to_string()))
                        .filter(|v| self.ty(*v).is_tile());
                    if let Some(t) = tile {
                        return self.tile_index(t, &ix.index, span);
                    }
                }
                let base = self.base_expr(&ix.expr)?;
                // `v[i]`, `q[3]`, `m[(i, j)]`, `sm[i][j]`: lanes of a vector, quaternion or
                // matrix (members at literal indices, checked elements at run-time ones).
                let base_ty = self.ty(base);
                if base_ty.lane_elems().is_some() {
                    let mut v = base;
                    for step in self.lane_steps(&base_ty, &ix.index)? {
                        v = match step {
                            places::Step::Field(m) => {
                                let t = self.member_ty(&self.ty(v), &m, span)?;
                                self.def(Op::Member(v, m), t, span)
                            }
                            places::Step::Elem(index) => {
                                let t = self.local_elem_ty(v);
                                self.def(Op::Index { array: v, index }, t, span)
                            }
                        };
                    }
                    return Ok(v);
                }
                let (array, index) = match self.array_index_at(base, ix)? {
                    places::Indexed::View(array, index) => (array, index),
                    places::Indexed::Local(array, index) => {
                        let elem = self.local_elem_ty(array);
                        return Ok(self.def(Op::Index { array, index }, elem, span));
                    }
                };
                let t = match self.ty(array) {
                    Ty::Array(e, _) => *e,
                    _ => Ty::Deferred,
                };
                Ok(self.def(Op::Load { array, index }, t, span))
            }
            Expr::If(i) => self.if_expr(i, true, want).map(|v| v.expect("value if")),
            Expr::Block(b) => {
                if b.label.is_some() {
                    return err(span, "block labels are not supported in kernels");
                }
                let (block, v) = self.in_block(|cx| cx.block_stmts(&b.block.stmts, want, true))?;
                self.blocks.last_mut().expect("block").extend(block);
                v.ok_or_else(|| syn::Error::new(span, "this block yields no value"))
            }
            Expr::Closure(_) => err(
                span,
                "closures are not supported in kernels: write a #[func]",
            ),
            Expr::Reference(_) => err(
                span,
                "references are not supported in kernels: pass values and arrays directly",
            ),
            Expr::Array(a) => self.array_literal(a, want, span),
            Expr::Repeat(r) => self.array_repeat(r, want, span),
            Expr::Tuple(t) => self.tuple_expr(t, want, span),
            Expr::Match(_) => err(span, "`match` is not supported in kernels: use if / else"),
            Expr::Struct(s) => self.struct_literal(s, span),
            Expr::Range(_) => err(span, "ranges are only supported as `for` loop bounds"),
            Expr::Try(_) => err(span, "`?` is not supported in kernels"),
            Expr::Async(_) | Expr::Await(_) => err(span, "async is not supported in kernels"),
            Expr::Unsafe(_) => err(span, "`unsafe` blocks are not supported in kernels"),
            Expr::Macro(m) => {
                let name = m
                    .mac
                    .path
                    .segments
                    .last()
                    .map(|s| s.ident.to_string())
                    .unwrap_or_default();
                if name == "vec" || name == "format" {
                    err(
                        span,
                        format!("`{name}!` allocates on the heap, which kernels cannot do"),
                    )
                } else {
                    err(
                        span,
                        format!("macro `{name}!` cannot be used as a value in kernels"),
                    )
                }
            }
            Expr::Assign(_) => err(span, "assignment is a statement, not a value"),
            Expr::While(_) | Expr::ForLoop(_) | Expr::Loop(_) => {
                err(span, "loops do not yield values in kernels")
            }
            Expr::Return(_) | Expr::Break(_) | Expr::Continue(_) => {
                err(span, "control flow is a statement, not a value")
            }
            _ => err(span, "this expression is not supported in kernels"),
        }
    }

    fn path_expr(&mut self, p: &syn::ExprPath, span: Span) -> R<VarId> {
        if p.qself.is_some() {
            return err(span, "qualified paths are not supported in kernels");
        }
        if let Some(id) = p.path.get_ident() {
            let name = id.to_string();
            if let Some(v) = self.lookup(&name) {
                if self.ref_params.contains(&v) {
                    return err(
                        span,
                        format!(
                            "`{name}` is a `&mut {}`: its value is `*{name}`",
                            self.ty(v)
                        ),
                    );
                }
                return Ok(v);
            }
            if is_const_name(&name) {
                return Ok(self.user_const(&p.path, span));
            }
            return err(span, format!("cannot find `{name}` in this kernel: kernels see their parameters, locals and module-level `const`s (SCREAMING_CASE; use a parameter for other outside values)"));
        }
        let segs: Vec<String> = p
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        if let Some((s, f, i)) = path_constant(&segs) {
            let lit = match i {
                Some(i) => Lit::Int(i),
                None => Lit::Float(f),
            };
            return Ok(self.def(Op::Lit(lit), Ty::Scalar(s), span));
        }
        // `Vec3::ZERO`, `Mat3::IDENTITY`, `Quat::IDENTITY`.
        if segs.len() >= 2 {
            if let Some(ty) = Ty::from_glam_name(&segs[segs.len() - 2]) {
                let name = segs[segs.len() - 1].clone();
                let known = match &ty {
                    Ty::Vector(..) => [
                        "ZERO", "ONE", "NEG_ONE", "X", "Y", "Z", "W", "NEG_X", "NEG_Y", "NEG_Z",
                        "NEG_W", "MIN", "MAX", "INFINITY", "NAN",
                    ]
                    .contains(&name.as_str()),
                    Ty::Matrix(..) => ["ZERO", "IDENTITY", "NAN"].contains(&name.as_str()),
                    Ty::Quat(_) => ["IDENTITY", "NAN"].contains(&name.as_str()),
                    Ty::Transform(_) => name == "IDENTITY",
                    Ty::SpatialVector(_) => name == "ZERO",
                    Ty::SpatialMatrix(_) => ["ZERO", "IDENTITY"].contains(&name.as_str()),
                    Ty::MatRC(..) => name == "ZERO",
                    _ => false,
                };
                if !known {
                    return err(span, format!("`{ty}::{name}` is not supported in kernels"));
                }
                return Ok(self.def(
                    Op::Construct {
                        ty: ty.clone(),
                        ctor: Ctor::Const(name),
                        args: vec![],
                    },
                    ty,
                    span,
                ));
            }
        }
        if segs.last().is_some_and(|s| is_const_name(s)) {
            return Ok(self.user_const(&p.path, span));
        }
        err(
            span,
            "paths to outside items other than `const`s are not supported in kernels: pass the value as a parameter",
        )
    }

    /// `(a, b, ..)`: a tuple of the values (each typed by `want`'s element, if any).
    fn tuple_expr(&mut self, t: &syn::ExprTuple, want: Option<&Ty>, span: Span) -> R<VarId> {
        let wants: Vec<Option<Ty>> = match want {
            Some(Ty::Tuple(ws)) if ws.len() == t.elems.len() => {
                ws.iter().cloned().map(Some).collect()
            }
            _ => vec![None; t.elems.len()],
        };
        let mut elems = Vec::new();
        for (e, w) in t.elems.iter().zip(&wants) {
            elems.push(self.expr(e, w.as_ref())?);
        }
        let tys = elems.iter().map(|v| self.ty(*v)).collect();
        let ty = crate::front::signature::tuple_type(tys, span)?;
        Ok(self.def(Op::Tuple(elems), ty, span))
    }

    /// A module-level `const` (Warp's `wp.constant`): its value on the CPU is the const
    /// itself; the CUDA source gets it at assembly. Its type is the const's (`Deferred` here).
    pub(super) fn user_const(&mut self, path: &syn::Path, span: Span) -> VarId {
        self.note_const(path);
        self.def(Op::Const(path.clone()), Ty::Deferred, span)
    }
}

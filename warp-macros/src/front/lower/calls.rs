//! Calls: builtins in function syntax (`max(a, b)`, `wp::max(a, b)`), method syntax
//! (`x.sqrt()`, aliases such as `x.powf(y)`) and path form (`f32::sqrt(x)`); glam's
//! constructors (`Vec3::new`, `vec3(..)`, `Mat3::from_cols`) and those that are builtins
//! (`Quat::from_axis_angle`); Warp's overloads by arity and keyword defaults; Warp's builtins
//! that are other operations here (`div_approx`, `inverse_approx`); `tid()`; user `#[func]`s;
//! and the matching of a call's arguments against a builtin's signature (literals typed from
//! it, array indices, atomics on views, `mod` as `%`).

use super::typing::{flex_literal, flex_value};
use super::*;

/// `vec3(..)`, `dvec2(..)`, `ivec4(..)`, `uvec3(..)`: glam's constructor functions.
fn lower_ctor_fn(name: &str) -> Option<Ty> {
    let (scalar, rest) = if let Some(r) = name.strip_prefix("dvec") {
        (Scalar::F64, r)
    } else if let Some(r) = name.strip_prefix("ivec") {
        (Scalar::I32, r)
    } else if let Some(r) = name.strip_prefix("uvec") {
        (Scalar::U32, r)
    } else if let Some(r) = name.strip_prefix("vec") {
        (Scalar::F32, r)
    } else {
        return None;
    };
    let n: u8 = rest.parse().ok().filter(|n| (2..=4).contains(n))?;
    Some(Ty::Vector(scalar, n))
}

/// The first identifier in `e`'s tokens for which `hit` holds (a conservative "reads": any
/// mention, wherever it stands).
fn mentions(e: &Expr, hit: &mut dyn FnMut(&str) -> bool) -> Option<String> {
    fn walk(ts: proc_macro2::TokenStream, hit: &mut dyn FnMut(&str) -> bool) -> Option<String> {
        for t in ts {
            match t {
                proc_macro2::TokenTree::Ident(i) if hit(&i.to_string()) => {
                    return Some(i.to_string())
                }
                proc_macro2::TokenTree::Group(g) => {
                    if let Some(n) = walk(g.stream(), hit) {
                        return Some(n);
                    }
                }
                _ => {}
            }
        }
        None
    }
    walk(quote::ToTokens::to_token_stream(e), hit)
}

/// The name of the companion `#[func]` emits for `wp::grad(f)`: `__wp_grad_f`.
pub(crate) fn companion_of(func: &str) -> String {
    format!("__wp_grad_{func}")
}

fn segs_of(p: &syn::Path) -> Vec<String> {
    p.segments.iter().map(|s| s.ident.to_string()).collect()
}

/// `wp::grad(f)` (or `grad(f)`) as the callee of a call, `wp::grad(f)(x, y)`: the path of the
/// companion `#[func]` emits next to `f` (`__wp_grad_f`, a func of `f`'s parameters that runs
/// `f`'s adjoint with its result's adjoint one, Warp's `wp.grad`), with `f`'s module path and
/// generic arguments. `None` when the callee is something else.
fn grad_of(callee: &Expr) -> R<Option<syn::Path>> {
    let Expr::Call(inner) = strip(callee) else {
        return Ok(None);
    };
    let Expr::Path(g) = strip(&inner.func) else {
        return Ok(None);
    };
    let segs = segs_of(&g.path);
    let is_grad = match segs.as_slice() {
        [one] => one == "grad",
        [facade, one] => crate::paths::names_facade(facade) && one == "grad",
        _ => false,
    };
    if !is_grad {
        return Ok(None);
    }
    let target = match inner.args.iter().collect::<Vec<_>>().as_slice() {
        [a] => match strip(a) {
            Expr::Path(p) if p.qself.is_none() => p.path.clone(),
            other => {
                return err(
                    other.span(),
                    "`wp::grad` takes a `#[func]` by its path: `wp::grad(f)(x, y)`",
                )
            }
        },
        _ => {
            return err(
                inner.span(),
                "`wp::grad` takes one `#[func]`: `wp::grad(f)(x, y)`",
            )
        }
    };
    let mut companion = target;
    let last = companion.segments.last_mut().expect("a path has a segment");
    let name = last.ident.to_string();
    last.ident = syn::Ident::new(&companion_of(&name), last.ident.span());
    Ok(Some(companion))
}

impl Lowerer {
    pub(super) fn call(&mut self, c: &syn::ExprCall, want: Option<&Ty>) -> R<VarId> {
        let span = c.span();
        if let Some(companion) = grad_of(&c.func)? {
            if segs_of(&companion) == [companion_of(&self.fn_name)] {
                return err(
                    span,
                    format!(
                        "recursion is not supported in kernels: `{}` takes its own gradient",
                        self.fn_name
                    ),
                );
            }
            return self.func_call(c, &companion, span);
        }
        let Expr::Path(fp) = strip(&c.func) else {
            return err(
                c.func.span(),
                "only functions named by a path can be called in kernels",
            );
        };
        let segs = segs_of(&fp.path);
        // `r#mod(a, b)`: a raw identifier names the builtin without its `r#`.
        let last = segs.last().cloned().unwrap_or_default();
        let last = last.strip_prefix("r#").map(str::to_owned).unwrap_or(last);
        let prefix_ok =
            segs.len() == 1 || (segs.len() == 2 && crate::paths::names_facade(&segs[0]));

        if prefix_ok && super::asserts::EXPECTATIONS.contains(&last.as_str()) {
            return Err(super::asserts::expectation_as_value(span, &last));
        }
        if prefix_ok && last == "tid" {
            if !c.args.is_empty() {
                return err(span, "tid() takes no arguments");
            }
            self.use_tid(1, span)?;
            return Ok(self.def(Op::Tid(0), USIZE, span));
        }
        if prefix_ok {
            let fish = match &fp.path.segments.last().expect("a segment").arguments {
                syn::PathArguments::AngleBracketed(a) => Some(a),
                _ => None,
            };
            if let Some(v) = self.tile_call(&last, c, fish, want, span)? {
                return Ok(v);
            }
        }
        // glam constructors: Vec3::new, Vec3::splat, Mat3::from_cols, Quat::from_xyzw, vec3(..)
        if segs.len() >= 2 {
            if let Some(ty) = Ty::from_glam_name(&segs[segs.len() - 2]) {
                // glam constructors that are builtins: `Quat::from_axis_angle(axis, angle)`,
                // `Mat3::from_quat(q)`.
                if let Some(b) = builtins::lookup_ctor(&ty, &last) {
                    let args: Vec<&Expr> = c.args.iter().collect();
                    let v = self.builtin_call(b, &args, want, span)?;
                    let got = self.ty(v);
                    if !got.is_deferred() && got != ty {
                        return err(
                            span,
                            format!(
                                "`{ty}::{last}` makes a `{ty}`, but these arguments make a `{got}`"
                            ),
                        );
                    }
                    return Ok(v);
                }
                return self.construct(ty, &last, c, span);
            }
            // `f32::sqrt(x)`: a builtin in function syntax on a scalar type.
            if Scalar::from_name(&segs[segs.len() - 2]).is_some() {
                if let Some(b) = builtins::lookup_method(&last) {
                    let args: Vec<&Expr> = c.args.iter().collect();
                    return self.builtin_call(b, &args, want, span);
                }
            }
        }
        if segs.len() == 1 {
            if let Some(ty) = lower_ctor_fn(&last) {
                return self.construct(ty, "new", c, span);
            }
        }
        if prefix_ok {
            // Warp's overloads by arity that are rows of their own (`min(v)`).
            if let Some(b) = builtins::lookup_overload(&last, c.args.len()) {
                let args: Vec<&Expr> = c.args.iter().collect();
                return self.builtin_call(b, &args, want, span);
            }
            if let Some(v) = self.rng_call(&last, c, want, span)? {
                return Ok(v);
            }
            if let Some(v) = self.builtin_alias(&last, c, want, span)? {
                return Ok(v);
            }
            if let Some(b) = builtins::lookup_user(&last) {
                let mut args: Vec<&Expr> = c.args.iter().collect();
                // Warp's keyword defaults (`norm_huber(v)` is `norm_huber(v, 1.0)`).
                let default: Option<Expr> = b
                    .default_last
                    .filter(|_| args.len() + 1 == b.params.len())
                    .map(|lit| syn::parse_str(lit).expect("a literal"));
                if let Some(d) = &default {
                    args.push(d);
                }
                let v = self.builtin_call(b, &args, want, span)?;
                if b.iterate.is_some() {
                    return err(
                        span,
                        format!(
                            "a `{0}` is iterated where it is made: `for j in {0}(..) {{ .. }}` (Warp's `{0}_next` loop)",
                            b.name
                        ),
                    );
                }
                return Ok(v);
            }
        }
        // `Type::function(..)` of a type the language does not know.
        if segs.len() >= 2 {
            let ty_name = &segs[segs.len() - 2];
            if ty_name.starts_with(|c: char| c.is_ascii_uppercase()) {
                let heap = [
                    "String", "Vec", "Box", "Rc", "Arc", "HashMap", "BTreeMap", "VecDeque",
                ];
                if heap.contains(&ty_name.as_str()) {
                    return err(span, format!("heap type `{ty_name}` is not supported in kernels: kernels cannot allocate"));
                }
                return err(span, format!("`{ty_name}::{last}` is not supported in kernels: call builtins, #[func]s and glam constructors"));
            }
        }
        // A user #[func].
        if segs.len() == 1 && last == self.fn_name {
            return err(
                span,
                format!("recursion is not supported in kernels: `{last}` calls itself"),
            );
        }
        self.func_call(c, &fp.path, span)
    }

    /// A call of a user `#[func]`. Its parameter types are not visible here: literals are left
    /// to rustc, which types them from the func's signature. A `&mut` argument (`&mut a`, a
    /// field, a lane, an element; in a func, its own `&mut` parameter passed on) is read
    /// before the call and written back after it from the func's result, which is then the
    /// tuple of its declared result and its `&mut` parameters' final values (see
    /// `Function::ret`): the same pure-function-plus-write-back shape as the random draws.
    fn func_call(&mut self, c: &syn::ExprCall, path: &syn::Path, span: Span) -> R<VarId> {
        let mut args = Vec::new();
        // The `&mut` arguments: the place, its type and the variable it is part of.
        let mut outs: Vec<(places::Place, Ty, VarId)> = Vec::new();
        let mut mut_args = 0u64;
        for (k, a) in c.args.iter().enumerate() {
            let Some(place_expr) = self.mut_arg(a)? else {
                let want = flex_literal(a).map(|_| Ty::Deferred);
                args.push(self.expr(a, want.as_ref())?);
                continue;
            };
            let place = self.place(place_expr)?;
            let ty = self.place_ty(&place, place_expr.span())?;
            let root = match &place {
                places::Place::Local { var, .. } => *var,
                places::Place::Elem { array, .. } => *array,
            };
            if outs.iter().any(|o| o.2 == root) {
                return err(
                    a.span(),
                    format!(
                        "`{}` is lent as `&mut` twice in this call (Rust lends a variable mutably once at a time)",
                        self.vars[root].name.as_deref().unwrap_or("this variable")
                    ),
                );
            }
            args.push(self.read_place(&place, ty.clone(), a.span()));
            outs.push((place, ty, root));
            mut_args |= 1u64.checked_shl(k as u32).unwrap_or(0);
        }
        // Rust's borrow rule: no other argument reads a variable lent as `&mut`.
        for a in &c.args {
            if self.mut_arg(a)?.is_some() {
                continue;
            }
            if let Some(name) = mentions(a, &mut |n| {
                self.lookup(n)
                    .is_some_and(|v| outs.iter().any(|o| o.2 == v))
            }) {
                return err(
                    a.span(),
                    format!("`{name}` is lent as `&mut` in this call and cannot be read by another argument: read it into a local before the call"),
                );
            }
        }
        // The func the arguments' types select (overloads, generic funcs: `resolve`).
        let resolved = self.resolve_callee(path, &args, span);
        let path = &resolved;
        if !self.callees.iter().any(|p| p == path) {
            self.callees.push(path.clone());
        }
        self.call_checks.push(CallCheck {
            span,
            path: path.clone(),
            mut_args,
        });
        let call = Op::Func {
            path: path.clone(),
            args,
        };
        let v = self.def(call, Ty::Deferred, span);
        if outs.is_empty() {
            return Ok(v);
        }
        for (k, (place, ty, _)) in outs.into_iter().enumerate() {
            let m = self.def(Op::Member(v, (k + 1).to_string()), ty, span);
            self.write_place(place, m, span);
        }
        Ok(self.def(Op::Member(v, "0".into()), Ty::Deferred, span))
    }

    /// The place a `&mut` argument lends (`&mut a` gives `a`; a func's own `&mut` parameter
    /// `acc`, passed on, gives itself), or `None` for a value argument.
    fn mut_arg<'e>(&self, a: &'e Expr) -> R<Option<&'e Expr>> {
        match strip(a) {
            Expr::Reference(r) if r.mutability.is_some() => {
                if let Some(v) = self.ref_param(&r.expr) {
                    let name = self.vars[v].name.clone().unwrap_or_default();
                    return err(
                        r.span(),
                        format!("`{name}` is a `&mut` already: pass it on as `{name}` (or `&mut *{name}`)"),
                    );
                }
                Ok(Some(&r.expr))
            }
            Expr::Reference(r) => err(
                r.span(),
                "funcs take values (`f(x)`, a copy) or `&mut` places (`f(&mut x)`): a shared reference `&x` is not a kernel value",
            ),
            _ if self.ref_param(a).is_some() => Ok(Some(a)),
            _ => Ok(None),
        }
    }

    /// Warp's builtins that are other operations here: `div_approx(a, b)` is `a / b` and
    /// `inverse_approx(m)` is `inverse(m)` (exact on both backends: see the builtin
    /// reference); and the arities of `lower_bound` that are no row.
    fn builtin_alias(
        &mut self,
        name: &str,
        c: &syn::ExprCall,
        want: Option<&Ty>,
        span: Span,
    ) -> R<Option<VarId>> {
        let args: Vec<&Expr> = c.args.iter().collect();
        let row = |n: &str| builtins::lookup(n).expect("in the table");
        match (name, args.len()) {
            ("lower_bound", n) if n != 2 => err(
                span,
                format!("`lower_bound` takes an array and a value, or an array, a range and a value (`lower_bound(a, v)`, `lower_bound(a, lo, hi, v)`), found {n} argument(s)"),
            ),
            ("div_approx", 2) => {
                let (a, b) = (args[0], args[1]);
                let e: Expr = syn::parse_quote_spanned!(span=> (#a) / (#b));
                let v = self.expr(&e, want)?;
                match self.ty(v).scalar() {
                    Some(s) if !s.is_float() => err(
                        span,
                        format!("`div_approx` divides floats, found `{}`", self.ty(v)),
                    ),
                    _ => Ok(Some(v)),
                }
            }
            ("div_approx", n) => err(span, format!("`div_approx` takes 2 arguments, found {n}")),
            ("inverse_approx", _) => {
                let v = self.builtin_call(row("inverse"), &args, want, span)?;
                match self.ty(v) {
                    Ty::Matrix(..) | Ty::Deferred => Ok(Some(v)),
                    t => err(
                        span,
                        format!("`inverse_approx` takes a matrix (Mat2-4, DMat2-4), found `{t}`"),
                    ),
                }
            }
            _ => Ok(None),
        }
    }

    fn construct(&mut self, ty: Ty, ctor: &str, c: &syn::ExprCall, span: Span) -> R<VarId> {
        if let (Ty::MatRC(..), "new") = (&ty, ctor) {
            return self.matrix_from_scalars(ty, c, span);
        }
        let scalar = Ty::Scalar(ty.scalar().expect("glam types have a scalar"));
        let (ctor_kind, arg_tys): (Ctor, Vec<Ty>) = match (&ty, ctor) {
            (Ty::Vector(_, n), "new") => (Ctor::Components, vec![scalar.clone(); *n as usize]),
            (Ty::Vector(..), "splat") => (Ctor::Splat, vec![scalar.clone()]),
            (Ty::Quat(_), "from_xyzw") => (Ctor::Components, vec![scalar.clone(); 4]),
            (Ty::Matrix(s, n), "from_cols") => {
                (Ctor::Components, vec![Ty::Vector(*s, *n); *n as usize])
            }
            (Ty::Matrix(s, n), "from_diagonal") => (Ctor::Splat, vec![Ty::Vector(*s, *n)]),
            (Ty::SpatialMatrix(s), "from_rows") => {
                (Ctor::Components, vec![Ty::SpatialVector(*s); 6])
            }
            (Ty::MatRC(_, r, _), "from_rows") => {
                let (row, _) = ty.lane_elems().expect("a matrix has rows");
                (Ctor::Components, vec![row; *r as usize])
            }
            _ => {
                return err(
                    c.func.span(),
                    format!("`{ty}::{ctor}` is not supported in kernels"),
                )
            }
        };
        if c.args.len() != arg_tys.len() {
            return err(
                span,
                format!("`{ty}::{ctor}` takes {} argument(s)", arg_tys.len()),
            );
        }
        let mut args = Vec::new();
        for (a, want) in c.args.iter().zip(&arg_tys) {
            let v = self.expr(a, Some(want))?;
            let t = self.ty(v);
            if !t.is_deferred() && t != *want {
                return err(
                    a.span(),
                    format!("mismatched types: expected `{want}`, found `{t}`"),
                );
            }
            args.push(v);
        }
        Ok(self.def(
            Op::Construct {
                ty: ty.clone(),
                ctor: ctor_kind,
                args,
            },
            ty,
            span,
        ))
    }

    pub(super) fn builtin_call(
        &mut self,
        b: &'static Builtin,
        args: &[&Expr],
        _want: Option<&Ty>,
        span: Span,
    ) -> R<VarId> {
        if args.len() != b.params.len() {
            return err(
                span,
                format!(
                    "`{}` takes {} argument(s), found {}",
                    b.name,
                    b.params.len(),
                    args.len()
                ),
            );
        }
        // First pass: everything but unsuffixed literals (and index tuples), in order.
        let mut vals: Vec<Option<Vec<VarId>>> = vec![None; args.len()];
        let mut arg_tys: Vec<ArgTy> = Vec::new();
        let mut array_ndim = 1u8;
        for (i, (a, pos)) in args.iter().zip(b.params).enumerate() {
            if *pos == Pos::Index {
                arg_tys.push(ArgTy::Known(Ty::Deferred));
                continue;
            }
            if let Some(float) = flex_literal(a) {
                arg_tys.push(ArgTy::Literal { float });
                continue;
            }
            let v = self.expr(a, None)?;
            let t = self.ty(v);
            if let Ty::Array(_, n) = &t {
                array_ndim = *n;
            }
            arg_tys.push(ArgTy::Known(t));
            vals[i] = Some(vec![v]);
        }
        // Indices: one variable per array dimension.
        for (i, (a, pos)) in args.iter().zip(b.params).enumerate() {
            if *pos == Pos::Index {
                let vs = self.index_vars(a, array_ndim)?;
                arg_tys[i] = ArgTy::Known(if array_ndim == 1 {
                    self.ty(vs[0])
                } else {
                    Ty::TidTuple(array_ndim)
                });
                vals[i] = Some(vs);
            }
        }
        let resolved = match b.resolve(&arg_tys) {
            Ok(r) => r,
            Err(m) => {
                // `max(acc, x)` with `acc` a literal `let` and `x` an f64: learn it.
                let known: Vec<VarId> = vals.iter().flatten().flatten().copied().collect();
                for (k, &a) in known.iter().enumerate() {
                    for &b in &known[k + 1..] {
                        self.learn_from_pair(a, b);
                    }
                }
                return err(span, m);
            }
        };
        // A literal in a `T` position whose type the macro cannot see takes the type of an
        // argument in another `T` position (`v.max(0.5)` with `v` from a user func); one in a
        // `ScalarOfT` position takes that argument's lane type (`lerp(f(a), f(b), 0.5)`).
        let like = b.params.iter().zip(&vals).find_map(|(p, v)| match (p, v) {
            (Pos::T, Some(vs)) if self.ty(vs[0]).is_deferred() => Some(vs[0]),
            _ => None,
        });
        let mut out = Vec::new();
        for (i, a) in args.iter().enumerate() {
            match vals[i].take() {
                Some(vs) => out.extend(vs),
                None => match (like, flex_value(a), b.params[i]) {
                    (Some(w), Some(value), pos @ (Pos::T | Pos::ScalarOfT))
                        if resolved.params[i].is_deferred() =>
                    {
                        let kind = if pos == Pos::T {
                            Like::Value
                        } else {
                            Like::Scalar
                        };
                        out.push(self.def(Op::LitLike(value, w, kind), Ty::Deferred, a.span()))
                    }
                    _ => out.push(self.expr(a, Some(&resolved.params[i]))?),
                },
            }
        }
        // A builtin reading an array (`lower_bound`): a 1-D array itself, not a view.
        if b.reads_array() {
            let at = b
                .params
                .iter()
                .position(|p| *p == Pos::ArrayOfT)
                .expect("reads_array: an array position");
            match self.ty(out[at]) {
                Ty::Array(_, 1) if !self.is_view(out[at]) => {}
                Ty::Array(_, 1) => {
                    return err(
                        args[at].span(),
                        if b.name.starts_with("lower_bound") {
                            format!("`{}` searches an array, not a view: pass the array and a range, `lower_bound(a, lo, hi, value)`", b.name)
                        } else {
                            format!(
                                "`{}` reads an array, not a view: pass the array itself",
                                b.name
                            )
                        },
                    )
                }
                Ty::Deferred => {}
                t => {
                    return err(
                        args[at].span(),
                        format!(
                            "`{}` {} a 1-D array, found `{t}`",
                            b.name,
                            if b.name.starts_with("lower_bound") {
                                "searches"
                            } else {
                                "reads"
                            }
                        ),
                    )
                }
            }
        }
        // An atomic on a view: on the viewed array, at the full index.
        if b.is_atomic() && self.is_view(out[0]) {
            let n_index = out.len() - 1 - b.atomic_values();
            let (base, index) = self.resolve_view(out[0], out[1..1 + n_index].to_vec(), span);
            let values = out[1 + n_index..].to_vec();
            out = std::iter::once(base).chain(index).chain(values).collect();
        }
        if let Emit::Operator(op) = b.emit {
            // Warp's `mod` is the `%` operator: the same faults, float semantics and adjoint.
            return Ok(self.def(Op::Binary(op, out[0], out[1]), resolved.ret, span));
        }
        Ok(self.def(
            Op::Builtin {
                builtin: b,
                args: out,
            },
            resolved.ret,
            span,
        ))
    }

    pub(super) fn method_call(&mut self, m: &syn::ExprMethodCall, want: Option<&Ty>) -> R<VarId> {
        let span = m.span();
        let name = m.method.to_string();
        if m.turbofish.is_some() {
            return err(span, "turbofish is not supported in kernels");
        }
        // Array methods.
        if let Some(v) = self.view_method(m)? {
            return Ok(v);
        }
        if name == "len" && m.args.is_empty() {
            let a = self.base_expr(&m.receiver)?;
            if self.is_view(a) {
                return Ok(self.view_len(a, span));
            }
            // A deferred value's `len()` is a struct's array field's or a func's array result's
            // (rustc refuses any other value there).
            if matches!(self.ty(a), Ty::Array(..) | Ty::Deferred) {
                return Ok(self.def(Op::Len(a), USIZE, span));
            }
            if matches!(self.ty(a), Ty::LocalArray(..)) {
                return Ok(self.local_len(a, span));
            }
            return err(
                m.method.span(),
                format!("`len()` is defined on arrays, not on `{}`", self.ty(a)),
            );
        }
        // A func's `&mut` parameter as a receiver is dereferenced, as Rust does (`acc.length()`).
        let deref: Option<Expr> = self.ref_param(&m.receiver).map(|_| {
            let r = &m.receiver;
            syn::parse_quote_spanned!(r.span()=> (*#r))
        });
        if let Some(b) = builtins::lookup_method(&name) {
            let mut args: Vec<&Expr> = vec![deref.as_ref().unwrap_or(&m.receiver)];
            args.extend(m.args.iter());
            return self.builtin_call(b, &args, want, span);
        }
        let recv = self.base_expr(&m.receiver)?;
        let rt = self.ty(recv);
        let known: Vec<&str> = builtins::BUILTINS
            .iter()
            .filter(|b| b.method)
            .map(|b| b.name)
            .chain(
                builtins::BUILTINS
                    .iter()
                    .flat_map(|b| b.aliases.iter().copied()),
            )
            .collect();
        err(
            m.method.span(),
            format!(
                "unknown method `{name}` on `{rt}` in a kernel; methods available: {}, len",
                known.join(", ")
            ),
        )
    }
}

//! Lowering: a kernel or func body (syn) to three-address IR, type-checking as it goes.
//!
//! # The literal rule (shared by both backends)
//! An unsuffixed numeric literal takes its type from its context: the other operand of a
//! binary operator (its scalar, for `2.0 * v`), the parameter it is passed to, the annotated
//! `let` or the place it is assigned to, or the function's return type. An integer literal in
//! a float context becomes a float of that type (`2 * x` is `2.0 * x`). With no context, an
//! integer literal is `i32` and a float literal is `f32` (as in Warp; Rust would pick `f64`).
//! The Rust emitter writes every literal with its suffix, and the CUDA emitter with its C++
//! type, so a literal can never silently become a double on one backend only. Where the
//! context is a value whose type the macro cannot see (a user func's result), the literal is
//! left for the target compiler to type from that same operand.

use crate::builtins::{self, ArgTy, Builtin, Emit, Pos};
use crate::front::signature::parse_type;
use crate::ir::*;
use crate::types::{Scalar, Ty, BOOL, USIZE};
use proc_macro2::Span;
use std::collections::HashMap;
use syn::spanned::Spanned;
use syn::{Expr, Pat};

mod rng;
mod views;

type R<T> = syn::Result<T>;

fn err<T>(span: Span, msg: impl std::fmt::Display) -> R<T> {
    Err(syn::Error::new(span, msg))
}

/// Lowers a kernel or func. All errors found are returned together.
pub fn lower_fn(item: &syn::ItemFn, kind: FnKind) -> Result<Function, Vec<syn::Error>> {
    let mut cx = Lowerer {
        kind,
        fn_name: item.sig.ident.to_string(),
        vars: Vec::new(),
        scopes: vec![HashMap::new()],
        blocks: vec![Vec::new()],
        errors: Vec::new(),
        tid_ndim: None,
        callees: Vec::new(),
        ret: Ty::Unit,
        loops: 0,
        views: HashMap::new(),
        consts: Vec::new(),
        tuple_result: false,
    };
    let sig = &item.sig;
    let unsupported = [
        (sig.asyncness.is_some(), "async kernels are not supported"),
        (sig.unsafety.is_some(), "unsafe kernels are not supported"),
        (sig.constness.is_some(), "const kernels are not supported"),
        (sig.variadic.is_some(), "variadic kernels are not supported"),
        (
            !sig.generics.params.is_empty(),
            "generic kernels and funcs are not supported yet",
        ),
    ];
    for (bad, msg) in unsupported {
        if bad {
            cx.errors.push(syn::Error::new(sig.span(), msg));
        }
    }
    let mut params = Vec::new();
    for input in &sig.inputs {
        match input {
            syn::FnArg::Receiver(r) => cx
                .errors
                .push(syn::Error::new(r.span(), "kernels take no `self`")),
            syn::FnArg::Typed(pt) => {
                let (name, mutable) = match &*pt.pat {
                    Pat::Ident(pi) if pi.by_ref.is_none() && pi.subpat.is_none() => {
                        (pi.ident.to_string(), pi.mutability.is_some())
                    }
                    other => {
                        cx.errors.push(syn::Error::new(
                            other.span(),
                            "parameters must be plain names",
                        ));
                        continue;
                    }
                };
                match parse_type(&pt.ty) {
                    Ok(ty) => {
                        let var = cx.new_var(Some(name.clone()), ty.clone(), mutable);
                        cx.scopes[0].insert(name.clone(), var);
                        params.push(Param {
                            name,
                            var,
                            ty,
                            syn_ty: (*pt.ty).clone(),
                        });
                    }
                    Err(e) => cx.errors.push(e),
                }
            }
        }
    }
    let ret_syn = match &sig.output {
        syn::ReturnType::Default => None,
        syn::ReturnType::Type(_, t) => Some((**t).clone()),
    };
    if let Some(t) = &ret_syn {
        match parse_type(t) {
            Ok(Ty::Array(..)) => cx
                .errors
                .push(syn::Error::new(t.span(), "funcs cannot return arrays")),
            Ok(ty) => cx.ret = ty,
            Err(e) => cx.errors.push(e),
        }
    }
    if kind == FnKind::Kernel && !matches!(cx.ret, Ty::Unit) {
        cx.errors.push(syn::Error::new(
            sig.output.span(),
            "kernels return nothing: write results into arrays",
        ));
    }

    let ret = cx.ret.clone();
    let tail = cx.block_stmts(
        &item.block.stmts,
        (!matches!(ret, Ty::Unit)).then_some(&ret),
        !matches!(ret, Ty::Unit),
    );
    match tail {
        Ok(Some(v)) if kind == FnKind::Func => {
            cx.push(StmtKind::Return { value: Some(v) }, item.block.span())
        }
        Ok(Some(_)) => {}
        Ok(None) if kind == FnKind::Func && !matches!(ret, Ty::Unit) => {
            // Allowed when every path returns explicitly; rustc checks that on the CPU side.
        }
        Ok(None) => {}
        Err(e) => cx.errors.push(e),
    }
    if let Some(b) = cx.blocks.last() {
        let mut errors = Vec::new();
        cx.unsupported_view_uses(b, &mut errors);
        cx.errors.extend(errors);
    }
    if !cx.errors.is_empty() {
        return Err(cx.errors);
    }
    let body = cx.blocks.pop().expect("function block");
    Ok(Function {
        kind,
        name: cx.fn_name,
        params,
        ret,
        ret_syn,
        vars: cx.vars,
        body,
        tid_ndim: cx.tid_ndim,
        callees: cx.callees,
        consts: cx.consts,
    })
}

struct Lowerer {
    kind: FnKind,
    fn_name: String,
    vars: Vec<Var>,
    scopes: Vec<HashMap<String, VarId>>,
    /// Blocks under construction; statements go to the last.
    blocks: Vec<Block>,
    errors: Vec<syn::Error>,
    tid_ndim: Option<u8>,
    callees: Vec<syn::Path>,
    ret: Ty,
    loops: usize,
    /// In-kernel views (`a.row(i)`, `a.view(lo..hi)`), resolved into the arrays they view.
    views: HashMap<VarId, views::ViewDef>,
    /// Module-level consts read (`Op::Const`), each once, in first-use order.
    consts: Vec<syn::Path>,
    /// Set by a destructuring `let` for the call it lowers: that call (and no other) may be a
    /// builtin returning a tuple (`let (u, sigma, v) = svd3(a);`).
    tuple_result: bool,
}

/// An assignable place: a local (with a member path) or an array element (with a member path).
enum Place {
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

/// Is `e` an unsuffixed numeric literal (possibly negated or parenthesised)? `Some(is_float)`.
fn flex_literal(e: &Expr) -> Option<bool> {
    match e {
        Expr::Lit(l) => match &l.lit {
            syn::Lit::Int(i) if i.suffix().is_empty() => Some(false),
            syn::Lit::Float(f) if f.suffix().is_empty() => Some(true),
            _ => None,
        },
        Expr::Unary(u) if matches!(u.op, syn::UnOp::Neg(_)) => flex_literal(&u.expr),
        Expr::Paren(p) => flex_literal(&p.expr),
        Expr::Group(g) => flex_literal(&g.expr),
        _ => None,
    }
}

/// The value of an unsuffixed numeric literal (possibly negated or parenthesised).
fn flex_value(e: &Expr) -> Option<Lit> {
    match e {
        Expr::Lit(l) => match &l.lit {
            syn::Lit::Int(i) if i.suffix().is_empty() => {
                i.base10_parse::<i128>().ok().map(Lit::Int)
            }
            syn::Lit::Float(f) if f.suffix().is_empty() => {
                f.base10_parse::<f64>().ok().map(Lit::Float)
            }
            _ => None,
        },
        Expr::Unary(u) if matches!(u.op, syn::UnOp::Neg(_)) => match flex_value(&u.expr)? {
            Lit::Int(v) => Some(Lit::Int(-v)),
            Lit::Float(v) => Some(Lit::Float(-v)),
            b => Some(b),
        },
        Expr::Paren(p) => flex_value(&p.expr),
        Expr::Group(g) => flex_value(&g.expr),
        // `else { 0.5 }`
        Expr::Block(b) if b.label.is_none() => match b.block.stmts.as_slice() {
            [syn::Stmt::Expr(e, None)] => flex_value(e),
            _ => None,
        },
        _ => None,
    }
}

fn strip(e: &Expr) -> &Expr {
    match e {
        Expr::Paren(p) => strip(&p.expr),
        Expr::Group(g) => strip(&g.expr),
        _ => e,
    }
}

/// The type a literal should take next to an operand of type `other` under `op`.
fn literal_hint(other: &Ty, op: BinOp) -> Option<Ty> {
    match op {
        BinOp::Shl | BinOp::Shr => None,
        _ => match other {
            Ty::Scalar(_) => Some(other.clone()),
            Ty::Vector(s, _) | Ty::Matrix(s, _) | Ty::Quat(s) | Ty::Transform(s) => {
                Some(Ty::Scalar(*s))
            }
            Ty::Deferred => Some(Ty::Deferred),
            _ => None,
        },
    }
}

/// The result type of `l op r`, or why there is none.
pub fn binary_result(op: BinOp, l: &Ty, r: &Ty) -> Result<Ty, String> {
    use Ty::*;
    let bad = || Err(format!("cannot apply `{}` to `{l}` and `{r}`", op.symbol()));
    if l.is_deferred() || r.is_deferred() {
        return Ok(if op.is_comparison() { BOOL } else { Deferred });
    }
    match op {
        BinOp::Eq | BinOp::Ne => {
            if l == r
                && matches!(
                    l,
                    Scalar(_) | Vector(..) | Quat(_) | Matrix(..) | Transform(_)
                )
            {
                Ok(BOOL)
            } else {
                bad()
            }
        }
        BinOp::Lt | BinOp::Le | BinOp::Gt | BinOp::Ge => match (l, r) {
            (Scalar(a), Scalar(b)) if a == b => Ok(BOOL),
            _ => bad(),
        },
        // Integer vectors too (glam's operators), lane by lane, a scalar splatted.
        BinOp::BitAnd | BinOp::BitOr | BinOp::BitXor => match (l, r) {
            (Scalar(a), Scalar(b)) if a == b && !a.is_float() => Ok(l.clone()),
            (Vector(a, n), Vector(b, m)) if a == b && n == m && !a.is_float() => Ok(l.clone()),
            (Vector(a, _), Scalar(b)) if a == b && !a.is_float() => Ok(l.clone()),
            (Scalar(a), Vector(b, _)) if a == b && !a.is_float() => Ok(r.clone()),
            _ => bad(),
        },
        // A vector shifts every lane by one scalar amount.
        BinOp::Shl | BinOp::Shr => match (l, r) {
            (Scalar(a) | Vector(a, _), Scalar(b)) if a.is_int() && b.is_int() => Ok(l.clone()),
            _ => bad(),
        },
        BinOp::Add | BinOp::Sub | BinOp::Mul | BinOp::Div | BinOp::Rem => match (l, r) {
            (Scalar(a), Scalar(b)) if a == b && *a != crate::types::Scalar::Bool => Ok(l.clone()),
            (Vector(a, n), Vector(b, m)) if a == b && n == m => Ok(l.clone()),
            (Vector(a, _), Scalar(b)) if a == b => Ok(l.clone()),
            (Scalar(a), Vector(b, _)) if a == b => Ok(r.clone()),
            (Matrix(a, n), Matrix(b, m))
                if a == b && n == m && matches!(op, BinOp::Add | BinOp::Sub | BinOp::Mul) =>
            {
                Ok(l.clone())
            }
            (Matrix(a, n), Vector(b, m)) if a == b && n == m && op == BinOp::Mul => Ok(r.clone()),
            (Matrix(a, _), Scalar(b)) if a == b && matches!(op, BinOp::Mul | BinOp::Div) => {
                Ok(l.clone())
            }
            (Scalar(a), Matrix(b, _)) if a == b && op == BinOp::Mul => Ok(r.clone()),
            (Quat(a), Quat(b)) if a == b && matches!(op, BinOp::Add | BinOp::Sub | BinOp::Mul) => {
                Ok(l.clone())
            }
            (Quat(a), Vector(b, 3)) if a == b && op == BinOp::Mul => Ok(r.clone()),
            (Quat(a), Scalar(b)) if a == b && matches!(op, BinOp::Mul | BinOp::Div) => {
                Ok(l.clone())
            }
            // Transforms: `*` composes (Warp's transform_multiply); `+`, `-` and `*` by a
            // scalar are lane by lane (Warp's add, sub, mul overloads).
            (Transform(a), Transform(b))
                if a == b && matches!(op, BinOp::Add | BinOp::Sub | BinOp::Mul) =>
            {
                Ok(l.clone())
            }
            (Transform(a), Scalar(b)) if a == b && op == BinOp::Mul => Ok(l.clone()),
            (Scalar(a), Transform(b)) if a == b && op == BinOp::Mul => Ok(r.clone()),
            _ => bad(),
        },
    }
}

fn map_binop(op: &syn::BinOp) -> Option<BinOp> {
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

fn is_compound_assign(op: &syn::BinOp) -> bool {
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
    if s == Scalar::F16 {
        // `half`'s constants (`f16::MAX`, `f16::PI`, ...); the value is rounded to f16 where
        // it is emitted.
        let v = match name {
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

fn int_range(s: Scalar) -> (i128, i128) {
    match s {
        Scalar::I8 => (i8::MIN.into(), i8::MAX.into()),
        Scalar::I16 => (i16::MIN.into(), i16::MAX.into()),
        Scalar::I32 => (i32::MIN.into(), i32::MAX.into()),
        Scalar::I64 | Scalar::Isize => (i64::MIN.into(), i64::MAX.into()),
        Scalar::U8 => (0, u8::MAX.into()),
        Scalar::U16 => (0, u16::MAX.into()),
        Scalar::U32 => (0, u32::MAX.into()),
        _ => (0, u64::MAX.into()),
    }
}

impl Lowerer {
    fn new_var(&mut self, name: Option<String>, ty: Ty, mutable: bool) -> VarId {
        self.vars.push(Var { name, ty, mutable });
        self.vars.len() - 1
    }

    fn push(&mut self, kind: StmtKind, span: Span) {
        self.blocks
            .last_mut()
            .expect("open block")
            .push(Stmt { kind, span });
    }

    /// Defines a new temporary holding `op`.
    fn def(&mut self, op: Op, ty: Ty, span: Span) -> VarId {
        let v = self.new_var(None, ty, false);
        self.push(
            StmtKind::Assign {
                dst: v,
                op,
                define: true,
            },
            span,
        );
        v
    }

    fn ty(&self, v: VarId) -> Ty {
        self.vars[v].ty.clone()
    }

    fn lookup(&self, name: &str) -> Option<VarId> {
        self.scopes.iter().rev().find_map(|s| s.get(name).copied())
    }

    /// Runs `f` with a fresh block; returns the block built.
    fn in_block<T>(&mut self, f: impl FnOnce(&mut Self) -> R<T>) -> R<(Block, T)> {
        self.blocks.push(Vec::new());
        self.scopes.push(HashMap::new());
        let r = f(self);
        self.scopes.pop();
        let b = self.blocks.pop().expect("block");
        r.map(|t| (b, t))
    }

    // ---------------------------------------------------------------- statements

    /// Lowers statements; returns the tail expression's value, if any. Errors inside single
    /// statements are recorded and lowering goes on, so that many are reported at once.
    fn block_stmts(
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
            Pat::Type(pt) => (&*pt.pat, Some(let_type(&pt.ty)?)),
            p => (p, None),
        };
        if let Pat::Tuple(tuple) = pat {
            if !is_tid_call(&init.expr) {
                return self.destructure(tuple, &init.expr, annot, span);
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
        let value = self.expr(&init.expr, annot.as_ref())?;
        if let Some(a) = &annot {
            let vt = self.ty(value);
            if !vt.is_deferred() && vt != *a {
                return err(
                    init.expr.span(),
                    format!("mismatched types: expected `{a}`, found `{vt}`"),
                );
            }
        }
        self.bind_pat(pat, value, span)
    }

    /// `let (u, sigma, v) = svd3(a);`: the call's tuple, then one member read per bound name.
    fn destructure(
        &mut self,
        tuple: &syn::PatTuple,
        init: &Expr,
        annot: Option<Ty>,
        span: Span,
    ) -> R<()> {
        let only = "tuple patterns are only supported for `let (i, j) = tid();` and the \
                    decompositions (`let (u, sigma, v) = svd3(a);`, `let (q, d) = eig3(a);`, ..)";
        if !matches!(strip(init), Expr::Call(_)) {
            return err(tuple.span(), only);
        }
        self.tuple_result = true;
        let value = self.expr(init, None);
        self.tuple_result = false;
        let value = value?;
        let Ty::Tuple(tys) = self.ty(value) else {
            return err(tuple.span(), only);
        };
        if tys.len() != tuple.elems.len() {
            return err(
                tuple.span(),
                format!(
                    "this pattern binds {} value(s), but the call returns {}: `{}`",
                    tuple.elems.len(),
                    tys.len(),
                    self.ty(value)
                ),
            );
        }
        if let Some(a) = annot {
            let ok = matches!(&a, Ty::Tuple(w) if w.len() == tys.len()
                && w.iter().zip(&tys).all(|(w, t)| t.is_deferred() || w == t));
            if !ok {
                return err(
                    init.span(),
                    format!(
                        "mismatched types: expected `{a}`, found `{}`",
                        self.ty(value)
                    ),
                );
            }
        }
        for (k, (el, ty)) in tuple.elems.iter().zip(tys).enumerate() {
            if matches!(el, Pat::Wild(_)) {
                continue;
            }
            let v = self.def(Op::Member(value, k.to_string()), ty, el.span());
            self.bind_pat(el, v, span)?;
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
                let v = self.new_var(Some(name.clone()), ty, pi.mutability.is_some());
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
                "only plain names (and `let (i, j) = tid();`) can be bound in kernels",
            ),
        }
    }

    fn use_tid(&mut self, n: u8, span: Span) -> R<()> {
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
    fn stmt_expr(&mut self, e: &Expr) -> R<()> {
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
                if self.loops == 0 {
                    return err(span, "`break` outside of a loop");
                }
                self.push(StmtKind::Break, span);
                Ok(())
            }
            Expr::Continue(c) => {
                if c.label.is_some() {
                    return err(span, "`continue` with a label is not supported in kernels");
                }
                if self.loops == 0 {
                    return err(span, "`continue` outside of a loop");
                }
                self.push(StmtKind::Continue, span);
                Ok(())
            }
            Expr::Return(r) => self.ret_stmt(r),
            Expr::Macro(m) => self.macro_stmt(&m.mac),
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
        self.push(StmtKind::Return { value }, span);
        Ok(())
    }

    fn loop_body<T>(&mut self, f: impl FnOnce(&mut Self) -> R<T>) -> R<(Block, T)> {
        self.loops += 1;
        let r = self.in_block(f);
        self.loops -= 1;
        r
    }

    fn while_loop(&mut self, w: &syn::ExprWhile) -> R<()> {
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

    fn for_loop(&mut self, f: &syn::ExprForLoop) -> R<()> {
        if f.label.is_some() {
            return err(f.span(), "loop labels are not supported in kernels");
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

    fn expect_bool(&self, v: VarId, span: Span) -> R<()> {
        let t = self.ty(v);
        if t.is_deferred() || t == BOOL {
            Ok(())
        } else {
            err(span, format!("expected `bool`, found `{t}`"))
        }
    }

    /// `if`; with `value`, both branches must yield a value of one type.
    fn if_expr(&mut self, i: &syn::ExprIf, value: bool, want: Option<&Ty>) -> R<Option<VarId>> {
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

    fn assign(&mut self, lhs: &Expr, op: Option<BinOp>, rhs: &Expr, span: Span) -> R<()> {
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

    fn place(&mut self, e: &Expr) -> R<Place> {
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

    fn member_ty(&self, base: &Ty, name: &str, span: Span) -> R<Ty> {
        match base {
            Ty::Deferred | Ty::Struct(_) => Ok(Ty::Deferred),
            t => t
                .member_ty(name)
                .ok_or_else(|| syn::Error::new(span, format!("`{t}` has no field `{name}`"))),
        }
    }

    fn place_ty(&self, p: &Place, span: Span) -> R<Ty> {
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

    fn read_place(&mut self, p: &Place, ty: Ty, span: Span) -> VarId {
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

    fn write_place(&mut self, p: Place, value: VarId, span: Span) {
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
            _ => {
                return err(
                    mac.path.span(),
                    format!(
                        "macro `{name}!` is not supported in kernels (print! and println! are)"
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
            values.push(self.expr(a, None)?);
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

    // ---------------------------------------------------------------- expressions

    /// Lowers an expression to a variable holding its value. `want` is the type the context
    /// expects (it types literals; mismatches are reported by the caller).
    fn expr(&mut self, e: &Expr, want: Option<&Ty>) -> R<VarId> {
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
                        Ty::Matrix(..) | Ty::Quat(_) | Ty::Transform(_) | Ty::Deferred => true,
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
                syn::UnOp::Deref(_) => err(
                    span,
                    "references are not supported in kernels (no `*` dereference)",
                ),
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
                        let res = binary_result(op, &self.ty(l), &self.ty(r))
                            .map_err(|m| syn::Error::new(b.op.span(), m))?;
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
                let syn::Member::Named(name) = &f.member else {
                    return err(f.member.span(), "tuple fields are not supported in kernels");
                };
                let base = self.expr(&f.base, None)?;
                let bt = self.ty(base);
                if matches!(bt, Ty::Array(..)) {
                    return err(span, "arrays have no fields: index them, `a[i]`");
                }
                let t = self.member_ty(&bt, &name.to_string(), name.span())?;
                Ok(self.def(Op::Member(base, name.to_string()), t, span))
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
                let (array, index) = self.array_index(ix)?;
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
            Expr::Array(_) | Expr::Repeat(_) => err(
                span,
                "fixed-size arrays are not supported in kernels: use a glam vector or Array<T>",
            ),
            Expr::Tuple(_) => err(
                span,
                "tuples are not supported in kernels (except array indices a[(i, j)])",
            ),
            Expr::Match(_) => err(span, "`match` is not supported in kernels: use if / else"),
            Expr::Struct(_) => err(
                span,
                "struct literals are not supported in kernels yet: pass the struct as an argument",
            ),
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

    /// Lowers two operands, typing an unsuffixed literal on either side from the other.
    fn operand_pair(
        &mut self,
        l: &Expr,
        r: &Expr,
        want: Option<&Ty>,
        op: BinOp,
    ) -> R<(VarId, VarId)> {
        let shift = matches!(op, BinOp::Shl | BinOp::Shr);
        match (flex_literal(l).is_some(), flex_literal(r).is_some()) {
            (true, false) => {
                // Literals have no side effects, so lowering the right side first is safe.
                let rv = self.expr(r, None)?;
                let lv = if shift {
                    self.expr(l, want)?
                } else {
                    self.literal_next_to(l, rv, op)?
                };
                Ok((lv, rv))
            }
            (false, true) => {
                let lv = self.expr(l, want)?;
                let rv = if shift {
                    self.expr(r, None)?
                } else {
                    self.literal_next_to(r, lv, op)?
                };
                Ok((lv, rv))
            }
            (true, true) => {
                let w = want.and_then(|w| literal_hint(w, op));
                let lv = self.expr(l, w.as_ref())?;
                let rv = if shift {
                    self.expr(r, None)?
                } else {
                    self.expr(r, w.as_ref())?
                };
                Ok((lv, rv))
            }
            (false, false) => Ok((self.expr(l, None)?, self.expr(r, None)?)),
        }
    }

    /// An unsuffixed literal `lit` that meets `other` under `op`: typed from `other`'s type, or,
    /// when the macro cannot see that type, made "a literal of the type of `other`".
    fn literal_next_to(&mut self, lit: &Expr, other: VarId, op: BinOp) -> R<VarId> {
        if self.ty(other).is_deferred() {
            if let Some(value) = flex_value(lit) {
                return Ok(self.def(Op::LitLike(value, other), Ty::Deferred, lit.span()));
            }
        }
        let hint = literal_hint(&self.ty(other), op);
        self.expr(lit, hint.as_ref())
    }

    fn short_circuit(&mut self, b: &syn::ExprBinary) -> R<VarId> {
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

    fn literal(&mut self, lit: &syn::Lit, neg: bool, want: Option<&Ty>, span: Span) -> R<VarId> {
        let want_scalar = want.map(|w| match w {
            Ty::Vector(s, _) | Ty::Matrix(s, _) | Ty::Quat(s) | Ty::Transform(s) => Ty::Scalar(*s),
            t => t.clone(),
        });
        match lit {
            syn::Lit::Bool(b) => {
                if neg {
                    return err(span, "cannot negate a bool");
                }
                Ok(self.def(Op::Lit(Lit::Bool(b.value)), BOOL, span))
            }
            syn::Lit::Int(i) => {
                let v: i128 = i
                    .base10_parse::<u128>()
                    .map_err(|_| syn::Error::new(span, "integer literal too large"))?
                    as i128;
                let v = if neg { -v } else { v };
                let ty = match i.suffix() {
                    "" => match want_scalar {
                        Some(Ty::Scalar(s)) if s.is_float() => {
                            return Ok(self.def(
                                Op::Lit(Lit::Float(v as f64)),
                                Ty::Scalar(s),
                                span,
                            ));
                        }
                        Some(Ty::Scalar(s)) if s.is_int() => Ty::Scalar(s),
                        Some(Ty::Deferred) => Ty::Deferred,
                        _ => crate::types::I32,
                    },
                    suf => match Scalar::from_name(suf) {
                        Some(s) if s.is_float() => {
                            return Ok(self.def(
                                Op::Lit(Lit::Float(v as f64)),
                                Ty::Scalar(s),
                                span,
                            ));
                        }
                        Some(s) if s.is_int() => Ty::Scalar(s),
                        _ => return err(span, format!("unknown literal suffix `{suf}`")),
                    },
                };
                if let Ty::Scalar(s) = ty {
                    let (lo, hi) = int_range(s);
                    if v < lo || v > hi {
                        return err(span, format!("literal out of range for `{}`", s.name()));
                    }
                }
                Ok(self.def(Op::Lit(Lit::Int(v)), ty, span))
            }
            syn::Lit::Float(f) => {
                let v: f64 = f
                    .base10_parse()
                    .map_err(|_| syn::Error::new(span, "bad float literal"))?;
                let v = if neg { -v } else { v };
                let ty = match f.suffix() {
                    "" => match want_scalar {
                        Some(Ty::Scalar(s)) if s.is_float() => Ty::Scalar(s),
                        Some(Ty::Scalar(s)) if s.is_int() => {
                            return err(
                                span,
                                format!("float literal where `{}` is expected", s.name()),
                            );
                        }
                        Some(Ty::Deferred) => Ty::Deferred,
                        _ => crate::types::F32,
                    },
                    "f32" => crate::types::F32,
                    "f64" => Ty::Scalar(Scalar::F64),
                    "f16" => Ty::Scalar(Scalar::F16),
                    suf => return err(span, format!("unknown literal suffix `{suf}`")),
                };
                Ok(self.def(Op::Lit(Lit::Float(v)), ty, span))
            }
            syn::Lit::Str(_) | syn::Lit::ByteStr(_) | syn::Lit::CStr(_) => err(
                span,
                "strings are not supported in kernels (except as print! formats)",
            ),
            _ => err(span, "this literal is not supported in kernels"),
        }
    }

    fn path_expr(&mut self, p: &syn::ExprPath, span: Span) -> R<VarId> {
        if p.qself.is_some() {
            return err(span, "qualified paths are not supported in kernels");
        }
        if let Some(id) = p.path.get_ident() {
            let name = id.to_string();
            if let Some(v) = self.lookup(&name) {
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

    /// A module-level `const` (Warp's `wp.constant`): its value on the CPU is the const
    /// itself; the CUDA source gets it at assembly. Its type is the const's (`Deferred` here).
    fn user_const(&mut self, path: &syn::Path, span: Span) -> VarId {
        if !self.consts.contains(path) {
            self.consts.push(path.clone());
        }
        self.def(Op::Const(path.clone()), Ty::Deferred, span)
    }

    /// `a[i]`, `a[(i, j)]`: the array variable and one index variable per dimension.
    fn array_index(&mut self, ix: &syn::ExprIndex) -> R<(VarId, Vec<VarId>)> {
        let array = self.expr(&ix.expr, None)?;
        let at = self.ty(array);
        let ndim = match &at {
            Ty::Array(_, n) => *n,
            Ty::Deferred => return err(ix.expr.span(), "only arrays can be indexed"),
            t => {
                return err(
                    ix.expr.span(),
                    format!("`{t}` cannot be indexed: vectors use .x .y .z .w"),
                )
            }
        };
        let index = self.index_vars(&ix.index, ndim)?;
        Ok(self.resolve_view(array, index, ix.span()))
    }

    fn index_vars(&mut self, e: &Expr, ndim: u8) -> R<Vec<VarId>> {
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

    fn call(&mut self, c: &syn::ExprCall, want: Option<&Ty>) -> R<VarId> {
        let span = c.span();
        // Only this call may return a tuple, not the calls in its arguments.
        let tuple_ok = std::mem::take(&mut self.tuple_result);
        let Expr::Path(fp) = strip(&c.func) else {
            return err(
                c.func.span(),
                "only functions named by a path can be called in kernels",
            );
        };
        let segs: Vec<String> = fp
            .path
            .segments
            .iter()
            .map(|s| s.ident.to_string())
            .collect();
        // `r#mod(a, b)`: a raw identifier names the builtin without its `r#`.
        let last = segs.last().cloned().unwrap_or_default();
        let last = last.strip_prefix("r#").map(str::to_owned).unwrap_or(last);
        let prefix_ok =
            segs.len() == 1 || (segs.len() == 2 && (segs[0] == "wp" || segs[0] == "warp_lang"));

        if prefix_ok && last == "tid" {
            if !c.args.is_empty() {
                return err(span, "tid() takes no arguments");
            }
            self.use_tid(1, span)?;
            return Ok(self.def(Op::Tid(0), USIZE, span));
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
                if let (Ty::Tuple(_), false) = (self.ty(v), tuple_ok) {
                    return err(
                        span,
                        format!(
                            "`{}` returns a tuple `{}`: destructure it where it is called, `{}`",
                            b.name,
                            self.ty(v),
                            tuple_hint(b)
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
        // The func's parameter types are not visible here: literals are left to rustc, which
        // types them from the func's signature.
        let mut args = Vec::new();
        for a in &c.args {
            let want = flex_literal(a).map(|_| Ty::Deferred);
            args.push(self.expr(a, want.as_ref())?);
        }
        if !self.callees.iter().any(|p| p == &fp.path) {
            self.callees.push(fp.path.clone());
        }
        Ok(self.def(
            Op::Func {
                path: fp.path.clone(),
                args,
            },
            Ty::Deferred,
            span,
        ))
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
        let scalar = Ty::Scalar(ty.scalar().expect("glam types have a scalar"));
        let (ctor_kind, arg_tys): (Ctor, Vec<Ty>) = match (&ty, ctor) {
            (Ty::Vector(_, n), "new") => (Ctor::Components, vec![scalar.clone(); *n as usize]),
            (Ty::Vector(..), "splat") => (Ctor::Splat, vec![scalar.clone()]),
            (Ty::Quat(_), "from_xyzw") => (Ctor::Components, vec![scalar.clone(); 4]),
            (Ty::Matrix(s, n), "from_cols") => {
                (Ctor::Components, vec![Ty::Vector(*s, *n); *n as usize])
            }
            (Ty::Matrix(s, n), "from_diagonal") => (Ctor::Splat, vec![Ty::Vector(*s, *n)]),
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

    fn builtin_call(
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
        let resolved = b.resolve(&arg_tys).map_err(|m| syn::Error::new(span, m))?;
        // A literal in a `T` position whose type the macro cannot see takes the type of an
        // argument in another `T` position (`v.max(0.5)` with `v` from a user func).
        let like = b.params.iter().zip(&vals).find_map(|(p, v)| match (p, v) {
            (Pos::T, Some(vs)) if self.ty(vs[0]).is_deferred() => Some(vs[0]),
            _ => None,
        });
        let mut out = Vec::new();
        for (i, a) in args.iter().enumerate() {
            match vals[i].take() {
                Some(vs) => out.extend(vs),
                None => match (like, flex_value(a)) {
                    (Some(w), Some(value))
                        if b.params[i] == Pos::T && resolved.params[i].is_deferred() =>
                    {
                        out.push(self.def(Op::LitLike(value, w), Ty::Deferred, a.span()))
                    }
                    _ => out.push(self.expr(a, Some(&resolved.params[i]))?),
                },
            }
        }
        // A builtin reading an array (`lower_bound`): a 1-D array itself, not a view.
        if b.reads_array() {
            match self.ty(out[0]) {
                Ty::Array(_, 1) if !self.is_view(out[0]) => {}
                Ty::Array(_, 1) => {
                    return err(
                        args[0].span(),
                        format!("`{}` searches an array, not a view: pass the array and a range, `lower_bound(a, lo, hi, value)`", b.name),
                    )
                }
                Ty::Deferred => {}
                t => {
                    return err(
                        args[0].span(),
                        format!("`{}` searches a 1-D array, found `{t}`", b.name),
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

    fn method_call(&mut self, m: &syn::ExprMethodCall, want: Option<&Ty>) -> R<VarId> {
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
            let a = self.expr(&m.receiver, None)?;
            if self.is_view(a) {
                return Ok(self.view_len(a, span));
            }
            if matches!(self.ty(a), Ty::Array(..)) {
                return Ok(self.def(Op::Len(a), USIZE, span));
            }
            return err(
                m.method.span(),
                format!("`len()` is defined on arrays, not on `{}`", self.ty(a)),
            );
        }
        if let Some(b) = builtins::lookup_method(&name) {
            let mut args: Vec<&Expr> = vec![&m.receiver];
            args.extend(m.args.iter());
            return self.builtin_call(b, &args, want, span);
        }
        let recv = self.expr(&m.receiver, None)?;
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

/// How to destructure a decomposition's tuple (for error messages).
fn tuple_hint(b: &Builtin) -> String {
    let names = b.results.expect("a tuple result has its names");
    format!("let {names} = {}(a);", b.name)
}

/// The type annotation of a `let`: a kernel type, or a tuple of them (for a destructured
/// decomposition).
fn let_type(ty: &syn::Type) -> R<Ty> {
    match ty {
        syn::Type::Tuple(t) if !t.elems.is_empty() => {
            Ok(Ty::Tuple(t.elems.iter().map(parse_type).collect::<R<_>>()?))
        }
        syn::Type::Paren(p) => let_type(&p.elem),
        _ => parse_type(ty),
    }
}

/// A `const`'s name by Rust's convention: SCREAMING_SNAKE_CASE, with a letter.
fn is_const_name(s: &str) -> bool {
    s.chars().any(|c| c.is_ascii_uppercase())
        && s.chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
}

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::{F32, I32};
    use syn::parse_quote;

    fn lower(item: syn::ItemFn) -> Function {
        lower_fn(&item, FnKind::Kernel)
            .unwrap_or_else(|e| panic!("{:?}", e.iter().map(|e| e.to_string()).collect::<Vec<_>>()))
    }

    fn errors(item: syn::ItemFn, kind: FnKind) -> Vec<String> {
        match lower_fn(&item, kind) {
            Ok(_) => vec![],
            Err(e) => e.iter().map(|e| e.to_string()).collect(),
        }
    }

    fn find_var(f: &Function, name: &str) -> Ty {
        f.vars
            .iter()
            .rev()
            .find(|v| v.name.as_deref() == Some(name))
            .unwrap()
            .ty
            .clone()
    }

    #[test]
    fn decompositions_destructure_into_members() {
        let f = lower(parse_quote! {
            fn k(a: Array<DMat3>, b: Array<Mat2>) {
                let i = tid();
                let (u, s, v) = svd3(a[i]);
                let (q, _): (DMat3, DVec3) = wp::eig3(a[i]);
                let (q2, r) = qr3(a[i]);
                let (u2, s2, v2) = svd2(b[i]);
            }
        });
        let m3 = Ty::Matrix(Scalar::F64, 3);
        assert_eq!(find_var(&f, "u"), m3);
        assert_eq!(find_var(&f, "s"), Ty::Vector(Scalar::F64, 3));
        assert_eq!(find_var(&f, "v"), m3);
        assert_eq!(find_var(&f, "q"), m3);
        assert_eq!(find_var(&f, "r"), m3);
        assert_eq!(find_var(&f, "s2"), Ty::Vector(Scalar::F32, 2));
        // One tuple temporary per call, read through members "0", "1", "2".
        let tuples: Vec<&Ty> = f
            .vars
            .iter()
            .map(|v| &v.ty)
            .filter(|t| matches!(t, Ty::Tuple(_)))
            .collect();
        assert_eq!(tuples.len(), 4);
        assert_eq!(
            tuples[0].to_string(),
            "(DMat3, DVec3, DMat3)",
            "the tuple type prints as Rust's"
        );
        let mut members = Vec::new();
        walk_stmts(&f.body, &mut |st| {
            if let StmtKind::Assign {
                op: Op::Member(_, m),
                ..
            } = &st.kind
            {
                members.push(m.clone());
            }
        });
        // `_` reads nothing.
        assert_eq!(members, ["0", "1", "2", "0", "0", "1", "0", "1", "2"]);
    }

    #[test]
    fn tuples_only_where_destructured() {
        let e = errors(
            parse_quote! {
                fn k(a: Array<Mat3>) {
                    let i = tid();
                    let t = svd3(a[i]);
                    let (x, y) = a[i];
                    let (p, q) = svd3(a[i]);
                    let m = transpose(qr3(a[i]));
                }
            },
            FnKind::Kernel,
        );
        assert_eq!(e.len(), 4, "{e:?}");
        assert!(e[0].contains("destructure it"), "{}", e[0]);
        assert!(
            e[1].contains("tuple patterns are only supported"),
            "{}",
            e[1]
        );
        assert!(
            e[2].contains("binds 2 value(s), but the call returns 3"),
            "{}",
            e[2]
        );
        assert!(e[3].contains("`qr3` returns a tuple"), "{}", e[3]);
    }

    #[test]
    fn literal_rule() {
        let f = lower(parse_quote! {
            fn k(x: f64, v: Vec3, a: Array<f32>) {
                let i = tid();
                let a1 = 2.0 * x;      // f64 from x
                let a2 = 2.0;          // no context: f32
                let a3 = v * 0.5;      // f32 from Vec3's scalar
                let a4 = 3;            // i32
                let a5 = 2 * x;        // integer literal in a float context
                let a6: f64 = 1.0;     // annotation
                let a7 = a[i] + 1.0;   // element type
                let a8 = if x > 0.0 { 1.0 } else { 2.0 };
            }
        });
        assert_eq!(find_var(&f, "a1"), Ty::Scalar(Scalar::F64));
        assert_eq!(find_var(&f, "a2"), F32);
        assert_eq!(find_var(&f, "a3"), Ty::Vector(Scalar::F32, 3));
        assert_eq!(find_var(&f, "a4"), I32);
        assert_eq!(find_var(&f, "a5"), Ty::Scalar(Scalar::F64));
        assert_eq!(find_var(&f, "a6"), Ty::Scalar(Scalar::F64));
        assert_eq!(find_var(&f, "a7"), F32);
        assert_eq!(find_var(&f, "a8"), F32);
        assert_eq!(f.tid_ndim, Some(1));
    }

    #[test]
    fn deferred_values_leave_literals_to_the_target() {
        let f = lower(parse_quote! {
            fn k(x: f32) { let y = helper(x) * 2.0; }
        });
        assert_eq!(find_var(&f, "y"), Ty::Deferred);
        assert_eq!(f.callees.len(), 1);
    }

    #[test]
    fn type_errors_are_gathered() {
        let e = errors(
            parse_quote! {
                fn k(x: f32, y: f64, v: Vec3) {
                    let a = x + y;
                    let b = v.frobnicate();
                    let c = |q: f32| q;
                    let d = &x;
                }
            },
            FnKind::Kernel,
        );
        assert_eq!(e.len(), 4, "{e:?}");
        assert!(
            e[0].contains("cannot apply `+` to `f32` and `f64`"),
            "{}",
            e[0]
        );
        assert!(e[1].contains("unknown method `frobnicate`"), "{}", e[1]);
        assert!(e[2].contains("closures"), "{}", e[2]);
        assert!(e[3].contains("references"), "{}", e[3]);
    }

    #[test]
    fn subset_errors() {
        let cases: Vec<(syn::ItemFn, &str)> = vec![
            (
                parse_quote!(
                    fn k(a: Array<f32>) {
                        let s = String::new();
                    }
                ),
                "heap type `String`",
            ),
            (
                parse_quote!(
                    fn k(a: Vec<f32>) {}
                ),
                "heap type",
            ),
            (
                parse_quote!(
                    fn k(a: &f32) {}
                ),
                "references",
            ),
            (
                parse_quote!(
                    fn k(x: f32) {
                        x = 1.0;
                    }
                ),
                "immutable",
            ),
            (
                parse_quote!(
                    fn k(a: Array<f32, 2>) {
                        let v = a[0];
                    }
                ),
                "2 dimension",
            ),
            (
                parse_quote!(
                    fn k(x: f32) {
                        break;
                    }
                ),
                "outside of a loop",
            ),
            (
                parse_quote!(
                    fn k(x: i32) {
                        match x {
                            _ => {}
                        }
                    }
                ),
                "match",
            ),
            (
                parse_quote!(
                    fn k(x: f32) -> f32 {
                        x
                    }
                ),
                "kernels return nothing",
            ),
            (
                parse_quote!(
                    fn k(x: u8) {
                        let y = x + 300;
                    }
                ),
                "out of range",
            ),
            (
                parse_quote!(
                    fn k(x: i32) {
                        let y = x + 1.5;
                    }
                ),
                "float literal",
            ),
        ];
        for (item, want) in cases {
            let e = errors(item.clone(), FnKind::Kernel);
            assert!(
                e.iter().any(|m| m.contains(want)),
                "{} -> {e:?}",
                quote::quote!(#item)
            );
        }
        let e = errors(
            parse_quote!(
                fn f(x: f32) -> f32 {
                    f(x)
                }
            ),
            FnKind::Func,
        );
        assert!(e[0].contains("recursion"), "{e:?}");
    }

    #[test]
    fn control_flow_lowers() {
        let f = lower(parse_quote! {
            fn k(a: Array<f32>, n: i32) {
                let mut s = 0.0;
                for j in (0..n).rev().step_by(2) { if j == 3 { continue; } s += 1.0; }
                let mut k = 0;
                while k < 10 && s > 0.0 { k += 1; if k > 5 { break; } }
                loop { break; }
                a[0] = s;
            }
        });
        let mut fors = 0;
        let mut loops = 0;
        walk_stmts(&f.body, &mut |s| match &s.kind {
            StmtKind::For { range, .. } => {
                fors += 1;
                assert!(matches!(
                    range.adapters.as_slice(),
                    [RangeAdapter::Rev, RangeAdapter::StepBy(_)]
                ));
            }
            StmtKind::Loop { .. } => loops += 1,
            _ => {}
        });
        assert_eq!((fors, loops), (1, 2));
        assert_eq!(find_var(&f, "j"), I32);
    }

    #[test]
    fn tid_forms() {
        let f = lower(parse_quote!(
            fn k(a: Array<f32, 2>) {
                let (i, j) = tid();
                a[(i, j)] = 1.0;
            }
        ));
        assert_eq!(f.tid_ndim, Some(2));
        let e = errors(
            parse_quote!(
                fn k() {
                    let i = tid();
                    let (a, b) = tid();
                }
            ),
            FnKind::Kernel,
        );
        assert!(e[0].contains("1 and with 2"), "{e:?}");
    }
}

//! Lowering: a kernel or func body (syn) to three-address IR, type-checking as it goes.
//!
//! This module is the entry, [`lower_fn`] (the signature, then the body), and the state of a
//! lowering, `Lowerer`: variables, scopes, the blocks under construction and the errors
//! gathered. The submodules own the parts of the language, each adding its methods to
//! `Lowerer`:
//!
//! - `typing`: the type rules of the operators and the literal rule; literals.
//! - `statements`: blocks, `let` and its patterns, expression statements, `return`, `print!`.
//! - `asserts`: `assert!`, `debug_assert!` and the expectations (`expect_eq(a, b);`).
//! - `control`: `if`, `while`, `for` over ranges, loop bodies, `&&` and `||`.
//! - `places`: assignment targets, assignment, array indexing, members.
//! - `expressions`: operators, casts, fields, paths and constants; what is outside the subset.
//! - `calls`: builtin, method, glam-constructor and func calls.
//! - `resolve`: the func a call runs, from its arguments' types (overloads, generic funcs).
//! - `views`: in-kernel views, rewritten into accesses of the viewed array.
//! - `rng`: the random draws that advance a state in place; `rand_init`'s and `pnoise`'s
//!   overloads by arity.
//! - `query`: `for j in hash_grid_query(..)`, a loop over a host object's query.
//! - `tiles`: tile calls typed by their shapes, `lane()`, operators and indexing on tiles.
//! - `local_arrays`: fixed-size local arrays (`[0.0f32; 8]`, `[x, y, z]`), their elements
//!   and `len()`.
//! - `struct_literals`: user struct literals (`Particle { x, v: Vec3::ZERO, ..q }`).

use crate::builtins::{self, ArgTy, Builtin, Emit, Pos};
use crate::front::signature::{parse_type, MAX_TUPLE};
use crate::ir::*;
use crate::types::{Scalar, Ty, BOOL, USIZE};
use proc_macro2::Span;
use std::collections::HashMap;
use syn::spanned::Spanned;
use syn::{Expr, Pat};

mod asserts;
pub(crate) mod calls;
mod control;
mod expressions;
mod literal_lets;
mod local_arrays;
mod matrices;
mod places;
mod query;
pub(crate) mod resolve;
mod rng;
mod statements;
mod struct_literals;
mod tiles;
pub(crate) mod typing;
mod views;

type R<T> = syn::Result<T>;

fn err<T>(span: Span, msg: impl std::fmt::Display) -> R<T> {
    Err(syn::Error::new(span, msg))
}

/// Lowers a kernel or func. All errors found are returned together.
pub fn lower_fn(item: &syn::ItemFn, kind: FnKind) -> Result<Function, Vec<syn::Error>> {
    lower_kernel(item, kind, None)
}

/// Lowers a kernel or func; `block_dim` is `#[kernel(block_dim = N)]`'s (which makes the kernel
/// tiled, and is the width of its `tile(x)`).
pub fn lower_kernel(
    item: &syn::ItemFn,
    kind: FnKind,
    block_dim: Option<crate::types::Dim>,
) -> Result<Function, Vec<syn::Error>> {
    // Another pass only when a failed one learned a literal `let`'s type from its uses
    // (`literal_lets`); each pass learns at least one, and a body has few such `let`s.
    let mut given = HashMap::new();
    for _ in 0..8 {
        let (result, found) = lower_pass(item, kind, block_dim.clone(), given.clone());
        if result.is_ok() || found.is_empty() {
            return result;
        }
        given.extend(found);
    }
    lower_pass(item, kind, block_dim, given).0
}

/// One pass of [`lower_kernel`], with the literal `let`s' types known so far; also returns
/// the types it learned.
fn lower_pass(
    item: &syn::ItemFn,
    kind: FnKind,
    block_dim: Option<crate::types::Dim>,
    given: HashMap<usize, Ty>,
) -> (Result<Function, Vec<syn::Error>>, HashMap<usize, Ty>) {
    let mut cx = Lowerer {
        defaults: literal_lets::Defaults::new(given),
        tiled: block_dim.clone().map(|width| Tiled { width: Some(width) }),
        obligations: Vec::new(),
        kind,
        fn_name: item.sig.ident.to_string(),
        vars: Vec::new(),
        scopes: vec![HashMap::new()],
        blocks: vec![Vec::new()],
        errors: Vec::new(),
        tid_ndim: None,
        callees: Vec::new(),
        ret: Ty::Unit,
        views: HashMap::new(),
        consts: Vec::new(),
        ref_params: Vec::new(),
        call_checks: Vec::new(),
        param_tys: Vec::new(),
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
                // `acc: &mut f32` (funcs): an in-out parameter, the type it refers to.
                let (ty_syn, by_ref) = match &*pt.ty {
                    syn::Type::Reference(r) if kind == FnKind::Func => {
                        if r.mutability.is_none() {
                            cx.errors.push(syn::Error::new(
                                pt.ty.span(),
                                "a func takes values by value (`x: f32`, a copy) or by `&mut` (`x: &mut f32`, to write the caller's variable): a shared reference `&T` adds nothing",
                            ));
                            continue;
                        }
                        (&*r.elem, true)
                    }
                    t => (t, false),
                };
                match parse_type(ty_syn) {
                    Ok(t @ (Ty::Array(..) | Ty::Object(_))) if by_ref => {
                        cx.errors.push(syn::Error::new(
                            pt.ty.span(),
                            format!("a `&mut` parameter is a value the caller owns: pass a `{t}` by value (an array is written in place)"),
                        ))
                    }
                    Ok(_) if by_ref && cx.ref_params.len() + 1 >= MAX_TUPLE => {
                        cx.errors.push(syn::Error::new(
                            pt.ty.span(),
                            format!("a func takes at most {} `&mut` parameters", MAX_TUPLE - 1),
                        ))
                    }
                    Ok(t @ Ty::Tuple(_)) if kind == FnKind::Kernel => cx.errors.push(syn::Error::new(
                        pt.ty.span(),
                        format!("a tuple is not a kernel parameter: pass its elements (funcs take `{t}`)"),
                    )),
                    Ok(Ty::Tile(..)) => cx.errors.push(syn::Error::new(
                        pt.ty.span(),
                        "a tile is not a parameter: pass an array and load tiles from it with `tile_load`",
                    )),
                    Ok(Ty::LocalArray(..)) if kind == FnKind::Kernel => cx.errors.push(syn::Error::new(
                        pt.ty.span(),
                        "a local array is not a kernel parameter: pass an `Array<T>` (funcs take local arrays)",
                    )),
                    Ok(ty) => {
                        // A `&mut` parameter's value is written by the body (`*acc += x`).
                        let var = cx.new_var(Some(name.clone()), ty.clone(), mutable || by_ref);
                        cx.scopes[0].insert(name.clone(), var);
                        if by_ref {
                            cx.ref_params.push(var);
                        }
                        cx.param_tys.push((var, ty_syn.clone()));
                        params.push(Param {
                            name,
                            var,
                            ty,
                            syn_ty: ty_syn.clone(),
                            by_ref,
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
            Ok(Ty::Object(k)) => cx.errors.push(syn::Error::new(
                t.span(),
                format!(
                    "funcs cannot return a `{}`: objects are kernel parameters",
                    k.row().name
                ),
            )),
            Ok(Ty::Tile(..)) => cx.errors.push(syn::Error::new(
                t.span(),
                "funcs cannot return tiles yet: write the tile code in the kernel",
            )),
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
            // rustc checks the tail's type; a literal `let`'s may still be learned from it.
            if !cx.ty(v).is_deferred() && !ret.is_deferred() && cx.ty(v) != ret {
                cx.learn_literal_type(v, &ret);
            }
            cx.push_return(Some(v), item.block.span())
        }
        Ok(Some(_)) => {}
        Ok(None) if kind == FnKind::Func && !matches!(ret, Ty::Unit) => {
            // Allowed when every path returns explicitly; rustc checks that on the CPU side.
        }
        // A unit func with `&mut` parameters returns their values at its end.
        Ok(None) if !cx.ref_params.is_empty() => cx.push_return(None, item.block.span()),
        Ok(None) => {}
        Err(e) => cx.errors.push(e),
    }
    // What a func with `&mut` parameters returns (see `Function::ret`).
    let (ret, ret_syn) = if cx.ref_params.is_empty() {
        (ret, ret_syn)
    } else {
        let mut tys = vec![ret];
        tys.extend(cx.ref_params.iter().map(|v| cx.ty(*v)));
        let user: syn::Type = ret_syn.unwrap_or_else(|| syn::parse_quote!(()));
        let refs = params.iter().filter(|p| p.by_ref).map(|p| &p.syn_ty);
        (Ty::Tuple(tys), Some(syn::parse_quote!((#user, #(#refs),*))))
    };
    if cx.tiled.is_some() && kind == FnKind::Func {
        cx.errors.push(syn::Error::new(
            item.sig.ident.span(),
            "funcs cannot use tiles or `lane()` yet: write the tile code in the kernel",
        ));
    }
    cx.note_tile_consts();
    cx.note_length_consts();
    if let (Some(_), Some(sp)) = (&cx.tiled, cx.local_array_span()) {
        cx.errors.push(syn::Error::new(
            sp,
            "local arrays are not supported in tiled kernels yet: use a tile or lane variables",
        ));
    }
    let found = std::mem::take(&mut cx.defaults.found);
    if !cx.errors.is_empty() {
        return (Err(cx.errors), found);
    }
    let body = cx.blocks.pop().expect("function block");
    let function = Function {
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
        tiled: cx.tiled,
        shape_obligations: cx.obligations,
        deterministic: None,
        call_checks: cx.call_checks,
        custom_replay: false,
    };
    (Ok(function), found)
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
    /// In-kernel views (`a.row(i)`, `a.view(lo..hi)`), resolved into the arrays they view.
    views: HashMap<VarId, views::ViewDef>,
    /// Module-level consts read (`Op::Const`), each once, in first-use order.
    consts: Vec<syn::Path>,
    /// A func's `&mut` parameters, in order (see `Function::ret`).
    ref_params: Vec<VarId>,
    /// Every user func call's `&mut` arguments (`Function::call_checks`).
    call_checks: Vec<CallCheck>,
    /// The parameters' types as written (a call's arguments' types, `resolve`).
    param_tys: Vec<(VarId, syn::Type)>,
    /// Set by the first tile operation or `lane()`, or by `#[kernel(block_dim = N)]`.
    tiled: Option<Tiled>,
    /// Tile shape rules left to rustc (`Function::shape_obligations`).
    obligations: Vec<ShapeObligation>,
    /// Literal `let`s typed by their uses (`literal_lets`).
    defaults: literal_lets::Defaults,
}

fn strip(e: &Expr) -> &Expr {
    match e {
        Expr::Paren(p) => strip(&p.expr),
        Expr::Group(g) => strip(&g.expr),
        _ => e,
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

    /// `return value`: in a func with `&mut` parameters, the tuple of the value (`()` if
    /// none) and those parameters' current values.
    fn push_return(&mut self, value: Option<VarId>, span: Span) {
        let value = if self.ref_params.is_empty() {
            value
        } else {
            let r = match value {
                Some(v) => v,
                None => self.def(Op::Tuple(Vec::new()), Ty::Unit, span),
            };
            let mut elems = vec![r];
            elems.extend(self.ref_params.iter().copied());
            let mut tys = vec![self.ret.clone()];
            tys.extend(self.ref_params.iter().map(|v| self.ty(*v)));
            Some(self.def(Op::Tuple(elems), Ty::Tuple(tys), span))
        };
        self.push(StmtKind::Return { value }, span);
    }

    /// The `&mut` parameter `e` names, if it is a bare name of one (`acc`, not `*acc`).
    fn ref_param(&self, e: &Expr) -> Option<VarId> {
        let Expr::Path(p) = strip(e) else { return None };
        let v = self.lookup(&p.path.get_ident()?.to_string())?;
        self.ref_params.contains(&v).then_some(v)
    }

    /// The base of a field, an index or a method call, where Rust dereferences a `&mut`
    /// parameter itself (`acc.x`, `acc[i]`, `acc.length()`).
    fn base_expr(&mut self, e: &Expr) -> R<VarId> {
        match self.ref_param(e) {
            Some(v) => Ok(v),
            None => self.expr(e, None),
        }
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
}

#[cfg(test)]
mod tests;

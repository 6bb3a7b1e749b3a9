//! Which func a call runs, from its arguments' types: `score(x)` with `x: f32` is the overload
//! of `score` taking an `f32`, `cube(v)` with `v: DVec3` the instance `cube<f64>`.
//!
//! The macro cannot see other items, so it does not resolve the call itself: it names the
//! callee as `Callee<score, (f32,)>` (the facade's `overload` module), a type that rustc maps
//! through the `Resolve` impls each `#[func]` emits (`expand::overloads`) to the func that
//! takes those types. Every later stage uses that path as it would the written one (the CPU
//! code's `path::__wp_cpu(..)`, the CUDA callee list's `path::__WP_FUNC`, the adjoint's
//! `path::__wp_adj(..)`), so the two back ends run the same func, and a call that no
//! overload takes fails at `cargo build`, at the call.
//!
//! An argument's type is written out when the macro knows it (a scalar, a glam type, a
//! parameter's type as written, an array's element, another func's result through
//! `RetOf<..>`), and `_` otherwise (a literal, a struct's field): rustc fills that in when
//! exactly one candidate fits.

use super::*;
use quote::{quote, quote_spanned, ToTokens};

/// The name of the func a callee path names: `score` for `a::score::<i32>` and for the
/// resolved `Callee<a::score, (i32,)>` (messages name the func as written).
pub(crate) fn callee_name(path: &syn::Path) -> String {
    let last = path.segments.last().expect("a path has a segment");
    if last.ident == "Callee" {
        if let syn::PathArguments::AngleBracketed(a) = &last.arguments {
            if let Some(syn::GenericArgument::Type(syn::Type::Path(tp))) = a.args.first() {
                return callee_name(&tp.path);
            }
        }
    }
    last.ident.to_string()
}

/// The func and the argument types of a resolved callee path (`Callee::<f, (A, _)>`), when
/// an argument's type was left to rustc (`_`): `expand::checks` asks rustc to resolve them
/// once more where an ambiguity reads as one.
pub(crate) fn unresolved_parts(path: &syn::Path) -> Option<(&syn::Type, &syn::Type)> {
    let last = path.segments.last()?;
    let syn::PathArguments::AngleBracketed(a) = &last.arguments else {
        return None;
    };
    match (last.ident == "Callee", a.args.first(), a.args.get(1)) {
        (true, Some(syn::GenericArgument::Type(f)), Some(syn::GenericArgument::Type(t))) => {
            fn open(ts: proc_macro2::TokenStream) -> bool {
                ts.into_iter().any(|tt| match tt {
                    proc_macro2::TokenTree::Group(g) => open(g.stream()),
                    tt => tt.to_string() == "_",
                })
            }
            open(t.to_token_stream()).then_some((f, t))
        }
        _ => None,
    }
}

/// `__wp::Vec3`-style tokens with `__wp` (the alias kernels' bodies import) replaced by the
/// facade's full path, since a callee path is also used outside those bodies (the `FuncInfo`
/// constants of a func).
fn absolute(ts: proc_macro2::TokenStream) -> proc_macro2::TokenStream {
    use proc_macro2::{Group, TokenTree};
    ts.into_iter()
        .flat_map(|t| match t {
            TokenTree::Ident(i) if i == "__wp" => crate::paths::private().into_iter().collect(),
            TokenTree::Group(g) => {
                let mut ng = Group::new(g.delimiter(), absolute(g.stream()));
                ng.set_span(g.span());
                vec![TokenTree::Group(ng)]
            }
            t => vec![t],
        })
        .collect()
}

impl Lowerer {
    /// The path a call of the func written `path` with argument variables `args` names its
    /// callee by (see the module's comment).
    pub(super) fn resolve_callee(&self, path: &syn::Path, args: &[VarId], span: Span) -> syn::Path {
        let wp = crate::paths::private_at(span);
        let tys: Vec<proc_macro2::TokenStream> = args
            .iter()
            .map(|a| self.rust_type(*a, 0).unwrap_or_else(|| quote!(_)))
            .collect();
        let tokens = quote_spanned!(span=> #wp::Callee::<#path, (#(#tys,)*)>);
        syn::parse2(tokens).expect("a path")
    }

    /// The Rust type of `v` as tokens valid anywhere in the user's module, when the macro can
    /// tell it.
    fn rust_type(&self, v: VarId, depth: usize) -> Option<proc_macro2::TokenStream> {
        if depth > 32 {
            return None;
        }
        if let Some((_, t)) = self.param_tys.iter().find(|(p, _)| *p == v) {
            return Some(t.to_token_stream());
        }
        if let Some(t) = crate::back::rust::ty_tokens(&self.vars[v].ty) {
            return Some(absolute(t));
        }
        let mut op = None;
        for b in &self.blocks {
            walk_stmts(b, &mut |s| {
                if let StmtKind::Assign { dst, op: o, .. } = &s.kind {
                    if *dst == v && op.is_none() {
                        op = Some(o.clone());
                    }
                }
            });
        }
        match op? {
            Op::Copy(w) => self.rust_type(w, depth + 1),
            // A func's result (one with `&mut` parameters is read through a member: `_`).
            // (`wp::grad(f)`'s companion declares no result type: its adjoints.)
            Op::Func { path, .. } if !callee_name(&path).starts_with("__wp_grad_") => {
                let wp = crate::paths::private();
                Some(quote!(#wp::RetOf<#path>))
            }
            // An element of an array parameter: the element type as written.
            Op::Load { array, .. } => {
                let arr = self.param_tys.iter().find(|(p, _)| *p == array)?;
                let syn::Type::Path(tp) = &arr.1 else {
                    return None;
                };
                let syn::PathArguments::AngleBracketed(a) = &tp.path.segments.last()?.arguments
                else {
                    return None;
                };
                match a.args.first()? {
                    syn::GenericArgument::Type(t) => Some(t.to_token_stream()),
                    _ => None,
                }
            }
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use syn::parse_quote;

    /// Every func call's callee, as text without spaces.
    fn callees(item: syn::ItemFn) -> Vec<String> {
        let f = lower_fn(&item, FnKind::Kernel).unwrap_or_else(|e| {
            panic!("{:?}", e.iter().map(|e| e.to_string()).collect::<Vec<_>>())
        });
        f.callees
            .iter()
            .map(|p| p.to_token_stream().to_string().replace(' ', ""))
            .collect()
    }

    #[test]
    fn arguments_name_their_types_where_the_macro_knows_them() {
        let got = callees(parse_quote! {
            fn k(x: Array<f32>, p: Array<crate::Probe>, v: Vec3, n: i32) {
                let i = tid();
                let a = mix(x[i], n);
                let b = mix(p[i], a, 1.0);
                let c = m::mix::<f32>(twice(v.x), p[i].w);
            }
        });
        let wp = ":: warp_lang :: __private".replace(' ', "");
        assert_eq!(
            got,
            [
                format!("{wp}::Callee::<mix,(f32,i32,)>"),
                format!("{wp}::Callee::<mix,(crate::Probe,{wp}::RetOf<{wp}::Callee::<mix,(f32,i32,)>>,_,)>"),
                format!("{wp}::Callee::<twice,(f32,)>"),
                format!("{wp}::Callee::<m::mix::<f32>,({wp}::RetOf<{wp}::Callee::<twice,(f32,)>>,_,)>"),
            ]
        );
        // Messages name the func as written; a key with `_` is checked once more.
        let p: syn::Path = syn::parse_str(&got[3]).unwrap();
        assert_eq!(callee_name(&p), "mix");
        assert!(unresolved_parts(&p).is_some());
        let p: syn::Path = syn::parse_str(&got[0]).unwrap();
        assert!(unresolved_parts(&p).is_none());
    }
}

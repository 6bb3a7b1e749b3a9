//! Overloads and the resolution of calls by their arguments' types: `wp::overloads!(name)`
//! (the set's types), and the keys and resolved options every func's `Resolve` impls and
//! custom gradients use (`funcs.rs` emits them, and each `#[func(overload)]` member), through
//! which a call `name(a, b)` (lowered to `Callee<name, (A, B)>`, see
//! `front::lower::resolve`) reaches the plain func, the overload or the generic instance that
//! takes arguments of those types.
//!
//! An overload's unit struct is `name<K, (R..)>`: `K` its first parameter's type and `R..` the
//! others'. Keying on every parameter lets two overloads share a first parameter type (Warp
//! resolves on every argument); keeping the first apart lets `name::<K>(..)`, the explicit
//! form, name the overloads of first parameter `K` (`name<K>` is `name<K, ()>`, itself a
//! resolver for them), and `name` alone (`name<Unresolved, ()>`) resolves among all of them.
//! Two overloads with the same parameter types are two impls of one `Resolve<..>` for `name`:
//! rustc's conflicting-implementations error, at the second.

use super::*;

/// The parameter types a func's resolution is keyed on, in order (a `&mut` parameter's
/// referent).
pub(super) fn param_key(item: &syn::ItemFn) -> Vec<syn::Type> {
    item.sig
        .inputs
        .iter()
        .filter_map(|a| match a {
            syn::FnArg::Typed(pt) => Some(match &*pt.ty {
                syn::Type::Reference(r) => (*r.elem).clone(),
                t => t.clone(),
            }),
            syn::FnArg::Receiver(_) => None,
        })
        .collect()
}

/// `(A, B,)`: a resolution key.
pub(super) fn key_tuple(tys: &[syn::Type]) -> TokenStream {
    quote!((#(#tys,)*))
}

/// A custom gradient's or replay's func, named as the user wrote it, resolved for one
/// instance or overload: its type parameters substituted (`dcube::<T>` of `cube<f64>` is
/// `dcube::<f64>`), then looked up by the types it is called with (a gradient func takes the
/// parameters and the result's adjoint; a replay the parameters), so that a generic or
/// overloaded gradient func needs no turbofish.
pub(super) fn resolve_attr_path(
    path: &syn::Path,
    subst: Option<(&generics::Generics, &[syn::Type])>,
    args: &[syn::Type],
) -> syn::Path {
    let path = match subst {
        Some((g, types)) => generics::substitute_path(path, g, types),
        None => path.clone(),
    };
    let sp = path.span();
    let wp = crate::paths::private_at(sp);
    let key = key_tuple(args);
    syn::parse2(quote_spanned!(sp=> #wp::Callee::<#path, #key>)).expect("a path")
}

/// The options of one instance or overload: its gradient and replay funcs resolved
/// ([`resolve_attr_path`]); `ret` is the func's declared result (a gradient func's last
/// argument is its adjoint).
pub(super) fn instance_attrs(
    fattrs: &attrs::FuncAttrs,
    subst: Option<(&generics::Generics, &[syn::Type])>,
    item: &syn::ItemFn,
) -> attrs::FuncAttrs {
    let params = param_key(item);
    let ret: syn::Type = match &item.sig.output {
        syn::ReturnType::Default => syn::parse_quote!(()),
        syn::ReturnType::Type(_, t) => (**t).clone(),
    };
    let mut grad_args = params.clone();
    grad_args.push(ret);
    attrs::FuncAttrs {
        grad: fattrs
            .grad
            .iter()
            .map(|(id, p)| (id.clone(), resolve_attr_path(p, subst, &grad_args)))
            .collect(),
        instances: Vec::new(),
        overload: fattrs.overload.clone(),
        replay: fattrs
            .replay
            .as_ref()
            .map(|r| resolve_attr_path(r, subst, &params)),
    }
}

/// `wp::overloads!(#[doc..] pub name)`: the set's unit struct and its `wp::grad` companion's,
/// each generic over an overload's key (`name<K, (R..)>`), `Unresolved` by default.
pub fn overload_set(input: TokenStream) -> TokenStream {
    use syn::parse::Parser;
    let parser = |input: syn::parse::ParseStream| {
        let attrs = input.call(syn::Attribute::parse_outer)?;
        let vis: syn::Visibility = input.parse()?;
        let name: syn::Ident = input.parse()?;
        Ok((attrs, vis, name))
    };
    let (attrs, vis, name) = match parser.parse2(input) {
        Ok(x) => x,
        Err(e) => return e.to_compile_error(),
    };
    let wp = crate::paths::private();
    let grad = format_ident!(
        "{}",
        lower::calls::companion_of(&name.to_string()),
        span = name.span()
    );
    quote! {
        #(#attrs)*
        ///
        /// A set of overloaded `#[func]`s: a call `name(a, b)` runs the overload whose
        /// parameter types the arguments have; `name::<i32>(..)` names the overloads whose
        /// first parameter is an `i32`.
        #[allow(non_camel_case_types)]
        #vis struct #name<K = #wp::Unresolved, R = ()> {
            _overload: ::core::marker::PhantomData<(K, R)>,
        }
        /// `wp::grad(f)` of the set's overloads.
        #[doc(hidden)]
        #[allow(non_camel_case_types)]
        #vis struct #grad<K = #wp::Unresolved, R = ()> {
            _overload: ::core::marker::PhantomData<(K, R)>,
        }
    }
}

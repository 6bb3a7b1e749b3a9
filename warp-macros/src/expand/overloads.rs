//! Overloads and the resolution of calls by their arguments' types: `wp::overloads!(name)`
//! (the set's types), `#[func(overload)]` (one member), and the `Resolve` impls every func
//! emits, through which a call `name(a, b)` (lowered to `Callee<name, (A, B)>`, see
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

use super::funcs::{func_instance, tile_map_impl};
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

/// `#[func(overload)]`: one overload of the set `wp::overloads!(name)` declares, for each of
/// its instances (one for a plain func) the inherent items of `name<K, (R..)>` and its
/// companion's, and the `Resolve` impls that lead a call to them (see the module's comment).
/// Emits no item of the func's own name, so several overloads may share it. One func's
/// instances with the same parameter types are refused here.
pub(super) fn overload_member(
    item: &syn::ItemFn,
    fattrs: &attrs::FuncAttrs,
    g: Option<&generics::Generics>,
    mut errors: Vec<syn::Error>,
) -> TokenStream {
    let wp = crate::paths::private();
    let name = &item.sig.ident;
    let grad = format_ident!(
        "{}",
        lower::calls::companion_of(&name.to_string()),
        span = name.span()
    );
    let instances: Vec<(syn::ItemFn, Option<Vec<syn::Type>>)> = match g {
        Some(g) => generics::instances(item, g)
            .into_iter()
            .map(|i| (i.item, Some(i.types)))
            .collect(),
        None => vec![(item.clone(), None)],
    };
    let text = |t: &dyn ToTokens| t.to_token_stream().to_string().replace(' ', "");
    let mut keys: Vec<Vec<syn::Type>> = Vec::new();
    for (inst, _) in &instances {
        let ps = param_key(inst);
        if ps.is_empty() {
            errors.push(syn::Error::new(
                item.sig.paren_token.span.join(),
                "an overload is selected by its parameters' types (`name(x)`, `name::<i32>(x)`): it needs a parameter",
            ));
            return errors_to_tokens(errors);
        }
        let t = text(&key_tuple(&ps));
        if keys.iter().any(|o| text(&key_tuple(o)) == t) {
            errors.push(syn::Error::new(
                ps[0].span(),
                format!(
                    "two instances of this overload take parameters of types `{t}`: overloads are told apart by their parameters' types, so a type parameter must appear in them"
                ),
            ));
            return errors_to_tokens(errors);
        }
        keys.push(ps);
    }
    if !errors.is_empty() {
        return errors_to_tokens(errors);
    }
    let mut impls = TokenStream::new();
    let mut per_instance = Vec::new();
    for ((inst, types), ps) in instances.iter().zip(&keys) {
        let (k, rest) = (&ps[0], &ps[1..]);
        // Named by its parameter types, as Warp prints an overload: `combine(i32, i32)`.
        let names: Vec<String> = ps.iter().map(|t| text(t)).collect();
        let display = format!("{name}({})", names.join(", "));
        let ksp = k.span();
        let rest_t = key_tuple(rest);
        let self_ty = quote_spanned!(ksp=> #name<#k, #rest_t>);
        let grad_ty = quote_spanned!(ksp=> #grad<#k, #rest_t>);
        let key = key_tuple(ps);
        let subst = g.zip(types.as_deref());
        let iattrs = instance_attrs(fattrs, subst, inst);
        // Lowered under a name of its own: a call of the set's name in the body is another
        // overload's (`quantize(x.x, step)` in the vector overload), not recursion, which
        // the call-depth constants still catch.
        let mut member = inst.clone();
        member.sig.ident = format_ident!("{}__overload", name, span = name.span());
        match func_instance(&member, &iattrs, Some(display.clone()), self_ty.clone()) {
            Ok((items, companion, ret)) => {
                impls.extend(quote_spanned! {ksp=>
                    impl #self_ty {
                        #items
                    }
                    impl #grad_ty {
                        #companion
                    }
                    impl #wp::Resolve<#key> for #name {
                        type Callee = #self_ty;
                    }
                    impl #wp::Resolve<#key> for #name<#k> {
                        type Callee = #self_ty;
                    }
                    impl #wp::Resolve<#key> for #grad {
                        type Callee = #grad_ty;
                    }
                    impl #wp::Resolve<#key> for #grad<#k> {
                        type Callee = #grad_ty;
                    }
                    impl #wp::FuncRet for #self_ty {
                        type Ret = #ret;
                    }
                });
                impls.extend(quote! {
                    const _: usize = <#self_ty>::__WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED;
                    const _: () = <#self_ty>::__WP_LOCAL_ARRAYS;
                    const _: () = <#self_ty>::__WP_CALLS;
                });
                impls.extend(tile_map_impl(inst, self_ty));
                per_instance.push((display, Vec::new()));
            }
            Err(e) => per_instance.push((display, e)),
        }
    }
    errors.extend(instance_errors(per_instance));
    if !errors.is_empty() {
        return errors_to_tokens(errors);
    }
    let bound_check = g.map(generics::bound_check).unwrap_or_default();
    quote! {
        #bound_check
        #impls
    }
}

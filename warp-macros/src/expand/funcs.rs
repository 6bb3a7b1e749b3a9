//! `#[func]`: a func's items (its CPU code, replay, adjoint and what the CUDA assembler
//! needs), per instance of a generic func and per overload, with the companion `wp::grad`
//! calls (`grad_of`). Kernels are expanded by the parent module, whose helpers this uses.

use super::overloads::{instance_attrs, key_tuple, param_key};
use super::*;

/// `#[func]`.
pub fn func(attr: TokenStream, item: TokenStream) -> TokenStream {
    let item: syn::ItemFn = match syn::parse2(item) {
        Ok(i) => i,
        Err(e) => return e.to_compile_error(),
    };
    let mut errors = Vec::new();
    let fattrs = match attrs::parse_func_attrs(attr) {
        Ok(a) => a,
        Err(e) => {
            errors.push(e);
            attrs::FuncAttrs::default()
        }
    };
    let vis = &item.vis;
    let name = &item.sig.ident;
    let doc_attrs: Vec<&syn::Attribute> = item
        .attrs
        .iter()
        .filter(|a| a.path().is_ident("doc"))
        .collect();
    let failed = |errors: Vec<syn::Error>| {
        let errs = errors_to_tokens(errors);
        quote!(#errs #[allow(non_camel_case_types)] #vis struct #name {})
    };
    // A kernel's call `sign(x)` resolves to the builtin before any func, so a func named like
    // a builtin would never be called: refused here rather than silently shadowed.
    let fname = name.to_string();
    if crate::builtins::lookup_user(&fname).is_some() {
        errors.push(syn::Error::new(
            name.span(),
            format!(
                "`{fname}` is a builtin's name: kernels calling `{fname}(..)` get the builtin, \
                 never this func; give the func another name"
            ),
        ));
    }
    let generics = match generics::parse(&item, &fattrs.instances) {
        Ok(g) => g,
        Err(e) => {
            errors.extend(e);
            return failed(errors);
        }
    };
    if fattrs.overload.is_some() {
        return overload_member(&item, &fattrs, generics.as_ref(), errors);
    }
    let Some(g) = generics else {
        if !errors.is_empty() {
            if let Err(e) = lower::lower_fn(&item, FnKind::Func) {
                errors.extend(e);
            }
            return failed(errors);
        }
        let tile_map_impl = tile_map_impl(&item, quote!(#name));
        let grad_name = format_ident!(
            "{}",
            lower::calls::companion_of(&name.to_string()),
            span = name.span()
        );
        let wp = crate::paths::private();
        let key = key_tuple(&param_key(&item));
        let iattrs = instance_attrs(&fattrs, None, &item);
        return match func_instance(&item, &iattrs, None, quote!(#name)) {
            Ok((items, companion, ret)) => quote! {
                #(#doc_attrs)*
                ///
                /// A `#[func]`: callable from kernels and other funcs.
                #[allow(non_camel_case_types)]
                #vis struct #name {}

                impl #name {
                    #items
                }

                /// `wp::grad(f)` of this func (`wp::grad` in kernels).
                #[doc(hidden)]
                #[allow(non_camel_case_types)]
                #vis struct #grad_name {}

                impl #grad_name {
                    #companion
                }

                // A call `name(..)` of these argument types (`overloads`).
                impl #wp::Resolve<#key> for #name {
                    type Callee = #name;
                }
                impl #wp::Resolve<#key> for #grad_name {
                    type Callee = #grad_name;
                }
                impl #wp::FuncRet for #name {
                    type Ret = #ret;
                }

                const _: usize = #name::__WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED;
                const _: () = #name::__WP_LOCAL_ARRAYS;
                const _: () = #name::__WP_CALLS;
                #tile_map_impl
            },
            Err(e) => failed(e),
        };
    };
    // A generic func: `f<T>` is a type with one inherent impl per instance. A call `f(x)`
    // reaches the instance whose parameter types the arguments have (`overloads`), and
    // `f::<T>(..)` names one (in a generic kernel, `T` is concrete by then).
    // (No `check_params_select` here: a caller may name an instance its arguments do not
    // tell apart, `zero::<f64>()`.)
    let wp = crate::paths::private();
    let instances = generics::instances(&item, &g);
    let keys: Vec<String> = instances
        .iter()
        .map(|i| key_tuple(&param_key(&i.item)).to_string())
        .collect();
    // Instances with the same parameter types cannot be told apart by a call's arguments:
    // such a func is called by naming its instance only.
    let by_args = (0..keys.len()).all(|k| !keys[..k].contains(&keys[k]));
    let grad_name = format_ident!(
        "{}",
        lower::calls::companion_of(&name.to_string()),
        span = name.span()
    );
    let mut impls = TokenStream::new();
    let mut per_instance = Vec::new();
    for inst in &instances {
        let display = inst.display_name(&name.to_string());
        let tys = &inst.types;
        let key = key_tuple(&param_key(&inst.item));
        let iattrs = instance_attrs(&fattrs, Some((&g, tys)), &inst.item);
        match func_instance(
            &inst.item,
            &iattrs,
            Some(display.clone()),
            quote!(#name<#(#tys),*>),
        ) {
            Ok((items, companion, ret)) => {
                let inferred = by_args.then(|| {
                    quote! {
                        impl #wp::Resolve<#key> for #name {
                            type Callee = #name<#(#tys),*>;
                        }
                        impl #wp::Resolve<#key> for #grad_name {
                            type Callee = #grad_name<#(#tys),*>;
                        }
                    }
                });
                impls.extend(quote! {
                    impl #name<#(#tys),*> {
                        #items
                    }
                    impl #grad_name<#(#tys),*> {
                        #companion
                    }
                    impl #wp::Resolve<#key> for #name<#(#tys),*> {
                        type Callee = Self;
                    }
                    impl #wp::Resolve<#key> for #grad_name<#(#tys),*> {
                        type Callee = Self;
                    }
                    impl #wp::FuncRet for #name<#(#tys),*> {
                        type Ret = #ret;
                    }
                    #inferred
                    const _: usize =
                        #name::<#(#tys),*>::__WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED;
                    const _: () = #name::<#(#tys),*>::__WP_LOCAL_ARRAYS;
                    const _: () = #name::<#(#tys),*>::__WP_CALLS;
                });
                impls.extend(tile_map_impl(&inst.item, quote!(#name<#(#tys),*>)));
                per_instance.push((display, Vec::new()));
            }
            Err(e) => per_instance.push((display, e)),
        }
    }
    errors.extend(instance_errors(per_instance));
    let params: Vec<&syn::Ident> = g.params.iter().map(|p| &p.ident).collect();
    if !errors.is_empty() {
        // Keep the generic type, so that callers' `f::<f32>(..)` add no errors of their own.
        let errs = errors_to_tokens(errors);
        return quote! {
            #errs
            #[allow(non_camel_case_types)]
            #vis struct #name<#(#params),*> {
                _instance: ::core::marker::PhantomData<(#(#params,)*)>,
            }
        };
    }
    let bound_check = generics::bound_check(&g);
    quote! {
        #(#doc_attrs)*
        ///
        /// A generic `#[func]`: callable from kernels and other funcs as `name(..)` (the
        /// instance the arguments' types select), `name::<f32>(..)` or, in a generic kernel,
        /// `name::<T>(..)`.
        #[allow(non_camel_case_types)]
        #vis struct #name<#(#params = #wp::Unresolved),*> {
            _instance: ::core::marker::PhantomData<(#(#params,)*)>,
        }
        /// `wp::grad(f::<T>)` of this func's instances.
        #[doc(hidden)]
        #[allow(non_camel_case_types)]
        #vis struct #grad_name<#(#params = #wp::Unresolved),*> {
            _instance: ::core::marker::PhantomData<(#(#params,)*)>,
        }
        #bound_check
        #impls
    }
}

/// `#[func(overload)]`: one overload of the set `wp::overloads!(name)` declares, for each of
/// its instances (one for a plain func) the inherent items of `name<K, (R..)>` and its
/// companion's, and the `Resolve` impls that lead a call to them (see `overloads`).
/// Emits no item of the func's own name, so several overloads may share it. One func's
/// instances with the same parameter types are refused here.
fn overload_member(
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

/// `impl TileMapFn<(params..), ret> for func {}` where every parameter and the result are
/// scalars other than `bool` (what `tile_map` can apply; the kernel checks its use against
/// it, as the kernel macro cannot see the func's signature); nothing otherwise.
fn tile_map_impl(item: &syn::ItemFn, self_ty: TokenStream) -> TokenStream {
    use crate::types::{Scalar, Ty};
    let wp = crate::paths::private();
    let scalar = |t: &syn::Type| matches!(crate::front::signature::parse_type(t), Ok(Ty::Scalar(s)) if s != Scalar::Bool);
    let mut params = Vec::new();
    for a in &item.sig.inputs {
        match a {
            syn::FnArg::Typed(p) if scalar(&p.ty) => params.push(&*p.ty),
            _ => return TokenStream::new(),
        }
    }
    let syn::ReturnType::Type(_, ret) = &item.sig.output else {
        return TokenStream::new();
    };
    if params.is_empty() || !scalar(ret) {
        return TokenStream::new();
    }
    let k: Vec<syn::Index> = (0..params.len()).map(syn::Index::from).collect();
    quote! {
        impl #wp::tile::TileMapFn<(#(#params,)*), #ret> for #self_ty {
            #[inline(always)]
            fn call(__a: (#(#params,)*)) -> #wp::KResult<#ret> {
                Self::__wp_cpu(#(__a.#k),*)
            }
            #[inline(always)]
            fn replay(__a: (#(#params,)*)) -> #wp::KResult<#ret> {
                Self::__wp_replay(#(__a.#k),*)
            }
            #[inline(always)]
            fn adj(
                __a: (#(#params,)*),
                __adj: &mut (#(#params,)*),
                __r: #ret,
                __stack: &mut #wp::AdStack,
            ) -> #wp::KResult<()> {
                Self::__wp_adj(#(__a.#k,)* #(&mut __adj.#k,)* __r, __stack)
            }
        }
    }
}

/// The type a func's parameter has in its CPU code: what a kernel thread sees of a kernel
/// parameter of that type (`KernelArg::CpuView`), or a local array or a tuple itself (values
/// that only funcs take). A `&mut` parameter is its value (see `ir::Function::ret`).
fn func_param_ty(p: &crate::ir::Param, wp: &TokenStream) -> TokenStream {
    let t = &p.syn_ty;
    match p.ty {
        crate::types::Ty::LocalArray(..) | crate::types::Ty::Tuple(_) => quote!(#t),
        _ => quote!(<#t as #wp::KernelArg>::CpuView),
    }
}

/// The inherent items of one func or one instance of a generic func (its CPU code, replay,
/// adjoint, and what the CUDA assembler needs); `display` names a generic instance.
fn func_instance(
    item: &syn::ItemFn,
    fattrs: &attrs::FuncAttrs,
    display: Option<String>,
    func_ty: TokenStream,
) -> Result<(TokenStream, TokenStream, TokenStream), Vec<syn::Error>> {
    let wp = crate::paths::private();
    let mut f = lower::lower_fn(item, FnKind::Func)?;
    if let Some(d) = display {
        f.name = d;
    }
    f.custom_replay = fattrs.replay.is_some();
    if let (Some((id, _)), Some(p)) = (fattrs.grad.first(), f.params.iter().find(|p| p.by_ref)) {
        return Err(vec![syn::Error::new(
            id.span(),
            format!(
                "custom gradients (`#[func(grad(..))]`) are not supported on funcs with `&mut` parameters (`{}`) yet",
                p.name
            ),
        )]);
    }
    let valid = crate::valid::validate(&f, crate::valid::Options::Func { grad: &fattrs.grad })?;
    let vis = &item.vis;
    let name = &item.sig.ident;
    let em = RustEmitter::new(&f);
    let params = f.params.iter().map(|p| {
        let v = em.var(p.var);
        let m = if f.vars[p.var].mutable {
            quote!(mut)
        } else {
            quote!()
        };
        let t = func_param_ty(p, &wp);
        quote!(#m #v: #t)
    });
    let ret = match &f.ret_syn {
        Some(t) => quote!(#t),
        None => quote!(()),
    };
    let body = em.block(&f.body);
    let tail = if f.ret_syn.is_none() {
        quote!(::core::result::Result::Ok(()))
    } else {
        quote!()
    };
    let depths = f
        .callees
        .iter()
        .map(|p| quote_spanned!(p.span()=> #p::__WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED));
    let cpu = format_ident!("__wp_cpu");
    // The replay (no stores, no atomics) and the adjoint, for kernels' adjoints.
    let replay_fn = crate::middle::adjoint::replay_of(&f);
    let mut replay_em = RustEmitter::new(&replay_fn);
    replay_em.replay = true;
    let replay_body = replay_em.block(&replay_fn.body);
    // Custom gradients replace the generated adjoint (`middle::adjoint::custom`): each named
    // parameter's adjoint is what its gradient func returns for (params.., adjoint of the
    // result); the validator checked that they name value parameters.
    let callees_of_f = &f.callees;
    let generated = if fattrs.grad.is_empty() {
        crate::back::rust_adjoint::emit(&f)
    } else {
        crate::back::rust_adjoint::emit_custom(&f, &fattrs.grad)
    };
    // The CUDA replay and adjoint templates (custom gradients: calls of the gradient funcs,
    // which are recorded as extra callees after the body's).
    let mut all_callees: Vec<syn::Path> = f.callees.clone();
    // Whether the CUDA adjoint may push (custom gradients: their funcs' forward code may call
    // funcs whose replays push; assumed).
    let mut cuda_stack = true;
    let (cuda_adj, cuda_adj_error) = if fattrs.grad.is_empty() {
        let replay = fattrs
            .replay
            .as_ref()
            .map(|r| crate::ir::push_callee(&mut all_callees, r));
        match crate::back::cuda_adjoint::emit_with_replay(&f, "@@FILE@@", replay) {
            Ok(a) => {
                cuda_stack = a.uses_stack;
                (a.source, None)
            }
            Err(why) => (String::new(), Some(why)),
        }
    } else {
        match crate::back::cuda_adjoint::emit_custom(
            &f,
            "@@FILE@@",
            &fattrs.grad,
            &mut all_callees,
            fattrs.replay.as_ref(),
        ) {
            Ok(src) => (src, None),
            Err(why) => (String::new(), Some(why)),
        }
    };
    let cuda_adj = Literal::string(&cuda_adj);
    let cuda_adj_error = match cuda_adj_error {
        None => quote!(::core::option::Option::None),
        Some(why) => {
            let why = Literal::string(&format!(
                "calls func `{}`, which cannot run backward on CUDA yet: {why}",
                f.name
            ));
            quote!(::core::option::Option::Some(#why))
        }
    };
    let (adj_body, adj_error) = match generated {
        // The generated adjoint runs its callees' adjoints: it has none if one of them has
        // none (a custom gradient runs its gradient funcs forward instead).
        Ok(b) if fattrs.grad.is_empty() => (
            b,
            quote!(#wp::first_error(&[#(#callees_of_f::__WP_ADJOINT_ERROR),*])),
        ),
        Ok(b) => (b, quote!(::core::option::Option::None)),
        Err(why) => {
            let why = Literal::string(&format!("calls func `{}`, which {why}", f.name));
            // Never run: backward refuses kernels whose funcs have no adjoint.
            (quote!(), quote!(::core::option::Option::Some(#why)))
        }
    };
    let replay_params: Vec<TokenStream> = f
        .params
        .iter()
        .map(|p| {
            let v = em.var(p.var);
            let t = func_param_ty(p, &wp);
            quote!(mut #v: #t)
        })
        .collect();
    let adj_params: Vec<TokenStream> = f
        .params
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let t = &p.syn_ty;
            if matches!(p.ty, crate::types::Ty::Array(..)) {
                let a = format_ident!("adj_{}", em.var(p.var));
                quote!(#a: <#t as #wp::KernelArg>::GradView)
            } else {
                let (o, t) = (format_ident!("__adj_out{}", k), func_param_ty(p, &wp));
                quote!(#o: &mut #t)
            }
        })
        .collect();
    // A custom replay (`#[func(replay = r)]`) is `r`'s forward code, as in Warp; rustc checks
    // at the option that `r` takes these parameters and returns this result.
    let replay_fn_body = match &fattrs.replay {
        Some(r) => {
            let names = f.params.iter().map(|p| em.var(p.var));
            quote_spanned!(r.span()=> #r::__wp_cpu(#(#names),*))
        }
        None => quote! {
            use #wp as __wp;
            const __FAST: bool = false;
            #replay_body
            #tail
        },
    };
    let (cuda_src, cuda_sections, cuda_ret) = cuda_template(&f);
    let struct_tys = struct_types(&f);
    let name_str = Literal::string(&f.name);
    let callees = &f.callees;
    let consts = const_literals(&f);
    let requires = valid.requires.iter().map(|c| c.tokens());
    let asserts = assert_sites(&f, &wp);
    let float_atomics = crate::analysis::has_float_accumulation(&f);
    let func_info = quote! {
        /// What the CUDA assembler needs to know about this func.
        #[doc(hidden)]
        #vis const __WP_FUNC: #wp::FuncInfo = #wp::FuncInfo {
            name: #name_str,
            module: ::core::module_path!(),
            file: ::core::file!(),
            cuda: #cuda_src,
            cuda_ret: #cuda_ret,
            sections: &[#(#cuda_sections),*],
            callees: &[#(&#all_callees::__WP_FUNC),*],
            structs: &[#(<#struct_tys as #wp::CudaStruct>::cuda_defs),*],
            cuda_adj: #cuda_adj,
            cuda_adj_error: #wp::first_error(&[#cuda_adj_error #(, #callees::__WP_FUNC.cuda_adj_error)*]),
            consts: #consts,
            requires: &[#(#requires),*],
            asserts: #asserts,
            float_atomics: #float_atomics,
            needs_adjoints: false,
        };
    };
    // Spanned at the func's name, so that rustc's cycle error for mutually recursive funcs
    // points there and names this constant.
    let wp_at_name = crate::paths::private_at(name.span());
    let depth_const = quote_spanned! {name.span()=>
        /// Longest chain of funcs below this one (a cycle fails to compile).
        #[doc(hidden)]
        #vis const __WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED: usize =
            1 + #wp_at_name::max_depth(&[#(#depths),*]);
    };
    let array_checks = local_array_checks(&f, &wp);
    let call_checks = call_checks(&f);
    let mut_params = f
        .params
        .iter()
        .enumerate()
        .filter(|(_, p)| p.by_ref)
        .fold(0u64, |m, (k, _)| {
            m | 1u64.checked_shl(k as u32).unwrap_or(0)
        });
    let companion = grad_of::items(
        &grad_of::Companion {
            f: &f,
            func_ty,
            vis,
            params: f
                .params
                .iter()
                .map(|p| (em.var(p.var), func_param_ty(p, &wp)))
                .collect(),
            adj_tys: f
                .params
                .iter()
                .map(|p| {
                    let t = &p.syn_ty;
                    match p.ty {
                        crate::types::Ty::Array(..) => quote!(<#t as #wp::KernelArg>::GradView),
                        _ => {
                            let t = func_param_ty(p, &wp);
                            quote!(&mut #t)
                        }
                    }
                })
                .collect(),
            cuda_stack,
        },
        &wp,
    );
    let items = quote! {
            #depth_const
            #func_info
            /// Which parameters are `&mut` (bit `k`: parameter `k`), which callers' checks
            /// compare with their `&mut` arguments.
            #[doc(hidden)]
            #vis const __WP_MUT_PARAMS: u64 = #mut_params;
            /// The checks of this func's calls of funcs (read at module level, so that rustc
            /// evaluates them).
            #[doc(hidden)]
            #vis const __WP_CALLS: () = { #call_checks };
            /// The local arrays' size checks (read at module level, so that rustc evaluates them).
            #[doc(hidden)]
            #vis const __WP_LOCAL_ARRAYS: () = #array_checks;

            #[doc(hidden)]
            #[inline(always)]
            #[allow(unused_variables, unused_mut, unused_assignments, unused_parens, non_snake_case, unreachable_code, clippy::all)]
            #vis fn #cpu(#(#params),*) -> #wp::KResult<#ret> {
                use #wp as __wp;
                #body
                #tail
            }

            /// Why backward cannot go through this func (`None`: it can).
            #[doc(hidden)]
            #vis const __WP_ADJOINT_ERROR: ::core::option::Option<&'static str> = #adj_error;

            #[doc(hidden)]
            #[inline(always)]
            #[allow(unused_variables, unused_mut, unused_assignments, unused_parens, non_snake_case, unreachable_code, clippy::all)]
            #vis fn __wp_replay(#(#replay_params),*) -> #wp::KResult<#ret> {
                #replay_fn_body
            }

            #[doc(hidden)]
            #[inline(always)]
            #[allow(unused_variables, unused_mut, unused_assignments, unused_parens, non_snake_case, unreachable_code, clippy::all)]
            #vis fn __wp_adj(
                #(#replay_params,)*
                #(#adj_params,)*
                __adj_ret: #ret,
                __stack: &mut #wp::AdStack,
            ) -> #wp::KResult<()> {
                use #wp as __wp;
                const __FAST: bool = false;
                #adj_body
                ::core::result::Result::Ok(())
            }
    };
    Ok((items, companion, ret))
}

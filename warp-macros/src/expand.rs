//! Expansion of the three macros: front end, then back ends, then the items around them.

use crate::back::rust::RustEmitter;
use crate::front::{attrs, generics, lower};
use crate::ir::FnKind;
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote, quote_spanned, ToTokens};
use syn::spanned::Spanned;

mod checks;
mod derive;
mod grad_of;
mod tiled;

use checks::{call_checks, local_array_checks};
pub use derive::derive_struct;

fn errors_to_tokens(errors: Vec<syn::Error>) -> TokenStream {
    errors.into_iter().map(|e| e.to_compile_error()).collect()
}

/// `#[kernel]`.
pub fn kernel(attr: TokenStream, item: TokenStream) -> TokenStream {
    let wp = crate::paths::private();
    let item: syn::ItemFn = match syn::parse2(item) {
        Ok(i) => i,
        Err(e) => return e.to_compile_error(),
    };
    let mut errors = Vec::new();
    let opts = attrs::parse_kernel_attrs(attr).unwrap_or_else(|e| {
        errors.push(e);
        Default::default()
    });
    let vis = &item.vis;
    let name = &item.sig.ident;
    let doc_attrs: Vec<&syn::Attribute> = item
        .attrs
        .iter()
        .filter(|a| a.path().is_ident("doc"))
        .collect();
    // Keep a unit struct when there are errors, so that uses of the kernel do not add errors
    // of their own.
    let failed = |errors: Vec<syn::Error>| {
        let errs = errors_to_tokens(errors);
        quote!(#errs #[allow(non_camel_case_types)] #vis struct #name;)
    };
    let generics = match generics::parse(&item, &opts.instances) {
        Ok(g) => g,
        Err(e) => {
            errors.extend(e);
            return failed(errors);
        }
    };
    let Some(g) = generics else {
        if !errors.is_empty() {
            // Still lower, to report the body's errors with the attribute's.
            if let Err(e) = lower::lower_fn(&item, FnKind::Kernel) {
                errors.extend(e);
            }
            return failed(errors);
        }
        return match kernel_instance(&item, &opts, name, None) {
            Ok((_, body)) => {
                let out = quote! {
                    #(#doc_attrs)*
                    #[allow(non_camel_case_types)]
                    #[derive(Clone, Copy, Debug, Default)]
                    #vis struct #name;
                    #body
                };
                dump(&name.to_string(), &out);
                out
            }
            Err(e) => failed(e),
        };
    };
    // A generic kernel: one hidden kernel struct per instance, and the named struct picks one
    // from the launch arguments' types (`Launchable`).
    errors.extend(generics::check_params_select(&item, &g));
    let instances = generics::instances(&item, &g);
    let mut bodies = TokenStream::new();
    let mut inst_idents = Vec::new();
    let mut inst_args = Vec::new();
    let mut per_instance = Vec::new();
    for inst in &instances {
        let ident = format_ident!("__wp_kernel_{}_{}", name, inst.ident_suffix());
        let display = inst.display_name(&name.to_string());
        match kernel_instance(&inst.item, &opts, &ident, Some(display.clone())) {
            Ok((args, body)) => {
                inst_args.push(args);
                bodies.extend(quote! {
                    #[doc(hidden)]
                    #[allow(non_camel_case_types)]
                    #[derive(Clone, Copy, Debug, Default)]
                    #vis struct #ident;
                    #body
                });
                per_instance.push((display, Vec::new()));
            }
            Err(e) => per_instance.push((display, e)),
        }
        inst_idents.push(ident);
    }
    errors.extend(instance_errors(per_instance));
    if !errors.is_empty() {
        return failed(errors);
    }
    let bound_check = generics::bound_check(&g);
    let out = quote! {
        #(#doc_attrs)*
        ///
        /// A generic kernel: [`launch`](::warp_lang::launch) picks its instance from the types
        /// of the launch arguments.
        #[allow(non_camel_case_types)]
        #[derive(Clone, Copy, Debug, Default)]
        #vis struct #name;
        #bound_check
        #bodies
        const _: () = {
            #( impl<'__a> #wp::Launchable<#inst_args> for #name {
                type Kernel = #inst_idents;
            } )*
            impl #wp::GenericKernel for #name {
                fn instances() -> ::std::vec::Vec<&'static #wp::KernelInfo> {
                    ::std::vec![ #( <#inst_idents as #wp::Kernel>::info() ),* ]
                }
            }
        };
    };
    dump(&name.to_string(), &out);
    out
}

/// The errors of a generic function's instances: an error every instance has is reported
/// once as it is; one that only some instances have names them (`in `k<f64>`: ..`), since it
/// comes from what a type parameter became.
fn instance_errors(per_instance: Vec<(String, Vec<syn::Error>)>) -> Vec<syn::Error> {
    let key = |e: &syn::Error| {
        let start = e.span().start();
        (e.to_string(), start.line, start.column)
    };
    let n = per_instance.len();
    let mut out: Vec<syn::Error> = Vec::new();
    let mut done = Vec::new();
    for (_, errs) in &per_instance {
        for e in errs {
            let k = key(e);
            if done.contains(&k) {
                continue;
            }
            let holders: Vec<&str> = per_instance
                .iter()
                .filter(|(_, es)| es.iter().any(|x| key(x) == k))
                .map(|(d, _)| d.as_str())
                .collect();
            if holders.len() == n {
                out.push(e.clone());
            } else {
                out.push(syn::Error::new(
                    e.span(),
                    format!("in `{}`: {e}", holders.join("`, `")),
                ));
            }
            done.push(k);
        }
    }
    out
}

/// The `Kernel` impl (and its checks) of one kernel or one instance of a generic kernel, for
/// the unit struct `ident`; `display` names a generic instance in messages (`integrate<f32>`).
fn kernel_instance(
    item: &syn::ItemFn,
    opts: &attrs::KernelAttrs,
    ident: &syn::Ident,
    display: Option<String>,
) -> Result<(TokenStream, TokenStream), Vec<syn::Error>> {
    let mut f = lower::lower_kernel(item, FnKind::Kernel, opts.block_dim.clone())?;
    if let Some(d) = display {
        f.name = d;
    }
    let valid = crate::valid::validate(
        &f,
        crate::valid::Options::Kernel {
            same_shape: &opts.same_shape,
        },
    )?;
    if let Some(explicit) = opts.deterministic {
        if f.tiled.is_some() {
            return Err(vec![syn::Error::new_spanned(
                &item.sig.ident,
                "a deterministic kernel cannot use tiles yet (its lanes' accumulations are not \
                 recorded)",
            )]);
        }
        f.deterministic = Some(crate::valid::deterministic::check(&f, explicit)?);
    }
    let groups = valid.same_shape;

    let paren = item.sig.paren_token.span.join();
    let (launch_args, primal) = kernel_impl(
        &f,
        ident,
        &groups,
        &valid.requires,
        opts.disable_backward,
        paren,
        false,
    );
    let forward = forward_impl(&f, ident, &item.vis, &groups, opts.disable_backward, paren);
    Ok((launch_args, quote!(#primal #forward)))
}

/// The `Kernel` impl of the lowered kernel `f` for the unit struct `ident` (the launch
/// arguments' type, and the impl): `groups` are its `same_shape` groups as parameter indices,
/// `requires` the target capabilities its code needs (both from the validator).
/// A `hidden` kernel (a tangent kernel) is left out of rustc's suggestions of kernels.
fn kernel_impl(
    f: &crate::ir::Function,
    ident: &syn::Ident,
    groups: &[Vec<usize>],
    requires: &[crate::valid::Capability],
    disable_backward: bool,
    paren: proc_macro2::Span,
    hidden: bool,
) -> (TokenStream, TokenStream) {
    let wp = crate::paths::private();
    let hide = hidden.then(|| quote!(#[diagnostic::do_not_recommend]));
    let em = RustEmitter::new(f);
    let name = ident;
    let name_str = Literal::string(&f.name);
    let tys: Vec<&syn::Type> = f.params.iter().map(|p| &p.syn_ty).collect();
    let pnames: Vec<Literal> = f.params.iter().map(|p| Literal::string(&p.name)).collect();
    let pvars: Vec<TokenStream> = f
        .params
        .iter()
        .map(|p| {
            let v = em.var(p.var);
            if f.vars[p.var].mutable {
                quote!(mut #v)
            } else {
                quote!(#v)
            }
        })
        .collect();
    let pnames_plain: Vec<syn::Ident> = f.params.iter().map(|p| em.var(p.var)).collect();
    let fast_params = crate::analysis::tid_accessed_params(f, &em.tid);
    let fast_arrays: Vec<syn::Ident> = fast_params.iter().map(|v| em.var(*v)).collect();
    let tid_indexed: Vec<usize> = fast_params
        .iter()
        .map(|v| f.params.iter().position(|p| p.var == *v).expect("a param"))
        .collect();
    let tid = match f.tid_ndim {
        Some(n) => {
            let n = n as usize;
            quote!(::core::option::Option::Some(#n))
        }
        None => quote!(::core::option::Option::None),
    };
    let tid_setup = f.tid_ndim.map(|n| {
        let n = n as usize;
        quote!(let __tid: [usize; #n] = __grid.unflatten::<#n>(__flat);)
    });
    let groups = groups.iter().map(|g| quote!(&[#(#g),*]));
    let written = crate::analysis::written_params(f);
    // A tiled kernel's body is printed by its block printer (`tiled::run_cpu`).
    let body = if f.tiled.is_none() {
        em.block(&f.body)
    } else {
        TokenStream::new()
    };
    // The lane plan of a tiled kernel, made once for its `TileInfo` and its CPU entry.
    let block = f
        .tiled
        .as_ref()
        .map(|_| crate::back::rust_tile::BlockPrinter::new(f));
    let tile_info = tiled::info(f, block.as_ref());
    let shape_checks = tiled::shape_checks(f);
    // A tangent kernel's arrays are the primal's and their tangents (the same types): the
    // primal's checks are enough, and one error each.
    let array_checks = match hidden {
        false => local_array_checks(f, &wp),
        true => quote!({}),
    };
    let callee_checks = callee_depths(&f.callees);
    let call_checks = call_checks(f);
    let (cuda_src, cuda_sections, _) = cuda_template(f);
    let callees = &f.callees;
    let consts = const_literals(f);
    let requires = requires.iter().map(|c| c.tokens());
    let asserts = assert_sites(f, &quote!(__wp));
    let struct_tys = struct_types(f);
    let deterministic = match f.deterministic {
        Some(n) => {
            let adjoint = crate::valid::deterministic::adjoint_limit(f, n);
            let lanes = crate::valid::deterministic::recorded_arrays(f)
                .into_iter()
                .filter_map(|a| element_lanes(f, a));
            quote!(::core::option::Option::Some(__wp::DeterministicInfo {
                max_records: #n,
                adjoint_records: #adjoint,
                lanes: __wp::DeterministicInfo::widest(&[#(#lanes),*]),
            }))
        }
        None => quote!(::core::option::Option::None),
    };
    // The CPU adjoint: generated unless the kernel opted out; a construct the reverse sweep
    // does not handle yet becomes an error that backward reports.
    let adjoint = if disable_backward {
        Err("was declared with #[kernel(enable_backward = false)]".to_string())
    } else {
        crate::back::rust_adjoint::emit(f)
    };
    let (adjoint_body, adjoint_error) = match adjoint {
        Ok(body) => (body, quote!(::core::option::Option::None)),
        Err(why) => {
            let why = Literal::string(&why);
            (quote!(), quote!(::core::option::Option::Some(#why)))
        }
    };
    let (cuda_adjoint, cuda_adjoint_stack, cuda_adjoint_error) =
        match crate::back::cuda_adjoint::emit(f, "@@FILE@@") {
            Ok(a) => (
                Literal::string(&a.source),
                a.uses_stack,
                quote!(::core::option::Option::None),
            ),
            Err(why) => {
                let why = Literal::string(&format!("cannot run backward on CUDA yet: {why}"));
                (
                    Literal::string(""),
                    false,
                    quote!(::core::option::Option::Some(#why)),
                )
            }
        };
    let grad_pats: Vec<TokenStream> = f
        .params
        .iter()
        .map(|p| {
            if matches!(p.ty, crate::types::Ty::Array(..)) {
                let v = em.var(p.var);
                let a = quote::format_ident!("adj_{}", v);
                quote!(#a)
            } else {
                quote!(_)
            }
        })
        .collect();
    // The parameter list, spanned at the signature's parentheses: a list the runtime has no
    // `KernelParams` for (more than `MAX_PARAMS` parameters) is reported there.
    let params = quote_spanned! {paren=>
        type Params = ( #(#tys,)* );
    };
    let grad_names: Vec<syn::Ident> = (0..f.params.len())
        .map(|k| quote::format_ident!("__grad{}", k))
        .collect();

    let run_cpu = match &block {
        Some(block) => tiled::run_cpu(f, block, &pvars, &pnames_plain, &tys, tid_setup.as_ref()),
        None => quote! {
                    fn run_cpu(
                        __params: &__wp::CpuParamsOf<Self>,
                        __grid: &__wp::Grid,
                        __range: ::core::ops::Range<usize>,
                    ) -> __wp::KResult<()> {
                        // One thread. Its parameters arrive by value, so that they live in registers:
                        // read through `__params`, every array access would have to reload the views,
                        // since a store through a raw pointer might alias them.
                        #[inline(always)]
                        #[allow(unused_variables, unused_mut, unused_assignments, unused_parens, non_snake_case, unreachable_code, clippy::all)]
                        fn __thread<const __FAST: bool>(
                            #( #pvars: <#tys as __wp::KernelArg>::CpuView, )*
                            __grid: &__wp::Grid,
                            __flat: usize,
                        ) -> __wp::KResult<()> {
                            #tid_setup
                            #body
                            ::core::result::Result::Ok(())
                        }
                        let ( #(#pnames_plain,)* ) = *__params;
                        let __grid = *__grid;
                        // Arrays indexed by the thread index: if they cover the grid, those accesses
                        // are in bounds for every thread and the per-thread checks can go.
                        if true #( && #fast_arrays.covers(&__grid.dims) )* {
                            for __flat in __range {
                                __thread::<true>( #(#pnames_plain,)* &__grid, __flat)?;
                            }
                        } else {
                            for __flat in __range {
                                __thread::<false>( #(#pnames_plain,)* &__grid, __flat)?;
                            }
                        }
                        ::core::result::Result::Ok(())
                    }
        },
    };
    // The launch arguments' type spelt out (what `KernelParams::Args` normalises to): a generic
    // kernel's `Launchable` impls are told apart by these, and coherence does not normalise.
    let launch_args = f.params.iter().map(|p| {
        let t = &p.syn_ty;
        // Arrays and host objects are passed by reference (`KernelArg::Arg<'a> = &'a T`).
        if matches!(
            p.ty,
            crate::types::Ty::Array(..) | crate::types::Ty::Object(_)
        ) {
            quote!(&'__a #t)
        } else {
            quote!(#t)
        }
    });
    let launch_args = quote!(( #(#launch_args,)* ));
    (
        launch_args,
        quote! {
            const _: () = {
                use #wp as __wp;
                #callee_checks
                #shape_checks
                #call_checks
                const _: () = #array_checks;
                #hide
                impl __wp::Kernel for #name {
                    #params
                    const INFO: __wp::KernelInfo = __wp::KernelInfo {
                        name: #name_str,
                        module: ::core::module_path!(),
                        params: &[#(#pnames),*],
                        tid_ndim: #tid,
                        same_shape: &[#(#groups),*],
                        written: &[#(#written),*],
                        tid_indexed: &[#(#tid_indexed),*],
                        file: ::core::file!(),
                        cuda: #cuda_src,
                        cuda_sections: &[#(#cuda_sections),*],
                        callees: &[#(&#callees::__WP_FUNC),*],
                        structs: &[#(<#struct_tys as __wp::CudaStruct>::cuda_defs),*],
                        adjoint_error: __wp::first_error(&[#adjoint_error #(, #callees::__WP_ADJOINT_ERROR)*]),
                        cuda_adjoint: #cuda_adjoint,
                        cuda_adjoint_stack: #cuda_adjoint_stack,
                        cuda_adjoint_error: __wp::first_error(&[#cuda_adjoint_error #(, #callees::__WP_FUNC.cuda_adj_error)*]),
                        consts: #consts,
                        requires: &[#(#requires),*],
                        asserts: #asserts,
                        tile: #tile_info,
                        deterministic: #deterministic,
                    };
                    fn info() -> &'static __wp::KernelInfo {
                        &<Self as __wp::Kernel>::INFO
                    }
                    fn run_cpu_adjoint(
                        __params: &__wp::CpuParamsOf<Self>,
                        __grads: &__wp::CpuGradsOf<Self>,
                        __grid: &__wp::Grid,
                        __range: ::core::ops::Range<usize>,
                        __stack: &mut __wp::AdStack,
                        __shared_grads: bool,
                    ) -> __wp::KResult<()> {
                        #[inline(always)]
                        #[allow(unused_variables, unused_mut, unused_assignments, unused_parens, non_snake_case, unreachable_code, clippy::all)]
                        fn __adj_thread<const __FAST: bool>(
                            #( mut #pnames_plain: <#tys as __wp::KernelArg>::CpuView, )*
                            #( #grad_pats: <#tys as __wp::KernelArg>::GradView, )*
                            __grid: &__wp::Grid,
                            __flat: usize,
                            __stack: &mut __wp::AdStack,
                        ) -> __wp::KResult<()> {
                            #tid_setup
                            #adjoint_body
                            ::core::result::Result::Ok(())
                        }
                        let ( #(#pnames_plain,)* ) = *__params;
                        let ( #(#grad_names,)* ) = *__grads;
                        let __grid = *__grid;
                        // As in `run_cpu`: thread-index accesses skip their checks when the arrays
                        // cover the grid, and their gradients skip atomics, unless another adjoint
                        // launch may share them (warp-runtime's cpu/shared_grads.rs).
                        if !__shared_grads #( && #fast_arrays.covers(&__grid.dims) )* {
                            for __flat in __range {
                                __stack.clear();
                                __adj_thread::<true>( #(#pnames_plain,)* #(#grad_names,)* &__grid, __flat, __stack)?;
                            }
                        } else {
                            for __flat in __range {
                                __stack.clear();
                                __adj_thread::<false>( #(#pnames_plain,)* #(#grad_names,)* &__grid, __flat, __stack)?;
                            }
                        }
                        ::core::result::Result::Ok(())
                    }
                    #run_cpu
                }
            };
        },
    )
}

/// The kernel's `Forward` impl: its tangent kernel (`middle::tangent`), emitted as a hidden
/// kernel of its own (forward code, adjoint, CUDA templates: the reverse-over-forward of
/// `wp::hvp` is that kernel's backward), or why there is none, which `wp::jvp` reports.
fn forward_impl(
    f: &crate::ir::Function,
    ident: &syn::Ident,
    vis: &syn::Visibility,
    groups: &[Vec<usize>],
    disable_backward: bool,
    paren: proc_macro2::Span,
) -> TokenStream {
    let wp = crate::paths::private();
    let idx: Vec<syn::Index> = (0..f.params.len()).map(syn::Index::from).collect();
    let tangent =
        if cfg!(feature = "forward-mode") {
            crate::middle::tangent::build(f)
        } else {
            Err("was compiled without forward mode (enable the `forward-mode` feature of warp-lang)"
            .to_string())
        };
    match tangent {
        Ok(g) => {
            let t = format_ident!("__wp_jvp_{}", ident);
            let requires = crate::valid::required_capabilities(&g);
            let (_, tangent) =
                kernel_impl(&g, &t, groups, &requires, disable_backward, paren, true);
            quote! {
                const _: () = {
                    #[doc(hidden)]
                    #[allow(non_camel_case_types)]
                    #[derive(Clone, Copy, Debug, Default)]
                    #vis struct #t;
                    #tangent
                    impl #wp::Forward for #ident {
                        type Tangent = #t;
                        const TANGENT_ERROR: ::core::option::Option<&'static str> =
                            ::core::option::Option::None;
                        #[allow(unused_variables, clippy::unused_unit)]
                        fn join<'__a>(
                            args: #wp::ArgsOf<'__a, Self>,
                            tangents: #wp::ArgsOf<'__a, Self>,
                        ) -> #wp::ArgsOf<'__a, #t> {
                            ( #(args.#idx,)* #(tangents.#idx,)* )
                        }
                    }
                };
            }
        }
        Err(why) => {
            let why = Literal::string(&why);
            quote! {
                impl #wp::Forward for #ident {
                    type Tangent = Self;
                    const TANGENT_ERROR: ::core::option::Option<&'static str> =
                        ::core::option::Option::Some(#why);
                    fn join<'__a>(
                        args: #wp::ArgsOf<'__a, Self>,
                        _tangents: #wp::ArgsOf<'__a, Self>,
                    ) -> #wp::ArgsOf<'__a, Self> {
                        args
                    }
                }
            }
        }
    }
}

/// With `WARP_LANG_DUMP=1` (or the kernel's name) in the environment at build time, prints the
/// generated code of kernels and funcs to stderr: a debugging aid for the language and for users.
fn dump(name: &str, tokens: &TokenStream) {
    if let Ok(v) = std::env::var("WARP_LANG_DUMP") {
        if v == "1" || v == name {
            eprintln!("// ---- warp-lang expansion of `{name}`\n{tokens}");
        }
    }
}

/// The CUDA template of a function, and its library sections. A function the CUDA emitter
/// cannot express yet still compiles for the CPU; its template is an `#error` that NVRTC
/// reports at the first CUDA launch.
fn cuda_template(f: &crate::ir::Function) -> (Literal, Vec<Literal>, Literal) {
    match crate::back::cuda::emit(f, "@@FILE@@") {
        Ok(t) => (
            Literal::string(&t.source),
            t.sections.iter().map(|s| Literal::string(s)).collect(),
            Literal::string(&t.ret),
        ),
        Err(e) => (
            Literal::string(&format!(
                "#error \"`{}` cannot run on CUDA yet: {e}\"\n",
                f.name
            )),
            vec![],
            Literal::string("void"),
        ),
    }
}

/// The function's assertion sites (`KernelInfo::asserts`, `FuncInfo::asserts`): the line and
/// column its CUDA code records on a failure, with the message the host reports.
fn assert_sites(f: &crate::ir::Function, wp: &TokenStream) -> TokenStream {
    let mut sites = Vec::new();
    crate::ir::walk_stmts(&f.body, &mut |s| {
        if let crate::ir::StmtKind::Assert { message, .. } = &s.kind {
            let (line, column) = (s.span.start().line as u32, s.span.start().column as u32);
            let message = Literal::string(message);
            sites.push(quote!(#wp::AssertSite { line: #line, column: #column, message: #message }));
        }
    });
    quote!(&[#(#sites),*])
}

/// The values of the module-level consts a function reads, as C++ expressions for its
/// `@@K<k>@@` placeholders: one small fn per const, spanned at the use, so that a const of a
/// type without `CudaConst` is an error there.
fn const_literals(f: &crate::ir::Function) -> TokenStream {
    let fns = f.consts.iter().map(|p| {
        let wp = crate::paths::private_at(p.span());
        quote_spanned! {p.span()=>
            {
                fn __wp_const() -> ::std::string::String {
                    #wp::CudaConst::cuda_literal(&#p)
                }
                __wp_const as #wp::ConstLiteral
            }
        }
    });
    quote!(&[#(#fns),*])
}

/// The user struct types a function names, as written: its parameters' (`S` and
/// `Array<S, N>`), its result's and its struct literals' (`S { .. }`), whose C++ definitions
/// its translation unit needs.
fn struct_types(f: &crate::ir::Function) -> Vec<syn::Type> {
    use crate::ir::{Ctor, Op, StmtKind};
    use crate::types::Ty;
    let mut out = Vec::new();
    for p in &f.params {
        let ty = match &p.ty {
            Ty::Struct(_) => Some(p.syn_ty.clone()),
            Ty::Array(e, _) if matches!(**e, Ty::Struct(_)) => array_elem(&p.syn_ty),
            _ => None,
        };
        if let Some(t) = ty {
            out.push(t);
        }
    }
    if let (Ty::Struct(_), Some(t)) = (&f.ret, &f.ret_syn) {
        out.push(t.clone());
    }
    crate::ir::walk_stmts(&f.body, &mut |s| {
        if let StmtKind::Assign {
            op:
                Op::Construct {
                    ctor: Ctor::Fields { path, .. },
                    ..
                },
            ..
        } = &s.kind
        {
            let t = syn::Type::Path(syn::TypePath {
                qself: None,
                path: path.clone(),
            });
            if !out.contains(&t) {
                out.push(t);
            }
        }
    });
    out
}

/// `T` of `Array<T, N>`.
/// The float lanes of array parameter `array`'s element (a `usize` expression): one record
/// each in a deterministic kernel's GPU slots. The macro counts those of the types it knows;
/// a struct's are bounded by its size over 2 (the narrowest lane, f16, is 2 bytes).
fn element_lanes(f: &crate::ir::Function, array: crate::ir::VarId) -> Option<TokenStream> {
    use crate::types::Ty;
    let Ty::Array(e, _) = f.ty(array) else {
        return None;
    };
    let n: usize = match &**e {
        Ty::Scalar(_) => 1,
        Ty::Vector(_, n) => *n as usize,
        Ty::Matrix(_, n) => (*n as usize) * (*n as usize),
        Ty::Quat(_) => 4,
        Ty::Transform(_) => 7,
        Ty::SpatialVector(_) => 6,
        Ty::SpatialMatrix(_) => 36,
        _ => {
            let p = f.params.iter().find(|p| p.var == array)?;
            let t = array_elem(&p.syn_ty)?;
            return Some(quote!((::core::mem::size_of::<#t>() / 2)));
        }
    };
    Some(quote!(#n))
}

fn array_elem(t: &syn::Type) -> Option<syn::Type> {
    let syn::Type::Path(tp) = t else { return None };
    let syn::PathArguments::AngleBracketed(a) = &tp.path.segments.last()?.arguments else {
        return None;
    };
    match a.args.first()? {
        syn::GenericArgument::Type(t) => Some(t.clone()),
        _ => None,
    }
}

/// Forces the recursion-depth constants of called funcs to be evaluated: a cycle of funcs
/// calling each other is then a compile-time error (a cycle in const evaluation).
fn callee_depths(callees: &[syn::Path]) -> TokenStream {
    let checks = callees.iter().map(
        |p| quote_spanned!(p.span()=> let _ = #p::__WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED;),
    );
    quote!(const _: () = { #(#checks)* };)
}

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
        return match func_instance(&item, &fattrs, None, quote!(#name)) {
            Ok((items, companion)) => quote! {
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

                const _: usize = #name::__WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED;
                const _: () = #name::__WP_LOCAL_ARRAYS;
                const _: () = #name::__WP_CALLS;
                #tile_map_impl
            },
            Err(e) => failed(e),
        };
    };
    // A generic func: `f<T>` is a type with one inherent impl per instance, so that a caller
    // names the instance as `f::<T>(..)` (in a generic kernel, `T` is concrete by then).
    if !fattrs.grad.is_empty() {
        errors.push(syn::Error::new(
            item.sig.generics.span(),
            "custom gradients (`#[func(grad(..))]`) are not supported on generic funcs yet",
        ));
    }
    // (No `check_params_select` here: callers name a func's instance, `f::<f32>(..)`.)
    let grad_name = format_ident!(
        "{}",
        lower::calls::companion_of(&name.to_string()),
        span = name.span()
    );
    let mut impls = TokenStream::new();
    let mut per_instance = Vec::new();
    for inst in generics::instances(&item, &g) {
        let display = inst.display_name(&name.to_string());
        let tys = &inst.types;
        match func_instance(
            &inst.item,
            &fattrs,
            Some(display.clone()),
            quote!(#name<#(#tys),*>),
        ) {
            Ok((items, companion)) => {
                impls.extend(quote! {
                    impl #name<#(#tys),*> {
                        #items
                    }
                    impl #grad_name<#(#tys),*> {
                        #companion
                    }
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
        /// A generic `#[func]`: callable from kernels and other funcs as `name::<f32>(..)` or,
        /// in a generic kernel, `name::<T>(..)`.
        #[allow(non_camel_case_types)]
        #vis struct #name<#(#params),*> {
            _instance: ::core::marker::PhantomData<(#(#params,)*)>,
        }
        /// `wp::grad(f::<T>)` of this func's instances.
        #[doc(hidden)]
        #[allow(non_camel_case_types)]
        #vis struct #grad_name<#(#params),*> {
            _instance: ::core::marker::PhantomData<(#(#params,)*)>,
        }
        #bound_check
        #impls
    }
}

/// `#[func(overload)]`: one overload of the set `wp::overloads!(name)` declares (the generic
/// struct `name<K>`), for each of its instances (one for a plain func) an inherent impl of
/// `name<K>`, `K` the instance's first parameter's type (a `&mut` parameter's referent):
/// callers name the overload as `name::<K>(..)`, and in a generic kernel `name::<T>(..)` picks
/// each instance's own overload. Emits no item of the func's own name, so several overloads
/// may share it (`fn combine(a: i32, ..)`, `fn combine<V: Vector>(a: V, ..)`). Two overloads
/// for one `K` are two inherent items of one name, rustc's error, spanned at the second's
/// first parameter type; one func's instances with one `K` are refused here.
fn overload_member(
    item: &syn::ItemFn,
    fattrs: &attrs::FuncAttrs,
    g: Option<&generics::Generics>,
    mut errors: Vec<syn::Error>,
) -> TokenStream {
    let name = &item.sig.ident;
    let attr = fattrs.overload.as_ref().expect("an overload");
    if !fattrs.grad.is_empty() {
        errors.push(syn::Error::new(
            attr.span(),
            "custom gradients (`#[func(grad(..))]`) are not supported on overloads yet",
        ));
    }
    let first_ty = |f: &syn::ItemFn| -> Option<syn::Type> {
        match f.sig.inputs.first()? {
            syn::FnArg::Typed(pt) => Some(match &*pt.ty {
                syn::Type::Reference(r) => (*r.elem).clone(),
                t => t.clone(),
            }),
            syn::FnArg::Receiver(_) => None,
        }
    };
    let instances: Vec<syn::ItemFn> = match g {
        Some(g) => generics::instances(item, g)
            .into_iter()
            .map(|i| i.item)
            .collect(),
        None => vec![item.clone()],
    };
    let mut keys: Vec<syn::Type> = Vec::new();
    for inst in &instances {
        let Some(k) = first_ty(inst) else {
            errors.push(syn::Error::new(
                item.sig.paren_token.span.join(),
                "an overload is selected by its first parameter's type (`name::<i32>(..)`): it needs a parameter",
            ));
            return errors_to_tokens(errors);
        };
        let text = k.to_token_stream().to_string();
        if keys.iter().any(|o| o.to_token_stream().to_string() == text) {
            errors.push(syn::Error::new(
                k.span(),
                format!(
                    "two instances of this overload take a first parameter of type `{}`: overloads are told apart by their first parameter's type, so a type parameter must appear in it",
                    text.replace(' ', "")
                ),
            ));
            return errors_to_tokens(errors);
        }
        keys.push(k);
    }
    if !errors.is_empty() {
        return errors_to_tokens(errors);
    }
    let mut impls = TokenStream::new();
    let mut per_instance = Vec::new();
    for (inst, key) in instances.iter().zip(&keys) {
        let display = format!(
            "{name}<{}>",
            key.to_token_stream().to_string().replace(' ', "")
        );
        let ksp = key.span();
        let self_ty = quote_spanned!(ksp=> #name<#key>);
        // (`wp::grad` of an overload: not yet; `wp::overloads!` declares no companion.)
        match func_instance(inst, fattrs, Some(display.clone()), self_ty.clone()) {
            Ok((items, _)) => {
                impls.extend(quote_spanned! {ksp=>
                    impl #self_ty {
                        #items
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
) -> Result<(TokenStream, TokenStream), Vec<syn::Error>> {
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
            .map(|r| crate::back::cuda_adjoint::push_callee(&mut all_callees, r));
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
    Ok((items, companion))
}

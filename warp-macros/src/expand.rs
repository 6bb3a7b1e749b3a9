//! Expansion of the three macros: front end, then back ends, then the items around them.

use crate::back::rust::RustEmitter;
use crate::front::{attrs, generics, lower};
use crate::ir::FnKind;
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote, quote_spanned, ToTokens};
use syn::spanned::Spanned;

mod checks;
mod derive;
mod funcs;
mod grad_of;
mod overloads;
mod tiled;

use checks::{call_checks, local_array_checks};
pub use derive::derive_struct;
pub use funcs::func;
pub use overloads::overload_set;

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
        Ty::MatRC(_, r, c) => (*r as usize) * (*c as usize),
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

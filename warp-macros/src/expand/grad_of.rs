//! `wp::grad(f)`: the companion `#[func]` emits next to `f`, `__wp_grad_f`, which a kernel's
//! `wp::grad(f)(x, y)` calls as an ordinary func (`front::lower::calls` rewrites the call).
//!
//! The companion takes `f`'s parameters and returns their adjoints after `f`'s adjoint ran
//! with the result's adjoint one in every lane (Warp's `wp.grad`: for a scalar result, the
//! partial derivatives; one parameter gives its adjoint, several a tuple). Like Warp's, the
//! call is a constant to the caller's own backward pass: the companion's adjoint adds
//! nothing. Being a func to the rest of the macro, it needs no case in the IR, the emitters or
//! the adjoint transform; its CUDA code calls `f`'s adjoint, so its `FuncInfo` asks for the
//! adjoint headers and the funcs' adjoints in forward units too (`needs_adjoints`).
//!
//! A func `wp::grad` cannot take (an array or `&mut` parameter, a result that is not a float
//! value, no adjoint) still gets a companion, whose `__WP_GRAD_REFUSAL` says why: a call's
//! `const` check (`checks::call_checks`) fails with it at the call, at `cargo check`.

use crate::ir::Function;
use crate::types::Ty;
use proc_macro2::{Literal, TokenStream};
use quote::{format_ident, quote};

/// What the companion of one func (or one instance of a generic func) needs.
pub(super) struct Companion<'a> {
    pub f: &'a Function,
    /// The func's type, `f` or `f<f32>`.
    pub func_ty: TokenStream,
    pub vis: &'a syn::Visibility,
    /// The parameters' names and CPU types, as the func's replay declares them.
    pub params: Vec<(syn::Ident, TokenStream)>,
    /// The types of the func's adjoint's gradient parameters, one per parameter, as callers'
    /// adjoints pass them (an array's gradient view; `&mut` a value's adjoint).
    pub adj_tys: Vec<TokenStream>,
    /// Whether the func's CUDA adjoint may push on its stack.
    pub cuda_stack: bool,
}

/// Whether `wp::grad` can seed a result of type `t` (warp-core's `GradSeed`).
fn seedable(t: &Ty) -> bool {
    let float = |s: &crate::types::Scalar| s.is_float();
    match t {
        Ty::Scalar(s)
        | Ty::Vector(s, _)
        | Ty::Matrix(s, _)
        | Ty::Quat(s)
        | Ty::SpatialVector(s)
        | Ty::SpatialMatrix(s)
        | Ty::MatRC(s, ..) => float(s),
        Ty::Tuple(ts) => (2..=4).contains(&ts.len()) && ts.iter().all(seedable),
        _ => false,
    }
}

/// Why `wp::grad` cannot take `f`, or `None`.
pub(super) fn refusal(f: &Function) -> Option<String> {
    if let Some(p) = f.params.iter().find(|p| p.by_ref) {
        return Some(format!("its parameter `{}` is `&mut`", p.name));
    }
    if let Some(p) = f.params.iter().find(|p| matches!(p.ty, Ty::Array(..))) {
        return Some(format!("its parameter `{}` is an array", p.name));
    }
    if f.params.is_empty() {
        return Some("it takes no parameters".into());
    }
    if !seedable(&f.ret) {
        return Some(
            "its result is not a float scalar, vector, matrix, quaternion or spatial value (or a tuple of them)"
                .into(),
        );
    }
    None
}

/// The companion's inherent items (an `impl` of `__wp_grad_f` holds them).
pub(super) fn items(c: &Companion<'_>, wp: &TokenStream) -> TokenStream {
    let Companion {
        f,
        func_ty,
        vis,
        params,
        adj_tys,
        ..
    } = c;
    let name = Literal::string(&crate::front::lower::calls::companion_of(&f.name));
    let names: Vec<&syn::Ident> = params.iter().map(|p| &p.0).collect();
    let tys: Vec<&TokenStream> = params.iter().map(|p| &p.1).collect();
    let grads: Vec<syn::Ident> = (0..params.len()).map(|k| format_ident!("__g{k}")).collect();
    let out_tys = match tys.as_slice() {
        [t] => quote!(#t),
        ts => quote!((#(#ts),*)),
    };
    let protocol = quote! {
        /// Longest chain of funcs below this one.
        #[doc(hidden)]
        #vis const __WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED: usize =
            1 + <#func_ty>::__WP_CALL_DEPTH__RECURSION_IS_NOT_SUPPORTED;
        /// A constant to the caller's backward pass (as Warp's `wp.grad`).
        #[doc(hidden)]
        #vis const __WP_ADJOINT_ERROR: ::core::option::Option<&'static str> =
            ::core::option::Option::None;
    };
    if let Some(why) = refusal(f) {
        let msg = Literal::string(&format!("`wp::grad` cannot take `{}`: {why}", f.name));
        // Never called: every call's check of `__WP_GRAD_REFUSAL` fails at compile time
        // (`checks::call_checks`). The result type is the caller's, so that nothing else in
        // the kernel fails to type-check first.
        return quote! {
            #protocol
            #[doc(hidden)]
            #vis const __WP_MUT_PARAMS: u64 = 0;
            #[doc(hidden)]
            #vis const __WP_GRAD_REFUSAL: ::core::option::Option<&'static str> =
                ::core::option::Option::Some(#msg);
            #[doc(hidden)]
            #vis const __WP_FUNC: #wp::FuncInfo = <#func_ty>::__WP_FUNC;
            #[doc(hidden)]
            #[allow(unused_variables, clippy::all)]
            #vis fn __wp_cpu<__R>(#(#names: #tys),*) -> #wp::KResult<__R> {
                ::core::unreachable!("refused at compile time")
            }
            #[doc(hidden)]
            #[allow(unused_variables, clippy::all)]
            #vis fn __wp_replay<__R>(#(#names: #tys),*) -> #wp::KResult<__R> {
                ::core::unreachable!("refused at compile time")
            }
            #[doc(hidden)]
            #[allow(unused_variables, clippy::all)]
            #vis fn __wp_adj<__R>(
                #(#names: #tys,)*
                #(#grads: #adj_tys,)*
                __adj_ret: __R,
                __stack: &mut #wp::AdStack,
            ) -> #wp::KResult<()> {
                ::core::unreachable!("refused at compile time")
            }
        };
    }
    let ret = f.ret_syn.as_ref().expect("a seedable result");
    let result = match grads.as_slice() {
        [g] => quote!(#g),
        gs => quote!((#(#gs),*)),
    };
    let (cuda, cuda_adj, cuda_ret) = match cuda(c) {
        Some(t) => t,
        None => (
            format!(
                "#error \"`wp::grad({})` cannot run on CUDA: a parameter or its result has no CUDA type\"\n",
                f.name
            ),
            String::new(),
            "void".to_string(),
        ),
    };
    let (cuda, cuda_adj, cuda_ret) = (
        Literal::string(&cuda),
        Literal::string(&cuda_adj),
        Literal::string(&cuda_ret),
    );
    quote! {
        #protocol
        #[doc(hidden)]
        #vis const __WP_MUT_PARAMS: u64 = 0;
        /// `f`'s adjoint, which this runs, must exist (its own and its callees').
        #[doc(hidden)]
        #vis const __WP_GRAD_REFUSAL: ::core::option::Option<&'static str> =
            <#func_ty>::__WP_ADJOINT_ERROR;
        /// What the CUDA assembler needs to know about this func.
        #[doc(hidden)]
        #vis const __WP_FUNC: #wp::FuncInfo = #wp::FuncInfo {
            name: #name,
            module: ::core::module_path!(),
            file: ::core::file!(),
            cuda: #cuda,
            cuda_ret: #cuda_ret,
            sections: &[],
            callees: &[&<#func_ty>::__WP_FUNC],
            structs: &[],
            cuda_adj: #cuda_adj,
            cuda_adj_error: <#func_ty>::__WP_FUNC.cuda_adj_error,
            consts: &[],
            requires: &[],
            asserts: &[],
            float_atomics: false,
            needs_adjoints: true,
        };

        #[doc(hidden)]
        #[inline(always)]
        #[allow(unused_mut, clippy::all)]
        #vis fn __wp_cpu(#(#names: #tys),*) -> #wp::KResult<#out_tys> {
            #(let mut #grads: #tys = #wp::adjoint::zero();)*
            #wp::with_grad_stack(#name, #wp::adstack_bytes(), |__stack| {
                <#func_ty>::__wp_adj(
                    #(#names,)*
                    #(&mut #grads,)*
                    <#ret as #wp::GradSeed>::grad_seed(),
                    __stack,
                )
            })?;
            ::core::result::Result::Ok(#result)
        }

        #[doc(hidden)]
        #[inline(always)]
        #vis fn __wp_replay(#(#names: #tys),*) -> #wp::KResult<#out_tys> {
            Self::__wp_cpu(#(#names),*)
        }

        #[doc(hidden)]
        #[inline(always)]
        #[allow(unused_variables, clippy::all)]
        #vis fn __wp_adj(
            #(#names: #tys,)*
            #(#grads: #adj_tys,)*
            __adj_ret: #out_tys,
            __stack: &mut #wp::AdStack,
        ) -> #wp::KResult<()> {
            ::core::result::Result::Ok(())
        }
    }
}

/// The companion's CUDA forward function, its replay and (empty) adjoint, and its C++ result
/// type; `None` when a type has no CUDA spelling.
fn cuda(c: &Companion<'_>) -> Option<(String, String, String)> {
    use crate::back::cuda::cpp_type;
    let f = c.f;
    let tys: Vec<String> = f
        .params
        .iter()
        .map(|p| cpp_type(&p.ty))
        .collect::<Option<_>>()?;
    let ret = cpp_type(&f.ret)?;
    let n = tys.len();
    let out = match tys.as_slice() {
        [t] => t.clone(),
        ts => format!("wp::tuple_t<{}>", ts.join(", ")),
    };
    let decl: Vec<String> = tys
        .iter()
        .enumerate()
        .map(|(k, t)| format!("{t} x{k}"))
        .collect();
    let xs: Vec<String> = (0..n).map(|k| format!("x{k}")).collect();
    let gs: Vec<String> = (0..n).map(|k| format!("g{k}")).collect();
    let bytes = if c.cuda_stack {
        "WP_GRAD_STACK_BYTES"
    } else {
        "0"
    };
    let result = match gs.as_slice() {
        [g] => g.clone(),
        gs => format!("wp::make_tuple({})", gs.join(", ")),
    };
    let mut fwd = format!(
        "static WP_FN {out} @@SELF@@({}, wp::ctx_t* __ctx) {{\n",
        decl.join(", ")
    );
    for (t, g) in tys.iter().zip(&gs) {
        fwd.push_str(&format!("    {t} {g} = wp::adj_zero<{t}>();\n"));
    }
    fwd.push_str(&format!(
        "    {ret} seed;\n    wp::adj_one_into(seed);\n    \
         char buf[{bytes} > 0 ? {bytes} : 1];\n    \
         wp::adstack_t st = wp::adstack_new(buf, {bytes});\n    \
         @@F0@@_adj({}, {}, seed, __ctx, &st);\n    return {result};\n}}\n",
        xs.join(", "),
        gs.join(", ")
    ));
    let mut adj = format!(
        "static WP_FN {out} @@SELF@@_replay({}, wp::ctx_t* __ctx) {{\n    return @@SELF@@({}, __ctx);\n}}\n",
        decl.join(", "),
        xs.join(", ")
    );
    let mut adj_params = decl.clone();
    for (k, t) in tys.iter().enumerate() {
        adj.push_str(&format!("typedef {t} @@SELF@@_adj_arg{k};\n"));
        adj_params.push(format!("{t}& __adj_out{k}"));
    }
    adj_params.push(format!("{out} __adj_ret"));
    adj.push_str(&format!(
        "static WP_FN void @@SELF@@_adj({}, wp::ctx_t* __ctx, wp::adstack_t* __stack) {{}}\n",
        adj_params.join(", ")
    ));
    Some((fwd, adj, out))
}

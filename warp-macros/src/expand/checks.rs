//! The `const` assertions rustc evaluates for a kernel or func at `cargo check`: what only
//! rustc can decide, because the macro cannot see a const's value or a func's signature.

use proc_macro2::TokenStream;
use quote::{quote, quote_spanned};

/// The most bytes one local array may take: a thread's array (and, in the adjoint, its
/// gradient twin) lives on the CPU worker's stack and in a CUDA thread's local memory.
const LOCAL_ARRAY_MAX_BYTES: usize = 65536;

/// An assertion per local array type of the function (`[f32; N]`, nested ones included), to
/// be evaluated in a `const` initializer: at least one element and at most
/// [`LOCAL_ARRAY_MAX_BYTES`]. The macro refuses a literal length of 0 itself; a length that
/// names a const is only known to rustc, which evaluates these at `cargo check`, spanned at the
/// first statement that makes a local array (or the function, for an array that only its
/// signature names). A kernel puts them in a `const _`; a func, whose items sit in an `impl`,
/// in its `__WP_LOCAL_ARRAYS`, which a module-level `const _` reads.
pub(super) fn local_array_checks(f: &crate::ir::Function, wp: &TokenStream) -> TokenStream {
    use crate::types::Ty;
    let mut tys: Vec<Ty> = Vec::new();
    let mut note = |t: &Ty| {
        if matches!(t, Ty::LocalArray(..)) && !tys.contains(t) {
            tys.push(t.clone());
        }
    };
    f.vars.iter().for_each(|v| note(&v.ty));
    note(&f.ret);
    let mut span = None;
    crate::ir::walk_stmts(&f.body, &mut |s| {
        if let crate::ir::StmtKind::Assign { dst, .. } = &s.kind {
            if span.is_none() && matches!(f.vars[*dst].ty, Ty::LocalArray(..)) {
                span = Some(s.span);
            }
        }
    });
    let span = span.unwrap_or_else(proc_macro2::Span::call_site);
    let max = LOCAL_ARRAY_MAX_BYTES;
    let checks = tys
        .iter()
        .filter_map(|t| {
            let rust = crate::back::rust::ty_tokens(t)?;
            let msg = format!(
                "a local array `{t}` of {} holds at least one element and at most {max} bytes",
                f.name
            );
            Some(quote_spanned! {span=>
                {
                    use #wp as __wp;
                    let __bytes = ::core::mem::size_of::<#rust>();
                    ::core::assert!(__bytes > 0 && __bytes <= #max, #msg);
                }
            })
        })
        .collect::<Vec<_>>();
    quote!({ #(#checks;)* })
}

/// Each user func call's `&mut` arguments against the func's `&mut` parameters
/// (`ir::CallCheck`): `const` assertions spanned at the calls, which rustc evaluates at
/// `cargo check`. (A call that passes `a` for `acc: &mut f32` would otherwise compile: the
/// func's CPU code takes the value.)
pub(super) fn call_checks(f: &crate::ir::Function) -> TokenStream {
    f.call_checks
        .iter()
        .map(|c| {
            let (path, mask) = (&c.path, c.mut_args);
            let name = crate::front::lower::resolve::callee_name(&c.path);
            let passed: Vec<String> = (0..64)
                .filter(|k| mask >> k & 1 == 1)
                .map(|k| (k + 1).to_string())
                .collect();
            let passed = match passed.len() {
                0 => "none".to_string(),
                _ => format!("argument(s) {}", passed.join(", ")),
            };
            let msg = format!(
                "the `&mut` arguments of this call do not match the `&mut` parameters of `{name}` (this call passes {passed} as `&mut`)"
            );
            // `wp::grad(f)(..)` calls `f`'s companion (`grad_of`), which says why it cannot
            // take `f`, if it cannot.
            let grad = name.starts_with("__wp_grad_").then(|| {
                quote_spanned! {c.span=>
                    const _: () = if let ::core::option::Option::Some(why) = #path::__WP_GRAD_REFUSAL {
                        ::core::panic!("{}", why)
                    };
                }
            });
            // An argument type left to rustc (`_`): when several overloads fit, rustc's
            // ambiguity error here names them (the call's own paths only say `_`).
            let open = crate::front::lower::resolve::unresolved_parts(path).map(|(f, a)| {
                let wp = crate::paths::private_at(c.span);
                quote_spanned! {c.span=> const _: () = #wp::resolves::<#f, #a>(); }
            });
            quote_spanned! {c.span=>
                #open
                const _: () = ::core::assert!(#path::__WP_MUT_PARAMS == #mask, #msg);
                #grad
            }
        })
        .collect()
}

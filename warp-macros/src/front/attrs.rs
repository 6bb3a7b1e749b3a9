//! Arguments of `#[kernel(...)]` and `#[func(...)]`.

use syn::parse::Parser;

/// Options of `#[kernel]`.
#[derive(Default, Debug)]
pub struct KernelAttrs {
    /// `same_shape(a, b, dim)` groups: parameter names, `dim` for the launch dim.
    pub same_shape: Vec<Vec<syn::Ident>>,
    /// `enable_backward = false`: no adjoint is generated; backward through the kernel is an
    /// error.
    pub disable_backward: bool,
    /// `block_dim = N` (a literal or a module const): the kernel is tiled, and `tile(x)` makes
    /// tiles N wide; `launch_tiled` with another block size is an error.
    pub block_dim: Option<crate::types::Dim>,
    /// `deterministic` or `deterministic(max_records = N)`: float `atomic_add`/`atomic_sub`
    /// are recorded and reduced after the launch in a fixed order (`Some(None)`: the limit of
    /// records per thread is counted, or `DEFAULT_MAX_RECORDS` under a loop).
    pub deterministic: Option<Option<u32>>,
    /// `instances(T = [f32, Particle])`: the instance types of a generic kernel's parameters
    /// (see `front::generics`).
    pub instances: crate::front::generics::Lists,
}

/// Parses `#[kernel(same_shape(x, v, dim), ...)]`.
pub fn parse_kernel_attrs(tokens: proc_macro2::TokenStream) -> syn::Result<KernelAttrs> {
    let mut out = KernelAttrs::default();
    let parser = syn::meta::parser(|meta| {
        if meta.path.is_ident("same_shape") {
            let mut group = Vec::new();
            meta.parse_nested_meta(|inner| {
                group.push(inner.path.require_ident()?.clone());
                Ok(())
            })?;
            if group.len() < 2 {
                return Err(
                    meta.error("same_shape needs at least two names (parameters, or `dim`)")
                );
            }
            out.same_shape.push(group);
            Ok(())
        } else if meta.path.is_ident("enable_backward") {
            let v: syn::LitBool = meta.value()?.parse()?;
            out.disable_backward = !v.value;
            Ok(())
        } else if meta.path.is_ident("block_dim") {
            let e: syn::Expr = meta.value()?.parse()?;
            let dim = match &e {
                syn::Expr::Lit(syn::ExprLit {
                    lit: syn::Lit::Int(i),
                    ..
                }) => i
                    .base10_parse::<u32>()
                    .ok()
                    .filter(|n| (1..=1024).contains(n))
                    .map(crate::types::Dim::Lit),
                syn::Expr::Path(p) if p.qself.is_none() => {
                    crate::front::signature::dim_of_path(&p.path)
                }
                _ => None,
            };
            out.block_dim = Some(dim.ok_or_else(|| {
                syn::Error::new_spanned(
                    &e,
                    "block_dim is an integer literal in 1..=1024 or a module const",
                )
            })?);
            Ok(())
        } else if meta.path.is_ident("deterministic") {
            let mut max = None;
            if meta.input.peek(syn::token::Paren) {
                meta.parse_nested_meta(|inner| {
                    if !inner.path.is_ident("max_records") {
                        return Err(inner.error("deterministic takes `max_records = N`"));
                    }
                    let n: syn::LitInt = inner.value()?.parse()?;
                    let v = n
                        .base10_parse::<u32>()
                        .ok()
                        .filter(|v| *v >= 1)
                        .ok_or_else(|| {
                            syn::Error::new_spanned(
                                &n,
                                "max_records is an integer in 1..=4294967295",
                            )
                        })?;
                    max = Some(v);
                    Ok(())
                })?;
            }
            out.deterministic = Some(max);
            Ok(())
        } else if meta.path.is_ident("instances") {
            out.instances = crate::front::generics::parse_lists(meta)?;
            Ok(())
        } else {
            Err(meta.error(
                "unknown kernel option; supported: same_shape(a, b, ..), enable_backward = false, block_dim = N, deterministic, deterministic(max_records = N), instances(T = [..])",
            ))
        }
    });
    parser.parse2(tokens)?;
    Ok(out)
}

/// Options of `#[func]`.
#[derive(Default)]
pub struct FuncAttrs {
    /// `grad(x = fx, y = fy)`: custom gradients, one func per parameter. `fx` takes the func's
    /// parameters followed by the adjoint of its result and returns the adjoint of `x`.
    pub grad: Vec<(syn::Ident, syn::Path)>,
    /// `instances(T = [f32, Particle])`, as for kernels.
    pub instances: crate::front::generics::Lists,
    /// `overload`: the func is one overload of the set `wp::overloads!(name)` declares,
    /// selected by its first parameter's type (`name::<i32>(..)`).
    pub overload: Option<syn::Path>,
    /// `replay = r`: the func's replacement in the forward code an adjoint reruns (Warp's
    /// `@wp.func_replay`): a func of the same signature, called where this one's replay would
    /// run, typically returning what the forward pass saved instead of redoing an atomic.
    pub replay: Option<syn::Path>,
}

/// Parses `#[func(grad(x = dfdx, ..))]`.
pub fn parse_func_attrs(tokens: proc_macro2::TokenStream) -> syn::Result<FuncAttrs> {
    let mut out = FuncAttrs::default();
    let parser = syn::meta::parser(|meta| {
        if meta.path.is_ident("grad") {
            meta.parse_nested_meta(|inner| {
                let param = inner.path.require_ident()?.clone();
                let f: syn::Path = inner.value()?.parse()?;
                out.grad.push((param, f));
                Ok(())
            })
        } else if meta.path.is_ident("instances") {
            out.instances = crate::front::generics::parse_lists(meta)?;
            Ok(())
        } else if meta.path.is_ident("overload") {
            out.overload = Some(meta.path.clone());
            Ok(())
        } else if meta.path.is_ident("replay") {
            out.replay = Some(meta.value()?.parse()?);
            Ok(())
        } else {
            Err(meta.error(
                "unknown func option; supported: grad(param = gradient_func, ..), replay = replay_func, instances(T = [..]), overload",
            ))
        }
    });
    parser.parse2(tokens)?;
    Ok(out)
}

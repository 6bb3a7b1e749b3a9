//! Generic kernels and funcs: `fn integrate<T: Float>(x: Array<Vec3<T>>, dt: T)`.
//!
//! The language has no generic IR. A generic function is *monomorphised before lowering*: for
//! every combination of its type parameters over the float types, the syntax tree is copied
//! with the parameters replaced by concrete types, and each copy is lowered and emitted like a
//! hand-written function. This keeps every later stage (type rules, both back ends, adjoints)
//! unaware of generics, and gives each instance exactly the code it would have had if written
//! out, so the CPU and CUDA results of an instance are those of the equivalent plain kernel.
//!
//! Inside a generic function the glam families take the parameter as an argument:
//! `Vec3<T>` is `Vec3` for `T = f32` and `DVec3` for `T = f64` (as a type, `Vec3<T>`, and in
//! a path, `Vec3::<T>::new(..)`); likewise `Vec2`, `Vec4`, `Mat2`..`Mat4`, `Quat`. `T` itself
//! may be used wherever a scalar type may: `x as T`, `T::MAX`, `T::consts::PI`.

use syn::spanned::Spanned;
use syn::visit_mut::VisitMut;

/// The float types a `T: Float` parameter ranges over, in instance order.
pub const FLOAT_TYPES: [&str; 2] = ["f32", "f64"];

/// The glam families a type parameter selects a member of: (written name, f32 name, f64 name).
const FAMILIES: [(&str, &str, &str); 10] = [
    ("Vec2", "Vec2", "DVec2"),
    ("Vec3", "Vec3", "DVec3"),
    ("Vec4", "Vec4", "DVec4"),
    ("Mat2", "Mat2", "DMat2"),
    ("Mat3", "Mat3", "DMat3"),
    ("Mat4", "Mat4", "DMat4"),
    ("Quat", "Quat", "DQuat"),
    ("Transform", "Transform", "DTransform"),
    ("SpatialVector", "SpatialVector", "DSpatialVector"),
    ("SpatialMatrix", "SpatialMatrix", "DSpatialMatrix"),
];

/// One instance of a generic function.
pub struct Instance {
    /// The function with its type parameters replaced (and removed from the signature).
    pub item: syn::ItemFn,
    /// The concrete types, in parameter order: `["f32"]`, `["f64", "f32"]`.
    pub types: Vec<&'static str>,
}

impl Instance {
    /// `integrate<f32>`: the instance's name in messages and reports.
    pub fn display_name(&self, base: &str) -> String {
        format!("{base}<{}>", self.types.join(", "))
    }

    /// `f32` / `f32_f64`: a suffix for identifiers.
    pub fn ident_suffix(&self) -> String {
        self.types.join("_")
    }
}

/// The generic parameters of a function, checked: type parameters bounded by `Float` only.
pub struct Generics {
    /// Parameter names and the bound path as written (kept so that the user's `use` of the
    /// trait stays used and a misspelt bound is still an error).
    pub params: Vec<(syn::Ident, syn::Path)>,
}

/// The generic parameters of `item`, or `None` when it has none.
pub fn parse(item: &syn::ItemFn) -> Result<Option<Generics>, Vec<syn::Error>> {
    let g = &item.sig.generics;
    if g.params.is_empty() {
        return Ok(None);
    }
    let mut errors = Vec::new();
    if let Some(w) = &g.where_clause {
        errors.push(syn::Error::new(
            w.span(),
            "write the bound on the parameter (`T: Float`): where clauses are not supported in kernels",
        ));
    }
    let mut params = Vec::new();
    for p in &g.params {
        match p {
            syn::GenericParam::Type(tp) => {
                let bounds: Vec<&syn::TypeParamBound> = tp.bounds.iter().collect();
                let float = match bounds.as_slice() {
                    [syn::TypeParamBound::Trait(tb)]
                        if tb.path.segments.last().is_some_and(|s| s.ident == "Float")
                            && tb.lifetimes.is_none()
                            && matches!(tb.modifier, syn::TraitBoundModifier::None) =>
                    {
                        Some(tb.path.clone())
                    }
                    _ => None,
                };
                match (float, &tp.default) {
                    (Some(path), None) => params.push((tp.ident.clone(), path)),
                    (_, Some(d)) => errors.push(syn::Error::new(
                        d.span(),
                        "type parameters of kernels and funcs take no default",
                    )),
                    (None, None) => errors.push(syn::Error::new(
                        tp.span(),
                        format!(
                            "a type parameter of a kernel or func must be bounded by `Float` \
                             alone (`{}: Float`): it is instantiated for f32 and f64",
                            tp.ident
                        ),
                    )),
                }
            }
            syn::GenericParam::Lifetime(l) => errors.push(syn::Error::new(
                l.span(),
                "kernels and funcs take no lifetime parameters",
            )),
            syn::GenericParam::Const(c) => errors.push(syn::Error::new(
                c.span(),
                "kernels and funcs take no const parameters",
            )),
        }
    }
    if errors.is_empty() {
        Ok(Some(Generics { params }))
    } else {
        Err(errors)
    }
}

/// Every instance of `item` over the float types (the cartesian product for several
/// parameters), each with the parameters substituted.
pub fn instances(item: &syn::ItemFn, g: &Generics) -> Vec<Instance> {
    let mut combos: Vec<Vec<&'static str>> = vec![vec![]];
    for _ in &g.params {
        combos = combos
            .into_iter()
            .flat_map(|c| {
                FLOAT_TYPES.iter().map(move |t| {
                    let mut c = c.clone();
                    c.push(*t);
                    c
                })
            })
            .collect();
    }
    combos
        .into_iter()
        .map(|types| {
            let mut item = item.clone();
            item.sig.generics = syn::Generics::default();
            let mut s = Substitute {
                map: g
                    .params
                    .iter()
                    .zip(&types)
                    .map(|((id, _), t)| (id.to_string(), *t))
                    .collect(),
            };
            s.visit_item_fn_mut(&mut item);
            Instance { item, types }
        })
        .collect()
}

/// Checks that every type parameter shows in a parameter's type: the launch arguments (or a
/// func's call) must tell the instances apart.
pub fn check_params_select(item: &syn::ItemFn, g: &Generics) -> Vec<syn::Error> {
    let mut errors = Vec::new();
    for (id, _) in &g.params {
        let mut seen = false;
        for input in &item.sig.inputs {
            if let syn::FnArg::Typed(pt) = input {
                let mut f = Find {
                    name: id.to_string(),
                    found: false,
                };
                syn::visit::Visit::visit_type(&mut f, &pt.ty);
                seen |= f.found;
            }
        }
        if !seen {
            errors.push(syn::Error::new(
                id.span(),
                format!(
                    "`{id}` appears in no parameter type: the launch arguments must say which \
                     instance runs (use `{id}` in a parameter, e.g. `x: Array<{id}>` or `s: {id}`)"
                ),
            ));
        }
    }
    errors
}

struct Find {
    name: String,
    found: bool,
}

impl<'ast> syn::visit::Visit<'ast> for Find {
    fn visit_ident(&mut self, i: &'ast syn::Ident) {
        if i == self.name.as_str() {
            self.found = true;
        }
    }
}

/// Replaces type parameters by concrete types, and `Family<T>` by the family's member.
struct Substitute {
    map: Vec<(String, &'static str)>,
}

impl Substitute {
    fn concrete(&self, ident: &syn::Ident) -> Option<&'static str> {
        self.map
            .iter()
            .find(|(n, _)| ident == n.as_str())
            .map(|(_, t)| *t)
    }
}

/// The float type a segment's single generic argument names after substitution, if it is
/// `<f32>` or `<f64>`.
fn family_arg(args: &syn::PathArguments) -> Option<&'static str> {
    let syn::PathArguments::AngleBracketed(a) = args else {
        return None;
    };
    if a.args.len() != 1 {
        return None;
    }
    let syn::GenericArgument::Type(syn::Type::Path(tp)) = a.args.first()? else {
        return None;
    };
    if tp.qself.is_some() || tp.path.segments.len() != 1 {
        return None;
    }
    let id = &tp.path.segments[0].ident;
    FLOAT_TYPES.into_iter().find(|t| id == t)
}

impl VisitMut for Substitute {
    /// `print!`/`println!` arguments are expressions too (`println!("{}", x as T)`): visited
    /// when they parse as a comma-separated expression list, left alone otherwise.
    fn visit_macro_mut(&mut self, mac: &mut syn::Macro) {
        use syn::parse::Parser;
        let parser = syn::punctuated::Punctuated::<syn::Expr, syn::Token![,]>::parse_terminated;
        if let Ok(mut args) = parser.parse2(mac.tokens.clone()) {
            for a in args.iter_mut() {
                self.visit_expr_mut(a);
            }
            mac.tokens = quote::ToTokens::to_token_stream(&args);
        }
    }

    fn visit_path_mut(&mut self, path: &mut syn::Path) {
        // Children first: `Vec3<T>` becomes `Vec3<f64>`, then `DVec3`.
        syn::visit_mut::visit_path_mut(self, path);
        // `T::MAX`, `T::consts::PI`, `T` as a type.
        if let Some(first) = path.segments.first_mut() {
            if matches!(first.arguments, syn::PathArguments::None) {
                if let Some(t) = self.concrete(&first.ident) {
                    first.ident = syn::Ident::new(t, first.ident.span());
                }
            }
        }
        for seg in path.segments.iter_mut() {
            let Some(t) = family_arg(&seg.arguments) else {
                continue;
            };
            let Some((_, f32_name, f64_name)) = FAMILIES.iter().find(|(n, ..)| seg.ident == n)
            else {
                continue;
            };
            let name = if t == "f32" { f32_name } else { f64_name };
            seg.ident = syn::Ident::new(name, seg.ident.span());
            seg.arguments = syn::PathArguments::None;
        }
    }
}

/// A check, emitted once per generic function, that each bound names the real `Float` trait
/// (and that f32 and f64 satisfy it), spanned at the bound.
pub fn bound_check(g: &Generics) -> proc_macro2::TokenStream {
    let checks = g.params.iter().map(|(_, path)| {
        let sp = path.span();
        quote::quote_spanned! {sp=>
            {
                fn __wp_bound<__T: #path>() {}
                __wp_bound::<f32>();
                __wp_bound::<f64>();
            }
        }
    });
    quote::quote! {
        const _: fn() = || { #(#checks)* };
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use quote::ToTokens;

    fn inst(src: &str) -> Vec<String> {
        let item: syn::ItemFn = syn::parse_str(src).unwrap();
        let g = parse(&item).unwrap().unwrap();
        instances(&item, &g)
            .into_iter()
            .map(|i| i.item.to_token_stream().to_string())
            .collect()
    }

    #[test]
    fn substitutes_scalars_families_and_paths() {
        let out = inst(
            "fn k<T: Float>(x: Array<Vec3<T>>, s: T) { let v = Vec3::<T>::new(s, 1.0, T::MAX); \
             let w = g::<T>(s as T, T::consts::PI); }",
        );
        assert_eq!(out.len(), 2);
        assert!(out[0].contains("x : Array < Vec3 >"), "{}", out[0]);
        assert!(out[0].contains("s : f32"), "{}", out[0]);
        assert!(
            out[0].contains("Vec3 :: new (s , 1.0 , f32 :: MAX)"),
            "{}",
            out[0]
        );
        assert!(out[0].contains("g :: < f32 > (s as f32 , f32 :: consts :: PI)"));
        assert!(out[1].contains("x : Array < DVec3 >"), "{}", out[1]);
        assert!(
            out[1].contains("DVec3 :: new (s , 1.0 , f64 :: MAX)"),
            "{}",
            out[1]
        );
        assert!(
            !out[1].contains('<') || !out[1].contains("< T"),
            "{}",
            out[1]
        );
    }

    #[test]
    fn several_parameters_make_the_product() {
        let item: syn::ItemFn =
            syn::parse_str("fn k<A: Float, B: wp::Float>(a: A, b: B) {}").unwrap();
        let g = parse(&item).unwrap().unwrap();
        let names: Vec<String> = instances(&item, &g)
            .iter()
            .map(|i| i.display_name("k"))
            .collect();
        assert_eq!(
            names,
            ["k<f32, f32>", "k<f32, f64>", "k<f64, f32>", "k<f64, f64>"]
        );
    }

    #[test]
    fn rejects_other_generics() {
        for src in [
            "fn k<T>(a: T) {}",
            "fn k<T: Copy>(a: T) {}",
            "fn k<'a>(a: f32) {}",
            "fn k<const N: usize>(a: f32) {}",
            "fn k<T: Float>(a: T) where T: Copy {}",
        ] {
            let item: syn::ItemFn = syn::parse_str(src).unwrap();
            assert!(parse(&item).is_err(), "{src}");
        }
    }

    #[test]
    fn a_parameter_must_select_the_instance() {
        let item: syn::ItemFn =
            syn::parse_str("fn k<T: Float>(a: Array<f32>) { let x: T = 1.0; }").unwrap();
        let g = parse(&item).unwrap().unwrap();
        assert_eq!(check_params_select(&item, &g).len(), 1);
        let item: syn::ItemFn = syn::parse_str("fn k<T: Float>(a: Array<Vec3<T>>) {}").unwrap();
        assert!(check_params_select(&item, &g).is_empty());
    }
}

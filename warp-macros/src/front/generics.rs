//! Generic kernels and funcs: `fn integrate<T: Float>(x: Array<Vec3<T>>, dt: T)`.
//!
//! The language has no generic IR. A generic function is *monomorphised before lowering*: for
//! every combination of its type parameters over their instance types, the syntax tree is
//! copied with the parameters replaced by concrete types, and each copy is lowered and emitted
//! like a hand-written function. This keeps every later stage (type rules, both back ends,
//! adjoints) unaware of generics, and gives each instance exactly the code it would have had if
//! written out, so the CPU and CUDA results of an instance are those of the equivalent plain
//! kernel.
//!
//! A type parameter's bound is one of four traits, each a closed list of types ([`KINDS`]):
//! `Float` (f32, f64), `Int` (i32, u32, i64, u64 by default; the other integer types when
//! listed), `Vector` (the float vectors of 2 to 4 lanes) and `Element` (any array element type,
//! scalars, vectors, matrices, user structs: its instances are always listed). A list
//! `#[kernel(instances(T = [f32, Particle]))]` picks the instances; without one, a parameter
//! ranges over its kind's defaults. Each instance's body is checked with its concrete type,
//! so a body that uses a parameter beyond what one of its instances has fails to compile at
//! the use (``in `k<u32>`: ..``): for the closed bounds, the instances *are* the bound.
//!
//! Inside a generic function the glam families take a float parameter as an argument:
//! `Vec3<T>` is `Vec3` for `T = f32` and `DVec3` for `T = f64` (as a type, `Vec3<T>`, and in
//! a path, `Vec3::<T>::new(..)`); likewise `Vec2`, `Vec4`, `Mat2`..`Mat4`, `Quat`. `T` itself
//! may be used wherever its concrete type may: `x as T`, `T::MAX`, `T::consts::PI`. A vector
//! parameter's lane type is `V::Scalar` and its lane count `V::LEN` (the `Vector` trait's
//! associated type and constant, so the same spelling means the same in plain Rust).

use syn::spanned::Spanned;
use syn::visit_mut::VisitMut;

/// The float types a `T: Float` parameter ranges over, in instance order.
pub const FLOAT_TYPES: [&str; 2] = ["f32", "f64"];

/// What a bound admits: its trait's name, the instance types without a list, and the types a
/// list may name (`None`: any type, checked by rustc against the trait).
pub struct Kind {
    pub bound: &'static str,
    pub defaults: &'static [&'static str],
    pub allowed: Option<&'static [&'static str]>,
}

/// The bounds, one row each.
pub const KINDS: [Kind; 4] = [
    Kind {
        bound: "Float",
        defaults: &FLOAT_TYPES,
        allowed: Some(&FLOAT_TYPES),
    },
    Kind {
        bound: "Int",
        defaults: &["i32", "u32", "i64", "u64"],
        allowed: Some(&["i8", "i16", "i32", "i64", "u8", "u16", "u32", "u64"]),
    },
    Kind {
        bound: "Vector",
        defaults: &VECTOR_TYPES,
        allowed: Some(&VECTOR_TYPES),
    },
    Kind {
        bound: "Element",
        defaults: &[],
        allowed: None,
    },
];

/// A `V: Vector` parameter's types, with their lane type and count (what `V::Scalar` and
/// `V::LEN` become).
const VECTOR_TYPES: [&str; 6] = ["Vec2", "Vec3", "Vec4", "DVec2", "DVec3", "DVec4"];
const VECTOR_SHAPES: [(&str, &str, usize); 6] = [
    ("Vec2", "f32", 2),
    ("Vec3", "f32", 3),
    ("Vec4", "f32", 4),
    ("DVec2", "f64", 2),
    ("DVec3", "f64", 3),
    ("DVec4", "f64", 4),
];

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
    /// The concrete types, in parameter order: `[f32]`, `[f64, f32]`, `[Particle]`.
    pub types: Vec<syn::Type>,
}

/// `Particle`, `crate::Particle`: a type as written, without spaces.
fn type_name(t: &syn::Type) -> String {
    quote::ToTokens::to_token_stream(t)
        .to_string()
        .replace(' ', "")
}

impl Instance {
    /// `integrate<f32>`: the instance's name in messages and reports.
    pub fn display_name(&self, base: &str) -> String {
        let names: Vec<String> = self.types.iter().map(type_name).collect();
        format!("{base}<{}>", names.join(", "))
    }

    /// `f32` / `f32_f64` / `crate_Particle`: a suffix for identifiers.
    pub fn ident_suffix(&self) -> String {
        let names: Vec<String> = self
            .types
            .iter()
            .map(|t| {
                type_name(t)
                    .chars()
                    .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
                    .collect()
            })
            .collect();
        names.join("_")
    }
}

/// One type parameter, checked.
pub struct Param {
    pub ident: syn::Ident,
    /// The bound path as written (kept so that the user's `use` of the trait stays used and a
    /// misspelt bound is still an error).
    pub bound: syn::Path,
    /// The instance types: the kind's defaults, or the user's list (spanned where written).
    pub types: Vec<syn::Type>,
}

/// The generic parameters of a function, checked.
pub struct Generics {
    pub params: Vec<Param>,
}

/// `instances(T = [f32, Vec3])` of `#[kernel(..)]` or `#[func(..)]`: per parameter, the
/// types listed.
pub type Lists = Vec<(syn::Ident, Vec<syn::Type>)>;

/// Parses the inside of `instances(..)`: `T = [f32, Vec3], I = [i32]`.
pub fn parse_lists(meta: syn::meta::ParseNestedMeta) -> syn::Result<Lists> {
    let mut out: Lists = Vec::new();
    meta.parse_nested_meta(|inner| {
        let id = inner.path.require_ident()?.clone();
        let value = inner.value()?;
        let content;
        syn::bracketed!(content in value);
        let tys =
            syn::punctuated::Punctuated::<syn::Type, syn::Token![,]>::parse_terminated(&content)?;
        if out.iter().any(|(o, _)| *o == id) {
            return Err(syn::Error::new(
                id.span(),
                format!("`{id}` is listed twice"),
            ));
        }
        out.push((id, tys.into_iter().collect()));
        Ok(())
    })?;
    Ok(out)
}

/// The kind a bound names by its last segment (`Float`, `wp::Int`), with its path.
fn kind_of(tp: &syn::TypeParam) -> Option<(syn::Path, &'static Kind)> {
    let bounds: Vec<&syn::TypeParamBound> = tp.bounds.iter().collect();
    let [syn::TypeParamBound::Trait(tb)] = bounds.as_slice() else {
        return None;
    };
    if tb.lifetimes.is_some() || !matches!(tb.modifier, syn::TraitBoundModifier::None) {
        return None;
    }
    let last = tb.path.segments.last()?;
    if !matches!(last.arguments, syn::PathArguments::None) {
        return None;
    }
    let kind = KINDS.iter().find(|k| last.ident == k.bound)?;
    Some((tb.path.clone(), kind))
}

/// The generic parameters of `item`, or `None` when it has none; `lists` are the
/// `instances(..)` of the attribute (an error names each list entry that is no parameter
/// of `item`).
pub fn parse(item: &syn::ItemFn, lists: &Lists) -> Result<Option<Generics>, Vec<syn::Error>> {
    let g = &item.sig.generics;
    let mut errors = Vec::new();
    if g.params.is_empty() {
        for (id, _) in lists {
            errors.push(syn::Error::new(
                id.span(),
                format!("`{id}` is not a type parameter of `{}`", item.sig.ident),
            ));
        }
        return if errors.is_empty() {
            Ok(None)
        } else {
            Err(errors)
        };
    }
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
                if let Some(d) = &tp.default {
                    errors.push(syn::Error::new(
                        d.span(),
                        "type parameters of kernels and funcs take no default",
                    ));
                    continue;
                }
                let Some((bound, kind)) = kind_of(tp) else {
                    errors.push(syn::Error::new(
                        tp.span(),
                        format!(
                            "a type parameter of a kernel or func is bounded by one of `Float`, \
                             `Int`, `Vector` or `Element` alone (`{}: Float`): it is \
                             instantiated for each of the bound's types",
                            tp.ident
                        ),
                    ));
                    continue;
                };
                let list = lists.iter().find(|(id, _)| *id == tp.ident);
                let types = match list {
                    Some((_, tys)) => match check_list(&tp.ident, kind, tys) {
                        Ok(()) => tys.clone(),
                        Err(e) => {
                            errors.extend(e);
                            continue;
                        }
                    },
                    None if kind.defaults.is_empty() => {
                        errors.push(syn::Error::new(
                            tp.span(),
                            format!(
                                "`{0}: {1}` ranges over every array element type: list its \
                                 instances in the attribute, e.g. `instances({0} = [f32, Vec3, \
                                 MyStruct])`",
                                tp.ident, kind.bound
                            ),
                        ));
                        continue;
                    }
                    None => kind
                        .defaults
                        .iter()
                        .map(|t| syn::parse_str(t).expect("a type name"))
                        .collect(),
                };
                params.push(Param {
                    ident: tp.ident.clone(),
                    bound,

                    types,
                });
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
    for (id, _) in lists {
        let is_param = g
            .params
            .iter()
            .any(|p| matches!(p, syn::GenericParam::Type(tp) if tp.ident == *id));
        if !is_param {
            errors.push(syn::Error::new(
                id.span(),
                format!("`{id}` is not a type parameter of `{}`", item.sig.ident),
            ));
        }
    }
    if errors.is_empty() {
        Ok(Some(Generics { params }))
    } else {
        Err(errors)
    }
}

/// A list's types against its parameter's kind: not empty, each a plain path (what
/// substitution can put where `T` was, `T::MAX` included), each once, and for the closed
/// kinds one of the kind's types.
fn check_list(id: &syn::Ident, kind: &Kind, tys: &[syn::Type]) -> Result<(), Vec<syn::Error>> {
    let mut errors = Vec::new();
    if tys.is_empty() {
        errors.push(syn::Error::new(
            id.span(),
            format!("`{id}` lists no instance"),
        ));
    }
    for (k, t) in tys.iter().enumerate() {
        let plain = matches!(t, syn::Type::Path(p) if p.qself.is_none()
            && p.path.segments.iter().all(|s| matches!(s.arguments, syn::PathArguments::None)));
        if !plain {
            errors.push(syn::Error::new(
                t.span(),
                "an instance is a type named by a path (`f32`, `Vec3`, `Particle`, `crate::Particle`)",
            ));
            continue;
        }
        let name = type_name(t);
        if tys[..k].iter().any(|u| type_name(u) == name) {
            errors.push(syn::Error::new(
                t.span(),
                format!("`{name}` is listed twice"),
            ));
        }
        if let Some(allowed) = kind.allowed {
            if !allowed.contains(&name.as_str()) {
                errors.push(syn::Error::new(
                    t.span(),
                    format!(
                        "`{name}` is not one of the types of `{id}: {}`: {}",
                        kind.bound,
                        allowed.join(", ")
                    ),
                ));
            }
        }
    }
    if errors.is_empty() {
        Ok(())
    } else {
        Err(errors)
    }
}

/// Every instance of `item` (the cartesian product of its parameters' types, first parameter
/// slowest), each with the parameters substituted.
pub fn instances(item: &syn::ItemFn, g: &Generics) -> Vec<Instance> {
    let mut combos: Vec<Vec<syn::Type>> = vec![vec![]];
    for p in &g.params {
        combos = combos
            .into_iter()
            .flat_map(|c| {
                p.types.iter().map(move |t| {
                    let mut c = c.clone();
                    c.push(t.clone());
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
                    .map(|(p, t)| (p.ident.to_string(), t.clone()))
                    .collect(),
            };
            s.visit_item_fn_mut(&mut item);
            Instance { item, types }
        })
        .collect()
}

/// `path` (a custom gradient's or replay's func, `dcube::<T>`) with `g`'s parameters replaced
/// by one instance's `types`, as in the instance's body.
pub fn substitute_path(path: &syn::Path, g: &Generics, types: &[syn::Type]) -> syn::Path {
    let mut s = Substitute {
        map: g
            .params
            .iter()
            .zip(types)
            .map(|(p, t)| (p.ident.to_string(), t.clone()))
            .collect(),
    };
    let mut out = path.clone();
    s.visit_path_mut(&mut out);
    out
}

/// Checks that every type parameter shows in a parameter's type: the launch arguments (or a
/// func's call) must tell the instances apart.
pub fn check_params_select(item: &syn::ItemFn, g: &Generics) -> Vec<syn::Error> {
    let mut errors = Vec::new();
    for p in &g.params {
        let id = &p.ident;
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

/// Replaces type parameters by concrete types, `Family<T>` by the family's member, and a
/// vector parameter's `V::Scalar` and `V::LEN` by its lane type and count.
struct Substitute {
    map: Vec<(String, syn::Type)>,
}

impl Substitute {
    fn concrete(&self, ident: &syn::Ident) -> Option<&syn::Type> {
        self.map
            .iter()
            .find(|(n, _)| ident == n.as_str())
            .map(|(_, t)| t)
    }

    /// The lane type and count of the vector a path's first segment names, when it is a
    /// vector parameter (`V` of `V::Scalar`).
    fn vector_shape(&self, ident: &syn::Ident) -> Option<(&'static str, usize)> {
        let name = type_name(self.concrete(ident)?);
        VECTOR_SHAPES
            .iter()
            .find(|(v, ..)| *v == name)
            .map(|(_, s, n)| (*s, *n))
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

    /// `V::LEN` (a vector parameter's lane count) becomes an unsuffixed integer literal, so
    /// that it takes the type its use gives it, as a `usize` constant would in a range or an
    /// index.
    fn visit_expr_mut(&mut self, e: &mut syn::Expr) {
        if let syn::Expr::Path(p) = e {
            let segs = &p.path.segments;
            if p.qself.is_none() && segs.len() == 2 && segs[1].ident == "LEN" {
                if let Some((_, n)) = self.vector_shape(&segs[0].ident) {
                    let lit = syn::LitInt::new(&n.to_string(), segs[1].ident.span());
                    *e = syn::parse_quote!(#lit);
                    return;
                }
            }
        }
        syn::visit_mut::visit_expr_mut(self, e);
    }

    fn visit_path_mut(&mut self, path: &mut syn::Path) {
        // Children first: `Vec3<T>` becomes `Vec3<f64>`, then `DVec3`.
        syn::visit_mut::visit_path_mut(self, path);
        // `V::Scalar`: the vector's lane type.
        if path.segments.len() >= 2 && path.segments[1].ident == "Scalar" {
            if let Some((s, _)) = self.vector_shape(&path.segments[0].ident) {
                let sp = path.segments[1].ident.span();
                let rest: Vec<syn::PathSegment> = path.segments.iter().skip(2).cloned().collect();
                path.segments.clear();
                path.segments.push(syn::Ident::new(s, sp).into());
                path.segments.extend(rest);
                return;
            }
        }
        // `T::MAX`, `T::consts::PI`, `T` as a type: the first segment becomes the concrete
        // type's path (`Particle`, `crate::Particle`).
        let first = path.segments.first().cloned();
        if let Some(first) = first {
            if matches!(first.arguments, syn::PathArguments::None) {
                if let Some(syn::Type::Path(tp)) = self.concrete(&first.ident).cloned() {
                    let sp = first.ident.span();
                    let rest: Vec<syn::PathSegment> =
                        path.segments.iter().skip(1).cloned().collect();
                    path.leading_colon = path.leading_colon.or(tp.path.leading_colon);
                    path.segments.clear();
                    for mut seg in tp.path.segments {
                        seg.ident.set_span(sp);
                        path.segments.push(seg);
                    }
                    path.segments.extend(rest);
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

/// A check, emitted once per generic function, that each bound names the real trait and that
/// each instance type satisfies it, spanned at the bound (and, for a listed type, at the
/// type: `instances(T = [Foo])` with `Foo` no array element fails there).
pub fn bound_check(g: &Generics) -> proc_macro2::TokenStream {
    let checks = g.params.iter().map(|p| {
        let path = &p.bound;
        let sp = path.span();
        let uses = p.types.iter().map(|t| {
            let tsp = t.span();
            quote::quote_spanned! {tsp=> __wp_bound::<#t>(); }
        });
        quote::quote_spanned! {sp=>
            {
                fn __wp_bound<__T: #path>() {}
                #(#uses)*
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
        let g = parse(&item, &Vec::new()).unwrap().unwrap();
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
        let g = parse(&item, &Vec::new()).unwrap().unwrap();
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
            "fn k<T: Element>(a: Array<T>) {}",
            "fn k<T: Float + Copy>(a: T) {}",
            "fn k<'a>(a: f32) {}",
            "fn k<const N: usize>(a: f32) {}",
            "fn k<T: Float>(a: T) where T: Copy {}",
        ] {
            let item: syn::ItemFn = syn::parse_str(src).unwrap();
            assert!(parse(&item, &Vec::new()).is_err(), "{src}");
        }
    }

    #[test]
    fn a_parameter_must_select_the_instance() {
        let item: syn::ItemFn =
            syn::parse_str("fn k<T: Float>(a: Array<f32>) { let x: T = 1.0; }").unwrap();
        let g = parse(&item, &Vec::new()).unwrap().unwrap();
        assert_eq!(check_params_select(&item, &g).len(), 1);
        let item: syn::ItemFn = syn::parse_str("fn k<T: Float>(a: Array<Vec3<T>>) {}").unwrap();
        assert!(check_params_select(&item, &g).is_empty());
    }

    fn lists(src: &str) -> Lists {
        use syn::parse::Parser;
        let mut out = Lists::new();
        syn::meta::parser(|meta| {
            out = parse_lists(meta)?;
            Ok(())
        })
        .parse_str(src)
        .unwrap();
        out
    }

    #[test]
    fn integer_and_vector_kinds_have_default_instances() {
        let item: syn::ItemFn =
            syn::parse_str("fn k<I: Int, V: Vector>(a: Array<I>, v: Array<V>) {}").unwrap();
        let g = parse(&item, &Vec::new()).unwrap().unwrap();
        let names: Vec<String> = instances(&item, &g)
            .iter()
            .map(|i| i.display_name("k"))
            .collect();
        assert_eq!(names.len(), 4 * 6);
        assert_eq!(names[0], "k<i32, Vec2>");
        assert_eq!(names[23], "k<u64, DVec4>");
    }

    #[test]
    fn vector_scalar_and_len_are_substituted() {
        let item: syn::ItemFn = syn::parse_str(
            "fn k<V: Vector>(v: Array<V>, s: V::Scalar) { let z = V::ZERO; \
             let n: V::Scalar = 0.0; for k in 0..V::LEN { } let a = [0.0f32; V::LEN]; }",
        )
        .unwrap();
        let g = parse(&item, &lists("instances(V = [DVec3, Vec2])"))
            .unwrap()
            .unwrap();
        let out: Vec<String> = instances(&item, &g)
            .into_iter()
            .map(|i| i.item.to_token_stream().to_string())
            .collect();
        assert!(
            out[0].contains("v : Array < DVec3 > , s : f64"),
            "{}",
            out[0]
        );
        assert!(out[0].contains("DVec3 :: ZERO"), "{}", out[0]);
        assert!(out[0].contains("n : f64"), "{}", out[0]);
        assert!(out[0].contains("0 .. 3"), "{}", out[0]);
        assert!(out[0].contains("[0.0f32 ; 3]"), "{}", out[0]);
        assert!(
            out[1].contains("s : f32") && out[1].contains("0 .. 2"),
            "{}",
            out[1]
        );
    }

    #[test]
    fn element_parameters_take_listed_paths() {
        let item: syn::ItemFn =
            syn::parse_str("fn k<T: Element>(a: Array<T>, b: T) { let c: T = b; }").unwrap();
        let g = parse(&item, &lists("instances(T = [f32, crate::Particle])"))
            .unwrap()
            .unwrap();
        let inst = instances(&item, &g);
        assert_eq!(inst[1].display_name("k"), "k<crate::Particle>");
        assert_eq!(inst[1].ident_suffix(), "crate__Particle");
        let text = inst[1].item.to_token_stream().to_string();
        assert!(text.contains("a : Array < crate :: Particle >"), "{text}");
        assert!(text.contains("let c : crate :: Particle = b"), "{text}");
    }

    #[test]
    fn lists_are_checked_against_the_kind() {
        let item: syn::ItemFn = syn::parse_str("fn k<I: Int>(a: Array<I>) {}").unwrap();
        for bad in [
            "instances(I = [f32])",
            "instances(I = [i32, i32])",
            "instances(I = [])",
            "instances(J = [i32])",
            "instances(I = [[i32; 2]])",
        ] {
            assert!(parse(&item, &lists(bad)).is_err(), "{bad}");
        }
        let g = parse(&item, &lists("instances(I = [u8, i16])"))
            .unwrap()
            .unwrap();
        assert_eq!(instances(&item, &g).len(), 2);
    }
}

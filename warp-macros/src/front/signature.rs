//! Kernel and func signatures: parameter types and the return type.

use crate::types::{BlockElem, Dim, Elem, ObjectKind, ObjectRow, Scalar, Ty, VolumeElem};
use syn::spanned::Spanned;
use syn::{GenericArgument, PathArguments, Type};

/// Maps a parameter or return type as written to the language's type, or explains why the
/// language has no such type.
pub fn parse_type(ty: &Type) -> syn::Result<Ty> {
    match ty {
        Type::Path(tp) if tp.qself.is_none() => {
            let last = tp.path.segments.last().expect("a path has a segment");
            let name = last.ident.to_string();
            if let Some(s) = Scalar::from_name(&name) {
                return Ok(Ty::Scalar(s));
            }
            if let Some(t) = Ty::from_glam_name(&name) {
                return Ok(t);
            }
            // Host objects (`HashGrid`, `Volume<f32>`): the runtime's type of that name, which
            // the prelude exports; kernels see its view.
            if let Some(row) = ObjectRow::param_named(&name) {
                if row.elem {
                    return parse_elem_object(row, last, ty);
                }
                if !matches!(last.arguments, PathArguments::None) {
                    return Err(syn::Error::new(
                        ty.span(),
                        format!("`{name}` takes no type arguments"),
                    ));
                }
                return Ok(Ty::Object(row.kind));
            }
            match name.as_str() {
                "Array" => parse_array(last, ty),
                "Tile" => parse_tile(last, ty),
                "String" | "Vec" | "Box" | "Rc" | "Arc" | "HashMap" | "BTreeMap" | "VecDeque" => Err(syn::Error::new(
                    ty.span(),
                    format!("heap type `{name}` is not supported in kernels: use Array<T> arguments"),
                )),
                "str" => Err(syn::Error::new(ty.span(), "strings are not supported in kernels")),
                "Option" | "Result" => {
                    Err(syn::Error::new(ty.span(), format!("`{name}` is not supported in kernels")))
                }
                _ if !matches!(last.arguments, PathArguments::None) => Err(syn::Error::new(
                    ty.span(),
                    format!("generic type `{name}<..>` is not supported in kernels"),
                )),
                _ => Ok(Ty::Struct(name)),
            }
        }
        Type::Reference(_) => Err(syn::Error::new(
            ty.span(),
            "references are not supported in kernels: pass arrays as Array<T> and values by value",
        )),
        Type::Ptr(_) => Err(syn::Error::new(
            ty.span(),
            "raw pointers are not supported in kernels",
        )),
        // A local array (`[f32; 8]`): a value, in funcs' signatures and `let` annotations.
        Type::Array(a) => {
            let elem = parse_type(&a.elem)?;
            if let Some(why) = local_array_elem_error(&elem) {
                return Err(syn::Error::new(a.elem.span(), why));
            }
            let n = local_array_length(&a.len)?;
            Ok(Ty::LocalArray(Box::new(elem), n))
        }
        Type::Slice(_) => Err(syn::Error::new(
            ty.span(),
            "slices are not supported in kernels: use Array<T>, or a local array `[T; N]`",
        )),
        Type::Tuple(t) if t.elems.is_empty() => Ok(Ty::Unit),
        // A tuple of values (`(f32, Vec3)`): a func's parameter or result, a `let` annotation.
        Type::Tuple(t) => {
            let elems: Vec<Ty> = t.elems.iter().map(parse_type).collect::<syn::Result<_>>()?;
            tuple_type(elems, ty.span())
        }
        Type::Paren(p) => parse_type(&p.elem),
        Type::Group(g) => parse_type(&g.elem),
        _ => Err(syn::Error::new(
            ty.span(),
            "this type is not supported in kernels",
        )),
    }
}

/// The most elements a tuple has (the CUDA library's `tuple_t` and warp-core's `Adjoint`
/// impls go this far).
pub const MAX_TUPLE: usize = 7;

/// A tuple of `elems`, or why the language has no such tuple: 2 to [`MAX_TUPLE`] values
/// (no arrays, host objects or tiles: those are kernel parameters or block-wide).
pub fn tuple_type(elems: Vec<Ty>, span: proc_macro2::Span) -> syn::Result<Ty> {
    if elems.len() < 2 || elems.len() > MAX_TUPLE {
        return Err(syn::Error::new(
            span,
            format!(
                "tuples in kernels have 2 to {MAX_TUPLE} elements, found {}",
                elems.len()
            ),
        ));
    }
    if let Some(t) = elems
        .iter()
        .find(|t| matches!(t, Ty::Array(..) | Ty::Object(_) | Ty::Tile(..) | Ty::Unit))
    {
        return Err(syn::Error::new(
            span,
            format!("`{t}` cannot be a tuple's element: tuples hold values"),
        ));
    }
    Ok(Ty::Tuple(elems))
}

fn parse_array(seg: &syn::PathSegment, whole: &Type) -> syn::Result<Ty> {
    let PathArguments::AngleBracketed(args) = &seg.arguments else {
        return Err(syn::Error::new(
            whole.span(),
            "Array needs an element type: Array<f32>, Array<Vec3, 2>",
        ));
    };
    let mut it = args.args.iter();
    let elem = match it.next() {
        Some(GenericArgument::Type(t)) => parse_type(t)?,
        _ => {
            return Err(syn::Error::new(
                whole.span(),
                "Array needs an element type: Array<f32>",
            ))
        }
    };
    if matches!(elem, Ty::Array(..) | Ty::Unit) || elem == Ty::Scalar(Scalar::Bool) {
        return Err(syn::Error::new(
            whole.span(),
            format!("`{elem}` cannot be an array element (bool arrays: use u8)"),
        ));
    }
    if let Ty::Object(_) = elem {
        return Err(syn::Error::new(
            whole.span(),
            format!("`{elem}` cannot be an array element: pass each one as a parameter"),
        ));
    }
    if let Ty::Tuple(_) = elem {
        return Err(syn::Error::new(
            whole.span(),
            format!("`{elem}` cannot be an array element: use one array per element, or a #[derive(Struct)]"),
        ));
    }
    if let Ty::LocalArray(..) = elem {
        return Err(syn::Error::new(
            whole.span(),
            format!("`{elem}` cannot be an array element: add a dimension to the array"),
        ));
    }
    let ndim = match it.next() {
        None => 1,
        Some(arg) => {
            let n = const_usize(arg).ok_or_else(|| {
                syn::Error::new(
                    arg.span(),
                    "the array dimension must be a literal 1, 2, 3 or 4",
                )
            })?;
            if !(1..=4).contains(&n) {
                return Err(syn::Error::new(arg.span(), "arrays have 1 to 4 dimensions"));
            }
            n as u8
        }
    };
    if let Some(extra) = it.next() {
        return Err(syn::Error::new(
            extra.span(),
            "Array takes an element type and a dimension count",
        ));
    }
    Ok(Ty::Array(Box::new(elem), ndim))
}

/// An object generic over its element (`Volume<T>`: a NanoVDB grid of one of the value types,
/// or `Volume<VoxelIndex>`; `Bsr<B>`: a block sparse matrix of `B` blocks).
fn parse_elem_object(row: &ObjectRow, seg: &syn::PathSegment, whole: &Type) -> syn::Result<Ty> {
    let name = row.name;
    let is_bsr = matches!(row.kind, ObjectKind::Bsr(_));
    let elems = || {
        if is_bsr {
            return BlockElem::DESCRIBE.to_string();
        }
        let names: Vec<String> = VolumeElem::ALL.iter().map(|e| e.name()).collect();
        names.join(", ")
    };
    let example = if is_bsr { "Mat3" } else { "f32" };
    let what = if is_bsr { "block" } else { "value" };
    let PathArguments::AngleBracketed(args) = &seg.arguments else {
        return Err(syn::Error::new(
            whole.span(),
            format!(
                "{name} needs its {what} type: {name}<{example}> (one of {})",
                elems()
            ),
        ));
    };
    let mut it = args.args.iter();
    let (Some(GenericArgument::Type(t)), None) = (it.next(), it.next()) else {
        return Err(syn::Error::new(
            whole.span(),
            format!("{name} takes one type argument: {name}<{example}>"),
        ));
    };
    let elem: Option<Elem> = if is_bsr {
        parse_type(t)
            .ok()
            .and_then(|t| BlockElem::of(&t))
            .map(Elem::from)
    } else if matches!(t, Type::Path(p) if p.path.segments.last().is_some_and(|s| s.ident == "VoxelIndex"))
    {
        Some(VolumeElem::Index.into())
    } else {
        parse_type(t)
            .ok()
            .and_then(|t| VolumeElem::of(&t))
            .map(Elem::from)
    };
    match elem {
        Some(e) => Ok(Ty::Object(row.kind.with_elem(e))),
        None => Err(syn::Error::new(
            t.span(),
            format!("a {name} holds one of {}", elems()),
        )),
    }
}

/// `Tile<T, D0>` or `Tile<T, D0, D1>`: a scalar (or `Vec2`/`DVec2`) element and one or two dims, each a literal or a
/// module const ([`dim_of`]).
fn parse_tile(seg: &syn::PathSegment, whole: &Type) -> syn::Result<Ty> {
    let PathArguments::AngleBracketed(args) = &seg.arguments else {
        return Err(syn::Error::new(
            whole.span(),
            "a tile type names its element and shape: `Tile<f32, 16, 16>`",
        ));
    };
    let mut it = args.args.iter();
    let elem = match it.next() {
        Some(GenericArgument::Type(t)) => parse_type(t)?,
        _ => {
            return Err(syn::Error::new(
                whole.span(),
                "a tile type names its element first: `Tile<f32, 16, 16>`",
            ))
        }
    };
    if !elem.is_tile_elem() {
        return Err(syn::Error::new(
            whole.span(),
            format!("tiles hold integer or float scalars, or `Vec2`/`DVec2` (complex values), not `{elem}`"),
        ));
    }
    let dims = it.map(dim_of).collect::<syn::Result<Vec<_>>>()?;
    tile_rank(&dims, whole.span())?;
    Ok(Ty::Tile(Box::new(elem), dims))
}

/// Checks a tile shape's rank (1 to 4, Warp's tiles' ranks) and that no literal dim is zero.
pub fn tile_rank(dims: &[Dim], span: proc_macro2::Span) -> syn::Result<()> {
    if dims.is_empty() || dims.len() > 4 {
        return Err(syn::Error::new(
            span,
            format!("tiles have one to four dimensions, found {}", dims.len()),
        ));
    }
    if dims.contains(&Dim::Lit(0)) {
        return Err(syn::Error::new(span, "a tile dimension must be at least 1"));
    }
    Ok(())
}

/// Why a type cannot be a local array's element, if it cannot.
pub fn local_array_elem_error(t: &Ty) -> Option<String> {
    match t {
        // Plain `Copy` structs on both back ends (glam's and warp-core's types, wp_core.h's),
        // with a zero and an adjoint: a Rust array and `wp::local_array_t` hold them as they are.
        Ty::Scalar(_)
        | Ty::Vector(..)
        | Ty::Matrix(..)
        | Ty::Quat(_)
        | Ty::Transform(_)
        | Ty::SpatialVector(_)
        | Ty::SpatialMatrix(_)
        | Ty::MatRC(..) => None,
        Ty::LocalArray(e, _) => local_array_elem_error(e),
        Ty::Deferred => Some(
            "the elements' type is not known here: annotate it (`let a: [f32; 2] = [f(x), f(y)];`)"
                .into(),
        ),
        t => Some(format!(
            "`{t}` cannot be a local array's element: scalars, vectors, matrices, quaternions, \
             transforms, spatial vectors and matrices, and local arrays can"
        )),
    }
}

/// A local array's length as written (`[v; N]`, `[f32; N]`): an integer literal of at least 1,
/// or a module const named by a SCREAMING_CASE path.
pub fn local_array_length(e: &syn::Expr) -> syn::Result<Dim> {
    let bad = || {
        syn::Error::new(
            e.span(),
            "a local array's length must be an integer literal or a module const (`8`, `N`)",
        )
    };
    match e {
        syn::Expr::Lit(syn::ExprLit {
            lit: syn::Lit::Int(i),
            ..
        }) => match i.base10_parse::<u32>() {
            Ok(0) => Err(syn::Error::new(
                e.span(),
                "a local array holds at least one element",
            )),
            Ok(n) => Ok(Dim::Lit(n)),
            Err(_) => Err(bad()),
        },
        syn::Expr::Path(p) if p.qself.is_none() => dim_of_path(&p.path).ok_or_else(bad),
        syn::Expr::Paren(p) => local_array_length(&p.expr),
        syn::Expr::Group(g) => local_array_length(&g.expr),
        _ => Err(bad()),
    }
}

/// A tile dimension as written in a type or a turbofish: an integer literal, or a module
/// const named by a SCREAMING_CASE path (`TM`, `consts::TM`).
pub fn dim_of(arg: &GenericArgument) -> syn::Result<Dim> {
    let bad = || {
        syn::Error::new(
            arg.span(),
            "a tile dimension must be an integer literal or a module const (`16`, `TM`)",
        )
    };
    if let Some(n) = const_usize(arg) {
        return u32::try_from(n).map(Dim::Lit).map_err(|_| bad());
    }
    let path = match arg {
        GenericArgument::Type(Type::Path(tp)) if tp.qself.is_none() => &tp.path,
        GenericArgument::Const(syn::Expr::Path(p)) if p.qself.is_none() => &p.path,
        _ => return Err(bad()),
    };
    dim_of_path(path).ok_or_else(bad)
}

/// A const path as a dim, if its last segment is SCREAMING_CASE and it has no arguments.
pub fn dim_of_path(path: &syn::Path) -> Option<Dim> {
    let plain = path
        .segments
        .iter()
        .all(|s| matches!(s.arguments, PathArguments::None));
    let last = path.segments.last()?.ident.to_string();
    let screaming = last.chars().next()?.is_ascii_uppercase()
        && last
            .chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_');
    (plain && screaming).then(|| {
        let segs: Vec<String> = path.segments.iter().map(|s| s.ident.to_string()).collect();
        Dim::Const(segs.join("::"))
    })
}

fn const_usize(arg: &GenericArgument) -> Option<usize> {
    let expr = match arg {
        GenericArgument::Const(e) => e,
        // `Array<f32, 2>` parses the `2` as a const expression; syn may also see a type here.
        _ => return None,
    };
    match expr {
        syn::Expr::Lit(syn::ExprLit {
            lit: syn::Lit::Int(i),
            ..
        }) => i.base10_parse().ok(),
        syn::Expr::Block(b) if b.block.stmts.len() == 1 => match &b.block.stmts[0] {
            syn::Stmt::Expr(
                syn::Expr::Lit(syn::ExprLit {
                    lit: syn::Lit::Int(i),
                    ..
                }),
                None,
            ) => i.base10_parse().ok(),
            _ => None,
        },
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use syn::parse_quote;

    #[test]
    fn types() {
        assert_eq!(
            parse_type(&parse_quote!(f32)).unwrap(),
            Ty::Scalar(Scalar::F32)
        );
        assert_eq!(
            parse_type(&parse_quote!(glam::DVec3)).unwrap(),
            Ty::Vector(Scalar::F64, 3)
        );
        assert_eq!(
            parse_type(&parse_quote!(Array<Vec3>)).unwrap(),
            Ty::Array(Box::new(Ty::Vector(Scalar::F32, 3)), 1)
        );
        assert_eq!(
            parse_type(&parse_quote!(wp::Array<u32, 3>)).unwrap(),
            Ty::Array(Box::new(Ty::Scalar(Scalar::U32)), 3)
        );
        assert_eq!(
            parse_type(&parse_quote!(Params)).unwrap(),
            Ty::Struct("Params".into())
        );
        assert_eq!(
            parse_type(&parse_quote!(wp::HashGrid)).unwrap(),
            Ty::Object(ObjectKind::HashGrid)
        );
        assert_eq!(
            parse_type(&parse_quote!(Volume<glam::Vec3>)).unwrap(),
            Ty::Object(ObjectKind::Volume(VolumeElem::Vec3))
        );
        assert_eq!(
            parse_type(&parse_quote!(wp::Volume<wp::VoxelIndex>)).unwrap(),
            Ty::Object(ObjectKind::Volume(VolumeElem::Index))
        );
        assert_eq!(
            parse_type(&parse_quote!(wp::Bsr<glam::Mat3>)).unwrap(),
            Ty::Object(ObjectKind::Bsr(BlockElem {
                scalar: Scalar::F32,
                rows: 3,
                cols: 3
            }))
        );
        assert_eq!(
            parse_type(&parse_quote!(Bsr<f64>)).unwrap().to_string(),
            "Bsr<f64>"
        );
        for bad in [
            quote::quote!(Bsr),
            quote::quote!(Bsr<Vec3>),
            quote::quote!(Bsr<i32>),
            quote::quote!(Bsr<SpatialMatrix>),
            quote::quote!(Bsr<f32, f32>),
        ] {
            let t: Type = syn::parse2(bad.clone()).unwrap();
            assert!(parse_type(&t).is_err(), "{bad}");
        }
        // Local arrays, nested, of a literal or a const length.
        let t = parse_type(&parse_quote!([[Vec3; 2]; consts::N])).unwrap();
        assert_eq!(t.to_string(), "[[Vec3; 2]; consts::N]");
        for bad in [
            quote::quote!(&f32),
            quote::quote!(String),
            quote::quote!(Vec<f32>),
            quote::quote!([f32]),
            quote::quote!([f32; 0]),
            quote::quote!([f32; n + 1]),
            quote::quote!([HashGrid; 2]),
            quote::quote!(Array<[f32; 2]>),
            quote::quote!(Array<f32, 5>),
            quote::quote!(Array<bool>),
            quote::quote!(Option<f32>),
            quote::quote!(Array<HashGrid>),
            quote::quote!(HashGrid<f32>),
            quote::quote!(Volume),
            quote::quote!(Volume<u8>),
            quote::quote!(Volume<f32, f32>),
            quote::quote!(Array<Volume<f32>>),
        ] {
            let t: Type = syn::parse2(bad.clone()).unwrap();
            assert!(parse_type(&t).is_err(), "{bad}");
        }
    }
}

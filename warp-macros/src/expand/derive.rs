//! `#[derive(Struct)]`: a user struct made a kernel type (`Pod`, `Element`, `GradElement`,
//! the adjoint, `KernelArg`) with its C++ definition (`CudaStruct`), field for field; array
//! fields are `wp::local_array_t`, and const lengths are filled in once, at first use.

use super::errors_to_tokens;
use proc_macro2::{Literal, TokenStream};
use quote::{quote, quote_spanned};
use syn::spanned::Spanned;

/// Whether the field `e` of type `t` holds only finite floats: an array field (`[f32; 4]`,
/// `[[Vec3; 2]; 3]`) element by element.
fn field_finite(t: &syn::Type, e: TokenStream) -> TokenStream {
    match t {
        syn::Type::Array(a) => {
            let inner = field_finite(&a.elem, quote!((*__e)));
            quote!(#e.iter().all(|__e| #inner))
        }
        syn::Type::Paren(p) => field_finite(&p.elem, e),
        _ => quote!(<#t as __wp::Element>::is_finite_value(&#e)),
    }
}

/// The field `e` of type `t` as text: an array field as `[a, b, ..]`.
fn field_describe(t: &syn::Type, e: TokenStream) -> TokenStream {
    match t {
        syn::Type::Array(a) => {
            let inner = field_describe(&a.elem, quote!((*__e)));
            quote!(::std::format!(
                "[{}]",
                #e.iter().map(|__e| #inner).collect::<::std::vec::Vec<_>>().join(", ")
            ))
        }
        syn::Type::Paren(p) => field_describe(&p.elem, e),
        _ => quote!(<#t as __wp::Element>::describe(&#e)),
    }
}

/// `#[derive(Struct)]`.
pub fn derive_struct(item: TokenStream) -> TokenStream {
    let wp = crate::paths::private();
    let input: syn::DeriveInput = match syn::parse2(item) {
        Ok(i) => i,
        Err(e) => return e.to_compile_error(),
    };
    let name = &input.ident;
    let syn::Data::Struct(data) = &input.data else {
        return syn::Error::new(input.span(), "#[derive(Struct)] is for structs")
            .to_compile_error();
    };
    if !input.generics.params.is_empty() {
        return syn::Error::new(
            input.generics.span(),
            "kernel structs cannot be generic yet",
        )
        .to_compile_error();
    }
    let repr_c = input.attrs.iter().any(|a| {
        a.path().is_ident("repr")
            && a.parse_args::<syn::Ident>()
                .map(|i| i == "C")
                .unwrap_or(false)
    });
    if !repr_c {
        return syn::Error::new(
            name.span(),
            "kernel structs need #[repr(C)] (the CUDA side must see the same layout)",
        )
        .to_compile_error();
    }
    let mut errors = Vec::new();
    let fields: Vec<&syn::Type> = data.fields.iter().map(|f| &f.ty).collect();
    for t in &fields {
        if let Err(e) = crate::front::signature::parse_type(t) {
            errors.push(e);
        } else if let Ok(crate::types::Ty::Array(..)) = crate::front::signature::parse_type(t) {
            errors.push(syn::Error::new(
                t.span(),
                "arrays cannot be struct fields yet: pass them as kernel parameters",
            ));
        } else if let Ok(crate::types::Ty::Object(k)) = crate::front::signature::parse_type(t) {
            errors.push(syn::Error::new(
                t.span(),
                format!(
                    "a `{}` cannot be a struct field: pass it as a kernel parameter",
                    k.row().name
                ),
            ));
        }
    }
    if !errors.is_empty() {
        return errors_to_tokens(errors);
    }
    let name_str = Literal::string(&name.to_string());
    let mut def = format!("struct {name} {{");
    // The module consts that array fields' lengths name (`[f32; N]`): C++ gets their values
    // when the definition is first used (`cuda_defs`), as kernels get theirs at assembly.
    let mut lengths: Vec<(String, syn::Path)> = Vec::new();
    for f in data.fields.iter() {
        let ty = crate::front::signature::parse_type(&f.ty).expect("checked above");
        let mut t = &ty;
        while let crate::types::Ty::LocalArray(e, n) = t {
            if let crate::types::Dim::Const(p) = n {
                if !lengths.iter().any(|(q, _)| q == p) {
                    lengths.push((p.clone(), syn::parse_str(p).expect("a const path")));
                }
            }
            t = e;
        }
        let cpp = crate::back::cuda::cpp_type(&ty).unwrap_or_else(|| name.to_string());
        let field = f.ident.as_ref().map(|i| i.to_string()).unwrap_or_default();
        def.push_str(&format!(" {cpp} {field};"));
    }
    def.push_str(" };");
    // Adjoint units (`WP_ADJOINT_UNIT`) also get the struct's adjoint helpers, field by field:
    // global overloads (found by argument-dependent lookup from the library's templates) and
    // `wp::` ones (for the qualified calls of generated code). Each field's helper is called
    // qualified: a struct field's global one (its `wp::` forwarder would be a second,
    // equally good candidate), the library's for the others.
    let fields_named: Vec<(String, bool)> = data
        .fields
        .iter()
        .filter_map(|f| {
            let is_struct = matches!(
                crate::front::signature::parse_type(&f.ty),
                Ok(crate::types::Ty::Struct(_))
            );
            f.ident.as_ref().map(|i| (i.to_string(), is_struct))
        })
        .collect();
    let accum: String = fields_named
        .iter()
        .map(|(f, is_struct)| {
            let ns = if *is_struct { "" } else { "wp" };
            format!(" {ns}::adj_accum(a.{f}, v.{f});")
        })
        .collect();
    let grad_add: String = fields_named
        .iter()
        .map(|(f, is_struct)| {
            let ns = if *is_struct { "" } else { "wp::detail" };
            format!(" {ns}::grad_add_p(&p->{f}, v.{f});")
        })
        .collect();
    // A deterministic kernel's adjoint records a gradient's lanes field by field
    // (`wp::det_record_p`, wp_core.h).
    let det_record: String = fields_named
        .iter()
        .map(|(f, is_struct)| {
            let ns = if *is_struct { "" } else { "wp" };
            format!(" {ns}::det_record_p(t, &p->{f}, v.{f}, op, ctx);")
        })
        .collect();
    def.push_str(&format!(
        "\n#ifdef WP_ADJOINT_UNIT\n\
         WP_FN void adj_accum({name}& a, const {name}& v) {{{accum} }}\n\
         WP_FN void grad_add_p({name}* p, const {name}& v) {{{grad_add} }}\n\
         WP_FN void det_record_p(wp::det_thread_t* t, {name}* p, const {name}& v, wp::u8 op, wp::ctx_t* ctx) {{{det_record} }}\n\
         namespace wp {{\n\
         WP_FN void adj_accum(::{name}& a, const ::{name}& v) {{ ::adj_accum(a, v); }}\n\
         WP_FN ::{name} zero_like(const ::{name}&) {{ return ::{name}{{}}; }}\n\
         template <> WP_FN ::{name} adj_zero<::{name}>() {{ return ::{name}{{}}; }}\n\
         }}\n\
         #endif"
    ));
    let cuda_def = Literal::string(&def);
    // Fields of user struct types: their definitions come first.
    let nested: Vec<&syn::Type> = fields
        .iter()
        .copied()
        .filter(|t| {
            matches!(
                crate::front::signature::parse_type(t),
                Ok(crate::types::Ty::Struct(_))
            )
        })
        .collect();
    let members: Vec<syn::Member> = data
        .fields
        .iter()
        .enumerate()
        .map(|(k, f)| match &f.ident {
            Some(i) => syn::Member::Named(i.clone()),
            None => syn::Member::Unnamed(syn::Index::from(k)),
        })
        .collect();
    let field_asserts = fields
        .iter()
        .map(|t| quote_spanned!(t.span()=> __assert_pod::<#t>();));
    let finite = fields
        .iter()
        .zip(&members)
        .map(|(t, m)| field_finite(t, quote!(self.#m)));
    let describe = fields
        .iter()
        .zip(&members)
        .map(|(t, m)| field_describe(t, quote!(self.#m)));
    let own_def = if lengths.is_empty() {
        quote!(Self::CUDA_DEF)
    } else {
        let holes = lengths.iter().map(|(name, p)| {
            let hole = format!("@@LEN:{name}@@");
            quote!(.replace(#hole, &::std::string::ToString::to_string(&(#p as usize))))
        });
        quote!({
            static DEF: ::std::sync::OnceLock<&'static str> = ::std::sync::OnceLock::new();
            *DEF.get_or_init(|| {
                // Once per struct and process: the definition lives as long as kernels do.
                let def = Self::CUDA_DEF.to_string() #(#holes)*;
                ::std::boxed::Box::leak(def.into_boxed_str())
            })
        })
    };
    quote! {
        const _: () = {
            use #wp as __wp;
            const fn __assert_pod<T: __wp::bytemuck::Pod>() {}
            const _: () = { #(#field_asserts)* };
            // No padding: the byte image of the struct is exactly its fields.
            const _: () = ::core::assert!(
                ::core::mem::size_of::<#name>() == 0 #( + ::core::mem::size_of::<#fields>() )*,
                "kernel structs must have no padding: reorder the fields or add explicit padding fields"
            );
            // SAFETY: repr(C), every field is Pod (asserted above) and there is no padding.
            unsafe impl __wp::bytemuck::Zeroable for #name {}
            unsafe impl __wp::bytemuck::Pod for #name {}
            impl __wp::Element for #name {
                const TYPE_NAME: &'static str = #name_str;
                fn is_finite_value(&self) -> bool {
                    true #( && #finite )*
                }
                fn describe(&self) -> ::std::string::String {
                    let parts: ::std::vec::Vec<::std::string::String> = ::std::vec![
                        #( #describe ),*
                    ];
                    ::std::format!("{} {{ {} }}", #name_str, parts.join(", "))
                }
            }
            impl __wp::GradElement for #name {
                unsafe fn grad_add(p: *mut Self, v: Self) {
                    // SAFETY: field by field, forwarded contract (p is live and aligned).
                    #( unsafe { <#fields as __wp::GradElement>::grad_add(::core::ptr::addr_of_mut!((*p).#members), v.#members) }; )*
                }
            }
            impl __wp::adjoint::Adjoint for #name {
                fn adj_zero() -> Self {
                    <Self as __wp::bytemuck::Zeroable>::zeroed()
                }
                fn adj_accum(&mut self, v: Self) {
                    #( <#fields as __wp::adjoint::Adjoint>::adj_accum(&mut self.#members, v.#members); )*
                }
            }
            impl __wp::CudaStruct for #name {
                const CUDA_DEF: &'static str = #cuda_def;
                fn cuda_defs(out: &mut ::std::vec::Vec<&'static str>) {
                    #( <#nested as __wp::CudaStruct>::cuda_defs(out); )*
                    let def: &'static str = #own_def;
                    if !out.contains(&def) {
                        out.push(def);
                    }
                }
            }
            impl __wp::KernelArg for #name {
                type Arg<'a> = #name;
                type CpuView = #name;
                unsafe fn cpu_view(arg: &Self::Arg<'_>, _ctx: &__wp::ArgCtx<'_>) -> __wp::Result<Self::CpuView> {
                    ::core::result::Result::Ok(*arg)
                }
                type CudaArg = #name;
                fn cuda_arg(arg: &Self::Arg<'_>, _ctx: &__wp::ArgCtx<'_>) -> __wp::Result<Self::CudaArg> {
                    ::core::result::Result::Ok(*arg)
                }
                type GradView = ();
                unsafe fn grad_view(_: &Self::Arg<'_>, _: &__wp::ArgCtx<'_>) -> __wp::Result<()> {
                    ::core::result::Result::Ok(())
                }
                type CudaGrad = ();
                fn cuda_grad(_: &Self::Arg<'_>, _: &__wp::ArgCtx<'_>) -> __wp::Result<()> {
                    ::core::result::Result::Ok(())
                }
                type Owned = #name;
                fn own(arg: &Self::Arg<'_>) -> #name {
                    *arg
                }
                fn borrow(owned: &#name) -> #name {
                    *owned
                }
            }
        };
    }
}

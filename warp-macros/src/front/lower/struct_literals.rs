//! Struct literals: `Particle { x: p, v: Vec3::ZERO, m: 1.0 }`, with field init shorthand
//! (`Particle { x, v, m }`), nested literals and functional update (`Particle { m: 2.0, ..q }`),
//! lowered to one `Op::Construct` of `Ctor::Fields`. The macro cannot see a struct's fields:
//! rustc checks them (missing, unknown, repeated, their types) on the CPU code the literal is
//! printed as, at `cargo build`; an unsuffixed literal value takes its field's type there and in
//! C++ (the literal rule's "the place it is assigned to").

use super::typing::flex_literal;
use super::*;

impl Lowerer {
    /// `Path { field: value, .., ..base }`.
    pub(super) fn struct_literal(&mut self, s: &syn::ExprStruct, span: Span) -> R<VarId> {
        if let Some(q) = &s.qself {
            return err(
                q.lt_token.span,
                "qualified paths are not supported in kernels",
            );
        }
        let last = s.path.segments.last().expect("a path has a segment");
        if !matches!(last.arguments, syn::PathArguments::None) {
            return err(
                last.arguments.span(),
                "kernel structs are not generic: write the struct's name without arguments",
            );
        }
        let name = last.ident.to_string();
        if let Some(t) = Ty::from_glam_name(&name) {
            return err(
                s.path.span(),
                format!("`{t}` is built with its constructor in kernels (`Vec3::new(x, y, z)`)"),
            );
        }
        if s.rest.is_none() && s.dot2_token.is_some() {
            return err(s.dot2_token.span(), "`..` needs a base value: `..base`");
        }
        let (mut names, mut args) = (Vec::new(), Vec::new());
        for f in &s.fields {
            let syn::Member::Named(m) = &f.member else {
                return err(
                    f.member.span(),
                    "tuple structs are not kernel structs: name the fields",
                );
            };
            // An unsuffixed literal is typed by its field, which only the target compilers see.
            let want = flex_literal(&f.expr).map(|_| Ty::Deferred);
            let v = self.expr(&f.expr, want.as_ref())?;
            self.field_value(v, f.expr.span())?;
            names.push(m.clone());
            args.push(v);
        }
        let base = match &s.rest {
            Some(b) => {
                let v = self.expr(b, None)?;
                let t = self.ty(v);
                if !matches!(t, Ty::Struct(_) | Ty::Deferred) {
                    return err(
                        b.span(),
                        format!("`..{t}` is no struct to copy fields from"),
                    );
                }
                args.push(v);
                true
            }
            None => false,
        };
        let ty = Ty::Struct(name);
        let ctor = Ctor::Fields {
            path: s.path.clone(),
            names,
            base,
        };
        Ok(self.def(
            Op::Construct {
                ty: ty.clone(),
                ctor,
                args,
            },
            ty,
            span,
        ))
    }

    /// A field's value is a value (arrays, views and host objects are not struct fields).
    fn field_value(&self, v: VarId, span: Span) -> R<()> {
        match self.ty(v) {
            t @ (Ty::Array(..) | Ty::Object(_) | Ty::Tile(..) | Ty::Tuple(_) | Ty::TidTuple(_)) => {
                err(span, format!("`{t}` cannot be a struct field"))
            }
            Ty::Unit => err(span, "`()` cannot be a struct field"),
            _ if self.is_view(v) => err(span, "a view cannot be a struct field"),
            _ => Ok(()),
        }
    }
}

//! The macro's options against the lowered signature: `#[kernel(same_shape(a, b, dim))]`
//! names array parameters (or `dim`, the launch dimensions), `#[func(grad(x = dfdx))]` names
//! value parameters (an array's gradient comes from its accesses).

use super::Options;
use crate::ir::Function;
use crate::types::Ty;

/// Checks `options` against `f`; returns the kernel's `same_shape` groups as parameter
/// indices (`usize::MAX` for `dim`).
pub(super) fn check(
    f: &Function,
    options: &Options,
    errors: &mut Vec<syn::Error>,
) -> Vec<Vec<usize>> {
    let param = |name: &syn::Ident| f.params.iter().position(|p| name == &p.name);
    match options {
        Options::Kernel { same_shape } => same_shape
            .iter()
            .map(|group| {
                let mut idx = Vec::new();
                for name in group {
                    if name == "dim" {
                        idx.push(usize::MAX);
                    } else if let Some(i) = param(name) {
                        if !matches!(f.params[i].ty, Ty::Array(..)) {
                            errors.push(syn::Error::new(
                                name.span(),
                                format!("`{name}` is not an array parameter"),
                            ));
                        }
                        idx.push(i);
                    } else {
                        errors.push(syn::Error::new(
                            name.span(),
                            format!("no parameter named `{name}`"),
                        ));
                    }
                }
                idx
            })
            .collect(),
        Options::Func { grad } => {
            for (name, _) in grad.iter() {
                match param(name) {
                    None => errors.push(syn::Error::new(
                        name.span(),
                        format!("`{name}` is not a parameter of this func"),
                    )),
                    Some(k) if matches!(f.params[k].ty, Ty::Array(..)) => {
                        errors.push(syn::Error::new(
                            name.span(),
                            "custom gradients are for value parameters; an array's gradient \
                             comes from the accesses",
                        ))
                    }
                    Some(_) => {}
                }
            }
            Vec::new()
        }
    }
}

//! The builtin table: one row per builtin, holding every fact about it.
//!
//! A row gives the builtin's name, which types its type variable `T` may take, its signature
//! in terms of `T`, the section of the CUDA builtin library it needs and how reverse mode
//! differentiates it, then each fact in which it differs from the defaults: forward mode's
//! rule (every row with a gradient states one, or that it has none), method syntax
//! (`v.dot(w)`) and Rust's method aliases (`x.powf(y)`), glam's constructor spelling
//! (`Quat::from_axis_angle`), Warp's overload by arity it is (`min(v)`), Warp's keyword
//! default, how a random draw advances the generator state, the names of a tuple result,
//! whether user code may name it, whether it is an extension of Warp's set, and whether it
//! reaches the emitters as a call or as something else (`mod` is `%`). The CPU function is
//! `warp_core::builtins::<name>`, the CUDA one `wp::<name>`. Adding a builtin is one row in
//! its section's file under `rows/` plus the two implementations and their tests, and its
//! line in docs/book/src/builtins.md, which a test holds to this table (`doc` below).
//!
//! - `row`: the row's facts ([`Builtin`]) and the builder the rows are written with;
//! - `signature`: the signature's vocabulary ([`Class`], [`Pos`]), a leaf; `matcher`: the matcher
//!   ([`Builtin::resolve`]);
//! - `tangent`: the vocabulary of forward mode's rules ([`Tangent`]);
//! - `rows`: the rows, by section, and [`BUILTINS`].

mod matcher;
mod row;
mod rows;
mod signature;
mod tangent;

pub use matcher::ArgTy;
pub use row::{Builtin, Draw, Emit, Grad};
pub use rows::BUILTINS;
pub use signature::{Class, Pos};
pub use tangent::{Dx, Pick, Tangent};

use crate::types::Ty;

/// Looks a builtin up by name (internal rows included).
pub fn lookup(name: &str) -> Option<&'static Builtin> {
    BUILTINS.iter().find(|b| b.name == name)
}

/// Looks up a builtin that user code may call by name (not an internal row).
pub fn lookup_user(name: &str) -> Option<&'static Builtin> {
    lookup(name).filter(|b| !b.internal)
}

/// Looks a builtin up by method name (aliases included).
pub fn lookup_method(name: &str) -> Option<&'static Builtin> {
    match BUILTINS.iter().find(|b| b.aliases.contains(&name)) {
        Some(b) => Some(b),
        None => lookup(name).filter(|b| b.method),
    }
}

/// The row a call of Warp's `name` with `arity` arguments is, where that overload is a row of
/// its own (`min(v)` is `min_element`, `lower_bound(a, lo, hi, v)` is `lower_bound_range`).
pub fn lookup_overload(name: &str, arity: usize) -> Option<&'static Builtin> {
    BUILTINS.iter().find(|b| b.overload == Some((name, arity)))
}

/// The builtin that glam's constructor `ty::f(..)` is (`Quat::from_axis_angle`).
pub fn lookup_ctor(ty: &Ty, f: &str) -> Option<&'static Builtin> {
    BUILTINS
        .iter()
        .find(|b| matches!(b.ctor, Some((class, g)) if g == f && class.admits(ty)))
}
#[cfg(test)]
mod tests;

#[cfg(test)]
mod doc;

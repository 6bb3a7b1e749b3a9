//! How generated code names the facade: the one place its crate name is spelled.
//!
//! Everything the macros emit reaches the runtime through `::warp_lang::__private` (re-exports
//! whose paths may move without breaking user crates). The macro crate does not depend on the
//! facade, it only writes its name into the code it generates, so the name is built here from
//! a string rather than written as a path in every `quote!`: one fact in one place, and the
//! seam a `#[kernel(crate = ..)]` option would change (as serde's `#[serde(crate = ..)]`).

use proc_macro2::{Ident, Span, TokenStream};
use quote::quote_spanned;

/// The facade crate's name as user crates see it.
const FACADE: &str = "warp_lang";

/// `::warp_lang::__private`, the module generated code takes every runtime item from.
pub fn private() -> TokenStream {
    private_at(Span::call_site())
}

/// The same path with every token at `span`: code generated at a user's span (a const's use,
/// a func's name) reports a trait bound there, not at the attribute.
pub fn private_at(span: Span) -> TokenStream {
    let facade = Ident::new(FACADE, span);
    quote_spanned!(span=> ::#facade::__private)
}

/// Whether `name` is a path segment that names the facade (`wp` is the alias the docs use:
/// `use warp_lang as wp`), so that `wp::dot` and `warp_lang::dot` resolve like `dot`.
pub fn names_facade(name: &str) -> bool {
    name == "wp" || name == FACADE
}

#[cfg(test)]
mod tests {
    #[test]
    fn private_path() {
        assert_eq!(super::private().to_string(), ":: warp_lang :: __private");
        assert!(super::names_facade("wp") && super::names_facade("warp_lang"));
        assert!(!super::names_facade("glam"));
    }
}

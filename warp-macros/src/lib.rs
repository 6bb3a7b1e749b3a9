//! The macros of warp-lang: `#[kernel]`, `#[func]` and `#[derive(Struct)]`.
//!
//! Pipeline (see ARCHITECTURE.md): `front` parses the function with syn and lowers it to the
//! IR in `ir`, checking the language subset and the type rules (`types`, `builtins`) and
//! gathering every error with its span; `back` emits code from the IR. The IR, the type rules
//! and the builtin table are plain modules with unit tests that need no macro expansion.
//!
//! Use these through the `warp-lang` facade (`#[wp::kernel]`), which re-exports them; the
//! generated code refers to `::warp_lang::__private`.

use proc_macro::TokenStream;

mod adjoint_prep;
mod analysis;
mod back;
mod builtins;
mod expand;
mod front;
mod ir;
mod types;

/// Turns a Rust function into a kernel: a unit struct of the same name implementing
/// `warp_lang::Kernel`, launched with `wp::launch(name, dim, (args..), &device)`.
///
/// Options: `#[kernel(same_shape(a, b, dim))]` makes the launch check that the named array
/// parameters (and `dim`, the launch dimensions) have equal shapes;
/// `#[kernel(enable_backward = false)]` generates no adjoint (backward through the kernel is
/// then an error).
#[proc_macro_attribute]
pub fn kernel(attr: TokenStream, item: TokenStream) -> TokenStream {
    expand::kernel(attr.into(), item.into()).into()
}

/// Turns a Rust function into a func callable from kernels and other funcs.
///
/// Option: `#[func(grad(x = dfdx, ..))]` replaces the generated adjoint with custom gradients:
/// `dfdx` is a `#[func]` taking this func's parameters followed by the adjoint of its result,
/// and returning the adjoint of `x`; value parameters not listed get no gradient.
#[proc_macro_attribute]
pub fn func(attr: TokenStream, item: TokenStream) -> TokenStream {
    expand::func(attr.into(), item.into()).into()
}

/// Makes a `#[repr(C)]`, `Copy` struct of plain fields usable as a kernel argument and as an
/// array element.
#[proc_macro_derive(Struct)]
pub fn derive_struct(item: TokenStream) -> TokenStream {
    expand::derive_struct(item.into()).into()
}

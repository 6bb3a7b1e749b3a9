//! The macros of warp-lang: `#[kernel]`, `#[func]` and `#[derive(Struct)]`.
//!
//! Pipeline (see ARCHITECTURE.md): `front` parses the function with syn and lowers it to the
//! IR in `ir`, checking the language subset and the type rules (`types`, `builtins`) and
//! gathering every error with its span; `valid` checks the lowered function as a whole (what
//! no single expression decides: definitions before uses, uniform control flow around
//! cooperative calls, the options against the signature) and says which target capabilities
//! it needs; `middle` transforms the IR for reverse mode (the adjoint IR); `back` emits code
//! from the IR and prints the adjoint IR. The IR, the type
//! rules and the builtin table are plain modules with unit tests that need no macro expansion.
//!
//! Use these through the `warp-lang` facade (`#[wp::kernel]`), which re-exports them; the
//! generated code refers to `::warp_lang::__private`.

use proc_macro::TokenStream;

mod analysis;
mod back;
mod builtins;
mod expand;
mod front;
mod ir;
#[cfg(test)]
#[path = "tests/library_sections.rs"]
mod library_sections;
mod middle;
mod operators;
mod paths;
#[cfg(test)]
mod proptests;
#[cfg(test)]
mod test_support;
mod types;
mod valid;

/// Turns a Rust function into a kernel: a unit struct of the same name implementing
/// `warp_lang::Kernel`, launched with `wp::launch(name, dim, (args..), &device)`.
///
/// Options: `#[kernel(same_shape(a, b, dim))]` makes the launch check that the named array
/// parameters (and `dim`, the launch dimensions) have equal shapes;
/// `#[kernel(enable_backward = false)]` generates no adjoint (backward through the kernel is
/// then an error).
///
/// Generic kernels: `fn k<T: Float>(x: Array<Vec3<T>>, s: T)` is instantiated for f32 and f64
/// (`Vec3<T>` is `Vec3` or `DVec3`; likewise `Vec2`, `Vec4`, `Mat2`..`Mat4`, `Quat`), and
/// `wp::launch(k, ..)` runs the instance the arguments' types select. Each type parameter must
/// appear in a parameter's type.
#[proc_macro_attribute]
pub fn kernel(attr: TokenStream, item: TokenStream) -> TokenStream {
    expand::kernel(attr.into(), item.into()).into()
}

/// Turns a Rust function into a func callable from kernels and other funcs.
///
/// Option: `#[func(grad(x = dfdx, ..))]` replaces the generated adjoint with custom gradients:
/// `dfdx` is a `#[func]` taking this func's parameters followed by the adjoint of its result,
/// and returning the adjoint of `x`; value parameters not listed get no gradient.
///
/// Generic funcs (`fn f<T: Float>(v: Vec3<T>) -> T`) are instantiated like generic kernels;
/// a call `f(v)` runs the instance whose parameter types the arguments have, `f::<f32>(v)`
/// names one (`f::<T>(v)` in generic code).
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

/// The items of `wp::overloads!(name)`: the set's type and its `wp::grad` companion's. Not
/// part of the API.
#[doc(hidden)]
#[proc_macro]
pub fn __overload_set(input: TokenStream) -> TokenStream {
    expand::overload_set(input.into()).into()
}

/// Calls the macro named by its input with every row of the object table, one
/// `(Name, param|state, elem|plain, RustView, "wp::cpp_t", "section")` per kind: how the
/// suite's `host_objects` test holds each row to its `HostObject` impl, its adjoint
/// placeholder and its C++ header, so that the host-object recipe cannot drift from the
/// table. Not part of the API.
#[doc(hidden)]
#[proc_macro]
pub fn __object_rows(callback: TokenStream) -> TokenStream {
    types::object_rows_callback(callback.into()).into()
}

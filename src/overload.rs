//! How a call names its func from its arguments' types (`score(x)` for `score::<f32>(x)`).
//!
//! A kernel's call `name(a, b)` is generated as `Callee<name, (A, B)>::__wp_cpu(a, b)`, `A` and
//! `B` the arguments' types as far as the macro can tell them (`_` where it cannot: rustc
//! fills it in when one candidate fits). Each `#[func]` says which funcs a type and an
//! argument tuple resolve to: a plain func is itself for any arguments; an overload set
//! (`wp::overloads!(name)`) and a generic func, named without type arguments, are the overload
//! or instance whose parameter types the arguments have; named with them (`name::<i32>`), the
//! overload of that first parameter type, or the named instance. The emitted code then uses
//! the resolved func's items as if its path had been written, so the CPU code, the CUDA
//! callee list and the compile-time checks all follow rustc's resolution.

/// The type argument of an overload set or a generic func named without one (`score`, the
/// type `score<Unresolved>`): the set itself, which [`Resolve`] maps to a member by the
/// arguments' types.
#[derive(Clone, Copy, Debug)]
pub struct Unresolved;

/// The func that a call of `Self` with arguments of types `A` (a tuple) runs.
#[diagnostic::on_unimplemented(
    message = "no func `{Self}` takes arguments of types `{A}`",
    label = "no overload or instance of this func takes these argument types",
    note = "an overload set (`wp::overloads!`) or a generic func is picked by the types of all its arguments; an unsuffixed literal fits any numeric type (suffix it, `1.0f32`, when several overloads would take it)"
)]
pub trait Resolve<A> {
    /// The func's unit struct (an overload `score<f32, (i32,)>`, an instance `cube<f64>`).
    type Callee;
}

/// The func a call resolves to: `Callee<score, (f32,)>::__wp_cpu(x)`.
pub type Callee<F, A> = <F as Resolve<A>>::Callee;

/// A func's result type (its CPU code's, `&mut` parameters' final values included), so that
/// a call's result can key the resolution of another call (`score(half(x))`).
pub trait FuncRet {
    type Ret;
}

/// The result type of func `F`.
pub type RetOf<F> = <F as FuncRet>::Ret;

/// Nothing, when `F` takes arguments of types `A`. A kernel calls it (in a `const`) for each
/// call whose argument types it could not all tell: when several overloads fit, rustc's
/// "type annotations needed" error here, at the call, lists them.
pub const fn resolves<F: Resolve<A>, A>() {}

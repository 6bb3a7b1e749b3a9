//! Static descriptions of funcs that generated code records, for the CUDA back end.

/// A `#[func]` as the CUDA assembler sees it.
#[derive(Debug)]
pub struct FuncInfo {
    /// The func's name.
    pub name: &'static str,
    /// `module_path!()` at the definition.
    pub module: &'static str,
    /// `file!()` at the definition (for `#line` directives).
    pub file: &'static str,
    /// The CUDA C++ template (`@@SELF@@`, `@@F<k>@@`, `@@FILE@@` placeholders).
    pub cuda: &'static str,
    /// The C++ return type (what `@@R<k>@@` placeholders of callers become).
    pub cuda_ret: &'static str,
    /// CUDA library sections the func uses.
    pub sections: &'static [&'static str],
    /// The funcs it calls, in the order of the `@@F<k>@@` placeholders.
    pub callees: &'static [&'static FuncInfo],
    /// The user structs its parameters use: each adds its C++ definition, after those of the
    /// structs its fields use, to the list (once).
    pub structs: &'static [StructDefs],
    /// The CUDA C++ templates of its replay (`@@SELF@@_replay`) and adjoint (`@@SELF@@_adj`),
    /// for adjoint translation units; empty when `cuda_adj_error` says why there are none.
    pub cuda_adj: &'static str,
    /// Why the func has no CUDA adjoint.
    pub cuda_adj_error: Option<&'static str>,
    /// The module-level `const`s it reads, in the order of its `@@K<k>@@` placeholders: each
    /// gives the constant's value as a C++ expression (see `CudaConst` in the runtime).
    pub consts: &'static [ConstLiteral],
    /// The capabilities its code (and its adjoint's) needs beyond the core language, by the
    /// macros' validator: a kernel calling it needs them too (see [`crate::capability`]).
    pub requires: &'static [crate::Capability],
    /// Its assertion sites (`assert!`, `debug_assert!`, `expect_*`), by which a GPU fault's
    /// line and column find the message.
    pub asserts: &'static [AssertSite],
    /// Whether it (or a func it calls) uses float `atomic_add`/`atomic_sub`: a
    /// `#[kernel(deterministic)]` kernel cannot record a func's accumulations, so launching
    /// one that calls such a func is refused.
    pub float_atomics: bool,
    /// Whether its CUDA code calls another func's adjoint (`wp::grad(f)(..)`): a unit with
    /// it, forward ones included, gets the adjoint headers and its funcs' `cuda_adj`.
    pub needs_adjoints: bool,
}

/// An assertion in a kernel or func's source. A GPU fault record holds no text: a failed
/// assertion records its line and column, and the host finds the message in the `asserts`
/// table of the kernel or of one of its callees (the CPU builds its fault with the message
/// directly).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AssertSite {
    /// The source line (as the fault reports it).
    pub line: u32,
    /// The column of the assertion's start (tells apart assertions on one line).
    pub column: u32,
    /// The message (see `FaultKind::AssertionFailed`).
    pub message: &'static str,
}

/// The value of a module-level `const` a kernel or func reads, as a C++ expression.
pub type ConstLiteral = fn() -> String;

/// Adds a user struct's C++ definition to a list, after the definitions it depends on, each
/// once (`CudaStruct::cuda_defs` in the runtime).
pub type StructDefs = fn(&mut Vec<&'static str>);

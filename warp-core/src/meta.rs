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
    /// C++ definitions of the user structs its parameters use.
    pub structs: &'static [&'static str],
}

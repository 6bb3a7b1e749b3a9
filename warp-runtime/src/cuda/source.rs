//! Assembles the CUDA translation unit of one kernel from the templates the macro recorded.
//!
//! The kernel's template and its funcs' templates (found through `KernelInfo::callees`,
//! transitively) are concatenated, callees first, with their placeholders filled: each func
//! gets a unique C++ name here (`wpf<k>_<name>`), because funcs of the same name may live in
//! different modules. Only the library sections that these templates use are included, so
//! NVRTC parses no more than the kernel needs: in the order of their rows in
//! `warp_cuda::library::SECTIONS`, and in an adjoint unit the adjoint core and the sections'
//! adjoint parts after them (each part includes its forward section and the parts it builds
//! on).
//!
//! A kernel's first launch under a recording tape (or `load_with_adjoints`) compiles one unit
//! holding both its forward and its adjoint entry ([`assemble_with_adjoint`]): the adjoint
//! unit's text with the kernel's forward template before its adjoint one. Nothing clashes:
//! every name a unit defines at file scope is a func's (`wpf<k>_<name>`, its `_replay` and
//! `_adj`, the same in both halves, each defined once) or the kernel's (`wpk_<name>_thread`
//! and the entry `wpk_<name>`, whose adjoint template appends `_adj` to both). One NVRTC run
//! then parses the library and the funcs once instead of twice.

use crate::kernel::KernelInfo;
use warp_core::FuncInfo;
use warp_cuda::library::{self, SECTIONS};

/// The assembled source of one kernel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CudaSource {
    /// The whole translation unit.
    pub text: String,
    /// The `extern "C"` entry point to look up in the compiled module.
    pub entry: String,
    /// The per-thread function (useful for host-side tests of the generated code).
    pub thread_fn: String,
    /// The library headers it includes, in order (`wp_core.h` first).
    pub headers: Vec<String>,
    /// In a unit of forward and adjoint ([`assemble_with_adjoint`]), the adjoint's names
    /// (`entry` and `thread_fn` are then the forward's); `None` in a unit of one of them.
    pub adjoint: Option<AdjointNames>,
}

/// The adjoint's entry point and per-thread function in a unit that also holds the forward.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AdjointNames {
    /// The `extern "C"` entry point (`wpk_<name>_adj`).
    pub entry: String,
    /// The per-thread function (`wpk_<name>_thread_adj`).
    pub thread_fn: String,
}

/// Which entries a unit holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Halves {
    Forward,
    Adjoint,
    Both,
}

impl Halves {
    /// Whether the unit holds the adjoint (and so the adjoint library and the funcs' replays
    /// and adjoints).
    fn adjoint(self) -> bool {
        self != Halves::Forward
    }
}

/// Funcs reachable from `roots`, callees before callers, each once (keyed by module and name:
/// two references to one `const` need not share an address).
fn collect(roots: &[&'static FuncInfo], out: &mut Vec<&'static FuncInfo>) {
    for f in roots {
        if out.iter().any(|g| g.module == f.module && g.name == f.name) {
            continue;
        }
        collect(f.callees, out);
        out.push(f);
    }
}

/// A name as part of a C identifier: an instance of a generic kernel or func is named
/// `integrate<f32>`, which C++ spells `integrate_f32_`.
fn c_ident(name: &str) -> String {
    name.chars()
        .filter(|c| *c != ' ')
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

fn fill(
    template: &str,
    self_name: &str,
    file: &str,
    callees: &[(String, &str)],
    consts: &[warp_core::ConstLiteral],
) -> String {
    let mut s = template
        .replace("@@SELF@@", self_name)
        .replace("@@FILE@@", file);
    for (k, value) in consts.iter().enumerate() {
        s = s.replace(&format!("@@K{k}@@"), &format!("({})", value()));
    }
    for (k, (name, ret)) in callees.iter().enumerate() {
        s = s
            .replace(&format!("@@F{k}@@"), name)
            .replace(&format!("@@R{k}@@"), ret);
    }
    s
}

/// Builds the translation unit for `info`.
pub fn assemble(info: &KernelInfo) -> CudaSource {
    assemble_unit(info, Halves::Forward)
}

/// Builds the adjoint translation unit for `info`: the adjoint library, every func's forward,
/// replay and adjoint templates, and the kernel's adjoint (entry `wpk_<name>_adj`). Compiled
/// only when backward first runs through the kernel on a GPU whose forward was compiled
/// without it.
pub fn assemble_adjoint(info: &KernelInfo) -> CudaSource {
    assemble_unit(info, Halves::Adjoint)
}

/// Builds one translation unit holding both the forward (`entry`, `thread_fn`) and the
/// adjoint (`adjoint`) of `info`: [`assemble_adjoint`]'s text with the kernel's forward
/// template before its adjoint one (see the module documentation). Compiled with the adjoint
/// unit's options, which change nothing in the forward's code (`WP_ADSTACK_BYTES` is read by
/// the adjoint entry alone, `WP_ADJOINT_UNIT` only adds the user structs' adjoint helpers, and
/// the rounding follows the sections, which both halves share).
pub fn assemble_with_adjoint(info: &KernelInfo) -> CudaSource {
    assemble_unit(info, Halves::Both)
}

fn assemble_unit(info: &KernelInfo, halves: Halves) -> CudaSource {
    let mut funcs = Vec::new();
    collect(info.callees, &mut funcs);
    // A func that evaluates another's gradient in forward code (`wp::grad(f)(..)`) needs the
    // adjoint headers and its callees' adjoints in every unit, forward ones included; the
    // kernel's own adjoint entry stays with the halves asked for.
    let adjoint = halves.adjoint() || funcs.iter().any(|f| f.needs_adjoints);
    let name_of = |f: &FuncInfo| -> String {
        let k = funcs
            .iter()
            .position(|g| g.module == f.module && g.name == f.name)
            .expect("collected");
        format!("wpf{k}_{}", c_ident(f.name))
    };
    let mut sections: Vec<&str> = info.cuda_sections.to_vec();
    for f in &funcs {
        for s in f.sections {
            if !sections.contains(s) {
                sections.push(s);
            }
        }
    }
    // The user structs the kernel and its funcs use. One with a transform field
    // (`wp::Transform` in its C++ definition) needs the transform section even where the
    // kernel never names a transform itself.
    let mut struct_defs: Vec<&str> = Vec::new();
    for defs in funcs.iter().flat_map(|f| f.structs).chain(info.structs) {
        defs(&mut struct_defs);
    }
    if struct_defs
        .iter()
        .any(|d| d.contains("wp::Transform") || d.contains("wp::DTransform"))
        && !sections.contains(&"transform")
    {
        sections.push("transform");
    }
    // Likewise a spatial field (`wp::SpatialVector`, `wp::DSpatialMatrix`, ..) needs the
    // spatial section, whose adjoint part has the operators' adjoints.
    if struct_defs
        .iter()
        .any(|d| d.contains("SpatialVector") || d.contains("SpatialMatrix"))
        && !sections.contains(&"spatial")
    {
        sections.push("spatial");
    }
    // And a non-square matrix field (`wp::Mat23`, `wp::DMat63`, ..) the matrix section.
    if struct_defs.iter().any(|d| names_nonsquare(d)) && !sections.contains(&"matrix") {
        sections.push("matrix");
    }
    let used = SECTIONS
        .iter()
        .filter(|s| s.kernel && sections.contains(&s.name));
    let mut headers = vec![library::CORE.name.to_string()];
    headers.extend(used.clone().map(|s| s.header.name.to_string()));
    if adjoint {
        headers.push(library::ADJOINT_CORE.name.to_string());
        for part in used.filter_map(|s| s.adjoint) {
            if !headers.iter().any(|h| h == part.name) {
                headers.push(part.name.to_string());
            }
        }
    }
    // The module path below the crate: a unit's text (so its cache and ahead-of-time keys)
    // must not depend on which crate compiled the kernel's Rust definition, because a build
    // script that includes a crate's kernel file (`examples/prebuilt`) compiles it as
    // `build_script_build::kernels` where the binary has `<crate>::kernels`.
    let path = match info.module.split_once("::") {
        Some((_, below)) => format!("{below}::{}", info.name),
        None => info.name.to_string(),
    };
    let mut text = format!("// warp-lang kernel `{path}` ({})\n", info.file);
    if adjoint {
        // User structs add their adjoint helpers (see `derive(Struct)`).
        text.push_str("#define WP_ADJOINT_UNIT 1\n");
    }
    for h in &headers {
        text.push_str(&format!("#include \"{h}\"\n"));
    }
    // User structs (gathered above), each once, in the order first met (callees first), a
    // struct after those its fields use.
    for def in struct_defs {
        text.push_str(def);
        text.push('\n');
    }
    for f in &funcs {
        let callees: Vec<(String, &str)> =
            f.callees.iter().map(|c| (name_of(c), c.cuda_ret)).collect();
        text.push('\n');
        text.push_str(&fill(f.cuda, &name_of(f), f.file, &callees, f.consts));
        if adjoint {
            text.push_str(&fill(f.cuda_adj, &name_of(f), f.file, &callees, f.consts));
        }
    }
    // The names the templates' `@@SELF@@`/`@@ENTRY@@` stand for; the adjoint template appends
    // `_adj` to both.
    let base_self = format!("wpk_{}_thread", c_ident(info.name));
    let base_entry = format!("wpk_{}", c_ident(info.name));
    let callees: Vec<(String, &str)> = info
        .callees
        .iter()
        .map(|c| (name_of(c), c.cuda_ret))
        .collect();
    let kernel = |template: &str| {
        fill(template, &base_self, info.file, &callees, info.consts)
            .replace("@@ENTRY@@", &base_entry)
    };
    if halves != Halves::Adjoint {
        text.push('\n');
        text.push_str(&kernel(info.cuda));
    }
    if halves.adjoint() {
        text.push('\n');
        text.push_str(&kernel(info.cuda_adjoint));
    }
    let adjoint_names = AdjointNames {
        entry: format!("{base_entry}_adj"),
        thread_fn: format!("{base_self}_adj"),
    };
    let (entry, thread_fn, adjoint) = match halves {
        Halves::Forward => (base_entry, base_self, None),
        Halves::Adjoint => (adjoint_names.entry, adjoint_names.thread_fn, None),
        Halves::Both => (base_entry, base_self, Some(adjoint_names)),
    };
    CudaSource {
        text,
        entry,
        thread_fn,
        headers,
        adjoint,
    }
}

/// Whether C++ text names a non-square matrix type: `wp::Mat` or `wp::DMat` and two
/// different digits (`wp::Mat23`; glam's square `wp::Mat3` has one).
fn names_nonsquare(text: &str) -> bool {
    text.match_indices("wp::").any(|(i, _)| {
        let rest = &text[i + 4..];
        let rest = rest.strip_prefix('D').unwrap_or(rest);
        let Some(d) = rest.strip_prefix("Mat") else {
            return false;
        };
        let b = d.as_bytes();
        b.len() >= 2
            && b[0].is_ascii_digit()
            && b[1].is_ascii_digit()
            && b[0] != b[1]
            && !b
                .get(2)
                .is_some_and(|c| c.is_ascii_alphanumeric() || *c == b'_')
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    static LEAF: FuncInfo = FuncInfo {
        name: "sq",
        module: "m::a",
        file: "src/a.rs",
        cuda: "static WP_FN wp::f32 @@SELF@@(wp::f32 x, wp::ctx_t* __ctx) {\n#line 3 \"@@FILE@@\"\n    return x * x;\n}\n",
        cuda_ret: "wp::f32",
        sections: &[],
        callees: &[],
        structs: &[],
        cuda_adj: "",
        cuda_adj_error: None,
        consts: &[],
        requires: &[],
        asserts: &[],
        float_atomics: false,
        needs_adjoints: false,
    };
    // A func of the same name in another module.
    static OTHER_SQ: FuncInfo = FuncInfo {
        name: "sq",
        module: "m::b",
        file: "src/b.rs",
        cuda: "static WP_FN wp::f32 @@SELF@@(wp::f32 x, wp::ctx_t* __ctx) { return x; }\n",
        cuda_ret: "wp::f32",
        sections: &["scalar"],
        callees: &[],
        structs: &[],
        cuda_adj: "",
        cuda_adj_error: None,
        consts: &[],
        requires: &[],
        asserts: &[],
        float_atomics: false,
        needs_adjoints: false,
    };
    static MID: FuncInfo = FuncInfo {
        name: "both",
        module: "m::a",
        file: "src/a.rs",
        cuda: "static WP_FN wp::f32 @@SELF@@(wp::f32 x, wp::ctx_t* __ctx) { return @@F0@@(x, __ctx) + @@F1@@(x, __ctx); }\n",
        cuda_ret: "wp::f32",
        sections: &[],
        callees: &[&LEAF, &OTHER_SQ],
        structs: &[],
        cuda_adj: "",
        cuda_adj_error: None,
        consts: &[],
        requires: &[],
        asserts: &[],
        float_atomics: false,
        needs_adjoints: false,
    };

    static KERNEL_CALLEES: [&FuncInfo; 2] = [&MID, &LEAF];

    #[test]
    fn funcs_are_named_ordered_and_deduplicated() {
        let info = KernelInfo {
            name: "k",
            module: "m",
            file: "src/k.rs",
            cuda: "static WP_FN void @@SELF@@(wp::ctx_t* __ctx) { @@F0@@(1.0f, __ctx); @@F1@@(2.0f, __ctx); }\nvoid @@ENTRY@@() {}\n",
            cuda_sections: &["vector"],
            callees: &KERNEL_CALLEES,
            ..KernelInfo::BLANK
        };
        let src = assemble(&info);
        assert_eq!(src.headers, vec!["wp_core.h", "wp_scalar.h", "wp_vector.h"]);
        let t = &src.text;
        // Callees before callers, each once; same-named funcs get different names.
        let leaf = t.find("wp::f32 wpf0_sq(").expect("leaf");
        let other = t.find("wp::f32 wpf1_sq(").expect("other sq");
        let mid = t.find("wp::f32 wpf2_both(").expect("mid");
        assert!(leaf < mid && other < mid, "{t}");
        assert_eq!(t.matches("wpf0_sq(wp::f32").count(), 1, "{t}");
        assert!(
            t.contains("return wpf0_sq(x, __ctx) + wpf1_sq(x, __ctx);"),
            "{t}"
        );
        assert!(t.contains("void wpk_k_thread(wp::ctx_t* __ctx) { wpf2_both(1.0f, __ctx); wpf0_sq(2.0f, __ctx); }"), "{t}");
        assert!(t.contains("void wpk_k() {}"), "{t}");
        assert!(t.contains("#line 3 \"src/a.rs\""), "{t}");
        assert_eq!(src.entry, "wpk_k");
        // The adjoint unit: the adjoint core and the parts of the sections used (the funcs'
        // "scalar" and the kernel's "vector" share one part), nothing of linalg and beyond.
        let adj = assemble_adjoint(&info);
        assert_eq!(
            adj.headers,
            vec![
                "wp_core.h",
                "wp_scalar.h",
                "wp_vector.h",
                "wp_adjoint_core.h",
                "wp_adjoint_builtins.h"
            ]
        );
    }

    /// A unit of forward and adjoint is the adjoint unit with the kernel's forward template
    /// before its adjoint one: the same headers and defines, each func once, both entries; the
    /// units of one half keep their text (their cache and ahead-of-time keys).
    #[test]
    fn a_unit_of_both_halves_holds_each_name_once() {
        let info = KernelInfo {
            name: "k",
            module: "m",
            file: "src/k.rs",
            cuda: "static WP_FN void @@SELF@@(wp::ctx_t* __ctx) { @@F0@@(1.0f, __ctx); }\nvoid @@ENTRY@@() {}\n",
            cuda_adjoint: "static WP_FN void @@SELF@@_adj(wp::ctx_t* __ctx) { @@F1@@(2.0f, __ctx); }\nvoid @@ENTRY@@_adj() {}\n",
            cuda_sections: &["vector"],
            callees: &KERNEL_CALLEES,
            ..KernelInfo::BLANK
        };
        let (fwd, adj, both) = (
            assemble(&info),
            assemble_adjoint(&info),
            assemble_with_adjoint(&info),
        );
        assert_eq!(both.headers, adj.headers);
        assert_eq!(
            (both.entry.as_str(), both.thread_fn.as_str()),
            ("wpk_k", "wpk_k_thread")
        );
        assert_eq!(
            both.adjoint,
            Some(AdjointNames {
                entry: "wpk_k_adj".into(),
                thread_fn: "wpk_k_thread_adj".into()
            })
        );
        assert_eq!((fwd.adjoint.as_ref(), adj.adjoint.as_ref()), (None, None));
        assert_eq!(
            (adj.entry.as_str(), adj.thread_fn.as_str()),
            ("wpk_k_adj", "wpk_k_thread_adj")
        );
        // The adjoint unit's text, the forward template spliced in before the adjoint's.
        let forward =
            "void wpk_k_thread(wp::ctx_t* __ctx) { wpf2_both(1.0f, __ctx); }\nvoid wpk_k() {}\n";
        let at = adj
            .text
            .find("\nstatic WP_FN void wpk_k_thread_adj")
            .expect("adjoint");
        assert_eq!(
            both.text,
            format!(
                "{}\nstatic WP_FN {forward}{}",
                &adj.text[..at],
                &adj.text[at..]
            )
        );
        assert!(both.text.starts_with(&adj.text[..at]));
        assert!(both.text.contains("#define WP_ADJOINT_UNIT 1"));
        for name in [
            "wpf0_sq(",
            "wpf1_sq(",
            "wpf2_both(",
            "wpk_k_thread(",
            "wpk_k(",
            "wpk_k_adj(",
        ] {
            assert_eq!(
                both.text.matches(&format!("void {name}")).count()
                    + both.text.matches(&format!("wp::f32 {name}")).count(),
                1,
                "{name} defined once in:\n{}",
                both.text
            );
        }
        // Forward and adjoint units alone are what they were (same text, so same keys).
        assert!(
            fwd.text.ends_with(&format!("\nstatic WP_FN {forward}")),
            "{}",
            fwd.text
        );
        assert!(!fwd.text.contains("wpk_k_adj"));
    }

    /// The unit does not depend on the crate that compiled the kernel (a build script that
    /// includes the kernel's file names it `build_script_build::...`), only on the module below
    /// it, the file and the templates.
    #[test]
    fn unit_text_does_not_name_the_crate() {
        let info = |module| KernelInfo {
            name: "k",
            module,
            file: "src/kernels.rs",
            cuda: "static WP_FN void @@SELF@@(wp::ctx_t* __ctx) {}\nvoid @@ENTRY@@() {}\n",
            ..KernelInfo::BLANK
        };
        let (bin, build) = (info("my_app::kernels"), info("build_script_build::kernels"));
        assert_eq!(assemble(&bin), assemble(&build));
        assert_eq!(assemble_adjoint(&bin), assemble_adjoint(&build));
        assert!(assemble(&bin)
            .text
            .starts_with("// warp-lang kernel `kernels::k` (src/kernels.rs)\n"));
        assert_ne!(assemble(&bin), assemble(&info("my_app::other")));
        // A kernel at the crate's root.
        assert!(assemble(&info("my_app"))
            .text
            .starts_with("// warp-lang kernel `k` (src/kernels.rs)\n"));
    }

    /// A unit includes the sections it uses in the table's order, whatever order the
    /// templates name them in, and an adjoint unit the parts of those that have one (a shared
    /// part once); a section with no part (`bvh`) adds none.
    #[test]
    fn sections_are_included_in_table_order() {
        let info = KernelInfo {
            name: "k",
            module: "m",
            file: "src/k.rs",
            cuda: "static WP_FN void @@SELF@@(wp::ctx_t* __ctx) {}\nvoid @@ENTRY@@() {}\n",
            cuda_sections: &["mesh", "vector", "bvh", "scalar", "rand"],
            ..KernelInfo::BLANK
        };
        assert_eq!(
            assemble(&info).headers,
            vec![
                "wp_core.h",
                "wp_scalar.h",
                "wp_vector.h",
                "wp_rand.h",
                "wp_bvh.h",
                "wp_mesh.h"
            ]
        );
        assert_eq!(
            assemble_adjoint(&info).headers[6..],
            [
                "wp_adjoint_core.h",
                "wp_adjoint_builtins.h",
                "wp_adjoint_rand.h",
                "wp_adjoint_mesh.h"
            ]
        );
    }

    #[test]
    fn struct_fields_of_nonsquare_matrices_are_found() {
        assert!(names_nonsquare("struct S { wp::Mat23 j; wp::f32 w; };"));
        assert!(names_nonsquare("wp::DMat63 m;"));
        assert!(!names_nonsquare("struct S { wp::Mat3 m; wp::DMat4 n; };"));
        assert!(!names_nonsquare(
            "wp::Mat33 m; wp::Mat23_ZERO(); wp::Vec3 v;"
        ));
        assert!(!names_nonsquare("Mat23 m;"));
    }
}

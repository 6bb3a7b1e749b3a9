//! The CUDA library's sections: one row per header of `cuda/`, from which every list that names
//! sections is derived.
//!
//! A section `s` is the header `wp_<s>.h`. Its row says everything the crates need to know of
//! it: whether kernel units include it (and where, by the row's place: [`SECTIONS`] is in include
//! order), the part of the adjoint library for it, how units that include it must round
//! ([`Exact`]), and whether it is also compiled on its own as a host object's build library.
//! Derived from the rows: [`HEADERS`] (what NVRTC is handed), the include order and the adjoint
//! parts of a kernel unit (warp-runtime's `cuda/source.rs`), the rounding of a unit
//! ([`exact_for`]), and the build libraries (warp-runtime's `objects::build_libraries`).
//!
//! The names the builtin table and the object kinds use (warp-macros) are checked against the
//! rows by a test there (`library_sections`), since a proc-macro crate cannot depend on this one.
//!
//! Adding a section: the header under `cuda/`, its row here (and, for builtins, the table's rows
//! that name it). The tests below check that every header on disk is embedded, that each header
//! includes only what comes before it, and the rounding decision.

/// A library header: its file name under `warp-cuda/cuda/` and its text, embedded so that NVRTC
/// can be handed it in memory.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// The file name, as `#include` names it (`wp_scalar.h`).
    pub name: &'static str,
    /// The header's text.
    pub text: &'static str,
}

/// The [`Header`] of a file under `cuda/`, embedded.
macro_rules! header {
    ($file:literal) => {
        Header {
            name: $file,
            text: include_str!(concat!("../cuda/", $file)),
        }
    };
}

/// How a translation unit must be compiled, from the sections it includes: the strictest
/// of its sections' rows ([`exact_for`]).
///
/// The geometry queries and the volume samples round as the CPU's do: with FMA contraction a
/// ray through a mesh vertex can miss both faces the CPU finds it on (a box's slab bounds or a
/// triangle's edge function rounded otherwise), and a volume's trilinear sample differs from
/// the CPU's in its last bit, so their units are compiled without contraction, whatever the
/// runtime's `cuda_fmad` setting says: the results are bit for bit the CPU's. (Measured on an
/// H100: contraction made `mesh_query_point_no_sign` 2% faster, 44.9 against 45.9 ms for 1M
/// queries; the queries are bound by memory latency.)
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Exact {
    /// FMA contraction as the runtime's setting says.
    No,
    /// No contraction.
    Yes,
    /// No contraction, and at most 64 registers a thread (the mesh queries): four blocks of
    /// 256 threads per SM instead of three (NVRTC gave the mesh queries 70 to 92), which hides
    /// more of the traversals' memory latency. Measured on an H100, 1M queries:
    /// `mesh_query_point_no_sign` 45.9 -> 42.0 ms, signed 93.8 -> 82.4, `mesh_query_ray` 2.48
    /// -> 2.23 (a cap of 56 spilled and was slower); again on an H200 (2026-11-30, without the
    /// cap: no_sign 44.6 against 41.7 ms, ray 2.37 against 2.17). The `Bvh` queries alone run
    /// better without it (1M `bvh_query_aabb` 3.67 against 4.11 ms, H200), so only the mesh
    /// section asks for it.
    WithRegisterCap,
}

impl Exact {
    /// Whether the unit may contract multiplies and adds into FMAs, given the runtime's
    /// setting `configured`.
    pub fn fmad(self, configured: bool) -> bool {
        configured && self == Exact::No
    }

    /// The NVRTC options it adds to a unit's (the register cap).
    pub fn extra_options(self) -> &'static [&'static str] {
        match self {
            Exact::WithRegisterCap => &["--maxrregcount=64"],
            Exact::No | Exact::Yes => &[],
        }
    }
}

/// One section of the CUDA library.
#[derive(Clone, Copy, Debug)]
pub struct Section {
    /// The name the builtin table uses (`"scalar"`); the header is `wp_<name>.h`.
    pub name: &'static str,
    /// `wp_<name>.h`, embedded.
    pub header: Header,
    /// Whether kernel units include it: those whose builtins or types name the section
    /// (the builtin table's rows, the object kinds), in the order of [`SECTIONS`]. A section
    /// that is not one (a build library alone, the primitives) is only compiled on its own.
    pub kernel: bool,
    /// The adjoint library's part for this section, which an adjoint unit includes when the
    /// kernel or its funcs use the section (`None`: the section has no adjoints). Each part
    /// includes its forward section and the parts it builds on; two sections may share one.
    pub adjoint: Option<Header>,
    /// How a unit that includes the section (or its adjoint part) must round.
    pub exact: Exact,
    /// The define that enables the header's build kernels, if it is a host object's build
    /// library (compiled on its own as `#define <define> 1` and the header's `#include`, the
    /// first time a GPU runs one of the object's build steps).
    pub build: Option<&'static str>,
}

impl Section {
    /// This row, also compiled on its own with `define` as a build library.
    const fn with_build(self, define: &'static str) -> Self {
        Section {
            build: Some(define),
            ..self
        }
    }

    /// The build library's program name (its NVRTC name and cache key): the define in lower
    /// case (`wp_hash_grid_build`).
    pub fn build_name(&self) -> Option<String> {
        self.build.map(str::to_ascii_lowercase)
    }

    /// The build library's translation unit: the define and the header's `#include`.
    pub fn build_source(&self) -> Option<String> {
        self.build
            .map(|d| format!("#define {d} 1\n#include \"{}\"\n", self.header.name))
    }

    /// The headers a unit compiled on its own from this section needs (a build library, a
    /// primitives module): the core, the standalone sections above it whose headers this
    /// one includes (the sparse operations include the sparse steps' header), and this
    /// section's.
    pub fn standalone_headers(&self) -> Vec<(&'static str, &'static str)> {
        let mut out = vec![(CORE.name, CORE.text)];
        out.extend(
            SECTIONS
                .iter()
                .filter(|s| {
                    !s.kernel
                        && s.name != self.name
                        && self
                            .header
                            .text
                            .contains(&format!("#include \"{}\"", s.header.name))
                })
                .map(|s| (s.header.name, s.header.text)),
        );
        out.push((self.header.name, self.header.text));
        out
    }
}

/// The core every unit includes first: the scalar types, the thread context, arrays.
pub const CORE: Header = header!("wp_core.h");

/// The part of the adjoint library every adjoint unit includes: zero and accumulation, lanes,
/// operators, casts, array gradients, the per-thread stack.
pub const ADJOINT_CORE: Header = header!("wp_adjoint_core.h");

/// The adjoint library's umbrella (the core and the math sections' parts), for host tests and
/// hand-written code; no generated unit includes it.
pub const ADJOINT_ALL: Header = header!("wp_adjoint.h");

/// The adjoint part that the scalar and vector sections share.
const ADJOINT_BUILTINS: Header = header!("wp_adjoint_builtins.h");

/// A kernel section's row: `wp_<name>.h`, its adjoint part, its rounding ([`Exact`]).
macro_rules! kernel {
    ($name:literal, $adjoint:expr, $exact:ident) => {
        Section {
            name: $name,
            header: Header {
                name: concat!("wp_", $name, ".h"),
                text: include_str!(concat!("../cuda/wp_", $name, ".h")),
            },
            kernel: true,
            adjoint: $adjoint,
            exact: Exact::$exact,
            build: None,
        }
    };
}

/// A standalone section's row: `wp_<name>.h`, the define of its build library if it is one.
macro_rules! standalone {
    ($name:literal, $build:expr) => {
        Section {
            name: $name,
            header: Header {
                name: concat!("wp_", $name, ".h"),
                text: include_str!(concat!("../cuda/wp_", $name, ".h")),
            },
            kernel: false,
            adjoint: None,
            exact: Exact::No,
            build: $build,
        }
    };
}

/// The sections, kernel sections first, in include order (each header includes only the core
/// and sections above it: a test checks it).
#[rustfmt::skip]
pub static SECTIONS: &[Section] = &[
    // Kernel sections: name, adjoint part, rounding (and the hash grid's build library).
    kernel!("scalar",    Some(ADJOINT_BUILTINS),                  No),
    kernel!("vector",    Some(ADJOINT_BUILTINS),                  No),
    kernel!("linalg",    Some(header!("wp_adjoint_linalg.h")),    No),
    kernel!("svd",       Some(header!("wp_adjoint_svd.h")),       No),
    kernel!("transform", Some(header!("wp_adjoint_transform.h")), No),
    kernel!("spatial",   Some(header!("wp_adjoint_spatial.h")),   No),
    // The non-square matrices (their types too: only units that use them parse them).
    kernel!("matrix",    Some(header!("wp_adjoint_matrix.h")),    No),
    kernel!("misc",      Some(header!("wp_adjoint_misc.h")),      No),
    kernel!("atomic",    None,                                    No),
    kernel!("rand",      Some(header!("wp_adjoint_rand.h")),      No),
    kernel!("hash_grid", None,                                    No).with_build("WP_HASH_GRID_BUILD"),
    kernel!("geometry",  Some(header!("wp_adjoint_geometry.h")),  Yes),
    kernel!("bvh",       None,                                    Yes),
    kernel!("mesh",      Some(header!("wp_adjoint_mesh.h")),      WithRegisterCap),
    kernel!("volume",    Some(header!("wp_adjoint_volume.h")),    Yes),
    // Sparse matrices in kernels (the sparse tier's Bsr<B>): loads, stores and atomic adds,
    // no arithmetic of their own to round.
    kernel!("bsr",       Some(header!("wp_adjoint_bsr.h")),       No),
    kernel!("print",     None,                                    No),
    // Tiles (docs: the tiles chapter): exact, so that elementwise results match the CPU.
    kernel!("tile",      Some(header!("wp_adjoint_tile.h")),      Yes),
    // The tile Cholesky factor and triangular solves: exact too, so that they match warp-core's
    // tile::linalg bit for bit (its order of roundings; tests/cuda_tile_linalg_host.rs).
    kernel!("tile_linalg", Some(header!("wp_adjoint_tile_linalg.h")), Yes),
    // The tile sort: comparisons and moves only, so nothing to round (bitonic, in shared memory).
    kernel!("tile_sort", None,                                    No),
    // The f16 tile matmul on tensor cores (its FMA fallback bit-exact with the CPU).
    kernel!("tile_mma",  None,                                    Yes),
    // The tile FFTs: exact, so that they match warp-core's tile::fft bit for bit (its order of
    // roundings; tests/cuda_tile_fft_host.rs).
    kernel!("tile_fft",  None,                                    Yes),
    // Compiled on their own: name, the define of a host object's build library.
    standalone!("bvh_build",      Some("WP_BVH_BUILD")),
    standalone!("marching_cubes", Some("WP_MARCHING_CUBES_BUILD")),
    standalone!("volume_build",   Some("WP_VOLUME_BUILD")),
    // The sparse tier's steps (warp-runtime's `sparse` feature): exact by spelling (`sp_add`..).
    standalone!("sparse",         Some("WP_SPARSE_BUILD")),
    // Its structure operations (transpose, products, dense), a library of their own that
    // includes wp_sparse.h (its helpers and records, not its kernels).
    standalone!("sparse_ops",     Some("WP_SPARSE_OPS_BUILD")),
    // Its graph colouring (adjacency, Jones-Plassmann rounds): integer steps, a library of its
    // own that includes wp_sparse.h and wp_sparse_ops.h (helpers and records).
    standalone!("sparse_color",   Some("WP_SPARSE_COLOR_BUILD")),
    standalone!("primitives",     None),
];

/// The section named `name`. In a constant (`const P: &Section = get("primitives")`) a name
/// that is no row fails the build.
///
/// # Panics
/// When no row is named `name` (at compile time where it is evaluated as a constant).
pub const fn get(name: &str) -> &'static Section {
    match find(name) {
        Some(s) => s,
        None => panic!("no section of the CUDA library has this name"),
    }
}

/// The section named `name`, if there is one.
pub const fn find(name: &str) -> Option<&'static Section> {
    let mut i = 0;
    while i < SECTIONS.len() {
        if str_eq(SECTIONS[i].name, name) {
            return Some(&SECTIONS[i]);
        }
        i += 1;
    }
    None
}

/// How a unit including `headers` (file names) must be compiled: the strictest [`Exact`] of
/// the sections whose header or adjoint part it includes.
pub fn exact_for<S: AsRef<str>>(headers: &[S]) -> Exact {
    SECTIONS
        .iter()
        .filter(|s| {
            headers.iter().any(|h| {
                let h = h.as_ref();
                h == s.header.name || s.adjoint.is_some_and(|a| a.name == h)
            })
        })
        .map(|s| s.exact)
        .max()
        .unwrap_or(Exact::No)
}

/// `a == b`, in a constant.
const fn str_eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// Whether row `i`'s adjoint part is named by no row above it (a shared part is listed once).
const fn first_use_of_part(i: usize) -> bool {
    let Some(part) = SECTIONS[i].adjoint else {
        return false;
    };
    let mut j = 0;
    while j < i {
        if let Some(p) = SECTIONS[j].adjoint {
            if str_eq(p.name, part.name) {
                return false;
            }
        }
        j += 1;
    }
    true
}

/// The count of [`HEADERS`].
const fn header_count() -> usize {
    let mut n = 3; // the core, the adjoint core, the adjoint umbrella
    let mut i = 0;
    while i < SECTIONS.len() {
        n += 1;
        if first_use_of_part(i) {
            n += 1;
        }
        i += 1;
    }
    n
}

/// [`HEADERS`], gathered from the rows: the core, each section's header, the adjoint core,
/// each adjoint part once, the adjoint umbrella.
const fn gather_headers<const N: usize>() -> [(&'static str, &'static str); N] {
    let mut out = [("", ""); N];
    out[0] = (CORE.name, CORE.text);
    let mut n = 1;
    let mut i = 0;
    while i < SECTIONS.len() {
        out[n] = (SECTIONS[i].header.name, SECTIONS[i].header.text);
        n += 1;
        i += 1;
    }
    out[n] = (ADJOINT_CORE.name, ADJOINT_CORE.text);
    n += 1;
    i = 0;
    while i < SECTIONS.len() {
        if first_use_of_part(i) {
            if let Some(p) = SECTIONS[i].adjoint {
                out[n] = (p.name, p.text);
                n += 1;
            }
        }
        i += 1;
    }
    out[n] = (ADJOINT_ALL.name, ADJOINT_ALL.text);
    out
}

const HEADER_ARRAY: [(&str, &str); header_count()] = gather_headers();

/// The CUDA library, embedded: `(name, contents)` pairs to hand to NVRTC as in-memory
/// headers, gathered from [`SECTIONS`] (`wp_core.h` first).
pub const HEADERS: &[(&str, &str)] = &HEADER_ARRAY;

#[cfg(test)]
mod tests {
    use super::*;

    /// Every library header on disk is embedded (NVRTC sees only what `HEADERS` hands it, so
    /// a header that is on disk but not embedded would compile on the host and fail on a GPU),
    /// once.
    #[test]
    fn every_header_is_embedded_once() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/cuda");
        let mut on_disk = 0;
        for e in std::fs::read_dir(dir).unwrap() {
            let name = e.unwrap().file_name().into_string().unwrap();
            // `wp.h` is the forward library's umbrella for host tests, which read `cuda/`.
            if name.ends_with(".h") && name != "wp.h" {
                on_disk += 1;
                assert_eq!(
                    HEADERS.iter().filter(|(n, _)| *n == name).count(),
                    1,
                    "{name} is not in warp_cuda::HEADERS once (add its row to library::SECTIONS)"
                );
            }
        }
        assert_eq!(HEADERS.len(), on_disk, "HEADERS names a header twice");
        assert_eq!(HEADERS[0].0, "wp_core.h");
    }

    /// Rows are named after their headers, once each; a standalone row has no adjoint part and
    /// rounds as configured (nothing reads those of it).
    #[test]
    fn rows_are_named_after_their_headers() {
        for (i, s) in SECTIONS.iter().enumerate() {
            assert_eq!(s.header.name, format!("wp_{}.h", s.name));
            assert!(
                SECTIONS[..i].iter().all(|t| t.name != s.name),
                "{} twice",
                s.name
            );
            assert!(std::ptr::eq(get(s.name), s));
            if !s.kernel {
                assert!(s.adjoint.is_none() && s.exact == Exact::No, "{}", s.name);
            }
        }
        // Kernel sections come first: their order is the include order.
        let first_standalone = SECTIONS.iter().position(|s| !s.kernel).unwrap();
        assert!(SECTIONS[first_standalone..].iter().all(|s| !s.kernel));
        assert!(find("no_such_section").is_none());
        assert_eq!(
            get("hash_grid").build_source().unwrap(),
            "#define WP_HASH_GRID_BUILD 1\n#include \"wp_hash_grid.h\"\n"
        );
        assert_eq!(get("hash_grid").build_name().unwrap(), "wp_hash_grid_build");
        assert_eq!(get("scalar").build_source(), None);
    }

    /// The `#include "wp_*.h"` lines of `text`.
    fn includes(text: &str) -> Vec<&str> {
        text.lines()
            .filter_map(|l| l.trim().strip_prefix("#include \""))
            .filter_map(|l| l.split_once('"').map(|(name, _)| name))
            .filter(|n| n.starts_with("wp_"))
            .collect()
    }

    /// The table's order is an include order: a kernel section's header includes only the
    /// core and the sections above it; an adjoint part includes the adjoint core, its section
    /// and parts and sections of rows above; a standalone header only the core, itself and
    /// standalone headers above it; and every header that any embedded header includes is
    /// embedded.
    #[test]
    fn the_table_is_in_include_order() {
        for (name, text) in HEADERS {
            for inc in includes(text) {
                assert!(
                    HEADERS.iter().any(|(n, _)| *n == inc),
                    "{name} includes {inc}, which is not embedded"
                );
            }
        }
        for (i, s) in SECTIONS.iter().enumerate() {
            let above = &SECTIONS[..i];
            for inc in includes(s.header.text) {
                // (A standalone header may build on a standalone one above it: the sparse
                // operations on the sparse steps' helpers.)
                let ok = inc == CORE.name
                    || inc == s.header.name
                    || above
                        .iter()
                        .any(|t| t.kernel == s.kernel && t.header.name == inc);
                assert!(
                    ok,
                    "{} includes {inc}, which is not above it",
                    s.header.name
                );
            }
            if let Some(part) = s.adjoint {
                let incs = includes(part.text);
                assert!(
                    incs.contains(&s.header.name),
                    "{} does not include {}",
                    part.name,
                    s.header.name
                );
                // A shared part is held to the last row that has it.
                let last = SECTIONS
                    .iter()
                    .rposition(|t| t.adjoint == Some(part))
                    .unwrap();
                for inc in incs {
                    let ok = inc == ADJOINT_CORE.name
                        || SECTIONS[..=last].iter().any(|t| {
                            t.header.name == inc || t.adjoint.is_some_and(|p| p.name == inc)
                        });
                    assert!(ok, "{} includes {inc}, which is not above it", part.name);
                }
            }
        }
    }

    #[test]
    fn geometry_and_volume_units_compile_without_contraction() {
        assert_eq!(
            exact_for(&["wp_core.h", "wp_geometry.h", "wp_bvh.h"]),
            Exact::Yes
        );
        assert_eq!(
            exact_for(&["wp_core.h", "wp_geometry.h", "wp_bvh.h", "wp_mesh.h"]),
            Exact::WithRegisterCap
        );
        assert_eq!(
            exact_for(&["wp_core.h", "wp_adjoint_core.h", "wp_adjoint_geometry.h"]),
            Exact::Yes
        );
        assert_eq!(exact_for(&["wp_core.h", "wp_volume.h"]), Exact::Yes);
        assert_eq!(
            exact_for(&["wp_core.h", "wp_hash_grid.h", "wp_vector.h"]),
            Exact::No
        );
        assert_eq!(exact_for::<&str>(&[]), Exact::No);
        assert!(!Exact::Yes.fmad(true) && Exact::No.fmad(true) && !Exact::No.fmad(false));
        assert_eq!(
            Exact::WithRegisterCap.extra_options(),
            &["--maxrregcount=64"]
        );
    }
}

//! The NVRTC options of a kernel translation unit.

use crate::config;
use warp_cuda::CompileOptions;

/// The library headers whose queries must round as the CPU's do: with FMA contraction a
/// ray through a mesh vertex can miss both faces the CPU finds it on (a box's slab bounds or
/// a triangle's edge function rounded otherwise), and a volume's trilinear sample differs
/// from the CPU's in its last bit, so a unit that includes one of them is compiled without
/// contraction, whatever `config::cuda_fmad` says: the geometry queries and the volume
/// samples are bit for bit the CPU's. (Measured on an H100: contraction made
/// `mesh_query_point_no_sign` 2% faster, 44.9 against 45.9 ms for 1M queries; the queries
/// are bound by memory latency.)
const EXACT_HEADERS: [&str; 7] = [
    "wp_geometry.h",
    "wp_bvh.h",
    "wp_mesh.h",
    "wp_volume.h",
    "wp_adjoint_geometry.h",
    "wp_adjoint_mesh.h",
    "wp_adjoint_volume.h",
];

/// The headers of the tree traversals, whose units are also capped in registers (see
/// [`with_compile_options`]).
const TRAVERSAL_HEADERS: [&str; 2] = ["wp_bvh.h", "wp_mesh.h"];

/// How a unit rounds and what it may use: from the library headers it includes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Exact {
    /// FMA contraction as `config::cuda_fmad` says.
    No,
    /// No contraction.
    Yes,
    /// No contraction, and at most 64 registers a thread (the BVH traversals).
    WithRegisterCap,
}

/// The [`Exact`] of a unit including `headers`.
pub(crate) fn needs_exact(headers: &[String]) -> Exact {
    let has = |list: &[&str]| headers.iter().any(|h| list.contains(&h.as_str()));
    if has(&TRAVERSAL_HEADERS) {
        Exact::WithRegisterCap
    } else if has(&EXACT_HEADERS) {
        Exact::Yes
    } else {
        Exact::No
    }
}

/// Calls `f` with the NVRTC options of a kernel translation unit (the runtime's and the
/// ahead-of-time compiler's, which must agree for AOT entries to be found).
/// `adstack_bytes`: the per-thread adjoint stack of an adjoint unit; `exact`: no FMA
/// contraction, and for traversals a register cap (see [`needs_exact`]).
pub(crate) fn with_compile_options<R>(
    contiguous: bool,
    adstack_bytes: Option<&str>,
    exact: Exact,
    f: impl FnOnce(&CompileOptions) -> R,
) -> R {
    let headers: Vec<(&str, &str)> = warp_cuda::HEADERS.to_vec();
    let mut defines: Vec<(&str, &str)> = Vec::new();
    if contiguous {
        defines.push(("WP_CONTIGUOUS", "1"));
    }
    if let Some(b) = adstack_bytes {
        defines.push(("WP_ADSTACK_BYTES", b));
    }
    let defines = &defines[..];
    // Geometry units are capped at 64 registers a thread: four blocks of 256 threads per SM
    // instead of three (NVRTC gave the mesh queries 70 to 92), which hides more of the
    // traversals' memory latency. Measured on an H100, 1M queries: mesh_query_point_no_sign
    // 45.9 -> 42.0 ms, signed 93.8 -> 82.4, mesh_query_ray 2.48 -> 2.23 (a cap of 56 spilled
    // and was slower).
    // (NVRTC's automatic precompiled headers, `-pch`, were tried for the autodiff example's six
    // variants on an H100: 1.34 s of NVRTC against 0.90 s without; they are not used.)
    let extra: &[&str] = if exact == Exact::WithRegisterCap {
        &["--maxrregcount=64"]
    } else {
        &[]
    };
    f(&CompileOptions {
        fmad: config::cuda_fmad() && exact == Exact::No,
        line_info: true,
        defines,
        headers: &headers,
        extra_options: extra,
        ..Default::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn geometry_and_volume_units_compile_without_contraction() {
        let h = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            needs_exact(&h(&["wp_core.h", "wp_geometry.h", "wp_bvh.h"])),
            Exact::WithRegisterCap
        );
        assert_eq!(
            needs_exact(&h(&["wp_core.h", "wp_adjoint_core.h", "wp_adjoint_mesh.h"])),
            Exact::Yes
        );
        assert_eq!(needs_exact(&h(&["wp_core.h", "wp_volume.h"])), Exact::Yes);
        assert_eq!(
            needs_exact(&h(&["wp_core.h", "wp_hash_grid.h", "wp_vector.h"])),
            Exact::No
        );
    }
}

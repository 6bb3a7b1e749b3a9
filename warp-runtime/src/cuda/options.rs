//! The NVRTC options of a kernel translation unit.

use crate::config;
use warp_cuda::CompileOptions;

/// How a unit rounds and what it may use: the strictest of its sections' rows
/// (`warp_cuda::library::SECTIONS`, whose [`Exact`] says why the geometry and volume units
/// are compiled without FMA contraction and the traversals with a register cap).
pub(crate) use warp_cuda::library::Exact;

/// The [`Exact`] of a unit including `headers`.
pub(crate) fn needs_exact(headers: &[String]) -> Exact {
    warp_cuda::library::exact_for(headers)
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
    // (NVRTC's automatic precompiled headers, `-pch`, were tried for the autodiff example's six
    // variants on an H100: 1.34 s of NVRTC against 0.90 s without; they are not used.)
    f(&CompileOptions {
        fmad: exact.fmad(config::cuda_fmad()),
        line_info: true,
        defines,
        headers: &headers,
        extra_options: exact.extra_options(),
        ..Default::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A unit's headers decide its rounding through their sections' rows (the rows' own
    /// decision is tested in warp-cuda).
    #[test]
    fn geometry_and_volume_units_compile_without_contraction() {
        let h = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            needs_exact(&h(&["wp_core.h", "wp_geometry.h", "wp_bvh.h"])),
            Exact::WithRegisterCap
        );
        assert_eq!(
            needs_exact(&h(&[
                "wp_core.h",
                "wp_adjoint_core.h",
                "wp_adjoint_volume.h"
            ])),
            Exact::Yes
        );
        assert_eq!(needs_exact(&h(&["wp_core.h", "wp_volume.h"])), Exact::Yes);
        assert_eq!(
            needs_exact(&h(&["wp_core.h", "wp_hash_grid.h", "wp_vector.h"])),
            Exact::No
        );
    }
}

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
/// contraction, and for traversals a register cap (see [`needs_exact`]); `tile`: a tiled
/// kernel's variant, its block size and the dynamic shared memory a block takes
/// (`WP_TILE_BLOCK_DIM`, `WP_TILE_SMEM_BYTES`). Defines are part of the options every cache
/// key hashes, so each block size is its own cubin in the kernel cache and the AOT directory.
pub(crate) fn with_compile_options<R>(
    contiguous: bool,
    adstack_bytes: Option<&str>,
    exact: Exact,
    tile: Option<TileDefines>,
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
    let tile = tile.map(|t| {
        (
            t.block_dim.to_string(),
            t.shared_bytes.to_string(),
            (t.pipe_extra > 0).then(|| t.pipe_extra.to_string()),
        )
    });
    if let Some((bd, smem, extra)) = &tile {
        defines.push(("WP_TILE_BLOCK_DIM", bd));
        defines.push(("WP_TILE_SMEM_BYTES", smem));
        if let Some(extra) = extra {
            defines.push(("WP_TILE_PIPE_EXTRA", extra));
        }
    }
    let defines = &defines[..];
    // (NVRTC's automatic precompiled headers, `-pch`, were tried for the autodiff example's six
    // variants on an H100: 1.34 s of NVRTC against 0.90 s without; they are not used.)
    f(&CompileOptions {
        fmad: exact.fmad(config::cuda_fmad()),
        line_info: config::cuda_line_info(),
        defines,
        headers: &headers,
        extra_options: exact.extra_options(),
        ..Default::default()
    })
}

/// The defines of a tiled kernel's unit: its launch's block size, the shared memory one
/// block of the unit (forward or adjoint) takes, and of it the pipelined GEMM loops' extra at
/// its end (`module::tile_shared`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct TileDefines {
    pub(crate) block_dim: usize,
    pub(crate) shared_bytes: usize,
    pub(crate) pipe_extra: usize,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A tiled unit's block size and shared memory are defines, so they are part of every
    /// cache key (each block size its own cubin); other units have neither.
    #[test]
    fn tiled_units_define_their_block_size() {
        let defines = |tile| {
            with_compile_options(true, None, Exact::No, tile, |o| {
                o.defines
                    .iter()
                    .map(|(k, v)| format!("{k}={v}"))
                    .collect::<Vec<_>>()
            })
        };
        assert_eq!(defines(None), vec!["WP_CONTIGUOUS=1"]);
        let tile = |block_dim| TileDefines {
            block_dim,
            shared_bytes: 2048,
            pipe_extra: 0,
        };
        assert_eq!(
            defines(Some(tile(64))),
            vec![
                "WP_CONTIGUOUS=1",
                "WP_TILE_BLOCK_DIM=64",
                "WP_TILE_SMEM_BYTES=2048"
            ]
        );
        assert_ne!(defines(Some(tile(64))), defines(Some(tile(128))));
        // The pipelined GEMM loops' extra shared memory, where the runtime grants it.
        let extra = TileDefines {
            shared_bytes: 3072,
            pipe_extra: 1024,
            ..tile(64)
        };
        assert_eq!(
            defines(Some(extra))[1..],
            [
                "WP_TILE_BLOCK_DIM=64",
                "WP_TILE_SMEM_BYTES=3072",
                "WP_TILE_PIPE_EXTRA=1024"
            ]
        );
        // The keys of the kernel cache and the AOT directory hash the options.
        let key = |tile| {
            with_compile_options(true, None, Exact::No, tile, |o| {
                warp_cuda::aot_key("extern \"C\" __global__ void k() {}", "k", o, 90)
            })
        };
        assert_ne!(key(Some(tile(64))), key(Some(tile(128))));
        assert_ne!(key(None), key(Some(tile(64))));
    }

    /// `-lineinfo` follows `config::set_cuda_line_info`, and the setting is part of the cache
    /// keys (a cubin built with line tables is not found without them). Restores the setting.
    #[test]
    fn line_tables_follow_the_setting_and_are_keyed() {
        let before = config::cuda_line_info();
        let at = |on: bool| {
            config::set_cuda_line_info(on);
            with_compile_options(true, None, Exact::No, None, |o| {
                let args = o.nvrtc_args(90);
                let key = warp_cuda::aot_key("extern \"C\" __global__ void k() {}", "k", o, 90);
                (args.iter().any(|a| a == "-lineinfo"), key)
            })
        };
        let (off, key_off) = at(false);
        let (on, key_on) = at(true);
        config::set_cuda_line_info(before);
        assert!(!off && on);
        assert_ne!(key_off, key_on);
    }

    /// A unit's headers decide its rounding through their sections' rows (the rows' own
    /// decision is tested in warp-cuda).
    #[test]
    fn geometry_and_volume_units_compile_without_contraction() {
        let h = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert_eq!(
            needs_exact(&h(&["wp_core.h", "wp_geometry.h", "wp_bvh.h"])),
            Exact::Yes
        );
        assert_eq!(
            needs_exact(&h(&["wp_core.h", "wp_geometry.h", "wp_bvh.h", "wp_mesh.h"])),
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

//! Ahead-of-time compilation: cubins built before the program runs (from a build script, or a
//! packaging step), so that no kernel is compiled at first launch and the running machine
//! needs no NVRTC.
//!
//! [`compile`] runs NVRTC (no GPU needed: only `libnvrtc`) for each kernel, each listed
//! architecture and both variants the runtime may launch (arrays all contiguous, or not),
//! and writes the cubins to a directory. At run time, when that directory is named by
//! [`set_aot_dir`] or `WARP_LANG_AOT_DIR`, a first launch looks there before the kernel
//! cache and before NVRTC. Entries are keyed by the generated source, the compile options
//! (including `config::cuda_fmad`, which must be the same at both times) and the architecture;
//! one that is missing or damaged falls back to the ordinary path. Entries are authenticated
//! as the kernel cache's (see `warp_cuda::cache`): ship the directory whole, its `key` file
//! included, or every entry counts as missing; the directory must be owned by the user who
//! runs the program (or root) and not writable by group or others. [`compile_with_adjoints`]
//! also compiles the adjoint units (for programs that run backward), and [`verify`] says,
//! without a GPU, whether a directory holds every entry a program will look for.
//!
//! Which cubin a GPU takes: the one of its own architecture, else one of a lower
//! architecture of the same major version (an `sm_80` cubin on an `sm_86` GPU: CUDA runs
//! SASS on any GPU of the same major version and an equal or higher minor one), the highest
//! such; else none (an `sm_90` cubin never runs on an `sm_100` GPU), and the launch compiles
//! through the kernel cache and NVRTC as without a directory. The directory is looked at
//! before the kernel cache, so a compatible lower-architecture cubin wins over an exact one
//! compiled earlier into the cache (a program shipped with cubins never needs NVRTC).
//!
//! From a build script (`examples/prebuilt` is a whole crate doing this). A build script can
//! only call code it is compiled with: the kernels live in a crate that is also a
//! build-dependency, or in a file the build script includes with `#[path]` (a unit's text
//! names the module below the crate and the file, never the crate, so both sides compute the
//! same keys):
//! ```ignore
//! // build.rs (needs NVRTC on the build machine, not a GPU; warp-lang is a build-dependency)
//! use warp_lang as wp;
//! #[path = "src/kernels.rs"]
//! mod kernels;
//! let dir = std::path::PathBuf::from(std::env::var("OUT_DIR").unwrap()).join("cubins");
//! println!("cargo:rustc-env=MY_AOT_DIR={}", dir.display());
//! // WARP_LANG_AOT_ARCHS=90,80 (H100/H200 and A100), else DEFAULT_ARCHS.
//! let archs = wp::aot::archs_from_env().unwrap();
//! let kernels = [wp::aot::kernel(kernels::integrate)]; // generic: wp::aot::instances(axpy)
//! if let Err(e) = wp::aot::compile_with_adjoints(&kernels, &archs, &dir) {
//!     // No NVRTC here: the program compiles at first launch instead.
//!     println!("cargo:warning=kernels not compiled at build time: {e}");
//! }
//! ```
//! and at start-up: `wp::aot::set_aot_dir(Some(env!("MY_AOT_DIR").into()))`. The suite's
//! `ahead_of_time_compile` and `ahead_of_time_adjoints` tests exercise this (they skip,
//! saying so, without NVRTC).

use super::options::{needs_exact, with_compile_options};
use super::source;
use super::source::CudaSource;
use crate::error::{Error, Result};
use crate::kernel::{GenericKernel, Kernel, KernelInfo};
use std::path::{Path, PathBuf};
use warp_cuda::{CacheLookup, CompileOptions, KernelCache};

// The directory setting is the config layer's (the device layer reads it to pick the preferred
// device without importing the CUDA backend); re-exported here, where users look for it.
pub use crate::config::{aot_dir, set_aot_dir, AOT_DIR_ENV};

/// The static description of a kernel, for [`compile`]: `wp::aot::kernel(integrate)`.
pub fn kernel<K: Kernel>(kernel: K) -> &'static KernelInfo {
    crate::kernel::kernel_info(kernel)
}

/// The static descriptions of every instance of a generic kernel, for [`compile`]:
/// `wp::aot::instances(integrate)` gives `integrate<f32>` and `integrate<f64>`.
pub fn instances<G: GenericKernel>(kernel: G) -> Vec<&'static KernelInfo> {
    let _ = kernel;
    G::instances()
}

/// One cubin written by [`compile`].
#[derive(Clone, Debug)]
pub struct AotEntry {
    /// The kernel.
    pub kernel: &'static str,
    /// The architecture (major * 10 + minor).
    pub arch: u32,
    /// Whether this is the variant for launches whose arrays are all contiguous.
    pub contiguous: bool,
    /// Whether this is the kernel's adjoint.
    pub adjoint: bool,
    /// Where it was written.
    pub path: PathBuf,
    /// NVRTC time.
    pub compile_ms: f64,
}

/// Compiles `kernels` for every architecture in `archs` (both launch variants each) into
/// `dir`, creating it, and returns the entries in the order kernel, architecture, variant
/// (contiguous first). Needs NVRTC, not a GPU. The compiles run one after the other, about
/// 150-350 ms each on a Xeon core; a forward and its adjoint are separate units here (a
/// program may launch the forward without a tape), which the runtime takes before compiling
/// them as one.
///
/// # Errors
/// [`Error::Cuda`] (device `"nvrtc"`) when NVRTC is missing, does not support one of `archs`
/// (said before anything is compiled, with the architectures it supports), or fails on a
/// kernel, or when `dir` cannot be written.
pub fn compile(
    kernels: &[&'static KernelInfo],
    archs: &[u32],
    dir: &Path,
) -> Result<Vec<AotEntry>> {
    compile_units(kernels, archs, dir, false)
}

/// [`compile`], and each kernel's adjoint unit too (both variants, with the adjoint stack
/// [`config::adstack_bytes`](crate::config::adstack_bytes) sets, which must be the same when
/// the program runs backward, as the runtime's default is), for programs that differentiate:
/// their first backward pass then compiles nothing either.
///
/// # Errors
/// As [`compile`].
pub fn compile_with_adjoints(
    kernels: &[&'static KernelInfo],
    archs: &[u32],
    dir: &Path,
) -> Result<Vec<AotEntry>> {
    compile_units(kernels, archs, dir, true)
}

/// Environment variable naming the architectures [`archs_from_env`] returns.
pub const ARCHS_ENV: &str = "WARP_LANG_AOT_ARCHS";

/// The architectures compiled for when `WARP_LANG_AOT_ARCHS` is not set: Turing (75), Ampere
/// (80, 86), Ada (89), Hopper (90) and Blackwell (100, 120), all of which CUDA 13's NVRTC
/// supports (it dropped sm_70 and older). With the same-major rule (see the module
/// documentation) these cover every GPU CUDA 13 runs on but Thor (`sm_110`): an A100 takes
/// the `sm_80` cubins, an RTX 3090 and a Jetson Orin (8.7) the `sm_86` ones, an L40 the `sm_89`
/// ones, an H100 or H200 the `sm_90` ones, a B200 or B300 (10.3) the `sm_100` ones, an RTX
/// 5090 or a DGX Spark (12.1) the `sm_120` ones.
pub const DEFAULT_ARCHS: &[u32] = &[75, 80, 86, 89, 90, 100, 120];

/// The architectures a build script compiles for: `WARP_LANG_AOT_ARCHS` (a comma-separated
/// list such as `90,80`; `sm_90` is read as 90) when set and not empty, else
/// [`DEFAULT_ARCHS`].
///
/// # Errors
/// [`Error::InvalidArgument`] for a list that does not parse.
pub fn archs_from_env() -> Result<Vec<u32>> {
    match std::env::var(ARCHS_ENV) {
        Ok(v) if !v.trim().is_empty() => parse_archs(&v),
        _ => Ok(DEFAULT_ARCHS.to_vec()),
    }
}

/// `"90, sm_80"` -> `[90, 80]`.
fn parse_archs(list: &str) -> Result<Vec<u32>> {
    list.split(',')
        .map(|a| {
            let a = a.trim();
            let digits = a.strip_prefix("sm_").unwrap_or(a);
            match digits.parse::<u32>() {
                Ok(n) if n >= 10 => Ok(n),
                _ => Err(Error::invalid(format!(
                    "{ARCHS_ENV}: \"{a}\" is not an architecture (write 90 or sm_90 for sm_90)"
                ))),
            }
        })
        .collect()
}

/// The architectures whose cubins a GPU of architecture `arch` runs, best first: its own,
/// then the lower ones of its major version (`86` -> 86, 85, .. 80).
pub fn compatible_archs(arch: u32) -> impl Iterator<Item = u32> {
    (arch / 10 * 10..=arch).rev()
}

/// One unit of a kernel: its source and, for an adjoint unit, the adjoint stack define.
type Unit = (&'static KernelInfo, CudaSource, Option<String>);

fn units(kernels: &[&'static KernelInfo], adjoints: bool) -> Vec<Unit> {
    let stack = crate::config::adstack_bytes().to_string();
    let mut out = Vec::new();
    for info in kernels {
        out.push((*info, source::assemble(info), None));
        if adjoints {
            out.push((*info, source::assemble_adjoint(info), Some(stack.clone())));
        }
    }
    out
}

/// Every (unit, architecture, variant) of `kernels`: each kernel's forward unit (then, with
/// `adjoints`, its adjoint unit), for each architecture, contiguous then strided.
fn plan(kernels: &[&'static KernelInfo], archs: &[u32], adjoints: bool) -> Vec<(Unit, u32, bool)> {
    let mut out = Vec::new();
    for unit in units(kernels, adjoints) {
        for &arch in archs {
            for contiguous in [true, false] {
                out.push((unit.clone(), arch, contiguous));
            }
        }
    }
    out
}

fn compile_units(
    kernels: &[&'static KernelInfo],
    archs: &[u32],
    dir: &Path,
    adjoints: bool,
) -> Result<Vec<AotEntry>> {
    let err = |e: warp_cuda::CudaError| Error::cuda("nvrtc", e);
    // Say which architectures this NVRTC lacks before compiling anything.
    let supported = warp_cuda::nvrtc_supported_archs().map_err(err)?;
    let unsupported: Vec<String> = archs
        .iter()
        .filter(|a| !supported.contains(a))
        .map(|a| format!("sm_{a}"))
        .collect();
    if !unsupported.is_empty() {
        let (major, minor) = warp_cuda::nvrtc_version().map_err(err)?;
        return Err(Error::cuda(
            "nvrtc",
            warp_cuda::CudaError::InvalidArgument(format!(
                "NVRTC {major}.{minor} cannot compile for {} (it supports {supported:?}; \
                 {ARCHS_ENV} names the architectures)",
                unsupported.join(", ")
            )),
        ));
    }
    // A tiled kernel's unit needs the block size of its launches, which `compile` is not
    // given: refuse it plainly rather than let NVRTC fail on an undefined WP_TILE_BLOCK_DIM.
    if let Some(info) = kernels.iter().find(|k| k.tile.is_some()) {
        return Err(Error::LaunchKind {
            kernel: info.name,
            why: "a tiled kernel given to `aot::compile`, which does not compile tiled kernels \
                  yet: load it at run time with `load_tiled`"
                .to_string(),
        });
    }
    let cache = KernelCache::new(dir);
    // One after the other: NVRTC compiles one program at a time in a process (measured with
    // NVRTC 13.0 on two cores: two threads took as long as one, each compile twice as long).
    plan(kernels, archs, adjoints)
        .into_iter()
        .map(|((info, src, stack_define), arch, contiguous)| {
            let exact = needs_exact(&src.headers);
            with_compile_options(contiguous, stack_define.as_deref(), exact, None, |opts| {
                let compiled = warp_cuda::compile(&src.text, info.name, opts, arch)?;
                let key = warp_cuda::aot_key(&src.text, info.name, opts, arch);
                let path = cache.store(info.name, key, &compiled.cubin)?;
                Ok(AotEntry {
                    kernel: info.name,
                    arch,
                    contiguous,
                    adjoint: stack_define.is_some(),
                    path,
                    compile_ms: compiled.compile_ms,
                })
            })
            .map_err(err)
        })
        .collect()
}

/// One entry [`verify`] looked for.
#[derive(Clone, Debug)]
pub struct AotCheck {
    /// The kernel.
    pub kernel: &'static str,
    /// The architecture.
    pub arch: u32,
    /// Whether this is the variant for launches whose arrays are all contiguous.
    pub contiguous: bool,
    /// Whether this is the kernel's adjoint.
    pub adjoint: bool,
    /// The file a GPU of this architecture would load.
    pub path: PathBuf,
    /// Whether `path` holds a sound entry.
    pub found: bool,
}

/// Which entries a program launching `kernels` (and with `adjoints` running them backward)
/// on GPUs of `archs` looks for in `dir`, and whether each is there and sound: the keys are
/// computed here as the runtime computes them, so a program can check (without a GPU or
/// NVRTC) that the cubins its build wrote are the ones its launches will find. An entry is
/// found only under its own architecture here (the same-major fallback is the GPU's).
pub fn verify(
    kernels: &[&'static KernelInfo],
    archs: &[u32],
    dir: &Path,
    adjoints: bool,
) -> Vec<AotCheck> {
    let cache = KernelCache::new(dir);
    plan(kernels, archs, adjoints)
        .into_iter()
        .map(|((info, src, stack_define), arch, contiguous)| {
            let exact = needs_exact(&src.headers);
            let key =
                with_compile_options(contiguous, stack_define.as_deref(), exact, None, |opts| {
                    warp_cuda::aot_key(&src.text, info.name, opts, arch)
                });
            AotCheck {
                kernel: info.name,
                arch,
                contiguous,
                adjoint: stack_define.is_some(),
                path: cache.path_for(info.name, key),
                found: matches!(cache.load(info.name, key), CacheLookup::Hit(_)),
            }
        })
        .collect()
}

/// The ahead-of-time cubin for this compile on a GPU of architecture `arch`, with its key and
/// file, when an AOT directory is set and holds a sound entry for it: its own architecture's,
/// else the best of the lower architectures of its major version ([`compatible_archs`]).
/// Forward and adjoint units alike (the runtime's first backward pass looks here too).
pub(crate) fn lookup(
    source: &str,
    name: &str,
    opts: &CompileOptions,
    arch: u32,
) -> Option<(Vec<u8>, u128, PathBuf)> {
    let cache = KernelCache::new(aot_dir()?);
    compatible_archs(arch).find_map(|a| {
        let key = warp_cuda::aot_key(source, name, opts, a);
        match cache.load(name, key) {
            CacheLookup::Hit(cubin) => Some((cubin, key, cache.path_for(name, key))),
            CacheLookup::Absent | CacheLookup::Damaged => None,
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn arch_lists_parse() {
        assert_eq!(parse_archs("90").unwrap(), vec![90]);
        assert_eq!(parse_archs(" 90, sm_80 ,120").unwrap(), vec![90, 80, 120]);
        for bad in ["", "90,", "sm90", "9", "compute_90", "90a"] {
            let e = parse_archs(bad).expect_err(bad).to_string();
            assert!(e.contains(ARCHS_ENV), "{e}");
        }
    }

    #[test]
    fn a_gpu_takes_cubins_of_its_major_version_up_to_its_own() {
        let c = |a| compatible_archs(a).collect::<Vec<_>>();
        assert_eq!(c(90), vec![90]);
        assert_eq!(c(86), vec![86, 85, 84, 83, 82, 81, 80]);
        assert_eq!(c(121), vec![121, 120]);
        assert_eq!(c(100), vec![100]);
        // Every default architecture is its own first choice, and every GPU generation CUDA
        // 13 supports but Thor finds one.
        for a in DEFAULT_ARCHS {
            assert_eq!(c(*a)[0], *a);
        }
        for gpu in [75, 80, 86, 87, 88, 89, 90, 100, 103, 120, 121] {
            assert!(c(gpu).iter().any(|a| DEFAULT_ARCHS.contains(a)), "sm_{gpu}");
        }
    }
}

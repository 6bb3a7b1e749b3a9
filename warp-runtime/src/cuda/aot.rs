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
//! one that is missing or damaged falls back to the ordinary path.
//!
//! From a build script of the crate that launches the kernels (the crate defining them is a
//! build-dependency):
//! ```ignore
//! // build.rs (needs NVRTC on the build machine; exercised by the suite's
//! // `ahead_of_time_compile` test)
//! use warp_lang as wp;
//! let dir = std::path::Path::new(&std::env::var("CARGO_MANIFEST_DIR").unwrap()).join("kernels");
//! // sm_90 (H100, H200) and sm_80 (A100).
//! wp::aot::compile(&[wp::aot::kernel(my_kernels::integrate)], &[90, 80], &dir).expect("NVRTC");
//! println!("cargo:rustc-env=WARP_LANG_AOT_DIR_BUILT={}", dir.display());
//! ```
//! (a generic kernel's instances: `wp::aot::instances(my_kernels::axpy)`), and at start-up: `wp::aot::set_aot_dir(Some(env!("WARP_LANG_AOT_DIR_BUILT").into()))`.

use super::options::{needs_exact, with_compile_options};
use super::source;
use crate::error::{Error, Result};
use crate::kernel::{GenericKernel, Kernel, KernelInfo};
use std::path::{Path, PathBuf};
use std::sync::RwLock;
use warp_cuda::{CacheLookup, CompileOptions, KernelCache};

/// Environment variable naming the ahead-of-time directory; wins over [`set_aot_dir`].
pub const AOT_DIR_ENV: &str = "WARP_LANG_AOT_DIR";

static AOT_DIR: RwLock<Option<PathBuf>> = RwLock::new(None);

/// Sets (or with `None` clears) the directory where first launches look for ahead-of-time
/// cubins. `WARP_LANG_AOT_DIR`, when set and not empty, wins.
pub fn set_aot_dir(dir: Option<PathBuf>) {
    *AOT_DIR.write().unwrap_or_else(|p| p.into_inner()) = dir;
}

/// The ahead-of-time directory in effect, if any.
pub fn aot_dir() -> Option<PathBuf> {
    match std::env::var_os(AOT_DIR_ENV) {
        Some(v) if !v.is_empty() => Some(PathBuf::from(v)),
        _ => AOT_DIR.read().unwrap_or_else(|p| p.into_inner()).clone(),
    }
}

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
/// `dir`, creating it. Needs NVRTC, not a GPU.
///
/// # Errors
/// [`Error::Cuda`] (device `"nvrtc"`) when NVRTC is missing, rejects an architecture, or
/// fails on a kernel, or when `dir` cannot be written.
pub fn compile(
    kernels: &[&'static KernelInfo],
    archs: &[u32],
    dir: &Path,
) -> Result<Vec<AotEntry>> {
    compile_units(kernels, archs, dir, false)
}

/// [`compile`], and each kernel's adjoint too (both variants, with the adjoint stack
/// [`config::adstack_bytes`](crate::config::adstack_bytes) sets, which must be the same when
/// the program runs backward), for programs that differentiate: their first backward pass then
/// compiles nothing either.
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

/// The architectures a build script compiles for: `WARP_LANG_AOT_ARCHS` (a comma-separated
/// list such as `90,80`) when set, else [`DEFAULT_ARCHS`].
///
/// # Errors
/// [`Error::InvalidArgument`] for a list that does not parse.
pub fn archs_from_env() -> Result<Vec<u32>> {
    match std::env::var(ARCHS_ENV) {
        Ok(v) if !v.trim().is_empty() => v
            .split(',')
            .map(|a| {
                let a = a.trim().trim_start_matches("sm_");
                a.parse::<u32>()
                    .map_err(|e| Error::invalid(format!("{ARCHS_ENV}: \"{a}\": {e}")))
            })
            .collect(),
        _ => Ok(DEFAULT_ARCHS.to_vec()),
    }
}

/// Environment variable naming the architectures [`archs_from_env`] returns.
pub const ARCHS_ENV: &str = "WARP_LANG_AOT_ARCHS";

/// The architectures compiled for when `WARP_LANG_AOT_ARCHS` is not set: Turing (75), Ampere
/// (80, 86), Ada (89) and Hopper (90), which CUDA 13's NVRTC all supports. A cubin runs only
/// on its own architecture; a GPU without an entry falls back to NVRTC at first launch.
pub const DEFAULT_ARCHS: &[u32] = &[75, 80, 86, 89, 90];

fn compile_units(
    kernels: &[&'static KernelInfo],
    archs: &[u32],
    dir: &Path,
    adjoints: bool,
) -> Result<Vec<AotEntry>> {
    let err = |e: warp_cuda::CudaError| Error::Cuda {
        device: "nvrtc".into(),
        message: e.to_string(),
    };
    let cache = KernelCache::new(dir);
    let mut out = Vec::new();
    let stack = crate::config::adstack_bytes().to_string();
    let units = kernels.iter().flat_map(|info| {
        let forward = Some((*info, source::assemble(info), None));
        let adjoint =
            adjoints.then(|| (*info, source::assemble_adjoint(info), Some(stack.as_str())));
        forward.into_iter().chain(adjoint)
    });
    for (info, src, stack_define) in units {
        for &arch in archs {
            for contiguous in [true, false] {
                let exact = needs_exact(&src.headers);
                let entry = with_compile_options(contiguous, stack_define, exact, |opts| {
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
                .map_err(err)?;
                out.push(entry);
            }
        }
    }
    Ok(out)
}

/// The ahead-of-time cubin for this compile, with its key and file, when an AOT directory is
/// set and holds a sound entry for it.
pub(crate) fn lookup(
    source: &str,
    name: &str,
    opts: &CompileOptions,
    arch: u32,
) -> Option<(Vec<u8>, u128, PathBuf)> {
    let dir = aot_dir()?;
    let key = warp_cuda::aot_key(source, name, opts, arch);
    let cache = KernelCache::new(dir);
    match cache.load(name, key) {
        CacheLookup::Hit(cubin) => Some((cubin, key, cache.path_for(name, key))),
        CacheLookup::Absent | CacheLookup::Damaged => None,
    }
}

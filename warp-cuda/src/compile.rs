//! NVRTC: CUDA C++ source to a cubin for one architecture.
//!
//! We ask for SASS (`--gpu-architecture=sm_XX`, `nvrtcGetCUBIN`) rather than PTX so that the
//! driver does no JIT at load time: a warm start is then a file read plus `cuModuleLoadData`.
//! libnvrtc is loaded with dlopen on first use; its absence is an `Err`, never a panic.

use std::ffi::{c_char, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::OnceLock;
use std::time::Instant;

use cudarc::nvrtc::result::NvrtcError;
use cudarc::nvrtc::sys;

use crate::device::panic_message;
use crate::error::{CudaError, Result};
use crate::nvrtc_pool::{acquire, Api};
pub use crate::nvrtc_pool::{MAX_NVRTC_THREADS, NVRTC_THREADS_ENV};

/// NVRTC options. `Default` gives IEEE-faithful code with FMA contraction on (NVRTC's own
/// default), no fast math, no line info.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CompileOptions<'a> {
    /// `--use_fast_math` (approximate division, sqrt and transcendentals, flush to zero).
    pub fast_math: bool,
    /// `--fmad=true` (contract `a * b + c` into FMA). Set `false` for results that match a
    /// separate multiply and add bit for bit.
    pub fmad: bool,
    /// `-lineinfo`: line tables for profilers and sanitizers (no effect on code).
    pub line_info: bool,
    /// Preprocessor definitions, `-DNAME=VALUE` (`-DNAME` when the value is empty).
    pub defines: &'a [(&'a str, &'a str)],
    /// In-memory headers `(include name, contents)`, found by `#include "name"`.
    pub headers: &'a [(&'a str, &'a str)],
    /// Further NVRTC options, passed verbatim after ours.
    pub extra_options: &'a [&'a str],
}

impl Default for CompileOptions<'_> {
    fn default() -> Self {
        CompileOptions {
            fast_math: false,
            fmad: true,
            line_info: false,
            defines: &[],
            headers: &[],
            extra_options: &[],
        }
    }
}

/// NVRTC's target for compute capability `arch`: `sm_XX`, except `sm_90a` on 9.0, whose
/// architecture-specific instructions (`wgmma`, the tile GEMM's warpgroup MMAs) need it. A
/// `sm_90a` cubin runs on 9.0 GPUs only, which are the only ones an `sm_90` cubin is chosen for
/// (`aot::compatible_archs`: the same major version, no newer minor exists).
pub fn nvrtc_target(arch: u32) -> String {
    if arch == 90 {
        "sm_90a".to_string()
    } else {
        format!("sm_{arch}")
    }
}

impl CompileOptions<'_> {
    /// The NVRTC command-line options these settings give for `sm_{arch}` (headers are passed
    /// separately, to `nvrtcCreateProgram`).
    pub fn nvrtc_args(&self, arch: u32) -> Vec<String> {
        let mut args = vec![
            format!("--gpu-architecture={}", nvrtc_target(arch)),
            "-std=c++17".to_string(),
            format!("--fmad={}", self.fmad),
        ];
        if self.fast_math {
            args.push("--use_fast_math".into());
        }
        if self.line_info {
            args.push("-lineinfo".into());
        }
        for (name, value) in self.defines {
            if value.is_empty() {
                args.push(format!("-D{name}"));
            } else {
                args.push(format!("-D{name}={value}"));
            }
        }
        args.extend(self.extra_options.iter().map(|s| s.to_string()));
        args
    }
}

/// A compiled kernel image.
#[derive(Debug, Clone, PartialEq)]
pub struct Compiled {
    /// The cubin (ELF with SASS for the requested architecture).
    pub cubin: Vec<u8>,
    /// NVRTC's log (warnings); empty when the cubin came from the disk cache.
    pub log: String,
    /// Wall time of the NVRTC compile in milliseconds; 0 when it came from the disk cache.
    pub compile_ms: f64,
}

/// Environment variable that, set to anything but empty or `0` before the first use of NVRTC,
/// makes this process behave as if libnvrtc were not installed: a machine with a GPU and the
/// CUDA toolkit can then run the paths of one with a driver alone (the preferred device falls
/// back to the CPU, a JIT launch on an explicit GPU is an error naming NVRTC, ahead-of-time
/// cubins still load). Read once, with the probe.
pub const NO_NVRTC_ENV: &str = "WARP_LANG_NO_NVRTC";

/// Whether `value` (of [`NO_NVRTC_ENV`]) turns NVRTC off: set, not empty and not `0`.
fn no_nvrtc_requested(value: Option<&std::ffi::OsStr>) -> bool {
    value.is_some_and(|v| !v.is_empty() && v != "0")
}

static NVRTC: OnceLock<std::result::Result<(i32, i32), String>> = OnceLock::new();

/// Loads libnvrtc (once) and returns its version, or why it cannot be used. Every reason
/// names NVRTC: it is shown to users whose GPU and driver are fine (see
/// `warp_runtime::cpu_fallback_reason`).
fn nvrtc_state() -> &'static std::result::Result<(i32, i32), String> {
    NVRTC.get_or_init(|| {
        if no_nvrtc_requested(std::env::var_os(NO_NVRTC_ENV).as_deref()) {
            log::info!("NVRTC not used: {NO_NVRTC_ENV} is set");
            return Err(format!("NVRTC turned off by {NO_NVRTC_ENV}"));
        }
        // The probe is one dlopen attempt per candidate name (no CUDA call): cheap enough for
        // `get_preferred_device` to make on a machine with a GPU.
        // SAFETY: only tries Library::new on cudarc's candidate names.
        if !unsafe { sys::is_culib_present() } {
            log::info!("NVRTC not available: libnvrtc.so not found");
            return Err(
                "NVRTC's libnvrtc.so not found (the CUDA toolkit's runtime libraries are not \
                 installed, or not on the library search path)"
                    .to_string(),
            );
        }
        let r = catch_unwind(AssertUnwindSafe(|| {
            let (mut major, mut minor) = (0, 0);
            // SAFETY: out-parameter call; library present.
            unsafe { sys::nvrtcVersion(&mut major, &mut minor) }
                .result()
                .map(|_| (major, minor))
        }));
        let state = match r {
            Ok(Ok(v)) => Ok(v),
            Ok(Err(e)) => Err(format!("NVRTC's nvrtcVersion failed: {e}")),
            Err(p) => Err(format!(
                "libnvrtc could not be used: {}",
                panic_message(p.as_ref())
            )),
        };
        match &state {
            Ok((major, minor)) => log::debug!("loaded NVRTC {major}.{minor}"),
            // A library present but unusable is worth a warning.
            Err(why) => log::warn!("NVRTC cannot be used: {why}"),
        }
        state
    })
}

/// NVRTC's version (major, minor), e.g. (13, 0). Fails with
/// [`CudaError::NoNvrtc`] when libnvrtc cannot be loaded.
pub fn nvrtc_version() -> Result<(i32, i32)> {
    nvrtc_state().clone().map_err(CudaError::NoNvrtc)
}

/// NVRTC's version if it is loaded already (`None` if not, or if it cannot be): never loads
/// it, so a lookup that needs the version only to find a cached cubin stays free.
pub(crate) fn loaded_nvrtc_version() -> Option<(i32, i32)> {
    NVRTC.get().and_then(|s| s.as_ref().ok().copied())
}

/// The `sm_XX` architectures this NVRTC can compile for, e.g. `[75, 80, 86, 89, 90, 100, ...]`.
pub fn nvrtc_supported_archs() -> Result<Vec<u32>> {
    nvrtc_version()?;
    let mut n = 0;
    // SAFETY: out-parameter calls; the buffer has the size NVRTC reported.
    unsafe { sys::nvrtcGetNumSupportedArchs(&mut n) }
        .result()
        .map_err(|e| CudaError::nvrtc(e, "nvrtcGetNumSupportedArchs"))?;
    let mut archs = vec![0i32; n.max(0) as usize];
    if !archs.is_empty() {
        unsafe { sys::nvrtcGetSupportedArchs(archs.as_mut_ptr()) }
            .result()
            .map_err(|e| CudaError::nvrtc(e, "nvrtcGetSupportedArchs"))?;
    }
    Ok(archs.into_iter().map(|a| a.max(0) as u32).collect())
}

/// Destroys the program on every exit path (with the copy of NVRTC that created it).
struct Program<'a>(sys::nvrtcProgram, &'a Api);

impl Drop for Program<'_> {
    fn drop(&mut self) {
        // SAFETY: created by this copy's nvrtcCreateProgram, destroyed once.
        let _ = unsafe { (self.1.destroy)(&mut self.0) };
    }
}

fn cstring(s: &str, what: &str) -> Result<CString> {
    CString::new(s).map_err(|_| CudaError::InvalidArgument(format!("{what} contains a NUL byte")))
}

fn program_log(prog: &Program) -> String {
    let mut size = 0usize;
    // SAFETY: out-parameter calls on a live program; buffer of the reported size.
    if unsafe { (prog.1.log_size)(prog.0, &mut size) }
        .result()
        .is_err()
        || size == 0
    {
        return String::new();
    }
    let mut buf = vec![0u8; size];
    if unsafe { (prog.1.log)(prog.0, buf.as_mut_ptr() as *mut c_char) }
        .result()
        .is_err()
    {
        return String::new();
    }
    while buf.last() == Some(&0) {
        buf.pop();
    }
    String::from_utf8_lossy(&buf).trim_end().to_string()
}

/// Compiles `source` (program name `name`, used in NVRTC's messages) to a cubin for
/// `sm_{arch}`. On a compile error the result is [`CudaError::Compile`] with NVRTC's log.
///
/// Threads may call it at once: compiles that overlap run side by side, each in a copy of
/// NVRTC of its own, up to a limit (`nvrtc_pool`: [`NVRTC_THREADS_ENV`]); `compile_ms` is
/// the compile's own time, not the wait for a copy.
pub fn compile(source: &str, name: &str, opts: &CompileOptions, arch: u32) -> Result<Compiled> {
    nvrtc_version()?;
    let slot = acquire().ok_or_else(|| CudaError::Nvrtc {
        op: "loading NVRTC's entry points".into(),
        message: "libnvrtc lacks an entry point of the CUDA 13 API".into(),
        code: None,
    })?;
    let api = &slot.api;
    api.enter();
    let start = Instant::now();
    let c_src = cstring(source, "kernel source")?;
    let c_name = cstring(name, "program name")?;
    let mut header_srcs = Vec::with_capacity(opts.headers.len());
    let mut header_names = Vec::with_capacity(opts.headers.len());
    for (hname, hsrc) in opts.headers {
        header_names.push(cstring(hname, "header name")?);
        header_srcs.push(cstring(hsrc, "header contents")?);
    }
    let src_ptrs: Vec<*const c_char> = header_srcs.iter().map(|c| c.as_ptr()).collect();
    let name_ptrs: Vec<*const c_char> = header_names.iter().map(|c| c.as_ptr()).collect();
    let args = opts.nvrtc_args(arch);
    let c_args = args
        .iter()
        .map(|a| cstring(a, "NVRTC option"))
        .collect::<Result<Vec<_>>>()?;
    let arg_ptrs: Vec<*const c_char> = c_args.iter().map(|c| c.as_ptr()).collect();

    let mut raw: sys::nvrtcProgram = std::ptr::null_mut();
    // SAFETY: all strings are NUL-terminated and outlive the program (dropped at function end,
    // after `Program`); header arrays have `len` entries each.
    unsafe {
        (api.create)(
            &mut raw,
            c_src.as_ptr(),
            c_name.as_ptr(),
            src_ptrs.len() as i32,
            if src_ptrs.is_empty() {
                std::ptr::null()
            } else {
                src_ptrs.as_ptr()
            },
            if name_ptrs.is_empty() {
                std::ptr::null()
            } else {
                name_ptrs.as_ptr()
            },
        )
    }
    .result()
    .map_err(|e| CudaError::nvrtc(e, format!("nvrtcCreateProgram({name})")))?;
    let prog = Program(raw, api);

    // SAFETY: live program; option pointers valid for the call.
    let compiled =
        unsafe { (api.compile)(prog.0, arg_ptrs.len() as i32, arg_ptrs.as_ptr()) }.result();
    let log = program_log(&prog);
    if let Err(NvrtcError(code)) = compiled {
        let log = if code == sys::nvrtcResult::NVRTC_ERROR_COMPILATION {
            log
        } else {
            // Invalid options and the like: say which, with the options we passed.
            let why = CudaError::nvrtc(NvrtcError(code), "nvrtcCompileProgram");
            format!("{why}\noptions: {}\n{log}", args.join(" "))
        };
        return Err(CudaError::Compile {
            name: name.to_string(),
            arch,
            log,
        });
    }

    let mut size = 0usize;
    // SAFETY: live, successfully compiled program; buffer of the reported size.
    unsafe { (api.cubin_size)(prog.0, &mut size) }
        .result()
        .map_err(|e| CudaError::nvrtc(e, format!("nvrtcGetCUBINSize({name}, sm_{arch})")))?;
    if size == 0 {
        return Err(CudaError::Nvrtc {
            op: format!("nvrtcGetCUBIN({name})"),
            message: format!("NVRTC produced no cubin for sm_{arch} (is it a real architecture?)"),
            code: None,
        });
    }
    let mut cubin = vec![0u8; size];
    unsafe { (api.cubin)(prog.0, cubin.as_mut_ptr() as *mut c_char) }
        .result()
        .map_err(|e| CudaError::nvrtc(e, format!("nvrtcGetCUBIN({name}, sm_{arch})")))?;
    drop(prog);
    let copy = api.copy;
    drop(slot);
    let compile_ms = start.elapsed().as_secs_f64() * 1e3;
    log::info!(
        "NVRTC compiled {name} for sm_{arch} in {compile_ms:.1} ms ({} bytes of cubin, copy {copy} \
         of libnvrtc)",
        cubin.len()
    );
    if !log.trim().is_empty() {
        log::debug!("NVRTC log of {name} (sm_{arch}):\n{}", log.trim_end());
    }
    Ok(Compiled {
        cubin,
        log,
        compile_ms,
    })
}

/// Environment variable naming `libcudadevrt.a`, for device code that calls the device runtime
/// (graph conditionals); wins over the search of [`cudadevrt_path`].
pub const CUDADEVRT_ENV: &str = "WARP_LANG_CUDADEVRT";

/// Where the CUDA toolkit's static device runtime `libcudadevrt.a` is: `WARP_LANG_CUDADEVRT`,
/// else under `CUDA_PATH`, `CUDA_HOME`, `/usr/local/cuda` and `/usr/local/cuda-*` (newest
/// first), in `lib64`, `targets/{x86_64,sbsa}-linux/lib` or `lib`. `None` when there is none
/// (a machine with a driver but no toolkit).
pub fn cudadevrt_path() -> Option<std::path::PathBuf> {
    use std::path::PathBuf;
    if let Some(p) = std::env::var_os(CUDADEVRT_ENV).filter(|v| !v.is_empty()) {
        return Some(PathBuf::from(p)).filter(|p| p.is_file());
    }
    let mut roots: Vec<PathBuf> = ["CUDA_PATH", "CUDA_HOME"]
        .iter()
        .filter_map(|v| {
            std::env::var_os(v)
                .filter(|v| !v.is_empty())
                .map(PathBuf::from)
        })
        .collect();
    roots.push(PathBuf::from("/usr/local/cuda"));
    let mut versioned: Vec<PathBuf> = std::fs::read_dir("/usr/local")
        .into_iter()
        .flatten()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("cuda-"))
        })
        .collect();
    versioned.sort();
    roots.extend(versioned.into_iter().rev());
    let subdirs = [
        "lib64",
        "targets/x86_64-linux/lib",
        "targets/sbsa-linux/lib",
        "lib",
    ];
    roots
        .iter()
        .flat_map(|r| {
            subdirs
                .iter()
                .map(move |d| r.join(d).join("libcudadevrt.a"))
        })
        .find(|p| p.is_file())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_args() {
        let o = CompileOptions::default();
        assert_eq!(
            o.nvrtc_args(80),
            ["--gpu-architecture=sm_80", "-std=c++17", "--fmad=true"]
        );
        // 9.0 compiles with its architecture-specific features (wgmma).
        assert_eq!(o.nvrtc_args(90)[0], "--gpu-architecture=sm_90a");
    }

    #[test]
    fn all_args() {
        let o = CompileOptions {
            fast_math: true,
            fmad: false,
            line_info: true,
            defines: &[("N", "4"), ("FLAG", "")],
            headers: &[("a.h", "")],
            extra_options: &["--extra-device-vectorization"],
        };
        assert_eq!(
            o.nvrtc_args(89),
            [
                "--gpu-architecture=sm_89",
                "-std=c++17",
                "--fmad=false",
                "--use_fast_math",
                "-lineinfo",
                "-DN=4",
                "-DFLAG",
                "--extra-device-vectorization"
            ]
        );
    }

    #[test]
    fn no_nvrtc_env_values() {
        use std::ffi::OsStr;
        assert!(!no_nvrtc_requested(None));
        assert!(!no_nvrtc_requested(Some(OsStr::new(""))));
        assert!(!no_nvrtc_requested(Some(OsStr::new("0"))));
        assert!(no_nvrtc_requested(Some(OsStr::new("1"))));
        assert!(no_nvrtc_requested(Some(OsStr::new("true"))));
    }

    #[test]
    fn missing_nvrtc_is_an_error_not_a_panic() {
        let r = compile(
            "extern \"C\" __global__ void k() {}",
            "k.cu",
            &Default::default(),
            90,
        );
        match nvrtc_version() {
            Err(CudaError::NoNvrtc(reason)) => {
                // The reason reaches users whose GPU works: it must say that NVRTC is missing.
                assert!(reason.contains("NVRTC"), "{reason}");
                assert!(matches!(r, Err(CudaError::NoNvrtc(ref r2)) if *r2 == reason));
            }
            Err(e) => panic!("unexpected {e}"),
            Ok(_) => {
                // NVRTC present: whether sm_90 compiles is checked by the GPU tests.
            }
        }
    }
}

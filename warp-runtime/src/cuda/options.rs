//! The NVRTC options of a kernel translation unit.

use crate::config;
use warp_cuda::CompileOptions;

/// Calls `f` with the NVRTC options of a kernel translation unit (the runtime's and the
/// ahead-of-time compiler's, which must agree for AOT entries to be found).
/// `adstack_bytes`: the per-thread adjoint stack of an adjoint unit. FMA contraction follows
/// `config::cuda_fmad` for every unit, the geometry queries' included: with it off, they are
/// the CPU's bit for bit (the headers are written step for step as the Rust); with it on (the
/// default, as nvcc and Warp), faster (`benches/geometry.rs` times both) and within rounding
/// of the CPU.
pub(crate) fn with_compile_options<R>(
    contiguous: bool,
    adstack_bytes: Option<&str>,
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
    f(&CompileOptions {
        fmad: config::cuda_fmad(),
        line_info: true,
        defines,
        headers: &headers,
        ..Default::default()
    })
}

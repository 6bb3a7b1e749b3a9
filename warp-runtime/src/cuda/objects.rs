//! Host objects' build steps on a GPU ([`ObjectStep`]): each object's build library (its
//! header with the build kernels enabled, e.g. `wp_hash_grid.h` with `WP_HASH_GRID_BUILD`) is
//! compiled by NVRTC through the kernel disk cache the first time a GPU runs one of its steps,
//! loaded, and kept for the process with its functions; a step's launch goes on the calling
//! thread's current stream, as a kernel's does (the ordering model of `gpu.rs`), without host
//! synchronisation. Nothing here names an object: the step says which library and kernel.
//! Inside a capture a step's launch goes on the capture stream; its library and kernel must
//! be loaded before (a module load would break the capture).

use super::gpu;
use crate::backend::{ObjectLibrary, ObjectStep};
use crate::config;
use crate::device::Device;
use crate::error::Result;
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::{Arc, Mutex, OnceLock};
use warp_cuda::{CompileOptions, Function};

/// Threads per block of the build kernels (grid-stride loops: any count of blocks works).
const THREADS: u32 = 256;

/// A build library loaded on one GPU, with the functions looked up so far.
struct Loaded {
    module: warp_cuda::Module,
    functions: Mutex<HashMap<&'static str, Function>>,
}

/// Compiles with the runtime's options: the library's headers, FMA contraction as
/// `config::cuda_fmad` says (one setting for all GPU code).
fn with_options<R>(lib: &ObjectLibrary, f: impl FnOnce(&CompileOptions) -> R) -> R {
    let headers: Vec<(&str, &str)> = warp_cuda::HEADERS
        .iter()
        .copied()
        .filter(|(name, _)| lib.headers.contains(name))
        .collect();
    f(&CompileOptions {
        fmad: config::cuda_fmad(),
        line_info: true,
        headers: &headers,
        ..Default::default()
    })
}

/// Compiles `lib` for `sm_{arch}` (no GPU needed, only libnvrtc): how the tests check that
/// NVRTC accepts every build library on machines without a GPU.
pub fn compile_library(lib: &ObjectLibrary, arch: u32) -> warp_cuda::Result<warp_cuda::Compiled> {
    with_options(lib, |opts| {
        warp_cuda::compile(lib.source, lib.name, opts, arch)
    })
}

/// What a capture refuses when a build step would load `what` (its library or kernel).
fn first_use(what: &str) -> String {
    format!(
        "loading {what} of a host object's build at its first use on this GPU: run the build \
         once on this device before capturing"
    )
}

/// `lib` on GPU `ordinal` (`device`), compiled and loaded once per process.
fn loaded(device: &Device, ordinal: usize, lib: &'static ObjectLibrary) -> Result<Arc<Loaded>> {
    type Cache = Mutex<HashMap<(usize, &'static str), Arc<Loaded>>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let key = (ordinal, lib.name);
    if let Some(l) = cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return Ok(l.clone());
    }
    gpu::refuse_in_capture(ordinal, &first_use(&format!("the library {}", lib.name)))?;
    let st = gpu::state(device, ordinal)?;
    let (compiled, _) = with_options(lib, |opts| {
        warp_cuda::compile_cached(lib.source, lib.name, opts, st.gpu.arch())
    })
    .map_err(|e| gpu::err(device, e))?;
    let module = st
        .gpu
        .load_module(&compiled.cubin)
        .map_err(|e| gpu::err(device, e))?;
    log::info!("loaded the build library {} on {device}", lib.name);
    let l = Arc::new(Loaded {
        module,
        functions: Mutex::new(HashMap::new()),
    });
    // A racing first use loaded it too: keep the first, drop this one.
    Ok(cache
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .entry(key)
        .or_insert(l)
        .clone())
}

/// [`Backend::object_step`](crate::backend::Backend::object_step) on a GPU: queues the step's
/// kernel over `step.len()` elements with the record as its one argument.
pub(super) fn object_step<S: ObjectStep>(device: &Device, ordinal: usize, step: &S) -> Result<()> {
    let n = step.len();
    if n == 0 {
        return Ok(());
    }
    let lib = loaded(device, ordinal, S::LIBRARY)?;
    let f = {
        let mut fns = lib.functions.lock().unwrap_or_else(|p| p.into_inner());
        match fns.get(S::KERNEL) {
            Some(f) => f.clone(),
            None => {
                gpu::refuse_in_capture(ordinal, &first_use(&format!("the kernel {}", S::KERNEL)))?;
                let f = lib
                    .module
                    .function(S::KERNEL)
                    .map_err(|e| gpu::err(device, e))?;
                fns.insert(S::KERNEL, f.clone());
                f
            }
        }
    };
    let st = gpu::state(device, ordinal)?;
    // At most 2^16 blocks: the kernels loop over the rest.
    let blocks = n.div_ceil(THREADS as usize).min(1 << 16) as u32;
    let mut record = *step;
    let mut params = [&mut record as *mut S as *mut c_void];
    st.queue(ordinal, None, |stream| {
        // SAFETY: the kernel takes one parameter, the C++ struct `S` is laid out as
        // (`ObjectStep`'s contract), and `params` points at a copy of the record that lives
        // until the launch is queued (the driver copies parameters at launch); the addresses
        // in it are of live device memory sized as the step needs (the object checked them).
        unsafe {
            st.gpu
                .launch_raw(&f, stream, blocks, THREADS, 0, &mut params)
                .map_err(|e| gpu::err(device, e))
        }
    })?;
    // (Inside a capture nothing has run yet: there is nothing to check.)
    if config::debug() && gpu::capture_stream(ordinal).is_none() {
        gpu::synchronize(device, ordinal)?;
    }
    Ok(())
}

//! The per-element steps of host objects' builds on a GPU: the hash grid's kernels
//! (`wp_hash_grid_keys`, `wp_hash_grid_ranges` in `wp_hash_grid.h`, compiled with
//! `WP_HASH_GRID_BUILD` defined). The module is compiled by NVRTC through the kernel disk
//! cache the first time a GPU builds a grid, loaded, and kept for the process; its launches go
//! on the calling thread's current stream, as a kernel's do (the ordering model of `gpu.rs`),
//! without host synchronisation.

use super::gpu;
use crate::backend::{HashGridKeys, HashGridRanges};
use crate::config;
use crate::device::Device;
use crate::error::Result;
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::{Arc, Mutex, OnceLock};
use warp_cuda::{CompileOptions, Function};

/// The build module's source: the header with its kernels.
const SOURCE: &str = "#define WP_HASH_GRID_BUILD 1\n#include \"wp_hash_grid.h\"\n";

/// Threads per block of the build kernels (grid-stride loops: any count of blocks works).
const THREADS: u32 = 256;

/// The build kernels, loaded on one GPU.
struct Kernels {
    // Keeps the functions' module loaded.
    _module: warp_cuda::Module,
    keys: Function,
    ranges: Function,
}

/// Compiles the module with the runtime's options: the two headers it includes, FMA
/// contraction as `config::cuda_fmad` says (the key step multiplies once, before a `floor`:
/// nothing to contract, but one setting for all GPU code).
fn with_options<R>(f: impl FnOnce(&CompileOptions) -> R) -> R {
    let headers: Vec<(&str, &str)> = warp_cuda::HEADERS
        .iter()
        .copied()
        .filter(|(name, _)| matches!(*name, "wp_core.h" | "wp_hash_grid.h"))
        .collect();
    f(&CompileOptions {
        fmad: config::cuda_fmad(),
        line_info: true,
        headers: &headers,
        ..Default::default()
    })
}

/// Compiles the build module for `sm_{arch}` (no GPU needed, only libnvrtc): how the tests
/// check that NVRTC accepts it on machines without a GPU.
pub fn compile_hash_grid_build(arch: u32) -> warp_cuda::Result<warp_cuda::Compiled> {
    with_options(|opts| warp_cuda::compile(SOURCE, "wp_hash_grid_build", opts, arch))
}

/// The build kernels on GPU `ordinal` (`device`), compiled and loaded once per process.
fn kernels(device: &Device, ordinal: usize) -> Result<Arc<Kernels>> {
    static CACHE: OnceLock<Mutex<HashMap<usize, Arc<Kernels>>>> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    if let Some(k) = cache
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .get(&ordinal)
    {
        return Ok(k.clone());
    }
    let st = gpu::state(device, ordinal)?;
    let (compiled, _) = with_options(|opts| {
        warp_cuda::compile_cached(SOURCE, "wp_hash_grid_build", opts, st.gpu.arch())
    })
    .map_err(|e| gpu::err(device, e))?;
    let module = st
        .gpu
        .load_module(&compiled.cubin)
        .map_err(|e| gpu::err(device, e))?;
    let f = |name: &str| module.function(name).map_err(|e| gpu::err(device, e));
    let k = Arc::new(Kernels {
        keys: f("wp_hash_grid_keys")?,
        ranges: f("wp_hash_grid_ranges")?,
        _module: module,
    });
    cache
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(ordinal, k.clone());
    Ok(k)
}

/// Queues `f` over `n` elements with `params` (pointers to each kernel argument, in order).
fn queue(
    device: &Device,
    ordinal: usize,
    f: &Function,
    n: usize,
    params: &mut [*mut c_void],
) -> Result<()> {
    if n == 0 {
        return Ok(());
    }
    let st = gpu::state(device, ordinal)?;
    // At most 2^16 blocks: the kernels loop over the rest.
    let blocks = n.div_ceil(THREADS as usize).min(1 << 16) as u32;
    st.queue(ordinal, None, |stream| {
        // SAFETY: `params` points at one value per kernel parameter, of its type (the callers
        // below list them in the kernels' order); the addresses among them are of live device
        // memory holding what the kernels touch (the build checked the sizes).
        unsafe {
            st.gpu
                .launch_raw(f, stream, blocks, THREADS, 0, params)
                .map_err(|e| gpu::err(device, e))
        }
    })?;
    if config::debug() {
        gpu::synchronize(device, ordinal)?;
    }
    Ok(())
}

/// [`Backend::hash_grid_keys`](crate::backend::Backend::hash_grid_keys) on a GPU.
pub(super) fn hash_grid_keys(device: &Device, ordinal: usize, s: &HashGridKeys) -> Result<()> {
    let k = kernels(device, ordinal)?;
    let (mut points, mut n) = (s.points, s.n as i32);
    let [mut dx, mut dy, mut dz] = s.dims;
    let mut inv = s.inv;
    let (mut keys, mut values, mut bad) = (s.keys, s.values, s.bad);
    let mut params = [
        ptr(&mut points),
        ptr(&mut n),
        ptr(&mut dx),
        ptr(&mut dy),
        ptr(&mut dz),
        ptr(&mut inv),
        ptr(&mut keys),
        ptr(&mut values),
        ptr(&mut bad),
    ];
    queue(device, ordinal, &k.keys, s.n, &mut params)
}

/// [`Backend::hash_grid_ranges`](crate::backend::Backend::hash_grid_ranges) on a GPU.
pub(super) fn hash_grid_ranges(device: &Device, ordinal: usize, s: &HashGridRanges) -> Result<()> {
    let k = kernels(device, ordinal)?;
    let (mut keys, mut n, mut starts, mut ends) = (s.keys, s.n as i32, s.starts, s.ends);
    let (mut buckets, mut clear) = (s.buckets as i32, s.clear as i32);
    let mut params = [
        ptr(&mut keys),
        ptr(&mut n),
        ptr(&mut starts),
        ptr(&mut ends),
        ptr(&mut buckets),
        ptr(&mut clear),
    ];
    queue(device, ordinal, &k.ranges, s.n, &mut params)
}

/// A kernel parameter as `cuLaunchKernel` takes it: the address of its value.
fn ptr<T>(x: &mut T) -> *mut c_void {
    x as *mut T as *mut c_void
}

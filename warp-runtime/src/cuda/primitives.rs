//! Runs the primitives' launch plans on a GPU.
//!
//! Each plan names one module of `wp_primitives.h` (scan of one element type, sort of one
//! key type, compaction of one element size). A module is compiled by NVRTC through the
//! kernel disk cache the first time a GPU needs it, loaded, and kept for the process, like a
//! kernel. A plan's launches go on the calling thread's current stream (the ordering model of
//! `gpu.rs`: after the array operations queued before; the scratch memory is the GPU's
//! workspace, ordered like an array), with no host synchronisation: counts stay on the device.
//! So a primitive can be recorded into a graph: inside a capture its launches go on the capture
//! stream, and the graph holds the workspace they use.

use super::fault;
use super::gpu;
use crate::config;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use crate::primitives::elements::{Extent, ScanOps, SortKeyOps};
use crate::primitives::plan::{self, gpu_tile, Buf, Module, Plan, ReduceOp, Word, GPU_TILE};
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::{Arc, Mutex, OnceLock};
use warp_cuda::library::{self, Section};
use warp_cuda::{CompileOptions, Function};

/// A module loaded on one GPU, with the entries looked up so far.
struct Loaded {
    module: warp_cuda::Module,
    functions: Mutex<HashMap<String, Function>>,
}

impl Loaded {
    /// Entry `name`, looked up at its first use (outside a capture: `func`'s call before).
    fn function(
        &self,
        device: &Device,
        ordinal: usize,
        func: &str,
        name: &str,
    ) -> Result<Function> {
        let mut fns = self.functions.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(f) = fns.get(name) {
            return Ok(f.clone());
        }
        gpu::refuse_in_capture(ordinal, &first_use(func, &format!("the GPU entry {name}")))?;
        let f = self
            .module
            .function(name)
            .map_err(|e| gpu::err(device, e))?;
        fns.insert(name.to_string(), f.clone());
        Ok(f)
    }
}

/// The primitives' section of the CUDA library (`wp_primitives.h`).
const PRIMITIVES: &Section = library::get("primitives");

/// Calls `f` with the NVRTC options of primitives module `module`: its GPU defines (tile, and
/// a sort's kernel), the core and the section's header (handing NVRTC the whole library would
/// only cost compile time and cache-key hashing), FMA contraction as `config::cuda_fmad` says (sums of
/// products do not occur, so it changes nothing here but keeps one setting for all GPU code).
pub(crate) fn with_options<R>(module: &Module, f: impl FnOnce(&CompileOptions) -> R) -> R {
    let defines = module.defines(gpu_tile(module));
    let defines: Vec<(&str, &str)> = defines.iter().map(|(k, v)| (*k, v.as_str())).collect();
    f(&CompileOptions {
        fmad: PRIMITIVES.exact.fmad(config::cuda_fmad()),
        line_info: config::cuda_line_info(),
        defines: &defines,
        headers: &PRIMITIVES.standalone_headers(),
        extra_options: PRIMITIVES.exact.extra_options(),
        ..Default::default()
    })
}

/// What a capture refuses when primitive `func` would load `what` (a module load would break
/// the capture).
fn first_use(func: &str, what: &str) -> String {
    format!(
        "loading {what} at the first use of `{func}` on this GPU: call `{func}` once with these \
         lengths on this device before capturing"
    )
}

/// `module` compiled and loaded for GPU `ordinal` (once per process), for primitive `func`.
fn loaded(device: &Device, ordinal: usize, module: &Module, func: &str) -> Result<Arc<Loaded>> {
    type Cache = Mutex<HashMap<(usize, Module), Arc<Loaded>>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let key = (ordinal, module.clone());
    if let Some(l) = cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return Ok(l.clone());
    }
    let what = format!("the GPU module {}", module.name());
    gpu::refuse_in_capture(ordinal, &first_use(func, &what))?;
    let st = gpu::state(device, ordinal)?;
    let (compiled, _) = with_options(module, |opts| {
        warp_cuda::compile_cached(&module.source(), &module.name(), opts, st.gpu.arch())
    })
    .map_err(|e| gpu::err(device, e))?;
    let m = st
        .gpu
        .load_module(&compiled.cubin)
        .map_err(|e| gpu::err(device, e))?;
    log::info!("loaded the primitives module {} on {device}", module.name());
    let l = Arc::new(Loaded {
        module: m,
        functions: Mutex::new(HashMap::new()),
    });
    cache
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(key, l.clone());
    Ok(l)
}

/// The `KernelInfo` a primitive's faults are reported under (its name and parameter names):
/// one per primitive function, made once.
fn info(func: &'static str, params: &'static [&'static str]) -> &'static KernelInfo {
    static INFOS: OnceLock<Mutex<HashMap<&'static str, &'static KernelInfo>>> = OnceLock::new();
    let mut infos = INFOS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    infos.entry(func).or_insert_with(|| {
        // A dozen primitives at most: leaked once each, like the macro's statics.
        Box::leak(Box::new(KernelInfo {
            name: func,
            module: "warp_lang::primitives",
            params,
            ..KernelInfo::BLANK
        }))
    })
}

/// Runs `plan` on GPU `ordinal` (`device`) for primitive `func` (whose parameters, for
/// fault reports, are `params`); `users` are the device addresses of the caller's arrays in
/// the plan's order.
///
/// Inside a capture the launches go on the capture stream (`GpuState::queue`), and the graph
/// holds the scratch they use (`capture::uses_scratch`); nothing may be compiled or
/// allocated there, so the module and a large enough workspace must be there already.
fn run(
    device: &Device,
    ordinal: usize,
    func: &'static str,
    params: &'static [&'static str],
    plan: &Plan,
    users: &[u64],
) -> Result<()> {
    run_on(device, ordinal, None, func, params, plan, users)
}

/// [`run`] on `stream` (`None`: the calling thread's current stream), as a launch on it.
fn run_on(
    device: &Device,
    ordinal: usize,
    stream: Option<&warp_cuda::Stream>,
    func: &'static str,
    params: &'static [&'static str],
    plan: &Plan,
    users: &[u64],
) -> Result<()> {
    let capturing = gpu::capture_stream(ordinal).is_some();
    let module = loaded(device, ordinal, &plan.module, func)?;
    let st = gpu::state(device, ordinal)?;
    // Scratch: slices of the GPU's workspace, which grows to the largest need and is kept
    // (no allocation per call). Its lock is held until the launches are queued.
    let (offsets, need) = scratch_layout(&plan.scratch);
    let mut ws = st.workspace.lock().unwrap_or_else(|p| p.into_inner());
    if ws.as_ref().is_none_or(|s| s.buffer.len() < need) {
        gpu::refuse_in_capture(
            ordinal,
            &format!(
                "growing the primitives' scratch memory to {need} bytes for `{func}` (an \
                 allocation): call `{func}` once with these lengths on this device before \
                 capturing"
            ),
        )?;
        let old = ws.as_ref().map_or(0, |s| s.buffer.len());
        // The old buffer's free is queued on the default stream: after its last user.
        st.join_pending()?;
        *ws = None;
        let bytes = need.max(old + old / 2);
        let buf = warp_cuda::DeviceBuffer::alloc(&st.gpu, bytes)
            .map_err(|e| Error::cuda_alloc(device.alias(), bytes, e))?;
        // Allocated on the default stream, which every user stream waits for before a launch:
        // no last user to wait for.
        *ws = Some(gpu::Scratch::new(buf));
    }
    let scratch = ws.as_ref().expect("made above").clone();
    let base = scratch.buffer.device_ptr();
    // A primitive is one launch, however many kernels it queues; its kernels carry no id, so
    // its record notes it as the launch a fault without one comes from.
    let launch = crate::launch_id::next();
    let (fault, flag) = fault::with_record(&st.faults, ordinal, launch, |r| {
        r.set_primitive(info(func, params), launch);
        r.addresses()
    })?;
    let word = |w: &Word| -> u64 {
        match *w {
            Word::Addr(Buf::User(k), off) => users[k] + off,
            Word::Addr(Buf::Scratch(k), off) => base + offsets[k] + off,
            Word::Null => 0,
            Word::Int(v) => v as u64,
            Word::Fault => fault,
            Word::FaultFlag => flag,
        }
    };
    let tile = gpu_tile(&plan.module);
    let mut launches = Vec::with_capacity(plan.steps.len());
    for s in &plan.steps {
        let blocks = u32::try_from(s.blocks).map_err(|_| {
            Error::invalid(format!(
                "{func}: {} blocks of {} elements are more than a grid holds",
                s.blocks,
                tile.elements()
            ))
        })?;
        let mut args = [0u64; 16];
        for (a, w) in args.iter_mut().zip(&s.args) {
            *a = word(w);
        }
        launches.push((
            module.function(device, ordinal, func, &s.entry)?,
            blocks,
            args,
        ));
    }
    let mut last = scratch.last();
    st.queue(ordinal, stream, |stream| {
        // The workspace's last user may be another stream: wait for its work first. A graph
        // orders itself so at each replay instead (nothing runs at capture).
        if !capturing {
            gpu::order_scratch(device, &mut last, stream)?;
        }
        for (f, blocks, args) in &mut launches {
            let mut params = [args.as_mut_ptr() as *mut c_void];
            // SAFETY: every entry takes one `wp::prim::args_t` (16 u64 words) by value, which
            // `params[0]` points at; the words are device addresses of live memory (the
            // caller's arrays, checked to hold what the plan touches, and the scratch, kept
            // by the workspace or the graph) and integers.
            unsafe {
                st.gpu
                    .launch_raw(f, stream, *blocks, tile.threads, 0, &mut params)
                    .map_err(|e| gpu::err(device, e))?;
            }
        }
        Ok(())
    })?;
    drop(last);
    drop(ws);
    if capturing {
        // (Nothing has run yet: there is no fault to check.)
        super::capture::uses_scratch(ordinal, scratch);
    } else if config::debug() {
        gpu::synchronize(device, ordinal)?;
    }
    Ok(())
}

/// Byte offsets of a plan's scratch buffers in the workspace (each 256-byte aligned), and
/// the bytes they need in all.
fn scratch_layout(sizes: &[u64]) -> (Vec<u64>, usize) {
    let mut offsets = Vec::with_capacity(sizes.len());
    let mut end = 0u64;
    for &bytes in sizes {
        offsets.push(end);
        end += bytes.next_multiple_of(256);
    }
    (offsets, end as usize)
}

/// The plan's length; a device count's address is appended to `users`. `arg` is the index
/// of `count` in the primitive's parameters (named by its faults).
fn plan_len(len: Extent, users: &mut Vec<u64>, arg: i64) -> plan::Len {
    match len {
        Extent::Host(n) => plan::Len::Host(n as u64),
        Extent::Device {
            count, capacity, ..
        } => {
            users.push(count);
            plan::Len::Device {
                count: users.len() - 1,
                capacity: capacity as u64,
                arg,
            }
        }
    }
}

/// `array_scan_n` on a GPU.
pub(super) fn scan<T: ScanOps>(
    device: &Device,
    ordinal: usize,
    func: &'static str,
    input: u64,
    output: u64,
    len: Extent,
    inclusive: bool,
) -> Result<()> {
    let mut users = vec![input, output];
    let len = plan_len(len, &mut users, 2);
    let size = std::mem::size_of::<T>() as u64;
    let (algorithm, tile) = plan::gpu_scan(T::CUDA, size);
    let p = algorithm.plan(tile, T::CUDA, size, len, inclusive);
    let params = &["input", "output", "count"];
    run(device, ordinal, func, params, &p, &users)
}

/// `array_sum_n` and friends on a GPU.
pub(super) fn reduce<T: ScanOps>(
    device: &Device,
    ordinal: usize,
    func: &'static str,
    input: u64,
    out: u64,
    len: Extent,
    op: ReduceOp,
) -> Result<()> {
    let mut users = vec![input, out];
    let len = plan_len(len, &mut users, 2);
    let size = std::mem::size_of::<T>() as u64;
    let p = plan::reduce(plan::gpu_scan(T::CUDA, size).1, T::CUDA, size, op, len);
    run(
        device,
        ordinal,
        func,
        &["values", "out", "count"],
        &p,
        &users,
    )
}

/// `radix_sort_pairs` on a GPU (values of every `SortValueOps` type move as 32-bit words).
pub(super) fn radix_sort_pairs<K: SortKeyOps>(
    device: &Device,
    ordinal: usize,
    func: &'static str,
    keys: u64,
    values: u64,
    len: Extent,
    key_bits: u32,
) -> Result<()> {
    let mut users = vec![keys, values];
    let len = plan_len(len, &mut users, 2);
    let p = plan::sort(plan::gpu_sort_config(), K::CUDA, key_bits, len);
    run(
        device,
        ordinal,
        func,
        &["keys", "values", "count"],
        &p,
        &users,
    )
}

/// A stable sort of `n` pairs of `u32` keys and values at device addresses `keys` and
/// `values`, on `stream` as a launch there (a deterministic launch's ordering,
/// `cuda/deterministic.rs`).
pub(super) fn sort_u32_pairs_on(
    device: &Device,
    ordinal: usize,
    stream: Option<&warp_cuda::Stream>,
    func: &'static str,
    keys: u64,
    values: u64,
    n: usize,
) -> Result<()> {
    let p = plan::sort(
        plan::gpu_sort_config(),
        <u32 as SortKeyOps>::CUDA,
        32,
        plan::Len::Host(n as u64),
    );
    run_on(
        device,
        ordinal,
        stream,
        func,
        &["keys", "values", "count"],
        &p,
        &[keys, values],
    )
}

/// `compact_n` on a GPU: `arrays` are values, flags, out, out_count.
pub(super) fn compact<T: bytemuck::Pod>(
    device: &Device,
    ordinal: usize,
    func: &'static str,
    arrays: [u64; 4],
    len: Extent,
) -> Result<()> {
    let mut users = arrays.to_vec();
    let len = plan_len(len, &mut users, 4);
    let (word, words) = blob_words::<T>();
    let p = plan::compact(GPU_TILE, word, words, len);
    let params = &["values", "flags", "out", "out_count", "count"];
    run(device, ordinal, func, params, &p, &users)
}

/// How a GPU moves an element of compaction: `words` words of `word` bytes (the widest word
/// that divides the element's size and alignment).
fn blob_words<T>() -> (u32, u32) {
    let (size, align) = (std::mem::size_of::<T>(), std::mem::align_of::<T>());
    let word = [8, 4, 2, 1]
        .into_iter()
        .find(|&w| size % w == 0 && align >= w)
        .unwrap_or(1);
    (word as u32, (size / word) as u32)
}

/// Compiles a module of the primitives with NVRTC for `sm_{arch}`, with the options the
/// runtime uses (no GPU needed, only libnvrtc): how the tests check that NVRTC accepts every
/// module on machines without a GPU.
pub fn compile_module(module: &Module, arch: u32) -> warp_cuda::Result<warp_cuda::Compiled> {
    with_options(module, |opts| {
        warp_cuda::compile(&module.source(), &module.name(), opts, arch)
    })
}

#[cfg(test)]
mod tests {
    use super::{blob_words, scratch_layout};
    use glam::{DVec3, Vec3};

    #[test]
    fn blobs_use_the_widest_word() {
        assert_eq!(blob_words::<u8>(), (1, 1));
        assert_eq!(blob_words::<warp_core::f16>(), (2, 1));
        assert_eq!(blob_words::<Vec3>(), (4, 3));
        assert_eq!(blob_words::<DVec3>(), (8, 3));
        assert_eq!(blob_words::<f64>(), (8, 1));
    }

    #[test]
    fn scratch_slices_are_aligned_and_disjoint() {
        assert_eq!(scratch_layout(&[]), (vec![], 0));
        assert_eq!(
            scratch_layout(&[4, 0, 300, 8]),
            (vec![0, 256, 256, 768], 1024)
        );
    }
}

//! Runs the primitives' launch plans on a GPU.
//!
//! Each plan names one module of `wp_primitives.h` (scan of one element type, sort of one
//! key type, compaction of one element size). A module is compiled by NVRTC through the
//! kernel disk cache the first time a GPU needs it, loaded, and kept for the process, like a
//! kernel. A plan's launches go on the calling thread's current stream (the ordering model of
//! `cuda.rs`: after the array operations queued before; the scratch arrays are freed on the
//! default stream after them), with no host synchronisation: counts stay on the device.

use super::plan::{Buf, Module, Plan, Word, GPU_TILE};
use crate::array::Array;
use crate::config;
use crate::device::{Device, DeviceKind};
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::{Arc, Mutex, OnceLock};
use warp_cuda::{CompileOptions, Function};

/// A module loaded on one GPU, with the entries looked up so far.
struct Loaded {
    module: warp_cuda::Module,
    functions: Mutex<HashMap<String, Function>>,
}

impl Loaded {
    fn function(&self, device: &Device, name: &str) -> Result<Function> {
        let mut fns = self.functions.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(f) = fns.get(name) {
            return Ok(f.clone());
        }
        let f = self
            .module
            .function(name)
            .map_err(|e| crate::cuda::err(device, e))?;
        fns.insert(name.to_string(), f.clone());
        Ok(f)
    }
}

/// The library headers a module needs (handing NVRTC the whole library would only cost
/// compile time and cache-key hashing).
fn headers() -> Vec<(&'static str, &'static str)> {
    warp_cuda::HEADERS
        .iter()
        .copied()
        .filter(|(name, _)| matches!(*name, "wp_core.h" | "wp_primitives.h"))
        .collect()
}

/// Calls `f` with the NVRTC options of every primitives module: the GPU tile's defines,
/// the two headers, FMA contraction as `config::cuda_fmad` says (sums of products do not
/// occur, so it changes nothing here but keeps one setting for all GPU code).
pub(super) fn with_options<R>(f: impl FnOnce(&CompileOptions) -> R) -> R {
    let defines = GPU_TILE.defines();
    let defines: Vec<(&str, &str)> = defines.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let headers = headers();
    f(&CompileOptions {
        fmad: config::cuda_fmad(),
        line_info: true,
        defines: &defines,
        headers: &headers,
        ..Default::default()
    })
}

/// `module` compiled and loaded for GPU `ordinal` (once per process).
fn loaded(device: &Device, ordinal: usize, module: &Module) -> Result<Arc<Loaded>> {
    type Cache = Mutex<HashMap<(usize, Module), Arc<Loaded>>>;
    static CACHE: OnceLock<Cache> = OnceLock::new();
    let cache = CACHE.get_or_init(Default::default);
    let key = (ordinal, module.clone());
    if let Some(l) = cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return Ok(l.clone());
    }
    let st = crate::cuda::state(device, ordinal)?;
    let (compiled, _) = with_options(|opts| {
        warp_cuda::compile_cached(&module.source(), &module.name(), opts, st.gpu.arch())
    })
    .map_err(|e| crate::cuda::err(device, e))?;
    let m = st
        .gpu
        .load_module(&compiled.cubin)
        .map_err(|e| crate::cuda::err(device, e))?;
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
            written: &[],
            tid_ndim: None,
            same_shape: &[],
            file: "",
            cuda: "",
            cuda_sections: &[],
            callees: &[],
            structs: &[],
            adjoint_error: None,
            cuda_adjoint: "",
            cuda_adjoint_stack: false,
            cuda_adjoint_error: None,
            consts: &[],
        }))
    })
}

/// Runs `plan` on `device` (a GPU) for primitive `func` (whose parameters, for fault
/// reports, are `params`); `users` are the device addresses of the caller's arrays in the
/// plan's order.
pub(super) fn run(
    func: &'static str,
    params: &'static [&'static str],
    device: &Device,
    plan: &Plan,
    users: &[u64],
) -> Result<()> {
    let DeviceKind::Cuda { ordinal } = device.kind() else {
        return Err(Error::invalid(format!(
            "{func}: not a CUDA device: {device}"
        )));
    };
    let module = loaded(device, ordinal, &plan.module)?;
    let st = crate::cuda::state(device, ordinal)?;
    // Scratch: plain arrays, so allocation and free follow the arrays' stream ordering.
    let scratch = plan
        .scratch
        .iter()
        .map(|&bytes| Array::<u64>::empty((bytes as usize).div_ceil(8), device))
        .collect::<Result<Vec<_>>>()?;
    let (fault, flag) = st.fault_record_for(info(func, params));
    let word = |w: &Word| -> u64 {
        match *w {
            Word::Addr(Buf::User(k), off) => users[k] + off,
            Word::Addr(Buf::Scratch(k), off) => scratch[k].device_ptr().unwrap_or(0) + off,
            Word::Null => 0,
            Word::Int(v) => v as u64,
            Word::Fault => fault,
            Word::FaultFlag => flag,
        }
    };
    let mut launches = Vec::with_capacity(plan.steps.len());
    for s in &plan.steps {
        let blocks = u32::try_from(s.blocks).map_err(|_| {
            Error::invalid(format!(
                "{func}: {} blocks of {} elements are more than a grid holds",
                s.blocks,
                GPU_TILE.elements()
            ))
        })?;
        let mut args = [0u64; 16];
        for (a, w) in args.iter_mut().zip(&s.args) {
            *a = word(w);
        }
        launches.push((module.function(device, &s.entry)?, blocks, args));
    }
    st.queue(ordinal, None, |stream| {
        for (f, blocks, args) in &mut launches {
            let mut params = [args.as_mut_ptr() as *mut c_void];
            // SAFETY: every entry takes one `wp::prim::args_t` (16 u64 words) by value, which
            // `params[0]` points at; the words are device addresses of live arrays (the
            // caller's, checked to hold what the plan touches, and the scratch, alive until
            // after the queued frees) and integers.
            unsafe {
                st.gpu
                    .launch_raw(f, stream, *blocks, GPU_TILE.threads, 0, &mut params)
                    .map_err(|e| crate::cuda::err(device, e))?;
            }
        }
        Ok(())
    })?;
    // The scratch frees queue on the default stream after the launches (see `Storage::drop`).
    drop(scratch);
    if config::debug() {
        crate::cuda::check_faults(device)?;
    }
    Ok(())
}

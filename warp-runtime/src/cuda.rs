//! The CUDA side of the runtime: GPU handles, compiled kernels, fault records, launch.
//!
//! A kernel is compiled for a GPU at its first launch there: its translation unit is assembled
//! (`cuda_source`), compiled by NVRTC to a cubin for that GPU's architecture through the disk
//! cache (`warp_cuda::compile_cached`), loaded, and kept for the process. Launches are
//! asynchronous on the GPU's stream. Threads record faults (out-of-bounds index, integer
//! division by zero, bad step) in a per-GPU record; it is read after each launch in debug mode,
//! and otherwise at the next synchronisation (`synchronize`, `to_vec`).

use crate::config;
use crate::cuda_source;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::{ArgsOf, Kernel, KernelInfo, KernelParams, MAX_PARAMS};
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use warp_core::{Fault, FaultKind, Grid};
use warp_cuda::{CacheOutcome, CompileOptions, CudaError, DeviceBuffer, Function, Gpu, Module};

/// A CUDA error on `device` as a runtime error.
pub(crate) fn err(device: &Device, e: CudaError) -> Error {
    Error::Cuda {
        device: device.alias().to_string(),
        message: e.to_string(),
    }
}

/// The opened GPU `ordinal`.
pub(crate) fn gpu(ordinal: usize) -> Result<Arc<Gpu>> {
    Gpu::open(ordinal).map_err(|e| Error::Cuda {
        device: format!("cuda:{ordinal}"),
        message: e.to_string(),
    })
}

/// `wp::fault_t` (80 bytes) followed by the `u32` flag the first faulting thread sets.
const FAULT_RECORD_BYTES: usize = 80;
const FAULT_BYTES: usize = FAULT_RECORD_BYTES + 8;

/// Per-GPU state: the fault record, the last kernel launched (named in fault reports), and
/// the user streams with work queued since the default stream last waited for them.
///
/// The ordering model (see `stream.rs`): array operations (allocation, copies, fills, frees)
/// and launches without a stream run on the GPU's default stream, which first waits for every
/// user stream that has had work since it last did (`pending`); a launch on a user stream
/// first waits for the default stream. So array memory is never freed or rewritten under a
/// kernel still using it, and kernels on different user streams may overlap.
pub(crate) struct GpuState {
    device: Device,
    pub(crate) gpu: Arc<Gpu>,
    fault: DeviceBuffer,
    last: Mutex<Option<&'static KernelInfo>>,
    pending: Mutex<Vec<warp_cuda::Stream>>,
    has_pending: AtomicBool,
}

impl GpuState {
    /// Makes the default stream wait for the user streams with work queued since it last did.
    fn join_pending(&self) -> Result<()> {
        if !self.has_pending.load(Ordering::Acquire) {
            return Ok(());
        }
        let mut pending = self.pending.lock().unwrap_or_else(|p| p.into_inner());
        let default = self.gpu.default_stream();
        for s in pending.drain(..) {
            default.wait_stream(&s).map_err(|e| err(&self.device, e))?;
        }
        self.has_pending.store(false, Ordering::Release);
        Ok(())
    }

    /// Queues work (`enqueue`) on `stream` when given, else on the calling thread's current
    /// stream for this GPU (`ScopedStream`), else on the default stream, with the ordering of
    /// the model above: a user stream first waits for the default stream and is then pending;
    /// the default stream first joins the pending streams.
    pub(crate) fn queue(
        &self,
        ordinal: usize,
        stream: Option<&warp_cuda::Stream>,
        enqueue: impl FnOnce(&warp_cuda::Stream) -> Result<()>,
    ) -> Result<()> {
        let default = self.gpu.default_stream();
        let scoped;
        let user = match stream {
            Some(s) => Some(s),
            None => {
                scoped = crate::stream::current(ordinal);
                scoped.as_ref()
            }
        }
        .filter(|s| !s.is(default));
        match user {
            Some(s) => {
                // Arrays are allocated and written on the default stream.
                s.wait_stream(default).map_err(|e| err(&self.device, e))?;
                enqueue(s)?;
                self.mark_pending(s);
                Ok(())
            }
            None => {
                self.join_pending()?;
                enqueue(default)
            }
        }
    }

    /// Records that `stream` (a user stream) has work the default stream must wait for.
    fn mark_pending(&self, stream: &warp_cuda::Stream) {
        let mut pending = self.pending.lock().unwrap_or_else(|p| p.into_inner());
        if !pending.iter().any(|s| s.is(stream)) {
            pending.push(stream.clone());
        }
        self.has_pending.store(true, Ordering::Release);
    }
}

/// Orders work about to be queued on `device`'s default stream (an array operation) after
/// the work of its user streams. Nothing to do for the CPU or a GPU never used.
pub(crate) fn before_default_work(device: &Device) -> Result<()> {
    match device.kind() {
        crate::device::DeviceKind::Cuda { ordinal } => join_ordinal(ordinal),
        crate::device::DeviceKind::Cpu => Ok(()),
    }
}

/// [`before_default_work`] for GPU `ordinal`.
pub(crate) fn join_ordinal(ordinal: usize) -> Result<()> {
    let st = states_map()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .get(&ordinal)
        .cloned();
    match st {
        Some(st) => st.join_pending(),
        None => Ok(()),
    }
}

fn states_map() -> &'static Mutex<HashMap<usize, Arc<GpuState>>> {
    static STATES: OnceLock<Mutex<HashMap<usize, Arc<GpuState>>>> = OnceLock::new();
    STATES.get_or_init(Default::default)
}

pub(crate) fn state(device: &Device, ordinal: usize) -> Result<Arc<GpuState>> {
    let mut map = states_map().lock().unwrap_or_else(|p| p.into_inner());
    if let Some(s) = map.get(&ordinal) {
        return Ok(s.clone());
    }
    let g = gpu(ordinal)?;
    let fault = DeviceBuffer::zeros(&g, FAULT_BYTES).map_err(|e| err(device, e))?;
    let s = Arc::new(GpuState {
        device: device.clone(),
        gpu: g,
        fault,
        last: Mutex::new(None),
        pending: Mutex::new(Vec::new()),
        has_pending: AtomicBool::new(false),
    });
    map.insert(ordinal, s.clone());
    Ok(s)
}

/// The states of the GPUs used so far (a GPU never used has nothing to synchronise).
fn states() -> Vec<Arc<GpuState>> {
    states_map()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .values()
        .cloned()
        .collect()
}

/// A kernel compiled and loaded for one GPU, with that GPU's state (one lookup per launch).
struct Loaded {
    st: Arc<GpuState>,
    _module: Module,
    function: Function,
}

/// What compiling a kernel cost, for reports.
#[derive(Clone, Debug)]
pub struct CompileReport {
    /// The kernel.
    pub kernel: &'static str,
    /// `module_path!()` where the kernel is defined (two kernels may share a name).
    pub module: &'static str,
    /// The device it was compiled for.
    pub device: String,
    /// Whether this is the variant for launches whose arrays are all contiguous.
    pub contiguous: bool,
    /// Whether this is the kernel's adjoint (compiled when backward first ran on the GPU).
    pub adjoint: bool,
    /// Bytes of generated CUDA source (without the library headers).
    pub source_bytes: usize,
    /// NVRTC time (0 on a cache hit).
    pub compile_ms: f64,
    /// Whether the cubin came from the disk cache (or the ahead-of-time directory).
    pub cache_hit: bool,
    /// Whether it came from the ahead-of-time directory (`aot`).
    pub aot: bool,
    /// Time from the start of the first launch to a loaded module.
    pub total_ms: f64,
}

fn reports() -> &'static Mutex<Vec<CompileReport>> {
    static R: OnceLock<Mutex<Vec<CompileReport>>> = OnceLock::new();
    R.get_or_init(Default::default)
}

/// What each kernel compiled so far in this process cost (per device, variant, and forward
/// or adjoint).
pub fn compile_reports() -> Vec<CompileReport> {
    reports().lock().unwrap_or_else(|p| p.into_inner()).clone()
}

/// One line per report (see `compile_summary`).
pub(crate) fn format_compile_reports(reports: &[CompileReport]) -> String {
    use std::fmt::Write as _;
    let mut s = format!(
        "compiled at run time: {} kernel variant(s)\n",
        reports.len()
    );
    for r in reports {
        let source = if r.aot {
            "ahead-of-time cubin".to_string()
        } else if r.cache_hit {
            "disk cache hit".to_string()
        } else {
            format!("NVRTC {:.1} ms", r.compile_ms)
        };
        // The path below the crate: `single::accelerations` beside `double::accelerations`.
        let name = match r.module.split_once("::") {
            Some((_, inner)) => format!("{inner}::{}", r.kernel),
            None => r.kernel.to_string(),
        };
        let _ = writeln!(
            s,
            "  {name:<26} {:<7} {:<10} {:>6} bytes of CUDA, {source}, loaded in {:.1} ms on {}",
            if r.adjoint { "adjoint" } else { "forward" },
            if r.contiguous {
                "contiguous"
            } else {
                "strided"
            },
            r.source_bytes,
            r.total_ms,
            r.device
        );
    }
    s
}

/// The kernel `info` compiled for GPU `ordinal`; `contiguous` picks the variant for launches
/// whose arrays are all contiguous (`WP_CONTIGUOUS`: strides known to the compiler). Each
/// variant is compiled the first time a launch needs it.
///
/// `adjoint: Some(bytes)` picks the adjoint unit instead, with `bytes` of adjoint stack per
/// thread (`WP_ADSTACK_BYTES`).
fn loaded(
    device: &Device,
    ordinal: usize,
    info: &'static KernelInfo,
    contiguous: bool,
    adjoint: Option<usize>,
) -> Result<Arc<Loaded>> {
    type Key = (usize, &'static str, &'static str, bool, Option<usize>);
    static CACHE: OnceLock<Mutex<HashMap<Key, Arc<Loaded>>>> = OnceLock::new();
    let key = (ordinal, info.module, info.name, contiguous, adjoint);
    let cache = CACHE.get_or_init(Default::default);
    if let Some(l) = cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return Ok(l.clone());
    }
    let st = state(device, ordinal)?;
    let t0 = std::time::Instant::now();
    let src = match adjoint {
        Some(_) => cuda_source::assemble_adjoint(info),
        None => cuda_source::assemble(info),
    };
    let arch = st.gpu.arch();
    let stack_define = adjoint.map(|b| b.to_string());
    let (compiled, outcome, aot) =
        with_compile_options(contiguous, stack_define.as_deref(), |opts| {
            // An ahead-of-time entry first: it needs no NVRTC (not even loading it).
            if let Some(cubin) = crate::aot::lookup(&src.text, info.name, opts, arch) {
                let c = warp_cuda::Compiled {
                    cubin,
                    log: String::new(),
                    compile_ms: 0.0,
                };
                return Ok((c, CacheOutcome::Hit, true));
            }
            warp_cuda::compile_cached(&src.text, info.name, opts, arch).map(|(c, o)| (c, o, false))
        })
        .map_err(|e| err(device, e))?;
    let module = st
        .gpu
        .load_module(&compiled.cubin)
        .map_err(|e| err(device, e))?;
    let function = module.function(&src.entry).map_err(|e| err(device, e))?;
    reports()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .push(CompileReport {
            kernel: info.name,
            module: info.module,
            device: device.alias().to_string(),
            contiguous,
            adjoint: adjoint.is_some(),
            source_bytes: src.text.len(),
            compile_ms: compiled.compile_ms,
            cache_hit: matches!(outcome, CacheOutcome::Hit),
            aot,
            total_ms: t0.elapsed().as_secs_f64() * 1e3,
        });
    let l = Arc::new(Loaded {
        st,
        _module: module,
        function,
    });
    cache
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(key, l.clone());
    Ok(l)
}

/// Calls `f` with the NVRTC options of a kernel translation unit (the runtime's and the
/// ahead-of-time compiler's, which must agree for AOT entries to be found).
/// `adstack_bytes`: the per-thread adjoint stack of an adjoint unit.
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

/// `wp::launch_t`.
#[repr(C)]
#[derive(Clone, Copy)]
struct LaunchDims {
    dims: [i64; 4],
    total: i64,
    ndim: i32,
    fast: i32,
}

/// `wp::ctx_t`.
#[repr(C)]
#[derive(Clone, Copy)]
struct Ctx {
    fault: u64,
    fault_flag: u64,
    raised: i32,
    pad: i32,
}

/// Launches `K` over `grid` on GPU `ordinal`: on `stream` when given, else on the calling
/// thread's current stream for the GPU (`ScopedStream`), else on the default stream.
///
/// `adjoint: Some(bytes)` launches the kernel's adjoint instead (with `bytes` of adjoint stack
/// per thread): the arrays' gradients follow the parameters.
pub(crate) fn launch<K: Kernel>(
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    device: &Device,
    ordinal: usize,
    stream: Option<&warp_cuda::Stream>,
    adjoint: Option<usize>,
) -> Result<()> {
    let info = K::info();
    if adjoint.is_some() {
        if let Some(reason) = info.cuda_adjoint_error {
            return Err(Error::NotDifferentiable {
                kernel: info.name,
                reason: reason.to_string(),
            });
        }
    }
    // Arguments first: a wrong device is reported before anything is compiled.
    let mut params = K::Params::cuda_params(args, info, device)?;
    let mut grads = match adjoint {
        Some(_) => Some(K::Params::cuda_grads(args, info, device)?),
        None => None,
    };
    let kernel = loaded(device, ordinal, info, K::Params::contiguous(args), adjoint)?;
    let st = &kernel.st;
    let mut dims = LaunchDims {
        dims: grid.dims.map(|d| d as i64),
        total: grid.total as i64,
        ndim: grid.ndim as i32,
        fast: K::Params::cover(args, info.tid_indexed, grid) as i32,
    };
    let base = st.fault.device_ptr();
    let mut ctx = Ctx {
        fault: base,
        fault_flag: base + FAULT_RECORD_BYTES as u64,
        raised: 0,
        pad: 0,
    };
    // The launch and the context, then the parameters and (adjoint) their gradients.
    let mut ptrs = [std::ptr::null_mut::<c_void>(); 2 + 2 * MAX_PARAMS];
    ptrs[0] = (&mut dims) as *mut LaunchDims as *mut c_void;
    ptrs[1] = (&mut ctx) as *mut Ctx as *mut c_void;
    let mut n = 2 + K::Params::cuda_param_ptrs(&mut params, &mut ptrs[2..]);
    if let Some(g) = grads.as_mut() {
        n += K::Params::cuda_grad_ptrs(g, &mut ptrs[n..]);
    }
    let block = config::cuda_block_dim();
    let blocks = grid.total.div_ceil(block as usize).min(i32::MAX as usize) as u32;
    *st.last.lock().unwrap_or_else(|p| p.into_inner()) = Some(info);
    st.queue(ordinal, stream, |on| {
        // SAFETY: `ptrs[..n]` point at values laid out as the kernel's C++ parameters
        // (launch_t, ctx_t, then each parameter's CudaArg, which mirrors its C++ type), alive
        // until the call returns; cuLaunchKernel copies them.
        unsafe {
            st.gpu
                .launch_raw(&kernel.function, on, blocks, block, 0, &mut ptrs[..n])
                .map_err(|e| err(device, e))
        }
    })?;
    if config::debug() {
        check_state(st)?;
    }
    Ok(())
}

/// Waits for `device` and reports a fault recorded since the last check.
pub(crate) fn check_faults(device: &Device) -> Result<()> {
    match device.kind() {
        crate::device::DeviceKind::Cuda { ordinal } => check_state(&*state(device, ordinal)?),
        crate::device::DeviceKind::Cpu => Ok(()),
    }
}

fn check_state(st: &GpuState) -> Result<()> {
    st.gpu.synchronize().map_err(|e| err(&st.device, e))?;
    // Every stream is idle: nothing is pending any more.
    st.pending.lock().unwrap_or_else(|p| p.into_inner()).clear();
    st.has_pending.store(false, Ordering::Release);
    read_fault(st)
}

/// Reports (and clears) the fault recorded on the GPU, if any, without waiting for the
/// GPU's other work (the read waits for the default stream only).
pub(crate) fn read_fault(st: &GpuState) -> Result<()> {
    let device = &st.device;
    let mut rec = [0u8; FAULT_BYTES];
    st.fault.download(0, &mut rec).map_err(|e| err(device, e))?;
    let flag = u32::from_le_bytes(
        rec[FAULT_RECORD_BYTES..FAULT_RECORD_BYTES + 4]
            .try_into()
            .expect("4 bytes"),
    );
    if flag == 0 {
        return Ok(());
    }
    st.fault
        .upload(0, &[0u8; FAULT_BYTES])
        .map_err(|e| err(device, e))?;
    let i32_at = |o: usize| i32::from_le_bytes(rec[o..o + 4].try_into().expect("4 bytes"));
    let i64_at = |o: usize| i64::from_le_bytes(rec[o..o + 8].try_into().expect("8 bytes"));
    let (kind, arg, ndim) = (i32_at(0), i32_at(4), i32_at(72).clamp(0, 4) as usize);
    let info = st
        .last
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .unwrap_or(&UNKNOWN);
    let kind = match kind {
        4 => FaultKind::AdStackOverflow {
            line: i64_at(8) as u32,
            capacity: i64_at(40) as usize,
        },
        1 => FaultKind::OutOfBounds {
            arg: info.params.get(arg as usize).copied().unwrap_or("?"),
            index: (0..ndim).map(|k| i64_at(8 + 8 * k) as i128).collect(),
            shape: (0..ndim).map(|k| i64_at(40 + 8 * k) as usize).collect(),
        },
        2 => FaultKind::DivisionByZero,
        _ => FaultKind::BadStep { step: i64_at(8) },
    };
    Err(Error::Fault(Fault {
        kernel: info.name,
        kind,
    }))
}

static UNKNOWN: KernelInfo = KernelInfo {
    name: "?",
    module: "",
    params: &[],
    written: &[],
    tid_indexed: &[],
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
};

/// Waits for every GPU used so far and reports the first recorded fault.
pub(crate) fn synchronize_all() -> Result<()> {
    for st in states() {
        check_state(&st)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::{format_compile_reports, CompileReport};

    fn report(module: &'static str, adjoint: bool, cache_hit: bool) -> CompileReport {
        CompileReport {
            kernel: "accelerations",
            module,
            device: "cuda:0".into(),
            contiguous: true,
            adjoint,
            source_bytes: 5730,
            compile_ms: if cache_hit { 0.0 } else { 145.25 },
            cache_hit,
            aot: false,
            total_ms: 156.3,
        }
    }

    #[test]
    fn summary_names_module_direction_and_source() {
        let s = format_compile_reports(&[
            report("nbody::single", false, false),
            report("nbody::double", true, true),
            report("top", false, true),
        ]);
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(lines[0], "compiled at run time: 3 kernel variant(s)");
        assert!(lines[1].contains("single::accelerations") && lines[1].contains("forward"));
        assert!(
            lines[1].contains("5730 bytes of CUDA, NVRTC 145.2 ms"),
            "{}",
            lines[1]
        );
        assert!(lines[2].contains("double::accelerations") && lines[2].contains("adjoint"));
        assert!(lines[2].contains("disk cache hit"), "{}", lines[2]);
        assert!(
            lines[3].trim_start().starts_with("accelerations "),
            "{}",
            lines[3]
        );
    }
}

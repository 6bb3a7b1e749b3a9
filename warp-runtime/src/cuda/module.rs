//! Kernels compiled and loaded per GPU, and what compiling them cost.
//!
//! A kernel is compiled for a GPU at its first launch there: its translation unit is assembled
//! (`source`), compiled by NVRTC to a cubin for that GPU's architecture (an ahead-of-time
//! cubin first, then the disk cache, `KernelCache::compile_cached_entry`), loaded, and kept
//! for the process.

use super::gpu::{err, state, GpuState};
use super::options::{needs_exact, with_compile_options, TileDefines};
use super::{aot, source};
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, OnceLock};
use warp_core::capability::{first_missing, Capability, Support, Target};
use warp_core::FuncInfo;
use warp_cuda::cache::CacheEntry;
use warp_cuda::{CacheOutcome, Function, KernelCache, Module};

/// A kernel compiled and loaded for one GPU, with that GPU's state (one lookup per launch).
pub(crate) struct Loaded {
    pub(crate) st: Arc<GpuState>,
    _module: Module,
    pub(crate) function: Function,
    /// What its launches put in `wp::launch_ctx_t::kernel`, so that a fault names this kernel.
    pub(crate) id: i32,
    /// The dynamic shared memory each block of its launches takes ([`tile_shared`]).
    pub(crate) shared_bytes: usize,
    /// A deterministic kernel's ordering and addition entries (`cuda/deterministic.rs`).
    pub(crate) det: Option<super::deterministic::DetFns>,
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
    /// Whether this is the kernel's adjoint (compiled when backward first ran on the GPU, or
    /// with the forward: `one_unit`).
    pub adjoint: bool,
    /// A tiled kernel's block size (each its own variant); `None` for an ordinary kernel.
    pub block_dim: Option<usize>,
    /// The dynamic shared memory each block of a tiled kernel takes on this device (0 for an
    /// ordinary kernel): its tiles' slots, and for the forward kernel the extra stages of its
    /// pipelined f16 GEMM k-loops where the device grants them (`pipe_extra_bytes` of it).
    pub shared_bytes: usize,
    /// Of `shared_bytes`, the pipelined GEMM k-loops' extra stages.
    pub pipe_extra_bytes: usize,
    /// Bytes of generated CUDA source (without the library headers).
    pub source_bytes: usize,
    /// NVRTC time (0 on a cache hit, and on the adjoint's report of a unit of both halves).
    pub compile_ms: f64,
    /// Whether the cubin came from the disk cache (or the ahead-of-time directory).
    pub cache_hit: bool,
    /// Whether it came from the ahead-of-time directory (`aot`).
    pub aot: bool,
    /// Time from the start of the first launch to a loaded module (0 on the adjoint's report
    /// of a unit of both halves).
    pub total_ms: f64,
    /// The key the cubin is stored under: a 128-bit hash of the generated source (with its
    /// `#line` directives, so the kernel's file and lines count), the NVRTC options, the
    /// headers, the architecture, this crate's version and (in the kernel cache, not for an
    /// ahead-of-time cubin) the NVRTC version. Printed as 32 hex digits it is the end of the
    /// entry's file name, `<kernel>-<key>.cubin`. A kernel whose body changes gets a new key,
    /// so it is compiled again.
    pub cache_key: u128,
    /// The cubin's file: the kernel cache entry (read on a hit, written after a compile;
    /// `warp_cuda::cache_dir()`), or the ahead-of-time entry when `aot` is set. `None` when a
    /// compiled cubin could not be written to the cache (the kernel still runs).
    pub cache_entry: Option<PathBuf>,
    /// Whether the forward and the adjoint came from one translation unit, compiled (or read
    /// from the kernel cache) and loaded once for both: the kernel's first launch was under a
    /// recording tape, or in `load_with_adjoints`. Each has its report, both with this set and
    /// the same key, entry and source; the unit's NVRTC and loading times are on the
    /// forward's, the adjoint's has 0 for both, so that sums over reports count each unit
    /// once ([`CompileReport::is_unit`]).
    pub one_unit: bool,
}

impl CompileReport {
    /// Whether this report carries a unit's cost: every report but the adjoint's of a unit of
    /// both halves (`one_unit`). Counting these counts NVRTC runs and module loads.
    pub fn is_unit(&self) -> bool {
        !(self.one_unit && self.adjoint)
    }
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
    let units = reports.iter().filter(|r| r.is_unit()).count();
    let mut s = format!(
        "compiled at run time: {} kernel variant(s) in {units} unit(s)\n",
        reports.len()
    );
    for r in reports {
        let source = if !r.is_unit() {
            "in the forward's unit".to_string()
        } else if r.aot {
            "ahead-of-time cubin".to_string()
        } else if r.cache_hit {
            "disk cache hit".to_string()
        } else {
            format!("NVRTC {:.1} ms", r.compile_ms)
        };
        let source = if r.one_unit && !r.adjoint {
            format!("{source}, one unit with the adjoint")
        } else {
            source
        };
        // The path below the crate: `single::accelerations` beside `double::accelerations`.
        let name = match r.module.split_once("::") {
            Some((_, inner)) => format!("{inner}::{}", r.kernel),
            None => r.kernel.to_string(),
        };
        // A tiled kernel's variants differ by block size: name it with the kernel.
        let name = match r.block_dim {
            Some(bd) => format!("{name} [block_dim {bd}]"),
            None => name,
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

/// A loaded kernel variant's key: the GPU, the kernel's module path and name, the contiguous
/// variant or not, the adjoint's stack (`None`: the forward), a tiled kernel's block size.
type Key = (
    usize,
    &'static str,
    &'static str,
    bool,
    Option<usize>,
    Option<usize>,
);

/// The kernel variants loaded in this process.
fn loaded_variants() -> &'static Mutex<HashMap<Key, Arc<Loaded>>> {
    static CACHE: OnceLock<Mutex<HashMap<Key, Arc<Loaded>>>> = OnceLock::new();
    CACHE.get_or_init(Default::default)
}

/// The variant of `key` if it is loaded.
fn loaded_variant(key: &Key) -> Option<Arc<Loaded>> {
    loaded_variants()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .get(key)
        .cloned()
}

/// Keeps `l` as the variant of `key` (for the process) and returns it.
fn keep(key: Key, l: Loaded) -> Arc<Loaded> {
    let l = Arc::new(l);
    loaded_variants()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .insert(key, l.clone());
    l
}

/// The kernel `info` compiled for GPU `ordinal`; `contiguous` picks the variant for launches
/// whose arrays are all contiguous (`WP_CONTIGUOUS`: strides known to the compiler). Each
/// variant is compiled the first time a launch needs it.
///
/// `adjoint: Some(bytes)` picks the adjoint unit instead, with `bytes` of adjoint stack per
/// thread (`WP_ADSTACK_BYTES`).
///
/// `block_dim: Some(n)` (a tiled kernel: `info.tile` is set) picks the variant for blocks of
/// `n` threads (`WP_TILE_BLOCK_DIM`), each block size its own module, and checks at load that
/// the GPU can run such blocks with the shared memory the kernel's tiles take
/// ([`check_tile_budget`]), so that a launch never fails for it.
///
/// `with_adjoint` is asked only when an ordinary kernel's forward is to be loaded: `Some(bytes)`
/// when its adjoint will be needed too, with that stack (a tape records the launch, or
/// `load_with_adjoints`). Unless the kernel has no CUDA adjoint, or one of the two variants is
/// loaded or compiled already (an ahead-of-time cubin, a kernel cache entry: it is used, and
/// the other compiled when it is needed), both then come from one unit
/// (`source::assemble_with_adjoint`): one NVRTC run, which parses the library and the funcs
/// once instead of twice, and one module, whose two functions are kept under both variants'
/// keys. (A tiled kernel's units differ in their shared memory defines: never one unit.)
pub(crate) fn loaded(
    device: &Device,
    ordinal: usize,
    info: &'static KernelInfo,
    contiguous: bool,
    adjoint: Option<usize>,
    block_dim: Option<usize>,
    with_adjoint: impl FnOnce() -> Option<usize>,
) -> Result<Arc<Loaded>> {
    let key = (
        ordinal,
        info.module,
        info.name,
        contiguous,
        adjoint,
        block_dim,
    );
    if let Some(l) = loaded_variant(&key) {
        // Every launch that is not a launch object comes here: nothing is formatted unless a
        // logger asked for trace records of this target.
        if log::log_enabled!(log::Level::Trace) {
            log::trace!(
                "module cache hit: {}::{} on {device} ({}, {})",
                info.module,
                info.name,
                variant_name(adjoint),
                layout_name(contiguous)
            );
        }
        return Ok(l);
    }
    log::debug!(
        "module cache miss: {}::{} on {device} ({}, {}): loading it",
        info.module,
        info.name,
        variant_name(adjoint),
        layout_name(contiguous)
    );
    // Loading a module inside a stream capture would break it; wp::load compiles before.
    super::gpu::refuse_in_capture(
        ordinal,
        &format!(
            "compiling kernel `{}` ({}, {}) at its first launch: load it before capturing with \
             wp::load{}(&[wp::kernel_info({})]{}, &device)",
            info.name,
            if adjoint.is_some() {
                "adjoint"
            } else {
                "forward"
            },
            if contiguous {
                "contiguous arrays"
            } else {
                "strided arrays: launch it once before capturing"
            },
            if block_dim.is_some() {
                "_tiled"
            } else if adjoint.is_some() {
                "_with_adjoints"
            } else {
                ""
            },
            info.name,
            block_dim.map_or(String::new(), |bd| format!(", {bd}"))
        ),
    )?;
    let t0 = std::time::Instant::now();
    let st = state(device, ordinal)?;
    check_capabilities(info, device.alias(), st.gpu.arch())?;
    let differentiable = info.adjoint_error.is_none() && info.cuda_adjoint_error.is_none();
    let stack = match (adjoint, block_dim) {
        (None, None) if differentiable => with_adjoint().filter(|bytes| {
            loaded_variant(&(
                ordinal,
                info.module,
                info.name,
                contiguous,
                Some(*bytes),
                None,
            ))
            .is_none()
        }),
        _ => None,
    };
    let Some(stack) = stack else {
        return load_variant(device, st, info, contiguous, adjoint, block_dim, None, t0);
    };
    // The forward and the adjoint, each where it is compiled already, else both in one unit.
    let forward = source::assemble(info);
    if let Some(found) = find_compiled(&forward, info.name, contiguous, None, st.gpu.arch()) {
        return load_variant(device, st, info, contiguous, None, None, Some(found), t0);
    }
    let stack_define = stack.to_string();
    let adjoint_src = source::assemble_adjoint(info);
    let arch = st.gpu.arch();
    if find_compiled(
        &adjoint_src,
        info.name,
        contiguous,
        Some(&stack_define),
        arch,
    )
    .is_some()
    {
        // (The adjoint loads its cubin when backward first needs it.)
        return load_variant(device, st, info, contiguous, None, None, None, t0);
    }
    match load_both(device, st.clone(), info, contiguous, stack, t0) {
        Ok(l) => Ok(l),
        Err(e) => {
            // The forward must not fail for its adjoint (one whose code NVRTC refuses, say):
            // it is compiled alone, and the adjoint's error comes when backward needs it.
            log::warn!(
                "kernel {}::{} on {device}: the unit of forward and adjoint failed ({e}); \
                 compiling the forward alone",
                info.module,
                info.name
            );
            load_variant(device, st, info, contiguous, None, None, None, t0)
        }
    }
}

/// A cubin and where it came from.
struct Obtained {
    compiled: warp_cuda::Compiled,
    outcome: CacheOutcome,
    /// From the ahead-of-time directory.
    aot: bool,
    entry: CacheEntry,
}

impl Obtained {
    /// An ahead-of-time entry's cubin, stored under `key` at `path`.
    fn ahead_of_time(cubin: Vec<u8>, key: u128, path: PathBuf) -> Self {
        Obtained {
            compiled: warp_cuda::Compiled {
                cubin,
                log: String::new(),
                compile_ms: 0.0,
            },
            outcome: CacheOutcome::Hit,
            aot: true,
            entry: CacheEntry {
                key,
                path: Some(path),
            },
        }
    }
}

/// The cubin of unit `src` (the variant of `contiguous`, an adjoint's `stack_define`) if it
/// is compiled already: in the ahead-of-time directory or the kernel cache. Never NVRTC.
fn find_compiled(
    src: &source::CudaSource,
    name: &str,
    contiguous: bool,
    stack_define: Option<&str>,
    arch: u32,
) -> Option<Obtained> {
    let exact = needs_exact(&src.headers);
    with_compile_options(contiguous, stack_define, exact, None, |opts| {
        if let Some((cubin, key, path)) = aot::lookup(&src.text, name, opts, arch) {
            return Some(Obtained::ahead_of_time(cubin, key, path));
        }
        let (compiled, entry) = KernelCache::current().lookup_entry(&src.text, name, opts, arch)?;
        Some(Obtained {
            compiled,
            outcome: CacheOutcome::Hit,
            aot: false,
            entry,
        })
    })
}

/// Where a unit's cubin came from, for log records.
fn origin(o: &Obtained) -> String {
    if o.aot {
        "ahead-of-time cubin".to_string()
    } else if matches!(o.outcome, CacheOutcome::Hit) {
        "kernel cache hit".to_string()
    } else {
        format!("NVRTC {:.1} ms", o.compiled.compile_ms)
    }
}

/// One variant of `info` (see [`loaded`]) from its own unit: `found` when [`find_compiled`]
/// found its cubin, else the ahead-of-time directory, the kernel cache or NVRTC. `t0`: when
/// its loading began.
#[allow(clippy::too_many_arguments)]
fn load_variant(
    device: &Device,
    st: Arc<GpuState>,
    info: &'static KernelInfo,
    contiguous: bool,
    adjoint: Option<usize>,
    block_dim: Option<usize>,
    found: Option<Obtained>,
    t0: std::time::Instant,
) -> Result<Arc<Loaded>> {
    let arch = st.gpu.arch();
    let src = match adjoint {
        Some(_) => source::assemble_adjoint(info),
        None => source::assemble(info),
    };
    let stack_define = adjoint.map(|b| b.to_string());
    let unit = |shared: TileShared, found: Option<Obtained>| {
        let tile = block_dim.map(|block_dim| TileDefines {
            block_dim,
            shared_bytes: shared.bytes,
            pipe_extra: shared.pipe_extra,
        });
        compile_unit(
            device,
            &st,
            info,
            &src,
            contiguous,
            stack_define.as_deref(),
            tile,
            found,
            variant_name(adjoint),
        )
    };
    let mut shared = match block_dim {
        Some(_) => tile_shared(info, adjoint.is_some(), arch, || {
            SharedLimits::of(&st.gpu, device)
        })?,
        None => TileShared::default(),
    };
    let (mut module, mut got) = unit(shared, found)?;
    let mut function = module.function(&src.entry).map_err(|e| err(device, e))?;
    // The extra stages were granted counting no static shared memory: with the unit's own,
    // the block must still fit and a multiprocessor hold as many blocks, or the unit is
    // compiled again without them.
    if shared.pipe_extra > 0 {
        let static_bytes = function.static_shared_bytes().map_err(|e| err(device, e))?;
        let limits = SharedLimits::of(&st.gpu, device)?;
        let slots = info.tile.map_or(0, |t| t.shared_bytes);
        if !limits.grants(slots, shared.bytes, static_bytes) {
            log::debug!(
                "kernel {}::{}: {static_bytes} bytes of static shared memory take back the \
                 pipelined loops' extra {} bytes; compiling it without them",
                info.module,
                info.name,
                shared.pipe_extra
            );
            shared = TileShared {
                bytes: slots,
                pipe_extra: 0,
            };
            (module, got) = unit(shared, None)?;
            function = module.function(&src.entry).map_err(|e| err(device, e))?;
        }
    }
    let tile_shared = shared.bytes;
    if let Some(bd) = block_dim {
        let f = |e| err(device, e);
        let budget = TileBudget {
            block_dim: bd,
            dynamic: tile_shared,
            static_bytes: function.static_shared_bytes().map_err(f)?,
            available: st.gpu.max_shared_bytes_per_block_optin().map_err(f)?,
            max_threads: function.max_threads_per_block().map_err(f)? as usize,
        };
        if check_tile_budget(info.name, device.alias(), &budget)? {
            function
                .set_max_dynamic_shared_bytes(tile_shared)
                .map_err(f)?;
        }
    }
    let total_ms = t0.elapsed().as_secs_f64() * 1e3;
    log::info!(
        "loaded kernel {}::{} ({}, {}) on {device} in {total_ms:.1} ms: {}",
        info.module,
        info.name,
        variant_name(adjoint),
        layout_name(contiguous),
        origin(&got)
    );
    report(CompileReport {
        kernel: info.name,
        module: info.module,
        device: device.alias().to_string(),
        contiguous,
        adjoint: adjoint.is_some(),
        block_dim,
        shared_bytes: shared.bytes,
        pipe_extra_bytes: shared.pipe_extra,
        source_bytes: src.text.len(),
        compile_ms: got.compiled.compile_ms,
        cache_hit: matches!(got.outcome, CacheOutcome::Hit),
        aot: got.aot,
        total_ms,
        cache_key: got.entry.key,
        cache_entry: got.entry.path,
        one_unit: false,
    });
    let key = (
        st.gpu.ordinal(),
        info.module,
        info.name,
        contiguous,
        adjoint,
        block_dim,
    );
    Ok(keep(
        key,
        Loaded {
            det: super::deterministic::DetFns::of(device, info, &module, &src.entry)?,
            st,
            _module: module,
            function,
            id: super::fault::kernel_id(info),
            shared_bytes: tile_shared,
        },
    ))
}

/// The forward of the ordinary kernel `info` and its adjoint with `stack` bytes of stack, from
/// one unit (see [`loaded`]): both kept, the forward returned. `t0`: when loading began.
fn load_both(
    device: &Device,
    st: Arc<GpuState>,
    info: &'static KernelInfo,
    contiguous: bool,
    stack: usize,
    t0: std::time::Instant,
) -> Result<Arc<Loaded>> {
    let src = source::assemble_with_adjoint(info);
    let adjoint = src
        .adjoint
        .as_ref()
        .expect("a unit of both halves names its adjoint");
    let stack_define = stack.to_string();
    let (module, got) = compile_unit(
        device,
        &st,
        info,
        &src,
        contiguous,
        Some(&stack_define),
        None,
        None,
        "forward and adjoint",
    )?;
    let forward_fn = module.function(&src.entry).map_err(|e| err(device, e))?;
    let adjoint_fn = module
        .function(&adjoint.entry)
        .map_err(|e| err(device, e))?;
    let det = super::deterministic::DetFns::of(device, info, &module, &src.entry)?;
    let total_ms = t0.elapsed().as_secs_f64() * 1e3;
    log::info!(
        "loaded kernel {}::{} (forward and adjoint in one unit, {}) on {device} in {total_ms:.1} \
         ms: {}",
        info.module,
        info.name,
        layout_name(contiguous),
        origin(&got)
    );
    // One report a variant; the unit's cost on the forward's alone, so that sums count it once.
    let forward_report = CompileReport {
        kernel: info.name,
        module: info.module,
        device: device.alias().to_string(),
        contiguous,
        adjoint: false,
        block_dim: None,
        shared_bytes: 0,
        pipe_extra_bytes: 0,
        source_bytes: src.text.len(),
        compile_ms: got.compiled.compile_ms,
        cache_hit: matches!(got.outcome, CacheOutcome::Hit),
        aot: got.aot,
        total_ms,
        cache_key: got.entry.key,
        cache_entry: got.entry.path,
        one_unit: true,
    };
    let adjoint_report = CompileReport {
        adjoint: true,
        compile_ms: 0.0,
        total_ms: 0.0,
        ..forward_report.clone()
    };
    report(forward_report);
    report(adjoint_report);
    let ordinal = st.gpu.ordinal();
    let id = super::fault::kernel_id(info);
    keep(
        (
            ordinal,
            info.module,
            info.name,
            contiguous,
            Some(stack),
            None,
        ),
        Loaded {
            st: st.clone(),
            _module: module.clone(),
            function: adjoint_fn,
            id,
            shared_bytes: 0,
            det: det.clone(),
        },
    );
    Ok(keep(
        (ordinal, info.module, info.name, contiguous, None, None),
        Loaded {
            st,
            _module: module,
            function: forward_fn,
            id,
            shared_bytes: 0,
            det,
        },
    ))
}

/// Adds `r` to [`compile_reports`].
fn report(r: CompileReport) {
    reports().lock().unwrap_or_else(|p| p.into_inner()).push(r);
}

/// Compiles `info`'s unit `src` (the variant of `contiguous`) with the options of
/// `stack_define` (an adjoint's stack) and `tile`, or takes `found`, or finds it in the
/// ahead-of-time directory or the kernel cache, and loads it on `st`'s GPU. `variant` names
/// the unit's entries in log records.
#[allow(clippy::too_many_arguments)]
fn compile_unit(
    device: &Device,
    st: &GpuState,
    info: &'static KernelInfo,
    src: &source::CudaSource,
    contiguous: bool,
    stack_define: Option<&str>,
    tile: Option<TileDefines>,
    found: Option<Obtained>,
    variant: &str,
) -> Result<(warp_cuda::Module, Obtained)> {
    let arch = st.gpu.arch();
    let exact = needs_exact(&src.headers);
    let got = match found {
        Some(found) => found,
        None => with_compile_options(contiguous, stack_define, exact, tile, |opts| {
            // An ahead-of-time entry first: it needs no NVRTC (not even loading it).
            if let Some((cubin, key, path)) = aot::lookup(&src.text, info.name, opts, arch) {
                return Ok(Obtained::ahead_of_time(cubin, key, path));
            }
            KernelCache::current()
                .compile_cached_entry(&src.text, info.name, opts, arch)
                .map(|(compiled, outcome, entry)| Obtained {
                    compiled,
                    outcome,
                    aot: false,
                    entry,
                })
        })
        .map_err(|e| err(device, e))?,
    };
    // A cubin from the disk cache or an ahead-of-time directory that the driver refuses is
    // compiled again (and the cache entry replaced; an ahead-of-time file is left alone) before
    // giving up: a second refusal is the error.
    match st.gpu.load_module(&got.compiled.cubin) {
        Ok(module) => Ok((module, got)),
        Err(e) if got.outcome == CacheOutcome::Hit => {
            log::warn!(
                "{} cubin {} of kernel {}::{} ({variant}, {}) failed to load on {device}: {e}; \
                 compiling it again",
                if got.aot { "ahead-of-time" } else { "cached" },
                got.entry
                    .path
                    .as_deref()
                    .map_or("(no file)".into(), |p| p.display().to_string()),
                info.module,
                info.name,
                layout_name(contiguous)
            );
            let bad = if got.aot {
                None
            } else {
                got.entry.path.as_deref()
            };
            let (compiled, entry) =
                with_compile_options(contiguous, stack_define, exact, tile, |opts| {
                    KernelCache::current().recompile_entry(&src.text, info.name, opts, arch, bad)
                })
                .map_err(|e| err(device, e))?;
            let module = st
                .gpu
                .load_module(&compiled.cubin)
                .map_err(|e| err(device, e))?;
            let got = Obtained {
                compiled,
                outcome: CacheOutcome::Rebuilt,
                aot: false,
                entry,
            };
            Ok((module, got))
        }
        Err(e) => Err(err(device, e)),
    }
}

/// What a GPU's shared memory allows a block: [`tile_shared`]'s view of the device.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SharedLimits {
    /// The most one block may have, opted in.
    pub(crate) per_block: usize,
    /// A multiprocessor's, shared by its resident blocks.
    pub(crate) per_sm: usize,
    /// What the system reserves for each resident block beside its own.
    pub(crate) reserved: usize,
}

impl SharedLimits {
    fn of(gpu: &warp_cuda::Gpu, device: &Device) -> Result<Self> {
        let f = |e| err(device, e);
        Ok(Self {
            per_block: gpu.max_shared_bytes_per_block_optin().map_err(f)?,
            per_sm: gpu.max_shared_bytes_per_sm().map_err(f)?,
            reserved: gpu.reserved_shared_bytes_per_block().map_err(f)?,
        })
    }

    /// Blocks of `bytes` shared memory a multiprocessor holds, by shared memory alone.
    fn blocks(&self, bytes: usize) -> usize {
        self.per_sm / (bytes + self.reserved).max(1)
    }

    /// Whether a block of `slots` bytes of dynamic shared memory and `static_bytes` of static
    /// may take `total` dynamic instead: it still fits, and a multiprocessor holds as many.
    fn grants(&self, slots: usize, total: usize, static_bytes: usize) -> bool {
        let blocks = self.blocks(slots + static_bytes);
        total + static_bytes <= self.per_block
            && blocks >= 1
            && self.blocks(total + static_bytes) == blocks
    }
}

/// The dynamic shared memory of a tiled kernel's unit: [`tile_shared`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct TileShared {
    /// What one block takes.
    pub(crate) bytes: usize,
    /// Of it, the extra at its end (1024-byte aligned) that the forward unit's pipelined GEMM
    /// k-loops use for more stages (`WP_TILE_PIPE_EXTRA`); 0: none.
    pub(crate) pipe_extra: usize,
}

/// The alignment of the pipe's extra shared memory: wgmma's swizzle patterns' period.
const PIPE_EXTRA_ALIGN: usize = 1024;

/// The dynamic shared memory one block of `info`'s forward unit (or adjoint unit) takes on a
/// GPU of compute capability `arch` with `limits`: the tiles' slots (`TileInfo::shared_bytes`,
/// or `adjoint_shared_bytes`), and for the forward unit on sm_80+ (where the pipelined loops
/// run) the extra its pipelined GEMM k-loops ask for (`TileInfo::pipe_extra_bytes`) where the
/// block then still fits and the multiprocessor still holds as many blocks (more stages in
/// flight at the price of occupancy measured slower: on an H200 at 4096^3 with 128 x 128 x 64
/// tiles, 0.47 ms against 0.40 ms). The unit's static shared memory is not known before it is
/// compiled: `loaded` checks the grant again with it. 0 for an ordinary kernel. `limits` is
/// asked only when there is an extra to grant.
pub(crate) fn tile_shared(
    info: &KernelInfo,
    adjoint: bool,
    arch: u32,
    limits: impl FnOnce() -> Result<SharedLimits>,
) -> Result<TileShared> {
    let Some(t) = info.tile else {
        return Ok(TileShared::default());
    };
    let slots = if adjoint {
        t.adjoint_shared_bytes
    } else {
        t.shared_bytes
    };
    let plain = TileShared {
        bytes: slots,
        pipe_extra: 0,
    };
    if adjoint || t.pipe_extra_bytes == 0 || arch < 80 {
        return Ok(plain);
    }
    let total = slots.next_multiple_of(PIPE_EXTRA_ALIGN) + t.pipe_extra_bytes;
    Ok(if limits()?.grants(slots, total, 0) {
        TileShared {
            bytes: total,
            pipe_extra: t.pipe_extra_bytes,
        }
    } else {
        plain
    })
}

/// The dynamic shared memory a launch may ask for without the kernel opting in: 48 KiB.
const DEFAULT_DYNAMIC_SHARED: usize = 48 * 1024;

/// What a tiled kernel's module asks of its GPU, and what the GPU and the compiled function
/// give (their attributes), for [`check_tile_budget`].
#[derive(Clone, Copy, Debug)]
struct TileBudget {
    /// Threads per block of the launch.
    block_dim: usize,
    /// Dynamic shared memory one block takes (`TileInfo::shared_bytes`).
    dynamic: usize,
    /// The function's static shared memory (`CU_FUNC_ATTRIBUTE_SHARED_SIZE_BYTES`).
    static_bytes: usize,
    /// The device's most per block, opted in
    /// (`CU_DEVICE_ATTRIBUTE_MAX_SHARED_MEMORY_PER_BLOCK_OPTIN`).
    available: usize,
    /// The function's `CU_FUNC_ATTRIBUTE_MAX_THREADS_PER_BLOCK` (registers can lower it).
    max_threads: usize,
}

/// Refuses a tiled kernel's module whose blocks cannot run on the GPU (too many threads for
/// the function, or more shared memory than a block may have), naming the kernel and the
/// numbers: at load, rather than as a launch failure. `Ok(true)` when the kernel must opt in
/// to more than 48 KiB of dynamic shared memory before its launches.
fn check_tile_budget(kernel: &'static str, device: &str, b: &TileBudget) -> Result<bool> {
    if b.block_dim > b.max_threads {
        return Err(Error::InvalidBlockDim {
            kernel,
            block_dim: b.block_dim,
            why: format!(
                "the compiled kernel runs at most {} threads per block on \"{device}\" (its \
                 registers limit it)",
                b.max_threads
            ),
        });
    }
    let requested = b.dynamic.saturating_add(b.static_bytes);
    if requested > b.available {
        return Err(Error::SharedMemory {
            kernel,
            device: device.to_string(),
            requested,
            available: b.available,
            block_dim: b.block_dim,
        });
    }
    Ok(b.dynamic > DEFAULT_DYNAMIC_SHARED)
}

/// The capabilities `info` and the funcs it calls (transitively) need, each once, in the
/// table's order.
fn required_capabilities(info: &KernelInfo) -> Vec<Capability> {
    fn funcs(f: &'static FuncInfo, seen: &mut Vec<*const FuncInfo>, out: &mut Vec<Capability>) {
        if seen.contains(&(f as *const FuncInfo)) {
            return;
        }
        seen.push(f);
        out.extend_from_slice(f.requires);
        for c in f.callees {
            funcs(c, seen, out);
        }
    }
    let mut out = info.requires.to_vec();
    let mut seen = Vec::new();
    for f in info.callees {
        funcs(f, &mut seen, &mut out);
    }
    out.sort();
    out.dedup();
    out
}

/// Refuses a kernel that needs a capability a GPU of architecture `arch` lacks (the table is
/// `warp_core::capability`), before NVRTC sees it; says at debug level which capabilities the
/// CUDA library emulates there.
fn check_capabilities(info: &KernelInfo, device: &str, arch: u32) -> Result<()> {
    let requires = required_capabilities(info);
    let target = Target::Cuda { arch };
    if let Some(row) = first_missing(&requires, target) {
        return Err(Error::MissingCapability {
            kernel: info.name,
            device: device.to_string(),
            found: format!("sm_{arch}"),
            capability: row.what,
            needs: format!("sm_{} or newer", row.cuda_required_arch),
        });
    }
    for c in requires {
        let row = c.row();
        if let Support::Emulated(how) = row.on(target) {
            log::debug!(
                "kernel {}::{} on {device} (sm_{arch}): {} is {how} (an instruction from sm_{})",
                info.module,
                info.name,
                row.what,
                row.cuda_native_arch
            );
        }
    }
    Ok(())
}

/// "forward" or "adjoint", for log records.
fn variant_name(adjoint: Option<usize>) -> &'static str {
    if adjoint.is_some() {
        "adjoint"
    } else {
        "forward"
    }
}

/// "contiguous" or "strided" (the `WP_CONTIGUOUS` variant or not), for log records.
fn layout_name(contiguous: bool) -> &'static str {
    if contiguous {
        "contiguous"
    } else {
        "strided"
    }
}

/// Compiles and loads `kernels` for GPU `ordinal` now (each variant the one `loaded` keeps,
/// so their first launches find them): the contiguous forward variant of each, and with
/// `adjoint: Some(bytes)` the adjoint with that stack, both from one unit where neither is
/// compiled yet (see [`loaded`]); with `block_dim: Some(n)` (tiled kernels,
/// [`crate::load_tiled`]) their variants for blocks of `n` threads. The kernels go to the rayon
/// pool together, compiled side by side (each overlapping compile in a copy of NVRTC of its
/// own: see `crate::load`). A kernel already loaded costs a map lookup. Every kernel is
/// tried: each failure is logged, and the first of `kernels` that failed is the error.
pub(crate) fn prepare(
    device: &Device,
    ordinal: usize,
    kernels: &[&'static KernelInfo],
    adjoint: Option<usize>,
    block_dim: Option<usize>,
) -> Result<()> {
    use rayon::prelude::*;
    // One task per kernel (a compile is hundreds of milliseconds, so no chunking): its forward
    // (with the adjoint when they make one unit), then its adjoint, loaded by then if so.
    let results: Vec<Result<()>> = kernels
        .par_iter()
        .with_max_len(1)
        .map(|info| {
            loaded(device, ordinal, info, true, None, block_dim, || adjoint)?;
            if adjoint.is_some() {
                loaded(device, ordinal, info, true, adjoint, block_dim, || None)?;
            }
            Ok(())
        })
        .collect();
    let mut first = None;
    for (info, r) in kernels.iter().zip(results) {
        if let Err(e) = r {
            log::error!(
                "loading kernel {}::{} on {device}: {e}",
                info.module,
                info.name
            );
            first.get_or_insert(e);
        }
    }
    first.map_or(Ok(()), Err)
}

#[cfg(test)]
mod tests {
    use super::{
        check_capabilities, check_tile_budget, format_compile_reports, tile_shared, CompileReport,
        SharedLimits, TileBudget, TileShared,
    };
    use crate::error::Error;
    use crate::kernel::KernelInfo;
    use crate::kernel::TileInfo;
    use warp_core::capability::{Capability, CAPABILITIES};
    use warp_core::FuncInfo;

    static LEAF: FuncInfo = FuncInfo {
        name: "leaf",
        module: "m",
        file: "src/m.rs",
        cuda: "",
        cuda_ret: "void",
        sections: &[],
        callees: &[],
        structs: &[],
        cuda_adj: "",
        cuda_adj_error: None,
        consts: &[],
        requires: &[Capability::AtomicMinMaxBits64],
        asserts: &[],
        float_atomics: false,
        needs_adjoints: false,
    };
    static MID: FuncInfo = FuncInfo {
        name: "mid",
        callees: &[&LEAF],
        requires: &[],
        asserts: &[],
        ..LEAF
    };

    /// A tiled kernel's module is refused at load, naming the numbers, when its blocks cannot
    /// run: too many threads for the compiled function, or too much shared memory (dynamic and
    /// static together); above 48 KiB of dynamic shared memory it must opt in.
    #[test]
    fn tile_budgets_are_checked_at_load() {
        let b = TileBudget {
            block_dim: 256,
            dynamic: 32 * 1024,
            static_bytes: 1024,
            available: 227 * 1024,
            max_threads: 1024,
        };
        assert!(!check_tile_budget("gemm", "cuda:0", &b).unwrap());
        let big = TileBudget {
            dynamic: 100 * 1024,
            ..b
        };
        assert!(check_tile_budget("gemm", "cuda:0", &big).unwrap());
        // Exactly what the device gives fits; one byte more does not.
        let full = TileBudget {
            dynamic: 226 * 1024,
            ..b
        };
        assert!(check_tile_budget("gemm", "cuda:0", &full).unwrap());
        let over = TileBudget {
            dynamic: 226 * 1024 + 1,
            ..b
        };
        let e = check_tile_budget("gemm", "cuda:1", &over).unwrap_err();
        assert_eq!(
            e,
            Error::SharedMemory {
                kernel: "gemm",
                device: "cuda:1".into(),
                requested: 227 * 1024 + 1,
                available: 227 * 1024,
                block_dim: 256,
            }
        );
        assert_eq!(
            e.to_string(),
            "kernel `gemm`: a block of 256 threads needs 232449 bytes of shared memory on \
             \"cuda:1\", which gives a block at most 232448; use smaller tiles"
        );
        let e = check_tile_budget(
            "gemm",
            "cuda:0",
            &TileBudget {
                max_threads: 128,
                ..b
            },
        )
        .unwrap_err();
        assert!(
            matches!(
                e,
                Error::InvalidBlockDim {
                    kernel: "gemm",
                    block_dim: 256,
                    ..
                }
            ),
            "{e}"
        );
        assert!(
            e.to_string().contains("at most 128 threads per block"),
            "{e}"
        );
    }

    /// An H100's or H200's shared memory.
    const HOPPER: SharedLimits = SharedLimits {
        per_block: 227 * 1024,
        per_sm: 228 * 1024,
        reserved: 1024,
    };

    fn tiled(shared_bytes: usize, pipe_extra_bytes: usize) -> KernelInfo {
        KernelInfo {
            tile: Some(TileInfo {
                width: None,
                shared_bytes,
                adjoint_shared_bytes: 8192,
                cpu_frame_bytes: 0,
                pipe_extra_bytes,
            }),
            ..KernelInfo::BLANK
        }
    }

    /// [`tile_shared`] on an sm_90 GPU with `limits`.
    fn shared_on(info: &KernelInfo, adjoint: bool, limits: SharedLimits) -> TileShared {
        tile_shared(info, adjoint, 90, || Ok(limits)).unwrap()
    }

    /// Forward and adjoint units take their own shared memory; ordinary kernels none.
    #[test]
    fn units_take_their_own_shared_memory() {
        let plain = |bytes| TileShared {
            bytes,
            pipe_extra: 0,
        };
        assert_eq!(shared_on(&tiled(4096, 0), false, HOPPER), plain(4096));
        assert_eq!(shared_on(&tiled(4096, 0), true, HOPPER), plain(8192));
        assert_eq!(shared_on(&KernelInfo::BLANK, false, HOPPER), plain(0));
        // Without an extra to grant, the device is not asked.
        let unasked = || -> crate::error::Result<SharedLimits> { panic!("limits asked") };
        assert_eq!(
            tile_shared(&tiled(4096, 0), false, 90, unasked).unwrap(),
            plain(4096)
        );
    }

    /// The pipelined GEMM loops' extra stages are granted, 1024-byte aligned at the end, where
    /// the block still fits and a multiprocessor holds as many blocks; never to the adjoint,
    /// nor below sm_80 (where the loops are not pipelined).
    #[test]
    fn pipe_extra_stages_are_granted_where_they_cost_no_blocks() {
        // 128 x 256 x 64 f16 tiles: a 128 KiB accumulator holds two stages of 48 KiB, the
        // operands' slots a third; the fourth is extra (one block an SM either way).
        let (acc, a, b) = (128 * 256 * 4, 128 * 64 * 2, 64 * 256 * 2);
        let want = TileInfo::pipe_extra_for(acc, a, b);
        assert_eq!(want, 48 * 1024);
        let base = acc + a + b;
        assert_eq!(
            shared_on(&tiled(base, want), false, HOPPER),
            TileShared {
                bytes: base + want,
                pipe_extra: want,
            }
        );
        // Unaligned slots: the extra starts at the next 1024 bytes.
        assert_eq!(
            shared_on(&tiled(base - 16, want), false, HOPPER).bytes,
            base + want
        );
        assert_eq!(shared_on(&tiled(base, want), true, HOPPER).pipe_extra, 0);
        let sm80 = tile_shared(&tiled(base, want), false, 80, || Ok(HOPPER)).unwrap();
        assert_eq!(sm80.pipe_extra, want);
        let sm75 = tile_shared(&tiled(base, want), false, 75, || Ok(HOPPER)).unwrap();
        assert_eq!(sm75.pipe_extra, 0);
        // 128 x 128 x 64: two blocks an SM without the extra stage, one with it: not granted.
        let (acc, a, b) = (128 * 128 * 4, 128 * 64 * 2, 64 * 128 * 2);
        let want = TileInfo::pipe_extra_for(acc, a, b);
        assert_eq!(want, 32 * 1024);
        assert_eq!(
            shared_on(&tiled(acc + a + b, want), false, HOPPER).pipe_extra,
            0
        );
        // A GPU whose blocks cannot have it (an sm_80-class 163 KiB block): not granted.
        let small = SharedLimits {
            per_block: 163 * 1024,
            per_sm: 164 * 1024,
            ..HOPPER
        };
        assert_eq!(
            shared_on(&tiled(128 * 1024, 48 * 1024), false, small),
            TileShared {
                bytes: 128 * 1024,
                pipe_extra: 0,
            }
        );
        // An accumulator that holds three stages already asks for none.
        assert_eq!(TileInfo::pipe_extra_for(3 * 8192, 4096, 4096), 0);
        assert_eq!(TileInfo::pipe_extra_for(2 * 8192, 4096, 4096), 8192);
        assert_eq!(TileInfo::pipe_extra_for(0, 0, 0), 0);
    }

    /// The grant counted again with the unit's static shared memory (`loaded` recompiles
    /// without the extra when it no longer holds): the block must still fit, and a
    /// multiprocessor hold as many blocks.
    #[test]
    fn static_shared_memory_can_take_the_grant_back() {
        let (slots, total) = (176 * 1024, 224 * 1024);
        assert!(HOPPER.grants(slots, total, 0));
        assert!(HOPPER.grants(slots, total, 3 * 1024));
        // A tile_sort's keys of 4 KiB: 228 KiB, more than a block may have.
        assert!(!HOPPER.grants(slots, total, 4 * 1024));
        // Two blocks an SM with 12 KiB of static memory and 100 KiB of slots; one with 10 KiB
        // more.
        assert!(HOPPER.grants(100 * 1024, 101 * 1024, 12 * 1024));
        assert!(!HOPPER.grants(100 * 1024, 110 * 1024, 12 * 1024));
        assert!(HOPPER.grants(100 * 1024, 110 * 1024, 0));
    }

    #[test]
    fn a_gpu_without_a_capability_is_refused_naming_kernel_and_capability() {
        // The capability comes from a func two calls down.
        static CALLEES: [&FuncInfo; 1] = [&MID];
        let info = KernelInfo {
            name: "minima",
            callees: &CALLEES,
            requires: &[Capability::AtomicAddF64],
            ..KernelInfo::BLANK
        };
        let e = check_capabilities(&info, "cuda:1", 35).unwrap_err();
        let msg = e.to_string();
        assert!(
            msg.contains("kernel `minima`")
                && msg.contains("\"cuda:1\" (sm_35)")
                && msg.contains("64-bit integer atomic min")
                && msg.contains("sm_50 or newer"),
            "{msg}"
        );
        // f64 atomic adds are emulated below sm_60, not refused; every capability runs on
        // sm_50 and newer.
        for arch in [50, 52, 61, 90, 120] {
            check_capabilities(&info, "cuda:0", arch).unwrap();
        }
        check_capabilities(&KernelInfo::BLANK, "cuda:0", 20).unwrap();
    }

    /// The CUDA library's `#if __CUDA_ARCH__ >= N` switches between an atomic's instruction and
    /// its emulation are the table's `cuda_native_arch` (`N` is the architecture times 10).
    #[test]
    fn the_atomic_header_switches_where_the_table_says() {
        let header = warp_cuda::HEADERS
            .iter()
            .find(|(n, _)| *n == "wp_atomic.h")
            .expect("wp_atomic.h")
            .1;
        // The `#if` guarding each emulated capability's instruction, and what it guards.
        let guard = |arch: u32| format!("__CUDA_ARCH__ >= {}", arch * 10);
        let guarded = |arch: u32| -> Vec<&str> {
            header
                .split(&guard(arch))
                .skip(1)
                .map(|rest| rest.split("#else").next().unwrap_or(""))
                .collect()
        };
        for row in CAPABILITIES {
            let uses = match row.capability {
                Capability::AtomicAddF64 => "atomicAdd(p, v)",
                Capability::AtomicF16 => "atomicCAS(h, assumed",
                // Not emulated: no switch.
                Capability::AtomicMinMaxBits64 => {
                    assert!(row.cuda_emulation.is_none());
                    continue;
                }
                _ => panic!("a capability this test does not know: {row:?}"),
            };
            assert!(
                guarded(row.cuda_native_arch)
                    .iter()
                    .any(|g| g.contains(uses)),
                "{:?}: wp_atomic.h has no `{}` guarding `{uses}`",
                row.capability,
                guard(row.cuda_native_arch)
            );
        }
        // No switch at an architecture the table does not name.
        let named: Vec<String> = CAPABILITIES
            .iter()
            .map(|r| guard(r.cuda_native_arch))
            .collect();
        for (k, _) in header.match_indices("__CUDA_ARCH__ >= ") {
            let at = &header[k..];
            assert!(
                named.iter().any(|n| at.starts_with(n.as_str())),
                "{}",
                &at[..24]
            );
        }
    }

    fn report(module: &'static str, adjoint: bool, cache_hit: bool) -> CompileReport {
        CompileReport {
            kernel: "accelerations",
            module,
            device: "cuda:0".into(),
            contiguous: true,
            adjoint,
            block_dim: None,
            shared_bytes: 0,
            pipe_extra_bytes: 0,
            source_bytes: 5730,
            compile_ms: if cache_hit { 0.0 } else { 145.25 },
            cache_hit,
            aot: false,
            total_ms: 156.3,
            cache_key: 0x1234,
            cache_entry: None,
            one_unit: false,
        }
    }

    #[test]
    fn summary_names_module_direction_and_source() {
        let s = format_compile_reports(&[
            report("nbody::single", false, false),
            report("nbody::double", true, true),
            report("top", false, true),
            CompileReport {
                block_dim: Some(128),
                ..report("tiles", false, false)
            },
        ]);
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(
            lines[0],
            "compiled at run time: 4 kernel variant(s) in 4 unit(s)"
        );
        assert!(
            lines[4]
                .trim_start()
                .starts_with("accelerations [block_dim 128] forward"),
            "{}",
            lines[4]
        );
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

    /// A unit of forward and adjoint has a report a variant: the forward's carries the unit's
    /// NVRTC and loading time and says it holds the adjoint; the adjoint's says where it came
    /// from and costs nothing, so that sums and unit counts see one compile.
    #[test]
    fn a_unit_of_both_halves_is_counted_once() {
        let forward = CompileReport {
            one_unit: true,
            ..report("seed_ad", false, false)
        };
        let adjoint = CompileReport {
            adjoint: true,
            compile_ms: 0.0,
            total_ms: 0.0,
            ..forward.clone()
        };
        assert!(forward.is_unit() && !adjoint.is_unit());
        assert!(report("m", true, false).is_unit());
        let s =
            format_compile_reports(&[forward.clone(), adjoint.clone(), report("m", false, true)]);
        let lines: Vec<&str> = s.lines().collect();
        assert_eq!(
            lines[0],
            "compiled at run time: 3 kernel variant(s) in 2 unit(s)"
        );
        assert!(
            lines[1].contains("forward")
                && lines[1].contains("NVRTC 145.2 ms, one unit with the adjoint"),
            "{}",
            lines[1]
        );
        assert!(
            lines[2].contains("adjoint") && lines[2].contains("in the forward's unit"),
            "{}",
            lines[2]
        );
        let units = [&forward, &adjoint].iter().filter(|r| r.is_unit()).count();
        let nvrtc: f64 = [&forward, &adjoint].iter().map(|r| r.compile_ms).sum();
        assert_eq!((units, nvrtc), (1, 145.25));
    }
}

//! Host objects' build steps on a GPU ([`ObjectStep`]): each object's build library (its
//! header with the build kernels enabled, e.g. `wp_hash_grid.h` with `WP_HASH_GRID_BUILD`: the
//! section's row in `warp_cuda::library::SECTIONS`) is
//! compiled by NVRTC through the kernel disk cache the first time a GPU runs one of its steps,
//! loaded, and kept for the process with its functions; a step's launch goes on the calling
//! thread's current stream, as a kernel's does (the ordering model of `gpu.rs`), without host
//! synchronisation. Nothing here names an object: the step says which library and kernel.
//! Inside a capture a step's launch goes on the capture stream; its library and kernel must
//! be loaded before (a module load would break the capture).

use super::{fault, gpu};
use crate::backend::{ObjectLibrary, ObjectStep};
use crate::config;
use crate::device::Device;
use crate::error::Result;
use crate::kernel::KernelInfo;
use std::collections::HashMap;
use std::ffi::c_void;
use std::sync::{Arc, Mutex, OnceLock};
use warp_cuda::library::{self, Section};
use warp_cuda::{CompileOptions, CudaError, Function};

/// Threads per block of the build kernels (grid-stride loops: any count of blocks works; the
/// sparse dot kernels are written for exactly this many).
pub(crate) const THREADS: u32 = 256;

/// A build library loaded on one GPU, with the functions looked up so far.
struct Loaded {
    module: warp_cuda::Module,
    functions: Mutex<HashMap<&'static str, Function>>,
}

/// A build library's program: its name (NVRTC's and the cache key), its translation unit, and
/// the section's row (headers and rounding).
struct Program {
    name: String,
    source: String,
    row: &'static Section,
}

/// The program of `lib`, from its section's row. (`ObjectLibrary::of` checked at compile time
/// that the row has a build library; the error is for a library made otherwise.)
fn program(lib: &ObjectLibrary) -> warp_cuda::Result<Program> {
    let row = library::find(lib.section());
    match row.and_then(|r| Some((r, r.build_name()?, r.build_source()?))) {
        Some((row, name, source)) => Ok(Program { name, source, row }),
        None => Err(CudaError::InvalidArgument(format!(
            "the CUDA library has no build library named `{}`",
            lib.section()
        ))),
    }
}

/// Compiles with the runtime's options: the core and the section's header, FMA contraction as
/// `config::cuda_fmad` says (one setting for all GPU code) unless the section's row rounds
/// exactly.
fn with_options<R>(p: &Program, f: impl FnOnce(&CompileOptions) -> R) -> R {
    f(&CompileOptions {
        fmad: p.row.exact.fmad(config::cuda_fmad()),
        line_info: config::cuda_line_info(),
        headers: &p.row.standalone_headers(),
        extra_options: p.row.exact.extra_options(),
        ..Default::default()
    })
}

/// Compiles `lib` for `sm_{arch}` (no GPU needed, only libnvrtc): how the tests check that
/// NVRTC accepts every build library on machines without a GPU.
pub fn compile_library(lib: &ObjectLibrary, arch: u32) -> warp_cuda::Result<warp_cuda::Compiled> {
    let p = program(lib)?;
    with_options(&p, |opts| {
        warp_cuda::compile(&p.source, &p.name, opts, arch)
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
    let key = (ordinal, lib.section());
    if let Some(l) = cache.lock().unwrap_or_else(|p| p.into_inner()).get(&key) {
        return Ok(l.clone());
    }
    gpu::refuse_in_capture(
        ordinal,
        &first_use(&format!("the library {}", lib.section())),
    )?;
    let st = gpu::state(device, ordinal)?;
    let p = program(lib).map_err(|e| gpu::err(device, e))?;
    let (compiled, _) = with_options(&p, |opts| {
        warp_cuda::compile_cached(&p.source, &p.name, opts, st.gpu.arch())
    })
    .map_err(|e| gpu::err(device, e))?;
    let module = st
        .gpu
        .load_module(&compiled.cubin)
        .map_err(|e| gpu::err(device, e))?;
    log::info!("loaded the build library {} on {device}", p.name);
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

/// The kernel id (`fault::kernel_id`) the faults of build steps named by `names` carry: one
/// per names, made at their first use.
fn names_id(names: &'static KernelInfo) -> i32 {
    static IDS: OnceLock<Mutex<HashMap<usize, i32>>> = OnceLock::new();
    let mut ids = IDS
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(|p| p.into_inner());
    *ids.entry(names as *const KernelInfo as usize)
        .or_insert_with(|| fault::kernel_id(names))
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
    if let Some(slot) = record.fault_slot() {
        // A step that raises faults is a launch of its own: its faults go to the calling
        // thread's record (the capture's, inside one) under its names and this number.
        let launch = crate::launch_id::next();
        let (fault, flag) = fault::with_record(&st.faults, ordinal, launch, |r| r.addresses())?;
        slot.fill(fault, flag, names_id(slot.names), launch.0);
    }
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

//! Graph capture on a GPU: what recording means on the CUDA backend (`backend.rs`).
//!
//! A capture records the calling thread's work on one GPU into a CUDA graph: `begin` starts
//! stream capture on a stream of its own and makes it the thread's capture stream
//! (`gpu::capture_stream`), so that everything this thread queues on that GPU (launches,
//! fills, copies, the primitives' kernels, host objects' build steps) is queued there, and
//! nothing else: what would allocate, upload, read back, synchronise or load a module is
//! refused with [`Error::Capture`]; `end` instantiates the graph. A replay is queued like a
//! launch, in the ordering model of `gpu.rs`: after the default stream's work (arrays written
//! before), and the default stream waits for it before its next operation; a graph that
//! recorded primitives also orders itself after the last user of the scratch memory it holds.

use super::fault::{self, FaultRecord};
use super::gpu::{self, err, state, GpuState, Scratch};
use super::stream::Stream;
use crate::device::Device;
use crate::error::{Error, Result};
use std::cell::RefCell;
use std::sync::Arc;

/// A capture in progress on one GPU.
struct CudaCapture {
    st: Arc<GpuState>,
    device: Device,
    stream: warp_cuda::Stream,
    faults: Arc<FaultRecord>,
    /// The primitives' scratch memory the recorded kernels use (the GPU's workspace, which
    /// cannot grow inside a capture: one at most).
    scratch: Option<Arc<Scratch>>,
}

thread_local! {
    /// The calling thread's capture, from `begin` to `end` or `abort`.
    static CAPTURE: RefCell<Option<CudaCapture>> = const { RefCell::new(None) };
}

/// A captured graph, with the fault record its launches write into (`fault.rs`) and the
/// scratch memory its primitives use.
pub(crate) struct CudaGraph {
    graph: warp_cuda::Graph,
    faults: Arc<FaultRecord>,
    scratch: Option<Arc<Scratch>>,
}

impl CudaGraph {
    /// The number of nodes in the graph.
    pub(crate) fn node_count(&self) -> usize {
        self.graph.node_count()
    }
}

/// Starts capturing the calling thread's work on GPU `ordinal` (`device`): on `stream` when
/// given (a stream the caller made, not the default one), else on the thread's current stream
/// when a `ScopedStream` set one, else on a new stream.
pub(crate) fn begin(device: &Device, ordinal: usize, stream: Option<&Stream>) -> Result<()> {
    let st = state(device, ordinal)?;
    let stream = match stream {
        Some(s) => {
            if s.device() != device {
                return Err(Error::Capture {
                    what: format!(
                        "a capture on \"{device}\" was given a stream of \"{}\"",
                        s.device()
                    ),
                });
            }
            if s.is_default() {
                return Err(Error::Capture {
                    what: format!(
                        "the default stream of \"{device}\" cannot capture: array operations of \
                         every thread run there (capture on a Stream::new, or on the device)"
                    ),
                });
            }
            s.cuda_stream().clone()
        }
        None => match gpu::current(ordinal) {
            Some(s) if !s.is(st.gpu.default_stream()) => s,
            _ => st.gpu.new_stream().map_err(|e| err(device, e))?,
        },
    };
    // Conditional nodes need their kernel loaded before the capture (nothing loads inside).
    if warp_cuda::driver_version().is_some_and(|v| v >= warp_cuda::CONDITIONAL_DRIVER_VERSION) {
        load_setter(&st, device, ordinal);
    }
    // Made before the capture starts (an allocation cannot be captured).
    let faults = fault::begin_capture(&st.faults, ordinal)?;
    if let Err(e) = stream.begin_capture() {
        fault::end_capture();
        return Err(err(device, e));
    }
    gpu::set_capture_stream(Some((ordinal, stream.clone())));
    let capture = CudaCapture {
        st,
        device: device.clone(),
        stream,
        faults,
        scratch: None,
    };
    CAPTURE.with(|c| *c.borrow_mut() = Some(capture));
    Ok(())
}

/// The calling thread's capture, taken (its capture stream cleared).
fn take() -> Option<CudaCapture> {
    gpu::set_capture_stream(None);
    fault::end_capture();
    CAPTURE.with(|c| c.borrow_mut().take())
}

/// Ends the calling thread's capture and instantiates the graph.
pub(crate) fn end() -> Result<CudaGraph> {
    let Some(c) = take() else {
        return Err(Error::Capture {
            what: "the capture was already ended".into(),
        });
    };
    let graph = c
        .stream
        .end_capture(&c.st.gpu)
        .map_err(|e| err(&c.device, e))?;
    Ok(CudaGraph {
        graph,
        faults: c.faults,
        scratch: c.scratch,
    })
}

/// Ends the calling thread's capture and drops what it recorded (the capture failed or was
/// abandoned).
pub(crate) fn abort() {
    if let Some(c) = take() {
        let _ = c.stream.end_capture(&c.st.gpu);
    }
}

/// Notes that the kernels just recorded into the calling thread's capture on GPU `ordinal`
/// use `scratch`: the graph holds it and orders its replays after the scratch's last user.
pub(crate) fn uses_scratch(ordinal: usize, scratch: Arc<Scratch>) {
    CAPTURE.with(|c| {
        if let Some(c) = c.borrow_mut().as_mut() {
            debug_assert_eq!(c.st.gpu.ordinal(), ordinal);
            debug_assert!(c.scratch.as_ref().is_none_or(|s| Arc::ptr_eq(s, &scratch)));
            c.scratch = Some(scratch);
        }
    });
}

/// Queues a replay of `graph` on `stream` when given, else on the calling thread's current
/// stream for its GPU, else on the default stream (the ordering model of `gpu.rs`).
pub(crate) fn launch(graph: &CudaGraph, device: &Device, stream: Option<&Stream>) -> Result<()> {
    let CudaGraph {
        graph,
        faults,
        scratch,
    } = graph;
    let ordinal = graph.ordinal();
    if let Some(s) = stream {
        if s.device() != device {
            return Err(Error::Capture {
                what: format!(
                    "a graph captured on \"{device}\" launched on a stream of \"{}\"",
                    s.device()
                ),
            });
        }
    }
    let st = state(device, ordinal)?;
    // Held while the replay is queued, as a primitive holds it (`primitives.rs`).
    let mut last = scratch.as_ref().map(|s| s.last());
    st.queue(ordinal, stream.map(Stream::cuda_stream), |on| {
        if let Some(last) = last.as_mut() {
            gpu::order_scratch(device, last, on)?;
        }
        graph.launch(on).map_err(|e| err(device, e))
    })?;
    drop(last);
    // This thread's next synchronisation reads the faults of the replay.
    fault::replayed(ordinal, faults);
    Ok(())
}

/// The kernel that sets conditional handles from a flag in device memory: `then` to whether
/// `*cond` is non-zero and, with `has_else`, `otherwise` to the opposite. One kernel node
/// before a conditional node (and at the end of a `while` body) evaluates the condition on the
/// device. `cudaGraphSetConditional` is in the device runtime, so this unit is compiled as
/// relocatable code and linked with the toolkit's `libcudadevrt.a`.
const SET_CONDITIONAL: &str = r#"
extern "C" __device__ void cudaGraphSetConditional(unsigned long long handle, unsigned int value);
extern "C" __global__ void wp_set_conditional(unsigned long long then, unsigned long long otherwise,
                                              int has_else, const int* cond) {
    unsigned int c = (*cond != 0) ? 1u : 0u;
    cudaGraphSetConditional(then, c);
    if (has_else) cudaGraphSetConditional(otherwise, 1u - c);
}
"#;

/// The condition kernel, loaded for one GPU.
struct Setter {
    _module: warp_cuda::Module,
    function: warp_cuda::Function,
}

type Setters = std::sync::Mutex<std::collections::HashMap<usize, Result<Arc<Setter>>>>;

fn setters() -> &'static Setters {
    static S: std::sync::OnceLock<Setters> = std::sync::OnceLock::new();
    S.get_or_init(Default::default)
}

/// Compiles and links the condition kernel for GPU `ordinal` once per process (outside any
/// capture: `begin` calls this before capturing, so that a conditional inside the capture
/// loads nothing). The outcome, success or why not, is kept.
fn load_setter(st: &GpuState, device: &Device, ordinal: usize) {
    let mut map = setters().lock().unwrap_or_else(|p| p.into_inner());
    if map.contains_key(&ordinal) {
        return;
    }
    let loaded = (|| {
        let Some(library) = warp_cuda::cudadevrt_path() else {
            return Err(Error::Capture {
                what: format!(
                    "capture_while and capture_if on \"{device}\" need the CUDA toolkit's \
                     libcudadevrt.a (for cudaGraphSetConditional), found neither through {} nor \
                     under CUDA_PATH, CUDA_HOME or /usr/local/cuda*",
                    warp_cuda::CUDADEVRT_ENV
                ),
            });
        };
        let opts = warp_cuda::CompileOptions {
            extra_options: &["-rdc=true"],
            ..Default::default()
        };
        // The linked image is cached under a key naming the library file as well (its path,
        // size and modification time): a warm start neither compiles nor links.
        let meta = std::fs::metadata(&library).ok();
        let identity = format!(
            "{SET_CONDITIONAL}\n// linked with {} ({} bytes, modified {:?})",
            library.display(),
            meta.as_ref().map_or(0, |m| m.len()),
            meta.and_then(|m| m.modified().ok())
        );
        let (name, arch) = ("wp_set_conditional_linked", st.gpu.arch());
        let key = warp_cuda::aot_key(&identity, name, &opts, arch);
        let cache = warp_cuda::KernelCache::current();
        let image = match cache.load(name, key) {
            warp_cuda::CacheLookup::Hit(image) => image,
            _ => {
                let (compiled, _) =
                    warp_cuda::compile_cached(SET_CONDITIONAL, "wp_set_conditional", &opts, arch)
                        .map_err(|e| err(device, e))?;
                let image = st
                    .gpu
                    .link_with_library(&compiled.cubin, &library)
                    .map_err(|e| err(device, e))?;
                // A cache that cannot be written only costs the next start a link.
                if let Err(e) = cache.store(name, key, &image) {
                    log::warn!(
                        "kernel cache: {} (the linked condition kernel is not kept)",
                        crate::error::Chain(&e)
                    );
                }
                image
            }
        };
        let module = st.gpu.load_module(&image).map_err(|e| err(device, e))?;
        let function = module
            .function("wp_set_conditional")
            .map_err(|e| err(device, e))?;
        Ok(Arc::new(Setter {
            _module: module,
            function,
        }))
    })();
    map.insert(ordinal, loaded);
}

/// Queues the condition kernel on `stream`.
fn set_conditional(
    st: &GpuState,
    device: &Device,
    setter: &Setter,
    stream: &warp_cuda::Stream,
    (then, otherwise): (u64, Option<u64>),
    cond: u64,
) -> Result<()> {
    let (mut then, mut otherwise, mut has_else, mut cond) = (
        then,
        otherwise.unwrap_or(0),
        otherwise.is_some() as i32,
        cond,
    );
    let mut args = [
        (&mut then) as *mut u64 as *mut std::ffi::c_void,
        (&mut otherwise) as *mut u64 as *mut std::ffi::c_void,
        (&mut has_else) as *mut i32 as *mut std::ffi::c_void,
        (&mut cond) as *mut u64 as *mut std::ffi::c_void,
    ];
    // SAFETY: the arguments match wp_set_conditional's parameters (two u64 handles, an int, a
    // pointer to an int that the caller keeps alive for the graph's replays).
    unsafe {
        st.gpu
            .launch_raw(&setter.function, stream, 1, 1, 0, &mut args)
            .map_err(|e| err(device, e))
    }
}

/// Inside the calling thread's capture on GPU `ordinal`: conditional nodes on the `i32` at
/// device address `cond`, evaluated on the device when the graph runs. `While` runs `bodies.0`
/// while the flag is non-zero (the flag is read again after each iteration); `If` runs
/// `bodies.0` when it is non-zero and `bodies.1` (if any) when it is zero, both decided by
/// one read before either runs.
pub(crate) fn conditional(
    device: &Device,
    ordinal: usize,
    kind: warp_cuda::Conditional,
    cond: u64,
    then: &mut dyn FnMut() -> Result<()>,
    otherwise: Option<&mut dyn FnMut() -> Result<()>>,
) -> Result<()> {
    let st = state(device, ordinal)?;
    let Some(outer) = gpu::capture_stream(ordinal) else {
        return Err(Error::Capture {
            what: format!("a conditional outside a capture on \"{device}\""),
        });
    };
    let setter = match setters()
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .get(&ordinal)
    {
        Some(Ok(s)) => s.clone(),
        Some(Err(e)) => return Err(e.clone()),
        None => {
            return Err(Error::Capture {
                what: format!("the condition kernel of \"{device}\" was not loaded"),
            })
        }
    };
    let gpu_err = |e| err(device, e);
    let then_handle = outer.conditional_handle(&st.gpu).map_err(gpu_err)?;
    let else_handle = match otherwise {
        Some(_) => Some(outer.conditional_handle(&st.gpu).map_err(gpu_err)?),
        None => None,
    };
    set_conditional(
        &st,
        device,
        &setter,
        &outer,
        (then_handle, else_handle),
        cond,
    )?;
    let capture_body = |handle: u64, body: &mut dyn FnMut() -> Result<()>| -> Result<()> {
        let body_stream = st.gpu.new_stream().map_err(gpu_err)?;
        outer
            .add_conditional(&st.gpu, handle, kind, &body_stream)
            .map_err(gpu_err)?;
        gpu::set_capture_stream(Some((ordinal, body_stream.clone())));
        let ran = body().and_then(|()| match kind {
            // A while body ends by evaluating the flag again.
            warp_cuda::Conditional::While => {
                set_conditional(&st, device, &setter, &body_stream, (handle, None), cond)
            }
            warp_cuda::Conditional::If => Ok(()),
        });
        let ended = body_stream.end_body_capture().map_err(gpu_err);
        gpu::set_capture_stream(Some((ordinal, outer.clone())));
        ran.and(ended)
    };
    capture_body(then_handle, then)?;
    if let (Some(h), Some(body)) = (else_handle, otherwise) {
        capture_body(h, body)?;
    }
    Ok(())
}

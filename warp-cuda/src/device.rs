//! Devices: probing, opened GPUs, streams and events.
//!
//! No GPU and no driver is a normal situation (the CPU backend just works), so nothing here
//! panics when CUDA is missing. cudarc loads `libcuda.so` with dlopen on first use and panics
//! if it cannot; [`probe`] therefore asks cudarc's own loader whether the library can be found
//! (`is_culib_present`, the same candidate names `culib()` tries) before any driver call, and
//! additionally runs the first calls under `catch_unwind` so that a library that loads but
//! lacks a symbol is an `Err`, not an abort of the user's program.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::{Arc, Mutex, OnceLock};

use cudarc::driver::result::{self, DriverError};
use cudarc::driver::safe::{CudaContext, CudaEvent, CudaStream};
use cudarc::driver::sys;

use crate::error::{CudaError, Result};

/// Oldest driver accepted, as `cuDriverGetVersion` reports it (major * 1000 + minor * 10).
///
/// The bindings are those of CUDA 13.0 and are resolved lazily, symbol by symbol; every symbol
/// this crate calls exists since CUDA 12.0 (event timing falls back to the pre-12.8 symbol),
/// and stream-ordered allocation needs 11.2. Cubins from a newer NVRTC than the driver may still
/// fail to load; that is reported by [`Gpu::load_module`].
pub const MIN_DRIVER_VERSION: i32 = 12000;

/// What [`probe`] learned about one device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct GpuInfo {
    /// CUDA device ordinal (the N of "cuda:N").
    pub ordinal: usize,
    /// Marketing name, e.g. "NVIDIA H200".
    pub name: String,
    /// Compute capability (major, minor), e.g. (9, 0).
    pub compute_capability: (u32, u32),
    /// Total device memory in bytes.
    pub total_memory: u64,
    /// Number of streaming multiprocessors (for grid sizing).
    pub multiprocessor_count: u32,
}

impl GpuInfo {
    /// The architecture number NVRTC wants, major * 10 + minor (90 for sm_90).
    pub fn arch(&self) -> u32 {
        self.compute_capability.0 * 10 + self.compute_capability.1
    }

    /// The device's alias, "cuda:N".
    pub fn alias(&self) -> String {
        format!("cuda:{}", self.ordinal)
    }
}

static DRIVER_PRESENT: OnceLock<bool> = OnceLock::new();
static PROBE: OnceLock<std::result::Result<Vec<GpuInfo>, String>> = OnceLock::new();
static DRIVER_VERSION: OnceLock<i32> = OnceLock::new();

/// Whether cudarc's loader can find libcuda. Cached: the answer cannot change usefully while the
/// process runs, and dlopen of a missing library walks the whole search path each time.
fn driver_library_present() -> bool {
    // SAFETY: `is_culib_present` only tries `Library::new` on candidate names and drops them.
    *DRIVER_PRESENT.get_or_init(|| unsafe { sys::is_culib_present() })
}

/// Lists the CUDA devices, or says why CUDA cannot be used here.
///
/// Never panics. The first call loads the driver and initialises it; the result (success or
/// reason) is cached for the life of the process. Reasons are short sentences such as
/// "libcuda.so not found ...", "no CUDA device", "driver too old: ...".
pub fn probe() -> std::result::Result<Vec<GpuInfo>, String> {
    probe_ref().clone()
}

pub(crate) fn probe_ref() -> &'static std::result::Result<Vec<GpuInfo>, String> {
    PROBE.get_or_init(|| {
        let found = if !driver_library_present() {
            Err(NO_DRIVER.to_string())
        } else {
            match catch_unwind(AssertUnwindSafe(probe_devices)) {
                Ok(r) => r,
                Err(payload) => Err(format!(
                    "the CUDA driver library could not be used: {}",
                    panic_message(payload.as_ref())
                )),
            }
        };
        log_probe(&found);
        found
    })
}

/// The probe's answer when there is no driver library at all.
const NO_DRIVER: &str = "libcuda.so not found (no NVIDIA driver installed, or it is not on \
                         the library search path)";

/// Says once what [`probe`] found: each GPU at info level; no driver or no device (an
/// ordinary machine) at info; a driver that is there but cannot be used (too old, a stub,
/// mismatched, failing) as a warning, since someone probably meant to use it.
fn log_probe(found: &std::result::Result<Vec<GpuInfo>, String>) {
    match found {
        Ok(gpus) => {
            let driver = DRIVER_VERSION.get().copied().unwrap_or(0);
            log::info!(
                "CUDA driver {}.{}: {} device(s)",
                driver / 1000,
                (driver % 1000) / 10,
                gpus.len()
            );
            for g in gpus {
                log::info!(
                    "{}: {} (sm_{}, {} SMs, {:.1} GiB)",
                    g.alias(),
                    g.name,
                    g.arch(),
                    g.multiprocessor_count,
                    g.total_memory as f64 / (1u64 << 30) as f64
                );
            }
        }
        Err(reason) if reason == NO_DRIVER || reason == "no CUDA device" => {
            log::info!("CUDA not available: {reason}")
        }
        Err(reason) => log::warn!("CUDA not available: {reason}"),
    }
}

/// The driver's CUDA version (e.g. 13000 for CUDA 13.0), once [`probe`] got that far.
pub fn driver_version() -> Option<i32> {
    let _ = probe_ref();
    DRIVER_VERSION.get().copied()
}

pub(crate) fn panic_message(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".to_string()
    }
}

fn describe(e: DriverError) -> String {
    match e.error_string() {
        Ok(s) => format!("{} ({:?})", s.to_string_lossy(), e.0),
        Err(_) => format!("{:?}", e.0),
    }
}

fn probe_devices() -> std::result::Result<Vec<GpuInfo>, String> {
    let mut version = 0i32;
    // SAFETY: plain out-parameter call; valid before cuInit.
    unsafe { sys::cuDriverGetVersion(&mut version) }
        .result()
        .map_err(|e| format!("cuDriverGetVersion failed: {}", describe(e)))?;
    let _ = DRIVER_VERSION.set(version);
    if version < MIN_DRIVER_VERSION {
        return Err(format!(
            "driver too old: it supports CUDA {}.{}, warp-lang needs CUDA {}.{} or newer",
            version / 1000,
            (version % 1000) / 10,
            MIN_DRIVER_VERSION / 1000,
            (MIN_DRIVER_VERSION % 1000) / 10
        ));
    }
    if let Err(e) = result::init() {
        return Err(match e.0 {
            sys::CUresult::CUDA_ERROR_NO_DEVICE => "no CUDA device".to_string(),
            sys::CUresult::CUDA_ERROR_STUB_LIBRARY => {
                "libcuda.so found is the CUDA toolkit's stub (no NVIDIA driver installed)"
                    .to_string()
            }
            sys::CUresult::CUDA_ERROR_SYSTEM_DRIVER_MISMATCH => {
                "driver mismatch: libcuda and the NVIDIA kernel module have different versions"
                    .to_string()
            }
            _ => format!("cuInit failed: {}", describe(e)),
        });
    }
    let count = result::device::get_count()
        .map_err(|e| format!("cuDeviceGetCount failed: {}", describe(e)))?;
    if count <= 0 {
        return Err("no CUDA device".to_string());
    }
    let mut out = Vec::with_capacity(count as usize);
    for ordinal in 0..count {
        let what =
            |call: &str, e: DriverError| format!("{call} on cuda:{ordinal}: {}", describe(e));
        let dev = result::device::get(ordinal).map_err(|e| what("cuDeviceGet", e))?;
        let name = result::device::get_name(dev).map_err(|e| what("cuDeviceGetName", e))?;
        let attr = |a: sys::CUdevice_attribute| {
            // SAFETY: `dev` is a valid device handle from cuDeviceGet.
            unsafe { result::device::get_attribute(dev, a) }
                .map_err(|e| what("cuDeviceGetAttribute", e))
        };
        use sys::CUdevice_attribute as A;
        let major = attr(A::CU_DEVICE_ATTRIBUTE_COMPUTE_CAPABILITY_MAJOR)?;
        let minor = attr(A::CU_DEVICE_ATTRIBUTE_COMPUTE_CAPABILITY_MINOR)?;
        let sms = attr(A::CU_DEVICE_ATTRIBUTE_MULTIPROCESSOR_COUNT)?;
        // SAFETY: as above.
        let total =
            unsafe { result::device::total_mem(dev) }.map_err(|e| what("cuDeviceTotalMem", e))?;
        out.push(GpuInfo {
            ordinal: ordinal as usize,
            name,
            compute_capability: (major.max(0) as u32, minor.max(0) as u32),
            total_memory: total as u64,
            multiprocessor_count: sms.max(0) as u32,
        });
    }
    Ok(out)
}

/// Fails with [`CudaError::NotAvailable`] unless [`probe`] found at least one device.
pub(crate) fn require_driver() -> Result<&'static [GpuInfo]> {
    match probe_ref() {
        Ok(list) => Ok(list),
        Err(reason) => Err(CudaError::NotAvailable(reason.clone())),
    }
}

/// An opened CUDA device: its primary context and a default stream.
///
/// Obtained with [`Gpu::open`]; there is one `Gpu` per ordinal for the whole process, so an
/// `Arc<Gpu>` can be compared by pointer and cached freely.
pub struct Gpu {
    info: GpuInfo,
    ctx: Arc<CudaContext>,
    stream: Stream,
    async_alloc: bool,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu")
            .field("info", &self.info)
            .field("async_alloc", &self.async_alloc)
            .finish()
    }
}

static GPUS: Mutex<Vec<Option<Arc<Gpu>>>> = Mutex::new(Vec::new());

impl Gpu {
    /// Opens device `ordinal` (retains its primary context and creates its default stream), or
    /// returns the already-open one.
    ///
    /// cudarc's per-argument event tracking is turned off on the context: our buffers are raw
    /// allocations ordered by streams we control, and tracking would cost an event record per
    /// argument per launch.
    pub fn open(ordinal: usize) -> Result<Arc<Gpu>> {
        let devices = require_driver()?;
        let Some(info) = devices.get(ordinal) else {
            return Err(CudaError::InvalidArgument(format!(
                "cuda:{ordinal} does not exist ({} CUDA device(s))",
                devices.len()
            )));
        };
        // A poisoned lock only means another thread panicked mid-open; the Vec is still valid.
        let mut gpus = GPUS.lock().unwrap_or_else(|e| e.into_inner());
        if gpus.len() < devices.len() {
            gpus.resize(devices.len(), None);
        }
        if let Some(gpu) = &gpus[ordinal] {
            return Ok(gpu.clone());
        }
        let ctx = CudaContext::new(ordinal).map_err(|e| {
            CudaError::driver(e, format!("cuDevicePrimaryCtxRetain on cuda:{ordinal}"))
        })?;
        // SAFETY: we never use cudarc's CudaSlice, whose cross-stream safety depends on the
        // tracking; our own buffers document their stream ordering.
        unsafe { ctx.disable_event_tracking() };
        let async_alloc = ctx.has_async_alloc();
        if async_alloc {
            // Keep freed memory in the device's pool instead of returning it to the OS at every
            // synchronisation (the default threshold is 0), so that a free followed by an
            // allocation of similar size costs no driver round trip (Warp does the same). An
            // optimisation only: failure is ignored.
            // SAFETY: valid device handle; the attribute takes a u64 (cuuint64_t).
            unsafe {
                if let Ok(pool) = result::device::get_mem_pool(ctx.cu_device()) {
                    let mut threshold = u64::MAX;
                    let _ = result::mem_pool::set_attribute(
                        pool,
                        sys::CUmemPool_attribute::CU_MEMPOOL_ATTR_RELEASE_THRESHOLD,
                        &mut threshold as *mut u64 as *mut std::ffi::c_void,
                    );
                }
            }
        }
        // A dedicated non-blocking stream rather than the legacy NULL stream: work on it does not
        // serialise against other libraries' streams, and every operation of this crate is
        // issued as an async call on an explicit stream, so nothing relies on NULL-stream
        // implicit synchronisation.
        let cu = ctx
            .new_stream()
            .map_err(|e| CudaError::driver(e, format!("cuStreamCreate on cuda:{ordinal}")))?;
        let gpu = Arc::new(Gpu {
            info: info.clone(),
            ctx,
            stream: Stream {
                inner: cu,
                ordinal,
                _owner: None,
                caller_ordered: false,
            },
            async_alloc,
        });
        gpus[ordinal] = Some(gpu.clone());
        log::debug!(
            "opened cuda:{ordinal} (primary context, stream-ordered allocation: {})",
            if async_alloc { "yes" } else { "no" }
        );
        Ok(gpu)
    }

    /// The device's description.
    pub fn info(&self) -> &GpuInfo {
        &self.info
    }

    /// The device ordinal.
    pub fn ordinal(&self) -> usize {
        self.info.ordinal
    }

    /// The architecture number, major * 10 + minor (90 for an H100/H200).
    pub fn arch(&self) -> u32 {
        self.info.arch()
    }

    /// Whether allocations are stream-ordered (`cuMemAllocAsync`); else `cuMemAlloc` is used.
    pub fn has_async_alloc(&self) -> bool {
        self.async_alloc
    }

    /// The most shared memory one block may have on this device, static and dynamic together,
    /// once a kernel opts in ([`Function::set_max_dynamic_shared_bytes`](crate::Function::set_max_dynamic_shared_bytes)):
    /// `CU_DEVICE_ATTRIBUTE_MAX_SHARED_MEMORY_PER_BLOCK_OPTIN` (227 KiB on an H100).
    pub fn max_shared_bytes_per_block_optin(&self) -> Result<usize> {
        self.bytes_attribute(
            sys::CUdevice_attribute::CU_DEVICE_ATTRIBUTE_MAX_SHARED_MEMORY_PER_BLOCK_OPTIN,
        )
    }

    /// The shared memory of one multiprocessor, which its resident blocks share:
    /// `CU_DEVICE_ATTRIBUTE_MAX_SHARED_MEMORY_PER_MULTIPROCESSOR` (228 KiB on an H100).
    pub fn max_shared_bytes_per_sm(&self) -> Result<usize> {
        self.bytes_attribute(
            sys::CUdevice_attribute::CU_DEVICE_ATTRIBUTE_MAX_SHARED_MEMORY_PER_MULTIPROCESSOR,
        )
    }

    /// The shared memory the system reserves for each resident block, on top of the block's
    /// own: `CU_DEVICE_ATTRIBUTE_RESERVED_SHARED_MEMORY_PER_BLOCK` (1 KiB on an H100).
    pub fn reserved_shared_bytes_per_block(&self) -> Result<usize> {
        self.bytes_attribute(
            sys::CUdevice_attribute::CU_DEVICE_ATTRIBUTE_RESERVED_SHARED_MEMORY_PER_BLOCK,
        )
    }

    /// A device attribute that counts bytes.
    fn bytes_attribute(&self, attr: sys::CUdevice_attribute) -> Result<usize> {
        // SAFETY: the device handle of a live context.
        unsafe { result::device::get_attribute(self.ctx.cu_device(), attr) }
            .map(|v| v.max(0) as usize)
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!("cuDeviceGetAttribute({attr:?}) on cuda:{}", self.ordinal()),
                )
            })
    }

    /// Waits for all work on all streams of this device.
    pub fn synchronize(&self) -> Result<()> {
        self.ctx.synchronize().map_err(|e| {
            CudaError::driver(e, format!("cuCtxSynchronize on cuda:{}", self.ordinal()))
        })
    }

    /// The device's default stream: allocations, frees, uploads, downloads and fills of
    /// [`DeviceBuffer`](crate::DeviceBuffer) run on it.
    pub fn default_stream(&self) -> &Stream {
        &self.stream
    }

    /// Creates a new non-blocking stream. Ordering it against other streams is the caller's
    /// job ([`Stream::wait_stream`], [`Stream::wait_event`]).
    pub fn new_stream(&self) -> Result<Stream> {
        let inner = self.ctx.new_stream().map_err(|e| {
            CudaError::driver(e, format!("cuStreamCreate on cuda:{}", self.ordinal()))
        })?;
        Ok(Stream {
            inner,
            ordinal: self.ordinal(),
            _owner: None,
            caller_ordered: false,
        })
    }

    /// Wraps a stream that another library created (PyTorch's, another CUDA crate's) in
    /// this device's context; it is never destroyed here, and `owner` (what keeps it alive)
    /// is held by every clone of the wrapper.
    ///
    /// # Safety
    /// `cu_stream` must be a valid stream of this device's primary context and stay alive
    /// while `owner` lives (or forever, without one).
    pub unsafe fn wrap_stream(
        &self,
        cu_stream: sys::CUstream,
        owner: Option<Arc<dyn std::any::Any + Send + Sync>>,
    ) -> Stream {
        // SAFETY: the caller's contract.
        let inner = unsafe { self.ctx.wrap_borrowed_stream(cu_stream) };
        Stream {
            inner,
            ordinal: self.ordinal(),
            _owner: owner,
            caller_ordered: false,
        }
    }

    /// Creates an event; `timing: true` lets it be used with [`Event::elapsed_ms`] (timing
    /// events are slightly more expensive to record).
    pub fn new_event(&self, timing: bool) -> Result<Event> {
        let flags = if timing {
            sys::CUevent_flags::CU_EVENT_DEFAULT
        } else {
            sys::CUevent_flags::CU_EVENT_DISABLE_TIMING
        };
        let inner = self.ctx.new_event(Some(flags)).map_err(|e| {
            CudaError::driver(e, format!("cuEventCreate on cuda:{}", self.ordinal()))
        })?;
        Ok(Event {
            inner,
            ordinal: self.ordinal(),
        })
    }

    /// Free and total device memory in bytes.
    pub fn mem_info(&self) -> Result<(usize, usize)> {
        self.ctx
            .mem_get_info()
            .map_err(|e| CudaError::driver(e, format!("cuMemGetInfo on cuda:{}", self.ordinal())))
    }

    /// The underlying cudarc context (for benchmarks and interop). Do not re-enable event
    /// tracking on it.
    pub fn cudarc_context(&self) -> &Arc<CudaContext> {
        &self.ctx
    }

    /// Makes this device's context current on the calling thread (CUDA contexts are per
    /// thread; cheap when it already is).
    pub(crate) fn bind(&self) -> Result<()> {
        self.ctx.bind_to_thread().map_err(|e| {
            CudaError::driver(e, format!("cuCtxSetCurrent on cuda:{}", self.ordinal()))
        })
    }

    pub(crate) fn cu_ctx(&self) -> sys::CUcontext {
        self.ctx.cu_ctx()
    }

    /// Whether this GPU can read and write `peer`'s memory directly (over NVLink or PCIe),
    /// which [`enable_peer_access`](Self::enable_peer_access) then turns on. False for the
    /// same GPU.
    pub fn can_access_peer(&self, peer: &Gpu) -> Result<bool> {
        if self.ordinal() == peer.ordinal() {
            return Ok(false);
        }
        let mut can: std::ffi::c_int = 0;
        // SAFETY: valid device handles and out pointer.
        unsafe { sys::cuDeviceCanAccessPeer(&mut can, self.ctx.cu_device(), peer.ctx.cu_device()) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!(
                        "cuDeviceCanAccessPeer (cuda:{} to cuda:{})",
                        self.ordinal(),
                        peer.ordinal()
                    ),
                )
            })?;
        Ok(can != 0)
    }

    /// Lets kernels and copies on this GPU access `peer`'s memory directly, where the
    /// hardware allows; returns whether access is on. Without it, copies between the two are
    /// staged through host memory by the driver (correct, slower). Idempotent.
    pub fn enable_peer_access(&self, peer: &Gpu) -> Result<bool> {
        if !self.can_access_peer(peer)? {
            return Ok(false);
        }
        self.bind()?;
        // SAFETY: the peer's live primary context; flags must be 0.
        match unsafe { sys::cuCtxEnablePeerAccess(peer.cu_ctx(), 0) } {
            sys::CUresult::CUDA_SUCCESS | sys::CUresult::CUDA_ERROR_PEER_ACCESS_ALREADY_ENABLED => {
                Ok(true)
            }
            e => Err(CudaError::driver(
                cudarc::driver::DriverError(e),
                format!(
                    "cuCtxEnablePeerAccess (cuda:{} to cuda:{})",
                    self.ordinal(),
                    peer.ordinal()
                ),
            )),
        }
    }

    /// Turns direct access to `peer`'s memory off again; returns whether it had been on.
    pub fn disable_peer_access(&self, peer: &Gpu) -> Result<bool> {
        if self.ordinal() == peer.ordinal() {
            return Ok(false);
        }
        self.bind()?;
        // SAFETY: the peer's live primary context.
        match unsafe { sys::cuCtxDisablePeerAccess(peer.cu_ctx()) } {
            sys::CUresult::CUDA_SUCCESS => Ok(true),
            sys::CUresult::CUDA_ERROR_PEER_ACCESS_NOT_ENABLED => Ok(false),
            e => Err(CudaError::driver(
                cudarc::driver::DriverError(e),
                format!(
                    "cuCtxDisablePeerAccess (cuda:{} to cuda:{})",
                    self.ordinal(),
                    peer.ordinal()
                ),
            )),
        }
    }
}

/// A CUDA stream on one device. Cloning is cheap (shared handle); the stream is destroyed when
/// the last clone is dropped.
#[derive(Clone, Debug)]
pub struct Stream {
    inner: Arc<CudaStream>,
    ordinal: usize,
    /// What keeps a wrapped external stream alive ([`Gpu::wrap_stream`]).
    _owner: Option<Arc<dyn std::any::Any + Send + Sync>>,
    /// Ordered by its owner alone ([`Stream::caller_ordered`]).
    caller_ordered: bool,
}

impl Stream {
    /// Waits until all work queued on this stream has finished.
    pub fn synchronize(&self) -> Result<()> {
        self.inner.synchronize().map_err(|e| {
            CudaError::driver(e, format!("cuStreamSynchronize on cuda:{}", self.ordinal))
        })
    }

    /// Whether all work queued on this stream has finished (`cuStreamQuery`), without
    /// blocking: what a wait with a timeout polls.
    pub fn query(&self) -> Result<bool> {
        self.bind()?;
        // SAFETY: a live stream of the bound context.
        match unsafe { sys::cuStreamQuery(self.cu_stream()) } {
            sys::CUresult::CUDA_SUCCESS => Ok(true),
            sys::CUresult::CUDA_ERROR_NOT_READY => Ok(false),
            e => Err(CudaError::driver(
                cudarc::driver::DriverError(e),
                format!("cuStreamQuery on cuda:{}", self.ordinal),
            )),
        }
    }

    /// Makes future work on this stream wait for `event`'s recorded work (any device).
    pub fn wait_event(&self, event: &Event) -> Result<()> {
        self.inner.wait(&event.inner).map_err(|e| {
            CudaError::driver(e, format!("cuStreamWaitEvent on cuda:{}", self.ordinal))
        })
    }

    /// Makes future work on this stream wait for the work queued so far on `other` (any
    /// device). Costs one event record and one wait, no host blocking.
    pub fn wait_stream(&self, other: &Stream) -> Result<()> {
        if Arc::ptr_eq(&self.inner, &other.inner) {
            return Ok(());
        }
        self.inner.join(&other.inner).map_err(|e| {
            CudaError::driver(
                e,
                format!(
                    "cuStreamWaitEvent (cuda:{} waits for cuda:{})",
                    self.ordinal, other.ordinal
                ),
            )
        })
    }

    /// Ordinal of the device this stream belongs to.
    pub fn ordinal(&self) -> usize {
        self.ordinal
    }

    /// This handle marked as ordered by its owner alone: the runtime queues work on it with no
    /// joins of its own (no wait for its default stream, nothing for the default stream to
    /// wait for), as work a CUDA graph capture of the owner's stream may contain. Only this
    /// handle and its clones carry the mark.
    pub fn caller_ordered(mut self) -> Stream {
        self.caller_ordered = true;
        self
    }

    /// Whether this handle is [`caller_ordered`](Self::caller_ordered).
    pub fn is_caller_ordered(&self) -> bool {
        self.caller_ordered
    }

    /// Whether `self` and `other` are handles of the same stream.
    pub fn is(&self, other: &Stream) -> bool {
        Arc::ptr_eq(&self.inner, &other.inner)
    }

    /// The raw `CUstream` handle. Do not destroy it.
    pub fn cu_stream(&self) -> sys::CUstream {
        self.inner.cu_stream()
    }

    /// The underlying cudarc stream (for benchmarks and interop).
    pub fn cudarc_stream(&self) -> &Arc<CudaStream> {
        &self.inner
    }

    pub(crate) fn cu_ctx(&self) -> sys::CUcontext {
        self.inner.context().cu_ctx()
    }

    /// Binds the stream's context to the calling thread.
    pub(crate) fn bind(&self) -> Result<()> {
        self.inner
            .context()
            .bind_to_thread()
            .map_err(|e| CudaError::driver(e, format!("cuCtxSetCurrent on cuda:{}", self.ordinal)))
    }
}

/// A CUDA event, for ordering streams and timing.
#[derive(Debug)]
pub struct Event {
    inner: CudaEvent,
    ordinal: usize,
}

type ElapsedFn = unsafe extern "C" fn(*mut f32, sys::CUevent, sys::CUevent) -> sys::CUresult;

/// `cuEventElapsedTime_v2` (CUDA 12.8+), else the original `cuEventElapsedTime`, looked up by
/// hand: cudarc's CUDA 13 bindings name only `_v2`, and a missing symbol would panic there.
fn elapsed_fn() -> Option<ElapsedFn> {
    static F: OnceLock<Option<ElapsedFn>> = OnceLock::new();
    *F.get_or_init(|| {
        // SAFETY: only reached after probe() succeeded, so culib() finds the library; the
        // symbol types match the CUDA headers for both names.
        let lib = unsafe { sys::culib() };
        for name in [
            &b"cuEventElapsedTime_v2\0"[..],
            &b"cuEventElapsedTime\0"[..],
        ] {
            if let Ok(sym) = unsafe { lib.get::<ElapsedFn>(name) } {
                return Some(*sym);
            }
        }
        None
    })
}

impl Event {
    /// Captures the work queued so far on `stream` (which must belong to the same device).
    pub fn record(&self, stream: &Stream) -> Result<()> {
        if stream.ordinal != self.ordinal {
            return Err(CudaError::InvalidArgument(format!(
                "event of cuda:{} recorded on a stream of cuda:{}",
                self.ordinal, stream.ordinal
            )));
        }
        self.inner
            .record(&stream.inner)
            .map_err(|e| CudaError::driver(e, format!("cuEventRecord on cuda:{}", self.ordinal)))
    }

    /// Waits until the captured work has finished.
    pub fn synchronize(&self) -> Result<()> {
        self.inner.synchronize().map_err(|e| {
            CudaError::driver(e, format!("cuEventSynchronize on cuda:{}", self.ordinal))
        })
    }

    /// Whether the captured work has finished (an unrecorded event counts as finished).
    pub fn is_complete(&self) -> Result<bool> {
        self.inner
            .try_is_complete()
            .map_err(|e| CudaError::driver(e, format!("cuEventQuery on cuda:{}", self.ordinal)))
    }

    /// Milliseconds between this event and `end` (both created with `timing: true`, both
    /// recorded); waits for both.
    pub fn elapsed_ms(&self, end: &Event) -> Result<f32> {
        if end.ordinal != self.ordinal {
            return Err(CudaError::InvalidArgument(
                "elapsed_ms between events of different devices".into(),
            ));
        }
        self.synchronize()?;
        end.synchronize()?;
        let f = elapsed_fn().ok_or_else(|| {
            CudaError::NotAvailable("libcuda has no cuEventElapsedTime symbol".into())
        })?;
        let mut ms = 0f32;
        // SAFETY: both events are live handles of the same context, recorded and complete.
        unsafe { f(&mut ms, self.inner.cu_event(), end.inner.cu_event()) }
            .result()
            .map_err(|e| {
                CudaError::driver(e, format!("cuEventElapsedTime on cuda:{}", self.ordinal))
            })?;
        Ok(ms)
    }

    /// The raw `CUevent` handle. Do not destroy it.
    pub fn cu_event(&self) -> sys::CUevent {
        self.inner.cu_event()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn probe_never_panics_and_is_cached() {
        let a = probe();
        let b = probe();
        assert_eq!(a, b);
        match a {
            Ok(list) => {
                assert!(!list.is_empty());
                for (i, g) in list.iter().enumerate() {
                    assert_eq!(g.ordinal, i);
                    assert!(g.arch() >= 50, "{g:?}");
                }
            }
            Err(reason) => {
                assert!(!reason.is_empty());
                eprintln!("probe: {reason}");
            }
        }
    }

    #[test]
    fn open_without_driver_is_an_error() {
        if let Err(reason) = probe() {
            match Gpu::open(0) {
                Err(CudaError::NotAvailable(r)) => assert_eq!(r, reason),
                other => panic!("expected NotAvailable, got {other:?}"),
            }
        }
    }

    #[test]
    fn open_out_of_range_ordinal() {
        if let Ok(list) = probe() {
            assert!(matches!(
                Gpu::open(list.len() + 3),
                Err(CudaError::InvalidArgument(_))
            ));
        }
    }

    #[test]
    fn arch_number() {
        let g = GpuInfo {
            ordinal: 1,
            name: "x".into(),
            compute_capability: (9, 0),
            total_memory: 1,
            multiprocessor_count: 132,
        };
        assert_eq!(g.arch(), 90);
        assert_eq!(g.alias(), "cuda:1");
    }
}

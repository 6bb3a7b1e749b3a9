//! The backends of this build, and the one place that picks one: a device's kind names its
//! backend (`with_backend!`), and an array's [`Storage`] is the memory of one of them.
//!
//! Everything above (launch, tapes, arrays, graphs) calls the functions here; nothing else
//! names a backend. A new backend adds an arm to `with_backend!`, a variant to [`Storage`] and
//! to [`Replay`] with their arms, and its device kind to `device.rs` (see `backend.rs` for
//! what it implements).
//!
//! Every operation a backend enqueues passes here, so this is where a capture meets it: the
//! capture's rules (`capturing.rs`: its device, what the graph keeps), then the backend's
//! [`Backend::record`] (the CPU records the operation, a GPU queues it into the capture).

use crate::backend::{Backend, Buffer, Conditional, ObjectStep, Op, Record};
use crate::capturing::{self, Keep};
use crate::cpu::capture::CpuGraph;
use crate::cpu::memory::HostBuffer;
use crate::cpu::Cpu;
#[cfg(feature = "cuda")]
use crate::cuda::capture::CudaGraph;
#[cfg(feature = "cuda")]
use crate::cuda::{memory::CudaBuffer, Cuda};
use crate::device::{Device, DeviceKind};
use crate::error::{Error, Result};
use crate::kernel::{ArgsOf, Kernel, KernelParams};
use crate::launch_id;
use crate::primitives::elements::{Extent, ScanOps, SortKeyOps, SortValueOps};
use crate::primitives::plan::ReduceOp;
use warp_core::{Grid, LaunchId};

/// Evaluates `$body` with `$b` bound to the backend of `$device`.
macro_rules! with_backend {
    ($device:expr, $b:ident => $body:expr) => {{
        let device: &Device = $device;
        match device.kind() {
            DeviceKind::Cpu => {
                let $b = Cpu::new(device);
                $body
            }
            #[cfg(feature = "cuda")]
            DeviceKind::Cuda { ordinal } => {
                let $b = Cuda::new(device, ordinal);
                $body
            }
            #[cfg(not(feature = "cuda"))]
            DeviceKind::Cuda { .. } => Err(Error::NoDevice {
                name: device.alias().to_string(),
                reason: crate::device::CUDA_UNAVAILABLE.to_string(),
            }),
        }
    }};
}

/// Makes `kernels` ready on `device`; see [`Backend::prepare`].
pub(crate) fn prepare(
    device: &Device,
    kernels: &[&'static crate::kernel::KernelInfo],
    adjoint: Option<usize>,
) -> Result<()> {
    with_backend!(device, b => b.prepare(kernels, adjoint, None))
}

/// Makes the tiled `kernels` ready on `device` for blocks of `block_dim` threads; see
/// [`Backend::prepare`].
pub(crate) fn prepare_tiled(
    device: &Device,
    kernels: &[&'static crate::kernel::KernelInfo],
    block_dim: usize,
) -> Result<()> {
    with_backend!(device, b => b.prepare(kernels, None, Some(block_dim)))
}

/// Runs (or queues) a launch of `K` on `device`; see [`Backend::launch`]. Inside a capture,
/// recorded ([`captured_launch`]).
#[inline]
pub(crate) fn launch<K: Kernel>(device: &Device, args: &ArgsOf<'_, K>, grid: &Grid) -> Result<()> {
    names_every_param::<K>();
    if capturing::capturing() {
        return captured_launch::<K>(device, args, grid, None);
    }
    let id = launch_id::next();
    run_launch::<K>(device, args, grid, None, id)
}

/// The launch of `K` (its adjoint with `adjoint: Some(stack bytes)`) numbered `id`, on
/// `device`'s backend.
fn run_launch<K: Kernel>(
    device: &Device,
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    adjoint: Option<usize>,
    id: LaunchId,
) -> Result<()> {
    with_backend!(device, b => match adjoint {
        None => b.launch::<K>(args, grid, id),
        Some(bytes) => b.launch_adjoint::<K>(args, grid, bytes, id),
    })
    .map_err(|e| e.in_launch(id))
}

/// A launch of `K` (or its adjoint) inside the calling thread's capture: on the capture's
/// device only; the backend records it (the CPU: an operation owning the arguments, which
/// replays the launch under the number it has now, as a GPU graph's launches keep theirs) or
/// queues it into the capture (a GPU: the graph keeps the arguments).
#[cold]
fn captured_launch<K: Kernel>(
    device: &Device,
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    adjoint: Option<usize>,
) -> Result<()> {
    capturing::check_device(device, &|| format!("a launch of kernel `{}`", K::INFO.name))?;
    let id = launch_id::next();
    let record = with_backend!(device, b => Ok::<_, Error>(b.record(|| {
        let owned = K::Params::own(args);
        let (grid, device) = (*grid, device.clone());
        Box::new(move || {
            run_launch::<K>(&device, &K::Params::borrow(&owned), &grid, adjoint, id)
        })
    })))?;
    if record == Record::Enqueue {
        run_launch::<K>(device, args, grid, adjoint, id)?;
        capturing::keep(Box::new(K::Params::own(args)));
    }
    capturing::launched();
    Ok(())
}

/// Queues a launch of `K` on `stream`: streams are the CUDA backend's API. Inside a capture,
/// only on the capture stream (`GpuState::queue` refuses another), with the arguments kept.
#[cfg(feature = "cuda")]
pub(crate) fn launch_on<K: Kernel>(
    stream: &crate::cuda::stream::Stream,
    args: &ArgsOf<'_, K>,
    grid: &Grid,
) -> Result<()> {
    names_every_param::<K>();
    let capturing = capturing::capturing();
    if capturing {
        capturing::check_device(stream.device(), &|| {
            format!("a launch of kernel `{}`", K::INFO.name)
        })?;
    }
    let id = launch_id::next();
    Cuda::of_stream(stream)
        .launch_on::<K>(args, grid, stream, id)
        .map_err(|e| e.in_launch(id))?;
    if capturing {
        capturing::keep(Box::new(K::Params::own(args)));
        capturing::launched();
    }
    Ok(())
}

/// A launch of `K` made ready to be queued again and again (a launch object's): on a GPU the
/// loaded kernel, the launch dims and the fault context; the CPU keeps nothing (the marker
/// only ties the variant to `K`, which a build without `cuda` would otherwise leave unused).
pub(crate) enum Prepared<K: Kernel> {
    Cpu(std::marker::PhantomData<fn() -> K>),
    #[cfg(feature = "cuda")]
    Cuda(crate::cuda::launch::Prepared<K>),
}

/// Makes a launch of `K` with `args` over `grid` on `device` ready (compiling the kernel on
/// a GPU); see [`launch_prepared`].
pub(crate) fn prepare_launch<K: Kernel>(
    device: &Device,
    // The CPU keeps nothing: only a GPU's preparation reads the arguments and the grid.
    #[cfg_attr(not(feature = "cuda"), allow(unused_variables))] args: &ArgsOf<'_, K>,
    #[cfg_attr(not(feature = "cuda"), allow(unused_variables))] grid: &Grid,
) -> Result<Prepared<K>> {
    names_every_param::<K>();
    match device.kind() {
        DeviceKind::Cpu => Ok(Prepared::Cpu(std::marker::PhantomData)),
        #[cfg(feature = "cuda")]
        DeviceKind::Cuda { ordinal } => {
            crate::cuda::launch::Prepared::new(args, grid, device, ordinal, None)
                .map(Prepared::Cuda)
        }
        #[cfg(not(feature = "cuda"))]
        DeviceKind::Cuda { .. } => Err(Error::NoDevice {
            name: device.alias().to_string(),
            reason: crate::device::CUDA_UNAVAILABLE.to_string(),
        }),
    }
}

/// Runs (or queues, on `stream` when given) a prepared launch with `args`: the arguments it
/// was prepared with, or others of the same devices, shapes and contiguity.
pub(crate) fn launch_prepared<K: Kernel>(
    device: &Device,
    prepared: &Prepared<K>,
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    #[cfg(feature = "cuda")] stream: Option<&crate::cuda::stream::Stream>,
) -> Result<()> {
    let id = launch_id::next();
    match prepared {
        Prepared::Cpu(_) => Cpu::new(device).launch::<K>(args, grid, id),
        #[cfg(feature = "cuda")]
        Prepared::Cuda(p) => p.enqueue(args, device, stream.map(|s| s.cuda_stream()), id),
    }
    .map_err(|e| e.in_launch(id))
}

/// Checks, at compile time, that `K`'s info names each parameter: the conversions name
/// parameter `k` by `INFO.params[k]`.
fn names_every_param<K: Kernel>() {
    const {
        assert!(
            K::INFO.params.len() == <K::Params as KernelParams>::COUNT,
            "KernelInfo::params must name every parameter of Kernel::Params"
        )
    };
}

/// Runs (or queues) the adjoint of a launch of `K` on `device`; see
/// [`Backend::launch_adjoint`].
pub(crate) fn launch_adjoint<K: Kernel>(
    device: &Device,
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    adstack_bytes: usize,
) -> Result<()> {
    if let Some(reason) = K::INFO.adjoint_error {
        return Err(Error::NotDifferentiable {
            kernel: K::INFO.name,
            reason: reason.to_string(),
        });
    }
    if capturing::capturing() {
        // A captured backward pass.
        return captured_launch::<K>(device, args, grid, Some(adstack_bytes));
    }
    let id = launch_id::next();
    run_launch::<K>(device, args, grid, Some(adstack_bytes), id)
}

/// Queues the adjoint of a launch of `K` on `stream` (a CUDA stream), as [`launch_on`]
/// queues a launch; see [`launch_adjoint`].
#[cfg(feature = "cuda")]
pub(crate) fn launch_adjoint_on<K: Kernel>(
    stream: &crate::cuda::stream::Stream,
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    adstack_bytes: usize,
) -> Result<()> {
    names_every_param::<K>();
    if let Some(reason) = K::INFO.adjoint_error {
        return Err(Error::NotDifferentiable {
            kernel: K::INFO.name,
            reason: reason.to_string(),
        });
    }
    let capturing = capturing::capturing();
    if capturing {
        capturing::check_device(stream.device(), &|| {
            format!("the adjoint of kernel `{}`", K::INFO.name)
        })?;
    }
    let id = launch_id::next();
    Cuda::of_stream(stream)
        .launch_adjoint_on::<K>(args, grid, stream, adstack_bytes, id)
        .map_err(|e| e.in_launch(id))?;
    if capturing {
        capturing::keep(Box::new(K::Params::own(args)));
        capturing::launched();
    }
    Ok(())
}

/// An operation (`what`) that `run` enqueues on `device`'s backend, using the memory of
/// `uses()` by address: run now, or inside the calling thread's capture recorded (on the
/// capture's device only), with `uses()` kept for the graph's replays. (A host object's
/// operation of its own, a CPU tree's refit, is one too.)
pub(crate) fn enqueue(
    device: &Device,
    what: &str,
    uses: impl FnOnce() -> Keep,
    run: impl Fn(&Device) -> Result<()> + Send + 'static,
) -> Result<()> {
    if !capturing::capturing() {
        return run(device);
    }
    capturing::check_device(device, &|| what.to_string())?;
    let uses = uses();
    let mut parts = Some((uses, run));
    let record = with_backend!(device, b => Ok::<_, Error>(b.record(|| {
        let (uses, run) = parts.take().expect("recorded once");
        let device = device.clone();
        Box::new(move || {
            // (The operation owns what it uses: alive as long as the graph.)
            let _uses = &uses;
            run(&device)
        })
    })))?;
    if let (Record::Enqueue, Some((uses, run))) = (record, parts) {
        run(device)?;
        capturing::keep(uses);
    }
    Ok(())
}

/// An operation on arrays of `devices` (`what`: a fill, a copy) inside the calling thread's
/// capture, if any (`None` otherwise): on the capture's device only, `uses()` kept for the
/// graph. `Recorded`: the backend recorded `op()`, which does it again at each replay (the
/// CPU); `Enqueue`: the caller does it now, its work going into the capture (a GPU).
pub(crate) fn on_array_op(
    devices: &[&Device],
    what: &str,
    uses: impl FnOnce() -> Keep,
    op: impl FnOnce() -> Op,
) -> Result<Option<Record>> {
    let Some(device) = capturing::device() else {
        return Ok(None);
    };
    for d in devices {
        capturing::check_device(d, &|| what.to_string())?;
    }
    let record = with_backend!(&device, b => Ok::<_, Error>(b.record(op)))?;
    if record == Record::Enqueue {
        capturing::keep(uses());
    }
    Ok(Some(record))
}

/// A scan on `device`'s backend; see [`Backend::scan`]. `uses()`: the arrays (kept by a
/// graph that records the scan).
pub(crate) fn scan<T: ScanOps>(
    device: &Device,
    func: &'static str,
    input: u64,
    output: u64,
    len: Extent,
    inclusive: bool,
    uses: impl FnOnce() -> Keep,
) -> Result<()> {
    enqueue(
        device,
        func,
        uses,
        move |d| with_backend!(d, b => b.scan::<T>(func, input, output, len, inclusive)),
    )
}

/// A reduction on `device`'s backend; see [`Backend::reduce`] (and [`scan`] for `uses`).
pub(crate) fn reduce<T: ScanOps>(
    device: &Device,
    func: &'static str,
    input: u64,
    out: u64,
    len: Extent,
    op: ReduceOp,
    uses: impl FnOnce() -> Keep,
) -> Result<()> {
    enqueue(
        device,
        func,
        uses,
        move |d| with_backend!(d, b => b.reduce::<T>(func, input, out, len, op)),
    )
}

/// A radix sort on `device`'s backend; see [`Backend::radix_sort_pairs`] (and [`scan`] for
/// `uses`).
pub(crate) fn radix_sort_pairs<K: SortKeyOps, V: SortValueOps>(
    device: &Device,
    func: &'static str,
    keys: u64,
    values: u64,
    len: Extent,
    key_bits: u32,
    uses: impl FnOnce() -> Keep,
) -> Result<()> {
    enqueue(
        device,
        func,
        uses,
        move |d| with_backend!(d, b => b.radix_sort_pairs::<K, V>(func, keys, values, len, key_bits)),
    )
}

/// Runs or queues a step of a host object's build on `device`'s backend; see
/// [`Backend::object_step`]. Refused inside a capture: the graph would not know what memory
/// the step uses ([`object_step_keeping`] is told).
pub(crate) fn object_step<S: ObjectStep>(device: &Device, step: &S) -> Result<()> {
    capturing::refuse(Some(device), "a host object's build")?;
    with_backend!(device, b => b.object_step(step))
}

/// [`object_step`], recorded inside a capture like a launch, with `uses()` (the object's
/// memory that the step's addresses point into) kept for the graph's replays.
pub(crate) fn object_step_keeping<S: ObjectStep + 'static>(
    device: &Device,
    step: &S,
    uses: impl FnOnce() -> Keep,
) -> Result<()> {
    let step = *step;
    enqueue(
        device,
        "a host object's build step",
        uses,
        move |d| with_backend!(d, b => b.object_step(&step)),
    )
}

/// A stream compaction on `device`'s backend; see [`Backend::compact`] (and [`scan`] for
/// `uses`).
pub(crate) fn compact<T: bytemuck::Pod + Send + Sync>(
    device: &Device,
    func: &'static str,
    arrays: [u64; 4],
    len: Extent,
    uses: impl FnOnce() -> Keep,
) -> Result<()> {
    enqueue(
        device,
        func,
        uses,
        move |d| with_backend!(d, b => b.compact::<T>(func, arrays, len)),
    )
}

/// `bytes` of zeroed memory on `device`, aligned to at least `align`.
pub(crate) fn alloc_zeroed(device: &Device, bytes: usize, align: usize) -> Result<Storage> {
    capturing::refuse(Some(device), "an allocation")?;
    with_backend!(device, b => b.alloc_zeroed(bytes, align).map(Storage::from))
}

/// Waits for `device` and reports a fault recorded there since the last check.
pub(crate) fn synchronize(device: &Device) -> Result<()> {
    capturing::refuse(Some(device), "a synchronisation")?;
    with_backend!(device, b => b.synchronize())
}

/// [`synchronize`] for every device used so far.
pub(crate) fn synchronize_all() -> Result<()> {
    capturing::refuse(None, "a synchronisation")?;
    Cpu::synchronize_all()?;
    #[cfg(feature = "cuda")]
    Cuda::synchronize_all()?;
    Ok(())
}

/// Starts capturing the calling thread's work on `device`; see [`Backend::begin_capture`].
pub(crate) fn begin_capture(device: &Device) -> Result<()> {
    with_backend!(device, b => b.begin_capture())
}

/// Starts capturing the calling thread's work on `stream`: streams are the CUDA backend's API.
#[cfg(feature = "cuda")]
pub(crate) fn begin_capture_on(stream: &crate::cuda::stream::Stream) -> Result<()> {
    Cuda::of_stream(stream).begin_capture_on(stream)
}

/// Ends the calling thread's capture on `device`; see [`Backend::end_capture`].
pub(crate) fn end_capture(device: &Device) -> Result<Replay> {
    with_backend!(device, b => b.end_capture().map(Replay::from))
}

/// Ends the calling thread's capture on `device`, dropping what it recorded.
pub(crate) fn abort_capture(device: &Device) {
    // (Without the backend in this build there is no capture to end.)
    let _: Result<()> = with_backend!(device, b => {
        b.abort_capture();
        Ok(())
    });
}

/// A conditional inside the calling thread's capture on `device`; see
/// [`Backend::capture_conditional`].
pub(crate) fn capture_conditional(
    device: &Device,
    kind: Conditional,
    cond: u64,
    then: &mut dyn FnMut() -> Result<()>,
    otherwise: Option<&mut dyn FnMut() -> Result<()>>,
) -> Result<()> {
    with_backend!(device, b => b.capture_conditional(kind, cond, then, otherwise))
}

/// What a graph replays: one backend's [`Backend::Graph`].
pub(crate) enum Replay {
    Cpu(CpuGraph),
    #[cfg(feature = "cuda")]
    Cuda(CudaGraph),
}

impl From<CpuGraph> for Replay {
    fn from(g: CpuGraph) -> Replay {
        Replay::Cpu(g)
    }
}

#[cfg(feature = "cuda")]
impl From<CudaGraph> for Replay {
    fn from(g: CudaGraph) -> Replay {
        Replay::Cuda(g)
    }
}

impl Replay {
    /// The graph's size: recorded operations on the CPU; CUDA graph nodes (kernels, memsets,
    /// copies, conditionals) on a GPU.
    pub(crate) fn node_count(&self) -> usize {
        match self {
            Replay::Cpu(g) => g.node_count(),
            #[cfg(feature = "cuda")]
            Replay::Cuda(g) => g.node_count(),
        }
    }
}

/// Replays `graph`, captured on `device`; see [`Backend::replay`].
pub(crate) fn replay(device: &Device, graph: &Replay) -> Result<()> {
    match (graph, device.kind()) {
        (Replay::Cpu(g), DeviceKind::Cpu) => Cpu::new(device).replay(g),
        #[cfg(feature = "cuda")]
        (Replay::Cuda(g), DeviceKind::Cuda { ordinal }) => Cuda::new(device, ordinal).replay(g),
        // (`Graph` pairs each recording with the device it was captured on.)
        _ => Err(Error::Capture {
            what: format!("a graph replayed on \"{device}\", another kind of device"),
        }),
    }
}

/// Replays `graph` (captured on `device`) on `stream`: streams are the CUDA backend's API.
#[cfg(feature = "cuda")]
pub(crate) fn replay_on(
    device: &Device,
    graph: &Replay,
    stream: &crate::cuda::stream::Stream,
) -> Result<()> {
    match (graph, device.kind()) {
        (Replay::Cuda(g), DeviceKind::Cuda { ordinal }) => {
            Cuda::new(device, ordinal).replay_on(g, stream)
        }
        _ => Err(Error::Capture {
            what: format!(
                "a graph captured on \"{device}\" launched on a stream of \"{}\"",
                stream.device()
            ),
        }),
    }
}

/// The memory behind an array: one backend's [`Buffer`].
pub(crate) enum Storage {
    /// Host memory (the CPU backend's): host code and CPU kernels address it directly.
    Host(HostBuffer),
    /// Memory on a CUDA GPU.
    #[cfg(feature = "cuda")]
    Cuda(CudaBuffer),
}

impl From<HostBuffer> for Storage {
    fn from(b: HostBuffer) -> Storage {
        Storage::Host(b)
    }
}

#[cfg(feature = "cuda")]
impl From<CudaBuffer> for Storage {
    fn from(b: CudaBuffer) -> Storage {
        Storage::Cuda(b)
    }
}

/// Evaluates `$body` with `$b` bound to the buffer in `$storage`, whichever backend's it is.
macro_rules! with_buffer {
    ($storage:expr, $b:ident => $body:expr) => {
        match $storage {
            Storage::Host($b) => $body,
            #[cfg(feature = "cuda")]
            Storage::Cuda($b) => $body,
        }
    };
}

impl Storage {
    /// Host memory that takes `data`'s allocation over, without a copy.
    pub(crate) fn host_from_vec<T: bytemuck::Pod>(data: Vec<T>) -> Result<Storage> {
        HostBuffer::from_vec(data).map(Storage::Host)
    }

    /// External memory of `bytes` bytes at `address` on `device`, not freed by the storage;
    /// `owner` drops with it (on a GPU once the work queued there has finished). Without an
    /// owner nothing waits at the drop (an op call's memory, which the caller orders).
    ///
    /// # Safety
    /// The memory must be valid on `device` (host memory for the CPU, device memory of that
    /// GPU's context) for reads and writes of `bytes` bytes for as long as `owner` lives (or,
    /// without one, as long as the storage and the work queued on it).
    pub(crate) unsafe fn external(
        device: &Device,
        address: u64,
        bytes: usize,
        owner: Option<Box<dyn std::any::Any + Send + Sync>>,
    ) -> Result<Storage> {
        match device.kind() {
            DeviceKind::Cpu => {
                let ptr = std::ptr::NonNull::new(address as usize as *mut u8)
                    .ok_or_else(|| Error::invalid("external memory at address 0"))?;
                // SAFETY: the caller's contract.
                Ok(Storage::Host(unsafe {
                    HostBuffer::external(ptr, bytes, owner)
                }))
            }
            #[cfg(feature = "cuda")]
            DeviceKind::Cuda { ordinal } => {
                // SAFETY: the caller's contract.
                unsafe { CudaBuffer::external(ordinal, address, bytes, owner) }.map(Storage::Cuda)
            }
            #[cfg(not(feature = "cuda"))]
            DeviceKind::Cuda { .. } => Err(Error::NoDevice {
                name: device.alias().to_string(),
                reason: crate::device::CUDA_UNAVAILABLE.to_string(),
            }),
        }
    }

    /// The host memory, for arrays on the CPU (`None` for a device's).
    pub(crate) fn host(&self) -> Option<&HostBuffer> {
        match self {
            Storage::Host(h) => Some(h),
            #[cfg(feature = "cuda")]
            Storage::Cuda(_) => None,
        }
    }

    /// The CUDA memory, for arrays on a GPU.
    #[cfg(feature = "cuda")]
    pub(crate) fn cuda(&self) -> Option<&CudaBuffer> {
        match self {
            Storage::Cuda(b) => Some(b),
            Storage::Host(_) => None,
        }
    }

    /// See [`Buffer::len`].
    pub(crate) fn len(&self) -> usize {
        with_buffer!(self, b => b.len())
    }

    /// See [`Buffer::address`].
    pub(crate) fn address(&self) -> u64 {
        with_buffer!(self, b => b.address())
    }

    /// See [`Buffer::read`].
    pub(crate) fn read(&self, offset: usize, out: &mut [u8]) -> Result<()> {
        with_buffer!(self, b => b.read(offset, out))
    }

    /// See [`Buffer::write`].
    pub(crate) fn write(&self, offset: usize, data: &[u8]) -> Result<()> {
        with_buffer!(self, b => b.write(offset, data))
    }

    /// See [`Buffer::fill`].
    pub(crate) fn fill(&self, offset: usize, bytes: usize, pattern: &[u8]) -> Result<()> {
        with_buffer!(self, b => b.fill(offset, bytes, pattern))
    }

    /// Copies `bytes` bytes from `src` (another storage, of any backend) at `src_offset` to
    /// `offset`.
    pub(crate) fn copy_from(
        &self,
        offset: usize,
        src: &Storage,
        src_offset: usize,
        bytes: usize,
    ) -> Result<()> {
        match (self, src) {
            (Storage::Host(d), Storage::Host(s)) => d.copy_from(offset, s, src_offset, bytes),
            #[cfg(feature = "cuda")]
            (Storage::Cuda(d), Storage::Cuda(s)) => d.copy_from(offset, s, src_offset, bytes),
            // Between a device and the host: the device's own copy from or to the host bytes.
            // SAFETY (both): during a host-side operation no kernel runs on host memory, and
            // the caller's array operation is the only one on these bytes (`Array`'s contract).
            #[cfg(feature = "cuda")]
            (Storage::Host(d), Storage::Cuda(s)) => {
                s.read(src_offset, unsafe { d.bytes_mut(offset, bytes) })
            }
            #[cfg(feature = "cuda")]
            (Storage::Cuda(d), Storage::Host(s)) => {
                d.write(offset, unsafe { s.bytes(src_offset, bytes) })
            }
        }
    }
}

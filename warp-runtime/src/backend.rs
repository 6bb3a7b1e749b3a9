//! What a backend implements: the seam between the device-neutral runtime (launch validation,
//! arrays, tapes) and the code that runs kernels and holds memory on one kind of device.
//!
//! A backend is a folder (`cpu/`, `cuda/`) with a type implementing [`Backend`] and a memory
//! type implementing [`Buffer`]. `dispatch.rs` is the one place that names every backend: it
//! picks the backend of a device, and its `Storage` holds any backend's memory. The runtime
//! above calls `dispatch`, never a backend directly.
//!
//! The methods are generic over the kernel, and dispatch is a `match` on the device kind, so a
//! launch is monomorphised down to the backend's own code: no `dyn`, no allocation.
//!
//! # Capture
//! Graph capture (`graph.rs`) goes through the seam too. A backend says what recording means
//! ([`Backend::begin_capture`] to [`Backend::end_capture`], and [`Backend::record`] for each
//! operation its thread enqueues meanwhile): the CPU keeps each operation as an [`Op`] to run
//! at every replay; a GPU has the operation queue its work on the capture stream as usual. So
//! every operation that a backend enqueues without a host read-back (launches, adjoint
//! launches, fills and copies, the primitives, host objects' build steps) can be recorded;
//! `capturing.rs` keeps the rules that are the same on every backend (one device per capture,
//! what the graph keeps alive, what is refused).

use crate::error::Result;
use crate::kernel::{ArgsOf, Kernel, KernelInfo};
use crate::primitives::elements::{Extent, ScanOps, SortKeyOps, SortValueOps};
use crate::primitives::plan::ReduceOp;
use warp_core::{Grid, LaunchId};

/// The tape layer's answer to "will the launch being compiled need its adjoint?": when a tape
/// records on the calling thread, the adjoint stack its backward will run with. The tape
/// registers it ([`set_recording_query`]) the first time one records, so that a backend below
/// it can ask (`recording_adstack_bytes`) without importing it; before that nothing records.
static RECORDING_QUERY: std::sync::OnceLock<fn() -> Option<usize>> = std::sync::OnceLock::new();

/// Registers the tape layer's query (see [`RECORDING_QUERY`]); later calls change nothing.
pub(crate) fn set_recording_query(query: fn() -> Option<usize>) {
    let _ = RECORDING_QUERY.set(query);
}

/// When a tape records on the calling thread, the adjoint stack its backward will run with: a
/// backend compiling a kernel for a launch then compiles its adjoint along (the CUDA backend's
/// one unit of both). `None` when nothing records.
#[cfg(feature = "cuda")]
pub(crate) fn recording_adstack_bytes() -> Option<usize> {
    RECORDING_QUERY.get().and_then(|query| query())
}

/// One operation recorded into a CPU graph, run again at each replay (it owns what it uses).
pub(crate) type Op = Box<dyn Fn() -> Result<()> + Send>;

/// What becomes of an operation enqueued while the calling thread captures
/// ([`Backend::record`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Record {
    /// The backend recorded the operation (the CPU): it runs at each replay, not now.
    Recorded,
    /// The caller runs it now, and the backend queues its work into the capture (a GPU: on
    /// the capture stream, where nothing runs until a replay).
    Enqueue,
}

/// A conditional of a capture (`capture_if`, `capture_while`), decided when the graph runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Conditional {
    /// The first body when the flag is non-zero, else the second.
    If,
    /// The body while the flag is non-zero, read before each iteration.
    While,
}

/// A backend, bound to one device for one operation (the value is a handle: the device and
/// what the backend needs to find its state, built by `dispatch` for each call).
pub(crate) trait Backend {
    /// The memory of arrays on this backend's devices.
    type Buffer: Buffer;

    /// What a finished capture replays (`graph.rs`'s `Graph` holds it).
    type Graph: Send;

    /// Runs a launch of `K` over `grid` (the CPU), or queues it (a GPU: on the calling
    /// thread's current stream). The launch dims and shapes are already checked; the backend
    /// converts the arguments, which checks their devices. (Launches on a named stream,
    /// `launch_on`, are the CUDA backend's own: streams are a CUDA API.) `launch` is the
    /// launch's number: a fault the backend reports later names it (the CPU's faults come
    /// back from the launch itself, and `dispatch` names the launch in them).
    fn launch<K: Kernel>(&self, args: &ArgsOf<'_, K>, grid: &Grid, launch: LaunchId) -> Result<()>;

    /// Runs (or queues) the adjoint of a launch of `K`, accumulating into the arrays'
    /// gradients, with `adstack_bytes` of adjoint stack per thread. `K` has an adjoint
    /// (`KernelInfo::adjoint_error` is checked before).
    fn launch_adjoint<K: Kernel>(
        &self,
        args: &ArgsOf<'_, K>,
        grid: &Grid,
        adstack_bytes: usize,
        launch: LaunchId,
    ) -> Result<()>;

    /// `bytes` of zeroed memory aligned to at least `align`.
    fn alloc_zeroed(&self, bytes: usize, align: usize) -> Result<Self::Buffer>;

    /// Waits for the work queued on the device, then reports a fault that a kernel recorded
    /// there since the last check (what `to_vec` does before reading).
    fn synchronize(&self) -> Result<()>;

    /// The parallel primitives (`primitives/`). `func` is the public function (for messages
    /// and fault reports); arrays are addresses as [`Buffer::address`] gives them (plus the
    /// array's offset): `primitives` has checked that they are contiguous, on this device,
    /// long enough for `len`'s capacity, and that the outputs overlap nothing else (`output`
    /// may be `input`: a scan in place). A device count's value is the backend's to check.
    /// Runs (the CPU) or queues (a GPU, on the calling thread's current stream). Nothing is
    /// read back, so a primitive can be recorded; on a GPU inside a capture, its module must
    /// be loaded and its scratch memory large enough already (the same call made once
    /// before: nothing is allocated or compiled inside a capture).
    fn scan<T: ScanOps>(
        &self,
        func: &'static str,
        input: u64,
        output: u64,
        len: Extent,
        inclusive: bool,
    ) -> Result<()>;

    /// The reduction `op` of `input`'s first `len` elements into the element at `out`.
    fn reduce<T: ScanOps>(
        &self,
        func: &'static str,
        input: u64,
        out: u64,
        len: Extent,
        op: ReduceOp,
    ) -> Result<()>;

    /// Stable sort of the first `len` pairs by the low `key_bits` bits of the keys' images
    /// (`SortKeyOps::to_radix`).
    fn radix_sort_pairs<K: SortKeyOps, V: SortValueOps>(
        &self,
        func: &'static str,
        keys: u64,
        values: u64,
        len: Extent,
        key_bits: u32,
    ) -> Result<()>;

    /// Stream compaction of `T`s: `arrays` are values, flags (`i32`), out, out_count (`i32`).
    fn compact<T: bytemuck::Pod + Send + Sync>(
        &self,
        func: &'static str,
        arrays: [u64; 4],
        len: Extent,
    ) -> Result<()>;

    /// Makes `kernels` ready to launch before their first launch: a backend that compiles at
    /// run time compiles and loads them now, each
    /// kernel's variant for contiguous arrays and, with `adjoint: Some(bytes)`, its adjoint
    /// with `bytes` of stack per thread; with `block_dim: Some(n)` (tiled kernels) the variants
    /// for blocks of `n` threads. The CPU's kernels are compiled by cargo: nothing.
    fn prepare(
        &self,
        kernels: &[&'static KernelInfo],
        adjoint: Option<usize>,
        block_dim: Option<usize>,
    ) -> Result<()>;

    /// Runs (the CPU: [`ObjectStep::run_cpu`]) or queues (a GPU: the step's kernel, on the
    /// calling thread's current stream) one step of a host object's build. On a GPU inside a
    /// capture, the step's build library must be loaded already (a step run once before).
    fn object_step<S: ObjectStep>(&self, step: &S) -> Result<()>;

    /// [`Backend::synchronize`] for every device of this backend used so far.
    fn synchronize_all() -> Result<()>
    where
        Self: Sized;

    /// Starts capturing the calling thread's work on this device (`capturing.rs` has checked
    /// that the thread is not capturing already). Until [`Backend::end_capture`] or
    /// [`Backend::abort_capture`], each operation the thread enqueues here is first offered to
    /// [`Backend::record`]. (A capture on a given CUDA stream is the CUDA backend's own.)
    fn begin_capture(&self) -> Result<()>;

    /// Ends the calling thread's capture on this device and returns what it recorded.
    fn end_capture(&self) -> Result<Self::Graph>;

    /// Ends the calling thread's capture on this device and drops what it recorded.
    fn abort_capture(&self);

    /// An operation enqueued on this device while the calling thread captures (its device
    /// checked, what it uses kept by the caller): the backend records `op()`, which does the
    /// operation again at each replay (the CPU), or says to run it now, its work going into
    /// the capture (a GPU).
    fn record(&self, op: impl FnOnce() -> Op) -> Record;

    /// A conditional inside the calling thread's capture on the `i32` flag at `cond` (an
    /// address on this device, kept alive by the caller for the graph's replays): `then`
    /// (and `otherwise`, for `If`) are called once each to record their bodies, and the flag
    /// is read when the graph runs.
    fn capture_conditional(
        &self,
        kind: Conditional,
        cond: u64,
        then: &mut dyn FnMut() -> Result<()>,
        otherwise: Option<&mut dyn FnMut() -> Result<()>>,
    ) -> Result<()>;

    /// Replays `graph` (captured on this device): runs it (the CPU) or queues it on the
    /// calling thread's current stream (a GPU).
    fn replay(&self, graph: &Self::Graph) -> Result<()>;
}

/// A data-parallel step of a host object's build (the hash grid's keys and ranges): a record
/// of arguments, run over `0..len()` by a Rust function on the CPU and by a kernel of the
/// object's CUDA build library on a GPU. Objects define their steps next to themselves
/// (`objects/`); a backend only knows how to run one, so a new object adds no backend method.
///
/// # Safety
/// `Self` is `#[repr(C)]` and laid out exactly as the C++ struct that [`ObjectStep::KERNEL`]
/// takes by value (both sides assert the size); the device addresses it holds are of live
/// memory on the step's device, sized for what the step reads and writes (the object checked
/// them).
pub(crate) unsafe trait ObjectStep: Copy + Send + Sync {
    /// The CUDA build library holding the kernel.
    // Read only by the CUDA backend: a build without `cuda` runs steps on the CPU alone.
    #[cfg_attr(not(feature = "cuda"), allow(dead_code))]
    const LIBRARY: &'static ObjectLibrary;
    /// The kernel: `extern "C" __global__ void KERNEL(Record r)`, a grid-stride loop over
    /// `0..len()`.
    #[cfg_attr(not(feature = "cuda"), allow(dead_code))]
    const KERNEL: &'static str;
    /// Elements (threads) of the step.
    fn len(&self) -> usize;
    /// The step on the CPU (rayon), on host memory.
    fn run_cpu(&self) -> Result<()>;
    /// The fault context in the record of a step whose kernel raises faults (`None`, the
    /// default: the step raises none). The GPU backend fills it before queuing the step (the
    /// calling thread's fault record, or the capture's; a kernel id for its names; the
    /// step's launch number), so that a fault the step raises is reported at the next
    /// synchronisation, or a graph replay's, like a kernel's. On the CPU, `run_cpu` returns
    /// the fault itself.
    #[cfg_attr(not(feature = "cuda"), allow(dead_code))]
    fn fault_slot(&mut self) -> Option<&mut StepFault> {
        None
    }
}

/// The fault context of a build step whose kernel raises faults (`wp::step_fault_t`: a
/// `wp::launch_ctx_t`, then the names), part of the step's record.
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct StepFault {
    /// The `wp::launch_ctx_t` the step's threads raise with: fault record and flag
    /// addresses, `reserved` (0), the kernel id of `names`, the launch number (the GPU
    /// backend's to fill; zeros on the CPU).
    pub(crate) ctx: [u64; 4],
    /// What the step's faults are named by: the operation (`Bvh::refit`) as the kernel and
    /// its arguments by index (the kernel never reads it).
    pub(crate) names: &'static KernelInfo,
}

const _: () = assert!(std::mem::size_of::<StepFault>() == 40);

impl StepFault {
    /// A context naming faults by `names`, to be filled by the GPU backend.
    pub(crate) const fn new(names: &'static KernelInfo) -> StepFault {
        StepFault { ctx: [0; 4], names }
    }

    /// Fills the context: the fault record at `fault`, its flag at `flag`, the kernel id
    /// `kernel` (of `names`), the launch number `launch`.
    // Called by the CUDA backend alone.
    #[cfg_attr(not(feature = "cuda"), allow(dead_code))]
    pub(crate) fn fill(&mut self, fault: u64, flag: u64, kernel: i32, launch: u64) {
        // launch_ctx_t: 0 fault, 8 fault_flag, 16 reserved (i16, 0), 18 flags (i16, 0),
        // 20 kernel (i32), 24 launch.
        self.ctx = [fault, flag, ((kernel as u32 as u64) << 32), launch];
    }
}

impl std::fmt::Debug for StepFault {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StepFault")
            .field("ctx", &self.ctx)
            .field("names", &self.names.name)
            .finish()
    }
}

/// A host object's CUDA build library: a section of the CUDA library whose header, with its
/// build kernels enabled, holds the kernels of the object's steps. The facts (header, define,
/// program name) are the section's row in `warp_cuda::library::SECTIONS`; this names the row.
/// Compiled by NVRTC through the kernel disk cache the first time a GPU runs one of its steps,
/// and kept loaded for the process.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ObjectLibrary {
    section: &'static str,
}

impl ObjectLibrary {
    /// The build library of `section`. With the `cuda` feature, a section that is no row of
    /// the library or has no build library fails the build where this is evaluated as a
    /// constant (the objects' `LIBRARY` statics are).
    pub(crate) const fn of(section: &'static str) -> Self {
        #[cfg(feature = "cuda")]
        assert!(
            warp_cuda::library::get(section).build.is_some(),
            "the section has no build library"
        );
        ObjectLibrary { section }
    }

    /// The library section's name (`"hash_grid"`; its header is `wp_hash_grid.h`).
    pub fn section(&self) -> &'static str {
        self.section
    }
}
/// A backend's memory, as array operations use it: bytes at offsets. Every operation is
/// ordered after the kernels that may use the memory (on a GPU: after every stream's work;
/// see `cuda/gpu.rs`) and has finished when it returns.
pub(crate) trait Buffer: Send + Sync + Sized {
    /// The size in bytes.
    fn len(&self) -> usize;
    /// The address of byte 0 as this backend's kernels receive it.
    fn address(&self) -> u64;
    /// Copies `out.len()` bytes from `offset` into `out`.
    fn read(&self, offset: usize, out: &mut [u8]) -> Result<()>;
    /// Copies `data` to `offset`.
    fn write(&self, offset: usize, data: &[u8]) -> Result<()>;
    /// Writes `pattern` over `bytes` bytes from `offset` (`bytes` is a multiple of its length).
    fn fill(&self, offset: usize, bytes: usize, pattern: &[u8]) -> Result<()>;
    /// Copies `bytes` bytes from `src` at `src_offset` to `offset` (callers pass another
    /// buffer than `self`).
    fn copy_from(&self, offset: usize, src: &Self, src_offset: usize, bytes: usize) -> Result<()>;
}

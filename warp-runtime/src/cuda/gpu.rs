//! Per-GPU state: the opened GPU and the stream ordering model (fault records: `fault.rs`,
//! which imports nothing from here).
//!
//! # The ordering model
//! Array operations (allocation, copies, fills, frees) and launches without a stream run on
//! the GPU's default stream, which first waits for every user stream that has had work since
//! it last did (`join_ordinal`); a launch on a user stream (named, or the calling thread's
//! current one, set by a `ScopedStream`) first waits for the default stream. So array memory
//! is never freed or rewritten under a kernel still using it, and kernels on different user
//! streams may overlap.
//!
//! A launch queues its waits and itself as one step (`GpuState::queue` holds a per-GPU lock
//! across them), so work on the default stream runs after or before every user stream's work
//! queued by any thread, never beside it. An adjoint launch there adds the gradients of its
//! thread-owned elements without atomics (`GpuState::alone`).
//!
//! # Faults
//! Kernel threads record faults (out-of-bounds index, integer division by zero, bad step,
//! adjoint stack overflow) in their launching thread's record (`fault.rs`); a thread reads its
//! record after each launch in debug mode, and otherwise at its next synchronisation
//! (`synchronize`, `to_vec`).

use super::fault::{self, RecordPool};
use crate::device::Device;
use crate::error::{Error, Result};
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};
use warp_cuda::{CudaError, DeviceBuffer, Gpu};

/// A CUDA error on `device` as a runtime error.
pub(crate) fn err(device: &Device, e: CudaError) -> Error {
    Error::cuda(device.alias(), e)
}

/// The opened GPU `ordinal`.
pub(crate) fn gpu(ordinal: usize) -> Result<Arc<Gpu>> {
    Gpu::open(ordinal).map_err(|e| Error::cuda(format!("cuda:{ordinal}"), e))
}

thread_local! {
    /// The calling thread's current streams, innermost last: `(GPU ordinal, stream)`.
    static CURRENT: RefCell<Vec<(usize, warp_cuda::Stream)>> = const { RefCell::new(Vec::new()) };
    /// The stream this thread is capturing into a graph, with its GPU (`cuda/capture.rs`).
    static CAPTURING: RefCell<Option<(usize, warp_cuda::Stream)>> = const { RefCell::new(None) };
}

/// The stream the calling thread is capturing on GPU `ordinal`, if it is: every operation of
/// this thread on that GPU (launches, fills, copies) is queued there, and nothing else.
pub(crate) fn capture_stream(ordinal: usize) -> Option<warp_cuda::Stream> {
    CAPTURING.with(|c| match &*c.borrow() {
        Some((o, s)) if *o == ordinal => Some(s.clone()),
        _ => None,
    })
}

/// Sets (or clears) the calling thread's capture stream.
pub(crate) fn set_capture_stream(capture: Option<(usize, warp_cuda::Stream)>) {
    CAPTURING.with(|c| *c.borrow_mut() = capture);
}

/// An [`Error::Capture`] for `what` when the calling thread is capturing on GPU `ordinal`:
/// what cannot be recorded into a graph (a read-back, an upload, an allocation) is refused
/// rather than run at capture time or left to break the capture.
pub(crate) fn refuse_in_capture(ordinal: usize, what: &str) -> Result<()> {
    if capture_stream(ordinal).is_some() {
        return Err(Error::Capture {
            what: format!(
                "{what} on cuda:{ordinal} cannot be recorded into a graph (do it before or \
                 after the capture)"
            ),
        });
    }
    Ok(())
}

/// The calling thread's current stream for GPU `ordinal`, when a `ScopedStream` set one.
pub(crate) fn current(ordinal: usize) -> Option<warp_cuda::Stream> {
    CURRENT.with(|c| {
        let c = c.borrow();
        if c.is_empty() {
            return None;
        }
        c.iter()
            .rev()
            .find(|(o, _)| *o == ordinal)
            .map(|(_, s)| s.clone())
    })
}

/// Makes `stream` the calling thread's current stream for GPU `ordinal` (innermost).
pub(crate) fn push_current(ordinal: usize, stream: warp_cuda::Stream) {
    CURRENT.with(|c| c.borrow_mut().push((ordinal, stream)));
}

/// Undoes the innermost [`push_current`] of `stream` on GPU `ordinal`.
pub(crate) fn pop_current(ordinal: usize, stream: &warp_cuda::Stream) {
    CURRENT.with(|c| {
        let mut c = c.borrow_mut();
        if let Some(k) = c.iter().rposition(|(o, s)| *o == ordinal && s.is(stream)) {
            c.remove(k);
        }
    });
}

/// Per-GPU state: the user streams with work queued since the default stream last waited for
/// them, the fault records, and the primitives' workspace.
///
/// The ordering model is the module's (`pending` holds the user streams the default stream
/// has yet to wait for).
pub(crate) struct GpuState {
    device: Device,
    ordinal: usize,
    pub(crate) gpu: Arc<Gpu>,
    /// The GPU's fault records (`fault.rs`).
    pub(crate) faults: Arc<RecordPool>,
    /// Each with the number of the mark that made it pending last (`marks`).
    pending: Mutex<Vec<(warp_cuda::Stream, u64)>>,
    has_pending: AtomicBool,
    /// Marks of pending streams so far: a synchronisation forgets only the streams marked
    /// before it began (`check_state`).
    marks: AtomicU64,
    /// Held while work is queued outside a capture: its waits and the work are one step (see
    /// the module's ordering model).
    order: Mutex<()>,
    /// The primitives' scratch memory (`cuda/primitives.rs`), kept between calls: the
    /// largest needed so far.
    pub(crate) workspace: Mutex<Option<Arc<Scratch>>>,
    /// The record slots of deterministic launches (`cuda/deterministic.rs`), kept between
    /// launches: the largest needed so far, ordered like the workspace.
    pub(crate) det_records: Mutex<Option<Arc<Scratch>>>,
}

/// Scratch memory the primitives reuse from call to call (the GPU's workspace), with the
/// stream of its last use. A use first waits for the last user's stream when it is another
/// one, and becomes the last user: uses of the scratch are ordered like those of an array.
/// A graph that recorded primitives holds the scratch they use and orders each replay the same
/// way (`capture.rs`), so the workspace growing later frees nothing a graph still uses.
pub(crate) struct Scratch {
    pub(crate) buffer: DeviceBuffer,
    last: Mutex<Option<warp_cuda::Stream>>,
}

impl Scratch {
    /// Scratch memory of `buffer`, not used yet.
    pub(crate) fn new(buffer: DeviceBuffer) -> Arc<Scratch> {
        Arc::new(Scratch {
            buffer,
            last: Mutex::new(None),
        })
    }

    /// The stream of the last use, locked: hold it while queueing a use, which then sets it
    /// ([`order_scratch`]).
    pub(crate) fn last(&self) -> MutexGuard<'_, Option<warp_cuda::Stream>> {
        self.last.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// Orders a use of scratch memory on `stream` after its last use (`last`, locked) and makes
/// `stream` the last user.
pub(crate) fn order_scratch(
    device: &Device,
    last: &mut Option<warp_cuda::Stream>,
    stream: &warp_cuda::Stream,
) -> Result<()> {
    if let Some(l) = last.as_ref().filter(|l| !l.is(stream)) {
        stream.wait_stream(l).map_err(|e| err(device, e))?;
    }
    *last = Some(stream.clone());
    Ok(())
}

impl Drop for Scratch {
    fn drop(&mut self) {
        // The free is queued on the default stream: after every user stream's work (a replay
        // of the last graph that held it, say). A failure means a broken context, which the
        // next fallible call reports.
        let _ = join_ordinal(self.buffer.gpu().ordinal());
    }
}

impl GpuState {
    /// Makes the default stream wait for the user streams with work queued since it last did.
    pub(crate) fn join_pending(&self) -> Result<()> {
        if !self.has_pending.load(Ordering::Acquire) {
            return Ok(());
        }
        let mut pending = self.pending.lock().unwrap_or_else(|p| p.into_inner());
        let default = self.gpu.default_stream();
        // A stream leaves the list once the wait for it is queued: one that failed stays.
        while let Some((s, _)) = pending.last() {
            default.wait_stream(s).map_err(|e| err(&self.device, e))?;
            pending.pop();
        }
        self.has_pending.store(false, Ordering::Release);
        Ok(())
    }

    /// Queues work (`enqueue`) on `stream` when given, else on the calling thread's current
    /// stream for this GPU (`ScopedStream`), else on the default stream, in the module's
    /// ordering model: a user stream first waits for the default stream and is then pending;
    /// the default stream first joins the pending streams.
    pub(crate) fn queue(
        &self,
        ordinal: usize,
        stream: Option<&warp_cuda::Stream>,
        enqueue: impl FnOnce(&warp_cuda::Stream) -> Result<()>,
    ) -> Result<()> {
        self.queue_with(ordinal, stream, true, enqueue)
    }

    /// [`queue`](Self::queue) without the order lock, for work whose queueing may wait for
    /// other threads or processes (an NCCL call waits for its communicator's call lock, up to
    /// a timeout, and inside a group holds it until the group ends): under the lock every
    /// launch on the GPU would wait too, and another thread's group could not finish. Such
    /// work is still ordered against the default stream as `queue` orders it, except that an
    /// adjoint launch the lock calls alone may run beside it: no gradient's additions are
    /// lost by that, since what it writes (an NCCL result) races with any concurrent access
    /// to the same memory, atomic adds included.
    pub(crate) fn queue_unordered(
        &self,
        ordinal: usize,
        stream: Option<&warp_cuda::Stream>,
        enqueue: impl FnOnce(&warp_cuda::Stream) -> Result<()>,
    ) -> Result<()> {
        self.queue_with(ordinal, stream, false, enqueue)
    }

    fn queue_with(
        &self,
        ordinal: usize,
        stream: Option<&warp_cuda::Stream>,
        ordered: bool,
        enqueue: impl FnOnce(&warp_cuda::Stream) -> Result<()>,
    ) -> Result<()> {
        if let Some(capture) = capture_stream(ordinal) {
            // A capture records this thread's work on its own stream, with no joins: the
            // graph is ordered against the default stream when it is launched.
            if stream.is_some_and(|s| !s.is(&capture)) {
                return Err(Error::Capture {
                    what: format!(
                        "work queued on another stream of cuda:{ordinal} than the capturing \
                         one (launch_on a stream inside a capture records nothing)"
                    ),
                });
            }
            return enqueue(&capture);
        }
        let scoped;
        let user = match stream {
            Some(s) => Some(s),
            None => {
                scoped = current(ordinal);
                scoped.as_ref()
            }
        };
        if let Some(s) = user.filter(|s| s.is_caller_ordered()) {
            // The caller orders it (`Stream::from_raw_caller_ordered`): no join either way,
            // so nothing here touches another stream, and a capture of it by its owner
            // (torch's, XLA's) holds just this work.
            return enqueue(s);
        }
        let _order = ordered.then(|| self.order.lock().unwrap_or_else(|p| p.into_inner()));
        let default = self.gpu.default_stream();
        match user.filter(|s| !s.is(default)) {
            Some(s) => {
                // A capture its owner began (torch's, XLA's): the join below would tie the
                // captured graph to the default stream's uncaptured work and, once marked
                // pending, the default stream to captured work, which CUDA refuses or breaks
                // the capture with. Refused here, with the mode that is allowed.
                if s.is_capturing().map_err(|e| err(&self.device, e))? {
                    return Err(Error::Capture {
                        what: format!(
                            "work queued on a stream of cuda:{ordinal} that another library is \
                             capturing into a CUDA graph (this crate's streams join its default \
                             stream; wrap the stream with Stream::from_raw_caller_ordered for \
                             work that uses only the caller's memory)"
                        ),
                    });
                }
                // Arrays are allocated and written on the default stream.
                s.wait_stream(default).map_err(|e| err(&self.device, e))?;
                // Pending even when `enqueue` failed: it may have queued part of its work.
                let queued = enqueue(s);
                self.mark_pending(s);
                queued
            }
            None => {
                self.join_pending()?;
                enqueue(default)
            }
        }
    }

    /// Whether work that [`queue`](Self::queue) hands `on` runs alone on the GPU: on the default
    /// stream outside a capture, where the queue's lock orders it after every user stream's
    /// work queued before and before every user stream's work queued after. (Inside a capture
    /// nothing runs until the graph is launched, on any stream: never alone.)
    pub(crate) fn alone(&self, on: &warp_cuda::Stream) -> bool {
        on.is(self.gpu.default_stream()) && capture_stream(self.ordinal).is_none()
    }

    /// Records that `stream` (a user stream) has work the default stream must wait for.
    fn mark_pending(&self, stream: &warp_cuda::Stream) {
        let mut pending = self.pending.lock().unwrap_or_else(|p| p.into_inner());
        let mark = self.marks.fetch_add(1, Ordering::SeqCst) + 1;
        match pending.iter_mut().find(|(s, _)| s.is(stream)) {
            Some(entry) => entry.1 = mark,
            None => pending.push((stream.clone(), mark)),
        }
        self.has_pending.store(true, Ordering::Release);
    }
}

/// Makes the default stream of GPU `ordinal` wait for the user streams with work queued since
/// it last did: what every array operation there does first. Nothing to do for a GPU never
/// used.
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

/// The state of GPU `ordinal` (`device`), made at its first use.
pub(crate) fn state(device: &Device, ordinal: usize) -> Result<Arc<GpuState>> {
    let mut map = states_map().lock().unwrap_or_else(|p| p.into_inner());
    if let Some(s) = map.get(&ordinal) {
        return Ok(s.clone());
    }
    let gpu = gpu(ordinal)?;
    let s = Arc::new(GpuState {
        device: device.clone(),
        ordinal,
        faults: RecordPool::new(gpu.clone(), device.clone()),
        gpu,
        pending: Mutex::new(Vec::new()),
        has_pending: AtomicBool::new(false),
        marks: AtomicU64::new(0),
        order: Mutex::new(()),
        workspace: Mutex::new(None),
        det_records: Mutex::new(None),
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

/// Waits for GPU `ordinal` (`device`) and reports a fault recorded since the last check.
pub(crate) fn synchronize(device: &Device, ordinal: usize) -> Result<()> {
    refuse_in_capture(ordinal, "a synchronisation")?;
    check_state(&*state(device, ordinal)?)
}

/// Waits for every stream of the GPU, then reports a fault that a launch of the calling
/// thread (or a graph it replayed) recorded since its last check.
pub(crate) fn check_state(st: &GpuState) -> Result<()> {
    // A stream marked pending before the synchronisation began had its work queued before it
    // (`queue` marks after queueing), so the synchronisation waits for that work; one marked
    // since, by another thread, may have work still running and stays pending.
    let before = st.marks.load(Ordering::SeqCst);
    st.gpu.synchronize().map_err(|e| err(&st.device, e))?;
    let mut pending = st.pending.lock().unwrap_or_else(|p| p.into_inner());
    pending.retain(|(_, mark)| *mark > before);
    st.has_pending.store(!pending.is_empty(), Ordering::Release);
    drop(pending);
    fault::check(&st.faults, st.ordinal, true)
}

/// Reports (and clears) a fault that a launch of the calling thread recorded, without waiting
/// for the GPU's other work (the read waits for the default stream only).
pub(crate) fn read_fault(st: &GpuState) -> Result<()> {
    fault::check(&st.faults, st.ordinal, false)
}

/// Waits for every GPU used so far and reports the first recorded fault.
pub(crate) fn synchronize_all() -> Result<()> {
    if let Some((ordinal, _)) = CAPTURING.with(|c| c.borrow().clone()) {
        refuse_in_capture(ordinal, "a synchronisation")?;
    }
    for st in states() {
        check_state(&st)?;
    }
    Ok(())
}

//! Per-GPU state: the opened GPU, the stream ordering model, and the fault record that
//! kernels fill and synchronisations read.
//!
//! # The ordering model
//! Array operations (allocation, copies, fills, frees) and launches without a stream run on
//! the GPU's default stream, which first waits for every user stream that has had work since
//! it last did (`join_ordinal`); a launch on a user stream (named, or the calling thread's
//! current one, set by a `ScopedStream`) first waits for the default stream. So array memory
//! is never freed or rewritten under a kernel still using it, and kernels on different user
//! streams may overlap.
//!
//! # Faults
//! Threads record faults (out-of-bounds index, integer division by zero, bad step, adjoint
//! stack overflow) in a per-GPU record; it is read after each launch in debug mode, and
//! otherwise at the next synchronisation (`synchronize`, `to_vec`).

use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::KernelInfo;
use std::cell::RefCell;
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use warp_core::{Fault, FaultKind};
use warp_cuda::{CudaError, DeviceBuffer, Gpu};

/// A CUDA error on `device` as a runtime error.
pub(crate) fn err(device: &Device, e: CudaError) -> Error {
    Error::cuda(device.alias(), e)
}

/// The opened GPU `ordinal`.
pub(crate) fn gpu(ordinal: usize) -> Result<Arc<Gpu>> {
    Gpu::open(ordinal).map_err(|e| Error::cuda(format!("cuda:{ordinal}"), e))
}

/// `wp::fault_t` (80 bytes) followed by the `u32` flag the first faulting thread sets.
pub(crate) const FAULT_RECORD_BYTES: usize = 80;
const FAULT_BYTES: usize = FAULT_RECORD_BYTES + 8;

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

/// Gives `info` a kernel id for fault records (`wp::ctx_t::kernel`): ids start at 1, and 0
/// means "not set". A kernel loaded several times (variants, GPUs) has several ids.
pub(crate) fn kernel_id(info: &'static KernelInfo) -> i32 {
    let mut ids = kernel_ids().lock().unwrap_or_else(|p| p.into_inner());
    ids.push(info);
    i32::try_from(ids.len()).unwrap_or(0)
}

fn kernel_ids() -> &'static Mutex<Vec<&'static KernelInfo>> {
    static IDS: OnceLock<Mutex<Vec<&'static KernelInfo>>> = OnceLock::new();
    IDS.get_or_init(Default::default)
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

/// Per-GPU state: the fault record, the last kernel launched (named in fault reports), and
/// the user streams with work queued since the default stream last waited for them.
///
/// The ordering model is the module's (`pending` holds the user streams the default stream
/// has yet to wait for).
pub(crate) struct GpuState {
    device: Device,
    pub(crate) gpu: Arc<Gpu>,
    fault: DeviceBuffer,
    /// The kernel launched last (what a fault report names).
    last: Mutex<Option<&'static KernelInfo>>,
    pending: Mutex<Vec<warp_cuda::Stream>>,
    has_pending: AtomicBool,
    /// The primitives' scratch memory (`cuda/primitives.rs`), kept between calls.
    pub(crate) workspace: Mutex<Workspace>,
}

/// Scratch memory the primitives reuse from call to call: one buffer per GPU that grows to
/// the largest need seen, and the stream of its last use. A primitive holds the lock while it
/// queues its launches; a launch on another stream than the last user's first waits for that
/// stream, so uses of the workspace are ordered like those of an array.
#[derive(Default)]
pub(crate) struct Workspace {
    pub(crate) buffer: Option<DeviceBuffer>,
    pub(crate) last: Option<warp_cuda::Stream>,
}

impl GpuState {
    /// Makes the default stream wait for the user streams with work queued since it last did.
    pub(crate) fn join_pending(&self) -> Result<()> {
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
    /// stream for this GPU (`ScopedStream`), else on the default stream, in the module's
    /// ordering model: a user stream first waits for the default stream and is then pending;
    /// the default stream first joins the pending streams.
    pub(crate) fn queue(
        &self,
        ordinal: usize,
        stream: Option<&warp_cuda::Stream>,
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
        let default = self.gpu.default_stream();
        let scoped;
        let user = match stream {
            Some(s) => Some(s),
            None => {
                scoped = current(ordinal);
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

    /// The device addresses of the fault record and of its flag, for a launch's `wp::ctx_t`.
    pub(crate) fn fault_record(&self) -> (u64, u64) {
        let base = self.fault.device_ptr();
        (base, base + FAULT_RECORD_BYTES as u64)
    }

    /// Records that `info` is the kernel launched last (the one a fault report will name).
    pub(crate) fn set_last(&self, info: &'static KernelInfo) {
        *self.last.lock().unwrap_or_else(|p| p.into_inner()) = Some(info);
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
    let g = gpu(ordinal)?;
    let fault = DeviceBuffer::zeros(&g, FAULT_BYTES).map_err(|e| err(device, e))?;
    let s = Arc::new(GpuState {
        device: device.clone(),
        gpu: g,
        fault,
        last: Mutex::new(None),
        pending: Mutex::new(Vec::new()),
        has_pending: AtomicBool::new(false),
        workspace: Mutex::new(Workspace::default()),
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

/// Waits for every stream of the GPU, then reports a fault recorded since the last check.
pub(crate) fn check_state(st: &GpuState) -> Result<()> {
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
    // The kernel id the faulting launch carried (`wp::ctx_t::kernel`), else the kernel
    // launched last (the primitives' kernels set no id).
    let by_id = usize::try_from(i32_at(76) - 1).ok().and_then(|k| {
        kernel_ids()
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(k)
            .copied()
    });
    let info = by_id.unwrap_or_else(|| {
        st.last
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .unwrap_or(&UNKNOWN)
    });
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
        // wp_core.h FAULT_NON_FINITE: the sample position's coordinates as f64 bit patterns.
        5 => FaultKind::NonFinite {
            what: "volume sample position",
            values: (0..ndim)
                .map(|k| f64::from_bits(i64_at(8 + 8 * k) as u64))
                .collect(),
        },
        _ => FaultKind::BadStep { step: i64_at(8) },
    };
    Err(Error::Fault(Fault {
        kernel: info.name,
        kind,
    }))
}

static UNKNOWN: KernelInfo = KernelInfo {
    name: "?",
    ..KernelInfo::BLANK
};

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

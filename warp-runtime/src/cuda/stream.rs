//! CUDA streams and events, as Warp exposes them: `Stream`, `Event`, `ScopedStream`,
//! `get_stream`, and launches on a given stream ([`launch_on`](crate::launch_on)).
//!
//! # Ordering
//! Each GPU has a default stream. Array operations (allocation, uploads, downloads, copies,
//! fills, frees) and launches that name no stream run there. A launch on another stream runs
//! after everything queued on the default stream before it; the default stream, before its
//! next operation, waits for the streams that have had launches since it last did. So:
//! - kernels on different user streams may run concurrently (order them with
//!   [`Stream::wait_stream`] and [`Stream::wait_event`] where they share data);
//! - an array is never freed, overwritten by a copy or fill, or read back while a kernel on any
//!   stream may still use it: no use-after-free on the GPU through safe code;
//! - `to_vec` and [`synchronize`](crate::synchronize) wait for every stream.
//!
//! Streams exist on CUDA devices only; CPU launches complete before `launch` returns.

use super::gpu;
use crate::device::{Device, DeviceKind};
use crate::error::{Error, Result};
use std::marker::PhantomData;
use std::sync::Arc;

/// The GPU ordinal of `device`, or an error naming what needed a GPU.
fn ordinal_of(device: &Device, what: &str) -> Result<usize> {
    match device.kind() {
        DeviceKind::Cuda { ordinal } => Ok(ordinal),
        DeviceKind::Cpu => Err(Error::invalid(format!(
            "{what} needs a CUDA device, got \"{device}\" (CPU launches complete before \
             `launch` returns; there is nothing to order)"
        ))),
    }
}

/// A CUDA stream: a queue of GPU work that runs in order. Cheap to clone (a shared handle);
/// the stream is destroyed when the last clone is dropped, after its queued work.
#[derive(Clone, Debug)]
pub struct Stream {
    device: Device,
    inner: warp_cuda::Stream,
}

impl Stream {
    /// Creates a new stream on `device` (a GPU).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for the CPU; [`Error::Cuda`] when the driver fails.
    pub fn new(device: &Device) -> Result<Stream> {
        let ordinal = ordinal_of(device, "a stream")?;
        let st = gpu::state(device, ordinal)?;
        let inner = st.gpu.new_stream().map_err(|e| gpu::err(device, e))?;
        Ok(Stream {
            device: device.clone(),
            inner,
        })
    }

    /// Wraps a CUDA stream that another library created (a `CUstream`, as PyTorch's
    /// `torch.cuda.current_stream().cuda_stream` or another CUDA crate gives it), so that
    /// [`launch_on`](crate::launch_on) and [`ScopedStream`] queue this crate's work on it.
    /// The stream is never destroyed here; `owner` (what keeps it alive, or `()`) is held by
    /// every clone of the wrapper and dropped with the last one.
    ///
    /// The ordering model of this module applies: array operations wait for the work this
    /// crate queued on the stream. Work the other library queues on it is ordered by the
    /// stream itself; work it queues elsewhere is the caller's to order. In particular a
    /// backward pass on the default stream counts as running alone (its thread-owned
    /// gradients are plain adds) against this crate's work only: another library's kernel
    /// that adds into a gradient array at the same time must be ordered by the caller.
    ///
    /// # Safety
    /// `cu_stream` must be a valid stream of `device`'s primary context (the runtime API's
    /// context: what PyTorch and CUDA runtime code use) and stay alive while `owner` lives
    /// (or forever, for an `owner` that does not destroy it).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for the CPU or a null stream (the legacy default stream is
    /// not wrapped: use [`get_stream`]); [`Error::Cuda`] when the device cannot start.
    pub unsafe fn from_raw(
        cu_stream: *mut std::ffi::c_void,
        device: &Device,
        owner: impl Send + Sync + 'static,
    ) -> Result<Stream> {
        let ordinal = ordinal_of(device, "Stream::from_raw")?;
        if cu_stream.is_null() {
            return Err(Error::invalid(
                "Stream::from_raw: cu_stream is null (the legacy default stream); use \
                 get_stream for the device's default stream",
            ));
        }
        let st = gpu::state(device, ordinal)?;
        // SAFETY: the caller's contract.
        let inner = unsafe { st.gpu.wrap_stream(cu_stream.cast(), Some(Arc::new(owner))) };
        Ok(Stream {
            device: device.clone(),
            inner,
        })
    }

    /// Wraps a CUDA stream that another library created and orders (a framework's stream an
    /// op runs on), as [`from_raw`](Self::from_raw), but ordered by its owner alone: launches
    /// on it neither wait for this crate's default stream nor make the default stream (and
    /// so array operations, `to_vec`, [`synchronize`](crate::synchronize)) wait for them.
    /// Such a launch is one `cuLaunchKernel` on the stream and nothing else, so it may run
    /// inside a CUDA graph capture of the stream that its owner began (PyTorch's, XLA's
    /// command buffers), where a [`from_raw`](Self::from_raw) stream's launch is refused.
    /// As a [`ScopedStream`] it keeps the mode for the launches in the scope.
    ///
    /// For work whose arrays are all the caller's (a framework's tensors): this crate's array
    /// operations still run on its default stream, unordered with this stream.
    ///
    /// # Safety
    /// As [`from_raw`](Self::from_raw) (`cu_stream` alive while the wrapper or a clone is
    /// used; it is never destroyed here); and every array a launch on it uses is ordered by the
    /// caller: no array this crate allocated, uploaded, copied or filled on its default stream
    /// is used on it unless that work has finished or the caller ordered it before (a
    /// [`wait_stream`](Self::wait_stream)), and no array is dropped, read back or written by
    /// this crate's default stream while work on this stream may still use it (synchronize
    /// this stream first).
    ///
    /// # Errors
    /// As [`from_raw`](Self::from_raw).
    pub unsafe fn from_raw_caller_ordered(
        cu_stream: *mut std::ffi::c_void,
        device: &Device,
    ) -> Result<Stream> {
        // SAFETY: the caller's contract (nothing is destroyed when the wrapper drops).
        let s = unsafe { Self::from_raw(cu_stream, device, ()) }.map_err(|e| match e {
            Error::InvalidArgument { what } => Error::InvalidArgument {
                what: what.replacen("Stream::from_raw", "Stream::from_raw_caller_ordered", 1),
            },
            e => e,
        })?;
        Ok(Stream {
            device: s.device,
            inner: s.inner.caller_ordered(),
        })
    }

    /// Whether the stream is ordered by its owner alone
    /// ([`from_raw_caller_ordered`](Self::from_raw_caller_ordered)).
    pub fn is_caller_ordered(&self) -> bool {
        self.inner.is_caller_ordered()
    }

    /// The device the stream belongs to.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Whether this is the device's default stream (where array operations run).
    pub fn is_default(&self) -> bool {
        gpu::state(&self.device, self.inner.ordinal())
            .map(|st| st.gpu.default_stream().is(&self.inner))
            .unwrap_or(false)
    }

    /// Waits until the work queued on this stream has finished, then reports a fault that a
    /// kernel on this GPU recorded (as [`Error::Fault`]).
    pub fn synchronize(&self) -> Result<()> {
        self.inner
            .synchronize()
            .map_err(|e| gpu::err(&self.device, e))?;
        let st = gpu::state(&self.device, self.inner.ordinal())?;
        gpu::read_fault(&st)
    }

    /// Makes work queued on this stream from now on wait for the work queued on `other` so
    /// far (any GPU). The host does not block.
    pub fn wait_stream(&self, other: &Stream) -> Result<()> {
        self.inner
            .wait_stream(&other.inner)
            .map_err(|e| gpu::err(&self.device, e))
    }

    /// Makes work queued on this stream from now on wait for the work `event` captured.
    pub fn wait_event(&self, event: &Event) -> Result<()> {
        self.inner
            .wait_event(&event.inner)
            .map_err(|e| gpu::err(&self.device, e))
    }

    /// Records a new timing event capturing the work queued on this stream so far.
    pub fn record_event(&self) -> Result<Event> {
        let event = Event::new(&self.device, true)?;
        event.record(self)?;
        Ok(event)
    }

    /// The underlying stream (for interop with other CUDA code).
    pub fn cuda_stream(&self) -> &warp_cuda::Stream {
        &self.inner
    }
}

/// The calling thread's current stream on `device`: the innermost [`ScopedStream`]'s, else the
/// device's default stream.
///
/// # Errors
/// [`Error::InvalidArgument`] for the CPU.
pub fn get_stream(device: &Device) -> Result<Stream> {
    let ordinal = ordinal_of(device, "get_stream")?;
    let inner = match gpu::current(ordinal) {
        Some(s) => s,
        None => gpu::state(device, ordinal)?.gpu.default_stream().clone(),
    };
    Ok(Stream {
        device: device.clone(),
        inner,
    })
}

/// A CUDA event: a marker in a stream's work, for ordering streams and timing.
#[derive(Clone, Debug)]
pub struct Event {
    device: Device,
    inner: Arc<warp_cuda::Event>,
}

impl Event {
    /// Creates an event on `device`; `timing` lets it measure elapsed time
    /// ([`Event::elapsed_ms`]), at a small cost per record.
    pub fn new(device: &Device, timing: bool) -> Result<Event> {
        let ordinal = ordinal_of(device, "an event")?;
        let inner = gpu::state(device, ordinal)?
            .gpu
            .new_event(timing)
            .map_err(|e| gpu::err(device, e))?;
        Ok(Event {
            device: device.clone(),
            inner: Arc::new(inner),
        })
    }

    /// Captures the work queued on `stream` so far (a stream of the event's device).
    pub fn record(&self, stream: &Stream) -> Result<()> {
        if stream.device != self.device {
            return Err(Error::invalid(format!(
                "an event of \"{}\" cannot record a stream of \"{}\"",
                self.device, stream.device
            )));
        }
        self.inner
            .record(&stream.inner)
            .map_err(|e| gpu::err(&self.device, e))
    }

    /// Waits until the captured work has finished.
    pub fn synchronize(&self) -> Result<()> {
        self.inner
            .synchronize()
            .map_err(|e| gpu::err(&self.device, e))
    }

    /// Whether the captured work has finished (an event never recorded counts as finished).
    pub fn is_complete(&self) -> Result<bool> {
        self.inner
            .is_complete()
            .map_err(|e| gpu::err(&self.device, e))
    }

    /// Milliseconds of GPU time from this event to `end` (both timing events, both recorded);
    /// waits for both.
    pub fn elapsed_ms(&self, end: &Event) -> Result<f32> {
        self.inner
            .elapsed_ms(&end.inner)
            .map_err(|e| gpu::err(&self.device, e))
    }

    /// The device the event belongs to.
    pub fn device(&self) -> &Device {
        &self.device
    }
}

/// While alive, makes `stream` the calling thread's current stream for its device: launches
/// that name no stream go there (like Warp's `wp.ScopedStream`). On creation the stream waits
/// for the previously current stream, so work queued before the scope is ordered before work
/// inside it. Scopes nest; dropping one restores the previous stream. Not `Send`: a scope
/// belongs to the thread that opened it.
#[must_use = "the stream is current only while the `ScopedStream` is alive: bind it (`let _scope = ...`), not `let _ =`, which restores the previous stream at once"]
#[derive(Debug)]
pub struct ScopedStream {
    ordinal: usize,
    stream: warp_cuda::Stream,
    _not_send: PhantomData<*const ()>,
}

impl ScopedStream {
    /// Makes `stream` current on this thread until the guard is dropped.
    pub fn new(stream: &Stream) -> Result<ScopedStream> {
        let ordinal = stream.inner.ordinal();
        let previous = get_stream(&stream.device)?;
        stream.wait_stream(&previous)?;
        gpu::push_current(ordinal, stream.inner.clone());
        Ok(ScopedStream {
            ordinal,
            stream: stream.inner.clone(),
            _not_send: PhantomData,
        })
    }
}

impl Drop for ScopedStream {
    fn drop(&mut self) {
        gpu::pop_current(self.ordinal, &self.stream);
    }
}

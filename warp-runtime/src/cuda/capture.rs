//! Graph capture on a GPU: the CUDA half of `graph.rs`.
//!
//! A capture records the calling thread's work on one GPU into a CUDA graph: `begin` starts
//! stream capture on a stream of its own and makes it the thread's capture stream
//! (`gpu::capture_stream`), so that launches, fills and copies of this thread on that GPU are
//! queued there (and nothing else: allocations, uploads, read-backs, synchronisations and
//! compiles are refused with [`Error::Capture`]); `end` instantiates the graph. A replay is
//! queued like a launch, in the ordering model of `gpu.rs`: after the default stream's work
//! (arrays written before), and the default stream waits for it before its next operation.

use super::gpu::{self, err, state, GpuState};
use super::stream::Stream;
use crate::device::Device;
use crate::error::{Error, Result};
use std::sync::Arc;

/// A capture in progress on one GPU.
pub(crate) struct CudaCapture {
    st: Arc<GpuState>,
    device: Device,
    stream: warp_cuda::Stream,
}

/// Starts capturing the calling thread's work on GPU `ordinal` (`device`): on `stream` when
/// given (a stream the caller made, not the default one), else on the thread's current stream
/// when a `ScopedStream` set one, else on a new stream.
pub(crate) fn begin(device: &Device, ordinal: usize, stream: Option<&Stream>) -> Result<CudaCapture> {
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
    stream.begin_capture().map_err(|e| err(device, e))?;
    gpu::set_capture_stream(Some((ordinal, stream.clone())));
    Ok(CudaCapture {
        st,
        device: device.clone(),
        stream,
    })
}

impl CudaCapture {
    /// Ends the capture and instantiates the graph.
    pub(crate) fn end(self) -> Result<warp_cuda::Graph> {
        gpu::set_capture_stream(None);
        self.stream
            .end_capture(&self.st.gpu)
            .map_err(|e| err(&self.device, e))
    }

    /// Ends the capture and drops what it recorded (the capture failed or was abandoned).
    pub(crate) fn abort(self) {
        gpu::set_capture_stream(None);
        let _ = self.stream.end_capture(&self.st.gpu);
    }
}

/// Queues a replay of `graph` on `stream` when given, else on the calling thread's current
/// stream for its GPU, else on the default stream (the ordering model of `gpu.rs`).
pub(crate) fn launch(
    graph: &warp_cuda::Graph,
    device: &Device,
    stream: Option<&Stream>,
) -> Result<()> {
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
    st.queue(ordinal, stream.map(Stream::cuda_stream), |on| {
        graph.launch(on).map_err(|e| err(device, e))
    })
}

//! CUDA graphs: work captured from a stream, instantiated once, replayed with one driver call.
//!
//! [`Stream::begin_capture`] starts recording what is queued on a stream (in the calling
//! thread's capture mode: other threads keep using the device normally, and this thread's
//! calls that would synchronise fail instead of breaking the capture silently);
//! [`Stream::end_capture`] ends it and instantiates the captured graph as a [`Graph`], which
//! [`Graph::launch`] replays on any stream of its device. What the captured work reads and
//! writes is fixed at capture: device addresses, kernel parameters, memset values. Keeping
//! that memory alive for as long as the graph may be replayed is the caller's job.

use std::sync::Arc;

use cudarc::driver::sys;

use crate::device::{Gpu, Stream};
use crate::error::{CudaError, Result};

/// An instantiated CUDA graph (`CUgraphExec` with its `CUgraph`), replayable on the streams of
/// one device.
///
/// `Send` but not `Sync`: CUDA does not synchronise uses of one graph from several threads.
pub struct Graph {
    gpu: Arc<Gpu>,
    graph: sys::CUgraph,
    exec: sys::CUgraphExec,
    nodes: usize,
}

// SAFETY: the handles are plain driver handles, usable from any thread once the context is
// bound; `Graph` is not `Sync`, so no two threads use them at once.
unsafe impl Send for Graph {}

impl std::fmt::Debug for Graph {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Graph")
            .field("device", &self.gpu.ordinal())
            .field("nodes", &self.nodes)
            .finish()
    }
}

impl Stream {
    /// Starts capturing the work queued on this stream into a graph
    /// (`CU_STREAM_CAPTURE_MODE_THREAD_LOCAL`). Until [`end_capture`](Self::end_capture),
    /// nothing queued on the stream runs.
    ///
    /// # Errors
    /// When the stream is already capturing, or the driver refuses (the legacy stream).
    pub fn begin_capture(&self) -> Result<()> {
        self.bind()?;
        // SAFETY: a live stream of the bound context.
        unsafe {
            sys::cuStreamBeginCapture_v2(
                self.cu_stream(),
                sys::CUstreamCaptureMode::CU_STREAM_CAPTURE_MODE_THREAD_LOCAL,
            )
        }
        .result()
        .map_err(|e| {
            CudaError::driver(e, format!("cuStreamBeginCapture on cuda:{}", self.ordinal()))
        })
    }

    /// Whether the stream is capturing (an invalidated capture counts as capturing: it still
    /// has to be ended).
    pub fn is_capturing(&self) -> Result<bool> {
        self.bind()?;
        let mut status = sys::CUstreamCaptureStatus::CU_STREAM_CAPTURE_STATUS_NONE;
        // SAFETY: out-parameter call on a live stream.
        unsafe { sys::cuStreamIsCapturing(self.cu_stream(), &mut status) }
            .result()
            .map_err(|e| {
                CudaError::driver(e, format!("cuStreamIsCapturing on cuda:{}", self.ordinal()))
            })?;
        Ok(status != sys::CUstreamCaptureStatus::CU_STREAM_CAPTURE_STATUS_NONE)
    }

    /// Ends the capture and instantiates what was captured. The stream is no longer capturing
    /// afterwards, also when this fails (an invalidated capture, a graph that does not
    /// instantiate).
    pub fn end_capture(&self, gpu: &Arc<Gpu>) -> Result<Graph> {
        self.bind()?;
        let ordinal = self.ordinal();
        let mut graph: sys::CUgraph = std::ptr::null_mut();
        // SAFETY: out-parameter call on a live stream.
        unsafe { sys::cuStreamEndCapture(self.cu_stream(), &mut graph) }
            .result()
            .map_err(|e| CudaError::driver(e, format!("cuStreamEndCapture on cuda:{ordinal}")))?;
        if graph.is_null() {
            return Err(CudaError::InvalidArgument(format!(
                "cuStreamEndCapture on cuda:{ordinal} returned no graph"
            )));
        }
        let destroy_graph = |graph| {
            // SAFETY: a graph this function owns, destroyed once.
            unsafe {
                let _ = sys::cuGraphDestroy(graph);
            }
        };
        let mut nodes = 0usize;
        // SAFETY: counting call (null node array) on the graph just returned.
        if let Err(e) =
            unsafe { sys::cuGraphGetNodes(graph, std::ptr::null_mut(), &mut nodes) }.result()
        {
            destroy_graph(graph);
            return Err(CudaError::driver(
                e,
                format!("cuGraphGetNodes on cuda:{ordinal}"),
            ));
        }
        let mut exec: sys::CUgraphExec = std::ptr::null_mut();
        // SAFETY: out-parameter call on a live graph.
        if let Err(e) = unsafe { sys::cuGraphInstantiateWithFlags(&mut exec, graph, 0) }.result() {
            destroy_graph(graph);
            return Err(CudaError::driver(
                e,
                format!("cuGraphInstantiate of {nodes} node(s) on cuda:{ordinal}"),
            ));
        }
        Ok(Graph {
            gpu: gpu.clone(),
            graph,
            exec,
            nodes,
        })
    }
}

impl Graph {
    /// Replays the graph on `stream` (a stream of the graph's device): queued after the
    /// stream's earlier work, like a kernel launch.
    pub fn launch(&self, stream: &Stream) -> Result<()> {
        if stream.ordinal() != self.gpu.ordinal() {
            return Err(CudaError::InvalidArgument(format!(
                "a graph of cuda:{} launched on a stream of cuda:{}",
                self.gpu.ordinal(),
                stream.ordinal()
            )));
        }
        self.gpu.bind()?;
        // SAFETY: a live executable graph and a live stream of the same context.
        unsafe { sys::cuGraphLaunch(self.exec, stream.cu_stream()) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!(
                        "cuGraphLaunch ({} node(s)) on cuda:{}",
                        self.nodes,
                        self.gpu.ordinal()
                    ),
                )
            })
    }

    /// The number of nodes in the graph (kernels, memsets, copies, ..).
    pub fn node_count(&self) -> usize {
        self.nodes
    }

    /// The device the graph runs on.
    pub fn ordinal(&self) -> usize {
        self.gpu.ordinal()
    }
}

impl Drop for Graph {
    fn drop(&mut self) {
        // Destroying an executable graph whose launches are still running is allowed: the
        // driver releases it once they finish. Errors cannot be returned from drop.
        if self.gpu.bind().is_err() {
            return;
        }
        // SAFETY: handles owned by this value, destroyed once.
        unsafe {
            let _ = sys::cuGraphExecDestroy(self.exec);
            let _ = sys::cuGraphDestroy(self.graph);
        }
    }
}

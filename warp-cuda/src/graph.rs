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
            CudaError::driver(
                e,
                format!("cuStreamBeginCapture on cuda:{}", self.ordinal()),
            )
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

/// What a conditional node does with its body graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Conditional {
    /// Runs the body once when the handle is non-zero.
    If,
    /// Runs the body while the handle is non-zero (checked before each iteration).
    While,
}

/// The driver version conditional nodes need (CUDA 12.4: `while` nodes and capture into them).
pub const CONDITIONAL_DRIVER_VERSION: i32 = 12040;

impl Stream {
    /// The graph this stream is capturing into and the nodes the next captured work will
    /// depend on.
    fn capture_info(&self) -> Result<(sys::CUgraph, Vec<sys::CUgraphNode>)> {
        self.bind()?;
        let mut status = sys::CUstreamCaptureStatus::CU_STREAM_CAPTURE_STATUS_NONE;
        let mut graph: sys::CUgraph = std::ptr::null_mut();
        let mut deps: *const sys::CUgraphNode = std::ptr::null();
        let mut edges: *const sys::CUgraphEdgeData = std::ptr::null();
        let mut n = 0usize;
        // SAFETY: out-parameter call on a live stream; the returned arrays are the driver's,
        // valid until the next call on the stream, and copied below.
        unsafe {
            sys::cuStreamGetCaptureInfo_v3(
                self.cu_stream(),
                &mut status,
                std::ptr::null_mut(),
                &mut graph,
                &mut deps,
                &mut edges,
                &mut n,
            )
        }
        .result()
        .map_err(|e| {
            CudaError::driver(
                e,
                format!("cuStreamGetCaptureInfo on cuda:{}", self.ordinal()),
            )
        })?;
        if status != sys::CUstreamCaptureStatus::CU_STREAM_CAPTURE_STATUS_ACTIVE {
            return Err(CudaError::InvalidArgument(format!(
                "a conditional node on a stream of cuda:{} that is not capturing ({status:?})",
                self.ordinal()
            )));
        }
        let deps = if n == 0 || deps.is_null() {
            Vec::new()
        } else {
            // SAFETY: the driver returned `n` nodes at `deps`.
            unsafe { std::slice::from_raw_parts(deps, n) }.to_vec()
        };
        Ok((graph, deps))
    }

    /// Creates a conditional handle in the graph this stream is capturing. Its value is 0 at
    /// each launch of the graph until a kernel sets it (`cudaGraphSetConditional`).
    pub fn conditional_handle(&self, gpu: &Gpu) -> Result<u64> {
        check_conditional_driver(self.ordinal())?;
        let (graph, _) = self.capture_info()?;
        let mut handle: sys::CUgraphConditionalHandle = 0;
        // SAFETY: out-parameter call on the capturing graph of this context.
        unsafe { sys::cuGraphConditionalHandleCreate(&mut handle, graph, gpu.cu_ctx(), 0, 0) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!("cuGraphConditionalHandleCreate on cuda:{}", self.ordinal()),
                )
            })?;
        Ok(handle)
    }

    /// Adds a conditional node on `handle` after the work this stream has captured so far
    /// (later work on it runs after the node), and starts capturing `body` (another stream of
    /// the device) into the node's body graph; end that with
    /// [`end_body_capture`](Self::end_body_capture) on `body`.
    pub fn add_conditional(
        &self,
        gpu: &Gpu,
        handle: u64,
        kind: Conditional,
        body: &Stream,
    ) -> Result<()> {
        check_conditional_driver(self.ordinal())?;
        let ordinal = self.ordinal();
        let (graph, mut deps) = self.capture_info()?;
        // SAFETY: a zeroed parameter block is the documented starting point; the conditional
        // member is then filled in full.
        let mut params: sys::CUgraphNodeParams = unsafe { std::mem::zeroed() };
        params.type_ = sys::CUgraphNodeType::CU_GRAPH_NODE_TYPE_CONDITIONAL;
        params.__bindgen_anon_1.conditional = sys::CUDA_CONDITIONAL_NODE_PARAMS {
            handle,
            type_: match kind {
                Conditional::If => sys::CUgraphConditionalNodeType::CU_GRAPH_COND_TYPE_IF,
                Conditional::While => sys::CUgraphConditionalNodeType::CU_GRAPH_COND_TYPE_WHILE,
            },
            size: 1,
            // An output: the driver points it at the node's own array of body graphs.
            phGraph_out: std::ptr::null_mut(),
            ctx: gpu.cu_ctx(),
        };
        let mut node: sys::CUgraphNode = std::ptr::null_mut();
        // SAFETY: `deps` are nodes of `graph` (from the capture info); `params` is filled.
        unsafe {
            sys::cuGraphAddNode_v2(
                &mut node,
                graph,
                deps.as_ptr(),
                std::ptr::null(),
                deps.len(),
                &mut params,
            )
        }
        .result()
        .map_err(|e| {
            CudaError::driver(e, format!("cuGraphAddNode (conditional) on cuda:{ordinal}"))
        })?;
        // SAFETY: after a successful cuGraphAddNode the driver's array holds `size` (1) body
        // graphs, valid for the node's lifetime.
        let body_graph = unsafe {
            let out = params.__bindgen_anon_1.conditional.phGraph_out;
            if out.is_null() {
                std::ptr::null_mut()
            } else {
                *out
            }
        };
        if body_graph.is_null() {
            return Err(CudaError::InvalidArgument(format!(
                "cuGraphAddNode (conditional) on cuda:{ordinal} returned no body graph"
            )));
        }
        deps.clear();
        deps.push(node);
        // SAFETY: one node of the capturing graph, replacing the stream's dependencies.
        unsafe {
            sys::cuStreamUpdateCaptureDependencies_v2(
                self.cu_stream(),
                deps.as_mut_ptr(),
                std::ptr::null(),
                1,
                sys::CUstreamUpdateCaptureDependencies_flags::CU_STREAM_SET_CAPTURE_DEPENDENCIES
                    as u32,
            )
        }
        .result()
        .map_err(|e| {
            CudaError::driver(
                e,
                format!("cuStreamUpdateCaptureDependencies on cuda:{ordinal}"),
            )
        })?;
        body.bind()?;
        // SAFETY: the body graph the driver made for the node; no dependencies.
        unsafe {
            sys::cuStreamBeginCaptureToGraph(
                body.cu_stream(),
                body_graph,
                std::ptr::null(),
                std::ptr::null(),
                0,
                sys::CUstreamCaptureMode::CU_STREAM_CAPTURE_MODE_THREAD_LOCAL,
            )
        }
        .result()
        .map_err(|e| CudaError::driver(e, format!("cuStreamBeginCaptureToGraph on cuda:{ordinal}")))
    }

    /// Ends a body capture begun by [`add_conditional`](Self::add_conditional) (the body
    /// graph belongs to its node).
    pub fn end_body_capture(&self) -> Result<()> {
        self.bind()?;
        let mut graph: sys::CUgraph = std::ptr::null_mut();
        // SAFETY: out-parameter call on a live stream; the graph is the node's, not ours.
        unsafe { sys::cuStreamEndCapture(self.cu_stream(), &mut graph) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!(
                        "cuStreamEndCapture (conditional body) on cuda:{}",
                        self.ordinal()
                    ),
                )
            })
    }
}

/// An error unless the driver has conditional nodes (a missing entry point would otherwise
/// end the process in the dynamic loader).
fn check_conditional_driver(ordinal: usize) -> Result<()> {
    match crate::device::driver_version() {
        Some(v) if v >= CONDITIONAL_DRIVER_VERSION => Ok(()),
        v => {
            Err(CudaError::NotAvailable(format!(
            "conditional graph nodes on cuda:{ordinal} need a CUDA {}.{} driver, this one is {}",
            CONDITIONAL_DRIVER_VERSION / 1000,
            CONDITIONAL_DRIVER_VERSION % 1000 / 10,
            v.map_or("unknown".to_string(), |v| format!("{}.{}", v / 1000, v % 1000 / 10))
        )))
        }
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

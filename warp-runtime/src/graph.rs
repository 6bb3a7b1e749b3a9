//! Graphs: work recorded once and replayed with one call ([`capture`], [`ScopedCapture`],
//! [`Graph`]), Warp's `wp.capture_begin`/`capture_end`/`capture_launch`.
//!
//! While a thread captures on a device, its kernel launches (forward and adjoint, so a tape's
//! backward pass can be captured too) and its array fills and copies on that device are
//! recorded instead of run; [`Graph::launch`] replays them in order. On a GPU the recording is
//! a CUDA graph (stream capture: a replay is one `cuGraphLaunch`); on the CPU it is the list
//! of recorded operations, run one after the other. The rules are the same on both, so code
//! written for one runs on the other:
//! - what cannot be replayed is an [`Error::Capture`] at the call inside the capture: an
//!   allocation, an upload or a read-back (`to_vec`, `check_finite`), a synchronisation, the
//!   primitives and object builds (they read sizes back), work on another device, a capture
//!   inside a capture, and on a GPU a kernel compiled at its first launch (load kernels
//!   before with [`crate::load`]);
//! - the graph holds what the recorded work uses (array handles, host objects), so a replay
//!   never touches freed memory: arrays dropped by their owner after the capture stay
//!   allocated until the graph is dropped;
//! - values (scalars, structs, launch dims) are those of the capture; to change them between
//!   replays, keep them in arrays (or capture again);
//! - only the capturing thread's work is recorded (other threads run as usual).
//!
//! A tape recording during a capture records the captured launches (once); its backward can
//! run plainly or be captured into a graph of its own.

use crate::capturing::{
    self, capturing, check_device, push_op, record_frame, take_active, Active, Captured, Op,
};
use crate::device::{Device, DeviceKind};
use crate::dispatch;
use crate::error::{Error, Result};
use crate::kernel::{ArgsOf, Kernel, KernelParams};
use std::marker::PhantomData;
use warp_core::Grid;

#[cfg(feature = "cuda")]
use crate::cuda::capture as cuda_capture;
#[cfg(feature = "cuda")]
use crate::cuda::stream::Stream;

/// Records a launch of `K` (its adjoint with `adjoint: Some(stack bytes)`) on the calling
/// thread's capture, if any: on the CPU as an operation of the graph, on a GPU by keeping the
/// arguments alive for the graph (the backend queues the launch on the capture stream).
pub(crate) fn on_launch<K: Kernel>(
    device: &Device,
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    adjoint: Option<usize>,
) -> Result<Captured> {
    let recorded = capturing::with_active(|active| {
        let what = format!("a launch of kernel `{}`", K::INFO.name);
        check_device(active, device, &what)?;
        let owned = K::Params::own(args);
        if matches!(device.kind(), DeviceKind::Cpu) {
            active.launches += 1;
            let (grid, device) = (*grid, device.clone());
            let op: Op = Box::new(move || {
                let args = K::Params::borrow(&owned);
                match adjoint {
                    None => dispatch::launch::<K>(&device, &args, &grid),
                    Some(bytes) => dispatch::launch_adjoint::<K>(&device, &args, &grid, bytes),
                }
            });
            push_op(active, op);
            return Ok(Captured::Recorded);
        }
        // (Counted by `launched` once the backend has queued it.)
        active.keep.push(Box::new(owned));
        Ok(Captured::OnGpu)
    });
    recorded.unwrap_or(Ok(Captured::No))
}

/// Counts a launch the backend queued on the capture stream (after [`on_launch`] said
/// `OnGpu`): a launch the backend refused is not part of the graph.
pub(crate) fn launched() {
    capturing::with_active(|active| active.launches += 1);
}

/// The adjoint of a launch of `K`, as a tape's backward runs it: recorded when the calling
/// thread captures (a captured backward pass), else run.
pub(crate) fn launch_adjoint<K: Kernel>(
    device: &Device,
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    adstack_bytes: usize,
) -> Result<()> {
    match on_launch::<K>(device, args, grid, Some(adstack_bytes))? {
        Captured::Recorded => Ok(()),
        Captured::OnGpu => {
            dispatch::launch_adjoint::<K>(device, args, grid, adstack_bytes)?;
            launched();
            Ok(())
        }
        Captured::No => dispatch::launch_adjoint::<K>(device, args, grid, adstack_bytes),
    }
}

/// Where a capture records: a device (on a GPU, a stream of the capture's own, or the
/// thread's current stream set by a `ScopedStream`), or a given CUDA stream.
#[derive(Clone, Debug)]
pub enum CaptureOn {
    /// Capture on a device.
    Device(Device),
    /// Capture on this CUDA stream (not the device's default stream).
    #[cfg(feature = "cuda")]
    Stream(Stream),
}

impl From<&Device> for CaptureOn {
    fn from(d: &Device) -> CaptureOn {
        CaptureOn::Device(d.clone())
    }
}

#[cfg(feature = "cuda")]
impl From<&Stream> for CaptureOn {
    fn from(s: &Stream) -> CaptureOn {
        CaptureOn::Stream(s.clone())
    }
}

/// A capture in progress on the calling thread (Warp's `wp.ScopedCapture`): from
/// [`ScopedCapture::new`] to [`ScopedCapture::finish`], the thread's work on the device is
/// recorded into the graph that `finish` returns. Dropped without `finish` (an early return
/// on an error), the capture ends and what it recorded is discarded. Not `Send`: the capture
/// belongs to its thread.
#[must_use = "dropping a `ScopedCapture` ends the capture and discards what it recorded: keep it and call `finish` for the graph"]
#[derive(Debug)]
pub struct ScopedCapture {
    finished: bool,
    _not_send: PhantomData<*const ()>,
}

impl ScopedCapture {
    /// Starts capturing on `on` (`&device` or, on a GPU, `&stream`).
    ///
    /// # Errors
    /// [`Error::Capture`] inside another capture, or on a GPU's default stream;
    /// [`Error::Cuda`] when the driver refuses.
    pub fn new(on: impl Into<CaptureOn>) -> Result<ScopedCapture> {
        if capturing() {
            let device = capturing::with_active(|a| a.device.clone());
            return Err(Error::Capture {
                what: format!(
                    "a capture inside a capture (the thread is capturing on \"{}\"); nest the \
                     work in the outer capture instead",
                    device.map(|d| d.to_string()).unwrap_or_default()
                ),
            });
        }
        let on = on.into();
        let device = match &on {
            CaptureOn::Device(d) => d.clone(),
            #[cfg(feature = "cuda")]
            CaptureOn::Stream(s) => s.device().clone(),
        };
        #[cfg(feature = "cuda")]
        let cuda = match device.kind() {
            DeviceKind::Cpu => None,
            DeviceKind::Cuda { ordinal } => {
                let stream = match &on {
                    CaptureOn::Stream(s) => Some(s),
                    CaptureOn::Device(_) => None,
                };
                Some(cuda_capture::begin(&device, ordinal, stream)?)
            }
        };
        #[cfg(not(feature = "cuda"))]
        if let DeviceKind::Cuda { .. } = device.kind() {
            return Err(Error::NoDevice {
                name: device.alias().to_string(),
                reason: crate::device::CUDA_UNAVAILABLE.to_string(),
            });
        }
        capturing::start(Active {
            device,
            frames: vec![Vec::new()],
            keep: Vec::new(),
            launches: 0,
            #[cfg(feature = "cuda")]
            cuda,
        });
        Ok(ScopedCapture {
            finished: false,
            _not_send: PhantomData,
        })
    }

    /// Ends the capture and returns its graph.
    ///
    /// # Errors
    /// [`Error::Capture`] when a conditional body is still open; [`Error::Cuda`] when the
    /// driver cannot instantiate the graph.
    pub fn finish(mut self) -> Result<Graph> {
        self.finished = true;
        let active = take_active();
        let Some(mut active) = active else {
            return Err(Error::Capture {
                what: "the capture was already ended".into(),
            });
        };
        #[cfg(feature = "cuda")]
        let cuda = active.cuda.take();
        if active.frames.len() != 1 {
            #[cfg(feature = "cuda")]
            if let Some(c) = cuda {
                c.abort();
            }
            return Err(Error::Capture {
                what: "a conditional body is still open at the end of the capture".into(),
            });
        }
        let ops = active.frames.swap_remove(0);
        #[cfg(feature = "cuda")]
        let body = match cuda {
            Some(c) => Body::Cuda(c.end()?),
            None => Body::Cpu(ops),
        };
        #[cfg(not(feature = "cuda"))]
        let body = Body::Cpu(ops);
        Ok(Graph {
            device: active.device,
            body,
            launches: active.launches,
            _keep: active.keep,
        })
    }
}

impl Drop for ScopedCapture {
    fn drop(&mut self) {
        if self.finished {
            return;
        }
        #[cfg(feature = "cuda")]
        if let Some(c) = take_active().and_then(|mut a| a.cuda.take()) {
            c.abort();
        }
        #[cfg(not(feature = "cuda"))]
        drop(take_active());
    }
}

/// Records what `body` does on `on` (`&device`, or on a GPU `&stream`) into a [`Graph`]:
/// `wp::capture(&dev, || { wp::launch(..)?; wp::launch(..)?; Ok(()) })?`. When `body` fails,
/// the capture is discarded and its error returned. See the [module docs](self) for what a
/// capture records and refuses.
///
/// ```ignore
/// // (tests/suite/graph.rs runs this on every backend)
/// wp::load(&[wp::kernel_info(integrate)], &dev)?; // a GPU compiles nothing inside a capture
/// let graph = wp::capture(&dev, || {
///     for _ in 0..substeps {
///         wp::launch(integrate, n, (&x, &v, dt), &dev)?;
///     }
///     Ok(())
/// })?;
/// for _frame in 0..frames {
///     graph.launch()?;
/// }
/// ```
///
/// # Errors
/// As [`ScopedCapture::new`] and [`ScopedCapture::finish`], and `body`'s.
pub fn capture(on: impl Into<CaptureOn>, body: impl FnOnce() -> Result<()>) -> Result<Graph> {
    let scope = ScopedCapture::new(on)?;
    body()?;
    scope.finish()
}

/// Runs `body` while element 0 of `cond` is non-zero, checked before each iteration (Warp's
/// `wp.capture_while`): the adaptive loop of a solver that runs until a kernel clears a flag.
///
/// Inside a capture the loop is recorded with its condition, evaluated when the graph runs:
/// on a GPU as a CUDA conditional node (a `while` node whose body graph ends by reading the
/// flag again; needs a CUDA 12.4 driver and the toolkit's `libcudadevrt.a`), on the CPU as a
/// loop over the recorded body. Outside a capture it is a host loop that reads the flag back
/// before each iteration. `body` is called once when captured, once per iteration otherwise.
///
/// ```ignore
/// // (tests/suite/graph.rs runs this on every backend)
/// let graph = wp::capture(&dev, || {
///     wp::launch(reset, 1, (&flag,), &dev)?;        // flag = 1
///     wp::capture_while(&flag, || {
///         wp::launch(relax, n, (&x, &residual), &dev)?;
///         wp::launch(check, 1, (&residual, tol, &flag), &dev) // flag = residual > tol
///     })
/// })?;
/// graph.launch()?;
/// ```
///
/// # Errors
/// [`Error::Capture`] when `cond` is empty or on another device than the capture's, or (on a
/// GPU) when conditional nodes are not available; `body`'s errors.
pub fn capture_while(cond: &crate::Array<i32>, mut body: impl FnMut() -> Result<()>) -> Result<()> {
    check_condition(cond, "capture_while")?;
    if !capturing() {
        while first(cond)? != 0 {
            body()?;
        }
        return Ok(());
    }
    conditional(cond, ConditionalKind::While, &mut body, None)
}

/// Runs `on_true` when element 0 of `cond` is non-zero and `on_false` otherwise (Warp's
/// `wp.capture_if`); inside a capture the branch is decided when the graph runs (CUDA
/// conditional nodes on a GPU, as for [`capture_while`]; both bodies are recorded, each once).
///
/// # Errors
/// As [`capture_while`].
pub fn capture_if(
    cond: &crate::Array<i32>,
    mut on_true: impl FnMut() -> Result<()>,
    mut on_false: impl FnMut() -> Result<()>,
) -> Result<()> {
    check_condition(cond, "capture_if")?;
    if !capturing() {
        return if first(cond)? != 0 {
            on_true()
        } else {
            on_false()
        };
    }
    conditional(cond, ConditionalKind::If, &mut on_true, Some(&mut on_false))
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum ConditionalKind {
    If,
    While,
}

fn check_condition(cond: &crate::Array<i32>, what: &str) -> Result<()> {
    if cond.is_empty() {
        return Err(Error::Capture {
            what: format!("{what}: the condition array is empty (its element 0 is the flag)"),
        });
    }
    Ok(())
}

/// Element 0 of `cond`, read back.
fn first(cond: &crate::Array<i32>) -> Result<i32> {
    Ok(cond.view(..1)?.to_vec()?[0])
}

/// A conditional inside the calling thread's capture: on the CPU the bodies recorded into
/// frames of their own and replayed by one operation that reads the flag; on a GPU conditional
/// nodes.
fn conditional(
    cond: &crate::Array<i32>,
    kind: ConditionalKind,
    then: &mut dyn FnMut() -> Result<()>,
    otherwise: Option<&mut dyn FnMut() -> Result<()>>,
) -> Result<()> {
    let what = match kind {
        ConditionalKind::If => "capture_if",
        ConditionalKind::While => "capture_while",
    };
    let device = capturing::with_active(|active| -> Result<Device> {
        check_device(active, cond.device(), what)?;
        active.keep.push(Box::new(cond.clone()));
        Ok(active.device.clone())
    })
    .expect("called while capturing")?;
    match device.kind() {
        DeviceKind::Cpu => {
            let then_ops = record_frame(then)?;
            let else_ops = match otherwise {
                Some(body) => record_frame(body)?,
                None => Vec::new(),
            };
            let cond = cond.clone();
            let op: Op = match kind {
                ConditionalKind::While => Box::new(move || {
                    while first(&cond)? != 0 {
                        run_ops(&then_ops)?;
                    }
                    Ok(())
                }),
                ConditionalKind::If => Box::new(move || {
                    if first(&cond)? != 0 {
                        run_ops(&then_ops)
                    } else {
                        run_ops(&else_ops)
                    }
                }),
            };
            capturing::with_active(|active| push_op(active, op));
            Ok(())
        }
        #[cfg(feature = "cuda")]
        DeviceKind::Cuda { ordinal } => {
            let kind = match kind {
                ConditionalKind::If => warp_cuda::Conditional::If,
                ConditionalKind::While => warp_cuda::Conditional::While,
            };
            cuda_capture::conditional(
                &device,
                ordinal,
                kind,
                cond.device_address(),
                then,
                otherwise,
            )
        }
        #[cfg(not(feature = "cuda"))]
        DeviceKind::Cuda { .. } => unreachable!("no CUDA capture without the cuda feature"),
    }
}

/// What a graph replays.
enum Body {
    Cpu(Vec<Op>),
    #[cfg(feature = "cuda")]
    Cuda(cuda_capture::CudaGraph),
}

/// Recorded work, replayed by [`Graph::launch`] (Warp's `wp.Graph` and `wp.capture_launch`).
#[must_use = "a capture records its work without running it: the work runs when the `Graph` is launched"]
pub struct Graph {
    device: Device,
    body: Body,
    launches: usize,
    /// What the recorded work uses, alive for as long as the graph can be replayed.
    _keep: Vec<capturing::Keep>,
}

impl std::fmt::Debug for Graph {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Graph")
            .field("device", &self.device)
            .field("launches", &self.launches)
            .field("nodes", &self.node_count())
            .finish()
    }
}

impl Graph {
    /// Replays the graph. On a GPU it is queued on the calling thread's current stream
    /// (a `ScopedStream`'s, else the default stream), ordered after array operations made
    /// before and before those made after, like a launch; faults are reported by the next
    /// synchronisation. On the CPU the recorded operations run in order before this returns.
    ///
    /// # Errors
    /// [`Error::Capture`] inside a capture; a fault or error of a recorded operation (CPU);
    /// [`Error::Cuda`] (GPU).
    pub fn launch(&self) -> Result<()> {
        self.launch_inner(
            #[cfg(feature = "cuda")]
            None,
        )
    }

    /// Replays the graph on `stream` (a stream of the graph's GPU).
    ///
    /// # Errors
    /// [`Error::Capture`] for a CPU graph, a stream of another device, or inside a capture.
    #[cfg(feature = "cuda")]
    pub fn launch_on(&self, stream: &Stream) -> Result<()> {
        self.launch_inner(Some(stream))
    }

    fn launch_inner(&self, #[cfg(feature = "cuda")] stream: Option<&Stream>) -> Result<()> {
        if capturing() {
            return Err(Error::Capture {
                what: "a graph launched inside a capture (capture its work in the outer \
                       capture instead)"
                    .into(),
            });
        }
        match &self.body {
            Body::Cpu(ops) => {
                #[cfg(feature = "cuda")]
                if let Some(s) = stream {
                    return Err(Error::Capture {
                        what: format!(
                            "a graph captured on \"{}\" launched on a stream of \"{}\"",
                            self.device,
                            s.device()
                        ),
                    });
                }
                run_ops(ops)
            }
            #[cfg(feature = "cuda")]
            Body::Cuda(g) => cuda_capture::launch(g, &self.device, stream),
        }
    }

    /// The device the graph runs on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// How many kernel launches were recorded (forward and adjoint).
    pub fn launches(&self) -> usize {
        self.launches
    }

    /// The graph's size: CUDA graph nodes (kernels, memsets, copies, conditionals) on a GPU,
    /// recorded operations on the CPU.
    pub fn node_count(&self) -> usize {
        match &self.body {
            Body::Cpu(ops) => ops.len(),
            #[cfg(feature = "cuda")]
            Body::Cuda(g) => g.node_count(),
        }
    }
}

fn run_ops(ops: &[Op]) -> Result<()> {
    for op in ops {
        op()?;
    }
    Ok(())
}

//! Graphs: work recorded once and replayed with one call ([`capture`], [`ScopedCapture`],
//! [`Graph`]), Warp's `wp.capture_begin`/`capture_end`/`capture_launch`.
//!
//! While a thread captures on a device, everything it enqueues there without a host
//! read-back is recorded instead of run: kernel launches (forward and adjoint, so a tape's
//! backward pass can be captured too), array fills and copies, the parallel primitives (scan,
//! reductions, radix sort, compaction: with a device count, a replay reads the count then) and
//! the host objects' operations that read nothing back ([`HashGrid::build`](crate::HashGrid::build),
//! [`Bvh::refit`](crate::Bvh::refit), [`Mesh::refit`](crate::Mesh::refit): each replay builds
//! or refits the object in place, as often as the capture did; a check of their input that
//! would read a flag back is a fault raised on the device instead).
//! [`Graph::launch`] replays them in order. Capture goes through the backend seam
//! (`backend.rs`): on a GPU the recording is a CUDA graph (stream capture: a replay is one
//! `cuGraphLaunch`); on the CPU it is the list of recorded operations, run one after the
//! other. The rules are the same on both, so code written for one runs on the other:
//! - what cannot be replayed is an [`Error::Capture`] at the call inside the capture: an
//!   allocation, an upload or a read-back (`to_vec`, `check_finite`, and the object builds
//!   that read sizes or checks back: a BVH, a mesh, a volume, marching cubes), a
//!   synchronisation, work on another device, a capture inside a capture; and on a GPU,
//!   where nothing is compiled or allocated inside a capture, a kernel compiled at its first
//!   launch (load kernels before with [`crate::load`]) and a primitive or build step at its
//!   first use on the device or needing more scratch memory than it had (run it once before
//!   capturing);
//! - the graph holds what the recorded work uses (array handles, host objects), so a replay
//!   never touches freed memory: arrays dropped by their owner after the capture stay
//!   allocated until the graph is dropped;
//! - values (scalars, structs, launch dims, host counts) are those of the capture; to change
//!   them between replays, keep them in arrays (a device count, say) or capture again;
//! - only the capturing thread's work is recorded (other threads run as usual).
//!
//! A tape recording during a capture records the captured launches (once); its backward can
//! run plainly or be captured into a graph of its own.

use crate::backend::Conditional;
use crate::capturing::{self, capturing, check_device, take_active, Active};
use crate::device::Device;
use crate::dispatch::{self, Replay};
use crate::error::{Error, Result};
use std::marker::PhantomData;

#[cfg(feature = "cuda")]
use crate::cuda::stream::Stream;

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
        if let Some(device) = capturing::device() {
            return Err(Error::Capture {
                what: format!(
                    "a capture inside a capture (the thread is capturing on \"{device}\"); nest \
                     the work in the outer capture instead"
                ),
            });
        }
        let device = match on.into() {
            CaptureOn::Device(d) => {
                dispatch::begin_capture(&d)?;
                d
            }
            #[cfg(feature = "cuda")]
            CaptureOn::Stream(s) => {
                dispatch::begin_capture_on(&s)?;
                s.device().clone()
            }
        };
        capturing::start(Active::new(device));
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
        let Some(active) = take_active() else {
            return Err(Error::Capture {
                what: "the capture was already ended".into(),
            });
        };
        let body = dispatch::end_capture(&active.device);
        if body.is_err() {
            // Whatever the backend still holds of the capture goes.
            dispatch::abort_capture(&active.device);
        }
        Ok(Graph {
            body: body?,
            device: active.device,
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
        if let Some(active) = take_active() {
            dispatch::abort_capture(&active.device);
        }
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
    conditional(cond, Conditional::While, &mut body, None)
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
    conditional(cond, Conditional::If, &mut on_true, Some(&mut on_false))
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

/// A conditional inside the calling thread's capture, recorded by the capture's backend (see
/// [`Backend::capture_conditional`](crate::backend::Backend::capture_conditional)), with
/// `cond` kept for the graph.
fn conditional(
    cond: &crate::Array<i32>,
    kind: Conditional,
    then: &mut dyn FnMut() -> Result<()>,
    otherwise: Option<&mut dyn FnMut() -> Result<()>>,
) -> Result<()> {
    let what = match kind {
        Conditional::If => "capture_if",
        Conditional::While => "capture_while",
    };
    check_device(cond.device(), &|| what.to_string())?;
    capturing::keep(Box::new(cond.clone()));
    dispatch::capture_conditional(cond.device(), kind, cond.device_address(), then, otherwise)
}

/// Recorded work, replayed by [`Graph::launch`] (Warp's `wp.Graph` and `wp.capture_launch`).
#[must_use = "a capture records its work without running it: the work runs when the `Graph` is launched"]
pub struct Graph {
    device: Device,
    body: Replay,
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
        #[cfg(feature = "cuda")]
        if let Some(s) = stream {
            return dispatch::replay_on(&self.device, &self.body, s);
        }
        dispatch::replay(&self.device, &self.body)
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
        self.body.node_count()
    }
}

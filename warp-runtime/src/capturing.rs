//! The calling thread's capture (`graph.rs`'s state), below `dispatch` and `array` so that
//! both can ask it what to do with an operation: record it (the CPU), let the backend queue it
//! on the capture stream (a GPU), or refuse it ([`refuse`]), the same on every backend.

use crate::device::{Device, DeviceKind};
use crate::error::{Error, Result};
use std::any::Any;
use std::cell::{Cell, RefCell};

#[cfg(feature = "cuda")]
use crate::cuda::capture::CudaCapture;

/// One recorded CPU operation.
pub(crate) type Op = Box<dyn Fn() -> Result<()> + Send>;

/// What is kept alive for a graph's replays (launch arguments' owned copies, arrays).
pub(crate) type Keep = Box<dyn Any + Send>;

/// The calling thread's capture.
pub(crate) struct Active {
    pub(crate) device: Device,
    /// The CPU recording: the operations of the graph, then one list per open conditional
    /// body (innermost last).
    pub(crate) frames: Vec<Vec<Op>>,
    pub(crate) keep: Vec<Keep>,
    pub(crate) launches: usize,
    #[cfg(feature = "cuda")]
    pub(crate) cuda: Option<CudaCapture>,
}

thread_local! {
    static ACTIVE: RefCell<Option<Active>> = const { RefCell::new(None) };
    /// Whether `ACTIVE` is set: one load on the launch path when nothing is captured.
    static CAPTURING: Cell<bool> = const { Cell::new(false) };
}

/// Whether the calling thread is capturing.
#[inline]
pub(crate) fn capturing() -> bool {
    CAPTURING.with(Cell::get)
}

/// What a capture does with an operation.
pub(crate) enum Captured {
    /// Nothing is captured on this thread: run it.
    No,
    /// Recorded for the CPU graph: do not run it now.
    Recorded,
    /// A GPU capture: run it (the backend queues it on the capture stream).
    OnGpu,
}

/// The device the calling thread captures on, or an error when `device` is another one.
pub(crate) fn check_device(active: &Active, device: &Device, what: &str) -> Result<()> {
    if *device != active.device {
        return Err(Error::Capture {
            what: format!(
                "{what} on \"{device}\" inside a capture on \"{}\" (a graph replays the work of \
                 one device)",
                active.device
            ),
        });
    }
    Ok(())
}

/// The innermost open frame gets `op`.
pub(crate) fn push_op(active: &mut Active, op: Op) {
    active
        .frames
        .last_mut()
        .expect("a capture has at least its graph's frame")
        .push(op);
}

/// An array operation (`what`, on arrays of `devices`) inside the calling thread's capture:
/// on the CPU recorded as `op()`, on a GPU run (the backend queues it on the capture stream),
/// and refused when it involves another device than the capture's. `keep` is what the
/// operation uses (kept alive for a GPU graph).
pub(crate) fn on_array_op(
    devices: &[&Device],
    what: &str,
    keep: impl FnOnce() -> Keep,
    op: impl FnOnce() -> Op,
) -> Result<Captured> {
    if !capturing() {
        return Ok(Captured::No);
    }
    ACTIVE.with(|a| {
        let mut a = a.borrow_mut();
        let Some(active) = a.as_mut() else {
            return Ok(Captured::No);
        };
        for d in devices {
            check_device(active, d, what)?;
        }
        if matches!(active.device.kind(), DeviceKind::Cpu) {
            push_op(active, op());
            Ok(Captured::Recorded)
        } else {
            active.keep.push(keep());
            Ok(Captured::OnGpu)
        }
    })
}

/// An [`Error::Capture`] when the calling thread is capturing and `what` (an operation on
/// `device`, or on any device with `None`) cannot be recorded: the same refusals on every
/// backend.
pub(crate) fn refuse(device: Option<&Device>, what: &str) -> Result<()> {
    if !capturing() {
        return Ok(());
    }
    ACTIVE.with(|a| match &*a.borrow() {
        Some(active) if device.is_none_or(|d| *d == active.device) => Err(Error::Capture {
            what: format!(
                "{what} on \"{}\" cannot be recorded into a graph (do it before or after the \
                 capture)",
                active.device
            ),
        }),
        _ => Ok(()),
    })
}

/// Clears the calling thread's capture and returns it.
pub(crate) fn take_active() -> Option<Active> {
    CAPTURING.with(|c| c.set(false));
    ACTIVE.with(|a| a.borrow_mut().take())
}

/// Makes `active` the calling thread's capture.
pub(crate) fn start(active: Active) {
    ACTIVE.with(|a| *a.borrow_mut() = Some(active));
    CAPTURING.with(|c| c.set(true));
}

/// `f` of the calling thread's capture, if it has one.
pub(crate) fn with_active<R>(f: impl FnOnce(&mut Active) -> R) -> Option<R> {
    if !capturing() {
        return None;
    }
    ACTIVE.with(|a| a.borrow_mut().as_mut().map(f))
}

/// Runs `body` with a new frame open on the calling thread's CPU capture, and returns what it
/// recorded there.
pub(crate) fn record_frame(body: &mut dyn FnMut() -> Result<()>) -> Result<Vec<Op>> {
    ACTIVE.with(|a| {
        a.borrow_mut()
            .as_mut()
            .expect("capturing")
            .frames
            .push(Vec::new())
    });
    let ran = body();
    let ops = ACTIVE.with(|a| {
        a.borrow_mut()
            .as_mut()
            .expect("capturing")
            .frames
            .pop()
            .expect("the frame pushed above")
    });
    ran.map(|()| ops)
}

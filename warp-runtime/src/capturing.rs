//! The calling thread's capture (`graph.rs`'s state): the rules that are the same on every
//! backend, below `dispatch` and `array` so that both can apply them to an operation before
//! the backend records it (`backend.rs`, [`Backend::record`](crate::backend::Backend::record)):
//! a capture is of one device ([`check_device`]), the graph keeps alive what the recorded work
//! uses ([`keep`]), and what cannot be replayed is refused ([`refuse`]).

use crate::device::Device;
use crate::error::{Error, Result};
use std::any::Any;
use std::cell::{Cell, RefCell};

/// What is kept alive for a graph's replays (launch arguments' owned copies, arrays).
pub(crate) type Keep = Box<dyn Any + Send>;

/// The calling thread's capture, as every backend has it (what recording means is the
/// backend's, which holds its own state from `begin_capture` to `end_capture`).
pub(crate) struct Active {
    pub(crate) device: Device,
    /// What the recorded work uses (see [`keep`]).
    pub(crate) keep: Vec<Keep>,
    /// Kernel launches recorded (forward and adjoint).
    pub(crate) launches: usize,
    /// The host objects' buffers this capture writes (see [`adopt`]), by address.
    adopted: Vec<usize>,
    /// The capture's number, distinct from every other capture's in the process ([`id`]).
    id: u64,
}

impl Active {
    /// A capture on `device` that has recorded nothing yet.
    pub(crate) fn new(device: Device) -> Active {
        Active {
            device,
            keep: Vec::new(),
            launches: 0,
            adopted: Vec::new(),
            id: {
                static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
                NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            },
        }
    }
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

/// The number of the calling thread's capture, if it captures: an object may note which
/// capture recorded its last operation (what it knows of its buffers holds within that
/// capture's replays only).
pub(crate) fn id() -> Option<u64> {
    with_active(|a| a.id)
}

/// The device the calling thread captures on, if it captures.
pub(crate) fn device() -> Option<Device> {
    with_active(|a| a.device.clone())
}

/// An error when the calling thread captures on another device than `device`, for the
/// operation `what()` (formatted only then): a graph replays the work of one device.
pub(crate) fn check_device(device: &Device, what: &dyn Fn() -> String) -> Result<()> {
    with_active(|active| {
        if *device == active.device {
            return Ok(());
        }
        Err(Error::Capture {
            what: format!(
                "{} on \"{device}\" inside a capture on \"{}\" (a graph replays the work of \
                 one device)",
                what(),
                active.device
            ),
        })
    })
    .unwrap_or(Ok(()))
}

/// Keeps `uses` (what an operation recorded into the calling thread's capture touches) alive
/// for as long as the graph, so that a replay never touches freed memory.
pub(crate) fn keep(uses: Keep) {
    with_active(|a| a.keep.push(uses));
}

/// Whether a host object may write the buffers `shared` (its `Arc`) in place in the calling
/// thread's capture, and if so makes them the capture's: when no one else holds them (the
/// object's own), or when this capture adopted them before. An object's operation recorded
/// into a graph (a hash grid's build, a BVH's refit) writes its buffers in place at every
/// replay, so the launches recorded after it (which hold the same buffers) see its result;
/// buffers shared with a clone made before the capture (a tape's) are refused, as that clone
/// must keep what it holds (the object's copy-on-write, which would allocate). Adopted
/// buffers are kept alive for the graph (their address names them until it is dropped).
///
/// A launch recorded into the capture adopts the host objects it takes this way before the
/// graph keeps their clones (`HostObject::adopt_in_capture`), so that a frame may query an
/// object before it rebuilds it.
pub(crate) fn adopt<T: Send + Sync + 'static>(shared: &std::sync::Arc<T>) -> bool {
    let address = std::sync::Arc::as_ptr(shared) as usize;
    // (No weak references to the objects' buffers are made: the strong count is every holder.)
    let own = std::sync::Arc::strong_count(shared) == 1;
    with_active(|a| {
        if a.adopted.contains(&address) {
            return true;
        }
        if !own {
            return false;
        }
        a.adopted.push(address);
        a.keep.push(Box::new(std::sync::Arc::clone(shared)));
        true
    })
    .unwrap_or(own)
}

/// Counts a kernel launch recorded into the calling thread's capture.
pub(crate) fn launched() {
    with_active(|a| a.launches += 1);
}

/// An [`Error::Capture`] when the calling thread is capturing and `what` (an operation on
/// `device`, or on any device with `None`) cannot be recorded: an allocation, an upload, a
/// read-back, a synchronisation. The same refusals on every backend.
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

/// Makes `active` the calling thread's capture (its backend has begun capturing).
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

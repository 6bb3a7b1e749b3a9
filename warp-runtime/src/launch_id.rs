//! Launch identities: every kernel launch (and every parallel primitive) gets the next number
//! of one process-wide counter, so that a fault can name the launch that raised it, not only
//! the kernel (a kernel launched a thousand times a frame faults in one of them).

use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};
pub use warp_core::LaunchId;

/// The next number to hand out (launch numbers start at 1: 0 means "none" in fault records).
static NEXT: AtomicU64 = AtomicU64::new(1);

thread_local! {
    /// The number of the calling thread's latest launch (0 before its first).
    static LAST: Cell<u64> = const { Cell::new(0) };
}

/// Numbers a new launch made by the calling thread.
#[inline]
pub(crate) fn next() -> LaunchId {
    // Relaxed: the numbers only need to be distinct and to grow; nothing is published through
    // them.
    let id = NEXT.fetch_add(1, Ordering::Relaxed);
    LAST.with(|l| l.set(id));
    LaunchId(id)
}

/// The number of the calling thread's latest kernel launch (forward or backward, on any
/// device) or GPU primitive, or `None` before its first: the number a
/// [`Fault`](warp_core::Fault) names as its `launch` when that launch faults. Log it beside a
/// launch to find the one that faulted.
pub fn last_launch_id() -> Option<LaunchId> {
    match LAST.with(Cell::get) {
        0 => None,
        id => Some(LaunchId(id)),
    }
}

//! The write-race check of CPU launches (`config::set_race_check`): which kernel thread wrote
//! each array element during one launch, so that a second thread writing it is a fault.
//!
//! A launch with the check on builds a [`WriteLog`] before its views: every `ArrayView` made
//! while the log is installed (`warp_core::view::with_write_log`) registers the bytes it can
//! reach, and the log's [`seal`](WriteLog::seal) merges overlapping spans into regions and
//! gives each region a shadow table: one `AtomicUsize` per granule (the largest size that
//! divides every element's size and offset in the region, so elements of different arrays
//! that overlap share granules), holding `1 + ` the flat index of the thread that wrote it,
//! or 0. A store claims its granules with a compare-exchange before it writes; finding
//! another thread's index there is the race, reported before the second write happens.
//!
//! Merging by address, not by argument, is what makes the check see two arguments that are
//! views of one array (`a` and `a.row(0)`, an array passed twice, a reinterpreted view): their
//! elements are the same memory. The shadows come from `alloc_zeroed` (`HostBuffer`), so an
//! array that is only read costs address space, not touched pages.
//!
//! The executor runs a checked launch one thread per call ([`each_thread`]), with the log and
//! the kernel thread's index installed on the OS thread that runs it
//! (`warp_core::view::with_write_log`): that is how a store knows where to log and who
//! writes. Nothing here runs unless the check is on for the launch.

use super::memory::HostBuffer;
use crate::error::Result;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, OnceLock, PoisonError};
use warp_core::view::with_write_log;
use warp_core::KResult;

/// Runs the kernel threads `range` one at a time through `run`, each with `log` installed as
/// its write log; stops at the first fault.
pub(crate) fn each_thread<F>(
    log: &WriteLog,
    range: std::ops::Range<usize>,
    mut run: F,
) -> KResult<()>
where
    F: FnMut(std::ops::Range<usize>) -> KResult<()>,
{
    for t in range {
        // SAFETY: the views the launch registered with `log` live in the launch's frame,
        // which `log` outlives (`Cpu::launch_race_checked`).
        unsafe { with_write_log(log, t, || run(t..t + 1))? };
    }
    Ok(())
}

/// What one view can reach: bytes `lo..hi`, elements of `elem` bytes starting at `base`
/// with byte strides `strides` (dimensions of one element or none left out).
struct Span {
    lo: usize,
    hi: usize,
    base: usize,
    elem: usize,
    strides: Vec<usize>,
}

/// Overlapping spans merged: bytes `lo..hi`, tracked in granules of `granule` bytes.
struct Region {
    lo: usize,
    hi: usize,
    granule: usize,
    /// `(hi - lo) / granule` zeroed `AtomicUsize`s.
    shadow: HostBuffer,
}

impl Region {
    /// The shadow entry of granule `k` (`k < (hi - lo) / granule`).
    fn slot(&self, k: usize) -> &AtomicUsize {
        debug_assert!(k < (self.hi - self.lo) / self.granule);
        // SAFETY: the shadow holds `(hi - lo) / granule` zero-initialised (valid) usizes,
        // aligned (host buffers are 64-byte aligned), accessed only atomically while the
        // region lives, and `k` is in range (the caller's address is inside the region).
        unsafe { AtomicUsize::from_ptr(self.shadow.ptr().cast::<usize>().add(k)) }
    }
}

/// The write log of one checked launch (see the module docs).
pub(crate) struct WriteLog {
    /// Views registered while the launch's views are made.
    spans: Mutex<Vec<Span>>,
    /// Set by `seal`, sorted by address, disjoint.
    regions: OnceLock<Vec<Region>>,
}

impl WriteLog {
    /// An empty log.
    pub(crate) fn new() -> Self {
        WriteLog {
            spans: Mutex::new(Vec::new()),
            regions: OnceLock::new(),
        }
    }

    /// Merges the registered spans into regions and allocates their shadows: after this, and
    /// before the launch runs, no view registers any more.
    ///
    /// # Errors
    /// [`Error::OutOfMemory`](crate::Error::OutOfMemory) when a shadow cannot be allocated
    /// (eight bytes per granule of every array of the launch).
    pub(crate) fn seal(&self) -> Result<()> {
        let mut spans =
            std::mem::take(&mut *self.spans.lock().unwrap_or_else(PoisonError::into_inner));
        spans.sort_by_key(|s| s.lo);
        let mut regions: Vec<Region> = Vec::new();
        let mut i = 0;
        while i < spans.len() {
            // The spans overlapping this one, transitively.
            let (lo, mut hi, mut j) = (spans[i].lo, spans[i].hi, i + 1);
            while j < spans.len() && spans[j].lo < hi {
                hi = hi.max(spans[j].hi);
                j += 1;
            }
            // Every element start is `base + sum(i_d * stride_d)`: a granule that divides
            // each span's `base - lo`, strides and element size divides every element's
            // offset and size in the region.
            let mut g = 0;
            for s in &spans[i..j] {
                g = gcd(g, s.base - lo);
                g = gcd(g, s.elem);
                for &st in &s.strides {
                    g = gcd(g, st);
                }
            }
            let slots = (hi - lo) / g;
            let bytes = slots
                .checked_mul(std::mem::size_of::<usize>())
                .ok_or_else(|| crate::Error::out_of_memory("cpu", usize::MAX))?;
            regions.push(Region {
                lo,
                hi,
                granule: g,
                shadow: HostBuffer::zeroed(bytes, std::mem::align_of::<usize>())?,
            });
            i = j;
        }
        // A log is sealed once, by the launch that made it.
        let _ = self.regions.set(regions);
        Ok(())
    }
}

/// Greatest common divisor (`gcd(0, x) = x`).
fn gcd(mut a: usize, mut b: usize) -> usize {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

impl warp_core::view::WriteLog for WriteLog {
    fn register(&self, base: usize, elem: usize, shape: &[usize], strides: &[isize]) {
        if elem == 0 || shape.contains(&0) {
            // Nothing to write.
            return;
        }
        // The lowest and highest element starts, and the byte strides that matter (a
        // dimension of extent one never moves).
        let (mut lo, mut hi) = (base, base);
        let mut steps = Vec::with_capacity(strides.len());
        for (&n, &s) in shape.iter().zip(strides) {
            if n <= 1 {
                continue;
            }
            let reach = (n - 1) * s.unsigned_abs() * elem;
            if s < 0 {
                lo -= reach;
            } else {
                hi += reach;
            }
            steps.push(s.unsigned_abs() * elem);
        }
        self.spans
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(Span {
                lo,
                hi: hi + elem,
                base,
                elem,
                strides: steps,
            });
    }

    fn record(&self, addr: usize, bytes: usize, me: usize) -> std::result::Result<(), usize> {
        let Some(regions) = self.regions.get() else {
            // Unreachable: launches seal before they run.
            return Ok(());
        };
        let k = regions.partition_point(|r| r.lo <= addr);
        let Some(r) = k.checked_sub(1).map(|k| &regions[k]) else {
            return Ok(());
        };
        if addr + bytes > r.hi || bytes == 0 {
            // Not memory a registered view reaches: unreachable for views of the launch.
            return Ok(());
        }
        let first = (addr - r.lo) / r.granule;
        for k in first..first + bytes / r.granule {
            // Relaxed is enough: the question is only which thread got to each granule
            // first, and a compare-exchange on one location answers it.
            match r
                .slot(k)
                .compare_exchange(0, me + 1, Ordering::Relaxed, Ordering::Relaxed)
            {
                Ok(_) => {}
                Err(v) if v == me + 1 => {}
                Err(v) => return Err(v - 1),
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use warp_core::view::WriteLog as _;

    // Addresses only: the log never touches the memory it tracks.
    const B: usize = 0x10_000;

    #[test]
    fn overlapping_views_share_granules() {
        let log = WriteLog::new();
        // Four f32 at B, and bytes B+1..B+3 as u8 (a reinterpreted view): one region of
        // 1-byte granules. An unrelated i64 array far away: its own region of 8-byte ones.
        log.register(B, 4, &[4], &[1]);
        log.register(B + 1, 1, &[2], &[1]);
        log.register(B + 0x1000, 8, &[3], &[1]);
        log.seal().unwrap();
        let regions = log.regions.get().unwrap();
        assert_eq!(regions.len(), 2);
        assert_eq!(
            (regions[0].lo, regions[0].hi, regions[0].granule),
            (B, B + 16, 1)
        );
        assert_eq!((regions[1].granule, regions[1].hi - regions[1].lo), (8, 24));
        // Thread 1 writes f32 element 1 (bytes 4..8) twice; thread 2 its u8 at byte 5.
        assert_eq!(log.record(B + 4, 4, 1), Ok(()));
        assert_eq!(log.record(B + 4, 4, 1), Ok(()));
        assert_eq!(log.record(B + 5, 1, 2), Err(1));
        // The u8 at byte 1 overlaps f32 element 0, which nobody wrote.
        assert_eq!(log.record(B + 1, 1, 2), Ok(()));
        assert_eq!(log.record(B, 4, 3), Err(2));
        assert_eq!(log.record(B + 0x1008, 8, 4), Ok(()));
        assert_eq!(log.record(B + 0x1008, 8, 5), Err(4));
        assert_eq!(log.record(B + 0x1010, 8, 5), Ok(()));
    }

    #[test]
    fn negative_zero_and_unit_strides() {
        let log = WriteLog::new();
        // Reversed: element k at B - 8k. Broadcast: all five indices are one element.
        // A column of a 3x2 f32 array: shape [3, 1], strides [2, 1] (extent 1 never moves).
        // An empty view registers nothing.
        log.register(B, 8, &[4], &[-1]);
        log.register(B + 0x100, 4, &[5], &[0]);
        log.register(B + 0x200, 4, &[3, 1], &[2, 1]);
        log.register(B + 0x300, 4, &[0], &[1]);
        log.seal().unwrap();
        let regions = log.regions.get().unwrap();
        let spans: Vec<_> = regions.iter().map(|r| (r.lo, r.hi, r.granule)).collect();
        assert_eq!(
            spans,
            [
                (B - 24, B + 8, 8),
                (B + 0x100, B + 0x104, 4),
                (B + 0x200, B + 0x214, 4)
            ]
        );
        assert_eq!(log.record(B - 24, 8, 0), Ok(()));
        assert_eq!(log.record(B - 24, 8, 7), Err(0));
        assert_eq!(log.record(B + 0x100, 4, 3), Ok(()));
        assert_eq!(log.record(B + 0x100, 4, 9), Err(3));
        assert_eq!(log.record(B + 0x210, 4, 1), Ok(()));
    }

    #[test]
    fn gcd_basics() {
        assert_eq!(gcd(0, 12), 12);
        assert_eq!(gcd(12, 0), 12);
        assert_eq!(gcd(12, 18), 6);
        assert_eq!(gcd(7, 1), 1);
    }
}

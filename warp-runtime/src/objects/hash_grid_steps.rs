//! The hash grid build's data-parallel steps ([`ObjectStep`]s): each a `#[repr(C)]` record
//! laid out as the C++ struct its kernel in `wp_hash_grid.h` takes, and the same step on the
//! CPU with rayon. `hash_grid.rs` orders them around the primitives' radix sort.

use crate::backend::{ObjectLibrary, ObjectStep, StepFault};
use crate::error::Result;
use crate::kernel::KernelInfo;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicI32, Ordering};
use warp_core::objects::hash_grid::point_bucket;

/// The hash grid's build library: `wp_hash_grid.h` with its kernels enabled.
pub(crate) static LIBRARY: ObjectLibrary = ObjectLibrary::of("hash_grid");

/// Each point's bucket and index: for each of the `n` points (contiguous `Vec3`s at `points`),
/// its bucket (`warp_core::objects::hash_grid::point_bucket`, the CUDA library's
/// `hash_grid_build_key`) into the `i32` at `keys[i]` and `i` into `values[i]`; the smallest
/// index of a point with a NaN or infinite coordinate into the `i32` at `bad` (atomically
/// lowered; left alone when every point is finite). `wp::hash_grid_keys_t` in C++ (56 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct HashGridKeys {
    pub points: u64,
    pub n: u64,
    pub dims: [i32; 3],
    pub inv: f32,
    pub keys: u64,
    pub values: u64,
    pub bad: u64,
}

const _: () = assert!(std::mem::size_of::<HashGridKeys>() == 56);

/// Bucket ranges from sorted keys: from the `n` sorted `i32` keys at `keys`, each named
/// bucket's range `[start, end)` in sorted order into the `i32`s at `starts` and `ends`
/// (`buckets` each; a bucket no key names is left alone, so the caller zeroed them). With
/// `clear` (nonzero), zeros instead of positions: the same writes, undoing a build from its
/// keys (cheaper than zeroing every bucket when the points are few). Keys outside
/// `0..buckets` are skipped. With `bad` (nonzero: the keys step's word; every build but the
/// clearing step passes it, since a build reads nothing back), the step also resets that
/// word to `i32::MAX` and reports the point it names (of the `points`) as a fault (`fault`;
/// on the CPU as the build's error). `wp::hash_grid_ranges_t` in C++ (96 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct HashGridRanges {
    pub keys: u64,
    pub starts: u64,
    pub ends: u64,
    pub n: i32,
    pub buckets: i32,
    pub clear: i32,
    pub pad: i32,
    pub bad: u64,
    pub points: u64,
    pub fault: StepFault,
}

const _: () = assert!(std::mem::size_of::<HashGridRanges>() == 96);

/// What a recorded build's report names its fault by (argument 0: the points).
pub(crate) static BUILD_NAMES: KernelInfo = KernelInfo {
    name: "HashGrid::build",
    module: "warp_lang::objects",
    params: &["points"],
    ..KernelInfo::BLANK
};

/// A pointer that rayon tasks may share, for writes to elements no two tasks share.
#[derive(Clone, Copy)]
struct Shared(*mut i32);
// SAFETY: every use writes elements that no other task touches (see the callers).
unsafe impl Send for Shared {}
unsafe impl Sync for Shared {}

impl Shared {
    /// Element `i` (a method, so that closures capture the `Shared`, not its raw pointer).
    fn at(self, i: usize) -> *mut i32 {
        self.0.wrapping_add(i)
    }
}

// SAFETY: `#[repr(C)]`, the layout of `wp::hash_grid_keys_t` (both sides assert 56 bytes);
// the build passes addresses of its own buffers, sized for `n` (see `hash_grid.rs`).
unsafe impl ObjectStep for HashGridKeys {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_hash_grid_keys";

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.len();
        if n == 0 {
            return Ok(());
        }
        // SAFETY: the build passes contiguous host arrays of at least `n` points, keys and
        // values (keys and values distinct allocations), and a 1-element i32 array at `bad`;
        // nothing else touches them during the build (it holds the grid mutably).
        let (points, keys, values) = unsafe {
            (
                std::slice::from_raw_parts(self.points as *const Vec3, n),
                std::slice::from_raw_parts_mut(self.keys as *mut i32, n),
                std::slice::from_raw_parts_mut(self.values as *mut i32, n),
            )
        };
        // SAFETY: as above; an i32 is aligned and sized as an AtomicI32.
        let bad = unsafe { &*(self.bad as *const AtomicI32) };
        let (dims, inv) = (self.dims, self.inv);
        keys.par_iter_mut()
            .zip(values.par_iter_mut())
            .enumerate()
            .with_min_len(4096)
            .for_each(|(i, (k, v))| {
                let p = points[i];
                if !p.is_finite() {
                    bad.fetch_min(i as i32, Ordering::Relaxed);
                }
                *k = point_bucket(dims, inv, p);
                *v = i as i32;
            });
        Ok(())
    }
}

// SAFETY: `#[repr(C)]`, the layout of `wp::hash_grid_ranges_t` (both sides assert 96 bytes);
// the build passes addresses of its own buffers: `n` keys, `buckets` starts and ends.
unsafe impl ObjectStep for HashGridRanges {
    const LIBRARY: &'static ObjectLibrary = &LIBRARY;
    const KERNEL: &'static str = "wp_hash_grid_ranges";

    fn len(&self) -> usize {
        self.n.max(0) as usize
    }

    fn run_cpu(&self) -> Result<()> {
        self.ranges_on_cpu();
        if self.bad == 0 {
            return Ok(());
        }
        // The kernel's report. SAFETY: the build's one-element i32 array (sized and aligned as
        // an AtomicI32), and its points, which hold the index the keys step recorded.
        let i = unsafe { &*(self.bad as *const AtomicI32) }.swap(i32::MAX, Ordering::Relaxed);
        if i == i32::MAX {
            return Ok(());
        }
        let p = unsafe { *(self.points as *const Vec3).add(i as usize) };
        Err(crate::error::Error::InvalidArgument {
            what: format!(
                "{}: argument `points` has a non-finite point at index {i}: {p:?}",
                BUILD_NAMES.name
            ),
        })
    }

    fn fault_slot(&mut self) -> Option<&mut StepFault> {
        (self.bad != 0).then_some(&mut self.fault)
    }
}

impl HashGridRanges {
    /// The ranges on the CPU (the step without its report).
    fn ranges_on_cpu(&self) {
        let n = self.len();
        if n == 0 {
            return;
        }
        // SAFETY: `n` sorted keys in a host array the build owns.
        let keys = unsafe { std::slice::from_raw_parts(self.keys as *const i32, n) };
        let (starts, ends) = (
            Shared(self.starts as *mut i32),
            Shared(self.ends as *mut i32),
        );
        let (buckets, clear) = (self.buckets, self.clear != 0);
        (0..n).into_par_iter().with_min_len(4096).for_each(|k| {
            let b = keys[k];
            // Keys are buckets by construction; one out of range is skipped, never written.
            if b < 0 || b >= buckets {
                return;
            }
            // SAFETY: `starts` and `ends` hold `buckets` i32s; a bucket's start is written
            // only by the first position of its run of keys, its end only by the last, so no
            // two tasks write one element.
            unsafe {
                if k == 0 || keys[k - 1] != b {
                    let v = if clear { 0 } else { k as i32 };
                    starts.at(b as usize).write(v);
                }
                if k + 1 == n || keys[k + 1] != b {
                    let v = if clear { 0 } else { k as i32 + 1 };
                    ends.at(b as usize).write(v);
                }
            }
        });
    }
}

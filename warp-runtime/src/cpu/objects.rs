//! The per-element steps of host objects' builds on the CPU, with rayon: the hash grid's keys
//! (each point's bucket and index) and bucket ranges (from the sorted keys). The build itself
//! (`objects/hash_grid.rs`) orders them around the primitives' radix sort; CUDA runs the same
//! steps as kernels of `wp_hash_grid.h`.

use crate::backend::{HashGridKeys, HashGridRanges};
use crate::error::Result;
use glam::Vec3;
use rayon::prelude::*;
use std::sync::atomic::{AtomicI32, Ordering};
use warp_core::objects::hash_grid::point_bucket;

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

/// [`Backend::hash_grid_keys`](crate::backend::Backend::hash_grid_keys) on the CPU.
pub(super) fn hash_grid_keys(s: &HashGridKeys) -> Result<()> {
    if s.n == 0 {
        return Ok(());
    }
    // SAFETY: the build passes contiguous host arrays of at least `n` points, keys and values
    // (keys and values distinct allocations), and a 1-element i32 array at `bad`; nothing else
    // touches them during the build (it holds the grid mutably).
    let (points, keys, values) = unsafe {
        (
            std::slice::from_raw_parts(s.points as *const Vec3, s.n),
            std::slice::from_raw_parts_mut(s.keys as *mut i32, s.n),
            std::slice::from_raw_parts_mut(s.values as *mut i32, s.n),
        )
    };
    // SAFETY: as above; an i32 is aligned and sized as an AtomicI32.
    let bad = unsafe { &*(s.bad as *const AtomicI32) };
    keys.par_iter_mut()
        .zip(values.par_iter_mut())
        .enumerate()
        .for_each(|(i, (k, v))| {
            let p = points[i];
            if !p.is_finite() {
                bad.fetch_min(i as i32, Ordering::Relaxed);
            }
            *k = point_bucket(s.dims, s.inv, p);
            *v = i as i32;
        });
    Ok(())
}

/// [`Backend::hash_grid_ranges`](crate::backend::Backend::hash_grid_ranges) on the CPU.
pub(super) fn hash_grid_ranges(s: &HashGridRanges) -> Result<()> {
    let n = s.n;
    if n == 0 {
        return Ok(());
    }
    // SAFETY: `n` sorted keys in a host array the build owns.
    let keys = unsafe { std::slice::from_raw_parts(s.keys as *const i32, n) };
    let (starts, ends) = (Shared(s.starts as *mut i32), Shared(s.ends as *mut i32));
    let (buckets, clear) = (s.buckets, s.clear);
    (0..n).into_par_iter().with_min_len(4096).for_each(|k| {
        let b = keys[k];
        // Keys are buckets by construction; one out of range is skipped, never written.
        if b < 0 || b as usize >= buckets {
            return;
        }
        // SAFETY: `starts` and `ends` hold `buckets` i32s; a bucket's start is written only by
        // the first position of its run of keys, its end only by the last, so no two tasks
        // write one element.
        unsafe {
            if k == 0 || keys[k - 1] != b {
                starts
                    .at(b as usize)
                    .write(if clear { 0 } else { k as i32 });
            }
            if k + 1 == n || keys[k + 1] != b {
                ends.at(b as usize)
                    .write(if clear { 0 } else { k as i32 + 1 });
            }
        }
    });
    Ok(())
}

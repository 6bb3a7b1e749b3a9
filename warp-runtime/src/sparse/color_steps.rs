//! The graph colouring's steps ([`ObjectStep`]s of the `sparse_color` build library,
//! `wp_sparse_color.h`): each a `#[repr(C)]` record laid out as its C++ struct (both sides
//! assert the size; a unit test compares every field's offset), with the same step on the CPU.
//! `color.rs` orders them around the primitives and the triplet pipeline of `mod.rs`.
//!
//! Every step is integer work whose result does not depend on how its threads are scheduled
//! (a colouring round reads the previous round's colours and writes a new array; the only
//! shared word, the round's flag, is written with one value per round), so the CPU at any
//! thread count and a GPU give the same colours.

use super::ops_steps::nnz_of;
use super::steps::{slice, Ptr};
use crate::backend::{ObjectLibrary, ObjectStep, StepFault};
use crate::error::{Error, Result};
use rayon::prelude::*;
use warp_core::{Fault, FaultKind};

/// The colouring's build library: `wp_sparse_color.h` with its kernels enabled.
pub(crate) static COLOR_LIBRARY: ObjectLibrary = ObjectLibrary::of("sparse_color");

/// The priority hash (`sp_color_hash`, Chris Wellons' `lowbias32`).
pub(crate) fn hash32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Whether vertex `a`'s priority `(hash32(a ^ seed), a)` is above `b`'s (`sp_color_beats`).
fn beats(a: i32, b: i32, seed: u32) -> bool {
    let (ha, hb) = (hash32(a as u32 ^ seed), hash32(b as u32 ^ seed));
    (ha, a) > (hb, b)
}

/// Row `r`'s range of a pattern, clamped into `0..nnz` (`sp_ops_row`).
fn row(offsets: &[i32], r: usize, nnz: usize) -> std::ops::Range<usize> {
    let lo = (offsets[r].max(0) as usize).min(nnz);
    let hi = (offsets[r + 1].max(0) as usize).clamp(lo, nnz);
    lo..hi
}

// ------------------------------------------------------------------------------------------
// Adjacency
// ------------------------------------------------------------------------------------------

/// Each edge's two directed triplets, or a constraint's two particle-constraint triplets, and
/// their keep flags (`sp_color_split_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Split {
    pub edges: u64,
    pub rows: u64,
    pub cols: u64,
    pub flags: u64,
    pub bad: u64,
    pub m: i32,
    pub n: i32,
    pub incidence: i32,
    pub pad: i32,
}
const _: () = assert!(std::mem::size_of::<Split>() == 56);

// SAFETY: `#[repr(C)]`, the layout of `sp_color_split_t`; `color.rs` passes m edges (2 m
// i32s), triplet and flag arrays of 2 m i32s and a 1-element i32 array at `bad`.
unsafe impl ObjectStep for Split {
    const LIBRARY: &'static ObjectLibrary = &COLOR_LIBRARY;
    const KERNEL: &'static str = "wp_sparse_color_split";

    fn len(&self) -> usize {
        self.m as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let m = self.m as usize;
        // SAFETY: see the impl.
        let edges = unsafe { slice::<i32>(self.edges, 2 * m) };
        let (rows, cols, flags) = (
            Ptr(self.rows as *mut i32),
            Ptr(self.cols as *mut i32),
            Ptr(self.flags as *mut i32),
        );
        let (n, incidence) = (self.n, self.incidence != 0);
        let bad = (0..m)
            .into_par_iter()
            .with_min_len(4096)
            .map(|e| {
                let (u, v) = (edges[2 * e], edges[2 * e + 1]);
                let ok = (0..n).contains(&u) && (0..n).contains(&v);
                let (ca, cb, keep) = if incidence {
                    (e as i32, e as i32, ok)
                } else {
                    (v, u, ok && u != v)
                };
                // SAFETY: each task writes its own two triplets 2e, 2e + 1.
                unsafe {
                    rows.at(2 * e).write(u);
                    rows.at(2 * e + 1).write(v);
                    cols.at(2 * e).write(ca);
                    cols.at(2 * e + 1).write(cb);
                    flags.at(2 * e).write(keep as i32);
                    flags.at(2 * e + 1).write(keep as i32);
                }
                if ok {
                    i32::MAX
                } else {
                    e as i32
                }
            })
            .min()
            .unwrap_or(i32::MAX);
        // SAFETY: the 1-element array at `bad`, which nothing else touches now.
        unsafe {
            let p = self.bad as *mut i32;
            *p = (*p).min(bad);
        }
        Ok(())
    }
}

/// The split's report (`sp_color_report_t`): one thread raises the smallest bad edge.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Report {
    pub edges: u64,
    pub bad: u64,
    pub m: i32,
    pub n: i32,
    pub fault: StepFault,
}
const _: () = assert!(std::mem::size_of::<Report>() == 64);

// SAFETY: `#[repr(C)]`, the layout of `sp_color_report_t`; the addresses are Split's.
unsafe impl ObjectStep for Report {
    const LIBRARY: &'static ObjectLibrary = &COLOR_LIBRARY;
    const KERNEL: &'static str = "wp_sparse_color_report";

    fn len(&self) -> usize {
        1
    }

    fn run_cpu(&self) -> Result<()> {
        // SAFETY: the 1-element array at `bad` and the m edges.
        let (e, edges) = unsafe {
            (
                *(self.bad as *const i32),
                slice::<i32>(self.edges, 2 * self.m as usize),
            )
        };
        if e == i32::MAX {
            return Ok(());
        }
        let (u, v) = (edges[2 * e as usize], edges[2 * e as usize + 1]);
        let bad = if (0..self.n).contains(&u) { v } else { u };
        let names = self.fault.names;
        Err(Error::Fault(Fault {
            kernel: names.name,
            kind: FaultKind::OutOfBounds {
                arg: names.params[0],
                index: vec![e as i128, bad as i128],
                shape: vec![self.m as usize, self.n as usize],
            },
            launch: None,
        }))
    }

    fn fault_slot(&mut self) -> Option<&mut StepFault> {
        Some(&mut self.fault)
    }
}

/// The ordered pairs of constraints sharing a particle (`sp_color_pairs_t`): `COUNT` the
/// count per particle, else the pairs themselves.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pairs<const COUNT: bool> {
    pub offsets: u64,
    pub columns: u64,
    pub starts: u64,
    pub rows: u64,
    pub cols: u64,
    pub limit: i64,
    pub n: i32,
    pub cap: i32,
}
const _: () = assert!(std::mem::size_of::<Pairs<true>>() == 56);

impl<const A: bool> Pairs<A> {
    /// The same record as the other step (count or expand).
    pub(crate) fn step<const B: bool>(self) -> Pairs<B> {
        let Pairs {
            offsets,
            columns,
            starts,
            rows,
            cols,
            limit,
            n,
            cap,
        } = self;
        Pairs {
            offsets,
            columns,
            starts,
            rows,
            cols,
            limit,
            n,
            cap,
        }
    }
}

// SAFETY: `#[repr(C)]`, the layout of `sp_color_pairs_t`; an incidence pattern of n rows
// (offsets n + 1, columns cap), starts of n + 1 i64s, `limit` i32s at rows and cols.
unsafe impl<const COUNT: bool> ObjectStep for Pairs<COUNT> {
    const LIBRARY: &'static ObjectLibrary = &COLOR_LIBRARY;
    const KERNEL: &'static str = if COUNT {
        "wp_sparse_color_pair_count"
    } else {
        "wp_sparse_color_pair_expand"
    };

    fn len(&self) -> usize {
        self.n as usize + COUNT as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.n as usize;
        // SAFETY: see the impl.
        let off = unsafe { slice::<i32>(self.offsets, n + 1) };
        let nnz = nnz_of(off, n, self.cap);
        // SAFETY: the first nnz columns (nnz <= cap).
        let cols = unsafe { slice::<i32>(self.columns, nnz) };
        let starts = Ptr(self.starts as *mut i64);
        if COUNT {
            (0..n + 1).into_par_iter().with_min_len(4096).for_each(|r| {
                let k = if r < n {
                    row(off, r, nnz).len() as i64
                } else {
                    0
                };
                // SAFETY: each task writes its own r <= n.
                unsafe { starts.at(r).write(k * (k - 1).max(0)) };
            });
            return Ok(());
        }
        let (rows_out, cols_out, limit) = (
            Ptr(self.rows as *mut i32),
            Ptr(self.cols as *mut i32),
            self.limit,
        );
        (0..n).into_par_iter().with_min_len(256).for_each(|r| {
            let range = row(off, r, nnz);
            // SAFETY: the scan's n + 1 entries, read only.
            let mut pos = unsafe { starts.get(r) };
            for a in range.clone() {
                for b in range.clone() {
                    if a == b {
                        continue;
                    }
                    if (0..limit).contains(&pos) {
                        // SAFETY: each particle's pairs land on its own positions (the scan
                        // of the counts); `limit` bounds them (an overwritten pattern).
                        unsafe {
                            rows_out.at(pos as usize).write(cols[a]);
                            cols_out.at(pos as usize).write(cols[b]);
                        }
                    }
                    pos += 1;
                }
            }
        });
        Ok(())
    }
}

// ------------------------------------------------------------------------------------------
// Colouring
// ------------------------------------------------------------------------------------------

/// One Jones-Plassmann round (`sp_color_round_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Round {
    pub offsets: u64,
    pub columns: u64,
    pub prev: u64,
    pub next: u64,
    pub flag: u64,
    pub n: i32,
    pub cap: i32,
    pub seed: u32,
    /// 1: zero the flag; 0: set it where a vertex stays uncoloured.
    pub clear: i32,
}
const _: () = assert!(std::mem::size_of::<Round>() == 56);

/// Vertex `v`'s colour after a round whose input colours are `prev` (-1: uncoloured): the
/// CPU body of `sp_color_round`, line for line.
fn round_vertex(off: &[i32], cols: &[i32], nnz: usize, prev: &[i32], v: usize, seed: u32) -> i32 {
    if prev[v] >= 0 {
        return prev[v];
    }
    let n = prev.len();
    let neighbours = || {
        cols[row(off, v, nnz)]
            .iter()
            .copied()
            .filter(move |&u| u >= 0 && (u as usize) < n && u as usize != v)
    };
    if neighbours().any(|u| prev[u as usize] < 0 && beats(u, v as i32, seed)) {
        return -1;
    }
    // The smallest colour no neighbour has, 64 colours a window (at most degree + 1 colours,
    // so the windows end).
    let mut base = 0;
    loop {
        let mask = neighbours().fold(0u64, |m, u| {
            let c = prev[u as usize] - base;
            if (0..64).contains(&c) {
                m | 1 << c
            } else {
                m
            }
        });
        if mask != u64::MAX {
            return base + mask.trailing_ones() as i32;
        }
        base += 64;
    }
}

// SAFETY: `#[repr(C)]`, the layout of `sp_color_round_t`; a pattern of n rows (offsets n + 1,
// columns cap), prev and next of n i32s (distinct arrays), a 1-element i32 array at `flag`.
unsafe impl ObjectStep for Round {
    const LIBRARY: &'static ObjectLibrary = &COLOR_LIBRARY;
    const KERNEL: &'static str = "wp_sparse_color_round";

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.n as usize;
        // SAFETY: see the impl.
        let (off, prev) = unsafe {
            (
                slice::<i32>(self.offsets, n + 1),
                slice::<i32>(self.prev, n),
            )
        };
        let nnz = nnz_of(off, n, self.cap);
        // SAFETY: the first nnz columns.
        let cols = unsafe { slice::<i32>(self.columns, nnz) };
        let next = Ptr(self.next as *mut i32);
        let seed = self.seed;
        let left = (0..n)
            .into_par_iter()
            .with_min_len(1024)
            .map(|v| {
                let c = round_vertex(off, cols, nnz, prev, v, seed);
                // SAFETY: each task writes its own v of `next`, which no task reads.
                unsafe { next.at(v).write(c) };
                c < 0
            })
            .reduce(|| false, |a, b| a || b);
        // SAFETY: the 1-element flag, which nothing else touches now.
        unsafe {
            let flag = self.flag as *mut i32;
            if self.clear != 0 {
                *flag = 0;
            } else if left {
                *flag = 1;
            }
        }
        Ok(())
    }
}

/// The colour sort's keys (`KEYS`) or the colours' offsets after it (`sp_color_sort_t`).
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub(crate) struct Sort<const KEYS: bool> {
    pub colors: u64,
    pub keys: u64,
    pub order: u64,
    pub offsets: u64,
    pub n: i32,
    pub ncolors: i32,
}
const _: () = assert!(std::mem::size_of::<Sort<true>>() == 40);

impl<const A: bool> Sort<A> {
    /// The same record as the other step (keys or offsets).
    pub(crate) fn step<const B: bool>(self) -> Sort<B> {
        let Sort {
            colors,
            keys,
            order,
            offsets,
            n,
            ncolors,
        } = self;
        Sort {
            colors,
            keys,
            order,
            offsets,
            n,
            ncolors,
        }
    }
}

// SAFETY: `#[repr(C)]`, the layout of `sp_color_sort_t`; n colours, keys and order, and
// (offsets step) ncolors + 1 offsets.
unsafe impl<const KEYS: bool> ObjectStep for Sort<KEYS> {
    const LIBRARY: &'static ObjectLibrary = &COLOR_LIBRARY;
    const KERNEL: &'static str = if KEYS {
        "wp_sparse_color_keys"
    } else {
        "wp_sparse_color_offsets"
    };

    fn len(&self) -> usize {
        self.n as usize
    }

    fn run_cpu(&self) -> Result<()> {
        let n = self.n as usize;
        if KEYS {
            // SAFETY: see the impl.
            let colors = unsafe { slice::<i32>(self.colors, n) };
            let (keys, order) = (Ptr(self.keys as *mut u32), Ptr(self.order as *mut i32));
            (0..n).into_par_iter().with_min_len(4096).for_each(|v| {
                // SAFETY: each task writes its own v.
                unsafe {
                    keys.at(v).write(colors[v] as u32);
                    order.at(v).write(v as i32);
                }
            });
            return Ok(());
        }
        // SAFETY: see the impl.
        let keys = unsafe { slice::<u32>(self.keys, n) };
        let offsets = Ptr(self.offsets as *mut i32);
        let nc = self.ncolors;
        (0..n).into_par_iter().with_min_len(4096).for_each(|i| {
            let c = keys[i];
            // SAFETY: a run of one colour has one head, so each offset has one writer; the
            // last position alone writes offsets[ncolors].
            unsafe {
                if (i == 0 || keys[i - 1] != c) && c < nc as u32 {
                    offsets.at(c as usize).write(i as i32);
                }
                if i == n - 1 {
                    offsets.at(nc as usize).write(n as i32);
                }
            }
        });
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The hash fixes zero (a multiply-xorshift chain) and the priority order is total.
    #[test]
    fn hash_and_priorities() {
        assert_eq!(hash32(0), 0);
        assert_ne!(hash32(1), hash32(2));
        for (a, b) in [(0, 1), (5, 9), (100, 3)] {
            assert_ne!(beats(a, b, 7), beats(b, a, 7));
        }
    }

    /// A round on a triangle with one vertex coloured: the best-priority uncoloured vertex
    /// takes the smallest free colour, the other waits.
    #[test]
    fn a_round_by_hand() {
        let off = [0, 2, 4, 6];
        let cols = [1, 2, 0, 2, 0, 1];
        let prev = [0, -1, -1];
        let seed = 3;
        let (w, l) = if beats(1, 2, seed) { (1, 2) } else { (2, 1) };
        assert_eq!(round_vertex(&off, &cols, 6, &prev, w, seed), 1);
        assert_eq!(round_vertex(&off, &cols, 6, &prev, l, seed), -1);
        assert_eq!(round_vertex(&off, &cols, 6, &prev, 0, seed), 0);
    }

    /// A vertex whose 70 neighbours hold colours 0..70 but 65 takes 65 (the second window).
    #[test]
    fn the_second_window() {
        let nb: Vec<i32> = (1..=70).collect();
        let mut off = vec![0, 70];
        off.extend(std::iter::repeat_n(70, 70));
        let mut prev = vec![-1];
        prev.extend((0..71).filter(|&c| c != 65));
        assert_eq!(round_vertex(&off, &nb, 70, &prev, 0, 0), 65);
    }

    /// Every kernel name the Rust side launches is a kernel of the compiled `sparse_color`
    /// library (NVRTC, no GPU; skipped, saying so, without libnvrtc).
    #[cfg(feature = "cuda")]
    #[test]
    fn every_color_kernel_name_is_in_the_compiled_library() {
        if let Err(e) = warp_cuda::nvrtc_version() {
            eprintln!("SKIPPED every_color_kernel_name_is_in_the_compiled_library: {e}");
            return;
        }
        let c80 = crate::cuda::objects::compile_library(&COLOR_LIBRARY, 80).unwrap();
        assert!(!c80.log.contains("warning"), "{}", c80.log);
        let c = crate::cuda::objects::compile_library(&COLOR_LIBRARY, 90).unwrap();
        assert!(!c.log.contains("warning"), "{}", c.log);
        let has = |name: &str| {
            let pat = format!("{name}\0");
            c.cubin.windows(pat.len()).any(|w| w == pat.as_bytes())
        };
        for n in [
            Split::KERNEL,
            Report::KERNEL,
            Pairs::<true>::KERNEL,
            Pairs::<false>::KERNEL,
            Round::KERNEL,
            Sort::<true>::KERNEL,
            Sort::<false>::KERNEL,
        ] {
            assert!(has(n), "{n} is not a kernel of the compiled library");
        }
    }

    /// Each record's fields sit at the same offsets in Rust and in C++ (g++'s `offsetof`).
    /// Skipped, saying so, without g++.
    #[test]
    fn color_record_offsets_are_the_headers() {
        let fields = record_layouts![
            Split => "sp_color_split_t" { edges, rows, cols, flags, bad, m, n, incidence, pad },
            Report => "sp_color_report_t" { edges, bad, m, n, fault },
            Pairs<true> => "sp_color_pairs_t" { offsets, columns, starts, rows, cols, limit, n, cap },
            Round => "sp_color_round_t" {
                offsets, columns, prev, next, flag, n, cap, seed, clear
            },
            Sort<true> => "sp_color_sort_t" { colors, keys, order, offsets, n, ncolors },
        ];
        crate::sparse::record_check::check_record_offsets(
            "sparse::color_steps::color_record_offsets_are_the_headers",
            "wp_sparse_color.h",
            &fields,
        );
    }
}

//! The primitives on the CPU, with rayon.
//!
//! Scan, reduction and compaction split the input into chunks of a fixed size ([`CHUNK`]),
//! so that float results depend on the length only, not on the number of threads: a chunk's
//! total is computed in parallel, the totals are scanned serially, then every chunk is
//! finished in parallel from its offset. The radix sort is an LSD sort with 8-bit digits:
//! per pass, per-chunk digit histograms in parallel, their scan (digit-major, so every chunk
//! knows where its elements of each digit go), and a parallel stable scatter; a pass whose
//! digit is the same for every key is skipped.
//!
//! The callers (`primitives/mod.rs`) have checked every argument: arrays on the CPU, contiguous, long
//! enough, and the arrays written overlap nothing they read (except an in-place scan, which
//! is handled as such).

use crate::error::Result;
use crate::primitives::elements::{bad_count, Extent, ScanOps, SortKeyOps, SortValueOps};
use crate::primitives::plan::ReduceOp;
use rayon::prelude::*;

/// Elements per chunk of the chunked algorithms: large enough to amortise a rayon task,
/// small enough to spread 10^6 elements over many cores.
const CHUNK: usize = 1 << 16;

/// The number of elements: a host count, or the device count read now (host memory), checked
/// before anything is written.
fn elements(func: &str, len: Extent) -> Result<usize> {
    match len {
        Extent::Host(n) => Ok(n),
        Extent::Device {
            count,
            capacity,
            limit,
        } => {
            // SAFETY: `count` is the address of a live 1-element i32 array in host memory
            // (checked by `primitives`); no kernel runs on host memory during this call.
            let n = unsafe { (count as *const i32).read() };
            if n < 0 || n as usize > capacity {
                return Err(bad_count(func, n, capacity, limit));
            }
            Ok(n as usize)
        }
    }
}

/// The `n` elements of host memory at `addr`.
///
/// # Safety
/// `addr` is the address of a contiguous array of at least `n` `T`s in host memory, and for as
/// long as the slice lives no other reference to those elements is used to write them (the
/// callers were checked not to overlap arrays read and written; another thread writing the
/// array meanwhile is the race `Array` documents).
unsafe fn slice<'a, T>(addr: u64, n: usize) -> &'a [T] {
    if n == 0 {
        return &[];
    }
    // SAFETY: see above; the address is aligned for T (arrays' elements are).
    unsafe { std::slice::from_raw_parts(addr as *const T, n) }
}

/// [`slice()`], mutable.
///
/// # Safety
/// As [`slice()`], and no other reference to these elements exists while it lives.
unsafe fn slice_mut<'a, T>(addr: u64, n: usize) -> &'a mut [T] {
    if n == 0 {
        return &mut [];
    }
    // SAFETY: as for `slice`; exclusivity is the caller's promise.
    unsafe { std::slice::from_raw_parts_mut(addr as *mut T, n) }
}

// ------------------------------------------------------------------------------------------
// Scan
// ------------------------------------------------------------------------------------------

/// Scans `src` into `dst` from `offset`.
fn scan_serial<T: ScanOps>(src: &[T], dst: &mut [T], mut acc: T, inclusive: bool) {
    for (d, &x) in dst.iter_mut().zip(src) {
        if inclusive {
            acc = acc.add(x);
            *d = acc;
        } else {
            *d = acc;
            acc = acc.add(x);
        }
    }
}

/// Scans `data` in place from `offset`.
fn scan_serial_in_place<T: ScanOps>(data: &mut [T], mut acc: T, inclusive: bool) {
    for d in data.iter_mut() {
        let x = *d;
        if inclusive {
            acc = acc.add(x);
            *d = acc;
        } else {
            *d = acc;
            acc = acc.add(x);
        }
    }
}

fn sum_serial<T: ScanOps>(s: &[T]) -> T {
    fold_lanes(s, T::ZERO, T::add)
}

/// The exclusive scan of the chunks' totals: each chunk's starting offset.
fn chunk_offsets<T: ScanOps>(src: &[T]) -> Vec<T> {
    let totals: Vec<T> = src.par_chunks(CHUNK).map(sum_serial).collect();
    let mut acc = T::ZERO;
    totals
        .into_iter()
        .map(|t| {
            let o = acc;
            acc = acc.add(t);
            o
        })
        .collect()
}

/// `array_scan_n` on the CPU.
pub(super) fn scan<T: ScanOps>(
    func: &str,
    input: u64,
    output: u64,
    len: Extent,
    inclusive: bool,
) -> Result<()> {
    let n = elements(func, len)?;
    if n == 0 {
        return Ok(());
    }
    if input == output {
        // SAFETY: in place: one slice, the only reference to the elements during the scan.
        let data = unsafe { slice_mut::<T>(output, n) };
        let offsets = chunk_offsets(data);
        data.par_chunks_mut(CHUNK)
            .zip(offsets)
            .for_each(|(c, o)| scan_serial_in_place(c, o, inclusive));
        return Ok(());
    }
    // SAFETY: the checks made sure `output` does not overlap `input`.
    let (src, dst) = unsafe { (slice::<T>(input, n), slice_mut::<T>(output, n)) };
    let offsets = chunk_offsets(src);
    dst.par_chunks_mut(CHUNK)
        .zip(src.par_chunks(CHUNK))
        .zip(offsets)
        .for_each(|((d, s), o)| scan_serial(s, d, o, inclusive));
    Ok(())
}

// ------------------------------------------------------------------------------------------
// Reductions
// ------------------------------------------------------------------------------------------

/// The fold of a chunk by `f` from `id`, with 8 independent accumulators combined at the
/// end: the dependency chain of one accumulator (4 cycles per float add) would bound the
/// speed, and 8 lanes let the compiler vectorise. For float sums this is a blocked sum (a
/// fixed order, so still deterministic).
#[inline(always)]
fn fold_lanes<T: ScanOps>(c: &[T], id: T, f: impl Fn(T, T) -> T) -> T {
    let mut lanes = [id; 8];
    let mut blocks = c.chunks_exact(8);
    for b in &mut blocks {
        for (l, &x) in lanes.iter_mut().zip(b) {
            *l = f(*l, x);
        }
    }
    let mut acc = lanes.into_iter().fold(id, &f);
    for &x in blocks.remainder() {
        acc = f(acc, x);
    }
    acc
}

/// The reduction of `values` by `f` from `id`: chunk by chunk in parallel, then the chunks'
/// results in order (so the result depends on the length only).
fn reduce_by<T: ScanOps>(values: &[T], id: T, f: impl Fn(T, T) -> T + Sync + Copy) -> T {
    let partials: Vec<T> = values
        .par_chunks(CHUNK)
        .map(|c| fold_lanes(c, id, f))
        .collect();
    partials.into_iter().fold(id, f)
}

/// The reduction of `values` by `op`.
fn reduce_slice<T: ScanOps>(values: &[T], op: ReduceOp) -> T {
    // One monomorphic loop per operator: `T::add` and friends inline into the folds.
    match op {
        ReduceOp::Sum => reduce_by(values, T::ZERO, T::add),
        ReduceOp::Min => reduce_by(values, T::MIN_IDENTITY, T::min_of),
        ReduceOp::Max => reduce_by(values, T::MAX_IDENTITY, T::max_of),
    }
}

/// `array_sum_n` and friends on the CPU.
pub(super) fn reduce<T: ScanOps>(
    func: &str,
    input: u64,
    out: u64,
    len: Extent,
    op: ReduceOp,
) -> Result<()> {
    let n = elements(func, len)?;
    // SAFETY: `out` does not overlap `input` (checked); it is written after the read.
    let r = reduce_slice(unsafe { slice::<T>(input, n) }, op);
    let out = unsafe { slice_mut::<T>(out, 1) };
    out[0] = r;
    Ok(())
}

// ------------------------------------------------------------------------------------------
// Radix sort
// ------------------------------------------------------------------------------------------

/// The most bits per CPU radix pass: 2048 counters per chunk (8 KiB) still fit in L1, and
/// fewer passes mean fewer trips through memory (a 21-bit hash grid key sorts in two passes
/// instead of three).
const CPU_RADIX_MAX_BITS: u32 = 11;

/// The CPU passes of a `bits`-bit sort: as few as [`CPU_RADIX_MAX_BITS`] allows, their digits
/// as even as possible (21 bits: 11 + 10).
fn cpu_radix_passes(bits: u32) -> Vec<(u32, u32)> {
    let passes = bits.div_ceil(CPU_RADIX_MAX_BITS).max(1);
    crate::primitives::plan::radix_passes(bits, bits.div_ceil(passes).max(1))
}

/// The sort's ping-pong buffers, kept between sorts (a sort of n pairs would otherwise
/// allocate, and fault in, 8n fresh bytes every call). A sort takes them out of the lock, so
/// concurrent sorts never wait: the second one allocates its own.
static SORT_SCRATCH: std::sync::Mutex<(Vec<u32>, Vec<u32>)> =
    std::sync::Mutex::new((Vec::new(), Vec::new()));

/// A pointer that rayon tasks may share: each task writes a disjoint set of its elements.
#[derive(Clone, Copy)]
struct SharedPtr(*mut u32);
// SAFETY: only used for writes to disjoint positions, computed from the histogram scan.
unsafe impl Send for SharedPtr {}
unsafe impl Sync for SharedPtr {}

/// One stable counting-sort pass of `(src_k, src_v)` into `(dst_k, dst_v)` by the digit
/// `(key >> shift) & mask`. Returns false (and writes nothing) when every key has the same
/// digit, so that the pass can be skipped.
fn radix_pass(
    src_k: &[u32],
    src_v: &[u32],
    dst_k: &mut [u32],
    dst_v: &mut [u32],
    shift: u32,
    mask: u32,
    chunk: usize,
) -> bool {
    let n = src_k.len();
    let digit = |k: u32| ((k >> shift) & mask) as usize;
    let radix = mask as usize + 1;
    let hists: Vec<Vec<u32>> = src_k
        .par_chunks(chunk)
        .map(|c| {
            let mut h = vec![0u32; radix];
            for &k in c {
                h[digit(k)] += 1;
            }
            h
        })
        .collect();
    let mut totals = vec![0usize; radix];
    for h in &hists {
        for (t, &c) in totals.iter_mut().zip(h) {
            *t += c as usize;
        }
    }
    if totals.contains(&n) {
        return false;
    }
    // Digit-major: all of digit 0 (chunk by chunk, in order), then digit 1, ...
    let mut offsets = vec![vec![0u32; radix]; hists.len()];
    let mut run = 0u32;
    for d in 0..radix {
        for (o, h) in offsets.iter_mut().zip(&hists) {
            o[d] = run;
            run += h[d];
        }
    }
    let (dk, dv) = (SharedPtr(dst_k.as_mut_ptr()), SharedPtr(dst_v.as_mut_ptr()));
    src_k
        .par_chunks(chunk)
        .zip(src_v.par_chunks(chunk))
        .zip(offsets)
        .for_each(|((ck, cv), mut off)| {
            // Bind the wrappers whole (edition 2021 closures would capture the raw fields).
            let (dk, dv) = (dk, dv);
            for (&k, &v) in ck.iter().zip(cv) {
                let slot = &mut off[digit(k)];
                let p = *slot as usize;
                *slot += 1;
                // SAFETY: the positions of all chunks partition 0..n (a histogram scan), and
                // `dst_k`/`dst_v` hold n elements and are not otherwise used meanwhile.
                unsafe {
                    dk.0.add(p).write(k);
                    dv.0.add(p).write(v);
                }
            }
        });
    true
}

/// `radix_sort_pairs` on the CPU: the first pairs by the low `bits` bits of the keys'
/// order-preserving images.
pub(super) fn radix_sort_pairs<K: SortKeyOps, V: SortValueOps>(
    func: &str,
    keys: u64,
    values: u64,
    len: Extent,
    bits: u32,
) -> Result<()> {
    let n = elements(func, len)?;
    if n < 2 {
        return Ok(());
    }
    // SAFETY: keys and values do not overlap (checked); both hold at least n elements.
    let (keys, values) = unsafe { (slice_mut::<K>(keys, n), slice_mut::<V>(values, n)) };
    // Sort the keys' images, in the keys' own memory (K and V are 4-byte Pod types).
    let k0: &mut [u32] = bytemuck::cast_slice_mut(keys);
    let v0: &mut [u32] = bytemuck::cast_slice_mut(values);
    k0.par_iter_mut()
        .for_each(|k| *k = K::to_radix(bytemuck::cast(*k)));
    let (mut k1, mut v1) =
        std::mem::take(&mut *SORT_SCRATCH.lock().unwrap_or_else(|p| p.into_inner()));
    k1.resize(n.max(k1.len()), 0);
    v1.resize(n.max(v1.len()), 0);
    let (ks, vs) = (&mut k1[..n], &mut v1[..n]);
    // About four chunks per thread, of at least 4096 pairs (a 2048-counter histogram each).
    let chunk = n.div_ceil(rayon::current_num_threads() * 4).max(1 << 12);
    // Whether the current data is in (ks, vs) rather than the arrays.
    let mut in_scratch = false;
    for (shift, mask) in cpu_radix_passes(bits) {
        let moved = if in_scratch {
            radix_pass(ks, vs, k0, v0, shift, mask, chunk)
        } else {
            radix_pass(k0, v0, ks, vs, shift, mask, chunk)
        };
        in_scratch ^= moved;
    }
    if in_scratch {
        k0.par_chunks_mut(CHUNK)
            .zip(ks.par_chunks(CHUNK))
            .for_each(|(d, s)| d.copy_from_slice(s));
        v0.par_chunks_mut(CHUNK)
            .zip(vs.par_chunks(CHUNK))
            .for_each(|(d, s)| d.copy_from_slice(s));
    }
    // Kept for the next sort, unless a concurrent sort left larger buffers meanwhile.
    let mut kept = SORT_SCRATCH.lock().unwrap_or_else(|p| p.into_inner());
    if kept.0.len() < k1.len() {
        *kept = (k1, v1);
    }
    k0.par_iter_mut()
        .for_each(|k| *k = bytemuck::cast(K::from_radix(*k)));
    Ok(())
}

// ------------------------------------------------------------------------------------------
// Compaction
// ------------------------------------------------------------------------------------------

/// Copies the kept elements of `values` (nonzero flag) to the front of `out`; returns how
/// many. `out` holds at least `values.len()` elements.
fn compact_slices<T: Copy + Send + Sync>(values: &[T], flags: &[i32], out: &mut [T]) -> usize {
    let counts: Vec<usize> = flags
        .par_chunks(CHUNK)
        .map(|c| c.iter().filter(|&&f| f != 0).count())
        .collect();
    let total: usize = counts.iter().sum();
    // Each chunk gets its own run of the output.
    let mut parts = Vec::with_capacity(counts.len());
    let mut rest = &mut out[..total];
    for &c in &counts {
        let (part, tail) = rest.split_at_mut(c);
        parts.push(part);
        rest = tail;
    }
    parts
        .into_par_iter()
        .zip(values.par_chunks(CHUNK).zip(flags.par_chunks(CHUNK)))
        .for_each(|(dst, (v, f))| {
            let kept = v.iter().zip(f).filter(|(_, &f)| f != 0).map(|(x, _)| *x);
            for (d, x) in dst.iter_mut().zip(kept) {
                *d = x;
            }
        });
    total
}

/// `compact_n` on the CPU: `arrays` are values, flags, out, out_count.
pub(super) fn compact<T: bytemuck::Pod + Send + Sync>(
    func: &str,
    arrays: [u64; 4],
    len: Extent,
) -> Result<()> {
    let n = elements(func, len)?;
    let [values, flags, out, out_count] = arrays;
    // SAFETY: `out` and `out_count` overlap none of the other arrays (checked); every array
    // holds at least n elements (`out_count` one).
    let (v, f, o) = unsafe {
        (
            slice::<T>(values, n),
            slice::<i32>(flags, n),
            slice_mut::<T>(out, n),
        )
    };
    let kept = compact_slices(v, f, o);
    // n <= i32::MAX (checked), so the count fits.
    let out_count = unsafe { slice_mut::<i32>(out_count, 1) };
    out_count[0] = kept as i32;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn radix_pass_is_stable_and_skips_uniform_digits() {
        let k = [0x12u32, 0x01, 0x22, 0x02, 0x11];
        let v = [0u32, 1, 2, 3, 4];
        let (mut dk, mut dv) = ([0u32; 5], [0u32; 5]);
        assert!(radix_pass(&k, &v, &mut dk, &mut dv, 0, 0xf, 2));
        assert_eq!(dk, [0x01, 0x11, 0x12, 0x22, 0x02]);
        assert_eq!(dv, [1, 4, 0, 2, 3]);
        // Digit 8..12 is 0 everywhere: nothing to do.
        assert!(!radix_pass(&k, &v, &mut dk, &mut dv, 8, 0xf, 2));
    }

    #[test]
    fn chunked_scan_matches_serial() {
        let n = 3 * CHUNK + 17;
        let src: Vec<i64> = (0..n as i64).map(|i| (i * 7919) % 1000 - 500).collect();
        let offsets = chunk_offsets(&src);
        let mut dst = vec![0i64; n];
        dst.par_chunks_mut(CHUNK)
            .zip(src.par_chunks(CHUNK))
            .zip(offsets)
            .for_each(|((d, s), o)| scan_serial(s, d, o, true));
        let mut acc = 0;
        for (i, &x) in src.iter().enumerate() {
            acc += x;
            assert_eq!(dst[i], acc);
        }
    }
}

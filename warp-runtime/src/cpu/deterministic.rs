//! Deterministic float accumulation on the CPU (`#[kernel(deterministic)]`,
//! docs/book/src/deterministic.md).
//!
//! In a deterministic kernel the macro emits each float `atomic_add`/`atomic_sub` as [`add`]/
//! [`sub`], and in its adjoint each accumulation into an array's gradient as [`grad_add`]:
//! the thread appends a record (the element's address, the value, how to add it) to the sink
//! of the chunk it runs in, and the element is left alone. After every chunk has run,
//! [`reduce`] puts the chunks' records in launch order (a chunk's records are already in
//! thread order, then program order within a thread), sorts them stably by address, and adds
//! each element's records into it one after the other. So an element ends as
//! `((old + r0) + r1) + ..` with its records in ascending flat thread index and, within a
//! thread, in program order: an order that depends on the launch alone, never on scheduling
//! or on the number of threads. A GPU path must add in the same order with the same additions
//! to give the same bits.
//!
//! The additions are the element type's own atomic ones (`AtomicElement::atomic_add`/
//! `atomic_sub`, `GradElement::grad_add`), applied one record at a time: the same `+` as the
//! ordinary kernel's, and still safe should two records' elements overlap in memory (two views
//! of one array with different element types).
//!
//! The sink is a thread-local installed by [`record_chunk`] around one chunk: kernel code runs
//! a chunk on one OS thread, calling nothing that would run another chunk there.

use std::cell::RefCell;
use std::mem::MaybeUninit;

use rayon::prelude::*;
use warp_core::builtins::AtomicElement;
use warp_core::{ArrayView, Fault, FaultKind, GradElement, GradView, KResult, KernelIndex};

/// Adds the value whose bytes start at the second argument into the element at the first.
type Apply = unsafe fn(usize, *const MaybeUninit<u8>);

/// One recorded accumulation.
#[derive(Clone, Copy)]
struct Record {
    /// The element's address: the records of one element share it, whichever argument or
    /// view they came through.
    addr: usize,
    /// Where the value's bytes start in its chunk's `bytes`.
    at: usize,
    /// Adds the value into the element.
    apply: Apply,
}

/// The records one chunk of a launch made, in thread order and program order within a
/// thread; the values' bytes one after the other.
#[derive(Default)]
pub(crate) struct Chunk {
    records: Vec<Record>,
    bytes: Vec<MaybeUninit<u8>>,
}

/// `T::atomic_add(addr, value)`.
///
/// # Safety
/// `addr` points to a live, aligned `T` accessed only atomically during the call; `value`
/// points to the bytes of a `T`.
unsafe fn apply_add<T: AtomicElement>(addr: usize, value: *const MaybeUninit<u8>) {
    // SAFETY: `record` wrote a `T`'s bytes there.
    let v: T = unsafe { std::ptr::read_unaligned(value.cast::<T>()) };
    // SAFETY: forwarded to the caller.
    unsafe { T::atomic_add(addr as *mut T, v) };
}

/// `T::atomic_sub(addr, value)` (the same IEEE operation as adding `-value`).
///
/// # Safety
/// As [`apply_add`].
unsafe fn apply_sub<T: AtomicElement>(addr: usize, value: *const MaybeUninit<u8>) {
    // SAFETY: as in `apply_add`.
    let v: T = unsafe { std::ptr::read_unaligned(value.cast::<T>()) };
    // SAFETY: forwarded to the caller.
    unsafe { T::atomic_sub(addr as *mut T, v) };
}

/// `T::grad_add(addr, value)`.
///
/// # Safety
/// As [`apply_add`].
unsafe fn apply_grad<T: GradElement>(addr: usize, value: *const MaybeUninit<u8>) {
    // SAFETY: as in `apply_add`.
    let v: T = unsafe { std::ptr::read_unaligned(value.cast::<T>()) };
    // SAFETY: forwarded to the caller.
    unsafe { T::grad_add(addr as *mut T, v) };
}

/// The records of the chunk running on this OS thread.
struct Sink {
    kernel: &'static str,
    limit: u32,
    chunk: Chunk,
    /// The flat index of the thread that recorded last, and how many records it made.
    thread: usize,
    count: u32,
}

thread_local! {
    static SINK: RefCell<Option<Sink>> = const { RefCell::new(None) };
}

/// Records `value` for the element at `p`, made by kernel thread `flat`, to be added by
/// `apply`.
#[inline]
fn record<T: Copy>(p: *mut T, value: T, flat: usize, apply: Apply) -> KResult<()> {
    SINK.with_borrow_mut(|sink| {
        let Some(sink) = sink else {
            // Generated code calls this only inside a deterministic launch's chunk.
            return Err(limit_fault("(outside a deterministic launch)", flat, 0));
        };
        if sink.thread != flat {
            sink.thread = flat;
            sink.count = 0;
        }
        if sink.count == sink.limit {
            return Err(limit_fault(sink.kernel, flat, sink.limit));
        }
        sink.count += 1;
        let bytes = &mut sink.chunk.bytes;
        let at = bytes.len();
        bytes.reserve(size_of::<T>());
        // SAFETY: `reserve` made room for a `T` past `at`; the bytes are `MaybeUninit`, so a
        // user struct's padding is copied without being read as initialised; `apply_*` reads
        // them back as the same `T`.
        unsafe {
            std::ptr::write_unaligned(bytes.as_mut_ptr().add(at).cast::<T>(), value);
            bytes.set_len(at + size_of::<T>());
        }
        sink.chunk.records.push(Record {
            addr: p as usize,
            at,
            apply,
        });
        Ok(())
    })
}

#[cold]
fn limit_fault(kernel: &'static str, thread: usize, limit: u32) -> Box<Fault> {
    Fault::new(kernel, FaultKind::DeterministicRecords { thread, limit })
}

/// `atomic_add(arr, idx, value)` in a deterministic kernel, thread `flat`: the index is
/// checked now, the addition happens after the launch (`reduce`). The old value does not
/// exist (the macro refuses a use of the result, which is `value`).
#[inline]
pub fn add<T: AtomicElement, const N: usize, I: KernelIndex<N>>(
    arr: &ArrayView<T, N>,
    idx: I,
    value: T,
    flat: usize,
) -> KResult<T> {
    record(arr.ptr_at(idx)?, value, flat, apply_add::<T>)?;
    Ok(value)
}

/// `atomic_sub(arr, idx, value)` in a deterministic kernel: as [`add`].
#[inline]
pub fn sub<T: AtomicElement, const N: usize, I: KernelIndex<N>>(
    arr: &ArrayView<T, N>,
    idx: I,
    value: T,
    flat: usize,
) -> KResult<T> {
    record(arr.ptr_at(idx)?, value, flat, apply_sub::<T>)?;
    Ok(value)
}

/// `grad[idx] += value` in a deterministic kernel's adjoint, thread `flat` (what
/// `GradView::accumulate` does in an ordinary one): recorded, added after the launch.
#[inline]
pub fn grad_add<T: GradElement, const N: usize, I: KernelIndex<N>>(
    grad: &GradView<T, N>,
    idx: I,
    value: T,
    flat: usize,
) -> KResult<()> {
    match grad.view() {
        Some(view) => record(view.ptr_at(idx)?, value, flat, apply_grad::<T>),
        None => Ok(()),
    }
}

/// Runs one chunk of a deterministic launch (`run`) with a sink for its records, at most
/// `limit` per kernel thread; returns the chunk's result and its records.
pub(crate) fn record_chunk<R>(
    kernel: &'static str,
    limit: u32,
    run: impl FnOnce() -> R,
) -> (R, Chunk) {
    let fresh = Sink {
        kernel,
        limit,
        chunk: Chunk::default(),
        thread: usize::MAX,
        count: 0,
    };
    // A sink already installed (none is, unless kernel code ran a launch) is put back after.
    let outer = SINK.with_borrow_mut(|s| s.replace(fresh));
    let r = run();
    let sink = SINK.with_borrow_mut(|s| std::mem::replace(s, outer));
    (r, sink.map(|s| s.chunk).unwrap_or_default())
}

/// Adds the records of a launch into their elements: `chunks` are (first thread, records)
/// per chunk, in any order. Each element receives its records in ascending flat thread index,
/// then program order; elements are independent, so they are reduced in parallel.
///
/// # Safety
/// Every record's element is live (the launch's arrays are still borrowed) and accessed by
/// nothing else during the call.
pub(crate) unsafe fn reduce(mut chunks: Vec<(usize, Chunk)>) {
    chunks.sort_unstable_by_key(|c| c.0);
    // (record, its chunk), in launch order.
    let mut order: Vec<(Record, usize)> = chunks
        .iter()
        .enumerate()
        .flat_map(|(k, (_, c))| c.records.iter().map(move |r| (*r, k)))
        .collect();
    // By element, then launch order: a chunk's bytes grow with its records, so (chunk, `at`)
    // is the launch order. The keys are unique, so an unstable sort (faster than a stable
    // one) gives the one order a stable sort by address would.
    order.par_sort_unstable_by_key(|(r, c)| (r.addr, *c, r.at));
    let starts: Vec<usize> = (0..order.len())
        .filter(|&i| i == 0 || order[i - 1].0.addr != order[i].0.addr)
        .collect();
    starts.par_iter().enumerate().for_each(|(k, &s)| {
        let e = starts.get(k + 1).copied().unwrap_or(order.len());
        for (r, c) in &order[s..e] {
            let value = chunks[*c].1.bytes[r.at..].as_ptr();
            // SAFETY: the caller's contract; `value` starts the bytes `record` wrote for this
            // record; the records of one element are applied by this task alone, in order.
            unsafe { (r.apply)(r.addr, value) };
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values whose sum rounds differently in another order.
    const VALUES: [f32; 6] = [1.0e8, 3.0, -1.0e8, 0.75, 2.5e-3, -7.0];

    /// Records `VALUES` as threads `first..` into element 0 (one each) and 1 (every other
    /// thread, a subtraction), as one chunk.
    fn chunk(view: &ArrayView<f32, 1>, first: usize, values: &[f32]) -> (usize, Chunk) {
        let (r, c) = record_chunk("k", 2, || -> KResult<()> {
            for (k, v) in values.iter().enumerate() {
                let t = first + k;
                add(view, 0usize, *v, t)?;
                if t.is_multiple_of(2) {
                    sub(view, 1usize, *v * 0.5, t)?;
                }
            }
            Ok(())
        });
        r.unwrap();
        (first, c)
    }

    /// The chunks arrive in any order; each element receives its records in thread order
    /// from its old value, which a sequential sum on the host reproduces bit for bit.
    #[test]
    fn chunks_in_any_order_reduce_in_launch_order() {
        let mut a = [0.5f32, -2.0];
        // SAFETY: `a` outlives the view and the reduction.
        let view = unsafe { ArrayView::new(a.as_mut_ptr(), [2], [1], "k", "a") };
        let chunks = vec![
            chunk(&view, 4, &VALUES[4..]),
            chunk(&view, 0, &VALUES[..2]),
            chunk(&view, 2, &VALUES[2..4]),
        ];
        // SAFETY: `a` is live and nothing else touches it.
        unsafe { reduce(chunks) };
        let mut want = [0.5f32, -2.0];
        for (t, v) in VALUES.iter().enumerate() {
            want[0] += v;
            if t.is_multiple_of(2) {
                want[1] -= v * 0.5;
            }
        }
        assert_eq!(a.map(f32::to_bits), want.map(f32::to_bits));
        // The values are order-sensitive: reversed, element 0's sum differs.
        let reversed = VALUES.iter().rev().fold(0.5f32, |acc, v| acc + v);
        assert_ne!(reversed.to_bits(), want[0].to_bits());
    }

    /// One record past the limit is a fault naming the thread; outside a deterministic
    /// launch, recording is a fault too, never a silent drop.
    #[test]
    fn the_limit_and_a_missing_sink_are_faults() {
        let mut a = [0.0f32];
        // SAFETY: `a` outlives the view.
        let view = unsafe { ArrayView::new(a.as_mut_ptr(), [1], [1], "k", "a") };
        let (r, c) = record_chunk("k", 2, || -> KResult<()> {
            add(&view, 0usize, 1.0, 7)?;
            add(&view, 0usize, 1.0, 7)?;
            add(&view, 0usize, 1.0, 7)?;
            Ok(())
        });
        assert_eq!(
            r.unwrap_err().kind,
            FaultKind::DeterministicRecords {
                thread: 7,
                limit: 2
            }
        );
        assert_eq!(c.records.len(), 2);
        assert!(add(&view, 0usize, 1.0, 0).is_err());
        assert_eq!(a, [0.0]);
    }
}

//! [`ArrayView`]: what an `Array<T, N>` argument becomes inside a kernel on the CPU.

use crate::fault::{Fault, FaultKind, KResult};
use crate::index::KernelIndex;
use std::cell::Cell;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A strided view of array memory, handed to each kernel thread.
///
/// It is a raw pointer plus shape and strides (in elements), `Copy`, and shared by all threads
/// of a launch. Every access is bounds-checked against the shape and a failed check becomes a
/// [`Fault`] naming the kernel and argument; out-of-bounds memory is never touched.
///
/// Concurrency contract (the same as CUDA's and Warp's): two threads of one launch that write
/// the same element without an atomic race, which is undefined behaviour in Rust's memory
/// model (the value left behind is one of the written values only by luck). Use the
/// `atomic_*` builtins for shared accumulation. During a launch with the runtime's race check
/// on, [`ArrayView::store`] reports such a write as a [`FaultKind::WriteRace`] before it
/// happens (see [`WriteLog`]).
pub struct ArrayView<T, const N: usize> {
    ptr: *mut T,
    shape: [usize; N],
    strides: [isize; N],
    kernel: &'static str,
    arg: &'static str,
}

/// The view's shape, strides, kernel and argument; not its elements (a view can be large, and
/// reading through it here would race with the launch that owns it).
impl<T, const N: usize> std::fmt::Debug for ArrayView<T, N> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ArrayView")
            .field("ptr", &self.ptr)
            .field("shape", &self.shape)
            .field("strides", &self.strides)
            .field("kernel", &self.kernel)
            .field("arg", &self.arg)
            .finish()
    }
}

impl<T, const N: usize> Clone for ArrayView<T, N> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<T, const N: usize> Copy for ArrayView<T, N> {}

// SAFETY: a view is a pointer into an allocation that the runtime keeps alive for the whole
// launch; threads access disjoint elements or use atomics (see the type's docs).
unsafe impl<T: Send, const N: usize> Send for ArrayView<T, N> {}
unsafe impl<T: Sync, const N: usize> Sync for ArrayView<T, N> {}

impl<T: Copy, const N: usize> ArrayView<T, N> {
    /// A view over memory the caller keeps alive and valid for `shape` and `strides`.
    ///
    /// Made inside [`with_write_log`], the view registers the memory it reaches with that log.
    ///
    /// # Safety
    /// Every in-bounds index must address a valid, aligned `T` inside one live allocation
    /// for as long as the view (or a copy of it) is used.
    pub unsafe fn new(
        ptr: *mut T,
        shape: [usize; N],
        strides: [isize; N],
        kernel: &'static str,
        arg: &'static str,
    ) -> Self {
        if logging() {
            if let Some((log, _)) = CURRENT_LOG.with(Cell::get) {
                // SAFETY: `with_write_log` installs a log only while its borrow lasts.
                let log = unsafe { log.as_ref() };
                log.register(ptr as usize, std::mem::size_of::<T>(), &shape, &strides);
            }
        }
        ArrayView {
            ptr,
            shape,
            strides,
            kernel,
            arg,
        }
    }

    /// The shape, one extent per dimension.
    #[inline(always)]
    pub fn shape(&self) -> [usize; N] {
        self.shape
    }

    /// Number of elements.
    ///
    /// Zero when an extent is zero, whatever the others (`[usize::MAX, 2, 0]` is empty, and
    /// its product taken left to right would overflow first); otherwise the product,
    /// saturating at `usize::MAX` (only a view of overlapping elements, with zero strides,
    /// can have more elements than bytes).
    #[inline(always)]
    pub fn len(&self) -> usize {
        if self.shape.contains(&0) {
            return 0;
        }
        self.shape.iter().fold(1usize, |n, &e| n.saturating_mul(e))
    }

    /// True when the view holds no element.
    #[inline(always)]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The element offset of `idx`, or an out-of-bounds fault.
    #[inline(always)]
    fn offset<I: KernelIndex<N>>(&self, idx: I) -> KResult<isize> {
        let u = idx.to_usize();
        let mut off = 0isize;
        for ((&i, &extent), &stride) in u.iter().zip(&self.shape).zip(&self.strides) {
            if i >= extent {
                return Err(self.out_of_bounds(&idx.components()));
            }
            off += i as isize * stride;
        }
        Ok(off)
    }

    #[cold]
    #[inline(never)]
    fn out_of_bounds(&self, c: &[i128; N]) -> Box<Fault> {
        Fault::new(
            self.kernel,
            FaultKind::OutOfBounds {
                arg: self.arg,
                index: c.to_vec(),
                shape: self.shape.to_vec(),
            },
        )
    }

    /// The bounds check of an in-kernel view of this array (`a.view(lo..hi)`): `index` as a
    /// usize when `index < bound` (`<=` when `inclusive`), else an out-of-bounds fault of
    /// this array's parameter showing `index` against the shape `[bound]`.
    #[inline(always)]
    pub fn view_check<I: crate::index::IndexInt>(
        &self,
        index: I,
        bound: usize,
        inclusive: bool,
    ) -> KResult<usize> {
        let u = index.as_usize();
        if u < bound || (inclusive && u == bound) {
            Ok(u)
        } else {
            Err(self.view_out_of_bounds(index.widen(), bound))
        }
    }

    #[cold]
    #[inline(never)]
    fn view_out_of_bounds(&self, index: i128, bound: usize) -> Box<Fault> {
        Fault::new(
            self.kernel,
            FaultKind::OutOfBounds {
                arg: self.arg,
                index: vec![index],
                shape: vec![bound],
            },
        )
    }

    /// A pointer to the element at `idx` (bounds-checked).
    #[inline(always)]
    pub fn ptr_at<I: KernelIndex<N>>(&self, idx: I) -> KResult<*mut T> {
        let off = self.offset(idx)?;
        // SAFETY: `off` addresses an in-bounds element (checked above, see `new`).
        Ok(unsafe { self.ptr.offset(off) })
    }

    /// Reads the element at `idx`.
    #[inline(always)]
    pub fn load<I: KernelIndex<N>>(&self, idx: I) -> KResult<T> {
        let p = self.ptr_at(idx)?;
        // SAFETY: in bounds and aligned (see `new`).
        Ok(unsafe { p.read() })
    }

    /// Writes the element at `idx`.
    ///
    /// Inside a logged kernel thread (the runtime's race check, [`with_write_log`]) the
    /// element is claimed for that thread first; an element another thread of the launch
    /// wrote is a [`FaultKind::WriteRace`] fault, and this write does not happen.
    #[inline(always)]
    pub fn store<I: KernelIndex<N>>(&self, idx: I, value: T) -> KResult<()> {
        let p = self.ptr_at(idx)?;
        if logging() {
            self.log_write(p, idx)?;
        }
        // SAFETY: in bounds and aligned (see `new`).
        unsafe { p.write(value) };
        Ok(())
    }

    /// Claims the element at `p` (index `idx`) for the calling kernel thread in the thread's
    /// write log, if it has one.
    #[cold]
    #[inline(never)]
    fn log_write<I: KernelIndex<N>>(&self, p: *mut T, idx: I) -> KResult<()> {
        let Some((log, thread)) = CURRENT_LOG.with(Cell::get) else {
            // Another launch is logged; this one is not.
            return Ok(());
        };
        // SAFETY: `with_write_log` installs a log only while its borrow lasts.
        let log = unsafe { log.as_ref() };
        match log.record(p as usize, std::mem::size_of::<T>(), thread) {
            Ok(()) => Ok(()),
            Err(first) => Err(Fault::new(
                self.kernel,
                FaultKind::WriteRace {
                    arg: self.arg,
                    index: idx.components().to_vec(),
                    threads: (first, thread),
                },
            )),
        }
    }

    /// The strides, in elements, one per dimension.
    #[inline(always)]
    pub fn strides(&self) -> [isize; N] {
        self.strides
    }

    /// The address of element 0 (never dereferenced here; see [`ArrayView::new`] for what
    /// the indices in bounds address).
    #[inline(always)]
    pub fn as_ptr(&self) -> *mut T {
        self.ptr
    }

    /// The kernel and argument names this view reports faults under.
    pub fn names(&self) -> (&'static str, &'static str) {
        (self.kernel, self.arg)
    }
}

impl<T: Copy, const N: usize> ArrayView<T, N> {
    /// The element offset of an index already known to be in bounds.
    #[inline(always)]
    fn offset_unchecked<I: KernelIndex<N>>(&self, idx: I) -> isize {
        let u = idx.to_usize();
        let mut off = 0isize;
        for ((&i, &extent), &stride) in u.iter().zip(&self.shape).zip(&self.strides) {
            debug_assert!(i < extent);
            off += i as isize * stride;
        }
        off
    }

    /// The address of the element at `idx`, without a bounds check.
    ///
    /// # Safety
    /// `idx` must be in bounds (then the pointer is live and aligned by `new`'s contract).
    #[inline(always)]
    pub unsafe fn ptr_unchecked<I: KernelIndex<N>>(&self, idx: I) -> *mut T {
        // SAFETY: in bounds by the caller's contract, so the offset stays inside the allocation.
        unsafe { self.ptr.offset(self.offset_unchecked(idx)) }
    }

    /// Reads the element at `idx` without a bounds check.
    ///
    /// # Safety
    /// `idx` must be in bounds. Generated code calls this only for accesses indexed by the
    /// thread index, after checking once per chunk that the array covers the launch grid.
    #[inline(always)]
    pub unsafe fn load_unchecked<I: KernelIndex<N>>(&self, idx: I) -> T {
        // SAFETY: in bounds by the caller's contract, aligned and live by `new`'s.
        unsafe { self.ptr_unchecked(idx).read() }
    }

    /// Writes the element at `idx` without a bounds check.
    ///
    /// # Safety
    /// As [`ArrayView::load_unchecked`].
    #[inline(always)]
    pub unsafe fn store_unchecked<I: KernelIndex<N>>(&self, idx: I, value: T) {
        // SAFETY: in bounds by the caller's contract, aligned and live by `new`'s.
        unsafe { self.ptr_unchecked(idx).write(value) }
    }

    /// True when the view covers `dims` (one extent per dimension): every index drawn from
    /// the launch grid is then in bounds. Generated code skips the per-thread checks of
    /// thread-indexed accesses only when this holds, so inside a logged kernel thread (the
    /// race check) it says false: every store of a checked launch then goes through
    /// [`ArrayView::store`], which logs it, whatever its index.
    #[inline(always)]
    pub fn covers(&self, dims: &[usize; 4]) -> bool {
        (0..N).all(|d| self.shape[d] >= dims[d]) && !(logging() && logged_here())
    }
}

/// Where one launch's views log their writes, for the runtime's write-race check
/// (`wp::config::set_race_check`). The runtime implements it; views call it.
///
/// Views do not carry the log (that would make every view, and every object view holding
/// one, larger, for launches without the check). Instead [`with_write_log`] installs it on
/// the calling thread for one kernel thread (or while views are made), and a process-wide
/// count of launches with a log ([`WriteLogActive`]) lets a store skip looking for it with
/// one load and a never-taken branch when no launch anywhere is checked.
pub trait WriteLog: Sync {
    /// A view was made for the launch: elements of `elem` bytes at byte address `base` plus
    /// `(index . strides) * elem`, for every index below `shape` (strides in elements,
    /// possibly negative or zero).
    fn register(&self, base: usize, elem: usize, shape: &[usize], strides: &[isize]);

    /// Kernel thread `thread` (a flat launch index) writes `bytes` bytes at `addr`, inside
    /// a registered view. `Err(first)`: thread `first` wrote some of them earlier in the
    /// launch.
    fn record(&self, addr: usize, bytes: usize, thread: usize) -> Result<(), usize>;
}

/// How many launches with a write log are running now, in the whole process.
static ACTIVE_LOGS: AtomicUsize = AtomicUsize::new(0);

/// True while some launch, on any thread, has a write log ([`WriteLogActive`]).
#[inline(always)]
fn logging() -> bool {
    ACTIVE_LOGS.load(Ordering::Relaxed) != 0
}

thread_local! {
    /// The log installed on this thread by [`with_write_log`], and the kernel thread running.
    static CURRENT_LOG: Cell<Option<(NonNull<dyn WriteLog>, usize)>> = const { Cell::new(None) };
}

/// Whether this thread has a log installed.
#[cold]
fn logged_here() -> bool {
    CURRENT_LOG.with(Cell::get).is_some()
}

/// Counts a launch with a write log as running while it lives: views look for logs only
/// while one does. The runtime holds one from before it makes a checked launch's views until
/// the launch has returned.
#[must_use = "views look for write logs only while the guard lives"]
#[derive(Debug)]
pub struct WriteLogActive(());

impl WriteLogActive {
    /// Counts one more launch with a write log.
    pub fn new() -> Self {
        // Relaxed: the threads of the launch are started (by the pool's queue, which
        // synchronises) after this, so they see it.
        ACTIVE_LOGS.fetch_add(1, Ordering::Relaxed);
        WriteLogActive(())
    }
}

impl Default for WriteLogActive {
    fn default() -> Self {
        Self::new()
    }
}

impl Drop for WriteLogActive {
    fn drop(&mut self) {
        ACTIVE_LOGS.fetch_sub(1, Ordering::Relaxed);
    }
}

/// Runs `f` with `log` installed on this thread, as the log of kernel thread `thread`: every
/// [`ArrayView`] made in `f` registers its memory with `log`, and every
/// [`ArrayView::store`] in `f` is logged as a write of `thread`. Only takes effect while a
/// [`WriteLogActive`] lives. The previous installation is restored afterwards, even if `f`
/// unwinds.
///
/// # Safety
/// The views registered with `log`, and every copy of them, must not be used after `log` is
/// gone (the runtime makes them for one launch and drops them when it returns).
#[inline]
pub unsafe fn with_write_log<L: WriteLog + 'static, R>(
    log: &L,
    thread: usize,
    f: impl FnOnce() -> R,
) -> R {
    /// Puts the previous installation back.
    struct Restore(Option<(NonNull<dyn WriteLog>, usize)>);
    impl Drop for Restore {
        fn drop(&mut self) {
            CURRENT_LOG.with(|c| c.set(self.0));
        }
    }
    let log: &(dyn WriteLog + 'static) = log;
    let _restore = Restore(CURRENT_LOG.with(|c| c.replace(Some((NonNull::from(log), thread)))));
    f()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// `len` multiplied the extents left to right: `[usize::MAX, 2, 0]` (empty, so valid over
    /// any pointer) overflowed before reaching the zero (a panic in debug builds).
    #[test]
    fn len_of_empty_and_overlapping_views() {
        let mut x = 0u8;
        let p: *mut u8 = &mut x;
        // SAFETY: the first two shapes address nothing; the last addresses `x` only (zero
        // strides: every index is element zero).
        let empty = unsafe { ArrayView::new(p, [usize::MAX, 2, 0], [0, 0, 0], "k", "a") };
        assert_eq!(empty.len(), 0);
        assert!(empty.is_empty());
        let empty = unsafe { ArrayView::new(p, [0, usize::MAX], [1, 1], "k", "a") };
        assert_eq!(empty.len(), 0);
        let overlapping = unsafe { ArrayView::new(p, [usize::MAX, 3], [0, 0], "k", "a") };
        assert_eq!(overlapping.len(), usize::MAX, "saturates");
        assert_eq!(overlapping.load((5usize, 2usize)).unwrap(), 0);
    }

    /// A log that claims each address for the first thread that writes it.
    #[derive(Default)]
    struct Claims {
        registered: Mutex<Vec<(usize, usize, Vec<usize>)>>,
        owners: Mutex<Vec<(usize, usize)>>,
    }

    impl WriteLog for Claims {
        fn register(&self, base: usize, elem: usize, shape: &[usize], _: &[isize]) {
            self.registered
                .lock()
                .unwrap()
                .push((base, elem, shape.to_vec()));
        }
        fn record(&self, addr: usize, _: usize, thread: usize) -> Result<(), usize> {
            let mut owners = self.owners.lock().unwrap();
            match owners.iter().find(|(a, _)| *a == addr) {
                Some(&(_, t)) if t != thread => Err(t),
                Some(_) => Ok(()),
                None => {
                    owners.push((addr, thread));
                    Ok(())
                }
            }
        }
    }

    #[test]
    fn stores_are_logged_only_where_a_log_is_installed() {
        let mut data = [0i32; 4];
        let log = Claims::default();
        let _active = WriteLogActive::new();
        // SAFETY: `data` outlives the view; the view is used only while `log` lives.
        let v = unsafe {
            with_write_log(&log, 0, || {
                ArrayView::new(data.as_mut_ptr(), [4], [1], "k", "a")
            })
        };
        assert_eq!(
            log.registered.lock().unwrap().as_slice(),
            [(data.as_ptr() as usize, 4, vec![4])]
        );
        // Outside any kernel thread's installation: written, not logged, fast path allowed.
        v.store(1usize, 5).unwrap();
        assert!(log.owners.lock().unwrap().is_empty());
        assert!(v.covers(&[4, 1, 1, 1]));
        // SAFETY: as above.
        let second = unsafe {
            with_write_log(&log, 3, || {
                // Thread 3: every store goes through the checked, logged path.
                assert!(!v.covers(&[4, 1, 1, 1]));
                v.store(2usize, 7).unwrap();
                v.store(2usize, 8).unwrap();
                with_write_log(&log, 4, || v.store(2usize, 9))
            })
        };
        let fault = second.unwrap_err();
        assert_eq!(
            fault.kind,
            FaultKind::WriteRace {
                arg: "a",
                index: vec![2],
                threads: (3, 4)
            }
        );
        assert_eq!(fault.kernel, "k");
        // The racing write did not happen; the installation ended with the call.
        assert_eq!(data[2], 8);
        assert!(!logged_here());
    }
}

//! [`ArrayView`]: what an `Array<T, N>` argument becomes inside a kernel on the CPU.

use crate::fault::{Fault, FaultKind, KResult};
use crate::index::KernelIndex;

/// A strided view of array memory, handed to each kernel thread.
///
/// It is a raw pointer plus shape and strides (in elements), `Copy`, and shared by all threads
/// of a launch. Every access is bounds-checked against the shape and a failed check becomes a
/// [`Fault`] naming the kernel and argument; out-of-bounds memory is never touched.
///
/// Concurrency contract (the same as CUDA's and Warp's): two threads of one launch that write
/// the same element without an atomic race, and the value left behind is one of the written
/// values only by luck. Use the `atomic_*` builtins for shared accumulation.
pub struct ArrayView<T, const N: usize> {
    ptr: *mut T,
    shape: [usize; N],
    strides: [isize; N],
    kernel: &'static str,
    arg: &'static str,
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
    #[inline(always)]
    pub fn len(&self) -> usize {
        self.shape.iter().product()
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
    #[inline(always)]
    pub fn store<I: KernelIndex<N>>(&self, idx: I, value: T) -> KResult<()> {
        let p = self.ptr_at(idx)?;
        // SAFETY: in bounds and aligned (see `new`).
        unsafe { p.write(value) };
        Ok(())
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

    /// Reads the element at `idx` without a bounds check.
    ///
    /// # Safety
    /// `idx` must be in bounds. Generated code calls this only for accesses indexed by the
    /// thread index, after checking once per chunk that the array covers the launch grid.
    #[inline(always)]
    pub unsafe fn load_unchecked<I: KernelIndex<N>>(&self, idx: I) -> T {
        // SAFETY: in bounds by the caller's contract, aligned and live by `new`'s.
        unsafe { self.ptr.offset(self.offset_unchecked(idx)).read() }
    }

    /// Writes the element at `idx` without a bounds check.
    ///
    /// # Safety
    /// As [`ArrayView::load_unchecked`].
    #[inline(always)]
    pub unsafe fn store_unchecked<I: KernelIndex<N>>(&self, idx: I, value: T) {
        // SAFETY: in bounds by the caller's contract, aligned and live by `new`'s.
        unsafe { self.ptr.offset(self.offset_unchecked(idx)).write(value) }
    }

    /// True when the view covers `dims` (one extent per dimension): every index drawn from
    /// the launch grid is then in bounds.
    #[inline(always)]
    pub fn covers(&self, dims: &[usize; 4]) -> bool {
        (0..N).all(|d| self.shape[d] >= dims[d])
    }
}

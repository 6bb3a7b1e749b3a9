//! Raw interop: the addresses of arrays, and arrays over memory that something else allocated
//! (another library's host or device buffer), kept alive by an owner the array holds.
//! With the `ndarray` feature, zero-copy `ndarray` views of CPU arrays and arrays from
//! `ndarray` arrays.

use super::{checked_size, row_major, Array, Element};
use crate::capturing;
use crate::device::Device;
use crate::dispatch::Storage;
use crate::error::{Error, Result};
use std::marker::PhantomData;
use std::sync::Arc;

/// Whether a layout overlaps itself: whether two different in-bounds indices address the
/// same element (`strides` in elements, or any unit common to all axes).
///
/// The rule (ndarray's own, which its safe constructors apply): leave out the axes of extent
/// 1 (their stride is never applied), sort the others by |stride|, and require each |stride|
/// to exceed the span of all the smaller axes (Σ |stride| · (extent - 1) over them). That
/// makes the index map injective (a mixed-radix number), so a layout that passes never
/// overlaps; it catches every zero stride on an axis of extent > 1 (a broadcast, PyTorch's
/// `expand()`) and every aliasing pair. It is conservative: a few interleaved layouts that
/// happen to be injective (shape `[3, 2]`, strides `[2, 3]`) are reported as overlapping,
/// none that array libraries produce by slicing, transposing or reversing. A layout of no
/// elements never overlaps. Arithmetic saturates in `u128`: a saturated span exceeds every
/// stride, which is then rightly counted as overlapping (no index reaches that far).
pub(crate) fn layout_overlaps<const N: usize>(shape: &[usize; N], strides: &[isize; N]) -> bool {
    if shape.contains(&0) {
        return false;
    }
    let mut axes = [(0u128, 0u128); N];
    let mut m = 0;
    for d in 0..N {
        if shape[d] > 1 {
            axes[m] = (strides[d].unsigned_abs() as u128, shape[d] as u128 - 1);
            m += 1;
        }
    }
    let axes = &mut axes[..m];
    axes.sort_unstable();
    // The highest offset the smaller axes reach from element zero, all strides made positive.
    let mut span = 0u128;
    for &(stride, last) in axes.iter() {
        if stride <= span {
            return true;
        }
        span = span.saturating_add(stride.saturating_mul(last));
    }
    false
}

/// The error for an overlapping layout at an import: the crate has no read-only array (every
/// array is writable, by kernels and host-side calls), so a layout whose elements alias
/// (threads writing one element through two indices race) is refused rather than wrapped.
pub(crate) fn overlap_error(what: &str, layout: &str) -> Error {
    Error::invalid(format!(
        "{what}: {layout} addresses some elements from more than one index (a zero or \
         aliasing stride, as of a broadcast or an expand()ed tensor); arrays are writable and \
         an overlapping layout would alias, so it is refused: import a contiguous copy"
    ))
}

/// The storage span of a strided layout: the byte offset of element zero from the lowest
/// byte the layout addresses, and the number of bytes from there to the end of the highest
/// element. `byte_strides` are checked to be whole elements; the result fits `isize`.
fn strided_span<T, const N: usize>(
    what: &str,
    shape: [usize; N],
    byte_strides: [isize; N],
) -> Result<([isize; N], usize, usize)> {
    let size = std::mem::size_of::<T>() as isize;
    let mut strides = [0isize; N];
    for d in 0..N {
        if byte_strides[d] % size != 0 {
            return Err(Error::invalid(format!(
                "{what}: byte_strides[{d}] = {} is not a multiple of {size}, the size of the \
                 element type (byte_strides are {byte_strides:?})",
                byte_strides[d]
            )));
        }
        strides[d] = byte_strides[d] / size;
    }
    if shape.contains(&0) {
        return Ok((strides, 0, 0));
    }
    // Element offsets of the lowest and highest elements, relative to element zero; in i128,
    // where no extent times stride overflows.
    let (mut lo, mut hi) = (0i128, 0i128);
    for d in 0..N {
        let reach = strides[d] as i128 * (shape[d] as i128 - 1);
        if reach < 0 {
            lo += reach;
        } else {
            hi += reach;
        }
    }
    let bytes = (hi - lo + 1) * size as i128;
    if bytes > isize::MAX as i128 {
        return Err(Error::invalid(format!(
            "{what}: shape {shape:?} with byte_strides {byte_strides:?} spans {bytes} bytes, \
             more than an address space"
        )));
    }
    Ok((strides, (-lo * size as i128) as usize, bytes as usize))
}

impl<T: Element, const N: usize> Array<T, N> {
    /// The strides in bytes, one per dimension (NumPy's convention; [`strides`](Self::strides)
    /// counts elements).
    pub fn byte_strides(&self) -> [isize; N] {
        self.strides.map(|s| s * std::mem::size_of::<T>() as isize)
    }

    /// The address of element zero on the array's device: a host address for a CPU array, a
    /// `CUdeviceptr` for a GPU array (what `__cuda_array_interface__` and DLPack exchange).
    /// The address is valid while the array, a clone or a view of its memory lives.
    pub fn device_ptr(&self) -> u64 {
        self.device_address()
    }

    /// A pointer to element zero of a CPU array, for reading (with [`strides`](Self::strides)
    /// in elements). Valid while the array, a clone or a view of its memory lives; reading
    /// through it races with kernels and host-side calls that write the array meanwhile.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an array on a GPU (see [`device_ptr`](Self::device_ptr)).
    pub fn as_ptr(&self) -> Result<*const T> {
        self.as_mut_ptr().map(|p| p as *const T)
    }

    /// A pointer to element zero of a CPU array, for reading and writing; as
    /// [`as_ptr`](Self::as_ptr). (Arrays have interior mutability: kernels write them through
    /// shared references too.)
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] for an array on a GPU.
    pub fn as_mut_ptr(&self) -> Result<*mut T> {
        self.host_base().ok_or_else(|| {
            Error::invalid(format!(
                "as_ptr: the array is on \"{}\", not the CPU; use device_ptr for the address of \
                 device memory",
                self.device
            ))
        })
    }

    /// An array over host memory that something else allocated, without a copy: element
    /// `[i0, .., iN-1]` is at `ptr + Σ i_d · byte_strides[d]` bytes (row-major contiguous when
    /// `byte_strides` is `None`; strides may be negative). `owner` is kept by the array (and
    /// shared by its clones and views) and dropped when the last of them drops; pass what
    /// frees the memory (a `Vec`, an `Arc` of another library's buffer) or `()`.
    ///
    /// # Safety
    /// - every element the shape and strides address lies in one allocation that is valid
    ///   for reads and writes of `T` until `owner` drops (or forever, for an `owner` that
    ///   does not free it);
    /// - nothing else reads the memory while a kernel or host-side call writes it, or writes
    ///   it while they read it (the array's own concurrency contract applies to its handles).
    ///
    /// A layout that overlaps itself (two indices addressing one element: a zero stride on an
    /// axis of extent > 1, as of a broadcast, or strides that alias) is refused: every array
    /// is writable and there is no read-only array, so an aliasing layout would let two
    /// threads write one element through different indices. The rule is ndarray's: sorted by
    /// |stride|, each axis of extent > 1 must step past the span of the smaller ones. Wrap a contiguous copy of broadcast data instead.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the argument: `device` is not the CPU, `ptr` is null
    /// (for a non-empty shape) or not aligned for `T`, a byte stride is not a multiple of the
    /// size of `T`, the layout overlaps itself, or the layout is too large.
    pub unsafe fn from_host_ptr(
        ptr: *mut T,
        shape: impl super::IntoShape<N>,
        byte_strides: Option<[isize; N]>,
        device: &Device,
        owner: impl Send + Sync + 'static,
    ) -> Result<Self> {
        if !device.is_cpu() {
            return Err(Error::invalid(format!(
                "from_host_ptr: device \"{device}\" is not the CPU (wrap device memory with \
                 from_device_ptr)"
            )));
        }
        // SAFETY: the caller's contract.
        unsafe {
            Self::from_external(
                "from_host_ptr",
                ptr as usize as u64,
                shape.into_shape(),
                byte_strides,
                device,
                Some(Box::new(owner)),
            )
        }
    }

    /// An array over device memory that something else allocated (another CUDA library's
    /// buffer, `__cuda_array_interface__`'s `data`), without a copy; as
    /// [`from_host_ptr`](Self::from_host_ptr), with `ptr` a `CUdeviceptr` of `device`'s
    /// context. When the array drops, the GPU first finishes the work queued on it, then
    /// `owner` drops.
    ///
    /// # Safety
    /// As [`from_host_ptr`](Self::from_host_ptr), for device memory of `device` (allocated
    /// in its primary context, or accessible from it: managed or peer memory).
    /// Work that another library queues on the memory on its own streams is not ordered
    /// with this crate's: synchronize between them.
    ///
    /// # Errors
    /// As [`from_host_ptr`](Self::from_host_ptr), with `device` not a GPU.
    pub unsafe fn from_device_ptr(
        ptr: u64,
        shape: impl super::IntoShape<N>,
        byte_strides: Option<[isize; N]>,
        device: &Device,
        owner: impl Send + Sync + 'static,
    ) -> Result<Self> {
        if device.is_cpu() {
            return Err(Error::invalid(
                "from_device_ptr: device \"cpu\" is not a GPU (wrap host memory with \
                 from_host_ptr)",
            ));
        }
        // SAFETY: the caller's contract.
        unsafe {
            Self::from_external(
                "from_device_ptr",
                ptr,
                shape.into_shape(),
                byte_strides,
                device,
                Some(Box::new(owner)),
            )
        }
    }

    /// An array over an op call's memory (`ops/buffer.rs`): as
    /// [`from_host_ptr`](Self::from_host_ptr) / [`from_device_ptr`](Self::from_device_ptr) by
    /// `device`, but with no owner, so that dropping it waits for nothing (the caller orders
    /// the memory; a GPU synchronisation per call would serialise the framework's stream).
    ///
    /// # Safety
    /// As [`from_device_ptr`](Self::from_device_ptr), the memory valid while the array, its
    /// clones and the work queued on it live.
    #[cfg(feature = "ops")]
    pub(crate) unsafe fn call_scoped(
        what: &str,
        ptr: u64,
        shape: [usize; N],
        byte_strides: [isize; N],
        device: &Device,
    ) -> Result<Self> {
        // SAFETY: the caller's contract.
        unsafe { Self::from_external(what, ptr, shape, Some(byte_strides), device, None) }
    }

    /// See [`from_host_ptr`](Self::from_host_ptr) and
    /// [`from_device_ptr`](Self::from_device_ptr).
    pub(super) unsafe fn from_external(
        what: &str,
        ptr: u64,
        shape: [usize; N],
        byte_strides: Option<[isize; N]>,
        device: &Device,
        owner: Option<Box<dyn std::any::Any + Send + Sync>>,
    ) -> Result<Self> {
        let () = Self::VALID_NDIM;
        capturing::refuse(Some(device), "wrapping external memory")?;
        let (len, _) = checked_size::<T>(&shape)?;
        let size = std::mem::size_of::<T>() as isize;
        let byte_strides = byte_strides.unwrap_or_else(|| row_major(&shape).map(|s| s * size));
        let (mut strides, byte_offset, bytes) = strided_span::<T, N>(what, shape, byte_strides)?;
        if layout_overlaps(&shape, &strides) {
            return Err(overlap_error(
                what,
                &format!("shape {shape:?} with byte_strides {byte_strides:?}"),
            ));
        }
        if len == 0 {
            // Nothing is addressed: row-major strides (valid for the shape, by
            // `checked_size`) rather than the caller's, whose products with the extents of
            // the other dimensions (in views and transposes) could overflow.
            strides = row_major(&shape);
        }
        let align = std::mem::align_of::<T>() as u64;
        let mut ptr = ptr;
        if len == 0 && ptr == 0 {
            // Nothing is ever read: any aligned, non-null address stands for it.
            ptr = align;
        }
        if ptr == 0 {
            return Err(Error::invalid(format!(
                "{what}: ptr is null for a shape of {len} elements"
            )));
        }
        if !ptr.is_multiple_of(align) {
            return Err(Error::invalid(format!(
                "{what}: ptr {ptr:#x} is not aligned to {align} bytes, the alignment of {}",
                T::TYPE_NAME
            )));
        }
        let base = ptr
            .checked_sub(byte_offset as u64)
            .filter(|&b| b != 0)
            .ok_or_else(|| {
                Error::invalid(format!(
                    "{what}: the negative byte_strides {byte_strides:?} reach address 0 or \
                     below from ptr {ptr:#x}"
                ))
            })?;
        // The span must end inside the address space: no allocation wraps around it, and the
        // element addresses computed from `base` (in `usize`) would wrap. An import can only
        // check its own arithmetic, not that the memory exists (the caller's contract); a
        // pointer this close to the top (a byte_offset near 2^64 on a null DLPack data
        // pointer, found by the `dlpack` fuzz target) is refused here.
        if base.checked_add(bytes as u64).is_none() {
            return Err(Error::invalid(format!(
                "{what}: the layout (shape {shape:?}, byte_strides {byte_strides:?}) spans                  {bytes} bytes from address {base:#x}, past the end of the address space"
            )));
        }
        // SAFETY: the caller's contract covers the span (lowest to highest element).
        let storage = unsafe { Storage::external(device, base, bytes, owner)? };
        Ok(Array {
            storage: Arc::new(storage),
            grad: None,
            byte_offset: (ptr - base) as usize,
            shape,
            strides,
            device: device.clone(),
            _elem: PhantomData,
        })
    }
}

#[cfg(feature = "ndarray")]
mod nd {
    use super::super::{Array, Element, NdComponents};
    use crate::device::Device;
    use crate::error::{Error, Result};
    use ndarray::{
        ArrayBase, ArrayView, ArrayViewD, ArrayViewMut, ArrayViewMutD, Data, Dim, Dimension, IxDyn,
        ShapeBuilder,
    };
    use std::sync::Arc;

    impl<T: NdComponents, const N: usize> Array<T, N> {
        /// The shape and strides (in scalars) with the trailing component axes.
        fn component_layout(&self) -> (IxDyn, IxDyn) {
            let (shape, strides) = self.component_shape_strides();
            // ndarray takes strides as `usize` and reads them as `isize` (two's complement).
            let strides: Vec<usize> = strides.into_iter().map(|s| s as usize).collect();
            (IxDyn(&shape), IxDyn(&strides))
        }

        /// A zero-copy `ndarray` view of a CPU array's scalars, with a trailing axis per
        /// component axis of the element type as NumPy has them in Warp: an
        /// `Array<Vec3, 2>` of shape `[a, b]` is viewed with shape `[a, b, 3]`, an
        /// `Array<Mat3>` of length `n` as `[n, 3, 3]` indexed `[k, row, column]`.
        ///
        /// # Errors
        /// As [`as_ndarray`](Self::as_ndarray).
        pub fn as_ndarray_components(&mut self) -> Result<ArrayViewD<'_, T::Scalar>> {
            if self.shared() {
                return Err(Self::shared_error("as_ndarray_components"));
            }
            let ptr = self.component_ptr("as_ndarray_components")?;
            let (shape, strides) = self.component_layout();
            // SAFETY: the scalars of every element in bounds (an invariant of every array),
            // kept alive by `self`; no other handle, `self` borrowed exclusively.
            Ok(unsafe { ArrayView::from_shape_ptr(shape.strides(strides), ptr.cast_const()) })
        }

        /// The mutable form of [`as_ndarray_components`](Self::as_ndarray_components).
        ///
        /// # Errors
        /// As [`as_ndarray`](Self::as_ndarray).
        pub fn as_ndarray_components_mut(&mut self) -> Result<ArrayViewMutD<'_, T::Scalar>> {
            if self.shared() {
                return Err(Self::shared_error("as_ndarray_components_mut"));
            }
            self.refuse_overlap("as_ndarray_components_mut")?;
            let ptr = self.component_ptr("as_ndarray_components_mut")?;
            let (shape, strides) = self.component_layout();
            // SAFETY: as in `as_ndarray_components`; the view is the only access, and no two
            // indices address one scalar (the elements do not overlap, checked above, and a
            // `T`'s components are distinct scalars of it).
            Ok(unsafe { ArrayViewMut::from_shape_ptr(shape.strides(strides), ptr) })
        }

        fn component_ptr(&self, what: &str) -> Result<*mut T::Scalar> {
            self.host_base().map(|p| p.cast()).ok_or_else(|| {
                Error::invalid(format!(
                    "{what}: the array is on \"{}\", not the CPU (copy it with to_vec first)",
                    self.device
                ))
            })
        }
    }

    impl<T: Element, const N: usize> Array<T, N> {
        /// Whether another handle (a clone, a view) shares this array's memory.
        fn shared(&self) -> bool {
            Arc::strong_count(&self.storage) > 1
        }

        /// Refuses a layout that overlaps itself for a mutable view: `ArrayViewMut` hands out
        /// `&mut` to each element, and two indices of one element would be two `&mut` to it.
        /// The imports refuse such layouts, and views, rows and transposes keep a layout
        /// injective, so no array has one today; the check keeps the safe views sound
        /// should a future layout (a broadcast) allow it.
        fn refuse_overlap(&self, what: &str) -> Result<()> {
            if super::layout_overlaps(&self.shape, &self.strides) {
                return Err(super::overlap_error(
                    what,
                    &format!(
                        "the array's shape {:?} with strides {:?} (in elements)",
                        self.shape, self.strides
                    ),
                ));
            }
            Ok(())
        }

        fn shared_error(what: &str) -> Error {
            Error::invalid(format!(
                "{what}: the array's memory is shared with a clone or view (which could write \
                 it while the view lives); drop them, or use the unsafe as_ndarray_unchecked"
            ))
        }
    }

    impl<T: Element, const N: usize> Array<T, N>
    where
        Dim<[usize; N]>: Dimension,
    {
        /// The shape and strides as ndarray takes them, and element zero's address, for a
        /// CPU array.
        #[allow(clippy::type_complexity)]
        fn nd_parts(&self, what: &str) -> Result<(Dim<[usize; N]>, Dim<[usize; N]>, *mut T)> {
            let ptr = self.host_base().ok_or_else(|| {
                Error::invalid(format!(
                    "{what}: the array is on \"{}\", not the CPU (copy it with to_vec first)",
                    self.device
                ))
            })?;
            // ndarray takes negative strides as their two's complement in `usize`.
            let (mut dim, mut strides) = (Dim::<[usize; N]>::zeros(N), Dim::<[usize; N]>::zeros(N));
            dim.slice_mut().copy_from_slice(&self.shape);
            strides
                .slice_mut()
                .copy_from_slice(&self.strides.map(|s| s as usize));
            Ok((dim, strides, ptr))
        }

        /// A zero-copy `ndarray` view of a CPU array, with its shape and strides (element
        /// types as they are: an `Array<Vec3>` gives a view of `Vec3`s).
        ///
        /// It takes `&mut self` and refuses an array whose memory another handle shares, so
        /// that nothing (a kernel, a host-side call through a clone) writes the memory while
        /// the view lives; [`as_ndarray_unchecked`](Self::as_ndarray_unchecked) lifts that.
        ///
        /// # Errors
        /// [`Error::InvalidArgument`] for an array on a GPU, or one whose memory a clone or
        /// view shares.
        pub fn as_ndarray(&mut self) -> Result<ArrayView<'_, T, Dim<[usize; N]>>> {
            if self.shared() {
                return Err(Self::shared_error("as_ndarray"));
            }
            // SAFETY: no other handle exists and `self` is borrowed exclusively for the
            // view's lifetime, so nothing writes the memory meanwhile.
            unsafe { self.as_ndarray_unchecked() }
        }

        /// A zero-copy mutable `ndarray` view of a CPU array; as
        /// [`as_ndarray`](Self::as_ndarray).
        ///
        /// # Errors
        /// As [`as_ndarray`](Self::as_ndarray).
        pub fn as_ndarray_mut(&mut self) -> Result<ArrayViewMut<'_, T, Dim<[usize; N]>>> {
            if self.shared() {
                return Err(Self::shared_error("as_ndarray_mut"));
            }
            self.refuse_overlap("as_ndarray_mut")?;
            let (dim, strides, ptr) = self.nd_parts("as_ndarray_mut")?;
            // SAFETY: every index of the shape and strides addresses an element of the
            // storage (an invariant of every array), which `self` keeps alive; no other handle
            // exists and `self` is borrowed exclusively, so the view is the only access; no
            // two indices address one element (checked above).
            Ok(unsafe { ArrayViewMut::from_shape_ptr(dim.strides(strides), ptr) })
        }

        /// A zero-copy `ndarray` view of a CPU array whose memory other handles may share.
        ///
        /// # Safety
        /// Nothing may write the array's memory while the view lives: no kernel launch or
        /// host-side call (`fill`, `copy_from`, ..) on this array or a clone or view of it.
        ///
        /// # Errors
        /// [`Error::InvalidArgument`] for an array on a GPU.
        pub unsafe fn as_ndarray_unchecked(&self) -> Result<ArrayView<'_, T, Dim<[usize; N]>>> {
            let (dim, strides, ptr) = self.nd_parts("as_ndarray")?;
            // SAFETY: in bounds and alive as in `as_ndarray_mut`; no writer (the caller's
            // contract).
            Ok(unsafe { ArrayView::from_shape_ptr(dim.strides(strides), ptr.cast_const()) })
        }

        /// An array that takes an owned `ndarray` array over without a copy on the CPU (any
        /// layout ndarray has, negative strides included): the ndarray array becomes the
        /// memory's owner and drops with the last handle. On a GPU: a copy.
        ///
        /// # Errors
        /// [`Error::InvalidArgument`] for a layout the array cannot address, or one that
        /// overlaps itself (as [`from_host_ptr`](Self::from_host_ptr); a broadcast view
        /// is imported by [`from_ndarray_copy`](Self::from_ndarray_copy)).
        pub fn from_ndarray(
            a: ndarray::Array<T, Dim<[usize; N]>>,
            device: &Device,
        ) -> Result<Self> {
            if !device.is_cpu() {
                return Self::from_ndarray_copy(&a, device);
            }
            let mut shape = [0usize; N];
            shape.copy_from_slice(a.shape());
            let mut byte_strides = [0isize; N];
            let size = std::mem::size_of::<T>() as isize;
            for (d, s) in a.strides().iter().enumerate() {
                byte_strides[d] = s * size;
            }
            let mut a = a;
            let ptr = a.as_mut_ptr();
            // SAFETY: the shape and strides are the ndarray array's own, so they address its
            // allocation, which the array keeps as the owner (moving an ndarray array does not
            // move its elements); the owner is moved into the array, so nothing else
            // accesses the memory.
            unsafe {
                Self::from_external(
                    "from_ndarray",
                    ptr as usize as u64,
                    shape,
                    Some(byte_strides),
                    device,
                    Some(Box::new(a)),
                )
            }
        }

        /// An array holding a copy of any `ndarray` array or view (of any layout), on any
        /// device; row-major contiguous.
        ///
        /// # Errors
        /// As [`from_slice_shape`](Self::from_slice_shape).
        pub fn from_ndarray_copy<S: Data<Elem = T>>(
            a: &ArrayBase<S, Dim<[usize; N]>>,
            device: &Device,
        ) -> Result<Self> {
            let mut shape = [0usize; N];
            shape.copy_from_slice(a.shape());
            match a.as_slice() {
                Some(s) => Self::from_slice_shape(s, shape, device),
                None => {
                    let data: Vec<T> = a.iter().copied().collect();
                    Self::from_slice_shape(&data, shape, device)
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::layout_overlaps;

    /// The rule on the layouts it is documented for: zero strides on extents > 1 and aliasing
    /// strides overlap; axes of extent 1, empty layouts, transposes, gaps and reversals do not.
    #[test]
    fn overlap_rule() {
        assert!(layout_overlaps(&[3, 4], &[0, 1]));
        assert!(layout_overlaps(&[3, 2], &[1, 1]));
        assert!(layout_overlaps(&[2, 3], &[2, 1]));
        assert!(layout_overlaps(&[3, 3], &[-2, -1]));
        assert!(layout_overlaps(&[2, 2], &[1 << 62, 1 << 62]));
        // Conservative: injective (offsets 0, 2, 4, 3, 5, 7) but interleaved.
        assert!(layout_overlaps(&[3, 2], &[2, 3]));
        // A saturated span: every later stride is within it.
        assert!(layout_overlaps(
            &[usize::MAX, usize::MAX, 2],
            &[isize::MAX, isize::MAX, isize::MAX]
        ));
        assert!(!layout_overlaps(&[1, 4], &[0, 1]));
        assert!(!layout_overlaps(&[0, 4], &[0, 0]));
        assert!(!layout_overlaps(&[3, 4], &[4, 1]));
        assert!(!layout_overlaps(&[4, 3], &[1, 4]));
        assert!(!layout_overlaps(&[3, 2], &[2, 6]));
        assert!(!layout_overlaps(&[3, 4], &[-5, 1]));
        assert!(!layout_overlaps::<0>(&[], &[]));
    }

    /// A layout whose span runs past the top of the address space is refused, not wrapped
    /// (it was accepted before: the `dlpack` fuzz target found it through a null data
    /// pointer and a byte offset near 2^64).
    #[test]
    fn span_past_the_address_space_is_an_error() {
        let dev = crate::device::get_device("cpu").unwrap();
        // 4 f32 (16 bytes) from 8 bytes below the top; aligned, not null.
        let top = (usize::MAX - 7) as *mut f32;
        // SAFETY: refused before any access (the assertion's point); nothing is read.
        let r = unsafe { crate::array::Array::<f32, 1>::from_host_ptr(top, 4, None, &dev, ()) };
        let e = r.unwrap_err().to_string();
        assert!(
            e.contains("from_host_ptr") && e.contains("past the end of the address space"),
            "{e}"
        );
        // Reversed from the same pointer, the 16 bytes lie below it: accepted (nothing is read).
        let last = top;
        // SAFETY: as above; the array is dropped without an access.
        let ok =
            unsafe { crate::array::Array::<f32, 1>::from_host_ptr(last, 4, Some([-4]), &dev, ()) };
        assert!(ok.is_ok());
    }

    /// `as_ndarray_mut` never builds an aliasing mutable view, even of an array whose layout
    /// overlaps (no import makes one; built here by hand: one element seen three times).
    #[cfg(feature = "ndarray")]
    #[test]
    fn as_ndarray_mut_refuses_overlap() {
        let dev = crate::device::get_device("cpu").unwrap();
        let mut a = crate::array::Array::<f32, 1>::zeros(1, &dev).unwrap();
        a.shape = [3];
        a.strides = [0];
        let e = a.as_ndarray_mut().unwrap_err().to_string();
        assert!(
            e.contains("as_ndarray_mut") && e.contains("shape [3] with strides [0]"),
            "{e}"
        );
        let e = a.as_ndarray_components_mut().unwrap_err().to_string();
        assert!(e.contains("as_ndarray_components_mut"), "{e}");
        // Reading through aliases is fine.
        assert_eq!(a.as_ndarray().unwrap().to_vec(), [0.0; 3]);
    }
}

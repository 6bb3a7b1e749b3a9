//! [`Array`]: typed, shaped, strided memory on a device.
//!
//! An `Array<T, N>` is a handle: cloning it is cheap and the clone shares the memory, as in
//! Warp. Views ([`Array::view`], [`Array::row`], [`Array::reshape`], [`Array::reinterpret`],
//! [`Array::transpose`]) share the memory too. Kernels read and write arrays through shared
//! references, so the memory has interior mutability; the concurrency contract is CUDA's and
//! Warp's: two writers of one element without an atomic race (see
//! [`ArrayView`]). The same holds for host-side calls such as
//! [`Array::fill`] made from several threads at once on handles to the same memory.

use crate::backend::Record;
use crate::capturing;
use crate::device::Device;
use crate::dispatch::{self, Storage};
use crate::error::{Error, Result};
use crate::kernel::{ArgCtx, CudaArray, KernelArg};
use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};
use std::fmt;
use std::marker::PhantomData;
use std::ops::{Bound, RangeBounds};
use std::sync::Arc;
use warp_core::{
    bf16, f16, ArrayView, DSpatialMatrix, DSpatialVector, DTransform, SpatialMatrix, SpatialVector,
    Transform,
};
use warp_core::{
    DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63, DMat64,
    Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64,
};

mod components;
#[cfg(feature = "dlpack")]
mod dlpack;
mod interop;
pub use components::NdComponents;
#[cfg(feature = "dlpack")]
pub use dlpack::DlpackScalar;
#[cfg(feature = "python")]
pub(crate) use dlpack::{device_of as device_of_dlpack, dlpack_device};

/// A type that can be stored in an [`Array`].
///
/// `Pod` is what makes zero-filled memory, byte copies between host and device and
/// [`Array::reinterpret`] sound. Implemented for the integer and float scalars (`f16`
/// and `bf16` included) and for glam's
/// vectors, matrices and quaternions that are `Pod` (not `Vec3A` or `Mat3A`, which have
/// padding), for warp-core's `Transform` and `DTransform`, and for its spatial vectors and matrices; `#[derive(Struct)]` implements it for user structs. `bool` is not an element: it is
/// not `Pod`.
pub trait Element: bytemuck::Pod + warp_core::GradElement + Send + Sync + 'static {
    /// The type's name as written in Rust (`"f32"`, `"Vec3"`), for messages and code generation.
    const TYPE_NAME: &'static str;
    /// False when a float component is NaN or infinite (always true for integer types); what
    /// `config::set_verify_fp` checks.
    fn is_finite_value(&self) -> bool {
        true
    }
    /// The value as text, for messages.
    fn describe(&self) -> String {
        String::new()
    }
}

macro_rules! elements {
    ($($t:ident),* $(,)?) => {$(
        impl Element for $t {
            const TYPE_NAME: &'static str = stringify!($t);
        }
    )*};
}
macro_rules! float_elements {
    ($($t:ident),* $(,)?) => {$(
        impl Element for $t {
            const TYPE_NAME: &'static str = stringify!($t);
            fn is_finite_value(&self) -> bool {
                self.is_finite()
            }
            fn describe(&self) -> String {
                format!("{:?}", self)
            }
        }
    )*};
}
elements!(i8, i16, i32, i64, u8, u16, u32, u64);
elements!(IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);
float_elements!(f32, f64, f16, bf16, Vec2, Vec3, Vec4, DVec2, DVec3, DVec4);
float_elements!(Mat2, Mat3, Mat4, DMat2, DMat3, DMat4, Quat, DQuat);
float_elements!(Transform, DTransform);
float_elements!(SpatialVector, DSpatialVector, SpatialMatrix, DSpatialMatrix);
float_elements!(Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64);
float_elements!(
    DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63, DMat64
);

/// Something that names the shape of an `N`-dimensional array: a `usize` (for `N = 1`), an
/// array `[usize; N]`, or a tuple of 2 to 4 `usize`s.
pub trait IntoShape<const N: usize> {
    /// The shape as an array of extents.
    fn into_shape(self) -> [usize; N];
}

impl IntoShape<1> for usize {
    fn into_shape(self) -> [usize; 1] {
        [self]
    }
}

impl<const N: usize> IntoShape<N> for [usize; N] {
    fn into_shape(self) -> [usize; N] {
        self
    }
}

impl IntoShape<2> for (usize, usize) {
    fn into_shape(self) -> [usize; 2] {
        [self.0, self.1]
    }
}

impl IntoShape<3> for (usize, usize, usize) {
    fn into_shape(self) -> [usize; 3] {
        [self.0, self.1, self.2]
    }
}

impl IntoShape<4> for (usize, usize, usize, usize) {
    fn into_shape(self) -> [usize; 4] {
        [self.0, self.1, self.2, self.3]
    }
}

/// Allocates zeroed memory for `bytes` bytes of `T`s on `device`.
fn alloc_zeroed<T: Element>(bytes: usize, device: &Device) -> Result<Arc<Storage>> {
    let storage = dispatch::alloc_zeroed(device, bytes, std::mem::align_of::<T>())?;
    Ok(Arc::new(storage))
}

/// `len` copies of `value` in a new host vector: the read-backs' and uploads' staging, whose
/// allocation failure is an [`Error::OutOfMemory`] on `"cpu"` rather than an abort (a GPU
/// array can be larger than the host's free memory).
fn host_vec<T: Clone>(len: usize, value: T) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(len)
        .map_err(|_| Error::out_of_memory("cpu", len.saturating_mul(std::mem::size_of::<T>())))?;
    v.resize(len, value);
    Ok(v)
}

/// Row-major strides (in elements) for `shape`.
fn row_major<const N: usize>(shape: &[usize; N]) -> [isize; N] {
    let mut strides = [0isize; N];
    let mut s = 1isize;
    for d in (0..N).rev() {
        strides[d] = s;
        // Cannot overflow: every stride divides the product of the non-zero extents, which
        // `byte_size` checked against `isize::MAX` bytes (empty shapes too).
        s = s.wrapping_mul(shape[d] as isize);
    }
    strides
}

/// The number of elements of `shape` and their size in bytes, or an error on overflow or
/// past `isize::MAX` bytes (which the stride arithmetic assumes no array reaches).
fn checked_size<T>(shape: &[usize]) -> Result<(usize, usize)> {
    let (len, bytes) = byte_size::<T>(shape)?;
    if bytes > isize::MAX as usize {
        return Err(too_large::<T>(shape));
    }
    Ok((len, bytes))
}

/// [`Error::InvalidArgument`]: `shape` of `T`s has too many bytes.
#[cold]
fn too_large<T>(shape: &[usize]) -> Error {
    Error::invalid(format!(
        "an array of shape {shape:?} and element size {} is too large",
        std::mem::size_of::<T>()
    ))
}

/// The number of elements of `shape` and their size in bytes, or an error when either does
/// not fit in `usize` (or `T` is zero-sized).
///
/// An empty shape is held to the same rule by its non-zero extents (NumPy's): `[0, 2^62, 4]`
/// of `f32`s is refused as too large although it holds nothing, because its row-major strides
/// in bytes (`2^64` for the first dimension) and the offsets of its views would overflow
/// `isize`. Every array's non-zero extents therefore multiply to at most `isize::MAX` bytes,
/// which the stride and offset arithmetic of views, transposes and launches relies on.
fn byte_size<T>(shape: &[usize]) -> Result<(usize, usize)> {
    let too_big = || too_large::<T>(shape);
    if std::mem::size_of::<T>() == 0 {
        // Zero-sized elements would let the element count exceed `isize::MAX`, which the
        // stride arithmetic assumes it never does; they carry no data anyway.
        return Err(Error::invalid(
            "arrays of zero-sized element types are not supported",
        ));
    }
    let size = std::mem::size_of::<T>();
    let nonzero_bytes = shape
        .iter()
        .filter(|&&e| e != 0)
        .try_fold(size, |acc, &e| acc.checked_mul(e))
        .ok_or_else(too_big)?;
    if shape.contains(&0) {
        if nonzero_bytes > isize::MAX as usize {
            return Err(too_big());
        }
        return Ok((0, 0));
    }
    Ok((nonzero_bytes / size, nonzero_bytes))
}

/// Element offsets of an `N`-dimensional strided layout, in row-major order (the last index
/// varies fastest).
struct Offsets<const N: usize> {
    shape: [usize; N],
    strides: [isize; N],
    index: [usize; N],
    offset: isize,
    remaining: usize,
}

impl<const N: usize> Offsets<N> {
    fn new(shape: [usize; N], strides: [isize; N]) -> Self {
        Offsets {
            shape,
            strides,
            index: [0; N],
            offset: 0,
            remaining: shape.iter().product(),
        }
    }
}

impl<const N: usize> Iterator for Offsets<N> {
    type Item = isize;

    fn next(&mut self) -> Option<isize> {
        if self.remaining == 0 {
            return None;
        }
        self.remaining -= 1;
        let current = self.offset;
        // Odometer increment: bump the last index, carrying into earlier ones.
        for d in (0..N).rev() {
            self.index[d] += 1;
            self.offset += self.strides[d];
            if self.index[d] < self.shape[d] {
                break;
            }
            self.offset -= self.strides[d] * self.shape[d] as isize;
            self.index[d] = 0;
        }
        Some(current)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        (self.remaining, Some(self.remaining))
    }
}

/// An `N`-dimensional array of `T` on a device (`N` from 1 to 4).
///
/// Cloning is cheap and shares the memory (like assigning a `wp.array` in Python). The layout
/// is a byte offset into shared storage plus a shape and strides in elements; arrays made by
/// the constructors are contiguous and row-major.
pub struct Array<T: Element, const N: usize = 1> {
    storage: Arc<Storage>,
    /// The gradient's storage (same size and layout as `storage`), when the array has one.
    grad: Option<Arc<Storage>>,
    // In bytes rather than elements, so that a reinterpretation as a larger type can start at
    // any suitably aligned byte.
    byte_offset: usize,
    shape: [usize; N],
    strides: [isize; N],
    device: Device,
    _elem: PhantomData<T>,
}

impl<T: Element, const N: usize> Clone for Array<T, N> {
    fn clone(&self) -> Self {
        Array {
            storage: Arc::clone(&self.storage),
            grad: self.grad.clone(),
            byte_offset: self.byte_offset,
            shape: self.shape,
            strides: self.strides,
            device: self.device.clone(),
            _elem: PhantomData,
        }
    }
}

impl<T: Element, const N: usize> Array<T, N> {
    /// Evaluated (and so checked at compile time) by every constructor.
    const VALID_NDIM: () = assert!(N >= 1 && N <= 4, "an Array has 1 to 4 dimensions");

    /// A new contiguous array over fresh zeroed storage.
    ///
    /// A shape whose byte count does not fit in `usize` is an [`Error::InvalidArgument`] (no
    /// allocation can be asked for); a representable size that the device cannot give, past
    /// `isize::MAX` included, is [`Error::OutOfMemory`].
    fn alloc(shape: [usize; N], device: &Device) -> Result<Self> {
        let () = Self::VALID_NDIM;
        let (_, bytes) = byte_size::<T>(&shape)?;
        if bytes > isize::MAX as usize {
            return Err(Error::out_of_memory(device.alias(), bytes));
        }
        Ok(Array {
            storage: alloc_zeroed::<T>(bytes, device)?,
            grad: None,
            byte_offset: 0,
            shape,
            strides: row_major(&shape),
            device: device.clone(),
            _elem: PhantomData,
        })
    }

    /// An array of zeros. A zero extent is allowed and gives an empty array.
    ///
    /// # Errors
    /// [`Error::OutOfMemory`] when the device cannot allocate the array (on the CPU too: the
    /// allocator's failure is an `Err`, not an abort); [`Error::InvalidArgument`] when the
    /// shape's byte count does not fit in `usize`; [`Error::Capture`] inside a graph capture.
    pub fn zeros(shape: impl IntoShape<N>, device: &Device) -> Result<Self> {
        Self::alloc(shape.into_shape(), device)
    }

    /// An array whose contents the caller will overwrite. Zero-filled too: safe Rust has no
    /// uninitialised memory, and the cost of zeroing is paid in the allocator's fast path.
    pub fn empty(shape: impl IntoShape<N>, device: &Device) -> Result<Self> {
        Self::alloc(shape.into_shape(), device)
    }

    /// An array with every element set to `value`.
    pub fn full(shape: impl IntoShape<N>, value: T, device: &Device) -> Result<Self> {
        let a = Self::alloc(shape.into_shape(), device)?;
        a.fill(value)?;
        Ok(a)
    }

    /// An array of the given shape holding `data` in row-major order.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `data.len()` is not the product of the extents.
    pub fn from_slice_shape(data: &[T], shape: impl IntoShape<N>, device: &Device) -> Result<Self> {
        let shape = shape.into_shape();
        let (len, _) = checked_size::<T>(&shape)?;
        if data.len() != len {
            return Err(Error::invalid(format!(
                "from_slice_shape: a slice of {} elements cannot fill shape {shape:?} ({len} \
                 elements)",
                data.len()
            )));
        }
        let a = Self::alloc(shape, device)?;
        a.write_row_major(data)?;
        Ok(a)
    }

    /// The shape, one extent per dimension.
    pub fn shape(&self) -> [usize; N] {
        self.shape
    }

    /// The strides, in elements (not bytes), one per dimension.
    pub fn strides(&self) -> [isize; N] {
        self.strides
    }

    /// The number of elements (the product of the extents).
    pub fn len(&self) -> usize {
        self.shape.iter().product()
    }

    /// True when the array has no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The number of dimensions, `N`.
    pub fn ndim(&self) -> usize {
        N
    }

    /// The device the array lives on.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// True when the elements are laid out row-major without gaps (extents of one and empty
    /// arrays do not constrain the strides).
    pub fn is_contiguous(&self) -> bool {
        if self.is_empty() {
            return true;
        }
        let mut expected = 1isize;
        for d in (0..N).rev() {
            if self.shape[d] != 1 && self.strides[d] != expected {
                return false;
            }
            expected *= self.shape[d] as isize;
        }
        true
    }

    /// This array with a gradient: zeroed memory of the same layout on the same device, shared
    /// by every clone and view made from the result (Warp's `requires_grad=True`). An array
    /// that already has one keeps it.
    pub fn with_grad(mut self) -> Result<Self> {
        if self.grad.is_none() {
            self.grad = Some(alloc_zeroed::<T>(self.storage.len(), &self.device)?);
        }
        Ok(self)
    }

    /// This array with `grad`'s memory as its gradient: another library's buffer (a torch
    /// tensor, an XLA result, imported with `from_dlpack` or `from_device_ptr`) instead of fresh
    /// memory, so that kernels and adjoints write the gradient where that library reads it
    /// (Warp's `from_torch(t, grad=g)`). A gradient the array had is replaced (its clones keep
    /// theirs); `grad`'s own gradient, if any, is not used.
    ///
    /// The gradient shares the array's layout (views, rows and reshapes of the result index
    /// both with one offset and one set of strides), so `grad` must be on the same device,
    /// have the same shape and element strides, start at the same byte offset within its
    /// memory, and span at least as much memory as the array's (every view of the array is
    /// then inside the gradient); it must not share the array's memory.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming both devices or both layouts, or the shared memory.
    pub fn with_grad_array(mut self, grad: Array<T, N>) -> Result<Self> {
        let what = format!("with_grad_array (Array<{}, {N}>)", T::TYPE_NAME);
        if grad.device != self.device {
            return Err(Error::invalid(format!(
                "{what}: the array is on \"{}\" and the gradient on \"{}\"; a gradient lives on \
                 its array's device",
                self.device, grad.device
            )));
        }
        if Arc::ptr_eq(&grad.storage, &self.storage) {
            return Err(Error::invalid(format!(
                "{what}: the gradient shares the array's memory; kernels would write gradients \
                 over the values"
            )));
        }
        // Empty arrays address nothing: only their shapes must agree.
        let empty = self.shape.contains(&0);
        let same = grad.shape == self.shape
            && (empty
                || (grad.strides == self.strides
                    && grad.byte_offset == self.byte_offset
                    && grad.storage.len() >= self.storage.len()));
        if !same {
            return Err(Error::invalid(format!(
                "{what}: the gradient's layout (shape {:?}, strides {:?}, byte offset {} in \
                 {} bytes) differs from the array's (shape {:?}, strides {:?}, byte offset {} \
                 in {} bytes); the gradient needs the array's shape, strides and byte offset, \
                 and at least its memory (make it like the array: zeros of the same shape for a \
                 contiguous array)",
                grad.shape,
                grad.strides,
                grad.byte_offset,
                grad.storage.len(),
                self.shape,
                self.strides,
                self.byte_offset,
                self.storage.len()
            )));
        }
        self.grad = Some(grad.storage);
        Ok(self)
    }

    /// Whether the array has a gradient ([`with_grad`](Self::with_grad)).
    pub fn requires_grad(&self) -> bool {
        self.grad.is_some()
    }

    /// The gradient as an array of the same shape (sharing the gradient's memory), if any.
    pub fn grad(&self) -> Option<Array<T, N>> {
        self.grad.as_ref().map(|g| Array {
            storage: Arc::clone(g),
            grad: None,
            byte_offset: self.byte_offset,
            shape: self.shape,
            strides: self.strides,
            device: self.device.clone(),
            _elem: PhantomData,
        })
    }

    /// Sets the gradient to zero (nothing without one).
    pub fn zero_grad(&self) -> Result<()> {
        match self.grad() {
            Some(g) => g.fill(T::zeroed()),
            None => Ok(()),
        }
    }

    /// The index (row-major order) and value of the first NaN or infinite element, if any.
    fn first_non_finite(&self) -> Result<Option<(Vec<usize>, String)>> {
        let values = self.to_vec()?;
        let Some(k) = values.iter().position(|v| !v.is_finite_value()) else {
            return Ok(None);
        };
        let mut index = vec![0usize; N];
        let mut rest = k;
        for d in (0..N).rev() {
            let extent = self.shape[d].max(1);
            index[d] = rest % extent;
            rest /= extent;
        }
        Ok(Some((index, values[k].describe())))
    }

    /// A divergence guard for simulations (like MuJoCo's bad-value check): an
    /// [`Error::Diverged`] naming `what`, the index and the value of the first NaN or
    /// infinite element. On a GPU this reads the array back.
    pub fn check_finite(&self, what: &str) -> Result<()> {
        match self.first_non_finite()? {
            None => Ok(()),
            Some((index, value)) => Err(Error::Diverged {
                what: what.to_string(),
                index,
                value,
            }),
        }
    }

    /// How many handles (this one, its clones and views) share this array's memory: an op
    /// checks that none of a call-scoped array's escaped its call (`ops/computation.rs`).
    #[cfg(feature = "ops")]
    pub(crate) fn storage_handles(&self) -> usize {
        Arc::strong_count(&self.storage)
    }

    /// True when `self` and `other` share storage (one is a clone or view of the other).
    pub fn shares_storage_with<U: Element, const M: usize>(&self, other: &Array<U, M>) -> bool {
        Arc::ptr_eq(&self.storage, &other.storage)
    }

    /// Pointer to the element at index zero, for arrays in host memory (`None` on a GPU).
    fn host_base(&self) -> Option<*mut T> {
        let host = self.storage.host()?;
        debug_assert!(self.byte_offset <= self.storage.len());
        // SAFETY: every constructor keeps `byte_offset` within the allocation (at most its
        // size, for an empty view at the end).
        Some(unsafe { host.ptr().add(self.byte_offset).cast::<T>() })
    }

    /// The element offsets of the array, row-major.
    fn offsets(&self) -> Offsets<N> {
        Offsets::new(self.shape, self.strides)
    }

    /// The address of element zero as the device's kernels receive it.
    pub(crate) fn device_address(&self) -> u64 {
        self.storage.address() + self.byte_offset as u64
    }

    /// The memory, byte offset and byte length of a contiguous array.
    #[cfg(feature = "cuda")]
    pub(crate) fn contiguous_range(&self) -> (&Storage, usize, usize) {
        debug_assert!(self.is_contiguous());
        (
            &self.storage,
            self.byte_offset,
            self.len() * std::mem::size_of::<T>(),
        )
    }

    /// The whole storage, copied to the host, for strided access to memory the host cannot
    /// address.
    fn read_storage(&self) -> Result<Vec<u8>> {
        let mut bytes = host_vec(self.storage.len(), 0u8)?;
        self.storage.read(0, &mut bytes)?;
        Ok(bytes)
    }

    /// The elements in row-major order (honouring strides). On a GPU this synchronises the
    /// device's stream and reports a fault recorded by an earlier launch.
    pub fn to_vec(&self) -> Result<Vec<T>> {
        capturing::refuse(Some(&self.device), "a read-back (to_vec)")?;
        let Some(base) = self.host_base() else {
            // Device memory: the kernels that may write it first (their faults are reported
            // here), then a copy.
            dispatch::synchronize(&self.device)?;
            let len = self.len();
            let size = std::mem::size_of::<T>();
            let mut out = host_vec(len, T::zeroed())?;
            if self.is_contiguous() {
                self.storage
                    .read(self.byte_offset, bytemuck::cast_slice_mut(&mut out))?;
            } else {
                let all = self.read_storage()?;
                for (o, off) in out.iter_mut().zip(self.offsets()) {
                    let at = (self.byte_offset as isize + off * size as isize) as usize;
                    *o = bytemuck::pod_read_unaligned(&all[at..at + size]);
                }
            }
            return Ok(out);
        };
        if self.is_contiguous() {
            let len = self.len();
            let mut out = Vec::<T>::new();
            // The array's own bytes: the product cannot overflow.
            out.try_reserve_exact(len)
                .map_err(|_| Error::out_of_memory("cpu", len * std::mem::size_of::<T>()))?;
            // SAFETY: a contiguous array's elements are `len` consecutive `T`s from `base`;
            // the destination has capacity `len` and is a distinct allocation.
            unsafe {
                std::ptr::copy_nonoverlapping(base, out.as_mut_ptr(), len);
                out.set_len(len);
            }
            return Ok(out);
        }
        // SAFETY: every offset produced for the shape and strides is an in-bounds element.
        Ok(self
            .offsets()
            .map(|off| unsafe { base.offset(off).read() })
            .collect())
    }

    /// Sets every element to `value`.
    pub fn fill(&self, value: T) -> Result<()> {
        if capturing::capturing() {
            let (keep, array) = (self.clone(), self.clone());
            let captured = dispatch::on_array_op(
                &[&self.device],
                "a fill",
                move || Box::new(keep),
                move || Box::new(move || array.fill(value)),
            )?;
            if captured == Some(Record::Recorded) {
                return Ok(());
            }
        }
        let Some(base) = self.host_base() else {
            if self.is_contiguous() {
                let bytes = self.len() * std::mem::size_of::<T>();
                return self
                    .storage
                    .fill(self.byte_offset, bytes, bytemuck::bytes_of(&value));
            }
            return self.write_row_major(&host_vec(self.len(), value)?);
        };
        if self.is_contiguous() {
            for i in 0..self.len() {
                // SAFETY: in bounds of a contiguous array (see `to_vec`).
                unsafe { base.add(i).write(value) };
            }
        } else {
            for off in self.offsets() {
                // SAFETY: every offset produced for the shape and strides is in bounds.
                unsafe { base.offset(off).write(value) };
            }
        }
        Ok(())
    }

    /// Copies `src` into `self` element by element (row-major correspondence).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the shapes differ.
    pub fn copy_from(&self, src: &Array<T, N>) -> Result<()> {
        if self.shape != src.shape {
            return Err(Error::invalid(format!(
                "copy between arrays of different shapes: destination {:?}, source {:?}",
                self.shape, src.shape
            )));
        }
        let same_storage = Arc::ptr_eq(&self.storage, &src.storage);
        let one_copy = self.is_contiguous() && src.is_contiguous() && !same_storage;
        let mut in_gpu_capture = false;
        if capturing::capturing() {
            let keep = (self.clone(), src.clone());
            let (dst, from) = (self.clone(), src.clone());
            match dispatch::on_array_op(
                &[&self.device, &src.device],
                "a copy",
                move || Box::new(keep),
                move || Box::new(move || dst.copy_from(&from)),
            )? {
                Some(Record::Recorded) => return Ok(()),
                Some(Record::Enqueue) if !one_copy => {
                    return Err(Error::Capture {
                        what: format!(
                            "a copy between strided or overlapping arrays on \"{}\" goes \
                             through the host, which a graph cannot replay (copy contiguous \
                             arrays, or launch a copy kernel)",
                            self.device
                        ),
                    })
                }
                Some(Record::Enqueue) => in_gpu_capture = true,
                None => {}
            }
        }
        if one_copy {
            // One copy of bytes, by the backends of the two memories. The kernels that may
            // still write `src` first (a GPU's; their faults are reported here); inside a GPU
            // capture the copy is queued after the captured kernels on the capture stream.
            if !in_gpu_capture {
                dispatch::synchronize(&src.device)?;
            }
            let bytes = self.len() * std::mem::size_of::<T>();
            return self
                .storage
                .copy_from(self.byte_offset, &src.storage, src.byte_offset, bytes);
        }
        let (Some(dst_base), Some(src_base), false) =
            (self.host_base(), src.host_base(), same_storage)
        else {
            // Device memory strided, or the two may overlap in any pattern: through a
            // temporary in row-major order, so that every source element is read before any
            // is overwritten.
            let tmp = src.to_vec()?;
            return self.write_row_major(&tmp);
        };
        for (d, s) in self.offsets().zip(src.offsets()) {
            // SAFETY: offsets are in bounds of their own arrays, whose shapes are equal.
            unsafe { dst_base.offset(d).write(src_base.offset(s).read()) };
        }
        Ok(())
    }

    /// Writes `data` (exactly `len` elements, row-major) into the array.
    fn write_row_major(&self, data: &[T]) -> Result<()> {
        debug_assert_eq!(data.len(), self.len());
        let Some(base) = self.host_base() else {
            if self.is_contiguous() {
                return self
                    .storage
                    .write(self.byte_offset, bytemuck::cast_slice(data));
            }
            let size = std::mem::size_of::<T>();
            let mut all = self.read_storage()?;
            for (v, off) in data.iter().zip(self.offsets()) {
                let at = (self.byte_offset as isize + off * size as isize) as usize;
                all[at..at + size].copy_from_slice(bytemuck::bytes_of(v));
            }
            return self.storage.write(0, &all);
        };
        for (off, &v) in self.offsets().zip(data) {
            // SAFETY: every offset produced for the shape and strides is in bounds.
            unsafe { base.offset(off).write(v) };
        }
        Ok(())
    }

    /// A view of the rows `range` of the first dimension, sharing storage.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the range is reversed or ends past the first extent.
    pub fn view(&self, range: impl RangeBounds<usize>) -> Result<Array<T, N>> {
        let extent = self.shape[0];
        let start = match range.start_bound() {
            Bound::Included(&s) => Some(s),
            Bound::Excluded(&s) => s.checked_add(1),
            Bound::Unbounded => Some(0),
        };
        let end = match range.end_bound() {
            Bound::Included(&e) => e.checked_add(1),
            Bound::Excluded(&e) => Some(e),
            Bound::Unbounded => Some(extent),
        };
        let (start, end) = match (start, end) {
            (Some(s), Some(e)) if s <= e && e <= extent => (s, e),
            _ => {
                return Err(Error::invalid(format!(
                    "view range {:?}..{:?} is out of bounds for first dimension of extent \
                     {extent} (shape {:?})",
                    range.start_bound(),
                    range.end_bound(),
                    self.shape
                )))
            }
        };
        let mut shape = self.shape;
        shape[0] = end - start;
        Ok(Array {
            byte_offset: self.offset_of_first(start, &shape),
            shape,
            ..self.clone()
        })
    }

    /// The byte offset of a view starting at index `i` along the first dimension, whose
    /// shape is `shape`.
    fn offset_of_first(&self, i: usize, shape: &[usize]) -> usize {
        if shape.contains(&0) {
            // An empty view addresses nothing: it keeps this array's offset, which is inside
            // (or at the end of) the allocation. Row `i`'s offset need not be: one row past
            // the end with a negative stride lies before the allocation, and in an empty
            // array (a transpose of `[0, n]`) row `i` may lie past its end.
            return self.byte_offset;
        }
        // Row `i` holds an element, which lies inside the allocation.
        let delta = i as isize * self.strides[0] * std::mem::size_of::<T>() as isize;
        (self.byte_offset as isize + delta) as usize
    }

    /// A view with the order of the dimensions reversed (a transpose for `N = 2`), sharing
    /// storage. The result is not contiguous unless at most one extent exceeds one.
    pub fn transpose(&self) -> Array<T, N> {
        let mut shape = self.shape;
        let mut strides = self.strides;
        shape.reverse();
        strides.reverse();
        Array {
            shape,
            strides,
            ..self.clone()
        }
    }

    /// The same elements viewed as another shape with the same number of elements, sharing
    /// storage.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the array is not contiguous or the element counts differ.
    pub fn reshape<const M: usize>(&self, shape: impl IntoShape<M>) -> Result<Array<T, M>> {
        let () = Array::<T, M>::VALID_NDIM;
        let shape = shape.into_shape();
        let (len, _) = checked_size::<T>(&shape)?;
        if !self.is_contiguous() {
            return Err(Error::invalid(format!(
                "reshape of a non-contiguous array (shape {:?}, strides {:?})",
                self.shape, self.strides
            )));
        }
        if len != self.len() {
            return Err(Error::invalid(format!(
                "cannot reshape an array of shape {:?} ({} elements) to shape {shape:?} ({len} \
                 elements)",
                self.shape,
                self.len()
            )));
        }
        Ok(Array {
            storage: Arc::clone(&self.storage),
            grad: self.grad.clone(),
            byte_offset: self.byte_offset,
            shape,
            strides: row_major(&shape),
            device: self.device.clone(),
            _elem: PhantomData,
        })
    }

    /// The same bytes viewed as a flat array of another element type, sharing storage (e.g.
    /// `Array<f32>` of length `3n` as `Array<Vec3>` of length `n`, or back).
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the array is not contiguous, when its size in bytes is
    /// not a multiple of `U`'s size, or when its start is not aligned for `U`.
    pub fn reinterpret<U: Element>(&self) -> Result<Array<U, 1>> {
        let (t, u) = (std::mem::size_of::<T>(), std::mem::size_of::<U>());
        let bytes = self.len() * t;
        let fail = |why: String| {
            Err(Error::invalid(format!(
                "cannot reinterpret an array of {} with shape {:?} as {}: {why}",
                T::TYPE_NAME,
                self.shape,
                U::TYPE_NAME
            )))
        };
        if !self.is_contiguous() {
            return fail("it is not contiguous".into());
        }
        // `checked_rem` also rejects zero-sized `U` (it is `None` for `u == 0`).
        if bytes.checked_rem(u) != Some(0) {
            return fail(format!(
                "{bytes} bytes are not a multiple of {u}, the size of the type"
            ));
        }
        let align = std::mem::align_of::<U>();
        // Alignments are powers of two.
        if self.device_address() & (align as u64 - 1) != 0 {
            return fail(format!("its start is not aligned to {align} bytes"));
        }
        let len = bytes / u;
        Ok(Array {
            storage: Arc::clone(&self.storage),
            grad: self.grad.clone(),
            byte_offset: self.byte_offset,
            shape: [len],
            strides: [1],
            device: self.device.clone(),
            _elem: PhantomData,
        })
    }

    /// The kernel-side view of this array, reporting faults under `kernel` and `arg`.
    pub(crate) fn cpu_view(&self, kernel: &'static str, arg: &'static str) -> ArrayView<T, N> {
        let base = self
            .host_base()
            .expect("the arrays of a CPU launch are on the CPU (checked by the launch)");
        // SAFETY: every in-bounds index of the shape and strides addresses an element inside
        // the storage (an invariant of every constructor and view); the storage is kept alive
        // by `self`, which the launch borrows for as long as the view is used.
        unsafe { ArrayView::new(base, self.shape, self.strides, kernel, arg) }
    }

    /// The storage's size in bytes (for tests of the layout invariants).
    #[cfg(test)]
    fn storage_bytes(&self) -> usize {
        self.storage.len()
    }
}

impl<T: Element> Array<T, 1> {
    /// A 1-D array holding a copy of `data`.
    pub fn from_slice(data: &[T], device: &Device) -> Result<Self> {
        Self::from_slice_shape(data, data.len(), device)
    }

    /// A 1-D array that takes over `data`'s memory (no copy on the CPU).
    pub fn from_vec(data: Vec<T>, device: &Device) -> Result<Self> {
        if !device.is_cpu() {
            return Self::from_slice(&data, device);
        }
        // Host memory: the array takes the vector's allocation over (an allocation as far as
        // a capture is concerned: refused on every backend alike).
        capturing::refuse(Some(device), "an allocation")?;
        let len = data.len();
        checked_size::<T>(&[len])?;
        Ok(Array {
            storage: Arc::new(Storage::host_from_vec(data)?),
            grad: None,
            byte_offset: 0,
            shape: [len],
            strides: [1],
            device: device.clone(),
            _elem: PhantomData,
        })
    }
}

impl<T: Element> Array<T, 2> {
    /// Row `i` (a 1-D view of `shape[1]` elements), sharing storage.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `i >= shape[0]`.
    pub fn row(&self, i: usize) -> Result<Array<T, 1>> {
        if i >= self.shape[0] {
            return Err(Error::invalid(format!(
                "row {i} is out of bounds for an array of shape {:?}",
                self.shape
            )));
        }
        Ok(Array {
            storage: Arc::clone(&self.storage),
            grad: self.grad.clone(),
            byte_offset: self.offset_of_first(i, &[self.shape[1]]),
            shape: [self.shape[1]],
            strides: [self.strides[1]],
            device: self.device.clone(),
            _elem: PhantomData,
        })
    }
}

/// How many leading elements `Debug` prints.
const DEBUG_ELEMENTS: usize = 8;

impl<T: Element + fmt::Debug, const N: usize> fmt::Debug for Array<T, N> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "Array<{}, {N}> {{ shape: {:?}, device: {}",
            T::TYPE_NAME,
            self.shape,
            self.device
        )?;
        if let Some(base) = self.host_base() {
            // SAFETY: every offset produced for the shape and strides is in bounds.
            let head: Vec<T> = self
                .offsets()
                .take(DEBUG_ELEMENTS)
                .map(|o| unsafe { base.offset(o).read() })
                .collect();
            write!(f, ", data: {head:?}")?;
            if self.len() > DEBUG_ELEMENTS {
                write!(f, " (first {DEBUG_ELEMENTS} of {})", self.len())?;
            }
        }
        write!(f, " }}")
    }
}

impl<T: Element, const N: usize> Array<T, N> {
    /// An argument must live on the launch device.
    fn check_device(&self, ctx: &ArgCtx<'_>) -> Result<()> {
        if self.device() == ctx.device {
            return Ok(());
        }
        Err(Error::DeviceMismatch {
            kernel: ctx.kernel,
            arg: ctx.arg,
            expected: ctx.device.alias().to_string(),
            found: self.device().alias().to_string(),
        })
    }
}

impl<T: Element, const N: usize> KernelArg for Array<T, N> {
    type Arg<'a> = &'a Array<T, N>;
    type CpuView = ArrayView<T, N>;

    unsafe fn cpu_view(arg: &Self::Arg<'_>, ctx: &ArgCtx<'_>) -> Result<Self::CpuView> {
        arg.check_device(ctx)?;
        Ok(arg.cpu_view(ctx.kernel, ctx.arg))
    }

    type CudaArg = CudaArray<N>;

    fn cuda_arg(arg: &Self::Arg<'_>, ctx: &ArgCtx<'_>) -> Result<Self::CudaArg> {
        arg.check_device(ctx)?;
        let data = arg.device_address();
        let size = std::mem::size_of::<T>() as i64;
        Ok(CudaArray {
            data,
            shape: arg.shape.map(|e| e as i64),
            strides: arg.strides.map(|s| s as i64 * size),
            arg: ctx.index as i32,
            pad: 0,
        })
    }

    type CudaGrad = CudaArray<N>;

    const HAS_CUDA_GRAD: bool = true;

    fn cuda_grad(arg: &Self::Arg<'_>, ctx: &ArgCtx<'_>) -> Result<Self::CudaGrad> {
        match arg.grad() {
            Some(g) => <Self as KernelArg>::cuda_arg(&&g, ctx),
            None => {
                let mut a = <Self as KernelArg>::cuda_arg(arg, ctx)?;
                a.data = 0;
                Ok(a)
            }
        }
    }

    type GradView = warp_core::GradView<T, N>;

    unsafe fn grad_view(arg: &Self::Arg<'_>, ctx: &ArgCtx<'_>) -> Result<Self::GradView> {
        arg.check_device(ctx)?;
        Ok(match arg.grad() {
            Some(g) if arg.device().is_cpu() => {
                warp_core::GradView::new(g.cpu_view(ctx.kernel, ctx.arg))
            }
            _ => warp_core::GradView::none(),
        })
    }

    fn zero_grad(arg: &Self::Arg<'_>) -> Result<()> {
        arg.zero_grad()
    }

    fn check_finite(arg: &Self::Arg<'_>, kernel: &'static str, name: &'static str) -> Result<()> {
        match arg.first_non_finite()? {
            None => Ok(()),
            Some((index, value)) => Err(Error::NonFinite {
                kernel,
                arg: name,
                index,
                value,
            }),
        }
    }

    type Owned = Array<T, N>;

    fn own(arg: &Self::Arg<'_>) -> Self::Owned {
        (*arg).clone()
    }

    fn borrow(owned: &Self::Owned) -> Self::Arg<'_> {
        owned
    }

    fn grad_key(arg: &Self::Arg<'_>) -> Option<crate::kernel::GradKey> {
        let g = arg.grad.as_ref()?;
        let mut strides = [0isize; 4];
        strides[..N].copy_from_slice(&arg.strides);
        Some(crate::kernel::GradKey {
            storage: Arc::as_ptr(g) as usize,
            byte_offset: arg.byte_offset,
            strides,
        })
    }

    fn covers(arg: &Self::Arg<'_>, dims: &[usize; 4]) -> bool {
        (0..N).all(|d| arg.shape[d] >= dims[d])
    }

    fn contiguous(arg: &Self::Arg<'_>) -> bool {
        arg.is_contiguous()
    }

    fn shape(arg: &Self::Arg<'_>) -> Option<Vec<usize>> {
        Some(arg.shape.to_vec())
    }
}

/// Implements [`KernelArg`] for types passed by value (scalars, vectors, matrices, structs):
/// the host value is what every kernel thread sees.
macro_rules! value_kernel_args {
    ($($t:ty),* $(,)?) => {$(
        impl KernelArg for $t {
            type Arg<'a> = $t;
            type CpuView = $t;

            #[inline(always)]
            unsafe fn cpu_view(arg: &Self::Arg<'_>, _ctx: &ArgCtx<'_>) -> Result<Self::CpuView> {
                Ok(*arg)
            }

            type CudaArg = $t;

            #[inline(always)]
            fn cuda_arg(arg: &Self::Arg<'_>, _ctx: &ArgCtx<'_>) -> Result<Self::CudaArg> {
                Ok(*arg)
            }

            type GradView = ();

            unsafe fn grad_view(_: &Self::Arg<'_>, _: &ArgCtx<'_>) -> Result<()> {
                Ok(())
            }

            type CudaGrad = ();

            fn cuda_grad(_: &Self::Arg<'_>, _: &ArgCtx<'_>) -> Result<()> {
                Ok(())
            }

            type Owned = $t;

            fn own(arg: &Self::Arg<'_>) -> $t {
                *arg
            }

            fn borrow(owned: &$t) -> $t {
                *owned
            }
        }
    )*};
}
value_kernel_args!(bool, i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64, f16, bf16);
value_kernel_args!(Vec2, Vec3, Vec4, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);
value_kernel_args!(Mat2, Mat3, Mat4, DMat2, DMat3, DMat4, Quat, DQuat);
value_kernel_args!(Transform, DTransform);
value_kernel_args!(SpatialVector, DSpatialVector, SpatialMatrix, DSpatialMatrix);
value_kernel_args!(
    Mat23, Mat24, Mat26, Mat32, Mat34, Mat36, Mat42, Mat43, Mat46, Mat62, Mat63, Mat64
);
value_kernel_args!(
    DMat23, DMat24, DMat26, DMat32, DMat34, DMat36, DMat42, DMat43, DMat46, DMat62, DMat63, DMat64
);

#[cfg(test)]
mod tests {
    use super::*;
    use crate::device::cpu;

    fn iota(n: usize) -> Vec<f32> {
        (0..n).map(|i| i as f32).collect()
    }

    #[test]
    fn creation_and_to_vec() {
        let dev = cpu();
        let z = Array::<f32>::zeros(4, &dev).unwrap();
        assert_eq!(z.to_vec().unwrap(), vec![0.0; 4]);
        assert_eq!(z.shape(), [4]);
        assert_eq!(z.strides(), [1]);
        assert_eq!((z.len(), z.ndim(), z.is_empty()), (4, 1, false));
        assert_eq!(z.device(), &dev);

        let e = Array::<i32, 2>::empty((2, 3), &dev).unwrap();
        assert_eq!(e.to_vec().unwrap(), vec![0; 6]);
        assert_eq!(e.strides(), [3, 1]);

        let f = Array::<u8, 3>::full([2, 1, 2], 7, &dev).unwrap();
        assert_eq!(f.to_vec().unwrap(), vec![7; 4]);
        assert_eq!(f.strides(), [2, 2, 1]);

        let s = Array::from_slice(&[1.0f64, 2.0, 3.0], &dev).unwrap();
        assert_eq!(s.to_vec().unwrap(), vec![1.0, 2.0, 3.0]);

        let v = Array::from_vec(vec![Vec3::X, Vec3::Y], &dev).unwrap();
        assert_eq!(v.to_vec().unwrap(), vec![Vec3::X, Vec3::Y]);
        let empty_vec = Array::<u16>::from_vec(Vec::new(), &dev).unwrap();
        assert!(empty_vec.is_empty() && empty_vec.to_vec().unwrap().is_empty());

        let m = Array::<f32, 4>::from_slice_shape(&iota(24), (2, 3, 2, 2), &dev).unwrap();
        assert_eq!(m.strides(), [12, 4, 2, 1]);
        assert_eq!(m.to_vec().unwrap(), iota(24));
        assert!(m.is_contiguous());

        let empty = Array::<f32, 2>::zeros([0, 5], &dev).unwrap();
        assert!(empty.is_empty() && empty.to_vec().unwrap().is_empty());
        assert!(empty.storage_bytes() == 0);
    }

    #[test]
    fn allocations_are_aligned() {
        let a = Array::<u8>::zeros(3, &cpu()).unwrap();
        assert_eq!(
            a.device_address() % crate::cpu::memory::HOST_ALIGN as u64,
            0
        );
    }

    #[test]
    fn from_slice_length_mismatch() {
        let err = Array::<f32, 2>::from_slice_shape(&[1.0; 5], [2, 3], &cpu()).unwrap_err();
        assert_eq!(
            err.to_string(),
            "invalid argument: from_slice_shape: a slice of 5 elements cannot fill shape [2, 3] \
             (6 elements)"
        );
    }

    #[test]
    fn too_large_is_an_error() {
        assert!(Array::<f64, 2>::zeros([usize::MAX / 2, 3], &cpu()).is_err());
        assert!(Array::<f64>::zeros(usize::MAX / 4, &cpu()).is_err());
    }

    #[test]
    fn fill_and_copy() {
        let dev = cpu();
        let a = Array::<i64, 2>::zeros([2, 2], &dev).unwrap();
        a.fill(-3).unwrap();
        assert_eq!(a.to_vec().unwrap(), vec![-3; 4]);

        let b = Array::<i64, 2>::from_slice_shape(&[1, 2, 3, 4], [2, 2], &dev).unwrap();
        a.copy_from(&b).unwrap();
        assert_eq!(a.to_vec().unwrap(), vec![1, 2, 3, 4]);

        // Strided source: the transpose.
        a.copy_from(&b.transpose()).unwrap();
        assert_eq!(a.to_vec().unwrap(), vec![1, 3, 2, 4]);

        // Overlapping copy within one storage.
        let c = Array::<i32>::from_slice(&[0, 1, 2, 3, 4], &dev).unwrap();
        c.view(1..)
            .unwrap()
            .copy_from(&c.view(..4).unwrap())
            .unwrap();
        assert_eq!(c.to_vec().unwrap(), vec![0, 0, 1, 2, 3]);

        // In-place transpose of a square matrix through the same storage.
        let sq = Array::<i32, 2>::from_slice_shape(&[1, 2, 3, 4], [2, 2], &dev).unwrap();
        sq.copy_from(&sq.transpose()).unwrap();
        assert_eq!(sq.to_vec().unwrap(), vec![1, 3, 2, 4]);
    }

    #[test]
    fn copy_shape_mismatch() {
        let dev = cpu();
        let a = Array::<f32>::zeros(3, &dev).unwrap();
        let b = Array::<f32>::zeros(4, &dev).unwrap();
        assert_eq!(
            a.copy_from(&b).unwrap_err().to_string(),
            "invalid argument: copy between arrays of different shapes: destination [3], source \
             [4]"
        );
    }

    #[test]
    fn views_share_storage() {
        let dev = cpu();
        let a = Array::<f32, 2>::from_slice_shape(&iota(12), [4, 3], &dev).unwrap();
        let v = a.view(1..3).unwrap();
        assert_eq!(v.shape(), [2, 3]);
        assert_eq!(v.to_vec().unwrap(), vec![3.0, 4.0, 5.0, 6.0, 7.0, 8.0]);
        assert!(v.shares_storage_with(&a));
        v.fill(-1.0).unwrap();
        assert_eq!(
            a.to_vec().unwrap(),
            vec![0.0, 1.0, 2.0, -1.0, -1.0, -1.0, -1.0, -1.0, -1.0, 9.0, 10.0, 11.0]
        );
        assert_eq!(a.view(..).unwrap().shape(), [4, 3]);
        assert_eq!(
            a.view(2..=3).unwrap().to_vec().unwrap(),
            a.to_vec().unwrap()[6..]
        );
        assert!(a.view(4..).unwrap().is_empty());

        let r = a.row(3).unwrap();
        assert_eq!(r.to_vec().unwrap(), vec![9.0, 10.0, 11.0]);
        r.fill(0.5).unwrap();
        assert_eq!(a.view(3..).unwrap().to_vec().unwrap(), vec![0.5; 3]);

        // A view of a view.
        let vv = a.view(1..4).unwrap().view(1..2).unwrap();
        assert_eq!(vv.to_vec().unwrap(), vec![-1.0; 3]);

        // Clones share storage.
        let c = a.clone();
        c.fill(2.0).unwrap();
        assert_eq!(a.to_vec().unwrap(), vec![2.0; 12]);
    }

    #[test]
    fn view_out_of_range() {
        let a = Array::<f32, 2>::zeros([4, 3], &cpu()).unwrap();
        let err = a.view(2..5).unwrap_err();
        assert_eq!(
            err.to_string(),
            "invalid argument: view range Included(2)..Excluded(5) is out of bounds for first \
             dimension of extent 4 (shape [4, 3])"
        );
        #[allow(clippy::reversed_empty_ranges)]
        let reversed = a.view(3..1);
        assert!(reversed.is_err());
        assert!(a.view(..=4).is_err());
        assert!(a.row(4).is_err());
    }

    #[test]
    fn transpose_is_strided() {
        let a = Array::<f32, 2>::from_slice_shape(&iota(6), [2, 3], &cpu()).unwrap();
        let t = a.transpose();
        assert_eq!(t.shape(), [3, 2]);
        assert_eq!(t.strides(), [1, 3]);
        assert!(!t.is_contiguous());
        assert_eq!(t.to_vec().unwrap(), vec![0.0, 3.0, 1.0, 4.0, 2.0, 5.0]);
        assert!(t.reshape(6).is_err());
        assert!(t.reinterpret::<Vec2>().is_err());
        t.row(0).unwrap().fill(9.0).unwrap();
        assert_eq!(a.to_vec().unwrap(), vec![9.0, 1.0, 2.0, 9.0, 4.0, 5.0]);
    }

    #[test]
    fn reinterpret_round_trip() {
        let dev = cpu();
        let flat = Array::from_slice(&iota(6), &dev).unwrap();
        let v = flat.reinterpret::<Vec3>().unwrap();
        assert_eq!(
            v.to_vec().unwrap(),
            vec![Vec3::new(0.0, 1.0, 2.0), Vec3::new(3.0, 4.0, 5.0)]
        );
        v.fill(Vec3::splat(1.5)).unwrap();
        assert_eq!(flat.to_vec().unwrap(), vec![1.5; 6]);
        let back = v.reinterpret::<f32>().unwrap();
        assert_eq!(back.shape(), [6]);
        assert!(back.shares_storage_with(&flat));

        // Sizes that do not divide.
        let err = Array::from_slice(&iota(4), &dev)
            .unwrap()
            .reinterpret::<Vec3>()
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            "invalid argument: cannot reinterpret an array of f32 with shape [4] as Vec3: 16 \
             bytes are not a multiple of 12, the size of the type"
        );

        // A 2-D contiguous array flattens.
        let m = Array::<f32, 2>::from_slice_shape(&iota(8), [2, 4], &dev).unwrap();
        assert_eq!(m.reinterpret::<Vec4>().unwrap().len(), 2);
        // Misaligned start for a 16-byte-aligned type (where Vec4 is SIMD-aligned).
        let off = Array::from_slice(&iota(8), &dev)
            .unwrap()
            .view(1..5)
            .unwrap();
        let r = off.reinterpret::<Vec4>();
        if std::mem::align_of::<Vec4>() > 4 {
            assert!(r.is_err());
        } else {
            assert_eq!(
                r.unwrap().to_vec().unwrap(),
                vec![Vec4::new(1.0, 2.0, 3.0, 4.0)]
            );
        }
        // bytemuck's cast_slice gives the same zero-copy view on the host side.
        let data = iota(6);
        let vs: &[Vec3] = bytemuck::cast_slice(&data);
        assert_eq!(
            Array::from_slice(vs, &dev).unwrap().to_vec().unwrap(),
            vec![Vec3::new(0.0, 1.0, 2.0), Vec3::new(3.0, 4.0, 5.0)]
        );
    }

    #[test]
    fn reshape_round_trip() {
        let dev = cpu();
        let a = Array::from_slice(&iota(12), &dev).unwrap();
        let m = a.reshape((3, 4)).unwrap();
        assert_eq!(m.shape(), [3, 4]);
        assert_eq!(m.strides(), [4, 1]);
        assert_eq!(
            m.row(1).unwrap().to_vec().unwrap(),
            vec![4.0, 5.0, 6.0, 7.0]
        );
        let c = m.reshape([2, 3, 2]).unwrap();
        assert_eq!(c.to_vec().unwrap(), iota(12));
        assert_eq!(c.reshape(12).unwrap().to_vec().unwrap(), iota(12));
        // A view of rows stays contiguous and reshapes.
        assert_eq!(
            m.view(1..3).unwrap().reshape(8).unwrap().to_vec().unwrap(),
            iota(12)[4..]
        );
        let err = a.reshape([5, 2]).unwrap_err();
        assert_eq!(
            err.to_string(),
            "invalid argument: cannot reshape an array of shape [12] (12 elements) to shape [5, \
             2] (10 elements)"
        );
    }

    #[test]
    fn debug_prints_head() {
        let a = Array::from_slice(&[1i32, 2, 3], &cpu()).unwrap();
        assert_eq!(
            format!("{a:?}"),
            "Array<i32, 1> { shape: [3], device: cpu, data: [1, 2, 3] }"
        );
        let b = Array::<u8>::zeros(10, &cpu()).unwrap();
        assert_eq!(
            format!("{b:?}"),
            "Array<u8, 1> { shape: [10], device: cpu, data: [0, 0, 0, 0, 0, 0, 0, 0] (first 8 of \
             10) }"
        );
    }

    #[test]
    fn kernel_arg_checks_device() {
        let dev = cpu();
        let a = Array::<f32>::zeros(3, &dev).unwrap();
        let fake = Device::fake_cuda(0);
        let ctx = ArgCtx {
            kernel: "k",
            arg: "x",
            index: 0,
            device: &fake,
        };
        // SAFETY: the view is not used after `a`.
        let Err(err) = (unsafe { <Array<f32> as KernelArg>::cpu_view(&&a, &ctx) }) else {
            panic!("a CPU array passed to a CUDA launch must be rejected")
        };
        assert_eq!(
            err.to_string(),
            "kernel `k`: argument `x` is on device \"cpu\" but the launch is on device \"cuda:0\""
        );
        let ctx = ArgCtx {
            kernel: "k",
            arg: "x",
            index: 0,
            device: &dev,
        };
        // SAFETY: the view is not used after `a`.
        let view = unsafe { <Array<f32> as KernelArg>::cpu_view(&&a, &ctx) }.unwrap();
        view.store(2usize, 4.0).unwrap();
        assert_eq!(a.to_vec().unwrap(), vec![0.0, 0.0, 4.0]);
        assert_eq!(<Array<f32> as KernelArg>::shape(&&a), Some(vec![3]));
        // SAFETY: a value argument borrows nothing.
        assert_eq!(
            unsafe { <f32 as KernelArg>::cpu_view(&2.5, &ctx) }.unwrap(),
            2.5
        );
        assert_eq!(<Vec3 as KernelArg>::shape(&Vec3::ONE), None);
        // Without a GPU, memory on "cuda:0" cannot be had; with one, it can.
        assert_eq!(
            Array::<f32>::zeros(3, &fake).is_ok(),
            crate::device::init().cuda_available()
        );
    }
}

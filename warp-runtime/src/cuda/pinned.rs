//! Page-locked host memory for asynchronous copies between the host and a GPU.
//!
//! A copy from ordinary (pageable) host memory makes the CPU wait while the driver stages it;
//! a copy from or to a [`PinnedVec`] is queued and returns at once, so the CPU can prepare the
//! next batch while the GPU copies and computes. Safe Rust all the same: a copy in flight
//! holds the `PinnedVec` mutably, and reading or writing its elements waits for the copies
//! queued on it.

use super::gpu;
use super::memory::CudaBuffer;
use crate::array::{Array, Element};
use crate::device::{Device, DeviceKind};
use crate::error::{Error, Result};
use std::marker::PhantomData;

/// A vector of `T` in page-locked host memory, paired with one GPU for asynchronous copies
/// ([`Array::copy_from_pinned_async`], [`Array::copy_to_pinned_async`]).
#[derive(Debug)]
pub struct PinnedVec<T: Element> {
    buf: warp_cuda::PinnedBuffer,
    device: Device,
    len: usize,
    _elem: PhantomData<T>,
}

impl<T: Element> PinnedVec<T> {
    /// `len` zeros in page-locked memory, for copies with the GPU `device`.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when `device` is the CPU; [`Error::OutOfMemory`] (naming
    /// `device`, the driver's error as its source) when there is not enough page-locked
    /// memory; [`Error::Cuda`] when the driver fails otherwise.
    pub fn zeros(len: usize, device: &Device) -> Result<Self> {
        let DeviceKind::Cuda { ordinal } = device.kind() else {
            return Err(Error::invalid(format!(
                "pinned memory pairs with a CUDA device, got \"{device}\""
            )));
        };
        let bytes = len.checked_mul(std::mem::size_of::<T>()).ok_or_else(|| {
            Error::invalid(format!("{len} elements of {} overflow", T::TYPE_NAME))
        })?;
        let gpu = gpu::state(device, ordinal)?.gpu.clone();
        let buf = warp_cuda::PinnedBuffer::new(&gpu, bytes)
            .map_err(|e| Error::cuda_alloc(device.alias(), bytes, e))?;
        Ok(PinnedVec {
            buf,
            device: device.clone(),
            len,
            _elem: PhantomData,
        })
    }

    /// A copy of `data` in page-locked memory.
    pub fn from_slice(data: &[T], device: &Device) -> Result<Self> {
        let mut v = Self::zeros(data.len(), device)?;
        v.as_mut_slice().copy_from_slice(data);
        Ok(v)
    }

    /// The number of elements.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether there are no elements.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The GPU this memory pairs with.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// The elements, once the copies queued on this vector have finished.
    pub fn as_slice(&self) -> &[T] {
        bytemuck::cast_slice(self.buf.as_slice())
    }

    /// The elements, mutably, once the copies queued on this vector have finished.
    pub fn as_mut_slice(&mut self) -> &mut [T] {
        bytemuck::cast_slice_mut(self.buf.as_mut_slice())
    }

    /// Waits for the copies queued on this vector.
    pub fn synchronize(&self) -> Result<()> {
        self.buf
            .synchronize()
            .map_err(|e| gpu::err(&self.device, e))
    }
}

impl<T: Element, const N: usize> Array<T, N> {
    /// Checks that `self` (a contiguous array on `pinned`'s GPU) and `pinned` hold the same
    /// number of elements; returns the array's GPU ordinal, memory, byte offset and length.
    fn pinned_peer(
        &self,
        pinned: &PinnedVec<T>,
        what: &str,
    ) -> Result<(usize, &CudaBuffer, usize, usize)> {
        let DeviceKind::Cuda { ordinal } = self.device().kind() else {
            return Err(Error::invalid(format!(
                "{what}: the array is on \"{}\"; asynchronous copies are between pinned memory \
                 and a GPU",
                self.device()
            )));
        };
        if self.device() != pinned.device() {
            return Err(Error::invalid(format!(
                "{what}: the array is on \"{}\", the pinned memory pairs with \"{}\"",
                self.device(),
                pinned.device()
            )));
        }
        if !self.is_contiguous() || self.len() != pinned.len() {
            return Err(Error::invalid(format!(
                "{what}: needs a contiguous array of {} elements, got shape {:?}{}",
                pinned.len(),
                self.shape(),
                if self.is_contiguous() {
                    ""
                } else {
                    " (strided)"
                }
            )));
        }
        let (storage, offset, bytes) = self.contiguous_range();
        let buf = storage
            .cuda()
            .expect("an array on a CUDA device lives in CUDA memory");
        Ok((ordinal, buf, offset, bytes))
    }

    /// Queues a copy of `src` into this GPU array on the calling thread's current stream and
    /// returns at once. `src` stays borrowed by the copy: touching its elements again waits.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] when the array is not a contiguous array on `src`'s GPU with
    /// `src.len()` elements.
    pub fn copy_from_pinned_async(&self, src: &mut PinnedVec<T>) -> Result<()> {
        let (ordinal, buf, off, bytes) = self.pinned_peer(src, "copy_from_pinned_async")?;
        // The pinned buffer tracks its copies with events, which a graph cannot replay.
        gpu::refuse_in_capture(ordinal, "copy_from_pinned_async")?;
        let buf = buf.device_buffer();
        let st = gpu::state(self.device(), ordinal)?;
        st.queue(ordinal, None, |s| {
            src.buf
                .copy_to_device_async(0, buf, off, bytes, s)
                .map_err(|e| gpu::err(self.device(), e))
        })
    }

    /// Queues a copy of this GPU array into `dst` on the calling thread's current stream and
    /// returns at once; `dst.as_slice()` waits for it.
    ///
    /// # Errors
    /// As [`copy_from_pinned_async`](Self::copy_from_pinned_async).
    pub fn copy_to_pinned_async(&self, dst: &mut PinnedVec<T>) -> Result<()> {
        let (ordinal, buf, off, bytes) = self.pinned_peer(dst, "copy_to_pinned_async")?;
        // The pinned buffer tracks its copies with events, which a graph cannot replay.
        gpu::refuse_in_capture(ordinal, "copy_to_pinned_async")?;
        let buf = buf.device_buffer();
        let st = gpu::state(self.device(), ordinal)?;
        st.queue(ordinal, None, |s| {
            dst.buf
                .copy_from_device_async(0, buf, off, bytes, s)
                .map_err(|e| gpu::err(self.device(), e))
        })
    }
}

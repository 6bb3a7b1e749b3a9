//! GPU memory: what arrays on a GPU live in.

use super::gpu::{self, join_ordinal};
use crate::backend::Buffer;
use crate::device::Device;
use crate::error::{Error, Result};
use warp_cuda::{CudaError, DeviceBuffer};

/// An allocation on one GPU. Every operation first orders itself after the user streams'
/// kernels (the ordering model of `gpu.rs`), then runs on the GPU's default stream.
pub(crate) struct CudaBuffer {
    inner: DeviceBuffer,
    /// What keeps external memory alive ([`CudaBuffer::external`]): dropped after the GPU has
    /// finished the work queued on it.
    owner: Option<Box<dyn std::any::Any + Send + Sync>>,
}

impl CudaBuffer {
    /// `bytes` of zeroed memory on GPU `ordinal` (`device`).
    pub(crate) fn zeros(device: &Device, ordinal: usize, bytes: usize) -> Result<CudaBuffer> {
        gpu::refuse_in_capture(ordinal, "an allocation")?;
        let g = gpu::gpu(ordinal)?;
        let inner = DeviceBuffer::zeros(&g, bytes)
            .map_err(|e| Error::cuda_alloc(device.alias(), bytes, e))?;
        Ok(CudaBuffer { inner, owner: None })
    }

    /// External device memory: `bytes` bytes at `ptr` on GPU `ordinal`, not freed here;
    /// `owner` is dropped with the buffer, once the work queued on the memory has finished.
    ///
    /// # Safety
    /// As [`DeviceBuffer::from_raw`]: device memory of that GPU's context, allocated for as
    /// long as `owner` lives (or forever, without one).
    pub(crate) unsafe fn external(
        ordinal: usize,
        ptr: u64,
        bytes: usize,
        owner: Option<Box<dyn std::any::Any + Send + Sync>>,
    ) -> Result<CudaBuffer> {
        let g = gpu::gpu(ordinal)?;
        // SAFETY: the caller's contract.
        let inner = unsafe { DeviceBuffer::from_raw(&g, ptr, bytes) };
        Ok(CudaBuffer { inner, owner })
    }

    /// The driver's buffer (for asynchronous copies with pinned memory).
    pub(crate) fn device_buffer(&self) -> &DeviceBuffer {
        &self.inner
    }

    fn ordinal(&self) -> usize {
        self.inner.gpu().ordinal()
    }

    /// A driver error as a runtime error naming this buffer's GPU.
    fn err(&self, e: CudaError) -> Error {
        Error::cuda(format!("cuda:{}", self.ordinal()), e)
    }
}

impl Buffer for CudaBuffer {
    fn len(&self) -> usize {
        self.inner.len()
    }

    fn address(&self) -> u64 {
        self.inner.device_ptr()
    }

    fn read(&self, offset: usize, out: &mut [u8]) -> Result<()> {
        gpu::refuse_in_capture(self.ordinal(), "a read-back to the host")?;
        join_ordinal(self.ordinal())?;
        self.inner.download(offset, out).map_err(|e| self.err(e))
    }

    fn write(&self, offset: usize, data: &[u8]) -> Result<()> {
        gpu::refuse_in_capture(self.ordinal(), "an upload from host memory")?;
        join_ordinal(self.ordinal())?;
        self.inner.upload(offset, data).map_err(|e| self.err(e))
    }

    fn fill(&self, offset: usize, bytes: usize, pattern: &[u8]) -> Result<()> {
        if let Some(capture) = gpu::capture_stream(self.ordinal()) {
            return self
                .inner
                .fill_pattern_on(&capture, offset, bytes, pattern)
                .map_err(|e| self.err(e));
        }
        join_ordinal(self.ordinal())?;
        self.inner
            .fill_pattern(offset, bytes, pattern)
            .map_err(|e| self.err(e))
    }

    fn copy_from(&self, offset: usize, src: &Self, src_offset: usize, bytes: usize) -> Result<()> {
        if let Some(capture) = gpu::capture_stream(self.ordinal()) {
            return self
                .inner
                .copy_from_device_on(&capture, offset, &src.inner, src_offset, bytes)
                .map_err(|e| self.err(e));
        }
        join_ordinal(self.ordinal())?;
        self.inner
            .copy_from_device(offset, &src.inner, src_offset, bytes)
            .map_err(|e| self.err(e))
    }
}

impl Drop for CudaBuffer {
    fn drop(&mut self) {
        // The buffer's free is queued on the default stream: order it after the kernels of
        // user streams that may still use the memory. A failure here means the context is
        // broken, which the next fallible call reports.
        let _ = join_ordinal(self.ordinal());
        if let Some(owner) = self.owner.take() {
            // External memory: its owner may free it as soon as it drops, so first wait for
            // every kernel and copy queued on it (the default stream now follows them all).
            let _ = self.inner.gpu().default_stream().synchronize();
            drop(owner);
        }
    }
}

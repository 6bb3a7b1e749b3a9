//! Device and pinned host memory.
//!
//! [`DeviceBuffer`] is untyped: the runtime's typed arrays sit on top and know element sizes and
//! shapes. Everything a buffer does is issued on its device's default stream
//! ([`Gpu::default_stream`]), so its allocation, uploads, fills, kernel launches on that stream,
//! downloads and its free are ordered without host synchronisation. Work on other streams must
//! be ordered against the default stream by the caller ([`Stream::wait_stream`]) — in
//! particular, a buffer must not be dropped while another stream may still use it, because its
//! stream-ordered free only waits for the default stream.

use std::ffi::c_void;
use std::ptr::NonNull;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use cudarc::driver::sys;

use crate::device::{Event, Gpu, Stream};
use crate::error::{CudaError, Result};

/// Checks `offset..offset + len` against a buffer of `size` bytes without overflowing.
fn check_range(offset: usize, len: usize, size: usize, what: &str) -> Result<()> {
    match offset.checked_add(len) {
        Some(end) if end <= size => Ok(()),
        _ => Err(CudaError::InvalidArgument(format!(
            "{what}: range {offset}..{offset}+{len} is outside a buffer of {size} bytes"
        ))),
    }
}

/// Whether `ptr` lies in page-locked (pinned or registered) host memory. An async copy from
/// pinned memory really is asynchronous, unlike one from pageable memory, which returns only
/// once the data is staged.
///
/// `cuPointerGetAttributes` (plural) rather than `cuPointerGetAttribute`: for memory the driver
/// does not know (pageable host memory, the common case) the singular form fails with
/// `CUDA_ERROR_INVALID_VALUE`, which compute-sanitizer reports as an API error on every copy,
/// while the plural form succeeds and leaves the memory type 0.
fn is_page_locked(ptr: *const u8) -> bool {
    let mut kind: u32 = 0;
    let mut attribute = sys::CUpointer_attribute::CU_POINTER_ATTRIBUTE_MEMORY_TYPE;
    let mut data = [&mut kind as *mut u32 as *mut c_void];
    // SAFETY: one attribute, MEMORY_TYPE, which writes one unsigned int through `data[0]`.
    let r = unsafe {
        sys::cuPointerGetAttributes(
            1,
            &mut attribute,
            data.as_mut_ptr(),
            ptr as sys::CUdeviceptr,
        )
    };
    r == sys::CUresult::CUDA_SUCCESS && kind == sys::CUmemorytype::CU_MEMORYTYPE_HOST as u32
}

/// The ordinal of the GPU whose memory `ptr` addresses (a buffer another library allocated:
/// an XLA operand), or `None` for memory the driver does not know as a device's (host memory,
/// a dangling address). The plural `cuPointerGetAttributes` for the reason given at
/// `is_page_locked`: unknown memory is not an API error.
pub fn pointer_device_ordinal(ptr: u64) -> Option<usize> {
    let mut ordinal: i32 = -1;
    let mut attribute = sys::CUpointer_attribute::CU_POINTER_ATTRIBUTE_DEVICE_ORDINAL;
    let mut data = [&mut ordinal as *mut i32 as *mut c_void];
    // SAFETY: one attribute, DEVICE_ORDINAL, which writes one int through `data[0]`.
    let r = unsafe {
        sys::cuPointerGetAttributes(
            1,
            &mut attribute,
            data.as_mut_ptr(),
            ptr as sys::CUdeviceptr,
        )
    };
    match r == sys::CUresult::CUDA_SUCCESS {
        true => usize::try_from(ordinal).ok(),
        false => None,
    }
}

/// The shortest prefix length `d` (dividing the length) such that `pattern` is that prefix
/// repeated.
fn minimal_period(pattern: &[u8]) -> usize {
    let n = pattern.len();
    (1..n)
        .filter(|d| n.is_multiple_of(*d))
        .find(|&d| (d..n).all(|i| pattern[i] == pattern[i - d]))
        .unwrap_or(n)
}

/// Largest host buffer built by [`DeviceBuffer::fill_pattern`] for patterns that the memset
/// family cannot express; the rest of the range is filled by doubling device-to-device copies.
const FILL_CHUNK: usize = 1 << 20;

/// An untyped allocation of device memory on one GPU.
///
/// Zero-byte buffers allocate nothing and have device pointer 0. Dropping frees the memory
/// (stream-ordered when the device supports it). All methods take `&self`: device memory is
/// not Rust memory, and ordering is given by the stream (see the module docs).
pub struct DeviceBuffer {
    ptr: u64,
    bytes: usize,
    gpu: Arc<Gpu>,
    /// False for memory wrapped by [`DeviceBuffer::from_raw`]: not freed on drop.
    owned: bool,
}

impl std::fmt::Debug for DeviceBuffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "DeviceBuffer({} bytes at {:#x} on cuda:{})",
            self.bytes,
            self.ptr,
            self.gpu.ordinal()
        )
    }
}

impl DeviceBuffer {
    /// Allocates `bytes` bytes whose contents are unspecified (reading them is harmless but
    /// yields arbitrary values). Use before overwriting the whole buffer.
    pub fn alloc(gpu: &Arc<Gpu>, bytes: usize) -> Result<Self> {
        if bytes == 0 {
            return Ok(DeviceBuffer {
                ptr: 0,
                bytes: 0,
                gpu: gpu.clone(),
                owned: true,
            });
        }
        gpu.bind()?;
        let mut ptr: sys::CUdeviceptr = 0;
        let stream = gpu.default_stream();
        let (call, r) = if gpu.has_async_alloc() {
            // SAFETY: out-parameter call on a live stream of the bound context.
            let r = unsafe { sys::cuMemAllocAsync(&mut ptr, bytes, stream.cu_stream()) };
            ("cuMemAllocAsync", r)
        } else {
            // SAFETY: out-parameter call in the bound context.
            ("cuMemAlloc", unsafe { sys::cuMemAlloc_v2(&mut ptr, bytes) })
        };
        r.result().map_err(|e| {
            CudaError::driver(
                e,
                format!("{call} of {bytes} bytes on cuda:{}", gpu.ordinal()),
            )
        })?;
        Ok(DeviceBuffer {
            ptr,
            bytes,
            gpu: gpu.clone(),
            owned: true,
        })
    }

    /// Wraps `bytes` bytes of device memory at `ptr` that something else allocated (another
    /// library, CUDA IPC): the buffer uses it like its own but never frees it.
    ///
    /// # Safety
    /// `ptr..ptr + bytes` must be device memory addressable in `gpu`'s context and stay
    /// allocated for as long as the buffer (and any copy of its pointer) is used.
    pub unsafe fn from_raw(gpu: &Arc<Gpu>, ptr: u64, bytes: usize) -> Self {
        DeviceBuffer {
            ptr,
            bytes,
            gpu: gpu.clone(),
            owned: false,
        }
    }

    /// Allocates `bytes` bytes set to zero (the memset is queued, not waited for).
    pub fn zeros(gpu: &Arc<Gpu>, bytes: usize) -> Result<Self> {
        let buf = Self::alloc(gpu, bytes)?;
        buf.fill_pattern(0, bytes, &[0])?;
        Ok(buf)
    }

    /// Allocates a buffer holding a copy of `data`.
    pub fn from_bytes(gpu: &Arc<Gpu>, data: &[u8]) -> Result<Self> {
        let buf = Self::alloc(gpu, data.len())?;
        buf.upload(0, data)?;
        Ok(buf)
    }

    /// Size in bytes.
    pub fn len(&self) -> usize {
        self.bytes
    }

    /// Whether the buffer has zero bytes.
    pub fn is_empty(&self) -> bool {
        self.bytes == 0
    }

    /// The device address (0 for a zero-byte buffer), as kernels receive it.
    pub fn device_ptr(&self) -> u64 {
        self.ptr
    }

    /// The device this buffer lives on.
    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    fn stream(&self) -> &Stream {
        self.gpu.default_stream()
    }

    /// Copies `data` into the buffer at byte `offset` (queued on the default stream, after
    /// earlier work). When it returns, `data` may be reused: the driver stages pageable memory
    /// before returning, and for page-locked memory we wait for the copy.
    pub fn upload(&self, offset: usize, data: &[u8]) -> Result<()> {
        check_range(offset, data.len(), self.bytes, "upload")?;
        if data.is_empty() {
            return Ok(());
        }
        self.gpu.bind()?;
        let stream = self.stream();
        // SAFETY: the range was checked; `data` is valid for reads for the duration of the
        // call, and beyond it only if page-locked, in which case we synchronise below.
        unsafe {
            sys::cuMemcpyHtoDAsync_v2(
                self.ptr + offset as u64,
                data.as_ptr() as *const c_void,
                data.len(),
                stream.cu_stream(),
            )
        }
        .result()
        .map_err(|e| self.op_err(e, "cuMemcpyHtoDAsync", data.len()))?;
        if is_page_locked(data.as_ptr()) {
            stream.synchronize()?;
        }
        Ok(())
    }

    /// Copies bytes from the buffer at `offset` into `out`, after all work queued so far on the
    /// default stream; waits for the copy.
    pub fn download(&self, offset: usize, out: &mut [u8]) -> Result<()> {
        check_range(offset, out.len(), self.bytes, "download")?;
        if out.is_empty() {
            return Ok(());
        }
        self.gpu.bind()?;
        let stream = self.stream();
        // SAFETY: range checked; `out` stays borrowed until the stream is synchronised below.
        unsafe {
            sys::cuMemcpyDtoHAsync_v2(
                out.as_mut_ptr() as *mut c_void,
                self.ptr + offset as u64,
                out.len(),
                stream.cu_stream(),
            )
        }
        .result()
        .map_err(|e| self.op_err(e, "cuMemcpyDtoHAsync", out.len()))?;
        stream.synchronize()
    }

    /// Downloads the whole buffer.
    pub fn to_vec(&self) -> Result<Vec<u8>> {
        let mut v = vec![0u8; self.bytes];
        self.download(0, &mut v)?;
        Ok(v)
    }

    /// Copies `bytes` bytes from `src` at `src_off` into this buffer at `dst_off`, queued.
    ///
    /// On one device this is a `cuMemcpyDtoDAsync` on the default stream. Across devices it is
    /// a `cuMemcpyPeerAsync` on this buffer's default stream, which first waits for `src`'s
    /// default stream; `src`'s default stream then waits for the copy, so later writes to or the
    /// free of `src` cannot overtake it. Overlapping ranges of the same memory are rejected.
    pub fn copy_from_device(
        &self,
        dst_off: usize,
        src: &DeviceBuffer,
        src_off: usize,
        bytes: usize,
    ) -> Result<()> {
        check_range(dst_off, bytes, self.bytes, "copy_from_device (destination)")?;
        check_range(src_off, bytes, src.bytes, "copy_from_device (source)")?;
        if bytes == 0 {
            return Ok(());
        }
        let dst = self.ptr + dst_off as u64;
        let sp = src.ptr + src_off as u64;
        let same_device = self.gpu.ordinal() == src.gpu.ordinal();
        if same_device && dst < sp + bytes as u64 && sp < dst + bytes as u64 {
            return Err(CudaError::InvalidArgument(format!(
                "copy_from_device: overlapping ranges ({bytes} bytes from {sp:#x} to {dst:#x})"
            )));
        }
        let stream = self.stream();
        if same_device {
            self.copy_within_device(stream, dst, sp, bytes)
        } else {
            stream.wait_stream(src.stream())?;
            self.gpu.bind()?;
            // SAFETY: both ranges checked; each context owns its pointer; ordering as documented.
            unsafe {
                sys::cuMemcpyPeerAsync(
                    dst,
                    self.gpu.cu_ctx(),
                    sp,
                    src.gpu.cu_ctx(),
                    bytes,
                    stream.cu_stream(),
                )
            }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!(
                        "cuMemcpyPeerAsync of {bytes} bytes from cuda:{} to cuda:{}",
                        src.gpu.ordinal(),
                        self.gpu.ordinal()
                    ),
                )
            })?;
            src.stream().wait_stream(stream)
        }
    }

    /// [`copy_from_device`](Self::copy_from_device) queued on `stream` (a stream of this
    /// buffer's device, ordered by the caller), for buffers of one device: what a graph
    /// capture records as a copy node.
    pub fn copy_from_device_on(
        &self,
        stream: &Stream,
        dst_off: usize,
        src: &DeviceBuffer,
        src_off: usize,
        bytes: usize,
    ) -> Result<()> {
        check_range(dst_off, bytes, self.bytes, "copy_from_device (destination)")?;
        check_range(src_off, bytes, src.bytes, "copy_from_device (source)")?;
        let (ordinal, src_ordinal) = (self.gpu.ordinal(), src.gpu.ordinal());
        if stream.ordinal() != ordinal || src_ordinal != ordinal {
            return Err(CudaError::InvalidArgument(format!(
                "copy_from_device_on: a copy from cuda:{src_ordinal} to cuda:{ordinal} on a \
                 stream of cuda:{} (only copies within the stream's device)",
                stream.ordinal()
            )));
        }
        if bytes == 0 {
            return Ok(());
        }
        let dst = self.ptr + dst_off as u64;
        let sp = src.ptr + src_off as u64;
        if dst < sp + bytes as u64 && sp < dst + bytes as u64 {
            return Err(CudaError::InvalidArgument(format!(
                "copy_from_device: overlapping ranges ({bytes} bytes from {sp:#x} to {dst:#x})"
            )));
        }
        self.copy_within_device(stream, dst, sp, bytes)
    }

    /// `cuMemcpyDtoDAsync` of checked, disjoint ranges of this device on `stream`.
    fn copy_within_device(&self, stream: &Stream, dst: u64, src: u64, bytes: usize) -> Result<()> {
        self.gpu.bind()?;
        // SAFETY: the caller checked both ranges (live buffers of this device, disjoint).
        unsafe { sys::cuMemcpyDtoDAsync_v2(dst, src, bytes, stream.cu_stream()) }
            .result()
            .map_err(|e| self.op_err(e, "cuMemcpyDtoDAsync", bytes))
    }

    /// Fills `bytes` bytes at `offset` with `pattern` repeated (`bytes` must be a multiple of
    /// the pattern's length), queued on the default stream.
    ///
    /// Patterns of 1, 2 and 4 bytes use `cuMemsetD8/D16/D32Async` (when the address is aligned
    /// for the element size); other patterns upload one host chunk of the repeated pattern and
    /// double it with device-to-device copies, so the host never builds the whole range.
    pub fn fill_pattern(&self, offset: usize, bytes: usize, pattern: &[u8]) -> Result<()> {
        self.fill_pattern_on(self.stream(), offset, bytes, pattern)
    }

    /// [`fill_pattern`](Self::fill_pattern) queued on `stream` (a stream of this buffer's
    /// device; ordering it is the caller's job). On a stream other than the default one,
    /// patterns that no single memset covers are written by one pitched memset per element
    /// of the pattern (`cuMemsetD2D*Async`, the pattern's length as the pitch) instead of an
    /// upload: nothing is read from host memory, so the fill can be captured into a graph.
    pub fn fill_pattern_on(
        &self,
        stream: &Stream,
        offset: usize,
        bytes: usize,
        pattern: &[u8],
    ) -> Result<()> {
        if stream.ordinal() != self.gpu.ordinal() {
            return Err(CudaError::InvalidArgument(format!(
                "fill_pattern: a buffer of cuda:{} filled on a stream of cuda:{}",
                self.gpu.ordinal(),
                stream.ordinal()
            )));
        }
        let p = pattern.len();
        if p == 0 {
            return Err(CudaError::InvalidArgument(
                "fill_pattern: empty pattern".into(),
            ));
        }
        if !bytes.is_multiple_of(p) {
            return Err(CudaError::InvalidArgument(format!(
                "fill_pattern: {bytes} bytes is not a multiple of the {p}-byte pattern"
            )));
        }
        check_range(offset, bytes, self.bytes, "fill_pattern")?;
        if bytes == 0 {
            return Ok(());
        }
        // A pattern that repeats a shorter one (a zero f64, [1, 2, 1, 2]) is filled with the
        // shorter one, so more patterns take the memset path.
        let pattern = &pattern[..minimal_period(pattern)];
        let p = pattern.len();
        let dst = self.ptr + offset as u64;
        let cu_stream = stream.cu_stream();
        let aligned = |n: u64| dst.is_multiple_of(n);
        if p == 1 || (p == 2 && aligned(2)) || (p == 4 && aligned(4)) {
            self.gpu.bind()?;
            // SAFETY: range checked, pointer live and aligned for the element size, queued on
            // the default stream.
            let (call, r) = unsafe {
                match p {
                    1 => (
                        "cuMemsetD8Async",
                        sys::cuMemsetD8Async(dst, pattern[0], bytes, cu_stream),
                    ),
                    2 => {
                        let v = u16::from_le_bytes([pattern[0], pattern[1]]);
                        (
                            "cuMemsetD16Async",
                            sys::cuMemsetD16Async(dst, v, bytes / 2, cu_stream),
                        )
                    }
                    _ => {
                        let v =
                            u32::from_le_bytes([pattern[0], pattern[1], pattern[2], pattern[3]]);
                        (
                            "cuMemsetD32Async",
                            sys::cuMemsetD32Async(dst, v, bytes / 4, cu_stream),
                        )
                    }
                }
            };
            return r.result().map_err(|e| self.op_err(e, call, bytes));
        }
        if !stream.is(self.stream()) {
            return self.fill_columns(stream, dst, bytes, pattern);
        }
        // General pattern: one chunk of whole patterns from the host, then doubling copies.
        let chunk_len = bytes.min((FILL_CHUNK / p).max(1) * p);
        let chunk: Vec<u8> = pattern.iter().copied().cycle().take(chunk_len).collect();
        self.upload(offset, &chunk)?;
        let mut filled = chunk_len;
        while filled < bytes {
            let n = filled.min(bytes - filled);
            // [offset, offset+n) and [offset+filled, ..+n) are disjoint since n <= filled, and
            // both start on a pattern boundary since `filled` is a multiple of `p`.
            self.copy_from_device(offset + filled, self, offset, n)?;
            filled += n;
        }
        Ok(())
    }

    /// Fills `bytes` at device address `dst` with `pattern` (its minimal period) on `stream`
    /// by pitched memsets: the pattern is cut into elements of the widest size (4, 2 or 1
    /// bytes) that divides its length and `dst`'s alignment, and element `k` of every
    /// repetition is set by one `cuMemsetD2D*Async` whose rows are the repetitions.
    fn fill_columns(&self, stream: &Stream, dst: u64, bytes: usize, pattern: &[u8]) -> Result<()> {
        let p = pattern.len();
        let e = [4usize, 2, 1]
            .into_iter()
            .find(|&e| p.is_multiple_of(e) && dst.is_multiple_of(e as u64))
            .unwrap_or(1);
        let rows = bytes / p;
        self.gpu.bind()?;
        for (k, word) in pattern.chunks_exact(e).enumerate() {
            let at = dst + (k * e) as u64;
            // SAFETY: rows * p bytes from dst were range-checked by the caller; each memset
            // writes element k (e bytes) of each of the `rows` repetitions, aligned for `e`.
            let (call, r) = unsafe {
                match e {
                    4 => {
                        let v = u32::from_le_bytes([word[0], word[1], word[2], word[3]]);
                        let r = sys::cuMemsetD2D32Async(at, p, v, 1, rows, stream.cu_stream());
                        ("cuMemsetD2D32Async", r)
                    }
                    2 => {
                        let v = u16::from_le_bytes([word[0], word[1]]);
                        let r = sys::cuMemsetD2D16Async(at, p, v, 1, rows, stream.cu_stream());
                        ("cuMemsetD2D16Async", r)
                    }
                    _ => {
                        let r = sys::cuMemsetD2D8Async(at, p, word[0], 1, rows, stream.cu_stream());
                        ("cuMemsetD2D8Async", r)
                    }
                }
            };
            r.result().map_err(|err| self.op_err(err, call, bytes))?;
        }
        Ok(())
    }

    fn op_err(
        &self,
        e: cudarc::driver::result::DriverError,
        call: &str,
        bytes: usize,
    ) -> CudaError {
        CudaError::driver(
            e,
            format!("{call} of {bytes} bytes on cuda:{}", self.gpu.ordinal()),
        )
    }
}

impl Drop for DeviceBuffer {
    fn drop(&mut self) {
        if self.bytes == 0 || !self.owned {
            return;
        }
        // Errors cannot be returned from drop; a failing free means the context is already
        // broken, which the next fallible call reports.
        if self.gpu.bind().is_err() {
            return;
        }
        let stream = self.gpu.default_stream();
        // SAFETY: allocated by us in this context, freed once; stream-ordered after all work
        // queued on the default stream (other streams: see the module docs).
        unsafe {
            if self.gpu.has_async_alloc() {
                let _ = sys::cuMemFreeAsync(self.ptr, stream.cu_stream());
            } else {
                let _ = stream.synchronize();
                let _ = sys::cuMemFree_v2(self.ptr);
            }
        }
    }
}

/// Page-locked host memory, for asynchronous copies to and from one device.
///
/// Safe to use: each async copy records an event, and [`as_slice`](Self::as_slice),
/// [`as_mut_slice`](Self::as_mut_slice) and drop wait for the copies in flight, so the host
/// never reads or writes bytes that a DMA is still touching. The copies take `&mut self`, so no
/// slice can be alive while one is queued. Successive copies on different streams are chained
/// (each stream waits for the previous copy's event) so one event covers them all.
pub struct PinnedBuffer {
    ptr: NonNull<u8>,
    len: usize,
    gpu: Arc<Gpu>,
    event: Option<Event>,
    in_flight: AtomicBool,
}

// SAFETY: the buffer owns its allocation; shared access only reads the bytes (after waiting for
// DMA writes), and everything that starts DMA takes `&mut self`.
unsafe impl Send for PinnedBuffer {}
unsafe impl Sync for PinnedBuffer {}

impl std::fmt::Debug for PinnedBuffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "PinnedBuffer({} bytes for cuda:{})",
            self.len,
            self.gpu.ordinal()
        )
    }
}

impl PinnedBuffer {
    /// Allocates `bytes` bytes of zeroed page-locked memory (`cuMemHostAlloc`, portable across
    /// contexts) for async copies with `gpu`.
    pub fn new(gpu: &Arc<Gpu>, bytes: usize) -> Result<Self> {
        if bytes == 0 {
            return Ok(PinnedBuffer {
                ptr: NonNull::dangling(),
                len: 0,
                gpu: gpu.clone(),
                event: None,
                in_flight: AtomicBool::new(false),
            });
        }
        let event = gpu.new_event(false)?;
        gpu.bind()?;
        let mut p: *mut c_void = std::ptr::null_mut();
        // SAFETY: out-parameter call in the bound context.
        unsafe { sys::cuMemHostAlloc(&mut p, bytes, sys::CU_MEMHOSTALLOC_PORTABLE) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!("cuMemHostAlloc of {bytes} bytes for cuda:{}", gpu.ordinal()),
                )
            })?;
        let Some(ptr) = NonNull::new(p as *mut u8) else {
            return Err(CudaError::InvalidArgument(
                "cuMemHostAlloc returned null".into(),
            ));
        };
        // SAFETY: fresh allocation of `bytes` bytes; zeroing makes every byte initialised.
        unsafe { std::ptr::write_bytes(ptr.as_ptr(), 0, bytes) };
        Ok(PinnedBuffer {
            ptr,
            len: bytes,
            gpu: gpu.clone(),
            event: Some(event),
            in_flight: AtomicBool::new(false),
        })
    }

    /// Size in bytes.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the buffer has zero bytes.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Waits for the async copies queued on this buffer.
    pub fn synchronize(&self) -> Result<()> {
        if self.in_flight.swap(false, Ordering::AcqRel) {
            if let Some(ev) = &self.event {
                return ev.synchronize();
            }
        }
        Ok(())
    }

    /// The bytes, after waiting for copies in flight. (If waiting fails, the context is in an
    /// error state and no copy is running; the error is reported by the next fallible call.)
    pub fn as_slice(&self) -> &[u8] {
        let _ = self.synchronize();
        // SAFETY: `len` initialised bytes owned by self; no DMA is writing (waited above, and
        // new copies need `&mut self`).
        unsafe { std::slice::from_raw_parts(self.ptr.as_ptr(), self.len) }
    }

    /// The bytes, mutably, after waiting for copies in flight.
    pub fn as_mut_slice(&mut self) -> &mut [u8] {
        let _ = self.synchronize();
        // SAFETY: as in `as_slice`, and no DMA is reading either.
        unsafe { std::slice::from_raw_parts_mut(self.ptr.as_ptr(), self.len) }
    }

    /// Common checks and bookkeeping around one queued copy.
    fn queue_copy(
        &mut self,
        stream: &Stream,
        dev: &DeviceBuffer,
        enqueue: impl FnOnce(sys::CUstream) -> sys::CUresult,
        call: &str,
        bytes: usize,
    ) -> Result<()> {
        if stream.ordinal() != self.gpu.ordinal() || dev.gpu.ordinal() != self.gpu.ordinal() {
            return Err(CudaError::InvalidArgument(format!(
                "{call}: pinned buffer of cuda:{}, stream of cuda:{}, device buffer of cuda:{}",
                self.gpu.ordinal(),
                stream.ordinal(),
                dev.gpu.ordinal()
            )));
        }
        let Some(event) = &self.event else {
            return Ok(()); // zero-byte pinned buffer: nothing can be copied
        };
        stream.bind()?;
        if self.in_flight.load(Ordering::Acquire) {
            stream.wait_event(event)?;
        }
        enqueue(stream.cu_stream()).result().map_err(|e| {
            CudaError::driver(
                e,
                format!("{call} of {bytes} bytes on cuda:{}", stream.ordinal()),
            )
        })?;
        if let Err(e) = event.record(stream) {
            // Without the event we cannot track the copy: wait for it now instead.
            let _ = stream.synchronize();
            return Err(e);
        }
        self.in_flight.store(true, Ordering::Release);
        Ok(())
    }

    /// Queues a copy of `bytes` bytes from this buffer at `src_off` to `dst` at `dst_off` on
    /// `stream` (of the same device) and returns at once.
    pub fn copy_to_device_async(
        &mut self,
        src_off: usize,
        dst: &DeviceBuffer,
        dst_off: usize,
        bytes: usize,
        stream: &Stream,
    ) -> Result<()> {
        check_range(
            src_off,
            bytes,
            self.len,
            "copy_to_device_async (pinned source)",
        )?;
        check_range(
            dst_off,
            bytes,
            dst.bytes,
            "copy_to_device_async (device destination)",
        )?;
        if bytes == 0 {
            return Ok(());
        }
        let src = self.ptr.as_ptr().wrapping_add(src_off) as *const c_void;
        let dptr = dst.ptr + dst_off as u64;
        // SAFETY: ranges checked; the pinned bytes stay alive and unaliased until the recorded
        // event completes (see the type docs).
        self.queue_copy(
            stream,
            dst,
            |s| unsafe { sys::cuMemcpyHtoDAsync_v2(dptr, src, bytes, s) },
            "cuMemcpyHtoDAsync",
            bytes,
        )
    }

    /// Queues a copy of `bytes` bytes from `src` at `src_off` into this buffer at `dst_off` on
    /// `stream` (of the same device) and returns at once; read the result with
    /// [`as_slice`](Self::as_slice), which waits.
    pub fn copy_from_device_async(
        &mut self,
        dst_off: usize,
        src: &DeviceBuffer,
        src_off: usize,
        bytes: usize,
        stream: &Stream,
    ) -> Result<()> {
        check_range(
            dst_off,
            bytes,
            self.len,
            "copy_from_device_async (pinned destination)",
        )?;
        check_range(
            src_off,
            bytes,
            src.bytes,
            "copy_from_device_async (device source)",
        )?;
        if bytes == 0 {
            return Ok(());
        }
        let dst = self.ptr.as_ptr().wrapping_add(dst_off) as *mut c_void;
        let sptr = src.ptr + src_off as u64;
        // SAFETY: as in `copy_to_device_async`.
        self.queue_copy(
            stream,
            src,
            |s| unsafe { sys::cuMemcpyDtoHAsync_v2(dst, sptr, bytes, s) },
            "cuMemcpyDtoHAsync",
            bytes,
        )
    }
}

impl Drop for PinnedBuffer {
    fn drop(&mut self) {
        if self.len == 0 {
            return;
        }
        let _ = self.synchronize();
        if self.gpu.bind().is_ok() {
            // SAFETY: allocated by cuMemHostAlloc, freed once, no copy in flight.
            let _ = unsafe { sys::cuMemFreeHost(self.ptr.as_ptr() as *mut c_void) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{check_range, minimal_period};

    #[test]
    fn periods() {
        assert_eq!(minimal_period(&[0; 8]), 1);
        assert_eq!(minimal_period(&[1, 2, 1, 2]), 2);
        assert_eq!(minimal_period(&[1, 2, 3]), 3);
        assert_eq!(minimal_period(&[1, 2, 3, 4, 1, 2, 3, 4, 1, 2, 3, 4]), 4);
        assert_eq!(minimal_period(&[1, 2, 1]), 3);
        assert_eq!(minimal_period(&[7]), 1);
    }

    #[test]
    fn ranges() {
        assert!(check_range(0, 0, 0, "x").is_ok());
        assert!(check_range(4, 4, 8, "x").is_ok());
        assert!(check_range(5, 4, 8, "x").is_err());
        assert!(check_range(usize::MAX, 2, 8, "x").is_err());
        let e = check_range(9, 0, 8, "upload").unwrap_err().to_string();
        assert!(e.contains("upload") && e.contains("8 bytes"), "{e}");
    }
}

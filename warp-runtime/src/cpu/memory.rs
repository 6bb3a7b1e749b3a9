//! Host memory: what arrays on the CPU live in.

use crate::backend::Buffer;
use crate::error::{Error, Result};
use std::alloc::{self, Layout};
use std::ptr::NonNull;

/// Every host allocation is aligned at least this much: a cache line, which also satisfies
/// every glam type, so that `Array::reinterpret` to a more-aligned type succeeds. (External
/// memory, [`HostBuffer::external`], is aligned for its element type only; `reinterpret`
/// checks the alignment it needs.)
pub(crate) const HOST_ALIGN: usize = 64;

/// Host memory: one allocation, written through raw pointers only.
///
/// No Rust reference to the bytes is ever created for longer than one copy, so writes through
/// `&Array` (kernels take arrays by shared reference) do not violate aliasing rules; the
/// pointer itself is the interior mutability.
pub(crate) struct HostBuffer {
    ptr: NonNull<u8>,
    bytes: usize,
    /// The layout the global allocator gave, or `None` for external memory (not freed here).
    layout: Option<Layout>,
    /// What keeps external memory alive: dropped with the buffer, after the last use.
    _owner: Option<Box<dyn std::any::Any + Send + Sync>>,
}

// SAFETY: the buffer owns its allocation (nothing else frees it), or external memory whose
// owner it keeps (`Send + Sync`), and only hands out raw pointers; concurrent access follows the documented CUDA-style contract of `Array`.
unsafe impl Send for HostBuffer {}
// SAFETY: as for `Send`.
unsafe impl Sync for HostBuffer {}

impl HostBuffer {
    /// A zero-filled allocation of `bytes` bytes aligned to `align` (at least [`HOST_ALIGN`]).
    ///
    /// # Errors
    /// [`Error::OutOfMemory`] (device `"cpu"`) when the allocator returns nothing or the size
    /// is more than any Rust allocation may be (`isize::MAX` rounded up to the alignment):
    /// an `Err`, never the allocator's abort, so that a program can free memory or try a
    /// smaller size.
    pub(crate) fn zeroed(bytes: usize, align: usize) -> Result<HostBuffer> {
        // Always allocate at least one byte: the allocator rejects zero sizes, and a real
        // pointer keeps empty arrays free of special cases. `align` is an element type's
        // alignment (a power of two), so the layout fails only for a size past `isize::MAX`.
        let layout = Layout::from_size_align(bytes.max(1), align.max(HOST_ALIGN))
            .map_err(|_| Error::out_of_memory("cpu", bytes))?;
        // SAFETY: the layout has a non-zero size.
        let ptr = unsafe { alloc::alloc_zeroed(layout) };
        let ptr = NonNull::new(ptr).ok_or_else(|| Error::out_of_memory("cpu", bytes))?;
        Ok(HostBuffer {
            ptr,
            bytes,
            layout: Some(layout),
            _owner: None,
        })
    }

    /// External memory: `bytes` bytes at `ptr`, not freed by the buffer; `owner` is dropped
    /// with it.
    ///
    /// # Safety
    /// `ptr..ptr + bytes` must be valid for reads and writes for as long as `owner` lives
    /// (or forever, without one), and nothing else may access it while an array operation or
    /// kernel does, except as `Array`'s concurrency contract allows.
    pub(crate) unsafe fn external(
        ptr: NonNull<u8>,
        bytes: usize,
        owner: Option<Box<dyn std::any::Any + Send + Sync>>,
    ) -> HostBuffer {
        HostBuffer {
            ptr,
            bytes,
            layout: None,
            _owner: owner,
        }
    }

    /// Takes ownership of a vector's memory without copying it.
    pub(crate) fn from_vec<T: bytemuck::Pod>(data: Vec<T>) -> Result<HostBuffer> {
        let bytes = std::mem::size_of_val(data.as_slice());
        if bytes == 0 {
            // An empty or zero-sized vector owns no allocation to take over.
            return HostBuffer::zeroed(0, std::mem::align_of::<T>());
        }
        if !(data.as_ptr() as usize).is_multiple_of(HOST_ALIGN) {
            // The allocator gave the vector less than every host buffer's alignment (what
            // `reinterpret` and the volumes' views rely on): copy it into one that has it.
            let b = HostBuffer::zeroed(bytes, std::mem::align_of::<T>())?;
            // SAFETY: `b` is a fresh allocation of `bytes` bytes; the source is the vector's.
            unsafe {
                std::ptr::copy_nonoverlapping(data.as_ptr().cast::<u8>(), b.ptr(), bytes);
            }
            return Ok(b);
        }
        let boxed = data.into_boxed_slice();
        let layout = Layout::for_value(&*boxed);
        let ptr = NonNull::from(Box::leak(boxed)).cast::<u8>();
        Ok(HostBuffer {
            ptr,
            bytes,
            layout: Some(layout),
            _owner: None,
        })
    }

    /// The address of byte 0.
    pub(crate) fn ptr(&self) -> *mut u8 {
        self.ptr.as_ptr()
    }

    /// Bytes `offset..offset + len`, as a slice for the length of one copy.
    ///
    /// # Safety
    /// No kernel or other thread may write these bytes while the slice lives.
    pub(crate) unsafe fn bytes(&self, offset: usize, len: usize) -> &[u8] {
        assert!(offset.checked_add(len).is_some_and(|end| end <= self.bytes));
        // SAFETY: in bounds (checked above); no writer (the caller's contract).
        unsafe { std::slice::from_raw_parts(self.ptr().add(offset), len) }
    }

    /// Bytes `offset..offset + len`, mutably, for the length of one copy.
    ///
    /// # Safety
    /// No kernel or other thread may read or write these bytes while the slice lives.
    #[allow(clippy::mut_from_ref)]
    pub(crate) unsafe fn bytes_mut(&self, offset: usize, len: usize) -> &mut [u8] {
        assert!(offset.checked_add(len).is_some_and(|end| end <= self.bytes));
        // SAFETY: in bounds (checked above); the pointer is the interior mutability, and no
        // other access overlaps (the caller's contract).
        unsafe { std::slice::from_raw_parts_mut(self.ptr().add(offset), len) }
    }
}

impl Drop for HostBuffer {
    fn drop(&mut self) {
        // External memory is its owner's to free (the owner drops after this, as a field).
        if let Some(layout) = self.layout {
            // SAFETY: `ptr` came from the global allocator with exactly `layout` (alloc_zeroed,
            // or a boxed slice whose layout is `Layout::for_value`) and is freed only here.
            unsafe { alloc::dealloc(self.ptr.as_ptr(), layout) };
        }
    }
}

/// Host memory as the array operations see every backend's: byte copies. (Host arrays also
/// take direct, typed paths in `array.rs`; these serve the operations shared with devices.)
///
/// The copies follow `Array`'s contract: no kernel runs on the memory during a host-side
/// operation (CPU launches finish before `launch` returns), and concurrent host-side calls on
/// the same memory race as they would on a GPU.
impl Buffer for HostBuffer {
    fn len(&self) -> usize {
        self.bytes
    }

    fn address(&self) -> u64 {
        self.ptr() as u64
    }

    fn read(&self, offset: usize, out: &mut [u8]) -> Result<()> {
        // SAFETY: no writer during a host-side operation (see above).
        out.copy_from_slice(unsafe { self.bytes(offset, out.len()) });
        Ok(())
    }

    fn write(&self, offset: usize, data: &[u8]) -> Result<()> {
        // SAFETY: no other access during a host-side operation (see above).
        unsafe { self.bytes_mut(offset, data.len()) }.copy_from_slice(data);
        Ok(())
    }

    fn fill(&self, offset: usize, bytes: usize, pattern: &[u8]) -> Result<()> {
        // SAFETY: no other access during a host-side operation (see above).
        let dst = unsafe { self.bytes_mut(offset, bytes) };
        for chunk in dst.chunks_exact_mut(pattern.len()) {
            chunk.copy_from_slice(pattern);
        }
        Ok(())
    }

    fn copy_from(&self, offset: usize, src: &Self, src_offset: usize, bytes: usize) -> Result<()> {
        assert!(offset
            .checked_add(bytes)
            .is_some_and(|end| end <= self.bytes));
        assert!(src_offset
            .checked_add(bytes)
            .is_some_and(|end| end <= src.bytes));
        // SAFETY: both ranges are in bounds (checked above); `copy` allows them to overlap
        // (the same buffer).
        unsafe { std::ptr::copy(src.ptr().add(src_offset), self.ptr().add(offset), bytes) };
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn allocations_are_aligned_and_zeroed() {
        let b = HostBuffer::zeroed(3, 1).unwrap();
        assert_eq!(b.ptr() as usize % HOST_ALIGN, 0);
        let mut out = [1u8; 3];
        b.read(0, &mut out).unwrap();
        assert_eq!(out, [0; 3]);
    }

    #[test]
    fn byte_operations() {
        let a = HostBuffer::zeroed(8, 1).unwrap();
        a.fill(0, 8, &[1, 2]).unwrap();
        a.write(6, &[9, 9]).unwrap();
        let b = HostBuffer::from_vec(vec![0u8; 8]).unwrap();
        b.copy_from(2, &a, 0, 6).unwrap();
        let mut out = [0u8; 8];
        b.read(0, &mut out).unwrap();
        assert_eq!(out, [0, 0, 1, 2, 1, 2, 1, 2]);
        // Overlapping, within one buffer.
        a.copy_from(1, &a, 0, 7).unwrap();
        a.read(0, &mut out).unwrap();
        assert_eq!(out, [1, 1, 2, 1, 2, 1, 2, 9]);
        assert_eq!(a.len(), 8);
    }
}

//! Modules and kernel launch.
//!
//! Launch cost is a headline figure (≤ 4 µs host time per small launch), so
//! [`Gpu::launch_raw`] is a direct `cuLaunchKernel`: no allocation, no per-argument event
//! tracking, no argument re-packing. The caller packs the arguments once and passes an array
//! of pointers to them, exactly as the driver expects.

use std::ffi::{c_void, CString};
use std::sync::Arc;

use cudarc::driver::sys;

use crate::device::{Gpu, Stream};
use crate::error::{CudaError, Result};

struct ModuleInner {
    module: sys::CUmodule,
    gpu: Arc<Gpu>,
}

// SAFETY: CUmodule handles may be used from any thread once the owning context is current,
// which every use ensures via `Gpu::bind`.
unsafe impl Send for ModuleInner {}
unsafe impl Sync for ModuleInner {}

impl Drop for ModuleInner {
    fn drop(&mut self) {
        if self.gpu.bind().is_ok() {
            // SAFETY: loaded by us, unloaded once; functions keep the module alive, so no
            // `Function` outlives it. Kernels already queued keep running (the driver defers).
            let _ = unsafe { sys::cuModuleUnload(self.module) };
        }
    }
}

/// A loaded module (cubin) on one device. Cheap to clone; unloaded when the last clone and the
/// last [`Function`] taken from it are dropped.
#[derive(Clone)]
pub struct Module {
    inner: Arc<ModuleInner>,
}

impl std::fmt::Debug for Module {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Module(on cuda:{})", self.inner.gpu.ordinal())
    }
}

/// A kernel entry point of a [`Module`].
#[derive(Clone)]
pub struct Function {
    func: sys::CUfunction,
    ctx: sys::CUcontext,
    name: Arc<str>,
    module: Arc<ModuleInner>,
}

// SAFETY: as for `ModuleInner`; the handle is immutable.
unsafe impl Send for Function {}
unsafe impl Sync for Function {}

impl std::fmt::Debug for Function {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Function({} on cuda:{})",
            self.name,
            self.module.gpu.ordinal()
        )
    }
}

fn rd_u16(b: &[u8], at: usize) -> u64 {
    u16::from_le_bytes([b[at], b[at + 1]]) as u64
}
fn rd_u32(b: &[u8], at: usize) -> u64 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap_or([0; 4])) as u64
}
fn rd_u64(b: &[u8], at: usize) -> u64 {
    u64::from_le_bytes(b[at..at + 8].try_into().unwrap_or([0; 8]))
}

/// Checks that an ELF64 image's header tables and section contents lie inside the slice.
/// `cuModuleLoadData` takes only a pointer and trusts the headers, so a truncated image would
/// make it read past the end of our buffer.
fn check_elf(img: &[u8]) -> std::result::Result<(), String> {
    let len = img.len() as u64;
    if img.len() < 64 || img[4] != 2 || img[5] != 1 {
        return Err("not a little-endian ELF64 image".into());
    }
    let table = |off: u64, num: u64, ent: u64| {
        num.checked_mul(ent)
            .and_then(|n| n.checked_add(off))
            .is_some_and(|end| end <= len)
    };
    let (phoff, phent, phnum) = (rd_u64(img, 0x20), rd_u16(img, 0x36), rd_u16(img, 0x38));
    let (shoff, shent, shnum) = (rd_u64(img, 0x28), rd_u16(img, 0x3A), rd_u16(img, 0x3C));
    if !table(phoff, phnum, phent) || !table(shoff, shnum, shent) {
        return Err("ELF header tables extend past the end of the image (truncated?)".into());
    }
    if shnum > 0 && shent < 64 {
        return Err("ELF section header entries too small".into());
    }
    for i in 0..shnum {
        let h = (shoff + i * shent) as usize;
        let sh_type = rd_u32(img, h + 4);
        let (off, size) = (rd_u64(img, h + 0x18), rd_u64(img, h + 0x20));
        const SHT_NOBITS: u64 = 8;
        if sh_type != SHT_NOBITS && off.checked_add(size).is_none_or(|end| end > len) {
            return Err(format!(
                "ELF section {i} extends past the end of the image (truncated?)"
            ));
        }
    }
    Ok(())
}

/// Checks a fatbin header's declared size against the slice.
fn check_fatbin(img: &[u8]) -> std::result::Result<(), String> {
    if img.len() < 16 {
        return Err("fatbin header truncated".into());
    }
    let total = rd_u16(img, 6).checked_add(rd_u64(img, 8));
    if total.is_none_or(|t| t > img.len() as u64) {
        return Err("fatbin extends past the end of the image (truncated?)".into());
    }
    Ok(())
}

impl Gpu {
    /// Loads a module image: a cubin (ELF), a fatbin, or PTX text.
    ///
    /// The image is checked to lie entirely within `image` (the driver reads it through a bare
    /// pointer); PTX without a terminating NUL is copied with one appended.
    pub fn load_module(self: &Arc<Self>, image: &[u8]) -> Result<Module> {
        let bad = |why: String| {
            CudaError::InvalidArgument(format!("load_module on cuda:{}: {why}", self.ordinal()))
        };
        let owned;
        let ptr: *const c_void = if image.starts_with(b"\x7fELF") {
            check_elf(image).map_err(bad)?;
            image.as_ptr() as *const c_void
        } else if image.starts_with(&0xBA55_ED50u32.to_le_bytes()) {
            check_fatbin(image).map_err(bad)?;
            image.as_ptr() as *const c_void
        } else if image.is_empty() {
            return Err(bad("empty image".into()));
        } else if image.last() == Some(&0) {
            image.as_ptr() as *const c_void
        } else {
            owned = [image, &[0]].concat();
            owned.as_ptr() as *const c_void
        };
        self.bind()?;
        let mut module: sys::CUmodule = std::ptr::null_mut();
        // SAFETY: `ptr` points to a complete image (checked above) alive during the call; the
        // driver copies what it needs.
        unsafe { sys::cuModuleLoadData(&mut module, ptr) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!(
                        "cuModuleLoadData of a {}-byte image on cuda:{}",
                        image.len(),
                        self.ordinal()
                    ),
                )
            })?;
        Ok(Module {
            inner: Arc::new(ModuleInner {
                module,
                gpu: self.clone(),
            }),
        })
    }

    /// Links relocatable device code (`cubin`, compiled with `-rdc=true`) with the static
    /// device library at `library` (`libcudadevrt.a`, for device-runtime calls such as
    /// `cudaGraphSetConditional`) by the driver's JIT linker; returns the linked cubin, for
    /// [`Gpu::load_module`] (and a cache).
    pub fn link_with_library(&self, cubin: &[u8], library: &std::path::Path) -> Result<Vec<u8>> {
        let ordinal = self.ordinal();
        let op = |what: &str| {
            format!(
                "{what} (linking with {}) on cuda:{ordinal}",
                library.display()
            )
        };
        let lib = std::ffi::CString::new(library.as_os_str().as_encoded_bytes()).map_err(|_| {
            CudaError::InvalidArgument(format!("a library path with a NUL: {}", library.display()))
        })?;
        self.bind()?;
        let mut state: sys::CUlinkState = std::ptr::null_mut();
        // SAFETY: out-parameter call with no options.
        unsafe { sys::cuLinkCreate_v2(0, std::ptr::null_mut(), std::ptr::null_mut(), &mut state) }
            .result()
            .map_err(|e| CudaError::driver(e, op("cuLinkCreate")))?;
        let linked = (|| {
            // SAFETY: `cubin` is alive for the call (the linker copies it); `lib` is a valid C
            // string; `state` is the link state created above.
            unsafe {
                sys::cuLinkAddData_v2(
                    state,
                    sys::CUjitInputType::CU_JIT_INPUT_CUBIN,
                    cubin.as_ptr() as *mut c_void,
                    cubin.len(),
                    c"wp_rdc".as_ptr(),
                    0,
                    std::ptr::null_mut(),
                    std::ptr::null_mut(),
                )
                .result()
                .map_err(|e| CudaError::driver(e, op("cuLinkAddData")))?;
                sys::cuLinkAddFile_v2(
                    state,
                    sys::CUjitInputType::CU_JIT_INPUT_LIBRARY,
                    lib.as_ptr(),
                    0,
                    std::ptr::null_mut(),
                    std::ptr::null_mut(),
                )
                .result()
                .map_err(|e| CudaError::driver(e, op("cuLinkAddFile")))?;
                let (mut out, mut size): (*mut c_void, usize) = (std::ptr::null_mut(), 0);
                sys::cuLinkComplete(state, &mut out, &mut size)
                    .result()
                    .map_err(|e| CudaError::driver(e, op("cuLinkComplete")))?;
                // The image belongs to the link state: copy it before destroying the state.
                Ok(std::slice::from_raw_parts(out as *const u8, size).to_vec())
            }
        })();
        // SAFETY: destroyed once, after the image was copied.
        unsafe {
            let _ = sys::cuLinkDestroy(state);
        }
        linked
    }

    /// Launches `func` with a 1-D grid of `grid_dim` blocks of `block_dim` threads on `stream`
    /// (`cuLaunchKernel`). A zero `grid_dim` launches nothing and returns `Ok`.
    ///
    /// # Safety
    /// - `params` must hold exactly one pointer per kernel parameter, in order, each pointing
    ///   to a value whose size and layout match that parameter (for a `float*`, a pointer to a
    ///   `u64` device address; for an `int`, a pointer to an `i32`; for a struct, to bytes laid
    ///   out as the CUDA struct). The driver copies the values before this call returns, so
    ///   they only need to live until then.
    /// - Every device address passed must be valid for all accesses the kernel makes, for as
    ///   long as the kernel runs: the buffers must outlive the kernel, and must not be freed
    ///   or reused before it completes (order other streams against the default stream).
    /// - The kernel must not race with other work on the same memory (the device may run
    ///   kernels of different streams concurrently).
    /// - Launch failures caused by the kernel itself (out-of-bounds access, trap) surface
    ///   asynchronously from a later call, and leave the context unusable.
    pub unsafe fn launch_raw(
        &self,
        func: &Function,
        stream: &Stream,
        grid_dim: u32,
        block_dim: u32,
        shared_bytes: u32,
        params: &mut [*mut c_void],
    ) -> Result<()> {
        self.launch_raw_3d(
            func,
            stream,
            (grid_dim, 1, 1),
            (block_dim, 1, 1),
            shared_bytes,
            params,
        )
    }

    /// [`launch_raw`](Self::launch_raw) with 3-D grid and block dimensions.
    ///
    /// # Safety
    /// As for [`launch_raw`](Self::launch_raw).
    pub unsafe fn launch_raw_3d(
        &self,
        func: &Function,
        stream: &Stream,
        grid: (u32, u32, u32),
        block: (u32, u32, u32),
        shared_bytes: u32,
        params: &mut [*mut c_void],
    ) -> Result<()> {
        let ctx = self.cu_ctx();
        if func.ctx != ctx || stream.cu_ctx() != ctx {
            return Err(CudaError::InvalidArgument(format!(
                "launch of {} on cuda:{}: the function or the stream belongs to another device \
                 (function on cuda:{}, stream on cuda:{})",
                func.name,
                self.ordinal(),
                func.module.gpu.ordinal(),
                stream.ordinal()
            )));
        }
        if grid.0 == 0 || grid.1 == 0 || grid.2 == 0 {
            return Ok(());
        }
        self.bind()?;
        // SAFETY: handles checked to belong to this context; the parameter contract is the
        // caller's (see above).
        unsafe {
            sys::cuLaunchKernel(
                func.func,
                grid.0,
                grid.1,
                grid.2,
                block.0,
                block.1,
                block.2,
                shared_bytes,
                stream.cu_stream(),
                params.as_mut_ptr(),
                std::ptr::null_mut(),
            )
        }
        .result()
        .map_err(|e| {
            CudaError::driver(
                e,
                format!(
                    "cuLaunchKernel of {} (grid {grid:?}, block {block:?}, {shared_bytes} bytes \
                     shared, {} params) on cuda:{}",
                    func.name,
                    params.len(),
                    self.ordinal()
                ),
            )
        })
    }
}

impl Module {
    /// Looks up the kernel named `name` (its `extern "C"` name).
    pub fn function(&self, name: &str) -> Result<Function> {
        let gpu = &self.inner.gpu;
        let cname = CString::new(name).map_err(|_| {
            CudaError::InvalidArgument(format!("kernel name {name:?} contains a NUL byte"))
        })?;
        gpu.bind()?;
        let mut func: sys::CUfunction = std::ptr::null_mut();
        // SAFETY: live module of the bound context; `cname` is NUL-terminated.
        unsafe { sys::cuModuleGetFunction(&mut func, self.inner.module, cname.as_ptr()) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!("cuModuleGetFunction({name}) on cuda:{}", gpu.ordinal()),
                )
            })?;
        Ok(Function {
            func,
            ctx: gpu.cu_ctx(),
            name: name.into(),
            module: self.inner.clone(),
        })
    }

    /// The device the module is loaded on.
    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.inner.gpu
    }
}

impl Function {
    /// The kernel's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The raw `CUfunction` handle (valid while this `Function` lives).
    pub fn cu_function(&self) -> sys::CUfunction {
        self.func
    }

    /// Reads a function attribute (`cuFuncGetAttribute`).
    pub fn attribute(&self, attr: sys::CUfunction_attribute) -> Result<i32> {
        self.module.gpu.bind()?;
        let mut v = 0i32;
        // SAFETY: out-parameter call on a live function handle.
        unsafe { sys::cuFuncGetAttribute(&mut v, attr, self.func) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!(
                        "cuFuncGetAttribute({attr:?}) of {} on cuda:{}",
                        self.name,
                        self.module.gpu.ordinal()
                    ),
                )
            })?;
        Ok(v)
    }

    /// The largest block this kernel can be launched with (registers limit it below 1024).
    pub fn max_threads_per_block(&self) -> Result<u32> {
        self.attribute(sys::CUfunction_attribute::CU_FUNC_ATTRIBUTE_MAX_THREADS_PER_BLOCK)
            .map(|v| v.max(0) as u32)
    }

    /// Registers used per thread.
    pub fn num_regs(&self) -> Result<u32> {
        self.attribute(sys::CUfunction_attribute::CU_FUNC_ATTRIBUTE_NUM_REGS)
            .map(|v| v.max(0) as u32)
    }

    /// Bytes of statically allocated shared memory (`__shared__` arrays of fixed size) the
    /// kernel uses, besides what a launch gives it dynamically.
    pub fn static_shared_bytes(&self) -> Result<usize> {
        self.attribute(sys::CUfunction_attribute::CU_FUNC_ATTRIBUTE_SHARED_SIZE_BYTES)
            .map(|v| v.max(0) as usize)
    }

    /// Lets launches of this kernel ask for up to `bytes` of dynamic shared memory
    /// (`cuFuncSetAttribute(CU_FUNC_ATTRIBUTE_MAX_DYNAMIC_SHARED_SIZE_BYTES)`): without it a
    /// launch may take at most 48 KiB, whatever the device has.
    pub fn set_max_dynamic_shared_bytes(&self, bytes: usize) -> Result<()> {
        let gpu = &self.module.gpu;
        let value = i32::try_from(bytes).map_err(|_| {
            CudaError::InvalidArgument(format!(
                "{bytes} bytes of dynamic shared memory for {} on cuda:{}",
                self.name,
                gpu.ordinal()
            ))
        })?;
        gpu.bind()?;
        let attr = sys::CUfunction_attribute::CU_FUNC_ATTRIBUTE_MAX_DYNAMIC_SHARED_SIZE_BYTES;
        // SAFETY: a live function handle of the bound context; the attribute takes an int.
        unsafe { sys::cuFuncSetAttribute(self.func, attr, value) }
            .result()
            .map_err(|e| {
                CudaError::driver(
                    e,
                    format!(
                        "cuFuncSetAttribute({attr:?}, {bytes}) of {} on cuda:{}",
                        self.name,
                        gpu.ordinal()
                    ),
                )
            })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny_elf() -> Vec<u8> {
        // ELF64 header with one section header table of 2 entries right after it.
        let mut v = vec![0u8; 64 + 2 * 64 + 16];
        v[..4].copy_from_slice(b"\x7fELF");
        v[4] = 2;
        v[5] = 1;
        v[0x28..0x30].copy_from_slice(&64u64.to_le_bytes());
        v[0x3A..0x3C].copy_from_slice(&64u16.to_le_bytes());
        v[0x3C..0x3E].copy_from_slice(&2u16.to_le_bytes());
        // section 1: PROGBITS at 192, 16 bytes
        let h = 64 + 64;
        v[h + 4..h + 8].copy_from_slice(&1u32.to_le_bytes());
        v[h + 0x18..h + 0x20].copy_from_slice(&192u64.to_le_bytes());
        v[h + 0x20..h + 0x28].copy_from_slice(&16u64.to_le_bytes());
        v
    }

    #[test]
    fn elf_checks() {
        let v = tiny_elf();
        assert_eq!(check_elf(&v), Ok(()));
        assert!(check_elf(&v[..v.len() - 1]).is_err(), "section past end");
        assert!(check_elf(&v[..100]).is_err(), "table past end");
        assert!(check_elf(&v[..20]).is_err());
        let mut big = v.clone();
        big[0x28..0x30].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(check_elf(&big).is_err(), "overflowing offset");
    }

    #[test]
    fn fatbin_checks() {
        let mut v = vec![0u8; 16 + 8];
        v[..4].copy_from_slice(&0xBA55_ED50u32.to_le_bytes());
        v[6..8].copy_from_slice(&16u16.to_le_bytes());
        v[8..16].copy_from_slice(&8u64.to_le_bytes());
        assert!(check_fatbin(&v).is_ok());
        assert!(check_fatbin(&v[..20]).is_err());
    }
}

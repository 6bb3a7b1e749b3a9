//! Concurrent NVRTC compiles: NVRTC (CUDA 13) runs one compile at a time per loaded copy of
//! libnvrtc, whatever the number of threads calling it (measured with NVRTC 13.0: of two
//! threads compiling at once, the second waits for the first; a six-variant load on an H100
//! took as long on the rayon pool as one variant after another). Each further compile that
//! runs at the same time gets a copy of its own, loaded with `dlmopen` into a new link-map
//! namespace (its own globals, so its own lock): two copies compiled side by side, each in
//! the time of one compile alone. A copy costs about 12 ms to load (the library's pages are
//! shared with the first) and is kept for the process; copies are made only when compiles
//! overlap (`wp::load` of several kernels), never for one compile at a time.
//!
//! **Opt-in and experimental:** on the H200 machine (glibc 2.39, a CUDA context open), a
//! `wp::load` of the autodiff example's three kernels with copies ended in a segmentation
//! fault (2026-11-30), where the same load with one compile at a time ran. So by default
//! compiles take turns on the first copy; [`NVRTC_THREADS_ENV`] (`WARP_LANG_NVRTC_THREADS`)
//! set to a number above 1 allows that many at once, at most [`MAX_NVRTC_THREADS`]. Only
//! on Linux with glibc 2.32 or newer (whose libc copies in other namespaces take their memory
//! with mmap, never by moving the program break that the first libc owns); elsewhere, or when
//! a copy cannot be loaded (said once, at warning level), compiles take turns on the first.
//!
//! Each call into a copy first runs that copy's own `__ctype_init` on the calling thread: a
//! libc loaded into another namespace has not set up the locale tables of threads it did not
//! start, and NVRTC's option parser (`isspace`) reads them.

use std::ffi::{c_char, c_void};
use std::sync::{Condvar, Mutex, OnceLock};

use cudarc::nvrtc::sys;

/// Environment variable: how many NVRTC compiles may run at once in this process (see the
/// module documentation); read once, at the first compile. `1` turns the copies of libnvrtc off.
pub const NVRTC_THREADS_ENV: &str = "WARP_LANG_NVRTC_THREADS";

/// The most compiles that run at once, whatever [`NVRTC_THREADS_ENV`] says. Each copy of
/// libnvrtc is a link-map namespace with a libc of its own, which takes static TLS; glibc
/// reserves room for four namespaces by default, and more copies would use up the reserve a
/// later `dlopen` of a library with initial-exec TLS needs.
pub const MAX_NVRTC_THREADS: usize = 4;

type Prog = sys::nvrtcProgram;
type Res = sys::nvrtcResult;

type CreateFn = unsafe extern "C" fn(
    *mut Prog,
    *const c_char,
    *const c_char,
    i32,
    *const *const c_char,
    *const *const c_char,
) -> Res;
type CompileFn = unsafe extern "C" fn(Prog, i32, *const *const c_char) -> Res;
type DestroyFn = unsafe extern "C" fn(*mut Prog) -> Res;
type SizeFn = unsafe extern "C" fn(Prog, *mut usize) -> Res;
type BytesFn = unsafe extern "C" fn(Prog, *mut c_char) -> Res;
type InitFn = unsafe extern "C" fn();

/// The NVRTC entry points compiling uses, from one copy of libnvrtc.
#[derive(Clone, Copy)]
pub(crate) struct Api {
    pub(crate) create: CreateFn,
    pub(crate) compile: CompileFn,
    pub(crate) destroy: DestroyFn,
    pub(crate) log_size: SizeFn,
    pub(crate) log: BytesFn,
    pub(crate) cubin_size: SizeFn,
    pub(crate) cubin: BytesFn,
    /// The copy's libc's `__ctype_init` (`None` for the first copy, whose libc is the
    /// program's).
    ctype_init: Option<InitFn>,
    /// Which copy: 0 for the first (cudarc's).
    pub(crate) copy: usize,
}

impl Api {
    /// Readies the calling thread for calls into this copy (see the module documentation).
    pub(crate) fn enter(&self) {
        if let Some(init) = self.ctype_init {
            // SAFETY: glibc's own per-thread initialisation of the copy's libc; idempotent.
            unsafe { init() }
        }
    }
}

/// Looks up NVRTC's symbols with `sym` into an [`Api`] (`None` if one is missing).
fn api_from(
    sym: impl Fn(&str) -> Option<*const c_void>,
    ctype_init: bool,
    copy: usize,
) -> Option<Api> {
    use std::mem::transmute;
    // SAFETY (each transmute): the symbol is NVRTC's (or glibc's) function of that name, whose
    // C signature is the field's type (cudarc's bindings of the CUDA 13 API).
    unsafe {
        Some(Api {
            create: transmute::<*const c_void, CreateFn>(sym("nvrtcCreateProgram")?),
            compile: transmute::<*const c_void, CompileFn>(sym("nvrtcCompileProgram")?),
            destroy: transmute::<*const c_void, DestroyFn>(sym("nvrtcDestroyProgram")?),
            log_size: transmute::<*const c_void, SizeFn>(sym("nvrtcGetProgramLogSize")?),
            log: transmute::<*const c_void, BytesFn>(sym("nvrtcGetProgramLog")?),
            cubin_size: transmute::<*const c_void, SizeFn>(sym("nvrtcGetCUBINSize")?),
            cubin: transmute::<*const c_void, BytesFn>(sym("nvrtcGetCUBIN")?),
            ctype_init: if ctype_init {
                Some(transmute::<*const c_void, InitFn>(sym("__ctype_init")?))
            } else {
                None
            },
            copy,
        })
    }
}

/// The first copy: the libnvrtc cudarc loaded (the caller has checked that it is there).
fn first() -> Option<Api> {
    // SAFETY: `culib` is cudarc's handle of the loaded library; symbols are only read.
    let lib = unsafe { sys::culib() };
    api_from(
        |name| {
            let name = format!("{name}\0");
            // SAFETY: a symbol lookup; the pointer is only turned into the function type of
            // its name (`api_from`).
            unsafe { lib.get::<*const c_void>(name.as_bytes()) }
                .ok()
                .map(|s| *s)
        },
        false,
        0,
    )
}

/// How many compiles may run at once: `value` of [`NVRTC_THREADS_ENV`] when it is a number of
/// at least 1, else 1 (the copies are opt-in, see the module documentation); at most
/// [`MAX_NVRTC_THREADS`] either way. Each copy is a link-map namespace with a libc of its
/// own, which takes static TLS: glibc reserves room for four namespaces by default
/// (`rtld.nns`), and copies past it would use up the reserve that a later, unrelated `dlopen`
/// of a library with initial-exec TLS needs.
pub(crate) fn limit_from(value: Option<&str>) -> usize {
    match value.map(str::trim).and_then(|v| v.parse::<usize>().ok()) {
        Some(n) if n >= 1 => n.min(MAX_NVRTC_THREADS),
        _ => 1,
    }
}

/// Whether glibc `version` ("2.36") keeps the memory of libc copies in other namespaces off
/// the program break (2.32 and newer).
pub(crate) fn glibc_allows_copies(version: &str) -> bool {
    let mut parts = version.split('.').map(|p| p.parse::<u32>().ok());
    match (parts.next().flatten(), parts.next().flatten()) {
        (Some(major), Some(minor)) => (major, minor) >= (2, 32),
        _ => false,
    }
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
mod copies {
    use super::{api_from, Api};
    use std::ffi::{c_void, CStr, CString};
    use std::sync::{mpsc, Mutex, OnceLock};

    /// Whether this process's glibc allows copies (see the module documentation).
    pub(super) fn allowed() -> bool {
        // SAFETY: returns a static NUL-terminated string.
        let v = unsafe { CStr::from_ptr(libc::gnu_get_libc_version()) };
        super::glibc_allows_copies(&v.to_string_lossy())
    }

    /// The file the first copy was loaded from.
    fn path(first: &Api) -> Result<CString, String> {
        let mut info: libc::Dl_info = unsafe { std::mem::zeroed() };
        // SAFETY: `dladdr` only reads the loader's tables for an address inside libnvrtc.
        if unsafe { libc::dladdr(first.compile as *const c_void, &mut info) } == 0
            || info.dli_fname.is_null()
        {
            return Err("dladdr found no file for libnvrtc".into());
        }
        // SAFETY: a NUL-terminated string owned by the loader, copied here.
        Ok(unsafe { CStr::from_ptr(info.dli_fname) }.to_owned())
    }

    /// A request to the loader thread: the file, the copy's number, where to answer.
    type Request = (CString, usize, mpsc::Sender<Result<Api, String>>);

    /// Loads copy number `copy` of the libnvrtc `first` came from, in a namespace of its own,
    /// on the loader thread: a thread that loaded a libc into a new namespace must never exit
    /// (measured with glibc 2.36: when it does, its exit frees memory of the other libc,
    /// "double free or corruption"; threads that only call into the copy exit cleanly), so
    /// every copy is loaded by one thread kept, parked, for the process.
    pub(super) fn load(first: &Api, copy: usize) -> Result<Api, String> {
        static LOADER: OnceLock<Mutex<mpsc::Sender<Request>>> = OnceLock::new();
        let path = path(first)?;
        let loader = LOADER.get_or_init(|| {
            let (tx, rx) = mpsc::channel::<Request>();
            let spawned = std::thread::Builder::new()
                .name("warp-nvrtc-loader".into())
                .spawn(move || {
                    // Never returns: the sender lives in a static.
                    for (path, copy, answer) in rx {
                        let _ = answer.send(load_here(&path, copy));
                    }
                    loop {
                        std::thread::park();
                    }
                });
            if let Err(e) = spawned {
                log::warn!("NVRTC: the thread that loads copies of libnvrtc failed to start: {e}");
            }
            Mutex::new(tx)
        });
        let (tx, rx) = mpsc::channel();
        loader
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .send((path, copy, tx))
            .map_err(|_| "the loader thread is not running".to_string())?;
        rx.recv()
            .map_err(|_| "the loader thread is not running".to_string())?
    }

    /// [`load`] on the calling thread (the loader thread's side).
    fn load_here(path: &CStr, copy: usize) -> Result<Api, String> {
        // SAFETY: loads the same library again into a new namespace; the handle is kept for
        // the process (never closed: compiles may still run in it at exit).
        let handle = unsafe { libc::dlmopen(libc::LM_ID_NEWLM, path.as_ptr(), libc::RTLD_NOW) };
        if handle.is_null() {
            // SAFETY: dlerror returns the thread's last loader error or null.
            let why = unsafe { libc::dlerror() };
            let why = if why.is_null() {
                "unknown".to_string()
            } else {
                unsafe { CStr::from_ptr(why) }
                    .to_string_lossy()
                    .into_owned()
            };
            return Err(format!("dlmopen({}): {why}", path.to_string_lossy()));
        }
        let sym = |name: &str| {
            let name = CString::new(name).ok()?;
            // SAFETY: a lookup in the handle's namespace (its libc for `__ctype_init`).
            let p = unsafe { libc::dlsym(handle, name.as_ptr()) };
            (!p.is_null()).then_some(p as *const c_void)
        };
        api_from(sym, true, copy).ok_or_else(|| {
            format!(
                "{} in a new namespace lacks an NVRTC entry point or __ctype_init",
                path.to_string_lossy()
            )
        })
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
mod copies {
    use super::Api;

    pub(super) fn allowed() -> bool {
        false
    }

    pub(super) fn load(_first: &Api, _copy: usize) -> Result<Api, String> {
        Err("copies of libnvrtc need dlmopen (Linux with glibc)".into())
    }
}

/// The copies free to compile, and how many there are.
struct State {
    free: Vec<Api>,
    made: usize,
    limit: usize,
    /// A copy failed to load: no more are tried.
    failed: bool,
}

struct Pool {
    state: Mutex<State>,
    freed: Condvar,
    first: Api,
    /// The process that made the pool: a child forked from it has neither the loader thread
    /// nor the slots its parent's compiling threads held (nor, maybe, an unlocked mutex).
    pid: u32,
}

fn pool() -> Option<&'static Pool> {
    static POOL: OnceLock<Option<Pool>> = OnceLock::new();
    POOL.get_or_init(|| {
        let first = first()?;
        let env = std::env::var(NVRTC_THREADS_ENV).ok();
        let mut limit = limit_from(env.as_deref());
        if limit > 1 && !copies::allowed() {
            log::debug!("NVRTC compiles take turns: no copies of libnvrtc on this platform");
            limit = 1;
        }
        log::debug!("NVRTC: up to {limit} compile(s) at once");
        Some(Pool {
            state: Mutex::new(State {
                free: vec![first],
                made: 1,
                limit,
                failed: false,
            }),
            freed: Condvar::new(),
            first,
            pid: std::process::id(),
        })
    })
    .as_ref()
}

/// A copy of NVRTC held for one compile; back to the pool on drop (`pool` is `None` for the
/// first copy handed out without the pool, in a forked child).
pub(crate) struct Slot {
    pool: Option<&'static Pool>,
    pub(crate) api: Api,
}

impl Drop for Slot {
    fn drop(&mut self) {
        if let Some(pool) = self.pool {
            let mut s = pool.state.lock().unwrap_or_else(|p| p.into_inner());
            s.free.push(self.api);
            pool.freed.notify_one();
        }
    }
}

/// A copy of NVRTC no other compile is using: a free one, else a new one while fewer than the
/// limit exist, else the first to come free. `None` when libnvrtc's entry points cannot be
/// found (the caller has checked that it loads).
pub(crate) fn acquire() -> Option<Slot> {
    let pool = pool()?;
    if pool.pid != std::process::id() {
        // A forked child: the first copy, without the pool's lock or loader (NVRTC makes its
        // compiles take turns there).
        return Some(Slot {
            pool: None,
            api: pool.first,
        });
    }
    let pool_ref = Some(pool);
    let mut s = pool.state.lock().unwrap_or_else(|p| p.into_inner());
    loop {
        if let Some(api) = s.free.pop() {
            return Some(Slot {
                pool: pool_ref,
                api,
            });
        }
        if s.made < s.limit && !s.failed {
            let copy = s.made;
            s.made += 1;
            drop(s);
            match copies::load(&pool.first, copy) {
                Ok(api) => {
                    log::debug!("NVRTC: loaded copy {copy} of libnvrtc for a concurrent compile");
                    return Some(Slot {
                        pool: pool_ref,
                        api,
                    });
                }
                Err(why) => {
                    log::warn!(
                        "NVRTC compiles take turns: a copy of libnvrtc failed to load ({why})"
                    );
                    s = pool.state.lock().unwrap_or_else(|p| p.into_inner());
                    s.made -= 1;
                    s.failed = true;
                    continue;
                }
            }
        }
        s = pool.freed.wait(s).unwrap_or_else(|p| p.into_inner());
    }
}

/// How many copies of libnvrtc are loaded (the first included) and the limit; `None` before
/// the first compile or without NVRTC.
#[cfg(test)]
fn copies() -> Option<(usize, usize)> {
    let pool = pool()?;
    let s = pool.state.lock().unwrap_or_else(|p| p.into_inner());
    Some((s.made, s.limit))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Threads compiling at once get what one compile alone gets, byte for byte, whichever
    /// copy of NVRTC served them; copies are made only up to the limit, and where the limit
    /// allows a second, overlapping compiles made one. Needs NVRTC (not a GPU); skipped
    /// without it.
    #[test]
    fn overlapping_compiles_give_the_same_cubins() {
        use crate::compile::{compile, nvrtc_version, CompileOptions};
        if let Err(e) = nvrtc_version() {
            eprintln!("SKIPPED overlapping_compiles_give_the_same_cubins: {e}");
            return;
        }
        let src = "extern \"C\" __global__ void k(float* x) { x[threadIdx.x] *= 2.0f; }";
        let opts = CompileOptions::default();
        let alone = compile(src, "k.cu", &opts, 80).unwrap().cubin;
        let n = 4;
        let start = std::sync::Barrier::new(n);
        let cubins: Vec<Vec<u8>> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..n)
                .map(|_| {
                    s.spawn(|| {
                        start.wait();
                        compile(src, "k.cu", &opts, 80).unwrap().cubin
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for c in &cubins {
            assert!(c == &alone, "a concurrent compile gave another cubin");
        }
        let (made, limit) = copies().expect("compiled");
        assert!(
            made >= 1 && made <= limit.max(1),
            "{made} copies, limit {limit}"
        );
        if limit > 1 && copies::allowed() {
            assert!(
                made > 1,
                "{n} overlapping compiles made no copy (limit {limit})"
            );
        }
    }

    /// The setting: a number of at least one, at most the cap; else one compile at a time.
    #[test]
    fn the_limit_comes_from_the_setting_else_one() {
        assert_eq!(limit_from(Some("1")), 1);
        assert_eq!(limit_from(Some(" 3 ")), 3);
        assert_eq!(limit_from(Some("64")), MAX_NVRTC_THREADS);
        assert_eq!(limit_from(None), 1);
        for bad in ["0", "", "many", "-2"] {
            assert_eq!(limit_from(Some(bad)), 1, "{bad:?}");
        }
    }

    #[test]
    fn copies_need_glibc_2_32() {
        for ok in ["2.32", "2.36", "2.39", "3.0"] {
            assert!(glibc_allows_copies(ok), "{ok}");
        }
        for no in ["2.31", "2.17", "2", "", "x.y"] {
            assert!(!glibc_allows_copies(no), "{no}");
        }
    }
}

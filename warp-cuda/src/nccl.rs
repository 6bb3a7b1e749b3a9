//! NCCL, loaded at run time: communicators and collectives on raw device memory.
//!
//! Like the driver, NCCL is opened with dlopen the first time a communicator is made, so
//! nothing about it is needed to build, and a machine without it fails with
//! [`CudaError::NotAvailable`] at that point only. The library is looked for, in order, at the
//! path in `WARP_NCCL_LIBRARY`, then as `libnccl.so.2` (the soname every NCCL package
//! installs) and `libnccl.so` on the loader's path. (cudarc's own NCCL loader looks for
//! `libnccl.so` and `libnccl.so.<CUDA major>` only, which misses a plain `libnccl.so.2`
//! install, and it panics on a missing symbol; this module resolves every symbol up front
//! and reports what is missing.) A pip install puts the library in
//! `site-packages/nvidia/nccl/lib/`: point `WARP_NCCL_LIBRARY` or `LD_LIBRARY_PATH` there.
//!
//! # Never a hang
//! Every communicator is created non-blocking (`ncclConfig_t::blocking = 0`): NCCL calls
//! return at once with `ncclInProgress` and this module polls `ncclCommGetAsyncError` until the
//! operation is ready, an error is reported, or the communicator's timeout passes, in which
//! case the communicator is aborted (`ncclCommAbort`) and the call returns
//! [`CudaError::Timeout`]. So a rank that never joins ([`Comm::init_rank`]) or a peer that
//! never posts the matching operation ([`Comm::synchronize`]) is an error after the timeout,
//! not a process stuck forever. An aborted communicator refuses further work.
//!
//! # One call at a time
//! NCCL's communicators are not thread-safe. Its user guide ("Thread Safety") says: "it is
//! not allowed to issue NCCL operations to a single communicator in parallel with multiple
//! threads; it is not safe to issue NCCL operations in parallel to independent communicators
//! located on the same device with multiple threads", and "It is safe to operate a
//! communicator from multiple threads as long as users can guarantee only one thread
//! operates the communicator at a time. However, for any grouped NCCL operations, users need
//! to ensure only one thread issues the all operations in the group." So the call lock is one
//! per GPU, shared by every communicator on it (`device_lock`), not one per communicator.
//! A [`Comm`] may still be shared between threads (it is `Sync`), because every NCCL call on
//! it takes its GPU's call lock first and holds it until NCCL has accepted the work
//! (the call returned and, in non-blocking mode, the communicator polled ready). Inside a
//! [`Group`] the calls are only recorded until `ncclGroupEnd`, so the lock of each
//! communicator used in the group stays held by the group's thread until the group ends. The
//! lock is re-entrant for its thread, and waiting for it is bounded by the communicator's
//! timeout (two threads whose groups take two communicators in opposite orders get a
//! [`CudaError::Timeout`], not a deadlock).

use crate::device::{Gpu, Stream};
use crate::error::{CudaError, Result};
use std::cell::RefCell;
use std::ffi::{c_char, c_int, c_uint, c_void, CStr};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, OnceLock};
use std::thread::ThreadId;
use std::time::{Duration, Instant};

/// The environment variable naming the NCCL library to load (a path).
pub const NCCL_LIBRARY_ENV: &str = "WARP_NCCL_LIBRARY";

/// How long a communicator waits for its peers by default before it aborts (see the module).
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(120);

type NcclComm = *mut c_void;
type NcclResult = c_int;
const NCCL_SUCCESS: NcclResult = 0;
const NCCL_IN_PROGRESS: NcclResult = 7;

/// `ncclUniqueId`: 128 opaque bytes that rank 0 creates and every rank receives.
#[repr(C)]
#[derive(Clone, Copy)]
struct RawUniqueId {
    internal: [c_char; 128],
}

/// `ncclConfig_t` as of NCCL 2.17 (the first layout with `splitShare`). NCCL reads a config by
/// its `size` and `version`, so newer libraries accept this layout and leave the fields it
/// lacks at their defaults.
#[repr(C)]
struct RawConfig {
    size: usize,
    magic: c_uint,
    version: c_uint,
    blocking: c_int,
    cga_cluster_size: c_int,
    min_ctas: c_int,
    max_ctas: c_int,
    net_name: *const c_char,
    split_share: c_int,
}

impl RawConfig {
    /// `NCCL_CONFIG_INITIALIZER` for this layout, non-blocking.
    fn non_blocking() -> RawConfig {
        const UNDEF: c_int = c_int::MIN;
        RawConfig {
            size: std::mem::size_of::<RawConfig>(),
            magic: 0xcafe_beef,
            version: 2 * 10000 + 17 * 100,
            blocking: 0,
            cga_cluster_size: UNDEF,
            min_ctas: UNDEF,
            max_ctas: UNDEF,
            net_name: std::ptr::null(),
            split_share: UNDEF,
        }
    }
}

/// NCCL's element types (`ncclDataType_t`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum DataType {
    /// `int8_t`.
    I8,
    /// `uint8_t`.
    U8,
    /// `int32_t`.
    I32,
    /// `uint32_t`.
    U32,
    /// `int64_t`.
    I64,
    /// `uint64_t`.
    U64,
    /// IEEE half precision.
    F16,
    /// `float`.
    F32,
    /// `double`.
    F64,
}

impl DataType {
    fn raw(self) -> c_int {
        match self {
            DataType::I8 => 0,
            DataType::U8 => 1,
            DataType::I32 => 2,
            DataType::U32 => 3,
            DataType::I64 => 4,
            DataType::U64 => 5,
            DataType::F16 => 6,
            DataType::F32 => 7,
            DataType::F64 => 8,
        }
    }

    /// The size of one element in bytes.
    pub fn size(self) -> usize {
        match self {
            DataType::I8 | DataType::U8 => 1,
            DataType::F16 => 2,
            DataType::I32 | DataType::U32 | DataType::F32 => 4,
            DataType::I64 | DataType::U64 | DataType::F64 => 8,
        }
    }
}

/// A reduction (`ncclRedOp_t`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ReduceOp {
    /// The sum over ranks.
    Sum,
    /// The product over ranks.
    Prod,
    /// The largest value.
    Max,
    /// The smallest value.
    Min,
    /// The mean over ranks (the sum divided by the number of ranks; integer division for
    /// integer types).
    Avg,
}

impl ReduceOp {
    fn raw(self) -> c_int {
        match self {
            ReduceOp::Sum => 0,
            ReduceOp::Prod => 1,
            ReduceOp::Max => 2,
            ReduceOp::Min => 3,
            ReduceOp::Avg => 4,
        }
    }
}

type FnComm1 = unsafe extern "C" fn(NcclComm) -> NcclResult;

/// The NCCL entry points this crate calls, resolved once.
struct Api {
    _lib: libloading::Library,
    path: String,
    get_version: unsafe extern "C" fn(*mut c_int) -> NcclResult,
    get_unique_id: unsafe extern "C" fn(*mut RawUniqueId) -> NcclResult,
    comm_init_rank_config: unsafe extern "C" fn(
        *mut NcclComm,
        c_int,
        RawUniqueId,
        c_int,
        *mut RawConfig,
    ) -> NcclResult,
    comm_finalize: FnComm1,
    comm_destroy: FnComm1,
    comm_abort: FnComm1,
    comm_get_async_error: unsafe extern "C" fn(NcclComm, *mut NcclResult) -> NcclResult,
    get_error_string: unsafe extern "C" fn(NcclResult) -> *const c_char,
    get_last_error: unsafe extern "C" fn(NcclComm) -> *const c_char,
    all_reduce: unsafe extern "C" fn(
        *const c_void,
        *mut c_void,
        usize,
        c_int,
        c_int,
        NcclComm,
        *mut c_void,
    ) -> NcclResult,
    reduce_scatter: unsafe extern "C" fn(
        *const c_void,
        *mut c_void,
        usize,
        c_int,
        c_int,
        NcclComm,
        *mut c_void,
    ) -> NcclResult,
    all_gather: unsafe extern "C" fn(
        *const c_void,
        *mut c_void,
        usize,
        c_int,
        NcclComm,
        *mut c_void,
    ) -> NcclResult,
    broadcast: unsafe extern "C" fn(
        *const c_void,
        *mut c_void,
        usize,
        c_int,
        c_int,
        NcclComm,
        *mut c_void,
    ) -> NcclResult,
    send: unsafe extern "C" fn(
        *const c_void,
        usize,
        c_int,
        c_int,
        NcclComm,
        *mut c_void,
    ) -> NcclResult,
    recv:
        unsafe extern "C" fn(*mut c_void, usize, c_int, c_int, NcclComm, *mut c_void) -> NcclResult,
    group_start: unsafe extern "C" fn() -> NcclResult,
    group_end: unsafe extern "C" fn() -> NcclResult,
}

// SAFETY: the function pointers are plain C entry points; NCCL's API is thread safe as used
// here (one thread per communicator call, groups per thread).
unsafe impl Send for Api {}
unsafe impl Sync for Api {}

fn load() -> std::result::Result<Api, String> {
    let mut candidates = Vec::new();
    if let Some(p) = std::env::var_os(NCCL_LIBRARY_ENV) {
        candidates.push(p.to_string_lossy().into_owned());
    }
    candidates.extend(["libnccl.so.2".to_string(), "libnccl.so".to_string()]);
    let mut tried = Vec::new();
    for name in &candidates {
        // SAFETY: loading NCCL runs its initialisers, which are safe to run in any process.
        match unsafe { libloading::Library::new(name) } {
            Ok(lib) => return resolve(lib, name),
            Err(e) => tried.push(format!("{name}: {e}")),
        }
    }
    Err(format!(
        "the NCCL library was not found (tried {}); install NCCL or set {NCCL_LIBRARY_ENV} to \
         the path of libnccl.so.2",
        tried.join("; ")
    ))
}

fn resolve(lib: libloading::Library, path: &str) -> std::result::Result<Api, String> {
    macro_rules! sym {
        ($name:literal) => {
            // SAFETY: the symbol is NCCL's, with the C signature of the field it fills.
            *unsafe { lib.get(concat!($name, "\0").as_bytes()) }.map_err(|e| {
                format!("{path} lacks {} ({e}); NCCL 2.17 or newer is needed", $name)
            })?
        };
    }
    Ok(Api {
        path: path.to_string(),
        get_version: sym!("ncclGetVersion"),
        get_unique_id: sym!("ncclGetUniqueId"),
        comm_init_rank_config: sym!("ncclCommInitRankConfig"),
        comm_finalize: sym!("ncclCommFinalize"),
        comm_destroy: sym!("ncclCommDestroy"),
        comm_abort: sym!("ncclCommAbort"),
        comm_get_async_error: sym!("ncclCommGetAsyncError"),
        get_error_string: sym!("ncclGetErrorString"),
        get_last_error: sym!("ncclGetLastError"),
        all_reduce: sym!("ncclAllReduce"),
        reduce_scatter: sym!("ncclReduceScatter"),
        all_gather: sym!("ncclAllGather"),
        broadcast: sym!("ncclBroadcast"),
        send: sym!("ncclSend"),
        recv: sym!("ncclRecv"),
        group_start: sym!("ncclGroupStart"),
        group_end: sym!("ncclGroupEnd"),
        _lib: lib,
    })
}

fn api() -> Result<&'static Api> {
    static API: OnceLock<std::result::Result<Api, String>> = OnceLock::new();
    API.get_or_init(|| {
        let api = load();
        match &api {
            Ok(a) => log::debug!(target: "warp_cuda::nccl", "loaded NCCL from {}", a.path),
            Err(e) => log::debug!(target: "warp_cuda::nccl", "{e}"),
        }
        api
    })
    .as_ref()
    .map_err(|e| CudaError::NotAvailable(e.clone()))
}

/// Whether the NCCL library can be loaded (it is loaded by this call when it can).
pub fn is_available() -> bool {
    api().is_ok()
}

/// The loaded NCCL's version as `(major, minor, patch)`.
///
/// # Errors
/// [`CudaError::NotAvailable`] when NCCL cannot be loaded.
pub fn version() -> Result<(u32, u32, u32)> {
    let api = api()?;
    let mut v: c_int = 0;
    // SAFETY: a valid out pointer.
    check(api, unsafe { (api.get_version)(&mut v) }, None, || {
        "ncclGetVersion".into()
    })?;
    let v = v as u32;
    Ok((v / 10000, (v % 10000) / 100, v % 100))
}

fn error_string(api: &Api, code: NcclResult) -> String {
    // SAFETY: NCCL returns a static C string for any code.
    let p = unsafe { (api.get_error_string)(code) };
    if p.is_null() {
        return format!("NCCL error {code}");
    }
    // SAFETY: non-null, NUL-terminated, static.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

fn last_error(api: &Api, comm: Option<NcclComm>) -> String {
    // SAFETY: a null communicator asks for the thread's last error, which NCCL allows.
    let p = unsafe { (api.get_last_error)(comm.unwrap_or(std::ptr::null_mut())) };
    if p.is_null() {
        return String::new();
    }
    // SAFETY: non-null, NUL-terminated, owned by NCCL until the next call on this thread.
    unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
}

fn nccl_error(api: &Api, code: NcclResult, comm: Option<NcclComm>, op: String) -> CudaError {
    let detail = last_error(api, comm);
    CudaError::Nccl {
        op,
        code,
        message: if detail.is_empty() {
            error_string(api, code)
        } else {
            format!("{} ({detail})", error_string(api, code))
        },
    }
}

/// Ok for success and in-progress (which the caller then polls), an error otherwise.
fn check(
    api: &Api,
    code: NcclResult,
    comm: Option<NcclComm>,
    op: impl FnOnce() -> String,
) -> Result<()> {
    match code {
        NCCL_SUCCESS | NCCL_IN_PROGRESS => Ok(()),
        c => Err(nccl_error(api, c, comm, op())),
    }
}

/// The unique id that names one communicator clique: rank 0 makes it with [`UniqueId::new`]
/// and hands it to every rank (over a file, an environment variable, MPI, a socket).
#[derive(Clone, Copy)]
pub struct UniqueId(RawUniqueId);

impl UniqueId {
    /// A new id (NCCL picks a network interface and port for its bootstrap here).
    ///
    /// # Errors
    /// [`CudaError::NotAvailable`] without NCCL; [`CudaError::Nccl`] when NCCL fails.
    pub fn new() -> Result<UniqueId> {
        let api = api()?;
        let mut id = RawUniqueId { internal: [0; 128] };
        // SAFETY: a valid out pointer to 128 bytes.
        let code = unsafe { (api.get_unique_id)(&mut id) };
        check(api, code, None, || "ncclGetUniqueId".into())?;
        Ok(UniqueId(id))
    }

    /// The id's 128 bytes.
    pub fn to_bytes(&self) -> [u8; 128] {
        self.0.internal.map(|c| c as u8)
    }

    /// An id from the bytes of [`to_bytes`](Self::to_bytes).
    pub fn from_bytes(bytes: [u8; 128]) -> UniqueId {
        UniqueId(RawUniqueId {
            internal: bytes.map(|b| b as c_char),
        })
    }

    /// The id as 256 lowercase hexadecimal digits (for an environment variable or a file).
    pub fn to_hex(&self) -> String {
        self.to_bytes().iter().map(|b| format!("{b:02x}")).collect()
    }

    /// Parses [`to_hex`](Self::to_hex)'s text (surrounding whitespace is ignored).
    ///
    /// # Errors
    /// [`CudaError::InvalidArgument`] unless the text is exactly 256 hexadecimal digits.
    pub fn from_hex(text: &str) -> Result<UniqueId> {
        let t = text.trim();
        let bad = || {
            CudaError::InvalidArgument(format!(
                "an NCCL unique id is 256 hexadecimal digits, got {} characters{}",
                t.len(),
                if t.len() > 16 {
                    format!(" starting \"{}\"", t.chars().take(16).collect::<String>())
                } else {
                    format!(" \"{t}\"")
                }
            ))
        };
        if t.len() != 256 || !t.is_ascii() {
            return Err(bad());
        }
        let mut bytes = [0u8; 128];
        for (i, b) in bytes.iter_mut().enumerate() {
            *b = u8::from_str_radix(&t[2 * i..2 * i + 2], 16).map_err(|_| bad())?;
        }
        Ok(UniqueId::from_bytes(bytes))
    }
}

impl std::fmt::Debug for UniqueId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let hex = self.to_hex();
        write!(f, "UniqueId({}..)", &hex[..16])
    }
}

/// One rank of an NCCL communicator, on one GPU.
///
/// Collectives are queued on a stream of the communicator's GPU and run when every rank has
/// queued its part; [`synchronize`](Self::synchronize) waits for a stream with the
/// communicator's timeout. Dropping the communicator finalizes and destroys it on a thread of
/// its own (destroying is a collective of the node's ranks; see `Drop`), or aborts it when it
/// does not finalize within the timeout.
pub struct Comm {
    /// The NCCL handle: used only while `lock` is held by the calling thread (or in `Drop`,
    /// which owns the communicator).
    raw: NcclComm,
    /// Serialises the NCCL calls on `raw` and on every communicator of its GPU (see "One call
    /// at a time" in the module). In an `Arc` because an open [`Group`] and the teardown
    /// thread hold it beyond a borrow.
    lock: Arc<CallLock>,
    gpu: Arc<Gpu>,
    rank: usize,
    world: usize,
    /// The timeout in nanoseconds (settable through shared handles).
    timeout_ns: AtomicU64,
    /// Set once `ncclCommAbort` has freed `raw` (read under the lock before every call).
    aborted: AtomicBool,
    /// An [`abort`](Comm::abort) that could not take the lock in time: the holder aborts at
    /// its next poll, and every later call does.
    abort_pending: AtomicBool,
}

// SAFETY: NCCL's user guide ("Thread Safety", quoted in the module docs) allows a
// communicator to be operated from any thread as long as one thread at a time operates it,
// and no two threads to operate communicators of one device in parallel, a group's calls
// coming from one thread. Every use of `raw` through `&self` happens while the calling thread
// holds `lock`, its GPU's lock ([`device_lock`]), which a group's thread keeps until the group
// ends (a
// re-entrant lock checked after acquisition for an earlier abort, so a freed handle is
// never used), and `Drop` owns the communicator (its teardown thread takes the lock too,
// after any group still holding it has ended). So moving or sharing a `Comm` between
// threads never lets two NCCL calls on one communicator overlap.
unsafe impl Send for Comm {}
unsafe impl Sync for Comm {}

/// The call lock of GPU `ordinal`, one per device for the whole process: NCCL allows no two
/// threads to issue operations in parallel to communicators of one device.
fn device_lock(ordinal: usize) -> Arc<CallLock> {
    static LOCKS: Mutex<Vec<Arc<CallLock>>> = Mutex::new(Vec::new());
    let mut locks = LOCKS.lock().unwrap_or_else(|e| e.into_inner());
    while locks.len() <= ordinal {
        locks.push(Arc::default());
    }
    locks[ordinal].clone()
}

/// A re-entrant lock with a bounded wait: the call lock of one GPU's communicators.
///
/// Not `std::sync::Mutex`: a thread re-enters it (a [`Group`] holds it across several calls
/// on one communicator, a timed-out wait aborts under it), an open group keeps it past the
/// call that took it (a `MutexGuard` would borrow the communicator), and waiting for it must
/// end in an error after the communicator's timeout rather than hang.
#[derive(Default)]
struct CallLock {
    state: Mutex<LockState>,
    freed: Condvar,
}

#[derive(Default)]
struct LockState {
    owner: Option<ThreadId>,
    depth: usize,
}

impl CallLock {
    /// Takes the lock for the calling thread (again, if it holds it already); false when
    /// another thread held it for all of `timeout`.
    fn acquire(&self, timeout: Duration) -> bool {
        let me = std::thread::current().id();
        let deadline = Instant::now().checked_add(timeout);
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        loop {
            match st.owner {
                None => {
                    st.owner = Some(me);
                    st.depth = 1;
                    return true;
                }
                Some(o) if o == me => {
                    st.depth += 1;
                    return true;
                }
                Some(_) => {
                    let wait = match deadline {
                        Some(d) => match d.checked_duration_since(Instant::now()) {
                            Some(w) if !w.is_zero() => w,
                            _ => return false,
                        },
                        // A timeout too large for an `Instant`: wait in steps, for ever.
                        None => Duration::from_secs(3600),
                    };
                    st = self
                        .freed
                        .wait_timeout(st, wait)
                        .unwrap_or_else(|p| p.into_inner())
                        .0;
                }
            }
        }
    }

    /// Undoes one `acquire` of the calling thread.
    fn release(&self) {
        let mut st = self.state.lock().unwrap_or_else(|p| p.into_inner());
        debug_assert_eq!(st.owner, Some(std::thread::current().id()));
        st.depth = st.depth.saturating_sub(1);
        if st.depth == 0 {
            st.owner = None;
            self.freed.notify_all();
        }
    }
}

/// One `acquire` of a [`CallLock`], released when dropped.
struct Held<'a>(&'a CallLock);

impl Drop for Held<'_> {
    fn drop(&mut self) {
        self.0.release();
    }
}

impl std::fmt::Debug for Comm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Comm(rank {} of {} on cuda:{})",
            self.rank,
            self.world,
            self.gpu.ordinal()
        )
    }
}

/// How a wait polls: yields the CPU for the first polls (an operation that is about to be
/// ready should not cost a sleep's latency: a step's halo exchange waits here), then sleeps
/// with a doubling pause up to 1 ms.
#[derive(Default)]
struct Backoff {
    polls: u32,
    pause: Duration,
}

impl Backoff {
    fn pause(&mut self) {
        self.polls += 1;
        if self.polls < 1000 {
            std::thread::yield_now();
            return;
        }
        self.pause = (self.pause * 2).clamp(Duration::from_micros(10), Duration::from_millis(1));
        std::thread::sleep(self.pause);
    }
}

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

fn check_world(rank: usize, world: usize) -> Result<()> {
    if world == 0 || rank >= world || world > c_int::MAX as usize {
        return Err(CudaError::InvalidArgument(format!(
            "NCCL rank {rank} of a world of {world} (ranks are 0..world, world at least 1)"
        )));
    }
    Ok(())
}

impl Comm {
    /// Rank `rank` of a world of `world` ranks named by `id`, on `gpu`: one process (or one
    /// thread) per GPU. Returns when every rank has joined, or fails after `timeout` (a
    /// missing rank, a different `world` elsewhere, an id from another clique).
    ///
    /// # Errors
    /// [`CudaError::InvalidArgument`] for a rank outside the world;
    /// [`CudaError::NotAvailable`] without NCCL; [`CudaError::Nccl`] when NCCL fails;
    /// [`CudaError::Timeout`] when the ranks have not all joined within `timeout`.
    pub fn init_rank(
        gpu: &Arc<Gpu>,
        rank: usize,
        world: usize,
        id: &UniqueId,
        timeout: Duration,
    ) -> Result<Comm> {
        check_world(rank, world)?;
        let api = api()?;
        gpu.bind()?;
        let mut raw: NcclComm = std::ptr::null_mut();
        let mut config = RawConfig::non_blocking();
        // SAFETY: valid out pointer and config; the id is 128 bytes by value.
        let code = unsafe {
            (api.comm_init_rank_config)(&mut raw, world as c_int, id.0, rank as c_int, &mut config)
        };
        let op = || {
            format!(
                "ncclCommInitRank (rank {rank} of {world} on cuda:{})",
                gpu.ordinal()
            )
        };
        if code != NCCL_SUCCESS && code != NCCL_IN_PROGRESS {
            let err = nccl_error(api, code, None, op());
            if !raw.is_null() {
                // SAFETY: a communicator NCCL handed back, never used again.
                unsafe { (api.comm_abort)(raw) };
            }
            return Err(err);
        }
        let comm = Comm {
            raw,
            lock: device_lock(gpu.ordinal()),
            gpu: gpu.clone(),
            rank,
            world,
            timeout_ns: AtomicU64::new(nanos(timeout)),
            aborted: AtomicBool::new(false),
            abort_pending: AtomicBool::new(false),
        };
        comm.wait_ready(op)?;
        Ok(comm)
    }

    /// One communicator per GPU of `gpus`, all in this process: rank `i` on `gpus[i]`.
    ///
    /// # Errors
    /// As [`init_rank`](Self::init_rank); the same GPU twice is an
    /// [`CudaError::InvalidArgument`] (NCCL needs one rank per GPU).
    pub fn init_all(gpus: &[Arc<Gpu>], timeout: Duration) -> Result<Vec<Comm>> {
        for (i, g) in gpus.iter().enumerate() {
            if let Some(j) = gpus[..i].iter().position(|h| h.ordinal() == g.ordinal()) {
                return Err(CudaError::InvalidArgument(format!(
                    "NCCL communicators need one rank per GPU: cuda:{} is given as rank {j} \
                     and rank {i}",
                    g.ordinal()
                )));
            }
        }
        check_world(0, gpus.len())?;
        let api = api()?;
        let id = UniqueId::new()?;
        let world = gpus.len();
        let mut raws: Vec<NcclComm> = vec![std::ptr::null_mut(); world];
        let group = Group::start()?;
        let mut first_err = None;
        for (rank, gpu) in gpus.iter().enumerate() {
            gpu.bind()?;
            let mut config = RawConfig::non_blocking();
            // SAFETY: as in `init_rank`; inside a group NCCL defers the work to the group end.
            let code = unsafe {
                (api.comm_init_rank_config)(
                    &mut raws[rank],
                    world as c_int,
                    id.0,
                    rank as c_int,
                    &mut config,
                )
            };
            if let Err(e) = check(api, code, None, || {
                format!(
                    "ncclCommInitRank (rank {rank} of {world} on cuda:{})",
                    gpu.ordinal()
                )
            }) {
                first_err.get_or_insert(e);
            }
        }
        let end = group.end();
        let comms: Vec<Comm> = raws
            .into_iter()
            .zip(gpus)
            .enumerate()
            .filter(|(_, (raw, _))| !raw.is_null())
            .map(|(rank, (raw, gpu))| Comm {
                raw,
                lock: device_lock(gpu.ordinal()),
                gpu: gpu.clone(),
                rank,
                world,
                timeout_ns: AtomicU64::new(nanos(timeout)),
                aborted: AtomicBool::new(false),
                abort_pending: AtomicBool::new(false),
            })
            .collect();
        if let Some(e) = first_err {
            comms.iter().for_each(Comm::abort);
            return Err(e);
        }
        end?;
        for c in &comms {
            c.wait_ready(|| {
                format!(
                    "ncclCommInitRank (rank {} of {world} on cuda:{})",
                    c.rank,
                    c.gpu.ordinal()
                )
            })?;
        }
        Ok(comms)
    }

    /// This communicator's rank.
    pub fn rank(&self) -> usize {
        self.rank
    }

    /// The number of ranks.
    pub fn world_size(&self) -> usize {
        self.world
    }

    /// The GPU this rank runs on.
    pub fn gpu(&self) -> &Arc<Gpu> {
        &self.gpu
    }

    /// How long calls wait for peers before they abort the communicator.
    pub fn timeout(&self) -> Duration {
        Duration::from_nanos(self.timeout_ns.load(Ordering::Relaxed))
    }

    /// Changes the timeout.
    pub fn set_timeout(&self, timeout: Duration) {
        self.timeout_ns.store(nanos(timeout), Ordering::Relaxed);
    }

    /// Whether the communicator was aborted (after a timeout or an asynchronous error): it
    /// then refuses every call.
    pub fn is_aborted(&self) -> bool {
        self.aborted.load(Ordering::Acquire)
    }

    /// Aborts the communicator: its queued and running collectives stop, and every later call
    /// fails. Peers blocked on this rank then time out or see a remote error.
    ///
    /// A call of another thread still in progress on this communicator finishes first (it
    /// holds the call lock, for at most the timeout); if it holds the lock longer (an open
    /// [`Group`]), the abort is left to that thread's next poll or call.
    pub fn abort(&self) {
        match self.hold(self.timeout()) {
            Some(_held) => self.abort_locked(),
            None => self.abort_pending.store(true, Ordering::Release),
        }
    }

    /// Takes the call lock (waiting at most `timeout`); see [`CallLock`].
    fn hold(&self, timeout: Duration) -> Option<Held<'_>> {
        self.lock.acquire(timeout).then(|| Held(&self.lock))
    }

    /// [`hold`](Self::hold) with the communicator's timeout, as an error naming `op`.
    fn hold_for(&self, op: &dyn Fn() -> String) -> Result<Held<'_>> {
        let start = Instant::now();
        self.hold(self.timeout()).ok_or_else(|| CudaError::Timeout {
            op: format!(
                "{}: another thread kept NCCL rank {} of {} busy (a call or an open group on \
                 the same communicator)",
                op(),
                self.rank,
                self.world
            ),
            waited: start.elapsed(),
        })
    }

    /// `ncclCommAbort`, once. The caller holds the call lock.
    fn abort_locked(&self) {
        if !self.aborted.swap(true, Ordering::AcqRel) {
            if let Ok(api) = api() {
                // SAFETY: a live communicator, used by no other thread (the caller holds the
                // call lock); marked aborted first so no call follows.
                unsafe { (api.comm_abort)(self.raw) };
            }
        }
    }

    /// The API, if the communicator may still be called. The caller holds the call lock, so
    /// no other thread can abort (free) the communicator between this check and the call.
    fn live(&self, op: &dyn Fn() -> String) -> Result<&'static Api> {
        if self.abort_pending.load(Ordering::Acquire) {
            self.abort_locked();
        }
        if self.is_aborted() {
            return Err(CudaError::InvalidArgument(format!(
                "{}: the NCCL communicator (rank {} of {}) was aborted after an earlier \
                 timeout or error; make a new one",
                op(),
                self.rank,
                self.world
            )));
        }
        api()
    }

    /// The communicator's asynchronous state: Ok(true) when ready, Ok(false) while an
    /// operation is in progress, an error (after which the communicator is aborted). The
    /// caller holds the call lock.
    fn async_state(&self, api: &Api, op: &dyn Fn() -> String) -> Result<bool> {
        let mut state: NcclResult = NCCL_SUCCESS;
        // SAFETY: a live communicator and a valid out pointer.
        let code = unsafe { (api.comm_get_async_error)(self.raw, &mut state) };
        for c in [code, state] {
            if c != NCCL_SUCCESS && c != NCCL_IN_PROGRESS {
                let e = nccl_error(api, c, Some(self.raw), op());
                self.abort_locked();
                return Err(e);
            }
        }
        Ok(state == NCCL_SUCCESS)
    }

    /// Waits until the calls made on this communicator (those of a [`Group`] after its end)
    /// are queued on their streams: NCCL's non-blocking mode may still be setting them up when
    /// a call returns. Aborts and fails after the timeout.
    ///
    /// # Errors
    /// [`CudaError::Timeout`], or NCCL's asynchronous error.
    pub fn wait_queued(&self) -> Result<()> {
        self.wait_ready(|| {
            format!(
                "queuing NCCL work on rank {} of {} (cuda:{})",
                self.rank,
                self.world,
                self.gpu.ordinal()
            )
        })
    }

    /// Polls until the communicator's last call is no longer in progress; aborts and fails
    /// after the timeout. Holds the call lock throughout: NCCL allows no other call on the
    /// communicator while one is in progress.
    fn wait_ready(&self, op: impl Fn() -> String) -> Result<()> {
        let _held = self.hold_for(&op)?;
        let start = Instant::now();
        let mut backoff = Backoff::default();
        loop {
            // `live` each poll: an abort left pending by another thread is done here.
            let api = self.live(&op)?;
            if self.async_state(api, &op)? {
                return Ok(());
            }
            if start.elapsed() > self.timeout() {
                self.abort_locked();
                return Err(CudaError::Timeout {
                    op: op(),
                    waited: start.elapsed(),
                });
            }
            backoff.pause();
        }
    }

    fn check_stream(&self, stream: &Stream, op: &dyn Fn() -> String) -> Result<()> {
        if stream.ordinal() != self.gpu.ordinal() {
            return Err(CudaError::InvalidArgument(format!(
                "{}: a stream of cuda:{} for the communicator on cuda:{}",
                op(),
                stream.ordinal(),
                self.gpu.ordinal()
            )));
        }
        Ok(())
    }

    /// Issues one NCCL call (`call` gets the communicator and the stream) and waits until it
    /// is queued, holding the call lock. Inside a [`Group`] NCCL defers the work to the
    /// group's end, so the lock stays held by this thread until then.
    fn issue(
        &self,
        stream: &Stream,
        op: &dyn Fn() -> String,
        call: impl FnOnce(&Api, NcclComm, *mut c_void) -> NcclResult,
    ) -> Result<()> {
        self.check_stream(stream, op)?;
        let _held = self.hold_for(op)?;
        let in_group = Group::depth() > 0;
        let already_in_group =
            in_group && GROUP_HELD.with(|h| h.borrow().iter().any(|l| Arc::ptr_eq(l, &self.lock)));
        if !already_in_group {
            // Another thread's group may have ended just before this thread took the lock,
            // its work still being set up: NCCL allows no call until the communicator is
            // ready again (immediate when it is).
            self.wait_ready(op)?;
        }
        let api = self.live(op)?;
        self.gpu.bind()?;
        let code = call(api, self.raw, stream.cu_stream() as *mut c_void);
        if code != NCCL_SUCCESS && code != NCCL_IN_PROGRESS {
            return Err(nccl_error(api, code, Some(self.raw), op()));
        }
        if !in_group {
            self.wait_ready(op)?;
        } else {
            // Re-entrant, so immediate; released by the outermost group's end.
            self.lock.acquire(Duration::ZERO);
            GROUP_HELD.with(|h| h.borrow_mut().push(self.lock.clone()));
        }
        Ok(())
    }

    /// All-reduce of `count` elements of `dtype`: `recv` gets the reduction of every rank's
    /// `send` (the same pointer for in place).
    ///
    /// # Safety
    /// `send` and `recv` address `count` elements of `dtype` on this communicator's GPU, valid
    /// until the operation completes on `stream`.
    pub unsafe fn all_reduce(
        &self,
        send: u64,
        recv: u64,
        count: usize,
        dtype: DataType,
        op: ReduceOp,
        stream: &Stream,
    ) -> Result<()> {
        let what = || {
            format!(
                "ncclAllReduce ({op:?}) of {count} {dtype:?} on rank {}",
                self.rank
            )
        };
        self.issue(stream, &what, |api, comm, s| {
            // SAFETY: the caller's contract.
            unsafe {
                (api.all_reduce)(
                    send as *const c_void,
                    recv as *mut c_void,
                    count,
                    dtype.raw(),
                    op.raw(),
                    comm,
                    s,
                )
            }
        })
    }

    /// Reduce-scatter: `recv` (`recv_count` elements) gets block `rank` of the reduction of
    /// every rank's `send` (`recv_count * world` elements).
    ///
    /// # Safety
    /// As [`all_reduce`](Self::all_reduce), for the sizes above.
    pub unsafe fn reduce_scatter(
        &self,
        send: u64,
        recv: u64,
        recv_count: usize,
        dtype: DataType,
        op: ReduceOp,
        stream: &Stream,
    ) -> Result<()> {
        let what = || {
            format!(
                "ncclReduceScatter ({op:?}) of {recv_count} {dtype:?} per rank on rank {}",
                self.rank
            )
        };
        self.issue(stream, &what, |api, comm, s| {
            // SAFETY: the caller's contract.
            unsafe {
                (api.reduce_scatter)(
                    send as *const c_void,
                    recv as *mut c_void,
                    recv_count,
                    dtype.raw(),
                    op.raw(),
                    comm,
                    s,
                )
            }
        })
    }

    /// All-gather: `recv` (`send_count * world` elements) gets every rank's `send`
    /// (`send_count` elements) in rank order.
    ///
    /// # Safety
    /// As [`all_reduce`](Self::all_reduce), for the sizes above.
    pub unsafe fn all_gather(
        &self,
        send: u64,
        recv: u64,
        send_count: usize,
        dtype: DataType,
        stream: &Stream,
    ) -> Result<()> {
        let what = || {
            format!(
                "ncclAllGather of {send_count} {dtype:?} per rank on rank {}",
                self.rank
            )
        };
        self.issue(stream, &what, |api, comm, s| {
            // SAFETY: the caller's contract.
            unsafe {
                (api.all_gather)(
                    send as *const c_void,
                    recv as *mut c_void,
                    send_count,
                    dtype.raw(),
                    comm,
                    s,
                )
            }
        })
    }

    /// Broadcast: every rank's `recv` gets `root`'s `send` (`send` is read on the root only).
    ///
    /// # Safety
    /// As [`all_reduce`](Self::all_reduce).
    pub unsafe fn broadcast(
        &self,
        send: u64,
        recv: u64,
        count: usize,
        dtype: DataType,
        root: usize,
        stream: &Stream,
    ) -> Result<()> {
        let what = || {
            format!(
                "ncclBroadcast of {count} {dtype:?} from rank {root} on rank {}",
                self.rank
            )
        };
        if root >= self.world {
            return Err(CudaError::InvalidArgument(format!(
                "{}: the root is not a rank of this world of {}",
                what(),
                self.world
            )));
        }
        self.issue(stream, &what, |api, comm, s| {
            // SAFETY: the caller's contract.
            unsafe {
                (api.broadcast)(
                    send as *const c_void,
                    recv as *mut c_void,
                    count,
                    dtype.raw(),
                    root as c_int,
                    comm,
                    s,
                )
            }
        })
    }

    fn check_peer(&self, peer: usize, what: &dyn Fn() -> String) -> Result<()> {
        if peer >= self.world || peer == self.rank {
            return Err(CudaError::InvalidArgument(format!(
                "{}: peer {peer} is not another rank of this world of {} (this is rank {})",
                what(),
                self.world,
                self.rank
            )));
        }
        Ok(())
    }

    /// Sends `count` elements to rank `peer`, which must post the matching
    /// [`recv`](Self::recv). Pairs of sends and receives between the same ranks go in one
    /// [`Group`] (otherwise two ranks sending to each other first wait forever).
    ///
    /// # Safety
    /// As [`all_reduce`](Self::all_reduce).
    pub unsafe fn send(
        &self,
        send: u64,
        count: usize,
        dtype: DataType,
        peer: usize,
        stream: &Stream,
    ) -> Result<()> {
        let what = || {
            format!(
                "ncclSend of {count} {dtype:?} from rank {} to {peer}",
                self.rank
            )
        };
        self.check_peer(peer, &what)?;
        self.issue(stream, &what, |api, comm, s| {
            // SAFETY: the caller's contract.
            unsafe {
                (api.send)(
                    send as *const c_void,
                    count,
                    dtype.raw(),
                    peer as c_int,
                    comm,
                    s,
                )
            }
        })
    }

    /// Receives `count` elements from rank `peer` (see [`send`](Self::send)).
    ///
    /// # Safety
    /// As [`all_reduce`](Self::all_reduce).
    pub unsafe fn recv(
        &self,
        recv: u64,
        count: usize,
        dtype: DataType,
        peer: usize,
        stream: &Stream,
    ) -> Result<()> {
        let what = || {
            format!(
                "ncclRecv of {count} {dtype:?} on rank {} from {peer}",
                self.rank
            )
        };
        self.check_peer(peer, &what)?;
        self.issue(stream, &what, |api, comm, s| {
            // SAFETY: the caller's contract.
            unsafe {
                (api.recv)(
                    recv as *mut c_void,
                    count,
                    dtype.raw(),
                    peer as c_int,
                    comm,
                    s,
                )
            }
        })
    }

    /// Waits for `stream` (a stream of this communicator's GPU) to finish, watching the
    /// communicator: an asynchronous NCCL error (a peer that failed or aborted) or the timeout
    /// passing (a peer that never posted its part) aborts the communicator and returns an
    /// error rather than waiting forever.
    ///
    /// # Errors
    /// [`CudaError::Timeout`], [`CudaError::Nccl`], or the stream's own error.
    pub fn synchronize(&self, stream: &Stream) -> Result<()> {
        let what = || {
            format!(
                "waiting for NCCL rank {} of {} on cuda:{}",
                self.rank,
                self.world,
                self.gpu.ordinal()
            )
        };
        self.check_stream(stream, &what)?;
        let start = Instant::now();
        let mut backoff = Backoff::default();
        loop {
            // The stream is the driver's, not NCCL's: queried without the lock.
            if stream.query()? {
                return Ok(());
            }
            // The lock for each poll only, not for the whole wait: other threads' calls on
            // this communicator go on meanwhile (one of them may be what this stream waits
            // for, on a peer's side).
            let held = self.hold_for(&what)?;
            let api = self.live(&what)?;
            self.async_state(api, &what)?;
            if start.elapsed() > self.timeout() {
                self.abort_locked();
                return Err(CudaError::Timeout {
                    op: format!("{} (a peer never posted its matching operation?)", what()),
                    waited: start.elapsed(),
                });
            }
            drop(held);
            backoff.pause();
        }
    }
}

impl Drop for Comm {
    fn drop(&mut self) {
        let Ok(api) = api() else { return };
        if self.is_aborted() {
            return;
        }
        // Finalize flushes this rank's outstanding work, and destroy is an intra-node
        // collective: it waits for the other ranks of this node to destroy theirs. Ranks that
        // one thread drops one after another (a `Vec` of `init_all`'s communicators) would
        // wait for each other forever, so the teardown runs on a thread of its own, with the
        // timeout for the finalize and an abort if it does not complete.
        struct Raw(NcclComm);
        // SAFETY: the handle moves to the teardown thread and is used there only, under the
        // call lock.
        unsafe impl Send for Raw {}
        let raw = Raw(self.raw);
        let gpu = self.gpu.clone();
        let timeout = self.timeout();
        let lock = self.lock.clone();
        let pending_abort = self.abort_pending.load(Ordering::Acquire);
        teardowns::started();
        let spawned = std::thread::Builder::new()
            .name("warp-nccl-teardown".into())
            .spawn(move || {
                let _done = teardowns::Done;
                let raw = raw;
                // A group of another thread may still hold the communicator (its calls are
                // issued at the group's end): finalize after it. If it does not let go within
                // the timeout, leak the handle rather than free it under that group.
                if !lock.acquire(timeout) {
                    log::warn!(
                        target: "warp_cuda::nccl",
                        "a dropped NCCL communicator stays in use by an open group: not \
                         destroyed"
                    );
                    return;
                }
                let _held = Held(&lock);
                let _ = gpu.bind();
                if pending_abort {
                    // SAFETY: a live communicator that nothing else uses any more; once.
                    unsafe { (api.comm_abort)(raw.0) };
                    return;
                }
                // SAFETY: a live communicator that nothing else uses any more.
                let code = unsafe { (api.comm_finalize)(raw.0) };
                let start = Instant::now();
                let mut finalized = code == NCCL_SUCCESS || code == NCCL_IN_PROGRESS;
                while finalized {
                    let mut state: NcclResult = NCCL_SUCCESS;
                    // SAFETY: as above.
                    let c = unsafe { (api.comm_get_async_error)(raw.0, &mut state) };
                    if c != NCCL_SUCCESS || (state != NCCL_SUCCESS && state != NCCL_IN_PROGRESS) {
                        finalized = false;
                    } else if state == NCCL_SUCCESS {
                        break;
                    } else if start.elapsed() > timeout {
                        finalized = false;
                    } else {
                        std::thread::sleep(Duration::from_micros(100));
                    }
                }
                // SAFETY: finalized (destroy frees it) or not (abort frees it); once.
                unsafe {
                    if finalized {
                        (api.comm_destroy)(raw.0);
                    } else {
                        (api.comm_abort)(raw.0);
                    }
                }
            });
        if spawned.is_err() {
            teardowns::finished();
            // No thread to be had: abort, which is local, unless a group of another thread
            // still holds the communicator (then leak it rather than free it under the group).
            if self.lock.acquire(Duration::ZERO) {
                let _held = Held(&self.lock);
                // SAFETY: a live communicator, freed once, under the call lock.
                unsafe { (api.comm_abort)(self.raw) };
            }
        }
    }
}

/// The teardown threads still running. The process must not exit under them (NCCL's and
/// CUDA's own exit handlers would free what they are using: a crash at exit), so the first
/// teardown registers an exit handler that waits for them, for at most 30 s.
mod teardowns {
    use std::sync::{Condvar, Mutex, Once};
    use std::time::{Duration, Instant};

    static RUNNING: Mutex<usize> = Mutex::new(0);
    static CHANGED: Condvar = Condvar::new();

    pub(super) fn started() {
        static REGISTER: Once = Once::new();
        REGISTER.call_once(|| {
            #[cfg(unix)]
            // SAFETY: registers a plain `extern "C" fn()`; handlers registered after NCCL and
            // the driver were loaded run before theirs.
            unsafe {
                libc::atexit(wait_at_exit);
            }
        });
        *RUNNING.lock().unwrap_or_else(|p| p.into_inner()) += 1;
    }

    pub(super) fn finished() {
        let mut n = RUNNING.lock().unwrap_or_else(|p| p.into_inner());
        *n = n.saturating_sub(1);
        CHANGED.notify_all();
    }

    /// Marks its thread's teardown finished when dropped (also if the thread panics).
    pub(super) struct Done;

    impl Drop for Done {
        fn drop(&mut self) {
            finished();
        }
    }

    /// Waits until no teardown runs, at most `limit`; returns whether none does.
    pub(super) fn wait(limit: Duration) -> bool {
        let deadline = Instant::now() + limit;
        let mut n = RUNNING.lock().unwrap_or_else(|p| p.into_inner());
        while *n > 0 {
            let now = Instant::now();
            if now >= deadline {
                return false;
            }
            n = CHANGED
                .wait_timeout(n, deadline - now)
                .unwrap_or_else(|p| p.into_inner())
                .0;
        }
        true
    }

    #[cfg(unix)]
    extern "C" fn wait_at_exit() {
        if !wait(Duration::from_secs(30)) {
            log::warn!(
                target: "warp_cuda::nccl",
                "exiting with NCCL communicators still being torn down (a peer is gone?)"
            );
        }
    }
}

/// Waits (at most `limit`) until the communicators dropped so far are torn down; returns
/// whether they are. A dropped communicator is finalized and destroyed on a thread of its
/// own (see [`Comm`]); the process also waits for them at exit.
pub fn wait_for_teardowns(limit: Duration) -> bool {
    teardowns::wait(limit)
}

thread_local! {
    static GROUP_DEPTH: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
    /// The call locks taken by calls inside this thread's open groups, one entry per
    /// acquisition: released when the outermost group ends (see [`Comm::issue`]).
    static GROUP_HELD: RefCell<Vec<Arc<CallLock>>> = const { RefCell::new(Vec::new()) };
}

/// An NCCL group on the calling thread (`ncclGroupStart` .. `ncclGroupEnd`): the calls made
/// while it is open are issued together at [`end`](Self::end). One thread driving several GPUs
/// must put their collectives in one group, and paired sends and receives go in one group.
/// Dropping an open group ends it (errors then are lost: call `end`).
#[must_use = "a group issues its calls when it ends"]
#[derive(Debug)]
pub struct Group {
    open: bool,
}

impl Group {
    /// Opens a group.
    ///
    /// # Errors
    /// [`CudaError::NotAvailable`] without NCCL.
    pub fn start() -> Result<Group> {
        let api = api()?;
        // SAFETY: no arguments.
        check(api, unsafe { (api.group_start)() }, None, || {
            "ncclGroupStart".into()
        })?;
        GROUP_DEPTH.with(|d| d.set(d.get() + 1));
        Ok(Group { open: true })
    }

    /// The number of groups open on the calling thread.
    pub fn depth() -> usize {
        GROUP_DEPTH.with(|d| d.get())
    }

    /// Ends the group, issuing its calls. The communicators used inside then still need
    /// their work polled to completion: [`Comm::synchronize`] does.
    ///
    /// # Errors
    /// [`CudaError::Nccl`] when NCCL refuses the group.
    pub fn end(mut self) -> Result<()> {
        self.finish()
    }

    fn finish(&mut self) -> Result<()> {
        if !std::mem::take(&mut self.open) {
            return Ok(());
        }
        let depth = GROUP_DEPTH.with(|d| {
            d.set(d.get().saturating_sub(1));
            d.get()
        });
        let end = api().and_then(|api| {
            // SAFETY: matches this group's start.
            check(api, unsafe { (api.group_end)() }, None, || {
                "ncclGroupEnd".into()
            })
        });
        if depth == 0 {
            // The outermost end issued the calls: the communicators are free again.
            let held = GROUP_HELD.with(|h| std::mem::take(&mut *h.borrow_mut()));
            held.iter().for_each(|l| l.release());
        }
        end
    }
}

impl Drop for Group {
    fn drop(&mut self) {
        let _ = self.finish();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicUsize;

    /// `Comm` stays `Send + Sync` (the runtime's `Communicator` is `Clone` and shared between
    /// threads): soundly, because of the call lock whose discipline the tests below check.
    #[test]
    fn comm_holds_a_shared_call_lock() {
        fn shared<T: Send + Sync>() {}
        shared::<Arc<CallLock>>();
        shared::<Comm>();
    }

    /// One lock per GPU: communicators of one device share it (NCCL allows no parallel calls
    /// to communicators of one device), communicators of other devices do not.
    #[test]
    fn call_locks_are_one_per_gpu() {
        assert!(Arc::ptr_eq(&device_lock(0), &device_lock(0)));
        assert!(Arc::ptr_eq(&device_lock(5), &device_lock(5)));
        assert!(!Arc::ptr_eq(&device_lock(0), &device_lock(1)));
    }

    /// The property `unsafe impl Sync for Comm` rests on: at most one thread inside.
    #[test]
    fn call_lock_admits_one_thread_at_a_time() {
        let lock = Arc::new(CallLock::default());
        let inside = Arc::new(AtomicUsize::new(0));
        let most = Arc::new(AtomicUsize::new(0));
        let threads: Vec<_> = (0..8)
            .map(|_| {
                let (lock, inside, most) = (lock.clone(), inside.clone(), most.clone());
                std::thread::spawn(move || {
                    for _ in 0..200 {
                        assert!(lock.acquire(Duration::from_secs(60)));
                        let _held = Held(&lock);
                        let now = inside.fetch_add(1, Ordering::SeqCst) + 1;
                        most.fetch_max(now, Ordering::SeqCst);
                        std::thread::yield_now();
                        inside.fetch_sub(1, Ordering::SeqCst);
                    }
                })
            })
            .collect();
        threads.into_iter().for_each(|t| t.join().unwrap());
        assert_eq!(most.load(Ordering::SeqCst), 1);
    }

    /// A group's thread re-enters the lock (several calls on one communicator, a timed-out
    /// wait aborting under it); another thread waits until every acquisition is released,
    /// and its wait is bounded by the timeout rather than a hang.
    #[test]
    fn call_lock_is_reentrant_and_bounded() {
        let lock = Arc::new(CallLock::default());
        assert!(lock.acquire(Duration::ZERO));
        assert!(lock.acquire(Duration::ZERO), "re-entry by the holder");
        let other = {
            let lock = lock.clone();
            std::thread::spawn(move || lock.acquire(Duration::from_millis(50)))
                .join()
                .unwrap()
        };
        assert!(
            !other,
            "another thread must time out while the lock is held"
        );
        lock.release();
        let other = {
            let lock = lock.clone();
            std::thread::spawn(move || lock.acquire(Duration::from_millis(50)))
                .join()
                .unwrap()
        };
        assert!(!other, "still held once");
        lock.release();
        let other = {
            let lock = lock.clone();
            std::thread::spawn(move || {
                let got = lock.acquire(Duration::from_millis(50));
                if got {
                    lock.release();
                }
                got
            })
            .join()
            .unwrap()
        };
        assert!(other, "free after the last release");
    }

    /// A group keeps the locks its calls took until the outermost group ends, and only then
    /// lets another thread in (the calls are issued at `ncclGroupEnd`). Exercised without
    /// NCCL: the group's bookkeeping, as `Comm::issue` and `Group::finish` do it.
    #[test]
    fn group_held_locks_are_released_at_the_outermost_end() {
        let lock = Arc::new(CallLock::default());
        GROUP_DEPTH.with(|d| d.set(2));
        for _ in 0..3 {
            assert!(lock.acquire(Duration::ZERO));
            GROUP_HELD.with(|h| h.borrow_mut().push(lock.clone()));
        }
        let try_other = |lock: &Arc<CallLock>| {
            let lock = lock.clone();
            std::thread::spawn(move || {
                let got = lock.acquire(Duration::from_millis(20));
                if got {
                    lock.release();
                }
                got
            })
            .join()
            .unwrap()
        };
        // The inner end (no NCCL here: its error is ignored) keeps the locks.
        let _ = Group { open: true }.finish();
        assert_eq!(Group::depth(), 1);
        assert!(!try_other(&lock));
        let _ = Group { open: true }.finish();
        assert_eq!(Group::depth(), 0);
        assert!(try_other(&lock));
        assert!(GROUP_HELD.with(|h| h.borrow().is_empty()));
    }
}

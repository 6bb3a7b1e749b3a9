//! Process-wide settings, like Warp's `wp.config`.
//!
//! Each setting is an atomic so that it can be read on every launch without a lock and changed
//! from any thread. Changes apply to launches that start afterwards.
//!
//! # Logging
//!
//! Diagnostics go to the [`log`](https://docs.rs/log) facade: the application picks where they
//! go (any `log` implementation, `env_logger` say, with `RUST_LOG=warp_cuda=debug`), and
//! without a logger they cost one atomic load. Targets are the modules that emit them:
//!
//! | target | level | what |
//! |---|---|---|
//! | `warp_runtime::device` | info | the [`init`](crate::init) banner (only here: nothing is printed to stdout); the preferred device, first asked, and why not a GPU when it is the CPU |
//! | `warp_runtime::device` | debug | each device found |
//! | `warp_cuda::device` | info | the CUDA driver version and each GPU (name, `sm_XX`, SMs, memory), or why CUDA is not available when there is no driver or no device |
//! | `warp_cuda::device` | warn | a driver that is there but cannot be used (too old, the toolkit's stub, a version mismatch, `cuInit` failing) |
//! | `warp_cuda::device` | debug | a GPU opened (its context and stream) |
//! | `warp_cuda::compile` | info | each NVRTC compile: program, `sm_XX`, milliseconds, cubin size; no NVRTC library |
//! | `warp_cuda::compile` | warn | an NVRTC library that cannot be used |
//! | `warp_cuda::compile` | debug | the NVRTC version loaded; NVRTC's log of a successful compile (warnings) |
//! | `warp_cuda::cache` | debug | kernel (disk) cache hits and misses, with the entry's file |
//! | `warp_cuda::cache` | warn | a damaged entry (compiled again) or one that cannot be written (the kernel still runs) |
//! | `warp_runtime::cuda::module` | info | a kernel loaded on a GPU at its first launch (forward or adjoint, contiguous or strided) in how many milliseconds, and from where: ahead-of-time cubin, kernel cache, or NVRTC with its time |
//! | `warp_runtime::cuda::module` | debug | a module cache miss (a kernel's first launch on a GPU) |
//! | `warp_runtime::cuda::module` | trace | a module cache hit (every GPU launch that is not a [`Launch`](crate::Launch) object; formatted only when trace is enabled for the target) |
//! | `warp_runtime::cuda::objects`, `::primitives` | info | a build or primitives library loaded on a GPU |
//!
//! CPU launches log nothing, and nothing on a launch path formats a message unless its
//! record is enabled. Errors that are returned are not logged as well: they are the caller's
//! to report.

use std::sync::atomic::{AtomicBool, AtomicU8, AtomicUsize, Ordering};

static DEBUG: AtomicBool = AtomicBool::new(cfg!(debug_assertions));

static CPU_MIN_CHUNK: AtomicUsize = AtomicUsize::new(DEFAULT_CPU_MIN_CHUNK);

/// The default of [`cpu_min_chunk`].
pub const DEFAULT_CPU_MIN_CHUNK: usize = 4096;

/// Turns debug mode on or off.
///
/// Array indices are checked on both backends whatever this says. In debug mode every GPU
/// launch waits for its kernel and reports the kernel's own fault at once, as a CPU launch does;
/// otherwise a GPU fault is reported by the next synchronisation (`synchronize`, `to_vec`,
/// `Stream::synchronize`), which costs no waiting per launch.
pub fn set_debug(on: bool) {
    DEBUG.store(on, Ordering::Relaxed);
}

/// Whether debug mode is on. Defaults to `cfg!(debug_assertions)` of this crate's build.
pub fn debug() -> bool {
    DEBUG.load(Ordering::Relaxed)
}

/// A tri-state switch (0: not decided, 1: false, 2: true) whose default is the environment
/// variable `var` (`1` or `true`) when first read: a setter called earlier wins.
fn env_flag(flag: &AtomicU8, var: &str) -> bool {
    match flag.load(Ordering::Relaxed) {
        1 => false,
        2 => true,
        _ => {
            let env = std::env::var(var)
                .map(|v| matches!(v.trim(), "1" | "true" | "TRUE" | "True"))
                .unwrap_or(false);
            // Only fill in the default: a concurrent setter must not be overwritten.
            let _ = flag.compare_exchange(
                0,
                if env { 2 } else { 1 },
                Ordering::Relaxed,
                Ordering::Relaxed,
            );
            flag.load(Ordering::Relaxed) == 2
        }
    }
}

/// Sets the smallest number of threads one rayon task of a CPU launch runs.
///
/// A launch of at most this many threads runs serially on the calling thread, so tiny launches
/// do not pay for waking the pool; larger launches are cut into about eight tasks per pool
/// thread, of at least an eighth of this size, so that uneven work balances out while the
/// per-task overhead stays small next to the work. Zero is treated as one.
pub fn set_cpu_min_chunk(threads: usize) {
    CPU_MIN_CHUNK.store(threads.max(1), Ordering::Relaxed);
}

/// The smallest number of threads one rayon task of a CPU launch runs (default
/// [`DEFAULT_CPU_MIN_CHUNK`]); see [`set_cpu_min_chunk`].
pub fn cpu_min_chunk() -> usize {
    CPU_MIN_CHUNK.load(Ordering::Relaxed)
}

static CUDA_FMAD: AtomicBool = AtomicBool::new(true);
static VERIFY_FP: AtomicBool = AtomicBool::new(false);

/// Turns on checking, after every launch on either backend, every array the kernel may write
/// for NaN and infinite values: the first one found is an [`Error::NonFinite`] naming the
/// kernel, the argument and the index. Costs a read-back of those arrays per launch (on a GPU,
/// a synchronisation): a debugging aid, like Warp's `verify_fp`.
///
/// [`Error::NonFinite`]: crate::Error::NonFinite
pub fn set_verify_fp(on: bool) {
    VERIFY_FP.store(on, Ordering::Relaxed);
}

thread_local! {
    static VERIFY_FP_HERE: std::cell::Cell<Option<bool>> = const { std::cell::Cell::new(None) };
}

/// Overrides [`set_verify_fp`] for launches made on the calling thread (`None`: follow the
/// process-wide setting).
pub fn set_verify_fp_for_thread(on: Option<bool>) {
    VERIFY_FP_HERE.with(|c| c.set(on));
}

/// Whether launches on this thread check written arrays for NaN and infinities (default off).
pub fn verify_fp() -> bool {
    VERIFY_FP_HERE
        .with(|c| c.get())
        .unwrap_or_else(|| VERIFY_FP.load(Ordering::Relaxed))
}

// 0: not decided yet (read `WARP_RACE_CHECK` at first use), 1: false, 2: true. A tri-state
// lets `set_race_check` win over the environment whichever comes first.
static RACE_CHECK: AtomicU8 = AtomicU8::new(0);

thread_local! {
    static RACE_CHECK_HERE: std::cell::Cell<Option<bool>> = const { std::cell::Cell::new(None) };
}

/// Turns the write-race check of CPU launches on or off for the whole process.
///
/// With the check on, every non-atomic array store of a CPU launch (forward or adjoint)
/// records which kernel thread wrote the element; a second thread of the same launch writing
/// the same element is a data race (undefined behaviour in Rust's memory model) and the
/// launch returns [`Error::Fault`] with [`FaultKind::WriteRace`], naming the kernel, the
/// argument, the index and both threads' flat launch indices, before the second write
/// happens. Atomic builtins are not recorded; reads are not checked; GPU launches ignore the
/// setting. ARCHITECTURE.md ("Concurrency and data races") says what is and is not covered.
///
/// Every kernel launch is checked (`launch`, `Launch` objects, a tape's backward, forward
/// mode), by the setting of the thread that runs it (for a captured CPU graph, the thread
/// that replays it); the library's own parallel primitives and object builds are not.
///
/// Costs, only while on: eight bytes of shadow memory per element of every array argument
/// of a launch (allocated zeroed per launch, touched only where written), a
/// compare-exchange per store, one call per kernel thread instead of per chunk, and no
/// skipped bounds checks (thread-indexed accesses are checked like any other): about 25
/// times slower on the CPU particle benchmark (1M threads, two stores each). While a
/// checked launch runs, stores of unchecked launches on other threads look up a
/// thread-local as well. Off (the default), a store costs one load of a process-wide count,
/// and the particle benchmark is unchanged.
///
/// The default is off, unless the environment variable `WARP_RACE_CHECK` is `1` (or `true`)
/// when this is first read and `set_race_check` has not been called.
///
/// [`Error::Fault`]: crate::Error::Fault
/// [`FaultKind::WriteRace`]: warp_core::FaultKind::WriteRace
pub fn set_race_check(on: bool) {
    RACE_CHECK.store(if on { 2 } else { 1 }, Ordering::Relaxed);
}

/// Overrides [`set_race_check`] for launches made on the calling thread (`None`: follow the
/// process-wide setting). See [`ScopedRaceCheck`] for a guard that restores it.
pub fn set_race_check_for_thread(on: Option<bool>) {
    RACE_CHECK_HERE.with(|c| c.set(on));
}

/// Whether CPU launches made on this thread check for write races (see [`set_race_check`]).
pub fn race_check() -> bool {
    RACE_CHECK_HERE
        .with(|c| c.get())
        .unwrap_or_else(|| env_flag(&RACE_CHECK, "WARP_RACE_CHECK"))
}

/// The race check set for launches on the calling thread while this guard lives
/// ([`set_race_check_for_thread`]); dropping it puts back the thread's previous override.
/// Other threads, tests running in parallel among them, are not affected.
///
/// ```
/// use warp_runtime::config;
/// {
///     let _check = config::ScopedRaceCheck::new(true);
///     assert!(config::race_check());
///     // launches here report write races
/// }
/// ```
#[must_use = "the override ends when the guard is dropped"]
#[derive(Debug)]
pub struct ScopedRaceCheck {
    previous: Option<bool>,
    /// The override belongs to the thread that made the guard.
    _not_send: std::marker::PhantomData<*const ()>,
}

impl ScopedRaceCheck {
    /// Turns the check on (or off) for this thread until the guard is dropped.
    pub fn new(on: bool) -> Self {
        let previous = RACE_CHECK_HERE.with(|c| c.replace(Some(on)));
        ScopedRaceCheck {
            previous,
            _not_send: std::marker::PhantomData,
        }
    }
}

impl Drop for ScopedRaceCheck {
    fn drop(&mut self) {
        RACE_CHECK_HERE.with(|c| c.set(self.previous));
    }
}

static ADSTACK_BYTES: AtomicUsize = AtomicUsize::new(DEFAULT_ADSTACK_BYTES);

/// The default of [`adstack_bytes`].
pub const DEFAULT_ADSTACK_BYTES: usize = 4096;

/// Sets the per-thread stack (in bytes) that adjoint kernels use to keep the values loops
/// overwrite for the reverse sweep. A backward that needs more fails with a fault naming the
/// kernel and the line; it never returns a wrong gradient.
pub fn set_adstack_bytes(bytes: usize) {
    ADSTACK_BYTES.store(bytes, Ordering::Relaxed);
}

/// The per-thread adjoint stack capacity in bytes (default [`DEFAULT_ADSTACK_BYTES`]).
pub fn adstack_bytes() -> usize {
    ADSTACK_BYTES.load(Ordering::Relaxed)
}
static CUDA_BLOCK_DIM: AtomicUsize = AtomicUsize::new(256);

/// Lets NVRTC contract `a * b + c` into fused multiply-adds (the default, as nvcc does). Turn
/// it off for IEEE results that match the CPU backend bit for bit; kernels already compiled
/// keep the setting they were compiled with.
pub fn set_cuda_fmad(on: bool) {
    CUDA_FMAD.store(on, Ordering::Relaxed);
}

/// Whether CUDA kernels are compiled with FMA contraction.
pub fn cuda_fmad() -> bool {
    CUDA_FMAD.load(Ordering::Relaxed)
}

// Line tables in GPU code: 0 not decided (the environment's), 1 off, 2 on.
static CUDA_LINE_INFO: AtomicU8 = AtomicU8::new(0);

/// Environment variable that turns [`cuda_line_info`] on (`1` or `true`) when
/// [`set_cuda_line_info`] was not called first.
pub const LINE_INFO_ENV: &str = "WARP_LANG_LINEINFO";

/// Compiles GPU code with line tables (`-lineinfo`), so that Nsight Compute and
/// compute-sanitizer name the source lines of the generated code. Off by default: the tables
/// cost NVRTC about a quarter of a kernel's compile time (the autodiff example's unit, forward
/// and adjoint: 137 ms with them, 101 ms without, on an H200 machine) and change no
/// instruction; faults and assertions name the user's lines without them. Like
/// [`set_cuda_fmad`], it applies to what is compiled afterwards, and it is part of every cache
/// key, so ahead-of-time cubins are found only under the setting they were built with.
pub fn set_cuda_line_info(on: bool) {
    CUDA_LINE_INFO.store(if on { 2 } else { 1 }, Ordering::Relaxed);
}

/// Whether GPU code is compiled with line tables: [`set_cuda_line_info`], else
/// [`LINE_INFO_ENV`] (`WARP_LANG_LINEINFO=1`), else off.
pub fn cuda_line_info() -> bool {
    env_flag(&CUDA_LINE_INFO, LINE_INFO_ENV)
}

/// Threads per block of CUDA launches (default 256, as Warp). Clamped to 32..=1024.
pub fn set_cuda_block_dim(threads: u32) {
    CUDA_BLOCK_DIM.store(threads.clamp(32, 1024) as usize, Ordering::Relaxed);
}

/// Threads per block of CUDA launches.
pub fn cuda_block_dim() -> u32 {
    CUDA_BLOCK_DIM.load(Ordering::Relaxed) as u32
}

// The ahead-of-time cubin directory (`wp::aot`): where first launches look before the kernel
// cache and NVRTC.
#[cfg(feature = "cuda")]
/// Environment variable naming the ahead-of-time directory; wins over [`set_aot_dir`].
pub const AOT_DIR_ENV: &str = "WARP_LANG_AOT_DIR";

#[cfg(feature = "cuda")]
static AOT_DIR: std::sync::RwLock<Option<std::path::PathBuf>> = std::sync::RwLock::new(None);

#[cfg(feature = "cuda")]
/// Sets (or with `None` clears) the directory where first launches look for ahead-of-time
/// cubins. `WARP_LANG_AOT_DIR`, when set and not empty, wins.
pub fn set_aot_dir(dir: Option<std::path::PathBuf>) {
    *AOT_DIR.write().unwrap_or_else(|p| p.into_inner()) = dir;
}

#[cfg(feature = "cuda")]
/// The ahead-of-time directory in effect, if any.
pub fn aot_dir() -> Option<std::path::PathBuf> {
    match std::env::var_os(AOT_DIR_ENV) {
        Some(v) if !v.is_empty() => Some(std::path::PathBuf::from(v)),
        _ => AOT_DIR.read().unwrap_or_else(|p| p.into_inner()).clone(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A forward CUDA unit, compiled without `WP_ADSTACK_BYTES`, gives a `wp::grad` call's
    /// adjoint the default stack, which the header writes as a number of its own.
    #[test]
    fn the_headers_grad_stack_default_is_this_default() {
        let header = include_str!("../../warp-cuda/cuda/wp_adjoint_core.h");
        let line = format!("#define WP_GRAD_STACK_BYTES {DEFAULT_ADSTACK_BYTES}\n");
        assert!(
            header.contains(&line),
            "wp_adjoint_core.h lacks `{}`",
            line.trim()
        );
    }

    // Only the setters whose effect other tests cannot observe are exercised here: tests run in
    // parallel and share these globals.
    #[test]
    fn debug_round_trips() {
        let before = debug();
        set_debug(!before);
        assert_eq!(debug(), !before);
        set_debug(before);
        assert_eq!(debug(), before);
    }

    #[test]
    fn scoped_race_check_restores_the_thread_override() {
        set_race_check_for_thread(Some(false));
        {
            let _on = ScopedRaceCheck::new(true);
            assert!(race_check());
            {
                let _off = ScopedRaceCheck::new(false);
                assert!(!race_check());
            }
            assert!(race_check());
        }
        assert!(!race_check());
        set_race_check_for_thread(None);
    }

    #[test]
    fn min_chunk_default() {
        assert_eq!(cpu_min_chunk(), DEFAULT_CPU_MIN_CHUNK);
    }
}

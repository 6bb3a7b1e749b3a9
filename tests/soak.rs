//! Stress and soak tests: many host threads launching at once, allocation cycles, and one
//! scene run for a long time, each checked for exact results and for memory that stays flat.
//!
//! - `stress_*`: 16 threads launch at once on one device into shared arrays (integer atomics,
//!   and float atomics of integer values, so that every order of the additions gives the same
//!   exact sum) and into arrays of their own (each checked exactly against its closed form),
//!   each thread with its own `Tape` (a two-kernel forward, backward, the gradient checked
//!   exactly) reading one parameter array shared by all, whose gradient must receive every
//!   backward pass's update. On a GPU each thread also uses a stream of its own, by `launch_on` and by
//!   `ScopedStream`, next to the default stream.
//! - `alloc_cycles_*`: 10,000 allocate/free cycles of 1 element to 4 MiB in five element
//!   types (every page written by a kernel, a tape every tenth cycle), with the live heap
//!   bytes, the resident set size and the GPU's free memory compared before and after.
//! - `scene_*`: the `springs` scene's chains (examples/common/springs.rs) stepped, the memory
//!   sampled and the state checked finite and bounded at regular steps.
//!
//! The normal suite runs them at a size that takes a few seconds in a debug build; the
//! `#[ignore]`d `*_soak_*` versions run them long (`cargo test --release --test soak --
//! --ignored --nocapture`, about 17 s on the CPU of a 2-core VM): 3,000 stress rounds a
//! thread, 100,000 allocation cycles, and the scene for 100,000 steps sampled every 10,000.
//!
//! The memory figures are the whole process's, so this file is a test binary of its own (the
//! suite's hundreds of tests would run in parallel threads of the same process), and every
//! test here takes [`serial`] first: tests of one binary run in parallel threads by default,
//! and 16 stress threads would disturb an allocation test's figures. Run with `--nocapture`,
//! each test prints its figures (steps, time, memory before and after) for the notes.
//!
//! GPU variants print `SKIPPED` without a CUDA device, as the suite's do.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

use warp_lang as wp;
use wp::prelude::*;

#[path = "../examples/common/springs.rs"]
mod springs;
// The sparse tier, for common/springs.rs (its coloured XPBD series).
use warp_runtime::sparse;

// ---------------------------------------------------------------------------------------------
// Measuring memory

/// The system allocator, counting the bytes it has handed out and not had back: a leak of a
/// few bytes a cycle shows in this count, where the resident set size moves only by pages and
/// by what the allocator keeps cached.
struct Counting;

static LIVE_HEAP: AtomicUsize = AtomicUsize::new(0);

// SAFETY: every call is forwarded to `System` unchanged; the counter only observes.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded contract.
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            LIVE_HEAP.fetch_add(layout.size(), Ordering::Relaxed);
        }
        p
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: forwarded contract.
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            LIVE_HEAP.fetch_add(layout.size(), Ordering::Relaxed);
        }
        p
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded contract.
        unsafe { System.dealloc(ptr, layout) };
        LIVE_HEAP.fetch_sub(layout.size(), Ordering::Relaxed);
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: forwarded contract.
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            // Add first: the counter is unsigned and other threads read it meanwhile.
            LIVE_HEAP.fetch_add(new_size, Ordering::Relaxed);
            LIVE_HEAP.fetch_sub(layout.size(), Ordering::Relaxed);
        }
        p
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Bytes of the Rust heap in use (the counting allocator's figure).
fn live_heap() -> usize {
    LIVE_HEAP.load(Ordering::Relaxed)
}

/// The resident set size of this process in bytes, or `None` where there is no procfs (not
/// Linux): `VmRSS` of `/proc/self/status`, the figure `/proc/self/statm` gives in pages, here
/// in kB (so no page size to look up).
fn rss() -> Option<usize> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: usize = status
        .lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))?
        .trim()
        .strip_suffix("kB")?
        .trim()
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// The free memory of `dev` when it is a GPU (the driver's figure), else `None`.
fn gpu_free(dev: &wp::Device) -> Option<usize> {
    dev.memory_info()
        .expect("Device::memory_info")
        .map(|m| m.free)
}

/// One sample of the memory figures.
#[derive(Clone, Copy, Debug)]
struct Memory {
    live_heap: usize,
    rss: Option<usize>,
    gpu_free: Option<usize>,
}

impl Memory {
    fn now(dev: &wp::Device) -> Memory {
        Memory {
            live_heap: live_heap(),
            rss: rss(),
            gpu_free: gpu_free(dev),
        }
    }

    /// The figures for a note: `live heap 1.2 MiB, RSS 40.1 MiB, GPU free 79.1 GiB`.
    fn show(&self) -> String {
        let mut s = format!("live heap {}", bytes(self.live_heap as f64));
        match self.rss {
            Some(r) => s += &format!(", RSS {}", bytes(r as f64)),
            None => s += ", RSS not measured (no /proc/self/status)",
        }
        if let Some(f) = self.gpu_free {
            s += &format!(", GPU free {}", bytes(f as f64));
        }
        s
    }
}

/// A byte count for people: `512 B`, `3.25 KiB`, `40.1 MiB`, `79.10 GiB` (negative: a
/// decrease).
fn bytes(b: f64) -> String {
    let a = b.abs();
    if a < 1024.0 {
        format!("{b:.0} B")
    } else if a < 1024.0 * 1024.0 {
        format!("{:.2} KiB", b / 1024.0)
    } else if a < 1024.0 * 1024.0 * 1024.0 {
        format!("{:.2} MiB", b / (1024.0 * 1024.0))
    } else {
        format!("{:.2} GiB", b / (1024.0 * 1024.0 * 1024.0))
    }
}

/// `after - before` as a signed count.
fn growth(before: usize, after: usize) -> i64 {
    after as i64 - before as i64
}

/// Asserts that the memory grew by at most the given bounds from `before` to `after` (live
/// heap and RSS in bytes; GPU memory as the drop of its free figure), saying which figure
/// did not hold. RSS is skipped, with a message, where it is not measured.
#[track_caller]
fn assert_flat(what: &str, before: Memory, after: Memory, heap: usize, rss: usize, gpu: usize) {
    let h = growth(before.live_heap, after.live_heap);
    assert!(
        h <= heap as i64,
        "{what}: the live heap grew by {} (bound {}): before {}, after {}",
        bytes(h as f64),
        bytes(heap as f64),
        before.show(),
        after.show()
    );
    match (before.rss, after.rss) {
        (Some(b), Some(a)) => {
            let g = growth(b, a);
            assert!(
                g <= rss as i64,
                "{what}: RSS grew by {} (bound {}): before {}, after {}",
                bytes(g as f64),
                bytes(rss as f64),
                before.show(),
                after.show()
            );
        }
        _ => eprintln!("SKIPPED {what}: RSS check (no /proc/self/status on this system)"),
    }
    if let (Some(b), Some(a)) = (before.gpu_free, after.gpu_free) {
        let g = growth(a, b);
        assert!(
            g <= gpu as i64,
            "{what}: GPU free memory fell by {} (bound {}): before {}, after {}",
            bytes(g as f64),
            bytes(gpu as f64),
            before.show(),
            after.show()
        );
    }
}

// ---------------------------------------------------------------------------------------------
// Test plumbing

/// Runs the tests of this binary one at a time (see the module docs): the memory figures are
/// the whole process's.
fn serial() -> MutexGuard<'static, ()> {
    static LOCK: Mutex<()> = Mutex::new(());
    // A failed test poisons the lock; the next test still runs.
    LOCK.lock().unwrap_or_else(|p| p.into_inner())
}

/// The first GPU, or `None` after printing that `test` skipped.
fn gpu(test: &str) -> Option<wp::Device> {
    match wp::get_device("cuda:0") {
        Ok(dev) => Some(dev),
        Err(e) => {
            eprintln!("SKIPPED soak::{test}: no CUDA device ({e})");
            None
        }
    }
}

/// Sets debug mode for its lifetime and restores the previous setting when dropped (a failed
/// assertion included). Off on a GPU lets launches queue without a wait each, so that the
/// stress threads' kernels and streams really overlap; faults still surface at the reads.
struct DebugMode(bool);

impl DebugMode {
    fn set(on: bool) -> DebugMode {
        let before = wp::config::debug();
        wp::config::set_debug(on);
        DebugMode(before)
    }
}

impl Drop for DebugMode {
    fn drop(&mut self) {
        wp::config::set_debug(self.0);
    }
}

/// A small deterministic generator (xorshift64*): the same sizes every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

/// `Device::memory_info`: `None` on the CPU; on a GPU free at most total, and a live 1 GiB
/// array is out of the free figure whatever the pool held before.
#[test]
fn memory_info() {
    let _serial = serial();
    assert_eq!(wp::cpu().memory_info().unwrap(), None);
    let Some(dev) = gpu("memory_info") else {
        return;
    };
    let m = dev
        .memory_info()
        .unwrap()
        .expect("a GPU reports its memory");
    assert!(m.total > 0 && m.free <= m.total, "{m:?}");
    let big = wp::Array::<u8>::zeros(1 << 30, &dev).unwrap();
    let held = dev.memory_info().unwrap().unwrap();
    assert!(
        held.free <= held.total - (1 << 30),
        "{held:?} with 1 GiB allocated"
    );
    drop(big);
    println!(
        "memory_info: \"{dev}\" total {}, free {} before and {} with 1 GiB allocated",
        bytes(m.total as f64),
        bytes(m.free as f64),
        bytes(held.free as f64)
    );
}

// ---------------------------------------------------------------------------------------------
// (a) Many threads launching at once

/// Bins of the shared histogram: prime, so that the shifted indices spread unevenly.
const BINS: usize = 97;
/// Slots of the shared float sums.
const SLOTS: usize = 64;

/// Shared arrays, every update atomic: a histogram of `(i + shift) % BINS`, and `v` added to
/// slot `i % SLOTS` of an f64 and an f32 sum. The added values are integers and every partial
/// sum stays below 2^24 (f32) and 2^53 (f64), so each addition is exact and any order of them
/// gives the same result bit for bit.
#[wp::kernel]
fn k_shared(hist: Array<i32>, sum64: Array<f64>, sum32: Array<f32>, shift: i32, v: f64) {
    let i = tid();
    atomic_add(hist, (i as i32 + shift) % 97, 1);
    atomic_add(sum64, i % 64, v);
    atomic_add(sum32, i % 64, 1.0);
}

/// A thread's own arrays: after `r` launches, `x[i] = r (i % 1024 + t)` and
/// `y[i] = r i (t + 1)`, exact: in f32 integers below 2^24, which holds for up to 16,000
/// rounds.
#[wp::kernel]
fn k_own(x: Array<f32>, y: Array<i64>, t: i32) {
    let i = tid();
    x[i] += (i % 1024) as f32 + t as f32;
    y[i] += i as i64 * (t as i64 + 1);
}

/// `y[i] = c x[i]^2 + p[i]`: the first step of each thread's taped forward. `x` is the
/// thread's own, `p` is shared by every thread (a parameter array several tapes read).
#[wp::kernel]
fn k_square(x: Array<f32>, p: Array<f32>, y: Array<f32>, c: f32) {
    let i = tid();
    y[i] = c * x[i] * x[i] + p[i];
}

/// `loss = sum y`: the second step.
#[wp::kernel]
fn k_sum(y: Array<f32>, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, 0, y[i]);
}

/// Stress threads on the CPU and on a GPU.
const THREADS: usize = 16;
/// Threads of the shared and own launches: above `config::cpu_min_chunk` (4096), so that on
/// the CPU they run on the rayon pool, all 16 host threads feeding it at once.
const N_POOL: usize = 10_000;
/// Threads of the taped launches: below it, so that they run on the launching thread.
const N_TAPE: usize = 1_000;

/// The taped input of thread `t`: integers from -3 to 4 (so that `c x^2` and its sums are
/// exact).
fn tape_input(t: usize) -> Vec<f32> {
    (0..N_TAPE).map(|i| ((i + t) % 8) as f32 - 3.0).collect()
}

/// How a GPU thread queues a round's launches: the default stream, its own stream named
/// (`launch_on`), or its own stream made current (`ScopedStream`).
#[derive(Clone, Copy, Debug)]
enum Queue {
    Default,
    On,
    Scoped,
}

/// One thread's work: `rounds` rounds of a shared launch, an own launch and a taped
/// forward-backward, each checked; the shared arrays are checked by the caller.
fn stress_thread(
    t: usize,
    rounds: usize,
    dev: &wp::Device,
    shared: (&wp::Array<i32>, &wp::Array<f64>, &wp::Array<f32>),
    param: &wp::Array<f32>,
) -> wp::Result<()> {
    let (hist, sum64, sum32) = shared;
    let x = wp::Array::<f32>::zeros(N_POOL, dev)?;
    let y = wp::Array::<i64>::zeros(N_POOL, dev)?;
    let stream = if dev.is_cuda() {
        Some(wp::Stream::new(dev)?)
    } else {
        None
    };
    let c = (t + 1) as f32;
    let input = tape_input(t);
    for r in 0..rounds {
        let queue = match (&stream, r % 3) {
            (None, _) | (_, 0) => Queue::Default,
            (_, 1) => Queue::On,
            _ => Queue::Scoped,
        };
        // The scope (when this round has one) covers every launch of the round, the tape's
        // forward and backward included.
        let _scope = match (&stream, queue) {
            (Some(s), Queue::Scoped) => Some(wp::ScopedStream::new(s)?),
            _ => None,
        };
        let shift = (7 * t + r) as i32;
        let v = (t + 1) as f64;
        match (&stream, queue) {
            (Some(s), Queue::On) => {
                wp::launch_on(k_shared, N_POOL, (hist, sum64, sum32, shift, v), s)?;
                wp::launch_on(k_own, N_POOL, (&x, &y, t as i32), s)?;
            }
            _ => {
                wp::launch(k_shared, N_POOL, (hist, sum64, sum32, shift, v), dev)?;
                wp::launch(k_own, N_POOL, (&x, &y, t as i32), dev)?;
            }
        }

        // A tape of this thread's: it must record this thread's two launches and nothing of
        // the 15 others launching meanwhile. It differentiates an array of this thread's own
        // (`xs`) and the shared `param`: both are read at the thread index ("thread owned"
        // within one launch), and the 16 backward passes running at once (on the CPU, each
        // on its own host thread; on a GPU, on several streams) all accumulate into
        // `param`'s gradient. Every update must count: checked by the caller.
        let xs = wp::Array::from_slice(&input, dev)?.with_grad()?;
        let ys = wp::Array::<f32>::zeros(N_TAPE, dev)?.with_grad()?;
        let loss = wp::Array::<f32>::zeros(1, dev)?.with_grad()?;
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            match (&stream, queue) {
                (Some(s), Queue::On) => {
                    wp::launch_on(k_square, N_TAPE, (&xs, param, &ys, c), s)?;
                    wp::launch_on(k_sum, N_TAPE, (&ys, &loss), s)?;
                }
                _ => {
                    wp::launch(k_square, N_TAPE, (&xs, param, &ys, c), dev)?;
                    wp::launch(k_sum, N_TAPE, (&ys, &loss), dev)?;
                }
            }
        }
        assert_eq!(
            tape.steps(),
            ["k_square", "k_sum"],
            "thread {t}, round {r}: the tape recorded another thread's launches"
        );
        tape.backward(&loss)?;
        // Exact: c x^2 and 2 c x are integers below 2^24, and so is every partial sum of the
        // loss (at most 16 * 16 * 1000), whatever order the atomic additions take. The
        // adjoint of c * x * x adds (c x) and c x: exact too, FMA contraction or not.
        let want_loss: f32 = input.iter().map(|&x| c * x * x).sum();
        assert_eq!(
            loss.to_vec()?,
            [want_loss],
            "thread {t}, round {r} ({queue:?}): loss"
        );
        let grad = xs.grad().expect("with_grad").to_vec()?;
        for (i, (&g, &x)) in grad.iter().zip(&input).enumerate() {
            assert_eq!(
                g,
                2.0 * c * x,
                "thread {t}, round {r} ({queue:?}): d loss / d x[{i}]"
            );
        }
    }
    // The own arrays after `rounds` rounds (see `k_own`): exact.
    let rounds_f = rounds as f32;
    let xv = x.to_vec()?;
    let yv = y.to_vec()?;
    for i in 0..N_POOL {
        assert_eq!(
            xv[i],
            rounds_f * (i % 1024 + t) as f32,
            "thread {t}: own x[{i}] after {rounds} rounds"
        );
        assert_eq!(
            yv[i],
            (rounds * i * (t + 1)) as i64,
            "thread {t}: own y[{i}] after {rounds} rounds"
        );
    }
    Ok(())
}

/// 16 threads, `rounds` rounds each, on `dev`; prints the figures and checks the shared
/// arrays exactly.
fn stress(dev: &wp::Device, rounds: usize, name: &str) {
    let hist = wp::Array::<i32>::zeros(BINS, dev).unwrap();
    let sum64 = wp::Array::<f64>::zeros(SLOTS, dev).unwrap();
    let sum32 = wp::Array::<f32>::zeros(SLOTS, dev).unwrap();
    let param = wp::Array::<f32>::zeros(N_TAPE, dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let start = Instant::now();
    std::thread::scope(|s| {
        let handles: Vec<_> = (0..THREADS)
            .map(|t| {
                let (hist, sum64, sum32, param) = (&hist, &sum64, &sum32, &param);
                s.spawn(move || stress_thread(t, rounds, dev, (hist, sum64, sum32), param))
            })
            .collect();
        for (t, h) in handles.into_iter().enumerate() {
            match h.join() {
                Ok(r) => r.unwrap_or_else(|e| panic!("{name}: thread {t}: {e}")),
                Err(p) => std::panic::resume_unwind(p),
            }
        }
    });
    let elapsed = start.elapsed();
    // The shared arrays: every thread's every launch counted exactly once.
    let mut want_hist = vec![0i32; BINS];
    let mut want64 = vec![0.0f64; SLOTS];
    let mut want32 = vec![0.0f32; SLOTS];
    for t in 0..THREADS {
        for r in 0..rounds {
            let shift = 7 * t + r;
            for i in 0..N_POOL {
                want_hist[(i + shift) % BINS] += 1;
            }
        }
        for i in 0..N_POOL {
            want64[i % SLOTS] += ((t + 1) * rounds) as f64;
            want32[i % SLOTS] += rounds as f32;
        }
    }
    assert_eq!(
        hist.to_vec().unwrap(),
        want_hist,
        "{name}: shared histogram"
    );
    assert_eq!(sum64.to_vec().unwrap(), want64, "{name}: shared f64 sums");
    assert_eq!(sum32.to_vec().unwrap(), want32, "{name}: shared f32 sums");
    // Every backward pass adds d loss / d p[i] = 1 to the shared parameter's gradient: an
    // integer count below 2^24, exact in f32 in any order. A lost update (a non-atomic
    // accumulation racing with another thread's) leaves an element short.
    let want_param = (THREADS * rounds) as f32;
    let grad = param.grad().expect("with_grad").to_vec().unwrap();
    let short: Vec<(usize, f32)> = grad
        .iter()
        .copied()
        .enumerate()
        .filter(|&(_, g)| g != want_param)
        .collect();
    assert!(
        short.is_empty(),
        "{name}: the shared parameter's gradient lost updates at {} of {N_TAPE} elements \
         (want {want_param} each; first: {:?})",
        short.len(),
        &short[..short.len().min(5)]
    );
    let launches = THREADS * rounds * 4;
    println!(
        "{name}: {THREADS} threads x {rounds} rounds on \"{dev}\": {launches} launches \
         ({} backward passes) in {:.2} s",
        THREADS * rounds,
        elapsed.as_secs_f64()
    );
}

/// Rounds in the normal suite: a few seconds in a debug build on two cores.
const STRESS_ROUNDS: usize = 8;
/// Rounds of the soak run.
const STRESS_SOAK_ROUNDS: usize = 3_000;

#[test]
fn stress_cpu() {
    let _serial = serial();
    stress(&wp::cpu(), STRESS_ROUNDS, "stress_cpu");
}

#[test]
fn stress_gpu() {
    let _serial = serial();
    let Some(dev) = gpu("stress_gpu") else {
        return;
    };
    let _debug = DebugMode::set(false);
    stress(&dev, STRESS_ROUNDS, "stress_gpu");
}

#[test]
#[ignore = "soak: cargo test --release --test soak -- --ignored --nocapture"]
fn stress_soak_cpu() {
    let _serial = serial();
    stress(&wp::cpu(), STRESS_SOAK_ROUNDS, "stress_soak_cpu");
}

#[test]
#[ignore = "soak: cargo test --release --test soak -- --ignored --nocapture"]
fn stress_soak_gpu() {
    let _serial = serial();
    let Some(dev) = gpu("stress_soak_gpu") else {
        return;
    };
    let _debug = DebugMode::set(false);
    stress(&dev, STRESS_SOAK_ROUNDS, "stress_soak_gpu");
}

// ---------------------------------------------------------------------------------------------
// (b) Allocate/free cycles

/// Writes `v` to every `stride`-th element, so that every page of a fresh allocation is
/// written (and resident) without a debug build's element-by-element fill of megabytes.
#[wp::kernel]
fn k_touch_f32(a: Array<f32>, stride: i32, v: f32) {
    let i = tid();
    a[i as i32 * stride] = v;
}

/// [`k_touch_f32`] for f64.
#[wp::kernel]
fn k_touch_f64(a: Array<f64>, stride: i32, v: f64) {
    let i = tid();
    a[i as i32 * stride] = v;
}

/// [`k_touch_f32`] for i32.
#[wp::kernel]
fn k_touch_i32(a: Array<i32>, stride: i32, v: i32) {
    let i = tid();
    a[i as i32 * stride] = v;
}

/// [`k_touch_f32`] for u8 (the value passed as an i32).
#[wp::kernel]
fn k_touch_u8(a: Array<u8>, stride: i32, v: i32) {
    let i = tid();
    a[i as i32 * stride] = v as u8;
}

/// [`k_touch_f32`] for Vec3 (12-byte elements, 4-byte aligned).
#[wp::kernel]
fn k_touch_vec3(a: Array<Vec3>, stride: i32, v: f32) {
    let i = tid();
    a[i as i32 * stride] = Vec3::new(v, -v, 0.5 * v);
}

/// The largest allocation of the cycles: 4 MiB.
const MAX_BYTES: u64 = 4 << 20;
/// Arrays alive at once: each cycle frees the oldest, so that frees come in another order
/// than allocations and the allocators see fragmentation, not a stack.
const RING: usize = 8;
/// Elements between two touched ones: at most 1 KiB, four writes a 4 KiB page.
const TOUCH_BYTES: usize = 1024;

/// Allocates an array of `len` elements of `T` on `dev`, by `how` (zeros, `full`, or from a
/// host vector; the last two only for small arrays: they fill element by element), writes
/// `value` into every [`TOUCH_BYTES`] by `touch`, and reads back the first and the last
/// written element (exact: stored and loaded unchanged).
fn alloc_touched<T: wp::Element + PartialEq + std::fmt::Debug>(
    len: usize,
    how: u64,
    value: T,
    dev: &wp::Device,
    touch: fn(&wp::Array<T>, i32, T, &wp::Device) -> wp::Result<()>,
) -> wp::Result<wp::Array<T>> {
    let small = len * std::mem::size_of::<T>() <= 64 << 10;
    let a = match how % 3 {
        1 if small => wp::Array::full(len, value, dev)?,
        2 if small => wp::Array::from_vec(vec![value; len], dev)?,
        _ => wp::Array::<T>::zeros(len, dev)?,
    };
    let stride = (TOUCH_BYTES / std::mem::size_of::<T>()).max(1);
    touch(&a, stride as i32, value, dev)?;
    let last = (len - 1) / stride * stride;
    for i in [0, last] {
        let got = a.view(i..i + 1)?.to_vec()?;
        assert_eq!(got, [value], "{len} x {}: element {i}", T::TYPE_NAME);
    }
    Ok(a)
}

/// A taped forward and backward on fresh arrays with gradients (the tape, its closures and
/// the gradient arrays are allocated and freed with the cycle), the gradient checked exactly.
fn tape_cycle(dev: &wp::Device, t: usize) -> wp::Result<()> {
    let input = tape_input(t);
    let c = (t % 16 + 1) as f32;
    let x = wp::Array::from_slice(&input, dev)?.with_grad()?;
    let y = wp::Array::<f32>::zeros(N_TAPE, dev)?.with_grad()?;
    let p = wp::Array::<f32>::zeros(N_TAPE, dev)?;
    let loss = wp::Array::<f32>::zeros(1, dev)?.with_grad()?;
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_square, N_TAPE, (&x, &p, &y, c), dev)?;
        wp::launch(k_sum, N_TAPE, (&y, &loss), dev)?;
    }
    tape.backward(&loss)?;
    // Exact, as in `stress_thread`.
    let grad = x.grad().expect("with_grad").to_vec()?;
    for (i, (&g, &x)) in grad.iter().zip(&input).enumerate() {
        assert_eq!(g, 2.0 * c * x, "tape cycle {t}: d loss / d x[{i}]");
    }
    Ok(())
}

/// `cycles` allocate/free cycles on `dev`: sizes from one element to [`MAX_BYTES`], spread
/// evenly over the powers of two, in five element types; a tape every tenth cycle. Returns the
/// bytes allocated.
fn alloc_cycles(dev: &wp::Device, rng: &mut Rng, cycles: usize) -> wp::Result<u64> {
    let mut ring: std::collections::VecDeque<Box<dyn std::any::Any>> =
        std::collections::VecDeque::new();
    let mut total = 0u64;
    for k in 0..cycles {
        // Bytes in [2^e, 2^(e + 1)) for e in 0..22: below MAX_BYTES.
        let e = rng.below(22);
        let bytes = (1u64 << e) + rng.below(1u64 << e);
        let how = rng.next();
        let dtype = rng.below(5);
        let len = |size: usize| (bytes as usize / size).max(1);
        // Integers and halves: exact in every type (u8 and i32 take the integer part).
        let v = (k % 100) as f32 + 0.5;
        let held: Box<dyn std::any::Any> = match dtype {
            0 => Box::new(alloc_touched(len(4), how, v, dev, |a, s, v, d| {
                wp::launch(k_touch_f32, a.len().div_ceil(s as usize), (a, s, v), d)
            })?),
            1 => Box::new(alloc_touched(len(8), how, v as f64, dev, |a, s, v, d| {
                wp::launch(k_touch_f64, a.len().div_ceil(s as usize), (a, s, v), d)
            })?),
            2 => Box::new(alloc_touched(len(4), how, v as i32, dev, |a, s, v, d| {
                wp::launch(k_touch_i32, a.len().div_ceil(s as usize), (a, s, v), d)
            })?),
            3 => Box::new(alloc_touched(len(1), how, v as u8, dev, |a, s, v, d| {
                wp::launch(
                    k_touch_u8,
                    a.len().div_ceil(s as usize),
                    (a, s, v as i32),
                    d,
                )
            })?),
            _ => Box::new(alloc_touched(
                len(12),
                how,
                Vec3::new(v, -v, 0.5 * v),
                dev,
                |a, s, v, d| wp::launch(k_touch_vec3, a.len().div_ceil(s as usize), (a, s, v.x), d),
            )?),
        };
        total += bytes;
        ring.push_back(held);
        if ring.len() > RING {
            ring.pop_front();
        }
        if k % 10 == 9 {
            tape_cycle(dev, k)?;
        }
    }
    Ok(total)
}

/// Cycles of the warm-up: enough for every size class and type to have been allocated, freed
/// and cached by the allocators, and for every kernel to be compiled (on a GPU).
const WARM_UP_CYCLES: usize = 1_000;
/// Cycles measured.
const CYCLES: usize = 10_000;

/// Growth bounds of the allocation cycles.
///
/// - Live heap: 64 KiB. Every array, tape and read-back of the cycles is dropped before the
///   figure is taken, so the Rust heap is back where it was, up to what the runtime creates
///   once (caches, thread-locals: the warm-up made them) and the test harness's own few
///   allocations. A leak of 7 bytes a cycle would pass 64 KiB.
/// - RSS: 48 MiB. glibc keeps freed memory for reuse: blocks freed from a `mmap` raise its
///   threshold (up to 32 MiB) so that later blocks of up to 4 MiB come from the heap, and the
///   heap's free top is returned only past twice that threshold (8 MiB here); between two
///   measurements the heap may also hold the holes of the ring's 8 live arrays (up to 32 MiB)
///   in another layout. So two steady states may differ by up to the ring plus the trim
///   threshold, 40 MiB; a leak of the arrays themselves would be gigabytes (10,000 cycles
///   allocate about 2.6 GiB).
/// - GPU free memory: 64 MiB. The stream-ordered pool keeps what arrays free (its release
///   threshold is the maximum), so free memory falls to the high-water mark in the warm-up;
///   fragmentation may make the pool reserve a few more chunks for the ring's 8 arrays (32 MiB
///   at most) at its granularity (2 MiB). GPU arrays leaked would again be gigabytes. The
///   figure is the whole device's: run on a GPU no other process is using.
const HEAP_BOUND: usize = 64 << 10;
const RSS_BOUND: usize = 48 << 20;
const GPU_BOUND: usize = 64 << 20;

/// Cycles of the soak run.
const SOAK_CYCLES: usize = 100_000;

/// Warm-up, then `cycles` cycles measured: prints the figures and checks the bounds.
fn alloc_test(dev: &wp::Device, cycles: usize, name: &str) {
    let mut rng = Rng(0x5eed_1234_abcd_ef01);
    alloc_cycles(dev, &mut rng, WARM_UP_CYCLES).unwrap();
    let before = Memory::now(dev);
    let start = Instant::now();
    let total = alloc_cycles(dev, &mut rng, cycles).unwrap();
    let elapsed = start.elapsed();
    let after = Memory::now(dev);
    println!(
        "{name}: {cycles} allocate/free cycles on \"{dev}\" ({} allocated, 1 element to {}, \
         {} tapes) in {:.2} s\n  before: {}\n  after:  {}",
        bytes(total as f64),
        bytes(MAX_BYTES as f64),
        cycles / 10,
        elapsed.as_secs_f64(),
        before.show(),
        after.show()
    );
    assert_flat(name, before, after, HEAP_BOUND, RSS_BOUND, GPU_BOUND);
}

#[test]
fn alloc_cycles_cpu() {
    let _serial = serial();
    alloc_test(&wp::cpu(), CYCLES, "alloc_cycles_cpu");
}

#[test]
fn alloc_cycles_gpu() {
    let _serial = serial();
    let Some(dev) = gpu("alloc_cycles_gpu") else {
        return;
    };
    alloc_test(&dev, CYCLES, "alloc_cycles_gpu");
}

#[test]
#[ignore = "soak: cargo test --release --test soak -- --ignored --nocapture"]
fn alloc_soak_cpu() {
    let _serial = serial();
    alloc_test(&wp::cpu(), SOAK_CYCLES, "alloc_soak_cpu");
}

#[test]
#[ignore = "soak: cargo test --release --test soak -- --ignored --nocapture"]
fn alloc_soak_gpu() {
    let _serial = serial();
    let Some(dev) = gpu("alloc_soak_gpu") else {
        return;
    };
    alloc_test(&dev, SOAK_CYCLES, "alloc_soak_gpu");
}

// ---------------------------------------------------------------------------------------------
// (c) One scene for many steps

/// Stiffness of the soak's chains (N/m) and its step (s): omega_max dt = 2 sqrt(k / m) dt =
/// 0.28, well inside symplectic Euler's stability limit of 2, so the chains swing for ever
/// without blowing up or coming to rest.
const SOAK_K: f32 = 1_000.0;
const SOAK_DT: f32 = 1e-3;

/// Growth bounds of the scene soak, from its first sample (taken after `every` steps, the
/// warm-up) to each later one.
///
/// - Live heap: 16 KiB. A step is one launch and allocates nothing that outlives it; the
///   samples' read-backs are dropped before the next sample. One byte leaked a step would be
///   90 KB over the full soak (18 KB over the normal suite's 1,800 steps).
/// - RSS: 4 MiB. Only the read-backs (two arrays of 256 x 21 Vec3, 64 KiB each) come and go;
///   the allocator may keep them cached in another place.
/// - GPU free memory: 4 MiB. A step allocates nothing on the GPU; the read-backs' staging
///   is the driver's, reused.
const SOAK_HEAP_BOUND: usize = 16 << 10;
const SOAK_RSS_BOUND: usize = 4 << 20;
const SOAK_GPU_BOUND: usize = 4 << 20;

/// The `springs` scene's chains (examples/common/springs.rs, semi-implicit Euler) for `steps`
/// steps on `dev`; every `every` steps the memory is sampled and the state read back and
/// checked: finite, every particle within 2 m of the pin (the chain is 1 m long; a chain that
/// blew up leaves that ball), and chain 0's energy within 10% of the energy scale of where it
/// started: a check against blow-up (an unstable chain gains energy without bound), not of
/// accuracy. Symplectic Euler's energy error in f32 wanders without growing: within +-1.6% of
/// the scale over 100,000 steps on the CPU.
fn scene_soak(dev: &wp::Device, chains: usize, steps: usize, every: usize, name: &str) {
    use springs::{energy, energy_scale, Chains, Solver};
    let mut state = Chains::new(chains, dev).unwrap();
    let (x0, v0) = state.first().unwrap();
    let e0 = energy(&x0, &v0, SOAK_K as f64);
    // Reserved up front: the samples' own growth would show in the live heap.
    let mut samples: Vec<(usize, Memory, f64)> = Vec::with_capacity(steps / every);
    let start = Instant::now();
    for step in 1..=steps {
        state.step(Solver::Euler, SOAK_K, SOAK_DT, dev).unwrap();
        if step % every == 0 {
            let (x, v) = (state.x.to_vec().unwrap(), state.v.to_vec().unwrap());
            assert!(
                x.iter().chain(&v).all(|p| p.is_finite()),
                "{name}: a non-finite position or velocity after {step} steps"
            );
            let far = x.iter().map(|p| p.length()).fold(0.0f32, f32::max);
            assert!(
                far <= 2.0,
                "{name}: a particle {far} m from the pin after {step} steps"
            );
            drop((x, v));
            let (x, v) = state.first().unwrap();
            let drift = (energy(&x, &v, SOAK_K as f64) - e0) / energy_scale();
            assert!(
                drift.abs() < 0.1,
                "{name}: energy drift {drift:e} of the scale after {step} steps"
            );
            drop((x, v));
            samples.push((step, Memory::now(dev), drift));
        }
    }
    let elapsed = start.elapsed();
    println!(
        "{name}: {chains} chains x {} particles on \"{dev}\", {steps} steps of {SOAK_DT} s in \
         {:.2} s ({:.1} us a step)",
        springs::PARTICLES,
        elapsed.as_secs_f64(),
        elapsed.as_secs_f64() * 1e6 / steps as f64
    );
    for (step, m, drift) in &samples {
        println!("  step {step:>7}: {}, energy drift {drift:+.2e}", m.show());
    }
    let (first_step, first, _) = samples[0];
    for &(step, m, _) in &samples[1..] {
        assert_flat(
            &format!("{name} (step {first_step} to {step})"),
            first,
            m,
            SOAK_HEAP_BOUND,
            SOAK_RSS_BOUND,
            SOAK_GPU_BOUND,
        );
    }
}

/// Chains of the soak: 256 x 21 = 5,376 threads a step, above `cpu_min_chunk`, so the CPU
/// runs them on the rayon pool.
const SOAK_CHAINS: usize = 256;
/// The normal suite's smaller run: 64 chains (1,344 threads, run on the test's thread) for
/// 2,000 steps, a sample every 200.
const SUITE_CHAINS: usize = 64;

#[test]
fn scene_cpu() {
    let _serial = serial();
    scene_soak(&wp::cpu(), SUITE_CHAINS, 2_000, 200, "scene_cpu");
}

#[test]
fn scene_gpu() {
    let _serial = serial();
    let Some(dev) = gpu("scene_gpu") else {
        return;
    };
    scene_soak(&dev, SUITE_CHAINS, 2_000, 200, "scene_gpu");
}

#[test]
#[ignore = "soak: cargo test --release --test soak -- --ignored --nocapture"]
fn scene_soak_cpu() {
    let _serial = serial();
    scene_soak(&wp::cpu(), SOAK_CHAINS, 100_000, 10_000, "scene_soak_cpu");
}

#[test]
#[ignore = "soak: cargo test --release --test soak -- --ignored --nocapture"]
fn scene_soak_gpu() {
    let _serial = serial();
    let Some(dev) = gpu("scene_soak_gpu") else {
        return;
    };
    // Launches queue without a wait each; faults surface at the samples' read-backs.
    let _debug = DebugMode::set(false);
    scene_soak(&dev, SOAK_CHAINS, 100_000, 10_000, "scene_soak_gpu");
}

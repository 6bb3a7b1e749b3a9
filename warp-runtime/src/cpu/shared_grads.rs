//! Adjoint launches running at once on the CPU, and the gradients they may share.
//!
//! A CPU adjoint thread adds the gradient of a thread-owned read (an array read at the thread
//! index, in a launch whose arrays cover the grid) with a plain load, add and store: no other
//! thread *of its launch* touches that element, and an atomic add there made the backward
//! pass of `benches/cpu_backward.rs` 2.3 times slower (an x86 `lock cmpxchg` per element).
//! But two launches may run at once on different host threads (two tapes' backward passes,
//! environments stepped in parallel) and read one parameter array: their plain adds into its
//! gradient would race, losing updates (and a data race is undefined behaviour).
//!
//! So the plain path runs only while one adjoint launch is active in the process. Every CPU
//! adjoint launch holds an [`AdjointLaunch`] for its duration and runs each of its chunks
//! through [`chunk`], which picks the path for the whole chunk: plain while the launch is
//! alone, otherwise the checked path, where every gradient update is atomic (as a launch
//! whose arrays do not cover the grid always does). A launch that starts while another is
//! active waits, before its first chunk, until the chunks already running on the plain path
//! have finished; chunks that start after it see two active launches and take the atomic
//! path. Those chunks are leaves (a kernel thread never enters rayon), so the wait is short
//! and cannot be on a chunk further down its own stack: no deadlock when a backward pass runs
//! inside a rayon task.
//!
//! Why it is sound, with every access sequentially consistent: a plain chunk increments
//! `PLAIN_CHUNKS` and then reads `ACTIVE` as 1 (its own launch). A second launch increments
//! `ACTIVE` and then reads `PLAIN_CHUNKS`. In the single total order, the chunk's read of
//! `ACTIVE` comes before the second launch's increment (it read 1), so its increment of
//! `PLAIN_CHUNKS` does too, and the second launch sees it until the chunk decrements it.
//!
//! The test: `tests/soak.rs`' stress threads differentiate a shared parameter array from 16
//! host threads at once and check every update arrived (it lost updates before).

use std::sync::atomic::{AtomicUsize, Ordering::SeqCst};

/// CPU adjoint launches under way in the process.
static ACTIVE: AtomicUsize = AtomicUsize::new(0);
/// Chunks running on the plain (non-atomic) gradient path, and chunks about to decide.
static PLAIN_CHUNKS: AtomicUsize = AtomicUsize::new(0);

/// One CPU adjoint launch, active from [`AdjointLaunch::begin`] until dropped.
pub(crate) struct AdjointLaunch(());

impl AdjointLaunch {
    /// Counts this launch as active; if another one already is, first waits until the chunks
    /// running on the plain path have finished (from then on every chunk takes the atomic
    /// path until only one launch is active again).
    pub(crate) fn begin() -> AdjointLaunch {
        if ACTIVE.fetch_add(1, SeqCst) > 0 {
            let mut spins = 0u32;
            while PLAIN_CHUNKS.load(SeqCst) != 0 {
                // A chunk is a few microseconds to milliseconds of kernel threads.
                if spins < 64 {
                    std::hint::spin_loop();
                    spins += 1;
                } else {
                    std::thread::yield_now();
                }
            }
        }
        AdjointLaunch(())
    }
}

impl Drop for AdjointLaunch {
    fn drop(&mut self) {
        ACTIVE.fetch_sub(1, SeqCst);
    }
}

/// Leaves the plain path when dropped (a fault returned by the chunk included).
struct PlainChunk;

impl Drop for PlainChunk {
    fn drop(&mut self) {
        PLAIN_CHUNKS.fetch_sub(1, SeqCst);
    }
}

/// Runs one chunk of an active [`AdjointLaunch`]: `run(shared)`, where `shared` says that
/// another adjoint launch may be accumulating into the same gradients, so every gradient
/// update of the chunk must be atomic.
#[inline]
pub(crate) fn chunk<R>(_launch: &AdjointLaunch, run: impl FnOnce(bool) -> R) -> R {
    PLAIN_CHUNKS.fetch_add(1, SeqCst);
    if ACTIVE.load(SeqCst) > 1 {
        PLAIN_CHUNKS.fetch_sub(1, SeqCst);
        return run(true);
    }
    let _plain = PlainChunk;
    run(false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::AtomicU8;
    use std::time::Duration;

    /// A second launch's `begin` waits for a running plain chunk; its chunks, run while both
    /// launches are active, are shared.
    #[test]
    fn second_launch_waits_for_plain_chunks() {
        // 0: not yet in the chunk; 1: in a plain chunk; 2: in a shared chunk (another test of
        // this binary had an adjoint launch active: the wait is then not exercised).
        let state = AtomicU8::new(0);
        let release = AtomicU8::new(0);
        let begun = AtomicU8::new(0);
        let a = AdjointLaunch::begin();
        std::thread::scope(|s| {
            s.spawn(|| {
                chunk(&a, |shared| {
                    state.store(if shared { 2 } else { 1 }, SeqCst);
                    while release.load(SeqCst) == 0 {
                        std::thread::yield_now();
                    }
                })
            });
            while state.load(SeqCst) == 0 {
                std::thread::yield_now();
            }
            let second = s.spawn(|| {
                let b = AdjointLaunch::begin();
                begun.store(1, SeqCst);
                chunk(&b, |shared| shared)
            });
            std::thread::sleep(Duration::from_millis(50));
            if state.load(SeqCst) == 1 {
                assert_eq!(
                    begun.load(SeqCst),
                    0,
                    "a second adjoint launch began while a plain chunk ran"
                );
            }
            release.store(1, SeqCst);
            assert!(
                second.join().unwrap(),
                "a chunk run while two adjoint launches are active must be shared"
            );
        });
        drop(a);
    }
}

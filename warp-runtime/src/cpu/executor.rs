//! The CPU executor: the threads of a launch, in chunks on the rayon pool; the blocks of a
//! tiled launch, in chunks on a pool of big-stack threads.

use crate::config;
use crate::error::{Error, Result};
use rayon::prelude::*;
use std::sync::OnceLock;
use warp_core::KResult;

/// Threads per rayon task: about eight tasks per pool thread, so that uneven work (a
/// neighbour query's threads differ severalfold) balances out by stealing, and at least an
/// eighth of `min_chunk`, so that the task overhead (about a microsecond) stays small next to
/// the work of light kernels. With four tasks per thread and chunks of at least `min_chunk`,
/// 100K queries on 16 threads made 25 tasks: the last round left 7 threads idle.
fn chunk_len(total: usize, min_chunk: usize, pool_threads: usize) -> usize {
    (min_chunk / 8)
        .max(1)
        .max(total / (pool_threads.max(1) * 8))
}

/// Runs `run` over the flat thread indices `0..total` on the CPU: serially for small grids,
/// in rayon chunks otherwise, stopping at the first fault. `run` is generic so that the
/// kernel's thread loop is inlined into it (forward launches and adjoints share this).
pub(crate) fn for_each_chunk<F>(total: usize, run: F) -> Result<()>
where
    F: Fn(std::ops::Range<usize>) -> KResult<()> + Sync,
{
    let min_chunk = config::cpu_min_chunk();
    if total <= min_chunk {
        // Waking the pool costs microseconds; a small launch is faster on this thread.
        return run(0..total).map_err(Error::from);
    }
    let chunk = chunk_len(total, min_chunk, rayon::current_num_threads());
    (0..total.div_ceil(chunk))
        .into_par_iter()
        .try_for_each(|c| {
            let start = c * chunk;
            run(start..(start + chunk).min(total))
        })
        .map_err(Error::from)
}

/// The stack of each thread that runs tiled launches. A block's tiles and per-lane values
/// (`PerLane`, up to 1024 slots per variable) are values on the stack of the thread running the
/// block, so a block can take megabytes: far past the 2 MiB a rayon thread has by default, and
/// rayon cannot grow the stacks of the global pool once it is built (the user may have built it
/// first). Address space only: the pages a block does not touch are never committed.
pub(crate) const TILE_STACK_BYTES: usize = 64 << 20;

/// The most stack one block of a tiled launch may take ([`TileInfo::cpu_frame_bytes`]): half
/// of [`TILE_STACK_BYTES`], the rest left to the executor, the kernel's calls and the
/// unoptimized frames of a debug build.
///
/// [`TileInfo::cpu_frame_bytes`]: crate::kernel::TileInfo::cpu_frame_bytes
pub(crate) const TILE_FRAME_LIMIT: usize = TILE_STACK_BYTES / 2;

/// The pool that runs tiled launches: as many threads as the global pool, each with
/// [`TILE_STACK_BYTES`] of stack, built at the first tiled launch (a program without tiles
/// never starts its threads).
fn tile_pool() -> Result<&'static rayon::ThreadPool> {
    static POOL: OnceLock<std::result::Result<rayon::ThreadPool, String>> = OnceLock::new();
    POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(rayon::current_num_threads())
            .stack_size(TILE_STACK_BYTES)
            .thread_name(|i| format!("warp-tile-{i}"))
            .build()
            .map_err(|e| e.to_string())
    })
    .as_ref()
    .map_err(|e| {
        Error::invalid(format!(
            "the CPU's pool for tiled launches (threads with {TILE_STACK_BYTES} bytes of \
             stack) could not be started: {e}"
        ))
    })
}

/// Runs `run` over the blocks `0..blocks` of a tiled launch with `block_dim` threads per block:
/// a block is the unit (`run` runs every lane of each block in its range), in chunks of about
/// the work of [`for_each_chunk`]'s (`min_chunk / block_dim` blocks at least), always on the
/// big-stack threads of [`tile_pool`], even when the launch is small enough to run serially.
pub(crate) fn for_each_block<F>(blocks: usize, block_dim: usize, run: F) -> Result<()>
where
    F: Fn(std::ops::Range<usize>) -> KResult<()> + Sync + Send,
{
    let pool = tile_pool()?;
    let min_chunk = config::cpu_min_chunk() / block_dim.max(1);
    pool.install(|| blocks_on_pool(pool, blocks, min_chunk, &run))
}

/// The body of [`for_each_block`], run by a thread of [`tile_pool`]. Never inlined: rayon's
/// `install` runs its closure in the calling thread's frame when that thread is a worker, so
/// with the closure inlined, LLVM hoists the block's frame (megabytes of tiles, allocated at
/// function entry) into the caller's own frame even when the caller is not a worker and
/// merely waits: a release build then overflowed the 2 MiB stack of the thread that launched
/// (found by `blocks_run_once_each_on_big_stacks`).
#[inline(never)]
fn blocks_on_pool<F>(
    pool: &rayon::ThreadPool,
    blocks: usize,
    min_chunk: usize,
    run: &F,
) -> Result<()>
where
    F: Fn(std::ops::Range<usize>) -> KResult<()> + Sync + Send,
{
    if blocks <= min_chunk.max(1) {
        // Waking more threads costs microseconds; one task of the pool runs it all.
        return run(0..blocks).map_err(Error::from);
    }
    let chunk = chunk_len(blocks, min_chunk, pool.current_num_threads());
    (0..blocks.div_ceil(chunk))
        .into_par_iter()
        .try_for_each(|c| {
            let start = c * chunk;
            run(start..(start + chunk).min(blocks))
        })
        .map_err(Error::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_run_once_each_on_big_stacks() {
        use std::sync::atomic::{AtomicU32, Ordering};
        for (blocks, bd) in [
            (1usize, 1usize),
            (3, 64),
            (5000, 1),
            (40_000, 128),
            (9, 1024),
        ] {
            let seen: Vec<AtomicU32> = (0..blocks).map(|_| AtomicU32::new(0)).collect();
            for_each_block(blocks, bd, |range| {
                // A frame a default 2 MiB thread could not hold: it runs on a big stack.
                let big = std::hint::black_box([7u8; 8 << 20]);
                assert_eq!(big[12345], 7);
                for b in range {
                    seen[b].fetch_add(1, Ordering::Relaxed);
                }
                Ok(())
            })
            .unwrap();
            assert!(
                seen.iter().all(|s| s.load(Ordering::Relaxed) == 1),
                "{blocks}x{bd}"
            );
        }
    }

    #[test]
    fn chunking() {
        assert_eq!(chunk_len(4097, 4096, 2), 512);
        assert_eq!(chunk_len(100_003, 4096, 2), 6_250);
        assert_eq!(chunk_len(100_003, 4096, 16), 781);
        assert_eq!(chunk_len(100_003, 4096, 64), 512);
        assert_eq!(chunk_len(3, 0, 0), 1);
        assert_eq!(chunk_len(10, 0, 0), 1);
        // The last chunk of 100_003 threads in chunks of 6_250 is partial and still covered.
        assert_eq!(100_003usize.div_ceil(6_250), 17);
    }
}

//! The CPU executor: the threads of a launch, in chunks on the rayon pool.

use crate::config;
use crate::error::{Error, Result};
use rayon::prelude::*;
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

#[cfg(test)]
mod tests {
    use super::*;

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

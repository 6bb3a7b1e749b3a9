//! [`Cpu`]: the CPU backend as the runtime dispatches to it (`backend.rs`).

use super::capture::{self, CpuGraph};
use super::deterministic;
use super::executor;
use super::memory::HostBuffer;
use super::primitives;
use super::race;
use super::shared_grads::{self, AdjointLaunch};
use crate::backend::{Backend, Conditional, ObjectStep, Op, Record};
use crate::config;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::{ArgsOf, Kernel, KernelInfo, KernelParams};
use crate::primitives::elements::{Extent, ScanOps, SortKeyOps, SortValueOps};
use crate::primitives::plan::ReduceOp;
use warp_core::view::{with_write_log, WriteLogActive};
use warp_core::{AdStack, Grid, LaunchId};

/// The CPU as a backend, for one launch or array operation on `device`.
pub(crate) struct Cpu<'d> {
    device: &'d Device,
}

impl<'d> Cpu<'d> {
    /// The backend of `device` (the CPU).
    pub(crate) fn new(device: &'d Device) -> Self {
        Cpu { device }
    }
}

/// Runs `run` over the launch's work items in chunks: the threads of an ordinary kernel's
/// launch on the rayon pool, the blocks of a tiled kernel's launch (`grid.total` counts blocks,
/// each running `grid.block_dim` lanes) on the big-stack pool, once a block's stack frame is
/// known to fit there.
fn for_each<K: Kernel, F>(grid: &Grid, run: F) -> Result<()>
where
    F: Fn(std::ops::Range<usize>) -> warp_core::KResult<()> + Sync + Send,
{
    match K::INFO.tile {
        None => executor::for_each_chunk(grid.total, run),
        Some(tile) => {
            if tile.cpu_frame_bytes > executor::TILE_FRAME_LIMIT {
                return Err(Error::TileFrame {
                    kernel: K::INFO.name,
                    bytes: tile.cpu_frame_bytes,
                    limit: executor::TILE_FRAME_LIMIT,
                });
            }
            executor::for_each_block(grid.total, grid.block_dim, run)
        }
    }
}

/// [`for_each`] of a launch; for a `#[kernel(deterministic)]` kernel, each chunk runs with a
/// sink for its float accumulations (forward) or gradient accumulations (adjoint), which are
/// added into their elements in launch order once every chunk has run (`deterministic.rs`). A fault drops the records:
/// the launch's results are not to be trusted then anyway.
///
/// The records per thread are limited as a GPU's record slots are
/// (`DeterministicInfo::limit`): a launch that faults on one backend faults on the other.
fn run_chunks<K: Kernel>(
    grid: &Grid,
    adjoint: bool,
    run: impl Fn(std::ops::Range<usize>) -> warp_core::KResult<()> + Sync + Send,
) -> Result<()> {
    let Some(det) = K::INFO.deterministic else {
        return for_each::<K, _>(grid, run);
    };
    let limit = det.limit(adjoint);
    let chunks = std::sync::Mutex::new(Vec::new());
    for_each::<K, _>(grid, |range| {
        let start = range.start;
        let (r, records) = deterministic::record_chunk(K::INFO.name, limit, || run(range));
        r?;
        chunks
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push((start, records));
        Ok(())
    })?;
    let chunks = chunks.into_inner().unwrap_or_else(|e| e.into_inner());
    // SAFETY: the caller's arguments (every array the records point into) stay borrowed until
    // it returns, and no kernel thread runs any more.
    unsafe { deterministic::reduce(chunks) };
    Ok(())
}

impl Cpu<'_> {
    /// `launch` with the write-race check (`config::set_race_check`): the views are made
    /// with a write log installed, so that they register their memory with it and log their
    /// stores; the threads run one per call, each telling the log who it is (`race.rs`).
    #[cold]
    fn launch_race_checked<K: Kernel>(&self, args: &ArgsOf<'_, K>, grid: &Grid) -> Result<()> {
        let _active = WriteLogActive::new();
        let log = race::WriteLog::new();
        // SAFETY: `args` stays borrowed, and `log` alive, until the run below ends; the
        // views are dropped with this frame, before `log`.
        let params = unsafe {
            with_write_log(&log, 0, || {
                K::Params::cpu_params(args, K::info(), self.device)
            })?
        };
        log.seal()?;
        // (A tiled launch's blocks log as threads: the lanes of a block share its index.)
        run_chunks::<K>(grid, false, |range| {
            race::each_thread(&log, range, |t| K::run_cpu(&params, grid, t))
        })
    }

    /// `launch_adjoint` with the write-race check, as [`Cpu::launch_race_checked`]: gradient
    /// views log their plain writes too (the adjoint of a write clears the gradient it takes),
    /// while gradient accumulation is atomic and not logged.
    #[cold]
    fn launch_adjoint_race_checked<K: Kernel>(
        &self,
        args: &ArgsOf<'_, K>,
        grid: &Grid,
        adstack_bytes: usize,
    ) -> Result<()> {
        let _active = WriteLogActive::new();
        let log = race::WriteLog::new();
        // SAFETY: as in `launch_race_checked`.
        let (params, grads) = unsafe {
            with_write_log(&log, 0, || -> Result<_> {
                Ok((
                    K::Params::cpu_params(args, K::info(), self.device)?,
                    K::Params::cpu_grads(args, K::info(), self.device)?,
                ))
            })?
        };
        log.seal()?;
        let own_alias = K::Params::grads_alias(args, K::INFO.tid_indexed);
        let launch = AdjointLaunch::begin();
        run_chunks::<K>(grid, true, |range| {
            let mut stack = AdStack::new(adstack_bytes, K::INFO.name);
            shared_grads::chunk(&launch, |shared| {
                race::each_thread(&log, range, |t| {
                    K::run_cpu_adjoint(&params, &grads, grid, t, &mut stack, shared || own_alias)
                })
            })
        })
    }
}

impl Backend for Cpu<'_> {
    type Buffer = HostBuffer;
    type Graph = CpuGraph;

    fn launch<K: Kernel>(&self, args: &ArgsOf<'_, K>, grid: &Grid, _: LaunchId) -> Result<()> {
        if config::race_check() {
            return self.launch_race_checked::<K>(args, grid);
        }
        // SAFETY: `args` (and so every array) stays borrowed until the run below ends.
        let params = unsafe { K::Params::cpu_params(args, K::info(), self.device)? };
        run_chunks::<K>(grid, false, |range| K::run_cpu(&params, grid, range))
    }

    fn launch_adjoint<K: Kernel>(
        &self,
        args: &ArgsOf<'_, K>,
        grid: &Grid,
        adstack_bytes: usize,
        _: LaunchId,
    ) -> Result<()> {
        if config::race_check() {
            return self.launch_adjoint_race_checked::<K>(args, grid, adstack_bytes);
        }
        // SAFETY: `args` (and so every array and gradient) stays borrowed for the run.
        let params = unsafe { K::Params::cpu_params(args, K::info(), self.device)? };
        let grads = unsafe { K::Params::cpu_grads(args, K::info(), self.device)? };
        // One adjoint stack per chunk, reused (cleared) thread by thread. Each chunk learns
        // whether another adjoint launch may share its gradients (`shared_grads`); a
        // thread-owned argument whose gradient another argument views differently
        // (`grads_alias`: `x.view(0..n-1)` beside `x.view(1..n)`) makes every add atomic too.
        let own_alias = K::Params::grads_alias(args, K::INFO.tid_indexed);
        let launch = AdjointLaunch::begin();
        run_chunks::<K>(grid, true, |range| {
            let mut stack = AdStack::new(adstack_bytes, K::INFO.name);
            shared_grads::chunk(&launch, |shared| {
                K::run_cpu_adjoint(
                    &params,
                    &grads,
                    grid,
                    range,
                    &mut stack,
                    shared || own_alias,
                )
            })
        })
    }

    fn alloc_zeroed(&self, bytes: usize, align: usize) -> Result<HostBuffer> {
        HostBuffer::zeroed(bytes, align)
    }

    fn synchronize(&self) -> Result<()> {
        // Launches have finished and reported their faults when `launch` returned.
        Ok(())
    }

    fn scan<T: ScanOps>(
        &self,
        func: &'static str,
        input: u64,
        output: u64,
        len: Extent,
        inclusive: bool,
    ) -> Result<()> {
        primitives::scan::<T>(func, input, output, len, inclusive)
    }

    fn reduce<T: ScanOps>(
        &self,
        func: &'static str,
        input: u64,
        out: u64,
        len: Extent,
        op: ReduceOp,
    ) -> Result<()> {
        primitives::reduce::<T>(func, input, out, len, op)
    }

    fn radix_sort_pairs<K: SortKeyOps, V: SortValueOps>(
        &self,
        func: &'static str,
        keys: u64,
        values: u64,
        len: Extent,
        key_bits: u32,
    ) -> Result<()> {
        primitives::radix_sort_pairs::<K, V>(func, keys, values, len, key_bits)
    }

    fn compact<T: bytemuck::Pod + Send + Sync>(
        &self,
        func: &'static str,
        arrays: [u64; 4],
        len: Extent,
    ) -> Result<()> {
        primitives::compact::<T>(func, arrays, len)
    }

    fn object_step<S: ObjectStep>(&self, step: &S) -> Result<()> {
        step.run_cpu()
    }

    fn prepare(
        &self,
        _kernels: &[&'static KernelInfo],
        _adjoint: Option<usize>,
        _block_dim: Option<usize>,
    ) -> Result<()> {
        Ok(())
    }

    fn synchronize_all() -> Result<()> {
        Ok(())
    }

    fn begin_capture(&self) -> Result<()> {
        capture::begin();
        Ok(())
    }

    fn end_capture(&self) -> Result<CpuGraph> {
        capture::end()
    }

    fn abort_capture(&self) {
        capture::abort();
    }

    fn record(&self, op: impl FnOnce() -> Op) -> Record {
        if capture::record(op()) {
            Record::Recorded
        } else {
            Record::Enqueue
        }
    }

    fn capture_conditional(
        &self,
        kind: Conditional,
        cond: u64,
        then: &mut dyn FnMut() -> Result<()>,
        otherwise: Option<&mut dyn FnMut() -> Result<()>>,
    ) -> Result<()> {
        capture::conditional(kind, cond, then, otherwise)
    }

    fn replay(&self, graph: &CpuGraph) -> Result<()> {
        graph.replay()
    }
}

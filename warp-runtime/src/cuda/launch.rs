//! A kernel launch on a GPU: the parameter block and `cuLaunchKernel`, asynchronous on a
//! stream.

use super::deterministic;
use super::fault;
use super::gpu::{check_state, err, read_fault};
use super::module::{loaded, Loaded};
use crate::config;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::{ArgsOf, Kernel, KernelParams, MAX_PARAMS};
use std::ffi::c_void;
use std::marker::PhantomData;
use std::sync::Arc;
use warp_core::{Grid, LaunchId};

/// `wp::launch_t`.
#[repr(C)]
#[derive(Clone, Copy)]
struct LaunchDims {
    dims: [i64; 4],
    total: i64,
    ndim: i32,
    /// `LAUNCH_FAST | LAUNCH_ALONE` (see `wp::launch_t`).
    flags: i32,
}

/// `wp::LAUNCH_FAST`: every array the kernel indexes by the thread index covers the grid.
const LAUNCH_FAST: i32 = 1;
/// `wp::LAUNCH_ALONE`: an adjoint launch that nothing else runs beside ([`GpuState::alone`]),
/// so its thread-owned gradients are plain adds.
///
/// [`GpuState::alone`]: super::gpu::GpuState::alone
const LAUNCH_ALONE: i32 = 2;

/// `wp::launch_ctx_t`.
#[repr(C)]
#[derive(Clone, Copy)]
struct Ctx {
    fault: u64,
    fault_flag: u64,
    reserved: i16,
    /// `CTX_DEBUG` (see `wp::launch_ctx_t`).
    flags: i16,
    kernel: i32,
    launch: u64,
}

/// `wp::CTX_DEBUG`: the runtime's debug mode is on for this launch, so `debug_assert!` is
/// checked (read at each enqueue: a graph keeps the setting of its capture).
const CTX_DEBUG: i16 = 1;
const _: () = assert!(
    std::mem::size_of::<Ctx>() == 32,
    "wp::launch_ctx_t is 32 bytes"
);
// The offsets `wp::launch_ctx_t` declares (and `StepFault::fill` writes).
const _: () = assert!(
    std::mem::offset_of!(Ctx, reserved) == 16
        && std::mem::offset_of!(Ctx, flags) == 18
        && std::mem::offset_of!(Ctx, kernel) == 20
        && std::mem::offset_of!(Ctx, launch) == 24,
    "wp::launch_ctx_t's field offsets"
);

/// Launches `K` over `grid` on GPU `ordinal`: on `stream` when given, else on the calling
/// thread's current stream for the GPU (`ScopedStream`), else on the default stream.
///
/// `adjoint: Some(bytes)` launches the kernel's adjoint instead (with `bytes` of adjoint stack
/// per thread): the arrays' gradients follow the parameters.
pub(crate) fn launch<K: Kernel>(
    args: &ArgsOf<'_, K>,
    grid: &Grid,
    device: &Device,
    ordinal: usize,
    stream: Option<&warp_cuda::Stream>,
    adjoint: Option<usize>,
    id: LaunchId,
) -> Result<()> {
    let (prepared, params, grads) =
        Prepared::<K>::with_params(args, grid, device, ordinal, adjoint)?;
    let plain_own = prepared.plain_own(args);
    prepared.enqueue_converted(params, grads, plain_own, device, stream, id)
}

type CudaParamsOf<K> = <<K as Kernel>::Params as KernelParams>::CudaParams;
type CudaGradsOf<K> = <<K as Kernel>::Params as KernelParams>::CudaGrads;

/// A launch of `K` made ready once (the loaded kernel, the launch dims, the fault context)
/// and queued any number of times with its arguments converted again each time (a launch
/// object's arguments are array handles whose memory a host object may have replaced since).
pub(crate) struct Prepared<K: Kernel> {
    kernel: Arc<Loaded>,
    dims: LaunchDims,
    ctx: Ctx,
    blocks: u32,
    block: u32,
    /// Dynamic shared memory per block: a tiled kernel's tiles (0 for an ordinary kernel).
    shared_bytes: u32,
    ordinal: usize,
    adjoint: bool,
    _kernel: PhantomData<K>,
}

impl<K: Kernel> Prepared<K> {
    /// Checks what a launch of `K` with `args` over `grid` needs (adjoint support, the
    /// arguments' devices) and compiles or finds the kernel.
    pub(crate) fn new(
        args: &ArgsOf<'_, K>,
        grid: &Grid,
        device: &Device,
        ordinal: usize,
        adjoint: Option<usize>,
    ) -> Result<Self> {
        Self::with_params(args, grid, device, ordinal, adjoint).map(|(p, _, _)| p)
    }

    /// [`Prepared::new`], and the arguments converted on the way.
    fn with_params(
        args: &ArgsOf<'_, K>,
        grid: &Grid,
        device: &Device,
        ordinal: usize,
        adjoint: Option<usize>,
    ) -> Result<(Self, CudaParamsOf<K>, Option<CudaGradsOf<K>>)> {
        let info = K::info();
        if adjoint.is_some() {
            if let Some(reason) = info.cuda_adjoint_error {
                return Err(Error::NotDifferentiable {
                    kernel: info.name,
                    reason: reason.to_string(),
                });
            }
        }
        super::deterministic::refuse_capture(info, ordinal)?;
        // Arguments first: a wrong device is reported before anything is compiled.
        let params = K::Params::cuda_params(args, info, device)?;
        let grads = match adjoint {
            Some(_) => Some(K::Params::cuda_grads(args, info, device)?),
            None => None,
        };
        // A tiled kernel is compiled per block size (`WP_TILE_BLOCK_DIM`); `launch.rs` has
        // checked that only tiled launches reach it, with a block size it takes.
        let tile_block = info.tile.map(|_| grid.block_dim);
        // A forward compiled under a recording tape brings its adjoint along (one unit).
        let kernel = loaded(
            device,
            ordinal,
            info,
            K::Params::contiguous(args),
            adjoint,
            tile_block,
            crate::backend::recording_adstack_bytes,
        )?;
        // The fault record and the launch number are each launch's (`enqueue_converted`).
        let ctx = Ctx {
            fault: 0,
            fault_flag: 0,
            reserved: 0,
            flags: 0,
            kernel: kernel.id,
            launch: 0,
        };
        let dims = LaunchDims {
            dims: grid.dims.map(|d| d as i64),
            total: grid.total as i64,
            ndim: grid.ndim as i32,
            flags: match K::Params::cover(args, info.tid_indexed, grid) {
                true => LAUNCH_FAST,
                false => 0,
            },
        };
        let (block, blocks) = match tile_block {
            // One CUDA block per block of the launch (`grid.total` counts them): the entry runs
            // block `blockIdx.x` and nothing else, which keeps the compiler from hoisting the
            // tile code's address arithmetic into registers across a grid-stride loop (96
            // registers a thread against 64 for the batched Cholesky).
            Some(bd) => (bd as u32, grid.total),
            // One thread per element: the forward entry has no grid-stride loop (it cost 0.13
            // us a kernel in graph replays), so the grid must cover the launch.
            None => {
                let block = config::cuda_block_dim();
                (block, grid.total.div_ceil(block as usize))
            }
        };
        // CUDA's grid holds at most `i32::MAX` blocks (the CPU has no such limit).
        let blocks = u32::try_from(blocks)
            .ok()
            .filter(|b| *b <= i32::MAX as u32)
            .ok_or_else(|| Error::InvalidDim {
                kernel: info.name,
                dim: grid.dims[..grid.ndim].to_vec(),
                reason: match tile_block {
                    Some(_) => format!(
                        "a tiled launch on a GPU runs one CUDA block per block: at most {} \
                         blocks, not {}",
                        i32::MAX,
                        grid.total
                    ),
                    None => format!(
                        "a launch on a GPU runs one thread per element, in at most {} blocks \
                         of {block} threads (`wp::config::set_cuda_block_dim`): at most {} \
                         threads, not {}",
                        i32::MAX,
                        i32::MAX as u64 * block as u64,
                        grid.total
                    ),
                },
            })?;
        // (`loaded` checked it against the device and opted in above 48 KiB; it fits u32.)
        let shared_bytes = kernel.shared_bytes as u32;
        let prepared = Prepared {
            kernel,
            dims,
            ctx,
            blocks,
            block,
            shared_bytes,
            ordinal,
            adjoint: adjoint.is_some(),
            _kernel: PhantomData,
        };
        Ok((prepared, params, grads))
    }

    /// Queues the launch with `args` (the arguments it was prepared with, or ones of the same
    /// shapes, contiguity and devices) in the ordering model of `gpu.rs`.
    pub(crate) fn enqueue(
        &self,
        args: &ArgsOf<'_, K>,
        device: &Device,
        stream: Option<&warp_cuda::Stream>,
        id: LaunchId,
    ) -> Result<()> {
        let info = K::info();
        let params = K::Params::cuda_params(args, info, device)?;
        let grads = match self.adjoint {
            true => Some(K::Params::cuda_grads(args, info, device)?),
            false => None,
        };
        self.enqueue_converted(params, grads, self.plain_own(args), device, stream, id)
    }

    /// Whether an adjoint launch with `args` may add its thread-owned gradients plainly when it
    /// runs alone: not when another argument views one of their gradients differently
    /// (`grads_alias`). False for a forward launch, which adds no gradients (and so pays
    /// nothing for the check).
    fn plain_own(&self, args: &ArgsOf<'_, K>) -> bool {
        self.adjoint && !K::Params::grads_alias(args, K::info().tid_indexed)
    }

    /// Queues the launch with arguments already converted. `plain_own`: [`Self::plain_own`].
    fn enqueue_converted(
        &self,
        mut params: CudaParamsOf<K>,
        mut grads: Option<CudaGradsOf<K>>,
        plain_own: bool,
        device: &Device,
        stream: Option<&warp_cuda::Stream>,
        id: LaunchId,
    ) -> Result<()> {
        let (mut dims, mut ctx) = (self.dims, self.ctx);
        let (kernel, ordinal) = (&self.kernel, self.ordinal);
        let st = &kernel.st;
        // A deterministic kernel records into the GPU's record buffer, ordered and added after
        // it on the same stream (`deterministic.rs`); the buffer stays locked until then.
        let records = match K::info().deterministic {
            Some(_) => Some(deterministic::records(
                st,
                device,
                ordinal,
                K::info(),
                self.dims.total as u64,
                self.adjoint,
            )?),
            None => None,
        };
        let mut det_args = records.as_ref().map(|r| r.args);
        // Faults go to the launching thread's record (the capture's inside a capture).
        (ctx.fault, ctx.fault_flag) =
            fault::with_record(&st.faults, ordinal, id, |r| r.addresses())?;
        ctx.launch = id.0;
        // Read once: the kernel's flag, the stream kept and the wait below agree.
        let debug = config::debug();
        if debug {
            ctx.flags |= CTX_DEBUG;
        }
        // Debug mode's wait after the launch: on a stream the caller orders (torch's, XLA's),
        // that stream alone (see below).
        let mut caller_stream = None;
        st.queue(ordinal, stream, |on| {
            if debug && on.is_caller_ordered() {
                caller_stream = Some(on.clone());
            }
            if plain_own && st.alone(on) {
                dims.flags |= LAUNCH_ALONE;
            }
            if let Some(r) = &records {
                r.order_on(device, on)?;
            }
            // The launch and the context, (deterministic) the record buffer, then the
            // parameters and (adjoint) their gradients.
            let mut ptrs = [std::ptr::null_mut::<c_void>(); 3 + 2 * MAX_PARAMS];
            ptrs[0] = (&mut dims) as *mut LaunchDims as *mut c_void;
            ptrs[1] = (&mut ctx) as *mut Ctx as *mut c_void;
            let mut n = 2;
            if let Some(d) = det_args.as_mut() {
                ptrs[2] = d as *mut deterministic::DetArgs as *mut c_void;
                n = 3;
            }
            n += K::Params::cuda_param_ptrs(&mut params, &mut ptrs[n..]);
            if let Some(g) = grads.as_mut() {
                n += K::Params::cuda_grad_ptrs(g, &mut ptrs[n..]);
            }
            // SAFETY: `ptrs[..n]` point at values laid out as the kernel's C++ parameters
            // (launch_t, launch_ctx_t, a deterministic kernel's det_t, then each parameter's
            // CudaArg, which mirrors its C++ type),
            // alive until the call returns; cuLaunchKernel copies them.
            unsafe {
                st.gpu
                    .launch_raw(
                        &kernel.function,
                        on,
                        self.blocks,
                        self.block,
                        self.shared_bytes,
                        &mut ptrs[..n],
                    )
                    .map_err(|e| err(device, e))
            }
        })?;
        if let Some(r) = records {
            let fns = kernel
                .det
                .as_ref()
                .expect("a deterministic kernel's unit has its ordering entries");
            r.reduce(st, device, ordinal, fns, stream)?;
        }
        // (Inside a capture nothing has run yet: there is nothing to check.)
        if debug && super::gpu::capture_stream(ordinal).is_none() {
            match caller_stream {
                // The caller's stream: waiting for the whole device would wait for its other
                // streams too and, while the caller captures this one into a graph (XLA's
                // command buffers), break the capture (CUDA refuses the synchronisation).
                Some(on) => {
                    if !on.is_capturing().map_err(|e| err(device, e))? {
                        on.synchronize().map_err(|e| err(device, e))?;
                        read_fault(st)?;
                    }
                }
                None => check_state(st)?,
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    /// The launch and context flags are the library's (`wp_core.h`), written there once each.
    #[test]
    fn flags_match_the_library() {
        let core = warp_cuda::library::CORE.text;
        for decl in [
            format!("constexpr i32 LAUNCH_FAST = {};", super::LAUNCH_FAST),
            format!("constexpr i32 LAUNCH_ALONE = {};", super::LAUNCH_ALONE),
            format!("constexpr i16 CTX_DEBUG = {};", super::CTX_DEBUG),
        ] {
            assert!(core.contains(&decl), "wp_core.h lacks `{decl}`");
        }
    }
}

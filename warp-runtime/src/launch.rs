//! Typed kernel launch.
//!
//! [`launch`] validates the launch dimensions and the kernel's declared shape constraints,
//! hands the launch to the device's backend (`dispatch.rs`), which converts the arguments into
//! kernel-side parameters and runs every thread of the grid (the CPU: in chunks on the rayon
//! pool; a GPU: queued on a stream), then records it on the recording tapes. Everything is
//! generic over the kernel, so that its thread body is inlined into the backend's loop.

use crate::config;
#[cfg(feature = "cuda")]
use crate::cuda::stream::Stream;
use crate::device::Device;
use crate::dispatch;
use crate::error::{Error, Result};
use crate::kernel::{ArgsOf, Kernel, KernelInfo, KernelParams, Launchable};
use warp_core::Grid;

/// Launch dimensions: 1 to 4 extents, like Warp's `dim=`.
///
/// Built from a `usize`, an array `[usize; K]` or a tuple of 2 to 4 `usize`s. Validity (no zero
/// extent, each extent at most `i32::MAX`, no overflow of the thread count) is checked by
/// [`launch`], which can name the kernel in the error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Dim {
    dims: [usize; 4],
    ndim: usize,
}

impl Dim {
    /// The extents, one per dimension.
    pub fn as_slice(&self) -> &[usize] {
        &self.dims[..self.ndim]
    }

    /// The number of dimensions.
    pub fn ndim(&self) -> usize {
        self.ndim
    }

    fn from_array<const K: usize>(a: [usize; K]) -> Dim {
        const { assert!(K >= 1 && K <= 4, "a launch has 1 to 4 dimensions") };
        let mut dims = [1usize; 4];
        dims[..K].copy_from_slice(&a);
        Dim { dims, ndim: K }
    }
}

impl From<usize> for Dim {
    fn from(n: usize) -> Dim {
        Dim::from_array([n])
    }
}

impl<const K: usize> From<[usize; K]> for Dim {
    /// Only `K` from 1 to 4 compiles.
    fn from(a: [usize; K]) -> Dim {
        Dim::from_array(a)
    }
}

impl From<(usize, usize)> for Dim {
    fn from((a, b): (usize, usize)) -> Dim {
        Dim::from_array([a, b])
    }
}

impl From<(usize, usize, usize)> for Dim {
    fn from((a, b, c): (usize, usize, usize)) -> Dim {
        Dim::from_array([a, b, c])
    }
}

impl From<(usize, usize, usize, usize)> for Dim {
    fn from((a, b, c, d): (usize, usize, usize, usize)) -> Dim {
        Dim::from_array([a, b, c, d])
    }
}

/// The most threads a block of a tiled launch may have: what every CUDA GPU allows, and
/// what `warp_core::block::PerLane` holds on the CPU (warp-core's constant, so the two cannot
/// drift).
pub use warp_core::block::MAX_BLOCK_DIM;

/// Checks that the launch fits the kind of kernel `K` is: `block_dim: None` for [`launch`],
/// `Some(threads per block)` for [`launch_tiled`]. A tiled kernel takes only tiled launches,
/// whose block size is 1 to [`MAX_BLOCK_DIM`] and the width its tiles fix, if any.
fn check_kind<K: Kernel>(block_dim: Option<usize>) -> Result<()> {
    let info = &K::INFO;
    let kernel = info.name;
    if info.deterministic.is_some() {
        if let Some(func) = float_atomic_func(info.callees) {
            return Err(Error::Deterministic {
                kernel,
                why: format!(
                    "it calls func `{func}`, which uses float atomic_add/atomic_sub: a func's \
                     accumulations are not recorded (do them in the kernel)"
                ),
            });
        }
    }
    match (info.tile, block_dim) {
        (None, None) => Ok(()),
        (Some(_), None) => Err(Error::LaunchKind {
            kernel,
            why: format!(
                "a tiled kernel (it uses tiles) launched with `launch`: launch it with \
                 `launch_tiled({kernel}, blocks, args, block_dim, &device)` (dim counts blocks)"
            ),
        }),
        (None, Some(_)) => Err(Error::LaunchKind {
            kernel,
            why: "an ordinary kernel (it uses no tiles) launched with `launch_tiled`: launch \
                  it with `launch`"
                .to_string(),
        }),
        (Some(_), Some(bd)) => check_tiled_info(info, bd),
    }
}

/// The name of a func among `funcs` and their callees that accumulates floats atomically.
fn float_atomic_func(funcs: &[&'static warp_core::FuncInfo]) -> Option<&'static str> {
    funcs.iter().find_map(|f| {
        if f.float_atomics {
            Some(f.name)
        } else {
            float_atomic_func(f.callees)
        }
    })
}

/// [`check_kind`], then [`grid_of`] with the block size (1 for an ordinary launch).
fn checked_grid<K: Kernel>(dim: Dim, block_dim: Option<usize>) -> Result<Grid> {
    check_kind::<K>(block_dim)?;
    let mut grid = grid_of(K::INFO.name, dim)?;
    grid.block_dim = block_dim.unwrap_or(1);
    Ok(grid)
}

/// Checks `dim` and turns it into the grid kernel code sees (of one-thread blocks: the caller
/// sets a tiled launch's block size).
fn grid_of(kernel: &'static str, dim: Dim) -> Result<Grid> {
    let invalid = |reason: String| Error::InvalidDim {
        kernel,
        dim: dim.as_slice().to_vec(),
        reason,
    };
    if !(1..=4).contains(&dim.ndim) {
        return Err(invalid(format!(
            "a launch has 1 to 4 dimensions, not {}",
            dim.ndim
        )));
    }
    let mut total = 1usize;
    for (d, &e) in dim.as_slice().iter().enumerate() {
        if e == 0 {
            return Err(invalid(format!("a launch dim of zero (dimension {d})")));
        }
        if e > i32::MAX as usize {
            // The GPU backend indexes threads with 32-bit extents, as Warp does; the CPU keeps
            // the same limit so that a launch valid on one backend is valid on the other.
            return Err(invalid(format!(
                "extent {e} of dimension {d} exceeds i32::MAX ({})",
                i32::MAX
            )));
        }
        total = total
            .checked_mul(e)
            .ok_or_else(|| invalid("the number of threads overflows usize".to_string()))?;
    }
    Ok(Grid {
        dims: dim.dims,
        ndim: dim.ndim,
        total,
        block_dim: 1,
    })
}

/// Checks the kernel's `tid()` arity and `same_shape` groups against the launch.
fn check_shapes<K: Kernel>(args: &ArgsOf<'_, K>, grid: &Grid) -> Result<()> {
    let info = &K::INFO;
    if let Some(k) = info.tid_ndim {
        if k != grid.ndim {
            return Err(Error::TidMismatch {
                kernel: info.name,
                tid_ndim: k,
                launch_ndim: grid.ndim,
            });
        }
    }
    if info.same_shape.is_empty() {
        // Skip `shapes`, which allocates: launch cost matters.
        return Ok(());
    }
    let shapes = K::Params::shapes(args);
    for group in info.same_shape {
        let mut names = Vec::with_capacity(group.len());
        let mut group_shapes = Vec::with_capacity(group.len());
        for &i in group.iter() {
            let (name, shape) = if i == usize::MAX {
                ("dim".to_string(), grid.dims[..grid.ndim].to_vec())
            } else {
                let name = info
                    .params
                    .get(i)
                    .map_or_else(|| format!("#{i}"), |n| n.to_string());
                // A non-array in a group is rejected by the macro; nothing to compare here.
                match shapes.get(i).cloned().flatten() {
                    Some(shape) => (name, shape),
                    None => continue,
                }
            };
            names.push(name);
            group_shapes.push(shape);
        }
        if group_shapes.windows(2).any(|w| w[0] != w[1]) {
            return Err(Error::ShapeMismatch {
                kernel: info.name,
                args: names,
                shapes: group_shapes,
            });
        }
    }
    Ok(())
}

/// Compiles `kernels` for `device` now rather than at their first launches (Warp's
/// `wp.load_module`): on a GPU every kernel's variant for contiguous arrays is compiled by
/// NVRTC (or read from the disk cache) and loaded, so that no later launch, timed loop or
/// graph capture compiles. On the CPU, nothing: cargo compiled the kernels.
///
/// The kernels are handed to the rayon pool together, but NVRTC (CUDA 13) runs one compile
/// at a time per loaded copy of libnvrtc: they take turns unless `warp_cuda::NVRTC_THREADS_ENV`
/// allows copies of libnvrtc (experimental, off by default: a load with copies crashed on a
/// GPU machine with glibc 2.39). A warm start needs none of this: the disk cache and
/// `wp::aot` serve the cubins.
///
/// ```ignore
/// // (tests/suite/launch.rs runs this on both backends)
/// #[wp::kernel]
/// fn scale(x: Array<f32>, s: f32) {
///     let i = tid();
///     x[i] *= s;
/// }
/// let dev = wp::get_preferred_device();
/// wp::load(&[wp::kernel_info(scale)], &dev).unwrap();
/// ```
///
/// # Errors
/// A kernel that does not compile ([`Error::Cuda`] with NVRTC's log); [`Error::NoDevice`].
pub fn load(kernels: &[&'static KernelInfo], device: &Device) -> Result<()> {
    dispatch::prepare(device, kernels, None)
}

/// [`load`], and each kernel's adjoint too (with the adjoint stack
/// [`config::adstack_bytes`] sets), for programs that will run backward. A kernel whose
/// forward and adjoint are both still to compile gets one unit holding both (one NVRTC run,
/// as a first launch under a recording [`Tape`](crate::Tape) does).
///
/// # Errors
/// As [`load`].
pub fn load_with_adjoints(kernels: &[&'static KernelInfo], device: &Device) -> Result<()> {
    dispatch::prepare(device, kernels, Some(config::adstack_bytes()))
}

/// [`load`] for tiled kernels, launched with `block_dim` threads per block: on a GPU each
/// kernel's variant for that block size (`WP_TILE_BLOCK_DIM`) is compiled and loaded, and its
/// shared memory checked against the device. On the CPU, nothing.
///
/// # Errors
/// As [`load`]; [`Error::LaunchKind`] for a kernel that is not tiled;
/// [`Error::InvalidBlockDim`] for a block size a kernel does not take;
/// [`Error::SharedMemory`] for a kernel whose blocks need more shared memory than the GPU has.
pub fn load_tiled(
    kernels: &[&'static KernelInfo],
    block_dim: usize,
    device: &Device,
) -> Result<()> {
    for info in kernels {
        check_tiled_info(info, block_dim)?;
    }
    dispatch::prepare_tiled(device, kernels, block_dim)
}

/// [`check_kind`] for a kernel known by its info only ([`load_tiled`]).
fn check_tiled_info(info: &KernelInfo, block_dim: usize) -> Result<()> {
    let kernel = info.name;
    let Some(tile) = info.tile else {
        return Err(Error::LaunchKind {
            kernel,
            why: "an ordinary kernel (it uses no tiles) given to `load_tiled`: load it with \
                  `load`"
                .to_string(),
        });
    };
    let invalid = |why: String| Error::InvalidBlockDim {
        kernel,
        block_dim,
        why,
    };
    if block_dim == 0 {
        return Err(invalid("a block has at least one thread".to_string()));
    }
    if block_dim > MAX_BLOCK_DIM {
        return Err(invalid(format!(
            "a block has at most {MAX_BLOCK_DIM} threads"
        )));
    }
    match tile.width {
        Some(w) if w != block_dim => Err(invalid(format!(
            "`{kernel}` tiles per-thread values into width {w}: launch it with block_dim {w}, \
             not {block_dim}"
        ))),
        _ => Ok(()),
    }
}

/// Launches `kernel` over `dim` threads with `args` on `device`.
///
/// On the CPU the launch has finished when this returns. On a GPU it is queued on the calling
/// thread's current stream for the device (see [`crate::stream`]: the default stream unless a
/// `ScopedStream` is active); faults are then reported by the next synchronisation, or at
/// once in debug mode ([`config::set_debug`]).
///
/// `args` is the tuple of host arguments in parameter order: `&Array<T, N>` for arrays, values
/// for everything else. A thread's fault stops the launch and is returned as
/// [`Error::Fault`]; when several threads fault, which one is reported is unspecified, and
/// threads in other chunks may have run.
///
/// # Errors
/// [`Error::InvalidDim`], [`Error::TidMismatch`], [`Error::ShapeMismatch`],
/// [`Error::DeviceMismatch`], [`Error::Fault`], and [`Error::NoDevice`] for a CUDA device
/// (not built yet).
///
/// A generic kernel (`#[kernel] fn k<T: Float>(..)`) runs its instance for the arguments'
/// types: `launch(k, n, (&x_f64, 0.5), &dev)` runs `k<f64>`.
pub fn launch<'a, L, A>(kernel: L, dim: impl Into<Dim>, args: A, device: &Device) -> Result<()>
where
    L: Launchable<A>,
    L::Kernel: Kernel<Params: KernelParams<Args<'a> = A>>,
{
    let _ = kernel;
    launch_with::<L::Kernel>(dim.into(), None, args, device, |args, grid| {
        dispatch::launch::<L::Kernel>(device, args, grid)
    })
}

/// Launches the tiled kernel `kernel` (one that uses tiles) over `dim` blocks of `block_dim`
/// threads each, with `args` on `device`: Warp's `wp.launch_tiled`. `tid()` is the block's
/// index in `dim`; the threads of a block (its lanes) run the kernel together, sharing its
/// tiles. Otherwise as [`launch`].
///
/// On the CPU a block is one task, its lanes run in turn between the tile operations; on a GPU
/// a block is a CUDA block of `block_dim` threads, compiled for that block size (each block
/// size a variant, compiled at its first launch or by [`load_tiled`]).
///
/// # Errors
/// As [`launch`], and [`Error::LaunchKind`] for a kernel that uses no tiles,
/// [`Error::InvalidBlockDim`] for a `block_dim` of 0, above [`MAX_BLOCK_DIM`], or not the
/// width the kernel's tiles fix (`#[kernel(block_dim = N)]`), [`Error::TileFrame`] when a
/// block's tiles do not fit the CPU's stack, [`Error::SharedMemory`] when they do not fit a
/// GPU's shared memory.
pub fn launch_tiled<'a, L, A>(
    kernel: L,
    dim: impl Into<Dim>,
    args: A,
    block_dim: usize,
    device: &Device,
) -> Result<()>
where
    L: Launchable<A>,
    L::Kernel: Kernel<Params: KernelParams<Args<'a> = A>>,
{
    let _ = kernel;
    launch_with::<L::Kernel>(dim.into(), Some(block_dim), args, device, |args, grid| {
        dispatch::launch::<L::Kernel>(device, args, grid)
    })
}

/// Launches `kernel` on `stream` (a CUDA stream; see [`crate::stream`] for how streams are
/// ordered against array operations). Returns once the launch is queued; a fault is
/// reported by a later synchronisation ([`Stream::synchronize`], `to_vec`,
/// [`synchronize`]), or at once in debug mode.
///
/// # Errors
/// As [`launch`].
#[cfg(feature = "cuda")]
pub fn launch_on<'a, L, A>(kernel: L, dim: impl Into<Dim>, args: A, stream: &Stream) -> Result<()>
where
    L: Launchable<A>,
    L::Kernel: Kernel<Params: KernelParams<Args<'a> = A>>,
{
    let _ = kernel;
    launch_with::<L::Kernel>(dim.into(), None, args, stream.device(), |args, grid| {
        dispatch::launch_on::<L::Kernel>(stream, args, grid)
    })
}

/// [`launch_tiled`] on `stream` (a CUDA stream), as [`launch_on`].
///
/// # Errors
/// As [`launch_tiled`].
#[cfg(feature = "cuda")]
pub fn launch_tiled_on<'a, L, A>(
    kernel: L,
    dim: impl Into<Dim>,
    args: A,
    block_dim: usize,
    stream: &Stream,
) -> Result<()>
where
    L: Launchable<A>,
    L::Kernel: Kernel<Params: KernelParams<Args<'a> = A>>,
{
    let _ = kernel;
    launch_with::<L::Kernel>(
        dim.into(),
        Some(block_dim),
        args,
        stream.device(),
        |args, grid| dispatch::launch_on::<L::Kernel>(stream, args, grid),
    )
}

/// Runs `kernel`'s adjoint once over `dim` with `args` on `device` (Warp's
/// `wp.launch(adjoint=True)`): the adjoint a [`Tape`](crate::Tape)'s backward runs for the same
/// launch, without a tape and without running the forward first. The arrays of `args` that
/// carry gradients ([`Array::with_grad`](crate::Array::with_grad),
/// [`Array::with_grad_array`](crate::Array::with_grad_array)) receive them: input gradients
/// are added to, and the gradients of what the kernel stores are read and cleared, as in a
/// tape's backward (the adjoint of a store takes its output's gradient). The primal arrays
/// are read, never written: the adjoint replays the forward without its stores and atomics.
/// Nothing is recorded on a recording tape; inside a capture the adjoint is captured.
///
/// On the CPU the adjoint has finished when this returns; on a GPU it is queued on the calling
/// thread's current stream, as [`launch`] queues.
///
/// # Errors
/// As [`launch`], and [`Error::NotDifferentiable`] for a kernel without an adjoint;
/// [`Error::Fault`] from an adjoint thread (an adjoint stack overflow included).
pub fn launch_adjoint<'a, L, A>(
    kernel: L,
    dim: impl Into<Dim>,
    args: A,
    device: &Device,
) -> Result<()>
where
    L: Launchable<A>,
    L::Kernel: Kernel<Params: KernelParams<Args<'a> = A>>,
{
    let _ = kernel;
    adjoint_with::<L::Kernel>(dim.into(), None, &args, |args, grid, bytes| {
        dispatch::launch_adjoint::<L::Kernel>(device, args, grid, bytes)
    })
}

/// [`launch_adjoint`] queued on `stream` (a CUDA stream), as [`launch_on`] queues a launch.
///
/// # Errors
/// As [`launch_adjoint`].
#[cfg(feature = "cuda")]
pub fn launch_adjoint_on<'a, L, A>(
    kernel: L,
    dim: impl Into<Dim>,
    args: A,
    stream: &Stream,
) -> Result<()>
where
    L: Launchable<A>,
    L::Kernel: Kernel<Params: KernelParams<Args<'a> = A>>,
{
    let _ = kernel;
    adjoint_with::<L::Kernel>(dim.into(), None, &args, |args, grid, bytes| {
        dispatch::launch_adjoint_on::<L::Kernel>(stream, args, grid, bytes)
    })
}

/// Checks an adjoint launch of `K` (a tiled one with `block_dim: Some(threads per block)`) as
/// [`launch`] checks a launch, then has `run` run it with the process-wide adjoint stack size
/// (what a tape without its own setting runs with). Nothing is recorded on tapes.
pub(crate) fn adjoint_with<'a, K: Kernel>(
    dim: Dim,
    block_dim: Option<usize>,
    args: &ArgsOf<'a, K>,
    run: impl FnOnce(&ArgsOf<'a, K>, &Grid, usize) -> Result<()>,
) -> Result<()> {
    let grid = checked_grid::<K>(dim, block_dim)?;
    check_shapes::<K>(args, &grid)?;
    run(args, &grid, config::adstack_bytes())
}

/// A launch of `K` (its adjoint with `adjoint`) with owned arguments, on `stream` when given,
/// checked and recorded as [`launch`] does (the adjoint as [`launch_adjoint`]): the path of
/// kernel ops (`ops/exec.rs`), whose arguments are made as owned tuples.
#[cfg(feature = "ops")]
pub(crate) fn launch_owned<K: Kernel>(
    dim: Dim,
    block_dim: Option<usize>,
    args: &OwnedArgsOf<K>,
    device: &Device,
    #[cfg(feature = "cuda")] stream: Option<&Stream>,
    adjoint: bool,
) -> Result<()> {
    let args = K::Params::borrow(args);
    if adjoint {
        return adjoint_with::<K>(dim, block_dim, &args, |args, grid, bytes| {
            #[cfg(feature = "cuda")]
            if let Some(s) = stream {
                return dispatch::launch_adjoint_on::<K>(s, args, grid, bytes);
            }
            dispatch::launch_adjoint::<K>(device, args, grid, bytes)
        });
    }
    launch_with::<K>(dim, block_dim, args, device, |args, grid| {
        #[cfg(feature = "cuda")]
        if let Some(s) = stream {
            return dispatch::launch_on::<K>(s, args, grid);
        }
        dispatch::launch::<K>(device, args, grid)
    })
}

/// The owned launch arguments of kernel `K` (array handles and values), as a [`Launch`]
/// holds them: for `fn k(x: Array<f32>, dt: f32)`, `(Array<f32>, f32)`.
pub type OwnedArgsOf<K> = <<K as Kernel>::Params as KernelParams>::Owned;

/// A launch with its arguments bound once and queued again with one call (Warp's
/// `wp.Launch`, `record_cmd=True`), for host loops that cannot be captured into a
/// [`Graph`](crate::Graph).
///
/// [`Launch::new`] checks the launch as [`launch`] does and, on a GPU, compiles the kernel;
/// [`Launch::launch`] then skips the checks, the argument typing and the kernel lookup: it
/// converts the bound arguments and queues the kernel. To change an argument between launches,
/// assign it through [`Launch::args_mut`] (the next launch checks the arguments again) or keep
/// it in an array the kernel reads.
///
/// ```ignore
/// // (tests/suite/graph.rs runs this on every backend)
/// let mut step = wp::Launch::new(integrate, n, (&x, &v, dt), &dev)?;
/// for frame in 0..frames {
///     step.args_mut().2 = dt_of(frame); // a value: rechecked at the next launch
///     step.launch()?;
/// }
/// ```
///
/// A launch object records on a recording [`Tape`](crate::Tape) like a plain launch, and
/// inside a capture it is captured like one.
#[must_use = "a `Launch` runs nothing until `launch()` is called on it"]
pub struct Launch<K: Kernel> {
    device: Device,
    dim: Dim,
    /// The block size of a tiled launch ([`Launch::new_tiled`]); `None` for an ordinary one.
    block_dim: Option<usize>,
    grid: Grid,
    args: OwnedArgsOf<K>,
    /// `None` after [`Launch::args_mut`] or [`Launch::set_dim`]: checked again at the next
    /// launch.
    prepared: Option<dispatch::Prepared<K>>,
}

impl<K: Kernel> std::fmt::Debug for Launch<K> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Launch")
            .field("kernel", &K::INFO.name)
            .field("dim", &self.dim)
            .field("block_dim", &self.block_dim)
            .field("device", &self.device)
            .finish()
    }
}

impl<K: Kernel> Launch<K> {
    /// Binds a launch of `kernel` over `dim` with `args` on `device`, checked as [`launch`]
    /// checks it; on a GPU the kernel is compiled (or found) now.
    ///
    /// # Errors
    /// As [`launch`].
    pub fn new<'a, L, A>(kernel: L, dim: impl Into<Dim>, args: A, device: &Device) -> Result<Self>
    where
        L: Launchable<A, Kernel = K>,
        K: Kernel<Params: KernelParams<Args<'a> = A>>,
    {
        let _ = kernel;
        Self::bind(dim.into(), None, args, device)
    }

    /// Binds a tiled launch of `kernel` over `dim` blocks of `block_dim` threads, as
    /// [`launch_tiled`] checks it; on a GPU the kernel's variant for `block_dim` is compiled
    /// (or found) now.
    ///
    /// # Errors
    /// As [`launch_tiled`].
    pub fn new_tiled<'a, L, A>(
        kernel: L,
        dim: impl Into<Dim>,
        args: A,
        block_dim: usize,
        device: &Device,
    ) -> Result<Self>
    where
        L: Launchable<A, Kernel = K>,
        K: Kernel<Params: KernelParams<Args<'a> = A>>,
    {
        let _ = kernel;
        Self::bind(dim.into(), Some(block_dim), args, device)
    }

    fn bind(
        dim: Dim,
        block_dim: Option<usize>,
        args: ArgsOf<'_, K>,
        device: &Device,
    ) -> Result<Self> {
        let grid = checked_grid::<K>(dim, block_dim)?;
        check_shapes::<K>(&args, &grid)?;
        let prepared = dispatch::prepare_launch::<K>(device, &args, &grid)?;
        Ok(Launch {
            device: device.clone(),
            dim,
            block_dim,
            grid,
            args: K::Params::own(&args),
            prepared: Some(prepared),
        })
    }

    /// The bound arguments.
    pub fn args(&self) -> &OwnedArgsOf<K> {
        &self.args
    }

    /// The bound arguments, to change some: `step.args_mut().1 = 0.5`. The next launch
    /// checks them again (devices, shapes, contiguity).
    pub fn args_mut(&mut self) -> &mut OwnedArgsOf<K> {
        self.prepared = None;
        &mut self.args
    }

    /// Changes the launch dimensions (checked at the next launch; blocks, for a tiled launch).
    pub fn set_dim(&mut self, dim: impl Into<Dim>) {
        self.dim = dim.into();
        self.prepared = None;
    }

    /// The launch dimensions.
    pub fn dim(&self) -> Dim {
        self.dim
    }

    /// The device.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Launches with the bound arguments, as [`launch`] would (on a GPU, queued on the calling
    /// thread's current stream).
    ///
    /// # Errors
    /// As [`launch`]; the checks run again only after [`Launch::args_mut`] or
    /// [`Launch::set_dim`].
    pub fn launch(&mut self) -> Result<()> {
        self.launch_inner(
            #[cfg(feature = "cuda")]
            None,
        )
    }

    /// [`Launch::launch`] on `stream` (a CUDA stream of the launch's device).
    ///
    /// # Errors
    /// As [`launch_on`].
    #[cfg(feature = "cuda")]
    pub fn launch_on(&mut self, stream: &Stream) -> Result<()> {
        if stream.device() != &self.device {
            return Err(Error::invalid(format!(
                "kernel `{}`: a launch object bound to \"{}\" launched on a stream of \"{}\"",
                K::INFO.name,
                self.device,
                stream.device()
            )));
        }
        self.launch_inner(Some(stream))
    }

    fn launch_inner(&mut self, #[cfg(feature = "cuda")] stream: Option<&Stream>) -> Result<()> {
        let args = K::Params::borrow(&self.args);
        if self.prepared.is_none() {
            self.grid = checked_grid::<K>(self.dim, self.block_dim)?;
            check_shapes::<K>(&args, &self.grid)?;
            self.prepared = Some(dispatch::prepare_launch::<K>(
                &self.device,
                &args,
                &self.grid,
            )?);
        }
        let device = &self.device;
        if crate::capturing::capturing() || config::verify_fp() {
            // What a plain launch does around the backend's: a capture's record, the check.
            return launch_with::<K>(self.dim, self.block_dim, args, device, |args, grid| {
                #[cfg(feature = "cuda")]
                if let Some(s) = stream {
                    return dispatch::launch_on::<K>(s, args, grid);
                }
                dispatch::launch::<K>(device, args, grid)
            });
        }
        let prepared = self.prepared.as_ref().expect("prepared above");
        dispatch::launch_prepared::<K>(
            device,
            prepared,
            &args,
            &self.grid,
            #[cfg(feature = "cuda")]
            stream,
        )?;
        crate::tape::on_launch::<K>(&args, &self.grid, device)?;
        Ok(())
    }
}

/// Checks a launch of `K` on `device` (a tiled one with `block_dim: Some(threads per
/// block)`), has `run` run it (on the device's backend), then records
/// it on the recording tapes and, in `verify_fp` mode, checks what it wrote.
fn launch_with<'a, K: Kernel>(
    dim: Dim,
    block_dim: Option<usize>,
    args: ArgsOf<'a, K>,
    device: &Device,
    run: impl FnOnce(&ArgsOf<'a, K>, &Grid) -> Result<()>,
) -> Result<()> {
    let grid = checked_grid::<K>(dim, block_dim)?;
    check_shapes::<K>(&args, &grid)?;
    // (Inside a capture `dispatch` has the backend record the launch.)
    run(&args, &grid)?;
    crate::tape::on_launch::<K>(&args, &grid, device)?;
    // (Inside a capture the launch has not run: there is nothing to check yet.)
    if config::verify_fp() && !crate::capturing::capturing() {
        K::Params::check_finite(&args, K::info())?;
    }
    Ok(())
}

/// Waits for all outstanding work on every GPU used so far, and reports a fault that a kernel
/// recorded there since the last check. CPU launches finish before [`launch`] returns.
pub fn synchronize() -> Result<()> {
    dispatch::synchronize_all()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::array::Array;
    use crate::device::cpu;
    use crate::kernel::{CpuGradsOf, CpuParamsOf, KernelInfo, TileInfo};
    use std::ops::Range;

    use warp_core::{Fault, FaultKind, KResult};

    /// The parts of a hand-written test kernel that `#[kernel]` would generate from the
    /// signature: the facts (`name`, parameter names, `tid()` arity, `same_shape` groups) and
    /// an adjoint that does nothing.
    macro_rules! test_kernel {
        ($name:literal, [$($param:literal),*], $tid:expr, $same_shape:expr) => {
            test_kernel!($name, [$($param),*], $tid, $same_shape, None);
        };
        ($name:literal, [$($param:literal),*], $tid:expr, $same_shape:expr, $tile:expr) => {
            const INFO: KernelInfo = KernelInfo {
                name: $name,
                module: module_path!(),
                params: &[$($param),*],
                tid_ndim: Some($tid),
                same_shape: $same_shape,
                file: file!(),
                tile: $tile,
                ..KernelInfo::BLANK
            };
            fn info() -> &'static KernelInfo {
                &Self::INFO
            }
            fn run_cpu_adjoint(
                _: &CpuParamsOf<Self>,
                _: &CpuGradsOf<Self>,
                _: &Grid,
                _: Range<usize>,
                _: &mut warp_core::AdStack,
                _: bool,
            ) -> KResult<()> {
                Ok(())
            }
        };
    }

    /// `out[tid] = tid`, written by hand the way `#[kernel]` would generate it.
    #[derive(Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct write_flat;

    impl Kernel for write_flat {
        type Params = (Array<u64>,);
        test_kernel!("write_flat", ["out"], 1, &[&[0, usize::MAX]]);
        fn run_cpu(params: &CpuParamsOf<Self>, grid: &Grid, range: Range<usize>) -> KResult<()> {
            for flat in range {
                let [i] = grid.unflatten::<1>(flat);
                params.0.store(i, i as u64)?;
            }
            Ok(())
        }
    }

    /// `out[tid] = data[tid]`: faults for every thread past `data`'s end.
    #[derive(Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct oob;

    impl Kernel for oob {
        type Params = (Array<f32>, f32);
        test_kernel!("oob", ["data", "scale"], 1, &[]);
        fn run_cpu(params: &CpuParamsOf<Self>, grid: &Grid, range: Range<usize>) -> KResult<()> {
            for flat in range {
                let [i] = grid.unflatten::<1>(flat);
                let v = params.0.load(i)?;
                params.0.store(i, v * params.1)?;
            }
            Ok(())
        }
    }

    /// `out[i, j] = flat` over a 2-D grid.
    #[derive(Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct write_2d;

    impl Kernel for write_2d {
        type Params = (Array<u64, 2>,);
        test_kernel!("write_2d", ["out"], 2, &[]);
        fn run_cpu(params: &CpuParamsOf<Self>, grid: &Grid, range: Range<usize>) -> KResult<()> {
            for flat in range {
                let [i, j] = grid.unflatten::<2>(flat);
                params.0.store((i, j), flat as u64)?;
            }
            Ok(())
        }
    }

    /// The facts of a tiled test kernel: any width, a small CPU frame.
    const ANY_WIDTH: Option<TileInfo> = Some(TileInfo {
        width: None,
        shared_bytes: 256,
        adjoint_shared_bytes: 0,
        cpu_frame_bytes: 4096,
        pipe_extra_bytes: 0,
    });

    /// A tiled kernel by hand: `run_cpu` gets a range of blocks and adds the launch's
    /// `block_dim` to `out[block]`, so that each element says how often its block ran and with
    /// what block size.
    #[derive(Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct record_blocks;

    impl Kernel for record_blocks {
        type Params = (Array<u64>,);
        test_kernel!("record_blocks", ["out"], 1, &[], ANY_WIDTH);
        fn run_cpu(params: &CpuParamsOf<Self>, grid: &Grid, range: Range<usize>) -> KResult<()> {
            for b in range {
                let [i] = grid.unflatten::<1>(b);
                let v = params.0.load(i)?;
                params.0.store(i, v + grid.block_dim as u64)?;
            }
            Ok(())
        }
    }

    /// [`record_blocks`] over a 2-D grid of blocks: `out[i, j] += flat * 10_000 + block_dim`.
    #[derive(Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct record_blocks_2d;

    impl Kernel for record_blocks_2d {
        type Params = (Array<u64, 2>,);
        test_kernel!("record_blocks_2d", ["out"], 2, &[], ANY_WIDTH);
        fn run_cpu(params: &CpuParamsOf<Self>, grid: &Grid, range: Range<usize>) -> KResult<()> {
            for b in range {
                let [i, j] = grid.unflatten::<2>(b);
                let v = params.0.load((i, j))?;
                params
                    .0
                    .store((i, j), v + b as u64 * 10_000 + grid.block_dim as u64)?;
            }
            Ok(())
        }
    }

    /// A tiled kernel whose tiles fix the block size at 64 (`#[kernel(block_dim = 64)]`).
    #[derive(Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct width_64;

    impl Kernel for width_64 {
        type Params = (Array<u64>,);
        test_kernel!(
            "width_64",
            ["out"],
            1,
            &[],
            Some(TileInfo {
                width: Some(64),
                ..ANY_WIDTH.unwrap()
            })
        );
        fn run_cpu(params: &CpuParamsOf<Self>, grid: &Grid, range: Range<usize>) -> KResult<()> {
            record_blocks::run_cpu(params, grid, range)
        }
    }

    /// A tiled kernel whose blocks need 40 MiB of stack on the CPU.
    #[derive(Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct huge_frame;

    impl Kernel for huge_frame {
        type Params = (Array<u64>,);
        test_kernel!(
            "huge_frame",
            ["out"],
            1,
            &[],
            Some(TileInfo {
                cpu_frame_bytes: 40 << 20,
                ..ANY_WIDTH.unwrap()
            })
        );
        fn run_cpu(params: &CpuParamsOf<Self>, grid: &Grid, range: Range<usize>) -> KResult<()> {
            record_blocks::run_cpu(params, grid, range)
        }
    }

    #[test]
    fn every_block_of_a_tiled_launch_runs_once_with_its_block_dim() {
        let dev = cpu();
        // Serial (few blocks) and chunked; chunks shrink with the block size.
        for (blocks, bd) in [
            (1usize, 1usize),
            (7, 64),
            (5000, 1),
            (3000, 256),
            (100_003, 32),
            (3, 1024),
        ] {
            let out = Array::<u64>::zeros(blocks, &dev).unwrap();
            launch_tiled(record_blocks, blocks, (&out,), bd, &dev).unwrap();
            let v = out.to_vec().unwrap();
            assert!(v.iter().all(|&x| x == bd as u64), "{blocks} blocks of {bd}");
        }
    }

    #[test]
    fn a_two_d_grid_of_blocks_is_row_major() {
        let dev = cpu();
        for ((rows, cols), bd) in [((3usize, 5usize), 128usize), ((70, 130), 16)] {
            let out = Array::<u64, 2>::zeros((rows, cols), &dev).unwrap();
            launch_tiled(record_blocks_2d, (rows, cols), (&out,), bd, &dev).unwrap();
            let v = out.to_vec().unwrap();
            for (flat, &x) in v.iter().enumerate() {
                assert_eq!(x, flat as u64 * 10_000 + bd as u64, "{rows}x{cols}");
            }
        }
        // `tid()` arity against the block grid, as for `launch`.
        let out = Array::<u64>::zeros(4, &dev).unwrap();
        let err = launch_tiled(record_blocks, (2, 2), (&out,), 8, &dev).unwrap_err();
        assert!(matches!(err, Error::TidMismatch { .. }), "{err}");
    }

    #[test]
    fn tiled_and_ordinary_kernels_take_only_their_launch() {
        let dev = cpu();
        let out = Array::<u64>::zeros(4, &dev).unwrap();
        let err = launch(record_blocks, 4, (&out,), &dev).unwrap_err();
        assert!(
            matches!(
                err,
                Error::LaunchKind {
                    kernel: "record_blocks",
                    ..
                }
            ),
            "{err}"
        );
        assert_eq!(
            err.to_string(),
            "kernel `record_blocks`: a tiled kernel (it uses tiles) launched with `launch`: \
             launch it with `launch_tiled(record_blocks, blocks, args, block_dim, &device)` (dim \
             counts blocks)"
        );
        let err = launch_tiled(write_flat, 4, (&out,), 64, &dev).unwrap_err();
        assert!(
            matches!(
                err,
                Error::LaunchKind {
                    kernel: "write_flat",
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("launch it with `launch`"), "{err}");
        let err = Launch::new(record_blocks, 4, (&out,), &dev).unwrap_err();
        assert!(matches!(err, Error::LaunchKind { .. }), "{err}");
        let err = Launch::new_tiled(write_flat, 4, (&out,), 1, &dev).unwrap_err();
        assert!(matches!(err, Error::LaunchKind { .. }), "{err}");
        // Nothing ran.
        assert_eq!(out.to_vec().unwrap(), vec![0; 4]);
    }

    #[test]
    fn block_dim_is_checked() {
        let dev = cpu();
        let out = Array::<u64>::zeros(4, &dev).unwrap();
        for bd in [0usize, 1025, usize::MAX] {
            let err = launch_tiled(record_blocks, 4, (&out,), bd, &dev).unwrap_err();
            assert!(
                matches!(err, Error::InvalidBlockDim { kernel: "record_blocks", block_dim, .. } if block_dim == bd),
                "{err}"
            );
        }
        let err = launch_tiled(record_blocks, 4, (&out,), 0, &dev).unwrap_err();
        assert_eq!(
            err.to_string(),
            "kernel `record_blocks`: invalid block_dim 0: a block has at least one thread"
        );
        let err = launch_tiled(width_64, 4, (&out,), 128, &dev).unwrap_err();
        assert_eq!(
            err.to_string(),
            "kernel `width_64`: invalid block_dim 128: `width_64` tiles per-thread values into \
             width 64: launch it with block_dim 64, not 128"
        );
        assert_eq!(out.to_vec().unwrap(), vec![0; 4]);
        launch_tiled(width_64, 4, (&out,), 64, &dev).unwrap();
        assert_eq!(out.to_vec().unwrap(), vec![64; 4]);
        // `load_tiled` checks the same (and on the CPU compiles nothing).
        load_tiled(&[&record_blocks::INFO, &width_64::INFO], 64, &dev).unwrap();
        let err = load_tiled(&[&width_64::INFO], 32, &dev).unwrap_err();
        assert!(
            matches!(err, Error::InvalidBlockDim { block_dim: 32, .. }),
            "{err}"
        );
        let err = load_tiled(&[&write_flat::INFO], 32, &dev).unwrap_err();
        assert!(
            matches!(
                err,
                Error::LaunchKind {
                    kernel: "write_flat",
                    ..
                }
            ),
            "{err}"
        );
    }

    #[test]
    fn a_block_frame_past_the_stack_is_an_error() {
        let dev = cpu();
        let out = Array::<u64>::zeros(4, &dev).unwrap();
        let err = launch_tiled(huge_frame, 4, (&out,), 64, &dev).unwrap_err();
        assert_eq!(
            err,
            Error::TileFrame {
                kernel: "huge_frame",
                bytes: 40 << 20,
                limit: 32 << 20
            }
        );
        assert!(err.to_string().contains("41943040 bytes of stack"), "{err}");
        assert_eq!(out.to_vec().unwrap(), vec![0; 4]);
    }

    #[test]
    fn a_bound_tiled_launch_keeps_its_block_dim() {
        let dev = cpu();
        let out = Array::<u64>::zeros(6, &dev).unwrap();
        let mut l = Launch::new_tiled(record_blocks, 4, (&out,), 32, &dev).unwrap();
        l.launch().unwrap();
        l.set_dim(6);
        l.launch().unwrap();
        assert_eq!(out.to_vec().unwrap(), vec![64, 64, 64, 64, 32, 32]);
        let err = Launch::new_tiled(width_64, 4, (&out,), 16, &dev).unwrap_err();
        assert!(
            matches!(err, Error::InvalidBlockDim { block_dim: 16, .. }),
            "{err}"
        );
    }

    /// [`record_blocks`] with an adjoint that adds `1000 * block_dim` to `out[block]`: what its
    /// backward saw of the launch.
    #[derive(Clone, Copy)]
    #[allow(non_camel_case_types)]
    struct record_blocks_adjoint;

    impl Kernel for record_blocks_adjoint {
        type Params = (Array<u64>,);
        const INFO: KernelInfo = KernelInfo {
            name: "record_blocks_adjoint",
            params: &["out"],
            tid_ndim: Some(1),
            tile: ANY_WIDTH,
            ..KernelInfo::BLANK
        };
        fn info() -> &'static KernelInfo {
            &Self::INFO
        }
        fn run_cpu(params: &CpuParamsOf<Self>, grid: &Grid, range: Range<usize>) -> KResult<()> {
            record_blocks::run_cpu(params, grid, range)
        }
        fn run_cpu_adjoint(
            params: &CpuParamsOf<Self>,
            _: &CpuGradsOf<Self>,
            grid: &Grid,
            range: Range<usize>,
            _: &mut warp_core::AdStack,
            _: bool,
        ) -> KResult<()> {
            for b in range {
                let v = params.0.load(b)?;
                params.0.store(b, v + 1000 * grid.block_dim as u64)?;
            }
            Ok(())
        }
    }

    #[test]
    fn tapes_and_graphs_keep_a_tiled_launch_block_dim() {
        let dev = cpu();
        let out = Array::<u64>::zeros(5, &dev).unwrap();
        let tape = crate::Tape::new();
        {
            let _rec = tape.record();
            launch_tiled(record_blocks_adjoint, 5, (&out,), 16, &dev).unwrap();
        }
        assert_eq!(out.to_vec().unwrap(), vec![16; 5]);
        // The backward pass launches the adjoint over the same blocks of the same size.
        tape.backward_from_grads().unwrap();
        assert_eq!(out.to_vec().unwrap(), vec![16 + 16_000; 5]);

        // A captured tiled launch replays with its block size.
        let out = Array::<u64>::zeros(3, &dev).unwrap();
        let graph =
            crate::capture(&dev, || launch_tiled(record_blocks, 3, (&out,), 8, &dev)).unwrap();
        graph.launch().unwrap();
        graph.launch().unwrap();
        assert_eq!(out.to_vec().unwrap(), vec![16; 3]);
    }

    #[test]
    fn every_thread_runs_once() {
        let dev = cpu();
        for n in [1usize, 4095, 4096, 4097, 100_003] {
            let out = Array::<u64>::full(n, u64::MAX, &dev).unwrap();
            launch(write_flat, n, (&out,), &dev).unwrap();
            let v = out.to_vec().unwrap();
            assert!(v.iter().enumerate().all(|(i, &x)| x == i as u64), "n = {n}");
        }
    }

    #[test]
    fn fault_names_kernel_arg_index_shape() {
        let dev = cpu();
        // Serial path (small) and parallel path (large).
        for n in [10usize, 50_000] {
            let data = Array::<f32>::full(n, 1.0, &dev).unwrap();
            let err = launch(oob, n + 1, (&data, 2.0), &dev).unwrap_err();
            // The fault names the launch: the calling thread's latest.
            let id = crate::last_launch_id().expect("a launch was made");
            assert_eq!(
                err,
                Error::Fault(Fault {
                    kernel: "oob",
                    kind: FaultKind::OutOfBounds {
                        arg: "data",
                        index: vec![n as i128],
                        shape: vec![n]
                    },
                    launch: Some(id),
                })
            );
            assert_eq!(
                err.to_string(),
                format!(
                    "kernel `oob`: index [{n}] is out of bounds for argument `data` of shape \
                     [{n}] ({id})"
                )
            );
        }
        // Without the extra thread the kernel runs cleanly.
        let data = Array::<f32>::full(5, 1.5, &dev).unwrap();
        launch(oob, 5, (&data, 2.0), &dev).unwrap();
        assert_eq!(data.to_vec().unwrap(), vec![3.0; 5]);
    }

    #[test]
    fn two_d_launch_is_row_major() {
        let dev = cpu();
        for (rows, cols) in [(3usize, 5usize), (70, 130)] {
            let out = Array::<u64, 2>::zeros((rows, cols), &dev).unwrap();
            launch(write_2d, (rows, cols), (&out,), &dev).unwrap();
            let v = out.to_vec().unwrap();
            for i in 0..rows {
                for j in 0..cols {
                    assert_eq!(v[i * cols + j], (i * cols + j) as u64);
                }
            }
        }
    }

    #[test]
    fn dim_validation() {
        let dev = cpu();
        let out = Array::<u64>::zeros(4, &dev).unwrap();
        let err = launch(write_flat, 0, (&out,), &dev).unwrap_err();
        assert_eq!(
            err.to_string(),
            "kernel `write_flat`: invalid launch dim [0]: a launch dim of zero (dimension 0)"
        );
        let err = launch(write_flat, [0], (&out,), &dev).unwrap_err();
        assert!(matches!(
            err,
            Error::InvalidDim {
                kernel: "write_flat",
                ..
            }
        ));
        let err = launch(write_flat, i32::MAX as usize + 1, (&out,), &dev).unwrap_err();
        assert!(err.to_string().contains("exceeds i32::MAX"), "{err}");
        let huge = i32::MAX as usize;
        let err = grid_of("k", Dim::from([huge, huge, huge, huge])).unwrap_err();
        assert!(err.to_string().contains("overflows"), "{err}");
        let g = grid_of("k", Dim::from((2, 3, 4))).unwrap();
        assert_eq!(
            g,
            Grid {
                dims: [2, 3, 4, 1],
                ndim: 3,
                total: 24,
                block_dim: 1
            }
        );
        assert_eq!(Dim::from([1, 2, 3, 4]).as_slice(), &[1, 2, 3, 4]);
        assert_eq!(Dim::from((5, 6, 7, 8)).ndim(), 4);
        assert_eq!(Dim::from(7), Dim::from([7]));
    }

    #[test]
    fn tid_and_shape_checks() {
        let dev = cpu();
        let out = Array::<u64>::zeros(4, &dev).unwrap();
        let err = launch(write_flat, (2, 2), (&out,), &dev).unwrap_err();
        assert_eq!(
            err.to_string(),
            "kernel `write_flat`: tid() is destructured into 1 dimension(s) but the kernel was \
             launched with 2 dimension(s)"
        );
        let err = launch(write_flat, 5, (&out,), &dev).unwrap_err();
        assert_eq!(
            err,
            Error::ShapeMismatch {
                kernel: "write_flat",
                args: vec!["out".into(), "dim".into()],
                shapes: vec![vec![4], vec![5]],
            }
        );
    }

    #[test]
    fn cuda_launch_of_cpu_arrays_is_refused() {
        let dev = cpu();
        let out = Array::<u64>::zeros(4, &dev).unwrap();
        // The arguments are checked before anything touches a GPU: the CPU array is on the
        // wrong device (or, without the `cuda` feature, there is no CUDA). Never a launch.
        let err = launch(write_flat, 4, (&out,), &crate::device::Device::fake_cuda(0)).unwrap_err();
        assert!(err.to_string().contains("cuda:0"), "{err}");
        synchronize().unwrap();
    }
}

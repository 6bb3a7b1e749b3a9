//! [`HostObject`]: the one seam between a kernel-visible host object and kernel launches.
//!
//! A host object (a hash grid, a BVH, a mesh, a volume) owns buffers on one device and is
//! passed to kernels by reference (`wp::launch(k, dim, (&grid, &x))`). Everything a launch,
//! an adjoint launch and a [`Tape`](crate::Tape) do with such an argument is the same for
//! every object: refuse it on another device, pass no separate gradient, keep a clone for
//! replay. So [`KernelArg`] is implemented once, here, for every [`HostObject`], and an object
//! writes only what is its own: its device, its CPU view and its CUDA record.
//!
//! The kernel macro knows an object by its row in `warp-macros`' object table (the parameter
//! type's name, the view's name under `warp_core::objects`, the C++ type, the CUDA section);
//! [`HostObject::View`] must be that view and [`HostObject::Cuda`] laid out as that C++ type.
//! The suite's `host_objects` test holds every row to an implementation.

use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::{ArgCtx, KernelArg};

/// A host object that kernels take as a parameter (`grid: HashGrid`, `v: Volume<f32>`).
///
/// Implementing it makes the type a [`KernelArg`]: the host passes `&Self`, a launch on
/// another device than [`HostObject::device`] is an error naming the kernel and argument
/// (checked before either conversion runs), the object carries no gradient argument (a
/// gradient it has travels inside its view, as a volume's does), and a tape keeps a clone.
///
/// # Clones
/// A clone must share the object's buffers and keep them as they are: an object rebuilt
/// after a launch was recorded gets fresh buffers (copy-on-write), so that the recorded
/// launch replays against the object as it was.
pub trait HostObject: Clone + Send + Sync + 'static {
    /// What a kernel thread sees on the CPU: the object's view in `warp_core::objects`
    /// (`HashGridView`), named by its row in the kernel macro's object table.
    type View: Copy + Send + Sync;
    /// What a CUDA kernel receives: a `#[repr(C)]` record laid out as the C++ type of the
    /// object's row (`wp::hash_grid_t`), size asserted on both sides.
    type Cuda: Copy;

    /// The device the object's buffers live on: launches on any other are refused.
    fn device(&self) -> &Device;

    /// The CPU view for a launch described by `ctx` (already on [`HostObject::device`]),
    /// after the object's own launch checks (built, sizes unchanged), which name `ctx`'s
    /// kernel and argument when they fail.
    ///
    /// # Safety
    /// As [`KernelArg::cpu_view`]: the view borrows the object's buffers without a lifetime
    /// and must not be used after the object is gone.
    unsafe fn cpu_view(&self, ctx: &ArgCtx<'_>) -> Result<Self::View>;

    /// The CUDA record for a launch described by `ctx` (already on
    /// [`HostObject::device`]), after the same checks as [`HostObject::cpu_view`];
    /// `ctx.index` is the parameter index its out-of-bounds faults report.
    fn cuda_record(&self, ctx: &ArgCtx<'_>) -> Result<Self::Cuda>;

    /// Zeroes a gradient the object carries (a volume's gradient grid); nothing by default.
    fn zero_grad(&self) -> Result<()> {
        Ok(())
    }

    /// Called when a launch recorded into the calling thread's capture takes the object,
    /// before the graph keeps a clone of it: an object whose builds or refits a capture
    /// records in place (a hash grid, a BVH, a mesh) makes its buffers the capture's, so that
    /// the capture may rebuild it after such a launch. Nothing by default.
    #[doc(hidden)]
    fn adopt_in_capture(&self) {}
}

/// The launch device check every object shares.
fn check_device(object: &Device, ctx: &ArgCtx<'_>) -> Result<()> {
    if object != ctx.device {
        return Err(Error::DeviceMismatch {
            kernel: ctx.kernel,
            arg: ctx.arg,
            expected: ctx.device.alias().to_string(),
            found: object.alias().to_string(),
        });
    }
    Ok(())
}

impl<O: HostObject> KernelArg for O {
    type Arg<'a> = &'a O;
    type CpuView = O::View;

    unsafe fn cpu_view(arg: &Self::Arg<'_>, ctx: &ArgCtx<'_>) -> Result<O::View> {
        check_device(arg.device(), ctx)?;
        // SAFETY: the caller's contract, passed on.
        unsafe { HostObject::cpu_view(*arg, ctx) }
    }

    type CudaArg = O::Cuda;

    fn cuda_arg(arg: &Self::Arg<'_>, ctx: &ArgCtx<'_>) -> Result<O::Cuda> {
        check_device(arg.device(), ctx)?;
        arg.cuda_record(ctx)
    }

    // An object's gradient, where it has one, travels in its view (the adjoints add into it
    // at the offsets they read): there is no separate gradient argument.
    type GradView = ();

    unsafe fn grad_view(_: &Self::Arg<'_>, _: &ArgCtx<'_>) -> Result<()> {
        Ok(())
    }

    type CudaGrad = ();

    fn cuda_grad(_: &Self::Arg<'_>, _: &ArgCtx<'_>) -> Result<()> {
        Ok(())
    }

    /// A clone sharing the buffers: the tape replays against the object as it was.
    type Owned = O;

    fn own(arg: &Self::Arg<'_>) -> O {
        if crate::capturing::capturing() {
            arg.adopt_in_capture();
        }
        (*arg).clone()
    }

    fn borrow(owned: &O) -> &O {
        owned
    }

    fn zero_grad(arg: &Self::Arg<'_>) -> Result<()> {
        HostObject::zero_grad(*arg)
    }
}

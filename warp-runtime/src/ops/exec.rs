//! Running an op on a call's buffers: where its launches go ([`Exec`]), and the forward and
//! backward of a kernel op.

use super::args::{CallArg, OpArgs};
use super::buffer::Buffer;
use super::shape::{LaunchDims, Shape, Shapes};
use super::spec::{ArgKind, OpSpec, Role};
#[cfg(feature = "cuda")]
use crate::cuda::stream::Stream;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::kernel::Kernel;
use crate::launch::{Dim, OwnedArgsOf};
use std::marker::PhantomData;

/// Where an op call's launches go: the CPU (done when the call returns), or a CUDA stream,
/// normally the framework's wrapped by
/// [`Stream::from_raw_caller_ordered`](crate::Stream::from_raw_caller_ordered) (a kernel op's
/// launches are then one `cuLaunchKernel` each, capturable by the framework).
#[derive(Clone, Debug)]
pub struct Exec<'s> {
    device: Device,
    #[cfg(feature = "cuda")]
    stream: Option<&'s Stream>,
    _stream: PhantomData<&'s ()>,
}

impl Exec<'static> {
    /// Launches on the CPU.
    pub fn cpu() -> Exec<'static> {
        Exec {
            device: crate::device::cpu(),
            #[cfg(feature = "cuda")]
            stream: None,
            _stream: PhantomData,
        }
    }
}

impl<'s> Exec<'s> {
    /// Launches queued on `stream`, on its device.
    #[cfg(feature = "cuda")]
    pub fn stream(stream: &'s Stream) -> Exec<'s> {
        Exec {
            device: stream.device().clone(),
            stream: Some(stream),
            _stream: PhantomData,
        }
    }

    /// The stream, if the launches go to one.
    #[cfg(feature = "cuda")]
    pub(crate) fn stream_of(&self) -> Option<&'s Stream> {
        self.stream
    }

    /// The device the call's buffers are on.
    pub fn device(&self) -> &Device {
        &self.device
    }
}

/// Launch dimensions as a [`Dim`] (1 to 4 extents, checked by [`LaunchDims::eval`]).
fn dim_of(v: &[usize]) -> Dim {
    match *v {
        [a] => Dim::from(a),
        [a, b] => Dim::from([a, b]),
        [a, b, c] => Dim::from([a, b, c]),
        [a, b, c, d] => Dim::from([a, b, c, d]),
        _ => unreachable!("LaunchDims::eval gives 1 to 4 extents"),
    }
}

/// The type-erased side of an op (kernel or computation): what the registry holds.
pub(crate) trait ErasedOp: Send + Sync {
    /// Whether this is a computation op (its backward replays the body on fresh outputs and
    /// scratch) rather than a kernel op (its backward reads the forward's outputs).
    fn is_computation(&self) -> bool {
        false
    }

    /// The launch dimensions and each output's leading shape (in parameter order) for a
    /// call's inputs and values.
    fn shapes(&self, spec: &OpSpec, args: &[CallArg<'_>]) -> Result<(Vec<usize>, Vec<Vec<usize>>)>;

    /// Compiles and loads what a call on `device` launches (a kernel op: its kernel and
    /// adjoint), so that no call compiles. A computation op's body is opaque: nothing.
    fn prepare(&self, device: &crate::device::Device) -> Result<()> {
        let _ = device;
        Ok(())
    }

    /// Runs the forward on the call's arguments (checked against `spec` by the caller).
    ///
    /// # Safety
    /// Every buffer is valid memory of `exec`'s device for the call (buffer.rs).
    unsafe fn forward(&self, spec: &OpSpec, args: &[CallArg<'_>], exec: &Exec<'_>) -> Result<()>;

    /// Runs the backward with gradient memory `grads` (per parameter).
    ///
    /// # Safety
    /// As [`forward`](Self::forward), for `grads` too.
    unsafe fn backward(
        &self,
        spec: &OpSpec,
        args: &[CallArg<'_>],
        grads: &[Option<&Buffer>],
        exec: &Exec<'_>,
    ) -> Result<()>;
}

/// A kernel op's runtime half: the rules, and the kernel as a type.
pub(crate) struct KernelRunner<K: Kernel> {
    /// The launch dimensions' rule.
    pub(crate) dims: LaunchDims,
    /// Each output's shape rule (by parameter position).
    pub(crate) shapes: Vec<(usize, Shape)>,
    /// A tiled kernel's threads per block.
    pub(crate) block_dim: Option<usize>,
    pub(crate) _kernel: PhantomData<fn() -> K>,
}

impl<K: Kernel> KernelRunner<K>
where
    OwnedArgsOf<K>: OpArgs,
{
    /// The call's launch dimensions, after checking every output buffer against its shape.
    fn checked_dims(&self, spec: &OpSpec, args: &[CallArg<'_>]) -> Result<Vec<usize>> {
        let (dims, outs) = self.shapes(spec, args)?;
        let shaped: Vec<(usize, Vec<usize>)> =
            self.shapes.iter().map(|(k, _)| *k).zip(outs).collect();
        check_outputs(spec, args, &shaped)?;
        Ok(dims)
    }

    /// Runs the kernel (or its adjoint) on `args` with gradient memory `grads`.
    ///
    /// # Safety
    /// As [`ErasedOp::forward`].
    unsafe fn run(
        &self,
        spec: &OpSpec,
        args: &[CallArg<'_>],
        grads: &[Option<&Buffer>],
        exec: &Exec<'_>,
        adjoint: bool,
    ) -> Result<()> {
        let dims = self.checked_dims(spec, args)?;
        let names: Vec<&str> = spec.params.iter().map(|p| p.name).collect();
        // SAFETY: forwarded contract; the arrays drop before this returns.
        let owned = unsafe {
            <OwnedArgsOf<K> as OpArgs>::from_call(args, grads, &exec.device, &spec.name, &names)?
        };
        // The call's arrays are over memory that lives only for the call: a tape recording
        // on this thread must not keep them.
        let _paused = crate::tape::pause_recording();
        crate::launch::launch_owned::<K>(
            dim_of(&dims),
            self.block_dim,
            &owned,
            &exec.device,
            #[cfg(feature = "cuda")]
            exec.stream,
            adjoint,
        )
    }
}

impl<K: Kernel> ErasedOp for KernelRunner<K>
where
    OwnedArgsOf<K>: OpArgs,
{
    fn prepare(&self, device: &crate::device::Device) -> Result<()> {
        match self.block_dim {
            Some(b) if K::info().tile.is_some() => {
                crate::launch::load_tiled(&[K::info()], b, device)
            }
            _ => crate::launch::load_with_adjoints(&[K::info()], device),
        }
    }

    fn shapes(&self, spec: &OpSpec, args: &[CallArg<'_>]) -> Result<(Vec<usize>, Vec<Vec<usize>>)> {
        let shapes = Shapes::of_call(spec, args);
        let dims = self.dims.eval(&shapes)?;
        let outs = self
            .shapes
            .iter()
            .map(|(_, rule)| rule.eval(&shapes, &dims))
            .collect::<Result<Vec<_>>>()?;
        Ok((dims, outs))
    }

    unsafe fn forward(&self, spec: &OpSpec, args: &[CallArg<'_>], exec: &Exec<'_>) -> Result<()> {
        let none = vec![None; args.len()];
        // SAFETY: forwarded contract.
        unsafe { self.run(spec, args, &none, exec, false) }
    }

    unsafe fn backward(
        &self,
        spec: &OpSpec,
        args: &[CallArg<'_>],
        grads: &[Option<&Buffer>],
        exec: &Exec<'_>,
    ) -> Result<()> {
        check_grads(spec, grads)?;
        // SAFETY: forwarded contract.
        unsafe { self.run(spec, args, grads, exec, true) }
    }
}

/// Checks each output (and scratch) buffer `(position, leading shape)` against its rule's
/// shape.
pub(crate) fn check_outputs(
    spec: &OpSpec,
    args: &[CallArg<'_>],
    shaped: &[(usize, Vec<usize>)],
) -> Result<()> {
    for (k, want) in shaped {
        let rank = match spec.params[*k].kind {
            ArgKind::Array { rank, .. } => rank,
            ArgKind::Value { .. } => 0,
        };
        if let CallArg::Buffer(b) = &args[*k] {
            if b.dims.len() < rank || b.dims[..rank] != want[..] {
                return Err(Error::invalid(format!(
                    "{}: output '{}': a buffer of shape {:?}; its shape rule gives {:?} (then \
                     the element's trailing axes)",
                    spec.name, spec.params[*k].name, b.dims, want
                )));
            }
        }
    }
    Ok(())
}

/// Refuses a gradient given for a parameter that has none (an integer array, a scalar): the
/// one check both op tiers' backward make before anything runs.
pub(crate) fn check_grads(spec: &OpSpec, grads: &[Option<&Buffer>]) -> Result<()> {
    for (p, g) in spec.params.iter().zip(grads) {
        if g.is_some() && !p.differentiable {
            return Err(Error::invalid(format!(
                "{}: argument '{}' ({}) has no gradient, and one was given",
                spec.name,
                p.name,
                p.kind.describe()
            )));
        }
    }
    Ok(())
}

/// Checks a call's argument count and that every array parameter got a buffer and every
/// scalar a value (the per-type checks follow when the arguments are made).
pub(crate) fn check_call(spec: &OpSpec, args: &[CallArg<'_>], what: &str) -> Result<()> {
    if args.len() != spec.params.len() {
        return Err(Error::invalid(format!(
            "{}: {what} with {} arguments; the op takes {} ({})",
            spec.name,
            args.len(),
            spec.params.len(),
            spec.params
                .iter()
                .map(|p| p.name)
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    for (k, (p, a)) in spec.params.iter().zip(args).enumerate() {
        // A scalar value comes as one value, a vector's or matrix's as its components.
        let ok = match (p.role, a) {
            (Role::Scalar, CallArg::Value(_)) => p.kind.is_scalar_value(),
            (Role::Scalar, CallArg::Values(_)) => !p.kind.is_scalar_value(),
            (Role::Input | Role::Output | Role::Scratch, CallArg::Buffer(_)) => true,
            _ => false,
        };
        if !ok {
            let given = a.describe();
            return Err(Error::invalid(format!(
                "{}: argument '{}' ({k}): {given}; the kernel takes {}",
                spec.name,
                p.name,
                p.kind.describe()
            )));
        }
    }
    Ok(())
}

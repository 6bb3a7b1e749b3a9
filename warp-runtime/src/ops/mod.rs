//! Kernels as framework ops (issue 36; the `ops` feature): the pure-Rust half that the
//! PyTorch and JAX glue calls once a call's tensors are addresses. An [`Op`] is built once
//! from a kernel ([`Op::kernel`]); its parameter types come from the kernel's owned argument
//! tuple ([`OpArgs`]), so dtypes, ranks and trailing axes are checked with no annotation.
//! A call hands it [`Buffer`]s and [`Value`]s in the kernel's parameter order and an
//! [`Exec`] (the CPU, or the caller's CUDA stream); the framework allocates every buffer
//! (outputs zeroed unless [`Init::Uninit`], gradients zeroed), this crate only launches.
//!
//! - **Forward**: the kernel, once, over the launch dimensions ([`LaunchDims`], by default the
//!   first input array's shape), after each output buffer is checked against its
//!   [`Shape`] rule.
//! - **Backward**: the kernel's adjoint ([`launch_adjoint`](crate::launch_adjoint)) on the
//!   saved inputs and outputs, with the framework's gradient memory attached to them
//!   ([`Array::with_grad_array`](crate::Array::with_grad_array)): input gradients are added
//!   to, output gradients are read and cleared. No tape and no second forward.
//!
//! A computation op ([`Op::computation`]) runs a Rust body that may launch any kernels on
//! declared arrays; its backward replays the body under a tape inside the backward call.
//!
//! Ops registered with [`register`] get a process-wide id that a native dispatcher (the XLA
//! handler) finds them by without a lock on a Python object.

mod args;
mod batch;
mod buffer;
mod computation;
mod exec;
mod shape;
mod spec;
pub mod xla_ffi;

#[cfg(feature = "python")]
pub(crate) use args::Given;
pub use args::{CallArg, OpArg, OpArgs};
pub use batch::Vmap;
pub use buffer::Buffer;
pub use computation::{ComputationOp, Ctx};
pub use exec::Exec;
pub use shape::{LaunchDims, Shape, ShapeFn, Shapes};
pub use spec::{ArgKind, Dtype, OpElement, OpScalar, OpSpec, OpValue, ParamSpec, Role, Value};

use crate::error::{Error, Result};
use crate::kernel::Kernel;
use crate::launch::OwnedArgsOf;
use exec::{ErasedOp, KernelRunner};
use std::marker::PhantomData;
use std::sync::{Arc, RwLock};

/// Whether the framework zero-fills an output before the forward.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Init {
    /// Zeroed (the default): kernels may `atomic_add` into the output.
    Zero,
    /// Left as allocated: for kernels that write every element.
    Uninit,
}

/// An op: a spec and what runs it. Cheap to clone (shared).
#[derive(Clone)]
pub struct Op {
    inner: Arc<OpInner>,
}

struct OpInner {
    spec: OpSpec,
    run: Box<dyn ErasedOp>,
    /// How a batched call runs.
    vmap: Vmap,
}

impl std::fmt::Debug for Op {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Op")
            .field("spec", &self.inner.spec)
            .finish()
    }
}

impl Op {
    /// A kernel op named `name`: `kernel`'s forward, and its adjoint as the backward. Name
    /// its outputs with [`KernelOp::outputs`]; every other array parameter is an input and
    /// every value parameter a static scalar. A generic kernel is given as one instance:
    /// [`Op::instance`].
    pub fn kernel<K: Kernel>(name: &str, kernel: K) -> KernelOp<K>
    where
        OwnedArgsOf<K>: OpArgs,
    {
        let _ = kernel;
        KernelOp {
            name: name.to_string(),
            outputs: Vec::new(),
            shapes: Vec::new(),
            dims: None,
            uninit: Vec::new(),
            block_dim: None,
            vmap: Vmap::Loop,
            _kernel: PhantomData,
        }
    }

    /// [`Op::kernel`] for the instance of the generic kernel `generic` whose owned arguments
    /// are `A` (`Op::instance::<_, (Array<f64>, f64, Array<f64>)>("axpy64", axpy)`): a generic
    /// kernel's instances are picked by their arguments' types, as a launch picks them.
    pub fn instance<G, A>(name: &str, generic: G) -> KernelOp<<G as InstanceOf<A>>::Kernel>
    where
        G: InstanceOf<A>,
        A: OpArgs + crate::kernel::KernelParams,
        OwnedArgsOf<<G as InstanceOf<A>>::Kernel>: OpArgs,
    {
        let _ = generic;
        KernelOp {
            name: name.to_string(),
            outputs: Vec::new(),
            shapes: Vec::new(),
            dims: None,
            uninit: Vec::new(),
            block_dim: None,
            vmap: Vmap::Loop,
            _kernel: PhantomData,
        }
    }

    /// The op's name.
    pub fn name(&self) -> &str {
        &self.inner.spec.name
    }

    /// What it takes.
    pub fn spec(&self) -> &OpSpec {
        &self.inner.spec
    }

    /// Whether this is a computation op ([`Op::computation`]): its backward takes fresh
    /// outputs and scratch (the body is replayed), where a kernel op's takes the forward's
    /// outputs.
    pub fn is_computation(&self) -> bool {
        self.inner.run.is_computation()
    }

    /// Readies the op for calls on `device` that must not compile, allocate or load anything,
    /// as inside another library's stream capture (XLA's command buffers, a torch CUDA graph):
    /// a kernel op's kernel and adjoint are compiled and loaded, and on a GPU `threads` spare
    /// fault records are made, one per thread whose first launch may fall inside a capture.
    /// A computation op's body is opaque: only the records.
    ///
    /// # Errors
    /// A kernel that does not compile; [`Error::NoDevice`].
    pub fn prepare(&self, device: &crate::device::Device, threads: usize) -> crate::Result<()> {
        self.inner.run.prepare(device)?;
        #[cfg(feature = "cuda")]
        crate::cuda::reserve_fault_records(device, threads)?;
        #[cfg(not(feature = "cuda"))]
        let _ = threads;
        Ok(())
    }

    /// How a batched call runs ([`forward_batched`](Self::forward_batched)).
    pub fn vmap(&self) -> Vmap {
        self.inner.vmap
    }

    /// The launch dimensions and each output's leading shape (in parameter order) for a call
    /// whose inputs and values are `args` (outputs may be [`CallArg::Absent`]): what a
    /// framework allocates the outputs by.
    ///
    /// # Errors
    /// A rule's error, or a rule naming what the op lacks.
    pub fn shapes(&self, args: &[CallArg<'_>]) -> Result<(Vec<usize>, Vec<Vec<usize>>)> {
        let spec = &self.inner.spec;
        if args.len() != spec.params.len() {
            exec::check_call(spec, args, "shapes asked")?;
        }
        self.inner.run.shapes(spec, args)
    }

    /// Runs the forward: `args` in the kernel's parameter order (a [`Buffer`] for each array,
    /// outputs included; a [`Value`] for each scalar), launched as `exec` says. On the CPU
    /// the work has finished when this returns; on a stream it is queued.
    ///
    /// # Safety
    /// Every buffer addresses memory of `exec`'s device, valid for reads and writes of its
    /// layout until the launch has finished (on a stream: until the stream's work up to now
    /// has run), and not used by other work meanwhile except as the stream orders it.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the op, the parameter and what was given against what
    /// the kernel takes; a launch's errors ([`crate::launch()`]).
    pub unsafe fn forward(&self, args: &[CallArg<'_>], exec: &Exec<'_>) -> Result<()> {
        let spec = &self.inner.spec;
        exec::check_call(spec, args, "called")?;
        // SAFETY: forwarded contract.
        unsafe { self.inner.run.forward(spec, args, exec) }
    }

    /// Runs the backward: `args` as for [`forward`](Self::forward) (the forward's inputs and
    /// its outputs' values), and `grads[k]` the gradient memory of parameter `k`, if any: for
    /// an input, zeroed memory that receives its gradient; for an output, the gradient the
    /// framework hands back, which is read and cleared (pass a copy the caller may lose).
    ///
    /// # Safety
    /// As [`forward`](Self::forward), for the gradient buffers too.
    ///
    /// # Errors
    /// As [`forward`](Self::forward); a gradient for a parameter that has none;
    /// [`Error::NotDifferentiable`] for a kernel without an adjoint.
    pub unsafe fn backward(
        &self,
        args: &[CallArg<'_>],
        grads: &[Option<&Buffer>],
        exec: &Exec<'_>,
    ) -> Result<()> {
        let spec = &self.inner.spec;
        exec::check_call(spec, args, "called backward")?;
        if grads.len() != spec.params.len() {
            return Err(Error::invalid(format!(
                "{}: backward with {} gradient slots; the op has {} parameters",
                spec.name,
                grads.len(),
                spec.params.len()
            )));
        }
        // SAFETY: forwarded contract.
        unsafe { self.inner.run.backward(spec, args, grads, exec) }
    }
}

/// A generic kernel's instance for owned arguments `A` (what [`Op::instance`] names): the
/// instance that a launch with `A`'s borrowed arguments runs.
pub trait InstanceOf<A>: Copy {
    /// The instance.
    type Kernel: Kernel;
}

impl<G, A> InstanceOf<A> for G
where
    A: crate::kernel::KernelParams,
    G: crate::kernel::Launchable<<A as crate::kernel::KernelParams>::Args<'static>>,
{
    type Kernel =
        <G as crate::kernel::Launchable<<A as crate::kernel::KernelParams>::Args<'static>>>::Kernel;
}

/// The builder of a kernel op ([`Op::kernel`]).
#[must_use = "a KernelOp is an op only after build()"]
pub struct KernelOp<K: Kernel> {
    name: String,
    outputs: Vec<&'static str>,
    shapes: Vec<(&'static str, Shape)>,
    dims: Option<LaunchDims>,
    uninit: Vec<&'static str>,
    block_dim: Option<usize>,
    vmap: Vmap,
    _kernel: PhantomData<fn() -> K>,
}

impl<K: Kernel> std::fmt::Debug for KernelOp<K> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KernelOp")
            .field("name", &self.name)
            .field("kernel", &K::INFO.name)
            .field("outputs", &self.outputs)
            .field("shapes", &self.shapes)
            .field("dims", &self.dims)
            .field("uninit", &self.uninit)
            .field("block_dim", &self.block_dim)
            .field("vmap", &self.vmap)
            .finish()
    }
}

impl<K: Kernel> KernelOp<K>
where
    OwnedArgsOf<K>: OpArgs,
{
    /// The array parameters the kernel writes: the op's outputs (allocated by the framework).
    pub fn outputs<const M: usize>(mut self, names: [&'static str; M]) -> Self {
        self.outputs.extend(names);
        self
    }

    /// The leading shape of output `output` (default [`Shape::Dims`]: the launch dimensions).
    pub fn shape(mut self, output: &'static str, rule: Shape) -> Self {
        self.shapes.push((output, rule));
        self
    }

    /// The launch dimensions (default: the first input array's shape).
    pub fn dims(mut self, rule: LaunchDims) -> Self {
        self.dims = Some(rule);
        self
    }

    /// Whether output `output` is zeroed before the forward (default [`Init::Zero`]).
    pub fn init(mut self, output: &'static str, init: Init) -> Self {
        self.uninit.retain(|n| *n != output);
        if init == Init::Uninit {
            self.uninit.push(output);
        }
        self
    }

    /// A tiled kernel's threads per block (its launches are `launch_tiled`'s).
    pub fn block_dim(mut self, n: usize) -> Self {
        self.block_dim = Some(n);
        self
    }

    /// How a batched call runs (default [`Vmap::Loop`]; [`Vmap::Fold`] is the caller's promise
    /// that thread `i` touches row `i` of every array and nothing else).
    pub fn vmap(mut self, v: Vmap) -> Self {
        self.vmap = v;
        self
    }

    /// The op, after checking every name against the kernel's parameters.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the op and the name: an output that is not an array
    /// parameter of the kernel, no output, a shape or init for a non-output, a rule naming no
    /// input array, no input array to take the launch dimensions from.
    pub fn build(self) -> Result<Op> {
        let info = K::INFO;
        let kinds = <OwnedArgsOf<K> as OpArgs>::KINDS;
        let op = &self.name;
        let bad = |m: String| {
            Err(Error::invalid(format!(
                "op {op} (kernel `{}`): {m}",
                info.name
            )))
        };
        let params: Vec<&'static str> = info.params.to_vec();
        debug_assert_eq!(params.len(), kinds.len());
        if self.outputs.is_empty() {
            return bad("names no output (.outputs([..]): the array parameters it writes)".into());
        }
        for o in &self.outputs {
            match params.iter().position(|p| p == o) {
                None => {
                    return bad(format!(
                        "output '{o}' is not a parameter (the kernel's: {})",
                        params.join(", ")
                    ))
                }
                Some(k) if matches!(kinds[k], ArgKind::Value { .. }) => {
                    return bad(format!("output '{o}' is a value, not an array"))
                }
                Some(_) => {}
            }
            if self.outputs.iter().filter(|x| *x == o).count() > 1 {
                return bad(format!("output '{o}' is named twice"));
            }
        }
        for (n, what) in self
            .shapes
            .iter()
            .map(|(n, _)| (n, "a shape"))
            .chain(self.uninit.iter().map(|n| (n, "an init")))
        {
            if !self.outputs.contains(n) {
                return bad(format!("{what} is given for '{n}', which is not an output"));
            }
        }
        let spec_params: Vec<ParamSpec> = params
            .iter()
            .zip(kinds)
            .map(|(&name, &kind)| {
                let output = self.outputs.contains(&name);
                let (role, differentiable) = match kind {
                    ArgKind::Array { dtype, .. } => (
                        if output { Role::Output } else { Role::Input },
                        dtype.is_float(),
                    ),
                    ArgKind::Value { .. } => (Role::Scalar, false),
                };
                ParamSpec {
                    name,
                    role,
                    kind,
                    differentiable,
                    zeroed: output && !self.uninit.contains(&name),
                }
            })
            .collect();
        let spec = OpSpec {
            name: self.name.clone(),
            params: spec_params,
        };
        let is_input = |n: &str| matches!(spec.param(n), Some((_, p)) if p.role == Role::Input);
        let dims = match self.dims {
            Some(d) => d,
            None => match spec
                .with_role(Role::Input)
                .find(|(_, p)| matches!(p.kind, ArgKind::Array { .. }))
            {
                Some((_, p)) => LaunchDims::Like(p.name),
                None => {
                    return bad(
                        "has no input array to take the launch dimensions from; give .dims(..)"
                            .into(),
                    )
                }
            },
        };
        if let LaunchDims::Like(n) = &dims {
            if !is_input(n) {
                return bad(format!(
                    "the launch dimensions are like '{n}', which is not an input array"
                ));
            }
        }
        let mut shapes = Vec::new();
        for (k, p) in spec
            .params
            .iter()
            .enumerate()
            .filter(|(_, p)| p.role == Role::Output)
        {
            let rule = self
                .shapes
                .iter()
                .rev()
                .find(|(n, _)| *n == p.name)
                .map(|(_, r)| r.clone())
                .unwrap_or(Shape::Dims);
            if let Shape::Like(n) = &rule {
                if !is_input(n) {
                    return bad(format!(
                        "output '{}' is shaped like '{n}', which is not an input array",
                        p.name
                    ));
                }
            }
            shapes.push((k, rule));
        }
        Ok(Op {
            inner: Arc::new(OpInner {
                spec,
                run: Box::new(KernelRunner::<K> {
                    dims,
                    shapes,
                    block_dim: self.block_dim,
                    _kernel: PhantomData,
                }),
                vmap: self.vmap,
            }),
        })
    }
}

/// The process-wide registry: ops by id, for native dispatchers that receive an id.
static REGISTRY: RwLock<Vec<Op>> = RwLock::new(Vec::new());

/// Registers `op` and returns its id (ids count from 0 in registration order; an op
/// registered twice gets two ids). Ops are never removed.
pub fn register(op: &Op) -> u64 {
    let mut r = REGISTRY.write().unwrap_or_else(|p| p.into_inner());
    r.push(op.clone());
    (r.len() - 1) as u64
}

/// The op registered under `id`.
///
/// # Errors
/// [`Error::InvalidArgument`] for an id never given out.
pub fn registered(id: u64) -> Result<Op> {
    let r = REGISTRY.read().unwrap_or_else(|p| p.into_inner());
    usize::try_from(id)
        .ok()
        .and_then(|k| r.get(k).cloned())
        .ok_or_else(|| {
            Error::invalid(format!(
                "no op is registered under id {id} ({} are)",
                r.len()
            ))
        })
}

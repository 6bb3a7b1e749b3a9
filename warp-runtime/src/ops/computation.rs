//! Computation ops: a Rust body that launches any kernels (and copies, fills, library calls)
//! on declared arrays. The backward runs the body again under a [`Tape`] made inside the
//! backward call and runs the tape: a tape never lives across calls (it is `!Send`, a
//! framework's backward may run on another thread, and XLA calls are stateless).

use super::args::{CallArg, OpArg};
use super::buffer::Buffer;
use super::exec::{check_grads, check_outputs, ErasedOp, Exec};
use super::shape::{Shape, Shapes};
use super::spec::{ArgKind, OpElement, OpScalar, OpSpec, ParamSpec, Role, Value};
use super::{Op, OpInner};
use crate::array::Array;
use crate::device::Device;
use crate::error::{Error, Result};
use crate::tape::Tape;
use std::any::Any;
use std::sync::Arc;

/// A call's array, type-erased (an `Array<T, N>` of the declared `T` and `N`).
type Erased = Box<dyn Any + Send + Sync>;

/// Makes a declared array from a call's buffer; `alloc_grad`: give it fresh gradient memory
/// when the call gave none.
type Maker = unsafe fn(&Buffer, Option<&Buffer>, bool, &Device, &str, &str) -> Result<Erased>;

unsafe fn make<T: OpElement, const N: usize>(
    b: &Buffer,
    g: Option<&Buffer>,
    alloc_grad: bool,
    device: &Device,
    op: &str,
    param: &str,
) -> Result<Erased> {
    // SAFETY: forwarded contract.
    let a =
        unsafe { <Array<T, N> as OpArg>::from_call(&CallArg::Buffer(b), g, device, op, param)? };
    let a = match g.is_none() && alloc_grad {
        true => a.with_grad()?,
        false => a,
    };
    Ok(Box::new(a))
}

/// Counts the handles sharing a declared array's memory.
type Handles = fn(&Erased) -> usize;

/// How many handles share a declared array's memory.
fn handles<T: OpElement, const N: usize>(a: &Erased) -> usize {
    a.downcast_ref::<Array<T, N>>()
        .map_or(1, |a| a.storage_handles())
}

/// A declared parameter of a computation op.
#[derive(Clone)]
struct Declared {
    spec: ParamSpec,
    /// Arrays: how to make one, and how to count its handles.
    array: Option<(Maker, Handles)>,
    /// Outputs and scratch: the shape rule.
    shape: Option<Shape>,
}

/// The builder of a computation op ([`Op::computation`]).
#[must_use = "a ComputationOp is an op only after build()"]
pub struct ComputationOp<F> {
    name: String,
    body: F,
    params: Vec<Declared>,
}

impl<F> std::fmt::Debug for ComputationOp<F> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ComputationOp")
            .field("name", &self.name)
            .field(
                "params",
                &self.params.iter().map(|p| &p.spec).collect::<Vec<_>>(),
            )
            .finish()
    }
}

impl Op {
    /// A computation op named `name`: `body` launches kernels on the arrays it declares
    /// ([`ComputationOp::input`], [`output`](ComputationOp::output),
    /// [`scratch`](ComputationOp::scratch)) with its [`scalar`](ComputationOp::scalar)s. The
    /// backward runs `body` again under a tape recorded inside the backward call, then the
    /// tape's backward from the outputs' gradients: one more forward of compute, and the
    /// scratch again (checkpointing). On a GPU the body runs with the call's stream as the
    /// current one ([`ScopedStream`](crate::ScopedStream)), so it may allocate, copy and read
    /// back as any warp-lang code does.
    pub fn computation<F>(name: &str, body: F) -> ComputationOp<F>
    where
        F: Fn(&mut Ctx<'_>) -> Result<()> + Send + Sync + 'static,
    {
        ComputationOp {
            name: name.to_string(),
            body,
            params: Vec::new(),
        }
    }
}

impl<F> ComputationOp<F>
where
    F: Fn(&mut Ctx<'_>) -> Result<()> + Send + Sync + 'static,
{
    fn array<T: OpElement, const N: usize>(
        mut self,
        name: &'static str,
        role: Role,
        shape: Option<Shape>,
    ) -> Self {
        let kind = <Array<T, N> as OpArg>::KIND;
        self.params.push(Declared {
            spec: ParamSpec {
                name,
                role,
                kind,
                differentiable: T::DTYPE.is_float(),
                zeroed: role != Role::Input,
            },
            array: Some((make::<T, N>, handles::<T, N>)),
            shape,
        });
        self
    }

    /// An input array `Array<T, N>` named `name`.
    pub fn input<T: OpElement, const N: usize>(self, name: &'static str) -> Self {
        self.array::<T, N>(name, Role::Input, None)
    }

    /// A static scalar of type `S` named `name`.
    pub fn scalar<S: OpScalar>(mut self, name: &'static str) -> Self {
        self.params.push(Declared {
            spec: ParamSpec {
                name,
                role: Role::Scalar,
                kind: ArgKind::scalar_value(S::DTYPE),
                differentiable: false,
                zeroed: false,
            },
            array: None,
            shape: None,
        });
        self
    }

    /// An output array `Array<T, N>` named `name`, of leading shape `shape` (zeroed by the
    /// framework).
    pub fn output<T: OpElement, const N: usize>(self, name: &'static str, shape: Shape) -> Self {
        self.array::<T, N>(name, Role::Output, Some(shape))
    }

    /// A scratch array `Array<T, N>` named `name`, of leading shape `shape`: memory the body
    /// works in (a rollout's states), allocated and zeroed by the framework per call.
    pub fn scratch<T: OpElement, const N: usize>(self, name: &'static str, shape: Shape) -> Self {
        self.array::<T, N>(name, Role::Scratch, Some(shape))
    }

    /// The op.
    ///
    /// # Errors
    /// [`Error::InvalidArgument`] naming the op and the name: a name declared twice, no
    /// output, a [`Shape::Dims`] rule (a computation has no launch dimensions), a
    /// [`Shape::Like`] naming no input array.
    pub fn build(self) -> Result<Op> {
        let op = &self.name;
        let bad = |m: String| Err(Error::invalid(format!("op {op} (a computation): {m}")));
        for (k, p) in self.params.iter().enumerate() {
            if self.params[..k].iter().any(|q| q.spec.name == p.spec.name) {
                return bad(format!("'{}' is declared twice", p.spec.name));
            }
        }
        if !self.params.iter().any(|p| p.spec.role == Role::Output) {
            return bad("declares no output".into());
        }
        let is_input = |n: &str| {
            self.params
                .iter()
                .any(|p| p.spec.name == n && p.spec.role == Role::Input)
        };
        for p in &self.params {
            match &p.shape {
                Some(Shape::Dims) => {
                    return bad(format!(
                        "'{}' is shaped by the launch dimensions, which a computation does not \
                         have; give Like, Fixed or Fn",
                        p.spec.name
                    ))
                }
                Some(Shape::Like(n)) if !is_input(n) => {
                    return bad(format!(
                        "'{}' is shaped like '{n}', which is not an input array",
                        p.spec.name
                    ))
                }
                _ => {}
            }
        }
        let spec = OpSpec {
            name: self.name.clone(),
            params: self.params.iter().map(|p| p.spec.clone()).collect(),
        };
        Ok(Op {
            inner: Arc::new(OpInner {
                spec,
                run: Box::new(ComputationRunner {
                    body: self.body,
                    params: self.params,
                }),
                vmap: super::Vmap::Loop,
            }),
        })
    }
}

/// What a computation's body sees: the call's arrays and scalars by name, and its device.
pub struct Ctx<'c> {
    op: &'c str,
    params: &'c [Declared],
    arrays: Vec<Option<Erased>>,
    values: Vec<Option<Value>>,
    device: Device,
    replay: bool,
}

impl std::fmt::Debug for Ctx<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Ctx")
            .field("op", &self.op)
            .field("device", &self.device)
            .field("replay", &self.replay)
            .finish()
    }
}

impl Ctx<'_> {
    fn array<T: OpElement, const N: usize>(&self, name: &str, role: Role) -> Result<&Array<T, N>> {
        let k = self
            .params
            .iter()
            .position(|p| p.spec.name == name && p.spec.role == role)
            .ok_or_else(|| {
                Error::invalid(format!(
                    "{}: the body asks for {role:?} '{name}', which the op does not declare",
                    self.op
                ))
            })?;
        self.arrays[k]
            .as_ref()
            .and_then(|a| a.downcast_ref::<Array<T, N>>())
            .ok_or_else(|| {
                Error::invalid(format!(
                    "{}: the body asks for '{name}' as Array<{}, {N}>; it is declared as {}",
                    self.op,
                    T::TYPE_NAME,
                    self.params[k].spec.kind.describe()
                ))
            })
    }

    /// Input array `name`.
    ///
    /// # Errors
    /// When the op declares no input `name` of type `Array<T, N>`.
    pub fn input<T: OpElement, const N: usize>(&self, name: &str) -> Result<&Array<T, N>> {
        self.array(name, Role::Input)
    }

    /// Output array `name`.
    ///
    /// # Errors
    /// As [`input`](Self::input).
    pub fn output<T: OpElement, const N: usize>(&self, name: &str) -> Result<&Array<T, N>> {
        self.array(name, Role::Output)
    }

    /// Scratch array `name`.
    ///
    /// # Errors
    /// As [`input`](Self::input).
    pub fn scratch<T: OpElement, const N: usize>(&self, name: &str) -> Result<&Array<T, N>> {
        self.array(name, Role::Scratch)
    }

    /// Scalar `name` as `S`.
    ///
    /// # Errors
    /// When the op declares no scalar `name`, or its value is not an `S`.
    pub fn scalar<S: OpScalar>(&self, name: &str) -> Result<S> {
        let k = self
            .params
            .iter()
            .position(|p| p.spec.name == name && p.spec.role == Role::Scalar);
        match k.and_then(|k| self.values[k]) {
            Some(v) => S::from_value(v, self.op, name),
            None => Err(Error::invalid(format!(
                "{}: the body asks for scalar '{name}', which the op does not declare",
                self.op
            ))),
        }
    }

    /// The call's device.
    pub fn device(&self) -> &Device {
        &self.device
    }

    /// Whether this run is the backward's replay (under its tape) rather than the forward.
    pub fn is_replay(&self) -> bool {
        self.replay
    }
}

struct ComputationRunner<F> {
    body: F,
    params: Vec<Declared>,
}

impl<F> ComputationRunner<F>
where
    F: Fn(&mut Ctx<'_>) -> Result<()> + Send + Sync + 'static,
{
    /// Runs the body on the call (`grads: Some` for the backward's replay and tape).
    ///
    /// # Safety
    /// As [`ErasedOp::forward`].
    unsafe fn run(
        &self,
        spec: &OpSpec,
        args: &[CallArg<'_>],
        grads: Option<&[Option<&Buffer>]>,
        exec: &Exec<'_>,
    ) -> Result<()> {
        #[cfg(feature = "cuda")]
        if exec.stream_of().is_some_and(|s| s.is_caller_ordered()) {
            // Its array operations run on this crate's default stream, which a caller-ordered
            // stream is not joined with.
            return Err(Error::invalid(format!(
                "{}: a computation op runs on a stream wrapped by Stream::from_raw (joined with \
                 this crate's default stream, where its body's array operations run), not a \
                 caller-ordered one",
                spec.name
            )));
        }
        let outs = self.shapes(spec, args)?.1;
        let shaped: Vec<usize> = (0..spec.params.len())
            .filter(|&k| self.params[k].shape.is_some())
            .collect();
        check_outputs(
            spec,
            args,
            &shaped.iter().copied().zip(outs).collect::<Vec<_>>(),
        )?;
        let device = exec.device().clone();
        let mut arrays = Vec::with_capacity(args.len());
        let mut values = Vec::with_capacity(args.len());
        for (k, (p, a)) in self.params.iter().zip(args).enumerate() {
            match (p.array, a) {
                (Some((maker, _)), CallArg::Buffer(b)) => {
                    let g = grads.and_then(|g| g[k]);
                    // Outputs and scratch get a gradient in the replay even when the call gave
                    // none (the tape's adjoints flow through them).
                    let alloc = grads.is_some()
                        && p.spec.differentiable
                        && matches!(p.spec.role, Role::Output | Role::Scratch);
                    // SAFETY: forwarded contract.
                    arrays.push(Some(unsafe {
                        maker(b, g, alloc, &device, &spec.name, p.spec.name)?
                    }));
                    values.push(None);
                }
                (None, CallArg::Value(v)) => {
                    arrays.push(None);
                    values.push(Some(*v));
                }
                _ => unreachable!("check_call matched roles and arguments"),
            }
        }
        let mut ctx = Ctx {
            op: &spec.name,
            params: &self.params,
            arrays,
            values,
            device,
            replay: grads.is_some(),
        };
        // The call's arrays live only for the call: no outer tape may keep them.
        let paused = crate::tape::pause_recording();
        #[cfg(feature = "cuda")]
        let _scope = match exec.stream_of() {
            Some(s) => Some(crate::cuda::stream::ScopedStream::new(s)?),
            None => None,
        };
        let body = std::panic::AssertUnwindSafe(|| -> Result<()> {
            match grads {
                None => (self.body)(&mut ctx),
                Some(_) => {
                    let tape = Tape::new();
                    {
                        let _r = tape.record();
                        (self.body)(&mut ctx)?;
                    }
                    tape.backward_from_grads()
                }
            }
        });
        let r = std::panic::catch_unwind(body).unwrap_or_else(|p| {
            let msg = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".into());
            Err(Error::invalid(format!(
                "{}: the body panicked: {msg}",
                spec.name
            )))
        });
        drop(paused);
        // A handle the body kept would address the framework's memory after the call, which
        // an error cannot take back: abort, naming it.
        for (k, a) in ctx.arrays.iter().enumerate() {
            if let (Some(a), Some((_, count))) = (a, self.params[k].array) {
                if count(a) > 1 {
                    eprintln!(
                        "warp-lang: op {}: the body kept a handle to array '{}' past the call; \
                         its memory is the framework's and is freed after the call (aborting)",
                        spec.name, self.params[k].spec.name
                    );
                    std::process::abort();
                }
            }
        }
        r
    }
}

impl<F> ErasedOp for ComputationRunner<F>
where
    F: Fn(&mut Ctx<'_>) -> Result<()> + Send + Sync + 'static,
{
    fn is_computation(&self) -> bool {
        true
    }

    fn shapes(&self, spec: &OpSpec, args: &[CallArg<'_>]) -> Result<(Vec<usize>, Vec<Vec<usize>>)> {
        let shapes = Shapes::of_call(spec, args);
        let outs = self
            .params
            .iter()
            .filter_map(|p| p.shape.as_ref())
            .map(|rule| rule.eval(&shapes, &[]))
            .collect::<Result<Vec<_>>>()?;
        Ok((Vec::new(), outs))
    }

    unsafe fn forward(&self, spec: &OpSpec, args: &[CallArg<'_>], exec: &Exec<'_>) -> Result<()> {
        // SAFETY: forwarded contract.
        unsafe { self.run(spec, args, None, exec) }
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
        unsafe { self.run(spec, args, Some(grads), exec) }
    }
}

//! The rules that give an op's launch dimensions and output shapes from a call's input shapes
//! and static values (evaluated at trace time by a framework, and again at each call).

use super::args::CallArg;
use super::spec::{ArgKind, OpScalar, OpSpec, Role};
use crate::error::{Error, Result};
use std::sync::Arc;

/// A rule written as a function of the call's [`Shapes`].
pub type ShapeFn = Arc<dyn Fn(&Shapes<'_>) -> Result<Vec<usize>> + Send + Sync>;

/// The leading shape of an output.
#[derive(Clone)]
pub enum Shape {
    /// The launch dimensions (a kernel op's default).
    Dims,
    /// The leading shape of array parameter `name` (an input).
    Like(&'static str),
    /// These extents.
    Fixed(Vec<usize>),
    /// Computed from the call's shapes and values.
    Fn(ShapeFn),
}

/// The launch dimensions of a kernel op (`LaunchDims`, not `Dim`: [`crate::Dim`] is the extent
/// type a launch takes).
#[derive(Clone)]
pub enum LaunchDims {
    /// The leading shape of array parameter `name` (the default: the first input array).
    Like(&'static str),
    /// These extents.
    Fixed(Vec<usize>),
    /// Computed from the call's shapes and values.
    Fn(ShapeFn),
}

impl std::fmt::Debug for Shape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Shape::Dims => write!(f, "Dims"),
            Shape::Like(n) => write!(f, "Like({n:?})"),
            Shape::Fixed(v) => write!(f, "Fixed({v:?})"),
            Shape::Fn(_) => write!(f, "Fn(..)"),
        }
    }
}

impl std::fmt::Debug for LaunchDims {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            LaunchDims::Like(n) => write!(f, "Like({n:?})"),
            LaunchDims::Fixed(v) => write!(f, "Fixed({v:?})"),
            LaunchDims::Fn(_) => write!(f, "Fn(..)"),
        }
    }
}

/// What a shape rule reads: the call's input arrays' leading shapes and its static values,
/// by parameter name.
pub struct Shapes<'a> {
    spec: &'a OpSpec,
    inputs: Vec<Option<&'a [usize]>>,
    values: &'a [CallArg<'a>],
}

impl std::fmt::Debug for Shapes<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Shapes")
            .field("op", &self.spec.name)
            .field("inputs", &self.inputs)
            .finish()
    }
}

impl<'a> Shapes<'a> {
    /// The shapes of a call's arguments `args` (in `spec`'s order; outputs are not read).
    pub(crate) fn of_call(spec: &'a OpSpec, args: &'a [CallArg<'a>]) -> Shapes<'a> {
        let inputs = spec
            .params
            .iter()
            .zip(args)
            .map(|(p, a)| match (p.role, p.kind, a) {
                (Role::Input, ArgKind::Array { rank, .. }, CallArg::Buffer(b))
                    if b.dims.len() >= rank =>
                {
                    Some(&b.dims[..rank])
                }
                _ => None,
            })
            .collect();
        Shapes {
            spec,
            inputs,
            values: args,
        }
    }

    /// The leading shape of input array `array`.
    ///
    /// # Errors
    /// When the op has no input array of that name.
    pub fn shape(&self, array: &str) -> Result<&'a [usize]> {
        match self.spec.param(array) {
            Some((k, _)) => self.inputs[k].ok_or_else(|| self.unknown(array, "input array")),
            None => Err(self.unknown(array, "input array")),
        }
    }

    /// The first extent of input array `array`.
    ///
    /// # Errors
    /// As [`shape`](Self::shape).
    pub fn len(&self, array: &str) -> Result<usize> {
        Ok(self.shape(array)?.first().copied().unwrap_or(0))
    }

    /// The static value of scalar parameter `name` as `S`.
    ///
    /// # Errors
    /// When the op has no scalar of that name, or the value is not an `S`.
    pub fn scalar<S: OpScalar>(&self, name: &str) -> Result<S> {
        match self.spec.param(name) {
            Some((k, p)) if p.role == Role::Scalar => match self.values.get(k) {
                Some(CallArg::Value(v)) => S::from_value(*v, &self.spec.name, name),
                _ => Err(self.unknown(name, "scalar")),
            },
            _ => Err(self.unknown(name, "scalar")),
        }
    }

    #[cold]
    fn unknown(&self, name: &str, what: &str) -> Error {
        Error::invalid(format!(
            "{}: a shape rule reads {what} '{name}', which the op does not have (its \
             parameters: {})",
            self.spec.name,
            self.spec
                .params
                .iter()
                .map(|p| p.name)
                .collect::<Vec<_>>()
                .join(", ")
        ))
    }
}

impl LaunchDims {
    /// The launch dimensions for `shapes` (1 to 4 extents).
    pub(crate) fn eval(&self, shapes: &Shapes<'_>) -> Result<Vec<usize>> {
        let dims = match self {
            LaunchDims::Like(name) => shapes.shape(name)?.to_vec(),
            LaunchDims::Fixed(v) => v.clone(),
            LaunchDims::Fn(f) => f(shapes)?,
        };
        if dims.is_empty() || dims.len() > 4 {
            return Err(Error::invalid(format!(
                "{}: the launch dimensions {dims:?} have {} extents; a launch has 1 to 4",
                shapes.spec.name,
                dims.len()
            )));
        }
        Ok(dims)
    }
}

impl Shape {
    /// The output's leading shape for `shapes`, given the launch dimensions `dims`.
    pub(crate) fn eval(&self, shapes: &Shapes<'_>, dims: &[usize]) -> Result<Vec<usize>> {
        match self {
            Shape::Dims => Ok(dims.to_vec()),
            Shape::Like(name) => Ok(shapes.shape(name)?.to_vec()),
            Shape::Fixed(v) => Ok(v.clone()),
            Shape::Fn(f) => f(shapes),
        }
    }
}

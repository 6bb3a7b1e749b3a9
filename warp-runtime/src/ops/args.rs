//! A kernel's owned argument tuple made from an op call's buffers and values: what decides,
//! at compile time, which kernels can become ops ([`OpArg`], [`OpArgs`]).

use super::buffer::Buffer;
use super::spec::{ArgKind, OpElement, OpScalar, OpValue, Value};
use crate::array::Array;
use crate::device::Device;
use crate::error::{Error, Result};

/// One argument of an op call, in the kernel's parameter order.
#[derive(Clone, Copy, Debug)]
pub enum CallArg<'a> {
    /// An array parameter's memory.
    Buffer(&'a Buffer),
    /// A scalar value parameter's static value.
    Value(Value),
    /// A vector, quaternion or matrix value parameter's components, row-major over its
    /// component axes (as NumPy lays out `np.asarray(v)`: a `Mat3`'s rows one after another).
    Values(&'a [Value]),
    /// Not given: an output's place when only the shapes are asked for
    /// ([`Op::shapes`](super::Op::shapes)).
    Absent,
}

/// A kernel parameter type that an op can take: an array of numeric elements or a numeric
/// value.
#[diagnostic::on_unimplemented(
    message = "kernel parameter type `{Self}` cannot cross into an op",
    note = "ops take Array<T, N> of numeric T (scalars, vectors, matrices, quaternions) and \
            value parameters of those types; wrap a kernel that takes structs, meshes or other \
            objects in an Op::computation and build those inside the body"
)]
pub trait OpArg: Sized + Send + Sync + 'static {
    /// The parameter's type as an op sees it.
    const KIND: ArgKind;

    /// The argument from the call's `src` on `device`, with `grad`'s memory as its gradient
    /// when given (an array's only).
    ///
    /// # Safety
    /// `src` and `grad` are valid memory of `device` while the result lives (buffer.rs).
    ///
    /// # Errors
    /// A buffer or value that is not of this type, naming `op` and `param`.
    unsafe fn from_call(
        src: &CallArg<'_>,
        grad: Option<&Buffer>,
        device: &Device,
        op: &str,
        param: &str,
    ) -> Result<Self>;
}

#[cold]
fn wrong_kind(kind: &ArgKind, given: &str, op: &str, param: &str) -> Error {
    Error::invalid(format!(
        "{op}: argument '{param}': {given}; the kernel takes {}",
        kind.describe()
    ))
}

impl<T: OpElement, const N: usize> OpArg for Array<T, N> {
    const KIND: ArgKind = ArgKind::Array {
        dtype: T::DTYPE,
        rank: N,
        element: T::SHAPE,
        type_name: T::TYPE_NAME,
    };

    unsafe fn from_call(
        src: &CallArg<'_>,
        grad: Option<&Buffer>,
        device: &Device,
        op: &str,
        param: &str,
    ) -> Result<Self> {
        let b = match src {
            CallArg::Buffer(b) => b,
            CallArg::Value(_) | CallArg::Values(_) | CallArg::Absent => {
                return Err(wrong_kind(&Self::KIND, &src.describe(), op, param))
            }
        };
        // SAFETY: forwarded contract.
        let array = unsafe { b.array::<T, N>(device, op, param)? };
        match grad {
            None => Ok(array),
            Some(g) => {
                // SAFETY: forwarded contract.
                let g = unsafe { g.array::<T, N>(device, op, &format!("{param}'s gradient"))? };
                array
                    .with_grad_array(g)
                    .map_err(|e| Error::invalid(format!("{op}: argument '{param}': {e}")))
            }
        }
    }
}

impl<'a> CallArg<'a> {
    /// How a message names what was given: "the value 2.5", "the values [1.0, 2.0]".
    pub fn describe(&self) -> String {
        match self {
            CallArg::Buffer(b) => format!("a {} buffer of shape {:?}", b.dtype.name(), b.dims),
            CallArg::Value(v) => format!("the value {v}"),
            CallArg::Values(vs) => {
                let vs: Vec<String> = vs.iter().map(|v| v.to_string()).collect();
                format!("the {} values [{}]", vs.len(), vs.join(", "))
            }
            CallArg::Absent => "nothing".to_string(),
        }
    }
}

/// A value parameter's value as a call holds it (owned), what [`CallArg::Value`] and
/// [`CallArg::Values`] borrow: the Python binding's and the XLA handlers' storage.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum Given {
    /// Not a value parameter.
    None,
    /// A scalar's value.
    One(Value),
    /// A vector's, quaternion's or matrix's components.
    Components(Vec<Value>),
}

impl Given {
    /// The argument borrowing it ([`CallArg::Absent`] for none).
    pub(crate) fn arg(&self) -> CallArg<'_> {
        match self {
            Given::None => CallArg::Absent,
            Given::One(v) => CallArg::Value(*v),
            Given::Components(vs) => CallArg::Values(vs),
        }
    }
}

/// A value parameter's check: no gradient.
fn no_grad(grad: Option<&Buffer>, op: &str, param: &str) -> Result<()> {
    match grad {
        Some(_) => Err(Error::invalid(format!(
            "{op}: argument '{param}': a static value has no gradient"
        ))),
        None => Ok(()),
    }
}

/// A value parameter of a numeric type: a scalar from [`CallArg::Value`], a vector,
/// quaternion or matrix from [`CallArg::Values`] (its components row-major over its
/// component axes, each converted as a scalar of its type is).
impl<T: OpValue> OpArg for T {
    const KIND: ArgKind = ArgKind::Value {
        dtype: <T::Scalar as OpScalar>::DTYPE,
        element: T::SHAPE,
        type_name: T::TYPE_NAME,
    };

    unsafe fn from_call(
        src: &CallArg<'_>,
        grad: Option<&Buffer>,
        _device: &Device,
        op: &str,
        param: &str,
    ) -> Result<Self> {
        no_grad(grad, op, param)?;
        let scalar = |v: &Value| <T::Scalar as OpScalar>::from_value(*v, op, param);
        let given: &[Value] = match (src, T::SHAPE.is_empty()) {
            (CallArg::Value(v), true) => std::slice::from_ref(v),
            (CallArg::Values(vs), false) => vs,
            _ => return Err(wrong_kind(&Self::KIND, &src.describe(), op, param)),
        };
        let count: usize = T::SHAPE.iter().product();
        if given.len() != count {
            return Err(wrong_kind(&Self::KIND, &src.describe(), op, param));
        }
        // Component k (row-major over SHAPE) lies at the dot product of its index with
        // STRIDES, in scalars (a glam matrix stores its columns: strides [1, rows]).
        let mut out = <T as bytemuck::Zeroable>::zeroed();
        let bytes = bytemuck::bytes_of_mut(&mut out);
        let size = std::mem::size_of::<T::Scalar>();
        for (k, v) in given.iter().enumerate() {
            let (mut rest, mut at) = (k, 0isize);
            for (&extent, &stride) in T::SHAPE.iter().zip(T::STRIDES).rev() {
                at += (rest % extent) as isize * stride;
                rest /= extent;
            }
            let at = at as usize * size;
            bytes[at..at + size].copy_from_slice(bytemuck::bytes_of(&scalar(v)?));
        }
        Ok(out)
    }
}

/// A `bool` value parameter (`bool` is a value type of ops, not an array element).
impl OpArg for bool {
    const KIND: ArgKind = ArgKind::scalar_value(<bool as OpScalar>::DTYPE);

    unsafe fn from_call(
        src: &CallArg<'_>,
        grad: Option<&Buffer>,
        _device: &Device,
        op: &str,
        param: &str,
    ) -> Result<Self> {
        no_grad(grad, op, param)?;
        match src {
            CallArg::Value(v) => bool::from_value(*v, op, param),
            _ => Err(wrong_kind(&Self::KIND, &src.describe(), op, param)),
        }
    }
}

/// A kernel's owned argument tuple ([`OwnedArgsOf`](crate::OwnedArgsOf)) whose every element
/// is an [`OpArg`]: the kernels that can become ops.
#[diagnostic::on_unimplemented(
    message = "the parameters `{Self}` of this kernel cannot cross into an op",
    note = "each parameter must be an Array<T, N> of numeric T or a numeric value; wrap other \
            kernels in an Op::computation"
)]
pub trait OpArgs: Sized + Send + Sync + 'static {
    /// Each parameter's type, in order.
    const KINDS: &'static [ArgKind];

    /// The tuple from the call's arguments (`src[k]` for parameter `k`, named `names[k]`),
    /// each with gradient memory `grads[k]` when given.
    ///
    /// # Safety
    /// As [`OpArg::from_call`].
    ///
    /// # Errors
    /// As [`OpArg::from_call`]; the caller has checked the counts.
    unsafe fn from_call(
        src: &[CallArg<'_>],
        grads: &[Option<&Buffer>],
        device: &Device,
        op: &str,
        names: &[&str],
    ) -> Result<Self>;
}

macro_rules! tuple_op_args {
    ($($T:ident $k:tt),*) => {
        #[allow(unused_variables, clippy::unused_unit)]
        impl<$($T: OpArg),*> OpArgs for ($($T,)*) {
            const KINDS: &'static [ArgKind] = &[$($T::KIND),*];

            unsafe fn from_call(
                src: &[CallArg<'_>],
                grads: &[Option<&Buffer>],
                device: &Device,
                op: &str,
                names: &[&str],
            ) -> Result<Self> {
                // SAFETY: forwarded contract.
                Ok(($(unsafe { $T::from_call(&src[$k], grads[$k], device, op, names[$k])? },)*))
            }
        }
    };
}

/// `tuple_op_args!` for every prefix of the list (as params.rs does for `KernelParams`).
macro_rules! tuple_op_args_upto {
    ($($T:ident $k:tt),*) => {
        tuple_op_args_upto!(@ [] $($T $k),*);
    };
    (@ [$($D:ident $dk:tt)*]) => {
        tuple_op_args!($($D $dk),*);
    };
    (@ [$($D:ident $dk:tt)*] $T:ident $k:tt $(, $R:ident $rk:tt)*) => {
        tuple_op_args!($($D $dk),*);
        tuple_op_args_upto!(@ [$($D $dk)* $T $k] $($R $rk),*);
    };
}

tuple_op_args_upto!(
    A0 0, A1 1, A2 2, A3 3, A4 4, A5 5, A6 6, A7 7, A8 8, A9 9, A10 10, A11 11, A12 12, A13 13,
    A14 14, A15 15, A16 16, A17 17, A18 18, A19 19, A20 20, A21 21, A22 22, A23 23, A24 24,
    A25 25, A26 26, A27 27, A28 28, A29 29, A30 30, A31 31
);

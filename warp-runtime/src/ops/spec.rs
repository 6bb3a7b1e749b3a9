//! What an op takes, as a framework sees it: each parameter's role, scalar type, rank and
//! trailing (component) axes. Made once from the kernel's parameter types ([`OpArgs`]) and the
//! builder's names; every check of a call's buffers and values reads it.
//!
//! [`OpArgs`]: super::OpArgs

use crate::array::NdComponents;
use crate::error::{Error, Result};

/// A scalar type a framework exchanges (NumPy's, torch's and JAX's names in [`Dtype::name`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Dtype {
    /// `bool`
    Bool,
    /// `i8`
    I8,
    /// `i16`
    I16,
    /// `i32`
    I32,
    /// `i64`
    I64,
    /// `u8`
    U8,
    /// `u16`
    U16,
    /// `u32`
    U32,
    /// `u64`
    U64,
    /// `f16`
    F16,
    /// `bf16`
    Bf16,
    /// `f32`
    F32,
    /// `f64`
    F64,
}

impl Dtype {
    /// The frameworks' name (`float32`, `int64`, `bfloat16`, ..).
    pub fn name(self) -> &'static str {
        match self {
            Dtype::Bool => "bool",
            Dtype::I8 => "int8",
            Dtype::I16 => "int16",
            Dtype::I32 => "int32",
            Dtype::I64 => "int64",
            Dtype::U8 => "uint8",
            Dtype::U16 => "uint16",
            Dtype::U32 => "uint32",
            Dtype::U64 => "uint64",
            Dtype::F16 => "float16",
            Dtype::Bf16 => "bfloat16",
            Dtype::F32 => "float32",
            Dtype::F64 => "float64",
        }
    }

    /// The size of one scalar in bytes.
    pub fn size(self) -> usize {
        match self {
            Dtype::Bool | Dtype::I8 | Dtype::U8 => 1,
            Dtype::I16 | Dtype::U16 | Dtype::F16 | Dtype::Bf16 => 2,
            Dtype::I32 | Dtype::U32 | Dtype::F32 => 4,
            Dtype::I64 | Dtype::U64 | Dtype::F64 => 8,
        }
    }

    /// The Rust name of the type (`f32`, `bf16`, `bool`).
    pub const fn rust_name(self) -> &'static str {
        match self {
            Dtype::Bool => "bool",
            Dtype::I8 => "i8",
            Dtype::I16 => "i16",
            Dtype::I32 => "i32",
            Dtype::I64 => "i64",
            Dtype::U8 => "u8",
            Dtype::U16 => "u16",
            Dtype::U32 => "u32",
            Dtype::U64 => "u64",
            Dtype::F16 => "f16",
            Dtype::Bf16 => "bf16",
            Dtype::F32 => "f32",
            Dtype::F64 => "f64",
        }
    }

    /// Whether gradients flow through values of this type (floating point).
    pub fn is_float(self) -> bool {
        matches!(self, Dtype::F16 | Dtype::Bf16 | Dtype::F32 | Dtype::F64)
    }
}

/// A static value given for a scalar parameter (a Python number, an XLA attribute), converted
/// to the parameter's type with a range check ([`OpScalar::from_value`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    /// A boolean.
    Bool(bool),
    /// An integer.
    Int(i64),
    /// A floating-point number.
    Float(f64),
}

impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Value::Bool(b) => write!(f, "{b}"),
            Value::Int(i) => write!(f, "{i}"),
            Value::Float(x) => write!(f, "{x:?}"),
        }
    }
}

/// A scalar type an op's arrays and values may have.
// (A kernel parameter that is neither an array nor a scalar fails here first, through
// `OpArg`'s blanket impl for scalars: the message is the one `OpArg` gives.)
#[diagnostic::on_unimplemented(
    message = "kernel parameter type `{Self}` cannot cross into an op",
    note = "ops take Array<T, N> of numeric T (scalars, vectors, matrices, quaternions) and \
            numeric value parameters (bool, integers, f16, bf16, f32, f64, and vectors, \
            matrices and quaternions of them); wrap a kernel that takes structs, meshes or \
            other objects in an Op::computation and build those inside the body"
)]
pub trait OpScalar: Copy + Send + Sync + 'static {
    /// Its dtype.
    const DTYPE: Dtype;
    /// The value as this type: an integer in range for an integer type, any number for a
    /// floating type (rounded to nearest), a boolean for `bool`; else an error naming the op
    /// and the parameter.
    fn from_value(v: Value, op: &str, param: &str) -> Result<Self>;
}

#[cold]
fn value_error(v: Value, dtype: Dtype, op: &str, param: &str) -> Error {
    Error::invalid(format!(
        "{op}: argument '{param}': {v} is not a {} (the kernel takes {})",
        dtype.name(),
        dtype.name()
    ))
}

macro_rules! int_scalars {
    ($($t:ty => $d:ident),*) => {$(
        impl OpScalar for $t {
            const DTYPE: Dtype = Dtype::$d;
            fn from_value(v: Value, op: &str, param: &str) -> Result<Self> {
                match v {
                    Value::Int(i) => <$t>::try_from(i).map_err(|_| value_error(v, Dtype::$d, op, param)),
                    _ => Err(value_error(v, Dtype::$d, op, param)),
                }
            }
        }
    )*};
}
int_scalars!(i8 => I8, i16 => I16, i32 => I32, i64 => I64, u8 => U8, u16 => U16, u32 => U32, u64 => U64);

macro_rules! float_scalars {
    ($($t:ty => $d:ident, $from:expr);*) => {$(
        impl OpScalar for $t {
            const DTYPE: Dtype = Dtype::$d;
            fn from_value(v: Value, op: &str, param: &str) -> Result<Self> {
                let from: fn(f64) -> $t = $from;
                match v {
                    Value::Float(x) => Ok(from(x)),
                    // Integers up to 2^53 are exact in f64 (what Python's float() does).
                    Value::Int(i) => Ok(from(i as f64)),
                    Value::Bool(_) => Err(value_error(v, Dtype::$d, op, param)),
                }
            }
        }
    )*};
}
float_scalars!(
    f32 => F32, |x| x as f32;
    f64 => F64, |x| x;
    warp_core::f16 => F16, <warp_core::f16 as warp_core::ops::FromLiteral>::from_f64;
    warp_core::bf16 => Bf16, <warp_core::bf16 as warp_core::ops::FromLiteral>::from_f64
);

impl OpScalar for bool {
    const DTYPE: Dtype = Dtype::Bool;
    fn from_value(v: Value, op: &str, param: &str) -> Result<Self> {
        match v {
            Value::Bool(b) => Ok(b),
            _ => Err(value_error(v, Dtype::Bool, op, param)),
        }
    }
}

/// A type an op's value parameters may have: a numeric scalar, vector, quaternion or matrix
/// (`f32`, `DVec3`, `Quat`, `Mat3`; `bool` too, apart): every [`NdComponents`] type of an
/// [`OpScalar`], whose components say how a call's numbers fill the value.
#[diagnostic::on_unimplemented(
    message = "kernel parameter type `{Self}` cannot cross into an op",
    note = "ops take Array<T, N> of numeric T (scalars, vectors, matrices, quaternions) and \
            value parameters of those types and bool; wrap a kernel that takes structs, meshes \
            or other objects in an Op::computation and build those inside the body"
)]
pub trait OpValue: NdComponents<Scalar: OpScalar> {}

impl<T: NdComponents<Scalar: OpScalar>> OpValue for T {}

/// An element type an op's arrays may have: a scalar, vector, quaternion or matrix of an
/// [`OpScalar`] (its components are the buffer's trailing axes, as [`NdComponents`] lays
/// them out).
pub trait OpElement: NdComponents {
    /// The scalar type of the components.
    const DTYPE: Dtype;
}

impl<T: NdComponents> OpElement for T
where
    T::Scalar: OpScalar,
{
    const DTYPE: Dtype = <T::Scalar as OpScalar>::DTYPE;
}

/// A parameter's type as an op sees it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArgKind {
    /// `Array<T, rank>` of `T` with scalar type `dtype` and trailing axes `element`.
    Array {
        /// The scalar type.
        dtype: Dtype,
        /// `N` of `Array<T, N>`.
        rank: usize,
        /// `T`'s trailing axes (`[3]` for a vector of 3, `[]` for a scalar).
        element: &'static [usize],
        /// `T`'s name (`DVec3`).
        type_name: &'static str,
    },
    /// A value parameter (static: a number the call gives, or for a vector, quaternion or
    /// matrix its components, row-major over `element`, as NumPy lays out `np.asarray(v)`).
    Value {
        /// The scalar type (of the components).
        dtype: Dtype,
        /// The type's component axes (`[3]` for a vector of 3, `[]` for a scalar).
        element: &'static [usize],
        /// The type's name (`f32`, `Vec3`).
        type_name: &'static str,
    },
}

impl ArgKind {
    /// How a message names the type: `Array<DVec3, 1> (float64, trailing axes [3])`.
    pub fn describe(&self) -> String {
        match self {
            ArgKind::Array {
                dtype,
                rank,
                element,
                type_name,
            } => {
                let tail = match element.is_empty() {
                    true => String::new(),
                    false => format!(", trailing axes {element:?}"),
                };
                format!("Array<{type_name}, {rank}> ({}{tail})", dtype.name())
            }
            ArgKind::Value {
                dtype, element: [], ..
            } => format!("a static {}", dtype.name()),
            ArgKind::Value {
                dtype,
                element,
                type_name,
            } => format!(
                "a static {type_name} ({} components of {}, shape {element:?})",
                element.iter().product::<usize>(),
                dtype.name()
            ),
        }
    }

    /// Whether this is a value of a scalar type (given as one [`Value`]), not an array nor a
    /// vector, quaternion or matrix value (given as its components).
    pub fn is_scalar_value(&self) -> bool {
        matches!(self, ArgKind::Value { element: [], .. })
    }

    /// A value parameter of scalar type `dtype`.
    pub const fn scalar_value(dtype: Dtype) -> ArgKind {
        ArgKind::Value {
            dtype,
            element: &[],
            type_name: dtype.rust_name(),
        }
    }
}

/// What a parameter is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Role {
    /// An array the op reads (the framework's input).
    Input,
    /// An array the op writes (allocated by the framework, zeroed unless `Init::Uninit`).
    Output,
    /// A static value.
    Scalar,
    /// A computation op's intermediate array (allocated and zeroed by the framework, dropped
    /// after the call; the backward gets it again, with a gradient).
    Scratch,
}

/// One parameter of an op.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ParamSpec {
    /// The kernel's parameter name (or the declared one).
    pub name: &'static str,
    /// Input, output or scalar.
    pub role: Role,
    /// Its type.
    pub kind: ArgKind,
    /// Whether a gradient flows through it: floating arrays; never integers or values.
    pub differentiable: bool,
    /// For an output: whether the framework zero-fills it before the forward.
    pub zeroed: bool,
}

/// What an op takes, in the kernel's parameter order.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct OpSpec {
    /// The op's name.
    pub name: String,
    /// Each parameter.
    pub params: Vec<ParamSpec>,
}

impl OpSpec {
    /// The position and spec of parameter `name`.
    pub fn param(&self, name: &str) -> Option<(usize, &ParamSpec)> {
        self.params.iter().enumerate().find(|(_, p)| p.name == name)
    }

    /// The parameters of role `role`, in order.
    pub fn with_role(&self, role: Role) -> impl Iterator<Item = (usize, &ParamSpec)> {
        self.params
            .iter()
            .enumerate()
            .filter(move |(_, p)| p.role == role)
    }
}

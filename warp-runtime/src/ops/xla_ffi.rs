//! Ops as XLA FFI custom calls (JAX's `jax.ffi.ffi_call`): `#[repr(C)]` mirrors of the parts
//! of XLA's C API (`xla/ffi/api/c_api.h`) a handler reads, and the eight native handlers
//! ([`handlers`]): forward and backward, each as a `graph` target (capturable into XLA's
//! command buffers: kernel ops) and an `eager` one (computation ops, and kernel ops in debug
//! mode), for the platforms `cpu` and `CUDA`. A handler takes no lock and touches no Python:
//! XLA's thread calls it, it finds the op in the process-wide registry by the `warp_op`
//! attribute, makes the call's buffers into [`CallArg`]s and runs the op.
//!
//! **What a call passes** ([`layout`] says it per op, for the glue that builds the
//! `ffi_call`): attributes `warp_op` (an `int64` scalar: the id [`register`](super::register)
//! gave) and one attribute per value parameter, named as the parameter and of exactly its
//! dtype: a scalar (`np.float32(x)` for an `f32`), or for a vector, quaternion or matrix an
//! array of its components, row-major (`np.asarray(v, np.float32).ravel()` for a `Vec3` or a
//! `Mat3`); operands and results as [`Slot`]s list them. With
//! `vmap_method="expand_dims"` every operand and result may carry the same number of leading
//! batch axes (extent 1 for an unbatched operand); the op then runs as its [`Vmap`] says.
//!
//! **ABI.** The C API's major version is still 0 and `XLA_FFI_Api` gained fields in its
//! middle between releases, so only its prefix through `XLA_FFI_Stream_Get` is mirrored
//! ([`Api`]), and `struct_size` is checked before any function is read: a smaller table (an
//! older layout) or a major version other than 0 is a `FAILED_PRECONDITION` naming both.
//!
//! **Errors.** Everything a handler refuses becomes an `XLA_FFI_Error` made by the table's
//! `XLA_FFI_Error_Create`: `INVALID_ARGUMENT` for attributes, buffers and the op's own checks
//! (the message names the target, the op, the parameter and the values), `FAILED_PRECONDITION`
//! for the API table and for CUDA without a usable device, `INTERNAL` for a panic (caught:
//! nothing unwinds into XLA), `UNKNOWN` for other runtime errors (CUDA's, a fault).
//!
//! [`Vmap`]: super::Vmap

use super::args::{CallArg, Given};
use super::buffer::Buffer;
use super::exec::Exec;
use super::spec::{ArgKind, Dtype, Role, Value};
use super::Op;
use crate::error::Error;
use std::ffi::{c_char, c_int, c_void, CString};
use std::mem::{offset_of, size_of};
use std::panic::{catch_unwind, AssertUnwindSafe};

// ---------------------------------------------------------------------------------------------
// The C API's structs (the fields read or written here, in c_api.h's order)
// ---------------------------------------------------------------------------------------------

/// `XLA_FFI_Extension_Base`: the head of an extension chained from a struct's
/// `extension_start`.
#[repr(C)]
#[derive(Debug)]
pub struct ExtensionBase {
    /// The extension's size in bytes.
    pub struct_size: usize,
    /// `XLA_FFI_Extension_Type` ([`EXTENSION_METADATA`]).
    pub kind: c_int,
    /// The next extension, or null.
    pub next: *mut ExtensionBase,
}

/// `XLA_FFI_Extension_Type_Metadata`: the call is XLA's metadata query, not an execution.
pub const EXTENSION_METADATA: c_int = 1;

/// `XLA_FFI_Api_Version`.
#[repr(C)]
#[derive(Debug)]
pub struct ApiVersion {
    /// Its size in bytes.
    pub struct_size: usize,
    /// Extensions (none read).
    pub extension_start: *mut ExtensionBase,
    /// The major version (0 for every release so far).
    pub major_version: c_int,
    /// The minor version.
    pub minor_version: c_int,
}

/// `XLA_FFI_Metadata`, the prefix written here (newer releases append fields; XLA sets
/// `struct_size` to its own size and zero-fills the rest).
#[repr(C)]
#[derive(Debug)]
pub struct Metadata {
    /// XLA's size of the struct.
    pub struct_size: usize,
    /// The API version the handler was written for (answered: [`HANDLER_API_VERSION`]).
    pub api_version: ApiVersion,
    /// `XLA_FFI_Handler_Traits` bits ([`TRAIT_COMMAND_BUFFER_COMPATIBLE`]).
    pub traits: u32,
}

/// `XLA_FFI_HANDLER_TRAITS_COMMAND_BUFFER_COMPATIBLE`: the handler always launches the same
/// device work for the same attributes, so XLA may capture it into a command buffer (a CUDA
/// graph) and replay it.
pub const TRAIT_COMMAND_BUFFER_COMPATIBLE: u32 = 1;

/// `XLA_FFI_Metadata_STRUCT_SIZE`: XLA's sizes are `XLA_FFI_STRUCT_SIZE(type, last field)`,
/// the end of the last field without the padding after it (36 bytes here, where
/// `size_of::<Metadata>()` is 40): what XLA writes into the query's `struct_size`.
pub const METADATA_STRUCT_SIZE: usize = offset_of!(Metadata, traits) + size_of::<u32>();

/// The API version the handlers answer the metadata query with (major, minor): the C API's
/// first versioned layout, the fields read here.
pub const HANDLER_API_VERSION: (c_int, c_int) = (0, 1);

/// `XLA_FFI_Metadata_Extension`: what `extension_start` points to in a metadata query.
#[repr(C)]
#[derive(Debug)]
pub struct MetadataExtension {
    /// The chain's head (`kind` = [`EXTENSION_METADATA`]).
    pub extension_base: ExtensionBase,
    /// Where the answer goes.
    pub metadata: *mut Metadata,
}

/// `XLA_FFI_Error`: opaque, made by the API table's `XLA_FFI_Error_Create` and freed by XLA.
#[repr(C)]
#[derive(Debug)]
pub struct XlaError {
    _opaque: [u8; 0],
}

/// `XLA_FFI_Error_Create_Args`.
#[repr(C)]
#[derive(Debug)]
pub struct ErrorCreateArgs {
    /// Its size in bytes.
    pub struct_size: usize,
    /// Extensions (none).
    pub extension_start: *mut ExtensionBase,
    /// The message, NUL-terminated (XLA copies it).
    pub message: *const c_char,
    /// `XLA_FFI_Error_Code` ([`ErrorCode`]).
    pub errc: c_int,
}

/// `XLA_FFI_Stream_Get_Args`.
#[repr(C)]
#[derive(Debug)]
pub struct StreamGetArgs {
    /// Its size in bytes.
    pub struct_size: usize,
    /// Extensions (none).
    pub extension_start: *mut ExtensionBase,
    /// The call frame's execution context.
    pub ctx: *mut c_void,
    /// Out: the platform's stream (a `CUstream` on CUDA).
    pub stream: *mut c_void,
}

/// `XLA_FFI_Error_Create`.
pub type ErrorCreateFn = unsafe extern "C" fn(*mut ErrorCreateArgs) -> *mut XlaError;
/// `XLA_FFI_Stream_Get`.
pub type StreamGetFn = unsafe extern "C" fn(*mut StreamGetArgs) -> *mut XlaError;

/// `XLA_FFI_Api`, its prefix through `XLA_FFI_Stream_Get` (the fields that have kept their
/// place since the table gained `api_version`). Later fields (type ids, execution context,
/// device ordinal, thread pool, ..) moved between releases and are never read.
#[repr(C)]
#[derive(Debug)]
pub struct Api {
    /// XLA's size of the whole table (checked against [`API_PREFIX_SIZE`]).
    pub struct_size: usize,
    /// Extensions (none read).
    pub extension_start: *mut ExtensionBase,
    /// The implementation's version (major must be 0).
    pub api_version: ApiVersion,
    /// XLA's internal table (never read).
    pub internal_api: *mut c_void,
    /// `XLA_FFI_Error_Create`.
    pub error_create: Option<ErrorCreateFn>,
    /// `XLA_FFI_Error_GetMessage` (never called).
    pub error_get_message: *mut c_void,
    /// `XLA_FFI_Error_Destroy` (never called).
    pub error_destroy: *mut c_void,
    /// `XLA_FFI_Handler_Register` (never called: JAX registers the handlers).
    pub handler_register: *mut c_void,
    /// `XLA_FFI_Stream_Get`.
    pub stream_get: Option<StreamGetFn>,
}

/// The bytes of `XLA_FFI_Api` read here: through `XLA_FFI_Stream_Get`.
pub const API_PREFIX_SIZE: usize = size_of::<Api>();

/// The bytes an `XLA_FFI_Api` must have for its `XLA_FFI_Error_Create` to be called (a table
/// too small for [`API_PREFIX_SIZE`] but this large gets a named error).
const API_ERROR_CREATE_END: usize = offset_of!(Api, error_create) + size_of::<usize>();

/// `XLA_FFI_ByteSpan`: a string that need not end in NUL.
#[repr(C)]
#[derive(Debug)]
pub struct ByteSpan {
    /// Its bytes.
    pub ptr: *const c_char,
    /// Their count.
    pub len: usize,
}

/// `XLA_FFI_Scalar`: a scalar attribute.
#[repr(C)]
#[derive(Debug)]
pub struct Scalar {
    /// `XLA_FFI_DataType` ([`DataType`]).
    pub dtype: c_int,
    /// The value, of `dtype`'s size.
    pub value: *mut c_void,
}

/// `XLA_FFI_Array`: an array attribute (a vector's, quaternion's or matrix's components).
#[repr(C)]
#[derive(Debug)]
pub struct ArrayAttr {
    /// `XLA_FFI_DataType`.
    pub dtype: c_int,
    /// The element count.
    pub size: usize,
    /// The elements.
    pub data: *mut c_void,
}

/// `XLA_FFI_Buffer`: an operand or result (dense, row-major: XLA's default layout).
#[repr(C)]
#[derive(Debug)]
pub struct FfiBuffer {
    /// Its size in bytes.
    pub struct_size: usize,
    /// Extensions (none read).
    pub extension_start: *mut ExtensionBase,
    /// `XLA_FFI_DataType` ([`DataType`]).
    pub dtype: c_int,
    /// Element zero (host memory on `cpu`, device memory on `CUDA`).
    pub data: *mut c_void,
    /// The number of axes.
    pub rank: i64,
    /// `rank` extents.
    pub dims: *mut i64,
}

/// `XLA_FFI_Args`: the operands.
#[repr(C)]
#[derive(Debug)]
pub struct Args {
    /// Its size in bytes.
    pub struct_size: usize,
    /// Extensions (none read).
    pub extension_start: *mut ExtensionBase,
    /// The count.
    pub size: i64,
    /// `size` `XLA_FFI_ArgType`s ([`BUFFER`]).
    pub types: *mut c_int,
    /// `size` pointers, each to an [`FfiBuffer`].
    pub args: *mut *mut c_void,
}

/// `XLA_FFI_Rets`: the results.
#[repr(C)]
#[derive(Debug)]
pub struct Rets {
    /// Its size in bytes.
    pub struct_size: usize,
    /// Extensions (none read).
    pub extension_start: *mut ExtensionBase,
    /// The count.
    pub size: i64,
    /// `size` `XLA_FFI_RetType`s ([`BUFFER`]).
    pub types: *mut c_int,
    /// `size` pointers, each to an [`FfiBuffer`].
    pub rets: *mut *mut c_void,
}

/// `XLA_FFI_ArgType_BUFFER` and `XLA_FFI_RetType_BUFFER`.
pub const BUFFER: c_int = 1;

/// `XLA_FFI_Attrs`: the attributes, sorted by name.
#[repr(C)]
#[derive(Debug)]
pub struct Attrs {
    /// Its size in bytes.
    pub struct_size: usize,
    /// Extensions (none read).
    pub extension_start: *mut ExtensionBase,
    /// The count.
    pub size: i64,
    /// `size` `XLA_FFI_AttrType`s ([`AttrType`]).
    pub types: *mut c_int,
    /// `size` names.
    pub names: *mut *mut ByteSpan,
    /// `size` pointers: a [`Scalar`], an [`ArrayAttr`], ...
    pub attrs: *mut *mut c_void,
}

/// `XLA_FFI_AttrType`.
#[derive(Clone, Copy, Debug)]
pub struct AttrType;

impl AttrType {
    /// `XLA_FFI_AttrType_ARRAY`.
    pub const ARRAY: c_int = 1;
    /// `XLA_FFI_AttrType_DICTIONARY`.
    pub const DICTIONARY: c_int = 2;
    /// `XLA_FFI_AttrType_SCALAR`.
    pub const SCALAR: c_int = 3;
    /// `XLA_FFI_AttrType_STRING`.
    pub const STRING: c_int = 4;
}

/// `XLA_FFI_CallFrame`, through `attrs` (newer releases append a future).
#[repr(C)]
#[derive(Debug)]
pub struct CallFrame {
    /// XLA's size of the frame (at least this mirror's).
    pub struct_size: usize,
    /// A [`MetadataExtension`] in a metadata query; else null or extensions not read.
    pub extension_start: *mut ExtensionBase,
    /// The API table.
    pub api: *const Api,
    /// `XLA_FFI_ExecutionContext` (passed to `XLA_FFI_Stream_Get`).
    pub ctx: *mut c_void,
    /// `XLA_FFI_ExecutionStage` ([`STAGE_EXECUTE`] is the only one that runs anything).
    pub stage: c_int,
    /// The operands.
    pub args: Args,
    /// The results.
    pub rets: Rets,
    /// The attributes.
    pub attrs: Attrs,
}

/// `XLA_FFI_ExecutionStage_EXECUTE` (the others, instantiate, prepare and initialize, have
/// nothing to do here).
pub const STAGE_EXECUTE: c_int = 3;

/// `XLA_FFI_DataType` values (`xla_data.proto`'s `PrimitiveType`).
#[derive(Clone, Copy, Debug)]
pub struct DataType;

impl DataType {
    /// `PRED` (bool).
    pub const PRED: c_int = 1;
    /// `S8`.
    pub const S8: c_int = 2;
    /// `S16`.
    pub const S16: c_int = 3;
    /// `S32`.
    pub const S32: c_int = 4;
    /// `S64`.
    pub const S64: c_int = 5;
    /// `U8`.
    pub const U8: c_int = 6;
    /// `U16`.
    pub const U16: c_int = 7;
    /// `U32`.
    pub const U32: c_int = 8;
    /// `U64`.
    pub const U64: c_int = 9;
    /// `F16`.
    pub const F16: c_int = 10;
    /// `F32`.
    pub const F32: c_int = 11;
    /// `F64`.
    pub const F64: c_int = 12;
    /// `BF16`.
    pub const BF16: c_int = 16;

    /// The XLA code of `d`.
    pub fn of(d: Dtype) -> c_int {
        match d {
            Dtype::Bool => Self::PRED,
            Dtype::I8 => Self::S8,
            Dtype::I16 => Self::S16,
            Dtype::I32 => Self::S32,
            Dtype::I64 => Self::S64,
            Dtype::U8 => Self::U8,
            Dtype::U16 => Self::U16,
            Dtype::U32 => Self::U32,
            Dtype::U64 => Self::U64,
            Dtype::F16 => Self::F16,
            Dtype::Bf16 => Self::BF16,
            Dtype::F32 => Self::F32,
            Dtype::F64 => Self::F64,
        }
    }

    /// The dtype of XLA code `code`, if an op can take it.
    pub fn dtype(code: c_int) -> Option<Dtype> {
        [
            Dtype::Bool,
            Dtype::I8,
            Dtype::I16,
            Dtype::I32,
            Dtype::I64,
            Dtype::U8,
            Dtype::U16,
            Dtype::U32,
            Dtype::U64,
            Dtype::F16,
            Dtype::Bf16,
            Dtype::F32,
            Dtype::F64,
        ]
        .into_iter()
        .find(|&d| Self::of(d) == code)
    }
}

/// How a message names an XLA dtype code.
fn dtype_name(code: c_int) -> String {
    match (DataType::dtype(code), code) {
        (Some(d), _) => d.name().to_string(),
        (None, 15) => "complex64".into(),
        (None, 18) => "complex128".into(),
        (None, 17) => "token".into(),
        (None, c) => format!("XLA dtype {c}"),
    }
}

/// `XLA_FFI_Error_Code`, the codes the handlers return.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(i32)]
pub enum ErrorCode {
    /// `UNKNOWN` (2): a runtime error (CUDA's, a kernel fault).
    Unknown = 2,
    /// `INVALID_ARGUMENT` (3): attributes, buffers, the op's checks.
    InvalidArgument = 3,
    /// `FAILED_PRECONDITION` (9): the API table, no CUDA.
    FailedPrecondition = 9,
    /// `INTERNAL` (13): a panic.
    Internal = 13,
}

// ---------------------------------------------------------------------------------------------
// The handlers and their seam
// ---------------------------------------------------------------------------------------------

/// Forward or backward.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Direction {
    /// The op's forward.
    Forward,
    /// The op's backward (§6 of the design: the kernel's adjoint, or the body's tape).
    Backward,
}

/// How XLA may run a target.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Capturable into XLA's command buffers (`COMMAND_BUFFER_COMPATIBLE` on `CUDA`): kernel
    /// ops, launched on XLA's stream in the caller-ordered mode.
    Graph,
    /// Run outside command buffers: computation ops (their bodies may allocate), and kernel ops
    /// in debug mode. On `CUDA` the stream is joined with this crate's default stream.
    Eager,
}

/// The signature of an XLA FFI handler (`XLA_FFI_Handler`).
pub type HandlerFn = unsafe extern "C" fn(*mut CallFrame) -> *mut XlaError;

/// One native handler, for the glue to register with JAX: wrap `handler` in a PyCapsule with
/// a NULL name (what `jax.ffi.pycapsule` makes) and call
/// `jax.ffi.register_ffi_target(f"warp_lang.{module}.{target}", capsule, platform=platform,
/// api_version=1)`. The module name keeps two extension modules (each with its own registry)
/// apart.
#[derive(Clone, Copy, Debug)]
pub struct FfiHandler {
    /// `fwd.graph`, `fwd.eager`, `bwd.graph` or `bwd.eager`.
    pub target: &'static str,
    /// JAX's platform name: `cpu` or `CUDA`.
    pub platform: &'static str,
    /// Forward or backward.
    pub direction: Direction,
    /// Graph or eager.
    pub mode: Mode,
    /// The handler.
    pub handler: HandlerFn,
}

/// The eight handlers: {fwd, bwd} × {graph, eager} × {cpu, CUDA}. Each is stateless and may be
/// called from any thread, any number at once.
pub fn handlers() -> &'static [FfiHandler] {
    use Direction::{Backward, Forward};
    use Mode::{Eager, Graph};
    const fn h(
        target: &'static str,
        platform: &'static str,
        direction: Direction,
        mode: Mode,
        handler: HandlerFn,
    ) -> FfiHandler {
        FfiHandler {
            target,
            platform,
            direction,
            mode,
            handler,
        }
    }
    static HANDLERS: [FfiHandler; 8] = [
        h(
            "fwd.graph",
            "cpu",
            Forward,
            Graph,
            handle::<false, true, false>,
        ),
        h(
            "fwd.eager",
            "cpu",
            Forward,
            Eager,
            handle::<false, false, false>,
        ),
        h(
            "bwd.graph",
            "cpu",
            Backward,
            Graph,
            handle::<true, true, false>,
        ),
        h(
            "bwd.eager",
            "cpu",
            Backward,
            Eager,
            handle::<true, false, false>,
        ),
        h(
            "fwd.graph",
            "CUDA",
            Forward,
            Graph,
            handle::<false, true, true>,
        ),
        h(
            "fwd.eager",
            "CUDA",
            Forward,
            Eager,
            handle::<false, false, true>,
        ),
        h(
            "bwd.graph",
            "CUDA",
            Backward,
            Graph,
            handle::<true, true, true>,
        ),
        h(
            "bwd.eager",
            "CUDA",
            Backward,
            Eager,
            handle::<true, false, true>,
        ),
    ];
    &HANDLERS
}

/// The handler for `target` (`fwd.graph`, ..) on `platform` (`cpu` or `CUDA`).
pub fn handler(target: &str, platform: &str) -> Option<HandlerFn> {
    handlers()
        .iter()
        .find(|h| h.target == target && h.platform == platform)
        .map(|h| h.handler)
}

/// What one operand or result of a handler call holds (parameter positions are the op's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// Parameter `k`'s value: an input (operand); an output or scratch (a forward's result,
    /// zeroed first when the spec says so); a forward output's value (a kernel op backward's
    /// operand, read by the adjoint's replay).
    Value(usize),
    /// The cotangent of output `k` (a backward's operand; read only).
    Cotangent(usize),
    /// The gradient of input `k` (a backward's result, zeroed, then added to).
    Grad(usize),
    /// A copy of output `k`'s cotangent (a backward's result, discarded): the adjoint reads
    /// and clears an output's gradient, and an operand is XLA's, read only.
    CotangentCopy(usize),
    /// Output or scratch `k` of a computation op backward's replay (a result, discarded).
    Replay(usize),
}

/// The operands and results of one op's call of a [`Direction`], in order: what the glue's
/// `ffi_call` passes and allocates (every result's dtype and trailing shape is its
/// parameter's; its leading shape: a forward output's from [`Op::shapes`], a gradient,
/// cotangent copy or replay buffer like its parameter's value).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Layout {
    /// The operands.
    pub operands: Vec<Slot>,
    /// The results.
    pub results: Vec<Slot>,
}

/// The call layout of `op` in `direction`:
///
/// - forward: operands the inputs; results the outputs and scratch arrays (parameter order).
/// - kernel op backward: operands the inputs, the outputs' values, then the cotangent of each
///   differentiable output; results the gradient of each differentiable input, then a copy
///   of each cotangent.
/// - computation op backward: operands the inputs, then the cotangents; results the input
///   gradients, the cotangent copies, then a replay buffer for every output and scratch
///   array (the replay recomputes the outputs; scratch gradients are this crate's).
pub fn layout(op: &Op, direction: Direction) -> Layout {
    let p = &op.spec().params;
    let with = |f: &dyn Fn(&super::ParamSpec) -> bool| -> Vec<usize> {
        (0..p.len()).filter(|&k| f(&p[k])).collect()
    };
    let inputs = with(&|q| q.role == Role::Input);
    let made = with(&|q| matches!(q.role, Role::Output | Role::Scratch));
    let outs = with(&|q| q.role == Role::Output);
    let diff_in = with(&|q| q.role == Role::Input && q.differentiable);
    let diff_out = with(&|q| q.role == Role::Output && q.differentiable);
    let map = |v: &[usize], f: fn(usize) -> Slot| v.iter().map(|&k| f(k)).collect::<Vec<_>>();
    match direction {
        Direction::Forward => Layout {
            operands: map(&inputs, Slot::Value),
            results: map(&made, Slot::Value),
        },
        Direction::Backward => {
            let mut operands = map(&inputs, Slot::Value);
            if !op.is_computation() {
                operands.extend(map(&outs, Slot::Value));
            }
            operands.extend(map(&diff_out, Slot::Cotangent));
            let mut results = map(&diff_in, Slot::Grad);
            results.extend(map(&diff_out, Slot::CotangentCopy));
            if op.is_computation() {
                results.extend(map(&made, Slot::Replay));
            }
            Layout { operands, results }
        }
    }
}

/// A handler's refusal: a code and the message.
#[derive(Debug)]
struct Fail {
    code: ErrorCode,
    msg: String,
}

fn invalid(msg: impl Into<String>) -> Fail {
    Fail {
        code: ErrorCode::InvalidArgument,
        msg: msg.into(),
    }
}

fn precondition(msg: impl Into<String>) -> Fail {
    Fail {
        code: ErrorCode::FailedPrecondition,
        msg: msg.into(),
    }
}

impl From<Error> for Fail {
    fn from(e: Error) -> Fail {
        let code = match &e {
            Error::InvalidArgument { .. }
            | Error::ShapeMismatch { .. }
            | Error::InvalidDim { .. }
            | Error::NotDifferentiable { .. }
            | Error::DeviceMismatch { .. } => ErrorCode::InvalidArgument,
            Error::NoDevice { .. } => ErrorCode::FailedPrecondition,
            _ => ErrorCode::Unknown,
        };
        let mut msg = e.to_string();
        let mut source = std::error::Error::source(&e);
        while let Some(s) = source {
            msg += &format!(": {s}");
            source = s.source();
        }
        Fail { code, msg }
    }
}

/// The generic handler: `BWD` backward, `GRAPH` the graph target, `CUDA` the platform.
///
/// # Safety
/// `frame` is XLA's call frame for this call (or a metadata query), valid for the call.
unsafe extern "C" fn handle<const BWD: bool, const GRAPH: bool, const CUDA: bool>(
    frame: *mut CallFrame,
) -> *mut XlaError {
    let target = format!(
        "warp_lang {}.{} ({})",
        if BWD { "bwd" } else { "fwd" },
        if GRAPH { "graph" } else { "eager" },
        if CUDA { "CUDA" } else { "cpu" }
    );
    // Only the table's prefix is trusted until checked; a frame without a usable table has no
    // way to report an error (XLA always passes one).
    // SAFETY: the caller's contract; `api` is the third field of every layout of the frame.
    let api = match unsafe { frame.as_ref() }.map(|f| f.api) {
        Some(a) if !a.is_null() => a,
        _ => fatal(&target, "the call frame or its XLA_FFI_Api is null"),
    };
    // SAFETY: XLA's table lives for the process; its first field is its size.
    let api_size = unsafe { (*api).struct_size };
    let mut op_name: Option<String> = None;
    let run = AssertUnwindSafe(|| -> Result<(), Fail> {
        check_api(api)?;
        // SAFETY: the caller's contract; the table was checked.
        unsafe { call(frame, BWD, GRAPH, CUDA, &mut op_name) }
    });
    let fail = match catch_unwind(run) {
        Ok(Ok(())) => return std::ptr::null_mut(),
        Ok(Err(f)) => f,
        Err(p) => {
            let what = p
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| p.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "a panic without a message".into());
            Fail {
                code: ErrorCode::Internal,
                msg: format!("panicked: {what}"),
            }
        }
    };
    let op = op_name.map(|n| format!(" op {n}:")).unwrap_or_default();
    let msg = format!("{target}:{op} {}", fail.msg);
    if api_size < API_ERROR_CREATE_END {
        fatal(&target, &msg);
    }
    // SAFETY: the table is at least large enough to hold XLA_FFI_Error_Create.
    unsafe { create_error(api, fail.code, &msg) }
}

/// The end of a call that cannot report an error through XLA (no usable API table): the
/// message to standard error, then abort (returning null would claim success, and unwinding
/// into XLA is undefined).
fn fatal(target: &str, msg: &str) -> ! {
    eprintln!("{target}: cannot report an error to XLA ({msg}); aborting");
    std::process::abort()
}

/// An XLA error made by the table's `XLA_FFI_Error_Create`.
///
/// # Safety
/// `api` is a table of at least [`API_ERROR_CREATE_END`] bytes.
unsafe fn create_error(api: *const Api, code: ErrorCode, msg: &str) -> *mut XlaError {
    let text = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    let mut args = ErrorCreateArgs {
        struct_size: size_of::<ErrorCreateArgs>(),
        extension_start: std::ptr::null_mut(),
        message: text.as_ptr(),
        errc: code as c_int,
    };
    // SAFETY: the field lies inside the table (the caller's contract).
    let create = unsafe { std::ptr::addr_of!((*api).error_create).read() };
    match create {
        // SAFETY: XLA's function; it copies the message.
        Some(f) => unsafe { f(&mut args) },
        None => fatal(
            "warp_lang",
            &format!("XLA_FFI_Error_Create is null ({msg})"),
        ),
    }
}

/// Checks the API table before anything but its size is read.
fn check_api(api: *const Api) -> Result<(), Fail> {
    // SAFETY: the first field of every table.
    let size = unsafe { (*api).struct_size };
    if size < API_PREFIX_SIZE {
        return Err(precondition(format!(
            "the XLA_FFI_Api table has {size} bytes; warp-lang reads its first {API_PREFIX_SIZE} \
             (through XLA_FFI_Stream_Get, the layout of XLA FFI API {}.{} and later): this jaxlib \
             is older than the layout warp-lang was written for",
            HANDLER_API_VERSION.0, HANDLER_API_VERSION.1
        )));
    }
    // SAFETY: the table holds the prefix.
    let v = unsafe { &(*api).api_version };
    if v.major_version != HANDLER_API_VERSION.0 {
        return Err(precondition(format!(
            "XLA FFI API version {}.{}; warp-lang's handlers were written for {}.{} (major \
             version {}): the table's layout may differ",
            v.major_version,
            v.minor_version,
            HANDLER_API_VERSION.0,
            HANDLER_API_VERSION.1,
            HANDLER_API_VERSION.0
        )));
    }
    Ok(())
}

/// A decoded attribute.
enum Attr {
    Scalar {
        dtype: c_int,
        value: *const c_void,
    },
    Array {
        dtype: c_int,
        size: usize,
        data: *const c_void,
    },
    Other(c_int),
}

fn attr_kind(a: &Attr) -> String {
    match a {
        Attr::Scalar { dtype, .. } => {
            let name = dtype_name(*dtype);
            // "an int32", "a float64", "a uint8".
            let article = if name.starts_with('i') { "an" } else { "a" };
            format!("{article} {name} scalar")
        }
        Attr::Array { dtype, size, .. } => {
            format!("an array of {size} {}", dtype_name(*dtype))
        }
        Attr::Other(AttrType::ARRAY) => "an array".into(),
        Attr::Other(AttrType::DICTIONARY) => "a dictionary".into(),
        Attr::Other(AttrType::STRING) => "a string".into(),
        Attr::Other(t) => format!("an attribute of XLA type {t}"),
    }
}

/// `n` items of `ptr` (none when `n` is 0, whatever `ptr` is).
///
/// # Safety
/// For `n > 0`, `ptr` addresses `n` valid items for the call.
unsafe fn items<'a, T>(ptr: *const T, n: i64, what: &str) -> Result<&'a [T], Fail> {
    let n = usize::try_from(n).map_err(|_| invalid(format!("{what}: a count of {n}")))?;
    if n == 0 {
        return Ok(&[]);
    }
    if ptr.is_null() {
        return Err(invalid(format!("{what}: {n} entries at a null address")));
    }
    // SAFETY: the caller's contract.
    Ok(unsafe { std::slice::from_raw_parts(ptr, n) })
}

/// The call's attributes by name.
///
/// # Safety
/// `attrs` is XLA's for the call.
unsafe fn read_attrs(attrs: &Attrs) -> Result<Vec<(String, Attr)>, Fail> {
    // SAFETY: XLA's arrays of `size` entries.
    let (types, names, values) = unsafe {
        (
            items(attrs.types, attrs.size, "attributes (types)")?,
            items(attrs.names, attrs.size, "attributes (names)")?,
            items(attrs.attrs, attrs.size, "attributes (values)")?,
        )
    };
    let mut out = Vec::with_capacity(types.len());
    for ((&t, &n), &v) in types.iter().zip(names).zip(values) {
        // SAFETY: XLA's name span.
        let name = match unsafe { n.as_ref() } {
            Some(s) if s.len == 0 => String::new(),
            Some(s) if !s.ptr.is_null() => {
                // SAFETY: `len` bytes at `ptr`.
                let b = unsafe { std::slice::from_raw_parts(s.ptr.cast::<u8>(), s.len) };
                String::from_utf8_lossy(b).into_owned()
            }
            _ => return Err(invalid("an attribute without a name")),
        };
        let a = match t {
            AttrType::SCALAR => {
                // SAFETY: a scalar attribute points to an XLA_FFI_Scalar.
                let s = unsafe { v.cast::<Scalar>().as_ref() }
                    .ok_or_else(|| invalid(format!("attribute '{name}' is null")))?;
                Attr::Scalar {
                    dtype: s.dtype,
                    value: s.value,
                }
            }
            AttrType::ARRAY => {
                // SAFETY: an array attribute points to an XLA_FFI_Array.
                let a = unsafe { v.cast::<ArrayAttr>().as_ref() }
                    .ok_or_else(|| invalid(format!("attribute '{name}' is null")))?;
                if a.size > 0 && a.data.is_null() {
                    return Err(invalid(format!(
                        "attribute '{name}': {} elements at a null address",
                        a.size
                    )));
                }
                Attr::Array {
                    dtype: a.dtype,
                    size: a.size,
                    data: a.data,
                }
            }
            t => Attr::Other(t),
        };
        out.push((name, a));
    }
    Ok(out)
}

/// The value of a scalar attribute of XLA dtype `dtype` at `value`, if it is `want`.
///
/// # Safety
/// `value` addresses a value of `dtype`.
unsafe fn scalar_value(dtype: c_int, value: *const c_void, want: Dtype) -> Option<Value> {
    if DataType::of(want) != dtype || value.is_null() {
        return None;
    }
    // SAFETY (each read): the caller's contract; unaligned reads, since XLA promises none.
    let v = unsafe {
        match want {
            Dtype::Bool => Value::Bool(value.cast::<u8>().read() != 0),
            Dtype::I8 => Value::Int(value.cast::<i8>().read().into()),
            Dtype::I16 => Value::Int(value.cast::<i16>().read_unaligned().into()),
            Dtype::I32 => Value::Int(value.cast::<i32>().read_unaligned().into()),
            Dtype::I64 => Value::Int(value.cast::<i64>().read_unaligned()),
            Dtype::U8 => Value::Int(value.cast::<u8>().read().into()),
            Dtype::U16 => Value::Int(value.cast::<u16>().read_unaligned().into()),
            Dtype::U32 => Value::Int(value.cast::<u32>().read_unaligned().into()),
            // A u64 beyond i64 is refused by the range check as a negative.. so name it.
            Dtype::U64 => Value::Int(i64::try_from(value.cast::<u64>().read_unaligned()).ok()?),
            Dtype::F16 => Value::Float(
                warp_core::f16::from_bits(value.cast::<u16>().read_unaligned()).to_f64(),
            ),
            Dtype::Bf16 => Value::Float(
                warp_core::bf16::from_bits(value.cast::<u16>().read_unaligned()).to_f64(),
            ),
            Dtype::F32 => Value::Float(value.cast::<f32>().read_unaligned().into()),
            Dtype::F64 => Value::Float(value.cast::<f64>().read_unaligned()),
        }
    };
    Some(v)
}

/// The call's buffers of one list (operands or results) as [`Buffer`]s.
///
/// # Safety
/// `types` and `ptrs` are XLA's for the call.
unsafe fn read_buffers(
    types: *const c_int,
    ptrs: *const *mut c_void,
    n: i64,
    what: &str,
) -> Result<Vec<Buffer>, Fail> {
    // SAFETY: XLA's arrays of `n` entries.
    let (types, ptrs) = unsafe { (items(types, n, what)?, items(ptrs, n, what)?) };
    let mut out = Vec::with_capacity(ptrs.len());
    for (i, (&t, &p)) in types.iter().zip(ptrs).enumerate() {
        if t != BUFFER {
            return Err(invalid(format!(
                "{what} {i} has XLA type {t}, not a buffer"
            )));
        }
        // SAFETY: a buffer entry points to an XLA_FFI_Buffer.
        let b = unsafe { p.cast::<FfiBuffer>().as_ref() }
            .ok_or_else(|| invalid(format!("{what} {i} is null")))?;
        if b.struct_size < size_of::<FfiBuffer>() {
            return Err(precondition(format!(
                "{what} {i}: an XLA_FFI_Buffer of {} bytes; warp-lang reads {}",
                b.struct_size,
                size_of::<FfiBuffer>()
            )));
        }
        let dtype = DataType::dtype(b.dtype).ok_or_else(|| {
            invalid(format!(
                "{what} {i}: a {} buffer; ops take bool, integers, float16, bfloat16, \
                 float32 and float64",
                dtype_name(b.dtype)
            ))
        })?;
        // SAFETY: `rank` extents at `dims`.
        let dims = unsafe { items(b.dims.cast_const(), b.rank, what)? };
        let dims = dims
            .iter()
            .map(|&d| usize::try_from(d))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|_| invalid(format!("{what} {i}: extents {dims:?}")))?;
        out.push(Buffer::contiguous(b.data as u64, &dims, dtype));
    }
    Ok(out)
}

/// One call (not a metadata query's answer only): decode, check, run.
///
/// # Safety
/// `frame` is XLA's for the call; its API table was checked.
unsafe fn call(
    frame: *mut CallFrame,
    bwd: bool,
    graph: bool,
    cuda: bool,
    op_name: &mut Option<String>,
) -> Result<(), Fail> {
    // SAFETY: the caller's contract.
    let f = unsafe { &*frame };
    if f.struct_size < size_of::<CallFrame>() {
        return Err(precondition(format!(
            "an XLA_FFI_CallFrame of {} bytes; warp-lang reads {} (through its attributes)",
            f.struct_size,
            size_of::<CallFrame>()
        )));
    }
    // The metadata query: the version, and whether XLA may capture the target.
    let mut ext = f.extension_start;
    // SAFETY (the loop): XLA's chain of extensions, each starting with its base.
    while let Some(e) = unsafe { ext.as_ref() } {
        if e.kind == EXTENSION_METADATA {
            // SAFETY: a metadata extension.
            let m = unsafe { &*ext.cast::<MetadataExtension>() };
            // SAFETY: XLA's answer struct, or null.
            let md = unsafe { m.metadata.as_mut() }
                .ok_or_else(|| invalid("the metadata query has a null XLA_FFI_Metadata"))?;
            if md.struct_size < METADATA_STRUCT_SIZE {
                return Err(precondition(format!(
                    "an XLA_FFI_Metadata of {} bytes; warp-lang writes {}",
                    md.struct_size, METADATA_STRUCT_SIZE
                )));
            }
            md.api_version = ApiVersion {
                struct_size: size_of::<ApiVersion>(),
                extension_start: std::ptr::null_mut(),
                major_version: HANDLER_API_VERSION.0,
                minor_version: HANDLER_API_VERSION.1,
            };
            md.traits = match graph && cuda {
                true => TRAIT_COMMAND_BUFFER_COMPATIBLE,
                false => 0,
            };
            return Ok(());
        }
        ext = e.next;
    }
    if f.stage != STAGE_EXECUTE {
        return Ok(());
    }
    // SAFETY: XLA's attributes.
    let attrs = unsafe { read_attrs(&f.attrs)? };
    let given = || {
        attrs
            .iter()
            .map(|(n, _)| n.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let id = match attrs.iter().find(|(n, _)| n == "warp_op") {
        None => {
            return Err(invalid(format!(
                "the attribute 'warp_op' (the op's id, an int64 scalar) is missing; the call \
                 has [{}]",
                given()
            )))
        }
        // SAFETY: XLA's scalar.
        Some((_, a)) => match a {
            Attr::Scalar { dtype, value } => unsafe { scalar_value(*dtype, *value, Dtype::I64) },
            Attr::Array { .. } | Attr::Other(_) => None,
        }
        .and_then(|v| match v {
            Value::Int(i) => u64::try_from(i).ok(),
            _ => None,
        })
        .ok_or_else(|| {
            invalid(format!(
                "the attribute 'warp_op' is {}; it must be an int64 scalar (the op's id, \
                 non-negative)",
                attr_kind(a)
            ))
        })?,
    };
    let op = super::registered(id).map_err(Fail::from)?;
    *op_name = Some(op.name().to_string());
    let spec = op.spec();
    if graph && op.is_computation() {
        return Err(invalid(
            "a computation op runs through the eager targets (its body may allocate and \
             synchronise, which a command buffer cannot hold), not the graph ones",
        ));
    }
    // Values by parameter name, each of exactly its dtype: a scalar's one, a vector's or
    // matrix's components (an array attribute of as many).
    let mut values: Vec<Given> = (0..spec.params.len()).map(|_| Given::None).collect();
    for (k, p) in spec.params.iter().enumerate() {
        let ArgKind::Value { dtype, element, .. } = p.kind else {
            continue;
        };
        let count: usize = element.iter().product();
        let what = if element.is_empty() {
            "scalar"
        } else {
            "value"
        };
        let want = match element {
            [] => format!("a {} scalar", dtype.name()),
            _ => format!(
                "an array of {count} {} ({})",
                dtype.name(),
                p.kind.describe()
            ),
        };
        let a = attrs.iter().find(|(n, _)| n == p.name).map(|(_, a)| a);
        let Some(a) = a else {
            return Err(invalid(format!(
                "{what} '{}' ({k}): no attribute '{}' ({want}); the call has [{}]",
                p.name,
                p.name,
                given()
            )));
        };
        let v = match (a, element.is_empty()) {
            // SAFETY: XLA's scalar.
            (Attr::Scalar { dtype: d, value }, true) => {
                unsafe { scalar_value(*d, *value, dtype) }.map(Given::One)
            }
            (
                Attr::Array {
                    dtype: d,
                    size,
                    data,
                },
                false,
            ) if *size == count => (0..count)
                .map(|i| {
                    // SAFETY: XLA's array of `size` elements of `d`; `scalar_value` refuses a
                    // `d` other than `dtype` before reading, so `i` steps by `dtype`'s size.
                    let at = unsafe { data.cast::<u8>().add(i * dtype.size()) };
                    unsafe { scalar_value(*d, at.cast(), dtype) }
                })
                .collect::<Option<Vec<Value>>>()
                .map(Given::Components),
            _ => None,
        };
        let hint = match element {
            [] => format!("np.{}(value)", dtype.name()),
            _ => format!("np.asarray(value, np.{}).ravel()", dtype.name()),
        };
        values[k] = v.ok_or_else(|| {
            invalid(format!(
                "{what} '{}' ({k}): the attribute is {}; the kernel takes {want} (pass {hint})",
                p.name,
                attr_kind(a),
            ))
        })?;
    }
    if let Some((n, _)) = attrs
        .iter()
        .find(|(n, _)| n != "warp_op" && spec.param(n).is_none_or(|(_, p)| p.role != Role::Scalar))
    {
        let scalars: Vec<&str> = spec.with_role(Role::Scalar).map(|(_, p)| p.name).collect();
        return Err(invalid(format!(
            "unknown attribute '{n}'; the op's values are [{}] (and warp_op)",
            scalars.join(", ")
        )));
    }
    // SAFETY: XLA's operands and results.
    let (operands, results) = unsafe {
        (
            read_buffers(f.args.types, f.args.args, f.args.size, "operand")?,
            read_buffers(f.rets.types, f.rets.rets, f.rets.size, "result")?,
        )
    };
    let dir = if bwd {
        Direction::Backward
    } else {
        Direction::Forward
    };
    let lay = layout(&op, dir);
    if operands.len() != lay.operands.len() || results.len() != lay.results.len() {
        let names = |v: &[Slot]| {
            v.iter()
                .map(|s| slot_name(&op, *s))
                .collect::<Vec<_>>()
                .join(", ")
        };
        return Err(invalid(format!(
            "{} operands and {} results; the {} takes operands [{}] and results [{}]",
            operands.len(),
            results.len(),
            if bwd { "backward" } else { "forward" },
            names(&lay.operands),
            names(&lay.results)
        )));
    }
    let all: Vec<&Buffer> = operands.iter().chain(&results).collect();
    // SAFETY: XLA's frame, table checked.
    let exec_owner = unsafe { Launch::new(f, cuda, graph, &all)? };
    let exec = exec_owner.exec();
    // Arguments in parameter order, gradients beside them.
    let mut args: Vec<CallArg<'_>> = values.iter().map(Given::arg).collect();
    let mut grads: Vec<Option<&Buffer>> = vec![None; spec.params.len()];
    let mut cotangents: Vec<Option<&Buffer>> = vec![None; spec.params.len()];
    for (s, b) in lay.operands.iter().zip(&operands) {
        match *s {
            Slot::Value(k) => args[k] = CallArg::Buffer(b),
            Slot::Cotangent(k) => cotangents[k] = Some(b),
            _ => unreachable!("layout: operands are values and cotangents"),
        }
    }
    // Results: zeroed where the spec says, cotangents copied.
    for (s, b) in lay.results.iter().zip(&results) {
        match *s {
            Slot::Value(k) | Slot::Replay(k) => {
                let p = &spec.params[k];
                if p.zeroed || p.role == Role::Scratch {
                    exec_owner.zero(b, &spec.name, p.name)?;
                }
                args[k] = CallArg::Buffer(b);
            }
            Slot::Grad(k) => {
                exec_owner.zero(b, &spec.name, spec.params[k].name)?;
                grads[k] = Some(b);
            }
            Slot::CotangentCopy(k) => {
                let c = cotangents[k].expect("layout: every copy has its cotangent");
                exec_owner.copy_broadcast(c, b, &spec.name, spec.params[k].name)?;
                grads[k] = Some(b);
            }
            Slot::Cotangent(_) => unreachable!("layout: cotangents are operands"),
        }
    }
    // SAFETY: XLA's buffers are valid memory of the call's device for the call, ordered by
    // its stream (or done with, on the CPU, when the handler returns).
    unsafe {
        match bwd {
            false => op.forward_batched(&args, &exec),
            true => op.backward_batched(&args, &grads, &exec),
        }
    }
    .map_err(Fail::from)
}

/// How a message names a slot.
fn slot_name(op: &Op, s: Slot) -> String {
    let n = |k: usize| op.spec().params[k].name;
    match s {
        Slot::Value(k) => n(k).to_string(),
        Slot::Cotangent(k) => format!("cotangent of {}", n(k)),
        Slot::Grad(k) => format!("gradient of {}", n(k)),
        Slot::CotangentCopy(k) => format!("copy of {}'s cotangent", n(k)),
        Slot::Replay(k) => format!("replay of {}", n(k)),
    }
}

/// Bytes of a dense buffer.
fn bytes_of(b: &Buffer) -> Result<usize, Fail> {
    b.dims
        .iter()
        .try_fold(b.dtype.size(), |a, &d| a.checked_mul(d))
        .ok_or_else(|| invalid(format!("a buffer of shape {:?} overflows", b.dims)))
}

/// Where a call's launches, fills and copies go: the CPU, or XLA's stream on a GPU.
enum Launch {
    Cpu,
    #[cfg(feature = "cuda")]
    Cuda(crate::cuda::stream::Stream),
}

impl Launch {
    /// The call's place: on `CUDA`, XLA's stream (`XLA_FFI_Stream_Get`) on the device of the
    /// first buffer's address, caller-ordered for a graph target.
    ///
    /// # Safety
    /// `frame` is XLA's for the call; its table was checked.
    unsafe fn new(
        frame: &CallFrame,
        cuda: bool,
        graph: bool,
        buffers: &[&Buffer],
    ) -> Result<Launch, Fail> {
        if !cuda {
            return Ok(Launch::Cpu);
        }
        #[cfg(not(feature = "cuda"))]
        {
            let _ = (frame, graph, buffers);
            Err(precondition(
                "a CUDA call, and warp-lang was built without its `cuda` feature",
            ))
        }
        #[cfg(feature = "cuda")]
        {
            // SAFETY: the caller's contract.
            let stream = unsafe { cuda::xla_stream(frame)? };
            let first = buffers.iter().map(|b| b.ptr).find(|&p| p != 0);
            cuda::launch(stream, first, graph)
        }
    }

    fn exec(&self) -> Exec<'_> {
        match self {
            Launch::Cpu => Exec::cpu(),
            #[cfg(feature = "cuda")]
            Launch::Cuda(s) => Exec::stream(s),
        }
    }

    /// Zero-fills `b` (all of it, batch axes included).
    fn zero(&self, b: &Buffer, op: &str, param: &str) -> Result<(), Fail> {
        let n = bytes_of(b)?;
        if n == 0 {
            return Ok(());
        }
        match self {
            Launch::Cpu => {
                let _ = (op, param);
                // SAFETY: a result buffer of the call: `n` writable host bytes.
                unsafe { std::ptr::write_bytes(b.ptr as *mut u8, 0, n) };
                Ok(())
            }
            #[cfg(feature = "cuda")]
            Launch::Cuda(s) => {
                cuda_fill(s, b.ptr, n).map_err(|e| Fail::from(e).with(op, param, "zeroing"))
            }
        }
    }

    /// Copies cotangent `src` into result `dst` (same trailing axes; `src`'s leading batch
    /// axes may be 1 where `dst`'s are not: an unbatched cotangent under `vmap`).
    fn copy_broadcast(
        &self,
        src: &Buffer,
        dst: &Buffer,
        op: &str,
        param: &str,
    ) -> Result<(), Fail> {
        let bad = || {
            invalid(format!(
                "the cotangent of '{param}': a {} buffer of shape {:?}; its copy is a {} buffer \
                 of shape {:?} (the same, or 1 on leading batch axes)",
                src.dtype.name(),
                src.dims,
                dst.dtype.name(),
                dst.dims
            ))
        };
        if src.dtype != dst.dtype || src.dims.len() != dst.dims.len() {
            return Err(bad());
        }
        // The axes from `lead` on agree: each block from there is copied whole. Before it, a
        // cotangent's axis is the copy's or 1 (broadcast: read at index 0).
        let lead = src
            .dims
            .iter()
            .zip(&dst.dims)
            .rposition(|(s, d)| s != d)
            .map_or(0, |i| i + 1);
        if src.dims[..lead]
            .iter()
            .zip(&dst.dims[..lead])
            .any(|(&s, &d)| s != 1 && s != d)
        {
            return Err(bad());
        }
        let inner = dst.dims[lead..]
            .iter()
            .try_fold(dst.dtype.size(), |a, &d| a.checked_mul(d))
            .ok_or_else(bad)?;
        let count: usize = dst.dims[..lead].iter().product();
        if inner == 0 || count == 0 {
            return Ok(());
        }
        // The cotangent's row-major block strides over the leading axes (0 where broadcast).
        let mut strides = vec![0usize; lead];
        let mut step = inner;
        for d in (0..lead).rev() {
            strides[d] = if src.dims[d] == 1 { 0 } else { step };
            step *= src.dims[d];
        }
        for n in 0..count {
            let (mut rest, mut from) = (n, 0usize);
            for d in (0..lead).rev() {
                from += (rest % dst.dims[d]) * strides[d];
                rest /= dst.dims[d];
            }
            let (to, from) = (dst.ptr + (n * inner) as u64, src.ptr + from as u64);
            match self {
                Launch::Cpu => {
                    // SAFETY: `inner` bytes inside the cotangent (an operand) and inside block
                    // `n` of the result: distinct XLA buffers.
                    unsafe {
                        std::ptr::copy_nonoverlapping(from as *const u8, to as *mut u8, inner)
                    }
                }
                #[cfg(feature = "cuda")]
                Launch::Cuda(s) => {
                    cuda_copy(s, to, from, inner)
                        .map_err(|e| Fail::from(e).with(op, param, "copying the cotangent"))?;
                }
            }
        }
        let _ = (op, param);
        Ok(())
    }
}

impl Fail {
    /// The failure with what was being done, to which parameter.
    #[cfg_attr(not(feature = "cuda"), allow(dead_code))]
    fn with(self, op: &str, param: &str, doing: &str) -> Fail {
        Fail {
            code: self.code,
            msg: format!("{op}: {doing} '{param}': {}", self.msg),
        }
    }
}

#[cfg(feature = "cuda")]
mod cuda {
    //! The CUDA half: XLA's stream, the device of a buffer, fills and copies on the stream.

    use super::{precondition, Api, CallFrame, Fail, Launch, StreamGetArgs};
    use crate::cuda::stream::Stream;
    use crate::error::Result;
    use std::mem::size_of;

    /// XLA's stream of the call (`XLA_FFI_Stream_Get`).
    ///
    /// # Safety
    /// `frame` is XLA's; its table was checked.
    pub(super) unsafe fn xla_stream(
        frame: &CallFrame,
    ) -> std::result::Result<*mut std::ffi::c_void, Fail> {
        let api: *const Api = frame.api;
        // SAFETY: the checked prefix holds the field.
        let get = unsafe { (*api).stream_get }
            .ok_or_else(|| precondition("XLA_FFI_Stream_Get is null"))?;
        let mut args = StreamGetArgs {
            struct_size: size_of::<StreamGetArgs>(),
            extension_start: std::ptr::null_mut(),
            ctx: frame.ctx,
            stream: std::ptr::null_mut(),
        };
        // SAFETY: XLA's function with its arguments.
        let err = unsafe { get(&mut args) };
        if !err.is_null() {
            return Err(precondition(
                "XLA_FFI_Stream_Get returned an error (no stream for this call)",
            ));
        }
        Ok(args.stream)
    }

    /// The call's stream on the device of `ptr`: caller-ordered for a graph target, joined
    /// with this crate's default stream for an eager one.
    pub(super) fn launch(
        stream: *mut std::ffi::c_void,
        ptr: Option<u64>,
        graph: bool,
    ) -> std::result::Result<Launch, Fail> {
        let ordinal = match ptr {
            // A call without buffers launches nothing that needs a device: the first GPU.
            None => 0,
            Some(p) => warp_cuda::pointer_device_ordinal(p).ok_or_else(|| {
                super::invalid(format!(
                    "the buffer at {p:#x} is not device memory of any GPU (a CUDA call)"
                ))
            })?,
        };
        let device = crate::device::get_device(&format!("cuda:{ordinal}"))?;
        // SAFETY: XLA's stream of the call's device, alive for the call; a graph target's
        // buffers are all XLA's (ordered by the stream alone).
        let s = unsafe {
            match graph {
                true => Stream::from_raw_caller_ordered(stream, &device)?,
                false => Stream::from_raw(stream, &device, ())?,
            }
        };
        Ok(Launch::Cuda(s))
    }

    /// The GPU of `s` and a non-owning view of `bytes` bytes at `ptr`.
    fn view(s: &Stream, ptr: u64, bytes: usize) -> Result<warp_cuda::DeviceBuffer> {
        let ordinal = s.cuda_stream().ordinal();
        let st = crate::cuda::gpu_state(s.device(), ordinal)?;
        // SAFETY: XLA's memory of this device for the call; never freed by the view.
        Ok(unsafe { warp_cuda::DeviceBuffer::from_raw(&st.gpu, ptr, bytes) })
    }

    /// Zeroes `bytes` at `ptr` on `s` (`cuMemsetD8Async`: captured like a launch).
    pub(super) fn fill(s: &Stream, ptr: u64, bytes: usize) -> Result<()> {
        let b = view(s, ptr, bytes)?;
        b.fill_pattern_on(s.cuda_stream(), 0, bytes, &[0])
            .map_err(|e| crate::cuda::gpu_err(s.device(), e))
    }

    /// Copies `bytes` from `src` to `dst` on `s` (`cuMemcpyDtoDAsync`).
    pub(super) fn copy(s: &Stream, dst: u64, src: u64, bytes: usize) -> Result<()> {
        let d = view(s, dst, bytes)?;
        let from = view(s, src, bytes)?;
        d.copy_from_device_on(s.cuda_stream(), 0, &from, 0, bytes)
            .map_err(|e| crate::cuda::gpu_err(s.device(), e))
    }
}

#[cfg(feature = "cuda")]
use cuda::{copy as cuda_copy, fill as cuda_fill};

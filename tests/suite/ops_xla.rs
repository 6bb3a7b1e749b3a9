//! The XLA FFI handlers of ops (`warp_runtime::ops::xla_ffi`, issue 36's JAX half in Rust),
//! driven as XLA drives them but with a mock `XLA_FFI_Api` table written here (its
//! `XLA_FFI_Error_Create` records the code and message; its `XLA_FFI_Stream_Get` hands out a
//! stream of the test's) and call frames over arrays of the backend: the metadata query, the
//! attributes, forward and backward against the op's own calls and `wp::launch`, batching
//! against a loop of unbatched calls, and every refusal's code and message.
//!
//! Tolerances: a handler runs the very launches the op's own call runs, on the same data, so
//! every comparison is bit for bit (the sums below add integers in f64, exact in any order).

use crate::{arr, host, zeros};
use std::cell::Cell;
use std::ffi::{c_int, c_void, CStr};
use std::mem::size_of;
use std::sync::Arc;
use warp_lang as wp;
use warp_runtime::ops::xla_ffi::{
    self as x, Api, ApiVersion, ArrayAttr, AttrType, ByteSpan, CallFrame, DataType, Direction,
    ErrorCreateArgs, ExtensionBase, FfiBuffer, Metadata, MetadataExtension, Mode, Scalar, Slot,
    StreamGetArgs, XlaError,
};
use warp_runtime::ops::{Buffer, CallArg, Dtype, Exec, Op, Shape, Value, Vmap};
use wp::prelude::*;

backend_tests!(
    xla_handlers_and_metadata,
    xla_forward_matches_launch,
    xla_backward_matches_op_backward,
    xla_attribute_errors,
    xla_vector_values,
    xla_buffer_errors,
    xla_batched_matches_a_loop,
    xla_computation_op,
    xla_panics_become_errors,
    xla_api_table_checks,
);

// ---------------------------------------------------------------------------------------------
// The mock API table and call frames
// ---------------------------------------------------------------------------------------------

/// What the mock `XLA_FFI_Error_Create` made: the error the handler returned.
struct MockError {
    code: c_int,
    msg: String,
}

unsafe extern "C" fn mock_error_create(a: *mut ErrorCreateArgs) -> *mut XlaError {
    // SAFETY: the handler's arguments, a NUL-terminated message.
    let a = unsafe { &*a };
    assert_eq!(a.struct_size, size_of::<ErrorCreateArgs>());
    let msg = unsafe { CStr::from_ptr(a.message) }
        .to_string_lossy()
        .into_owned();
    Box::into_raw(Box::new(MockError { code: a.errc, msg })).cast()
}

thread_local! {
    /// The stream `mock_stream_get` hands out (a CUDA test's; null on the CPU).
    static STREAM: Cell<*mut c_void> = const { Cell::new(std::ptr::null_mut()) };
    /// How many times `mock_stream_get` was called on this thread.
    static STREAM_GETS: Cell<usize> = const { Cell::new(0) };
}

unsafe extern "C" fn mock_stream_get(a: *mut StreamGetArgs) -> *mut XlaError {
    STREAM_GETS.with(|n| n.set(n.get() + 1));
    // SAFETY: the handler's arguments.
    unsafe { (*a).stream = STREAM.with(|s| s.get()) };
    std::ptr::null_mut()
}

/// A table as a newer XLA has it: larger than the prefix the handlers read.
fn mock_api() -> Api {
    Api {
        struct_size: x::API_PREFIX_SIZE + 12 * size_of::<usize>(),
        extension_start: std::ptr::null_mut(),
        api_version: ApiVersion {
            struct_size: size_of::<ApiVersion>(),
            extension_start: std::ptr::null_mut(),
            major_version: 0,
            minor_version: 3,
        },
        internal_api: std::ptr::null_mut(),
        error_create: Some(mock_error_create),
        error_get_message: std::ptr::null_mut(),
        error_destroy: std::ptr::null_mut(),
        handler_register: std::ptr::null_mut(),
        stream_get: Some(mock_stream_get),
    }
}

/// An attribute of a call.
#[derive(Clone, Copy, Debug)]
enum A {
    I64(i64),
    I32(i32),
    F64(f64),
    F32(f32),
    /// An array attribute (of two f64).
    Array,
}

/// A handler's answer: `Err((code, message))` for an error.
type Answer = Result<(), (c_int, String)>;

/// Takes back what the mock made.
fn answer(e: *mut XlaError) -> Answer {
    if e.is_null() {
        return Ok(());
    }
    // SAFETY: made by `mock_error_create`, returned once.
    let e = unsafe { Box::from_raw(e.cast::<MockError>()) };
    Err((e.code, e.msg))
}

/// Calls `handler` as XLA's execute stage would: `operands`, `results` and `attrs` (sorted
/// by name, as XLA passes them), with `api` as the table.
fn invoke(
    handler: x::HandlerFn,
    api: &Api,
    operands: &[&Buffer],
    results: &[&Buffer],
    attrs: &[(&str, A)],
) -> Answer {
    invoke_frame(handler, api, operands, results, attrs, |_| {})
}

/// [`invoke`], with `edit` applied to the frame before the call.
fn invoke_frame(
    handler: x::HandlerFn,
    api: &Api,
    operands: &[&Buffer],
    results: &[&Buffer],
    attrs: &[(&str, A)],
    edit: impl FnOnce(&mut CallFrame),
) -> Answer {
    let code = |d: Dtype| DataType::of(d);
    let all: Vec<&Buffer> = operands.iter().chain(results).copied().collect();
    let mut dims: Vec<Vec<i64>> = all
        .iter()
        .map(|b| b.dims.iter().map(|&d| d as i64).collect())
        .collect();
    let mut bufs: Vec<FfiBuffer> = all
        .iter()
        .zip(dims.iter_mut())
        .map(|(b, d)| FfiBuffer {
            struct_size: size_of::<FfiBuffer>(),
            extension_start: std::ptr::null_mut(),
            dtype: code(b.dtype),
            data: b.ptr as *mut c_void,
            rank: d.len() as i64,
            dims: d.as_mut_ptr(),
        })
        .collect();
    let mut ptrs: Vec<*mut c_void> = bufs
        .iter_mut()
        .map(|b| b as *mut FfiBuffer as *mut c_void)
        .collect();
    let (op_ptrs, ret_ptrs) = ptrs.split_at_mut(operands.len());
    let mut arg_types = vec![x::BUFFER; operands.len()];
    let mut ret_types = vec![x::BUFFER; results.len()];
    // Attributes, sorted by name.
    let mut attrs = attrs.to_vec();
    attrs.sort_by(|a, b| a.0.cmp(b.0));
    let mut storage: Vec<u64> = vec![0; attrs.len()];
    let mut array_data = [1.0f64, 2.0];
    let mut array = ArrayAttr {
        dtype: DataType::F64,
        size: 2,
        data: array_data.as_mut_ptr().cast(),
    };
    let mut scalars: Vec<Scalar> = Vec::new();
    let mut types = Vec::new();
    for (k, (_, a)) in attrs.iter().enumerate() {
        let p = &mut storage[k] as *mut u64;
        // SAFETY: an 8-byte slot for each value.
        let dtype = unsafe {
            match *a {
                A::I64(v) => {
                    p.cast::<i64>().write(v);
                    DataType::S64
                }
                A::I32(v) => {
                    p.cast::<i32>().write(v);
                    DataType::S32
                }
                A::F64(v) => {
                    p.cast::<f64>().write(v);
                    DataType::F64
                }
                A::F32(v) => {
                    p.cast::<f32>().write(v);
                    DataType::F32
                }
                A::Array => 0,
            }
        };
        types.push(match a {
            A::Array => AttrType::ARRAY,
            _ => AttrType::SCALAR,
        });
        scalars.push(Scalar {
            dtype,
            value: p.cast(),
        });
    }
    let mut values: Vec<*mut c_void> = attrs
        .iter()
        .zip(scalars.iter_mut())
        .map(|((_, a), s)| match a {
            A::Array => &mut array as *mut ArrayAttr as *mut c_void,
            _ => s as *mut Scalar as *mut c_void,
        })
        .collect();
    let mut spans: Vec<ByteSpan> = attrs
        .iter()
        .map(|(n, _)| ByteSpan {
            ptr: n.as_ptr().cast(),
            len: n.len(),
        })
        .collect();
    let mut names: Vec<*mut ByteSpan> = spans.iter_mut().map(|s| s as *mut ByteSpan).collect();
    let mut frame = CallFrame {
        struct_size: size_of::<CallFrame>() + size_of::<usize>(),
        extension_start: std::ptr::null_mut(),
        api,
        ctx: std::ptr::null_mut(),
        stage: x::STAGE_EXECUTE,
        args: x::Args {
            struct_size: size_of::<x::Args>(),
            extension_start: std::ptr::null_mut(),
            size: operands.len() as i64,
            types: arg_types.as_mut_ptr(),
            args: op_ptrs.as_mut_ptr(),
        },
        rets: x::Rets {
            struct_size: size_of::<x::Rets>(),
            extension_start: std::ptr::null_mut(),
            size: results.len() as i64,
            types: ret_types.as_mut_ptr(),
            rets: ret_ptrs.as_mut_ptr(),
        },
        attrs: x::Attrs {
            struct_size: size_of::<x::Attrs>(),
            extension_start: std::ptr::null_mut(),
            size: attrs.len() as i64,
            types: types.as_mut_ptr(),
            names: names.as_mut_ptr(),
            attrs: values.as_mut_ptr(),
        },
    };
    edit(&mut frame);
    // SAFETY: a frame whose every pointer is alive until the handler returns.
    answer(unsafe { handler(&mut frame) })
}

/// The metadata query XLA makes when a target is registered: (version, traits).
fn metadata(handler: x::HandlerFn, api: &Api) -> ((c_int, c_int), u32) {
    let mut md = Metadata {
        // What XLA writes: the end of the last field, not the padded size.
        struct_size: x::METADATA_STRUCT_SIZE,
        api_version: ApiVersion {
            struct_size: 0,
            extension_start: std::ptr::null_mut(),
            major_version: -1,
            minor_version: -1,
        },
        traits: 0xdead,
    };
    let mut ext = MetadataExtension {
        extension_base: ExtensionBase {
            struct_size: size_of::<MetadataExtension>(),
            kind: x::EXTENSION_METADATA,
            next: std::ptr::null_mut(),
        },
        metadata: &mut md,
    };
    let r = invoke_frame(handler, api, &[], &[], &[], |f| {
        f.extension_start = &mut ext.extension_base;
    });
    r.unwrap();
    let v = &md.api_version;
    assert_eq!(v.struct_size, size_of::<ApiVersion>());
    ((v.major_version, v.minor_version), md.traits)
}

/// The platform of `dev` as JAX names it.
fn platform(dev: &wp::Device) -> &'static str {
    if dev.is_cpu() {
        "cpu"
    } else {
        "CUDA"
    }
}

/// The handler of `target` for `dev`'s platform.
fn handler(target: &str, dev: &wp::Device) -> x::HandlerFn {
    x::handler(target, platform(dev)).expect("a handler of every target and platform")
}

/// Runs `f` with `mock_stream_get` handing out a fresh stream of `dev` (a GPU; nothing on the
/// CPU), then synchronises it: XLA's stream of the call. The arrays were written on the
/// default stream: synchronised first.
fn on_xla_stream<R>(dev: &wp::Device, f: impl FnOnce() -> R) -> R {
    if dev.is_cpu() {
        let n = STREAM_GETS.with(|n| n.get());
        let r = f();
        assert_eq!(
            STREAM_GETS.with(|n| n.get()),
            n,
            "a CPU call asked for a stream"
        );
        return r;
    }
    #[cfg(feature = "cuda")]
    {
        wp::synchronize().unwrap();
        let s = wp::Stream::new(dev).unwrap();
        STREAM.with(|c| c.set(s.cuda_stream().cu_stream().cast()));
        let r = f();
        s.synchronize().unwrap();
        STREAM.with(|c| c.set(std::ptr::null_mut()));
        r
    }
    #[cfg(not(feature = "cuda"))]
    unreachable!("a GPU device without the cuda feature")
}

/// Runs `f` with the device's [`Exec`]: the CPU's, or on a GPU a caller-ordered stream (as a
/// framework's), synchronised before and after.
fn with_exec(dev: &wp::Device, f: impl FnOnce(&Exec<'_>)) {
    if dev.is_cpu() {
        return f(&Exec::cpu());
    }
    #[cfg(feature = "cuda")]
    {
        wp::synchronize().unwrap();
        let owner = wp::Stream::new(dev).unwrap();
        // SAFETY: a live stream of the device; the arrays were synchronised.
        let st = unsafe {
            wp::Stream::from_raw_caller_ordered(owner.cuda_stream().cu_stream().cast(), dev)
        }
        .unwrap();
        f(&Exec::stream(&st));
        st.synchronize().unwrap();
    }
}

/// A framework's buffer over `a`'s memory.
fn buf<T: wp::Element, const M: usize>(a: &wp::Array<T, M>, dtype: Dtype) -> Buffer {
    let ptr = if a.device().is_cpu() {
        a.as_mut_ptr().unwrap() as u64
    } else {
        a.device_ptr()
    };
    Buffer::contiguous(ptr, &a.shape(), dtype)
}

fn bits(v: &[f64]) -> Vec<u64> {
    v.iter().map(|x| x.to_bits()).collect()
}

// ---------------------------------------------------------------------------------------------
// Kernels and ops
// ---------------------------------------------------------------------------------------------

/// Two outputs, every gradient thread-owned.
#[wp::kernel]
fn kx_own(x: Array<f64>, s: f64, y: Array<f64>, z: Array<f64>) {
    let i = tid();
    y[i] = x[i] * x[i] * s + sin(x[i]);
    z[i] = x[i] * s - cos(x[i]);
}

/// `amp`'s gradient is every thread's; `total` a reduction (needs its zeroing).
#[wp::kernel]
fn kx_shared(x: Array<f64>, amp: Array<f64>, y: Array<f64>, total: Array<f64>) {
    let i = tid();
    y[i] = amp[0] * x[i] + amp[1];
    atomic_add(total, 0, x[i]);
}

fn own_op() -> Op {
    Op::kernel("xown", kx_own)
        .outputs(["y", "z"])
        .build()
        .unwrap()
}

fn shared_op() -> Op {
    Op::kernel("xshared", kx_shared)
        .outputs(["y", "total"])
        .shape("total", Shape::Fixed(vec![1]))
        .build()
        .unwrap()
}

const N: usize = 256;

/// Integers and halves: every product and sum below is exact in f64.
fn xs(k: usize) -> Vec<f64> {
    (0..N)
        .map(|i| ((i * 7 + k * 3) % 23) as f64 * 0.5 - 5.0)
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------------

fn xla_handlers_and_metadata(dev: &wp::Device) {
    let api = mock_api();
    let hs = x::handlers();
    assert_eq!(hs.len(), 8);
    let mut seen = std::collections::HashSet::new();
    for h in hs {
        assert!(
            seen.insert((h.target, h.platform)),
            "{} {}",
            h.target,
            h.platform
        );
        let want_target = format!(
            "{}.{}",
            if h.direction == Direction::Forward {
                "fwd"
            } else {
                "bwd"
            },
            if h.mode == Mode::Graph {
                "graph"
            } else {
                "eager"
            }
        );
        assert_eq!(h.target, want_target);
        assert!(["cpu", "CUDA"].contains(&h.platform));
        // Only a graph target on CUDA may be captured into a command buffer.
        let (version, traits) = metadata(h.handler, &api);
        assert_eq!(version, x::HANDLER_API_VERSION, "{want_target}");
        let capturable = h.mode == Mode::Graph && h.platform == "CUDA";
        assert_eq!(
            traits,
            if capturable {
                x::TRAIT_COMMAND_BUFFER_COMPATIBLE
            } else {
                0
            },
            "{} on {}",
            h.target,
            h.platform
        );
    }
    // Stages other than execute do nothing (no attributes, no buffers: still fine).
    for stage in [0, 1, 2] {
        let r = invoke_frame(handler("fwd.graph", dev), &api, &[], &[], &[], |f| {
            f.stage = stage
        });
        assert_eq!(r, Ok(()), "stage {stage}");
    }
    // The layouts the glue builds its calls by.
    let op = own_op();
    let l = x::layout(&op, Direction::Forward);
    assert_eq!(l.operands, [Slot::Value(0)]);
    assert_eq!(l.results, [Slot::Value(2), Slot::Value(3)]);
    let l = x::layout(&op, Direction::Backward);
    assert_eq!(
        l.operands,
        [
            Slot::Value(0),
            Slot::Value(2),
            Slot::Value(3),
            Slot::Cotangent(2),
            Slot::Cotangent(3)
        ]
    );
    assert_eq!(
        l.results,
        [
            Slot::Grad(0),
            Slot::CotangentCopy(2),
            Slot::CotangentCopy(3)
        ]
    );
}

fn xla_forward_matches_launch(dev: &wp::Device) {
    let api = mock_api();
    let (xh, s) = (xs(0), 0.75);
    let x = arr(&xh, dev);
    let (y1, z1) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
    wp::launch(kx_own, N, (&x, s, &y1, &z1), dev).unwrap();
    let op = own_op();
    let id = warp_runtime::ops::register(&op) as i64;
    for target in ["fwd.graph", "fwd.eager"] {
        let (y2, z2) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
        let (bx, by, bz) = (
            buf(&x, Dtype::F64),
            buf(&y2, Dtype::F64),
            buf(&z2, Dtype::F64),
        );
        let r = on_xla_stream(dev, || {
            invoke(
                handler(target, dev),
                &api,
                &[&bx],
                &[&by, &bz],
                &[("warp_op", A::I64(id)), ("s", A::F64(s))],
            )
        });
        assert_eq!(r, Ok(()), "{target}");
        assert_eq!(bits(&host(&y1)), bits(&host(&y2)), "{target}");
        assert_eq!(bits(&host(&z1)), bits(&host(&z2)), "{target}");
    }
    // Outputs are zeroed first (XLA's results are uninitialised): a reduction into garbage
    // still sums from zero. The sum of halves and integers is exact in any order.
    let op = shared_op();
    let id = warp_runtime::ops::register(&op) as i64;
    let amp = arr(&[2.0, -1.0], dev);
    let y = arr(&vec![7.0; N], dev);
    let total = arr(&[99.0], dev);
    let r = on_xla_stream(dev, || {
        invoke(
            handler("fwd.graph", dev),
            &api,
            &[&buf(&x, Dtype::F64), &buf(&amp, Dtype::F64)],
            &[&buf(&y, Dtype::F64), &buf(&total, Dtype::F64)],
            &[("warp_op", A::I64(id))],
        )
    });
    assert_eq!(r, Ok(()));
    assert_eq!(host(&total), [xh.iter().sum::<f64>()]);
    let want: Vec<f64> = xh.iter().map(|v| 2.0 * v - 1.0).collect();
    assert_eq!(bits(&host(&y)), bits(&want));
}

fn xla_backward_matches_op_backward(dev: &wp::Device) {
    let api = mock_api();
    let (xh, s) = (xs(1), 0.75);
    let (gy, gz) = (xs(2), xs(3));
    let op = own_op();
    let id = warp_runtime::ops::register(&op) as i64;
    let x = arr(&xh, dev);
    let (y, z) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
    wp::launch(kx_own, N, (&x, s, &y, &z), dev).unwrap();
    let (bx, by, bz) = (
        buf(&x, Dtype::F64),
        buf(&y, Dtype::F64),
        buf(&z, Dtype::F64),
    );
    // The reference: the op's own backward, with zeroed input gradients and copies of the
    // cotangents (which it clears).
    let gx1 = zeros::<f64, 1>(N, dev);
    let (cy1, cz1) = (arr(&gy, dev), arr(&gz, dev));
    let (bgx1, bcy1, bcz1) = (
        buf(&gx1, Dtype::F64),
        buf(&cy1, Dtype::F64),
        buf(&cz1, Dtype::F64),
    );
    let args = [
        CallArg::Buffer(&bx),
        CallArg::Value(Value::Float(s)),
        CallArg::Buffer(&by),
        CallArg::Buffer(&bz),
    ];
    let grads = [Some(&bgx1), None, Some(&bcy1), Some(&bcz1)];
    // SAFETY: the arrays' memory, alive for the call.
    with_exec(dev, |e| unsafe { op.backward(&args, &grads, e) }.unwrap());
    // The handler: cotangents are read-only operands; the input gradient arrives as garbage
    // (XLA's results are uninitialised) and the copies too.
    for target in ["bwd.graph", "bwd.eager"] {
        let (cy, cz) = (arr(&gy, dev), arr(&gz, dev));
        let gx = arr(&vec![5.0; N], dev);
        let (copy_y, copy_z) = (arr(&vec![3.0; N], dev), arr(&vec![3.0; N], dev));
        let r = on_xla_stream(dev, || {
            invoke(
                handler(target, dev),
                &api,
                &[&bx, &by, &bz, &buf(&cy, Dtype::F64), &buf(&cz, Dtype::F64)],
                &[
                    &buf(&gx, Dtype::F64),
                    &buf(&copy_y, Dtype::F64),
                    &buf(&copy_z, Dtype::F64),
                ],
                &[("warp_op", A::I64(id)), ("s", A::F64(s))],
            )
        });
        assert_eq!(r, Ok(()), "{target}");
        assert_eq!(bits(&host(&gx)), bits(&host(&gx1)), "{target}");
        // The operands are untouched (the adjoint took the copies, which it clears).
        assert_eq!(bits(&host(&cy)), bits(&gy), "{target}");
        assert_eq!(bits(&host(&cz)), bits(&gz), "{target}");
        assert!(host(&copy_y).iter().all(|&v| v == 0.0), "{target}");
        assert!(host(&copy_z).iter().all(|&v| v == 0.0), "{target}");
    }
    // The closed form (to 1e-12: a few roundings): dy/dx = 2 s x + cos x, dz/dx = s + sin x.
    let g = host(&gx1);
    for i in 0..N {
        let v = xh[i];
        let want = gy[i] * (2.0 * s * v + v.cos()) + gz[i] * (s + v.sin());
        assert!((g[i] - want).abs() <= 1e-12 * want.abs().max(1.0), "{i}");
    }
}

fn xla_attribute_errors(dev: &wp::Device) {
    let api = mock_api();
    let op = own_op();
    let id = warp_runtime::ops::register(&op) as i64;
    let x = arr(&xs(0), dev);
    let (y, z) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
    let (bx, by, bz) = (
        buf(&x, Dtype::F64),
        buf(&y, Dtype::F64),
        buf(&z, Dtype::F64),
    );
    let call = |attrs: &[(&str, A)]| {
        on_xla_stream(dev, || {
            invoke(handler("fwd.graph", dev), &api, &[&bx], &[&by, &bz], attrs)
        })
        .unwrap_err()
    };
    let expect = |attrs: &[(&str, A)], parts: &[&str]| {
        let (code, msg) = call(attrs);
        assert_eq!(code, 3, "{msg}");
        for p in parts {
            assert!(msg.contains(p), "{msg:?} lacks {p:?}");
        }
        msg
    };
    let target = format!("warp_lang fwd.graph ({})", platform(dev));
    let m = expect(
        &[("s", A::F64(1.0))],
        &["'warp_op'", "missing", "int64", "[s]"],
    );
    assert!(m.starts_with(&target), "{m}");
    expect(
        &[("warp_op", A::F64(id as f64)), ("s", A::F64(1.0))],
        &["'warp_op'", "a float64 scalar", "int64"],
    );
    expect(
        &[("warp_op", A::I32(id as i32)), ("s", A::F64(1.0))],
        &["'warp_op'", "an int32 scalar"],
    );
    expect(
        &[("warp_op", A::I64(1 << 40)), ("s", A::F64(1.0))],
        &["no op is registered under id 1099511627776"],
    );
    let m = expect(
        &[("warp_op", A::I64(id))],
        &[
            "op xown",
            "scalar 's' (1)",
            "no attribute 's'",
            "a float64 scalar",
            "[warp_op]",
        ],
    );
    assert!(m.starts_with(&format!("{target}: op xown:")), "{m}");
    expect(
        &[("warp_op", A::I64(id)), ("s", A::F32(1.0))],
        &[
            "scalar 's' (1)",
            "a float32 scalar",
            "takes a float64 scalar",
            "np.float64",
        ],
    );
    expect(
        &[("warp_op", A::I64(id)), ("s", A::Array)],
        &["scalar 's' (1)", "an array", "float64"],
    );
    expect(
        &[
            ("warp_op", A::I64(id)),
            ("s", A::F64(1.0)),
            ("sigma", A::F64(2.0)),
        ],
        &["unknown attribute 'sigma'", "[s]"],
    );
    // A computation op asked through a graph target.
    let r_op = rollout_op();
    let rid = warp_runtime::ops::register(&r_op) as i64;
    let (code, msg) = on_xla_stream(dev, || {
        invoke(
            handler("fwd.graph", dev),
            &api,
            &[],
            &[],
            &[("warp_op", A::I64(rid))],
        )
    })
    .unwrap_err();
    assert_eq!(code, 3);
    assert!(
        msg.contains("op rollout") && msg.contains("eager targets"),
        "{msg}"
    );
}

/// `y = x d.x + d.y`: a vector value (the mock's array attribute is [1, 2] of f64).
#[wp::kernel]
fn kx_vec(d: DVec2, x: Array<f64>, y: Array<f64>) {
    let i = tid();
    y[i] = x[i] * d.x + d.y;
}

/// The same with a DVec3, which the mock's two-element array cannot be.
#[wp::kernel]
fn kx_vec3(d: DVec3, x: Array<f64>, y: Array<f64>) {
    let i = tid();
    y[i] = x[i] * d.x + d.y + d.z;
}

fn xla_vector_values(dev: &wp::Device) {
    let api = mock_api();
    let op = Op::kernel("xvec", kx_vec).outputs(["y"]).build().unwrap();
    let id = warp_runtime::ops::register(&op) as i64;
    let x = arr(&xs(0), dev);
    let y = zeros::<f64, 1>(N, dev);
    let (bx, by) = (buf(&x, Dtype::F64), buf(&y, Dtype::F64));
    let run = |id: i64, attrs: &[(&str, A)]| {
        on_xla_stream(dev, || {
            invoke(
                handler("fwd.graph", dev),
                &api,
                &[&bx],
                &[&by],
                &[&[("warp_op", A::I64(id))], attrs].concat(),
            )
        })
    };
    run(id, &[("d", A::Array)]).unwrap();
    // The op's own call with the same components: bit for bit.
    let want = zeros::<f64, 1>(N, dev);
    let bw = buf(&want, Dtype::F64);
    let d = [Value::Float(1.0), Value::Float(2.0)];
    let args = [
        CallArg::Values(&d),
        CallArg::Buffer(&bx),
        CallArg::Buffer(&bw),
    ];
    // SAFETY: the buffers are the arrays' memory, alive for the call.
    with_exec(dev, |e| unsafe { op.forward(&args, e) }.unwrap());
    assert_eq!(bits(&host(&y)), bits(&host(&want)));
    // x * 1 + 2: exact for these x.
    assert!(host(&y).iter().zip(xs(0)).all(|(y, x)| *y == x + 2.0));
    let expect = |id: i64, attrs: &[(&str, A)], parts: &[&str]| {
        let (code, msg) = run(id, attrs).unwrap_err();
        assert_eq!(code, 3, "{msg}");
        for p in parts {
            assert!(msg.contains(p), "{msg:?} lacks {p:?}");
        }
    };
    expect(
        id,
        &[("d", A::F64(1.0))],
        &[
            "value 'd' (0)",
            "a float64 scalar",
            "an array of 2 float64",
            "DVec2",
            "np.asarray(value, np.float64).ravel()",
        ],
    );
    expect(
        id,
        &[],
        &["value 'd' (0)", "no attribute 'd'", "an array of 2 float64"],
    );
    let op3 = Op::kernel("xvec3", kx_vec3).outputs(["y"]).build().unwrap();
    let id3 = warp_runtime::ops::register(&op3) as i64;
    expect(
        id3,
        &[("d", A::Array)],
        &[
            "value 'd' (0)",
            "the attribute is an array of 2 float64",
            "an array of 3 float64",
        ],
    );
}

fn xla_buffer_errors(dev: &wp::Device) {
    let api = mock_api();
    let op = own_op();
    let id = warp_runtime::ops::register(&op) as i64;
    let attrs = [("warp_op", A::I64(id)), ("s", A::F64(1.0))];
    let x = arr(&xs(0), dev);
    let x32 = arr(&vec![1.0f32; N], dev);
    let (y, z) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
    let short = zeros::<f64, 1>(N - 1, dev);
    let (bx, by, bz) = (
        buf(&x, Dtype::F64),
        buf(&y, Dtype::F64),
        buf(&z, Dtype::F64),
    );
    let call = |ops: &[&Buffer], rets: &[&Buffer]| {
        on_xla_stream(dev, || {
            invoke(handler("fwd.eager", dev), &api, ops, rets, &attrs)
        })
    };
    let expect = |r: Answer, parts: &[&str]| {
        let (code, msg) = r.unwrap_err();
        assert_eq!(code, 3, "{msg}");
        for p in parts {
            assert!(msg.contains(p), "{msg:?} lacks {p:?}");
        }
    };
    expect(
        call(&[&bx, &bx], &[&by, &bz]),
        &[
            "op xown",
            "2 operands and 2 results",
            "operands [x]",
            "results [y, z]",
        ],
    );
    expect(
        call(&[&buf(&x32, Dtype::F32)], &[&by, &bz]),
        &["xown", "argument 'x'", "float32", "float64"],
    );
    expect(
        call(&[&bx], &[&by, &buf(&short, Dtype::F64)]),
        &["xown", "output 'z'", "[255]", "[256]"],
    );
    // The backward names its slots too.
    let r = on_xla_stream(dev, || {
        invoke(handler("bwd.eager", dev), &api, &[&bx], &[], &attrs)
    });
    expect(
        r,
        &[
            "backward takes operands [x, y, z, cotangent of y, cotangent of z]",
            "gradient of x",
        ],
    );
    // A cotangent whose copy has another shape.
    let r = on_xla_stream(dev, || {
        invoke(
            handler("bwd.eager", dev),
            &api,
            &[&bx, &by, &bz, &by, &bz],
            &[&bx, &buf(&short, Dtype::F64), &bz],
            &attrs,
        )
    });
    expect(r, &["the cotangent of 'y'", "[256]", "[255]"]);
    // A result XLA marks as something other than a buffer.
    let r = on_xla_stream(dev, || {
        let mut t = [x::BUFFER, 7];
        invoke_frame(
            handler("fwd.eager", dev),
            &api,
            &[&bx],
            &[&by, &bz],
            &attrs,
            |f| {
                f.rets.types = t.as_mut_ptr();
            },
        )
    });
    expect(r, &["result 1 has XLA type 7, not a buffer"]);
}

fn xla_batched_matches_a_loop(dev: &wp::Device) {
    // vmap with expand_dims: x batched (B, N), amp unbatched (1, 2); results (B, ..).
    const B: usize = 3;
    let api = mock_api();
    let op = shared_op();
    let id = warp_runtime::ops::register(&op) as i64;
    let attrs = [("warp_op", A::I64(id))];
    let rows: Vec<Vec<f64>> = (0..B).map(xs).collect();
    let xb = wp::Array::<f64, 2>::from_slice_shape(&rows.concat(), [B, N], dev).unwrap();
    let ampb = wp::Array::<f64, 2>::from_slice_shape(&[2.0, -1.0], [1, 2], dev).unwrap();
    let yb = zeros::<f64, 2>([B, N], dev);
    let tb = zeros::<f64, 2>([B, 1], dev);
    let r = on_xla_stream(dev, || {
        invoke(
            handler("fwd.graph", dev),
            &api,
            &[&buf(&xb, Dtype::F64), &buf(&ampb, Dtype::F64)],
            &[&buf(&yb, Dtype::F64), &buf(&tb, Dtype::F64)],
            &attrs,
        )
    });
    assert_eq!(r, Ok(()));
    // The loop: one unbatched call per row.
    let amp = arr(&[2.0, -1.0], dev);
    let (yh, th) = (host(&yb), host(&tb));
    for (b, row) in rows.iter().enumerate() {
        let x = arr(row, dev);
        let (y, t) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(1, dev));
        let r = on_xla_stream(dev, || {
            invoke(
                handler("fwd.graph", dev),
                &api,
                &[&buf(&x, Dtype::F64), &buf(&amp, Dtype::F64)],
                &[&buf(&y, Dtype::F64), &buf(&t, Dtype::F64)],
                &attrs,
            )
        });
        assert_eq!(r, Ok(()));
        assert_eq!(bits(&yh[b * N..(b + 1) * N]), bits(&host(&y)), "row {b}");
        assert_eq!(th[b].to_bits(), host(&t)[0].to_bits(), "row {b}");
    }
    // The backward, batched: an unbatched cotangent of y (1, N) and of total (1, 1), copied
    // into full-batch scratch; per-row gradients of x and amp (JAX sums amp's over the batch).
    let gy: Vec<f64> = xs(5);
    let cy = wp::Array::<f64, 2>::from_slice_shape(&gy, [1, N], dev).unwrap();
    let ct = wp::Array::<f64, 2>::from_slice_shape(&[0.5], [1, 1], dev).unwrap();
    let gxb = arr(&vec![9.0; B * N], dev);
    let gampb = arr(&[9.0; B * 2], dev);
    let (copy_y, copy_t) = (zeros::<f64, 2>([B, N], dev), zeros::<f64, 2>([B, 1], dev));
    let shaped = |a: &wp::Array<f64>, d: &[usize]| {
        let mut b = buf(a, Dtype::F64);
        b.dims = d.to_vec();
        b
    };
    let r = on_xla_stream(dev, || {
        invoke(
            handler("bwd.graph", dev),
            &api,
            &[
                &buf(&xb, Dtype::F64),
                &buf(&ampb, Dtype::F64),
                &buf(&yb, Dtype::F64),
                &buf(&tb, Dtype::F64),
                &buf(&cy, Dtype::F64),
                &buf(&ct, Dtype::F64),
            ],
            &[
                &shaped(&gxb, &[B, N]),
                &shaped(&gampb, &[B, 2]),
                &buf(&copy_y, Dtype::F64),
                &buf(&copy_t, Dtype::F64),
            ],
            &attrs,
        )
    });
    assert_eq!(r, Ok(()));
    let (gxh, gah) = (host(&gxb), host(&gampb));
    for (b, row) in rows.iter().enumerate() {
        let x = arr(row, dev);
        let (y, t) = (arr(&yh[b * N..(b + 1) * N], dev), arr(&[th[b]], dev));
        let (gx, ga) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(2, dev));
        let (c1, c2) = (arr(&gy, dev), arr(&[0.5], dev));
        // The cotangents, made before the call (on_xla_stream synchronises first): arrays
        // made inside it would be uploaded on this crate's default stream, which nothing
        // orders before the caller's stream.
        let (gy_in, ct_in) = (arr(&gy, dev), arr(&[0.5], dev));
        let r = on_xla_stream(dev, || {
            invoke(
                handler("bwd.graph", dev),
                &api,
                &[
                    &buf(&x, Dtype::F64),
                    &buf(&amp, Dtype::F64),
                    &buf(&y, Dtype::F64),
                    &buf(&t, Dtype::F64),
                    &buf(&gy_in, Dtype::F64),
                    &buf(&ct_in, Dtype::F64),
                ],
                &[
                    &buf(&gx, Dtype::F64),
                    &buf(&ga, Dtype::F64),
                    &buf(&c1, Dtype::F64),
                    &buf(&c2, Dtype::F64),
                ],
                &attrs,
            )
        });
        assert_eq!(r, Ok(()));
        assert_eq!(bits(&gxh[b * N..(b + 1) * N]), bits(&host(&gx)), "row {b}");
        assert_eq!(bits(&gah[b * 2..(b + 1) * 2]), bits(&host(&ga)), "row {b}");
        // Closed form: d/damp0 = sum gy x, d/damp1 = sum gy; dx = amp0 gy + ct (exact sums).
        let want0: f64 = gy.iter().zip(row).map(|(g, v)| g * v).sum();
        assert_eq!(host(&ga), [want0, gy.iter().sum::<f64>()], "row {b}");
    }
    // Operands whose batch ranks differ.
    let (code, msg) = on_xla_stream(dev, || {
        invoke(
            handler("fwd.graph", dev),
            &api,
            &[&buf(&xb, Dtype::F64), &buf(&amp, Dtype::F64)],
            &[&buf(&yb, Dtype::F64), &buf(&tb, Dtype::F64)],
            &attrs,
        )
    })
    .unwrap_err();
    assert_eq!(code, 3);
    assert!(msg.contains("xshared: batched call"), "{msg}");
    let _ = Vmap::Loop;
}

#[wp::kernel]
fn kx_step(x0: Array<f64>, v0: Array<f64>, dt: f64, x1: Array<f64>, v1: Array<f64>) {
    let i = tid();
    v1[i] = v0[i] - dt * sin(x0[i]);
    x1[i] = x0[i] + dt * v1[i];
}

/// A computation op: `steps` steps of a pendulum, the states in scratch.
fn rollout_op() -> Op {
    let states = || {
        Shape::Fn(Arc::new(|s| {
            Ok(vec![s.scalar::<i64>("steps")? as usize + 1, s.len("x0")?])
        }))
    };
    Op::computation("rollout", |c| {
        let (x0, v0) = (c.input::<f64, 1>("x0")?, c.input::<f64, 1>("v0")?);
        let (xs, vs) = (c.scratch::<f64, 2>("xs")?, c.scratch::<f64, 2>("vs")?);
        let out = c.output::<f64, 1>("x_final")?;
        let (dt, steps) = (c.scalar::<f64>("dt")?, c.scalar::<i64>("steps")? as usize);
        wp::copy(&xs.row(0)?, x0)?;
        wp::copy(&vs.row(0)?, v0)?;
        for k in 0..steps {
            let (xa, va, xb, vb) = (xs.row(k)?, vs.row(k)?, xs.row(k + 1)?, vs.row(k + 1)?);
            wp::launch(kx_step, x0.len(), (&xa, &va, dt, &xb, &vb), c.device())?;
        }
        wp::copy(out, &xs.row(steps)?)
    })
    .input::<f64, 1>("x0")
    .input::<f64, 1>("v0")
    .scalar::<f64>("dt")
    .scalar::<i64>("steps")
    .scratch::<f64, 2>("xs", states())
    .scratch::<f64, 2>("vs", states())
    .output::<f64, 1>("x_final", Shape::Like("x0"))
    .build()
    .unwrap()
}

fn xla_computation_op(dev: &wp::Device) {
    let (n, steps, dt) = (32usize, 10usize, 0.05);
    let api = mock_api();
    let op = rollout_op();
    let id = warp_runtime::ops::register(&op) as i64;
    let attrs = [
        ("warp_op", A::I64(id)),
        ("dt", A::F64(dt)),
        ("steps", A::I64(steps as i64)),
    ];
    let x0h: Vec<f64> = (0..n).map(|i| 0.1 * i as f64 - 1.0).collect();
    let v0h: Vec<f64> = (0..n).map(|i| 0.05 * i as f64).collect();
    let (x0, v0) = (arr(&x0h, dev), arr(&v0h, dev));
    // Forward: results x_final and the scratch (parameter order: xs, vs, x_final).
    let l = x::layout(&op, Direction::Forward);
    assert_eq!(l.operands, [Slot::Value(0), Slot::Value(1)]);
    assert_eq!(l.results, [Slot::Value(4), Slot::Value(5), Slot::Value(6)]);
    let (xs_, vs_) = (
        zeros::<f64, 2>([steps + 1, n], dev),
        zeros::<f64, 2>([steps + 1, n], dev),
    );
    let out = arr(&vec![4.0; n], dev);
    let r = on_xla_stream(dev, || {
        invoke(
            handler("fwd.eager", dev),
            &api,
            &[&buf(&x0, Dtype::F64), &buf(&v0, Dtype::F64)],
            &[
                &buf(&xs_, Dtype::F64),
                &buf(&vs_, Dtype::F64),
                &buf(&out, Dtype::F64),
            ],
            &attrs,
        )
    });
    assert_eq!(r, Ok(()));
    // The reference: the same launches by hand.
    let (xs2, vs2) = (
        zeros::<f64, 2>([steps + 1, n], dev),
        zeros::<f64, 2>([steps + 1, n], dev),
    );
    wp::copy(&xs2.row(0).unwrap(), &x0).unwrap();
    wp::copy(&vs2.row(0).unwrap(), &v0).unwrap();
    for k in 0..steps {
        let r = |a: &wp::Array<f64, 2>, j| a.row(j).unwrap();
        wp::launch(
            kx_step,
            n,
            (
                &r(&xs2, k),
                &r(&vs2, k),
                dt,
                &r(&xs2, k + 1),
                &r(&vs2, k + 1),
            ),
            dev,
        )
        .unwrap();
    }
    let want = host(&xs2.row(steps).unwrap());
    assert_eq!(bits(&host(&out)), bits(&want));
    // Backward: operands x0, v0, the cotangent of x_final; results the input gradients, the
    // cotangent's copy, and the replay's xs, vs, x_final.
    let l = x::layout(&op, Direction::Backward);
    assert_eq!(
        l.operands,
        [Slot::Value(0), Slot::Value(1), Slot::Cotangent(6)]
    );
    assert_eq!(
        l.results,
        [
            Slot::Grad(0),
            Slot::Grad(1),
            Slot::CotangentCopy(6),
            Slot::Replay(4),
            Slot::Replay(5),
            Slot::Replay(6)
        ]
    );
    let gout: Vec<f64> = (0..n).map(|i| 1.0 + (i % 3) as f64).collect();
    let cot = arr(&gout, dev);
    let (gx, gv, copy) = (
        arr(&vec![8.0; n], dev),
        arr(&vec![8.0; n], dev),
        zeros::<f64, 1>(n, dev),
    );
    let (rx, rv, ro) = (
        arr(&vec![6.0; (steps + 1) * n], dev),
        arr(&vec![6.0; (steps + 1) * n], dev),
        arr(&vec![6.0; n], dev),
    );
    let shaped = |a: &wp::Array<f64>| {
        let mut b = buf(a, Dtype::F64);
        b.dims = vec![steps + 1, n];
        b
    };
    let r = on_xla_stream(dev, || {
        invoke(
            handler("bwd.eager", dev),
            &api,
            &[
                &buf(&x0, Dtype::F64),
                &buf(&v0, Dtype::F64),
                &buf(&cot, Dtype::F64),
            ],
            &[
                &buf(&gx, Dtype::F64),
                &buf(&gv, Dtype::F64),
                &buf(&copy, Dtype::F64),
                &shaped(&rx),
                &shaped(&rv),
                &buf(&ro, Dtype::F64),
            ],
            &attrs,
        )
    });
    assert_eq!(r, Ok(()));
    // The reference: the op's own backward on fresh zeroed buffers.
    let (gx1, gv1, c1) = (
        zeros::<f64, 1>(n, dev),
        zeros::<f64, 1>(n, dev),
        arr(&gout, dev),
    );
    let (rx1, rv1, ro1) = (
        zeros::<f64, 2>([steps + 1, n], dev),
        zeros::<f64, 2>([steps + 1, n], dev),
        zeros::<f64, 1>(n, dev),
    );
    let b = |a: &wp::Array<f64>| buf(a, Dtype::F64);
    let (bx0, bv0, bgx, bgv, bc, bro) = (b(&x0), b(&v0), b(&gx1), b(&gv1), b(&c1), b(&ro1));
    let (brx, brv) = (buf(&rx1, Dtype::F64), buf(&rv1, Dtype::F64));
    let args = [
        CallArg::Buffer(&bx0),
        CallArg::Buffer(&bv0),
        CallArg::Value(Value::Float(dt)),
        CallArg::Value(Value::Int(steps as i64)),
        CallArg::Buffer(&brx),
        CallArg::Buffer(&brv),
        CallArg::Buffer(&bro),
    ];
    let grads = [Some(&bgx), Some(&bgv), None, None, None, None, Some(&bc)];
    if dev.is_cpu() {
        // SAFETY: the arrays' memory, alive for the call.
        unsafe { op.backward(&args, &grads, &Exec::cpu()) }.unwrap();
    } else {
        #[cfg(feature = "cuda")]
        {
            wp::synchronize().unwrap();
            let owner = wp::Stream::new(dev).unwrap();
            // SAFETY: a live stream of the device; the arrays were synchronised.
            let st =
                unsafe { wp::Stream::from_raw(owner.cuda_stream().cu_stream().cast(), dev, ()) }
                    .unwrap();
            unsafe { op.backward(&args, &grads, &Exec::stream(&st)) }.unwrap();
            st.synchronize().unwrap();
        }
    }
    assert_eq!(bits(&host(&gx)), bits(&host(&gx1)));
    assert_eq!(bits(&host(&gv)), bits(&host(&gv1)));
    assert_eq!(bits(&host(&ro)), bits(&want), "the replay's output");
    assert!(host(&gx).iter().any(|&v| v != 0.0));
}

fn xla_panics_become_errors(dev: &wp::Device) {
    let api = mock_api();
    // A shape rule that panics: caught by the handler (nothing unwinds into XLA).
    let op = Op::kernel("xpanic", kx_own)
        .outputs(["y", "z"])
        .shape(
            "y",
            Shape::Fn(Arc::new(|_| -> wp::Result<Vec<usize>> {
                panic!("the rule's own panic, 42")
            })),
        )
        .build()
        .unwrap();
    let id = warp_runtime::ops::register(&op) as i64;
    let x = arr(&xs(0), dev);
    let (y, z) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
    let (code, msg) = on_xla_stream(dev, || {
        invoke(
            handler("fwd.graph", dev),
            &api,
            &[&buf(&x, Dtype::F64)],
            &[&buf(&y, Dtype::F64), &buf(&z, Dtype::F64)],
            &[("warp_op", A::I64(id)), ("s", A::F64(1.0))],
        )
    })
    .unwrap_err();
    assert_eq!(code, 13, "{msg}");
    assert!(
        msg.contains("op xpanic") && msg.contains("panicked: the rule's own panic, 42"),
        "{msg}"
    );
    // A computation body that panics: the op's own catch, an error naming it.
    let op = Op::computation("xbody", |_c| -> wp::Result<()> { panic!("body gave up") })
        .input::<f64, 1>("a")
        .output::<f64, 1>("b", Shape::Like("a"))
        .build()
        .unwrap();
    let id = warp_runtime::ops::register(&op) as i64;
    let (code, msg) = on_xla_stream(dev, || {
        invoke(
            handler("fwd.eager", dev),
            &api,
            &[&buf(&x, Dtype::F64)],
            &[&buf(&y, Dtype::F64)],
            &[("warp_op", A::I64(id))],
        )
    })
    .unwrap_err();
    assert_eq!(code, 3, "{msg}");
    assert!(
        msg.contains("xbody") && msg.contains("body gave up"),
        "{msg}"
    );
}

fn xla_api_table_checks(dev: &wp::Device) {
    let op = own_op();
    let id = warp_runtime::ops::register(&op) as i64;
    let attrs = [("warp_op", A::I64(id)), ("s", A::F64(1.0))];
    let x = arr(&xs(0), dev);
    let (y, z) = (zeros::<f64, 1>(N, dev), zeros::<f64, 1>(N, dev));
    let (bx, by, bz) = (
        buf(&x, Dtype::F64),
        buf(&y, Dtype::F64),
        buf(&z, Dtype::F64),
    );
    // A table too small for the prefix (an older layout): refused before anything is read,
    // the metadata query included.
    let mut api = mock_api();
    api.struct_size = x::API_PREFIX_SIZE - size_of::<usize>();
    let want = format!(
        "the XLA_FFI_Api table has {} bytes; warp-lang reads its first {}",
        api.struct_size,
        x::API_PREFIX_SIZE
    );
    for h in x::handlers() {
        let (code, msg) = invoke(h.handler, &api, &[&bx], &[&by, &bz], &attrs).unwrap_err();
        assert_eq!(code, 9, "{msg}");
        assert!(msg.contains(&want), "{msg}");
    }
    // Another major version.
    let mut api = mock_api();
    api.api_version.major_version = 1;
    api.api_version.minor_version = 4;
    let (code, msg) =
        invoke(handler("fwd.graph", dev), &api, &[&bx], &[&by, &bz], &attrs).unwrap_err();
    assert_eq!(code, 9, "{msg}");
    assert!(
        msg.contains("XLA FFI API version 1.4") && msg.contains("0.1"),
        "{msg}"
    );
    // A call frame smaller than the fields read.
    let api = mock_api();
    let (code, msg) = invoke_frame(
        handler("fwd.graph", dev),
        &api,
        &[&bx],
        &[&by, &bz],
        &attrs,
        |f| f.struct_size = 40,
    )
    .unwrap_err();
    assert_eq!(code, 9, "{msg}");
    assert!(msg.contains("an XLA_FFI_CallFrame of 40 bytes"), "{msg}");
}

//! Port of Warp's `warp/tests/test_grad_customs.py`: user funcs with custom gradients (Warp's
//! `@wp.func_grad`, here `#[func(grad(x = dfdx))]`) on scalar, tuple-returning and struct
//! funcs, called directly, from another module, and from funcs that have automatic adjoints;
//! and a func's automatic adjoint after a forward-only kernel used it.
//!
//! Ported (Warp test -> here): `test_custom_overload_grad` -> [`custom_overload_grad_float`]
//! and [`custom_overload_grad_struct`], `test_custom_import_grad` -> [`custom_import_grad`],
//! `test_nested_custom_grad` -> [`nested_custom_grad`],
//! `test_custom_grad_with_helper_dependency` -> [`custom_grad_with_helper_dependency`],
//! `test_custom_grad_helper_backward_propagation` ->
//! [`custom_grad_helper_backward_propagation`], `test_backward_use_propagation_across_kernels`
//! -> [`backward_use_propagation_across_kernels`], `test_custom_replay_grad` ->
//! [`custom_replay_grad`] (Warp's `@wp.func_replay` is `#[func(replay = r)]`). Tolerances are
//! Warp's: exact for the
//! overload tests (`assert_np_equal` without `tol`: small integers, exact in f32), absolute
//! `1e-4` for the others.
//!
//! Adapted: a Warp gradient func adds into `wp.adjoint[x]` for each parameter; here each
//! parameter's gradient func returns that parameter's adjoint, given the func's arguments and
//! the adjoint of its result (for a tuple result, the tuple of its elements' adjoints; for a
//! struct parameter, a struct of its fields' adjoints). Warp's two `overload_fn` overloads
//! (floats; a struct) and their gradient funcs are `wp::overloads!` sets. `aux_custom_fn`, imported by Warp
//! from another file, lives in a module of its own here and is called by path.
//!
//! Not ported: `test_custom_grad_no_return` and the `dense_gemm` code-generation
//! check (custom gradients of array parameters, `wp.adjoint[xs][i]`: a custom gradient here
//! is for value parameters, an array's gradient comes from its accesses);
//! `test_native_snippet_in_forward_with_custom_grad` and `test_native_snippet_in_custom_grad`
//! (`@wp.func_native` C++/CUDA snippets: not in the language); `test_custom_grad_tile_matmul`
//! (a custom gradient on array parameters, in a tiled func); `test_wrapped_docstring`
//! (Python docstrings).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    custom_overload_grad_float,
    custom_overload_grad_struct,
    custom_import_grad,
    nested_custom_grad,
    custom_grad_with_helper_dependency,
    custom_grad_helper_backward_propagation,
    backward_use_propagation_across_kernels,
    custom_replay_grad,
);

#[track_caller]
fn near(got: &[f32], want: &[f32], tol: f32, what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= tol,
            "{what}[{k}]: got {g}, want {w} (Warp's absolute tolerance {tol:e})"
        );
    }
}

wp::overloads!(overload_fn);
wp::overloads!(overload_fn_dx);

/// Warp's `overload_fn` for floats; its gradient funcs are overloads too (the struct
/// overload's is below), each picked by the types it is called with.
#[wp::func(overload, grad(x = overload_fn_dx, y = overload_fn_dy))]
fn overload_fn(x: f32, y: f32) -> (f32, f32) {
    (x * 3.0 + y / 3.0, y.powf(2.5))
}

#[wp::func(overload)]
fn overload_fn_dx(x: f32, y: f32, adj_ret: (f32, f32)) -> f32 {
    x * adj_ret.0 * 42.0 + y * adj_ret.1 * 10.0
}

#[wp::func]
fn overload_fn_dy(x: f32, y: f32, adj_ret: (f32, f32)) -> f32 {
    let _ = x;
    y * adj_ret.1 * 3.0
}

#[wp::kernel]
fn k_run_overload_float_fn(
    xs: Array<f32>,
    ys: Array<f32>,
    output0: Array<f32>,
    output1: Array<f32>,
) {
    let i = tid();
    let (out0, out1) = overload_fn(xs[i], ys[i]);
    output0[i] = out0;
    output1[i] = out1;
}

/// Launches `k_run_overload_float_fn` or the imported `aux::k_run_defined_float_fn` on Warp's
/// inputs under a tape, seeds both outputs' gradients with ones and checks Warp's gradients.
fn check_two_output_grads(dev: &wp::Device, imported: bool) {
    let dim = 3;
    let (xv, yv) = ([1.0f32, 2.0, 3.0], [10.0f32, 11.0, 12.0]);
    let xs = arr(&xv, dev).with_grad().unwrap();
    let ys = arr(&yv, dev).with_grad().unwrap();
    let out0 = zeros::<f32, 1>(dim, dev).with_grad().unwrap();
    let out1 = zeros::<f32, 1>(dim, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        let args = (&xs, &ys, &out0, &out1);
        if imported {
            wp::launch(aux::k_run_defined_float_fn, dim, args, dev).unwrap();
        } else {
            wp::launch(k_run_overload_float_fn, dim, args, dev).unwrap();
        }
    }
    out0.grad().unwrap().fill(1.0).unwrap();
    out1.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let want_x: Vec<f32> = xv
        .iter()
        .zip(&yv)
        .map(|(x, y)| x * 42.0 + y * 10.0)
        .collect();
    let want_y: Vec<f32> = yv.iter().map(|y| y * 3.0).collect();
    assert_eq!(host(&xs.grad().unwrap()), want_x, "x gradient");
    assert_eq!(host(&ys.grad().unwrap()), want_y, "y gradient");
}

fn custom_overload_grad_float(dev: &wp::Device) {
    check_two_output_grads(dev, false);
}

fn custom_import_grad(dev: &wp::Device) {
    check_two_output_grads(dev, true);
}

/// Warp's `aux_test_grad_customs.py`: the same func and gradient, defined in another module.
mod aux {
    use warp_lang as wp;
    use wp::prelude::*;

    #[wp::func(grad(x = aux_custom_fn_dx, y = aux_custom_fn_dy))]
    pub fn aux_custom_fn(x: f32, y: f32) -> (f32, f32) {
        (x * 3.0 + y / 3.0, y.powf(2.5))
    }

    #[wp::func]
    pub fn aux_custom_fn_dx(x: f32, y: f32, adj_ret: (f32, f32)) -> f32 {
        x * adj_ret.0 * 42.0 + y * adj_ret.1 * 10.0
    }

    #[wp::func]
    pub fn aux_custom_fn_dy(x: f32, y: f32, adj_ret: (f32, f32)) -> f32 {
        let _ = x;
        y * adj_ret.1 * 3.0
    }

    #[wp::kernel]
    pub fn k_run_defined_float_fn(
        xs: Array<f32>,
        ys: Array<f32>,
        output0: Array<f32>,
        output1: Array<f32>,
    ) {
        let i = tid();
        let (out0, out1) = aux_custom_fn(xs[i], ys[i]);
        output0[i] = out0;
        output1[i] = out1;
    }
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct MyStruct {
    scalar: f32,
    vec: Vec3,
}

/// Warp's `overload_fn` for the struct: another overload of the same name.
#[wp::func(overload, grad(x = overload_fn_dx))]
fn overload_fn(x: MyStruct) -> (f32, f32, f32) {
    (
        x.vec.x * x.vec.y * x.vec.z * 4.0,
        x.vec.length(),
        x.scalar.powf(0.5),
    )
}

/// Warp's `overload_fn_grad` for the struct: one adjoint per field.
#[wp::func(overload)]
fn overload_fn_dx(x: MyStruct, adj_ret: (f32, f32, f32)) -> MyStruct {
    MyStruct {
        scalar: x.scalar * adj_ret.0 * 10.0,
        vec: vec3(
            adj_ret.0 * x.vec.y * x.vec.z * 20.0,
            adj_ret.1 * x.vec.x * x.vec.z * 30.0,
            adj_ret.2 * x.vec.x * x.vec.y * 40.0,
        ),
    }
}

#[wp::kernel]
fn k_run_overload_struct_fn(xs: Array<MyStruct>, output: Array<f32>) {
    let i = tid();
    let (out0, out1, out2) = overload_fn(xs[i]);
    output[i] = out0 + out1 + out2;
}

fn custom_overload_grad_struct(dev: &wp::Device) {
    let values = [
        MyStruct {
            scalar: 4.0,
            vec: Vec3::new(1.0, 2.0, 3.0),
        },
        MyStruct {
            scalar: -1.0,
            vec: Vec3::new(5.0, 6.0, 7.0),
        },
        MyStruct {
            scalar: 19.0,
            vec: Vec3::new(8.0, 9.0, 10.0),
        },
    ];
    let xs = arr(&values, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_run_overload_struct_fn, 3, (&xs, &out), dev).unwrap();
    }
    tape.backward(&out).unwrap();
    let grads = host(&xs.grad().unwrap());
    for (k, (g, x)) in grads.iter().zip(&values).enumerate() {
        let v = x.vec;
        assert_eq!(g.scalar, x.scalar * 10.0, "struct {k}: scalar gradient");
        assert_eq!(g.vec.x, v.y * v.z * 20.0, "struct {k}: vec[0] gradient");
        assert_eq!(g.vec.y, v.x * v.z * 30.0, "struct {k}: vec[1] gradient");
        assert_eq!(g.vec.z, v.x * v.y * 40.0, "struct {k}: vec[2] gradient");
    }
}

#[wp::func(grad(v = adj_custom_norm))]
fn custom_norm(v: Vec3) -> f32 {
    v.length()
}

/// The normalized vector times the adjoint, instead of the automatic adjoint.
#[wp::func]
fn adj_custom_norm(v: Vec3, adj_ret: f32) -> Vec3 {
    v.normalize() * adj_ret
}

/// Calls a func with a custom gradient from a func with an automatic one.
#[wp::func]
fn nested_norm(v: Vec3) -> f32 {
    custom_norm(v)
}

#[wp::kernel]
fn k_nested_custom_grad(vectors: Array<Vec3>, norms: Array<f32>) {
    let i = tid();
    norms[i] = nested_norm(vectors[i]);
}

fn nested_custom_grad(dev: &wp::Device) {
    let vecs = [
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(3.0, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -1.0),
    ];
    let v = arr(&vecs, dev).with_grad().unwrap();
    let norms = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_nested_custom_grad, 3, (&v, &norms), dev).unwrap();
    }
    near(&host(&norms), &[2.0, 3.0, 1.0], 1e-4, "norms");
    tape.backward(&norms).unwrap();
    let g: Vec<f32> = host(&v.grad().unwrap())
        .iter()
        .flat_map(|g| g.to_array())
        .collect();
    near(
        &g,
        &[0.0, 1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, -1.0],
        1e-4,
        "vector gradients",
    );
}

#[wp::func]
fn helper_multiply(x: f32) -> f32 {
    x * 2.0
}

#[wp::func(grad(x = adj_custom_transform))]
fn custom_transform(x: f32) -> f32 {
    helper_multiply(x) + 1.0
}

#[wp::func]
fn adj_custom_transform(x: f32, adj_ret: f32) -> f32 {
    let _ = x;
    2.0 * adj_ret
}

#[wp::func]
fn outer_transform(x: f32) -> f32 {
    custom_transform(x) * 3.0
}

#[wp::kernel]
fn k_custom_grad_with_helper(inputs: Array<f32>, outputs: Array<f32>) {
    let i = tid();
    outputs[i] = outer_transform(inputs[i]);
}

fn custom_grad_with_helper_dependency(dev: &wp::Device) {
    let inputs = arr(&[1.0f32, 2.0, 3.0], dev).with_grad().unwrap();
    let outputs = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_custom_grad_with_helper, 3, (&inputs, &outputs), dev).unwrap();
    }
    near(&host(&outputs), &[9.0, 15.0, 21.0], 1e-4, "outputs");
    tape.backward(&outputs).unwrap();
    near(
        &host(&inputs.grad().unwrap()),
        &[6.0, 6.0, 6.0],
        1e-4,
        "input gradients",
    );
}

#[wp::func]
fn build_order_leaf(x: f32) -> f32 {
    x * x
}

#[wp::func]
fn build_order_helper(x: f32) -> f32 {
    build_order_leaf(x)
}

#[wp::func(grad(x = adj_build_order_trigger))]
fn build_order_trigger(x: f32) -> f32 {
    x
}

/// Calls the helper first, from a gradient func: the helper's own adjoint must still work.
#[wp::func]
fn adj_build_order_trigger(x: f32, adj_ret: f32) -> f32 {
    let poison = build_order_helper(x);
    0.0 * poison * adj_ret
}

#[wp::kernel]
fn k_build_order(x: Array<f32>, y: Array<f32>) {
    let tid = tid();
    let t = build_order_trigger(x[tid]);
    y[tid] = build_order_helper(x[tid]) + 0.0 * t;
}

fn custom_grad_helper_backward_propagation(dev: &wp::Device) {
    let x = arr(&[3.0f32], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_build_order, 1, (&x, &y), dev).unwrap();
    }
    tape.backward(&y).unwrap();
    near(&host(&y), &[9.0], 1e-4, "y");
    near(&host(&x.grad().unwrap()), &[6.0], 1e-4, "d(x²)/dx");
}

#[wp::func]
fn cross_kernel_leaf(x: f32) -> f32 {
    x * x
}

#[wp::func]
fn cross_kernel_helper(x: f32) -> f32 {
    cross_kernel_leaf(x)
}

#[wp::kernel(enable_backward = false)]
fn k_cross_kernel_forward_only(x: Array<f32>, y: Array<f32>) {
    let tid = tid();
    y[tid] = cross_kernel_helper(x[tid]);
}

#[wp::kernel]
fn k_cross_kernel_backward(x: Array<f32>, y: Array<f32>) {
    let tid = tid();
    y[tid] = cross_kernel_helper(x[tid]);
}

fn backward_use_propagation_across_kernels(dev: &wp::Device) {
    let x = arr(&[3.0f32], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    wp::launch(k_cross_kernel_forward_only, 1, (&x, &y), dev).unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_cross_kernel_backward, 1, (&x, &y), dev).unwrap();
    }
    tape.backward(&y).unwrap();
    near(&host(&y), &[9.0], 1e-4, "y");
    near(&host(&x.grad().unwrap()), &[6.0], 1e-4, "d(x²)/dx");
}

/// Warp's `test_custom_replay_grad` (test_grad_customs.py): each thread takes a slot from an
/// atomic counter and remembers it; the replay recalls the remembered slot instead of taking
/// another, so the adjoint sends each gradient to the slot the forward pass wrote.
#[wp::func(replay = replay_reversible_increment)]
fn reversible_increment(
    counter: Array<i32>,
    counter_index: i32,
    value: i32,
    thread_values: Array<i32>,
    tid: usize,
) -> i32 {
    let next_index = atomic_add(counter, counter_index, value);
    thread_values[tid] = next_index;
    next_index
}

#[wp::func]
fn replay_reversible_increment(
    counter: Array<i32>,
    counter_index: i32,
    value: i32,
    thread_values: Array<i32>,
    tid: usize,
) -> i32 {
    thread_values[tid]
}

#[wp::kernel]
fn k_run_atomic_add(
    input: Array<f32>,
    counter: Array<i32>,
    thread_values: Array<i32>,
    output: Array<f32>,
) {
    let t = tid();
    let idx = reversible_increment(counter, 0, 1, thread_values, t);
    output[idx] = input[idx].powf(2.0);
}

fn custom_replay_grad(dev: &wp::Device) {
    let n = 128;
    let inputs: Vec<f32> = (0..n).map(|k| k as f32).collect();
    let input = arr(&inputs, dev).with_grad().unwrap();
    let counter = zeros::<i32, 1>(1, dev);
    let thread_values = zeros::<i32, 1>(n, dev);
    let output = zeros::<f32, 1>(n, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        let args = (&input, &counter, &thread_values, &output);
        wp::launch(k_run_atomic_add, n, args, dev).unwrap();
    }
    output.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    assert_eq!(
        host(&counter),
        vec![n as i32],
        "the replay took no more slots"
    );
    let grads = host(&input.grad().unwrap());
    for (k, g) in grads.into_iter().enumerate() {
        // Warp's tolerance 1e-4; 2k is exact in f32 for these k.
        assert!(
            (g - 2.0 * inputs[k]).abs() <= 1e-4,
            "slot {k}: gradient {g}, want {}",
            2.0 * inputs[k]
        );
    }
}

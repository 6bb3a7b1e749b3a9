//! Port of Warp's `warp/tests/test_tuple.py`: tuples built in kernels, returned by builtins and
//! user funcs, and passed to funcs, checked in the kernel with Warp's expectations (a failed one
//! fails the launch, so each test's `unwrap` is its assertion).
//!
//! Ported (Warp test -> here): `test_basics` -> [`basics`] (launched over 3 threads as Warp
//! does), `test_builtin_with_multiple_return` -> [`builtin_with_multiple_return`],
//! `test_user_func_with_multiple_return` -> [`user_func_with_multiple_return`],
//! `test_user_func_with_tuple_arg` -> [`user_func_with_tuple_arg`],
//! `test_complex_tuple_functions` -> [`complex_tuple_functions`]. Tolerances are Warp's:
//! `expect_near`'s default `1e-6`, written out (here the tolerance is not optional).
//!
//! Adapted: Warp's `wp.mat22(1.1, 2.2, 3.3, 4.4)` lists rows; glam builds from columns, so the
//! same matrix is `Mat2::from_cols(vec2(1.1, 3.3), vec2(2.2, 4.4))`. Warp's positional struct
//! constructor `BasicsStruct(origin, scale)` is a struct literal. Warp reads elements as
//! `t[0]`; Rust's spelling is `t.0`.
//!
//! Not ported: the `len(t)` / `wp.static(len(t))` checks inside the ported kernels (a Rust
//! tuple's arity is part of its type, there is no `len`); `test_loop` (a `for` loop indexing
//! a tuple with a run-time index: Rust tuples are indexed by literal `.N` only, so this
//! construct does not exist in the language); `test_loop_variadic_any` and
//! `test_loop_variadic_ellipsis` (funcs generic over the tuple's arity, `Any` /
//! `tuple[int, ...]`: funcs here are generic over float types only).

use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    basics,
    builtin_with_multiple_return,
    user_func_with_multiple_return,
    user_func_with_tuple_arg,
    complex_tuple_functions,
);

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct BasicsStruct {
    origin: Vec3,
    scale: f32,
}

/// Warp's row-major `mat22(1.1, 2.2, 3.3, 4.4)`.
#[wp::func]
fn warp_mat22() -> Mat2 {
    Mat2::from_cols(vec2(1.1, 3.3), vec2(2.2, 4.4))
}

#[wp::kernel]
fn k_basics() {
    let tid = tid();
    let s = BasicsStruct {
        origin: vec3(1.1, 2.2, 3.3),
        scale: 1.23,
    };
    let t = (1, 2.2f32, vec3(1.1, 2.2, 3.3), warp_mat22(), s, tid);
    expect_eq(t.0, 1);
    expect_eq(t.1, 2.2);
    expect_eq(t.2, vec3(1.1, 2.2, 3.3));
    expect_eq(t.3, warp_mat22());
    expect_eq(t.4.origin, vec3(1.1, 2.2, 3.3));
    expect_eq(t.4.scale, 1.23);
    expect_eq(t.5, tid());

    let (t0, t1, t2, t3, t4, t5) = t;
    expect_eq(t0, 1);
    expect_eq(t1, 2.2);
    expect_eq(t2, vec3(1.1, 2.2, 3.3));
    expect_eq(t3, warp_mat22());
    expect_eq(t4.origin, vec3(1.1, 2.2, 3.3));
    expect_eq(t4.scale, 1.23);
    expect_eq(t5, tid());
}

fn basics(dev: &wp::Device) {
    wp::launch(k_basics, 3, (), dev).unwrap();
}

#[wp::kernel]
fn k_builtin_with_multiple_return() {
    let expected_axis = vec3(0.26726124, 0.53452247, 0.80178368);
    let expected_angle = 1.50408018f32;
    let q = Quat::from_xyzw(1.0, 2.0, 3.0, 4.0);

    let t = quat_to_axis_angle(q);
    let axis_1 = t.0;
    let angle_1 = t.1;
    expect_near(axis_1.x, expected_axis.x, 1e-6);
    expect_near(axis_1.y, expected_axis.y, 1e-6);
    expect_near(axis_1.z, expected_axis.z, 1e-6);
    expect_near(angle_1, expected_angle, 1e-6);

    let (axis_2, angle_2) = t;
    expect_near(axis_2.x, expected_axis.x, 1e-6);
    expect_near(axis_2.y, expected_axis.y, 1e-6);
    expect_near(axis_2.z, expected_axis.z, 1e-6);
    expect_near(angle_2, expected_angle, 1e-6);

    let (axis_3, angle_3) = quat_to_axis_angle(q);
    expect_near(axis_3.x, expected_axis.x, 1e-6);
    expect_near(axis_3.y, expected_axis.y, 1e-6);
    expect_near(axis_3.z, expected_axis.z, 1e-6);
    expect_near(angle_3, expected_angle, 1e-6);
}

fn builtin_with_multiple_return(dev: &wp::Device) {
    wp::launch(k_builtin_with_multiple_return, 1, (), dev).unwrap();
}

#[wp::func]
fn user_func_with_multiple_return_f(x: i32, y: f32) -> (i32, f32) {
    (x * 123, y * 1.23)
}

#[wp::kernel]
fn k_user_func_with_multiple_return() {
    let t = user_func_with_multiple_return_f(4, pow(2.0f32, 3.0));
    let x_1 = t.0;
    let y_1 = t.1;
    expect_eq(x_1, 492);
    expect_near(y_1, 9.84, 1e-6);

    let (x_2, y_2) = t;
    expect_eq(x_2, 492);
    expect_near(y_2, 9.84, 1e-6);

    let (x_3, y_3) = user_func_with_multiple_return_f(4, pow(2.0f32, 3.0));
    expect_eq(x_3, 492);
    expect_near(y_3, 9.84, 1e-6);
}

fn user_func_with_multiple_return(dev: &wp::Device) {
    wp::launch(k_user_func_with_multiple_return, 1, (), dev).unwrap();
}

#[wp::func]
fn user_func_with_tuple_arg_f(values: (Vec3, f32)) -> f32 {
    values.0.length() * values.1
}

#[wp::kernel]
fn k_user_func_with_tuple_arg() {
    let t = (vec3(1.0, 2.0, 3.0), pow(2.0f32, 4.0));

    let x_1 = user_func_with_tuple_arg_f(t);
    expect_near(x_1, 59.86652, 1e-6);

    let x_2 = user_func_with_tuple_arg_f((t.0, t.1));
    expect_near(x_2, 59.86652, 1e-6);

    let x_3 = user_func_with_tuple_arg_f((vec3(1.0, 2.0, 3.0), pow(2.0f32, 4.0)));
    expect_near(x_3, 59.86652, 1e-6);
}

fn user_func_with_tuple_arg(dev: &wp::Device) {
    wp::launch(k_user_func_with_tuple_arg, 1, (), dev).unwrap();
}

#[wp::func]
fn complex_tuple_function(scale: f32, offset: Vec3) -> (f32, Vec3, Vec3) {
    let scaled_value = scale * 2.5;
    let position = vec3(offset.x + 1.0, offset.y + 2.0, offset.z + 3.0);
    let velocity = vec3(scale * 0.1, scale * 0.2, scale * 0.3);
    (scaled_value, position, velocity)
}

#[wp::func]
fn mixed_types_tuple_function() -> (Vec3, Vec3, f32, Mat3) {
    (
        vec3(1.0, 2.0, 3.0),
        vec3(4.0, 5.0, 6.0),
        42.0,
        Mat3::IDENTITY,
    )
}

#[wp::func]
fn homogeneous_tuple_function() -> (Vec3, Vec3, Vec3) {
    (
        vec3(1.0, 2.0, 3.0),
        vec3(4.0, 5.0, 6.0),
        vec3(7.0, 8.0, 9.0),
    )
}

#[wp::kernel]
fn k_complex_tuple_functions() {
    let result1 = complex_tuple_function(4.0, vec3(10.0, 20.0, 30.0));

    let (scale_result, pos_result, vel_result) = result1;
    expect_near(scale_result, 10.0, 1e-6);
    expect_eq(pos_result, vec3(11.0, 22.0, 33.0));
    expect_eq(vel_result, vec3(0.4, 0.8, 1.2));

    expect_near(result1.0, 10.0, 1e-6);
    expect_eq(result1.1, vec3(11.0, 22.0, 33.0));
    expect_eq(result1.2, vec3(0.4, 0.8, 1.2));

    let mixed_result = mixed_types_tuple_function();
    let (result_pos, result_vel, result_energy, result_transform) = mixed_result;
    expect_eq(result_pos, vec3(1.0, 2.0, 3.0));
    expect_eq(result_vel, vec3(4.0, 5.0, 6.0));
    expect_eq(result_energy, 42.0);
    expect_eq(result_transform.x_axis.x, 1.0);
    expect_eq(result_transform.y_axis.y, 1.0);
    expect_eq(result_transform.z_axis.z, 1.0);

    let homo_result = homogeneous_tuple_function();
    expect_eq(homo_result.0, vec3(1.0, 2.0, 3.0));
    expect_eq(homo_result.1, vec3(4.0, 5.0, 6.0));
    expect_eq(homo_result.2, vec3(7.0, 8.0, 9.0));

    let (vec1, vec2, vec3_) = homo_result;
    expect_eq(vec1, vec3(1.0, 2.0, 3.0));
    expect_eq(vec2, vec3(4.0, 5.0, 6.0));
    expect_eq(vec3_, vec3(7.0, 8.0, 9.0));
}

fn complex_tuple_functions(dev: &wp::Device) {
    wp::launch(k_complex_tuple_functions, 1, (), dev).unwrap();
}

//! Port of Warp's `warp/tests/test_struct.py`: structs as kernel parameters, locals, func
//! results and array elements; nested structs; struct literals (Warp's positional
//! constructors `Model(1.0, g, m)`); matrix fields written element by element; gradients
//! through struct parameters, literals and func results.
//!
//! Ported (Warp test -> here): `test_step` -> [`step`], `test_step_grad` -> [`step_grad`],
//! `test_nested_struct` -> [`nested_struct`], `test_nested_mat` -> [`nested_mat`],
//! `test_struct_instantiate` -> [`struct_instantiate`], `test_return_struct` ->
//! [`return_struct`], `test_return` -> [`return_func`], `test_struct_mutate_attributes` ->
//! [`mutate_attributes`], `test_nested_array_struct` -> [`nested_array_struct`],
//! `test_struct_returned_from_func_grad` -> [`returned_from_func_grad`] (its first case).
//! Tolerances are Warp's: absolute `1e-6` for the integration step and its gradients
//! (`assert_np_equal(.., tol=1e-6)`), `1e-5` for the returned-struct gradient, exact
//! (`expect_eq`, `assert_np_equal` without `tol`) elsewhere.
//!
//! Adapted: Warp's structs hold `wp.array` fields (`Model.m`, `State.x`, `State.v`,
//! `Baz.data`, `ArrayStruct.array`); a `#[derive(Struct)]` holds values only (scalars,
//! vectors, matrices, fixed-size arrays, structs), so those arrays are kernel parameters of
//! their own next to the struct, and the structs keep their value fields. Warp's random
//! inputs (`numpy.random.default_rng(123)`) are replaced by a fixed hash of the same sizes
//! (5 bodies; masses in [0.1, 1.1) as Warp's). Warp's default-constructed `MatStruct()` is
//! the literal `MatStruct { m: Mat4::ZERO }`; its row-major `m[1, 2]` is glam's column-major
//! `m.z_axis.y`.
//!
//! Not ported: the `State(state_out.x, state_out.v)` copy in `kernel_step_with_copy` (a struct
//! of arrays); `test_empty`, `test_uninitialized`, `test_nested_empty_struct` (structs without
//! value fields, or whose only field is an array); `test_struct_default_attributes` (Warp's
//! zero-initialising `DefaultAttribStruct()` in a kernel: there is no `Default` for structs in
//! kernels; a literal spells every field); the second case of
//! `test_struct_returned_from_func_grad` (a struct holding an array); and Python-side tests
//! without a kernel equivalent (`test_struct_math_conversions`, `test_convert_to_device`,
//! `test_struct_attribute_error`, `test_struct_inheritance_error`, `test_assign_view`, the
//! hashing, garbage-collection and field-assignment validation tests), which the Rust type
//! system or the host API decide at compile time.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    step,
    step_grad,
    nested_struct,
    nested_mat,
    struct_instantiate,
    return_struct,
    return_func,
    mutate_attributes,
    nested_array_struct,
    returned_from_func_grad,
);

/// Warp's `Model` without its mass array.
#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Model {
    dt: f32,
    gravity: Vec3,
}

#[wp::kernel]
fn k_step(
    x_in: Array<Vec3>,
    v_in: Array<Vec3>,
    x_out: Array<Vec3>,
    v_out: Array<Vec3>,
    model: Model,
    m: Array<f32>,
) {
    let i = tid();
    v_out[i] = v_in[i] + model.gravity / m[i] * model.dt;
    x_out[i] = x_in[i] + v_out[i] * model.dt;
}

#[wp::kernel]
fn k_step_with_copy(
    x_in: Array<Vec3>,
    v_in: Array<Vec3>,
    x_out: Array<Vec3>,
    v_out: Array<Vec3>,
    model: Model,
    m: Array<f32>,
) {
    let i = tid();
    let model_rescaled = Model {
        dt: 1.0,
        gravity: model.gravity / m[i] * model.dt,
    };
    v_out[i] = v_in[i] + model_rescaled.gravity;
    x_out[i] = x_in[i] + v_out[i] * model.dt;
}

#[wp::kernel]
fn k_loss(x: Array<Vec3>, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, 0, x[i].x * x[i].x + x[i].y * x[i].y + x[i].z * x[i].z);
}

const DIM: usize = 5;
const DT: f32 = 0.01;

/// Fixed pseudo-random numbers in [-1, 1) (a sine hash), standing in for Warp's seeded draws.
fn noise(k: usize) -> f32 {
    (((k as f64 * 12.9898).sin() * 43758.5453).rem_euclid(1.0) * 2.0 - 1.0) as f32
}

fn vecs(offset: usize) -> Vec<Vec3> {
    (0..DIM)
        .map(|i| {
            2.0 * Vec3::new(
                noise(offset + 3 * i),
                noise(offset + 3 * i + 1),
                noise(offset + 3 * i + 2),
            )
        })
        .collect()
}

#[track_caller]
fn near3(got: &[Vec3], want: &[[f64; 3]], tol: f64, what: &str) {
    for (i, (g, w)) in got.iter().zip(want).enumerate() {
        for k in 0..3 {
            let d = (g[k] as f64 - w[k]).abs();
            assert!(
                d <= tol,
                "{what}[{i}][{k}]: got {}, want {} (Warp's absolute tolerance {tol:e})",
                g[k],
                w[k]
            );
        }
    }
}

fn model() -> Model {
    Model {
        dt: DT,
        gravity: Vec3::new(0.0, 0.0, -9.81),
    }
}

/// `x + (v + g / m * dt) * dt` in f64 from the f32 inputs, as Warp's numpy reference.
fn expected_x(x: &[Vec3], v: &[Vec3], m: &[f32]) -> Vec<[f64; 3]> {
    let g = [0.0, 0.0, -9.81f32 as f64];
    let dt = DT as f64;
    (0..DIM)
        .map(|i| {
            std::array::from_fn(|k| {
                x[i][k] as f64 + (v[i][k] as f64 + g[k] / m[i] as f64 * dt) * dt
            })
        })
        .collect()
}

fn step(dev: &wp::Device) {
    let m = vec![1.0f32; DIM];
    let (x, v) = (vecs(0), vecs(100));
    let want = expected_x(&x, &v, &m);
    let (x_in, v_in, m_a) = (arr(&x, dev), arr(&v, dev), arr(&m, dev));
    for with_copy in [false, true] {
        let (x_out, v_out) = (zeros::<Vec3, 1>(DIM, dev), zeros::<Vec3, 1>(DIM, dev));
        let args = (&x_in, &v_in, &x_out, &v_out, model(), &m_a);
        if with_copy {
            wp::launch(k_step_with_copy, DIM, args, dev).unwrap();
        } else {
            wp::launch(k_step, DIM, args, dev).unwrap();
        }
        near3(
            &host(&x_out),
            &want,
            1e-6,
            if with_copy {
                "kernel_step_with_copy x"
            } else {
                "kernel_step x"
            },
        );
    }
}

fn step_grad(dev: &wp::Device) {
    let m: Vec<f32> = (0..DIM).map(|i| noise(200 + i) * 0.5 + 0.6).collect();
    let (x, v) = (vecs(0), vecs(100));
    let x_in = arr(&x, dev).with_grad().unwrap();
    let v_in = arr(&v, dev).with_grad().unwrap();
    let m_a = arr(&m, dev).with_grad().unwrap();
    let x_out = zeros::<Vec3, 1>(DIM, dev).with_grad().unwrap();
    let v_out = zeros::<Vec3, 1>(DIM, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let g = [0.0, 0.0, -9.81f32 as f64];
    let dt = DT as f64;
    for with_copy in [false, true] {
        let name = if with_copy {
            "kernel_step_with_copy"
        } else {
            "kernel_step"
        };
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            let args = (&x_in, &v_in, &x_out, &v_out, model(), &m_a);
            if with_copy {
                wp::launch(k_step_with_copy, DIM, args, dev).unwrap();
            } else {
                wp::launch(k_step, DIM, args, dev).unwrap();
            }
            wp::launch(k_loss, DIM, (&x_out, &loss), dev).unwrap();
        }
        tape.backward(&loss).unwrap();
        // Warp's reference: dl/dx = 2 x_out, dl/dv = dl/dx dt, dl/dm = sum(dl/dv * -g dt / m²).
        let xo = host(&x_out);
        let dl_dx: Vec<[f64; 3]> = xo
            .iter()
            .map(|p| std::array::from_fn(|k| 2.0 * p[k] as f64))
            .collect();
        let dl_dv: Vec<[f64; 3]> = dl_dx
            .iter()
            .map(|d| std::array::from_fn(|k| d[k] * dt))
            .collect();
        let dl_dm: Vec<f64> = (0..DIM)
            .map(|i| {
                (0..3)
                    .map(|k| dl_dv[i][k] * (-g[k] * dt / (m[i] as f64).powi(2)))
                    .sum()
            })
            .collect();
        near3(
            &host(&x_in.grad().unwrap()),
            &dl_dx,
            1e-6,
            &format!("{name}: x grad"),
        );
        near3(
            &host(&v_in.grad().unwrap()),
            &dl_dv,
            1e-6,
            &format!("{name}: v grad"),
        );
        for (i, (gm, w)) in host(&m_a.grad().unwrap()).iter().zip(&dl_dm).enumerate() {
            assert!(
                (*gm as f64 - w).abs() <= 1e-6,
                "{name}: m grad[{i}]: got {gm}, want {w}"
            );
        }
        tape.zero().unwrap();
        // Warp checks that zeroing the tape clears the inputs' gradients.
        assert!(host(&x_in.grad().unwrap()).iter().all(|g| *g == Vec3::ZERO));
        assert!(host(&v_in.grad().unwrap()).iter().all(|g| *g == Vec3::ZERO));
        assert!(host(&m_a.grad().unwrap()).iter().all(|g| *g == 0.0));
        loss.fill(0.0).unwrap();
    }
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Baz {
    z: Vec3,
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Bar {
    baz: Baz,
    y: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Foo {
    bar: Bar,
    x: i32,
}

#[wp::kernel]
fn k_nested_struct(foo: Foo, data: Array<i32>) {
    let tid = tid();
    data[tid] = data[tid]
        + foo.x
        + (foo.bar.y * 100.0) as i32
        + foo.bar.baz.z.length_squared() as i32
        + tid as i32 * 2;
}

fn nested_struct(dev: &wp::Device) {
    let nested = Foo {
        bar: Bar {
            baz: Baz {
                z: Vec3::new(1.0, 2.0, 3.0),
            },
            y: 1.23,
        },
        x: 123,
    };
    let data = zeros::<i32, 1>(3, dev);
    wp::launch(k_nested_struct, 3, (nested, &data), dev).unwrap();
    assert_eq!(host(&data), vec![260, 262, 264]);
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct MatStruct {
    m: Mat4,
}

#[wp::kernel]
fn k_nested_mat(out: Array<Mat4>) {
    let mut s = MatStruct { m: Mat4::ZERO };
    // Warp's row-major s.m[0, 0], s.m[1, 2], s.m[2][1].
    s.m.x_axis.x = 2.0;
    s.m.z_axis.y = 3.0;
    s.m.y_axis.z = 5.0;

    out[0] = s.m;

    // out[0][2, 2], out[0][1][1], out[0][3, 3] = out[0][0][0].
    out[0].z_axis.z = 6.0;
    out[0].y_axis.y = 7.0;
    out[0].w_axis.w = out[0].x_axis.x;
}

fn nested_mat(dev: &wp::Device) {
    let m = zeros::<Mat4, 1>(1, dev);
    wp::launch(k_nested_mat, 1, (&m,), dev).unwrap();
    let o = host(&m)[0];
    // (row, column) as Warp's assertions read them.
    let at = |r: usize, c: usize| o.col(c)[r];
    assert_eq!(at(0, 0), 2.0);
    assert_eq!(at(1, 2), 3.0);
    assert_eq!(at(2, 1), 5.0);
    assert_eq!(at(2, 2), 6.0);
    assert_eq!(at(1, 1), 7.0);
    assert_eq!(at(3, 3), 2.0);
}

#[wp::kernel]
fn k_struct_instantiate(data: Array<i32>) {
    let baz = Baz {
        z: vec3(0.0, 0.0, 26.0),
    };
    let bar = Bar { baz, y: 25.0 };
    let foo = Foo { bar, x: 24 };

    expect_eq(foo.x, 24);
    expect_eq(foo.bar.y, 25.0);
    expect_eq(foo.bar.baz.z.z, 26.0);
    expect_eq(data[0], 1);
}

fn struct_instantiate(dev: &wp::Device) {
    wp::launch(k_struct_instantiate, 1, (&arr(&[1i32], dev),), dev).unwrap();
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct TestData {
    value: i32,
}

#[wp::func]
fn get_test_data(value: i32) -> TestData {
    TestData { value: value * 2 }
}

#[wp::kernel]
fn k_return_struct(data: Array<i32>) {
    let tid = tid();
    data[tid] = get_test_data(tid as i32).value;
    expect_eq(data[tid], tid as i32 * 2);
}

fn return_struct(dev: &wp::Device) {
    // Warp launches one thread on an array of 10.
    let data = zeros::<i32, 1>(10, dev);
    wp::launch(k_return_struct, 1, (&data,), dev).unwrap();
    assert_eq!(host(&data)[0], 0);
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct ReturnStruct {
    a: i32,
    b: i32,
}

#[wp::func]
fn return_func_f() -> ReturnStruct {
    let a = ReturnStruct { a: 1, b: 2 };
    a
}

#[wp::kernel]
fn k_return() {
    let t = return_func_f();
    expect_eq(t.a, 1);
    expect_eq(t.b, 2);
}

fn return_func(dev: &wp::Device) {
    wp::launch(k_return, 1, (), dev).unwrap();
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct MutableStruct {
    param1: i32,
    param2: f32,
}

#[wp::kernel]
fn k_mutate_attributes() {
    let mut t = MutableStruct {
        param1: 0,
        param2: 0.0,
    };
    t.param1 = 1;
    t.param2 = 1.1;
    expect_eq(t.param1, 1);
    expect_eq(t.param2, 1.1);
}

fn mutate_attributes(dev: &wp::Device) {
    wp::launch(k_mutate_attributes, 1, (), dev).unwrap();
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct InnerStruct {
    i: i32,
}

#[wp::kernel]
fn k_struct2_reader(array: Array<InnerStruct>) {
    let k = tid();
    expect_eq(k as i32 + 1, array[k].i);
}

fn nested_array_struct(dev: &wp::Device) {
    let a = arr(&[InnerStruct { i: 1 }, InnerStruct { i: 2 }], dev);
    wp::launch(k_struct2_reader, 2, (&a,), dev).unwrap();
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct ScaledVecStruct {
    v: Vec3,
}

#[wp::func]
fn make_scaled_vec_struct(x: Vec3) -> ScaledVecStruct {
    let mut s = ScaledVecStruct { v: Vec3::ZERO };
    s.v = x * 2.0;
    s
}

#[wp::kernel]
fn k_scaled_vec_struct_dot(x: Array<Vec3>, loss: Array<f32>) {
    let s = make_scaled_vec_struct(x[0]);
    loss[0] = s.v.dot(s.v);
}

fn returned_from_func_grad(dev: &wp::Device) {
    // loss = dot(2x, 2x), so d/dx = 8x: [8, 16, 24] at x = [1, 2, 3].
    let x = arr(&[Vec3::new(1.0, 2.0, 3.0)], dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_scaled_vec_struct_dot, 1, (&x, &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    let g = host(&x.grad().unwrap())[0];
    for (k, want) in [8.0f32, 16.0, 24.0].into_iter().enumerate() {
        assert!(
            (g[k] - want).abs() <= 1e-5,
            "x grad [{k}]: got {}, want {want} (Warp's tolerance 1e-5)",
            g[k]
        );
    }
}

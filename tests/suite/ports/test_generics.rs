//! Port of Warp's `warp/tests/test_generics.py`: generic funcs and kernels (Warp's `Any`
//! parameters and `wp.overload`), here `fn f<T: Float>(..)`, whose instances the launch
//! arguments pick (f32 and f64; `Vec3<T>`, `Mat3<T>` name the glam family members). Warp's
//! kernels check themselves with `wp.expect_eq`; so do these, and host checks are exact as
//! Warp's `assert_np_equal` without `tol` (every value here is exact in both precisions),
//! except the norm, within Warp's relative `1e-6`.
//!
//! Ported (Warp test -> here): `test_generic_adder` -> [`generic_adder_instances`],
//! `test_eager_generic_func_after_concrete_overload` -> [`eager_generic_norm`] (its kernel),
//! `test_eager_generic_func_does_not_retain_array` -> [`generic_array_length`] (its kernel),
//! `test_generic_array_kernel` -> [`generic_array_kernel`], `test_generic_accumulator_kernel`
//! -> [`generic_accumulator_kernel`], `test_generic_fill` -> [`generic_fill`],
//! `test_generic_conditional_setter` -> [`generic_conditional_setter`],
//! `test_generic_transform_kernel` -> [`generic_transform`], `test_generic_transform_array_kernel`
//! -> [`generic_transform_array`], `test_generic_type_cast` -> [`generic_type_cast`],
//! `test_generic_scalar_construction` -> [`generic_scalar_construction`],
//! `test_generic_type_as_argument` -> [`generic_type_as_argument`].
//!
//! Adapted: type parameters range over the float scalars (f32, f64) only, so each Warp
//! overload on `int`, `bool` or a `vec3` argument keeps its float instances, and a vector or
//! matrix overload is a func or kernel over `Vec3<T>` / `Mat3<T>` of its own (one per length:
//! there are no length generics). `test_generic_accumulator_kernel` adds 17.0 (f32) and 8.0
//! (f64), so its arrays end at 25 (Warp's 51 adds the int 25 and the bool 1 too).
//! `type(a)(b)` is `b as A`; `type(a[0])(0)` a literal of `T`; `wp.identity(n=2, dtype=T)` is
//! `Mat2::<T>::IDENTITY`.
//!
//! Not ported: the int, bool and `vec3b` instances and the `my_vec5` / `my_mat55` instances
//! (integer, boolean and length generics, and vectors longer than 4, are not in the
//! language); `test_specialized_func` (overloads by arity and by concrete type next to a
//! generic one: Rust has no overloading); `test_generic_fill_overloads` (explicit instances
//! made by `wp.overload` and launched by name: instances here are picked from the arguments);
//! `test_generic_struct_kernel` and `test_generic_struct_construction` (kernels generic over
//! struct types: type parameters are float scalars only); `test_generic_type_construction`
//! (its `mat22d` instance constructs a matrix from a matrix by `type(a[0])`, and its
//! `vec3f` instance a vector from a vector: no generic over the vector type itself);
//! `test_annotations_kernel` (`wp.Int` / `wp.Scalar` annotations and int16 vectors and
//! matrices); the overload-stub, garbage-collection and error-message tests, which are about
//! Python's decorators and error text.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    generic_adder_instances,
    eager_generic_norm,
    generic_array_length,
    generic_array_kernel,
    generic_accumulator_kernel,
    generic_fill,
    generic_conditional_setter,
    generic_transform,
    generic_transform_array,
    generic_type_cast,
    generic_scalar_construction,
    generic_type_as_argument,
);

#[wp::func]
fn generic_adder<T: Float>(a: T, b: T) -> T {
    a + b
}

#[wp::func]
fn generic_adder_vec<T: Float>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    a + b
}

#[wp::kernel]
fn k_generic_adder() {
    expect_eq(generic_adder::<f32>(7.0, 10.0), 17.0);
    expect_eq(generic_adder::<f64>(7.0, 10.0), 17.0);
    let v1 = vec3(1.0, 2.0, 3.0);
    let v2 = vec3(10.0, 20.0, 30.0);
    expect_eq(generic_adder_vec::<f32>(v1, v2), vec3(11.0, 22.0, 33.0));
    let d1 = DVec3::new(1.0, 2.0, 3.0);
    let d2 = DVec3::new(10.0, 20.0, 30.0);
    expect_eq(
        generic_adder_vec::<f64>(d1, d2),
        DVec3::new(11.0, 22.0, 33.0),
    );
}

fn generic_adder_instances(dev: &wp::Device) {
    wp::launch(k_generic_adder, 1, (), dev).unwrap();
}

#[wp::func]
fn eager_generic_norm_f<T: Float>(x: Vec2<T>) -> T {
    x.length()
}

#[wp::kernel]
fn k_eager_generic_norm_use_vec2(out: Array<f32>) {
    out[0] = eager_generic_norm_f::<f32>(vec2(1.0, 2.0));
}

fn eager_generic_norm(dev: &wp::Device) {
    let out = zeros::<f32, 1>(1, dev);
    wp::launch(k_eager_generic_norm_use_vec2, 1, (&out,), dev).unwrap();
    let (got, want) = (host(&out)[0] as f64, 5.0f64.sqrt());
    // numpy's assert_allclose(rtol=1e-6).
    assert!(
        (got - want).abs() <= 1e-6 * want.abs(),
        "|(1, 2)|: got {got}, want {want}"
    );
}

#[wp::func]
fn eager_generic_array_length_f<T: Float>(x: Array<T>) -> i32 {
    x.len() as i32
}

#[wp::kernel]
fn k_eager_generic_array_length<T: Float>(x: Array<T>, out: Array<i32>) {
    out[0] = eager_generic_array_length_f::<T>(x);
}

fn generic_array_length(dev: &wp::Device) {
    let out = zeros::<i32, 1>(1, dev);
    wp::launch(
        k_eager_generic_array_length,
        1,
        (&zeros::<f32, 1>(1, dev), &out),
        dev,
    )
    .unwrap();
    assert_eq!(host(&out), vec![1]);
    wp::launch(
        k_eager_generic_array_length,
        1,
        (&zeros::<f64, 1>(3, dev), &out),
        dev,
    )
    .unwrap();
    assert_eq!(host(&out), vec![3]);
}

#[wp::kernel]
fn k_generic_array<T: Float>(a: Array<T>, b: Array<T>, c: Array<T>) {
    let tid = tid();
    let sum = a[tid] + b[tid];
    c[tid] = generic_adder::<T>(sum, sum);
}

#[wp::kernel]
fn k_generic_array_vec<T: Float>(a: Array<Vec3<T>>, b: Array<Vec3<T>>, c: Array<Vec3<T>>) {
    let tid = tid();
    let sum = a[tid] + b[tid];
    c[tid] = generic_adder_vec::<T>(sum, sum);
}

fn generic_array_kernel(dev: &wp::Device) {
    let n = 10;
    let (af, cf) = (arr(&vec![1.0f32; n], dev), zeros::<f32, 1>(n, dev));
    let (ad, cd) = (arr(&vec![1.0f64; n], dev), zeros::<f64, 1>(n, dev));
    let (a3, c3) = (arr(&vec![Vec3::ONE; n], dev), zeros::<Vec3, 1>(n, dev));
    wp::launch(k_generic_array, n, (&af, &af, &cf), dev).unwrap();
    wp::launch(k_generic_array, n, (&ad, &ad, &cd), dev).unwrap();
    wp::launch(k_generic_array_vec, n, (&a3, &a3, &c3), dev).unwrap();
    assert_eq!(host(&cf), vec![4.0; n]);
    assert_eq!(host(&cd), vec![4.0; n]);
    assert_eq!(host(&c3), vec![Vec3::splat(4.0); n]);
}

#[wp::kernel]
fn k_generic_accumulator<T: Float>(a: Array<f64>, value: T) {
    let tid = tid();
    a[tid] = a[tid] + value as f64;
}

fn generic_accumulator_kernel(dev: &wp::Device) {
    let n = 10;
    let a = zeros::<f64, 1>(n, dev);
    wp::launch(k_generic_accumulator, n, (&a, 17.0f32), dev).unwrap();
    wp::launch(k_generic_accumulator, n, (&a, 8.0f64), dev).unwrap();
    assert_eq!(host(&a), vec![25.0; n]);
}

#[wp::kernel]
fn k_generic_fill<T: Float>(a: Array<T>, value: T) {
    let tid = tid();
    a[tid] = value;
}

#[wp::kernel]
fn k_generic_fill_vec<T: Float>(a: Array<Vec3<T>>, value: Vec3<T>) {
    let tid = tid();
    a[tid] = value;
}

fn generic_fill(dev: &wp::Device) {
    let n = 10;
    let (af, ad, a3) = (
        zeros::<f32, 1>(n, dev),
        zeros::<f64, 1>(n, dev),
        zeros::<Vec3, 1>(n, dev),
    );
    wp::launch(k_generic_fill, n, (&af, 17.0f32), dev).unwrap();
    wp::launch(k_generic_fill, n, (&ad, 42.0f64), dev).unwrap();
    wp::launch(k_generic_fill_vec, n, (&a3, Vec3::splat(5.0)), dev).unwrap();
    assert_eq!(host(&af), vec![17.0; n]);
    assert_eq!(host(&ad), vec![42.0; n]);
    assert_eq!(host(&a3), vec![Vec3::splat(5.0); n]);
}

#[wp::func]
fn generic_conditional_setter_f<T: Float>(a: Array<T>, i: i32, value: T, relative: bool) {
    if relative {
        a[i] += value;
    } else {
        a[i] = value;
    }
}

#[wp::kernel]
fn k_generic_conditional_setter<T: Float>(a: Array<T>, i: i32, value: T, relative: bool) {
    generic_conditional_setter_f::<T>(a, i, value, relative);
}

fn generic_conditional_setter(dev: &wp::Device) {
    let n = 10;
    let a = zeros::<f32, 1>(n, dev);
    wp::launch(
        k_generic_conditional_setter,
        1,
        (&a, 1, 42.0f32, false),
        dev,
    )
    .unwrap();
    wp::launch(k_generic_conditional_setter, 1, (&a, 1, 5.0f32, true), dev).unwrap();
    let mut want = vec![0.0f32; n];
    want[1] = 47.0;
    assert_eq!(host(&a), want);
}

#[wp::kernel]
fn k_generic_transform2<T: Float>(v: Vec2<T>, m: Mat2<T>, expected: Vec2<T>) {
    expect_eq(m * v, expected);
}

#[wp::kernel]
fn k_generic_transform3<T: Float>(v: Vec3<T>, m: Mat3<T>, expected: Vec3<T>) {
    expect_eq(m * v, expected);
}

#[wp::kernel]
fn k_generic_transform4<T: Float>(v: Vec4<T>, m: Mat4<T>, expected: Vec4<T>) {
    expect_eq(m * v, expected);
}

fn generic_transform(dev: &wp::Device) {
    let (v2, v3, v4) = (
        Vec2::new(1.0, 2.0),
        Vec3::new(1.0, 2.0, 3.0),
        Vec4::new(1.0, 2.0, 3.0, 4.0),
    );
    wp::launch(
        k_generic_transform2,
        1,
        (v2, Mat2::from_diagonal(Vec2::splat(2.0)), v2 * 2.0),
        dev,
    )
    .unwrap();
    wp::launch(
        k_generic_transform3,
        1,
        (v3, Mat3::from_diagonal(Vec3::splat(2.0)), v3 * 2.0),
        dev,
    )
    .unwrap();
    wp::launch(
        k_generic_transform4,
        1,
        (v4, Mat4::from_diagonal(Vec4::splat(2.0)), v4 * 2.0),
        dev,
    )
    .unwrap();
    // And the f64 instances.
    let d3 = DVec3::new(1.0, 2.0, 3.0);
    wp::launch(
        k_generic_transform3,
        1,
        (d3, DMat3::from_diagonal(DVec3::splat(2.0)), d3 * 2.0),
        dev,
    )
    .unwrap();
    wp::synchronize().unwrap();
}

#[wp::kernel]
fn k_generic_transform_array2<T: Float>(
    v: Array<Vec2<T>>,
    m: Array<Mat2<T>>,
    result: Array<Vec2<T>>,
) {
    let tid = tid();
    result[tid] = m[tid] * v[tid];
}

#[wp::kernel]
fn k_generic_transform_array3<T: Float>(
    v: Array<Vec3<T>>,
    m: Array<Mat3<T>>,
    result: Array<Vec3<T>>,
) {
    let tid = tid();
    result[tid] = m[tid] * v[tid];
}

#[wp::kernel]
fn k_generic_transform_array4<T: Float>(
    v: Array<Vec4<T>>,
    m: Array<Mat4<T>>,
    result: Array<Vec4<T>>,
) {
    let tid = tid();
    result[tid] = m[tid] * v[tid];
}

fn generic_transform_array(dev: &wp::Device) {
    let n = 10;
    // Warp's data: every row is (0, 1, .., k-1), every matrix 2 I.
    let a2 = vec![Vec2::new(0.0, 1.0); n];
    let a3 = vec![Vec3::new(0.0, 1.0, 2.0); n];
    let a4 = vec![Vec4::new(0.0, 1.0, 2.0, 3.0); n];
    let b2 = zeros::<Vec2, 1>(n, dev);
    let b3 = zeros::<Vec3, 1>(n, dev);
    let b4 = zeros::<Vec4, 1>(n, dev);
    let m2 = arr(&vec![Mat2::from_diagonal(Vec2::splat(2.0)); n], dev);
    let m3 = arr(&vec![Mat3::from_diagonal(Vec3::splat(2.0)); n], dev);
    let m4 = arr(&vec![Mat4::from_diagonal(Vec4::splat(2.0)); n], dev);
    wp::launch(
        k_generic_transform_array2,
        n,
        (&arr(&a2, dev), &m2, &b2),
        dev,
    )
    .unwrap();
    wp::launch(
        k_generic_transform_array3,
        n,
        (&arr(&a3, dev), &m3, &b3),
        dev,
    )
    .unwrap();
    wp::launch(
        k_generic_transform_array4,
        n,
        (&arr(&a4, dev), &m4, &b4),
        dev,
    )
    .unwrap();
    assert_eq!(host(&b2), a2.iter().map(|v| *v * 2.0).collect::<Vec<_>>());
    assert_eq!(host(&b3), a3.iter().map(|v| *v * 2.0).collect::<Vec<_>>());
    assert_eq!(host(&b4), a4.iter().map(|v| *v * 2.0).collect::<Vec<_>>());
}

#[wp::kernel]
fn k_generic_type_cast<A: Float, B: Float>(a: A, b: B) {
    let a = b as A;
    let c = a as B;
    expect_eq(b, c);
}

fn generic_type_cast(dev: &wp::Device) {
    wp::launch(k_generic_type_cast, 1, (1.0f32, 2.0f64), dev).unwrap();
    wp::launch(k_generic_type_cast, 1, (1.0f64, -5.0f32), dev).unwrap();
    wp::synchronize().unwrap();
}

#[wp::kernel]
fn k_generic_scalar_construction<T: Float>(a: Array<T>) {
    let zero = 0.0 as T;
    let mut copy = a[0];
    copy += zero;
    expect_eq(copy, a[0]);
}

fn generic_scalar_construction(dev: &wp::Device) {
    wp::launch(
        k_generic_scalar_construction,
        1,
        (&arr(&[-5.0f64], dev),),
        dev,
    )
    .unwrap();
    wp::launch(
        k_generic_scalar_construction,
        1,
        (&arr(&[1.0f32], dev),),
        dev,
    )
    .unwrap();
    wp::synchronize().unwrap();
}

#[wp::kernel]
fn k_generic_type_as_argument<T: Float>(a: T) {
    let matrix = Mat2::<T>::IDENTITY * a;
    expect_eq(trace(matrix), 2.0 * a);
}

fn generic_type_as_argument(dev: &wp::Device) {
    wp::launch(k_generic_type_as_argument, 1, (2.0f32,), dev).unwrap();
    wp::launch(k_generic_type_as_argument, 1, (-1.0f64,), dev).unwrap();
    wp::synchronize().unwrap();
}

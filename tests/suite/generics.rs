//! Generic kernels and funcs (`fn k<T: Float>(..)`): the launch arguments pick the instance;
//! each instance computes what the same kernel written for that type computes, forward and
//! backward.

use crate::{arr, assert_close_f32, assert_close_f64, fma_rel, fma_rel64, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    generic_kernel_runs_each_instance,
    generic_func_from_generic_kernel,
    generic_vectors_and_constants,
    two_type_parameters,
    generic_kernel_gradients,
    instances_are_named,
    generic_transforms,
);

/// `y = a * x + y` in the array's precision.
#[wp::kernel]
fn axpy<T: Float>(a: T, x: Array<T>, y: Array<T>) {
    let i = tid();
    y[i] = a * x[i] + y[i];
}

fn generic_kernel_runs_each_instance(dev: &wp::Device) {
    let xs = [1.0f64, -2.5, 3.25, 1e-3];
    let ys = [0.5f64, 4.0, -1.0, 7.0];
    // f32: the literal 2.0 becomes f32 from the arrays' type.
    let x32 = arr(&xs.map(|v| v as f32), dev);
    let y32 = arr(&ys.map(|v| v as f32), dev);
    wp::launch(axpy, 4, (2.0, &x32, &y32), dev).unwrap();
    // f64 on the same kernel.
    let x64 = arr(&xs, dev);
    let y64 = arr(&ys, dev);
    wp::launch(axpy, 4, (2.0, &x64, &y64), dev).unwrap();
    for (k, (x, y)) in xs.iter().zip(&ys).enumerate() {
        // One multiply and one add: FMA on CUDA.
        assert_close_f32(
            host(&y32)[k],
            2.0 * (*x as f32) + *y as f32,
            fma_rel(dev),
            "axpy<f32>",
        );
        assert_close_f64(host(&y64)[k], 2.0 * x + y, fma_rel64(dev), "axpy<f64>");
    }
    // The f64 instance really computes in f64: 1 + 1e-10 is not representable in f32.
    let x = arr(&[1e-10f64], dev);
    let y = arr(&[1.0f64], dev);
    wp::launch(axpy, 1, (1.0, &x, &y), dev).unwrap();
    assert_eq!(host(&y)[0], 1.0 + 1e-10);
}

/// A generic func whose type parameter is in no parameter: callers name the instance.
#[wp::func]
fn half<T: Float>() -> T {
    0.5
}

/// A generic func: called as `norm2::<T>(..)` from generic code.
#[wp::func]
fn norm2<T: Float>(v: Vec3<T>) -> T {
    v.dot(v)
}

#[wp::func]
fn scaled_norm2<T: Float>(v: Vec3<T>, s: T) -> T {
    norm2::<T>(v) * s
}

#[wp::kernel]
fn norms<T: Float>(v: Array<Vec3<T>>, out: Array<T>) {
    let i = tid();
    out[i] = scaled_norm2::<T>(v[i], half::<T>()) + norm2::<T>(Vec3::<T>::splat(1.0));
    if i == 99 {
        // `T` inside print arguments is substituted too (never printed: 3 threads).
        println!("{} {}", out[i] as T, T::MAX);
    }
}

fn generic_func_from_generic_kernel(dev: &wp::Device) {
    let vs = [[1.0f64, 2.0, 2.0], [0.0, -3.0, 4.0], [0.5, 0.25, 0.125]];
    let v64: Vec<DVec3> = vs.iter().map(|a| DVec3::from_array(*a)).collect();
    let v32: Vec<Vec3> = v64.iter().map(|v| v.as_vec3()).collect();
    let o64 = zeros::<f64, 1>(3, dev);
    let o32 = zeros::<f32, 1>(3, dev);
    wp::launch(norms, 3, (&arr(&v64, dev), &o64), dev).unwrap();
    wp::launch(norms, 3, (&arr(&v32, dev), &o32), dev).unwrap();
    for k in 0..3 {
        // The inputs are exact in both precisions and every sum is exact: no tolerance.
        assert_eq!(host(&o64)[k], v64[k].dot(v64[k]) * 0.5 + 3.0);
        assert_eq!(host(&o32)[k], v32[k].dot(v32[k]) * 0.5 + 3.0);
    }
    // A non-generic kernel calls a generic func by naming the instance.
    let o = zeros::<f32, 1>(3, dev);
    wp::launch(norms_f32, 3, (&arr(&v32, dev), &o), dev).unwrap();
    assert_eq!(host(&o), host(&o32));
}

#[wp::kernel]
fn norms_f32(v: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    out[i] = scaled_norm2::<f32>(v[i], 0.5) + norm2::<f32>(Vec3::splat(1.0));
}

/// Family members, `T::` constants and casts to `T`.
#[wp::kernel]
fn rotate_all<T: Float>(q: Quat<T>, v: Array<Vec3<T>>, m: Array<Mat3<T>>, info: Array<T>) {
    let i = tid();
    let r = Mat3::<T>::from_quat(q);
    m[i] = r;
    v[i] = r * v[i];
    info[0] = T::MAX;
    info[1] = T::consts::PI;
    info[2] = (i as T) * 0.5;
}

fn generic_vectors_and_constants(dev: &wp::Device) {
    let angle = 0.7f64;
    let q64 = DQuat::from_axis_angle(DVec3::Z, angle);
    let v = [DVec3::new(1.0, 0.0, 0.0), DVec3::new(0.0, 2.0, 1.0)];
    let v64 = arr(&v, dev);
    let m64 = zeros::<DMat3, 1>(2, dev);
    let i64_ = zeros::<f64, 1>(3, dev);
    wp::launch(rotate_all, 2, (q64, &v64, &m64, &i64_), dev).unwrap();
    let v32 = arr(&v.map(|x| x.as_vec3()), dev);
    let m32 = zeros::<Mat3, 1>(2, dev);
    let i32_ = zeros::<f32, 1>(3, dev);
    wp::launch(rotate_all, 2, (q64.as_quat(), &v32, &m32, &i32_), dev).unwrap();
    let info64 = host(&i64_);
    assert_eq!(info64[..2], [f64::MAX, std::f64::consts::PI]);
    let info32 = host(&i32_);
    assert_eq!(info32[..2], [f32::MAX, std::f32::consts::PI]);
    // The last thread to write info[2] is either one: 0 or 0.5.
    assert!(info64[2] == 0.0 || info64[2] == 0.5);
    for (k, want) in v.iter().enumerate() {
        let want = DMat3::from_quat(q64) * *want;
        let got64 = host(&v64)[k];
        let got32 = host(&v32)[k];
        // A rotation is a few products and sums of unit-size terms: 4 ulp of the vector's
        // size in each precision covers the rounding and FMA contraction.
        assert!(
            (got64 - want).length() <= 4.0 * f64::EPSILON * want.length(),
            "{got64} {want}"
        );
        assert!(
            (got32.as_dvec3() - want).length() <= 4.0 * f32::EPSILON as f64 * want.length(),
            "{got32} {want}"
        );
    }
    // Unit-size products and sums: 4 ulp.
    assert!(host(&m64)[0].abs_diff_eq(DMat3::from_quat(q64), 4.0 * f64::EPSILON));
}

/// Two type parameters: four instances.
#[wp::kernel]
fn convert<A: Float, B: Float>(src: Array<A>, dst: Array<B>) {
    let i = tid();
    dst[i] = (src[i] as B) * 2.0;
}

fn two_type_parameters(dev: &wp::Device) {
    let s64 = arr(&[0.1f64, 1e-40, 3.0], dev);
    let s32 = arr(&[0.1f32, 1e-40, 3.0], dev);
    let d32 = zeros::<f32, 1>(3, dev);
    let d64 = zeros::<f64, 1>(3, dev);
    wp::launch(convert, 3, (&s64, &d32), dev).unwrap();
    assert_eq!(
        host(&d32),
        [0.1f64 as f32 * 2.0, 1e-40f64 as f32 * 2.0, 6.0]
    );
    wp::launch(convert, 3, (&s32, &d64), dev).unwrap();
    assert_eq!(
        host(&d64),
        [0.1f32 as f64 * 2.0, 1e-40f32 as f64 * 2.0, 6.0]
    );
    wp::launch(convert, 3, (&s64, &d64), dev).unwrap();
    assert_eq!(host(&d64), [0.2, 2e-40, 6.0]);
    wp::launch(convert, 3, (&s32, &d32), dev).unwrap();
    assert_eq!(host(&d32), [0.2f32, 1e-40f32 * 2.0, 6.0]);
}

/// A loop-carried value, so that the adjoint's stack is exercised in both precisions.
#[wp::kernel]
fn power_sum<T: Float>(x: Array<T>, n: i32, out: Array<T>) {
    let i = tid();
    let mut p = x[i];
    let mut acc: T = 0.0;
    for _ in 0..n {
        acc += p;
        p = p * x[i];
    }
    out[i] = acc;
}

fn generic_kernel_gradients(dev: &wp::Device) {
    // d/dx (x + x^2 + x^3) = 1 + 2x + 3x^2.
    let xs = [0.5f64, -1.25, 2.0];
    let x64 = arr(&xs, dev).with_grad().unwrap();
    let o64 = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let x32 = arr(&xs.map(|v| v as f32), dev).with_grad().unwrap();
    let o32 = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let tape64 = wp::Tape::new();
    {
        let _rec = tape64.record();
        wp::launch(power_sum, 3, (&x64, 3, &o64), dev).unwrap();
    }
    tape64.backward(&o64).unwrap();
    let tape32 = wp::Tape::new();
    {
        let _rec = tape32.record();
        wp::launch(power_sum, 3, (&x32, 3, &o32), dev).unwrap();
    }
    tape32.backward(&o32).unwrap();
    let g64 = host(&x64.grad().unwrap());
    let g32 = host(&x32.grad().unwrap());
    for (k, x) in xs.iter().enumerate() {
        let want = 1.0 + 2.0 * x + 3.0 * x * x;
        // The inputs are dyadic and the powers small: the derivative is exact in f64 and in
        // f32 on the CPU; FMA contraction on CUDA may round differently.
        assert_close_f64(g64[k], want, fma_rel64(dev), "d/dx power_sum<f64>");
        assert_close_f32(g32[k], want as f32, fma_rel(dev), "d/dx power_sum<f32>");
    }
}

/// Each instance is a kernel of its own: named after its types in reports and errors, with a
/// CUDA entry point of its own.
fn instances_are_named(dev: &wp::Device) {
    let infos = wp::aot::instances(convert);
    let names: Vec<&str> = infos.iter().map(|i| i.name).collect();
    assert_eq!(
        names,
        [
            "convert<f32, f32>",
            "convert<f32, f64>",
            "convert<f64, f32>",
            "convert<f64, f64>"
        ]
    );
    let entries: Vec<String> = infos
        .iter()
        .map(|i| wp::cuda_source::assemble(i).entry)
        .collect();
    assert_eq!(entries[1], "wpk_convert_f32_f64_");
    assert!(entries.windows(2).all(|w| w[0] != w[1]));
    // A fault names the instance.
    let src = arr(&[1.0f64], dev);
    let dst = zeros::<f32, 1>(1, dev);
    let err = wp::launch(convert, 2, (&src, &dst), dev).unwrap_err();
    assert!(err.to_string().contains("convert<f64, f32>"), "{err}");
}

/// `Transform<T>` names `Transform` or `DTransform`.
#[wp::kernel]
fn move_points<T: Float>(t: Array<Transform<T>>, p: Array<Vec3<T>>) {
    let i = tid();
    p[i] = t[i].transform_point(p[i]);
}

fn generic_transforms(dev: &wp::Device) {
    let t64 = DTransform::new(DVec3::new(1.0, 2.0, 3.0), DQuat::IDENTITY);
    let p64 = arr(&[DVec3::new(0.5, 0.25, -1.0)], dev);
    wp::launch(move_points, 1, (&arr(&[t64], dev), &p64), dev).unwrap();
    // An identity rotation and dyadic sums: exact.
    assert_eq!(host(&p64), [DVec3::new(1.5, 2.25, 2.0)]);
    let t32 = Transform::new(Vec3::new(1.0, 2.0, 3.0), Quat::IDENTITY);
    let p32 = arr(&[Vec3::new(0.5, 0.25, -1.0)], dev);
    wp::launch(move_points, 1, (&arr(&[t32], dev), &p32), dev).unwrap();
    assert_eq!(host(&p32), [Vec3::new(1.5, 2.25, 2.0)]);
}

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
    integer_type_parameters,
    listed_integer_instances,
    vector_type_parameters,
    vector_kernel_gradients,
    element_type_parameters,
    element_kernel_gradients,
    overloads_by_first_argument,
    overload_gradients,
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

/// `I: Int`: the integer types' own semantics in each instance (unsigned shifts and division,
/// `*` wrapping at the type's width).
#[wp::kernel]
fn int_mix<I: Int>(a: Array<I>, s: I, out: Array<I>) {
    let i = tid();
    let x = a[i];
    out[i] = (x >> 1) / s + x * 3 + clamp_to::<I>(x, I::MAX / 4);
}

#[wp::func]
fn clamp_to<I: Int>(x: I, hi: I) -> I {
    if x > hi {
        hi
    } else {
        x
    }
}

fn integer_type_parameters(dev: &wp::Device) {
    let i32s = [-7i32, 100, i32::MAX, 5];
    let a = arr(&i32s, dev);
    let out = zeros::<i32, 1>(4, dev);
    wp::launch(int_mix, 4, (&a, 3, &out), dev).unwrap();
    let want: Vec<i32> = i32s
        .iter()
        .map(|&x| {
            ((x >> 1) / 3)
                .wrapping_add(x.wrapping_mul(3))
                .wrapping_add(x.min(i32::MAX / 4))
        })
        .collect();
    assert_eq!(host(&out), want, "int_mix<i32>");
    // The same bits as u32: logical shift, unsigned division, another clamp bound.
    let u32s = i32s.map(|x| x as u32);
    let a = arr(&u32s, dev);
    let out = zeros::<u32, 1>(4, dev);
    wp::launch(int_mix, 4, (&a, 3u32, &out), dev).unwrap();
    let want: Vec<u32> = u32s
        .iter()
        .map(|&x| {
            ((x >> 1) / 3)
                .wrapping_add(x.wrapping_mul(3))
                .wrapping_add(x.min(u32::MAX / 4))
        })
        .collect();
    assert_eq!(host(&out), want, "int_mix<u32>");
    let i64s = [-7i64, i64::MAX, 1 << 40, 5];
    let a = arr(&i64s, dev);
    let out = zeros::<i64, 1>(4, dev);
    wp::launch(int_mix, 4, (&a, 3i64, &out), dev).unwrap();
    let want: Vec<i64> = i64s
        .iter()
        .map(|&x| {
            ((x >> 1) / 3)
                .wrapping_add(x.wrapping_mul(3))
                .wrapping_add(x.min(i64::MAX / 4))
        })
        .collect();
    assert_eq!(host(&out), want, "int_mix<i64>");
    let u64s = i64s.map(|x| x as u64);
    let a = arr(&u64s, dev);
    let out = zeros::<u64, 1>(4, dev);
    wp::launch(int_mix, 4, (&a, 3u64, &out), dev).unwrap();
    let want: Vec<u64> = u64s
        .iter()
        .map(|&x| {
            ((x >> 1) / 3)
                .wrapping_add(x.wrapping_mul(3))
                .wrapping_add(x.min(u64::MAX / 4))
        })
        .collect();
    assert_eq!(host(&out), want, "int_mix<u64>");
    // A fault names the instance: division by a zero `s`.
    let err = wp::launch(int_mix, 4, (&a, 0u64, &out), dev).unwrap_err();
    assert!(err.to_string().contains("int_mix<u64>"), "{err}");
}

/// A list picks other integer types than the defaults (`+` wraps at 8 and 16 bits).
#[wp::kernel(instances(I = [u8, i16]))]
fn narrow_sum<I: Int>(a: Array<I>, out: Array<I>) {
    let i = tid();
    out[i] = a[i] + a[i] + 1;
}

fn listed_integer_instances(dev: &wp::Device) {
    let names: Vec<&str> = wp::aot::instances(narrow_sum)
        .iter()
        .map(|i| i.name)
        .collect();
    assert_eq!(names, ["narrow_sum<u8>", "narrow_sum<i16>"]);
    let a = arr(&[200u8, 3], dev);
    let out = zeros::<u8, 1>(2, dev);
    wp::launch(narrow_sum, 2, (&a, &out), dev).unwrap();
    assert_eq!(host(&out), [145, 7]);
    let a = arr(&[-20000i16, 3], dev);
    let out = zeros::<i16, 1>(2, dev);
    wp::launch(narrow_sum, 2, (&a, &out), dev).unwrap();
    assert_eq!(host(&out), [(-40000i32 + 65536 + 1) as i16, 7]);
}

/// `V: Vector`: the operations every float vector has, its lane type `V::Scalar` and lane
/// count `V::LEN` (a literal in each instance).
#[wp::kernel]
fn reject<V: Vector>(x: Array<V>, d: V, s: V::Scalar, out: Array<V>, len: Array<V::Scalar>) {
    let i = tid();
    let n = d.normalize();
    let r = (x[i] - n * x[i].dot(n)) * s + V::ZERO;
    out[i] = r;
    let sq: V::Scalar = r.length_squared();
    len[i] = r.length() + sq + (V::LEN as V::Scalar);
}

fn vector_type_parameters(dev: &wp::Device) {
    // Vec2 (f32): d = (0, 2) normalises exactly to (0, 1); rejection keeps x's first lane.
    let x = arr(&[Vec2::new(3.0, 4.0), Vec2::new(-1.0, 0.5)], dev);
    let out = zeros::<Vec2, 1>(2, dev);
    let len = zeros::<f32, 1>(2, dev);
    wp::launch(
        reject,
        2,
        (&x, Vec2::new(0.0, 2.0), 2.0f32, &out, &len),
        dev,
    )
    .unwrap();
    // Exact: products by 0 and 1, doubling, and sums of small dyadic squares.
    assert_eq!(host(&out), [Vec2::new(6.0, 0.0), Vec2::new(-2.0, 0.0)]);
    assert_eq!(host(&len), [6.0 + 36.0 + 2.0, 2.0 + 4.0 + 2.0]);
    // Vec4 (f32): the lane count is 4.
    let x = arr(&[Vec4::new(1.0, 2.0, 3.0, 4.0)], dev);
    let out = zeros::<Vec4, 1>(1, dev);
    let len = zeros::<f32, 1>(1, dev);
    wp::launch(reject, 1, (&x, Vec4::W, 1.0f32, &out, &len), dev).unwrap();
    assert_eq!(host(&out), [Vec4::new(1.0, 2.0, 3.0, 0.0)]);
    // length of (1, 2, 3) is sqrt(14), correctly rounded on both backends.
    assert_eq!(host(&len), [14f32.sqrt() + 14.0 + 4.0]);
    // DVec3 (f64): a general direction; compared with the same formula in f64.
    let xs = [DVec3::new(0.3, -1.2, 2.5), DVec3::new(1.0, 1.0, 1.0)];
    let d = DVec3::new(1.0, 2.0, -0.5);
    let x = arr(&xs, dev);
    let out = zeros::<DVec3, 1>(2, dev);
    let len = zeros::<f64, 1>(2, dev);
    wp::launch(reject, 2, (&x, d, 0.5f64, &out, &len), dev).unwrap();
    let n = d.normalize();
    for (k, xv) in xs.iter().enumerate() {
        let want = (*xv - n * xv.dot(n)) * 0.5;
        // A normalisation, a dot product and a few products of unit-size values: 16 ulp of
        // the vector's size covers the rounding and CUDA's FMA contraction.
        let got = host(&out)[k];
        assert!(
            (got - want).length() <= 16.0 * f64::EPSILON * xv.length(),
            "reject<DVec3>: {got} vs {want}"
        );
        let want_len = want.length() + want.length_squared() + 3.0;
        assert_close_f64(host(&len)[k], want_len, 1e-14, "reject<DVec3> length");
    }
}

/// A vector-generic loss for gradients: sum of squared distances to a point, scaled.
#[wp::kernel]
fn spring_energy<V: Vector>(x: Array<V>, anchor: V, k: V::Scalar, e: Array<V::Scalar>) {
    let i = tid();
    let r = x[i] - anchor;
    atomic_add(e, 0, k * r.dot(r) * r.length());
}

fn vector_kernel_gradients(dev: &wp::Device) {
    let x = arr(
        &[DVec3::new(0.3, -1.2, 2.5), DVec3::new(1.0, 0.5, -0.25)],
        dev,
    )
    .with_grad()
    .unwrap();
    let e = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    let anchor = DVec3::new(0.1, 0.2, 0.3);
    // f64 central differences (the f64 defaults: step 1e-6, atol 1e-8, rtol 1e-6) of a cubic
    // in inputs of order 1 whose distances stay away from 0 (where |r| is not smooth).
    let flat = x.reinterpret::<f64>().unwrap();
    let report = wp::gradcheck(
        || wp::launch(spring_energy, 2, (&x, anchor, 1.5f64, &e), dev),
        &[&flat],
        &[&e],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "spring_energy<DVec3>: {:?}", report.worst);
    // The Vec2 (f32) instance's gradient by hand: d/dx k |r|^3 = 3 k |r| r. r = (3, 4):
    // |r| = 5, so the gradient is 3 * 2 * 5 * (3, 4) = (90, 120), exact in f32.
    let x = arr(&[Vec2::new(3.0, 4.0)], dev).with_grad().unwrap();
    let e = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(spring_energy, 1, (&x, Vec2::ZERO, 2.0f32, &e), dev).unwrap();
    }
    tape.backward(&e).unwrap();
    assert_eq!(host(&e), [250.0]);
    assert_eq!(host(&x.grad().unwrap()), [Vec2::new(90.0, 120.0)]);
}

/// A struct for `T: Element` instances.
#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Probe {
    pos: DVec3,
    weight: f64,
}

/// `T: Element` ranges over any array element type, so its instances are listed: a gather
/// that only moves values, through a generic func.
#[wp::kernel(instances(T = [i32, f64, DVec3, Probe]))]
fn gather<T: Element>(src: Array<T>, idx: Array<i32>, dst: Array<T>) {
    let i = tid();
    let j = idx[i];
    // A negative index keeps the destination (src is read at 0 then, not out of bounds).
    dst[i] = pick::<T>(src[j.max(0)], dst[i], j >= 0);
}

/// Selects one of two values of any listed type.
#[wp::func(instances(T = [i32, f64, DVec3, Probe]))]
fn pick<T: Element>(a: T, b: T, first: bool) -> T {
    let mut out: T = b;
    if first {
        out = a;
    }
    out
}

fn element_type_parameters(dev: &wp::Device) {
    let names: Vec<&str> = wp::aot::instances(gather).iter().map(|i| i.name).collect();
    assert_eq!(
        names,
        [
            "gather<i32>",
            "gather<f64>",
            "gather<DVec3>",
            "gather<Probe>"
        ]
    );
    let idx = arr(&[2i32, 0, 1, 2], dev);
    let src = arr(&[10i32, 20, 30], dev);
    let dst = zeros::<i32, 1>(4, dev);
    wp::launch(gather, 4, (&src, &idx, &dst), dev).unwrap();
    assert_eq!(host(&dst), [30, 10, 20, 30]);
    let src = arr(&[DVec3::X, DVec3::Y, DVec3::Z], dev);
    let dst = zeros::<DVec3, 1>(4, dev);
    wp::launch(gather, 4, (&src, &idx, &dst), dev).unwrap();
    assert_eq!(host(&dst), [DVec3::Z, DVec3::X, DVec3::Y, DVec3::Z]);
    let probes: Vec<Probe> = (0..3)
        .map(|k| Probe {
            pos: DVec3::splat(k as f64),
            weight: 0.5 * k as f64,
        })
        .collect();
    let src = arr(&probes, dev);
    let dst = zeros::<Probe, 1>(4, dev);
    // A negative index keeps the destination: the func's `else` value.
    let idx = arr(&[2i32, -1, 1, 0], dev);
    wp::launch(gather, 4, (&src, &idx, &dst), dev).unwrap();
    let zero = Probe {
        pos: DVec3::ZERO,
        weight: 0.0,
    };
    assert_eq!(host(&dst), [probes[2], zero, probes[1], probes[0]]);
}

fn element_kernel_gradients(dev: &wp::Device) {
    // The gather's adjoint scatters dst's gradient into src's: src[j] gets the sum of the
    // seeds of the threads that read it. Exact (sums of small integers).
    let idx = arr(&[2i32, 0, 2, -1], dev);
    let src = arr(&[1.0f64, 2.0, 3.0], dev).with_grad().unwrap();
    let dst = zeros::<f64, 1>(4, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(gather, 4, (&src, &idx, &dst), dev).unwrap();
    }
    dst.grad()
        .unwrap()
        .copy_from(&arr(&[1.0f64, 10.0, 100.0, 1000.0], dev))
        .unwrap();
    tape.backward_from_grads().unwrap();
    assert_eq!(host(&src.grad().unwrap()), [10.0, 0.0, 101.0]);
    // The struct instance: the same scatter, field by field.
    let probes = [Probe {
        pos: DVec3::new(1.0, 2.0, 3.0),
        weight: 4.0,
    }; 2];
    let src = arr(&probes, dev).with_grad().unwrap();
    let dst = zeros::<Probe, 1>(2, dev).with_grad().unwrap();
    let idx = arr(&[1i32, 1], dev);
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(gather, 2, (&src, &idx, &dst), dev).unwrap();
    }
    let seed = Probe {
        pos: DVec3::new(0.5, 1.0, 2.0),
        weight: 8.0,
    };
    dst.grad().unwrap().fill(seed).unwrap();
    tape.backward_from_grads().unwrap();
    let g = host(&src.grad().unwrap());
    assert_eq!(g[0].weight, 0.0);
    assert_eq!(g[1].pos, DVec3::new(1.0, 2.0, 4.0));
    assert_eq!(g[1].weight, 16.0);
}

wp::overloads!(
    /// One name, a body per first-argument type (Warp's `@wp.func` overloads).
    combine
);

/// Integers: the difference.
#[wp::func(overload)]
fn combine(a: i32, b: i32) -> i32 {
    a - b
}

/// Float vectors: the midpoint (one generic overload gives one instance per vector type).
#[wp::func(overload)]
fn combine<V: Vector>(a: V, b: V) -> V {
    (a + b) * 0.5
}

/// Structs: the first position, the weights summed.
#[wp::func(overload)]
fn combine(a: Probe, b: Probe) -> Probe {
    Probe {
        pos: a.pos,
        weight: a.weight + b.weight,
    }
}

/// A generic kernel whose instances each call their own overload.
#[wp::kernel(instances(T = [i32, Vec2, DVec3, Probe]))]
fn combine_all<T: Element>(a: Array<T>, b: Array<T>, out: Array<T>) {
    let i = tid();
    out[i] = combine::<T>(a[i], b[i]);
}

/// A plain kernel names the overload by the argument type.
#[wp::kernel]
fn combine_ints(out: Array<i32>) {
    out[0] = combine::<i32>(7, 10) + combine::<i32>(out[1], 1);
}

fn overloads_by_first_argument(dev: &wp::Device) {
    let out = zeros::<i32, 1>(2, dev);
    wp::launch(
        combine_all,
        2,
        (&arr(&[5i32, -1], dev), &arr(&[2i32, 4], dev), &out),
        dev,
    )
    .unwrap();
    assert_eq!(host(&out), [3, -5]);
    let out = zeros::<Vec2, 1>(1, dev);
    let a = arr(&[Vec2::new(1.0, 3.0)], dev);
    let b = arr(&[Vec2::new(2.0, -1.0)], dev);
    wp::launch(combine_all, 1, (&a, &b, &out), dev).unwrap();
    // Dyadic values: exact.
    assert_eq!(host(&out), [Vec2::new(1.5, 1.0)]);
    let p = Probe {
        pos: DVec3::new(1.0, 2.0, 3.0),
        weight: 0.25,
    };
    let q = Probe {
        pos: DVec3::ZERO,
        weight: 0.5,
    };
    let out = zeros::<Probe, 1>(1, dev);
    wp::launch(
        combine_all,
        1,
        (&arr(&[p], dev), &arr(&[q], dev), &out),
        dev,
    )
    .unwrap();
    assert_eq!(
        host(&out),
        [Probe {
            pos: p.pos,
            weight: 0.75
        }]
    );
    let out = arr(&[0i32, 9], dev);
    wp::launch(combine_ints, 1, (&out,), dev).unwrap();
    assert_eq!(host(&out)[0], (7 - 10) + (9 - 1));
    // Each overload is a func of its own in reports: named by its parameter types.
    let info = wp::aot::instances(combine_all);
    let callees: Vec<&str> = info.iter().map(|i| i.callees[0].name).collect();
    assert_eq!(
        callees,
        [
            "combine(i32, i32)",
            "combine(Vec2, Vec2)",
            "combine(DVec3, DVec3)",
            "combine(Probe, Probe)"
        ]
    );
}

fn overload_gradients(dev: &wp::Device) {
    // d out / d a = d out / d b = 0.5 through the vector overload: exact.
    let a = arr(&[DVec3::new(1.0, 2.0, 3.0)], dev).with_grad().unwrap();
    let b = arr(&[DVec3::new(-1.0, 0.5, 8.0)], dev).with_grad().unwrap();
    let out = zeros::<DVec3, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(combine_all, 1, (&a, &b, &out), dev).unwrap();
    }
    out.grad()
        .unwrap()
        .fill(DVec3::new(2.0, 4.0, -8.0))
        .unwrap();
    tape.backward_from_grads().unwrap();
    assert_eq!(host(&a.grad().unwrap()), [DVec3::new(1.0, 2.0, -4.0)]);
    assert_eq!(host(&b.grad().unwrap()), [DVec3::new(1.0, 2.0, -4.0)]);
    // Through the struct overload: the weight's gradient reaches both, the position's only a.
    let p = Probe {
        pos: DVec3::ONE,
        weight: 1.0,
    };
    let a = arr(&[p], dev).with_grad().unwrap();
    let b = arr(&[p], dev).with_grad().unwrap();
    let out = zeros::<Probe, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(combine_all, 1, (&a, &b, &out), dev).unwrap();
    }
    out.grad()
        .unwrap()
        .fill(Probe {
            pos: DVec3::splat(3.0),
            weight: 5.0,
        })
        .unwrap();
    tape.backward_from_grads().unwrap();
    let (ga, gb) = (host(&a.grad().unwrap())[0], host(&b.grad().unwrap())[0]);
    assert_eq!((ga.pos, ga.weight), (DVec3::splat(3.0), 5.0));
    assert_eq!((gb.pos, gb.weight), (DVec3::ZERO, 5.0));
}

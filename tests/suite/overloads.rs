//! Overloads and generic funcs called as Warp users call them: `mix(a, b)` runs the overload
//! whose parameter types the arguments have (all of them, so that two overloads may share a
//! first parameter type), `norm2(v)` the generic func's instance; `wp::grad(mix)(..)` of an
//! overload; and custom gradients (`#[func(grad(..))]`) on generic funcs and on overloads,
//! checked against central differences.

use crate::{arr, assert_close_f32, assert_close_f64, fma_rel, fma_rel64, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    overloads_by_every_argument,
    generic_funcs_by_arguments,
    grad_of_an_overload,
    generic_custom_gradient,
    overload_custom_gradient,
    straight_through_overload,
);

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Pair {
    a: f32,
    b: f32,
}

wp::overloads!(
    /// Warp-style overloads: one name, told apart by all their parameter types.
    mix
);

#[wp::func(overload)]
fn mix(x: f32, y: f32) -> f32 {
    x * y
}

/// The same first parameter type as the overload above: the second tells them apart.
#[wp::func(overload)]
fn mix(x: f32, n: i32) -> f32 {
    x + n as f32
}

/// One overload per float vector type (a generic overload).
#[wp::func(overload)]
fn mix<V: Vector>(v: V, s: V::Scalar) -> V {
    v * s
}

#[wp::func(overload)]
fn mix(p: Pair, y: f32) -> f32 {
    p.a * y + p.b
}

#[wp::func]
fn twice(x: f32) -> f32 {
    x + x
}

#[wp::kernel]
fn mix_all(
    x: Array<f32>,
    n: Array<i32>,
    p: Array<Pair>,
    v: Array<Vec3>,
    d: Array<DVec2>,
    out: Array<f32>,
    vout: Array<Vec3>,
    dout: Array<DVec2>,
) {
    let i = tid();
    let xi = x[i];
    // (f32, f32), (f32, i32), (Pair, f32) from an array's element type, a func's result, and
    // a struct field (whose type the macro cannot see: the second argument decides).
    out[i] = mix(xi, 2.0f32) + mix(xi, n[i]) + mix(p[i], xi) + mix(twice(xi), n[i]);
    out[i] += mix(p[i].b, n[i]) + mix::<f32>(xi, 4.0f32);
    vout[i] = mix(v[i], xi);
    // An unsuffixed literal: the one overload taking a `DVec2` first decides its type.
    dout[i] = mix(d[i], 0.5);
}

fn overloads_by_every_argument(dev: &wp::Device) {
    let xs = [1.5f32, -2.0, 0.25];
    let ns = [3i32, -1, 8];
    let ps = [
        Pair { a: 2.0, b: 0.5 },
        Pair { a: -1.0, b: 4.0 },
        Pair { a: 0.5, b: -3.0 },
    ];
    let vs = [Vec3::new(1.0, 2.0, 3.0), Vec3::X, Vec3::new(-4.0, 0.5, 8.0)];
    let ds = [DVec2::new(1.0, 2.0), DVec2::Y, DVec2::new(-6.0, 0.125)];
    let out = zeros::<f32, 1>(3, dev);
    let vout = zeros::<Vec3, 1>(3, dev);
    let dout = zeros::<DVec2, 1>(3, dev);
    let args = (
        &arr(&xs, dev),
        &arr(&ns, dev),
        &arr(&ps, dev),
        &arr(&vs, dev),
        &arr(&ds, dev),
        &out,
        &vout,
        &dout,
    );
    wp::launch(mix_all, 3, args, dev).unwrap();
    for k in 0..3 {
        let (x, n, p) = (xs[k], ns[k], ps[k]);
        let n32 = n as f32;
        let first = x * 2.0 + (x + n32) + (p.a * x + p.b) + ((x + x) + n32);
        let want = first + ((p.b + n32) + x * 4.0);
        // Small dyadic values: every product and sum is exact in f32 (no FMA can change it).
        assert_close_f32(host(&out)[k], want, fma_rel(dev), "mix sum");
        assert_eq!(host(&vout)[k], vs[k] * x);
        assert_eq!(host(&dout)[k], ds[k] * 0.5);
    }
    // Each overload is a func of its own, named by its parameter types as Warp prints it.
    let callees: Vec<&str> = wp::kernel_info(mix_all)
        .callees
        .iter()
        .map(|c| c.name)
        .collect();
    for name in [
        "mix(f32, f32)",
        "mix(f32, i32)",
        "mix(Pair, f32)",
        "mix(Vec3, f32)",
        "mix(DVec2, f64)",
    ] {
        assert!(callees.contains(&name), "{name} in {callees:?}");
    }
}

/// A generic func called without naming its instance: the argument's type picks it.
#[wp::func]
fn norm2<T: Float>(v: Vec3<T>) -> T {
    v.dot(v)
}

/// Its type parameter is in no parameter: the arguments cannot pick an instance, so callers
/// name it (`zero::<T>()`).
#[wp::func]
fn zero<T: Float>() -> T {
    0.0
}

#[wp::kernel]
fn norms<T: Float>(v: Array<Vec3<T>>, out: Array<T>) {
    let i = tid();
    out[i] = norm2(v[i]) + zero::<T>() + norm2(Vec3::<T>::splat(1.0));
}

#[wp::kernel]
fn norms_f64(v: Array<DVec3>, out: Array<f64>) {
    let i = tid();
    out[i] = norm2(v[i]) * 2.0;
}

fn generic_funcs_by_arguments(dev: &wp::Device) {
    let v64 = [DVec3::new(1.0, 2.0, 2.0), DVec3::new(0.5, -3.0, 4.0)];
    let v32: Vec<Vec3> = v64.iter().map(|v| v.as_vec3()).collect();
    let (o32, o64) = (zeros::<f32, 1>(2, dev), zeros::<f64, 1>(2, dev));
    wp::launch(norms, 2, (&arr(&v32, dev), &o32), dev).unwrap();
    wp::launch(norms, 2, (&arr(&v64, dev), &o64), dev).unwrap();
    let o = zeros::<f64, 1>(2, dev);
    wp::launch(norms_f64, 2, (&arr(&v64, dev), &o), dev).unwrap();
    for k in 0..2 {
        // Exact inputs, exact sums of squares: no tolerance.
        assert_eq!(host(&o32)[k], v32[k].dot(v32[k]) + 3.0);
        assert_eq!(host(&o64)[k], v64[k].dot(v64[k]) + 3.0);
        assert_eq!(host(&o)[k], v64[k].dot(v64[k]) * 2.0);
    }
    let callees: Vec<&str> = wp::kernel_info(norms_f64)
        .callees
        .iter()
        .map(|c| c.name)
        .collect();
    assert_eq!(callees, ["norm2<f64>"]);
}

/// `wp::grad` of an overload: the arguments pick the overload, as Warp's `wp.grad(f)(args)`.
#[wp::kernel]
fn mix_grads(x: Array<f32>, v: Array<Vec3>, gx: Array<f32>, gv: Array<Vec3>) {
    let i = tid();
    let g = wp::grad(mix)(x[i], 3.0f32);
    gx[i] = g.0 * 10.0 + g.1;
    let h = wp::grad(mix)(v[i], x[i]);
    gv[i] = h.0 + Vec3::splat(h.1);
}

fn grad_of_an_overload(dev: &wp::Device) {
    let xs = [1.5f32, -2.0];
    let vs = [Vec3::new(1.0, 2.0, 3.0), Vec3::new(-4.0, 0.5, 8.0)];
    let (gx, gv) = (zeros::<f32, 1>(2, dev), zeros::<Vec3, 1>(2, dev));
    wp::launch(
        mix_grads,
        2,
        (&arr(&xs, dev), &arr(&vs, dev), &gx, &gv),
        dev,
    )
    .unwrap();
    for k in 0..2 {
        // d(x y)/dx = y = 3, d(x y)/dy = x; d(v s)/dv = s per lane (a one seed in every lane),
        // d(v s)/ds = the lanes' sum. Small dyadic values: exact.
        assert_eq!(host(&gx)[k], 30.0 + xs[k]);
        let sum = vs[k].x + vs[k].y + vs[k].z;
        assert_eq!(host(&gv)[k], Vec3::splat(xs[k] + sum));
    }
}

/// x³ with its derivative written out (Warp's `@wp.func_grad`), for each instance: the
/// gradient func is generic too and needs no turbofish (each instance calls its own).
#[wp::func(grad(x = dcube))]
fn cube<T: Float>(x: T) -> T {
    x * x * x
}

#[wp::func]
fn dcube<T: Float>(x: T, adj: T) -> T {
    3.0 * x * x * adj
}

#[wp::kernel]
fn cubes<T: Float>(x: Array<T>, y: Array<T>) {
    let i = tid();
    y[i] = cube(x[i] * 2.0) - x[i];
}

/// The derivative of `sum(f(x))` by central differences of step `h`, `f` a launch.
fn central_differences(x: &[f64], h: f64, f: &dyn Fn(&[f64]) -> f64) -> Vec<f64> {
    (0..x.len())
        .map(|k| {
            let (mut lo, mut hi) = (x.to_vec(), x.to_vec());
            lo[k] -= h;
            hi[k] += h;
            (f(&hi) - f(&lo)) / (2.0 * h)
        })
        .collect()
}

fn generic_custom_gradient(dev: &wp::Device) {
    let xv = [0.75f64, -1.25, 2.0];
    let x = arr(&xv, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(cubes, 3, (&x, &y), dev).unwrap();
    }
    tape.backward(&y).unwrap();
    let got = host(&x.grad().unwrap());
    let sum = |xs: &[f64]| {
        let y = zeros::<f64, 1>(xs.len(), dev);
        wp::launch(cubes, xs.len(), (&arr(xs, dev), &y), dev).unwrap();
        host(&y).iter().sum::<f64>()
    };
    let want = central_differences(&xv, 1e-5, &sum);
    for k in 0..3 {
        // The custom gradient is exact, 24 x² - 1; central differences of a cubic are off by
        // h² f'''/6 = 8e-10 plus rounding (1e-16 |y| / h, about 1e-10): 1e-8 relative.
        assert_close_f64(
            got[k],
            want[k],
            1e-8,
            "d cube / dx against central differences",
        );
        assert_close_f64(
            got[k],
            24.0 * xv[k] * xv[k] - 1.0,
            fma_rel64(dev),
            "d cube / dx",
        );
    }
    // The f32 instance runs its own gradient func (`dcube<f32>`).
    let x = arr(&[0.5f32], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(cubes, 1, (&x, &y), dev).unwrap();
    }
    tape.backward(&y).unwrap();
    assert_eq!(host(&x.grad().unwrap()), [5.0]);
}

wp::overloads!(energy);

/// Spring energies, one overload per argument type, each with its gradient written out.
#[wp::func(overload, grad(x = denergy))]
fn energy(x: f64, k: f64) -> f64 {
    0.5 * k * x * x
}

#[wp::func(overload, grad(x = denergy))]
fn energy(x: DVec3, k: f64) -> f64 {
    0.5 * k * x.dot(x)
}

wp::overloads!(denergy);

#[wp::func(overload)]
fn denergy(x: f64, k: f64, adj: f64) -> f64 {
    k * x * adj
}

#[wp::func(overload)]
fn denergy(x: DVec3, k: f64, adj: f64) -> DVec3 {
    x * (k * adj)
}

#[wp::kernel]
fn energies(x: Array<f64>, v: Array<DVec3>, k: f64, e: Array<f64>) {
    let i = tid();
    e[i] = energy(x[i], k) * energy(v[i], k);
}

fn overload_custom_gradient(dev: &wp::Device) {
    let xv = [0.5f64, -1.5];
    let vv = [DVec3::new(1.0, -2.0, 0.25), DVec3::new(0.75, 0.5, -3.0)];
    let k = 3.0;
    let x = arr(&xv, dev).with_grad().unwrap();
    let v = arr(&vv, dev).with_grad().unwrap();
    let e = zeros::<f64, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(energies, 2, (&x, &v, k, &e), dev).unwrap();
    }
    tape.backward(&e).unwrap();
    let (gx, gv) = (host(&x.grad().unwrap()), host(&v.grad().unwrap()));
    // All inputs in one vector: x0, x1, then v0's and v1's lanes.
    let flat: Vec<f64> = xv
        .iter()
        .copied()
        .chain(vv.iter().flat_map(|v| v.to_array()))
        .collect();
    let sum = |f: &[f64]| {
        let vs: Vec<DVec3> = f[2..].chunks(3).map(DVec3::from_slice).collect();
        let e = zeros::<f64, 1>(2, dev);
        let args = (&arr(&f[..2], dev), &arr(&vs, dev), k, &e);
        wp::launch(energies, 2, args, dev).unwrap();
        host(&e).iter().sum::<f64>()
    };
    let want = central_differences(&flat, 1e-5, &sum);
    let got: Vec<f64> = gx
        .iter()
        .copied()
        .chain(gv.iter().flat_map(|v| v.to_array()))
        .collect();
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        // A product of quadratics (degree 4): central differences are off by h² f'''/6, under
        // 1e-8 here, plus rounding (1e-16 |e| / h, about 1e-10): 1e-7 relative.
        assert_close_f64(
            *g,
            *w,
            1e-7,
            &format!("input {k} against central differences"),
        );
    }
}

wp::overloads!(quantize);

/// Rounds towards zero to a multiple of `step`. Its own adjoint is zero almost everywhere
/// (the integer cast); the custom gradient passes the adjoint straight through (the
/// straight-through estimator), which shows that the custom gradient, not the body's, runs.
#[wp::func(overload, grad(x = through))]
fn quantize(x: f32, step: f32) -> f32 {
    ((x / step) as i32) as f32 * step
}

#[wp::func(overload, grad(x = through))]
fn quantize(x: Vec2, step: f32) -> Vec2 {
    vec2(quantize(x.x, step), quantize(x.y, step))
}

wp::overloads!(through);

#[wp::func(overload)]
fn through(x: f32, step: f32, adj: f32) -> f32 {
    adj
}

#[wp::func(overload)]
fn through(x: Vec2, step: f32, adj: Vec2) -> Vec2 {
    adj
}

#[wp::kernel]
fn quantize_all(x: Array<f32>, v: Array<Vec2>, out: Array<f32>) {
    let i = tid();
    let q = quantize(v[i], 0.5);
    out[i] = quantize(x[i], 0.25) * 3.0 + q.x + q.y * 2.0;
}

fn straight_through_overload(dev: &wp::Device) {
    let x = arr(&[0.7f32, -1.3], dev).with_grad().unwrap();
    let v = arr(&[Vec2::new(0.9, 1.6), Vec2::new(-0.2, 2.4)], dev)
        .with_grad()
        .unwrap();
    let out = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(quantize_all, 2, (&x, &v, &out), dev).unwrap();
    }
    // Values: 0.5 * 3 + 0.5 + 1.5 * 2 and -1.25 * 3 + 0 + 2 * 2 (dyadic: exact).
    assert_eq!(host(&out), [5.0, 0.25]);
    tape.backward(&out).unwrap();
    assert_eq!(host(&x.grad().unwrap()), [3.0, 3.0]);
    assert_eq!(host(&v.grad().unwrap()), [Vec2::new(1.0, 2.0); 2]);
}

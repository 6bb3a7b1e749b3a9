//! Tuples and `&mut` parameters: funcs returning tuples, destructured (`_`, nested patterns,
//! annotations) or read by element (`f(x).0`), tuple locals and literals, tuple parameters;
//! funcs with `&mut` parameters (Warp's `wp.ref` out-parameters) called on a local, a struct
//! field, a vector lane, a local array's element, an array element, and passed on by funcs;
//! destructuring assignment (`(a, b) = (b, a)`); and their gradients in both modes where the modes reach (reverse through funcs, forward
//! through tuples in a kernel).

use crate::{arr, assert_close_slice, fma_rel, host, math_rel, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    funcs_return_tuples,
    tuple_locals_and_literals,
    mut_params_write_back,
    mut_params_gradcheck,
    mut_param_overwrite_has_no_gradient,
    tuples_forward_mode,
    destructuring_assignment,
    destructuring_assignment_gradients,
);

#[wp::func]
fn polar(v: Vec2) -> (f32, f32) {
    (v.length(), v.y.atan2(v.x))
}

#[wp::func]
fn split(x: f32) -> (f32, Vec3) {
    let s = x * 2.0;
    (s, vec3(x, s, x * x))
}

#[wp::func]
fn nested(x: f32) -> ((f32, f32), f32) {
    let (r, t) = polar(vec2(x, 1.0));
    ((r, t), x + 1.0)
}

/// A tuple parameter, read by element.
#[wp::func]
fn pair_sum(p: (f32, Vec3)) -> f32 {
    p.0 + p.1.z
}

#[wp::kernel]
fn k_tuples(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let (r, theta) = polar(vec2(x[i], 2.0));
    let (_, w) = split(x[i]);
    let ((a, _), c) = nested(x[i]);
    let (s, v): (f32, Vec3) = split(x[i] + 1.0);
    out[(i, 0)] = r;
    out[(i, 1)] = theta;
    out[(i, 2)] = w.y + w.z;
    out[(i, 3)] = a + c;
    out[(i, 4)] = s + v.x;
    out[(i, 5)] = polar(vec2(1.0, x[i])).0 + split(x[i]).1.z;
    out[(i, 6)] = pair_sum(split(x[i]));
}

fn funcs_return_tuples(dev: &wp::Device) {
    let xs = [0.5f32, -1.25, 3.0];
    let x = arr(&xs, dev);
    let out = zeros::<f32, 2>((3, 7), dev);
    wp::launch(k_tuples, 3, (&x, &out), dev).unwrap();
    let want: Vec<f32> = xs
        .iter()
        .flat_map(|&x| {
            let p = Vec2::new(x, 2.0);
            let q = Vec2::new(x, 1.0);
            let y = x + 1.0;
            [
                p.length(),
                p.y.atan2(p.x),
                x * 2.0 + x * x,
                q.length() + (x + 1.0),
                y * 2.0 + y,
                Vec2::new(1.0, x).length() + x * x,
                x * 2.0 + x * x,
            ]
        })
        .collect();
    // atan2 and the square root: CUDA's math library.
    assert_close_slice(&host(&out), &want, math_rel(dev), "tuple results");
}

#[wp::kernel]
fn k_tuple_locals(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let mut t = (x[i], vec3(1.0, 2.0, 3.0));
    t.0 += 1.0;
    t.1.y = x[i] * 3.0;
    let u = if x[i] > 0.0 { (t.0, 1) } else { (-t.0, 2) };
    let (p, q) = (u.0 * 2.0, u.1);
    let (m, k) = (x[i], 7);
    out[(i, 0)] = t.0;
    out[(i, 1)] = t.1.y + t.1.z;
    out[(i, 2)] = p + q as f32;
    out[(i, 3)] = m + k as f32;
}

fn tuple_locals_and_literals(dev: &wp::Device) {
    let xs = [0.5f32, -1.25];
    let out = zeros::<f32, 2>((2, 4), dev);
    wp::launch(k_tuple_locals, 2, (&arr(&xs, dev), &out), dev).unwrap();
    let want: Vec<f32> = xs
        .iter()
        .flat_map(|&x| {
            let t0 = x + 1.0;
            let (u0, u1) = if x > 0.0 { (t0, 1) } else { (-t0, 2) };
            [t0, x * 3.0 + 3.0, u0 * 2.0 + u1 as f32, x + 7.0]
        })
        .collect();
    assert_close_slice(&host(&out), &want, 0.0, "tuple locals");
}

#[wp::func]
fn accumulate(acc: &mut f32, x: f32) {
    *acc += x;
}

/// Two `&mut` parameters, and a result.
#[wp::func]
fn swap_sum(a: &mut f32, b: &mut f32) -> f32 {
    let t = *a;
    *a = *b;
    *b = t;
    *a + *b
}

/// A `&mut` parameter passed on to other funcs (bare and reborrowed), read through Rust's
/// auto-dereference (`v.x`, `v.length()`), and an early return.
#[wp::func]
fn push_out(v: &mut Vec3, d: f32) -> bool {
    if d < 0.0 {
        return false;
    }
    accumulate(&mut v.x, d);
    let mut s = v.y;
    accumulate(&mut s, v.length());
    v.y = s;
    let mut w = *v;
    accumulate(&mut w.z, 1.0);
    *v = w;
    true
}

#[wp::func]
fn bump(v: &mut Vec3, d: f32) {
    let _ = push_out(v, d);
}

#[wp::kernel]
fn k_mut_params(x: Array<f32>, acc: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let mut a = 0.0f32;
    accumulate(&mut a, x[i]);
    accumulate(&mut a, 2.0);
    let mut v = vec3(x[i], 1.0, 0.0);
    accumulate(&mut v.y, x[i]);
    let mut arr = [1.0f32, 2.0, 3.0];
    accumulate(&mut arr[1], x[i]);
    accumulate(&mut acc[i], x[i]);
    let mut p = x[i];
    let mut q = 10.0f32;
    let s = swap_sum(&mut p, &mut q);
    let mut w = vec3(1.0, 0.0, 0.0);
    let moved = push_out(&mut w, x[i]);
    bump(&mut w, 1.0);
    out[(i, 0)] = a;
    out[(i, 1)] = v.y;
    out[(i, 2)] = arr[1] + arr[2];
    out[(i, 3)] = p - q + s;
    out[(i, 4)] = w.x + w.y + w.z;
    out[(i, 5)] = if moved { 1.0 } else { 0.0 };
}

fn mut_params_write_back(dev: &wp::Device) {
    let xs = [0.5f32, -1.25, 3.0];
    let acc = arr(&[10.0f32, 20.0, 30.0], dev);
    let out = zeros::<f32, 2>((3, 6), dev);
    wp::launch(k_mut_params, 3, (&arr(&xs, dev), &acc, &out), dev).unwrap();
    let push = |v: &mut Vec3, d: f32| {
        if d < 0.0 {
            return false;
        }
        v.x += d;
        v.y += v.length();
        v.z += 1.0;
        true
    };
    let want: Vec<f32> = xs
        .iter()
        .flat_map(|&x| {
            let mut w = Vec3::new(1.0, 0.0, 0.0);
            let moved = push(&mut w, x);
            push(&mut w, 1.0);
            [
                x + 2.0,
                1.0 + x,
                2.0 + x + 3.0,
                10.0 - x + (10.0 + x),
                w.x + w.y + w.z,
                if moved { 1.0 } else { 0.0 },
            ]
        })
        .collect();
    // The vector's length: a square root of a sum of products (FMA on CUDA).
    assert_close_slice(&host(&out), &want, fma_rel(dev), "&mut parameters");
    let want_acc: Vec<f32> = [10.0f32, 20.0, 30.0]
        .iter()
        .zip(&xs)
        .map(|(a, x)| a + x)
        .collect();
    assert_eq!(host(&acc), want_acc, "an array element lent as `&mut`");
}

/// `acc = acc * x + x^2`: reads and overwrites the caller's variable.
#[wp::func]
fn scale_add(acc: &mut f64, x: f64) {
    *acc = *acc * x + x * x;
}

/// A tuple result and a `&mut` parameter at once.
#[wp::func]
fn sincos_into(r: &mut f64, x: f64) -> (f64, f64) {
    *r *= x.sin();
    (x.sin() * *r, x.cos())
}

#[wp::kernel]
pub(crate) fn k_refs_grad(x: Array<f64>, out: Array<f64>) {
    let mut a = x[0];
    scale_add(&mut a, x[1]);
    // In a loop: the caller's variable is overwritten every iteration.
    for k in 0..3 {
        scale_add(&mut a, x[k] * 0.5);
    }
    out[0] = a;
    let mut v = DVec3::new(x[0], x[1], x[2]);
    scale_add(&mut v.y, x[2]);
    let mut l = [x[1], x[2]];
    scale_add(&mut l[1], x[0]);
    out[1] = v.x * v.y + l[0] * l[1];
    let mut r = x[2];
    let (s, c) = sincos_into(&mut r, x[0]);
    out[2] = s * c + r;
    let (p, (q, _)) = (x[1] * s, (c * x[2], 1));
    out[3] = p + q;
}

/// Reverse mode through tuple results and `&mut` parameters (a value read and overwritten by
/// the func, in a loop, in a lane, in a local array element), by `wp::gradcheck` against
/// central differences in f64. The default f64 step (1e-6 relative) leaves a truncation error
/// of order 1e-12 and rounding of order 1e-10 relative for these smooth functions; 1e-6 is a
/// bound no wrong adjoint (a lost or doubled term is O(1)) passes.
fn mut_params_gradcheck(dev: &wp::Device) {
    let x = arr(&[0.7f64, -0.4, 1.3], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(4, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_refs_grad, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    assert!(report.max_rel_error < 1e-6, "{report:?}");
}

#[wp::func]
fn set_sq(out: &mut f64, x: f64) {
    *out = x * x;
}

#[wp::kernel]
fn k_overwrite(x: Array<f64>, out: Array<f64>) {
    let mut a = x[0] * 3.0;
    set_sq(&mut a, x[1]);
    out[0] = a + x[0];
}

/// A func that overwrites its `&mut` parameter without reading it: the caller's old value
/// gets no gradient (only `out[0]`'s own `+ x[0]`), the new one `2 x[1]`. Exact: the adjoint
/// computes `1` and `2 * x[1]` without rounding.
fn mut_param_overwrite_has_no_gradient(dev: &wp::Device) {
    let x = arr(&[0.5f64, 1.5], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _r = tape.record();
        wp::launch(k_overwrite, 1, (&x, &out), dev).unwrap();
    }
    assert_eq!(host(&out), [1.5 * 1.5 + 0.5]);
    out.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    assert_eq!(host(&x.grad().unwrap()), [1.0, 3.0]);
}

#[wp::kernel]
fn k_tuple_jvp(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    let t = (x[i] * x[i], 3);
    let (a, b) = (t.0 * 2.0, x[i]);
    out[i] = a + b * t.1 as f32;
}

/// Forward mode through tuple literals, locals and destructuring (funcs are not yet in
/// forward mode): d/dx (2 x^2 + 3 x) = 4 x + 3, exact in f32 at these binary fractions.
fn tuples_forward_mode(dev: &wp::Device) {
    let x = arr(&[0.5f32, -2.0], dev);
    let out = zeros::<f32, 1>(2, dev);
    let dx = arr(&[1.0f32, 1.0], dev);
    let dout = zeros::<f32, 1>(2, dev);
    wp::jvp(k_tuple_jvp, 2, (&x, &out), (&dx, &dout), dev).unwrap();
    assert_eq!(host(&dout), [5.0, -5.0]);
}

/// Rust's destructuring assignment: the right-hand side is read whole before any place is
/// written (so `(a, b) = (b, a)` and `(t.1, t.0) = t` swap), `_` skips an element, tuples
/// nest, and the places are locals, lanes, tuple elements, array elements and `&mut`
/// parameters.
#[wp::func]
fn rotate3(x: &mut f32, y: &mut f32, z: &mut f32) {
    (*x, *y, *z) = (*y, *z, *x);
}

#[wp::kernel]
fn k_destructure(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let mut a = x[i];
    let mut b = 2.0f32;
    (a, b) = (b, a);
    let mut t = (a, b);
    (t.1, t.0) = t;
    let mut v = vec3(1.0, 2.0, 3.0);
    let mut c = 0.0f32;
    (v.z, (c, _), v.x) = (x[i], split(x[i]), 7.0);
    let (mut p, mut q, mut r) = (1.0f32, 2.0f32, 3.0f32);
    rotate3(&mut p, &mut q, &mut r);
    (out[(i, 0)], out[(i, 1)]) = (a, b);
    (out[(i, 2)], out[(i, 3)]) = t;
    out[(i, 4)] = v.x + 10.0 * v.z;
    out[(i, 5)] = c;
    (out[(i, 6)], out[(i, 7)], out[(i, 8)]) = (p, q, r);
}

fn destructuring_assignment(dev: &wp::Device) {
    let xs = [0.5f32, -3.0];
    let out = zeros::<f32, 2>((2, 9), dev);
    wp::launch(k_destructure, 2, (&arr(&xs, dev), &out), dev).unwrap();
    let want: Vec<f32> = xs
        .iter()
        .flat_map(|&x| [2.0, x, x, 2.0, 7.0 + 10.0 * x, 2.0 * x, 2.0, 3.0, 1.0])
        .collect();
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_destructure_grad(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    let mut a = x[i];
    let mut b = x[i] * x[i];
    (a, b) = (b * 3.0, a);
    y[i] = a + b * 5.0;
}

/// y = 3 x² + 5 x through a swap by destructuring: dy/dx = 6 x + 5, exact in f32 here.
fn destructuring_assignment_gradients(dev: &wp::Device) {
    let x = arr(&[1.0f32, -2.0, 0.5], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_destructure_grad, 3, (&x, &y), dev).unwrap();
    }
    assert_eq!(host(&y), vec![8.0, 2.0, 3.25]);
    tape.backward(&y).unwrap();
    assert_eq!(host(&x.grad().unwrap()), vec![11.0, -7.0, 8.0]);
    // Forward mode, the same derivative.
    let (v, y_dot) = (arr(&[1.0f32, 1.0, 1.0], dev), zeros::<f32, 1>(3, dev));
    wp::jvp(k_destructure_grad, 3, (&x, &y), (&v, &y_dot), dev).unwrap();
    assert_eq!(host(&y_dot), vec![11.0, -7.0, 8.0]);
}

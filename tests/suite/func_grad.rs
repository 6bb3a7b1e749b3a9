//! `wp::grad(f)(..)` in kernels (Warp's `wp.grad`): a func's gradient evaluated in forward
//! code, its result's adjoint seeded with one; and backward refused through a func whose
//! callee has no adjoint. (`#[func(replay = r)]`, Warp's `@wp.func_replay`, is tested by the
//! port of Warp's own test, `ports::test_grad_customs::custom_replay_grad`.)
//!
//! Tolerances: the gradients are computed in f64 by the func's adjoint, against closed forms
//! evaluated in f64 on the host. The operations are the same few roundings on both sides but
//! not always in the same order (the adjoint's sums against the closed form's), so a relative
//! `1e-14` (a few dozen ulps) where transcendental functions enter (`sin`, `sqrt`: within an
//! ulp or two on both backends), exact where the derivative is a product of exact values.

use crate::{arr, assert_close_f64, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    scalar_gradient,
    two_parameters_give_a_tuple,
    vector_result_seeds_every_lane,
    loop_through_the_stack,
    custom_gradient_is_used,
    inside_a_custom_gradient,
    constant_in_backward,
    generic_instance,
    callee_without_adjoint_refuses_backward,
);

#[wp::func]
fn square(x: f64) -> f64 {
    x * x
}

#[wp::kernel]
fn k_square_grad(xs: Array<f64>, out: Array<f64>) {
    let i = tid();
    out[i] = wp::grad(square)(xs[i]);
}

const XS: [f64; 5] = [-2.5, -1.0, 0.0, 0.75, 3.0];

fn scalar_gradient(dev: &wp::Device) {
    let xs = arr(&XS, dev);
    let out = zeros::<f64, 1>(XS.len(), dev);
    wp::launch(k_square_grad, XS.len(), (&xs, &out), dev).unwrap();
    let want: Vec<f64> = XS.iter().map(|x| 2.0 * x).collect();
    // 2x and x + x are the same exact double.
    assert_eq!(host(&out), want, "d(x^2)/dx");
}

#[wp::func]
fn mixed(a: f64, b: f64) -> f64 {
    a * b + a.sin()
}

#[wp::kernel]
fn k_mixed_grad(a: Array<f64>, b: Array<f64>, da: Array<f64>, db: Array<f64>) {
    let i = tid();
    let (ga, gb) = wp::grad(mixed)(a[i], b[i]);
    da[i] = ga;
    db[i] = gb;
}

fn two_parameters_give_a_tuple(dev: &wp::Device) {
    let bs = [0.5, -3.0, 2.0, 1.25, -0.125];
    let (a, b) = (arr(&XS, dev), arr(&bs, dev));
    let (da, db) = (zeros::<f64, 1>(5, dev), zeros::<f64, 1>(5, dev));
    wp::launch(k_mixed_grad, 5, (&a, &b, &da, &db), dev).unwrap();
    let (da, db) = (host(&da), host(&db));
    for k in 0..5 {
        let want_a = bs[k] + XS[k].cos();
        assert_close_f64(da[k], want_a, 1e-14, &format!("d/da at {k}"));
        assert_eq!(db[k], XS[k], "d/db at {k} is a, exactly");
    }
}

/// `v |v|`: its Jacobian is `|v| I + v vᵀ/|v|`, so the gradient of the sum of its lanes is
/// `|v| (1, 1, 1) + v (v · (1, 1, 1))/|v|`.
#[wp::func]
fn scaled(v: DVec3) -> DVec3 {
    v * v.length()
}

#[wp::kernel]
fn k_scaled_grad(vs: Array<DVec3>, out: Array<DVec3>) {
    let i = tid();
    out[i] = wp::grad(scaled)(vs[i]);
}

fn vector_result_seeds_every_lane(dev: &wp::Device) {
    let vs = [
        DVec3::new(1.0, 2.0, -2.0),
        DVec3::new(-0.5, 0.25, 4.0),
        DVec3::new(3.0, 0.0, 0.0),
    ];
    let (input, out) = (arr(&vs, dev), zeros::<DVec3, 1>(3, dev));
    wp::launch(k_scaled_grad, 3, (&input, &out), dev).unwrap();
    for (k, (v, g)) in vs.iter().zip(host(&out)).enumerate() {
        let n = v.length();
        let want = DVec3::splat(n) + *v * (v.x + v.y + v.z) / n;
        for j in 0..3 {
            assert_close_f64(g[j], want[j], 1e-14, &format!("lane {j} of vector {k}"));
        }
    }
}

/// `x^n` by a loop that overwrites its accumulator: the adjoint keeps each step's value on
/// its stack (the `wp::grad` call's own stack, in a kernel with no backward of its own).
#[wp::func]
fn power(x: f64, n: i32) -> f64 {
    let mut acc = 1.0f64;
    for _ in 0..n {
        acc *= x;
    }
    acc
}

#[wp::kernel]
fn k_power_grad(xs: Array<f64>, out: Array<f64>, n_grad: Array<i32>) {
    let i = tid();
    let (gx, gn) = wp::grad(power)(xs[i], 5);
    out[i] = gx;
    n_grad[i] = gn;
}

fn loop_through_the_stack(dev: &wp::Device) {
    let xs = arr(&XS, dev);
    let (out, n_grad) = (zeros::<f64, 1>(5, dev), zeros::<i32, 1>(5, dev));
    wp::launch(k_power_grad, 5, (&xs, &out, &n_grad), dev).unwrap();
    for (k, g) in host(&out).into_iter().enumerate() {
        let want = 5.0 * XS[k].powi(4);
        assert_close_f64(g, want, 1e-14, &format!("d(x^5)/dx at {}", XS[k]));
    }
    assert_eq!(host(&n_grad), vec![0; 5], "an integer's adjoint is zero");
}

/// A custom gradient (deliberately not the derivative, so that its use shows).
#[wp::func(grad(x = fake_dx))]
fn with_custom(x: f64) -> f64 {
    x * x * x
}

#[wp::func]
fn fake_dx(x: f64, adj_ret: f64) -> f64 {
    adj_ret * (x + 100.0)
}

#[wp::kernel]
fn k_custom_grad(xs: Array<f64>, out: Array<f64>) {
    let i = tid();
    out[i] = wp::grad(with_custom)(xs[i]);
}

fn custom_gradient_is_used(dev: &wp::Device) {
    let xs = arr(&XS, dev);
    let out = zeros::<f64, 1>(5, dev);
    wp::launch(k_custom_grad, 5, (&xs, &out), dev).unwrap();
    let want: Vec<f64> = XS.iter().map(|x| x + 100.0).collect();
    assert_eq!(host(&out), want, "wp::grad runs the custom gradient");
}

/// Warp's use of `wp.grad` inside a custom gradient: `tripled`'s gradient is built from
/// `inner`'s automatic one (`tripled(x) = 3 inner(x)`, `inner = sin`).
#[wp::func]
fn inner(x: f64) -> f64 {
    x.sin()
}

#[wp::func(grad(x = tripled_dx))]
fn tripled(x: f64) -> f64 {
    3.0 * inner(x)
}

#[wp::func]
fn tripled_dx(x: f64, adj_ret: f64) -> f64 {
    3.0 * adj_ret * wp::grad(inner)(x)
}

#[wp::kernel]
fn k_tripled(xs: Array<f64>, ys: Array<f64>) {
    let i = tid();
    ys[i] = tripled(xs[i]);
}

fn inside_a_custom_gradient(dev: &wp::Device) {
    let xs = arr(&XS, dev).with_grad().unwrap();
    let ys = zeros::<f64, 1>(5, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_tripled, 5, (&xs, &ys), dev).unwrap();
    }
    ys.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    for (k, g) in host(&xs.grad().unwrap()).into_iter().enumerate() {
        assert_close_f64(
            g,
            3.0 * XS[k].cos(),
            1e-14,
            &format!("d(3 sin x)/dx at {k}"),
        );
    }
}

/// `y = x * wp::grad(square)(x) = 2x²` forward; backward treats the gradient as a constant
/// (Warp's rule), so `dy/dx` is that constant, `2x`, not `4x`.
#[wp::kernel]
fn k_times_grad(xs: Array<f64>, ys: Array<f64>) {
    let i = tid();
    let x = xs[i];
    ys[i] = x * wp::grad(square)(x);
}

fn constant_in_backward(dev: &wp::Device) {
    let xs = arr(&XS, dev).with_grad().unwrap();
    let ys = zeros::<f64, 1>(5, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_times_grad, 5, (&xs, &ys), dev).unwrap();
    }
    let want_y: Vec<f64> = XS.iter().map(|x| 2.0 * x * x).collect();
    assert_eq!(host(&ys), want_y, "forward 2x^2");
    ys.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let want: Vec<f64> = XS.iter().map(|x| 2.0 * x).collect();
    assert_eq!(
        host(&xs.grad().unwrap()),
        want,
        "the gradient call is a constant"
    );
}

#[wp::func]
fn cube<T: Float>(x: T) -> T {
    x * x * x
}

#[wp::kernel]
fn k_cube_grad(xs: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = wp::grad(cube::<f32>)(xs[i]);
}

fn generic_instance(dev: &wp::Device) {
    let xs32: Vec<f32> = XS.iter().map(|&x| x as f32).collect();
    let (xs, out) = (arr(&xs32, dev), zeros::<f32, 1>(5, dev));
    wp::launch(k_cube_grad, 5, (&xs, &out), dev).unwrap();
    for (k, g) in host(&out).into_iter().enumerate() {
        let x = xs32[k];
        // The adjoint of x*x*x adds 3 products of two of these small exact values: exact.
        assert_eq!(g, 3.0 * x * x, "d(x^3)/dx at {x}");
    }
}

/// `leaf` uses the old value `atomic_add` returns to pick where it writes, which no replay
/// can recompute: backward through a kernel that reaches it through `middle` is refused (it
/// was refused only when the kernel called `leaf` itself).
#[wp::func]
fn leaf(slots: Array<i32>, out: Array<f32>, x: f32) -> f32 {
    let k = atomic_add(slots, 0, 1);
    out[k] = x;
    x
}

#[wp::func]
fn middle(slots: Array<i32>, out: Array<f32>, x: f32) -> f32 {
    2.0 * leaf(slots, out, x)
}

#[wp::kernel]
fn k_through_middle(xs: Array<f32>, slots: Array<i32>, out: Array<f32>, ys: Array<f32>) {
    let i = tid();
    ys[i] = middle(slots, out, xs[i]);
}

fn callee_without_adjoint_refuses_backward(dev: &wp::Device) {
    let xs = arr(&[1.0f32, 2.0], dev).with_grad().unwrap();
    let slots = zeros::<i32, 1>(1, dev);
    let out = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let ys = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_through_middle, 2, (&xs, &slots, &out, &ys), dev).unwrap();
    }
    ys.grad().unwrap().fill(1.0).unwrap();
    let e = tape.backward_from_grads().unwrap_err();
    assert!(
        matches!(e, wp::Error::NotDifferentiable { .. }),
        "want NotDifferentiable, got {e:?}"
    );
    let text = e.to_string();
    assert!(
        text.contains("leaf") && text.contains("old value"),
        "{text}"
    );
}

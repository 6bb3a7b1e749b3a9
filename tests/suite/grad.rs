//! Reverse-mode AD through a `Tape`: gradients of kernels against closed forms, loops that
//! carry values (where NVIDIA Warp is wrong), branches, array writes, the adjoint stack's
//! limit, and kernels without an adjoint.
//!
//! Tolerances: f64 results are compared with relative error <= 1e-12 where the adjoint does
//! the same arithmetic as the closed form up to a few roundings; f32 with 1e-6 (a few ulps of
//! the f32 unit roundoff 6e-8 over the ~10 operations involved).

use crate::hash_grid::k_energy;
use crate::{arr, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::{Error, FaultKind};

backend_tests!(
    polynomial_gradient,
    seed_function_gradient,
    loop_carried_product,
    branches_and_writes,
    adjoint_stack_limit,
    kernels_without_adjoint,
    tape_zero_accumulate_reset,
    aliased_views_gradient,
    gradcheck_builtins,
    gradcheck_scalar_math,
    funcs_gradient,
    jumps_gradient,
    copy_and_custom_steps,
    atomic_extremes_gradient,
    custom_gradients,
    structs_and_nested_loops,
    gradcheck_linalg,
    gradcheck_noise,
    rng_draws_have_zero_gradient,
    gradcheck_transforms,
    gradcheck_decompositions,
    gradcheck_misc,
    nested_dependent_loops,
    nested_struct_field_gradient,
    loops_in_funcs_gradient,
    nested_exits_gradient,
    store_semantics,
);

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Body {
    pos: DVec3,
    scale: f64,
}

/// Struct fields read and written (`b.pos.x += ..`), vector components, a 2-D array, and
/// nested dynamic loops carrying a value.
#[wp::kernel]
fn k_struct_loops(bodies: Array<Body>, m: Array<f64, 2>, n: i32, out: Array<f64>) {
    let i = tid();
    let mut b = bodies[i];
    let mut acc: f64 = 0.0;
    for r in 0..n {
        for c in 0..n {
            acc = acc * 0.5 + m[(r, c)] * b.scale;
        }
        b.pos.x += acc;
    }
    out[i] = b.pos.x * b.pos.y + b.pos.z;
}

fn structs_and_nested_loops(dev: &wp::Device) {
    let bodies_h = [
        Body {
            pos: DVec3::new(1.0, 2.0, 3.0),
            scale: 0.5,
        },
        Body {
            pos: DVec3::new(-1.0, 0.25, 0.0),
            scale: 2.0,
        },
    ];
    let m_h: Vec<f64> = (0..9).map(|k| 0.25 * k as f64 - 1.0).collect();
    let bodies = arr(&bodies_h, dev).with_grad().unwrap();
    let m = wp::Array::from_slice_shape(&m_h, (3, 3), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let out = zeros::<f64, 1>(2, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_struct_loops, 2, (&bodies, &m, 3, &out), dev),
        &[&m.reshape::<1>(9).unwrap()],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    // The struct's gradient: d out / d pos = (pos.y, pos.x + sum, 1) and d/d scale.
    let tape = wp::Tape::new();
    out.fill(0.0).unwrap();
    {
        let _rec = tape.record();
        wp::launch(k_struct_loops, 2, (&bodies, &m, 3, &out), dev).unwrap();
    }
    bodies.zero_grad().unwrap();
    assert!(backward_ok(dev, tape.backward(&out)));
    let g = bodies.grad().unwrap().to_vec().unwrap();
    let f = |b: Body| {
        let mut b = b;
        let mut acc = 0.0;
        for r in 0..3 {
            for c in 0..3 {
                acc = acc * 0.5 + m_h[r * 3 + c] * b.scale;
            }
            b.pos.x += acc;
        }
        b.pos.x * b.pos.y + b.pos.z
    };
    for (k, b) in bodies_h.iter().enumerate() {
        let h = 1e-6;
        let d = |mut p: Body, mut q: Body, set: &dyn Fn(&mut Body, f64)| {
            set(&mut p, h);
            set(&mut q, -h);
            (f(p) - f(q)) / (2.0 * h)
        };
        let want_y = d(*b, *b, &|x, e| x.pos.y += e);
        let want_s = d(*b, *b, &|x, e| x.scale += e);
        assert!(
            (g[k].pos.y - want_y).abs() <= 1e-6 * want_y.abs().max(1.0),
            "{:?}",
            g[k]
        );
        assert!(
            (g[k].scale - want_s).abs() <= 1e-6 * want_s.abs().max(1.0),
            "{:?}",
            g[k]
        );
        assert_eq!(g[k].pos.z, 1.0);
    }
}

#[wp::func(grad(x = safe_sqrt_dx))]
fn safe_sqrt(x: f64) -> f64 {
    sqrt(x)
}

/// d sqrt(x)/dx, but 0 instead of infinity at x = 0.
#[wp::func]
fn safe_sqrt_dx(x: f64, adj_ret: f64) -> f64 {
    if x > 0.0 {
        adj_ret * 0.5 / sqrt(x)
    } else {
        0.0
    }
}

/// A custom gradient for `a` only (scaled by 10 so that the test sees it is used); `b` gets
/// none.
#[wp::func(grad(a = scaled_da))]
fn product(a: f64, b: f64) -> f64 {
    a * b
}

#[wp::func]
fn scaled_da(a: f64, b: f64, adj_ret: f64) -> f64 {
    let _ = a;
    adj_ret * b * 10.0
}

#[wp::kernel]
fn k_custom(x: Array<f64>, w: Array<f64>, y: Array<f64>) {
    let i = tid();
    y[i] = safe_sqrt(x[i]) + product(x[i], w[i]);
}

/// `#[func(grad(x = f))]` replaces a func's generated adjoint.
fn custom_gradients(dev: &wp::Device) {
    let x = arr(&[0.0f64, 4.0], dev).with_grad().unwrap();
    let w = arr(&[2.0f64, 2.0], dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_custom, 2, (&x, &w, &y), dev).unwrap();
    }
    assert_eq!(y.to_vec().unwrap(), vec![0.0, 10.0]);
    if !backward_ok(dev, tape.backward(&y)) {
        return;
    }
    // Exact: 0 + 10 * 2, and 0.5 / 2 + 10 * 2.
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![20.0, 20.25]);
    assert_eq!(w.grad().unwrap().to_vec().unwrap(), vec![0.0, 0.0]);
}

/// `wp::copy` is recorded (the gradient flows back through it) and `record_func` runs a
/// host-side step at its place in the reverse order.
fn copy_and_custom_steps(dev: &wp::Device) {
    let x = arr(&[1.0f32, 2.0, 3.0], dev).with_grad().unwrap();
    let x2 = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    let order = std::rc::Rc::new(std::cell::RefCell::new(Vec::new()));
    {
        let _rec = tape.record();
        wp::copy(&x2, &x).unwrap();
        let o = order.clone();
        tape.record_func(move || {
            o.borrow_mut().push("custom");
            Ok(())
        })
        .unwrap();
        wp::launch(k_poly, 3, (&x2, &y), dev).unwrap();
        wp::launch(k_sum, 3, (&y, &loss), dev).unwrap();
    }
    assert_eq!(tape.steps(), vec!["copy", "custom", "k_poly", "k_sum"]);
    if !backward_ok(dev, tape.backward(&loss)) {
        return;
    }
    assert_eq!(*order.borrow(), vec!["custom"]);
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![5.0, 7.0, 9.0]);
    assert_eq!(x2.grad().unwrap().to_vec().unwrap(), vec![0.0; 3]);
}

#[wp::func]
fn poly3(x: f64, c: f64) -> f64 {
    // A loop inside a func: x^3 + c x.
    let mut p: f64 = 1.0;
    for _k in 0..3 {
        p = p * x;
    }
    p + c * x
}

#[wp::func]
fn weighted(a: Array<f64>, i: usize, w: f64) -> f64 {
    poly3(a[i], w) * w
}

#[wp::func]
fn put(out: Array<f64>, i: usize, v: f64) {
    out[i] = v * 2.0;
}

#[wp::kernel]
fn k_funcs(x: Array<f64>, w: f64, out: Array<f64>) {
    let i = tid();
    let y = weighted(x, i, w) + poly3(w, x[i]);
    put(out, i, y);
}

/// Gradients through funcs: nested calls, a loop inside a func, an array read inside a func
/// and a unit func that writes the output.
fn funcs_gradient(dev: &wp::Device) {
    // out = 2 ((x^3 + w x) w + w^3 + x w): d/dx = 2 ((3x^2 + w) w + w).
    let (xs, w) = ([0.5f64, -1.25, 2.0], 0.75f64);
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_funcs, 3, (&x, w, &out), dev).unwrap();
    }
    let got = out.to_vec().unwrap();
    for (o, &v) in got.iter().zip(&xs) {
        let want = 2.0 * ((v * v * v + w * v) * w + w * w * w + v * w);
        assert!((o - want).abs() <= 1e-12 * want.abs().max(1.0));
    }
    if !backward_ok(dev, tape.backward(&out)) {
        return;
    }
    for (g, &v) in x.grad().unwrap().to_vec().unwrap().iter().zip(&xs) {
        let want = 2.0 * ((3.0 * v * v + w) * w + w);
        assert!(((g - want) / want).abs() <= 1e-12, "x = {v}: {g} vs {want}");
    }
}

/// Every differentiable builtin of the table in one kernel (f64 and f32 versions), checked
/// by `wp::gradcheck` against central differences; and a wrong gradient is caught.
#[wp::kernel]
fn k_builtins(x: Array<f64>, out: Array<f64>) {
    let a = x[0];
    let b = x[1];
    let c = x[2];
    let v = DVec3::new(a, b, c);
    let w = DVec3::new(c, a * 0.5, b + 1.0);
    out[0] = min(a, b) + max(a, c) + clamp(b, -1.0, 1.0) + abs(a) + sign(b) * a;
    out[1] = floor(a) + ceil(b) + sqrt(c) + exp(a * 0.25) + log(c);
    out[2] = sin(a) + cos(b) + tan(c * 0.25) + atan2(a, c) + pow(c, a);
    out[3] = dot(v, w) + length(v) + normalize(w).y + cross(v, w).z + lerp(a, b, c);
    out[4] = (a / c - b) * (a % 0.75) - a * b * c;
}

#[wp::kernel]
fn k_builtins32(x: Array<f32>, out: Array<f32>) {
    let a = x[0];
    let b = x[1];
    let c = x[2];
    let v = vec3(a, b, c);
    out[0] = min(a, b) + max(a, c) + sqrt(c) + exp(a * 0.25) * log(c) + sin(a) * cos(b);
    // Casts: through f64 and back (exact for f32 values, so the check sees a smooth map).
    out[1] = dot(v, v)
        + length(v)
        + normalize(v).x
        + cross(v, vec3(1.0, 0.0, 0.0)).y
        + (a as f64 * 2.0) as f32;
}

#[wp::kernel]
fn k_wrong_free(x: Array<f64>, out: Array<f64>) {
    // d/dx of x * x is 2x; the tape agrees. The check must flag a function whose tape
    // gradient differs from its values: here `floor` has zero gradient but jumps between
    // the two central-difference points around 2.0.
    out[0] = floor(x[0]) * 10.0;
}

fn gradcheck_builtins(dev: &wp::Device) {
    let x = arr(&[0.7f64, -0.4, 1.3], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(5, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_builtins, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    assert!(report.max_rel_error < 1e-6, "{report:?}");
    assert_eq!((report.analytic.len(), report.analytic[0].len()), (5, 3));

    let x = arr(&[0.7f32, -0.4, 1.3], dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_builtins32, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f32>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);

    // A jump the tape cannot see is reported, not passed.
    let x = arr(&[2.0f64], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_wrong_free, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(!report.passed);
    assert_eq!(report.worst.unwrap().2, 0.0);
}

/// Every differentiable scalar-math builtin added for Warp parity, one per output (so that a
/// failure names it), at points away from their kinks: `wp::gradcheck` against central
/// differences, f64 and f32: one body for both precisions, so the two cannot drift apart.
macro_rules! scalar_math_kernel {
    ($name:ident, $t:ident) => {
        #[wp::kernel]
        fn $name(x: Array<$t>, out: Array<$t>) {
            let a = x[0];
            let b = x[1];
            let c = x[2];
            out[0] = asin(a);
            out[1] = acos(b);
            out[2] = atan(c);
            out[3] = sinh(b);
            out[4] = cosh(a);
            out[5] = tanh(c);
            out[6] = exp2(b);
            out[7] = log2(c);
            out[8] = log10(c);
            out[9] = cbrt(b);
            out[10] = erf(b);
            out[11] = erfc(c);
            out[12] = erfinv(a);
            out[13] = erfcinv(c);
            out[14] = frac(c) * a;
            out[15] = degrees(a);
            out[16] = radians(b);
            out[17] = smoothstep(b, c, a);
            out[18] = r#mod(c * 3.0, a + 1.0);
            // Piecewise constant (zero gradient), away from their jumps.
            out[19] = (round(a * 3.0) + rint(b) + trunc(c) + step(b)) * c;
        }
    };
}

scalar_math_kernel!(k_scalar_math, f64);
scalar_math_kernel!(k_scalar_math32, f32);

fn gradcheck_scalar_math(dev: &wp::Device) {
    let x = arr(&[0.3f64, -0.45, 1.2], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(20, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_scalar_math, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    assert!(report.max_rel_error < 1e-6, "{report:?}");
    // The analytic Jacobian is the closed form: spot-check rows against it.
    let j = &report.analytic;
    let (a, b, c) = (0.3f64, -0.45f64, 1.2f64);
    let close = |got: f64, want: f64, what: &str| {
        assert!(
            (got - want).abs() <= 1e-12 * want.abs().max(1.0),
            "{what}: {got} vs {want}"
        )
    };
    close(j[0][0], 1.0 / (1.0 - a * a).sqrt(), "d asin");
    close(j[1][1], -1.0 / (1.0 - b * b).sqrt(), "d acos");
    close(j[5][2], 1.0 - c.tanh().powi(2), "d tanh");
    close(
        j[10][1],
        2.0 / std::f64::consts::PI.sqrt() * (-b * b).exp(),
        "d erf",
    );
    close(j[14][2], a, "d frac");
    close(j[18][0], -(c * 3.0 / (a + 1.0)).trunc(), "d mod / d b");
    assert_eq!(j[19], vec![0.0, 0.0, 3.0], "piecewise-constant builtins");

    let x = arr(&[0.3f32, -0.45, 1.2], dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(20, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_scalar_math32, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f32>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
}

/// Runs a backward; every test below runs on both backends (a failed backward panics with
/// its error).
fn backward_ok(dev: &wp::Device, r: wp::Result<()>) -> bool {
    if let Err(e) = r {
        panic!("backward on {dev}: {e}");
    }
    true
}

#[wp::kernel]
fn k_poly(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    y[i] = x[i] * x[i] + 3.0 * x[i] + 1.0;
}

#[wp::kernel]
fn k_sum(y: Array<f32>, loss: Array<f32>) {
    let i = tid();
    atomic_add(loss, 0, y[i]);
}

/// Warp's documented example: y = x^2 + 3x + 1 at [1, 2, 3] has dy/dx = [5, 7, 9].
fn polynomial_gradient(dev: &wp::Device) {
    let x = arr(&[1.0f32, 2.0, 3.0], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_poly, 3, (&x, &y), dev).unwrap();
        wp::launch(k_sum, 3, (&y, &loss), dev).unwrap();
    }
    assert_eq!(tape.steps(), vec!["k_poly", "k_sum"]);
    assert_eq!(loss.to_vec().unwrap(), vec![5.0 + 11.0 + 19.0]);
    if !backward_ok(dev, tape.backward(&loss)) {
        return;
    }
    // Exact: small integers.
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![5.0, 7.0, 9.0]);
    // The write y[i] = .. handed y's gradient to the value and cleared it.
    assert_eq!(y.grad().unwrap().to_vec().unwrap(), vec![0.0; 3]);
}

#[wp::kernel]
fn k_seed(x: Array<f64>, out: Array<f64>) {
    let i = tid();
    let v = x[i];
    out[i] = sin(v * v) * log(v) + v * v * v / sqrt(1.0 - v * v);
}

#[wp::kernel]
fn k_seed32(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    let v = x[i];
    out[i] = (v * v).sin() * v.ln() + v * v * v / (1.0 - v * v).sqrt();
}

/// The seed program's f(x) = sin(x^2) ln x + x^3 / sqrt(1 - x^2): f'(0.5) = 0.7854595.
fn seed_function_gradient(dev: &wp::Device) {
    let fp = |x: f64| {
        let s = (1.0 - x * x).sqrt();
        2.0 * x * (x * x).cos() * x.ln()
            + (x * x).sin() / x
            + 3.0 * x * x / s
            + x.powi(4) / (s * s * s)
    };
    assert!((fp(0.5) - 0.7854595).abs() < 5e-8);
    let xs = [0.5f64, 0.25, 0.75];
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_seed, 3, (&x, &out), dev).unwrap();
    }
    if !backward_ok(dev, tape.backward(&out)) {
        return;
    }
    for (g, &x0) in x.grad().unwrap().to_vec().unwrap().iter().zip(&xs) {
        let want = fp(x0);
        assert!(
            ((g - want) / want).abs() <= 1e-12,
            "x = {x0}: {g} vs {want}"
        );
    }
    let x = arr(&[0.5f32], dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_seed32, 1, (&x, &out), dev).unwrap();
    }
    tape.backward(&out).unwrap();
    let g = x.grad().unwrap().to_vec().unwrap()[0];
    assert!((g as f64 - 0.7854595).abs() / 0.7854595 <= 1e-6, "{g}");
}

/// p = prod x[j] over a dynamic loop: dp/dx[j] = prod of the others. NVIDIA Warp returns
/// [32, 8, 2] for x = [2, 2, 2]; the answer is [4, 4, 4].
#[wp::kernel]
fn k_prod(x: Array<f32>, n: i32, out: Array<f32>) {
    let mut p = 1.0;
    for j in 0..n {
        p = p * x[j];
    }
    out[0] = p;
}

fn loop_carried_product(dev: &wp::Device) {
    for (xs, want) in [
        (vec![2.0f32, 2.0, 2.0], vec![4.0f32, 4.0, 4.0]),
        (vec![1.5, -2.0, 4.0, 0.5], vec![-4.0, 3.0, -1.5, -12.0]),
    ] {
        let x = arr(&xs, dev).with_grad().unwrap();
        let out = zeros::<f32, 1>(1, dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch(k_prod, 1, (&x, xs.len() as i32, &out), dev).unwrap();
        }
        if !backward_ok(dev, tape.backward(&out)) {
            return;
        }
        // Exact: products of a few binary fractions.
        assert_eq!(x.grad().unwrap().to_vec().unwrap(), want);
    }
}

/// Both sides of an if/else, an `if` inside a loop, a `mut` variable, and a value written
/// then read back.
#[wp::kernel]
fn k_branches(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let v = x[i];
    let mut s: f64 = 0.0;
    if v > 0.0 {
        s = v * v;
    } else {
        s = -3.0 * v;
    }
    for k in 0..3 {
        if k % 2 == 0 {
            s = s * v;
        } else {
            s = s + v;
        }
    }
    y[i] = s;
}

fn branches_and_writes(dev: &wp::Device) {
    // v > 0: ((v^3) + v) * v = v^4 + v^2: d = 4v^3 + 2v. v <= 0: (-3v^2 + v) v = -3v^3 + v^2:
    // d = -9v^2 + 2v.
    let xs = [1.5f64, -0.5, 2.0];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_branches, 3, (&x, &y), dev).unwrap();
    }
    if !backward_ok(dev, tape.backward(&y)) {
        return;
    }
    let g = x.grad().unwrap().to_vec().unwrap();
    for (g, &v) in g.iter().zip(&xs) {
        let want = if v > 0.0 {
            4.0 * v * v * v + 2.0 * v
        } else {
            -9.0 * v * v + 2.0 * v
        };
        assert!(((g - want) / want).abs() <= 1e-12, "v = {v}: {g} vs {want}");
    }
}

/// A loop that needs more adjoint stack than configured: backward is an error naming the
/// kernel and the line, never a wrong gradient.
fn adjoint_stack_limit(dev: &wp::Device) {
    let n = 1000;
    let x = arr(&vec![1.0f32; n], dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_prod, 1, (&x, n as i32, &out), dev).unwrap();
    }
    // A per-tape capacity: the process-wide one (other tests run in parallel) is untouched.
    tape.set_adstack_bytes(Some(256)).unwrap();
    match tape.backward(&out) {
        Err(Error::Fault(f)) => {
            assert_eq!(f.kernel, "k_prod");
            assert!(
                matches!(f.kind, FaultKind::AdStackOverflow { capacity: 256, .. }),
                "{f:?}"
            );
            assert!(f.to_string().contains("set_adstack_bytes"), "{f}");
        }
        other => panic!("expected an adjoint stack fault, got {other:?}"),
    }
    // With room it works (about 16 bytes per iteration here): every gradient is the
    // product of the other ones, 1.
    x.zero_grad().unwrap();
    tape.set_adstack_bytes(Some(1 << 16)).unwrap();
    tape.backward(&out).unwrap();
    assert!(x
        .grad()
        .unwrap()
        .to_vec()
        .unwrap()
        .iter()
        .all(|&g| g == 1.0));
}

#[wp::kernel]
fn k_extremes(x: Array<f32>, lo: Array<f32>, hi: Array<f32>) {
    let i = tid();
    atomic_min(lo, 0, x[i] * 2.0);
    atomic_max(hi, 0, x[i] * 3.0);
}

/// atomic_min / atomic_max pass the gradient to the value that won.
fn atomic_extremes_gradient(dev: &wp::Device) {
    let x = arr(&[0.5f32, -1.0, 2.0, 0.25], dev).with_grad().unwrap();
    let lo = arr(&[f32::INFINITY], dev).with_grad().unwrap();
    let hi = arr(&[f32::NEG_INFINITY], dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_extremes, 4, (&x, &lo, &hi), dev).unwrap();
    }
    assert_eq!(
        (lo.to_vec().unwrap()[0], hi.to_vec().unwrap()[0]),
        (-2.0, 6.0)
    );
    lo.grad().unwrap().fill(1.0).unwrap();
    hi.grad().unwrap().fill(10.0).unwrap();
    if !backward_ok(dev, tape.backward_from_grads()) {
        return;
    }
    // d lo / d x[1] = 2, d hi / d x[2] = 3 (times the seeds 1 and 10).
    assert_eq!(
        x.grad().unwrap().to_vec().unwrap(),
        vec![0.0, 2.0, 30.0, 0.0]
    );
}

#[wp::kernel(enable_backward = false)]
fn k_no_adjoint(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    y[i] = x[i] * 2.0;
}

/// Backward through a kernel without an adjoint is an error naming it and saying why.
fn kernels_without_adjoint(dev: &wp::Device) {
    let x = arr(&[3.0f32], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_no_adjoint, 1, (&x, &y), dev).unwrap();
    }
    let e = tape.backward(&y).unwrap_err();
    assert!(matches!(e, Error::NotDifferentiable { .. }), "{e:?}");
    assert!(
        e.to_string()
            .contains("`k_no_adjoint`: it was declared with #[kernel(enable_backward = false)]"),
        "{e}"
    );
}

#[wp::func]
fn first_above(x: Array<f64>, n: i32, t: f64) -> f64 {
    // Early return from inside a loop; the tail value otherwise.
    for j in 0..n {
        if x[j] > t {
            return x[j] * x[j];
        }
    }
    -1.0
}

/// `while` (halving until at most 1), `break` and `continue` in a `for`, an early `return`
/// from a kernel and from inside a func's loop: gradients follow the path actually taken.
#[wp::kernel]
fn k_jumps(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let mut v = x[i];
    while v > 1.0 {
        v = v * 0.5;
    }
    let mut s: f64 = 0.0;
    for k in 0..10 {
        if k == 1 {
            continue;
        }
        if k == 4 {
            break;
        }
        s += v * (k as f64);
    }
    y[i] = s + first_above(x, 3, 2.5);
    if x[i] < 0.0 {
        return;
    }
    y[i] += x[i] * 3.0;
}

fn jumps_gradient(dev: &wp::Device) {
    // v = x / 2^m (m halvings), s = v (0 + 2 + 3) = 5 v; first_above over x = [0.75, 3.0, 6.0]
    // returns x[1]^2 (the first above 2.5) for every thread; x >= 0 adds 3 x.
    let xs = [0.75f64, 3.0, 6.0, -0.5];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(4, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_jumps, 4, (&x, &y), dev).unwrap();
    }
    let halvings = |v: f64| {
        let (mut v, mut m) = (v, 0);
        while v > 1.0 {
            v *= 0.5;
            m += 1;
        }
        m
    };
    let want_y: Vec<f64> = xs
        .iter()
        .map(|&v| 5.0 * v / 2f64.powi(halvings(v)) + 9.0 + if v < 0.0 { 0.0 } else { 3.0 * v })
        .collect();
    assert_eq!(y.to_vec().unwrap(), want_y);
    if !backward_ok(dev, tape.backward(&y)) {
        return;
    }
    // dy_i/dx_i = 5 / 2^m (+ 3 unless the thread returned early), and each of the 4 threads
    // adds 2 x[1] = 6 to x[1]'s gradient.
    let want: Vec<f64> = xs
        .iter()
        .enumerate()
        .map(|(k, &v)| {
            let ret = if v < 0.0 { 0.0 } else { 3.0 };
            5.0 / 2f64.powi(halvings(v)) + ret + if k == 1 { 24.0 } else { 0.0 }
        })
        .collect();
    // Exact: binary fractions.
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), want);
}

#[wp::kernel]
fn k_add_in_place(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    y[i] += 2.0 * x[i];
}

/// The semantics README's "Backward semantics" states: a plain store hands its element's
/// gradient to the stored value and clears it (so an intermediate's gradient is zero after
/// backward and a second backward from the same seed adds exactly the first's gradients to
/// the leaves, not a compounded amount); `y[i] += v` is a read, an add and a store (not an
/// atomic): its backward gives `v` the gradient at `i` and leaves `y`'s gradient at `i` as it
/// was, which is what `y_new = y_old + v` means. All values are small integers: exact.
fn store_semantics(dev: &wp::Device) {
    let x = arr(&[1.0f32, 2.0], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_poly, 2, (&x, &y), dev).unwrap();
        wp::launch(k_sum, 2, (&y, &loss), dev).unwrap();
    }
    if !backward_ok(dev, tape.backward(&loss)) {
        return;
    }
    // dy/dx = 2x + 3; the store in k_poly took y's gradient and cleared it.
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![5.0, 7.0]);
    assert_eq!(y.grad().unwrap().to_vec().unwrap(), vec![0.0, 0.0]);
    tape.backward(&loss).unwrap();
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![10.0, 14.0]);
    assert_eq!(y.grad().unwrap().to_vec().unwrap(), vec![0.0, 0.0]);

    // y[i] += 2 x[i], seeded directly on y: x gets 2 * seed, y keeps its seed.
    let x = arr(&[1.0f32, 2.0], dev).with_grad().unwrap();
    let y = arr(&[10.0f32, 20.0], dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_add_in_place, 2, (&x, &y), dev).unwrap();
    }
    assert_eq!(y.to_vec().unwrap(), vec![12.0, 24.0]);
    tape.backward(&y).unwrap();
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![2.0, 2.0]);
    assert_eq!(y.grad().unwrap().to_vec().unwrap(), vec![1.0, 1.0]);
}

/// Gradients accumulate across backward calls; zero() clears them; reset() forgets.
fn tape_zero_accumulate_reset(dev: &wp::Device) {
    let x = arr(&[1.0f32, 2.0], dev).with_grad().unwrap();
    let y = zeros::<f32, 1>(2, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_poly, 2, (&x, &y), dev).unwrap();
        wp::launch(k_sum, 2, (&y, &loss), dev).unwrap();
    }
    // Launches outside the recording are not recorded.
    wp::launch(k_sum, 2, (&y, &loss), dev).unwrap();
    assert_eq!(tape.len(), 2);
    if !backward_ok(dev, tape.backward(&loss)) {
        return;
    }
    tape.backward(&loss).unwrap();
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![10.0, 14.0]);
    tape.zero().unwrap();
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![0.0, 0.0]);
    tape.reset().unwrap();
    assert!(tape.is_empty());
    tape.backward(&loss).unwrap();
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), vec![0.0, 0.0]);
}

/// `c[i] = a[i] - b[i]`: every array at the thread index (thread-owned).
#[wp::kernel]
fn k_difference(a: Array<f32>, b: Array<f32>, c: Array<f32>) {
    let i = tid();
    c[i] = a[i] - b[i];
}

/// `out[i, j] = m[i, j] + mt[i, j]` (thread-owned 2-D arrays).
#[wp::kernel]
fn k_sum2(m: Array<f32, 2>, mt: Array<f32, 2>, out: Array<f32, 2>) {
    let (i, j) = tid();
    out[(i, j)] = m[(i, j)] + mt[(i, j)];
}

/// Two thread-owned arguments viewing one gradient differently (`x.view(0..n-1)` beside
/// `x.view(1..n)`, `m` beside `m.transpose()`): thread `i` adds into an element another
/// thread adds into through the other argument, so the launch takes the atomic adds; every
/// update must arrive. 64K threads, so that many chunks (CPU) and blocks (GPU) meet at
/// shared elements. Exact: each gradient element is a sum of at most two +-1.
fn aliased_views_gradient(dev: &wp::Device) {
    let n = 1 << 16;
    let x = zeros::<f32, 1>(n + 1, dev).with_grad().unwrap();
    let (a, b) = (x.view(0..n).unwrap(), x.view(1..n + 1).unwrap());
    let c = zeros::<f32, 1>(n, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_difference, n, (&a, &b, &c), dev).unwrap();
    }
    c.grad().unwrap().fill(1.0).unwrap();
    if !backward_ok(dev, tape.backward_from_grads()) {
        return;
    }
    let g = x.grad().unwrap().to_vec().unwrap();
    let mut want = vec![0.0f32; n + 1];
    want[0] = 1.0;
    want[n] = -1.0;
    let wrong = (0..=n).filter(|&k| g[k] != want[k]).count();
    assert_eq!(
        wrong,
        0,
        "{wrong} of {} gradient elements of x lost updates",
        n + 1
    );

    let s = 256;
    let m = zeros::<f32, 2>((s, s), dev).with_grad().unwrap();
    let out = zeros::<f32, 2>((s, s), dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_sum2, [s, s], (&m, &m.transpose(), &out), dev).unwrap();
    }
    out.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let g = m.grad().unwrap().to_vec().unwrap();
    let wrong = g.iter().filter(|&&v| v != 2.0).count();
    assert_eq!(
        wrong,
        0,
        "{wrong} of {} gradient elements of m are not 2",
        s * s
    );
}

/// The CUDA adjoint units of this module's kernels compile as host C++ (g++), so a C++ error
/// in the adjoint emitter shows without a GPU. (They run for real in the CUDA instances.)
#[test]
fn cuda_adjoint_units_compile_on_the_host() {
    if std::process::Command::new("g++")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("SKIPPED cuda_adjoint_units_compile_on_the_host: no g++");
        return;
    }
    let infos = [
        <k_poly as wp::Kernel>::info(),
        <k_sum as wp::Kernel>::info(),
        <k_seed as wp::Kernel>::info(),
        <k_seed32 as wp::Kernel>::info(),
        <k_prod as wp::Kernel>::info(),
        <k_branches as wp::Kernel>::info(),
        <k_builtins as wp::Kernel>::info(),
        <k_builtins32 as wp::Kernel>::info(),
        <k_scalar_math as wp::Kernel>::info(),
        <k_scalar_math32 as wp::Kernel>::info(),
        <k_funcs as wp::Kernel>::info(),
        <k_jumps as wp::Kernel>::info(),
        <k_extremes as wp::Kernel>::info(),
        <k_custom as wp::Kernel>::info(),
        <k_struct_loops as wp::Kernel>::info(),
        <k_linalg_grad as wp::Kernel>::info(),
        <k_noise_grad as wp::Kernel>::info(),
        <k_rng_in_grad as wp::Kernel>::info(),
        <k_xform_grad as wp::Kernel>::info(),
        <crate::transforms::k_xform_loss as wp::Kernel>::info(),
        <crate::transforms::k_xform64 as wp::Kernel>::info(),
        <crate::transforms::k_xform32 as wp::Kernel>::info(),
        <crate::transforms::k_bodies as wp::Kernel>::info(),
        <crate::spatial::k_spatial64 as wp::Kernel>::info(),
        <crate::spatial::k_spatial32 as wp::Kernel>::info(),
        <crate::spatial::k_bodies as wp::Kernel>::info(),
        <crate::spatial::k_spatial_loss as wp::Kernel>::info(),
        <crate::spatial::k_spatial_array_loss as wp::Kernel>::info(),
        <crate::spatial::k_spatial_fwd as wp::Kernel>::info(),
        <k_decomp_grad as wp::Kernel>::info(),
        <k_misc_grad as wp::Kernel>::info(),
        <crate::misc::k_lower_bound as wp::Kernel>::info(),
        <crate::misc::k_sample_cdf as wp::Kernel>::info(),
        <crate::misc::k_quats as wp::Kernel>::info(),
        <k_triangle as wp::Kernel>::info(),
        <k_triangle_const as wp::Kernel>::info(),
        <k_triangle_func as wp::Kernel>::info(),
        <k_links as wp::Kernel>::info(),
        <k_func_loops as wp::Kernel>::info(),
        <k_nested_exits as wp::Kernel>::info(),
        // Kernels whose variables the macro cannot type (consts, struct fields and func results
        // as loop bounds, `!` of a func's bool): their CUDA adjoints declare them by the type
        // of their definitions.
        <crate::funcs::k_mut_bool as wp::Kernel>::info(),
        <crate::funcs::k_untyped as wp::Kernel>::info(),
        <crate::params::k_consts as wp::Kernel>::info(),
        // A hash grid query loop in a func.
        <k_energy as wp::Kernel>::info(),
    ];
    let dir = std::env::temp_dir().join(format!("wp-adj-host-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    for info in infos {
        assert!(
            info.cuda_adjoint_error.is_none(),
            "{}: {:?}",
            info.name,
            info.cuda_adjoint_error
        );
        let src = wp::cuda_source::assemble_adjoint(info);
        let cpp = dir.join(format!("{}.cpp", info.name));
        std::fs::write(
            &cpp,
            format!(
                "#include <cstring>\n#define WP_ADSTACK_BYTES 4096\n{}",
                src.text
            ),
        )
        .unwrap();
        let out = std::process::Command::new("g++")
            .args(["-std=c++17", "-fsyntax-only", "-Wno-unused", "-I", include])
            .arg(&cpp)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}:\n{}",
            cpp.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The vector, matrix and quaternion builtins, one per output, by `wp::gradcheck` against
/// central differences (f64; at generic points: an invertible matrix, non-unit and unit
/// quaternions, a rotation matrix inside one branch of `quat_from_matrix`, a slerp between
/// distinct rotations).
#[wp::kernel]
fn k_linalg_grad(x: Array<f64>, out: Array<f64>) {
    let a = DMat3::from_cols(
        DVec3::new(x[0], x[1], x[2]),
        DVec3::new(x[3], x[4], x[5]),
        DVec3::new(x[6], x[7], x[8]),
    );
    let v = DVec3::new(x[9], x[10], x[11]);
    let w = DVec3::new(x[1], x[5], x[9]);
    let q = DQuat::from_xyzw(x[0], x[4], x[8], x[11]);
    let p = DQuat::from_xyzw(x[2], x[6], x[10], x[3]);
    let probe = DVec3::new(0.3, -0.7, 1.1);
    out[0] = length_sq(v);
    out[1] = dot(outer(v, w) * probe, probe);
    out[2] = dot(diag(v) * probe, w);
    out[3] = dot(cw_mul(v, w) + cw_div(v, w), probe);
    out[4] = dot(transpose(a) * probe, v);
    out[5] = determinant(a);
    out[6] = dot(inverse(a) * probe, w);
    out[7] = trace(a) + ddot(a, cw_mul(a, a));
    out[8] = dot(skew(v) * w, probe);
    out[9] = dot(q, p) + length(q) + length_sq(p);
    out[10] = dot(normalize(q), p);
    out[11] = dot(inverse(q), p) + dot(quat_inverse(p), q);
    out[12] = dot(quat_rotate(q, v), probe) + dot(quat_rotate_inv(p, w), probe);
    out[13] = dot(quat_from_axis_angle(v, x[3]), p);
    out[14] = ddot(quat_to_matrix(q), a);
    out[15] = dot(quat_from_matrix(quat_to_matrix(normalize(q))), p);
    out[16] = dot(quat_slerp(normalize(q), normalize(p), x[5] * 0.5), p);
    out[17] = cw_div(a, transpose(a)).x_axis.y;
}

fn gradcheck_linalg(dev: &wp::Device) {
    let xs = [
        1.2f64, 0.3, -0.4, 0.5, 1.5, 0.2, -0.3, 0.6, 1.1, 0.7, -0.2, 0.9,
    ];
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(18, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_linalg_grad, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    assert!(report.max_rel_error < 1e-6, "{report:?}");
}

/// Perlin noise and periodic noise in every dimension (f32 only, as in Warp), one per output,
/// by `wp::gradcheck` against central differences (f32 defaults: eps 1e-3 against the
/// noise's second derivatives of order 10, so a difference quotient is good to about 1e-3).
#[wp::kernel]
fn k_noise_grad(x: Array<f32>, out: Array<f32>) {
    let s = rand_init(7);
    let v = vec4(x[0], x[1], x[2], x[3]);
    out[0] = noise(s, x[0]);
    out[1] = noise(s, vec2(x[1], x[2]));
    out[2] = noise(s, vec3(x[0], x[2], x[3]));
    out[3] = noise(s, v);
    out[4] = pnoise(s, x[3], 2);
    out[5] = pnoise(s, vec2(x[0], x[3]), 2, 3);
    out[6] = pnoise(s, vec3(x[1], x[2], x[3]), 4, 2, 3);
    out[7] = pnoise(s, v * 2.0, 3, 5, 2, 4);
}

fn gradcheck_noise(dev: &wp::Device) {
    let x = arr(&[0.3f32, 1.45, -0.7, 2.2], dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(8, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_noise_grad, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f32>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    // Every output depends on some input: the gradient is not trivially zero.
    for (k, row) in report.analytic.iter().enumerate() {
        assert!(row.iter().any(|g| *g != 0.0), "output {k}: {row:?}");
    }
}

/// RNG draws inside a differentiated kernel (in a loop, so the state is pushed on the adjoint
/// stack and replayed): the draws are constants of the gradient, the rest is differentiated.
#[wp::kernel]
fn k_rng_in_grad(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    let mut s = rand_init(11, i as i32);
    let mut acc = 0.0;
    for _k in 0..3 {
        acc += x[i] * randf(&mut s) + randn(&mut s);
        let p = sample_unit_disk(&mut s);
        acc += p.x * x[i] * x[i];
    }
    out[i] = acc + noise(s, x[i]);
}

fn rng_draws_have_zero_gradient(dev: &wp::Device) {
    use wp::__private::builtins as core;
    let xs = [0.3f32, -1.2, 2.7];
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_rng_in_grad, 3, (&x, &out), dev).unwrap();
    }
    assert!(backward_ok(dev, tape.backward(&out)));
    let g = x.grad().unwrap().to_vec().unwrap();
    // The closed form: d/dx (x u + n + p.x x²) = u + 2 p.x x per round, plus the noise's
    // derivative at the final state.
    for (i, x) in xs.iter().enumerate() {
        let mut s = core::rand_init_offset(11, i as i32);
        let mut want = 0.0f32;
        for _ in 0..3 {
            let u = core::randf(s);
            s = core::rand_pcg(core::rand_pcg(core::rand_pcg(s)));
            let p = core::sample_unit_disk(s);
            s = core::rand_pcg(core::rand_pcg(s));
            want += u + 2.0 * p.x * x;
        }
        let h = 1e-3f32;
        want += (core::noise(s, x + h) - core::noise(s, x - h)) / (2.0 * h);
        assert!((g[i] - want).abs() < 2e-3, "thread {i}: {} vs {want}", g[i]);
    }
}

/// The transform builtins and operators, one or two per output, by `wp::gradcheck` against
/// central differences (f64; generic points: non-unit rotations, where the glam rotation
/// formula the adjoints differentiate is not Warp's, and a unit one with a clear
/// `quat_from_matrix` branch for the matrix round trip).
#[wp::kernel]
fn k_xform_grad(x: Array<f64>, out: Array<f64>) {
    let a = DTransform::new(
        DVec3::new(x[0], x[1], x[2]),
        DQuat::from_xyzw(x[3], x[4], x[5], x[6]),
    );
    let b = transformation(
        DVec3::new(x[7], x[8], x[9]),
        DQuat::from_xyzw(x[10], x[11], x[12], x[13]),
    );
    let v = DVec3::new(x[14], x[15], x[16]);
    let probe = DVec3::new(0.3, -0.7, 1.1);
    let w = DQuat::from_xyzw(0.2, -0.4, 0.6, 0.5);
    out[0] = dot(transform_point(a, v), probe);
    out[1] = dot(a.transform_vector(v), probe);
    let ab = a * b;
    out[2] = dot(ab.p, probe) + dot(ab.q, w);
    let ba = transform_multiply(b, a);
    out[3] = dot(ba.p, v) + dot(ba.q, w);
    out[4] = dot(a.inverse().p, probe) + dot(transform_inverse(b).q, w) + dot(inverse(b).p, v);
    out[5] = dot(transform_get_translation(a), v) + dot(transform_get_rotation(b), w);
    out[6] = ddot(transform_to_matrix(a), transform_to_matrix(b));
    let u = DTransform::new(a.p, normalize(a.q));
    let back = transform_from_matrix(transform_to_matrix(u));
    out[7] = dot(back.q, w) + dot(back.p, probe);
    out[8] = dot((a + b).q, w) + dot((a - b).p, probe) + dot((a * x[2]).p, v);
    out[9] = dot((x[3] * b).q, w) + dot((-a).p, probe);
    out[10] = dot(lerp(a, b, x[16]).p, probe) + dot(a.lerp(b, 0.3).q, w);
    let m = transform_to_matrix(b);
    out[11] = dot(transform_point(m, v), probe) + dot(m.transform_vector3(v), probe);
    let mut t = a;
    t.p = v;
    t.q = b.q * 2.0;
    out[12] = dot(t.transform_point(probe), probe);
}

fn gradcheck_transforms(dev: &wp::Device) {
    let xs = [
        0.4f64, -1.1, 0.7, 0.1, 0.2, -0.3, 0.9, 1.3, 0.25, -0.6, -0.5, 0.45, 0.3, 0.6, -0.6, 0.9,
        0.35,
    ];
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(13, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_xform_grad, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    assert!(report.max_rel_error < 1e-6, "{report:?}");
}

/// The decompositions by `wp::gradcheck` (f64), each output on its own and through a loop that
/// overwrites a destructured result (the adjoint stack then holds tuples). The point is generic
/// with well-separated singular values (about 3.2, 1.9, 0.8) and eigenvalues of the symmetric
/// part (about 3.1, 1.5, 0.7), where the decompositions are smooth; eig3 is differentiated
/// through a symmetric matrix, as its adjoint requires.
#[wp::kernel]
fn k_decomp_grad(x: Array<f64>, out: Array<f64>) {
    let a = DMat3::from_cols(
        DVec3::new(x[0], x[1], x[2]),
        DVec3::new(x[3], x[4], x[5]),
        DVec3::new(x[6], x[7], x[8]),
    );
    let p = DVec3::new(0.3, -0.7, 1.1);
    let w = DVec3::new(-0.4, 0.2, 0.9);
    let (u, s, v) = svd3(a);
    out[0] = s.x;
    out[1] = s.y;
    out[2] = s.z;
    out[3] = dot(u * p, w);
    out[4] = dot(v * p, w);
    let (q, d) = eig3((a + a.transpose()) * 0.5);
    out[5] = d.x + d.y * 2.0 + d.z * 3.0;
    out[6] = dot(q * p, w);
    let (q2, r) = qr3(a);
    out[7] = dot(q2 * p, w);
    out[8] = dot(r * p, w);
    let m2 = DMat2::from_cols(DVec2::new(x[0], x[1]), DVec2::new(x[3], x[4]));
    let (u2, s2, v2) = svd2(m2);
    out[9] = s2.x + s2.y * 0.5;
    out[10] = dot(u2 * DVec2::new(0.3, -0.7), DVec2::new(0.2, 0.9));
    out[11] = dot(v2 * DVec2::new(0.3, -0.7), DVec2::new(0.2, 0.9));
    let mut m = a;
    let mut acc: f64 = 0.0;
    for _k in 0..2 {
        let (uu, ss, vv) = svd3(m);
        acc += dot(ss, p) + dot(uu * p, w);
        m = uu * DMat3::from_diagonal(ss * 0.5) * vv.transpose() + a;
    }
    out[12] = acc;
}

fn gradcheck_decompositions(dev: &wp::Device) {
    let xs = [2.0f64, 0.4, -0.3, 0.5, 1.6, 0.6, -0.2, 0.3, 1.1];
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(13, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_decomp_grad, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    assert!(report.max_rel_error < 1e-6, "{report:?}");
}

/// The differentiable builtins of the "misc" section, one per output, by `wp::gradcheck`
/// against central differences (f64, at generic points: away from the norms' thresholds,
/// with distinct vector lanes, unit and non-unit quaternions, a rigid motion with scales).
#[wp::kernel]
fn k_misc_grad(x: Array<f64>, out: Array<f64>) {
    let v = DVec3::new(x[0], x[1], x[2]);
    let w = DVec3::new(x[3], x[4], x[5]);
    let q = DQuat::from_xyzw(x[6], x[7], x[8], x[9]);
    let probe = DVec3::new(0.3, -0.7, 1.1);
    let pq = DQuat::from_xyzw(0.2, -0.4, 0.5, 0.7);
    out[0] = copysign(x[0], x[1]) + x[2].copysign(-1.0);
    out[1] = min(v) + 2.0 * max(v) + w.min_element();
    out[2] = dot(get_diag(DMat3::from_cols(v, w, probe)), probe);
    out[3] = norm_l1(v) + norm_l2(w);
    out[4] = norm_huber(v, 0.5) + norm_huber(w, x[10]);
    out[5] = norm_pseudo_huber(v, x[10]) + norm_pseudo_huber(w);
    out[6] = dot(smooth_normalize(v, x[10]), probe);
    let (axis, angle) = quat_to_axis_angle(q);
    out[7] = dot(axis, probe) + angle;
    out[8] = dot(quat_rpy(x[0], x[1], x[2]), pq);
    out[9] = dot(quat_to_rpy(normalize(q)), probe);
    out[10] = dot(quat_twist(normalize(w), q), pq);
    out[11] = quat_twist_angle(normalize(w), q) + quat_twist_angle_signed(v, q);
    let m = transform_compose(v, normalize(q), w);
    out[12] = ddot(
        m,
        DMat4::from_cols(
            DVec4::new(0.3, 0.1, -0.2, 0.5),
            DVec4::new(-0.4, 0.7, 0.2, 0.1),
            DVec4::new(0.6, -0.3, 0.9, -0.8),
            DVec4::new(0.2, 0.4, -0.6, 1.0),
        ),
    );
    let (p, r, s) = transform_decompose(m);
    out[13] = dot(p, probe) + dot(r, pq) + dot(s, probe);
}

fn gradcheck_misc(dev: &wp::Device) {
    let xs = [0.7f64, -0.4, 1.3, 0.5, 1.1, -0.8, 0.3, -0.2, 0.6, 0.7, 0.9];
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(14, dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_misc_grad, 1, (&x, &out), dev),
        &[&x],
        &[&out],
        wp::GradcheckOptions::for_type::<f64>(),
    )
    .unwrap();
    assert!(report.passed, "{:?}", report.worst);
    assert!(report.max_rel_error < 1e-6, "{report:?}");
}

/// The outer bound of `k_triangle_const`: a module const, whose type the kernel macro cannot
/// see (the loop variables are then typed by the target compiler).
const TRI_N: i32 = 4;

/// `n` through a func: a result type the kernel macro cannot see either.
#[wp::func]
fn tri_bound(n: i32) -> i32 {
    n
}

/// Nested dynamic loops whose inner bound is the outer loop's variable, carrying a product and
/// a sum: p = prod_{i<n} prod_{j<i} x[j], s = sum_{i<n} sum_{j<i} i x[j], out[t] = p + (t + 1) s.
/// One body, three outer bounds: a parameter, a const and a func's result (with the last two,
/// only the target compiler knows the loop variables' types: the CUDA adjoint could not
/// declare them).
macro_rules! triangle_kernel {
    ($name:ident, $n:ident => $bound:expr) => {
        #[wp::kernel]
        fn $name(x: Array<f64>, $n: i32, out: Array<f64>) {
            let t = tid();
            let mut p: f64 = 1.0;
            let mut s: f64 = 0.0;
            for i in 0..$bound {
                for j in 0..i {
                    p = p * x[j];
                    s += x[j] * (i as f64);
                }
            }
            out[t] = p + s * (t as f64 + 1.0);
        }
    };
}

triangle_kernel!(k_triangle, n => n);
triangle_kernel!(k_triangle_const, n => TRI_N);
triangle_kernel!(k_triangle_func, n => tri_bound(n));

/// Closed form of the triangle kernels' gradient. x[j] appears n - 1 - j times in p, so
/// dp/dx[j] = (n - 1 - j) x[j]^(n - 2 - j) prod_{k != j} x[k]^(n - 1 - k); ds/dx[j] =
/// sum_{i=j+1}^{n-1} i; over `threads` threads, dx[j] = threads dp + threads (threads + 1) / 2 ds.
///
/// Compared exactly: the inputs are binary fractions of a few bits, so every product and sum
/// here and in the adjoint is exactly representable in f64 and any correct evaluation order
/// (or FMA contraction, on CUDA) gives the same bits.
fn nested_dependent_loops(dev: &wp::Device) {
    let xs = [1.5f64, -2.0, 0.5, 3.0, -0.25];
    let n = TRI_N as usize;
    let threads = 3usize;
    let pow = |v: f64, e: i64| if e <= 0 { 1.0 } else { v.powi(e as i32) };
    let want: Vec<f64> = (0..xs.len())
        .map(|j| {
            if j >= n {
                return 0.0;
            }
            let e = (n - 1 - j) as i64;
            let mut dp = e as f64 * pow(xs[j], e - 1);
            for (k, x) in xs.iter().enumerate().take(n) {
                if k != j {
                    dp *= pow(*x, (n - 1 - k) as i64);
                }
            }
            let ds: f64 = ((j + 1)..n).map(|i| i as f64).sum();
            let t = threads as f64;
            t * dp + t * (t + 1.0) / 2.0 * ds
        })
        .collect();
    type Launch = fn(&wp::Array<f64>, &wp::Array<f64>, &wp::Device) -> wp::Result<()>;
    let launches: [(&str, Launch); 3] = [
        ("parameter bound", |x, out, dev| {
            wp::launch(k_triangle, 3, (x, TRI_N, out), dev)
        }),
        ("const bound", |x, out, dev| {
            wp::launch(k_triangle_const, 3, (x, 0, out), dev)
        }),
        ("func bound", |x, out, dev| {
            wp::launch(k_triangle_func, 3, (x, TRI_N, out), dev)
        }),
    ];
    for (what, launch) in launches {
        let x = arr(&xs, dev).with_grad().unwrap();
        let out = zeros::<f64, 1>(threads, dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            launch(&x, &out, dev).unwrap();
        }
        // p = 1.5^3 (-2)^2 0.5 = 6.75; s = 1 x0 + 2 (x0 + x1) + 3 (x0 + x1 + x2) = 0.5.
        let got = out.to_vec().unwrap();
        assert_eq!(got, vec![7.25, 7.75, 8.25], "{what}");
        assert!(backward_ok(dev, tape.backward(&out)));
        assert_eq!(x.grad().unwrap().to_vec().unwrap(), want, "{what}");
    }
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Joint {
    axis: DVec3,
    stiffness: f64,
}

/// A struct with a struct field.
#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Link {
    joint: Joint,
    length: f64,
}

/// A struct with a nested struct field read in a differentiated kernel: whole (`links[i]`),
/// through a copy of the inner struct, by a nested path (`l.joint.axis.z`), and written by a
/// nested path inside a loop (the adjoint stack then holds the outer struct).
/// out = s x^2 + (a.x x + a.y + 2 a.z) L + a.z, with s the stiffness, a the axis, L the length.
#[wp::kernel]
fn k_links(links: Array<Link>, x: Array<f64>, out: Array<f64>) {
    let i = tid();
    let mut l = links[i];
    let j = l.joint;
    for _k in 0..2 {
        l.joint.stiffness = l.joint.stiffness * x[i];
    }
    out[i] =
        l.joint.stiffness + dot(j.axis, DVec3::new(x[i], 1.0, 2.0)) * l.length + l.joint.axis.z;
}

/// Two links whose values are binary fractions of a few bits (exact in any evaluation order).
fn sample_links() -> [Link; 2] {
    [
        Link {
            joint: Joint {
                axis: DVec3::new(0.5, -1.0, 2.0),
                stiffness: 1.5,
            },
            length: 0.75,
        },
        Link {
            joint: Joint {
                axis: DVec3::new(-2.0, 0.25, 1.0),
                stiffness: -0.5,
            },
            length: 3.0,
        },
    ]
}

/// The closed form: d/dx = 2 s x + a.x L, d/ds = x^2, d/da = (x L, L, 2 L + 1),
/// d/dL = a.x x + a.y + 2 a.z. Exact (binary fractions of a few bits: see
/// `nested_dependent_loops`).
fn nested_struct_field_gradient(dev: &wp::Device) {
    let links_h = sample_links();
    let xs = [2.0f64, -0.5];
    let links = arr(&links_h, dev).with_grad().unwrap();
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_links, 2, (&links, &x, &out), dev).unwrap();
    }
    assert!(backward_ok(dev, tape.backward(&out)));
    let (gl, gx) = (
        links.grad().unwrap().to_vec().unwrap(),
        x.grad().unwrap().to_vec().unwrap(),
    );
    for (k, (l, &x)) in links_h.iter().zip(&xs).enumerate() {
        let (a, s, len) = (l.joint.axis, l.joint.stiffness, l.length);
        assert_eq!(gx[k], 2.0 * s * x + a.x * len, "d/dx, thread {k}");
        let want = Link {
            joint: Joint {
                axis: DVec3::new(x * len, len, 2.0 * len + 1.0),
                stiffness: x * x,
            },
            length: a.x * x + a.y + 2.0 * a.z,
        };
        assert_eq!(gl[k], want, "d/dlink, thread {k}");
    }
}

/// Horner's scheme over a dynamic reversed range: sum_{k<n} x[k] t^k.
#[wp::func]
fn horner(x: Array<f64>, n: i32, t: f64) -> f64 {
    let mut acc: f64 = 0.0;
    for k in (0..n).rev() {
        acc = acc * t + x[k];
    }
    acc
}

/// An early `return` from a loop: x[k] level for the first x[k] above `level`, else `level`.
#[wp::func]
fn first_over(x: Array<f64>, n: i32, level: f64) -> f64 {
    for k in 0..n {
        if x[k] > level {
            return x[k] * level;
        }
    }
    level
}

/// Nested loops, the inner one starting at the outer variable: sum_{a<=b<n} x[a] x[b].
#[wp::func]
fn pair_sum(x: Array<f64>, n: i32) -> f64 {
    let mut s: f64 = 0.0;
    for a in 0..n {
        for b in a..n {
            s += x[a] * x[b];
        }
    }
    s
}

/// Funcs with loops, called from a loop of a differentiated kernel whose trip count depends on
/// the thread.
#[wp::kernel]
fn k_func_loops(x: Array<f64>, ts: Array<f64>, n: i32, out: Array<f64>) {
    let i = tid();
    let t = ts[i];
    let mut s: f64 = 0.0;
    for r in 0..(i as i32 + 1) {
        s += horner(x, n - r, t);
    }
    out[i] = s + first_over(x, n, t) + pair_sum(x, n) * t;
}

/// The closed form: for thread i with t = ts[i] and m = n - r, d horner(x, m, t)/dx[k] = t^k
/// (k < m) and /dt = sum_{k<m} k x[k] t^(k-1); first_over gives `level` to the first x[k0]
/// above it and x[k0] to `level` (1 when none is); d pair_sum/dx[k] = sum x + x[k]. Exact
/// (binary fractions of a few bits: see `nested_dependent_loops`).
fn loops_in_funcs_gradient(dev: &wp::Device) {
    let xs = [0.5f64, -1.5, 2.0, 0.25];
    let ts_h = [0.5f64, -1.5, 3.0];
    let n = xs.len();
    let x = arr(&xs, dev).with_grad().unwrap();
    let ts = arr(&ts_h, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_func_loops, 3, (&x, &ts, n as i32, &out), dev).unwrap();
    }
    assert!(backward_ok(dev, tape.backward(&out)));
    let total: f64 = xs.iter().sum();
    let pairs: f64 = (0..n)
        .flat_map(|a| (a..n).map(move |b| (a, b)))
        .map(|(a, b)| xs[a] * xs[b])
        .sum();
    let mut want_x = vec![0.0f64; n];
    let mut want_t = vec![0.0f64; 3];
    for (i, &t) in ts_h.iter().enumerate() {
        for r in 0..=i {
            for k in 0..n - r {
                want_x[k] += t.powi(k as i32);
                if k > 0 {
                    want_t[i] += k as f64 * xs[k] * t.powi(k as i32 - 1);
                }
            }
        }
        match xs.iter().position(|&v| v > t) {
            Some(k0) => {
                want_x[k0] += t;
                want_t[i] += xs[k0];
            }
            None => want_t[i] += 1.0,
        }
        for (k, w) in want_x.iter_mut().enumerate() {
            *w += t * (total + xs[k]);
        }
        want_t[i] += pairs;
    }
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), want_x);
    assert_eq!(ts.grad().unwrap().to_vec().unwrap(), want_t);
}

/// Early exits in nested loops: `continue` in the outer `for`, `break` out of an inner `while`,
/// and a `return` from inside the inner loop that writes its own result first; each thread's
/// cap makes it leave at a different point.
#[wp::kernel]
fn k_nested_exits(x: Array<f64>, caps: Array<f64>, n: i32, out: Array<f64>) {
    let t = tid();
    let cap = caps[t];
    let mut acc: f64 = 1.0;
    for i in 0..n {
        if i % 3 == 1 {
            continue;
        }
        let mut j = 0;
        while j < n {
            if j > i {
                break;
            }
            acc = acc * x[j] + x[i];
            if acc > cap {
                out[t] = acc * 2.0;
                return;
            }
            j += 1;
        }
    }
    out[t] = acc;
}

/// `k_nested_exits` in plain Rust, in forward mode: the value and its derivative with respect
/// to every x[k].
fn nested_exits_reference(x: &[f64], cap: f64) -> (f64, Vec<f64>) {
    let n = x.len();
    let unit = |k: usize| (0..n).map(move |m| if m == k { 1.0 } else { 0.0 });
    let (mut acc, mut d) = (1.0f64, vec![0.0f64; n]);
    for i in 0..n {
        if i % 3 == 1 {
            continue;
        }
        for j in 0..=i {
            // acc = acc x[j] + x[i]
            d = d
                .iter()
                .zip(unit(j).zip(unit(i)))
                .map(|(dacc, (dj, di))| dacc * x[j] + acc * dj + di)
                .collect();
            acc = acc * x[j] + x[i];
            if acc > cap {
                return (acc * 2.0, d.iter().map(|g| g * 2.0).collect());
            }
        }
    }
    (acc, d)
}

/// Against the forward-mode reference, exactly (binary fractions of a few bits, and at most 8
/// steps of `acc x + x`: every value stays exactly representable, see
/// `nested_dependent_loops`). The caps: thread 0 never returns early, thread 1 returns in the
/// third outer iteration, thread 2 at the first step.
fn nested_exits_gradient(dev: &wp::Device) {
    let xs = [1.5f64, -0.5, 2.0, 0.75, -1.25];
    let caps_h = [1e9f64, 5.0, 0.5];
    let x = arr(&xs, dev).with_grad().unwrap();
    let caps = arr(&caps_h, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_nested_exits, 3, (&x, &caps, xs.len() as i32, &out), dev).unwrap();
    }
    let mut want_x = vec![0.0f64; xs.len()];
    let mut want_out = Vec::new();
    for &cap in &caps_h {
        let (v, d) = nested_exits_reference(&xs, cap);
        want_out.push(v);
        for (w, g) in want_x.iter_mut().zip(d) {
            *w += g;
        }
    }
    // Thread 0 runs to the end (acc = 2.4375); thread 1 returns 2 x 6.5 at i = 2, j = 0;
    // thread 2 returns 2 x 3 at i = 0, j = 0.
    assert_eq!(want_out, vec![2.4375, 13.0, 6.0]);
    assert_eq!(out.to_vec().unwrap(), want_out);
    assert!(backward_ok(dev, tape.backward(&out)));
    assert_eq!(x.grad().unwrap().to_vec().unwrap(), want_x);
    assert_eq!(caps.grad().unwrap().to_vec().unwrap(), vec![0.0; 3]);
}

// ------------------------------------------------------------------------------------------
// CUDA adjoints run on the host
// ------------------------------------------------------------------------------------------

/// A launch argument of [`run_adjoint_on_host`].
pub(crate) enum HostArg {
    /// A scalar parameter: its C++ type and value.
    Scalar(&'static str, String),
    /// A built hash grid: its buffers, dims and `1 / cell width`, declared as the
    /// `wp::hash_grid_t` over copies of them.
    HashGrid {
        ids: Vec<i32>,
        starts: Vec<i32>,
        ends: Vec<i32>,
        dims: [usize; 3],
        inv: f32,
    },
    /// An array parameter made of f64 words (f64 elements, or structs of f64 fields): its C++
    /// element type, shape, words per element, values, and gradient before the adjoint runs.
    Array {
        elem: &'static str,
        shape: Vec<usize>,
        words: usize,
        values: Vec<f64>,
        grad: Vec<f64>,
    },
}

impl HostArg {
    /// A built CPU grid, as it is now.
    pub(crate) fn hash_grid(g: &wp::HashGrid) -> Self {
        let (starts, ends) = g.cell_ranges().unwrap();
        HostArg::HashGrid {
            ids: g.point_ids().unwrap().to_vec().unwrap(),
            starts: starts.to_vec().unwrap(),
            ends: ends.to_vec().unwrap(),
            dims: g.dims(),
            inv: 1.0 / g.cell_width().unwrap(),
        }
    }

    fn i32(v: i32) -> Self {
        HostArg::Scalar("wp::i32", v.to_string())
    }

    pub(crate) fn f64(v: f64) -> Self {
        HostArg::Scalar("wp::f64", format!("bits64({:#018x}ULL)", v.to_bits()))
    }

    /// An array with a gradient, as it is now.
    pub(crate) fn array<T: wp::Element + wp::__private::bytemuck::Pod, const N: usize>(
        a: &wp::Array<T, N>,
        elem: &'static str,
    ) -> Self {
        HostArg::Array {
            elem,
            shape: a.shape().to_vec(),
            words: std::mem::size_of::<T>() / 8,
            values: words(a),
            grad: words(&a.grad().unwrap()),
        }
    }
}

/// The elements of an array of f64 words, as f64s.
fn words<T: wp::Element + wp::__private::bytemuck::Pod, const N: usize>(
    a: &wp::Array<T, N>,
) -> Vec<f64> {
    wp::__private::bytemuck::cast_slice::<T, f64>(&a.to_vec().unwrap()).to_vec()
}

/// Runs `info`'s CUDA adjoint unit as host C++ (g++, no FMA contraction) over a 1-D grid of
/// `threads`, one thread after another with a fresh adjoint stack each, and returns the
/// gradients of the array arguments afterwards (as f64 words, in parameter order); `None`
/// without g++. Both variants of the thread function run, each on fresh data: the one a launch
/// whose arrays cover the grid runs (`__FAST`: thread-owned gradients gathered in registers,
/// clears deferred) and the checked one; they must agree.
fn run_adjoint_on_host(
    info: &wp::KernelInfo,
    threads: usize,
    args: &[HostArg],
) -> Option<Vec<Vec<f64>>> {
    use std::fmt::Write as _;
    if std::process::Command::new("g++")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("SKIPPED run_adjoint_on_host: no g++");
        return None;
    }
    let src = wp::cuda_source::assemble_adjoint(info);
    let lit = |v: &[f64]| {
        v.iter()
            .map(|x| format!("bits64({:#018x}ULL)", x.to_bits()))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let (mut decl, mut print) = (String::new(), String::new());
    let (mut params, mut grads) = (Vec::new(), Vec::new());
    for (k, a) in args.iter().enumerate() {
        match a {
            HostArg::Scalar(t, v) => writeln!(decl, "{t} p{k} = {v};").unwrap(),
            HostArg::HashGrid {
                ids,
                starts,
                ends,
                dims,
                inv,
            } => {
                // A trailing 0 in each buffer: C++ has no empty arrays.
                for (name, data) in [("ids", ids), ("starts", starts), ("ends", ends)] {
                    let list: Vec<String> = data.iter().map(|x| x.to_string()).collect();
                    writeln!(
                        decl,
                        "static wp::i32 {name}{k}[] = {{{}, 0}};",
                        list.join(", ")
                    )
                    .unwrap();
                }
                writeln!(
                    decl,
                    "wp::hash_grid_t p{k} = {{ids{k}, starts{k}, ends{k}, {{{}, {}, {}}}, {}, bits32({:#010x}u), {k}}};",
                    dims[0],
                    dims[1],
                    dims[2],
                    ids.len(),
                    inv.to_bits()
                )
                .unwrap();
            }
            HostArg::Array {
                elem,
                shape,
                words,
                values,
                grad,
            } => {
                let n = shape.len();
                let dims = shape.iter().map(|d| d.to_string()).collect::<Vec<_>>();
                // Row-major byte strides.
                let strides: Vec<String> = (0..n)
                    .map(|d| (shape[d + 1..].iter().product::<usize>() * words * 8).to_string())
                    .collect();
                let (dims, strides) = (dims.join(", "), strides.join(", "));
                for (name, data) in [("p", values), ("g", grad)] {
                    writeln!(decl, "static wp::f64 {name}d{k}[] = {{{}}};", lit(data)).unwrap();
                    writeln!(
                        decl,
                        "wp::array_t<{elem}, {n}> {name}{k} = {{({elem}*){name}d{k}, {{{dims}}}, {{{strides}}}, {k}, 0}};"
                    )
                    .unwrap();
                }
                writeln!(
                    print,
                    "for (int e = 0; e < {}; ++e) print_f64(gd{k}[e]);",
                    grad.len()
                )
                .unwrap();
                grads.push(format!("g{k}"));
            }
        }
        params.push(format!("p{k}"));
    }
    params.extend(grads);
    let program = format!(
        "#include <cstring>\n#define WP_ADSTACK_BYTES 4096\n{text}\n\
         static wp::f64 bits64(unsigned long long u) {{ wp::f64 x; memcpy(&x, &u, 8); return x; }}\n\
         static wp::f32 bits32(unsigned u) {{ wp::f32 x; memcpy(&x, &u, 4); return x; }}\n\
         static void print_f64(wp::f64 x) {{ unsigned long long u; memcpy(&u, &x, 8); printf(\"%016llx\\n\", u); }}\n\
         template <bool FAST> static int run() {{\n\
         {decl}\n\
         wp::fault_t fault = {{}}; unsigned int flag = 0;\n\
         wp::launch_ctx_t rec = wp::launch_ctx_make(&fault, &flag);\n\
         wp::ctx_t ctx = wp::ctx_make(&rec);\n\
         wp::launch_t launch = {{{{{threads}, 1, 1, 1}}, {threads}, 1, FAST ? 1 : 0}};\n\
         static char buf[WP_ADSTACK_BYTES];\n\
         wp::adstack_t st = wp::adstack_new(buf, WP_ADSTACK_BYTES);\n\
         for (wp::i64 flat = 0; flat < {threads}; ++flat) {{ st.top = 0; {thread}({params}, launch, flat, &ctx, &st); }}\n\
         if (flag) {{ printf(\"fault %d\\n\", fault.kind); return 1; }}\n\
         {print}\n\
         return 0;\n}}\n\
         int main() {{ if (run<true>()) return 1; printf(\"--\\n\"); return run<false>(); }}\n",
        text = src.text,
        thread = src.thread_fn,
        params = params.join(", "),
    );
    let dir = std::env::temp_dir().join(format!("wp-adj-run-{}-{}", info.name, std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (cpp, exe) = (dir.join("k.cpp"), dir.join("k"));
    std::fs::write(&cpp, program).unwrap();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let out = std::process::Command::new("g++")
        .args([
            "-std=c++17",
            "-O1",
            "-ffp-contract=off",
            "-fno-strict-aliasing",
        ])
        .args(["-Wno-unused", "-DWP_GENERAL_STRIDES", "-I", include])
        .arg(&cpp)
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "g++ failed on {}:\n{}",
        cpp.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let run = std::process::Command::new(&exe).output().unwrap();
    let text = String::from_utf8(run.stdout).unwrap();
    assert!(
        run.status.success(),
        "{}: the adjoint faulted: {text}",
        info.name
    );
    let (fast, checked) = text.split_once("--\n").expect("two runs");
    assert_eq!(
        fast, checked,
        "{}: the __FAST and checked variants disagree",
        info.name
    );
    let _ = std::fs::remove_dir_all(&dir);
    let mut lines = fast
        .lines()
        .map(|l| f64::from_bits(u64::from_str_radix(l, 16).unwrap()));
    Some(
        args.iter()
            .filter_map(|a| match a {
                HostArg::Array { grad, .. } => Some(lines.by_ref().take(grad.len()).collect()),
                HostArg::Scalar(..) | HostArg::HashGrid { .. } => None,
            })
            .collect(),
    )
}

/// One launch of [`cuda_adjoints_run_on_the_host_like_the_cpu`].
struct HostCase {
    info: &'static wp::KernelInfo,
    threads: usize,
    /// The arguments as the adjoint starts (the output's gradient seeded).
    host: Vec<HostArg>,
    /// The CPU backend's gradients of the array arguments after its adjoint.
    cpu: Vec<Vec<f64>>,
}

/// The CUDA adjoints of the kernels above, compiled from their generated CUDA with g++, run
/// over the grid on the host and compared with the CPU backend's gradients, bit for bit (both
/// sides do the same IEEE operations, without FMA contraction; the inputs are binary
/// fractions, so even a different summation order would give the same bits). So CI without a
/// GPU runs the CUDA adjoint of nested dependent loops (over a parameter, a const and a func's
/// bound), nested struct fields, loops in funcs, early exits, custom gradients, funcs' tuple
/// results and `&mut` parameters, and the older loop, branch and func kernels.
#[test]
fn cuda_adjoints_run_on_the_host_like_the_cpu() {
    let dev = wp::cpu();
    let f64s = |v: &[f64]| arr(v, &dev).with_grad().unwrap();
    let outs = |n: usize| zeros::<f64, 1>(n, &dev).with_grad().unwrap();
    let xs = [1.5f64, -2.0, 0.5, 3.0, -0.25];
    // (what, kernel, threads, arguments as the adjoint starts, the CPU's gradients after it).
    let mut cases: Vec<HostCase> = Vec::new();
    // Launches on the CPU under a tape, captures the arguments (the caller seeded the output's
    // gradient), runs the CPU adjoint and captures the gradients.
    macro_rules! case {
        ($k:ident, $threads:expr, ($($arg:expr),*), [$($host:expr),*], [$($grad:expr),*]) => {{
            let tape = wp::Tape::new();
            {
                let _rec = tape.record();
                wp::launch($k, $threads, ($($arg,)*), &dev).unwrap();
            }
            let host = vec![$($host),*];
            tape.backward_from_grads().unwrap();
            cases.push(HostCase {
                info: <$k as wp::Kernel>::info(),
                threads: $threads,
                host,
                cpu: vec![$(words(&$grad.grad().unwrap())),*],
            });
        }};
    }
    // The three triangle kernels: parameter, const and func bounds (k_triangle_const ignores n).
    for (k, n) in [(0, TRI_N), (1, 0), (2, TRI_N)] {
        let (x, out) = (f64s(&xs), outs(3));
        out.grad().unwrap().fill(1.0).unwrap();
        let (hx, hn, hout) = (
            HostArg::array(&x, "wp::f64"),
            HostArg::i32(n),
            HostArg::array(&out, "wp::f64"),
        );
        match k {
            0 => case!(k_triangle, 3, (&x, n, &out), [hx, hn, hout], [x, out]),
            1 => case!(k_triangle_const, 3, (&x, n, &out), [hx, hn, hout], [x, out]),
            _ => case!(k_triangle_func, 3, (&x, n, &out), [hx, hn, hout], [x, out]),
        }
    }
    {
        let links_h = sample_links();
        let links = arr(&links_h, &dev).with_grad().unwrap();
        let (x, out) = (f64s(&[2.0, -0.5]), outs(2));
        out.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_links,
            2,
            (&links, &x, &out),
            [
                HostArg::array(&links, "Link"),
                HostArg::array(&x, "wp::f64"),
                HostArg::array(&out, "wp::f64")
            ],
            [links, x, out]
        );
    }
    {
        let (x, ts, out) = (
            f64s(&[0.5, -1.5, 2.0, 0.25]),
            f64s(&[0.5, -1.5, 3.0]),
            outs(3),
        );
        out.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_func_loops,
            3,
            (&x, &ts, 4, &out),
            [
                HostArg::array(&x, "wp::f64"),
                HostArg::array(&ts, "wp::f64"),
                HostArg::i32(4),
                HostArg::array(&out, "wp::f64")
            ],
            [x, ts, out]
        );
    }
    {
        let (x, caps, out) = (
            f64s(&[1.5, -0.5, 2.0, 0.75, -1.25]),
            f64s(&[1e9, 5.0, 0.5]),
            outs(3),
        );
        out.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_nested_exits,
            3,
            (&x, &caps, 5, &out),
            [
                HostArg::array(&x, "wp::f64"),
                HostArg::array(&caps, "wp::f64"),
                HostArg::i32(5),
                HostArg::array(&out, "wp::f64")
            ],
            [x, caps, out]
        );
    }
    {
        let (x, w, y) = (f64s(&[0.0, 4.0]), f64s(&[2.0, 2.0]), outs(2));
        y.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_custom,
            2,
            (&x, &w, &y),
            [
                HostArg::array(&x, "wp::f64"),
                HostArg::array(&w, "wp::f64"),
                HostArg::array(&y, "wp::f64")
            ],
            [x, w, y]
        );
    }
    {
        let (x, y) = (f64s(&[1.5, -0.5, 2.0]), outs(3));
        y.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_branches,
            3,
            (&x, &y),
            [HostArg::array(&x, "wp::f64"), HostArg::array(&y, "wp::f64")],
            [x, y]
        );
    }
    {
        let (x, y) = (f64s(&[0.75, 3.0, 6.0, -0.5]), outs(4));
        y.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_jumps,
            4,
            (&x, &y),
            [HostArg::array(&x, "wp::f64"), HostArg::array(&y, "wp::f64")],
            [x, y]
        );
    }
    {
        let (x, out) = (f64s(&[0.5, -1.25, 2.0]), outs(3));
        out.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_funcs,
            3,
            (&x, 0.75, &out),
            [
                HostArg::array(&x, "wp::f64"),
                HostArg::f64(0.75),
                HostArg::array(&out, "wp::f64")
            ],
            [x, out]
        );
    }
    {
        let bodies_h = [
            Body {
                pos: DVec3::new(1.0, 2.0, 3.0),
                scale: 0.5,
            },
            Body {
                pos: DVec3::new(-1.0, 0.25, 0.0),
                scale: 2.0,
            },
        ];
        let bodies = arr(&bodies_h, &dev).with_grad().unwrap();
        let m_h: Vec<f64> = (0..9).map(|k| 0.25 * k as f64 - 1.0).collect();
        let m = wp::Array::from_slice_shape(&m_h, (3, 3), &dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let out = outs(2);
        out.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_struct_loops,
            2,
            (&bodies, &m, 3, &out),
            [
                HostArg::array(&bodies, "Body"),
                HostArg::array(&m, "wp::f64"),
                HostArg::i32(3),
                HostArg::array(&out, "wp::f64")
            ],
            [bodies, m, out]
        );
    }
    {
        // A hash grid query in a func, its body reading the neighbours' positions.
        let (x, out, grid) = crate::hash_grid::energy_case(&dev);
        let n = out.len();
        out.grad().unwrap().fill(1.0).unwrap();
        let hg = HostArg::hash_grid(&grid);
        case!(
            k_energy,
            n,
            (&grid, &x, 0.6, &out),
            [
                hg,
                HostArg::array(&x, "wp::f64"),
                HostArg::f64(0.6),
                HostArg::array(&out, "wp::f64")
            ],
            [x, out]
        );
    }
    {
        // Every spatial builtin and operator's adjoint (`spatial::k_spatial_loss`).
        use crate::spatial::k_spatial_loss;
        let n = 3;
        let xs_h: Vec<f64> = (0..n * 12)
            .map(|k| ((k as f64) * 0.83).sin() * 2.0)
            .collect();
        let ms_h: Vec<f64> = (0..18).map(|k| ((k as f64) * 0.731).sin()).collect();
        let tq_h = [0.4, -1.1, 0.7, 0.3, -0.2, 0.5, 0.8];
        let (xs, ms, tq) = (f64s(&xs_h), f64s(&ms_h), f64s(&tq_h));
        let loss = outs(n);
        loss.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_spatial_loss,
            n,
            (&xs, &ms, &tq, &loss),
            [
                HostArg::array(&xs, "wp::f64"),
                HostArg::array(&ms, "wp::f64"),
                HostArg::array(&tq, "wp::f64"),
                HostArg::array(&loss, "wp::f64")
            ],
            [xs, ms, tq, loss]
        );
    }
    {
        // Tuple results and `&mut` parameters of funcs (`refs_tuples::k_refs_grad`).
        use crate::refs_tuples::k_refs_grad;
        let (x, out) = (f64s(&[0.75, -0.5, 1.25]), outs(4));
        out.grad().unwrap().fill(1.0).unwrap();
        case!(
            k_refs_grad,
            1,
            (&x, &out),
            [
                HostArg::array(&x, "wp::f64"),
                HostArg::array(&out, "wp::f64")
            ],
            [x, out]
        );
    }
    for c in &cases {
        let Some(got) = run_adjoint_on_host(c.info, c.threads, &c.host) else {
            return;
        };
        assert_eq!(
            got, c.cpu,
            "{}: the CUDA adjoint on the host against the CPU backend",
            c.info.name
        );
    }
}

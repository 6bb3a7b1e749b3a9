//! Forward mode: `wp::jvp` (a kernel's tangent kernel) against the reverse-mode Jacobian times
//! the direction and against central differences of the kernel; `wp::hvp` (forward over
//! reverse) against central differences of the reverse gradient; what forward mode refuses.
//!
//! Tolerances, with why they fit:
//! - jvp against the reverse Jacobian: both are exact derivatives evaluated with the same
//!   builtins, differing only in the order of a few roundings: f64 relative 1e-12, f32
//!   relative 1e-5 (a few ulps of f32's unit roundoff 6e-8 over ~20 operations, with CUDA's
//!   FMA contraction and transcendental functions, which are a few ulps from the host's).
//! - against central differences with step h: truncation error h^2 |f'''| / 6 plus rounding
//!   u |f| / h. f64 with h = 1e-6: about 1e-10 each, so relative 1e-7 (absolute 1e-9 near 0);
//!   f32 with h = 1e-2 on values of order 1: truncation 1e-4, rounding 6e-6, so 1e-3 relative
//!   with 1e-3 absolute.
//! - hvp against central differences of the reverse gradient, f64, h = 1e-5: truncation
//!   h^2 |f''''| ~ 1e-10, rounding of the gradient 1e-16 / 1e-5 ~ 1e-11: relative 1e-6.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::Error;

backend_tests!(
    jvp_scalar_chain_f64,
    jvp_vectors_f32,
    jvp_loop_accumulator,
    jvp_branches_and_selections,
    jvp_atomic_loss_and_tape,
    jvp_matrices_and_members,
    hvp_scalar_energy,
    hvp_springs_vectors,
    jvp_refuses_what_it_cannot_differentiate,
    jvp_normalize_at_zero,
    jvp_struct_matrix_and_quat_fields,
);

/// `a` close to `b`: `|a - b| <= atol + rtol |b|`, with a message naming `what` and the index.
fn close(what: &str, a: &[f64], b: &[f64], rtol: f64, atol: f64) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    for (k, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(
            (x - y).abs() <= atol + rtol * y.abs(),
            "{what}[{k}]: {x} against {y} (rtol {rtol}, atol {atol})"
        );
    }
}

/// `J v` from a Jacobian's rows.
fn mat_vec(j: &[Vec<f64>], v: &[f64]) -> Vec<f64> {
    j.iter()
        .map(|row| row.iter().zip(v).map(|(a, b)| a * b).sum())
        .collect()
}

fn to64<T: Copy + Into<f64>>(v: &[T]) -> Vec<f64> {
    v.iter().map(|x| (*x).into()).collect()
}

// ---- jvp ----

#[wp::kernel]
fn k_chain(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let t = x[i];
    y[i] = (t * t).sin() * t.ln() + t * t * t / (1.0 - t * t).sqrt();
}

fn jvp_scalar_chain_f64(dev: &wp::Device) {
    let xs = [0.1, 0.3, 0.5, 0.7, 0.9];
    let vs = [1.0, -0.5, 2.0, 0.25, -1.5];
    let n = xs.len();
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(n, dev));
    wp::jvp(k_chain, n, (&x, &y), (&v, &y_dot), dev).unwrap();
    let got = host(&y_dot);

    // The closed form.
    let closed: Vec<f64> = xs
        .iter()
        .zip(&vs)
        .map(|(&t, &v)| {
            let s = (1.0 - t * t).sqrt();
            let d = 2.0 * t * (t * t).cos() * t.ln()
                + (t * t).sin() / t
                + (3.0 * t * t * s + t * t * t * t / s) / (1.0 - t * t);
            d * v
        })
        .collect();
    close("jvp vs closed form", &got, &closed, 1e-12, 1e-14);

    // The reverse-mode Jacobian times v.
    let j = wp::jacobian(|| wp::launch(k_chain, n, (&x, &y), dev), &[&x], &[&y]).unwrap();
    close("jvp vs J v", &got, &mat_vec(&j, &vs), 1e-12, 1e-14);

    // Central differences along v.
    let h = 1e-6;
    let shifted = |s: f64| {
        let xp: Vec<f64> = xs.iter().zip(&vs).map(|(a, b)| a + s * b).collect();
        let (xp, yp) = (arr(&xp, dev), zeros::<f64, 1>(n, dev));
        wp::launch(k_chain, n, (&xp, &yp), dev).unwrap();
        host(&yp)
    };
    let (p, m) = (shifted(h), shifted(-h));
    let fd: Vec<f64> = p.iter().zip(&m).map(|(a, b)| (a - b) / (2.0 * h)).collect();
    close("jvp vs central differences", &got, &fd, 1e-7, 1e-9);
    // The primal ran too.
    let y_ref: Vec<f64> = xs
        .iter()
        .map(|&t| (t * t).sin() * t.ln() + t * t * t / (1.0 - t * t).sqrt())
        .collect();
    close("primal", &host(&y), &y_ref, 1e-14, 0.0);
}

/// Two 3-vectors per thread from a flat array: constructors, cross, dot, length, normalize,
/// length_sq, members, scalar-vector products.
#[wp::kernel]
fn k_vec(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    let a = Vec3::new(x[6 * i], x[6 * i + 1], x[6 * i + 2]);
    let b = Vec3::new(x[6 * i + 3], x[6 * i + 4], x[6 * i + 5]);
    let c = a.cross(b) + a * 0.5;
    let n = (b + Vec3::new(0.3, 0.0, 0.0)).normalize();
    out[2 * i] = c.dot(n) * a.length() + c.length();
    let d = (a - b * 2.0).length_squared() / (1.0 + b.y * b.y);
    out[2 * i + 1] = d + c.x * n.z;
}

fn jvp_vectors_f32(dev: &wp::Device) {
    let xs: Vec<f32> = (0..12)
        .map(|k| 0.3 + 0.17 * k as f32 - 0.02 * (k * k) as f32)
        .collect();
    let vs: Vec<f32> = (0..12).map(|k| ((k * 7 % 5) as f32 - 2.0) * 0.5).collect();
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f32, 1>(4, dev).with_grad().unwrap();
    let (v, out_dot) = (arr(&vs, dev), zeros::<f32, 1>(4, dev));
    wp::jvp(k_vec, 2, (&x, &out), (&v, &out_dot), dev).unwrap();
    let got = to64(&host(&out_dot));

    let j = wp::jacobian(|| wp::launch(k_vec, 2, (&x, &out), dev), &[&x], &[&out]).unwrap();
    close("jvp vs J v", &got, &mat_vec(&j, &to64(&vs)), 1e-5, 1e-5);

    let h = 1e-2f32;
    let shifted = |s: f32| {
        let xp: Vec<f32> = xs.iter().zip(&vs).map(|(a, b)| a + s * b).collect();
        let (xp, op) = (arr(&xp, dev), zeros::<f32, 1>(4, dev));
        wp::launch(k_vec, 2, (&xp, &op), dev).unwrap();
        to64(&host(&op))
    };
    let (p, m) = (shifted(h), shifted(-h));
    let fd: Vec<f64> = p
        .iter()
        .zip(&m)
        .map(|(a, b)| (a - b) / (2.0 * h as f64))
        .collect();
    close("jvp vs central differences", &got, &fd, 1e-3, 1e-3);
}

#[wp::kernel]
fn k_normalize(x: Array<DVec3>, y: Array<DVec3>) {
    let i = tid();
    y[i] = x[i].normalize() * 2.0;
}

/// normalize of the zero vector is zero, and so are its derivatives, in forward mode as in
/// reverse mode (not NaN); elsewhere the tangent is (v - n (n . v)) / |x|. Exact at zero;
/// 1e-14 relative elsewhere (a few f64 roundings).
fn jvp_normalize_at_zero(dev: &wp::Device) {
    let xs = [DVec3::ZERO, DVec3::new(3.0, 0.0, 4.0)];
    let vs = [DVec3::new(1.0, -2.0, 0.5), DVec3::new(0.0, 1.0, 0.0)];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<DVec3, 1>(2, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<DVec3, 1>(2, dev));
    wp::jvp(k_normalize, 2, (&x, &y), (&v, &y_dot), dev).unwrap();
    let got = host(&y_dot);
    assert_eq!(got[0], DVec3::ZERO, "the tangent at the zero vector");
    // At (3, 0, 4): n = (0.6, 0, 0.8), v = (0, 1, 0) is orthogonal to n, so 2 v / 5.
    let want = DVec3::new(0.0, 0.4, 0.0);
    assert!(
        (got[1] - want).length() <= 1e-14,
        "{:?} against {want:?}",
        got[1]
    );
    // Reverse mode agrees at zero.
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_normalize, 2, (&x, &y), dev).unwrap();
    }
    y.grad().unwrap().fill(DVec3::ONE).unwrap();
    tape.backward_from_grads().unwrap();
    assert_eq!(host(&x.grad().unwrap())[0], DVec3::ZERO);
}

/// A loop carrying a value that it reads and overwrites (`acc = acc * t + ..`), a break on an
/// integer condition, and a second array input.
#[wp::kernel]
fn k_horner(x: Array<f64>, c: Array<f64>, n: i32, stop: i32, y: Array<f64>) {
    let i = tid();
    let t = x[i];
    let mut acc: f64 = 1.0;
    for k in 0..n {
        if k == stop {
            break;
        }
        acc = acc * t + c[k] * acc.cos();
        acc += 0.1 * t;
    }
    y[i] = acc;
}

fn jvp_loop_accumulator(dev: &wp::Device) {
    let xs = [0.2, -0.4, 0.6];
    let cs = [0.5, -0.25, 0.75, 1.0, -0.5];
    let (vx, vc) = ([1.0, 0.5, -2.0], [0.3, -0.7, 0.2, 1.1, 0.9]);
    let x = arr(&xs, dev).with_grad().unwrap();
    let c = arr(&cs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let (x_dot, c_dot, y_dot) = (arr(&vx, dev), arr(&vc, dev), zeros::<f64, 1>(3, dev));
    // `n` and `stop` are integers: their tangents are ignored.
    wp::jvp(
        k_horner,
        3,
        (&x, &c, 5, 4, &y),
        (&x_dot, &c_dot, 0, 0, &y_dot),
        dev,
    )
    .unwrap();
    let got = host(&y_dot);

    let j = wp::jacobian(
        || wp::launch(k_horner, 3, (&x, &c, 5, 4, &y), dev),
        &[&x, &c],
        &[&y],
    )
    .unwrap();
    let v: Vec<f64> = vx.iter().chain(&vc).copied().collect();
    close("jvp vs J v", &got, &mat_vec(&j, &v), 1e-12, 1e-14);

    let h = 1e-6;
    let shifted = |s: f64| {
        let xp: Vec<f64> = xs.iter().zip(&vx).map(|(a, b)| a + s * b).collect();
        let cp: Vec<f64> = cs.iter().zip(&vc).map(|(a, b)| a + s * b).collect();
        let (xp, cp, yp) = (arr(&xp, dev), arr(&cp, dev), zeros::<f64, 1>(3, dev));
        wp::launch(k_horner, 3, (&xp, &cp, 5, 4, &yp), dev).unwrap();
        host(&yp)
    };
    let (p, m) = (shifted(h), shifted(-h));
    let fd: Vec<f64> = p.iter().zip(&m).map(|(a, b)| (a - b) / (2.0 * h)).collect();
    close("jvp vs central differences", &got, &fd, 1e-7, 1e-9);
}

/// Branches on the value, an `if` expression, and the selections `abs`, `min`, `max`,
/// `clamp`, `powf`, `exp`.
#[wp::kernel]
fn k_branch(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let t = x[i];
    let mut r: f64 = 0.0;
    if t > 0.5 {
        r = t * t * 3.0;
    } else {
        r = (2.0 * t).exp();
    }
    let s = if t < 0.2 { t.abs() } else { t.max(0.3) };
    y[i] = r + s * t.clamp(0.1, 0.9) + t.min(0.7).powf(1.5) + (t - 0.6).abs();
}

fn jvp_branches_and_selections(dev: &wp::Device) {
    // Away from every switch point (0.1, 0.2, 0.3, 0.5, 0.6, 0.7, 0.9).
    let xs = [0.05, 0.25, 0.35, 0.45, 0.55, 0.65, 0.8, 0.95];
    let vs = [1.0, -1.0, 0.5, 2.0, -0.5, 1.5, -2.0, 0.75];
    let n = xs.len();
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(n, dev));
    wp::jvp(k_branch, n, (&x, &y), (&v, &y_dot), dev).unwrap();
    let got = host(&y_dot);
    let j = wp::jacobian(|| wp::launch(k_branch, n, (&x, &y), dev), &[&x], &[&y]).unwrap();
    close("jvp vs J v", &got, &mat_vec(&j, &vs), 1e-12, 1e-14);
    let h = 1e-6;
    let shifted = |s: f64| {
        let xp: Vec<f64> = xs.iter().zip(&vs).map(|(a, b)| a + s * b).collect();
        let (xp, yp) = (arr(&xp, dev), zeros::<f64, 1>(n, dev));
        wp::launch(k_branch, n, (&xp, &yp), dev).unwrap();
        host(&yp)
    };
    let (p, m) = (shifted(h), shifted(-h));
    let fd: Vec<f64> = p.iter().zip(&m).map(|(a, b)| (a - b) / (2.0 * h)).collect();
    close("jvp vs central differences", &got, &fd, 1e-7, 1e-9);
}

/// A scalar loss accumulated with `atomic_add`.
#[wp::kernel]
fn k_energy(x: Array<f64>, w: Array<f64>, loss: Array<f64>) {
    let i = tid();
    let t = x[i];
    atomic_add(loss, 0, w[i] * t * t * t.sin() + (t * w[i]).cos());
}

fn energy_host(x: &[f64], w: &[f64]) -> f64 {
    x.iter()
        .zip(w)
        .map(|(t, w)| w * t * t * t.sin() + (t * w).cos())
        .sum()
}

fn jvp_atomic_loss_and_tape(dev: &wp::Device) {
    let xs = [0.3, -1.2, 0.8, 2.0];
    let ws = [1.0, 0.5, -0.75, 0.25];
    let vx = [0.5, 1.0, -1.0, 2.0];
    let vw = [0.1, -0.2, 0.3, 0.0];
    let x = arr(&xs, dev).with_grad().unwrap();
    let w = arr(&ws, dev).with_grad().unwrap();
    let loss = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    let (x_dot, w_dot) = (arr(&vx, dev), arr(&vw, dev));
    let loss_dot = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    // Recorded on a tape like a launch.
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::jvp(
            k_energy,
            4,
            (&x, &w, &loss),
            (&x_dot, &w_dot, &loss_dot),
            dev,
        )
        .unwrap();
    }
    assert_eq!(tape.len(), 1);
    let got = host(&loss_dot)[0];
    let j = wp::jacobian(
        || wp::launch(k_energy, 4, (&x, &w, &loss), dev),
        &[&x, &w],
        &[&loss],
    )
    .unwrap();
    let v: Vec<f64> = vx.iter().chain(&vw).copied().collect();
    close("jvp vs J v", &[got], &mat_vec(&j, &v), 1e-12, 1e-14);
    let h = 1e-6;
    let f = |s: f64| {
        let xp: Vec<f64> = xs.iter().zip(&vx).map(|(a, b)| a + s * b).collect();
        let wp_: Vec<f64> = ws.iter().zip(&vw).map(|(a, b)| a + s * b).collect();
        energy_host(&xp, &wp_)
    };
    close(
        "jvp vs central differences",
        &[got],
        &[(f(h) - f(-h)) / (2.0 * h)],
        1e-7,
        1e-9,
    );
    // Backward through the recorded tangent launch from the loss (not its tangent) gives the
    // ordinary gradient: the primal part of the tangent kernel is the kernel.
    x.zero_grad().unwrap();
    w.zero_grad().unwrap();
    tape.backward(&loss).unwrap();
    close(
        "gradient through the tangent launch",
        &host(&x.grad().unwrap()),
        &j[0][..4],
        1e-12,
        1e-14,
    );
}

/// Member writes (`v.y = ..`), matrix construction, inverse, determinant, transpose and
/// columns.
#[wp::kernel]
fn k_mat(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let t = x[i];
    let mut v = DVec3::new(t, 1.0, 2.0);
    v.y = t * t;
    let m = DMat3::from_cols(
        v,
        DVec3::new(0.5, t.sin(), 0.0),
        DVec3::new(0.0, 0.3, 1.0 + t),
    );
    let w = m.inverse() * v;
    y[i] = m.determinant() + w.dot(v) + m.transpose().x_axis.z;
}

fn jvp_matrices_and_members(dev: &wp::Device) {
    let xs = [0.4, 1.1, -0.7];
    let vs = [1.0, -0.5, 0.25];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(3, dev));
    wp::jvp(k_mat, 3, (&x, &y), (&v, &y_dot), dev).unwrap();
    let got = host(&y_dot);
    let j = wp::jacobian(|| wp::launch(k_mat, 3, (&x, &y), dev), &[&x], &[&y]).unwrap();
    // The inverse's rounding (condition numbers near 10 here) on both sides: 1e-11.
    close("jvp vs J v", &got, &mat_vec(&j, &vs), 1e-11, 1e-13);
    let h = 1e-6;
    let shifted = |s: f64| {
        let xp: Vec<f64> = xs.iter().zip(&vs).map(|(a, b)| a + s * b).collect();
        let (xp, yp) = (arr(&xp, dev), zeros::<f64, 1>(3, dev));
        wp::launch(k_mat, 3, (&xp, &yp), dev).unwrap();
        host(&yp)
    };
    let (p, m) = (shifted(h), shifted(-h));
    let fd: Vec<f64> = p.iter().zip(&m).map(|(a, b)| (a - b) / (2.0 * h)).collect();
    close("jvp vs central differences", &got, &fd, 1e-7, 1e-9);
}

// ---- hvp ----

/// The reverse gradient of `k_energy`'s loss with respect to x at `xs`.
fn energy_grad(xs: &[f64], ws: &[f64], dev: &wp::Device) -> Vec<f64> {
    let x = arr(xs, dev).with_grad().unwrap();
    let w = arr(ws, dev);
    let loss = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_energy, xs.len(), (&x, &w, &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    host(&x.grad().unwrap())
}

fn hvp_scalar_energy(dev: &wp::Device) {
    let xs = [0.3, -1.2, 0.8, 2.0];
    let ws = [1.0, 0.5, -0.75, 0.25];
    let vs = [0.5, 1.0, -1.0, 2.0];
    let x = arr(&xs, dev).with_grad().unwrap();
    let w = arr(&ws, dev);
    let loss = zeros::<f64, 1>(1, dev);
    let v = arr(&vs, dev).with_grad().unwrap();
    let (w_dot, loss_dot) = (
        zeros::<f64, 1>(4, dev),
        zeros::<f64, 1>(1, dev).with_grad().unwrap(),
    );
    wp::hvp(
        k_energy,
        4,
        (&x, &w, &loss),
        (&v, &w_dot, &loss_dot),
        &loss_dot,
        dev,
    )
    .unwrap();
    let hv = host(&x.grad().unwrap());

    let h = 1e-5;
    let shifted = |s: f64| -> Vec<f64> {
        let xp: Vec<f64> = xs.iter().zip(&vs).map(|(a, b)| a + s * b).collect();
        energy_grad(&xp, &ws, dev)
    };
    let (p, m) = (shifted(h), shifted(-h));
    let fd: Vec<f64> = p.iter().zip(&m).map(|(a, b)| (a - b) / (2.0 * h)).collect();
    close(
        "hvp vs central differences of the gradient",
        &hv,
        &fd,
        1e-6,
        1e-8,
    );
    // The Hessian is diagonal here: closed form d2/dt2 (w t^2 sin t + cos(t w)).
    let closed: Vec<f64> = xs
        .iter()
        .zip(&ws)
        .zip(&vs)
        .map(|((t, w), v)| {
            let d2 =
                w * (2.0 * t.sin() + 4.0 * t * t.cos() - t * t * t.sin()) - w * w * (t * w).cos();
            d2 * v
        })
        .collect();
    close("hvp vs closed form", &hv, &closed, 1e-12, 1e-13);
    // The direction's gradient is the loss's gradient.
    close(
        "v.grad vs gradient",
        &host(&v.grad().unwrap()),
        &energy_grad(&xs, &ws, dev),
        1e-12,
        1e-14,
    );
}

/// A chain of springs between consecutive points: `k (|p_{i+1} - p_i| - rest)^2`.
#[wp::kernel]
fn k_springs(p: Array<DVec3>, k: f64, rest: f64, loss: Array<f64>) {
    let i = tid();
    let d = p[i + 1] - p[i];
    let stretch = d.length() - rest;
    atomic_add(
        loss,
        0,
        k * stretch * stretch + 0.1 * d.dot(DVec3::new(1.0, 0.0, 0.0)).sin(),
    );
}

fn springs_grad(ps: &[DVec3], dev: &wp::Device) -> Vec<f64> {
    let p = arr(ps, dev).with_grad().unwrap();
    let loss = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_springs, ps.len() - 1, (&p, 3.0, 0.8, &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    host(&p.grad().unwrap())
        .iter()
        .flat_map(|g| g.to_array())
        .collect()
}

fn hvp_springs_vectors(dev: &wp::Device) {
    let ps: Vec<DVec3> = (0..5)
        .map(|i| {
            DVec3::new(
                i as f64 * 0.9,
                (i as f64 * 1.3).sin(),
                0.2 * (i * i) as f64 - 0.5,
            )
        })
        .collect();
    let vs: Vec<DVec3> = (0..5)
        .map(|i| DVec3::new(1.0 - 0.3 * i as f64, 0.5, (i as f64).cos()))
        .collect();
    let p = arr(&ps, dev).with_grad().unwrap();
    let v = arr(&vs, dev).with_grad().unwrap();
    let loss = zeros::<f64, 1>(1, dev);
    let loss_dot = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    // The scalars' tangents: k and rest held fixed (0).
    wp::hvp(
        k_springs,
        4,
        (&p, 3.0, 0.8, &loss),
        (&v, 0.0, 0.0, &loss_dot),
        &loss_dot,
        dev,
    )
    .unwrap();
    let hv: Vec<f64> = host(&p.grad().unwrap())
        .iter()
        .flat_map(|g| g.to_array())
        .collect();
    let h = 1e-5;
    let shifted = |s: f64| {
        let pp: Vec<DVec3> = ps.iter().zip(&vs).map(|(a, b)| *a + *b * s).collect();
        springs_grad(&pp, dev)
    };
    let (a, b) = (shifted(h), shifted(-h));
    let fd: Vec<f64> = a.iter().zip(&b).map(|(a, b)| (a - b) / (2.0 * h)).collect();
    close(
        "hvp vs central differences of the gradient",
        &hv,
        &fd,
        1e-6,
        1e-8,
    );
    close(
        "v.grad vs gradient",
        &host(&v.grad().unwrap())
            .iter()
            .flat_map(|g| g.to_array())
            .collect::<Vec<_>>(),
        &springs_grad(&ps, dev),
        1e-12,
        1e-14,
    );
}

// ---- refusals ----

#[wp::func]
fn twice(x: f32) -> f32 {
    x * 2.0
}

#[wp::kernel]
fn k_quat(q: Array<Quat>, v: Array<Vec3>, out: Array<Vec3>) {
    let i = tid();
    out[i] = quat_rotate(q[i], v[i]);
}

#[wp::kernel]
fn k_calls_func(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = twice(x[i]);
}

/// A func called on a constant is fine: its result has no tangent.
#[wp::kernel]
fn k_func_on_constant(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    out[i] = x[i] * twice(1.5);
}

fn jvp_refuses_what_it_cannot_differentiate(dev: &wp::Device) {
    let q = arr(&[Quat::IDENTITY], dev);
    let v = arr(&[Vec3::X], dev);
    let out = zeros::<Vec3, 1>(1, dev);
    let err = wp::jvp(k_quat, 1, (&q, &v, &out), (&q, &v, &out), dev).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(
            err,
            Error::NoTangent {
                kernel: "k_quat",
                ..
            }
        ),
        "{msg}"
    );
    assert!(
        msg.contains("`quat_rotate`") && msg.contains("line"),
        "{msg}"
    );
    // Nothing ran.
    assert_eq!(host(&out), vec![Vec3::ZERO]);

    let (x, o) = (arr(&[1.0f32], dev), zeros::<f32, 1>(1, dev));
    let err = wp::jvp(k_calls_func, 1, (&x, &o), (&x, &o), dev).unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(
            err,
            Error::NoTangent {
                kernel: "k_calls_func",
                ..
            }
        ),
        "{msg}"
    );
    assert!(msg.contains("func `twice`"), "{msg}");

    let (x_dot, o_dot) = (arr(&[2.0f32], dev), zeros::<f32, 1>(1, dev));
    wp::jvp(k_func_on_constant, 1, (&x, &o), (&x_dot, &o_dot), dev).unwrap();
    assert_eq!(host(&o_dot), vec![6.0]);

    // A tangent array of another shape than its array's.
    let bad = zeros::<f32, 1>(2, dev);
    let err = wp::jvp(k_func_on_constant, 1, (&x, &o), (&bad, &o_dot), dev).unwrap_err();
    assert!(matches!(err, Error::ShapeMismatch { .. }), "{err}");
}

/// A struct of a matrix and a quaternion, constant in the kernel below (`t` fills it to a
/// multiple of the quaternion's 16-byte alignment: kernel structs have no padding).
#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Pose {
    q: Quat,
    m: Mat3,
    t: Vec3,
}

/// Stores a struct parameter's matrix and quaternion fields: values whose type the macro
/// cannot see, with no tangent, so the tangent kernel stores their zero. (That zero was once
/// a splatted literal, which matrices and quaternions do not have: the kernel did not
/// compile.)
#[wp::kernel]
fn k_pose_fields(s: Pose, x: Array<f32>, m: Array<Mat3>, q: Array<Quat>, y: Array<f32>) {
    let i = tid();
    m[i] = s.m;
    q[i] = s.q;
    y[i] = x[i] * x[i];
}

fn jvp_struct_matrix_and_quat_fields(dev: &wp::Device) {
    let pose = Pose {
        q: Quat::from_xyzw(0.0, 0.6, 0.0, 0.8),
        m: Mat3::from_diagonal(Vec3::new(1.0, 2.0, 3.0)),
        t: Vec3::ZERO,
    };
    let x = arr(&[1.5f32, -2.0], dev);
    let (m, q, y) = (
        zeros::<Mat3, 1>(2, dev),
        zeros::<Quat, 1>(2, dev),
        zeros::<f32, 1>(2, dev),
    );
    // Tangent outputs start non-zero: the tangent kernel must overwrite them with zeros.
    let m_dot = arr(&[Mat3::IDENTITY; 2], dev);
    let q_dot = arr(&[Quat::IDENTITY; 2], dev);
    let (x_dot, y_dot) = (arr(&[1.0f32, 0.5], dev), zeros::<f32, 1>(2, dev));
    wp::jvp(
        k_pose_fields,
        2,
        (pose, &x, &m, &q, &y),
        (pose, &x_dot, &m_dot, &q_dot, &y_dot),
        dev,
    )
    .unwrap();
    assert_eq!(host(&m), vec![pose.m; 2]);
    assert_eq!(host(&q), vec![pose.q; 2]);
    assert_eq!(host(&m_dot), vec![Mat3::ZERO; 2]);
    assert_eq!(host(&q_dot), vec![Quat::from_xyzw(0.0, 0.0, 0.0, 0.0); 2]);
    // d(x²) = 2 x dx, exact in f32 here.
    assert_eq!(host(&y_dot), vec![3.0, -2.0]);
}

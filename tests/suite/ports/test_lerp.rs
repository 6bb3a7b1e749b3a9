//! Port of Warp's `warp/tests/test_lerp.py`: `lerp(a, b, t)` over Warp's table of types, the
//! value for each, and for f32 the gradients with respect to `a`, `b` and `t` through a Tape.
//!
//! Ported: `test_lerp` -> [`lerp_f32_values_and_gradients`] (Warp's three f32 cases with
//! their gradients), [`lerp_vectors`] (the `vec2`, `vec3`, `vec4` rows) and
//! [`lerp_transform`] (the `transform` row: lane by lane, the rotation not renormalized, as
//! Warp). Tolerance: Warp's absolute `1e-6` on every value and gradient (values of size <= 8,
//! so at most a few f32 ulps of slack; exact on the CPU).
//!
//! Not ported (rows of Warp's table this language cannot launch yet): `mat22`, `mat33`,
//! `mat44`, `quat`, `spatial_vector` and `spatial_matrix`: `lerp` here takes scalars, float
//! vectors and transforms only (the builtin reference lists the matrix and quaternion
//! overloads as "not yet"; the spatial ones are missing as well).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(lerp_f32_values_and_gradients, lerp_vectors, lerp_transform);

#[track_caller]
fn near(got: &[f32], want: &[f32], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= 1e-6,
            "{what} [lane {k}]: got {g:e}, want {w:e} (Warp's absolute tolerance 1e-6)"
        );
    }
}

#[wp::kernel]
fn k_lerp_f32(a: Array<f32>, b: Array<f32>, t: Array<f32>, out: Array<f32>) {
    out[0] = lerp(a[0], b[0], t[0]);
}

/// Warp's `TEST_DATA[wp.float32]`: (a, b, t, value, d/da, d/db, d/dt).
const F32_CASES: [[f32; 7]; 3] = [
    [1.0, 5.0, 0.75, 4.0, 0.25, 0.75, 4.0],
    [-2.0, 5.0, 0.25, -0.25, 0.75, 0.25, 7.0],
    [1.23, 2.34, 0.5, 1.785, 0.5, 0.5, 1.11],
];

fn lerp_f32_values_and_gradients(dev: &wp::Device) {
    for [a0, b0, t0, want, da, db, dt] in F32_CASES {
        let a = arr(&[a0], dev).with_grad().unwrap();
        let b = arr(&[b0], dev).with_grad().unwrap();
        let t = arr(&[t0], dev).with_grad().unwrap();
        let out = zeros::<f32, 1>(1, dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch(k_lerp_f32, 1, (&a, &b, &t, &out), dev).unwrap();
        }
        let case = format!("lerp({a0}, {b0}, {t0})");
        near(&host(&out), &[want], &case);
        tape.backward(&out).unwrap();
        near(&host(&a.grad().unwrap()), &[da], &format!("d/da of {case}"));
        near(&host(&b.grad().unwrap()), &[db], &format!("d/db of {case}"));
        near(&host(&t.grad().unwrap()), &[dt], &format!("d/dt of {case}"));
    }
}

#[wp::kernel]
fn k_lerp_vec2(a: Array<Vec2>, b: Array<Vec2>, t: Array<f32>, out: Array<Vec2>) {
    out[0] = lerp(a[0], b[0], t[0]);
}

#[wp::kernel]
fn k_lerp_vec3(a: Array<Vec3>, b: Array<Vec3>, t: Array<f32>, out: Array<Vec3>) {
    out[0] = lerp(a[0], b[0], t[0]);
}

#[wp::kernel]
fn k_lerp_vec4(a: Array<Vec4>, b: Array<Vec4>, t: Array<f32>, out: Array<Vec4>) {
    out[0] = lerp(a[0], b[0], t[0]);
}

fn lerp_vectors(dev: &wp::Device) {
    let t = arr(&[0.5f32], dev);
    let out2 = zeros::<Vec2, 1>(1, dev);
    let (a, b) = (Vec2::new(1.0, 2.0), Vec2::new(3.0, 4.0));
    wp::launch(
        k_lerp_vec2,
        1,
        (&arr(&[a], dev), &arr(&[b], dev), &t, &out2),
        dev,
    )
    .unwrap();
    near(&host(&out2)[0].to_array(), &[2.0, 3.0], "vec2");

    let out3 = zeros::<Vec3, 1>(1, dev);
    let (a, b) = (Vec3::new(1.0, 2.0, 3.0), Vec3::new(3.0, 4.0, 5.0));
    wp::launch(
        k_lerp_vec3,
        1,
        (&arr(&[a], dev), &arr(&[b], dev), &t, &out3),
        dev,
    )
    .unwrap();
    near(&host(&out3)[0].to_array(), &[2.0, 3.0, 4.0], "vec3");

    let out4 = zeros::<Vec4, 1>(1, dev);
    let (a, b) = (Vec4::new(1.0, 2.0, 3.0, 4.0), Vec4::new(3.0, 4.0, 5.0, 6.0));
    wp::launch(
        k_lerp_vec4,
        1,
        (&arr(&[a], dev), &arr(&[b], dev), &t, &out4),
        dev,
    )
    .unwrap();
    near(&host(&out4)[0].to_array(), &[2.0, 3.0, 4.0, 5.0], "vec4");
}

#[wp::kernel]
fn k_lerp_transform(
    a: Array<Transform>,
    b: Array<Transform>,
    t: Array<f32>,
    out: Array<Transform>,
) {
    out[0] = lerp(a[0], b[0], t[0]);
}

/// The seven lanes in Warp's order: `p` then `q` as (x, y, z, w).
fn lanes(x: Transform) -> [f32; 7] {
    let (p, q) = (x.p, x.q);
    [p.x, p.y, p.z, q.x, q.y, q.z, q.w]
}

fn lerp_transform(dev: &wp::Device) {
    let a = Transform::new(
        Vec3::new(1.0, 2.0, 3.0),
        Quat::from_xyzw(4.0, 5.0, 6.0, 7.0),
    );
    let b = Transform::new(
        Vec3::new(3.0, 4.0, 5.0),
        Quat::from_xyzw(6.0, 7.0, 8.0, 9.0),
    );
    let out = zeros::<Transform, 1>(1, dev);
    let t = arr(&[0.5f32], dev);
    wp::launch(
        k_lerp_transform,
        1,
        (&arr(&[a], dev), &arr(&[b], dev), &t, &out),
        dev,
    )
    .unwrap();
    near(
        &lanes(host(&out)[0]),
        &[2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0],
        "transform",
    );
}

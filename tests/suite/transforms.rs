//! Rigid transforms (`Transform`, `DTransform`): the builtins of the "transform" section, the
//! operators, fields, arrays of transforms with their gradients, transforms in structs and
//! funcs.
//!
//! Values are checked twice: against the host API (warp-core's `Transform` methods, the same
//! Rust functions the CPU backend calls: bit for bit on the CPU; on CUDA within [`gpu_tol`]),
//! and against references written here from Warp's definitions in f64 (its `quat_rotate`
//! formula for unit quaternions, the textbook Hamilton product, the matrix built column by
//! column) within [`ref_tol`]. The identities (associativity, `t * t⁻¹ = 1`, point versus
//! vector, the matrix round trip) are checked in the kernels' own precision.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    transforms_f64,
    transforms_f32,
    transform_fields_and_arrays,
    transform_struct_field_and_func,
    transform_array_gradients,
);

/// Max over lanes of |got - want| / max(1, max |want|) (normwise: a lane that cancels to near
/// zero carries an error of the size of the terms, about one ulp of the largest lane).
fn normwise(got: &[f64], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    let scale = want.iter().fold(1.0f64, |m, w| m.max(w.abs()));
    got.iter()
        .zip(want)
        .map(|(g, w)| if g == w { 0.0 } else { (g - w).abs() / scale })
        .fold(0.0, f64::max)
}

/// Values as f64 lanes (transforms: p.x, p.y, p.z, q.x, q.y, q.z, q.w).
trait Lanes {
    fn lanes(&self) -> Vec<f64>;
}
impl Lanes for Transform {
    fn lanes(&self) -> Vec<f64> {
        self.to_array().iter().map(|&x| x as f64).collect()
    }
}
impl Lanes for DTransform {
    fn lanes(&self) -> Vec<f64> {
        self.to_array().to_vec()
    }
}
impl Lanes for Vec3 {
    fn lanes(&self) -> Vec<f64> {
        self.as_dvec3().to_array().to_vec()
    }
}
impl Lanes for DVec3 {
    fn lanes(&self) -> Vec<f64> {
        self.to_array().to_vec()
    }
}
impl Lanes for Quat {
    fn lanes(&self) -> Vec<f64> {
        self.as_dquat().to_array().to_vec()
    }
}
impl Lanes for DQuat {
    fn lanes(&self) -> Vec<f64> {
        self.to_array().to_vec()
    }
}
impl Lanes for Mat4 {
    fn lanes(&self) -> Vec<f64> {
        self.as_dmat4().to_cols_array().to_vec()
    }
}
impl Lanes for DMat4 {
    fn lanes(&self) -> Vec<f64> {
        self.to_cols_array().to_vec()
    }
}

/// Backend parity, normwise: 0 on the CPU (the kernel runs the host's own Rust functions);
/// on CUDA, FMA contraction changes roundings: each lane here is at most ~20 roundings of
/// values of size <= 4, so 2e-6 (f32, eps 6e-8) and 1e-14 (f64, eps 1.1e-16) with margin.
fn gpu_tol(dev: &wp::Device, f32: bool) -> f64 {
    match (dev.is_cpu(), f32) {
        (true, _) => 0.0,
        (false, true) => 2e-6,
        (false, false) => 1e-14,
    }
}

/// Against the f64 references of Warp's definitions: the same bound as [`gpu_tol`] on the
/// GPU (at most ~20 roundings per lane of values of size <= 4, and the references' own
/// roundings): 2e-6 for f32 results, 1e-13 for f64 (a factor 10 over the rounding bound: the
/// references use Warp's rotation formula, not glam's, so the roundings differ too).
fn ref_tol(f32: bool) -> f64 {
    if f32 {
        2e-6
    } else {
        1e-13
    }
}

#[track_caller]
fn close(got: &dyn Lanes, want: &dyn Lanes, tol: f64, what: &str) {
    let (g, w) = (got.lanes(), want.lanes());
    let d = normwise(&g, &w);
    assert!(d <= tol, "{what}: got {g:?}, want {w:?} ({d:e} > {tol:e})");
}

/// [`close`] relative to `scale` instead of the result's size: for results that cancel (the
/// translation of `t * t⁻¹` is `|p|`-sized terms summing to 0, so its error is `|p|`-sized).
#[track_caller]
fn close_at(got: &dyn Lanes, want: &dyn Lanes, tol: f64, scale: f64, what: &str) {
    let (g, w) = (got.lanes(), want.lanes());
    let d = g
        .iter()
        .zip(&w)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max)
        / scale.max(1.0);
    assert!(
        d <= tol,
        "{what}: got {g:?}, want {w:?} ({d:e} > {tol:e} at scale {scale})"
    );
}

// ----- f64 references from Warp's definitions -----

/// Warp's `quat_rotate` (unit q): `v (2w² - 1) + (b × v) 2w + b (2 b·v)`.
fn rot(q: DQuat, v: DVec3) -> DVec3 {
    let b = DVec3::new(q.x, q.y, q.z);
    v * (2.0 * q.w * q.w - 1.0) + b.cross(v) * (2.0 * q.w) + b * (2.0 * b.dot(v))
}

/// The Hamilton product, textbook form.
fn ham(a: DQuat, b: DQuat) -> DQuat {
    let (va, vb) = (DVec3::new(a.x, a.y, a.z), DVec3::new(b.x, b.y, b.z));
    let v = vb * a.w + va * b.w + va.cross(vb);
    DQuat::from_xyzw(v.x, v.y, v.z, a.w * b.w - va.dot(vb))
}

fn conj(q: DQuat) -> DQuat {
    DQuat::from_xyzw(-q.x, -q.y, -q.z, q.w)
}

/// Warp's `transform_multiply`.
fn compose(a: DTransform, b: DTransform) -> DTransform {
    DTransform::new(rot(a.q, b.p) + a.p, ham(a.q, b.q))
}

/// Warp's `transform_inverse`.
fn inv(t: DTransform) -> DTransform {
    let qi = conj(t.q);
    DTransform::new(-rot(qi, t.p), qi)
}

/// Warp's `transform_to_matrix` (columns: the rotated axes, then p).
fn matrix(t: DTransform) -> DMat4 {
    DMat4::from_cols(
        rot(t.q, DVec3::X).extend(0.0),
        rot(t.q, DVec3::Y).extend(0.0),
        rot(t.q, DVec3::Z).extend(0.0),
        t.p.extend(1.0),
    )
}

fn lanewise(a: DTransform, b: DTransform, f: impl Fn(f64, f64) -> f64) -> DTransform {
    let (x, y) = (a.to_array(), b.to_array());
    DTransform::from_array(std::array::from_fn(|k| f(x[k], y[k])))
}

/// Transforms with unit rotations (as rigid motions have; rounded to f32 for the f32 tests,
/// where |q|² - 1 is then a few 1e-8, within the f32 tolerance), translations of size <= 5.2.
fn inputs() -> Vec<(DTransform, DTransform, DTransform, DVec3)> {
    let r = |k: f64| ((k * 12.9898).sin() * 43758.5453).fract() * 2.0 - 1.0;
    let xf = |k: f64| {
        let q = DQuat::from_xyzw(r(k), r(k + 1.0), r(k + 2.0), r(k + 3.0)).normalize();
        let p = DVec3::new(r(k + 4.0) * 3.0, r(k + 5.0) * 3.0, r(k + 6.0) * 3.0);
        DTransform::new(p, q)
    };
    let mut v: Vec<_> = (0..6)
        .map(|i| {
            let k = i as f64 * 17.0;
            (
                xf(k),
                xf(k + 7.0),
                xf(k + 31.0),
                DVec3::new(r(k + 50.0), r(k + 51.0), r(k + 52.0)),
            )
        })
        .collect();
    // The identity, and a half turn about x (w = 0).
    v.push((
        DTransform::IDENTITY,
        DTransform::new(
            DVec3::new(1.0, -2.0, 0.5),
            DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0),
        ),
        DTransform::new(DVec3::Z, DQuat::IDENTITY),
        DVec3::new(0.5, 0.25, -1.0),
    ));
    v
}

/// One kernel body for both precisions: every transform builtin, operator and spelling.
macro_rules! xform_kernel {
    ($name:ident, $x:ident, $v3:ident, $q:ident, $m4:ident, $s:ident) => {
        #[wp::kernel]
        pub(crate) fn $name(
            a: Array<$x>,
            b: Array<$x>,
            c: Array<$x>,
            x: Array<$v3>,
            s: $s,
            to: Array<$x, 2>,
            vo: Array<$v3, 2>,
            mo: Array<$m4, 2>,
            qo: Array<$q, 2>,
        ) {
            let i = tid();
            let ta = a[i];
            let tb = b[i];
            let tc = c[i];
            let v = x[i];
            to[(i, 0)] = ta * tb;
            to[(i, 1)] = transform_multiply(ta, tb);
            to[(i, 2)] = ta.inverse();
            to[(i, 3)] = transform_inverse(ta);
            to[(i, 4)] = inverse(ta);
            to[(i, 5)] = $x::new(v, tb.q);
            to[(i, 6)] = transformation(ta.p, tb.q);
            to[(i, 7)] = $x::IDENTITY;
            to[(i, 8)] = ta + tb;
            to[(i, 9)] = ta - tb;
            to[(i, 10)] = ta * s;
            to[(i, 11)] = 2.0 * ta;
            to[(i, 12)] = -ta;
            to[(i, 13)] = lerp(ta, tb, 0.25);
            to[(i, 14)] = ta.lerp(tb, s);
            to[(i, 15)] = $x::from_matrix(transform_to_matrix(ta));
            to[(i, 16)] = transform_from_matrix(mo[(i, 1)]);
            // Identities.
            to[(i, 17)] = (ta * tb) * tc;
            to[(i, 18)] = ta * (tb * tc);
            to[(i, 19)] = ta * ta.inverse();
            to[(i, 20)] = ta.inverse() * ta;
            vo[(i, 0)] = transform_point(ta, v);
            vo[(i, 1)] = ta.transform_point(v);
            vo[(i, 2)] = transform_vector(ta, v);
            vo[(i, 3)] = ta.transform_vector(v);
            vo[(i, 4)] = transform_get_translation(ta);
            vo[(i, 5)] = ta.p;
            let m = transform_to_matrix(ta);
            vo[(i, 6)] = transform_point(m, v);
            vo[(i, 7)] = m.transform_point3(v);
            vo[(i, 8)] = transform_vector(m, v);
            vo[(i, 9)] = m.transform_vector3(v);
            vo[(i, 10)] = ta.transform_point($v3::ZERO);
            vo[(i, 11)] = ta.transform_vector($v3::ZERO);
            vo[(i, 12)] = ta.transform_point(v) - ta.transform_vector(v);
            mo[(i, 0)] = m;
            mo[(i, 2)] = transform_to_matrix(ta * tb);
            mo[(i, 3)] = transform_to_matrix(ta) * transform_to_matrix(tb);
            qo[(i, 0)] = transform_get_rotation(ta);
            qo[(i, 1)] = ta.q;
            if ta == ta && ta != tb {
                qo[(i, 2)] = $q::IDENTITY;
            }
        }
    };
}
xform_kernel!(k_xform64, DTransform, DVec3, DQuat, DMat4, f64);
xform_kernel!(k_xform32, Transform, Vec3, Quat, Mat4, f32);

/// Runs a `xform_kernel!` and checks it: `$cast` maps the f64 inputs to the kernel's types,
/// `$up` a kernel transform to f64.
macro_rules! xform_test {
    ($dev:expr, $kernel:ident, $x:ident, $v3:ident, $q:ident, $m4:ident, $s:ident, $f32:expr,
     $cast:expr, $castv:expr, $up:expr) => {{
        let dev: &wp::Device = $dev;
        let cast: fn(DTransform) -> $x = $cast;
        let castv: fn(DVec3) -> $v3 = $castv;
        let up: fn($x) -> DTransform = $up;
        let ins = inputs();
        let n = ins.len();
        let ta: Vec<$x> = ins.iter().map(|t| cast(t.0)).collect();
        let tb: Vec<$x> = ins.iter().map(|t| cast(t.1)).collect();
        let tc: Vec<$x> = ins.iter().map(|t| cast(t.2)).collect();
        let xs: Vec<$v3> = ins.iter().map(|t| castv(t.3)).collect();
        let s: $s = 0.625;
        let (to, vo) = (zeros::<$x, 2>((n, 21), dev), zeros::<$v3, 2>((n, 13), dev));
        let (mo, qo) = (zeros::<$m4, 2>((n, 4), dev), zeros::<$q, 2>((n, 3), dev));
        // mo[(i, 1)]: a rigid-motion matrix for transform_from_matrix.
        let mut m_in = host(&mo);
        for i in 0..n {
            m_in[i * 4 + 1] = tb[i].to_matrix();
        }
        let mo = wp::Array::<$m4, 2>::from_slice_shape(&m_in, [n, 4], dev).unwrap();
        wp::launch(
            $kernel,
            n,
            (
                &arr(&ta, dev),
                &arr(&tb, dev),
                &arr(&tc, dev),
                &arr(&xs, dev),
                s,
                &to,
                &vo,
                &mo,
                &qo,
            ),
            dev,
        )
        .unwrap();
        let (to, vo, mo, qo) = (host(&to), host(&vo), host(&mo), host(&qo));
        let (gt, rt) = (gpu_tol(dev, $f32), ref_tol($f32));
        for i in 0..n {
            let (a, b, c, v) = (ta[i], tb[i], tc[i], xs[i]);
            let (da, db) = (up(a), up(b));
            let l = v.lanes();
            let dv = DVec3::new(l[0], l[1], l[2]);
            let t = |k: usize| to[i * 21 + k];
            let vv = |k: usize| vo[i * 13 + k];
            let w = format!("row {i}");
            // Host API (bit for bit on the CPU) and the f64 references.
            let cases: Vec<(usize, $x, DTransform, &str)> = vec![
                (0, a * b, compose(da, db), "a * b"),
                (1, a * b, compose(da, db), "transform_multiply"),
                (2, a.inverse(), inv(da), "a.inverse()"),
                (3, a.inverse(), inv(da), "transform_inverse"),
                (4, a.inverse(), inv(da), "inverse"),
                (8, a + b, lanewise(da, db, |x, y| x + y), "a + b"),
                (9, a - b, lanewise(da, db, |x, y| x - y), "a - b"),
                (10, a * s, lanewise(da, da, |x, _| x * 0.625), "a * s"),
                (11, a * 2.0, lanewise(da, da, |x, _| x * 2.0), "2 * a"),
                (12, -a, lanewise(da, da, |x, _| -x), "-a"),
                (
                    13,
                    a.lerp(b, 0.25),
                    lanewise(da, db, |x, y| x * 0.75 + y * 0.25),
                    "lerp",
                ),
                (
                    14,
                    a.lerp(b, s),
                    lanewise(da, db, |x, y| x * 0.375 + y * 0.625),
                    "a.lerp",
                ),
            ];
            for (k, host_v, reference, what) in cases {
                close(&t(k), &host_v, gt, &format!("{what} vs host, {w}"));
                close(
                    &up(t(k)),
                    &reference,
                    rt,
                    &format!("{what} vs Warp's definition, {w}"),
                );
            }
            // Exact ones.
            assert_eq!(t(5), $x::new(v, b.q), "Transform::new, {w}");
            assert_eq!(t(6), $x::new(a.p, b.q), "transformation, {w}");
            assert_eq!(t(7), $x::IDENTITY, "IDENTITY");
            assert_eq!((vv(4), vv(5)), (a.p, a.p), "translation, {w}");
            assert_eq!((qo[i * 3], qo[i * 3 + 1]), (a.q, a.q), "rotation, {w}");
            assert_eq!(vv(10), a.p, "transform_point(t, 0) is t.p, {w}");
            assert_eq!(vv(11), $v3::ZERO, "transform_vector(t, 0) is 0, {w}");
            assert_eq!(qo[i * 3 + 2], $q::IDENTITY, "== and !=, {w}");
            // The matrix round trip gives q or -q (the same rotation).
            for (k, want, what) in [
                (15, a, "from_matrix(to_matrix(a))"),
                (16, b, "transform_from_matrix"),
            ] {
                let got = up(t(k));
                let dw = up(want);
                let sgn = if got.q.dot(dw.q) < 0.0 { -1.0 } else { 1.0 };
                close(
                    &DTransform::new(got.p, got.q * sgn),
                    &dw,
                    rt,
                    &format!("{what}, {w}"),
                );
                close(
                    &t(k),
                    &$x::from_matrix(want.to_matrix()),
                    gt,
                    &format!("{what} vs host, {w}"),
                );
            }
            // Associativity and the inverse round trip (the identity up to the sign of q).
            close(
                &up(t(17)),
                &up(t(18)),
                rt,
                &format!("(a * b) * c = a * (b * c), {w}"),
            );
            for k in [19, 20] {
                let id = up(t(k));
                let id = DTransform::new(id.p, id.q * id.q.w.signum());
                let scale = da.p.length();
                close_at(
                    &id,
                    &DTransform::IDENTITY,
                    rt,
                    scale,
                    &format!("a * a⁻¹ = 1 (#{k}), {w}"),
                );
            }
            let pv = [
                (0, a.transform_point(v), da.p + rot(da.q, dv)),
                (1, a.transform_point(v), da.p + rot(da.q, dv)),
                (2, a.transform_vector(v), rot(da.q, dv)),
                (3, a.transform_vector(v), rot(da.q, dv)),
                (
                    6,
                    a.to_matrix().transform_point3(v),
                    (matrix(da) * dv.extend(1.0)).truncate(),
                ),
                (
                    7,
                    a.to_matrix().transform_point3(v),
                    (matrix(da) * dv.extend(1.0)).truncate(),
                ),
                (
                    8,
                    a.to_matrix().transform_vector3(v),
                    (matrix(da) * dv.extend(0.0)).truncate(),
                ),
                (
                    9,
                    a.to_matrix().transform_vector3(v),
                    (matrix(da) * dv.extend(0.0)).truncate(),
                ),
                (12, a.transform_point(v) - a.transform_vector(v), da.p),
            ];
            for (k, host_v, reference) in pv {
                close(
                    &vv(k),
                    &host_v,
                    gt,
                    &format!("vector output #{k} vs host, {w}"),
                );
                close(
                    &vv(k),
                    &reference,
                    rt,
                    &format!("vector output #{k} vs Warp's definition, {w}"),
                );
            }
            close(
                &mo[i * 4],
                &a.to_matrix(),
                gt,
                &format!("transform_to_matrix vs host, {w}"),
            );
            close(
                &mo[i * 4],
                &matrix(da),
                rt,
                &format!("transform_to_matrix vs Warp's, {w}"),
            );
            close(
                &mo[i * 4 + 2],
                &mo[i * 4 + 3],
                rt,
                &format!("matrix of a * b, {w}"),
            );
            let _ = c;
        }
    }};
}

fn transforms_f64(dev: &wp::Device) {
    xform_test!(
        dev,
        k_xform64,
        DTransform,
        DVec3,
        DQuat,
        DMat4,
        f64,
        false,
        |t| t,
        |v| v,
        |t| t
    );
}

fn transforms_f32(dev: &wp::Device) {
    xform_test!(
        dev,
        k_xform32,
        Transform,
        Vec3,
        Quat,
        Mat4,
        f32,
        true,
        |t| t.as_transform(),
        |v| v.as_vec3(),
        |t| t.as_dtransform()
    );
}

// ----- fields, arrays, struct fields, funcs -----

#[wp::kernel]
fn k_xform_fields(ts: Array<Transform, 2>, shift: Vec3, spin: Transform, out: Array<Transform, 2>) {
    let (i, j) = tid();
    let mut t = ts[(i, j)];
    t.p += shift;
    t.p.x = t.p.x * 2.0;
    t.q = spin.q * t.q;
    out[(i, j)] = t;
    out[(i, j)].p.z = 7.0;
    ts[(i, j)].q = Quat::IDENTITY;
}

/// Field reads and writes (nested, compound, on locals and on array elements), 2-D arrays of
/// transforms and a transform parameter: exact on the CPU, `gpu_tol` on CUDA (the one
/// quaternion product).
fn transform_fields_and_arrays(dev: &wp::Device) {
    let ins = inputs();
    let t0: Vec<Transform> = ins.iter().take(6).map(|t| t.0.as_transform()).collect();
    let ts = wp::Array::<Transform, 2>::from_slice_shape(&t0, [2, 3], dev).unwrap();
    let out = zeros::<Transform, 2>((2, 3), dev);
    let spin = ins[1].1.as_transform();
    let shift = Vec3::new(0.5, -1.0, 2.0);
    wp::launch(k_xform_fields, (2, 3), (&ts, shift, spin, &out), dev).unwrap();
    let (got, after) = (host(&out), host(&ts));
    for (k, t) in t0.iter().enumerate() {
        let mut w = *t;
        w.p += shift;
        w.p.x *= 2.0;
        w.q = spin.q * w.q;
        w.p.z = 7.0;
        close(&got[k], &w, gpu_tol(dev, true), &format!("element {k}"));
        assert_eq!(
            after[k],
            Transform::new(t.p, Quat::IDENTITY),
            "ts[{k}].q = .."
        );
    }
}

/// A transform as a struct field (the struct has no padding: 32 + 12 + 4 bytes).
#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
pub(crate) struct Body {
    pose: Transform,
    vel: Vec3,
    mass: f32,
}

#[wp::func]
fn drift(b: Body, dt: f32) -> Transform {
    let dp = Transform::new(b.vel * dt, Quat::IDENTITY);
    dp * b.pose
}

#[wp::func]
fn apply(t: Transform, x: Vec3) -> Vec3 {
    t.transform_point(x)
}

#[wp::kernel]
pub(crate) fn k_bodies(bodies: Array<Body>, dt: f32, out: Array<Transform>, tip: Array<Vec3>) {
    let i = tid();
    let b = bodies[i];
    out[i] = drift(b, dt);
    let mut c = b;
    c.pose = out[i];
    c.mass = b.mass * 2.0;
    bodies[i] = c;
    tip[i] = apply(c.pose, Vec3::X);
}

fn transform_struct_field_and_func(dev: &wp::Device) {
    let ins = inputs();
    let bodies: Vec<Body> = ins
        .iter()
        .map(|t| Body {
            pose: t.0.as_transform(),
            vel: t.3.as_vec3(),
            mass: 1.5,
        })
        .collect();
    let n = bodies.len();
    let (arr_b, out, tip) = (
        arr(&bodies, dev),
        zeros::<Transform, 1>(n, dev),
        zeros::<Vec3, 1>(n, dev),
    );
    wp::launch(k_bodies, n, (&arr_b, 0.25f32, &out, &tip), dev).unwrap();
    let (got_b, got_t, got_tip) = (host(&arr_b), host(&out), host(&tip));
    for (k, b) in bodies.iter().enumerate() {
        let want = Transform::new(b.vel * 0.25, Quat::IDENTITY) * b.pose;
        close(&got_t[k], &want, gpu_tol(dev, true), &format!("drift {k}"));
        assert_eq!(got_b[k].pose, got_t[k], "struct field written back {k}");
        assert_eq!(
            (got_b[k].vel, got_b[k].mass),
            (b.vel, 3.0),
            "other fields {k}"
        );
        close(
            &got_tip[k],
            &got_t[k].transform_point(Vec3::X),
            gpu_tol(dev, true),
            &format!("func on a field {k}"),
        );
    }
}

// ----- gradients of arrays of transforms -----

#[wp::kernel]
pub(crate) fn k_xform_loss(ts: Array<Transform>, xs: Array<Vec3>, w: Vec3, loss: Array<f32>) {
    let i = tid();
    let y = ts[i].transform_point(xs[i]);
    atomic_add(loss, 0, dot(y, w));
}

/// `loss = Σ dot(transform_point(t_i, x_i), w)` through a Tape: `d loss / d t_i.p = w`
/// exactly; the rotation and point gradients are warp-core's `adj_transform_point` (bit for
/// bit on the CPU; `gpu_tol` on CUDA); the padding lane of the gradient stays zero.
fn transform_array_gradients(dev: &wp::Device) {
    let ins = inputs();
    let t0: Vec<Transform> = ins.iter().map(|t| t.0.as_transform()).collect();
    let x0: Vec<Vec3> = ins.iter().map(|t| t.3.as_vec3()).collect();
    let n = t0.len();
    let ts = arr(&t0, dev).with_grad().unwrap();
    let xs = arr(&x0, dev).with_grad().unwrap();
    let loss = zeros::<f32, 1>(1, dev).with_grad().unwrap();
    let w = Vec3::new(0.3, -0.7, 1.1);
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_xform_loss, n, (&ts, &xs, w, &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    let (gt, gx) = (host(&ts.grad().unwrap()), host(&xs.grad().unwrap()));
    let raw: &[u32] = wp::__private::bytemuck::cast_slice(&gt);
    for k in 0..n {
        use wp::__private::adjoint::{adj_transform_point, Adjoint};
        let (mut at, mut ax) = (Transform::adj_zero(), Vec3::ZERO);
        adj_transform_point(t0[k], x0[k], &mut at, &mut ax, w);
        assert_eq!(gt[k].p, w, "d loss / d p, element {k}");
        close(
            &gt[k].q,
            &at.q,
            gpu_tol(dev, true),
            &format!("d loss / d q, element {k}"),
        );
        close(
            &gx[k],
            &ax,
            gpu_tol(dev, true),
            &format!("d loss / d x, element {k}"),
        );
        assert_eq!(
            raw[k * 8 + 3],
            0,
            "padding lane of the gradient, element {k}"
        );
    }
}

//! Lanes at run-time indices, as Warp code writes them (`v[i]`, `m[i, j]`, here `m[(i, j)]`):
//! a matrix-vector product and a transpose by loops against glam's, every vector type and
//! quaternions read and written lane by lane, spatial vectors and matrices, lanes of struct
//! fields, array elements and a func's `&mut` parameter, the fault of an index outside the
//! lanes, and derivatives (reverse mode against closed forms, forward mode against reverse).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::FaultKind;

backend_tests!(
    matvec_and_transpose_by_loops,
    every_vector_type,
    spatial_lanes,
    places_with_lanes,
    lanes_in_a_tiled_kernel,
    index_out_of_range_faults,
    gradients_route_lane_by_lane,
    gradient_of_a_quadratic_form,
    jvp_matches_the_gradient,
);

/// `y = m x` and `t = mᵀ` by loops over lanes, Warp's way.
#[wp::kernel]
fn k_matvec(m: Array<Mat3>, x: Array<Vec3>, y: Array<Vec3>, t: Array<Mat3>) {
    let i = tid();
    let a = m[i];
    let v = x[i];
    let mut r = Vec3::ZERO;
    let mut tr = Mat3::ZERO;
    for row in 0..3 {
        for col in 0..3 {
            r[row] += a[(row, col)] * v[col];
            tr[(col, row)] = a[(row, col)];
        }
    }
    y[i] = r;
    t[i] = tr;
}

/// glam's `m * x` sums the columns scaled by `x`'s lanes in order, lane by lane the same
/// roundings as the loop's `((0 + a0 x0) + a1 x1) + a2 x2` (`0 + p` is `p`): bit-exact on the
/// CPU; CUDA may contract into FMAs (`fma_rel`). The transpose moves values: exact everywhere.
fn matvec_and_transpose_by_loops(dev: &wp::Device) {
    let ms: Vec<Mat3> = (0..5)
        .map(|k| {
            Mat3::from_cols_array(&core::array::from_fn(|e| {
                ((k * 9 + e) as f32 * 0.37).sin() * 3.0
            }))
        })
        .collect();
    let xs: Vec<Vec3> = (0..5)
        .map(|k| Vec3::new(k as f32 * 0.5 - 1.0, 0.25, -(k as f32) * 1.5))
        .collect();
    let (y, t) = (zeros::<Vec3, 1>(5, dev), zeros::<Mat3, 1>(5, dev));
    wp::launch(k_matvec, 5, (&arr(&ms, dev), &arr(&xs, dev), &y, &t), dev).unwrap();
    let rel = crate::fma_rel(dev);
    for (k, (got, tr)) in host(&y).iter().zip(host(&t)).enumerate() {
        let want = ms[k] * xs[k];
        for l in 0..3 {
            crate::assert_close_f32(got[l], want[l], rel, "m x by loops");
        }
        assert_eq!(tr, ms[k].transpose());
    }
}

/// Every vector type and quaternions: lane `k` read, written and updated (`+=`), the others
/// kept.
#[wp::kernel]
fn k_vectors(
    k: Array<i32>,
    a: Array<Vec2>,
    b: Array<DVec4>,
    c: Array<IVec3>,
    d: Array<UVec4>,
    q: Array<Quat>,
    lanes: Array<f64>,
) {
    let i = tid();
    let j = k[i];
    let mut va = a[i];
    let mut vb = b[i];
    let mut vc = c[i];
    let mut vd = d[i];
    let mut vq = q[i];
    lanes[i] = va[j % 2] as f64 + vb[j] + vc[j % 3] as f64 + vd[j] as f64 + vq[j] as f64;
    va[j % 2] = 10.0;
    vb[j] += 0.5;
    vc[j % 3] *= -3;
    vd[j] -= 1;
    vq[j] = vq[j] * 2.0;
    a[i] = va;
    b[i] = vb;
    c[i] = vc;
    d[i] = vd;
    q[i] = vq;
}

fn every_vector_type(dev: &wp::Device) {
    let ks = [0i32, 1, 2, 3];
    let a0: Vec<Vec2> = (0..4).map(|k| Vec2::new(k as f32, -1.0)).collect();
    let b0: Vec<DVec4> = (0..4)
        .map(|k| DVec4::new(1.0, 2.0, 3.0, k as f64))
        .collect();
    let c0: Vec<IVec3> = (0..4).map(|k| IVec3::new(k, 5, -7)).collect();
    let d0: Vec<UVec4> = (0..4).map(|k| UVec4::new(9, 8, 7, k as u32 + 1)).collect();
    let q0: Vec<Quat> = (0..4)
        .map(|k| Quat::from_xyzw(0.5, -0.25, 0.125, k as f32))
        .collect();
    let (a, b, c, d, q) = (
        arr(&a0, dev),
        arr(&b0, dev),
        arr(&c0, dev),
        arr(&d0, dev),
        arr(&q0, dev),
    );
    let lanes = zeros::<f64, 1>(4, dev);
    let args = (&arr(&ks, dev), &a, &b, &c, &d, &q, &lanes);
    wp::launch(k_vectors, 4, args, dev).unwrap();
    let (a1, b1, c1, d1, q1) = (host(&a), host(&b), host(&c), host(&d), host(&q));
    for (i, &j) in ks.iter().enumerate() {
        let j = j as usize;
        // A quaternion's lanes in glam's order: x, y, z, w.
        let q_lane = |q: Quat| [q.x, q.y, q.z, q.w][j];
        // Small integers and dyadic fractions: every sum is exact.
        let want = a0[i][j % 2] as f64
            + b0[i][j]
            + c0[i][j % 3] as f64
            + d0[i][j] as f64
            + q_lane(q0[i]) as f64;
        assert_eq!(host(&lanes)[i], want, "lanes of thread {i}");
        let (mut va, mut vb, mut vc, mut vd) = (a0[i], b0[i], c0[i], d0[i]);
        va[j % 2] = 10.0;
        vb[j] += 0.5;
        vc[j % 3] *= -3;
        vd[j] -= 1;
        assert_eq!((a1[i], b1[i], c1[i], d1[i]), (va, vb, vc, vd));
        let mut vq = q0[i].to_array();
        vq[j] *= 2.0;
        assert_eq!(q1[i].to_array(), vq);
    }
}

/// A spatial vector's lanes and a spatial matrix's rows and entries at run-time indices
/// (row-major: `m[(r, c)]` is lane `c` of row `r`, and `m[r]` is row `r`).
#[wp::kernel]
fn k_spatial(v: Array<SpatialVector>, m: Array<SpatialMatrix>, out: Array<f32>) {
    let i = tid();
    let mut sv = v[i];
    let mut sm = m[i];
    let mut s = 0.0f32;
    for r in 0..6usize {
        s += sv[r] * sm[(r, (r + i) % 6)];
        sm[r][(r + 1) % 6] = sv[r];
    }
    sv[i % 6] += s;
    sm[(i % 6, 0)] = -1.0;
    let row = sm[(i + 2) % 6];
    out[i] = row[i % 6];
    v[i] = sv;
    m[i] = sm;
}

fn spatial_lanes(dev: &wp::Device) {
    let n = 7;
    let vs: Vec<SpatialVector> = (0..n)
        .map(|k| SpatialVector::from_array(core::array::from_fn(|l| (k * 6 + l) as f32 * 0.5)))
        .collect();
    let ms: Vec<SpatialMatrix> = (0..n)
        .map(|k| SpatialMatrix::IDENTITY * (k as f32 + 1.0))
        .collect();
    let (v, m, out) = (arr(&vs, dev), arr(&ms, dev), zeros::<f32, 1>(n, dev));
    wp::launch(k_spatial, n, (&v, &m, &out), dev).unwrap();
    let (v1, m1, o) = (host(&v), host(&m), host(&out));
    for i in 0..n {
        let (mut sv, mut sm) = (vs[i], ms[i]);
        let mut s = 0.0f32;
        for r in 0..6 {
            s += sv[r] * sm[(r, (r + i) % 6)];
            sm[r][(r + 1) % 6] = sv[r];
        }
        sv[i % 6] += s;
        sm[(i % 6, 0)] = -1.0;
        // Products of dyadic fractions and small integers, summed: exact in f32.
        assert_eq!(o[i], sm[(i + 2) % 6][i % 6], "thread {i}");
        assert_eq!(v1[i], sv, "thread {i}");
        assert_eq!(m1[i], sm, "thread {i}");
    }
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Body {
    x: Vec3,
    w: f32,
    r: Mat3,
}

/// `v[k] += x` through a `&mut` parameter.
#[wp::func]
fn bump(v: &mut Vec3, k: i32, x: f32) {
    v[k] += x;
}

/// Lanes of a struct's field (a local and an array element's), of an array element in place,
/// and of a func's `&mut` parameter.
#[wp::kernel]
fn k_places(k: Array<i32>, bodies: Array<Body>, xs: Array<Vec3>) {
    let i = tid();
    let j = k[i];
    let mut b = bodies[i];
    b.x[j] = b.w;
    bodies[i].x[(j + 1) % 3] -= 1.0;
    bodies[i].w = b.x[j] + bodies[i].x[(j + 1) % 3];
    xs[i][j] *= 4.0;
    bump(&mut xs[i], (j + 2) % 3, b.w);
    // A matrix field: bound with its type, then indexed by entry.
    let mut r: Mat3 = bodies[i].r;
    r[(j, (j + 1) % 3)] += b.w;
    bodies[i].r = r;
}

fn places_with_lanes(dev: &wp::Device) {
    let ks = [0i32, 1, 2];
    let b0: Vec<Body> = (0..3)
        .map(|k| Body {
            x: Vec3::new(1.0, 2.0, 3.0) * (k as f32 + 1.0),
            w: 0.5 + k as f32,
            r: Mat3::from_diagonal(Vec3::splat(k as f32)),
        })
        .collect();
    let x0 = [Vec3::ONE, Vec3::new(1.0, 2.0, 3.0), Vec3::splat(-2.0)];
    let (bodies, xs) = (arr(&b0, dev), arr(&x0, dev));
    wp::launch(k_places, 3, (&arr(&ks, dev), &bodies, &xs), dev).unwrap();
    let (b1, x1) = (host(&bodies), host(&xs));
    for i in 0..3 {
        let j = ks[i] as usize;
        let mut want = b0[i];
        want.x[(j + 1) % 3] -= 1.0;
        want.w = b0[i].w + want.x[(j + 1) % 3];
        // Row j, column j + 1: lane j of that column.
        want.r.col_mut((j + 1) % 3)[j] += b0[i].w;
        assert_eq!(b1[i], want, "body {i}");
        let mut x = x0[i];
        x[j] *= 4.0;
        x[(j + 2) % 3] += b0[i].w;
        assert_eq!(x1[i], x, "x {i}");
    }
}

/// Lanes in a tiled kernel's per-lane code, around a block-cooperative sum.
#[wp::kernel(block_dim = 64)]
fn k_tiled_lanes(x: Array<Vec3>, out: Array<f32>, n: usize) {
    let b = tid();
    let i = b * 64 + lane();
    let mut v = if i < n { x[i] } else { Vec3::ZERO };
    let k = i % 3;
    v[k] *= 2.0;
    let s = tile_sum(tile(1.0f32));
    if i < n {
        out[i] = (v[k] + v[(k + 1) % 3]) * s[0];
    }
}

/// The block sum of 64 ones is 64, exactly: every value is the host's, bit for bit.
fn lanes_in_a_tiled_kernel(dev: &wp::Device) {
    let n = 100;
    let xs: Vec<Vec3> = (0..n)
        .map(|k| Vec3::new(k as f32, 0.5 * k as f32, -0.25))
        .collect();
    let out = zeros::<f32, 1>(n, dev);
    wp::launch_tiled(k_tiled_lanes, 2, (&arr(&xs, dev), &out, n), 64, dev).unwrap();
    for (i, got) in host(&out).iter().enumerate() {
        let (mut v, k) = (xs[i], i % 3);
        v[k] *= 2.0;
        assert_eq!(*got, (v[k] + v[(k + 1) % 3]) * 64.0, "lane {i}");
    }
}

#[wp::kernel]
fn k_lane_oob(k: Array<i32>, v: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    out[i] = v[i][k[i]];
}

#[wp::kernel]
fn k_lane_oob_write(k: Array<i32>, out: Array<Quat>) {
    let i = tid();
    let mut q = Quat::IDENTITY;
    q[k[i]] = 2.0;
    out[i] = q;
}

#[wp::kernel]
fn k_entry_oob(k: Array<i32>, m: Array<Mat3>, out: Array<f32>) {
    let i = tid();
    out[i] = m[i][(0, k[i])];
}

/// The line of the first source line of this file that is `text`, trimmed.
fn line_of(text: &str) -> u32 {
    let src = include_str!("lanes.rs");
    1 + src.lines().position(|l| l.trim() == text).unwrap() as u32
}

/// The fault of launching `kernel`, which must be a `LocalIndex` fault of `name`.
#[track_caller]
fn local_index_fault(err: wp::Error, name: &str) -> FaultKind {
    let wp::Error::Fault(f) = &err else {
        panic!("not a fault: {err}");
    };
    assert_eq!(f.kernel, name);
    f.kind.clone()
}

/// An index outside the lanes (past the end, negative, a matrix column past the last) is a
/// fault naming the kernel, the index, the length and the line, on both backends.
fn index_out_of_range_faults(dev: &wp::Device) {
    let v = arr(&[Vec3::ONE; 3], dev);
    let out = zeros::<f32, 1>(3, dev);
    // The suite runs CUDA in debug mode: the launch reports the fault, as the CPU's does.
    let err = wp::launch(k_lane_oob, 3, (&arr(&[0i32, 3, 1], dev), &v, &out), dev).unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains(
            "kernel `k_lane_oob`: index 3 is out of bounds for a local array or vector of length 3"
        ),
        "{msg}"
    );
    let line = line_of("out[i] = v[i][k[i]];");
    assert_eq!(
        local_index_fault(err, "k_lane_oob"),
        FaultKind::LocalIndex {
            index: 3,
            len: 3,
            line
        }
    );
    let q = zeros::<Quat, 1>(2, dev);
    let err = wp::launch(k_lane_oob_write, 2, (&arr(&[1i32, -1], dev), &q), dev).unwrap_err();
    let line = line_of("q[k[i]] = 2.0;");
    assert_eq!(
        local_index_fault(err, "k_lane_oob_write"),
        FaultKind::LocalIndex {
            index: -1,
            len: 4,
            line
        }
    );
    let m = arr(&[Mat3::IDENTITY; 2], dev);
    let out = zeros::<f32, 1>(2, dev);
    let err = wp::launch(k_entry_oob, 2, (&arr(&[2i32, 3], dev), &m, &out), dev).unwrap_err();
    let line = line_of("out[i] = m[i][(0, k[i])];");
    assert_eq!(
        local_index_fault(err, "k_entry_oob"),
        FaultKind::LocalIndex {
            index: 3,
            len: 3,
            line
        }
    );
}

// ---- derivatives ----

/// `out = Σ_l c_l w_l` where `w` is `x` with lane `k` overwritten by `s²` and then lane `k`
/// of a quaternion and a spatial vector added in: the gradient of `x` is `c` except at lane
/// `k` (zero: the write replaced it), `s`'s is `2 s c_k`, and `q`'s and `sv`'s are `c_k` at
/// lane `k` only.
#[wp::kernel]
fn k_route(
    k: Array<i32>,
    x: Array<DVec3>,
    s: Array<f64>,
    q: Array<DQuat>,
    sv: Array<DSpatialVector>,
    c: DVec3,
    out: Array<f64>,
) {
    let i = tid();
    let j = k[i];
    let mut w = x[i];
    w[j] = s[i] * s[i];
    w[j] += q[i][j] + sv[i][j + 2];
    out[i] = w.dot(c);
}

/// Closed forms: every result is a product or sum of at most two exact terms of dyadic
/// values, so the gradients are exact on both backends.
fn gradients_route_lane_by_lane(dev: &wp::Device) {
    let ks = [0i32, 2, 1];
    let xs = [DVec3::new(1.0, 2.0, 3.0); 3];
    let ss = [0.5f64, -1.5, 2.0];
    let qs = [DQuat::from_xyzw(0.25, 0.5, 0.75, 1.0); 3];
    let svs = [DSpatialVector::from_array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0]); 3];
    let c = DVec3::new(0.5, -2.0, 4.0);
    let x = arr(&xs, dev).with_grad().unwrap();
    let s = arr(&ss, dev).with_grad().unwrap();
    let q = arr(&qs, dev).with_grad().unwrap();
    let sv = arr(&svs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        let args = (&arr(&ks, dev), &x, &s, &q, &sv, c, &out);
        wp::launch(k_route, 3, args, dev).unwrap();
    }
    out.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let (gx, gs) = (host(&x.grad().unwrap()), host(&s.grad().unwrap()));
    let (gq, gsv) = (host(&q.grad().unwrap()), host(&sv.grad().unwrap()));
    for i in 0..3 {
        let j = ks[i] as usize;
        let mut w = xs[i];
        w[j] = ss[i] * ss[i] + (qs[i].to_array()[j] + svs[i][j + 2]);
        assert_eq!(host(&out)[i], w.dot(c), "value {i}");
        let mut want_x = c;
        want_x[j] = 0.0;
        assert_eq!(gx[i], want_x, "x's gradient {i}");
        assert_eq!(gs[i], 2.0 * ss[i] * c[j], "s's gradient {i}");
        let mut want_q = [0.0; 4];
        want_q[j] = c[j];
        assert_eq!(gq[i].to_array(), want_q, "q's gradient {i}");
        let mut want_sv = [0.0; 6];
        want_sv[j + 2] = c[j];
        assert_eq!(gsv[i].to_array(), want_sv, "sv's gradient {i}");
    }
}

/// `f = xᵀ M x` by loops over entries, with `M` rebuilt entry by entry (writes in a loop).
#[wp::kernel]
fn k_quadratic(m: Array<DMat3>, x: Array<DVec3>, out: Array<f64>) {
    let i = tid();
    let v = x[i];
    let mut a = DMat3::ZERO;
    for r in 0..3 {
        for c in 0..3 {
            a[(r, c)] = m[i][(r, c)];
        }
    }
    let mut f = 0.0f64;
    for r in 0..3 {
        for c in 0..3 {
            f += v[r] * a[(r, c)] * v[c];
        }
    }
    out[i] = f;
}

/// `∂f/∂x = (M + Mᵀ) x` and `∂f/∂M = x xᵀ`. Values of order 1, a few dozen f64 roundings:
/// 1e-13 relative is a margin of 100 over the rounding, and a wrong route (a transposed
/// entry, a lost write's gradient) is off by O(1).
fn gradient_of_a_quadratic_form(dev: &wp::Device) {
    let ms: Vec<DMat3> = (0..4)
        .map(|k| DMat3::from_cols_array(&core::array::from_fn(|e| ((k * 9 + e) as f64).cos())))
        .collect();
    let xs: Vec<DVec3> = (0..4)
        .map(|k| DVec3::new(0.3 * k as f64 - 0.5, 1.25, -0.75 + 0.1 * k as f64))
        .collect();
    let m = arr(&ms, dev).with_grad().unwrap();
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(4, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_quadratic, 4, (&m, &x, &out), dev).unwrap();
    }
    out.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let (gm, gx) = (host(&m.grad().unwrap()), host(&x.grad().unwrap()));
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-13 * b.abs().max(1.0);
    for i in 0..4 {
        let want_x = (ms[i] + ms[i].transpose()) * xs[i];
        let want_m = DMat3::from_cols(xs[i] * xs[i].x, xs[i] * xs[i].y, xs[i] * xs[i].z);
        for r in 0..3 {
            assert!(close(gx[i][r], want_x[r]), "x {i}: {} vs {want_x}", gx[i]);
            for c in 0..3 {
                let (g, w) = (gm[i].col(c)[r], want_m.col(c)[r]);
                assert!(close(g, w), "M {i} ({r}, {c}): {g} vs {w}");
            }
        }
    }
}

#[wp::kernel]
fn k_lanes_smooth(x: Array<DVec3>, y: Array<f64>) {
    let i = tid();
    let mut v = x[i];
    for _pass in 0..2 {
        for l in 0..3 {
            v[l] = v[l] * v[(l + 1) % 3] + v[(l + 2) % 3].sin();
        }
    }
    y[i] = v[0] + v[1] * v[2];
}

/// Forward mode (`wp::jvp`) through lane reads and writes in loops, against reverse mode: both
/// exact derivatives of the same f64 program, so they agree to rounding (1e-12 relative: a
/// few dozen operations on values of order 1).
fn jvp_matches_the_gradient(dev: &wp::Device) {
    let xs = [DVec3::new(0.4, -0.6, 0.9), DVec3::new(0.1, 0.2, -0.3)];
    let vs = [DVec3::new(1.0, 2.0, -0.5), DVec3::new(-1.0, 0.5, 0.25)];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(2, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(2, dev));
    wp::jvp(k_lanes_smooth, 2, (&x, &y), (&v, &y_dot), dev).unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_lanes_smooth, 2, (&x, &y), dev).unwrap();
    }
    y.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let g = host(&x.grad().unwrap());
    for ((jv, g), v) in host(&y_dot).iter().zip(&g).zip(&vs) {
        let want = g.dot(*v);
        assert!(
            (jv - want).abs() <= 1e-12 * want.abs().max(1.0),
            "jvp {jv}, gradient times tangent {want}"
        );
    }
}

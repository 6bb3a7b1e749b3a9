//! Builtins, in function syntax and in method syntax: scalar math on floats and integers,
//! vector math, and the atomics (with many threads on one element, and on a 2-D array).

use crate::{
    arr, assert_close_f32, assert_close_f64, assert_close_slice, fma_rel, fma_rel64, host,
    math_rel, zeros,
};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    float_builtins_function_syntax,
    float_builtins_method_syntax,
    f64_builtins,
    integer_builtins,
    vector_builtins,
    int_vector_builtins,
    atomic_add_many_threads,
    atomic_sub_min_max,
    atomic_2d_and_vectors,
    scalar_math_f32,
    scalar_math_f64,
    scalar_math_methods,
    classification_builtins,
    linalg_builtins,
);

/// Warp's `sign`: -1 below zero, else +1 (so +1 for 0, -0 and NaN).
fn sign_f32(x: f32) -> f32 {
    if x < 0.0 {
        -1.0
    } else {
        1.0
    }
}

/// Warp's `clamp`: `min(max(x, lo), hi)`, so a NaN `x` gives `lo` (`f32::clamp` would keep the
/// NaN).
#[allow(clippy::manual_clamp)]
fn clamp_f32(x: f32, lo: f32, hi: f32) -> f32 {
    x.max(lo).min(hi)
}

/// Host reference for the 16 scalar builtins of `k_scalar_fns` and `k_scalar_methods`:
/// (value, tolerance class) where the class is 0 = exact, 1 = transcendental, 2 = FMA.
fn scalar_ref(a: f32, b: f32) -> [(f32, u8); 16] {
    [
        (a.min(b), 0),
        (a.max(b), 0),
        (a.abs(), 0),
        (sign_f32(a), 0),
        (clamp_f32(a, -1.0, 1.0), 0),
        (a.floor(), 0),
        (a.ceil(), 0),
        (b.sqrt(), 0),
        (a.exp(), 1),
        (b.ln(), 1),
        (a.sin(), 1),
        (a.cos(), 1),
        (a.tan(), 1),
        (a.atan2(b), 1),
        (b.powf(a), 1),
        (a * (1.0 - 0.25) + b * 0.25, 2),
    ]
}

const SCALAR_X: [f32; 7] = [0.5, -1.3, 2.0, -0.0, 3.7, f32::NAN, -7.5];
const SCALAR_Y: [f32; 7] = [0.25, 2.0, 9.0, 1.0, 0.1, 4.0, 1e-3];

fn check_scalar_rows(dev: &wp::Device, out: &wp::Array<f32, 2>, what: &str) {
    for (i, row) in host(out).chunks(16).enumerate() {
        let (a, b) = (SCALAR_X[i], SCALAR_Y[i]);
        for (k, (want, class)) in scalar_ref(a, b).into_iter().enumerate() {
            let rel = match class {
                0 => 0.0,
                1 => math_rel(dev),
                _ => fma_rel(dev),
            };
            assert_close_f32(
                row[k],
                want,
                rel,
                &format!("{what}: builtin #{k} of ({a}, {b})"),
            );
        }
    }
}

#[wp::kernel]
fn k_scalar_fns(x: Array<f32>, y: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let b = y[i];
    out[(i, 0)] = min(a, b);
    out[(i, 1)] = max(a, b);
    out[(i, 2)] = abs(a);
    out[(i, 3)] = sign(a);
    out[(i, 4)] = clamp(a, -1.0, 1.0);
    out[(i, 5)] = floor(a);
    out[(i, 6)] = ceil(a);
    out[(i, 7)] = sqrt(b);
    out[(i, 8)] = exp(a);
    out[(i, 9)] = log(b);
    out[(i, 10)] = sin(a);
    out[(i, 11)] = cos(a);
    out[(i, 12)] = tan(a);
    out[(i, 13)] = atan2(a, b);
    out[(i, 14)] = pow(b, a);
    out[(i, 15)] = lerp(a, b, 0.25);
}

fn float_builtins_function_syntax(dev: &wp::Device) {
    let n = SCALAR_X.len();
    let out = zeros::<f32, 2>((n, 16), dev);
    wp::launch(
        k_scalar_fns,
        n,
        (&arr(&SCALAR_X, dev), &arr(&SCALAR_Y, dev), &out),
        dev,
    )
    .unwrap();
    check_scalar_rows(dev, &out, "function syntax");
}

#[wp::kernel]
fn k_scalar_methods(x: Array<f32>, y: Array<f32>, out: Array<f32, 2>, typed: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let b = y[i];
    out[(i, 0)] = a.min(b);
    out[(i, 1)] = a.max(b);
    out[(i, 2)] = a.abs();
    out[(i, 3)] = sign(a);
    out[(i, 4)] = a.clamp(-1.0, 1.0);
    out[(i, 5)] = a.floor();
    out[(i, 6)] = a.ceil();
    out[(i, 7)] = b.sqrt();
    out[(i, 8)] = a.exp();
    out[(i, 9)] = b.ln();
    out[(i, 10)] = a.sin();
    out[(i, 11)] = a.cos();
    out[(i, 12)] = a.tan();
    out[(i, 13)] = a.atan2(b);
    out[(i, 14)] = b.powf(a);
    out[(i, 15)] = a.lerp(b, 0.25);
    // Builtins named through the scalar type, as in Rust: `f32::sqrt(x)`.
    typed[(i, 0)] = f32::sqrt(b);
    typed[(i, 1)] = f32::max(a, b);
    typed[(i, 2)] = f32::abs(a);
}

fn float_builtins_method_syntax(dev: &wp::Device) {
    let n = SCALAR_X.len();
    let (out, typed) = (zeros::<f32, 2>((n, 16), dev), zeros::<f32, 2>((n, 3), dev));
    wp::launch(
        k_scalar_methods,
        n,
        (&arr(&SCALAR_X, dev), &arr(&SCALAR_Y, dev), &out, &typed),
        dev,
    )
    .unwrap();
    check_scalar_rows(dev, &out, "method syntax");
    for (i, row) in host(&typed).chunks(3).enumerate() {
        let (a, b) = (SCALAR_X[i], SCALAR_Y[i]);
        assert_close_slice(
            row,
            &[b.sqrt(), a.max(b), a.abs()],
            0.0,
            "f32::sqrt / f32::max / f32::abs",
        );
    }
}

#[wp::kernel]
fn k_f64_fns(x: Array<f64>, y: Array<f64>, out: Array<f64, 2>) {
    let i = tid();
    let a = x[i];
    let b = y[i];
    out[(i, 0)] = min(a, b);
    out[(i, 1)] = max(a, 0.5);
    out[(i, 2)] = abs(a);
    out[(i, 3)] = sign(a);
    out[(i, 4)] = clamp(a, -1.0, 1.0);
    out[(i, 5)] = floor(a);
    out[(i, 6)] = ceil(a);
    out[(i, 7)] = sqrt(b);
    out[(i, 8)] = exp(a);
    out[(i, 9)] = log(b);
    out[(i, 10)] = sin(a);
    out[(i, 11)] = cos(a);
    out[(i, 12)] = tan(a);
    out[(i, 13)] = atan2(a, b);
    out[(i, 14)] = pow(b, a);
    out[(i, 15)] = lerp(a, b, 0.1);
}

fn f64_builtins(dev: &wp::Device) {
    let x = [0.5f64, -1.3, 2.0, 0.1, 3.7];
    let y = [0.25f64, 2.0, 9.0, 1.0, 0.1];
    let out = zeros::<f64, 2>((5, 16), dev);
    wp::launch(k_f64_fns, 5, (&arr(&x, dev), &arr(&y, dev), &out), dev).unwrap();
    for (i, row) in host(&out).chunks(16).enumerate() {
        let (a, b) = (x[i], y[i]);
        let exact = [
            a.min(b),
            a.max(0.5),
            a.abs(),
            if a < 0.0 { -1.0 } else { 1.0 },
            a.clamp(-1.0, 1.0),
            a.floor(),
            a.ceil(),
            b.sqrt(),
        ];
        assert_eq!(&row[..8], exact, "exact f64 builtins on ({a}, {b})");
        let math = [
            a.exp(),
            b.ln(),
            a.sin(),
            a.cos(),
            a.tan(),
            a.atan2(b),
            b.powf(a),
        ];
        // CUDA's double-precision functions are within a couple of ulp: 1e-14 relative there.
        let rel = if dev.is_cpu() { 0.0 } else { 1e-14 };
        for (k, w) in math.into_iter().enumerate() {
            assert_close_f64(
                row[8 + k],
                w,
                rel,
                &format!("f64 transcendental #{k} of ({a}, {b})"),
            );
        }
        assert_close_f64(
            row[15],
            a * (1.0 - 0.1) + b * 0.1,
            fma_rel64(dev),
            "f64 lerp",
        );
    }
}

#[wp::kernel]
fn k_int_fns(
    x: Array<i32>,
    y: Array<i32>,
    u: Array<u32>,
    l: Array<i64>,
    out: Array<i32, 2>,
    uout: Array<u32, 2>,
    lout: Array<i64, 2>,
) {
    let i = tid();
    let a = x[i];
    let b = y[i];
    out[(i, 0)] = min(a, b);
    out[(i, 1)] = max(a, b);
    out[(i, 2)] = abs(a);
    out[(i, 3)] = sign(a);
    out[(i, 4)] = clamp(a, -10, 10);
    out[(i, 5)] = a.min(b);
    out[(i, 6)] = a.max(3);
    out[(i, 7)] = a.abs();
    out[(i, 8)] = a.clamp(b, 100);
    let c = u[i];
    uout[(i, 0)] = min(c, 7);
    uout[(i, 1)] = max(c, 7);
    uout[(i, 2)] = clamp(c, 2, 9);
    let d = l[i];
    lout[(i, 0)] = abs(d);
    lout[(i, 1)] = sign(d);
    lout[(i, 2)] = max(d, 5_000_000_000);
}

fn integer_builtins(dev: &wp::Device) {
    let x = [5, -5, 0, i32::MIN, i32::MAX, -11];
    let y = [3, -2, 0, 0, -1, 20];
    let u = [0u32, 7, 100, u32::MAX, 3, 8];
    let l = [-6_000_000_000i64, 0, 1, i64::MIN, 6_000_000_000, -1];
    let (out, uout, lout) = (
        zeros::<i32, 2>((6, 9), dev),
        zeros::<u32, 2>((6, 3), dev),
        zeros::<i64, 2>((6, 3), dev),
    );
    wp::launch(
        k_int_fns,
        6,
        (
            &arr(&x, dev),
            &arr(&y, dev),
            &arr(&u, dev),
            &arr(&l, dev),
            &out,
            &uout,
            &lout,
        ),
        dev,
    )
    .unwrap();
    let sign = |v: i64| if v < 0 { -1 } else { 1 };
    // clamp is min(max(x, lo), hi): defined (never a panic) even when lo > hi.
    let clamp = |v: i32, lo: i32, hi: i32| v.max(lo).min(hi);
    let want: Vec<i32> = (0..6)
        .flat_map(|i| {
            let (a, b) = (x[i], y[i]);
            [
                a.min(b),
                a.max(b),
                a.wrapping_abs(),
                sign(a.into()) as i32,
                clamp(a, -10, 10),
                a.min(b),
                a.max(3),
                a.wrapping_abs(),
                clamp(a, b, 100),
            ]
        })
        .collect();
    assert_eq!(
        host(&out),
        want,
        "abs(i32::MIN) wraps to i32::MIN, as on CUDA"
    );
    let want: Vec<u32> = u
        .iter()
        .flat_map(|&c| [c.min(7), c.max(7), c.clamp(2, 9)])
        .collect();
    assert_eq!(host(&uout), want);
    let want: Vec<i64> = l
        .iter()
        .flat_map(|&d| [d.wrapping_abs(), sign(d), d.max(5_000_000_000)])
        .collect();
    assert_eq!(host(&lout), want);
}

#[wp::kernel]
fn k_vec_fns(
    v: Array<Vec3>,
    w: Array<Vec3>,
    s: Array<f32, 2>,
    out: Array<Vec3, 2>,
    d: Array<DVec4>,
    dout: Array<DVec4>,
    ds: Array<f64>,
) {
    let i = tid();
    let a = v[i];
    let b = w[i];
    s[(i, 0)] = dot(a, b);
    s[(i, 1)] = a.dot(b);
    s[(i, 2)] = length(a);
    s[(i, 3)] = a.length();
    out[(i, 0)] = cross(a, b);
    out[(i, 1)] = a.cross(b);
    out[(i, 2)] = normalize(a);
    out[(i, 3)] = a.normalize();
    out[(i, 4)] = lerp(a, b, 0.75);
    out[(i, 5)] = a.lerp(b, 0.75);
    out[(i, 6)] = min(a, b);
    out[(i, 7)] = a.max(b);
    out[(i, 8)] = abs(a);
    out[(i, 9)] = sign(a);
    out[(i, 10)] = clamp(a, Vec3::splat(-1.0), Vec3::ONE);
    let e = d[i];
    dout[i] = normalize(e);
    ds[i] = length(e);
}

/// Warp's definitions, componentwise and left to right (glam's SIMD order or its NaN-on-zero
/// normalize are not the reference).
fn dot3(a: Vec3, b: Vec3) -> f32 {
    a.x * b.x + a.y * b.y + a.z * b.z
}

fn vector_builtins(dev: &wp::Device) {
    let v = [
        vec3(1.0, 2.0, 3.0),
        vec3(-0.3, 0.4, 1.2),
        Vec3::ZERO,
        vec3(3.0, -4.0, 0.0),
    ];
    let w = [
        vec3(4.0, -5.0, 6.0),
        vec3(0.7, 0.1, -2.0),
        vec3(1.0, 1.0, 1.0),
        vec3(0.5, 0.5, -0.5),
    ];
    let d = [
        dvec4(1.0, 2.0, 2.0, 4.0),
        DVec4::ZERO,
        dvec4(0.1, 0.2, 0.3, 0.4),
        dvec4(-3.0, 0.0, 0.0, 4.0),
    ];
    let n = v.len();
    let (s, out) = (zeros::<f32, 2>((n, 4), dev), zeros::<Vec3, 2>((n, 11), dev));
    let (dout, ds) = (zeros::<DVec4, 1>(n, dev), zeros::<f64, 1>(n, dev));
    wp::launch(
        k_vec_fns,
        n,
        (
            &arr(&v, dev),
            &arr(&w, dev),
            &s,
            &out,
            &arr(&d, dev),
            &dout,
            &ds,
        ),
        dev,
    )
    .unwrap();
    let (s, out, dout, ds) = (host(&s), host(&out), host(&dout), host(&ds));
    let rel = fma_rel(dev);
    for i in 0..n {
        let (a, b) = (v[i], w[i]);
        let len = dot3(a, a).sqrt();
        let norm = if len > 0.0 { a / len } else { Vec3::ZERO };
        let cross = vec3(
            a.y * b.z - a.z * b.y,
            a.z * b.x - a.x * b.z,
            a.x * b.y - a.y * b.x,
        );
        let lerp = a * (1.0 - 0.75) + b * 0.75;
        assert_close_slice(
            &s[i * 4..i * 4 + 4],
            &[dot3(a, b), dot3(a, b), len, len],
            rel,
            "dot / length",
        );
        let row = &out[i * 11..i * 11 + 11];
        for (k, want) in [cross, cross, norm, norm, lerp, lerp]
            .into_iter()
            .enumerate()
        {
            assert_close_slice(
                &row[k].to_array(),
                &want.to_array(),
                rel,
                &format!("vector builtin #{k} of {a}, {b}"),
            );
        }
        let sign = Vec3::from_array(a.to_array().map(sign_f32));
        assert_eq!(
            &row[6..],
            [
                a.min(b),
                a.max(b),
                a.abs(),
                sign,
                a.clamp(Vec3::splat(-1.0), Vec3::ONE)
            ],
            "componentwise builtins"
        );
        let e = d[i];
        let dl = (e.x * e.x + e.y * e.y + e.z * e.z + e.w * e.w).sqrt();
        assert_close_f64(ds[i], dl, fma_rel64(dev), "DVec4 length");
        let dn = if dl > 0.0 { e / dl } else { DVec4::ZERO };
        for k in 0..4 {
            assert_close_f64(dout[i][k], dn[k], fma_rel64(dev), "DVec4 normalize");
        }
    }
    assert_eq!(
        out[2 * 11 + 2],
        Vec3::ZERO,
        "normalize of the zero vector is zero, not NaN"
    );
}

#[wp::kernel]
fn k_ivec_fns(
    a: Array<IVec3>,
    b: Array<IVec3>,
    u: Array<UVec2>,
    dots: Array<i32>,
    udots: Array<u32>,
    out: Array<IVec3, 2>,
) {
    let i = tid();
    dots[i] = dot(a[i], b[i]);
    udots[i] = u[i].dot(u[i]);
    out[(i, 0)] = cross(a[i], b[i]);
    out[(i, 1)] = min(a[i], b[i]);
    out[(i, 2)] = abs(a[i]);
}

fn int_vector_builtins(dev: &wp::Device) {
    let a = [
        ivec3(1, 2, 3),
        ivec3(i32::MAX, -1, 0),
        ivec3(-4, 5, i32::MIN),
    ];
    let b = [ivec3(4, 5, 6), ivec3(2, 3, 1), ivec3(1, 1, 1)];
    let u = [uvec2(3, 4), uvec2(u32::MAX, 2), uvec2(65_536, 0)];
    let (dots, udots, out) = (
        zeros::<i32, 1>(3, dev),
        zeros::<u32, 1>(3, dev),
        zeros::<IVec3, 2>((3, 3), dev),
    );
    wp::launch(
        k_ivec_fns,
        3,
        (
            &arr(&a, dev),
            &arr(&b, dev),
            &arr(&u, dev),
            &dots,
            &udots,
            &out,
        ),
        dev,
    )
    .unwrap();
    // Integer vector builtins wrap like CUDA.
    let wdot = |p: IVec3, q: IVec3| {
        p.x.wrapping_mul(q.x)
            .wrapping_add(p.y.wrapping_mul(q.y))
            .wrapping_add(p.z.wrapping_mul(q.z))
    };
    let wcross = |p: IVec3, q: IVec3| {
        ivec3(
            p.y.wrapping_mul(q.z).wrapping_sub(p.z.wrapping_mul(q.y)),
            p.z.wrapping_mul(q.x).wrapping_sub(p.x.wrapping_mul(q.z)),
            p.x.wrapping_mul(q.y).wrapping_sub(p.y.wrapping_mul(q.x)),
        )
    };
    assert_eq!(
        host(&dots),
        (0..3).map(|i| wdot(a[i], b[i])).collect::<Vec<_>>()
    );
    assert_eq!(
        host(&udots),
        u.iter()
            .map(|p| p.x.wrapping_mul(p.x).wrapping_add(p.y.wrapping_mul(p.y)))
            .collect::<Vec<_>>()
    );
    let want: Vec<IVec3> = (0..3)
        .flat_map(|i| {
            [
                wcross(a[i], b[i]),
                a[i].min(b[i]),
                IVec3::from_array(a[i].to_array().map(i32::wrapping_abs)),
            ]
        })
        .collect();
    assert_eq!(host(&out), want);
}

// ------------------------------------------------------------------------------ atomics

/// More threads than one CPU chunk (4096), so that the CPU runs them on several workers.
const MANY: usize = 10_000;

#[wp::kernel]
fn k_atomic_add(
    ti: Array<i32>,
    tf: Array<f32>,
    tl: Array<i64>,
    tu: Array<u64>,
    td: Array<f64>,
    tickets: Array<i32>,
    counter: Array<u32>,
) {
    let i = tid();
    atomic_add(ti, 0, 1);
    atomic_add(ti, 1, (i % 7) as i32);
    atomic_add(tf, 0, 0.5);
    atomic_add(tf, 1, (i % 7) as f32);
    atomic_add(tl, 0, i as i64 * 1_000_000);
    atomic_add(tu, 0, 3);
    atomic_add(td, 0, 0.25);
    // An i32 index, and the builtin named through `wp::`.
    let j = (i % 2) as i32;
    wp::atomic_add(ti, j + 2, 1);
    let old = atomic_add(counter, 0, 1);
    tickets[i] = old as i32;
}

fn atomic_add_many_threads(dev: &wp::Device) {
    let (ti, tf, tl) = (
        zeros::<i32, 1>(4, dev),
        zeros::<f32, 1>(2, dev),
        zeros::<i64, 1>(1, dev),
    );
    let (tu, td) = (zeros::<u64, 1>(1, dev), zeros::<f64, 1>(1, dev));
    let (tickets, counter) = (zeros::<i32, 1>(MANY, dev), zeros::<u32, 1>(1, dev));
    wp::launch(
        k_atomic_add,
        MANY,
        (&ti, &tf, &tl, &tu, &td, &tickets, &counter),
        dev,
    )
    .unwrap();
    let mod7: i32 = (0..MANY).map(|i| (i % 7) as i32).sum();
    let half = MANY as i32 / 2;
    assert_eq!(
        host(&ti),
        vec![MANY as i32, mod7, half, half],
        "integer totals are exact"
    );
    // Every partial sum is a small integer or half-integer, exactly representable in f32, so
    // the total does not depend on the order of the additions.
    assert_eq!(host(&tf), vec![MANY as f32 * 0.5, mod7 as f32]);
    assert_eq!(
        host(&tl),
        vec![(0..MANY as i64).map(|i| i * 1_000_000).sum::<i64>()]
    );
    assert_eq!(host(&tu), vec![3 * MANY as u64]);
    assert_eq!(host(&td), vec![MANY as f64 * 0.25]);
    assert_eq!(host(&counter), vec![MANY as u32]);
    // atomic_add returns the old value: the tickets are a permutation of 0..MANY.
    let mut t = host(&tickets);
    t.sort_unstable();
    assert_eq!(t, (0..MANY as i32).collect::<Vec<_>>());
}

#[wp::kernel]
fn k_atomic_sub_min_max(
    vals: Array<i32>,
    si: Array<i32>,
    su: Array<u32>,
    sf: Array<f32>,
    mi: Array<i32>,
    mf: Array<f32>,
    mu: Array<u64>,
) {
    let i = tid();
    let v = vals[i];
    atomic_sub(si, 0, 3);
    atomic_sub(su, 0, 1);
    atomic_sub(sf, 0, 0.25);
    atomic_min(mi, 0, v);
    atomic_max(mi, 1, v);
    atomic_min(mf, 0, v as f32 * 0.5);
    atomic_max(mf, 1, v as f32 * 0.5);
    atomic_max(mu, 0, i as u64);
    atomic_min(mu, 1, (i + 5) as u64);
}

fn atomic_sub_min_max(dev: &wp::Device) {
    let vals: Vec<i32> = (0..MANY as i32)
        .map(|i| (i * 7919) % 10_007 - 5000)
        .collect();
    let si = arr(&[100_000], dev);
    let su = zeros::<u32, 1>(1, dev);
    let sf = arr(&[10_000.0f32], dev);
    let mi = arr(&[i32::MAX, i32::MIN], dev);
    let mf = arr(&[f32::INFINITY, f32::NEG_INFINITY], dev);
    let mu = arr(&[0u64, u64::MAX], dev);
    wp::launch(
        k_atomic_sub_min_max,
        MANY,
        (&arr(&vals, dev), &si, &su, &sf, &mi, &mf, &mu),
        dev,
    )
    .unwrap();
    assert_eq!(host(&si), vec![100_000 - 3 * MANY as i32]);
    assert_eq!(
        host(&su),
        vec![0u32.wrapping_sub(MANY as u32)],
        "unsigned atomic_sub wraps"
    );
    assert_eq!(host(&sf), vec![10_000.0 - 0.25 * MANY as f32]);
    let (lo, hi) = (*vals.iter().min().unwrap(), *vals.iter().max().unwrap());
    assert_eq!(host(&mi), vec![lo, hi]);
    assert_eq!(host(&mf), vec![lo as f32 * 0.5, hi as f32 * 0.5]);
    assert_eq!(host(&mu), vec![MANY as u64 - 1, 5]);
}

#[wp::kernel]
fn k_atomic_2d(hist: Array<i32, 2>, peak: Array<f32, 3>, vsum: Array<Vec3>, dsum: Array<DVec2, 2>) {
    let (i, j) = tid();
    atomic_add(hist, (i % 3, j % 4), 1);
    atomic_max(peak, (i % 2, j % 2, 0), (i * j) as f32);
    atomic_add(vsum, 0, vec3(1.0, 0.5, -2.0));
    atomic_sub(dsum, (0, j % 2), dvec2(0.5, 1.0));
}

fn atomic_2d_and_vectors(dev: &wp::Device) {
    let (rows, cols) = (30usize, 40usize);
    let hist = zeros::<i32, 2>((3, 4), dev);
    let peak = zeros::<f32, 3>((2, 2, 1), dev);
    let vsum = zeros::<Vec3, 1>(1, dev);
    let dsum = zeros::<DVec2, 2>((1, 2), dev);
    wp::launch(k_atomic_2d, (rows, cols), (&hist, &peak, &vsum, &dsum), dev).unwrap();
    let mut want_hist = vec![0; 12];
    let mut want_peak = [0.0f32; 4];
    for i in 0..rows {
        for j in 0..cols {
            want_hist[(i % 3) * 4 + j % 4] += 1;
            let p = &mut want_peak[(i % 2) * 2 + j % 2];
            *p = p.max((i * j) as f32);
        }
    }
    assert_eq!(host(&hist), want_hist);
    assert_eq!(host(&peak), want_peak);
    let n = (rows * cols) as f32;
    assert_eq!(
        host(&vsum),
        vec![vec3(n, n * 0.5, -2.0 * n)],
        "vector atomics add componentwise"
    );
    let half = (rows * cols / 2) as f64;
    assert_eq!(host(&dsum), vec![dvec2(-0.5 * half, -half); 2]);
}

// ------------------------------------------------------------------------------------------
// Warp's scalar math: trigonometric, hyperbolic, exp/log, erf family, rounding, step,
// smoothstep, degrees/radians, mod, classification.
// ------------------------------------------------------------------------------------------

/// Rows per builtin column in the scalar-math kernels.
const ROWS: usize = 8;
/// Columns of the scalar-math kernels: one builtin each, with inputs in its domain (and at its
/// edges: asin/acos outside [-1, 1] are clamped, erfinv(1) = inf, erfcinv(0) = inf and
/// erfcinv(2) = -inf, smoothstep with equal edges).
const COLS: usize = 25;
const INPUTS: [[f32; ROWS]; COLS] = [
    [-1.5, -1.0, -0.7, -0.0, 0.25, 0.999, 1.0, 2.0], // 0 asin
    [-1.5, -1.0, -0.7, -0.0, 0.25, 0.999, 1.0, 2.0], // 1 acos
    [-1e3, -2.0, -0.5, 0.0, 0.3, 1.0, 7.5, f32::INFINITY], // 2 atan
    [-5.0, -1.0, -0.1, 0.0, 0.2, 1.5, 10.0, 30.0],   // 3 sinh
    [-5.0, -1.0, -0.1, 0.0, 0.2, 1.5, 10.0, 30.0],   // 4 cosh
    [-20.0, -1.0, -0.1, 0.0, 0.05, 0.5, 2.0, 9.0],   // 5 tanh
    [-10.0, -1.5, -0.25, 0.0, 0.5, 3.0, 10.5, 100.0], // 6 exp2
    [1e-3, 0.1, 0.5, 1.0, 2.0, 10.0, 1000.0, 1e30],  // 7 log2
    [1e-3, 0.1, 0.5, 1.0, 2.0, 10.0, 1000.0, 1e30],  // 8 log10
    [-27.0, -2.0, -1e-3, 0.0, 1e-6, 0.5, 8.0, 1e9],  // 9 cbrt
    [-3.0, -1.0, -0.5, -0.0, 0.1, 0.9, 2.0, 4.0],    // 10 erf
    [-3.0, -1.0, -0.5, -0.0, 0.1, 0.9, 2.0, 4.0],    // 11 erfc
    [-0.999, -0.5, -0.1, 0.0, 0.25, 0.75, 0.9999, 1.0], // 12 erfinv
    [1e-20, 1e-3, 0.1, 0.5, 1.0, 1.5, 1.99, 2.0],    // 13 erfcinv
    [-2.5, -1.5, -0.5, 0.5, 1.5, 2.5, 3.7, -3.7],    // 14 round
    [-2.5, -1.5, -0.5, 0.5, 1.5, 2.5, 3.7, -3.7],    // 15 rint
    [-2.5, -1.5, -0.5, 0.5, 1.5, 2.5, 3.7, -3.7],    // 16 trunc
    [-2.5, -1.5, -0.25, 0.5, 1.75, 2.5, 3.7, -3.7],  // 17 frac
    [-6.3, -1.0, 0.0, 0.5, 1.0, std::f32::consts::PI, 100.0, 1e-3], // 18 degrees
    [-360.0, -90.0, 0.0, 1.0, 45.0, 180.0, 720.0, 0.5], // 19 radians
    [
        -2.0,
        -1e-30,
        -0.0,
        0.0,
        1e-30,
        1.0,
        f32::NAN,
        f32::NEG_INFINITY,
    ], // 20 step
    [-2.0, -1.0, -0.5, 0.0, 0.5, 1.0, 2.0, 3.0],     // 21 smoothstep(-1, 2, x)
    [-1.0, 0.0, 0.5, 0.500_001, 1.0, 2.0, -0.0, 100.0], // 22 smoothstep(0.5, 0.5, x)
    [-2.5, -0.7, 0.0, 0.7, 1.6, 7.25, 100.0, -100.0], // 23 mod(x, 0.75)
    [-1.0, -0.5, 0.0, 0.5, 1.0, 2.0, -2.0, 4.0],     // 24 atan(x) via f32::atan
];

/// The f64 reference of column `k` at `x`: Rust's f64 functions, the clamps and definitions
/// of the builtins, and warp-core's f64 erf family (std has no erf; warp-core's is checked
/// against 50-digit mpmath values to 4 eps in its unit tests).
fn scalar_math_ref(k: usize, x: f64) -> f64 {
    use wp::__private::builtins::special;
    let unit = |x: f64| x.clamp(-1.0, 1.0);
    // max/min, not clamp: with equal edges the quotient may be NaN, which must clamp to 0.
    #[allow(clippy::manual_clamp)]
    let smooth = |e0: f64, e1: f64, x: f64| {
        let t = ((x - e0) / (e1 - e0)).max(0.0).min(1.0);
        t * t * (3.0 - 2.0 * t)
    };
    match k {
        0 => unit(x).asin(),
        1 => unit(x).acos(),
        2 | 24 => x.atan(),
        3 => x.sinh(),
        4 => x.cosh(),
        5 => x.tanh(),
        6 => x.exp2(),
        7 => x.log2(),
        8 => x.log10(),
        9 => x.cbrt(),
        10 => special::erf(x),
        11 => special::erfc(x),
        12 => special::erfinv(x),
        13 => special::erfcinv(x),
        14 => x.round(),
        15 => x.round_ties_even(),
        16 => x.trunc(),
        17 => x.fract(),
        18 => x.to_degrees(),
        19 => x.to_radians(),
        20 => {
            if x < 0.0 {
                1.0
            } else {
                0.0
            }
        }
        21 => smooth(-1.0, 2.0, x),
        22 => smooth(0.5, 0.5, x),
        23 => x % 0.75,
        _ => unreachable!(),
    }
}

/// Tolerance of column `k` in ulps of the result's type, against the f64 reference.
///
/// * CPU, f32: the libm group (asin .. cbrt) calls glibc's single-precision functions (or,
///   for cbrt, std's own), within 1 ulp of the correctly rounded result in glibc's tables of
///   known errors for x86_64 (2 allowed); the erf family is warp-core's f64 result rounded
///   once (documented: 1 ulp); degrees/radians multiply by a constant rounded to f32 (1 ulp);
///   smoothstep is about six roundings (4 ulp); rounding, frac, step and mod are exact.
/// * CPU, f64: the reference is the very same computation: exact.
/// * CUDA: the maximum ulp errors of CUDA's functions in the CUDA C++ Programming Guide
///   ("Mathematical Functions" appendix, tables of single- and double-precision standard
///   library functions), plus one: f32 asinf 2, acosf 2, atanf 2, sinhf 3, coshf 2, tanhf 2,
///   exp2f 2, log2f 1, log10f 2, cbrtf 1, erff 2, erfcf 4, erfinvf 2, erfcinvf 4; f64 asin 2,
///   acos 2, atan 2, sinh 2, cosh 1, tanh 1, exp2 1, log2 1, log10 1, cbrt 1, erf 2, erfc 5,
///   erfinv 5, erfcinv 6; the rest as on the CPU (IEEE arithmetic, `--fmad=false`).
fn scalar_math_ulps(k: usize, cpu: bool, f64_: bool) -> f64 {
    const CUDA32: [f64; 14] = [2., 2., 2., 3., 2., 2., 2., 1., 2., 1., 2., 4., 2., 4.];
    const CUDA64: [f64; 14] = [2., 2., 2., 2., 1., 1., 1., 1., 1., 1., 2., 5., 5., 6.];
    match (k, cpu, f64_) {
        (_, true, true) => 0.0,
        (0..=9 | 24, true, false) => 2.0,
        (10..=13, true, false) => 1.0,
        (0..=13, false, false) => CUDA32[k] + 1.0,
        (24, false, false) => CUDA32[2] + 1.0,
        (0..=13, false, true) => CUDA64[k] + 1.0,
        (24, false, true) => CUDA64[2] + 1.0,
        (18 | 19, _, false) => 1.0,
        (21 | 22, _, false) => 4.0,
        _ => 0.0,
    }
}

/// `got` within `ulps` ulps (of a type with machine epsilon `eps`) of `want`, relative to
/// `|want|`; non-finite and zero references must match exactly (zeros up to sign).
#[track_caller]
fn assert_ulps(got: f64, want: f64, ulps: f64, eps: f64, what: &str) {
    let ok = if want.is_nan() {
        got.is_nan()
    } else if !want.is_finite() || want == 0.0 {
        got == want
    } else {
        (got - want).abs() <= ulps * eps * want.abs()
    };
    assert!(ok, "{what}: got {got:e}, want {want:e} ({ulps} ulp)");
}

/// One kernel body for both precisions, so that the f32 and f64 tests cannot drift apart.
macro_rules! scalar_math_kernel {
    ($name:ident, $t:ident) => {
        #[wp::kernel]
        fn $name(x: Array<$t, 2>, out: Array<$t, 2>) {
            let i = tid();
            out[(0, i)] = asin(x[(0, i)]);
            out[(1, i)] = acos(x[(1, i)]);
            out[(2, i)] = atan(x[(2, i)]);
            out[(3, i)] = sinh(x[(3, i)]);
            out[(4, i)] = cosh(x[(4, i)]);
            out[(5, i)] = tanh(x[(5, i)]);
            out[(6, i)] = exp2(x[(6, i)]);
            out[(7, i)] = log2(x[(7, i)]);
            out[(8, i)] = log10(x[(8, i)]);
            out[(9, i)] = cbrt(x[(9, i)]);
            out[(10, i)] = erf(x[(10, i)]);
            out[(11, i)] = erfc(x[(11, i)]);
            out[(12, i)] = erfinv(x[(12, i)]);
            out[(13, i)] = erfcinv(x[(13, i)]);
            out[(14, i)] = round(x[(14, i)]);
            out[(15, i)] = rint(x[(15, i)]);
            out[(16, i)] = trunc(x[(16, i)]);
            out[(17, i)] = frac(x[(17, i)]);
            out[(18, i)] = degrees(x[(18, i)]);
            out[(19, i)] = radians(x[(19, i)]);
            out[(20, i)] = step(x[(20, i)]);
            out[(21, i)] = smoothstep(-1.0, 2.0, x[(21, i)]);
            out[(22, i)] = smoothstep(0.5, 0.5, x[(22, i)]);
            out[(23, i)] = wp::r#mod(x[(23, i)], 0.75);
            out[(24, i)] = $t::atan(x[(24, i)]);
        }
    };
}

scalar_math_kernel!(k_scalar_math_f32, f32);
scalar_math_kernel!(k_scalar_math_f64, f64);

fn scalar_math_inputs() -> Vec<f32> {
    INPUTS.iter().flatten().copied().collect()
}

fn scalar_math_f32(dev: &wp::Device) {
    let x =
        wp::Array::<f32, 2>::from_slice_shape(&scalar_math_inputs(), (COLS, ROWS), dev).unwrap();
    let out = zeros::<f32, 2>((COLS, ROWS), dev);
    wp::launch(k_scalar_math_f32, ROWS, (&x, &out), dev).unwrap();
    for (k, row) in host(&out).chunks(ROWS).enumerate() {
        let ulps = scalar_math_ulps(k, dev.is_cpu(), false);
        for (j, &got) in row.iter().enumerate() {
            let xin = INPUTS[k][j];
            let want = scalar_math_ref(k, xin as f64);
            // Compare with the reference rounded to f32 where it leaves the f32 range.
            let want = if (want as f32).is_finite() {
                want
            } else {
                want as f32 as f64
            };
            assert_ulps(
                got as f64,
                want,
                ulps.max(0.5),
                f32::EPSILON as f64,
                &format!("f32 column {k} at {xin:e}"),
            );
        }
    }
}

fn scalar_math_f64(dev: &wp::Device) {
    let xs: Vec<f64> = scalar_math_inputs().iter().map(|&v| v as f64).collect();
    let x = wp::Array::<f64, 2>::from_slice_shape(&xs, (COLS, ROWS), dev).unwrap();
    let out = zeros::<f64, 2>((COLS, ROWS), dev);
    wp::launch(k_scalar_math_f64, ROWS, (&x, &out), dev).unwrap();
    for (k, row) in host(&out).chunks(ROWS).enumerate() {
        let ulps = scalar_math_ulps(k, dev.is_cpu(), true);
        for (j, &got) in row.iter().enumerate() {
            let xin = INPUTS[k][j] as f64;
            let want = scalar_math_ref(k, xin);
            assert_ulps(
                got,
                want,
                ulps,
                f64::EPSILON,
                &format!("f64 column {k} at {xin:e}"),
            );
        }
    }
}

/// Rust method syntax for the new builtins: the same builtin as the function syntax, so the
/// results must agree exactly with the function-syntax kernel's; on the CPU they also equal
/// Rust's own methods.
#[wp::kernel]
fn k_scalar_math_methods(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let u = a * 0.1;
    out[(i, 0)] = u.asin();
    out[(i, 1)] = u.acos();
    out[(i, 2)] = a.atan();
    out[(i, 3)] = a.sinh();
    out[(i, 4)] = a.cosh();
    out[(i, 5)] = a.tanh();
    out[(i, 6)] = a.exp2();
    out[(i, 7)] = a.abs().log2();
    out[(i, 8)] = a.abs().log10();
    out[(i, 9)] = a.cbrt();
    out[(i, 10)] = a.round();
    out[(i, 11)] = a.round_ties_even();
    out[(i, 12)] = a.trunc();
    out[(i, 13)] = a.fract();
    out[(i, 14)] = a.to_degrees();
    out[(i, 15)] = a.to_radians();
    let f = if a.is_finite() { 1.0 } else { 0.0 };
    let n = if a.is_nan() { 2.0 } else { 0.0 };
    let inf = if a.is_infinite() { 4.0 } else { 0.0 };
    out[(i, 16)] = f + n + inf;
}

#[wp::kernel]
fn k_scalar_math_fns(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let u = a * 0.1;
    out[(i, 0)] = asin(u);
    out[(i, 1)] = acos(u);
    out[(i, 2)] = atan(a);
    out[(i, 3)] = sinh(a);
    out[(i, 4)] = cosh(a);
    out[(i, 5)] = tanh(a);
    out[(i, 6)] = exp2(a);
    out[(i, 7)] = log2(abs(a));
    out[(i, 8)] = log10(abs(a));
    out[(i, 9)] = cbrt(a);
    out[(i, 10)] = round(a);
    out[(i, 11)] = rint(a);
    out[(i, 12)] = trunc(a);
    out[(i, 13)] = frac(a);
    out[(i, 14)] = degrees(a);
    out[(i, 15)] = radians(a);
    let f = if isfinite(a) { 1.0 } else { 0.0 };
    let n = if isnan(a) { 2.0 } else { 0.0 };
    let inf = if isinf(a) { 4.0 } else { 0.0 };
    out[(i, 16)] = f + n + inf;
}

fn scalar_math_methods(dev: &wp::Device) {
    let xs = [
        -12.5f32,
        -2.5,
        -0.5,
        0.5,
        1.5,
        3.7,
        9.0,
        f32::NAN,
        f32::INFINITY,
    ];
    let n = xs.len();
    let (m, f) = (zeros::<f32, 2>((n, 17), dev), zeros::<f32, 2>((n, 17), dev));
    let x = arr(&xs, dev);
    wp::launch(k_scalar_math_methods, n, (&x, &m), dev).unwrap();
    wp::launch(k_scalar_math_fns, n, (&x, &f), dev).unwrap();
    let (m, f) = (host(&m), host(&f));
    for (k, (a, b)) in m.iter().zip(&f).enumerate() {
        assert!(
            a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
            "method vs function syntax, case {k}: {a:e} vs {b:e}"
        );
    }
    if dev.is_cpu() {
        for (i, row) in m.chunks(17).enumerate() {
            let a = xs[i];
            let u = a * 0.1;
            let want = [
                u.clamp(-1.0, 1.0).asin(),
                u.clamp(-1.0, 1.0).acos(),
                a.atan(),
                a.sinh(),
                a.cosh(),
                a.tanh(),
                a.exp2(),
                a.abs().log2(),
                a.abs().log10(),
                a.cbrt(),
                a.round(),
                a.round_ties_even(),
                a.trunc(),
                a.fract(),
                a.to_degrees(),
                a.to_radians(),
                a.is_finite() as u8 as f32
                    + 2.0 * a.is_nan() as u8 as f32
                    + 4.0 * a.is_infinite() as u8 as f32,
            ];
            for (k, (g, w)) in row.iter().zip(want).enumerate() {
                assert_close_f32(*g, w, 0.0, &format!("method {k} at {a}: Rust's meaning"));
            }
        }
    }
}

#[wp::kernel]
fn k_classify(x: Array<f64>, v: Array<Vec3>, out: Array<i32, 2>) {
    let i = tid();
    out[(i, 0)] = isfinite(x[i]) as i32;
    out[(i, 1)] = isnan(x[i]) as i32;
    out[(i, 2)] = isinf(x[i]) as i32;
    out[(i, 3)] = isfinite(v[i]) as i32;
    out[(i, 4)] = isnan(v[i]) as i32;
    out[(i, 5)] = v[i].is_infinite() as i32;
    out[(i, 6)] = step(i as i32 - 2);
    out[(i, 7)] = r#mod(i as i32 - 3, 2);
}

fn classification_builtins(dev: &wp::Device) {
    let xs = [
        0.0,
        -0.0,
        1e-310,
        f64::MAX,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NAN,
    ];
    let vs = [
        Vec3::ZERO,
        Vec3::new(1.0, f32::NAN, 0.0),
        Vec3::new(f32::INFINITY, 0.0, 0.0),
        Vec3::new(0.0, 0.0, f32::NEG_INFINITY),
        Vec3::new(f32::NAN, f32::INFINITY, 1.0),
        Vec3::splat(f32::MAX),
        Vec3::new(1e-40, -1.0, 2.0),
    ];
    let n = xs.len();
    let out = zeros::<i32, 2>((n, 8), dev);
    wp::launch(k_classify, n, (&arr(&xs, dev), &arr(&vs, dev), &out), dev).unwrap();
    for (i, row) in host(&out).chunks(8).enumerate() {
        let (x, v) = (xs[i], vs[i]);
        let a = v.to_array();
        let want = [
            x.is_finite() as i32,
            x.is_nan() as i32,
            x.is_infinite() as i32,
            a.iter().all(|c| c.is_finite()) as i32,
            a.iter().any(|c| c.is_nan()) as i32,
            a.iter().any(|c| c.is_infinite()) as i32,
            (i < 2) as i32,
            (i as i32 - 3) % 2,
        ];
        assert_eq!(row, want, "classification row {i}");
    }
}

// ------------------------------------------------------------------------------------------
// Vector, matrix and quaternion builtins (wp_linalg.h / warp-core builtins::linalg)
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_linalg64(
    m: Array<DMat3>,
    v: Array<DVec3>,
    q: Array<DQuat>,
    mo: Array<DMat3, 2>,
    vo: Array<DVec3, 2>,
    qo: Array<DQuat, 2>,
    so: Array<f64, 2>,
) {
    let i = tid();
    let a = m[i];
    let x = v[i];
    let r = q[i];
    mo[(i, 0)] = transpose(a);
    mo[(i, 1)] = a.transpose();
    mo[(i, 2)] = inverse(a);
    mo[(i, 3)] = a.inverse();
    mo[(i, 4)] = outer(x, x * 2.0);
    mo[(i, 5)] = diag(x);
    mo[(i, 6)] = skew(x);
    mo[(i, 7)] = cw_mul(a, a);
    mo[(i, 8)] = quat_to_matrix(r);
    mo[(i, 9)] = DMat3::from_quat(r);
    so[(i, 0)] = determinant(a);
    so[(i, 1)] = a.determinant();
    so[(i, 2)] = trace(a);
    so[(i, 3)] = ddot(a, a);
    so[(i, 4)] = length_sq(x);
    so[(i, 5)] = x.length_squared();
    so[(i, 6)] = dot(r, r);
    so[(i, 7)] = r.length();
    vo[(i, 0)] = quat_rotate(r, x);
    vo[(i, 1)] = quat_rotate_inv(r, x);
    vo[(i, 2)] = cw_div(x, DVec3::new(2.0, 4.0, 8.0));
    vo[(i, 3)] = skew(x) * DVec3::new(0.5, -1.0, 2.0);
    qo[(i, 0)] = normalize(r);
    qo[(i, 1)] = r.inverse();
    qo[(i, 2)] = quat_inverse(r);
    qo[(i, 3)] = quat_from_axis_angle(normalize(x), 0.75);
    qo[(i, 4)] = DQuat::from_axis_angle(normalize(x), 0.75);
    qo[(i, 5)] = quat_from_matrix(quat_to_matrix(normalize(r)));
    qo[(i, 6)] = quat_slerp(normalize(r), qo[(i, 3)], 0.25);
    qo[(i, 7)] = quat_slerp(normalize(r), normalize(r), 0.5);
}

#[wp::kernel]
fn k_linalg32(m: Array<Mat4>, v: Array<Vec4>, mo: Array<Mat4, 2>, so: Array<f32, 2>) {
    let i = tid();
    let a = m[i];
    let x = v[i];
    mo[(i, 0)] = a.inverse();
    mo[(i, 1)] = transpose(a);
    mo[(i, 2)] = outer(x, x);
    so[(i, 0)] = a.determinant();
    so[(i, 1)] = trace(a);
    so[(i, 2)] = length_sq(x);
}

/// Max over components of |got - want| / max(1, max |want|).
fn normwise(got: &[f64], want: &[f64]) -> f64 {
    let scale = want.iter().fold(1.0f64, |m, w| m.max(w.abs()));
    got.iter()
        .zip(want)
        .map(|(g, w)| if g == w { 0.0 } else { (g - w).abs() / scale })
        .fold(0.0, f64::max)
}

/// The f64 builtins against independent f64 formulas (Warp's definitions written out here);
/// f32 `Mat4` against the same formulas in f64. Tolerances: f64 1e-13 normwise (a few
/// roundings, at most ~30 operations on numbers of size ~1 with condition numbers below 20,
/// so under 100 ulp); f32 `Mat4` inverse and determinant 2e-5 normwise (cond(A) <= 20 times
/// f32's 6e-8 times the ~16 roundings of the cofactor expansion), products 1e-6. Quaternion
/// builtins that call sin/cos/atan2 get 1e-12 (f64) to allow CUDA's libdevice ulps.
fn linalg_builtins(dev: &wp::Device) {
    let ms = [
        DMat3::from_cols(
            DVec3::new(2.0, 0.5, -1.0),
            DVec3::new(0.3, 3.0, 0.2),
            DVec3::new(-0.7, 0.1, 1.5),
        ),
        DMat3::from_cols(DVec3::X, DVec3::Y, DVec3::X), // singular
        DMat3::IDENTITY,
        DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0)), // 180 degrees about x
    ];
    let vs = [
        DVec3::new(0.3, -1.2, 2.0),
        DVec3::new(1.0, 0.0, 0.0),
        DVec3::new(-0.5, 0.25, 0.125),
        DVec3::new(0.0, 2.0, -1.0),
    ];
    let qs = [
        DQuat::from_xyzw(0.1, 0.2, -0.3, 0.9),
        DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0), // normalize gives the identity
        DQuat::from_xyzw(1.0, 2.0, 3.0, 4.0),
        DQuat::from_xyzw(0.0, 0.0, 1.0, 0.0), // 180 degrees about z
    ];
    let n = ms.len();
    let (mo, vo) = (
        zeros::<DMat3, 2>((n, 10), dev),
        zeros::<DVec3, 2>((n, 4), dev),
    );
    let (qo, so) = (zeros::<DQuat, 2>((n, 8), dev), zeros::<f64, 2>((n, 8), dev));
    wp::launch(
        k_linalg64,
        n,
        (
            &arr(&ms, dev),
            &arr(&vs, dev),
            &arr(&qs, dev),
            &mo,
            &vo,
            &qo,
            &so,
        ),
        dev,
    )
    .unwrap();
    let (mo, vo, qo, so) = (host(&mo), host(&vo), host(&qo), host(&so));
    let tol = 1e-13;
    let tol_tr = 1e-12;
    let cols = |m: DMat3| m.to_cols_array();
    for i in 0..n {
        let (a, x, r) = (ms[i], vs[i], qs[i]);
        let e = |k: usize, c: usize| a.col(k)[c];
        let det = e(0, 0) * (e(1, 1) * e(2, 2) - e(2, 1) * e(1, 2))
            - e(1, 0) * (e(0, 1) * e(2, 2) - e(2, 1) * e(0, 2))
            + e(2, 0) * (e(0, 1) * e(1, 2) - e(1, 1) * e(0, 2));
        // Warp's inverse: the adjugate over det, zero when det == 0.
        let inv = if det == 0.0 {
            DMat3::ZERO
        } else {
            DMat3::from_cols_array(&std::array::from_fn(|k| {
                let (c, rr) = (k / 3, k % 3);
                let (c1, c2) = ((rr + 1) % 3, (rr + 2) % 3);
                let (r1, r2) = ((c + 1) % 3, (c + 2) % 3);
                (e(c1, r1) * e(c2, r2) - e(c2, r1) * e(c1, r2)) / det
            }))
        };
        let tr: DMat3 = DMat3::from_cols_array(&std::array::from_fn(|k| e(k % 3, k / 3)));
        let outer = DMat3::from_cols(x * (2.0 * x.x), x * (2.0 * x.y), x * (2.0 * x.z));
        let skew = DMat3::from_cols(
            DVec3::new(0.0, x.z, -x.y),
            DVec3::new(-x.z, 0.0, x.x),
            DVec3::new(x.y, -x.x, 0.0),
        );
        let sq = DMat3::from_cols_array(&cols(a).map(|c| c * c));
        // Rotation matrix of r by rotating the axes (Warp's quat_to_matrix), exact for unit r.
        let rot = |q: DQuat, v: DVec3| {
            let b = DVec3::new(q.x, q.y, q.z);
            v * (q.w * q.w - b.dot(b)) + b * (2.0 * v.dot(b)) + b.cross(v) * (2.0 * q.w)
        };
        let want_m = [tr, tr, inv, inv, outer, DMat3::from_diagonal(x), skew, sq];
        for (k, w) in want_m.iter().enumerate() {
            let d = normwise(&cols(mo[i * 10 + k]), &cols(*w));
            assert!(
                d <= tol,
                "matrix builtin #{k} of row {i}: {:?} vs {w:?} ({d:e})",
                mo[i * 10 + k]
            );
        }
        let len2 = r.x * r.x + r.y * r.y + r.z * r.z + r.w * r.w;
        if (len2 - 1.0).abs() < 1e-12 || i == 3 {
            let m = DMat3::from_cols(rot(r, DVec3::X), rot(r, DVec3::Y), rot(r, DVec3::Z));
            for k in [8, 9] {
                assert!(
                    normwise(&cols(mo[i * 10 + k]), &cols(m)) <= tol,
                    "quat_to_matrix {i}"
                );
            }
        }
        let want_s = [
            det,
            det,
            e(0, 0) + e(1, 1) + e(2, 2),
            cols(a).iter().map(|c| c * c).sum(),
            x.dot(x),
            x.dot(x),
            len2,
            len2.sqrt(),
        ];
        for (k, w) in want_s.iter().enumerate() {
            let d = normwise(&[so[i * 8 + k]], &[*w]);
            assert!(
                d <= tol,
                "scalar builtin #{k} of row {i}: {} vs {w} ({d:e})",
                so[i * 8 + k]
            );
        }
        let rinv = DQuat::from_xyzw(-r.x, -r.y, -r.z, r.w);
        let want_v = [
            rot(r, x),
            rot(rinv, x),
            DVec3::new(x.x / 2.0, x.y / 4.0, x.z / 8.0),
            x.cross(DVec3::new(0.5, -1.0, 2.0)),
        ];
        for (k, w) in want_v.iter().enumerate() {
            let d = normwise(&vo[i * 4 + k].to_array(), &w.to_array());
            assert!(
                d <= tol,
                "vector builtin #{k} of row {i}: {} vs {w} ({d:e})",
                vo[i * 4 + k]
            );
        }
        let unit = if len2 > 0.0 {
            r / len2.sqrt()
        } else {
            DQuat::IDENTITY
        };
        let ax = x / x.length();
        let (s, c) = (0.375f64.sin(), 0.375f64.cos());
        let aa = DQuat::from_xyzw(ax.x * s, ax.y * s, ax.z * s, c);
        let qa = |k: usize| qo[i * 8 + k].to_array();
        let close = |k: usize, w: DQuat, t: f64, what: &str| {
            let d = normwise(&qa(k), &w.to_array());
            assert!(
                d <= t,
                "{what} of row {i}: {:?} vs {w:?} ({d:e})",
                qo[i * 8 + k]
            );
        };
        close(0, unit, tol, "normalize");
        close(1, rinv, 0.0, "inverse");
        close(2, rinv, 0.0, "quat_inverse");
        close(3, aa, tol_tr, "quat_from_axis_angle");
        close(4, aa, tol_tr, "Quat::from_axis_angle");
        // from_matrix(to_matrix(q)) is q or -q (the same rotation).
        let back = qo[i * 8 + 5];
        let sgn = if back.dot(unit) < 0.0 { -1.0 } else { 1.0 };
        close(5, unit * sgn, tol_tr, "quat_from_matrix(quat_to_matrix(q))");
        // slerp at t = 1/4 from unit to aa, along the short path: rotation angle a quarter.
        let rel = DQuat::from_xyzw(-unit.x, -unit.y, -unit.z, unit.w) * aa;
        let (half, vlen) = (rel.w.abs(), DVec3::new(rel.x, rel.y, rel.z).length());
        let angle = 2.0 * vlen.atan2(half);
        let axis = DVec3::new(rel.x, rel.y, rel.z) / vlen * rel.w.signum();
        let step = DQuat::from_xyzw(
            axis.x * (0.125 * angle).sin(),
            axis.y * (0.125 * angle).sin(),
            axis.z * (0.125 * angle).sin(),
            (0.125 * angle).cos(),
        );
        close(6, unit * step, tol_tr, "quat_slerp");
        close(7, unit, 0.0, "quat_slerp of identical quaternions");
    }
    // Edge cases, exactly: the singular inverse is zero, the zero quaternion normalizes to the
    // identity, the 180-degree rotation about x comes back as (1, 0, 0, 0).
    assert_eq!(mo[10 + 2], DMat3::ZERO, "inverse of a singular matrix");
    assert_eq!(qo[8], DQuat::IDENTITY, "normalize of the zero quaternion");
    let m180 = host_from_matrix_180(dev);
    assert_eq!(m180, DQuat::from_xyzw(1.0, 0.0, 0.0, 0.0));

    // f32 Mat4.
    let m4 = [
        Mat4::from_cols(
            vec4(2.0, 0.5, -1.0, 0.1),
            vec4(0.3, 3.0, 0.2, -0.4),
            vec4(-0.7, 0.1, 1.5, 0.3),
            vec4(0.2, -0.3, 0.4, 2.5),
        ),
        Mat4::from_cols(Vec4::X, Vec4::Y, Vec4::Z, Vec4::X), // singular
    ];
    let v4 = [vec4(1.0, -2.0, 0.5, 3.0), vec4(0.25, 0.0, -1.0, 2.0)];
    let (mo, so) = (zeros::<Mat4, 2>((2, 3), dev), zeros::<f32, 2>((2, 3), dev));
    wp::launch(
        k_linalg32,
        2,
        (&arr(&m4, dev), &arr(&v4, dev), &mo, &so),
        dev,
    )
    .unwrap();
    let (mo, so) = (host(&mo), host(&so));
    for i in 0..2 {
        let a = m4[i].as_dmat4();
        let det = a.determinant();
        let inv = if det == 0.0 { DMat4::ZERO } else { a.inverse() };
        let f = |m: Mat4| m.as_dmat4().to_cols_array();
        let d = normwise(&f(mo[i * 3]), &inv.to_cols_array());
        assert!(d <= 2e-5, "Mat4 inverse {i}: {d:e}");
        assert!(
            normwise(&[so[i * 3] as f64], &[det]) <= 2e-5,
            "Mat4 determinant {i}"
        );
        assert_eq!(mo[i * 3 + 1], m4[i].transpose());
        let x = v4[i].as_dvec4();
        let o = DMat4::from_cols(x * x.x, x * x.y, x * x.z, x * x.w);
        assert!(normwise(&f(mo[i * 3 + 2]), &o.to_cols_array()) <= 1e-6);
        assert!(
            normwise(
                &[so[i * 3 + 1] as f64],
                &[a.x_axis.x + a.y_axis.y + a.z_axis.z + a.w_axis.w]
            ) <= 1e-6
        );
        assert!(normwise(&[so[i * 3 + 2] as f64], &[x.dot(x)]) <= 1e-6);
    }
    assert_eq!(mo[3], Mat4::ZERO, "inverse of a singular Mat4");
}

#[wp::kernel]
fn k_from_matrix(m: Array<DMat3>, q: Array<DQuat>) {
    let i = tid();
    q[i] = quat_from_matrix(m[i]);
}

fn host_from_matrix_180(dev: &wp::Device) -> DQuat {
    let m = arr(&[DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0))], dev);
    let q = zeros::<DQuat, 1>(1, dev);
    wp::launch(k_from_matrix, 1, (&m, &q), dev).unwrap();
    host(&q)[0]
}

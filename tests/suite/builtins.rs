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

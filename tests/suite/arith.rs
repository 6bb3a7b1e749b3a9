//! Arithmetic: integer operators with CUDA's wrapping semantics, float, vector, matrix and
//! quaternion arithmetic, comparisons, `&&`/`||` short-circuit, unary operators, `as` casts,
//! compound assignment, the literal rule, path constants and glam constructors.

use crate::{arr, assert_close_f32, assert_close_slice, fma_rel, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    i32_operators,
    u8_operators,
    i64_operators,
    integer_wrapping,
    compound_assign_locals,
    compound_assign_elements,
    float_operators,
    vector_operators,
    int_vector_operators,
    int_vector_bitwise,
    int_vector_wrapping,
    int_vector_division_by_zero,
    matrix_operators,
    quat_operators,
    comparisons,
    short_circuit_and,
    short_circuit_or,
    short_circuit_skips_side_effects,
    unary_operators,
    float_casts,
    int_casts,
    literal_rule,
    constants,
    glam_constructors,
);

// ------------------------------------------------------------------------------ integers

#[wp::kernel]
fn k_i32_ops(a: Array<i32>, b: Array<i32>, out: Array<i32, 2>) {
    let i = tid();
    let x = a[i];
    let y = b[i];
    out[(i, 0)] = x + y;
    out[(i, 1)] = x - y;
    out[(i, 2)] = x * y;
    out[(i, 3)] = x / y;
    out[(i, 4)] = x % y;
    out[(i, 5)] = x & y;
    out[(i, 6)] = x | y;
    out[(i, 7)] = x ^ y;
    out[(i, 8)] = x << y;
    out[(i, 9)] = x >> y;
}

/// Shift amounts are taken modulo the bit width (`wrapping_shl`), as the language defines.
fn i32_ops_ref(x: i32, y: i32) -> [i32; 10] {
    [
        x.wrapping_add(y),
        x.wrapping_sub(y),
        x.wrapping_mul(y),
        x.wrapping_div(y),
        x.wrapping_rem(y),
        x & y,
        x | y,
        x ^ y,
        x.wrapping_shl(y as u32),
        x.wrapping_shr(y as u32),
    ]
}

fn i32_operators(dev: &wp::Device) {
    let pairs = [
        (7, 3),
        (-7, 3),
        (7, -3),
        (-7, -3),
        (i32::MAX, 1),
        (i32::MIN, -1),
        (i32::MIN, 1),
        (123_456_789, 1000),
        (-1, 33),
        (5, -1),
        (0x0F0F, 0x00FF),
        (1, 31),
        (i32::MIN, 31),
        (-100, 2),
    ];
    let (a, b): (Vec<i32>, Vec<i32>) = pairs.iter().copied().unzip();
    let out = zeros::<i32, 2>((pairs.len(), 10), dev);
    wp::launch(
        k_i32_ops,
        pairs.len(),
        (&arr(&a, dev), &arr(&b, dev), &out),
        dev,
    )
    .unwrap();
    for (row, &(x, y)) in host(&out).chunks(10).zip(&pairs) {
        assert_eq!(
            row,
            i32_ops_ref(x, y),
            "x = {x}, y = {y}: + - * / % & | ^ << >>"
        );
    }
}

#[wp::kernel]
fn k_u8_ops(a: Array<u8>, b: Array<u8>, out: Array<u8, 2>) {
    let i = tid();
    let x = a[i];
    let y = b[i];
    out[(i, 0)] = x + y;
    out[(i, 1)] = x - y;
    out[(i, 2)] = x * y;
    out[(i, 3)] = x / y;
    out[(i, 4)] = x % y;
    out[(i, 5)] = x & y;
    out[(i, 6)] = x | y;
    out[(i, 7)] = x ^ y;
    out[(i, 8)] = x << y;
    out[(i, 9)] = x >> y;
}

fn u8_operators(dev: &wp::Device) {
    let pairs: [(u8, u8); 8] = [
        (200, 100),
        (255, 1),
        (0, 1),
        (17, 5),
        (1, 9),
        (128, 7),
        (3, 200),
        (0xF0, 0x3C),
    ];
    let (a, b): (Vec<u8>, Vec<u8>) = pairs.iter().copied().unzip();
    let out = zeros::<u8, 2>((pairs.len(), 10), dev);
    wp::launch(
        k_u8_ops,
        pairs.len(),
        (&arr(&a, dev), &arr(&b, dev), &out),
        dev,
    )
    .unwrap();
    for (row, &(x, y)) in host(&out).chunks(10).zip(&pairs) {
        let want = [
            x.wrapping_add(y),
            x.wrapping_sub(y),
            x.wrapping_mul(y),
            x / y,
            x % y,
            x & y,
            x | y,
            x ^ y,
            x.wrapping_shl(u32::from(y)),
            x.wrapping_shr(u32::from(y)),
        ];
        assert_eq!(row, want, "x = {x}, y = {y}: + - * / % & | ^ << >>");
    }
}

#[wp::kernel]
fn k_i64_ops(a: Array<i64>, b: Array<i64>, out: Array<i64, 2>) {
    let i = tid();
    let x = a[i];
    let y = b[i];
    out[(i, 0)] = x + y;
    out[(i, 1)] = x - y;
    out[(i, 2)] = x * y;
    out[(i, 3)] = x / y;
    out[(i, 4)] = x % y;
    out[(i, 5)] = x & y;
    out[(i, 6)] = x | y;
    out[(i, 7)] = x ^ y;
    out[(i, 8)] = x << y;
    out[(i, 9)] = x >> y;
}

fn i64_operators(dev: &wp::Device) {
    let pairs: [(i64, i64); 7] = [
        (5_000_000_000, 3),
        (-5_000_000_000, 7),
        (i64::MAX, 2),
        (i64::MIN, -1),
        (1, 63),
        (-1, 65),
        (0x0123_4567_89AB_CDEF, -0x00FF_00FF),
    ];
    let (a, b): (Vec<i64>, Vec<i64>) = pairs.iter().copied().unzip();
    let out = zeros::<i64, 2>((pairs.len(), 10), dev);
    wp::launch(
        k_i64_ops,
        pairs.len(),
        (&arr(&a, dev), &arr(&b, dev), &out),
        dev,
    )
    .unwrap();
    for (row, &(x, y)) in host(&out).chunks(10).zip(&pairs) {
        let want = [
            x.wrapping_add(y),
            x.wrapping_sub(y),
            x.wrapping_mul(y),
            x.wrapping_div(y),
            x.wrapping_rem(y),
            x & y,
            x | y,
            x ^ y,
            x.wrapping_shl(y as u32),
            x.wrapping_shr(y as u32),
        ];
        assert_eq!(row, want, "x = {x}, y = {y}: + - * / % & | ^ << >>");
    }
}

/// Overflow wraps like CUDA and never panics, even in a debug build; the constants come from
/// paths (`i32::MAX`) inside the kernel.
#[wp::kernel]
fn k_wrap(one: i32, out: Array<i32>, out64: Array<i64>, out8: Array<i8>) {
    let big = i32::MAX;
    let small = i32::MIN;
    out[0] = big + one;
    out[1] = small - one;
    out[2] = big * 2;
    out[3] = -small;
    out[4] = small / -one;
    out[5] = small % -one;
    out[6] = big + big;
    let mut acc = big;
    acc += one;
    out[7] = acc;
    out64[0] = i64::MAX + 1;
    out64[1] = i64::MIN * -1;
    let m = i8::MIN;
    out8[0] = m - 1;
    out8[1] = -m;
}

fn integer_wrapping(dev: &wp::Device) {
    let (out, out64, out8) = (
        zeros::<i32, 1>(8, dev),
        zeros::<i64, 1>(2, dev),
        zeros::<i8, 1>(2, dev),
    );
    wp::launch(k_wrap, 1, (1, &out, &out64, &out8), dev).unwrap();
    let (big, small) = (i32::MAX, i32::MIN);
    assert_eq!(
        host(&out),
        vec![
            big.wrapping_add(1),
            small.wrapping_sub(1),
            big.wrapping_mul(2),
            small.wrapping_neg(),
            small.wrapping_div(-1),
            small.wrapping_rem(-1),
            big.wrapping_add(big),
            big.wrapping_add(1),
        ]
    );
    assert_eq!(host(&out64), vec![i64::MIN, i64::MIN]);
    assert_eq!(host(&out8), vec![i8::MAX, i8::MIN]);
}

#[wp::kernel]
fn k_compound_locals(
    a: Array<i32>,
    b: Array<i32>,
    fa: Array<f32>,
    out: Array<i32, 2>,
    fout: Array<f32, 2>,
) {
    let i = tid();
    let y = b[i];
    let mut x = a[i];
    x += y;
    out[(i, 0)] = x;
    x -= 3;
    out[(i, 1)] = x;
    x *= y;
    out[(i, 2)] = x;
    x /= 2;
    out[(i, 3)] = x;
    x %= 1000;
    out[(i, 4)] = x;
    x &= 0xff;
    out[(i, 5)] = x;
    x |= y;
    out[(i, 6)] = x;
    x ^= 0x55;
    out[(i, 7)] = x;
    x <<= 3;
    out[(i, 8)] = x;
    x >>= 1;
    out[(i, 9)] = x;
    let mut f = fa[i];
    f += 1.5;
    fout[(i, 0)] = f;
    f -= 0.25;
    fout[(i, 1)] = f;
    f *= 3.0;
    fout[(i, 2)] = f;
    f /= 4.0;
    fout[(i, 3)] = f;
    f %= 2.0;
    fout[(i, 4)] = f;
}

fn compound_assign_locals(dev: &wp::Device) {
    let a = [10, -7, i32::MAX, 12345];
    let b = [3, 5, 2, -9];
    let fa = [1.0f32, -2.5, 0.1, 1e6];
    let (out, fout) = (zeros::<i32, 2>((4, 10), dev), zeros::<f32, 2>((4, 5), dev));
    wp::launch(
        k_compound_locals,
        4,
        (&arr(&a, dev), &arr(&b, dev), &arr(&fa, dev), &out, &fout),
        dev,
    )
    .unwrap();
    let (out, fout) = (host(&out), host(&fout));
    for i in 0..4 {
        let y = b[i];
        let mut x = a[i];
        let mut want = Vec::new();
        x = x.wrapping_add(y);
        want.push(x);
        x = x.wrapping_sub(3);
        want.push(x);
        x = x.wrapping_mul(y);
        want.push(x);
        x /= 2;
        want.push(x);
        x %= 1000;
        want.push(x);
        x &= 0xff;
        want.push(x);
        x |= y;
        want.push(x);
        x ^= 0x55;
        want.push(x);
        x = x.wrapping_shl(3);
        want.push(x);
        x >>= 1;
        want.push(x);
        assert_eq!(&out[i * 10..i * 10 + 10], want.as_slice(), "row {i}");
        let mut f = fa[i];
        let mut fwant = Vec::new();
        f += 1.5;
        fwant.push(f);
        f -= 0.25;
        fwant.push(f);
        f *= 3.0;
        fwant.push(f);
        f /= 4.0;
        fwant.push(f);
        f %= 2.0;
        fwant.push(f);
        // Each step is one IEEE operation: exact on every backend.
        assert_eq!(&fout[i * 5..i * 5 + 5], fwant.as_slice(), "float row {i}");
    }
}

#[wp::kernel]
fn k_compound_elems(b: Array<i32>, o: Array<i32, 2>, v: Array<Vec3>, w: Array<Vec3>) {
    let i = tid();
    let y = b[i];
    o[(i, 0)] += y;
    o[(i, 1)] -= y;
    o[(i, 2)] *= y;
    o[(i, 3)] /= y;
    o[(i, 4)] %= y;
    o[(i, 5)] &= y;
    o[(i, 6)] |= y;
    o[(i, 7)] ^= y;
    o[(i, 8)] <<= y;
    o[(i, 9)] >>= y;
    v[i] += w[i];
    v[i] *= 2.0;
    v[i] -= Vec3::ONE;
    v[i] /= 4.0;
    v[i] *= w[i];
}

fn compound_assign_elements(dev: &wp::Device) {
    let b = [3, -5, 7, 33];
    let init: Vec<i32> = (0..40).map(|k| k * 7919 - 100_000).collect();
    let o = wp::Array::from_slice_shape(&init, (4, 10), dev).unwrap();
    let v0 = [
        vec3(1.0, 2.0, 3.0),
        vec3(-1.0, 0.5, 0.25),
        vec3(0.1, 0.2, 0.3),
        Vec3::ZERO,
    ];
    let w = [
        vec3(0.5, 0.5, 0.5),
        vec3(2.0, -3.0, 4.0),
        vec3(0.3, 0.2, 0.1),
        Vec3::ONE,
    ];
    let v = arr(&v0, dev);
    wp::launch(
        k_compound_elems,
        4,
        (&arr(&b, dev), &o, &v, &arr(&w, dev)),
        dev,
    )
    .unwrap();
    let got = host(&o);
    for i in 0..4 {
        let y = b[i];
        let x = &init[i * 10..i * 10 + 10];
        let want = [
            x[0].wrapping_add(y),
            x[1].wrapping_sub(y),
            x[2].wrapping_mul(y),
            x[3].wrapping_div(y),
            x[4].wrapping_rem(y),
            x[5] & y,
            x[6] | y,
            x[7] ^ y,
            x[8].wrapping_shl(y as u32),
            x[9].wrapping_shr(y as u32),
        ];
        assert_eq!(&got[i * 10..i * 10 + 10], want, "row {i}");
    }
    for (i, got) in host(&v).into_iter().enumerate() {
        let want = ((v0[i] + w[i]) * 2.0 - Vec3::ONE) / 4.0 * w[i];
        // One rounding per step, and no step is a multiply feeding an add: exact everywhere.
        assert_eq!(got, want, "vector element {i}");
    }
}

// ------------------------------------------------------------------------------ floats

#[wp::kernel]
fn k_float_ops(
    a: Array<f32>,
    b: Array<f32>,
    c: Array<f32>,
    out: Array<f32, 2>,
    da: Array<f64>,
    db: Array<f64>,
    dout: Array<f64, 2>,
) {
    let i = tid();
    let x = a[i];
    let y = b[i];
    out[(i, 0)] = x + y;
    out[(i, 1)] = x - y;
    out[(i, 2)] = x * y;
    out[(i, 3)] = x / y;
    out[(i, 4)] = x % y;
    out[(i, 5)] = x * y + c[i];
    let p = da[i];
    let q = db[i];
    dout[(i, 0)] = p + q;
    dout[(i, 1)] = p - q;
    dout[(i, 2)] = p * q;
    dout[(i, 3)] = p / q;
    dout[(i, 4)] = p % q;
}

fn float_operators(dev: &wp::Device) {
    let a = [1.5f32, -0.1, 1e30, 3.0, 0.0, 7.25];
    let b = [0.25f32, 0.3, 1e-30, 0.0, -2.0, -1.5];
    let c = [1.0f32, -1.0, 0.5, 2.0, 1e-7, 3.3];
    let n = a.len();
    let da: Vec<f64> = a.iter().map(|&x| f64::from(x) * 1.1).collect();
    let db: Vec<f64> = b.iter().map(|&x| f64::from(x) + 0.01).collect();
    let (out, dout) = (zeros::<f32, 2>((n, 6), dev), zeros::<f64, 2>((n, 5), dev));
    wp::launch(
        k_float_ops,
        n,
        (
            &arr(&a, dev),
            &arr(&b, dev),
            &arr(&c, dev),
            &out,
            &arr(&da, dev),
            &arr(&db, dev),
            &dout,
        ),
        dev,
    )
    .unwrap();
    let (out, dout) = (host(&out), host(&dout));
    for i in 0..n {
        let (x, y) = (a[i], b[i]);
        // Single IEEE operations (division by zero included: inf, no fault): exact everywhere.
        let row = &out[i * 6..i * 6 + 6];
        let want = [x + y, x - y, x * y, x / y, x % y];
        for k in 0..5 {
            assert_close_f32(row[k], want[k], 0.0, &format!("f32 op {k} on ({x}, {y})"));
        }
        // `x * y + c` may become one FMA on CUDA.
        assert_close_f32(row[5], x * y + c[i], fma_rel(dev), "x * y + c");
        let (p, q) = (da[i], db[i]);
        assert_eq!(
            &dout[i * 5..i * 5 + 5],
            [p + q, p - q, p * q, p / q, p % q],
            "f64 ops on ({p}, {q})"
        );
    }
}

#[wp::kernel]
fn k_vec_ops(
    a: Array<Vec3>,
    b: Array<Vec3>,
    s: f32,
    out: Array<Vec3, 2>,
    da: Array<DVec2>,
    dout: Array<DVec2, 2>,
) {
    let i = tid();
    let v = a[i];
    let w = b[i];
    out[(i, 0)] = v * s;
    out[(i, 1)] = s * v;
    out[(i, 2)] = v + w;
    out[(i, 3)] = v - w;
    out[(i, 4)] = v * w;
    out[(i, 5)] = v / w;
    out[(i, 6)] = v / s;
    out[(i, 7)] = -v;
    out[(i, 8)] = 2.0 * v + w * 0.5;
    out[(i, 9)] = v * 3;
    let d = da[i];
    dout[(i, 0)] = d * 0.1;
    dout[(i, 1)] = 0.1 * d;
    dout[(i, 2)] = d + d * d;
    dout[(i, 3)] = -d / 3;
}

fn vector_operators(dev: &wp::Device) {
    let a = [
        vec3(1.0, 2.0, 3.0),
        vec3(-0.1, 0.2, -0.3),
        vec3(1e20, -1e-20, 0.0),
    ];
    let b = [
        vec3(4.0, -5.0, 6.0),
        vec3(0.7, 0.11, 13.0),
        vec3(3.0, 2.0, 1.0),
    ];
    let s = 0.3f32;
    let da = [dvec2(0.1, 0.2), dvec2(-1e100, 3.0), dvec2(7.0, -0.5)];
    let out = zeros::<Vec3, 2>((3, 10), dev);
    let dout = zeros::<DVec2, 2>((3, 4), dev);
    wp::launch(
        k_vec_ops,
        3,
        (&arr(&a, dev), &arr(&b, dev), s, &out, &arr(&da, dev), &dout),
        dev,
    )
    .unwrap();
    let (out, dout) = (host(&out), host(&dout));
    for i in 0..3 {
        let (v, w) = (a[i], b[i]);
        // Single IEEE operations per component (2.0 * v and w * 0.5 are exact, so the sum has
        // one rounding even when fused): exact everywhere.
        let want = [
            v * s,
            s * v,
            v + w,
            v - w,
            v * w,
            v / w,
            v / s,
            -v,
            2.0 * v + w * 0.5,
            v * 3.0,
        ];
        assert_eq!(&out[i * 10..i * 10 + 10], want, "Vec3 row {i}");
        let d = da[i];
        assert_eq!(dout[i * 4], d * 0.1, "DVec2 * literal (f64, not 0.1f32)");
        assert_eq!(dout[i * 4 + 1], 0.1 * d);
        // `d + d * d` may be fused on CUDA.
        let (g, want) = (dout[i * 4 + 2], d + d * d);
        crate::assert_close_f64(g.x, want.x, crate::fma_rel64(dev), "d + d * d (x)");
        crate::assert_close_f64(g.y, want.y, crate::fma_rel64(dev), "d + d * d (y)");
        assert_eq!(dout[i * 4 + 3], -d / 3.0);
    }
}

#[wp::kernel]
fn k_ivec_ops(
    a: Array<IVec3>,
    b: Array<IVec3>,
    u: Array<UVec2>,
    out: Array<IVec3, 2>,
    uout: Array<UVec2, 2>,
) {
    let i = tid();
    let v = a[i];
    let w = b[i];
    out[(i, 0)] = v + w;
    out[(i, 1)] = v - w;
    out[(i, 2)] = v * w;
    out[(i, 3)] = v / w;
    out[(i, 4)] = v * 3;
    // `2 * v` (integer scalar times integer vector) does not compile: see the report.
    out[(i, 5)] = v * 2;
    out[(i, 6)] = -v;
    out[(i, 7)] = v % w;
    let x = u[i];
    uout[(i, 0)] = x + x;
    uout[(i, 1)] = x * 5;
    uout[(i, 2)] = x / 2;
}

fn int_vector_operators(dev: &wp::Device) {
    let a = [ivec3(1, -2, 3), ivec3(100, 7, -7), ivec3(-9, 0, 5)];
    let b = [ivec3(4, 5, -6), ivec3(3, -2, 2), ivec3(2, 1, -5)];
    let u = [uvec2(1, 2), uvec2(100, 7), uvec2(9, 0)];
    let (out, uout) = (
        zeros::<IVec3, 2>((3, 8), dev),
        zeros::<UVec2, 2>((3, 3), dev),
    );
    wp::launch(
        k_ivec_ops,
        3,
        (&arr(&a, dev), &arr(&b, dev), &arr(&u, dev), &out, &uout),
        dev,
    )
    .unwrap();
    let (out, uout) = (host(&out), host(&uout));
    for i in 0..3 {
        let (v, w) = (a[i], b[i]);
        assert_eq!(
            &out[i * 8..i * 8 + 8],
            [v + w, v - w, v * w, v / w, v * 3, v * 2, -v, v % w],
            "IVec3 row {i}"
        );
        let x = u[i];
        assert_eq!(
            &uout[i * 3..i * 3 + 3],
            [x + x, x * 5, x / 2],
            "UVec2 row {i}"
        );
    }
}

/// Bitwise operators and shifts on integer vectors, lane by lane (glam's meaning), with
/// scalars splatted; shift amounts are taken modulo the bit width like scalars' (no panic).
#[wp::kernel]
fn k_ivec_bits(
    a: Array<IVec3>,
    b: Array<IVec3>,
    u: Array<UVec4>,
    out: Array<IVec3, 2>,
    uout: Array<UVec4, 2>,
) {
    let i = tid();
    let v = a[i];
    let w = b[i];
    out[(i, 0)] = v & w;
    out[(i, 1)] = v | w;
    out[(i, 2)] = v ^ w;
    out[(i, 3)] = !v;
    out[(i, 4)] = (v << 3) >> 1;
    out[(i, 5)] = v & 6;
    out[(i, 6)] = 12 ^ w;
    let mut x = u[i];
    x |= UVec4::splat(0x100);
    x ^= u[i] << 33u32;
    uout[(i, 0)] = x;
    uout[(i, 1)] = !u[i] >> 28;
}

fn int_vector_bitwise(dev: &wp::Device) {
    let a = [
        ivec3(1, -2, 0x7fff_ffff),
        ivec3(100, 7, -7),
        ivec3(-9, 0, 5),
    ];
    let b = [ivec3(4, 5, -6), ivec3(3, -2, 2), ivec3(2, 1, -5)];
    let u = [
        uvec4(1, 2, 3, u32::MAX),
        uvec4(100, 7, 0, 9),
        uvec4(9, 0, 1 << 31, 6),
    ];
    let (out, uout) = (
        zeros::<IVec3, 2>((3, 7), dev),
        zeros::<UVec4, 2>((3, 2), dev),
    );
    wp::launch(
        k_ivec_bits,
        3,
        (&arr(&a, dev), &arr(&b, dev), &arr(&u, dev), &out, &uout),
        dev,
    )
    .unwrap();
    let (out, uout) = (host(&out), host(&uout));
    let wrap = |v: IVec3, f: fn(i32) -> i32| IVec3::from_array(v.to_array().map(f));
    let wrapu = |v: UVec4, f: fn(u32) -> u32| UVec4::from_array(v.to_array().map(f));
    for i in 0..3 {
        let (v, w) = (a[i], b[i]);
        assert_eq!(
            &out[i * 7..i * 7 + 7],
            [
                v & w,
                v | w,
                v ^ w,
                !v,
                wrap(wrap(v, |x| x.wrapping_shl(3)), |x| x >> 1),
                v & IVec3::splat(6),
                IVec3::splat(12) ^ w,
            ],
            "IVec3 row {i}"
        );
        // `<< 33` on u32 lanes shifts by 33 mod 32 = 1.
        let x = (u[i] | UVec4::splat(0x100)) ^ wrapu(u[i], |x| x.wrapping_shl(33));
        assert_eq!(
            &uout[i * 2..i * 2 + 2],
            [x, wrapu(!u[i], |x| x >> 28)],
            "UVec4 row {i}"
        );
    }
}

/// Integer vectors wrap componentwise like integer scalars (CUDA semantics), without a
/// debug-build overflow panic.
#[wp::kernel]
fn k_ivec_wrap(a: IVec2, out: Array<IVec2>) {
    out[0] = a + IVec2::ONE;
    out[1] = a * 2;
    out[2] = -(a + IVec2::ONE);
}

fn int_vector_wrapping(dev: &wp::Device) {
    let out = zeros::<IVec2, 1>(3, dev);
    let a = IVec2::splat(i32::MAX);
    wp::launch(k_ivec_wrap, 1, (a, &out), dev).unwrap();
    let wrapped = IVec2::splat(i32::MIN);
    assert_eq!(host(&out), vec![wrapped, IVec2::splat(-2), wrapped]);
}

#[wp::kernel]
fn k_ivec_div(a: IVec2, b: IVec2, out: Array<IVec2>) {
    out[0] = a / b;
}

/// Like integer scalars, integer vectors fault on division by zero instead of panicking.
fn int_vector_division_by_zero(dev: &wp::Device) {
    let out = zeros::<IVec2, 1>(1, dev);
    let r = wp::launch(k_ivec_div, 1, (ivec2(1, 2), ivec2(1, 0), &out), dev);
    assert!(
        matches!(&r, Err(wp::Error::Fault(f)) if f.kind == wp::FaultKind::DivisionByZero),
        "{r:?}"
    );
}

#[wp::kernel]
fn k_mat_ops(
    m: Array<Mat3>,
    n: Array<Mat3>,
    v: Array<Vec3>,
    mv: Array<Vec3>,
    mm: Array<Mat3, 2>,
    m4: Mat4,
    v4: Vec4,
    out4: Array<Vec4>,
    dm: DMat3,
    dv: DVec3,
    dout: Array<DVec3>,
) {
    let i = tid();
    mv[i] = m[i] * v[i];
    mm[(i, 0)] = m[i] * n[i];
    mm[(i, 1)] = m[i] + n[i];
    mm[(i, 2)] = m[i] - n[i];
    mm[(i, 3)] = 0.5 * m[i];
    mm[(i, 4)] = m[i] / 4.0;
    out4[i] = m4 * v4;
    dout[i] = dm * dv;
}

fn matrix_operators(dev: &wp::Device) {
    let m = [
        Mat3::from_cols(
            vec3(1.0, 2.0, 3.0),
            vec3(4.0, 5.0, 6.0),
            vec3(7.0, 8.0, 10.0),
        ),
        Mat3::from_cols(
            vec3(0.1, -0.2, 0.3),
            vec3(0.7, 0.5, -0.6),
            vec3(1.7, 0.8, 0.9),
        ),
    ];
    let n = [
        Mat3::from_diagonal(vec3(2.0, 3.0, 4.0)),
        Mat3::from_cols(
            vec3(0.3, 0.3, 0.1),
            vec3(-1.0, 2.0, 0.25),
            vec3(0.0, 0.6, 0.7),
        ),
    ];
    let v = [vec3(1.0, -1.0, 0.5), vec3(0.3, 0.2, 0.1)];
    let m4 = Mat4::from_cols_array(&[
        0.5, 1.0, 1.5, 2.0, -1.0, 0.1, 0.2, 0.3, 3.0, 2.0, 1.0, 0.0, 0.7, 0.6, 0.5, 0.4,
    ]);
    let v4 = vec4(0.1, 0.2, 0.3, 0.4);
    let dm = DMat3::from_cols(
        dvec3(0.1, 0.2, 0.3),
        dvec3(1.1, 1.2, 1.3),
        dvec3(-2.0, 0.5, 0.25),
    );
    let dv = dvec3(0.7, 0.8, 0.9);
    let (mv, mm) = (zeros::<Vec3, 1>(2, dev), zeros::<Mat3, 2>((2, 5), dev));
    let (out4, dout) = (zeros::<Vec4, 1>(2, dev), zeros::<DVec3, 1>(2, dev));
    wp::launch(
        k_mat_ops,
        2,
        (
            &arr(&m, dev),
            &arr(&n, dev),
            &arr(&v, dev),
            &mv,
            &mm,
            m4,
            v4,
            &out4,
            dm,
            dv,
            &dout,
        ),
        dev,
    )
    .unwrap();
    let (mv, mm, out4, dout) = (host(&mv), host(&mm), host(&out4), host(&dout));
    // Products sum several products: FMA on CUDA (fma_rel); the rest is one rounding each.
    let rel = fma_rel(dev);
    for i in 0..2 {
        assert_close_slice(
            &mv[i].to_array(),
            &(m[i] * v[i]).to_array(),
            rel,
            "Mat3 * Vec3",
        );
        assert_close_slice(
            &mm[i * 5].to_cols_array(),
            &(m[i] * n[i]).to_cols_array(),
            rel,
            "Mat3 * Mat3",
        );
        assert_eq!(mm[i * 5 + 1], m[i] + n[i], "Mat3 + Mat3");
        assert_eq!(mm[i * 5 + 2], m[i] - n[i], "Mat3 - Mat3");
        assert_eq!(mm[i * 5 + 3], 0.5 * m[i], "f32 * Mat3");
        assert_eq!(mm[i * 5 + 4], m[i] / 4.0, "Mat3 / f32");
        assert_close_slice(
            &out4[i].to_array(),
            &(m4 * v4).to_array(),
            rel,
            "Mat4 * Vec4",
        );
        let want = dm * dv;
        for k in 0..3 {
            crate::assert_close_f64(dout[i][k], want[k], crate::fma_rel64(dev), "DMat3 * DVec3");
        }
    }
}

#[wp::kernel]
fn k_quat_ops(q: Array<Quat>, r: Array<Quat>, v: Array<Vec3>, qv: Array<Vec3>, qq: Array<Quat, 2>) {
    let i = tid();
    qv[i] = q[i] * v[i];
    qq[(i, 0)] = q[i] * r[i];
    qq[(i, 1)] = q[i] + r[i];
    qq[(i, 2)] = q[i] - r[i];
    qq[(i, 3)] = -q[i];
    qq[(i, 4)] = q[i] * 0.5;
}

fn quat_operators(dev: &wp::Device) {
    let q = [
        Quat::from_rotation_z(std::f32::consts::FRAC_PI_2),
        Quat::from_axis_angle(vec3(1.0, 2.0, 3.0).normalize(), 0.7),
    ];
    let r = [
        Quat::from_rotation_x(0.3),
        Quat::from_xyzw(0.5, 0.5, 0.5, 0.5),
    ];
    let v = [vec3(1.0, 0.0, 0.0), vec3(0.3, -0.4, 2.0)];
    let (qv, qq) = (zeros::<Vec3, 1>(2, dev), zeros::<Quat, 2>((2, 5), dev));
    wp::launch(
        k_quat_ops,
        2,
        (&arr(&q, dev), &arr(&r, dev), &arr(&v, dev), &qv, &qq),
        dev,
    )
    .unwrap();
    let (qv, qq) = (host(&qv), host(&qq));
    let rel = fma_rel(dev);
    for i in 0..2 {
        // Rotation and the Hamilton product sum products: FMA on CUDA.
        assert_close_slice(
            &qv[i].to_array(),
            &(q[i] * v[i]).to_array(),
            rel,
            "Quat * Vec3",
        );
        assert_close_slice(
            &qq[i * 5].to_array(),
            &(q[i] * r[i]).to_array(),
            rel,
            "Quat * Quat",
        );
        assert_eq!(qq[i * 5 + 1], q[i] + r[i]);
        assert_eq!(qq[i * 5 + 2], q[i] - r[i]);
        assert_eq!(qq[i * 5 + 3], -q[i]);
        assert_eq!(qq[i * 5 + 4], q[i] * 0.5);
    }
    // A quarter turn about z takes x to y.
    assert_close_slice(&qv[0].to_array(), &[0.0, 1.0, 0.0], 1e-6, "rotation");
}

// ------------------------------------------------------------------------------ comparisons

#[wp::kernel]
fn k_cmp(
    a: Array<f32>,
    b: Array<f32>,
    ia: Array<i32>,
    ib: Array<i32>,
    va: Array<Vec3>,
    vb: Array<Vec3>,
    out: Array<u8, 2>,
) {
    let i = tid();
    let x = a[i];
    let y = b[i];
    out[(i, 0)] = (x < y) as u8;
    out[(i, 1)] = (x <= y) as u8;
    out[(i, 2)] = (x > y) as u8;
    out[(i, 3)] = (x >= y) as u8;
    out[(i, 4)] = (x == y) as u8;
    out[(i, 5)] = (x != y) as u8;
    let m = ia[i];
    let n = ib[i];
    out[(i, 6)] = (m < n) as u8;
    out[(i, 7)] = (m <= n) as u8;
    out[(i, 8)] = (m > n) as u8;
    out[(i, 9)] = (m >= n) as u8;
    out[(i, 10)] = (m == n) as u8;
    out[(i, 11)] = (m != n) as u8;
    out[(i, 12)] = (va[i] == vb[i]) as u8;
    out[(i, 13)] = (va[i] != vb[i]) as u8;
    out[(i, 14)] = (x < 0.5) as u8;
    out[(i, 15)] = (0 > m) as u8;
}

fn comparisons(dev: &wp::Device) {
    let a = [1.0f32, 2.0, -0.0, f32::NAN, f32::INFINITY, 0.25];
    let b = [2.0f32, 2.0, 0.0, 1.0, f32::MAX, f32::NAN];
    let ia = [1, 2, -3, i32::MIN, 7, 0];
    let ib = [2, 2, -4, i32::MAX, -7, 0];
    let va = [
        Vec3::ONE,
        Vec3::X,
        vec3(1.0, 2.0, 3.0),
        Vec3::ZERO,
        Vec3::NAN,
        vec3(-0.0, 0.0, 0.0),
    ];
    let vb = [
        Vec3::ONE,
        Vec3::Y,
        vec3(1.0, 2.0, 3.5),
        Vec3::ZERO,
        Vec3::NAN,
        Vec3::ZERO,
    ];
    let out = zeros::<u8, 2>((6, 16), dev);
    let args = (
        &arr(&a, dev),
        &arr(&b, dev),
        &arr(&ia, dev),
        &arr(&ib, dev),
        &arr(&va, dev),
        &arr(&vb, dev),
        &out,
    );
    wp::launch(k_cmp, 6, args, dev).unwrap();
    for (i, row) in host(&out).chunks(16).enumerate() {
        let (x, y, m, n) = (a[i], b[i], ia[i], ib[i]);
        let want = [
            x < y,
            x <= y,
            x > y,
            x >= y,
            x == y,
            x != y,
            m < n,
            m <= n,
            m > n,
            m >= n,
            m == n,
            m != n,
            va[i] == vb[i],
            va[i] != vb[i],
            x < 0.5,
            0 > m,
        ];
        let want: Vec<u8> = want.iter().map(|&b| u8::from(b)).collect();
        assert_eq!(row, want, "row {i}: ({x}, {y}), ({m}, {n})");
    }
}

/// Launched with `a.len() + 1` threads: the last thread's `a[i]` is out of bounds, so the
/// launch faults unless `&&` skips its right side when the left is false.
#[wp::kernel]
fn k_and(a: Array<f32>, out: Array<u8>) {
    let i = tid();
    out[i] = (i < a.len() && a[i] > 0.0) as u8;
}

fn short_circuit_and(dev: &wp::Device) {
    let a = [1.0f32, -1.0, 0.0, 2.0];
    let out = zeros::<u8, 1>(5, dev);
    wp::launch(k_and, 5, (&arr(&a, dev), &out), dev).unwrap();
    assert_eq!(host(&out), vec![1, 0, 0, 1, 0]);
}

#[wp::kernel]
fn k_or(a: Array<f32>, out: Array<u8>) {
    let i = tid();
    let skip = i >= a.len() || a[i] > 0.0;
    out[i] = skip as u8;
}

fn short_circuit_or(dev: &wp::Device) {
    let a = [1.0f32, -1.0, 0.0, 2.0];
    let out = zeros::<u8, 1>(5, dev);
    wp::launch(k_or, 5, (&arr(&a, dev), &out), dev).unwrap();
    assert_eq!(host(&out), vec![1, 0, 0, 1, 1]);
}

/// The right side of `&&`/`||` is an atomic increment: the counters show how often it ran.
#[wp::kernel]
fn k_short_effects(a: Array<i32>, and_count: Array<i32>, or_count: Array<i32>, out: Array<u8, 2>) {
    let i = tid();
    let x = a[i];
    let p = x > 0 && atomic_add(and_count, 0, 1) >= 0;
    let q = x > 0 || atomic_add(or_count, 0, 1) < 0;
    out[(i, 0)] = p as u8;
    out[(i, 1)] = q as u8;
}

fn short_circuit_skips_side_effects(dev: &wp::Device) {
    let a: Vec<i32> = (0..20).map(|k| if k % 3 == 0 { k } else { -k }).collect();
    let (and_count, or_count) = (zeros::<i32, 1>(1, dev), zeros::<i32, 1>(1, dev));
    let out = zeros::<u8, 2>((20, 2), dev);
    wp::launch(
        k_short_effects,
        20,
        (&arr(&a, dev), &and_count, &or_count, &out),
        dev,
    )
    .unwrap();
    let positive = a.iter().filter(|&&x| x > 0).count() as i32;
    assert_eq!(
        host(&and_count),
        vec![positive],
        "&& evaluates its right side only when the left is true"
    );
    assert_eq!(
        host(&or_count),
        vec![20 - positive],
        "|| evaluates its right side only when the left is false"
    );
    let want: Vec<u8> = a
        .iter()
        .flat_map(|&x| [u8::from(x > 0), u8::from(x > 0)])
        .collect();
    assert_eq!(host(&out), want);
}

// ------------------------------------------------------------------------------ unary, casts

#[wp::kernel]
fn k_unary(
    xi: Array<i32>,
    xf: Array<f32>,
    xb: Array<u8>,
    oi: Array<i32, 2>,
    of: Array<f32>,
    ob: Array<u8, 2>,
) {
    let i = tid();
    oi[(i, 0)] = -xi[i];
    oi[(i, 1)] = !xi[i];
    oi[(i, 2)] = -(-xi[i]);
    of[i] = -xf[i];
    let b = xb[i] != 0;
    ob[(i, 0)] = (!b) as u8;
    ob[(i, 1)] = !xb[i];
    ob[(i, 2)] = !!b as u8;
}

fn unary_operators(dev: &wp::Device) {
    let xi = [0, 5, -7, i32::MIN, i32::MAX];
    let xf = [0.0f32, 1.5, -2.0, f32::INFINITY, -0.0];
    let xb = [0u8, 1, 2, 255, 0];
    let (oi, of, ob) = (
        zeros::<i32, 2>((5, 3), dev),
        zeros::<f32, 1>(5, dev),
        zeros::<u8, 2>((5, 3), dev),
    );
    wp::launch(
        k_unary,
        5,
        (
            &arr(&xi, dev),
            &arr(&xf, dev),
            &arr(&xb, dev),
            &oi,
            &of,
            &ob,
        ),
        dev,
    )
    .unwrap();
    let want_i: Vec<i32> = xi.iter().flat_map(|&x| [x.wrapping_neg(), !x, x]).collect();
    assert_eq!(host(&oi), want_i);
    let of = host(&of);
    for (g, x) in of.iter().zip(xf) {
        assert_eq!(g.to_bits(), (-x).to_bits(), "-{x} (sign of zero included)");
    }
    let want_b: Vec<u8> = xb
        .iter()
        .flat_map(|&x| [u8::from(x == 0), !x, u8::from(x != 0)])
        .collect();
    assert_eq!(host(&ob), want_b);
}

#[wp::kernel]
fn k_float_casts(
    x: Array<f32>,
    y: Array<f64>,
    oi32: Array<i32>,
    ou8: Array<u8>,
    oi64: Array<i64>,
    ou64: Array<u64>,
    of64: Array<f64>,
    of32: Array<f32>,
) {
    let i = tid();
    oi32[i] = x[i] as i32;
    ou8[i] = x[i] as u8;
    oi64[i] = y[i] as i64;
    ou64[i] = y[i] as u64;
    of64[i] = x[i] as f64;
    of32[i] = y[i] as f32;
}

fn float_casts(dev: &wp::Device) {
    let x = [
        2.7f32,
        -2.7,
        1e10,
        -1e10,
        f32::NAN,
        255.9,
        300.0,
        -0.5,
        f32::INFINITY,
        f32::NEG_INFINITY,
    ];
    let y = [
        2.7f64,
        -2.7,
        1e20,
        -1e20,
        f64::NAN,
        0.1,
        9_007_199_254_740_993.0,
        -0.5,
        f64::INFINITY,
        1e300,
    ];
    let n = x.len();
    let (oi32, ou8, oi64, ou64) = (
        zeros::<i32, 1>(n, dev),
        zeros::<u8, 1>(n, dev),
        zeros::<i64, 1>(n, dev),
        zeros::<u64, 1>(n, dev),
    );
    let (of64, of32) = (zeros::<f64, 1>(n, dev), zeros::<f32, 1>(n, dev));
    let args = (
        &arr(&x, dev),
        &arr(&y, dev),
        &oi32,
        &ou8,
        &oi64,
        &ou64,
        &of64,
        &of32,
    );
    wp::launch(k_float_casts, n, args, dev).unwrap();
    // Float to int saturates and maps NaN to 0, as Rust's `as` does.
    assert_eq!(host(&oi32), x.iter().map(|&v| v as i32).collect::<Vec<_>>());
    assert_eq!(host(&ou8), x.iter().map(|&v| v as u8).collect::<Vec<_>>());
    assert_eq!(host(&oi64), y.iter().map(|&v| v as i64).collect::<Vec<_>>());
    assert_eq!(host(&ou64), y.iter().map(|&v| v as u64).collect::<Vec<_>>());
    let of64 = host(&of64);
    let of32 = host(&of32);
    for k in 0..n {
        crate::assert_close_f64(of64[k], f64::from(x[k]), 0.0, "f32 as f64");
        assert_close_f32(of32[k], y[k] as f32, 0.0, "f64 as f32");
    }
    assert_eq!(host(&oi32)[2], i32::MAX);
    assert_eq!(host(&oi32)[4], 0);
}

#[wp::kernel]
fn k_int_casts(
    a: Array<i64>,
    oi32: Array<i32>,
    ou32: Array<u32>,
    oi8: Array<i8>,
    ou8: Array<u8>,
    of32: Array<f32>,
    of64: Array<f64>,
    ou64: Array<u64>,
    os: Array<i64, 2>,
) {
    let i = tid();
    let x = a[i];
    oi32[i] = x as i32;
    ou32[i] = x as u32;
    oi8[i] = x as i8;
    ou8[i] = x as u8;
    of32[i] = x as f32;
    of64[i] = x as f64;
    ou64[i] = x as u64;
    let narrow = x as i8;
    os[(i, 0)] = narrow as i64;
    let bits = x as u32;
    os[(i, 1)] = (bits as i32) as i64;
    let small = x as i32;
    os[(i, 2)] = (small as u32) as i64;
    os[(i, 3)] = (x < 0) as i64;
    os[(i, 4)] = ((x > 0) as i32) as i64;
}

fn int_casts(dev: &wp::Device) {
    let a = [
        0i64,
        1,
        -1,
        255,
        256,
        -129,
        i64::from(i32::MAX) + 1,
        i64::MIN,
        i64::MAX,
        16_777_217,
        (1 << 53) + 1,
    ];
    let n = a.len();
    let (oi32, ou32, oi8, ou8) = (
        zeros::<i32, 1>(n, dev),
        zeros::<u32, 1>(n, dev),
        zeros::<i8, 1>(n, dev),
        zeros::<u8, 1>(n, dev),
    );
    let (of32, of64, ou64, os) = (
        zeros::<f32, 1>(n, dev),
        zeros::<f64, 1>(n, dev),
        zeros::<u64, 1>(n, dev),
        zeros::<i64, 2>((n, 5), dev),
    );
    wp::launch(
        k_int_casts,
        n,
        (
            &arr(&a, dev),
            &oi32,
            &ou32,
            &oi8,
            &ou8,
            &of32,
            &of64,
            &ou64,
            &os,
        ),
        dev,
    )
    .unwrap();
    assert_eq!(
        host(&oi32),
        a.iter().map(|&v| v as i32).collect::<Vec<_>>(),
        "i64 as i32 truncates"
    );
    assert_eq!(host(&ou32), a.iter().map(|&v| v as u32).collect::<Vec<_>>());
    assert_eq!(host(&oi8), a.iter().map(|&v| v as i8).collect::<Vec<_>>());
    assert_eq!(host(&ou8), a.iter().map(|&v| v as u8).collect::<Vec<_>>());
    assert_eq!(
        host(&of32),
        a.iter().map(|&v| v as f32).collect::<Vec<_>>(),
        "int to float rounds to nearest"
    );
    assert_eq!(host(&of64), a.iter().map(|&v| v as f64).collect::<Vec<_>>());
    assert_eq!(host(&ou64), a.iter().map(|&v| v as u64).collect::<Vec<_>>());
    let want: Vec<i64> = a
        .iter()
        .flat_map(|&x| {
            [
                i64::from(x as i8),
                i64::from(x as u32 as i32),
                i64::from(x as i32 as u32),
                i64::from(x < 0),
                i64::from(i32::from(x > 0)),
            ]
        })
        .collect();
    assert_eq!(
        host(&os),
        want,
        "sign extension, reinterpretation, bool as int"
    );
}

// ------------------------------------------------------------------------------ literals

#[wp::kernel]
fn k_literals(x: f64, n: i32, out: Array<f64>, outi: Array<i64>, outf: Array<f32>) {
    let a = 2.0 * x;
    out[0] = a;
    out[1] = x + 0.1;
    let b = 0.1;
    out[2] = b as f64;
    out[3] = 2 * x;
    let c: f64 = 0.1;
    out[4] = c;
    out[5] = if x > 0.0 { 0.1 } else { 0.2 };
    let third = 1.0 / 3.0;
    out[6] = third as f64;
    let dthird: f64 = 1.0 / 3.0;
    out[7] = dthird;
    out[8] = max(x, 0.1);
    let k = 2147483647;
    outi[0] = (k + 1) as i64;
    outi[1] = (n * 3) as i64;
    let half = 1 / 2;
    outi[2] = half as i64;
    let e = 3_000_000_000_i64;
    outi[3] = e + 1;
    outf[0] = b;
    outf[1] = -1;
}

fn literal_rule(dev: &wp::Device) {
    let (out, outi, outf) = (
        zeros::<f64, 1>(9, dev),
        zeros::<i64, 1>(4, dev),
        zeros::<f32, 1>(2, dev),
    );
    let x = 0.1f64;
    wp::launch(k_literals, 1, (x, 7, &out, &outi, &outf), dev).unwrap();
    let out = host(&out);
    assert_eq!(out[0], 2.0 * x, "2.0 * x is f64");
    assert_eq!(out[1], x + 0.1, "x + 0.1 adds the f64 0.1");
    assert_ne!(out[1], x + f64::from(0.1f32), "not the f32 0.1");
    assert_eq!(out[2], f64::from(0.1f32), "`let b = 0.1;` is f32");
    assert_eq!(out[3], 2.0 * x, "`2 * x` is a float product");
    assert_eq!(out[4], 0.1f64, "an annotated let types its literal");
    assert_eq!(
        out[5], 0.1f64,
        "if/else branches take the type of the place"
    );
    assert_eq!(
        out[6],
        f64::from(1.0f32 / 3.0),
        "1.0 / 3.0 with no context is f32"
    );
    assert_eq!(out[7], 1.0f64 / 3.0, "annotated f64");
    assert_eq!(
        out[8], 0.1f64,
        "a builtin's literal argument takes the other argument's type"
    );
    assert_eq!(
        host(&outi),
        vec![i64::from(i32::MIN), 21, 0, 3_000_000_001],
        "integer literals are i32 without context"
    );
    assert_eq!(host(&outf), vec![0.1f32, -1.0]);
}

#[wp::kernel]
fn k_consts(out: Array<f32>, outd: Array<f64>, outi: Array<i64>, outu: Array<u64>) {
    out[0] = f32::MAX;
    out[1] = f32::consts::PI;
    out[2] = std::f32::consts::PI;
    out[3] = f32::EPSILON;
    out[4] = f32::MIN_POSITIVE;
    out[5] = f32::INFINITY;
    out[6] = f32::MIN;
    out[7] = f32::consts::TAU;
    out[8] = core::f32::consts::FRAC_PI_2;
    outd[0] = std::f64::consts::PI;
    outd[1] = f64::consts::E;
    outd[2] = f64::consts::SQRT_2;
    outd[3] = f64::MAX;
    outd[4] = f64::NEG_INFINITY;
    outd[5] = f64::consts::LN_2;
    outi[0] = i32::MIN as i64;
    outi[1] = i64::MAX;
    outi[2] = u8::MAX as i64;
    outi[3] = i16::MIN as i64;
    outu[0] = u64::MAX;
    outu[1] = u32::MAX as u64;
    let nan = f32::NAN;
    out[9] = (nan != nan) as i32 as f32;
}

fn constants(dev: &wp::Device) {
    let (out, outd, outi, outu) = (
        zeros::<f32, 1>(10, dev),
        zeros::<f64, 1>(6, dev),
        zeros::<i64, 1>(4, dev),
        zeros::<u64, 1>(2, dev),
    );
    wp::launch(k_consts, 1, (&out, &outd, &outi, &outu), dev).unwrap();
    use std::f32::consts as c32;
    use std::f64::consts as c64;
    assert_eq!(
        host(&out),
        vec![
            f32::MAX,
            c32::PI,
            c32::PI,
            f32::EPSILON,
            f32::MIN_POSITIVE,
            f32::INFINITY,
            f32::MIN,
            c32::TAU,
            c32::FRAC_PI_2,
            1.0
        ]
    );
    assert_eq!(
        host(&outd),
        vec![
            c64::PI,
            c64::E,
            c64::SQRT_2,
            f64::MAX,
            f64::NEG_INFINITY,
            c64::LN_2
        ]
    );
    assert_eq!(
        host(&outi),
        vec![i64::from(i32::MIN), i64::MAX, 255, -32768]
    );
    assert_eq!(host(&outu), vec![u64::MAX, u64::from(u32::MAX)]);
}

#[wp::kernel]
fn k_ctors(
    s: f32,
    ov: Array<Vec3>,
    om: Array<Mat3>,
    oq: Array<Quat>,
    o2: Array<DVec2>,
    oi: Array<IVec3>,
    ou: Array<UVec2>,
    o4: Array<Vec4>,
) {
    ov[0] = Vec3::new(1.0, 2.0, s);
    ov[1] = vec3(s, 0.5, -1);
    ov[2] = Vec3::splat(s);
    ov[3] = Vec3::ZERO;
    ov[4] = Vec3::X + Vec3::ONE;
    om[0] = Mat3::from_cols(Vec3::X, vec3(0.0, 2.0, 0.0), Vec3::splat(s));
    om[1] = Mat3::IDENTITY;
    om[2] = Mat3::from_diagonal(vec3(1.0, 2.0, 3.0));
    om[3] = Mat3::ZERO;
    oq[0] = Quat::from_xyzw(0.0, 0.0, s, 1.0);
    oq[1] = Quat::IDENTITY;
    o2[0] = DVec2::new(0.1, 0.2);
    o2[1] = dvec2(1, 2);
    oi[0] = ivec3(1, -2, 3);
    oi[1] = IVec3::splat(7);
    ou[0] = uvec2(1, 2);
    ou[1] = UVec2::new(3, 4);
    o4[0] = vec4(1.0, 2.0, 3.0, 4.0);
    o4[1] = Vec4::W;
    let m = om[0];
    ov[5] = m.y_axis;
    ov[6] = om[2].z_axis;
    ov[7] = Vec3::NEG_Z;
}

fn glam_constructors(dev: &wp::Device) {
    let (ov, om, oq) = (
        zeros::<Vec3, 1>(8, dev),
        zeros::<Mat3, 1>(4, dev),
        zeros::<Quat, 1>(2, dev),
    );
    let (o2, oi, ou, o4) = (
        zeros::<DVec2, 1>(2, dev),
        zeros::<IVec3, 1>(2, dev),
        zeros::<UVec2, 1>(2, dev),
        zeros::<Vec4, 1>(2, dev),
    );
    let s = 0.7f32;
    wp::launch(k_ctors, 1, (s, &ov, &om, &oq, &o2, &oi, &ou, &o4), dev).unwrap();
    let m0 = Mat3::from_cols(Vec3::X, vec3(0.0, 2.0, 0.0), Vec3::splat(s));
    assert_eq!(
        host(&ov),
        vec![
            vec3(1.0, 2.0, s),
            vec3(s, 0.5, -1.0),
            Vec3::splat(s),
            Vec3::ZERO,
            vec3(2.0, 1.0, 1.0),
            m0.y_axis,
            vec3(0.0, 0.0, 3.0),
            Vec3::NEG_Z
        ]
    );
    assert_eq!(
        host(&om),
        vec![
            m0,
            Mat3::IDENTITY,
            Mat3::from_diagonal(vec3(1.0, 2.0, 3.0)),
            Mat3::ZERO
        ]
    );
    assert_eq!(
        host(&oq),
        vec![Quat::from_xyzw(0.0, 0.0, s, 1.0), Quat::IDENTITY]
    );
    assert_eq!(
        host(&o2),
        vec![dvec2(0.1, 0.2), dvec2(1.0, 2.0)],
        "f64 components take f64 literals"
    );
    assert_eq!(host(&oi), vec![ivec3(1, -2, 3), IVec3::splat(7)]);
    assert_eq!(host(&ou), vec![uvec2(1, 2), uvec2(3, 4)]);
    assert_eq!(host(&o4), vec![vec4(1.0, 2.0, 3.0, 4.0), Vec4::W]);
}

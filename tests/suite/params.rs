//! Every parameter type a kernel accepts by value: bool, the integers, the floats, glam's
//! vectors, matrices and quaternions. (Arrays of 1-4 dimensions are in `arrays`, structs in
//! `structs`.)

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    bool_param,
    integer_params,
    float_params,
    float_vector_params,
    double_vector_params,
    int_vector_params,
    matrix_params,
    quat_params,
    module_constants,
    constants_in_funcs_and_gradients,
);

#[wp::kernel]
fn k_bool(flag: bool, out: Array<u8>) {
    out[0] = if flag { 1 } else { 0 };
    out[1] = if !flag { 1 } else { 0 };
    out[2] = flag as u8;
    out[3] = (flag == true) as u8;
}

fn bool_param(dev: &wp::Device) {
    for flag in [false, true] {
        let out = zeros::<u8, 1>(4, dev);
        wp::launch(k_bool, 1, (flag, &out), dev).unwrap();
        let f = u8::from(flag);
        assert_eq!(host(&out), vec![f, 1 - f, f, f], "flag = {flag}");
    }
}

/// Each integer parameter is stored as given and plus one (which wraps at the maximum, as on
/// CUDA, without a debug-build overflow panic).
#[wp::kernel]
fn k_ints(
    a8: i8,
    a16: i16,
    a32: i32,
    a64: i64,
    b8: u8,
    b16: u16,
    b32: u32,
    b64: u64,
    o8: Array<i8>,
    o16: Array<i16>,
    o32: Array<i32>,
    o64: Array<i64>,
    p8: Array<u8>,
    p16: Array<u16>,
    p32: Array<u32>,
    p64: Array<u64>,
) {
    o8[0] = a8;
    o8[1] = a8 + 1;
    o16[0] = a16;
    o16[1] = a16 + 1;
    o32[0] = a32;
    o32[1] = a32 + 1;
    o64[0] = a64;
    o64[1] = a64 + 1;
    p8[0] = b8;
    p8[1] = b8 + 1;
    p16[0] = b16;
    p16[1] = b16 + 1;
    p32[0] = b32;
    p32[1] = b32 + 1;
    p64[0] = b64;
    p64[1] = b64 + 1;
}

fn integer_params(dev: &wp::Device) {
    let (o8, o16, o32, o64) = (
        zeros::<i8, 1>(2, dev),
        zeros::<i16, 1>(2, dev),
        zeros::<i32, 1>(2, dev),
        zeros::<i64, 1>(2, dev),
    );
    let (p8, p16, p32, p64) = (
        zeros::<u8, 1>(2, dev),
        zeros::<u16, 1>(2, dev),
        zeros::<u32, 1>(2, dev),
        zeros::<u64, 1>(2, dev),
    );
    let outs = (&o8, &o16, &o32, &o64, &p8, &p16, &p32, &p64);
    // Small values, then every type's maximum (wraps to its minimum).
    wp::launch(
        k_ints,
        1,
        (
            -5i8,
            -300i16,
            -70_000i32,
            -5_000_000_000i64,
            7u8,
            300u16,
            70_000u32,
            5_000_000_000u64,
            outs.0,
            outs.1,
            outs.2,
            outs.3,
            outs.4,
            outs.5,
            outs.6,
            outs.7,
        ),
        dev,
    )
    .unwrap();
    assert_eq!(host(&o8), vec![-5, -4]);
    assert_eq!(host(&o16), vec![-300, -299]);
    assert_eq!(host(&o32), vec![-70_000, -69_999]);
    assert_eq!(host(&o64), vec![-5_000_000_000, -4_999_999_999]);
    assert_eq!(host(&p8), vec![7, 8]);
    assert_eq!(host(&p16), vec![300, 301]);
    assert_eq!(host(&p32), vec![70_000, 70_001]);
    assert_eq!(host(&p64), vec![5_000_000_000, 5_000_000_001]);
    wp::launch(
        k_ints,
        1,
        (
            i8::MAX,
            i16::MAX,
            i32::MAX,
            i64::MAX,
            u8::MAX,
            u16::MAX,
            u32::MAX,
            u64::MAX,
            outs.0,
            outs.1,
            outs.2,
            outs.3,
            outs.4,
            outs.5,
            outs.6,
            outs.7,
        ),
        dev,
    )
    .unwrap();
    assert_eq!(host(&o8), vec![i8::MAX, i8::MIN]);
    assert_eq!(host(&o16), vec![i16::MAX, i16::MIN]);
    assert_eq!(host(&o32), vec![i32::MAX, i32::MIN]);
    assert_eq!(host(&o64), vec![i64::MAX, i64::MIN]);
    assert_eq!(host(&p8), vec![u8::MAX, 0]);
    assert_eq!(host(&p16), vec![u16::MAX, 0]);
    assert_eq!(host(&p32), vec![u32::MAX, 0]);
    assert_eq!(host(&p64), vec![u64::MAX, 0]);
}

#[wp::kernel]
fn k_floats(f: f32, d: f64, of: Array<f32>, od: Array<f64>) {
    of[0] = f;
    of[1] = f * 0.5;
    od[0] = d;
    od[1] = d * 0.5;
}

fn float_params(dev: &wp::Device) {
    let (of, od) = (zeros::<f32, 1>(2, dev), zeros::<f64, 1>(2, dev));
    // 0.1 differs between f32 and f64: each must arrive with its own precision.
    wp::launch(k_floats, 1, (0.1f32, 0.1f64, &of, &od), dev).unwrap();
    assert_eq!(host(&of), vec![0.1f32, 0.1f32 * 0.5]);
    assert_eq!(host(&od), vec![0.1f64, 0.1f64 * 0.5]);
    wp::launch(k_floats, 1, (f32::MAX, f64::MIN_POSITIVE, &of, &od), dev).unwrap();
    assert_eq!(host(&of), vec![f32::MAX, f32::MAX * 0.5]);
    assert_eq!(host(&od), vec![f64::MIN_POSITIVE, f64::MIN_POSITIVE * 0.5]);
}

#[wp::kernel]
fn k_vecs(a: Vec2, b: Vec3, c: Vec4, oa: Array<Vec2>, ob: Array<Vec3>, oc: Array<Vec4>) {
    oa[0] = a;
    oa[1] = a + a;
    ob[0] = b;
    ob[1] = b + b;
    oc[0] = c;
    oc[1] = c + c;
}

fn float_vector_params(dev: &wp::Device) {
    let (oa, ob, oc) = (
        zeros::<Vec2, 1>(2, dev),
        zeros::<Vec3, 1>(2, dev),
        zeros::<Vec4, 1>(2, dev),
    );
    let (a, b, c) = (
        vec2(1.5, -2.0),
        vec3(0.1, 0.2, 0.3),
        vec4(1.0, 2.0, 3.0, -4.25),
    );
    wp::launch(k_vecs, 1, (a, b, c, &oa, &ob, &oc), dev).unwrap();
    assert_eq!(host(&oa), vec![a, a + a]);
    assert_eq!(host(&ob), vec![b, b + b]);
    assert_eq!(host(&oc), vec![c, c + c]);
}

#[wp::kernel]
fn k_dvecs(a: DVec2, b: DVec3, c: DVec4, oa: Array<DVec2>, ob: Array<DVec3>, oc: Array<DVec4>) {
    oa[0] = a;
    oa[1] = a + a;
    ob[0] = b;
    ob[1] = b + b;
    oc[0] = c;
    oc[1] = c + c;
}

fn double_vector_params(dev: &wp::Device) {
    let (oa, ob, oc) = (
        zeros::<DVec2, 1>(2, dev),
        zeros::<DVec3, 1>(2, dev),
        zeros::<DVec4, 1>(2, dev),
    );
    let (a, b, c) = (
        dvec2(1.5, -2.0),
        dvec3(0.1, 0.2, 0.3),
        dvec4(1e300, 2.0, 3.0, -4.25),
    );
    wp::launch(k_dvecs, 1, (a, b, c, &oa, &ob, &oc), dev).unwrap();
    assert_eq!(host(&oa), vec![a, a + a]);
    assert_eq!(host(&ob), vec![b, b + b]);
    assert_eq!(host(&oc), vec![c, c + c]);
}

#[wp::kernel]
fn k_ivecs(
    a: IVec2,
    b: IVec3,
    c: IVec4,
    d: UVec2,
    e: UVec3,
    f: UVec4,
    oa: Array<IVec2>,
    ob: Array<IVec3>,
    oc: Array<IVec4>,
    od: Array<UVec2>,
    oe: Array<UVec3>,
    of: Array<UVec4>,
) {
    oa[0] = a;
    oa[1] = a * 3;
    ob[0] = b;
    ob[1] = b * 3;
    oc[0] = c;
    oc[1] = c * 3;
    od[0] = d;
    od[1] = d * 3;
    oe[0] = e;
    oe[1] = e * 3;
    of[0] = f;
    of[1] = f * 3;
}

fn int_vector_params(dev: &wp::Device) {
    let (oa, ob, oc) = (
        zeros::<IVec2, 1>(2, dev),
        zeros::<IVec3, 1>(2, dev),
        zeros::<IVec4, 1>(2, dev),
    );
    let (od, oe, of) = (
        zeros::<UVec2, 1>(2, dev),
        zeros::<UVec3, 1>(2, dev),
        zeros::<UVec4, 1>(2, dev),
    );
    let (a, b, c) = (ivec2(1, -2), ivec3(-3, 4, 5), ivec4(6, -7, 8, 1 << 20));
    let (d, e, f) = (uvec2(1, 2), uvec3(3, 4, 5), uvec4(6, 7, 8, 1 << 30));
    wp::launch(
        k_ivecs,
        1,
        (a, b, c, d, e, f, &oa, &ob, &oc, &od, &oe, &of),
        dev,
    )
    .unwrap();
    assert_eq!(host(&oa), vec![a, a * 3]);
    assert_eq!(host(&ob), vec![b, b * 3]);
    assert_eq!(host(&oc), vec![c, c * 3]);
    assert_eq!(host(&od), vec![d, d * 3]);
    assert_eq!(host(&oe), vec![e, e * 3]);
    assert_eq!(host(&of), vec![f, f * 3]);
}

#[wp::kernel]
fn k_mats(
    a: Mat2,
    b: Mat3,
    c: Mat4,
    d: DMat2,
    e: DMat3,
    f: DMat4,
    oa: Array<Mat2>,
    ob: Array<Mat3>,
    oc: Array<Mat4>,
    od: Array<DMat2>,
    oe: Array<DMat3>,
    of: Array<DMat4>,
) {
    // Scaling by two is exact on every backend.
    oa[0] = a;
    oa[1] = a * 2.0;
    ob[0] = b;
    ob[1] = b * 2.0;
    oc[0] = c;
    oc[1] = c * 2.0;
    od[0] = d;
    od[1] = d * 2.0;
    oe[0] = e;
    oe[1] = e * 2.0;
    of[0] = f;
    of[1] = f * 2.0;
}

fn matrix_params(dev: &wp::Device) {
    let (oa, ob, oc) = (
        zeros::<Mat2, 1>(2, dev),
        zeros::<Mat3, 1>(2, dev),
        zeros::<Mat4, 1>(2, dev),
    );
    let (od, oe, of) = (
        zeros::<DMat2, 1>(2, dev),
        zeros::<DMat3, 1>(2, dev),
        zeros::<DMat4, 1>(2, dev),
    );
    let seq = |n: usize| (0..n).map(|k| k as f32 * 0.5 - 1.0).collect::<Vec<f32>>();
    let dseq = |n: usize| (0..n).map(|k| k as f64 * 0.1 - 1.0).collect::<Vec<f64>>();
    let a = Mat2::from_cols_slice(&seq(4));
    let b = Mat3::from_cols_slice(&seq(9));
    let c = Mat4::from_cols_slice(&seq(16));
    let d = DMat2::from_cols_slice(&dseq(4));
    let e = DMat3::from_cols_slice(&dseq(9));
    let f = DMat4::from_cols_slice(&dseq(16));
    wp::launch(
        k_mats,
        1,
        (a, b, c, d, e, f, &oa, &ob, &oc, &od, &oe, &of),
        dev,
    )
    .unwrap();
    assert_eq!(host(&oa), vec![a, a * 2.0]);
    assert_eq!(host(&ob), vec![b, b * 2.0]);
    assert_eq!(host(&oc), vec![c, c * 2.0]);
    assert_eq!(host(&od), vec![d, d * 2.0]);
    assert_eq!(host(&oe), vec![e, e * 2.0]);
    assert_eq!(host(&of), vec![f, f * 2.0]);
}

#[wp::kernel]
fn k_quats(q: Quat, d: DQuat, oq: Array<Quat>, od: Array<DQuat>, parts: Array<f64>) {
    oq[0] = q;
    oq[1] = q * 2.0;
    od[0] = d;
    od[1] = d * 2.0;
    parts[0] = q.x as f64;
    parts[1] = q.w as f64;
    parts[2] = d.y;
    parts[3] = d.z;
}

fn quat_params(dev: &wp::Device) {
    let (oq, od, parts) = (
        zeros::<Quat, 1>(2, dev),
        zeros::<DQuat, 1>(2, dev),
        zeros::<f64, 1>(4, dev),
    );
    let q = Quat::from_xyzw(0.1, 0.2, 0.3, 0.9);
    let d = DQuat::from_xyzw(0.4, 0.5, 0.6, 0.7);
    wp::launch(k_quats, 1, (q, d, &oq, &od, &parts), dev).unwrap();
    assert_eq!(host(&oq), vec![q, q * 2.0]);
    assert_eq!(host(&od), vec![d, d * 2.0]);
    assert_eq!(host(&parts), vec![0.1f32 as f64, 0.9f32 as f64, 0.5, 0.6]);
}

// ------------------------------------------------------------------ module-level constants

const GRAVITY: f32 = -9.81;
/// Not exact in binary: the GPU must see the very same f64 (its bits are passed).
const THIRD: f64 = 1.0 / 3.0;
const N_STEPS: i32 = 4;
const MASK: u64 = 0xdead_beef_0000_0001;
const OFFSET: Vec3 = Vec3::new(1.0, 2.0, 3.0);
const NOT_A_NUMBER: f32 = f32::NAN;
const LEN: usize = 2;
const MOST_NEGATIVE: i64 = i64::MIN;

mod physics {
    pub const DRAG: f32 = 0.25;
}

/// Module-level consts (Warp's `wp.constant`), by name and by path, of several types.
#[wp::kernel]
pub(crate) fn k_consts(
    x: Array<f32>,
    y: Array<f64>,
    v: Array<Vec3>,
    bits: Array<u64>,
    ints: Array<i64>,
) {
    let i = tid();
    if i == 0 {
        for k in 0..LEN {
            ints[k] = MOST_NEGATIVE + k as i64;
        }
    }
    let mut acc = x[i];
    for _ in 0..N_STEPS {
        acc += GRAVITY * physics::DRAG;
    }
    x[i] = acc;
    y[i] = y[i] * THIRD;
    v[i] = v[i] + OFFSET * 2.0;
    bits[i] = (bits[i] ^ MASK) + (NOT_A_NUMBER != NOT_A_NUMBER) as u64;
}

fn module_constants(dev: &wp::Device) {
    let x = arr(&[1.0f32, -2.0], dev);
    let y = arr(&[3.0f64, 0.1], dev);
    let v = arr(&[Vec3::ZERO, Vec3::ONE], dev);
    let bits = arr(&[0u64, u64::MAX], dev);
    let ints = zeros::<i64, 1>(LEN, dev);
    wp::launch(k_consts, 2, (&x, &y, &v, &bits, &ints), dev).unwrap();
    assert_eq!(host(&ints), [i64::MIN, i64::MIN + 1]);
    let step = GRAVITY * physics::DRAG;
    // The same additions in the same order: exact on every backend.
    let want: Vec<f32> = [1.0f32, -2.0]
        .iter()
        .map(|&x0| (0..N_STEPS).fold(x0, |a, _| a + step))
        .collect();
    assert_eq!(host(&x), want);
    // One rounding of the same operands: exact.
    assert_eq!(host(&y), [3.0 * THIRD, 0.1 * THIRD]);
    assert_eq!(host(&v), [OFFSET * 2.0, Vec3::ONE + OFFSET * 2.0]);
    assert_eq!(host(&bits), [MASK + 1, (u64::MAX ^ MASK) + 1]);
}

#[wp::func]
fn weight(x: f64) -> f64 {
    x * THIRD + physics::DRAG as f64
}

#[wp::kernel]
fn k_const_loss(x: Array<f64>, out: Array<f64>) {
    let i = tid();
    out[i] = weight(x[i]) * x[i];
}

fn constants_in_funcs_and_gradients(dev: &wp::Device) {
    let x = arr(&[2.0f64, -1.5], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_const_loss, 2, (&x, &out), dev).unwrap();
    }
    tape.backward(&out).unwrap();
    let d = physics::DRAG as f64;
    for (k, x0) in [2.0f64, -1.5].iter().enumerate() {
        // (x/3 + d) x: forward and d/dx = 2x/3 + d, a few roundings (FMA on CUDA): 4 ulp.
        let f = (x0 * THIRD + d) * x0;
        let g = 2.0 * x0 * THIRD + d;
        assert!(
            (host(&out)[k] - f).abs() <= 4.0 * f64::EPSILON * f.abs(),
            "f({x0})"
        );
        let got = host(&x.grad().unwrap())[k];
        assert!(
            (got - g).abs() <= 4.0 * f64::EPSILON * g.abs(),
            "grad({x0}) {got} vs {g}"
        );
    }
}

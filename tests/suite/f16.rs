//! `f16` (Warp's `float16`, the `half` crate's type): arithmetic, casts, literals, IEEE edge
//! cases, builtins, arrays and atomics, gradients and the divergence guard.
//!
//! Why results are compared bit for bit on both backends: every `f16` operation converts its
//! operands to f32 exactly, computes one IEEE f32 operation (or the f32 builtin) and rounds to
//! f16 once, to nearest even, on the CPU (`half`) and on CUDA (`wp::f16`, PTX `cvt.rn.f16.f32`).
//! `+ - * / %` and `sqrt` are correctly rounded f32 operations on both, and a single operation
//! leaves nothing to contract into an FMA, so they agree exactly. NaN payloads may differ
//! between backends (each platform's default NaN), so NaNs compare as NaN. The transcendental
//! builtins are the platforms' f32 functions (CUDA's differ from glibc's by a few f32 ulp),
//! so after rounding to f16 they may differ by one f16 ulp on CUDA, never more.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    arithmetic_matches_half,
    compound_assignment,
    casts_have_rust_semantics,
    literals_round_once,
    overflow_subnormals_nan,
    builtins_round_the_f32_result_once,
    arrays_and_atomics,
    struct_fields_and_funcs,
    gradients_through_a_tape,
    gradcheck_f16,
    divergence_is_detected,
);

fn h(x: f32) -> f16 {
    f16::from_f32(x)
}

/// Same bits, or both NaN (payloads are each platform's).
#[track_caller]
fn same(got: f16, want: f16, what: &str) {
    assert!(
        got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
        "{what}: got {got} ({:#06x}), want {want} ({:#06x})",
        got.to_bits(),
        want.to_bits()
    );
}

/// How many f16 values lie between `a` and `b` (0 for the same value; NaN to NaN is 0).
fn ulps(a: f16, b: f16) -> u32 {
    if a.is_nan() || b.is_nan() {
        return if a.is_nan() && b.is_nan() {
            0
        } else {
            u32::MAX
        };
    }
    // Map the sign-magnitude pattern to a monotonic integer.
    let key = |x: f16| {
        let b = x.to_bits() as i32;
        if b & 0x8000 != 0 {
            -(b & 0x7FFF)
        } else {
            b
        }
    };
    key(a).abs_diff(key(b))
}

/// A sample of f16 bit patterns: every 97th pattern (all exponents, both signs, subnormals,
/// infinities and NaNs) and the special values.
fn sample() -> Vec<f16> {
    let mut v: Vec<f16> = (0u32..=0xFFFF)
        .step_by(97)
        .map(|b| f16::from_bits(b as u16))
        .collect();
    v.extend([
        f16::ZERO,
        f16::NEG_ZERO,
        f16::ONE,
        f16::NEG_ONE,
        f16::MAX,
        f16::MIN,
        f16::INFINITY,
        f16::NEG_INFINITY,
        f16::NAN,
        f16::MIN_POSITIVE,
        f16::MIN_POSITIVE_SUBNORMAL,
        h(0.1),
        h(3.0),
        h(-2.5),
    ]);
    v
}

#[wp::kernel]
fn k_arith(
    a: Array<f16>,
    b: Array<f16>,
    sum: Array<f16>,
    diff: Array<f16>,
    prod: Array<f16>,
    quot: Array<f16>,
    rem: Array<f16>,
    neg: Array<f16>,
    cmp: Array<u8>,
) {
    let i = tid();
    let x = a[i];
    let y = b[i];
    sum[i] = x + y;
    diff[i] = x - y;
    prod[i] = x * y;
    quot[i] = x / y;
    rem[i] = x % y;
    neg[i] = -x;
    let mut c = 0u8;
    if x < y {
        c |= 1;
    }
    if x <= y {
        c |= 2;
    }
    if x == y {
        c |= 4;
    }
    if x != y {
        c |= 8;
    }
    if x > y {
        c |= 16;
    }
    if x >= y {
        c |= 32;
    }
    cmp[i] = c;
}

/// `+ - * / %`, negation and comparisons on pairs of the sample: `half`'s host results, bit for
/// bit.
fn arithmetic_matches_half(dev: &wp::Device) {
    let s = sample();
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    for (k, &x) in s.iter().enumerate() {
        for j in 0..8 {
            xs.push(x);
            ys.push(s[(k * 31 + j * 101 + 7) % s.len()]);
        }
    }
    let n = xs.len();
    let (a, b) = (arr(&xs, dev), arr(&ys, dev));
    let outs: Vec<wp::Array<f16>> = (0..6).map(|_| zeros::<f16, 1>(n, dev)).collect();
    let cmp = zeros::<u8, 1>(n, dev);
    wp::launch(
        k_arith,
        n,
        (
            &a, &b, &outs[0], &outs[1], &outs[2], &outs[3], &outs[4], &outs[5], &cmp,
        ),
        dev,
    )
    .unwrap();
    let got: Vec<Vec<f16>> = outs.iter().map(host).collect();
    let cmp = host(&cmp);
    for i in 0..n {
        let (x, y) = (xs[i], ys[i]);
        let what = |op: &str| format!("{x} {op} {y} ({:#06x}, {:#06x})", x.to_bits(), y.to_bits());
        same(got[0][i], x + y, &what("+"));
        same(got[1][i], x - y, &what("-"));
        same(got[2][i], x * y, &what("*"));
        same(got[3][i], x / y, &what("/"));
        same(got[4][i], x % y, &what("%"));
        if !x.is_nan() {
            // Negation flips the sign bit (NaN's sign is the platform's).
            assert_eq!(got[5][i].to_bits(), x.to_bits() ^ 0x8000, "{}", what("neg"));
        }
        let want = (x < y) as u8
            | ((x <= y) as u8) << 1
            | ((x == y) as u8) << 2
            | ((x != y) as u8) << 3
            | ((x > y) as u8) << 4
            | ((x >= y) as u8) << 5;
        assert_eq!(cmp[i], want, "{}", what("comparisons"));
    }
}

#[wp::kernel]
fn k_compound(a: Array<f16>, out: Array<f16>) {
    let i = tid();
    let mut x = a[i];
    x += 1.5;
    x *= a[i];
    x -= 0.25;
    x /= 3.0;
    out[i] = x;
    out[i] += 2.0;
}

/// Compound assignment: one rounding per operation, in order.
fn compound_assignment(dev: &wp::Device) {
    let xs: Vec<f16> = [0.1f32, -7.25, 300.0, 1e-3, 250.5, -0.0].map(h).to_vec();
    let a = arr(&xs, dev);
    let out = zeros::<f16, 1>(xs.len(), dev);
    wp::launch(k_compound, xs.len(), (&a, &out), dev).unwrap();
    for (x, g) in xs.iter().zip(host(&out)) {
        let mut w = *x;
        w += h(1.5);
        w *= *x;
        w -= h(0.25);
        w /= h(3.0);
        w += h(2.0);
        same(g, w, &format!("compound on {x}"));
    }
}

#[wp::kernel]
fn k_from_f16(
    a: Array<f16>,
    to_f32: Array<f32>,
    to_f64: Array<f64>,
    to_i32: Array<i32>,
    to_u8: Array<u8>,
    to_i64: Array<i64>,
) {
    let i = tid();
    let x = a[i];
    to_f32[i] = x as f32;
    to_f64[i] = x as f64;
    to_i32[i] = x as i32;
    to_u8[i] = x as u8;
    to_i64[i] = x as i64;
}

#[wp::kernel]
fn k_to_f16(
    f: Array<f32>,
    d: Array<f64>,
    n: Array<i32>,
    u: Array<u64>,
    from_f32: Array<f16>,
    from_f64: Array<f16>,
    from_i32: Array<f16>,
    from_u64: Array<f16>,
) {
    let i = tid();
    from_f32[i] = f[i] as f16;
    from_f64[i] = d[i] as f16;
    from_i32[i] = n[i] as f16;
    from_u64[i] = u[i] as f16;
}

/// `as` with Rust's semantics: f16 to floats exactly, to integers saturating (NaN to 0); to
/// f16 rounded once to nearest even, overflowing to infinity.
fn casts_have_rust_semantics(dev: &wp::Device) {
    // From f16: every bit pattern.
    let all: Vec<f16> = (0u32..=0xFFFF).map(|b| f16::from_bits(b as u16)).collect();
    let n = all.len();
    let a = arr(&all, dev);
    let (f, d) = (zeros::<f32, 1>(n, dev), zeros::<f64, 1>(n, dev));
    let (i, u, l) = (
        zeros::<i32, 1>(n, dev),
        zeros::<u8, 1>(n, dev),
        zeros::<i64, 1>(n, dev),
    );
    wp::launch(k_from_f16, n, (&a, &f, &d, &i, &u, &l), dev).unwrap();
    let (f, d, i, u, l) = (host(&f), host(&d), host(&i), host(&u), host(&l));
    for k in 0..n {
        let x = all[k];
        let (wf, wd) = (x.to_f32(), x.to_f64());
        assert!(f[k] == wf || (wf.is_nan() && f[k].is_nan()), "{x} as f32");
        assert!(
            f[k].to_bits() == wf.to_bits() || wf.is_nan(),
            "{x} as f32 (sign of zero)"
        );
        assert!(
            d[k].to_bits() == wd.to_bits() || (wd.is_nan() && d[k].is_nan()),
            "{x} as f64"
        );
        assert_eq!(i[k], wf as i32, "{x} as i32");
        assert_eq!(u[k], wf as u8, "{x} as u8");
        assert_eq!(l[k], wf as i64, "{x} as i64");
    }

    // To f16: f32 values around every f16 tie and a pseudo-random sample of all f32.
    let mut fs: Vec<f32> = Vec::new();
    for b in (0u16..0x7C00).step_by(13) {
        let v = f16::from_bits(b).to_f32();
        let next = f16::from_bits(b + 1).to_f32();
        let mid = (v + next) / 2.0; // exact in f32
        fs.extend([
            mid,
            f32::from_bits(mid.to_bits() - 1),
            f32::from_bits(mid.to_bits() + 1),
        ]);
        fs.extend([-mid, v]);
    }
    let mut s = 0x9E37_79B9u32;
    for _ in 0..4000 {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        fs.push(f32::from_bits(s));
    }
    fs.extend([
        65519.0,
        65520.0,
        65536.0,
        1e30,
        -1e30,
        f32::INFINITY,
        f32::NAN,
        1e-10,
    ]);
    let n = fs.len();
    // f64 values: the f32 ones (exact in f64: half's single rounding is the reference) and the
    // points just off a tie that rounding through f32 would move onto it.
    let mut ds: Vec<f64> = fs.iter().map(|&x| x as f64).collect();
    let off_tie = [
        (1.0 + 2f64.powi(-11) + 2f64.powi(-40), 0x3C01u16),
        (1.0 + 2f64.powi(-11) - 2f64.powi(-40), 0x3C00),
        (-(1.0 + 3.0 * 2f64.powi(-11) - 2f64.powi(-45)), 0xBC01),
        (65520.0 - 2f64.powi(-30), 0x7BFF),
        (2f64.powi(-25) + 2f64.powi(-60), 0x0001),
    ];
    for (k, (x, _)) in off_tie.iter().enumerate() {
        ds[k] = *x;
    }
    let ns: Vec<i32> = (0..n as i32)
        .map(|k| (k - n as i32 / 2).wrapping_mul(37))
        .collect();
    let us: Vec<u64> = (0..n as u64)
        .map(|k| k.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> (k % 64))
        .collect();
    let (fa, da, na, ua) = (arr(&fs, dev), arr(&ds, dev), arr(&ns, dev), arr(&us, dev));
    let outs: Vec<wp::Array<f16>> = (0..4).map(|_| zeros::<f16, 1>(n, dev)).collect();
    wp::launch(
        k_to_f16,
        n,
        (&fa, &da, &na, &ua, &outs[0], &outs[1], &outs[2], &outs[3]),
        dev,
    )
    .unwrap();
    let got: Vec<Vec<f16>> = outs.iter().map(host).collect();
    for k in 0..n {
        same(got[0][k], h(fs[k]), &format!("{:e} as f16", fs[k]));
        if k < off_tie.len() {
            assert_eq!(
                got[1][k].to_bits(),
                off_tie[k].1,
                "{:e} (f64) as f16",
                ds[k]
            );
        } else {
            same(got[1][k], h(fs[k]), &format!("{:e} (f64) as f16", ds[k]));
        }
        same(
            got[2][k],
            h(ns[k] as f32),
            &format!("{} (i32) as f16", ns[k]),
        );
        same(
            got[3][k],
            h(us[k] as f32),
            &format!("{} (u64) as f16", us[k]),
        );
    }
}

#[wp::kernel]
fn k_literals(x: Array<f16>, out: Array<f16>) {
    out[0] = x[0] * 2.0;
    out[1] = 0.1;
    out[2] = 65504.0;
    // The largest literal below the midpoint above MAX (from 65520 on a literal would round
    // to infinity, which the literal rule rejects as out of range, as Rust does).
    out[3] = 65519.99;
    out[4] = 1e-8;
    out[5] = 6e-8;
    out[6] = 1.00048828125;
    out[7] = 1.0004882812500002;
    out[8] = f16::MAX;
    out[9] = f16::EPSILON;
    out[10] = f16::INFINITY;
    out[11] = std::f64::consts::PI as f16;
    out[12] = f16::PI;
    out[13] = 1.5f16;
    out[14] = 3 as f16;
    out[15] = x[0] + 1;
}

/// Literals next to an f16 are f16, rounded once (ties to even) from their value.
fn literals_round_once(dev: &wp::Device) {
    let x = arr(&[h(1.25)], dev);
    let out = zeros::<f16, 1>(16, dev);
    wp::launch(k_literals, 1, (&x, &out), dev).unwrap();
    let got: Vec<u16> = host(&out).iter().map(|v| v.to_bits()).collect();
    let want: [u16; 16] = [
        0x4100, // 2.5
        0x2E66, // 0.1 rounded
        0x7BFF, // f16::MAX
        0x7BFF, // just below the midpoint above MAX: MAX
        0x0000, // below half the smallest subnormal
        0x0001, // nearest the smallest subnormal 2^-24
        0x3C00, // 1 + 2^-11 is a tie: to even, 1
        0x3C01, // just above the tie: up
        0x7BFF, 0x1400, // 2^-10
        0x7C00, 0x4248, // pi
        0x4248, 0x3E00, 0x4200, 0x4080, // 2.25
    ];
    assert_eq!(got, want);
}

#[wp::kernel]
fn k_edges(a: Array<f16>, b: Array<f16>, out: Array<f16>) {
    let i = tid();
    out[i] = a[i] * b[i];
}

/// Overflow to infinity past 65504, gradual underflow through the subnormals, NaN
/// propagation: as IEEE binary16.
fn overflow_subnormals_nan(dev: &wp::Device) {
    let tiny = f16::MIN_POSITIVE_SUBNORMAL;
    let cases: &[(f16, f16, f16)] = &[
        (f16::MAX, h(1.0), f16::MAX),
        (f16::MAX, h(1.001), f16::INFINITY),
        (f16::MAX, h(-2.0), f16::NEG_INFINITY),
        (h(300.0), h(300.0), f16::INFINITY),
        (h(255.0), h(256.0), h(65280.0)),
        (tiny, h(0.5), f16::ZERO),         // the tie 2^-25 goes to even: 0
        (tiny, h(1.5), f16::from_bits(2)), // the tie 1.5 units goes to 2
        (tiny, h(-0.25), f16::NEG_ZERO),   // underflow keeps the sign
        (f16::MIN_POSITIVE, h(0.5), f16::from_bits(0x200)), // normal to subnormal, exact
        (f16::NAN, h(1.0), f16::NAN),
        (f16::INFINITY, f16::ZERO, f16::NAN),
        (f16::INFINITY, h(-1.0), f16::NEG_INFINITY),
    ];
    let (a, b): (Vec<f16>, Vec<f16>) = cases.iter().map(|c| (c.0, c.1)).unzip();
    let out = zeros::<f16, 1>(cases.len(), dev);
    wp::launch(
        k_edges,
        cases.len(),
        (&arr(&a, dev), &arr(&b, dev), &out),
        dev,
    )
    .unwrap();
    for (c, g) in cases.iter().zip(host(&out)) {
        same(g, c.2, &format!("{} * {}", c.0, c.1));
        same(g, c.0 * c.1, "half's product");
    }
}

#[wp::kernel]
fn k_math(x: Array<f16>, y: Array<f16>, out: Array<f16, 2>) {
    let i = tid();
    let a = x[i];
    let b = y[i];
    out[(i, 0)] = a.sqrt();
    out[(i, 1)] = exp(a);
    out[(i, 2)] = log(a);
    out[(i, 3)] = sin(a);
    out[(i, 4)] = cos(a);
    out[(i, 5)] = tan(a);
    out[(i, 6)] = pow(a, b);
    out[(i, 7)] = abs(a);
    out[(i, 8)] = sign(a);
    out[(i, 9)] = floor(a);
    out[(i, 10)] = a.ceil();
    out[(i, 11)] = min(a, b);
    out[(i, 12)] = max(a, b);
    out[(i, 13)] = clamp(a, -1.0, 2.0);
    out[(i, 14)] = atan2(a, b);
    out[(i, 15)] = tanh(a);
    out[(i, 16)] = a.round();
    out[(i, 17)] = lerp(a, b, 0.25);
    out[(i, 18)] = smoothstep(-1.0, 3.0, a);
    out[(i, 19)] = erf(a);
    out[(i, 20)] = a.trunc();
    out[(i, 21)] = frac(a);
    out[(i, 22)] = asin(a);
    out[(i, 23)] = exp2(a);
    out[(i, 24)] = cbrt(a);
    out[(i, 25)] = degrees(a);
    out[(i, 26)] = step(a);
}

/// Which columns of `k_math` are exact on both backends (the rest are the platforms' f32
/// transcendental functions: one f16 ulp apart at most on CUDA).
const MATH_EXACT: [bool; 27] = [
    true, false, false, false, false, false, false, true, true, true, true, true, true, true,
    false, false, true, false, false, false, true, true, false, false, false, false, true,
];

/// The scalar math builtins on f16: the f32 builtin of the widened arguments rounded once
/// (`half::f16::from_f32(f32 op)`), bit for bit on the CPU. (`max(..).min(..)`, not `clamp`,
/// in the reference: the builtin's NaN rule gives the lower bound for a NaN input.)
#[allow(clippy::manual_clamp)]
fn builtins_round_the_f32_result_once(dev: &wp::Device) {
    let xs = sample();
    let ys: Vec<f16> = (0..xs.len())
        .map(|k| xs[(k * 53 + 11) % xs.len()])
        .collect();
    let n = xs.len();
    let out = zeros::<f16, 2>((n, 27), dev);
    wp::launch(k_math, n, (&arr(&xs, dev), &arr(&ys, dev), &out), dev).unwrap();
    let got = host(&out);
    let lerp = |a: f32, b: f32, t: f32| a * (1.0 - t) + b * t;
    let smooth = |e0: f32, e1: f32, x: f32| {
        let t = ((x - e0) / (e1 - e0)).max(0.0).min(1.0);
        t * t * (3.0 - 2.0 * t)
    };
    for i in 0..n {
        let (a, b) = (xs[i].to_f32(), ys[i].to_f32());
        let want: [f32; 27] = [
            a.sqrt(),
            a.exp(),
            a.ln(),
            a.sin(),
            a.cos(),
            a.tan(),
            a.powf(b),
            a.abs(),
            if a < 0.0 { -1.0 } else { 1.0 },
            a.floor(),
            a.ceil(),
            a.min(b),
            a.max(b),
            a.max(-1.0).min(2.0),
            a.atan2(b),
            a.tanh(),
            a.round(),
            lerp(a, b, 0.25),
            smooth(-1.0, 3.0, a),
            wp_erf(a),
            a.trunc(),
            a - a.trunc(),
            a.clamp(-1.0, 1.0).asin(),
            a.exp2(),
            a.cbrt(),
            a.to_degrees(),
            if a < 0.0 { 1.0 } else { 0.0 },
        ];
        for (c, w) in want.iter().enumerate() {
            let g = got[i * 27 + c];
            let w = h(*w);
            if dev.is_cpu() || MATH_EXACT[c] {
                same(g, w, &format!("builtin {c} of {a:e}, {b:e}"));
            } else {
                assert!(
                    ulps(g, w) <= 1,
                    "builtin {c} of {a:e}, {b:e}: got {g}, want {w}"
                );
            }
        }
    }
}

/// The f32 `erf` of the CPU backend, through a kernel (its implementation is warp-core's).
fn wp_erf(x: f32) -> f32 {
    #[wp::kernel]
    fn k_erf(x: Array<f32>, out: Array<f32>) {
        out[0] = erf(x[0]);
    }
    let cpu = wp::cpu();
    let out = zeros::<f32, 1>(1, &cpu);
    wp::launch(k_erf, 1, (&arr(&[x], &cpu), &out), &cpu).unwrap();
    host(&out)[0]
}

#[wp::kernel]
fn k_scale(x: Array<f16>, y: Array<f16>) {
    let i = tid();
    y[i] = x[i] * 2.0 - 1.0;
}

#[wp::kernel]
fn k_histogram(bins: Array<f16>, lo: Array<f16>, hi: Array<f16>) {
    let i = tid();
    atomic_add(bins, i % 8, 1.0);
    atomic_sub(bins, 8 + i % 4, 0.5);
    let v = (i % 1000) as f16 - 300.0;
    atomic_min(lo, 0, v);
    atomic_max(hi, 0, v);
}

/// f16 arrays read and written by kernels; atomic_add/sub/min/max from many threads (sums of
/// integers and halves below 2048 are exact in f16, so the result is exact in any order).
fn arrays_and_atomics(dev: &wp::Device) {
    let xs: Vec<f16> = (0..1000).map(|k| h(k as f32 * 0.125 - 40.0)).collect();
    let y = zeros::<f16, 1>(xs.len(), dev);
    wp::launch(k_scale, xs.len(), (&arr(&xs, dev), &y), dev).unwrap();
    for (x, g) in xs.iter().zip(host(&y)) {
        same(g, *x * h(2.0) - h(1.0), "x * 2 - 1");
    }
    let n = 4096;
    let bins = zeros::<f16, 1>(12, dev);
    let (lo, hi) = (arr(&[f16::MAX], dev), arr(&[f16::MIN], dev));
    wp::launch(k_histogram, n, (&bins, &lo, &hi), dev).unwrap();
    let bins = host(&bins);
    for (k, b) in bins.iter().enumerate() {
        let want = if k < 8 { h(512.0) } else { h(-512.0) };
        same(*b, want, &format!("bin {k}"));
    }
    same(host(&lo)[0], h(-300.0), "atomic_min");
    same(host(&hi)[0], h(699.0), "atomic_max");
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Half {
    a: f16,
    b: f16,
    n: i32,
}

#[wp::func]
fn fma16(x: f16, y: f16, z: f16) -> f16 {
    x * y + z
}

#[wp::kernel]
fn k_struct(p: Array<Half>, s: f16, out: Array<f16>) {
    let i = tid();
    let mut q = p[i];
    q.a = fma16(q.a, s, q.b);
    q.b += 1.0;
    p[i] = q;
    out[i] = q.a + (q.n as f16);
}

/// f16 as a struct field, a kernel parameter, and a func's parameters and result.
fn struct_fields_and_funcs(dev: &wp::Device) {
    let ps: Vec<Half> = (0..5)
        .map(|k| Half {
            a: h(k as f32 + 0.5),
            b: h(-1.25),
            n: k * 1000,
        })
        .collect();
    let p = arr(&ps, dev);
    let out = zeros::<f16, 1>(5, dev);
    wp::launch(k_struct, 5, (&p, h(3.0), &out), dev).unwrap();
    let got = host(&p);
    for (k, (q, o)) in ps.iter().zip(host(&out)).enumerate() {
        let a = q.a * h(3.0) + q.b;
        same(got[k].a, a, "field a");
        same(got[k].b, q.b + h(1.0), "field b");
        assert_eq!(got[k].n, q.n);
        same(o, a + h(q.n as f32), "result");
    }
}

#[wp::kernel]
fn k_loss(x: Array<f16>, loss: Array<f16>) {
    let i = tid();
    let v = x[i];
    atomic_add(loss, 0, v * v * 0.5 + sin(v));
}

/// Gradients of f16 arrays through a Tape: d/dx (x^2/2 + sin x) = x + cos x, each adjoint
/// step an f16 operation (so the gradient is the f16 evaluation of `1 * x + 1 * cos(x)`
/// accumulated in f16).
fn gradients_through_a_tape(dev: &wp::Device) {
    let xs: Vec<f16> = [-2.0f32, -0.5, 0.0, 0.75, 1.5, 3.0].map(h).to_vec();
    let x = arr(&xs, dev).with_grad().unwrap();
    let loss = zeros::<f16, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_loss, xs.len(), (&x, &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    let g = host(&x.grad().unwrap());
    for (v, g) in xs.iter().zip(g) {
        // The adjoint of `v * v * 0.5 + sin(v)` with adj_ret 1, each step an f16 operation:
        // `sin` gives 1 * cos(v), `* 0.5` gives 1 * 0.5 to `v * v`, which gives 0.5 * v to
        // each side; the three contributions to v's adjoint add up in the emitter's order.
        let exact = v.to_f32() + v.to_f32().cos();
        assert!(
            (g.to_f32() - exact).abs() <= 4.0 * f32::from(f16::EPSILON) * exact.abs().max(1.0),
            "grad at {v}: {g} vs {exact}"
        );
        let c = h(1.0) * h(v.to_f32().cos());
        let s = (h(1.0) * h(0.5)) * *v;
        let orders = [(c + s) + s, (s + s) + c, c + (s + s), (s + c) + s];
        if dev.is_cpu() {
            assert!(
                orders.iter().any(|o| o.to_bits() == g.to_bits()),
                "grad at {v}: {g}, not an f16 evaluation of cos(v) + v/2 + v/2 ({orders:?})"
            );
        }
    }
}

#[wp::kernel]
fn k_f16_fn(x: Array<f16>, y: Array<f16>) {
    let i = tid();
    let v = x[i];
    y[i] = sqrt(v * v + 1.0) * tanh(v) - exp(v * 0.5) / (v * v + 2.0) + max(v, 0.25) * 3.0;
}

/// `wp::gradcheck` on an f16 kernel with the f16 defaults (step 1/16, 5e-2 relative; the
/// reasons are at `CheckFloat for f16`): a Jacobian from f16 adjoints against central
/// differences of f16 outputs.
fn gradcheck_f16(dev: &wp::Device) {
    let xs: Vec<f16> = [-1.5f32, -0.75, 0.5, 1.25, 2.0].map(h).to_vec();
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f16, 1>(xs.len(), dev).with_grad().unwrap();
    let report = wp::gradcheck(
        || wp::launch(k_f16_fn, xs.len(), (&x, &y), dev),
        &[&x],
        &[&y],
        wp::GradcheckOptions::for_type::<f16>(),
    )
    .unwrap();
    assert!(report.passed, "{report:?}");
    // A wrong gradient fails: the same check with the Jacobian doubled.
    let opts = wp::GradcheckOptions::for_type::<f16>();
    let mut bad = 0;
    for (r, row) in report.analytic.iter().enumerate() {
        for (c, a) in row.iter().enumerate() {
            let num = report.numeric[r][c];
            if (2.0 * a - num).abs() > opts.atol + opts.rtol * num.abs() {
                bad += 1;
            }
        }
    }
    assert_eq!(
        bad,
        xs.len(),
        "a doubled gradient must fail on the diagonal"
    );
}

#[wp::kernel]
fn k_blowup(x: Array<f16>, y: Array<f16>) {
    let i = tid();
    y[i] = x[i] * x[i] * 10.0;
}

/// A computation that overflows f16 (100^2 * 10 > 65504) is caught by `verify_fp` at the
/// launch and by `check_finite` between steps.
fn divergence_is_detected(dev: &wp::Device) {
    let x = arr(&[h(1.0), h(100.0), h(2.0)], dev);
    let y = zeros::<f16, 1>(3, dev);
    wp::config::set_verify_fp_for_thread(Some(true));
    let r = wp::launch(k_blowup, 3, (&x, &y), dev);
    wp::config::set_verify_fp_for_thread(None);
    match r {
        Err(e @ wp::Error::NonFinite { .. }) => assert_eq!(
            e.to_string(),
            "kernel `k_blowup` wrote a non-finite value to `y` at index [1]: inf"
        ),
        other => panic!("expected NonFinite, got {other:?}"),
    }
    wp::launch(k_blowup, 3, (&x, &y), dev).unwrap();
    let e = y.check_finite("f16 step").unwrap_err();
    assert_eq!(
        e.to_string(),
        "f16 step diverged: non-finite value at index [1]: inf"
    );
    x.copy_from(&arr(&[h(1.0), h(80.0), h(2.0)], dev)).unwrap();
    wp::launch(k_blowup, 3, (&x, &y), dev).unwrap();
    y.check_finite("f16 step").unwrap();
    same(host(&y)[1], h(64000.0), "80^2 * 10");
}

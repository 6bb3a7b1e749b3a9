//! `bf16` (Warp's `bfloat16`, the `half` crate's type) in the kernel language: arithmetic,
//! casts, literals, builtins, arrays and atomics, gradients, and tiles (loads, stores,
//! elementwise operators, `tile_matmul` accumulating in f32), on every backend, against the
//! host.
//!
//! Exactness: every bf16 operation widens its operands to f32 exactly, computes one f32
//! operation and rounds once to nearest even, in software on both backends (`half`'s rounding,
//! transcribed in `wp_core.h`), so `+ - * / %`, casts and the exact builtins are compared bit
//! for bit (a NaN result against any NaN: an f32 operation's NaN payload is the platform's). The transcendental builtins are each platform's f32 functions, a few
//! f32 ulp apart, so they may differ by one bf16 ulp on CUDA. The tile matmul's FMA path (the
//! CPU; CUDA below sm_80, or for shapes or blocks the tensor cores do not take) is one f32 FMA
//! chain per output in ascending k, compared bit for bit with the host's chain; CUDA's tensor
//! cores (`mma.sync` m16n8k16 `.bf16`) sum each k-step in their own order, so there the matmul
//! is compared with f64 only, within the bound stated at `bf16_gemm_accumulates_in_f32`.

// The kernel language has no `div_ceil` yet: kernels round up with `(n + d - 1) / d`.
#![allow(clippy::manual_div_ceil)]

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    bf16_arithmetic_matches_half,
    bf16_casts_round_once,
    bf16_literals_round_once,
    bf16_builtins_round_the_f32_result_once,
    bf16_atomics,
    bf16_gradients_through_a_tape,
    bf16_tiles_elementwise,
    bf16_gemm_accumulates_in_f32,
    bf16_tile_matmul_gradients,
    bf16_dlpack_dtype,
);

fn b(x: f32) -> bf16 {
    bf16::from_f32(x)
}

/// Same bits, or both NaN.
#[track_caller]
fn same(got: bf16, want: bf16, what: &str) {
    assert!(
        got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()),
        "{what}: got {got} ({:#06x}), want {want} ({:#06x})",
        got.to_bits(),
        want.to_bits()
    );
}

/// Every 89th bf16 bit pattern (all exponents, both signs, subnormals, infinities, NaNs) and
/// the special values.
fn sample() -> Vec<bf16> {
    let mut v: Vec<bf16> = (0u32..=0xFFFF)
        .step_by(89)
        .map(|x| bf16::from_bits(x as u16))
        .collect();
    v.extend([
        bf16::ZERO,
        bf16::NEG_ZERO,
        bf16::ONE,
        bf16::MAX,
        bf16::MIN,
        bf16::INFINITY,
        bf16::NEG_INFINITY,
        bf16::NAN,
        bf16::MIN_POSITIVE,
        bf16::from_bits(1),
        b(0.1),
        b(3.0),
    ]);
    v
}

#[wp::kernel]
fn k_arith(
    a: Array<bf16>,
    b: Array<bf16>,
    sum: Array<bf16>,
    diff: Array<bf16>,
    prod: Array<bf16>,
    quot: Array<bf16>,
    rem: Array<bf16>,
    neg: Array<bf16>,
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

/// `+ - * / %`, negation and comparisons on pairs of the sample: `half`'s host results, bit
/// for bit.
fn bf16_arithmetic_matches_half(dev: &wp::Device) {
    let s = sample();
    let (mut xs, mut ys) = (Vec::new(), Vec::new());
    for (k, &x) in s.iter().enumerate() {
        for j in 0..8 {
            xs.push(x);
            ys.push(s[(k * 31 + j * 101 + 7) % s.len()]);
        }
    }
    let n = xs.len();
    let (a, bb) = (arr(&xs, dev), arr(&ys, dev));
    let outs: Vec<wp::Array<bf16>> = (0..6).map(|_| zeros::<bf16, 1>(n, dev)).collect();
    let cmp = zeros::<u8, 1>(n, dev);
    wp::launch(
        k_arith,
        n,
        (
            &a, &bb, &outs[0], &outs[1], &outs[2], &outs[3], &outs[4], &outs[5], &cmp,
        ),
        dev,
    )
    .unwrap();
    let got: Vec<Vec<bf16>> = outs.iter().map(host).collect();
    let cmp = host(&cmp);
    for i in 0..n {
        let (x, y) = (xs[i], ys[i]);
        let what = |op: &str| format!("{x} {op} {y} ({:#06x}, {:#06x})", x.to_bits(), y.to_bits());
        same(got[0][i], x + y, &what("+"));
        same(got[1][i], x - y, &what("-"));
        same(got[2][i], x * y, &what("*"));
        same(got[3][i], x / y, &what("/"));
        same(got[4][i], x % y, &what("%"));
        assert_eq!(got[5][i].to_bits(), x.to_bits() ^ 0x8000, "{}", what("neg"));
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
fn k_from_bf16(
    a: Array<bf16>,
    to_f32: Array<f32>,
    to_f64: Array<f64>,
    to_i32: Array<i32>,
    to_u8: Array<u8>,
    to_f16: Array<f16>,
) {
    let i = tid();
    let x = a[i];
    to_f32[i] = x as f32;
    to_f64[i] = x as f64;
    to_i32[i] = x as i32;
    to_u8[i] = x as u8;
    to_f16[i] = x as f16;
}

#[wp::kernel]
fn k_to_bf16(
    f: Array<f32>,
    d: Array<f64>,
    n: Array<i64>,
    h: Array<f16>,
    from_f32: Array<bf16>,
    from_f64: Array<bf16>,
    from_i64: Array<bf16>,
    from_f16: Array<bf16>,
) {
    let i = tid();
    from_f32[i] = f[i] as bf16;
    from_f64[i] = d[i] as bf16;
    from_i64[i] = n[i] as bf16;
    from_f16[i] = h[i] as bf16;
}

/// `as` with Rust's meaning: from bf16 exactly to floats, saturating to integers (NaN to 0),
/// rounded once to f16; to bf16 rounded once to nearest even from every type (f64 values just
/// off a tie, and 64-bit integers past 2^24, where rounding through f32 would round twice).
fn bf16_casts_round_once(dev: &wp::Device) {
    use wp::__private::ops::{FromBf16, ToBf16};
    let all: Vec<bf16> = (0u32..=0xFFFF).map(|x| bf16::from_bits(x as u16)).collect();
    let n = all.len();
    let a = arr(&all, dev);
    let (f, d, i, u, h) = (
        zeros::<f32, 1>(n, dev),
        zeros::<f64, 1>(n, dev),
        zeros::<i32, 1>(n, dev),
        zeros::<u8, 1>(n, dev),
        zeros::<f16, 1>(n, dev),
    );
    wp::launch(k_from_bf16, n, (&a, &f, &d, &i, &u, &h), dev).unwrap();
    let (f, d, i, u, h) = (host(&f), host(&d), host(&i), host(&u), host(&h));
    for k in 0..n {
        let x = all[k];
        let wf = x.to_f32();
        assert!(
            f[k].to_bits() == wf.to_bits() || (wf.is_nan() && f[k].is_nan()),
            "{x} as f32"
        );
        assert!(
            d[k] == x.to_f64() || (wf.is_nan() && d[k].is_nan()),
            "{x} as f64"
        );
        assert_eq!(i[k], wf as i32, "{x} as i32");
        assert_eq!(u[k], wf as u8, "{x} as u8");
        let wh = f16::from_bf16(x);
        assert!(
            h[k].to_bits() == wh.to_bits() || (wh.is_nan() && h[k].is_nan()),
            "{x} as f16"
        );
    }

    // To bf16: f32 values at, just below and just above every 7th tie, and a random sample.
    let mut fs: Vec<f32> = Vec::new();
    for x in (0u16..0x7F80).step_by(7) {
        let v = bf16::from_bits(x).to_f32();
        let mid = f32::from_bits(v.to_bits() + 0x8000); // the tie above v, exact in f32
        fs.extend([
            mid,
            f32::from_bits(mid.to_bits() - 1),
            f32::from_bits(mid.to_bits() + 1),
            -mid,
            v,
        ]);
    }
    let mut s = 0x9E37_79B9u32;
    for _ in 0..4000 {
        s ^= s << 13;
        s ^= s >> 17;
        s ^= s << 5;
        fs.push(f32::from_bits(s));
    }
    fs.extend([f32::MAX, f32::INFINITY, f32::NAN, 1e-40]);
    let m = fs.len();
    let mut ds: Vec<f64> = fs.iter().map(|&x| x as f64).collect();
    // Just off a tie: through f32 these land on the tie and round to even, the wrong way.
    let off_tie = [
        (1.0 + 2f64.powi(-8) + 2f64.powi(-40), 0x3F81u16),
        (-(1.0 + 3.0 * 2f64.powi(-8) - 2f64.powi(-45)), 0xBF81),
        (2f64.powi(-134) + 2f64.powi(-170), 0x0001),
    ];
    for (k, (x, _)) in off_tie.iter().enumerate() {
        ds[k] = *x;
    }
    let mut ns: Vec<i64> = (0..m as i64)
        .map(|k| (k - m as i64 / 2).wrapping_mul(0x5DEE_CE66D) >> (k % 40))
        .collect();
    // 2^24 + 2^16 + 1: above the tie between 2^24 and 2^24 + 2^17, which f32 would round to.
    ns[0] = (1 << 24) + (1 << 16) + 1;
    ns[1] = i64::MIN;
    ns[2] = 257;
    let hs: Vec<f16> = (0..m).map(|k| f16::from_bits((k * 13) as u16)).collect();
    let (fa, da, na, ha) = (arr(&fs, dev), arr(&ds, dev), arr(&ns, dev), arr(&hs, dev));
    let outs: Vec<wp::Array<bf16>> = (0..4).map(|_| zeros::<bf16, 1>(m, dev)).collect();
    wp::launch(
        k_to_bf16,
        m,
        (&fa, &da, &na, &ha, &outs[0], &outs[1], &outs[2], &outs[3]),
        dev,
    )
    .unwrap();
    let got: Vec<Vec<bf16>> = outs.iter().map(host).collect();
    for k in 0..m {
        same(got[0][k], b(fs[k]), &format!("{:e} as bf16", fs[k]));
        if k < off_tie.len() {
            assert_eq!(
                got[1][k].to_bits(),
                off_tie[k].1,
                "{:e} (f64) as bf16",
                ds[k]
            );
        } else {
            same(got[1][k], b(fs[k]), &format!("{:e} (f64) as bf16", ds[k]));
        }
        same(
            got[2][k],
            ns[k].to_bf16(),
            &format!("{} (i64) as bf16", ns[k]),
        );
        same(
            got[3][k],
            hs[k].to_bf16(),
            &format!("{} (f16) as bf16", hs[k]),
        );
    }
    assert_eq!(got[2][0].to_f64(), ((1i64 << 24) + (1 << 17)) as f64);
    assert_eq!(got[2][2].to_f32(), 256.0);
}

#[wp::kernel]
fn k_literals(x: Array<bf16>, out: Array<bf16>) {
    out[0] = x[0] * 2.0;
    out[1] = 0.1;
    out[2] = 1.00390625; // 1 + 2^-8, a tie: to even, 1
    out[3] = 1.0039062500000002; // just above the tie: up
    out[4] = bf16::MAX;
    out[5] = bf16::EPSILON;
    out[6] = bf16::INFINITY;
    out[7] = std::f64::consts::PI as bf16;
    out[8] = 1.5bf16;
    out[9] = 3 as bf16;
    out[10] = x[0] + 1;
    out[11] = 3.0e38;
}

/// Literals next to a bf16 are bf16, rounded once (ties to even) from their value.
fn bf16_literals_round_once(dev: &wp::Device) {
    let x = arr(&[b(1.25)], dev);
    let out = zeros::<bf16, 1>(12, dev);
    wp::launch(k_literals, 1, (&x, &out), dev).unwrap();
    let got: Vec<u16> = host(&out).iter().map(|v| v.to_bits()).collect();
    let want: [u16; 12] = [
        0x4020, // 2.5
        0x3DCD, // 0.1 rounded
        0x3F80, 0x3F81, 0x7F7F, // bf16::MAX
        0x3C00, // 2^-7
        0x7F80, 0x4049, // pi
        0x3FC0, 0x4040, 0x4010, // 2.25
        0x7F62, // 3e38
    ];
    assert_eq!(got, want);
}

#[wp::kernel]
fn k_builtins(a: Array<bf16>, exact: Array<bf16, 2>, approx: Array<bf16, 2>, flags: Array<u8>) {
    let i = tid();
    let x = a[i];
    exact[(i, 0)] = sqrt(x);
    exact[(i, 1)] = abs(x);
    exact[(i, 2)] = floor(x);
    exact[(i, 3)] = min(x, 0.5);
    exact[(i, 4)] = clamp(x, -2.0, 3.0);
    approx[(i, 0)] = exp(x);
    approx[(i, 1)] = sin(x);
    approx[(i, 2)] = pow(x, 1.5);
    let mut f = 0u8;
    if isnan(x) {
        f |= 1;
    }
    if isinf(x) {
        f |= 2;
    }
    flags[i] = f;
}

/// Builtins: the f32 builtin on the widened argument, rounded once (warp-core's rule); exact
/// ones bit for bit, transcendental ones within one bf16 ulp on CUDA (the platform's f32
/// functions differ by a few f32 ulp, which rounding to 8 bits almost always hides).
fn bf16_builtins_round_the_f32_result_once(dev: &wp::Device) {
    let xs = sample();
    let n = xs.len();
    let a = arr(&xs, dev);
    let exact = wp::Array::<bf16, 2>::zeros((n, 5), dev).unwrap();
    let approx = wp::Array::<bf16, 2>::zeros((n, 3), dev).unwrap();
    let flags = zeros::<u8, 1>(n, dev);
    wp::launch(k_builtins, n, (&a, &exact, &approx, &flags), dev).unwrap();
    let (e, ap, fl) = (host(&exact), host(&approx), host(&flags));
    for (k, &x) in xs.iter().enumerate() {
        let xf = x.to_f32();
        let want = [
            xf.sqrt(),
            xf.abs(),
            xf.floor(),
            xf.min(0.5),
            // The builtin is fmin(fmax(x, lo), hi): a NaN x loses to lo.
            xf.clamp(-2.0, 3.0).max(-2.0),
        ];
        for (c, w) in want.iter().enumerate() {
            same(e[k * 5 + c], b(*w), &format!("exact builtin {c} of {x}"));
        }
        let want = [xf.exp(), xf.sin(), xf.powf(1.5)];
        for (c, w) in want.iter().enumerate() {
            let (g, w) = (ap[k * 3 + c], b(*w));
            let ok = g.to_bits() == w.to_bits()
                || (g.is_nan() && w.is_nan())
                || (!dev.is_cpu() && (g.to_bits() as i32 - w.to_bits() as i32).abs() <= 1);
            assert!(ok, "builtin {c} of {x}: {g} vs {w}");
        }
        assert_eq!(
            fl[k],
            xf.is_nan() as u8 | (xf.is_infinite() as u8) << 1,
            "{x}"
        );
    }
}

#[wp::kernel]
fn k_atomics(v: Array<bf16>, sum: Array<bf16>, lo: Array<bf16>, hi: Array<bf16>) {
    let i = tid();
    atomic_add(sum, 0, v[i]);
    atomic_min(lo, 0, v[i]);
    atomic_max(hi, 0, v[i]);
}

/// Atomics on bf16 arrays: 256 values of -1, 0 and 1, whose every partial sum, in whatever
/// order the GPU adds them, is an integer of magnitude at most 256 and so exact in bf16 (8
/// significant bits): any order gives the same bits. (Multiples of 1/8 in [-8, 8) were not:
/// a partial sum past 32 in magnitude needs 9 bits, and an H200's order rounded one.)
fn bf16_atomics(dev: &wp::Device) {
    let xs: Vec<bf16> = (0..256).map(|k| b((k * 37 % 3) as f32 - 1.0)).collect();
    let total: f32 = xs.iter().map(|x| x.to_f32()).sum();
    let v = arr(&xs, dev);
    let (sum, lo, hi) = (
        zeros::<bf16, 1>(1, dev),
        arr(&[bf16::INFINITY], dev),
        arr(&[bf16::NEG_INFINITY], dev),
    );
    wp::launch(k_atomics, xs.len(), (&v, &sum, &lo, &hi), dev).unwrap();
    assert_eq!(host(&sum)[0], b(total));
    assert_eq!(host(&lo)[0], b(-1.0));
    assert_eq!(host(&hi)[0], b(1.0));
}

#[wp::kernel]
fn k_loss(x: Array<bf16>, loss: Array<bf16>) {
    let i = tid();
    let v = x[i];
    atomic_add(loss, 0, v * v * 0.5 + sin(v));
}

/// Reverse mode through bf16: bf16 adjoints (each step of the formula a bf16 operation), and
/// the gradient accumulated into a bf16 array; against `v + cos(v)` within 4 bf16 epsilons.
fn bf16_gradients_through_a_tape(dev: &wp::Device) {
    let xs: Vec<bf16> = [-2.0f32, -0.5, 0.0, 0.75, 1.5, 3.0].map(b).to_vec();
    let x = arr(&xs, dev).with_grad().unwrap();
    let loss = zeros::<bf16, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_loss, xs.len(), (&x, &loss), dev).unwrap();
    }
    tape.backward(&loss).unwrap();
    let g = host(&x.grad().unwrap());
    for (v, g) in xs.iter().zip(g) {
        let exact = v.to_f32() + v.to_f32().cos();
        assert!(
            (g.to_f32() - exact).abs() <= 4.0 * f32::from(bf16::EPSILON) * exact.abs().max(1.0),
            "grad at {v}: {g} vs {exact}"
        );
    }
}

#[wp::kernel]
fn k_tile_ops(a: Array<bf16, 2>, out: Array<bf16, 2>, s: bf16, red: Array<bf16>) {
    let (i, j) = tid();
    let t: Tile<bf16, 16, 8> = tile_load(a, ((i * 16) as i32, (j * 8) as i32));
    let u = -(t * s + t) - tile_ones::<bf16, 16, 8>();
    tile_store(out, tile_map(abs, u), ((i * 16) as i32, (j * 8) as i32));
    let total = tile_sum(tile_map(sign, t));
    let hi = tile_max(t);
    if lane() == 0 && i == 0 && j == 0 {
        red[0] = total[0];
        red[1] = hi[0];
    }
}

/// Tiles of bf16: a ragged load, `abs(-(t s + t) - 1)`, a store; bit for bit the host's. The
/// first block's reductions: the sum of the signs (partial sums are integers of at most 128 in
/// magnitude, exact in bf16 in any order) and the maximum (one of the values).
fn bf16_tiles_elementwise(dev: &wp::Device) {
    let (m, n) = (37usize, 21usize);
    let data: Vec<bf16> = (0..m * n)
        .map(|k| b((k as f32 * 0.37).sin() * 5.0))
        .collect();
    let a = wp::Array::from_slice_shape(&data, (m, n), dev).unwrap();
    let out = wp::Array::<bf16, 2>::zeros((m, n), dev).unwrap();
    let s = b(1.7);
    let red = zeros::<bf16, 1>(2, dev);
    let block0: Vec<f32> = (0..16)
        .flat_map(|r| (0..8).map(move |c| r * n + c))
        .map(|k| data[k].to_f32())
        .collect();
    let signs: f32 = block0
        .iter()
        .map(|x| if *x < 0.0 { -1.0 } else { 1.0 })
        .sum();
    let hi = block0.iter().copied().fold(f32::MIN, f32::max);
    for bd in [1, 32, 64] {
        wp::launch_tiled(
            k_tile_ops,
            (m.div_ceil(16), n.div_ceil(8)),
            (&a, &out, s, &red),
            bd,
            dev,
        )
        .unwrap();
        for (k, (&g, &x)) in host(&out).iter().zip(&data).enumerate() {
            let want = b((-(x * s + x) - b(1.0)).to_f32().abs());
            same(g, want, &format!("element {k} at block_dim {bd}"));
        }
        assert_eq!(
            host(&red),
            vec![b(signs), b(hi)],
            "reductions at block_dim {bd}"
        );
    }
}

const GM: usize = 16;
const GN: usize = 16;
const GK: usize = 16;

#[wp::kernel]
fn k_gemm(a: Array<bf16, 2>, b: Array<bf16, 2>, c: Array<f32, 2>, d: Array<bf16, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f32, GM, GN>();
    let k_tiles = (a.shape()[1] + GK - 1) / GK;
    for k in 0..k_tiles {
        let ta = tile_load::<GM, GK>(a, ((i * GM) as i32, (k * GK) as i32));
        let tb = tile_load::<GK, GN>(b, ((k * GK) as i32, (j * GN) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * GM) as i32, (j * GN) as i32));
    // The returning form, of the first k-step: bf16 out, accumulated in f32, rounded once.
    let ta = tile_load::<GM, GK>(a, ((i * GM) as i32, 0));
    let tb = tile_load::<GK, GN>(b, (0, (j * GN) as i32));
    let p = tile_matmul(ta, tb);
    tile_store(d, p, ((i * GM) as i32, (j * GN) as i32));
}

/// A tiled GEMM of bf16 inputs (each rounded to bf16 once from a value in [-1, 1)) with an
/// f32 accumulator on a ragged 37 x 45 x 29 problem, and the returning form's bf16 product of
/// the first k-step.
///
/// Tolerance: the product of two bf16 values (8 significant bits each) has at most 16 bits
/// and is exact in f32, so the only errors are the f32 accumulation's roundings: the FMA chain
/// is within K 2^-24 sum_k |a||b| (K additions, each off by half an f32 ulp of the running
/// magnitude, itself at most sum |a||b|); the tensor cores, which may truncate rather than
/// round at each addition, within K 2^-23 sum |a||b|. The test allows `K 2^-22 sum |a||b|`
/// against the f64 product of the same bf16 inputs, plus half a bf16 ulp (2^-8 relative to the
/// result) for the bf16 result. Block size 1 (and the CPU at every block size) takes the FMA
/// path and equals the host's chain bit for bit; on CUDA, block sizes 32 and 128 (whole warps,
/// 16 x 16 x 16 operands) take the tensor cores on sm_80+.
fn bf16_gemm_accumulates_in_f32(dev: &wp::Device) {
    let (m, k, n) = (37usize, 45usize, 29usize);
    let vals = |len: usize, seed: usize| -> Vec<bf16> {
        (0..len)
            .map(|t| b((((t * 7919 + seed) % 2039) as f32) / 1019.5 - 1.0))
            .collect()
    };
    let (ad, bd_) = (vals(m * k, 3), vals(k * n, 11));
    let a = wp::Array::from_slice_shape(&ad, (m, k), dev).unwrap();
    let bb = wp::Array::from_slice_shape(&bd_, (k, n), dev).unwrap();
    let c = wp::Array::<f32, 2>::zeros((m, n), dev).unwrap();
    let d = wp::Array::<bf16, 2>::zeros((m, n), dev).unwrap();
    for bd in [1, 32, 128] {
        wp::launch_tiled(
            k_gemm,
            (m.div_ceil(GM), n.div_ceil(GN)),
            (&a, &bb, &c, &d),
            bd,
            dev,
        )
        .unwrap();
        let (gc, gd) = (host(&c), host(&d));
        // The FMA path: the CPU, or a block of fewer than a warp on CUDA.
        let exact_chain = dev.is_cpu() || bd % 32 != 0;
        for i in 0..m {
            for j in 0..n {
                let chain = |ks: std::ops::Range<usize>| {
                    let (mut acc, mut exact, mut mag) = (0f32, 0f64, 0f64);
                    for p in ks {
                        let (x, y) = (ad[i * k + p].to_f32(), bd_[p * n + j].to_f32());
                        acc = x.mul_add(y, acc);
                        exact += x as f64 * y as f64;
                        mag += (x as f64 * y as f64).abs();
                    }
                    (acc, exact, mag)
                };
                let (acc, exact, mag) = chain(0..k);
                let got = gc[i * n + j];
                if exact_chain {
                    assert_eq!(
                        got.to_bits(),
                        acc.to_bits(),
                        "c[{i}][{j}] at block_dim {bd}"
                    );
                }
                let tol = k as f64 * 2f64.powi(-22) * mag;
                assert!(
                    (got as f64 - exact).abs() <= tol,
                    "c[{i}][{j}]: {got} vs {exact} (tol {tol:e})"
                );
                let (acc1, exact1, mag1) = chain(0..GK.min(k));
                let gotd = gd[i * n + j];
                if exact_chain {
                    assert_eq!(gotd, b(acc1), "d[{i}][{j}] at block_dim {bd}");
                }
                let tol = GK as f64 * 2f64.powi(-22) * mag1 + 2f64.powi(-8) * exact1.abs();
                assert!(
                    (gotd.to_f64() - exact1).abs() <= tol,
                    "d[{i}][{j}]: {gotd} vs {exact1} (tol {tol:e})"
                );
            }
        }
    }
}

#[wp::kernel]
fn k_mm_loss(a: Array<bf16, 2>, b: Array<bf16, 2>, out: Array<bf16, 2>) {
    let ta = tile_load::<8, 8>(a, (0, 0));
    let tb = tile_load::<8, 8>(b, (0, 0));
    let p = tile_matmul(ta, tb);
    tile_store(out, p, (0, 0));
}

/// Backward of the returning bf16 `tile_matmul`: with an upstream gradient of ones,
/// `adj_a = 1 bᵀ` (row sums of b) and `adj_b = aᵀ 1` (column sums of a), each an f32 chain of
/// exact products rounded once to bf16. The inputs are multiples of 1/8 in [-2, 2): every
/// partial sum of 8 of them is exact in f32, so the result is the exact sum rounded once.
fn bf16_tile_matmul_gradients(dev: &wp::Device) {
    let av: Vec<bf16> = (0..64)
        .map(|k| b(((k * 29 % 32) as f32 - 16.0) / 8.0))
        .collect();
    let bv: Vec<bf16> = (0..64)
        .map(|k| b(((k * 13 % 32) as f32 - 16.0) / 8.0))
        .collect();
    let a = wp::Array::from_slice_shape(&av, (8, 8), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let bb = wp::Array::from_slice_shape(&bv, (8, 8), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let out = wp::Array::<bf16, 2>::zeros((8, 8), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_mm_loss, 1, (&a, &bb, &out), 32, dev).unwrap();
    }
    tape.backward(&out).unwrap();
    let (ga, gb) = (host(&a.grad().unwrap()), host(&bb.grad().unwrap()));
    for i in 0..8 {
        for kk in 0..8 {
            let want: f32 = (0..8).map(|j| bv[kk * 8 + j].to_f32()).sum();
            assert_eq!(ga[i * 8 + kk], b(want), "adj_a[{i}][{kk}]");
        }
    }
    for kk in 0..8 {
        for j in 0..8 {
            let want: f32 = (0..8).map(|i| av[i * 8 + kk].to_f32()).sum();
            assert_eq!(gb[kk * 8 + j], b(want), "adj_b[{kk}][{j}]");
        }
    }
}

/// DLPack: a bf16 array exports as `kDLBfloat` (code 4), 16 bits, one lane (what PyTorch's
/// `torch.bfloat16` is), imports back as the same memory, and refuses to import as f16.
fn bf16_dlpack_dtype(dev: &wp::Device) {
    use warp_runtime::dlpack::ffi::{DLDataType, DLDataTypeCode};
    use warp_runtime::dlpack::versioned;
    let xs: Vec<bf16> = [1.5f32, -2.0, 0.1, 3e38].map(b).to_vec();
    let a = arr(&xs, dev);
    let t: versioned::Dlpack = a.to_dlpack().unwrap();
    {
        let r = t.validate().unwrap();
        assert!(r
            .dtype()
            .matches(DLDataType::scalar(DLDataTypeCode::BFLOAT, 16)));
        assert_eq!(r.shape(), &[4]);
    }
    // SAFETY: this crate's export (valid until its deleter runs).
    let back = unsafe { wp::Array::<bf16>::from_dlpack(t) }.unwrap();
    assert_eq!(back.device_ptr(), a.device_ptr());
    assert_eq!(host(&back), xs);
    let t: versioned::Dlpack = a.to_dlpack().unwrap();
    // SAFETY: rejected by its dtype before any access.
    match unsafe { wp::Array::<f16>::from_dlpack(t) } {
        Ok(_) => panic!("a bfloat16 tensor imported as f16"),
        Err(e) => assert!(e.to_string().contains("bfloat16"), "{e}"),
    }
}

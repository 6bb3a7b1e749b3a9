//! Extreme values in the norms: `length` and `normalize` of vectors and quaternions (and so
//! distances, `length(a - b)`), forward and adjoint, for components from the smallest
//! subnormal to the largest finite value, in f32 and f64, plus zero, NaN and infinities.
//!
//! The plain formula `sqrt(dot(v, v))` squares the components, which overflows f32 beyond
//! about 1e19 and underflows below about 1e-19; the builtins scale by an exact power of two
//! first (warp-core/src/builtins/norm.rs). The references here do not share that method:
//! f32 results are checked against the same sums computed in f64 (whose range holds every
//! square of an f32, and whose precision makes the reference correctly rounded to f32 but for
//! rare double roundings); f64 results against chained `f64::hypot` (libm's, overflow-free).
//!
//! Tolerances, from the error of the scaled formula (each product, sum, the square root and
//! the quotient round once, relative error at most 2^-24, f64 2^-53, each; the scaling and
//! its undoing are exact but for a subnormal result, which rounds once more):
//! * `length`: 2 ulps (f32) of the reference (a dot of up to 4 terms in error of at most
//!   about 2 ulps of the square, halved by the square root, plus the root's rounding, plus
//!   the reference's own half ulp); f64: 4 ulps, as chained hypot adds up to 1 ulp per link.
//! * `normalize`: each component within 2 (f64: 4) ulps of 1 of the reference, normwise: the
//!   result is a unit vector and components far below 1 carry the error of the norm.
//! * adjoints: 8 ulps of the largest reference component, normwise (several roundings more:
//!   the reciprocal, the projection, and on CUDA FMA contraction).
//!
//! These tolerances hold on both backends: the CUDA library runs the same operations in the
//! same order (bit for bit with `--fmad=false`; contraction only removes roundings).

use crate::{arr, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    length_and_normalize_f32_all_scales,
    length_and_normalize_f64_all_scales,
    quaternion_norms_all_scales,
    exact_cases_and_ieee_specials,
    distance_between_huge_points,
    adjoints_at_huge_and_tiny_scales,
);

#[wp::kernel]
fn k_norms3(v: Array<Vec3>, len: Array<f32>, n: Array<Vec3>) {
    let i = tid();
    len[i] = length(v[i]);
    n[i] = normalize(v[i]);
}

#[wp::kernel]
fn k_norms4(v: Array<Vec4>, len: Array<f32>, n: Array<Vec4>) {
    let i = tid();
    len[i] = length(v[i]);
    n[i] = normalize(v[i]);
}

#[wp::kernel]
fn k_norms3d(v: Array<DVec3>, len: Array<f64>, n: Array<DVec3>) {
    let i = tid();
    len[i] = length(v[i]);
    n[i] = normalize(v[i]);
}

#[wp::kernel]
fn k_norms2d(v: Array<DVec2>, len: Array<f64>, n: Array<DVec2>) {
    let i = tid();
    len[i] = length(v[i]);
    n[i] = normalize(v[i]);
}

#[wp::kernel]
fn k_qnorms(q: Array<Quat>, len: Array<f32>, n: Array<Quat>) {
    let i = tid();
    len[i] = length(q[i]);
    n[i] = normalize(q[i]);
}

#[wp::kernel]
fn k_distance(a: Array<Vec3>, b: Array<Vec3>, d: Array<f32>) {
    let i = tid();
    d[i] = length(a[i] - b[i]);
}

/// A xorshift generator of full-precision lanes in [-1, 1).
struct Rng(u64);
impl Rng {
    fn unit(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

/// `2^e` for any `e` in -1074..=1023, without intermediate over- or underflow.
fn pow2(e: i32) -> f64 {
    2f64.powi(e / 2) * 2f64.powi(e - e / 2)
}

/// The distance in ulps between two finite f32 of the same sign (bit patterns are ordered).
fn ulps32(a: f32, b: f32) -> u32 {
    (a.to_bits() as i64 - b.to_bits() as i64).unsigned_abs() as u32
}

/// The distance in ulps between two finite non-negative f64.
fn ulps64(a: f64, b: f64) -> u64 {
    (a.to_bits() as i128 - b.to_bits() as i128).unsigned_abs() as u64
}

/// Lanes at every binade of f32, from the smallest subnormal (2^-149) to the top (2^127):
/// random directions at `2^e`, and one lane dominating the others by 2^20.
fn f32_lanes<const N: usize>(rng: &mut Rng) -> Vec<[f32; N]> {
    let mut out = Vec::new();
    for e in (-149..=127).step_by(2) {
        let s = pow2(e);
        for _ in 0..3 {
            out.push(std::array::from_fn(|_| (rng.unit() * s) as f32));
        }
        out.push(std::array::from_fn(|i| {
            (s * if i == 0 { -1.0 } else { rng.unit() * pow2(-20) }) as f32
        }));
    }
    // Nonzero: a vector whose lanes all rounded to zero is a zero-vector case (tested apart).
    out.retain(|l| l.iter().any(|&x| x != 0.0));
    out
}

/// Checks f32 lengths and normalized vectors against the f64 reference (module docs).
#[track_caller]
fn check_f32<const N: usize>(lanes: &[[f32; N]], len: &[f32], n: &[[f32; N]], what: &str) {
    for (k, l) in lanes.iter().enumerate() {
        let l64 = l
            .iter()
            .map(|&x| (x as f64) * (x as f64))
            .sum::<f64>()
            .sqrt();
        let want = l64 as f32;
        assert!(
            len[k].is_finite() && ulps32(len[k], want) <= 2,
            "{what} length of {l:?}: got {:e}, want {want:e}",
            len[k]
        );
        for i in 0..N {
            let wi = (l[i] as f64 / l64) as f32;
            assert!(
                (n[k][i] - wi).abs() <= 2.0 * f32::EPSILON,
                "{what} normalize of {l:?}: got {:?}, want component {i} {wi:e}",
                n[k]
            );
        }
    }
}

fn length_and_normalize_f32_all_scales(dev: &wp::Device) {
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let l3 = f32_lanes::<3>(&mut rng);
    let v = arr(
        &l3.iter().map(|l| Vec3::from_array(*l)).collect::<Vec<_>>(),
        dev,
    );
    let (len, n) = (
        zeros::<f32, 1>(l3.len(), dev),
        zeros::<Vec3, 1>(l3.len(), dev),
    );
    wp::launch(k_norms3, l3.len(), (&v, &len, &n), dev).unwrap();
    let n3: Vec<[f32; 3]> = n.to_vec().unwrap().iter().map(|v| v.to_array()).collect();
    check_f32(&l3, &len.to_vec().unwrap(), &n3, "Vec3");

    let l4 = f32_lanes::<4>(&mut rng);
    let v = arr(
        &l4.iter().map(|l| Vec4::from_array(*l)).collect::<Vec<_>>(),
        dev,
    );
    let (len, n) = (
        zeros::<f32, 1>(l4.len(), dev),
        zeros::<Vec4, 1>(l4.len(), dev),
    );
    wp::launch(k_norms4, l4.len(), (&v, &len, &n), dev).unwrap();
    let n4: Vec<[f32; 4]> = n.to_vec().unwrap().iter().map(|v| v.to_array()).collect();
    check_f32(&l4, &len.to_vec().unwrap(), &n4, "Vec4");
}

/// Lanes at binades of f64 from 2^-1074 to 2^1023, as [`f32_lanes`].
fn f64_lanes<const N: usize>(rng: &mut Rng) -> Vec<[f64; N]> {
    let mut out = Vec::new();
    for e in (-1074..=1023).step_by(7) {
        let s = pow2(e);
        for _ in 0..2 {
            out.push(std::array::from_fn(|_| rng.unit() * s));
        }
        out.push(std::array::from_fn(|i| {
            s * if i == 0 { 1.0 } else { rng.unit() * pow2(-40) }
        }));
    }
    out.retain(|l| l.iter().any(|&x| x != 0.0));
    out
}

/// Chained hypot: the f64 reference length.
fn hypot_all(l: &[f64]) -> f64 {
    l.iter().fold(0.0f64, |acc, &x| acc.hypot(x))
}

#[track_caller]
fn check_f64<const N: usize>(lanes: &[[f64; N]], len: &[f64], n: &[[f64; N]], what: &str) {
    for (k, l) in lanes.iter().enumerate() {
        let want = hypot_all(l);
        assert!(
            len[k].is_finite() && ulps64(len[k], want) <= 4,
            "{what} length of {l:?}: got {:e}, want {want:e}",
            len[k]
        );
        // The direction from the lanes scaled to a largest magnitude near 1 (exact: powers
        // of two, applied in two steps), so that a subnormal length's coarse rounding does
        // not enter it.
        let m = l.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let p = -(m.log2().floor() as i32);
        let ls = l.map(|x| x * pow2(p / 2) * pow2(p - p / 2));
        let ws = hypot_all(&ls);
        for i in 0..N {
            let wi = ls[i] / ws;
            assert!(
                (n[k][i] - wi).abs() <= 4.0 * f64::EPSILON,
                "{what} normalize of {l:?}: got {:?}, want component {i} {wi:e}",
                n[k]
            );
        }
    }
}

fn length_and_normalize_f64_all_scales(dev: &wp::Device) {
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let l3 = f64_lanes::<3>(&mut rng);
    let v = arr(
        &l3.iter().map(|l| DVec3::from_array(*l)).collect::<Vec<_>>(),
        dev,
    );
    let (len, n) = (
        zeros::<f64, 1>(l3.len(), dev),
        zeros::<DVec3, 1>(l3.len(), dev),
    );
    wp::launch(k_norms3d, l3.len(), (&v, &len, &n), dev).unwrap();
    let n3: Vec<[f64; 3]> = n.to_vec().unwrap().iter().map(|v| v.to_array()).collect();
    check_f64(&l3, &len.to_vec().unwrap(), &n3, "DVec3");

    let l2 = f64_lanes::<2>(&mut rng);
    let v = arr(
        &l2.iter().map(|l| DVec2::from_array(*l)).collect::<Vec<_>>(),
        dev,
    );
    let (len, n) = (
        zeros::<f64, 1>(l2.len(), dev),
        zeros::<DVec2, 1>(l2.len(), dev),
    );
    wp::launch(k_norms2d, l2.len(), (&v, &len, &n), dev).unwrap();
    let n2: Vec<[f64; 2]> = n.to_vec().unwrap().iter().map(|v| v.to_array()).collect();
    check_f64(&l2, &len.to_vec().unwrap(), &n2, "DVec2");
}

fn quaternion_norms_all_scales(dev: &wp::Device) {
    let mut rng = Rng(0x1234_5678_9abc_def1);
    let lq = f32_lanes::<4>(&mut rng);
    let q = arr(
        &lq.iter().map(|l| Quat::from_array(*l)).collect::<Vec<_>>(),
        dev,
    );
    let (len, n) = (
        zeros::<f32, 1>(lq.len(), dev),
        zeros::<Quat, 1>(lq.len(), dev),
    );
    wp::launch(k_qnorms, lq.len(), (&q, &len, &n), dev).unwrap();
    let nq: Vec<[f32; 4]> = n.to_vec().unwrap().iter().map(|q| q.to_array()).collect();
    check_f32(&lq, &len.to_vec().unwrap(), &nq, "Quat");
    // The zero quaternion normalizes to the identity (not the zero vector), NaN too.
    let q = arr(
        &[
            Quat::from_xyzw(0.0, 0.0, 0.0, 0.0),
            Quat::from_xyzw(0.0, f32::NAN, 1e30, 0.0),
        ],
        dev,
    );
    let (len, n) = (zeros::<f32, 1>(2, dev), zeros::<Quat, 1>(2, dev));
    wp::launch(k_qnorms, 2, (&q, &len, &n), dev).unwrap();
    let (len, n) = (len.to_vec().unwrap(), n.to_vec().unwrap());
    assert_eq!(len[0], 0.0);
    assert!(len[1].is_nan());
    assert_eq!(n, vec![Quat::IDENTITY, Quat::IDENTITY]);
}

/// Exact results (Pythagorean triples at extreme binades, a lone lane) and the IEEE cases.
fn exact_cases_and_ieee_specials(dev: &wp::Device) {
    let (inf, nan) = (f32::INFINITY, f32::NAN);
    let p = |e: i32| pow2(e) as f32;
    let vs = [
        // 0..6: exact.
        Vec3::new(3.0 * p(100), 4.0 * p(100), 0.0),
        Vec3::new(0.0, -3.0 * p(-149), 4.0 * p(-149)),
        Vec3::new(f32::MAX, 0.0, 0.0),
        Vec3::new(0.0, 0.0, -1e-40),
        Vec3::new(2.0 * p(-80), -p(-80), 2.0 * p(-80)),
        Vec3::new(1e38, 1e38, 1e38),
        // 6..: zero and IEEE specials.
        Vec3::ZERO,
        Vec3::new(-0.0, 0.0, -0.0),
        Vec3::new(inf, 1.0, 0.0),
        Vec3::new(1e-30, -inf, 1e30),
        Vec3::new(nan, 1e30, 0.0),
        Vec3::new(inf, nan, 0.0),
        Vec3::new(f32::MAX, f32::MAX, 0.0),
    ];
    let v = arr(&vs, dev);
    let (len, n) = (
        zeros::<f32, 1>(vs.len(), dev),
        zeros::<Vec3, 1>(vs.len(), dev),
    );
    wp::launch(k_norms3, vs.len(), (&v, &len, &n), dev).unwrap();
    let (len, n) = (len.to_vec().unwrap(), n.to_vec().unwrap());
    assert_eq!(len[0], 5.0 * p(100));
    assert_eq!(n[0], Vec3::new(0.6, 0.8, 0.0));
    assert_eq!(len[1], 5.0 * p(-149));
    assert_eq!(n[1], Vec3::new(0.0, -0.6, 0.8));
    assert_eq!((len[2], n[2]), (f32::MAX, Vec3::X));
    assert_eq!((len[3], n[3]), (1e-40, Vec3::NEG_Z));
    assert_eq!(len[4], 3.0 * p(-80));
    // 1e38 * sqrt(3), which f32 holds (the plain formula gave inf).
    assert!(
        ulps32(len[5], (1e38f32 as f64 * 3f64.sqrt()) as f32) <= 1,
        "{}",
        len[5]
    );
    // Zero: length 0, normalize the zero vector.
    assert_eq!((len[6], n[6]), (0.0, Vec3::ZERO));
    assert_eq!((len[7], n[7]), (0.0, Vec3::ZERO));
    // An infinite lane: length inf; normalize divides it to NaN and the finite lanes to 0.
    assert_eq!(len[8], inf);
    assert!(
        n[8].x.is_nan() && n[8].y == 0.0 && n[8].z == 0.0,
        "{:?}",
        n[8]
    );
    assert_eq!(len[9], inf);
    assert!(
        n[9].x == 0.0 && n[9].y.is_nan() && n[9].z == 0.0,
        "{:?}",
        n[9]
    );
    // NaN: length NaN (even beside an infinity); normalize the zero vector (no length > 0).
    assert!(len[10].is_nan() && len[11].is_nan());
    assert_eq!((n[10], n[11]), (Vec3::ZERO, Vec3::ZERO));
    // A length beyond f32::MAX overflows, as IEEE arithmetic does; the direction is still
    // finite.
    assert_eq!(len[12], inf);
    let h = std::f32::consts::FRAC_1_SQRT_2;
    assert!((n[12] - Vec3::new(h, h, 0.0)).abs().max_element() <= f32::EPSILON);
}

/// Distances are `length(a - b)`: between points at 1e30 and 1e-30 apart, finite and accurate.
fn distance_between_huge_points(dev: &wp::Device) {
    let a = arr(
        &[
            Vec3::new(1e30, -2e30, 3e30),
            Vec3::new(1e-30, 0.0, 0.0),
            Vec3::new(1e38, 0.0, 0.0),
        ],
        dev,
    );
    let b = arr(
        &[
            Vec3::new(-1e30, 2e30, 0.0),
            Vec3::new(0.0, 1e-30, 1e-30),
            Vec3::new(-1e38, 1e38, 0.0),
        ],
        dev,
    );
    let d = zeros::<f32, 1>(3, dev);
    wp::launch(k_distance, 3, (&a, &b, &d), dev).unwrap();
    let d = d.to_vec().unwrap();
    let want =
        |x: [f32; 3]| (x.iter().map(|&c| (c as f64) * (c as f64)).sum::<f64>()).sqrt() as f32;
    let diffs = [
        [2e30f32, -4e30, 3e30],
        [1e-30, -1e-30, -1e-30],
        [2e38, -1e38, 0.0],
    ];
    for (k, x) in diffs.iter().enumerate() {
        assert!(
            ulps32(d[k], want(*x)) <= 2,
            "distance {k}: {} vs {}",
            d[k],
            want(*x)
        );
    }
}

#[wp::kernel]
fn k_len_loss(v: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    out[i] = length(v[i]);
}

#[wp::kernel]
fn k_dir_loss(v: Array<Vec3>, c: Vec3, out: Array<f32>) {
    let i = tid();
    out[i] = dot(normalize(v[i]), c);
}

#[wp::kernel]
fn k_len_loss_d(v: Array<DVec3>, c: DVec3, out: Array<f64>) {
    let i = tid();
    out[i] = length(v[i]) + dot(normalize(v[i]), c);
}

/// Normwise comparison of gradients: within `ulps` of the largest reference component.
#[track_caller]
fn close_normwise(got: [f64; 3], want: [f64; 3], eps: f64, ulps: f64, what: &str) {
    let scale = want.iter().fold(0.0f64, |m, w| m.max(w.abs()));
    for i in 0..3 {
        assert!(
            got[i].is_finite() && (got[i] - want[i]).abs() <= ulps * eps * scale,
            "{what}: got {got:?}, want {want:?}"
        );
    }
}

/// Gradients of `length` (`v / |v|`) and of `dot(normalize(v), c)` (`(c - n (n.c)) / |v|`)
/// at scales where the squares leave the range, against those closed forms in f64 (f32
/// kernels) or over hypot (f64); the zero vector's gradient is zero.
fn adjoints_at_huge_and_tiny_scales(dev: &wp::Device) {
    let dirs = [[1.0f64, -2.0, 2.0], [0.3, 0.0, -0.4], [-1.0, 1e-3, 5.0]];
    let c = [0.25f64, -1.5, 0.5];
    for s in [1e30f64, 1e20, 1e-20, 1e-30, 1e-37] {
        let vs: Vec<Vec3> = dirs
            .iter()
            .map(|d| Vec3::new((d[0] * s) as f32, (d[1] * s) as f32, (d[2] * s) as f32))
            .collect();
        for loss in ["length", "normalize"] {
            let v = arr(&vs, dev).with_grad().unwrap();
            let out = zeros::<f32, 1>(vs.len(), dev).with_grad().unwrap();
            let tape = wp::Tape::new();
            {
                let _rec = tape.record();
                let cv = Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
                if loss == "length" {
                    wp::launch(k_len_loss, vs.len(), (&v, &out), dev).unwrap();
                } else {
                    wp::launch(k_dir_loss, vs.len(), (&v, cv, &out), dev).unwrap();
                }
            }
            tape.backward(&out).unwrap();
            let g = v.grad().unwrap().to_vec().unwrap();
            for (k, x) in vs.iter().enumerate() {
                let x = [x.x as f64, x.y as f64, x.z as f64];
                let l = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
                let n = x.map(|a| a / l);
                let want = if loss == "length" {
                    n
                } else {
                    let d = n[0] * c[0] + n[1] * c[1] + n[2] * c[2];
                    [0, 1, 2].map(|i| (c[i] - n[i] * d) / l)
                };
                let got = [g[k].x as f64, g[k].y as f64, g[k].z as f64];
                let what = format!("d {loss} at {x:?}");
                close_normwise(got, want, f32::EPSILON as f64, 8.0, &what);
            }
        }
    }
    // f64 at 1e300 and 1e-300: both gradients in one loss.
    for s in [1e300f64, 1e160, 1e-160, 1e-300] {
        let vs: Vec<DVec3> = dirs
            .iter()
            .map(|d| DVec3::new(d[0] * s, d[1] * s, d[2] * s))
            .collect();
        let v = arr(&vs, dev).with_grad().unwrap();
        let out = zeros::<f64, 1>(vs.len(), dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            let cv = DVec3::from_array(c);
            wp::launch(k_len_loss_d, vs.len(), (&v, cv, &out), dev).unwrap();
        }
        tape.backward(&out).unwrap();
        let g = v.grad().unwrap().to_vec().unwrap();
        for (k, x) in vs.iter().enumerate() {
            let x = x.to_array();
            let l = hypot_all(&x);
            let n = x.map(|a| a / l);
            let d = n[0] * c[0] + n[1] * c[1] + n[2] * c[2];
            // The two terms live at different scales (1 and 1/|v|): compare each part's sum
            // normwise against the larger.
            let want = [0, 1, 2].map(|i| n[i] + (c[i] - n[i] * d) / l);
            close_normwise(
                g[k].to_array(),
                want,
                f64::EPSILON,
                8.0,
                &format!("DVec3 at {x:?}"),
            );
        }
    }
    // The zero vector: zero gradient (the forward returned the zero vector and length 0).
    for loss in ["length", "normalize"] {
        let v = arr(&[Vec3::ZERO], dev).with_grad().unwrap();
        let out = zeros::<f32, 1>(1, dev).with_grad().unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            if loss == "length" {
                wp::launch(k_len_loss, 1, (&v, &out), dev).unwrap();
            } else {
                wp::launch(k_dir_loss, 1, (&v, Vec3::ONE, &out), dev).unwrap();
            }
        }
        tape.backward(&out).unwrap();
        assert_eq!(
            v.grad().unwrap().to_vec().unwrap(),
            vec![Vec3::ZERO],
            "{loss}"
        );
    }
}

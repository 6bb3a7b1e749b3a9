//! Random numbers and Perlin noise: statistics of the draws, the samplers' domains, distinct
//! streams, the state as any assignable place, the same sequences as the host reference on
//! every backend, and the noise's properties.
//!
//! Tolerances. The reference is warp-core's own functions run on the host
//! (`wp::__private::builtins`), which is what the CPU backend calls: bit for bit there. On
//! CUDA, integer draws, uniform floats (`randf`, with a range too), the samplers built from
//! them and `sqrt` (`sample_triangle`, `sample_unit_square`, `sample_unit_cube`) and the noise
//! are bit for bit as well (the CUDA library spells the rounding-sensitive operations with
//! `__fmul_rn`/`__fadd_rn`, which are never contracted). Draws through `logf`, `cosf`, `sinf`,
//! `acosf` or `powf` (`randn`, the ring, disk, sphere and hemisphere samplers) are within
//! [`transcendental_tol`]. `poisson`'s accept/reject decisions go through `logf`/`expf`, so a
//! rare GPU draw may take another branch: at most 1% of the counts may differ there.
//!
//! Statistical bounds: a sample mean of `n` draws with variance `σ²` is within `5 σ / √n` of
//! the true mean (a normal tail of 6e-7; the draws are deterministic, so a failure is a real
//! change of the generator, not bad luck on a rerun).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::__private::builtins as core;
use wp::prelude::*;

backend_tests!(
    uniform_and_normal_statistics,
    integer_draws_and_ranges,
    samplers_stay_in_their_domains,
    sequences_match_the_reference,
    streams_differ_by_offset,
    state_in_arrays_and_struct_fields,
    empty_range_faults,
    poisson_statistics,
    noise_properties,
    noise_matches_the_reference,
);

/// `|got - want| <= tol * max(1, |want|)`: draws through CUDA's `logf`, `cosf`, `sinf`,
/// `acosf`, `powf` (documented to 1, 2, 2, 2 and 4 ulp of their results) against glibc's
/// (under 1 ulp), then a few products: 16 ulp at unit scale (2e-6) covers the chain. The
/// samples are O(1) (`randn` at most 5.8 in size), so the unit scale is the right one where a
/// component cancels to nearly zero. On the CPU: 0.
fn transcendental_tol(dev: &wp::Device) -> f32 {
    if dev.is_cpu() {
        0.0
    } else {
        2e-6
    }
}

#[track_caller]
fn close(got: f32, want: f32, tol: f32, what: &str) {
    assert!(
        got.to_bits() == want.to_bits() || (got - want).abs() <= tol * want.abs().max(1.0),
        "{what}: got {got:e}, want {want:e} (tolerance {tol:e} at unit scale)"
    );
}

// ------------------------------------------------------------------------------------------
// Statistics
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_moments(seed: i32, draws: i32, out: Array<f64, 2>) {
    let i = tid();
    let mut s = rand_init(seed, i as i32);
    let mut su: f64 = 0.0;
    let mut suu: f64 = 0.0;
    let mut sn: f64 = 0.0;
    let mut snn: f64 = 0.0;
    for _k in 0..draws {
        let u = randf(&mut s) as f64;
        let n = randn(&mut s) as f64;
        su += u;
        suu += u * u;
        sn += n;
        snn += n * n;
    }
    out[(i, 0)] = su;
    out[(i, 1)] = suu;
    out[(i, 2)] = sn;
    out[(i, 3)] = snn;
}

fn uniform_and_normal_statistics(dev: &wp::Device) {
    let (threads, draws) = (1usize << 16, 16);
    let n = (threads * draws) as f64;
    let out = zeros::<f64, 2>((threads, 4), dev);
    wp::launch(k_moments, threads, (2024, draws as i32, &out), dev).unwrap();
    let h = host(&out);
    let sum = |c: usize| (0..threads).map(|t| h[t * 4 + c]).sum::<f64>();
    let (mu, mn) = (sum(0) / n, sum(2) / n);
    let (vu, vn) = (sum(1) / n - mu * mu, sum(3) / n - mn * mn);
    // Uniform [0, 1): mean 1/2, variance 1/12; the sample variance's own variance is
    // (μ4 - σ⁴)/n with μ4 = 1/80.
    assert!(
        (mu - 0.5).abs() < 5.0 * (1.0 / 12.0 / n).sqrt(),
        "randf mean {mu}"
    );
    let sd_var_u = ((1.0 / 80.0 - 1.0 / 144.0) / n).sqrt();
    assert!(
        (vu - 1.0 / 12.0).abs() < 5.0 * sd_var_u,
        "randf variance {vu}"
    );
    // Standard normal: mean 0, variance 1 (the sample variance's variance is 2/n).
    assert!(mn.abs() < 5.0 / n.sqrt(), "randn mean {mn}");
    assert!(
        (vn - 1.0).abs() < 5.0 * (2.0 / n).sqrt(),
        "randn variance {vn}"
    );
}

#[wp::kernel]
fn k_ints(seed: i32, ints: Array<i32, 2>, uints: Array<u32, 2>, floats: Array<f32>) {
    let i = tid();
    let mut s = rand_init(seed, i as i32);
    ints[(i, 0)] = randi(&mut s);
    ints[(i, 1)] = randi(&mut s, -5, 7);
    ints[(i, 2)] = randi(&mut s, i32::MIN, i32::MAX);
    uints[(i, 0)] = randu(&mut s);
    uints[(i, 1)] = randu(&mut s, 10, 20);
    floats[i] = randf(&mut s, -2.0, 3.0);
}

/// `k` buckets of `n` draws: each count within 5 binomial standard deviations.
#[track_caller]
fn assert_uniform_counts(counts: &[usize], n: usize, what: &str) {
    let p = 1.0 / counts.len() as f64;
    let (mean, sd) = (n as f64 * p, (n as f64 * p * (1.0 - p)).sqrt());
    for (k, c) in counts.iter().enumerate() {
        assert!(
            (*c as f64 - mean).abs() < 5.0 * sd,
            "{what}: bucket {k} has {c}, expected {mean} ± {sd}"
        );
    }
}

fn integer_draws_and_ranges(dev: &wp::Device) {
    let n = 1usize << 14;
    let ints = zeros::<i32, 2>((n, 3), dev);
    let uints = zeros::<u32, 2>((n, 2), dev);
    let floats = zeros::<f32, 1>(n, dev);
    wp::launch(k_ints, n, (7, &ints, &uints, &floats), dev).unwrap();
    let (ih, uh, fh) = (host(&ints), host(&uints), host(&floats));
    let mut range = vec![0usize; 12];
    let mut sign = vec![0usize; 2];
    let mut urange = vec![0usize; 10];
    let mut frange = vec![0usize; 5];
    for t in 0..n {
        let r = ih[t * 3 + 1];
        assert!((-5..7).contains(&r), "randi(-5, 7) gave {r}");
        range[(r + 5) as usize] += 1;
        sign[(ih[t * 3] < 0) as usize] += 1;
        // hi - lo wraps to u32::MAX: any i32 but i32::MAX.
        assert_ne!(ih[t * 3 + 2], i32::MAX);
        let u = uh[t * 2 + 1];
        assert!((10..20).contains(&u), "randu(10, 20) gave {u}");
        urange[(u - 10) as usize] += 1;
        let f = fh[t];
        assert!((-2.0..3.0).contains(&f), "randf(-2, 3) gave {f}");
        frange[((f + 2.0).floor() as usize).min(4)] += 1;
    }
    assert_uniform_counts(&range, n, "randi(-5, 7)");
    assert_uniform_counts(&sign, n, "sign of randi()");
    assert_uniform_counts(&urange, n, "randu(10, 20)");
    assert_uniform_counts(&frange, n, "randf(-2, 3)");
}

#[wp::kernel]
fn k_samplers(seed: i32, v2: Array<Vec2, 2>, v3: Array<Vec3, 2>) {
    let i = tid();
    let mut s = rand_init(seed, i as i32);
    v2[(i, 0)] = sample_triangle(&mut s);
    v2[(i, 1)] = sample_unit_ring(&mut s);
    v2[(i, 2)] = sample_unit_disk(&mut s);
    v2[(i, 3)] = sample_unit_square(&mut s);
    v3[(i, 0)] = sample_unit_cube(&mut s);
    v3[(i, 1)] = sample_unit_sphere_surface(&mut s);
    v3[(i, 2)] = sample_unit_sphere(&mut s);
    v3[(i, 3)] = sample_unit_hemisphere_surface(&mut s);
    v3[(i, 4)] = sample_unit_hemisphere(&mut s);
}

fn samplers_stay_in_their_domains(dev: &wp::Device) {
    let n = 1usize << 14;
    let v2 = zeros::<Vec2, 2>((n, 4), dev);
    let v3 = zeros::<Vec3, 2>((n, 5), dev);
    wp::launch(k_samplers, n, (99, &v2, &v3), dev).unwrap();
    let (a, b) = (host(&v2), host(&v3));
    // f32 lengths of unit vectors: a few roundings of cos/sin products and the sum of
    // squares, well inside 1e-6 (8 ulp at 1).
    let unit = 1e-6;
    let half = |x: f32| (-0.5..0.5).contains(&x);
    let mut mean_sphere = Vec3::ZERO;
    let mut inner = 0usize;
    for t in 0..n {
        let tri = a[t * 4];
        assert!(
            tri.x >= 0.0 && tri.y >= 0.0 && tri.x + tri.y <= 1.0,
            "triangle {tri}"
        );
        assert!(
            (a[t * 4 + 1].length() - 1.0).abs() < unit,
            "ring {}",
            a[t * 4 + 1]
        );
        assert!(a[t * 4 + 2].length() <= 1.0 + unit, "disk {}", a[t * 4 + 2]);
        let sq = a[t * 4 + 3];
        assert!(half(sq.x) && half(sq.y), "square {sq}");
        let c = b[t * 5];
        assert!(half(c.x) && half(c.y) && half(c.z), "cube {c}");
        let surf = b[t * 5 + 1];
        assert!((surf.length() - 1.0).abs() < unit, "sphere surface {surf}");
        mean_sphere += surf;
        let ball = b[t * 5 + 2];
        assert!(ball.length() <= 1.0 + unit, "sphere {ball}");
        // Uniform in the ball: P(|p| < 1/2) = 1/8.
        inner += (ball.length() < 0.5) as usize;
        let hs = b[t * 5 + 3];
        assert!(
            (hs.length() - 1.0).abs() < unit && hs.z >= 0.0,
            "hemisphere surface {hs}"
        );
        let hb = b[t * 5 + 4];
        assert!(hb.length() <= 1.0 + unit && hb.z >= 0.0, "hemisphere {hb}");
    }
    // The surface samples average to the centre: each component has variance 1/3.
    let m = mean_sphere / n as f32;
    let bound = 5.0 * (1.0 / 3.0 / n as f32).sqrt();
    assert!(m.abs().max_element() < bound, "sphere surface mean {m}");
    let (p, nf) = (1.0 / 8.0, n as f64);
    let dev_inner = (inner as f64 - nf * p).abs();
    assert!(
        dev_inner < 5.0 * (nf * p * (1.0 - p)).sqrt(),
        "{inner} of {n} ball samples within radius 1/2"
    );
}

// ------------------------------------------------------------------------------------------
// Sequences
// ------------------------------------------------------------------------------------------

/// Every draw in turn, the state before `poisson`, then the Poisson counts.
#[wp::kernel]
fn k_sequence(seed: i32, f: Array<f32, 2>, u: Array<u32, 2>) {
    let i = tid();
    let mut s = rand_init(seed, i as i32);
    u[(i, 0)] = rand_init(seed + i as i32);
    u[(i, 1)] = s;
    f[(i, 0)] = randf(&mut s);
    f[(i, 1)] = randf(&mut s, -2.0, 3.0);
    let t = sample_triangle(&mut s);
    f[(i, 2)] = t.x;
    f[(i, 3)] = t.y;
    let q = sample_unit_square(&mut s);
    f[(i, 4)] = q.x;
    f[(i, 5)] = q.y;
    let c = sample_unit_cube(&mut s);
    f[(i, 6)] = c.x;
    f[(i, 7)] = c.y;
    f[(i, 8)] = c.z;
    u[(i, 2)] = randi(&mut s) as u32;
    u[(i, 3)] = randi(&mut s, -100, 100) as u32;
    u[(i, 4)] = randu(&mut s);
    u[(i, 5)] = randu(&mut s, 3, 1000);
    // Through the math library from here on.
    f[(i, 9)] = randn(&mut s);
    let r = sample_unit_ring(&mut s);
    f[(i, 10)] = r.x;
    f[(i, 11)] = r.y;
    let d = sample_unit_disk(&mut s);
    f[(i, 12)] = d.x;
    f[(i, 13)] = d.y;
    let mut col = 14;
    for k in 0..4 {
        let v = if k == 0 {
            sample_unit_sphere_surface(&mut s)
        } else if k == 1 {
            sample_unit_sphere(&mut s)
        } else if k == 2 {
            sample_unit_hemisphere_surface(&mut s)
        } else {
            sample_unit_hemisphere(&mut s)
        };
        f[(i, col)] = v.x;
        f[(i, col + 1)] = v.y;
        f[(i, col + 2)] = v.z;
        col += 3;
    }
    u[(i, 6)] = s;
    u[(i, 7)] = poisson(&mut s, 3.5);
    u[(i, 8)] = poisson(&mut s, 25.0);
    u[(i, 9)] = s;
}

/// The host reference of `k_sequence`: `(floats, uints)` of one thread.
fn sequence_ref(seed: i32, i: i32) -> (Vec<f32>, Vec<u32>) {
    let mut s = core::rand_init_offset(seed, i);
    let mut f = Vec::new();
    let mut u = vec![core::rand_init(seed + i), s];
    let step = |s: &mut u32, k: u32| {
        for _ in 0..k {
            *s = core::rand_pcg(*s);
        }
    };
    f.push(core::randf(s));
    step(&mut s, 1);
    f.push(core::randf_range(s, -2.0, 3.0));
    step(&mut s, 1);
    f.extend(core::sample_triangle(s).to_array());
    step(&mut s, 2);
    f.extend(core::sample_unit_square(s).to_array());
    step(&mut s, 2);
    f.extend(core::sample_unit_cube(s).to_array());
    step(&mut s, 3);
    step(&mut s, 1);
    u.push(s); // randi() is the new state's bits
    step(&mut s, 1);
    u.push((s % 200).wrapping_add(-100i32 as u32));
    step(&mut s, 1);
    u.push(s);
    step(&mut s, 1);
    u.push(s % 997 + 3);
    f.push(core::randn(s));
    step(&mut s, 2);
    f.extend(core::sample_unit_ring(s).to_array());
    step(&mut s, 1);
    f.extend(core::sample_unit_disk(s).to_array());
    step(&mut s, 2);
    f.extend(core::sample_unit_sphere_surface(s).to_array());
    step(&mut s, 2);
    f.extend(core::sample_unit_sphere(s).to_array());
    step(&mut s, 3);
    f.extend(core::sample_unit_hemisphere_surface(s).to_array());
    step(&mut s, 2);
    f.extend(core::sample_unit_hemisphere(s).to_array());
    step(&mut s, 3);
    u.push(s);
    u.push(core::poisson(s, 3.5));
    s = core::poisson_state(s, 3.5);
    u.push(core::poisson(s, 25.0));
    s = core::poisson_state(s, 25.0);
    u.push(s);
    (f, u)
}

fn sequences_match_the_reference(dev: &wp::Device) {
    let n = 4096;
    let f = zeros::<f32, 2>((n, 26), dev);
    let u = zeros::<u32, 2>((n, 10), dev);
    wp::launch(k_sequence, n, (31337, &f, &u), dev).unwrap();
    let (fh, uh) = (host(&f), host(&u));
    let tol = transcendental_tol(dev);
    let mut poisson_mismatch = 0;
    for t in 0..n {
        let (fw, uw) = sequence_ref(31337, t as i32);
        let (fg, ug) = (&fh[t * 26..t * 26 + 26], &uh[t * 10..t * 10 + 10]);
        // Exact: the integer draws and states, the uniform floats and their sqrt samplers.
        assert_eq!(&ug[..7], &uw[..7], "thread {t}: states and integer draws");
        for k in 0..9 {
            assert_eq!(fg[k].to_bits(), fw[k].to_bits(), "thread {t}, float {k}");
        }
        for k in 9..26 {
            close(fg[k], fw[k], tol, &format!("thread {t}, float {k}"));
        }
        if ug[7..] != uw[7..] {
            poisson_mismatch += 1;
        }
    }
    if dev.is_cpu() {
        assert_eq!(poisson_mismatch, 0);
    } else {
        assert!(
            poisson_mismatch * 100 <= n,
            "{poisson_mismatch} Poisson draws differ"
        );
    }
}

#[wp::kernel]
fn k_first(seed: i32, out: Array<u32>) {
    let i = tid();
    let mut s = rand_init(seed, i as i32);
    out[i] = randu(&mut s);
}

fn streams_differ_by_offset(dev: &wp::Device) {
    let n = 1usize << 16;
    let a = zeros::<u32, 1>(n, dev);
    let b = zeros::<u32, 1>(n, dev);
    let c = zeros::<u32, 1>(n, dev);
    wp::launch(k_first, n, (5, &a), dev).unwrap();
    wp::launch(k_first, n, (6, &b), dev).unwrap();
    wp::launch(k_first, n, (5, &c), dev).unwrap();
    let (a, b, c) = (host(&a), host(&b), host(&c));
    assert_eq!(a, c, "one seed, one sequence");
    // 2^16 draws of 32 bits: about 0.5 collisions are expected; 8 would be a broken hash.
    let mut sorted = a.clone();
    sorted.sort_unstable();
    sorted.dedup();
    assert!(
        sorted.len() + 8 >= n,
        "only {} distinct first draws",
        sorted.len()
    );
    let same = a.iter().zip(&b).filter(|(x, y)| x == y).count();
    assert!(same < 8, "seeds 5 and 6 agree on {same} threads");
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Walker {
    state: u32,
    pos: f32,
}

#[wp::kernel]
fn k_places(states: Array<u32>, walkers: Array<Walker>, out: Array<f32>) {
    let i = tid();
    // An array element and a struct field as the state, loaded and stored once per draw.
    out[i] = randf(&mut states[i]) + randf(&mut states[i]) * 2.0;
    let mut w = walkers[i];
    for _k in 0..3 {
        w.pos += randf(&mut w.state, -1.0, 1.0);
    }
    walkers[i] = w;
}

fn state_in_arrays_and_struct_fields(dev: &wp::Device) {
    let n = 64;
    let s0: Vec<u32> = (0..n).map(|i| core::rand_init(i as i32 * 3)).collect();
    let states = arr(&s0, dev);
    let w0: Vec<Walker> = s0
        .iter()
        .map(|s| Walker {
            state: !s,
            pos: 0.5,
        })
        .collect();
    let walkers = arr(&w0, dev);
    let out = zeros::<f32, 1>(n, dev);
    wp::launch(k_places, n, (&states, &walkers, &out), dev).unwrap();
    let (sh, wh, oh) = (host(&states), host(&walkers), host(&out));
    for i in 0..n {
        let s = s0[i];
        let s1 = core::rand_pcg(s);
        assert_eq!(oh[i], core::randf(s) + core::randf(s1) * 2.0, "thread {i}");
        assert_eq!(sh[i], core::rand_pcg(s1));
        let mut w = w0[i];
        for _ in 0..3 {
            w.pos += core::randf_range(w.state, -1.0, 1.0);
            w.state = core::rand_pcg(w.state);
        }
        assert_eq!(wh[i], w, "thread {i}");
    }
}

#[wp::kernel]
fn k_empty_range(lo: i32, out: Array<i32>) {
    let i = tid();
    let mut s = rand_init(1, i as i32);
    out[i] = randi(&mut s, lo, lo);
}

fn empty_range_faults(dev: &wp::Device) {
    let out = zeros::<i32, 1>(4, dev);
    let r = wp::launch(k_empty_range, 4, (3, &out), dev);
    assert!(
        matches!(&r, Err(wp::Error::Fault(f)) if f.kind == wp::FaultKind::DivisionByZero),
        "{r:?}"
    );
}

#[wp::kernel]
fn k_poisson(lam: f32, draws: i32, out: Array<f64, 2>) {
    let i = tid();
    let mut s = rand_init(77, i as i32);
    let mut sum: f64 = 0.0;
    let mut sq: f64 = 0.0;
    for _k in 0..draws {
        let x = poisson(&mut s, lam) as f64;
        sum += x;
        sq += x * x;
    }
    out[(i, 0)] = sum;
    out[(i, 1)] = sq;
}

fn poisson_statistics(dev: &wp::Device) {
    let (threads, draws) = (1usize << 12, 32);
    let n = (threads * draws) as f64;
    for lam in [0.0f32, 0.7, 4.0, 9.9, 10.0, 60.0] {
        let out = zeros::<f64, 2>((threads, 2), dev);
        wp::launch(k_poisson, threads, (lam, draws as i32, &out), dev).unwrap();
        let h = host(&out);
        let mean = (0..threads).map(|t| h[t * 2]).sum::<f64>() / n;
        let var = (0..threads).map(|t| h[t * 2 + 1]).sum::<f64>() / n - mean * mean;
        let l = lam as f64;
        if lam == 0.0 {
            assert_eq!((mean, var), (0.0, 0.0));
            continue;
        }
        // Mean and variance are both lam; the sample variance's variance is about
        // (μ4 - σ⁴)/n = (lam + 2 lam²)/n.
        assert!(
            (mean - l).abs() < 5.0 * (l / n).sqrt(),
            "lam {lam}: mean {mean}"
        );
        assert!(
            (var - l).abs() < 5.0 * ((l + 2.0 * l * l) / n).sqrt(),
            "lam {lam}: variance {var}"
        );
    }
}

// ------------------------------------------------------------------------------------------
// Perlin noise
// ------------------------------------------------------------------------------------------

#[wp::kernel]
fn k_noise(seed: u32, p: Array<Vec4>, out: Array<f32, 2>) {
    let i = tid();
    let x = p[i];
    out[(i, 0)] = noise(seed, x.x);
    out[(i, 1)] = noise(seed, vec2(x.x, x.y));
    out[(i, 2)] = noise(seed, vec3(x.x, x.y, x.z));
    out[(i, 3)] = noise(seed, x);
    out[(i, 4)] = pnoise(seed, x.x, 3);
    out[(i, 5)] = pnoise(seed, vec2(x.x, x.y), 3, 5);
    out[(i, 6)] = pnoise(seed, vec3(x.x, x.y, x.z), 3, 5, 2);
    out[(i, 7)] = pnoise(seed, x, 3, 5, 2, 4);
}

fn noise_at(seed: u32, pts: &[Vec4], dev: &wp::Device) -> Vec<[f32; 8]> {
    let p = arr(pts, dev);
    let out = zeros::<f32, 2>((pts.len(), 8), dev);
    wp::launch(k_noise, pts.len(), (seed, &p, &out), dev).unwrap();
    host(&out)
        .chunks(8)
        .map(|c| c.try_into().expect("8 lanes"))
        .collect()
}

fn noise_properties(dev: &wp::Device) {
    let seed = core::rand_init(42);
    // Zero on the integer lattice, every dimension, plain and periodic.
    let lattice: Vec<Vec4> = (0..64)
        .map(|k| Vec4::new((k % 7) as f32 - 3.0, (k % 5) as f32, (k / 8) as f32, -1.0))
        .collect();
    for (k, row) in noise_at(seed, &lattice, dev).iter().enumerate() {
        assert!(row.iter().all(|v| *v == 0.0), "lattice point {k}: {row:?}");
    }
    // Continuity across cell faces (the quintic blend makes the noise C¹: a step of h moves
    // it by at most about |∇n| h; a wrong corner would jump by O(0.1)), and the amplitude
    // bound sqrt(N)/2 of gradient noise with unit gradients.
    let h = 1e-3f32;
    let mut pts = Vec::new();
    for k in 0..200 {
        let face = (k % 9) as f32 - 4.0;
        let c = Vec4::new(face, 0.37 * k as f32, -0.11 * k as f32, 0.05 * k as f32);
        let axis = Vec4::AXES[k % 4];
        let base = c * (Vec4::ONE - axis) + axis * face;
        pts.push(base - axis * (h / 2.0));
        pts.push(base + axis * (h / 2.0));
    }
    let vals = noise_at(seed, &pts, dev);
    for k in 0..200 {
        for (lane, (&a, &b)) in vals[2 * k].iter().zip(&vals[2 * k + 1]).enumerate() {
            assert!(
                (a - b).abs() < 10.0 * h,
                "point {k}, lane {lane}: {a} vs {b}"
            );
            let dim = (lane % 4 + 1) as f32;
            assert!(a.abs() <= dim.sqrt() / 2.0 + 1e-6, "lane {lane}: {a}");
        }
    }
    // Periods (3, 5, 2, 4): shifting by whole periods, on either side of zero, changes
    // nothing (the shifts are exact in f32).
    let base: Vec<Vec4> = (0..100)
        .map(|k| {
            Vec4::new(
                0.125 * k as f32 - 6.0,
                0.25 * k as f32,
                -0.375 * k as f32,
                0.5,
            )
        })
        .collect();
    let shifted: Vec<Vec4> = base
        .iter()
        .map(|p| *p + Vec4::new(-6.0, 10.0, 4.0, -8.0))
        .collect();
    let (a, b) = (noise_at(seed, &base, dev), noise_at(seed, &shifted, dev));
    for k in 0..100 {
        assert_eq!(a[k][4..], b[k][4..], "point {k}");
        // ... and the plain noise is not periodic.
    }
    assert!((0..100).any(|k| a[k][..4] != b[k][..4]));
    // Different states are different fields (except at the 13 of these points that are
    // lattice points in 3-D, where both are 0).
    let other = noise_at(seed ^ 1, &base, dev);
    assert_eq!((0..100).filter(|k| other[*k][2] != a[*k][2]).count(), 87);
}

fn noise_matches_the_reference(dev: &wp::Device) {
    let seed = core::rand_init_offset(3, 9);
    let pts: Vec<Vec4> = (0..500)
        .map(|k| {
            let t = k as f32;
            Vec4::new(
                t * 0.173 - 40.0,
                (t * 0.71).sin() * 9.0,
                t * -0.031,
                1e4 - t * 13.7,
            )
        })
        .collect();
    let got = noise_at(seed, &pts, dev);
    for (k, p) in pts.iter().enumerate() {
        let want = [
            core::noise(seed, p.x),
            core::noise(seed, p.truncate().truncate()),
            core::noise(seed, p.truncate()),
            core::noise(seed, *p),
            core::pnoise(seed, p.x, 3),
            core::pnoise(seed, p.truncate().truncate(), IVec2::new(3, 5)),
            core::pnoise(seed, p.truncate(), IVec3::new(3, 5, 2)),
            core::pnoise(seed, *p, IVec4::new(3, 5, 2, 4)),
        ];
        // Bit for bit on every backend (see the module documentation).
        for (lane, (g, w)) in got[k].iter().zip(want).enumerate() {
            assert_eq!(
                g.to_bits(),
                w.to_bits(),
                "point {k} {p}, lane {lane}: {g} vs {w}"
            );
        }
    }
}

//! `#[func]`s: funcs calling funcs, funcs in other modules (by path and through `use`), funcs
//! taking arrays, returning vectors, returning early, and writing through an array.

use crate::{arr, assert_close_slice, fma_rel, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    func_calls_func,
    func_in_other_module,
    func_with_array_argument,
    func_returning_vector,
    func_with_early_return,
    func_literal_arguments,
    func_writing_array,
    func_mutable_and_bool,
    literals_next_to_untyped_values,
    literal_lets_typed_by_their_uses,
);

#[wp::func]
fn sq(x: f32) -> f32 {
    x * x
}

#[wp::func]
fn sum_sq(a: f32, b: f32) -> f32 {
    sq(a) + sq(b)
}

#[wp::func]
fn poly(x: f32) -> f32 {
    let s = sum_sq(x, 1.0);
    s * 2.0 + sq(s)
}

#[wp::kernel]
fn k_calls(a: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let x = a[i];
    out[(i, 0)] = sq(x);
    out[(i, 1)] = sum_sq(x, 2.0);
    out[(i, 2)] = poly(x);
    out[(i, 3)] = sq(sq(x)) + 1.0;
}

fn func_calls_func(dev: &wp::Device) {
    let a = [1.0f32, 2.0, 3.0, -0.5];
    let out = zeros::<f32, 2>((4, 4), dev);
    wp::launch(k_calls, 4, (&arr(&a, dev), &out), dev).unwrap();
    let want: Vec<f32> = a
        .iter()
        .flat_map(|&x| {
            let s = x * x + 1.0;
            [x * x, x * x + 4.0, s * 2.0 + s * s, (x * x) * (x * x) + 1.0]
        })
        .collect();
    // Sums of products: FMA on CUDA.
    assert_close_slice(&host(&out), &want, fma_rel(dev), "nested func calls");
}

/// Funcs in another module, called by path and through `use`.
mod physics {
    use warp_lang as wp;
    use wp::prelude::*;

    #[wp::func]
    pub fn kinetic(m: f32, v: Vec3) -> f32 {
        0.5 * m * dot(v, v)
    }

    pub mod units {
        use warp_lang as wp;

        #[wp::func]
        pub fn to_cm(x: f32) -> f32 {
            x * 100.0
        }
    }

    #[wp::func]
    pub fn kinetic_cm(m: f32, v: Vec3) -> f32 {
        units::to_cm(units::to_cm(kinetic(m, v)))
    }
}

use physics::units::to_cm;

#[wp::kernel]
fn k_modules(m: Array<f32>, v: Array<Vec3>, out: Array<f32, 2>) {
    let i = tid();
    out[(i, 0)] = physics::kinetic(m[i], v[i]);
    out[(i, 1)] = to_cm(m[i]);
    out[(i, 2)] = physics::kinetic_cm(m[i], v[i]);
    out[(i, 3)] = physics::units::to_cm(1.5);
}

fn func_in_other_module(dev: &wp::Device) {
    let m = [2.0f32, 0.5];
    let v = [vec3(1.0, 2.0, 3.0), vec3(-0.5, 0.25, 4.0)];
    let out = zeros::<f32, 2>((2, 4), dev);
    wp::launch(k_modules, 2, (&arr(&m, dev), &arr(&v, dev), &out), dev).unwrap();
    let want: Vec<f32> = (0..2)
        .flat_map(|i| {
            let k = 0.5 * m[i] * (v[i].x * v[i].x + v[i].y * v[i].y + v[i].z * v[i].z);
            [k, m[i] * 100.0, k * 100.0 * 100.0, 150.0]
        })
        .collect();
    assert_close_slice(&host(&out), &want, fma_rel(dev), "funcs in modules");
}

/// A func reading an array argument (and its length).
#[wp::func]
fn window_sum(a: Array<f32>, center: usize, radius: usize) -> f32 {
    let mut s: f32 = 0.0;
    let lo = if center >= radius { center - radius } else { 0 };
    // `min(center + radius + 1, a.len())` does not compile (no usize builtins): see the report.
    let end = center + radius + 1;
    let hi = if end < a.len() { end } else { a.len() };
    for j in lo..hi {
        s += a[j];
    }
    s
}

#[wp::func]
fn grid_at(g: Array<i32, 2>, i: usize, j: usize) -> i32 {
    g[(i, j)] * 10
}

#[wp::kernel]
fn k_window(a: Array<f32>, g: Array<i32, 2>, radius: usize, out: Array<f32>, gout: Array<i32>) {
    let i = tid();
    out[i] = window_sum(a, i, radius);
    gout[i] = grid_at(g, i % 2, i % 3);
}

fn func_with_array_argument(dev: &wp::Device) {
    let a: Vec<f32> = (0..9).map(|k| k as f32 * 0.5).collect();
    let g: Vec<i32> = (0..6).collect();
    let (out, gout) = (zeros::<f32, 1>(9, dev), zeros::<i32, 1>(9, dev));
    wp::launch(
        k_window,
        9,
        (
            &arr(&a, dev),
            &wp::Array::from_slice_shape(&g, (2, 3), dev).unwrap(),
            2,
            &out,
            &gout,
        ),
        dev,
    )
    .unwrap();
    let want: Vec<f32> = (0..9usize)
        .map(|c| {
            let mut s = 0.0;
            for x in &a[c.saturating_sub(2)..(c + 3).min(9)] {
                s += x;
            }
            s
        })
        .collect();
    assert_eq!(host(&out), want, "half-integer sums are exact");
    assert_eq!(
        host(&gout),
        (0..9)
            .map(|i| g[(i % 2) * 3 + i % 3] * 10)
            .collect::<Vec<_>>()
    );
}

#[wp::func]
fn reflect(v: Vec3, n: Vec3) -> Vec3 {
    v - n * (2.0 * dot(v, n))
}

#[wp::func]
fn orbit(t: f32) -> Vec2 {
    vec2(cos(t), sin(t)) * 2.0
}

#[wp::kernel]
fn k_vectors(v: Array<Vec3>, n: Vec3, out: Array<Vec3>, t: Array<f32>, o2: Array<Vec2>) {
    let i = tid();
    out[i] = reflect(v[i], n);
    o2[i] = orbit(t[i]);
    let r = reflect(v[i], n);
    out[i] += r * 0.0;
}

fn func_returning_vector(dev: &wp::Device) {
    let v = [vec3(1.0, -1.0, 0.0), vec3(0.3, 0.5, -0.25)];
    let n = vec3(0.0, 1.0, 0.0);
    let t = [0.0f32, 1.0];
    let (out, o2) = (zeros::<Vec3, 1>(2, dev), zeros::<Vec2, 1>(2, dev));
    wp::launch(
        k_vectors,
        2,
        (&arr(&v, dev), n, &out, &arr(&t, dev), &o2),
        dev,
    )
    .unwrap();
    let out = host(&out);
    for i in 0..2 {
        let d = v[i].x * n.x + v[i].y * n.y + v[i].z * n.z;
        let want = v[i] - n * (2.0 * d);
        assert_close_slice(
            &out[i].to_array(),
            &want.to_array(),
            fma_rel(dev),
            "reflect",
        );
        let o = host(&o2)[i];
        assert_close_slice(
            &o.to_array(),
            &[t[i].cos() * 2.0, t[i].sin() * 2.0],
            crate::math_rel(dev),
            "orbit",
        );
    }
}

#[wp::func]
fn safe_div(a: f32, b: f32) -> f32 {
    if b == 0.0 {
        return 0.0;
    }
    a / b
}

#[wp::func]
fn first_multiple(start: i32, k: i32) -> i32 {
    let mut x = start;
    loop {
        if x % k == 0 {
            return x;
        }
        x += 1;
    }
}

#[wp::func]
fn classify(x: i32) -> i32 {
    if x < 0 {
        return -1;
    } else if x == 0 {
        return 0;
    }
    1
}

#[wp::kernel]
fn k_early(a: Array<f32>, b: Array<f32>, out: Array<f32>, m: Array<i32, 2>) {
    let i = tid();
    out[i] = safe_div(a[i], b[i]);
    let s = i as i32 * 5 - 7;
    m[(i, 0)] = first_multiple(s, 4);
    m[(i, 1)] = classify(s);
}

fn func_with_early_return(dev: &wp::Device) {
    let a = [1.0f32, 2.0, 3.0, 4.0];
    let b = [2.0f32, 0.0, -0.5, 0.0];
    let (out, m) = (zeros::<f32, 1>(4, dev), zeros::<i32, 2>((4, 2), dev));
    wp::launch(k_early, 4, (&arr(&a, dev), &arr(&b, dev), &out, &m), dev).unwrap();
    assert_eq!(host(&out), vec![0.5, 0.0, -6.0, 0.0]);
    let want: Vec<i32> = (0..4)
        .flat_map(|i: i32| {
            let s = i * 5 - 7;
            let fm = (s..).find(|x| x % 4 == 0).unwrap();
            [fm, s.signum()]
        })
        .collect();
    assert_eq!(host(&m), want);
}

#[wp::func]
fn scale64(x: f64, s: f64) -> f64 {
    x * s
}

#[wp::func]
fn twice64(x: f64) -> f64 {
    x * 2.0
}

#[wp::func]
fn tenth() -> f64 {
    0.1
}

/// A literal combined with a func's result takes that result's type (f64 here), and a
/// literal returned by a func takes its return type.
///
/// An unsuffixed literal passed as a func argument (`scale64(x, 0.1)`, `twice64(0.1)`) is typed
/// f32/i32 instead of the parameter's type and does not compile: see the report. Suffixed
/// literals are used for the arguments meanwhile.
#[wp::kernel]
fn k_func_literals(x: f64, out: Array<f64>) {
    out[0] = scale64(x, 0.1f64);
    out[1] = twice64(0.1f64);
    out[2] = twice64(x) + 0.1;
    out[3] = tenth() * x;
}

fn func_literal_arguments(dev: &wp::Device) {
    let out = zeros::<f64, 1>(4, dev);
    wp::launch(k_func_literals, 1, (3.0f64, &out), dev).unwrap();
    assert_eq!(host(&out), vec![3.0 * 0.1, 0.1 * 2.0, 6.0 + 0.1, 0.1 * 3.0]);
}

/// A func without a result, writing through the array it is given.
#[wp::func]
fn put(a: Array<i32>, i: usize, v: i32) {
    if i >= a.len() {
        return;
    }
    a[i] = v;
}

#[wp::kernel]
fn k_put(out: Array<i32>) {
    let i = tid();
    put(out, i, i as i32 * 2);
    put(out, i + 100, 7);
}

fn func_writing_array(dev: &wp::Device) {
    let out = zeros::<i32, 1>(6, dev);
    wp::launch(k_put, 6, (&out,), dev).unwrap();
    assert_eq!(host(&out), vec![0, 2, 4, 6, 8, 10]);
}

/// A func with a mutable parameter.
#[wp::func]
fn bump(mut x: i32, by: i32) -> i32 {
    x += by;
    x *= 2;
    x
}

#[wp::func]
fn is_positive(x: f32) -> bool {
    x > 0.0
}

/// Kernels with a mutable parameter, funcs returning bool in conditions, and builtins on func
/// results (whose type the macro cannot see).
#[wp::kernel]
pub(crate) fn k_mut_bool(a: Array<f32>, mut n: i32, out: Array<i32>, f: Array<f32>) {
    let i = tid();
    n += bump(n, i as i32);
    if is_positive(a[i]) && n > 5 {
        out[i] = n;
    } else if !is_positive(a[i]) {
        out[i] = -n;
    }
    f[i] = sq(a[i]).min(1.0);
    f[i] += max(sq(a[i]), 0.5);
}

fn func_mutable_and_bool(dev: &wp::Device) {
    let a = [0.5f32, -2.0, 3.0, 0.0];
    let (out, f) = (zeros::<i32, 1>(4, dev), zeros::<f32, 1>(4, dev));
    wp::launch(k_mut_bool, 4, (&arr(&a, dev), 1, &out, &f), dev).unwrap();
    let want: Vec<i32> = (0..4)
        .map(|i| {
            let n = 1 + (1 + i as i32) * 2;
            if a[i] > 0.0 && n > 5 {
                n
            } else if a[i] <= 0.0 {
                -n
            } else {
                0
            }
        })
        .collect();
    assert_eq!(host(&out), want);
    assert_eq!(
        host(&f),
        a.iter()
            .map(|x| (x * x).min(1.0) + (x * x).max(0.5))
            .collect::<Vec<_>>()
    );
}

// ------------------------------------------------- literals next to values the macro can't type

#[wp::func]
fn count_of(n: usize) -> usize {
    n
}

#[derive(Clone, Copy, wp::Struct)]
#[repr(C)]
pub(crate) struct Span64 {
    scale: f64,
    n: i32,
    _pad: i32,
}

/// A user func's result and a struct field are typed by rustc, not by the macro: a literal
/// beside them must take their type (f64 here, where the default would be f32), also as a
/// func argument, as a range bound and as the other branch of an `if`.
#[wp::kernel]
pub(crate) fn k_untyped(s: Span64, x: f64, c: bool, out: Array<f64>, iv: IVec3, ov: Array<IVec3>) {
    out[0] = twice64(0.1); // literal argument typed by the func's signature (f64)
    out[1] = twice64(x) + 1; // integer literal beside an f64 result
    out[2] = s.scale * 2; // integer literal beside an f64 field
    let mut n = 0;
    for _ in 0..s.n {
        n += 1;
    }
    out[3] = n as f64;
    let y = if c { twice64(x) } else { 0.1 };
    out[4] = y;
    let z = 1.5 + twice64(x);
    out[5] = z;
    out[6] = count_of(3) as f64;
    ov[0] = 2 * iv; // scalar integer times integer vector
}

fn literals_next_to_untyped_values(dev: &wp::Device) {
    let out = zeros::<f64, 1>(7, dev);
    let ov = zeros::<IVec3, 1>(1, dev);
    let s = Span64 {
        scale: 0.3,
        n: 5,
        _pad: 0,
    };
    let x = 0.1f64;
    wp::launch(k_untyped, 1, (s, x, false, &out, ivec3(1, -2, 3), &ov), dev).expect("launch");
    // 0.1 and 0.3 are not f32 values: these only match if every literal was typed f64.
    // f64 results of one or two roundings: on CUDA FMA may change the last bit (fma_rel).
    let want = [
        0.1 * 2.0,
        x * 2.0 + 1.0,
        0.3 * 2.0,
        5.0,
        0.1,
        1.5 + x * 2.0,
        3.0,
    ];
    let got = host(&out);
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        assert!(
            (g - w).abs() <= w.abs() * 1e-15,
            "out[{k}] = {g}, expected {w}"
        );
    }
    assert_eq!(host(&ov), vec![ivec3(2, -4, 6)]);
}

/// `acc` and `best` are f64 and `k` a usize by their uses, as rustc infers them (one pass
/// over the body would have typed them f32 and i32 at their `let`s).
#[wp::func]
fn power64(x: f64, n: i32) -> f64 {
    let mut acc = 1.0;
    for _ in 0..n {
        acc *= x;
    }
    let mut best = 0.0;
    best = best.max(acc);
    best
}

#[wp::kernel]
fn k_literal_lets(x: Array<f64>, out: Array<f64>) {
    let i = tid();
    let mut k = 0;
    k += i;
    let mut sum = 0.0;
    sum += x[k];
    out[i] = power64(sum, 3) + 0.1;
}

fn literal_lets_typed_by_their_uses(dev: &wp::Device) {
    let xs = [0.1f64, -1.3, 2.7];
    let x = wp::Array::from_slice(&xs, dev).expect("upload");
    let out = zeros::<f64, 1>(3, dev);
    wp::launch(k_literal_lets, 3, (&x, &out), dev).expect("launch");
    for (k, (g, x)) in host(&out).iter().zip(xs).enumerate() {
        // x³ + 0.1 in f64, three roundings (FMA on CUDA may differ in the last bits); 0.1 and
        // the inputs are not f32 values, so an f32 `acc` would be off by about 1e-8.
        let want = (x * x * x).max(0.0) + 0.1;
        assert!(
            (g - want).abs() <= 4.0 * f64::EPSILON * want.abs().max(1.0),
            "out[{k}] = {g}, expected {want}"
        );
    }
}

//! Fixed-size local arrays (`[0.0f32; 8]`, `[x, y, z]`, Warp's in-kernel `wp.zeros`): filling
//! and summing, reads and writes at dynamic indices (elements, their members, nested arrays),
//! an insertion sort, funcs taking and returning arrays, a length that names a const, the
//! fault of an index outside the array, and derivatives through them (reverse mode against
//! central differences, through overwrites in loops; forward mode against reverse mode);
//! arrays of spatial vectors and matrices, their elements' lanes read and written.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;
use wp::FaultKind;

backend_tests!(
    fill_and_sum,
    dynamic_reads_and_writes,
    members_and_nested_arrays,
    insertion_sort_of_eight,
    funcs_take_and_return_arrays,
    const_length,
    generic_kernel,
    index_out_of_range_faults,
    gradient_against_finite_differences,
    gradient_through_overwrites_in_loops,
    jvp_matches_the_gradient,
    adjoint_stack_holds_whole_arrays,
    spatial_elements,
);

#[wp::kernel]
fn k_fill_sum(x: Array<f32>, out: Array<f32>) {
    let i = tid();
    let mut a = [0.0f32; 8];
    for j in 0..8 {
        a[j] = x[i] * (j as f32);
    }
    let mut s = 0.0;
    for j in 0..a.len() {
        s += a[j];
    }
    out[i] = s;
}

/// Small integers times small integers: every sum is exact in f32 on both backends.
fn fill_and_sum(dev: &wp::Device) {
    let xs = [1.0f32, -2.0, 0.5, 3.0];
    let out = zeros::<f32, 1>(4, dev);
    wp::launch(k_fill_sum, 4, (&arr(&xs, dev), &out), dev).unwrap();
    let want: Vec<f32> = xs.iter().map(|x| x * 28.0).collect();
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_dynamic(k: Array<i32>, out: Array<i32, 2>) {
    let i = tid();
    let table = [10, 20, 30, 40];
    let mut b = [1i32, 2, 3, 4];
    let j = k[i];
    b[j] += table[3 - j];
    b[(j + 1) % 4] = b[j] * 2;
    let mut flags = [false; 4];
    flags[j as usize] = true;
    for q in 0..4 {
        out[(i, q)] = b[q];
    }
    out[(i, 4)] = if flags[j] { 1 } else { 0 };
}

fn dynamic_reads_and_writes(dev: &wp::Device) {
    let ks = [0i32, 1, 2, 3];
    let out = zeros::<i32, 2>((4, 5), dev);
    wp::launch(k_dynamic, 4, (&arr(&ks, dev), &out), dev).unwrap();
    let mut want = Vec::new();
    for &j in &ks {
        let j = j as usize;
        let mut b = [1, 2, 3, 4];
        b[j] += [10, 20, 30, 40][3 - j];
        b[(j + 1) % 4] = b[j] * 2;
        want.extend(b);
        want.push(1);
    }
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_members(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let mut v = [Vec3::ZERO; 3];
    let mut m: [[f32; 3]; 2] = [[0.0; 3]; 2];
    for j in 0..3 {
        v[j].y = x[i] + j as f32;
        v[j].x += 1.0;
        m[j % 2][j] = x[i] * 2.0;
    }
    m[1][0] += 5.0;
    let row = m[1];
    out[(i, 0)] = v[2].y;
    out[(i, 1)] = v[0].x + v[1].x + v[2].x;
    out[(i, 2)] = m[0][0] + m[0][2];
    out[(i, 3)] = row[0] + row[1];
    out[(i, 4)] = m.len() as f32 + row.len() as f32;
}

fn members_and_nested_arrays(dev: &wp::Device) {
    let xs = [1.0f32, 2.5];
    let out = zeros::<f32, 2>((2, 5), dev);
    wp::launch(k_members, 2, (&arr(&xs, dev), &out), dev).unwrap();
    let want: Vec<f32> = xs
        .iter()
        .flat_map(|&x| [x + 2.0, 3.0, x * 4.0, 5.0 + x * 2.0, 5.0])
        .collect();
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_sort(x: Array<f32, 2>, out: Array<f32, 2>) {
    let i = tid();
    let mut a = [0.0f32; 8];
    for j in 0..8 {
        a[j] = x[(i, j)];
    }
    for j in 1..8 {
        let key = a[j];
        let mut p = j;
        while p > 0 && a[p - 1] > key {
            a[p] = a[p - 1];
            p -= 1;
        }
        a[p] = key;
    }
    for j in 0..8 {
        out[(i, j)] = a[j];
    }
}

fn insertion_sort_of_eight(dev: &wp::Device) {
    let rows: [[f32; 8]; 3] = [
        [5.0, -1.0, 3.5, 0.0, 9.0, 2.0, 2.0, -7.5],
        [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0],
        [8.0, 7.0, 6.0, 5.0, 4.0, 3.0, 2.0, 1.0],
    ];
    let flat: Vec<f32> = rows.iter().flatten().copied().collect();
    let x = wp::Array::from_slice_shape(&flat, (3, 8), dev).unwrap();
    let out = zeros::<f32, 2>((3, 8), dev);
    wp::launch(k_sort, 3, (&x, &out), dev).unwrap();
    let mut want = Vec::new();
    for r in rows {
        let mut r = r.to_vec();
        r.sort_by(f32::total_cmp);
        want.extend(r);
    }
    assert_eq!(host(&out), want);
}

#[wp::func]
fn reversed(a: [f32; 4]) -> [f32; 4] {
    let mut r = a;
    for j in 0..4 {
        r[j] = a[3 - j];
    }
    r
}

#[wp::func]
fn centroid(p: [Vec3; 3]) -> Vec3 {
    (p[0] + p[1] + p[2]) / 3.0
}

#[wp::kernel]
fn k_funcs(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = [x[i], 2.0, 3.0, 4.0];
    let r: [f32; 4] = reversed(a);
    let p = [Vec3::new(x[i], 0.0, 0.0), Vec3::Y * 3.0, Vec3::Z * 6.0];
    let c = centroid(p);
    for j in 0..4 {
        out[(i, j)] = r[j];
    }
    out[(i, 4)] = c.x + c.y + c.z;
}

fn funcs_take_and_return_arrays(dev: &wp::Device) {
    let xs = [3.0f32, -6.0];
    let out = zeros::<f32, 2>((2, 5), dev);
    wp::launch(k_funcs, 2, (&arr(&xs, dev), &out), dev).unwrap();
    // Thirds of multiples of 3 and sums of small integers: exact.
    let want: Vec<f32> = xs
        .iter()
        .flat_map(|&x| [4.0, 3.0, 2.0, x, x / 3.0 + 1.0 + 2.0])
        .collect();
    assert_eq!(host(&out), want);
}

const LEN: usize = 6;

#[wp::kernel]
fn k_const_len(out: Array<u32>) {
    let i = tid();
    let mut a = [0u32; LEN];
    for j in 0..a.len() {
        a[j] = (i as u32) * 10 + j as u32;
    }
    out[i] = a[LEN - 1] + a.len() as u32;
}

fn const_length(dev: &wp::Device) {
    let out = zeros::<u32, 1>(3, dev);
    wp::launch(k_const_len, 3, (&out,), dev).unwrap();
    assert_eq!(host(&out), vec![5 + 6, 15 + 6, 25 + 6]);
}

#[wp::kernel]
fn k_generic<T: Float>(x: Array<T>, out: Array<T>) {
    let i = tid();
    let mut a = [x[i]; 3];
    a[1] = a[0] * 2.0;
    let b: [T; 2] = [a[1], a[2]];
    out[i] = a[0] + b[0] * b[1];
}

/// One generic kernel, both instances: `[x; 3]` and `[T; 2]` take the instance's float.
fn generic_kernel(dev: &wp::Device) {
    let out = zeros::<f32, 1>(2, dev);
    wp::launch(k_generic, 2, (&arr(&[1.0f32, 3.0], dev), &out), dev).unwrap();
    assert_eq!(host(&out), vec![1.0 + 2.0, 3.0 + 18.0]);
    let out = zeros::<f64, 1>(2, dev);
    wp::launch(k_generic, 2, (&arr(&[0.5f64, -2.0], dev), &out), dev).unwrap();
    assert_eq!(host(&out), vec![0.5 + 0.5, -2.0 + 8.0]);
}

#[wp::kernel]
fn k_oob(k: Array<i32>, out: Array<f32>) {
    let i = tid();
    let a = [1.0f32, 2.0, 3.0, 4.0];
    out[i] = a[k[i]];
}

fn index_out_of_range_faults(dev: &wp::Device) {
    let out = zeros::<f32, 1>(3, dev);
    let k = arr(&[0i32, 4, 1], dev);
    // The suite runs CUDA in debug mode: the launch reports the fault, as the CPU's does.
    let err = wp::launch(k_oob, 3, (&k, &out), dev).unwrap_err();
    let wp::Error::Fault(f) = &err else {
        panic!("not a fault: {err}");
    };
    assert_eq!(f.kernel, "k_oob");
    // The line of `k_oob`'s read of `a`.
    let src = include_str!("local_arrays.rs");
    let line = 1 + src
        .lines()
        .position(|l| l.trim() == "out[i] = a[k[i]];")
        .unwrap() as u32;
    assert_eq!(
        f.kind,
        FaultKind::LocalIndex {
            index: 4,
            len: 4,
            line
        }
    );
    let msg = err.to_string();
    assert!(
        msg.contains(
            "kernel `k_oob`: index 4 is out of bounds for a local array or vector of length 4"
        ),
        "{msg}"
    );
}

// ---- derivatives ----

#[wp::func]
fn weighted(a: [f64; 4], w: f64) -> f64 {
    let mut s = 0.0f64;
    for j in 0..4 {
        s += a[j] * (w + j as f64);
    }
    s
}

#[wp::func]
fn scaled(a: [f64; 4], s: f64) -> [f64; 4] {
    let mut r = a;
    for j in 0..4 {
        r[j] *= s;
    }
    r
}

/// Literals, repeats, element reads and writes, and funcs that take and return arrays.
#[wp::kernel]
fn k_smooth(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let t = x[i];
    let lit = [t, t * t, 1.0, t.sin()];
    let mut a = [t; 4];
    a[1] = lit[1] * lit[3];
    a[2] += lit[0] * 3.0;
    let b: [f64; 4] = scaled(a, t);
    y[i] = weighted(b, t) + b[3] * a[0];
}

/// The closed form of `k_smooth`, for the values themselves.
fn smooth(t: f64) -> f64 {
    let lit = [t, t * t, 1.0, t.sin()];
    let mut a = [t; 4];
    a[1] = lit[1] * lit[3];
    a[2] += lit[0] * 3.0;
    let b = a.map(|v| v * t);
    let w: f64 = (0..4).map(|j| b[j] * (t + j as f64)).sum();
    w + b[3] * a[0]
}

/// Central differences of `f` at `t`: the truncation error is O(h^2 f''') ~ 1e-12 for these
/// smooth functions of values near 1 with h = 1e-6, and the rounding error O(eps f / h) ~ 1e-10;
/// a relative tolerance of 1e-7 leaves a margin of 1000 over both, while a wrong adjoint (a
/// missing or doubled term) is off by O(1).
fn assert_matches_fd(f: impl Fn(f64) -> f64, xs: &[f64], grads: &[f64], what: &str) {
    let h = 1e-6;
    for (&t, &g) in xs.iter().zip(grads) {
        let fd = (f(t + h) - f(t - h)) / (2.0 * h);
        assert!(
            (g - fd).abs() <= 1e-7 * fd.abs().max(1.0),
            "{what} at {t}: adjoint {g}, central difference {fd}"
        );
    }
}

fn gradient_against_finite_differences(dev: &wp::Device) {
    let xs = [0.3f64, -0.8, 1.1];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_smooth, 3, (&x, &y), dev).unwrap();
    }
    let ys = host(&y);
    for (t, v) in xs.iter().zip(&ys) {
        // The same f64 operations on the CPU; FMA contraction on CUDA.
        assert!((v - smooth(*t)).abs() <= 1e-14 * v.abs().max(1.0), "{v}");
    }
    y.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let g = host(&x.grad().unwrap());
    assert_matches_fd(smooth, &xs, &g, "k_smooth");
}

/// Each pass overwrites every element with a function of itself and its neighbour: the adjoint
/// must restore the array each iteration had (the stack keeps the whole array per store).
#[wp::kernel]
fn k_relax(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let t = x[i];
    let mut a = [0.0f64; 4];
    for j in 0..4 {
        a[j] = t * (j as f64 + 1.0);
    }
    for _pass in 0..3 {
        for j in 0..4 {
            a[j] = a[j] * a[(j + 1) % 4] * 0.5 + t;
        }
    }
    let mut s = 0.0f64;
    for j in 0..4 {
        s += a[j];
    }
    y[i] = s;
}

fn relax(t: f64) -> f64 {
    let mut a = [t, 2.0 * t, 3.0 * t, 4.0 * t];
    for _ in 0..3 {
        for j in 0..4 {
            a[j] = a[j] * a[(j + 1) % 4] * 0.5 + t;
        }
    }
    a.iter().sum()
}

fn gradient_through_overwrites_in_loops(dev: &wp::Device) {
    let xs = [0.2f64, -0.35, 0.5];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_relax, 3, (&x, &y), dev).unwrap();
    }
    y.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let g = host(&x.grad().unwrap());
    assert_matches_fd(relax, &xs, &g, "k_relax");
}

#[wp::kernel]
fn k_relax_plain(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let t = x[i];
    let mut a = [t, t * t, 1.0];
    for _pass in 0..2 {
        for j in 0..3 {
            a[j] = a[j] * a[(j + 2) % 3] + t;
        }
    }
    y[i] = a[0] + a[1] * a[2];
}

/// Forward mode (`wp::jvp`) through element reads and writes in loops, against reverse mode:
/// both are exact derivatives of the same f64 program, so they agree to rounding (1e-12
/// relative: a few dozen operations, each within an ulp, on values of order 1).
fn jvp_matches_the_gradient(dev: &wp::Device) {
    let xs = [0.4f64, -0.6, 0.9];
    let vs = [1.0f64, 2.0, -0.5];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(3, dev).with_grad().unwrap();
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(3, dev));
    wp::jvp(k_relax_plain, 3, (&x, &y), (&v, &y_dot), dev).unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_relax_plain, 3, (&x, &y), dev).unwrap();
    }
    y.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let g = host(&x.grad().unwrap());
    for ((jv, g), v) in host(&y_dot).iter().zip(&g).zip(&vs) {
        let want = g * v;
        assert!(
            (jv - want).abs() <= 1e-12 * want.abs().max(1.0),
            "jvp {jv}, gradient times tangent {want}"
        );
    }
}

#[wp::kernel]
fn k_big(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let mut a = [0.0f64; 32];
    for j in 0..32 {
        a[j] = x[i] + j as f64;
    }
    for j in 0..32 {
        a[(j + 1) % 32] += a[j] * 0.5;
    }
    y[i] = a[0];
}

/// Each element store in a loop pushes the whole array (here 256 bytes, 64 stores): a stack
/// too small for that is an error naming the kernel and the line of the store that did not
/// fit (the fill: 4096 bytes hold 15 of its pushes), never a wrong gradient; with room, the
/// gradient is the recurrence's.
fn adjoint_stack_holds_whole_arrays(dev: &wp::Device) {
    let x = arr(&[0.5f64], dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(1, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_big, 1, (&x, &y), dev).unwrap();
    }
    tape.set_adstack_bytes(Some(4096)).unwrap();
    y.grad().unwrap().fill(1.0).unwrap();
    match tape.backward_from_grads() {
        Err(wp::Error::Fault(f)) => {
            assert_eq!(f.kernel, "k_big");
            let src = include_str!("local_arrays.rs");
            let store = src
                .lines()
                .position(|l| l.trim() == "a[j] = x[i] + j as f64;")
                .unwrap() as u32
                + 1;
            assert!(
                matches!(f.kind, FaultKind::AdStackOverflow { capacity: 4096, line } if line == store),
                "{f:?}"
            );
        }
        other => panic!("expected an adjoint stack fault, got {other:?}"),
    }
    // A failed backward leaves partial gradients behind (on a GPU the overflowing thread's
    // reverse sweep still ran and took the output's gradient): zero them, seed again, retry.
    tape.zero().unwrap();
    y.grad().unwrap().fill(1.0).unwrap();
    tape.set_adstack_bytes(Some(1 << 16)).unwrap();
    tape.backward_from_grads().unwrap();
    // d/dx of every element of the fill is 1, and each store of the ring adds half of its
    // predecessor's derivative: the same recurrence on the derivatives, in the same f64
    // operations (sums of powers of two: exact on both backends).
    let mut d = [1.0f64; 32];
    for j in 0..32 {
        d[(j + 1) % 32] += d[j] * 0.5;
    }
    assert_eq!(host(&x.grad().unwrap()), vec![d[0]]);
}

// ---- arrays of spatial vectors and matrices ----

/// Elements at dynamic indices, their lanes by literal index (`a[j][3] *= t`, `m[1][(2, 3)]`,
/// `m[0][4][5]`), whole elements into spatial products: reads and writes through both the
/// element step and the lane members.
#[wp::kernel]
fn k_spatial_elems(x: Array<f64>, y: Array<f64>) {
    let i = tid();
    let t = x[i];
    let mut a = [DSpatialVector::ZERO; 4];
    for j in 0..4 {
        // Lane by lane (the six-scalar `spatial_vector` has no forward-mode rule yet).
        let mut e = DSpatialVector::ZERO;
        e[0] = t;
        e[1] = t * t;
        e[2] = 1.0;
        e[3] = t.sin();
        e[4] = j as f64;
        e[5] = t * (j as f64);
        a[j] = e;
        a[j][3] *= t;
    }
    let k = (i + 1) % 4;
    a[k][0] += t * 3.0;
    let mut m = [DSpatialMatrix::IDENTITY; 2];
    m[1][(2, 3)] = t;
    m[0][4][5] = a[k][1];
    let r = m[k % 2] * a[k];
    let mut s = 0.0f64;
    for j in 0..4 {
        s += spatial_dot(a[j], r) * a[j][3];
    }
    y[i] = s + m[1][(2, 3)] * m[0][(4, 5)];
}

/// The closed form of `k_spatial_elems` for thread `i`, with warp-core's host types.
fn spatial_elems(i: usize, t: f64) -> f64 {
    let mut a = [DSpatialVector::ZERO; 4];
    for (j, e) in a.iter_mut().enumerate() {
        let j = j as f64;
        *e = DSpatialVector::from_array([t, t * t, 1.0, t.sin(), j, t * j]);
        e[3] *= t;
    }
    let k = (i + 1) % 4;
    a[k][0] += t * 3.0;
    let mut m = [DSpatialMatrix::IDENTITY; 2];
    m[1][(2, 3)] = t;
    m[0][(4, 5)] = a[k][1];
    let r = m[k % 2] * a[k];
    let s: f64 = a.iter().map(|e| e.dot(r) * e[3]).sum();
    s + m[1][(2, 3)] * m[0][(4, 5)]
}

/// Values against the closed form, the gradient against central differences (the tolerances
/// of [`assert_matches_fd`]) and forward mode against the gradient (1e-12 relative, as in
/// `jvp_matches_the_gradient`).
fn spatial_elements(dev: &wp::Device) {
    let xs = [0.3f64, -0.8, 1.1, 0.6];
    let x = arr(&xs, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(4, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_spatial_elems, 4, (&x, &y), dev).unwrap();
    }
    // Each element store pushes its whole array (`a`: 192 bytes, eight stores in the loop;
    // `m`: 576 bytes, three stores): more than the default 4096 bytes a thread.
    tape.set_adstack_bytes(Some(16384)).unwrap();
    for (i, (t, v)) in xs.iter().zip(host(&y)).enumerate() {
        // The same f64 operations on the CPU; FMA contraction on CUDA.
        let want = spatial_elems(i, *t);
        assert!(
            (v - want).abs() <= 1e-13 * want.abs().max(1.0),
            "{v} vs {want}"
        );
    }
    y.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let g = host(&x.grad().unwrap());
    for (i, (&t, &g)) in xs.iter().zip(&g).enumerate() {
        assert_matches_fd(|t| spatial_elems(i, t), &[t], &[g], "k_spatial_elems");
    }
    let vs = [1.0f64, 2.0, -0.5, 0.25];
    let (v, y_dot) = (arr(&vs, dev), zeros::<f64, 1>(4, dev));
    let y2 = zeros::<f64, 1>(4, dev);
    wp::jvp(k_spatial_elems, 4, (&arr(&xs, dev), &y2), (&v, &y_dot), dev).unwrap();
    for ((jv, g), v) in host(&y_dot).iter().zip(&g).zip(&vs) {
        let want = g * v;
        assert!(
            (jv - want).abs() <= 1e-12 * want.abs().max(1.0),
            "jvp {jv}, gradient times tangent {want}"
        );
    }
}

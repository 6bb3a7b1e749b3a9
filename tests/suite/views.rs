//! In-kernel views: `a.row(i)` and `a.view(lo..hi)`, of arrays and of views, in kernels and
//! funcs; accesses, lengths, atomics and gradients through them; their bounds faults.

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    rows_read_and_write,
    rows_of_rows,
    ranges,
    atomics_through_views,
    views_in_funcs,
    view_bounds_fault,
    view_range_fault,
    gradients_through_views,
    indexed_views,
    indexed_gradients_and_faults,
    row_index_is_taken_when_made,
);

#[wp::kernel]
fn k_rows(m: Array<f32, 2>, out: Array<f32>, lens: Array<u64>) {
    let i = tid();
    let r = m.row(i);
    out[i] = r[0] + r[1] * 2.0 + r[2] * 4.0;
    r[1] = -r[1];
    lens[i] = (r.len() * 10 + r.shape()[0]) as u64;
}

fn rows_read_and_write(dev: &wp::Device) {
    let data: Vec<f32> = (0..12).map(|k| k as f32).collect();
    let m = wp::Array::from_slice(&data, dev)
        .unwrap()
        .reshape::<2>([4, 3])
        .unwrap();
    let out = zeros::<f32, 1>(4, dev);
    let lens = zeros::<u64, 1>(4, dev);
    wp::launch(k_rows, 4, (&m, &out, &lens), dev).unwrap();
    // Small integers: exact in f32 on every backend.
    let want: Vec<f32> = (0..4)
        .map(|i| data[3 * i] + data[3 * i + 1] * 2.0 + data[3 * i + 2] * 4.0)
        .collect();
    assert_eq!(host(&out), want);
    assert_eq!(host(&lens), [33; 4]);
    let got = host(&m);
    for i in 0..4 {
        assert_eq!(got[3 * i + 1], -data[3 * i + 1]);
        assert_eq!(got[3 * i], data[3 * i]);
    }
}

#[wp::kernel]
fn k_rows_of_rows(a: Array<i32, 3>, out: Array<i32, 2>) {
    let (i, j) = tid();
    let plane = a.row(i);
    let line = plane.row(j);
    out[(i, j)] = line[0] * 100 + a.row(i).row(j)[1] * 10 + line[line.len() - 1];
}

fn rows_of_rows(dev: &wp::Device) {
    let data: Vec<i32> = (0..24).collect();
    let a = wp::Array::from_slice(&data, dev)
        .unwrap()
        .reshape::<3>([2, 3, 4])
        .unwrap();
    let out = zeros::<i32, 2>([2, 3], dev);
    wp::launch(k_rows_of_rows, [2, 3], (&a, &out), dev).unwrap();
    let want: Vec<i32> = (0..2)
        .flat_map(|i| (0..3).map(move |j| (i, j)))
        .map(|(i, j)| {
            let at = |k: usize| data[i * 12 + j * 4 + k];
            at(0) * 100 + at(1) * 10 + at(3)
        })
        .collect();
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_ranges(x: Array<f64>, out: Array<f64>, lens: Array<u64>) {
    let i = tid();
    let v = x.view(2..6);
    let w = v.view(1..);
    let head = x.view(..=2);
    out[i] = v[i] + w[i % w.len()] * 10.0 + head[i % 3] * 100.0;
    if i == 0 {
        lens[0] = v.len() as u64;
        lens[1] = w.len() as u64;
        lens[2] = head.len() as u64;
        lens[3] = x.view(3..3).len() as u64;
    }
}

fn ranges(dev: &wp::Device) {
    let xs: Vec<f64> = (0..8).map(|k| k as f64 + 0.5).collect();
    let x = arr(&xs, dev);
    let out = zeros::<f64, 1>(4, dev);
    let lens = zeros::<u64, 1>(4, dev);
    wp::launch(k_ranges, 4, (&x, &out, &lens), dev).unwrap();
    let want: Vec<f64> = (0..4)
        .map(|i| xs[2 + i] + xs[3 + i % 3] * 10.0 + xs[i % 3] * 100.0)
        .collect();
    // Exact halves and small sums: exact in f64 (an FMA would not round differently).
    assert_eq!(host(&out), want);
    assert_eq!(host(&lens), [4, 3, 3, 0]);
}

#[wp::kernel]
fn k_view_atomics(m: Array<f32, 2>, total: Array<f32>) {
    let (i, j) = tid();
    atomic_add(m.row(i), j, 1.0);
    atomic_add(total.view(1..), 0, m.row(i)[j]);
}

fn atomics_through_views(dev: &wp::Device) {
    let m = zeros::<f32, 2>([8, 5], dev);
    let total = zeros::<f32, 1>(2, dev);
    wp::launch(k_view_atomics, [8, 5], (&m, &total), dev).unwrap();
    assert_eq!(host(&m), vec![1.0; 40]);
    // 40 threads each add m[i, j], which is 1 by then (its own update came first): 40, exact.
    assert_eq!(host(&total), [0.0, 40.0]);
}

#[wp::func]
fn row_sum(m: Array<f32, 2>, i: usize) -> f32 {
    let r = m.row(i);
    let mut s = 0.0;
    for j in 0..r.len() {
        s += r[j];
    }
    s
}

#[wp::kernel]
fn k_func_views(m: Array<f32, 2>, out: Array<f32>) {
    let i = tid();
    out[i] = row_sum(m, i);
}

fn views_in_funcs(dev: &wp::Device) {
    let data: Vec<f32> = (0..15).map(|k| k as f32 * 0.5).collect();
    let m = wp::Array::from_slice(&data, dev)
        .unwrap()
        .reshape::<2>([3, 5])
        .unwrap();
    let out = zeros::<f32, 1>(3, dev);
    wp::launch(k_func_views, 3, (&m, &out), dev).unwrap();
    let want: Vec<f32> = data.chunks(5).map(|r| r.iter().sum()).collect();
    assert_eq!(host(&out), want);
}

#[wp::kernel]
fn k_view_oob(x: Array<f32>, k: i32) {
    let v = x.view(1..5);
    x[0] = v[k];
}

fn view_bounds_fault(dev: &wp::Device) {
    let x = arr(&[0.0f32; 8], dev);
    // In the view and in the array: fine.
    wp::launch(k_view_oob, 1, (&x, 3), dev).unwrap();
    // Past the view (x[5] exists, v[4] does not): a fault of `x`, index 4 of 4.
    let e = wp::launch(k_view_oob, 1, (&x, 4), dev)
        .and_then(|_| wp::synchronize())
        .unwrap_err()
        .to_string();
    assert!(e.contains("k_view_oob") && e.contains("`x`"), "{e}");
    assert!(e.contains('4'), "{e}");
    // Negative: out of bounds too.
    assert!(wp::launch(k_view_oob, 1, (&x, -1), dev)
        .and_then(|_| wp::synchronize())
        .is_err());
}

#[wp::kernel]
fn k_view_range(x: Array<f32>, lo: i32, hi: i32, out: Array<u64>) {
    out[0] = x.view(lo..hi).len() as u64;
}

fn view_range_fault(dev: &wp::Device) {
    let x = arr(&[0.0f32; 8], dev);
    let out = zeros::<u64, 1>(1, dev);
    wp::launch(k_view_range, 1, (&x, 2, 8, &out), dev).unwrap();
    assert_eq!(host(&out), [6]);
    // Past the end, and backwards (Rust's slicing panics on both): faults.
    for (lo, hi) in [(0, 9), (5, 3), (-1, 2)] {
        let r =
            wp::launch(k_view_range, 1, (&x, lo, hi, &out), dev).and_then(|_| wp::synchronize());
        assert!(r.is_err(), "view({lo}..{hi}) of 8 elements must fault");
    }
}

#[wp::kernel]
fn k_view_grad(m: Array<f64, 2>, out: Array<f64>) {
    let i = tid();
    let r = m.row(i).view(1..);
    out[i] = r[0] * r[1];
}

fn gradients_through_views(dev: &wp::Device) {
    let data = [1.0f64, 2.0, 3.0, 4.0, 5.0, 6.0];
    let m = wp::Array::from_slice(&data, dev)
        .unwrap()
        .reshape::<2>([2, 3])
        .unwrap()
        .with_grad()
        .unwrap();
    let out = zeros::<f64, 1>(2, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_view_grad, 2, (&m, &out), dev).unwrap();
    }
    tape.backward(&out).unwrap();
    assert_eq!(host(&out), [6.0, 30.0]);
    // d(m[i,1] m[i,2]) = (m[i,2], m[i,1]) in columns 1 and 2; nothing in column 0. Exact.
    assert_eq!(host(&m.grad().unwrap()), [0.0, 3.0, 2.0, 0.0, 6.0, 5.0]);
}

/// Warp's indexed arrays: the leading dimension gathered through an index array.
#[wp::kernel]
fn k_gather(x: Array<Vec3>, idx: Array<i32>, out: Array<Vec3>, m: Array<f32, 2>, rows: Array<f32>) {
    let k = tid();
    let g = x.indexed(idx);
    out[k] = g[k] * 2.0;
    let gm = m.indexed(idx);
    rows[k] = gm.row(k)[1] + gm[(k, 0)] * 10.0 + (g.len() * 100) as f32;
}

fn indexed_views(dev: &wp::Device) {
    let xs: Vec<Vec3> = (0..5).map(|k| Vec3::splat(k as f32)).collect();
    let x = arr(&xs, dev);
    let idx_h = [4i32, 0, 4, 2];
    let idx = arr(&idx_h, dev);
    let out = zeros::<Vec3, 1>(4, dev);
    let mh: Vec<f32> = (0..10).map(|k| k as f32).collect();
    let m = wp::Array::from_slice(&mh, dev)
        .unwrap()
        .reshape::<2>([5, 2])
        .unwrap();
    let rows = zeros::<f32, 1>(4, dev);
    wp::launch(k_gather, 4, (&x, &idx, &out, &m, &rows), dev).unwrap();
    let want: Vec<Vec3> = idx_h.iter().map(|&i| xs[i as usize] * 2.0).collect();
    assert_eq!(host(&out), want);
    let want: Vec<f32> = idx_h
        .iter()
        .map(|&i| mh[2 * i as usize + 1] + mh[2 * i as usize] * 10.0 + 400.0)
        .collect();
    assert_eq!(host(&rows), want);
}

#[wp::kernel]
fn k_gather_sum(x: Array<f64>, idx: Array<u32>, out: Array<f64>) {
    let k = tid();
    let g = x.indexed(idx);
    out[k] = g[k] * g[k];
}

fn indexed_gradients_and_faults(dev: &wp::Device) {
    let x = arr(&[1.0f64, 2.0, 3.0], dev).with_grad().unwrap();
    // Index 2 three times: its gradient is the sum of the three uses.
    let idx = arr(&[2u32, 0, 2, 2], dev);
    let out = zeros::<f64, 1>(4, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(k_gather_sum, 4, (&x, &idx, &out), dev).unwrap();
    }
    tape.backward(&out).unwrap();
    assert_eq!(host(&out), [9.0, 1.0, 9.0, 9.0]);
    // d(x^2)/dx = 2x per use: x0 once (2), x2 three times (18). Exact.
    assert_eq!(host(&x.grad().unwrap()), [2.0, 0.0, 18.0]);
    // An index array entry past `x`: a fault of `x`; a thread past the index array: of `idx`.
    let bad = arr(&[0u32, 7], dev);
    let e = wp::launch(k_gather_sum, 2, (&x, &bad, &zeros::<f64, 1>(2, dev)), dev)
        .and_then(|_| wp::synchronize())
        .unwrap_err()
        .to_string();
    assert!(e.contains("`x`") && e.contains('7'), "{e}");
    let short = arr(&[0u32], dev);
    let e = wp::launch(k_gather_sum, 2, (&x, &short, &zeros::<f64, 1>(2, dev)), dev)
        .and_then(|_| wp::synchronize())
        .unwrap_err()
        .to_string();
    assert!(e.contains("`idx`"), "{e}");
}

/// A row keeps naming the row it was made at, whatever its index variable does later.
#[wp::kernel]
fn k_row_snapshot(a: Array<i32, 2>, out: Array<i32>) {
    let mut k = 0;
    let r = a.row(k);
    let mut s = 0;
    while k < 3 {
        s += r[k];
        k += 1;
    }
    out[0] = s;
}

fn row_index_is_taken_when_made(dev: &wp::Device) {
    let a = wp::Array::from_slice(&[1, 2, 3, 10, 20, 30, 100, 200, 300], dev)
        .unwrap()
        .reshape::<2>([3, 3])
        .unwrap();
    let out = zeros::<i32, 1>(1, dev);
    wp::launch(k_row_snapshot, 1, (&a, &out), dev).unwrap();
    // Row 0: 1 + 2 + 3 (the diagonal would be 1 + 20 + 300).
    assert_eq!(host(&out), [6]);
}

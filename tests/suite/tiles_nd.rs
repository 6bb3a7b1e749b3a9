//! Tiles of rank 3 and 4 (`Tile<T, A, B, C>`, `Tile<T, A, B, C, D>`), on every backend: loads
//! and stores against 3-D and 4-D arrays whose extents are not multiples of the tile (elements
//! outside read zero and are not stored), the constructors, elementwise operators and maps,
//! reductions to `Tile<T, 1>`, reshapes across ranks, indexing and atomic adds, each against
//! the same computation written in plain Rust on the host; then f64 gradchecks of their
//! adjoints, and the CPU and a GPU compared bit for bit.
//!
//! Exactness: every operation here but `tile_map(sin, ..)` and the reductions is one rounding
//! per element, computed the same way on the host, so those comparisons are exact; the
//! reductions are compared with the host's sum within 1e-5 relative (a different order of
//! f32 additions), `sin` with `math_rel`. Gradchecks: 1e-6 relative, as tile_grad.rs.

// The kernel language has no `div_ceil` yet: kernels round up with `(n + d - 1) / d`.
#![allow(clippy::manual_div_ceil)]

use crate::tile_grad::{check, values};
use crate::{host, math_rel, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    load_ops_store_3d_ragged,
    load_store_4d_ragged,
    constructors_reductions_and_index,
    reshapes_across_ranks,
    atomic_add_3d,
    gradients_3d,
    gradients_4d_and_reshape,
    atomic_add_gradients_3d_and_4d,
    func_maps_3d_and_4d,
);

const A: usize = 2;
const B: usize = 3;
const C: usize = 4;

/// The host's element of a row-major array of `shape` at signed coordinates, or `None` outside.
fn at(shape: &[usize], c: &[i64]) -> Option<usize> {
    let mut flat = 0usize;
    for (&n, &x) in shape.iter().zip(c) {
        if x < 0 || x >= n as i64 {
            return None;
        }
        flat = flat * n + x as usize;
    }
    Some(flat)
}

#[wp::kernel]
fn k_ops3(a: Array<f32, 3>, b: Array<f32, 3>, s: f32) {
    let (i, j, k) = tid();
    let o0 = (i * A) as i32;
    let o1 = (j * B) as i32;
    let o2 = (k * C) as i32;
    let t: Tile<f32, A, B, C> = tile_load(a, (o0, o1, o2));
    let one: Tile<f32, A, B, C> = tile_ones();
    let u = (t * s + one) - t / 2.0;
    let v = tile_map(sin, u) + tile_map(max, t, u);
    tile_store(b, v, (o0, o1, o2));
}

/// `(t * s + 1) - t / 2`, `sin`, a binary map, on a 5 x 7 x 9 array with 2 x 3 x 4 tiles (every
/// axis ragged): each element against the host's; the padding is never stored.
fn load_ops_store_3d_ragged(dev: &wp::Device) {
    let shape = [5usize, 7, 9];
    let n: usize = shape.iter().product();
    let data: Vec<f32> = (0..n).map(|k| (k as f32 * 0.37).sin() * 3.0).collect();
    let a = wp::Array::from_slice_shape(&data, (shape[0], shape[1], shape[2]), dev).unwrap();
    let b = wp::Array::<f32, 3>::full((shape[0], shape[1], shape[2]), -7.0, dev).unwrap();
    let blocks = (
        (shape[0] + A - 1) / A,
        (shape[1] + B - 1) / B,
        (shape[2] + C - 1) / C,
    );
    for bd in [1, 7, 32] {
        b.fill(-7.0).unwrap();
        wp::launch_tiled(k_ops3, blocks, (&a, &b, 1.5f32), bd, dev).unwrap();
        let got = host(&b);
        for (k, (&g, &x)) in got.iter().zip(&data).enumerate() {
            let u = (x * 1.5 + 1.0) - x / 2.0;
            let want = u.sin() + x.max(u);
            assert!(
                (g - want).abs() <= math_rel(dev) * want.abs().max(1.0),
                "element {k} at block_dim {bd}: {g} vs {want}"
            );
        }
    }
}

#[wp::kernel]
fn k_copy4(a: Array<i32, 4>, b: Array<i32, 4>, o: Array<i32>) {
    // Warp's positional shape; one block reads at offsets that cross every edge (some below 0).
    let t = tile_load(a, (2, 3, 2, 3), (o[0], o[1], o[2], o[3]));
    let z: Tile<i32, 2, 3, 2, 3> = tile_full(5);
    tile_store(b, t * 10 + z, (o[0], o[1], o[2], o[3]));
}

/// A 4-D load and store at offsets crossing both ends of every axis of a 3 x 4 x 3 x 5 array:
/// the elements inside get `10 x + 5`, the rest of `b` keeps its fill.
fn load_store_4d_ragged(dev: &wp::Device) {
    let shape = [3usize, 4, 3, 5];
    let n: usize = shape.iter().product();
    let data: Vec<i32> = (0..n as i32).collect();
    let a = wp::Array::from_slice_shape(&data, (3, 4, 3, 5), dev).unwrap();
    let b = wp::Array::<i32, 4>::full((3, 4, 3, 5), -1, dev).unwrap();
    for offs in [
        [0i32, 0, 0, 0],
        [2, 2, 2, 3],
        [-1, -2, 1, -2],
        [1, 3, -1, 4],
    ] {
        b.fill(-1).unwrap();
        let o = wp::Array::from_slice(&offs, dev).unwrap();
        wp::launch_tiled(k_copy4, 1, (&a, &b, &o), 16, dev).unwrap();
        let got = host(&b);
        let mut want = vec![-1; n];
        for i in 0..2i64 {
            for j in 0..3i64 {
                for k in 0..2i64 {
                    for l in 0..3i64 {
                        let c = [
                            offs[0] as i64 + i,
                            offs[1] as i64 + j,
                            offs[2] as i64 + k,
                            offs[3] as i64 + l,
                        ];
                        if let Some(f) = at(&shape, &c) {
                            want[f] = data[f] * 10 + 5;
                        }
                    }
                }
            }
        }
        assert_eq!(got, want, "offsets {offs:?}");
    }
}

#[wp::kernel]
fn k_reduce3(a: Array<f32, 3>, out: Array<f32>, q: Array<i32, 4>, iout: Array<i32>) {
    let t = tile_load(a, (3, 4, 5), (0, 0, 0));
    tile_store(out, tile_sum(t), 0);
    tile_store(out, tile_min(t), 1);
    tile_store(out, tile_max(t), 2);
    out[3] = t[(2, 1, 4)];
    let z = tile_zeros::<i32, 1, 2, 2, 3>();
    let w = tile_load::<1, 2, 2, 3>(q, (0, 0, 0, 0)) + z;
    tile_store(iout, tile_sum(w), 0);
    tile_store(iout, tile_argmax(w), 1);
    iout[2] = w[(0, 1, 0, 2)];
}

/// `tile_sum`, `tile_min`, `tile_max`, `tile_argmax` of rank-3 and rank-4 tiles (to
/// `Tile<T, 1>`), `t[(i, j, k)]` and `t[(i, j, k, l)]`, `tile_zeros` of rank 4.
fn constructors_reductions_and_index(dev: &wp::Device) {
    let data: Vec<f32> = (0..60).map(|k| ((k * 17) % 23) as f32 - 11.5).collect();
    let a = wp::Array::from_slice_shape(&data, (3, 4, 5), dev).unwrap();
    let qd: Vec<i32> = (0..12).map(|k| (k * 5) % 12 - 3).collect();
    let q = wp::Array::from_slice_shape(&qd, (1, 2, 2, 3), dev).unwrap();
    let out = zeros::<f32, 1>(4, dev);
    let iout = zeros::<i32, 1>(3, dev);
    for bd in [1, 5, 64] {
        wp::launch_tiled(k_reduce3, 1, (&a, &out, &q, &iout), bd, dev).unwrap();
        let got = host(&out);
        let sum: f32 = data.iter().sum();
        assert!(
            (got[0] - sum).abs() <= 1e-5 * sum.abs().max(1.0),
            "sum {got:?}"
        );
        assert_eq!(got[1], data.iter().cloned().fold(f32::INFINITY, f32::min));
        assert_eq!(
            got[2],
            data.iter().cloned().fold(f32::NEG_INFINITY, f32::max)
        );
        assert_eq!(got[3], data[(2 * 4 + 1) * 5 + 4]);
        let gi = host(&iout);
        let imax = qd.iter().max().unwrap();
        let first = qd.iter().position(|x| x == imax).unwrap() as i32;
        assert_eq!(gi, vec![qd.iter().sum::<i32>(), first, qd[(2) * 3 + 2]]);
    }
}

#[wp::kernel]
fn k_reshape(a: Array<f32>, o2: Array<f32, 2>, o1: Array<f32>, o4: Array<f32, 4>) {
    let t = tile_load::<24>(a, 0);
    let t3: Tile<f32, 2, 3, 4> = tile_reshape(t);
    let t2: Tile<f32, 6, 4> = tile_reshape(t3 * 2.0);
    tile_store(o2, t2, (0, 0));
    let s: Tile<f32, 4, 1, 6> = tile_reshape(t2);
    let flat = tile_reshape::<24>(tile_squeeze(s) + 1.0);
    tile_store(o1, flat, 0);
    let t4: Tile<f32, 1, 2, 3, 4> = tile_reshape(t3);
    tile_store(o4, t4, (0, 0, 0, 0));
}

/// `tile_reshape` 1 -> 3 -> 2 -> 3 -> (squeeze) 2 -> 1 and 3 -> 4: the row-major order kept.
fn reshapes_across_ranks(dev: &wp::Device) {
    let data: Vec<f32> = (0..24).map(|k| k as f32 - 5.0).collect();
    let a = wp::Array::from_slice(&data, dev).unwrap();
    let o2 = wp::Array::<f32, 2>::zeros((6, 4), dev).unwrap();
    let o1 = zeros::<f32, 1>(24, dev);
    let o4 = wp::Array::<f32, 4>::zeros((1, 2, 3, 4), dev).unwrap();
    wp::launch_tiled(k_reshape, 1, (&a, &o2, &o1, &o4), 8, dev).unwrap();
    let twice: Vec<f32> = data.iter().map(|x| x * 2.0).collect();
    assert_eq!(host(&o2), twice);
    let plus: Vec<f32> = twice.iter().map(|x| x + 1.0).collect();
    assert_eq!(host(&o1), plus);
    assert_eq!(host(&o4), data);
}

#[wp::kernel]
fn k_atomic3(a: Array<f32, 3>, t_in: Array<f32, 3>, old: Array<f32, 3>) {
    let b = tid();
    let t = tile_load::<2, 2, 3>(t_in, (0, 0, 0));
    // Every block adds the same tile at offset (1, 1, -1): the in-array part accumulates.
    let o = tile_atomic_add(a, t, (1, 1, -1));
    if b == 0 {
        tile_store(old, o * 0.0, (0, 0, 0));
    }
}

/// `tile_atomic_add` of a rank-3 tile from 3 blocks into a 2 x 3 x 2 array at offsets that
/// cross its edges: the elements inside gain 3x the tile's element, the rest is untouched.
fn atomic_add_3d(dev: &wp::Device) {
    let a = wp::Array::<f32, 3>::full((2, 3, 2), 1.0, dev).unwrap();
    let td: Vec<f32> = (0..12).map(|k| k as f32).collect();
    let t_in = wp::Array::from_slice_shape(&td, (2, 2, 3), dev).unwrap();
    let old = wp::Array::<f32, 3>::zeros((2, 2, 3), dev).unwrap();
    wp::launch_tiled(k_atomic3, 3, (&a, &t_in, &old), 4, dev).unwrap();
    let mut want = vec![1.0f32; 12];
    for i in 0..2i64 {
        for j in 0..2i64 {
            for k in 0..3i64 {
                if let Some(f) = at(&[2, 3, 2], &[1 + i, 1 + j, k - 1]) {
                    want[f] += 3.0 * td[((i * 2 + j) * 3 + k) as usize];
                }
            }
        }
    }
    assert_eq!(host(&a), want);
}

// ---- Gradients -----------------------------------------------------------------------------

#[wp::kernel]
fn k_grad3(x: Array<f64, 3>, y: Array<f64, 3>, w: Array<f64>, out: Array<f64, 3>, tot: Array<f64>) {
    let (i, j, k) = tid();
    // Each block's total in its own element of `tot` (2 x 3 x 2 blocks).
    let blk = ((i * 3 + j) * 2 + k) as i32;
    let o0 = (i * 2) as i32;
    let o1 = (j * 2) as i32;
    let o2 = (k * 3) as i32;
    let s = w[0] * 2.0 + 0.5;
    let a: Tile<f64, 2, 2, 3> = tile_load(x, (o0, o1, o2));
    let b: Tile<f64, 2, 2, 3> = tile_load(y, (o0, o1, o2));
    let p = a * b + a * s - tile_map(sin, b) / (a * a + 2.0);
    tile_store(out, p * w[1], (o0, o1, o2));
    let r: Tile<f64, 4, 3> = tile_reshape(p * a);
    tile_store(tot, tile_sum(r), blk);
}

/// `+ - * /`, a uniform scalar, `sin`, loads and stores of rank 3 on a 3 x 5 x 4 array (ragged
/// against 2 x 2 x 3 tiles), a reshape to rank 2 and a sum, at block sizes 1, 5 and 32.
fn gradients_3d(dev: &wp::Device) {
    let (m, n, p) = (3usize, 5usize, 4usize);
    let x = crate::arr(&values(m * n * p, 1), dev).with_grad().unwrap();
    let y = crate::arr(&values(m * n * p, 2), dev).with_grad().unwrap();
    let w = crate::arr(&[0.3f64, -1.25], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(m * n * p, dev).with_grad().unwrap();
    let tot = zeros::<f64, 1>(12, dev).with_grad().unwrap();
    let (x3, y3, o3) = (
        x.reshape((m, n, p)).unwrap(),
        y.reshape((m, n, p)).unwrap(),
        out.reshape((m, n, p)).unwrap(),
    );
    let blocks = ((m + 1) / 2, (n + 1) / 2, (p + 2) / 3);
    assert_eq!(blocks, (2, 3, 2));
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_grad3, blocks, (&x3, &y3, &w, &o3, &tot), bd, dev);
        check(
            &format!("rank 3, out, block_dim {bd}"),
            run,
            &[&x, &y, &w],
            &out,
        );
        let run = || wp::launch_tiled(k_grad3, blocks, (&x3, &y3, &w, &o3, &tot), bd, dev);
        check(
            &format!("rank 3, totals, block_dim {bd}"),
            run,
            &[&x, &y],
            &tot,
        );
    }
}

#[wp::kernel]
fn k_grad4(x: Array<f64, 4>, out: Array<f64>, z: Array<f64, 4>) {
    let t = tile_load(x, (2, 2, 2, 2), (0, -1, 0, 1));
    let u = t * t - t * 0.5;
    let r: Tile<f64, 16> = tile_reshape(u);
    tile_store(out, r, 0);
    let m = tile_max(t);
    let back: Tile<f64, 2, 1, 4, 2> = tile_reshape(m[0] * 3.0 + r);
    tile_store(z, back, (1, 0, 0, 0));
}

/// A 4-D load at offsets crossing two edges, `t * t - t / 2`, reshapes 4 -> 1 -> 4, a max and a
/// store into a 4-D output at an offset that cuts the tile (the store's adjoint hands only the
/// stored elements' gradients to the tile).
fn gradients_4d_and_reshape(dev: &wp::Device) {
    let shape = (3usize, 2usize, 4usize, 3usize);
    let total = shape.0 * shape.1 * shape.2 * shape.3;
    let x = crate::arr(&values(total, 5), dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(16, dev).with_grad().unwrap();
    let z = zeros::<f64, 1>(total, dev).with_grad().unwrap();
    let (x4, z4) = (x.reshape(shape).unwrap(), z.reshape(shape).unwrap());
    for bd in [1, 3, 32] {
        let run = || wp::launch_tiled(k_grad4, 1, (&x4, &out, &z4), bd, dev);
        check(&format!("rank 4, out, block_dim {bd}"), run, &[&x], &out);
        let run = || wp::launch_tiled(k_grad4, 1, (&x4, &out, &z4), bd, dev);
        check(&format!("rank 4, stored, block_dim {bd}"), run, &[&x], &z);
    }
}

#[wp::kernel]
fn k_atomic_grad(x: Array<f64, 3>, w: Array<f64>, acc3: Array<f64, 3>, acc4: Array<f64, 4>) {
    let t: Tile<f64, 2, 2, 3> = tile_load(x, (0, 1, 0));
    let u = t * t * w[0] + t;
    // Windows that stick out of both arrays: x's elements whose place is outside get nothing.
    tile_atomic_add(acc3, u, (1, -1, 0));
    let v: Tile<f64, 1, 2, 2, 3> = tile_reshape(u * t);
    tile_atomic_add(acc4, v, (0, 1, 0, 1));
}

/// A nonlinear read of the accumulators, so that their gradients differ element by element.
#[wp::kernel]
fn k_atomic_post(a3: Array<f64>, a4: Array<f64>, out: Array<f64>) {
    let i = tid();
    let n3 = a3.len();
    let v = if i < n3 { a3[i] } else { a4[i - n3] };
    out[i] = v * v * 0.5 + v * (i as f64 + 1.0);
}

/// Backward through `tile_atomic_add` of rank 3 and 4 (the tile gathers the array's gradient
/// over the window, the elements outside get nothing), gradcheck in f64 at block sizes 1, 5
/// and 32; the accumulators are zeroed before every run, as the adds would pile up otherwise.
fn atomic_add_gradients_3d_and_4d(dev: &wp::Device) {
    let (s3, s4) = ((2usize, 3usize, 3usize), (1usize, 2usize, 3usize, 3usize));
    let n3 = s3.0 * s3.1 * s3.2;
    let n4 = s4.0 * s4.1 * s4.2 * s4.3;
    let x = crate::arr(&values(2 * 3 * 3, 7), dev).with_grad().unwrap();
    let w = crate::arr(&[0.6f64], dev).with_grad().unwrap();
    let a3 = zeros::<f64, 1>(n3, dev).with_grad().unwrap();
    let a4 = zeros::<f64, 1>(n4, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(n3 + n4, dev).with_grad().unwrap();
    let x3 = x.reshape((2, 3, 3)).unwrap();
    let (acc3, acc4) = (a3.reshape(s3).unwrap(), a4.reshape(s4).unwrap());
    for bd in [1, 5, 32] {
        let run = || -> wp::Result<()> {
            a3.fill(0.0)?;
            a4.fill(0.0)?;
            wp::launch_tiled(k_atomic_grad, 1, (&x3, &w, &acc3, &acc4), bd, dev)?;
            wp::launch(k_atomic_post, n3 + n4, (&a3, &a4, &out), dev)
        };
        check(
            &format!("rank 3 and 4 atomic adds, block_dim {bd}"),
            run,
            &[&x, &w],
            &out,
        );
    }
}

#[wp::func]
fn nd_blend(a: f64, b: f64) -> f64 {
    if a > b {
        return a - 0.5 * b;
    }
    a * b + 1.0
}

#[wp::func]
fn nd_three(a: f64, b: f64, c: f64) -> f64 {
    a * b - c * c * 0.25
}

#[wp::kernel]
fn k_func_nd(x: Array<f64, 3>, y: Array<f64, 3>, out3: Array<f64, 3>, out4: Array<f64, 4>) {
    let a: Tile<f64, 2, 2, 3> = tile_load(x, (0, 1, -1));
    let b: Tile<f64, 2, 2, 3> = tile_load(y, (0, 1, -1));
    tile_store(out3, tile_map(nd_blend, a, b), (0, 0, 0));
    let c: Tile<f64, 2, 1, 2, 3> = tile_reshape(tile_map(nd_three, a, b, a));
    tile_store(out4, tile_map(sin, c), (0, 0, 0, 0));
}

/// `tile_map` of user funcs over tiles of rank 3 and 4 (two and three tiles, a loaded window
/// that sticks out of the arrays): forward against the host's computation (exact on the CPU,
/// the same roundings; on CUDA within 1e-14 relative: FMA contraction and the device's f64
/// `sin`, a few ulp), then an f64 gradcheck through the funcs' adjoints at block sizes 1, 5 and 32.
fn func_maps_3d_and_4d(dev: &wp::Device) {
    let (s3, s4) = ((2usize, 3usize, 3usize), (2usize, 1usize, 2usize, 3usize));
    let n = s3.0 * s3.1 * s3.2;
    let x = crate::arr(&values(n, 11), dev).with_grad().unwrap();
    let y = crate::arr(&values(n, 12), dev).with_grad().unwrap();
    let o3 = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let o4 = zeros::<f64, 1>(12, dev).with_grad().unwrap();
    let (x3, y3) = (x.reshape(s3).unwrap(), y.reshape(s3).unwrap());
    let (out3, out4) = (o3.reshape(s3).unwrap(), o4.reshape(s4).unwrap());
    wp::launch_tiled(k_func_nd, 1, (&x3, &y3, &out3, &out4), 7, dev).unwrap();
    let (hx, hy) = (host(&x), host(&y));
    // Tile element (i, j, k) reads array element (i, j + 1, k - 1), zero outside.
    let read = |h: &[f64], i: usize, j: usize, k: usize| -> f64 {
        let (jj, kk) = (j + 1, k as i64 - 1);
        if jj < s3.1 && kk >= 0 {
            h[(i * s3.1 + jj) * s3.2 + kk as usize]
        } else {
            0.0
        }
    };
    let (g3, g4) = (host(&o3), host(&o4));
    let tol = if dev.is_cpu() { 0.0 } else { 1e-14 };
    let close = |g: f64, w: f64| (g - w).abs() <= tol * w.abs().max(1.0);
    for i in 0..2 {
        for j in 0..2 {
            for k in 0..3 {
                let (a, b) = (read(&hx, i, j, k), read(&hy, i, j, k));
                let want = if a > b { a - 0.5 * b } else { a * b + 1.0 };
                assert_eq!(
                    g3[(i * s3.1 + j) * s3.2 + k],
                    want,
                    "blend at ({i}, {j}, {k})"
                );
                let three = (a * b - a * a * 0.25).sin();
                let g = g4[(i * 2 + j) * 3 + k];
                assert!(close(g, three), "three at ({i}, {j}, {k}): {g} != {three}");
            }
        }
    }
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_func_nd, 1, (&x3, &y3, &out3, &out4), bd, dev);
        check(
            &format!("rank 3 func maps, block_dim {bd}"),
            run,
            &[&x, &y],
            &o3,
        );
        let run = || wp::launch_tiled(k_func_nd, 1, (&x3, &y3, &out3, &out4), bd, dev);
        check(
            &format!("rank 4 func maps, block_dim {bd}"),
            run,
            &[&x, &y],
            &o4,
        );
    }
}

/// The rank-3 and rank-4 forward and backward on the CPU and on a GPU: every operation here has
/// a fixed order on both backends, but `sin` is CUDA's on the GPU (a few ulp off the CPU's), so
/// each output is equal bit for bit or within 1e-14 relative. Skipped, saying so, without a GPU.
#[test]
fn cpu_and_gpu_agree_on_rank_3_and_4() {
    let Ok(gpu) = wp::get_device(&crate::test_gpu()) else {
        eprintln!("SKIPPED cpu_and_gpu_agree_on_rank_3_and_4: no GPU");
        return;
    };
    let _gpu = crate::gpu_lock();
    let cpu = wp::get_device("cpu").unwrap();
    let run = |dev: &wp::Device| -> Vec<Vec<f64>> {
        let (m, n, p) = (3usize, 5usize, 4usize);
        let x = crate::arr(&values(m * n * p, 1), dev).with_grad().unwrap();
        let y = crate::arr(&values(m * n * p, 2), dev).with_grad().unwrap();
        let w = crate::arr(&[0.3f64, -1.25], dev).with_grad().unwrap();
        let out = zeros::<f64, 1>(m * n * p, dev).with_grad().unwrap();
        let tot = zeros::<f64, 1>(12, dev).with_grad().unwrap();
        let (x3, y3, o3) = (
            x.reshape((m, n, p)).unwrap(),
            y.reshape((m, n, p)).unwrap(),
            out.reshape((m, n, p)).unwrap(),
        );
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch_tiled(k_grad3, (2, 3, 2), (&x3, &y3, &w, &o3, &tot), 32, dev).unwrap();
        }
        let seed: Vec<f64> = (0..m * n * p).map(|k| (k % 7) as f64 - 3.0).collect();
        out.grad()
            .unwrap()
            .copy_from(&crate::arr(&seed, dev))
            .unwrap();
        tot.grad().unwrap().fill(0.5).unwrap();
        tape.backward_from_grads().unwrap();
        vec![
            out.to_vec().unwrap(),
            tot.to_vec().unwrap(),
            x.grad().unwrap().to_vec().unwrap(),
            y.grad().unwrap().to_vec().unwrap(),
        ]
    };
    let (c, g) = (run(&cpu), run(&gpu));
    for (k, (c, g)) in c.iter().zip(&g).enumerate() {
        let (cb, gb): (Vec<u64>, Vec<u64>) = (
            c.iter().map(|v| v.to_bits()).collect(),
            g.iter().map(|v| v.to_bits()).collect(),
        );
        // `sin` is CUDA's on the GPU: its results may differ in the last bit.
        let close = c
            .iter()
            .zip(g)
            .all(|(x, y)| (x - y).abs() <= 1e-14 * x.abs().max(1.0));
        assert!(cb == gb || close, "output {k}: CPU {c:?} vs GPU {g:?}");
    }
}

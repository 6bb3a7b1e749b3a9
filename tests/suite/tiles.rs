//! Tiles: block-cooperative kernels launched with `launch_tiled`, on every backend, each
//! operation against the same computation written in plain Rust on the host, with array sizes
//! that are not multiples of the tile (ragged edges read zeros and skip their stores).
//!
//! Exactness: loads, stores, elementwise `+ - *`, reductions (a fixed order that both backends
//! share) and the FMA matmul (one `mul_add` chain per output in ascending k, on both) give the
//! same bits on the CPU and on a GPU, so those comparisons are exact; `tile_map(sin, ..)` is
//! compared with `math_rel` (CUDA's `sinf` is not the host's).

// The kernel language has no `div_ceil` yet: kernels round up with `(n + d - 1) / d`.
#![allow(clippy::manual_div_ceil)]

use crate::{arr, assert_close_f32, host, math_rel, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    load_scale_store_2d_ragged,
    block_sum_of_thread_values,
    gemm_k_loop,
    gemm_f64,
    reductions_and_construction,
    tile_map_and_extract,
    lanes_keep_values_between_tile_operations,
    lane_returns_after_the_last_tile_operation,
    tiled_kernel_launched_plainly_is_an_error,
    width_must_match_block_dim,
    tile_index_out_of_range_faults,
    transpose_and_broadcast,
    reduce_with_functions,
    atomic_add_of_tiles,
    scans,
    shared_memory_beyond_48k_and_beyond_the_device,
    more_blocks_than_a_gpu_grid_holds,
);

const TM: usize = 16;
const TN: usize = 8;

#[wp::kernel]
fn k_scale_2d(a: Array<f32, 2>, b: Array<f32, 2>, s: f32) {
    let (i, j) = tid();
    let t: Tile<f32, TM, TN> = tile_load(a, ((i * TM) as i32, (j * TN) as i32));
    let u = t * s + t;
    tile_store(b, u, ((i * TM) as i32, (j * TN) as i32));
}

/// A 2-D load, `t * s + t` and a store, on a 37 x 45 array (not a multiple of 16 x 8): the
/// padding is never stored, and every element is exactly the host's `x * s + x`.
fn load_scale_store_2d_ragged(dev: &wp::Device) {
    let (m, n) = (37usize, 45usize);
    let data: Vec<f32> = (0..m * n).map(|k| k as f32 * 0.25 - 3.0).collect();
    let a = wp::Array::from_slice_shape(&data, (m, n), dev).unwrap();
    let b = wp::Array::<f32, 2>::full((m, n), -7.0, dev).unwrap();
    for bd in [1, 32, 64, 128] {
        b.fill(-7.0).unwrap();
        let blocks = (m.div_ceil(TM), n.div_ceil(TN));
        wp::launch_tiled(k_scale_2d, blocks, (&a, &b, 1.5f32), bd, dev).unwrap();
        let got = host(&b);
        for (k, (&g, &x)) in got.iter().zip(&data).enumerate() {
            assert_eq!(g, x * 1.5 + x, "element {k} at block_dim {bd}");
        }
    }
}

#[wp::kernel(block_dim = 64)]
fn k_block_sum(x: Array<f32>, out: Array<f32>, n: usize) {
    let b = tid();
    let i = b * 64 + lane();
    let v = if i < n { x[i] * 2.0 } else { 0.0 };
    let s = tile_sum(tile(v));
    if lane() == 0 {
        out[b] = s[0];
    }
}

/// `tile(x)` of per-thread values, a block sum, and one thread writing it: 1000 values in
/// blocks of 64 (the last one ragged), against the host's sum in the reduction's order.
fn block_sum_of_thread_values(dev: &wp::Device) {
    let n = 1000usize;
    let data: Vec<f32> = (0..n)
        .map(|k| ((k * 37 % 101) as f32 - 50.0) * 0.125)
        .collect();
    let x = arr(&data, dev);
    let blocks = n.div_ceil(64);
    let out = zeros::<f32, 1>(blocks, dev);
    wp::launch_tiled(k_block_sum, blocks, (&x, &out, n), 64, dev).unwrap();
    let got = host(&out);
    for (b, &g) in got.iter().enumerate() {
        // Values that are multiples of 1/8 below 2^20: every order of the sum is exact.
        let want: f32 = (b * 64..(b * 64 + 64).min(n)).map(|i| data[i] * 2.0).sum();
        assert_eq!(g, want, "block {b}");
    }
}

const BM: usize = 16;
const BN: usize = 16;
const BK: usize = 8;

#[wp::kernel]
fn k_gemm(a: Array<f32, 2>, b: Array<f32, 2>, c: Array<f32, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f32, BM, BN>();
    let k_tiles = (a.shape()[1] + BK - 1) / BK;
    for k in 0..k_tiles {
        let ta = tile_load::<BM, BK>(a, ((i * BM) as i32, (k * BK) as i32));
        let tb = tile_load::<BK, BN>(b, ((k * BK) as i32, (j * BN) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * BM) as i32, (j * BN) as i32));
}

/// Host reference of the tiled product: each output one `mul_add` chain over k ascending from
/// +0, as the tile matmul computes it on both backends (the zero padding adds exact zeros).
fn gemm_host(a: &[f32], b: &[f32], m: usize, k: usize, n: usize) -> Vec<f32> {
    let mut c = vec![0f32; m * n];
    for i in 0..m {
        for j in 0..n {
            let mut acc = 0f32;
            for p in 0..k {
                acc = a[i * k + p].mul_add(b[p * n + j], acc);
            }
            c[i * n + j] = acc;
        }
    }
    c
}

/// A GEMM of 45 x 37 by 37 x 29 in 16 x 16 tiles over k-tiles of 8 (every edge ragged):
/// bit-exact against the host's FMA chains at several block sizes, and within the f32
/// rounding bound of a float64 product.
fn gemm_k_loop(dev: &wp::Device) {
    let (m, k, n) = (45usize, 37usize, 29usize);
    let ad: Vec<f32> = (0..m * k)
        .map(|t| ((t * 7919 % 1013) as f32) / 1013.0 - 0.5)
        .collect();
    let bd_: Vec<f32> = (0..k * n)
        .map(|t| ((t * 104729 % 997) as f32) / 997.0 - 0.5)
        .collect();
    let a = wp::Array::from_slice_shape(&ad, (m, k), dev).unwrap();
    let b = wp::Array::from_slice_shape(&bd_, (k, n), dev).unwrap();
    let c = zeros::<f32, 2>((m, n), dev);
    let want = gemm_host(&ad, &bd_, m, k, n);
    for block_dim in [1, 33, 128, 256] {
        c.fill(0.0).unwrap();
        wp::launch_tiled(
            k_gemm,
            (m.div_ceil(BM), n.div_ceil(BN)),
            (&a, &b, &c),
            block_dim,
            dev,
        )
        .unwrap();
        let got = host(&c);
        assert_eq!(got, want, "block_dim {block_dim}");
    }
    // Against float64: |error| <= k * 2^-24 * sum |a||b| per element (a rounding per FMA).
    for i in 0..m {
        for j in 0..n {
            let exact: f64 = (0..k)
                .map(|p| ad[i * k + p] as f64 * bd_[p * n + j] as f64)
                .sum();
            let mag: f64 = (0..k)
                .map(|p| (ad[i * k + p] as f64 * bd_[p * n + j] as f64).abs())
                .sum();
            let err = (want[i * n + j] as f64 - exact).abs();
            assert!(
                err <= k as f64 * f32::EPSILON as f64 * mag,
                "({i}, {j}): {err:e}"
            );
        }
    }
}

#[wp::kernel]
fn k_gemm64(a: Array<f64, 2>, b: Array<f64, 2>, c: Array<f64, 2>) {
    let (i, j) = tid();
    let ta = tile_load(a, (8, 4), ((i * 8) as i32, 0));
    let tb = tile_load(b, (4, 8), (0, (j * 8) as i32));
    let p = tile_matmul(ta, tb);
    tile_store(c, p * 2.0, ((i * 8) as i32, (j * 8) as i32));
}

/// f64 tiles, Warp's positional shape (`tile_load(a, (8, 4), offsets)`), the two-argument
/// matmul and a tile times a scalar.
fn gemm_f64(dev: &wp::Device) {
    let (m, n) = (10usize, 13usize);
    let ad: Vec<f64> = (0..m * 4).map(|t| t as f64 * 0.5 - 3.0).collect();
    let bd_: Vec<f64> = (0..4 * n).map(|t| 1.0 - t as f64 * 0.25).collect();
    let a = wp::Array::from_slice_shape(&ad, (m, 4), dev).unwrap();
    let b = wp::Array::from_slice_shape(&bd_, (4, n), dev).unwrap();
    let c = zeros::<f64, 2>((m, n), dev);
    wp::launch_tiled(
        k_gemm64,
        (m.div_ceil(8), n.div_ceil(8)),
        (&a, &b, &c),
        32,
        dev,
    )
    .unwrap();
    let got = host(&c);
    for i in 0..m {
        for j in 0..n {
            let mut acc = 0f64;
            for p in 0..4 {
                acc = ad[i * 4 + p].mul_add(bd_[p * n + j], acc);
            }
            assert_eq!(got[i * n + j], acc * 2.0, "({i}, {j})");
        }
    }
}

#[wp::kernel]
fn k_reduce(x: Array<f32>, out: Array<f32>, idx: Array<i32>) {
    let b = tid();
    let t = tile_load::<40>(x, (b * 40) as i32);
    let lo = tile_min(t);
    let hi = tile_max(t);
    let s = tile_sum(t);
    let am = tile_argmax(t);
    let an = tile_argmin(t);
    let ones: Tile<f32, 40> = tile_ones();
    let r = tile_arange::<f32, 40>();
    let dot = tile_sum(ones + r);
    if lane() == 0 {
        out[b * 4] = lo[0];
        out[b * 4 + 1] = hi[0];
        out[b * 4 + 2] = s[0];
        out[b * 4 + 3] = dot[0];
        idx[b * 2] = am[0];
        idx[b * 2 + 1] = an[0];
    }
}

/// Min, max, sum, argmax and argmin of ragged tiles of 40 (the last block reads 20 values and
/// 20 zeros), `tile_ones` and `tile_arange`.
fn reductions_and_construction(dev: &wp::Device) {
    let n = 100usize;
    let data: Vec<f32> = (0..n)
        .map(|k| ((k * 29 % 53) as f32 - 20.0) * 0.5)
        .collect();
    let x = arr(&data, dev);
    let blocks = n.div_ceil(40);
    let out = zeros::<f32, 1>(blocks * 4, dev);
    let idx = zeros::<i32, 1>(blocks * 2, dev);
    wp::launch_tiled(k_reduce, blocks, (&x, &out, &idx), 64, dev).unwrap();
    let (got, gidx) = (host(&out), host(&idx));
    for b in 0..blocks {
        let t: Vec<f32> = (0..40)
            .map(|e| data.get(b * 40 + e).copied().unwrap_or(0.0))
            .collect();
        let lo = t.iter().copied().fold(f32::INFINITY, f32::min);
        let hi = t.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        assert_eq!(got[b * 4], lo, "min of block {b}");
        assert_eq!(got[b * 4 + 1], hi, "max of block {b}");
        // Multiples of 1/2 below 2^20: the sum is exact in any order.
        assert_eq!(got[b * 4 + 2], t.iter().sum::<f32>(), "sum of block {b}");
        assert_eq!(got[b * 4 + 3], (0..40).map(|e| 1.0 + e as f32).sum::<f32>());
        let first = |v: f32| t.iter().position(|&e| e == v).unwrap() as i32;
        assert_eq!(gidx[b * 2], first(hi), "argmax of block {b}");
        assert_eq!(gidx[b * 2 + 1], first(lo), "argmin of block {b}");
    }
}

#[wp::kernel]
fn k_map(x: Array<f32>, out: Array<f32>) {
    let b = tid();
    let t = tile_load::<32>(x, (b * 32) as i32);
    let s = tile_map(sin, t);
    let m = tile_map(max, t, s);
    let d = -m;
    let i = b * 32 + lane();
    if i < out.len() {
        out[i] = d[lane()];
    }
}

/// `tile_map` of a unary and a binary builtin, unary minus, and each thread reading its own
/// element with `t[lane()]`.
fn tile_map_and_extract(dev: &wp::Device) {
    let n = 50usize;
    let data: Vec<f32> = (0..n).map(|k| k as f32 * 0.3 - 6.0).collect();
    let x = arr(&data, dev);
    let out = zeros::<f32, 1>(n, dev);
    wp::launch_tiled(k_map, n.div_ceil(32), (&x, &out), 32, dev).unwrap();
    let got = host(&out);
    for (k, &v) in data.iter().enumerate() {
        let want = -v.max(v.sin());
        assert_close_f32(got[k], want, math_rel(dev), &format!("element {k}"));
    }
}

#[wp::kernel(block_dim = 32)]
fn k_lanes(x: Array<f32>, out: Array<f32>) {
    let b = tid();
    let l = lane();
    // A per-lane value that lives across tile operations.
    let mut acc = x[b * 32 + l];
    let t0 = tile(acc);
    let s0 = tile_sum(t0);
    acc = acc * 2.0 + s0[0];
    for r in 0..3 {
        let t = tile(acc);
        let m = tile_max(t);
        acc = acc + m[0] * (r as f32);
    }
    out[b * 32 + l] = acc;
}

/// Per-lane values kept between tile operations, a block-level loop with lane code inside,
/// and tiles read by every thread: against the same steps computed on the host.
fn lanes_keep_values_between_tile_operations(dev: &wp::Device) {
    let blocks = 3usize;
    let data: Vec<f32> = (0..blocks * 32).map(|k| (k % 7) as f32 - 3.0).collect();
    let x = arr(&data, dev);
    let out = zeros::<f32, 1>(blocks * 32, dev);
    wp::launch_tiled(k_lanes, blocks, (&x, &out), 32, dev).unwrap();
    let got = host(&out);
    for b in 0..blocks {
        let mut acc: Vec<f32> = data[b * 32..b * 32 + 32].to_vec();
        let s0: f32 = acc.iter().sum();
        acc.iter_mut().for_each(|a| *a = *a * 2.0 + s0);
        for r in 0..3 {
            let m = acc.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            acc.iter_mut().for_each(|a| *a += m * r as f32);
        }
        // Small integers: every step is exact.
        assert_eq!(&got[b * 32..b * 32 + 32], &acc[..], "block {b}");
    }
}

#[wp::kernel]
fn k_lane_return(x: Array<f32>, out: Array<f32>, odd: Array<f32>) {
    let b = tid();
    let t = tile_load::<16>(x, (b * 16) as i32);
    let s = tile_sum(t);
    let i = b * 16 + lane();
    if lane() >= 16 || i >= out.len() {
        return;
    }
    out[i] = t[lane()] / s[0];
    // Even lanes stop here; the odd ones (after the even ones on the CPU) go on.
    if lane() % 2 == 0 {
        return;
    }
    odd[i] = s[0];
}

/// A `return` some threads take after the last tile operation: they stop, the others go on.
fn lane_returns_after_the_last_tile_operation(dev: &wp::Device) {
    let n = 40usize;
    let data: Vec<f32> = (0..n).map(|k| (k % 5 + 1) as f32).collect();
    let x = arr(&data, dev);
    let out = wp::Array::<f32, 1>::full(n, -1.0, dev).unwrap();
    let odd = wp::Array::<f32, 1>::full(n, -1.0, dev).unwrap();
    wp::launch_tiled(k_lane_return, n.div_ceil(16), (&x, &out, &odd), 64, dev).unwrap();
    let (got, godd) = (host(&out), host(&odd));
    for b in 0..n.div_ceil(16) {
        let s: f32 = (b * 16..(b * 16 + 16).min(n)).map(|i| data[i]).sum();
        for i in b * 16..(b * 16 + 16).min(n) {
            assert_eq!(got[i], data[i] / s, "element {i}");
            let want = if i % 2 == 1 { s } else { -1.0 };
            assert_eq!(godd[i], want, "odd lanes' element {i}");
        }
    }
}

/// A tiled kernel needs `launch_tiled`, and an ordinary one `launch`: the other is an error
/// that names the kernel and the launch to use.
fn tiled_kernel_launched_plainly_is_an_error(dev: &wp::Device) {
    let x = arr(&[1.0f32; 64], dev);
    let out = zeros::<f32, 1>(1, dev);
    let e = wp::launch(k_block_sum, 1, (&x, &out, 64usize), dev).unwrap_err();
    let msg = crate::chain(&e);
    assert!(
        msg.contains("k_block_sum") && msg.contains("launch_tiled"),
        "{msg}"
    );
    let e = wp::launch_tiled(k_plain, 1, (&out,), 32, dev).unwrap_err();
    let msg = crate::chain(&e);
    assert!(msg.contains("k_plain"), "{msg}");
}

#[wp::kernel]
fn k_plain(out: Array<f32>) {
    out[tid()] = 1.0;
}

/// `#[kernel(block_dim = 64)]` fixes the width of `tile(x)`: another block size, 0, or more
/// than 1024 is an error before anything runs.
fn width_must_match_block_dim(dev: &wp::Device) {
    let x = arr(&[1.0f32; 128], dev);
    let out = zeros::<f32, 1>(2, dev);
    for bd in [0, 32, 128, 2048] {
        let e = wp::launch_tiled(k_block_sum, 2, (&x, &out, 128usize), bd, dev).unwrap_err();
        let msg = crate::chain(&e);
        assert!(
            msg.contains("k_block_sum") && msg.contains(&bd.to_string()),
            "{msg}"
        );
    }
    assert_eq!(host(&out), vec![0.0, 0.0], "nothing ran");
}

#[wp::kernel]
fn k_extract_oob(out: Array<f32>, k: i32) {
    let t = tile_arange::<f32, 8>();
    out[0] = t[k];
}

/// `t[i]` outside the tile is a fault naming the index and the tile's shape.
fn tile_index_out_of_range_faults(dev: &wp::Device) {
    let out = zeros::<f32, 1>(1, dev);
    wp::launch_tiled(k_extract_oob, 1, (&out, 7), 8, dev).unwrap();
    assert_eq!(host(&out), vec![7.0]);
    let e = wp::launch_tiled(k_extract_oob, 1, (&out, 8), 8, dev).unwrap_err();
    let msg = crate::chain(&e);
    assert!(msg.contains("k_extract_oob") && msg.contains('8'), "{msg}");
    let wp::Error::Fault(f) = e else {
        panic!("expected a fault, got {msg}")
    };
    assert!(
        matches!(
            f.kind,
            wp::FaultKind::TileIndex {
                index: [8, ..],
                shape: [8, ..],
                rank: 1
            }
        ),
        "{:?}",
        f.kind
    );
}

#[wp::kernel]
fn k_shapes(a: Array<f32, 2>, row: Array<f32>, t_out: Array<f32, 2>, b_out: Array<f32, 2>) {
    let t = tile_load::<8, 4>(a, (0, 0));
    let tt = tile_transpose(t);
    tile_store(t_out, tt, (0, 0));
    let r = tile_load::<4>(row, 0);
    let rb = tile_broadcast::<8, 4>(r);
    let one = tile_sum(r);
    let ob: Tile<f32, 8, 4> = tile_broadcast(one);
    tile_store(b_out, t + rb * 10.0 + ob, (0, 0));
}

/// `tile_transpose`, and `tile_broadcast` of a row (`(4,)` to `(8, 4)`) and of one element.
fn transpose_and_broadcast(dev: &wp::Device) {
    let ad: Vec<f32> = (0..32).map(|k| k as f32).collect();
    let rd = [1.0f32, 2.0, 3.0, 4.0];
    let a = wp::Array::from_slice_shape(&ad, (8, 4), dev).unwrap();
    let row = arr(&rd, dev);
    let t_out = zeros::<f32, 2>((4, 8), dev);
    let b_out = zeros::<f32, 2>((8, 4), dev);
    wp::launch_tiled(k_shapes, 1, (&a, &row, &t_out, &b_out), 32, dev).unwrap();
    let (tt, bb) = (host(&t_out), host(&b_out));
    for i in 0..8 {
        for j in 0..4 {
            assert_eq!(tt[j * 8 + i], ad[i * 4 + j], "transpose ({j}, {i})");
            assert_eq!(
                bb[i * 4 + j],
                ad[i * 4 + j] + rd[j] * 10.0 + 10.0,
                "({i}, {j})"
            );
        }
    }
}

#[wp::kernel]
fn k_reduce_fns(x: Array<f32>, ints: Array<i32>, out: Array<f32>, iout: Array<i32>) {
    let t = tile_load::<50>(x, 0);
    let m = tile_reduce(max, t);
    let s = tile_reduce(add, t);
    let s2 = tile_sum(t);
    let it = tile_load::<6>(ints, 0);
    let p = tile_reduce(mul, it);
    let q = tile_map(add, it, it);
    if lane() == 0 {
        out[0] = m[0];
        out[1] = s[0];
        out[2] = s2[0];
        iout[0] = p[0];
        iout[1] = q[5];
    }
}

/// `tile_reduce` with a builtin (`max`) and with Warp's operator names (`add` gives
/// `tile_sum`'s bits; `mul` on integers wraps), and `tile_map(add, a, b)`.
fn reduce_with_functions(dev: &wp::Device) {
    // Order-sensitive floats: a large value then small ones.
    let xd: Vec<f32> = (0..50)
        .map(|k| if k == 0 { 1e8 } else { 0.3 + k as f32 * 0.01 })
        .collect();
    let ints = [3i32, -7, 11, 100000, 5, 9];
    let (x, xi) = (arr(&xd, dev), arr(&ints, dev));
    let out = zeros::<f32, 1>(3, dev);
    let iout = zeros::<i32, 1>(2, dev);
    for bd in [1, 32, 64] {
        wp::launch_tiled(k_reduce_fns, 1, (&x, &xi, &out, &iout), bd, dev).unwrap();
        let (o, io) = (host(&out), host(&iout));
        assert_eq!(o[0], 1e8, "max at block_dim {bd}");
        assert_eq!(
            o[1].to_bits(),
            o[2].to_bits(),
            "add == tile_sum at block_dim {bd}"
        );
        let prod = ints.iter().fold(1i32, |p, &v| p.wrapping_mul(v));
        assert_eq!(io[0], prod, "wrapping product at block_dim {bd}");
        assert_eq!(io[1], 18);
    }
}

#[wp::kernel]
fn k_atomic_tiles(acc: Array<i32, 2>, facc: Array<f32>, old_sum: Array<i32>) {
    let b = tid();
    let ones: Tile<i32, 4, 4> = tile_ones();
    // Blocks overlap: block b adds at (b % 3, 1); part of each tile falls outside the array.
    let old = tile_atomic_add(acc, ones, ((b % 3) as i32, 1));
    let f = tile_arange::<f32, 8>();
    let fold = tile_atomic_add(facc, f, -2);
    let s = tile_sum(old);
    let fs = tile_sum(fold);
    if lane() == 0 {
        atomic_add(old_sum, 0, s[0]);
        atomic_add(old_sum, 1, fs[0] as i32);
    }
}

/// `tile_atomic_add` from many blocks into overlapping parts of an array (integers and
/// integer-valued floats: exact in any order); parts outside the array are skipped.
fn atomic_add_of_tiles(dev: &wp::Device) {
    let blocks = 30usize;
    let acc = zeros::<i32, 2>((5, 4), dev);
    let facc = zeros::<f32, 1>(5, dev);
    let old_sum = zeros::<i32, 1>(2, dev);
    wp::launch_tiled(k_atomic_tiles, blocks, (&acc, &facc, &old_sum), 64, dev).unwrap();
    let got = host(&acc);
    let mut want = vec![0i32; 20];
    for b in 0..blocks {
        for i in 0..4 {
            for j in 0..4 {
                let (r, c) = (b % 3 + i, 1 + j);
                if r < 5 && c < 4 {
                    want[r * 4 + c] += 1;
                }
            }
        }
    }
    assert_eq!(got, want);
    // Element e of the float tile lands at e - 2: elements 2..7 at 0..5.
    let fwant: Vec<f32> = (0..5).map(|c| (c + 2) as f32 * blocks as f32).collect();
    assert_eq!(host(&facc), fwant);
    // The old values a block saw sum to at most what was there: their total over the blocks is
    // the sum of 0 + 1 + .. + (n - 1) over each element's n adds.
    let olds = host(&old_sum);
    let tri = |n: i32| n * (n - 1) / 2;
    assert_eq!(olds[0], want.iter().map(|&n| tri(n)).sum::<i32>());
    let ftri: i32 = (0..5).map(|c| (c + 2) * tri(blocks as i32)).sum();
    assert_eq!(olds[1], ftri);
}

#[wp::kernel]
fn k_scans(x: Array<f32>, ix: Array<i32>, out: Array<f32, 2>, iout: Array<i32, 2>) {
    let t = tile_load::<100>(x, 0);
    tile_store(
        out,
        tile_broadcast::<1, 100>(tile_scan_inclusive(t)),
        (0, 0),
    );
    tile_store(
        out,
        tile_broadcast::<1, 100>(tile_scan_max_inclusive(t)),
        (1, 0),
    );
    tile_store(
        out,
        tile_broadcast::<1, 100>(tile_scan_min_inclusive(t)),
        (2, 0),
    );
    let it = tile_load::<100>(ix, 0);
    tile_store(
        iout,
        tile_broadcast::<1, 100>(tile_scan_exclusive(it)),
        (0, 0),
    );
    tile_store(
        iout,
        tile_broadcast::<1, 100>(tile_scan_inclusive(it)),
        (1, 0),
    );
}

/// Inclusive and exclusive scans (integers: exact prefix sums for every block size), running
/// maxima and minima, and float sums in the documented chunked order: a large value then ones,
/// where the order decides the bits.
fn scans(dev: &wp::Device) {
    let xd: Vec<f32> = (0..100)
        .map(|k| {
            if k == 0 {
                1e8
            } else {
                ((k * 37 % 11) as f32) - 5.0
            }
        })
        .collect();
    let id: Vec<i32> = (0..100).map(|k| (k * 7919 % 201) - 100).collect();
    let (x, ix) = (arr(&xd, dev), arr(&id, dev));
    let out = zeros::<f32, 2>((3, 100), dev);
    let iout = zeros::<i32, 2>((2, 100), dev);
    for bd in [1, 7, 32, 128] {
        wp::launch_tiled(k_scans, 1, (&x, &ix, &out, &iout), bd, dev).unwrap();
        let (o, io) = (host(&out), host(&iout));
        // The documented order on the host: chunks of ceil(100 / bd), their running values,
        // then the prefixes of their totals in lane order.
        let c = 100usize.div_ceil(bd);
        let mut want = vec![0f32; 100];
        let mut prefix: Option<f32> = None;
        for start in (0..100).step_by(c) {
            let mut r = xd[start];
            for e in start..(start + c).min(100) {
                if e > start {
                    r += xd[e];
                }
                want[e] = prefix.map_or(r, |p| p + r);
            }
            prefix = Some(prefix.map_or(r, |p| p + r));
        }
        assert_eq!(&o[..100], &want[..], "sum scan at block_dim {bd}");
        let (mut hi, mut lo) = (f32::NEG_INFINITY, f32::INFINITY);
        for e in 0..100 {
            hi = hi.max(xd[e]);
            lo = lo.min(xd[e]);
            assert_eq!(o[100 + e], hi, "max scan {e} at block_dim {bd}");
            assert_eq!(o[200 + e], lo, "min scan {e} at block_dim {bd}");
        }
        let mut acc = 0i32;
        for e in 0..100 {
            assert_eq!(io[e], acc, "exclusive {e} at block_dim {bd}");
            acc += id[e];
            assert_eq!(io[100 + e], acc, "inclusive {e} at block_dim {bd}");
        }
    }
}

/// 64 KiB of tiles: above the 48 KiB a CUDA kernel gets without opting in.
#[wp::kernel]
fn k_big_tile(a: Array<f32, 2>, b: Array<f32, 2>) {
    let t = tile_load::<128, 128>(a, (0, 0));
    tile_store(b, t, (0, 0));
}

/// 256 KiB of tiles: more shared memory than any GPU has per block (227 KiB on an H100).
#[wp::kernel]
fn k_huge_tile(a: Array<f32, 2>, b: Array<f32, 2>) {
    let t = tile_load::<256, 256>(a, (0, 0));
    tile_store(b, t, (0, 0));
}

/// A kernel with more than 48 KiB of tiles runs (the launch opts in); one with more than the
/// device allows is an error at load naming the kernel and the sizes, not a failed launch. The
/// CPU runs both (its tiles are stack values on the tile pool's big stacks).
fn shared_memory_beyond_48k_and_beyond_the_device(dev: &wp::Device) {
    let data: Vec<f32> = (0..256 * 256).map(|k| k as f32).collect();
    let a = wp::Array::from_slice_shape(&data, (256, 256), dev).unwrap();
    let b = zeros::<f32, 2>((256, 256), dev);
    wp::launch_tiled(k_big_tile, 1, (&a, &b), 256, dev).unwrap();
    let got = host(&b);
    for i in 0..256 {
        for j in 0..256 {
            let want = if i < 128 && j < 128 {
                data[i * 256 + j]
            } else {
                0.0
            };
            assert_eq!(got[i * 256 + j], want, "({i}, {j})");
        }
    }
    let r = wp::launch_tiled(k_huge_tile, 1, (&a, &b), 256, dev);
    if dev.is_cpu() {
        r.unwrap();
        assert_eq!(host(&b), data);
    } else {
        let e = r.unwrap_err();
        let msg = crate::chain(&e);
        assert!(msg.contains("k_huge_tile"), "{msg}");
        // The tiles' bytes, plus whatever static shared memory the kernel has.
        let wp::Error::SharedMemory {
            requested,
            available,
            ..
        } = e
        else {
            panic!("expected a shared-memory error, got {msg}")
        };
        assert!(requested >= 256 * 256 * 4 && requested > available, "{msg}");
    }
}

#[wp::kernel]
fn k_copy_block(a: Array<f32>, b: Array<f32>) {
    let i = tid();
    let t = tile_load::<4>(a, (i * 4) as i32);
    tile_store(b, t, (i * 4) as i32);
}

/// A GPU runs one CUDA block per block of a tiled launch: more than `i32::MAX` blocks is an
/// error naming the kernel and the count, before anything runs (the CPU has no such limit, and
/// 2^31 blocks would take it a while: checked on GPUs only).
fn more_blocks_than_a_gpu_grid_holds(dev: &wp::Device) {
    if dev.is_cpu() {
        return;
    }
    let a = zeros::<f32, 1>(8, dev);
    let b = zeros::<f32, 1>(8, dev);
    let e = wp::launch_tiled(k_copy_block, 1usize << 31, (&a, &b), 32, dev).unwrap_err();
    let msg = e.to_string();
    assert!(
        matches!(e, wp::Error::InvalidDim { .. })
            && msg.contains("k_copy_block")
            && msg.contains("2147483648"),
        "{msg}"
    );
    // A launch within the limit runs.
    wp::launch_tiled(k_copy_block, 2, (&a, &b), 32, dev).unwrap();
}

#[test]
#[ignore = "prints the CUDA template"]
fn dump_cuda() {
    println!("{}", wp::kernel_info(k_gemm).cuda);
    println!("{}", wp::kernel_info(k_lanes).cuda);
}

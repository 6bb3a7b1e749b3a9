//! Windows of tiles: `tile_view` (a copy of a sub-tile), `tile_assign` and the in-place forms
//! (`tile_add_inplace`, `tile_sub_inplace`, the bitwise ones), on every backend, against the
//! same computation on the host, with a run-time offset outside the tile as a fault; and
//! backward through them, by `wp::gradcheck` in f64.
//!
//! Exactness: the windows move elements and add or subtract one pair per element, so every
//! comparison is exact. Gradients: `GradcheckOptions::for_type::<f64>()` and a 1e-6 relative
//! bound on the worst element (`tile_grad::check`); the functions are polynomial of degree 2,
//! so central differences are exact up to rounding.

use crate::tile_grad::{check, values};
use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    views_copy_windows,
    a_view_outside_the_tile_faults,
    assign_and_inplace_forms,
    bitwise_inplace_forms,
    an_assign_outside_the_tile_faults,
    backward_through_views,
    backward_through_assign_and_adds,
);

#[wp::kernel]
fn k_views(a: Array<f32, 2>, out: Array<f32, 2>, row: Array<f32>, i: i32, j: i32) {
    let t: Tile<f32, 6, 8> = tile_load(a, (0, 0));
    // Shape from the turbofish, from Warp's positional shape and from the annotation.
    let v = tile_view::<2, 3>(t, (i, j));
    let w = tile_view(t, (1, 2), (3, 4));
    let u: Tile<f32, 4, 8> = tile_view(t, (2, 0));
    // Warp's view without a shape: row `i` of the 2-D tile.
    let r = tile_view(t, i);
    tile_store(out, v, (0, 0));
    tile_store(out, w, (2, 0));
    tile_store(out, u, (5, 0));
    tile_store(row, r, 0);
}

/// A view is the window's elements at run-time and constant offsets, and a row view is the
/// row; at block sizes 1, 5 and 64.
fn views_copy_windows(dev: &wp::Device) {
    let (m, n) = (6usize, 8usize);
    let data: Vec<f32> = (0..m * n).map(|k| k as f32).collect();
    let a = wp::Array::from_slice_shape(&data, (m, n), dev).unwrap();
    let at = |r: usize, c: usize| data[r * n + c];
    for bd in [1, 5, 64] {
        let out = wp::Array::<f32, 2>::full((9, 8), -1.0, dev).unwrap();
        let row = zeros::<f32, 1>(8, dev);
        wp::launch_tiled(k_views, 1, (&a, &out, &row, 3, 5), bd, dev).unwrap();
        let got = host(&out);
        let g = |r: usize, c: usize| got[r * 8 + c];
        for r in 0..2 {
            for c in 0..3 {
                assert_eq!(g(r, c), at(3 + r, 5 + c), "view ({r}, {c}), block_dim {bd}");
            }
            assert_eq!(g(r, 3), -1.0, "outside the stored view");
        }
        for r in 0..3 {
            for c in 0..4 {
                assert_eq!(
                    g(2 + r, c),
                    at(1 + r, 2 + c),
                    "positional shape, block_dim {bd}"
                );
            }
        }
        for r in 0..4 {
            for c in 0..8 {
                assert_eq!(g(5 + r, c), at(2 + r, c), "annotated shape, block_dim {bd}");
            }
        }
        assert_eq!(host(&row), data[3 * n..4 * n].to_vec(), "row view");
    }
}

/// A window reaching past the tile at run time is a fault naming the first coordinate outside
/// and the tile's shape: nothing outside the tile is read.
fn a_view_outside_the_tile_faults(dev: &wp::Device) {
    let a = wp::Array::<f32, 2>::zeros((6, 8), dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((9, 8), dev).unwrap();
    let row = zeros::<f32, 1>(8, dev);
    // (4, 5): rows 4 and 5 fit, columns 5..8 fit; (5, 5): row 6 is outside.
    wp::launch_tiled(k_views, 1, (&a, &out, &row, 4, 5), 32, dev).unwrap();
    let e = wp::launch_tiled(k_views, 1, (&a, &out, &row, 5, 5), 32, dev).unwrap_err();
    let msg = crate::chain(&e);
    let wp::Error::Fault(f) = e else {
        panic!("expected a fault, got {msg}")
    };
    assert!(
        matches!(
            f.kind,
            wp::FaultKind::TileIndex {
                index: [6, 5, ..],
                shape: [6, 8, ..],
                rank: 2
            }
        ),
        "{:?}",
        f.kind
    );
    // A negative offset is outside too.
    let e = wp::launch_tiled(k_views, 1, (&a, &out, &row, 0, -1), 32, dev).unwrap_err();
    assert!(matches!(e, wp::Error::Fault(_)), "{}", crate::chain(&e));
}

#[wp::kernel]
fn k_windows(a: Array<f32, 2>, s: Array<f32, 2>, out: Array<f32, 2>, i: i32, j: i32) {
    let src: Tile<f32, 2, 3> = tile_load(s, (0, 0));
    let mut d: Tile<f32, 4, 5> = tile_load(a, (0, 0));
    tile_assign(&mut d, src, (i, j));
    let mut e: Tile<f32, 4, 5> = tile_load(a, (0, 0));
    tile_add_inplace(&mut e, src, (1, 2));
    tile_sub_inplace(&mut e, src, (i, j));
    // Without offsets: at the origin; a source of the destination's shape is Warp's `a += b`.
    let mut f: Tile<f32, 4, 5> = tile_load(a, (0, 0));
    tile_assign(&mut f, src);
    tile_add_inplace(&mut f, e);
    tile_store(out, d, (0, 0));
    tile_store(out, e, (4, 0));
    tile_store(out, f, (8, 0));
}

/// `tile_assign`, `tile_add_inplace` and `tile_sub_inplace` change exactly their window.
fn assign_and_inplace_forms(dev: &wp::Device) {
    let a0: Vec<f32> = (0..20).map(|k| k as f32 * 0.5).collect();
    let s0: Vec<f32> = (0..6).map(|k| 100.0 + k as f32).collect();
    let a = wp::Array::from_slice_shape(&a0, (4, 5), dev).unwrap();
    let s = wp::Array::from_slice_shape(&s0, (2, 3), dev).unwrap();
    let (i, j) = (2usize, 1usize);
    let window = |r: usize, c: usize, oi: usize, oj: usize| {
        (oi..oi + 2).contains(&r) && (oj..oj + 3).contains(&c)
    };
    let mut d = a0.clone();
    let mut e = a0.clone();
    let mut f = a0.clone();
    for r in 0..4 {
        for c in 0..5 {
            let k = r * 5 + c;
            if window(r, c, i, j) {
                d[k] = s0[(r - i) * 3 + c - j];
            }
            if window(r, c, 1, 2) {
                e[k] += s0[(r - 1) * 3 + c - 2];
            }
            if window(r, c, i, j) {
                e[k] -= s0[(r - i) * 3 + c - j];
            }
            if window(r, c, 0, 0) {
                f[k] = s0[r * 3 + c];
            }
        }
    }
    for k in 0..20 {
        f[k] += e[k];
    }
    for bd in [1, 3, 64] {
        let out = wp::Array::<f32, 2>::zeros((12, 5), dev).unwrap();
        wp::launch_tiled(k_windows, 1, (&a, &s, &out, i as i32, j as i32), bd, dev).unwrap();
        let got = host(&out);
        assert_eq!(got[..20], d[..], "tile_assign, block_dim {bd}");
        assert_eq!(got[20..40], e[..], "add and sub, block_dim {bd}");
        assert_eq!(got[40..], f[..], "at the origin, block_dim {bd}");
    }
}

#[wp::kernel]
fn k_tile_bits(a: Array<i32>, s: Array<i32>, out: Array<i32>) {
    let src = tile_load::<3>(s, 0);
    let mut x = tile_load::<8>(a, 0);
    let mut y = x;
    let mut z = x;
    tile_bit_and_inplace(&mut x, src, 1);
    tile_bit_or_inplace(&mut y, src, 5);
    tile_bit_xor_inplace(&mut z, src, 0);
    tile_store(out, x, 0);
    tile_store(out, y, 8);
    tile_store(out, z, 16);
}

/// The bitwise in-place forms of integer tiles.
fn bitwise_inplace_forms(dev: &wp::Device) {
    let a0: Vec<i32> = (0..8).map(|k| k * 37 - 100).collect();
    let s0 = [0x0f, -1, 0x55];
    let a = arr(&a0, dev);
    let s = arr(&s0, dev);
    let out = zeros::<i32, 1>(24, dev);
    wp::launch_tiled(k_tile_bits, 1, (&a, &s, &out), 4, dev).unwrap();
    let (mut x, mut y, mut z) = (a0.clone(), a0.clone(), a0.clone());
    for k in 0..3 {
        x[1 + k] &= s0[k];
        y[5 + k] |= s0[k];
        z[k] ^= s0[k];
    }
    let want: Vec<i32> = x.into_iter().chain(y).chain(z).collect();
    assert_eq!(host(&out), want);
}

/// A `tile_assign` whose window reaches past the destination faults, and writes nothing.
fn an_assign_outside_the_tile_faults(dev: &wp::Device) {
    let a = wp::Array::<f32, 2>::zeros((4, 5), dev).unwrap();
    let s = wp::Array::<f32, 2>::zeros((2, 3), dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((12, 5), dev).unwrap();
    let e = wp::launch_tiled(k_windows, 1, (&a, &s, &out, 1, 3), 16, dev).unwrap_err();
    let msg = crate::chain(&e);
    let wp::Error::Fault(f) = e else {
        panic!("expected a fault, got {msg}")
    };
    assert!(
        matches!(
            f.kind,
            wp::FaultKind::TileIndex {
                index: [1, 5, ..],
                shape: [4, 5, ..],
                rank: 2
            }
        ),
        "{:?}",
        f.kind
    );
}

const VR: usize = 4;
const VC: usize = 6;

#[wp::kernel]
fn k_view_grad(a: Array<f64, 2>, out: Array<f64>) {
    let b = tid();
    let t: Tile<f64, VR, VC> = tile_load(a, ((b * VR) as i32, 0));
    // Two overlapping windows (their adjoints add up where they meet) and a row.
    let v = tile_view::<2, 3>(t, (1, 2));
    let w = tile_view::<2, 3>(t, (0, (b % 2) as i32 + 1));
    let r = tile_view(t, 3);
    let o = (b * 12) as i32;
    tile_store(out, tile_reshape::<6>(v * w), o);
    tile_store(out, r * r, o + 6);
}

/// Backward through views: the adjoint of each view reaches the window it came from.
fn backward_through_views(dev: &wp::Device) {
    let a = arr(&values(2 * VR * VC, 3), dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(24, dev).with_grad().unwrap();
    let a2 = a.reshape((2 * VR, VC)).unwrap();
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_view_grad, 2, (&a2, &out), bd, dev);
        check(&format!("views, block_dim {bd}"), run, &[&a], &out);
    }
}

#[wp::kernel]
fn k_assign_grad(a: Array<f64, 2>, s: Array<f64, 2>, out: Array<f64, 2>) {
    let b = tid();
    let src: Tile<f64, 2, 3> = tile_load(s, ((b * 2) as i32, 0));
    let mut d: Tile<f64, VR, VC> = tile_load(a, ((b * VR) as i32, 0));
    // `d`'s value before the writes reaches the result too (its history is kept).
    let d0 = d * d;
    tile_assign(&mut d, src * src, (1, (b * 2) as i32));
    tile_add_inplace(&mut d, src, (2, 3));
    tile_sub_inplace(&mut d, src * 2.0, (0, 1));
    tile_store(out, d * d + d0, ((b * VR) as i32, 0));
}

/// Backward through `tile_assign` (the window's adjoint goes to the source, and none to the
/// replaced elements) and the in-place add and sub (passed through, `-` for the sub).
fn backward_through_assign_and_adds(dev: &wp::Device) {
    let a = arr(&values(2 * VR * VC, 4), dev).with_grad().unwrap();
    let s = arr(&values(12, 5), dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(2 * VR * VC, dev).with_grad().unwrap();
    let (a2, s2, o2) = (
        a.reshape((2 * VR, VC)).unwrap(),
        s.reshape((4, 3)).unwrap(),
        out.reshape((2 * VR, VC)).unwrap(),
    );
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_assign_grad, 2, (&a2, &s2, &o2), bd, dev);
        check(
            &format!("assign and adds, block_dim {bd}"),
            run,
            &[&a, &s],
            &out,
        );
    }
}

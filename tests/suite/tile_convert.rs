//! The tile conversions on every backend: `tile_full`, `tile_astype`, `tile_reshape`,
//! `tile_squeeze` and `tile_diag_add`, against the same computation on the host. Exact: they
//! move elements, convert them with `as`'s meaning, or add one number to each diagonal element
//! (one IEEE addition), so every backend must give the host's bits.

// The code the kernel macro generates for a tiled kernel's CPU block rounds up by hand, and
// clippy reports it at the kernel (as in tiles.rs).
#![allow(clippy::manual_div_ceil)]

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    conversions,
    reshape_squeeze_diag_add_gradients,
    astype_gradients,
    full_gradients,
);

#[wp::kernel]
#[allow(clippy::too_many_arguments)]
fn k_convert(
    x: Array<f32, 2>,
    d: Array<f32>,
    full: Array<f32, 2>,
    ints: Array<i32, 2>,
    wide: Array<f64, 2>,
    flat: Array<f32>,
    re: Array<f32, 2>,
    sq: Array<f32>,
    diag: Array<f32, 2>,
    s: f32,
) {
    let t = tile_load::<4, 6>(x, (0, 0));
    let f = tile_full::<f32, 4, 6>(s);
    tile_store(full, f, (0, 0));
    tile_store(ints, tile_astype::<i32>(t), (0, 0));
    let w: Tile<f64, 4, 6> = tile_astype(t);
    tile_store(wide, w, (0, 0));
    let fl: Tile<f32, 24> = tile_reshape(t);
    tile_store(flat, fl, 0);
    let r = tile_reshape::<6, 4>(fl);
    tile_store(re, r, (0, 0));
    let row = tile_load::<1, 6>(x, (1, 0));
    let one_row = tile_squeeze(row);
    tile_store(sq, one_row, 0);
    let square = tile_load::<4, 4>(x, (0, 0));
    let dv = tile_load::<4>(d, 0);
    tile_store(diag, tile_diag_add(square, dv), (0, 0));
}

/// Every conversion at several block sizes, on values that test `as`'s meaning (NaN to 0,
/// saturation at the integer range, truncation toward zero) and `-0.0` off the diagonal.
fn conversions(dev: &wp::Device) {
    let mut xd: Vec<f32> = (0..24).map(|k| k as f32 * 0.75 - 7.3).collect();
    xd[1] = f32::NAN;
    xd[2] = 3e9;
    xd[3] = -3e9;
    xd[7] = -0.0; // (1, 1): on the diagonal
    xd[8] = -0.0; // (1, 2): off it
    let dd = [1.5f32, -2.0, 0.25, 1e-3];
    let x = wp::Array::from_slice_shape(&xd, (4, 6), dev).unwrap();
    let d = arr(&dd, dev);
    let full = zeros::<f32, 2>((4, 6), dev);
    let ints = zeros::<i32, 2>((4, 6), dev);
    let wide = zeros::<f64, 2>((4, 6), dev);
    let flat = zeros::<f32, 1>(24, dev);
    let re = zeros::<f32, 2>((6, 4), dev);
    let sq = zeros::<f32, 1>(6, dev);
    let diag = zeros::<f32, 2>((4, 4), dev);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    for bd in [1, 5, 32, 64] {
        wp::launch_tiled(
            k_convert,
            1,
            (&x, &d, &full, &ints, &wide, &flat, &re, &sq, &diag, 2.5f32),
            bd,
            dev,
        )
        .unwrap();
        assert_eq!(host(&full), vec![2.5f32; 24], "tile_full at block_dim {bd}");
        let want_i: Vec<i32> = xd.iter().map(|&v| v as i32).collect();
        assert_eq!(host(&ints), want_i, "tile_astype::<i32> at block_dim {bd}");
        let got_w = host(&wide);
        for (k, (&g, &v)) in got_w.iter().zip(&xd).enumerate() {
            assert_eq!(
                g.to_bits(),
                (v as f64).to_bits(),
                "f64 {k} at block_dim {bd}"
            );
        }
        assert_eq!(
            bits(&host(&flat)),
            bits(&xd),
            "reshape to 24 at block_dim {bd}"
        );
        assert_eq!(
            bits(&host(&re)),
            bits(&xd),
            "reshape to 6 x 4 at block_dim {bd}"
        );
        assert_eq!(
            bits(&host(&sq)),
            bits(&xd[6..12]),
            "squeeze at block_dim {bd}"
        );
        let want_d: Vec<f32> = (0..16)
            .map(|k| {
                let (i, j) = (k / 4, k % 4);
                let a = xd[i * 6 + j];
                if i == j {
                    a + dd[i]
                } else {
                    a
                }
            })
            .collect();
        assert_eq!(
            bits(&host(&diag)),
            bits(&want_d),
            "diag_add at block_dim {bd}"
        );
    }
}

#[wp::kernel]
fn k_convert_grad(a: Array<f64>, dg: Array<f64>, out: Array<f64, 2>) {
    let t = tile_load::<16>(a, 0);
    let sq: Tile<f64, 4, 4> = tile_reshape(t);
    let v = tile_load::<4>(dg, 0);
    let col = tile_reshape::<4, 1>(v);
    let d = v * tile_squeeze(col);
    tile_store(out, tile_diag_add(sq * sq, d), (0, 0));
}

/// `gradcheck` (f64 central differences, 1e-6 relative: see tile_grad.rs) through a reshape, a
/// squeeze of a reshape, and `tile_diag_add` with both operands differentiable, at several
/// block sizes.
fn reshape_squeeze_diag_add_gradients(dev: &wp::Device) {
    let a = arr(&crate::tile_grad::values(16, 3), dev)
        .with_grad()
        .unwrap();
    let dg = arr(&crate::tile_grad::values(4, 5), dev)
        .with_grad()
        .unwrap();
    let out = zeros::<f64, 1>(16, dev).with_grad().unwrap();
    let o2 = out.reshape((4, 4)).unwrap();
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_convert_grad, 1, (&a, &dg, &o2), bd, dev);
        crate::tile_grad::check(
            &format!("reshape, squeeze, diag_add at block_dim {bd}"),
            run,
            &[&a, &dg],
            &out,
        );
    }
}

#[wp::kernel]
fn k_astype_grad(a: Array<f64>, out: Array<f64>, ints: Array<f64>) {
    let t = tile_load::<8>(a, 0);
    tile_store(out, tile_astype::<f64>(tile_astype::<f32>(t)), 0);
    // Through an integer: no gradient (Warp's rule, as `x as i32` in any kernel).
    tile_store(ints, tile_astype::<f64>(tile_astype::<i32>(t * 4.0)), 0);
}

/// Backward through `tile_astype`: between floats the seed converted back (f64 to f32 and
/// back: each element's seed rounded to f32, exactly as `as` would); through an integer,
/// nothing. Exact: one rounding of the seed, computed here the same way.
fn astype_gradients(dev: &wp::Device) {
    let a = arr(&crate::tile_grad::values(8, 3), dev)
        .with_grad()
        .unwrap();
    let out = zeros::<f64, 1>(8, dev).with_grad().unwrap();
    let ints = zeros::<f64, 1>(8, dev).with_grad().unwrap();
    let seed: Vec<f64> = (0..8).map(|k| 0.1 + k as f64 / 3.0).collect();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_astype_grad, 1, (&a, &out, &ints), 8, dev).unwrap();
    }
    out.grad().unwrap().copy_from(&arr(&seed, dev)).unwrap();
    ints.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let want: Vec<f64> = seed.iter().map(|g| *g as f32 as f64).collect();
    assert_eq!(host(&a.grad().unwrap()), want);
}

#[wp::kernel]
fn k_full_grad(a: Array<f64>, w: Array<f64>, out: Array<f64, 2>) {
    let t = tile_load::<12>(a, 0);
    let s = w[0] * 2.0 + w[1];
    let f = tile_full::<f64, 3, 4>(s);
    let g = f * tile_reshape::<3, 4>(t) + tile_full::<f64, 3, 4>(1.5);
    tile_store(out, g, (0, 0));
}

/// `gradcheck` (f64 central differences, 1e-6 relative: see tile_grad.rs) through `tile_full`
/// of a value every lane computed (its adjoint: the sum of the seed, added once for the block)
/// and of a constant, at several block sizes.
fn full_gradients(dev: &wp::Device) {
    let a = arr(&crate::tile_grad::values(12, 4), dev)
        .with_grad()
        .unwrap();
    let w = arr(&[0.7f64, -0.4], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(12, dev).with_grad().unwrap();
    let o2 = out.reshape((3, 4)).unwrap();
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_full_grad, 1, (&a, &w, &o2), bd, dev);
        crate::tile_grad::check(
            &format!("tile_full at block_dim {bd}"),
            run,
            &[&a, &w],
            &out,
        );
    }
}

/// The CUDA adjoint the GPU compiles (checked here without one) calls the two new adjoints,
/// and nothing refused it.
#[test]
fn cuda_adjoint_calls_the_copy_rules() {
    let info = wp::kernel_info(k_convert_grad);
    assert!(
        info.adjoint_error.is_none() && info.cuda_adjoint_error.is_none(),
        "{:?} {:?}",
        info.adjoint_error,
        info.cuda_adjoint_error
    );
    let adj = info.cuda_adjoint;
    assert!(adj.matches("wp::adj_tile_reshape(").count() == 3, "{adj}");
    assert!(adj.contains("wp::adj_tile_diag_add("), "{adj}");
}

/// The CUDA printer translates the conversions' adjoints (NVRTC compiles them only on a GPU:
/// `full_gradients` and `astype_gradients` there).
#[test]
fn cuda_adjoint_calls_the_conversion_rules() {
    let info = wp::kernel_info(k_full_grad);
    assert!(
        info.cuda_adjoint_error.is_none(),
        "{:?}",
        info.cuda_adjoint_error
    );
    assert!(
        info.cuda_adjoint.contains("wp::adj_tile_full("),
        "{}",
        info.cuda_adjoint
    );
    let info = wp::kernel_info(k_astype_grad);
    assert!(
        info.cuda_adjoint_error.is_none(),
        "{:?}",
        info.cuda_adjoint_error
    );
    assert!(
        info.cuda_adjoint.contains("wp::adj_tile_astype("),
        "{}",
        info.cuda_adjoint
    );
}

//! Backward through the tile linear algebra (`tile_lower_solve`, `tile_upper_solve`,
//! `tile_cholesky_solve`, `tile_cholesky`) and the scans: `wp::gradcheck` against central
//! differences in f64 at several block sizes (below a warp, one warp, two: the forward's
//! warp-synchronous and block-wide forms), and the same gradients on the CPU and a GPU bit for
//! bit (the adjoints run one order of roundings on both, as the forwards do).
//!
//! Every element of each matrix operand is perturbed, the triangle the operation does not read
//! included: there both gradients must be zero (the solves' gradient goes to the triangle they
//! read; the factor's to `a`'s lower triangle, the upper one holding values that are not
//! symmetric to show it is never read).
//!
//! Tolerance: `tile_grad::check`'s (`GradcheckOptions::for_type::<f64>()`, worst relative error
//! below 1e-6) for the solves and scans. The factor's gradients span four orders of magnitude,
//! and the central differences' truncation error (2e-10 measured) is a larger part of the
//! smallest ones (2e-6 of one near 1.5e-4), so there the worst absolute error is bounded against
//! the largest gradient instead (1e-7 of it), as tile_grad's layer loop does; a wrong rule is
//! an O(1) error either way.

use crate::tile_grad::{check, values};
use crate::{arr, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(solves, cholesky, scans, integer_tiles_only);

const N: usize = 5;
const K: usize = 3;

#[wp::kernel]
fn k_solves(m: Array<f64, 2>, y: Array<f64, 2>, y1: Array<f64>, out: Array<f64, 2>) {
    let mt: Tile<f64, N, N> = tile_load(m, (0, 0));
    let yt: Tile<f64, N, K> = tile_load(y, (0, 0));
    let y1t = tile_load::<N>(y1, 0);
    // `mt`'s lower triangle as L, its upper triangle as U.
    let z = tile_lower_solve(mt, yt);
    tile_store(out, z, (0, 0));
    tile_store(out, tile_upper_solve(mt, z), (N as i32, 0));
    tile_store(out, tile_cholesky_solve(mt, yt), ((2 * N) as i32, 0));
    // One right-hand side (1-D), into column 0 of the last rows.
    let w = tile_lower_solve(mt, y1t) + tile_upper_solve(mt, y1t) + tile_cholesky_solve(mt, y1t);
    tile_store(out, tile_reshape::<N, 1>(w), ((3 * N) as i32, 0));
}

/// An N x N matrix both of whose triangles are well conditioned (diagonal 2 .. 3.5, the rest
/// within 0.35), row-major.
fn triangles() -> Vec<f64> {
    let v = values(N * N, 21);
    (0..N * N)
        .map(|e| match e / N == e % N {
            true => 2.0 + v[e].abs(),
            false => 0.25 * v[e],
        })
        .collect()
}

fn solves(dev: &wp::Device) {
    let m = arr(&triangles(), dev).with_grad().unwrap();
    let y = arr(&values(N * K, 22), dev).with_grad().unwrap();
    let y1 = arr(&values(N, 23), dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(4 * N * K, dev).with_grad().unwrap();
    let (m2, y2, o2) = (
        m.reshape((N, N)).unwrap(),
        y.reshape((N, K)).unwrap(),
        out.reshape((4 * N, K)).unwrap(),
    );
    for bd in [1, 7, 32, 64] {
        let run = || wp::launch_tiled(k_solves, 1, (&m2, &y2, &y1, &o2), bd, dev);
        check(
            &format!("solves, block_dim {bd}"),
            run,
            &[&m, &y, &y1],
            &out,
        );
    }
}

const C: usize = 6;

#[wp::kernel]
fn k_cholesky(a: Array<f64, 2>, y: Array<f64>, l: Array<f64, 2>, x: Array<f64>) {
    let at: Tile<f64, C, C> = tile_load(a, (0, 0));
    let lt = tile_cholesky(at);
    tile_store(l, lt, (0, 0));
    let yt = tile_load::<C>(y, 0);
    tile_store(x, tile_cholesky_solve(lt, yt), 0);
}

/// `B Bᵀ + C I` in the lower triangle (row-major), values that are not its mirror above.
fn spd_lower() -> Vec<f64> {
    let b = values(C * C, 24);
    let junk = values(C * C, 25);
    (0..C * C)
        .map(|e| {
            let (i, j) = (e / C, e % C);
            if i < j {
                return 3.0 * junk[e];
            }
            let d: f64 = (0..C).map(|k| b[i * C + k] * b[j * C + k]).sum();
            d + if i == j { C as f64 } else { 0.0 }
        })
        .collect()
}

fn cholesky(dev: &wp::Device) {
    let a = arr(&spd_lower(), dev).with_grad().unwrap();
    let y = arr(&values(C, 26), dev).with_grad().unwrap();
    let l = zeros::<f64, 1>(C * C, dev).with_grad().unwrap();
    let x = zeros::<f64, 1>(C, dev).with_grad().unwrap();
    let (a2, l2) = (a.reshape((C, C)).unwrap(), l.reshape((C, C)).unwrap());
    for bd in [1, 5, 32, 64] {
        // The factor alone, then the factor through a solve.
        let run = || wp::launch_tiled(k_cholesky, 1, (&a2, &y, &l2, &x), bd, dev);
        check_scaled(&format!("cholesky, block_dim {bd}"), run, &[&a], &l);
        check_scaled(
            &format!("cholesky solve, block_dim {bd}"),
            run,
            &[&a, &y],
            &x,
        );
    }
}

/// `gradcheck` of `run`, the worst absolute error within 1e-7 of the largest gradient (see the
/// module's docs).
fn check_scaled(
    what: &str,
    mut run: impl FnMut() -> wp::Result<()>,
    xs: &[&wp::Array<f64>],
    out: &wp::Array<f64>,
) {
    let opts = wp::GradcheckOptions::for_type::<f64>();
    let report = wp::gradcheck(&mut run, xs, &[out], opts).unwrap();
    let scale = report
        .analytic
        .iter()
        .flatten()
        .fold(0.0f64, |m, g| m.max(g.abs()));
    let worst = report.max_abs_error;
    assert!(
        report.passed && scale > 0.0 && worst <= 1e-7 * scale,
        "{what}: worst {worst:e} of {scale:e} ({:?})",
        report.worst
    );
}

const S: usize = 11;

#[wp::kernel]
fn k_scans(x: Array<f64>, out: Array<f64>) {
    let t = tile_load::<S>(x, 0);
    tile_store(out, tile_scan_inclusive(t), 0);
    tile_store(out, tile_scan_exclusive(t * t), S as i32);
    tile_store(out, tile_scan_max_inclusive(t), (2 * S) as i32);
    tile_store(out, tile_scan_min_inclusive(t), (3 * S) as i32);
}

/// The scans at block sizes that split the tile into chunks of 11, 3 (a ragged last one), 2
/// and 1. Distinct values, so that each running extremum is one element and smooth.
fn scans(dev: &wp::Device) {
    let xs: Vec<f64> = values(S, 27)
        .iter()
        .enumerate()
        .map(|(k, v)| v + k as f64 * 1e-3)
        .collect();
    let x = arr(&xs, dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(4 * S, dev).with_grad().unwrap();
    for bd in [1, 4, 6, 32] {
        let run = || wp::launch_tiled(k_scans, 1, (&x, &out), bd, dev);
        check(&format!("scans, block_dim {bd}"), run, &[&x], &out);
    }
}

#[wp::kernel]
fn k_int_scan(x: Array<i32>, out: Array<i32>) {
    let t = tile_load::<S>(x, 0);
    tile_store(out, tile_scan_exclusive(t), 0);
}

/// A tiled kernel whose tiles are all integers (nothing to differentiate) compiles: its CPU
/// adjoint declares `tile_store`'s unit result with nothing to infer its type from (it did not
/// compile before, whatever the operations), and it runs forward.
fn integer_tiles_only(dev: &wp::Device) {
    let x = arr(&(1..=S as i32).collect::<Vec<_>>(), dev);
    let out = zeros::<i32, 1>(S, dev);
    wp::launch_tiled(k_int_scan, 1, (&x, &out), 4, dev).unwrap();
    let want: Vec<i32> = (0..S as i32).map(|k| k * (k + 1) / 2).collect();
    assert_eq!(crate::host(&out), want);
}

/// One backward of each kernel (seeds: the `values` of the outputs) on `dev` at block size
/// `bd`: the inputs' gradients.
fn grads(dev: &wp::Device, bd: usize) -> Vec<Vec<f64>> {
    let m = arr(&triangles(), dev).with_grad().unwrap();
    let y = arr(&values(N * K, 22), dev).with_grad().unwrap();
    let y1 = arr(&values(N, 23), dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(4 * N * K, dev).with_grad().unwrap();
    let a = arr(&spd_lower(), dev).with_grad().unwrap();
    let cy = arr(&values(C, 26), dev).with_grad().unwrap();
    let l = zeros::<f64, 1>(C * C, dev).with_grad().unwrap();
    let cx = zeros::<f64, 1>(C, dev).with_grad().unwrap();
    let sx = arr(&values(S, 27), dev).with_grad().unwrap();
    let sout = zeros::<f64, 1>(4 * S, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        let (m2, y2, o2) = (
            m.reshape((N, N)).unwrap(),
            y.reshape((N, K)).unwrap(),
            out.reshape((4 * N, K)).unwrap(),
        );
        wp::launch_tiled(k_solves, 1, (&m2, &y2, &y1, &o2), bd, dev).unwrap();
        let (a2, l2) = (a.reshape((C, C)).unwrap(), l.reshape((C, C)).unwrap());
        wp::launch_tiled(k_cholesky, 1, (&a2, &cy, &l2, &cx), bd, dev).unwrap();
        wp::launch_tiled(k_scans, 1, (&sx, &sout), bd, dev).unwrap();
    }
    for (g, n, seed) in [
        (&out, 4 * N * K, 30),
        (&l, C * C, 31),
        (&cx, C, 32),
        (&sout, 4 * S, 33),
    ] {
        g.grad()
            .unwrap()
            .copy_from(&arr(&values(n, seed), dev))
            .unwrap();
    }
    tape.backward_from_grads().unwrap();
    [&m, &y, &y1, &a, &cy, &sx]
        .iter()
        .map(|v| v.grad().unwrap().to_vec().unwrap())
        .collect()
}

/// The gradients on the CPU and a GPU, bit for bit (tolerance: none), at a block size below a
/// warp (the block-wide forwards) and at 64 (the warp-synchronous ones). Skipped, saying so,
/// without a GPU.
#[test]
fn cpu_and_gpu_gradients_are_equal() {
    let Ok(gpu) = wp::get_device(&crate::test_gpu()) else {
        eprintln!("SKIPPED tile_grad_linalg::cpu_and_gpu_gradients_are_equal: no GPU");
        return;
    };
    let _gpu = crate::gpu_lock();
    let cpu = wp::get_device("cpu").unwrap();
    for bd in [7, 64] {
        let (c, g) = (grads(&cpu, bd), grads(&gpu, bd));
        for (k, (c, g)) in c.iter().zip(&g).enumerate() {
            let (cb, gb): (Vec<u64>, Vec<u64>) = (
                c.iter().map(|v| v.to_bits()).collect(),
                g.iter().map(|v| v.to_bits()).collect(),
            );
            assert_eq!(cb, gb, "block_dim {bd}, input {k}: CPU {c:?} vs GPU {g:?}");
        }
    }
}

/// The CUDA adjoints of the kernels above are generated (what NVRTC compiles on a GPU), with
/// the library's adjoint calls; the host harness tests/cuda_tile_linalg_adjoint_host.rs runs
/// those functions against warp-core.
#[test]
fn cuda_adjoints_are_generated() {
    for (info, calls) in [
        (
            wp::kernel_info(k_solves),
            &[
                "wp::adj_tile_lower_solve(",
                "wp::adj_tile_upper_solve(",
                "wp::adj_tile_cholesky_solve(",
            ][..],
        ),
        (
            wp::kernel_info(k_cholesky),
            &["wp::adj_tile_cholesky(", "wp::adj_tile_cholesky_solve("][..],
        ),
        (
            wp::kernel_info(k_scans),
            &[
                "wp::adj_tile_scan_inclusive(",
                "wp::adj_tile_scan_exclusive(",
                "wp::adj_tile_scan_max_inclusive(",
                "wp::adj_tile_scan_min_inclusive(",
            ][..],
        ),
    ] {
        assert!(
            info.cuda_adjoint_error.is_none(),
            "{}: {:?}",
            info.name,
            info.cuda_adjoint_error
        );
        for c in calls {
            assert!(info.cuda_adjoint.contains(c), "{}: no {c}", info.name);
        }
    }
}

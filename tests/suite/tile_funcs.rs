//! `tile_map` with user `#[func]`s: forward on every backend against the same func applied on
//! the host, a func whose result type differs from its input (the tile's element follows the
//! annotation, checked against the func's signature by rustc), a func that faults, and
//! backward through the funcs' own adjoints (`wp::gradcheck` in f64, CPU against GPU).
//!
//! Tolerances: the forward maps use `+ - *` and `as` only, so every backend computes the
//! host's bits (exact comparisons); gradients pass `tile_grad::check` (1e-6 relative on the
//! worst element against central differences) and equal the GPU's bit for bit (the same
//! scalar adjoint on each element, no reduction order involved).

use crate::tile_grad::{check, values};
use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    unary_and_binary_funcs,
    func_with_another_result_type,
    func_calling_func_and_builtins,
    fault_in_a_mapped_func,
    gradients_through_funcs,
    generic_func_instances,
    reduce_with_funcs,
    fault_in_a_reducing_func,
    map_with_scalar_constants,
    gradients_of_scalar_constants,
);

#[wp::func]
fn cubic(x: f32) -> f32 {
    x * x * x - 2.0 * x
}

#[wp::func]
fn blend(a: f32, b: f32) -> f32 {
    if a > b {
        return a - 0.5 * b;
    }
    a * b + 1.0
}

#[wp::func]
fn weighted(a: f32, b: f32, c: f32) -> f32 {
    0.5 * a + 0.25 * b - c * c
}

#[wp::kernel]
fn k_unary_binary(
    x: Array<f32>,
    y: Array<f32>,
    out: Array<f32>,
    out2: Array<f32>,
    out3: Array<f32>,
) {
    let b = tid();
    let o = (b * 16) as i32;
    let t = tile_load::<16>(x, o);
    let u = tile_load::<16>(y, o);
    tile_store(out, tile_map(cubic, t), o);
    tile_store(out2, tile_map(blend, t, u) + t, o);
    tile_store(out3, tile_map(weighted, t, u, t), o);
}

fn host_cubic(x: f32) -> f32 {
    x * x * x - 2.0 * x
}

fn host_blend(a: f32, b: f32) -> f32 {
    if a > b {
        return a - 0.5 * b;
    }
    a * b + 1.0
}

/// `tile_map(cubic, t)`, `tile_map(blend, t, u)` and `tile_map(weighted, t, u, t)` on 37
/// elements (ragged against 16), at block sizes 1, 7 and 64: every stored element is the
/// host's, bit for bit.
fn unary_and_binary_funcs(dev: &wp::Device) {
    let n = 37;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.25 - 4.0).collect();
    let ys: Vec<f32> = (0..n).map(|k| 3.0 - k as f32 * 0.125).collect();
    let (x, y) = (arr(&xs, dev), arr(&ys, dev));
    for bd in [1, 7, 64] {
        let out = zeros::<f32, 1>(n, dev);
        let out2 = zeros::<f32, 1>(n, dev);
        let out3 = zeros::<f32, 1>(n, dev);
        wp::launch_tiled(k_unary_binary, 3, (&x, &y, &out, &out2, &out3), bd, dev).unwrap();
        let (g, g2, g3) = (host(&out), host(&out2), host(&out3));
        for k in 0..n {
            assert_eq!(
                g[k].to_bits(),
                host_cubic(xs[k]).to_bits(),
                "cubic {k}, bd {bd}"
            );
            let want = host_blend(xs[k], ys[k]) + xs[k];
            assert_eq!(g2[k].to_bits(), want.to_bits(), "blend {k}, bd {bd}");
            let want = 0.5 * xs[k] + 0.25 * ys[k] - xs[k] * xs[k];
            assert_eq!(g3[k].to_bits(), want.to_bits(), "weighted {k}, bd {bd}");
        }
    }
}

#[wp::func]
fn bucket(x: f32) -> i32 {
    (x * 2.0) as i32 + 1
}

#[wp::kernel]
fn k_bucket(x: Array<f32>, out: Array<i32>) {
    let t = tile_load::<8>(x, 0);
    // The func returns i32: the annotation names the result tile's element.
    let k: Tile<i32, 8> = tile_map(bucket, t);
    tile_store(out, k * 3, 0);
}

/// A func from `f32` to `i32`: the result is an `i32` tile (integer `*` on it).
fn func_with_another_result_type(dev: &wp::Device) {
    let xs = [-2.25f32, -1.0, -0.2, 0.0, 0.4, 1.6, 2.5, 7.9];
    let x = arr(&xs, dev);
    let out = zeros::<i32, 1>(8, dev);
    wp::launch_tiled(k_bucket, 1, (&x, &out), 32, dev).unwrap();
    let want: Vec<i32> = xs.iter().map(|v| ((v * 2.0) as i32 + 1) * 3).collect();
    assert_eq!(host(&out), want);
}

#[wp::func]
fn scaled(x: f64, s: f64) -> f64 {
    let mut acc = 0.0f64;
    for k in 0..3 {
        acc += x * s + k as f64;
    }
    acc
}

#[wp::func]
fn twice_scaled(x: f64) -> f64 {
    scaled(x, 2.0) + max(x, 0.0)
}

#[wp::kernel]
fn k_nested(x: Array<f64, 2>, out: Array<f64, 2>) {
    let t: Tile<f64, 3, 4> = tile_load(x, (0, 0));
    tile_store(out, tile_map(twice_scaled, t), (0, 0));
}

/// A 2-D tile through a func that loops and calls another func and a builtin.
fn func_calling_func_and_builtins(dev: &wp::Device) {
    let xs: Vec<f64> = (0..12).map(|k| k as f64 * 0.5 - 2.5).collect();
    let x = wp::Array::from_slice_shape(&xs, (3, 4), dev).unwrap();
    let out = wp::Array::<f64, 2>::zeros((3, 4), dev).unwrap();
    wp::launch_tiled(k_nested, 1, (&x, &out), 5, dev).unwrap();
    let got = out.to_vec().unwrap();
    for (k, v) in xs.iter().enumerate() {
        let mut acc = 0.0;
        for j in 0..3 {
            acc += v * 2.0 + j as f64;
        }
        let want = acc + v.max(0.0);
        assert_eq!(got[k].to_bits(), want.to_bits(), "element {k}");
    }
}

#[wp::func]
fn idiv(a: i32, b: i32) -> i32 {
    a / b
}

#[wp::kernel]
fn k_idiv(a: Array<i32>, b: Array<i32>, out: Array<i32>) {
    let t = tile_load::<4>(a, 0);
    let u = tile_load::<4>(b, 0);
    tile_store(out, tile_map(idiv, t, u), 0);
}

/// An integer division by zero inside a mapped func is the launch's `Err`, as in a scalar
/// call; without the zero the quotients are the host's.
fn fault_in_a_mapped_func(dev: &wp::Device) {
    let a = arr(&[7i32, -9, 12, 5], dev);
    let out = zeros::<i32, 1>(4, dev);
    let good = arr(&[2i32, 4, -5, 1], dev);
    wp::launch_tiled(k_idiv, 1, (&a, &good, &out), 8, dev).unwrap();
    assert_eq!(host(&out), vec![3, -2, -2, 5]);
    let bad = arr(&[2i32, 0, -5, 1], dev);
    let e = wp::launch_tiled(k_idiv, 1, (&a, &bad, &out), 8, dev).unwrap_err();
    let msg = crate::chain(&e);
    assert!(
        matches!(e, wp::Error::Fault(_)) && msg.contains("division by zero"),
        "expected a division fault, got {msg}"
    );
}

#[wp::func]
fn soft(x: f64) -> f64 {
    x * tanh(x) + sin(2.0 * x)
}

#[wp::func]
fn mix(a: f64, b: f64) -> f64 {
    let mut s = a;
    for _ in 0..2 {
        s = s * b + cos(a);
    }
    s
}

#[wp::func]
fn mix3(a: f64, b: f64, c: f64) -> f64 {
    a * b * c + sin(b) * a
}

#[wp::kernel]
fn k_func_grads(x: Array<f64>, y: Array<f64>, out: Array<f64>) {
    let b = tid();
    let o = (b * 8) as i32;
    let t = tile_load::<8>(x, o);
    let u = tile_load::<8>(y, o);
    let s = tile_map(soft, t);
    let m = tile_map(mix, s, u) + tile_map(mix, t, t) + tile_map(mix3, t, u, s);
    tile_store(out, m, o);
    let total = tile_sum(tile_map(soft, m));
    tile_store(out, total, 24 + b as i32);
}

/// Backward through `tile_map` of a unary, a binary and a ternary func (one with a loop, so
/// its adjoint uses the stack; the same tile twice; a func of a mapped tile), 21 elements in three
/// blocks of 8 (ragged), at block sizes 1, 5 and 32: gradcheck in f64.
fn gradients_through_funcs(dev: &wp::Device) {
    let n = 21;
    let x = arr(&values(n, 7), dev).with_grad().unwrap();
    let y = arr(&values(n, 8), dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(27, dev).with_grad().unwrap();
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_func_grads, 3, (&x, &y, &out), bd, dev);
        check(
            &format!("tile_map of funcs, block_dim {bd}"),
            run,
            &[&x, &y],
            &out,
        );
    }
}

/// The gradients of `k_func_grads` on `dev`.
fn func_grads_on(dev: &wp::Device) -> Vec<Vec<f64>> {
    let n = 21;
    let x = arr(&values(n, 7), dev).with_grad().unwrap();
    let y = arr(&values(n, 8), dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(27, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_func_grads, 3, (&x, &y, &out), 32, dev).unwrap();
    }
    out.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    [&x, &y]
        .iter()
        .map(|v| v.grad().unwrap().to_vec().unwrap())
        .collect()
}

/// The same func gradients on the CPU and on a GPU. The funcs call `tanh`, `sin` and `cos`,
/// whose CUDA versions are not the host's: within 1e-12 relative (a few ulps through each
/// adjoint). Skipped, saying so, without a GPU.
#[test]
fn cpu_and_gpu_func_gradients_agree() {
    let Ok(gpu) = wp::get_device(&crate::test_gpu()) else {
        eprintln!("SKIPPED cpu_and_gpu_func_gradients_agree: no GPU");
        return;
    };
    let _gpu = crate::gpu_lock();
    let cpu = wp::get_device("cpu").unwrap();
    let (c, g) = (func_grads_on(&cpu), func_grads_on(&gpu));
    for (k, (c, g)) in c.iter().zip(&g).enumerate() {
        for (e, (x, y)) in c.iter().zip(g).enumerate() {
            assert!(
                (x - y).abs() <= 1e-12 * x.abs().max(1.0),
                "input {k}, element {e}: CPU {x} vs GPU {y}"
            );
        }
    }
}

/// The CUDA forward and adjoint of a kernel mapping funcs (NVRTC compiles them only on a GPU:
/// `cuda_backend::gradients_through_funcs` there): functors calling the funcs and their
/// adjoints with the fault context (and the thread's stack), and nothing refused.
#[test]
fn cuda_templates_call_the_funcs() {
    let info = wp::kernel_info(k_func_grads);
    assert!(
        info.adjoint_error.is_none() && info.cuda_adjoint_error.is_none(),
        "{:?} {:?}",
        info.adjoint_error,
        info.cuda_adjoint_error
    );
    let fwd = wp::cuda_source::assemble(info).text;
    let adj = wp::cuda_source::assemble_adjoint(info).text;
    if let Ok(dir) = std::env::var("WP_DUMP_TILE_FUNCS") {
        std::fs::write(format!("{dir}/fwd.cu"), &fwd).unwrap();
        std::fs::write(format!("{dir}/adj.cu"), &adj).unwrap();
    }
    assert!(!fwd.contains("#error") && !adj.contains("#error"));
    assert!(fwd.contains("wp::tile_map2("), "{fwd}");
    let generic = wp::cuda_source::assemble(wp::kernel_info(k_generic)).text;
    assert!(!generic.contains("#error"), "{generic}");
    assert!(
        adj.contains("wp::adj_tile_map1(") && adj.contains("wp::adj_tile_map2("),
        "{adj}"
    );
}

#[wp::func]
fn affine<T: Float>(x: T, s: T) -> T {
    x * s + 1.0
}

#[wp::kernel]
fn k_generic(x: Array<f64>, y: Array<f32>, out: Array<f64>, out32: Array<f32>) {
    let t = tile_load::<8>(x, 0);
    let u = tile_load::<8>(y, 0);
    tile_store(out, tile_map(affine::<f64>, t, t), 0);
    tile_store(out32, tile_map(affine::<f32>, u, u), 0);
}

/// A generic func's instances by path (`affine::<f64>`, `affine::<f32>`).
fn generic_func_instances(dev: &wp::Device) {
    let xs: Vec<f64> = (0..8).map(|k| k as f64 * 0.5 - 1.0).collect();
    let ys: Vec<f32> = xs.iter().map(|v| *v as f32).collect();
    let (x, y) = (arr(&xs, dev), arr(&ys, dev));
    let out = zeros::<f64, 1>(8, dev);
    let out32 = zeros::<f32, 1>(8, dev);
    wp::launch_tiled(k_generic, 1, (&x, &y, &out, &out32), 4, dev).unwrap();
    let want: Vec<f64> = xs.iter().map(|v| v * v + 1.0).collect();
    assert_eq!(host(&out), want);
    let want: Vec<f32> = ys.iter().map(|v| v * v + 1.0).collect();
    assert_eq!(host(&out32), want);
}

// ---- `tile_reduce` with a user #[func] ----------------------------------------------------

/// Order-dependent (neither associative nor commutative), so the result shows the order.
#[wp::func]
fn halve_add(a: f32, b: f32) -> f32 {
    0.5 * a + b
}

/// The same on integers (values stay below 2^17: no overflow).
#[wp::func]
fn mix_int(a: i32, b: i32) -> i32 {
    (a * 7 + b) % 10007
}

#[wp::kernel]
fn k_reduce_funcs(
    x: Array<f32>,
    xi: Array<i32>,
    x2: Array<f32, 2>,
    out: Array<f32>,
    outi: Array<i32>,
) {
    let t = tile_load::<37>(x, 0);
    tile_store(out, tile_reduce(halve_add, t), 0);
    let t2: Tile<f32, 3, 5> = tile_load(x2, (0, 0));
    tile_store(out, tile_reduce(halve_add, t2), 1);
    let ti = tile_load::<37>(xi, 0);
    tile_store(outi, tile_reduce(mix_int, ti), 0);
}

/// The reductions' documented order (warp-core's tile/reduce.rs, `wp_tile.h`), written out
/// on the host: lane `l` folds elements `l, l + bd, ..`; each warp of 32 lanes combines by
/// `shfl_down` offsets 16..1 (an absent partner leaves the value); warps fold in order.
fn host_gpu_order<E: Copy>(x: &[E], bd: usize, op: impl Fn(E, E) -> E) -> E {
    let comb = |a: Option<E>, b: Option<E>| match (a, b) {
        (Some(a), Some(b)) => Some(op(a, b)),
        (a, None) => a,
        (None, b) => b,
    };
    let lanes: Vec<Option<E>> = (0..x.len().min(bd))
        .map(|l| {
            let mut p = x[l];
            let mut e = l + bd;
            while e < x.len() {
                p = op(p, x[e]);
                e += bd;
            }
            Some(p)
        })
        .collect();
    let mut result = None;
    for w in lanes.chunks(32) {
        let mut p = w.to_vec();
        p.resize(32, None);
        for off in [16, 8, 4, 2, 1] {
            for i in 0..off {
                p[i] = comb(p[i], p[i + off]);
            }
        }
        result = comb(result, p[0]);
    }
    result.expect("a non-empty tile")
}

/// `tile_reduce` of a user func over a 37-element f32 tile, a 3x5 f32 tile and a 37-element
/// i32 tile, at block sizes 1 (sequential), 7, 33 (two warps, one partial) and 64: the host's
/// order applied to the same func, bit for bit (exact: the func is `*` and `+` only).
fn reduce_with_funcs(dev: &wp::Device) {
    let xs: Vec<f32> = (0..37).map(|k| (k as f32 * 0.37).sin() * 3.0).collect();
    let xis: Vec<i32> = (0..37).map(|k| (k * 131 + 17) % 1000).collect();
    let x2s: Vec<f32> = xs[..15].to_vec();
    let x = arr(&xs, dev);
    let xi = arr(&xis, dev);
    let x2 = wp::Array::from_slice_shape(&x2s, (3, 5), dev).unwrap();
    for bd in [1, 7, 33, 64] {
        let out = zeros::<f32, 1>(2, dev);
        let outi = zeros::<i32, 1>(1, dev);
        wp::launch_tiled(k_reduce_funcs, 1, (&x, &xi, &x2, &out, &outi), bd, dev).unwrap();
        let (g, gi) = (host(&out), host(&outi));
        let f = |a: f32, b: f32| 0.5 * a + b;
        let want = host_gpu_order(&xs, bd, f);
        assert_eq!(
            g[0].to_bits(),
            want.to_bits(),
            "1-D, bd {bd}: {} vs {want}",
            g[0]
        );
        let want = host_gpu_order(&x2s, bd, f);
        assert_eq!(
            g[1].to_bits(),
            want.to_bits(),
            "2-D, bd {bd}: {} vs {want}",
            g[1]
        );
        let want = host_gpu_order(&xis, bd, |a: i32, b: i32| (a * 7 + b) % 10007);
        assert_eq!(gi[0], want, "i32, bd {bd}");
    }
}

#[wp::kernel]
fn k_reduce_idiv(a: Array<i32>, out: Array<i32>) {
    let t = tile_load::<4>(a, 0);
    tile_store(out, tile_reduce(idiv, t), 0);
}

/// An integer division by zero inside a reducing func is the launch's `Err`; without the
/// zero the quotient is the host's (block size 1: `((1000 / 5) / -4) / 2`).
fn fault_in_a_reducing_func(dev: &wp::Device) {
    let out = zeros::<i32, 1>(1, dev);
    let good = arr(&[1000i32, 5, -4, 2], dev);
    wp::launch_tiled(k_reduce_idiv, 1, (&good, &out), 1, dev).unwrap();
    assert_eq!(host(&out), vec![-25]);
    let bad = arr(&[1000i32, 5, 0, 2], dev);
    for bd in [1, 8] {
        let e = wp::launch_tiled(k_reduce_idiv, 1, (&bad, &out), bd, dev).unwrap_err();
        let msg = crate::chain(&e);
        assert!(
            matches!(e, wp::Error::Fault(_)) && msg.contains("division by zero"),
            "bd {bd}: expected a division fault, got {msg}"
        );
    }
}

/// Backward through `tile_reduce` of a user func is refused (Warp differentiates none) with
/// an error naming the call, and only the adjoint is: the forward kernel and its CUDA source
/// are whole (the CUDA reduction calls the func through a functor with the fault context).
#[test]
fn reduce_with_a_func_refuses_backward() {
    let info = wp::kernel_info(k_reduce_funcs);
    let why = info.adjoint_error.unwrap_or("");
    assert!(
        why.contains("tile_reduce(halve_add, ..)") && why.contains("Warp differentiates none"),
        "{why:?}"
    );
    let fwd = wp::cuda_source::assemble(info).text;
    assert!(!fwd.contains("#error"), "{fwd}");
    assert!(fwd.contains("wp::tile_reduce("), "{fwd}");
}

// ---- `tile_map` with scalar constants ------------------------------------------------------

#[wp::func]
fn scale_shift(x: f32, s: f32) -> f32 {
    x * s + 1.0
}

#[wp::func]
fn lerp_by(a: f32, b: f32, w: f32) -> f32 {
    a + (b - a) * w
}

#[wp::func]
fn times_int(x: f32, k: i32) -> f32 {
    x * (k as f32)
}

#[wp::kernel]
fn k_map_consts(
    x: Array<f32>,
    y: Array<f32>,
    w: Array<f32>,
    xi: Array<i32>,
    out: Array<f32>,
    outi: Array<i32>,
) {
    let t = tile_load::<16>(x, 0);
    let u = tile_load::<16>(y, 0);
    let s = w[0];
    // A literal (the tile's element type), a run-time scalar with an operator and with a
    // builtin, a scalar after two tiles, an integer constant to a float func, integers.
    tile_store(out, tile_map(scale_shift, t, 2.0), 0);
    tile_store(out, tile_map(mul, t, s), 16);
    tile_store(out, tile_map(max, t, 0.5), 32);
    tile_store(out, tile_map(lerp_by, t, u, s), 48);
    tile_store(out, tile_map(times_int, t, 3i32), 64);
    let ti = tile_load::<16>(xi, 0);
    tile_store(outi, tile_map(add, ti, 3), 0);
}

/// `tile_map` with a scalar constant broadcast to every element, at block sizes 1, 7 and 32:
/// the host's bits exactly (`+ - *`, `max`, `as`).
fn map_with_scalar_constants(dev: &wp::Device) {
    let xs: Vec<f32> = (0..16).map(|k| k as f32 * 0.25 - 2.0).collect();
    let ys: Vec<f32> = (0..16).map(|k| 1.5 - k as f32 * 0.375).collect();
    let xis: Vec<i32> = (0..16).map(|k| k * 5 - 40).collect();
    let s = -1.75f32;
    let (x, y, w, xi) = (arr(&xs, dev), arr(&ys, dev), arr(&[s], dev), arr(&xis, dev));
    for bd in [1, 7, 32] {
        let out = zeros::<f32, 1>(80, dev);
        let outi = zeros::<i32, 1>(16, dev);
        wp::launch_tiled(k_map_consts, 1, (&x, &y, &w, &xi, &out, &outi), bd, dev).unwrap();
        let (g, gi) = (host(&out), host(&outi));
        for k in 0..16 {
            let (a, b) = (xs[k], ys[k]);
            let want = [a * 2.0 + 1.0, a * s, a.max(0.5), a + (b - a) * s, a * 3.0];
            for (j, w) in want.iter().enumerate() {
                let v = g[16 * j + k];
                assert_eq!(
                    v.to_bits(),
                    w.to_bits(),
                    "map {j}, element {k}, bd {bd}: {v} vs {w}"
                );
            }
            assert_eq!(gi[k], xis[k] + 3, "i32 element {k}, bd {bd}");
        }
    }
}

#[wp::func]
fn soft_scale(x: f64, s: f64) -> f64 {
    x * tanh(s * x) + s
}

#[wp::func]
fn two_consts(a: f64, b: f64, s: f64, c: f64, k: i32) -> f64 {
    a * s + sin(b) * (k as f64) * c * s
}

#[wp::kernel]
fn k_const_grads(x: Array<f64>, y: Array<f64>, w: Array<f64>, out: Array<f64>) {
    let b = tid();
    let o = (b * 8) as i32;
    // Scalars every lane computes from `w`: their gradients reach `w` through the Tape.
    let s = w[0] * 2.0 + 0.5;
    let c = w[1];
    let t = tile_load::<8>(x, o);
    let u = tile_load::<8>(y, o);
    let m =
        tile_map(soft_scale, t, s) + tile_map(mul, u, c) + tile_map(two_consts, t, u, s, c, 3i32);
    tile_store(out, m + tile_map(sub, t, s), o);
}

/// Backward through `tile_map` with scalar constants (a func with one, an operator with one,
/// a func with two float constants and an integer one, the same constant in several maps):
/// gradcheck in f64 on 21 elements in three blocks of 8 (ragged), block sizes 1, 5 and 32.
/// The constants' gradients are checked through `w`, from which they are computed.
fn gradients_of_scalar_constants(dev: &wp::Device) {
    let n = 21;
    let x = arr(&values(n, 3), dev).with_grad().unwrap();
    let y = arr(&values(n, 4), dev).with_grad().unwrap();
    let w = arr(&[0.35f64, -0.8], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_const_grads, 3, (&x, &y, &w, &out), bd, dev);
        check(
            &format!("tile_map with constants, block_dim {bd}"),
            run,
            &[&x, &y, &w],
            &out,
        );
    }
}

/// The gradients of `k_const_grads` on `dev` (x, y, w).
fn const_grads_on(dev: &wp::Device, bd: usize) -> Vec<Vec<f64>> {
    let n = 21;
    let x = arr(&values(n, 3), dev).with_grad().unwrap();
    let y = arr(&values(n, 4), dev).with_grad().unwrap();
    let w = arr(&[0.35f64, -0.8], dev).with_grad().unwrap();
    let out = zeros::<f64, 1>(n, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_const_grads, 3, (&x, &y, &w, &out), bd, dev).unwrap();
    }
    out.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    [&x, &y, &w]
        .iter()
        .map(|v| v.grad().unwrap().to_vec().unwrap())
        .collect()
}

/// The constants' gradients (and the tiles') on the CPU and on a GPU, at block sizes 5 and 32:
/// within 1e-12 relative (`tanh` and `sin` differ by ulps on CUDA; the sums over elements
/// run in the same order on both). Skipped, saying so, without a GPU.
#[test]
fn cpu_and_gpu_constant_gradients_agree() {
    let Ok(gpu) = wp::get_device(&crate::test_gpu()) else {
        eprintln!("SKIPPED cpu_and_gpu_constant_gradients_agree: no GPU");
        return;
    };
    let _gpu = crate::gpu_lock();
    let cpu = wp::get_device("cpu").unwrap();
    for bd in [5, 32] {
        let (c, g) = (const_grads_on(&cpu, bd), const_grads_on(&gpu, bd));
        for (k, (c, g)) in c.iter().zip(&g).enumerate() {
            for (e, (a, b)) in c.iter().zip(g).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-12 * a.abs().max(1.0),
                    "bd {bd}, input {k}, element {e}: CPU {a} vs GPU {b}"
                );
            }
        }
    }
}

/// The CUDA forward and adjoint of the kernels with constants assemble without a refusal:
/// the maps written out with the constants as they are, the constants' block totals.
#[test]
fn cuda_sources_of_maps_with_constants() {
    for info in [
        wp::kernel_info(k_map_consts),
        wp::kernel_info(k_const_grads),
    ] {
        assert!(
            info.cuda_adjoint_error.is_none(),
            "{:?}",
            info.cuda_adjoint_error
        );
        let fwd = wp::cuda_source::assemble(info).text;
        assert!(!fwd.contains("#error"), "{fwd}");
    }
    let info = wp::kernel_info(k_const_grads);
    assert!(info.adjoint_error.is_none(), "{:?}", info.adjoint_error);
    let adj = wp::cuda_source::assemble_adjoint(info).text;
    assert!(!adj.contains("#error"), "{adj}");
    assert!(adj.contains("wp::tile_detail::block_total<"), "{adj}");
}

//! Half-precision tiles: `Tile<f16, ..>` through loads, stores, elementwise operators,
//! `tile_map`, reductions, and `tile_matmul` with f16 operands (an f32 accumulator, or an f16
//! result accumulated in f32 and rounded once), on every backend, against the host.
//!
//! Exactness: every f16 operation is one f32 operation rounded once, on both backends (see
//! `f16.rs`), so elementwise results and reductions of exactly representable sums are compared
//! bit for bit. The matmul's FMA path (the CPU; CUDA for shapes or block sizes the tensor cores
//! do not take, and below sm_80) is one f32 FMA chain per output in ascending k on both, so
//! it is bit-exact too. CUDA's tensor-core path (`mma.sync.m16n8k16`, f32 accumulate) sums
//! each k-step of 16 exact products in an order and with alignment roundings the hardware
//! does not specify: truncating instead of rounding at each of the K additions is at most one
//! f32 ulp (2^-23) relative to the running magnitude, itself at most sum |a||b|, so per output
//! |c - c64| <= K 2^-23 sum |a||b|; the tests allow twice that (`K 2^-22`), plus half an f16
//! ulp (2^-11 relative) for the f16 result. The CPU's chain is within K 2^-24 sum |a||b|.

// The kernel language has no `div_ceil` yet: kernels round up with `(n + d - 1) / d`.
#![allow(clippy::manual_div_ceil)]

use crate::{host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    f16_elementwise_map_and_reductions,
    f16_gemm_accumulates_in_f32,
    f16_matmul_fma_shapes_are_exact,
    f16_gemm_pipelined_k_loop_matches_the_plain_loop,
    f16_gemm_with_an_extra_stage_matches_the_smaller_tiles,
);

fn h(x: f32) -> f16 {
    f16::from_f32(x)
}

#[wp::kernel]
fn k_f16_ops(a: Array<f16, 2>, b: Array<f16, 2>, s: f16, sums: Array<f16>) {
    let (i, j) = tid();
    let t: Tile<f16, 16, 8> = tile_load(a, ((i * 16) as i32, (j * 8) as i32));
    let u = -(t * s + t) - tile_ones::<f16, 16, 8>();
    let w = tile_map(sqrt, tile_map(abs, u));
    tile_store(b, w, ((i * 16) as i32, (j * 8) as i32));
    let total = tile_sum(t);
    let hi = tile_max(t);
    if lane() == 0 && i == 0 && j == 0 {
        sums[0] = total[0];
        sums[1] = hi[0];
    }
}

/// Load, `-(t s + t) - 1`, `sqrt(abs(..))` and store on a ragged 37 x 45 f16 array, bit for bit
/// the host's `half` arithmetic (each step one f32 operation rounded once); the first block's
/// sum and maximum (128 multiples of 1/4 in [-2, 2]: every partial sum, in any order, is a
/// multiple of 1/4 below 512, exact in f16).
fn f16_elementwise_map_and_reductions(dev: &wp::Device) {
    let (m, n) = (37usize, 45usize);
    let data: Vec<f16> = (0..m * n)
        .map(|k| h(((k * 37 % 17) as f32 - 8.0) * 0.25))
        .collect();
    let a = wp::Array::from_slice_shape(&data, (m, n), dev).unwrap();
    let b = wp::Array::<f16, 2>::zeros((m, n), dev).unwrap();
    let sums = zeros::<f16, 1>(2, dev);
    let s = h(1.5);
    for bd in [1, 32, 45, 128] {
        let blocks = (m.div_ceil(16), n.div_ceil(8));
        wp::launch_tiled(k_f16_ops, blocks, (&a, &b, s, &sums), bd, dev).unwrap();
        let got = host(&b);
        for (k, (&g, &x)) in got.iter().zip(&data).enumerate() {
            let u = -(x * s + x) - h(1.0);
            let want = h(u.to_f32().abs().sqrt());
            assert_eq!(g.to_bits(), want.to_bits(), "element {k} at block_dim {bd}");
        }
        let block0: Vec<f16> = (0..16)
            .flat_map(|r| (0..8).map(move |c| (r, c)))
            .map(|(r, c)| data[r * n + c])
            .collect();
        let total: f32 = block0.iter().map(|x| x.to_f32()).sum();
        let hi = block0.iter().map(|x| x.to_f32()).fold(f32::MIN, f32::max);
        assert_eq!(host(&sums), vec![h(total), h(hi)], "block_dim {bd}");
    }
}

const GM: usize = 32;
const GN: usize = 32;
const GK: usize = 32;

#[wp::kernel]
fn k_gemm_f16(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>, d: Array<f16, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f32, GM, GN>();
    let k_tiles = (a.shape()[1] + GK - 1) / GK;
    for k in 0..k_tiles {
        let ta = tile_load::<GM, GK>(a, ((i * GM) as i32, (k * GK) as i32));
        let tb = tile_load::<GK, GN>(b, ((k * GK) as i32, (j * GN) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * GM) as i32, (j * GN) as i32));
    // The returning form, of the first k-step alone: f16 out, accumulated in f32.
    let ta = tile_load::<GM, GK>(a, ((i * GM) as i32, 0));
    let tb = tile_load::<GK, GN>(b, (0, (j * GN) as i32));
    let p = tile_matmul(ta, tb);
    tile_store(d, p, ((i * GM) as i32, (j * GN) as i32));
}

/// Deterministic f16 values in [-1, 1), with full 11-bit significands.
fn values(n: usize, seed: usize) -> Vec<f16> {
    (0..n)
        .map(|t| h((((t * 7919 + seed) % 2039) as f32) / 1019.5 - 1.0))
        .collect()
}

/// The host's FMA chain of row `i` of `a` (m x k) and column `j` of `b` (k x n) over `ks`,
/// widened to f32 (warp-core's f16 matmul), and the f64 product and magnitude.
fn chain(
    a: &[f16],
    b: &[f16],
    (k, n): (usize, usize),
    (i, j): (usize, usize),
    ks: std::ops::Range<usize>,
) -> (f32, f64, f64) {
    let (mut acc, mut exact, mut mag) = (0f32, 0f64, 0f64);
    for p in ks {
        let (x, y) = (a[i * k + p].to_f32(), b[p * n + j].to_f32());
        acc = x.mul_add(y, acc);
        exact += x as f64 * y as f64;
        mag += (x as f64 * y as f64).abs();
    }
    (acc, exact, mag)
}

/// A tiled GEMM of f16 inputs with an f32 accumulator on a ragged 45 x 40 x 37 problem, and
/// the returning form's f16 product of the first k-step. Block sizes 64 and 128 (whole warps:
/// tensor cores on an sm_80+ GPU; 32 x 32 operands, whose 64-byte rows the tensor-core path
/// reads from padded copies) are within the tolerance of the module docs of the f64 product;
/// block size 45 (not whole warps: the FMA path on every GPU) and the CPU are the host's FMA
/// chain bit for bit.
fn f16_gemm_accumulates_in_f32(dev: &wp::Device) {
    let (m, k, n) = (45usize, 40usize, 37usize);
    let ad = values(m * k, 3);
    let bd_ = values(k * n, 11);
    let a = wp::Array::from_slice_shape(&ad, (m, k), dev).unwrap();
    let b = wp::Array::from_slice_shape(&bd_, (k, n), dev).unwrap();
    let c = zeros::<f32, 2>((m, n), dev);
    let d = wp::Array::<f16, 2>::zeros((m, n), dev).unwrap();
    let blocks = (m.div_ceil(GM), n.div_ceil(GN));
    let kp = k.div_ceil(GK) * GK; // the padded k the loop runs over (zeros past k)
    for bd in [45, 64, 128] {
        c.fill(0.0).unwrap();
        wp::launch_tiled(k_gemm_f16, blocks, (&a, &b, &c, &d), bd, dev).unwrap();
        let (got, gotp) = (host(&c), host(&d));
        let exact_path = dev.is_cpu() || bd % 32 != 0;
        for i in 0..m {
            for j in 0..n {
                let (acc, exact, mag) = chain(&ad, &bd_, (k, n), (i, j), 0..k);
                let g = got[i * n + j];
                if exact_path {
                    assert_eq!(g.to_bits(), acc.to_bits(), "({i}, {j}) block_dim {bd}");
                }
                let tol = kp as f64 * 2f64.powi(-22) * mag;
                assert!(
                    (g as f64 - exact).abs() <= tol,
                    "({i}, {j}) block_dim {bd}: {g} against {exact} (tolerance {tol:e})"
                );
                let (acc, exact, mag) = chain(&ad, &bd_, (k, n), (i, j), 0..GK.min(k));
                let g = gotp[i * n + j];
                if exact_path {
                    assert_eq!(g.to_bits(), h(acc).to_bits(), "f16 ({i}, {j}) {bd}");
                }
                let tol = (GK as f64 * 2f64.powi(-22) + 2f64.powi(-11)) * mag;
                assert!(
                    (g.to_f64() - exact).abs() <= tol,
                    "f16 ({i}, {j}) block_dim {bd}: {g} against {exact}"
                );
            }
        }
    }
}

const PM: usize = 64;
const PK: usize = 32;
const PN: usize = 64;

/// A GEMM k-loop the CUDA back end pipelines (cp.async stages, accumulators in registers).
#[wp::kernel]
fn k_gemm_pipe(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f32, PM, PN>();
    for k in 0..(a.shape()[1] + PK - 1) / PK {
        let ta = tile_load::<PM, PK>(a, ((i * PM) as i32, (k * PK) as i32));
        let tb = tile_load::<PK, PN>(b, ((k * PK) as i32, (j * PN) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * PM) as i32, (j * PN) as i32));
}

/// The same loop, printed as written: the body's `min` is a call, which the pipelined form
/// does not evaluate ahead (back/cuda_tile_pipe.rs takes pure arithmetic only).
#[wp::kernel]
fn k_gemm_plain(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f32, PM, PN>();
    for k in 0..(a.shape()[1] + PK - 1) / PK {
        let kk = min(k, 1_000_000);
        let ta = tile_load::<PM, PK>(a, ((i * PM) as i32, (kk * PK) as i32));
        let tb = tile_load::<PK, PN>(b, ((kk * PK) as i32, (j * PN) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * PM) as i32, (j * PN) as i32));
}

/// The pipelined k-loop gives the loop's own bits: the same tensor-core k-steps per output in
/// the same order (or, on the CPU and where the pipe is off, the same code). Shapes: aligned
/// (every load a cp.async), and ragged with A's rows 600 bytes apart (A's loads element by
/// element into the stages, B's by cp.async inside and element by element at the edge).
/// Block sizes: 64 (the pipe is off: too many accumulators a thread), 128 and 256 (on, on
/// sm_80+). Both within the module's tensor-core tolerance of the f64 product.
fn f16_gemm_pipelined_k_loop_matches_the_plain_loop(dev: &wp::Device) {
    // The first kernel's k-loop is the pipelined form's, the second's is not.
    assert!(wp::kernel_info(k_gemm_pipe)
        .cuda
        .contains("tile_gemm_pipe_of"));
    assert!(!wp::kernel_info(k_gemm_plain)
        .cuda
        .contains("tile_gemm_pipe_of"));
    for (m, k, n) in [(256usize, 256usize, 256usize), (200, 300, 136)] {
        let ad = values(m * k, 5);
        let bd_ = values(k * n, 17);
        let a = wp::Array::from_slice_shape(&ad, (m, k), dev).unwrap();
        let b = wp::Array::from_slice_shape(&bd_, (k, n), dev).unwrap();
        let c = zeros::<f32, 2>((m, n), dev);
        let c2 = zeros::<f32, 2>((m, n), dev);
        let blocks = (m.div_ceil(PM), n.div_ceil(PN));
        let kp = k.div_ceil(PK) * PK;
        for bd in [64, 128, 256] {
            wp::launch_tiled(k_gemm_pipe, blocks, (&a, &b, &c), bd, dev).unwrap();
            wp::launch_tiled(k_gemm_plain, blocks, (&a, &b, &c2), bd, dev).unwrap();
            let (got, plain) = (host(&c), host(&c2));
            for i in 0..m {
                for j in 0..n {
                    let g = got[i * n + j];
                    let at = format!("({i}, {j}) of {m} x {k} x {n}, block_dim {bd}");
                    assert_eq!(g.to_bits(), plain[i * n + j].to_bits(), "{at}");
                    let (_, exact, mag) = chain(&ad, &bd_, (k, n), (i, j), 0..k);
                    let tol = kp as f64 * 2f64.powi(-22) * mag;
                    assert!((g as f64 - exact).abs() <= tol, "{at}: {g} against {exact}");
                }
            }
        }
    }
}

const WM: usize = 128;
const WK: usize = 64;
const WN: usize = 256;

/// The bench's tiles: a 128 KiB accumulator holds two 48 KiB stages and the operands' slots a
/// third, so the pipelined loop asks the runtime for a fourth (`TileInfo::pipe_extra_bytes`).
#[wp::kernel]
fn k_gemm_wide(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>) {
    let (i, j) = tid();
    let mut acc = tile_zeros::<f32, WM, WN>();
    for k in 0..(a.shape()[1] + WK - 1) / WK {
        let ta = tile_load::<WM, WK>(a, ((i * WM) as i32, (k * WK) as i32));
        let tb = tile_load::<WK, WN>(b, ((k * WK) as i32, (j * WN) as i32));
        tile_matmul(ta, tb, &mut acc);
    }
    tile_store(c, acc, ((i * WM) as i32, (j * WN) as i32));
}

/// A pipelined k-loop with a stage in the shared memory the runtime adds gives the bits of
/// another tiling's (each output the same k-steps in the same order: tensor-core k-steps of 16
/// on the GPU, wgmma or mma.sync alike, one FMA chain on the CPU): `k_gemm_pipe`'s 64 x 64
/// tiles at the same block size, and within the tensor-core tolerance of the f64 product. On
/// Hopper (227 KiB a block) the runtime adds the fourth stage, 48 KiB.
fn f16_gemm_with_an_extra_stage_matches_the_smaller_tiles(dev: &wp::Device) {
    let info = wp::kernel_info(k_gemm_wide);
    let want = info.tile.expect("a tiled kernel").pipe_extra_bytes;
    assert_eq!(want, 48 * 1024);
    for (m, k, n) in [(256usize, 320usize, 512usize), (200, 300, 300)] {
        let ad = values(m * k, 7);
        let bd_ = values(k * n, 11);
        let a = wp::Array::from_slice_shape(&ad, (m, k), dev).unwrap();
        let b = wp::Array::from_slice_shape(&bd_, (k, n), dev).unwrap();
        let c = zeros::<f32, 2>((m, n), dev);
        let c2 = zeros::<f32, 2>((m, n), dev);
        wp::launch_tiled(
            k_gemm_wide,
            (m.div_ceil(WM), n.div_ceil(WN)),
            (&a, &b, &c),
            256,
            dev,
        )
        .unwrap();
        let blocks = (m.div_ceil(PM), n.div_ceil(PN));
        wp::launch_tiled(k_gemm_pipe, blocks, (&a, &b, &c2), 256, dev).unwrap();
        let (got, other) = (host(&c), host(&c2));
        let kp = k.div_ceil(16) * 16;
        for i in 0..m {
            for j in 0..n {
                let g = got[i * n + j];
                let at = format!("({i}, {j}) of {m} x {k} x {n}");
                assert_eq!(g.to_bits(), other[i * n + j].to_bits(), "{at}");
                let (_, exact, mag) = chain(&ad, &bd_, (k, n), (i, j), 0..k);
                let tol = kp as f64 * 2f64.powi(-22) * mag;
                assert!((g as f64 - exact).abs() <= tol, "{at}: {g} against {exact}");
            }
        }
    }
    if dev.is_cuda() {
        let report = wp::compile_reports()
            .into_iter()
            .find(|r| r.kernel == "k_gemm_wide" && r.device == dev.alias() && !r.adjoint)
            .expect("a compile report for k_gemm_wide");
        let ordinal: usize = dev.alias()["cuda:".len()..].parse().unwrap();
        let arch = warp_cuda::Gpu::open(ordinal).unwrap().arch();
        eprintln!(
            "k_gemm_wide on {} (sm_{arch}): {} bytes of shared memory a block, {} of them extra",
            dev.alias(),
            report.shared_bytes,
            report.pipe_extra_bytes
        );
        if arch == 90 {
            assert_eq!(report.pipe_extra_bytes, want, "{report:?}");
        }
        if report.pipe_extra_bytes > 0 {
            let slots = info.tile.unwrap().shared_bytes;
            assert_eq!(report.shared_bytes, slots.next_multiple_of(1024) + want);
        }
    }
}

#[wp::kernel]
fn k_mm_f16_odd(a: Array<f16, 2>, b: Array<f16, 2>, c: Array<f32, 2>) {
    let ta = tile_load::<12, 20>(a, (0, 0));
    let tb = tile_load::<20, 8>(b, (0, 0));
    let mut acc = tile_load::<12, 8>(c, (0, 0));
    tile_matmul(ta, tb, &mut acc);
    tile_store(c, acc, (0, 0));
}

/// Shapes the tensor cores do not take (12 x 20 by 20 x 8: M and K not multiples of 16) use
/// the FMA path on every backend and block size: the host's chain from `c`'s value, exactly.
fn f16_matmul_fma_shapes_are_exact(dev: &wp::Device) {
    let ad = values(12 * 20, 5);
    let bd_ = values(20 * 8, 9);
    let c0: Vec<f32> = (0..12 * 8).map(|t| t as f32 * 0.125 - 3.0).collect();
    let a = wp::Array::from_slice_shape(&ad, (12, 20), dev).unwrap();
    let b = wp::Array::from_slice_shape(&bd_, (20, 8), dev).unwrap();
    for bd in [32, 64] {
        let c = wp::Array::from_slice_shape(&c0, (12, 8), dev).unwrap();
        wp::launch_tiled(k_mm_f16_odd, 1, (&a, &b, &c), bd, dev).unwrap();
        let got = host(&c);
        for i in 0..12 {
            for j in 0..8 {
                let mut acc = c0[i * 8 + j];
                for p in 0..20 {
                    acc = ad[i * 20 + p]
                        .to_f32()
                        .mul_add(bd_[p * 8 + j].to_f32(), acc);
                }
                assert_eq!(got[i * 8 + j].to_bits(), acc.to_bits(), "({i}, {j}) {bd}");
            }
        }
    }
}

/// NVRTC compiles the f16 tile kernels (the tensor-core path on sm_80 and sm_90, the FMA
/// fallback on sm_75 and for a block that is not whole warps) without a GPU: the CUDA tests
/// above compile them only where a GPU is. Skipped, saying so, without NVRTC.
#[test]
fn f16_tile_kernels_compile_under_nvrtc() {
    let archs = match warp_cuda::nvrtc_supported_archs() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("SKIPPED f16_tile_kernels_compile_under_nvrtc: no NVRTC ({e})");
            return;
        }
    };
    let headers: Vec<(&str, &str)> = warp_cuda::HEADERS.to_vec();
    for info in [
        wp::aot::kernel(k_f16_ops),
        wp::aot::kernel(k_gemm_f16),
        wp::aot::kernel(k_mm_f16_odd),
    ] {
        let src = wp::cuda_source::assemble(info);
        assert!(
            info.name == "k_f16_ops" || src.text.contains("#include \"wp_tile_mma.h\""),
            "{}: an f16 matmul includes the tensor-core section",
            info.name
        );
        let smem = info.tile.as_ref().expect("tiled").shared_bytes.to_string();
        for arch in [75, 80, 90].into_iter().filter(|a| archs.contains(a)) {
            for bd in ["45", "128"] {
                let defines = [
                    ("WP_CONTIGUOUS", "1"),
                    ("WP_TILE_BLOCK_DIM", bd),
                    ("WP_TILE_SMEM_BYTES", smem.as_str()),
                ];
                let opts = warp_cuda::CompileOptions {
                    fmad: false,
                    defines: &defines,
                    headers: &headers,
                    ..Default::default()
                };
                if let Err(e) = warp_cuda::compile(&src.text, info.name, &opts, arch) {
                    panic!("{} at sm_{arch}, block_dim {bd}: {e}", info.name);
                }
            }
        }
    }
}

//! Tiles of complex values (`Tile<Vec2, ..>`, `Tile<DVec2, ..>`) and the FFTs `tile_fft` /
//! `tile_ifft` on every backend.
//!
//! Two kinds of check:
//! - **Exact:** each backend's transforms are warp-core's (`tile::fft`, run here on the host)
//!   bit for bit, at several block sizes. The CPU backend calls those functions; the CUDA
//!   section runs the same roundings in the same order (no FMA contraction, no sin/cos), and
//!   tests/cuda_tile_fft_host.rs checks it under the block emulator. So CPU == GPU exactly.
//! - **Accuracy, against an f64 DFT:** every output element within `4 eps log2(N) sqrt(N)
//!   max|x|` of the DFT (radix-2's error grows as `eps log2 N` relative to the row's 2-norm,
//!   which is at most `sqrt(N) max|x|`); the round trip `ifft(fft(x))` is `N x` (Warp's
//!   unnormalised inverse) within `N` times that.

// The code the kernel macro generates for a tiled kernel's CPU block rounds up by hand.
#![allow(clippy::manual_div_ceil)]

use crate::{host, zeros};
use warp_core::tile::{self as ct, Tile2};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    vector_tiles_load_store_and_arithmetic,
    fft_f32_sizes_and_block_sizes,
    fft_f64,
    fft_with_named_consts_round_trips,
    fft_gradients,
    backward_through_vector_transpose_is_refused,
);

/// Seeded values in [-1, 1).
fn values(seed: u64) -> impl FnMut() -> f64 {
    let mut s = seed;
    move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    }
}

#[wp::kernel]
fn k_vec_tiles(a: Array<Vec2, 2>, b: Array<Vec2, 2>, c: Array<DVec2>, d: Array<DVec2>, s: f32) {
    let i = tid();
    let t: Tile<Vec2, 4, 8> = tile_load(a, ((i * 4) as i32, 0));
    let z = tile_zeros::<Vec2, 4, 8>();
    let u = (t + t) * s - t + z;
    let v = 0.5 * u;
    tile_store(b, v, ((i * 4) as i32, 0));
    let e = tile_load::<16>(c, 0);
    let f = e - e * 2.0;
    tile_store(d, f, 0);
    if lane() == 0 && i == 0 {
        let e12 = t[(1, 2)];
        d[16] = DVec2::new(e12.x as f64, e12.y as f64);
    }
}

/// Loads, stores, `tile_zeros`, `+ -`, `*` by a scalar (both sides), `t[(i, j)]` on tiles of
/// `Vec2` (2-D, a ragged edge) and `DVec2` (1-D): exact against the host's glam arithmetic.
fn vector_tiles_load_store_and_arithmetic(dev: &wp::Device) {
    let (m, n) = (10usize, 8usize);
    let mut r = values(1);
    let a: Vec<Vec2> = (0..m * n)
        .map(|_| Vec2::new(r() as f32, r() as f32))
        .collect();
    let c: Vec<DVec2> = (0..16).map(|_| DVec2::new(r(), r())).collect();
    let da = wp::Array::from_slice_shape(&a, (m, n), dev).unwrap();
    let dc = wp::Array::from_slice(&c, dev).unwrap();
    let s = 1.75f32;
    for bd in [1, 32, 45] {
        let db = wp::Array::<Vec2, 2>::zeros((m, n), dev).unwrap();
        let dd = zeros::<DVec2, 1>(17, dev);
        wp::launch_tiled(k_vec_tiles, m.div_ceil(4), (&da, &db, &dc, &dd, s), bd, dev).unwrap();
        let got = host(&db);
        for (k, (g, x)) in got.iter().zip(&a).enumerate() {
            let want = 0.5 * ((*x + *x) * s - *x + Vec2::ZERO);
            assert_eq!(
                g.to_array().map(f32::to_bits),
                want.to_array().map(f32::to_bits),
                "element {k}, block_dim {bd}"
            );
        }
        let gd = host(&dd);
        for k in 0..16 {
            assert_eq!(gd[k], c[k] - c[k] * 2.0, "element {k}");
        }
        assert_eq!(gd[16], DVec2::new(a[n + 2].x as f64, a[n + 2].y as f64));
    }
}

macro_rules! fft_kernel {
    ($name:ident, $v:ident, $m:tt, $n:tt) => {
        /// Block `b` transforms rows `b M ..` of `x` into `y` (forward) and `z` (inverse of
        /// the forward: `N x`).
        #[wp::kernel]
        fn $name(x: Array<$v, 2>, y: Array<$v, 2>, z: Array<$v, 2>) {
            let b = tid();
            let o = (b * $m) as i32;
            let mut a = tile_load::<$m, $n>(x, (o, 0));
            tile_fft(&mut a);
            tile_store(y, a, (o, 0));
            tile_ifft(&mut a);
            tile_store(z, a, (o, 0));
        }
    };
}

fft_kernel!(k_fft_f32_1_2, Vec2, 1, 2);
fft_kernel!(k_fft_f32_3_4, Vec2, 3, 4);
fft_kernel!(k_fft_f32_2_16, Vec2, 2, 16);
fft_kernel!(k_fft_f32_4_64, Vec2, 4, 64);
fft_kernel!(k_fft_f32_2_256, Vec2, 2, 256);
fft_kernel!(k_fft_f64_2_32, DVec2, 2, 32);
fft_kernel!(k_fft_f64_1_128, DVec2, 1, 128);

/// The f64 DFT of a row.
fn dft(x: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let n = x.len();
    (0..n)
        .map(|k| {
            let mut acc = (0.0, 0.0);
            for (j, &(a, b)) in x.iter().enumerate() {
                let th = -2.0 * std::f64::consts::PI * ((j * k) % n) as f64 / n as f64;
                let (s, c) = th.sin_cos();
                acc.0 += a * c - b * s;
                acc.1 += a * s + b * c;
            }
            acc
        })
        .collect()
}

/// The complex values' elements: bits, and the parts in f64.
trait Cx: Copy + wp::Element + PartialEq + std::fmt::Debug + ct::fft::Complex {
    fn parts(self) -> (f64, f64);
    fn from64(re: f64, im: f64) -> Self;
    const EPS: f64;
}
impl Cx for Vec2 {
    fn parts(self) -> (f64, f64) {
        (self.x as f64, self.y as f64)
    }
    fn from64(re: f64, im: f64) -> Self {
        Vec2::new(re as f32, im as f32)
    }
    const EPS: f64 = f32::EPSILON as f64;
}
impl Cx for DVec2 {
    fn parts(self) -> (f64, f64) {
        (self.x, self.y)
    }
    fn from64(re: f64, im: f64) -> Self {
        DVec2::new(re, im)
    }
    const EPS: f64 = f64::EPSILON;
}

/// Runs `k` (an `fft_kernel!` of `M x N`) on `B` blocks of random values at several block
/// sizes: bit for bit warp-core's transforms, and within the module's tolerance of the DFT.
fn check<C: Cx, const M: usize, const N: usize>(
    dev: &wp::Device,
    launch: impl Fn(&wp::Array<C, 2>, &wp::Array<C, 2>, &wp::Array<C, 2>, usize),
    blocks: usize,
) {
    let rows = blocks * M;
    let mut r = values(N as u64 * 7 + M as u64);
    let x: Vec<C> = (0..rows * N).map(|_| C::from64(r(), r())).collect();
    let dx = wp::Array::from_slice_shape(&x, (rows, N), dev).unwrap();
    // The host's transforms (warp-core), tile by tile.
    let mut want_y = Vec::new();
    let mut want_z = Vec::new();
    for b in 0..blocks {
        let t = Tile2::<C, M, N> {
            data: std::array::from_fn(|i| std::array::from_fn(|j| x[(b * M + i) * N + j])),
        };
        let y = ct::fft(&t);
        let z = ct::ifft(&y);
        want_y.extend(y.data.iter().flatten().copied());
        want_z.extend(z.data.iter().flatten().copied());
    }
    let l = N.trailing_zeros().max(1) as f64;
    let tol = 4.0 * C::EPS * l * (N as f64).sqrt() * 2f64.sqrt();
    for bd in [1, 32, 45, 128] {
        let dy = wp::Array::<C, 2>::zeros((rows, N), dev).unwrap();
        let dz = wp::Array::<C, 2>::zeros((rows, N), dev).unwrap();
        launch(&dx, &dy, &dz, bd);
        let (gy, gz) = (host(&dy), host(&dz));
        let bits = |v: &[C]| -> Vec<u8> { bytemuck::cast_slice(v).to_vec() };
        assert!(
            bits(&gy) == bits(&want_y),
            "fft {M}x{N}: not warp-core's bits at block_dim {bd}"
        );
        assert!(
            bits(&gz) == bits(&want_z),
            "ifft {M}x{N}: not warp-core's bits at block_dim {bd}"
        );
    }
    for row in 0..rows {
        let xr: Vec<(f64, f64)> = x[row * N..][..N].iter().map(|c| c.parts()).collect();
        let want = dft(&xr);
        for k in 0..N {
            let (g, w) = (want_y[row * N + k].parts(), want[k]);
            let e = (g.0 - w.0).abs().max((g.1 - w.1).abs());
            assert!(
                e <= tol,
                "fft {M}x{N} row {row} k {k}: error {e:e} > {tol:e}"
            );
            let (z, x0) = (want_z[row * N + k].parts(), xr[k]);
            let n = N as f64;
            let e = (z.0 - n * x0.0).abs().max((z.1 - n * x0.1).abs());
            assert!(e <= 2.0 * n * tol, "round trip {M}x{N}: {e:e}");
        }
    }
}

fn fft_f32_sizes_and_block_sizes(dev: &wp::Device) {
    check::<Vec2, 1, 2>(
        dev,
        |x, y, z, bd| wp::launch_tiled(k_fft_f32_1_2, 3, (x, y, z), bd, dev).unwrap(),
        3,
    );
    check::<Vec2, 3, 4>(
        dev,
        |x, y, z, bd| wp::launch_tiled(k_fft_f32_3_4, 2, (x, y, z), bd, dev).unwrap(),
        2,
    );
    check::<Vec2, 2, 16>(
        dev,
        |x, y, z, bd| wp::launch_tiled(k_fft_f32_2_16, 3, (x, y, z), bd, dev).unwrap(),
        3,
    );
    check::<Vec2, 4, 64>(
        dev,
        |x, y, z, bd| wp::launch_tiled(k_fft_f32_4_64, 2, (x, y, z), bd, dev).unwrap(),
        2,
    );
    check::<Vec2, 2, 256>(
        dev,
        |x, y, z, bd| wp::launch_tiled(k_fft_f32_2_256, 2, (x, y, z), bd, dev).unwrap(),
        2,
    );
}

fn fft_f64(dev: &wp::Device) {
    check::<DVec2, 2, 32>(
        dev,
        |x, y, z, bd| wp::launch_tiled(k_fft_f64_2_32, 3, (x, y, z), bd, dev).unwrap(),
        3,
    );
    check::<DVec2, 1, 128>(
        dev,
        |x, y, z, bd| wp::launch_tiled(k_fft_f64_1_128, 2, (x, y, z), bd, dev).unwrap(),
        2,
    );
}

const TM: usize = 2;
const TN: usize = 8;

/// Warp's example, line for line: load, `tile_fft`, `tile_ifft`, store, with the shape in
/// named consts.
#[wp::kernel]
fn fft_tiled(x: Array<Vec2, 2>, y: Array<Vec2, 2>) {
    let (i, j) = tid();
    let mut a = tile_load::<TM, TN>(x, ((i * TM) as i32, (j * TN) as i32));
    tile_fft(&mut a);
    tile_ifft(&mut a);
    tile_store(y, a, ((i * TM) as i32, (j * TN) as i32));
}

fn fft_with_named_consts_round_trips(dev: &wp::Device) {
    let mut r = values(5);
    let x: Vec<Vec2> = (0..TM * TN)
        .map(|_| Vec2::new(r() as f32, r() as f32))
        .collect();
    let dx = wp::Array::from_slice_shape(&x, (TM, TN), dev).unwrap();
    let dy = wp::Array::<Vec2, 2>::zeros((TM, TN), dev).unwrap();
    wp::launch_tiled(fft_tiled, (1, 1), (&dx, &dy), 64, dev).unwrap();
    for (g, x) in host(&dy).iter().zip(&x) {
        assert!(
            (*g - *x * TN as f32).length() < 1e-5 * TN as f32,
            "{g} vs {x} * {TN}"
        );
    }
}

const GM: usize = 3;
const GN: usize = 8;

/// Each block transforms `GM` rows of `x` (a ragged last block), stores the spectrum in `s`,
/// scales it by `w[0]` (with `+`, `-` and `*` on both sides: `u = 2 w t - 0.5 t + t w`), takes
/// the inverse and stores that in `y`: gradients through `tile_fft` alone (`s`) and through
/// both transforms, the operators of tiles of vectors and a uniform scalar (`y`). `t` is read
/// by the products after its transform, so its value before goes on the lanes' stacks.
#[wp::kernel]
fn k_fft_grad(x: Array<DVec2, 2>, w: Array<f64>, s: Array<DVec2, 2>, y: Array<DVec2, 2>) {
    let b = tid();
    let o = (b * GM) as i32;
    let mut t = tile_load::<GM, GN>(x, (o, 0));
    tile_fft(&mut t);
    tile_store(s, t, (o, 0));
    let c = w[0];
    let mut u = (2.0 * c) * t - t * 0.5 + t * c;
    tile_ifft(&mut u);
    tile_store(y, u, (o, 0));
}

/// A loss that is not linear in the spectrum: `tile_fft`, then the squares of the spectrum's
/// parts (elementwise, read back by each lane), then `tile_ifft` of a tile that is itself
/// loaded again and reassigned in place.
#[wp::kernel]
fn k_fft_square(x: Array<DVec2, 2>, s: Array<DVec2, 2>, out: Array<f64>) {
    let mut t = tile_load::<GM, GN>(x, (0, 0));
    tile_fft(&mut t);
    tile_ifft(&mut t);
    tile_fft(&mut t);
    tile_store(s, t, (0, 0));
    let i = lane();
    if i < GM * GN {
        let e = t[((i / GN) as i32, (i % GN) as i32)];
        out[i] = e.x * e.x - 0.5 * e.y * e.y + e.x * e.y;
    }
}

/// `x` as an `f64` array (its parts, for `gradcheck`) and as `(rows, GN)` complex values.
fn complex_input(
    rows: usize,
    seed: u64,
    dev: &wp::Device,
) -> (wp::Array<f64>, wp::Array<DVec2, 2>) {
    let mut r = values(seed);
    let parts: Vec<f64> = (0..2 * rows * GN).map(|_| r()).collect();
    let x = wp::Array::from_slice(&parts, dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let c = x
        .reinterpret::<DVec2>()
        .unwrap()
        .reshape((rows, GN))
        .unwrap();
    (x, c)
}

/// Backward through `tile_fft` / `tile_ifft` (Warp's rule: the adjoint of the unnormalised
/// forward transform is the unnormalised inverse of the seed, real and imaginary parts taken
/// as independent reals, and the other way round), checked by `gradcheck` against central
/// differences in f64 at block sizes 1, 5 and 32 (two blocks, the second ragged), within 1e-6
/// relative (the transforms are linear: the differences' error is rounding only, near 1e-10).
fn fft_gradients(dev: &wp::Device) {
    let rows = 5;
    let (x, xc) = complex_input(rows, 21, dev);
    let w = wp::Array::from_slice(&[0.75f64], dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let s = zeros::<f64, 1>(2 * rows * GN, dev).with_grad().unwrap();
    let y = zeros::<f64, 1>(2 * rows * GN, dev).with_grad().unwrap();
    let view = |a: &wp::Array<f64>| {
        a.reinterpret::<DVec2>()
            .unwrap()
            .reshape((rows, GN))
            .unwrap()
    };
    let (sc, yc) = (view(&s), view(&y));
    let blocks = (rows + GM - 1) / GM;
    for bd in [1, 5, 32] {
        let run = || wp::launch_tiled(k_fft_grad, blocks, (&xc, &w, &sc, &yc), bd, dev);
        crate::tile_grad::check(
            &format!("tile_fft spectrum, block_dim {bd}"),
            run,
            &[&x, &w],
            &s,
        );
        let run = || wp::launch_tiled(k_fft_grad, blocks, (&xc, &w, &sc, &yc), bd, dev);
        crate::tile_grad::check(
            &format!("tile_fft round trip, block_dim {bd}"),
            run,
            &[&x, &w],
            &y,
        );
    }
    let (x, xc) = complex_input(GM, 22, dev);
    let s = zeros::<f64, 1>(2 * GM * GN, dev).with_grad().unwrap();
    let sc = s.reinterpret::<DVec2>().unwrap().reshape((GM, GN)).unwrap();
    let out = zeros::<f64, 1>(GM * GN, dev).with_grad().unwrap();
    for bd in [GM * GN, 32] {
        let run = || wp::launch_tiled(k_fft_square, 1, (&xc, &sc, &out), bd, dev);
        crate::tile_grad::check(
            &format!("squares of a spectrum, block_dim {bd}"),
            run,
            &[&x],
            &out,
        );
    }
}

/// The gradients of `k_fft_grad` (one backward from all-ones seeds) at block size 32.
fn fft_grads_on(dev: &wp::Device) -> Vec<Vec<f64>> {
    let rows = 5;
    let (x, xc) = complex_input(rows, 23, dev);
    let w = wp::Array::from_slice(&[-1.25f64], dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let s = wp::Array::<DVec2, 2>::zeros((rows, GN), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let y = wp::Array::<DVec2, 2>::zeros((rows, GN), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        let blocks = (rows + GM - 1) / GM;
        wp::launch_tiled(k_fft_grad, blocks, (&xc, &w, &s, &y), 32, dev).unwrap();
    }
    s.grad().unwrap().fill(DVec2::new(1.0, -0.5)).unwrap();
    y.grad().unwrap().fill(DVec2::new(0.25, 2.0)).unwrap();
    tape.backward_from_grads().unwrap();
    [&x, &w].iter().map(|a| host(&a.grad().unwrap())).collect()
}

/// The FFT adjoints on a GPU give the CPU's bits (the same transforms run in the same order):
/// `x`'s gradient exactly; `w`'s sums two blocks' contributions through an atomic, in an order
/// neither backend fixes, so to 1e-13 relative. Skipped, saying so, without a GPU.
#[test]
fn fft_gradients_cpu_and_gpu_are_equal() {
    let Ok(gpu) = wp::get_device(&crate::test_gpu()) else {
        eprintln!("SKIPPED fft_gradients_cpu_and_gpu_are_equal: no GPU");
        return;
    };
    let _gpu = crate::gpu_lock();
    let (c, g) = (
        fft_grads_on(&wp::get_device("cpu").unwrap()),
        fft_grads_on(&gpu),
    );
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(
        bits(&c[0]),
        bits(&g[0]),
        "x: CPU {:?} vs GPU {:?}",
        c[0],
        g[0]
    );
    for (a, b) in c[1].iter().zip(&g[1]) {
        assert!(
            (a - b).abs() <= 1e-13 * a.abs().max(1.0),
            "w: CPU {a} vs GPU {b}"
        );
    }
}

#[wp::kernel]
fn k_vec_transpose(x: Array<DVec2, 2>, y: Array<DVec2, 2>) {
    let t = tile_load::<4, 8>(x, (0, 0));
    tile_store(y, tile_transpose(t), (0, 0));
}

/// Backward through a row whose adjoint is written for scalar elements, on a tile of vectors,
/// is an error naming the kernel and the row, never a silent zero.
fn backward_through_vector_transpose_is_refused(dev: &wp::Device) {
    let x = wp::Array::<DVec2, 2>::zeros((4, 8), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let y = wp::Array::<DVec2, 2>::zeros((8, 4), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_vec_transpose, 1, (&x, &y), 32, dev).unwrap();
    }
    let e = tape.backward_from_grads().unwrap_err();
    assert!(matches!(e, wp::Error::NotDifferentiable { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("k_vec_transpose") && msg.contains("`tile_transpose` on tiles of vectors"),
        "{msg}"
    );
}

/// The CUDA printer translates the FFT kernels' adjoints (NVRTC compiles them only on a GPU:
/// `fft_gradients` there).
#[test]
fn fft_adjoints_have_a_cuda_form() {
    for info in [wp::kernel_info(k_fft_grad), wp::kernel_info(k_fft_square)] {
        assert!(
            info.cuda_adjoint_error.is_none(),
            "{}: {:?}",
            info.name,
            info.cuda_adjoint_error
        );
        if std::env::var_os("WARP_TEST_PRINT_CUDA").is_some() {
            println!("// ---- {}\n{}", info.name, info.cuda_adjoint);
        }
    }
}

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
    backward_through_tile_fft_is_refused_by_name,
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

fn backward_through_tile_fft_is_refused_by_name(dev: &wp::Device) {
    let x = wp::Array::<Vec2, 2>::zeros((4, 8), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let y = wp::Array::<Vec2, 2>::zeros((4, 8), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let z = wp::Array::<Vec2, 2>::zeros((4, 8), dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_fft_f32_3_4, 1, (&x, &y, &z), 32, dev).unwrap();
    }
    let e = tape.backward_from_grads().unwrap_err();
    assert!(matches!(e, wp::Error::NotDifferentiable { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("k_fft_f32_3_4") && msg.contains("tile_fft"),
        "{msg}"
    );
}

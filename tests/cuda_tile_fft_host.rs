//! The CUDA tile FFTs (`warp-cuda/cuda/wp_tile_fft.h`), checked without a GPU against the
//! CPU's (`warp_core::tile::fft`), bit for bit.
//!
//! A driver (`warp-cuda/cuda/tests/wp_tile_fft_driver.cpp`) runs the header's cooperative
//! `tile_fft` then `tile_ifft` (in place, one slot) in one block under the block emulator
//! (`wp_prim_emu.h`: the block's threads are fibers that run in a new random order between
//! barriers, so a read that races a write in the same phase would show). It is compiled with
//! g++ without FMA contraction for several block sizes: 1, 7, a warp, 45 (a partial warp),
//! 128, 256. Every case must give warp-core's bits: the two compute the same twiddles (no
//! sin/cos: half-angle square roots and products in f64) and run the same butterflies in the
//! same order of roundings. What this cannot check is what only hardware does (NVRTC's
//! acceptance, real shared memory); the suite's `tile_fft` tests do that on a GPU. The same
//! driver checks the FFTs' adjoints (`adj_tile_fft`/`adj_tile_ifft`, in the seed's slot) and
//! the elementwise adjoints of `wp_adjoint_tile.h` on tiles of vectors against
//! `warp_core::tile::adjoint`, bit for bit.
//!
//! Skipped, saying so, without g++.

#[path = "common/host_cpp.rs"]
mod host_cpp;

use glam::{DVec2, Vec2};
use std::process::Command;
use warp_core::tile::{self, adjoint as ta, Tile, Tile2};

const BLOCK_DIMS: [usize; 6] = [1, 7, 32, 45, 128, 256];

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

fn bytes<X: Tile>(t: &X) -> Vec<u8>
where
    X::Elem: bytemuck::Pod,
{
    bytemuck::cast_slice(t.as_flat()).to_vec()
}

fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

/// Runs `cases` (name, input bytes) on the driver for block size `bd`: each case's output.
fn run(bd: usize, cases: &[(String, Vec<u8>)]) -> Vec<Vec<u8>> {
    let (dir, exe) = host_cpp::compile_driver(
        &format!("tile_fft_{bd}"),
        include_str!("../warp-cuda/cuda/tests/wp_tile_fft_driver.cpp"),
        &[&format!("WP_TILE_BLOCK_DIM={bd}")],
    );
    let script: String = cases
        .iter()
        .map(|(n, b)| format!("run {n} {}\n", hex(b)))
        .collect();
    let path = dir.join("script.txt");
    std::fs::write(&path, script).unwrap();
    let out = Command::new(&exe).arg(&path).output().unwrap();
    assert!(
        out.status.success(),
        "driver (block size {bd}): {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let got: Vec<Vec<u8>> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| unhex(l.strip_prefix("out ").expect("an out line")))
        .collect();
    assert_eq!(got.len(), cases.len());
    got
}

/// A case: random values (some specials: zeros, a signed zero), warp-core's `fft` then `ifft`.
macro_rules! case {
    ($cases:ident, $want:ident, $c:ident, $s:ty, $m:literal, $n:literal) => {{
        let mut r = values($m * 1000 + $n);
        let mut x = Tile2::<$c, $m, $n> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| $c::new(r() as $s, r() as $s))),
        };
        x.data[0][0] = $c::new(0.0, -0.0);
        let y = tile::fft(&x);
        let z = tile::ifft(&y);
        $cases.push((format!("{}_{}_{}", stringify!($c), $m, $n), bytes(&x)));
        $want.push([bytes(&y), bytes(&z)].concat());
    }};
}

#[test]
fn fft_and_ifft_match_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_tile_fft_host: no g++ on this machine");
        return;
    }
    let mut cases = Vec::new();
    let mut want = Vec::new();
    case!(cases, want, Vec2, f32, 3, 1);
    case!(cases, want, Vec2, f32, 1, 2);
    case!(cases, want, Vec2, f32, 3, 4);
    case!(cases, want, Vec2, f32, 5, 8);
    case!(cases, want, Vec2, f32, 2, 16);
    case!(cases, want, Vec2, f32, 4, 64);
    case!(cases, want, Vec2, f32, 1, 256);
    case!(cases, want, Vec2, f32, 2, 256);
    case!(cases, want, DVec2, f64, 2, 2);
    case!(cases, want, DVec2, f64, 3, 32);
    case!(cases, want, DVec2, f64, 1, 128);
    case!(cases, want, DVec2, f64, 2, 256);
    // The elementwise operators of tiles of vectors: 0.5 ((x + x) 1.75 - x) + 0.
    let mut r = values(99);
    let x = Tile2::<Vec2, 3, 5> {
        data: std::array::from_fn(|_| std::array::from_fn(|_| Vec2::new(r() as f32, r() as f32))),
    };
    cases.push(("ops_Vec2_3_5".into(), bytes(&x)));
    want.push(bytes(&(0.5 * ((x + x) * 1.75 - x) + Tile2::zeros())));
    let x = Tile2::<DVec2, 2, 4> {
        data: std::array::from_fn(|_| std::array::from_fn(|_| DVec2::new(r(), r()))),
    };
    cases.push(("ops_DVec2_2_4".into(), bytes(&x)));
    want.push(bytes(&(0.5 * ((x + x) * 1.75 - x) + Tile2::zeros())));
    for bd in BLOCK_DIMS {
        let (mut cases, mut want) = (cases.clone(), want.clone());
        adjoint_cases(bd, &mut cases, &mut want);
        let got = run(bd, &cases);
        for ((name, _), (g, w)) in cases.iter().zip(got.iter().zip(&want)) {
            assert!(g == w, "{name} at block size {bd}: not warp-core's bits");
        }
    }
}

/// The FFTs' adjoints (`adj_*`: the seed transformed in its slot, `adj_tile_fft` then
/// `adj_tile_ifft`) and the elementwise adjoints on tiles of vectors (`vadj_*`, the driver's
/// `k_vadj`; a uniform scalar's adjoint is a block total, so it depends on `bd`), as
/// warp-core computes them.
fn adjoint_cases(bd: usize, cases: &mut Vec<(String, Vec<u8>)>, want: &mut Vec<Vec<u8>>) {
    macro_rules! adj {
        ($c:ident, $s:ty, $m:literal, $n:literal) => {{
            let mut r = values($m * 77 + $n);
            let x = Tile2::<$c, $m, $n> {
                data: std::array::from_fn(|_| {
                    std::array::from_fn(|_| $c::new(r() as $s, r() as $s))
                }),
            };
            let mut a = x;
            ta::adj_tile_fft(&x, &mut a, &x, bd);
            let y = a;
            ta::adj_tile_ifft(&x, &mut a, &y, bd);
            cases.push((format!("adj_{}_{}_{}", stringify!($c), $m, $n), bytes(&x)));
            want.push([bytes(&y), bytes(&a)].concat());
        }};
    }
    adj!(Vec2, f32, 3, 8);
    adj!(DVec2, f64, 2, 32);
    macro_rules! vadj {
        ($c:ident, $s:ty, $m:literal, $n:literal) => {{
            let mut r = values($m * 91 + $n);
            let x = Tile2::<$c, $m, $n> {
                data: std::array::from_fn(|_| {
                    std::array::from_fn(|_| $c::new(r() as $s, r() as $s))
                }),
            };
            let mut rev = x;
            for (d, v) in rev.as_flat_mut().iter_mut().zip(x.as_flat().iter().rev()) {
                *d = *v;
            }
            let (mut a, mut b) = (Tile2::<$c, $m, $n>::zeros(), Tile2::<$c, $m, $n>::zeros());
            let (s, mut gs, mut gt): ($s, $s, $s) = (1.75, 0.0, 0.0);
            ta::adj_tile_mul_ts(&x, s, &mut a, &mut gs, &rev, bd);
            ta::adj_tile_mul_st(s, &x, &mut gt, &mut a, &rev, bd);
            ta::adj_tile_add_tt(&x, &rev, &mut a, &mut b, &rev, bd);
            ta::adj_tile_sub_tt(&x, &rev, &mut a, &mut b, &rev, bd);
            a.data[0][0] += x.as_flat()[1];
            cases.push((format!("vadj_{}_{}_{}", stringify!($c), $m, $n), bytes(&x)));
            let scalars = [gs.to_ne_bytes(), gt.to_ne_bytes()].concat();
            want.push([bytes(&a), bytes(&b), scalars].concat());
        }};
    }
    vadj!(Vec2, f32, 3, 5);
    vadj!(DVec2, f64, 4, 9);
}

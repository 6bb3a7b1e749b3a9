//! The CUDA tile linear algebra (`warp-cuda/cuda/wp_tile_linalg.h`), checked without a GPU
//! against the CPU's (`warp_core::tile::linalg`), bit for bit.
//!
//! A driver (`warp-cuda/cuda/tests/wp_tile_linalg_driver.cpp`) runs the header's cooperative
//! Cholesky factor and solves in one block under the block emulator (`wp_prim_emu.h`: the
//! block's threads are fibers that run in a new random order between barriers, so a read that
//! races a write in the same phase would show). It is compiled with g++ without FMA
//! contraction for several block sizes: 1, a warp, 45 (a partial warp), 64 (the benchmark's),
//! 96, 256. Every case must give warp-core's bits: the two run the same roundings in the same
//! order. From a whole warp up, matrices of up to 32 rows run warp-synchronously (warp 0, a lane
//! per column, shuffles: the emulator's `__shfl_sync` is an exchange among the warp's lanes
//! alone) and each operation takes one block barrier, which the driver counts; block size 1
//! runs the block-wide forms (N + 2 barriers for a factor). What this cannot check is what only
//! hardware does (NVRTC's acceptance, real shared memory, the speed); the suite's `tile_linalg`
//! tests and `benches/gpu.rs --tile-cholesky` do that on a GPU.
//!
//! Skipped, saying so, without g++.

#[path = "common/host_cpp.rs"]
mod host_cpp;

use std::process::Command;
use warp_core::tile::{self, Tile, Tile1, Tile2};

const BLOCK_DIMS: [usize; 6] = [1, 32, 45, 64, 96, 256];

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

/// `B Bᵀ + n I`, rounded to `T`: symmetric positive definite.
fn spd<const N: usize>(seed: u64) -> [[f64; N]; N] {
    let mut r = values(seed);
    let b: [[f64; N]; N] = std::array::from_fn(|_| std::array::from_fn(|_| r()));
    std::array::from_fn(|i| {
        std::array::from_fn(|j| {
            (0..N).map(|k| b[i][k] * b[j][k]).sum::<f64>() + if i == j { N as f64 } else { 0.0 }
        })
    })
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

/// Runs `cases` (name, input bytes) on the driver for block size `bd`: each case's output, and
/// the block barriers its factor, lower solve, Cholesky solve and upper solve took.
fn run(bd: usize, cases: &[(String, Vec<u8>)]) -> Vec<(Vec<u8>, [u64; 4])> {
    let (dir, exe) = host_cpp::compile_driver(
        &format!("tile_linalg_{bd}"),
        include_str!("../warp-cuda/cuda/tests/wp_tile_linalg_driver.cpp"),
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
    let text = String::from_utf8(out.stdout).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    let got: Vec<(Vec<u8>, [u64; 4])> = lines
        .chunks(2)
        .map(|l| {
            let bytes = unhex(l[0].strip_prefix("out ").expect("an out line"));
            let n: Vec<u64> = l[1]
                .strip_prefix("barriers ")
                .expect("a barriers line")
                .split(' ')
                .map(|v| v.parse().unwrap())
                .collect();
            (bytes, [n[0], n[1], n[2], n[3]])
        })
        .collect();
    assert_eq!(got.len(), cases.len());
    got
}

/// What warp-core gives for a case: L, Z = lower_solve(L, y), X = cholesky_solve(L, y),
/// W = upper_solve(Lᵀ, Z), as bytes; `solve` is the rank's (1-D or 2-D) trio of solves.
macro_rules! case {
    ($cases:ident, $want:ident, $t:ty, $n:literal, 0, $a:expr, $seed:expr) => {{
        let a = Tile2::<$t, $n, $n> {
            data: $a.map(|r| r.map(|v| v as $t)),
        };
        let mut r = values($seed);
        let y = Tile1::<$t, $n> {
            data: std::array::from_fn(|_| r() as $t),
        };
        let l = tile::cholesky(&a);
        let z = tile::lower_solve1(&l, &y);
        let x = tile::cholesky_solve1(&l, &y);
        let w = tile::upper_solve1(&tile::transpose(&l), &z);
        let mut input = bytes(&a);
        input.extend(bytes(&y));
        $cases.push((format!("{}_{}_0", stringify!($t), $n), input));
        $want.push([bytes(&l), bytes(&z), bytes(&x), bytes(&w)].concat());
    }};
    ($cases:ident, $want:ident, $t:ty, $n:literal, $k:literal, $a:expr, $seed:expr) => {{
        let a = Tile2::<$t, $n, $n> {
            data: $a.map(|r| r.map(|v| v as $t)),
        };
        let mut r = values($seed);
        let y = Tile2::<$t, $n, $k> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r() as $t)),
        };
        let l = tile::cholesky(&a);
        let z = tile::lower_solve2(&l, &y);
        let x = tile::cholesky_solve2(&l, &y);
        let w = tile::upper_solve2(&tile::transpose(&l), &z);
        let mut input = bytes(&a);
        input.extend(bytes(&y));
        $cases.push((format!("{}_{}_{}", stringify!($t), $n, $k), input));
        $want.push([bytes(&l), bytes(&z), bytes(&x), bytes(&w)].concat());
    }};
}

#[test]
fn cholesky_and_solves_match_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_tile_linalg_host: no g++ on this machine");
        return;
    }
    let mut cases = Vec::new();
    let mut want = Vec::new();
    case!(cases, want, f32, 1, 0, spd::<1>(1), 2);
    case!(cases, want, f32, 4, 0, spd::<4>(3), 4);
    case!(cases, want, f32, 5, 3, spd::<5>(5), 6);
    case!(cases, want, f32, 16, 0, spd::<16>(7), 8);
    case!(cases, want, f32, 16, 3, spd::<16>(9), 10);
    case!(cases, want, f32, 32, 0, spd::<32>(11), 12);
    case!(cases, want, f64, 4, 2, spd::<4>(13), 14);
    case!(cases, want, f64, 16, 0, spd::<16>(15), 16);
    case!(cases, want, f64, 32, 0, spd::<32>(17), 18);
    case!(cases, want, f64, 32, 2, spd::<32>(19), 20);
    // Not positive definite (pivot 2 is 1 - 4): an all-NaN factor and NaN solutions.
    let mut bad = spd::<4>(21);
    bad[1][0] = 2.0 * bad[0][0].sqrt() * bad[1][1].sqrt();
    case!(cases, want, f32, 4, 0, bad, 22);
    assert!(
        bytemuck::cast_slice::<u8, f32>(&want.last().unwrap()[..64])
            .iter()
            .all(|v| v.is_nan()),
        "the bad case is not positive definite"
    );
    // Signed zeros and an unread upper triangle: the lower triangle holds -0.0 off the
    // diagonal in its first column (so L keeps -0.0 there and products of zeros meet
    // subtractions), the upper triangle NaN. The warp form loads every column whole and keeps
    // the strict upper part as scratch that nothing reads back: a NaN there must not reach L.
    let mut odd = spd::<32>(25);
    for (i, row) in odd.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            if j > i {
                *v = f64::NAN;
            } else if j == 0 && i > 0 {
                *v = -0.0;
            }
        }
    }
    case!(cases, want, f32, 32, 0, odd, 26);
    case!(cases, want, f64, 32, 0, odd, 27);
    assert!(
        want.last().unwrap()[..8 * 32 * 32]
            .chunks(8)
            .all(|b| !f64::from_le_bytes(b.try_into().unwrap()).is_nan()),
        "the NaN upper triangle is not read by warp-core"
    );
    assert_eq!(
        want.last().unwrap()[8 * 32..8 * 33],
        (-0.0f64).to_le_bytes(),
        "L[1][0] is -0.0"
    );
    // In place: `tile_cholesky(A, A)`.
    let a16 = Tile2::<f32, 16, 16> {
        data: spd::<16>(23).map(|r| r.map(|v| v as f32)),
    };
    cases.push(("inplace_f32_16".into(), bytes(&a16)));
    want.push(bytes(&tile::cholesky(&a16)));
    for bd in BLOCK_DIMS {
        let got = run(bd, &cases);
        for ((name, _), ((g, barriers), w)) in cases.iter().zip(got.iter().zip(&want)) {
            // NaNs compare by bits too: both produce the default quiet NaN.
            assert!(
                g == w,
                "block size {bd}, case {name}: the GPU header differs from warp-core"
            );
            if bd < 32 {
                // Block-wide forms: a barrier per column and more (not pinned down here).
                continue;
            }
            // Warp-synchronous: one barrier per operation, whatever N (the in-place case only
            // factors).
            let expect = match name.starts_with("inplace") {
                false => [1, 1, 1, 1],
                true => [1, 0, 0, 0],
            };
            assert_eq!(
                *barriers, expect,
                "block size {bd}, case {name}: block barriers (factor, lower, Cholesky, upper \
                 solve)"
            );
        }
    }
}

/// The header as NVRTC compiles it, for the shapes and block sizes of both forms: the warp
/// forms' shuffles and register arrays (N <= 32, whole first warp), the block-wide ones
/// (N > 32, and blocks under a warp), a partial last warp (45), one right-hand side and several.
const NVRTC_SOURCE: &str = r#"
#include "wp_tile.h"
#include "wp_tile_linalg.h"

template <typename T, int N, int K>
__device__ unsigned char* linalg(unsigned char* at) {
  wp::tile_t<T, N, N> a(at);
  at += (wp::tile_t<T, N, N>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, N, N> l(at);
  at += (wp::tile_t<T, N, N>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, N> y(at);
  at += (wp::tile_t<T, N>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, N> x(at);
  at += (wp::tile_t<T, N>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, N, K> ys(at);
  at += (wp::tile_t<T, N, K>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_t<T, N, K> xs(at);
  at += (wp::tile_t<T, N, K>::BYTES + 15) & ~(wp::usize)15;
  wp::tile_cholesky(l, a);
  wp::tile_cholesky(a, a);
  wp::tile_cholesky_solve(x, l, y);
  wp::tile_lower_solve(x, l, y);
  wp::tile_upper_solve(x, l, y);
  wp::tile_cholesky_solve(xs, l, ys);
  wp::tile_lower_solve(xs, l, ys);
  wp::tile_upper_solve(xs, l, ys);
  return at;
}

extern "C" __global__ void linalg_all() {
  extern __shared__ __align__(16) unsigned char smem[];
  linalg<wp::f32, 32, 3>(smem);
  linalg<wp::f32, 5, 2>(smem);
  linalg<wp::f64, 32, 2>(smem);
  linalg<wp::f64, 1, 4>(smem);
  linalg<wp::f32, 40, 2>(smem);
}
"#;

#[test]
fn nvrtc_compiles_the_linalg_header() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED nvrtc_compiles_the_linalg_header: {e}");
        return;
    }
    for bd in ["1", "45", "64"] {
        let defines = [("WP_TILE_BLOCK_DIM", bd)];
        let opts = warp_cuda::CompileOptions {
            fmad: false,
            defines: &defines,
            headers: warp_cuda::HEADERS,
            ..Default::default()
        };
        let c = warp_cuda::compile(NVRTC_SOURCE, "tile_linalg.cu", &opts, 90)
            .unwrap_or_else(|e| panic!("block size {bd}: {e}"));
        assert!(!c.cubin.is_empty());
        assert!(!c.log.contains("warning"), "block size {bd}: {}", c.log);
    }
}

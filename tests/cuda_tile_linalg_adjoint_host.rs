//! The CUDA adjoints of the tile linear algebra (`warp-cuda/cuda/wp_adjoint_tile_linalg.h`) and
//! of the scans (`wp_adjoint_tile.h`), checked without a GPU against warp-core's
//! (`warp_core::tile::adjoint`), bit for bit (tolerance: none).
//!
//! A driver (`warp-cuda/cuda/tests/wp_tile_linalg_adjoint_driver.cpp`) runs them in one block
//! under the block emulator (`wp_prim_emu.h`: the threads are fibers run in a new random order
//! between barriers, so a read racing a write in one phase would show), compiled with g++
//! without FMA contraction for block sizes 1, 32, 45 (a partial warp), 64 and 256. The cases:
//! the three solves with 2-D and 1-D right-hand sides and the factor, in f64 at N = 5 and
//! N = 1, in f32 at N = 32 (the forward's warp-synchronous form from a whole warp up) and
//! N = 40 (its block-wide form), each adjoint accumulating into nonzero adjoints; the four
//! scans of 37 elements (f32 and f64, seeds led by a large value so that the suffix sums depend
//! on their order, which the block size changes: the test checks that it does) and of one.
//! Where NVRTC is installed, `nvrtc_compiles_the_adjoint_headers` compiles every adjoint for
//! sm_90. Not checked here: real hardware (the suite's tile_grad_linalg on a GPU).
//!
//! Skipped, saying so, without g++ (without NVRTC, the NVRTC test).

#[path = "common/host_cpp.rs"]
mod host_cpp;

use std::process::Command;
use warp_core::tile::adjoint as ta;
use warp_core::tile::{Tile, Tile1, Tile2};

const BLOCK_DIMS: [usize; 5] = [1, 32, 45, 64, 256];

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

/// Runs `cases` (name, input bytes) for block size `bd`: each case's output bytes.
fn run(bd: usize, cases: &[(String, Vec<u8>)]) -> Vec<Vec<u8>> {
    let (dir, exe) = host_cpp::compile_driver(
        &format!("tile_linalg_adjoint_{bd}"),
        include_str!("../warp-cuda/cuda/tests/wp_tile_linalg_adjoint_driver.cpp"),
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
    let got: Vec<Vec<u8>> = text
        .lines()
        .map(|l| {
            let h = l.strip_prefix("out ").expect("an out line");
            (0..h.len())
                .step_by(2)
                .map(|i| u8::from_str_radix(&h[i..i + 2], 16).unwrap())
                .collect()
        })
        .collect();
    assert_eq!(got.len(), cases.len());
    got
}

/// A linear-algebra case: its input bytes and warp-core's output (the driver's order).
macro_rules! lin_case {
    ($t:ty, $n:literal, $k:literal, $seed:expr) => {{
        const N: usize = $n;
        const K: usize = $k;
        let mut r = values($seed);
        let mat = |f: &mut dyn FnMut(usize, usize) -> f64| Tile2::<$t, N, N> {
            data: std::array::from_fn(|i| std::array::from_fn(|j| f(i, j) as $t)),
        };
        // Both triangles well conditioned.
        let m = mat(&mut |i, j| {
            let v = r();
            if i == j {
                2.0 + v.abs()
            } else {
                0.3 * v / N as f64
            }
        });
        // B Bᵀ + N I in the lower triangle, values that are not its mirror above.
        let b: Vec<f64> = (0..N * N).map(|_| r()).collect();
        let a = mat(&mut |i, j| {
            if i < j {
                return 5.0;
            }
            (0..N).map(|k| b[i * N + k] * b[j * N + k]).sum::<f64>()
                + if i == j { N as f64 } else { 0.0 }
        });
        let mut rhs = || Tile2::<$t, N, K> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r() as $t)),
        };
        let (y, seed, h) = (rhs(), rhs(), rhs());
        let mut vec = || Tile1::<$t, N> {
            data: std::array::from_fn(|_| r() as $t),
        };
        let (y1, seed1, h1) = (vec(), vec(), vec());
        let mut r2 = values($seed + 1);
        let mut mat2 = || Tile2::<$t, N, N> {
            data: std::array::from_fn(|_| std::array::from_fn(|_| r2() as $t)),
        };
        let (ra, g) = (mat2(), mat2());
        let input = [
            bytes(&m),
            bytes(&y),
            bytes(&y1),
            bytes(&seed),
            bytes(&seed1),
            bytes(&a),
            bytes(&ra),
            bytes(&g),
            bytes(&h),
            bytes(&h1),
        ]
        .concat();
        let mut want = Vec::new();
        type Adj2 = fn(
            &Tile2<$t, N, N>,
            &Tile2<$t, N, K>,
            &mut Tile2<$t, N, N>,
            &mut Tile2<$t, N, K>,
            &Tile2<$t, N, K>,
            usize,
        );
        type Adj1 = fn(
            &Tile2<$t, N, N>,
            &Tile1<$t, N>,
            &mut Tile2<$t, N, N>,
            &mut Tile1<$t, N>,
            &Tile1<$t, N>,
            usize,
        );
        let solves: [(Adj2, Adj1); 3] = [
            (ta::adj_tile_lower_solve, ta::adj_tile_lower_solve),
            (ta::adj_tile_upper_solve, ta::adj_tile_upper_solve),
            (ta::adj_tile_cholesky_solve, ta::adj_tile_cholesky_solve),
        ];
        for (f2, f1) in solves {
            let (mut gm, mut hy) = (g, h);
            f2(&m, &y, &mut gm, &mut hy, &seed, 1);
            want.extend(bytes(&gm));
            want.extend(bytes(&hy));
            let (mut gm, mut hy1) = (g, h1);
            f1(&m, &y1, &mut gm, &mut hy1, &seed1, 1);
            want.extend(bytes(&gm));
            want.extend(bytes(&hy1));
        }
        let mut gm = g;
        ta::adj_tile_cholesky(&a, &mut gm, &ra, 1);
        want.extend(bytes(&gm));
        (
            format!("lin_{}_{}_{}", stringify!($t), N, K),
            input,
            (0..BLOCK_DIMS.len())
                .map(|_| want.clone())
                .collect::<Vec<_>>(),
        )
    }};
}

/// A scan case: input bytes, and warp-core's output for each block size.
macro_rules! scan_case {
    ($t:ty, $s:literal, $seed:expr) => {{
        const S: usize = $s;
        let mut r = values($seed);
        let mut v = || Tile1::<$t, S> {
            data: std::array::from_fn(|_| r() as $t),
        };
        let (x, mut seed, h) = (v(), v(), v());
        // The suffix sums start from the last element: a large value there, then values of 1
        // to 4, which vanish when added to it one by one (below half its spacing, 8 or 16) but
        // not as a chunk's total.
        let big = if std::mem::size_of::<$t>() == 4 {
            1e8
        } else {
            1e17
        };
        for (k, s) in seed.data.iter_mut().enumerate() {
            *s = if k == S - 1 {
                big
            } else {
                1.0 + 3.0 * r().abs()
            } as $t;
        }
        let input = [bytes(&x), bytes(&seed), bytes(&h)].concat();
        let per_bd = BLOCK_DIMS
            .iter()
            .map(|&bd| {
                let mut out = Vec::new();
                for f in [
                    ta::adj_tile_scan_inclusive::<$t, S>,
                    ta::adj_tile_scan_exclusive::<$t, S>,
                    ta::adj_tile_scan_max_inclusive::<$t, S>,
                    ta::adj_tile_scan_min_inclusive::<$t, S>,
                ] {
                    let mut g = h;
                    f(&x, &mut g, &seed, bd);
                    out.extend(bytes(&g));
                }
                out
            })
            .collect::<Vec<_>>();
        (format!("scan_{}_{}", stringify!($t), S), input, per_bd)
    }};
}

#[test]
fn adjoints_match_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_tile_linalg_adjoint_host: no g++ on this machine");
        return;
    }
    let cases = [
        lin_case!(f64, 5, 3, 1),
        lin_case!(f32, 32, 4, 3),
        lin_case!(f32, 40, 2, 5),
        lin_case!(f64, 1, 1, 7),
        scan_case!(f32, 37, 9),
        scan_case!(f64, 37, 11),
        scan_case!(f64, 1, 13),
    ];
    // The scans' order shows: block sizes 1 and 32 chunk the 37 elements differently.
    let f32_scan = &cases[4].2;
    assert_ne!(f32_scan[0], f32_scan[1], "the order-sensitive seed");
    let script: Vec<(String, Vec<u8>)> = cases
        .iter()
        .map(|(n, i, _)| (n.clone(), i.clone()))
        .collect();
    for (bi, &bd) in BLOCK_DIMS.iter().enumerate() {
        let got = run(bd, &script);
        for ((name, _, want), g) in cases.iter().zip(&got) {
            let w = &want[bi];
            assert_eq!(g.len(), w.len(), "{name}, block size {bd}: output length");
            let at = g.iter().zip(w).position(|(a, b)| a != b);
            assert!(
                at.is_none(),
                "{name}, block size {bd}: differs from warp-core first at byte {at:?}"
            );
        }
    }
}

/// Every adjoint of the two headers at the sizes above and a 48 x 48 f64, for NVRTC. Each
/// instantiation has its own static shared scratch, about 36 KiB in all (under CUDA's 48).
const NVRTC_SOURCE: &str = r#"
#include "wp_tile.h"
#include "wp_tile_linalg.h"
#include "wp_adjoint_tile.h"
#include "wp_adjoint_tile_linalg.h"

template <typename Tile>
__device__ Tile slot(unsigned char*& at) {
  Tile t(at);
  at += (Tile::BYTES + 15) & ~(wp::usize)15;
  return t;
}

template <typename T, int N, int K>
__device__ unsigned char* adjoints(unsigned char* at) {
  auto m = slot<wp::tile_t<T, N, N>>(at);
  auto gm = slot<wp::tile_t<T, N, N>>(at);
  auto rm = slot<wp::tile_t<T, N, N>>(at);
  auto y = slot<wp::tile_t<T, N, K>>(at);
  auto gy = slot<wp::tile_t<T, N, K>>(at);
  auto r = slot<wp::tile_t<T, N, K>>(at);
  auto y1 = slot<wp::tile_t<T, N>>(at);
  auto gy1 = slot<wp::tile_t<T, N>>(at);
  auto r1 = slot<wp::tile_t<T, N>>(at);
  wp::adj_tile_lower_solve(m, y, gm, gy, r);
  wp::adj_tile_upper_solve(m, y, gm, gy, r);
  wp::adj_tile_cholesky_solve(m, y, gm, gy, r);
  wp::adj_tile_lower_solve(m, y1, gm, gy1, r1);
  wp::adj_tile_upper_solve(m, y1, gm, gy1, r1);
  wp::adj_tile_cholesky_solve(m, y1, gm, gy1, r1);
  wp::adj_tile_cholesky(m, gm, rm);
  wp::adj_tile_scan_inclusive(y1, gy1, r1);
  wp::adj_tile_scan_exclusive(y1, gy1, r1);
  wp::adj_tile_scan_max_inclusive(y1, gy1, r1);
  wp::adj_tile_scan_min_inclusive(y1, gy1, r1);
  return at;
}

extern "C" __global__ void adjoints_all() {
  extern __shared__ __align__(16) unsigned char smem[];
  adjoints<wp::f32, 32, 4>(smem);
  adjoints<wp::f64, 5, 3>(smem);
  adjoints<wp::f32, 40, 2>(smem);
  adjoints<wp::f64, 48, 1>(smem);
}
"#;

/// NVRTC accepts the adjoints (no warnings), at block sizes below, at and above a warp.
/// Skipped, saying so, without NVRTC.
#[test]
fn nvrtc_compiles_the_adjoint_headers() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED nvrtc_compiles_the_adjoint_headers: {e}");
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
        let c = warp_cuda::compile(NVRTC_SOURCE, "tile_linalg_adjoint.cu", &opts, 90)
            .unwrap_or_else(|e| panic!("block size {bd}: {e}"));
        assert!(!c.cubin.is_empty());
        assert!(!c.log.contains("warning"), "block size {bd}: {}", c.log);
    }
}

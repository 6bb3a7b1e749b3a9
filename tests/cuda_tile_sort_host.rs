//! The CUDA tile sort (`warp-cuda/cuda/wp_tile_sort.h`), checked without a GPU against the
//! CPU's (`warp_core::tile::sort`), bit for bit.
//!
//! A driver (`warp-cuda/cuda/tests/wp_tile_sort_driver.cpp`) runs the header's sorting
//! permutation and the in-place permutes that `tile_sort(&mut keys, &mut values)` lowers to, in
//! one block under the block emulator (`wp_prim_emu.h`: the block's threads are fibers that run
//! in a new random order between barriers, so a comparator that raced another in the same step
//! would show). It is compiled with g++ for block sizes 1, 7 (fewer than most lengths), 32,
//! 45 (a partial warp) and 256 (more than most lengths). Every case must give warp-core's
//! permutation, keys and values exactly: keys with many duplicates, both zeros, NaNs of both
//! signs and infinities (floats), extremes (integers), lengths 1, 7, 64, 100 and 1000. What this
//! cannot check is what only hardware does (NVRTC's acceptance, real shared memory); the suite's
//! `tile_sort` tests do that on a GPU.
//!
//! Skipped, saying so, without g++.

#[path = "common/host_cpp.rs"]
mod host_cpp;

use std::process::Command;
use warp_core::tile::{self, SortKey, Tile1};

const BLOCK_DIMS: [usize; 5] = [1, 7, 32, 45, 256];

/// Seeded draws in `0..m`.
fn draws(n: usize, m: u64, seed: u64) -> Vec<u64> {
    let mut s = seed;
    (0..n)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (s >> 33) % m
        })
        .collect()
}

fn float_key(d: u64) -> f64 {
    match d {
        0 => f64::NAN,
        1 => -f64::NAN,
        2 => -0.0,
        3 => 0.0,
        4 => f64::INFINITY,
        5 => f64::NEG_INFINITY,
        _ => (d as f64 - 12.0) * 0.5,
    }
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
        &format!("tile_sort_{bd}"),
        include_str!("../warp-cuda/cuda/tests/wp_tile_sort_driver.cpp"),
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

/// Adds the case `name` for `keys` (i64 values: their indices times 3, minus 1000) and what
/// warp-core gives for it: the permutation, the sorted keys, the permuted values.
fn case<K: SortKey + bytemuck::Pod, const N: usize>(
    cases: &mut Vec<(String, Vec<u8>)>,
    want: &mut Vec<Vec<u8>>,
    name: &str,
    keys: impl Fn(u64) -> K,
    seed: u64,
) {
    let d = draws(N, 30, seed);
    let k = Tile1::<K, N> {
        data: std::array::from_fn(|i| keys(d[i])),
    };
    let v = Tile1::<i64, N> {
        data: std::array::from_fn(|i| i as i64 * 3 - 1000),
    };
    let p = tile::sort_perm(&k);
    let mut input = bytemuck::cast_slice(&k.data).to_vec();
    input.extend_from_slice(bytemuck::cast_slice(&v.data));
    cases.push((name.to_string(), input));
    let mut out = bytemuck::cast_slice(&p.data).to_vec();
    out.extend_from_slice(bytemuck::cast_slice(&tile::permute(&k, &p).data));
    out.extend_from_slice(bytemuck::cast_slice(&tile::permute(&v, &p).data));
    want.push(out);
}

#[test]
fn sort_matches_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_tile_sort_host: no g++ on this machine");
        return;
    }
    let (mut cases, mut want) = (Vec::new(), Vec::new());
    let f32k = |d| float_key(d) as f32;
    case::<f32, 1>(&mut cases, &mut want, "f32_1", f32k, 1);
    case::<f32, 7>(&mut cases, &mut want, "f32_7", f32k, 2);
    case::<f32, 64>(&mut cases, &mut want, "f32_64", f32k, 3);
    case::<f32, 100>(&mut cases, &mut want, "f32_100", f32k, 4);
    case::<f32, 1000>(&mut cases, &mut want, "f32_1000", f32k, 5);
    case::<f64, 100>(&mut cases, &mut want, "f64_100", float_key, 6);
    case::<f64, 1000>(&mut cases, &mut want, "f64_1000", float_key, 7);
    let i32k = |d| match d {
        0 => i32::MIN,
        1 => i32::MAX,
        _ => d as i32 - 15,
    };
    case::<i32, 100>(&mut cases, &mut want, "i32_100", i32k, 8);
    let u32k = |d| if d == 0 { u32::MAX } else { d as u32 };
    case::<u32, 100>(&mut cases, &mut want, "u32_100", u32k, 9);
    let i64k = |d| match d {
        0 => i64::MIN,
        1 => i64::MAX,
        _ => (d as i64 - 15) << 35,
    };
    case::<i64, 100>(&mut cases, &mut want, "i64_100", i64k, 10);
    let u64k = |d| if d == 0 { u64::MAX } else { d << 40 };
    case::<u64, 100>(&mut cases, &mut want, "u64_100", u64k, 11);
    for bd in BLOCK_DIMS {
        let got = run(bd, &cases);
        for ((name, _), (g, w)) in cases.iter().zip(got.iter().zip(&want)) {
            // NaN keys compare by bits too: a sort only moves them.
            assert!(
                g == w,
                "block size {bd}, case {name}: the GPU header differs from warp-core"
            );
        }
    }
}

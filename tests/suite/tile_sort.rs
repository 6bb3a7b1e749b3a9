//! `tile_sort(&mut keys, &mut values)` on every backend, against a stable sort on the host in
//! the documented order (ascending by key, equal keys in their original order, NaN keys last,
//! `-0.0` and `+0.0` tied): keys with duplicates, both zeros and NaNs, lengths 1, 7, 64, 100
//! and 1000 (shorter and longer than the block, powers of two and not), block sizes 1 to 256,
//! several blocks each sorting its own segment. Exact: a sort only moves elements, so keys and
//! values must be the host's bits (NaN keys included).

// The code the kernel macro generates for a tiled kernel's CPU block rounds up by hand, and
// clippy reports it at the kernel (as in tiles.rs).
#![allow(clippy::manual_div_ceil)]

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::prelude::*;

backend_tests!(
    sorts_f32_keys_of_every_length,
    sorts_every_key_type,
    sort_then_use_the_tiles,
    backward_through_sort_is_refused_by_name,
);

/// Blocks of a launch: each sorts its segment of `N` keys and values.
const BLOCKS: usize = 3;

/// A kernel sorting segment `tid()` of `k`/`v` (`N` each) into `ko`/`vo`.
macro_rules! sort_kernel {
    ($name:ident, $k:ident, $v:ident, $n:tt) => {
        #[wp::kernel]
        fn $name(k: Array<$k>, v: Array<$v>, ko: Array<$k>, vo: Array<$v>) {
            let o = (tid() * $n) as i32;
            let mut keys = tile_load::<$n>(k, o);
            let mut vals = tile_load::<$n>(v, o);
            tile_sort(&mut keys, &mut vals);
            tile_store(ko, keys, o);
            tile_store(vo, vals, o);
        }
    };
}

sort_kernel!(k_sort_f32_1, f32, i32, 1);
sort_kernel!(k_sort_f32_7, f32, i32, 7);
sort_kernel!(k_sort_f32_64, f32, i32, 64);
sort_kernel!(k_sort_f32_100, f32, i32, 100);
sort_kernel!(k_sort_f32_1000, f32, i32, 1000);
sort_kernel!(k_sort_f64, f64, f32, 100);
sort_kernel!(k_sort_i32, i32, u8, 100);
sort_kernel!(k_sort_u32, u32, i64, 100);
sort_kernel!(k_sort_i64, i64, f64, 100);
sort_kernel!(k_sort_u64, u64, u32, 100);

/// Seeded values in `0..m`.
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

/// Float keys from draws: a few distinct values (many duplicates), both zeros, NaNs of both
/// signs, infinities.
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

/// The documented order, on the host: a stable sort of the indices by key, NaN last.
fn host_order<K: Copy>(
    keys: &[K],
    nan: impl Fn(K) -> bool,
    lt: impl Fn(K, K) -> bool,
) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..keys.len()).collect();
    idx.sort_by(|&a, &b| {
        let (x, y) = (keys[a], keys[b]);
        match (nan(x), nan(y)) {
            (true, true) => std::cmp::Ordering::Equal,
            (true, false) => std::cmp::Ordering::Greater,
            (false, true) => std::cmp::Ordering::Less,
            _ if lt(x, y) => std::cmp::Ordering::Less,
            _ if lt(y, x) => std::cmp::Ordering::Greater,
            _ => std::cmp::Ordering::Equal,
        }
    });
    idx
}

/// Launches `kernel` on `BLOCKS` segments of `n` at each block size and checks every segment
/// against [`host_order`]; `bits` makes a key comparable bit for bit.
#[allow(clippy::too_many_arguments)]
fn check<
    K: wp::Element,
    V: wp::Element + PartialEq + std::fmt::Debug,
    KB: PartialEq + std::fmt::Debug,
>(
    what: &str,
    dev: &wp::Device,
    kernel: impl Fn(&wp::Array<K>, &wp::Array<V>, &wp::Array<K>, &wp::Array<V>, usize),
    keys: &[K],
    vals: &[V],
    n: usize,
    nan: impl Fn(K) -> bool + Copy,
    lt: impl Fn(K, K) -> bool + Copy,
    bits: impl Fn(K) -> KB,
    block_dims: &[usize],
) {
    let (k, v) = (arr(keys, dev), arr(vals, dev));
    let ko = zeros::<K, 1>(keys.len(), dev);
    let vo = zeros::<V, 1>(vals.len(), dev);
    for &bd in block_dims {
        kernel(&k, &v, &ko, &vo, bd);
        let (gk, gv) = (host(&ko), host(&vo));
        for b in 0..BLOCKS {
            let seg = b * n..(b + 1) * n;
            let order = host_order(&keys[seg.clone()], nan, lt);
            for (r, &i) in order.iter().enumerate() {
                let (at, from) = (b * n + r, b * n + i);
                assert_eq!(
                    bits(gk[at]),
                    bits(keys[from]),
                    "{what}: block {b}, key {r} (from {i}) at block_dim {bd}"
                );
                assert_eq!(
                    gv[at], vals[from],
                    "{what}: block {b}, value {r} (from {i}) at block_dim {bd}"
                );
            }
        }
    }
}

const BLOCK_DIMS: [usize; 6] = [1, 7, 32, 64, 128, 256];

/// f32 keys with duplicates, both zeros, NaNs and infinities, at every length and block size;
/// the values are the indices (so the permutation itself is checked).
fn sorts_f32_keys_of_every_length(dev: &wp::Device) {
    macro_rules! len {
        ($kernel:ident, $n:literal) => {{
            let n = $n;
            let keys: Vec<f32> = draws(BLOCKS * n, 30, n as u64)
                .into_iter()
                .map(|d| float_key(d) as f32)
                .collect();
            let vals: Vec<i32> = (0..(BLOCKS * n) as i32).collect();
            check(
                concat!("f32 keys, N = ", stringify!($n)),
                dev,
                |k, v, ko, vo, bd| {
                    wp::launch_tiled($kernel, BLOCKS, (k, v, ko, vo), bd, dev).unwrap()
                },
                &keys,
                &vals,
                n,
                f32::is_nan,
                |a, b| a < b,
                f32::to_bits,
                &BLOCK_DIMS,
            );
        }};
    }
    len!(k_sort_f32_1, 1);
    len!(k_sort_f32_7, 7);
    len!(k_sort_f32_64, 64);
    len!(k_sort_f32_100, 100);
    len!(k_sort_f32_1000, 1000);
}

/// f64, i32, u32, i64 and u64 keys (with their extremes, and many duplicates) carrying values of
/// other types (f32, u8, i64, f64, u32).
fn sorts_every_key_type(dev: &wp::Device) {
    const N: usize = 100;
    let d = |seed| draws(BLOCKS * N, 40, seed);
    let bds = [1, 32, 100, 256];

    let keys: Vec<f64> = d(1).into_iter().map(float_key).collect();
    let vals: Vec<f32> = (0..BLOCKS * N).map(|i| i as f32 * 0.5).collect();
    check(
        "f64 keys",
        dev,
        |k, v, ko, vo, bd| wp::launch_tiled(k_sort_f64, BLOCKS, (k, v, ko, vo), bd, dev).unwrap(),
        &keys,
        &vals,
        N,
        f64::is_nan,
        |a, b| a < b,
        f64::to_bits,
        &bds,
    );

    let keys: Vec<i32> = d(2)
        .into_iter()
        .map(|x| match x {
            0 => i32::MIN,
            1 => i32::MAX,
            _ => x as i32 - 20,
        })
        .collect();
    let vals: Vec<u8> = (0..BLOCKS * N).map(|i| (i % 251) as u8).collect();
    check(
        "i32 keys",
        dev,
        |k, v, ko, vo, bd| wp::launch_tiled(k_sort_i32, BLOCKS, (k, v, ko, vo), bd, dev).unwrap(),
        &keys,
        &vals,
        N,
        |_| false,
        |a, b| a < b,
        |x| x,
        &bds,
    );

    let keys: Vec<u32> = d(3)
        .into_iter()
        .map(|x| if x == 0 { u32::MAX } else { x as u32 })
        .collect();
    let vals: Vec<i64> = (0..BLOCKS * N).map(|i| i as i64 - (1 << 40)).collect();
    check(
        "u32 keys",
        dev,
        |k, v, ko, vo, bd| wp::launch_tiled(k_sort_u32, BLOCKS, (k, v, ko, vo), bd, dev).unwrap(),
        &keys,
        &vals,
        N,
        |_| false,
        |a, b| a < b,
        |x| x,
        &bds,
    );

    let keys: Vec<i64> = d(4)
        .into_iter()
        .map(|x| match x {
            0 => i64::MIN,
            1 => i64::MAX,
            _ => (x as i64 - 20) << 33,
        })
        .collect();
    let vals: Vec<f64> = (0..BLOCKS * N).map(|i| i as f64 * 0.25).collect();
    check(
        "i64 keys",
        dev,
        |k, v, ko, vo, bd| wp::launch_tiled(k_sort_i64, BLOCKS, (k, v, ko, vo), bd, dev).unwrap(),
        &keys,
        &vals,
        N,
        |_| false,
        |a, b| a < b,
        |x| x,
        &bds,
    );

    let keys: Vec<u64> = d(5)
        .into_iter()
        .map(|x| if x == 0 { u64::MAX } else { x << 40 })
        .collect();
    let vals: Vec<u32> = (0..(BLOCKS * N) as u32).collect();
    check(
        "u64 keys",
        dev,
        |k, v, ko, vo, bd| wp::launch_tiled(k_sort_u64, BLOCKS, (k, v, ko, vo), bd, dev).unwrap(),
        &keys,
        &vals,
        N,
        |_| false,
        |a, b| a < b,
        |x| x,
        &bds,
    );
}

#[wp::kernel]
fn k_sort_and_use(k: Array<f32>, out: Array<f32>, first: Array<i32>) {
    let mut keys = tile_load::<64>(k, 0);
    let mut idx = tile_arange::<i32, 64>();
    tile_sort(&mut keys, &mut idx);
    // The sorted tiles are ordinary tiles afterwards: arithmetic, an element read by a lane.
    let scaled = keys * 2.0;
    tile_store(out, scaled, 0);
    if lane() == 0 {
        first[0] = idx[0];
    }
}

/// The sorted tiles flow on into other tile operations and lane code: the smallest key's index
/// read by `idx[0]`, the keys doubled.
fn sort_then_use_the_tiles(dev: &wp::Device) {
    let keys: Vec<f32> = (0..64).map(|i| ((i * 37) % 64) as f32 - 10.0).collect();
    let k = arr(&keys, dev);
    let out = zeros::<f32, 1>(64, dev);
    let first = zeros::<i32, 1>(1, dev);
    for bd in [1, 16, 64, 96] {
        wp::launch_tiled(k_sort_and_use, 1, (&k, &out, &first), bd, dev).unwrap();
        let want: Vec<f32> = (0..64).map(|i| (i as f32 - 10.0) * 2.0).collect();
        assert_eq!(host(&out), want, "block_dim {bd}");
        // Key -10 is element i with 37 i = 0 (mod 64), i = 0.
        assert_eq!(host(&first), vec![0], "block_dim {bd}");
    }
}

#[wp::kernel]
fn k_sort_grad(k: Array<f64>, out: Array<f64>) {
    let mut keys = tile_load::<8>(k, 0);
    let mut vals = tile_load::<8>(k, 0);
    tile_sort(&mut keys, &mut vals);
    tile_store(out, vals, 0);
}

/// Warp's sort has no adjoint: backward through it is an error naming the kernel and
/// `tile_sort`, never a silent zero gradient.
fn backward_through_sort_is_refused_by_name(dev: &wp::Device) {
    let a = arr(&[3.0f64, 1.0, 2.0, 0.0, 5.0, 4.0, 7.0, 6.0], dev)
        .with_grad()
        .unwrap();
    let out = zeros::<f64, 1>(8, dev).with_grad().unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch_tiled(k_sort_grad, 1, (&a, &out), 8, dev).unwrap();
    }
    let e = tape.backward(&out).unwrap_err();
    assert!(matches!(e, wp::Error::NotDifferentiable { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("k_sort_grad") && msg.contains("tile_sort"),
        "{msg}"
    );
}

/// The CUDA translation the GPU runs (checked here without one): the sorting permutation into
/// a slot of its own, then the two in-place permutes, from the `tile_sort` section.
#[test]
fn cuda_template_sorts_through_the_section() {
    let info = wp::kernel_info(k_sort_f32_100);
    assert!(
        info.cuda_sections.contains(&"tile_sort"),
        "{:?}",
        info.cuda_sections
    );
    let (perm, permute) = (
        info.cuda.find("wp::tile_sort("),
        info.cuda.matches("wp::tile_permute(").count(),
    );
    assert!(perm.is_some() && permute == 2, "{}", info.cuda);
}

//! Tests of the reductions against an independent simulation of the CUDA block reduction.
//!
//! Float results are compared bit for bit (tolerance 0): the point of the module is that the
//! order, and so every rounding, is the GPU's.

use super::*;
use crate::tile::Tile2;

/// A literal simulation of the CUDA code the module docs describe, written as the GPU runs
/// it rather than as `gpu_order` does: `bd` lanes, each lane's partial starting from the
/// identity `id`; `__shfl_down_sync` over full 32-lane warps (lanes past `bd` hold `id`; a
/// source lane past the warp returns the caller's own value, as the hardware does); each
/// warp's lane 0 writes shared memory; lane 0 of the block folds the warps left to right.
fn cuda_sim<T: Copy>(x: &[T], bd: usize, id: T, op: impl Fn(T, T) -> T) -> T {
    let warps = bd.div_ceil(32);
    let mut reg = vec![id; warps * 32];
    for (l, r) in reg.iter_mut().enumerate().take(bd) {
        let mut e = l;
        while e < x.len() {
            *r = if e == l { x[e] } else { op(*r, x[e]) };
            e += bd;
        }
    }
    let mut smem = Vec::new();
    for w in 0..warps {
        let mut v: Vec<T> = reg[w * 32..w * 32 + 32].to_vec();
        for off in [16, 8, 4, 2, 1] {
            let before = v.clone();
            for i in 0..32 {
                let other = if i + off < 32 {
                    before[i + off]
                } else {
                    before[i]
                };
                v[i] = op(before[i], other);
            }
        }
        smem.push(v[0]);
    }
    let mut acc = smem[0];
    for &s in &smem[1..] {
        acc = op(acc, s);
    }
    acc
}

/// Block sizes worth checking: 1, around the warp size, not multiples of 32, the maximum.
const BDS: &[usize] = &[
    1, 2, 7, 31, 32, 33, 45, 64, 96, 100, 128, 255, 256, 1000, 1024,
];

#[test]
fn sum_of_a_large_value_and_ones_follows_the_block_order() {
    // 1e8 has an f32 ulp of 8, so 1e8 + 1.0 rounds back to 1e8: the order decides how many
    // of the ones are absorbed.
    let mut t = Tile1::<f32, 256> { data: [1.0; 256] };
    t.data[0] = 1e8;
    let naive = t.data.iter().fold(0.0f32, |a, &b| a + b);
    assert_eq!(naive, 1e8);
    // bd = 1 is the naive order.
    assert_eq!(sum(&t, 1).data[0], naive);
    // bd = 32: lane 0 owns 1e8 and seven ones (all absorbed); lanes 1..31 each sum eight ones
    // to 8.0; the tree adds 31 * 8 = 248 to 1e8 in multiples of 8, all exact.
    assert_eq!(sum(&t, 32).data[0], 100_000_248.0);
    for &bd in BDS {
        let s = sum(&t, bd).data[0];
        let sim = cuda_sim(&t.data, bd, 0.0f32, |a, b| a + b);
        assert_eq!(s.to_bits(), sim.to_bits(), "bd {bd}");
        if bd > 1 {
            assert_ne!(s, naive, "bd {bd}");
        }
    }
}

#[test]
fn float_sums_match_the_simulation_bit_for_bit() {
    // Values of mixed magnitude and sign, so that nearly every order rounds differently.
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        let m = (state >> 40) as f32 / (1u64 << 24) as f32 - 0.5;
        m * 10f32.powi((state % 9) as i32 - 4)
    };
    let t = Tile2::<f32, 37, 29> {
        data: std::array::from_fn(|_| std::array::from_fn(|_| next())),
    };
    let d = Tile2::<f64, 5, 3> {
        data: std::array::from_fn(|i| std::array::from_fn(|j| (i * 3 + j) as f64 * 0.1 - 0.7)),
    };
    let mut distinct = std::collections::HashSet::new();
    for &bd in BDS {
        let s = sum(&t, bd).data[0];
        let sim = cuda_sim(t.as_flat(), bd, 0.0, |a, b| a + b);
        assert_eq!(s.to_bits(), sim.to_bits(), "bd {bd}");
        distinct.insert(s.to_bits());
        let s = sum(&d, bd).data[0];
        assert_eq!(
            s.to_bits(),
            cuda_sim(d.as_flat(), bd, 0.0, |a, b| a + b).to_bits()
        );
    }
    // The order matters for these values: different block sizes give different sums.
    assert!(distinct.len() > 3, "{distinct:?}");
}

#[test]
fn integer_sums_are_exact_for_every_block_size() {
    let t = Tile2::<i64, 20, 50> {
        data: std::array::from_fn(|i| std::array::from_fn(|j| (i as i64 - 7) * 1000 + j as i64)),
    };
    let exact: i64 = t.as_flat().iter().sum();
    let w = Tile1::<i32, 3> {
        data: [i32::MAX, 1, 5],
    };
    for &bd in BDS {
        assert_eq!(sum(&t, bd).data[0], exact, "bd {bd}");
        // Wrapping, in any order.
        assert_eq!(sum(&w, bd).data[0], i32::MIN + 5, "bd {bd}");
    }
}

#[test]
fn block_larger_than_the_tile_and_out_of_range_block_sizes() {
    let t = Tile1::<f32, 10>::arange(0.5, 1.25);
    let seq = t.data.iter().fold(0.0f32, |a, &b| a + b);
    for bd in [10, 11, 64, 1024] {
        // Every lane owns at most one element.
        let s = sum(&t, bd).data[0];
        assert_eq!(
            s.to_bits(),
            cuda_sim(&t.data, bd, 0.0, |a, b| a + b).to_bits()
        );
        assert!((s - seq).abs() <= 1e-5 * seq.abs(), "{s} vs {seq}");
    }
    // Clamped into 1..=1024.
    assert_eq!(sum(&t, 0), sum(&t, 1));
    assert_eq!(sum(&t, 5000), sum(&t, 1024));
    let one = Tile1::<f32, 1> { data: [-0.0] };
    // An empty lane never changes a result, not even the sign of a zero.
    assert_eq!(sum(&one, 64).data[0].to_bits(), (-0.0f32).to_bits());
}

#[test]
fn min_and_max_ignore_empty_lanes_and_nans() {
    let t = Tile1::<f32, 70> {
        data: std::array::from_fn(|i| ((i * 37) % 70) as f32 - 20.0),
    };
    let mut n = t;
    n.data[0] = f32::NAN;
    n.data[33] = f32::NAN;
    for &bd in BDS {
        assert_eq!(min(&t, bd).data[0], -20.0);
        assert_eq!(max(&t, bd).data[0], 49.0);
        // Empty lanes contribute nothing, so an all-positive tile keeps its minimum.
        let p = t.map(|x| x + 100.0);
        assert_eq!(min(&p, bd).data[0], 80.0);
        let m = min(&n, bd).data[0];
        assert_eq!(
            m.to_bits(),
            cuda_sim(&n.data, bd, f32::NAN, f32::min).to_bits()
        );
        assert!(!m.is_nan());
        let i = Tile2::<i8, 3, 3> {
            data: [[3, -128, 5], [127, 0, 1], [2, 2, 2]],
        };
        assert_eq!((min(&i, bd).data[0], max(&i, bd).data[0]), (-128, 127));
    }
}

#[test]
fn reduce_passes_the_earlier_partial_first() {
    // A non-commutative, non-associative op: the result encodes the whole combination tree.
    let op = |a: u64, b: u64| a.wrapping_mul(1_000_003).wrapping_add(b ^ 0x5555);
    let t = Tile2::<u64, 9, 11> {
        data: std::array::from_fn(|i| std::array::from_fn(|j| (i * 11 + j) as u64 + 1)),
    };
    let mut seen = std::collections::HashSet::new();
    for &bd in BDS {
        // The simulation needs an identity; this op has none, so pass one that cannot occur and
        // let the simulation skip it.
        let skip = |a: Option<u64>, b: Option<u64>| match (a, b) {
            (Some(a), Some(b)) => Some(op(a, b)),
            (a, None) => a,
            (None, b) => b,
        };
        let x: Vec<Option<u64>> = t.as_flat().iter().map(|&v| Some(v)).collect();
        let sim = cuda_sim(&x, bd, None, skip).unwrap();
        assert_eq!(reduce(&t, bd, op).data[0], sim, "bd {bd}");
        seen.insert(sim);
    }
    // From bd 100 up every lane owns at most one of the 99 elements and the same 99 lanes
    // form the same four warps: one result for those six block sizes.
    assert_eq!(seen.len(), BDS.len() - 5);
}

#[test]
fn argmin_and_argmax_give_the_first_index_for_every_block_size() {
    let mut t = Tile2::<f32, 8, 16> {
        data: std::array::from_fn(|i| std::array::from_fn(|j| ((i * 16 + j) % 13) as f32)),
    };
    // Minimum 0.0 first at index 0, maximum 12.0 first at index 12; a NaN never wins.
    t.data[0][5] = f32::NAN;
    t.data[7][15] = f32::NAN;
    for &bd in BDS {
        assert_eq!(argmin(&t, bd).data[0], 0, "bd {bd}");
        assert_eq!(argmax(&t, bd).data[0], 12, "bd {bd}");
    }
    let mut u = t;
    u.data[0][0] = 3.0; // the first 0.0 is now at 13
    u.data[6][9] = -1.0; // index 105
    for &bd in BDS {
        assert_eq!(argmin(&u, bd).data[0], 105, "bd {bd}");
    }
    let nan = Tile1::<f64, 40> {
        data: [f64::NAN; 40],
    };
    let ints = Tile1::<i32, 6> {
        data: [4, -2, 9, -2, 9, 0],
    };
    for &bd in BDS {
        assert_eq!(argmin(&nan, bd).data[0], 0);
        assert_eq!(argmax(&nan, bd).data[0], 0);
        assert_eq!(argmin(&ints, bd).data[0], 1);
        assert_eq!(argmax(&ints, bd).data[0], 2);
    }
}

//! The linear BVH build (`warp-runtime/src/objects/lbvh.rs`, `wp_bvh_build.h`): a GPU builds
//! and refits the same tree as the CPU, bit for bit (every step is exact), for sizes from the
//! empty tree up, with duplicate boxes (equal Morton codes).

use glam::Vec3;
use warp_lang as wp;

backend_tests!(the_tree_is_the_cpus, refit_is_the_cpus);

/// `n` boxes in [-10, 10]^3, every third one next to the previous (near-equal codes) and every
/// seventh equal to the previous (equal codes).
fn boxes(n: usize, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut s = seed;
    let mut r = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 40) as f32 / (1u64 << 24) as f32
    };
    let (mut lo, mut hi) = (Vec::<Vec3>::new(), Vec::<Vec3>::new());
    for i in 0..n {
        let (l, h) = if i > 0 && i % 7 == 0 {
            (lo[i - 1], hi[i - 1])
        } else {
            let c = if i > 0 && i % 3 == 0 {
                lo[i - 1] + Vec3::splat(1e-3)
            } else {
                Vec3::new(r(), r(), r()) * 20.0 - 10.0
            };
            let e = Vec3::new(r(), r(), r()) * 0.2;
            (c - e, c + e)
        };
        lo.push(l);
        hi.push(h);
    }
    (lo, hi)
}

fn build(
    dev: &wp::Device,
    lo: &[Vec3],
    hi: &[Vec3],
    leaf: usize,
    moved: Option<(&[Vec3], &[Vec3])>,
) -> wp::objects::lbvh::HostTree {
    let a = |v: &[Vec3]| wp::Array::from_slice(v, dev).unwrap();
    let (l, h) = (a(lo), a(hi));
    let m = moved.map(|(ml, mh)| (a(ml), a(mh)));
    wp::objects::lbvh::build_for_tests(&l, &h, leaf, m.as_ref().map(|(x, y)| (x, y))).unwrap()
}

/// The leaf sizes of a `Bvh`'s and of a `Mesh`'s trees.
const LEAF_SIZES: [usize; 2] = [
    wp::objects::lbvh::BVH_LEAF_SIZE,
    wp::objects::lbvh::MESH_LEAF_SIZE,
];

fn the_tree_is_the_cpus(dev: &wp::Device) {
    let cpu = wp::cpu();
    for n in [0usize, 1, 2, 3, 64, 1000, 100_000] {
        let (lo, hi) = boxes(n, 0x9e37_79b9 ^ n as u64);
        for leaf in LEAF_SIZES {
            let here = build(dev, &lo, &hi, leaf, None);
            let there = build(&cpu, &lo, &hi, leaf, None);
            assert!(
                here == there,
                "n = {n}, leaf size {leaf}: the {dev} tree differs from the CPU's"
            );
        }
    }
}

fn refit_is_the_cpus(dev: &wp::Device) {
    let cpu = wp::cpu();
    let n = 20_000;
    let (lo, hi) = boxes(n, 7);
    // Moved far and unevenly: the refit keeps the shape and recomputes every box.
    let shift = |v: &[Vec3]| -> Vec<Vec3> {
        v.iter()
            .enumerate()
            .map(|(i, p)| *p * 1.5 + Vec3::new((i % 13) as f32, -3.0, 0.25 * (i % 5) as f32))
            .collect()
    };
    let (ml, mh) = (shift(&lo), shift(&hi));
    for leaf in LEAF_SIZES {
        let here = build(dev, &lo, &hi, leaf, Some((&ml, &mh)));
        let there = build(&cpu, &lo, &hi, leaf, Some((&ml, &mh)));
        assert!(
            here == there,
            "leaf size {leaf}: the refit {dev} tree differs from the CPU's"
        );
        let fresh = build(&cpu, &lo, &hi, leaf, None);
        assert_eq!(here.1, fresh.1, "a refit changed the shape");
        assert!(here.0 != fresh.0, "a refit changed no box");
        // Every box the refit wrote contains what is under it, leaves of several boxes too.
        let nodes: &[warp_core::objects::bvh::BvhNode] = wp::cast_slice(&here.0);
        wp::objects::bvh_build::check_layout(nodes, &here.1, &here.2, &ml, &mh)
            .unwrap_or_else(|e| panic!("leaf size {leaf}: the refit tree: {e}"));
    }
}

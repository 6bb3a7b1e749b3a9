//! `wp::Bvh` (Warp's BVH over boxes) on both backends: `for i in bvh_query_aabb(bvh, lo, hi)`
//! and `for i in bvh_query_ray(bvh, start, dir)` against brute force on random seeded boxes
//! (degenerate, flat and duplicate boxes among them; rays with zero direction components,
//! parallel to the slabs); the empty BVH; a kernel moving the boxes, then `refit`, then the
//! queries again (and a clone keeping the tree it had: copy-on-write); `break` in a query loop
//! and a query in a `#[func]`; bad input (errors naming the argument).

use crate::{arr, host, zeros};
use warp_lang as wp;
use wp::__private::objects::geometry::{intersect_ray_aabb, ray_inv_dir};
use wp::prelude::*;
use wp::Error;

backend_tests!(
    queries_match_brute_force,
    empty_bvh_finds_nothing,
    refit_after_a_kernel_moves_the_boxes,
    break_and_funcs,
    bad_input_is_an_error,
);

// ------------------------------------------------------------------------------------------
// Kernels
// ------------------------------------------------------------------------------------------

/// For query box `i`: the boxes found (in `found[i]`, as many as fit) and their count.
#[wp::kernel]
fn k_aabb(bvh: Bvh, qlo: Array<Vec3>, qhi: Array<Vec3>, found: Array<i32, 2>, counts: Array<i32>) {
    let i = tid();
    let mut c = 0;
    for j in bvh_query_aabb(bvh, qlo[i], qhi[i]) {
        if (c as usize) < found.shape()[1] {
            found[(i, c)] = j;
        }
        c += 1;
    }
    counts[i] = c;
}

/// For ray `i`: the boxes it meets and their count.
#[wp::kernel]
pub(crate) fn k_ray(
    bvh: Bvh,
    start: Array<Vec3>,
    dir: Array<Vec3>,
    found: Array<i32, 2>,
    counts: Array<i32>,
) {
    let i = tid();
    let mut c = 0;
    for j in bvh_query_ray(bvh, start[i], dir[i]) {
        if (c as usize) < found.shape()[1] {
            found[(i, c)] = j;
        }
        c += 1;
    }
    counts[i] = c;
}

/// Moves every box by `d` (the BVH's own arrays, shared with the host).
#[wp::kernel]
fn k_move(lowers: Array<Vec3>, uppers: Array<Vec3>, d: Vec3) {
    let i = tid();
    lowers[i] += d;
    uppers[i] += d;
}

/// Whether any box overlaps `[lo, hi]`, stopping at the first.
#[wp::func]
fn any_overlap(bvh: Bvh, lo: Vec3, hi: Vec3) -> i32 {
    let mut first = -1;
    for j in bvh_query_aabb(bvh, lo, hi) {
        first = j;
        break;
    }
    first
}

#[wp::kernel]
fn k_first(bvh: Bvh, qlo: Array<Vec3>, qhi: Array<Vec3>, first: Array<i32>) {
    let i = tid();
    first[i] = any_overlap(bvh, qlo[i], qhi[i]);
}

// ------------------------------------------------------------------------------------------
// Data and references
// ------------------------------------------------------------------------------------------

/// A small deterministic generator (xorshift64*).
pub(crate) struct Rng(pub u64);

impl Rng {
    pub fn f(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        let u = self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40;
        u as f32 / (1u64 << 24) as f32
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
    pub fn vec(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
    pub fn below(&mut self, n: usize) -> usize {
        ((self.f() * n as f32) as usize).min(n - 1)
    }
}

/// Random boxes in `[-10, 10]^3` of sizes from 0 (points) to 3, some flat, some duplicated.
fn boxes(seed: u64, n: usize) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut rng = Rng(seed);
    let (mut lo, mut hi) = (Vec::new(), Vec::new());
    for k in 0..n {
        let l = rng.vec(-10.0, 10.0);
        let mut s = rng.vec(0.0, 3.0);
        match k % 7 {
            0 => s = Vec3::ZERO,
            1 => s.y = 0.0,
            _ => {}
        }
        lo.push(l);
        hi.push(l + s);
    }
    for k in 0..n / 20 {
        lo.push(lo[k * 3]);
        hi.push(hi[k * 3]);
    }
    (lo, hi)
}

fn overlaps(l: Vec3, u: Vec3, ql: Vec3, qu: Vec3) -> bool {
    l.cmple(qu).all() && ql.cmple(u).all()
}

const SLOTS: usize = 800;

/// Runs `k` (a box or ray kernel of the shape above) and returns each query's sorted hits.
fn run<F>(n: usize, dev: &wp::Device, launch: F) -> Vec<Vec<i32>>
where
    F: FnOnce(&wp::Array<i32, 2>, &wp::Array<i32>),
{
    let found = zeros::<i32, 2>([n, SLOTS], dev);
    let counts = zeros::<i32, 1>(n, dev);
    launch(&found, &counts);
    let (flat, counts) = (host(&found), host(&counts));
    (0..n)
        .map(|i| {
            let k = counts[i] as usize;
            assert!(
                k <= SLOTS,
                "query {i}: {k} hits, more than the test's slots"
            );
            let mut v = flat[i * SLOTS..i * SLOTS + k].to_vec();
            v.sort_unstable();
            v
        })
        .collect()
}

fn aabb_hits(bvh: &wp::Bvh, ql: &[Vec3], qu: &[Vec3], dev: &wp::Device) -> Vec<Vec<i32>> {
    let (a, b) = (arr(ql, dev), arr(qu, dev));
    run(ql.len(), dev, |found, counts| {
        wp::launch(k_aabb, ql.len(), (bvh, &a, &b, found, counts), dev).unwrap()
    })
}

fn ray_hits(bvh: &wp::Bvh, s: &[Vec3], d: &[Vec3], dev: &wp::Device) -> Vec<Vec<i32>> {
    let (a, b) = (arr(s, dev), arr(d, dev));
    run(s.len(), dev, |found, counts| {
        wp::launch(k_ray, s.len(), (bvh, &a, &b, found, counts), dev).unwrap()
    })
}

fn check_aabb(lo: &[Vec3], hi: &[Vec3], ql: &[Vec3], qu: &[Vec3], got: &[Vec<i32>]) {
    for (i, g) in got.iter().enumerate() {
        let want: Vec<i32> = (0..lo.len())
            .filter(|j| overlaps(lo[*j], hi[*j], ql[i], qu[i]))
            .map(|j| j as i32)
            .collect();
        assert_eq!(*g, want, "box query {i}: [{}, {}]", ql[i], qu[i]);
    }
}

/// Query boxes: random, tiny, huge, inverted, NaN.
fn query_boxes(seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut rng = Rng(seed);
    let (mut ql, mut qu) = (Vec::new(), Vec::new());
    for _ in 0..150 {
        let l = rng.vec(-12.0, 12.0);
        ql.push(l);
        qu.push(l + rng.vec(0.0, 4.0));
    }
    ql.push(Vec3::splat(-100.0));
    qu.push(Vec3::splat(100.0));
    ql.push(Vec3::splat(1.0));
    qu.push(Vec3::splat(-1.0));
    ql.push(Vec3::new(f32::NAN, 0.0, 0.0));
    qu.push(Vec3::splat(5.0));
    (ql, qu)
}

/// Rays: random; axis-aligned (two zero direction components) and in coordinate planes (one
/// zero), so parallel to slabs; a zero direction; NaN.
fn rays(seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut rng = Rng(seed);
    let (mut s, mut d) = (Vec::new(), Vec::new());
    for k in 0..150 {
        s.push(rng.vec(-15.0, 15.0));
        let mut v = rng.vec(-1.0, 1.0);
        match k % 5 {
            0 => v = Vec3::new(0.0, 0.0, v.z),
            1 => v.x = 0.0,
            _ => {}
        }
        d.push(v);
    }
    s.push(Vec3::ZERO);
    d.push(Vec3::ZERO);
    s.push(Vec3::ZERO);
    d.push(Vec3::new(f32::NAN, 1.0, 0.0));
    (s, d)
}

fn check_rays(lo: &[Vec3], hi: &[Vec3], s: &[Vec3], d: &[Vec3], got: &[Vec<i32>]) {
    for (i, g) in got.iter().enumerate() {
        let inv = ray_inv_dir(d[i]);
        let want: Vec<i32> = (0..lo.len())
            .filter(|j| intersect_ray_aabb(s[i], inv, lo[*j], hi[*j]).is_some())
            .map(|j| j as i32)
            .collect();
        assert_eq!(*g, want, "ray {i}: {} + t {}", s[i], d[i]);
    }
}

// ------------------------------------------------------------------------------------------
// Tests
// ------------------------------------------------------------------------------------------

fn queries_match_brute_force(dev: &wp::Device) {
    let (lo, hi) = boxes(0x1234_5678, 600);
    let bvh = wp::Bvh::new(&arr(&lo, dev), &arr(&hi, dev)).unwrap();
    assert_eq!(bvh.num_prims(), lo.len());
    let (ql, qu) = query_boxes(99);
    let got = aabb_hits(&bvh, &ql, &qu, dev);
    check_aabb(&lo, &hi, &ql, &qu, &got);
    assert_eq!(got[150].len(), lo.len(), "a box around everything");
    assert!(got[151].is_empty() && got[152].is_empty(), "inverted, NaN");
    let (s, d) = rays(7);
    let got = ray_hits(&bvh, &s, &d, dev);
    check_rays(&lo, &hi, &s, &d, &got);
    assert!(got.iter().filter(|g| !g.is_empty()).count() > 50);
    if !dev.is_cpu() {
        // A GPU builds a linear BVH: the CPU's run of the same steps gives the same tree.
        let cpu = wp::cpu();
        let (lbvh, parents, ids) = wp::objects::lbvh::build_for_tests(
            &arr(&lo, &cpu),
            &arr(&hi, &cpu),
            wp::objects::lbvh::BVH_LEAF_SIZE,
            None,
        )
        .unwrap();
        let (nodes, p, i) = bvh.tree_host().unwrap();
        let words: &[[i32; 8]] = wp::cast_slice(&nodes);
        assert!(
            (words, &p, &i) == (&lbvh[..], &parents, &ids),
            "the GPU's tree is the CPU's linear BVH"
        );
    }
}

fn empty_bvh_finds_nothing(dev: &wp::Device) {
    let bvh = wp::Bvh::new(&arr::<Vec3>(&[], dev), &arr(&[], dev)).unwrap();
    assert_eq!((bvh.num_prims(), bvh.num_nodes()), (0, 1));
    let got = aabb_hits(&bvh, &[Vec3::splat(-1e30)], &[Vec3::splat(1e30)], dev);
    assert_eq!(got, vec![Vec::<i32>::new()]);
    let got = ray_hits(&bvh, &[Vec3::ZERO], &[Vec3::X], dev);
    assert_eq!(got, vec![Vec::<i32>::new()]);
}

fn refit_after_a_kernel_moves_the_boxes(dev: &wp::Device) {
    let (lo, hi) = boxes(42, 300);
    let (l, u) = (arr(&lo, dev), arr(&hi, dev));
    let mut bvh = wp::Bvh::new(&l, &u).unwrap();
    let before = bvh.clone();
    let built = bvh.tree_host().unwrap();
    let d = Vec3::new(30.0, -5.0, 2.0);
    wp::launch(k_move, lo.len(), (bvh.lowers(), bvh.uppers(), d), dev).unwrap();
    bvh.refit().unwrap();
    let (lo2, hi2): (Vec<Vec3>, Vec<Vec3>) = (host(&l), host(&u));
    assert_eq!(lo2[3], lo[3] + d, "the BVH's arrays are the user's");
    let (ql, qu) = query_boxes(5);
    let ql: Vec<Vec3> = ql.iter().map(|p| *p + d).collect();
    let qu: Vec<Vec3> = qu.iter().map(|p| *p + d).collect();
    check_aabb(&lo2, &hi2, &ql, &qu, &aabb_hits(&bvh, &ql, &qu, dev));
    let (s, dir) = rays(3);
    let s: Vec<Vec3> = s.iter().map(|p| *p + d).collect();
    check_rays(&lo2, &hi2, &s, &dir, &ray_hits(&bvh, &s, &dir, dev));
    // The clone kept the tree as built (copy-on-write: a tape's launch replays against it);
    // the refit kept the shape.
    assert_eq!(before.tree_host().unwrap(), built);
    let now = bvh.tree_host().unwrap();
    assert_eq!((&now.1, &now.2), (&built.1, &built.2));
    assert_ne!(now.0, built.0);
}

fn break_and_funcs(dev: &wp::Device) {
    let (lo, hi) = boxes(8, 200);
    let bvh = wp::Bvh::new(&arr(&lo, dev), &arr(&hi, dev)).unwrap();
    let (ql, qu) = query_boxes(11);
    let first = zeros::<i32, 1>(ql.len(), dev);
    wp::launch(
        k_first,
        ql.len(),
        (&bvh, &arr(&ql, dev), &arr(&qu, dev), &first),
        dev,
    )
    .unwrap();
    let all = aabb_hits(&bvh, &ql, &qu, dev);
    for (i, f) in host(&first).into_iter().enumerate() {
        match f {
            -1 => assert!(all[i].is_empty(), "query {i}"),
            j => assert!(all[i].contains(&j), "query {i}: {j}"),
        }
    }
}

fn bad_input_is_an_error(dev: &wp::Device) {
    let has = |e: &Error, s: &str| {
        let t = e.to_string();
        assert!(t.contains(s), "`{s}` not in: {t}");
    };
    let one = arr(&[Vec3::ZERO], dev);
    let two = arr(&[Vec3::ZERO, Vec3::ONE], dev);
    let e = wp::Bvh::new(&one, &two).unwrap_err();
    has(&e, "argument `uppers`");
    has(&e, "2 boxes");
    let nan = arr(&[Vec3::ZERO, Vec3::new(0.0, 0.0, f32::NAN)], dev);
    let e = wp::Bvh::new(&two, &nan).unwrap_err();
    has(&e, "argument `uppers`");
    has(&e, "index 1");
    let inf = arr(&[Vec3::NEG_INFINITY, Vec3::ZERO], dev);
    has(&wp::Bvh::new(&inf, &two).unwrap_err(), "argument `lowers`");
    // A refit re-reads the boxes and refuses non-finite ones: the CPU before refitting,
    // keeping its tree; a GPU's refit faults (reported at once in the suite's debug mode),
    // naming the argument and the index, its tree refit from what it read.
    let (l, u) = (
        arr(&[Vec3::ZERO, Vec3::ONE], dev),
        arr(&[Vec3::ONE, Vec3::splat(2.0)], dev),
    );
    let mut bvh = wp::Bvh::new(&l, &u).unwrap();
    let tree = bvh.tree_host().unwrap();
    l.copy_from(&nan).unwrap();
    let e = bvh.refit().unwrap_err();
    has(&e, "argument `lowers`");
    has(&e, "index 1");
    if dev.is_cpu() {
        assert_eq!(bvh.tree_host().unwrap(), tree);
    } else {
        assert!(
            matches!(&e, Error::Fault(f) if f.kernel == "Bvh::refit"),
            "{e:?}"
        );
    }
    // Finite again: the refit is right (the check was reset).
    l.copy_from(&arr(&[Vec3::ZERO, Vec3::ONE], dev)).unwrap();
    bvh.refit().unwrap();
    assert_eq!(bvh.tree_host().unwrap(), tree);
    let other = if dev.is_cpu() {
        wp::get_device("cuda:0").ok()
    } else {
        Some(wp::cpu())
    };
    match other {
        Some(other) => {
            let there = arr(&[Vec3::ONE, Vec3::ONE], &other);
            let e = wp::Bvh::new(&two, &there).unwrap_err();
            has(&e, "argument `uppers`");
            has(&e, other.alias());
            let b = wp::Bvh::new(&there, &there).unwrap();
            let (found, counts) = (zeros::<i32, 2>([1, 1], dev), zeros::<i32, 1>(1, dev));
            match wp::launch(k_aabb, 1, (&b, &one, &one, &found, &counts), dev) {
                Err(Error::DeviceMismatch { arg: "bvh", .. }) => {}
                r => panic!("a BVH of another device: {r:?}"),
            }
        }
        None => {
            eprintln!("bvh::bad_input_is_an_error: one device only, other-device cases skipped")
        }
    }
}

//! The volume builder (`warp-runtime/src/objects/volume_build.rs`, the steps behind
//! `Volume::allocate_by_tiles`, `allocate_index_by_tiles`, `allocate_by_voxels` and
//! `allocate_by_points`) against warp-core's CPU builder (`nanovdb::build_from_tiles`,
//! `build_from_voxels`), byte for byte:
//! - on the CPU backend, for random tile and voxel sets (negative coordinates, several uppers,
//!   node boundaries, the ends of the i32 range, duplicates) over every value type, Index and
//!   OnIndex grids, with uniform and non-symmetric transforms;
//! - world points against Warp's rounding (`floor(invMatF * (p - vecF) + 0.5)`, f32 with
//!   NanoVDB's fused multiply-adds), and bad points (NaN, infinite, beyond i32) named;
//! - the C++ steps of `warp-cuda/cuda/wp_volume_build.h`, compiled with g++ and run serially on
//!   the host (with a stable sort and serial scans in place of the primitives), against the CPU
//!   backend's grids (skipped, saying so, without g++);
//! - the first GPU against the CPU (skipped, saying so, without one), and NVRTC accepting the
//!   kernels (skipped without libnvrtc).
//!
//! Every comparison is exact: the builders compute integers, and the two float computations
//! (the world-to-index map, the world bbox) are the same operations on every side.

use std::process::Command;

use warp_core::objects::nanovdb::{self, BuildKind, GridType, Map};
use warp_core::objects::volume::VolumeValue;
use warp_lang as wp;
use wp::glam::{DVec3, IVec3, Vec3};
use wp::VoxelIndex;

#[path = "common/host_cpp.rs"]
mod host_cpp;

// ------------------------------------------------------------------------------------------
// Inputs
// ------------------------------------------------------------------------------------------

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    /// Uniform in `lo..=hi`.
    fn int(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.next() % (hi - lo + 1) as u64) as i64
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Coordinates that exercise the tree: a cluster around the origin, node boundaries on both
/// sides of 0, a few far away (several uppers), the ends of the i32 range, and duplicates.
fn coords(r: &mut Rng, n: usize) -> Vec<IVec3> {
    const EDGES: [i32; 16] = [
        0,
        -1,
        7,
        -8,
        -9,
        127,
        128,
        -128,
        -129,
        4095,
        4096,
        -4096,
        -4097,
        20000,
        i32::MIN,
        i32::MAX,
    ];
    let mut v: Vec<IVec3> = Vec::with_capacity(n);
    for _ in 0..n {
        let c = match r.int(0, 9) {
            0..=5 => IVec3::new(
                r.int(-300, 300) as i32,
                r.int(-40, 200) as i32,
                r.int(-300, 60) as i32,
            ),
            6 | 7 => IVec3::new(
                EDGES[r.int(0, 13) as usize] + r.int(-3, 3) as i32,
                EDGES[r.int(0, 13) as usize] + r.int(-3, 3) as i32,
                EDGES[r.int(0, 13) as usize] + r.int(-3, 3) as i32,
            ),
            8 => IVec3::new(
                EDGES[r.int(0, 15) as usize],
                EDGES[r.int(0, 15) as usize],
                EDGES[r.int(0, 15) as usize],
            ),
            _ => match v.get(r.int(0, v.len().max(1) as i64 - 1) as usize) {
                Some(d) => *d,
                None => IVec3::ZERO,
            },
        };
        v.push(c);
    }
    v
}

/// The cases' input sets: single points, small sets, a few thousand points.
fn coord_sets() -> Vec<Vec<IVec3>> {
    let mut r = Rng(0x9E37_79B9_7F4A_7C15);
    let mut sets = vec![
        vec![IVec3::ZERO],
        vec![IVec3::new(-1, -1, -1)],
        vec![
            IVec3::new(8, 3, -9),
            IVec3::new(8, 3, -9),
            IVec3::new(15, 0, -16),
        ],
        vec![IVec3::splat(i32::MIN), IVec3::splat(i32::MAX)],
        // One leaf (a sort key of no bits for tiles, 9 for voxels); one lower.
        vec![
            IVec3::new(1, 2, 3),
            IVec3::new(1, 2, 3),
            IVec3::new(4, 5, 6),
            IVec3::new(0, 0, 7),
        ],
        vec![
            IVec3::new(-128, 0, 5),
            IVec3::new(-1, 127, -3),
            IVec3::new(-64, 64, 0),
        ],
    ];
    for n in [7, 60, 3000] {
        sets.push(coords(&mut r, n));
    }
    sets
}

/// The transforms: uniform with a translation, and a non-symmetric, anisotropic one.
fn maps() -> Vec<Map> {
    vec![
        Map::uniform(0.25, [-1.0, 2.0, 0.5]),
        Map {
            mat: [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.0, 3.0]],
            translation: [0.125, -4.0, 7.0],
        },
    ]
}

fn arrays(v: &[IVec3]) -> Vec<[i32; 3]> {
    v.iter().map(|c| c.to_array()).collect()
}

/// The first differing byte of two grids, for messages.
fn first_difference(a: &[u8], b: &[u8]) -> String {
    if a.len() != b.len() {
        return format!("sizes {} and {}", a.len(), b.len());
    }
    let k = a.iter().zip(b).position(|(x, y)| x != y).unwrap_or(0);
    format!("first difference at byte {k}: {} vs {}", a[k], b[k])
}

fn assert_same(got: &[u8], want: &[u8], what: &str) {
    assert!(got == want, "{what}: {}", first_difference(got, want));
}

// ------------------------------------------------------------------------------------------
// The CPU backend against the CPU builder
// ------------------------------------------------------------------------------------------

/// A grid value type with its NanoVDB code and little-endian bytes.
trait Bg: VolumeValue + Copy {
    const GRID_TYPE: GridType;
    fn bytes(&self) -> Vec<u8>;
}

impl Bg for f32 {
    const GRID_TYPE: GridType = GridType::Float;
    fn bytes(&self) -> Vec<u8> {
        self.to_le_bytes().to_vec()
    }
}
impl Bg for f64 {
    const GRID_TYPE: GridType = GridType::Double;
    fn bytes(&self) -> Vec<u8> {
        self.to_le_bytes().to_vec()
    }
}
impl Bg for i32 {
    const GRID_TYPE: GridType = GridType::Int32;
    fn bytes(&self) -> Vec<u8> {
        self.to_le_bytes().to_vec()
    }
}
impl Bg for Vec3 {
    const GRID_TYPE: GridType = GridType::Vec3f;
    fn bytes(&self) -> Vec<u8> {
        self.to_array()
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect()
    }
}
impl Bg for DVec3 {
    const GRID_TYPE: GridType = GridType::Vec3d;
    fn bytes(&self) -> Vec<u8> {
        self.to_array()
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect()
    }
}

/// A value grid of `T` over `tiles`, built by `Volume` on `dev`, and by the CPU builder.
fn value_case<T: Bg>(tiles: &[IVec3], bg: T, map: &Map, dev: &wp::Device) -> (Vec<u8>, Vec<u8>) {
    let got = wp::Volume::allocate_by_tiles(tiles, bg, map, dev)
        .unwrap()
        .grid_bytes()
        .unwrap();
    let kind = BuildKind::Value {
        grid_type: T::GRID_TYPE,
        background: &bg.bytes(),
    };
    let want = nanovdb::build_from_tiles(kind, &arrays(tiles), map).unwrap();
    (got, want)
}

/// Every grid the builder makes, on `dev`, against the CPU builder's.
fn every_kind_matches(dev: &wp::Device) {
    for (s, set) in coord_sets().iter().enumerate() {
        for (m, map) in maps().iter().enumerate() {
            let what = |k: &str| format!("set {s} ({} coords), map {m}, {k}", set.len());
            let cases = [
                ("f32", value_case(set, 7.5f32, map, dev)),
                ("f64", value_case(set, -2.25f64, map, dev)),
                ("i32", value_case(set, -3i32, map, dev)),
                ("Vec3", value_case(set, Vec3::new(1.0, -2.0, 0.5), map, dev)),
                (
                    "DVec3",
                    value_case(set, DVec3::new(0.25, 4.0, -8.0), map, dev),
                ),
            ];
            for (k, (got, want)) in &cases {
                assert_same(got, want, &what(k));
            }
            let got = wp::Volume::<VoxelIndex>::allocate_index_by_tiles(set, map, dev)
                .unwrap()
                .grid_bytes()
                .unwrap();
            let want = nanovdb::build_from_tiles(BuildKind::Index, &arrays(set), map).unwrap();
            assert_same(&got, &want, &what("Index"));
            let vol = wp::Volume::<VoxelIndex>::allocate_by_voxels(set, map, dev).unwrap();
            let want = nanovdb::build_from_voxels(&arrays(set), map).unwrap();
            assert_same(&vol.grid_bytes().unwrap(), &want, &what("OnIndex"));
            let mut unique = arrays(set);
            unique.sort_unstable();
            unique.dedup();
            assert_eq!(vol.voxel_count(), unique.len() as u64, "{}", what("voxels"));
        }
    }
}

#[test]
fn cpu_grids_are_the_cpu_builders() {
    every_kind_matches(&wp::cpu());
}

// ------------------------------------------------------------------------------------------
// World points
// ------------------------------------------------------------------------------------------

/// Warp's voxel of a world point (NanoVDB's `applyInverseMapF` then `Vec3::round`): the f32
/// inverse and translation, `fmaf(x, m0, fmaf(y, m1, z * m2))`, `floor(x + 0.5)` in f64.
fn warp_voxel(p: Vec3, map: &Map) -> [i32; 3] {
    let inv = map.inverse().unwrap();
    let t = map.translation.map(|x| x as f32);
    let d = [p.x - t[0], p.y - t[1], p.z - t[2]];
    [0, 1, 2].map(|r| {
        let m = inv[r].map(|x| x as f32);
        let x = d[0].mul_add(m[0], d[1].mul_add(m[1], d[2] * m[2]));
        (x as f64 + 0.5).floor() as i32
    })
}

/// Random world points over a few uppers, and the rounding's edge cases.
fn world_points(r: &mut Rng, n: usize) -> Vec<Vec3> {
    let mut v = vec![
        Vec3::new(-0.5, 0.5, 2.5),
        Vec3::new(-1.5, -0.49999997, 1e-30),
        Vec3::new(-0.0, 0.0, -2.5),
    ];
    for _ in 0..n {
        let s = if r.int(0, 3) == 0 { 3000.0 } else { 40.0 };
        v.push(Vec3::new(
            (r.unit() - 0.5) * s,
            (r.unit() - 0.5) * s,
            (r.unit() - 0.5) * s,
        ));
    }
    v
}

/// Points on `dev` make the grid of their Warp-rounded voxels.
fn points_match(dev: &wp::Device) {
    let mut r = Rng(7);
    let unit = Map::uniform(1.0, [0.0; 3]);
    // The rounding's edges under the identity: -0.5 -> 0, 0.5 -> 1, 2.5 -> 3, -0.49999997 -> 0.
    let p = wp::Array::from_slice(&world_points(&mut r, 0), dev).unwrap();
    let vol = wp::Volume::<VoxelIndex>::allocate_by_points(&p, &unit).unwrap();
    let want = nanovdb::build_from_voxels(&[[0, 1, 3], [-1, 0, 0], [0, 0, -2]], &unit).unwrap();
    assert_same(&vol.grid_bytes().unwrap(), &want, "rounding edges");
    for (m, map) in maps().iter().enumerate() {
        let pts = world_points(&mut r, 5000);
        let voxels: Vec<[i32; 3]> = pts.iter().map(|p| warp_voxel(*p, map)).collect();
        let arr = wp::Array::from_slice(&pts, dev).unwrap();
        let got = wp::Volume::<VoxelIndex>::allocate_by_points(&arr, map)
            .unwrap()
            .grid_bytes()
            .unwrap();
        let want = nanovdb::build_from_voxels(&voxels, map).unwrap();
        assert_same(&got, &want, &format!("map {m}"));
    }
}

#[test]
fn cpu_points_round_as_warp() {
    points_match(&wp::cpu());
}

/// Bad points are an error naming the first one, whatever else is in the array.
fn bad_points_are_named(dev: &wp::Device) {
    let map = Map::uniform(0.5, [0.0; 3]);
    let err = |pts: &[Vec3]| -> String {
        let a = wp::Array::from_slice(pts, dev).unwrap();
        wp::Volume::<VoxelIndex>::allocate_by_points(&a, &map)
            .unwrap_err()
            .to_string()
    };
    let mut pts = vec![Vec3::ONE; 100];
    pts[71] = Vec3::new(0.0, f32::INFINITY, 0.0);
    pts[37] = Vec3::new(f32::NAN, 0.0, 0.0);
    let e = err(&pts);
    assert!(e.contains("point 37") && e.contains("NaN"), "{e}");
    // Finite, but 4e9 voxels away: beyond i32.
    let e = err(&[Vec3::ZERO, Vec3::new(0.0, 0.0, -2e9)]);
    assert!(e.contains("point 1"), "{e}");
    // Voxels near the ends of i32 (2^31 - 128 and -2^31) are fine; empty input is refused as
    // in Warp.
    let a = wp::Array::from_slice(&[Vec3::new(1073741760.0, 0.0, -1073741824.0)], dev).unwrap();
    assert!(wp::Volume::<VoxelIndex>::allocate_by_points(&a, &map).is_ok());
    let e = err(&[]);
    assert!(e.contains("empty"), "{e}");
}

#[test]
fn cpu_bad_points_are_named() {
    bad_points_are_named(&wp::cpu());
}

/// A strided view of points (every other one) builds as its contiguous copy.
#[test]
fn strided_points_are_copied() {
    let dev = wp::cpu();
    let mut r = Rng(3);
    let pts = world_points(&mut r, 200);
    let map = Map::uniform(0.5, [1.0, 0.0, -1.0]);
    let all = wp::Array::from_slice_shape(&pts[..202], (101, 2), &dev).unwrap();
    let column = all.transpose().row(0).unwrap();
    assert!(!column.is_contiguous());
    let got = wp::Volume::<VoxelIndex>::allocate_by_points(&column, &map)
        .unwrap()
        .grid_bytes()
        .unwrap();
    let voxels: Vec<[i32; 3]> = pts[..202]
        .iter()
        .step_by(2)
        .map(|p| warp_voxel(*p, &map))
        .collect();
    assert_same(
        &got,
        &nanovdb::build_from_voxels(&voxels, &map).unwrap(),
        "strided",
    );
}

// ------------------------------------------------------------------------------------------
// The C++ steps on the host
// ------------------------------------------------------------------------------------------

/// The C++ driver: reads a case (u32 words: kind, whether the points are world positions, the
/// layout, the background's words, the f32 inverse and translation, the f64 map, the headers'
/// bytes, the points), runs the header's steps serially in the build's order (the key layout
/// from the bbox with the header's `vb_key_layout`, a stable sort per key word and serial
/// inclusive scans in place of the runtime's primitives; the headers as the host writes them),
/// and writes the grid to the output file (or prints `bad <i>`).
const DRIVER: &str = r#"
#include <algorithm>
#include <cstdio>
#include <cstring>
#include <vector>
#include "wp_volume_build.h"
using namespace wp;

int main(int argc, char** argv) {
  if (argc < 3) return 2;
  FILE* f = fopen(argv[1], "rb");
  if (!f) return 2;
  std::vector<u32> in;
  u32 word;
  while (fread(&word, 4, 1, f) == 1) in.push_back(word);
  fclose(f);
  size_t at = 0;
  auto w = [&]() { return in[at++]; };
  auto wf = [&]() { u32 u = w(); f32 x; memcpy(&x, &u, 4); return x; };
  auto wd = [&]() { u64 lo = w(); u64 hi = w(); u64 u = lo | (hi << 32); f64 x; memcpy(&x, &u, 8); return x; };
  const u32 kind = w(), world = w();
  u32 lay[12];
  for (int k = 0; k < 12; ++k) lay[k] = w();
  const u32 value_size = lay[0], root_size = lay[1], tile_size = lay[3], stride = lay[5];
  const u32 up_table = lay[6], up_size = lay[7], lo_table = lay[8], lo_size = lay[9];
  const u32 leaf_table = lay[10], leaf_size = lay[11];
  u32 bg[6];
  for (int k = 0; k < 6; ++k) bg[k] = w();
  vb_ijk_t ijk_rec{};
  for (int k = 0; k < 9; ++k) ijk_rec.inv[k] = wf();
  for (int k = 0; k < 3; ++k) ijk_rec.t[k] = wf();
  vb_world_t world_rec{};
  for (int k = 0; k < 9; ++k) world_rec.mat[k] = wd();
  for (int k = 0; k < 3; ++k) world_rec.t[k] = wd();
  const u32 head_words = w();
  std::vector<u32> head(in.begin() + at, in.begin() + at + head_words);
  at += head_words;
  const u64 n = w();
  std::vector<u32> pts(in.begin() + at, in.begin() + at + 3 * n);

  std::vector<i32> ijk(3 * n);
  if (world) {
    i32 bad = -1;
    ijk_rec.points = (u64)pts.data();
    ijk_rec.ijk = (u64)ijk.data();
    ijk_rec.n = n;
    for (u64 i = 0; i < n; ++i)
      if (!vb_ijk_at(ijk_rec, i) && bad < 0) bad = (i32)i;
    if (bad >= 0) { printf("bad %d\n", bad); return 0; }
  } else {
    memcpy(ijk.data(), pts.data(), 12 * n);
  }
  const u32 voxels = kind == vb_kind_on_index ? 1 : 0;
  i32 box[6] = {2147483647, 2147483647, 2147483647, -2147483647 - 1, -2147483647 - 1, -2147483647 - 1};
  vb_bounds_t bounds{(u64)ijk.data(), (u64)box, n};
  for (u64 i = 0; i < n; ++i) vb_bounds_add(bounds, i, box);
  u32 lo[12], bits[12];
  const u32 total = vb_key_layout(box, voxels, lo, bits);
  std::vector<u32> keys(n), perm(n);
  for (u32 word_k = 0; word_k < (total + 31) / 32 || word_k == 0; ++word_k) {
    vb_keys_t k{(u64)ijk.data(), (u64)perm.data(), (u64)keys.data(), n, word_k, 0, {}, {}};
    memcpy(k.lo, lo, sizeof lo);
    memcpy(k.bits, bits, sizeof bits);
    for (u64 i = 0; i < n; ++i) vb_keys_at(k, i);
    std::vector<std::pair<u32, u32>> pairs(n);
    for (u64 i = 0; i < n; ++i) pairs[i] = {keys[i], perm[i]};
    std::stable_sort(pairs.begin(), pairs.end(),
                     [](const std::pair<u32, u32>& a, const std::pair<u32, u32>& b) { return a.first < b.first; });
    for (u64 i = 0; i < n; ++i) { keys[i] = pairs[i].first; perm[i] = pairs[i].second; }
  }
  std::vector<i32> sorted(3 * n);
  std::vector<u64> sa(n), sb(n);
  vb_flags_t fl{(u64)ijk.data(), (u64)perm.data(), (u64)sorted.data(), (u64)sa.data(), (u64)sb.data(), n, voxels, 0};
  for (u64 i = 0; i < n; ++i) vb_flags_at(fl, i);
  for (u64 i = 1; i < n; ++i) { sa[i] += sa[i - 1]; sb[i] += sb[i - 1]; }
  i32 counts[4];
  vb_totals_t tot{(u64)sa.data(), (u64)sb.data(), (u64)counts, n};
  vb_totals(tot);
  const u64 U = counts[0], Lo = counts[1], Lf = counts[2];
  const u64 root = 736, tiles = root + root_size, upper = tiles + U * tile_size;
  const u64 lower = upper + U * up_size, leaf = lower + Lo * lo_size, size = leaf + Lf * leaf_size;
  std::vector<u64> grid(size / 8, 0);
  memcpy(grid.data(), head.data(), 4 * head_words);
  const u64 g = (u64)grid.data();
  if (kind == vb_kind_value) {
    const u64 levels[3][5] = {{upper + up_table, U, up_size, 15, stride},
                              {lower + lo_table, Lo, lo_size, 12, stride},
                              {leaf + leaf_table, Lf, leaf_size, 9, value_size}};
    for (const auto& l : levels) {
      vb_fill_t fill{g + l[0], l[1] << l[3], l[2], (u32)l[3], (u32)l[4], value_size / 4, 0, {}};
      memcpy(fill.bg, bg, sizeof bg);
      for (u64 e = 0; e < fill.count; ++e) vb_fill_at(fill, e);
    }
  }
  std::vector<u32> leaf_lower(Lf), lower_upper(Lo);
  vb_link_t link{(u64)sorted.data(), (u64)sa.data(), (u64)sb.data(), g, (u64)leaf_lower.data(),
                 (u64)lower_upper.data(), n, root, tiles, upper, lower, leaf, tile_size, up_size,
                 up_table, lo_size, lo_table, leaf_size, leaf_table, stride, kind, 0};
  for (u64 i = 0; i < n; ++i) vb_link_at(link, i);
  vb_leaf_box_t lb{g, leaf, lower, (u64)leaf_lower.data(), Lf, leaf_size, leaf_table, lo_size, kind == vb_kind_on_index};
  for (u64 k = 0; k < Lf; ++k) vb_leaf_box_at(lb, k);
  vb_node_box_t nb{g, lower, upper, (u64)lower_upper.data(), Lo, lo_size, up_size};
  for (u64 k = 0; k < Lo; ++k) vb_node_box_at(nb, k);
  vb_node_box_t rb{g, upper, root, 0, U, up_size, 0};
  for (u64 k = 0; k < U; ++k) vb_node_box_at(rb, k);
  world_rec.grid = g;
  world_rec.root = root;
  vb_world(world_rec);
  FILE* o = fopen(argv[2], "wb");
  if (!o) return 2;
  fwrite(grid.data(), 1, size, o);
  fclose(o);
  printf("ok %d %d %d %d\n", counts[0], counts[1], counts[2], counts[3]);
  return 0;
}
"#;

/// One case for the driver: the grid the CPU backend built (whose headers the driver starts
/// from, with the two bboxes the steps compute reset), its kind, its inputs.
struct CppCase {
    kind: u32,
    grid_type: GridType,
    background: Vec<u8>,
    map: Map,
    coords: Vec<[i32; 3]>,
    world: Option<Vec<Vec3>>,
    want: Vec<u8>,
}

fn case_words(c: &CppCase) -> Vec<u32> {
    let l = nanovdb::Layout::of(c.grid_type).unwrap();
    let mut w = vec![c.kind, c.world.is_some() as u32];
    w.extend(
        [
            l.value_size,
            l.root_size,
            l.background,
            l.tile_size,
            l.tile_value,
            l.stride,
            l.up_table,
            l.up_size,
            l.lo_table,
            l.lo_size,
            l.leaf_table,
            l.leaf_size,
        ]
        .map(|x| x as u32),
    );
    let mut bg = [0u32; 6];
    for (k, b) in c.background.chunks_exact(4).enumerate() {
        bg[k] = u32::from_le_bytes(b.try_into().unwrap());
    }
    w.extend(bg);
    let inv = c.map.inverse().unwrap();
    w.extend(inv.iter().flatten().map(|x| (*x as f32).to_bits()));
    w.extend(c.map.translation.map(|x| (x as f32).to_bits()));
    for x in c.map.mat.iter().flatten().chain(&c.map.translation) {
        let b = x.to_bits();
        w.extend([b as u32, (b >> 32) as u32]);
    }
    // The headers as the host writes them: the built grid's, with the root bbox empty and the
    // world bbox that of an empty grid.
    let l_root = nanovdb::GRID_DATA + nanovdb::TREE_DATA;
    let mut head = c.want[..l_root + l.root_size].to_vec();
    for k in 0..3 {
        head[nanovdb::grid::WORLD_BBOX + 8 * k..][..8].copy_from_slice(&f64::MAX.to_le_bytes());
        head[nanovdb::grid::WORLD_BBOX + 24 + 8 * k..][..8]
            .copy_from_slice(&(-f64::MAX).to_le_bytes());
        head[l_root + 4 * k..][..4].copy_from_slice(&i32::MAX.to_le_bytes());
        head[l_root + 12 + 4 * k..][..4].copy_from_slice(&i32::MIN.to_le_bytes());
    }
    w.push((head.len() / 4) as u32);
    w.extend(
        head.chunks_exact(4)
            .map(|b| u32::from_le_bytes(b.try_into().unwrap())),
    );
    match &c.world {
        Some(p) => {
            w.push(p.len() as u32);
            w.extend(p.iter().flat_map(|v| v.to_array().map(f32::to_bits)));
        }
        None => {
            w.push(c.coords.len() as u32);
            w.extend(c.coords.iter().flat_map(|v| v.map(|x| x as u32)));
        }
    }
    w
}

fn cpp_cases() -> Vec<CppCase> {
    let dev = wp::cpu();
    let mut cases = Vec::new();
    let mut r = Rng(11);
    for set in coord_sets() {
        for map in maps() {
            let c = arrays(&set);
            let (_, want) = value_case(&set, 7.5f32, &map, &dev);
            cases.push(CppCase {
                kind: 0,
                grid_type: GridType::Float,
                background: 7.5f32.to_le_bytes().to_vec(),
                map,
                coords: c.clone(),
                world: None,
                want,
            });
            let (_, want) = value_case(&set, DVec3::new(0.25, 4.0, -8.0), &map, &dev);
            cases.push(CppCase {
                kind: 0,
                grid_type: GridType::Vec3d,
                background: DVec3::new(0.25, 4.0, -8.0).bytes(),
                map,
                coords: c.clone(),
                world: None,
                want,
            });
            let want = wp::Volume::<VoxelIndex>::allocate_index_by_tiles(&set, &map, &dev)
                .unwrap()
                .grid_bytes()
                .unwrap();
            cases.push(CppCase {
                kind: 1,
                grid_type: GridType::Index,
                background: vec![],
                map,
                coords: c.clone(),
                world: None,
                want,
            });
            let want = wp::Volume::<VoxelIndex>::allocate_by_voxels(&set, &map, &dev)
                .unwrap()
                .grid_bytes()
                .unwrap();
            cases.push(CppCase {
                kind: 2,
                grid_type: GridType::OnIndex,
                background: vec![],
                map,
                coords: c,
                world: None,
                want,
            });
        }
    }
    for map in maps() {
        let pts = world_points(&mut r, 2000);
        let arr = wp::Array::from_slice(&pts, &dev).unwrap();
        let want = wp::Volume::<VoxelIndex>::allocate_by_points(&arr, &map)
            .unwrap()
            .grid_bytes()
            .unwrap();
        cases.push(CppCase {
            kind: 2,
            grid_type: GridType::OnIndex,
            background: vec![],
            map,
            coords: vec![],
            world: Some(pts),
            want,
        });
    }
    cases
}

/// The header compiles as host C++ (g++, warnings as errors, no FMA contraction), and its
/// steps, run serially in the build's order, write the CPU backend's grids byte for byte.
#[test]
fn cpp_steps_write_the_cpu_grids() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED volume_build::cpp_steps_write_the_cpu_grids: no g++");
        return;
    }
    let (dir, exe) = host_cpp::compile_driver("volume_build", DRIVER, &["WP_VOLUME_BUILD"]);
    for (k, case) in cpp_cases().iter().enumerate() {
        let (input, output) = (
            dir.join(format!("case{k}.bin")),
            dir.join(format!("grid{k}.bin")),
        );
        let bytes: Vec<u8> = case_words(case)
            .iter()
            .flat_map(|w| w.to_le_bytes())
            .collect();
        std::fs::write(&input, bytes).unwrap();
        let run = Command::new(&exe)
            .arg(&input)
            .arg(&output)
            .output()
            .unwrap();
        let said = String::from_utf8_lossy(&run.stdout);
        assert!(
            run.status.success() && said.starts_with("ok"),
            "case {k}: {said}"
        );
        let got = std::fs::read(&output).unwrap();
        assert_same(
            &got,
            &case.want,
            &format!("C++ case {k} ({:?})", case.grid_type),
        );
    }
    // A bad world point: the driver names the first, as the runtime does.
    let mut bad = cpp_cases().pop().unwrap();
    let pts = bad.world.as_mut().unwrap();
    pts[9].y = f32::NAN;
    pts[4].z = 3e12;
    let input = dir.join("bad.bin");
    let bytes: Vec<u8> = case_words(&bad)
        .iter()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    std::fs::write(&input, bytes).unwrap();
    let run = Command::new(&exe)
        .arg(&input)
        .arg(dir.join("bad.grid"))
        .output()
        .unwrap();
    assert_eq!(String::from_utf8_lossy(&run.stdout), "bad 4\n");
    let _ = std::fs::remove_dir_all(&dir);
}

// ------------------------------------------------------------------------------------------
// A GPU
// ------------------------------------------------------------------------------------------

fn gpu(test: &str) -> Option<wp::Device> {
    match wp::get_device("cuda:0") {
        Ok(d) => Some(d),
        Err(e) => {
            eprintln!("SKIPPED volume_build::{test}: no CUDA device ({e})");
            None
        }
    }
}

/// On a GPU every grid is the CPU builder's too, byte for byte, and bad points are named.
#[test]
fn gpu_grids_are_the_cpu_builders() {
    let Some(dev) = gpu("gpu_grids_are_the_cpu_builders") else {
        return;
    };
    every_kind_matches(&dev);
    points_match(&dev);
    bad_points_are_named(&dev);
}

/// A million points on a GPU, as the benchmark allocates them: the grid is the CPU builder's
/// (which rounds on the host), and the build's time is printed (median of 5, after a warm-up).
#[test]
fn gpu_million_points() {
    let Some(dev) = gpu("gpu_million_points") else {
        return;
    };
    let mut r = Rng(5);
    let pts: Vec<Vec3> = (0..1_000_000)
        .map(|_| {
            // A thin spherical shell of radius 0.6 (voxel size 1/128), like the benchmark's band.
            let d = Vec3::new(r.unit() - 0.5, r.unit() - 0.5, r.unit() - 0.5).normalize_or_zero();
            d * (0.6 + 0.05 * (r.unit() - 0.5))
        })
        .collect();
    let map = Map::uniform(1.0 / 128.0, [-1.0, -1.0, -1.0]);
    let arr = wp::Array::from_slice(&pts, &dev).unwrap();
    let vol = wp::Volume::<VoxelIndex>::allocate_by_points(&arr, &map).unwrap();
    let voxels: Vec<[i32; 3]> = pts.iter().map(|p| warp_voxel(*p, &map)).collect();
    let want = nanovdb::build_from_voxels(&voxels, &map).unwrap();
    assert_same(&vol.grid_bytes().unwrap(), &want, "1M points");
    let mut ms = Vec::new();
    for _ in 0..6 {
        wp::synchronize().unwrap();
        let t = std::time::Instant::now();
        let v = wp::Volume::<VoxelIndex>::allocate_by_points(&arr, &map).unwrap();
        wp::synchronize().unwrap();
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        drop(v);
    }
    ms.remove(0);
    ms.sort_by(f64::total_cmp);
    eprintln!(
        "volume_build: allocate_by_points of 1M points on {}: {:.3} ms (median of 5), {} voxels",
        dev.alias(),
        ms[2],
        vol.voxel_count()
    );
}

/// NVRTC accepts the volume build library for sm_90 (H100, H200) and sm_80 (A100) with the
/// runtime's options, without warnings: needs libnvrtc, no GPU; skipped, saying so, without it.
#[test]
fn nvrtc_compiles_the_kernels() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED volume_build::nvrtc_compiles_the_kernels: {e}");
        return;
    }
    let lib = wp::objects::build_libraries()
        .find(|l| l.section() == "volume_build")
        .expect("the volume build library is listed");
    for arch in [90, 80] {
        let c = wp::objects::compile_library(&lib, arch)
            .unwrap_or_else(|e| panic!("{} for sm_{arch}: {e}", lib.section()));
        assert!(!c.cubin.is_empty());
        assert!(!c.log.contains("warning"), "sm_{arch}: {}", c.log);
    }
}

// wp_volume_build.h: building a NanoVDB grid on a GPU from tiles, voxels or world points, the
// build steps of warp-runtime's objects/volume_build.rs (`Volume::allocate_by_tiles`,
// `allocate_index_by_tiles`, `allocate_by_voxels`, `allocate_by_points`), which runs the same
// steps on the CPU with rayon. Both write the same bytes, which are the bytes of warp-core's CPU
// builder (`objects::nanovdb::build_from_tiles` / `build_from_voxels`, laid out as Warp 1.19's
// `volume_builder.cu` lays grids out; docs/nanovdb.md sections 2 and 6).
//
// Every step below is exact: integer keys and masks, atomic OR / min / max (order-free), and two
// float computations spelled out operation by operation (the world-to-index map, with Warp's
// fused multiply-adds; the world bbox, with none).
//
// Coordinates: a point's voxel is ijk (i32 x 3). Its upper node is ijk >> 12 (4096^3 voxels),
// its lower node ijk >> 7 (128^3), its leaf ijk >> 3 (8^3). Node order (Warp's): uppers by their
// signed origins (x, then y, then z), lowers by (upper, slot in the upper), leaves by (lower,
// slot in the lower). That is the lexicographic order of 12 fields,
//   X Y Z (20 bits each: (x + 2^31) >> 12) | upper slot x y z (5 bits each: (x >> 7) & 31)
//   | lower slot x y z (4: (x >> 3) & 15) [| leaf slot x y z (3: x & 7), voxel grids only]
// (87 or 96 bits). The build compacts that key with the points' index bbox (read back once,
// before the sort): a field that cannot vary gets no bits, the others their range's bits from
// their minimum (a slot field spans its whole range unless the coarser fields of its axis are
// constant). The order is unchanged, and typical inputs fit one 32-bit word, where the full key
// needs three. The words (least significant first) go through the runtime's stable radix sort
// of (word, point index) pairs: an LSD sort of the whole key. After the sort, equal nodes are
// runs; flags at the run starts, scanned, number the nodes.
//
// Steps (one kernel each, grid-stride loops over the record's count):
//   wp_vb_ijk      (world points only) ijk = floor(invMatF * (p - vecF) + 0.5): f32 with
//                  Warp's fmaf order, then the +0.5 and floor in f64 (exact). A NaN, infinite
//                  or out-of-i32 result stores 0 and lowers *bad to the point's index.
//   wp_vb_bounds   the index bbox of the voxels (per-block reduction, then atomic min/max);
//                  (the host reads it back with *bad and lays out the compact key:
//                  vb_key_layout)
//   wp_vb_keys     one 32-bit word of each point's compact key (word 0: with perm = identity;
//                  words 1 and 2: of the point perm[i], the order of the previous sorts).
//   (the runtime's stable radix sort of (keys, perm), once per word)
//   wp_vb_flags    per sorted position i: sorted[i] = ijk[perm[i]], and whether it starts a new
//                  upper, lower, leaf, voxel (differs from position i - 1 above that level),
//                  packed into two u64s: scan_a = upper << 32 | lower, scan_b = leaf << 32 |
//                  voxel (voxel grids only; 0 for tiles).
//   (the runtime's inclusive u64 scans of scan_a and scan_b: the 32-bit halves cannot carry,
//    each count being at most the point count < 2^31; so position i's upper id is
//    (scan_a[i] >> 32) - 1, its lower id (scan_a[i] & 0xffffffff) - 1, ...)
//   wp_vb_totals   one thread: the four counts (uppers, lowers, leaves, voxels) into counts[0..4],
//                  which the host reads back (the build's second and last wait).
//   (the host allocates the zeroed grid and writes GridData, TreeData and RootData: the
//    header, the map, the counts, the root's empty bbox and background)
//   wp_vb_fill     value grids: the background into every table entry of a level (uppers,
//                  lowers: 2^15, 2^12 entries; leaves: 512 values), one thread per entry.
//   wp_vb_link     per sorted position, at the start of a run: a new upper writes its root tile
//                  (key, child offset) and empties its bbox; a new lower sets its bit in the
//                  upper's child mask (atomic OR), its child offset in the upper's table, empties
//                  its bbox and records its upper; a new leaf does the same in its lower, writes
//                  its origin (as bboxMin), flags 2, and, by kind: all 512 mask bits (tile
//                  grids), mOffset = leaf * 512 + 1 (Index), mOffset = 1 + active voxels before
//                  it (OnIndex: the inclusive voxel count at its first position). OnIndex: every
//                  position ORs its voxel's bit into the leaf's mask (duplicates are harmless).
//   wp_vb_leaf_box per leaf: the bbox of its active voxels from its mask (dif, flags 2); OnIndex
//                  also mPrefixSum (9-bit running popcounts of mask words 0..6); then atomic
//                  min/max into its lower's bbox.
//   wp_vb_node_box per lower (into its upper's bbox), then per upper (into the root's): atomic
//                  min/max of the child's bbox.
//   wp_vb_world    one thread: the world bbox, the 8 corners of the root's index bbox mapped by
//                  matD/vecD (f64, no FMA), min and max (Warp's CUDA builder's corners min..max).
//
// Host C++ (g++/clang++) compiles the same functions with __atomic builtins for the atomics, so
// the steps can run serially on the host against the Rust steps (tests/volume_build.rs).
#pragma once
#include "wp_core.h"

namespace wp {

// The NanoVDB byte offsets the steps use (warp-core objects::nanovdb's constants).
constexpr u64 vb_upper_child_mask = 4128;  // UPPER_CHILD_MASK
constexpr u64 vb_lower_child_mask = 544;   // LOWER_CHILD_MASK
constexpr u64 vb_leaf_value_mask = 16;     // LEAF_VALUE_MASK
constexpr u64 vb_leaf_bbox_dif = 12;       // LEAF_BBOX_DIF (3 x u8 dif, u8 flags)
constexpr u64 vb_world_bbox = 560;         // grid::WORLD_BBOX

/// The kinds of grid the link step builds.
constexpr u32 vb_kind_value = 0;
constexpr u32 vb_kind_index = 1;
constexpr u32 vb_kind_on_index = 2;

namespace vb_detail {
#if defined(__CUDA_ARCH__)
WP_FN void or64(u64 addr, u64 bits) { atomicOr((unsigned long long*)addr, (unsigned long long)bits); }
WP_FN void min32(u64 addr, i32 v) { atomicMin((int*)addr, v); }
WP_FN void max32(u64 addr, i32 v) { atomicMax((int*)addr, v); }
WP_FN i32 popc64(u64 x) { return __popcll(x); }
WP_FN i32 ctz64(u64 x) { return __ffsll((long long)x) - 1; }
WP_FN i32 clz64(u64 x) { return __clzll((long long)x); }
WP_FN f32 fma_rn(f32 a, f32 b, f32 c) { return __fmaf_rn(a, b, c); }
WP_FN f32 mul(f32 a, f32 b) { return __fmul_rn(a, b); }
WP_FN f32 sub(f32 a, f32 b) { return __fsub_rn(a, b); }
WP_FN f64 dmul(f64 a, f64 b) { return __dmul_rn(a, b); }
WP_FN f64 dadd(f64 a, f64 b) { return __dadd_rn(a, b); }
WP_FN f64 dfloor(f64 x) { return floor(x); }
#else
WP_FN void or64(u64 addr, u64 bits) { __atomic_fetch_or((u64*)addr, bits, __ATOMIC_RELAXED); }
WP_FN void min32(u64 addr, i32 v) {
  i32* p = (i32*)addr;
  i32 old = __atomic_load_n(p, __ATOMIC_RELAXED);
  while (v < old && !__atomic_compare_exchange_n(p, &old, v, true, __ATOMIC_RELAXED, __ATOMIC_RELAXED)) {
  }
}
WP_FN void max32(u64 addr, i32 v) {
  i32* p = (i32*)addr;
  i32 old = __atomic_load_n(p, __ATOMIC_RELAXED);
  while (v > old && !__atomic_compare_exchange_n(p, &old, v, true, __ATOMIC_RELAXED, __ATOMIC_RELAXED)) {
  }
}
WP_FN i32 popc64(u64 x) { return __builtin_popcountll(x); }
WP_FN i32 ctz64(u64 x) { return __builtin_ctzll(x); }
WP_FN i32 clz64(u64 x) { return __builtin_clzll(x); }
WP_FN f32 fma_rn(f32 a, f32 b, f32 c) { return std::fma(a, b, c); }
WP_FN f32 mul(f32 a, f32 b) { return a * b; }
WP_FN f32 sub(f32 a, f32 b) { return a - b; }
WP_FN f64 dmul(f64 a, f64 b) { return a * b; }
WP_FN f64 dadd(f64 a, f64 b) { return a + b; }
WP_FN f64 dfloor(f64 x) { return std::floor(x); }
#endif

/// Stores and loads at byte addresses (every address the steps use is aligned for its type: the
/// grid starts 32-byte aligned and every offset is a multiple of the width).
template <typename T>
WP_FN void put(u64 addr, T v) { *(T*)addr = v; }
template <typename T>
WP_FN T load_at(u64 addr) { return *(const T*)addr; }
}  // namespace vb_detail

/// VolumeBuildIjk (80 bytes): points (f32 x 3 each), ijk (i32 x 3 each), bad (i32, one), n,
/// inv (invMatF, row-major), t (vecF).
struct vb_ijk_t {
  u64 points;
  u64 ijk;
  u64 bad;
  u64 n;
  f32 inv[9];
  f32 t[3];
};
static_assert(sizeof(vb_ijk_t) == 80, "vb_ijk_t layout");

/// VolumeBuildBounds (24 bytes): ijk, bounds (i32 x 6: min xyz, max xyz; atomically
/// narrowed), n.
struct vb_bounds_t {
  u64 ijk;
  u64 bounds;
  u64 n;
};
static_assert(sizeof(vb_bounds_t) == 24, "vb_bounds_t layout");

/// VolumeBuildKeys (136 bytes): ijk, perm (u32, one per point), keys (u32, one per point), n,
/// word (0, 1, 2), pad, and the compact key's layout (vb_key_layout): each field's minimum and
/// bits.
struct vb_keys_t {
  u64 ijk;
  u64 perm;
  u64 keys;
  u64 n;
  u32 word;
  u32 pad;
  u32 lo[12];
  u32 bits[12];
};
static_assert(sizeof(vb_keys_t) == 136, "vb_keys_t layout");

/// VolumeBuildFlags (56 bytes): ijk, perm (sorted), sorted (i32 x 3 out), scan_a, scan_b (u64
/// out), n, voxels (nonzero: a voxel grid, whose distinct voxels are counted), pad.
struct vb_flags_t {
  u64 ijk;
  u64 perm;
  u64 sorted;
  u64 scan_a;
  u64 scan_b;
  u64 n;
  u32 voxels;
  u32 pad;
};
static_assert(sizeof(vb_flags_t) == 56, "vb_flags_t layout");

/// VolumeBuildTotals (32 bytes): scan_a, scan_b (scanned), counts (i32 x 4 out), n (>= 1).
struct vb_totals_t {
  u64 scan_a;
  u64 scan_b;
  u64 counts;
  u64 n;
};
static_assert(sizeof(vb_totals_t) == 32, "vb_totals_t layout");

/// VolumeBuildFill (64 bytes): base (the address of node 0's first table entry), count
/// (entries), node_size (bytes), log2 (entries per node), stride (bytes per entry), words (u32
/// words of a value), bg (the value's words).
struct vb_fill_t {
  u64 base;
  u64 count;
  u64 node_size;
  u32 log2;
  u32 stride;
  u32 words;
  u32 pad;
  u32 bg[6];
};
static_assert(sizeof(vb_fill_t) == 64, "vb_fill_t layout");

/// VolumeBuildLink (136 bytes): sorted, scan_a, scan_b (per sorted position), grid (the
/// buffer's address), leaf_lower, lower_upper (u32 out: each leaf's lower, each lower's upper),
/// n; root, tiles, upper, lower, leaf (byte offsets of RootData, the first root tile and the
/// first node of each level); the layout's sizes and offsets; kind (vb_kind_*).
struct vb_link_t {
  u64 sorted;
  u64 scan_a;
  u64 scan_b;
  u64 grid;
  u64 leaf_lower;
  u64 lower_upper;
  u64 n;
  u64 root;
  u64 tiles;
  u64 upper;
  u64 lower;
  u64 leaf;
  u32 tile_size;
  u32 up_size;
  u32 up_table;
  u32 lo_size;
  u32 lo_table;
  u32 leaf_size;
  u32 leaf_table;
  u32 stride;
  u32 kind;
  u32 pad;
};
static_assert(sizeof(vb_link_t) == 136, "vb_link_t layout");

/// VolumeBuildLeafBox (56 bytes): grid, leaf, lower (offsets of the first leaf and lower),
/// leaf_lower, count (leaves), leaf_size, leaf_table, lo_size, on_index (1: write mPrefixSum).
struct vb_leaf_box_t {
  u64 grid;
  u64 leaf;
  u64 lower;
  u64 leaf_lower;
  u64 count;
  u32 leaf_size;
  u32 leaf_table;
  u32 lo_size;
  u32 on_index;
};
static_assert(sizeof(vb_leaf_box_t) == 56, "vb_leaf_box_t layout");

/// VolumeBuildNodeBox (48 bytes): grid, child, parent (offsets of the first child and parent
/// node), parent_of (u32 per child, or 0: every child's parent is node 0), count (children),
/// child_size, parent_size.
struct vb_node_box_t {
  u64 grid;
  u64 child;
  u64 parent;
  u64 parent_of;
  u64 count;
  u32 child_size;
  u32 parent_size;
};
static_assert(sizeof(vb_node_box_t) == 48, "vb_node_box_t layout");

/// VolumeBuildWorld (112 bytes): grid, root (offset of RootData), mat (row-major f64), t.
struct vb_world_t {
  u64 grid;
  u64 root;
  f64 mat[9];
  f64 t[3];
};
static_assert(sizeof(vb_world_t) == 112, "vb_world_t layout");

/// The ijk step at point i; returns whether the point has a voxel.
WP_FN bool vb_ijk_at(const vb_ijk_t& s, u64 i) {
  const f32* p = (const f32*)s.points + 3 * i;
  const f32 d0 = vb_detail::sub(p[0], s.t[0]);
  const f32 d1 = vb_detail::sub(p[1], s.t[1]);
  const f32 d2 = vb_detail::sub(p[2], s.t[2]);
  i32* out = (i32*)s.ijk + 3 * i;
  bool ok = true;
  i32 v[3];
  for (i32 r = 0; r < 3; ++r) {
    const f32* m = s.inv + 3 * r;
    // NanoVDB's matMult: fmaf(x, m0, fmaf(y, m1, z * m2)); then Vec3::round: floor(x + 0.5)
    // with 0.5 a double (exact for every f32).
    const f32 x = vb_detail::fma_rn(d0, m[0], vb_detail::fma_rn(d1, m[1], vb_detail::mul(d2, m[2])));
    const f64 f = vb_detail::dfloor((f64)x + 0.5);
    // False for NaN too.
    const bool in = f >= -2147483648.0 && f <= 2147483647.0;
    v[r] = in ? (i32)f : 0;
    ok = ok && in;
  }
  if (!ok) v[0] = v[1] = v[2] = 0;
  out[0] = v[0];
  out[1] = v[1];
  out[2] = v[2];
  return ok;
}

/// Field `level` (0 upper origin, 1 upper slot, 2 lower slot, 3 leaf slot) of coordinate v.
WP_FN u32 vb_field(i32 v, u32 level) {
  const u32 u = (u32)v;
  if (level == 0) return (u ^ 0x80000000u) >> 12;
  if (level == 1) return (u >> 7) & 31u;
  if (level == 2) return (u >> 3) & 15u;
  return u & 7u;
}

/// The compact key's layout for voxels in the index bbox `b` (min xyz, max xyz): field f (level
/// f / 3, axis f % 3, most significant first) is stored as its value minus lo[f] in bits[f]
/// bits. A level-0 field ranges over the fields of the bbox's corners (the field is monotone);
/// a slot field over the corners' slots when the coarser level of its axis is the same at both
/// corners, else over every slot. `leaf_slots` 0 leaves the leaf slots out (tile grids).
/// Returns the total bits (at most 96).
WP_FN u32 vb_key_layout(const i32* b, u32 leaf_slots, u32* lo, u32* bits) {
  const u32 full[4] = {0xfffffu, 31u, 15u, 7u};
  const i32 parent_shift[4] = {0, 12, 7, 3};
  u32 total = 0;
  for (u32 f = 0; f < 12; ++f) {
    const u32 level = f / 3, axis = f % 3;
    const i32 mn = b[axis], mx = b[3 + axis];
    u32 l = 0, h = full[level];
    if (level == 0 || (mn >> parent_shift[level]) == (mx >> parent_shift[level])) {
      l = vb_field(mn, level);
      h = vb_field(mx, level);
    }
    if (level == 3 && !leaf_slots) h = l = 0;
    u32 n = 0;
    while (n < 32 && ((h - l) >> n) != 0) ++n;
    lo[f] = l;
    bits[f] = n;
    total += n;
  }
  return total;
}

/// Word `word` (0 least significant) of voxel c's compact key.
WP_FN u32 vb_key_word(const i32* c, u32 word, const u32* lo, const u32* bits) {
  u64 hi = 0, low = 0;
  for (u32 f = 0; f < 12; ++f) {
    const u32 b = bits[f];
    if (b == 0) continue;
    const u64 v = (u64)(vb_field(c[f % 3], f / 3) - lo[f]);
    hi = (hi << b) | (low >> (64 - b));
    low = (low << b) | v;
  }
  if (word == 0) return (u32)low;
  if (word == 1) return (u32)(low >> 32);
  return (u32)hi;
}

/// The bounds step's element: point i's voxel into the running box `acc`.
WP_FN void vb_bounds_add(const vb_bounds_t& s, u64 i, i32* acc) {
  const i32* c = (const i32*)s.ijk + 3 * i;
  for (i32 a = 0; a < 3; ++a) {
    if (c[a] < acc[a]) acc[a] = c[a];
    if (c[a] > acc[3 + a]) acc[3 + a] = c[a];
  }
}

/// The keys step at point i.
WP_FN void vb_keys_at(const vb_keys_t& s, u64 i) {
  u32* perm = (u32*)s.perm;
  u64 p = i;
  if (s.word == 0)
    perm[i] = (u32)i;
  else
    p = perm[i];
  const i32* c = (const i32*)s.ijk + 3 * p;
  ((u32*)s.keys)[i] = vb_key_word(c, s.word, s.lo, s.bits);
}

/// The flags step at sorted position i.
WP_FN void vb_flags_at(const vb_flags_t& s, u64 i) {
  const i32* ijk = (const i32*)s.ijk;
  const u32* perm = (const u32*)s.perm;
  const i32* c = ijk + 3 * (u64)perm[i];
  i32* out = (i32*)s.sorted + 3 * i;
  out[0] = c[0];
  out[1] = c[1];
  out[2] = c[2];
  u64 up = 1, lo = 1, lf = 1, vx = 1;
  if (i > 0) {
    const i32* q = ijk + 3 * (u64)perm[i - 1];
    // The highest differing bit of any coordinate says which levels change.
    const u32 d = ((u32)c[0] ^ (u32)q[0]) | ((u32)c[1] ^ (u32)q[1]) | ((u32)c[2] ^ (u32)q[2]);
    up = d > 4095u;
    lo = d > 127u;
    lf = d > 7u;
    vx = d != 0u;
  }
  if (!s.voxels) vx = 0;
  ((u64*)s.scan_a)[i] = (up << 32) | lo;
  ((u64*)s.scan_b)[i] = (lf << 32) | vx;
}

/// The totals step (one thread).
WP_FN void vb_totals(const vb_totals_t& s) {
  const u64 a = ((const u64*)s.scan_a)[s.n - 1];
  const u64 b = ((const u64*)s.scan_b)[s.n - 1];
  i32* c = (i32*)s.counts;
  c[0] = (i32)(a >> 32);
  c[1] = (i32)(a & 0xffffffffu);
  c[2] = (i32)(b >> 32);
  c[3] = (i32)(b & 0xffffffffu);
}

/// The fill step at entry e.
WP_FN void vb_fill_at(const vb_fill_t& s, u64 e) {
  const u64 node = e >> s.log2;
  const u64 k = e & (((u64)1 << s.log2) - 1);
  u32* at = (u32*)(s.base + node * s.node_size + k * s.stride);
  for (u32 w = 0; w < s.words; ++w) at[w] = s.bg[w];
}

/// The slot of (x, y, z)'s child in a node of `log2` over children of `child_bits` voxels.
WP_FN u64 vb_slot(const i32* c, u32 log2, u32 child_bits) {
  const u32 mask = (1u << (log2 + child_bits)) - 1;
  return ((u64)(((u32)c[0] & mask) >> child_bits) << (2 * log2)) |
         ((u64)(((u32)c[1] & mask) >> child_bits) << log2) | (u64)(((u32)c[2] & mask) >> child_bits);
}

/// Empties the bbox of the node at `addr` (min i32::MAX, max i32::MIN: ready for atomics).
WP_FN void vb_empty_box(u64 addr) {
  i32* b = (i32*)addr;
  b[0] = b[1] = b[2] = 2147483647;
  b[3] = b[4] = b[5] = -2147483647 - 1;
}

/// The link step at sorted position i.
WP_FN void vb_link_at(const vb_link_t& s, u64 i) {
  using namespace vb_detail;
  const i32* c = (const i32*)s.sorted + 3 * i;
  const u64 a = ((const u64*)s.scan_a)[i];
  const u64 b = ((const u64*)s.scan_b)[i];
  const u64 pa = i > 0 ? ((const u64*)s.scan_a)[i - 1] : 0;
  const u64 pb = i > 0 ? ((const u64*)s.scan_b)[i - 1] : 0;
  const u64 m32 = 0xffffffffu;
  const u64 uid = (a >> 32) - 1, lid = (a & m32) - 1, fid = (b >> 32) - 1;
  const u64 upper = s.grid + s.upper + uid * s.up_size;
  const u64 lower = s.grid + s.lower + lid * s.lo_size;
  const u64 leaf = s.grid + s.leaf + fid * s.leaf_size;
  if ((a >> 32) != (pa >> 32)) {
    // The root tile: the root key of any voxel of the upper is the upper's; the child offset
    // is from the RootData. State and value stay 0, as Warp leaves them.
    const u64 tile = s.grid + s.tiles + uid * s.tile_size;
    const u64 key = ((u64)((u32)c[2] >> 12)) | ((u64)((u32)c[1] >> 12) << 21) |
                    ((u64)((u32)c[0] >> 12) << 42);
    put<u64>(tile, key);
    put<i64>(tile + 8, (i64)(upper - (s.grid + s.root)));
    vb_empty_box(upper);
  }
  if ((a & m32) != (pa & m32)) {
    const u64 slot = vb_slot(c, 5, 7);
    or64(upper + vb_upper_child_mask + 8 * (slot >> 6), (u64)1 << (slot & 63));
    put<i64>(upper + s.up_table + slot * s.stride, (i64)(lower - upper));
    vb_empty_box(lower);
    ((u32*)s.lower_upper)[lid] = (u32)uid;
  }
  if ((b >> 32) != (pb >> 32)) {
    const u64 slot = vb_slot(c, 4, 3);
    or64(lower + vb_lower_child_mask + 8 * (slot >> 6), (u64)1 << (slot & 63));
    put<i64>(lower + s.lo_table + slot * s.stride, (i64)(leaf - lower));
    i32* o = (i32*)leaf;
    o[0] = c[0] & ~7;
    o[1] = c[1] & ~7;
    o[2] = c[2] & ~7;
    put<u32>(leaf + vb_leaf_bbox_dif, 2u << 24);
    if (s.kind == vb_kind_on_index) {
      put<u64>(leaf + s.leaf_table, b & m32);
    } else {
      for (u64 w = 0; w < 8; ++w) put<u64>(leaf + vb_leaf_value_mask + 8 * w, ~(u64)0);
      if (s.kind == vb_kind_index) put<u64>(leaf + s.leaf_table, fid * 512 + 1);
    }
    ((u32*)s.leaf_lower)[fid] = (u32)lid;
  }
  if (s.kind == vb_kind_on_index) {
    const u64 slot = vb_slot(c, 3, 0);
    or64(leaf + vb_leaf_value_mask + 8 * (slot >> 6), (u64)1 << (slot & 63));
  }
}

/// Atomic min/max of the box (6 i32) at `from` into the box at `into`.
WP_FN void vb_union_into(u64 into, const i32* from) {
  for (i32 k = 0; k < 3; ++k) {
    vb_detail::min32(into + 4 * k, from[k]);
    vb_detail::max32(into + 12 + 4 * k, from[3 + k]);
  }
}

/// The leaf box step at leaf f.
WP_FN void vb_leaf_box_at(const vb_leaf_box_t& s, u64 f) {
  using namespace vb_detail;
  const u64 leaf = s.grid + s.leaf + f * s.leaf_size;
  i32* bb = (i32*)leaf;
  const i32 o[3] = {bb[0], bb[1], bb[2]};
  u64 words[8];
  u64 any = 0;
  i32 x0 = -1, x1 = -1;
  for (i32 w = 0; w < 8; ++w) {
    words[w] = load_at<u64>(leaf + vb_leaf_value_mask + 8 * w);
    any |= words[w];
    if (words[w] != 0) {
      if (x0 < 0) x0 = w;
      x1 = w;
    }
  }
  // Every leaf has an active voxel by construction; an empty one keeps its origin.
  if (any == 0) return;
  // The mask word is x; bits 3..6 of a word are y, bits 0..3 z.
  const i32 y0 = ctz64(any) >> 3, y1 = (63 - clz64(any)) >> 3;
  u32 zs = 0;
  for (i32 y = 0; y < 8; ++y) zs |= (u32)(any >> (8 * y)) & 0xffu;
  const i32 z0 = ctz64((u64)zs), z1 = 63 - clz64((u64)zs);
  const i32 box[6] = {o[0] + x0, o[1] + y0, o[2] + z0, o[0] + x1, o[1] + y1, o[2] + z1};
  bb[0] = box[0];
  bb[1] = box[1];
  bb[2] = box[2];
  put<u32>(leaf + vb_leaf_bbox_dif,
           (u32)(x1 - x0) | ((u32)(y1 - y0) << 8) | ((u32)(z1 - z0) << 16) | (2u << 24));
  if (s.on_index) {
    u64 sum = 0, prefix = 0;
    for (i32 w = 0; w < 7; ++w) {
      sum += (u64)popc64(words[w]);
      prefix |= sum << (9 * w);
    }
    put<u64>(leaf + s.leaf_table + 8, prefix);
  }
  const u64 lid = ((const u32*)s.leaf_lower)[f];
  vb_union_into(s.grid + s.lower + lid * s.lo_size, box);
}

/// The node box step at child k.
WP_FN void vb_node_box_at(const vb_node_box_t& s, u64 k) {
  const i32* from = (const i32*)(s.grid + s.child + k * s.child_size);
  const u64 parent = s.parent_of ? (u64)((const u32*)s.parent_of)[k] : 0;
  vb_union_into(s.grid + s.parent + parent * s.parent_size, from);
}

/// The world bbox step (one thread).
WP_FN void vb_world(const vb_world_t& s) {
  using namespace vb_detail;
  const i32* b = (const i32*)(s.grid + s.root);
  f64 lo[3] = {1.7976931348623157e308, 1.7976931348623157e308, 1.7976931348623157e308};
  f64 hi[3] = {-1.7976931348623157e308, -1.7976931348623157e308, -1.7976931348623157e308};
  for (i32 corner = 0; corner < 8; ++corner) {
    f64 p[3];
    for (i32 c = 0; c < 3; ++c) p[c] = (f64)b[((corner >> c) & 1) * 3 + c];
    for (i32 r = 0; r < 3; ++r) {
      const f64* m = s.mat + 3 * r;
      const f64 q = dadd(dadd(dadd(dmul(m[0], p[0]), dmul(m[1], p[1])), dmul(m[2], p[2])), s.t[r]);
      if (q < lo[r]) lo[r] = q;
      if (q > hi[r]) hi[r] = q;
    }
  }
  f64* w = (f64*)(s.grid + vb_world_bbox);
  for (i32 c = 0; c < 3; ++c) {
    w[c] = lo[c];
    w[3 + c] = hi[c];
  }
}

}  // namespace wp

// The kernels (warp-runtime's objects/volume_build.rs runs them through the generic object-step
// launcher, which compiles this header with WP_VOLUME_BUILD defined once per GPU). Each takes one
// record, laid out as the Rust step's `#[repr(C)]` struct (both sides assert the size);
// grid-stride loops, consecutive threads on consecutive elements (coalesced reads of the
// per-point and per-entry arrays).
#if defined(__CUDACC__) && defined(WP_VOLUME_BUILD)
#define WP_VB_LOOP(i, n)                                                        \
  for (wp::u64 i = (wp::u64)blockIdx.x * blockDim.x + threadIdx.x; i < (n); \
       i += (wp::u64)blockDim.x * gridDim.x)

extern "C" __global__ void wp_vb_ijk(wp::vb_ijk_t s) {
  WP_VB_LOOP(i, s.n) {
    // Only a bad point reaches the atomic (off the hot path).
    if (!wp::vb_ijk_at(s, i)) atomicMin((wp::i32*)s.bad, (wp::i32)i);
  }
}
extern "C" __global__ void wp_vb_bounds(wp::vb_bounds_t s) {
  // Each thread's box, then its warp's (shuffles), then its block's (shared memory), then one
  // atomic per block and word: an atomic per point would serialise on the 6 words.
  __shared__ wp::i32 part[6][32];
  wp::i32 acc[6] = {2147483647, 2147483647, 2147483647, -2147483647 - 1, -2147483647 - 1,
                    -2147483647 - 1};
  WP_VB_LOOP(i, s.n) wp::vb_bounds_add(s, i, acc);
  for (int o = 16; o > 0; o >>= 1) {
    for (int k = 0; k < 6; ++k) {
      const wp::i32 v = __shfl_xor_sync(0xffffffffu, acc[k], o);
      acc[k] = k < 3 ? min(acc[k], v) : max(acc[k], v);
    }
  }
  const unsigned lane = threadIdx.x & 31u, warp = threadIdx.x >> 5;
  if (lane == 0)
    for (int k = 0; k < 6; ++k) part[k][warp] = acc[k];
  __syncthreads();
  if (threadIdx.x == 0) {
    const unsigned warps = (blockDim.x + 31u) >> 5;
    wp::i32* b = (wp::i32*)s.bounds;
    for (int k = 0; k < 6; ++k) {
      wp::i32 r = part[k][0];
      for (unsigned w = 1; w < warps; ++w) r = k < 3 ? min(r, part[k][w]) : max(r, part[k][w]);
      if (k < 3)
        atomicMin(&b[k], r);
      else
        atomicMax(&b[k], r);
    }
  }
}
extern "C" __global__ void wp_vb_keys(wp::vb_keys_t s) {
  WP_VB_LOOP(i, s.n) wp::vb_keys_at(s, i);
}
extern "C" __global__ void wp_vb_flags(wp::vb_flags_t s) {
  WP_VB_LOOP(i, s.n) wp::vb_flags_at(s, i);
}
extern "C" __global__ void wp_vb_totals(wp::vb_totals_t s) {
  if (blockIdx.x == 0 && threadIdx.x == 0) wp::vb_totals(s);
}
extern "C" __global__ void wp_vb_fill(wp::vb_fill_t s) {
  WP_VB_LOOP(e, s.count) wp::vb_fill_at(s, e);
}
extern "C" __global__ void wp_vb_link(wp::vb_link_t s) {
  WP_VB_LOOP(i, s.n) wp::vb_link_at(s, i);
}
extern "C" __global__ void wp_vb_leaf_box(wp::vb_leaf_box_t s) {
  WP_VB_LOOP(f, s.count) wp::vb_leaf_box_at(s, f);
}
extern "C" __global__ void wp_vb_node_box(wp::vb_node_box_t s) {
  WP_VB_LOOP(k, s.count) wp::vb_node_box_at(s, k);
}
extern "C" __global__ void wp_vb_world(wp::vb_world_t s) {
  if (blockIdx.x == 0 && threadIdx.x == 0) wp::vb_world(s);
}
#endif

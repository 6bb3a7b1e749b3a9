// wp_volume.h: section "volume" of the builtin table: NVIDIA Warp's sparse volumes (NanoVDB
// grids), the CUDA mirror of warp-core/src/objects/volume.rs. Read that module's docs for the
// definitions and the exact arithmetic (and docs/nanovdb.md sections 2, 4 and 5 for the
// format): every step below is the Rust one in the same order, so both backends read the
// same grid words, visit the same nodes and round the same way.
//
//   volume_t<T>                                   a Volume<T> kernel parameter (VolumeView<T>)
//   VoxelIndex                                    the element type of index grids (Index, OnIndex)
//   volume_sample(v, uvw, mode, ctx) -> T         T: f32 f64 Vec3 DVec3; mode 0 CLOSEST, else LINEAR
//   volume_sample_grad(v, uvw, mode, ctx) -> tuple_t<T, G>   G: Vec3 DVec3 Mat3 DMat3
//   volume_lookup(v, i, j, k, ctx) -> T           T: also i32
//   volume_store(v, i, j, k, value, ctx)          writes only into an allocated leaf
//   volume_index_to_world(v, uvw, ctx), volume_world_to_index, volume_index_to_world_dir,
//   volume_world_to_index_dir                     the f32 map copies; any T incl. VoxelIndex
//   volume_sample_index(v, uvw, mode, data, bg, ctx) -> T   any grid; data: array_t<T, 1>
//   volume_sample_grad_index(v, uvw, mode, data, bg, ctx) -> tuple_t<T, G>
//   volume_lookup_index(v, i, j, k, ctx) -> i32   the voxel's slot in a value array, or -1
//
// The adjoints are in wp_adjoint_volume.h.
//
// Faults: a NaN or infinite coordinate of a sample position (every sampling builtin, in both
// modes) raises FAULT_NON_FINITE with the three coordinates' f64 bit patterns; an index of
// the index variants past `data` is that array's OutOfBounds fault. Nothing else faults:
// every offset a lookup follows was proven in range on the host (warp-core's
// objects::nanovdb::validate) before the view was made, so lookups do no bounds checks, and
// the grid type always matches T (the runtime checks it), so there is no type test either. A
// finite coordinate outside the i32 index range reads the root background (voxel coordinates
// are computed in i64).
//
// Loads: the tree's structure (root keys, child offsets, masks, index-leaf offsets, the map)
// is never written by a kernel (volume_store writes leaf values only), so it is read through
// the read-only data cache (`__ldg`). Values may be written by volume_store in the same
// kernel, so they are read with plain loads, unless the translation unit defines
// WP_VOLUME_NO_STORE (for a kernel that calls no volume_store): then through `__ldg` as well.
// Host builds read and write with memcpy. Measured once (H100, nvcc -O3 -fmad=false, 1M
// LINEAR samples of a sphere SDF band in 256^3, 7942 leaves): 55 us for points spread over
// the box and 77 us near the surface, against 50 and 81 us for PNanoVDB's read-accessor
// sampler (Warp 1.19's), with bit-identical results; WP_VOLUME_NO_STORE changed nothing
// measurable there, and hoisting the i64 range tests out of the taps made it slower.
//
// Floating point: bit for bit the CPU's with no FMA contraction (NVRTC `--fmad=false`):
// floorf, roundf and the additions and multiplications below are exact or correctly rounded
// on both.
#pragma once
#include "wp_core.h"

namespace wp {

/// The element type of index grids (warp-core's `VoxelIndex`): a grid of this type holds
/// indices into a separate value array, not values; only the index variants and the
/// transforms take it.
struct VoxelIndex {};

/// Sampling modes (warp-core's CLOSEST / LINEAR; any mode other than CLOSEST samples
/// trilinearly).
enum { VOLUME_CLOSEST = 0, VOLUME_LINEAR = 1 };

/// A Volume<T> kernel parameter (104 bytes, align 8), field for field warp-core's
/// #[repr(C)] VolumeView<T>. Offsets are bytes from the grid's start (`data`).
///     0 data         address of grid byte 0 (32-byte aligned)
///     8 grad         address of the gradient twin (the grid's size, values at its offsets), 0 = none
///    16 size         grid bytes
///    24 first_leaf   leaf 0
///    32 name         CPU only (the kernel name for faults); unused here
///    40 grid_type    NanoVDB GridType code
///    44 root         RootData (root tiles' child offsets are relative to it)
///    48 tiles        root tile 0
///    52 tile_count
///    56 leaf_count
///    60 background   the root background value
///    64 tile_size    68 tile_value   72 stride (internal table entry)
///    76 upper_table  80 lower_table  84 leaf_table (index grids: mOffset, 80)
///    88 leaf_size    92 value_size (0 for index grids)   96 name_len (CPU only)   100 pad
template <typename T>
struct volume_t {
  u64 data;
  u64 grad;
  u64 size;
  u64 first_leaf;
  u64 name;
  u32 grid_type;
  u32 root;
  u32 tiles;
  u32 tile_count;
  u32 leaf_count;
  u32 background;
  u32 tile_size;
  u32 tile_value;
  u32 stride;
  u32 upper_table;
  u32 lower_table;
  u32 leaf_table;
  u32 leaf_size;
  u32 value_size;
  u32 name_len;
  u32 pad;
  /// Marks a kernel object for the adjoint library (zero value, no gradient).
  typedef void wp_object_tag;
};
static_assert(sizeof(volume_t<f32>) == 104 && alignof(volume_t<f32>) == 8, "volume_t layout");

namespace detail {

// ------------------------------------------------------------------------------------------
// Grid words
// ------------------------------------------------------------------------------------------

// Node-internal offsets, the same for every value type: child masks (upper, lower), the leaf
// value mask, an index leaf's mPrefixSum, the map in GridData.
enum : u32 {
  VOL_UPPER_CHILD_MASK = 4128u,
  VOL_LOWER_CHILD_MASK = 544u,
  VOL_LEAF_MASK = 16u,
  VOL_PREFIX_SUM = 88u,
  VOL_MAP = 296u,
};

#if defined(__CUDACC__)
/// Structure words (read-only for a whole launch).
WP_LFN u64 vol_u64(u64 a) { return (u64)__ldg((const unsigned long long*)a); }
WP_LFN f32 vol_map_f32(u64 a) { return __ldg((const float*)a); }
/// Values: plain loads unless no kernel store can change them during the launch.
#if defined(WP_VOLUME_NO_STORE)
template <typename S>
WP_FN S vol_val(u64 a) { return __ldg((const S*)a); }
#else
template <typename S>
WP_FN S vol_val(u64 a) { return *(const S*)a; }
#endif
template <typename S>
WP_FN void vol_put(u64 a, S x) { *(S*)a = x; }
#else
template <typename S>
WP_FN S vol_host_load(u64 a) {
  S x;
  std::memcpy(&x, (const void*)(uintptr_t)a, sizeof(S));
  return x;
}
WP_LFN u64 vol_u64(u64 a) { return vol_host_load<u64>(a); }
WP_LFN f32 vol_map_f32(u64 a) { return vol_host_load<f32>(a); }
template <typename S>
WP_FN S vol_val(u64 a) { return vol_host_load<S>(a); }
template <typename S>
WP_FN void vol_put(u64 a, S x) { std::memcpy((void*)(uintptr_t)a, &x, sizeof(S)); }
#endif

// ------------------------------------------------------------------------------------------
// Value types (warp-core's VolumeValue / VolumeSample)
// ------------------------------------------------------------------------------------------

/// `load` / `store` at an address (vectors component by component); for the float types the
/// scalar `S` of the arithmetic and the gradient type `G`.
template <typename T>
struct vol_value;

template <>
struct vol_value<f32> {
  typedef f32 S;
  typedef Vec3 G;
  WP_FN static f32 zero() { return 0.0f; }
  WP_FN static f32 load(u64 a) { return vol_val<f32>(a); }
  WP_FN static void store(u64 a, f32 x) { vol_put(a, x); }
};
template <>
struct vol_value<f64> {
  typedef f64 S;
  typedef DVec3 G;
  WP_FN static f64 zero() { return 0.0; }
  WP_FN static f64 load(u64 a) { return vol_val<f64>(a); }
  WP_FN static void store(u64 a, f64 x) { vol_put(a, x); }
};
template <>
struct vol_value<i32> {
  WP_FN static i32 zero() { return 0; }
  WP_FN static i32 load(u64 a) { return vol_val<i32>(a); }
  WP_FN static void store(u64 a, i32 x) { vol_put(a, x); }
};
template <>
struct vol_value<Vec3> {
  typedef f32 S;
  typedef Mat3 G;
  WP_FN static Vec3 zero() { return Vec3_ZERO(); }
  WP_FN static Vec3 load(u64 a) {
    return Vec3_new(vol_val<f32>(a), vol_val<f32>(a + 4), vol_val<f32>(a + 8));
  }
  WP_FN static void store(u64 a, Vec3 x) {
    vol_put(a, x.x);
    vol_put(a + 4, x.y);
    vol_put(a + 8, x.z);
  }
};
template <>
struct vol_value<DVec3> {
  typedef f64 S;
  typedef DMat3 G;
  WP_FN static DVec3 zero() { return DVec3_ZERO(); }
  WP_FN static DVec3 load(u64 a) {
    return DVec3_new(vol_val<f64>(a), vol_val<f64>(a + 8), vol_val<f64>(a + 16));
  }
  WP_FN static void store(u64 a, DVec3 x) {
    vol_put(a, x.x);
    vol_put(a + 8, x.y);
    vol_put(a + 16, x.z);
  }
};

// The elementary steps of the sampling formulas (VolumeSample's methods), in their order.

/// add_scaled: `acc + w * v`, componentwise.
WP_LFN f32 vol_add_scaled(f32 acc, f32 w, f32 v) { return acc + w * v; }
WP_LFN f64 vol_add_scaled(f64 acc, f64 w, f64 v) { return acc + w * v; }
WP_LFN Vec3 vol_add_scaled(Vec3 acc, f32 w, Vec3 v) {
  return Vec3_new(acc.x + w * v.x, acc.y + w * v.y, acc.z + w * v.z);
}
WP_LFN DVec3 vol_add_scaled(DVec3 acc, f64 w, DVec3 v) {
  return DVec3_new(acc.x + w * v.x, acc.y + w * v.y, acc.z + w * v.z);
}
/// scale: `w * a`, componentwise.
WP_LFN f32 vol_scale(f32 w, f32 a) { return w * a; }
WP_LFN f64 vol_scale(f64 w, f64 a) { return w * a; }
WP_LFN Vec3 vol_scale(f32 w, Vec3 a) { return Vec3_new(w * a.x, w * a.y, w * a.z); }
WP_LFN DVec3 vol_scale(f64 w, DVec3 a) { return DVec3_new(w * a.x, w * a.y, w * a.z); }
/// add: `a + b`, componentwise.
WP_LFN f32 vol_add(f32 a, f32 b) { return a + b; }
WP_LFN f64 vol_add(f64 a, f64 b) { return a + b; }
WP_LFN Vec3 vol_add(Vec3 a, Vec3 b) { return Vec3_new(a.x + b.x, a.y + b.y, a.z + b.z); }
WP_LFN DVec3 vol_add(DVec3 a, DVec3 b) { return DVec3_new(a.x + b.x, a.y + b.y, a.z + b.z); }
/// grad_zero.
WP_LFN void vol_grad_zero(Vec3& g) { g = Vec3_ZERO(); }
WP_LFN void vol_grad_zero(DVec3& g) { g = DVec3_ZERO(); }
WP_LFN void vol_grad_zero(Mat3& g) { g = Mat3{Vec3_ZERO(), Vec3_ZERO(), Vec3_ZERO()}; }
WP_LFN void vol_grad_zero(DMat3& g) { g = DMat3{DVec3_ZERO(), DVec3_ZERO(), DVec3_ZERO()}; }
/// grad_add_outer: `g + outer(v, gw)`, entry (component c, axis a) `g + v_c * gw_a`; column
/// a of a matrix is the derivative along axis a.
WP_LFN Vec3 vol_grad_add_outer(Vec3 g, f32 v, const f32* gw) {
  return Vec3_new(g.x + v * gw[0], g.y + v * gw[1], g.z + v * gw[2]);
}
WP_LFN DVec3 vol_grad_add_outer(DVec3 g, f64 v, const f64* gw) {
  return DVec3_new(g.x + v * gw[0], g.y + v * gw[1], g.z + v * gw[2]);
}
template <typename V, typename M, typename S>
WP_FN M vol_outer_cols(const M& g, const V& v, const S* gw) {
  M r;
  r.x_axis = vol_add_scaled(g.x_axis, gw[0], v);  // c.x + w * v.x == c.x + v.x * w
  r.y_axis = vol_add_scaled(g.y_axis, gw[1], v);
  r.z_axis = vol_add_scaled(g.z_axis, gw[2], v);
  return r;
}
WP_LFN Mat3 vol_grad_add_outer(const Mat3& g, Vec3 v, const f32* gw) {
  return vol_outer_cols(g, v, gw);
}
WP_LFN DMat3 vol_grad_add_outer(const DMat3& g, DVec3 v, const f64* gw) {
  return vol_outer_cols(g, v, gw);
}

// ------------------------------------------------------------------------------------------
// Coordinate to value (VolumeView::locate and its read accessor)
// ------------------------------------------------------------------------------------------

/// Where a voxel's value lives (VoxelAddress): the byte offset from the grid's start and the
/// level holding it (0 leaf, 1 lower table, 2 upper table, 3 root tile, 4 root background).
/// For index grids a level-0 offset is the leaf's mOffset field.
struct vol_addr_t {
  u64 offset;
  u32 level;
  u32 pad;
};
WP_LFN vol_addr_t vol_addr(u64 offset, u32 level) {
  vol_addr_t a;
  a.offset = offset;
  a.level = level;
  a.pad = 0;
  return a;
}

/// PNanoVDB's read accessor (Accessor): the nodes on the path to the last voxel looked up;
/// each non-zero node contains `key`.
struct vol_acc_t {
  i32 key[3];
  u64 leaf, lower, upper;
};
WP_LFN vol_acc_t vol_acc_new() {
  vol_acc_t a;
  a.key[0] = a.key[1] = a.key[2] = 2147483647;
  a.leaf = a.lower = a.upper = 0;
  return a;
}
WP_LFN void vol_acc_set_key(vol_acc_t& a, i32 i, i32 j, i32 k) {
  a.key[0] = i;
  a.key[1] = j;
  a.key[2] = k;
}

WP_LFN u64 vol_leaf_voxel(i32 i, i32 j, i32 k) {
  return (u64)(u32)(((i & 7) << 6) | ((j & 7) << 3) | (k & 7));
}
WP_LFN u64 vol_lower_slot(i32 i, i32 j, i32 k) {
  return (u64)(u32)((((i & 127) >> 3) << 8) | (((j & 127) >> 3) << 4) | ((k & 127) >> 3));
}
WP_LFN u64 vol_upper_slot(i32 i, i32 j, i32 k) {
  return (u64)(u32)((((i & 4095) >> 7) << 10) | (((j & 4095) >> 7) << 5) | ((k & 4095) >> 7));
}
/// The root table key (nanovdb::root_key): each coordinate as unsigned, shifted by 12.
WP_LFN u64 vol_root_key(i32 i, i32 j, i32 k) {
  return (u64)((u32)k >> 12) | ((u64)((u32)j >> 12) << 21) | ((u64)((u32)i >> 12) << 42);
}

template <typename T>
WP_FN bool vol_child_bit(const volume_t<T>& v, u64 mask, u64 n) {
  return ((vol_u64(v.data + mask + ((n >> 6) << 3)) >> (n & 63u)) & 1u) != 0;
}

template <typename T>
WP_FN vol_addr_t vol_in_leaf(const volume_t<T>& v, u64 leaf, i32 i, i32 j, i32 k) {
  return vol_addr(leaf + v.leaf_table + vol_leaf_voxel(i, j, k) * v.value_size, 0u);
}

template <typename T>
WP_FN vol_addr_t vol_in_lower(const volume_t<T>& v, u64 lower, i32 i, i32 j, i32 k,
                              vol_acc_t& acc) {
  const u64 n = vol_lower_slot(i, j, k);
  const u64 entry = lower + v.lower_table + n * v.stride;
  if (vol_child_bit(v, lower + VOL_LOWER_CHILD_MASK, n)) {
    const u64 leaf = lower + vol_u64(v.data + entry);
    acc.leaf = leaf;
    vol_acc_set_key(acc, i, j, k);
    return vol_in_leaf(v, leaf, i, j, k);
  }
  return vol_addr(entry, 1u);
}

template <typename T>
WP_FN vol_addr_t vol_in_upper(const volume_t<T>& v, u64 upper, i32 i, i32 j, i32 k,
                              vol_acc_t& acc) {
  const u64 n = vol_upper_slot(i, j, k);
  const u64 entry = upper + v.upper_table + n * v.stride;
  if (vol_child_bit(v, upper + VOL_UPPER_CHILD_MASK, n)) {
    const u64 lower = upper + vol_u64(v.data + entry);
    acc.lower = lower;
    vol_acc_set_key(acc, i, j, k);
    return vol_in_lower(v, lower, i, j, k, acc);
  }
  return vol_addr(entry, 2u);
}

/// The root: a linear scan of the tiles for the key (the grids hold few tiles; one 8-byte
/// load and compare per tile).
template <typename T>
WP_FN vol_addr_t vol_in_root(const volume_t<T>& v, i32 i, i32 j, i32 k, vol_acc_t& acc) {
  const u64 key = vol_root_key(i, j, k);
  u64 tile = v.tiles;
  for (u32 t = 0; t < v.tile_count; ++t, tile += v.tile_size) {
    if (vol_u64(v.data + tile) == key) {
      const u64 child = vol_u64(v.data + tile + 8);
      if (child == 0) return vol_addr(tile + v.tile_value, 3u);
      const u64 upper = (u64)v.root + child;
      acc.upper = upper;
      vol_acc_set_key(acc, i, j, k);
      return vol_in_upper(v, upper, i, j, k, acc);
    }
  }
  return vol_addr(v.background, 4u);
}

/// locate_cached: the cached leaf, lower or upper node when (i, j, k) falls in it (a node
/// that does not is dropped), else the root.
template <typename T>
WP_FN vol_addr_t vol_locate_cached(const volume_t<T>& v, i32 i, i32 j, i32 k, vol_acc_t& acc) {
  const i32 dirty = (i ^ acc.key[0]) | (j ^ acc.key[1]) | (k ^ acc.key[2]);
  if (acc.leaf != 0) {
    if ((dirty & ~7) == 0) return vol_in_leaf(v, acc.leaf, i, j, k);
    acc.leaf = 0;
  }
  if (acc.lower != 0) {
    if ((dirty & ~127) == 0) return vol_in_lower(v, acc.lower, i, j, k, acc);
    acc.lower = 0;
  }
  if (acc.upper != 0) {
    if ((dirty & ~4095) == 0) return vol_in_upper(v, acc.upper, i, j, k, acc);
    acc.upper = 0;
  }
  return vol_in_root(v, i, j, k, acc);
}

/// locate: without a cache.
template <typename T>
WP_FN vol_addr_t vol_locate(const volume_t<T>& v, i32 i, i32 j, i32 k) {
  vol_acc_t acc = vol_acc_new();
  return vol_locate_cached(v, i, j, k, acc);
}

WP_LFN bool vol_inside_i32(i64 x) { return x >= -2147483648ll && x <= 2147483647ll; }

/// locate_wide: a voxel coordinate in i64; outside the i32 range the root background.
template <typename T>
WP_FN vol_addr_t vol_locate_wide(const volume_t<T>& v, const i64* c, vol_acc_t& acc) {
  if (vol_inside_i32(c[0]) && vol_inside_i32(c[1]) && vol_inside_i32(c[2]))
    return vol_locate_cached(v, (i32)c[0], (i32)c[1], (i32)c[2], acc);
  return vol_addr(v.background, 4u);
}

/// The voxel coordinate clamped into i32 (what the Rust taps pass on; meaningful only where
/// the address is not the range rule's background).
WP_LFN i32 vol_clamp_i32(i64 x) {
  return x < -2147483648ll ? (i32)(-2147483647 - 1) : x > 2147483647ll ? 2147483647 : (i32)x;
}

WP_LFN u64 vol_popc(u64 x) {
#if defined(__CUDACC__)
  return (u64)__popcll(x);
#else
  return (u64)__builtin_popcountll(x);
#endif
}

/// voxel_index: Warp's value index of a lookup's result (0: none). Level 0 only; voxel n of
/// the leaf has, in an Index grid, mOffset + n; in an OnIndex grid 0 when inactive, else
/// mOffset + the active voxels before it; in a value grid leafId * 512 + n + 1.
template <typename T>
WP_FN u64 vol_voxel_index(const volume_t<T>& v, vol_addr_t at, i32 i, i32 j, i32 k) {
  if (at.level != 0) return 0;
  const u64 n = vol_leaf_voxel(i, j, k);
  if (v.grid_type == 19u) return vol_u64(v.data + at.offset) + n;
  if (v.grid_type == 20u) {
    const u64 leaf = at.offset - v.leaf_table;
    const u64 w = n >> 6, b = n & 63u;
    const u64 word = vol_u64(v.data + leaf + VOL_LEAF_MASK + 8u * w);
    if (((word >> b) & 1u) == 0) return 0;
    u64 sum = vol_popc(word & ((1ull << b) - 1u));
    if (w > 0) sum += (vol_u64(v.data + leaf + VOL_PREFIX_SUM) >> (9u * (w - 1u))) & 511u;
    return vol_u64(v.data + at.offset) + sum;
  }
  const u64 leaf = at.offset - v.leaf_table - n * v.value_size;
  const u64 id = (leaf - v.first_leaf) / v.leaf_size;
  return id * 512u + n + 1u;
}

// ------------------------------------------------------------------------------------------
// Sample positions and taps
// ------------------------------------------------------------------------------------------

/// check_position: false, and a NonFinite fault with the coordinates' f64 bit patterns,
/// unless every coordinate is finite.
WP_LFN bool vol_check_position(Vec3 uvw, ctx_t* ctx) {
  const f32 m = 3.40282347e38f;  // f32::MAX: NaN and the infinities fail the test
  if (::fabsf(uvw.x) <= m && ::fabsf(uvw.y) <= m && ::fabsf(uvw.z) <= m) return true;
  const i64 bits[3] = {(i64)f64_to_bits((f64)uvw.x), (i64)f64_to_bits((f64)uvw.y),
                       (i64)f64_to_bits((f64)uvw.z)};
  raise(ctx, FAULT_NON_FINITE, -1, 3, bits, nullptr);
  return false;
}

/// wide: an integral finite f32 as an i64 voxel coordinate, clamped to +-2^40 first (exact;
/// far outside the i32 range, so anything clamped is background).
WP_LFN i64 vol_wide(f32 c) {
  const f32 lim = 1099511627776.0f;
  return (i64)(c < -lim ? -lim : c > lim ? lim : c);
}

/// The LINEAR cell (cell): the base voxel and the per-axis weights [1 - f, f].
struct vol_cell_t {
  i64 base[3];
  f32 wx[2], wy[2], wz[2];
};
WP_LFN vol_cell_t vol_cell(Vec3 uvw) {
  vol_cell_t c;
  const f32 bx = ::floorf(uvw.x), by = ::floorf(uvw.y), bz = ::floorf(uvw.z);
  const f32 fx = uvw.x - bx, fy = uvw.y - by, fz = uvw.z - bz;
  c.wx[0] = 1.0f - fx;
  c.wx[1] = fx;
  c.wy[0] = 1.0f - fy;
  c.wy[1] = fy;
  c.wz[0] = 1.0f - fz;
  c.wz[1] = fz;
  c.base[0] = vol_wide(bx);
  c.base[1] = vol_wide(by);
  c.base[2] = vol_wide(bz);
  return c;
}

/// Corner `n` (0..8, o = (n>>2 & 1, n>>1 & 1, n & 1)) of a cell (Corner): the weight w, its
/// gradient gw and the weight Hessian's off-diagonal h = [hxy, hxz, hyz], all f32.
struct vol_corner_t {
  f32 w;
  f32 gw[3];
  f32 h[3];
};
WP_LFN vol_corner_t vol_corner(const vol_cell_t& c, int n) {
  const int ox = (n >> 2) & 1, oy = (n >> 1) & 1, oz = n & 1;
  const f32 sx = ox == 1 ? 1.0f : -1.0f, sy = oy == 1 ? 1.0f : -1.0f, sz = oz == 1 ? 1.0f : -1.0f;
  const f32 x = c.wx[ox], y = c.wy[oy], z = c.wz[oz];
  vol_corner_t r;
  r.w = (x * y) * z;
  r.gw[0] = (sx * y) * z;
  r.gw[1] = (sy * x) * z;
  r.gw[2] = (sz * x) * y;
  r.h[0] = (sx * sy) * z;
  r.h[1] = (sx * sz) * y;
  r.h[2] = (sy * sz) * x;
  return r;
}

/// Corner n's voxel (in i64) and address, through the shared accessor; `ijk` gets the
/// voxel clamped into i32.
template <typename G>
WP_FN vol_addr_t vol_tap(const volume_t<G>& v, const vol_cell_t& c, int n, vol_acc_t& acc,
                         i32* ijk) {
  const i64 p[3] = {c.base[0] + ((n >> 2) & 1), c.base[1] + ((n >> 1) & 1), c.base[2] + (n & 1)};
  const vol_addr_t at = vol_locate_wide(v, p, acc);
  ijk[0] = vol_clamp_i32(p[0]);
  ijk[1] = vol_clamp_i32(p[1]);
  ijk[2] = vol_clamp_i32(p[2]);
  return at;
}

/// closest_tap: the voxel of round(uvw) (halves away from zero) and its address.
template <typename G>
WP_FN vol_addr_t vol_closest_tap(const volume_t<G>& v, Vec3 uvw, i32* ijk) {
  const i64 p[3] = {vol_wide(::roundf(uvw.x)), vol_wide(::roundf(uvw.y)),
                    vol_wide(::roundf(uvw.z))};
  vol_acc_t acc = vol_acc_new();
  const vol_addr_t at = vol_locate_wide(v, p, acc);
  ijk[0] = vol_clamp_i32(p[0]);
  ijk[1] = vol_clamp_i32(p[1]);
  ijk[2] = vol_clamp_i32(p[2]);
  return at;
}

/// index_value: data[idx - 1] for a voxel with an index, else bg.
template <typename G, typename T>
WP_FN T vol_index_value(const volume_t<G>& v, vol_addr_t at, const i32* ijk,
                        const array_t<T, 1>& data, const T& bg, ctx_t* ctx) {
  const u64 idx = vol_voxel_index(v, at, ijk[0], ijk[1], ijk[2]);
  if (idx > 0) return load(data, (i64)(idx - 1u), ctx);
  return bg;
}

/// The value source of the plain builtins: the grid's own values.
template <typename T>
struct vol_grid_reader_t {
  const volume_t<T>* v;
  WP_FN T operator()(vol_addr_t at, const i32*, ctx_t*) const {
    return vol_value<T>::load(v->data + at.offset);
  }
};
/// The value source of the index variants.
template <typename G, typename T>
struct vol_index_reader_t {
  const volume_t<G>* v;
  const array_t<T, 1>* data;
  const T* bg;
  WP_FN T operator()(vol_addr_t at, const i32* ijk, ctx_t* ctx) const {
    return vol_index_value(*v, at, ijk, *data, *bg, ctx);
  }
};

/// linear: the LINEAR sum (and, WITH_GRAD, gradient) over the values `read` gives, corners
/// in order; stops at a fault (the results are then zero).
template <bool WITH_GRAD, typename G, typename T, typename R>
WP_FN T vol_linear(const volume_t<G>& v, Vec3 uvw, const R& read,
                   typename vol_value<T>::G* grad, ctx_t* ctx) {
  typedef typename vol_value<T>::S S;
  const vol_cell_t c = vol_cell(uvw);
  vol_acc_t acc = vol_acc_new();
  T val = vol_value<T>::zero();
  if constexpr (WITH_GRAD) vol_grad_zero(*grad);
#if defined(__CUDACC__)
#pragma unroll
#endif
  for (int n = 0; n < 8; ++n) {
    i32 ijk[3];
    const vol_addr_t at = vol_tap(v, c, n, acc, ijk);
    const T x = read(at, ijk, ctx);
    if (faulted(ctx)) {
      if constexpr (WITH_GRAD) vol_grad_zero(*grad);
      return vol_value<T>::zero();
    }
    const vol_corner_t k = vol_corner(c, n);
    val = vol_add_scaled(val, (S)k.w, x);
    if constexpr (WITH_GRAD) {
      const S gw[3] = {(S)k.gw[0], (S)k.gw[1], (S)k.gw[2]};
      *grad = vol_grad_add_outer(*grad, x, gw);
    }
  }
  return val;
}

}  // namespace detail

// ------------------------------------------------------------------------------------------
// Builtins
// ------------------------------------------------------------------------------------------

/// The grid sampled at index-space uvw: CLOSEST (mode 0) the voxel of round(uvw), any other
/// mode the trilinear blend of the 8 voxels around it.
template <typename T>
WP_FN T volume_sample(const volume_t<T>& v, Vec3 uvw, i32 mode, ctx_t* ctx) {
  using namespace detail;
  if (!vol_check_position(uvw, ctx)) return vol_value<T>::zero();
  const vol_grid_reader_t<T> read{&v};
  if (mode == VOLUME_CLOSEST) {
    i32 ijk[3];
    return read(vol_closest_tap(v, uvw, ijk), ijk, ctx);
  }
  return vol_linear<false, T, T>(v, uvw, read, (typename vol_value<T>::G*)nullptr, ctx);
}

/// The sample and its gradient with respect to uvw (index space; zero in CLOSEST mode).
template <typename T>
WP_FN tuple_t<T, typename detail::vol_value<T>::G> volume_sample_grad(const volume_t<T>& v,
                                                                      Vec3 uvw, i32 mode,
                                                                      ctx_t* ctx) {
  using namespace detail;
  tuple_t<T, typename vol_value<T>::G> r;
  r.f0 = vol_value<T>::zero();
  vol_grad_zero(r.f1);
  if (!vol_check_position(uvw, ctx)) return r;
  const vol_grid_reader_t<T> read{&v};
  if (mode == VOLUME_CLOSEST) {
    i32 ijk[3];
    r.f0 = read(vol_closest_tap(v, uvw, ijk), ijk, ctx);
    return r;
  }
  r.f0 = vol_linear<true, T, T>(v, uvw, read, &r.f1, ctx);
  return r;
}

/// The value of voxel (i, j, k) as stored (leaf, tile or background value alike).
template <typename T>
WP_FN T volume_lookup(const volume_t<T>& v, i32 i, i32 j, i32 k, ctx_t* ctx) {
  (void)ctx;
  return detail::vol_value<T>::load(v.data + detail::vol_locate(v, i, j, k).offset);
}

/// Writes `value` at voxel (i, j, k) when it lies in a leaf (active or not); a silent no-op
/// elsewhere (tiles and the background are never written).
template <typename T>
WP_FN void volume_store(const volume_t<T>& v, i32 i, i32 j, i32 k,
                        const typename identity<T>::type& value, ctx_t* ctx) {
  (void)ctx;
  const detail::vol_addr_t at = detail::vol_locate(v, i, j, k);
  if (at.level == 0) detail::vol_value<T>::store(v.data + at.offset, value);
}

namespace detail {
/// The grid's f32 map: matF (row-major) at 0, invMatF at 36, vecF at 72 of the Map.
enum : u32 { VOL_MAT_F = 0u, VOL_INV_MAT_F = 36u, VOL_VEC_F = 72u };
WP_LFN f32 vol_map_at(u64 data, u32 m, int k) { return vol_map_f32(data + VOL_MAP + m + 4u * (u32)k); }
/// linear_map: row r of M times p, `(p.x*M[r][0] + p.y*M[r][1]) + p.z*M[r][2]`.
WP_LFN Vec3 vol_linear_map(u64 data, u32 m, Vec3 p) {
  f32 r[3];
  for (int row = 0; row < 3; ++row)
    r[row] = (p.x * vol_map_at(data, m, 3 * row) + p.y * vol_map_at(data, m, 3 * row + 1)) +
             p.z * vol_map_at(data, m, 3 * row + 2);
  return Vec3_new(r[0], r[1], r[2]);
}
/// transposed: column c of M times a, `(a.x*M[0][c] + a.y*M[1][c]) + a.z*M[2][c]`.
WP_LFN Vec3 vol_transposed(u64 data, u32 m, Vec3 a) {
  f32 r[3];
  for (int col = 0; col < 3; ++col)
    r[col] = (a.x * vol_map_at(data, m, col) + a.y * vol_map_at(data, m, 3 + col)) +
             a.z * vol_map_at(data, m, 6 + col);
  return Vec3_new(r[0], r[1], r[2]);
}
WP_LFN Vec3 vol_map_t(u64 data) {
  return Vec3_new(vol_map_at(data, VOL_VEC_F, 0), vol_map_at(data, VOL_VEC_F, 1),
                  vol_map_at(data, VOL_VEC_F, 2));
}
}  // namespace detail

/// `M uvw + t` with the grid's f32 map.
template <typename G>
WP_FN Vec3 volume_index_to_world(const volume_t<G>& v, Vec3 uvw, ctx_t* ctx) {
  (void)ctx;
  const Vec3 m = detail::vol_linear_map(v.data, detail::VOL_MAT_F, uvw), t = detail::vol_map_t(v.data);
  return Vec3_new(m.x + t.x, m.y + t.y, m.z + t.z);
}
/// `M^-1 (xyz - t)` with the grid's f32 map.
template <typename G>
WP_FN Vec3 volume_world_to_index(const volume_t<G>& v, Vec3 xyz, ctx_t* ctx) {
  (void)ctx;
  const Vec3 t = detail::vol_map_t(v.data);
  return detail::vol_linear_map(v.data, detail::VOL_INV_MAT_F,
                                Vec3_new(xyz.x - t.x, xyz.y - t.y, xyz.z - t.z));
}
/// `M uvw`.
template <typename G>
WP_FN Vec3 volume_index_to_world_dir(const volume_t<G>& v, Vec3 uvw, ctx_t* ctx) {
  (void)ctx;
  return detail::vol_linear_map(v.data, detail::VOL_MAT_F, uvw);
}
/// `M^-1 xyz`.
template <typename G>
WP_FN Vec3 volume_world_to_index_dir(const volume_t<G>& v, Vec3 xyz, ctx_t* ctx) {
  (void)ctx;
  return detail::vol_linear_map(v.data, detail::VOL_INV_MAT_F, xyz);
}

/// volume_sample with the values taken from `data` by voxel index (data[idx - 1], `bg` where
/// the voxel has none), on any grid (index and value grids alike).
template <typename G, typename T>
WP_FN T volume_sample_index(const volume_t<G>& v, Vec3 uvw, i32 mode, const array_t<T, 1>& data,
                            const typename identity<T>::type& bg, ctx_t* ctx) {
  using namespace detail;
  if (!vol_check_position(uvw, ctx)) return vol_value<T>::zero();
  const vol_index_reader_t<G, T> read{&v, &data, &bg};
  if (mode == VOLUME_CLOSEST) {
    i32 ijk[3];
    return read(vol_closest_tap(v, uvw, ijk), ijk, ctx);
  }
  return vol_linear<false, G, T>(v, uvw, read, (typename vol_value<T>::G*)nullptr, ctx);
}

/// volume_sample_grad with the values of volume_sample_index.
template <typename G, typename T>
WP_FN tuple_t<T, typename detail::vol_value<T>::G> volume_sample_grad_index(
    const volume_t<G>& v, Vec3 uvw, i32 mode, const array_t<T, 1>& data,
    const typename identity<T>::type& bg, ctx_t* ctx) {
  using namespace detail;
  tuple_t<T, typename vol_value<T>::G> r;
  r.f0 = vol_value<T>::zero();
  vol_grad_zero(r.f1);
  if (!vol_check_position(uvw, ctx)) return r;
  const vol_index_reader_t<G, T> read{&v, &data, &bg};
  if (mode == VOLUME_CLOSEST) {
    i32 ijk[3];
    r.f0 = read(vol_closest_tap(v, uvw, ijk), ijk, ctx);
    return r;
  }
  r.f0 = vol_linear<true, G, T>(v, uvw, read, &r.f1, ctx);
  return r;
}

/// The voxel's index into a value array (idx - 1), or -1 where it has none (not in a leaf;
/// an inactive voxel of an OnIndex grid).
template <typename G>
WP_FN i32 volume_lookup_index(const volume_t<G>& v, i32 i, i32 j, i32 k, ctx_t* ctx) {
  (void)ctx;
  const detail::vol_addr_t at = detail::vol_locate(v, i, j, k);
  return (i32)((u32)detail::vol_voxel_index(v, at, i, j, k) - 1u);
}

}  // namespace wp

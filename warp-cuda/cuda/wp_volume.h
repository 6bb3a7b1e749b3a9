// wp_volume.h: section "volume" of the builtin table: NVIDIA Warp's sparse volumes (NanoVDB
// grids), the CUDA mirror of warp-core/src/objects/volume.rs (read that, and docs/nanovdb.md
// sections 2, 4 and 5, for the definitions). Every step below is the Rust one in the same
// order, so both backends read the same grid words and round the same way.
//
//   volume_t<T>                                   a Volume<T> kernel parameter (VolumeView<T>)
//   VoxelIndex                                    the value type of index grids (Index, OnIndex)
//   volume_sample(v, uvw, mode, ctx) -> T          T: f32 f64 Vec3 DVec3; mode 0 CLOSEST, else LINEAR
//   volume_sample_grad(v, uvw, mode, ctx) -> tuple_t<T, G>   G: Vec3 DVec3 Mat3 DMat3
//   volume_lookup(v, i, j, k, ctx) -> T            T: also i32
//   volume_store(v, i, j, k, value, ctx)           writes only into an allocated leaf
//   volume_index_to_world(v, uvw, ctx), volume_world_to_index, volume_index_to_world_dir,
//   volume_world_to_index_dir                      the f32 Map copies; any T incl. VoxelIndex
//   volume_sample_index(v, uvw, mode, data, bg, ctx) -> T   any grid; data: array_t<T, 1>
//   volume_sample_grad_index(v, uvw, mode, data, bg, ctx) -> tuple_t<T, G>
//   volume_lookup_index(v, i, j, k, ctx) -> i32    the value index (idx - 1), or -1
//
// The adjoints are in wp_adjoint_volume.h.
//
// Faults: a NaN or infinite coordinate of a sample position (every sample, in both modes)
// raises FAULT_NON_FINITE with the coordinates' f64 bit patterns; a data index of the index
// variants outside `data` is the array's OutOfBounds fault. Nothing else faults: every offset
// a lookup follows was proven in range when the grid was validated on the host (warp-core
// objects::nanovdb::validate), so lookups do no bounds checks. A finite coordinate outside
// the i32 index range reads the root background (corners are computed in i64).
//
// A sample of the wrong grid type returns zero and a store into one does nothing (Warp).
//
// Loads: the tree's structure (root keys, child offsets, masks, index offsets) is never
// written by a kernel, so it is read through the read-only data cache (`__ldg`). Values may be
// written by `volume_store` in the same kernel, so they are read with plain loads unless the
// translation unit defines WP_VOLUME_NO_STORE (the code generator does for kernels that call
// no volume_store: then values go through `__ldg` too). Host builds read with memcpy (the
// grid buffer may not be aligned on the host).
//
// Floating point: as warp-core, with no FMA contraction (NVRTC `--fmad=false`).
//
// Kernel-argument layout: see volume_t below (warp-core's #[repr(C)] VolumeView<T>).
#pragma once
#include "wp_core.h"

namespace wp {

/// The value type of index grids (warp-core's `VoxelIndex`): a grid of this type has no
/// values of its own, only indices into an external array; only the index variants and the
/// transforms take it.
struct VoxelIndex {};

/// Sampling modes (warp-core's VOLUME_CLOSEST / VOLUME_LINEAR; any mode other than CLOSEST
/// samples trilinearly).
enum { VOLUME_CLOSEST = 0, VOLUME_LINEAR = 1 };

/// A Volume<T> kernel parameter, field for field warp-core's #[repr(C)] VolumeView<T>.
/// Offsets are bytes from the grid's start (`data`).
template <typename T>
struct volume_t {
  u64 data;        // address of grid byte 0 (32-byte aligned)
  u64 grad;        // the gradient grid (same layout, values zeroed), 0 = none
  u64 size;        // grid bytes
  u64 first_leaf;  // leaf 0
  u32 grid_type;   // NanoVDB GridType code
  u32 root;        // RootData
  u32 tile_count;  // root table size
  u32 leaf_count;
  // The per-type layout (warp-core objects::nanovdb::Layout).
  u32 value_size;
  u32 root_size;
  u32 background;
  u32 tile_size;
  u32 tile_value;
  u32 stride;
  u32 up_table;
  u32 up_size;
  u32 lo_table;
  u32 lo_size;
  u32 leaf_table;
  u32 leaf_size;
  /// Marks a kernel object for the adjoint library (zero value, no gradient).
  typedef void wp_object_tag;
};
static_assert(sizeof(volume_t<f32>) == 96 && alignof(volume_t<f32>) == 8, "volume_t layout");

// ------------------------------------------------------------------------------------------
// Value types
// ------------------------------------------------------------------------------------------

namespace detail {

/// Loads of grid words at byte address `a`. Structure words (`vol_ld_*`) always go through
/// the read-only cache on the device; values (`vol_val_*`) only under WP_VOLUME_NO_STORE.
#if defined(__CUDACC__)
WP_FN u32 vol_ld_u32(u64 a) { return __ldg((const unsigned int*)a); }
WP_FN u64 vol_ld_u64(u64 a) { return (u64)__ldg((const unsigned long long*)a); }
#if defined(WP_VOLUME_NO_STORE)
WP_FN f32 vol_val_f32(u64 a) { return __ldg((const float*)a); }
WP_FN f64 vol_val_f64(u64 a) { return __ldg((const double*)a); }
WP_FN i32 vol_val_i32(u64 a) { return __ldg((const int*)a); }
#else
WP_FN f32 vol_val_f32(u64 a) { return *(const float*)a; }
WP_FN f64 vol_val_f64(u64 a) { return *(const double*)a; }
WP_FN i32 vol_val_i32(u64 a) { return *(const int*)a; }
#endif
#else
template <typename X>
WP_FN X vol_ld_host(u64 a) {
  X x;
  std::memcpy(&x, (const void*)(uintptr_t)a, sizeof(X));
  return x;
}
WP_FN u32 vol_ld_u32(u64 a) { return vol_ld_host<u32>(a); }
WP_FN u64 vol_ld_u64(u64 a) { return vol_ld_host<u64>(a); }
WP_FN f32 vol_val_f32(u64 a) { return vol_ld_host<f32>(a); }
WP_FN f64 vol_val_f64(u64 a) { return vol_ld_host<f64>(a); }
WP_FN i32 vol_val_i32(u64 a) { return vol_ld_host<i32>(a); }
#endif

/// Stores of values (volume_store), plain stores.
template <typename X>
WP_FN void vol_st(u64 a, X x) {
#if defined(__CUDACC__)
  *(X*)a = x;
#else
  std::memcpy((void*)(uintptr_t)a, &x, sizeof(X));
#endif
}

/// The value types of grids (warp-core's VolumeValue): their grid types, how a value is read
/// and written at an address, the scalar of the trilinear weights and the gradient type.
template <typename T>
struct vol_value;

template <>
struct vol_value<f32> {
  typedef f32 scalar;
  typedef Vec3 grad;
  static constexpr bool is_float = true;
  WP_FN static bool has_type(u32 t) { return t == 1u; }
  WP_FN static f32 read(u64 a) { return vol_val_f32(a); }
  WP_FN static void write(u64 a, f32 x) { vol_st(a, x); }
  WP_FN static f32 zero() { return 0.0f; }
};
template <>
struct vol_value<f64> {
  typedef f64 scalar;
  typedef DVec3 grad;
  static constexpr bool is_float = true;
  WP_FN static bool has_type(u32 t) { return t == 2u; }
  WP_FN static f64 read(u64 a) { return vol_val_f64(a); }
  WP_FN static void write(u64 a, f64 x) { vol_st(a, x); }
  WP_FN static f64 zero() { return 0.0; }
};
template <>
struct vol_value<i32> {
  static constexpr bool is_float = false;
  WP_FN static bool has_type(u32 t) { return t == 4u; }
  WP_FN static i32 read(u64 a) { return vol_val_i32(a); }
  WP_FN static void write(u64 a, i32 x) { vol_st(a, x); }
  WP_FN static i32 zero() { return 0; }
};
template <>
struct vol_value<Vec3> {
  typedef f32 scalar;
  typedef Mat3 grad;
  static constexpr bool is_float = true;
  WP_FN static bool has_type(u32 t) { return t == 6u; }
  WP_FN static Vec3 read(u64 a) {
    return Vec3_new(vol_val_f32(a), vol_val_f32(a + 4), vol_val_f32(a + 8));
  }
  WP_FN static void write(u64 a, Vec3 x) {
    vol_st(a, x.x);
    vol_st(a + 4, x.y);
    vol_st(a + 8, x.z);
  }
  WP_FN static Vec3 zero() { return Vec3_ZERO(); }
};
template <>
struct vol_value<DVec3> {
  typedef f64 scalar;
  typedef DMat3 grad;
  static constexpr bool is_float = true;
  WP_FN static bool has_type(u32 t) { return t == 7u; }
  WP_FN static DVec3 read(u64 a) {
    return DVec3_new(vol_val_f64(a), vol_val_f64(a + 8), vol_val_f64(a + 16));
  }
  WP_FN static void write(u64 a, DVec3 x) {
    vol_st(a, x.x);
    vol_st(a + 8, x.y);
    vol_st(a + 16, x.z);
  }
  WP_FN static DVec3 zero() { return DVec3_ZERO(); }
};
template <>
struct vol_value<VoxelIndex> {
  static constexpr bool is_float = false;
  WP_FN static bool has_type(u32 t) { return t == 19u || t == 20u; }
};

// ------------------------------------------------------------------------------------------
// Coordinate to value (docs/nanovdb.md section 4)
// ------------------------------------------------------------------------------------------

/// Where a lookup ended: `level` 0 (leaf), 1 (lower table), 2 (upper table), 3 (root tile),
/// 4 (root background); `node` the byte offset of that leaf or node (level 3: the tile; level
/// 4: the root), `n` the entry in its table (level 0: the voxel 0..512).
struct vol_hit_t {
  u64 node;
  u32 n;
  u32 level;
};

/// The byte offset of the value a hit names.
template <typename T>
WP_FN u64 vol_value_offset(const volume_t<T>& v, const vol_hit_t& h) {
  switch (h.level) {
    case 0: return h.node + v.leaf_table + (u64)h.n * v.value_size;
    case 1: return h.node + v.lo_table + (u64)h.n * v.stride;
    case 2: return h.node + v.up_table + (u64)h.n * v.stride;
    case 3: return h.node + v.tile_value;
    default: return h.node + v.background;
  }
}

WP_FN u64 vol_root_key(i32 i, i32 j, i32 k) {
  return (u64)((u32)k >> 12) | ((u64)((u32)j >> 12) << 21) | ((u64)((u32)i >> 12) << 42);
}
/// Mask bit n of the 64-bit little-endian words at byte offset `mask`.
WP_FN bool vol_bit(u64 data, u64 mask, u32 n) {
  return ((vol_ld_u64(data + mask + (u64)(n >> 6) * 8u) >> (n & 63u)) & 1u) != 0;
}
WP_FN u32 vol_upper_n(i32 i, i32 j, i32 k) {
  return ((((u32)i & 4095u) >> 7) << 10) | ((((u32)j & 4095u) >> 7) << 5) | (((u32)k & 4095u) >> 7);
}
WP_FN u32 vol_lower_n(i32 i, i32 j, i32 k) {
  return ((((u32)i & 127u) >> 3) << 8) | ((((u32)j & 127u) >> 3) << 4) | (((u32)k & 127u) >> 3);
}
WP_FN u32 vol_leaf_n(i32 i, i32 j, i32 k) {
  return (((u32)i & 7u) << 6) | (((u32)j & 7u) << 3) | ((u32)k & 7u);
}

// NanoVDB child masks: upper at 4128, lower at 544 (the value masks at 32).
enum : u32 { VOL_UPPER_CHILD_MASK = 4128u, VOL_LOWER_CHILD_MASK = 544u };

/// The walk from a lower node down (level 1 or 0).
template <typename T>
WP_FN vol_hit_t vol_from_lower(const volume_t<T>& v, u64 lower, i32 i, i32 j, i32 k) {
  const u32 n = vol_lower_n(i, j, k);
  if (!vol_bit(v.data, lower + VOL_LOWER_CHILD_MASK, n)) return vol_hit_t{lower, n, 1u};
  const u64 leaf = lower + vol_ld_u64(v.data + lower + v.lo_table + (u64)n * v.stride);
  return vol_hit_t{leaf, vol_leaf_n(i, j, k), 0u};
}

/// The walk from an upper node down (level 2, 1 or 0).
template <typename T>
WP_FN vol_hit_t vol_from_upper(const volume_t<T>& v, u64 upper, i32 i, i32 j, i32 k) {
  const u32 n = vol_upper_n(i, j, k);
  if (!vol_bit(v.data, upper + VOL_UPPER_CHILD_MASK, n)) return vol_hit_t{upper, n, 2u};
  const u64 lower = upper + vol_ld_u64(v.data + upper + v.up_table + (u64)n * v.stride);
  return vol_from_lower(v, lower, i, j, k);
}

/// The root tile holding (i, j, k), or 0 (the tiles start after RootData, so 0 is never one).
template <typename T>
WP_FN u64 vol_find_tile(const volume_t<T>& v, i32 i, i32 j, i32 k) {
  const u64 key = vol_root_key(i, j, k);
  u64 tile = (u64)v.root + v.root_size;
  for (u32 t = 0; t < v.tile_count; ++t, tile += v.tile_size)
    if (vol_ld_u64(v.data + tile) == key) return tile;
  return 0;
}

/// Section 4 without a cache.
template <typename T>
WP_FN vol_hit_t vol_lookup(const volume_t<T>& v, i32 i, i32 j, i32 k) {
  const u64 tile = vol_find_tile(v, i, j, k);
  if (tile == 0) return vol_hit_t{(u64)v.root, 0u, 4u};
  const i64 child = (i64)vol_ld_u64(v.data + tile + 8);
  if (child == 0) return vol_hit_t{tile, 0u, 3u};
  return vol_from_upper(v, (u64)v.root + (u64)child, i, j, k);
}

/// PNanoVDB's read accessor (docs/nanovdb.md section 4): the coordinate of the last descent
/// and the leaf, lower and upper node on its path (0: none). A descent into a node caches it
/// with the coordinate and clears the levels below it, so every cached node contains `key`:
/// the same hits as vol_lookup, with fewer reads for nearby coordinates (the 8 taps of a
/// LINEAR sample).
struct vol_acc_t {
  i32 ki, kj, kk;
  u64 leaf, lower, upper;
};

WP_FN vol_acc_t vol_acc_new() {
  vol_acc_t a;
  a.ki = a.kj = a.kk = 2147483647;
  a.leaf = a.lower = a.upper = 0;
  return a;
}

WP_FN void vol_acc_key(vol_acc_t& a, i32 i, i32 j, i32 k) {
  a.ki = i;
  a.kj = j;
  a.kk = k;
}

template <typename T>
WP_FN vol_hit_t vol_lower_cached(const volume_t<T>& v, vol_acc_t& a, u64 lower, i32 i, i32 j,
                                 i32 k) {
  const u32 n = vol_lower_n(i, j, k);
  if (!vol_bit(v.data, lower + VOL_LOWER_CHILD_MASK, n)) return vol_hit_t{lower, n, 1u};
  const u64 leaf = lower + vol_ld_u64(v.data + lower + v.lo_table + (u64)n * v.stride);
  a.leaf = leaf;
  vol_acc_key(a, i, j, k);
  return vol_hit_t{leaf, vol_leaf_n(i, j, k), 0u};
}

template <typename T>
WP_FN vol_hit_t vol_upper_cached(const volume_t<T>& v, vol_acc_t& a, u64 upper, i32 i, i32 j,
                                 i32 k) {
  const u32 n = vol_upper_n(i, j, k);
  if (!vol_bit(v.data, upper + VOL_UPPER_CHILD_MASK, n)) return vol_hit_t{upper, n, 2u};
  const u64 lower = upper + vol_ld_u64(v.data + upper + v.up_table + (u64)n * v.stride);
  a.lower = lower;
  a.leaf = 0;
  vol_acc_key(a, i, j, k);
  return vol_lower_cached(v, a, lower, i, j, k);
}

template <typename T>
WP_FN vol_hit_t vol_lookup_cached(const volume_t<T>& v, vol_acc_t& a, i32 i, i32 j, i32 k) {
  const u32 dirty = (u32)((i ^ a.ki) | (j ^ a.kj) | (k ^ a.kk));
  if (a.leaf != 0 && (dirty & ~7u) == 0) return vol_hit_t{a.leaf, vol_leaf_n(i, j, k), 0u};
  if (a.lower != 0 && (dirty & ~127u) == 0) return vol_lower_cached(v, a, a.lower, i, j, k);
  if (a.upper != 0 && (dirty & ~4095u) == 0) return vol_upper_cached(v, a, a.upper, i, j, k);
  const u64 tile = vol_find_tile(v, i, j, k);
  if (tile == 0) return vol_hit_t{(u64)v.root, 0u, 4u};
  const i64 child = (i64)vol_ld_u64(v.data + tile + 8);
  if (child == 0) return vol_hit_t{tile, 0u, 3u};
  const u64 upper = (u64)v.root + (u64)child;
  a.upper = upper;
  a.lower = 0;
  a.leaf = 0;
  vol_acc_key(a, i, j, k);
  return vol_upper_cached(v, a, upper, i, j, k);
}

// ------------------------------------------------------------------------------------------
// Sample positions
// ------------------------------------------------------------------------------------------

/// False, and a NonFinite fault with the coordinates' f64 bit patterns, unless every
/// coordinate of `uvw` is finite.
WP_FN bool vol_finite(Vec3 uvw, ctx_t* ctx) {
  const f32 lim = 3.40282347e38f;
  if (::fabsf(uvw.x) <= lim && ::fabsf(uvw.y) <= lim && ::fabsf(uvw.z) <= lim) return true;
  const i64 bits[3] = {(i64)f64_to_bits((f64)uvw.x), (i64)f64_to_bits((f64)uvw.y),
                       (i64)f64_to_bits((f64)uvw.z)};
  raise(ctx, FAULT_NON_FINITE, -1, 3, bits, nullptr);
  return false;
}

/// An integer-valued finite f32 as i64, saturated just outside the i32 range (so that it and
/// its +1 neighbour both stay outside): what a coordinate beyond the index range reads is the
/// root background.
WP_FN i64 vol_coord(f32 r) {
  if (r < -2147483648.0f) return -2147483650ll;
  if (r >= 2147483648.0f) return 2147483648ll;
  return (i64)r;
}
WP_FN bool vol_in_i32(i64 c) { return c >= -2147483648ll && c <= 2147483647ll; }

/// The hit of coordinate (i, j, k) in i64: the root background outside the i32 range.
template <typename T>
WP_FN vol_hit_t vol_lookup64(const volume_t<T>& v, i64 i, i64 j, i64 k) {
  if (!(vol_in_i32(i) && vol_in_i32(j) && vol_in_i32(k))) return vol_hit_t{(u64)v.root, 0u, 4u};
  return vol_lookup(v, (i32)i, (i32)j, (i32)k);
}
template <typename T>
WP_FN vol_hit_t vol_lookup64_cached(const volume_t<T>& v, vol_acc_t& a, i64 i, i64 j, i64 k) {
  if (!(vol_in_i32(i) && vol_in_i32(j) && vol_in_i32(k))) return vol_hit_t{(u64)v.root, 0u, 4u};
  return vol_lookup_cached(v, a, (i32)i, (i32)j, (i32)k);
}

/// CLOSEST: the voxel of round(uvw) (halves away from zero).
template <typename T>
WP_FN vol_hit_t vol_closest(const volume_t<T>& v, Vec3 uvw) {
  return vol_lookup64(v, vol_coord(::roundf(uvw.x)), vol_coord(::roundf(uvw.y)),
                      vol_coord(::roundf(uvw.z)));
}

/// The LINEAR stencil: base corner, fractions, and per corner c (bit 2: +x, bit 1: +y, bit 0:
/// +z, the order (0,0,0), (0,0,1), (0,1,0), ..., (1,1,1)) its weight and the weight's
/// gradient.
struct vol_stencil_t {
  i64 bi, bj, bk;
  f32 wx[2], wy[2], wz[2];
};

WP_FN vol_stencil_t vol_stencil(Vec3 uvw) {
  vol_stencil_t s;
  const f32 fx = ::floorf(uvw.x), fy = ::floorf(uvw.y), fz = ::floorf(uvw.z);
  s.bi = vol_coord(fx);
  s.bj = vol_coord(fy);
  s.bk = vol_coord(fz);
  const f32 ux = uvw.x - fx, uy = uvw.y - fy, uz = uvw.z - fz;
  s.wx[0] = 1.0f - ux;
  s.wx[1] = ux;
  s.wy[0] = 1.0f - uy;
  s.wy[1] = uy;
  s.wz[0] = 1.0f - uz;
  s.wz[1] = uz;
  return s;
}
/// Corner c's weight wx * wy * wz.
WP_FN f32 vol_w(const vol_stencil_t& s, int c) {
  return s.wx[(c >> 2) & 1] * s.wy[(c >> 1) & 1] * s.wz[c & 1];
}
/// Corner c's weight gradient (s_x wy wz, s_y wx wz, s_z wx wy), s = -1 or +1 by side.
WP_FN Vec3 vol_dw(const vol_stencil_t& s, int c) {
  const int ox = (c >> 2) & 1, oy = (c >> 1) & 1, oz = c & 1;
  const f32 sx = ox ? 1.0f : -1.0f, sy = oy ? 1.0f : -1.0f, sz = oz ? 1.0f : -1.0f;
  return Vec3_new(sx * s.wy[oy] * s.wz[oz], sy * s.wx[ox] * s.wz[oz], sz * s.wx[ox] * s.wy[oy]);
}
template <typename T>
WP_FN vol_hit_t vol_corner(const volume_t<T>& v, vol_acc_t& a, const vol_stencil_t& s, int c) {
  return vol_lookup64_cached(v, a, s.bi + ((c >> 2) & 1), s.bj + ((c >> 1) & 1), s.bk + (c & 1));
}

// ------------------------------------------------------------------------------------------
// Trilinear arithmetic per value type
// ------------------------------------------------------------------------------------------

/// `w * x` with the weight in the value's scalar type.
WP_FN f32 vol_scale(f32 w, f32 x) { return w * x; }
WP_FN f64 vol_scale(f32 w, f64 x) { return (f64)w * x; }
WP_FN Vec3 vol_scale(f32 w, Vec3 x) { return Vec3_new(w * x.x, w * x.y, w * x.z); }
WP_FN DVec3 vol_scale(f32 w, DVec3 x) {
  const f64 d = (f64)w;
  return DVec3_new(d * x.x, d * x.y, d * x.z);
}
/// `grad += x (outer) dw`: column a (d/du_a) gains x * dw_a.
WP_FN void vol_outer_acc(Vec3& g, f32 x, Vec3 dw) {
  g.x = g.x + x * dw.x;
  g.y = g.y + x * dw.y;
  g.z = g.z + x * dw.z;
}
WP_FN void vol_outer_acc(DVec3& g, f64 x, Vec3 dw) {
  g.x = g.x + x * (f64)dw.x;
  g.y = g.y + x * (f64)dw.y;
  g.z = g.z + x * (f64)dw.z;
}
WP_FN void vol_outer_acc(Mat3& g, Vec3 x, Vec3 dw) {
  g.x_axis = g.x_axis + vol_scale(dw.x, x);
  g.y_axis = g.y_axis + vol_scale(dw.y, x);
  g.z_axis = g.z_axis + vol_scale(dw.z, x);
}
WP_FN void vol_outer_acc(DMat3& g, DVec3 x, Vec3 dw) {
  g.x_axis = g.x_axis + vol_scale(dw.x, x);
  g.y_axis = g.y_axis + vol_scale(dw.y, x);
  g.z_axis = g.z_axis + vol_scale(dw.z, x);
}
template <typename G>
WP_FN G vol_zero_grad();
template <>
WP_FN Vec3 vol_zero_grad<Vec3>() { return Vec3_ZERO(); }
template <>
WP_FN DVec3 vol_zero_grad<DVec3>() { return DVec3_ZERO(); }
template <>
WP_FN Mat3 vol_zero_grad<Mat3>() { return Mat3{Vec3_ZERO(), Vec3_ZERO(), Vec3_ZERO()}; }
template <>
WP_FN DMat3 vol_zero_grad<DMat3>() { return DMat3{DVec3_ZERO(), DVec3_ZERO(), DVec3_ZERO()}; }

// ------------------------------------------------------------------------------------------
// Index variants: the value index of a level-0 hit (docs/nanovdb.md sections 2 and 5)
// ------------------------------------------------------------------------------------------

WP_FN u32 vol_popc(u64 x) {
#if defined(__CUDACC__)
  return (u32)__popcll(x);
#else
  return (u32)__builtin_popcountll(x);
#endif
}

/// Warp's value index of voxel n of leaf `leaf` (0: none, the background): Index grids
/// mOffset + n; OnIndex grids 0 for an inactive voxel, else mOffset + the active voxels
/// before n; value grids leafId * 512 + n + 1.
template <typename T>
WP_FN u64 vol_voxel_index(const volume_t<T>& v, u64 leaf, u32 n) {
  if (v.grid_type == 19u) return vol_ld_u64(v.data + leaf + 80) + n;
  if (v.grid_type == 20u) {
    const u32 w = n >> 6, b = n & 63u;
    const u64 word = vol_ld_u64(v.data + leaf + 16 + (u64)w * 8u);
    if (((word >> b) & 1u) == 0) return 0;
    u64 idx = vol_ld_u64(v.data + leaf + 80) + vol_popc(word & ((1ull << b) - 1u));
    if (w > 0) idx += (vol_ld_u64(v.data + leaf + 88) >> (9u * (w - 1u))) & 511u;
    return idx;
  }
  return ((leaf - v.first_leaf) / v.leaf_size) * 512u + n + 1u;
}

/// The value of an index-variant read: data[idx - 1] for a level-0 hit with idx > 0, else bg
/// (an index past the data is the array's OutOfBounds fault).
template <typename G, typename T>
WP_FN T vol_index_value(const volume_t<G>& v, const vol_hit_t& h, const array_t<T, 1>& data,
                        const T& bg, ctx_t* ctx) {
  if (h.level == 0) {
    const u64 idx = vol_voxel_index(v, h.node, h.n);
    if (idx > 0) return load(data, (i64)(idx - 1u), ctx);
  }
  return bg;
}

}  // namespace detail

// ------------------------------------------------------------------------------------------
// Builtins
// ------------------------------------------------------------------------------------------

/// The value at uvw (index space): CLOSEST the voxel of round(uvw), else the trilinear blend
/// of the 8 corners of floor(uvw). Zero for a grid of another type.
template <typename T>
WP_FN T volume_sample(const volume_t<T>& v, Vec3 uvw, i32 mode, ctx_t* ctx) {
  using namespace detail;
  typedef vol_value<T> V;
  static_assert(V::is_float, "volume_sample: float value types only");
  if (!vol_finite(uvw, ctx)) return V::zero();
  if (!V::has_type(v.grid_type)) return V::zero();
  if (mode == VOLUME_CLOSEST) return V::read(v.data + vol_value_offset(v, vol_closest(v, uvw)));
  const vol_stencil_t s = vol_stencil(uvw);
  vol_acc_t a = vol_acc_new();
  T val = V::zero();
  for (int c = 0; c < 8; ++c) {
    const T x = V::read(v.data + vol_value_offset(v, vol_corner(v, a, s, c)));
    val = val + vol_scale(vol_w(s, c), x);
  }
  return val;
}

/// The value and its index-space gradient at uvw (CLOSEST: the gradient is zero).
template <typename T>
WP_FN tuple_t<T, typename detail::vol_value<T>::grad> volume_sample_grad(const volume_t<T>& v,
                                                                         Vec3 uvw, i32 mode,
                                                                         ctx_t* ctx) {
  using namespace detail;
  typedef vol_value<T> V;
  typedef typename V::grad G;
  G grad = vol_zero_grad<G>();
  if (!vol_finite(uvw, ctx)) return {V::zero(), grad};
  if (!V::has_type(v.grid_type)) return {V::zero(), grad};
  if (mode == VOLUME_CLOSEST)
    return {V::read(v.data + vol_value_offset(v, vol_closest(v, uvw))), grad};
  const vol_stencil_t s = vol_stencil(uvw);
  vol_acc_t a = vol_acc_new();
  T val = V::zero();
  for (int c = 0; c < 8; ++c) {
    const T x = V::read(v.data + vol_value_offset(v, vol_corner(v, a, s, c)));
    val = val + vol_scale(vol_w(s, c), x);
    vol_outer_acc(grad, x, vol_dw(s, c));
  }
  return {val, grad};
}

/// The value stored for voxel (i, j, k) (section 4: leaf, tile or background value).
template <typename T>
WP_FN T volume_lookup(const volume_t<T>& v, i32 i, i32 j, i32 k, ctx_t* ctx) {
  using namespace detail;
  (void)ctx;
  typedef vol_value<T> V;
  if (!V::has_type(v.grid_type)) return V::zero();
  return V::read(v.data + vol_value_offset(v, vol_lookup(v, i, j, k)));
}

/// Writes voxel (i, j, k) when it lies in an allocated leaf (active or not); otherwise, and
/// for a grid of another type, does nothing.
template <typename T>
WP_FN void volume_store(const volume_t<T>& v, i32 i, i32 j, i32 k,
                        const typename identity<T>::type& value, ctx_t* ctx) {
  using namespace detail;
  (void)ctx;
  typedef vol_value<T> V;
  if (!V::has_type(v.grid_type)) return;
  const vol_hit_t h = vol_lookup(v, i, j, k);
  if (h.level == 0) V::write(v.data + vol_value_offset(v, h), value);
}

namespace detail {
/// Row r of the f32 3x3 at byte `m` of the Map (row-major) times p.
WP_FN Vec3 vol_map_mul(u64 data, u32 m, Vec3 p) {
  f32 r[3];
  for (int row = 0; row < 3; ++row) {
    const u64 a = data + 296u + m + (u64)row * 12u;
    r[row] = (f32_from_bits(vol_ld_u32(a)) * p.x + f32_from_bits(vol_ld_u32(a + 4)) * p.y) +
             f32_from_bits(vol_ld_u32(a + 8)) * p.z;
  }
  return Vec3_new(r[0], r[1], r[2]);
}
WP_FN Vec3 vol_map_vec(u64 data) {
  const u64 a = data + 296u + 72u;
  return Vec3_new(f32_from_bits(vol_ld_u32(a)), f32_from_bits(vol_ld_u32(a + 4)),
                  f32_from_bits(vol_ld_u32(a + 8)));
}
// Map offsets: matF 0, invMatF 36, vecF 72.
enum : u32 { VOL_MAT_F = 0u, VOL_INV_MAT_F = 36u };
}  // namespace detail

/// matF * uvw + vecF.
template <typename T>
WP_FN Vec3 volume_index_to_world(const volume_t<T>& v, Vec3 uvw, ctx_t* ctx) {
  (void)ctx;
  return detail::vol_map_mul(v.data, detail::VOL_MAT_F, uvw) + detail::vol_map_vec(v.data);
}
/// invMatF * (xyz - vecF).
template <typename T>
WP_FN Vec3 volume_world_to_index(const volume_t<T>& v, Vec3 xyz, ctx_t* ctx) {
  (void)ctx;
  return detail::vol_map_mul(v.data, detail::VOL_INV_MAT_F, xyz - detail::vol_map_vec(v.data));
}
/// matF * d.
template <typename T>
WP_FN Vec3 volume_index_to_world_dir(const volume_t<T>& v, Vec3 d, ctx_t* ctx) {
  (void)ctx;
  return detail::vol_map_mul(v.data, detail::VOL_MAT_F, d);
}
/// invMatF * d.
template <typename T>
WP_FN Vec3 volume_world_to_index_dir(const volume_t<T>& v, Vec3 d, ctx_t* ctx) {
  (void)ctx;
  return detail::vol_map_mul(v.data, detail::VOL_INV_MAT_F, d);
}

/// Index variant of volume_sample over any grid: voxel values come from data[idx - 1], every
/// other read (no voxel index, a tile, the background) is `bg`.
template <typename G, typename T>
WP_FN T volume_sample_index(const volume_t<G>& v, Vec3 uvw, i32 mode, const array_t<T, 1>& data,
                            const typename identity<T>::type& bg, ctx_t* ctx) {
  using namespace detail;
  typedef vol_value<T> V;
  static_assert(V::is_float, "volume_sample_index: float value types only");
  if (!vol_finite(uvw, ctx)) return V::zero();
  if (mode == VOLUME_CLOSEST) return vol_index_value(v, vol_closest(v, uvw), data, bg, ctx);
  const vol_stencil_t s = vol_stencil(uvw);
  vol_acc_t a = vol_acc_new();
  T val = V::zero();
  for (int c = 0; c < 8; ++c) {
    const T x = vol_index_value(v, vol_corner(v, a, s, c), data, bg, ctx);
    if (faulted(ctx)) return V::zero();
    val = val + vol_scale(vol_w(s, c), x);
  }
  return val;
}

/// Index variant of volume_sample_grad.
template <typename G, typename T>
WP_FN tuple_t<T, typename detail::vol_value<T>::grad> volume_sample_grad_index(
    const volume_t<G>& v, Vec3 uvw, i32 mode, const array_t<T, 1>& data,
    const typename identity<T>::type& bg, ctx_t* ctx) {
  using namespace detail;
  typedef vol_value<T> V;
  typedef typename V::grad GT;
  GT grad = vol_zero_grad<GT>();
  if (!vol_finite(uvw, ctx)) return {V::zero(), grad};
  if (mode == VOLUME_CLOSEST) return {vol_index_value(v, vol_closest(v, uvw), data, bg, ctx), grad};
  const vol_stencil_t s = vol_stencil(uvw);
  vol_acc_t a = vol_acc_new();
  T val = V::zero();
  for (int c = 0; c < 8; ++c) {
    const T x = vol_index_value(v, vol_corner(v, a, s, c), data, bg, ctx);
    if (faulted(ctx)) return {V::zero(), vol_zero_grad<GT>()};
    val = val + vol_scale(vol_w(s, c), x);
    vol_outer_acc(grad, x, vol_dw(s, c));
  }
  return {val, grad};
}

/// The value index of voxel (i, j, k) minus one (its slot in a value array), or -1.
template <typename G>
WP_FN i32 volume_lookup_index(const volume_t<G>& v, i32 i, i32 j, i32 k, ctx_t* ctx) {
  using namespace detail;
  (void)ctx;
  const vol_hit_t h = vol_lookup(v, i, j, k);
  if (h.level != 0) return -1;
  const u64 idx = vol_voxel_index(v, h.node, h.n);
  return (i32)idx - 1;
}

}  // namespace wp

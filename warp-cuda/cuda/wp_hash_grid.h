// wp_hash_grid.h: section "hash_grid" of the builtin table: NVIDIA Warp's hash grid, the CUDA
// mirror of warp-core/src/objects/hash_grid.rs (read that for the definitions: cells are
// floor(x / h) as i32, wrapped into dim_x x dim_y x dim_z buckets by the Euclidean remainder;
// a query visits the buckets of the cells overlapping p +- r, x fastest, at most dim cells per
// axis). Every step below is the Rust one in the same order, so both backends visit the same
// candidates in the same order.
//
//   hash_grid_t                     a HashGrid kernel parameter (warp_runtime's CudaHashGrid)
//   hash_grid_query_t               a query's state (warp_core's HashGridQuery)
//   hash_grid_query(g, p, r, ctx)   the state before the first candidate
//   hash_grid_query_next(g, q, ctx) the state at the next candidate, or at the end
//   hash_grid_query_done(q)         whether the query ended
//   hash_grid_query_point(q)        the current candidate (usize)
//   hash_grid_point_id(g, i, ctx)   the i-th point in bucket order (usize), any integer i
//   hash_grid_build_key, hash_grid_build_range   the per-thread steps of a device build (and,
//                                   with WP_HASH_GRID_BUILD, its kernels)
//
// Kernels never mutate a query through these functions: the macro lowers
// `for j in hash_grid_query(g, p, r) { .. }` into `q = next(g, q)` written back each
// iteration (see warp-macros/src/front/lower/query.rs).
//
// Every point read is a checked `load` reporting the grid's parameter: a bad point_id index
// is an out-of-bounds fault, and so is a point id that is not a point index (negative, or
// num_points or more: the fault's index is the id); bucket indices are below the bucket count by construction, and a
// query ends after at most dim_x * dim_y * dim_z buckets whatever the buffers hold (after a fault the thread goes on with zero values, as everywhere on the
// GPU, and still ends).
#pragma once
#include "wp_core.h"

namespace wp {

/// A built hash grid (48 bytes, align 8), field for field warp_runtime's `CudaHashGrid`:
///   0 point_ids (the point indices in bucket order), 8 cell_starts, 16 cell_ends (one per
///   bucket), 24 dims[3], 36 num_points, 40 cell_width_inv, 44 arg (the parameter's index,
///   for faults).
struct hash_grid_t {
  const i32* point_ids;
  const i32* cell_starts;
  const i32* cell_ends;
  i32 dims[3];
  i32 num_points;
  f32 cell_width_inv;
  i32 arg;
  /// Marks a kernel object for the adjoint library (zero value, no gradient).
  typedef void wp_object_tag;
};
static_assert(sizeof(hash_grid_t) == 48 && alignof(hash_grid_t) == 8, "hash_grid_t layout");

/// A query's state (48 bytes, warp_core's HashGridQuery): the box's first cell per axis
/// (wrapped into [0, dim)) and its size per axis (all 0 for an empty query), the current cell's
/// offsets in the box (x fastest; at[0] = -1 before the first cell; done once at[2] reaches
/// span[2]), the range left in the current bucket, and the current candidate (-1 before the
/// first and at the end). Counters, not a cell index: no division per cell.
struct hash_grid_query_t {
  i32 lo[3];
  i32 span[3];
  i32 at[3];
  i32 next;
  i32 end;
  i32 point;
  typedef void wp_object_tag;
};
static_assert(sizeof(hash_grid_query_t) == 48, "hash_grid_query_t layout");

namespace detail {
/// floor(x * inv) as i32, Rust's `as` (saturating, NaN to 0).
WP_LFN i32 hash_grid_cell(f32 x, f32 inv) { return cast<i32>(::floorf(x * inv)); }
/// The Euclidean remainder of c by d > 0, without dividing when c is in [0, d) already (a
/// 64-bit remainder is a long software sequence on a GPU).
WP_LFN i32 hash_grid_wrap(i64 c, i32 d) {
  if ((u64)c < (u64)d) return (i32)c;
  i64 r = c % (i64)d;
  if (r < 0) r += (i64)d;
  return (i32)r;
}
/// A checked view of one of the grid's buffers, reporting the grid's parameter.
WP_LFN array_t<i32, 1> hash_grid_buffer(const i32* p, i64 n, i32 arg) {
  array_t<i32, 1> a;
  a.data = const_cast<i32*>(p);
  a.shape[0] = n;
  a.strides[0] = (i64)sizeof(i32);
  a.arg = arg;
  a.pad = 0;
  return a;
}
}  // namespace detail

/// The bucket of cell (x, y, z): each wrapped into [0, dim), then (z * dim_y + y) * dim_x + x.
WP_LFN i32 hash_grid_bucket(const i32* dims, i64 x, i64 y, i64 z) {
  const i32 bx = detail::hash_grid_wrap(x, dims[0]);
  const i32 by = detail::hash_grid_wrap(y, dims[1]);
  const i32 bz = detail::hash_grid_wrap(z, dims[2]);
  return (bz * dims[1] + by) * dims[0] + bx;
}

/// The bucket of point p (what a build sorts by).
WP_LFN i32 hash_grid_point_bucket(const i32* dims, f32 inv, Vec3 p) {
  return hash_grid_bucket(dims, (i64)detail::hash_grid_cell(p.x, inv),
                          (i64)detail::hash_grid_cell(p.y, inv),
                          (i64)detail::hash_grid_cell(p.z, inv));
}

WP_LFN hash_grid_query_t hash_grid_query(const hash_grid_t& grid, Vec3 p, f32 radius, ctx_t* ctx) {
  (void)ctx;
  hash_grid_query_t q{};
  q.at[0] = -1;
  q.point = -1;
  // A negative or NaN radius: no cell (span 0 on every axis).
  if (radius >= 0.0f) {
    const f32 xs[3] = {p.x, p.y, p.z};
    for (int a = 0; a < 3; ++a) {
      const i32 lo = detail::hash_grid_cell(xs[a] - radius, grid.cell_width_inv);
      const i32 hi = detail::hash_grid_cell(xs[a] + radius, grid.cell_width_inv);
      i64 span = (i64)hi - (i64)lo + 1;
      if (span < 1) span = 1;
      if (span > (i64)grid.dims[a]) span = (i64)grid.dims[a];
      q.lo[a] = detail::hash_grid_wrap((i64)lo, grid.dims[a]);
      q.span[a] = (i32)span;
    }
  }
  return q;
}

namespace detail {
/// The bucket of the query's current cell: first cell plus offset, each below the dim, so one
/// subtraction wraps their sum (as u32, which holds twice any i32).
WP_LFN i32 hash_grid_query_bucket(const i32* dims, const hash_grid_query_t& q) {
  i32 c[3];
  for (int a = 0; a < 3; ++a) {
    const u32 s = (u32)q.lo[a] + (u32)q.at[a];
    c[a] = (i32)(s >= (u32)dims[a] ? s - (u32)dims[a] : s);
  }
  return (c[2] * dims[1] + c[1]) * dims[0] + c[0];
}
}  // namespace detail

WP_LFN hash_grid_query_t hash_grid_query_next(const hash_grid_t& grid, hash_grid_query_t q,
                                             ctx_t* ctx) {
  const array_t<i32, 1> ids =
      detail::hash_grid_buffer(grid.point_ids, (i64)grid.num_points, grid.arg);
  for (;;) {
    if (q.next < q.end) {
      // A checked read (a corrupt start below 0 faults here), which measured faster than a
      // plain read behind a check at the bucket's entry (0.83 against 0.96 ms for the
      // cell-order count of 1M points on an H100), unlike on the CPU.
      const i32 id = load(ids, (i64)q.next, ctx);
      q.next += 1;
      // Every candidate is a point index (hash_grid_item_bound): a corrupt id is the
      // out-of-bounds fault of the grid's points at that index, and ends the query. So a
      // kernel's accesses at the loop variable need no check of their own once the array
      // holds num_points elements (the forward emitter's unswitched query loop).
      if ((u32)id >= (u32)grid.num_points) {
        ctx->raised = 1;
        raise_out_of_bounds_1d(ctx->rec, grid.arg, (i64)id, (i64)grid.num_points);
        q.at[2] = q.span[2];
        q.next = 0;
        q.end = 0;
        q.point = -1;
        return q;
      }
      q.point = id;
      return q;
    }
    // The next cell of the box, x fastest (an empty box has span[2] == 0: done at once).
    if (q.at[2] < q.span[2]) {
      q.at[0] += 1;
      if (q.at[0] >= q.span[0]) {
        q.at[0] = 0;
        q.at[1] += 1;
        if (q.at[1] >= q.span[1]) {
          q.at[1] = 0;
          q.at[2] += 1;
        }
      }
    }
    if (q.at[2] >= q.span[2]) {
      q.next = 0;
      q.end = 0;
      q.point = -1;
      return q;
    }
    // Every bucket index is below the bucket count, which both range buffers hold (the runtime
    // allocates them so): no check needed.
    const i32 b = detail::hash_grid_query_bucket(grid.dims, q);
    q.next = grid.cell_starts[b];
    const i32 e = grid.cell_ends[b];
    // Bounded by the point count, whatever the buffer holds: a query never runs longer than
    // its buckets' points, and reads no point outside them.
    q.end = e < grid.num_points ? e : grid.num_points;
  }
}

WP_LFN bool hash_grid_query_done(hash_grid_query_t q) { return q.point < 0; }

WP_LFN usize hash_grid_query_point(hash_grid_query_t q) { return (usize)(i64)q.point; }

/// Every candidate a query yields is below this (hash_grid_query_next checks each).
WP_LFN i64 hash_grid_item_bound(const hash_grid_t& grid) { return (i64)grid.num_points; }

template <typename I>
WP_FN usize hash_grid_point_id(const hash_grid_t& grid, I i, ctx_t* ctx) {
  const array_t<i32, 1> ids =
      detail::hash_grid_buffer(grid.point_ids, (i64)grid.num_points, grid.arg);
  return (usize)(i64)load(ids, (i64)i, ctx);
}

// ------------------------------------------------------------------------------------------
// The device build: one thread per point computes its bucket (the key) with its index (the
// value); a stable sort of the pairs by key gives the point indices in bucket order; one thread
// per sorted position then marks where its bucket's range starts and ends (starts and ends
// zeroed first, so empty buckets have start == end). The same result as warp-runtime's CPU
// build, which sorts (bucket, index) pairs.
// ------------------------------------------------------------------------------------------

/// Point i's bucket and index, and whether the point is finite (a build refuses NaN and
/// infinite points: the caller records the first such index).
WP_LFN bool hash_grid_build_key(const i32* dims, f32 inv, Vec3 p, i32 i, i32* key, i32* value) {
  *key = hash_grid_point_bucket(dims, inv, p);
  *value = i;
  return p.x - p.x == 0.0f && p.y - p.y == 0.0f && p.z - p.z == 0.0f;
}

/// Sorted position k of n (keys sorted): the range of bucket keys[k] starts here if k is the
/// first of its bucket, and ends after it if k is the last; with `clear`, the same entries are
/// zeroed instead (undoing a build from its keys). Keys are buckets by construction; one
/// outside [0, buckets) is skipped, never written.
WP_LFN void hash_grid_build_range(const i32* sorted_keys, i32 n, i32 k, i32* starts, i32* ends,
                                 i32 buckets, bool clear) {
  const i32 b = sorted_keys[k];
  if (b < 0 || b >= buckets) return;
  if (k == 0 || sorted_keys[k - 1] != b) starts[b] = clear ? 0 : k;
  if (k == n - 1 || sorted_keys[k + 1] != b) ends[b] = clear ? 0 : k + 1;
}

}  // namespace wp

// The device build's kernels (warp-runtime's objects/hash_grid_steps.rs runs them through the
// generic object-step launcher, which compiles this header with WP_HASH_GRID_BUILD defined once
// per GPU; kernels that only query a grid do not get them). Each takes one record, laid out as
// the Rust step's `#[repr(C)]` struct (both sides assert the size). Grid-stride loops, one
// element per thread; no index can be out of range (by construction: n points, keys in
// [0, buckets)); the one fault is a recorded build's report of a non-finite point.
#if defined(WP_HASH_GRID_BUILD)
namespace wp {
/// HashGridKeys: points (Vec3*), n, dims, inv, keys (i32*), values (i32*), bad (i32*).
struct hash_grid_keys_t {
  u64 points;
  u64 n;
  i32 dims[3];
  f32 inv;
  u64 keys;
  u64 values;
  u64 bad;
};
static_assert(sizeof(hash_grid_keys_t) == 56, "hash_grid_keys_t layout");
/// HashGridRanges: keys (sorted i32*), starts, ends (i32*, buckets each), n, buckets, clear;
/// bad (the keys step's i32*, or 0): reset to INT_MAX, and the point of `points` (Vec3*) it
/// names reported as a fault (argument 0) with the `fault` context (a build reads nothing
/// back; 0 in the clearing step).
struct hash_grid_ranges_t {
  u64 keys;
  u64 starts;
  u64 ends;
  i32 n;
  i32 buckets;
  i32 clear;
  i32 pad;
  u64 bad;
  u64 points;
  step_fault_t fault;
};
static_assert(sizeof(hash_grid_ranges_t) == 96, "hash_grid_ranges_t layout");
}  // namespace wp
#endif

#if defined(__CUDACC__) && defined(WP_HASH_GRID_BUILD)
/// Points' buckets and indices; the smallest index of a non-finite point into *bad.
extern "C" __global__ void wp_hash_grid_keys(wp::hash_grid_keys_t s) {
  const wp::Vec3* points = (const wp::Vec3*)s.points;
  wp::i32* keys = (wp::i32*)s.keys;
  wp::i32* values = (wp::i32*)s.values;
  const wp::i64 stride = (wp::i64)blockDim.x * gridDim.x;
  for (wp::i64 i = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x; i < (wp::i64)s.n;
       i += stride) {
    if (!wp::hash_grid_build_key(s.dims, s.inv, points[i], (wp::i32)i, &keys[i], &values[i]))
      atomicMin((wp::i32*)s.bad, (wp::i32)i);
  }
}
/// Bucket ranges from the sorted keys (starts and ends zeroed before), or with `clear` != 0
/// their zeroing; with `bad`, the keys step's report (by one thread: the word was written by
/// an earlier launch).
extern "C" __global__ void wp_hash_grid_ranges(wp::hash_grid_ranges_t s) {
  const wp::i64 stride = (wp::i64)blockDim.x * gridDim.x;
  for (wp::i64 k = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x; k < s.n; k += stride)
    wp::hash_grid_build_range((const wp::i32*)s.keys, s.n, (wp::i32)k, (wp::i32*)s.starts,
                              (wp::i32*)s.ends, s.buckets, s.clear != 0);
  if (s.bad != 0 && blockIdx.x == 0 && threadIdx.x == 0) {
    const wp::i32 i = atomicExch((wp::i32*)s.bad, 0x7fffffff);
    if (i != 0x7fffffff) {
      const wp::Vec3 p = ((const wp::Vec3*)s.points)[i];
      const wp::i64 index[4] = {(wp::i64)i, (wp::i64)wp::f64_to_bits((wp::f64)p.x),
                                (wp::i64)wp::f64_to_bits((wp::f64)p.y),
                                (wp::i64)wp::f64_to_bits((wp::f64)p.z)};
      wp::ctx_t ctx = wp::ctx_make(&s.fault.ctx);
      wp::raise(&ctx, wp::FAULT_NON_FINITE_INPUT, 0, 4, index, nullptr);
    }
  }
}
#endif

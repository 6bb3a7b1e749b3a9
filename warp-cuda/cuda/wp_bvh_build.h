// wp_bvh_build.h: the GPU build of a BVH (a linear BVH over Morton codes, Karras 2012) and its
// refit, as the build steps of warp-runtime's objects/lbvh.rs, which runs the same steps on
// the CPU with rayon: both produce the same tree, bit for bit (the steps below are exact or
// written as the Rust ones are).
//
// The tree is in the layout of warp-core/src/objects/bvh.rs (read its module docs): nodes of
// 32 bytes {lower xyz, left, upper xyz, right}, the root at node 0, a leaf `left = ~start`
// holding prim_ids[start, right), an internal node's children by index, `parents` the links:
// each node's parent (-1 at the root), then each node's escape (the node a left-first
// traversal visits after its subtree, -1 for none). For n >= 2 primitives: internal node k is node k (k < n - 1, so the root is
// internal node 0), the leaf of sorted primitive k is node n - 1 + k with one primitive; for
// n = 1 the root is that leaf (node 0). The runtime writes the empty tree (n = 0) itself.
//
// Steps (one kernel each, grid-stride over the count in the record):
//   wp_lbvh_bounds     the centroids' bounding box, by atomic min/max of order-preserving u32
//                      images of the coordinates (exact, so any order gives the same box)
//   wp_lbvh_morton     each primitive's 30-bit Morton code (10 bits per axis of its centroid in
//                      that box) and its index: the pairs the primitives' stable radix sort
//                      orders (equal codes stay in index order)
//   wp_lbvh_hierarchy  Karras's construction over the sorted codes, with the index breaking
//                      ties (so duplicate codes still give a binary tree): every internal
//                      node's children and their parent links, every node's escape (from
//                      the codes, lbvh_escape), every leaf's range and primitive; an internal
//                      node over at most leaf_size primitives is
//                      written as a leaf of their range (the nodes under it stay, unreached)
//   wp_lbvh_refit      each leaf's box, then up the parent links: the second thread to reach a
//                      node (an atomic counter per node, incremented with release-acquire
//                      semantics, zero at the start, which that thread sets to zero again
//                      for the next refit) writes its box as the union of
//                      its children's, or of its primitives' for an internal node the hierarchy
//                      made a leaf (fminf/fmaxf: exact and order-free). With a check word pair
//                      `bad`, it also checks each box it reads for NaN and infinite coordinates
//                      (when asked) and the thread that writes the root reports the smallest
//                      bad index as a fault (FAULT_NON_FINITE_INPUT; for a mesh also the
//                      smallest position of an index outside the points, which its triangle
//                      boxes' step found, as FAULT_OUT_OF_BOUNDS on `indices`), resetting the
//                      words: a refit is one launch, with no read-back, that a graph can
//                      record.
//
// Only compiled with WP_BVH_BUILD (the runtime's BVH build library); kernels that query a BVH
// never include this file.
#pragma once
#include "wp_core.h"

#if defined(WP_BVH_BUILD)
namespace wp {

/// A node as the build writes it (the layout above; warp_core's BvhNode).
struct lbvh_node_t {
  f32 lower[3];
  i32 left;
  f32 upper[3];
  i32 right;
};
static_assert(sizeof(lbvh_node_t) == 32, "lbvh_node_t layout");

/// LbvhBounds: lowers, uppers (Vec3*, n each), n, bounds (u32*, 6: the min images of x, y, z
/// then the max images).
struct lbvh_bounds_t {
  u64 lowers;
  u64 uppers;
  u64 bounds;
  i64 n;
};
static_assert(sizeof(lbvh_bounds_t) == 32, "lbvh_bounds_t layout");

/// LbvhMorton: lowers, uppers (n each), bounds (as above, final), keys and values (u32*, n).
struct lbvh_morton_t {
  u64 lowers;
  u64 uppers;
  u64 bounds;
  u64 keys;
  u64 values;
  i64 n;
};
static_assert(sizeof(lbvh_morton_t) == 48, "lbvh_morton_t layout");

/// LbvhHierarchy: the sorted keys and values (n each), nodes (2n - 1), links (2 (2n - 1)),
/// prim_ids (n), n, leaf_size (>= 1: an internal node over at most this many primitives is
/// written as a leaf).
struct lbvh_hierarchy_t {
  u64 keys;
  u64 values;
  u64 nodes;
  u64 parents;
  u64 prim_ids;
  i64 n;
  i64 leaf_size;
};
static_assert(sizeof(lbvh_hierarchy_t) == 56, "lbvh_hierarchy_t layout");

/// LbvhRefit: lowers, uppers (per primitive), nodes, parents, prim_ids, counters (i32*, one per
/// internal node, zero, left zero), n; bad (i32*, two words at INT_MAX, or 0: no check and no
/// report): with `check`, the smallest index of a box with a non-finite lower corner lowers
/// bad[0], of an upper one bad[1] (an earlier step may have lowered them too); the thread that
/// writes the root resets both and reports the first word that is set as a fault of argument
/// 0 or 1, with the element of `sources[0]` or `sources[1]` (Vec3*) at that index; `fault`
/// is the fault context. `check` bit 0: check the boxes; bit 1: the boxes are by leaf
/// position (box k is that of prim_ids[k], as the triangle boxes' step writes them in leaf
/// order), else by primitive; bit 2: bad[1] is instead the smallest position of an index
/// outside the `num_points` points (a mesh's triangle boxes' step lowered it) in sources[1]
/// (i32*, 3 per primitive), reported as out of bounds on argument 1: index {position,
/// value}, shape {3n, num_points}.
struct lbvh_refit_t {
  u64 lowers;
  u64 uppers;
  u64 nodes;
  u64 parents;
  u64 prim_ids;
  u64 counters;
  i64 n;
  u64 bad;
  u64 sources[2];
  i64 check;
  i64 num_points;
  step_fault_t fault;
};
static_assert(sizeof(lbvh_refit_t) == 136, "lbvh_refit_t layout");

/// LbvhFinite: the smallest index of a non-finite vector of `n` (Vec3*) into *bad (i32,
/// atomically lowered; left alone when all are finite).
struct lbvh_finite_t {
  u64 values;
  u64 bad;
  i64 n;
};
static_assert(sizeof(lbvh_finite_t) == 24, "lbvh_finite_t layout");

/// LbvhTriangleBoxes: each of the `n` triangles' box (points: `num_points`, indices: 3 per
/// triangle) into lowers and uppers; the smallest position of an index outside the points
/// into *bad (i32, atomically lowered; `bad` 0: not recorded), whose triangle gets an empty
/// box and reads no point (a build refuses such an index, a refit's report raises it as a
/// fault); the smallest index of a point with a NaN or infinite coordinate into *bad_point
/// (i32, likewise; 0: not checked). With leaf_tris (f32*, 12 per triangle, 16-aligned; 0:
/// none) and a built tree's prim_ids (i32*, n): the step runs over the leaf positions k,
/// writing the box of face prim_ids[k] at position k (for a refit whose boxes are by
/// position, check bit 1) and that face's corners {x, y, z, 0} at leaf_tris[12k..12k + 12]
/// (NaN corners for a face with an index outside the points, or an id outside [0, n)): a
/// mesh's leaf-ordered triangles (warp_core's leaf_triangles), gathered where the vertices
/// are read anyway.
struct lbvh_triangle_boxes_t {
  u64 points;
  u64 indices;
  u64 lowers;
  u64 uppers;
  u64 bad;
  i64 n;
  i64 num_points;
  u64 bad_point;
  u64 prim_ids;
  u64 leaf_tris;
};
static_assert(sizeof(lbvh_triangle_boxes_t) == 80, "lbvh_triangle_boxes_t layout");

/// Whether every coordinate of `v` is finite (x - x is 0 exactly when x is finite).
WP_FN bool lbvh_finite(const Vec3& v) {
  return v.x - v.x == 0.0f && v.y - v.y == 0.0f && v.z - v.z == 0.0f;
}

/// The order-preserving u32 image of an f32 (negative values reversed below positive ones).
WP_FN u32 lbvh_ordered(f32 x) {
  const u32 u = f32_to_bits(x);
  return (u & 0x80000000u) ? ~u : (u | 0x80000000u);
}
WP_FN f32 lbvh_unordered(u32 u) {
  return f32_from_bits((u & 0x80000000u) ? (u & 0x7fffffffu) : ~u);
}

/// The centroid's coordinate: the midpoint of the box's extent.
WP_FN f32 lbvh_centre(f32 lo, f32 hi) { return 0.5f * (lo + hi); }

/// 10 bits of `x` in [lo, hi]: floor((x - lo) / (hi - lo) * 1024) clamped to 0..1023 (0 for an
/// empty extent).
WP_FN u32 lbvh_quantize(f32 x, f32 lo, f32 hi) {
  const f32 ext = hi - lo;
  if (!(ext > 0.0f)) return 0u;
  const f32 t = (x - lo) / ext * 1024.0f;
  if (!(t > 0.0f)) return 0u;
  if (t >= 1023.0f) return 1023u;
  return (u32)t;
}

/// The 10 bits of `v` spread to every third bit.
WP_FN u32 lbvh_spread(u32 v) {
  v = (v | (v << 16)) & 0x030000FFu;
  v = (v | (v << 8)) & 0x0300F00Fu;
  v = (v | (v << 4)) & 0x030C30C3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

/// The Morton code of primitive i's centroid in the box `b` (6 ordered images, as wp_lbvh_bounds
/// leaves them): x in the highest of each triple of bits.
WP_FN u32 lbvh_code(const Vec3& lo, const Vec3& hi, const u32* b) {
  const f32 c[3] = {lbvh_centre(lo.x, hi.x), lbvh_centre(lo.y, hi.y), lbvh_centre(lo.z, hi.z)};
  u32 code = 0;
  for (int a = 0; a < 3; ++a) {
    const u32 q = lbvh_quantize(c[a], lbvh_unordered(b[a]), lbvh_unordered(b[3 + a]));
    code |= lbvh_spread(q) << (2 - a);
  }
  return code;
}

/// The length of the common prefix of the (code, index) keys of sorted positions i and j, or
/// -1 when j is outside [0, n).
WP_FN i32 lbvh_delta(const u32* keys, i64 n, i64 i, i64 j) {
  if (j < 0 || j >= n) return -1;
  const u64 a = ((u64)keys[i] << 32) | (u64)i;
  const u64 b = ((u64)keys[j] << 32) | (u64)j;
  // i != j, so the xor is nonzero.
#if defined(__CUDACC__)
  return __clzll((long long)(a ^ b));
#else
  return __builtin_clzll(a ^ b);
#endif
}

/// Internal node i of n - 1: its range of sorted positions [first, last] and its split (the
/// last position of its left child), by Karras's binary searches.
WP_FN void lbvh_internal(const u32* keys, i64 n, i64 i, i64* first, i64* last, i64* split) {
  const i32 d = lbvh_delta(keys, n, i, i + 1) > lbvh_delta(keys, n, i, i - 1) ? 1 : -1;
  const i32 dmin = lbvh_delta(keys, n, i, i - d);
  i64 lmax = 2;
  while (lbvh_delta(keys, n, i, i + lmax * d) > dmin) lmax *= 2;
  i64 l = 0;
  for (i64 t = lmax / 2; t >= 1; t /= 2)
    if (lbvh_delta(keys, n, i, i + (l + t) * d) > dmin) l += t;
  const i64 j = i + l * d;
  const i32 dnode = lbvh_delta(keys, n, i, j);
  i64 s = 0;
  for (i64 t = (l + 1) / 2;; t = (t + 1) / 2) {
    if (lbvh_delta(keys, n, i, i + (s + t) * d) > dnode) s += t;
    if (t == 1) break;
  }
  *split = i + s * d + (d < 0 ? -1 : 0);
  *first = i < j ? i : j;
  *last = i < j ? j : i;
}

/// The escape of a node whose range of sorted positions ends at `last` (lbvh.rs' `escape`): the
/// node starting at last + 1 that the internal node splitting after `last` has as its right
/// child: internal node last + 1 when its range starts there (direction +1), else the leaf of
/// last + 1; -1 after the last position.
WP_FN i32 lbvh_escape(const u32* keys, i64 n, i64 last) {
  const i64 j = last + 1;
  if (j >= n) return -1;
  if (j <= n - 2 && lbvh_delta(keys, n, j, j + 1) > lbvh_delta(keys, n, j, j - 1)) return (i32)j;
  return (i32)(n - 1 + j);
}

/// Step k of the hierarchy: internal node k (k < n - 1) and the leaf of sorted position k. An
/// internal node over at most leaf_size positions becomes a leaf of them; its children keep
/// their parent links (the refit climbs through them) but no traversal reaches them.
WP_FN void lbvh_hierarchy_step(const u32* keys, const u32* values, i64 n, i64 k,
                               i64 leaf_size, lbvh_node_t* nodes, i32* parents, i32* prim_ids) {
  const i64 leaf = n - 1 + k;
  // The escapes follow the parents: node_count(n) links each.
  i32* escapes = parents + (n >= 2 ? 2 * n - 1 : 1);
  nodes[leaf].left = ~(i32)k;
  nodes[leaf].right = (i32)(k + 1);
  prim_ids[k] = (i32)values[k];
  escapes[leaf] = lbvh_escape(keys, n, k);
  if (k == 0) parents[0] = -1;
  if (k < n - 1) {
    i64 first, last, split;
    lbvh_internal(keys, n, k, &first, &last, &split);
    escapes[k] = lbvh_escape(keys, n, last);
    const i64 left = split == first ? n - 1 + split : split;
    const i64 right = split + 1 == last ? n - 1 + split + 1 : split + 1;
    if (last - first + 1 <= leaf_size) {
      nodes[k].left = ~(i32)first;
      nodes[k].right = (i32)(last + 1);
    } else {
      nodes[k].left = (i32)left;
      nodes[k].right = (i32)right;
    }
    parents[left] = (i32)k;
    parents[right] = (i32)k;
  }
}

}  // namespace wp
#endif

#if defined(__CUDACC__) && defined(WP_BVH_BUILD)
#define WP_LBVH_LOOP(i, n)                                                                 \
  for (wp::i64 i = (wp::i64)blockIdx.x * blockDim.x + threadIdx.x; i < (n);               \
       i += (wp::i64)blockDim.x * gridDim.x)

extern "C" __global__ void wp_lbvh_bounds(wp::lbvh_bounds_t s) {
  const wp::Vec3* lo = (const wp::Vec3*)s.lowers;
  const wp::Vec3* hi = (const wp::Vec3*)s.uppers;
  wp::u32* b = (wp::u32*)s.bounds;
  // Each thread's box, then each warp's (shuffles), then one atomic per warp and word: an
  // atomic per primitive serialises on the 6 words.
  wp::u32 acc[6] = {0xffffffffu, 0xffffffffu, 0xffffffffu, 0u, 0u, 0u};
  WP_LBVH_LOOP(i, s.n) {
    const wp::f32 c[3] = {wp::lbvh_centre(lo[i].x, hi[i].x), wp::lbvh_centre(lo[i].y, hi[i].y),
                          wp::lbvh_centre(lo[i].z, hi[i].z)};
    for (int a = 0; a < 3; ++a) {
      const wp::u32 u = wp::lbvh_ordered(c[a]);
      acc[a] = umin(acc[a], u);
      acc[3 + a] = umax(acc[3 + a], u);
    }
  }
  // Every lane of the warp gets here (no early exit; blocks are whole warps).
  for (int off = 16; off > 0; off >>= 1) {
    for (int a = 0; a < 3; ++a) {
      acc[a] = umin(acc[a], __shfl_xor_sync(0xffffffffu, acc[a], off));
      acc[3 + a] = umax(acc[3 + a], __shfl_xor_sync(0xffffffffu, acc[3 + a], off));
    }
  }
  // Then the block's (one atomic per block and word: same-address atomics serialise in L2).
  __shared__ wp::u32 warps[32][6];
  const unsigned lane = threadIdx.x & 31u, warp = threadIdx.x >> 5;
  if (lane == 0u)
    for (int a = 0; a < 6; ++a) warps[warp][a] = acc[a];
  __syncthreads();
  if (threadIdx.x == 0u) {
    for (unsigned w = 1; w < (blockDim.x + 31u) >> 5; ++w) {
      for (int a = 0; a < 3; ++a) {
        acc[a] = umin(acc[a], warps[w][a]);
        acc[3 + a] = umax(acc[3 + a], warps[w][3 + a]);
      }
    }
    for (int a = 0; a < 3; ++a) {
      if (acc[a] != 0xffffffffu) atomicMin(&b[a], acc[a]);
      if (acc[3 + a] != 0u) atomicMax(&b[3 + a], acc[3 + a]);
    }
  }
}

extern "C" __global__ void wp_lbvh_morton(wp::lbvh_morton_t s) {
  const wp::Vec3* lo = (const wp::Vec3*)s.lowers;
  const wp::Vec3* hi = (const wp::Vec3*)s.uppers;
  WP_LBVH_LOOP(i, s.n) {
    ((wp::u32*)s.keys)[i] = wp::lbvh_code(lo[i], hi[i], (const wp::u32*)s.bounds);
    ((wp::u32*)s.values)[i] = (wp::u32)i;
  }
}

extern "C" __global__ void wp_lbvh_hierarchy(wp::lbvh_hierarchy_t s) {
  WP_LBVH_LOOP(k, s.n) {
    wp::lbvh_hierarchy_step((const wp::u32*)s.keys, (const wp::u32*)s.values, s.n, k,
                            s.leaf_size, (wp::lbvh_node_t*)s.nodes, (wp::i32*)s.parents,
                            (wp::i32*)s.prim_ids);
  }
}

namespace wp {
/// The refit's arrival at a node: an atomic increment of its counter with release-acquire
/// semantics at device scope (PTX `atom.acq_rel.gpu`), returning the old count. Release: the
/// boxes this thread wrote (and its check words) are visible to whoever observes the increment;
/// acquire: the second arrival sees its sibling's boxes. It replaces two sequentially consistent
/// fences (`__threadfence()` before and after a relaxed atomicAdd) per level of the climb.
__device__ __forceinline__ i32 lbvh_arrive(i32* counter) {
  i32 old;
  asm volatile("atom.acq_rel.gpu.global.add.s32 %0, [%1], 1;" : "=r"(old) : "l"(counter) : "memory");
  return old;
}
}  // namespace wp

/// The refit's report (by the thread that wrote the root, after every other thread's check):
/// both check words reset, the first one set raised as a fault of argument 0 or 1.
__device__ void wp_lbvh_refit_report(const wp::lbvh_refit_t& s) {
  wp::i32* bad = (wp::i32*)s.bad;
  wp::ctx_t ctx = wp::ctx_make(&s.fault.ctx);
  for (int a = 0; a < 2; ++a) {
    const wp::i32 i = atomicExch(&bad[a], 0x7fffffff);
    if (i == 0x7fffffff || wp::faulted(&ctx) || s.sources[a] == 0) continue;
    if (a == 1 && (s.check & 4) != 0) {
      // A mesh's index outside its points (written by a kernel since the build): position
      // i of the indices holds it, as the CPU's refit names it.
      const wp::i64 index[2] = {(wp::i64)i, (wp::i64)((const wp::i32*)s.sources[1])[i]};
      const wp::i64 shape[2] = {3 * s.n, s.num_points};
      wp::raise(&ctx, wp::FAULT_OUT_OF_BOUNDS, a, 2, index, shape);
      continue;
    }
    const wp::Vec3 v = ((const wp::Vec3*)s.sources[a])[i];
    const wp::i64 index[4] = {(wp::i64)i, (wp::i64)wp::f64_to_bits((wp::f64)v.x),
                              (wp::i64)wp::f64_to_bits((wp::f64)v.y),
                              (wp::i64)wp::f64_to_bits((wp::f64)v.z)};
    wp::raise(&ctx, wp::FAULT_NON_FINITE_INPUT, a, 4, index, nullptr);
  }
}

extern "C" __global__ void wp_lbvh_refit(wp::lbvh_refit_t s) {
  const wp::Vec3* lo = (const wp::Vec3*)s.lowers;
  const wp::Vec3* hi = (const wp::Vec3*)s.uppers;
  // A node as two 16-byte words: {lower xyz, left} and {upper xyz, right}. Nodes other threads
  // wrote are read through L2 (__ldcg: L1 is not coherent), whole words at a time.
  float4* nodes = (float4*)s.nodes;
  const wp::i32* parents = (const wp::i32*)s.parents;
  const wp::i32* prim_ids = (const wp::i32*)s.prim_ids;
  wp::i32* counters = (wp::i32*)s.counters;
  wp::i32* bad = (wp::i32*)s.bad;
  WP_LBVH_LOOP(k, s.n) {
    const wp::i64 leaf = s.n - 1 + k;
    const bool by_position = (s.check & 2) != 0;
    const wp::i32 p = by_position ? (wp::i32)k : prim_ids[k];
    const wp::Vec3 l = lo[p], h = hi[p];
    // Every primitive is one leaf's: checked once, before this thread arrives anywhere.
    if ((s.check & 1) != 0) {
      if (!wp::lbvh_finite(l)) atomicMin(&bad[0], p);
      if (!wp::lbvh_finite(h)) atomicMin(&bad[1], p);
    }
    // The leaf of sorted position k holds [k, k + 1) (the hierarchy wrote the same).
    __stcg(&nodes[2 * leaf], make_float4(l.x, l.y, l.z, __int_as_float(~(wp::i32)k)));
    __stcg(&nodes[2 * leaf + 1], make_float4(h.x, h.y, h.z, __int_as_float((wp::i32)k + 1)));
    wp::i32 c = parents[leaf];
    // The box this thread wrote last (node `prev`'s), kept in registers: a second arrival
    // reads only the sibling's box from L2, two 16-byte words instead of four.
    wp::i64 prev = leaf;
    float3 mine_l = make_float3(l.x, l.y, l.z), mine_u = make_float3(h.x, h.y, h.z);
    while (c >= 0) {
      // Arrive with a release-acquire increment (lbvh_arrive): this subtree's boxes (and
      // checks) are published before it, and the second arrival reads both children after it.
      if (wp::lbvh_arrive(&counters[c]) == 0) break;
      // The second arrival: the node's last visitor in this refit, which leaves its counter
      // zero for the next (no fill before a refit).
      counters[c] = 0;
      const float4 a = __ldcg(&nodes[2 * c]), b = __ldcg(&nodes[2 * c + 1]);
      const wp::i32 left = __float_as_int(a.w), right = __float_as_int(b.w);
      float3 bl, bu;
      if (left < 0) {
        // A leaf over several primitives (leaf_size > 1): the union of their boxes.
        wp::i32 q = by_position ? ~left : prim_ids[~left];
        bl = make_float3(lo[q].x, lo[q].y, lo[q].z);
        bu = make_float3(hi[q].x, hi[q].y, hi[q].z);
        for (wp::i32 j = ~left + 1; j < right; ++j) {
          q = by_position ? j : prim_ids[j];
          bl = make_float3(fminf(bl.x, lo[q].x), fminf(bl.y, lo[q].y), fminf(bl.z, lo[q].z));
          bu = make_float3(fmaxf(bu.x, hi[q].x), fmaxf(bu.y, hi[q].y), fmaxf(bu.z, hi[q].z));
        }
      } else {
        // Left operand first, as before (fminf of zeros of both signs may depend on order).
        const bool came_left = (wp::i64)left == prev;
        const wp::i32 sib = came_left ? right : left;
        const float4 s0 = __ldcg(&nodes[2 * sib]), s1 = __ldcg(&nodes[2 * sib + 1]);
        const float3 sl = make_float3(s0.x, s0.y, s0.z), su = make_float3(s1.x, s1.y, s1.z);
        const float3 l0 = came_left ? mine_l : sl, r0 = came_left ? sl : mine_l;
        const float3 l1 = came_left ? mine_u : su, r1 = came_left ? su : mine_u;
        bl = make_float3(fminf(l0.x, r0.x), fminf(l0.y, r0.y), fminf(l0.z, r0.z));
        bu = make_float3(fmaxf(l1.x, r1.x), fmaxf(l1.y, r1.y), fmaxf(l1.z, r1.z));
      }
      __stcg(&nodes[2 * c], make_float4(bl.x, bl.y, bl.z, a.w));
      __stcg(&nodes[2 * c + 1], make_float4(bu.x, bu.y, bu.z, b.w));
      mine_l = bl;
      mine_u = bu;
      prev = c;
      c = parents[c];
    }
    // Past the root (c < 0, not a first arrival's break): this thread wrote the root, after
    // every other thread's boxes and checks (the counters' chain of fences orders them).
    if (c < 0 && s.bad != 0) {
      __threadfence();
      wp_lbvh_refit_report(s);
    }
  }
}
extern "C" __global__ void wp_lbvh_finite(wp::lbvh_finite_t s) {
  const wp::Vec3* v = (const wp::Vec3*)s.values;
  WP_LBVH_LOOP(i, s.n) {
    // x - x is 0 exactly when x is finite.
    if (!(v[i].x - v[i].x == 0.0f && v[i].y - v[i].y == 0.0f && v[i].z - v[i].z == 0.0f))
      atomicMin((wp::i32*)s.bad, (wp::i32)i);
  }
}

extern "C" __global__ void wp_lbvh_triangle_boxes(wp::lbvh_triangle_boxes_t s) {
  const wp::Vec3* p = (const wp::Vec3*)s.points;
  const wp::i32* ix = (const wp::i32*)s.indices;
  wp::Vec3* lo = (wp::Vec3*)s.lowers;
  wp::Vec3* hi = (wp::Vec3*)s.uppers;
  const wp::i32* ids = (const wp::i32*)s.prim_ids;
  float4* tris = (float4*)s.leaf_tris;
  WP_LBVH_LOOP(i, s.n) {
    // Face order, or leaf order (position i holds face ids[i]) with the corners' copy; the
    // box goes to index i either way (by face, or by position for a refit that reads them so).
    const wp::i64 f = tris != nullptr ? (wp::i64)ids[i] : i;
    const float4 nan4 = make_float4(__int_as_float(0x7fc00000), __int_as_float(0x7fc00000),
                                    __int_as_float(0x7fc00000), 0.0f);
    if (f < 0 || f >= s.n) {
      // Only a corrupt tree's id: an empty box, NaN corners.
      lo[i] = wp::Vec3_new(0.0f, 0.0f, 0.0f);
      hi[i] = lo[i];
      for (int j = 0; j < 3; ++j) tris[3 * i + j] = nan4;
      continue;
    }
    bool in_range = true;
    for (int k = 0; k < 3; ++k) {
      const wp::i32 v = ix[3 * f + k];
      if (v < 0 || (wp::i64)v >= s.num_points) {
        if (s.bad != 0) atomicMin((wp::i32*)s.bad, (wp::i32)(3 * f + k));
        in_range = false;
      }
    }
    if (!in_range) {
      lo[i] = wp::Vec3_new(0.0f, 0.0f, 0.0f);
      hi[i] = lo[i];
      if (tris != nullptr)
        for (int j = 0; j < 3; ++j) tris[3 * i + j] = nan4;
      continue;
    }
    const wp::Vec3 a = p[ix[3 * f]], b = p[ix[3 * f + 1]], c = p[ix[3 * f + 2]];
    if (tris != nullptr) {
      tris[3 * i] = make_float4(a.x, a.y, a.z, 0.0f);
      tris[3 * i + 1] = make_float4(b.x, b.y, b.z, 0.0f);
      tris[3 * i + 2] = make_float4(c.x, c.y, c.z, 0.0f);
    }
    // Finite points (checked, here or by the caller): fminf/fmaxf are the CPU's f32::min/max.
    lo[i] = wp::Vec3_new(fminf(fminf(a.x, b.x), c.x), fminf(fminf(a.y, b.y), c.y),
                         fminf(fminf(a.z, b.z), c.z));
    hi[i] = wp::Vec3_new(fmaxf(fmaxf(a.x, b.x), c.x), fmaxf(fmaxf(a.y, b.y), c.y),
                         fmaxf(fmaxf(a.z, b.z), c.z));
  }
  if (s.bad_point != 0) {
    WP_LBVH_LOOP(i, s.num_points) {
      if (!wp::lbvh_finite(p[i])) atomicMin((wp::i32*)s.bad_point, (wp::i32)i);
    }
  }
}
#undef WP_LBVH_LOOP
#endif

// wp_bvh.h: section "bvh" of the builtin table: NVIDIA Warp's BVH queries, the CUDA mirror of
// warp-core/src/objects/bvh.rs (read that for the node layout, the stackless traversal by
// escape links of the box and ray loops, the ordered walk's 32-entry ring with the climb by
// parent links as its overflow path, the move budget and the corrupt-tree rules). Every step below is the Rust
// one in the same order: both backends visit the same nodes and yield the same primitives in
// the same order, fault on the same read with the same index, and end at the same move.
//
//   bvh_node_t                              BvhNode (32 bytes: lower, left, upper, right)
//   bvh_tree_t                              the tree part of a bvh_t / mesh_t (BvhTree)
//   bvh_t                                   a Bvh kernel parameter (warp_runtime's CudaBvh)
//   bvh_walk_t                              Walk: a left-first traversal's position (20 bytes)
//   bvh_query_aabb_t, bvh_query_ray_t       BvhQueryAabb, BvhQueryRay (44 bytes each)
//   bvh_query_aabb(b, lo, hi, ctx)          the state before the first primitive
//   bvh_query_aabb_next(b, q, ctx)          the state at the next primitive, or at the end
//   bvh_query_aabb_done(q), bvh_query_aabb_item(q)    whether it ended; the primitive (i32)
//   bvh_query_ray(b, start, dir, ctx), bvh_query_ray_next/_done/_item   the same for a ray
//   detail::bvh_walk_next, detail::bvh_walk_ordered   the traversals (the mesh's too)
//
// Faults: every read whose index comes from buffer contents is checked and reported as an
// out-of-bounds fault of the tree's parameter (`arg`), with Rust's index and shape: a node
// or parent link, or an escape (when its node is read), outside [0, num_nodes), a prim_ids position or id outside [0, num_prims),
// a leaf end past num_prims (index end - 1). After a fault a function returns at once (the
// CPU's `?`); the caller checks ctx->raised. No query runs longer than 2 * num_nodes + 2
// moves, whatever the buffers hold.
//
// Kernel-argument layout (all little-endian, align 8; the runtime's #[repr(C)] mirror must
// match byte for byte; device addresses as u64 on the Rust side):
//
//   bvh_t, 56 bytes:
//      0 nodes      (const bvh_node_t*, num_nodes entries; the root is node 0)
//      8 parents    (const i32*, 2 * num_nodes entries, the links: each node's parent, -1 at
//                    the root, then each node's escape, -1 for none)
//     16 prim_ids   (const i32*, num_prims entries)
//     24 num_nodes  (i32, >= 1: the empty tree is one empty leaf)
//     28 num_prims  (i32)
//     32 arg        (i32: the kernel parameter's index, for faults)
//     36 pad        (i32, 0)
//     40 lowers     (const Vec3*, num_prims entries: the primitives' boxes)
//     48 uppers     (const Vec3*, num_prims entries)
//   (bytes 0..40 are a bvh_tree_t, which mesh_t starts with too.)
#pragma once
#include "wp_geometry.h"

namespace wp {

/// BvhNode: an internal node has left, right >= 0 (its children); a leaf has left < 0 and holds
/// prim_ids[~left .. right].
struct bvh_node_t {
  f32 lower[3];
  i32 left;
  f32 upper[3];
  i32 right;
};
static_assert(sizeof(bvh_node_t) == 32, "bvh_node_t layout");

/// The tree every query reads (bytes 0..40 of bvh_t and mesh_t, see the top).
struct bvh_tree_t {
  const bvh_node_t* nodes;
  const i32* parents;
  const i32* prim_ids;
  i32 num_nodes;
  i32 num_prims;
  i32 arg;
  i32 pad;
};
static_assert(sizeof(bvh_tree_t) == 40 && alignof(bvh_tree_t) == 8, "bvh_tree_t layout");

/// A Bvh kernel parameter (56 bytes, see the top).
struct bvh_t {
  bvh_tree_t tree;
  const Vec3* lowers;
  const Vec3* uppers;
  /// Marks a kernel object for the adjoint library (zero value, no gradient).
  typedef void wp_object_tag;
};
static_assert(sizeof(bvh_t) == 56 && alignof(bvh_t) == 8, "bvh_t layout");

/// Walk (20 bytes): the current leaf (-2 before the root, -1 once done), the next position in
/// prim_ids and the leaf's end, the current primitive (-1 before the first and once done), and
/// the moves taken.
struct bvh_walk_t {
  i32 node;
  i32 next;
  i32 end;
  i32 item;
  u32 steps;
};
static_assert(sizeof(bvh_walk_t) == 20, "bvh_walk_t layout");

/// BvhQueryAabb (44 bytes): 0 lower, 12 upper, 24 walk.
struct bvh_query_aabb_t {
  Vec3 lower;
  Vec3 upper;
  bvh_walk_t walk;
  typedef void wp_object_tag;
};
static_assert(sizeof(bvh_query_aabb_t) == 44, "bvh_query_aabb_t layout");

/// BvhQueryRay (44 bytes): 0 start, 12 inv_dir (1 / dir), 24 walk.
struct bvh_query_ray_t {
  Vec3 start;
  Vec3 inv_dir;
  bvh_walk_t walk;
  typedef void wp_object_tag;
};
static_assert(sizeof(bvh_query_ray_t) == 44, "bvh_query_ray_t layout");

namespace detail {

#define WP_BVH_WALK_START (-2)
#define WP_BVH_WALK_END (-1)

WP_LFN bvh_walk_t bvh_walk_start() {
  bvh_walk_t w;
  w.node = WP_BVH_WALK_START;
  w.next = 0;
  w.end = 0;
  w.item = -1;
  w.steps = 0u;
  return w;
}

/// The out-of-bounds fault of the tree's parameter: `index` against a buffer of `len`.
/// `Inline` picks how it is raised, measured per traversal (H200, benches/geometry.rs):
/// the ordered walks (mesh point and ray queries) raise it out of line, as a 1-D array
/// access does (`raise_out_of_bounds_1d`): an inlined `raise` at each of their checks
/// lengthened the hot path (signed point query 29.7 -> 26.7 ms, ray 1.42 -> 1.28 ms). The
/// stackless walk of the box and ray iterators (`bvh_walk_next`) keeps it inline: out of
/// line, its box query took 10.0 ms instead of 4.2 (measured when the call took the launch's
/// whole record by value rather than its address). Out of line, the thread's ctx_t is marked
/// here and the call fills the launch's record.
template <bool Inline = false>
WP_FN void bvh_fault(const bvh_tree_t& t, i64 index, i64 len, ctx_t* ctx) {
  if constexpr (Inline) {
    raise(ctx, FAULT_OUT_OF_BOUNDS, t.arg, 1, &index, &len);
  } else {
    ctx->raised = 1;
    raise_out_of_bounds_1d(ctx->rec, t.arg, index, len);
  }
}

WP_LFN Vec3 bvh_node_lower(const bvh_node_t& n) { return Vec3_new(n.lower[0], n.lower[1], n.lower[2]); }
WP_LFN Vec3 bvh_node_upper(const bvh_node_t& n) { return Vec3_new(n.upper[0], n.upper[1], n.upper[2]); }

/// Node i, which the caller has checked to be one of the nodes.
WP_LFN bvh_node_t bvh_node_in_bounds(const bvh_tree_t& t, i32 i) {
#if defined(__CUDACC__)
  // Two 16-byte read-only loads (the runtime allocates nodes 16-byte aligned) instead of
  // eight 4-byte ones: the traversals are bound by these loads.
  const float4* q = reinterpret_cast<const float4*>(t.nodes + i);
  const float4 lo = __ldg(q), hi = __ldg(q + 1);
  bvh_node_t n;
  n.lower[0] = lo.x; n.lower[1] = lo.y; n.lower[2] = lo.z; n.left = __float_as_int(lo.w);
  n.upper[0] = hi.x; n.upper[1] = hi.y; n.upper[2] = hi.z; n.right = __float_as_int(hi.w);
  return n;
#else
  return t.nodes[i];
#endif
}

/// Node i, or a fault (and a zero node) when i is outside the nodes.
template <bool Inline = false>
WP_FN bvh_node_t bvh_node(const bvh_tree_t& t, i32 i, ctx_t* ctx) {
  if ((u32)i < (u32)t.num_nodes) return bvh_node_in_bounds(t, i);
  bvh_fault<Inline>(t, (i64)i, (i64)t.num_nodes, ctx);
  return bvh_node_t{};
}

/// Nodes i and j, or a fault at the first of them outside the nodes (and zero nodes). Both
/// indices are checked before either node is read, so that the two reads are issued together:
/// a read after a check that may return cannot be hoisted above it, and the ordered walk reads
/// both children of every node it enters.
WP_LFN void bvh_node_pair(const bvh_tree_t& t, i32 i, i32 j, bvh_node_t* a, bvh_node_t* b,
                         ctx_t* ctx) {
  const bool ok_i = (u32)i < (u32)t.num_nodes, ok_j = (u32)j < (u32)t.num_nodes;
  if (ok_i && ok_j) {
    *a = bvh_node_in_bounds(t, i);
    *b = bvh_node_in_bounds(t, j);
    return;
  }
  bvh_fault(t, ok_i ? (i64)j : (i64)i, (i64)t.num_nodes, ctx);
  *a = bvh_node_t{};
  *b = bvh_node_t{};
}

/// The parent of node i, or a fault.
template <bool Inline = false>
WP_FN i32 bvh_parent(const bvh_tree_t& t, i32 i, ctx_t* ctx) {
  if ((u32)i < (u32)t.num_nodes) return t.parents[i];
  bvh_fault<Inline>(t, (i64)i, (i64)t.num_nodes, ctx);
  return 0;
}

/// The primitive at position k of prim_ids, or a fault when k, or the id read, is outside
/// [0, num_prims).
template <bool Inline = false>
WP_FN i32 bvh_prim(const bvh_tree_t& t, i32 k, ctx_t* ctx) {
  if ((u32)k >= (u32)t.num_prims) {
    bvh_fault<Inline>(t, (i64)k, (i64)t.num_prims, ctx);
    return 0;
  }
  const i32 id = t.prim_ids[k];
  if ((u32)id < (u32)t.num_prims) return id;
  bvh_fault<Inline>(t, (i64)id, (i64)t.num_prims, ctx);
  return 0;
}

/// A leaf's range [~left, right), its end checked against prim_ids.
template <bool Inline = false>
WP_FN void bvh_leaf_range(const bvh_tree_t& t, const bvh_node_t& n, i32* start, i32* end,
                          ctx_t* ctx) {
  *start = ~n.left;
  *end = n.right;
  if (n.right > t.num_prims) bvh_fault<Inline>(t, (i64)n.right - 1, (i64)t.num_prims, ctx);
}

/// The move budget: 2 * num_nodes + 2, at most u32::MAX.
WP_LFN u32 bvh_max_steps(const bvh_tree_t& t) {
  const i64 m = 2 * (i64)t.num_nodes + 2;
  return m < (i64)0xffffffffu ? (u32)m : 0xffffffffu;
}

/// BvhTree::escape: the node a left-first traversal visits after node i's subtree (i a node the
/// caller read), or false at the end (a negative escape). The escape is checked when its node
/// is read.
WP_LFN bool bvh_escape(const bvh_tree_t& t, i32 i, i32* out) {
  if ((u32)i >= (u32)t.num_nodes) return false;  // not a node: never taken
  const i32* at = t.parents + (i64)t.num_nodes + (i64)i;
#if defined(__CUDACC__)
  const i32 e = __ldg(at);
#else
  const i32 e = *at;
#endif
  *out = e;
  return e >= 0;
}

/// The walk at its end (no primitive; it stays there).
WP_LFN bvh_walk_t bvh_walk_ended(bvh_walk_t w) {
  w.node = WP_BVH_WALK_END;
  w.next = 0;
  w.end = 0;
  w.item = -1;
  return w;
}

/// Walk::next: advances w to the next primitive `prim_test(id, ctx)` accepts, in a leaf whose
/// box and whose ancestors' boxes `node_test(lower, upper)` accepts; or to the end. Once done
/// it stays done. On a fault it returns the ended walk with ctx->raised set: the CPU's walk
/// stops at its fault, and a GPU thread goes on, so a walk that kept its state would hand the
/// kernel's loop its last primitive again, and a fault at a primitive (which takes no move)
/// would repeat at every call, for ever.
template <typename NodeTest, typename PrimTest>
WP_FN bvh_walk_t bvh_walk_next(bvh_walk_t w, const bvh_tree_t& t, NodeTest node_test,
                               PrimTest prim_test, ctx_t* ctx) {
  for (;;) {
    while (w.next < w.end) {
      const i32 id = bvh_prim<true>(t, w.next, ctx);
      if (faulted(ctx)) return bvh_walk_ended(w);
      w.next += 1;
      const bool ok = prim_test(id, ctx);
      if (faulted(ctx)) return bvh_walk_ended(w);
      if (ok) {
        w.item = id;
        return w;
      }
    }
    bool has;
    i32 n = 0;
    if (w.node == WP_BVH_WALK_START) {
      has = true;
      n = 0;
    } else if (w.node == WP_BVH_WALK_END) {
      has = false;
    } else {
      // The current leaf is finished: its escape.
      has = bvh_escape(t, w.node, &n);
    }
    // Down from n to the next accepted leaf, past rejected subtrees by their escapes.
    for (;;) {
      if (!has) return bvh_walk_ended(w);
      w.steps += 1u;
      if (w.steps > bvh_max_steps(t)) {
        has = false;
        continue;
      }
      const bvh_node_t node = bvh_node<true>(t, n, ctx);
      if (faulted(ctx)) return bvh_walk_ended(w);
      if (!node_test(bvh_node_lower(node), bvh_node_upper(node))) {
        const i32 i = n;
        has = bvh_escape(t, i, &n);
      } else if (node.left < 0) {
        i32 start, end;
        bvh_leaf_range<true>(t, node, &start, &end, ctx);
        if (faulted(ctx)) return bvh_walk_ended(w);
        w.node = n;
        w.next = start;
        w.end = end;
        break;
      } else {
        n = node.left;
      }
    }
  }
}

/// A NaN key as +inf (keys totally ordered).
WP_LFN f32 bvh_key(f32 k) { return k < f32_inf() ? k : f32_inf(); }

/// ordered_children: the children of internal node n nearest first (ties to the left), with
/// their keys and nodes. S: node_key(lower, upper) -> f32, bound() -> f32, visit(k, ctx) with
/// k a position in prim_ids within a leaf's checked range.
template <typename S>
WP_FN void bvh_ordered_children(const bvh_tree_t& t, const S& s, const bvh_node_t& n, i32* a,
                                f32* ka, bvh_node_t* an, i32* b, f32* kb, bvh_node_t* bn,
                                ctx_t* ctx) {
  bvh_node_t l, r;
  bvh_node_pair(t, n.left, n.right, &l, &r, ctx);
  if (faulted(ctx)) return;
  const f32 kl = bvh_key(s.node_key(bvh_node_lower(l), bvh_node_upper(l)));
  const f32 kr = bvh_key(s.node_key(bvh_node_lower(r), bvh_node_upper(r)));
  if (kr < kl) {
    *a = n.right; *ka = kr; *an = r; *b = n.left; *kb = kl; *bn = l;
  } else {
    *a = n.left; *ka = kl; *an = l; *b = n.right; *kb = kr; *bn = r;
  }
}

/// ORDERED_STACK: the entries of walk_ordered's ring of farther children.
#define WP_BVH_ORDERED_STACK 32

/// walk_ordered: visits the leaves nearest first, skipping every box whose key is not below
/// the search's current bound (which never rises). The farther child, when it passes too, is
/// pushed on a ring of WP_BVH_ORDERED_STACK entries with its key and popped when the nearer
/// subtree is finished; entries the ring dropped (a deeper tree) are found by climbing the
/// parent links. At most 2 * num_nodes + 2 moves.
template <typename S>
WP_FN void bvh_walk_ordered(const bvh_tree_t& t, S& s, ctx_t* ctx) {
  bvh_node_t node = bvh_node(t, 0, ctx);
  if (faulted(ctx)) return;
  if (!(bvh_key(s.node_key(bvh_node_lower(node), bvh_node_upper(node))) < s.bound())) return;
  const u32 max = bvh_max_steps(t);
  u32 steps = 0u;
  // An entry is the node (low word) and its key's bits (high word) in one u64: one local
  // store per push and one load per pop rather than two (and, unlike an array of structs,
  // the arrays of the walks inlined into one kernel still share their stack frame).
  u64 stack[WP_BVH_ORDERED_STACK];
  u32 held = 0u, head = 0u;
  bool dropped = false;
  // node is node cur: a child entered goes on with the node read to order it.
  i32 cur = 0;
  for (;;) {  // 'down
    steps += 1u;
    if (steps > max) return;
    bool descended = false;
    if (node.left < 0) {
      i32 start, end;
      bvh_leaf_range(t, node, &start, &end, ctx);
      if (faulted(ctx)) return;
      // visit takes the position in prim_ids (inside the range just checked); a search
      // reads the id (bvh_prim, checked) only where it needs it.
      for (i32 k = start; k < end; ++k) {
        s.visit(k, ctx);
        if (faulted(ctx)) return;
      }
    } else {
      i32 a = 0, b = 0;
      f32 ka = 0.0f, kb = 0.0f;
      bvh_node_t an{}, bn{};
      bvh_ordered_children(t, s, node, &a, &ka, &an, &b, &kb, &bn, ctx);
      if (faulted(ctx)) return;
      // ka <= kb: when the nearer child fails the bound the farther fails too.
      if (ka < s.bound()) {
        if (kb < s.bound()) {
          stack[head] = (u64)(u32)b | ((u64)f32_to_bits(kb) << 32);
          head = (head + 1u) % WP_BVH_ORDERED_STACK;
          dropped = dropped || held == WP_BVH_ORDERED_STACK;
          held = held < WP_BVH_ORDERED_STACK ? held + 1u : held;
        }
        cur = a;
        node = an;
        descended = true;
      }
    }
    if (descended) continue;
    // cur is finished: the next entry still below the bound.
    while (held > 0u) {
      head = (head + WP_BVH_ORDERED_STACK - 1u) % WP_BVH_ORDERED_STACK;
      held -= 1u;
      const u64 e = stack[head];
      if (f32_from_bits((u32)(e >> 32)) < s.bound()) {
        cur = (i32)(u32)e;
        node = bvh_node(t, cur, ctx);
        if (faulted(ctx)) return;
        descended = true;
        break;
      }
    }
    if (descended) continue;
    if (!dropped) return;
    // Entries were dropped: climb to the next subtree to enter.
    i32 c = cur;
    for (;;) {
      steps += 1u;
      if (steps > max) return;
      const i32 p = bvh_parent(t, c, ctx);
      if (faulted(ctx)) return;
      if (p < 0) return;
      const bvh_node_t pn = bvh_node(t, p, ctx);
      if (faulted(ctx)) return;
      if (pn.left < 0) return;
      i32 a = 0, b = 0;
      f32 ka = 0.0f, kb = 0.0f;
      bvh_node_t an{}, bn{};
      bvh_ordered_children(t, s, pn, &a, &ka, &an, &b, &kb, &bn, ctx);
      if (faulted(ctx)) return;
      if (c == a && b != a) {
        if (kb < s.bound()) {
          cur = b;
          node = bn;
          descended = true;
          break;
        }
      } else if (c != b) {
        return;  // a parent link that does not lead back: corrupt
      }
      c = p;
    }
    (void)descended;
  }
}

}  // namespace detail

// ------------------------------------------------------------------------------------------
// Box query
// ------------------------------------------------------------------------------------------

/// Starts a query for the primitives whose boxes overlap [lower, upper] (touching counts).
WP_LFN bvh_query_aabb_t bvh_query_aabb(const bvh_t& bvh, Vec3 lower, Vec3 upper, ctx_t* ctx) {
  (void)bvh;
  (void)ctx;
  bvh_query_aabb_t q;
  q.lower = lower;
  q.upper = upper;
  q.walk = detail::bvh_walk_start();
  return q;
}

WP_LFN bvh_query_aabb_t bvh_query_aabb_next(const bvh_t& bvh, bvh_query_aabb_t q, ctx_t* ctx) {
  const Vec3 lo = q.lower, hi = q.upper;
  q.walk = detail::bvh_walk_next(
      q.walk, bvh.tree, [lo, hi](Vec3 l, Vec3 u) { return aabb_overlap(l, u, lo, hi); },
      [&bvh, lo, hi](i32 id, ctx_t*) {
        return aabb_overlap(bvh.lowers[id], bvh.uppers[id], lo, hi);
      },
      ctx);
  return q;
}

WP_LFN bool bvh_query_aabb_done(bvh_query_aabb_t q) { return q.walk.item < 0; }

WP_LFN i32 bvh_query_aabb_item(bvh_query_aabb_t q) { return q.walk.item; }

/// Every item a box or ray query yields is below this (bvh_prim checks each id).
WP_LFN i64 bvh_item_bound(const bvh_t& bvh) { return (i64)bvh.tree.num_prims; }

// ------------------------------------------------------------------------------------------
// Ray query
// ------------------------------------------------------------------------------------------

/// Starts a query for the primitives whose boxes the ray start + t * dir, t >= 0, meets.
WP_LFN bvh_query_ray_t bvh_query_ray(const bvh_t& bvh, Vec3 start, Vec3 dir, ctx_t* ctx) {
  (void)bvh;
  (void)ctx;
  bvh_query_ray_t q;
  q.start = start;
  q.inv_dir = ray_inv_dir(dir);
  q.walk = detail::bvh_walk_start();
  return q;
}

WP_LFN bvh_query_ray_t bvh_query_ray_next(const bvh_t& bvh, bvh_query_ray_t q, ctx_t* ctx) {
  const Vec3 o = q.start, inv = q.inv_dir;
  q.walk = detail::bvh_walk_next(
      q.walk, bvh.tree,
      [o, inv](Vec3 l, Vec3 u) {
        f32 t;
        return intersect_ray_aabb(o, inv, l, u, &t);
      },
      [&bvh, o, inv](i32 id, ctx_t*) {
        f32 t;
        return intersect_ray_aabb(o, inv, bvh.lowers[id], bvh.uppers[id], &t);
      },
      ctx);
  return q;
}

WP_LFN bool bvh_query_ray_done(bvh_query_ray_t q) { return q.walk.item < 0; }

WP_LFN i32 bvh_query_ray_item(bvh_query_ray_t q) { return q.walk.item; }

}  // namespace wp

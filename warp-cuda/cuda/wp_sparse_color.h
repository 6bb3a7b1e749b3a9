// wp_sparse_color.h: the sparse tier's graph colouring (warp-runtime's sparse/color.rs and
// sparse/color_steps.rs, cargo feature `sparse`), a build library of its own beside
// wp_sparse.h's and wp_sparse_ops.h's: the adjacency of edges or of constraints sharing a
// particle (fed to wp_sparse.h's triplet pipeline), and Jones-Plassmann colouring rounds.
// Every step here runs the same on the CPU (color_steps.rs, with rayon): integer steps whose
// result does not depend on the order of the threads (each round reads the previous round's
// colours and writes a new array), so the CPU and a GPU give the same colours.
//
// A graph is a symmetric pattern in CSR form: vertex v's neighbours are columns[offsets[v] ..
// offsets[v + 1]], with no self-loop; the neighbour count `sp_nnz` (wp_sparse_ops.h) is
// offsets[n] clamped into [0, cap], each row's range clamped into it (`sp_ops_row`), and a
// column outside [0, n) or equal to v is skipped: an overwritten structure gives meaningless
// colours, never a wild read.
//
// Steps (grid-stride loops; kernels wp_sparse_color_<step>):
//   split     per edge e: its two directed triplets (u, v), (v, u) (`incidence`: the
//             particle-constraint triplets (u, e), (v, e)) and their keep flags (0 for a
//             self-loop or an endpoint outside [0, n)); the smallest bad e lowers bad[0].
//   report    one thread: the smallest bad edge, raised as a fault (out of bounds on argument
//             0 with index [e, endpoint] and shape [m, n]).
//   (the runtime's compaction of the kept triplets, then wp_sparse.h's triplet pipeline)
//   pair_count  per particle r <= n of the incidence pattern: k (k - 1) ordered pairs of
//             its k constraints (i64; 0 at r = n), scanned by the runtime (exclusive).
//   pair_expand per particle: its pairs (a, b), a != b, in the order of its constraints,
//             from starts[r] on (positions past `limit` skipped).
//   round     per vertex: Jones-Plassmann with priorities (sp_color_hash(v ^ seed), v). A
//             vertex coloured in `prev` keeps its colour; an uncoloured one whose priority
//             beats every uncoloured neighbour's takes the smallest colour none of its
//             neighbours has in `prev` (64 colours a window), others stay -1. `clear`:
//             thread 0 zeroes the flag; else a vertex left uncoloured sets it to 1.
//   keys      per vertex: the sort key (its colour) and the vertex.
//   (the runtime's stable radix sort of (colour, vertex))
//   offsets   per sorted position: where each colour's run starts; the last writes `ncolors`.
#pragma once
#include "wp_core.h"
#include "wp_sparse.h"
#include "wp_sparse_ops.h"

namespace wp {

/// The priority hash (Chris Wellons' `lowbias32`): every bit of v moves about half of the
/// result's, so neighbouring vertex ids get unrelated priorities.
WP_FN u32 sp_color_hash(u32 x) {
  x ^= x >> 16;
  x *= 0x7feb352du;
  x ^= x >> 15;
  x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}

/// Whether vertex a's priority (hash(a ^ seed), a) is above b's (a total order).
WP_FN bool sp_color_beats(i32 a, i32 b, u32 seed) {
  const u32 ha = sp_color_hash((u32)a ^ seed), hb = sp_color_hash((u32)b ^ seed);
  return ha > hb || (ha == hb && a > b);
}

#if defined(__CUDACC__)
WP_FN void sp_color_flag(u64 addr, i32 v) { atomicExch((int*)addr, v); }
#else
WP_FN void sp_color_flag(u64 addr, i32 v) { *(i32*)addr = v; }
#endif

/// ColorSplit: edges (i32 pairs), rows, cols, flags (i32*, 2 m each, written), bad (i32[1]),
/// m (edges), n (vertices or particles), incidence (1: the particle-constraint triplets).
struct sp_color_split_t {
  u64 edges, rows, cols, flags, bad;
  i32 m, n, incidence, pad;
};
static_assert(sizeof(sp_color_split_t) == 56, "sp_color_split_t layout");

/// ColorReport: edges, bad (i32[1], INT_MAX for none), m, n; the fault context (argument 0:
/// the edges).
struct sp_color_report_t {
  u64 edges, bad;
  i32 m, n;
  step_fault_t fault;
};
static_assert(sizeof(sp_color_report_t) == 64, "sp_color_report_t layout");

/// ColorPairs: the incidence pattern's offsets, columns, starts (i64*, n + 1: pair_count
/// writes the counts, pair_expand reads their exclusive scan), rows, cols (i32*, written),
/// limit (the triplet arrays' length), n (particles), cap (the pattern's capacity).
struct sp_color_pairs_t {
  u64 offsets, columns, starts, rows, cols;
  i64 limit;
  i32 n, cap;
};
static_assert(sizeof(sp_color_pairs_t) == 56, "sp_color_pairs_t layout");

/// ColorRound: offsets, columns (the graph), prev, next (i32*, n: -1 uncoloured), flag
/// (i32[1]), n, cap, seed, clear.
struct sp_color_round_t {
  u64 offsets, columns, prev, next, flag;
  i32 n, cap;
  u32 seed;
  i32 clear;
};
static_assert(sizeof(sp_color_round_t) == 56, "sp_color_round_t layout");

/// ColorSort: colors, keys (u32*), order (i32*), offsets (i32*, ncolors + 1), n, ncolors
/// (keys: unused).
struct sp_color_sort_t {
  u64 colors, keys, order, offsets;
  i32 n, ncolors;
};
static_assert(sizeof(sp_color_sort_t) == 40, "sp_color_sort_t layout");

WP_FN void sp_color_split(const sp_color_split_t& s, i32 e) {
  const i32 u = ((const i32*)s.edges)[2 * (i64)e], v = ((const i32*)s.edges)[2 * (i64)e + 1];
  const bool ok = u >= 0 && u < s.n && v >= 0 && v < s.n;
  if (!ok) sp_min32(s.bad, e);
  i32* rows = (i32*)s.rows;
  i32* cols = (i32*)s.cols;
  i32* flags = (i32*)s.flags;
  const i64 a = 2 * (i64)e, b = a + 1;
  rows[a] = u;
  rows[b] = v;
  if (s.incidence) {
    cols[a] = e;
    cols[b] = e;
    flags[a] = flags[b] = ok ? 1 : 0;
  } else {
    cols[a] = v;
    cols[b] = u;
    flags[a] = flags[b] = ok && u != v ? 1 : 0;
  }
}

/// The split's report (one thread): out of bounds on the edges, index [e, the first endpoint
/// of e outside [0, n)], shape [m, n].
WP_FN void sp_color_report(const sp_color_report_t& s) {
  const i32 e = *(const i32*)s.bad;
  if (e == 0x7fffffff) return;
  ctx_t ctx = ctx_make(&s.fault.ctx);
  const i32 u = ((const i32*)s.edges)[2 * (i64)e], v = ((const i32*)s.edges)[2 * (i64)e + 1];
  const i32 bad = (u >= 0 && u < s.n) ? v : u;
  const i64 index[2] = {(i64)e, (i64)bad};
  const i64 shape[2] = {(i64)s.m, (i64)s.n};
  raise(&ctx, FAULT_OUT_OF_BOUNDS, 0, 2, index, shape);
}

WP_FN void sp_color_pair_count(const sp_color_pairs_t& s, i32 r) {
  i64 k = 0;
  if (r < s.n) {
    i32 lo, hi;
    sp_ops_row((const i32*)s.offsets, r, sp_nnz((const i32*)s.offsets, s.n, s.cap), &lo, &hi);
    k = (i64)(hi - lo);
  }
  ((i64*)s.starts)[r] = k * (k > 0 ? k - 1 : 0);
}

WP_FN void sp_color_pair_expand(const sp_color_pairs_t& s, i32 r) {
  const i32* cols = (const i32*)s.columns;
  i32 lo, hi;
  sp_ops_row((const i32*)s.offsets, r, sp_nnz((const i32*)s.offsets, s.n, s.cap), &lo, &hi);
  i64 pos = ((const i64*)s.starts)[r];
  for (i32 a = lo; a < hi; ++a)
    for (i32 b = lo; b < hi; ++b) {
      if (a == b) continue;
      if (pos >= 0 && pos < s.limit) {
        ((i32*)s.rows)[pos] = cols[a];
        ((i32*)s.cols)[pos] = cols[b];
      }
      ++pos;
    }
}

WP_FN void sp_color_round(const sp_color_round_t& s, i32 v) {
  const i32* prev = (const i32*)s.prev;
  i32* next = (i32*)s.next;
  if (s.clear && v == 0) sp_color_flag(s.flag, 0);
  if (prev[v] >= 0) {
    next[v] = prev[v];
    return;
  }
  const i32* off = (const i32*)s.offsets;
  const i32* cols = (const i32*)s.columns;
  i32 lo, hi;
  sp_ops_row(off, v, sp_nnz(off, s.n, s.cap), &lo, &hi);
  for (i32 k = lo; k < hi; ++k) {
    const i32 u = cols[k];
    if (u < 0 || u >= s.n || u == v) continue;
    if (prev[u] < 0 && sp_color_beats(u, v, s.seed)) {
      next[v] = -1;
      if (!s.clear) sp_color_flag(s.flag, 1);
      return;
    }
  }
  // The smallest colour no neighbour has, 64 colours a window (at most degree + 1 colours,
  // so the windows end).
  for (i32 base = 0;; base += 64) {
    u64 mask = 0;
    for (i32 k = lo; k < hi; ++k) {
      const i32 u = cols[k];
      if (u < 0 || u >= s.n || u == v) continue;
      const i32 c = prev[u] - base;
      if (c >= 0 && c < 64) mask |= (u64)1 << c;
    }
    if (mask != ~(u64)0) {
      i32 c = 0;
      while (mask & ((u64)1 << c)) ++c;
      next[v] = base + c;
      return;
    }
  }
}

WP_FN void sp_color_keys(const sp_color_sort_t& s, i32 v) {
  ((u32*)s.keys)[v] = (u32)((const i32*)s.colors)[v];
  ((i32*)s.order)[v] = v;
}

WP_FN void sp_color_offsets(const sp_color_sort_t& s, i32 i) {
  const u32* keys = (const u32*)s.keys;
  i32* offsets = (i32*)s.offsets;
  const u32 c = keys[i];
  if ((i == 0 || keys[i - 1] != c) && c < (u32)s.ncolors) offsets[c] = i;
  if (i == s.n - 1) offsets[s.ncolors] = s.n;
}

}  // namespace wp

// ------------------------------------------------------------------------------------------
// The kernels (only in this build library: WP_SPARSE_COLOR_BUILD; WP_SPARSE_EMULATED: as
// host C++ under the block emulator).
// ------------------------------------------------------------------------------------------
#if defined(WP_SPARSE_COLOR_BUILD) && (defined(__CUDACC__) || defined(WP_SPARSE_EMULATED))
#ifndef WP_SP_LOOP
#define WP_SP_LOOP(i, n)                                                                    \
  for (::wp::i64 i = (::wp::i64)blockIdx.x * blockDim.x + threadIdx.x,                      \
                 i##_stride = (::wp::i64)blockDim.x * gridDim.x;                            \
       i < (::wp::i64)(n); i += i##_stride)
#endif

extern "C" __global__ void wp_sparse_color_split(wp::sp_color_split_t s) {
  WP_SP_LOOP(e, s.m) wp::sp_color_split(s, (wp::i32)e);
}
extern "C" __global__ void wp_sparse_color_report(wp::sp_color_report_t s) {
  if (blockIdx.x == 0 && threadIdx.x == 0) wp::sp_color_report(s);
}
extern "C" __global__ void wp_sparse_color_pair_count(wp::sp_color_pairs_t s) {
  WP_SP_LOOP(r, (wp::i64)s.n + 1) wp::sp_color_pair_count(s, (wp::i32)r);
}
extern "C" __global__ void wp_sparse_color_pair_expand(wp::sp_color_pairs_t s) {
  WP_SP_LOOP(r, s.n) wp::sp_color_pair_expand(s, (wp::i32)r);
}
extern "C" __global__ void wp_sparse_color_round(wp::sp_color_round_t s) {
  WP_SP_LOOP(v, s.n) wp::sp_color_round(s, (wp::i32)v);
}
extern "C" __global__ void wp_sparse_color_keys(wp::sp_color_sort_t s) {
  WP_SP_LOOP(v, s.n) wp::sp_color_keys(s, (wp::i32)v);
}
extern "C" __global__ void wp_sparse_color_offsets(wp::sp_color_sort_t s) {
  WP_SP_LOOP(i, s.n) wp::sp_color_offsets(s, (wp::i32)i);
}
#endif

// wp_bsr.h: section "bsr" of the builtin table: block sparse row matrices in kernels (the
// sparse tier's Bsr<B>), the CUDA mirror of warp-core/src/objects/bsr.rs (read that for the
// definitions: row r holds slots offsets[r] .. offsets[r + 1], slot k is block (r, columns[k])
// with value values[k]; nnz = offsets[nrow] clamped into the capacity, each row's range clamped
// into 0..nnz). Every step below is the Rust one in the same order, so both backends visit the
// same slots and find the same indices.
//
//   bsr_t<B>                        a Bsr<B> kernel parameter (warp_runtime's CudaBsr)
//   bsr_row_query_t                 a row iteration's state (warp_core's BsrRowQuery)
//   bsr_nrow(a, ctx), bsr_ncol, bsr_nnz
//   bsr_row(a, r, ctx)              the state before row r's first slot; bsr_row_next(a, q, ctx),
//                                   bsr_row_done(q), bsr_row_item(q)
//   bsr_col(a, k, ctx)              slot k's block column
//   bsr_block(a, k, ctx)            slot k's block (adjoint in wp_adjoint_bsr.h)
//   bsr_set_block(a, k, v, ctx)     writes slot k's block
//   bsr_add_block(a, k, v, ctx)     adds v into slot k's block, an atomicAdd per scalar
//   bsr_block_index(a, r, c, ctx)   the slot of block (r, c), or -1
//   bsr_row_index(a, k, ctx)        the row holding slot k, or -1
//
// A row outside [0, nrow) or a slot outside [0, nnz) is an out-of-bounds fault of the matrix's
// parameter (index [r] against shape [nrow], or [k] against [nnz]); the call then reads and
// writes nothing and gives zero. Blocks are accessed scalar by scalar in memory order (a block
// is its scalars and nothing else), the adds one atomicAdd each.
#pragma once
#include "wp_core.h"
#include "wp_atomic.h"

namespace wp {

/// A block sparse matrix of B blocks (48 bytes, align 8), field for field warp_runtime's
/// `CudaBsr`: 0 offsets (nrow + 1 row starts), 8 columns, 16 values, 24 grad (the values'
/// gradient, null for none), 32 nrow, 36 ncol, 40 cap (elements of columns, values, grad),
/// 44 arg (the parameter's index, for faults).
template <typename B>
struct bsr_t {
  const i32* offsets;
  const i32* columns;
  B* values;
  B* grad;
  i32 nrow;
  i32 ncol;
  i32 cap;
  i32 arg;
  /// Marks a kernel object for the adjoint library (zero value, no gradient).
  typedef void wp_object_tag;
};
static_assert(sizeof(bsr_t<f32>) == 48 && alignof(bsr_t<f32>) == 8, "bsr_t layout");

/// A row iteration's state (8 bytes, warp_core's BsrRowQuery): the current slot (one before the
/// row's first until the first step) and the row's end.
struct bsr_row_query_t {
  i32 cur;
  i32 end;
  typedef void wp_object_tag;
};
static_assert(sizeof(bsr_row_query_t) == 8, "bsr_row_query_t layout");

namespace detail {
/// A block's scalar and scalar count: f32 and f64 are their own single scalar; the matrices'
/// come from vec_traits (glam's in wp_core.h, the non-square ones in wp_matrix.h).
template <typename B>
struct bsr_block_of {
  typedef typename vec_traits<B>::scalar S;
  static constexpr int N = vec_traits<B>::N;
};
template <>
struct bsr_block_of<f32> {
  typedef f32 S;
  static constexpr int N = 1;
};
template <>
struct bsr_block_of<f64> {
  typedef f64 S;
  static constexpr int N = 1;
};

/// The offsets as a checked view reporting the matrix's parameter (for view_check's fault).
template <typename B>
WP_FN array_t<i32, 1> bsr_offsets(const bsr_t<B>& a) {
  array_t<i32, 1> v;
  v.data = const_cast<i32*>(a.offsets);
  v.shape[0] = (i64)a.nrow + 1;
  v.strides[0] = (i64)sizeof(i32);
  v.arg = a.arg;
  v.pad = 0;
  return v;
}

WP_LFN i32 bsr_clamp(i32 x, i32 lo, i32 hi) { return x < lo ? lo : (x > hi ? hi : x); }

template <typename B>
WP_FN i32 bsr_nnz_of(const bsr_t<B>& a) {
  return bsr_clamp(a.offsets[a.nrow], 0, a.cap);
}

/// Whether r is a row; if not, the fault.
template <typename B>
WP_FN bool bsr_row_ok(const bsr_t<B>& a, i32 r, ctx_t* ctx) {
  if ((u32)r < (u32)a.nrow) return true;
  view_check(bsr_offsets(a), (i64)r, (usize)a.nrow, false, ctx);
  return false;
}

/// Whether k is a slot; if not, the fault.
template <typename B>
WP_FN bool bsr_slot_ok(const bsr_t<B>& a, i32 k, ctx_t* ctx) {
  const i32 nnz = bsr_nnz_of(a);
  if ((u32)k < (u32)nnz) return true;
  view_check(bsr_offsets(a), (i64)k, (usize)nnz, false, ctx);
  return false;
}

/// Row r's slots [start, end), clamped: 0 <= start <= end <= nnz.
template <typename B>
WP_FN void bsr_range(const bsr_t<B>& a, i32 r, i32* start, i32* end) {
  const i32 nnz = bsr_nnz_of(a);
  *start = bsr_clamp(a.offsets[r], 0, nnz);
  *end = bsr_clamp(a.offsets[r + 1], *start, nnz);
}

/// *p, scalar by scalar (volatile loads: every scalar read once, in memory order).
template <typename B>
WP_FN B bsr_load(const B* p) {
  typedef typename bsr_block_of<B>::S S;
  B out;
  S* o = (S*)&out;
  const volatile S* s = (const volatile S*)p;
  for (int i = 0; i < bsr_block_of<B>::N; ++i) o[i] = s[i];
  return out;
}

template <typename B>
WP_FN void bsr_store(B* p, const B& v) {
  typedef typename bsr_block_of<B>::S S;
  const S* s = (const S*)&v;
  volatile S* d = (volatile S*)p;
  for (int i = 0; i < bsr_block_of<B>::N; ++i) d[i] = s[i];
}

template <typename B>
WP_FN void bsr_add(B* p, const B& v) {
  typedef typename bsr_block_of<B>::S S;
  const S* s = (const S*)&v;
  S* d = (S*)p;
  for (int i = 0; i < bsr_block_of<B>::N; ++i) atomic_add_p(d + i, s[i]);
}
}  // namespace detail

template <typename B>
WP_FN i32 bsr_nrow(const bsr_t<B>& a, ctx_t* ctx) {
  (void)ctx;
  return a.nrow;
}

template <typename B>
WP_FN i32 bsr_ncol(const bsr_t<B>& a, ctx_t* ctx) {
  (void)ctx;
  return a.ncol;
}

template <typename B>
WP_FN i32 bsr_nnz(const bsr_t<B>& a, ctx_t* ctx) {
  (void)ctx;
  return detail::bsr_nnz_of(a);
}

template <typename B>
WP_FN bsr_row_query_t bsr_row(const bsr_t<B>& a, i32 r, ctx_t* ctx) {
  bsr_row_query_t q{};
  if (!detail::bsr_row_ok(a, r, ctx)) return q;
  i32 start, end;
  detail::bsr_range(a, r, &start, &end);
  q.cur = start - 1;
  q.end = end;
  return q;
}

template <typename B>
WP_FN bsr_row_query_t bsr_row_next(const bsr_t<B>& a, bsr_row_query_t q, ctx_t* ctx) {
  (void)a;
  (void)ctx;
  const i32 next = q.cur == 0x7fffffff ? q.cur : q.cur + 1;
  q.cur = next < q.end ? next : q.end;
  return q;
}

WP_LFN bool bsr_row_done(bsr_row_query_t q) { return q.cur >= q.end; }
WP_LFN i32 bsr_row_item(bsr_row_query_t q) { return q.cur; }

template <typename B>
WP_FN i32 bsr_col(const bsr_t<B>& a, i32 k, ctx_t* ctx) {
  if (!detail::bsr_slot_ok(a, k, ctx)) return 0;
  return a.columns[k];
}

template <typename B>
WP_FN B bsr_block(const bsr_t<B>& a, i32 k, ctx_t* ctx) {
  if (!detail::bsr_slot_ok(a, k, ctx)) return B{};
  return detail::bsr_load(a.values + k);
}

template <typename B>
WP_FN void bsr_set_block(const bsr_t<B>& a, i32 k, const typename identity<B>::type& v,
                         ctx_t* ctx) {
  if (detail::bsr_slot_ok(a, k, ctx)) detail::bsr_store(a.values + k, v);
}

template <typename B>
WP_FN void bsr_add_block(const bsr_t<B>& a, i32 k, const typename identity<B>::type& v,
                         ctx_t* ctx) {
  if (detail::bsr_slot_ok(a, k, ctx)) detail::bsr_add(a.values + k, v);
}

template <typename B>
WP_FN i32 bsr_block_index(const bsr_t<B>& a, i32 r, i32 c, ctx_t* ctx) {
  if (!detail::bsr_row_ok(a, r, ctx)) return 0;
  if (c < 0 || c >= a.ncol) return -1;
  i32 lo, end;
  detail::bsr_range(a, r, &lo, &end);
  i32 hi = end;
  while (lo < hi) {
    const i32 mid = lo + (hi - lo) / 2;
    if (a.columns[mid] < c) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  return lo < end && a.columns[lo] == c ? lo : -1;
}

template <typename B>
WP_FN i32 bsr_row_index(const bsr_t<B>& a, i32 k, ctx_t* ctx) {
  if (!detail::bsr_slot_ok(a, k, ctx)) return 0;
  i32 lo = 0, hi = a.nrow;
  while (lo < hi) {
    const i32 mid = lo + (hi - lo) / 2;
    if (a.offsets[mid + 1] <= k) {
      lo = mid + 1;
    } else {
      hi = mid;
    }
  }
  return lo < a.nrow ? lo : -1;
}

}  // namespace wp

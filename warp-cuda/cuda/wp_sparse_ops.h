// wp_sparse_ops.h: the sparse tier's structure operations (warp-runtime's sparse/ops.rs and
// sparse/ops_steps.rs, cargo feature `sparse`), a build library of its own beside
// wp_sparse.h's: scaling, the block diagonal (read and set), dense matrices both ways, the
// transpose, and the expansions that `axpy` and `mm` feed to wp_sparse.h's triplet pipeline.
// Every step here runs the same on the CPU (ops_steps.rs, with rayon) and gives the same bits:
// the float operations are spelled with wp_sparse.h's `sp_*` helpers (rounded intrinsics on a
// GPU, never contracted), in the Rust code's order; the others move scalars unchanged.
//
// Matrices as in wp_sparse.h. The block shape is a field of each record (rows R, cols C, the
// layout `cm`: entry (i, j) at j R + i when column-major, i C + j otherwise), so every step is
// instantiated once per scalar type (f32, f64; kernels wp_sparse_ops_<step>_<f32|f64>) or once
// (the integer steps, wp_sparse_ops_<step>), for every block type at once. A matrix's block
// count is `sp_nnz`: offsets[nrow] when it is in [0, cap], else 0 (the primitives' rule for a
// device count, which the transpose's sort reads from the same word).
//
// Steps (grid-stride loops):
//   scale         per stored scalar: v = alpha v.
//   diag          per i < min(nrow, ncol): out[i] = block (i, i), or zeros.
//   set_diag      per block row r <= nrow: the block diagonal matrix of d (or the identity).
//   to_dense      per scalar row: the row of the dense row-major matrix.
//   dense_flags   per block of a dense matrix: 1 if any scalar is nonzero (NaN included),
//                 and the smallest dense row holding a non-finite scalar (bad).
//   dense_report  one thread: the first non-finite scalar in row-major order, as a fault.
//   dense_gather  per kept block (after the runtime's scan of the flags): row, column, block.
//   row_keys      per block row: each stored block's row, its column as a sort key, its index.
//   (the runtime's stable radix sort by column: row order kept within a column)
//   transpose     per sorted block: the transposed block, its column (the old row); and per
//                 column c <= ncol the new offsets (lower bound of c in the sorted keys).
//   to_triplets   per block row: each stored block as a triplet (row, col, factor x block)
//                 after `base` earlier triplets; the block count plus base into `count_out`.
//   mm_count      per block row of A: the products A_rk B_kc of the row (i64).
//   (the runtime's exclusive scan of the counts: each row's first product)
//   mm_total      one thread: the product count as an i32 count (saturated).
//   mm_expand     per block row of A: its products as triplets (r, c, alpha A_rk B_kc), in
//                 the order of A's blocks, then B's: the order the pipeline sums them in.
#pragma once
#include "wp_core.h"
#include "wp_sparse.h"

namespace wp {

/// A matrix's block count: offsets[nrow] if it is in [0, cap], else 0.
WP_FN i32 sp_nnz(const i32* offsets, i32 nrow, i32 cap) {
  const i32 c = offsets[nrow];
  return (c < 0 || c > cap) ? 0 : c;
}

/// Block row r's blocks [*lo, *hi), clamped into [0, nnz] (wp_sparse.h's `sp_row_range`
/// with the block count of `sp_nnz`).
WP_FN void sp_ops_row(const i32* offsets, i32 r, i32 nnz, i32* lo, i32* hi) {
  i32 a = offsets[r], b = offsets[r + 1];
  a = a < 0 ? 0 : (a > nnz ? nnz : a);
  b = b < a ? a : (b > nnz ? nnz : b);
  *lo = a;
  *hi = b;
}

/// Entry (i, j)'s scalar in a block of `rows` x `cols`, column-major when `cm`.
WP_FN i32 sp_ops_at(i32 i, i32 j, i32 rows, i32 cols, i32 cm) {
  return cm ? j * rows + i : i * cols + j;
}

/// Scale: offsets (for the count), values (S*), alpha (rounded to S), nrow, cap, block (R C).
struct sp_ops_scale_t {
  u64 offsets, values;
  f64 alpha;
  i32 nrow, cap, block, pad;
};
static_assert(sizeof(sp_ops_scale_t) == 40, "sp_ops_scale_t layout");

/// Diag: offsets, columns, values, out (S*, R C per diagonal block), nrow, ncol, cap, block.
struct sp_ops_diag_t {
  u64 offsets, columns, values, out;
  i32 nrow, ncol, cap, block;
};
static_assert(sizeof(sp_ops_diag_t) == 48, "sp_ops_diag_t layout");

/// SetDiag: offsets (nrow + 1), columns, values (n blocks each, written), d (S*, n blocks, or 0
/// for the identity), nrow, n = min(nrow, ncol), dim (R = C), block (R C).
struct sp_ops_set_diag_t {
  u64 offsets, columns, values, d;
  i32 nrow, n, dim, block;
};
static_assert(sizeof(sp_ops_set_diag_t) == 48, "sp_ops_set_diag_t layout");

/// ToDense: offsets, columns, values, out (S*, nrow R x ncol C row-major), nrow, ncol, cap,
/// rows (R), cols (C), cm.
struct sp_ops_to_dense_t {
  u64 offsets, columns, values, out;
  i32 nrow, ncol, cap, rows, cols, cm;
};
static_assert(sizeof(sp_ops_to_dense_t) == 56, "sp_ops_to_dense_t layout");

/// DenseFlags / DenseGather: dense (S*, nrow R x ncol C row-major), pos (i32*, a block's flag,
/// then its inclusive scan), bad (i32*: the smallest dense row with a non-finite scalar),
/// block_rows, columns, values (the kept blocks, written by the gather), nrow, ncol, rows,
/// cols, cm.
struct sp_ops_dense_t {
  u64 dense, pos, bad, block_rows, columns, values;
  i32 nrow, ncol, rows, cols, cm, pad;
};
static_assert(sizeof(sp_ops_dense_t) == 72, "sp_ops_dense_t layout");

/// DenseReport: dense, bad (as above), width (ncol C), the fault context (argument 0: `a`).
struct sp_ops_dense_report_t {
  u64 dense, bad;
  i64 width;
  step_fault_t fault;
};
static_assert(sizeof(sp_ops_dense_report_t) == 64, "sp_ops_dense_report_t layout");

/// RowKeys: offsets, columns, block_rows, keys (u32*), idx (i32*) (each written per stored
/// block), nrow, ncol, cap.
struct sp_ops_row_keys_t {
  u64 offsets, columns, block_rows, keys, idx;
  i32 nrow, ncol, cap, pad;
};
static_assert(sizeof(sp_ops_row_keys_t) == 56, "sp_ops_row_keys_t layout");

/// Transpose: offsets (A's, for the count), block_rows, keys, idx (sorted by key), values
/// (A's), out_offsets (ncol + 1), out_columns, out_values, nrow, ncol, cap, rows (A's R),
/// cols (A's C), cm (A's layout), cm_t (the transpose's), pad.
struct sp_ops_transpose_t {
  u64 offsets, block_rows, keys, idx, values, out_offsets, out_columns, out_values;
  i32 nrow, ncol, cap, rows, cols, cm, cm_t, pad;
};
static_assert(sizeof(sp_ops_transpose_t) == 96, "sp_ops_transpose_t layout");

/// ToTriplets: offsets, columns, values (a matrix), base (i32*: the triplets before these, or
/// 0 for none), rows, cols, vals (the triplet arrays), count_out (i32*: base + the block count,
/// written by thread 0), factor (rounded to S), nrow, cap, block, limit (the triplet arrays'
/// length: nothing is written at or past it).
struct sp_ops_to_triplets_t {
  u64 offsets, columns, values, base, rows, cols, vals, count_out;
  f64 factor;
  i32 nrow, cap, block, limit;
};
static_assert(sizeof(sp_ops_to_triplets_t) == 88, "sp_ops_to_triplets_t layout");

/// MmCount: A's offsets and columns, B's offsets, counts (i64*, a_nrow + 1: the last 0),
/// a_nrow, a_cap, b_nrow, b_cap.
struct sp_ops_mm_count_t {
  u64 a_offsets, a_columns, b_offsets, counts;
  i32 a_nrow, a_cap, b_nrow, b_cap;
};
static_assert(sizeof(sp_ops_mm_count_t) == 48, "sp_ops_mm_count_t layout");

/// MmTotal: starts (i64*, the exclusive scan: entry a_nrow is the total), count (i32*,
/// written: the total, or INT_MAX when it does not fit), a_nrow.
struct sp_ops_mm_total_t {
  u64 starts, count;
  i32 a_nrow, pad;
};
static_assert(sizeof(sp_ops_mm_total_t) == 24, "sp_ops_mm_total_t layout");

/// MmExpand: A's offsets, columns, values, B's, starts (i64*), the triplet arrays rows, cols,
/// vals, alpha, limit (their length), a_nrow, a_cap, b_nrow, b_cap, r (A's block rows: C's),
/// k (the inner dimension), c (B's block cols: C's), cm_a, cm_b, cm_c (the layouts of A's, B's
/// and C's blocks).
struct sp_ops_mm_expand_t {
  u64 a_offsets, a_columns, a_values, b_offsets, b_columns, b_values, starts, rows, cols, vals;
  f64 alpha;
  i64 limit;
  i32 a_nrow, a_cap, b_nrow, b_cap, r, k, c, cm_a, cm_b, cm_c;
};
static_assert(sizeof(sp_ops_mm_expand_t) == 136, "sp_ops_mm_expand_t layout");

// ------------------------------------------------------------------------------------------
// Per-element steps
// ------------------------------------------------------------------------------------------

template <typename S>
WP_FN void sp_ops_scale(const sp_ops_scale_t& s, i64 i) {
  const i32 nnz = sp_nnz((const i32*)s.offsets, s.nrow, s.cap);
  if (i >= (i64)nnz * s.block) return;
  S* v = (S*)s.values;
  v[i] = sp_mul((S)s.alpha, v[i]);
}

/// The stored block of row r at column c, or -1 (a binary search of the row's ascending
/// columns).
WP_FN i32 sp_ops_find(const i32* offsets, const i32* columns, i32 nnz, i32 r, i32 c) {
  i32 lo, end;
  sp_ops_row(offsets, r, nnz, &lo, &end);
  i32 hi = end;
  while (lo < hi) {
    const i32 mid = lo + (hi - lo) / 2;
    if (columns[mid] < c)
      lo = mid + 1;
    else
      hi = mid;
  }
  return (lo < end && columns[lo] == c) ? lo : -1;
}

template <typename S>
WP_FN void sp_ops_diag(const sp_ops_diag_t& s, i32 i) {
  const i32* offsets = (const i32*)s.offsets;
  const i32 nnz = sp_nnz(offsets, s.nrow, s.cap);
  const i32 k = sp_ops_find(offsets, (const i32*)s.columns, nnz, i, i);
  S* out = (S*)s.out + (i64)i * s.block;
  for (i32 e = 0; e < s.block; ++e) out[e] = k < 0 ? (S)0 : ((const S*)s.values)[(i64)k * s.block + e];
}

template <typename S>
WP_FN void sp_ops_set_diag(const sp_ops_set_diag_t& s, i32 r) {
  ((i32*)s.offsets)[r] = r < s.n ? r : s.n;
  if (r >= s.n) return;
  ((i32*)s.columns)[r] = r;
  S* out = (S*)s.values + (i64)r * s.block;
  // The identity's entry (i, i) is scalar i (R + 1) in either layout.
  for (i32 e = 0; e < s.block; ++e)
    out[e] = s.d ? ((const S*)s.d)[(i64)r * s.block + e] : (e % (s.dim + 1) == 0 ? (S)1 : (S)0);
}

template <typename S>
WP_FN void sp_ops_to_dense(const sp_ops_to_dense_t& s, i64 i) {
  const i32* offsets = (const i32*)s.offsets;
  const i32* columns = (const i32*)s.columns;
  const S* values = (const S*)s.values;
  const i64 width = (i64)s.ncol * s.cols;
  S* row = (S*)s.out + i * width;
  for (i64 j = 0; j < width; ++j) row[j] = (S)0;
  const i32 r = (i32)(i / s.rows), ii = (i32)(i % s.rows);
  const i32 nnz = sp_nnz(offsets, s.nrow, s.cap);
  i32 lo, hi;
  sp_ops_row(offsets, r, nnz, &lo, &hi);
  for (i32 k = lo; k < hi; ++k) {
    const i32 c = columns[k];
    if (c < 0 || c >= s.ncol) continue;  // (never in an assembled matrix)
    const S* b = values + (i64)k * s.rows * s.cols;
    for (i32 j = 0; j < s.cols; ++j) row[(i64)c * s.cols + j] = b[sp_ops_at(ii, j, s.rows, s.cols, s.cm)];
  }
}

template <typename S>
WP_FN void sp_ops_dense_flags(const sp_ops_dense_t& s, i64 b) {
  const i32 br = (i32)(b / s.ncol), bc = (i32)(b % s.ncol);
  const i64 width = (i64)s.ncol * s.cols;
  const S* dense = (const S*)s.dense;
  i32 flag = 0;
  for (i32 i = 0; i < s.rows; ++i) {
    const i64 row = (i64)br * s.rows + i;
    bool finite = true;
    for (i32 j = 0; j < s.cols; ++j) {
      const S x = dense[row * width + (i64)bc * s.cols + j];
      flag |= x != (S)0;
      finite = finite && sp_finite(x);
    }
    if (!finite) sp_min32(s.bad, (i32)row);
  }
  ((i32*)s.pos)[b] = flag;
}

template <typename S>
WP_FN void sp_ops_dense_report(const sp_ops_dense_report_t& s) {
  const i32 row = *(const i32*)s.bad;
  if (row == 0x7fffffff) return;
  const S* r = (const S*)s.dense + (i64)row * s.width;
  for (i64 j = 0; j < s.width; ++j)
    if (!sp_finite(r[j])) {
      ctx_t ctx = ctx_make(&s.fault.ctx);
      const i64 index[2] = {(i64)row * s.width + j, (i64)f64_to_bits((f64)r[j])};
      raise(&ctx, FAULT_NON_FINITE_INPUT, 0, 2, index, nullptr);
      return;
    }
}

template <typename S>
WP_FN void sp_ops_dense_gather(const sp_ops_dense_t& s, i64 b) {
  const i32* pos = (const i32*)s.pos;
  if (pos[b] - (b > 0 ? pos[b - 1] : 0) != 1) return;
  const i32 k = pos[b] - 1;
  const i32 br = (i32)(b / s.ncol), bc = (i32)(b % s.ncol);
  ((i32*)s.block_rows)[k] = br;
  ((i32*)s.columns)[k] = bc;
  const i64 width = (i64)s.ncol * s.cols;
  const S* dense = (const S*)s.dense;
  S* out = (S*)s.values + (i64)k * s.rows * s.cols;
  for (i32 i = 0; i < s.rows; ++i)
    for (i32 j = 0; j < s.cols; ++j)
      out[sp_ops_at(i, j, s.rows, s.cols, s.cm)] =
          dense[((i64)br * s.rows + i) * width + (i64)bc * s.cols + j];
}

WP_FN void sp_ops_row_keys(const sp_ops_row_keys_t& s, i32 r) {
  const i32* offsets = (const i32*)s.offsets;
  const i32* columns = (const i32*)s.columns;
  const i32 nnz = sp_nnz(offsets, s.nrow, s.cap);
  i32 lo, hi;
  sp_ops_row(offsets, r, nnz, &lo, &hi);
  for (i32 k = lo; k < hi; ++k) {
    const i32 c = columns[k];
    ((i32*)s.block_rows)[k] = r;
    // A column out of range (never in an assembled matrix) sorts last, past every column.
    ((u32*)s.keys)[k] = (c < 0 || c >= s.ncol) ? (u32)s.ncol : (u32)c;
    ((i32*)s.idx)[k] = k;
  }
}

template <typename S>
WP_FN void sp_ops_transpose(const sp_ops_transpose_t& s, i32 t) {
  const i32 nnz = sp_nnz((const i32*)s.offsets, s.nrow, s.cap);
  const u32* keys = (const u32*)s.keys;
  if (t < nnz) {
    const i32 k = ((const i32*)s.idx)[t];
    ((i32*)s.out_columns)[t] = ((const i32*)s.block_rows)[k];
    const S* a = (const S*)s.values + (i64)k * s.rows * s.cols;
    S* o = (S*)s.out_values + (i64)t * s.rows * s.cols;
    // Entry (j, i) of the cols x rows transpose is entry (i, j) of the block.
    for (i32 i = 0; i < s.rows; ++i)
      for (i32 j = 0; j < s.cols; ++j)
        o[sp_ops_at(j, i, s.cols, s.rows, s.cm_t)] = a[sp_ops_at(i, j, s.rows, s.cols, s.cm)];
  }
  if (t <= s.ncol) {
    i32 lo = 0, hi = nnz;  // the first sorted block whose column is >= t
    while (lo < hi) {
      const i32 mid = lo + (hi - lo) / 2;
      if (keys[mid] < (u32)t)
        lo = mid + 1;
      else
        hi = mid;
    }
    ((i32*)s.out_offsets)[t] = lo;
  }
}

template <typename S>
WP_FN void sp_ops_to_triplets(const sp_ops_to_triplets_t& s, i32 r) {
  const i32* offsets = (const i32*)s.offsets;
  const i32 nnz = sp_nnz(offsets, s.nrow, s.cap);
  const i32 base = s.base ? *(const i32*)s.base : 0;
  if (r == 0 && s.count_out) {
    // base + nnz, saturated (a count past the arrays is the pipeline's fault).
    const i64 total = (i64)base + nnz;
    *(i32*)s.count_out = total > 0x7fffffff ? 0x7fffffff : (i32)total;
  }
  i32 lo, hi;
  sp_ops_row(offsets, r, nnz, &lo, &hi);
  const S f = (S)s.factor;
  for (i32 k = lo; k < hi; ++k) {
    const i64 t = (i64)base + k;
    if (t < 0 || t >= s.limit) continue;
    ((i32*)s.rows)[t] = r;
    ((i32*)s.cols)[t] = ((const i32*)s.columns)[k];
    const S* v = (const S*)s.values + (i64)k * s.block;
    S* o = (S*)s.vals + t * s.block;
    for (i32 e = 0; e < s.block; ++e) o[e] = sp_mul(f, v[e]);
  }
}

WP_FN void sp_ops_mm_count(const sp_ops_mm_count_t& s, i32 r) {
  i64* counts = (i64*)s.counts;
  if (r == s.a_nrow) {
    counts[r] = 0;
    return;
  }
  const i32* ao = (const i32*)s.a_offsets;
  const i32* ac = (const i32*)s.a_columns;
  const i32* bo = (const i32*)s.b_offsets;
  const i32 annz = sp_nnz(ao, s.a_nrow, s.a_cap), bnnz = sp_nnz(bo, s.b_nrow, s.b_cap);
  i64 n = 0;
  i32 lo, hi;
  sp_ops_row(ao, r, annz, &lo, &hi);
  for (i32 k = lo; k < hi; ++k) {
    const i32 c = ac[k];
    if (c < 0 || c >= s.b_nrow) continue;  // (never in an assembled matrix)
    i32 blo, bhi;
    sp_ops_row(bo, c, bnnz, &blo, &bhi);
    n += bhi - blo;
  }
  counts[r] = n;
}

WP_FN void sp_ops_mm_total(const sp_ops_mm_total_t& s) {
  const i64 total = ((const i64*)s.starts)[s.a_nrow];
  *(i32*)s.count = total > 0x7fffffff ? 0x7fffffff : (i32)total;
}

template <typename S>
WP_FN void sp_ops_mm_expand(const sp_ops_mm_expand_t& s, i32 r) {
  const i32* ao = (const i32*)s.a_offsets;
  const i32* ac = (const i32*)s.a_columns;
  const i32* bo = (const i32*)s.b_offsets;
  const i32* bc = (const i32*)s.b_columns;
  const S* av = (const S*)s.a_values;
  const S* bv = (const S*)s.b_values;
  const i32 annz = sp_nnz(ao, s.a_nrow, s.a_cap), bnnz = sp_nnz(bo, s.b_nrow, s.b_cap);
  const S alpha = (S)s.alpha;
  i64 t = ((const i64*)s.starts)[r];
  i32 lo, hi;
  sp_ops_row(ao, r, annz, &lo, &hi);
  for (i32 k = lo; k < hi; ++k) {
    const i32 c = ac[k];
    if (c < 0 || c >= s.b_nrow) continue;  // (as mm_count)
    const S* a = av + (i64)k * s.r * s.k;
    i32 blo, bhi;
    sp_ops_row(bo, c, bnnz, &blo, &bhi);
    for (i32 l = blo; l < bhi; ++l, ++t) {
      if (t >= s.limit) return;  // more products than room: the pipeline's count faults
      ((i32*)s.rows)[t] = r;
      ((i32*)s.cols)[t] = bc[l];
      const S* b = bv + (i64)l * s.k * s.c;
      S* o = (S*)s.vals + t * s.r * s.c;
      for (i32 i = 0; i < s.r; ++i)
        for (i32 j = 0; j < s.c; ++j) {
          S acc = (S)0;
          for (i32 m = 0; m < s.k; ++m)
            acc = sp_add(acc, sp_mul(a[sp_ops_at(i, m, s.r, s.k, s.cm_a)],
                                     b[sp_ops_at(m, j, s.k, s.c, s.cm_b)]));
          o[sp_ops_at(i, j, s.r, s.c, s.cm_c)] = sp_mul(alpha, acc);
        }
    }
  }
}

}  // namespace wp

// ------------------------------------------------------------------------------------------
// The kernels (only in this build library: WP_SPARSE_OPS_BUILD; WP_SPARSE_EMULATED: as host
// C++ under the block emulator, tests/cuda_sparse_host.rs). WP_SP_LOOP is wp_sparse.h's when
// its build is on too (the emulator compiles both), else defined here.
// ------------------------------------------------------------------------------------------
#if defined(WP_SPARSE_OPS_BUILD) && (defined(__CUDACC__) || defined(WP_SPARSE_EMULATED))
#ifndef WP_SP_LOOP
#define WP_SP_LOOP(i, n)                                                                    \
  for (::wp::i64 i = (::wp::i64)blockIdx.x * blockDim.x + threadIdx.x,                      \
                 i##_stride = (::wp::i64)blockDim.x * gridDim.x;                            \
       i < (::wp::i64)(n); i += i##_stride)
#endif

#define WP_SP_OPS_KERNELS(tag, S)                                                           \
  extern "C" __global__ void wp_sparse_ops_scale_##tag(wp::sp_ops_scale_t s) {              \
    WP_SP_LOOP(i, (wp::i64)s.cap * s.block) wp::sp_ops_scale<S>(s, i);                      \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_diag_##tag(wp::sp_ops_diag_t s) {                \
    WP_SP_LOOP(i, s.nrow < s.ncol ? s.nrow : s.ncol) wp::sp_ops_diag<S>(s, (wp::i32)i);     \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_set_diag_##tag(wp::sp_ops_set_diag_t s) {        \
    WP_SP_LOOP(r, (wp::i64)s.nrow + 1) wp::sp_ops_set_diag<S>(s, (wp::i32)r);               \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_to_dense_##tag(wp::sp_ops_to_dense_t s) {        \
    WP_SP_LOOP(i, (wp::i64)s.nrow * s.rows) wp::sp_ops_to_dense<S>(s, i);                   \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_dense_flags_##tag(wp::sp_ops_dense_t s) {        \
    WP_SP_LOOP(b, (wp::i64)s.nrow * s.ncol) wp::sp_ops_dense_flags<S>(s, b);                \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_dense_report_##tag(wp::sp_ops_dense_report_t s) { \
    if (blockIdx.x == 0 && threadIdx.x == 0) wp::sp_ops_dense_report<S>(s);                 \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_dense_gather_##tag(wp::sp_ops_dense_t s) {       \
    WP_SP_LOOP(b, (wp::i64)s.nrow * s.ncol) wp::sp_ops_dense_gather<S>(s, b);               \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_transpose_##tag(wp::sp_ops_transpose_t s) {      \
    WP_SP_LOOP(t, (s.cap > s.ncol ? (wp::i64)s.cap : (wp::i64)s.ncol + 1))                  \
    wp::sp_ops_transpose<S>(s, (wp::i32)t);                                                 \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_to_triplets_##tag(wp::sp_ops_to_triplets_t s) {  \
    WP_SP_LOOP(r, s.nrow) wp::sp_ops_to_triplets<S>(s, (wp::i32)r);                         \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_ops_mm_expand_##tag(wp::sp_ops_mm_expand_t s) {      \
    WP_SP_LOOP(r, s.a_nrow) wp::sp_ops_mm_expand<S>(s, (wp::i32)r);                         \
  }

WP_SP_OPS_KERNELS(f32, wp::f32)
WP_SP_OPS_KERNELS(f64, wp::f64)

// `y = alpha A x + beta y` of the rectangular blocks (warp-core's row-major Mat23 .. Mat64),
// wp_sparse.h's step instantiated here, named as it names the square blocks' (the runtime's
// BsrMv picks this library for them).
#define WP_SP_OPS_MV(tag, S, R, C)                                                          \
  extern "C" __global__ void wp_sparse_bsr_mv_##tag(wp::sp_bsr_mv_t s) {                    \
    if (s.lanes > 1) {                                                                      \
      wp::sp_bsr_mv_lanes<S, R, C, false>(s);                                               \
      return;                                                                               \
    }                                                                                       \
    WP_SP_LOOP(t, (wp::i64)s.nrow * R)                                                      \
    wp::sp_bsr_mv_sub<S, R, C, false>(s, (wp::i32)(t / R), (wp::i32)(t % R));              \
  }
WP_SP_OPS_MV(mat23, wp::f32, 2, 3)
WP_SP_OPS_MV(mat24, wp::f32, 2, 4)
WP_SP_OPS_MV(mat26, wp::f32, 2, 6)
WP_SP_OPS_MV(mat32, wp::f32, 3, 2)
WP_SP_OPS_MV(mat34, wp::f32, 3, 4)
WP_SP_OPS_MV(mat36, wp::f32, 3, 6)
WP_SP_OPS_MV(mat42, wp::f32, 4, 2)
WP_SP_OPS_MV(mat43, wp::f32, 4, 3)
WP_SP_OPS_MV(mat46, wp::f32, 4, 6)
WP_SP_OPS_MV(mat62, wp::f32, 6, 2)
WP_SP_OPS_MV(mat63, wp::f32, 6, 3)
WP_SP_OPS_MV(mat64, wp::f32, 6, 4)
WP_SP_OPS_MV(dmat23, wp::f64, 2, 3)
WP_SP_OPS_MV(dmat24, wp::f64, 2, 4)
WP_SP_OPS_MV(dmat26, wp::f64, 2, 6)
WP_SP_OPS_MV(dmat32, wp::f64, 3, 2)
WP_SP_OPS_MV(dmat34, wp::f64, 3, 4)
WP_SP_OPS_MV(dmat36, wp::f64, 3, 6)
WP_SP_OPS_MV(dmat42, wp::f64, 4, 2)
WP_SP_OPS_MV(dmat43, wp::f64, 4, 3)
WP_SP_OPS_MV(dmat46, wp::f64, 4, 6)
WP_SP_OPS_MV(dmat62, wp::f64, 6, 2)
WP_SP_OPS_MV(dmat63, wp::f64, 6, 3)
WP_SP_OPS_MV(dmat64, wp::f64, 6, 4)

extern "C" __global__ void wp_sparse_ops_row_keys(wp::sp_ops_row_keys_t s) {
  WP_SP_LOOP(r, s.nrow) wp::sp_ops_row_keys(s, (wp::i32)r);
}
extern "C" __global__ void wp_sparse_ops_mm_count(wp::sp_ops_mm_count_t s) {
  WP_SP_LOOP(r, (wp::i64)s.a_nrow + 1) wp::sp_ops_mm_count(s, (wp::i32)r);
}
extern "C" __global__ void wp_sparse_ops_mm_total(wp::sp_ops_mm_total_t s) {
  if (blockIdx.x == 0 && threadIdx.x == 0) wp::sp_ops_mm_total(s);
}
#endif

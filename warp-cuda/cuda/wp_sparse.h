// wp_sparse.h: the sparse tier's device steps (warp-runtime's `sparse` module, cargo feature
// `sparse`): block sparse row (BSR) assembly from triplets, y = alpha A x + beta y, the dot
// product with a fixed reduction tree, the Jacobi preconditioner and the conjugate gradient
// updates. warp-runtime's sparse/steps.rs runs the same steps on the CPU with rayon; both give
// the same bits. The integer steps are exact, and every float operation below is spelled with
// the `sp_*` helpers (`__fadd_rn`, `__fmul_rn`, ... on a GPU: never contracted into an FMA,
// whatever `--fmad` says), in the Rust code's order.
//
// Matrices: `nrow` x `ncol` blocks of R x C scalars S (float or double); block row r holds
// blocks offsets[r] .. offsets[r + 1] (i32), block k in column columns[k], its scalars at
// values + k R C, entry (i, j) at j R + i when the block is column-major (glam's matrices) and
// i C + j otherwise (scalars). Vectors are flat arrays of S: x has ncol C, y nrow R scalars.
//
// Steps (one kernel each, grid-stride over the record's count, which for the triplet steps
// may be a device count (`sp_count`); the shape-dependent ones are instantiated per block type
// at the end of the file, named wp_sparse_<step>_<block>, the others per scalar type):
//   tpl_keys     per triplet t: the sort key (row * ncol + col, or col alone in the two-pass
//                path; a sentinel past every valid key for an out-of-range triplet) and t;
//                the smallest t with a row, a column or a value out of range / non-finite
//                lowers bad[0], bad[1], bad[2].
//   tpl_report   one thread: a device count outside [0, capacity], else the smallest of
//                those (rows, then columns, then values on a tie), raised as a fault, named
//                by the runtime as `sparse::from_triplets`.
//   tpl_row_keys per sorted position (two-pass path): the key of the second sort, the row.
//   (the runtime's stable radix sort of (key, t))
//   tpl_heads    per sorted position: 1 where a run of equal (row, col) starts, else 0.
//   (the runtime's inclusive scan of the heads, in place: pos)
//   tpl_sum      per run head: block pos - 1 gets the row, column and the sum of the run's
//                values in sorted order, which is ascending triplet order (the sort is stable).
//   bsr_offsets  per block row r (and r = nrow): offsets[r] = the first block whose row is >= r.
//   bsr_mv       per (block row, sub-row): y = alpha A x + beta y (y not read when beta == 0);
//                the row's range clamped (`sp_row_range`), columns out of range skipped.
//   dot_partials per chunk of 4096 elements (a block of 256 threads): see `sp_dot_lane`.
//   dot_final    one block of 256 threads: the partials reduced the same way.
//                (Both index their shared lanes by threadIdx.x: correct only for blocks of
//                exactly SP_DOT_LANES threads, which the runtime's launcher asserts.)
//   jacobi_inv   per block row: the inverse of the diagonal block (or of its diagonal alone).
//   jacobi_apply per block row: z = D^-1 r.
//   cg_init, cg_update, cg_check, cg_direction: the conjugate gradient's set-up, x/r update,
//                convergence check (one thread) and search direction (see sparse/solve.rs).
#pragma once
#include "wp_core.h"

namespace wp {

// ------------------------------------------------------------------------------------------
// Rounded arithmetic: the one spelling of every float operation of the steps.
// ------------------------------------------------------------------------------------------
#if defined(__CUDACC__)
WP_FN f32 sp_add(f32 a, f32 b) { return __fadd_rn(a, b); }
WP_FN f32 sp_sub(f32 a, f32 b) { return __fsub_rn(a, b); }
WP_FN f32 sp_mul(f32 a, f32 b) { return __fmul_rn(a, b); }
WP_FN f32 sp_div(f32 a, f32 b) { return __fdiv_rn(a, b); }
WP_FN f32 sp_sqrt(f32 a) { return __fsqrt_rn(a); }
WP_FN f64 sp_add(f64 a, f64 b) { return __dadd_rn(a, b); }
WP_FN f64 sp_sub(f64 a, f64 b) { return __dsub_rn(a, b); }
WP_FN f64 sp_mul(f64 a, f64 b) { return __dmul_rn(a, b); }
WP_FN f64 sp_div(f64 a, f64 b) { return __ddiv_rn(a, b); }
WP_FN f64 sp_sqrt(f64 a) { return __dsqrt_rn(a); }
WP_FN void sp_min32(u64 addr, i32 v) { atomicMin((int*)addr, v); }
#else
WP_FN f32 sp_add(f32 a, f32 b) { return a + b; }
WP_FN f32 sp_sub(f32 a, f32 b) { return a - b; }
WP_FN f32 sp_mul(f32 a, f32 b) { return a * b; }
WP_FN f32 sp_div(f32 a, f32 b) { return a / b; }
WP_FN f32 sp_sqrt(f32 a) { return std::sqrt(a); }
WP_FN f64 sp_add(f64 a, f64 b) { return a + b; }
WP_FN f64 sp_sub(f64 a, f64 b) { return a - b; }
WP_FN f64 sp_mul(f64 a, f64 b) { return a * b; }
WP_FN f64 sp_div(f64 a, f64 b) { return a / b; }
WP_FN f64 sp_sqrt(f64 a) { return std::sqrt(a); }
WP_FN void sp_min32(u64 addr, i32 v) {
  i32* p = (i32*)addr;
  if (v < *p) *p = v;  // the host drivers run one thread
}
#endif

/// Finite (neither NaN nor infinite), without library calls: x - x is 0 exactly then.
template <typename S>
WP_FN bool sp_finite(S x) {
  return x - x == (S)0;
}

/// The dot product's shape: chunks of SP_DOT_CHUNK elements, one block of SP_DOT_LANES threads
/// each (the object-step launcher's block size; the runtime asserts it), SP_DOT_CHUNK /
/// SP_DOT_LANES elements per lane.
constexpr i32 SP_DOT_LANES = 256;
constexpr i64 SP_DOT_CHUNK = 4096;

/// Lane `lane`'s serial sum over chunk `c` of the n-element vectors a and b: starting from 0,
/// + a[i] b[i] for i = c CHUNK + lane + LANES m, m ascending, i < n.
template <typename S>
WP_FN S sp_dot_lane(const S* a, const S* b, i64 n, i64 c, i32 lane) {
  S acc = (S)0;
  const i64 base = c * SP_DOT_CHUNK + lane;
  for (i64 m = 0; m < SP_DOT_CHUNK / SP_DOT_LANES; ++m) {
    const i64 i = base + m * SP_DOT_LANES;
    if (i < n) acc = sp_add(acc, sp_mul(a[i], b[i]));
  }
  return acc;
}

/// Lane `lane`'s serial sum of the partials lane, lane + LANES, .. below `count`, from 0.
template <typename S>
WP_FN S sp_dot_final_lane(const S* partials, i64 count, i32 lane) {
  S acc = (S)0;
  for (i64 i = lane; i < count; i += SP_DOT_LANES) acc = sp_add(acc, partials[i]);
  return acc;
}

/// One level of the lanes' tree: s[l] = s[l] + s[l + stride] for l < stride (strides 128, 64,
/// .., 1; the total ends in s[0]). On a GPU lane l does its own l between barriers.
template <typename S>
WP_FN void sp_tree_level(S* s, i32 stride, i32 lane) {
  if (lane < stride) s[lane] = sp_add(s[lane], s[lane + stride]);
}

// ------------------------------------------------------------------------------------------
// Records (each laid out as its Rust step's #[repr(C)] struct; both sides assert the size)
// ------------------------------------------------------------------------------------------

// The triplet steps' first field, `count`: the address of a device count of triplets (an
// i32), or 0 when there is none and `n` is the count. With one, `n` is the capacity (the
// arrays' length) and the steps process `sp_count(count, n)` triplets: the count, or 0 when
// it is outside [0, n] (the primitives' rule for a bad count, so that the sort, the scan and
// these steps agree and the matrix is empty; the report raises the fault).
WP_FN i32 sp_count(u64 count, i32 n) {
  if (count == 0) return n;
  const i32 c = *(const i32*)count;
  return (c < 0 || c > n) ? 0 : c;
}

/// TplKeys: count, rows, cols (i32*), values (S*, `block` scalars per triplet), n, nrow, ncol,
/// block, two_pass (0: key row * ncol + col; 1: key col), no_finite_check (1: values are not
/// checked, for the structure operations of wp_sparse_ops.h, whose values are a matrix's),
/// keys (u32*), idx (i32*), bad (i32[3]).
struct sp_tpl_keys_t {
  u64 count, rows, cols, values;
  i32 n, nrow, ncol, block, two_pass, no_finite_check;
  u64 keys, idx, bad;
};
static_assert(sizeof(sp_tpl_keys_t) == 80, "sp_tpl_keys_t layout");

/// TplReport: count, bad (i32[3], INT_MAX where nothing was found), rows, cols, values, n,
/// nrow, ncol, block; the fault context (argument 0 rows, 1 columns, 2 values, 3 count).
struct sp_tpl_report_t {
  u64 count, bad, rows, cols, values;
  i32 n, nrow, ncol, block;
  step_fault_t fault;
};
static_assert(sizeof(sp_tpl_report_t) == 96, "sp_tpl_report_t layout");

/// TplRowKeys: count, rows, cols, idx (sorted), keys (u32*, written), n, nrow, ncol.
struct sp_tpl_row_keys_t {
  u64 count, rows, cols, idx, keys;
  i32 n, nrow, ncol, pad;
};
static_assert(sizeof(sp_tpl_row_keys_t) == 56, "sp_tpl_row_keys_t layout");

/// TplHeads: count, rows, cols, idx (sorted), heads (i32*, written), n, nrow, ncol.
struct sp_tpl_heads_t {
  u64 count, rows, cols, idx, heads;
  i32 n, nrow, ncol, pad;
};
static_assert(sizeof(sp_tpl_heads_t) == 56, "sp_tpl_heads_t layout");

/// TplSum: count, rows, cols, values (S*), idx (sorted), pos (inclusive scan of the heads),
/// block_rows, columns (i32*), out (S*, `block` scalars per block), n, nrow, ncol, block.
struct sp_tpl_sum_t {
  u64 count, rows, cols, values, idx, pos, block_rows, columns, out;
  i32 n, nrow, ncol, block;
};
static_assert(sizeof(sp_tpl_sum_t) == 88, "sp_tpl_sum_t layout");

/// BsrOffsets: count, block_rows (sorted), pos (the scan: entry count - 1 is the block count),
/// offsets (i32*, nrow + 1, written), n (the triplets: a count of 0 means no block), nrow.
struct sp_bsr_offsets_t {
  u64 count, block_rows, pos, offsets;
  i32 n, nrow;
};
static_assert(sizeof(sp_bsr_offsets_t) == 40, "sp_bsr_offsets_t layout");

/// BsrMv: offsets, columns, values, x, y, alpha, beta (as f64, rounded to S like Rust's `as`),
/// nrow, ncol, cap (the capacity of columns and values: see `sp_row_range`), lanes (w, a
/// power of two up to 32, lanes per scalar row: see `sp_bsr_mv_lane`; below 1 means 1).
struct sp_bsr_mv_t {
  u64 offsets, columns, values, x, y;
  f64 alpha, beta;
  i32 nrow, ncol, cap, lanes;
};
static_assert(sizeof(sp_bsr_mv_t) == 72, "sp_bsr_mv_t layout");

/// DotPartials / DotFinal: a, b (S*, n each; DotFinal: the partials in a, b unused), n, out
/// (S*: the partials, one per chunk, or the one result), chunks.
struct sp_dot_t {
  u64 a, b;
  i64 n;
  u64 out;
  i64 chunks;
};
static_assert(sizeof(sp_dot_t) == 40, "sp_dot_t layout");

/// JacobiInv: offsets, columns, values, dinv (S*, R R per block row, row-major), bad (i32*:
/// lowered to the first block row whose diagonal block is missing, singular or not finite),
/// nrow, point (1: the diagonal entries alone).
struct sp_jacobi_inv_t {
  u64 offsets, columns, values, dinv, bad;
  i32 nrow, point, cap, pad;
};
static_assert(sizeof(sp_jacobi_inv_t) == 56, "sp_jacobi_inv_t layout");

/// JacobiApply: dinv, r, z (S*), nrow, dim (R).
struct sp_jacobi_apply_t {
  u64 dinv, r, z;
  i32 nrow, dim;
};
static_assert(sizeof(sp_jacobi_apply_t) == 32, "sp_jacobi_apply_t layout");

/// The CG's control words (i32) and scalars (S): see sparse/solve.rs, which names the same
/// (a unit test of sparse/steps.rs parses these SP_ constants and compares the records' offsets).
// SP_CTL_RUN: 1 while no stop is set (cg_init and cg_check write it): the flag a captured
// solve's `capture_while` loops on.
constexpr i32 SP_CTL_STOP = 0, SP_CTL_ITER = 1, SP_CTL_BAD = 2, SP_CTL_RUN = 3;
constexpr i32 SP_STOP_NONE = 0, SP_STOP_CONVERGED = 1, SP_STOP_MAX_ITER = 2,
              SP_STOP_NON_FINITE = 3, SP_STOP_BREAKDOWN = 4, SP_STOP_SINGULAR = 5,
              SP_STOP_BREAKDOWN_RZ = 6;
constexpr i32 SP_RZ = 0, SP_RZ_NEW = 1, SP_PAP = 2, SP_RR = 3, SP_BB = 4, SP_TOL2 = 5,
              SP_BETA = 6, SP_BREAK = 7, SP_TOL = 8;

/// CgScalar (cg_init, cg_check; one thread): ctl, scal, history (S*), rtol, atol, max_iter.
struct sp_cg_scalar_t {
  u64 ctl, scal, history;
  f64 rtol, atol;
  i32 max_iter, pad;
};
static_assert(sizeof(sp_cg_scalar_t) == 48, "sp_cg_scalar_t layout");

/// CgVector (cg_update: x += alpha p, r -= alpha ap; cg_direction: p = z + beta p): ctl, scal,
/// x, r, p, ap (cg_direction: z in `r`), n.
struct sp_cg_vector_t {
  u64 ctl, scal, x, r, p, ap;
  i64 n;
};
static_assert(sizeof(sp_cg_vector_t) == 56, "sp_cg_vector_t layout");

// ------------------------------------------------------------------------------------------
// Per-element steps (the kernels below loop over these; the host drivers call them directly)
// ------------------------------------------------------------------------------------------

/// Whether triplet t's row and column are in range.
WP_FN bool sp_tpl_valid(const i32* rows, const i32* cols, i32 t, i32 nrow, i32 ncol) {
  const i32 r = rows[t], c = cols[t];
  return r >= 0 && r < nrow && c >= 0 && c < ncol;
}

template <typename S>
WP_FN void sp_tpl_keys(const sp_tpl_keys_t& s, i32 t) {
  const i32* rows = (const i32*)s.rows;
  const i32* cols = (const i32*)s.cols;
  const S* v = (const S*)s.values + (i64)t * s.block;
  const i32 r = rows[t], c = cols[t];
  const bool row_ok = r >= 0 && r < s.nrow, col_ok = c >= 0 && c < s.ncol;
  if (!row_ok) sp_min32(s.bad, t);
  if (!col_ok) sp_min32(s.bad + 4, t);
  for (i32 e = 0; !s.no_finite_check && e < s.block; ++e)
    if (!sp_finite(v[e])) {
      sp_min32(s.bad + 8, t);
      break;
    }
  u32 key;
  if (s.two_pass)
    key = row_ok && col_ok ? (u32)c : (u32)s.ncol;
  else
    key = row_ok && col_ok ? (u32)r * (u32)s.ncol + (u32)c : (u32)s.nrow * (u32)s.ncol;
  ((u32*)s.keys)[t] = key;
  ((i32*)s.idx)[t] = t;
}

/// The keys step's report (one thread): the smallest triplet found bad, rows before columns
/// before values on a tie, raised as a fault: out of bounds on `rows` (argument 0) or
/// `columns` (1) with index [t, value] and shape [n, nrow or ncol]; a non-finite value
/// (argument 2) with index t and the first non-finite scalar of its block.
template <typename S>
WP_FN void sp_tpl_report(const sp_tpl_report_t& s) {
  ctx_t ctx = ctx_make(&s.fault.ctx);
  if (s.count != 0) {
    const i32 c = *(const i32*)s.count;
    if (c < 0 || c > s.n) {
      const i64 index[1] = {(i64)c};
      const i64 shape[1] = {(i64)s.n + 1};
      raise(&ctx, FAULT_OUT_OF_BOUNDS, 3, 1, index, shape);
      return;
    }
  }
  const i32 n = sp_count(s.count, s.n);
  const i32* bad = (const i32*)s.bad;
  i32 which = -1, t = 0x7fffffff;
  for (i32 w = 0; w < 3; ++w)
    if (bad[w] < t) {
      t = bad[w];
      which = w;
    }
  if (which < 0) return;
  if (which < 2) {
    const i32 v = ((const i32*)(which == 0 ? s.rows : s.cols))[t];
    const i64 index[2] = {(i64)t, (i64)v};
    const i64 shape[2] = {(i64)n, (i64)(which == 0 ? s.nrow : s.ncol)};
    raise(&ctx, FAULT_OUT_OF_BOUNDS, which, 2, index, shape);
  } else {
    const S* v = (const S*)s.values + (i64)t * s.block;
    S x = v[0];
    for (i32 e = 0; e < s.block; ++e)
      if (!sp_finite(v[e])) {
        x = v[e];
        break;
      }
    const i64 index[2] = {(i64)t, (i64)f64_to_bits((f64)x)};
    raise(&ctx, FAULT_NON_FINITE_INPUT, 2, 2, index, nullptr);
  }
}

WP_FN void sp_tpl_row_keys(const sp_tpl_row_keys_t& s, i32 k) {
  const i32 t = ((const i32*)s.idx)[k];
  const bool ok = sp_tpl_valid((const i32*)s.rows, (const i32*)s.cols, t, s.nrow, s.ncol);
  ((u32*)s.keys)[k] = ok ? (u32)((const i32*)s.rows)[t] : (u32)s.nrow;
}

WP_FN void sp_tpl_heads(const sp_tpl_heads_t& s, i32 k) {
  const i32* rows = (const i32*)s.rows;
  const i32* cols = (const i32*)s.cols;
  const i32* idx = (const i32*)s.idx;
  const i32 t = idx[k];
  i32 head = 0;
  if (sp_tpl_valid(rows, cols, t, s.nrow, s.ncol)) {
    // Out-of-range triplets sort after every valid one: a valid one's predecessor is valid.
    head = k == 0 || rows[idx[k - 1]] != rows[t] || cols[idx[k - 1]] != cols[t];
  }
  ((i32*)s.heads)[k] = head;
}

template <typename S>
WP_FN void sp_tpl_sum(const sp_tpl_sum_t& s, i32 k) {
  const i32* rows = (const i32*)s.rows;
  const i32* cols = (const i32*)s.cols;
  const i32* idx = (const i32*)s.idx;
  const i32* pos = (const i32*)s.pos;
  const i32 t = idx[k];
  if (!sp_tpl_valid(rows, cols, t, s.nrow, s.ncol)) return;
  if (pos[k] - (k > 0 ? pos[k - 1] : 0) != 1) return;  // not the head of its run
  const i32 b = pos[k] - 1;
  const i32 r = rows[t], c = cols[t];
  ((i32*)s.block_rows)[b] = r;
  ((i32*)s.columns)[b] = c;
  const S* values = (const S*)s.values;
  S* out = (S*)s.out + (i64)b * s.block;
  for (i32 e = 0; e < s.block; ++e) out[e] = values[(i64)t * s.block + e];
  const i32 n = sp_count(s.count, s.n);
  for (i32 m = k + 1; m < n; ++m) {
    const i32 u = idx[m];
    if (!sp_tpl_valid(rows, cols, u, s.nrow, s.ncol) || rows[u] != r || cols[u] != c) break;
    for (i32 e = 0; e < s.block; ++e) out[e] = sp_add(out[e], values[(i64)u * s.block + e]);
  }
}

WP_FN void sp_bsr_offsets(const sp_bsr_offsets_t& s, i32 r) {
  const i32 n = sp_count(s.count, s.n);
  const i32 nnz = n > 0 ? ((const i32*)s.pos)[n - 1] : 0;
  const i32* rows = (const i32*)s.block_rows;
  i32 lo = 0, hi = nnz;  // the first block whose row is >= r
  while (lo < hi) {
    const i32 mid = lo + (hi - lo) / 2;
    if (rows[mid] < r)
      lo = mid + 1;
    else
      hi = mid;
  }
  ((i32*)s.offsets)[r] = lo;
}

/// Block row r's blocks [*lo, *hi): offsets[r] .. offsets[r + 1], each clamped into
/// [0, nnz] with nnz = offsets[nrow] clamped into [0, cap], so that offsets a user wrote
/// (the arrays are handles anyone may fill) never make a step read outside the arrays.
/// A matrix made by the assembly is unchanged by the clamps.
WP_FN void sp_row_range(const i32* offsets, i32 nrow, i32 cap, i32 r, i32* lo, i32* hi) {
  i32 nnz = offsets[nrow];
  nnz = nnz < 0 ? 0 : (nnz > cap ? cap : nnz);
  i32 a = offsets[r], b = offsets[r + 1];
  a = a < 0 ? 0 : (a > nnz ? nnz : a);
  b = b < a ? a : (b > nnz ? nnz : b);
  *lo = a;
  *hi = b;
}

/// A load through the read-only data cache on a GPU (`__ldg`; a plain load under the host
/// emulator): for arrays no thread of the kernel writes.
template <typename T>
WP_FN T sp_ldg(const T* p) {
#if defined(__CUDA_ARCH__)
  return __ldg(p);
#else
  return *p;
#endif
}

/// Entry (i, j) of an R x C block stored column-major (CM) or row-major.
template <int R, int C, bool CM>
WP_FN i32 sp_at(i32 i, i32 j) {
  return CM ? j * R + i : i * C + j;
}

/// Lane l's partial sum of scalar row i of block row r of A x, for w lanes per scalar row:
/// from 0, over the row's blocks l, l + w, l + 2w, .. (positions in the row, in storage
/// order) and within a block over ascending j, of a_ij * x_j, each operation rounded. The w
/// partials are then added in a butterfly with partners w/2, .., 1 (`sp_bsr_mv_tree`), so a
/// scalar's sum depends on w alone, never on the device: the CPU body runs the same lanes
/// and tree. (w = 1: the row's plain sum in storage order.)
template <typename S, int R, int C, bool CM>
WP_FN S sp_bsr_mv_lane(const sp_bsr_mv_t& s, i32 r, i32 i, i32 l, i32 w) {
  // The matrix and x are read-only here (mv checks that y overlaps neither): their loads go
  // through the read-only data cache.
  const i32* offsets = (const i32*)s.offsets;
  const i32* columns = (const i32*)s.columns;
  const S* values = (const S*)s.values;
  const S* x = (const S*)s.x;
  S acc = (S)0;
  i32 lo, hi;
  sp_row_range(offsets, s.nrow, s.cap, r, &lo, &hi);
  for (i32 k = lo + l; k < hi; k += w) {
    const i32 c = sp_ldg(columns + k);
    if (c < 0 || c >= s.ncol) continue;  // (never in an assembled matrix)
    const S* a = values + (i64)k * (R * C);
    const S* xc = x + (i64)c * C;
    for (i32 j = 0; j < C; ++j)
      acc = sp_add(acc, sp_mul(sp_ldg(a + sp_at<R, C, CM>(i, j)), sp_ldg(xc + j)));
  }
  return acc;
}

/// y's scalar i of block row r from the row's sum: alpha * acc (+ beta * y when beta != 0;
/// when beta == 0, y is not read: it may hold NaN).
template <typename S, int R>
WP_FN void sp_bsr_mv_store(const sp_bsr_mv_t& s, i32 r, i32 i, S acc) {
  S* y = (S*)s.y;
  const S alpha = (S)s.alpha, beta = (S)s.beta;
  const i64 o = (i64)r * R + i;
  y[o] = beta == (S)0 ? sp_mul(alpha, acc) : sp_add(sp_mul(alpha, acc), sp_mul(beta, y[o]));
}

/// Scalar row i of block row r of y = alpha A x + beta y with one lane (w = 1). A thread per
/// (block row, sub-row), as Warp's bsr_mv: R times the threads of a thread per block row,
/// and the R threads of a block row read its blocks side by side. Each scalar's sum is the
/// one the CPU body computes, so the bits do not depend on the split.
template <typename S, int R, int C, bool CM>
WP_FN void sp_bsr_mv_sub(const sp_bsr_mv_t& s, i32 r, i32 i) {
  sp_bsr_mv_store<S, R>(s, r, i, sp_bsr_mv_lane<S, R, C, CM>(s, r, i, 0, 1));
}

/// Block row r of the product: its R scalar rows, one after the other.
template <typename S, int R, int C, bool CM>
WP_FN void sp_bsr_mv_row(const sp_bsr_mv_t& s, i32 r) {
  for (i32 i = 0; i < R; ++i) sp_bsr_mv_sub<S, R, C, CM>(s, r, i);
}

// (Device code: in every build library that includes this header, for the mv kernels of
// wp_sparse_ops.h too; also under the host emulator.)
#if defined(__CUDACC__) || defined(WP_SPARSE_EMULATED)
/// y = alpha A x + beta y with w = s.lanes > 1 lanes per scalar row: thread t is lane t % w
/// of scalar row t / w (w divides 32 and a block's threads are whole warps, so a row's lanes
/// are consecutive lanes of one warp); each lane sums its blocks (`sp_bsr_mv_lane`), the
/// butterfly adds the partials (partners w/2, .., 1: the order of `sp_bsr_mv_tree` on the
/// CPU), and lane 0 writes. The loop advances a whole warp at a time, so a warp's lanes meet
/// every shuffle together; the rows' total (nrow R w) is a multiple of w, so a row's lanes
/// are all in range or all out.
template <typename S, int R, int C, bool CM>
__device__ void sp_bsr_mv_lanes(const sp_bsr_mv_t& s) {
  const i32 w = s.lanes;
  const i64 total = (i64)s.nrow * R * w;
  const i64 stride = (i64)blockDim.x * gridDim.x;
  const i32 lane = (i32)(threadIdx.x & 31u);
  for (i64 base = (i64)blockIdx.x * blockDim.x + (threadIdx.x & ~31u); base < total;
       base += stride) {
    const i64 t = base + lane;
    const bool on = t < total;
    const unsigned mask = __ballot_sync(0xffffffffu, on);
    if (!on) continue;
    const i64 g = t / w;
    const i32 l = (i32)(t % w), r = (i32)(g / R), i = (i32)(g % R);
    S acc = sp_bsr_mv_lane<S, R, C, CM>(s, r, i, l, w);
    for (i32 d = w / 2; d >= 1; d /= 2) acc = sp_add(acc, __shfl_sync(mask, acc, lane ^ d));
    if (l == 0) sp_bsr_mv_store<S, R>(s, r, i, acc);
  }
}
#endif

/// The inverse of block row r's diagonal block by Gauss-Jordan with partial pivoting (the
/// first largest |pivot| of the column, rows swapped), or of its diagonal alone (`point`);
/// zeros and `bad` lowered to r when the block is missing, a pivot is zero, or the inverse is
/// not finite.
template <typename S, int R, int C, bool CM>
WP_FN void sp_jacobi_inv_row(const sp_jacobi_inv_t& s, i32 r) {
  const i32* offsets = (const i32*)s.offsets;
  const i32* columns = (const i32*)s.columns;
  S* out = (S*)s.dinv + (i64)r * (R * R);
  S a[R][R], inv[R][R];
  bool ok = false;
  i32 lo, hi;
  sp_row_range(offsets, s.nrow, s.cap, r, &lo, &hi);
  for (i32 k = lo; k < hi; ++k) {
    if (columns[k] != r) continue;
    const S* b = (const S*)s.values + (i64)k * (R * C);
    for (i32 i = 0; i < R; ++i)
      for (i32 j = 0; j < R; ++j) {
        a[i][j] = (!s.point || i == j) ? b[sp_at<R, C, CM>(i, j)] : (S)0;
        inv[i][j] = i == j ? (S)1 : (S)0;
      }
    ok = true;
    break;
  }
  for (i32 col = 0; ok && col < R; ++col) {
    i32 p = col;
    for (i32 i = col + 1; i < R; ++i) {
      const S ai = a[i][col] < (S)0 ? -a[i][col] : a[i][col];
      const S ap = a[p][col] < (S)0 ? -a[p][col] : a[p][col];
      if (ai > ap) p = i;
    }
    if (!(a[p][col] != (S)0)) {
      ok = false;
      break;
    }
    if (p != col)
      for (i32 j = 0; j < R; ++j) {
        S t = a[p][j];
        a[p][j] = a[col][j];
        a[col][j] = t;
        t = inv[p][j];
        inv[p][j] = inv[col][j];
        inv[col][j] = t;
      }
    const S piv = a[col][col];
    for (i32 j = 0; j < R; ++j) {
      a[col][j] = sp_div(a[col][j], piv);
      inv[col][j] = sp_div(inv[col][j], piv);
    }
    for (i32 i = 0; i < R; ++i) {
      if (i == col) continue;
      const S f = a[i][col];
      for (i32 j = 0; j < R; ++j) {
        a[i][j] = sp_sub(a[i][j], sp_mul(f, a[col][j]));
        inv[i][j] = sp_sub(inv[i][j], sp_mul(f, inv[col][j]));
      }
    }
  }
  for (i32 i = 0; ok && i < R; ++i)
    for (i32 j = 0; j < R; ++j) ok = ok && sp_finite(inv[i][j]);
  for (i32 i = 0; i < R; ++i)
    for (i32 j = 0; j < R; ++j) out[i * R + j] = ok ? inv[i][j] : (S)0;
  if (!ok) sp_min32(s.bad, r);
}

template <typename S>
WP_FN void sp_jacobi_apply_row(const sp_jacobi_apply_t& s, i32 r) {
  const S* d = (const S*)s.dinv + (i64)r * s.dim * s.dim;
  const S* rv = (const S*)s.r + (i64)r * s.dim;
  S* z = (S*)s.z + (i64)r * s.dim;
  for (i32 i = 0; i < s.dim; ++i) {
    S acc = (S)0;
    for (i32 j = 0; j < s.dim; ++j) acc = sp_add(acc, sp_mul(d[i * s.dim + j], rv[j]));
    z[i] = acc;
  }
}

/// The CG's set-up check (one thread): tolerance max(atol, rtol |b|), history[0] = |r|, and
/// the stop before any iteration (a singular preconditioner, a non-finite residual,
/// convergence, r.z <= 0, max_iter == 0).
template <typename S>
WP_FN void sp_cg_init(const sp_cg_scalar_t& s) {
  i32* ctl = (i32*)s.ctl;
  S* sc = (S*)s.scal;
  S* hist = (S*)s.history;
  const S rt = sp_mul((S)s.rtol, sp_sqrt(sc[SP_BB]));
  const S at = (S)s.atol;
  const S tol = at > rt ? at : rt;
  sc[SP_TOL] = tol;
  sc[SP_TOL2] = sp_mul(tol, tol);
  const S rr = sc[SP_RR], rz = sc[SP_RZ];
  hist[0] = sp_sqrt(rr);
  ctl[SP_CTL_ITER] = 0;
  i32 stop = SP_STOP_NONE;
  if (ctl[SP_CTL_BAD] != 0x7fffffff)
    stop = SP_STOP_SINGULAR;
  else if (!sp_finite(rr) || !sp_finite(rz))
    stop = SP_STOP_NON_FINITE;
  else if (rr <= sc[SP_TOL2])
    stop = SP_STOP_CONVERGED;
  else if (rz <= (S)0) {
    // An indefinite preconditioner (r != 0 here, so an SPD one gives r.z > 0).
    sc[SP_BREAK] = rz;
    stop = SP_STOP_BREAKDOWN_RZ;
  } else if (s.max_iter <= 0)
    stop = SP_STOP_MAX_ITER;
  ctl[SP_CTL_STOP] = stop;
  ctl[SP_CTL_RUN] = stop == SP_STOP_NONE;
}

/// Whether an iteration may update x and r: not stopped, and p.Ap positive and finite.
template <typename S>
WP_FN bool sp_cg_step_ok(const i32* ctl, const S* sc) {
  const S pap = sc[SP_PAP];
  return ctl[SP_CTL_STOP] == SP_STOP_NONE && pap > (S)0 && sp_finite(pap);
}

template <typename S>
WP_FN void sp_cg_update(const sp_cg_vector_t& s, i64 i) {
  const S* sc = (const S*)s.scal;
  if (!sp_cg_step_ok((const i32*)s.ctl, sc)) return;
  const S alpha = sp_div(sc[SP_RZ], sc[SP_PAP]);
  S* x = (S*)s.x;
  S* r = (S*)s.r;
  x[i] = sp_add(x[i], sp_mul(alpha, ((const S*)s.p)[i]));
  r[i] = sp_sub(r[i], sp_mul(alpha, ((const S*)s.ap)[i]));
}

/// The CG's check after an iteration (one thread): a bad p.Ap stops it (NonFinite or
/// Breakdown, x and r untouched by that iteration); else the iteration counts, its residual
/// norm goes to the history, and it stops on a non-finite residual, convergence, a new r.z
/// <= 0 (a breakdown) or max_iter; else beta = (r.z)new / (r.z) for the direction.
template <typename S>
WP_FN void sp_cg_check_stop(const sp_cg_scalar_t& s) {
  i32* ctl = (i32*)s.ctl;
  S* sc = (S*)s.scal;
  if (ctl[SP_CTL_STOP] != SP_STOP_NONE) return;
  const S pap = sc[SP_PAP];
  if (!sp_finite(pap)) {
    ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
    return;
  }
  if (pap <= (S)0) {
    sc[SP_BREAK] = pap;
    ctl[SP_CTL_STOP] = SP_STOP_BREAKDOWN;
    return;
  }
  const i32 it = ctl[SP_CTL_ITER] + 1;
  ctl[SP_CTL_ITER] = it;
  const S rr = sc[SP_RR];
  ((S*)s.history)[it] = sp_sqrt(rr);
  if (!sp_finite(rr) || !sp_finite(sc[SP_RZ_NEW]))
    ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
  else if (rr <= sc[SP_TOL2])
    ctl[SP_CTL_STOP] = SP_STOP_CONVERGED;
  else if (sc[SP_RZ_NEW] <= (S)0) {
    sc[SP_BREAK] = sc[SP_RZ_NEW];
    ctl[SP_CTL_STOP] = SP_STOP_BREAKDOWN_RZ;
  } else if (it >= s.max_iter)
    ctl[SP_CTL_STOP] = SP_STOP_MAX_ITER;
  else {
    sc[SP_BETA] = sp_div(sc[SP_RZ_NEW], sc[SP_RZ]);
    sc[SP_RZ] = sc[SP_RZ_NEW];
  }
}

template <typename S>
WP_FN void sp_cg_check(const sp_cg_scalar_t& s) {
  sp_cg_check_stop<S>(s);
  i32* ctl = (i32*)s.ctl;
  ctl[SP_CTL_RUN] = ctl[SP_CTL_STOP] == SP_STOP_NONE;
}

template <typename S>
WP_FN void sp_cg_direction(const sp_cg_vector_t& s, i64 i) {
  if (((const i32*)s.ctl)[SP_CTL_STOP] != SP_STOP_NONE) return;
  const S beta = ((const S*)s.scal)[SP_BETA];
  S* p = (S*)s.p;
  p[i] = sp_add(((const S*)s.r)[i], sp_mul(beta, p[i]));
}

}  // namespace wp

// ------------------------------------------------------------------------------------------
// The kernels (only in the build library: WP_SPARSE_BUILD). Grid-stride loops; the dot
// kernels are block-cooperative (blocks of SP_DOT_LANES threads). WP_SPARSE_EMULATED: the
// same kernels as host C++ under the block emulator (tests/cuda_sparse_host.rs defines the
// CUDA names they use).
// ------------------------------------------------------------------------------------------
#if defined(WP_SPARSE_BUILD) && (defined(__CUDACC__) || defined(WP_SPARSE_EMULATED))
namespace wp {
// A grid-stride loop of i over [0, n) (the kernels' macros expand it outside namespace wp).
#define WP_SP_LOOP(i, n)                                                                    \
  for (::wp::i64 i = (::wp::i64)blockIdx.x * blockDim.x + threadIdx.x,                      \
                 i##_stride = (::wp::i64)blockDim.x * gridDim.x;                            \
       i < (::wp::i64)(n); i += i##_stride)

template <typename S>
__device__ void sp_dot_partials_kernel(const sp_dot_t& s) {
  __shared__ S sh[SP_DOT_LANES];
  const i32 lane = (i32)threadIdx.x;
  for (i64 c = blockIdx.x; c < s.chunks; c += gridDim.x) {
    sh[lane] = sp_dot_lane((const S*)s.a, (const S*)s.b, s.n, c, lane);
    __syncthreads();
    for (i32 stride = SP_DOT_LANES / 2; stride > 0; stride /= 2) {
      sp_tree_level(sh, stride, lane);
      __syncthreads();
    }
    if (lane == 0) ((S*)s.out)[c] = sh[0];
    __syncthreads();
  }
}

template <typename S>
__device__ void sp_dot_final_kernel(const sp_dot_t& s) {
  __shared__ S sh[SP_DOT_LANES];
  const i32 lane = (i32)threadIdx.x;
  if (blockIdx.x != 0) return;
  sh[lane] = sp_dot_final_lane((const S*)s.a, s.chunks, lane);
  __syncthreads();
  for (i32 stride = SP_DOT_LANES / 2; stride > 0; stride /= 2) {
    sp_tree_level(sh, stride, lane);
    __syncthreads();
  }
  if (lane == 0) *(S*)s.out = sh[0];
}
}  // namespace wp

// The kernels of one scalar type.
#define WP_SP_SCALAR_KERNELS(tag, S)                                                        \
  extern "C" __global__ void wp_sparse_tpl_keys_##tag(wp::sp_tpl_keys_t s) {                \
    WP_SP_LOOP(t, wp::sp_count(s.count, s.n)) wp::sp_tpl_keys<S>(s, (wp::i32)t);            \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_tpl_report_##tag(wp::sp_tpl_report_t s) {            \
    if (blockIdx.x == 0 && threadIdx.x == 0) wp::sp_tpl_report<S>(s);                       \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_tpl_sum_##tag(wp::sp_tpl_sum_t s) {                  \
    WP_SP_LOOP(k, wp::sp_count(s.count, s.n)) wp::sp_tpl_sum<S>(s, (wp::i32)k);             \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_dot_partials_##tag(wp::sp_dot_t s) {                 \
    wp::sp_dot_partials_kernel<S>(s);                                                       \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_dot_final_##tag(wp::sp_dot_t s) {                    \
    wp::sp_dot_final_kernel<S>(s);                                                          \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_jacobi_apply_##tag(wp::sp_jacobi_apply_t s) {        \
    WP_SP_LOOP(r, s.nrow) wp::sp_jacobi_apply_row<S>(s, (wp::i32)r);                        \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_cg_init_##tag(wp::sp_cg_scalar_t s) {                \
    if (blockIdx.x == 0 && threadIdx.x == 0) wp::sp_cg_init<S>(s);                          \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_cg_check_##tag(wp::sp_cg_scalar_t s) {               \
    if (blockIdx.x == 0 && threadIdx.x == 0) wp::sp_cg_check<S>(s);                         \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_cg_update_##tag(wp::sp_cg_vector_t s) {              \
    WP_SP_LOOP(i, s.n) wp::sp_cg_update<S>(s, i);                                           \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_cg_direction_##tag(wp::sp_cg_vector_t s) {           \
    WP_SP_LOOP(i, s.n) wp::sp_cg_direction<S>(s, i);                                        \
  }

// The kernels of one block type (scalar S, R x C, column-major CM).
#define WP_SP_BLOCK_KERNELS(tag, S, R, C, CM)                                               \
  extern "C" __global__ void wp_sparse_bsr_mv_##tag(wp::sp_bsr_mv_t s) {                    \
    if (s.lanes > 1) {                                                                      \
      wp::sp_bsr_mv_lanes<S, R, C, CM>(s);                                                  \
      return;                                                                               \
    }                                                                                       \
    WP_SP_LOOP(t, (wp::i64)s.nrow * R)                                                      \
    wp::sp_bsr_mv_sub<S, R, C, CM>(s, (wp::i32)(t / R), (wp::i32)(t % R));                  \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_jacobi_inv_##tag(wp::sp_jacobi_inv_t s) {            \
    WP_SP_LOOP(r, s.nrow) wp::sp_jacobi_inv_row<S, R, C, CM>(s, (wp::i32)r);                \
  }

extern "C" __global__ void wp_sparse_tpl_row_keys(wp::sp_tpl_row_keys_t s) {
  WP_SP_LOOP(k, wp::sp_count(s.count, s.n)) wp::sp_tpl_row_keys(s, (wp::i32)k);
}
extern "C" __global__ void wp_sparse_tpl_heads(wp::sp_tpl_heads_t s) {
  WP_SP_LOOP(k, wp::sp_count(s.count, s.n)) wp::sp_tpl_heads(s, (wp::i32)k);
}
extern "C" __global__ void wp_sparse_bsr_offsets(wp::sp_bsr_offsets_t s) {
  WP_SP_LOOP(r, (wp::i64)s.nrow + 1) wp::sp_bsr_offsets(s, (wp::i32)r);
}

WP_SP_SCALAR_KERNELS(f32, wp::f32)
WP_SP_SCALAR_KERNELS(f64, wp::f64)
// The block types of warp-runtime's sparse/block.rs (its `kernels!` names the same tags).
WP_SP_BLOCK_KERNELS(f32, wp::f32, 1, 1, false)
WP_SP_BLOCK_KERNELS(f64, wp::f64, 1, 1, false)
WP_SP_BLOCK_KERNELS(mat2, wp::f32, 2, 2, true)
WP_SP_BLOCK_KERNELS(mat3, wp::f32, 3, 3, true)
WP_SP_BLOCK_KERNELS(mat4, wp::f32, 4, 4, true)
WP_SP_BLOCK_KERNELS(dmat2, wp::f64, 2, 2, true)
WP_SP_BLOCK_KERNELS(dmat3, wp::f64, 3, 3, true)
WP_SP_BLOCK_KERNELS(dmat4, wp::f64, 4, 4, true)
#endif

// ==========================================================================================
// Krylov solvers beyond CG: BiCGSTAB, CR, restarted GMRES (warp-runtime's sparse/solve/
// {bicgstab,cr,gmres}.rs; the steps' CPU bodies are sparse/solve/steps.rs, in the same order
// of operations). They reuse the products, dots and Jacobi steps above, and add:
//   kr_vec       per element: a vector update (SPK_OP_*) of y, x, w with a = scal[ia], b =
//                scal[ib], when its gate (SPK_GATE_*) is open (the control words).
//   kr_comb      per element: GMRES's basis combination sum_k y_k V_k, added to or stored in
//                `out`, while the cycle's update is pending.
//   bicgstab_scalar, cr_scalar, gmres_scalar: one thread: the method's check of `phase`.
// ==========================================================================================
namespace wp {

/// The control words beyond SP_CTL_RUN, the first scalars of every method, the breakdown
/// codes, the vector operations and gates, and the per-method scalars (sparse/solve/steps.rs's
/// `kr` module names the same; a unit test there parses these SPK_ constants).
constexpr i32 SPK_CTL_WHAT = 4, SPK_CTL_ACTIVE = 5, SPK_CTL_PENDING = 6, SPK_CTL_K = 7,
              SPK_CTL_LEN = 8;
constexpr i32 SPK_TOL = 0, SPK_TOL2 = 1, SPK_BB = 2, SPK_RR = 3, SPK_BREAK = 4;
constexpr i32 SPK_WHAT_RHO = 0, SPK_WHAT_OMEGA = 1, SPK_WHAT_R0V = 2, SPK_WHAT_APAP = 3,
              SPK_WHAT_ZAZ = 4, SPK_WHAT_HJJ = 5;
constexpr i32 SPK_OP_AXPY = 0, SPK_OP_AXMY = 1, SPK_OP_XPAY = 2, SPK_OP_P = 3, SPK_OP_DIV = 4,
              SPK_OP_ADD = 5;
constexpr i32 SPK_GATE_RUN = 0, SPK_GATE_ACTIVE = 1, SPK_GATE_PENDING = 2;
constexpr i32 SPK_B_RHO = 5, SPK_B_R0V = 6, SPK_B_ALPHA = 7, SPK_B_SS = 8, SPK_B_TS = 9,
              SPK_B_TT = 10, SPK_B_OMEGA = 11, SPK_B_RHO_NEW = 12, SPK_B_BETA = 13,
              SPK_B_LEN = 14;
constexpr i32 SPK_C_ZAZ = 5, SPK_C_ZAZ_NEW = 6, SPK_C_APAP = 7, SPK_C_ALPHA = 8,
              SPK_C_BETA = 9, SPK_C_LEN = 10;
constexpr i32 SPK_G_HN = 5, SPK_G_H = 6;
/// GMRES's scalars after H ((m + 1) x m, row-major from SPK_G_H): cosines, sines (m each),
/// g (m + 1), y (m).
WP_FN i32 spk_g_cs(i32 m) { return SPK_G_H + (m + 1) * m; }
WP_FN i32 spk_g_sn(i32 m) { return spk_g_cs(m) + m; }
WP_FN i32 spk_g_g(i32 m) { return spk_g_sn(m) + m; }
WP_FN i32 spk_g_y(i32 m) { return spk_g_g(m) + m + 1; }

/// KrVec: ctl, scal, y, x, w (S*, n each; x may be y for SPK_OP_DIV), n, op, ia, ib, gate.
struct spk_vec_t {
  u64 ctl, scal, y, x, w;
  i64 n;
  i32 op, ia, ib, gate;
};
static_assert(sizeof(spk_vec_t) == 64, "spk_vec_t layout");

/// KrComb: ctl, scal, out (S*, n), v (S*, (m + 1) n: the basis), n, iy (y's first slot in
/// scal), add (1: out += sum, 0: out = sum), m.
struct spk_comb_t {
  u64 ctl, scal, out, v;
  i64 n;
  i32 iy, add, m, pad;
};
static_assert(sizeof(spk_comb_t) == 56, "spk_comb_t layout");

/// KrScalar: ctl, scal, history (S*), rtol, atol, max_iter, phase, m, j (GMRES's restart
/// length and column).
struct spk_scalar_t {
  u64 ctl, scal, history;
  f64 rtol, atol;
  i32 max_iter, phase, m, j;
};
static_assert(sizeof(spk_scalar_t) == 56, "spk_scalar_t layout");

WP_FN bool spk_open(const i32* ctl, i32 gate) {
  if (gate == SPK_GATE_RUN) return ctl[SP_CTL_STOP] == SP_STOP_NONE;
  if (gate == SPK_GATE_ACTIVE)
    return ctl[SP_CTL_STOP] == SP_STOP_NONE && ctl[SPK_CTL_ACTIVE] == 1;
  return ctl[SPK_CTL_PENDING] == 1;
}

template <typename S>
WP_FN void spk_vec(const spk_vec_t& s, i64 i) {
  if (!spk_open((const i32*)s.ctl, s.gate)) return;
  const S* sc = (const S*)s.scal;
  const S a = sc[s.ia], b = sc[s.ib];
  S* y = (S*)s.y;
  const S* x = (const S*)s.x;
  const S* w = (const S*)s.w;
  S v;
  switch (s.op) {
    case SPK_OP_AXPY: v = sp_add(y[i], sp_mul(a, x[i])); break;
    case SPK_OP_AXMY: v = sp_sub(y[i], sp_mul(a, x[i])); break;
    case SPK_OP_XPAY: v = sp_add(x[i], sp_mul(a, y[i])); break;
    case SPK_OP_P: v = sp_add(x[i], sp_mul(a, sp_sub(y[i], sp_mul(b, w[i])))); break;
    case SPK_OP_DIV: v = sp_div(x[i], a); break;
    default: v = sp_add(y[i], x[i]); break;
  }
  y[i] = v;
}

template <typename S>
WP_FN void spk_comb(const spk_comb_t& s, i64 i) {
  const i32* ctl = (const i32*)s.ctl;
  if (!spk_open(ctl, SPK_GATE_PENDING)) return;
  const i32 m = s.m < 0 ? 0 : s.m;
  i32 k = ctl[SPK_CTL_K];
  k = k < 0 ? 0 : (k > m ? m : k);
  const S* y = (const S*)s.scal + s.iy;
  const S* v = (const S*)s.v;
  S acc = (S)0;
  for (i32 kk = 0; kk < k; ++kk) acc = sp_add(acc, sp_mul(y[kk], v[(i64)kk * s.n + i]));
  S* out = (S*)s.out;
  out[i] = s.add ? sp_add(out[i], acc) : acc;
}

/// The tolerance max(atol, rtol |b|) and its square (the order of sp_cg_init).
template <typename S>
WP_FN void spk_init_tol(const spk_scalar_t& s, S* sc) {
  const S rt = sp_mul((S)s.rtol, sp_sqrt(sc[SPK_BB]));
  const S at = (S)s.atol;
  const S tol = at > rt ? at : rt;
  sc[SPK_TOL] = tol;
  sc[SPK_TOL2] = sp_mul(tol, tol);
}

template <typename S>
WP_FN void spk_breakdown(i32* ctl, S* sc, i32 what, S v) {
  sc[SPK_BREAK] = v;
  ctl[SPK_CTL_WHAT] = what;
  ctl[SP_CTL_STOP] = SP_STOP_BREAKDOWN;
}

/// The stop before any iteration of BiCGSTAB and CR: a singular preconditioner, a
/// non-finite residual (or q), convergence; SP_STOP_NONE to go on.
template <typename S>
WP_FN i32 spk_first_stop(const i32* ctl, const S* sc, S q) {
  const S rr = sc[SPK_RR];
  if (ctl[SP_CTL_BAD] != 0x7fffffff) return SP_STOP_SINGULAR;
  if (!sp_finite(rr) || !sp_finite(q)) return SP_STOP_NON_FINITE;
  if (rr <= sc[SPK_TOL2]) return SP_STOP_CONVERGED;
  return SP_STOP_NONE;
}

template <typename S>
WP_FN void spk_bicgstab(const spk_scalar_t& s, i32* ctl, S* sc, S* hist) {
  if (s.phase == 0) {
    spk_init_tol(s, sc);
    const S rr = sc[SPK_RR];
    hist[0] = sp_sqrt(rr);
    ctl[SP_CTL_ITER] = 0;
    sc[SPK_B_RHO] = rr;
    i32 stop = spk_first_stop(ctl, sc, rr);
    if (stop == SP_STOP_NONE && s.max_iter <= 0) stop = SP_STOP_MAX_ITER;
    ctl[SP_CTL_STOP] = stop;
    return;
  }
  if (ctl[SP_CTL_STOP] != SP_STOP_NONE) return;
  if (s.phase == 1) {
    const S r0v = sc[SPK_B_R0V];
    if (!sp_finite(r0v))
      ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
    else if (r0v == (S)0)
      spk_breakdown(ctl, sc, SPK_WHAT_R0V, r0v);
    else
      sc[SPK_B_ALPHA] = sp_div(sc[SPK_B_RHO], r0v);
  } else if (s.phase == 2) {
    const S ss = sc[SPK_B_SS];
    if (!sp_finite(ss))
      ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
    else if (ss <= sc[SPK_TOL2]) {
      const i32 it = ctl[SP_CTL_ITER] + 1;
      ctl[SP_CTL_ITER] = it;
      hist[it] = sp_sqrt(ss);
      ctl[SP_CTL_STOP] = SP_STOP_CONVERGED;
    }
  } else if (s.phase == 3) {
    const S ts = sc[SPK_B_TS], tt = sc[SPK_B_TT];
    if (!sp_finite(ts) || !sp_finite(tt))
      ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
    else if (tt == (S)0)
      sc[SPK_B_OMEGA] = (S)0;  // t = 0: no stabilising step (the check names the breakdown)
    else
      sc[SPK_B_OMEGA] = sp_div(ts, tt);
  } else {
    const i32 it = ctl[SP_CTL_ITER] + 1;
    ctl[SP_CTL_ITER] = it;
    const S rr = sc[SPK_RR], rho_new = sc[SPK_B_RHO_NEW], omega = sc[SPK_B_OMEGA];
    hist[it] = sp_sqrt(rr);
    if (!sp_finite(rr) || !sp_finite(rho_new))
      ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
    else if (rr <= sc[SPK_TOL2])
      ctl[SP_CTL_STOP] = SP_STOP_CONVERGED;
    else if (omega == (S)0)
      spk_breakdown(ctl, sc, SPK_WHAT_OMEGA, omega);
    else if (rho_new == (S)0)
      spk_breakdown(ctl, sc, SPK_WHAT_RHO, rho_new);
    else if (it >= s.max_iter)
      ctl[SP_CTL_STOP] = SP_STOP_MAX_ITER;
    else {
      sc[SPK_B_BETA] = sp_mul(sp_div(rho_new, sc[SPK_B_RHO]), sp_div(sc[SPK_B_ALPHA], omega));
      sc[SPK_B_RHO] = rho_new;
    }
  }
}

template <typename S>
WP_FN void spk_cr(const spk_scalar_t& s, i32* ctl, S* sc, S* hist) {
  if (s.phase == 0) {
    spk_init_tol(s, sc);
    const S rr = sc[SPK_RR];
    hist[0] = sp_sqrt(rr);
    ctl[SP_CTL_ITER] = 0;
    const S zaz = sc[SPK_C_ZAZ];
    const i32 stop = spk_first_stop(ctl, sc, zaz);
    if (stop != SP_STOP_NONE)
      ctl[SP_CTL_STOP] = stop;
    else if (zaz == (S)0)
      spk_breakdown(ctl, sc, SPK_WHAT_ZAZ, zaz);
    else if (s.max_iter <= 0)
      ctl[SP_CTL_STOP] = SP_STOP_MAX_ITER;
    else
      ctl[SP_CTL_STOP] = SP_STOP_NONE;
    return;
  }
  if (ctl[SP_CTL_STOP] != SP_STOP_NONE) return;
  if (s.phase == 1) {
    const S apap = sc[SPK_C_APAP];
    if (!sp_finite(apap))
      ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
    else if (apap == (S)0)
      spk_breakdown(ctl, sc, SPK_WHAT_APAP, apap);
    else
      sc[SPK_C_ALPHA] = sp_div(sc[SPK_C_ZAZ], apap);
    return;
  }
  const i32 it = ctl[SP_CTL_ITER] + 1;
  ctl[SP_CTL_ITER] = it;
  const S rr = sc[SPK_RR], zn = sc[SPK_C_ZAZ_NEW];
  hist[it] = sp_sqrt(rr);
  if (!sp_finite(rr) || !sp_finite(zn))
    ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
  else if (rr <= sc[SPK_TOL2])
    ctl[SP_CTL_STOP] = SP_STOP_CONVERGED;
  else if (zn == (S)0)
    spk_breakdown(ctl, sc, SPK_WHAT_ZAZ, zn);
  else if (it >= s.max_iter)
    ctl[SP_CTL_STOP] = SP_STOP_MAX_ITER;
  else {
    sc[SPK_C_BETA] = sp_div(zn, sc[SPK_C_ZAZ]);
    sc[SPK_C_ZAZ] = zn;
  }
}

/// GMRES's cycle start: from |r|^2 in SPK_RR, the true residual norm replaces the history's
/// last entry; then a stop (non-finite, converged, max_iter) or g = (|r|, 0, ..) and the cycle
/// active and pending.
template <typename S>
WP_FN void spk_gmres_start(const spk_scalar_t& s, i32* ctl, S* sc, S* hist) {
  const i32 m = s.m;
  ctl[SPK_CTL_ACTIVE] = 0;
  ctl[SPK_CTL_PENDING] = 0;
  ctl[SPK_CTL_K] = 0;
  if (ctl[SP_CTL_STOP] != SP_STOP_NONE) return;
  const S rr = sc[SPK_RR];
  const S beta = sp_sqrt(rr);
  const i32 it = ctl[SP_CTL_ITER];
  hist[it] = beta;
  if (!sp_finite(rr))
    ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
  else if (rr <= sc[SPK_TOL2])
    ctl[SP_CTL_STOP] = SP_STOP_CONVERGED;
  else if (it >= s.max_iter)
    ctl[SP_CTL_STOP] = SP_STOP_MAX_ITER;
  else {
    const i32 g = spk_g_g(m);
    sc[g] = beta;
    for (i32 i = 1; i <= m; ++i) sc[g + i] = (S)0;
    ctl[SPK_CTL_ACTIVE] = 1;
    ctl[SPK_CTL_PENDING] = 1;
  }
}

/// GMRES's Arnoldi check of column j: H's new entry |w|, the earlier rotations applied to the
/// column, its own rotation, g rotated, the iteration counted with |g_(j+1)| as its residual;
/// then a stop, or the cycle's end at j = m - 1.
template <typename S>
WP_FN void spk_gmres_column(const spk_scalar_t& s, i32* ctl, S* sc, S* hist) {
  if (ctl[SP_CTL_STOP] != SP_STOP_NONE || ctl[SPK_CTL_ACTIVE] != 1) return;
  const i32 m = s.m, j = s.j;
#define SPK_H(i) sc[SPK_G_H + (i) * m + j]
  const S hn = sp_sqrt(sc[SPK_G_HN]);
  sc[SPK_G_HN] = hn;
  bool finite = sp_finite(hn);
  for (i32 i = 0; i <= j; ++i) finite = finite && sp_finite(SPK_H(i));
  if (!finite) {
    ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
    ctl[SPK_CTL_ACTIVE] = 0;
    ctl[SPK_CTL_PENDING] = 0;
    return;
  }
  SPK_H(j + 1) = hn;
  const i32 cs = spk_g_cs(m), sn = spk_g_sn(m), g = spk_g_g(m);
  for (i32 i = 0; i < j; ++i) {
    const S a = SPK_H(i), b = SPK_H(i + 1);
    const S cc = sc[cs + i], ss = sc[sn + i];
    SPK_H(i) = sp_add(sp_mul(cc, a), sp_mul(ss, b));
    SPK_H(i + 1) = sp_sub(sp_mul(cc, b), sp_mul(ss, a));
  }
  const S a = SPK_H(j), b = SPK_H(j + 1);
  const S rho = sp_sqrt(sp_add(sp_mul(a, a), sp_mul(b, b)));
  if (rho == (S)0) {
    // The column is zero: H is singular. The cycle's earlier columns still update x.
    spk_breakdown(ctl, sc, SPK_WHAT_HJJ, rho);
    ctl[SPK_CTL_ACTIVE] = 0;
    return;
  }
  const S cc = sp_div(a, rho), ss = sp_div(b, rho);
  sc[cs + j] = cc;
  sc[sn + j] = ss;
  SPK_H(j) = rho;
  SPK_H(j + 1) = (S)0;
#undef SPK_H
  const S gj = sc[g + j];
  sc[g + j + 1] = sp_sub((S)0, sp_mul(ss, gj));
  sc[g + j] = sp_mul(cc, gj);
  ctl[SPK_CTL_K] = j + 1;
  const i32 it = ctl[SP_CTL_ITER] + 1;
  ctl[SP_CTL_ITER] = it;
  const S gn = sc[g + j + 1];
  const S res = gn < (S)0 ? sp_sub((S)0, gn) : gn;
  hist[it] = res;
  if (!sp_finite(res) || !sp_finite(rho)) {
    ctl[SP_CTL_STOP] = SP_STOP_NON_FINITE;
    ctl[SPK_CTL_PENDING] = 0;
  } else if (res <= sc[SPK_TOL])
    ctl[SP_CTL_STOP] = SP_STOP_CONVERGED;
  else if (it >= s.max_iter)
    ctl[SP_CTL_STOP] = SP_STOP_MAX_ITER;
  if (ctl[SP_CTL_STOP] != SP_STOP_NONE || j + 1 == m) ctl[SPK_CTL_ACTIVE] = 0;
}

/// GMRES's least-squares solve while pending: H y = g over the cycle's K columns (H upper
/// triangular after the rotations), by back substitution.
template <typename S>
WP_FN void spk_gmres_solve(const spk_scalar_t& s, const i32* ctl, S* sc) {
  if (ctl[SPK_CTL_PENDING] != 1) return;
  const i32 m = s.m;
  i32 k = ctl[SPK_CTL_K];
  k = k < 0 ? 0 : (k > m ? m : k);
  const i32 g = spk_g_g(m), y = spk_g_y(m);
  for (i32 i = k - 1; i >= 0; --i) {
    S acc = sc[g + i];
    for (i32 l = i + 1; l < k; ++l) acc = sp_sub(acc, sp_mul(sc[SPK_G_H + i * m + l], sc[y + l]));
    sc[y + i] = sp_div(acc, sc[SPK_G_H + i * m + i]);
  }
}

template <typename S>
WP_FN void spk_gmres(const spk_scalar_t& s, i32* ctl, S* sc, S* hist) {
  switch (s.phase) {
    case 0:
      spk_init_tol(s, sc);
      ctl[SP_CTL_ITER] = 0;
      if (ctl[SP_CTL_BAD] != 0x7fffffff) {
        ctl[SP_CTL_STOP] = SP_STOP_SINGULAR;
        hist[0] = sp_sqrt(sc[SPK_RR]);
      }
      spk_gmres_start(s, ctl, sc, hist);
      break;
    case 1: spk_gmres_start(s, ctl, sc, hist); break;
    case 2: spk_gmres_column(s, ctl, sc, hist); break;
    case 3: spk_gmres_solve(s, ctl, sc); break;
    default: ctl[SPK_CTL_PENDING] = 0; break;
  }
}

/// One method's one-thread step (0 BiCGSTAB, 1 CR, 2 GMRES), then the loop's flag.
template <typename S, int METHOD>
WP_FN void spk_scalar(const spk_scalar_t& s) {
  i32* ctl = (i32*)s.ctl;
  S* sc = (S*)s.scal;
  S* hist = (S*)s.history;
  if (METHOD == 0)
    spk_bicgstab(s, ctl, sc, hist);
  else if (METHOD == 1)
    spk_cr(s, ctl, sc, hist);
  else
    spk_gmres(s, ctl, sc, hist);
  ctl[SP_CTL_RUN] = ctl[SP_CTL_STOP] == SP_STOP_NONE;
}

}  // namespace wp

#if defined(WP_SPARSE_BUILD) && (defined(__CUDACC__) || defined(WP_SPARSE_EMULATED))
// The Krylov kernels of one scalar type.
#define WP_SPK_SCALAR_KERNELS(tag, S)                                                       \
  extern "C" __global__ void wp_sparse_kr_vec_##tag(wp::spk_vec_t s) {                      \
    WP_SP_LOOP(i, s.n) wp::spk_vec<S>(s, i);                                                \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_kr_comb_##tag(wp::spk_comb_t s) {                    \
    WP_SP_LOOP(i, s.n) wp::spk_comb<S>(s, i);                                               \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_bicgstab_scalar_##tag(wp::spk_scalar_t s) {          \
    if (blockIdx.x == 0 && threadIdx.x == 0) wp::spk_scalar<S, 0>(s);                       \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_cr_scalar_##tag(wp::spk_scalar_t s) {                \
    if (blockIdx.x == 0 && threadIdx.x == 0) wp::spk_scalar<S, 1>(s);                       \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_gmres_scalar_##tag(wp::spk_scalar_t s) {             \
    if (blockIdx.x == 0 && threadIdx.x == 0) wp::spk_scalar<S, 2>(s);                       \
  }

WP_SPK_SCALAR_KERNELS(f32, wp::f32)
WP_SPK_SCALAR_KERNELS(f64, wp::f64)
#endif

// ==========================================================================================
// Adjoints (slice 5: warp-runtime's sparse/adjoint.rs, whose CPU bodies run the same order of
// operations; the solves' records in sparse/solve/adjoint.rs queue them). No float atomics:
// each thread owns what it writes.
//   adj_tpl      per sorted triplet k: tgrad[idx[k]] += vgrad[pos[k] - 1] (scalar by scalar)
//                when its sorted key is below the sentinel (an assembled triplet): the
//                assembly's adjoint, over from_triplets' kept sort.
//   adj_axpby    per element: y = a y + b x (x 0: y = a y).
//   adj_outer    per stored block k < nnz: with r its block row (a binary search of the
//                offsets) and c its column (skipped outside [0, ncol)), grad_k(i, j) +=
//                alpha (u[r R + i] v[c C + j]).
// ==========================================================================================
namespace wp {

/// AdjTpl: count (as the triplet steps'), idx, pos (i32*), keys (u32*), vgrad, tgrad (S*,
/// `block` scalars per block / triplet), n, block, sentinel.
struct sp_adj_tpl_t {
  u64 count, idx, pos, keys, vgrad, tgrad;
  i32 n, block;
  u32 sentinel;
  i32 pad;
};
static_assert(sizeof(sp_adj_tpl_t) == 64, "sp_adj_tpl_t layout");

/// AdjAxpby: y, x (S*, n each; x 0 for none), a, b (as f64, rounded to S), n.
struct sp_adj_axpby_t {
  u64 y, x;
  f64 a, b;
  i64 n;
};
static_assert(sizeof(sp_adj_axpby_t) == 40, "sp_adj_axpby_t layout");

/// AdjOuter: offsets, columns (i32*), grad (S*, cap blocks of rows x cols), u (S*, nrow rows),
/// v (S*, ncol cols), alpha (as f64, rounded to S), nrow, ncol, cap, rows, cols, cm (1:
/// column-major blocks).
struct sp_adj_outer_t {
  u64 offsets, columns, grad, u, v;
  f64 alpha;
  i32 nrow, ncol, cap, rows, cols, cm;
};
static_assert(sizeof(sp_adj_outer_t) == 72, "sp_adj_outer_t layout");

template <typename S>
WP_FN void sp_adj_tpl(const sp_adj_tpl_t& s, i32 k) {
  if (((const u32*)s.keys)[k] >= s.sentinel) return;
  const i64 t = ((const i32*)s.idx)[k];
  const i64 blk = (i64)((const i32*)s.pos)[k] - 1;
  const S* g = (const S*)s.vgrad + blk * s.block;
  S* o = (S*)s.tgrad + t * s.block;
  for (i32 e = 0; e < s.block; ++e) o[e] = sp_add(o[e], g[e]);
}

template <typename S>
WP_FN void sp_adj_axpby(const sp_adj_axpby_t& s, i64 i) {
  S* y = (S*)s.y;
  const S ay = sp_mul((S)s.a, y[i]);
  y[i] = s.x != 0 ? sp_add(ay, sp_mul((S)s.b, ((const S*)s.x)[i])) : ay;
}

/// The block row of stored block k: the last r < nrow with offsets[r] <= k, by binary search
/// over [1, nrow) (Rust's `block_row`; nrow >= 1).
WP_FN i32 sp_adj_block_row(const i32* offsets, i32 nrow, i32 k) {
  i32 lo = 1, hi = nrow;
  while (lo < hi) {
    const i32 mid = lo + (hi - lo) / 2;
    if (offsets[mid] <= k)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo - 1;
}

/// The clamped block count, as `sp_row_range` clamps it: offsets[nrow] in [0, cap].
WP_FN i32 sp_adj_nnz(const sp_adj_outer_t& s) {
  const i32 v = ((const i32*)s.offsets)[s.nrow];
  const i32 cap = s.cap < 0 ? 0 : s.cap;
  return v < 0 ? 0 : (v > cap ? cap : v);
}

template <typename S>
WP_FN void sp_adj_outer(const sp_adj_outer_t& s, i32 k) {
  const i32 r = sp_adj_block_row((const i32*)s.offsets, s.nrow, k);
  const i32 c = ((const i32*)s.columns)[k];
  if (c < 0 || c >= s.ncol) return;
  const S* u = (const S*)s.u + (i64)r * s.rows;
  const S* v = (const S*)s.v + (i64)c * s.cols;
  S* g = (S*)s.grad + (i64)k * s.rows * s.cols;
  const S alpha = (S)s.alpha;
  for (i32 i = 0; i < s.rows; ++i)
    for (i32 j = 0; j < s.cols; ++j) {
      const i32 e = s.cm ? j * s.rows + i : i * s.cols + j;
      g[e] = sp_add(g[e], sp_mul(alpha, sp_mul(u[i], v[j])));
    }
}

}  // namespace wp

#if defined(WP_SPARSE_BUILD) && (defined(__CUDACC__) || defined(WP_SPARSE_EMULATED))
// The adjoint kernels of one scalar type.
#define WP_SPA_SCALAR_KERNELS(tag, S)                                                       \
  extern "C" __global__ void wp_sparse_adj_tpl_##tag(wp::sp_adj_tpl_t s) {                  \
    WP_SP_LOOP(k, wp::sp_count(s.count, s.n)) wp::sp_adj_tpl<S>(s, (wp::i32)k);             \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_adj_axpby_##tag(wp::sp_adj_axpby_t s) {              \
    WP_SP_LOOP(i, s.n) wp::sp_adj_axpby<S>(s, i);                                           \
  }                                                                                         \
  extern "C" __global__ void wp_sparse_adj_outer_##tag(wp::sp_adj_outer_t s) {              \
    if (s.nrow > 0) WP_SP_LOOP(k, wp::sp_adj_nnz(s)) wp::sp_adj_outer<S>(s, (wp::i32)k);    \
  }

WP_SPA_SCALAR_KERNELS(f32, wp::f32)
WP_SPA_SCALAR_KERNELS(f64, wp::f64)
#endif

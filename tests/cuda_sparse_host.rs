//! The sparse tier's CUDA steps (`warp-cuda/cuda/wp_sparse.h`, the kernels themselves),
//! checked without a GPU: compiled with g++ under the block emulator
//! (`warp-cuda/cuda/tests/wp_prim_emu.h`: a block's threads are fibers, `__syncthreads` a
//! barrier, blocks one after another), launched with small blocks and grids so the
//! grid-stride loops wrap and the dot product's blocks loop over several chunks, and compared
//! bit for bit with the CPU backend's bodies through the public API (`warp_runtime::sparse`):
//! triplet assembly (the sort is the host's stable sort here, as the primitives' radix sort is
//! stable on both backends), `mv` for every block type, `dot`, and whole CG solves (every
//! step of the solver, with and without Jacobi). What this cannot check: NVRTC's acceptance
//! of the CUDA-only lines (the rounded intrinsics, `atomicMin`), and hardware scheduling; the
//! suite's `sparse::cuda_backend` tests and `hash_grid::nvrtc_compiles_the_build_kernels` do,
//! on a machine with a GPU.
//!
//! Skipped, saying so, without g++.

use glam::{DMat2, DMat3, DMat4, Mat2, Mat3, Mat4};
use std::process::Command;
use std::sync::OnceLock;
use warp_lang as wp;
use warp_runtime::sparse::{self, Block, Bsr, Precond, SolveOptions, SparseScalar, Stop};

#[path = "common/host_cpp.rs"]
mod host_cpp;

/// The driver: reads u64 words (a command, then its data; f32 scalars in the low 32 bits),
/// runs the header's kernels under the emulator, prints hex words.
const DRIVER: &str = r#"
#include <algorithm>
#include <cstdio>
#include <functional>
#include <vector>
#include "wp_prim_emu.h"
namespace wp_sp_emu {
inline unsigned threads = 1, blocks = 1;
}
#define __global__
#define __device__ inline
#define __shared__ static
#define blockIdx (::wp_emu::dim3_t{(unsigned)::wp_emu::bid, 0u, 0u})
#define blockDim (::wp_emu::dim3_t{::wp_sp_emu::threads, 1u, 1u})
#define gridDim (::wp_emu::dim3_t{::wp_sp_emu::blocks, 1u, 1u})
#include "wp_sparse.h"
#include "wp_sparse_ops.h"
#include "wp_sparse_color.h"
using namespace wp;

template <typename A>
void run(void (*k)(A), unsigned blocks, unsigned threads, const A& a) {
  wp_sp_emu::blocks = blocks;
  wp_sp_emu::threads = threads;
  wp_emu::launch(k, (long long)blocks, (int)threads, a);
}

std::vector<u64> in;
size_t at = 0;
u64 word() { return in.at(at++); }
template <typename T> T scalar() {
  const u64 w = word();
  T x;
  if (sizeof(T) == 4) { const u32 u = (u32)w; memcpy(&x, &u, 4); } else memcpy(&x, &w, 8);
  return x;
}
template <typename T> std::vector<T> scalars(size_t n) {
  std::vector<T> v(n + 1);  // one spare: never a null pointer
  for (size_t i = 0; i < n; ++i) v[i] = scalar<T>();
  return v;
}
std::vector<i32> ints(size_t n) {
  std::vector<i32> v(n + 1);
  for (size_t i = 0; i < n; ++i) v[i] = (i32)(i64)word();
  return v;
}
template <typename T> void print(const T* v, size_t n) {
  for (size_t i = 0; i < n; ++i) {
    u64 w = 0;
    memcpy(&w, &v[i], sizeof(T));
    printf("%llx\n", (unsigned long long)w);
  }
}
u64 addr(const void* p) { return (u64)p; }

// The kernels of one block type.
struct BlockKernels {
  void (*mv)(sp_bsr_mv_t);
  void (*jacobi)(sp_jacobi_inv_t);
  int rows, cols;
};
// The kernels of one scalar type.
struct ScalarKernels {
  void (*keys)(sp_tpl_keys_t);
  void (*report)(sp_tpl_report_t);
  void (*sum)(sp_tpl_sum_t);
  void (*partials)(sp_dot_t);
  void (*final_)(sp_dot_t);
  void (*apply)(sp_jacobi_apply_t);
  void (*init)(sp_cg_scalar_t);
  void (*check)(sp_cg_scalar_t);
  void (*update)(sp_cg_vector_t);
  void (*direction)(sp_cg_vector_t);
};
#define SK(t) ScalarKernels{wp_sparse_tpl_keys_##t, wp_sparse_tpl_report_##t, wp_sparse_tpl_sum_##t, \
    wp_sparse_dot_partials_##t, wp_sparse_dot_final_##t, wp_sparse_jacobi_apply_##t,             \
    wp_sparse_cg_init_##t, wp_sparse_cg_check_##t, wp_sparse_cg_update_##t,                      \
    wp_sparse_cg_direction_##t}
const BlockKernels BLOCKS[32] = {
    {wp_sparse_bsr_mv_f32, wp_sparse_jacobi_inv_f32, 1, 1},
    {wp_sparse_bsr_mv_f64, wp_sparse_jacobi_inv_f64, 1, 1},
    {wp_sparse_bsr_mv_mat2, wp_sparse_jacobi_inv_mat2, 2, 2},
    {wp_sparse_bsr_mv_mat3, wp_sparse_jacobi_inv_mat3, 3, 3},
    {wp_sparse_bsr_mv_mat4, wp_sparse_jacobi_inv_mat4, 4, 4},
    {wp_sparse_bsr_mv_dmat2, wp_sparse_jacobi_inv_dmat2, 2, 2},
    {wp_sparse_bsr_mv_dmat3, wp_sparse_jacobi_inv_dmat3, 3, 3},
    {wp_sparse_bsr_mv_dmat4, wp_sparse_jacobi_inv_dmat4, 4, 4},
    // The rectangular blocks (wp_sparse_ops.h; no Jacobi), f32 then f64, R then C ascending.
    {wp_sparse_bsr_mv_mat23, nullptr, 2, 3},
    {wp_sparse_bsr_mv_mat24, nullptr, 2, 4},
    {wp_sparse_bsr_mv_mat26, nullptr, 2, 6},
    {wp_sparse_bsr_mv_mat32, nullptr, 3, 2},
    {wp_sparse_bsr_mv_mat34, nullptr, 3, 4},
    {wp_sparse_bsr_mv_mat36, nullptr, 3, 6},
    {wp_sparse_bsr_mv_mat42, nullptr, 4, 2},
    {wp_sparse_bsr_mv_mat43, nullptr, 4, 3},
    {wp_sparse_bsr_mv_mat46, nullptr, 4, 6},
    {wp_sparse_bsr_mv_mat62, nullptr, 6, 2},
    {wp_sparse_bsr_mv_mat63, nullptr, 6, 3},
    {wp_sparse_bsr_mv_mat64, nullptr, 6, 4},
    {wp_sparse_bsr_mv_dmat23, nullptr, 2, 3},
    {wp_sparse_bsr_mv_dmat24, nullptr, 2, 4},
    {wp_sparse_bsr_mv_dmat26, nullptr, 2, 6},
    {wp_sparse_bsr_mv_dmat32, nullptr, 3, 2},
    {wp_sparse_bsr_mv_dmat34, nullptr, 3, 4},
    {wp_sparse_bsr_mv_dmat36, nullptr, 3, 6},
    {wp_sparse_bsr_mv_dmat42, nullptr, 4, 2},
    {wp_sparse_bsr_mv_dmat43, nullptr, 4, 3},
    {wp_sparse_bsr_mv_dmat46, nullptr, 4, 6},
    {wp_sparse_bsr_mv_dmat62, nullptr, 6, 2},
    {wp_sparse_bsr_mv_dmat63, nullptr, 6, 3},
    {wp_sparse_bsr_mv_dmat64, nullptr, 6, 4},
};

// Small launches: 3 blocks of 32 threads (the grid-stride loops wrap); the dot's partials 2
// blocks of 256 (each loops over several chunks), its final one block of 256.
constexpr unsigned GB = 3, GT = 32;

struct Matrix {
  i32 nrow, ncol, nnz;
  std::vector<i32> offsets, columns;
};
template <typename S> Matrix matrix(const BlockKernels& k, std::vector<S>& values) {
  Matrix m;
  m.nrow = (i32)word();
  m.ncol = (i32)word();
  m.nnz = (i32)word();
  m.offsets = ints(m.nrow + 1);
  m.columns = ints(m.nnz);
  values = scalars<S>((size_t)m.nnz * k.rows * k.cols);
  return m;
}

template <typename S> void mv(const BlockKernels& k) {
  std::vector<S> values;
  Matrix m = matrix<S>(k, values);
  std::vector<S> x = scalars<S>((size_t)m.ncol * k.cols);
  std::vector<S> y = scalars<S>((size_t)m.nrow * k.rows);
  const f64 alpha = scalar<f64>(), beta = scalar<f64>();
  const i32 lanes = (i32)word();
  run(k.mv, GB, GT,
      sp_bsr_mv_t{addr(m.offsets.data()), addr(m.columns.data()), addr(values.data()),
                  addr(x.data()), addr(y.data()), alpha, beta, m.nrow, m.ncol,
                  m.nnz, lanes});
  print(y.data(), (size_t)m.nrow * k.rows);
}

template <typename S> void dot_into(const ScalarKernels& k, const S* a, const S* b, i64 n, S* out) {
  const i64 chunks = std::max<i64>(1, (n + SP_DOT_CHUNK - 1) / SP_DOT_CHUNK);
  std::vector<S> partials(chunks);
  run(k.partials, 2, (unsigned)SP_DOT_LANES, sp_dot_t{addr(a), addr(b), n, addr(partials.data()), chunks});
  run(k.final_, 1, (unsigned)SP_DOT_LANES, sp_dot_t{addr(partials.data()), 0, chunks, addr(out), chunks});
}

template <typename S> void dot(const ScalarKernels& k) {
  const i64 n = (i64)word();
  std::vector<S> a = scalars<S>(n), b = scalars<S>(n);
  S out = (S)-1;
  dot_into(k, a.data(), b.data(), n, &out);
  print(&out, 1);
}

// The steps of warp-runtime's sparse/solve.rs, in its order (check_every iterations between
// two reads of the control words).
template <typename S> void cg(const BlockKernels& bk, const ScalarKernels& k) {
  std::vector<S> values;
  Matrix m = matrix<S>(bk, values);
  const i64 n = (i64)m.nrow * bk.rows;
  std::vector<S> b = scalars<S>(n), x = scalars<S>(n);
  const i32 pre = (i32)word();
  const f64 rtol = scalar<f64>(), atol = scalar<f64>();
  const i32 max_iter = (i32)word(), every = (i32)word();
  std::vector<S> r(b), p(n + 1), ap(n + 1), z(n + 1), scal(SP_TOL + 1), hist(max_iter + 1);
  std::vector<S> dinv((size_t)m.nrow * bk.rows * bk.rows + 1);
  std::vector<i32> ctl = {0, 0, 0x7fffffff, 0};
  auto mvk = [&](const S* xv, S* yv, f64 al, f64 be) {
    run(bk.mv, GB, GT, sp_bsr_mv_t{addr(m.offsets.data()), addr(m.columns.data()),
                                   addr(values.data()), addr(xv), addr(yv), al, be, m.nrow, m.ncol,
                                   m.nnz, 0});
  };
  S* zp = pre ? z.data() : r.data();
  auto apply = [&]() {
    run(k.apply, GB, GT, sp_jacobi_apply_t{addr(dinv.data()), addr(r.data()), addr(z.data()), m.nrow, bk.rows});
  };
  const sp_cg_scalar_t sc{addr(ctl.data()), addr(scal.data()), addr(hist.data()), rtol, atol, max_iter, 0};
  mvk(x.data(), r.data(), -1.0, 1.0);
  if (pre) {
    run(bk.jacobi, GB, GT, sp_jacobi_inv_t{addr(m.offsets.data()), addr(m.columns.data()),
                                           addr(values.data()), addr(dinv.data()),
                                           addr(&ctl[SP_CTL_BAD]), m.nrow, pre == 2, m.nnz, 0});
    apply();
  }
  for (i64 i = 0; i < n; ++i) p[i] = zp[i];
  dot_into(k, b.data(), b.data(), n, &scal[SP_BB]);
  dot_into(k, r.data(), zp, n, &scal[SP_RZ]);
  dot_into(k, r.data(), r.data(), n, &scal[SP_RR]);
  run(k.init, 1, 1, sc);
  i32 queued = 0;
  while (ctl[SP_CTL_STOP] == SP_STOP_NONE && queued < max_iter) {
    for (i32 j = 0; j < every && queued < max_iter; ++j, ++queued) {
      mvk(p.data(), ap.data(), 1.0, 0.0);
      dot_into(k, p.data(), ap.data(), n, &scal[SP_PAP]);
      run(k.update, GB, GT, sp_cg_vector_t{addr(ctl.data()), addr(scal.data()), addr(x.data()),
                                           addr(r.data()), addr(p.data()), addr(ap.data()), n});
      if (pre) apply();
      dot_into(k, r.data(), zp, n, &scal[SP_RZ_NEW]);
      dot_into(k, r.data(), r.data(), n, &scal[SP_RR]);
      run(k.check, 1, 1, sc);
      run(k.direction, GB, GT, sp_cg_vector_t{addr(ctl.data()), addr(scal.data()), 0, addr(zp),
                                              addr(p.data()), 0, n});
    }
  }
  printf("%d %d %d\n", ctl[SP_CTL_STOP], ctl[SP_CTL_ITER], ctl[SP_CTL_BAD]);
  print(hist.data(), (size_t)ctl[SP_CTL_ITER] + 1);
  print(x.data(), (size_t)n);
}

// The Krylov kernels of one scalar type.
struct KrylovKernels {
  void (*vec)(spk_vec_t);
  void (*comb)(spk_comb_t);
  void (*scalar[3])(spk_scalar_t);
};
#define KK(t) KrylovKernels{wp_sparse_kr_vec_##t, wp_sparse_kr_comb_##t, \
    {wp_sparse_bicgstab_scalar_##t, wp_sparse_cr_scalar_##t, wp_sparse_gmres_scalar_##t}}

// The steps of warp-runtime's sparse/solve/{bicgstab,cr,gmres}.rs, in their order, under
// the drivers of sparse/solve/mod.rs (`drive`, Host mode): method 0 BiCGSTAB, 1 CR, 2 GMRES.
template <typename S> void krylov(const BlockKernels& bk, const ScalarKernels& k,
                                  const KrylovKernels& kk) {
  std::vector<S> values;
  Matrix mat = matrix<S>(bk, values);
  const i64 n = (i64)mat.nrow * bk.rows;
  std::vector<S> b = scalars<S>(n), x = scalars<S>(n);
  const i32 method = (i32)word(), pre = (i32)word();
  const f64 rtol = scalar<f64>(), atol = scalar<f64>();
  const i32 max_iter = (i32)word(), every = (i32)word(), m = (i32)word();
  const i32 len = method == 0 ? SPK_B_LEN : method == 1 ? SPK_C_LEN : spk_g_y(m) + m;
  std::vector<S> scal(len + 1), hist(max_iter + 1), r(n + 1), partials(1);
  std::vector<S> dinv((size_t)mat.nrow * bk.rows * bk.rows + 1);
  std::vector<i32> ctl(SPK_CTL_LEN), ctl0(SPK_CTL_LEN, 0);
  ctl0[SP_CTL_BAD] = 0x7fffffff;
  // The method's vectors: 8 of n (BiCGSTAB, CR), or the basis of m + 1 and one more (GMRES).
  std::vector<std::vector<S>> vs(8, std::vector<S>(n + 1));
  std::vector<S> basis((size_t)(m + 1) * n + 1);
  auto A = [](std::vector<S>& v) { return addr(v.data()); };
  auto mvk = [&](u64 xv, u64 yv, f64 al, f64 be) {
    run(bk.mv, GB, GT, sp_bsr_mv_t{addr(mat.offsets.data()), addr(mat.columns.data()),
                                   addr(values.data()), xv, yv, al, be, mat.nrow, mat.ncol,
                                   mat.nnz, 0});
  };
  auto dot = [&](u64 a, u64 bb, i32 slot) { dot_into(k, (const S*)a, (const S*)bb, n, &scal[slot]); };
  auto apply = [&](u64 rv, u64 zv) {
    if (pre) run(k.apply, GB, GT, sp_jacobi_apply_t{A(dinv), rv, zv, mat.nrow, bk.rows});
  };
  auto vec = [&](i32 op, u64 y, u64 xv, u64 w, i32 ia, i32 ib, i32 gate) {
    run(kk.vec, GB, GT, spk_vec_t{addr(ctl.data()), A(scal), y, xv, w, n, op, ia, ib, gate});
  };
  auto sc = [&](i32 phase, i32 j) {
    run(kk.scalar[method], 1, 1, spk_scalar_t{addr(ctl.data()), A(scal), A(hist), rtol, atol,
                                              max_iter, phase, m, j});
  };
  auto residual = [&]() {
    for (i64 i = 0; i < n; ++i) r[i] = b[i];
    mvk(A(x), A(r), -1.0, 1.0);
  };
  auto setup = [&]() {
    ctl = ctl0;
    residual();
    if (pre)
      run(bk.jacobi, GB, GT, sp_jacobi_inv_t{addr(mat.offsets.data()), addr(mat.columns.data()),
                                             A(values), A(dinv), addr(&ctl[SP_CTL_BAD]),
                                             mat.nrow, pre == 2, mat.nnz, 0});
    dot(A(b), A(b), SPK_BB);
    dot(A(r), A(r), SPK_RR);
  };
  auto copy = [&](std::vector<S>& to, const std::vector<S>& from) {
    for (i64 i = 0; i < n; ++i) to[i] = from[i];
  };
  const u64 rr = A(r), xx = A(x);
  // BiCGSTAB: r0 p v t p^ s^; CR: p Ap Az z q.
  std::vector<S>&r0 = vs[0], &p = vs[1], &v = vs[2], &t = vs[3], &ph = vs[4], &sh = vs[5];
  std::vector<S>&ap = vs[2], &az = vs[3], &z = vs[4], &q = vs[5];
  std::vector<S>& gz = vs[6];
  auto vb = [&](i32 kidx) { return A(basis) + (u64)kidx * (u64)n * sizeof(S); };
  std::function<void()> unit;
  if (method == 0) {
    setup();
    copy(r0, r);
    copy(p, r);
    sc(0, 0);
    unit = [&]() {
      const u64 phat = pre ? A(ph) : A(p), shat = pre ? A(sh) : rr;
      apply(A(p), phat);
      mvk(phat, A(v), 1.0, 0.0);
      dot(A(r0), A(v), SPK_B_R0V);
      sc(1, 0);
      vec(SPK_OP_AXPY, xx, phat, 0, SPK_B_ALPHA, 0, SPK_GATE_RUN);
      vec(SPK_OP_AXMY, rr, A(v), 0, SPK_B_ALPHA, 0, SPK_GATE_RUN);
      dot(rr, rr, SPK_B_SS);
      sc(2, 0);
      apply(rr, shat);
      mvk(shat, A(t), 1.0, 0.0);
      dot(A(t), rr, SPK_B_TS);
      dot(A(t), A(t), SPK_B_TT);
      sc(3, 0);
      vec(SPK_OP_AXPY, xx, shat, 0, SPK_B_OMEGA, 0, SPK_GATE_RUN);
      vec(SPK_OP_AXMY, rr, A(t), 0, SPK_B_OMEGA, 0, SPK_GATE_RUN);
      dot(rr, rr, SPK_RR);
      dot(A(r0), rr, SPK_B_RHO_NEW);
      sc(4, 0);
      vec(SPK_OP_P, A(p), rr, A(v), SPK_B_BETA, SPK_B_OMEGA, SPK_GATE_RUN);
    };
  } else if (method == 1) {
    const u64 zz = pre ? A(z) : rr;
    setup();
    apply(rr, zz);
    for (i64 i = 0; i < n; ++i) p[i] = ((const S*)zz)[i];
    mvk(zz, A(az), 1.0, 0.0);
    copy(ap, az);
    dot(zz, A(az), SPK_C_ZAZ);
    sc(0, 0);
    unit = [&, zz]() {
      const u64 qq = pre ? A(q) : A(ap);
      apply(A(ap), qq);
      dot(A(ap), qq, SPK_C_APAP);
      sc(1, 0);
      vec(SPK_OP_AXPY, xx, A(p), 0, SPK_C_ALPHA, 0, SPK_GATE_RUN);
      vec(SPK_OP_AXMY, rr, A(ap), 0, SPK_C_ALPHA, 0, SPK_GATE_RUN);
      apply(rr, zz);
      mvk(zz, A(az), 1.0, 0.0);
      dot(zz, A(az), SPK_C_ZAZ_NEW);
      dot(rr, rr, SPK_RR);
      sc(2, 0);
      vec(SPK_OP_XPAY, A(p), zz, 0, SPK_C_BETA, 0, SPK_GATE_RUN);
      vec(SPK_OP_XPAY, A(ap), A(az), 0, SPK_C_BETA, 0, SPK_GATE_RUN);
    };
  } else {
    setup();
    sc(0, 0);
    unit = [&]() {
      vec(SPK_OP_DIV, vb(0), rr, 0, spk_g_g(m), 0, SPK_GATE_ACTIVE);
      for (i32 j = 0; j < m; ++j) {
        const u64 vj = vb(j), wv = vb(j + 1), zj = pre ? A(gz) : vj;
        apply(vj, zj);
        mvk(zj, wv, 1.0, 0.0);
        for (i32 i = 0; i <= j; ++i) {
          const i32 h = SPK_G_H + i * m + j;
          dot(wv, vb(i), h);
          vec(SPK_OP_AXMY, wv, vb(i), 0, h, 0, SPK_GATE_ACTIVE);
        }
        dot(wv, wv, SPK_G_HN);
        sc(2, j);
        vec(SPK_OP_DIV, wv, wv, 0, SPK_G_HN, 0, SPK_GATE_ACTIVE);
      }
      sc(3, 0);
      if (pre) {
        run(kk.comb, GB, GT, spk_comb_t{addr(ctl.data()), A(scal), rr, A(basis), n, spk_g_y(m), 0, m, 0});
        apply(rr, A(gz));
        vec(SPK_OP_ADD, xx, A(gz), 0, 0, 0, SPK_GATE_PENDING);
      } else {
        run(kk.comb, GB, GT, spk_comb_t{addr(ctl.data()), A(scal), xx, A(basis), n, spk_g_y(m), 1, m, 0});
      }
      sc(4, 0);
      residual();
      dot(rr, rr, SPK_RR);
      sc(1, 0);
    };
  }
  const i32 per_unit = method == 2 ? m : 1;
  const i32 per_check = std::max(1, every / per_unit);
  const i32 max_units = (max_iter + per_unit - 1) / per_unit;
  i32 queued = 0;
  while (ctl[SP_CTL_STOP] == SP_STOP_NONE && queued < max_units)
    for (i32 j = 0; j < std::min(per_check, max_units - queued); ++j, ++queued) unit();
  printf("%d %d %d %d\n", ctl[SP_CTL_STOP], ctl[SP_CTL_ITER], ctl[SP_CTL_BAD], ctl[SPK_CTL_WHAT]);
  print(hist.data(), (size_t)ctl[SP_CTL_ITER] + 1);
  print(x.data(), (size_t)n);
}

// The triplet pipeline of warp-runtime's sparse/mod.rs (from_triplets), with the host's
// stable sort in place of the radix sort; prints the fault if the report raised one, then
// the matrix (a GPU runs every queued step after a fault too; the CPU stops at it).
template <typename S> void pipeline(const ScalarKernels& k, i32 block, i32 nrow, i32 ncol, i32 n,
                                    u64 ca, std::vector<i32>& rows, std::vector<i32>& cols,
                                    std::vector<S>& values, i32 no_finite_check);

template <typename S> void triplets(const ScalarKernels& k) {
  const i32 block = (i32)word(), nrow = (i32)word(), ncol = (i32)word(), n = (i32)word();
  // A device count: a word 1 then the count, or a word 0 (none).
  i32 dcount = 0;
  const bool has_count = word() != 0;
  if (has_count) dcount = (i32)(i64)word();
  const u64 ca = has_count ? addr(&dcount) : 0;
  std::vector<i32> rows = ints(n), cols = ints(n);
  std::vector<S> values = scalars<S>((size_t)n * block);
  pipeline<S>(k, block, nrow, ncol, n, ca, rows, cols, values, 0);
}

// The pipeline of `n` triplets (a device count at `ca`, or none); `no_finite_check` as the
// structure operations of wp_sparse_ops.h run it.
template <typename S> void pipeline(const ScalarKernels& k, i32 block, i32 nrow, i32 ncol, i32 n,
                                    u64 ca, std::vector<i32>& rows, std::vector<i32>& cols,
                                    std::vector<S>& values, i32 no_finite_check) {
  const i32 m = ca ? sp_count(ca, n) : n;
  std::vector<u32> keys(n + 1);
  std::vector<i32> idx(n + 1), pos(n + 1), brows(n + 1), columns(n + 1), offsets(nrow + 1);
  std::vector<S> out((size_t)n * block + 1);
  std::vector<i32> bad = {0x7fffffff, 0x7fffffff, 0x7fffffff};
  const bool two_pass = (u64)nrow * (u64)ncol > 0xffffffffull;
  run(k.keys, GB, GT, sp_tpl_keys_t{ca, addr(rows.data()), addr(cols.data()), addr(values.data()), n,
                                    nrow, ncol, block, two_pass, no_finite_check, addr(keys.data()),
                                    addr(idx.data()), addr(bad.data())});
  fault_t f{};
  u32 flag = 0;
  sp_tpl_report_t rep{ca, addr(bad.data()), addr(rows.data()), addr(cols.data()), addr(values.data()),
                      n, nrow, ncol, block, step_fault_t{}};
  rep.fault.ctx.fault = &f;
  rep.fault.ctx.fault_flag = &flag;
  run(k.report, 1, 1, rep);
  if (flag) {
    printf("fault %d %d %lld %lld %lld %lld\n", f.kind, f.arg, (long long)f.index[0],
           (long long)f.index[1], (long long)f.shape[0], (long long)f.shape[1]);
  }
  auto sort = [&]() {
    std::vector<std::pair<u32, i32>> kv(m);
    for (i32 i = 0; i < m; ++i) kv[i] = {keys[i], idx[i]};
    std::stable_sort(kv.begin(), kv.end(), [](auto a, auto b) { return a.first < b.first; });
    for (i32 i = 0; i < m; ++i) { keys[i] = kv[i].first; idx[i] = kv[i].second; }
  };
  sort();
  if (two_pass) {
    run(wp_sparse_tpl_row_keys, GB, GT, sp_tpl_row_keys_t{ca, addr(rows.data()), addr(cols.data()),
                                                          addr(idx.data()), addr(keys.data()), n, nrow, ncol, 0});
    sort();
  }
  run(wp_sparse_tpl_heads, GB, GT, sp_tpl_heads_t{ca, addr(rows.data()), addr(cols.data()),
                                                  addr(idx.data()), addr(pos.data()), n, nrow, ncol, 0});
  for (i32 i = 1; i < m; ++i) pos[i] += pos[i - 1];
  run(k.sum, GB, GT, sp_tpl_sum_t{ca, addr(rows.data()), addr(cols.data()), addr(values.data()),
                                  addr(idx.data()), addr(pos.data()), addr(brows.data()),
                                  addr(columns.data()), addr(out.data()), n, nrow, ncol, block});
  run(wp_sparse_bsr_offsets, GB, GT, sp_bsr_offsets_t{ca, addr(brows.data()), addr(pos.data()),
                                                      addr(offsets.data()), n, nrow});
  const i32 nnz = offsets[nrow];
  printf("matrix %d\n", nnz);
  print(offsets.data(), (size_t)nrow + 1);
  print(columns.data(), (size_t)nnz);
  print(out.data(), (size_t)nnz * block);
}


// ---- Slice 2: the structure operations (wp_sparse_ops.h), in warp-runtime's sparse/ops.rs
// order, the primitives replaced by the host's stable sort and scans ----
struct OpsKernels {
  void (*scale)(sp_ops_scale_t);
  void (*diag)(sp_ops_diag_t);
  void (*set_diag)(sp_ops_set_diag_t);
  void (*to_dense)(sp_ops_to_dense_t);
  void (*flags)(sp_ops_dense_t);
  void (*report)(sp_ops_dense_report_t);
  void (*gather)(sp_ops_dense_t);
  void (*transpose)(sp_ops_transpose_t);
  void (*to_triplets)(sp_ops_to_triplets_t);
  void (*expand)(sp_ops_mm_expand_t);
};
#define OK(t) OpsKernels{wp_sparse_ops_scale_##t, wp_sparse_ops_diag_##t, wp_sparse_ops_set_diag_##t, \
    wp_sparse_ops_to_dense_##t, wp_sparse_ops_dense_flags_##t, wp_sparse_ops_dense_report_##t,      \
    wp_sparse_ops_dense_gather_##t, wp_sparse_ops_transpose_##t, wp_sparse_ops_to_triplets_##t,     \
    wp_sparse_ops_mm_expand_##t}

// A matrix of blocks of `rc` scalars (nrow, ncol, nnz, offsets, columns, values); cap = nnz.
template <typename S> Matrix mat(i32 rc, std::vector<S>& values) {
  Matrix m;
  m.nrow = (i32)word();
  m.ncol = (i32)word();
  m.nnz = (i32)word();
  m.offsets = ints(m.nrow + 1);
  m.columns = ints(m.nnz);
  values = scalars<S>((size_t)m.nnz * rc);
  return m;
}

template <typename S> void print_matrix(i32 nrow, i32 nnz, i32 rc, const i32* offsets, const i32* columns,
                                        const S* values) {
  printf("matrix %d\n", nnz);
  print(offsets, (size_t)nrow + 1);
  print(columns, (size_t)nnz);
  print(values, (size_t)nnz * rc);
}

template <typename S> void ops(const OpsKernels& o, const ScalarKernels& k, u64 op) {
  const i32 r = (i32)word(), c = (i32)word(), cm = (i32)word(), rc = r * c;
  switch (op) {
    case 0: {  // scale
      std::vector<S> v;
      Matrix m = mat<S>(rc, v);
      run(o.scale, GB, GT, sp_ops_scale_t{addr(m.offsets.data()), addr(v.data()), scalar<f64>(), m.nrow, m.nnz, rc, 0});
      print(v.data(), (size_t)m.nnz * rc);
      break;
    }
    case 1: {  // diag
      std::vector<S> v;
      Matrix m = mat<S>(rc, v);
      const i32 n = m.nrow < m.ncol ? m.nrow : m.ncol;
      std::vector<S> out((size_t)n * rc + 1);
      run(o.diag, GB, GT, sp_ops_diag_t{addr(m.offsets.data()), addr(m.columns.data()), addr(v.data()),
                                        addr(out.data()), m.nrow, m.ncol, m.nnz, rc});
      print(out.data(), (size_t)n * rc);
      break;
    }
    case 2: {  // from_diag / identity: nrow, ncol, has_d, d
      const i32 nrow = (i32)word(), ncol = (i32)word(), n = nrow < ncol ? nrow : ncol;
      const bool has_d = word() != 0;
      std::vector<S> d = scalars<S>(has_d ? (size_t)n * rc : 0);
      std::vector<i32> offsets(nrow + 1), columns(n + 1);
      std::vector<S> v((size_t)n * rc + 1);
      run(o.set_diag, GB, GT, sp_ops_set_diag_t{addr(offsets.data()), addr(columns.data()), addr(v.data()),
                                                has_d ? addr(d.data()) : 0, nrow, n, r, rc});
      print_matrix(nrow, n, rc, offsets.data(), columns.data(), v.data());
      break;
    }
    case 3: {  // to_dense
      std::vector<S> v;
      Matrix m = mat<S>(rc, v);
      const size_t len = (size_t)m.nrow * r * m.ncol * c;
      std::vector<S> out(len + 1, (S)7);
      run(o.to_dense, GB, GT, sp_ops_to_dense_t{addr(m.offsets.data()), addr(m.columns.data()), addr(v.data()),
                                                addr(out.data()), m.nrow, m.ncol, m.nnz, r, c, cm});
      print(out.data(), len);
      break;
    }
    case 4: {  // from_dense: nrow, ncol (blocks), the dense scalars
      const i32 nrow = (i32)word(), ncol = (i32)word(), nb = nrow * ncol;
      std::vector<S> dense = scalars<S>((size_t)nb * rc);
      std::vector<i32> pos(nb + 1), brows(nb + 1), columns(nb + 1), offsets(nrow + 1);
      std::vector<S> v((size_t)nb * rc + 1);
      i32 bad = 0x7fffffff;
      const sp_ops_dense_t st{addr(dense.data()), addr(pos.data()), addr(&bad), addr(brows.data()),
                              addr(columns.data()), addr(v.data()), nrow, ncol, r, c, cm, 0};
      run(o.flags, GB, GT, st);
      fault_t f{};
      u32 flag = 0;
      sp_ops_dense_report_t rep{addr(dense.data()), addr(&bad), (i64)ncol * c, step_fault_t{}};
      rep.fault.ctx.fault = &f;
      rep.fault.ctx.fault_flag = &flag;
      run(o.report, 1, 1, rep);
      if (flag)
        printf("fault %d %d %lld %lld\n", f.kind, f.arg, (long long)f.index[0], (long long)f.index[1]);
      for (i32 i = 1; i < nb; ++i) pos[i] += pos[i - 1];
      run(o.gather, GB, GT, st);
      run(wp_sparse_bsr_offsets, GB, GT, sp_bsr_offsets_t{0, addr(brows.data()), addr(pos.data()),
                                                          addr(offsets.data()), nb, nrow});
      print_matrix(nrow, offsets[nrow], rc, offsets.data(), columns.data(), v.data());
      break;
    }
    case 5: {  // transpose: cm_t, the matrix
      const i32 cm_t = (i32)word();
      std::vector<S> v;
      Matrix m = mat<S>(rc, v);
      const i32 cap = m.nnz;
      std::vector<i32> brows(cap + 1), idx(cap + 1), offsets(m.ncol + 1), columns(cap + 1);
      std::vector<u32> keys(cap + 1);
      std::vector<S> out((size_t)cap * rc + 1);
      run(wp_sparse_ops_row_keys, GB, GT, sp_ops_row_keys_t{addr(m.offsets.data()), addr(m.columns.data()),
                                                            addr(brows.data()), addr(keys.data()),
                                                            addr(idx.data()), m.nrow, m.ncol, cap, 0});
      const i32 nnz = sp_nnz(m.offsets.data(), m.nrow, cap);
      std::vector<std::pair<u32, i32>> kv(nnz);
      for (i32 i = 0; i < nnz; ++i) kv[i] = {keys[i], idx[i]};
      std::stable_sort(kv.begin(), kv.end(), [](auto a, auto b) { return a.first < b.first; });
      for (i32 i = 0; i < nnz; ++i) { keys[i] = kv[i].first; idx[i] = kv[i].second; }
      run(o.transpose, GB, GT, sp_ops_transpose_t{addr(m.offsets.data()), addr(brows.data()), addr(keys.data()),
                                                  addr(idx.data()), addr(v.data()), addr(offsets.data()),
                                                  addr(columns.data()), addr(out.data()), m.nrow, m.ncol, cap,
                                                  r, c, cm, cm_t, 0});
      print_matrix(m.ncol, nnz, rc, offsets.data(), columns.data(), out.data());
      break;
    }
    case 6: {  // axpy: x, y, alpha, beta
      std::vector<S> xv, yv;
      Matrix x = mat<S>(rc, xv);
      Matrix y = mat<S>(rc, yv);
      const f64 alpha = scalar<f64>(), beta = scalar<f64>();
      const i32 n = x.nnz + y.nnz;
      std::vector<i32> rows(n + 1), cols(n + 1), counts(2, 0);
      std::vector<S> vals((size_t)n * rc + 1);
      run(o.to_triplets, GB, GT, sp_ops_to_triplets_t{addr(x.offsets.data()), addr(x.columns.data()), addr(xv.data()),
                                                      0, addr(rows.data()), addr(cols.data()), addr(vals.data()),
                                                      addr(&counts[0]), alpha, x.nrow, x.nnz, rc, n});
      run(o.to_triplets, GB, GT, sp_ops_to_triplets_t{addr(y.offsets.data()), addr(y.columns.data()), addr(yv.data()),
                                                      addr(&counts[0]), addr(rows.data()), addr(cols.data()),
                                                      addr(vals.data()), addr(&counts[1]), beta, y.nrow, y.nnz, rc, n});
      pipeline<S>(k, rc, y.nrow, y.ncol, n, addr(&counts[1]), rows, cols, vals, 1);
      break;
    }
    case 7: {  // mm: (A's r, c, cm in the head) B's cols, B's and C's layouts; a, b, c,
               // alpha, beta, capacity (-1: exact)
      const i32 cn = (i32)word(), cm_b = (i32)word(), cm_c = (i32)word();
      const i32 rc_b = c * cn, rc_c = r * cn;
      std::vector<S> av, bv, cv;
      Matrix a = mat<S>(rc, av);
      Matrix b = mat<S>(rc_b, bv);
      Matrix cm_ = mat<S>(rc_c, cv);
      const f64 alpha = scalar<f64>(), beta = scalar<f64>();
      const i64 fixed = (i64)word();
      std::vector<i64> starts(a.nrow + 1);
      run(wp_sparse_ops_mm_count, GB, GT, sp_ops_mm_count_t{addr(a.offsets.data()), addr(a.columns.data()),
                                                            addr(b.offsets.data()), addr(starts.data()),
                                                            a.nrow, a.nnz, b.nrow, b.nnz});
      i64 acc = 0;  // the exclusive scan
      for (i32 i = 0; i <= a.nrow; ++i) { const i64 t = starts[i]; starts[i] = acc; acc += t; }
      std::vector<i32> cells(2, 0);
      run(wp_sparse_ops_mm_total, 1, 1, sp_ops_mm_total_t{addr(starts.data()), addr(&cells[0]), a.nrow, 0});
      const bool with_c = beta != 0.0;
      const i64 n = fixed >= 0 ? fixed : starts[a.nrow] + (with_c ? cm_.nnz : 0);
      std::vector<i32> rows(n + 1), cols(n + 1);
      std::vector<S> vals((size_t)n * rc_c + 1);
      run(o.expand, GB, GT, sp_ops_mm_expand_t{addr(a.offsets.data()), addr(a.columns.data()), addr(av.data()),
                                               addr(b.offsets.data()), addr(b.columns.data()), addr(bv.data()),
                                               addr(starts.data()), addr(rows.data()), addr(cols.data()),
                                               addr(vals.data()), alpha, n, a.nrow, a.nnz, b.nrow, b.nnz,
                                               r, c, cn, cm, cm_b, cm_c});
      if (with_c)
        run(o.to_triplets, GB, GT, sp_ops_to_triplets_t{addr(cm_.offsets.data()), addr(cm_.columns.data()),
                                                        addr(cv.data()), addr(&cells[0]), addr(rows.data()),
                                                        addr(cols.data()), addr(vals.data()), addr(&cells[1]),
                                                        beta, cm_.nrow, cm_.nnz, rc_c, (i32)n});
      pipeline<S>(k, rc_c, a.nrow, b.ncol, (i32)n, addr(&cells[with_c ? 1 : 0]), rows, cols, vals, 1);
      break;
    }
    default:
      exit(2);
  }
}

// ---- Slice 6: graph colouring (wp_sparse_color.h), in warp-runtime's sparse/color.rs order.
// Words: n, cap, seed, threads, blocks, offsets (n + 1), columns (cap). Jones-Plassmann rounds
// two at a time until the flag is 0 (as `Coloring::new`), then the sort keys, the host's stable
// sort (the primitives' radix sort is stable), the offsets. Prints the colours, the order, the
// offsets.
void color() {
  const i32 n = (i32)word(), cap = (i32)word();
  const u32 seed = (u32)word();
  const unsigned threads = (unsigned)word(), blocks = (unsigned)word();
  std::vector<i32> off = ints(n + 1), cols = ints(cap);
  std::vector<i32> a(n + 1, -1), b(n + 1, 0), flag{1, 0};
  for (i32 rounds = 0; flag[0] != 0; ++rounds) {
    if (rounds > n + 1) exit(3);  // each pass colours a vertex at least
    sp_color_round_t r{addr(off.data()), addr(cols.data()), addr(a.data()), addr(b.data()),
                       addr(flag.data()), n, cap, seed, 1};
    run(wp_sparse_color_round, blocks, threads, r);
    r.prev = addr(b.data());
    r.next = addr(a.data());
    r.clear = 0;
    run(wp_sparse_color_round, blocks, threads, r);
  }
  std::vector<u32> keys(n + 1);
  std::vector<i32> order(n + 1);
  sp_color_sort_t s{addr(a.data()), addr(keys.data()), addr(order.data()), 0, n, 0};
  run(wp_sparse_color_keys, blocks, threads, s);
  std::vector<std::pair<u32, i32>> p;
  for (i32 i = 0; i < n; ++i) p.push_back({keys[i], order[i]});
  std::stable_sort(p.begin(), p.end(), [](auto x, auto y) { return x.first < y.first; });
  for (i32 i = 0; i < n; ++i) {
    keys[i] = p[i].first;
    order[i] = p[i].second;
  }
  const i32 ncolors = n ? (i32)keys[n - 1] + 1 : 0;
  std::vector<i32> offsets(ncolors + 2, 0);
  s.offsets = addr(offsets.data());
  s.ncolors = ncolors;
  run(wp_sparse_color_offsets, blocks, threads, s);
  print(a.data(), n);
  print(order.data(), n);
  print(offsets.data(), ncolors + 1);
}

// Words: m, n, incidence, threads, blocks, edges (2 m). The split step; prints rows, cols,
// flags (2 m each) and the smallest bad edge.
void color_split() {
  const i32 m = (i32)word(), n = (i32)word(), incidence = (i32)word();
  const unsigned threads = (unsigned)word(), blocks = (unsigned)word();
  std::vector<i32> edges = ints(2 * m), rows(2 * m + 1), cols(2 * m + 1), flags(2 * m + 1);
  std::vector<i32> bad{0x7fffffff, 0};
  sp_color_split_t s{addr(edges.data()), addr(rows.data()), addr(cols.data()), addr(flags.data()),
                     addr(bad.data()), m, n, incidence, 0};
  run(wp_sparse_color_split, blocks, threads, s);
  print(rows.data(), 2 * m);
  print(cols.data(), 2 * m);
  print(flags.data(), 2 * m);
  print(bad.data(), 1);
}

// Words: n, cap, threads, blocks, offsets (n + 1), columns (cap) of an incidence pattern.
// pair_count, the host's exclusive scan, pair_expand; prints the pairs' rows and columns.
void color_pairs() {
  const i32 n = (i32)word(), cap = (i32)word();
  const unsigned threads = (unsigned)word(), blocks = (unsigned)word();
  std::vector<i32> off = ints(n + 1), cols = ints(cap);
  std::vector<i64> starts(n + 2, 0);
  sp_color_pairs_t s{addr(off.data()), addr(cols.data()), addr(starts.data()), 0, 0, 0, n, cap};
  run(wp_sparse_color_pair_count, blocks, threads, s);
  i64 total = 0;
  for (i32 r = 0; r <= n; ++r) {
    const i64 c = starts[r];
    starts[r] = total;
    total += c;
  }
  std::vector<i32> rows(total + 1), pcols(total + 1);
  s.rows = addr(rows.data());
  s.cols = addr(pcols.data());
  s.limit = total;
  run(wp_sparse_color_pair_expand, blocks, threads, s);
  print(rows.data(), total);
  print(pcols.data(), total);
}

// ---- Slice 5: the adjoint kernels (wp_sparse.h's adjoint section), in warp-runtime's
// sparse/adjoint.rs order ----
struct AdjointKernels {
  void (*tpl)(sp_adj_tpl_t);
  void (*axpby)(sp_adj_axpby_t);
  void (*outer)(sp_adj_outer_t);
};
#define AK(t) AdjointKernels{wp_sparse_adj_tpl_##t, wp_sparse_adj_axpby_##t, wp_sparse_adj_outer_##t}

template <typename S> void adjoint(const AdjointKernels& a, const ScalarKernels& k, u64 op) {
  switch (op) {
    case 0: {  // the assembly's adjoint: block, nrow, ncol, n, count (flag, value), rows, cols,
               // values, the blocks' gradient (n blocks, the matrix's capacity)
      const i32 block = (i32)word(), nrow = (i32)word(), ncol = (i32)word(), n = (i32)word();
      i32 dcount = 0;
      const bool has_count = word() != 0;
      if (has_count) dcount = (i32)(i64)word();
      const u64 ca = has_count ? addr(&dcount) : 0;
      std::vector<i32> rows = ints(n), cols = ints(n);
      std::vector<S> values = scalars<S>((size_t)n * block);
      std::vector<S> vgrad = scalars<S>((size_t)n * block);
      const i32 m = ca ? sp_count(ca, n) : n;
      std::vector<u32> keys(n + 1);
      std::vector<i32> idx(n + 1), pos(n + 1);
      std::vector<i32> bad = {0x7fffffff, 0x7fffffff, 0x7fffffff};
      const bool two_pass = (u64)nrow * (u64)ncol > 0xffffffffull;
      run(k.keys, GB, GT, sp_tpl_keys_t{ca, addr(rows.data()), addr(cols.data()), addr(values.data()), n,
                                        nrow, ncol, block, two_pass, 0, addr(keys.data()),
                                        addr(idx.data()), addr(bad.data())});
      auto sort = [&]() {
        std::vector<std::pair<u32, i32>> kv(m);
        for (i32 i = 0; i < m; ++i) kv[i] = {keys[i], idx[i]};
        std::stable_sort(kv.begin(), kv.end(), [](auto x, auto y) { return x.first < y.first; });
        for (i32 i = 0; i < m; ++i) { keys[i] = kv[i].first; idx[i] = kv[i].second; }
      };
      sort();
      if (two_pass) {
        run(wp_sparse_tpl_row_keys, GB, GT, sp_tpl_row_keys_t{ca, addr(rows.data()), addr(cols.data()),
                                                              addr(idx.data()), addr(keys.data()), n, nrow, ncol, 0});
        sort();
      }
      run(wp_sparse_tpl_heads, GB, GT, sp_tpl_heads_t{ca, addr(rows.data()), addr(cols.data()),
                                                      addr(idx.data()), addr(pos.data()), n, nrow, ncol, 0});
      for (i32 i = 1; i < m; ++i) pos[i] += pos[i - 1];
      std::vector<S> tgrad((size_t)n * block + 1);
      const u32 sentinel = two_pass ? (u32)nrow : (u32)((u64)nrow * (u64)ncol);
      run(a.tpl, GB, GT, sp_adj_tpl_t{ca, addr(idx.data()), addr(pos.data()), addr(keys.data()),
                                      addr(vgrad.data()), addr(tgrad.data()), n, block, sentinel, 0});
      print(tgrad.data(), (size_t)n * block);
      break;
    }
    case 1: {  // the outer product: r, c, cm, the matrix, u (rows), v (columns), the gradient
               // (nnz blocks), alpha
      const i32 r = (i32)word(), c = (i32)word(), cm = (i32)word(), rc = r * c;
      std::vector<S> vals;
      Matrix mt = mat<S>(rc, vals);
      std::vector<S> u = scalars<S>((size_t)mt.nrow * r), v = scalars<S>((size_t)mt.ncol * c);
      std::vector<S> g = scalars<S>((size_t)mt.nnz * rc);
      const f64 alpha = scalar<f64>();
      run(a.outer, GB, GT, sp_adj_outer_t{addr(mt.offsets.data()), addr(mt.columns.data()), addr(g.data()),
                                          addr(u.data()), addr(v.data()), alpha, mt.nrow, mt.ncol, mt.nnz,
                                          r, c, cm});
      print(g.data(), (size_t)mt.nnz * rc);
      break;
    }
    case 2: {  // y = a y + b x: n, y, has_x, x, a, b
      const i64 n = (i64)word();
      std::vector<S> y = scalars<S>(n);
      const bool has_x = word() != 0;
      std::vector<S> x = scalars<S>(has_x ? n : 0);
      const f64 al = scalar<f64>(), be = scalar<f64>();
      run(a.axpby, GB, GT, sp_adj_axpby_t{addr(y.data()), has_x ? addr(x.data()) : 0, al, be, n});
      print(y.data(), (size_t)n);
      break;
    }
    default:
      exit(2);
  }
}

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  FILE* file = fopen(argv[1], "rb");
  if (!file) return 2;
  u64 w;
  while (fread(&w, 8, 1, file) == 1) in.push_back(w);
  fclose(file);
  const u64 cmd = word(), kind = word();
  const ScalarKernels sk[2] = {SK(f32), SK(f64)};
  const bool f64s = kind == 1 || (kind >= 5 && kind < 8) || kind >= 20;
  switch (cmd) {
    case 0: f64s ? mv<f64>(BLOCKS[kind]) : mv<f32>(BLOCKS[kind]); break;
    case 1: kind ? dot<f64>(sk[1]) : dot<f32>(sk[0]); break;
    case 2: f64s ? cg<f64>(BLOCKS[kind], sk[1]) : cg<f32>(BLOCKS[kind], sk[0]); break;
    case 3: kind ? triplets<f64>(sk[1]) : triplets<f32>(sk[0]); break;
    // The structure operations: a third word names the operation (`ops`), kind the scalar.
    case 4: {
      const u64 op = word();
      kind ? ops<f64>(OK(f64), sk[1], op) : ops<f32>(OK(f32), sk[0], op);
      break;
    }
    case 5: {
      const KrylovKernels kk[2] = {KK(f32), KK(f64)};
      f64s ? krylov<f64>(BLOCKS[kind], sk[1], kk[1]) : krylov<f32>(BLOCKS[kind], sk[0], kk[0]);
      break;
    }
    case 6: color(); break;
    case 7: color_split(); break;
    case 8: color_pairs(); break;
    // The adjoint kernels: a third word names the operation (`adjoint`), kind the scalar.
    case 9: {
      const u64 op = word();
      const AdjointKernels ak[2] = {AK(f32), AK(f64)};
      kind ? adjoint<f64>(ak[1], sk[1], op) : adjoint<f32>(ak[0], sk[0], op);
      break;
    }
    default: return 2;
  }
  return 0;
}
"#;

/// The driver, compiled once per process (`None` without g++).
fn driver() -> Option<&'static (std::path::PathBuf, std::path::PathBuf)> {
    static EXE: OnceLock<Option<(std::path::PathBuf, std::path::PathBuf)>> = OnceLock::new();
    EXE.get_or_init(|| {
        host_cpp::gpp().then(|| {
            host_cpp::compile_driver(
                "sparse",
                DRIVER,
                &[
                    "WP_SPARSE_BUILD",
                    "WP_SPARSE_OPS_BUILD",
                    "WP_SPARSE_COLOR_BUILD",
                    "WP_SPARSE_EMULATED",
                ],
            )
        })
    })
    .as_ref()
}

/// Runs the driver on `words` and returns its output lines.
fn run(name: &str, words: &[u64]) -> Vec<String> {
    let (dir, exe) = driver().expect("g++");
    let input = dir.join(format!("{name}.bin"));
    let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
    std::fs::write(&input, bytes).unwrap();
    let out = Command::new(exe).arg(&input).output().unwrap();
    assert!(
        out.status.success(),
        "driver on {name}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

fn skip(test: &str) -> bool {
    if driver().is_none() {
        eprintln!("SKIPPED cuda_sparse_host::{test}: no g++ on this machine");
        return true;
    }
    false
}

/// A scalar as the driver reads it (f32 in the low bits).
fn word<S: SparseScalar>(x: S) -> u64 {
    let b = bytemuck::bytes_of(&x);
    let mut w = [0u8; 8];
    w[..b.len()].copy_from_slice(b);
    u64::from_le_bytes(w)
}

/// The scalars of `v` as words.
fn words<B: Block>(v: &[B]) -> Vec<u64> {
    v.iter()
        .flat_map(|b| {
            let s: &[B::Scalar] = bytemuck::cast_slice(bytemuck::bytes_of(b));
            s.to_vec()
        })
        .map(word)
        .collect()
}

/// The driver's hex lines as words.
fn hex(lines: &[String]) -> Vec<u64> {
    lines
        .iter()
        .map(|l| u64::from_str_radix(l, 16).unwrap())
        .collect()
}

/// Elements of `T` from their scalars (copied: `T` may be more aligned than `S`).
fn from_scalars<T: bytemuck::Pod, S: bytemuck::Pod>(s: &[S]) -> Vec<T> {
    let n = std::mem::size_of_val(s) / std::mem::size_of::<T>();
    let mut v = vec![<T as bytemuck::Zeroable>::zeroed(); n];
    bytemuck::cast_slice_mut::<T, u8>(&mut v).copy_from_slice(bytemuck::cast_slice::<S, u8>(s));
    v
}

/// A block of `B` from scalars.
fn block<B: Block>(s: &[B::Scalar]) -> B {
    let mut b = <B as bytemuck::Zeroable>::zeroed();
    bytemuck::bytes_of_mut(&mut b).copy_from_slice(bytemuck::cast_slice(s));
    b
}

/// The driver's code of a block type (its `BLOCKS` index).
fn kind<B: Block>() -> u64 {
    let f64s = std::mem::size_of::<B::Scalar>() == 8;
    if B::ROWS != B::COLS {
        // The rectangular blocks, after the 8 square ones: f32 then f64, R then C ascending.
        let shapes: Vec<(usize, usize)> = [2, 3, 4, 6]
            .iter()
            .flat_map(|&r| [2, 3, 4, 6].map(move |c| (r, c)))
            .filter(|(r, c)| r != c)
            .collect();
        let i = shapes
            .iter()
            .position(|&s| s == (B::ROWS, B::COLS))
            .unwrap();
        return 8 + 12 * f64s as u64 + i as u64;
    }
    match (B::ROWS, f64s) {
        (1, false) => 0,
        (1, true) => 1,
        (n, false) => n as u64,
        (n, true) => n as u64 + 3,
    }
}

/// Deterministic values in [-1, 1) with a spread of magnitudes.
fn value(i: usize) -> f64 {
    let h = (i as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    let u = (h >> 11) as f64 / (1u64 << 53) as f64;
    (2.0 * u - 1.0) * 10f64.powi((h % 7) as i32 - 3)
}

/// Deterministic values in [-1, 1).
fn uniform(i: usize) -> f64 {
    let h = (i as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    2.0 * ((h >> 11) as f64 / (1u64 << 53) as f64) - 1.0
}

/// A random `nrow x ncol` matrix of `B` with duplicates, on the CPU, and its words for the
/// driver (nrow, ncol, nnz, offsets, columns, values).
fn random_matrix<B: Block>(
    nrow: usize,
    ncol: usize,
    count: usize,
    seed: usize,
) -> (Bsr<B>, Vec<u64>) {
    let cpu = wp::cpu();
    let rows: Vec<i32> = (0..count).map(|t| ((t * 7 + seed) % nrow) as i32).collect();
    let cols: Vec<i32> = (0..count)
        .map(|t| ((t * t + 3 * seed) % ncol) as i32)
        .collect();
    let rc = B::ROWS * B::COLS;
    let vals: Vec<B> = (0..count)
        .map(|t| {
            let s: Vec<B::Scalar> = (0..rc)
                .map(|e| B::Scalar::from_f64(value(seed * 100_000 + t * rc + e)))
                .collect();
            block::<B>(&s)
        })
        .collect();
    let a = Bsr::from_triplets(
        nrow,
        ncol,
        &wp::Array::from_slice(&rows, &cpu).unwrap(),
        &wp::Array::from_slice(&cols, &cpu).unwrap(),
        &wp::Array::from_slice(&vals, &cpu).unwrap(),
    )
    .unwrap();
    (a.clone(), matrix_words(&a))
}

fn matrix_words<B: Block>(a: &Bsr<B>) -> Vec<u64> {
    let nnz = a.nnz().unwrap();
    let mut w = vec![a.nrow() as u64, a.ncol() as u64, nnz as u64];
    w.extend(
        a.offsets()
            .to_vec()
            .unwrap()
            .iter()
            .map(|&o| o as i64 as u64),
    );
    w.extend(
        a.columns().to_vec().unwrap()[..nnz]
            .iter()
            .map(|&c| c as i64 as u64),
    );
    w.extend(words(&a.values().to_vec().unwrap()[..nnz]));
    w
}

fn mv_case<B: Block>(seed: usize) {
    let cpu = wp::cpu();
    let (nrow, ncol) = (37, 23);
    let (a, mw) = random_matrix::<B>(nrow, ncol, 300, seed);
    let xs: Vec<B::Scalar> = (0..ncol * B::COLS)
        .map(|i| B::Scalar::from_f64(value(seed + 7 * i)))
        .collect();
    let ys: Vec<B::Scalar> = (0..nrow * B::ROWS)
        .map(|i| B::Scalar::from_f64(value(seed + 11 * i + 5)))
        .collect();
    let x_in: Vec<B::In> = from_scalars(&xs);
    let y_out: Vec<B::Out> = from_scalars(&ys);
    // Every lane count (lanes per scalar row, `set_mv_lanes`): 1 at three (alpha, beta), the
    // others at one, each of the CPU backend's results against the header's.
    let cases = [(1, 0.75, -1.25), (1, 1.0, 0.0), (1, -2.5, 1.0)]
        .into_iter()
        .chain([2, 4, 8, 16, 32].map(|w| (w, 0.75, -1.25)));
    for (lanes, alpha, beta) in cases {
        sparse::set_mv_lanes(Some(lanes)).unwrap();
        let y = wp::Array::from_slice(&y_out, &cpu).unwrap();
        sparse::mv(
            B::Scalar::from_f64(alpha),
            &a,
            &wp::Array::from_slice(&x_in, &cpu).unwrap(),
            B::Scalar::from_f64(beta),
            &y,
        )
        .unwrap();
        let got_y = y.to_vec().unwrap();
        let want: Vec<u64> = bytemuck::cast_slice::<B::Out, B::Scalar>(&got_y)
            .iter()
            .map(|&v| word(v))
            .collect();
        let mut input = vec![0, kind::<B>()];
        input.extend(&mw);
        input.extend(xs.iter().map(|&v| word(v)));
        input.extend(ys.iter().map(|&v| word(v)));
        input.extend([alpha.to_bits(), beta.to_bits(), lanes as u64]);
        let got = hex(&run(&format!("mv{}", kind::<B>()), &input));
        assert_eq!(
            got,
            want,
            "{}: {lanes} lanes, alpha {alpha}, beta {beta}",
            std::any::type_name::<B>()
        );
    }
    sparse::set_mv_lanes(None).unwrap();
}

/// `y = alpha A x + beta y` of every block type, at three (alpha, beta): the same bits as the
/// CPU backend.
#[test]
fn mv_matches_the_cpu_bit_for_bit() {
    if skip("mv_matches_the_cpu_bit_for_bit") {
        return;
    }
    mv_case::<f32>(1);
    mv_case::<f64>(2);
    mv_case::<Mat2>(3);
    mv_case::<Mat3>(4);
    mv_case::<Mat4>(5);
    mv_case::<DMat2>(6);
    mv_case::<DMat3>(7);
    mv_case::<DMat4>(8);
}

fn dot_case<S: SparseScalar + Block<Scalar = S>>(n: usize) {
    let cpu = wp::cpu();
    // Magnitudes of one order (values' spread would let the largest products hide the order
    // of the others' additions).
    let a: Vec<S> = (0..n).map(|i| S::from_f64(uniform(3 * i))).collect();
    let b: Vec<S> = (0..n).map(|i| S::from_f64(uniform(3 * i + 1))).collect();
    let out = wp::Array::from_slice(&[S::ZERO], &cpu).unwrap();
    sparse::dot(
        &wp::Array::from_slice(&a, &cpu).unwrap(),
        &wp::Array::from_slice(&b, &cpu).unwrap(),
        &out,
    )
    .unwrap();
    let want = word(out.to_vec().unwrap()[0]);
    let mut input = vec![1, (std::mem::size_of::<S>() == 8) as u64, n as u64];
    input.extend(a.iter().map(|&v| word(v)));
    input.extend(b.iter().map(|&v| word(v)));
    let got = hex(&run(&format!("dot{n}"), &input));
    assert_eq!(got, [want], "{} n {n}", std::any::type_name::<S>());
}

/// The fixed-tree dot product (two blocks looping over up to five chunks, then one block over
/// the partials): the same bits as the CPU backend.
#[test]
fn dot_matches_the_cpu_bit_for_bit() {
    if skip("dot_matches_the_cpu_bit_for_bit") {
        return;
    }
    for n in [0, 1, 255, 4096, 4097, 19_000] {
        dot_case::<f32>(n);
        dot_case::<f64>(n);
    }
}

/// The 2-D Laplacian on an `m x m` grid, its entries times `k` (a square block).
fn poisson<B: Block>(m: usize, k: B, neg: B) -> Bsr<B> {
    let cpu = wp::cpu();
    let (mut r, mut c, mut v) = (vec![], vec![], vec![]);
    for i in 0..m * m {
        r.push(i as i32);
        c.push(i as i32);
        v.push(k);
        let (y, x) = (i / m, i % m);
        for (dy, dx) in [(-1i64, 0i64), (1, 0), (0, -1), (0, 1)] {
            let (yy, xx) = (y as i64 + dy, x as i64 + dx);
            if (0..m as i64).contains(&yy) && (0..m as i64).contains(&xx) {
                r.push(i as i32);
                c.push((yy as usize * m + xx as usize) as i32);
                v.push(neg);
            }
        }
    }
    Bsr::from_triplets(
        m * m,
        m * m,
        &wp::Array::from_slice(&r, &cpu).unwrap(),
        &wp::Array::from_slice(&c, &cpu).unwrap(),
        &wp::Array::from_slice(&v, &cpu).unwrap(),
    )
    .unwrap()
}

fn cg_case<B: sparse::SquareBlock>(a: &Bsr<B>, pre: Precond, o: SolveOptions, b: Vec<B::Scalar>) {
    let x0: Vec<B::Scalar> = (0..b.len())
        .map(|i| B::Scalar::from_f64(value(i) * 0.01))
        .collect();
    cg_case_from(a, pre, o, b, x0);
}

/// [`cg_case`] from the initial guess `x0`; the CPU's report.
fn cg_case_from<B: sparse::SquareBlock>(
    a: &Bsr<B>,
    pre: Precond,
    o: SolveOptions,
    b: Vec<B::Scalar>,
    x0: Vec<B::Scalar>,
) -> sparse::SolveReport {
    let cpu = wp::cpu();
    let x = wp::Array::from_slice(&x0, &cpu).unwrap();
    let rep = sparse::cg(a, &wp::Array::from_slice(&b, &cpu).unwrap(), &x, pre, &o).unwrap();
    let mut input = vec![2, kind::<B>()];
    input.extend(matrix_words(a));
    input.extend(b.iter().map(|&v| word(v)));
    input.extend(x0.iter().map(|&v| word(v)));
    let code = match pre {
        Precond::None => 0,
        Precond::Jacobi => 1,
        Precond::PointJacobi => 2,
    };
    input.extend([
        code,
        o.rtol.to_bits(),
        o.atol.to_bits(),
        o.max_iter as u64,
        o.check_every as u64,
    ]);
    let out = run(&format!("cg{}_{code}", kind::<B>()), &input);
    let head: Vec<i64> = out[0].split(' ').map(|t| t.parse().unwrap()).collect();
    let stop = match rep.stop {
        Stop::Converged => 1,
        Stop::MaxIterations => 2,
        Stop::NonFinite => 3,
        Stop::Breakdown { what: "p.Ap", .. } => 4,
        Stop::Breakdown { what, .. } => {
            assert_eq!(what, "r.z");
            6
        }
        Stop::SingularPreconditioner { .. } => 5,
    };
    let what = format!("{} {pre:?}", std::any::type_name::<B>());
    assert_eq!(
        (head[0], head[1] as usize),
        (stop, rep.iterations),
        "{what}: {rep:?}"
    );
    let words_out = hex(&out[1..]);
    let (hist, xs) = words_out.split_at(rep.iterations + 1);
    let want_hist: Vec<u64> = rep
        .history
        .iter()
        .map(|&h| word(B::Scalar::from_f64(h)))
        .collect();
    assert_eq!(hist, want_hist, "{what}: history");
    let want_x: Vec<u64> = x.to_vec().unwrap().iter().map(|&v| word(v)).collect();
    assert_eq!(xs, want_x, "{what}: x");
    rep
}

/// Whole CG solves through the C++ steps (the solver's loop replayed by the driver): the
/// same stop, iterations, history and x bits as the CPU backend; f64 and f32 scalars,
/// `DMat3`/`Mat2` blocks, no preconditioner, block and point Jacobi, a run stopped by
/// `max_iter`, a singular preconditioner, and `r . z` breakdowns.
#[test]
fn cg_matches_the_cpu_bit_for_bit() {
    if skip("cg_matches_the_cpu_bit_for_bit") {
        return;
    }
    let o = SolveOptions {
        rtol: 1e-8,
        check_every: 4,
        ..Default::default()
    };
    let a = poisson::<f64>(8, 4.0, -1.0);
    let b: Vec<f64> = (0..64).map(value).collect();
    for pre in [Precond::None, Precond::Jacobi, Precond::PointJacobi] {
        cg_case(&a, pre, o, b.clone());
    }
    let a32 = poisson::<f32>(8, 4.5, -1.0);
    let b32: Vec<f32> = b.iter().map(|&v| v as f32).collect();
    cg_case(
        &a32,
        Precond::Jacobi,
        SolveOptions { rtol: 1e-4, ..o },
        b32.clone(),
    );
    cg_case(&a32, Precond::None, SolveOptions { max_iter: 5, ..o }, b32);
    let k = DMat3::from_cols_array(&[4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0]);
    let a3 = poisson::<DMat3>(5, k * 4.0, -k);
    let b3: Vec<f64> = (0..75).map(|i| value(i + 9)).collect();
    cg_case(&a3, Precond::Jacobi, o, b3.clone());
    cg_case(&a3, Precond::PointJacobi, o, b3);
    let k2 = Mat2::from_cols_array(&[2.0, 0.5, 0.5, 1.0]);
    let a2 = poisson::<Mat2>(4, k2 * 4.0, -k2);
    let b2: Vec<f32> = (0..32).map(|i| value(i) as f32).collect();
    cg_case(&a2, Precond::Jacobi, SolveOptions { rtol: 1e-4, ..o }, b2);
    // A singular diagonal block: the solve stops before iterating, on both.
    let sing = Mat4::from_cols_array(&[1.0; 16]);
    let a4 = poisson::<Mat4>(2, sing, Mat4::IDENTITY);
    cg_case(&a4, Precond::Jacobi, o, vec![1.0f32; 16]);
    // An indefinite Jacobi preconditioner (a negative diagonal entry): r.z <= 0 stops the
    // solve as a breakdown, at the set-up (r.z = 1 - 4 < 0) or after an iteration (r.z = 1,
    // p.Ap = 2, then r.z = -0.25).
    let cpu = wp::cpu();
    let scalars = |n: usize, t: &[(i32, i32, f64)]| {
        let (r, c, v): (Vec<i32>, Vec<i32>, Vec<f64>) = t.iter().copied().fold(
            (vec![], vec![], vec![]),
            |(mut r, mut c, mut v), (i, j, x)| {
                r.push(i);
                c.push(j);
                v.push(x);
                (r, c, v)
            },
        );
        Bsr::from_triplets(
            n,
            n,
            &wp::Array::from_slice(&r, &cpu).unwrap(),
            &wp::Array::from_slice(&c, &cpu).unwrap(),
            &wp::Array::from_slice(&v, &cpu).unwrap(),
        )
        .unwrap()
    };
    let a = scalars(2, &[(0, 0, 1.0), (0, 1, -0.5), (1, 0, -0.5), (1, 1, -1.0)]);
    let rep = cg_case_from(&a, Precond::Jacobi, o, vec![1.0, 2.0], vec![0.0; 2]);
    assert_eq!(
        (rep.stop, rep.iterations),
        (
            Stop::Breakdown {
                what: "r.z",
                value: -3.0
            },
            0
        )
    );
    let t = [
        (0, 0, 1.0),
        (0, 1, 0.5),
        (1, 0, 0.5),
        (1, 1, -1.0),
        (2, 2, 1.0),
    ];
    let rep = cg_case_from(
        &scalars(3, &t),
        Precond::Jacobi,
        o,
        vec![1.0, -1.0, 1.0],
        vec![0.0; 3],
    );
    assert_eq!(
        (rep.stop, rep.iterations),
        (
            Stop::Breakdown {
                what: "r.z",
                value: -0.25
            },
            1
        )
    );
}

fn triplet_words<B: Block>(
    nrow: usize,
    ncol: usize,
    rows: &[i32],
    cols: &[i32],
    vals: &[B],
    device_count: Option<i32>,
) -> Vec<u64> {
    let mut w = vec![
        3,
        (std::mem::size_of::<B::Scalar>() == 8) as u64,
        (B::ROWS * B::COLS) as u64,
        nrow as u64,
        ncol as u64,
        rows.len() as u64,
    ];
    match device_count {
        Some(c) => w.extend([1, c as i64 as u64]),
        None => w.push(0),
    }
    w.extend(rows.iter().map(|&r| r as i64 as u64));
    w.extend(cols.iter().map(|&c| c as i64 as u64));
    w.extend(words(vals));
    w
}

fn triplet_case<B: Block>(
    nrow: usize,
    ncol: usize,
    count: usize,
    seed: usize,
    device_count: Option<i32>,
) {
    let cpu = wp::cpu();
    // The triplets of random_matrix.
    let rows: Vec<i32> = (0..count).map(|t| ((t * 7 + seed) % nrow) as i32).collect();
    let cols: Vec<i32> = (0..count)
        .map(|t| ((t * t + 3 * seed) % ncol) as i32)
        .collect();
    let rc = B::ROWS * B::COLS;
    let vals: Vec<B> = (0..count)
        .map(|t| {
            let s: Vec<B::Scalar> = (0..rc)
                .map(|e| B::Scalar::from_f64(value(seed * 100_000 + t * rc + e)))
                .collect();
            block::<B>(&s)
        })
        .collect();
    let (r, c, v) = (
        wp::Array::from_slice(&rows, &cpu).unwrap(),
        wp::Array::from_slice(&cols, &cpu).unwrap(),
        wp::Array::from_slice(&vals, &cpu).unwrap(),
    );
    let a = match device_count {
        Some(k) => {
            let k = wp::Array::from_slice(&[k], &cpu).unwrap();
            Bsr::from_triplets_n(nrow, ncol, &r, &c, &v, &k).unwrap()
        }
        None => Bsr::from_triplets(nrow, ncol, &r, &c, &v).unwrap(),
    };
    let out = run(
        &format!("tpl{}_{nrow}", kind::<B>()),
        &triplet_words(nrow, ncol, &rows, &cols, &vals, device_count),
    );
    let nnz = a.nnz().unwrap();
    assert_eq!(out[0], format!("matrix {nnz}"));
    let mut want: Vec<u64> = a
        .offsets()
        .to_vec()
        .unwrap()
        .iter()
        .map(|&o| o as u32 as u64)
        .collect();
    want.extend(
        a.columns().to_vec().unwrap()[..nnz]
            .iter()
            .map(|&c| c as u32 as u64),
    );
    want.extend(words(&a.values().to_vec().unwrap()[..nnz]));
    assert_eq!(
        hex(&out[1..]),
        want,
        "{} {nrow} x {ncol}",
        std::any::type_name::<B>()
    );
}

/// The triplet pipeline's C++ steps (keys, heads, run sums, offsets; one sort and two): the
/// same matrix as the CPU backend, bit for bit; and the same fault for a bad triplet.
#[test]
fn triplets_match_the_cpu_bit_for_bit() {
    if skip("triplets_match_the_cpu_bit_for_bit") {
        return;
    }
    triplet_case::<f32>(31, 17, 2000, 1, None);
    triplet_case::<f64>(5, 300, 1000, 2, None);
    triplet_case::<Mat3>(12, 9, 700, 3, None);
    triplet_case::<DMat2>(8, 8, 300, 4, None);
    // Two sorts (more cells than 32 bits): column, then row.
    triplet_case::<f32>(70_000, 70_000, 500, 5, None);
    // A device count: the first 1234 of 2000 triplets, and none of them.
    triplet_case::<f32>(31, 17, 2000, 1, Some(1234));
    triplet_case::<Mat3>(12, 9, 700, 3, Some(0));
    triplet_case::<f32>(70_000, 70_000, 500, 5, Some(321));
    // Faults: the CPU's error and the C++ report's record agree.
    let cpu = wp::cpu();
    for (rows, cols, vals) in [
        (vec![0, 1, 9, 0], vec![0, 1, 1, -3], vec![1.0f32; 4]),
        (vec![0, 1, 1, 0], vec![0, 1, 2, 0], vec![1.0f32; 4]),
        (
            vec![0, 1, 1, 0],
            vec![0, 1, 1, 0],
            vec![1.0, f32::NAN, 1.0, 1.0],
        ),
    ] {
        let e = Bsr::from_triplets(
            2,
            2,
            &wp::Array::from_slice(&rows, &cpu).unwrap(),
            &wp::Array::from_slice(&cols, &cpu).unwrap(),
            &wp::Array::from_slice(&vals, &cpu).unwrap(),
        )
        .unwrap_err();
        let want = match e {
            wp::Error::Fault(wp::Fault {
                kind: wp::FaultKind::OutOfBounds { arg, index, shape },
                ..
            }) => format!(
                "fault 1 {} {} {} {} {}",
                ["rows", "columns"].iter().position(|a| *a == arg).unwrap(),
                index[0],
                index[1],
                shape[0],
                shape[1]
            ),
            wp::Error::Fault(wp::Fault {
                kind: wp::FaultKind::NonFiniteInput { arg, index, values },
                ..
            }) => {
                assert_eq!(arg, "values");
                format!("fault 7 2 {index} {} 0 0", values[0].to_bits() as i64)
            }
            e => panic!("{e}"),
        };
        let out = run("tplfault", &triplet_words(2, 2, &rows, &cols, &vals, None));
        assert_eq!(out[0], want);
    }
    // A device count outside 0..=4 (of 4 triplets): out of bounds on `count` (argument 3).
    for k in [5, -1] {
        let (r, c, v) = ([0, 1, 1, 0], [0, 1, 1, 0], [1.0f32; 4]);
        let e = Bsr::from_triplets_n(
            2,
            2,
            &wp::Array::from_slice(&r, &cpu).unwrap(),
            &wp::Array::from_slice(&c, &cpu).unwrap(),
            &wp::Array::from_slice(&v, &cpu).unwrap(),
            &wp::Array::from_slice(&[k], &cpu).unwrap(),
        )
        .unwrap_err();
        match e {
            wp::Error::Fault(wp::Fault {
                kind: wp::FaultKind::OutOfBounds { arg, index, shape },
                ..
            }) => assert_eq!((arg, index, shape), ("count", vec![k as i128], vec![5])),
            e => panic!("{e}"),
        }
        let out = run("tplcount", &triplet_words(2, 2, &r, &c, &v, Some(k)));
        assert_eq!(out[0], format!("fault 1 3 {k} 0 5 0"));
        // The steps after the fault (which a GPU runs) treat the count as 0, the primitives'
        // rule: they process nothing, and the matrix is empty (offsets all 0).
        assert_eq!(out[1..], ["matrix 0", "0", "0", "0"], "count {k}");
    }
}

// ------------------------------------------------------------------------------------------
// Slice 2: the structure operations (wp_sparse_ops.h)
// ------------------------------------------------------------------------------------------

/// The head of an `ops` command: 4, the scalar, the operation, the block's R, C and layout.
fn ops_head<B: Block>(op: u64) -> Vec<u64> {
    vec![
        4,
        (std::mem::size_of::<B::Scalar>() == 8) as u64,
        op,
        B::ROWS as u64,
        B::COLS as u64,
        B::COL_MAJOR as u64,
    ]
}

/// Hex lines of words, as the driver prints them.
fn lines(words: &[u64]) -> Vec<String> {
    words.iter().map(|w| format!("{w:x}")).collect()
}

/// A CPU matrix as the driver's `print_matrix` prints it.
fn matrix_lines<B: Block>(a: &Bsr<B>) -> Vec<String> {
    let nnz = a.nnz().unwrap();
    let mut w: Vec<u64> = a
        .offsets()
        .to_vec()
        .unwrap()
        .iter()
        .map(|&o| o as u32 as u64)
        .collect();
    w.extend(
        a.columns().to_vec().unwrap()[..nnz]
            .iter()
            .map(|&c| c as u32 as u64),
    );
    w.extend(words(&a.values().to_vec().unwrap()[..nnz]));
    let mut out = vec![format!("matrix {nnz}")];
    out.extend(lines(&w));
    out
}

/// Every structure operation on blocks of `B`, through the C++ steps and through the CPU
/// backend's bodies (the public API): the same bits.
fn ops_case<B: sparse::SquareBlock + sparse::BlockMul<B, Output = B>>(seed: usize) {
    let what = std::any::type_name::<B>();
    let cpu = wp::cpu();
    let (nrow, ncol) = (23, 17);
    // scale
    let (a, aw) = random_matrix::<B>(nrow, ncol, 150, seed);
    let mut s = a.clone();
    s.scale(B::Scalar::from_f64(-0.3)).unwrap();
    let nnz = a.nnz().unwrap();
    let mut input = ops_head::<B>(0);
    input.extend(&aw);
    input.push((-0.3f64).to_bits());
    let got = run(&format!("scale_{seed}"), &input);
    assert_eq!(
        got,
        lines(&words(&s.values().to_vec().unwrap()[..nnz])),
        "{what} scale"
    );
    // diag
    let (a, aw) = random_matrix::<B>(nrow, ncol, 300, seed + 1);
    let out = wp::Array::<B>::zeros(ncol, &cpu).unwrap();
    sparse::diag(&a, &out).unwrap();
    let mut input = ops_head::<B>(1);
    input.extend(&aw);
    let got = run(&format!("diag_{seed}"), &input);
    assert_eq!(got, lines(&words(&out.to_vec().unwrap())), "{what} diag");
    // from_diag and identity
    let dw: Vec<B::Scalar> = (0..ncol * B::ROWS * B::COLS)
        .map(|i| B::Scalar::from_f64(value(seed + 3 * i)))
        .collect();
    let d: Vec<B> = from_scalars(&dw);
    let m = Bsr::from_diag(nrow, ncol, &wp::Array::from_slice(&d, &cpu).unwrap()).unwrap();
    let mut input = ops_head::<B>(2);
    input.extend([nrow as u64, ncol as u64, 1]);
    input.extend(dw.iter().map(|&v| word(v)));
    assert_eq!(
        run(&format!("fdiag_{seed}"), &input),
        matrix_lines(&m),
        "{what} from_diag"
    );
    let id = Bsr::<B>::identity(9, &cpu).unwrap();
    let mut input = ops_head::<B>(2);
    input.extend([9, 9, 0]);
    assert_eq!(
        run(&format!("id_{seed}"), &input),
        matrix_lines(&id),
        "{what} identity"
    );
    // to_dense
    let (r, c) = a.shape();
    let dense = wp::Array::<B::Scalar, 2>::zeros([r, c], &cpu).unwrap();
    a.to_dense(&dense).unwrap();
    let dv = dense.to_vec().unwrap();
    let mut input = ops_head::<B>(3);
    input.extend(&aw);
    let got = run(&format!("dense_{seed}"), &input);
    assert_eq!(
        got,
        lines(&dv.iter().map(|&v| word(v)).collect::<Vec<_>>()),
        "{what} to_dense"
    );
    // from_dense (the dense matrix of `a`: zero blocks where `a` has none)
    let back = Bsr::<B>::from_dense(&dense).unwrap();
    let mut input = ops_head::<B>(4);
    input.extend([nrow as u64, ncol as u64]);
    input.extend(dv.iter().map(|&v| word(v)));
    assert_eq!(
        run(&format!("fdense_{seed}"), &input),
        matrix_lines(&back),
        "{what} from_dense"
    );
    // transpose
    let t = a.transpose().unwrap();
    let mut input = ops_head::<B>(5);
    input.push(<B::Transpose as Block>::COL_MAJOR as u64);
    input.extend(&aw);
    assert_eq!(
        run(&format!("tr_{seed}"), &input),
        matrix_lines(&t),
        "{what} transpose"
    );
    // axpy (different structures, duplicates between them)
    let (x, xw) = random_matrix::<B>(nrow, ncol, 120, seed + 2);
    let (mut y, yw) = random_matrix::<B>(nrow, ncol, 90, seed + 3);
    sparse::axpy(
        B::Scalar::from_f64(0.75),
        &x,
        B::Scalar::from_f64(-1.25),
        &mut y,
    )
    .unwrap();
    let mut input = ops_head::<B>(6);
    input.extend(&xw);
    input.extend(&yw);
    input.extend([0.75f64.to_bits(), (-1.25f64).to_bits()]);
    assert_eq!(
        run(&format!("axpy_{seed}"), &input),
        matrix_lines(&y),
        "{what} axpy"
    );
    // mm: alpha A B, and alpha A B + beta C; a fixed capacity one product short faults
    let (a, aw) = random_matrix::<B>(nrow, ncol, 90, seed + 4);
    let (b, bw) = random_matrix::<B>(ncol, 19, 80, seed + 5);
    for beta in [0.0, 0.5] {
        let (mut cm, cw) = random_matrix::<B>(nrow, 19, 40, seed + 6);
        let alpha = B::Scalar::from_f64(-1.5);
        sparse::mm(
            alpha,
            &a,
            &b,
            B::Scalar::from_f64(beta),
            &mut cm,
            &mut sparse::MmWork::new(),
        )
        .unwrap();
        let mut input = ops_head::<B>(7);
        input.extend([B::COLS as u64, B::COL_MAJOR as u64, B::COL_MAJOR as u64]);
        input.extend(&aw);
        input.extend(&bw);
        input.extend(&cw);
        input.extend([(-1.5f64).to_bits(), f64::to_bits(beta), -1i64 as u64]);
        assert_eq!(
            run(&format!("mm_{seed}_{beta}"), &input),
            matrix_lines(&cm),
            "{what} mm beta {beta}"
        );
    }
    let products: usize = {
        let ac = a.columns().to_vec().unwrap();
        let bo = b.offsets().to_vec().unwrap();
        (0..a.nnz().unwrap())
            .map(|k| (bo[ac[k] as usize + 1] - bo[ac[k] as usize]) as usize)
            .sum()
    };
    let mut cm = Bsr::<B>::zeros(nrow, 19, &cpu).unwrap();
    let e = sparse::mm(
        B::Scalar::ONE,
        &a,
        &b,
        B::Scalar::ZERO,
        &mut cm,
        &mut sparse::MmWork::with_capacity(products - 1),
    )
    .unwrap_err();
    match e {
        wp::Error::Fault(wp::Fault {
            kernel: "sparse::mm",
            kind: wp::FaultKind::OutOfBounds { arg, index, shape },
            ..
        }) => assert_eq!(
            (arg, index, shape),
            ("products", vec![products as i128], vec![products])
        ),
        e => panic!("{what}: {e}"),
    }
    let (_, cw) = random_matrix::<B>(nrow, 19, 40, seed + 6);
    let mut input = ops_head::<B>(7);
    input.extend([B::COLS as u64, B::COL_MAJOR as u64, B::COL_MAJOR as u64]);
    input.extend(&aw);
    input.extend(&bw);
    input.extend(&cw);
    input.extend([1f64.to_bits(), 0f64.to_bits(), (products - 1) as u64]);
    let out = run(&format!("mmcap_{seed}"), &input);
    // The same fault (out of bounds on argument 3, `products`), then (as a GPU runs on)
    // an empty product.
    assert_eq!(
        out[0],
        format!("fault 1 3 {products} 0 {products} 0"),
        "{what}"
    );
    assert_eq!(out[1], "matrix 0");
}

/// The structure operations' C++ steps (scale, diag, from_diag, identity, to_dense,
/// from_dense, transpose, axpy and mm through the triplet pipeline, mm's capacity fault) give
/// the CPU backend's bits, for scalar, glam f32 and f64 blocks.
#[test]
fn structure_ops_match_the_cpu_bit_for_bit() {
    if skip("structure_ops_match_the_cpu_bit_for_bit") {
        return;
    }
    ops_case::<f32>(1);
    ops_case::<f64>(2);
    ops_case::<Mat2>(3);
    ops_case::<Mat3>(4);
    ops_case::<Mat4>(5);
    ops_case::<DMat2>(6);
    ops_case::<DMat3>(7);
    ops_case::<DMat4>(8);
}

/// from_dense's non-finite fault: the same index (the first in row-major order) and value on
/// both.
#[test]
fn from_dense_fault_matches_the_cpu() {
    if skip("from_dense_fault_matches_the_cpu") {
        return;
    }
    let cpu = wp::cpu();
    let mut v = vec![1.0f32; 6 * 4];
    v[4 + 3] = f32::NEG_INFINITY;
    v[2 * 4] = f32::NAN;
    let a = wp::Array::from_slice(&v, &cpu)
        .unwrap()
        .reshape([6, 4])
        .unwrap();
    let e = Bsr::<Mat2>::from_dense(&a).unwrap_err();
    let (index, x) = match e {
        wp::Error::Fault(wp::Fault {
            kernel: "sparse::from_dense",
            kind:
                wp::FaultKind::NonFiniteInput {
                    arg: "a",
                    index,
                    values,
                },
            ..
        }) => (index, values[0]),
        e => panic!("{e}"),
    };
    assert_eq!((index, x), (7, f64::NEG_INFINITY));
    let mut input = ops_head::<Mat2>(4);
    input.extend([3, 2]);
    input.extend(v.iter().map(|&x| word(x)));
    let out = run("fdense_fault", &input);
    assert_eq!(out[0], format!("fault 7 0 {index} {}", x.to_bits() as i64));
}

/// The rectangular blocks' operations through the C++ steps: mv (wp_sparse_ops.h's
/// instantiations), transpose (into the transposed shape), dense both ways, axpy, and mm of
/// mixed shapes and layouts; the same bits as the CPU backend.
fn rect_case<A, B>(seed: usize)
where
    A: sparse::BlockMul<B>,
    B: Block<Scalar = A::Scalar>,
{
    let what = std::any::type_name::<A>();
    let cpu = wp::cpu();
    mv_case::<A>(seed);
    let (nrow, ncol) = (19, 11);
    let (a, aw) = random_matrix::<A>(nrow, ncol, 120, seed);
    // transpose
    let t = a.transpose().unwrap();
    let mut input = ops_head::<A>(5);
    input.push(<A::Transpose as Block>::COL_MAJOR as u64);
    input.extend(&aw);
    assert_eq!(
        run(&format!("rtr_{seed}"), &input),
        matrix_lines(&t),
        "{what} transpose"
    );
    // dense both ways
    let (r, c) = a.shape();
    let dense = wp::Array::<A::Scalar, 2>::zeros([r, c], &cpu).unwrap();
    a.to_dense(&dense).unwrap();
    let dv = dense.to_vec().unwrap();
    let mut input = ops_head::<A>(3);
    input.extend(&aw);
    let got = run(&format!("rdense_{seed}"), &input);
    assert_eq!(
        got,
        lines(&dv.iter().map(|&v| word(v)).collect::<Vec<_>>()),
        "{what} to_dense"
    );
    let back = Bsr::<A>::from_dense(&dense).unwrap();
    let mut input = ops_head::<A>(4);
    input.extend([nrow as u64, ncol as u64]);
    input.extend(dv.iter().map(|&v| word(v)));
    assert_eq!(
        run(&format!("rfdense_{seed}"), &input),
        matrix_lines(&back),
        "{what} from_dense"
    );
    // axpy
    let (x, xw) = random_matrix::<A>(nrow, ncol, 70, seed + 1);
    let (mut y, yw) = random_matrix::<A>(nrow, ncol, 60, seed + 2);
    sparse::axpy(
        A::Scalar::from_f64(-0.5),
        &x,
        A::Scalar::from_f64(2.0),
        &mut y,
    )
    .unwrap();
    let mut input = ops_head::<A>(6);
    input.extend(&xw);
    input.extend(&yw);
    input.extend([(-0.5f64).to_bits(), 2f64.to_bits()]);
    assert_eq!(
        run(&format!("raxpy_{seed}"), &input),
        matrix_lines(&y),
        "{what} axpy"
    );
    // mm: A (nrow x ncol) times B (ncol x 13), plus beta C
    let (b, bw) = random_matrix::<B>(ncol, 13, 60, seed + 3);
    let (mut cm, cw) = random_matrix::<A::Output>(nrow, 13, 30, seed + 4);
    sparse::mm(
        A::Scalar::from_f64(1.25),
        &a,
        &b,
        A::Scalar::from_f64(-0.75),
        &mut cm,
        &mut sparse::MmWork::new(),
    )
    .unwrap();
    let mut input = ops_head::<A>(7);
    input.extend([
        B::COLS as u64,
        B::COL_MAJOR as u64,
        <A::Output as Block>::COL_MAJOR as u64,
    ]);
    input.extend(&aw);
    input.extend(&bw);
    input.extend(&cw);
    input.extend([1.25f64.to_bits(), (-0.75f64).to_bits(), -1i64 as u64]);
    assert_eq!(
        run(&format!("rmm_{seed}"), &input),
        matrix_lines(&cm),
        "{what} mm"
    );
}

/// Rectangular (row-major) blocks, alone and mixed with glam's column-major squares: the
/// C++ steps give the CPU backend's bits.
#[test]
fn rectangular_blocks_match_the_cpu_bit_for_bit() {
    use warp_lang::{DMat26, DMat32, DMat46, DMat63, Mat23, Mat24, Mat32, Mat43, Mat62, Mat64};
    if skip("rectangular_blocks_match_the_cpu_bit_for_bit") {
        return;
    }
    rect_case::<Mat23, Mat32>(1);
    rect_case::<Mat32, Mat23>(2);
    rect_case::<Mat24, Mat43>(3);
    rect_case::<Mat62, Mat23>(4);
    rect_case::<Mat64, Mat4>(5);
    rect_case::<DMat26, DMat63>(6);
    rect_case::<DMat32, DMat2>(7);
    rect_case::<DMat46, DMat63>(8);
    // A square (column-major) block times a rectangular one.
    rect_case_square::<DMat3, DMat32>(9);
}

/// mm of a square block by a rectangular one (the other operations are ops_case's).
fn rect_case_square<A, B>(seed: usize)
where
    A: sparse::BlockMul<B>,
    B: Block<Scalar = A::Scalar>,
{
    let (a, aw) = random_matrix::<A>(10, 7, 50, seed);
    let (b, bw) = random_matrix::<B>(7, 9, 40, seed + 1);
    let (mut cm, cw) = random_matrix::<A::Output>(10, 9, 20, seed + 2);
    sparse::mm(
        A::Scalar::from_f64(0.5),
        &a,
        &b,
        A::Scalar::from_f64(1.0),
        &mut cm,
        &mut sparse::MmWork::new(),
    )
    .unwrap();
    let mut input = ops_head::<A>(7);
    input.extend([
        B::COLS as u64,
        B::COL_MAJOR as u64,
        <A::Output as Block>::COL_MAJOR as u64,
    ]);
    input.extend(&aw);
    input.extend(&bw);
    input.extend(&cw);
    input.extend([0.5f64.to_bits(), 1f64.to_bits(), -1i64 as u64]);
    assert_eq!(run(&format!("rsmm_{seed}"), &input), matrix_lines(&cm));
}

/// A whole BiCGSTAB (method 0), CR (1) or GMRES (2) solve through the C++ steps (the
/// solver's steps and host loop replayed by the driver) against the CPU backend's: the same
/// stop (and breakdown quantity), iterations, history and x bits. Returns the CPU's report.
fn krylov_case<B: sparse::SquareBlock>(
    method: u64,
    a: &Bsr<B>,
    pre: Precond,
    o: SolveOptions,
    b: Vec<B::Scalar>,
    x0: Vec<B::Scalar>,
) -> sparse::SolveReport {
    let cpu = wp::cpu();
    let x = wp::Array::from_slice(&x0, &cpu).unwrap();
    let bb = wp::Array::from_slice(&b, &cpu).unwrap();
    let rep = match method {
        0 => sparse::bicgstab(a, &bb, &x, pre, &o),
        1 => sparse::cr(a, &bb, &x, pre, &o),
        _ => sparse::gmres(a, &bb, &x, pre, &o),
    }
    .unwrap();
    let mut input = vec![5, kind::<B>()];
    input.extend(matrix_words(a));
    input.extend(b.iter().map(|&v| word(v)));
    input.extend(x0.iter().map(|&v| word(v)));
    let code = match pre {
        Precond::None => 0,
        Precond::Jacobi => 1,
        Precond::PointJacobi => 2,
    };
    input.extend([
        method,
        code,
        o.rtol.to_bits(),
        o.atol.to_bits(),
        o.max_iter as u64,
        o.check_every as u64,
        o.restart as u64,
    ]);
    let out = run(&format!("kr{method}_{}_{code}", kind::<B>()), &input);
    let head: Vec<i64> = out[0].split(' ').map(|t| t.parse().unwrap()).collect();
    const WHATS: [&str; 6] = ["rho", "omega", "r0.v", "Ap.M^-1Ap", "z.Az", "H_jj"];
    let (stop, what) = match rep.stop {
        Stop::Converged => (1, None),
        Stop::MaxIterations => (2, None),
        Stop::NonFinite => (3, None),
        Stop::Breakdown { what, .. } => (4, Some(what)),
        Stop::SingularPreconditioner { .. } => (5, None),
    };
    let name = format!("method {method} {} {pre:?}", std::any::type_name::<B>());
    assert_eq!(
        (head[0], head[1] as usize),
        (stop, rep.iterations),
        "{name}: {rep:?}"
    );
    if let Some(what) = what {
        assert_eq!(WHATS[head[3] as usize], what, "{name}");
    }
    let words_out = hex(&out[1..]);
    let (hist, xs) = words_out.split_at(rep.iterations + 1);
    let want_hist: Vec<u64> = rep
        .history
        .iter()
        .map(|&h| word(B::Scalar::from_f64(h)))
        .collect();
    assert_eq!(hist, want_hist, "{name}: history");
    let want_x: Vec<u64> = x.to_vec().unwrap().iter().map(|&v| word(v)).collect();
    assert_eq!(xs, want_x, "{name}: x");
    rep
}

/// The 2-D convection-diffusion operator on an `m x m` grid (4 on the diagonal, `-1 -/+ c`
/// to the neighbours along x, `-1 -/+ c / 2` along y), scaled by `k` (a block type's
/// scalar multiple): non-symmetric.
fn convection<B: Block + std::ops::Mul<<B as Block>::Scalar, Output = B>>(
    m: usize,
    c: f64,
    k: B,
) -> Bsr<B> {
    let s = B::Scalar::from_f64;
    let cpu = wp::cpu();
    let (mut r, mut cc, mut v) = (vec![], vec![], vec![]);
    for i in 0..m * m {
        let (y, x) = (i / m, i % m);
        r.push(i as i32);
        cc.push(i as i32);
        v.push(k * s(4.0));
        for (dy, dx, w) in [
            (0i64, -1i64, -1.0 - c),
            (0, 1, -1.0 + c),
            (-1, 0, -1.0 - c / 2.0),
            (1, 0, -1.0 + c / 2.0),
        ] {
            let (yy, xx) = (y as i64 + dy, x as i64 + dx);
            if (0..m as i64).contains(&yy) && (0..m as i64).contains(&xx) {
                r.push(i as i32);
                cc.push((yy as usize * m + xx as usize) as i32);
                v.push(k * s(w));
            }
        }
    }
    Bsr::from_triplets(
        m * m,
        m * m,
        &wp::Array::from_slice(&r, &cpu).unwrap(),
        &wp::Array::from_slice(&cc, &cpu).unwrap(),
        &wp::Array::from_slice(&v, &cpu).unwrap(),
    )
    .unwrap()
}

/// Whole BiCGSTAB, CR and GMRES solves through the C++ steps: the same stop, iterations,
/// history and x bits as the CPU backend; f64 and f32 scalars, `DMat3`/`Mat2` blocks, no
/// preconditioner, block and point Jacobi, GMRES restarts (cycles of 5, and of 30: one) with
/// `max_iter` stopping inside a cycle, a singular preconditioner, and each breakdown.
#[test]
fn krylov_matches_the_cpu_bit_for_bit() {
    if skip("krylov_matches_the_cpu_bit_for_bit") {
        return;
    }
    // Small systems and tolerances: the emulator runs each dot's 256-thread blocks as fibers.
    let o = SolveOptions {
        rtol: 1e-6,
        check_every: 4,
        restart: 5,
        ..Default::default()
    };
    let sym = poisson::<f64>(5, 4.0, -1.0);
    let conv = convection::<f64>(5, 0.6, 1.0f64);
    let b: Vec<f64> = (0..25).map(value).collect();
    let x0: Vec<f64> = (0..25).map(|i| value(i + 3) * 0.01).collect();
    for pre in [Precond::None, Precond::Jacobi, Precond::PointJacobi] {
        for method in [0, 2] {
            let rep = krylov_case(method, &conv, pre, o, b.clone(), x0.clone());
            assert_eq!(rep.stop, Stop::Converged, "{method} {pre:?}");
        }
        let rep = krylov_case(1, &sym, pre, o, b.clone(), x0.clone());
        assert_eq!(rep.stop, Stop::Converged, "CR {pre:?}");
    }
    // A cycle long enough to converge in one.
    let rep = krylov_case(
        2,
        &conv,
        Precond::Jacobi,
        SolveOptions { restart: 30, ..o },
        b.clone(),
        x0.clone(),
    );
    assert_eq!(rep.stop, Stop::Converged, "GMRES(30)");
    // max_iter inside a GMRES cycle, and for the others.
    for method in [0, 1, 2] {
        let a = if method == 1 { &sym } else { &conv };
        let rep = krylov_case(
            method,
            a,
            Precond::Jacobi,
            SolveOptions {
                max_iter: 7,
                rtol: 1e-14,
                ..o
            },
            b.clone(),
            x0.clone(),
        );
        assert_eq!(
            (rep.stop, rep.iterations),
            (Stop::MaxIterations, 7),
            "{method}"
        );
    }
    // f32 and blocks.
    let conv32 = convection::<f32>(5, 0.5, 1.0f32);
    let b32: Vec<f32> = (0..25).map(|i| value(i) as f32).collect();
    for method in [0, 2] {
        krylov_case(
            method,
            &conv32,
            Precond::Jacobi,
            SolveOptions { rtol: 1e-4, ..o },
            b32.clone(),
            vec![0.0; 25],
        );
    }
    let k = DMat3::from_cols_array(&[4.0, 1.0, 0.0, 1.0, 3.0, 1.0, 0.0, 1.0, 2.0]);
    let a3 = poisson::<DMat3>(3, k * 4.0, -k);
    let b3: Vec<f64> = (0..27).map(|i| value(i + 9)).collect();
    for method in [0, 1, 2] {
        for pre in [Precond::Jacobi, Precond::PointJacobi] {
            krylov_case(method, &a3, pre, o, b3.clone(), vec![0.0; 27]);
        }
    }
    let k2 = Mat2::from_cols_array(&[2.0, 0.5, -0.5, 1.0]);
    let a2 = convection::<Mat2>(3, 0.4, k2);
    let b2: Vec<f32> = (0..18).map(|i| value(i) as f32).collect();
    krylov_case(
        0,
        &a2,
        Precond::Jacobi,
        SolveOptions { rtol: 1e-4, ..o },
        b2.clone(),
        vec![0.0; 18],
    );
    krylov_case(
        2,
        &a2,
        Precond::Jacobi,
        SolveOptions { rtol: 1e-4, ..o },
        b2,
        vec![0.0; 18],
    );
    // A singular diagonal block: every method stops before iterating.
    let sing = Mat4::from_cols_array(&[1.0; 16]);
    let a4 = poisson::<Mat4>(2, sing, Mat4::IDENTITY);
    for method in [0, 1, 2] {
        let rep = krylov_case(
            method,
            &a4,
            Precond::Jacobi,
            o,
            vec![1.0f32; 16],
            vec![0.0; 16],
        );
        assert!(
            matches!(rep.stop, Stop::SingularPreconditioner { .. }),
            "{rep:?}"
        );
    }
    // The breakdowns (exact in binary; see the suite's `krylov_breakdowns`).
    let cpu = wp::cpu();
    let scalars = |n: usize, t: &[(i32, i32, f64)]| {
        let r: Vec<i32> = t.iter().map(|e| e.0).collect();
        let c: Vec<i32> = t.iter().map(|e| e.1).collect();
        let v: Vec<f64> = t.iter().map(|e| e.2).collect();
        Bsr::from_triplets(
            n,
            n,
            &wp::Array::from_slice(&r, &cpu).unwrap(),
            &wp::Array::from_slice(&c, &cpu).unwrap(),
            &wp::Array::from_slice(&v, &cpu).unwrap(),
        )
        .unwrap()
    };
    // (method, n, triplets, b, the breakdown's quantity)
    type Case = (u64, usize, Vec<(i32, i32, f64)>, Vec<f64>, &'static str);
    let cases: [Case; 5] = [
        (
            0,
            2,
            vec![(0, 1, 1.0), (1, 0, -1.0)],
            vec![1.0, 0.0],
            "r0.v",
        ),
        (
            0,
            3,
            vec![
                (0, 0, 1.0),
                (0, 2, 1.0),
                (1, 0, 1.0),
                (1, 1, -2.0),
                (1, 2, -2.0),
                (2, 1, 1.0),
            ],
            vec![1.0, -1.0, 0.0],
            "omega",
        ),
        (
            0,
            3,
            vec![
                (0, 0, 2.0),
                (0, 1, -1.0),
                (1, 1, 2.0),
                (1, 2, 1.0),
                (2, 0, 2.0),
                (2, 2, 2.0),
            ],
            vec![0.0, -1.0, 0.0],
            "rho",
        ),
        (
            1,
            2,
            vec![(0, 0, 1.0), (1, 1, -1.0)],
            vec![1.0, 1.0],
            "z.Az",
        ),
        (2, 2, vec![(0, 1, 1.0)], vec![0.0, 1.0], "H_jj"),
    ];
    for (method, n, t, b, what) in cases {
        let rep = krylov_case(method, &scalars(n, &t), Precond::None, o, b, vec![0.0; n]);
        assert!(
            matches!(rep.stop, Stop::Breakdown { what: w, .. } if w == what),
            "{rep:?}"
        );
    }
}

// ------------------------------------------------------------------------------------------
// Slice 6: graph colouring (wp_sparse_color.h)
// ------------------------------------------------------------------------------------------

/// The driver's i32 lines (printed as the low 32 bits).
fn i32s(lines: &[String]) -> Vec<i32> {
    hex(lines).into_iter().map(|w| w as u32 as i32).collect()
}

/// Random graphs (with repeats and self-loops in the edge list) coloured by the header's
/// rounds, keys and offsets under the emulator at several block shapes (grid-stride loops
/// that wrap), against `Coloring::new` on the CPU: the same colours, order and offsets. And
/// the split and pair steps against their definitions.
#[test]
fn coloring_matches_the_cpu() {
    use glam::IVec2;
    use sparse::{Adjacency, Coloring};
    if skip("coloring_matches_the_cpu") {
        return;
    }
    let cpu = wp::cpu();
    let mut state = 12345u64;
    let mut below = |n: u32| {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((state >> 33) % n as u64) as i32
    };
    for (case, &(n, m)) in [
        (1usize, 1usize),
        (7, 12),
        (60, 300),
        (500, 1500),
        (90, 4000),
    ]
    .iter()
    .enumerate()
    {
        let edges: Vec<IVec2> = (0..m)
            .map(|_| IVec2::new(below(n as u32), below(n as u32)))
            .collect();
        let e = wp::Array::from_slice(&edges, &cpu).unwrap();
        let g = Adjacency::from_edges(n, &e).unwrap();
        let (off, cols) = (g.offsets().to_vec().unwrap(), g.columns().to_vec().unwrap());
        for (seed, (threads, blocks)) in [(0u32, (1u64, 1u64)), (77, (32, 3)), (9, (5, 2))] {
            let c = Coloring::new(&g, seed).unwrap();
            let mut w = vec![
                6,
                0,
                n as u64,
                cols.len() as u64,
                seed as u64,
                threads,
                blocks,
            ];
            w.extend(off.iter().map(|&v| v as i64 as u64));
            w.extend(cols.iter().map(|&v| v as i64 as u64));
            let out = i32s(&run(&format!("color_{case}_{seed}"), &w));
            let k = c.count();
            assert_eq!(out.len(), 2 * n + k + 1);
            assert_eq!(out[..n], c.colors.to_vec().unwrap(), "case {case}: colours");
            assert_eq!(
                out[n..2 * n],
                c.order.to_vec().unwrap(),
                "case {case}: order"
            );
            assert_eq!(
                out[2 * n..],
                c.offsets.to_vec().unwrap(),
                "case {case}: offsets"
            );
        }
        // The split, both ways and as incidence; an endpoint out of range (n) in edge m / 2.
        let mut bad = edges.clone();
        bad[m / 2].y = n as i32;
        for incidence in [0u64, 1] {
            let mut w = vec![7, 0, m as u64, n as u64, incidence, 32, 2];
            w.extend(
                bad.iter()
                    .flat_map(|e| [e.x as i64 as u64, e.y as i64 as u64]),
            );
            let out = i32s(&run(&format!("split_{case}_{incidence}"), &w));
            assert_eq!(out.len(), 6 * m + 1);
            for (t, e) in bad.iter().enumerate() {
                let ok = (0..n as i32).contains(&e.x) && (0..n as i32).contains(&e.y);
                let (rows, cols, flags) = (&out[..2 * m], &out[2 * m..4 * m], &out[4 * m..6 * m]);
                assert_eq!([rows[2 * t], rows[2 * t + 1]], [e.x, e.y]);
                if incidence == 1 {
                    assert_eq!([cols[2 * t], cols[2 * t + 1]], [t as i32; 2]);
                    assert_eq!(flags[2 * t], ok as i32);
                } else {
                    assert_eq!([cols[2 * t], cols[2 * t + 1]], [e.y, e.x]);
                    assert_eq!(flags[2 * t], (ok && e.x != e.y) as i32);
                }
                assert_eq!(flags[2 * t], flags[2 * t + 1]);
            }
            let first_bad = bad
                .iter()
                .position(|e| !((0..n as i32).contains(&e.x) && (0..n as i32).contains(&e.y)));
            assert_eq!(out[6 * m], first_bad.map_or(i32::MAX, |t| t as i32));
        }
        // The pairs of the graph's rows taken as an incidence pattern: every ordered pair of
        // distinct entries of a row, rows in order, in the row's order.
        let mut w = vec![8, 0, n as u64, cols.len() as u64, 32, 2];
        w.extend(off.iter().map(|&v| v as i64 as u64));
        w.extend(cols.iter().map(|&v| v as i64 as u64));
        let out = i32s(&run(&format!("pairs_{case}"), &w));
        let mut want = (vec![], vec![]);
        for r in 0..n {
            let row = &cols[off[r] as usize..off[r + 1] as usize];
            for (i, &a) in row.iter().enumerate() {
                for (j, &b) in row.iter().enumerate() {
                    if i != j {
                        want.0.push(a);
                        want.1.push(b);
                    }
                }
            }
        }
        let p = want.0.len();
        assert_eq!(out.len(), 2 * p);
        assert_eq!(
            (&out[..p], &out[p..]),
            (&want.0[..], &want.1[..]),
            "case {case}: pairs"
        );
    }
}

// ---- Slice 5: the adjoint kernels ----

/// The driver's scalar code (0 f32, 1 f64).
fn scalar_kind<S: SparseScalar>() -> u64 {
    (std::mem::size_of::<S>() == 8) as u64
}

/// The assembly's adjoint (`adj_tpl`) of random triplets with duplicates, a host or a device
/// count: the triplets' gradient from the blocks' through the tape on the CPU, and the
/// kernel after the header's own pipeline.
fn adjoint_tpl_case<B: Block>(count: Option<i32>, seed: usize) {
    let cpu = wp::cpu();
    let (nrow, ncol, n) = (13, 11, 90);
    let rc = B::ROWS * B::COLS;
    let rows: Vec<i32> = (0..n).map(|t| ((t * 7 + seed) % nrow) as i32).collect();
    let cols: Vec<i32> = (0..n).map(|t| ((t * t + 3 * seed) % ncol) as i32).collect();
    let scal = |off: usize| -> Vec<B::Scalar> {
        (0..n * rc)
            .map(|e| B::Scalar::from_f64(value(seed * 1000 + off + e)))
            .collect()
    };
    let (vs, gs) = (scal(0), scal(500_000));
    let tv = wp::Array::from_slice(&from_scalars::<B, B::Scalar>(&vs), &cpu)
        .unwrap()
        .with_grad()
        .unwrap();
    let (r, c) = (
        wp::Array::from_slice(&rows, &cpu).unwrap(),
        wp::Array::from_slice(&cols, &cpu).unwrap(),
    );
    let dc = wp::Array::from_slice(&[count.unwrap_or(0)], &cpu).unwrap();
    let tape = wp::Tape::new();
    let a = {
        let _rec = tape.record();
        match count {
            None => Bsr::from_triplets(nrow, ncol, &r, &c, &tv).unwrap(),
            Some(_) => Bsr::from_triplets_n(nrow, ncol, &r, &c, &tv, &dc).unwrap(),
        }
    };
    let g = a.values().grad().unwrap();
    g.copy_from(&wp::Array::from_slice(&from_scalars::<B, B::Scalar>(&gs), &cpu).unwrap())
        .unwrap();
    tape.backward_from_grads().unwrap();
    let want = words(&tv.grad().unwrap().to_vec().unwrap());
    let mut input = vec![9, scalar_kind::<B::Scalar>(), 0];
    input.extend([rc as u64, nrow as u64, ncol as u64, n as u64]);
    match count {
        None => input.push(0),
        Some(k) => input.extend([1, k as i64 as u64]),
    }
    input.extend(rows.iter().map(|&v| v as i64 as u64));
    input.extend(cols.iter().map(|&v| v as i64 as u64));
    input.extend(vs.iter().map(|&v| word(v)));
    input.extend(gs.iter().map(|&v| word(v)));
    let got = hex(&run(&format!("adj_tpl{}", kind::<B>()), &input));
    assert_eq!(got, want, "{}: count {count:?}", std::any::type_name::<B>());
}

/// mv's adjoint (`adj_outer` into a preset gradient, `adj_axpby` scaling y's gradient by
/// beta) through the tape on the CPU, against the kernels; `transposed`: mv_transpose's
/// (the outer product's factors swapped).
fn adjoint_mv_case<B: Block>(seed: usize, transposed: bool) {
    let cpu = wp::cpu();
    let (nrow, ncol) = (17, 12);
    let (a, mw) = random_matrix::<B>(nrow, ncol, 120, seed);
    let a = a.with_grad().unwrap();
    let (nnz, cap, rc) = (a.nnz().unwrap(), a.nnz_bound(), B::ROWS * B::COLS);
    let vals = |len: usize, off: usize| -> Vec<B::Scalar> {
        (0..len)
            .map(|i| B::Scalar::from_f64(value(seed * 977 + off + i)))
            .collect()
    };
    let g0 = vals(cap * rc, 0);
    a.values()
        .grad()
        .unwrap()
        .copy_from(&wp::Array::from_slice(&from_scalars::<B, B::Scalar>(&g0), &cpu).unwrap())
        .unwrap();
    let (rows, cols) = (nrow * B::ROWS, ncol * B::COLS);
    let (alpha, beta) = (-1.75, 0.625);
    let (al, be) = (B::Scalar::from_f64(alpha), B::Scalar::from_f64(beta));
    let tape = wp::Tape::new();
    // x in A's columns and ȳ in its rows (mv), or the other way round (mv_transpose).
    let (xs, ys) = if transposed {
        (vals(rows, 900_000), vals(cols, 800_000))
    } else {
        (vals(cols, 900_000), vals(rows, 800_000))
    };
    let ygrad: Vec<u64> = if transposed {
        let x = wp::Array::from_slice(&from_scalars::<B::Out, B::Scalar>(&xs), &cpu).unwrap();
        let y = wp::Array::<B::In>::zeros(ncol, &cpu)
            .unwrap()
            .with_grad()
            .unwrap();
        {
            let _rec = tape.record();
            sparse::mv_transpose(al, &a, &x, be, &y).unwrap();
        }
        let yg = y.grad().unwrap();
        yg.copy_from(&wp::Array::from_slice(&from_scalars::<B::In, B::Scalar>(&ys), &cpu).unwrap())
            .unwrap();
        tape.backward_from_grads().unwrap();
        let v = yg.to_vec().unwrap();
        bytemuck::cast_slice::<B::In, B::Scalar>(&v)
            .iter()
            .map(|&s| word(s))
            .collect()
    } else {
        let x = wp::Array::from_slice(&from_scalars::<B::In, B::Scalar>(&xs), &cpu).unwrap();
        let y = wp::Array::<B::Out>::zeros(nrow, &cpu)
            .unwrap()
            .with_grad()
            .unwrap();
        {
            let _rec = tape.record();
            sparse::mv(al, &a, &x, be, &y).unwrap();
        }
        let yg = y.grad().unwrap();
        yg.copy_from(
            &wp::Array::from_slice(&from_scalars::<B::Out, B::Scalar>(&ys), &cpu).unwrap(),
        )
        .unwrap();
        tape.backward_from_grads().unwrap();
        let v = yg.to_vec().unwrap();
        bytemuck::cast_slice::<B::Out, B::Scalar>(&v)
            .iter()
            .map(|&s| word(s))
            .collect()
    };
    let name = std::any::type_name::<B>();
    let want_g = words(&a.values().grad().unwrap().to_vec().unwrap()[..nnz]);
    let (u, v) = if transposed { (&xs, &ys) } else { (&ys, &xs) };
    let mut input = vec![9, scalar_kind::<B::Scalar>(), 1];
    input.extend([B::ROWS as u64, B::COLS as u64, B::COL_MAJOR as u64]);
    input.extend(&mw);
    input.extend(u.iter().map(|&s| word(s)));
    input.extend(v.iter().map(|&s| word(s)));
    input.extend(g0[..nnz * rc].iter().map(|&s| word(s)));
    input.push(alpha.to_bits());
    let got = hex(&run(&format!("adj_outer{}", kind::<B>()), &input));
    assert_eq!(
        got, want_g,
        "{name} (transposed {transposed}): A's gradient"
    );
    let mut input = vec![9, scalar_kind::<B::Scalar>(), 2, ys.len() as u64];
    input.extend(ys.iter().map(|&s| word(s)));
    input.push(0);
    input.extend([beta.to_bits(), 0f64.to_bits()]);
    let got = hex(&run(&format!("adj_scale{}", kind::<B>()), &input));
    assert_eq!(got, ygrad, "{name} (transposed {transposed}): y's gradient");
}

/// `y = a y + b x` with an x (a solve's `b.grad += lambda`), against the same formula on
/// the host (each product and the sum rounded once in S).
fn adjoint_axpby_case<S: SparseScalar + Block<Scalar = S>>(seed: usize) {
    let n = 1000;
    let ys: Vec<S> = (0..n).map(|i| S::from_f64(value(seed + 3 * i))).collect();
    let xs: Vec<S> = (0..n)
        .map(|i| S::from_f64(value(seed + 5 * i + 1)))
        .collect();
    for (a, b) in [(1.0, 1.0), (0.75, -2.5)] {
        let (sa, sb) = (S::from_f64(a).to_f64(), S::from_f64(b).to_f64());
        // Each operation rounded once in S: for f64 directly; for f32, f64 holds the exact
        // product of two f32s (48 bits), and the exact sum of two f32s within 2^29 of each
        // other in magnitude (`value`'s spread is 10^6), so one rounding to f32 each.
        let want: Vec<u64> = ys
            .iter()
            .zip(&xs)
            .map(|(&y, &x)| {
                let ay = S::from_f64(sa * y.to_f64());
                let bx = S::from_f64(sb * x.to_f64());
                word(S::from_f64(ay.to_f64() + bx.to_f64()))
            })
            .collect();
        let mut input = vec![9, scalar_kind::<S>(), 2, n as u64];
        input.extend(ys.iter().map(|&v| word(v)));
        input.push(1);
        input.extend(xs.iter().map(|&v| word(v)));
        input.extend([a.to_bits(), b.to_bits()]);
        let got = hex(&run(&format!("adj_axpby{}", kind::<S>()), &input));
        assert_eq!(got, want, "{}: a {a}, b {b}", std::any::type_name::<S>());
    }
}

/// Slice 5's adjoint kernels give the CPU backend's bits: the assembly's adjoint (host and
/// device counts, scalar and block values), mv's and mv_transpose's (the outer product for
/// square and rectangular, column- and row-major blocks, and the scaling of y's gradient),
/// and `y = a y + b x`.
#[test]
fn adjoints_match_the_cpu_bit_for_bit() {
    if skip("adjoints_match_the_cpu_bit_for_bit") {
        return;
    }
    use warp_lang::{DMat32, Mat23};
    for count in [None, Some(57)] {
        adjoint_tpl_case::<f32>(count, 1);
        adjoint_tpl_case::<f64>(count, 2);
        adjoint_tpl_case::<Mat3>(count, 3);
        adjoint_tpl_case::<DMat2>(count, 4);
    }
    for transposed in [false, true] {
        adjoint_mv_case::<f32>(5, transposed);
        adjoint_mv_case::<f64>(6, transposed);
        adjoint_mv_case::<Mat3>(7, transposed);
        adjoint_mv_case::<DMat4>(8, transposed);
        adjoint_mv_case::<Mat23>(9, transposed);
        adjoint_mv_case::<DMat32>(10, transposed);
    }
    adjoint_axpby_case::<f32>(11);
    adjoint_axpby_case::<f64>(12);
}

// wp_tile_mma.h: tile_matmul of half-precision tiles (docs/design/tiles.md section 5,
// "Tensor cores"), the CUDA side of warp-core/src/tile/matmul.rs's f16 case.
//
//   tile_matmul_acc(c, a, b)   c: tile_t<f32, M, N> += a: tile_t<f16, M, K> . b: tile_t<f16, K, N>
//   tile_matmul(c, a, b)       c: tile_t<f16, M, N>  = a . b, accumulated in f32, rounded once
//
// Two paths, chosen at compile time by mma_plan:
//   * tensor cores (sm_80 and up): `mma.sync.aligned.m16n8k16.row.col.f32.f16.f16.f32`, its
//     operands loaded from the shared-memory slots with `ldmatrix` (A row-major as it is; B
//     row-major through `ldmatrix.trans`, which gives the column-major fragment the `.col`
//     operand wants; operands whose rows would make ldmatrix conflict 4 ways or more are first
//     copied to padded rows in static shared memory). Each warp owns warp tiles of FM x FN mma
//     tiles (16 x 8 outputs each),
//     handed out round-robin; per k-step of 16 it loads FM A fragments and FN B fragments and
//     issues FM * FN mmas, the accumulators in registers, loaded from and stored to `c` once
//     per call. The hardware sums each k-step's 16 products (exact: an f16 x f16 product fits
//     in f32) onto the accumulator in an order and with alignment roundings it does not
//     specify, so results agree with the CPU's FMA chains only to a tolerance (the tiles
//     chapter states it: about K * 2^-23 * sum |a||b| per output);
//   * FMA (any other shape, block size, architecture, or slots not 16-byte aligned): each
//     output one chain acc = fmaf(f32(a[i][k]), f32(b[k][j]), acc) over k ascending, from
//     c[i][j] or +0: bit for bit warp-core's f16 matmul.
//
// The planner takes the tensor cores when M % 16 == 0, N % 8 == 0, K % 16 == 0 and the block
// is whole warps (WP_TILE_BLOCK_DIM % 32 == 0); the architecture is checked with
// __CUDA_ARCH__ (no capability needed: the fallback is always there). f32 and f64 tiles never
// come here: wp_tile.h's FMA matmul, bit-exact with the CPU, is theirs.
#pragma once

#include "wp_tile.h"

namespace wp {
namespace tile_mma_detail {

/// The tensor-core plan of an M x K by K x N product of f16 tiles over BD threads.
template <int M, int K, int N>
struct mma_plan {
  static constexpr int BD = TILE_BLOCK_DIM;
  static constexpr int WARPS = BD / 32;
  /// The shapes and block fit m16n8k16 on whole warps.
  static constexpr bool FITS = M % 16 == 0 && N % 8 == 0 && K % 16 == 0 && BD % 32 == 0;
  /// mma tiles along M and N.
  static constexpr int MT = M / 16;
  static constexpr int NT = N / 8;
  /// A warp tile of FM x FN mma tiles (FM * FN * 4 f32 accumulators a thread, at most 64):
  /// the largest that divides the mma grid and still gives every warp one; else the largest
  /// that divides it (fewer warp tiles than warps: some warps idle); else 1 x 1.
#if defined(__CUDACC__)
  __host__ __device__
#endif
  static constexpr int pick(int which) {
    constexpr int cand[9][2] = {{4, 4}, {2, 8}, {4, 2}, {2, 4}, {2, 2},
                                {1, 4}, {2, 1}, {1, 2}, {1, 1}};
    if (!FITS) return 1;
    for (int pass = 0; pass < 2; ++pass)
      for (int c = 0; c < 9; ++c) {
        const int fm = cand[c][0], fn = cand[c][1];
        if (MT % fm == 0 && NT % fn == 0 && (pass == 1 || (MT / fm) * (NT / fn) >= WARPS))
          return cand[c][which];
      }
    return 1;
  }
  static constexpr int FM = pick(0);
  static constexpr int FN = pick(1);
  /// Warp tiles along N, and in all.
  static constexpr int WTN = FITS ? NT / FN : 1;
  static constexpr int WT = FITS ? (MT / FM) * WTN : 1;
};

/// How matmul_mma reads an R x C f16 operand (row-major, C a multiple of 8): from its slot, or
/// from a padded copy in static shared memory. ldmatrix reads 8 rows of 16 bytes per matrix in
/// one pass; rows S = C / 8 16-byte units apart fall on gcd(S, 8) times the same banks (S = 8,
/// a 64-wide f16 row, is an 8-way conflict). A copy whose rows are S + 1 units apart (S + 1
/// odd) is conflict-free; it costs one pass over the operand, so it is made for conflicts of 4
/// ways or more, and while the copies of both operands fit STAGE_BUDGET (static shared memory
/// has a 48 KiB limit; the copies are per matmul instantiation).
template <int R, int C>
struct stage_plan {
  static constexpr int S = C / 8;
  static constexpr int WAYS = S % 8 == 0 ? 8 : S % 4 == 0 ? 4 : S % 2 == 0 ? 2 : 1;
  static constexpr bool WANT = WAYS >= 4;
  static constexpr int BYTES = R * (C + 8) * 2;
};
constexpr int STAGE_BUDGET = 40 * 1024;

/// The staging decisions of an M x K by K x N product: A's copy first, then B's if it fits too.
template <int M, int K, int N>
struct stage_both {
  typedef stage_plan<M, K> SA;
  typedef stage_plan<K, N> SB;
  static constexpr bool A = SA::WANT && SA::BYTES <= STAGE_BUDGET;
  static constexpr bool B = SB::WANT && (A ? SA::BYTES : 0) + SB::BYTES <= STAGE_BUDGET;
  /// Row pitches (halves) of the operands as read.
  static constexpr int PA = A ? K + 8 : K;
  static constexpr int PB = B ? N + 8 : N;
  /// Static shared bytes of the copies (at least 16: no zero-sized arrays).
  static constexpr int BYTES_A = A ? SA::BYTES : 16;
  static constexpr int BYTES_B = B ? SB::BYTES : 16;
};

/// Copies an R x C f16 operand (16-byte aligned, C a multiple of 8) to rows `P` halves apart,
/// 16 bytes at a time, block-strided; the caller synchronises.
template <int R, int C, int P>
WP_FN void stage_copy(f16* dst, const f16* src) {
  constexpr int S = C / 8;
  for (int e = (int)threadIdx.x; e < R * S; e += WP_TILE_BLOCK_DIM) {
    const int r = e / S, u = e % S;
    *reinterpret_cast<tile_detail::raw16*>(dst + r * P + u * 8) =
        *reinterpret_cast<const tile_detail::raw16*>(src + r * C + u * 8);
  }
}

/// The FMA path: each output one f32 chain over k ascending (warp-core's order), written as
/// f32 (`Acc`: starting from c) or rounded once to f16 (starting from +0).
template <bool Acc, typename C, int M, int K, int N>
WP_FN void matmul_fma(C* c, const f16* a, const f16* b) {
  for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, j = e % N;
    f32 acc = 0.0f;
    if constexpr (Acc) acc = (f32)c[e];
    for (int k = 0; k < K; ++k)
      acc = ::fmaf(f16_to_f32(a[i * K + k]), f16_to_f32(b[k * N + j]), acc);
    if constexpr (Acc) c[e] = acc;
    else c[e] = f16_from_f32(acc);
  }
}

#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
#define WP_TILE_MMA 1

/// A shared-memory address for ldmatrix.
WP_FN unsigned smem_addr(const void* p) { return (unsigned)__cvta_generic_to_shared(p); }

/// Four 8 x 8 b16 matrices: lane l names row l % 8 of matrix l / 8; register r of every lane
/// receives matrix r's elements (row lane / 4, columns 2 (lane % 4) + {0, 1}).
WP_FN void ldmatrix_x4(unsigned* r, const void* p) {
  asm volatile("ldmatrix.sync.aligned.m8n8.x4.shared.b16 {%0, %1, %2, %3}, [%4];\n"
               : "=r"(r[0]), "=r"(r[1]), "=r"(r[2]), "=r"(r[3])
               : "r"(smem_addr(p)));
}
/// The same, transposed: register r receives matrix r's (row 2 (lane % 4) + {0, 1}, column
/// lane / 4).
WP_FN void ldmatrix_x4_trans(unsigned* r, const void* p) {
  asm volatile("ldmatrix.sync.aligned.m8n8.x4.trans.shared.b16 {%0, %1, %2, %3}, [%4];\n"
               : "=r"(r[0]), "=r"(r[1]), "=r"(r[2]), "=r"(r[3])
               : "r"(smem_addr(p)));
}
/// Two matrices, transposed (lanes 0..15 name their rows).
WP_FN void ldmatrix_x2_trans(unsigned* r, const void* p) {
  asm volatile("ldmatrix.sync.aligned.m8n8.x2.trans.shared.b16 {%0, %1}, [%2];\n"
               : "=r"(r[0]), "=r"(r[1])
               : "r"(smem_addr(p)));
}

/// d = a . b + d for one 16 x 8 x 16 step. Fragments (PTX ISA, "Matrix Fragments for
/// mma.m16n8k16 with floating point type"), g = lane / 4, t = lane % 4:
///   a[0]: A[g][2t..2t+1]   a[1]: A[g+8][2t..]   a[2]: A[g][2t+8..]   a[3]: A[g+8][2t+8..]
///   b[0]: B[2t..2t+1][g]   b[1]: B[2t+8..2t+9][g]
///   d[0], d[1]: D[g][2t], D[g][2t+1]   d[2], d[3]: D[g+8][2t], D[g+8][2t+1]
WP_FN void mma_16816(f32* d, const unsigned* a, const unsigned* b) {
  asm volatile(
      "mma.sync.aligned.m16n8k16.row.col.f32.f16.f16.f32 {%0, %1, %2, %3}, {%4, %5, %6, %7}, "
      "{%8, %9}, {%0, %1, %2, %3};\n"
      : "+f"(d[0]), "+f"(d[1]), "+f"(d[2]), "+f"(d[3])
      : "r"(a[0]), "r"(a[1]), "r"(a[2]), "r"(a[3]), "r"(b[0]), "r"(b[1]));
}

/// The tensor-core path of mma_plan (slots 16-byte aligned: every ldmatrix row address is,
/// since K and N, and the copies' pitches, are multiples of 8 halves). Operands whose rows
/// would make ldmatrix conflict 4 ways or more are read from padded copies (stage_both).
template <bool Acc, typename C, int M, int K, int N>
WP_FN void matmul_mma(C* c, const f16* a_slot, const f16* b_slot) {
  typedef mma_plan<M, K, N> P;
  typedef stage_both<M, K, N> ST;
  constexpr int FM = P::FM, FN = P::FN, PA = ST::PA, PB = ST::PB;
  const f16* a = a_slot;
  const f16* b = b_slot;
  if constexpr (ST::A || ST::B) {
    WP_TILE_SHARED_ALIGNED unsigned char stage_a[ST::BYTES_A];
    WP_TILE_SHARED_ALIGNED unsigned char stage_b[ST::BYTES_B];
    if constexpr (ST::A) {
      stage_copy<M, K, PA>(reinterpret_cast<f16*>(stage_a), a_slot);
      a = reinterpret_cast<const f16*>(stage_a);
    }
    if constexpr (ST::B) {
      stage_copy<K, N, PB>(reinterpret_cast<f16*>(stage_b), b_slot);
      b = reinterpret_cast<const f16*>(stage_b);
    }
    __syncthreads();
  }
  const int lane = (int)threadIdx.x & 31;
  const int warp = (int)threadIdx.x >> 5;
  const int g = lane >> 2, t = lane & 3;
  for (int wt = warp; wt < P::WT; wt += P::WARPS) {
    const int m0 = (wt / P::WTN) * FM * 16;
    const int n0 = (wt % P::WTN) * FN * 8;
    f32 acc[FM][FN][4];
WP_TILE_UNROLL
    for (int fm = 0; fm < FM; ++fm)
WP_TILE_UNROLL
      for (int fn = 0; fn < FN; ++fn)
WP_TILE_UNROLL
        for (int h = 0; h < 2; ++h) {
          const int row = m0 + fm * 16 + g + 8 * h, col = n0 + fn * 8 + 2 * t;
          if constexpr (Acc) {
            const float2 v = *reinterpret_cast<const float2*>(&c[row * N + col]);
            acc[fm][fn][2 * h] = v.x;
            acc[fm][fn][2 * h + 1] = v.y;
          } else {
            acc[fm][fn][2 * h] = 0.0f;
            acc[fm][fn][2 * h + 1] = 0.0f;
          }
        }
WP_TILE_UNROLL_N(4)
    for (int k0 = 0; k0 < K; k0 += 16) {
      unsigned af[FM][4];
      unsigned bf[FN][2];
      // A: lane l names row (l % 8) + 8 ((l / 8) % 2), columns k0 + 8 (l / 16): matrices
      // (rows 0-7, k 0-7), (rows 8-15, k 0-7), (rows 0-7, k 8-15), (rows 8-15, k 8-15), which
      // are a[0..3] in order.
WP_TILE_UNROLL
      for (int fm = 0; fm < FM; ++fm) {
        const int row = m0 + fm * 16 + (lane & 7) + 8 * ((lane >> 3) & 1);
        ldmatrix_x4(af[fm], a + row * PA + k0 + 8 * (lane >> 4));
      }
      // B (K x N row-major): lane l names row k0 + (l % 16) at column n + 8 (l / 16); the
      // transposed matrices (k 0-7, k 8-15) of columns n..n+7 are b[0], b[1] of that mma tile,
      // those of n+8..n+15 the next one's.
WP_TILE_UNROLL
      for (int fn = 0; fn + 1 < FN; fn += 2) {
        unsigned r[4];
        ldmatrix_x4_trans(r, b + (k0 + (lane & 15)) * PB + n0 + fn * 8 + 8 * (lane >> 4));
        bf[fn][0] = r[0], bf[fn][1] = r[1], bf[fn + 1][0] = r[2], bf[fn + 1][1] = r[3];
      }
      if constexpr (FN % 2 == 1) {
        ldmatrix_x2_trans(bf[FN - 1], b + (k0 + (lane & 15)) * PB + n0 + (FN - 1) * 8);
      }
WP_TILE_UNROLL
      for (int fm = 0; fm < FM; ++fm)
WP_TILE_UNROLL
        for (int fn = 0; fn < FN; ++fn) mma_16816(acc[fm][fn], af[fm], bf[fn]);
    }
WP_TILE_UNROLL
    for (int fm = 0; fm < FM; ++fm)
WP_TILE_UNROLL
      for (int fn = 0; fn < FN; ++fn)
WP_TILE_UNROLL
        for (int h = 0; h < 2; ++h) {
          const int row = m0 + fm * 16 + g + 8 * h, col = n0 + fn * 8 + 2 * t;
          if constexpr (Acc) {
            *reinterpret_cast<float2*>(&c[row * N + col]) =
                make_float2(acc[fm][fn][2 * h], acc[fm][fn][2 * h + 1]);
          } else {
            c[row * N + col] = f16_from_f32(acc[fm][fn][2 * h]);
            c[row * N + col + 1] = f16_from_f32(acc[fm][fn][2 * h + 1]);
          }
        }
  }
}
#endif  // __CUDA_ARCH__ >= 800

template <bool Acc, typename C, int M, int K, int N>
WP_FN void matmul(C* c, const f16* a, const f16* b) {
#if defined(WP_TILE_MMA)
  if constexpr (mma_plan<M, K, N>::FITS) {
    // The emitter's slots are 16-byte aligned (tile_slot_end); a tile over another pointer
    // takes the FMA path. One uniform test per call.
    if (tile_detail::aligned16(a) && tile_detail::aligned16(b) && tile_detail::aligned16(c)) {
      matmul_mma<Acc, C, M, K, N>(c, a, b);
      __syncthreads();
      return;
    }
  }
#endif
  matmul_fma<Acc, C, M, K, N>(c, a, b);
  __syncthreads();
}

}  // namespace tile_mma_detail

/// `c += a . b` of f16 tiles into an f32 accumulator (Warp's `tile_matmul(a, b, out)`).
/// `c` is a slot of its own (neither `a` nor `b`).
template <int M, int K, int N>
WP_FN void tile_matmul_acc(const tile_t<f32, M, N>& c, const tile_t<f16, M, K>& a,
                           const tile_t<f16, K, N>& b) {
  tile_mma_detail::matmul<true, f32, M, K, N>(c.data, a.data, b.data);
}

/// `c = a . b` of f16 tiles: accumulated in f32 from +0, each output rounded to f16 once.
template <int M, int K, int N>
WP_FN void tile_matmul(const tile_t<f16, M, N>& c, const tile_t<f16, M, K>& a,
                       const tile_t<f16, K, N>& b) {
  tile_mma_detail::matmul<false, f16, M, K, N>(c.data, a.data, b.data);
}

}  // namespace wp

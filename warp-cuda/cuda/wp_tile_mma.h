// wp_tile_mma.h: tile_matmul of 16-bit float tiles, f16 and bf16 (docs/design/tiles.md
// section 5, "Tensor cores"), the CUDA side of warp-core/src/tile/matmul.rs's f16 and bf16
// cases. `E` below is f16 or bf16:
//
//   tile_matmul_acc(c, a, b)   c: tile_t<f32, M, N> += a: tile_t<E, M, K> . b: tile_t<E, K, N>
//   tile_matmul(c, a, b)       c: tile_t<E, M, N>  = a . b, accumulated in f32, rounded once
//
// Two paths, chosen at compile time by mma_plan:
//   * tensor cores (sm_80 and up): `mma.sync.aligned.m16n8k16.row.col.f32.E.E.f32` (bf16
//     fragments have f16's layout, so the loads are the same), its
//     operands loaded from the shared-memory slots with `ldmatrix` (A row-major as it is; B
//     row-major through `ldmatrix.trans`, which gives the column-major fragment the `.col`
//     operand wants; operands whose rows would make ldmatrix conflict 4 ways or more are first
//     copied to padded rows in static shared memory). Each warp owns warp tiles of FM x FN mma
//     tiles (16 x 8 outputs each),
//     handed out round-robin; per k-step of 16 it loads FM A fragments and FN B fragments and
//     issues FM * FN mmas, the accumulators in registers, loaded from and stored to `c` once
//     per call. The hardware sums each k-step's 16 products (exact: an f16 x f16 or a
//     bf16 x bf16 product fits in f32) onto the accumulator in an order and with alignment roundings it does not
//     specify, so results agree with the CPU's FMA chains only to a tolerance (the tiles
//     chapter states it: about K * 2^-23 * sum |a||b| per output);
//   * FMA (any other shape, block size, architecture, or slots not 16-byte aligned): each
//     output one chain acc = fmaf(f32(a[i][k]), f32(b[k][j]), acc) over k ascending, from
//     c[i][j] or +0: bit for bit warp-core's f16 and bf16 matmuls.
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
template <int R, int C, int P, typename E>
WP_FN void stage_copy(E* dst, const E* src) {
  constexpr int S = C / 8;
  for (int e = (int)threadIdx.x; e < R * S; e += WP_TILE_BLOCK_DIM) {
    const int r = e / S, u = e % S;
    *reinterpret_cast<tile_detail::raw16*>(dst + r * P + u * 8) =
        *reinterpret_cast<const tile_detail::raw16*>(src + r * C + u * 8);
  }
}

/// The FMA path: each output one f32 chain over k ascending (warp-core's order), written as
/// f32 (`Acc`: starting from c) or rounded once to `E` (starting from +0). The explicit
/// conversions are f16_to_f32/f16_from_f32 (bf16_to_f32/bf16_from_f32).
template <bool Acc, typename C, int M, int K, int N, typename E>
WP_FN void matmul_fma(C* c, const E* a, const E* b) {
  for (int e = (int)threadIdx.x; e < M * N; e += WP_TILE_BLOCK_DIM) {
    const int i = e / N, j = e % N;
    f32 acc = 0.0f;
    if constexpr (Acc) acc = (f32)c[e];
    for (int k = 0; k < K; ++k)
      acc = ::fmaf(static_cast<f32>(a[i * K + k]), static_cast<f32>(b[k * N + j]), acc);
    if constexpr (Acc) c[e] = acc;
    else c[e] = static_cast<C>(acc);
  }
}

#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
#define WP_TILE_MMA 1

/// A shared-memory address for ldmatrix.
WP_LFN unsigned smem_addr(const void* p) { return (unsigned)__cvta_generic_to_shared(p); }

/// Four 8 x 8 b16 matrices: lane l names row l % 8 of matrix l / 8; register r of every lane
/// receives matrix r's elements (row lane / 4, columns 2 (lane % 4) + {0, 1}).
WP_LFN void ldmatrix_x4(unsigned* r, const void* p) {
  asm volatile("ldmatrix.sync.aligned.m8n8.x4.shared.b16 {%0, %1, %2, %3}, [%4];\n"
               : "=r"(r[0]), "=r"(r[1]), "=r"(r[2]), "=r"(r[3])
               : "r"(smem_addr(p)));
}
/// The same, transposed: register r receives matrix r's (row 2 (lane % 4) + {0, 1}, column
/// lane / 4).
WP_LFN void ldmatrix_x4_trans(unsigned* r, const void* p) {
  asm volatile("ldmatrix.sync.aligned.m8n8.x4.trans.shared.b16 {%0, %1, %2, %3}, [%4];\n"
               : "=r"(r[0]), "=r"(r[1]), "=r"(r[2]), "=r"(r[3])
               : "r"(smem_addr(p)));
}
/// Two matrices, transposed (lanes 0..15 name their rows).
WP_LFN void ldmatrix_x2_trans(unsigned* r, const void* p) {
  asm volatile("ldmatrix.sync.aligned.m8n8.x2.trans.shared.b16 {%0, %1}, [%2];\n"
               : "=r"(r[0]), "=r"(r[1])
               : "r"(smem_addr(p)));
}

/// d = a . b + d for one 16 x 8 x 16 step. Fragments (PTX ISA, "Matrix Fragments for
/// mma.m16n8k16 with floating point type"), g = lane / 4, t = lane % 4:
///   a[0]: A[g][2t..2t+1]   a[1]: A[g+8][2t..]   a[2]: A[g][2t+8..]   a[3]: A[g+8][2t+8..]
///   b[0]: B[2t..2t+1][g]   b[1]: B[2t+8..2t+9][g]
///   d[0], d[1]: D[g][2t], D[g][2t+1]   d[2], d[3]: D[g+8][2t], D[g+8][2t+1]
/// `E`: the operands' type, f16 or bf16 (the same fragments; only the instruction differs).
template <typename E = f16>
WP_FN void mma_16816(f32* d, const unsigned* a, const unsigned* b) {
  if constexpr (detail::same_type<E, bf16>::value) {
    asm volatile(
        "mma.sync.aligned.m16n8k16.row.col.f32.bf16.bf16.f32 {%0, %1, %2, %3}, {%4, %5, %6, %7}, "
        "{%8, %9}, {%0, %1, %2, %3};\n"
        : "+f"(d[0]), "+f"(d[1]), "+f"(d[2]), "+f"(d[3])
        : "r"(a[0]), "r"(a[1]), "r"(a[2]), "r"(a[3]), "r"(b[0]), "r"(b[1]));
  } else {
    asm volatile(
        "mma.sync.aligned.m16n8k16.row.col.f32.f16.f16.f32 {%0, %1, %2, %3}, {%4, %5, %6, %7}, "
        "{%8, %9}, {%0, %1, %2, %3};\n"
        : "+f"(d[0]), "+f"(d[1]), "+f"(d[2]), "+f"(d[3])
        : "r"(a[0]), "r"(a[1]), "r"(a[2]), "r"(a[3]), "r"(b[0]), "r"(b[1]));
  }
}

/// The tensor-core path of mma_plan (slots 16-byte aligned: every ldmatrix row address is,
/// since K and N, and the copies' pitches, are multiples of 8 halves). Operands whose rows
/// would make ldmatrix conflict 4 ways or more are read from padded copies (stage_both).
template <bool Acc, typename C, int M, int K, int N, bool Stage, typename E>
WP_FN void matmul_mma(C* c, const E* a_slot, const E* b_slot) {
  typedef mma_plan<M, K, N> P;
  typedef stage_both<M, K, N> ST;
  // `Stage`: padded copies allowed (their static shared memory is reserved by every block of
  // the kernel, whether or not this call runs).
  constexpr bool SA = Stage && ST::A, SB = Stage && ST::B;
  constexpr int FM = P::FM, FN = P::FN, PA = SA ? ST::PA : K, PB = SB ? ST::PB : N;
  const E* a = a_slot;
  const E* b = b_slot;
  if constexpr (SA || SB) {
    WP_TILE_SHARED_ALIGNED unsigned char stage_a[ST::BYTES_A];
    WP_TILE_SHARED_ALIGNED unsigned char stage_b[ST::BYTES_B];
    if constexpr (SA) {
      stage_copy<M, K, PA>(reinterpret_cast<E*>(stage_a), a_slot);
      a = reinterpret_cast<const E*>(stage_a);
    }
    if constexpr (SB) {
      stage_copy<K, N, PB>(reinterpret_cast<E*>(stage_b), b_slot);
      b = reinterpret_cast<const E*>(stage_b);
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
        for (int fn = 0; fn < FN; ++fn) mma_16816<E>(acc[fm][fn], af[fm], bf[fn]);
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
            c[row * N + col] = static_cast<C>(acc[fm][fn][2 * h]);
            c[row * N + col + 1] = static_cast<C>(acc[fm][fn][2 * h + 1]);
          }
        }
  }
}
#endif  // __CUDA_ARCH__ >= 800


#if defined(WP_TILE_MMA) && defined(__CUDA_ARCH_FEAT_SM90_ALL)
// Hopper's warpgroup MMA (sm_90a: the runtime compiles for it on compute capability 9.0).
#define WP_TILE_WGMMA 1

/// A shared-memory matrix descriptor (PTX ISA, "Matrix Descriptor Format"): the start address,
/// the leading and stride byte offsets (16-byte units), and the swizzle mode (1: 128-byte,
/// 2: 64-byte, 3: 32-byte). The swizzle patterns repeat every 8 rows, so stage buffers are
/// 1024-byte aligned and the base-offset field stays 0.
WP_LFN unsigned long long wg_desc(const void* p, int lbo, int sbo, int mode) {
  unsigned long long d = (unsigned long long)((smem_addr(p) & 0x3FFFF) >> 4);
  d |= (unsigned long long)((lbo >> 4) & 0x3FFF) << 16;
  d |= (unsigned long long)((sbo >> 4) & 0x3FFF) << 32;
  d |= (unsigned long long)mode << 62;
  return d;
}

/// d (m64 x n64, f32) += A . B for one k-step of 16 (`wgmma` m64n64k16, f16 inputs; A from
/// its K-major descriptor, B from its MN-major one; every warp of the warpgroup issues it).
WP_LFN void wgmma_n64(f32* d, unsigned long long da, unsigned long long db) {
  asm volatile(
      "{\n.reg .pred p;\nsetp.ne.b32 p, 1, 0;\n"
      "wgmma.mma_async.sync.aligned.m64n64k16.f32.f16.f16 {%0, %1, %2, %3, %4, %5, %6, %7, %8, %9, %10, %11, %12, %13, %14, %15, %16, %17, %18, %19, %20, %21, %22, %23, %24, %25, %26, %27, %28, %29, %30, %31}, %32, %33, p, 1, 1, 0, 1;\n}\n"
      : "+f"(d[0]), "+f"(d[1]), "+f"(d[2]), "+f"(d[3]), "+f"(d[4]), "+f"(d[5]), "+f"(d[6]), "+f"(d[7]),
        "+f"(d[8]), "+f"(d[9]), "+f"(d[10]), "+f"(d[11]), "+f"(d[12]), "+f"(d[13]), "+f"(d[14]), "+f"(d[15]),
        "+f"(d[16]), "+f"(d[17]), "+f"(d[18]), "+f"(d[19]), "+f"(d[20]), "+f"(d[21]), "+f"(d[22]), "+f"(d[23]),
        "+f"(d[24]), "+f"(d[25]), "+f"(d[26]), "+f"(d[27]), "+f"(d[28]), "+f"(d[29]), "+f"(d[30]), "+f"(d[31])
      : "l"(da), "l"(db));
}

/// d (m64 x n128, f32) += A . B for one k-step of 16 (`wgmma` m64n128k16, f16 inputs; A from
/// its K-major descriptor, B from its MN-major one; every warp of the warpgroup issues it).
WP_LFN void wgmma_n128(f32* d, unsigned long long da, unsigned long long db) {
  asm volatile(
      "{\n.reg .pred p;\nsetp.ne.b32 p, 1, 0;\n"
      "wgmma.mma_async.sync.aligned.m64n128k16.f32.f16.f16 {%0, %1, %2, %3, %4, %5, %6, %7, %8, %9, %10, %11, %12, %13, %14, %15, %16, %17, %18, %19, %20, %21, %22, %23, %24, %25, %26, %27, %28, %29, %30, %31, %32, %33, %34, %35, %36, %37, %38, %39, %40, %41, %42, %43, %44, %45, %46, %47, %48, %49, %50, %51, %52, %53, %54, %55, %56, %57, %58, %59, %60, %61, %62, %63}, %64, %65, p, 1, 1, 0, 1;\n}\n"
      : "+f"(d[0]), "+f"(d[1]), "+f"(d[2]), "+f"(d[3]), "+f"(d[4]), "+f"(d[5]), "+f"(d[6]), "+f"(d[7]),
        "+f"(d[8]), "+f"(d[9]), "+f"(d[10]), "+f"(d[11]), "+f"(d[12]), "+f"(d[13]), "+f"(d[14]), "+f"(d[15]),
        "+f"(d[16]), "+f"(d[17]), "+f"(d[18]), "+f"(d[19]), "+f"(d[20]), "+f"(d[21]), "+f"(d[22]), "+f"(d[23]),
        "+f"(d[24]), "+f"(d[25]), "+f"(d[26]), "+f"(d[27]), "+f"(d[28]), "+f"(d[29]), "+f"(d[30]), "+f"(d[31]),
        "+f"(d[32]), "+f"(d[33]), "+f"(d[34]), "+f"(d[35]), "+f"(d[36]), "+f"(d[37]), "+f"(d[38]), "+f"(d[39]),
        "+f"(d[40]), "+f"(d[41]), "+f"(d[42]), "+f"(d[43]), "+f"(d[44]), "+f"(d[45]), "+f"(d[46]), "+f"(d[47]),
        "+f"(d[48]), "+f"(d[49]), "+f"(d[50]), "+f"(d[51]), "+f"(d[52]), "+f"(d[53]), "+f"(d[54]), "+f"(d[55]),
        "+f"(d[56]), "+f"(d[57]), "+f"(d[58]), "+f"(d[59]), "+f"(d[60]), "+f"(d[61]), "+f"(d[62]), "+f"(d[63])
      : "l"(da), "l"(db));
}

/// d (m64 x n256, f32) += A . B for one k-step of 16 (`wgmma` m64n256k16, f16 inputs; A from
/// its K-major descriptor, B from its MN-major one; every warp of the warpgroup issues it).
WP_LFN void wgmma_n256(f32* d, unsigned long long da, unsigned long long db) {
  asm volatile(
      "{\n.reg .pred p;\nsetp.ne.b32 p, 1, 0;\n"
      "wgmma.mma_async.sync.aligned.m64n256k16.f32.f16.f16 {%0, %1, %2, %3, %4, %5, %6, %7, %8, %9, %10, %11, %12, %13, %14, %15, %16, %17, %18, %19, %20, %21, %22, %23, %24, %25, %26, %27, %28, %29, %30, %31, %32, %33, %34, %35, %36, %37, %38, %39, %40, %41, %42, %43, %44, %45, %46, %47, %48, %49, %50, %51, %52, %53, %54, %55, %56, %57, %58, %59, %60, %61, %62, %63, %64, %65, %66, %67, %68, %69, %70, %71, %72, %73, %74, %75, %76, %77, %78, %79, %80, %81, %82, %83, %84, %85, %86, %87, %88, %89, %90, %91, %92, %93, %94, %95, %96, %97, %98, %99, %100, %101, %102, %103, %104, %105, %106, %107, %108, %109, %110, %111, %112, %113, %114, %115, %116, %117, %118, %119, %120, %121, %122, %123, %124, %125, %126, %127}, %128, %129, p, 1, 1, 0, 1;\n}\n"
      : "+f"(d[0]), "+f"(d[1]), "+f"(d[2]), "+f"(d[3]), "+f"(d[4]), "+f"(d[5]), "+f"(d[6]), "+f"(d[7]),
        "+f"(d[8]), "+f"(d[9]), "+f"(d[10]), "+f"(d[11]), "+f"(d[12]), "+f"(d[13]), "+f"(d[14]), "+f"(d[15]),
        "+f"(d[16]), "+f"(d[17]), "+f"(d[18]), "+f"(d[19]), "+f"(d[20]), "+f"(d[21]), "+f"(d[22]), "+f"(d[23]),
        "+f"(d[24]), "+f"(d[25]), "+f"(d[26]), "+f"(d[27]), "+f"(d[28]), "+f"(d[29]), "+f"(d[30]), "+f"(d[31]),
        "+f"(d[32]), "+f"(d[33]), "+f"(d[34]), "+f"(d[35]), "+f"(d[36]), "+f"(d[37]), "+f"(d[38]), "+f"(d[39]),
        "+f"(d[40]), "+f"(d[41]), "+f"(d[42]), "+f"(d[43]), "+f"(d[44]), "+f"(d[45]), "+f"(d[46]), "+f"(d[47]),
        "+f"(d[48]), "+f"(d[49]), "+f"(d[50]), "+f"(d[51]), "+f"(d[52]), "+f"(d[53]), "+f"(d[54]), "+f"(d[55]),
        "+f"(d[56]), "+f"(d[57]), "+f"(d[58]), "+f"(d[59]), "+f"(d[60]), "+f"(d[61]), "+f"(d[62]), "+f"(d[63]),
        "+f"(d[64]), "+f"(d[65]), "+f"(d[66]), "+f"(d[67]), "+f"(d[68]), "+f"(d[69]), "+f"(d[70]), "+f"(d[71]),
        "+f"(d[72]), "+f"(d[73]), "+f"(d[74]), "+f"(d[75]), "+f"(d[76]), "+f"(d[77]), "+f"(d[78]), "+f"(d[79]),
        "+f"(d[80]), "+f"(d[81]), "+f"(d[82]), "+f"(d[83]), "+f"(d[84]), "+f"(d[85]), "+f"(d[86]), "+f"(d[87]),
        "+f"(d[88]), "+f"(d[89]), "+f"(d[90]), "+f"(d[91]), "+f"(d[92]), "+f"(d[93]), "+f"(d[94]), "+f"(d[95]),
        "+f"(d[96]), "+f"(d[97]), "+f"(d[98]), "+f"(d[99]), "+f"(d[100]), "+f"(d[101]), "+f"(d[102]), "+f"(d[103]),
        "+f"(d[104]), "+f"(d[105]), "+f"(d[106]), "+f"(d[107]), "+f"(d[108]), "+f"(d[109]), "+f"(d[110]), "+f"(d[111]),
        "+f"(d[112]), "+f"(d[113]), "+f"(d[114]), "+f"(d[115]), "+f"(d[116]), "+f"(d[117]), "+f"(d[118]), "+f"(d[119]),
        "+f"(d[120]), "+f"(d[121]), "+f"(d[122]), "+f"(d[123]), "+f"(d[124]), "+f"(d[125]), "+f"(d[126]), "+f"(d[127])
      : "l"(da), "l"(db));
}

template <int N>
WP_FN void wgmma_n(f32* d, unsigned long long da, unsigned long long db) {
  if constexpr (N == 64) wgmma_n64(d, da, db);
  else if constexpr (N == 128) wgmma_n128(d, da, db);
  else wgmma_n256(d, da, db);
}
#endif  // WP_TILE_WGMMA

// ------------------------------------------------------------------------------------------
// The pipelined k-loop (tile_gemm_pipe below)
// ------------------------------------------------------------------------------------------

/// The 16-byte unit that logical unit `u` of row `r` occupies in a stage buffer whose rows hold
/// U units. ldmatrix reads one unit from each of 8 consecutive rows (starting at a multiple of
/// 8); an XOR of the unit index with bits of the row spreads those 8 over the 8 distinct
/// 16-byte positions of a 128-byte line, so no read conflicts (rows of 128 bytes or more: the
/// row's low 3 bits; 64-byte rows, two to a line: bits 1-2; 32-byte rows: bit 2). The XOR
/// stays inside the row. cp.async writes and ldmatrix reads use the same map.
template <int U>
WP_FN int swz(int r, int u) {
  if constexpr (U % 8 == 0) return u ^ (r & 7);
  else if constexpr (U == 4) return u ^ ((r >> 1) & 3);
  else if constexpr (U == 2) return u ^ ((r >> 2) & 1);
  else return u;
}
template <int U>
constexpr bool swz_ok = U % 8 == 0 || U == 4 || U == 2 || U == 1;

/// Shared memory the runtime gave the block's pipelined k-loops beyond its tiles' slots, at the
/// end of the block's dynamic shared memory, 1024-byte aligned (0: none). The runtime grants
/// what `TileInfo::pipe_extra_bytes` asks (warp-runtime's `TileInfo::pipe_extra_for`, which
/// counts the stages up to MAX_STAGES below) where it costs the kernel no blocks per SM.
#if defined(WP_TILE_PIPE_EXTRA) && defined(WP_TILE_SMEM_BYTES)
constexpr int PIPE_EXTRA = WP_TILE_PIPE_EXTRA;
#else
constexpr int PIPE_EXTRA = 0;
#endif
/// The most stages a pipelined k-loop uses (warp-runtime's `TileInfo::PIPE_MAX_STAGES`, which
/// must agree).
constexpr int MAX_STAGES = 4;

/// The plan of the pipelined k-loop of an M x K by K x N f16 product.
///
/// Stages: a stage holds one iteration's A and B tiles (SA + SB bytes). The stages live in
/// slots the kernel already has, which the loop leaves unused: the accumulator's slot (its
/// value is in registers for the whole loop, written back after it) holds R0 stages, and the
/// A and B tiles' own slots one more; then XS more in the extra shared memory the runtime gave
/// (PIPE_EXTRA). Two to four stages: loads run up to STAGES - 1 iterations ahead of the tensor
/// cores. (Measured on an H200 at 4096^3 with 128 x 256 x 64 tiles, 256 threads: 0.44 ms with
/// three stages, 0.34 ms with four.)
///
/// Warp tiles: the accumulators stay in registers across the loop, so a warp tile can be
/// larger than the unpipelined matmul's (which reloads its accumulators every call): the
/// first of 64 x 64, 64 x 32, .. that gives every warp one (wider tiles load fewer fragments
/// per mma), at most 128 accumulators a thread. Which warp computes an output does not change
/// its arithmetic (the same mma k-steps in the same order), so any tiling gives the same bits.
template <int M, int K, int N>
struct pipe_plan {
  typedef mma_plan<M, K, N> P;
  // At least one: below 32 threads the plan is off (P::FITS), but its arithmetic still
  // instantiates (a division by zero would be a compile error, not an off plan).
  static constexpr int WARPS = P::WARPS > 0 ? P::WARPS : 1;
  static constexpr int UA = K / 8, UB = N / 8;
  static constexpr int SA = M * K * 2, SB = K * N * 2;
  static constexpr int R0 = (M * N * 4) / (SA + SB);
  static constexpr int XS = PIPE_EXTRA / (SA + SB);
  static constexpr int STAGES = R0 + 1 + XS > MAX_STAGES ? MAX_STAGES : R0 + 1 + XS;
#if defined(__CUDACC__)
  __host__ __device__
#endif
  static constexpr int pick(int which) {
    constexpr int cand[10][2] = {{4, 8}, {4, 4}, {2, 8}, {4, 2}, {2, 4},
                                 {2, 2}, {1, 4}, {2, 1}, {1, 2}, {1, 1}};
    if (!P::FITS) return 1;
    for (int pass = 0; pass < 2; ++pass)
      for (int c = 0; c < 10; ++c) {
        const int fm = cand[c][0], fn = cand[c][1];
        const int wt = (P::MT % fm == 0 && P::NT % fn == 0) ? (P::MT / fm) * (P::NT / fn) : 0;
        const int nw = (wt + WARPS - 1) / WARPS;
        if (wt > 0 && nw * fm * fn * 4 <= 128 && (pass == 1 || wt >= WARPS))
          return cand[c][which];
      }
    return 1;
  }
  static constexpr int FM = pick(0);
  static constexpr int FN = pick(1);
  static constexpr int WTN = P::FITS ? P::NT / FN : 1;
  static constexpr int WT = P::FITS ? (P::MT / FM) * WTN : 1;
  /// Warp tiles a warp owns.
  static constexpr int NW = (WT + WARPS - 1) / WARPS;
  static constexpr bool FITS = P::FITS && swz_ok<UA> && swz_ok<UB> && STAGES >= 2 &&
                               NW * FM * FN * 4 <= 128;
};

/// The warpgroup-MMA plan of the pipelined k-loop (sm_90a): each warpgroup (4 warps) owns MH
/// row blocks of 64 x N, one `wgmma` m64nNk16 per row block and k-step, A read K-major from
/// the stage (its rows are the 32-, 64- or 128-byte swizzle span: K = 16, 32 or 64) and B
/// MN-major (in 64-column atoms). At most 128 accumulators a thread.
template <int M, int K, int N>
struct wg_plan {
  static constexpr int WG = WP_TILE_BLOCK_DIM / 128;
  static constexpr int MH = (WG >= 1 && M % (64 * (WG > 0 ? WG : 1)) == 0) ? M / (64 * (WG > 0 ? WG : 1)) : 0;
  /// A's swizzle (the descriptor's mode): rows of 128, 64 or 32 bytes.
  static constexpr int AMODE = K == 64 ? 1 : K == 32 ? 2 : K == 16 ? 3 : 0;
  static constexpr bool FITS = WP_TILE_BLOCK_DIM % 128 == 0 && MH >= 1 && AMODE != 0 &&
                               (N == 64 || N == 128 || N == 256) && MH * (N / 2) <= 128;
};

/// cp.async of 16 bytes, global to shared, bypassing L1 (the stages are read once from shared
/// memory). No-ops below sm_80, where the pipeline is never switched on.
WP_LFN void cp_async16(void* dst, const void* src) {
#if defined(WP_TILE_MMA)
  asm volatile("cp.async.cg.shared.global [%0], [%1], 16;\n" ::"r"(smem_addr(dst)), "l"(src));
#else
  *reinterpret_cast<tile_detail::raw16*>(dst) = *reinterpret_cast<const tile_detail::raw16*>(src);
#endif
}
WP_LFN void cp_async_commit() {
#if defined(WP_TILE_MMA)
  asm volatile("cp.async.commit_group;\n" ::);
#endif
}
template <int PENDING>
WP_FN void cp_async_wait() {
#if defined(WP_TILE_MMA)
  asm volatile("cp.async.wait_group %0;\n" ::"n"(PENDING));
#endif
}

/// `tile_load` into a stage buffer (R x C f16, rows C halves apart, units swizzled by `swz`):
/// the same elements as `tile_load(out, a, o0, o1)`. A tile wholly inside a row-contiguous
/// array with 16-byte aligned rows is copied with cp.async (completed by the pipe's wait);
/// otherwise element by element, outside elements zero, as tile_load's general path.
/// Where unit `u` (8 halves) of row `r` of an R x C stage operand lands, in halves: rows C
/// halves apart with `swz`'s units (ldmatrix's reads, and wgmma's K-major A, whose rows are
/// its swizzle span); or, with `MN`, wgmma's MN-major B: 64-column atoms of R rows of 128 bytes,
/// 128-byte swizzled.
template <bool MN, int R, int C>
WP_FN int stage_unit(int r, int u) {
  if constexpr (MN) return (u >> 3) * (R * 64) + r * 64 + (((u & 7) ^ (r & 7)) << 3);
  else return r * C + swz<C / 8>(r, u) * 8;
}

template <bool MN, int R, int C, typename O0, typename O1>
WP_FN void pipe_load(f16* dst, const array_t<f16, 2>& a, O0 o0, O1 o1, ctx_t* ctx) {
  constexpr int U = C / 8;
  i64 s0, s1;
  if (tile_detail::inside(o0, R, a.shape[0], &s0) && tile_detail::inside(o1, C, a.shape[1], &s1) &&
      tile_detail::inner_contiguous(a)) {
    const i64 rs = tile_detail::row_stride(a);
    const char* base = reinterpret_cast<const char*>(a.data) + s0 * rs + s1 * (i64)sizeof(f16);
    if (tile_detail::aligned16(base) && (rs & 15) == 0) {
      for (int e = (int)threadIdx.x; e < R * U; e += WP_TILE_BLOCK_DIM) {
        const int r = e / U, u = e % U;
        cp_async16(dst + stage_unit<MN, R, C>(r, u), base + (i64)r * rs + u * 16);
      }
      return;
    }
  }
  for (int e = (int)threadIdx.x; e < R * C; e += WP_TILE_BLOCK_DIM) {
    const int r = e / C, j = e % C;
    i64 c0, c1;
    const bool in =
        tile_detail::coord(o0, r, a.shape[0], &c0) && tile_detail::coord(o1, j, a.shape[1], &c1);
    dst[stage_unit<MN, R, C>(r, j / 8) + j % 8] = in ? load(a, c0, c1, ctx) : f16{};
  }
}

/// The matmul of f16 or bf16 operands (`E`, deduced): the tensor cores where mma_plan fits,
/// else the FMA path.
template <bool Acc, typename C, int M, int K, int N, bool Stage = true, typename E>
WP_FN void matmul(C* c, const E* a, const E* b) {
#if defined(WP_TILE_MMA)
  if constexpr (mma_plan<M, K, N>::FITS) {
    // The emitter's slots are 16-byte aligned (tile_slot_end); a tile over another pointer
    // takes the FMA path. One uniform test per call.
    if (tile_detail::aligned16(a) && tile_detail::aligned16(b) && tile_detail::aligned16(c)) {
      matmul_mma<Acc, C, M, K, N, Stage>(c, a, b);
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

// ---- bf16 ----------------------------------------------------------------------------------
// bf16 (Warp's bfloat16; the scalar is wp_core.h's `wp::bf16`): the same two paths as f16's,
// the tensor cores through `mma.sync.aligned.m16n8k16.row.col.f32.bf16.bf16.f32`. The
// pipelined GEMM k-loop below (and its wgmma) is f16's only: a bf16 k-loop runs as written.

/// `c += a . b` of bf16 tiles into an f32 accumulator.
template <int M, int K, int N>
WP_FN void tile_matmul_acc(const tile_t<f32, M, N>& c, const tile_t<bf16, M, K>& a,
                           const tile_t<bf16, K, N>& b) {
  tile_mma_detail::matmul<true, f32, M, K, N>(c.data, a.data, b.data);
}

/// `c = a . b` of bf16 tiles: accumulated in f32 from +0, each output rounded to bf16 once.
template <int M, int K, int N>
WP_FN void tile_matmul(const tile_t<bf16, M, N>& c, const tile_t<bf16, M, K>& a,
                       const tile_t<bf16, K, N>& b) {
  tile_mma_detail::matmul<false, bf16, M, K, N>(c.data, a.data, b.data);
}

/// The software-pipelined k-loop of a tile GEMM: the CUDA emitter's form of
///
///     for k in a..b { let ta = tile_load(A, ..); let tb = tile_load(B, ..); tile_matmul(ta, tb, &mut c); }
///
/// with f16 tiles and an f32 accumulator (back/cuda_tile_pipe.rs states when it applies). The
/// accumulator stays in the mma fragments for the whole loop (loaded from `c` at `begin`,
/// written back at `end`), and each iteration's loads are issued AHEAD iterations ahead
/// with cp.async into stage buffers, so global-memory latency overlaps the tensor cores. The
/// products are those of `tile_matmul_acc`'s tensor-core path, in the same order (per output,
/// the k-steps of 16 ascending, iteration after iteration), so the results are the same bits.
/// `ON` is false where that path is not taken (FMA fallback shapes, below sm_80, too many
/// accumulators): the emitter then runs the loop as written.
template <int M, int K, int N>
struct tile_gemm_pipe {
  typedef tile_mma_detail::pipe_plan<M, K, N> PP;
  typedef tile_mma_detail::wg_plan<M, K, N> WP;
#if defined(WP_TILE_WGMMA)
  /// Warpgroup MMAs (Hopper) rather than mma.sync.
  static constexpr bool WGM = WP::FITS && PP::STAGES >= 2;
#else
  static constexpr bool WGM = false;
#endif
#if defined(WP_TILE_MMA)
  static constexpr bool ON = WGM || PP::FITS;
#else
  static constexpr bool ON = false;
#endif
  static constexpr int STAGES = PP::STAGES;
  /// wgmma groups `mma` leaves in flight when it returns: one, where there are three stages or
  /// more (the tensor cores run on while the next stage's barrier and copies are issued;
  /// measured on an H200 at 4096^3 with 256 x 128 x 64 tiles, 512 threads: 0.39 ms against
  /// 0.42 ms waiting for all).
  static constexpr int IN_FLIGHT = WGM && STAGES >= 3 ? 1 : 0;
  /// Loads are issued this many iterations ahead, into the stage read IN_FLIGHT + 1 iterations
  /// before, whose products are complete.
  static constexpr int AHEAD = STAGES - 1 - IN_FLIGHT;
  static constexpr int FM = WGM ? 1 : PP::FM, FN = WGM ? 1 : PP::FN, NW = WGM ? 1 : PP::NW;
  static constexpr int MH = WGM ? WP::MH : 1, NR = WGM ? N / 2 : 1;
  /// Blocks an SM should hold (the entry's `__launch_bounds__` hint): two when two blocks'
  /// shared memory fits an SM's 227 KiB (with 1 KiB reserved each) and the registers two blocks
  /// leave a thread (65536 / (2 x block) ) hold the accumulators plus 64 for the rest;
  /// measured on an H200 at 4096^3 with 128 x 128 x 64 tiles and 256 threads: 0.39 ms against
  /// 0.64 ms with the compiler's own register choice (one block an SM).
  static constexpr int ACC_REGS = WGM ? MH * NR : NW * FM * FN * 4;
#if defined(WP_TILE_SMEM_BYTES)
  static constexpr int MIN_BLOCKS = ON && 2 * ((i64)WP_TILE_SMEM_BYTES + 1024) <= 227 * 1024 &&
                                            ACC_REGS + 64 <= 65536 / (2 * WP_TILE_BLOCK_DIM)
                                        ? 2
                                        : 1;
#else
  static constexpr int MIN_BLOCKS = 1;
#endif
  f32 acc[NW][FM][FN][4];
  /// The wgmma accumulators: row block h of this warpgroup, register 4 j + 2 i + e holds
  /// row 16 (warp % 4) + lane / 4 + 8 i, column 8 j + 2 (lane % 4) + e of the block.
  f32 wacc[MH][NR];
  unsigned char* region;  // the accumulator's slot: stages 0 .. R0 - 1
  f16* a_own;             // stage R0: the A and B tiles' slots
  f16* b_own;
  unsigned char* extra;   // stages R0 + 1 ..: the extra shared memory (PIPE_EXTRA)

  WP_FN tile_gemm_pipe(const tile_t<f32, M, N>& c, const tile_t<f16, M, K>& a,
                       const tile_t<f16, K, N>& b)
      : region(reinterpret_cast<unsigned char*>(c.data)), a_own(a.data), b_own(b.data),
        extra(extra_region()) {}

  /// The extra shared memory: the tail of the block's dynamic shared memory (every
  /// `extern __shared__` array starts at its base).
  WP_FN static unsigned char* extra_region() {
#if defined(WP_TILE_PIPE_EXTRA) && defined(WP_TILE_SMEM_BYTES)
    extern __shared__ __align__(16) unsigned char wp_pipe_smem[];
    return wp_pipe_smem + ((usize)WP_TILE_SMEM_BYTES - (usize)WP_TILE_PIPE_EXTRA);
#else
    return nullptr;
#endif
  }

  /// Whether this loop runs pipelined: the plan is on, and for wgmma the slots holding stages
  /// are 1024-byte aligned (the swizzle patterns' period; the emitter's slots are when the
  /// block's shared memory is, which CUDA does not promise, so it is checked).
  WP_FN static bool usable(const tile_t<f32, M, N>& c, const tile_t<f16, M, K>& a,
                           const tile_t<f16, K, N>& b) {
    if (!ON) return false;
    if (!WGM) return true;
    const usize bits = (usize)c.data | (usize)a.data | (usize)b.data |
                       (PP::XS > 0 ? (usize)extra_region() : (usize)0);
    return (bits & 1023) == 0 && (PP::SA % 1024) == 0 && (PP::SB % 1024) == 0;
  }

  WP_FN f16* stage_a(int s) const {
    return s < PP::R0    ? reinterpret_cast<f16*>(region + s * (PP::SA + PP::SB))
           : s == PP::R0 ? a_own
                         : reinterpret_cast<f16*>(extra + (s - PP::R0 - 1) * (PP::SA + PP::SB));
  }
  WP_FN f16* stage_b(int s) const {
    return s < PP::R0 ? reinterpret_cast<f16*>(region + s * (PP::SA + PP::SB) + PP::SA)
           : s == PP::R0
               ? b_own
               : reinterpret_cast<f16*>(extra + (s - PP::R0 - 1) * (PP::SA + PP::SB) + PP::SA);
  }

  /// This warp's k-th warp tile origin, or false past the last warp tile.
  WP_FN bool origin(int w, int* m0, int* n0) const {
    const int wt = ((int)threadIdx.x >> 5) + w * PP::WARPS;
    *m0 = (wt / PP::WTN) * FM * 16;
    *n0 = (wt % PP::WTN) * FN * 8;
    return wt < PP::WT;
  }

  /// Reads the accumulator from `c` into the fragments; the barrier after it frees `c`'s slot
  /// for the stages.
  WP_FN void begin(const tile_t<f32, M, N>& c) {
    __syncthreads();
    const int lane = (int)threadIdx.x & 31, g = lane >> 2, t = lane & 3;
    if constexpr (WGM) {
      const int grp = (int)threadIdx.x >> 7, w = ((int)threadIdx.x >> 5) & 3;
WP_TILE_UNROLL
      for (int h = 0; h < MH; ++h)
WP_TILE_UNROLL
        for (int q = 0; q < NR; ++q) {
          const int row = (grp * MH + h) * 64 + w * 16 + g + 8 * ((q >> 1) & 1);
          const int col = 8 * (q >> 2) + 2 * t + (q & 1);
          wacc[h][q] = c.data[row * N + col];
        }
      __syncthreads();
      return;
    }
WP_TILE_UNROLL
    for (int w = 0; w < NW; ++w) {
      int m0, n0;
      const bool mine = origin(w, &m0, &n0);
WP_TILE_UNROLL
      for (int fm = 0; fm < FM; ++fm)
WP_TILE_UNROLL
        for (int fn = 0; fn < FN; ++fn)
WP_TILE_UNROLL
          for (int h = 0; h < 2; ++h) {
            const int row = m0 + fm * 16 + g + 8 * h, col = n0 + fn * 8 + 2 * t;
            acc[w][fm][fn][2 * h] = mine ? c.data[row * N + col] : 0.0f;
            acc[w][fm][fn][2 * h + 1] = mine ? c.data[row * N + col + 1] : 0.0f;
          }
    }
    __syncthreads();
  }

  template <typename O0, typename O1>
  WP_FN void load_a(int s, const array_t<f16, 2>& a, O0 o0, O1 o1, ctx_t* ctx) {
    tile_mma_detail::pipe_load<false, M, K>(stage_a(s), a, o0, o1, ctx);
  }
  template <typename O0, typename O1>
  WP_FN void load_b(int s, const array_t<f16, 2>& b, O0 o0, O1 o1, ctx_t* ctx) {
    tile_mma_detail::pipe_load<WGM, K, N>(stage_b(s), b, o0, o1, ctx);
  }
  WP_FN void commit() { tile_mma_detail::cp_async_commit(); }

  /// Waits for the oldest stage in flight (this thread's copies), then a barrier: every
  /// thread's copies of it are visible, and every warpgroup's products of the stage read
  /// IN_FLIGHT + 1 iterations before are complete (the next loads overwrite it).
  WP_FN void wait() {
    tile_mma_detail::cp_async_wait<AHEAD - 1>();
#if defined(WP_TILE_WGMMA)
    // wgmma reads shared memory through the async proxy: order this thread's writes (cp.async
    // and plain stores) before it.
    if constexpr (WGM) asm volatile("fence.proxy.async.shared::cta;\n" ::: "memory");
#endif
    __syncthreads();
  }

  /// The tensor-core products of stage `s` onto the fragments.
  WP_FN void mma(int s) {
#if defined(WP_TILE_WGMMA)
    if constexpr (WGM) {
      using namespace tile_mma_detail;
      const unsigned char* a = reinterpret_cast<const unsigned char*>(stage_a(s));
      const unsigned char* b = reinterpret_cast<const unsigned char*>(stage_b(s));
      const int grp = (int)threadIdx.x >> 7;
      asm volatile("wgmma.fence.sync.aligned;\n" ::: "memory");
WP_TILE_UNROLL
      for (int k0 = 0; k0 < K; k0 += 16) {
        // B: k-rows k0.. of every 64-column atom (atoms K * 128 bytes apart, 8-row groups
        // 1024 apart).
        const unsigned long long db = wg_desc(b + k0 * 128, K * 128, 1024, 1);
WP_TILE_UNROLL
        for (int h = 0; h < MH; ++h) {
          // A: rows of this row block, k0's 32 bytes inside the swizzled row (the hardware
          // applies the swizzle to the address it forms); 8-row groups 16 K bytes apart.
          const int row0 = (grp * MH + h) * 64;
          const unsigned long long da = wg_desc(a + row0 * K * 2 + k0 * 2, 16, 16 * K, WP::AMODE);
          wgmma_n<N>(wacc[h], da, db);
        }
      }
      asm volatile("wgmma.commit_group.sync.aligned;\n" ::: "memory");
      asm volatile("wgmma.wait_group.sync.aligned %0;\n" ::"n"(IN_FLIGHT) : "memory");
      return;
    }
#endif
#if defined(WP_TILE_MMA)
    using namespace tile_mma_detail;
    constexpr int UA = PP::UA, UB = PP::UB;
    const f16* a = stage_a(s);
    const f16* b = stage_b(s);
    const int lane = (int)threadIdx.x & 31;
WP_TILE_UNROLL
    for (int w = 0; w < NW; ++w) {
      int m0, n0;
      if (!origin(w, &m0, &n0)) continue;
WP_TILE_UNROLL
      for (int k0 = 0; k0 < K; k0 += 16) {
        unsigned af[FM][4];
        unsigned bf[FN][2];
WP_TILE_UNROLL
        for (int fm = 0; fm < FM; ++fm) {
          const int row = m0 + fm * 16 + (lane & 7) + 8 * ((lane >> 3) & 1);
          const int u = k0 / 8 + (lane >> 4);
          ldmatrix_x4(af[fm], a + row * K + swz<UA>(row, u) * 8);
        }
WP_TILE_UNROLL
        for (int fn = 0; fn + 1 < FN; fn += 2) {
          unsigned r[4];
          const int row = k0 + (lane & 15);
          const int u = (n0 + fn * 8) / 8 + (lane >> 4);
          ldmatrix_x4_trans(r, b + row * N + swz<UB>(row, u) * 8);
          bf[fn][0] = r[0], bf[fn][1] = r[1], bf[fn + 1][0] = r[2], bf[fn + 1][1] = r[3];
        }
        if constexpr (FN % 2 == 1) {
          const int row = k0 + (lane & 15);
          const int u = (n0 + (FN - 1) * 8) / 8;
          ldmatrix_x2_trans(bf[FN - 1], b + row * N + swz<UB>(row, u) * 8);
        }
WP_TILE_UNROLL
        for (int fm = 0; fm < FM; ++fm)
WP_TILE_UNROLL
          for (int fn = 0; fn < FN; ++fn) mma_16816(acc[w][fm][fn], af[fm], bf[fn]);
      }
    }
#else
    (void)s;
#endif
  }

  /// Drains the wgmma groups and copies still in flight (loads past the end were never issued,
  /// but the last groups may be empty), then writes the fragments back to `c`.
  WP_FN void end(const tile_t<f32, M, N>& c) {
#if defined(WP_TILE_WGMMA)
    if constexpr (WGM) asm volatile("wgmma.wait_group.sync.aligned 0;\n" ::: "memory");
#endif
    tile_mma_detail::cp_async_wait<0>();
    __syncthreads();
    const int lane = (int)threadIdx.x & 31, g = lane >> 2, t = lane & 3;
    if constexpr (WGM) {
      const int grp = (int)threadIdx.x >> 7, w = ((int)threadIdx.x >> 5) & 3;
WP_TILE_UNROLL
      for (int h = 0; h < MH; ++h)
WP_TILE_UNROLL
        for (int q = 0; q < NR; ++q) {
          const int row = (grp * MH + h) * 64 + w * 16 + g + 8 * ((q >> 1) & 1);
          const int col = 8 * (q >> 2) + 2 * t + (q & 1);
          c.data[row * N + col] = wacc[h][q];
        }
      __syncthreads();
      return;
    }
WP_TILE_UNROLL
    for (int w = 0; w < NW; ++w) {
      int m0, n0;
      if (!origin(w, &m0, &n0)) continue;
WP_TILE_UNROLL
      for (int fm = 0; fm < FM; ++fm)
WP_TILE_UNROLL
        for (int fn = 0; fn < FN; ++fn)
WP_TILE_UNROLL
          for (int h = 0; h < 2; ++h) {
            const int row = m0 + fm * 16 + g + 8 * h, col = n0 + fn * 8 + 2 * t;
            c.data[row * N + col] = acc[w][fm][fn][2 * h];
            c.data[row * N + col + 1] = acc[w][fm][fn][2 * h + 1];
          }
    }
    __syncthreads();
  }
};

/// `tile_matmul_acc` in the loop printed beside the pipelined one, `Pipe`
/// (back/cuda_tile_pipe.rs). Where the pipe is on, this copy runs only when the slots are not
/// aligned for it, so it makes no padded operand copies: their static shared memory would be
/// reserved by every block, the pipelined ones too (35 KiB for 128 x 64 and 64 x 128 operands,
/// which would halve the blocks an SM holds).
template <typename Pipe, int M, int K, int N>
WP_FN void tile_matmul_acc_beside(const tile_t<f32, M, N>& c, const tile_t<f16, M, K>& a,
                                  const tile_t<f16, K, N>& b) {
  tile_mma_detail::matmul<true, f32, M, K, N, !Pipe::ON>(c.data, a.data, b.data);
}

/// The pipe of a loop over tiles `c`, `a`, `b` (the emitter names their types).
template <typename C, typename A, typename B>
struct tile_gemm_pipe_of;
template <int M, int K, int N>
struct tile_gemm_pipe_of<tile_t<f32, M, N>, tile_t<f16, M, K>, tile_t<f16, K, N>> {
  typedef tile_gemm_pipe<M, K, N> type;
};

}  // namespace wp

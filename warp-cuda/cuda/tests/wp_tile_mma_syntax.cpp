// wp_tile_mma_syntax.cpp: type-checks wp_tile_mma.h's tensor-core path (compiled only for
// sm_80+ devices, so no host driver runs it) with the host compiler: `g++ -fsyntax-only`, with
// __CUDA_ARCH__ faked after the other headers and shims for the CUDA names the path uses.
// Instantiates both element types' matmuls (f16, bf16) on shapes the tensor cores take, so a
// type error in the templates fails here rather than first under NVRTC on a GPU. The inline
// PTX itself is checked by NVRTC only (tests/suite: tiles_f16, bf16).
#include "wp_prim_emu.h"
#include "wp_tile.h"
struct float2 {
  float x, y;
};
static inline float2 make_float2(float x, float y) { return float2{x, y}; }
static inline unsigned long long __cvta_generic_to_shared(const void* p) {
  return (unsigned long long)p;
}
#define __CUDA_ARCH__ 800
#include "wp_tile_mma.h"
#ifndef WP_TILE_MMA
#error "the tensor-core path is not compiled"
#endif
using namespace wp;

void instantiate(tile_t<f32, 32, 32>& c, tile_t<bf16, 32, 32>& a, tile_t<bf16, 32, 32>& b,
                 tile_t<bf16, 32, 32>& p, tile_t<f16, 32, 32>& ha, tile_t<f16, 32, 32>& hb,
                 tile_t<f16, 32, 32>& hp) {
  tile_matmul_acc(c, a, b);
  tile_matmul(p, a, b);
  tile_matmul_acc(c, ha, hb);
  tile_matmul(hp, ha, hb);
  // The tensor-core path itself (the calls above choose it at run time, by alignment).
  tile_mma_detail::matmul_mma<false, bf16, 32, 32, 32, true>(p.data, a.data, b.data);
  tile_mma_detail::matmul_mma<true, f32, 32, 32, 32, false>(c.data, a.data, b.data);
  tile_mma_detail::matmul_mma<false, f16, 32, 32, 32, true>(hp.data, ha.data, hb.data);
}

int main() { return 0; }

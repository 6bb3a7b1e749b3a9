// wp_adjoint_bsr.h: adjoints of the "bsr" section (warp-core/src/objects/bsr.rs's
// adj_bsr_block). Part of the CUDA adjoint library; see wp_adjoint.h for its conventions.
//
//   adj_bsr_block(a, k, adj_a, adj_k, adj_ret, ctx)
//       adj_ret added into the values' gradient at slot k (a.grad, when not null), an
//       atomicAdd per scalar in memory order; a slot outside [0, nnz) faults and adds nothing.
//   The structure queries have no adjoint (Grad::Zero); bsr_set_block and bsr_add_block are
//   writes without one (a kernel making one is refused backward by the macro).
//
// Concurrent adds into one slot may land in any order on the GPU, so the gradient's sums are
// bit for bit the CPU's only where the order does not matter.
#pragma once
#include "wp_adjoint_core.h"
#include "wp_bsr.h"

namespace wp {

template <typename B>
WP_FN void adj_bsr_block(const bsr_t<B>& a, i32 k, bsr_t<B>& adj_a, i32& adj_k,
                         const typename identity<B>::type& adj_ret, ctx_t* ctx) {
  (void)adj_a;
  (void)adj_k;
  if (!detail::bsr_slot_ok(a, k, ctx)) return;
  if (a.grad != nullptr) detail::bsr_add(a.grad + k, adj_ret);
}

}  // namespace wp

// wp_adjoint.h: reverse-mode adjoints (namespace `wp`), the CUDA mirror of warp-core's
// `adjoint` module (warp-core/src/adjoint/{mod,ops,builtins,cast,lanes}.rs) and of the gradient
// accessors of `GradView` (warp-core/src/grad.rs).
//
// Conventions (as on the CPU):
//   * The adjoint of a value has the value's own type. Integer, integer-vector and bool values
//     are not differentiable: every adjoint function taking them is a no-op.
//   * Every adjoint function ACCUMULATES (`+=`) into its adjoint arguments (non-const
//     references), given the adjoint `adj_ret` of the operation's result:
//       adj_<op>(a, b, adj_a, adj_b, adj_ret)     op in add sub mul div rem
//       adj_neg(a, adj_a, adj_ret)
//       adj_<builtin>(args.., adj_args.., adj_ret) min max clamp abs sign floor ceil sqrt exp
//                                                 log sin cos tan atan2 pow lerp dot length
//                                                 normalize cross asin acos atan sinh cosh
//                                                 tanh exp2 log2 log10 cbrt erf erfc erfinv
//                                                 erfcinv round rint trunc frac step degrees
//                                                 radians smoothstep noise pnoise
//       adj_svd3 adj_svd2 adj_eig3 adj_qr3(a, adj_a, adj_ret)  adj_ret: the tuple_t of the
//                                                 results' adjoints (forward recomputed)
//       adj_copysign adj_min_element adj_max_element adj_get_diag adj_norm_l1 adj_norm_l2
//       adj_norm_huber adj_norm_pseudo_huber adj_smooth_normalize adj_quat_rpy adj_quat_to_rpy
//       adj_quat_twist adj_quat_twist_angle(_signed) adj_transform_compose (section "misc")
//       adj_quat_to_axis_angle adj_transform_decompose(x, adj_x, adj_ret)  adj_ret: the tuple_t
//       adj_cast(adj_from, adj_to)                template over the 13 scalar types
//     for exactly the operand types the Rust functions take (the kernel language's operator
//     combinations and the builtin table's signatures, with glam's meaning of each operator).
//   * adj_zero<T>() / zero<T>() / zero_like(x): the zero adjoint (quaternions: (0, 0, 0, 0));
//     adj_accum(a, v): `a += v` for float types, a no-op for the others.
//   * grad_accum / grad_take / grad_get: an array's gradient in an adjoint kernel (an
//     `array_t` whose `data` is null when the array has no gradient).
//
// Floating point: every formula is evaluated in the order the Rust function documents
// (left to right, the same temporaries), so that the GPU agrees with the CPU bit for bit when
// nothing is contracted into an FMA (NVRTC: `--fmad=false`) and the math library agrees
// (sqrt, floor, trunc are exact everywhere; exp, log, sin, cos, tan, pow, sinh, cosh, tanh,
// exp2, cbrt, erfinv, erfcinv come from CUDA's libdevice on the GPU and may differ in the
// last bits from the CPU's, as the forward ones do).
// The edge rules are the CPU's: min/max send the whole adjoint to the operand the forward
// returned (ties to the first, a lone NaN loses, two NaNs to the first); clamp goes through
// max then min in reverse; abs uses sign(0) = +1; length/normalize give nothing at the zero
// vector; pow skips d/dx when y == 0 and d/dy unless x > 0; atan2 gives nothing at (0, 0);
// division is `gb = g / b; adj_a += gb; adj_b -= gb * (a / b)`.
//
// Checked by tests/cuda_adjoint_host.rs against warp-core: bit for bit on the host (g++), and
// on an H200 (nvcc and NVRTC, --fmad=false) bit for bit except the exp/sin/cos/tan/pow adjoints.
//
// `%`: Rust's float `%` (fmod) has the adjoint `adj_b -= g * trunc(a / b)`. This library's
// Vec4 `%` is glam's SSE floored modulo `a - floor(a / b) * b` (wp_core.h); its adjoint is
// `adj_b -= g * floor(a / b)`, with the ordinary floor, which is what warp-core computes where
// glam's Vec4 `%` is floored (x86_64: it asks glam at run time).
//
// This header is the whole library: it includes every part. The runtime includes only
// wp_adjoint_core.h and the parts of the sections a kernel uses (warp_cuda::ADJOINT_SECTIONS):
//   wp_adjoint_core.h       zero/accumulation, lanes, operators, casts, gradients, the stack
//   wp_adjoint_builtins.h   sections "scalar" and "vector"
//   wp_adjoint_linalg.h     section "linalg"
//   wp_adjoint_transform.h  section "transform" (and the transforms' operators)
//   wp_adjoint_spatial.h    section "spatial" (and the spatial types' operators)
//   wp_adjoint_matrix.h     section "matrix" (the non-square matrices' operators)
//   wp_adjoint_svd.h        section "svd"
//   wp_adjoint_misc.h       section "misc"
//   wp_adjoint_rand.h       section "rand" (noise)
#pragma once
#include "wp_adjoint_core.h"
#include "wp_adjoint_builtins.h"
#include "wp_adjoint_linalg.h"
#include "wp_adjoint_transform.h"
#include "wp_adjoint_spatial.h"
#include "wp_adjoint_matrix.h"
#include "wp_adjoint_svd.h"
#include "wp_adjoint_misc.h"
#include "wp_adjoint_rand.h"

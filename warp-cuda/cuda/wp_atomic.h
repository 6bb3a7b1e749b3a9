// wp_atomic.h: section "atomic" of the builtin table (warp-core/src/builtins/atomic.rs).
//
//   atomic_add / atomic_sub / atomic_min / atomic_max (a, idx..., value, ctx) -> old value
//   atomic_exch, atomic_and / atomic_or / atomic_xor (integers), and
//   atomic_cas (a, idx..., compare, value, ctx) -> old value (floats: bitwise compare)
//
// for arrays of i32, u32, i64, u64 (wrapping add/sub), f32, f64, f16 (add/sub/min/max only; f16:
// a 16-bit CAS loop) (min/max with fmin/fmax
// semantics: a NaN operand loses) and float vectors (componentwise, x first, each component
// atomic on its own; the vector as a whole is not updated atomically, as in Warp/CUDA).
// The index is bounds-checked like `load`: out of bounds records OutOfBounds, touches no
// memory and returns T{}.
//
// Device: CUDA's atomicAdd/Sub/Min/Max (relaxed, device scope); f32/f64 min/max are an
// atomicCAS loop on the bit pattern; f64 add falls back to a CAS loop below sm_60.
// Host (g++ checks of generated code): a plain read-modify-write, NOT atomic; the host build
// is only used single-threaded.
#pragma once
#include "wp_scalar.h"

namespace wp {

namespace detail {

#if defined(__CUDACC__)

// ----- integers -----
WP_LFN i32 atomic_add_p(i32* p, i32 v) { return atomicAdd(p, v); }
WP_LFN i32 atomic_sub_p(i32* p, i32 v) { return atomicSub(p, v); }
WP_LFN i32 atomic_min_p(i32* p, i32 v) { return atomicMin(p, v); }
WP_LFN i32 atomic_max_p(i32* p, i32 v) { return atomicMax(p, v); }
WP_LFN u32 atomic_add_p(u32* p, u32 v) { return atomicAdd(p, v); }
WP_LFN u32 atomic_sub_p(u32* p, u32 v) { return atomicSub(p, v); }
WP_LFN u32 atomic_min_p(u32* p, u32 v) { return atomicMin(p, v); }
WP_LFN u32 atomic_max_p(u32* p, u32 v) { return atomicMax(p, v); }
WP_LFN i64 atomic_add_p(i64* p, i64 v) {
  return (i64)atomicAdd((unsigned long long*)p, (unsigned long long)v);
}
WP_LFN i64 atomic_sub_p(i64* p, i64 v) {
  return (i64)atomicAdd((unsigned long long*)p, 0ull - (unsigned long long)v);
}
WP_LFN i64 atomic_min_p(i64* p, i64 v) { return (i64)atomicMin((long long*)p, (long long)v); }
WP_LFN i64 atomic_max_p(i64* p, i64 v) { return (i64)atomicMax((long long*)p, (long long)v); }
WP_LFN u64 atomic_add_p(u64* p, u64 v) { return atomicAdd((unsigned long long*)p, v); }
WP_LFN u64 atomic_sub_p(u64* p, u64 v) { return atomicAdd((unsigned long long*)p, 0ull - v); }
WP_LFN u64 atomic_min_p(u64* p, u64 v) { return atomicMin((unsigned long long*)p, v); }
WP_LFN u64 atomic_max_p(u64* p, u64 v) { return atomicMax((unsigned long long*)p, v); }

// ----- floats -----
template <typename F>
WP_FN f32 cas_loop_f32(f32* p, F f) {
  unsigned int* ip = (unsigned int*)p;
  unsigned int old = *(volatile unsigned int*)ip;
  unsigned int assumed;
  do {
    assumed = old;
    old = atomicCAS(ip, assumed, f32_to_bits(f(f32_from_bits(assumed))));
  } while (old != assumed);
  return f32_from_bits(old);
}
template <typename F>
WP_FN f64 cas_loop_f64(f64* p, F f) {
  unsigned long long* ip = (unsigned long long*)p;
  unsigned long long old = *(volatile unsigned long long*)ip;
  unsigned long long assumed;
  do {
    assumed = old;
    old = atomicCAS(ip, assumed, (unsigned long long)f64_to_bits(f(f64_from_bits(assumed))));
  } while (old != assumed);
  return f64_from_bits(old);
}
WP_LFN f32 atomic_add_p(f32* p, f32 v) { return atomicAdd(p, v); }
WP_LFN f32 atomic_sub_p(f32* p, f32 v) { return atomicAdd(p, -v); }  // x + (-v) == x - v
WP_LFN f32 atomic_min_p(f32* p, f32 v) { return cas_loop_f32(p, [v](f32 x) { return ::fminf(x, v); }); }
WP_LFN f32 atomic_max_p(f32* p, f32 v) { return cas_loop_f32(p, [v](f32 x) { return ::fmaxf(x, v); }); }
#if !defined(__CUDA_ARCH__) || __CUDA_ARCH__ >= 600
WP_LFN f64 atomic_add_p(f64* p, f64 v) { return atomicAdd(p, v); }
WP_LFN f64 atomic_sub_p(f64* p, f64 v) { return atomicAdd(p, -v); }
#else
WP_LFN f64 atomic_add_p(f64* p, f64 v) { return cas_loop_f64(p, [v](f64 x) { return x + v; }); }
WP_LFN f64 atomic_sub_p(f64* p, f64 v) { return cas_loop_f64(p, [v](f64 x) { return x - v; }); }
#endif
WP_LFN f64 atomic_min_p(f64* p, f64 v) { return cas_loop_f64(p, [v](f64 x) { return ::fmin(x, v); }); }
WP_LFN f64 atomic_max_p(f64* p, f64 v) { return cas_loop_f64(p, [v](f64 x) { return ::fmax(x, v); }); }

// ----- f16 and bf16: a CAS loop on the element's 16 bits -----
// sm_70 and newer (every architecture CUDA 13's NVRTC targets) have a 16-bit atomicCAS.
// Older ones CAS the aligned 32-bit word holding the element, writing the other half back
// unchanged (a concurrent change to it fails the CAS and retries); that reads 2 bytes past a
// last element at the end of an allocation (inside the allocation granularity, but
// compute-sanitizer's memcheck reports it, and an external array's neighbour may lie there),
// so it is kept only where there is nothing else. Each new value is one f16 or bf16
// operation (through f32), as on the CPU.
/// The bits of a 16-bit float as `H` (f16 or bf16).
template <typename H> WP_FN H h16_from_bits(u16 b) {
  H h;
  h.bits = b;
  return h;
}
template <typename H, typename F>
WP_FN H cas_loop_h16(H* p, F f) {
#if !defined(__CUDA_ARCH__) || __CUDA_ARCH__ >= 700
  unsigned short* h = (unsigned short*)p;
  unsigned short old = *(volatile unsigned short*)h;
  unsigned short assumed;
  do {
    assumed = old;
    old = atomicCAS(h, assumed, (unsigned short)f(h16_from_bits<H>((u16)assumed)).bits);
  } while (old != assumed);
  return h16_from_bits<H>((u16)old);
#else
  const unsigned long long addr = (unsigned long long)p;
  unsigned int* w = (unsigned int*)(addr & ~3ull);
  const unsigned int shift = (addr & 2ull) != 0 ? 16u : 0u;  // little-endian
  unsigned int old = *(volatile unsigned int*)w;
  unsigned int assumed;
  do {
    assumed = old;
    const u16 next = f(h16_from_bits<H>((u16)(assumed >> shift))).bits;
    const unsigned int word = (assumed & ~(0xFFFFu << shift)) | ((unsigned int)next << shift);
    old = atomicCAS(w, assumed, word);
  } while (old != assumed);
  return h16_from_bits<H>((u16)(old >> shift));
#endif
}
WP_LFN f16 atomic_add_p(f16* p, f16 v) { return cas_loop_h16(p, [v](f16 x) { return x + v; }); }
WP_LFN f16 atomic_sub_p(f16* p, f16 v) { return cas_loop_h16(p, [v](f16 x) { return x - v; }); }
WP_LFN f16 atomic_min_p(f16* p, f16 v) { return cas_loop_h16(p, [v](f16 x) { return wp::min(x, v); }); }
WP_LFN f16 atomic_max_p(f16* p, f16 v) { return cas_loop_h16(p, [v](f16 x) { return wp::max(x, v); }); }
WP_LFN bf16 atomic_add_p(bf16* p, bf16 v) { return cas_loop_h16(p, [v](bf16 x) { return x + v; }); }
WP_LFN bf16 atomic_sub_p(bf16* p, bf16 v) { return cas_loop_h16(p, [v](bf16 x) { return x - v; }); }
WP_LFN bf16 atomic_min_p(bf16* p, bf16 v) { return cas_loop_h16(p, [v](bf16 x) { return wp::min(x, v); }); }
WP_LFN bf16 atomic_max_p(bf16* p, bf16 v) { return cas_loop_h16(p, [v](bf16 x) { return wp::max(x, v); }); }

// ----- compare-and-swap, exchange, bitwise (no adjoint) -----
// Floats compare and swap bit patterns (as warp-core's AtomicSwapElement).
WP_LFN i32 atomic_cas_p(i32* p, i32 c, i32 v) { return atomicCAS(p, c, v); }
WP_LFN u32 atomic_cas_p(u32* p, u32 c, u32 v) { return atomicCAS(p, c, v); }
WP_LFN i64 atomic_cas_p(i64* p, i64 c, i64 v) {
  return (i64)atomicCAS((unsigned long long*)p, (unsigned long long)c, (unsigned long long)v);
}
WP_LFN u64 atomic_cas_p(u64* p, u64 c, u64 v) { return atomicCAS((unsigned long long*)p, c, v); }
WP_LFN f32 atomic_cas_p(f32* p, f32 c, f32 v) {
  return f32_from_bits(atomicCAS((unsigned int*)p, f32_to_bits(c), f32_to_bits(v)));
}
WP_LFN f64 atomic_cas_p(f64* p, f64 c, f64 v) {
  return f64_from_bits(atomicCAS((unsigned long long*)p, (unsigned long long)f64_to_bits(c),
                                 (unsigned long long)f64_to_bits(v)));
}
WP_LFN i32 atomic_exch_p(i32* p, i32 v) { return atomicExch(p, v); }
WP_LFN u32 atomic_exch_p(u32* p, u32 v) { return atomicExch(p, v); }
WP_LFN i64 atomic_exch_p(i64* p, i64 v) {
  return (i64)atomicExch((unsigned long long*)p, (unsigned long long)v);
}
WP_LFN u64 atomic_exch_p(u64* p, u64 v) { return atomicExch((unsigned long long*)p, v); }
WP_LFN f32 atomic_exch_p(f32* p, f32 v) { return atomicExch(p, v); }
WP_LFN f64 atomic_exch_p(f64* p, f64 v) {
  return f64_from_bits(atomicExch((unsigned long long*)p, (unsigned long long)f64_to_bits(v)));
}
#define WP_BITS_ATOMIC(OP, CU)                                                         \
  WP_LFN i32 atomic_##OP##_p(i32* p, i32 v) { return CU(p, v); }                        \
  WP_LFN u32 atomic_##OP##_p(u32* p, u32 v) { return CU(p, v); }                        \
  WP_LFN i64 atomic_##OP##_p(i64* p, i64 v) {                                           \
    return (i64)CU((unsigned long long*)p, (unsigned long long)v);                     \
  }                                                                                    \
  WP_LFN u64 atomic_##OP##_p(u64* p, u64 v) { return CU((unsigned long long*)p, v); }
WP_BITS_ATOMIC(and, atomicAnd)
WP_BITS_ATOMIC(or, atomicOr)
WP_BITS_ATOMIC(xor, atomicXor)
#undef WP_BITS_ATOMIC

#else  // host: single-threaded read-modify-write (not atomic)

#define WP_HOST_RMW(T)                                                           \
  WP_LFN T atomic_add_p(T* p, T v) { const T o = *p; *p = w_add(o, v); return o; } \
  WP_LFN T atomic_sub_p(T* p, T v) { const T o = *p; *p = w_sub(o, v); return o; } \
  WP_LFN T atomic_min_p(T* p, T v) { const T o = *p; *p = min(o, v); return o; }   \
  WP_LFN T atomic_max_p(T* p, T v) { const T o = *p; *p = max(o, v); return o; }
WP_HOST_RMW(i32)
WP_HOST_RMW(u32)
WP_HOST_RMW(i64)
WP_HOST_RMW(u64)
#undef WP_HOST_RMW
#define WP_HOST_RMW_F(T)                                                         \
  WP_LFN T atomic_add_p(T* p, T v) { const T o = *p; *p = o + v; return o; }      \
  WP_LFN T atomic_sub_p(T* p, T v) { const T o = *p; *p = o - v; return o; }      \
  WP_LFN T atomic_min_p(T* p, T v) { const T o = *p; *p = min(o, v); return o; }  \
  WP_LFN T atomic_max_p(T* p, T v) { const T o = *p; *p = max(o, v); return o; }
WP_HOST_RMW_F(f32)
WP_HOST_RMW_F(f64)
WP_HOST_RMW_F(f16)
WP_HOST_RMW_F(bf16)
#undef WP_HOST_RMW_F
#define WP_HOST_SWAP(T, BITS)                                                    \
  WP_LFN T atomic_cas_p(T* p, T c, T v) {                                         \
    const T o = *p;                                                              \
    if (BITS(o) == BITS(c)) *p = v;                                              \
    return o;                                                                    \
  }                                                                              \
  WP_LFN T atomic_exch_p(T* p, T v) { const T o = *p; *p = v; return o; }
#define WP_SAME(x) (x)
WP_HOST_SWAP(i32, WP_SAME)
WP_HOST_SWAP(u32, WP_SAME)
WP_HOST_SWAP(i64, WP_SAME)
WP_HOST_SWAP(u64, WP_SAME)
WP_HOST_SWAP(f32, f32_to_bits)
WP_HOST_SWAP(f64, f64_to_bits)
#undef WP_SAME
#undef WP_HOST_SWAP
#define WP_HOST_BITS(T)                                                          \
  WP_LFN T atomic_and_p(T* p, T v) { const T o = *p; *p = o & v; return o; }      \
  WP_LFN T atomic_or_p(T* p, T v) { const T o = *p; *p = o | v; return o; }       \
  WP_LFN T atomic_xor_p(T* p, T v) { const T o = *p; *p = o ^ v; return o; }
WP_HOST_BITS(i32)
WP_HOST_BITS(u32)
WP_HOST_BITS(i64)
WP_HOST_BITS(u64)
#undef WP_HOST_BITS

#endif

// ----- float vectors: componentwise, x first -----
#define WP_VEC_ATOMIC(V, S, OP)                                                  \
  WP_LFN V atomic_##OP##_p(V* p, V v) {                                           \
    V old;                                                                       \
    for (int i = 0; i < vec_traits<V>::N; ++i)                                   \
      vec_traits<V>::at(old, i) =                                                \
          atomic_##OP##_p(&vec_traits<V>::at(*p, i), vec_traits<V>::get(v, i));  \
    return old;                                                                  \
  }
#define WP_VEC_ATOMICS(V, S) \
  WP_VEC_ATOMIC(V, S, add)   \
  WP_VEC_ATOMIC(V, S, sub)   \
  WP_VEC_ATOMIC(V, S, min)   \
  WP_VEC_ATOMIC(V, S, max)
WP_VEC_ATOMICS(Vec2, f32)
WP_VEC_ATOMICS(Vec3, f32)
WP_VEC_ATOMICS(Vec4, f32)
WP_VEC_ATOMICS(DVec2, f64)
WP_VEC_ATOMICS(DVec3, f64)
WP_VEC_ATOMICS(DVec4, f64)
#undef WP_VEC_ATOMICS
#undef WP_VEC_ATOMIC

}  // namespace detail

// The builtins: (array, one i64 index per dimension, value, ctx) -> old value.
#define WP_ATOMIC_BUILTIN(OP)                                                                  \
  template <typename T>                                                                        \
  WP_FN T atomic_##OP(const array_t<T, 1>& a, i64 i0, typename identity<T>::type v, ctx_t* ctx) {                       \
    const i64 idx[] = {i0};                                                               \
    return detail::check_idx(a, idx, ctx) ? detail::atomic_##OP##_p(detail::elem_ptr_unchecked_idx(a, idx), v) : T{}; \
  }                                                                                            \
  template <typename T>                                                                        \
  WP_FN T atomic_##OP(const array_t<T, 2>& a, i64 i0, i64 i1, typename identity<T>::type v, ctx_t* ctx) {               \
    const i64 idx[] = {i0, i1};                                                           \
    return detail::check_idx(a, idx, ctx) ? detail::atomic_##OP##_p(detail::elem_ptr_unchecked_idx(a, idx), v) : T{}; \
  }                                                                                            \
  template <typename T>                                                                        \
  WP_FN T atomic_##OP(const array_t<T, 3>& a, i64 i0, i64 i1, i64 i2, typename identity<T>::type v, ctx_t* ctx) {       \
    const i64 idx[] = {i0, i1, i2};                                                       \
    return detail::check_idx(a, idx, ctx) ? detail::atomic_##OP##_p(detail::elem_ptr_unchecked_idx(a, idx), v) : T{}; \
  }                                                                                            \
  template <typename T>                                                                        \
  WP_FN T atomic_##OP(const array_t<T, 4>& a, i64 i0, i64 i1, i64 i2, i64 i3, typename identity<T>::type v, ctx_t* ctx) { \
    const i64 idx[] = {i0, i1, i2, i3};                                                   \
    return detail::check_idx(a, idx, ctx) ? detail::atomic_##OP##_p(detail::elem_ptr_unchecked_idx(a, idx), v) : T{}; \
  }
WP_ATOMIC_BUILTIN(add)
WP_ATOMIC_BUILTIN(sub)
WP_ATOMIC_BUILTIN(min)
WP_ATOMIC_BUILTIN(max)
WP_ATOMIC_BUILTIN(exch)
WP_ATOMIC_BUILTIN(and)
WP_ATOMIC_BUILTIN(or)
WP_ATOMIC_BUILTIN(xor)
#undef WP_ATOMIC_BUILTIN

// atomic_cas: (array, one i64 index per dimension, compare, value, ctx) -> old value.
template <typename T>
WP_FN T atomic_cas(const array_t<T, 1>& a, i64 i0, typename identity<T>::type c,
                   typename identity<T>::type v, ctx_t* ctx) {
  const i64 idx[] = {i0};
  return detail::check_idx(a, idx, ctx) ? detail::atomic_cas_p(detail::elem_ptr_unchecked_idx(a, idx), c, v)
                                        : T{};
}
template <typename T>
WP_FN T atomic_cas(const array_t<T, 2>& a, i64 i0, i64 i1, typename identity<T>::type c,
                   typename identity<T>::type v, ctx_t* ctx) {
  const i64 idx[] = {i0, i1};
  return detail::check_idx(a, idx, ctx) ? detail::atomic_cas_p(detail::elem_ptr_unchecked_idx(a, idx), c, v)
                                        : T{};
}
template <typename T>
WP_FN T atomic_cas(const array_t<T, 3>& a, i64 i0, i64 i1, i64 i2, typename identity<T>::type c,
                   typename identity<T>::type v, ctx_t* ctx) {
  const i64 idx[] = {i0, i1, i2};
  return detail::check_idx(a, idx, ctx) ? detail::atomic_cas_p(detail::elem_ptr_unchecked_idx(a, idx), c, v)
                                        : T{};
}
template <typename T>
WP_FN T atomic_cas(const array_t<T, 4>& a, i64 i0, i64 i1, i64 i2, i64 i3,
                   typename identity<T>::type c, typename identity<T>::type v, ctx_t* ctx) {
  const i64 idx[] = {i0, i1, i2, i3};
  return detail::check_idx(a, idx, ctx) ? detail::atomic_cas_p(detail::elem_ptr_unchecked_idx(a, idx), c, v)
                                        : T{};
}

}  // namespace wp

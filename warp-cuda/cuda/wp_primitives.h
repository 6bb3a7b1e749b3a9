// wp_primitives.h: warp-lang's parallel primitives as CUDA kernels (namespace `wp::prim`):
// scan, reduction (sum, min, max), stream compaction and LSD radix sort of key/value pairs.
//
// The runtime (warp-runtime/src/primitives/) compiles one small module per element type
// through NVRTC and the kernel disk cache: the module's text is `#include "wp_primitives.h"`
// followed by the entry macros at the end of this file (`WP_PRIM_SCAN_MODULE(i32)`, ...). It
// decides the sequence of launches (a "plan": which entry, how many blocks, which buffers);
// the kernels here are the steps.
//
// Every kernel has one parameter, `args_t` (sixteen 64-bit words: device addresses and
// integers), so that every entry has the same C++ signature: the host tests run the very same
// plans on the CPU by compiling this file with g++ under a block emulator
// (warp-cuda/cuda/tests/wp_prim_emu.h), which finds entries by name through
// `WP_PRIM_REGISTER`. For the same reason the kernels use only `__syncthreads` and shared
// memory for cooperation inside a block (no warp shuffles, no atomics), and never wait for
// another block: a block emulated on the host runs to completion before the next starts.
//
// Algorithms (learned from the literature, written for this project):
//   * Block scan: each thread reduces WP_PRIM_ITEMS consecutive elements serially, the block
//     scans the per-thread totals (Hillis-Steele in shared memory, double buffered), and each
//     thread rescans its elements from its offset.
//   * Device scan and reduction: three phases without inter-block waiting: (1) every block
//     writes its tile's total, (2) one block scans the totals in tiles with a carry (the
//     "spine"), (3) every block rescans its tile from its offset. A reduction stops after (2).
//   * Compaction: the scan of the flags (nonzero = keep) gives each kept element its output
//     position; the spine's total is the count.
//   * Radix sort: LSD, 4 bits per pass, stable. Per pass: every block counts the digits of
//     its tile, per thread (`counts[digit][thread]`), and scans those counts in digit-major
//     order, which gives every element its rank among the tile's elements of the same digit
//     (stable: thread t's elements come after those of threads < t, and each thread walks its
//     elements in order); the tiles' digit counts (`hist[digit * blocks + block]`) are
//     scanned by the device scan, which gives every (digit, block) its first output position.
//
// Lengths: a kernel processes `n` elements where `n` is a host value (`capacity`), or read on
// the device from a 1-element i32 array (`count`) so that no host synchronisation is needed.
// A device count outside 0..=capacity is a fault (OutOfBounds of the count argument with
// index [count] and shape [capacity + 1], recorded by the plan's first kernel) and is treated
// as 0 by every kernel, so nothing is written out of bounds.
//
// Integer sums wrap (as integer arithmetic does in the kernel language). Float min and max
// ignore NaN (the language's `min`/`max`: with one NaN operand, the other one).
#pragma once

#include "wp_core.h"

#if !defined(WP_PRIM_THREADS) || !defined(WP_PRIM_ITEMS)
#error "wp_primitives.h: define WP_PRIM_THREADS and WP_PRIM_ITEMS (the runtime passes both)"
#endif

#if defined(__CUDACC__)
#define WP_PRIM_FN __device__ __forceinline__
#define WP_PRIM_ENTRY extern "C" __global__ void __launch_bounds__(WP_PRIM_THREADS)
#define WP_PRIM_SHARED __shared__
#define WP_PRIM_SYNC() __syncthreads()
#define WP_PRIM_TID ((wp::i32)threadIdx.x)
#define WP_PRIM_BID ((wp::i64)blockIdx.x)
#define WP_PRIM_REGISTER(name)
#elif !defined(WP_PRIM_EMULATOR)
#error "wp_primitives.h on the host needs the block emulator (include tests/wp_prim_emu.h first)"
#endif

namespace wp {
namespace prim {

constexpr i32 THREADS = WP_PRIM_THREADS;
constexpr i32 ITEMS = WP_PRIM_ITEMS;
constexpr i64 TILE = (i64)THREADS * ITEMS;
/// Bits of the key sorted per radix pass, and the number of digits.
constexpr i32 RADIX_BITS = 4;
constexpr i32 RADIX = 1 << RADIX_BITS;

static_assert(THREADS >= RADIX && (THREADS & (THREADS - 1)) == 0,
              "the block size is a power of two of at least RADIX threads");
static_assert(ITEMS >= 1, "at least one element per thread");

/// The one kernel parameter: device addresses and integers, in an order each kernel states.
struct args_t {
  u64 w[16];
};
static_assert(sizeof(args_t) == 128, "args_t layout");

template <typename P>
WP_PRIM_FN P* ptr(const args_t& a, int k) {
  return (P*)(a.w[k]);
}
WP_PRIM_FN i64 int_arg(const args_t& a, int k) { return (i64)a.w[k]; }

// ------------------------------------------------------------------------------------------
// Operators
// ------------------------------------------------------------------------------------------

/// `a + b`, wrapping for integers (through the unsigned type: no signed-overflow UB).
template <typename T>
WP_PRIM_FN T add(T a, T b) {
  if constexpr (num<T>::is_int) {
    typedef typename num<T>::unsigned_t U;
    return (T)(U)((U)a + (U)b);
  } else {
    return a + b;
  }
}

template <typename T>
WP_PRIM_FN T pos_inf();
template <>
WP_PRIM_FN f32 pos_inf<f32>() {
  return f32_from_bits(0x7f800000u);
}
template <>
WP_PRIM_FN f64 pos_inf<f64>() {
  return f64_from_bits(0x7ff0000000000000ull);
}

template <typename T>
struct op_sum {
  static WP_PRIM_FN T identity() { return (T)0; }
  static WP_PRIM_FN T apply(T a, T b) { return add(a, b); }
};

/// Minimum; for floats a NaN operand gives the other one (NaNs are ignored; all-NaN gives
/// the identity, +inf).
template <typename T>
struct op_min {
  static WP_PRIM_FN T identity() {
    if constexpr (num<T>::is_int) {
      return num<T>::max_value;
    } else {
      return pos_inf<T>();
    }
  }
  static WP_PRIM_FN T apply(T a, T b) { return (b < a || a != a) ? b : a; }
};

/// Maximum; NaNs ignored as in `op_min` (identity -inf).
template <typename T>
struct op_max {
  static WP_PRIM_FN T identity() {
    if constexpr (num<T>::is_int) {
      return num<T>::min_value;
    } else {
      return -pos_inf<T>();
    }
  }
  static WP_PRIM_FN T apply(T a, T b) { return (b > a || a != a) ? b : a; }
};

// ------------------------------------------------------------------------------------------
// Lengths
// ------------------------------------------------------------------------------------------

/// The number of elements to process: `capacity` without a count array, else `*count` when
/// it lies in 0..=capacity, else 0 (and, when `report`, a fault on argument `count_arg`).
/// Only thread 0 of block 0 reports, so one bad count is one fault record.
WP_PRIM_FN i64 resolve_count(const i32* count, i64 capacity, fault_t* fault, u32* flag,
                             i64 count_arg, bool report) {
  if (count == nullptr) return capacity;
  i64 c = (i64)*count;
  if (c >= 0 && c <= capacity) return c;
  if (report && WP_PRIM_TID == 0 && WP_PRIM_BID == 0) {
    ctx_t ctx = ctx_make(fault, flag);
    i64 index[1] = {c};
    i64 shape[1] = {capacity + 1};
    raise(&ctx, FAULT_OUT_OF_BOUNDS, (i32)count_arg, 1, index, shape);
  }
  return 0;
}

// ------------------------------------------------------------------------------------------
// Block-level building blocks
// ------------------------------------------------------------------------------------------

/// Exclusive scan of one value per thread across the block (Hillis-Steele in `sh`, which
/// holds 2 * THREADS values). Sets `*total` to the block's total. Every thread of the block
/// must call it (it synchronises); `sh` may be reused as soon as it returns.
template <typename T, typename Op>
WP_PRIM_FN T block_exclusive_scan(T v, T* sh, T* total) {
  const i32 t = WP_PRIM_TID;
  sh[t] = v;
  WP_PRIM_SYNC();
  i32 pin = 0;
  for (i32 off = 1; off < THREADS; off <<= 1) {
    T x = sh[pin * THREADS + t];
    if (t >= off) x = Op::apply(sh[pin * THREADS + t - off], x);
    sh[(1 - pin) * THREADS + t] = x;
    pin ^= 1;
    WP_PRIM_SYNC();
  }
  const T excl = t > 0 ? sh[pin * THREADS + t - 1] : Op::identity();
  *total = sh[pin * THREADS + THREADS - 1];
  // Nobody may overwrite `sh` (the next call) before every thread has read it.
  WP_PRIM_SYNC();
  return excl;
}

/// Phase 1: the total of block b's tile of `load(i)` for i < n (the identity for a tile past
/// n), written to `partials[b]`.
template <typename T, typename Op, typename Load>
WP_PRIM_FN void tile_total(Load load, i64 n, T* partials) {
  WP_PRIM_SHARED T sh[2 * THREADS];
  const i64 b = WP_PRIM_BID;
  const i64 base = b * TILE + (i64)WP_PRIM_TID * ITEMS;
  T acc = Op::identity();
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 i = base + k;
    if (i < n) acc = Op::apply(acc, load(i));
  }
  T total;
  block_exclusive_scan<T, Op>(acc, sh, &total);
  if (WP_PRIM_TID == 0) partials[b] = total;
}

/// Phase 2, one block: the exclusive scan of `partials[0..nb)` in place (when `write_prefix`)
/// and their total into `*total_out` (when not null). Tiles of the partials are scanned one
/// after another with a carry, so any number of blocks fits.
template <typename T, typename Op>
WP_PRIM_FN void spine(T* partials, i64 nb, bool write_prefix, T* total_out) {
  WP_PRIM_SHARED T sh[2 * THREADS];
  T carry = Op::identity();
  for (i64 start = 0; start < nb; start += TILE) {
    const i64 base = start + (i64)WP_PRIM_TID * ITEMS;
    T vals[ITEMS];
    T acc = Op::identity();
    for (i32 k = 0; k < ITEMS; ++k) {
      const i64 i = base + k;
      vals[k] = i < nb ? partials[i] : Op::identity();
      acc = Op::apply(acc, vals[k]);
    }
    T tile;
    const T excl = block_exclusive_scan<T, Op>(acc, sh, &tile);
    if (write_prefix) {
      T run = Op::apply(carry, excl);
      for (i32 k = 0; k < ITEMS; ++k) {
        const i64 i = base + k;
        if (i < nb) {
          partials[i] = run;
          run = Op::apply(run, vals[k]);
        }
      }
    }
    carry = Op::apply(carry, tile);
  }
  if (total_out != nullptr && WP_PRIM_TID == 0) *total_out = carry;
}

/// Phase 3: block b rescans its tile from `prefixes[b]` (the exclusive scan of the tile
/// totals) and hands `emit(i, value)` the inclusive or exclusive result of each i < n. An
/// element is read and written by the same thread, so `emit` may overwrite the input.
template <typename T, typename Op, typename Load, typename Emit>
WP_PRIM_FN void tile_scan(Load load, Emit emit, i64 n, const T* prefixes, bool inclusive) {
  WP_PRIM_SHARED T sh[2 * THREADS];
  const i64 b = WP_PRIM_BID;
  if (b * TILE >= n) return;  // the whole block leaves: no barrier is skipped by some only
  const i64 base = b * TILE + (i64)WP_PRIM_TID * ITEMS;
  T vals[ITEMS];
  T acc = Op::identity();
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 i = base + k;
    vals[k] = i < n ? load(i) : Op::identity();
    acc = Op::apply(acc, vals[k]);
  }
  T total;
  const T excl = block_exclusive_scan<T, Op>(acc, sh, &total);
  T run = Op::apply(prefixes[b], excl);
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 i = base + k;
    if (i >= n) break;
    if (inclusive) {
      run = Op::apply(run, vals[k]);
      emit(i, run);
    } else {
      emit(i, run);
      run = Op::apply(run, vals[k]);
    }
  }
}

template <typename T>
struct load_array {
  const T* a;
  WP_PRIM_FN T operator()(i64 i) const { return a[i]; }
};

template <typename T>
struct store_array {
  T* a;
  WP_PRIM_FN void operator()(i64 i, T v) const { a[i] = v; }
};

/// A compaction flag as a count: 1 when nonzero.
struct load_flag {
  const i32* a;
  WP_PRIM_FN i32 operator()(i64 i) const { return a[i] != 0 ? 1 : 0; }
};

// ------------------------------------------------------------------------------------------
// Scan and reduction kernels
// ------------------------------------------------------------------------------------------

/// args: 0 in (const T*), 1 count (const i32* or 0), 2 capacity, 3 partials (T*), 4 fault,
/// 5 fault flag, 6 count's argument index (for the fault), 7 report (1: this kernel reports a
/// bad count).
template <typename T, typename Op>
WP_PRIM_FN void k_tile_total(const args_t& a) {
  const i64 n = resolve_count(ptr<const i32>(a, 1), int_arg(a, 2), ptr<fault_t>(a, 4),
                              ptr<u32>(a, 5), int_arg(a, 6), int_arg(a, 7) != 0);
  tile_total<T, Op>(load_array<T>{ptr<const T>(a, 0)}, n, ptr<T>(a, 3));
}

/// args: 0 partials (T*), 1 number of partials, 2 write the exclusive prefixes (0/1),
/// 3 total (T* or 0). One block.
template <typename T, typename Op>
WP_PRIM_FN void k_spine(const args_t& a) {
  spine<T, Op>(ptr<T>(a, 0), int_arg(a, 1), int_arg(a, 2) != 0, ptr<T>(a, 3));
}

/// args: 0 in (const T*), 1 out (T*, may be `in`), 2 count, 3 capacity, 4 prefixes (const T*),
/// 5 inclusive (0/1).
template <typename T>
WP_PRIM_FN void k_scan_down(const args_t& a) {
  const i64 n = resolve_count(ptr<const i32>(a, 2), int_arg(a, 3), nullptr, nullptr, 0, false);
  tile_scan<T, op_sum<T>>(load_array<T>{ptr<const T>(a, 0)}, store_array<T>{ptr<T>(a, 1)}, n,
                          ptr<const T>(a, 4), int_arg(a, 5) != 0);
}

// ------------------------------------------------------------------------------------------
// Stream compaction
// ------------------------------------------------------------------------------------------

/// An element moved as raw bytes (`W` words of type `Word`): compaction never looks inside.
template <typename Word, int W>
struct blob {
  Word w[W];
};

/// args: 0 flags (const i32*), 1 count, 2 capacity, 3 partials (i32*), 4 fault, 5 fault flag,
/// 6 count's argument index, 7 report.
WP_PRIM_FN void k_compact_count(const args_t& a) {
  const i64 n = resolve_count(ptr<const i32>(a, 1), int_arg(a, 2), ptr<fault_t>(a, 4),
                              ptr<u32>(a, 5), int_arg(a, 6), int_arg(a, 7) != 0);
  tile_total<i32, op_sum<i32>>(load_flag{ptr<const i32>(a, 0)}, n, ptr<i32>(a, 3));
}

/// Writes the kept element `i` to its position (the exclusive scan of the flags).
template <typename V>
struct emit_kept {
  const V* values;
  const i32* flags;
  V* out;
  WP_PRIM_FN void operator()(i64 i, i32 pos) const {
    if (flags[i] != 0) out[pos] = values[i];
  }
};

/// args: 0 values (const V*), 1 flags (const i32*), 2 out (V*), 3 count, 4 capacity,
/// 5 prefixes (const i32*: exclusive scan of the tiles' kept counts).
template <typename V>
WP_PRIM_FN void k_compact_down(const args_t& a) {
  const i64 n = resolve_count(ptr<const i32>(a, 3), int_arg(a, 4), nullptr, nullptr, 0, false);
  const i32* flags = ptr<const i32>(a, 1);
  tile_scan<i32, op_sum<i32>>(load_flag{flags},
                              emit_kept<V>{ptr<const V>(a, 0), flags, ptr<V>(a, 2)}, n,
                              ptr<const i32>(a, 5), false);
}

// ------------------------------------------------------------------------------------------
// Radix sort
// ------------------------------------------------------------------------------------------

/// Keys as unsigned integers whose order is the keys' order: u32 as is; i32 with the sign bit
/// flipped; f32 by `f32::total_cmp`'s order (-NaN < -inf < .. < -0.0 < +0.0 < .. < +inf <
/// +NaN): negative values have every bit flipped, others the sign bit.
template <typename K>
struct radix_key;
template <>
struct radix_key<u32> {
  static WP_PRIM_FN u32 bits(u32 k) { return k; }
};
template <>
struct radix_key<i32> {
  static WP_PRIM_FN u32 bits(u32 k) { return k ^ 0x80000000u; }
};
template <>
struct radix_key<f32> {
  static WP_PRIM_FN u32 bits(u32 k) { return (k & 0x80000000u) ? ~k : (k | 0x80000000u); }
};

/// The digit counts of block b's tile, scanned: afterwards `counts[d * THREADS + t]` is the
/// number of the tile's elements with a digit below d plus those with digit d held by threads
/// below t (each thread holds ITEMS consecutive elements). Returns the tile's element count.
/// Keys are the raw 32-bit patterns; `K` says how to order them.
template <typename K>
WP_PRIM_FN u32 tile_digit_ranks(const u32* keys, i64 n, i32 shift, u32 mask, u32* counts,
                                u32* sh) {
  const i32 t = WP_PRIM_TID;
  const i64 base = WP_PRIM_BID * TILE + (i64)t * ITEMS;
  for (i32 d = 0; d < RADIX; ++d) counts[d * THREADS + t] = 0;
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 i = base + k;
    if (i < n) {
      const u32 d = (radix_key<K>::bits(keys[i]) >> shift) & mask;
      counts[d * THREADS + t] += 1;  // thread t's own column: no other thread writes it
    }
  }
  WP_PRIM_SYNC();
  // Digit-major order, RADIX consecutive entries per thread (RADIX * THREADS in all).
  u32* mine = counts + (i64)t * RADIX;
  u32 sum = 0;
  u32 vals[RADIX];
  for (i32 k = 0; k < RADIX; ++k) {
    vals[k] = mine[k];
    sum += vals[k];
  }
  u32 total;
  u32 run = block_exclusive_scan<u32, op_sum<u32>>(sum, sh, &total);
  for (i32 k = 0; k < RADIX; ++k) {
    mine[k] = run;
    run += vals[k];
  }
  WP_PRIM_SYNC();
  return total;
}

/// args: 0 keys (const u32*), 1 count, 2 capacity, 3 shift, 4 mask, 5 hist (u32*, RADIX *
/// blocks, digit-major), 6 number of blocks, 7 fault, 8 fault flag, 9 count's argument index,
/// 10 report.
template <typename K>
WP_PRIM_FN void k_sort_hist(const args_t& a) {
  WP_PRIM_SHARED u32 counts[RADIX * THREADS];
  WP_PRIM_SHARED u32 sh[2 * THREADS];
  const i64 n = resolve_count(ptr<const i32>(a, 1), int_arg(a, 2), ptr<fault_t>(a, 7),
                              ptr<u32>(a, 8), int_arg(a, 9), int_arg(a, 10) != 0);
  u32* hist = ptr<u32>(a, 5);
  const i64 nb = int_arg(a, 6);
  const i64 b = WP_PRIM_BID;
  const i32 t = WP_PRIM_TID;
  if (b * TILE >= n) {
    if (t < RADIX) hist[t * nb + b] = 0;
    return;
  }
  const u32 total = tile_digit_ranks<K>(ptr<const u32>(a, 0), n, (i32)int_arg(a, 3),
                                        (u32)int_arg(a, 4), counts, sh);
  if (t < RADIX) {
    const u32 end = t + 1 < RADIX ? counts[(t + 1) * THREADS] : total;
    hist[t * nb + b] = end - counts[t * THREADS];
  }
}

/// args: 0 keys in (const u32*), 1 values in (const u32*), 2 keys out (u32*), 3 values out
/// (u32*), 4 count, 5 capacity, 6 shift, 7 mask, 8 offsets (const u32*: the exclusive scan
/// of the histogram, digit-major), 9 number of blocks.
template <typename K>
WP_PRIM_FN void k_sort_scatter(const args_t& a) {
  WP_PRIM_SHARED u32 counts[RADIX * THREADS];
  WP_PRIM_SHARED u32 sh[2 * THREADS];
  WP_PRIM_SHARED u32 dst_base[RADIX];
  const i64 n = resolve_count(ptr<const i32>(a, 4), int_arg(a, 5), nullptr, nullptr, 0, false);
  const i64 b = WP_PRIM_BID;
  if (b * TILE >= n) return;
  const i32 t = WP_PRIM_TID;
  const u32* keys = ptr<const u32>(a, 0);
  const u32* values = ptr<const u32>(a, 1);
  u32* keys_out = ptr<u32>(a, 2);
  u32* values_out = ptr<u32>(a, 3);
  const i32 shift = (i32)int_arg(a, 6);
  const u32 mask = (u32)int_arg(a, 7);
  const u32* offsets = ptr<const u32>(a, 8);
  const i64 nb = int_arg(a, 9);
  tile_digit_ranks<K>(keys, n, shift, mask, counts, sh);
  // Element with digit d and tile rank r goes to offsets[d][b] + r - (tile's first rank of d).
  // Read column 0 before thread 0 starts bumping it below.
  if (t < RADIX) dst_base[t] = offsets[t * nb + b] - counts[t * THREADS];
  WP_PRIM_SYNC();
  const i64 base = b * TILE + (i64)t * ITEMS;
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 i = base + k;
    if (i >= n) break;
    const u32 key = keys[i];
    const u32 d = (radix_key<K>::bits(key) >> shift) & mask;
    const u32 dst = dst_base[d] + counts[d * THREADS + t];
    counts[d * THREADS + t] += 1;
    keys_out[dst] = key;
    values_out[dst] = values[i];
  }
}

/// args: 0 keys in, 1 values in, 2 keys out, 3 values out (u32*), 4 count, 5 capacity.
/// Copies the first n pairs (the last pass of an odd number of passes ends in the scratch).
WP_PRIM_FN void k_copy_pairs(const args_t& a) {
  const i64 n = resolve_count(ptr<const i32>(a, 4), int_arg(a, 5), nullptr, nullptr, 0, false);
  const i64 base = WP_PRIM_BID * TILE + (i64)WP_PRIM_TID;
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 i = base + (i64)k * THREADS;  // strided: consecutive threads, consecutive words
    if (i < n) {
      ptr<u32>(a, 2)[i] = ptr<const u32>(a, 0)[i];
      ptr<u32>(a, 3)[i] = ptr<const u32>(a, 1)[i];
    }
  }
}

}  // namespace prim
}  // namespace wp

// ------------------------------------------------------------------------------------------
// Entry points: what a module instantiates (names are what the runtime's plans launch)
// ------------------------------------------------------------------------------------------

#define WP_PRIM_DEFINE(name, body)                 \
  WP_PRIM_ENTRY name(wp::prim::args_t a) { body(a); } \
  WP_PRIM_REGISTER(name)

/// Scan and reductions of T: `wp_prim_total_{sum,min,max}_T`, `wp_prim_spine_{sum,min,max}_T`,
/// `wp_prim_scan_down_T`.
#define WP_PRIM_SCAN_MODULE(T)                                                       \
  WP_PRIM_DEFINE(wp_prim_total_sum_##T, (wp::prim::k_tile_total<wp::T, wp::prim::op_sum<wp::T>>)) \
  WP_PRIM_DEFINE(wp_prim_total_min_##T, (wp::prim::k_tile_total<wp::T, wp::prim::op_min<wp::T>>)) \
  WP_PRIM_DEFINE(wp_prim_total_max_##T, (wp::prim::k_tile_total<wp::T, wp::prim::op_max<wp::T>>)) \
  WP_PRIM_DEFINE(wp_prim_spine_sum_##T, (wp::prim::k_spine<wp::T, wp::prim::op_sum<wp::T>>))      \
  WP_PRIM_DEFINE(wp_prim_spine_min_##T, (wp::prim::k_spine<wp::T, wp::prim::op_min<wp::T>>))      \
  WP_PRIM_DEFINE(wp_prim_spine_max_##T, (wp::prim::k_spine<wp::T, wp::prim::op_max<wp::T>>))      \
  WP_PRIM_DEFINE(wp_prim_scan_down_##T, (wp::prim::k_scan_down<wp::T>))

/// Radix sort with keys K (u32, i32 or f32): `wp_prim_sort_hist_K`, `wp_prim_sort_scatter_K`,
/// plus what every sort needs: the u32 scan of the histogram and `wp_prim_copy_pairs`.
#define WP_PRIM_SORT_MODULE(K)                                              \
  WP_PRIM_DEFINE(wp_prim_sort_hist_##K, (wp::prim::k_sort_hist<wp::K>))       \
  WP_PRIM_DEFINE(wp_prim_sort_scatter_##K, (wp::prim::k_sort_scatter<wp::K>)) \
  WP_PRIM_DEFINE(wp_prim_sort_total_u32, (wp::prim::k_tile_total<wp::u32, wp::prim::op_sum<wp::u32>>)) \
  WP_PRIM_DEFINE(wp_prim_sort_spine_u32, (wp::prim::k_spine<wp::u32, wp::prim::op_sum<wp::u32>>))      \
  WP_PRIM_DEFINE(wp_prim_sort_scan_down_u32, (wp::prim::k_scan_down<wp::u32>))                         \
  WP_PRIM_DEFINE(wp_prim_copy_pairs, wp::prim::k_copy_pairs)

/// Compaction of elements of `W` words of type `Word` (u8, u16, u32 or u64):
/// `wp_prim_compact_count`, `wp_prim_compact_spine`, `wp_prim_compact_down`.
#define WP_PRIM_COMPACT_MODULE(Word, W)                                                   \
  WP_PRIM_DEFINE(wp_prim_compact_count, wp::prim::k_compact_count)                         \
  WP_PRIM_DEFINE(wp_prim_compact_spine, (wp::prim::k_spine<wp::i32, wp::prim::op_sum<wp::i32>>)) \
  WP_PRIM_DEFINE(wp_prim_compact_down, (wp::prim::k_compact_down<wp::prim::blob<wp::Word, W>>))

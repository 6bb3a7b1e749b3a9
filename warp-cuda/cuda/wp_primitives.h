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
// `WP_PRIM_REGISTER`. For the same reason the kernels cooperate only through what the
// emulator models: `__syncthreads`, shared memory, `atomicAdd` (WP_PRIM_ATOMIC_ADD), and the
// warp intrinsics `__ballot_sync`, `__match_any_sync`, `__shfl_sync`, `__shfl_up_sync`,
// `__shfl_down_sync` (with `__popc`, `__clz`); the kernels that wait for other blocks (the
// look-backs of the sort and of the single-pass scan) wait only for tiles handed out earlier
// by an atomic counter, which the emulator (blocks in order) has already finished. Memory
// ordering between blocks is the one thing the emulator cannot check: where a look-back reads
// a value published apart from its flag, a fence (WP_PRIM_FENCE, `__threadfence` on a GPU,
// nothing in the emulator) orders the two on both sides.
//
// Algorithms (learned from the literature, written for this project):
//   * Block scan: each thread reduces WP_PRIM_ITEMS consecutive elements serially, the block
//     scans the per-thread totals (warp shuffles, the warps' totals in shared memory, one
//     barrier: `block_scan_warps`; Hillis-Steele in shared memory, double buffered, in the
//     one-block spine, which scans tile after tile), and each thread rescans its elements
//     from its offset.
//   * Block total (reductions, and the tile totals of the three-phase scan and compaction):
//     each thread's elements reduced serially (two accumulators), then a shuffle tree in each
//     warp and one barrier: thread 0 combines the warps' totals in warp order.
//   * Device scan, three phases without inter-block waiting (the default): (1) every block
//     writes its tile's total, (2) one block scans the totals in tiles with a carry (the
//     "spine"), (3) every block rescans its tile from its offset. The input is read twice.
//     A reduction stops after (2), its blocks totalling several tiles each.
//   * Device scan, single pass (decoupled look-back, `k_scan_onepass`; chosen by the plan):
//     after an init step that zeroes the per-tile status and the tile counter, a block takes
//     the next tile from the counter, loads and scans it, publishes its aggregate, and its
//     first warp looks back over a window of WARP_LANES earlier tiles at a time (the nearest
//     tile that has published its inclusive prefix ends the walk; the others' aggregates are
//     added), publishes its inclusive prefix and writes the tile. The input is read once.
//     Integer results equal the three-phase scan's. Float prefixes follow one fixed grouping
//     of the tiles' aggregates (groups of WARP_LANES tiles, each scanned by a fixed shuffle
//     tree, the groups' sums added one after another: `scan_lookback_grouped`), whichever
//     tiles a walk finds published, so float results are the same from run to run (another
//     order than the three-phase scan's spine, so other bits, each within the bound of any
//     summation order, |error| <= 2 k eps sum |x| for the k-th prefix).
//   * Compaction: the scan of the flags (nonzero = keep) gives each kept element its output
//     position; the spine's total is the count.
//   * Radix sort: LSD "onesweep", 8 bits per pass, stable. One upfront kernel reads the keys
//     once and counts the digits of every pass; then one kernel per pass: a block takes the
//     next tile from an atomic counter, ranks its keys by the digit (per warp, the lanes of
//     one digit found by ballots; the warps' counts scanned digit-major), publishes its digit
//     counts, sorts keys and values in shared memory, and adds the counts of earlier tiles by
//     decoupled look-back; each element goes to digit offset + earlier tiles' count + rank in
//     the tile (runs written coalesced). See k_sort_onesweep.
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
// An entry that asks for `min_blocks` resident blocks per multiprocessor (a register cap).
#define WP_PRIM_ENTRY_MIN(min_blocks) \
  extern "C" __global__ void __launch_bounds__(WP_PRIM_THREADS, min_blocks)
#define WP_PRIM_SHARED __shared__
#define WP_PRIM_SYNC() __syncthreads()
#define WP_PRIM_TID ((wp::i32)threadIdx.x)
#define WP_PRIM_BID ((wp::i64)blockIdx.x)
#define WP_PRIM_REGISTER(name)
#define WP_PRIM_ATOMIC_ADD(p, v) atomicAdd((p), (v))
// A look-back waits for a block that has started and will publish: keep polling.
#define WP_PRIM_LOOKBACK_WAIT() ((void)0)
// Orders a block's global writes (and reads) before and after it as every other block sees
// them: between a look-back value and its flag.
#define WP_PRIM_FENCE() __threadfence()
#define WP_PRIM_UNROLL _Pragma("unroll")
#define WP_PRIM_NO_UNROLL _Pragma("unroll 1")
#elif !defined(WP_PRIM_EMULATOR)
#error "wp_primitives.h on the host needs the block emulator (include tests/wp_prim_emu.h first)"
#endif

// The sort's onesweep kernel (see "Radix sort" below): 0 ranks a tile with two 4-bit counting
// passes, 1 with warp ballots, 2 with `__match_any_sync`. The runtime passes it for the sort
// module (`SortVariant` in warp-runtime/src/primitives/plan.rs); other modules have no sort.
#ifndef WP_PRIM_SORT_VARIANT
#define WP_PRIM_SORT_VARIANT 1
#endif
#ifndef WP_PRIM_SORT_MIN_BLOCKS
#define WP_PRIM_SORT_MIN_BLOCKS 1
#endif

namespace wp {
namespace prim {

constexpr i32 THREADS = WP_PRIM_THREADS;
constexpr i32 ITEMS = WP_PRIM_ITEMS;
constexpr i64 TILE = (i64)THREADS * ITEMS;

// A block of fewer than 32 threads is one partial warp (the host tests' small tiles); a
// larger one is whole warps, so that the sort's warp-level ranking never meets a partial warp.
static_assert(THREADS >= 16 && (THREADS < 32 ? (THREADS & (THREADS - 1)) == 0 : THREADS % 32 == 0),
              "the block size is 16 threads, or a multiple of 32");
static_assert(ITEMS >= 1, "at least one element per thread");

/// Lanes of a warp of the block (a block below 32 threads is one partial warp), the warps,
/// and the mask of a warp's lanes.
constexpr i32 WARP_LANES = THREADS < 32 ? THREADS : 32;
constexpr i32 WARPS = THREADS / WARP_LANES;
constexpr u32 WARP_MASK = THREADS < 32 ? (1u << THREADS) - 1u : 0xffffffffu;

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
    const launch_ctx_t rec = launch_ctx_make(fault, flag);
    i64 index[1] = {c};
    i64 shape[1] = {capacity + 1};
    raise_record(&rec, FAULT_OUT_OF_BOUNDS, (i32)count_arg, 1, index, shape);
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

/// The block's total of one value per thread, in thread 0 (other threads get their warp's
/// partial result, which they must not use): a shuffle tree in each warp (lane 0 gets the
/// warp's total), the warps' totals in `warp_totals` (WARPS values in shared memory), one
/// barrier, and thread 0 combines them in warp order. Every thread of the block must call it;
/// `warp_totals` must not be written again before the caller's next barrier.
template <typename T, typename Op>
WP_PRIM_FN T block_reduce(T v, T* warp_totals) {
  const i32 lane = WP_PRIM_TID % WARP_LANES;
  T x = v;
  // Lane l combines lane l + off's value (a lane past the warp's end gets its own back: those
  // lanes' results are garbage, but lane 0 reads only lanes that are in range at every step).
  WP_PRIM_UNROLL
  for (i32 off = WARP_LANES / 2; off > 0; off >>= 1) {
    x = Op::apply(x, __shfl_down_sync(WARP_MASK, x, off));
  }
  if (lane == 0) warp_totals[WP_PRIM_TID / WARP_LANES] = x;
  WP_PRIM_SYNC();
  if (WP_PRIM_TID == 0) {
    for (i32 w = 1; w < WARPS; ++w) x = Op::apply(x, warp_totals[w]);
  }
  return x;
}

/// Exclusive scan of one value per thread across the block, by warp shuffles and one
/// barrier: each warp scans its lanes (`__shfl_up_sync`), the last lane of each warp leaves
/// the warp's total in `warp_totals` (WARPS values in shared memory), and each thread
/// combines the totals of the warps before its own. Sets `*total` to the block's total in
/// thread 0 (only). Every thread of the block must call it; `warp_totals` must not be written
/// again before the caller's next barrier.
template <typename T, typename Op>
WP_PRIM_FN T block_scan_warps(T v, T* warp_totals, T* total) {
  const i32 lane = WP_PRIM_TID % WARP_LANES;
  const i32 w = WP_PRIM_TID / WARP_LANES;
  T x = v;
  WP_PRIM_UNROLL
  for (i32 off = 1; off < WARP_LANES; off <<= 1) {
    const T y = __shfl_up_sync(WARP_MASK, x, off);
    if (lane >= off) x = Op::apply(y, x);
  }
  // The lane below's inclusive result is this lane's exclusive one (no inverse needed: min
  // and max have none).
  T excl = __shfl_up_sync(WARP_MASK, x, 1);
  if (lane == 0) excl = Op::identity();
  if (lane == WARP_LANES - 1) warp_totals[w] = x;
  WP_PRIM_SYNC();
  T before = Op::identity();
  for (i32 i = 0; i < w; ++i) before = Op::apply(before, warp_totals[i]);
  if (WP_PRIM_TID == 0) {
    T all = before;
    for (i32 i = 0; i < WARPS; ++i) all = Op::apply(all, warp_totals[i]);
    *total = all;
  }
  return Op::apply(before, excl);
}

/// Elements of T per 16-byte vector load, and whether a thread's ITEMS elements of a tile are
/// whole vectors (then a full tile of a 16-byte aligned array is read by vector loads).
template <typename T>
struct vec_load {
  static constexpr i32 V = sizeof(T) <= 16 && 16 % sizeof(T) == 0 ? (i32)(16 / sizeof(T)) : 1;
  static constexpr bool OK = V > 1 && ITEMS % V == 0;
  struct alignas(16) vec_t {
    T v[V];
  };
};

/// Phase 1: the total of block b's tile of `load(i)` for i < n (the identity for a tile past
/// n), written to `partials[b]`. Loads are striped (element k * THREADS + t of the tile for
/// thread t): consecutive threads read consecutive elements, so every load is coalesced.
/// With `per` > 1, block b totals the `per` tiles from b * per (a reduction needs no
/// per-tile totals, and fewer, fuller blocks spend less on the block total). `aligned`, when
/// not null, is the array `load` reads, 16-byte aligned: its full tiles are then read by
/// 16-byte vector loads (vector k * THREADS + t of the tile for thread t: still coalesced,
/// a quarter of the load instructions for 4-byte T), where `vec_load<T>::OK`.
template <typename T, typename Op, typename Load>
WP_PRIM_FN void tile_total(Load load, i64 n, T* partials, i64 per = 1,
                           const T* aligned = nullptr) {
  WP_PRIM_SHARED T warp_totals[WARPS];
  const i64 b = WP_PRIM_BID;
  const i32 t = WP_PRIM_TID;
  T acc = Op::identity();
  for (i64 j = 0; j < per; ++j) {
    const i64 tb = (b * per + j) * TILE;
    if (tb >= n) break;
    // Two accumulators: half the dependent chain (their order is fixed: deterministic).
    T acc0 = Op::identity(), acc1 = Op::identity();
    bool done = false;
    if constexpr (vec_load<T>::OK) {
      if (aligned != nullptr && tb + TILE <= n) {
        typedef typename vec_load<T>::vec_t vec_t;
        const vec_t* tv = reinterpret_cast<const vec_t*>(aligned + tb);
        WP_PRIM_UNROLL
        for (i32 k = 0; k < ITEMS / vec_load<T>::V; ++k) {
          const vec_t x = tv[(i64)k * THREADS + t];
          WP_PRIM_UNROLL
          for (i32 e = 0; e + 1 < vec_load<T>::V; e += 2) {
            acc0 = Op::apply(acc0, x.v[e]);
            acc1 = Op::apply(acc1, x.v[e + 1]);
          }
        }
        done = true;
      }
    }
    if (!done) {
      const i64 base = tb + (i64)t;
      for (i32 k = 0; k + 1 < ITEMS; k += 2) {
        const i64 i = base + (i64)k * THREADS;
        if (i < n) acc0 = Op::apply(acc0, load(i));
        if (i + THREADS < n) acc1 = Op::apply(acc1, load(i + THREADS));
      }
      if (ITEMS % 2 == 1) {
        const i64 i = base + (i64)(ITEMS - 1) * THREADS;
        if (i < n) acc0 = Op::apply(acc0, load(i));
      }
    }
    acc = Op::apply(acc, Op::apply(acc0, acc1));
  }
  const T total = block_reduce<T, Op>(acc, warp_totals);
  if (t == 0) partials[b] = total;
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

/// A tile's element `i` in shared memory: a slot of padding after every 32 elements, so that
/// a warp's accesses fall in distinct banks (4-byte T) both striped (lane l element
/// k * THREADS + l) and per thread (lane l elements l * ITEMS + k, which unpadded would share
/// 32 / ITEMS banks); TILE_SLOTS slots hold a tile.
WP_PRIM_FN i64 slot(i64 i) { return i + (i >> 5); }
constexpr i64 TILE_SLOTS = TILE + TILE / 32 + 1;

/// Phase 3: block b rescans its tile from `prefixes[b]` (the exclusive scan of the tile
/// totals) and hands `emit(i, value)` the inclusive or exclusive result of each i < n. The
/// tile goes through shared memory so that global loads and `emit` calls are striped
/// (coalesced) while each thread scans ITEMS consecutive elements (`slot`: no bank
/// conflicts). Every load of the tile
/// happens before the first barrier and every `emit` after the last, so `emit` may overwrite
/// the input.
template <typename T, typename Op, typename Load, typename Emit>
WP_PRIM_FN void tile_scan(Load load, Emit emit, i64 n, const T* prefixes, bool inclusive) {
  WP_PRIM_SHARED T warp_totals[WARPS];
  WP_PRIM_SHARED T stile[TILE_SLOTS];
  const i64 b = WP_PRIM_BID;
  if (b * TILE >= n) return;  // the whole block leaves: no barrier is skipped by some only
  const i32 t = WP_PRIM_TID;
  const i64 tb = b * TILE;
  const i64 tn = n - tb < TILE ? n - tb : TILE;
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 li = t + (i64)k * THREADS;
    if (li < tn) stile[slot(li)] = load(tb + li);
  }
  WP_PRIM_SYNC();
  const i64 mine = (i64)t * ITEMS;
  T vals[ITEMS];
  T acc = Op::identity();
  for (i32 k = 0; k < ITEMS; ++k) {
    vals[k] = mine + k < tn ? stile[slot(mine + k)] : Op::identity();
    acc = Op::apply(acc, vals[k]);
  }
  T total = Op::identity();  // (the tile's total: not needed)
  const T excl = block_scan_warps<T, Op>(acc, warp_totals, &total);
  // Each thread rewrites only its own slots of `stile`, which only it has read.
  T run = Op::apply(prefixes[b], excl);
  for (i32 k = 0; k < ITEMS; ++k) {
    if (mine + k >= tn) break;
    if (inclusive) {
      run = Op::apply(run, vals[k]);
      stile[slot(mine + k)] = run;
    } else {
      stile[slot(mine + k)] = run;
      run = Op::apply(run, vals[k]);
    }
  }
  WP_PRIM_SYNC();
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 li = t + (i64)k * THREADS;
    if (li < tn) emit(tb + li, stile[slot(li)]);
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
/// bad count), 8 tiles per block (0 or 1: one).
template <typename T, typename Op>
WP_PRIM_FN void k_tile_total(const args_t& a) {
  const i64 n = resolve_count(ptr<const i32>(a, 1), int_arg(a, 2), ptr<fault_t>(a, 4),
                              ptr<u32>(a, 5), int_arg(a, 6), int_arg(a, 7) != 0);
  const i64 per = int_arg(a, 8) > 1 ? int_arg(a, 8) : 1;
  const T* in = ptr<const T>(a, 0);
  tile_total<T, Op>(load_array<T>{in}, n, ptr<T>(a, 3), per,
                    ((u64)in & 15u) == 0 ? in : nullptr);
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
// Single-pass scan (decoupled look-back)
// ------------------------------------------------------------------------------------------

/// A 64-bit word another block may be writing: read once, never cached in a register.
WP_PRIM_FN u64 load_status(const u64* p) { return *(const volatile u64*)p; }
WP_PRIM_FN void store_status(u64* p, u64 v) { *(volatile u64*)p = v; }

/// A tile's look-back status: 0 nothing published yet, SCAN_AGGREGATE its own total,
/// SCAN_INCLUSIVE the total of it and every tile before it.
constexpr u32 SCAN_AGGREGATE = 1;
constexpr u32 SCAN_INCLUSIVE = 2;

/// Host tests only: an integer scan's tile publishes its inclusive prefix only when its index
/// is a multiple of this (tile 0 always), a float scan's group (`scan_lookback_grouped`) only
/// when the group's is, so that look-backs, which in the emulator always find the tile or
/// group before inclusive, walk back over aggregates and across windows as they may on a GPU.
#ifndef WP_PRIM_SCAN_INCLUSIVE_EVERY
#define WP_PRIM_SCAN_INCLUSIVE_EVERY 1
#endif

/// The per-tile status of a single-pass scan of T. A 4-byte T is packed with its flag in one
/// 64-bit word, `(flag << 32) | bits`, written and read at once (as the sort's). A wider T
/// has its flag alone in the word (u64 words for both layouts: one init step zeroes them) and
/// its value in `values`: the aggregate at [tile], the inclusive prefix at [tiles + tile] (two
/// slots, so that a reader that saw the aggregate flag never reads an inclusive value written
/// since); the writer fences between the value and the flag, the reader between the flag and
/// the value.
template <typename T>
struct scan_status {
  u64* words;
  T* values;  // (wide T only)
  i64 tiles;

  static constexpr bool PACKED = sizeof(T) == 4;

  static WP_PRIM_FN u32 to_bits(T v) {
    if constexpr (num<T>::is_int) {
      return (u32)v;
    } else {
      return f32_to_bits((f32)v);
    }
  }
  static WP_PRIM_FN T from_bits(u32 b) {
    if constexpr (num<T>::is_int) {
      return (T)b;
    } else {
      return (T)f32_from_bits(b);
    }
  }

  WP_PRIM_FN void publish(i64 tile, u32 flag, T v) const {
    if constexpr (PACKED) {
      store_status(words + tile, ((u64)flag << 32) | to_bits(v));
    } else {
      *(volatile T*)(values + (flag == SCAN_INCLUSIVE ? tiles : 0) + tile) = v;
      WP_PRIM_FENCE();
      store_status(words + tile, (u64)flag);
    }
  }

  /// Waits until tile `k` (handed out before the caller's: its block has started) has
  /// published, and returns its flag and value.
  WP_PRIM_FN u32 wait(i64 k, T* v) const {
    u64 s = load_status(words + k);
    while (s == 0) {
      WP_PRIM_LOOKBACK_WAIT();
      s = load_status(words + k);
    }
    if constexpr (PACKED) {
      *v = from_bits((u32)s);
      return (u32)(s >> 32);
    } else {
      WP_PRIM_FENCE();
      const u32 flag = (u32)s;
      *v = *(const volatile T*)(values + (flag == SCAN_INCLUSIVE ? tiles : 0) + k);
      return flag;
    }
  }
};

/// The exclusive prefix of tile `tile` (> 0) for integers, whose sums do not depend on their
/// order: called by every lane of the block's first warp (the same result in each). The lanes
/// read a window of WARP_LANES tiles before it at once, lane l tile `end - 1 - l` (tiles before
/// 0 count as the identity, inclusive); the nearest tile of the window that has published its
/// inclusive prefix ends the walk, and the values of the tiles from there to the window's
/// nearest are combined by a shuffle tree (earlier tiles on the left); else the whole window's
/// aggregates are, and the walk goes on with the window before.
template <typename T, typename Op>
WP_PRIM_FN T scan_lookback_tree(const scan_status<T>& st, i64 tile) {
  const i32 lane = WP_PRIM_TID;
  T excl = Op::identity();
  for (i64 end = tile;; end -= WARP_LANES) {
    const i64 k = end - 1 - lane;
    T v = Op::identity();
    const u32 flag = k >= 0 ? st.wait(k, &v) : SCAN_INCLUSIVE;
    const u32 incl = __ballot_sync(WARP_MASK, flag == SCAN_INCLUSIVE);
    // The lanes up to the lowest inclusive one (all when there is none).
    const u32 upto = incl == 0 ? WARP_MASK : ((incl & (0u - incl)) << 1) - 1u;
    T x = ((upto >> lane) & 1u) ? v : Op::identity();
    WP_PRIM_UNROLL
    for (i32 off = WARP_LANES / 2; off > 0; off >>= 1) {
      x = Op::apply(__shfl_down_sync(WARP_MASK, x, off), x);
    }
    x = __shfl_sync(WARP_MASK, x, 0);
    excl = Op::apply(x, excl);
    if (incl != 0) return excl;
  }
}

/// A fixed-shape inclusive scan of one value per lane of the first warp (lane l: lanes 0..l
/// combined by `__shfl_up_sync` steps, always the same tree): the same bits wherever it runs.
template <typename T, typename Op>
WP_PRIM_FN T warp_scan_fixed(T x) {
  const i32 lane = WP_PRIM_TID;
  WP_PRIM_UNROLL
  for (i32 off = 1; off < WARP_LANES; off <<= 1) {
    const T y = __shfl_up_sync(WARP_MASK, x, off);
    if (lane >= off) x = Op::apply(y, x);
  }
  return x;
}

/// The exclusive prefix of group `group` (> 0) of the grouped float look-back (see
/// `scan_lookback_grouped`): G(group), the groups' sums S(0), ..., S(group - 1) added one after
/// another. The last tile of group h publishes G(h + 1) as its inclusive value; the walk reads
/// the last tiles of WARP_LANES groups at once (lane l: group `end - 1 - l`), back to the
/// window holding the nearest published G, and adds the sums of the groups after it in order,
/// each from its tiles' aggregates by `warp_scan_fixed` (every tile there has published: the
/// re-read does not wait). A group whose G has been published since counts as that G, the
/// value the adding reaches. Usually the group before has published: one read.
template <typename T, typename Op>
WP_PRIM_FN T scan_group_prefix(const scan_status<T>& st, i64 group) {
  const i32 lane = WP_PRIM_TID;
  i64 end = group;
  T v = Op::identity();
  u32 incl = 0;
  for (;; end -= WARP_LANES) {
    const i64 h = end - 1 - lane;
    v = Op::identity();
    const u32 flag = h >= 0 ? st.wait(h * WARP_LANES + (WARP_LANES - 1), &v) : SCAN_INCLUSIVE;
    incl = __ballot_sync(WARP_MASK, flag == SCAN_INCLUSIVE);
    if (incl != 0) break;
  }
  // The lowest inclusive lane: the nearest group with its G published (before group 0: the
  // identity, G(0)).
  const i32 from = __popc((incl & (0u - incl)) - 1u);
  T g = __shfl_sync(WARP_MASK, v, from);
  WP_PRIM_NO_UNROLL
  for (i64 h = end - from; h < group; ++h) {
    T x = Op::identity();
    const u32 flag = st.wait(h * WARP_LANES + lane, &x);
    const bool last_incl = __shfl_sync(WARP_MASK, flag, WARP_LANES - 1) == SCAN_INCLUSIVE;
    // A G(h + 1) published since is the value the adding reaches (it took the place of the
    // last tile's aggregate).
    const T published = __shfl_sync(WARP_MASK, x, WARP_LANES - 1);
    x = warp_scan_fixed<T, Op>(x);
    const T sum = __shfl_sync(WARP_MASK, x, WARP_LANES - 1);
    g = last_incl ? published : Op::apply(g, sum);
  }
  return g;
}

/// The exclusive prefix of tile `tile` for floats, the same bit for bit whatever the timing,
/// called by every lane of the block's first warp. Float sums depend on their order, and
/// which tiles have published when a look-back reads them depends on timing; so the prefixes
/// are defined by one grouping. Tiles fall in aligned groups of WARP_LANES. A tile's
/// exclusive prefix is G(g) + W, with W the `warp_scan_fixed` of its group's aggregates up to
/// the tile before it, and G(g) the groups' sums S added one after another (S: the same scan's
/// last lane over the whole group). Only a group's last tile publishes an inclusive value, and
/// it is G(g + 1) = G(g) + S(g); the other tiles publish only their aggregate. Every value is
/// then a fixed function of the aggregates, wherever a walk ends (`scan_group_prefix`). The
/// adding one after another is over groups, not tiles: the serial part of a walk is short.
/// Sets `*group_incl` to G(g) + S(g) (what a group's last tile publishes); `own` is the
/// tile's aggregate.
template <typename T, typename Op>
WP_PRIM_FN T scan_lookback_grouped(const scan_status<T>& st, i64 tile, T own, T* group_incl) {
  const i32 lane = WP_PRIM_TID;
  const i64 group = tile / WARP_LANES;
  const i64 first = group * WARP_LANES;
  const i32 pos = (i32)(tile - first);
  // This group's tiles before this one publish only their aggregates.
  T a = Op::identity();
  if (lane < pos) (void)st.wait(first + lane, &a);
  if (lane == pos) a = own;
  a = warp_scan_fixed<T, Op>(a);
  const T within = __shfl_sync(WARP_MASK, a, pos == 0 ? 0 : pos - 1);
  const T through = __shfl_sync(WARP_MASK, a, WARP_LANES - 1);
  const T g = group == 0 ? Op::identity() : scan_group_prefix<T, Op>(st, group);
  *group_incl = Op::apply(g, through);
  return pos == 0 ? g : Op::apply(g, within);
}

/// args: 0 count (const i32* or 0), 1 capacity, 2 status words (u64*, `tiles`), 3 number of
/// tiles, 4 tile counter (u32*), 5 fault, 6 fault flag, 7 count's argument index, 8 report.
/// Zeroes the status words (block b the words b * TILE ..) and, in block 0, the counter; and
/// reports a bad device count.
WP_PRIM_FN void k_scan_init(const args_t& a) {
  resolve_count(ptr<const i32>(a, 0), int_arg(a, 1), ptr<fault_t>(a, 5), ptr<u32>(a, 6),
                int_arg(a, 7), int_arg(a, 8) != 0);
  u64* words = ptr<u64>(a, 2);
  const i64 tiles = int_arg(a, 3);
  const i64 base = WP_PRIM_BID * TILE + (i64)WP_PRIM_TID;
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 i = base + (i64)k * THREADS;
    if (i < tiles) words[i] = 0;
  }
  if (WP_PRIM_BID == 0 && WP_PRIM_TID == 0) *ptr<u32>(a, 4) = 0;
}

/// Single-pass scan. args: 0 in (const T*), 1 out (T*, may be `in`), 2 count, 3 capacity,
/// 4 inclusive (0/1), 5 status words (u64*, `tiles`, zeroed), 6 values (T*, 2 * `tiles`; wide
/// T only, else 0), 7 tile counter (u32*, zeroed), 8 number of tiles.
///
/// A block takes the next tile from the counter (so every tile before it belongs to a block
/// that has started: waiting for them cannot deadlock), loads it striped through shared
/// memory (coalesced), scans it (each thread its ITEMS consecutive elements, then
/// `block_scan_warps`), publishes its aggregate (tile 0: its inclusive prefix), looks back
/// with its first warp (`scan_lookback`), publishes its inclusive prefix, and writes its
/// results striped. Every load of the tile happens before the first barrier and every store
/// after the last, so `out` may be `in`.
template <typename T, typename Op>
WP_PRIM_FN void k_scan_onepass(const args_t& a) {
  WP_PRIM_SHARED T stile[TILE_SLOTS];
  WP_PRIM_SHARED T warp_totals[WARPS];
  WP_PRIM_SHARED T prefix_sh;
  WP_PRIM_SHARED i64 tile_sh;
  const i64 n = resolve_count(ptr<const i32>(a, 2), int_arg(a, 3), nullptr, nullptr, 0, false);
  const T* in = ptr<const T>(a, 0);
  T* out = ptr<T>(a, 1);
  const bool inclusive = int_arg(a, 4) != 0;
  const scan_status<T> st{ptr<u64>(a, 5), ptr<T>(a, 6), int_arg(a, 8)};
  const i32 t = WP_PRIM_TID;
  if (t == 0) tile_sh = (i64)WP_PRIM_ATOMIC_ADD(ptr<u32>(a, 7), 1u);
  WP_PRIM_SYNC();
  const i64 tile = tile_sh;
  const i64 tb = tile * TILE;
  if (tb >= n) return;  // the whole block: tiles past n are nobody's predecessors
  const i64 tn = n - tb < TILE ? n - tb : TILE;
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 li = t + (i64)k * THREADS;
    if (li < tn) stile[slot(li)] = in[tb + li];
  }
  WP_PRIM_SYNC();
  const i64 mine = (i64)t * ITEMS;
  T vals[ITEMS];
  T acc = Op::identity();
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    vals[k] = mine + k < tn ? stile[slot(mine + k)] : Op::identity();
    acc = Op::apply(acc, vals[k]);
  }
  T total = Op::identity();  // (set in thread 0, which alone publishes it)
  const T excl = block_scan_warps<T, Op>(acc, warp_totals, &total);
  // Published as early as possible: later tiles wait for it. Integers: tile 0's is its
  // inclusive prefix too, and every tile publishes that after its look-back (the tree walk).
  // Floats: only a group's last tile publishes an inclusive value (`scan_lookback_grouped`).
  if (t == 0) {
    st.publish(tile, num<T>::is_int && tile == 0 ? SCAN_INCLUSIVE : SCAN_AGGREGATE, total);
    if (tile == 0) prefix_sh = Op::identity();
  }
  if constexpr (num<T>::is_int) {
    if (tile > 0 && t < WARP_LANES) {
      const T prefix = scan_lookback_tree<T, Op>(st, tile);
      if (t == 0) {
        if (tile % WP_PRIM_SCAN_INCLUSIVE_EVERY == 0) {
          st.publish(tile, SCAN_INCLUSIVE, Op::apply(prefix, total));
        }
        prefix_sh = prefix;
      }
    }
  } else {
    if (t < WARP_LANES) {
      T group_incl = Op::identity();
      const T own = __shfl_sync(WARP_MASK, total, 0);
      const T prefix = scan_lookback_grouped<T, Op>(st, tile, own, &group_incl);
      if (t == 0) {
        const i64 group = tile / WARP_LANES;
        if (tile % WARP_LANES == WARP_LANES - 1 && group % WP_PRIM_SCAN_INCLUSIVE_EVERY == 0) {
          st.publish(tile, SCAN_INCLUSIVE, group_incl);
        }
        if (tile > 0) prefix_sh = prefix;
      }
    }
  }
  WP_PRIM_SYNC();
  // Each thread rewrites only its own slots of `stile`, which only it has read.
  T run = Op::apply(prefix_sh, excl);
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    if (mine + k < tn) {
      if (inclusive) {
        run = Op::apply(run, vals[k]);
        stile[slot(mine + k)] = run;
      } else {
        stile[slot(mine + k)] = run;
        run = Op::apply(run, vals[k]);
      }
    }
  }
  WP_PRIM_SYNC();
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 li = t + (i64)k * THREADS;
    if (li < tn) out[tb + li] = stile[slot(li)];
  }
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

/// Bits of the key sorted per pass of the GPU sort (onesweep), and its digits.
constexpr i32 SORT_BITS = 8;
constexpr i32 SORT_RADIX = 1 << SORT_BITS;
/// At most this many passes (32-bit keys).
constexpr i32 SORT_MAX_PASSES = 4;
/// Blocks of the histogram kernel at most (each takes every so many tiles).
constexpr i32 SORT_HIST_BLOCKS = 512;
/// Look-back status words: (flag << 32) | count, flag 0 not yet published, 1 the tile's own
/// count (aggregate), 2 the count of this tile and every tile before it (inclusive).
constexpr u64 STATUS_AGGREGATE = 1ull << 32;
constexpr u64 STATUS_INCLUSIVE = 2ull << 32;

static_assert(TILE <= 65536, "a sort tile's local indices (and ranks) fit in 16 bits");

/// Decoupled look-back for digit `d` of tile `tile`: the counts of the tiles before it, added
/// from the nearest back until one has published its inclusive count (waiting for a tile
/// that has published nothing yet: it has started, the tile counter's order).
WP_PRIM_FN u32 lookback_exclusive(const u64* status, i64 tile, i32 d) {
  u32 excl = 0;
  for (i64 k = tile - 1; k >= 0; --k) {
    const u64* other = status + k * SORT_RADIX + d;
    u64 s = load_status(other);
    while ((s >> 32) == 0) {
      WP_PRIM_LOOKBACK_WAIT();
      s = load_status(other);
    }
    excl += (u32)s;
    if ((s >> 32) == (STATUS_INCLUSIVE >> 32)) break;
  }
  return excl;
}

/// The key's digit of a pass: `mask` (at most 255) of its ordered image shifted right.
template <typename K>
WP_PRIM_FN u32 sort_digit(u32 key, i32 shift, u32 mask) {
  return (radix_key<K>::bits(key) >> shift) & mask;
}

#if WP_PRIM_SORT_VARIANT == 0
// ---- Variant 0: the tile sorted by two stable 4-bit counting passes in shared memory ----

/// Bits of one counting pass of variant 0, and its digits.
constexpr i32 RADIX_BITS = 4;
constexpr i32 RADIX = 1 << RADIX_BITS;
static_assert((THREADS & (THREADS - 1)) == 0 &&
                  (SORT_RADIX % THREADS == 0 || THREADS % SORT_RADIX == 0),
              "variant 0: the block size is a power of two (threads and digits divide one "
              "another)");

/// One stable 4-bit counting pass over the tile held in registers (thread t holds the tile's
/// elements t * ITEMS + k, k < ITEMS, of which those below `tn` are real): ranks them by
/// `(digit >> sub) & 15` (`digit` of the pass) and writes key and index to their rank in
/// `skeys` / `sidx`. Thread t's elements come after those of threads < t with the same nibble
/// and keep their order, so the pass is stable. Synchronises; the registers may be read from
/// `skeys` (the shared arrays are written only after every thread has passed a barrier).
template <typename K>
WP_PRIM_FN void nibble_pass(const u32* kr, const u16* ir, i64 tn, i32 shift, u32 mask, i32 sub,
                            u32* skeys, u16* sidx, u32* counts, u32* sh) {
  const i32 t = WP_PRIM_TID;
  for (i32 d = 0; d < RADIX; ++d) counts[d * THREADS + t] = 0;
  for (i32 k = 0; k < ITEMS; ++k) {
    if ((i64)t * ITEMS + k < tn) {
      const u32 nib = (sort_digit<K>(kr[k], shift, mask) >> sub) & (RADIX - 1);
      counts[nib * THREADS + t] += 1;  // thread t's own column
    }
  }
  WP_PRIM_SYNC();
  // Digit-major order, RADIX consecutive entries per thread.
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
  for (i32 k = 0; k < ITEMS; ++k) {
    if ((i64)t * ITEMS + k < tn) {
      const u32 nib = (sort_digit<K>(kr[k], shift, mask) >> sub) & (RADIX - 1);
      const u32 pos = counts[nib * THREADS + t]++;
      skeys[pos] = kr[k];
      sidx[pos] = ir[k];
    }
  }
  WP_PRIM_SYNC();
}

#else
// ---- Variants 1 and 2: warp-level ranking of the 8-bit digit ----

/// Digits of the pass per thread in the per-digit steps (threads past SORT_RADIX have none).
constexpr i32 DIGITS_PER_THREAD = (SORT_RADIX + THREADS - 1) / THREADS;

/// The lanes of the caller's warp whose `d` (a digit of `bits` bits) equals the caller's.
WP_PRIM_FN u32 warp_peers(u32 d, i32 bits) {
#if WP_PRIM_SORT_VARIANT == 2
  (void)bits;
  return __match_any_sync(WARP_MASK, d);
#else
  // One ballot per bit: the lanes that agree with the caller on every bit.
  u32 peers = WARP_MASK;
WP_PRIM_UNROLL
  for (i32 b = 0; b < SORT_BITS; ++b) {
    if (b < bits) {
      const u32 bit = (d >> b) & 1u;
      const u32 set = __ballot_sync(WARP_MASK, bit);
      peers &= bit ? set : ~set;
    }
  }
  return peers;
#endif
}

#endif

/// args: 0 count, 1 capacity, 2 hist (u32*, SORT_MAX_PASSES * SORT_RADIX), 3 tile counters
/// (u32*, SORT_MAX_PASSES), 4 fault, 5 fault flag, 6 count's argument index, 7 report.
/// One block: zeroes the histograms and the tile counters (and reports a bad count).
WP_PRIM_FN void k_sort_init(const args_t& a) {
  resolve_count(ptr<const i32>(a, 0), int_arg(a, 1), ptr<fault_t>(a, 4), ptr<u32>(a, 5),
                int_arg(a, 6), int_arg(a, 7) != 0);
  u32* hist = ptr<u32>(a, 2);
  u32* counters = ptr<u32>(a, 3);
  for (i32 i = WP_PRIM_TID; i < SORT_MAX_PASSES * SORT_RADIX; i += THREADS) hist[i] = 0;
  if (WP_PRIM_TID < SORT_MAX_PASSES) counters[WP_PRIM_TID] = 0;
}

/// args: 0 keys (const u32*), 1 count, 2 capacity, 3 hist (u32*, zeroed), 4 passes, 5 key
/// bits, 6 status (u64*, passes * tiles * SORT_RADIX), 7 number of tiles, 8 number of blocks.
/// Block h takes tiles h, h + blocks, .. (at most SORT_HIST_BLOCKS blocks, so that large sorts
/// flush few per-block counts, and small ones still spread over the GPU): it zeroes their
/// look-back status words of every pass and counts the digits of every pass of their keys
/// (one read of the keys for all passes: each thread loads its ITEMS keys of a tile at once,
/// striped and coalesced, then counts them in shared memory); at the end one global atomic
/// add per digit it saw.
template <typename K>
WP_PRIM_FN void k_sort_upsweep(const args_t& a) {
  WP_PRIM_SHARED u32 counts[SORT_MAX_PASSES * SORT_RADIX];
  const i64 n = resolve_count(ptr<const i32>(a, 1), int_arg(a, 2), nullptr, nullptr, 0, false);
  const u32* keys = ptr<const u32>(a, 0);
  u32* hist = ptr<u32>(a, 3);
  const i32 passes = (i32)int_arg(a, 4);
  const i32 key_bits = (i32)int_arg(a, 5);
  u64* status = ptr<u64>(a, 6);
  const i64 tiles = int_arg(a, 7);
  const i64 blocks = int_arg(a, 8);
  const i32 t = WP_PRIM_TID;
  for (i32 i = t; i < SORT_MAX_PASSES * SORT_RADIX; i += THREADS) counts[i] = 0;
  for (i64 tile = WP_PRIM_BID; tile < tiles; tile += blocks) {
    for (i32 p = 0; p < passes; ++p) {
      u64* s = status + (p * tiles + tile) * SORT_RADIX;
      for (i32 i = t; i < SORT_RADIX; i += THREADS) s[i] = 0;
    }
  }
  WP_PRIM_SYNC();
  for (i64 tile = WP_PRIM_BID; tile * TILE < n; tile += blocks) {
    const i64 base = tile * TILE + t;
    u32 kr[ITEMS];
    WP_PRIM_UNROLL
    for (i32 k = 0; k < ITEMS; ++k) {
      const i64 i = base + (i64)k * THREADS;
      kr[k] = i < n ? keys[i] : 0u;
    }
    // Runs of one digit among a thread's keys count with one atomic: keys in order (a grid's
    // coherent points) have few digits of the high passes per thread, and the lanes of a warp
    // that add to one counter at once are served one after another.
    const i64 left = n - base;  // this thread's keys of the tile: k < valid
    const i32 valid = left <= 0                       ? 0
                      : left >= (i64)ITEMS * THREADS ? ITEMS
                                                      : (i32)((left + THREADS - 1) / THREADS);
    for (i32 p = 0; p < passes; ++p) {
      const i32 shift = p * SORT_BITS;
      const i32 width = key_bits - shift < SORT_BITS ? key_bits - shift : SORT_BITS;
      const u32 m = (1u << width) - 1;
      u32* c = counts + p * SORT_RADIX;
      u32 run_d = (radix_key<K>::bits(kr[0]) >> shift) & m;
      u32 run_n = 0;
      WP_PRIM_UNROLL
      for (i32 k = 0; k < ITEMS; ++k) {
        if (k >= valid) break;
        const u32 d = (radix_key<K>::bits(kr[k]) >> shift) & m;
        if (d != run_d) {
          WP_PRIM_ATOMIC_ADD(&c[run_d], run_n);
          run_d = d;
          run_n = 0;
        }
        ++run_n;
      }
      if (run_n != 0) WP_PRIM_ATOMIC_ADD(&c[run_d], run_n);
    }
  }
  WP_PRIM_SYNC();
  for (i32 i = t; i < passes * SORT_RADIX; i += THREADS) {
    if (counts[i] != 0) WP_PRIM_ATOMIC_ADD(&hist[i], counts[i]);
  }
}

#if WP_PRIM_SORT_VARIANT == 0
/// One pass of the onesweep sort. args: 0 keys in (const u32*), 1 values in (const u32*),
/// 2 keys out (u32*), 3 values out (u32*), 4 count, 5 capacity, 6 shift, 7 mask (at most
/// 255), 8 the pass's histogram (const u32*, SORT_RADIX digit counts of all keys), 9 the
/// pass's status words (u64*, tiles * SORT_RADIX, zeroed), 10 the pass's tile counter
/// (u32*, zeroed), 11 number of tiles.
///
/// A block takes the next tile (an atomic counter, so every tile before it belongs to a block
/// that has started: waiting for them cannot deadlock), sorts it by the digit in shared memory
/// (two stable 4-bit passes), publishes its digit counts, adds up those of the tiles before
/// it (decoupled look-back: a tile that has published its inclusive count ends the walk), and
/// writes each element to digit offset + tiles before + rank in the tile. Runs of one digit
/// are consecutive in the output, so writes are coalesced by runs.
template <typename K>
WP_PRIM_FN void k_sort_onesweep(const args_t& a) {
  WP_PRIM_SHARED u32 counts[RADIX * THREADS];
  WP_PRIM_SHARED u32 sh[2 * THREADS];
  WP_PRIM_SHARED u32 skeys[TILE];
  WP_PRIM_SHARED u16 sidx[TILE];
  WP_PRIM_SHARED u32 dstart[SORT_RADIX];
  WP_PRIM_SHARED u32 dend[SORT_RADIX];
  WP_PRIM_SHARED u32 dbase[SORT_RADIX];
  WP_PRIM_SHARED i64 tile_sh;
  const i64 n = resolve_count(ptr<const i32>(a, 4), int_arg(a, 5), nullptr, nullptr, 0, false);
  const u32* keys = ptr<const u32>(a, 0);
  const u32* values = ptr<const u32>(a, 1);
  u32* keys_out = ptr<u32>(a, 2);
  u32* values_out = ptr<u32>(a, 3);
  const i32 shift = (i32)int_arg(a, 6);
  const u32 mask = (u32)int_arg(a, 7);
  const u32* hist = ptr<const u32>(a, 8);
  u64* status = ptr<u64>(a, 9);
  u32* counter = ptr<u32>(a, 10);
  const i32 t = WP_PRIM_TID;
  if (t == 0) tile_sh = (i64)WP_PRIM_ATOMIC_ADD(counter, 1u);
  WP_PRIM_SYNC();
  const i64 tile = tile_sh;
  const i64 tb = tile * TILE;
  if (tb >= n) return;  // the whole block: tiles past n are nobody's predecessors
  const i64 tn = n - tb < TILE ? n - tb : TILE;
  // The digits' global offsets: the exclusive scan of the pass's histogram.
  {
    constexpr i32 PER = SORT_RADIX >= THREADS ? SORT_RADIX / THREADS : 1;
    u32 v[PER];
    u32 sum = 0;
    for (i32 k = 0; k < PER; ++k) {
      const i32 d = t * PER + k;
      v[k] = d < SORT_RADIX ? hist[d] : 0;
      sum += v[k];
    }
    u32 total;
    u32 run = block_exclusive_scan<u32, op_sum<u32>>(sum, sh, &total);
    for (i32 k = 0; k < PER; ++k) {
      const i32 d = t * PER + k;
      if (d < SORT_RADIX) dbase[d] = run;
      run += v[k];
    }
  }
  // Coalesced load of the keys, then each thread takes ITEMS consecutive ones.
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 i = t + (i64)k * THREADS;
    if (i < tn) skeys[i] = keys[tb + i];
  }
  for (i32 d = t; d < SORT_RADIX; d += THREADS) {
    dstart[d] = 0;
    dend[d] = 0;
  }
  WP_PRIM_SYNC();
  u32 kr[ITEMS];
  u16 ir[ITEMS];
  for (i32 k = 0; k < ITEMS; ++k) {
    const i64 li = (i64)t * ITEMS + k;
    kr[k] = li < tn ? skeys[li] : 0u;
    ir[k] = (u16)li;
  }
  // Every thread holds its keys: the shared tile may be rewritten after nibble_pass's barrier.
  nibble_pass<K>(kr, ir, tn, shift, mask, 0, skeys, sidx, counts, sh);
  if (mask > (u32)(RADIX - 1)) {
    for (i32 k = 0; k < ITEMS; ++k) {
      const i64 li = (i64)t * ITEMS + k;
      kr[k] = li < tn ? skeys[li] : 0u;
      ir[k] = li < tn ? sidx[li] : (u16)0;
    }
    nibble_pass<K>(kr, ir, tn, shift, mask, RADIX_BITS, skeys, sidx, counts, sh);
  }
  // The tile is sorted by digit: find where each digit's run starts and ends.
  for (i64 i = t; i < tn; i += THREADS) {
    const u32 d = sort_digit<K>(skeys[i], shift, mask);
    if (i == 0 || sort_digit<K>(skeys[i - 1], shift, mask) != d) dstart[d] = (u32)i;
    if (i == tn - 1 || sort_digit<K>(skeys[i + 1], shift, mask) != d) dend[d] = (u32)(i + 1);
  }
  WP_PRIM_SYNC();
  // Decoupled look-back, one digit per thread: publish this tile's count, add the counts of
  // the tiles before until one has published its inclusive count, publish the inclusive.
  for (i32 d = t; d < SORT_RADIX; d += THREADS) {
    const u32 cnt = dend[d] - dstart[d];
    u64* mine = status + tile * SORT_RADIX + d;
    if (tile == 0) {
      store_status(mine, STATUS_INCLUSIVE | cnt);
      dbase[d] = dbase[d] - dstart[d];
      continue;
    }
    store_status(mine, STATUS_AGGREGATE | cnt);
    const u32 excl = lookback_exclusive(status, tile, d);
    store_status(mine, STATUS_INCLUSIVE | (u32)(excl + cnt));
    dbase[d] = dbase[d] + excl - dstart[d];
  }
  WP_PRIM_SYNC();
  // Scatter in tile order: consecutive threads, consecutive positions of one digit's run.
  for (i64 i = t; i < tn; i += THREADS) {
    const u32 key = skeys[i];
    const u32 dst = dbase[sort_digit<K>(key, shift, mask)] + (u32)i;
    keys_out[dst] = key;
    values_out[dst] = values[tb + sidx[i]];
  }
}

#else
/// One pass of the onesweep sort. args: 0 keys in (const u32*), 1 values in (const u32*),
/// 2 keys out (u32*), 3 values out (u32*), 4 count, 5 capacity, 6 shift, 7 mask (at most
/// 255), 8 the pass's histogram (const u32*, SORT_RADIX digit counts of all keys), 9 the
/// pass's status words (u64*, tiles * SORT_RADIX, zeroed), 10 the pass's tile counter
/// (u32*, zeroed), 11 number of tiles.
///
/// A block takes the next tile from an atomic counter (so every tile before it belongs to a
/// block that has started: waiting for them cannot deadlock) and:
///   1. loads the tile's pairs into registers, warp-striped: warp w holds the tile's elements
///      w * WARP_LANES * ITEMS .., lane l its element k * WARP_LANES + l of them (every load
///      coalesced, and the order of (warp, item, lane) is the tile's order);
///   2. ranks each key among its warp's keys of the same digit, item after item: the lanes
///      of one digit find one another with ballots (variant 1) or `__match_any_sync`
///      (variant 2), the highest of them adds their number to the warp's count of the
///      digit, and each takes the old count plus the number of its peers on lower lanes;
///   3. scans the warps' counts digit-major (the tile's start of each digit, and each warp's
///      start within it) and publishes the tile's digit counts for the look-back;
///   4. writes keys and values to shared memory at their rank, so that the tile is sorted
///      by digit and stable (earlier warps, items and lanes first);
///   5. adds up the counts of the tiles before it, one thread per digit (decoupled
///      look-back: a tile that has published its inclusive count ends the walk; tile 0's
///      inclusive counts start from the digits' offsets, the scan of the pass's histogram);
///   6. writes each element to its digit's offset + earlier tiles' count + its rank, threads
///      striped over the sorted tile, so that runs of one digit are written coalesced.
/// The elements of a partial tile's tail are ranked as the largest digit (`mask`): they
/// come after every real element, and are neither counted nor written.
template <typename K>
WP_PRIM_FN void k_sort_onesweep(const args_t& a) {
  // The warps' digit counts (steps 2-4) have their own memory where it fits in the 48 KiB of
  // static shared memory beside the sorted tile; else they share the sorted keys' (steps
  // 4-6), and a barrier more separates their last read from the keys' first write.
  constexpr i32 COUNTS = WARPS * SORT_RADIX;
#ifdef WP_PRIM_SORT_SHARE_COUNTS  // the host tests' way to run the shared layout on small tiles
  constexpr bool SHARE = WP_PRIM_SORT_SHARE_COUNTS != 0;
#else
  constexpr bool SHARE = (2 * TILE + COUNTS + SORT_RADIX) * 4 + (WARPS + 1) * 8 > 48 * 1024;
#endif
  WP_PRIM_SHARED u32 skeys[SHARE && COUNTS > TILE ? COUNTS : TILE];
  WP_PRIM_SHARED u32 svals[TILE];
  WP_PRIM_SHARED u32 own_counts[SHARE ? 1 : COUNTS];
  WP_PRIM_SHARED u32 gbase[SORT_RADIX];
  WP_PRIM_SHARED u64 warp_totals[WARPS];
  WP_PRIM_SHARED i64 tile_sh;
  u32* counts = SHARE ? skeys : own_counts;
  const i64 n = resolve_count(ptr<const i32>(a, 4), int_arg(a, 5), nullptr, nullptr, 0, false);
  const i32 shift = (i32)int_arg(a, 6);
  const u32 mask = (u32)int_arg(a, 7);
  const u32* hist = ptr<const u32>(a, 8);
  u64* status = ptr<u64>(a, 9);
  u32* counter = ptr<u32>(a, 10);
  const i32 t = WP_PRIM_TID;
  const i32 lane = t % WARP_LANES;
  const i32 w = t / WARP_LANES;
  if (t == 0) tile_sh = (i64)WP_PRIM_ATOMIC_ADD(counter, 1u);
  for (i32 i = t; i < COUNTS; i += THREADS) counts[i] = 0;
  WP_PRIM_SYNC();
  const i64 tile = tile_sh;
  const i64 tb = tile * TILE;
  if (tb >= n) return;  // the whole block: tiles past n are nobody's predecessors
  // Elements of this tile (TILE <= 65536: local indices are 32-bit).
  const i32 tn = (i32)(n - tb < TILE ? n - tb : TILE);
  const u32* keys = ptr<const u32>(a, 0) + tb;
  const u32* values = ptr<const u32>(a, 1) + tb;
  u32* keys_out = ptr<u32>(a, 2);
  u32* values_out = ptr<u32>(a, 3);
  u64* my_status = status + tile * SORT_RADIX;

  // 1. Warp-striped loads of the keys.
  const i32 wb = w * WARP_LANES * ITEMS + lane;
  u32 kr[ITEMS];
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    const i32 li = wb + k * WARP_LANES;
    kr[k] = li < tn ? keys[li] : 0u;
  }

  // 2. Ranks within the warp.
  const i32 bits = 32 - __clz((i32)mask);
  const u32 lower = (1u << lane) - 1u;
  u32* wcounts = counts + w * SORT_RADIX;
  // The digit (high 16 bits) and the rank among the warp's keys of that digit (low 16 bits):
  // one register per element between the steps.
  u32 rank[ITEMS];
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    const u32 d = wb + k * WARP_LANES < tn ? sort_digit<K>(kr[k], shift, mask) : mask;
    const u32 peers = warp_peers(d, bits);
    const i32 leader = 31 - __clz((i32)peers);
    u32 before = 0;
    // Only the leader of each digit's lanes touches the warp's count of that digit; the
    // atomic orders it after the previous item's update by another lane.
    if (lane == leader) before = WP_PRIM_ATOMIC_ADD(&wcounts[d], (u32)__popc(peers));
    before = __shfl_sync(WARP_MASK, before, leader);
    rank[k] = (d << 16) | (before + (u32)__popc(peers & lower));
  }
  WP_PRIM_SYNC();

  // 3. Digit-major scan: each thread sums its digits' counts over the warps; tile 0 also
  // scans the pass's histogram (in the high word: both sums fit 32 bits).
  u32 cnt[DIGITS_PER_THREAD];
  u64 hi[DIGITS_PER_THREAD];
  u64 sum = 0;
  WP_PRIM_UNROLL
  for (i32 j = 0; j < DIGITS_PER_THREAD; ++j) {
    const i32 d = t * DIGITS_PER_THREAD + j;
    u32 c = 0;
    hi[j] = 0;
    if (d < SORT_RADIX) {
      // (A partial tile's padding counts as digit `mask`: only the last tile has padding,
      // and no tile reads its counts.)
      for (i32 v = 0; v < WARPS; ++v) c += counts[v * SORT_RADIX + d];
      if (tile == 0) hi[j] = (u64)hist[d] << 32;
    }
    cnt[j] = c;
    sum += hi[j] + c;
  }
  u64 tile_all = 0;  // (the tile's total: not needed)
  u64 run = block_scan_warps<u64, op_sum<u64>>(sum, warp_totals, &tile_all);
  u32 dstart[DIGITS_PER_THREAD];
  WP_PRIM_UNROLL
  for (i32 j = 0; j < DIGITS_PER_THREAD; ++j) {
    const i32 d = t * DIGITS_PER_THREAD + j;
    dstart[j] = (u32)run;
    if (d < SORT_RADIX) {
      // Published as early as possible: later tiles wait for it.
      const u32 goff = (u32)(run >> 32);
      store_status(my_status + d, tile == 0 ? STATUS_INCLUSIVE | (u32)(goff + cnt[j])
                                            : STATUS_AGGREGATE | cnt[j]);
      if (tile == 0) gbase[d] = goff - dstart[j];
      run += hi[j] + cnt[j];
      // Each warp's start within the digit (exclusive over warps), from the digit's start.
      u32 at = dstart[j];
      for (i32 v = 0; v < WARPS; ++v) {
        u32* c = &counts[v * SORT_RADIX + d];
        const u32 mine = *c;
        *c = at;
        at += mine;
      }
    }
  }
  WP_PRIM_SYNC();

  // 4. The tile sorted by digit in shared memory (where the counts share the keys' memory,
  // they are read before the barrier, and the sorted tile written after it).
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    rank[k] = (rank[k] & 0xffffu) + counts[w * SORT_RADIX + (rank[k] >> 16)];
  }
  if (SHARE) WP_PRIM_SYNC();
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    const i32 li = wb + k * WARP_LANES;
    if (li < tn) {
      skeys[rank[k]] = kr[k];
      svals[rank[k]] = values[li];
    }
  }

  // 5. Decoupled look-back, one digit per thread (tile 0 has its offsets from step 3).
  if (tile > 0) {
    WP_PRIM_UNROLL
    for (i32 j = 0; j < DIGITS_PER_THREAD; ++j) {
      const i32 d = t * DIGITS_PER_THREAD + j;
      if (d >= SORT_RADIX) break;
      const u32 excl = lookback_exclusive(status, tile, d);
      store_status(my_status + d, STATUS_INCLUSIVE | (u32)(excl + cnt[j]));
      gbase[d] = excl - dstart[j];
    }
  }
  WP_PRIM_SYNC();

  // 6. Scatter in tile order: consecutive threads, consecutive positions of a digit's run.
  WP_PRIM_UNROLL
  for (i32 k = 0; k < ITEMS; ++k) {
    const i32 i = t + k * THREADS;
    if (i < tn) {
      const u32 key = skeys[i];
      const u32 dst = gbase[sort_digit<K>(key, shift, mask)] + (u32)i;
      keys_out[dst] = key;
      values_out[dst] = svals[i];
    }
  }
}
#endif

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
#define WP_PRIM_DEFINE_MIN(name, body, min_blocks)                 \
  WP_PRIM_ENTRY_MIN(min_blocks) name(wp::prim::args_t a) { body(a); } \
  WP_PRIM_REGISTER(name)

/// Scan and reductions of T: `wp_prim_total_{sum,min,max}_T`, `wp_prim_spine_{sum,min,max}_T`,
/// `wp_prim_scan_down_T` (the three-phase scan), `wp_prim_scan_init` and
/// `wp_prim_scan_onepass_T` (the single-pass scan).
#define WP_PRIM_SCAN_MODULE(T)                                                       \
  WP_PRIM_DEFINE(wp_prim_total_sum_##T, (wp::prim::k_tile_total<wp::T, wp::prim::op_sum<wp::T>>)) \
  WP_PRIM_DEFINE(wp_prim_total_min_##T, (wp::prim::k_tile_total<wp::T, wp::prim::op_min<wp::T>>)) \
  WP_PRIM_DEFINE(wp_prim_total_max_##T, (wp::prim::k_tile_total<wp::T, wp::prim::op_max<wp::T>>)) \
  WP_PRIM_DEFINE(wp_prim_spine_sum_##T, (wp::prim::k_spine<wp::T, wp::prim::op_sum<wp::T>>))      \
  WP_PRIM_DEFINE(wp_prim_spine_min_##T, (wp::prim::k_spine<wp::T, wp::prim::op_min<wp::T>>))      \
  WP_PRIM_DEFINE(wp_prim_spine_max_##T, (wp::prim::k_spine<wp::T, wp::prim::op_max<wp::T>>))      \
  WP_PRIM_DEFINE(wp_prim_scan_down_##T, (wp::prim::k_scan_down<wp::T>))                \
  WP_PRIM_DEFINE(wp_prim_scan_init, wp::prim::k_scan_init)                              \
  WP_PRIM_DEFINE(wp_prim_scan_onepass_##T, (wp::prim::k_scan_onepass<wp::T, wp::prim::op_sum<wp::T>>))

/// Radix sort with keys K (u32, i32 or f32): `wp_prim_sort_upsweep_K`,
/// `wp_prim_sort_onesweep_K`, plus what every sort needs: `wp_prim_sort_init` and
/// `wp_prim_copy_pairs`.
#define WP_PRIM_SORT_MODULE(K)                                                    \
  WP_PRIM_DEFINE(wp_prim_sort_init, wp::prim::k_sort_init)                        \
  WP_PRIM_DEFINE(wp_prim_sort_upsweep_##K, (wp::prim::k_sort_upsweep<wp::K>))     \
  WP_PRIM_DEFINE_MIN(wp_prim_sort_onesweep_##K, (wp::prim::k_sort_onesweep<wp::K>),   \
                     WP_PRIM_SORT_MIN_BLOCKS)                                      \
  WP_PRIM_DEFINE(wp_prim_copy_pairs, wp::prim::k_copy_pairs)

/// Compaction of elements of `W` words of type `Word` (u8, u16, u32 or u64):
/// `wp_prim_compact_count`, `wp_prim_compact_spine`, `wp_prim_compact_down`.
#define WP_PRIM_COMPACT_MODULE(Word, W)                                                   \
  WP_PRIM_DEFINE(wp_prim_compact_count, wp::prim::k_compact_count)                         \
  WP_PRIM_DEFINE(wp_prim_compact_spine, (wp::prim::k_spine<wp::i32, wp::prim::op_sum<wp::i32>>)) \
  WP_PRIM_DEFINE(wp_prim_compact_down, (wp::prim::k_compact_down<wp::prim::blob<wp::Word, W>>))

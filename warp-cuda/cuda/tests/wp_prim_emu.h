// wp_prim_emu.h: a CUDA block emulator for the host, so that the kernels of wp_primitives.h
// compile with g++ and run on the CPU (tests/cuda_primitives_host.rs).
//
// Include it before wp_primitives.h. Each CUDA thread of a block is a fiber (ucontext) with
// its own stack; the blocks of a launch run one after another, on the calling thread:
//   * `__syncthreads` switches back to the scheduler. When every thread of the block has
//     reached it, the next phase starts; when some threads have finished the kernel while
//     others wait at a barrier, that is a barrier divergence (undefined behaviour on a GPU)
//     and the emulator aborts, naming the block;
//   * between two barriers the threads run one at a time, in an order shuffled anew for every
//     phase (a fixed seed, so runs repeat), so that a kernel that read what another thread
//     writes in the same phase would see it sometimes before and sometimes after the write;
//   * `__shared__` is `static` storage of the kernel function: shared by the threads of the
//     block running now, and reused by the next block, as on a GPU (every kernel writes its
//     shared memory before reading it);
//   * blocks never run concurrently, so a kernel that waited for another block would hang:
//     the primitives never do.
//   * `atomicAdd` is a plain read-modify-write: threads never run at the same time, so it is
//     exact (and returns the old value, as on a GPU);
//   * a decoupled look-back that finds a predecessor's status unpublished aborts: blocks run
//     in order (tile counters hand out tiles in launch order), so every tile before has been
//     finished and an unpublished status is a bug that would hang a GPU. `WP_PRIM_FENCE()`
//     (`__threadfence` on a GPU) is nothing here.
//   * for the tile library (wp_tile.h, tests/cuda_tile_host.rs) and its linear algebra
//     (wp_tile_linalg.h): `threadIdx` (x only), `__syncthreads()`, and the warp-synchronous
//     operations `__syncwarp(mask)`, `__shfl_sync(mask, v, src)` and
//     `__shfl_down_sync(mask, v, delta)`. Warp w is threads 32 w .. 32 w + 31 (fewer in a
//     partial last warp). `__syncwarp` is a barrier among the lanes of `mask` that exist: a lane
//     that reaches it waits until every one of them has, while the block's other warps run on
//     (a warp is not a block: its lanes are released without the rest of the block, and run
//     again in a shuffled order, so shared memory written by one lane and read by another with
//     no `__syncwarp` between them is seen sometimes before and sometimes after the write). A
//     shuffle is an exchange made of two such barriers (every lane writes its value, the lanes
//     wait, each reads its source's, they wait). A caller outside its mask, a source lane
//     outside the mask or the block (for `__shfl_sync`; `__shfl_down_sync` past the warp's end
//     gives the caller's own value, as CUDA), a lane of the mask that has left the kernel, and
//     lanes of one mask waiting at different barriers (a `__syncwarp` against a
//     `__syncthreads`: a deadlock on a GPU) abort, naming the block.
//   * for the radix sort's warp-level ranking, the primitives' block totals and scans and the
//     single-pass scan's look-back window (with the shuffles above): `__ballot_sync(mask, pred)`,
//     `__match_any_sync(mask, v)` and `__shfl_up_sync(mask, v, delta)`, exchanges like the
//     shuffles, which also abort when their mask names a lane past the block's end or (for
//     `__shfl_up_sync`) reads a lane outside the mask; and `__popc`, `__clz`. Every lane of a
//     warp collective (a shuffle, ballot or match, and a `__syncwarp`) records which one it is
//     in, and one that finds a lane of its mask in another aborts (undefined on a GPU).
//   * `block_barriers` counts the `__syncthreads` phases released since the program started
//     (the linear-algebra test checks how many barriers an operation costs).
// Not emulated: memory ordering between blocks, and interleavings inside a phase (a lane runs
// from one barrier to the next without a switch).
#pragma once

#define WP_PRIM_EMULATOR 1

#include <ucontext.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <string>
#include <vector>

namespace wp_emu {

/// The running thread's index and block (set by the scheduler before each switch).
inline int tid = 0;
inline long long bid = 0;
/// `__syncthreads` phases released so far (every block of every launch).
inline long long block_barriers = 0;

/// A fiber runs, waits at `__syncthreads`, waits at `__syncwarp(mask)`, or has finished.
enum class state { running, waiting, at_warp, done };

struct fiber {
  ucontext_t ctx;
  std::vector<char> stack;
  state st = state::running;
  /// The mask of the `__syncwarp` it waits at (`at_warp`).
  unsigned mask = 0;
};

struct scheduler {
  ucontext_t main;
  std::vector<fiber> fibers;
  void (*body)(const void*) = nullptr;
  const void* args = nullptr;
  unsigned long long rng = 0x9e3779b97f4a7c15ull;
};

inline scheduler& sched() {
  static scheduler s;
  return s;
}

/// `__syncthreads`: back to the scheduler until every thread of the block is here.
inline void sync() {
  scheduler& s = sched();
  s.fibers[tid].st = state::waiting;
  swapcontext(&s.fibers[tid].ctx, &s.main);
}

[[noreturn]] inline void warp_fail(const char* what, unsigned mask) {
  std::fprintf(stderr, "wp_prim_emu: block %lld, thread %d (lane %d), mask %08x: %s\n", bid, tid,
               tid % 32, mask, what);
  std::abort();
}

/// `__syncwarp(mask)`: back to the scheduler until every existing lane of `mask` in the
/// caller's warp is here (see the top).
inline void warp_sync(unsigned mask) {
  scheduler& s = sched();
  if (!((mask >> (tid % 32)) & 1u)) warp_fail("__syncwarp or a shuffle outside its own mask", mask);
  s.fibers[tid].st = state::at_warp;
  s.fibers[tid].mask = mask;
  swapcontext(&s.fibers[tid].ctx, &s.main);
}

/// Releases every warp group whose lanes all wait at a `__syncwarp` of the same mask; aborts
/// when a lane of a waiting group has left the kernel or waits with another mask. Whether any
/// was released.
inline bool release_warps() {
  scheduler& s = sched();
  const int threads = (int)s.fibers.size();
  bool released = false;
  for (int t = 0; t < threads; ++t) {
    if (s.fibers[t].st != state::at_warp) continue;
    const unsigned mask = s.fibers[t].mask;
    const int base = t - t % 32;
    bool complete = true;
    for (int l = 0; l < 32 && base + l < threads; ++l) {
      if (!((mask >> l) & 1u)) continue;
      const fiber& f = s.fibers[base + l];
      if (f.st == state::done) {
        tid = t;
        warp_fail("a lane of the mask has left the kernel", mask);
      }
      if (f.st == state::at_warp && f.mask != mask) {
        tid = t;
        warp_fail("lanes of one warp wait at __syncwarp with different masks", mask);
      }
      complete = complete && f.st == state::at_warp;
    }
    if (!complete) continue;
    for (int l = 0; l < 32 && base + l < threads; ++l)
      if ((mask >> l) & 1u) s.fibers[base + l].st = state::running;
    released = true;
  }
  return released;
}

inline void fiber_entry() {
  scheduler& s = sched();
  s.body(s.args);
  s.fibers[tid].st = state::done;
  // Returning resumes `uc_link`, the scheduler.
}

/// Makes `f` start the kernel at its next switch. Out of line: `getcontext` returns twice,
/// which would make the compiler distrust the scheduler's locals (-Wclobbered).
__attribute__((noinline)) inline void start_fiber(fiber& f) {
  f.stack.resize(256 * 1024);
  f.st = state::running;
  getcontext(&f.ctx);
  f.ctx.uc_stack.ss_sp = f.stack.data();
  f.ctx.uc_stack.ss_size = f.stack.size();
  f.ctx.uc_link = &sched().main;
  makecontext(&f.ctx, fiber_entry, 0);
}

/// Entry points by name (filled by WP_PRIM_REGISTER at static initialisation).
inline std::map<std::string, void*>& registry() {
  static std::map<std::string, void*> r;
  return r;
}

struct registrar {
  registrar(const char* name, void* fn) { registry()[name] = fn; }
};

template <typename Args>
struct call {
  static void run(const void* p) {
    const call* c = static_cast<const call*>(p);
    c->fn(*c->args);
  }
  void (*fn)(Args);
  const Args* args;
};

/// Runs `blocks` blocks of `threads` threads of `fn(args)`.
template <typename Args>
void launch(void (*fn)(Args), long long blocks, int threads, const Args& args) {
  scheduler& s = sched();
  const call<Args> c{fn, &args};
  s.body = &call<Args>::run;
  // The scheduler keeps the address of `c` only while this launch runs (every fiber finishes
  // before it returns); newer g++ flags the store anyway (-Wdangling-pointer).
#if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 12
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wdangling-pointer"
#endif
  s.args = &c;
#if defined(__GNUC__) && !defined(__clang__) && __GNUC__ >= 12
#pragma GCC diagnostic pop
#endif
  s.fibers.resize(threads);
  for (long long b = 0; b < blocks; ++b) {
    bid = b;
    for (fiber& f : s.fibers) start_fiber(f);
    std::vector<int> order;
    for (long long phase = 0;; ++phase) {
      // Rounds until every thread waits at __syncthreads (or has finished): each round runs
      // the runnable threads in a new order (Fisher-Yates with an xorshift generator), each to
      // its next barrier; then the warps whose __syncwarp is complete go on.
      for (;;) {
        order.clear();
        for (int t = 0; t < threads; ++t)
          if (s.fibers[t].st == state::running) order.push_back(t);
        for (int t = (int)order.size() - 1; t > 0; --t) {
          s.rng ^= s.rng << 13;
          s.rng ^= s.rng >> 7;
          s.rng ^= s.rng << 17;
          const int k = (int)(s.rng % (unsigned long long)(t + 1));
          const int tmp = order[t];
          order[t] = order[k];
          order[k] = tmp;
        }
        for (int t : order) {
          tid = t;
          swapcontext(&s.main, &s.fibers[t].ctx);
        }
        if (!release_warps()) break;
      }
      int waiting = 0, done = 0, at_warp = 0;
      for (const fiber& f : s.fibers) {
        waiting += f.st == state::waiting;
        done += f.st == state::done;
        at_warp += f.st == state::at_warp;
      }
      if (done == threads) break;
      if (waiting != threads) {
        std::fprintf(stderr,
                     "wp_prim_emu: barrier divergence in block %lld, phase %lld: %d threads "
                     "wait at __syncthreads, %d at an incomplete __syncwarp, %d have left the "
                     "kernel\n",
                     b, phase, waiting, at_warp, done);
        std::abort();
      }
      ++block_barriers;
      for (fiber& f : s.fibers) f.st = state::running;
    }
  }
}

template <typename T>
T atomic_add(T* p, T v) {
  const T old = *p;
  *p = (T)(old + v);
  return old;
}

[[noreturn]] inline void lookback_stuck() {
  std::fprintf(stderr,
               "wp_prim_emu: block %lld waits in a look-back for a tile that every earlier "
               "block has left unpublished\n",
               bid);
  std::abort();
}

/// `threadIdx` of the running thread (a 1-D block).
struct dim3_t {
  unsigned x, y, z;
};
inline dim3_t thread_idx() { return dim3_t{(unsigned)tid, 0u, 0u}; }

/// The warp collective each thread is in (its name), checked by every lane of a collective.
inline std::vector<const char*>& collective_names() {
  static std::vector<const char*> names;
  return names;
}

/// The values the lanes of `mask` in the caller's warp hand to collective `what` (see the
/// top): every lane writes its `v` and `what`, waits for the others, checks that each lane of
/// the mask is in the same collective (a shuffle against a ballot, say, is undefined on a
/// GPU), copies the mask's values into `out` (by lane), and waits again, so that no lane
/// overwrites a value another has yet to read.
template <typename T>
void gather(unsigned mask, T v, const char* what, T* out) {
  static std::vector<T> slots;
  std::vector<const char*>& names = collective_names();
  const int threads = (int)sched().fibers.size();
  if ((int)slots.size() < threads) slots.resize((size_t)threads);
  if ((int)names.size() < threads) names.resize((size_t)threads, nullptr);
  slots[(size_t)tid] = v;
  names[(size_t)tid] = what;
  warp_sync(mask);
  const int base = tid - tid % 32;
  for (int l = 0; l < 32 && base + l < threads; ++l) {
    if (!((mask >> l) & 1u)) continue;
    const char* theirs = names[(size_t)(base + l)];
    if (theirs == nullptr || std::strcmp(theirs, what) != 0)
      warp_fail("lanes of one mask are in different warp collectives", mask);
    out[l] = slots[(size_t)(base + l)];
  }
  warp_sync(mask);
}

/// `__syncwarp(mask)`: a barrier of the mask's lanes, which no lane of the mask may meet in
/// a warp collective.
inline void syncwarp(unsigned mask) {
  std::vector<const char*>& names = collective_names();
  const int threads = (int)sched().fibers.size();
  if ((int)names.size() < threads) names.resize((size_t)threads, nullptr);
  names[(size_t)tid] = "__syncwarp";
  warp_sync(mask);
}

/// Aborts when `mask` names a lane past the end of the block (a lane of a partial warp that
/// does not exist: the collectives of the sort use the exact mask of their warp).
inline void mask_in_block(unsigned mask, const char* what) {
  const int threads = (int)sched().fibers.size();
  const int base = tid - tid % 32;
  for (int l = 0; l < 32; ++l)
    if (((mask >> l) & 1u) && base + l >= threads) warp_fail(what, mask);
}

/// The value lane `src` of the caller's warp handed to shuffle `what` (`src` < 0: the
/// caller's own).
template <typename T>
T exchange(unsigned mask, T v, int src, const char* what) {
  T all[32];
  gather(mask, v, what, all);
  return src < 0 ? v : all[src];
}

/// `__shfl_sync(mask, v, src)`: lane `src % 32`'s value, which must be in the mask and exist.
template <typename T>
T shfl_sync(unsigned mask, T v, int src) {
  const int lane = src & 31;
  if (!((mask >> lane) & 1u) || tid - tid % 32 + lane >= (int)sched().fibers.size())
    warp_fail("__shfl_sync reads a lane outside the mask or the block", mask);
  return exchange(mask, v, lane, "__shfl_sync");
}

/// `__shfl_down_sync(mask, v, delta)`: lane + delta's value; the caller's own past the warp's
/// end, the mask or the block.
template <typename T>
T shfl_down_sync(unsigned mask, T v, unsigned delta) {
  const unsigned src = (unsigned)(tid % 32) + delta;
  const bool own = src >= 32u || !((mask >> src) & 1u) ||
                   tid - tid % 32 + (int)src >= (int)sched().fibers.size();
  return exchange(mask, v, own ? -1 : (int)src, "__shfl_down_sync");
}

/// `__shfl_up_sync(mask, v, delta)`: lane - delta's value; the caller's own below lane delta
/// (as CUDA). A source lane outside the mask aborts (its value is undefined on a GPU).
template <typename T>
T shfl_up_sync(unsigned mask, T v, unsigned delta) {
  mask_in_block(mask, "__shfl_up_sync with a mask past the block's end");
  const int lane = tid % 32;
  const int src = lane - (int)delta;
  if (src >= 0 && !((mask >> src) & 1u))
    warp_fail("__shfl_up_sync reads a lane outside the mask", mask);
  return exchange(mask, v, src, "__shfl_up_sync");
}

/// `__ballot_sync(mask, pred)`: bit l set for each lane l of the mask whose `pred` is nonzero.
inline unsigned ballot_sync(unsigned mask, int pred) {
  mask_in_block(mask, "__ballot_sync with a mask past the block's end");
  int all[32];
  gather(mask, pred, "__ballot_sync", all);
  unsigned r = 0;
  for (int l = 0; l < 32; ++l)
    if (((mask >> l) & 1u) && all[l] != 0) r |= 1u << l;
  return r;
}

/// `__match_any_sync(mask, v)`: the lanes of the mask whose `v` equals the caller's.
template <typename T>
unsigned match_any_sync(unsigned mask, T v) {
  mask_in_block(mask, "__match_any_sync with a mask past the block's end");
  T all[32];
  gather(mask, v, "__match_any_sync", all);
  unsigned r = 0;
  for (int l = 0; l < 32; ++l)
    if (((mask >> l) & 1u) && all[l] == v) r |= 1u << l;
  return r;
}

/// `__popc(x)`: the set bits of x; `__clz(x)`: its leading zero bits (32 for 0), as CUDA.
inline int popc(unsigned x) { return __builtin_popcount(x); }
inline int clz(int x) { return x == 0 ? 32 : __builtin_clz((unsigned)x); }

}  // namespace wp_emu

#define threadIdx (::wp_emu::thread_idx())
#define __syncthreads() ::wp_emu::sync()
#define __shfl_down_sync(mask, v, delta) ::wp_emu::shfl_down_sync((mask), (v), (unsigned)(delta))
#define __shfl_sync(mask, v, src) ::wp_emu::shfl_sync((mask), (v), (int)(src))
#define __syncwarp(mask) ::wp_emu::syncwarp((unsigned)(mask))
#define __shfl_up_sync(mask, v, delta) ::wp_emu::shfl_up_sync((mask), (v), (unsigned)(delta))
#define __ballot_sync(mask, pred) ::wp_emu::ballot_sync((unsigned)(mask), (int)(pred))
#define __match_any_sync(mask, v) ::wp_emu::match_any_sync((unsigned)(mask), (v))
#define __popc(x) ::wp_emu::popc((unsigned)(x))
#define __clz(x) ::wp_emu::clz((int)(x))

#define WP_PRIM_FN inline
#define WP_PRIM_ENTRY extern "C" void
#define WP_PRIM_ENTRY_MIN(min_blocks) extern "C" void
#define WP_PRIM_SHARED static
#define WP_PRIM_SYNC() ::wp_emu::sync()
#define WP_PRIM_TID ((wp::i32)::wp_emu::tid)
#define WP_PRIM_BID ((wp::i64)::wp_emu::bid)
#define WP_PRIM_ATOMIC_ADD(p, v) ::wp_emu::atomic_add((p), (v))
#define WP_PRIM_LOOKBACK_WAIT() ::wp_emu::lookback_stuck()
// Blocks never run at once, so there is nothing to order (the one thing these tests cannot
// check: that the kernels fence where a GPU needs it).
#define WP_PRIM_FENCE() ((void)0)
#define WP_PRIM_UNROLL
#define WP_PRIM_NO_UNROLL
#define WP_PRIM_REGISTER(name) \
  static ::wp_emu::registrar wp_emu_registrar_##name(#name, reinterpret_cast<void*>(&name));

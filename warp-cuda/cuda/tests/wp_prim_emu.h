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
//     finished and an unpublished status is a bug that would hang a GPU.
//   * for the tile library (wp_tile.h, tests/cuda_tile_host.rs): `threadIdx` (x only),
//     `__syncthreads()`, and `__shfl_down_sync`, an exchange among the 32 lanes of a warp made
//     of two block-wide barriers (every thread writes its value, all wait, each reads its
//     partner's, all wait). It is exact for shuffles that every thread of the block calls
//     together, as the tile reductions do; a thread outside `mask`, or a shuffle that only some
//     warps reach, aborts or is a barrier divergence. A source lane outside the warp or the
//     mask gives the caller's own value (CUDA leaves the latter undefined).
// Not emulated: warps otherwise (the primitives use no warp-level operations), memory ordering
// between blocks, and interleavings inside a phase.
#pragma once

#define WP_PRIM_EMULATOR 1

#include <ucontext.h>

#include <cstdio>
#include <cstdlib>
#include <map>
#include <string>
#include <vector>

namespace wp_emu {

/// The running thread's index and block (set by the scheduler before each switch).
inline int tid = 0;
inline long long bid = 0;

enum class state { running, waiting, done };

struct fiber {
  ucontext_t ctx;
  std::vector<char> stack;
  state st = state::running;
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
  std::vector<int> order(threads);
  for (long long b = 0; b < blocks; ++b) {
    bid = b;
    for (fiber& f : s.fibers) start_fiber(f);
    for (long long phase = 0;; ++phase) {
      // A new order for every phase (Fisher-Yates with an xorshift generator).
      for (int t = 0; t < threads; ++t) order[t] = t;
      for (int t = threads - 1; t > 0; --t) {
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
      int waiting = 0, done = 0;
      for (const fiber& f : s.fibers) {
        waiting += f.st == state::waiting;
        done += f.st == state::done;
      }
      if (done == threads) break;
      if (waiting != threads) {
        std::fprintf(stderr,
                     "wp_prim_emu: barrier divergence in block %lld, phase %lld: %d threads "
                     "wait at __syncthreads, %d have left the kernel\n",
                     b, phase, waiting, done);
        std::abort();
      }
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

/// `__shfl_down_sync(mask, v, delta)` among the 32 lanes of the caller's warp (see the top).
template <typename T>
T shfl_down_sync(unsigned mask, T v, unsigned delta) {
  static std::vector<T> slots;
  const int threads = (int)sched().fibers.size();
  const int lane = tid % 32;
  if (!((mask >> lane) & 1u)) {
    std::fprintf(stderr, "wp_prim_emu: thread %d of block %lld shuffles outside its mask %08x\n",
                 tid, bid, mask);
    std::abort();
  }
  if ((int)slots.size() < threads) slots.resize((size_t)threads);
  slots[(size_t)tid] = v;
  sync();
  const unsigned src = (unsigned)lane + delta;
  T r = v;
  if (src < 32u && ((mask >> src) & 1u) && tid - lane + (int)src < threads)
    r = slots[(size_t)(tid - lane + (int)src)];
  sync();
  return r;
}

}  // namespace wp_emu

#define threadIdx (::wp_emu::thread_idx())
#define __syncthreads() ::wp_emu::sync()
#define __shfl_down_sync(mask, v, delta) ::wp_emu::shfl_down_sync((mask), (v), (unsigned)(delta))

#define WP_PRIM_FN inline
#define WP_PRIM_ENTRY extern "C" void
#define WP_PRIM_SHARED static
#define WP_PRIM_SYNC() ::wp_emu::sync()
#define WP_PRIM_TID ((wp::i32)::wp_emu::tid)
#define WP_PRIM_BID ((wp::i64)::wp_emu::bid)
#define WP_PRIM_ATOMIC_ADD(p, v) ::wp_emu::atomic_add((p), (v))
#define WP_PRIM_LOOKBACK_WAIT() ::wp_emu::lookback_stuck()
#define WP_PRIM_REGISTER(name) \
  static ::wp_emu::registrar wp_emu_registrar_##name(#name, reinterpret_cast<void*>(&name));

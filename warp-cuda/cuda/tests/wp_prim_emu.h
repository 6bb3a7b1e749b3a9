// wp_prim_emu.h: a CUDA block emulator for the host, so that the kernels of wp_primitives.h
// compile with g++ and run on the CPU (tests/cuda_primitives_host.rs).
//
// Include it before wp_primitives.h. A launch of B blocks of T threads runs T host threads;
// each runs the kernel for block 0, waits at a barrier, then block 1, and so on. So:
//   * `__syncthreads` is a barrier of the T threads (a thread that skipped a barrier the others
//     reached would deadlock; the barrier aborts after a timeout instead of hanging the test);
//   * `__shared__` is `static` storage of the kernel function: shared by the threads of the
//     block running now, and reused by the next block, as on a GPU (nothing carries over
//     because every kernel writes its shared memory before reading it);
//   * blocks never run concurrently, so a kernel that waited for another block would hang:
//     the primitives never do.
#pragma once

#define WP_PRIM_EMULATOR 1

#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace wp_emu {

inline thread_local int tid = 0;
inline thread_local long long bid = 0;

/// A reusable barrier for a fixed number of threads.
class Barrier {
 public:
  void reset(int count) {
    count_ = count;
    waiting_ = 0;
  }
  void wait() {
    std::unique_lock<std::mutex> lock(m_);
    const unsigned long long gen = gen_;
    if (++waiting_ == count_) {
      waiting_ = 0;
      ++gen_;
      cv_.notify_all();
      return;
    }
    if (!cv_.wait_for(lock, std::chrono::seconds(60), [&] { return gen != gen_; })) {
      std::fprintf(stderr,
                   "wp_prim_emu: __syncthreads timed out in block %lld (a thread of the block "
                   "skipped a barrier the others reached)\n",
                   bid);
      std::abort();
    }
  }

 private:
  std::mutex m_;
  std::condition_variable cv_;
  int count_ = 1;
  int waiting_ = 0;
  unsigned long long gen_ = 0;
};

inline Barrier& barrier() {
  static Barrier b;
  return b;
}

inline void sync() { barrier().wait(); }

/// Entry points by name (filled by WP_PRIM_REGISTER at static initialisation).
inline std::map<std::string, void*>& registry() {
  static std::map<std::string, void*> r;
  return r;
}

struct registrar {
  registrar(const char* name, void* fn) { registry()[name] = fn; }
};

/// Runs `blocks` blocks of `threads` threads of `fn(args)`, blocks one after another.
template <typename Args>
void launch(void (*fn)(Args), long long blocks, int threads, const Args& args) {
  barrier().reset(threads);
  std::vector<std::thread> pool;
  pool.reserve(threads);
  for (int t = 0; t < threads; ++t) {
    pool.emplace_back([=, &args] {
      tid = t;
      for (long long b = 0; b < blocks; ++b) {
        bid = b;
        fn(args);
        sync();  // the block's shared memory is the next block's
      }
    });
  }
  for (auto& th : pool) th.join();
}

}  // namespace wp_emu

#define WP_PRIM_FN inline
#define WP_PRIM_ENTRY extern "C" void
#define WP_PRIM_SHARED static
#define WP_PRIM_SYNC() ::wp_emu::sync()
#define WP_PRIM_TID ((wp::i32)::wp_emu::tid)
#define WP_PRIM_BID ((wp::i64)::wp_emu::bid)
#define WP_PRIM_REGISTER(name) \
  static ::wp_emu::registrar wp_emu_registrar_##name(#name, reinterpret_cast<void*>(&name));

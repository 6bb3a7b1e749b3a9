// Test driver for the warp-lang CUDA C++ builtin library.
//
// Reads test cases (one per line) from the file named by argv[1], evaluates each through the
// library and prints one result line per case. The expected results are computed by the Rust
// test tests/cuda_host_cpp.rs through warp-core and glam, which also writes the case file.
//
// Built with g++ (`g++ -std=c++17 -O1 -Wall -Werror`) everything runs on the host. Built with
// nvcc (`nvcc -std=c++17 -x cu --fmad=false`) the cases run on the GPU, one thread each
// (`print` cases are host-only and answer SKIP there); with `-DWP_DRIVER_NVRTC ... -lnvrtc
// -lcuda` the kernel is instead compiled at run time by NVRTC from driver_core.h, as
// generated kernels are (run it as `driver CASES path/to/warp-cuda/cuda`).
//
// Case line:   OP TYPE TYPE2 N A0 .. A(N-1)      (TYPE2 is `-` except for casts; A* in hex)
// Result line: R0 R1 ... [F kind arg ndim i0 i1 i2 i3 s0 s1 s2 s3]   (hex; ERR if unsupported)
// A value of a composite type is its scalars in memory order (vectors x first, matrices column
// by column); a scalar is its bit pattern (integers as unsigned of the same width).
#include "driver_core.h"

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>
#if defined(WP_DRIVER_NVRTC)
#include <cuda.h>
#include <nvrtc.h>
#endif

namespace drv {

static const char* const TYPE_NAMES[] = {
#define NAME(t) #t,
    TYPE_LIST(NAME)
#undef NAME
};
static const char* const OP_NAMES[] = {
#define NAME(o) #o,
    OP_LIST(NAME)
#undef NAME
};

// ------------------------------------------------------------------------------------------
// Host side: parse, run (here or on the GPU), print
// ------------------------------------------------------------------------------------------

static int lookup(const char* const* names, int count, const std::string& s) {
  for (int i = 0; i < count; ++i)
    if (s == names[i]) return i;
  return -1;
}

template <typename T>
static void print_case_value(const case_t& c) {
  if constexpr (num<T>::is_bool) {
    print_value(c.a[0] != 0);
  } else {
    reader r;
    r.a = c.a;
    r.pos = 0;
    T v = get<T>(r);
    print_value(v);
  }
}

static void print_case(const case_t& c) {
  switch (c.ty) {
#define CASE_T(t)                \
  case T_##t:                    \
    print_case_value<t>(c);      \
    return;
    TYPE_LIST(CASE_T)
#undef CASE_T
    default:
      printf("ERR");
  }
}

static void print_result(const case_t& c, const out_t& o, bool device) {
  if (c.op == OP_print) {
    if (device) {
      printf("SKIP\n");
    } else {
      printf("P ");
      print_case(c);
      printf("\n");
    }
    return;
  }
  if (o.n < 0) {
    printf("ERR\n");
    return;
  }
  for (int k = 0; k < o.n; ++k) printf(k ? " %llx" : "%llx", o.v[k]);
  if (o.flag) {
    const fault_t& f = o.fault;
    printf("%sF %llx %llx %llx", o.n ? " " : "", (u64)(i64)f.kind, (u64)(i64)f.arg, (u64)(i64)f.ndim);
    for (int k = 0; k < 4; ++k) printf(" %llx", (u64)f.index[k]);
    for (int k = 0; k < 4; ++k) printf(" %llx", (u64)f.shape[k]);
  }
  printf("\n");
}


static int run_main(int argc, char** argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s CASES\n", argv[0]);
    return 2;
  }
  FILE* f = fopen(argv[1], "r");
  if (!f) {
    fprintf(stderr, "cannot open %s\n", argv[1]);
    return 2;
  }
  std::vector<case_t> cases;
  char op[64], ty[64], ty2[64];
  int n;
  while (fscanf(f, "%63s %63s %63s %d", op, ty, ty2, &n) == 4) {
    case_t c;
    c.op = lookup(OP_NAMES, OP_COUNT, op);
    c.ty = std::string(ty) == "-" ? -1 : lookup(TYPE_NAMES, T_COUNT, ty);
    c.ty2 = std::string(ty2) == "-" ? -1 : lookup(TYPE_NAMES, T_COUNT, ty2);
    c.n = n;
    if (n < 0 || n > 40) {
      fprintf(stderr, "bad arg count %d\n", n);
      return 2;
    }
    for (int k = 0; k < 40; ++k) c.a[k] = 0;
    for (int k = 0; k < n; ++k) {
      if (fscanf(f, "%llx", &c.a[k]) != 1) {
        fprintf(stderr, "bad case line\n");
        return 2;
      }
    }
    if (c.op < 0) {
      fprintf(stderr, "unknown op %s\n", op);
      return 2;
    }
    cases.push_back(c);
  }
  fclose(f);
  std::vector<out_t> outs(cases.size());
  bool device = false;
#if defined(__CUDACC__)
  device = true;
  case_t* dc = nullptr;
  out_t* dout = nullptr;
  const size_t nc = cases.size();
  if (cudaMalloc(&dc, nc * sizeof(case_t)) != cudaSuccess ||
      cudaMalloc(&dout, nc * sizeof(out_t)) != cudaSuccess) {
    fprintf(stderr, "cudaMalloc failed\n");
    return 3;
  }
  cudaMemcpy(dc, cases.data(), nc * sizeof(case_t), cudaMemcpyHostToDevice);
  cudaMemset(dout, 0, nc * sizeof(out_t));
  const unsigned blocks = (unsigned)((nc + 127) / 128);
#if defined(WP_DRIVER_NVRTC)
  // The kernel as generated code gets it: driver_core.h compiled at run time by NVRTC, with
  // no standard headers, --fmad=false, for this GPU's architecture. argv[2]: the directory
  // that holds the library (warp-cuda/cuda).
  if (argc < 3) {
    fprintf(stderr, "usage: %s CASES LIBDIR\n", argv[0]);
    return 2;
  }
  cudaDeviceProp prop;
  cudaGetDeviceProperties(&prop, 0);
  const std::string arch = "--gpu-architecture=sm_" + std::to_string(prop.major * 10 + prop.minor);
  const std::string inc = std::string("-I") + argv[2];
  const char* src = "#include \"tests/driver_core.h\"\n";
  nvrtcProgram prog;
  nvrtcCreateProgram(&prog, src, "nvrtc_driver.cu", 0, nullptr, nullptr);
  const char* opts[] = {"--std=c++17", "--fmad=false", arch.c_str(), inc.c_str()};
  const nvrtcResult cr = nvrtcCompileProgram(prog, 4, opts);
  size_t log_size = 0;
  nvrtcGetProgramLogSize(prog, &log_size);
  std::string log(log_size, '\0');
  nvrtcGetProgramLog(prog, &log[0]);
  if (cr != NVRTC_SUCCESS) {
    fprintf(stderr, "NVRTC failed: %s\n%s\n", nvrtcGetErrorString(cr), log.c_str());
    return 4;
  }
  if (log_size > 1) fprintf(stderr, "NVRTC log:\n%s\n", log.c_str());
  size_t cubin_size = 0;
  nvrtcGetCUBINSize(prog, &cubin_size);
  std::string cubin(cubin_size, '\0');
  nvrtcGetCUBIN(prog, &cubin[0]);
  nvrtcDestroyProgram(&prog);
  CUmodule mod;
  CUfunction fn;
  if (cuModuleLoadData(&mod, cubin.data()) != CUDA_SUCCESS ||
      cuModuleGetFunction(&fn, mod, "compute_all") != CUDA_SUCCESS) {
    fprintf(stderr, "cannot load the NVRTC cubin\n");
    return 4;
  }
  int ni = (int)nc;
  void* args[] = {&dc, &dout, &ni};
  if (cuLaunchKernel(fn, blocks, 1, 1, 128, 1, 1, 0, nullptr, args, nullptr) != CUDA_SUCCESS) {
    fprintf(stderr, "cuLaunchKernel failed\n");
    return 4;
  }
  fprintf(stderr, "ran the NVRTC build (%s)\n", arch.c_str());
#else
  compute_all<<<blocks, 128>>>(dc, dout, (int)nc);
#endif
  cudaError_t e = cudaDeviceSynchronize();
  if (e != cudaSuccess) {
    fprintf(stderr, "kernel failed: %s\n", cudaGetErrorString(e));
    return 3;
  }
  cudaMemcpy(outs.data(), dout, nc * sizeof(out_t), cudaMemcpyDeviceToHost);
#else
  for (size_t i = 0; i < cases.size(); ++i) {
    memset(&outs[i], 0, sizeof(out_t));
    if (cases[i].op != OP_print) compute(cases[i], outs[i]);
  }
#endif
  for (size_t i = 0; i < cases.size(); ++i) print_result(cases[i], outs[i], device);
  return 0;
}

}  // namespace drv

int main(int argc, char** argv) { return drv::run_main(argc, argv); }

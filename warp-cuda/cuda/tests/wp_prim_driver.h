// wp_prim_driver.h: runs launch plans of the parallel primitives on the host (see
// tests/cuda_primitives_host.rs, which writes the plans and checks the results).
//
// A translation unit is: wp_prim_emu.h, one module of wp_primitives.h (the text the runtime
// hands NVRTC), then this file. It reads a script (argv[1]), one command per line:
//   buf ID BYTES            a buffer, filled with 0xCD (scratch contents are unspecified)
//   data ID HEX             its initial bytes
//   launch ENTRY BLOCKS W0 .. W15
//                           one kernel launch; a word is `aID+OFFSET` (a buffer's address),
//                           `null`, `iVALUE` (an integer), `fault` or `flag` (the fault record)
//   dump ID                 prints `dump ID HEX`
//   check                   prints `fault KIND ARG INDEX0 SHAPE0` or `nofault`, clears the record
//   reset                   drops every buffer (the next case starts)
#include <cstdint>
#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>

namespace wp_driver {

struct buffer {
  std::vector<unsigned long long> words;  // 8-byte aligned storage
  size_t bytes = 0;
  unsigned char* data() { return reinterpret_cast<unsigned char*>(words.data()); }
};

static int hexval(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  return c - 'A' + 10;
}

static int run(const char* path) {
  std::ifstream in(path);
  if (!in) {
    std::fprintf(stderr, "cannot open %s\n", path);
    return 2;
  }
  std::map<long long, buffer> bufs;
  wp::fault_t fault{};
  wp::u32 flag[2] = {0, 0};
  std::string line;
  while (std::getline(in, line)) {
    std::istringstream ss(line);
    std::string cmd;
    ss >> cmd;
    if (cmd.empty()) continue;
    if (cmd == "buf") {
      long long id;
      size_t bytes;
      ss >> id >> bytes;
      buffer& b = bufs[id];
      b.bytes = bytes;
      b.words.assign(bytes / 8 + 1, 0xCDCDCDCDCDCDCDCDull);
    } else if (cmd == "data") {
      long long id;
      std::string hex;
      ss >> id >> hex;
      buffer& b = bufs.at(id);
      if (hex.size() != 2 * b.bytes) {
        std::fprintf(stderr, "data %lld: %zu hex digits for %zu bytes\n", id, hex.size(),
                     b.bytes);
        return 2;
      }
      for (size_t k = 0; k < b.bytes; ++k)
        b.data()[k] = (unsigned char)(hexval(hex[2 * k]) * 16 + hexval(hex[2 * k + 1]));
    } else if (cmd == "launch") {
      std::string entry;
      long long blocks;
      ss >> entry >> blocks;
      wp::prim::args_t a{};
      for (int k = 0; k < 16; ++k) {
        std::string w;
        ss >> w;
        if (w == "null") {
          a.w[k] = 0;
        } else if (w == "fault") {
          a.w[k] = (wp::u64)(uintptr_t)&fault;
        } else if (w == "flag") {
          a.w[k] = (wp::u64)(uintptr_t)&flag[0];
        } else if (w[0] == 'i') {
          a.w[k] = (wp::u64)std::stoll(w.substr(1));
        } else if (w[0] == 'a') {
          const size_t plus = w.find('+');
          const long long id = std::stoll(w.substr(1, plus - 1));
          const long long off = std::stoll(w.substr(plus + 1));
          a.w[k] = (wp::u64)(uintptr_t)(bufs.at(id).data() + off);
        } else {
          std::fprintf(stderr, "bad word %s\n", w.c_str());
          return 2;
        }
      }
      auto it = wp_emu::registry().find(entry);
      if (it == wp_emu::registry().end()) {
        std::fprintf(stderr, "no entry %s in this module\n", entry.c_str());
        return 2;
      }
      auto fn = reinterpret_cast<void (*)(wp::prim::args_t)>(it->second);
      wp_emu::launch(fn, blocks, WP_PRIM_THREADS, a);
    } else if (cmd == "dump") {
      long long id;
      ss >> id;
      buffer& b = bufs.at(id);
      std::printf("dump %lld ", id);
      for (size_t k = 0; k < b.bytes; ++k) std::printf("%02x", b.data()[k]);
      std::printf("\n");
    } else if (cmd == "check") {
      if (flag[0]) {
        std::printf("fault %d %d %lld %lld\n", fault.kind, fault.arg, (long long)fault.index[0],
                    (long long)fault.shape[0]);
        fault = wp::fault_t{};
        flag[0] = 0;
      } else {
        std::printf("nofault\n");
      }
    } else if (cmd == "reset") {
      bufs.clear();
    } else {
      std::fprintf(stderr, "bad command %s\n", cmd.c_str());
      return 2;
    }
  }
  return 0;
}

}  // namespace wp_driver

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: %s SCRIPT\n", argv[0]);
    return 2;
  }
  return wp_driver::run(argv[1]);
}

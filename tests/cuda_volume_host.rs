//! The CUDA sparse-volume builtins (`warp-cuda/cuda/wp_volume.h`, `wp_adjoint_volume.h`)
//! against warp-core's (`objects::volume`), bit for bit, on the host.
//!
//! As in tests/cuda_geometry_host.rs, one C++ driver (below, `DRIVER`) reads a stream of
//! cases (u32 words: an op code and its inputs as bit patterns) and prints one line per case;
//! the same cases run through warp-core's functions here and print the same line format, and
//! the two are compared as text. Floats are printed as their bits (any NaN as `nan`), faults
//! as their kind, argument and index words, so "equal" means bit for bit, faults included.
//! The driver is built with `g++ -std=c++17 -O1 -ffp-contract=off -Wall -Wextra -Werror
//! -Wdouble-promotion` (no FMA contraction, as the runtime's `--fmad=false`). Skipped, saying
//! so, without g++.
//!
//! Grids come from warp-core's builder (`objects::nanovdb`), validated, then given distinct
//! values everywhere a lookup can end: every leaf voxel, every internal table entry without a
//! child, every root tile and the background (random values; the C++ side receives the same
//! bytes), and one root tile turned into a value tile (child 0), so that samples end at every
//! level 0..4. Value grids of f32, f64, i32, Vec3 and DVec3, an Index and an OnIndex grid,
//! over tiles with negative coordinates, leaves on both sides of leaf, lower and upper node
//! boundaries, and leaves at the ends of the i32 range; non-symmetric, anisotropic maps.
//! Every builtin and adjoint runs on positions inside and around the leaves, far into tiles
//! and background, on integers and halves (CLOSEST's rounding, LINEAR's positive-side cell),
//! near and beyond the i32 range (the background rule), and with NaN and infinite
//! coordinates (the NonFinite fault); the index variants also with value arrays too short
//! (the array's OutOfBounds fault). Adjoints compare the position's adjoint and every word
//! the gradient twin receives (`adj_volume_lookup` on the i32 grid gets a zero adjoint, the
//! only one an integer has). Stores compare the whole grid's digest after each store. The
//! test also counts the LINEAR taps that end at each level and the faults of each kind, and
//! fails when a kind is barely reached.
//!
//! A second test checks that NVRTC accepts the headers (every function instantiated in a
//! kernel) for sm_90 and sm_80 with `--fmad=false`; skipped, saying so, without libnvrtc.

use std::process::Command;

use warp_core::adjoint::{
    adj_volume_index_to_world, adj_volume_index_to_world_dir, adj_volume_lookup, adj_volume_sample,
    adj_volume_sample_grad, adj_volume_sample_grad_index, adj_volume_sample_index,
    adj_volume_world_to_index, adj_volume_world_to_index_dir,
};
use warp_core::builtins::volume::{
    volume_index_to_world, volume_index_to_world_dir, volume_lookup, volume_lookup_index,
    volume_sample, volume_sample_grad, volume_sample_grad_index, volume_sample_index, volume_store,
    volume_world_to_index, volume_world_to_index_dir,
};
use warp_core::glam::{DMat3, DVec3, Mat3, Vec3};
use warp_core::objects::nanovdb::{
    build_from_tiles, build_from_voxels, grid, root, root_key, validate, BuildKind, GridInfo,
    GridType, Map, LOWER_CHILD_MASK, UPPER_CHILD_MASK,
};
use warp_core::objects::{VolumeGrid, VolumeSample, VolumeValue, VolumeView, VoxelIndex};
use warp_core::{ArrayView, Fault, FaultKind, GradView};

#[path = "common/host_cpp.rs"]
mod host_cpp;

/// The fault argument index the driver gives its value arrays, and the name Rust faults
/// carry.
const DATA_ARG: i32 = 3;
const DATA_NAME: &str = "data";

// ------------------------------------------------------------------------------------------
// The C++ driver
// ------------------------------------------------------------------------------------------

const DRIVER: &str = r#"
#include <cstdio>
#include <cstring>
#include <cstddef>
#include <cstdlib>
#include <vector>
#include "wp_adjoint_volume.h"
using namespace wp;

static std::vector<u32> in;
static size_t at = 0;
static u32 w() { return in[at++]; }
static i32 wi() { return (i32)w(); }
static f32 wf() { return f32_from_bits(w()); }
static f64 wd() { const u64 lo = w(); const u64 hi = w(); return f64_from_bits(lo | (hi << 32)); }
static Vec3 wv() { const f32 x = wf(); const f32 y = wf(); const f32 z = wf(); return Vec3_new(x, y, z); }

static void pr(f32 x) { if (x != x) printf(" nan"); else printf(" %08x", f32_to_bits(x)); }
static void pr(f64 x) { if (x != x) printf(" nan"); else printf(" %016llx", (unsigned long long)f64_to_bits(x)); }
static void pr(i32 x) { printf(" %d", x); }
static void pr(Vec3 v) { pr(v.x); pr(v.y); pr(v.z); }
static void pr(DVec3 v) { pr(v.x); pr(v.y); pr(v.z); }
static void pr(const Mat3& m) { pr(m.x_axis); pr(m.y_axis); pr(m.z_axis); }
static void pr(const DMat3& m) { pr(m.x_axis); pr(m.y_axis); pr(m.z_axis); }

template <typename T> T rd();
template <> f32 rd<f32>() { return wf(); }
template <> f64 rd<f64>() { return wd(); }
template <> i32 rd<i32>() { return wi(); }
template <> Vec3 rd<Vec3>() { return wv(); }
template <> DVec3 rd<DVec3>() { const f64 x = wd(); const f64 y = wd(); const f64 z = wd(); return DVec3_new(x, y, z); }
template <> Mat3 rd<Mat3>() { const Vec3 a = rd<Vec3>(); const Vec3 b = rd<Vec3>(); const Vec3 c = rd<Vec3>(); return Mat3{a, b, c}; }
template <> DMat3 rd<DMat3>() { const DVec3 a = rd<DVec3>(); const DVec3 b = rd<DVec3>(); const DVec3 c = rd<DVec3>(); return DMat3{a, b, c}; }

static fault_t fault;
static u32 flag;
static launch_ctx_t rec;
static ctx_t fresh() {
  memset(&fault, 0, sizeof fault);
  flag = 0;
  rec = launch_ctx_make(&fault, &flag);
  return ctx_make(&rec);
}
/// ` F kind arg ndim index..` (index words in hex; OutOfBounds also the shape), if a fault.
static bool pfault(const ctx_t& c) {
  if (!c.raised) return false;
  printf(" F %d %d %d", fault.kind, fault.arg, fault.ndim);
  for (int k = 0; k < fault.ndim; ++k) printf(" %llx", (unsigned long long)fault.index[k]);
  if (fault.kind == FAULT_OUT_OF_BOUNDS) printf(" %lld", (long long)fault.shape[0]);
  return true;
}

/// A 32-byte aligned buffer.
struct buf_t {
  u8* p = nullptr;
  size_t n = 0;
  void alloc(size_t bytes) {
    free(p);
    n = bytes;
    p = (u8*)aligned_alloc(32, (bytes + 31) / 32 * 32);
    memset(p, 0, (bytes + 31) / 32 * 32);
  }
};

/// A grid slot: the grid, a gradient twin (zeros) and the Rust view's bytes.
struct slot_t {
  u32 kind = 0;  // 0 f32, 1 f64, 2 i32, 3 Vec3, 4 DVec3, 5 VoxelIndex
  buf_t grid, grad;
  u8 view[256];
};
static slot_t slots[16];

template <typename T>
static volume_t<T> view_of(slot_t& s) {
  volume_t<T> v;
  memcpy(&v, s.view, sizeof v);
  v.data = (u64)(uintptr_t)s.grid.p;
  v.grad = s.kind == 5 ? 0 : (u64)(uintptr_t)s.grad.p;
  return v;
}

/// The twin's non-zero words (offset:bits), which are then cleared (4 KiB blocks compared
/// with a zero block first: the twins are megabytes).
static void pgrad(slot_t& s) {
  static const u8 zeros[4096] = {};
  printf(" |");
  for (size_t b = 0; b < s.grad.n; b += 4096) {
    const size_t n = s.grad.n - b < 4096 ? s.grad.n - b : 4096;
    if (memcmp(s.grad.p + b, zeros, n) == 0) continue;
    for (size_t o = b; o + 4 <= b + n; o += 4) {
      u32 x;
      memcpy(&x, s.grad.p + o, 4);
      if (x != 0) printf(" %zx:%08x", o, x);
    }
    memset(s.grad.p + b, 0, n);
  }
}

/// FNV-1a 64 of the grid bytes.
static u64 digest(const buf_t& b) {
  u64 h = 0xcbf29ce484222325ull;
  for (size_t i = 0; i < b.n; ++i) { h ^= b.p[i]; h *= 0x100000001b3ull; }
  return h;
}

/// The value arrays of the index variants, one per value kind.
static buf_t data_bufs[5];
template <typename T> static array_t<T, 1> data_of(u32 kind) {
  array_t<T, 1> a;
  a.data = (T*)data_bufs[kind].p;
  a.shape[0] = (i64)(data_bufs[kind].n / sizeof(T));
  a.strides[0] = (i64)sizeof(T);
  a.arg = 3;
  a.pad = 0;
  return a;
}

// op 2: sample, sample_grad and their adjoints.
template <typename T>
static void op_sample(slot_t& s) {
  typedef typename detail::vol_value<T>::G G;
  const i32 mode = wi();
  const Vec3 uvw = wv();
  const T ar = rd<T>();
  const T av = rd<T>();
  const G ag = rd<G>();
  const Vec3 au0 = wv();
  volume_t<T> v = view_of<T>(s), adj_v{};
  printf("s");
  ctx_t c = fresh();
  const T r = volume_sample(v, uvw, mode, &c);
  if (!pfault(c)) pr(r);
  c = fresh();
  const tuple_t<T, G> g = volume_sample_grad(v, uvw, mode, &c);
  printf(" |");
  if (!pfault(c)) { pr(g.f0); pr(g.f1); }
  Vec3 au = au0;
  i32 am = 0;
  c = fresh();
  adj_volume_sample(v, uvw, mode, adj_v, au, am, ar, &c);
  printf(" |");
  if (!pfault(c)) pr(au);
  pgrad(s);
  au = au0;
  c = fresh();
  tuple_t<T, G> at2;
  at2.f0 = av;
  at2.f1 = ag;
  adj_volume_sample_grad(v, uvw, mode, adj_v, au, am, at2, &c);
  printf(" |");
  if (!pfault(c)) pr(au);
  pgrad(s);
}

// op 3: lookup (and its adjoint), lookup_index.
template <typename T>
static void op_lookup(slot_t& s) {
  const i32 i = wi(), j = wi(), k = wi();
  printf("l");
  ctx_t c = fresh();
  volume_t<T> v = view_of<T>(s), adj_v{};
  if constexpr (!detail::same_type<T, VoxelIndex>::value) {
    const T ar = rd<T>();
    pr(volume_lookup(v, i, j, k, &c));
    i32 ai = 0;
    adj_volume_lookup(v, i, j, k, adj_v, ai, ai, ai, ar, &c);
    pgrad(s);
  }
  pr(volume_lookup_index(v, i, j, k, &c));
}

// op 4: store, then the grid's digest and the value read back.
template <typename T>
static void op_store(slot_t& s) {
  const i32 i = wi(), j = wi(), k = wi();
  const T x = rd<T>();
  volume_t<T> v = view_of<T>(s);
  ctx_t c = fresh();
  volume_store(v, i, j, k, x, &c);
  printf("w %016llx", (unsigned long long)digest(s.grid));
  pr(volume_lookup(v, i, j, k, &c));
}

// op 5: the transforms and their adjoints (from (1, 1, 1)).
template <typename T>
static void op_xform(slot_t& s) {
  const Vec3 p = wv();
  const Vec3 g = wv();
  volume_t<T> v = view_of<T>(s), adj_v{};
  ctx_t c = fresh();
  printf("x");
  pr(volume_index_to_world(v, p, &c));
  pr(volume_world_to_index(v, p, &c));
  pr(volume_index_to_world_dir(v, p, &c));
  pr(volume_world_to_index_dir(v, p, &c));
  Vec3 a = Vec3_ONE();
  adj_volume_index_to_world(v, p, adj_v, a, g, &c); pr(a);
  a = Vec3_ONE();
  adj_volume_world_to_index(v, p, adj_v, a, g, &c); pr(a);
  a = Vec3_ONE();
  adj_volume_index_to_world_dir(v, p, adj_v, a, g, &c); pr(a);
  a = Vec3_ONE();
  adj_volume_world_to_index_dir(v, p, adj_v, a, g, &c); pr(a);
}

// op 6: the index variants with value arrays of kind `dkind`.
template <typename GT, typename T>
static void op_index(slot_t& s, u32 dkind) {
  typedef typename detail::vol_value<T>::G G;
  const i32 mode = wi();
  const Vec3 uvw = wv();
  const T bg = rd<T>();
  const T ar = rd<T>();
  const T av = rd<T>();
  const G ag = rd<G>();
  const Vec3 au0 = wv();
  volume_t<GT> v = view_of<GT>(s), adj_v{};
  array_t<T, 1> d = data_of<T>(dkind), ad{};
  printf("i");
  ctx_t c = fresh();
  const T r = volume_sample_index(v, uvw, mode, d, bg, &c);
  if (!pfault(c)) pr(r);
  c = fresh();
  const tuple_t<T, G> g = volume_sample_grad_index(v, uvw, mode, d, bg, &c);
  printf(" |");
  if (!pfault(c)) { pr(g.f0); pr(g.f1); }
  Vec3 au = au0;
  T abg = detail::vol_value<T>::zero();
  i32 am = 0;
  c = fresh();
  adj_volume_sample_index(v, uvw, mode, d, bg, adj_v, au, am, ad, abg, ar, &c);
  printf(" |");
  if (!pfault(c)) { pr(au); pr(abg); }
  au = au0;
  abg = detail::vol_value<T>::zero();
  tuple_t<T, G> at2;
  at2.f0 = av;
  at2.f1 = ag;
  c = fresh();
  adj_volume_sample_grad_index(v, uvw, mode, d, bg, adj_v, au, am, ad, abg, at2, &c);
  printf(" |");
  if (!pfault(c)) { pr(au); pr(abg); }
}
template <typename GT>
static void op_index_any(slot_t& s) {
  const u32 dk = w();
  switch (dk) {
    case 0: op_index<GT, f32>(s, dk); break;
    case 1: op_index<GT, f64>(s, dk); break;
    case 3: op_index<GT, Vec3>(s, dk); break;
    default: op_index<GT, DVec3>(s, dk); break;
  }
}

#define DISPATCH(FN, S)                                      \
  switch ((S).kind) {                                        \
    case 0: FN<f32>(S); break;                               \
    case 1: FN<f64>(S); break;                               \
    case 2: FN<i32>(S); break;                               \
    case 3: FN<Vec3>(S); break;                              \
    case 4: FN<DVec3>(S); break;                             \
    default: FN<VoxelIndex>(S); break;                       \
  }
#define DISPATCH_FLOAT(FN, S)                                \
  switch ((S).kind) {                                        \
    case 0: FN<f32>(S); break;                               \
    case 1: FN<f64>(S); break;                               \
    case 3: FN<Vec3>(S); break;                              \
    case 4: FN<DVec3>(S); break;                             \
    default: fprintf(stderr, "not a float grid\n"); exit(4); \
  }
#define DISPATCH_VALUE(FN, S)                                \
  switch ((S).kind) {                                        \
    case 0: FN<f32>(S); break;                               \
    case 1: FN<f64>(S); break;                               \
    case 2: FN<i32>(S); break;                               \
    case 3: FN<Vec3>(S); break;                              \
    case 4: FN<DVec3>(S); break;                             \
    default: fprintf(stderr, "not a value grid\n"); exit(4); \
  }

static void read_bytes(u8* dst, size_t n) {
  for (size_t o = 0; o < n; o += 4) {
    const u32 x = w();
    memcpy(dst + o, &x, n - o < 4 ? n - o : 4);
  }
}

int main(int argc, char** argv) {
  if (argc < 2) return 2;
  FILE* f = fopen(argv[1], "rb");
  if (!f) return 2;
  u32 word;
  while (fread(&word, 4, 1, f) == 1) in.push_back(word);
  fclose(f);
  while (at < in.size()) {
    const u32 op = w();
    switch (op) {
      case 0:
        printf("layout %zu %zu %zu %zu %zu %zu %zu", sizeof(volume_t<f32>), alignof(volume_t<f32>),
               offsetof(volume_t<f32>, grid_type), offsetof(volume_t<f32>, background),
               offsetof(volume_t<f32>, value_size), sizeof(volume_t<DVec3>),
               sizeof(volume_t<VoxelIndex>));
        break;
      case 1: {
        slot_t& s = slots[w()];
        s.kind = w();
        const u32 nbytes = w(), nview = w();
        if (nview > sizeof s.view) return 5;
        read_bytes(s.view, nview);
        s.grid.alloc(nbytes);
        read_bytes(s.grid.p, nbytes);
        s.grad.alloc(nbytes);
        printf("grid %016llx", (unsigned long long)digest(s.grid));
        break;
      }
      case 2: { slot_t& s = slots[w()]; DISPATCH_FLOAT(op_sample, s); break; }
      case 3: { slot_t& s = slots[w()]; DISPATCH(op_lookup, s); break; }
      case 4: { slot_t& s = slots[w()]; DISPATCH_VALUE(op_store, s); break; }
      case 5: { slot_t& s = slots[w()]; DISPATCH(op_xform, s); break; }
      case 6: { slot_t& s = slots[w()]; DISPATCH(op_index_any, s); break; }
      case 7: {
        const u32 dk = w(), nbytes = w();
        data_bufs[dk].alloc(nbytes);
        read_bytes(data_bufs[dk].p, nbytes);
        printf("data %u %u", dk, nbytes);
        break;
      }
      default:
        fprintf(stderr, "bad op %u at word %zu\n", op, at - 1);
        return 3;
    }
    printf("\n");
  }
  return 0;
}
"#;

// ------------------------------------------------------------------------------------------
// Values on the wire
// ------------------------------------------------------------------------------------------

/// xorshift64*, seeded (warp-core's test generator).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn f(&mut self, lo: f32, hi: f32) -> f32 {
        let u = (self.next() >> 40) as f32 / (1u64 << 24) as f32;
        lo + (hi - lo) * u
    }
    fn d(&mut self, lo: f64, hi: f64) -> f64 {
        let u = (self.next() >> 11) as f64 / (1u64 << 53) as f64;
        lo + (hi - lo) * u
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn coin(&mut self, p: f32) -> bool {
        self.f(0.0, 1.0) < p
    }
}

/// A value as the driver reads it (`put`) and prints it (`pr`), and a random one.
trait Wire: Copy {
    fn put(&self, w: &mut Vec<u32>);
    fn pr(&self) -> String;
    fn rand(r: &mut Rng) -> Self;
}

impl Wire for f32 {
    fn put(&self, w: &mut Vec<u32>) {
        w.push(self.to_bits());
    }
    fn pr(&self) -> String {
        if self.is_nan() {
            " nan".into()
        } else {
            format!(" {:08x}", self.to_bits())
        }
    }
    fn rand(r: &mut Rng) -> Self {
        r.f(-4.0, 4.0)
    }
}
impl Wire for f64 {
    fn put(&self, w: &mut Vec<u32>) {
        let b = self.to_bits();
        w.push(b as u32);
        w.push((b >> 32) as u32);
    }
    fn pr(&self) -> String {
        if self.is_nan() {
            " nan".into()
        } else {
            format!(" {:016x}", self.to_bits())
        }
    }
    fn rand(r: &mut Rng) -> Self {
        r.d(-4.0, 4.0)
    }
}
impl Wire for i32 {
    fn put(&self, w: &mut Vec<u32>) {
        w.push(*self as u32);
    }
    fn pr(&self) -> String {
        format!(" {self}")
    }
    fn rand(r: &mut Rng) -> Self {
        r.next() as i32
    }
}
impl Wire for Vec3 {
    fn put(&self, w: &mut Vec<u32>) {
        for x in self.to_array() {
            x.put(w);
        }
    }
    fn pr(&self) -> String {
        self.to_array().iter().map(Wire::pr).collect()
    }
    fn rand(r: &mut Rng) -> Self {
        Vec3::new(f32::rand(r), f32::rand(r), f32::rand(r))
    }
}
impl Wire for DVec3 {
    fn put(&self, w: &mut Vec<u32>) {
        for x in self.to_array() {
            x.put(w);
        }
    }
    fn pr(&self) -> String {
        self.to_array().iter().map(Wire::pr).collect()
    }
    fn rand(r: &mut Rng) -> Self {
        DVec3::new(f64::rand(r), f64::rand(r), f64::rand(r))
    }
}
impl Wire for Mat3 {
    fn put(&self, w: &mut Vec<u32>) {
        for c in [self.x_axis, self.y_axis, self.z_axis] {
            c.put(w);
        }
    }
    fn pr(&self) -> String {
        [self.x_axis, self.y_axis, self.z_axis]
            .iter()
            .map(Wire::pr)
            .collect()
    }
    fn rand(r: &mut Rng) -> Self {
        Mat3::from_cols(Vec3::rand(r), Vec3::rand(r), Vec3::rand(r))
    }
}
impl Wire for DMat3 {
    fn put(&self, w: &mut Vec<u32>) {
        for c in [self.x_axis, self.y_axis, self.z_axis] {
            c.put(w);
        }
    }
    fn pr(&self) -> String {
        [self.x_axis, self.y_axis, self.z_axis]
            .iter()
            .map(Wire::pr)
            .collect()
    }
    fn rand(r: &mut Rng) -> Self {
        DMat3::from_cols(DVec3::rand(r), DVec3::rand(r), DVec3::rand(r))
    }
}

/// The little-endian bytes of a value.
fn le<T: Wire>(x: T) -> Vec<u8> {
    let mut w = Vec::new();
    x.put(&mut w);
    w.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// The driver's kind code of a grid's element type, and its grid type.
trait Kind: VolumeGrid {
    const KIND: u32;
    const TYPE: GridType;
}
impl Kind for f32 {
    const KIND: u32 = 0;
    const TYPE: GridType = GridType::Float;
}
impl Kind for f64 {
    const KIND: u32 = 1;
    const TYPE: GridType = GridType::Double;
}
impl Kind for i32 {
    const KIND: u32 = 2;
    const TYPE: GridType = GridType::Int32;
}
impl Kind for Vec3 {
    const KIND: u32 = 3;
    const TYPE: GridType = GridType::Vec3f;
}
impl Kind for DVec3 {
    const KIND: u32 = 4;
    const TYPE: GridType = GridType::Vec3d;
}
impl Kind for VoxelIndex {
    const KIND: u32 = 5;
    const TYPE: GridType = GridType::Index;
}

/// A fault as the driver prints it.
fn hfault(e: &Fault) -> String {
    match &e.kind {
        FaultKind::OutOfBounds { arg, index, shape } => {
            assert_eq!(*arg, DATA_NAME, "{e}");
            format!(
                " F 1 {DATA_ARG} 1 {:x} {}",
                index[0] as i64 as u64, shape[0]
            )
        }
        FaultKind::NonFinite { what, values } => {
            assert_eq!(*what, "volume sample position");
            let mut s = format!(" F 5 -1 {}", values.len());
            for v in values {
                s += &format!(" {:x}", v.to_bits());
            }
            s
        }
        k => panic!("unexpected fault kind {k:?}"),
    }
}

/// `r`'s value, or its fault, as the driver prints them.
fn show<T>(r: Result<T, Box<Fault>>, f: impl FnOnce(T) -> String) -> String {
    match r {
        Ok(x) => f(x),
        Err(e) => hfault(&e),
    }
}

// ------------------------------------------------------------------------------------------
// Grids
// ------------------------------------------------------------------------------------------

/// 32 bytes, 32-aligned: grid buffers are vectors of these.
#[repr(C, align(32))]
#[derive(Clone, Copy)]
struct A32([u8; 32]);

fn aligned(bytes: &[u8]) -> Vec<A32> {
    let mut v = vec![A32([0; 32]); bytes.len().div_ceil(32)];
    for (k, b) in bytes.iter().enumerate() {
        v[k / 32].0[k % 32] = *b;
    }
    v
}

/// FNV-1a 64.
fn digest(b: &[u8]) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    for &x in b {
        h ^= x as u64;
        h = h.wrapping_mul(0x100_0000_01b3);
    }
    h
}

/// A grid in an aligned buffer, with its gradient twin (value grids), as the views address
/// them (through the raw pointers only, once made).
struct Slot {
    id: u32,

    size: usize,
    _data: Vec<A32>,
    _grad: Vec<A32>,
    data: *mut u8,
    grad: *mut u8,
    /// The twin as built (its words that change are what the adjoints added).
    twin: Vec<u8>,
    info: GridInfo,
}

impl Slot {
    fn view<T: VolumeGrid>(&self) -> VolumeView<T> {
        // SAFETY: validated, aligned, alive as long as `self`; the twin is the same build
        // with zero values (and the same structural edit), so it has the grid's structure.
        unsafe { VolumeView::from_info(&self.info, self.data as u64, self.grad as u64) }
    }
    fn bytes(&self) -> &[u8] {
        // SAFETY: `size` bytes of `_data`; no view writes while the slice lives.
        unsafe { std::slice::from_raw_parts(self.data, self.size) }
    }
    /// The twin's changed words (offset:bits, as the driver prints them), then restored.
    fn grad_words(&self) -> String {
        let mut s = String::from(" |");
        if self.grad.is_null() {
            return s;
        }
        // SAFETY: `size` bytes of `_grad`, not otherwise borrowed now.
        let g = unsafe { std::slice::from_raw_parts_mut(self.grad, self.size) };
        // 4 KiB blocks compared first (memcmp): the twins are megabytes.
        for b in (0..self.size).step_by(4096) {
            let e = (b + 4096).min(self.size);
            if g[b..e] == self.twin[b..e] {
                continue;
            }
            for o in (b..e).step_by(4) {
                if g[o..o + 4] != self.twin[o..o + 4] {
                    let x = u32::from_le_bytes(g[o..o + 4].try_into().unwrap());
                    s += &format!(" {o:x}:{x:08x}");
                }
            }
            g[b..e].copy_from_slice(&self.twin[b..e]);
        }
        s
    }
}

fn u64_at(b: &[u8], o: usize) -> u64 {
    u64::from_le_bytes(b[o..o + 8].try_into().unwrap())
}

/// Random values at every location a lookup of a value grid can end (leaf values, internal
/// table entries without a child, root tile values, the background).
fn fill_values(
    b: &mut [u8],
    info: &GridInfo,
    rng: &mut Rng,
    mut val: impl FnMut(&mut Rng) -> Vec<u8>,
) {
    let l = info.layout;
    let mut put = |b: &mut [u8], o: usize, rng: &mut Rng| {
        let v = val(rng);
        b[o..o + v.len()].copy_from_slice(&v);
    };
    let root0 = info.root as usize;
    put(b, root0 + l.background, rng);
    for t in 0..info.tile_count as usize {
        put(b, root0 + l.root_size + t * l.tile_size + l.tile_value, rng);
    }
    let child =
        |b: &[u8], mask: usize, n: usize| (u64_at(b, mask + 8 * (n >> 6)) >> (n & 63)) & 1 == 1;
    for u in 0..info.upper_count as usize {
        let node = info.first_upper as usize + u * l.up_size;
        for n in 0..32768 {
            if !child(b, node + UPPER_CHILD_MASK, n) {
                put(b, node + l.up_table + n * l.stride, rng);
            }
        }
    }
    for u in 0..info.lower_count as usize {
        let node = info.first_lower as usize + u * l.lo_size;
        for n in 0..4096 {
            if !child(b, node + LOWER_CHILD_MASK, n) {
                put(b, node + l.lo_table + n * l.stride, rng);
            }
        }
    }
    for f in 0..info.leaf_count as usize {
        let leaf = info.first_leaf as usize + f * l.leaf_size;
        for n in 0..512 {
            put(b, leaf + l.leaf_table + n * l.value_size, rng);
        }
    }
}

/// Turns the root tile holding `ijk` into a value tile (child 0).
fn make_value_tile(b: &mut [u8], info: &GridInfo, ijk: [i32; 3]) {
    let l = info.layout;
    let key = root_key(ijk);
    for t in 0..info.tile_count as usize {
        let tile = info.root as usize + l.root_size + t * l.tile_size;
        if u64_at(b, tile + root::TILE_KEY) == key {
            b[tile + root::TILE_CHILD..tile + root::TILE_CHILD + 8].fill(0);
            return;
        }
    }
    panic!("no root tile holds {ijk:?}");
}

/// The case stream and the expected output.
#[derive(Default)]
struct Cases {
    words: Vec<u32>,
    want: Vec<String>,
    /// What each case is (for failure messages).
    what: Vec<String>,
    label: String,
    /// How many LINEAR taps of the value-grid samples ended at each level (0 leaf .. 4
    /// background), to check that every level is reached.
    levels: [usize; 5],
}

impl Cases {
    fn op(&mut self, op: u32) -> &mut Self {
        self.words.push(op);
        self
    }
    fn u(&mut self, x: u32) -> &mut Self {
        self.words.push(x);
        self
    }
    fn i(&mut self, x: i32) -> &mut Self {
        self.words.push(x as u32);
        self
    }
    fn put<T: Wire>(&mut self, x: T) -> &mut Self {
        x.put(&mut self.words);
        self
    }
    fn bytes(&mut self, b: &[u8]) -> &mut Self {
        for c in b.chunks(4) {
            let mut w = [0u8; 4];
            w[..c.len()].copy_from_slice(c);
            self.words.push(u32::from_le_bytes(w));
        }
        self
    }
    fn expect(&mut self, line: String) {
        self.want.push(line);
        self.what.push(self.label.clone());
    }

    /// Sends grid `bytes` (validated, then `edit`ed identically in grid and twin) to slot
    /// `id`.
    fn grid<T: Kind>(
        &mut self,
        id: u32,
        bytes: Vec<u8>,
        twin: Option<Vec<u8>>,
        edit: impl Fn(&mut [u8], &GridInfo),
    ) -> Slot {
        let info = validate(&bytes).expect("a valid grid");
        let (mut bytes, mut twin) = (bytes, twin);
        edit(&mut bytes, &info);
        if let Some(t) = twin.as_mut() {
            edit(t, &info);
        }
        let mut data = aligned(&bytes);
        let mut grad = twin.as_deref().map(aligned).unwrap_or_default();
        let slot = Slot {
            id,

            size: bytes.len(),
            data: data.as_mut_ptr().cast(),
            grad: if grad.is_empty() {
                std::ptr::null_mut()
            } else {
                grad.as_mut_ptr().cast()
            },
            _data: data,
            _grad: grad,
            twin: twin.unwrap_or_default(),
            info,
        };
        let view = slot.view::<T>();
        self.label = format!("grid {id} ({:?})", slot.info.grid_type);
        // SAFETY: a #[repr(C)] struct of plain words, read as its 104 bytes.
        let view_bytes = unsafe {
            std::slice::from_raw_parts(
                (&view as *const VolumeView<T>).cast::<u8>(),
                std::mem::size_of::<VolumeView<T>>(),
            )
        }
        .to_vec();
        self.op(1)
            .u(id)
            .u(T::KIND)
            .u(bytes.len() as u32)
            .u(view_bytes.len() as u32)
            .bytes(&view_bytes)
            .bytes(&bytes);
        self.expect(format!("grid {:016x}", digest(&bytes)));
        slot
    }

    fn sample<T: VolumeSample + Wire + Kind>(
        &mut self,
        s: &Slot,
        mode: i32,
        uvw: Vec3,
        rng: &mut Rng,
    ) where
        T::Grad: Wire,
    {
        let (ar, av, ag, au0) = (
            T::rand(rng),
            T::rand(rng),
            T::Grad::rand(rng),
            Vec3::rand(rng),
        );
        self.op(2)
            .u(s.id)
            .i(mode)
            .put(uvw)
            .put(ar)
            .put(av)
            .put(ag)
            .put(au0);
        let v = s.view::<T>();
        if uvw.is_finite() {
            let b = uvw.floor();
            for c in 0..8 {
                let p = [(b.x, c >> 2), (b.y, c >> 1), (b.z, c)]
                    .map(|(x, o)| (x as i64).saturating_add(o & 1));
                if p.iter().all(|&x| i32::try_from(x).is_ok()) {
                    self.levels[v.locate(p.map(|x| x as i32)).level as usize] += 1;
                }
            }
        }
        let mut line = String::from("s");
        line += &show(volume_sample(v, uvw, mode), |r| r.pr());
        line += " |";
        line += &show(volume_sample_grad(v, uvw, mode), |(r, g)| r.pr() + &g.pr());
        let (mut au, mut am) = (au0, 0);
        let r = adj_volume_sample(v, uvw, mode, &mut VolumeView::empty(), &mut au, &mut am, ar);
        line += " |";
        line += &show(r, |_| au.pr());
        line += &s.grad_words();
        au = au0;
        let r = adj_volume_sample_grad(
            v,
            uvw,
            mode,
            &mut VolumeView::empty(),
            &mut au,
            &mut am,
            (av, ag),
        );
        line += " |";
        line += &show(r, |_| au.pr());
        line += &s.grad_words();
        self.expect(line);
    }

    fn lookup<T: VolumeValue + Wire + Kind + warp_core::adjoint::Adjoint>(
        &mut self,
        s: &Slot,
        p: [i32; 3],
        rng: &mut Rng,
    ) {
        // An integer's adjoint is always zero (integers are not differentiable).
        let ar = if T::KIND == i32::KIND {
            T::zero()
        } else {
            T::rand(rng)
        };
        self.op(3).u(s.id).i(p[0]).i(p[1]).i(p[2]).put(ar);
        let v = s.view::<T>();
        let mut line = String::from("l");
        line += &volume_lookup(v, p[0], p[1], p[2]).unwrap().pr();
        let mut ai = 0;
        let (mut aj, mut ak) = (0, 0);
        adj_volume_lookup(
            v,
            p[0],
            p[1],
            p[2],
            &mut VolumeView::empty(),
            &mut ai,
            &mut aj,
            &mut ak,
            ar,
        )
        .unwrap();
        line += &s.grad_words();
        line += &volume_lookup_index(v, p[0], p[1], p[2]).unwrap().pr();
        self.expect(line);
    }

    fn lookup_index(&mut self, s: &Slot, p: [i32; 3]) {
        self.op(3).u(s.id).i(p[0]).i(p[1]).i(p[2]);
        let v = s.view::<VoxelIndex>();
        self.expect(format!(
            "l{}",
            volume_lookup_index(v, p[0], p[1], p[2]).unwrap().pr()
        ));
    }

    fn store<T: VolumeValue + Wire + Kind>(&mut self, s: &Slot, p: [i32; 3], rng: &mut Rng) {
        let x = T::rand(rng);
        self.op(4).u(s.id).i(p[0]).i(p[1]).i(p[2]).put(x);
        let v = s.view::<T>();
        volume_store(v, p[0], p[1], p[2], x).unwrap();
        let back = volume_lookup(v, p[0], p[1], p[2]).unwrap();
        self.expect(format!("w {:016x}{}", digest(s.bytes()), back.pr()));
    }

    fn xform<T: Kind>(&mut self, s: &Slot, p: Vec3, g: Vec3) {
        self.op(5).u(s.id).put(p).put(g);
        let v = s.view::<T>();
        let mut line = String::from("x");
        for r in [
            volume_index_to_world(v, p),
            volume_world_to_index(v, p),
            volume_index_to_world_dir(v, p),
            volume_world_to_index_dir(v, p),
        ] {
            line += &r.unwrap().pr();
        }
        let adjs: [TransformAdjoint<T>; 4] = [
            adj_volume_index_to_world,
            adj_volume_world_to_index,
            adj_volume_index_to_world_dir,
            adj_volume_world_to_index_dir,
        ];
        for f in adjs {
            let mut a = Vec3::ONE;
            f(v, p, &mut VolumeView::empty(), &mut a, g).unwrap();
            line += &a.pr();
        }
        self.expect(line);
    }

    /// The value array of kind `T` the index variants read from now on.
    fn data<T: Wire + Kind>(&mut self, d: &mut Data, n: usize, rng: &mut Rng) {
        let vals: Vec<T> = (0..n).map(|_| T::rand(rng)).collect();
        let bytes: Vec<u8> = vals.iter().flat_map(|&x| le(x)).collect();
        d.set(T::KIND, &bytes);
        self.op(7).u(T::KIND).u(bytes.len() as u32).bytes(&bytes);
        self.expect(format!("data {} {}", T::KIND, bytes.len()));
    }

    #[allow(clippy::too_many_arguments)]
    fn index<G: Kind, T: VolumeSample + Wire + Kind + warp_core::GradElement>(
        &mut self,
        s: &Slot,
        d: &Data,
        mode: i32,
        uvw: Vec3,
        rng: &mut Rng,
    ) where
        T::Grad: Wire,
    {
        let (bg, ar, av, ag, au0) = (
            T::rand(rng),
            T::rand(rng),
            T::rand(rng),
            T::Grad::rand(rng),
            Vec3::rand(rng),
        );
        self.op(6)
            .u(s.id)
            .u(T::KIND)
            .i(mode)
            .put(uvw)
            .put(bg)
            .put(ar)
            .put(av)
            .put(ag)
            .put(au0);
        let v = s.view::<G>();
        let data = d.view::<T>();
        let mut line = String::from("i");
        line += &show(volume_sample_index(v, uvw, mode, &data, bg), |r| r.pr());
        line += " |";
        line += &show(
            volume_sample_grad_index(v, uvw, mode, &data, bg),
            |(r, g)| r.pr() + &g.pr(),
        );
        let (mut au, mut am, mut abg) = (au0, 0, T::zero());
        let r = adj_volume_sample_index(
            v,
            uvw,
            mode,
            &data,
            bg,
            &mut VolumeView::empty(),
            &mut au,
            &mut am,
            &mut GradView::none(),
            &mut abg,
            ar,
        );
        line += " |";
        line += &show(r, |_| au.pr() + &abg.pr());
        au = au0;
        abg = T::zero();
        let r = adj_volume_sample_grad_index(
            v,
            uvw,
            mode,
            &data,
            bg,
            &mut VolumeView::empty(),
            &mut au,
            &mut am,
            &mut GradView::none(),
            &mut abg,
            (av, ag),
        );
        line += " |";
        line += &show(r, |_| au.pr() + &abg.pr());
        self.expect(line);
    }
}

/// The signature of the transforms' adjoints.
type TransformAdjoint<T> =
    fn(VolumeView<T>, Vec3, &mut VolumeView<T>, &mut Vec3, Vec3) -> warp_core::KResult<()>;

/// The value arrays of the index variants on the Rust side (aligned, one per kind).
#[derive(Default)]
struct Data {
    bufs: [Vec<A32>; 5],
    lens: [usize; 5],
}

impl Data {
    fn set(&mut self, kind: u32, bytes: &[u8]) {
        self.bufs[kind as usize] = aligned(bytes);
        self.lens[kind as usize] = bytes.len();
    }
    fn view<T: Kind>(&self) -> ArrayView<T, 1> {
        let k = T::KIND as usize;
        let n = self.lens[k] / std::mem::size_of::<T>();
        // SAFETY: `n` elements of T in the aligned buffer, alive and unchanged while the view
        // is used (within one case).
        unsafe {
            ArrayView::new(
                self.bufs[k].as_ptr() as *mut T,
                [n],
                [1],
                "driver",
                DATA_NAME,
            )
        }
    }
}

// ------------------------------------------------------------------------------------------
// Cases
// ------------------------------------------------------------------------------------------

/// The tiles of the test grids: a dense block around the origin (negative and positive,
/// leaf boundaries), leaves on both sides of lower (128) and upper (4096) node boundaries,
/// leaves at both ends of the i32 range, and the upper that becomes a value tile.
fn tiles() -> Vec<[i32; 3]> {
    let mut t = Vec::new();
    for i in (-16..16).step_by(8) {
        for j in (-16..16).step_by(8) {
            for k in (-16..16).step_by(8) {
                t.push([i, j, k]);
            }
        }
    }
    t.extend_from_slice(&[
        [120, 0, 0],
        [128, 0, 0],
        [-136, 8, 0],
        [-128, 8, 0],
        [4088, 0, 0],
        [4096, 0, 0],
        [-4104, -8, 16],
        [-4096, -8, 16],
        [8, 3, -9],
        [2147483640, 0, 0],
        [2147483520, 0, 0],
        [-2147483648, -2147483648, -2147483648],
        [0, 2147483000, -2147483000],
        VALUE_TILE,
    ]);
    t
}

/// A voxel of the upper node made a value tile.
const VALUE_TILE: [i32; 3] = [-9000, 5000, 300];

/// Where samples go: around these voxels.
fn centres() -> Vec<[i32; 3]> {
    let mut c = tiles()[64..].to_vec();
    c.extend_from_slice(&[
        [0, 0, 0],
        [-8, -8, -8],
        [7, 7, 7],
        [300, 40, -20],
        [-2000, 100, 3000],
    ]);
    c
}

fn maps() -> [Map; 2] {
    [
        Map {
            mat: [[1.0, 2.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 3.0]],
            translation: [0.5, -1.25, 3.0],
        },
        Map {
            mat: [[0.3, -0.1, 0.05], [0.02, 0.25, -0.07], [0.11, 0.0, 0.4]],
            translation: [10.1, -3.3, 7.7],
        },
    ]
}

/// Sample positions: random around the centres and in a wide box, integers and halves,
/// the edges of the i32 range, huge and non-finite coordinates.
fn positions(rng: &mut Rng, n: usize) -> Vec<Vec3> {
    let centres = centres();
    let mut p = Vec::new();
    let specials = [
        0.0f32,
        -0.0,
        0.5,
        -0.5,
        2.5,
        -2.5,
        7.5,
        8.0,
        -8.0,
        -9.0,
        -1.0,
        127.5,
        128.0,
        -128.5,
        4095.5,
        4096.0,
        -4096.5,
        -4097.0,
        1e10,
        -1e10,
        3e38,
        -3e38,
        2147483520.0,
        2147483648.0,
        -2147483648.0,
        -2147483904.0,
    ];
    let nonfinite = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY];
    while p.len() < n {
        let k = rng.below(10);
        let v = match k {
            0..=4 => {
                let c = centres[rng.below(centres.len())];
                let o = |r: &mut Rng| r.f(-12.0, 20.0);
                Vec3::new(
                    c[0] as f32 + o(rng),
                    c[1] as f32 + o(rng),
                    c[2] as f32 + o(rng),
                )
            }
            5 => Vec3::new(rng.f(-20.0, 20.0), rng.f(-20.0, 20.0), rng.f(-20.0, 20.0)),
            6 => Vec3::new(
                rng.f(-5000.0, 5000.0),
                rng.f(-5000.0, 5000.0),
                rng.f(-5000.0, 5000.0),
            ),
            7 => {
                // Integers and halves near the origin and the centres.
                let c = centres[rng.below(centres.len())];
                let o = |r: &mut Rng| (r.below(40) as f32 - 20.0) * 0.5;
                let base = if rng.coin(0.5) { [0; 3] } else { c };
                Vec3::new(
                    base[0] as f32 + o(rng),
                    base[1] as f32 + o(rng),
                    base[2] as f32 + o(rng),
                )
            }
            8 => {
                let mut a = [0.0f32; 3];
                for x in &mut a {
                    *x = if rng.coin(0.5) {
                        specials[rng.below(specials.len())]
                    } else {
                        rng.f(-10.0, 10.0)
                    };
                }
                Vec3::from_array(a)
            }
            _ => {
                let mut a = [rng.f(-10.0, 10.0), rng.f(-10.0, 10.0), rng.f(-10.0, 10.0)];
                a[rng.below(3)] = nonfinite[rng.below(3)];
                if rng.coin(0.3) {
                    a[rng.below(3)] = nonfinite[rng.below(3)];
                }
                Vec3::from_array(a)
            }
        };
        p.push(v);
    }
    p
}

/// Voxel coordinates for lookups and stores: around the centres, at node boundaries, at the
/// ends of the i32 range, in the value tile's upper.
fn voxels(rng: &mut Rng, n: usize) -> Vec<[i32; 3]> {
    let centres = centres();
    let ends = [
        i32::MIN,
        i32::MIN + 1,
        i32::MAX,
        i32::MAX - 1,
        -1,
        0,
        127,
        128,
        -129,
        4095,
        4096,
        -4097,
    ];
    (0..n)
        .map(|_| {
            if rng.coin(0.2) {
                [0, 1, 2].map(|_| {
                    if rng.coin(0.6) {
                        ends[rng.below(ends.len())]
                    } else {
                        rng.below(40) as i32 - 20
                    }
                })
            } else {
                let c = centres[rng.below(centres.len())];
                c.map(|x| x.wrapping_add(rng.below(40) as i32 - 12))
            }
        })
        .collect()
}

fn modes(rng: &mut Rng) -> i32 {
    [0, 1, 1, 1, 0, 2, -1][rng.below(7)]
}

/// A value grid of T over the test tiles, with random values everywhere and the value tile.
fn value_grid<T: Kind + Wire + VolumeValue>(
    c: &mut Cases,
    id: u32,
    map: &Map,
    rng: &mut Rng,
) -> Slot {
    let build = |bg: T| {
        build_from_tiles(
            BuildKind::Value {
                grid_type: T::TYPE,
                background: &le(bg),
            },
            &tiles(),
            map,
        )
        .expect("built")
    };
    let bytes = build(T::rand(rng));
    let twin = build(T::zero());
    let info = validate(&bytes).expect("valid");
    let mut bytes = bytes;
    fill_values(&mut bytes, &info, rng, |r| le(T::rand(r)));
    c.grid::<T>(id, bytes, Some(twin), |b, info| {
        make_value_tile(b, info, VALUE_TILE)
    })
}

fn float_grid_cases<T: Kind + Wire + VolumeSample + warp_core::adjoint::Adjoint>(
    c: &mut Cases,
    id: u32,
    map: &Map,
    rng: &mut Rng,
    n: usize,
) -> Slot
where
    T::Grad: Wire,
{
    let s = value_grid::<T>(c, id, map, rng);
    c.label = format!("{:?} samples", T::TYPE);
    for p in positions(rng, n) {
        let m = modes(rng);
        c.sample::<T>(&s, m, p, rng);
    }
    c.label = format!("{:?} lookups", T::TYPE);
    for p in voxels(rng, n / 4) {
        c.lookup::<T>(&s, p, rng);
    }
    c.label = format!("{:?} transforms", T::TYPE);
    for p in positions(rng, 20) {
        c.xform::<T>(&s, p, Vec3::rand(rng));
    }
    c.label = format!("{:?} stores", T::TYPE);
    for p in voxels(rng, n / 8) {
        c.store::<T>(&s, p, rng);
    }
    // Samples again, over the stored values.
    c.label = format!("{:?} samples after stores", T::TYPE);
    for p in positions(rng, n / 4) {
        let m = modes(rng);
        c.sample::<T>(&s, m, p, rng);
    }
    s
}

/// The index variants on grid `s` with value arrays of every kind, `needed` values long
/// (and, for the fault cases, shorter).
fn index_cases<G: Kind>(c: &mut Cases, s: &Slot, needed: usize, rng: &mut Rng, n: usize) {
    let mut d = Data::default();
    for short in [false, true] {
        let len = if short { needed / 3 } else { needed };
        c.label = format!(
            "index variants on {:?} (data {len} of {needed})",
            s.info.grid_type
        );
        c.data::<f32>(&mut d, len, rng);
        c.data::<f64>(&mut d, len, rng);
        c.data::<Vec3>(&mut d, len, rng);
        c.data::<DVec3>(&mut d, len, rng);
        for p in positions(rng, n) {
            let m = modes(rng);
            match rng.below(4) {
                0 => c.index::<G, f32>(s, &d, m, p, rng),
                1 => c.index::<G, f64>(s, &d, m, p, rng),
                2 => c.index::<G, Vec3>(s, &d, m, p, rng),
                _ => c.index::<G, DVec3>(s, &d, m, p, rng),
            }
        }
    }
}

fn layout_case(c: &mut Cases) {
    use std::mem::{align_of, size_of};
    c.label = "layout".into();
    c.op(0);
    // Field offsets of VolumeView (its docs' table): grid_type 40, background 60, value_size 92.
    c.expect(format!(
        "layout {} {} 40 60 92 {} {}",
        size_of::<VolumeView<f32>>(),
        align_of::<VolumeView<f32>>(),
        size_of::<VolumeView<DVec3>>(),
        size_of::<VolumeView<VoxelIndex>>(),
    ));
}

fn all_cases() -> Cases {
    let mut c = Cases::default();
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
    layout_case(&mut c);
    let [m0, m1] = maps();
    let n = 600;
    let f = float_grid_cases::<f32>(&mut c, 0, &m0, &mut rng, n);
    float_grid_cases::<f64>(&mut c, 1, &m1, &mut rng, n);
    float_grid_cases::<Vec3>(&mut c, 2, &m1, &mut rng, n);
    float_grid_cases::<DVec3>(&mut c, 3, &m0, &mut rng, n);

    // i32: lookups, stores, transforms.
    let s = value_grid::<i32>(&mut c, 4, &m0, &mut rng);
    c.label = "Int32 lookups and stores".into();
    for p in voxels(&mut rng, 150) {
        c.lookup::<i32>(&s, p, &mut rng);
        c.store::<i32>(&s, p, &mut rng);
    }
    c.xform::<i32>(&s, Vec3::new(1.5, -2.0, 3.25), Vec3::new(-0.5, 2.0, 1.0));

    // Index grids: the same tiles (Index) and random voxels (OnIndex).
    let index = c.grid::<VoxelIndex>(
        5,
        build_from_tiles(BuildKind::Index, &tiles(), &m1).expect("built"),
        None,
        |b, info| make_value_tile(b, info, VALUE_TILE),
    );
    let mut vox: Vec<[i32; 3]> = voxels(&mut rng, 3000);
    vox.extend((0..2000).map(|_| [0, 1, 2].map(|_| rng.below(40) as i32 - 20)));
    let onindex = c.grid::<VoxelIndex>(
        6,
        build_from_voxels(&vox, &m0).expect("built"),
        None,
        |_, _| {},
    );
    for (s, name) in [(&index, "Index"), (&onindex, "OnIndex")] {
        c.label = format!("{name} lookup_index");
        for p in voxels(&mut rng, 300) {
            c.lookup_index(s, p);
        }
        for p in vox.iter().take(300) {
            c.lookup_index(s, *p);
        }
        c.label = format!("{name} transforms");
        for p in positions(&mut rng, 10) {
            c.xform::<VoxelIndex>(s, p, Vec3::rand(&mut rng));
        }
    }
    let leaves = |s: &Slot| s.info.leaf_count as usize * 512;
    index_cases::<VoxelIndex>(&mut c, &index, leaves(&index), &mut rng, 400);
    let active = u64_at(onindex.bytes(), grid::DATA1) as usize - 1;
    index_cases::<VoxelIndex>(&mut c, &onindex, active, &mut rng, 400);
    // On value grids: idx = leafId * 512 + n + 1.
    index_cases::<f32>(&mut c, &f, leaves(&f), &mut rng, 300);
    index_cases::<i32>(&mut c, &s, leaves(&s), &mut rng, 300);
    c
}

#[test]
fn cuda_volume_matches_warp_core_bit_for_bit() {
    if !host_cpp::gpp() {
        eprintln!("SKIPPED cuda_volume_matches_warp_core_bit_for_bit: no g++");
        return;
    }
    let c = all_cases();
    let (dir, exe) = host_cpp::compile_driver("cuda_volume", DRIVER, &[]);
    let input = dir.join("cases.bin");
    let bytes: Vec<u8> = c.words.iter().flat_map(|w| w.to_le_bytes()).collect();
    std::fs::write(&input, bytes).unwrap();
    let run = Command::new(&exe).arg(&input).output().unwrap();
    assert!(
        run.status.success(),
        "driver: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    let text = String::from_utf8(run.stdout).unwrap();
    let got: Vec<&str> = text.lines().collect();
    assert_eq!(got.len(), c.want.len(), "one line per case");
    let mut bad = Vec::new();
    for (k, (g, w)) in got.iter().zip(&c.want).enumerate() {
        if g != w {
            bad.push(format!(
                "case {k} ({}):\n  C++:  {}\n  Rust: {}",
                c.what[k],
                &g[..g.len().min(600)],
                &w[..w.len().min(600)]
            ));
        }
    }
    // What the cases reached (so that a change that stops exercising something shows).
    let count = |pat: &str| c.want.iter().filter(|l| l.contains(pat)).count();
    let (non_finite, oob) = (count(" F 5 "), count(" F 1 "));
    let twin_adds = c
        .want
        .iter()
        .filter(|l| l.starts_with('s') && l.contains(':'))
        .count();
    eprintln!(
        "{} cases: {} NonFinite faults, {} OutOfBounds faults, {} samples adding into a twin, \
         taps per level {:?}; {} mismatches",
        c.want.len(),
        non_finite,
        oob,
        twin_adds,
        c.levels,
        bad.len()
    );
    assert!(
        bad.is_empty(),
        "{} of {} cases differ:\n{}",
        bad.len(),
        c.want.len(),
        bad[..bad.len().min(20)].join("\n")
    );
    assert!(
        non_finite > 100 && oob > 100 && twin_adds > 500 && c.levels.iter().all(|&n| n >= 50),
        "too few cases of a kind"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// NVRTC accepts the headers, every builtin and adjoint instantiated in a kernel for every
/// grid type, for sm_90 and sm_80 with `--fmad=false`: needs libnvrtc, no GPU; skipped,
/// saying so, without it.
#[test]
fn nvrtc_compiles_the_volume_headers() {
    if let Err(e) = warp_cuda::nvrtc_version() {
        eprintln!("SKIPPED nvrtc_compiles_the_volume_headers: {e}");
        return;
    }
    let source = r#"
#define WP_ADJOINT_UNIT 1
#include "wp_core.h"
#include "wp_volume.h"
#include "wp_adjoint_core.h"
#include "wp_adjoint_volume.h"
template <typename T>
__device__ void all_float(wp::volume_t<T> v, wp::Vec3 p, wp::ctx_t* c, T* o, wp::Vec3* ou) {
  using namespace wp;
  volume_t<T> av = adj_zero<volume_t<T>>();
  Vec3 au = Vec3_ZERO();
  i32 am = 0, ai = 0;
  const T r = volume_sample(v, p, 1, c);
  const auto g = volume_sample_grad(v, p, 0, c);
  adj_volume_sample(v, p, 1, av, au, am, r, c);
  adj_volume_sample_grad(v, p, 1, av, au, am, g, c);
  const T l = volume_lookup(v, 1, -2, 3, c);
  adj_volume_lookup(v, 1, -2, 3, av, ai, ai, ai, l, c);
  volume_store(v, 1, -2, 3, l, c);
  array_t<T, 1> d = {}, ad = {};
  d.data = o + 8;
  d.shape[0] = 4;
  d.strides[0] = sizeof(T);
  T abg = r;
  const T s = volume_sample_index(v, p, 1, d, r, c);
  const auto sg = volume_sample_grad_index(v, p, 1, d, r, c);
  adj_volume_sample_index(v, p, 1, d, r, av, au, am, ad, abg, s, c);
  adj_volume_sample_grad_index(v, p, 1, d, r, av, au, am, ad, abg, sg, c);
  au += volume_index_to_world(v, p, c) + volume_world_to_index(v, p, c) +
        volume_index_to_world_dir(v, p, c) + volume_world_to_index_dir(v, p, c);
  adj_volume_index_to_world(v, p, av, au, p, c);
  adj_volume_world_to_index(v, p, av, au, p, c);
  adj_volume_index_to_world_dir(v, p, av, au, p, c);
  adj_volume_world_to_index_dir(v, p, av, au, p, c);
  o[0] = r;
  o[1] = g.f0;
  o[2] = s;
  o[3] = sg.f0;
  o[4] = abg;
  ou[0] = au;
}
extern "C" __global__ void volume_all(wp::volume_t<float> a, wp::volume_t<double> b,
                                      wp::volume_t<wp::Vec3> v3, wp::volume_t<wp::DVec3> d3,
                                      wp::volume_t<int> e, wp::volume_t<wp::VoxelIndex> x,
                                      float* o1, double* o2, wp::Vec3* o3, wp::DVec3* o4,
                                      int* o5, wp::fault_t* fault, wp::u32* flag) {
  using namespace wp;
  launch_ctx_t rec = launch_ctx_make(fault, flag);
  ctx_t c = ctx_make(&rec);
  const Vec3 p = o3[threadIdx.x];
  all_float(a, p, &c, o1, o3);
  all_float(b, p, &c, o2, o3);
  all_float(v3, p, &c, o3, o3);
  all_float(d3, p, &c, o4, o3);
  volume_t<int> ae = adj_zero<volume_t<int>>();
  i32 ai = 0;
  o5[0] = volume_lookup(e, 1, 2, 3, &c) + volume_lookup_index(x, 1, 2, 3, &c) +
          volume_lookup_index(e, 1, 2, 3, &c);
  volume_store(e, 1, 2, 3, o5[1], &c);
  adj_volume_lookup(e, 1, 2, 3, ae, ai, ai, ai, o5[0], &c);
  array_t<float, 1> d = {};
  o1[10] = volume_sample_index(x, p, 1, d, 0.0f, &c) +
           volume_sample_grad_index(x, p, 1, d, 0.0f, &c).f0;
  o3[10] = volume_index_to_world(x, p, &c);
}
"#;
    let headers: Vec<(&str, &str)> = warp_cuda::HEADERS.to_vec();
    for arch in [90, 80] {
        let opts = warp_cuda::CompileOptions {
            fmad: false,
            headers: &headers,
            ..Default::default()
        };
        let c = warp_cuda::compile(source, "volume_all.cu", &opts, arch)
            .unwrap_or_else(|e| panic!("sm_{arch}: {e}"));
        assert!(!c.cubin.is_empty());
        assert!(!c.log.contains("warning"), "sm_{arch}: {}", c.log);
    }
}

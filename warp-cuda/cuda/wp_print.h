// wp_print.h: `print_value(x)` for the emitter's `print!`/`println!` lowering, which emits
// printf for the literal text and one print_value call per `{}` argument.
//
// Format: Rust's Display, approximately.
//   * integers and bool: exactly as Rust (`-3`, `18446744073709551615`, `true`);
//   * floats: printf "%g" (6 significant digits), except NaN -> "NaN" (Rust's spelling).
//     Rust prints the shortest string that round-trips and never uses an exponent, so the
//     two agree on short values (`1`, `-2.5`, `0.1`, `inf`, `-0`) but not on others:
//     1/3 prints `0.333333` (Rust `0.33333334`), 1e7 prints `1e+07` (Rust `10000000`).
//   * vectors and quaternions: `[x, y, z]`; matrices: `[[col0], [col1], ...]` (glam's Display);
//     transforms: `{p: [x, y, z], q: [x, y, z, w]}` (warp-core's Display); spatial vectors
//     `[a, .., f]`, spatial matrices `[[row0], .., [row5]]`.
// Device printf output of different threads may interleave between print_value calls.
#pragma once
#include "wp_core.h"

namespace wp {

WP_LFN void print_value(bool x) { printf("%s", x ? "true" : "false"); }
WP_LFN void print_value(i8 x) { printf("%d", (int)x); }
WP_LFN void print_value(i16 x) { printf("%d", (int)x); }
WP_LFN void print_value(i32 x) { printf("%d", x); }
WP_LFN void print_value(i64 x) { printf("%lld", x); }
WP_LFN void print_value(u8 x) { printf("%u", (unsigned)x); }
WP_LFN void print_value(u16 x) { printf("%u", (unsigned)x); }
WP_LFN void print_value(u32 x) { printf("%u", x); }
WP_LFN void print_value(u64 x) { printf("%llu", x); }
WP_LFN void print_value(f64 x) {
  if (x != x)
    printf("NaN");
  else
    printf("%g", x);
}
WP_LFN void print_value(f32 x) { print_value((f64)x); }
WP_LFN void print_value(f16 x) { print_value((f64)f16_to_f32(x)); }
WP_LFN void print_value(bf16 x) { print_value((f64)bf16_to_f32(x)); }

namespace detail {
template <typename V>
WP_FN void print_components(const V& v) {
  printf("[");
  for (int i = 0; i < vec_traits<V>::N; ++i) {
    if (i > 0) printf(", ");
    print_value(vec_traits<V>::get(v, i));
  }
  printf("]");
}
template <typename M>
WP_FN void print_columns(const M& m) {
  printf("[");
  for (int i = 0; i < mat_traits<M>::N; ++i) {
    if (i > 0) printf(", ");
    print_components(mat_traits<M>::get(m, i));
  }
  printf("]");
}
}  // namespace detail

#define WP_PRINT_VEC(V) \
  WP_LFN void print_value(const V& v) { detail::print_components(v); }
WP_PRINT_VEC(Vec2)
WP_PRINT_VEC(Vec3)
WP_PRINT_VEC(Vec4)
WP_PRINT_VEC(DVec2)
WP_PRINT_VEC(DVec3)
WP_PRINT_VEC(DVec4)
WP_PRINT_VEC(IVec2)
WP_PRINT_VEC(IVec3)
WP_PRINT_VEC(IVec4)
WP_PRINT_VEC(UVec2)
WP_PRINT_VEC(UVec3)
WP_PRINT_VEC(UVec4)
WP_PRINT_VEC(Quat)
WP_PRINT_VEC(DQuat)
#undef WP_PRINT_VEC
#define WP_PRINT_MAT(M) \
  WP_LFN void print_value(const M& m) { detail::print_columns(m); }
WP_PRINT_MAT(Mat2)
WP_PRINT_MAT(Mat3)
WP_PRINT_MAT(Mat4)
WP_PRINT_MAT(DMat2)
WP_PRINT_MAT(DMat3)
WP_PRINT_MAT(DMat4)
#undef WP_PRINT_MAT
/// Transforms: `{p: [x, y, z], q: [x, y, z, w]}` (warp-core's Display).
#define WP_PRINT_XFORM(X)                  \
  WP_LFN void print_value(const X& t) {     \
    printf("{p: ");                        \
    detail::print_components(t.p);         \
    printf(", q: ");                       \
    detail::print_components(t.q);         \
    printf("}");                           \
  }
WP_PRINT_XFORM(Transform)
WP_PRINT_XFORM(DTransform)
#undef WP_PRINT_XFORM
/// Spatial vectors: `[a, b, c, d, e, f]`; spatial matrices: `[[row0], .., [row5]]`
/// (warp-core's Display).
#define WP_PRINT_SPATIAL(SV, SM)                                        \
  WP_LFN void print_value(const SV& v) { detail::print_components(v); } \
  WP_LFN void print_value(const SM& m) {                                 \
    printf("[");                                                        \
    for (int i = 0; i < 6; ++i) {                                       \
      if (i > 0) printf(", ");                                          \
      detail::print_components(SM##_row(m, i));                         \
    }                                                                   \
    printf("]");                                                        \
  }
WP_PRINT_SPATIAL(SpatialVector, SpatialMatrix)
WP_PRINT_SPATIAL(DSpatialVector, DSpatialMatrix)
#undef WP_PRINT_SPATIAL

}  // namespace wp

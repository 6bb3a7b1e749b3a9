// wp_matrix.h: the non-square matrices (warp-core/src/matrix.rs): Mat23 .. Mat64 and their f64
// twins DMat23 .. DMat64, every R x C with R != C in {2, 3, 4, 6}.
//
// A matrix is its R rows f0.. (row-major, as Warp's mat_t<R, C>), each the vector of the
// column count: Vec2-4 / DVec2-4, or a spatial vector for six columns; no padding (a kernel's
// `m[(i, j)]` is `m.fi.<lane j>`). Every sum is formed left to right in ascending index, as
// warp-core's:
//
//   + - (unary -) * and / by the scalar, ==, !=    lane by lane
//   m * x                                          lane i: sum_k m[i][k] x[k]
//   a * b (a non-square, or b; the other may be a  entry (i, j): sum_k a[i][k] b[k][j]; the
//     glam square or a spatial matrix)             matrix of that shape (mat_of)
//   transpose(m), outer(a, b) (vectors of          entry (i, j) of outer: a[i] b[j]
//     different lengths), ddot(a, b)               ddot: row by row
//   Mat23_from_rows(r0, r1), Mat23_ZERO(); local_get/local_set/local_at of a row (m[i]).
#pragma once
#include "wp_linalg.h"
#include "wp_spatial.h"

namespace wp {

struct Mat23 { Vec3 f0, f1; };
struct Mat24 { Vec4 f0, f1; };
struct Mat26 { SpatialVector f0, f1; };
struct Mat32 { Vec2 f0, f1, f2; };
struct Mat34 { Vec4 f0, f1, f2; };
struct Mat36 { SpatialVector f0, f1, f2; };
struct Mat42 { Vec2 f0, f1, f2, f3; };
struct Mat43 { Vec3 f0, f1, f2, f3; };
struct Mat46 { SpatialVector f0, f1, f2, f3; };
struct Mat62 { Vec2 f0, f1, f2, f3, f4, f5; };
struct Mat63 { Vec3 f0, f1, f2, f3, f4, f5; };
struct Mat64 { Vec4 f0, f1, f2, f3, f4, f5; };
struct DMat23 { DVec3 f0, f1; };
struct DMat24 { DVec4 f0, f1; };
struct DMat26 { DSpatialVector f0, f1; };
struct DMat32 { DVec2 f0, f1, f2; };
struct DMat34 { DVec4 f0, f1, f2; };
struct DMat36 { DSpatialVector f0, f1, f2; };
struct DMat42 { DVec2 f0, f1, f2, f3; };
struct DMat43 { DVec3 f0, f1, f2, f3; };
struct DMat46 { DSpatialVector f0, f1, f2, f3; };
struct DMat62 { DVec2 f0, f1, f2, f3, f4, f5; };
struct DMat63 { DVec3 f0, f1, f2, f3, f4, f5; };
struct DMat64 { DVec4 f0, f1, f2, f3, f4, f5; };

namespace detail {
template <bool B, typename T = void>
struct rc_enable {};
template <typename T>
struct rc_enable<true, T> {
  typedef T type;
};
}  // namespace detail

/// A float vector's scalar and length (glam's float vectors, the spatial vectors).
template <typename V>
struct vshape {
  static constexpr bool is_vec = false;
  static constexpr int N = 0;
  typedef void scalar;
};
#define WP_VSHAPE(V, S, NN)                 \
  template <>                               \
  struct vshape<V> {                        \
    static constexpr bool is_vec = true;    \
    static constexpr int N = NN;            \
    typedef S scalar;                       \
  };
WP_VSHAPE(Vec2, f32, 2)
WP_VSHAPE(Vec3, f32, 3)
WP_VSHAPE(Vec4, f32, 4)
WP_VSHAPE(SpatialVector, f32, 6)
WP_VSHAPE(DVec2, f64, 2)
WP_VSHAPE(DVec3, f64, 3)
WP_VSHAPE(DVec4, f64, 4)
WP_VSHAPE(DSpatialVector, f64, 6)
#undef WP_VSHAPE

/// The vector of length N of scalar S, the matrix of shape R x C (glam's square ones, the
/// spatial matrices, this header's).
template <typename S, int N>
struct vec_of;
template <typename S, int R, int C>
struct mat_of;
#define WP_VEC_OF(V, S, N) \
  template <>              \
  struct vec_of<S, N> {    \
    typedef V type;        \
  };
WP_VEC_OF(Vec2, f32, 2)
WP_VEC_OF(Vec3, f32, 3)
WP_VEC_OF(Vec4, f32, 4)
WP_VEC_OF(SpatialVector, f32, 6)
WP_VEC_OF(DVec2, f64, 2)
WP_VEC_OF(DVec3, f64, 3)
WP_VEC_OF(DVec4, f64, 4)
WP_VEC_OF(DSpatialVector, f64, 6)
#undef WP_VEC_OF

/// A matrix as its entries (i, j): `mshape<M>::get(m, i, j)`, `at`; R, C, its scalar.
template <typename M>
struct mshape {
  static constexpr bool is_mat = false;
  static constexpr bool is_rc = false;
  static constexpr int R = 0;
  static constexpr int C = 0;
  typedef void scalar;
};
// glam: column-major, mat_traits' columns.
#define WP_MSHAPE_GLAM(M, S, N)                                                               \
  template <>                                                                                 \
  struct mshape<M> {                                                                          \
    static constexpr bool is_mat = true;                                                      \
    static constexpr bool is_rc = false;                                                      \
    static constexpr int R = N;                                                               \
    static constexpr int C = N;                                                               \
    typedef S scalar;                                                                         \
    typedef mat_traits<M>::column V;                                                          \
    static WP_FN S get(const M& m, int i, int j) { return vec_traits<V>::get(mat_traits<M>::get(m, j), i); } \
    static WP_FN S& at(M& m, int i, int j) { return vec_traits<V>::at(mat_traits<M>::at(m, j), i); } \
  };                                                                                          \
  template <>                                                                                 \
  struct mat_of<S, N, N> {                                                                    \
    typedef M type;                                                                           \
  };
WP_MSHAPE_GLAM(Mat2, f32, 2)
WP_MSHAPE_GLAM(Mat3, f32, 3)
WP_MSHAPE_GLAM(Mat4, f32, 4)
WP_MSHAPE_GLAM(DMat2, f64, 2)
WP_MSHAPE_GLAM(DMat3, f64, 3)
WP_MSHAPE_GLAM(DMat4, f64, 4)
#undef WP_MSHAPE_GLAM
#define WP_MSHAPE_SPATIAL(M, S)                                                               \
  template <>                                                                                 \
  struct mshape<M> {                                                                          \
    static constexpr bool is_mat = true;                                                      \
    static constexpr bool is_rc = false;                                                      \
    static constexpr int R = 6;                                                               \
    static constexpr int C = 6;                                                               \
    typedef S scalar;                                                                         \
    static WP_FN S get(const M& m, int i, int j) { return vec_traits<M>::get(m, i * 6 + j); } \
    static WP_FN S& at(M& m, int i, int j) { return vec_traits<M>::at(m, i * 6 + j); }         \
  };                                                                                          \
  template <>                                                                                 \
  struct mat_of<S, 6, 6> {                                                                    \
    typedef M type;                                                                           \
  };
WP_MSHAPE_SPATIAL(SpatialMatrix, f32)
WP_MSHAPE_SPATIAL(DSpatialMatrix, f64)
#undef WP_MSHAPE_SPATIAL

// The rows at a run-time index.
#define WP_PICK2(x, i) (i == 0 ? x.f0 : x.f1)
#define WP_PICK3(x, i) (i == 0 ? x.f0 : i == 1 ? x.f1 : x.f2)
#define WP_PICK4(x, i) (i == 0 ? x.f0 : i == 1 ? x.f1 : i == 2 ? x.f2 : x.f3)
#define WP_PICK6(x, i) \
  (i == 0 ? x.f0 : i == 1 ? x.f1 : i == 2 ? x.f2 : i == 3 ? x.f3 : i == 4 ? x.f4 : x.f5)
#define WP_RC(M, S, RR, CC, ROW, PICK)                                                         \
  template <>                                                                                 \
  struct mshape<M> {                                                                          \
    static constexpr bool is_mat = true;                                                      \
    static constexpr bool is_rc = true;                                                       \
    static constexpr int R = RR;                                                              \
    static constexpr int C = CC;                                                              \
    typedef S scalar;                                                                         \
    typedef ROW row;                                                                          \
    static WP_FN const ROW& row_get(const M& m, int i) { return PICK(m, i); }                 \
    static WP_FN ROW& row_at(M& m, int i) { return PICK(m, i); }                              \
    static WP_FN S get(const M& m, int i, int j) { return vec_traits<ROW>::get(row_get(m, i), j); } \
    static WP_FN S& at(M& m, int i, int j) { return vec_traits<ROW>::at(row_at(m, i), j); }   \
  };                                                                                          \
  template <>                                                                                 \
  struct mat_of<S, RR, CC> {                                                                  \
    typedef M type;                                                                           \
  };                                                                                          \
  template <>                                                                                 \
  struct vec_traits<M> {                                                                      \
    typedef S scalar;                                                                         \
    static constexpr int N = RR * CC;                                                         \
    static constexpr bool is_vec = false;                                                     \
    static WP_FN S get(const M& m, int k) { return mshape<M>::get(m, k / CC, k % CC); }      \
    static WP_FN S& at(M& m, int k) { return mshape<M>::at(m, k / CC, k % CC); }             \
  };                                                                                          \
  WP_LFN M M##_ZERO() {                                                                        \
    M r;                                                                                      \
    for (int k = 0; k < RR * CC; ++k) vec_traits<M>::at(r, k) = (S)0;                         \
    return r;                                                                                 \
  }
WP_RC(Mat23, f32, 2, 3, Vec3, WP_PICK2)
WP_RC(Mat24, f32, 2, 4, Vec4, WP_PICK2)
WP_RC(Mat26, f32, 2, 6, SpatialVector, WP_PICK2)
WP_RC(Mat32, f32, 3, 2, Vec2, WP_PICK3)
WP_RC(Mat34, f32, 3, 4, Vec4, WP_PICK3)
WP_RC(Mat36, f32, 3, 6, SpatialVector, WP_PICK3)
WP_RC(Mat42, f32, 4, 2, Vec2, WP_PICK4)
WP_RC(Mat43, f32, 4, 3, Vec3, WP_PICK4)
WP_RC(Mat46, f32, 4, 6, SpatialVector, WP_PICK4)
WP_RC(Mat62, f32, 6, 2, Vec2, WP_PICK6)
WP_RC(Mat63, f32, 6, 3, Vec3, WP_PICK6)
WP_RC(Mat64, f32, 6, 4, Vec4, WP_PICK6)
WP_RC(DMat23, f64, 2, 3, DVec3, WP_PICK2)
WP_RC(DMat24, f64, 2, 4, DVec4, WP_PICK2)
WP_RC(DMat26, f64, 2, 6, DSpatialVector, WP_PICK2)
WP_RC(DMat32, f64, 3, 2, DVec2, WP_PICK3)
WP_RC(DMat34, f64, 3, 4, DVec4, WP_PICK3)
WP_RC(DMat36, f64, 3, 6, DSpatialVector, WP_PICK3)
WP_RC(DMat42, f64, 4, 2, DVec2, WP_PICK4)
WP_RC(DMat43, f64, 4, 3, DVec3, WP_PICK4)
WP_RC(DMat46, f64, 4, 6, DSpatialVector, WP_PICK4)
WP_RC(DMat62, f64, 6, 2, DVec2, WP_PICK6)
WP_RC(DMat63, f64, 6, 3, DVec3, WP_PICK6)
WP_RC(DMat64, f64, 6, 4, DVec4, WP_PICK6)
#undef WP_RC
#undef WP_PICK2
#undef WP_PICK3
#undef WP_PICK4
#undef WP_PICK6

// Constructors from rows (one per row count).
#define WP_FROM_ROWS2(M, V) \
  WP_LFN M M##_from_rows(const V& r0, const V& r1) { return M{r0, r1}; }
#define WP_FROM_ROWS3(M, V) \
  WP_LFN M M##_from_rows(const V& r0, const V& r1, const V& r2) { return M{r0, r1, r2}; }
#define WP_FROM_ROWS4(M, V)                                                      \
  WP_LFN M M##_from_rows(const V& r0, const V& r1, const V& r2, const V& r3) {    \
    return M{r0, r1, r2, r3};                                                    \
  }
#define WP_FROM_ROWS6(M, V)                                                                  \
  WP_LFN M M##_from_rows(const V& r0, const V& r1, const V& r2, const V& r3, const V& r4,     \
                        const V& r5) {                                                       \
    return M{r0, r1, r2, r3, r4, r5};                                                        \
  }
WP_FROM_ROWS2(Mat23, Vec3)
WP_FROM_ROWS2(Mat24, Vec4)
WP_FROM_ROWS2(Mat26, SpatialVector)
WP_FROM_ROWS3(Mat32, Vec2)
WP_FROM_ROWS3(Mat34, Vec4)
WP_FROM_ROWS3(Mat36, SpatialVector)
WP_FROM_ROWS4(Mat42, Vec2)
WP_FROM_ROWS4(Mat43, Vec3)
WP_FROM_ROWS4(Mat46, SpatialVector)
WP_FROM_ROWS6(Mat62, Vec2)
WP_FROM_ROWS6(Mat63, Vec3)
WP_FROM_ROWS6(Mat64, Vec4)
WP_FROM_ROWS2(DMat23, DVec3)
WP_FROM_ROWS2(DMat24, DVec4)
WP_FROM_ROWS2(DMat26, DSpatialVector)
WP_FROM_ROWS3(DMat32, DVec2)
WP_FROM_ROWS3(DMat34, DVec4)
WP_FROM_ROWS3(DMat36, DSpatialVector)
WP_FROM_ROWS4(DMat42, DVec2)
WP_FROM_ROWS4(DMat43, DVec3)
WP_FROM_ROWS4(DMat46, DSpatialVector)
WP_FROM_ROWS6(DMat62, DVec2)
WP_FROM_ROWS6(DMat63, DVec3)
WP_FROM_ROWS6(DMat64, DVec4)
#undef WP_FROM_ROWS2
#undef WP_FROM_ROWS3
#undef WP_FROM_ROWS4
#undef WP_FROM_ROWS6

// Literals splat every entry (warp-core's FromLiteral).
namespace detail {
#define WP_RC_LITERAL(M) \
  template <>            \
  struct literal<M, false> : literal<M, true> {};
WP_RC_LITERAL(Mat23)
WP_RC_LITERAL(Mat24)
WP_RC_LITERAL(Mat26)
WP_RC_LITERAL(Mat32)
WP_RC_LITERAL(Mat34)
WP_RC_LITERAL(Mat36)
WP_RC_LITERAL(Mat42)
WP_RC_LITERAL(Mat43)
WP_RC_LITERAL(Mat46)
WP_RC_LITERAL(Mat62)
WP_RC_LITERAL(Mat63)
WP_RC_LITERAL(Mat64)
WP_RC_LITERAL(DMat23)
WP_RC_LITERAL(DMat24)
WP_RC_LITERAL(DMat26)
WP_RC_LITERAL(DMat32)
WP_RC_LITERAL(DMat34)
WP_RC_LITERAL(DMat36)
WP_RC_LITERAL(DMat42)
WP_RC_LITERAL(DMat43)
WP_RC_LITERAL(DMat46)
WP_RC_LITERAL(DMat62)
WP_RC_LITERAL(DMat63)
WP_RC_LITERAL(DMat64)
#undef WP_RC_LITERAL
}  // namespace detail

/// `T` where `M` is a non-square matrix.
#define WP_IF_RC(M, T) typename detail::rc_enable<mshape<M>::is_rc, T>::type

// Lane-by-lane operators.
template <typename M>
WP_FN WP_IF_RC(M, M) operator+(const M& a, const M& b) {
  M r;
  for (int k = 0; k < vec_traits<M>::N; ++k)
    vec_traits<M>::at(r, k) = vec_traits<M>::get(a, k) + vec_traits<M>::get(b, k);
  return r;
}
template <typename M>
WP_FN WP_IF_RC(M, M) operator-(const M& a, const M& b) {
  M r;
  for (int k = 0; k < vec_traits<M>::N; ++k)
    vec_traits<M>::at(r, k) = vec_traits<M>::get(a, k) - vec_traits<M>::get(b, k);
  return r;
}
template <typename M>
WP_FN WP_IF_RC(M, M) operator-(const M& a) {
  M r;
  for (int k = 0; k < vec_traits<M>::N; ++k) vec_traits<M>::at(r, k) = -vec_traits<M>::get(a, k);
  return r;
}
template <typename M>
WP_FN WP_IF_RC(M, M) operator*(const M& a, typename mshape<M>::scalar s) {
  M r;
  for (int k = 0; k < vec_traits<M>::N; ++k) vec_traits<M>::at(r, k) = vec_traits<M>::get(a, k) * s;
  return r;
}
template <typename M>
WP_FN WP_IF_RC(M, M) operator*(typename mshape<M>::scalar s, const M& a) {
  M r;
  for (int k = 0; k < vec_traits<M>::N; ++k) vec_traits<M>::at(r, k) = s * vec_traits<M>::get(a, k);
  return r;
}
template <typename M>
WP_FN WP_IF_RC(M, M) operator/(const M& a, typename mshape<M>::scalar s) {
  M r;
  for (int k = 0; k < vec_traits<M>::N; ++k) vec_traits<M>::at(r, k) = vec_traits<M>::get(a, k) / s;
  return r;
}
template <typename M>
WP_FN WP_IF_RC(M, M&) operator+=(M& a, const M& b) {
  return a = a + b;
}
template <typename M>
WP_FN WP_IF_RC(M, M&) operator-=(M& a, const M& b) {
  return a = a - b;
}
template <typename M>
WP_FN WP_IF_RC(M, bool) operator==(const M& a, const M& b) {
  for (int k = 0; k < vec_traits<M>::N; ++k)
    if (!(vec_traits<M>::get(a, k) == vec_traits<M>::get(b, k))) return false;
  return true;
}
template <typename M>
WP_FN WP_IF_RC(M, bool) operator!=(const M& a, const M& b) {
  return !(a == b);
}

/// `m * x`: lane i is sum_k m[i][k] x[k].
template <typename M>
WP_FN typename vec_of<typename mshape<M>::scalar, mshape<M>::R>::type operator*(
    const M& m, const typename detail::rc_enable<mshape<M>::is_rc, typename mshape<M>::row>::type& x) {
  typedef mshape<M> T;
  typedef typename vec_of<typename T::scalar, T::R>::type V;
  typedef typename T::row W;
  V r;
  for (int i = 0; i < T::R; ++i) {
    typename T::scalar acc = T::get(m, i, 0) * vec_traits<W>::get(x, 0);
    for (int k = 1; k < T::C; ++k) acc += T::get(m, i, k) * vec_traits<W>::get(x, k);
    vec_traits<V>::at(r, i) = acc;
  }
  return r;
}

/// `a * b` with a non-square side: entry (i, j) is sum_k a[i][k] b[k][j].
template <typename A, typename B>
WP_FN typename detail::rc_enable<
    (mshape<A>::is_rc || mshape<B>::is_rc) && mshape<A>::is_mat && mshape<B>::is_mat &&
        mshape<A>::C == mshape<B>::R,
    typename mat_of<typename mshape<A>::scalar, mshape<A>::R, mshape<B>::C>::type>::type
operator*(const A& a, const B& b) {
  typedef typename mat_of<typename mshape<A>::scalar, mshape<A>::R, mshape<B>::C>::type O;
  O r;
  for (int i = 0; i < mshape<A>::R; ++i)
    for (int j = 0; j < mshape<B>::C; ++j) {
      typename mshape<A>::scalar acc = mshape<A>::get(a, i, 0) * mshape<B>::get(b, 0, j);
      for (int k = 1; k < mshape<A>::C; ++k) acc += mshape<A>::get(a, i, k) * mshape<B>::get(b, k, j);
      mshape<O>::at(r, i, j) = acc;
    }
  return r;
}

/// The transpose (a Mat32 for a Mat23).
template <typename M>
WP_FN typename detail::rc_enable<
    mshape<M>::is_rc, typename mat_of<typename mshape<M>::scalar, mshape<M>::C, mshape<M>::R>::type>::type
transpose(const M& m) {
  typedef typename mat_of<typename mshape<M>::scalar, mshape<M>::C, mshape<M>::R>::type O;
  O r;
  for (int i = 0; i < mshape<M>::R; ++i)
    for (int j = 0; j < mshape<M>::C; ++j) mshape<O>::at(r, j, i) = mshape<M>::get(m, i, j);
  return r;
}

/// `outer(a, b)` of vectors of one scalar and different lengths: entry (i, j) is a[i] b[j].
template <typename A, typename B>
WP_FN typename detail::rc_enable<
    vshape<A>::is_vec && vshape<B>::is_vec && vshape<A>::N != vshape<B>::N,
    typename mat_of<typename vshape<A>::scalar, vshape<A>::N, vshape<B>::N>::type>::type
outer(const A& a, const B& b) {
  typedef typename mat_of<typename vshape<A>::scalar, vshape<A>::N, vshape<B>::N>::type O;
  O r;
  for (int i = 0; i < vshape<A>::N; ++i)
    for (int j = 0; j < vshape<B>::N; ++j)
      mshape<O>::at(r, i, j) = vec_traits<A>::get(a, i) * vec_traits<B>::get(b, j);
  return r;
}

/// `ddot(a, b)`: sum_ij a[i][j] b[i][j], row by row, left to right.
template <typename M>
WP_FN WP_IF_RC(M, typename mshape<M>::scalar) ddot(const M& a, const M& b) {
  typename mshape<M>::scalar acc = vec_traits<M>::get(a, 0) * vec_traits<M>::get(b, 0);
  for (int k = 1; k < vec_traits<M>::N; ++k) acc += vec_traits<M>::get(a, k) * vec_traits<M>::get(b, k);
  return acc;
}

// A row at a run-time index (`m[i]`), with local arrays' faults (warp-core's local_array::get
// and set through `Lanes`) and `local_at`'s in-bounds rule for adjoints.
template <typename M>
WP_FN WP_IF_RC(M, typename mshape<M>::row) local_get(const M& m, i64 i, i64 line, ctx_t* ctx) {
  if ((u64)i < (u64)mshape<M>::R) return mshape<M>::row_get(m, (int)i);
  detail::local_index_fault(i, mshape<M>::R, line, ctx);
  return typename mshape<M>::row{};
}
template <typename M>
WP_FN WP_IF_RC(M, void) local_set(M& m, i64 i, const typename mshape<M>::row& v, i64 line,
                                  ctx_t* ctx) {
  if ((u64)i < (u64)mshape<M>::R) {
    mshape<M>::row_at(m, (int)i) = v;
    return;
  }
  detail::local_index_fault(i, mshape<M>::R, line, ctx);
}
template <typename M>
WP_FN WP_IF_RC(M, typename mshape<M>::row&) local_at(M& m, i64 i) {
  return mshape<M>::row_at(m, (u64)i < (u64)mshape<M>::R ? (int)i : 0);
}

#define WP_RC_LAYOUT(M, SIZE, ALIGN) \
  static_assert(sizeof(M) == SIZE && alignof(M) == ALIGN, #M " must match warp-core's layout");
WP_RC_LAYOUT(Mat23, 24, 4)
WP_RC_LAYOUT(Mat24, 32, 16)  // Vec4 rows, glam's 16-byte alignment
WP_RC_LAYOUT(Mat26, 48, 4)
WP_RC_LAYOUT(Mat32, 24, 4)
WP_RC_LAYOUT(Mat34, 48, 16)
WP_RC_LAYOUT(Mat36, 72, 4)
WP_RC_LAYOUT(Mat42, 32, 4)
WP_RC_LAYOUT(Mat43, 48, 4)
WP_RC_LAYOUT(Mat46, 96, 4)
WP_RC_LAYOUT(Mat62, 48, 4)
WP_RC_LAYOUT(Mat63, 72, 4)
WP_RC_LAYOUT(Mat64, 96, 16)
WP_RC_LAYOUT(DMat23, 48, 8)
WP_RC_LAYOUT(DMat24, 64, 8)
WP_RC_LAYOUT(DMat26, 96, 8)
WP_RC_LAYOUT(DMat32, 48, 8)
WP_RC_LAYOUT(DMat34, 96, 8)
WP_RC_LAYOUT(DMat36, 144, 8)
WP_RC_LAYOUT(DMat42, 64, 8)
WP_RC_LAYOUT(DMat43, 96, 8)
WP_RC_LAYOUT(DMat46, 192, 8)
WP_RC_LAYOUT(DMat62, 96, 8)
WP_RC_LAYOUT(DMat63, 144, 8)
WP_RC_LAYOUT(DMat64, 192, 8)
#undef WP_RC_LAYOUT

}  // namespace wp

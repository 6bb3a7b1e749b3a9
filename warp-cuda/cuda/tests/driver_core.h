// driver_core.h: the device-compatible part of the library's test driver (see driver.cpp):
// case and result records, and `compute`, which evaluates one case through the library. It
// includes nothing but the library, so that it compiles under NVRTC as well as g++ and nvcc.
#pragma once
#include "../wp.h"

namespace drv {
using namespace wp;

#define DRV_FN WP_FN

// ------------------------------------------------------------------------------------------
// Names
// ------------------------------------------------------------------------------------------

#define TYPE_LIST(X)                                                                          \
  X(i8) X(i16) X(i32) X(i64) X(u8) X(u16) X(u32) X(u64) X(f32) X(f64) X(bool) X(Vec2) X(Vec3) \
  X(Vec4) X(DVec2) X(DVec3) X(DVec4) X(IVec2) X(IVec3) X(IVec4) X(UVec2) X(UVec3) X(UVec4)    \
  X(Mat2) X(Mat3) X(Mat4) X(DMat2) X(DMat3) X(DMat4) X(Quat) X(DQuat) X(Transform)           \
  X(DTransform)

#define ENUM_T(t) T_##t,
enum type_id { TYPE_LIST(ENUM_T) T_COUNT };
#undef ENUM_T

#define OP_LIST(X)                                                                              \
  X(w_add) X(w_sub) X(w_mul) X(w_neg) X(w_div) X(w_rem) X(w_shl) X(w_shr) X(min) X(max)         \
  X(clamp) X(abs) X(sign) X(floor) X(ceil) X(sqrt) X(exp) X(log) X(sin) X(cos) X(tan) X(atan2) \
  X(pow) X(lerp) X(frem) X(dot) X(cross) X(length) X(normalize) X(add) X(sub) X(mul) X(div)    \
  X(rem) X(adds) X(subs) X(muls) X(divs) X(rems) X(sadd) X(ssub) X(smul) X(sdiv) X(srem)       \
  X(neg) X(eq) X(ne) X(mulv) X(make) X(splat) X(from_diag) X(konst) X(cast) X(lit) X(intlit)   \
  X(range) X(load) X(store) X(len) X(atomic_add) X(atomic_sub) X(atomic_min) X(atomic_max)     \
  X(unflatten) X(layout) X(print) X(addassign) X(mulassign) X(asin) X(acos) X(atan) X(sinh)   \
  X(cosh) X(tanh) X(exp2) X(log2) X(log10) X(cbrt) X(erf) X(erfc) X(erfinv) X(erfcinv)        \
  X(round) X(rint) X(trunc) X(frac) X(degrees) X(radians) X(smoothstep) X(step) X(isfinite)    \
  X(isnan) X(isinf) X(length_sq) X(outer) X(diag) X(cw_mul) X(cw_div) X(transpose)           \
  X(determinant) X(inverse) X(trace) X(ddot) X(skew) X(qaxis) X(qrot) X(qrotinv) X(qinv) X(q2m) \
  X(m2q) X(slerp) X(rand_pcg) X(rand_init) X(rand_init_offset) X(randf) X(randf_range) X(randn) \
  X(sample_triangle) X(sample_unit_ring) X(sample_unit_disk) X(sample_unit_square)            \
  X(sample_unit_cube) X(sample_unit_sphere_surface) X(sample_unit_sphere)                    \
  X(sample_unit_hemisphere_surface) X(sample_unit_hemisphere) X(poisson) X(poisson_state)    \
  X(noise) X(pnoise) \
  X(xinv) X(xpoint) X(xvector) X(x2m) X(m2x) X(xget) \
  X(svd3) X(eig3) X(qr3) X(svd2) \
  X(copysign) X(nonzero) X(min_element) X(max_element) X(argmin) X(argmax) X(get_diag)      \
  X(norm_l1) X(norm_l2) X(norm_huber) X(norm_pseudo_huber) X(smooth_normalize) X(q2aa)     \
  X(qrpy) X(q2rpy) X(qtwist) X(qtwista) X(qtwistas) X(xcompose) X(xdecompose)

#define ENUM_OP(o) OP_##o,
enum op_id { OP_LIST(ENUM_OP) OP_COUNT };
#undef ENUM_OP

// ------------------------------------------------------------------------------------------
// Cases and results
// ------------------------------------------------------------------------------------------

struct case_t {
  int op, ty, ty2, n;
  u64 a[40];
};

struct alignas(16) out_t {
  u64 scratch[32];  // array storage for load/store/atomic cases (global memory on the GPU)
  u64 v[24];
  fault_t fault;
  u32 flag;
  i32 n;  // number of result tokens; -1: unsupported
};

struct reader {
  const u64* a;
  int pos;
};

// Scalars from/to bit patterns.
template <typename S>
DRV_FN S scalar_from(u64 b) {
  if constexpr (num<S>::is_float) {
    if constexpr (sizeof(S) == 4)
      return f32_from_bits((u32)b);
    else
      return f64_from_bits(b);
  } else if constexpr (num<S>::is_bool) {
    return b != 0;
  } else {
    return (S)(typename num<S>::unsigned_t)b;
  }
}
template <typename S>
DRV_FN u64 scalar_bits(S x) {
  if constexpr (num<S>::is_float) {
    if constexpr (sizeof(S) == 4)
      return (u64)f32_to_bits(x);
    else
      return f64_to_bits(x);
  } else if constexpr (num<S>::is_bool) {
    return x ? 1 : 0;
  } else {
    return (u64)(typename num<S>::unsigned_t)x;
  }
}

template <typename T>
struct is_composite {
  static constexpr bool value = vec_traits<T>::is_vec || mat_traits<T>::is_mat;
};
template <>
struct is_composite<Quat> {
  static constexpr bool value = true;
};
template <>
struct is_composite<DQuat> {
  static constexpr bool value = true;
};
template <>
struct is_composite<Transform> {
  static constexpr bool value = true;
};
template <>
struct is_composite<DTransform> {
  static constexpr bool value = true;
};

template <typename T>
DRV_FN T get(reader& r) {
  if constexpr (is_composite<T>::value) {
    typedef typename vec_traits<T>::scalar S;
    T v;
    for (int i = 0; i < vec_traits<T>::N; ++i) vec_traits<T>::at(v, i) = scalar_from<S>(r.a[r.pos++]);
    return v;
  } else {
    return scalar_from<T>(r.a[r.pos++]);
  }
}

template <typename T>
DRV_FN void put(out_t& o, const T& x) {
  if constexpr (is_composite<T>::value) {
    typedef typename vec_traits<T>::scalar S;
    for (int i = 0; i < vec_traits<T>::N; ++i) o.v[o.n++] = scalar_bits<S>(vec_traits<T>::get(x, i));
  } else {
    o.v[o.n++] = scalar_bits<T>(x);
  }
}

// ------------------------------------------------------------------------------------------
// Type classes
// ------------------------------------------------------------------------------------------

template <typename T>
struct cls {
  static constexpr bool vec = vec_traits<T>::is_vec;
  static constexpr bool mat = mat_traits<T>::is_mat;
  static constexpr bool quat = false;
  static constexpr bool xform = false;
  static constexpr bool scalar = !vec && !mat;
};
template <>
struct cls<Quat> {
  static constexpr bool vec = false, mat = false, quat = true, xform = false, scalar = false;
};
template <>
struct cls<DQuat> {
  static constexpr bool vec = false, mat = false, quat = true, xform = false, scalar = false;
};
template <>
struct cls<Transform> {
  static constexpr bool vec = false, mat = false, quat = false, xform = true, scalar = false;
};
template <>
struct cls<DTransform> {
  static constexpr bool vec = false, mat = false, quat = false, xform = true, scalar = false;
};

template <typename T, bool V = vec_traits<T>::is_vec || mat_traits<T>::is_mat || cls<T>::quat ||
                               cls<T>::xform>
struct scalar_of {
  typedef T type;
};
template <typename T>
struct scalar_of<T, true> {
  typedef typename vec_traits<T>::scalar type;
};

template <typename T, bool V = vec_traits<T>::is_vec>
struct lanes {
  static constexpr int value = 0;
};
template <typename T>
struct lanes<T, true> {
  static constexpr int value = vec_traits<T>::N;
};

// Vector constructors from components.
DRV_FN Vec2 make_vec(reader& r, Vec2*) { f32 x = get<f32>(r), y = get<f32>(r); return Vec2_new(x, y); }
DRV_FN Vec3 make_vec(reader& r, Vec3*) { f32 x = get<f32>(r), y = get<f32>(r), z = get<f32>(r); return Vec3_new(x, y, z); }
DRV_FN Vec4 make_vec(reader& r, Vec4*) { f32 x = get<f32>(r), y = get<f32>(r), z = get<f32>(r), w = get<f32>(r); return Vec4_new(x, y, z, w); }
DRV_FN DVec2 make_vec(reader& r, DVec2*) { f64 x = get<f64>(r), y = get<f64>(r); return DVec2_new(x, y); }
DRV_FN DVec3 make_vec(reader& r, DVec3*) { f64 x = get<f64>(r), y = get<f64>(r), z = get<f64>(r); return DVec3_new(x, y, z); }
DRV_FN DVec4 make_vec(reader& r, DVec4*) { f64 x = get<f64>(r), y = get<f64>(r), z = get<f64>(r), w = get<f64>(r); return DVec4_new(x, y, z, w); }
DRV_FN IVec2 make_vec(reader& r, IVec2*) { i32 x = get<i32>(r), y = get<i32>(r); return IVec2_new(x, y); }
DRV_FN IVec3 make_vec(reader& r, IVec3*) { i32 x = get<i32>(r), y = get<i32>(r), z = get<i32>(r); return IVec3_new(x, y, z); }
DRV_FN IVec4 make_vec(reader& r, IVec4*) { i32 x = get<i32>(r), y = get<i32>(r), z = get<i32>(r), w = get<i32>(r); return IVec4_new(x, y, z, w); }
DRV_FN UVec2 make_vec(reader& r, UVec2*) { u32 x = get<u32>(r), y = get<u32>(r); return UVec2_new(x, y); }
DRV_FN UVec3 make_vec(reader& r, UVec3*) { u32 x = get<u32>(r), y = get<u32>(r), z = get<u32>(r); return UVec3_new(x, y, z); }
DRV_FN UVec4 make_vec(reader& r, UVec4*) { u32 x = get<u32>(r), y = get<u32>(r), z = get<u32>(r), w = get<u32>(r); return UVec4_new(x, y, z, w); }
DRV_FN Mat2 make_vec(reader& r, Mat2*) { Vec2 a = get<Vec2>(r), b = get<Vec2>(r); return Mat2_from_cols(a, b); }
DRV_FN Mat3 make_vec(reader& r, Mat3*) { Vec3 a = get<Vec3>(r), b = get<Vec3>(r), c = get<Vec3>(r); return Mat3_from_cols(a, b, c); }
DRV_FN Mat4 make_vec(reader& r, Mat4*) { Vec4 a = get<Vec4>(r), b = get<Vec4>(r), c = get<Vec4>(r), d = get<Vec4>(r); return Mat4_from_cols(a, b, c, d); }
DRV_FN DMat2 make_vec(reader& r, DMat2*) { DVec2 a = get<DVec2>(r), b = get<DVec2>(r); return DMat2_from_cols(a, b); }
DRV_FN DMat3 make_vec(reader& r, DMat3*) { DVec3 a = get<DVec3>(r), b = get<DVec3>(r), c = get<DVec3>(r); return DMat3_from_cols(a, b, c); }
DRV_FN DMat4 make_vec(reader& r, DMat4*) { DVec4 a = get<DVec4>(r), b = get<DVec4>(r), c = get<DVec4>(r), d = get<DVec4>(r); return DMat4_from_cols(a, b, c, d); }
DRV_FN Quat make_vec(reader& r, Quat*) { f32 x = get<f32>(r), y = get<f32>(r), z = get<f32>(r), w = get<f32>(r); return Quat_from_xyzw(x, y, z, w); }
DRV_FN DQuat make_vec(reader& r, DQuat*) { f64 x = get<f64>(r), y = get<f64>(r), z = get<f64>(r), w = get<f64>(r); return DQuat_from_xyzw(x, y, z, w); }

#define SPLAT(V) DRV_FN V splat_of(V*, vec_traits<V>::scalar s) { return V##_splat(s); }
SPLAT(Vec2) SPLAT(Vec3) SPLAT(Vec4) SPLAT(DVec2) SPLAT(DVec3) SPLAT(DVec4)
SPLAT(IVec2) SPLAT(IVec3) SPLAT(IVec4) SPLAT(UVec2) SPLAT(UVec3) SPLAT(UVec4)
#undef SPLAT
#define FROM_DIAG(M, V) DRV_FN M from_diag_of(M*, const V& d) { return M##_from_diagonal(d); }
FROM_DIAG(Mat2, Vec2) FROM_DIAG(Mat3, Vec3) FROM_DIAG(Mat4, Vec4)
FROM_DIAG(DMat2, DVec2) FROM_DIAG(DMat3, DVec3) FROM_DIAG(DMat4, DVec4)
#undef FROM_DIAG

// Constants: ids as in the Rust test.
enum {
  K_ZERO, K_ONE, K_NEG_ONE, K_X, K_Y, K_Z, K_W, K_NEG_X, K_NEG_Y, K_NEG_Z, K_NEG_W, K_MIN,
  K_MAX, K_INFINITY, K_NEG_INFINITY, K_NAN, K_IDENTITY
};
#define KC(T, NAME) \
  case K_##NAME:    \
    put(o, T##_##NAME()); \
    return true;
#define K_COMMON(T) KC(T, ZERO) KC(T, ONE) KC(T, X) KC(T, Y) KC(T, MIN) KC(T, MAX)
#define K_SIGNED(T) KC(T, NEG_ONE) KC(T, NEG_X) KC(T, NEG_Y)
#define K_FLOAT(T) KC(T, INFINITY) KC(T, NEG_INFINITY) KC(T, NAN)
#define K3(T) KC(T, Z)
#define K4(T) KC(T, Z) KC(T, W)
#define K3N(T) KC(T, NEG_Z)
#define K4N(T) KC(T, NEG_Z) KC(T, NEG_W)
#define KFN(T, BODY) \
  DRV_FN bool konst_of(T*, int id, out_t& o) { switch (id) { BODY default: return false; } }
KFN(Vec2, K_COMMON(Vec2) K_SIGNED(Vec2) K_FLOAT(Vec2))
KFN(Vec3, K_COMMON(Vec3) K_SIGNED(Vec3) K_FLOAT(Vec3) K3(Vec3) K3N(Vec3))
KFN(Vec4, K_COMMON(Vec4) K_SIGNED(Vec4) K_FLOAT(Vec4) K4(Vec4) K4N(Vec4))
KFN(DVec2, K_COMMON(DVec2) K_SIGNED(DVec2) K_FLOAT(DVec2))
KFN(DVec3, K_COMMON(DVec3) K_SIGNED(DVec3) K_FLOAT(DVec3) K3(DVec3) K3N(DVec3))
KFN(DVec4, K_COMMON(DVec4) K_SIGNED(DVec4) K_FLOAT(DVec4) K4(DVec4) K4N(DVec4))
KFN(IVec2, K_COMMON(IVec2) K_SIGNED(IVec2))
KFN(IVec3, K_COMMON(IVec3) K_SIGNED(IVec3) K3(IVec3) K3N(IVec3))
KFN(IVec4, K_COMMON(IVec4) K_SIGNED(IVec4) K4(IVec4) K4N(IVec4))
KFN(UVec2, K_COMMON(UVec2))
KFN(UVec3, K_COMMON(UVec3) K3(UVec3))
KFN(UVec4, K_COMMON(UVec4) K4(UVec4))
KFN(Mat2, KC(Mat2, ZERO) KC(Mat2, IDENTITY) KC(Mat2, NAN))
KFN(Mat3, KC(Mat3, ZERO) KC(Mat3, IDENTITY) KC(Mat3, NAN))
KFN(Mat4, KC(Mat4, ZERO) KC(Mat4, IDENTITY) KC(Mat4, NAN))
KFN(DMat2, KC(DMat2, ZERO) KC(DMat2, IDENTITY) KC(DMat2, NAN))
KFN(DMat3, KC(DMat3, ZERO) KC(DMat3, IDENTITY) KC(DMat3, NAN))
KFN(DMat4, KC(DMat4, ZERO) KC(DMat4, IDENTITY) KC(DMat4, NAN))
KFN(Quat, KC(Quat, IDENTITY) KC(Quat, NAN))
KFN(DQuat, KC(DQuat, IDENTITY) KC(DQuat, NAN))
KFN(Transform, KC(Transform, IDENTITY))
KFN(DTransform, KC(DTransform, IDENTITY))
#undef KC
#undef K_COMMON
#undef K_SIGNED
#undef K_FLOAT
#undef K3
#undef K4
#undef K3N
#undef K4N
#undef KFN

// The column type of a matrix / the Vec3 a quaternion rotates.
template <typename T>
struct mulv_rhs {
  typedef typename mat_traits<T>::column type;
};
template <>
struct mulv_rhs<Quat> {
  typedef Vec3 type;
};
template <>
struct mulv_rhs<DQuat> {
  typedef DVec3 type;
};

// ------------------------------------------------------------------------------------------
// Arrays for load/store/atomic cases
// ------------------------------------------------------------------------------------------

// A = [ndim, shape.., colmajor, idx..]; storage in o.scratch, element (row-major linear L) = L.
template <typename T>
DRV_FN void build_array(reader& r, out_t& o, int ndim, i64* shape, i64* strides, i64* idx, bool fill) {
  for (int k = 0; k < ndim; ++k) shape[k] = (i64)r.a[r.pos++];
  const bool colmajor = r.a[r.pos++] != 0;
  for (int k = 0; k < ndim; ++k) idx[k] = (i64)r.a[r.pos++];
  if (colmajor) {
    i64 s = (i64)sizeof(T);
    for (int k = 0; k < ndim; ++k) {
      strides[k] = s;
      s *= shape[k];
    }
  } else {
    i64 s = (i64)sizeof(T);
    for (int k = ndim - 1; k >= 0; --k) {
      strides[k] = s;
      s *= shape[k];
    }
  }
  if (fill) {
    i64 total = 1;
    for (int k = 0; k < ndim; ++k) total *= shape[k];
    for (i64 L = 0; L < total; ++L) {
      i64 rem = L, off = 0;
      for (int k = ndim - 1; k >= 0; --k) {
        off += (rem % shape[k]) * strides[k];
        rem /= shape[k];
      }
      *(T*)((char*)o.scratch + off) = (T)L;
    }
  }
}

template <int N>
DRV_FN void array_case(int op, reader& r, out_t& o, ctx_t* ctx) {
  array_t<f32, N> a;
  i64 idx[4] = {0, 0, 0, 0};
  build_array<f32>(r, o, N, a.shape, a.strides, idx, true);
  a.data = (f32*)o.scratch;
  a.arg = 7;
  a.pad = 0;
  if (op == OP_len) {
    put(o, len(a));
    for (int k = 0; k < N; ++k) put(o, extent(a, k));
    return;
  }
  f32 v = 0.0f;
  f32* p = nullptr;
  if (op == OP_load) {
    if constexpr (N == 1) v = load(a, idx[0], ctx), p = elem_ptr(a, idx[0], ctx);
    if constexpr (N == 2) v = load(a, idx[0], idx[1], ctx), p = elem_ptr(a, idx[0], idx[1], ctx);
    if constexpr (N == 3) v = load(a, idx[0], idx[1], idx[2], ctx), p = elem_ptr(a, idx[0], idx[1], idx[2], ctx);
    if constexpr (N == 4) v = load(a, idx[0], idx[1], idx[2], idx[3], ctx), p = elem_ptr(a, idx[0], idx[1], idx[2], idx[3], ctx);
    put(o, v);
    f32 u = 0.0f;
    if (p != nullptr) {
      if constexpr (N == 1) u = load_unchecked(a, idx[0]);
      if constexpr (N == 2) u = load_unchecked(a, idx[0], idx[1]);
      if constexpr (N == 3) u = load_unchecked(a, idx[0], idx[1], idx[2]);
      if constexpr (N == 4) u = load_unchecked(a, idx[0], idx[1], idx[2], idx[3]);
    }
    put(o, u);
    put(o, (u32)(p != nullptr));
  } else {  // store
    const f32 x = get<f32>(r);
    if constexpr (N == 1) store(a, idx[0], x, ctx);
    if constexpr (N == 2) store(a, idx[0], idx[1], x, ctx);
    if constexpr (N == 3) store(a, idx[0], idx[1], idx[2], x, ctx);
    if constexpr (N == 4) store(a, idx[0], idx[1], idx[2], idx[3], x, ctx);
    i64 total = 1;
    for (int k = 0; k < N; ++k) total *= a.shape[k];
    u64 h = 0;
    const u32* w = (const u32*)o.scratch;
    for (i64 k = 0; k < total; ++k) h += (u64)w[k] * (u64)(k + 1);
    put(o, h);
  }
}

template <typename T>
DRV_FN void atomic_case(int op, reader& r, out_t& o, ctx_t* ctx) {
  const T init = get<T>(r);
  const T v = get<T>(r);
  const i64 i = (i64)r.a[r.pos++];
  T* buf = (T*)o.scratch;
  for (int k = 0; k < 4; ++k) buf[k] = init;
  array_t<T, 1> a;
  a.data = buf;
  a.shape[0] = 4;
  a.strides[0] = (i64)sizeof(T);
  a.arg = 3;
  a.pad = 0;
  T old;
  if (op == OP_atomic_add) old = atomic_add(a, i, v, ctx);
  else if (op == OP_atomic_sub) old = atomic_sub(a, i, v, ctx);
  else if (op == OP_atomic_min) old = atomic_min(a, i, v, ctx);
  else old = atomic_max(a, i, v, ctx);
  put(o, old);
  put(o, buf[(i >= 0 && i < 4) ? i : 0]);
}

// ------------------------------------------------------------------------------------------
// Evaluation
// ------------------------------------------------------------------------------------------

template <typename From, typename To>
DRV_FN void run_cast(reader& r, out_t& o) {
  if constexpr (num<To>::is_bool || (num<From>::is_bool && !num<To>::is_int)) {
    o.n = -1;
  } else {
    const From x = get<From>(r);
    put(o, cast<To>(x));
  }
}

template <typename From>
DRV_FN void dispatch_cast_to(int ty2, reader& r, out_t& o) {
  switch (ty2) {
#define CASE_TO(t) \
  case T_##t:      \
    run_cast<From, t>(r, o); \
    return;
    CASE_TO(i8) CASE_TO(i16) CASE_TO(i32) CASE_TO(i64) CASE_TO(u8) CASE_TO(u16) CASE_TO(u32)
    CASE_TO(u64) CASE_TO(f32) CASE_TO(f64) CASE_TO(bool)
#undef CASE_TO
    default:
      o.n = -1;
  }
}

/// The period type of `pnoise` over T (i32 for f32, the IVec of a Vec's size).
template <typename T>
struct noise_period {
  typedef i32 type;
};
template <>
struct noise_period<Vec2> {
  typedef IVec2 type;
};
template <>
struct noise_period<Vec3> {
  typedef IVec3 type;
};
template <>
struct noise_period<Vec4> {
  typedef IVec4 type;
};

template <typename T>
DRV_FN void run(const case_t& c, reader& r, out_t& o, ctx_t* ctx) {
  typedef typename scalar_of<T>::type S;
  constexpr bool is_int = cls<T>::scalar && num<T>::is_int;
  constexpr bool is_float = cls<T>::scalar && num<T>::is_float;
  constexpr bool is_vec = cls<T>::vec;
  constexpr bool is_fvec = is_vec && num<S>::is_float;
  constexpr bool is_ivec = is_vec && num<S>::is_int;
  constexpr bool is_svec = is_fvec || (is_ivec && num<S>::is_signed);
  constexpr bool is_mat = cls<T>::mat;
  constexpr bool is_quat = cls<T>::quat;
  constexpr bool is_v3 = lanes<T>::value == 3 && num<S>::is_signed;  // Vec3, DVec3, IVec3
  const int op = c.op;

  if (op == OP_layout) {
    put(o, (u64)sizeof(T));
    put(o, (u64)alignof(T));
    return;
  }
  if (op == OP_cast) {
    if constexpr (cls<T>::scalar) {
      dispatch_cast_to<T>(c.ty2, r, o);
      return;
    }
  }
  if constexpr (is_int || is_ivec) {
    switch (op) {
      case OP_w_add: { T a = get<T>(r), b = get<T>(r); put(o, w_add(a, b)); return; }
      case OP_w_sub: { T a = get<T>(r), b = get<T>(r); put(o, w_sub(a, b)); return; }
      case OP_w_mul: { T a = get<T>(r), b = get<T>(r); put(o, w_mul(a, b)); return; }
      case OP_w_neg: { T a = get<T>(r); put(o, w_neg(a)); return; }
      case OP_w_div: { T a = get<T>(r), b = get<T>(r); put(o, w_div(a, b, ctx)); return; }
      case OP_w_rem: { T a = get<T>(r), b = get<T>(r); put(o, w_rem(a, b, ctx)); return; }
      case OP_w_shl: { T a = get<T>(r); u32 s = get<u32>(r); put(o, w_shl(a, s)); return; }
      case OP_w_shr: { T a = get<T>(r); u32 s = get<u32>(r); put(o, w_shr(a, s)); return; }
      default: break;
    }
  }
  if constexpr (is_int || is_float || is_vec) {
    switch (op) {
      case OP_min: { T a = get<T>(r), b = get<T>(r); put(o, wp::min(a, b)); return; }
      case OP_max: { T a = get<T>(r), b = get<T>(r); put(o, wp::max(a, b)); return; }
      case OP_clamp: { T a = get<T>(r), b = get<T>(r), d = get<T>(r); put(o, wp::clamp(a, b, d)); return; }
      default: break;
    }
  }
  if constexpr ((is_int && num<T>::is_signed) || is_float || is_svec) {
    switch (op) {
      case OP_abs: { T a = get<T>(r); put(o, wp::abs(a)); return; }
      case OP_sign: { T a = get<T>(r); put(o, wp::sign(a)); return; }
      default: break;
    }
  }
  if constexpr (is_float) {
    switch (op) {
      case OP_floor: { T a = get<T>(r); put(o, wp::floor(a)); return; }
      case OP_ceil: { T a = get<T>(r); put(o, wp::ceil(a)); return; }
      case OP_sqrt: { T a = get<T>(r); put(o, wp::sqrt(a)); return; }
      case OP_exp: { T a = get<T>(r); put(o, wp::exp(a)); return; }
      case OP_log: { T a = get<T>(r); put(o, wp::log(a)); return; }
      case OP_sin: { T a = get<T>(r); put(o, wp::sin(a)); return; }
      case OP_cos: { T a = get<T>(r); put(o, wp::cos(a)); return; }
      case OP_tan: { T a = get<T>(r); put(o, wp::tan(a)); return; }
      case OP_atan2: { T a = get<T>(r), b = get<T>(r); put(o, wp::atan2(a, b)); return; }
      case OP_pow: { T a = get<T>(r), b = get<T>(r); put(o, wp::pow(a, b)); return; }
      case OP_frem: { T a = get<T>(r), b = get<T>(r); put(o, wp::frem(a, b)); return; }
      case OP_asin: { T a = get<T>(r); put(o, wp::asin(a)); return; }
      case OP_acos: { T a = get<T>(r); put(o, wp::acos(a)); return; }
      case OP_atan: { T a = get<T>(r); put(o, wp::atan(a)); return; }
      case OP_sinh: { T a = get<T>(r); put(o, wp::sinh(a)); return; }
      case OP_cosh: { T a = get<T>(r); put(o, wp::cosh(a)); return; }
      case OP_tanh: { T a = get<T>(r); put(o, wp::tanh(a)); return; }
      case OP_exp2: { T a = get<T>(r); put(o, wp::exp2(a)); return; }
      case OP_log2: { T a = get<T>(r); put(o, wp::log2(a)); return; }
      case OP_log10: { T a = get<T>(r); put(o, wp::log10(a)); return; }
      case OP_cbrt: { T a = get<T>(r); put(o, wp::cbrt(a)); return; }
      case OP_erf: { T a = get<T>(r); put(o, wp::erf(a)); return; }
      case OP_erfc: { T a = get<T>(r); put(o, wp::erfc(a)); return; }
      case OP_erfinv: { T a = get<T>(r); put(o, wp::erfinv(a)); return; }
      case OP_erfcinv: { T a = get<T>(r); put(o, wp::erfcinv(a)); return; }
      case OP_round: { T a = get<T>(r); put(o, wp::round(a)); return; }
      case OP_rint: { T a = get<T>(r); put(o, wp::rint(a)); return; }
      case OP_trunc: { T a = get<T>(r); put(o, wp::trunc(a)); return; }
      case OP_frac: { T a = get<T>(r); put(o, wp::frac(a)); return; }
      case OP_degrees: { T a = get<T>(r); put(o, wp::degrees(a)); return; }
      case OP_radians: { T a = get<T>(r); put(o, wp::radians(a)); return; }
      case OP_smoothstep: { T a = get<T>(r), b = get<T>(r), d = get<T>(r); put(o, wp::smoothstep(a, b, d)); return; }
      default: break;
    }
  }
  if constexpr (is_int || is_float) {
    if (op == OP_step) { T a = get<T>(r); put(o, wp::step(a)); return; }
  }
  if constexpr (is_float || is_fvec) {
    switch (op) {
      case OP_isfinite: { T a = get<T>(r); put(o, (u32)wp::isfinite(a)); return; }
      case OP_isnan: { T a = get<T>(r); put(o, (u32)wp::isnan(a)); return; }
      case OP_isinf: { T a = get<T>(r); put(o, (u32)wp::isinf(a)); return; }
      default: break;
    }
  }
  if constexpr (is_float || is_fvec) {
    if (op == OP_lerp) { T a = get<T>(r), b = get<T>(r); S t = get<S>(r); put(o, wp::lerp(a, b, t)); return; }
  }
  if constexpr (is_vec) {
    switch (op) {
      case OP_dot: { T a = get<T>(r), b = get<T>(r); put(o, wp::dot(a, b)); return; }
      case OP_make: { put(o, make_vec(r, (T*)nullptr)); return; }
      case OP_splat: { S s = get<S>(r); put(o, splat_of((T*)nullptr, s)); return; }
      case OP_eq: { T a = get<T>(r), b = get<T>(r); put(o, (u32)(a == b)); return; }
      case OP_ne: { T a = get<T>(r), b = get<T>(r); put(o, (u32)(a != b)); return; }
      default: break;
    }
  }
  if constexpr (is_v3) {
    if (op == OP_cross) { T a = get<T>(r), b = get<T>(r); put(o, wp::cross(a, b)); return; }
  }
  if constexpr (is_fvec) {
    switch (op) {
      case OP_length: { T a = get<T>(r); put(o, wp::length(a)); return; }
      case OP_normalize: { T a = get<T>(r); put(o, wp::normalize(a)); return; }
      case OP_add: { T a = get<T>(r), b = get<T>(r); put(o, a + b); return; }
      case OP_sub: { T a = get<T>(r), b = get<T>(r); put(o, a - b); return; }
      case OP_mul: { T a = get<T>(r), b = get<T>(r); put(o, a * b); return; }
      case OP_div: { T a = get<T>(r), b = get<T>(r); put(o, a / b); return; }
      case OP_rem: { T a = get<T>(r), b = get<T>(r); put(o, a % b); return; }
      case OP_adds: { T a = get<T>(r); S s = get<S>(r); put(o, a + s); return; }
      case OP_subs: { T a = get<T>(r); S s = get<S>(r); put(o, a - s); return; }
      case OP_muls: { T a = get<T>(r); S s = get<S>(r); put(o, a * s); return; }
      case OP_divs: { T a = get<T>(r); S s = get<S>(r); put(o, a / s); return; }
      case OP_rems: { T a = get<T>(r); S s = get<S>(r); put(o, a % s); return; }
      case OP_sadd: { S s = get<S>(r); T a = get<T>(r); put(o, s + a); return; }
      case OP_ssub: { S s = get<S>(r); T a = get<T>(r); put(o, s - a); return; }
      case OP_smul: { S s = get<S>(r); T a = get<T>(r); put(o, s * a); return; }
      case OP_sdiv: { S s = get<S>(r); T a = get<T>(r); put(o, s / a); return; }
      case OP_srem: { S s = get<S>(r); T a = get<T>(r); put(o, s % a); return; }
      case OP_neg: { T a = get<T>(r); put(o, -a); return; }
      case OP_addassign: { T a = get<T>(r), b = get<T>(r); a += b; a *= (S)2; put(o, a); return; }
      default: break;
    }
  }
  if constexpr (is_mat || is_quat) {
    typedef typename mulv_rhs<T>::type V;
    switch (op) {
      case OP_make: { put(o, make_vec(r, (T*)nullptr)); return; }
      case OP_add: { T a = get<T>(r), b = get<T>(r); put(o, a + b); return; }
      case OP_sub: { T a = get<T>(r), b = get<T>(r); put(o, a - b); return; }
      case OP_mul: { T a = get<T>(r), b = get<T>(r); put(o, a * b); return; }
      case OP_mulv: { T a = get<T>(r); V v = get<V>(r); put(o, a * v); return; }
      case OP_muls: { T a = get<T>(r); S s = get<S>(r); put(o, a * s); return; }
      case OP_divs: { T a = get<T>(r); S s = get<S>(r); put(o, a / s); return; }
      case OP_neg: { T a = get<T>(r); put(o, -a); return; }
      case OP_eq: { T a = get<T>(r), b = get<T>(r); put(o, (u32)(a == b)); return; }
      case OP_ne: { T a = get<T>(r), b = get<T>(r); put(o, (u32)(a != b)); return; }
      case OP_mulassign: { T a = get<T>(r), b = get<T>(r); a *= b; a += b; put(o, a); return; }
      default: break;
    }
  }
  if constexpr (is_mat) {
    switch (op) {
      case OP_smul: { S s = get<S>(r); T a = get<T>(r); put(o, s * a); return; }
      case OP_sdiv: { S s = get<S>(r); T a = get<T>(r); put(o, s / a); return; }
      case OP_from_diag: { typename mat_traits<T>::column d = get<typename mat_traits<T>::column>(r); put(o, from_diag_of((T*)nullptr, d)); return; }
      default: break;
    }
  }
  // wp_linalg.h
  if constexpr (is_vec) {
    if (op == OP_length_sq) { T a = get<T>(r); put(o, wp::length_sq(a)); return; }
  }
  if constexpr (is_fvec) {
    switch (op) {
      case OP_outer: { T a = get<T>(r), b = get<T>(r); put(o, wp::outer(a, b)); return; }
      case OP_diag: { T a = get<T>(r); put(o, wp::diag(a)); return; }
      case OP_cw_mul: { T a = get<T>(r), b = get<T>(r); put(o, wp::cw_mul(a, b)); return; }
      case OP_cw_div: { T a = get<T>(r), b = get<T>(r); put(o, wp::cw_div(a, b)); return; }
      default: break;
    }
  }
  if constexpr (is_v3 && num<S>::is_float) {
    switch (op) {
      case OP_skew: { T a = get<T>(r); put(o, wp::skew(a)); return; }
      case OP_qaxis: { T a = get<T>(r); S s = get<S>(r); put(o, wp::quat_from_axis_angle(a, s)); return; }
      default: break;
    }
  }
  if constexpr (is_mat) {
    switch (op) {
      case OP_cw_mul: { T a = get<T>(r), b = get<T>(r); put(o, wp::cw_mul(a, b)); return; }
      case OP_cw_div: { T a = get<T>(r), b = get<T>(r); put(o, wp::cw_div(a, b)); return; }
      case OP_transpose: { T a = get<T>(r); put(o, wp::transpose(a)); return; }
      case OP_determinant: { T a = get<T>(r); put(o, wp::determinant(a)); return; }
      case OP_inverse: { T a = get<T>(r); put(o, wp::inverse(a)); return; }
      case OP_trace: { T a = get<T>(r); put(o, wp::trace(a)); return; }
      case OP_ddot: { T a = get<T>(r), b = get<T>(r); put(o, wp::ddot(a, b)); return; }
      default: break;
    }
    if constexpr (mat_traits<T>::N == 3) {
      if (op == OP_m2q) { T a = get<T>(r); put(o, wp::quat_from_matrix(a)); return; }
      // wp_svd.h
      if (op == OP_svd3) { T a = get<T>(r); auto t = wp::svd3(a); put(o, t.f0); put(o, t.f1); put(o, t.f2); return; }
      if (op == OP_eig3) { T a = get<T>(r); auto t = wp::eig3(a); put(o, t.f0); put(o, t.f1); return; }
      if (op == OP_qr3) { T a = get<T>(r); auto t = wp::qr3(a); put(o, t.f0); put(o, t.f1); return; }
    }
    if constexpr (mat_traits<T>::N == 2) {
      if (op == OP_svd2) { T a = get<T>(r); auto t = wp::svd2(a); put(o, t.f0); put(o, t.f1); put(o, t.f2); return; }
    }
  }
  if constexpr (is_quat) {
    typedef typename mulv_rhs<T>::type V3;
    switch (op) {
      case OP_length_sq: { T a = get<T>(r); put(o, wp::length_sq(a)); return; }
      case OP_dot: { T a = get<T>(r), b = get<T>(r); put(o, wp::dot(a, b)); return; }
      case OP_length: { T a = get<T>(r); put(o, wp::length(a)); return; }
      case OP_normalize: { T a = get<T>(r); put(o, wp::normalize(a)); return; }
      case OP_inverse: { T a = get<T>(r); put(o, wp::inverse(a)); return; }
      case OP_qinv: { T a = get<T>(r); put(o, wp::quat_inverse(a)); return; }
      case OP_qrot: { T a = get<T>(r); V3 v = get<V3>(r); put(o, wp::quat_rotate(a, v)); return; }
      case OP_qrotinv: { T a = get<T>(r); V3 v = get<V3>(r); put(o, wp::quat_rotate_inv(a, v)); return; }
      case OP_q2m: { T a = get<T>(r); put(o, wp::quat_to_matrix(a)); return; }
      case OP_slerp: { T a = get<T>(r), b = get<T>(r); S t = get<S>(r); put(o, wp::quat_slerp(a, b, t)); return; }
      default: break;
    }
  }
  // wp_core.h / wp_transform.h: transforms
  if constexpr (cls<T>::xform) {
    typedef typename detail::remove_cvref<decltype(T{}.p)>::type V3;
    typedef typename detail::remove_cvref<decltype(T{}.q)>::type Q;
    switch (op) {
      case OP_make: { V3 p = get<V3>(r); Q q = get<Q>(r); put(o, transformation(p, q)); return; }
      case OP_add: { T a = get<T>(r), b = get<T>(r); put(o, a + b); return; }
      case OP_sub: { T a = get<T>(r), b = get<T>(r); put(o, a - b); return; }
      case OP_mul: { T a = get<T>(r), b = get<T>(r); put(o, a * b); put(o, transform_multiply(a, b)); return; }
      case OP_muls: { T a = get<T>(r); S s = get<S>(r); put(o, a * s); return; }
      case OP_smul: { S s = get<S>(r); T a = get<T>(r); put(o, s * a); return; }
      case OP_neg: { T a = get<T>(r); put(o, -a); return; }
      case OP_eq: { T a = get<T>(r), b = get<T>(r); put(o, (u32)(a == b)); return; }
      case OP_ne: { T a = get<T>(r), b = get<T>(r); put(o, (u32)(a != b)); return; }
      case OP_mulassign: { T a = get<T>(r), b = get<T>(r); a *= b; a += b; put(o, a); return; }
      case OP_lerp: { T a = get<T>(r), b = get<T>(r); S t = get<S>(r); put(o, wp::lerp(a, b, t)); return; }
      case OP_inverse: { T a = get<T>(r); put(o, wp::inverse(a)); return; }
      case OP_xinv: { T a = get<T>(r); put(o, transform_inverse(a)); return; }
      case OP_xpoint: { T a = get<T>(r); V3 v = get<V3>(r); put(o, transform_point(a, v)); return; }
      case OP_xvector: { T a = get<T>(r); V3 v = get<V3>(r); put(o, transform_vector(a, v)); return; }
      case OP_x2m: { T a = get<T>(r); put(o, transform_to_matrix(a)); return; }
      case OP_xget: { T a = get<T>(r); put(o, transform_get_translation(a)); put(o, transform_get_rotation(a)); return; }
      case OP_konst: { if (!konst_of((T*)nullptr, (int)r.a[r.pos++], o)) o.n = -1; return; }
      default: break;
    }
  }
  if constexpr (is_mat) {
    if constexpr (mat_traits<T>::N == 4) {
      typedef typename detail::remove_cvref<decltype(transform_from_matrix(T{}).p)>::type V3;
      switch (op) {
        case OP_xpoint: { T a = get<T>(r); V3 v = get<V3>(r); put(o, transform_point(a, v)); return; }
        case OP_xvector: { T a = get<T>(r); V3 v = get<V3>(r); put(o, transform_vector(a, v)); return; }
        case OP_m2x: { T a = get<T>(r); put(o, transform_from_matrix(a)); return; }
        default: break;
      }
    }
  }
  if constexpr (is_vec || is_mat || is_quat) {
    if (op == OP_konst) {
      if (!konst_of((T*)nullptr, (int)r.a[r.pos++], o)) o.n = -1;
      return;
    }
  }
  if constexpr (cls<T>::scalar || is_vec) {
    if constexpr (!num<T>::is_bool) {
      // Both spellings: explicit (cv/ref-qualified, as `decltype(x)` may give) and deduced.
      if (op == OP_lit) { f64 v = get<f64>(r); put(o, lit_like<const T&>(v)); return; }
      if (op == OP_intlit) { i64 v = get<i64>(r); const T like{}; put(o, int_like(like, v)); return; }
    }
  }
  // wp_rand.h: the generator on u32 states (i32 seeds), the noise on f32 and Vec2-4.
  if constexpr (is_int && sizeof(T) == 4 && !num<T>::is_signed) {
    switch (op) {
      case OP_rand_pcg: { u32 a = get<u32>(r); put(o, wp::rand_pcg(a)); return; }
      case OP_rand_init: { i32 a = get<i32>(r); put(o, wp::rand_init(a)); return; }
      case OP_rand_init_offset: { i32 a = get<i32>(r), b = get<i32>(r); put(o, wp::rand_init_offset(a, b)); return; }
      case OP_randf: { u32 a = get<u32>(r); put(o, wp::randf(a)); return; }
      case OP_randf_range: { u32 a = get<u32>(r); f32 lo = get<f32>(r), hi = get<f32>(r); put(o, wp::randf_range(a, lo, hi)); return; }
      case OP_randn: { u32 a = get<u32>(r); put(o, wp::randn(a)); return; }
      case OP_sample_triangle: { u32 a = get<u32>(r); put(o, wp::sample_triangle(a)); return; }
      case OP_sample_unit_ring: { u32 a = get<u32>(r); put(o, wp::sample_unit_ring(a)); return; }
      case OP_sample_unit_disk: { u32 a = get<u32>(r); put(o, wp::sample_unit_disk(a)); return; }
      case OP_sample_unit_square: { u32 a = get<u32>(r); put(o, wp::sample_unit_square(a)); return; }
      case OP_sample_unit_cube: { u32 a = get<u32>(r); put(o, wp::sample_unit_cube(a)); return; }
      case OP_sample_unit_sphere_surface: { u32 a = get<u32>(r); put(o, wp::sample_unit_sphere_surface(a)); return; }
      case OP_sample_unit_sphere: { u32 a = get<u32>(r); put(o, wp::sample_unit_sphere(a)); return; }
      case OP_sample_unit_hemisphere_surface: { u32 a = get<u32>(r); put(o, wp::sample_unit_hemisphere_surface(a)); return; }
      case OP_sample_unit_hemisphere: { u32 a = get<u32>(r); put(o, wp::sample_unit_hemisphere(a)); return; }
      case OP_poisson: { u32 a = get<u32>(r); f32 l = get<f32>(r); put(o, wp::poisson(a, l)); return; }
      case OP_poisson_state: { u32 a = get<u32>(r); f32 l = get<f32>(r); put(o, wp::poisson_state(a, l)); return; }
      default: break;
    }
  }
  if constexpr ((is_float || is_fvec) && sizeof(S) == 4) {
    typedef typename noise_period<T>::type P;
    switch (op) {
      case OP_noise: { u32 a = get<u32>(r); T x = get<T>(r); put(o, wp::noise(a, x)); return; }
      case OP_pnoise: { u32 a = get<u32>(r); T x = get<T>(r); P p = get<P>(r); put(o, wp::pnoise(a, x, p)); return; }
      default: break;
    }
  }
  // wp_misc.h (and the quaternion/matrix classification of wp_scalar.h)
  if constexpr (is_float) {
    if (op == OP_copysign) { T a = get<T>(r), b = get<T>(r); put(o, wp::copysign(a, b)); return; }
    if (op == OP_qrpy) {
      T a = get<T>(r), b = get<T>(r), d = get<T>(r);
      put(o, wp::quat_rpy(a, b, d));
      return;
    }
  }
  if constexpr (is_int || is_float) {
    if (op == OP_nonzero) { T a = get<T>(r); put(o, wp::nonzero(a)); return; }
  }
  if constexpr (is_vec) {
    switch (op) {
      case OP_min_element: { T a = get<T>(r); put(o, wp::min_element(a)); return; }
      case OP_max_element: { T a = get<T>(r); put(o, wp::max_element(a)); return; }
      case OP_argmin: { T a = get<T>(r); put(o, wp::argmin(a)); return; }
      case OP_argmax: { T a = get<T>(r); put(o, wp::argmax(a)); return; }
      default: break;
    }
  }
  if constexpr (is_fvec) {
    switch (op) {
      case OP_norm_l1: { T a = get<T>(r); put(o, wp::norm_l1(a)); return; }
      case OP_norm_l2: { T a = get<T>(r); put(o, wp::norm_l2(a)); return; }
      case OP_norm_huber: { T a = get<T>(r); S d = get<S>(r); put(o, wp::norm_huber(a, d)); return; }
      case OP_norm_pseudo_huber: { T a = get<T>(r); S d = get<S>(r); put(o, wp::norm_pseudo_huber(a, d)); return; }
      case OP_smooth_normalize: { T a = get<T>(r); S d = get<S>(r); put(o, wp::smooth_normalize(a, d)); return; }
      default: break;
    }
  }
  if constexpr (is_v3 && num<S>::is_float) {
    typedef typename detail::remove_cvref<decltype(wp::quat_rpy(S{}, S{}, S{}))>::type Q;
    switch (op) {
      case OP_qtwist: { T a = get<T>(r); Q q = get<Q>(r); put(o, wp::quat_twist(a, q)); return; }
      case OP_qtwista: { T a = get<T>(r); Q q = get<Q>(r); put(o, wp::quat_twist_angle(a, q)); return; }
      case OP_qtwistas: { T a = get<T>(r); Q q = get<Q>(r); put(o, wp::quat_twist_angle_signed(a, q)); return; }
      case OP_xcompose: { T p = get<T>(r); Q q = get<Q>(r); T s = get<T>(r); put(o, wp::transform_compose(p, q, s)); return; }
      default: break;
    }
  }
  if constexpr (is_mat || is_quat) {
    switch (op) {
      case OP_isfinite: { T a = get<T>(r); put(o, (u32)wp::isfinite(a)); return; }
      case OP_isnan: { T a = get<T>(r); put(o, (u32)wp::isnan(a)); return; }
      case OP_isinf: { T a = get<T>(r); put(o, (u32)wp::isinf(a)); return; }
      default: break;
    }
  }
  if constexpr (is_mat) {
    if (op == OP_get_diag) { T a = get<T>(r); put(o, wp::get_diag(a)); return; }
    if constexpr (mat_traits<T>::N == 4) {
      if (op == OP_xdecompose) { T a = get<T>(r); auto t = wp::transform_decompose(a); put(o, t.f0); put(o, t.f1); put(o, t.f2); return; }
    }
  }
  if constexpr (is_quat) {
    if (op == OP_q2aa) { T a = get<T>(r); auto t = wp::quat_to_axis_angle(a); put(o, t.f0); put(o, t.f1); return; }
    if (op == OP_q2rpy) { T a = get<T>(r); put(o, wp::quat_to_rpy(a)); return; }
  }
  if constexpr (is_int || is_float || is_fvec) {
    if (op == OP_atomic_add || op == OP_atomic_sub || op == OP_atomic_min || op == OP_atomic_max) {
      if constexpr (is_int && (sizeof(T) < 4)) {
        o.n = -1;
      } else {
        atomic_case<T>(op, r, o, ctx);
      }
      return;
    }
  }
  o.n = -1;
}

DRV_FN void run_range(reader& r, out_t& o, ctx_t* ctx) {
  const i64 start = (i64)r.a[r.pos++], end = (i64)r.a[r.pos++];
  const bool incl = r.a[r.pos++] != 0;
  const int nad = (int)r.a[r.pos++];
  range_t g = range_new(start, end, incl);
  for (int k = 0; k < nad; ++k) {
    const u64 kind = r.a[r.pos++];
    const i64 step = (i64)r.a[r.pos++];
    if (kind == 0)
      g = range_rev(g);
    else
      g = range_step_by(g, step, ctx);
    if (faulted(ctx)) break;  // the CPU's `?`
  }
  put(o, g.first);
  put(o, g.step);
  put(o, g.count);
  // A few values through range_at (the first, second and last).
  put(o, range_at(g, 0));
  put(o, range_at(g, 1));
  put(o, range_at(g, g.count > 0 ? g.count - 1 : 0));
}

DRV_FN void run_unflatten(reader& r, out_t& o) {
  launch_t l;
  const int n = (int)r.a[r.pos++];
  l.total = 1;
  for (int k = 0; k < 4; ++k) {
    l.dims[k] = (i64)r.a[r.pos++];
    if (k < n) l.total *= l.dims[k];
  }
  l.ndim = n;
  l.flags = 0;
  const i64 flat = (i64)r.a[r.pos++];
  i64 out[4] = {0, 0, 0, 0};
  unflatten(l, flat, out, n);
  for (int k = 0; k < n; ++k) put(o, out[k]);
}

DRV_FN void compute(const case_t& c, out_t& o) {
  o.n = 0;
  o.flag = 0;
  launch_ctx_t rec = launch_ctx_make(&o.fault, &o.flag);
  ctx_t ctxv = ctx_make(&rec);
  ctx_t* ctx = &ctxv;
  reader r;
  r.a = c.a;
  r.pos = 0;
  if (c.op == OP_range) {
    run_range(r, o, ctx);
    return;
  }
  if (c.op == OP_unflatten) {
    run_unflatten(r, o);
    return;
  }
  if (c.op == OP_load || c.op == OP_store || c.op == OP_len) {
    const int ndim = (int)r.a[r.pos++];
    switch (ndim) {
      case 1: array_case<1>(c.op, r, o, ctx); return;
      case 2: array_case<2>(c.op, r, o, ctx); return;
      case 3: array_case<3>(c.op, r, o, ctx); return;
      case 4: array_case<4>(c.op, r, o, ctx); return;
      default: o.n = -1; return;
    }
  }
  switch (c.ty) {
#define CASE_T(t)           \
  case T_##t:               \
    run<t>(c, r, o, ctx);   \
    return;
    TYPE_LIST(CASE_T)
#undef CASE_T
    default:
      o.n = -1;
  }
}

}  // namespace drv

#if defined(__CUDACC__)
extern "C" __global__ void compute_all(const drv::case_t* cases, drv::out_t* outs, int n) {
  const wp::i64 i = wp::flat_thread_id();
  if (i < n) drv::compute(cases[i], outs[i]);
}
#endif

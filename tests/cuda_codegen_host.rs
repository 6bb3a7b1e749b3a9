//! The CUDA code generator, checked without a GPU: real kernels' CUDA translation units (as
//! the runtime assembles them for NVRTC) are compiled as host C++ with g++ against the CUDA
//! builtin library in `warp-cuda/cuda/`, their per-thread functions are run over the grid, and
//! the results are compared with the CPU backend's, bit for bit.
//!
//! Bit-exact is the right tolerance here: both sides do the same IEEE operations in the same
//! order (g++ is run with `-ffp-contract=off`, so no FMA contraction; sqrt is correctly
//! rounded on both). On the GPU, FMA contraction changes the last bits, which the backend
//! suite allows for; this test is about the generated code's meaning.

use std::fmt::Write as _;
use std::process::Command;
use warp_lang as wp;
use wp::prelude::*;
use wp::Kernel;

#[wp::kernel]
fn integrate(x: Array<Vec3>, v: Array<Vec3>, b: f32, mass: f32, gravity: Vec3, dt: f32) {
    let i = tid();
    let a = -b * v[i] / mass + gravity;
    v[i] += a * dt;
    x[i] += v[i] * dt;
}

#[wp::func]
fn poly(x: f32, n: i32) -> f32 {
    let mut s = 0.0;
    for k in (0..n).rev().step_by(2) {
        s += x * (k as f32);
    }
    s
}

#[wp::func]
fn half_or_neg(x: f32, odd: bool) -> f32 {
    if odd {
        return -x;
    }
    x * 0.5
}

#[wp::func]
fn is_pos(x: f32) -> bool {
    x > 0.0
}

#[wp::kernel]
fn mixed(a: Array<f32>, b: Array<i32>, out: Array<f32>, total: Array<i32>) {
    let i = tid();
    let v = if b[i] % 2 == 0 {
        poly(a[i], b[i])
    } else {
        half_or_neg(a[i], true)
    };
    out[i] = v.max(0.5) + sqrt(a[i].abs()) + (b[i] as f32) / 3.0;
    let w = b[i] / 3 + (b[i] << 2) - i32::MAX;
    atomic_add(total, 0, w);
    let mut k = 0;
    while k < 10 && a[i] > 0.0 {
        k += 1;
        if k == 7 {
            break;
        }
    }
    out[i] += k as f32 * 0.25;
    // A plain range loop (emitted as a native C++ loop) with `continue`.
    let mut acc = 0;
    for q in 0..b[i].abs() % 7 {
        if q == 2 {
            continue;
        }
        acc += q;
    }
    out[i] += acc as f32;
    // Accesses at a loop variable (checked once before the loop when the range is inside).
    for j in 0..(b[i].abs() % 9) as usize {
        out[i] += a[j] * 0.5;
    }
    // `!` on a func's bool (a type the kernel macro cannot see): logical, not bitwise.
    if !is_pos(a[i]) {
        out[i] -= 1.0;
    }
}

#[wp::kernel]
fn grid2d(m: Array<f32, 2>, s: f32) {
    let (i, j) = tid();
    let c = vec2(i as f32, j as f32);
    m[(i, j)] = c.dot(c) * s + m[(i, j)] - c.length();
}

/// Warp's scalar math builtins (the ones with a CUDA transcription or glibc on both sides;
/// `cbrt` is left out: Rust's is no longer glibc's), `mod` lowered to `%`, and the
/// classification builtins returning bool.
#[wp::kernel]
fn scalar_math(x: Array<f32>, out: Array<f32, 2>, flags: Array<i32>) {
    let i = tid();
    let a = x[i];
    let u = a * 0.125;
    out[(i, 0)] = asin(u) + acos(u) * atan(a);
    out[(i, 1)] = sinh(u) + cosh(u) * tanh(a);
    out[(i, 2)] = exp2(u) + log2(abs(a)) * log10(abs(a));
    out[(i, 3)] = erf(a) + erfc(u) * erfinv(u) + erfcinv(u + 1.0);
    out[(i, 4)] = round(a) + rint(a) * 2.0 + trunc(a) * 4.0 + frac(a) * 8.0;
    out[(i, 5)] = degrees(a) + radians(a) + step(a) + smoothstep(-1.0, 2.0, a);
    out[(i, 6)] = r#mod(a, 0.75) + smoothstep(0.5, 0.5, a);
    flags[i] = isfinite(a) as i32 + isnan(u) as i32 * 2 + isinf(a * 1e38) as i32 * 4;
}

/// The atomics without an adjoint (the host build runs its threads one after another, as the
/// CPU backend does for a launch this small, so even exchanges give the same order).
#[wp::kernel]
fn swaps_and_bits(a: Array<i32>, f: Array<f32>, flags: Array<i32>) {
    let i = tid();
    let k = i as i32;
    a[i] = atomic_exch(flags, 0, k) + atomic_cas(flags, 1, k - 1, k) * 100;
    atomic_or(flags, 2, 1 << (k % 31));
    atomic_xor(flags, 3, k * 7);
    atomic_and(flags, 4, !(k & 3));
    let g = atomic_cas(f, i, -0.0, 1.5) + atomic_exch(f, (i + 1) % 25, 0.5) * 2.0;
    f[i] += g;
}

/// In-kernel views: rows of a 2-D array, ranges, a view of a view, lengths; thread 5 (in the
/// CPU-only 6-thread launch) reads `v[5]` of a 5-element view and faults.
#[wp::kernel]
fn views(m: Array<f32, 2>, x: Array<f32>, out: Array<f32>) {
    let i = tid();
    let r = m.row(i % 3);
    let v = x.view(1..6);
    let w = v.view(2..);
    out[i] = r[i % 4] * 2.0 + v[i % 5] + w[i % w.len()] * 0.5 + (r.len() + w.len()) as f32;
    if i == 5 {
        out[i] = v[5];
    }
}

/// The random-number lowering: draws advance a state in place (in a loop, so the state is
/// loop-carried), ranges, the samplers, poisson, noise and pnoise with Warp's spelling.
#[wp::kernel]
fn rng_draws(x: Array<f32>, out: Array<f32, 2>, ints: Array<i32>) {
    let i = tid();
    let mut s = rand_init(7, i as i32);
    let mut acc = 0.0;
    for _k in 0..3 {
        acc += randf(&mut s) + randf(&mut s, -1.0, x[i]);
    }
    out[(i, 0)] = acc;
    out[(i, 1)] = randn(&mut s);
    let d = sample_unit_disk(&mut s);
    out[(i, 2)] = d.x * d.y;
    let c = sample_unit_sphere(&mut s);
    out[(i, 3)] = c.x + c.y + c.z;
    out[(i, 4)] = noise(s, vec3(x[i], 0.5, -x[i])) + pnoise(s, vec2(x[i], 1.5), 3, 4);
    ints[i] = randi(&mut s, -3, 9) + poisson(&mut s, 4.5) as i32 + (randu(&mut s) % 7) as i32;
}

/// Rigid transforms: construction (`Transform::new`, `transformation`, `IDENTITY`,
/// `from_matrix`), fields (read, nested compound write), composition and the lane operators,
/// every transform builtin (the 4x4 overloads too), `inverse`, `lerp`, `==`.
#[wp::kernel]
fn transforms(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let t = Transform::new(
        vec3(a, a * 0.5, -a),
        normalize(Quat::from_xyzw(0.1 * a, 0.2, -0.3, 1.0)),
    );
    let u = transformation(
        vec3(0.25, a, 1.0),
        Quat::from_axis_angle(vec3(0.0, 0.6, 0.8), a),
    );
    let mut c = t * u * Transform::IDENTITY;
    c.p.y += 0.5;
    c.q = c.q * 0.5 + u.q * 0.5;
    let v = vec3(a, 1.0, 2.0);
    let m = transform_to_matrix(u);
    let p = c.transform_point(v)
        + transform_vector(inverse(t), v)
        + transform_point(m, v)
        + m.transform_vector3(v)
        + Transform::from_matrix(transform_to_matrix(t)).p
        + lerp(t, u, 0.3).p
        + (t + u - t * 2.0 + 0.5 * (-u)).p
        + transform_get_translation(transform_inverse(c));
    let q = transform_multiply(c, t).q
        + transform_get_rotation(t.lerp(c, a))
        + transform_from_matrix(m).q;
    out[(i, 0)] = p.x;
    out[(i, 1)] = p.y;
    out[(i, 2)] = p.z;
    out[(i, 3)] = q.x;
    out[(i, 4)] = q.y;
    out[(i, 5)] = q.z;
    out[(i, 6)] = q.w;
    out[(i, 7)] = if t == t && t != u { 1.0 } else { 0.0 };
}

/// Spatial vectors and matrices: construction (`SpatialVector::new`, `spatial_vector` of two
/// 3-vectors and of six scalars, `ZERO`, `IDENTITY`, `SpatialMatrix::from_rows`), literal
/// indexing and lane, row and entry writes, the operators and products, every spatial builtin
/// (`transpose`, `outer`, `spatial_adjoint`, `transform_twist`/`wrench` too), `==`, and local
/// arrays of spatial vectors and matrices.
#[wp::kernel]
fn spatial(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let u = SpatialVector::new(vec3(a, 0.5, -a), vec3(1.0, a * 0.25, 2.0));
    let w = spatial_vector(0.3, a, -1.5, 0.75 * a, 2.0, -0.5);
    let t = Transform::new(
        vec3(a, 1.0, -0.5),
        Quat::from_axis_angle(vec3(0.0, 0.6, 0.8), a),
    );
    let mut m = outer(u, w) + SpatialMatrix::IDENTITY * a;
    m[(0, 5)] = a * 3.0;
    m[2][1] -= 1.0;
    m[4] = spatial_cross(u, w);
    let r = quat_to_matrix(t.q);
    let x6 = spatial_adjoint(r, skew(t.p) * r);
    let n = SpatialMatrix::from_rows(w, u, w, SpatialVector::ZERO, u, w) * 0.5;
    let p = (m * n) * u + transpose(m) * w - x6 * u / 2.0 + (-n.transpose()) * w;
    let mut q = spatial_cross_dual(p, u) + transform_twist(t, u) - transform_wrench(t, w) * a;
    q[1] += spatial_dot(u, w);
    let top = spatial_top(q) + spatial_bottom(p);
    // Local arrays of spatial values: elements at run-time indices, their lanes and entries.
    let mut sa = [SpatialVector::ZERO; 3];
    let j = i % 3;
    sa[j] = u;
    sa[(j + 1) % 3][4] = a;
    sa[j][2] += sa[(j + 1) % 3][4];
    let mut sm = [SpatialMatrix::IDENTITY; 2];
    sm[i % 2][(1, 3)] = a;
    sm[1][5][0] = -a;
    let mut k = 0;
    while k < 6 {
        out[(i, k)] = 0.0;
        k += 1;
    }
    out[(i, 0)] = q[0];
    out[(i, 1)] = q[1];
    out[(i, 2)] = q[2];
    out[(i, 3)] = q[3] + top.x;
    out[(i, 4)] = q[4] + top.y + m[(4, 2)];
    out[(i, 5)] = q[5] + top.z + x6[3][1];
    out[(i, 6)] = if u == u && u != w && m == m { 1.0 } else { 0.0 };
    out[(i, 7)] = spatial_dot(2.0 * p, q) + spatial_dot(sm[i % 2] * sa[j], w);
}

/// Non-square matrices: `from_rows`, `ZERO`, rows and entries at literal and run-time
/// indices (read and written), the operators, products with glam's square and the spatial
/// matrices on either side, `transpose`, `outer` of vectors of different lengths, `ddot`, `==`,
/// and a local array of matrices.
#[wp::kernel]
fn nonsquare(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let mut m = Mat23::from_rows(vec3(a, 0.5, -a), vec3(1.0, a * 0.25, 2.0));
    m[(0, 2)] = a * 3.0;
    m[1].y -= 1.0;
    let j = i % 2;
    m[(j, j + 1)] += 0.5;
    let t = transpose(m) * 2.0 - outer(vec3(a, 1.0, -0.5), vec2(0.25, a)) / 3.0;
    let s = Mat3::from_cols(vec3(1.0, a, 0.0), vec3(0.5, -1.0, a), vec3(a, 2.0, 0.75));
    let p = m * s * t + m * t * 0.5;
    let big = Mat63::from_rows(m[0], m[1], m[0] * a, vec3(1.0, 2.0, 3.0), m[j], -m[1]);
    let sm = big * transpose(big);
    let sv = big * vec3(0.5, a, -1.0);
    let mut loc = [Mat23::ZERO; 2];
    loc[j] = m;
    loc[1 - j][(1, 2)] = a;
    out[(i, 0)] = p.x_axis.x + p.y_axis.y;
    out[(i, 1)] = p.x_axis.y - p.y_axis.x;
    out[(i, 2)] = ddot(m, transpose(t)) + ddot(loc[0], loc[1]);
    out[(i, 3)] = sm[(2, 5)] + sm[4][4];
    out[(i, 4)] = spatial_dot(sv, sv) + (m * vec3(1.0, -2.0, a)).x;
    out[(i, 5)] = (s * t)[(2, 1)] + t[j].y;
    out[(i, 6)] = if m == m && m != -m { 1.0 } else { 0.0 };
    out[(i, 7)] = (m + m - m * 0.5)[(1, j)];
}

/// Lanes at run-time indices, as Warp code writes them: a vector's `v[k]` read, written and
/// updated, a matrix-vector product by loops over `m[(r, c)]`, a quaternion's lane (x, y, z,
/// w), a 4x4 matrix's entries and an integer vector's lanes, a spatial vector's lanes and a
/// spatial matrix's rows and entries.
#[wp::kernel]
fn lanes(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let k = i % 3;
    let mut v = vec3(a, a * 0.5, -a);
    v[k] += 1.5;
    v[(k + 1) % 3] = v[k] * 2.0;
    let mut m = Mat3::from_cols(v, vec3(0.25, a, 2.0), vec3(-1.0, 0.5, a * a));
    let mut y = Vec3::ZERO;
    for r in 0..3 {
        for c in 0..3 {
            y[r] += m[(r, c)] * v[c];
        }
    }
    m[(k, 2)] -= y[k];
    let mut q = Quat::from_xyzw(a, 0.5, -0.25, 1.0);
    q[3 - k] *= 2.0;
    let mut w = Vec4::new(1.0, a, 2.0, -a);
    let mut m4 = Mat4::IDENTITY * a;
    for c in 0..4usize {
        m4[(c, (c + k) % 4)] += w[c];
        w[c] = q[c] + m4[(3, c)];
    }
    let mut iv = IVec3::new(1, 2, 3);
    iv[k] = iv[(k + 2) % 3] * 7;
    let mut sv = spatial_vector(a, 1.0, 2.0, 3.0, -a, 0.5);
    let mut sm = SpatialMatrix::IDENTITY * a;
    for r in 0..6usize {
        sv[r] += sm[(r, (r + k) % 6)];
        sm[r][k] = sv[r];
    }
    sm[(5 - k, k)] = 4.0;
    let row = sm[k];
    out[(i, 0)] = y[0];
    out[(i, 1)] = y[1];
    out[(i, 2)] = y[2];
    out[(i, 3)] = m[(k, 2)] + m[(2, k)];
    out[(i, 4)] = q[k] + q[3];
    out[(i, 5)] = w[0] + w[3] + m4[(k, 3)];
    out[(i, 6)] = iv[k] as f32 + iv[(k + 1) % 3] as f32;
    out[(i, 7)] = sv[5] + row[k] + sm[(2, 2)] + sv[k];
}

/// The decompositions: tuple results destructured (with `_` and an annotation), inside a loop
/// that overwrites them, and every output written out.
#[wp::kernel]
fn decompositions(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let b = i * 9;
    let a = Mat3::from_cols(
        Vec3::new(x[b], x[b + 1], x[b + 2]),
        Vec3::new(x[b + 3], x[b + 4], x[b + 5]),
        Vec3::new(x[b + 6], x[b + 7], x[b + 8]),
    );
    let mut m = a;
    let mut k = 0;
    for _r in 0..2 {
        let (u, s, v): (Mat3, Vec3, Mat3) = svd3(m);
        m = u * Mat3::from_diagonal(s) * v.transpose() + Mat3::IDENTITY * 0.25;
        out[(i, k)] = s.x + s.y * 2.0 + s.z * 4.0;
        out[(i, k + 1)] = u.x_axis.x + u.y_axis.z + v.z_axis.y;
        k += 2;
    }
    let (q, d) = eig3((a + a.transpose()) * 0.5);
    out[(i, 4)] = d.x;
    out[(i, 5)] = d.y;
    out[(i, 6)] = d.z;
    out[(i, 7)] = q.x_axis.y + q.z_axis.x;
    let (q2, r) = qr3(a);
    out[(i, 8)] = q2.y_axis.x + r.z_axis.z;
    let (_, s2, v2) = svd2(Mat2::from_cols(
        Vec2::new(a.x_axis.x, a.x_axis.y),
        Vec2::new(a.y_axis.x, a.y_axis.y),
    ));
    out[(i, 9)] = s2.x + s2.y * 3.0 + v2.x_axis.y;
}

#[wp::func]
fn split_pair(x: f32) -> (f32, Vec3) {
    (x * 2.0, vec3(x, x * x, 1.0))
}

#[wp::func]
fn add_into(acc: &mut f32, x: f32) -> f32 {
    *acc += x;
    *acc * 0.5
}

#[wp::func]
fn scale_lanes(v: &mut Vec3, k: &mut f32) {
    v.x *= *k;
    add_into(&mut v.y, *k);
    *k = 0.0;
}

/// Tuple results (destructured, by element, nested in a literal), destructuring assignment,
/// and `&mut` parameters (a local, a lane, a local array's element, an array element; two at
/// once; passed on).
#[wp::kernel]
fn refs_and_tuples(x: Array<f32>, acc: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let (s, v) = split_pair(x[i]);
    let t = (s, (v.y, 3));
    let mut a = x[i];
    let h = add_into(&mut a, t.1 .0);
    let mut w = vec3(x[i], 1.0, 2.0);
    let mut k = 2.0f32;
    scale_lanes(&mut w, &mut k);
    let mut l = [x[i], 0.5];
    add_into(&mut l[1], split_pair(x[i]).0);
    add_into(&mut acc[i], x[i]);
    // Destructuring assignment: the right-hand side is read whole first (a swap).
    let mut p = (a, h);
    (p.1, p.0) = p;
    (w.z, _) = (w.z * 0.5, 0);
    out[(i, 0)] = p.1 + p.0 * 3.0;
    out[(i, 1)] = w.x + w.y + w.z + k;
    out[(i, 2)] = l[0] + l[1] + t.1 .1 as f32;
}

const GRAVITY: f32 = -9.81;
const THIRD: f64 = 1.0 / 3.0;
const N_STEPS: i32 = 3;
const OFFSET: Vec3 = Vec3::new(0.5, -1.25, 2.0);
mod physics {
    pub const DRAG: f32 = 0.1;
}

/// Module-level consts: their values reach the CUDA source exactly (bit patterns).
#[wp::kernel]
fn consts(x: Array<f32>, v: Array<Vec3>, n: Array<i32>) {
    let i = tid();
    let mut acc = x[i];
    for _ in 0..N_STEPS {
        acc = acc * (1.0 - physics::DRAG) + GRAVITY;
    }
    x[i] = acc + (THIRD * x[i] as f64) as f32;
    v[i] = v[i] * physics::DRAG + OFFSET;
    n[i] = N_STEPS * i as i32;
}

#[wp::func]
fn f16_poly(x: f16, k: i32) -> f16 {
    x * x * 0.5 - (k as f16) + 1.0
}

/// f16 (converted from and to the f32 arrays): operators, compound assignment, literals
/// (rounded once, ties to even), casts from f32/f64/integers and to f32/i32, a func's f16
/// parameters and result (cast where the macro cannot see its type), builtins.
#[wp::kernel]
fn half_precision(a: Array<f32>, d: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let x = a[i] as f16;
    let y = (d[i] as f64) as f16;
    let mut acc = x;
    acc += 0.1;
    acc *= y;
    acc -= 1.00048828125;
    out[(i, 0)] = (x + y) as f32;
    out[(i, 1)] = (x * y - 3.0) as f32;
    out[(i, 2)] = (x / y) as f32;
    out[(i, 3)] = (x % y) as f32;
    out[(i, 4)] = acc as f32;
    out[(i, 5)] = sqrt(abs(x)) as f32;
    out[(i, 6)] = max(x, y).min(2.5) as f32;
    out[(i, 7)] = f16_poly(x, i as i32) as f32;
    out[(i, 8)] = ((x * 1000.0) as i32) as f32;
    out[(i, 9)] = (-x + f16::MAX * 0.5 + y) as f32;
    let big = (i as i32 * 9000) as f16;
    out[(i, 10)] = big as f32;
    out[(i, 11)] = if x < y {
        floor(x * 3.0) as f32
    } else {
        lerp(x, y, 0.25) as f32
    };
}

#[wp::func]
fn bf16_poly(x: bf16, k: i32) -> bf16 {
    x * x * 0.5 - (k as bf16) + 1.0
}

/// bf16, as `half_precision` does f16: operators, compound assignment, literals (rounded once,
/// ties to even), casts from f32/f64/integers/f16 and to f32/i32/f16, a func's bf16 parameters
/// and result, builtins.
#[wp::kernel]
fn brain_float(a: Array<f32>, d: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let x = a[i] as bf16;
    let y = (d[i] as f64) as bf16;
    let mut acc = x;
    acc += 0.1;
    acc *= y;
    acc -= 1.00390625;
    out[(i, 0)] = (x + y) as f32;
    out[(i, 1)] = (x * y - 3.0) as f32;
    out[(i, 2)] = (x / y) as f32;
    out[(i, 3)] = (x % y) as f32;
    out[(i, 4)] = acc as f32;
    out[(i, 5)] = sqrt(abs(x)) as f32;
    out[(i, 6)] = max(x, y).min(2.5) as f32;
    out[(i, 7)] = bf16_poly(x, i as i32) as f32;
    out[(i, 8)] = ((x * 1000.0) as i32) as f32;
    out[(i, 9)] = (-x + bf16::MAX * 0.5 + y) as f32;
    let big = (i as i64 * 33_554_435) as bf16;
    out[(i, 10)] = big as f32;
    out[(i, 11)] = if x < y {
        floor(x * 3.0) as f32
    } else {
        ((lerp(x, y, 0.25) as f16) as bf16) as f32
    };
}

/// The misc section: reductions and their overloads, copysign, nonzero, get_diag, norms
/// (with the default delta), axis-angle (a tuple), roll-pitch-yaw, twists, compose and
/// decompose (a tuple), classification of quaternions and matrices, `lower_bound` (both
/// overloads, through the fault context) and `sample_cdf` (a draw reading an array).
#[wp::kernel]
fn misc_builtins(x: Array<f32>, cdf: Array<f32>, out: Array<f32, 2>, ints: Array<i32>) {
    let i = tid();
    let a = x[i];
    let v = vec3(a, 1.0 - a, a * a - 2.0);
    let q = normalize(Quat::from_xyzw(0.1 * a, 0.2, -0.3, 1.0 - a));
    let (axis, angle) = quat_to_axis_angle(q);
    let e = quat_to_rpy(q);
    let r = quat_rpy(a, 0.5 * a, -a);
    let m = transform_compose(v, q, vec3(2.0, 0.5 + a * a, 1.0));
    let (p, q2, s) = transform_decompose(m);
    out[(i, 0)] = min(v) + max(v) * 2.0 + v.min_element() * 4.0 + copysign(a, -1.0);
    out[(i, 1)] = norm_l1(v) + norm_l2(v) + norm_huber(v, 0.8) + norm_pseudo_huber(v);
    out[(i, 2)] = dot(smooth_normalize(v, 1.5), axis) + angle + nonzero(a);
    out[(i, 3)] = e.x + e.y * 2.0 + e.z * 4.0 + dot(r, q);
    out[(i, 4)] = dot(quat_twist(normalize(v), q), r)
        + quat_twist_angle(axis, r)
        + quat_twist_angle_signed(axis, q);
    out[(i, 5)] = dot(get_diag(m), vec4(1.0, 2.0, 3.0, 4.0)) + dot(p + s, v) + dot(q2, q);
    out[(i, 6)] = div_approx(a, 3.0)
        + inverse_approx(Mat2::from_cols(vec2(a, 1.0), vec2(0.5, 2.0)))
            .x_axis
            .y;
    ints[i * 3] =
        argmin(v) as i32 + 4 * argmax(v) as i32 + 16 * (if isnan(m) || isinf(q) { 1 } else { 0 });
    ints[i * 3 + 1] = lower_bound(cdf, a) + 8 * lower_bound(cdf, 1, 4, a * 0.5);
    let mut st = rand_init(11, i as i32);
    ints[i * 3 + 2] = sample_cdf(&mut st, cdf) + 8 * sample_cdf(&mut st, cdf);
}

/// The nearest other point within `r` of `p` (through a func: a query in a func), or -1.
#[wp::func]
fn nearest_other(grid: HashGrid, x: Array<Vec3>, p: Vec3, r: f32, me: usize) -> i32 {
    let mut best = -1;
    let mut bd = r;
    for j in hash_grid_query(grid, p, r) {
        let d = length(x[j] - p);
        if j != me && d <= bd {
            best = j as i32;
            bd = d;
        }
    }
    best
}

/// The hash grid's query in a kernel and a func: `hash_grid_point_id`, `continue`, `break`,
/// and a float sum over the candidates in their order (so the order must be the CPU's).
#[wp::kernel]
fn hash_grid_queries(grid: HashGrid, x: Array<Vec3>, r: f32, out: Array<f32>, ints: Array<i32>) {
    let t = tid();
    let i = hash_grid_point_id(grid, t);
    let p = x[i];
    let mut s = 0.0;
    let mut c = 0;
    let mut m = 0;
    for j in hash_grid_query(grid, p, r) {
        m += 1;
        if j == i {
            continue;
        }
        let d = length(x[j] - p);
        if d <= r {
            s += (r - d) * (j as f32 + 1.0);
            c += 1;
        }
        if c > 5 {
            break;
        }
    }
    out[i] = s;
    ints[3 * i] = c;
    ints[3 * i + 1] = m;
    ints[3 * i + 2] = nearest_other(grid, x, p, r * 0.5, i);
}

wp::overloads!(blend);

/// Overloads told apart by their second parameter (the CUDA unit holds each as a function of
/// its own; the call sites name the one rustc resolved).
#[wp::func(overload)]
fn blend(a: f32, b: f32) -> f32 {
    a * 0.75 + b
}

#[wp::func(overload)]
fn blend(a: f32, n: i32) -> f32 {
    a * (n as f32) - 0.5
}

/// A vector overload with a custom gradient, itself an overload of another set.
#[wp::func(overload, grad(a = dblend))]
fn blend(a: Vec3, b: f32) -> Vec3 {
    a * b + Vec3::X
}

wp::overloads!(dblend);

#[wp::func(overload)]
fn dblend(a: Vec3, b: f32, adj: Vec3) -> Vec3 {
    adj * b
}

/// A generic func with a generic custom gradient, called without naming its instance.
#[wp::func(grad(x = dcubic))]
fn cubic<T: Float>(x: T) -> T {
    x * x * x - x
}

#[wp::func]
fn dcubic<T: Float>(x: T, adj: T) -> T {
    (3.0 * x * x - 1.0) * adj
}

#[wp::kernel]
fn overloaded(x: Array<f32>, n: Array<i32>, v: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    out[i] = blend(x[i], 2.0f32) + blend(x[i], n[i]) + cubic(x[i]) + blend(cubic(x[i]), n[i]);
    v[i] = blend(v[i], x[i]);
}

/// A host argument: how to declare it in C++, and how to print it back.
enum Arg<'a> {
    F32(f32),
    Vec3(Vec3),
    F32s(&'a wp::Array<f32>),
    I32s(&'a wp::Array<i32>),
    Vec3s(&'a wp::Array<Vec3>),
    F32Grid(&'a wp::Array<f32, 2>),
    /// A built CPU hash grid, passed as the `wp::hash_grid_t` over copies of its buffers.
    HashGrid(&'a wp::HashGrid),
}

fn f32_bits(x: f32) -> String {
    format!("0x{:08x}u", x.to_bits())
}

/// C++ that declares the arguments (`p0`, `p1`, ..), and C++ that prints every array's
/// elements as bit patterns, one per line.
fn cpp_args(args: &[Arg]) -> (String, String) {
    let mut decl = String::new();
    let mut print = String::new();
    let floats = |v: &[f32]| {
        v.iter()
            .map(|x| format!("bits_f32({})", f32_bits(*x)))
            .collect::<Vec<_>>()
            .join(", ")
    };
    for (k, a) in args.iter().enumerate() {
        match a {
            Arg::F32(x) => writeln!(decl, "wp::f32 p{k} = bits_f32({});", f32_bits(*x)).unwrap(),
            Arg::Vec3(v) => writeln!(
                decl,
                "wp::Vec3 p{k} = wp::Vec3_new({});",
                floats(&v.to_array())
            )
            .unwrap(),
            Arg::F32s(a) => {
                let d = a.to_vec().unwrap();
                writeln!(decl, "static wp::f32 d{k}[] = {{{}}};", floats(&d)).unwrap();
                writeln!(
                    decl,
                    "wp::array_t<wp::f32, 1> p{k} = {{d{k}, {{{}}}, {{4}}, {k}, 0}};",
                    d.len()
                )
                .unwrap();
                writeln!(
                    print,
                    "for (int e = 0; e < {}; ++e) print_f32(d{k}[e]);",
                    d.len()
                )
                .unwrap();
            }
            Arg::I32s(a) => {
                let d = a.to_vec().unwrap();
                let list = d
                    .iter()
                    .map(|x| format!("{x}"))
                    .collect::<Vec<_>>()
                    .join(", ");
                writeln!(decl, "static wp::i32 d{k}[] = {{{list}}};").unwrap();
                writeln!(
                    decl,
                    "wp::array_t<wp::i32, 1> p{k} = {{d{k}, {{{}}}, {{4}}, {k}, 0}};",
                    d.len()
                )
                .unwrap();
                writeln!(
                    print,
                    "for (int e = 0; e < {}; ++e) printf(\"%d\\n\", d{k}[e]);",
                    d.len()
                )
                .unwrap();
            }
            Arg::Vec3s(a) => {
                let d = a.to_vec().unwrap();
                let items = d
                    .iter()
                    .map(|v| format!("wp::Vec3_new({})", floats(&v.to_array())))
                    .collect::<Vec<_>>();
                writeln!(decl, "static wp::Vec3 d{k}[] = {{{}}};", items.join(", ")).unwrap();
                writeln!(
                    decl,
                    "wp::array_t<wp::Vec3, 1> p{k} = {{d{k}, {{{}}}, {{12}}, {k}, 0}};",
                    d.len()
                )
                .unwrap();
                writeln!(
                    print,
                    "for (int e = 0; e < {}; ++e) {{ print_f32(d{k}[e].x); print_f32(d{k}[e].y); print_f32(d{k}[e].z); }}",
                    d.len()
                )
                .unwrap();
            }
            Arg::HashGrid(g) => {
                // A trailing 0 in each buffer: C++ has no empty arrays.
                let ints = |a: &wp::Array<i32>| {
                    let mut v: Vec<String> =
                        a.to_vec().unwrap().iter().map(|x| x.to_string()).collect();
                    v.push("0".into());
                    v.join(", ")
                };
                let ids = g.point_ids().unwrap();
                let (starts, ends) = g.cell_ranges().unwrap();
                for (name, a) in [("ids", &ids), ("starts", &starts), ("ends", &ends)] {
                    writeln!(decl, "static wp::i32 {name}{k}[] = {{{}}};", ints(a)).unwrap();
                }
                let [dx, dy, dz] = g.dims();
                let inv = 1.0 / g.cell_width().unwrap();
                writeln!(
                    decl,
                    "wp::hash_grid_t p{k} = {{ids{k}, starts{k}, ends{k}, {{{dx}, {dy}, {dz}}}, {}, bits_f32({}), {k}}};",
                    ids.len(),
                    f32_bits(inv)
                )
                .unwrap();
            }
            Arg::F32Grid(a) => {
                let d = a.to_vec().unwrap();
                let [r, c] = a.shape();
                writeln!(decl, "static wp::f32 d{k}[] = {{{}}};", floats(&d)).unwrap();
                writeln!(
                    decl,
                    "wp::array_t<wp::f32, 2> p{k} = {{d{k}, {{{r}, {c}}}, {{{}, 4}}, {k}, 0}};",
                    c * 4
                )
                .unwrap();
                writeln!(
                    print,
                    "for (int e = 0; e < {}; ++e) print_f32(d{k}[e]);",
                    d.len()
                )
                .unwrap();
            }
        }
    }
    (decl, print)
}

/// The host's view of the same arrays after the CPU launch, in the C++ program's print order.
fn cpu_results(args: &[Arg]) -> Vec<String> {
    let bits = |v: Vec<f32>| {
        v.into_iter()
            .map(|x| format!("{:08x}", x.to_bits()))
            .collect::<Vec<_>>()
    };
    let mut out = Vec::new();
    for a in args {
        match a {
            Arg::F32s(a) => out.extend(bits(a.to_vec().unwrap())),
            Arg::F32Grid(a) => out.extend(bits(a.to_vec().unwrap())),
            Arg::Vec3s(a) => out.extend(bits(
                a.to_vec()
                    .unwrap()
                    .into_iter()
                    .flat_map(|v| v.to_array())
                    .collect(),
            )),
            Arg::I32s(a) => out.extend(a.to_vec().unwrap().into_iter().map(|x| x.to_string())),
            Arg::F32(_) | Arg::Vec3(_) | Arg::HashGrid(_) => {}
        }
    }
    out
}

/// Compiles and runs `K`'s CUDA translation unit on the host over `dims`, with `args`
/// (the state before the launch); returns what it printed, one value per line.
fn run_on_host<K: Kernel>(dims: &[usize], args: &[Arg]) -> Option<Vec<String>> {
    run_info_on_host(&K::INFO, dims, args)
}

/// [`run_on_host`] for a kernel's static facts (an instance of a generic kernel, from
/// `wp::aot::instances`).
fn run_info_on_host(info: &wp::KernelInfo, dims: &[usize], args: &[Arg]) -> Option<Vec<String>> {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED cuda_codegen_host: no g++ on this machine");
        return None;
    }
    let src = wp::cuda_source::assemble(info);
    let (decl, print) = cpp_args(args);
    let mut dims4 = [1usize; 4];
    dims4[..dims.len()].copy_from_slice(dims);
    let total: usize = dims.iter().product();
    let params: Vec<String> = (0..args.len()).map(|k| format!("p{k}")).collect();
    let program = |text: &str| {
        format!(
        "{text}\n\
         static void print_f32(wp::f32 x) {{ unsigned u; memcpy(&u, &x, 4); printf(\"%08x\\n\", u); }}\n\
         static wp::f32 bits_f32(unsigned u) {{ wp::f32 x; memcpy(&x, &u, 4); return x; }}\n\
         template <bool FAST> static int run() {{\n\
         {decl}\n\
         wp::fault_t fault = {{}}; unsigned int flag = 0;\n\
         wp::launch_ctx_t rec = wp::launch_ctx_make(&fault, &flag);\n\
         wp::ctx_t ctx = wp::ctx_make(&rec);\n\
         wp::launch_t launch = {{{{{d0}, {d1}, {d2}, {d3}}}, {total}, {ndim}, FAST ? 1 : 0}};\n\
         for (wp::i64 flat = 0; flat < {total}; ++flat) {thread}({params}, launch, flat, &ctx);\n\
         if (flag) {{ printf(\"fault %d\\n\", fault.kind); return 1; }}\n\
         {print}\n\
         return 0;\n}}\n\
         // Both variants of the thread function, each on fresh data: the unchecked one (what\n\
         // a launch whose arrays cover the grid runs) and the checked one.\n\
         int main() {{ if (run<true>()) return 1; printf(\"--\\n\"); return run<false>(); }}\n",
        d0 = dims4[0],
        d1 = dims4[1],
        d2 = dims4[2],
        d3 = dims4[3],
        ndim = dims.len(),
        thread = src.thread_fn,
        params = params.join(", "),
    )
    };
    let dir = std::env::temp_dir().join(format!(
        "wp_codegen_{}_{}",
        info.name.replace(|c: char| !c.is_ascii_alphanumeric(), "_"),
        std::process::id()
    ));
    std::fs::create_dir_all(&dir).unwrap();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    // Both translation units the runtime may compile: the general one and the variant for
    // launches whose arrays are all contiguous (the arrays here are); and for a kernel with an
    // adjoint, the unit that holds both halves (what a launch under a recording tape
    // compiles), whose forward must run as the forward's own unit does.
    let differentiable = info.adjoint_error.is_none() && info.cuda_adjoint_error.is_none();
    let both = wp::cuda_source::assemble_with_adjoint(info);
    assert_eq!(both.thread_fn, src.thread_fn);
    let mut units = vec![
        (src.text.as_str(), "-DWP_GENERAL_STRIDES"),
        (src.text.as_str(), "-DWP_CONTIGUOUS=1"),
    ];
    if differentiable {
        units.push((both.text.as_str(), "-DWP_CONTIGUOUS=1"));
    }
    let mut outputs = Vec::new();
    for (k, (text, define)) in units.into_iter().enumerate() {
        let cpp = dir.join(format!("k{k}.cpp"));
        std::fs::write(&cpp, format!("#include <cstring>\n{}", program(text))).unwrap();
        let exe = dir.join(format!("k{k}"));
        let out = Command::new("g++")
            .args([
                "-std=c++17",
                "-O1",
                "-ffp-contract=off",
                "-Wno-unused",
                define,
                "-I",
                include,
            ])
            .arg(&cpp)
            .arg("-o")
            .arg(&exe)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "g++ {define} failed on {}:\n{}",
            cpp.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let run = Command::new(&exe).output().unwrap();
        assert!(
            run.status.success(),
            "generated code ({define}) faulted: {}",
            String::from_utf8_lossy(&run.stdout)
        );
        outputs.push(String::from_utf8(run.stdout).unwrap());
    }
    assert_eq!(
        outputs[0], outputs[1],
        "the general and the contiguous-array translation units disagree"
    );
    if let Some(both) = outputs.get(2) {
        assert_eq!(
            *both, outputs[1],
            "the unit of forward and adjoint runs the forward otherwise than the forward's unit"
        );
    }
    let text = outputs.swap_remove(0);
    let (fast, checked) = text.split_once("--\n").expect("two runs");
    assert_eq!(fast, checked, "the unchecked and checked variants disagree");
    Some(fast.lines().map(str::to_string).collect())
}

#[test]
fn particle_kernel_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let x0: Vec<Vec3> = (0..37)
        .map(|k| Vec3::new(k as f32 * 0.1, -0.3, 1.7 - k as f32 * 0.01))
        .collect();
    let v0: Vec<Vec3> = (0..37)
        .map(|k| Vec3::new(0.5, k as f32 * -0.02, 0.25))
        .collect();
    let x = wp::Array::from_slice(&x0, &dev).unwrap();
    let v = wp::Array::from_slice(&v0, &dev).unwrap();
    let gravity = Vec3::new(0.0, 0.0, -9.81);
    let host = {
        let args = [
            Arg::Vec3s(&x),
            Arg::Vec3s(&v),
            Arg::F32(0.05),
            Arg::F32(0.1),
            Arg::Vec3(gravity),
            Arg::F32(0.04),
        ];
        run_on_host::<integrate>(&[37], &args)
    };
    wp::launch(integrate, 37, (&x, &v, 0.05, 0.1, gravity, 0.04), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::Vec3s(&x), Arg::Vec3s(&v)]));
    }
}

#[test]
fn control_flow_funcs_ints_and_atomics_match_the_cpu_backend() {
    let dev = wp::cpu();
    let a = wp::Array::from_slice(
        &(0..25).map(|k| k as f32 * 0.37 - 3.0).collect::<Vec<_>>(),
        &dev,
    )
    .unwrap();
    let b =
        wp::Array::from_slice(&(0..25).map(|k| k * 7 - 40).collect::<Vec<i32>>(), &dev).unwrap();
    let out = wp::Array::<f32>::zeros(25, &dev).unwrap();
    let total = wp::Array::<i32>::zeros(1, &dev).unwrap();
    let host = run_on_host::<mixed>(
        &[25],
        &[
            Arg::F32s(&a),
            Arg::I32s(&b),
            Arg::F32s(&out),
            Arg::I32s(&total),
        ],
    );
    wp::launch(mixed, 25, (&a, &b, &out, &total), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(
            host,
            cpu_results(&[
                Arg::F32s(&a),
                Arg::I32s(&b),
                Arg::F32s(&out),
                Arg::I32s(&total)
            ])
        );
    }
}

#[test]
fn two_dimensional_launch_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let m = wp::Array::<f32, 2>::from_slice_shape(
        &(0..12).map(|k| k as f32 * 0.5).collect::<Vec<_>>(),
        [3, 4],
        &dev,
    )
    .unwrap();
    let host = run_on_host::<grid2d>(&[3, 4], &[Arg::F32Grid(&m), Arg::F32(0.3)]);
    wp::launch(grid2d, (3, 4), (&m, 0.3), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::F32Grid(&m)]));
    }
}

#[test]
fn scalar_math_builtins_match_the_cpu_backend() {
    let dev = wp::cpu();
    let mut xs: Vec<f32> = (0..40).map(|k| k as f32 * 0.37 - 7.0).collect();
    xs.extend([0.5, -2.5, 1.5, 0.0, -0.0, f32::INFINITY, f32::NAN, 8.0]);
    let n = xs.len();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 7), &dev).unwrap();
    let flags = wp::Array::<i32>::zeros(n, &dev).unwrap();
    let host = run_on_host::<scalar_math>(
        &[n],
        &[Arg::F32s(&x), Arg::F32Grid(&out), Arg::I32s(&flags)],
    );
    wp::launch(scalar_math, n, (&x, &out, &flags), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(
            host,
            cpu_results(&[Arg::F32s(&x), Arg::F32Grid(&out), Arg::I32s(&flags)])
        );
    }
}

#[test]
fn f16_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let mut xs: Vec<f32> = (0..40).map(|k| k as f32 * 0.37 - 7.0).collect();
    xs.extend([
        0.5,
        -2.5,
        65504.0,
        1e-7,
        -0.0,
        f32::INFINITY,
        f32::NAN,
        70000.0,
    ]);
    let ds: Vec<f32> = xs.iter().rev().map(|x| x * 0.7 + 0.3).collect();
    let n = xs.len();
    let a = wp::Array::from_slice(&xs, &dev).unwrap();
    let d = wp::Array::from_slice(&ds, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 12), &dev).unwrap();
    let args = [Arg::F32s(&a), Arg::F32s(&d), Arg::F32Grid(&out)];
    let host = run_on_host::<half_precision>(&[n], &args);
    wp::launch(half_precision, n, (&a, &d, &out), &dev).unwrap();
    if let Some(host) = host {
        let cpu = cpu_results(&args);
        assert_eq!(host.len(), cpu.len());
        for (k, (h, c)) in host.iter().zip(&cpu).enumerate() {
            // NaN payloads are each side's arithmetic's; every other result bit for bit.
            let nan = |s: &str| f32::from_bits(u32::from_str_radix(s, 16).unwrap()).is_nan();
            assert!(
                h == c || (nan(h) && nan(c)),
                "element {k}: C++ {h}, CPU {c}"
            );
        }
    }
}

#[test]
fn bf16_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let mut xs: Vec<f32> = (0..40).map(|k| k as f32 * 0.37 - 7.0).collect();
    xs.extend([
        0.5,
        -2.5,
        3.3e38,
        1e-39,
        -0.0,
        f32::INFINITY,
        f32::NAN,
        70000.0,
    ]);
    let ds: Vec<f32> = xs.iter().rev().map(|x| x * 0.7 + 0.3).collect();
    let n = xs.len();
    let a = wp::Array::from_slice(&xs, &dev).unwrap();
    let d = wp::Array::from_slice(&ds, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 12), &dev).unwrap();
    let args = [Arg::F32s(&a), Arg::F32s(&d), Arg::F32Grid(&out)];
    let host = run_on_host::<brain_float>(&[n], &args);
    wp::launch(brain_float, n, (&a, &d, &out), &dev).unwrap();
    if let Some(host) = host {
        let cpu = cpu_results(&args);
        assert_eq!(host.len(), cpu.len());
        for (k, (h, c)) in host.iter().zip(&cpu).enumerate() {
            // bf16 converts in software on both sides, so NaNs match too.
            assert_eq!(h, c, "element {k}: C++ {h}, CPU {c}");
        }
    }
}

#[test]
fn cas_exch_and_bitwise_atomics_match_the_cpu_backend() {
    let dev = wp::cpu();
    let a = wp::Array::<i32>::zeros(25, &dev).unwrap();
    let mut fs: Vec<f32> = (0..25).map(|k| k as f32 * 0.25 - 2.0).collect();
    fs[3] = -0.0;
    fs[8] = 0.0;
    let f = wp::Array::from_slice(&fs, &dev).unwrap();
    let flags = wp::Array::from_slice(&[5, -1, 0, 0x55, -1], &dev).unwrap();
    let args = [Arg::I32s(&a), Arg::F32s(&f), Arg::I32s(&flags)];
    let host = run_on_host::<swaps_and_bits>(&[25], &args);
    wp::launch(swaps_and_bits, 25, (&a, &f, &flags), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
}

#[test]
fn views_match_the_cpu_backend() {
    let dev = wp::cpu();
    let m = wp::Array::<f32, 2>::from_slice_shape(
        &(0..12).map(|k| k as f32 * 0.25 - 1.0).collect::<Vec<_>>(),
        [3, 4],
        &dev,
    )
    .unwrap();
    let x =
        wp::Array::from_slice(&(0..8).map(|k| k as f32 * 1.5).collect::<Vec<_>>(), &dev).unwrap();
    let out = wp::Array::<f32>::zeros(5, &dev).unwrap();
    let args = [Arg::F32Grid(&m), Arg::F32s(&x), Arg::F32s(&out)];
    let host = run_on_host::<views>(&[5], &args);
    wp::launch(views, 5, (&m, &x, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
    // Thread 5 faults on both sides; here on the CPU.
    let out6 = wp::Array::<f32>::zeros(6, &dev).unwrap();
    let e = wp::launch(views, 6, (&m, &x, &out6), &dev)
        .unwrap_err()
        .to_string();
    assert!(e.contains("`x`"), "{e}");
}

#[test]
fn random_numbers_and_noise_match_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 40;
    let x = wp::Array::from_slice(
        &(0..n).map(|k| k as f32 * 0.173 - 2.0).collect::<Vec<_>>(),
        &dev,
    )
    .unwrap();
    let out = wp::Array::<f32, 2>::zeros([n, 5], &dev).unwrap();
    let ints = wp::Array::<i32>::zeros(n, &dev).unwrap();
    let host =
        run_on_host::<rng_draws>(&[n], &[Arg::F32s(&x), Arg::F32Grid(&out), Arg::I32s(&ints)]);
    wp::launch(rng_draws, n, (&x, &out, &ints), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(
            host,
            cpu_results(&[Arg::F32s(&x), Arg::F32Grid(&out), Arg::I32s(&ints)])
        );
    }
}

#[test]
fn transforms_match_the_cpu_backend() {
    let dev = wp::cpu();
    let mut xs: Vec<f32> = (0..30).map(|k| k as f32 * 0.29 - 4.0).collect();
    xs.extend([0.0, -0.0, 1.0, 3.0]);
    let n = xs.len();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 8), &dev).unwrap();
    let host = run_on_host::<transforms>(&[n], &[Arg::F32s(&x), Arg::F32Grid(&out)]);
    wp::launch(transforms, n, (&x, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::F32s(&x), Arg::F32Grid(&out)]));
    }
}

#[test]
fn spatial_types_match_the_cpu_backend() {
    let dev = wp::cpu();
    let mut xs: Vec<f32> = (0..30).map(|k| k as f32 * 0.29 - 4.0).collect();
    xs.extend([0.0, -0.0, 1.0, 3.0]);
    let n = xs.len();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 8), &dev).unwrap();
    let host = run_on_host::<spatial>(&[n], &[Arg::F32s(&x), Arg::F32Grid(&out)]);
    wp::launch(spatial, n, (&x, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::F32s(&x), Arg::F32Grid(&out)]));
    }
}

/// The non-square matrices' generated CUDA against the CPU backend, bit for bit.
#[test]
fn nonsquare_matrices_match_the_cpu_backend() {
    let dev = wp::cpu();
    let mut xs: Vec<f32> = (0..24).map(|k| k as f32 * 0.31 - 3.5).collect();
    xs.extend([0.0, -0.0, 1.0]);
    let n = xs.len();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 8), &dev).unwrap();
    let host = run_on_host::<nonsquare>(&[n], &[Arg::F32s(&x), Arg::F32Grid(&out)]);
    wp::launch(nonsquare, n, (&x, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::F32s(&x), Arg::F32Grid(&out)]));
    }
}

/// Lanes at run-time indices (`lanes`): the generated CUDA's `local_get`/`local_set`/
/// `col_get`/`col_set` against the CPU's `Lanes` and `Columns`, bit for bit.
#[test]
fn lanes_match_the_cpu_backend() {
    let dev = wp::cpu();
    let mut xs: Vec<f32> = (0..20).map(|k| k as f32 * 0.37 - 3.0).collect();
    xs.extend([0.0, -0.0, 1.0]);
    let n = xs.len();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 8), &dev).unwrap();
    let host = run_on_host::<lanes>(&[n], &[Arg::F32s(&x), Arg::F32Grid(&out)]);
    wp::launch(lanes, n, (&x, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::F32s(&x), Arg::F32Grid(&out)]));
    }
}

#[test]
fn decompositions_match_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 12;
    let mut xs: Vec<f32> = (0..n * 9)
        .map(|k| ((k * 37 % 23) as f32 - 11.0) * 0.173)
        .collect();
    xs[9..18].copy_from_slice(&[3.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 1.0]);
    xs[18..27].fill(0.0);
    xs[31] = f32::NAN;
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 10), &dev).unwrap();
    let host = run_on_host::<decompositions>(&[n], &[Arg::F32s(&x), Arg::F32Grid(&out)]);
    wp::launch(decompositions, n, (&x, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::F32s(&x), Arg::F32Grid(&out)]));
    }
}

#[test]
fn refs_and_tuples_match_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 5;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.75 - 1.5).collect();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let acc = wp::Array::from_slice(&vec![0.25f32; n], &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 3), &dev).unwrap();
    let args = [Arg::F32s(&x), Arg::F32s(&acc), Arg::F32Grid(&out)];
    let host = run_on_host::<refs_and_tuples>(&[n], &args);
    wp::launch(refs_and_tuples, n, (&x, &acc, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
}

#[test]
fn overloads_and_generic_funcs_by_arguments_match_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 6;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.7 - 1.9).collect();
    let ns: Vec<i32> = (0..n as i32).map(|k| 3 - k).collect();
    let vs: Vec<Vec3> = (0..n)
        .map(|k| Vec3::new(k as f32 * 0.3, 1.1, -0.2 * k as f32))
        .collect();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let ni = wp::Array::from_slice(&ns, &dev).unwrap();
    let v = wp::Array::from_slice(&vs, &dev).unwrap();
    let out = wp::Array::<f32>::zeros(n, &dev).unwrap();
    let args = [
        Arg::F32s(&x),
        Arg::I32s(&ni),
        Arg::Vec3s(&v),
        Arg::F32s(&out),
    ];
    let host = run_on_host::<overloaded>(&[n], &args);
    wp::launch(overloaded, n, (&x, &ni, &v, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
    // The unit that holds the adjoint (the custom gradients' calls) compiled above; the
    // callees are the resolved overloads and instance (`blend(cubic(..), n)` names
    // `blend(f32, i32)` by another path, `RetOf<cubic>`: the same func, listed once here and
    // assembled once by the runtime).
    let mut names: Vec<&str> = Vec::new();
    for c in overloaded::INFO.callees {
        if !names.contains(&c.name) {
            names.push(c.name);
        }
    }
    assert_eq!(
        names,
        [
            "blend(f32, f32)",
            "blend(f32, i32)",
            "cubic<f32>",
            "blend(Vec3, f32)"
        ]
    );
}

#[test]
fn module_constants_match_the_cpu_backend() {
    let dev = wp::cpu();
    let x = wp::Array::from_slice(&[1.0f32, -0.3, 7.5, 1e-3], &dev).unwrap();
    let v = wp::Array::from_slice(
        &[Vec3::ONE, Vec3::new(0.1, 0.2, 0.3), Vec3::ZERO, -Vec3::ONE],
        &dev,
    )
    .unwrap();
    let n = wp::Array::<i32>::zeros(4, &dev).unwrap();
    let args = [Arg::F32s(&x), Arg::Vec3s(&v), Arg::I32s(&n)];
    let host = run_on_host::<consts>(&[4], &args);
    wp::launch(consts, 4, (&x, &v, &n), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
    // The values are spelt as bit patterns, not rounded decimals.
    let src = wp::cuda_source::assemble(&<consts as wp::Kernel>::INFO).text;
    assert!(
        src.contains(&format!("0x{:016x}", THIRD.to_bits())),
        "{src}"
    );
}

#[test]
fn misc_builtins_match_the_cpu_backend() {
    let dev = wp::cpu();
    let mut xs: Vec<f32> = (0..30).map(|k| k as f32 * 0.137 - 1.9).collect();
    // No NaN input: NaN payload signs depend on operand order (tests/cuda_host_cpp.rs covers NaN).
    xs.extend([0.0, -0.0, 1.0, 2.5]);
    let n = xs.len();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let cdf = wp::Array::from_slice(&[0.1f32, 0.35, 0.35, 0.6, 0.9, 1.0], &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 7), &dev).unwrap();
    let ints = wp::Array::<i32>::zeros(n * 3, &dev).unwrap();
    let args = [
        Arg::F32s(&x),
        Arg::F32s(&cdf),
        Arg::F32Grid(&out),
        Arg::I32s(&ints),
    ];
    let host = run_on_host::<misc_builtins>(&[n], &args);
    wp::launch(misc_builtins, n, (&x, &cdf, &out, &ints), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
}

/// The points of the hash grid tests: a cloud reaching outside the grid's nominal extent
/// (negative too), with duplicates.
fn grid_points() -> Vec<Vec3> {
    let mut pts: Vec<Vec3> = (0..90)
        .map(|k| {
            let f = k as f32;
            Vec3::new(
                (f * 0.61).sin() * 2.5,
                (f * 0.23).cos() * 1.7 - 0.4,
                f * 0.031 - 1.3,
            )
        })
        .collect();
    pts.push(pts[4]);
    pts.push(Vec3::new(-40.0, 17.5, 3.25));
    pts
}

#[test]
fn hash_grid_queries_match_the_cpu_backend() {
    let dev = wp::cpu();
    let pts = grid_points();
    let n = pts.len();
    let x = wp::Array::from_slice(&pts, &dev).unwrap();
    let mut grid = wp::HashGrid::new(4, 3, 5, &dev).unwrap();
    grid.build(&x, 0.4).unwrap();
    let out = wp::Array::<f32>::zeros(n, &dev).unwrap();
    let ints = wp::Array::<i32>::zeros(3 * n, &dev).unwrap();
    let args = [
        Arg::HashGrid(&grid),
        Arg::Vec3s(&x),
        Arg::F32(0.9),
        Arg::F32s(&out),
        Arg::I32s(&ints),
    ];
    let host = run_on_host::<hash_grid_queries>(&[n], &args);
    wp::launch(hash_grid_queries, n, (&grid, &x, 0.9, &out, &ints), &dev).unwrap();
    // Some points have neighbours, some more than the `break` allows.
    let c: Vec<i32> = ints.to_vec().unwrap().iter().step_by(3).copied().collect();
    assert!(c.contains(&0) && c.iter().any(|c| *c > 5), "{c:?}");
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
}

/// The device build's per-thread steps (`wp::hash_grid_build_key`, a stable sort of the pairs
/// as the primitives' radix sort will do, `wp::hash_grid_build_range`) give the CPU build's
/// buffers, and flag a non-finite point.
#[test]
fn hash_grid_device_build_steps_match_the_cpu_build() {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED hash_grid_device_build_steps_match_the_cpu_build: no g++");
        return;
    }
    let dev = wp::cpu();
    let pts = grid_points();
    let mut grid = wp::HashGrid::new(4, 3, 5, &dev).unwrap();
    grid.build(&wp::Array::from_slice(&pts, &dev).unwrap(), 0.4)
        .unwrap();
    let inv = 1.0 / 0.4f32;
    let items: Vec<String> = pts
        .iter()
        .map(|p| {
            let b = |x: f32| format!("bits_f32({})", f32_bits(x));
            format!("wp::Vec3_new({}, {}, {})", b(p.x), b(p.y), b(p.z))
        })
        .collect();
    let n = pts.len();
    let program = format!(
        "#include <cstring>\n#include <algorithm>\n#include <vector>\n#include \"wp_hash_grid.h\"\n\
         static wp::f32 bits_f32(unsigned u) {{ wp::f32 x; memcpy(&x, &u, 4); return x; }}\n\
         int main() {{\n\
           const wp::i32 dims[3] = {{4, 3, 5}};\n\
           const wp::f32 inv = bits_f32({inv});\n\
           wp::Vec3 pts[] = {{{items}}};\n\
           std::vector<std::pair<wp::i32, wp::i32>> kv({n});\n\
           for (int i = 0; i < {n}; ++i) if (!wp::hash_grid_build_key(dims, inv, pts[i], i, &kv[i].first, &kv[i].second)) return 1;\n\
           std::stable_sort(kv.begin(), kv.end(), [](auto a, auto b) {{ return a.first < b.first; }});\n\
           std::vector<wp::i32> keys({n}), starts(60, 0), ends(60, 0);\n\
           for (int k = 0; k < {n}; ++k) keys[k] = kv[k].first;\n\
           for (int k = 0; k < {n}; ++k) wp::hash_grid_build_range(keys.data(), {n}, k, starts.data(), ends.data(), 60, false);\n\
           for (auto& p : kv) printf(\"%d\\n\", p.second);\n\
           for (int c = 0; c < 60; ++c) printf(\"%d %d\\n\", starts[c], ends[c]);\n\
           wp::i32 key, value;\n\
           const bool nan_ok = wp::hash_grid_build_key(dims, inv, wp::Vec3_new(0.0f, bits_f32(0x7fc00000u), 1.0f), 0, &key, &value);\n\
           const bool inf_ok = wp::hash_grid_build_key(dims, inv, wp::Vec3_new(bits_f32(0xff800000u), 0.0f, 1.0f), 0, &key, &value);\n\
           printf(\"%d %d\\n\", (int)nan_ok, (int)inf_ok);\n\
           return 0;\n\
         }}\n",
        inv = f32_bits(inv),
        items = items.join(", "),
    );
    let dir = std::env::temp_dir().join(format!("wp_hash_grid_build_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (cpp, exe) = (dir.join("b.cpp"), dir.join("b"));
    std::fs::write(&cpp, program).unwrap();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let out = Command::new("g++")
        .args([
            "-std=c++17",
            "-O1",
            "-ffp-contract=off",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-I",
            include,
        ])
        .arg(&cpp)
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "g++: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(&exe).output().unwrap();
    assert!(run.status.success(), "a finite point was flagged");
    let text = String::from_utf8(run.stdout).unwrap();
    let mut lines = text.lines();
    let ids: Vec<i32> = lines.by_ref().take(n).map(|l| l.parse().unwrap()).collect();
    assert_eq!(ids, grid.point_ids().unwrap().to_vec().unwrap());
    let (s, e) = grid.cell_ranges().unwrap();
    let want: Vec<String> = s
        .to_vec()
        .unwrap()
        .iter()
        .zip(e.to_vec().unwrap())
        .map(|(s, e)| format!("{s} {e}"))
        .collect();
    let got: Vec<String> = lines.by_ref().take(60).map(str::to_string).collect();
    assert_eq!(got, want);
    assert_eq!(
        lines.next(),
        Some("0 0"),
        "NaN and infinite points are flagged"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Forward mode: a kernel whose tangent kernel uses the scalar and vector rules.
#[wp::kernel]
fn tangent_rules(x: Array<f32>, v: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    let t = x[i];
    let a = v[i];
    let b = Vec3::new(t, t * t, 1.0);
    let c = a.cross(b).normalize() * a.length();
    let s = t.sin() * t.exp() + (t * t + 1.0).sqrt() / (2.0 + t.cos()) + t.atan2(1.5);
    let m = t.max(0.2).min(0.8) + t.clamp(-0.5, 0.5) + t.abs() + t.tanh();
    out[i] = s + m + c.dot(a) + (t * t + 0.5).ln() + (t * t + 0.1).powf(1.3);
    v[i] = c + a * t;
}

#[test]
fn tangent_kernel_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 20;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.13 - 1.21).collect();
    let vs: Vec<Vec3> = (0..n)
        .map(|k| Vec3::new(0.5 + k as f32 * 0.1, -0.3, 1.0 - k as f32 * 0.05))
        .collect();
    let x_dots: Vec<f32> = (0..n).map(|k| 1.0 - k as f32 * 0.07).collect();
    let v_dots: Vec<Vec3> = (0..n)
        .map(|k| Vec3::new(0.2, k as f32 * 0.03, -0.5))
        .collect();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let v = wp::Array::from_slice(&vs, &dev).unwrap();
    let out = wp::Array::<f32>::zeros(n, &dev).unwrap();
    let x_dot = wp::Array::from_slice(&x_dots, &dev).unwrap();
    let v_dot = wp::Array::from_slice(&v_dots, &dev).unwrap();
    let out_dot = wp::Array::<f32>::zeros(n, &dev).unwrap();
    let args = [
        Arg::F32s(&x),
        Arg::Vec3s(&v),
        Arg::F32s(&out),
        Arg::F32s(&x_dot),
        Arg::Vec3s(&v_dot),
        Arg::F32s(&out_dot),
    ];
    type Tangent = <tangent_rules as wp::Forward>::Tangent;
    let host = run_on_host::<Tangent>(&[n], &args);
    wp::jvp(
        tangent_rules,
        n,
        (&x, &v, &out),
        (&x_dot, &v_dot, &out_dot),
        &dev,
    )
    .unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
        // The tangent kernel's adjoint (reverse over forward, `wp::hvp`) is valid C++ too.
        let src = wp::cuda_source::assemble_adjoint(&<Tangent as Kernel>::INFO);
        let dir =
            std::env::temp_dir().join(format!("wp_codegen_tangent_adj_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let cpp = dir.join("adj.cpp");
        std::fs::write(&cpp, format!("#include <cstring>\n{}", src.text)).unwrap();
        let out = Command::new("g++")
            .args([
                "-std=c++17",
                "-fsyntax-only",
                "-Wno-unused",
                "-DWP_GENERAL_STRIDES",
                "-I",
            ])
            .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda"))
            .arg(&cpp)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "g++ failed on the tangent's adjoint {}:\n{}",
            cpp.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

// ------------------------------------------------------------------------------------------
// Tiled kernels: one block at a time under the block emulator
// ------------------------------------------------------------------------------------------

#[wp::func]
fn tile_cubic(x: f32) -> f32 {
    x * x * x - 2.0 * x
}

#[wp::func]
fn tile_blend(a: f32, b: f32) -> f32 {
    if a > b {
        return a - 0.5 * b;
    }
    a * b + tile_cubic(b)
}

#[wp::func]
fn tile_bucket(x: f32) -> i32 {
    (x * 2.0) as i32 + 1
}

#[wp::kernel]
fn tile_funcs(x: Array<f32>, y: Array<f32>, out: Array<f32>, out2: Array<f32>, k: Array<i32>) {
    let o = (tid() * 16) as i32;
    let t = tile_load::<16>(x, o);
    let u = tile_load::<16>(y, o);
    tile_store(out, tile_map(tile_cubic, t), o);
    let b = tile_map(tile_blend, t, u);
    tile_store(out2, b + t, o);
    let kk: Tile<i32, 16> = tile_map(tile_bucket, b);
    tile_store(k, kk * 3, o);
    tile_store(out, tile_map(tile_weighted, t, u, b), o + 48);
}

#[wp::func]
fn tile_weighted(a: f32, b: f32, c: f32) -> f32 {
    0.5 * a + 0.25 * b - c * tile_cubic(a)
}

/// The C++ compiler's flags for a tiled kernel's translation unit under the block emulator
/// (`warp-cuda/cuda/tests/wp_prim_emu.h`): dynamic shared memory (`extern __shared__`) is a
/// global buffer the program defines.
fn emu_flags(bd: usize) -> Vec<String> {
    [
        "-std=c++17",
        "-O1",
        "-ffp-contract=off",
        "-Wno-unused",
        "-D__shared__=",
        "-D__align__(n)=__attribute__((aligned(n)))",
        "-DWP_GENERAL_STRIDES",
    ]
    .iter()
    .map(|s| s.to_string())
    .chain([
        format!("-DWP_TILE_BLOCK_DIM={bd}"),
        "-include".into(),
        concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/warp-cuda/cuda/tests/wp_prim_emu.h"
        )
        .into(),
        "-I".into(),
        concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda").into(),
    ])
    .collect()
}

/// Compiles `K`'s CUDA translation unit (a tiled kernel) on the host and runs `blocks` blocks
/// of `bd` threads under the block emulator, each thread calling the kernel's thread function
/// with its block's index, as the entry does; returns what it printed, one value per line.
///
/// With `adjoint`, the kernel's adjoint instead (`args`: the parameters, then the arrays'
/// adjoints), each thread on a stack of its own.
fn run_tiled_on_host<K: Kernel>(
    blocks: usize,
    bd: usize,
    args: &[Arg],
    adjoint: bool,
) -> Option<Vec<String>> {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED cuda_codegen_host (tiled): no g++ on this machine");
        return None;
    }
    let (src, thread, stack) = if adjoint {
        let src = wp::cuda_source::assemble_adjoint(&K::INFO);
        let t = src.thread_fn.clone();
        (src, t, ", &st")
    } else {
        let src = wp::cuda_source::assemble(&K::INFO);
        let t = src.thread_fn.clone();
        (src, t, "")
    };
    let (decl, print) = cpp_args(args);
    let params: Vec<String> = (0..args.len()).map(|k| format!("p{k}")).collect();
    let program = format!(
        "#include <cstring>\n#include <functional>\n\
         alignas(16) unsigned char __smem[1 << 16];\n\
         {text}\n\
         static void print_f32(wp::f32 x) {{ unsigned u; memcpy(&u, &x, 4); printf(\"%08x\\n\", u); }}\n\
         static wp::f32 bits_f32(unsigned u) {{ wp::f32 x; memcpy(&x, &u, 4); return x; }}\n\
         static void block(std::function<void()>* body) {{ (*body)(); }}\n\
         int main() {{\n\
         {decl}\n\
         wp::fault_t fault = {{}}; unsigned int flag = 0;\n\
         wp::launch_ctx_t rec = wp::launch_ctx_make(&fault, &flag);\n\
         wp::ctx_t ctx = wp::ctx_make(&rec);\n\
         wp::launch_t launch = {{{{{blocks}, 1, 1, 1}}, {blocks}, 1, 0}};\n\
         std::function<void()> body = [&] {{\n\
           {stack_decl}\n\
           {thread}({params}, launch, (wp::i64)wp_emu::bid, &ctx{stack}); }};\n\
         wp_emu::launch(block, {blocks}, {bd}, &body);\n\
         if (flag) {{ printf(\"fault %d\\n\", fault.kind); return 1; }}\n\
         {print}\n\
         return 0;\n}}\n",
        text = src.text,
        stack_decl = if adjoint {
            "char buf[4096]; wp::adstack_t st = wp::adstack_new(buf, 4096);"
        } else {
            ""
        },
        params = params.join(", "),
    );
    let dir = std::env::temp_dir().join(format!(
        "wp_codegen_tiled_{}{}_{bd}_{}",
        if adjoint { "adj_" } else { "" },
        K::INFO.name,
        std::process::id()
    ));
    Some(build_and_run(
        &dir,
        &program,
        &emu_flags(bd),
        "generated tiled code",
    ))
}

/// Writes `program` into `dir`, compiles it with g++ and `flags`, runs it, and returns what
/// it printed, one value per line; a compile error or a failed run (`what` faulted) panics
/// with the messages.
fn build_and_run(
    dir: &std::path::Path,
    program: &str,
    flags: &[String],
    what: &str,
) -> Vec<String> {
    std::fs::create_dir_all(dir).unwrap();
    let (cpp, exe) = (dir.join("k.cpp"), dir.join("k"));
    std::fs::write(&cpp, program).unwrap();
    let out = Command::new("g++")
        .args(flags)
        .arg(&cpp)
        .arg("-o")
        .arg(&exe)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "g++ failed on {}:\n{}",
        cpp.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    let run = Command::new(&exe).output().unwrap();
    assert!(
        run.status.success(),
        "{what} faulted: {}{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    String::from_utf8(run.stdout)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

/// `tile_map` of user funcs (unary, binary calling another func, one returning `i32`, and
/// one of three tiles) in
/// the generated CUDA, run on the host under the block emulator at block sizes 1, 7 and 32
/// over 37 elements (ragged against 16): the CPU backend's bits exactly (`+ - *`, `as`).
#[test]
fn tile_map_of_funcs_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 37;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.25 - 4.0).collect();
    let ys: Vec<f32> = (0..n).map(|k| 3.0 - k as f32 * 0.125).collect();
    for bd in [1, 7, 32] {
        let x = wp::Array::from_slice(&xs, &dev).unwrap();
        let y = wp::Array::from_slice(&ys, &dev).unwrap();
        let out = wp::Array::<f32>::zeros(n + 48, &dev).unwrap();
        let out2 = wp::Array::<f32>::zeros(n, &dev).unwrap();
        let k = wp::Array::<i32>::zeros(n, &dev).unwrap();
        let args = [
            Arg::F32s(&x),
            Arg::F32s(&y),
            Arg::F32s(&out),
            Arg::F32s(&out2),
            Arg::I32s(&k),
        ];
        let Some(host) = run_tiled_on_host::<tile_funcs>(3, bd, &args, false) else {
            return;
        };
        wp::launch_tiled(tile_funcs, 3, (&x, &y, &out, &out2, &k), bd, &dev).unwrap();
        assert_eq!(host, cpu_results(&args), "block_dim {bd}");
    }
}

/// The adjoint translation unit of a kernel mapping funcs (functors calling the funcs'
/// adjoints with the fault context and the thread's stack) compiles as host C++ under the
/// emulator; NVRTC compiles it on a GPU (the suite's `tile_funcs` backward tests there).
#[test]
fn tile_map_of_funcs_adjoint_compiles() {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED cuda_codegen_host (tiled adjoint): no g++ on this machine");
        return;
    }
    let info = &<tile_funcs as Kernel>::INFO;
    assert!(
        info.cuda_adjoint_error.is_none(),
        "{:?}",
        info.cuda_adjoint_error
    );
    let src = wp::cuda_source::assemble_adjoint(info);
    assert!(src.text.contains("wp::adj_tile_map2("), "{}", src.text);
    let dir = std::env::temp_dir().join(format!("wp_codegen_tiled_adj_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cpp = dir.join("adj.cpp");
    std::fs::write(
        &cpp,
        format!(
            "#include <cstring>\nalignas(16) unsigned char __smem[1 << 16];\n{}",
            src.text
        ),
    )
    .unwrap();
    let out = Command::new("g++")
        .args(emu_flags(32))
        .arg("-fsyntax-only")
        .arg(&cpp)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "g++ failed on {}:\n{}",
        cpp.display(),
        String::from_utf8_lossy(&out.stderr)
    );
}

#[wp::kernel]
fn tile_func_grads(x: Array<f32>, y: Array<f32>, out: Array<f32>) {
    let o = (tid() * 16) as i32;
    let t = tile_load::<16>(x, o);
    let u = tile_load::<16>(y, o);
    let c = tile_map(tile_cubic, t);
    let w = tile_map(tile_weighted, t, u, c);
    tile_store(
        out,
        tile_map(tile_blend, c, u) + tile_map(tile_blend, t, t) + w,
        o,
    );
}

/// Backward through `tile_map` of funcs (one calling another; the same tile twice; three
/// tiles) in the
/// generated CUDA adjoint, run on the host under the block emulator at block sizes 1, 7 and
/// 32: the CPU backend's gradients bit for bit (`+ - *` only, the same per-element adjoint
/// chain on both).
#[test]
fn tile_map_of_funcs_gradients_match_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 37;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.25 - 4.0).collect();
    let ys: Vec<f32> = (0..n).map(|k| 3.0 - k as f32 * 0.125).collect();
    for bd in [1, 7, 32] {
        let x = wp::Array::from_slice(&xs, &dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let y = wp::Array::from_slice(&ys, &dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let out = wp::Array::<f32>::zeros(n, &dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch_tiled(tile_func_grads, 3, (&x, &y, &out), bd, &dev).unwrap();
        }
        // The host run's inputs: the values after the forward, zero input gradients, a seed
        // of ones.
        let gx = wp::Array::<f32>::zeros(n, &dev).unwrap();
        let gy = wp::Array::<f32>::zeros(n, &dev).unwrap();
        let gout = wp::Array::<f32>::full(n, 1.0, &dev).unwrap();
        let args = [
            Arg::F32s(&x),
            Arg::F32s(&y),
            Arg::F32s(&out),
            Arg::F32s(&gx),
            Arg::F32s(&gy),
            Arg::F32s(&gout),
        ];
        let Some(host) = run_tiled_on_host::<tile_func_grads>(3, bd, &args, true) else {
            return;
        };
        out.grad().unwrap().fill(1.0).unwrap();
        tape.backward_from_grads().unwrap();
        let bits = |a: &wp::Array<f32>| -> Vec<String> {
            a.to_vec()
                .unwrap()
                .iter()
                .map(|v| format!("{:08x}", v.to_bits()))
                .collect()
        };
        let (hx, hy) = (&host[3 * n..4 * n], &host[4 * n..5 * n]);
        assert_eq!(hx, &bits(&x.grad().unwrap())[..], "x, block_dim {bd}");
        assert_eq!(hy, &bits(&y.grad().unwrap())[..], "y, block_dim {bd}");
        assert!(hx.iter().any(|b| b != "00000000"), "no gradient reached x");
    }
}

#[wp::func]
fn tile_halve_add(a: f32, b: f32) -> f32 {
    0.5 * a + b
}

#[wp::func]
fn tile_mix_int(a: i32, b: i32) -> i32 {
    (a * 7 + b) % 10007
}

#[wp::kernel]
fn tile_reduce_funcs(x: Array<f32>, xi: Array<i32>, out: Array<f32>, outi: Array<i32>) {
    let b = tid();
    let o = (b * 37) as i32;
    let t = tile_load::<37>(x, o);
    tile_store(out, tile_reduce(tile_halve_add, t), b as i32);
    let ti = tile_load::<37>(xi, o);
    tile_store(outi, tile_reduce(tile_mix_int, ti), b as i32);
}

/// `tile_reduce` of user funcs (order-dependent: neither associative nor commutative) in the
/// generated CUDA, run on the host under the block emulator at block sizes 1, 7 and 32 over
/// two blocks of 37: the CPU backend's bits exactly (the same order of combination).
#[test]
fn tile_reduce_of_funcs_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 74;
    let xs: Vec<f32> = (0..n).map(|k| (k as f32 * 0.37).sin() * 3.0).collect();
    let xis: Vec<i32> = (0..n).map(|k| (k * 131 + 17) % 1000).collect();
    for bd in [1, 7, 32] {
        let x = wp::Array::from_slice(&xs, &dev).unwrap();
        let xi = wp::Array::from_slice(&xis, &dev).unwrap();
        let out = wp::Array::<f32>::zeros(2, &dev).unwrap();
        let outi = wp::Array::<i32>::zeros(2, &dev).unwrap();
        let args = [
            Arg::F32s(&x),
            Arg::I32s(&xi),
            Arg::F32s(&out),
            Arg::I32s(&outi),
        ];
        let Some(host) = run_tiled_on_host::<tile_reduce_funcs>(2, bd, &args, false) else {
            return;
        };
        wp::launch_tiled(tile_reduce_funcs, 2, (&x, &xi, &out, &outi), bd, &dev).unwrap();
        assert_eq!(host, cpu_results(&args), "block_dim {bd}");
    }
}

#[wp::func]
fn tile_lerp_by(a: f32, b: f32, w: f32) -> f32 {
    a + (b - a) * w
}

#[wp::func]
fn tile_two_consts(a: f32, s: f32, c: f32, k: i32) -> f32 {
    a * s - c * (k as f32) * a * a
}

#[wp::kernel]
fn tile_map_consts(x: Array<f32>, y: Array<f32>, s: f32, out: Array<f32>, k: Array<i32>) {
    let o = (tid() * 16) as i32;
    let t = tile_load::<16>(x, o);
    let u = tile_load::<16>(y, o);
    tile_store(out, tile_map(tile_cubic, t) + tile_map(mul, t, s), o);
    tile_store(
        out,
        tile_map(tile_lerp_by, t, u, s) - tile_map(max, u, 0.25),
        o + 48,
    );
    tile_store(out, tile_map(tile_two_consts, t, s, 1.5, 2i32), o + 96);
    let ki: Tile<i32, 16> = tile_map(tile_bucket, t);
    tile_store(k, tile_map(sub, ki, 4), o);
}

/// `tile_map` with scalar constants (a kernel parameter, literals; operators, builtins and
/// funcs) in the generated CUDA, run on the host under the block emulator at block sizes 1,
/// 7 and 32 over 37 elements (ragged against 16): the CPU backend's bits exactly.
#[test]
fn tile_map_with_constants_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 37;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.25 - 4.0).collect();
    let ys: Vec<f32> = (0..n).map(|k| 3.0 - k as f32 * 0.125).collect();
    for bd in [1, 7, 32] {
        let x = wp::Array::from_slice(&xs, &dev).unwrap();
        let y = wp::Array::from_slice(&ys, &dev).unwrap();
        let out = wp::Array::<f32>::zeros(n + 96, &dev).unwrap();
        let k = wp::Array::<i32>::zeros(n, &dev).unwrap();
        let s = -0.75f32;
        let args = [
            Arg::F32s(&x),
            Arg::F32s(&y),
            Arg::F32(s),
            Arg::F32s(&out),
            Arg::I32s(&k),
        ];
        let Some(host) = run_tiled_on_host::<tile_map_consts>(3, bd, &args, false) else {
            return;
        };
        wp::launch_tiled(tile_map_consts, 3, (&x, &y, s, &out, &k), bd, &dev).unwrap();
        assert_eq!(host, cpu_results(&args), "block_dim {bd}");
    }
}

#[wp::kernel]
fn tile_const_grads(x: Array<f32>, w: Array<f32>, out: Array<f32>) {
    let o = (tid() * 16) as i32;
    let s = w[0] * 2.0;
    let c = w[1];
    let t = tile_load::<16>(x, o);
    let m = tile_map(tile_two_consts, t, s, c, 3i32) + tile_map(mul, t, c);
    tile_store(out, m + tile_map(tile_lerp_by, t, t, s), o);
}

/// Backward through `tile_map` with scalar constants (a func with two float constants and an
/// integer one, an operator, the same tile twice) in the generated CUDA adjoint, run on the
/// host under the block emulator at block sizes 1, 7 and 32: the CPU backend's gradients bit
/// for bit, the constants' (through `w`) included: each element's contribution is the same
/// scalar adjoint on both, summed in the reductions' order on both.
#[test]
fn tile_map_constant_gradients_match_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 37;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.25 - 4.0).collect();
    for bd in [1, 7, 32] {
        let x = wp::Array::from_slice(&xs, &dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let w = wp::Array::from_slice(&[0.375f32, -1.25], &dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let out = wp::Array::<f32>::zeros(n, &dev)
            .unwrap()
            .with_grad()
            .unwrap();
        let tape = wp::Tape::new();
        {
            let _rec = tape.record();
            wp::launch_tiled(tile_const_grads, 3, (&x, &w, &out), bd, &dev).unwrap();
        }
        let gx = wp::Array::<f32>::zeros(n, &dev).unwrap();
        let gw = wp::Array::<f32>::zeros(2, &dev).unwrap();
        let gout = wp::Array::<f32>::full(n, 1.0, &dev).unwrap();
        let args = [
            Arg::F32s(&x),
            Arg::F32s(&w),
            Arg::F32s(&out),
            Arg::F32s(&gx),
            Arg::F32s(&gw),
            Arg::F32s(&gout),
        ];
        let Some(host) = run_tiled_on_host::<tile_const_grads>(3, bd, &args, true) else {
            return;
        };
        out.grad().unwrap().fill(1.0).unwrap();
        tape.backward_from_grads().unwrap();
        let bits = |a: &wp::Array<f32>| -> Vec<String> {
            a.to_vec()
                .unwrap()
                .iter()
                .map(|v| format!("{:08x}", v.to_bits()))
                .collect()
        };
        let at = 2 * n + 2;
        let (hx, hw) = (&host[at..at + n], &host[at + n..at + n + 2]);
        assert_eq!(hx, &bits(&x.grad().unwrap())[..], "x, block_dim {bd}");
        assert_eq!(hw, &bits(&w.grad().unwrap())[..], "w, block_dim {bd}");
        assert!(hw.iter().all(|b| b != "00000000"), "no gradient reached w");
    }
}

#[wp::func]
fn halve_checked(x: f32) -> f32 {
    assert!(x < 100.0, "too big");
    x * 0.5
}

/// Every kind of assertion: one always checked, one in debug mode only, the three
/// expectations, and one in a func.
#[wp::kernel]
fn asserting(x: Array<f32>, v: Array<Vec3>, out: Array<f32>) {
    let i = tid();
    assert!(x[i] >= 0.0);
    debug_assert!(x[i] < 50.0, "debug only");
    expect_near(v[i], vec3(1.0, 2.0, 3.0), 0.5);
    expect_eq(x[i] * 0.0, 0.0);
    expect_neq(x[i], 7.0);
    out[i] = halve_checked(x[i]);
}

/// The generated CUDA's assertions run on the host (g++) with the debug flag off and on
/// (`wp::CTX_DEBUG` in the context), against the CPU backend: the same first fault (the host
/// runs the threads in order, as a small CPU launch does), whose record's line, column and
/// thread lead to the CPU's message through the kernel's and its func's `asserts` tables.
#[test]
fn assertions_fault_as_on_the_cpu_backend() {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED cuda_codegen_host (assertions): no g++ on this machine");
        return;
    }
    let dev = wp::cpu();
    let n = 4;
    let good_v = [Vec3::new(1.0, 2.0, 3.0); 4];
    let mut near_v = good_v;
    near_v[1] = Vec3::new(1.0, 2.5, 2.5);
    let mut far_v = good_v;
    far_v[1] = Vec3::new(1.0, 2.0, 3.75);
    // (x, v, debug): what passes, what fails each assertion.
    let cases: [([f32; 4], [Vec3; 4], bool); 8] = [
        ([0.0, 1.0, 2.0, 3.0], good_v, true),
        ([0.0, 1.0, 2.0, 3.0], near_v, true),
        ([0.0, 1.0, -2.0, 3.0], good_v, false),
        ([0.0, 1.0, 60.0, 3.0], good_v, false),
        ([0.0, 1.0, 60.0, 3.0], good_v, true),
        ([0.0, 1.0, 2.0, 3.0], far_v, false),
        ([0.0, 7.0, f32::NAN, 3.0], good_v, false),
        ([0.0, 1.0, 2.0, 200.0], good_v, false),
    ];
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let src = wp::cuda_source::assemble(&asserting::INFO);
    let dir = std::env::temp_dir().join(format!("wp_codegen_asserts_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let was = wp::config::debug();
    let mut faulted = 0;
    for (k, (xs, vs, debug)) in cases.into_iter().enumerate() {
        let x = wp::Array::from_slice(&xs, &dev).unwrap();
        let v = wp::Array::from_slice(&vs, &dev).unwrap();
        let out = wp::Array::<f32>::zeros(n, &dev).unwrap();
        let args = [Arg::F32s(&x), Arg::Vec3s(&v), Arg::F32s(&out)];
        let (decl, _) = cpp_args(&args);
        let program = format!(
            "#include <cstring>\n{text}\n\
             static wp::f32 bits_f32(unsigned u) {{ wp::f32 x; memcpy(&x, &u, 4); return x; }}\n\
             int main() {{\n\
             {decl}\n\
             wp::fault_t fault = {{}}; unsigned int flag = 0;\n\
             wp::launch_ctx_t rec = wp::launch_ctx_make(&fault, &flag);\n\
             wp::ctx_t ctx = wp::ctx_make(&rec);\n\
             rec.flags = {flags};\n\
             wp::launch_t launch = {{{{{n}, 1, 1, 1}}, {n}, 1, 0}};\n\
             for (wp::i64 flat = 0; flat < {n}; ++flat) {thread}(p0, p1, p2, launch, flat, &ctx);\n\
             if (flag) printf(\"%d %lld %lld %lld\\n\", fault.kind, (long long)fault.index[0],\n\
                              (long long)fault.index[1], (long long)fault.index[2]);\n\
             else printf(\"ok\\n\");\n\
             return 0;\n}}\n",
            text = src.text,
            flags = if debug { "wp::CTX_DEBUG" } else { "0" },
            thread = src.thread_fn,
        );
        let flags = [
            "-std=c++17",
            "-O1",
            "-Wno-unused",
            "-DWP_CONTIGUOUS=1",
            "-I",
            include,
        ]
        .map(String::from);
        let host =
            build_and_run(&dir.join(format!("a{k}")), &program, &flags, "asserting").join("\n");
        wp::config::set_debug(debug);
        let cpu = wp::launch(asserting, n, (&x, &v, &out), &dev);
        wp::config::set_debug(was);
        match cpu {
            Ok(()) => assert_eq!(host.trim(), "ok", "case {k}"),
            Err(wp::Error::Fault(f)) => {
                faulted += 1;
                let wp::FaultKind::AssertionFailed {
                    line,
                    message,
                    thread,
                } = f.kind
                else {
                    panic!("case {k}: {f}")
                };
                let rec: Vec<i64> = host
                    .split_whitespace()
                    .map(|w| w.parse().unwrap())
                    .collect();
                // FAULT_ASSERTION, line, column, thread (-1 in a func).
                assert_eq!(rec.len(), 4, "case {k}: {host}");
                assert_eq!((rec[0], rec[1]), (8, line as i64), "case {k}: {f}");
                let thread_rec = usize::try_from(rec[3]).ok();
                assert_eq!(thread_rec, thread, "case {k}: {f}");
                let sites = asserting::INFO
                    .asserts
                    .iter()
                    .chain(asserting::INFO.callees.iter().flat_map(|c| c.asserts));
                let found: Vec<&str> = sites
                    .filter(|s| (s.line as i64, s.column as i64) == (rec[1], rec[2]))
                    .map(|s| s.message)
                    .collect();
                assert_eq!(found, [message], "case {k}: {f}");
            }
            Err(e) => panic!("case {k}: {e}"),
        }
    }
    // Cases 2 and 4 to 7 fail (the debug assertion only with the flag on).
    assert_eq!(faulted, 5);
    // The adjoint drops the assertions but replays the debug guard's reads: its unit (forward
    // and adjoint, as a launch under a tape compiles it) compiles too.
    assert_eq!(asserting::INFO.adjoint_error, None);
    assert_eq!(asserting::INFO.cuda_adjoint_error, None);
    let both = wp::cuda_source::assemble_with_adjoint(&asserting::INFO);
    let cpp = dir.join("both.cpp");
    std::fs::write(&cpp, &both.text).unwrap();
    let built = Command::new("g++")
        .args([
            "-std=c++17",
            "-fsyntax-only",
            "-Wno-unused",
            "-DWP_CONTIGUOUS=1",
            "-I",
            include,
        ])
        .arg(&cpp)
        .output()
        .unwrap();
    assert!(
        built.status.success(),
        "g++ failed on {}:\n{}",
        cpp.display(),
        String::from_utf8_lossy(&built.stderr)
    );
}

// ------------------------------------------------------------------------------------------
// Local arrays: forward, fault, adjoint and tangent units on the host
// ------------------------------------------------------------------------------------------

const LOCAL_LEN: usize = 5;

#[wp::func]
fn local_reversed(a: [f32; 4]) -> [f32; 4] {
    let mut r = a;
    for j in 0..4 {
        r[j] = a[3 - j];
    }
    r
}

#[wp::func]
fn local_dot(a: [Vec3; 2], w: Vec3) -> f32 {
    a[0].dot(w) - a[1].dot(w)
}

/// Literals, repeats (a literal and a const length), element, member and nested writes at
/// dynamic indices, an insertion sort, `len()`, and funcs taking and returning arrays.
#[wp::kernel]
fn local_arrays(x: Array<f32>, k: Array<i32>, out: Array<f32, 2>) {
    let i = tid();
    let mut a = [0.0f32; 8];
    for j in 0..8 {
        a[j] = x[(i * 3 + j as usize * 5) % 37] - (j as f32) * 0.5;
    }
    for j in 1..a.len() {
        let key = a[j];
        let mut p = j;
        while p > 0 && a[p - 1] > key {
            a[p] = a[p - 1];
            p -= 1;
        }
        a[p] = key;
    }
    let q = k[i];
    let mut v = [Vec3::ZERO; 2];
    v[(q % 2) as usize].y = a[3];
    v[1].x += a[0] * 2.0;
    let mut m = [[0.0f32; 3]; 2];
    m[(q % 2) as usize][(q % 3) as usize] = a[7];
    m[1][1] -= 1.5;
    let mut c = [0i32; LOCAL_LEN];
    c[(q % 5) as usize] += q;
    let r: [f32; 4] = local_reversed([a[1], a[2], m[1][1], 4.0]);
    for j in 0..8 {
        out[(i, j)] = a[j];
    }
    out[(i, 8)] = local_dot(v, Vec3::new(1.0, 2.0, 3.0)) + r[0] * 3.0 - r[3];
    out[(i, 9)] = m[0][0] + m[0][1] * 2.0 + m[0][2] * 4.0 + m[1][0] * 8.0 + m[1][2];
    out[(i, 10)] = (c[0] + c[1] * 3 + c[4] * 5) as f32 + c.len() as f32;
}

/// The forward CUDA unit of `local_arrays` on the host: the CPU backend's bits exactly.
#[test]
fn local_arrays_match_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 9;
    let xs: Vec<f32> = (0..37)
        .map(|k| ((k * 7) % 11) as f32 * 0.75 - 3.0)
        .collect();
    let ks: Vec<i32> = (0..n).map(|k| (k * 13 + 4) % 17).collect();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let k = wp::Array::from_slice(&ks, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n as usize, 11), &dev).unwrap();
    let args = [Arg::F32s(&x), Arg::I32s(&k), Arg::F32Grid(&out)];
    let Some(host) = run_on_host::<local_arrays>(&[n as usize], &args) else {
        return;
    };
    wp::launch(local_arrays, n as usize, (&x, &k, &out), &dev).unwrap();
    assert_eq!(host, cpu_results(&args));
    // The sort ran: each row's first eight values ascend.
    let o = out.to_vec().unwrap();
    assert!(o
        .chunks(11)
        .all(|r| r[..8].windows(2).all(|w| w[0] <= w[1])));
}

#[wp::kernel]
fn local_oob(k: Array<i32>, out: Array<f32>) {
    let i = tid();
    let mut a = [1.0f32, 2.0, 3.0];
    a[k[i]] = 5.0;
    out[i] = a[k[i] - 1];
}

/// An index outside a local array in the CUDA unit: the record the host decodes into the
/// CPU's fault (FAULT_LOCAL_INDEX with the index, the length and the line), for a write and a
/// read.
#[test]
fn local_array_index_faults_like_the_cpu_backend() {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED cuda_codegen_host (local arrays): no g++ on this machine");
        return;
    }
    let dev = wp::cpu();
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let src = wp::cuda_source::assemble(&local_oob::INFO);
    let dir = std::env::temp_dir().join(format!("wp_codegen_local_oob_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (case, ks) in [[0i32, 2, 3], [1, 0, 2]].into_iter().enumerate() {
        let k = wp::Array::from_slice(&ks, &dev).unwrap();
        let out = wp::Array::<f32>::zeros(3, &dev).unwrap();
        let (decl, _) = cpp_args(&[Arg::I32s(&k), Arg::F32s(&out)]);
        let program = format!(
            "#include <cstring>\n{text}\n\
             static wp::f32 bits_f32(unsigned u) {{ wp::f32 x; memcpy(&x, &u, 4); return x; }}\n\
             int main() {{\n\
             {decl}\n\
             wp::fault_t fault = {{}}; unsigned int flag = 0;\n\
             wp::launch_ctx_t rec = wp::launch_ctx_make(&fault, &flag);\n\
             wp::ctx_t ctx = wp::ctx_make(&rec);\n\
             wp::launch_t launch = {{{{3, 1, 1, 1}}, 3, 1, 0}};\n\
             for (wp::i64 flat = 0; flat < 3; ++flat) {thread}(p0, p1, launch, flat, &ctx);\n\
             if (flag) printf(\"%d %d %lld %lld %lld\\n\", fault.kind, fault.ndim,\n\
                              (long long)fault.index[0], (long long)fault.index[1],\n\
                              (long long)fault.index[2]);\n\
             else printf(\"ok\\n\");\n\
             return 0;\n}}\n",
            text = src.text,
            thread = src.thread_fn,
        );
        let flags = ["-std=c++17", "-O1", "-Wno-unused", "-I", include].map(String::from);
        let host =
            build_and_run(&dir.join(format!("oob{case}")), &program, &flags, "oob").join("\n");
        let Err(wp::Error::Fault(f)) = wp::launch(local_oob, 3, (&k, &out), &dev) else {
            panic!("case {case}: the CPU launch did not fault");
        };
        let wp::FaultKind::LocalIndex { index, len, line } = f.kind else {
            panic!("case {case}: {f}");
        };
        // FAULT_LOCAL_INDEX (wp_core.h), ndim 3: the index, the length, the line.
        let want = format!("9 3 {index} {len} {line}");
        assert_eq!(host.trim(), want, "case {case}: {f}");
    }
}

#[wp::func]
fn local_scaled(a: [f32; 3], s: f32) -> [f32; 3] {
    let mut r = a;
    for j in 0..3 {
        r[j] = r[j] * s - a[(j + 1) % 3];
    }
    r
}

/// Literals, a repeat, reads and writes at dynamic indices overwriting the array inside loops,
/// and a func taking and returning an array: `+ - *` only, so that the adjoint is the same
/// IEEE operations in the same order on both sides.
#[wp::kernel]
fn local_grads(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    let t = x[i];
    let mut a = [t, t * t, 1.0];
    let mut b = [t * 0.5; 3];
    for _pass in 0..3 {
        for j in 0..3 {
            a[j] = a[j] * a[(j + 2) % 3] * 0.5 + b[j];
            b[(j as usize + i) % 3] -= a[j] * 0.25;
        }
    }
    let c: [f32; 3] = local_scaled(a, t);
    y[i] = c[0] + c[1] * b[2] - c[2] * a[1];
}

/// Compiles and runs `K`'s CUDA adjoint unit on the host over a 1-D grid of `n` threads, each
/// with an empty stack of its own; `args` are the parameters, then the arrays' adjoints.
fn run_adjoint_on_host<K: Kernel>(n: usize, args: &[Arg]) -> Option<Vec<String>> {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED cuda_codegen_host (adjoint): no g++ on this machine");
        return None;
    }
    assert_eq!(K::INFO.cuda_adjoint_error, None);
    let src = wp::cuda_source::assemble_adjoint(&K::INFO);
    let (decl, print) = cpp_args(args);
    let params: Vec<String> = (0..args.len()).map(|k| format!("p{k}")).collect();
    let program = format!(
        "#include <cstring>\n{text}\n\
         static void print_f32(wp::f32 x) {{ unsigned u; memcpy(&u, &x, 4); printf(\"%08x\\n\", u); }}\n\
         static wp::f32 bits_f32(unsigned u) {{ wp::f32 x; memcpy(&x, &u, 4); return x; }}\n\
         int main() {{\n\
         {decl}\n\
         wp::fault_t fault = {{}}; unsigned int flag = 0;\n\
         wp::launch_ctx_t rec = wp::launch_ctx_make(&fault, &flag);\n\
         wp::ctx_t ctx = wp::ctx_make(&rec);\n\
         wp::launch_t launch = {{{{{n}, 1, 1, 1}}, {n}, 1, 0}};\n\
         static char buf[1 << 16];\n\
         wp::adstack_t st = wp::adstack_new(buf, sizeof buf);\n\
         for (wp::i64 flat = 0; flat < {n}; ++flat) {{ st.top = 0; {thread}({params}, launch, flat, &ctx, &st); }}\n\
         if (flag) {{ printf(\"fault %d\\n\", fault.kind); return 1; }}\n\
         {print}\n\
         return 0;\n}}\n",
        text = src.text,
        thread = src.thread_fn,
        params = params.join(", "),
    );
    let dir = std::env::temp_dir().join(format!(
        "wp_codegen_adj_{}_{}",
        K::INFO.name,
        std::process::id()
    ));
    let flags = [
        "-std=c++17",
        "-O1",
        "-ffp-contract=off",
        "-Wno-unused",
        "-DWP_CONTIGUOUS=1",
        "-I",
        concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda"),
    ]
    .map(String::from);
    Some(build_and_run(
        &dir,
        &program,
        &flags,
        "the generated adjoint",
    ))
}

/// The CUDA adjoint of `local_grads` (element stores in loops pushing the whole array, a func
/// adjoint taking an array) on the host: the CPU backend's gradients bit for bit.
#[test]
fn local_array_gradients_match_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 7;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.25 - 0.8).collect();
    let x = wp::Array::from_slice(&xs, &dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let y = wp::Array::<f32>::zeros(n, &dev)
        .unwrap()
        .with_grad()
        .unwrap();
    let tape = wp::Tape::new();
    {
        let _rec = tape.record();
        wp::launch(local_grads, n, (&x, &y), &dev).unwrap();
    }
    let gx = wp::Array::<f32>::zeros(n, &dev).unwrap();
    let gy = wp::Array::<f32>::full(n, 1.0, &dev).unwrap();
    let args = [Arg::F32s(&x), Arg::F32s(&y), Arg::F32s(&gx), Arg::F32s(&gy)];
    let Some(host) = run_adjoint_on_host::<local_grads>(n, &args) else {
        return;
    };
    y.grad().unwrap().fill(1.0).unwrap();
    tape.backward_from_grads().unwrap();
    let bits: Vec<String> = x
        .grad()
        .unwrap()
        .to_vec()
        .unwrap()
        .iter()
        .map(|v| format!("{:08x}", v.to_bits()))
        .collect();
    assert_eq!(&host[2 * n..3 * n], &bits[..]);
    assert!(
        bits.iter().all(|b| b != "00000000"),
        "no gradient reached x"
    );
}

/// The tangent kernel of `local_grads` (forward mode through the element stores and the func)
/// is refused by name, and that of a kernel without funcs runs on the host as on the CPU.
#[wp::kernel]
fn local_tangent(x: Array<f32>, y: Array<f32>) {
    let i = tid();
    let t = x[i];
    let mut a = [t, t * t, 1.0];
    for _pass in 0..2 {
        for j in 0..3 {
            a[j] = a[j] * a[(j + 2) % 3] + t;
        }
    }
    let b = [a[2]; 2];
    y[i] = a[0] - a[1] * b[1];
}

#[test]
fn local_array_tangent_matches_the_cpu_backend() {
    let dev = wp::cpu();
    let n = 6;
    let xs: Vec<f32> = (0..n).map(|k| k as f32 * 0.125 - 0.3).collect();
    let vs: Vec<f32> = (0..n).map(|k| 1.0 - k as f32 * 0.25).collect();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let y = wp::Array::<f32>::zeros(n, &dev).unwrap();
    let x_dot = wp::Array::from_slice(&vs, &dev).unwrap();
    let y_dot = wp::Array::<f32>::zeros(n, &dev).unwrap();
    let args = [
        Arg::F32s(&x),
        Arg::F32s(&y),
        Arg::F32s(&x_dot),
        Arg::F32s(&y_dot),
    ];
    type Tangent = <local_tangent as wp::Forward>::Tangent;
    let host = run_on_host::<Tangent>(&[n], &args);
    wp::jvp(local_tangent, n, (&x, &y), (&x_dot, &y_dot), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
        assert!(y_dot.to_vec().unwrap().iter().any(|v| *v != 0.0));
    }
}

/// The length of `Strand::rest`: a module const, which the C++ definition gets at assembly.
const STRAND_REST: usize = 3;

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Knot {
    p: Vec3,
    m: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, wp::Struct)]
#[repr(C)]
struct Strand {
    w: [f32; 4],
    knots: [Vec3; 2],
    rest: [f32; STRAND_REST],
    grid: [[i32; 2]; 2],
    frame: [Mat3; 1],
    head: Knot,
    id: u32,
}

#[wp::func]
fn strand_of(x: f32, k: i32) -> Strand {
    Strand {
        w: [x, x * 2.0, 0.5, -x],
        knots: [Vec3::splat(x), Vec3::new(1.0, x, 2.0)],
        rest: [0.25; STRAND_REST],
        grid: [[k, 1], [2, k * 3]],
        frame: [Mat3::from_diagonal(Vec3::new(x, 1.0, 2.0))],
        head: Knot {
            p: Vec3::Z * x,
            m: 1.5,
        },
        id: 7,
    }
}

#[wp::func]
fn quad(x: f32) -> [f32; 4] {
    [x, x * 2.0, x * 3.0, x * 4.0]
}

/// Struct literals (shorthand, nested, `..base`, from a func) and array fields read and
/// written at constant and dynamic indices, nested, through `len()`, lanes of vector
/// elements, a matrix element's column.
#[wp::kernel]
fn struct_values(x: Array<f32>, j: Array<i32>, out: Array<f32, 2>, ints: Array<i32>) {
    let i = tid();
    let k = j[i];
    let mut s = strand_of(x[i], k);
    s.w[k] += s.knots[1].y;
    s.knots[0].z = s.w[(k + 1) % 4];
    s.rest[2] *= 3.0;
    s.grid[1][k % 2] -= 5;
    s.head.m = s.frame[0].x_axis.x * 2.0;
    let m = 0.75;
    let t = Strand {
        head: Knot { p: s.knots[0], m },
        ..s
    };
    let mut total = 0.0;
    for q in 0..t.w.len() {
        total += t.w[q] * (q as f32 + 1.0);
    }
    out[(i, 0)] = total;
    out[(i, 1)] = t.knots[0].z + t.rest[2] + t.head.m + t.head.p.x;
    // A func's array result and a func's struct's array field, indexed directly.
    out[(i, 2)] = t.frame[0].z_axis.z + s.head.m + quad(x[i])[k] + strand_of(1.5, k).w[k];
    ints[i] = t.grid[1][0] * 100 + t.grid[1][1] + t.id as i32 + t.rest.len() as i32;
}

#[test]
fn struct_literals_and_array_fields_match_the_cpu_backend() {
    let dev = wp::cpu();
    let xs: Vec<f32> = (0..9).map(|k| k as f32 * 0.375 - 1.0).collect();
    let js: Vec<i32> = (0..9).map(|k| (k * 5 + 1) % 4).collect();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let j = wp::Array::from_slice(&js, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((9, 3), &dev).unwrap();
    let ints = wp::Array::<i32>::zeros(9, &dev).unwrap();
    let args = [
        Arg::F32s(&x),
        Arg::I32s(&j),
        Arg::F32Grid(&out),
        Arg::I32s(&ints),
    ];
    let host = run_on_host::<struct_values>(&[9], &args);
    wp::launch(struct_values, 9, (&x, &j, &out, &ints), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
}

/// A struct's C++ definition has the Rust struct's layout: its size and every field's offset,
/// with array fields (`wp::local_array_t`) and a const length filled in.
#[test]
fn struct_layouts_match_the_rust_side() {
    if Command::new("g++").arg("--version").output().is_err() {
        eprintln!("SKIPPED cuda_codegen_host (struct layouts): no g++ on this machine");
        return;
    }
    let mut defs = Vec::new();
    <Strand as wp::__private::CudaStruct>::cuda_defs(&mut defs);
    let fields = ["w", "knots", "rest", "grid", "frame", "head", "id"];
    let print: String = fields
        .iter()
        .map(|f| format!("printf(\"%zu\\n\", offsetof(Strand, {f}));\n"))
        .collect();
    let program = format!(
        "#include <cstdio>\n#include <cstddef>\n#include \"wp_core.h\"\n{}\n\
         int main() {{ printf(\"%zu\\n%zu\\n\", sizeof(Strand), alignof(Strand));\n{print}return 0; }}\n",
        defs.join("\n")
    );
    let dir = std::env::temp_dir().join(format!("wp_codegen_layout_{}", std::process::id()));
    let include = concat!(env!("CARGO_MANIFEST_DIR"), "/warp-cuda/cuda");
    let flags: Vec<String> = ["-std=c++17", "-I", include]
        .iter()
        .map(|s| s.to_string())
        .collect();
    let got = build_and_run(&dir, &program, &flags, "the layout program");
    let want: Vec<String> = [
        std::mem::size_of::<Strand>(),
        std::mem::align_of::<Strand>(),
        std::mem::offset_of!(Strand, w),
        std::mem::offset_of!(Strand, knots),
        std::mem::offset_of!(Strand, rest),
        std::mem::offset_of!(Strand, grid),
        std::mem::offset_of!(Strand, frame),
        std::mem::offset_of!(Strand, head),
        std::mem::offset_of!(Strand, id),
    ]
    .iter()
    .map(|n| n.to_string())
    .collect();
    assert_eq!(got, want);
}

// Generic kernels beyond `T: Float`: integer, vector and element type parameters and
// overloads; each instance's translation unit is compiled and run like a plain kernel's.

#[wp::func]
fn g_clamp<I: Int>(x: I, hi: I) -> I {
    if x > hi {
        hi
    } else {
        x
    }
}

#[wp::kernel]
fn g_int<I: Int>(a: Array<I>, out: Array<I>) {
    let i = tid();
    let x = a[i];
    out[i] = (x >> 1) / 3 + x * 3 + g_clamp::<I>(x, I::MAX / 4);
}

#[wp::kernel]
fn g_reject<V: Vector>(x: Array<V>, d: V, s: V::Scalar, out: Array<V>, len: Array<V::Scalar>) {
    let i = tid();
    let n = d.normalize();
    let r = (x[i] - n * x[i].dot(n)) * s + V::ZERO;
    out[i] = r;
    len[i] = r.length() + r.length_squared() + (V::LEN as V::Scalar);
}

wp::overloads!(g_combine);

#[wp::func(overload)]
fn g_combine(a: i32, b: i32) -> i32 {
    a - b
}

#[wp::func(overload)]
fn g_combine<V: Vector>(a: V, b: V) -> V {
    (a + b) * 0.5
}

#[wp::kernel(instances(T = [i32, Vec3]))]
fn g_gather<T: Element>(src: Array<T>, idx: Array<i32>, dst: Array<T>) {
    let i = tid();
    let j = idx[i];
    dst[i] = g_combine::<T>(src[j], dst[i]);
}

/// The instance of a generic kernel named `name`.
fn instance<G: wp::GenericKernel>(kernel: G, name: &str) -> &'static wp::KernelInfo {
    wp::aot::instances(kernel)
        .into_iter()
        .find(|i| i.name == name)
        .unwrap_or_else(|| panic!("no instance {name}"))
}

#[test]
fn generic_instances_match_the_cpu_backend() {
    let dev = wp::cpu();
    // `Int`: the i32 instance (shifts, division, wrapping `*`, a generic func).
    let a0 = [-7i32, 100, i32::MAX, 5, i32::MIN, 0];
    let a = wp::Array::from_slice(&a0, &dev).unwrap();
    let out = wp::Array::<i32>::zeros(6, &dev).unwrap();
    let host = run_info_on_host(
        instance(g_int, "g_int<i32>"),
        &[6],
        &[Arg::I32s(&a), Arg::I32s(&out)],
    );
    wp::launch(g_int, 6, (&a, &out), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::I32s(&a), Arg::I32s(&out)]));
    }
    // `Vector`: the Vec3 instance (normalize, dot, length, `V::Scalar`, `V::LEN`).
    let x0: Vec<Vec3> = (0..9)
        .map(|k| Vec3::new(k as f32 * 0.3 - 1.0, 0.7, 2.0 - k as f32 * 0.11))
        .collect();
    let x = wp::Array::from_slice(&x0, &dev).unwrap();
    let out = wp::Array::<Vec3>::zeros(9, &dev).unwrap();
    let len = wp::Array::<f32>::zeros(9, &dev).unwrap();
    let d = Vec3::new(0.3, -1.1, 0.6);
    let args = |x, out, len| {
        [
            Arg::Vec3s(x),
            Arg::Vec3(d),
            Arg::F32(0.75),
            Arg::Vec3s(out),
            Arg::F32s(len),
        ]
    };
    let host = run_info_on_host(
        instance(g_reject, "g_reject<Vec3>"),
        &[9],
        &args(&x, &out, &len),
    );
    wp::launch(g_reject, 9, (&x, d, 0.75f32, &out, &len), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args(&x, &out, &len)));
    }
    // `Element` with overloads: the i32 instance calls the plain overload, the Vec3 one the
    // generic overload's Vec3 instance.
    let idx = wp::Array::from_slice(&[2i32, 0, 1, 2], &dev).unwrap();
    let src = wp::Array::from_slice(&[10i32, 20, 30], &dev).unwrap();
    let dst = wp::Array::from_slice(&[1i32, 2, 3, 4], &dev).unwrap();
    let host = run_info_on_host(
        instance(g_gather, "g_gather<i32>"),
        &[4],
        &[Arg::I32s(&src), Arg::I32s(&idx), Arg::I32s(&dst)],
    );
    wp::launch(g_gather, 4, (&src, &idx, &dst), &dev).unwrap();
    assert_eq!(dst.to_vec().unwrap(), [29, 8, 17, 26]);
    if let Some(host) = host {
        assert_eq!(
            host,
            cpu_results(&[Arg::I32s(&src), Arg::I32s(&idx), Arg::I32s(&dst)])
        );
    }
    let src = wp::Array::from_slice(&x0[..3], &dev).unwrap();
    let dst = wp::Array::from_slice(&x0[5..9], &dev).unwrap();
    let host = run_info_on_host(
        instance(g_gather, "g_gather<Vec3>"),
        &[4],
        &[Arg::Vec3s(&src), Arg::I32s(&idx), Arg::Vec3s(&dst)],
    );
    wp::launch(g_gather, 4, (&src, &idx, &dst), &dev).unwrap();
    if let Some(host) = host {
        assert_eq!(
            host,
            cpu_results(&[Arg::Vec3s(&src), Arg::I32s(&idx), Arg::Vec3s(&dst)])
        );
    }
}

// `wp::grad(f)(..)`: the companion func's CUDA code runs `f`'s adjoint (in a forward unit,
// which then carries the adjoint library) and must give the CPU's bits.
#[wp::func]
fn fg_mixed(a: f32, b: f32) -> f32 {
    a * b + a.sin()
}

#[wp::func]
fn fg_scaled(v: Vec3) -> Vec3 {
    v * v.length()
}

#[wp::func]
fn fg_power(x: f32, n: i32) -> f32 {
    let mut acc = 1.0;
    for _ in 0..n {
        acc *= x;
    }
    acc
}

#[wp::kernel]
fn k_func_grads(xs: Array<f32>, vs: Array<Vec3>, out: Array<f32>, outv: Array<Vec3>) {
    let i = tid();
    let x = xs[i];
    let (ga, gb) = wp::grad(fg_mixed)(x, 0.5);
    let (gp, _) = wp::grad(fg_power)(x, 4);
    out[i] = ga + 3.0 * gb + x * gp;
    outv[i] = wp::grad(fg_scaled)(vs[i]) * x;
}

#[wp::func(replay = fg_recall)]
fn fg_take_slot(counter: Array<i32>, slots: Array<i32>, t: usize) -> i32 {
    let s = atomic_add(counter, 0, 1);
    slots[t] = s;
    s
}

#[wp::func]
fn fg_recall(counter: Array<i32>, slots: Array<i32>, t: usize) -> i32 {
    slots[t]
}

#[wp::kernel]
fn k_custom_replay(xs: Array<f32>, counter: Array<i32>, slots: Array<i32>, out: Array<f32>) {
    let t = tid();
    let s = fg_take_slot(counter, slots, t);
    out[s] = xs[s] * xs[s];
}

#[test]
fn func_gradients_and_custom_replays_match_the_cpu_backend() {
    let dev = wp::cpu();
    let x0 = [-2.5f32, -1.0, 0.0, 0.75, 3.0, 1.0e-3];
    let v0: Vec<Vec3> = (0..6)
        .map(|k| Vec3::new(k as f32 * 0.4 - 1.0, 0.7, 2.0 - k as f32 * 0.3))
        .collect();
    let xs = wp::Array::from_slice(&x0, &dev).unwrap();
    let vs = wp::Array::from_slice(&v0, &dev).unwrap();
    let out = wp::Array::<f32>::zeros(6, &dev).unwrap();
    let outv = wp::Array::<Vec3>::zeros(6, &dev).unwrap();
    let args = [
        Arg::F32s(&xs),
        Arg::Vec3s(&vs),
        Arg::F32s(&out),
        Arg::Vec3s(&outv),
    ];
    // Also compiles its adjoint unit (the kernel is differentiable: the gradient calls are
    // constants there).
    let host = run_on_host::<k_func_grads>(&[6], &args);
    wp::launch(k_func_grads, 6, (&xs, &vs, &out, &outv), &dev).unwrap();
    let want: Vec<f32> = x0
        .iter()
        .map(|&x| (0.5 + x.cos()) + 3.0 * x + x * (4.0 * x * x * x))
        .collect();
    let got = out.to_vec().unwrap();
    for (k, (g, w)) in got.iter().zip(&want).enumerate() {
        // The closed form rounds in another order than the adjoint: a few ulps of f32.
        assert!(
            (g - w).abs() <= 1e-5 * w.abs().max(1.0),
            "out[{k}]: {g} vs {w}"
        );
    }
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
    // One thread, so that the slot the counter gives is the same on both sides; the host run
    // compiles the adjoint unit, whose replay of `fg_take_slot` is `fg_recall`.
    let counter = wp::Array::<i32>::zeros(1, &dev).unwrap();
    let slots = wp::Array::<i32>::zeros(1, &dev).unwrap();
    let out = wp::Array::<f32>::zeros(1, &dev).unwrap();
    let args = [
        Arg::F32s(&xs),
        Arg::I32s(&counter),
        Arg::I32s(&slots),
        Arg::F32s(&out),
    ];
    let host = run_on_host::<k_custom_replay>(&[1], &args);
    wp::launch(k_custom_replay, 1, (&xs, &counter, &slots, &out), &dev).unwrap();
    assert_eq!(out.to_vec().unwrap(), [x0[0] * x0[0]]);
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&args));
    }
}

#[wp::func]
fn sl_pair(x: f32) -> (f32, Vec3) {
    (x * 1.5, vec3(x, 2.0 * x, -x))
}

#[wp::func]
fn sl_sq(x: f32) -> f32 {
    x * x
}

/// Unsuffixed literals in builtins' scalar positions beside values the macro cannot type
/// (funcs' results, tuple fields): each must be the lane type in C++ (a `double` there made
/// `lerp` ambiguous and `expect_near` fail its deduction under NVRTC).
#[wp::kernel]
fn scalar_literals(x: Array<f32>, out: Array<f32, 2>) {
    let i = tid();
    let a = x[i];
    let t = sl_pair(a);
    expect_near(t.0, a * 1.5, 1e-6);
    expect_near(sl_sq(a), a * a, 0.0);
    out[(i, 0)] = lerp(sl_sq(a), sl_sq(a + 1.0), 0.25);
    out[(i, 1)] = lerp(t.1, sl_pair(2.0 * a).1, 0.75).y;
    out[(i, 2)] = norm_huber(t.1, 0.5);
    out[(i, 3)] = smooth_normalize(t.1, 0.5).z;
    out[(i, 4)] = norm_pseudo_huber(t.1, 2.0);
    out[(i, 5)] = lerp(sl_sq(a), 2.0, -1.0);
}

#[test]
fn scalar_position_literals_match_the_cpu_backend() {
    let dev = wp::cpu();
    let xs: Vec<f32> = (0..9).map(|k| k as f32 * 0.61 - 2.2).collect();
    let n = xs.len();
    let x = wp::Array::from_slice(&xs, &dev).unwrap();
    let out = wp::Array::<f32, 2>::zeros((n, 6), &dev).unwrap();
    let host = run_on_host::<scalar_literals>(&[n], &[Arg::F32s(&x), Arg::F32Grid(&out)]);
    wp::launch(scalar_literals, n, (&x, &out), &dev).unwrap();
    let got = out.to_vec().unwrap();
    for (k, &a) in xs.iter().enumerate() {
        // lerp(a², (a+1)², 0.25) and lerp(a², 2, -1) in f32: a few ulps from the f64 forms.
        let l = (a * a) as f64 * 0.75 + ((a + 1.0) * (a + 1.0)) as f64 * 0.25;
        assert!((got[k * 6] as f64 - l).abs() <= 1e-5 * l.abs().max(1.0));
        let e = 2.0 * (a * a) as f64 - 2.0;
        assert!((got[k * 6 + 5] as f64 - e).abs() <= 1e-5 * e.abs().max(1.0));
    }
    if let Some(host) = host {
        assert_eq!(host, cpu_results(&[Arg::F32s(&x), Arg::F32Grid(&out)]));
    }
}

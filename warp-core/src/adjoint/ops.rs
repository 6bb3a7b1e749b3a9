//! Adjoints of the arithmetic operators `+ - * / %` and unary `-`.
//!
//! One trait per operator, implemented on the left operand's type with the right operand's
//! type as parameter, for exactly the combinations the kernel language types (see
//! `binary_result` in `warp-macros/src/front/lower/typing.rs`), each with glam's meaning:
//!
//! | operands                                      | operators           | adjoint            |
//! |-----------------------------------------------|---------------------|--------------------|
//! | `f32 op f32`, `f64 op f64`, `f16 op f16`      | `+ - * / %`         | scalar rules       |
//! | float vector `op` same vector                 | `+ - * / %`         | lane by lane       |
//! | float vector `op` its scalar, scalar `op` it  | `+ - * / %`         | lane by lane       |
//! | matrix `op` same matrix                       | `+ - *`             | matrix rules       |
//! | matrix `*` its column vector                  | `*`                 | `outer`, `Mᵀ g`    |
//! | matrix `op` its scalar                        | `* /`               | lane by lane       |
//! | scalar `op` matrix                            | `*`, `/` (glam: `s / M` is `M / s`) | lanes |
//! | quaternion `op` same quaternion               | `+ - *` (Hamilton)  | quaternion rules   |
//! | quaternion `*` its `Vec3`/`DVec3` (rotation)  | `*`                 | glam's formula     |
//! | quaternion `op` its scalar                    | `* /`               | lane by lane       |
//! | integer scalar, integer vector (with `i32`/`u32` on either side) | `+ - * / %` | no-op |
//! | unary `-` on all of the above                 | `-`                 | `adj_a -= g`       |
//!
//! Lane rules (`g` is the result's adjoint, per lane): `+`: `adj_a += g; adj_b += g`.
//! `-`: `adj_a += g; adj_b -= g`. `*`: `adj_a += g * b; adj_b += g * a`. `/`: `gb = g / b;
//! adj_a += gb; adj_b -= gb * (a / b)`. `%` (Rust's `%`, C's `fmod`): `adj_a += g;
//! adj_b -= g * trunc(a / b)`; for `Vec4` (with either operand a scalar too) glam's SSE2,
//! NEON and wasm32 `%` is the floored `a - floor(a / b) * b`, so there
//! `adj_b -= g * floor(a / b)` (which of the two this build's glam does is asked of glam
//! itself, `(-1 % 3).x`, so the adjoint always follows the forward). Where a
//! scalar meets a vector, matrix or quaternion, its adjoint collects the lanes'
//! contributions in lane order (matrices column-major; quaternions `x, y, z, w`).

use glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};

use super::lanes::{l_add, l_div, l_mul, l_rem_trunc, l_rem_vec4, l_sub, zip_sv, zip_vs, zip_vv};

macro_rules! binary_trait {
    ($tr:ident, $m:ident, $sym:literal) => {
        #[doc = concat!("Adjoint of `a ", $sym, " b`, implemented on `a`'s type with `b`'s type as `Rhs`.")]
        pub trait $tr<Rhs = Self>: Sized {
            #[doc = concat!("The type of `a ", $sym, " b`.")]
            type Output;
            #[doc = concat!("Accumulates into `adj_a` and `adj_b` the contributions of `a ", $sym, " b` given the adjoint `adj_ret` of its result.")]
            fn $m(a: Self, b: Rhs, adj_a: &mut Self, adj_b: &mut Rhs, adj_ret: Self::Output);
        }

        #[doc = concat!("Adjoint of `a ", $sym, " b`: accumulates (`+=`) into `adj_a` and `adj_b` the reverse-mode contributions, given the adjoint `adj_ret` of the result (see the module documentation for the rules; a no-op for integer operands).")]
        #[inline(always)]
        pub fn $m<A: $tr<B>, B>(a: A, b: B, adj_a: &mut A, adj_b: &mut B, adj_ret: A::Output) {
            A::$m(a, b, adj_a, adj_b, adj_ret)
        }
    };
}
binary_trait!(AdjAdd, adj_add, "+");
binary_trait!(AdjSub, adj_sub, "-");
binary_trait!(AdjMul, adj_mul, "*");
binary_trait!(AdjDiv, adj_div, "/");
binary_trait!(AdjRem, adj_rem, "%");

/// Adjoint of unary `-a`.
pub trait AdjNeg: Sized {
    /// Accumulates into `adj_a` the contribution of `-a` given the adjoint `adj_ret` of its
    /// result (`adj_a -= adj_ret`; a no-op for integers).
    fn adj_neg(a: Self, adj_a: &mut Self, adj_ret: Self);
}

/// Adjoint of unary `-a`: `adj_a -= adj_ret` (a no-op for integer operands).
#[inline(always)]
pub fn adj_neg<A: AdjNeg>(a: A, adj_a: &mut A, adj_ret: A) {
    A::adj_neg(a, adj_a, adj_ret)
}

// ------------------------------------------------------------------------------------------
// Integers: no-ops
// ------------------------------------------------------------------------------------------

macro_rules! noop_bin {
    ($($l:ty, $r:ty => $o:ty);* $(;)?) => {$(
        noop_bin!(@one AdjAdd, adj_add, $l, $r, $o);
        noop_bin!(@one AdjSub, adj_sub, $l, $r, $o);
        noop_bin!(@one AdjMul, adj_mul, $l, $r, $o);
        noop_bin!(@one AdjDiv, adj_div, $l, $r, $o);
        noop_bin!(@one AdjRem, adj_rem, $l, $r, $o);
    )*};
    (@one $tr:ident, $m:ident, $l:ty, $r:ty, $o:ty) => {
        impl $tr<$r> for $l {
            type Output = $o;
            #[inline(always)]
            fn $m(_a: $l, _b: $r, _adj_a: &mut $l, _adj_b: &mut $r, _adj_ret: $o) {}
        }
    };
}
noop_bin!(
    i8, i8 => i8; i16, i16 => i16; i32, i32 => i32; i64, i64 => i64; isize, isize => isize;
    u8, u8 => u8; u16, u16 => u16; u32, u32 => u32; u64, u64 => u64; usize, usize => usize;
    IVec2, IVec2 => IVec2; IVec2, i32 => IVec2; i32, IVec2 => IVec2;
    IVec3, IVec3 => IVec3; IVec3, i32 => IVec3; i32, IVec3 => IVec3;
    IVec4, IVec4 => IVec4; IVec4, i32 => IVec4; i32, IVec4 => IVec4;
    UVec2, UVec2 => UVec2; UVec2, u32 => UVec2; u32, UVec2 => UVec2;
    UVec3, UVec3 => UVec3; UVec3, u32 => UVec3; u32, UVec3 => UVec3;
    UVec4, UVec4 => UVec4; UVec4, u32 => UVec4; u32, UVec4 => UVec4;
);

macro_rules! noop_neg {
    ($($t:ty),*) => {$(
        impl AdjNeg for $t {
            #[inline(always)]
            fn adj_neg(_a: $t, _adj_a: &mut $t, _adj_ret: $t) {}
        }
    )*};
}
noop_neg!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);
noop_neg!(IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);

// ------------------------------------------------------------------------------------------
// Float scalars
// ------------------------------------------------------------------------------------------

macro_rules! float_scalar_ops {
    ($($s:ident),*) => {$(
        float_scalar_ops!(@one $s, AdjAdd, adj_add, l_add);
        float_scalar_ops!(@one $s, AdjSub, adj_sub, l_sub);
        float_scalar_ops!(@one $s, AdjMul, adj_mul, l_mul);
        float_scalar_ops!(@one $s, AdjDiv, adj_div, l_div);
        float_scalar_ops!(@one $s, AdjRem, adj_rem, l_rem_trunc);
        impl AdjNeg for $s {
            #[inline(always)]
            fn adj_neg(_a: $s, adj_a: &mut $s, adj_ret: $s) {
                *adj_a -= adj_ret;
            }
        }
    )*};
    (@one $s:ident, $tr:ident, $m:ident, $lane:ident) => {
        impl $tr for $s {
            type Output = $s;
            #[inline(always)]
            fn $m(a: $s, b: $s, adj_a: &mut $s, adj_b: &mut $s, adj_ret: $s) {
                $lane(a, b, adj_a, adj_b, adj_ret)
            }
        }
    };
}
use half::{bf16, f16};
float_scalar_ops!(f32, f64, f16, bf16);

// ------------------------------------------------------------------------------------------
// Float vectors (componentwise; with a scalar on either side)
// ------------------------------------------------------------------------------------------

macro_rules! float_vec_ops {
    ($($v:ident: $s:ident, $rem:ident);* $(;)?) => {$(
        float_vec_ops!(@one $v, $s, AdjAdd, adj_add, l_add);
        float_vec_ops!(@one $v, $s, AdjSub, adj_sub, l_sub);
        float_vec_ops!(@one $v, $s, AdjMul, adj_mul, l_mul);
        float_vec_ops!(@one $v, $s, AdjDiv, adj_div, l_div);
        float_vec_ops!(@one $v, $s, AdjRem, adj_rem, $rem);
        impl AdjNeg for $v {
            #[inline(always)]
            fn adj_neg(_a: $v, adj_a: &mut $v, adj_ret: $v) {
                *adj_a -= adj_ret;
            }
        }
    )*};
    (@one $v:ident, $s:ident, $tr:ident, $m:ident, $lane:ident) => {
        impl $tr for $v {
            type Output = $v;
            #[inline(always)]
            fn $m(a: $v, b: $v, adj_a: &mut $v, adj_b: &mut $v, adj_ret: $v) {
                zip_vv(a, b, adj_a, adj_b, adj_ret, $lane)
            }
        }
        impl $tr<$s> for $v {
            type Output = $v;
            #[inline(always)]
            fn $m(a: $v, b: $s, adj_a: &mut $v, adj_b: &mut $s, adj_ret: $v) {
                zip_vs(a, b, adj_a, adj_b, adj_ret, $lane)
            }
        }
        impl $tr<$v> for $s {
            type Output = $v;
            #[inline(always)]
            fn $m(a: $s, b: $v, adj_a: &mut $s, adj_b: &mut $v, adj_ret: $v) {
                zip_sv(a, b, adj_a, adj_b, adj_ret, $lane)
            }
        }
    };
}
float_vec_ops!(
    Vec2: f32, l_rem_trunc; Vec3: f32, l_rem_trunc; Vec4: f32, l_rem_vec4;
    DVec2: f64, l_rem_trunc; DVec3: f64, l_rem_trunc; DVec4: f64, l_rem_trunc;
);

// ------------------------------------------------------------------------------------------
// Matrices (glam, column-major)
// ------------------------------------------------------------------------------------------

macro_rules! mat_ops {
    ($($m:ident: $v:ident, $s:ident, $n:literal);* $(;)?) => {$(
        /// `A + B`: `adj_a += g; adj_b += g`.
        impl AdjAdd for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_add(_a: $m, _b: $m, adj_a: &mut $m, adj_b: &mut $m, adj_ret: $m) {
                *adj_a += adj_ret;
                *adj_b += adj_ret;
            }
        }
        /// `A - B`: `adj_a += g; adj_b -= g`.
        impl AdjSub for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_sub(_a: $m, _b: $m, adj_a: &mut $m, adj_b: &mut $m, adj_ret: $m) {
                *adj_a += adj_ret;
                *adj_b -= adj_ret;
            }
        }
        /// `A * B`: `adj_a += g * Bᵀ; adj_b += Aᵀ * g` (glam products).
        impl AdjMul for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_mul(a: $m, b: $m, adj_a: &mut $m, adj_b: &mut $m, adj_ret: $m) {
                *adj_a += adj_ret * b.transpose();
                *adj_b += a.transpose() * adj_ret;
            }
        }
        /// `M * v` (column vector): `adj_m.col(j) += g * v[j]` (the outer product `g vᵀ`);
        /// `adj_v += Mᵀ * g`.
        impl AdjMul<$v> for $m {
            type Output = $v;
            #[inline(always)]
            fn adj_mul(a: $m, b: $v, adj_a: &mut $m, adj_b: &mut $v, adj_ret: $v) {
                for j in 0..$n {
                    *adj_a.col_mut(j) += adj_ret * b[j];
                }
                *adj_b += a.transpose() * adj_ret;
            }
        }
        /// `M * s`: lane by lane.
        impl AdjMul<$s> for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_mul(a: $m, b: $s, adj_a: &mut $m, adj_b: &mut $s, adj_ret: $m) {
                zip_vs(a, b, adj_a, adj_b, adj_ret, l_mul)
            }
        }
        /// `M / s`: lane by lane.
        impl AdjDiv<$s> for $m {
            type Output = $m;
            #[inline(always)]
            fn adj_div(a: $m, b: $s, adj_a: &mut $m, adj_b: &mut $s, adj_ret: $m) {
                zip_vs(a, b, adj_a, adj_b, adj_ret, l_div)
            }
        }
        /// `s * M`: lane by lane.
        impl AdjMul<$m> for $s {
            type Output = $m;
            #[inline(always)]
            fn adj_mul(a: $s, b: $m, adj_a: &mut $s, adj_b: &mut $m, adj_ret: $m) {
                zip_sv(a, b, adj_a, adj_b, adj_ret, l_mul)
            }
        }
        /// `s / M`, which glam 0.30 computes as `M / s` (its quirk, mirrored by the CUDA
        /// library): the adjoint of `M / s`, with the operands' roles swapped back.
        impl AdjDiv<$m> for $s {
            type Output = $m;
            #[inline(always)]
            fn adj_div(a: $s, b: $m, adj_a: &mut $s, adj_b: &mut $m, adj_ret: $m) {
                zip_vs(b, a, adj_b, adj_a, adj_ret, l_div)
            }
        }
        /// `-M`: `adj_a -= g`.
        impl AdjNeg for $m {
            #[inline(always)]
            fn adj_neg(_a: $m, adj_a: &mut $m, adj_ret: $m) {
                *adj_a -= adj_ret;
            }
        }
    )*};
}
mat_ops!(
    Mat2: Vec2, f32, 2; Mat3: Vec3, f32, 3; Mat4: Vec4, f32, 4;
    DMat2: DVec2, f64, 2; DMat3: DVec3, f64, 3; DMat4: DVec4, f64, 4;
);

// ------------------------------------------------------------------------------------------
// Quaternions
// ------------------------------------------------------------------------------------------

macro_rules! quat_ops {
    ($($q:ident: $v3:ident, $s:ident);* $(;)?) => {$(
        /// `p + q`: `adj_p += g; adj_q += g`.
        impl AdjAdd for $q {
            type Output = $q;
            #[inline(always)]
            fn adj_add(_a: $q, _b: $q, adj_a: &mut $q, adj_b: &mut $q, adj_ret: $q) {
                *adj_a += adj_ret;
                *adj_b += adj_ret;
            }
        }
        /// `p - q`: `adj_p += g; adj_q -= g`.
        impl AdjSub for $q {
            type Output = $q;
            #[inline(always)]
            fn adj_sub(_a: $q, _b: $q, adj_a: &mut $q, adj_b: &mut $q, adj_ret: $q) {
                *adj_a += adj_ret;
                *adj_b -= adj_ret;
            }
        }
        /// `p * q`, the Hamilton product (glam's `mul_quat`, for any quaternions, unit or
        /// not):
        /// `x = w0 x1 + x0 w1 + y0 z1 - z0 y1`, `y = w0 y1 - x0 z1 + y0 w1 + z0 x1`,
        /// `z = w0 z1 + x0 y1 - y0 x1 + z0 w1`, `w = w0 w1 - x0 x1 - y0 y1 - z0 z1`;
        /// the adjoint is the transpose of that bilinear map in each argument.
        impl AdjMul for $q {
            type Output = $q;
            #[inline(always)]
            fn adj_mul(a: $q, b: $q, adj_a: &mut $q, adj_b: &mut $q, adj_ret: $q) {
                let (x0, y0, z0, w0) = (a.x, a.y, a.z, a.w);
                let (x1, y1, z1, w1) = (b.x, b.y, b.z, b.w);
                let (gx, gy, gz, gw) = (adj_ret.x, adj_ret.y, adj_ret.z, adj_ret.w);
                *adj_a += $q::from_xyzw(
                    gx * w1 - gy * z1 + gz * y1 - gw * x1,
                    gx * z1 + gy * w1 - gz * x1 - gw * y1,
                    -gx * y1 + gy * x1 + gz * w1 - gw * z1,
                    gx * x1 + gy * y1 + gz * z1 + gw * w1,
                );
                *adj_b += $q::from_xyzw(
                    gx * w0 + gy * z0 - gz * y0 - gw * x0,
                    -gx * z0 + gy * w0 + gz * x0 - gw * y0,
                    gx * y0 - gy * x0 + gz * w0 - gw * z0,
                    gx * x0 + gy * y0 + gz * z0 + gw * w0,
                );
            }
        }
        /// `q * v`, glam's rotation formula, exact also for a non-unit `q = (b, w)`:
        /// `r = v (w² - b·b) + b (2 v·b) + (b × v)(2 w)`. With `g` the adjoint of `r`:
        /// `adj_v += g (w² - b·b) + b (2 b·g) + (g × b)(2 w)`;
        /// `adj_w += 2 (w (g·v) + g·(b × v))`;
        /// `adj_b += g (2 v·b) + v (2 b·g) - b (2 v·g) + (v × g)(2 w)`.
        impl AdjMul<$v3> for $q {
            type Output = $v3;
            #[inline(always)]
            fn adj_mul(a: $q, v: $v3, adj_a: &mut $q, adj_b: &mut $v3, adj_ret: $v3) {
                let two: $s = 2.0;
                let w = a.w;
                let b = $v3::new(a.x, a.y, a.z);
                let g = adj_ret;
                let (bb, bg, vb, vg) = (b.dot(b), b.dot(g), v.dot(b), v.dot(g));
                *adj_b += g * (w * w - bb) + b * (two * bg) + g.cross(b) * (two * w);
                let ab = g * (two * vb) + v * (two * bg) - b * (two * vg) + v.cross(g) * (two * w);
                let aw = two * (w * vg + g.dot(b.cross(v)));
                *adj_a += $q::from_xyzw(ab.x, ab.y, ab.z, aw);
            }
        }
        /// `q * s`: lane by lane (`x, y, z, w`).
        impl AdjMul<$s> for $q {
            type Output = $q;
            #[inline(always)]
            fn adj_mul(a: $q, b: $s, adj_a: &mut $q, adj_b: &mut $s, adj_ret: $q) {
                zip_vs(a, b, adj_a, adj_b, adj_ret, l_mul)
            }
        }
        /// `q / s`: lane by lane (`x, y, z, w`).
        impl AdjDiv<$s> for $q {
            type Output = $q;
            #[inline(always)]
            fn adj_div(a: $q, b: $s, adj_a: &mut $q, adj_b: &mut $s, adj_ret: $q) {
                zip_vs(a, b, adj_a, adj_b, adj_ret, l_div)
            }
        }
        /// `-q`: `adj_q -= g`.
        impl AdjNeg for $q {
            #[inline(always)]
            fn adj_neg(_a: $q, adj_a: &mut $q, adj_ret: $q) {
                *adj_a -= adj_ret;
            }
        }
    )*};
}
quat_ops!(Quat: Vec3, f32; DQuat: DVec3, f64);

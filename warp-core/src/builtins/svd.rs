//! Matrix decompositions (CPU side of the table's "svd" section): `svd3`, `svd2`, `qr3`,
//! `eig3`, with NVIDIA Warp's algorithms and conventions (`warp/native/svd.h`, after McAdams
//! et al., "Computing the Singular Value Decomposition of 3x3 matrices with minimal branching
//! and elementary floating point operations", 2011).
//!
//! Each returns a tuple, in the order of Warp's output arguments: `svd3(a) = (U, σ, V)` with
//! `a = U diag(σ) Vᵀ`, `eig3(a) = (Q, d)` with `a = Q diag(d) Qᵀ`, `qr3(a) = (Q, R)` with
//! `a = Q R`, `svd2(a) = (U, σ, V)`.
//!
//! # Algorithms and conventions
//!
//! * `eig3(a)` (symmetric `a`; only its lower triangle is read by the iteration): cyclic
//!   Jacobi, a fixed number of sweeps (5 for f32, where Warp has 4; 8 for f64), each rotating the pairs
//!   (0,1), (1,2), (0,2) in turn by an *approximate* Givens angle (from the 2x2 block, with a
//!   fixed π/4 rotation where the block's diagonal is too close for the approximation); the
//!   rotations are accumulated as a quaternion, so `Q` is a rotation (`det Q = +1`) up to
//!   rounding. `d_k = (Qᵀ a Q)_kk` (the whole of `a` is read there). The eigenvalues are in
//!   the order the sweeps leave them, *not sorted* (as Warp); `d_k` belongs to column `k`.
//! * `svd3(a)`: the Jacobi iteration above on `aᵀa` gives `V`; the columns of `B = a V` are
//!   sorted by decreasing length (each swap negates one column, so `V` stays a rotation); a
//!   QR decomposition of `B` by three Givens rotations gives `U` and `R`, and `σ = diag(R)`.
//!   So `U` and `V` are rotations, `σ0 ≥ σ1 ≥ |σ2|`, `σ0, σ1 ≥ 0`, and `σ2` has the sign of
//!   `det a` (a reflection is carried by `σ2`, never by `U` or `V`: Warp's convention, the
//!   one "inversion-aware" elasticity models want). The off-diagonal entries of `R` (zero up
//!   to rounding and the iteration's convergence) are dropped.
//! * `qr3(a)`: the same three Givens rotations: `Q` a rotation, `R` upper triangular with
//!   `R00, R11 ≥ 0` and `R22` of the sign of `det a`; the entries below the diagonal of `R`
//!   are what the rotations leave (zero up to rounding), as in Warp.
//! * `svd2(a)`: Warp's closed form from the eigenvalues of `aᵀa`: `V` a rotation,
//!   `σ0 ≥ σ1 ≥ 0`, and `det U = sign(det a)` (`sign(0) = +1`), so a reflection is carried by
//!   `U` here (Warp's convention for 2x2). A repeated eigenvalue of `aᵀa` (discriminant
//!   exactly zero) gives `U = V = I` and `σ0 = σ1 = sqrt(trace(aᵀa) / 2)`. One deviation from
//!   Warp: where rounding makes the smaller eigenvalue of `aᵀa` negative (rank-deficient `a`),
//!   `σ1` is 0 here, NaN in Warp.
//!
//! Edge cases: the iteration counts are fixed, so no input makes these loop longer; the zero
//! matrix gives `U = V = I`-like rotations and `σ = 0`; NaN in `a` makes `σ` and `U` NaN (for
//! `svd3`/`eig3` `V`/`Q` stay finite rotations, as the Jacobi test `γ sh² < ch²` is false for
//! NaN and picks the fixed rotation), infinities give NaNs.
//!
//! # Floating point
//!
//! Everything is IEEE `+ - * /` and `sqrt` (no FMA), evaluated left to right in the order
//! written here, and the CUDA library (`wp_svd.h`) does the same operations in the same
//! order, so both backends agree bit for bit. Where Warp's GPU code uses the approximate
//! `rsqrt`, both use `1 / sqrt(x)` (correctly rounded on both). The constants of the
//! approximate Givens rotation (`3 + 2√2`, `cos π/8`, `sin π/8`) are f64 values rounded to the
//! working precision, as Warp's.

use glam::{DMat2, DMat3, DVec2, DVec3, Mat2, Mat3, Vec2, Vec3};

use core::ops::{Add, Div, Mul, Neg, Sub};

/// A 3x3 matrix as rows: `m[row][col]`.
pub type Rows3<S> = [[S; 3]; 3];
/// A 2x2 matrix as rows: `m[row][col]`.
pub type Rows2<S> = [[S; 2]; 2];

/// The float scalars the decompositions work in (`f32`, `f64`), with Warp's constants.
pub trait DecompFloat:
    Copy
    + PartialOrd
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// 0.
    const ZERO: Self;
    /// 1.
    const ONE: Self;
    /// 2.
    const TWO: Self;
    /// Warp's `_svd_config::SVD_EPSILON` and `QR_GIVENS_EPSILON`: 1e-6 (f32), 1e-12 (f64).
    const EPS: Self;
    /// Jacobi sweeps: 5 (f32; Warp's `JACOBI_ITERATIONS` is 4, which leaves about 1 random
    /// matrix in 40 unconverged), 8 (f64, Warp's).
    const SWEEPS: usize;
    /// `3 + 2√2` (`4γ²` of McAdams et al.), from f64.
    const GAMMA: Self;
    /// `cos(π/8)`, from f64.
    const CSTAR: Self;
    /// `sin(π/8)`, from f64.
    const SSTAR: Self;
    /// `1/√2`.
    const SQRT1_2: Self;
    /// 0.5.
    const HALF: Self;
    /// 4.
    const FOUR: Self;
    /// 8.
    const EIGHT: Self;
    /// Square root (correctly rounded).
    fn d_sqrt(self) -> Self;
    /// Absolute value.
    fn d_abs(self) -> Self;
    /// IEEE minNum (C `fmin`): a lone NaN loses.
    fn d_min(self, o: Self) -> Self;
    /// IEEE maxNum (C `fmax`): a lone NaN loses.
    fn d_max(self, o: Self) -> Self;
}

macro_rules! decomp_float {
    ($t:ident, $eps:expr, $sweeps:expr) => {
        impl DecompFloat for $t {
            const ZERO: Self = 0.0;
            const ONE: Self = 1.0;
            const TWO: Self = 2.0;
            const EPS: Self = $eps;
            const SWEEPS: usize = $sweeps;
            const GAMMA: Self = 5.828_427_124_746_19_f64 as $t;
            const CSTAR: Self = 0.923_879_532_511_286_7_f64 as $t;
            const SSTAR: Self = 0.382_683_432_365_089_8_f64 as $t;
            const SQRT1_2: Self = core::f64::consts::FRAC_1_SQRT_2 as $t;
            const HALF: Self = 0.5;
            const FOUR: Self = 4.0;
            const EIGHT: Self = 8.0;
            #[inline(always)]
            fn d_sqrt(self) -> Self {
                self.sqrt()
            }
            #[inline(always)]
            fn d_abs(self) -> Self {
                self.abs()
            }
            #[inline(always)]
            fn d_min(self, o: Self) -> Self {
                self.min(o)
            }
            #[inline(always)]
            fn d_max(self, o: Self) -> Self {
                self.max(o)
            }
        }
    };
}
// f32: 5 Jacobi sweeps where Warp has 4: with 4, about 1 random matrix in 40 is left
// unconverged (reconstruction errors up to 1.4e-2 of max |A| over 100,000 matrices); with 5 the
// worst is 1.1e-5, for a quarter more sweeps. f64: Warp's 8.
decomp_float!(f32, 1e-6, 5);
decomp_float!(f64, 1e-12, 8);

/// 3x3 float matrices (`Mat3`, `DMat3`) as the decompositions see them.
pub trait Decomp3: Copy {
    /// The scalar.
    type S: DecompFloat;
    /// The 3-vector (`Vec3`, `DVec3`).
    type V: Copy;
    /// The rows.
    fn rows(self) -> Rows3<Self::S>;
    /// The matrix with these rows.
    fn from_rows(r: Rows3<Self::S>) -> Self;
    /// A vector from its components.
    fn vec(v: [Self::S; 3]) -> Self::V;
    /// A vector's components.
    fn comps(v: Self::V) -> [Self::S; 3];
    /// The `inverse` builtin on rows (the zero matrix when the determinant is 0).
    fn inverse_rows(r: Rows3<Self::S>) -> Rows3<Self::S>;
}

/// 2x2 float matrices (`Mat2`, `DMat2`) as `svd2` sees them.
pub trait Decomp2: Copy {
    /// The scalar.
    type S: DecompFloat;
    /// The 2-vector (`Vec2`, `DVec2`).
    type V: Copy;
    /// The rows.
    fn rows(self) -> Rows2<Self::S>;
    /// The matrix with these rows.
    fn from_rows(r: Rows2<Self::S>) -> Self;
    /// A vector from its components.
    fn vec(v: [Self::S; 2]) -> Self::V;
    /// A vector's components.
    fn comps(v: Self::V) -> [Self::S; 2];
}

macro_rules! decomp3 {
    ($m:ident, $v:ident, $s:ident) => {
        impl Decomp3 for $m {
            type S = $s;
            type V = $v;
            #[inline(always)]
            fn rows(self) -> Rows3<$s> {
                let c = self.to_cols_array_2d();
                [
                    [c[0][0], c[1][0], c[2][0]],
                    [c[0][1], c[1][1], c[2][1]],
                    [c[0][2], c[1][2], c[2][2]],
                ]
            }
            #[inline(always)]
            fn from_rows(r: Rows3<$s>) -> Self {
                $m::from_cols_array_2d(&[
                    [r[0][0], r[1][0], r[2][0]],
                    [r[0][1], r[1][1], r[2][1]],
                    [r[0][2], r[1][2], r[2][2]],
                ])
            }
            #[inline(always)]
            fn vec(v: [$s; 3]) -> $v {
                $v::from_array(v)
            }
            #[inline(always)]
            fn comps(v: $v) -> [$s; 3] {
                v.to_array()
            }
            #[inline(always)]
            fn inverse_rows(r: Rows3<$s>) -> Rows3<$s> {
                super::linalg::inverse(Self::from_rows(r)).rows()
            }
        }
    };
}
decomp3!(Mat3, Vec3, f32);
decomp3!(DMat3, DVec3, f64);

macro_rules! decomp2 {
    ($m:ident, $v:ident, $s:ident) => {
        impl Decomp2 for $m {
            type S = $s;
            type V = $v;
            #[inline(always)]
            fn rows(self) -> Rows2<$s> {
                let c = self.to_cols_array_2d();
                [[c[0][0], c[1][0]], [c[0][1], c[1][1]]]
            }
            #[inline(always)]
            fn from_rows(r: Rows2<$s>) -> Self {
                $m::from_cols_array_2d(&[[r[0][0], r[1][0]], [r[0][1], r[1][1]]])
            }
            #[inline(always)]
            fn vec(v: [$s; 2]) -> $v {
                $v::from_array(v)
            }
            #[inline(always)]
            fn comps(v: $v) -> [$s; 2] {
                v.to_array()
            }
        }
    };
}
decomp2!(Mat2, Vec2, f32);
decomp2!(DMat2, DVec2, f64);

// ------------------------------------------------------------------------------------------
// Public builtins
// ------------------------------------------------------------------------------------------

/// Singular value decomposition of a 3x3 matrix: `(U, σ, V)` with `a = U diag(σ) Vᵀ`, `U`
/// and `V` rotations, `σ0 ≥ σ1 ≥ |σ2|` and `σ2` of the sign of `det a` (Warp's `svd3`; see
/// the module documentation).
#[inline]
pub fn svd3<M: Decomp3>(a: M) -> (M, M::V, M) {
    let (u, s, v) = svd3_rows(a.rows());
    (M::from_rows(u), M::vec(s), M::from_rows(v))
}

/// Eigendecomposition of a symmetric 3x3 matrix: `(Q, d)` with `a = Q diag(d) Qᵀ`, `Q` a
/// rotation whose column `k` is the eigenvector of `d_k`; eigenvalues not sorted (Warp's
/// `eig3`; see the module documentation).
#[inline]
pub fn eig3<M: Decomp3>(a: M) -> (M, M::V) {
    let (q, d) = eig3_rows(a.rows());
    (M::from_rows(q), M::vec(d))
}

/// QR decomposition of a 3x3 matrix by Givens rotations: `(Q, R)` with `a = Q R`, `Q` a
/// rotation, `R` upper triangular up to rounding (Warp's `qr3`).
#[inline]
pub fn qr3<M: Decomp3>(a: M) -> (M, M) {
    let (q, r) = qr_rows(a.rows());
    (M::from_rows(q), M::from_rows(r))
}

/// Singular value decomposition of a 2x2 matrix: `(U, σ, V)` with `a = U diag(σ) Vᵀ`,
/// `σ0 ≥ σ1 ≥ 0`, `V` a rotation and `det U = sign(det a)` (Warp's `svd2`).
#[inline]
pub fn svd2<M: Decomp2>(a: M) -> (M, M::V, M) {
    let (u, s, v) = svd2_rows(a.rows());
    (M::from_rows(u), M::vec(s), M::from_rows(v))
}

// ------------------------------------------------------------------------------------------
// Row-major helpers (shared with the adjoints)
// ------------------------------------------------------------------------------------------

/// `a b`: each entry `a[i][0]*b[0][j] + a[i][1]*b[1][j] + a[i][2]*b[2][j]`, left to right.
#[inline(always)]
pub(crate) fn mul3<S: DecompFloat>(a: &Rows3<S>, b: &Rows3<S>) -> Rows3<S> {
    core::array::from_fn(|i| {
        core::array::from_fn(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j])
    })
}

/// `aᵀ b`: each entry `a[0][i]*b[0][j] + a[1][i]*b[1][j] + a[2][i]*b[2][j]`, left to right.
#[inline(always)]
pub(crate) fn mul3_tn<S: DecompFloat>(a: &Rows3<S>, b: &Rows3<S>) -> Rows3<S> {
    core::array::from_fn(|i| {
        core::array::from_fn(|j| a[0][i] * b[0][j] + a[1][i] * b[1][j] + a[2][i] * b[2][j])
    })
}

/// `a bᵀ`: each entry `a[i][0]*b[j][0] + a[i][1]*b[j][1] + a[i][2]*b[j][2]`, left to right.
#[inline(always)]
pub(crate) fn mul3_nt<S: DecompFloat>(a: &Rows3<S>, b: &Rows3<S>) -> Rows3<S> {
    core::array::from_fn(|i| {
        core::array::from_fn(|j| a[i][0] * b[j][0] + a[i][1] * b[j][1] + a[i][2] * b[j][2])
    })
}

// ------------------------------------------------------------------------------------------
// Symmetric eigenanalysis: cyclic Jacobi with approximate Givens rotations
// ------------------------------------------------------------------------------------------

/// The rotation (as the half-angle pair `(cos, sin)` of a quaternion) that approximately
/// zeroes the off-diagonal entry of the symmetric block `[[a11, a21], [a21, a22]]`: the
/// first-order angle, or the fixed angle π/8 (a π/4 rotation) where `γ sh² ≥ ch²`.
#[inline(always)]
fn approx_givens<S: DecompFloat>(a11: S, a21: S, a22: S) -> (S, S) {
    let ch = S::TWO * (a11 - a22);
    let sh = a21;
    let first_order = S::GAMMA * sh * sh < ch * ch;
    let w = S::ONE / (ch * ch + sh * sh).d_sqrt();
    if first_order {
        (w * ch, w * sh)
    } else {
        (S::CSTAR, S::SSTAR)
    }
}

/// One Jacobi rotation of the symmetric matrix held as its lower triangle
/// `s = [s11, s21, s22, s31, s32, s33]` in the plane of its first two rows, accumulated into
/// the quaternion `q = [x, y, z, w]` about axis `z` (`(x, y, z)` a cyclic permutation of
/// `(0, 1, 2)` naming the current plane); then the triangle is relabelled so that the next
/// plane of the cycle comes first.
#[inline(always)]
fn jacobi_rotation<S: DecompFloat>(s: &mut [S; 6], q: &mut [S; 4], x: usize, y: usize, z: usize) {
    let [s11, s21, s22, s31, s32, s33] = *s;
    let (ch, sh) = approx_givens(s11, s21, s22);
    let scale = ch * ch + sh * sh;
    // cos and sin of the full angle.
    let c = (ch * ch - sh * sh) / scale;
    let t = (S::TWO * sh * ch) / scale;
    // Gᵀ S G on the block and the two entries of the third row.
    let n11 = c * (c * s11 + t * s21) + t * (c * s21 + t * s22);
    let n21 = c * (-t * s11 + c * s21) + t * (-t * s21 + c * s22);
    let n22 = -t * (-t * s11 + c * s21) + c * (-t * s21 + c * s22);
    let n31 = c * s31 + t * s32;
    let n32 = -t * s31 + c * s32;
    // q = q * (ch + sh e_z), written out.
    let tmp = [q[0] * sh, q[1] * sh, q[2] * sh];
    let shw = sh * q[3];
    for k in q.iter_mut() {
        *k = *k * ch;
    }
    q[z] = q[z] + shw;
    q[3] = q[3] - tmp[z];
    q[x] = q[x] + tmp[y];
    q[y] = q[y] - tmp[x];
    // Rows and columns renamed (1, 2, 3) -> (3, 1, 2): the plane (2, 3) comes first.
    *s = [n22, n32, s33, n21, n31, n11];
}

/// The fixed sweeps over the planes (0,1), (1,2), (0,2); the accumulated rotation.
#[inline(always)]
fn jacobi<S: DecompFloat>(s: &mut [S; 6]) -> [S; 4] {
    let mut q = [S::ZERO, S::ZERO, S::ZERO, S::ONE];
    for _ in 0..S::SWEEPS {
        jacobi_rotation(s, &mut q, 0, 1, 2);
        jacobi_rotation(s, &mut q, 1, 2, 0);
        jacobi_rotation(s, &mut q, 2, 0, 1);
    }
    q
}

/// The rotation matrix of the quaternion `q = [x, y, z, w]` (unit up to rounding).
#[inline(always)]
fn quat_rows<S: DecompFloat>(q: [S; 4]) -> Rows3<S> {
    let [x, y, z, w] = q;
    let (xx, yy, zz) = (x * x, y * y, z * z);
    let (xz, xy, yz) = (x * z, x * y, y * z);
    let (wx, wy, wz) = (w * x, w * y, w * z);
    let (one, two) = (S::ONE, S::TWO);
    [
        [one - two * (yy + zz), two * (xy - wz), two * (xz + wy)],
        [two * (xy + wz), one - two * (xx + zz), two * (yz - wx)],
        [two * (xz - wy), two * (yz + wx), one - two * (xx + yy)],
    ]
}

/// `eig3` on rows.
pub(crate) fn eig3_rows<S: DecompFloat>(a: Rows3<S>) -> (Rows3<S>, [S; 3]) {
    let mut s = [a[0][0], a[1][0], a[1][1], a[2][0], a[2][1], a[2][2]];
    let q = quat_rows(jacobi(&mut s));
    let d = mul3(&mul3_tn(&q, &a), &q);
    (q, [d[0][0], d[1][1], d[2][2]])
}

// ------------------------------------------------------------------------------------------
// QR by Givens rotations
// ------------------------------------------------------------------------------------------

/// The half-angle pair `(cos, sin)` of the rotation taking `(a1, a2)` to `(ρ, 0)`, `ρ ≥ 0`
/// (no rotation where `ρ ≤ ε`).
#[inline(always)]
fn qr_givens<S: DecompFloat>(a1: S, a2: S) -> (S, S) {
    let rho = (a1 * a1 + a2 * a2).d_sqrt();
    let mut sh = if rho > S::EPS { a2 } else { S::ZERO };
    let mut ch = a1.d_abs() + rho.d_max(S::EPS);
    if a1 < S::ZERO {
        core::mem::swap(&mut sh, &mut ch);
    }
    let w = S::ONE / (ch * ch + sh * sh).d_sqrt();
    (ch * w, sh * w)
}

/// Rows `i` and `j` of `m` replaced by `c m_i + t m_j` and `-t m_i + c m_j`, where `(c, t)`
/// are the cosine and sine of the full angle of the half-angle pair `(ch, sh)`.
#[inline(always)]
fn rotate_rows<S: DecompFloat>(m: &mut Rows3<S>, i: usize, j: usize, ch: S, sh: S) {
    let c = S::ONE - S::TWO * sh * sh;
    let t = S::TWO * ch * sh;
    let (ri, rj) = (m[i], m[j]);
    for k in 0..3 {
        m[i][k] = c * ri[k] + t * rj[k];
        m[j][k] = -t * ri[k] + c * rj[k];
    }
}

/// `qr3` on rows: three Givens rotations zero `b[1][0]`, `b[2][0]`, `b[2][1]`; `Q` is their
/// product written out from the half angles.
pub(crate) fn qr_rows<S: DecompFloat>(b: Rows3<S>) -> (Rows3<S>, Rows3<S>) {
    let mut r = b;
    let (ch1, sh1) = qr_givens(r[0][0], r[1][0]);
    rotate_rows(&mut r, 0, 1, ch1, sh1);
    let (ch2, sh2) = qr_givens(r[0][0], r[2][0]);
    rotate_rows(&mut r, 0, 2, ch2, sh2);
    let (ch3, sh3) = qr_givens(r[1][1], r[2][1]);
    rotate_rows(&mut r, 1, 2, ch3, sh3);

    let one = S::ONE;
    let two = S::TWO;
    let (s1, s2, s3) = (sh1 * sh1, sh2 * sh2, sh3 * sh3);
    // cos of the full angles, negated: -1 + 2 sh².
    let (m1, m2, m3) = (-one + two * s1, -one + two * s2, -one + two * s3);
    let q = [
        [
            m1 * m2,
            S::FOUR * ch2 * ch3 * m1 * sh2 * sh3 + two * ch1 * sh1 * m3,
            S::FOUR * ch1 * ch3 * sh1 * sh3 - two * ch2 * m1 * sh2 * m3,
        ],
        [
            two * ch1 * sh1 * (one - two * s2),
            -S::EIGHT * ch1 * ch2 * ch3 * sh1 * sh2 * sh3 + m1 * m3,
            -two * ch3 * sh3 + S::FOUR * sh1 * (ch3 * sh1 * sh3 + ch1 * ch2 * sh2 * m3),
        ],
        [two * ch2 * sh2, two * ch3 * (one - two * s2) * sh3, m2 * m3],
    ];
    (q, r)
}

// ------------------------------------------------------------------------------------------
// SVD
// ------------------------------------------------------------------------------------------

/// Columns `i` and `j` of `b` and `v` swapped, the new column `j` negated (so a rotation stays
/// a rotation).
#[inline(always)]
fn swap_neg<S: DecompFloat>(b: &mut Rows3<S>, v: &mut Rows3<S>, i: usize, j: usize) {
    for m in [b, v] {
        for row in m.iter_mut() {
            let x = row[i];
            row[i] = row[j];
            row[j] = -x;
        }
    }
}

/// `svd3` on rows.
pub(crate) fn svd3_rows<S: DecompFloat>(a: Rows3<S>) -> (Rows3<S>, [S; 3], Rows3<S>) {
    let ata = mul3_tn(&a, &a);
    let mut s = [
        ata[0][0], ata[1][0], ata[1][1], ata[2][0], ata[2][1], ata[2][2],
    ];
    let mut v = quat_rows(jacobi(&mut s));
    let mut b = mul3(&a, &v);
    // Columns of B by decreasing squared length (a NaN length compares false: no swap).
    let len2 = |b: &Rows3<S>, k: usize| b[0][k] * b[0][k] + b[1][k] * b[1][k] + b[2][k] * b[2][k];
    let mut rho = [len2(&b, 0), len2(&b, 1), len2(&b, 2)];
    if rho[0] < rho[1] {
        swap_neg(&mut b, &mut v, 0, 1);
        rho.swap(0, 1);
    }
    if rho[0] < rho[2] {
        swap_neg(&mut b, &mut v, 0, 2);
        rho.swap(0, 2);
    }
    if rho[1] < rho[2] {
        swap_neg(&mut b, &mut v, 1, 2);
    }
    let (u, r) = qr_rows(b);
    (u, [r[0][0], r[1][1], r[2][2]], v)
}

/// `svd2` on rows (Warp's closed form; see the module documentation).
pub(crate) fn svd2_rows<S: DecompFloat>(a: Rows2<S>) -> (Rows2<S>, [S; 2], Rows2<S>) {
    let [[a11, a12], [a21, a22]] = a;
    let (zero, one, two) = (S::ZERO, S::ONE, S::TWO);
    let p = a11 * a11 + a21 * a21;
    let r = a11 * a12 + a21 * a22;
    let q = a12 * a12 + a22 * a22;
    let trace = p + q;
    let diff = p - q;
    let disc = diff * diff + S::FOUR * r * r;
    if disc == zero {
        let s = (S::HALF * trace).d_sqrt();
        let id = [[one, zero], [zero, one]];
        return (id, [s, s], id);
    }
    let root = disc.d_sqrt();
    let l1 = (trace + root) * S::HALF;
    let l2 = (trace - root) * S::HALF;
    let inv_s1 = one / l1.d_sqrt();
    let s1 = one / inv_s1;
    // Rounding may leave l2 slightly negative for a rank-deficient matrix (Warp: NaN).
    let s2 = (if l2 < zero { zero } else { l2 }).d_sqrt();
    // The eigenvector of l1.
    let vy = diff - root + two * r;
    let vx = diff + root - two * r;
    let len2 = vx * vx + vy * vy;
    let (v11, v21) = if len2 == zero {
        (S::SQRT1_2, S::SQRT1_2)
    } else {
        let inv = one / len2.d_sqrt();
        (vx * inv, vy * inv)
    };
    let u11 = (a11 * v11 + a12 * v21) * inv_s1;
    let u21 = (a21 * v11 + a22 * v21) * inv_s1;
    let det = a11 * a22 - a12 * a21;
    let sign = if det < zero { -one } else { one };
    let u = [[u11, -u21 * sign], [u21, u11 * sign]];
    let v = [[v11, -v21], [v21, v11]];
    (u, [s1, s2], v)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rows_close(a: Rows3<f64>, b: Rows3<f64>, tol: f64) -> bool {
        (0..3).all(|i| (0..3).all(|j| (a[i][j] - b[i][j]).abs() <= tol))
    }

    #[test]
    fn svd3_reconstructs_with_rotations() {
        let a = DMat3::from_cols_array(&[0.3, -1.2, 2.0, 0.7, 0.1, -0.4, 1.5, 0.2, 0.9]);
        let (u, s, v) = svd3(a);
        let back = u * DMat3::from_diagonal(s) * v.transpose();
        assert!(rows_close(back.rows(), a.rows(), 1e-13), "{back} vs {a}");
        assert!((u.determinant() - 1.0).abs() < 1e-14);
        assert!((v.determinant() - 1.0).abs() < 1e-14);
        assert!(s.x >= s.y && s.y >= s.z.abs());
        assert_eq!(s.z < 0.0, a.determinant() < 0.0);
    }

    #[test]
    fn eig3_of_a_diagonal_matrix_is_exact() {
        let a = Mat3::from_diagonal(Vec3::new(3.0, -1.0, 2.0));
        let (q, d) = eig3(a);
        assert_eq!(q, Mat3::IDENTITY);
        assert_eq!(d, Vec3::new(3.0, -1.0, 2.0));
    }

    #[test]
    fn qr3_and_svd2() {
        let a = DMat3::from_cols_array(&[1.0, 2.0, 3.0, -1.0, 0.5, 4.0, 2.0, 2.0, -3.0]);
        let (q, r) = qr3(a);
        assert!(rows_close((q * r).rows(), a.rows(), 1e-14));
        let rr = r.rows();
        assert!(rr[1][0].abs() < 1e-15 && rr[2][0].abs() < 1e-15 && rr[2][1].abs() < 1e-15);
        let m = DMat2::from_cols_array(&[1.0, 2.0, -3.0, 0.5]);
        let (u, s, v) = svd2(m);
        let back = u * DMat2::from_diagonal(s) * v.transpose();
        let err = (back - m).to_cols_array();
        assert!(err.iter().all(|e| e.abs() < 1e-14), "{err:?}");
        assert!(s.x >= s.y && s.y >= 0.0);
    }

    #[test]
    fn nan_does_not_hang_and_stays_visible() {
        let mut a = Mat3::IDENTITY.to_cols_array();
        a[4] = f32::NAN;
        let (u, s, v) = svd3(Mat3::from_cols_array(&a));
        assert!(s.is_nan() && u.is_nan());
        assert!(v.is_finite());
    }
}

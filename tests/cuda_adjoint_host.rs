//! The CUDA C++ adjoint library (`warp-cuda/cuda/wp_adjoint.h`) against warp-core's CPU
//! adjoints (`warp_lang::__private::adjoint`) and `GradView`, on the host.
//!
//! Every adjoint function is called on both sides with the same inputs, the same nonzero
//! starting adjoints (so that accumulation, not assignment, is checked) and the same `adj_ret`,
//! for every operand-type combination the Rust side implements: operators and builtins on
//! `f32`/`f64`, the float vectors, matrices, quaternions, transforms, spatial vectors and
//! matrices and the non-square matrices (whose forward functions are compared too), the integer types (no-ops), all
//! 13 x 13 casts, `adj_zero`/`zero`/`zero_like`/`adj_accum`, and the array gradient helpers
//! `grad_accum`/`grad_take`/`grad_get` (1-D to 4-D, row- and column-major, in and out of
//! bounds, with and without a gradient array). Inputs mix special values (0, -0, NaN,
//! infinities, ties, zero vectors) with full-precision random ones; scalar operands also run
//! over every pair of special values.
//!
//! The C++ side is a program generated here (one function per signature, reading its cases
//! at run time so that nothing is constant-folded), built with `g++ -std=c++17 -O1
//! -ffp-contract=off` and run once; each case reports the resulting adjoints as hex bit
//! patterns. Comparison is bit for bit (any NaN matches any NaN, as NaN payloads depend on
//! operand order, which compilers may swap, and GPUs make their own). That includes the
//! adjoints that call `exp`, `log`, `sin`, `cos`, `tan`, `pow`, `sinh`, `cosh`, `tanh`, `exp2`,
//! `cbrt`, `erfinv` and `erfcinv`: both sides call the same libm (glibc) at run time (and the
//! same erf-family algorithm, transcribed), so they agree exactly on the host. (The scalar
//! builtins added after the H200 run below have not been run on a GPU yet.) Skipped, saying so, without
//! g++ or off x86_64 (the library reproduces glam's x86_64 layout and arithmetic).
//!
//! The same program runs the cases on a GPU, one thread per case (see the test's doc). On an
//! H200 (CUDA 13.0, `--fmad=false`), built by nvcc and by NVRTC, every case matched: bit for
//! bit except the `exp`/`sin`/`cos`/`tan`/`pow` adjoints (CUDA's own math functions: a few
//! dozen of their ~1,300 cases differed in the last bits, all within `LOOSE_ON_GPU`'s
//! tolerance).

use std::collections::HashMap;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::Command;

use warp_lang::__private::adjoint::{self as ad, Adjoint};
use warp_lang::__private::builtins as bi;
use warp_lang::__private::glam::{
    DMat2, DMat3, DMat4, DQuat, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, Mat2, Mat3, Mat4, Quat,
    UVec2, UVec3, UVec4, Vec2, Vec3, Vec4,
};
use warp_lang::__private::{zero_like, ArrayView, GradElement, GradView};
use warp_lang::{
    DMat23, DMat32, DMat34, DMat36, DMat63, DSpatialMatrix, DSpatialVector, DTransform, Fault,
    FaultKind, Mat23, Mat32, Mat34, Mat36, Mat63, SpatialMatrix, SpatialVector, Transform,
};

// ------------------------------------------------------------------------------------------
// Values as lanes of bit patterns (vectors x first, matrices column by column, quats x y z w)
// ------------------------------------------------------------------------------------------

trait Val: Copy {
    /// The C++ type (in namespace `wp` unless `bool`).
    const TY: &'static str;
    /// 32 or 64 for float lanes, 0 for integer and bool lanes.
    const FLOAT: u32;
    const LANES: usize;
    fn bits(&self) -> Vec<u64>;
    fn from_bits(w: &[u64]) -> Self;
}

macro_rules! float_val {
    ($($t:ident: $width:literal, $u:ty);*) => {$(
        impl Val for $t {
            const TY: &'static str = stringify!($t);
            const FLOAT: u32 = $width;
            const LANES: usize = 1;
            fn bits(&self) -> Vec<u64> { vec![self.to_bits() as u64] }
            fn from_bits(w: &[u64]) -> Self { $t::from_bits(w[0] as $u) }
        }
    )*};
}
float_val!(f32: 32, u32; f64: 64, u64);

macro_rules! int_val {
    ($($t:ty => $u:ty, $name:literal);*) => {$(
        impl Val for $t {
            const TY: &'static str = $name;
            const FLOAT: u32 = 0;
            const LANES: usize = 1;
            fn bits(&self) -> Vec<u64> { vec![*self as $u as u64] }
            fn from_bits(w: &[u64]) -> Self { w[0] as $u as $t }
        }
    )*};
}
int_val!(
    i8 => u8, "i8"; i16 => u16, "i16"; i32 => u32, "i32"; i64 => u64, "i64"; isize => usize, "i64";
    u8 => u8, "u8"; u16 => u16, "u16"; u32 => u32, "u32"; u64 => u64, "u64"; usize => usize, "u64"
);
impl Val for bool {
    const TY: &'static str = "bool";
    const FLOAT: u32 = 0;
    const LANES: usize = 1;
    fn bits(&self) -> Vec<u64> {
        vec![*self as u64]
    }
    fn from_bits(w: &[u64]) -> Self {
        w[0] != 0
    }
}

macro_rules! comp_val {
    ($($t:ident: $s:ident, $n:literal, $to:ident, $from:ident $(, $by_ref:tt)?);* $(;)?) => {$(
        impl Val for $t {
            const TY: &'static str = stringify!($t);
            const FLOAT: u32 = <$s as Val>::FLOAT;
            const LANES: usize = $n;
            fn bits(&self) -> Vec<u64> {
                self.$to().iter().flat_map(|x| x.bits()).collect()
            }
            fn from_bits(w: &[u64]) -> Self {
                let a: [$s; $n] = std::array::from_fn(|i| <$s as Val>::from_bits(&w[i..]));
                $t::$from($($by_ref)? a)
            }
        }
    )*};
}
comp_val!(
    Vec2: f32, 2, to_array, from_array; Vec3: f32, 3, to_array, from_array;
    Vec4: f32, 4, to_array, from_array; DVec2: f64, 2, to_array, from_array;
    DVec3: f64, 3, to_array, from_array; DVec4: f64, 4, to_array, from_array;
    IVec2: i32, 2, to_array, from_array; IVec3: i32, 3, to_array, from_array;
    IVec4: i32, 4, to_array, from_array; UVec2: u32, 2, to_array, from_array;
    UVec3: u32, 3, to_array, from_array; UVec4: u32, 4, to_array, from_array;
    Quat: f32, 4, to_array, from_array; DQuat: f64, 4, to_array, from_array;
    Mat2: f32, 4, to_cols_array, from_cols_array, &; Mat3: f32, 9, to_cols_array, from_cols_array, &;
    Mat4: f32, 16, to_cols_array, from_cols_array, &; DMat2: f64, 4, to_cols_array, from_cols_array, &;
    DMat3: f64, 9, to_cols_array, from_cols_array, &; DMat4: f64, 16, to_cols_array, from_cols_array, &;
    Transform: f32, 7, to_array, from_array; DTransform: f64, 7, to_array, from_array;
    SpatialVector: f32, 6, to_array, from_array; DSpatialVector: f64, 6, to_array, from_array;
);

// Spatial matrices: 36 lanes, row by row (the C++ vec_traits order).
macro_rules! spatial_mat_val {
    ($($t:ident: $s:ident),*) => {$(
        impl Val for $t {
            const TY: &'static str = stringify!($t);
            const FLOAT: u32 = <$s as Val>::FLOAT;
            const LANES: usize = 36;
            fn bits(&self) -> Vec<u64> {
                self.to_rows_array().iter().flatten().flat_map(|x| x.bits()).collect()
            }
            fn from_bits(w: &[u64]) -> Self {
                $t::from_rows_array(std::array::from_fn(|i| {
                    std::array::from_fn(|j| <$s as Val>::from_bits(&w[i * 6 + j..]))
                }))
            }
        }
    )*};
}
spatial_mat_val!(SpatialMatrix: f32, DSpatialMatrix: f64);

// Non-square matrices: R * C lanes, row by row (the C++ vec_traits order).
macro_rules! nonsquare_val {
    ($($t:ident: $s:ident, $r:literal, $c:literal);*) => {$(
        impl Val for $t {
            const TY: &'static str = stringify!($t);
            const FLOAT: u32 = <$s as Val>::FLOAT;
            const LANES: usize = $r * $c;
            fn bits(&self) -> Vec<u64> {
                self.to_rows_array().iter().flatten().flat_map(|x| x.bits()).collect()
            }
            fn from_bits(w: &[u64]) -> Self {
                $t::from_rows_array(std::array::from_fn(|i| {
                    std::array::from_fn(|j| <$s as Val>::from_bits(&w[i * $c + j..]))
                }))
            }
        }
    )*};
}
nonsquare_val!(
    Mat23: f32, 2, 3; Mat32: f32, 3, 2; Mat34: f32, 3, 4; Mat36: f32, 3, 6; Mat63: f32, 6, 3;
    DMat23: f64, 2, 3; DMat32: f64, 3, 2; DMat34: f64, 3, 4; DMat36: f64, 3, 6; DMat63: f64, 6, 3
);

fn cxx(ty: &str) -> String {
    if ty == "bool" {
        ty.into()
    } else {
        format!("wp::{ty}")
    }
}

/// One lane holding `x` (floats rounded to the lane's width, integers saturated).
fn lane_bits(float: u32, x: f64) -> u64 {
    match float {
        32 => (x as f32).to_bits() as u64,
        64 => x.to_bits(),
        _ => x as i64 as u64,
    }
}

fn splat<T: Val>(x: f64) -> T {
    T::from_bits(&vec![lane_bits(T::FLOAT, x); T::LANES])
}

// ------------------------------------------------------------------------------------------
// Inputs
// ------------------------------------------------------------------------------------------

const SPECIAL: [f64; 12] = [
    0.0,
    -0.0,
    1.0,
    -1.0,
    2.0,
    0.5,
    -2.5,
    3.0,
    f64::NAN,
    f64::INFINITY,
    f64::NEG_INFINITY,
    1e-3,
];

struct Gen(u64);
impl Gen {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    /// A full-precision float in [-4, 4) (so that evaluation order shows in the last bits).
    fn rand(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64 * 8.0 - 4.0
    }
    fn lane(&mut self, float: u32, special: bool) -> u64 {
        let r = self.next();
        if float == 0 {
            return match r % 3 {
                0 => (r >> 8) % 7,
                1 => ((r >> 8) % 2001).wrapping_sub(1000),
                _ => r >> 3,
            };
        }
        let x = if special {
            SPECIAL[(r >> 8) as usize % SPECIAL.len()]
        } else {
            self.rand()
        };
        lane_bits(float, x)
    }
    /// An input: one in 8 a splat of a special value (the zero vector, NaNs, ...), else lanes
    /// that are special 3 times in 8 and random otherwise.
    fn val<T: Val>(&mut self) -> T {
        let r = self.next();
        if r.is_multiple_of(8) {
            return splat(SPECIAL[(r >> 8) as usize % SPECIAL.len()]);
        }
        let w: Vec<u64> = (0..T::LANES)
            .map(|_| {
                let special = self.next() % 8 < 3;
                self.lane(T::FLOAT, special)
            })
            .collect();
        T::from_bits(&w)
    }
    /// A starting adjoint: random lanes, one in 16 a negative zero (which adding `+0`
    /// changes, so that an adjoint rule that adds a zero where the CPU adds nothing shows).
    fn adj<T: Val>(&mut self) -> T {
        let w: Vec<u64> = (0..T::LANES)
            .map(|_| match self.next() % 16 {
                0 => lane_bits(T::FLOAT, -0.0),
                _ => self.lane(T::FLOAT, false),
            })
            .collect();
        T::from_bits(&w)
    }
    /// An `adj_ret`: random lanes, one in 8 an input-like value (zeros, NaN, infinities).
    fn ret<T: Val>(&mut self) -> T {
        if self.next().is_multiple_of(8) {
            self.val()
        } else {
            self.adj()
        }
    }
}

fn same<A: Val, B: Val>(a: A) -> Option<B> {
    (A::TY == B::TY).then(|| B::from_bits(&a.bits()))
}

fn is_fscalar<T: Val>() -> bool {
    T::FLOAT != 0 && T::LANES == 1
}

// ------------------------------------------------------------------------------------------
// Cases: one C++ function per signature, one line per case
// ------------------------------------------------------------------------------------------

/// One expected result word: its bits and float width (0: integer or bool).
#[derive(Clone, Copy, Debug)]
struct Tok(u64, u32);

fn toks<T: Val>(v: &T) -> Vec<Tok> {
    v.bits().into_iter().map(|b| Tok(b, T::FLOAT)).collect()
}

/// The adjoints that call a transcendental function (`exp`, `sin`, `cos`, `tan`, `pow`,
/// `sinh`, `cosh`, `tanh`, `exp2`, `cbrt`, the erf family; `asin`/`acos` only call `sqrt`,
/// which is exact, but are listed as not yet run on a GPU). On the host both sides call glibc
/// (and, for `erfinv`/`erfcinv`, the same transcribed algorithm), and they match exactly; against a GPU (CUDA's libdevice,
/// documented to 1 to 4 ulp) they are compared within 8 ulps of `max(|want|, 8)`: the term
/// added is at most `|want| + |starting adjoint|` in size, and starting adjoints are below 4.
const LOOSE_ON_GPU: [&str; 21] = [
    "adj_quat_rpy",
    "adj_quat_from_euler",
    "adj_quat_to_euler",
    "adj_quat_from_axis_angle",
    "adj_quat_slerp",
    "adj_exp",
    "adj_sin",
    "adj_cos",
    "adj_tan",
    "adj_pow",
    "adj_sinh",
    "adj_cosh",
    "adj_tanh",
    "adj_exp2",
    "adj_cbrt",
    "adj_erf",
    "adj_erfc",
    "adj_erfinv",
    "adj_erfcinv",
    "adj_asin",
    "adj_acos",
];

/// Adjoints whose GPU results amplify the forward function's error: `adj_erfinv`/`adj_erfcinv`
/// multiply by `exp(r²)` with `r` the inverse error function's value, whose relative error
/// becomes `2r²` times larger there (about 11 at `erfcinv(1e-3)`, 24 at `1e-6`). CUDA documents
/// `erfinvf` within 2 ulp and `erfcinvf` within 4: so 128 ulp of the result's binade for these
/// (measured on an H200: 39 ulp at `erfcinv(1e-3)` in f32), where 8 suffice elsewhere.
const ILL_CONDITIONED_ON_GPU: [&str; 2] = ["adj_erfinv", "adj_erfcinv"];

/// The adjoints compared within `LOOSE_ON_GPU`'s tolerance on the host too: Rust's `f32::cbrt`
/// and `f64::cbrt` no longer call glibc but the standard library's own (correctly rounded)
/// implementation, while C++'s `cbrt` is glibc's (within 1 ulp), so `cbrt(x)` itself may differ
/// in the last bit between the two sides (the forward comparison in tests/cuda_host_cpp.rs
/// allows 2 ulp for the libm functions for this kind of reason).
const LOOSE_ON_HOST: [&str; 1] = ["adj_cbrt"];

/// Same bits (any NaN matches any NaN: payloads depend on operand order, which compilers may
/// swap), or within `ulps` units of the result's binade (the GPU tolerances above) when
/// `ulps > 0`.
fn tok_matches(want: Tok, got: &str, ulps: f64) -> bool {
    let Ok(g) = u64::from_str_radix(got, 16) else {
        return false;
    };
    macro_rules! float {
        ($t:ident, $u:ty, $exp_mask:expr) => {{
            let (w, g) = ($t::from_bits(want.0 as $u), $t::from_bits(g as $u));
            if w.is_nan() || g.is_nan() {
                return w.is_nan() && g.is_nan();
            }
            if ulps > 0.0 && w.is_finite() && g.is_finite() {
                let scale = $t::from_bits(w.abs().max(8.0).to_bits() & $exp_mask);
                return (w - g).abs() <= ulps as $t * scale * $t::EPSILON;
            }
            w.to_bits() == g.to_bits()
        }};
    }
    match want.1 {
        32 => float!(f32, u32, 0x7f80_0000),
        64 => float!(f64, u64, 0x7ff0_0000_0000_0000),
        _ => want.0 == g,
    }
}

struct Suite {
    g: Gen,
    /// Random cases per signature.
    n: usize,
    /// (name, C++ body) per signature.
    ops: Vec<(String, String)>,
    by_body: HashMap<String, usize>,
    text: String,
    /// (signature, case line, expected words).
    cases: Vec<(usize, String, Vec<Tok>)>,
}

impl Suite {
    fn op(&mut self, name: String, body: String) -> usize {
        if let Some(&k) = self.by_body.get(&body) {
            return k;
        }
        self.ops.push((name, body.clone()));
        self.by_body.insert(body, self.ops.len() - 1);
        self.ops.len() - 1
    }

    /// `call` with `$` replaced by the value arguments, the adjoints and `adj_ret`; prints
    /// the adjoints after the call.
    fn sig(&mut self, call: &str, vals: &[&str], adjs: &[&str], ret: Option<&str>) -> usize {
        let mut body = String::new();
        let mut args = Vec::new();
        let decls = vals
            .iter()
            .map(|t| ('v', t))
            .chain(adjs.iter().map(|t| ('a', t)));
        let mut counts = [0, 0];
        for (p, t) in decls {
            let i = &mut counts[(p == 'a') as usize];
            let _ = writeln!(body, "  {} {p}{i}; rd(r, {p}{i});", cxx(t));
            args.push(format!("{p}{i}"));
            *i += 1;
        }
        if let Some(t) = ret {
            let _ = writeln!(body, "  {} g; rd(r, g);", cxx(t));
            args.push("g".into());
        }
        let _ = writeln!(body, "  {};", call.replace('$', &args.join(", ")));
        for i in 0..adjs.len() {
            let _ = writeln!(body, "  wr(r, a{i});");
        }
        let name = format!(
            "{} ({}) [{}] -> {}",
            call.replace("($)", ""),
            vals.join(", "),
            adjs.join(", "),
            ret.unwrap_or("-")
        );
        self.op(name, body)
    }

    fn case(&mut self, op: usize, words: &[u64], want: Vec<Tok>) {
        let mut line = format!("{op:x} {:x}", words.len());
        for w in words {
            let _ = write!(line, " {w:x}");
        }
        self.text.push_str(&line);
        self.text.push('\n');
        self.cases.push((op, line, want));
    }

    fn inputs1<A: Val>(&mut self) -> Vec<A> {
        let mut v: Vec<A> = Vec::new();
        if is_fscalar::<A>() {
            v.extend(SPECIAL.iter().map(|&x| splat::<A>(x)));
        }
        v.extend((0..self.n).map(|_| self.g.val::<A>()));
        v
    }

    fn inputs2<A: Val, B: Val>(&mut self) -> Vec<(A, B)> {
        let mut v = Vec::new();
        if is_fscalar::<A>() && is_fscalar::<B>() {
            for &x in &SPECIAL {
                for &y in &SPECIAL {
                    v.push((splat::<A>(x), splat::<B>(y)));
                }
            }
        }
        for k in 0..self.n {
            let a = self.g.val::<A>();
            let b = match same::<A, B>(a) {
                Some(b) if k % 8 == 7 => b, // ties in every lane
                _ => self.g.val::<B>(),
            };
            v.push((a, b));
        }
        v
    }

    fn inputs3<A: Val, B: Val, C: Val>(&mut self) -> Vec<(A, B, C)> {
        let mut v = Vec::new();
        if is_fscalar::<A>() && is_fscalar::<B>() && is_fscalar::<C>() {
            let few = &SPECIAL[..8];
            for &x in few.iter().chain(&[f64::NAN]) {
                for &y in few {
                    for &z in few {
                        v.push((splat::<A>(x), splat::<B>(y), splat::<C>(z)));
                    }
                }
            }
        }
        for k in 0..self.n {
            let a = self.g.val::<A>();
            let b = match same::<A, B>(a) {
                Some(b) if k % 8 == 5 => b,
                _ => self.g.val::<B>(),
            };
            let c = match same::<A, C>(a) {
                Some(c) if k % 8 == 6 => c,
                _ => self.g.val::<C>(),
            };
            v.push((a, b, c));
        }
        v
    }
}

fn call(name: &str) -> String {
    format!("wp::{name}($)")
}

/// `adj_<name>(a, adj_a, adj_ret)`.
fn un<A: Val, R: Val>(s: &mut Suite, name: &str, f: fn(A, &mut A, R)) {
    let op = s.sig(&call(name), &[A::TY], &[A::TY], Some(R::TY));
    for a in s.inputs1::<A>() {
        let (mut aa, g) = (s.g.adj::<A>(), s.g.ret::<R>());
        let words = [a.bits(), aa.bits(), g.bits()].concat();
        f(a, &mut aa, g);
        s.case(op, &words, toks(&aa));
    }
}

/// `adj_<name>(a, adj_a, adj_ret)` over `inputs` (and the usual starting adjoints and
/// `adj_ret`s).
fn un_over<A: Val, R: Val>(s: &mut Suite, name: &str, f: fn(A, &mut A, R), inputs: &[A]) {
    let op = s.sig(&call(name), &[A::TY], &[A::TY], Some(R::TY));
    for &a in inputs {
        let (mut aa, g) = (s.g.adj::<A>(), s.g.ret::<R>());
        let words = [a.bits(), aa.bits(), g.bits()].concat();
        f(a, &mut aa, g);
        s.case(op, &words, toks(&aa));
    }
}

/// Float vectors or quaternions of `T` whose squared norm overflows or underflows (the
/// rescaled norms' slow path): random lanes at magnitudes `2^e` from the smallest subnormal
/// to the top binade, one lane dominating the others, and huge or tiny lanes with zeros,
/// infinities and NaN.
fn extreme_vals<T: Val>(g: &mut Gen) -> Vec<T> {
    let f32_lanes = T::FLOAT == 32;
    let exps: &[i32] = if f32_lanes {
        &[-149, -135, -127, -126, -105, -70, 64, 100, 127]
    } else {
        &[-1074, -1050, -1022, -1005, -600, 520, 1000, 1023]
    };
    // 2^e without intermediate over- or underflow.
    let p2 = |e: i32| 2f64.powi(e / 2) * 2f64.powi(e - e / 2);
    let max = if f32_lanes { f32::MAX as f64 } else { f64::MAX };
    let mut lanes: Vec<Vec<f64>> = Vec::new();
    for &e in exps {
        for _ in 0..3 {
            // [-1, 1) times 2^e: finite even in the top binade.
            lanes.push(
                (0..T::LANES)
                    .map(|_| ((g.next() >> 11) as f64 / (1u64 << 52) as f64 - 1.0) * p2(e))
                    .collect(),
            );
        }
        lanes.push(
            (0..T::LANES)
                .map(|i| p2(e) * [1.0, -p2(-30), p2(-60), 0.5][i % 4])
                .collect(),
        );
    }
    for l in [
        [max, max, max, max],
        [max, -max * 0.5, 0.0, 1.0],
        [p2(-120), -0.0, f64::NAN, 0.0],
        [max, f64::INFINITY, 0.0, 0.0],
        [p2(-140), f64::NEG_INFINITY, 1.0, 0.0],
        [-p2(-149), p2(-149), -p2(-149), p2(-149)],
        [0.0, -0.0, 0.0, -0.0],
    ] {
        lanes.push(l[..T::LANES].to_vec());
    }
    lanes
        .iter()
        .map(|l| {
            T::from_bits(
                &l.iter()
                    .map(|&x| lane_bits(T::FLOAT, x))
                    .collect::<Vec<_>>(),
            )
        })
        .collect()
}

/// `adj_length` and `adj_normalize` on their rescaled slow path.
fn extreme_norms(s: &mut Suite) {
    macro_rules! each {
        ($($v:ident: $s:ident),*) => {$(
            let xs = extreme_vals::<$v>(&mut s.g);
            un_over::<$v, $s>(s, "adj_length", ad::adj_length, &xs);
            un_over::<$v, $v>(s, "adj_normalize", ad::adj_normalize, &xs);
        )*};
    }
    each!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64, Quat: f32, DQuat: f64);
}

/// `adj_<name>(a, b, adj_a, adj_b, adj_ret)`.
fn bin<A: Val, B: Val, R: Val>(s: &mut Suite, name: &str, f: fn(A, B, &mut A, &mut B, R)) {
    let op = s.sig(&call(name), &[A::TY, B::TY], &[A::TY, B::TY], Some(R::TY));
    for (a, b) in s.inputs2::<A, B>() {
        let (mut aa, mut ab, g) = (s.g.adj::<A>(), s.g.adj::<B>(), s.g.ret::<R>());
        let words = [a.bits(), b.bits(), aa.bits(), ab.bits(), g.bits()].concat();
        f(a, b, &mut aa, &mut ab, g);
        s.case(op, &words, [toks(&aa), toks(&ab)].concat());
    }
}

type Tri<A, B, C, R> = fn(A, B, C, &mut A, &mut B, &mut C, R);

type Euler<A, R> = fn(A, i32, i32, i32, &mut A, &mut i32, &mut i32, &mut i32, R);

/// `adj_<name>(a, i, j, k, adj_a, adj_i, adj_j, adj_k, adj_ret)` of `quat_from_euler` and
/// `quat_to_euler`, the axis indices taken in turn from every Tait-Bryan and some proper
/// sequences, and some no valid sequence (repeated, out of range: Warp's branches still give
/// both sides the same steps).
fn euler<A: Val, R: Val>(s: &mut Suite, name: &str, f: Euler<A, R>) {
    let tys = [A::TY, i32::TY, i32::TY, i32::TY];
    let op = s.sig(&call(name), &tys, &tys, Some(R::TY));
    let seqs: [[i32; 3]; 11] = [
        [0, 1, 2],
        [0, 2, 1],
        [1, 0, 2],
        [1, 2, 0],
        [2, 0, 1],
        [2, 1, 0],
        [0, 1, 0],
        [1, 2, 1],
        [2, 0, 2],
        [0, 0, 1],
        [5, -1, 2],
    ];
    for (n, a) in s.inputs1::<A>().into_iter().enumerate() {
        let [i, j, k] = seqs[n % seqs.len()];
        let (mut aa, g) = (s.g.adj::<A>(), s.g.ret::<R>());
        let (mut ai, mut aj, mut ak) = (0i32, 0i32, 0i32);
        let words = [
            a.bits(),
            i.bits(),
            j.bits(),
            k.bits(),
            aa.bits(),
            ai.bits(),
            aj.bits(),
            ak.bits(),
            g.bits(),
        ];
        f(a, i, j, k, &mut aa, &mut ai, &mut aj, &mut ak, g);
        let got = [toks(&aa), toks(&ai), toks(&aj), toks(&ak)].concat();
        s.case(op, &words.concat(), got);
    }
}

/// `adj_<name>(a, b, c, adj_a, adj_b, adj_c, adj_ret)`.
fn tri<A: Val, B: Val, C: Val, R: Val>(s: &mut Suite, name: &str, f: Tri<A, B, C, R>) {
    let tys = [A::TY, B::TY, C::TY];
    let op = s.sig(&call(name), &tys, &tys, Some(R::TY));
    for (a, b, c) in s.inputs3::<A, B, C>() {
        let (mut aa, mut ab, mut ac) = (s.g.adj::<A>(), s.g.adj::<B>(), s.g.adj::<C>());
        let g = s.g.ret::<R>();
        let words = [
            a.bits(),
            b.bits(),
            c.bits(),
            aa.bits(),
            ab.bits(),
            ac.bits(),
            g.bits(),
        ];
        f(a, b, c, &mut aa, &mut ab, &mut ac, g);
        s.case(
            op,
            &words.concat(),
            [toks(&aa), toks(&ab), toks(&ac)].concat(),
        );
    }
}

/// `adj_cast(adj_from, adj_to)`.
fn cast<F: Val, T: Val>(s: &mut Suite, f: fn(&mut F, T)) {
    let op = s.sig(&call("adj_cast"), &[], &[F::TY], Some(T::TY));
    let extreme = [1e300, -1e-300, f64::MAX, 3.4e38, 1e-45, 0.1, -0.0, f64::NAN];
    let mut tos: Vec<T> = extreme.iter().map(|&x| splat::<T>(x)).collect();
    tos.extend((0..8).map(|_| s.g.ret::<T>()));
    for to in tos {
        let mut a = s.g.adj::<F>();
        let words = [a.bits(), to.bits()].concat();
        f(&mut a, to);
        s.case(op, &words, toks(&a));
    }
}

/// `adj_zero<T>()`, `zero<T>()`, `zero_like(x)` and `adj_accum(a, v)`.
fn zero_accum<T: Val + Adjoint>(s: &mut Suite) {
    let ty = cxx(T::TY);
    for c in [
        format!("a0 = wp::adj_zero<{ty}>()"),
        format!("a0 = wp::zero<{ty}>()"),
        "a0 = wp::zero_like(a0)".into(),
    ] {
        let op = s.sig(&c, &[], &[T::TY], None);
        let start = s.g.adj::<T>();
        let (z1, z2) = (ad::zero::<T>(), zero_like(&start));
        assert_eq!(z1.bits(), z2.bits());
        s.case(op, &start.bits(), toks(&z1));
    }
    let op = s.sig(&call("adj_accum"), &[], &[T::TY], Some(T::TY));
    for _ in 0..s.n {
        let (mut a, v) = (s.g.adj::<T>(), s.g.ret::<T>());
        let words = [a.bits(), v.bits()].concat();
        a.adj_accum(v);
        s.case(op, &words, toks(&a));
    }
}

// ------------------------------------------------------------------------------------------
// The operand-type combinations of warp-core/src/adjoint
// ------------------------------------------------------------------------------------------

/// `+ - * / %` for each `A op B => R`.
macro_rules! arith {
    ($s:expr; $($a:ty, $b:ty => $r:ty);* $(;)?) => {$(
        bin::<$a, $b, $r>($s, "adj_add", ad::adj_add);
        bin::<$a, $b, $r>($s, "adj_sub", ad::adj_sub);
        bin::<$a, $b, $r>($s, "adj_mul", ad::adj_mul);
        bin::<$a, $b, $r>($s, "adj_div", ad::adj_div);
        bin::<$a, $b, $r>($s, "adj_rem", ad::adj_rem);
    )*};
}

/// min, max, clamp.
macro_rules! minmax {
    ($s:expr; $($t:ty),*) => {$(
        bin::<$t, $t, $t>($s, "adj_min", ad::adj_min);
        bin::<$t, $t, $t>($s, "adj_max", ad::adj_max);
        tri::<$t, $t, $t, $t>($s, "adj_clamp", ad::adj_clamp);
    )*};
}

fn float_scalars(s: &mut Suite) {
    macro_rules! each {
        ($($t:ident),*) => {$(
            arith!(s; $t, $t => $t);
            un::<$t, $t>(s, "adj_neg", ad::adj_neg);
            minmax!(s; $t);
            un::<$t, $t>(s, "adj_abs", ad::adj_abs);
            un::<$t, $t>(s, "adj_sign", ad::adj_sign);
            un::<$t, $t>(s, "adj_floor", ad::adj_floor);
            un::<$t, $t>(s, "adj_ceil", ad::adj_ceil);
            un::<$t, $t>(s, "adj_sqrt", ad::adj_sqrt);
            un::<$t, $t>(s, "adj_exp", ad::adj_exp);
            un::<$t, $t>(s, "adj_log", ad::adj_log);
            un::<$t, $t>(s, "adj_sin", ad::adj_sin);
            un::<$t, $t>(s, "adj_cos", ad::adj_cos);
            un::<$t, $t>(s, "adj_tan", ad::adj_tan);
            bin::<$t, $t, $t>(s, "adj_atan2", ad::adj_atan2);
            bin::<$t, $t, $t>(s, "adj_pow", ad::adj_pow);
            tri::<$t, $t, $t, $t>(s, "adj_lerp", ad::adj_lerp);
            un::<$t, $t>(s, "adj_asin", ad::adj_asin);
            un::<$t, $t>(s, "adj_acos", ad::adj_acos);
            un::<$t, $t>(s, "adj_atan", ad::adj_atan);
            un::<$t, $t>(s, "adj_sinh", ad::adj_sinh);
            un::<$t, $t>(s, "adj_cosh", ad::adj_cosh);
            un::<$t, $t>(s, "adj_tanh", ad::adj_tanh);
            un::<$t, $t>(s, "adj_exp2", ad::adj_exp2);
            un::<$t, $t>(s, "adj_log2", ad::adj_log2);
            un::<$t, $t>(s, "adj_log10", ad::adj_log10);
            un::<$t, $t>(s, "adj_cbrt", ad::adj_cbrt);
            un::<$t, $t>(s, "adj_erf", ad::adj_erf);
            un::<$t, $t>(s, "adj_erfc", ad::adj_erfc);
            un::<$t, $t>(s, "adj_erfinv", ad::adj_erfinv);
            un::<$t, $t>(s, "adj_erfcinv", ad::adj_erfcinv);
            un::<$t, $t>(s, "adj_round", ad::adj_round);
            un::<$t, $t>(s, "adj_rint", ad::adj_rint);
            un::<$t, $t>(s, "adj_trunc", ad::adj_trunc);
            un::<$t, $t>(s, "adj_frac", ad::adj_frac);
            un::<$t, $t>(s, "adj_step", ad::adj_step);
            un::<$t, $t>(s, "adj_degrees", ad::adj_degrees);
            un::<$t, $t>(s, "adj_radians", ad::adj_radians);
            tri::<$t, $t, $t, $t>(s, "adj_smoothstep", ad::adj_smoothstep);
        )*};
    }
    each!(f32, f64);
}

fn float_vectors(s: &mut Suite) {
    macro_rules! each {
        ($($v:ident: $s:ident),*) => {$(
            arith!(s; $v, $v => $v; $v, $s => $v; $s, $v => $v);
            un::<$v, $v>(s, "adj_neg", ad::adj_neg);
            minmax!(s; $v);
            un::<$v, $v>(s, "adj_abs", ad::adj_abs);
            un::<$v, $v>(s, "adj_sign", ad::adj_sign);
            tri::<$v, $v, $s, $v>(s, "adj_lerp", ad::adj_lerp);
            bin::<$v, $v, $s>(s, "adj_dot", ad::adj_dot);
            un::<$v, $s>(s, "adj_length", ad::adj_length);
            un::<$v, $v>(s, "adj_normalize", ad::adj_normalize);
        )*};
    }
    each!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64);
    bin::<Vec3, Vec3, Vec3>(s, "adj_cross", ad::adj_cross);
    bin::<DVec3, DVec3, DVec3>(s, "adj_cross", ad::adj_cross);
}

fn matrices_and_quats(s: &mut Suite) {
    macro_rules! mats {
        ($($m:ident: $v:ident, $s:ident),*) => {$(
            bin::<$m, $m, $m>(s, "adj_add", ad::adj_add);
            bin::<$m, $m, $m>(s, "adj_sub", ad::adj_sub);
            bin::<$m, $m, $m>(s, "adj_mul", ad::adj_mul);
            bin::<$m, $v, $v>(s, "adj_mul", ad::adj_mul);
            bin::<$m, $s, $m>(s, "adj_mul", ad::adj_mul);
            bin::<$m, $s, $m>(s, "adj_div", ad::adj_div);
            bin::<$s, $m, $m>(s, "adj_mul", ad::adj_mul);
            bin::<$s, $m, $m>(s, "adj_div", ad::adj_div);
            un::<$m, $m>(s, "adj_neg", ad::adj_neg);
            // lerp lane by lane (wp_scalar.h), t the second value.
            fwd2::<$m, $s, $m>(s, "wp::lerp(v0, -v0, v1)", |a, t| bi::lerp(a, -a, t));
            tri::<$m, $m, $s, $m>(s, "adj_lerp", ad::adj_lerp);
        )*};
    }
    mats!(Mat2: Vec2, f32, Mat3: Vec3, f32, Mat4: Vec4, f32);
    mats!(DMat2: DVec2, f64, DMat3: DVec3, f64, DMat4: DVec4, f64);
    macro_rules! quats {
        ($($q:ident: $v:ident, $s:ident),*) => {$(
            bin::<$q, $q, $q>(s, "adj_add", ad::adj_add);
            bin::<$q, $q, $q>(s, "adj_sub", ad::adj_sub);
            bin::<$q, $q, $q>(s, "adj_mul", ad::adj_mul);
            bin::<$q, $v, $v>(s, "adj_mul", ad::adj_mul);
            bin::<$q, $s, $q>(s, "adj_mul", ad::adj_mul);
            bin::<$q, $s, $q>(s, "adj_div", ad::adj_div);
            un::<$q, $q>(s, "adj_neg", ad::adj_neg);
            fwd2::<$q, $s, $q>(s, "wp::lerp(v0, -v0, v1)", |a, t| bi::lerp(a, -a, t));
            tri::<$q, $q, $s, $q>(s, "adj_lerp", ad::adj_lerp);
        )*};
    }
    quats!(Quat: Vec3, f32, DQuat: DVec3, f64);
}

/// The vector, matrix and quaternion builtins of wp_linalg.h.
fn linalg(s: &mut Suite) {
    macro_rules! vecs {
        ($($v:ident: $m:ident, $s:ident),*) => {$(
            un::<$v, $s>(s, "adj_length_sq", ad::adj_length_sq);
            bin::<$v, $v, $m>(s, "adj_outer", ad::adj_outer);
            un::<$v, $m>(s, "adj_diag", ad::adj_diag);
            bin::<$v, $v, $v>(s, "adj_cw_mul", ad::adj_cw_mul);
            bin::<$v, $v, $v>(s, "adj_cw_div", ad::adj_cw_div);
            bin::<$m, $m, $m>(s, "adj_cw_mul", ad::adj_cw_mul);
            bin::<$m, $m, $m>(s, "adj_cw_div", ad::adj_cw_div);
            un::<$m, $m>(s, "adj_transpose", ad::adj_transpose);
            un::<$m, $s>(s, "adj_determinant", ad::adj_determinant);
            un::<$m, $m>(s, "adj_inverse", ad::adj_inverse);
            un::<$m, $s>(s, "adj_trace", ad::adj_trace);
            bin::<$m, $m, $s>(s, "adj_ddot", ad::adj_ddot);
        )*};
    }
    vecs!(Vec2: Mat2, f32, Vec3: Mat3, f32, Vec4: Mat4, f32);
    vecs!(DVec2: DMat2, f64, DVec3: DMat3, f64, DVec4: DMat4, f64);
    un::<Vec3, Mat3>(s, "adj_skew", ad::adj_skew);
    un::<DVec3, DMat3>(s, "adj_skew", ad::adj_skew);
    un::<IVec3, i32>(s, "adj_length_sq", ad::adj_length_sq);
    un::<UVec2, u32>(s, "adj_length_sq", ad::adj_length_sq);
    macro_rules! quats {
        ($($q:ident: $v:ident, $m:ident, $s:ident),*) => {$(
            un::<$q, $s>(s, "adj_length_sq", ad::adj_length_sq);
            bin::<$q, $q, $s>(s, "adj_dot", ad::adj_dot);
            un::<$q, $s>(s, "adj_length", ad::adj_length);
            un::<$q, $q>(s, "adj_normalize", ad::adj_normalize);
            un::<$q, $q>(s, "adj_inverse", ad::adj_inverse);
            un::<$q, $q>(s, "adj_quat_inverse", ad::adj_quat_inverse::<$q>);
            bin::<$v, $s, $q>(s, "adj_quat_from_axis_angle", ad::adj_quat_from_axis_angle::<$q>);
            bin::<$q, $v, $v>(s, "adj_quat_rotate", ad::adj_quat_rotate::<$q>);
            bin::<$q, $v, $v>(s, "adj_quat_rotate_inv", ad::adj_quat_rotate_inv::<$q>);
            un::<$q, $m>(s, "adj_quat_to_matrix", ad::adj_quat_to_matrix::<$q>);
            un::<$m, $q>(s, "adj_quat_from_matrix", ad::adj_quat_from_matrix::<$q>);
            tri::<$q, $q, $s, $q>(s, "adj_quat_slerp", ad::adj_quat_slerp::<$q>);
            euler::<$v, $q>(s, "adj_quat_from_euler", ad::adj_quat_from_euler::<$v>);
            euler::<$q, $v>(s, "adj_quat_to_euler", ad::adj_quat_to_euler::<$q>);
        )*};
    }
    quats!(Quat: Vec3, Mat3, f32, DQuat: DVec3, DMat3, f64);
}

/// Perlin noise (wp_rand.h's `perlin` with a gradient, wp_adjoint.h's accumulation): every
/// dimension, plain and periodic (periods from the integer lanes: 0, negative, huge).
fn noise(s: &mut Suite) {
    bin::<u32, f32, f32>(s, "adj_noise", ad::adj_noise::<f32>);
    bin::<u32, Vec2, f32>(s, "adj_noise", ad::adj_noise::<Vec2>);
    bin::<u32, Vec3, f32>(s, "adj_noise", ad::adj_noise::<Vec3>);
    bin::<u32, Vec4, f32>(s, "adj_noise", ad::adj_noise::<Vec4>);
    tri::<u32, f32, i32, f32>(s, "adj_pnoise", ad::adj_pnoise::<f32>);
    tri::<u32, Vec2, IVec2, f32>(s, "adj_pnoise", ad::adj_pnoise::<Vec2>);
    tri::<u32, Vec3, IVec3, f32>(s, "adj_pnoise", ad::adj_pnoise::<Vec3>);
    tri::<u32, Vec4, IVec4, f32>(s, "adj_pnoise", ad::adj_pnoise::<Vec4>);
}

/// The rigid-transform operators and builtins (wp_core.h, wp_transform.h).
fn transforms(s: &mut Suite) {
    macro_rules! xforms {
        ($($x:ident: $v:ident, $q:ident, $m:ident, $s:ident),*) => {$(
            bin::<$x, $x, $x>(s, "adj_add", ad::adj_add);
            bin::<$x, $x, $x>(s, "adj_sub", ad::adj_sub);
            bin::<$x, $x, $x>(s, "adj_mul", ad::adj_mul);
            bin::<$x, $s, $x>(s, "adj_mul", ad::adj_mul);
            bin::<$s, $x, $x>(s, "adj_mul", ad::adj_mul);
            un::<$x, $x>(s, "adj_neg", ad::adj_neg);
            tri::<$x, $x, $s, $x>(s, "adj_lerp", ad::adj_lerp);
            un::<$x, $x>(s, "adj_inverse", ad::adj_inverse);
            bin::<$v, $q, $x>(s, "adj_transformation", ad::adj_transformation::<$v>);
            un::<$x, $v>(s, "adj_transform_get_translation", ad::adj_transform_get_translation::<$x>);
            un::<$x, $q>(s, "adj_transform_get_rotation", ad::adj_transform_get_rotation::<$x>);
            bin::<$x, $x, $x>(s, "adj_transform_multiply", ad::adj_transform_multiply::<$x>);
            bin::<$x, $v, $v>(s, "adj_transform_point", ad::adj_transform_point::<$x>);
            bin::<$x, $v, $v>(s, "adj_transform_vector", ad::adj_transform_vector::<$x>);
            un::<$x, $x>(s, "adj_transform_inverse", ad::adj_transform_inverse::<$x>);
            un::<$x, $m>(s, "adj_transform_to_matrix", ad::adj_transform_to_matrix::<$x>);
            un::<$m, $x>(s, "adj_transform_from_matrix", ad::adj_transform_from_matrix::<$m>);
            bin::<$m, $v, $v>(s, "adj_transform_point", ad::adj_transform_point::<$m>);
            bin::<$m, $v, $v>(s, "adj_transform_vector", ad::adj_transform_vector::<$m>);
        )*};
    }
    xforms!(Transform: Vec3, Quat, Mat4, f32, DTransform: DVec3, DQuat, DMat4, f64);
}

/// `a0 = <expr of v0, v1>`: a forward function of two values, compared bit for bit (the
/// starting `a0` is overwritten).
fn fwd2<A: Val, B: Val, R: Val>(s: &mut Suite, expr: &str, f: fn(A, B) -> R) {
    let op = s.sig(&format!("a0 = {expr}"), &[A::TY, B::TY], &[R::TY], None);
    for (a, b) in s.inputs2::<A, B>() {
        let r0 = s.g.adj::<R>();
        let words = [a.bits(), b.bits(), r0.bits()].concat();
        s.case(op, &words, toks(&f(a, b)));
    }
}

/// The non-square matrices (wp_matrix.h's operators and builtins, wp_adjoint_matrix.h's
/// adjoints), forward and adjoint, with glam's square and the spatial matrices in products.
fn nonsquare(s: &mut Suite) {
    macro_rules! each {
        ($($m23:ident, $m32:ident, $m34:ident, $m36:ident, $m63:ident, $m2:ident, $m3:ident,
           $sm:ident, $v2:ident, $v3:ident, $v4:ident, $sv:ident, $s:ident);*) => {$(
            // Forward.
            fwd2::<$m23, $m23, $m23>(s, "v0 + v1", |a, b| a + b);
            fwd2::<$m23, $m23, $m23>(s, "v0 - v1", |a, b| a - b);
            fwd2::<$m23, $s, $m23>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$s, $m23, $m23>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m23, $s, $m23>(s, "v0 / v1", |a, b| a / b);
            fwd2::<$m23, $v3, $v2>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m34, $v4, $v3>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m63, $v3, $sv>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m23, $m32, $m2>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m23, $m3, $m23>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m3, $m32, $m32>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m63, $m36, $sm>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m36, $m63, $m3>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$m23, $m32, $m23>(s, "wp::transpose(v1) - v0", |a, b| bi::transpose(b) - a);
            fwd2::<$v3, $v2, $m32>(s, "wp::outer(v0, v1)", bi::outer);
            fwd2::<$sv, $v3, $m63>(s, "wp::outer(v0, v1)", bi::outer);
            fwd2::<$m23, $m23, $s>(s, "wp::ddot(v0, v1)", bi::ddot);
            fwd2::<$m23, $m23, bool>(s, "v0 == v1 && !(v0 != v1)", |a, b| a == b);
            // Adjoints.
            bin::<$m23, $m23, $m23>(s, "adj_add", ad::adj_add);
            bin::<$m23, $m23, $m23>(s, "adj_sub", ad::adj_sub);
            bin::<$m23, $s, $m23>(s, "adj_mul", ad::adj_mul);
            bin::<$s, $m23, $m23>(s, "adj_mul", ad::adj_mul);
            bin::<$m23, $s, $m23>(s, "adj_div", ad::adj_div);
            un::<$m23, $m23>(s, "adj_neg", ad::adj_neg);
            bin::<$m23, $v3, $v2>(s, "adj_mul", ad::adj_mul);
            bin::<$m63, $v3, $sv>(s, "adj_mul", ad::adj_mul);
            bin::<$m23, $m32, $m2>(s, "adj_mul", ad::adj_mul);
            bin::<$m23, $m3, $m23>(s, "adj_mul", ad::adj_mul);
            bin::<$m3, $m32, $m32>(s, "adj_mul", ad::adj_mul);
            bin::<$m63, $m36, $sm>(s, "adj_mul", ad::adj_mul);
            un::<$m23, $m32>(s, "adj_transpose", ad::adj_transpose);
            bin::<$v3, $v2, $m32>(s, "adj_outer", ad::adj_outer);
            bin::<$sv, $v3, $m63>(s, "adj_outer", ad::adj_outer);
            bin::<$m23, $m23, $s>(s, "adj_ddot", ad::adj_ddot);
            zero_accum::<$m23>(s);
            zero_accum::<$m63>(s);
            grad_cases::<$m23>(s);
        )*};
    }
    each!(
        Mat23, Mat32, Mat34, Mat36, Mat63, Mat2, Mat3, SpatialMatrix, Vec2, Vec3, Vec4,
        SpatialVector, f32;
        DMat23, DMat32, DMat34, DMat36, DMat63, DMat2, DMat3, DSpatialMatrix, DVec2, DVec3, DVec4,
        DSpatialVector, f64
    );
}

/// The spatial vectors and matrices (wp_core.h's operators, wp_spatial.h's builtins, and
/// wp_adjoint_spatial.h's adjoints of both), forward and adjoint.
fn spatial(s: &mut Suite) {
    macro_rules! each {
        ($($sv:ident, $sm:ident: $v3:ident, $m3:ident, $x:ident, $s:ident);*) => {$(
            // Forward.
            fwd2::<$sv, $sv, $sv>(s, "v0 + v1", |a, b| a + b);
            fwd2::<$sv, $sv, $sv>(s, "v0 - v1", |a, b| a - b);
            fwd2::<$sv, $s, $sv>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$s, $sv, $sv>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$sv, $s, $sv>(s, "v0 / v1", |a, b| a / b);
            fwd2::<$sm, $sm, $sm>(s, "v0 + v1", |a, b| a + b);
            fwd2::<$sm, $sm, $sm>(s, "v0 - v1", |a, b| a - b);
            fwd2::<$sm, $s, $sm>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$sm, $s, $sm>(s, "v0 / v1", |a, b| a / b);
            fwd2::<$sm, $sv, $sv>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$sm, $sm, $sm>(s, "v0 * v1", |a, b| a * b);
            fwd2::<$sv, $sv, $s>(s, "wp::spatial_dot(v0, v1)", bi::spatial_dot);
            fwd2::<$sv, $sv, $sv>(s, "wp::spatial_cross(v0, v1)", bi::spatial_cross);
            fwd2::<$sv, $sv, $sv>(s, "wp::spatial_cross_dual(v0, v1)", bi::spatial_cross_dual);
            fwd2::<$sv, $sv, $sm>(s, "wp::outer(v0, v1)", bi::outer);
            fwd2::<$sm, $sm, $sm>(s, "wp::transpose(v0) - v1", |a, b| bi::transpose(a) - b);
            fwd2::<$sv, $sv, $v3>(s, "wp::spatial_top(v0) + wp::spatial_bottom(v1)", |a, b| {
                bi::spatial_top(a) + bi::spatial_bottom(b)
            });
            fwd2::<$v3, $v3, $sv>(s, "wp::spatial_vector(v0, v1)", bi::spatial_vector);
            fwd2::<$m3, $m3, $sm>(s, "wp::spatial_adjoint(v0, v1)", bi::spatial_adjoint);
            fwd2::<$x, $sv, $sv>(s, "wp::transform_twist(v0, v1)", bi::transform_twist);
            fwd2::<$sv, $v3, $v3>(s, "wp::velocity_at_point(v0, v1)", bi::velocity_at_point);
            fwd2::<$x, $sv, $sv>(s, "wp::transform_wrench(v0, v1)", bi::transform_wrench);
            fwd2::<$sv, $sv, bool>(s, "v0 == v1 && !(v0 != v1)", |a, b| a == b);
            // Adjoints.
            bin::<$sv, $sv, $sv>(s, "adj_add", ad::adj_add);
            bin::<$sv, $sv, $sv>(s, "adj_sub", ad::adj_sub);
            bin::<$sv, $s, $sv>(s, "adj_mul", ad::adj_mul);
            bin::<$s, $sv, $sv>(s, "adj_mul", ad::adj_mul);
            bin::<$sv, $s, $sv>(s, "adj_div", ad::adj_div);
            un::<$sv, $sv>(s, "adj_neg", ad::adj_neg);
            bin::<$sm, $sm, $sm>(s, "adj_add", ad::adj_add);
            bin::<$sm, $sm, $sm>(s, "adj_sub", ad::adj_sub);
            bin::<$sm, $s, $sm>(s, "adj_mul", ad::adj_mul);
            bin::<$s, $sm, $sm>(s, "adj_mul", ad::adj_mul);
            bin::<$sm, $s, $sm>(s, "adj_div", ad::adj_div);
            un::<$sm, $sm>(s, "adj_neg", ad::adj_neg);
            bin::<$sm, $sv, $sv>(s, "adj_mul", ad::adj_mul);
            bin::<$sm, $sm, $sm>(s, "adj_mul", ad::adj_mul);
            un::<$sm, $sm>(s, "adj_transpose", ad::adj_transpose);
            bin::<$sv, $sv, $sm>(s, "adj_outer", ad::adj_outer);
            bin::<$sv, $sv, $s>(s, "adj_spatial_dot", ad::adj_spatial_dot);
            bin::<$sv, $sv, $sv>(s, "adj_spatial_cross", ad::adj_spatial_cross);
            bin::<$sv, $sv, $sv>(s, "adj_spatial_cross_dual", ad::adj_spatial_cross_dual);
            un::<$sv, $v3>(s, "adj_spatial_top", ad::adj_spatial_top);
            un::<$sv, $v3>(s, "adj_spatial_bottom", ad::adj_spatial_bottom);
            bin::<$v3, $v3, $sv>(s, "adj_spatial_vector", ad::adj_spatial_vector);
            bin::<$m3, $m3, $sm>(s, "adj_spatial_adjoint", ad::adj_spatial_adjoint);
            bin::<$x, $sv, $sv>(s, "adj_transform_twist", ad::adj_transform_twist);
            bin::<$sv, $v3, $v3>(s, "adj_velocity_at_point", ad::adj_velocity_at_point);
            fwd2::<$sv, $s, $sv>(s, "wp::lerp(v0, -v0, v1)", |a, t| bi::lerp(a, -a, t));
            fwd2::<$sm, $s, $sm>(s, "wp::lerp(v0, -v0, v1)", |a, t| bi::lerp(a, -a, t));
            tri::<$sv, $sv, $s, $sv>(s, "adj_lerp", ad::adj_lerp);
            tri::<$sm, $sm, $s, $sm>(s, "adj_lerp", ad::adj_lerp);
            bin::<$x, $sv, $sv>(s, "adj_transform_wrench", ad::adj_transform_wrench);
            zero_accum::<$sv>(s);
            zero_accum::<$sm>(s);
            grad_cases::<$sv>(s);
        )*};
    }
    each!(
        SpatialVector, SpatialMatrix: Vec3, Mat3, Transform, f32;
        DSpatialVector, DSpatialMatrix: DVec3, DMat3, DTransform, f64
    );
    // The six-scalar constructor and its adjoint (each lane's adjoint is its own).
    macro_rules! six {
        ($($sv:ident: $s:ident),*) => {$({
            let ty = [$s::TY; 6];
            let op = s.sig("a0 = wp::spatial_vector_scalars(v0, v1, v2, v3, v4, v5)", &ty, &[$sv::TY], None);
            let adj = s.sig("wp::adj_spatial_vector_scalars($)", &ty, &ty, Some($sv::TY));
            for _ in 0..s.n {
                let v: [$s; 6] = std::array::from_fn(|_| s.g.val::<$s>());
                let r0 = s.g.adj::<$sv>();
                let words: Vec<u64> = v.iter().flat_map(|x| x.bits()).chain(r0.bits()).collect();
                s.case(op, &words, toks(&bi::spatial_vector_scalars(v[0], v[1], v[2], v[3], v[4], v[5])));
                let mut a: [$s; 6] = std::array::from_fn(|_| s.g.adj::<$s>());
                let g = s.g.ret::<$sv>();
                let words: Vec<u64> = v.iter().chain(&a).flat_map(|x| x.bits()).chain(g.bits()).collect();
                let [a0, a1, a2, a3, a4, a5] = &mut a;
                ad::adj_spatial_vector_scalars(v[0], v[1], v[2], v[3], v[4], v[5], a0, a1, a2, a3, a4, a5, g);
                s.case(adj, &words, a.iter().flat_map(toks).collect());
            }
        })*};
    }
    six!(SpatialVector: f32, DSpatialVector: f64);
}

/// The decompositions of wp_svd.h: `adj_<name>(a, adj_a, tuple_t{..})` on random and special
/// matrices (the generator's: NaNs, infinities, zero and repeated lanes), and on diagonal
/// matrices with repeated entries (the clamped `F` of the SVD and the tie rule of eig3).
fn decomps(s: &mut Suite) {
    macro_rules! mats {
        ($($m:ident, $v:ident, $s:ident);*) => {$({
            let (m, v) = (stringify!($m), stringify!($v));
            let t3 = format!("wp::tuple_t<wp::{m}, wp::{v}, wp::{m}>");
            let t2m = format!("wp::tuple_t<wp::{m}, wp::{m}>");
            let t2v = format!("wp::tuple_t<wp::{m}, wp::{v}>");
            let svd = s.sig(&format!("wp::adj_svd3(v0, a0, {t3}{{v1, v2, v3}})"), &[m, m, v, m], &[m], None);
            let eig = s.sig(&format!("wp::adj_eig3(v0, a0, {t2v}{{v1, v2}})"), &[m, m, v], &[m], None);
            let qr = s.sig(&format!("wp::adj_qr3(v0, a0, {t2m}{{v1, v2}})"), &[m, m, m], &[m], None);
            let mut inputs: Vec<$m> = s.inputs1::<$m>();
            for d in [[2.0, 2.0, 1.0], [1.0, 1.0, 1.0], [0.0, 0.0, 0.0], [3.0, -1.0, 2.0]] {
                inputs.push($m::from_diagonal($v::from_array(d)));
            }
            for a in inputs {
                let sym = (a + a.transpose()) * 0.5;
                let (mut aa, gu, gs, gv) = (s.g.adj::<$m>(), s.g.ret::<$m>(), s.g.ret::<$v>(), s.g.ret::<$m>());
                let words = [a.bits(), gu.bits(), gs.bits(), gv.bits(), aa.bits()].concat();
                ad::adj_svd3(a, &mut aa, (gu, gs, gv));
                s.case(svd, &words, toks(&aa));
                let mut aa = s.g.adj::<$m>();
                let words = [sym.bits(), gu.bits(), gs.bits(), aa.bits()].concat();
                ad::adj_eig3(sym, &mut aa, (gu, gs));
                s.case(eig, &words, toks(&aa));
                let mut aa = s.g.adj::<$m>();
                let words = [a.bits(), gu.bits(), gv.bits(), aa.bits()].concat();
                ad::adj_qr3(a, &mut aa, (gu, gv));
                s.case(qr, &words, toks(&aa));
            }
        })*};
    }
    mats!(Mat3, Vec3, f32; DMat3, DVec3, f64);
    macro_rules! mats2 {
        ($($m:ident, $v:ident, $s:ident);*) => {$({
            let (m, v) = (stringify!($m), stringify!($v));
            let t3 = format!("wp::tuple_t<wp::{m}, wp::{v}, wp::{m}>");
            let svd = s.sig(&format!("wp::adj_svd2(v0, a0, {t3}{{v1, v2, v3}})"), &[m, m, v, m], &[m], None);
            let mut inputs: Vec<$m> = s.inputs1::<$m>();
            for d in [[2.0, 2.0], [0.0, 0.0], [3.0, -1.0]] {
                inputs.push($m::from_diagonal($v::from_array(d)));
            }
            for a in inputs {
                let (mut aa, gu, gs, gv) = (s.g.adj::<$m>(), s.g.ret::<$m>(), s.g.ret::<$v>(), s.g.ret::<$m>());
                let words = [a.bits(), gu.bits(), gs.bits(), gv.bits(), aa.bits()].concat();
                ad::adj_svd2(a, &mut aa, (gu, gs, gv));
                s.case(svd, &words, toks(&aa));
            }
        })*};
    }
    mats2!(Mat2, Vec2, f32; DMat2, DVec2, f64);
}

/// The builtins of wp_misc.h (warp-core adjoint/misc.rs): the generator's inputs (NaNs,
/// infinities, zeros, ties), and for the norms' thresholds and the decomposition also
/// inputs on both sides of their branches.
fn misc(s: &mut Suite) {
    bin::<f32, f32, f32>(s, "adj_copysign", ad::adj_copysign);
    bin::<f64, f64, f64>(s, "adj_copysign", ad::adj_copysign);
    macro_rules! vecs {
        ($($v:ident: $s:ident),*) => {$(
            un::<$v, $s>(s, "adj_min_element", ad::adj_min_element);
            un::<$v, $s>(s, "adj_max_element", ad::adj_max_element);
            un::<$v, $s>(s, "adj_norm_l1", ad::adj_norm_l1);
            un::<$v, $s>(s, "adj_norm_l2", ad::adj_norm_l2);
            bin::<$v, $s, $s>(s, "adj_norm_huber", ad::adj_norm_huber);
            bin::<$v, $s, $s>(s, "adj_norm_pseudo_huber", ad::adj_norm_pseudo_huber);
            bin::<$v, $s, $v>(s, "adj_smooth_normalize", ad::adj_smooth_normalize);
        )*};
    }
    vecs!(Vec2: f32, Vec3: f32, Vec4: f32, DVec2: f64, DVec3: f64, DVec4: f64);
    un::<IVec3, i32>(s, "adj_min_element", ad::adj_min_element);
    un::<UVec4, u32>(s, "adj_max_element", ad::adj_max_element);
    macro_rules! mats {
        ($($m:ident: $v:ident),*) => {$(
            un::<$m, $v>(s, "adj_get_diag", ad::adj_get_diag);
        )*};
    }
    mats!(Mat2: Vec2, Mat3: Vec3, Mat4: Vec4, DMat2: DVec2, DMat3: DVec3, DMat4: DVec4);
    macro_rules! quats {
        ($($q:ident: $v:ident, $m4:ident, $s:ident),*) => {$({
            tri::<$s, $s, $s, $q>(s, "adj_quat_rpy", ad::adj_quat_rpy::<$q>);
            un::<$q, $v>(s, "adj_quat_to_rpy", ad::adj_quat_to_rpy::<$q>);
            bin::<$v, $q, $q>(s, "adj_quat_twist", ad::adj_quat_twist::<$q>);
            bin::<$v, $q, $s>(s, "adj_quat_twist_angle", ad::adj_quat_twist_angle::<$q>);
            bin::<$v, $q, $s>(s, "adj_quat_twist_angle_signed", ad::adj_quat_twist_angle_signed::<$q>);
            tri::<$v, $q, $v, $m4>(s, "adj_transform_compose", ad::adj_transform_compose::<$v>);
            let (q, v, m4, sc) = (stringify!($q), stringify!($v), stringify!($m4), stringify!($s));
            let aa = s.sig(
                &format!("wp::adj_quat_to_axis_angle(v0, a0, wp::tuple_t<wp::{v}, wp::{sc}>{{v1, v2}})"),
                &[q, v, sc],
                &[q],
                None,
            );
            for a in s.inputs1::<$q>() {
                let (mut ag, gv, gs) = (s.g.adj::<$q>(), s.g.ret::<$v>(), s.g.ret::<$s>());
                let words = [a.bits(), gv.bits(), gs.bits(), ag.bits()].concat();
                ad::adj_quat_to_axis_angle(a, &mut ag, (gv, gs));
                s.case(aa, &words, toks(&ag));
            }
            let dec = s.sig(
                &format!("wp::adj_transform_decompose(v0, a0, wp::tuple_t<wp::{v}, wp::{q}, wp::{v}>{{v1, v2, v3}})"),
                &[m4, v, q, v],
                &[m4],
                None,
            );
            let mut inputs: Vec<$m4> = s.inputs1::<$m4>();
            for k in 0..s.n {
                // Rigid motions with scales (one of them zero): both branches per column.
                let g = &mut s.g;
                let q = $q::from_xyzw(g.rand() as $s, g.rand() as $s, g.rand() as $s, g.rand() as $s).normalize();
                let p = $v::new(g.rand() as $s, g.rand() as $s, g.rand() as $s);
                let sc = $v::new(g.rand() as $s, if k % 4 == 0 { 0.0 } else { g.rand() as $s }, g.rand() as $s);
                inputs.push(warp_lang::__private::builtins::transform_compose(p, q, sc));
            }
            for m in inputs {
                let (mut am, gp, gq, gs) = (s.g.adj::<$m4>(), s.g.ret::<$v>(), s.g.ret::<$q>(), s.g.ret::<$v>());
                let words = [m.bits(), gp.bits(), gq.bits(), gs.bits(), am.bits()].concat();
                ad::adj_transform_decompose(m, &mut am, (gp, gq, gs));
                s.case(dec, &words, toks(&am));
            }
        })*};
    }
    quats!(Quat: Vec3, Mat4, f32, DQuat: DVec3, DMat4, f64);
}

/// Integers: every adjoint is a no-op (the starting adjoints come back unchanged).
fn integers(s: &mut Suite) {
    let n = s.n;
    s.n = 4;
    macro_rules! scalars {
        ($($t:ident),*) => {$(
            arith!(s; $t, $t => $t);
            un::<$t, $t>(s, "adj_neg", ad::adj_neg);
            minmax!(s; $t);
            un::<$t, $t>(s, "adj_step", ad::adj_step);
        )*};
    }
    scalars!(i8, i16, i32, i64, isize, u8, u16, u32, u64, usize);
    macro_rules! signed {
        ($($t:ident),*) => {$(
            un::<$t, $t>(s, "adj_abs", ad::adj_abs);
            un::<$t, $t>(s, "adj_sign", ad::adj_sign);
        )*};
    }
    signed!(i8, i16, i32, i64, isize, IVec2, IVec3, IVec4);
    macro_rules! vectors {
        ($($v:ident: $s:ident),*) => {$(
            arith!(s; $v, $v => $v; $v, $s => $v; $s, $v => $v);
            un::<$v, $v>(s, "adj_neg", ad::adj_neg);
            minmax!(s; $v);
            bin::<$v, $v, $s>(s, "adj_dot", ad::adj_dot);
        )*};
    }
    vectors!(IVec2: i32, IVec3: i32, IVec4: i32, UVec2: u32, UVec3: u32, UVec4: u32);
    bin::<IVec3, IVec3, IVec3>(s, "adj_cross", ad::adj_cross);
    s.n = n;
}

fn casts(s: &mut Suite) {
    macro_rules! row {
        ($f:ty; $($t:ty),*) => {$( cast::<$f, $t>(s, ad::adj_cast); )*};
    }
    macro_rules! all {
        ($($f:ty),*) => {$(
            row!($f; bool, i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64);
        )*};
    }
    all!(bool, i8, i16, i32, i64, isize, u8, u16, u32, u64, usize, f32, f64);
}

fn zeros(s: &mut Suite) {
    macro_rules! all {
        ($($t:ty),*) => {$( zero_accum::<$t>(s); )*};
    }
    all!(bool, i8, i16, i32, i64, u8, u16, u32, u64, f32, f64);
    all!(Vec2, Vec3, Vec4, DVec2, DVec3, DVec4, IVec2, IVec3, IVec4, UVec2, UVec3, UVec4);
    all!(Mat2, Mat3, Mat4, DMat2, DMat3, DMat4, Quat, DQuat, Transform, DTransform);
}

// ------------------------------------------------------------------------------------------
// Gradient arrays: grad_accum / grad_take / grad_get against GradView
// ------------------------------------------------------------------------------------------

/// The initial lane `k` of element `l` (the C++ `init`).
fn init_lane(float: u32, l: usize, k: usize) -> u64 {
    let n = (l * 8 + k) as u64;
    match float {
        32 => (n as f32 + 0.5).to_bits() as u64,
        64 => (n as f64 + 0.5).to_bits(),
        _ => n,
    }
}

/// `op`: 0 accumulate, 1 take, 2 get; the result value (take, get), the fault if any, then
/// the whole gradient buffer in storage order.
fn grad_expect<T: Val + GradElement>(
    shape: &[usize],
    colmajor: bool,
    op: u64,
    has: bool,
    ix: &[i64],
    v: T,
) -> Vec<Tok> {
    let n = shape.len();
    let total: usize = shape.iter().product();
    let mut strides = vec![0isize; n];
    let mut st = 1isize;
    let order: Vec<usize> = if colmajor {
        (0..n).collect()
    } else {
        (0..n).rev().collect()
    };
    for k in order {
        strides[k] = st;
        st *= shape[k] as isize;
    }
    let mut data: Vec<T> = (0..total)
        .map(|l| {
            let w: Vec<u64> = (0..T::LANES).map(|k| init_lane(T::FLOAT, l, k)).collect();
            T::from_bits(&w)
        })
        .collect();
    let p = data.as_mut_ptr();
    macro_rules! run {
        ($n:literal, $idx:expr) => {{
            // SAFETY: every in-bounds index addresses an element of `data` (strides computed
            // from the shape above), which outlives the view.
            let view = unsafe {
                ArrayView::<T, $n>::new(
                    p,
                    std::array::from_fn(|k| shape[k]),
                    std::array::from_fn(|k| strides[k]),
                    "k",
                    "g",
                )
            };
            let gv = if has {
                GradView::new(view)
            } else {
                GradView::none()
            };
            match op {
                0 => gv.accumulate($idx, v).map(|_| None),
                1 => gv.take($idx, v).map(Some),
                _ => gv.get($idx, v).map(Some),
            }
        }};
    }
    let r: Result<Option<T>, Box<Fault>> = match n {
        1 => run!(1, ix[0]),
        2 => run!(2, (ix[0], ix[1])),
        3 => run!(3, (ix[0], ix[1], ix[2])),
        _ => run!(4, (ix[0], ix[1], ix[2], ix[3])),
    };
    let mut want = Vec::new();
    let mut fault = [0u64; 12];
    match r {
        Ok(Some(x)) => want.extend(toks(&x)),
        Ok(None) => {}
        Err(f) => {
            if op != 0 {
                want.extend(toks(&T::from_bits(&vec![0; T::LANES])));
            }
            let FaultKind::OutOfBounds { index, shape, .. } = &f.kind else {
                panic!("unexpected fault {f}");
            };
            fault[..4].copy_from_slice(&[1, 1, 3, n as u64]);
            for (k, &i) in index.iter().enumerate() {
                fault[4 + k] = i as i64 as u64;
            }
            for (k, &e) in shape.iter().enumerate() {
                fault[8 + k] = e as u64;
            }
        }
    }
    want.extend(fault.iter().map(|&w| Tok(w, 0)));
    for x in &data {
        want.extend(toks(x));
    }
    want
}

fn grad_cases<T: Val + GradElement>(s: &mut Suite) {
    let shapes: [&[usize]; 4] = [&[5], &[2, 3], &[2, 3, 2], &[2, 1, 3, 2]];
    for shape in shapes {
        let n = shape.len();
        let body = format!("  grad_case<{}, {n}>(r);\n", cxx(T::TY));
        let op = s.op(format!("grad {} {n}-D", T::TY), body);
        let total: usize = shape.iter().product();
        let mut idxs: Vec<Vec<i64>> = (0..total)
            .map(|l| {
                let mut rem = l;
                let mut ix = vec![0i64; n];
                for k in (0..n).rev() {
                    ix[k] = (rem % shape[k]) as i64;
                    rem /= shape[k];
                }
                ix
            })
            .collect();
        for k in 0..n {
            for bad in [-1, shape[k] as i64] {
                let mut ix = vec![0i64; n];
                ix[k] = bad;
                idxs.push(ix);
            }
        }
        for colmajor in [false, true] {
            for has in [false, true] {
                for kind in 0..3u64 {
                    for ix in &idxs {
                        let v = s.g.ret::<T>();
                        let mut words: Vec<u64> = shape.iter().map(|&e| e as u64).collect();
                        words.extend([colmajor as u64, kind, has as u64]);
                        words.extend(ix.iter().map(|&i| i as u64));
                        words.extend(v.bits());
                        let want = grad_expect(shape, colmajor, kind, has, ix, v);
                        s.case(op, &words, want);
                    }
                }
            }
        }
    }
}

fn grads(s: &mut Suite) {
    grad_cases::<f32>(s);
    grad_cases::<f64>(s);
    grad_cases::<Vec3>(s);
    grad_cases::<Vec4>(s);
    grad_cases::<DVec3>(s);
    grad_cases::<Mat3>(s);
    grad_cases::<DMat2>(s);
    grad_cases::<Quat>(s);
    grad_cases::<DQuat>(s);
    grad_cases::<Transform>(s);
    grad_cases::<DTransform>(s);
    grad_cases::<i32>(s);
    grad_cases::<u8>(s);
    grad_cases::<bool>(s);
}

// ------------------------------------------------------------------------------------------
// The generated C++ program
// ------------------------------------------------------------------------------------------

const PRELUDE: &str = r#"// Generated by tests/cuda_adjoint_host.rs. Host: g++ -std=c++17 -O1 -ffp-contract=off.
// GPU: nvcc -std=c++17 -x cu --fmad=false (one thread per case); NVRTC: -DWP_ADJ_NO_MAIN.
#include "wp_adjoint.h"

#if !defined(__CUDACC_RTC__)
#include <cstdio>
#include <cstring>
#include <vector>
#endif

#if defined(__CUDACC__)
#define DRV __device__
#define DRV_OP __device__ __noinline__
#else
#define DRV
#define DRV_OP
#endif

namespace {
constexpr int OUT_WORDS = 256;     // result words per case, at most
constexpr int SCRATCH = 2048;      // gradient buffer bytes per case (global memory on a GPU)
struct R {
  const unsigned long long* w;     // the case's words
  int p;
  unsigned long long* o;           // its result words
  int n;
  unsigned char* scratch;
};
template <typename T>
DRV void rd(R& r, T& x) {
  if constexpr (wp::num<T>::is_float) {
    if constexpr (sizeof(T) == 4)
      x = wp::f32_from_bits((wp::u32)r.w[r.p++]);
    else
      x = wp::f64_from_bits(r.w[r.p++]);
  } else if constexpr (wp::num<T>::is_int || wp::num<T>::is_bool) {
    x = (T)r.w[r.p++];
  } else {
    for (int i = 0; i < wp::vec_traits<T>::N; ++i) rd(r, wp::vec_traits<T>::at(x, i));
  }
}
DRV void wr_word(R& r, unsigned long long v) {
  if (r.n < OUT_WORDS) r.o[r.n] = v;
  ++r.n;
}
template <typename T>
DRV void wr(R& r, const T& x) {
  if constexpr (wp::num<T>::is_float) {
    if constexpr (sizeof(T) == 4)
      wr_word(r, wp::f32_to_bits(x));
    else
      wr_word(r, wp::f64_to_bits(x));
  } else if constexpr (wp::num<T>::is_bool) {
    wr_word(r, x ? 1u : 0u);
  } else if constexpr (wp::num<T>::is_int) {
    wr_word(r, (unsigned long long)(typename wp::num<T>::unsigned_t)x);
  } else {
    for (int i = 0; i < wp::vec_traits<T>::N; ++i) wr(r, wp::vec_traits<T>::get(x, i));
  }
}

// ----- gradient arrays -----
template <typename T>
DRV constexpr int lanes() {
  if constexpr (wp::detail::adj_is_scalar<T>::value)
    return 1;
  else
    return wp::vec_traits<T>::N;
}
template <typename T>
DRV typename wp::detail::adj_scalar_of<T>::type& lane(T& x, int k) {
  if constexpr (wp::detail::adj_is_scalar<T>::value) {
    (void)k;
    return x;
  } else {
    return wp::vec_traits<T>::at(x, k);
  }
}
#define GRAD_OP(N, ...)                                                                    \
  template <typename T>                                                                    \
  DRV T grad_op(const wp::array_t<T, N>& g, const wp::i64* i, int op, const T& v, wp::ctx_t* c) { \
    if (op == 0) {                                                                         \
      wp::grad_accum(g, __VA_ARGS__, v, c);                                                \
      return T{};                                                                          \
    }                                                                                      \
    if (op == 1) return wp::grad_take(g, __VA_ARGS__, v, c);                               \
    return wp::grad_get(g, __VA_ARGS__, v, c);                                             \
  }
GRAD_OP(1, i[0])
GRAD_OP(2, i[0], i[1])
GRAD_OP(3, i[0], i[1], i[2])
GRAD_OP(4, i[0], i[1], i[2], i[3])
#undef GRAD_OP
// Words: shape[N], colmajor, op (0 accum, 1 take, 2 get), has_grad, index[N], value.
// Results: the value (take, get); the fault (flag kind arg ndim index[4] shape[4], all 0
// without one); the gradient buffer in storage order.
template <typename T, int N>
DRV void grad_case(R& r) {
  typedef typename wp::detail::adj_scalar_of<T>::type S;
  wp::i64 shape[N], idx[N];
  for (int k = 0; k < N; ++k) shape[k] = (wp::i64)r.w[r.p++];
  const bool colmajor = r.w[r.p++] != 0;
  const int op = (int)r.w[r.p++];
  const bool has = r.w[r.p++] != 0;
  for (int k = 0; k < N; ++k) idx[k] = (wp::i64)r.w[r.p++];
  T v;
  rd(r, v);
  wp::i64 total = 1;
  for (int k = 0; k < N; ++k) total *= shape[k];
  // The buffer, the fault record and its flag live in the case's scratch memory (global
  // memory on a GPU, where atomics cannot address a thread's local variables).
  T* buf = (T*)r.scratch;
  if (total * (wp::i64)sizeof(T) > 1024) return;
  wp::fault_t& f = *(wp::fault_t*)(r.scratch + 1024);
  wp::u32& flag = *(wp::u32*)(r.scratch + 1024 + sizeof(wp::fault_t));
  f = wp::fault_t{};
  flag = 0;
  for (wp::i64 l = 0; l < total; ++l)
    for (int k = 0; k < lanes<T>(); ++k) {
      if constexpr (wp::num<S>::is_float)
        lane(buf[l], k) = (S)(l * 8 + k) + (S)0.5;
      else
        lane(buf[l], k) = (S)(l * 8 + k);
    }
  wp::array_t<T, N> g;
  g.data = has ? buf : nullptr;
  wp::i64 st = (wp::i64)sizeof(T);
  for (int j = 0; j < N; ++j) {
    const int k = colmajor ? j : N - 1 - j;
    g.shape[k] = shape[k];
    g.strides[k] = st;
    st *= shape[k];
  }
  g.arg = 3;
  g.pad = 0;
  wp::launch_ctx_t rec = wp::launch_ctx_make(&f, &flag);
  wp::ctx_t ctx = wp::ctx_make(&rec);
  const T res = grad_op(g, idx, op, v, &ctx);
  if (op != 0) wr(r, res);
  wr_word(r, flag);
  wr_word(r, (unsigned long long)(wp::i64)f.kind);
  wr_word(r, (unsigned long long)(wp::i64)f.arg);
  wr_word(r, (unsigned long long)(wp::i64)f.ndim);
  for (int k = 0; k < 4; ++k) wr_word(r, (unsigned long long)f.index[k]);
  for (int k = 0; k < 4; ++k) wr_word(r, (unsigned long long)f.shape[k]);
  for (wp::i64 l = 0; l < total; ++l) wr(r, buf[l]);
}
"#;

const MAIN: &str = r#"
#if defined(__CUDACC__)
extern "C" __global__ void run_all(const unsigned* ops, const unsigned long long* offs,
                                   const unsigned long long* words, unsigned long long* out,
                                   int* counts, unsigned char* scratch, int ncases) {
  const int i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= ncases) return;
  R r{words + offs[i], 0, out + (unsigned long long)i * OUT_WORDS, 0,
    scratch + (unsigned long long)i * SCRATCH};
  run_case(ops[i], r);
  counts[i] = r.p == (int)(offs[i + 1] - offs[i]) ? r.n : -1;
}
#endif

#if !defined(WP_ADJ_NO_MAIN)
int main(int argc, char** argv) {
  if (argc < 2) return 2;
  FILE* f = fopen(argv[1], "r");
  if (!f) return 2;
  std::vector<unsigned> ops;
  std::vector<unsigned long long> offs{0}, words;
  unsigned op, n;
  while (fscanf(f, "%x %x", &op, &n) == 2) {
    for (unsigned i = 0; i < n; ++i) {
      unsigned long long x;
      if (fscanf(f, "%llx", &x) != 1) return 3;
      words.push_back(x);
    }
    ops.push_back(op);
    offs.push_back(words.size());
  }
  fclose(f);
  const size_t nc = ops.size();
  words.push_back(0);
  std::vector<unsigned long long> out(nc * OUT_WORDS);
  std::vector<int> counts(nc);
#if defined(__CUDACC__)
  unsigned* d_ops;
  unsigned long long *d_offs, *d_words, *d_out;
  int* d_counts;
  unsigned char* d_scratch;
  cudaMalloc(&d_ops, nc * sizeof(unsigned));
  cudaMalloc(&d_offs, offs.size() * 8);
  cudaMalloc(&d_words, words.size() * 8);
  cudaMalloc(&d_out, out.size() * 8);
  cudaMalloc(&d_counts, nc * sizeof(int));
  cudaMalloc(&d_scratch, nc * SCRATCH);
  cudaMemcpy(d_ops, ops.data(), nc * sizeof(unsigned), cudaMemcpyHostToDevice);
  cudaMemcpy(d_offs, offs.data(), offs.size() * 8, cudaMemcpyHostToDevice);
  cudaMemcpy(d_words, words.data(), words.size() * 8, cudaMemcpyHostToDevice);
  run_all<<<(unsigned)((nc + 127) / 128), 128>>>(d_ops, d_offs, d_words, d_out, d_counts, d_scratch, (int)nc);
  if (cudaDeviceSynchronize() != cudaSuccess) return 5;
  cudaMemcpy(out.data(), d_out, out.size() * 8, cudaMemcpyDeviceToHost);
  cudaMemcpy(counts.data(), d_counts, nc * sizeof(int), cudaMemcpyDeviceToHost);
#else
  alignas(16) static unsigned char scratch[SCRATCH];
  for (size_t i = 0; i < nc; ++i) {
    R r{words.data() + offs[i], 0, out.data() + i * OUT_WORDS, 0, scratch};
    run_case(ops[i], r);
    counts[i] = r.p == (int)(offs[i + 1] - offs[i]) ? r.n : -1;
  }
#endif
  for (size_t i = 0; i < nc; ++i) {
    if (counts[i] < 0 || counts[i] > OUT_WORDS) {
      printf("BADLEN\n");
      continue;
    }
    for (int k = 0; k < counts[i]; ++k) printf(k ? " %llx" : "%llx", out[i * OUT_WORDS + k]);
    printf("\n");
  }
  return 0;
}
#endif
"#;

fn program(s: &Suite) -> String {
    let mut src = PRELUDE.to_string();
    for (k, (name, body)) in s.ops.iter().enumerate() {
        let _ = write!(src, "// {name}\nDRV_OP void op_{k}(R& r) {{\n{body}}}\n");
    }
    src.push_str("DRV void run_case(unsigned op, R& r) {\n  switch (op) {\n");
    for k in 0..s.ops.len() {
        let _ = writeln!(src, "    case {k}: op_{k}(r); break;");
    }
    src.push_str("    default: break;\n  }\n}\n}  // namespace\n");
    src.push_str(MAIN);
    src
}

// ------------------------------------------------------------------------------------------
// The test
// ------------------------------------------------------------------------------------------

/// Builds and runs the generated program with g++; `None` (having said SKIPPED) without g++.
fn run_on_host(s: &Suite) -> Option<String> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::temp_dir().join(format!("warp_cuda_adjoint_host_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (src, exe, cases) = (dir.join("adj.cpp"), dir.join("adj"), dir.join("cases.txt"));
    std::fs::write(&src, program(s)).unwrap();
    std::fs::write(&cases, &s.text).unwrap();
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "g++".into());
    let flags = [
        "-std=c++17",
        "-O1",
        "-ffp-contract=off",
        "-Wall",
        "-Wextra",
        "-Werror",
    ];
    let include = root.join("warp-cuda/cuda");
    let build = Command::new(&cxx)
        .args(flags)
        .arg("-I")
        .arg(&include)
        .arg("-o")
        .arg(&exe)
        .arg(&src)
        .output();
    let Ok(build) = build else {
        println!("SKIPPED: no g++ ({cxx} could not be run)");
        return None;
    };
    assert!(
        build.status.success(),
        "the generated C++ program ({}) does not compile:\n{}",
        src.display(),
        String::from_utf8_lossy(&build.stderr)
    );
    let run = Command::new(&exe).arg(&cases).output().expect("run it");
    assert!(run.status.success(), "the C++ program failed: {run:?}");
    let _ = std::fs::remove_dir_all(&dir);
    Some(String::from_utf8(run.stdout).expect("utf-8 output"))
}

/// On a GPU: set `WARP_CUDA_ADJOINT_CASES=DIR` to write `adj.cpp` and `cases.txt` there, build
/// and run them on the GPU machine (`nvcc -std=c++17 -O2 -x cu --fmad=false -arch=native -I
/// warp-cuda/cuda adj.cpp -o adj && ./adj cases.txt > OUT`: one GPU thread per case; NVRTC
/// compiles the same source with `-DWP_ADJ_NO_MAIN`), and set `WARP_CUDA_ADJOINT_RESULTS=OUT`
/// to compare its output here instead of running g++ (transcendental adjoints then within the
/// tolerance of `LOOSE_ON_GPU`).
#[test]
fn cuda_adjoints_match_cpu_adjoints_on_the_host() {
    if !cfg!(target_arch = "x86_64") {
        println!("SKIPPED: the library reproduces glam's x86_64 (SSE2) layout and arithmetic");
        return;
    }
    let mut s = Suite {
        g: Gen(0x2545_f491_4f6c_dd1d),
        n: 96,
        ops: Vec::new(),
        by_body: HashMap::new(),
        text: String::new(),
        cases: Vec::new(),
    };
    float_scalars(&mut s);
    float_vectors(&mut s);
    extreme_norms(&mut s);
    matrices_and_quats(&mut s);
    linalg(&mut s);
    noise(&mut s);
    transforms(&mut s);
    spatial(&mut s);
    nonsquare(&mut s);
    decomps(&mut s);
    misc(&mut s);
    integers(&mut s);
    casts(&mut s);
    zeros(&mut s);
    grads(&mut s);
    println!("{} cases, {} C++ signatures", s.cases.len(), s.ops.len());
    if let Some(dir) = std::env::var_os("WARP_CUDA_ADJOINT_CASES") {
        let dir = PathBuf::from(dir);
        std::fs::write(dir.join("adj.cpp"), program(&s)).expect("write adj.cpp");
        std::fs::write(dir.join("cases.txt"), &s.text).expect("write cases.txt");
    }
    let results = std::env::var_os("WARP_CUDA_ADJOINT_RESULTS");
    let gpu = results.is_some();
    let out = match results {
        Some(path) => std::fs::read_to_string(path).expect("read the GPU results"),
        None => match run_on_host(&s) {
            Some(out) => out,
            None => return,
        },
    };
    let got: Vec<&str> = out.lines().collect();
    assert_eq!(got.len(), s.cases.len(), "one result line per case");

    let mut failures = Vec::new();
    let mut by_op: std::collections::BTreeMap<&str, usize> = Default::default();
    for ((op, line, want), g) in s.cases.iter().zip(&got) {
        let name = &s.ops[*op].0;
        let listed = |list: &[&str]| list.iter().any(|f| name.starts_with(&format!("wp::{f} ")));
        let ulps = if gpu && listed(&ILL_CONDITIONED_ON_GPU) {
            128.0
        } else if (gpu && listed(&LOOSE_ON_GPU)) || listed(&LOOSE_ON_HOST) {
            8.0
        } else {
            0.0
        };
        let gt: Vec<&str> = g.split_whitespace().collect();
        let ok =
            gt.len() == want.len() && want.iter().zip(&gt).all(|(w, g)| tok_matches(*w, g, ulps));
        if !ok {
            *by_op.entry(name).or_default() += 1;
            if failures.len() < 30 {
                failures.push(format!(
                    "{name}\n  case {line}\n  want {want:x?}\n  got  {g}"
                ));
            }
        }
    }
    if !by_op.is_empty() {
        let summary: Vec<String> = by_op.iter().map(|(k, v)| format!("{k}: {v}")).collect();
        panic!(
            "{} cases differ:\n{}\n\n{}",
            by_op.values().sum::<usize>(),
            summary.join("\n"),
            failures.join("\n")
        );
    }
}

//! `wp::bf16` of the CUDA C++ library (`warp-cuda/cuda/wp_core.h` and the bf16 overloads of
//! `wp_scalar.h`, `wp_atomic.h`, `wp_adjoint.h`) against the CPU backend (`half::bf16` and
//! warp-core), on the host, bit for bit; the twin of `cuda_f16_host.rs`.
//!
//! The library converts bf16 in software on every target (the device too), transcribing
//! `half`'s conversions, so every result must equal the CPU's exactly, NaN payloads included.
//! Cases: all 65,536 bf16 -> f32, f64 and integer conversions; f32 -> bf16 at every bf16
//! value, every tie and the f32 values next to each tie, both signs, plus 200,000
//! pseudo-random f32 bit patterns; f64 -> bf16 rounded once (the same points, and points just
//! off the ties that rounding through f32 would move onto them); 32- and 64-bit integers ->
//! bf16 rounded once (64-bit values just off a tie past 2^24); f16 <-> bf16 every pattern;
//! `+ - * / %` and comparisons on 120,000 pairs; the scalar builtins; the adjoints of the
//! operators, builtins and casts; the host atomics. Skipped, saying so, without g++.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::process::Command;

use warp_lang::__private::adjoint as adj;
use warp_lang::__private::builtins as b;
use warp_lang::__private::ops::{FromBf16, ToBf16};
use warp_lang::{bf16, f16};

/// The C++ side: reads `op operands..` lines (hex bit patterns), prints one hex result line
/// per case (several space-separated words for adjoints).
const DRIVER: &str = r#"
#include "wp.h"
#include "wp_adjoint.h"
#include <cstdio>
#include <cstring>
#include <cinttypes>
using namespace wp;
static bf16 H(unsigned long long b) { return bf16_from_bits((u16)b); }
static unsigned hb(bf16 h) { return h.bits; }
int main(int argc, char** argv) {
  if (argc < 2) return 1;
  FILE* in = std::fopen(argv[1], "r");
  if (!in) return 2;
  char op[32];
  unsigned long long a, b, c;
  while (std::fscanf(in, "%31s %llx %llx %llx", op, &a, &b, &c) == 4) {
    const bf16 x = H(a), y = H(b), z = H(c);
    if (!std::strcmp(op, "h2f")) std::printf("%x\n", f32_to_bits(bf16_to_f32(x)));
    else if (!std::strcmp(op, "f2h")) std::printf("%x\n", hb(bf16_from_f32(f32_from_bits((u32)a))));
    else if (!std::strcmp(op, "d2h")) std::printf("%x\n", hb(cast<bf16>(f64_from_bits(a))));
    else if (!std::strcmp(op, "h2d")) std::printf("%llx\n", (unsigned long long)f64_to_bits(cast<f64>(x)));
    else if (!std::strcmp(op, "i2h")) std::printf("%x\n", hb(cast<bf16>((i32)(u32)a)));
    else if (!std::strcmp(op, "u2h")) std::printf("%x\n", hb(cast<bf16>((u64)a)));
    else if (!std::strcmp(op, "l2h")) std::printf("%x\n", hb(cast<bf16>((i64)a)));
    else if (!std::strcmp(op, "h2b")) std::printf("%x\n", hb(cast<bf16>(f16_from_bits((u16)a))));
    else if (!std::strcmp(op, "b2h")) std::printf("%x\n", (unsigned)cast<f16>(x).bits);
    else if (!std::strcmp(op, "h2i")) std::printf("%x\n", (u32)cast<i32>(x));
    else if (!std::strcmp(op, "h2u8")) std::printf("%x\n", (u32)cast<u8>(x));
    else if (!std::strcmp(op, "h2i64")) std::printf("%llx\n", (unsigned long long)cast<i64>(x));
    else if (!std::strcmp(op, "arith"))
      std::printf("%x %x %x %x %x %x %x\n", hb(x + y), hb(x - y), hb(x * y), hb(x / y),
                  hb(fmod(x, y)), hb(-x),
                  (x < y) | (x <= y) << 1 | (x == y) << 2 | (x != y) << 3 | (x > y) << 4 |
                      (x >= y) << 5);
    else if (!std::strcmp(op, "math"))
      std::printf("%x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x %x\n",
                  hb(sqrt(x)), hb(exp(x)), hb(log(x)), hb(sin(x)), hb(cos(x)), hb(tan(x)),
                  hb(pow(x, y)), hb(abs(x)), hb(sign(x)), hb(floor(x)), hb(ceil(x)),
                  hb(min(x, y)), hb(max(x, y)), hb(clamp(x, y, z)), hb(atan2(x, y)),
                  hb(tanh(x)), hb(round(x)), hb(lerp(x, y, z)), hb(smoothstep(y, z, x)),
                  hb(erf(x)), hb(trunc(x)), hb(frac(x)), hb(asin(x)), hb(exp2(x)), hb(cbrt(x)),
                  hb(degrees(x)), hb(step(x)));
    else if (!std::strcmp(op, "adj")) {
      bf16 ga = adj_zero<bf16>(), gb = adj_zero<bf16>(), gc = adj_zero<bf16>();
      adj_div(x, y, ga, gb, z);
      adj_mul(y, x, gb, ga, z);
      adj_sqrt(x, ga, z);
      adj_pow(x, y, ga, gb, z);
      adj_sin(y, gb, z);
      adj_lerp(x, y, z, ga, gb, gc, y);
      adj_min(x, y, ga, gb, z);
      adj_abs(x, ga, z);
      adj_tanh(x, ga, z);
      adj_log2(y, gb, z);
      adj_rem(x, y, ga, gb, z);
      adj_clamp(x, y, z, ga, gb, gc, x);
      f32 af = 0.25f;
      adj_cast(af, x);
      adj_cast(gc, f64_from_bits(0x3fb999999999999aull));
      adj_cast(gc, 1.0f);
      std::printf("%x %x %x %x\n", hb(ga), hb(gb), hb(gc), f32_to_bits(af));
    } else if (!std::strcmp(op, "adj2")) {
      // One fresh adjoint per call (its start value y), printed in order.
#define ONE(CALL) { bf16 g = y; CALL; std::printf("%x ", hb(g)); }
#define TWO(CALL) { bf16 g = y, h = z; CALL; std::printf("%x %x ", hb(g), hb(h)); }
      ONE(adj_exp(x, g, z)) ONE(adj_log(x, g, z)) ONE(adj_cos(x, g, z)) ONE(adj_tan(x, g, z))
      TWO(adj_atan2(x, y, g, h, z)) ONE(adj_asin(x, g, z)) ONE(adj_acos(x, g, z))
      ONE(adj_atan(x, g, z)) ONE(adj_sinh(x, g, z)) ONE(adj_cosh(x, g, z)) ONE(adj_exp2(x, g, z))
      ONE(adj_log10(x, g, z)) ONE(adj_cbrt(x, g, z)) ONE(adj_erf(x, g, z)) ONE(adj_erfc(x, g, z))
      ONE(adj_erfinv(x, g, z)) ONE(adj_erfcinv(x, g, z)) ONE(adj_frac(x, g, z))
      ONE(adj_degrees(x, g, z)) ONE(adj_radians(x, g, z)) ONE(adj_neg(x, g, z))
      TWO(adj_max(x, y, g, h, z)) TWO(adj_add(x, y, g, h, z)) TWO(adj_sub(x, y, g, h, z))
      ONE(adj_atomic_extreme(x, z, g, y))
      { bf16 g = y, h = z, k = x; adj_smoothstep(y, z, x, g, h, k, y);
        std::printf("%x %x %x\n", hb(g), hb(h), hb(k)); }
#undef ONE
#undef TWO
    } else if (!std::strcmp(op, "atomic")) {
      bf16 cell[2] = {x, y};
      const bf16 o1 = detail::atomic_add_p(&cell[1], z);
      const bf16 o2 = detail::atomic_min_p(&cell[0], z);
      const bf16 o3 = detail::atomic_sub_p(&cell[0], y);
      std::printf("%x %x %x %x %x\n", hb(cell[0]), hb(cell[1]), hb(o1), hb(o2), hb(o3));
    } else return 3;
  }
  return 0;
}
"#;

struct Cases {
    text: String,
    wants: Vec<(String, String)>,
}

impl Cases {
    fn add(&mut self, op: &str, a: u64, b: u64, c: u64, want: String) {
        writeln!(self.text, "{op} {a:x} {b:x} {c:x}").unwrap();
        self.wants
            .push((format!("{op} {a:#x} {b:#x} {c:#x}"), want));
    }
}

fn bits(h: bf16) -> u64 {
    h.to_bits() as u64
}

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
}

/// A pseudo-random bf16: a quarter of them any bit pattern, the rest moderate values (|x| < 8).
fn pick(rng: &mut Rng) -> bf16 {
    let r = rng.next();
    if r.is_multiple_of(4) {
        bf16::from_bits((r >> 8) as u16)
    } else {
        bf16::from_f32(((r >> 16) as u32 as f32 / u32::MAX as f32 - 0.5) * 16.0)
    }
}

fn build() -> Cases {
    let mut c = Cases {
        text: String::new(),
        wants: Vec::new(),
    };
    let mut rng = Rng(0x2545_F491_4F6C_DD1D);
    // bf16 -> f32, f64: every pattern.
    for h in 0..=0xFFFFu16 {
        let x = bf16::from_bits(h);
        c.add("h2f", h as u64, 0, 0, format!("{:x}", x.to_f32().to_bits()));
        c.add(
            "h2d",
            h as u64,
            0,
            0,
            format!("{:x}", f64::from_bf16(x).to_bits()),
        );
        c.add(
            "h2i",
            h as u64,
            0,
            0,
            format!("{:x}", i32::from_bf16(x) as u32),
        );
        c.add("h2u8", h as u64, 0, 0, format!("{:x}", u8::from_bf16(x)));
        c.add(
            "h2i64",
            h as u64,
            0,
            0,
            format!("{:x}", i64::from_bf16(x) as u64),
        );
    }
    // f32 -> bf16 and f64 -> bf16: every value, midpoint (tie) and the neighbours of the tie.
    let mut f32s: Vec<f32> = Vec::new();
    let mut f64s: Vec<f64> = Vec::new();
    for h in 0..0x7F80u16 {
        let v = bf16::from_bits(h).to_f64();
        let next = if h == 0x7F7F {
            2f64.powi(128)
        } else {
            bf16::from_bits(h + 1).to_f64()
        };
        let mid = (v + next) / 2.0;
        let m32 = mid as f32; // exact
        for s in [1.0f32, -1.0] {
            f32s.extend([
                s * v as f32,
                s * m32,
                s * f32::from_bits(m32.to_bits() - 1),
                s * f32::from_bits(m32.to_bits() + 1),
            ]);
        }
        for s in [1.0f64, -1.0] {
            f64s.extend([
                s * v,
                s * mid,
                s * f64::from_bits(mid.to_bits() - 1),
                s * f64::from_bits(mid.to_bits() + 1),
                // Off the tie by less than f32 resolves: through f32 these land on the tie.
                s * (mid + mid * 2f64.powi(-40)),
                s * (mid - mid * 2f64.powi(-40)),
            ]);
        }
    }
    for _ in 0..200_000 {
        f32s.push(f32::from_bits(rng.next() as u32));
        f64s.push(f64::from_bits(rng.next()));
    }
    f32s.extend([
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        -f32::NAN,
        1e-40,
        -1e-45,
    ]);
    f64s.extend([
        f64::INFINITY,
        f64::NAN,
        1e-320,
        -1e300,
        3.3961e38,
        3.3962e38,
        -1e-300,
    ]);
    for &x in &f32s {
        c.add(
            "f2h",
            x.to_bits() as u64,
            0,
            0,
            format!("{:x}", bf16::from_f32(x).to_bits()),
        );
    }
    for &x in &f64s {
        c.add(
            "d2h",
            x.to_bits(),
            0,
            0,
            format!("{:x}", x.to_bf16().to_bits()),
        );
    }
    // Integers -> bf16.
    for k in 0..20_000u64 {
        let r = rng.next();
        let i = (r as i32) >> (k % 32);
        c.add(
            "i2h",
            i as u32 as u64,
            0,
            0,
            format!("{:x}", i.to_bf16().to_bits()),
        );
        let u = r >> (k % 64);
        c.add("u2h", u, 0, 0, format!("{:x}", u.to_bf16().to_bits()));
        let l = (rng.next() as i64) >> (k % 64);
        c.add(
            "l2h",
            l as u64,
            0,
            0,
            format!("{:x}", l.to_bf16().to_bits()),
        );
    }
    // Integers just off a tie past 2^24, where rounding through f32 would round twice.
    for e in 25..63u32 {
        for off in [1i64, -1] {
            let l = (1i64 << e) + (1i64 << (e - 8)) + off;
            c.add(
                "l2h",
                l as u64,
                0,
                0,
                format!("{:x}", l.to_bf16().to_bits()),
            );
            c.add(
                "l2h",
                (-l) as u64,
                0,
                0,
                format!("{:x}", (-l).to_bf16().to_bits()),
            );
            c.add(
                "u2h",
                l as u64,
                0,
                0,
                format!("{:x}", (l as u64).to_bf16().to_bits()),
            );
        }
    }
    for v in [i64::MIN, i64::MAX, 0, -1] {
        c.add(
            "l2h",
            v as u64,
            0,
            0,
            format!("{:x}", v.to_bf16().to_bits()),
        );
    }
    // f16 <-> bf16: every pattern each way, rounded once.
    for p in 0..=0xFFFFu16 {
        let hx = f16::from_bits(p);
        c.add(
            "h2b",
            p as u64,
            0,
            0,
            format!("{:x}", hx.to_bf16().to_bits()),
        );
        let bx = bf16::from_bits(p);
        c.add(
            "b2h",
            p as u64,
            0,
            0,
            format!("{:x}", f16::from_bf16(bx).to_bits()),
        );
    }
    // Operators, builtins, adjoints, atomics on pseudo-random bf16 operands (all patterns:
    // subnormals, infinities, NaNs), with a bias towards moderate values where the results
    // are neither overflowed nor zero.
    let h = bf16::from_f32;
    for _ in 0..120_000 {
        let (x, y) = (pick(&mut rng), pick(&mut rng));
        let cmp = (x < y) as u32
            | ((x <= y) as u32) << 1
            | ((x == y) as u32) << 2
            | ((x != y) as u32) << 3
            | ((x > y) as u32) << 4
            | ((x >= y) as u32) << 5;
        let want = format!(
            "{:x} {:x} {:x} {:x} {:x} {:x} {:x}",
            bits(x + y),
            bits(x - y),
            bits(x * y),
            bits(x / y),
            bits(x % y),
            bits(-x),
            cmp
        );
        c.add("arith", bits(x), bits(y), 0, want);
    }
    for _ in 0..30_000 {
        let (x, y, z) = (pick(&mut rng), pick(&mut rng), pick(&mut rng));
        let r = [
            b::sqrt(x),
            b::exp(x),
            b::log(x),
            b::sin(x),
            b::cos(x),
            b::tan(x),
            b::pow(x, y),
            b::abs(x),
            b::sign(x),
            b::floor(x),
            b::ceil(x),
            b::min(x, y),
            b::max(x, y),
            b::clamp(x, y, z),
            b::atan2(x, y),
            b::tanh(x),
            b::round(x),
            b::lerp(x, y, z),
            b::smoothstep(y, z, x),
            b::erf(x),
            b::trunc(x),
            b::frac(x),
            b::asin(x),
            b::exp2(x),
            b::cbrt(x),
            b::degrees(x),
            b::step(x),
        ];
        let want: Vec<String> = r.iter().map(|v| format!("{:x}", v.to_bits())).collect();
        c.add("math", bits(x), bits(y), bits(z), want.join(" "));

        // The same sequence of adjoint calls as the driver.
        let (mut ga, mut gb, mut gc) = (bf16::ZERO, bf16::ZERO, bf16::ZERO);
        adj::adj_div(x, y, &mut ga, &mut gb, z);
        adj::adj_mul(y, x, &mut gb, &mut ga, z);
        adj::adj_sqrt(x, &mut ga, z);
        adj::adj_pow(x, y, &mut ga, &mut gb, z);
        adj::adj_sin(y, &mut gb, z);
        adj::adj_lerp(x, y, z, &mut ga, &mut gb, &mut gc, y);
        adj::adj_min(x, y, &mut ga, &mut gb, z);
        adj::adj_abs(x, &mut ga, z);
        adj::adj_tanh(x, &mut ga, z);
        adj::adj_log2(y, &mut gb, z);
        adj::adj_rem(x, y, &mut ga, &mut gb, z);
        adj::adj_clamp(x, y, z, &mut ga, &mut gb, &mut gc, x);
        let mut af = 0.25f32;
        adj::adj_cast(&mut af, x);
        adj::adj_cast(&mut gc, 0.1f64);
        adj::adj_cast(&mut gc, 1.0f32);
        let want = format!(
            "{:x} {:x} {:x} {:x}",
            ga.to_bits(),
            gb.to_bits(),
            gc.to_bits(),
            af.to_bits()
        );
        c.add("adj", bits(x), bits(y), bits(z), want);

        let mut w: Vec<String> = Vec::new();
        let mut one = |f: &dyn Fn(&mut bf16)| {
            let mut g = y;
            f(&mut g);
            w.push(format!("{:x}", g.to_bits()));
        };
        one(&|g| adj::adj_exp(x, g, z));
        one(&|g| adj::adj_log(x, g, z));
        one(&|g| adj::adj_cos(x, g, z));
        one(&|g| adj::adj_tan(x, g, z));
        let (mut g, mut k) = (y, z);
        adj::adj_atan2(x, y, &mut g, &mut k, z);
        w.push(format!("{:x} {:x}", g.to_bits(), k.to_bits()));
        let mut one = |f: &dyn Fn(&mut bf16)| {
            let mut g = y;
            f(&mut g);
            w.push(format!("{:x}", g.to_bits()));
        };
        one(&|g| adj::adj_asin(x, g, z));
        one(&|g| adj::adj_acos(x, g, z));
        one(&|g| adj::adj_atan(x, g, z));
        one(&|g| adj::adj_sinh(x, g, z));
        one(&|g| adj::adj_cosh(x, g, z));
        one(&|g| adj::adj_exp2(x, g, z));
        one(&|g| adj::adj_log10(x, g, z));
        one(&|g| adj::adj_cbrt(x, g, z));
        one(&|g| adj::adj_erf(x, g, z));
        one(&|g| adj::adj_erfc(x, g, z));
        one(&|g| adj::adj_erfinv(x, g, z));
        one(&|g| adj::adj_erfcinv(x, g, z));
        one(&|g| adj::adj_frac(x, g, z));
        one(&|g| adj::adj_degrees(x, g, z));
        one(&|g| adj::adj_radians(x, g, z));
        one(&|g| adj::adj_neg(x, g, z));
        type Bin = fn(bf16, bf16, &mut bf16, &mut bf16, bf16);
        let bins: [Bin; 3] = [adj::adj_max, adj::adj_add, adj::adj_sub];
        for f in bins {
            let (mut g, mut k) = (y, z);
            f(x, y, &mut g, &mut k, z);
            w.push(format!("{:x} {:x}", g.to_bits(), k.to_bits()));
        }
        let mut g = y;
        warp_lang::__private::adj_atomic_extreme(x, z, &mut g, y);
        w.push(format!("{:x}", g.to_bits()));
        let (mut g, mut k, mut l) = (y, z, x);
        adj::adj_smoothstep(y, z, x, &mut g, &mut k, &mut l, y);
        w.push(format!(
            "{:x} {:x} {:x}",
            g.to_bits(),
            k.to_bits(),
            l.to_bits()
        ));
        c.add("adj2", bits(x), bits(y), bits(z), w.join(" "));

        let mut cell = [x, y];
        let p = cell.as_mut_ptr();
        // SAFETY: a live local array, touched by this thread only.
        let (o1, o2, o3) = unsafe {
            (
                <bf16 as b::AtomicElement>::atomic_add(p.add(1), z),
                <bf16 as b::AtomicElement>::atomic_min(p, z),
                <bf16 as b::AtomicElement>::atomic_sub(p, y),
            )
        };
        let want = format!(
            "{:x} {:x} {:x} {:x} {:x}",
            cell[0].to_bits(),
            cell[1].to_bits(),
            o1.to_bits(),
            o2.to_bits(),
            o3.to_bits()
        );
        c.add("atomic", bits(x), bits(y), bits(z), want);
    }
    // A few hand-picked cases the random ones may miss.
    for (x, y) in [
        (bf16::MAX, h(2.0)),
        (bf16::from_bits(1), h(0.5)),
        (h(-0.0), h(0.0)),
    ] {
        let want = format!(
            "{:x} {:x} {:x} {:x} {:x} {:x} {:x}",
            bits(x + y),
            bits(x - y),
            bits(x * y),
            bits(x / y),
            bits(x % y),
            bits(-x),
            (x < y) as u32
                | ((x <= y) as u32) << 1
                | ((x == y) as u32) << 2
                | ((x != y) as u32) << 3
                | ((x > y) as u32) << 4
                | ((x >= y) as u32) << 5
        );
        c.add("arith", bits(x), bits(y), 0, want);
    }
    c
}

/// Conversions must match bit for bit, NaNs included. Results of arithmetic on two NaN
/// operands carry the payload of one of them, and which one depends on the order in which
/// the compiler feeds a commutative x86 instruction (`addss` returns its first operand's
/// NaN): there a NaN equals any NaN (bf16 words; the f32 adjoint of a cast, word 3 of `adj`).
fn same_result(case: &str, want: &str, got: &str) -> bool {
    if want == got {
        return true;
    }
    let op = case.split(' ').next().unwrap_or("");
    if !matches!(op, "arith" | "math" | "adj" | "adj2" | "atomic") {
        return false;
    }
    let (w, g): (Vec<&str>, Vec<&str>) = (want.split(' ').collect(), got.split(' ').collect());
    w.len() == g.len()
        && w.iter().zip(&g).enumerate().all(|(k, (w, g))| {
            let (Ok(w), Ok(g)) = (u32::from_str_radix(w, 16), u32::from_str_radix(g, 16)) else {
                return false;
            };
            let nan = |x: u32| {
                if op == "adj" && k == 3 {
                    f32::from_bits(x).is_nan()
                } else {
                    x <= 0xFFFF && bf16::from_bits(x as u16).is_nan()
                }
            };
            w == g || (nan(w) && nan(g))
        })
}

#[test]
fn cuda_bf16_matches_half_on_the_host() {
    let c = build();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::temp_dir().join(format!("warp_cuda_bf16_host_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (src, exe, cases) = (
        dir.join("bf16.cpp"),
        dir.join("bf16"),
        dir.join("cases.txt"),
    );
    std::fs::write(&src, DRIVER).unwrap();
    std::fs::write(&cases, &c.text).unwrap();
    let cxx = std::env::var("CXX").unwrap_or_else(|_| "g++".into());
    let build = match Command::new(&cxx)
        .args(["-std=c++17", "-O1", "-Wall", "-Wextra", "-Werror", "-I"])
        .arg(root.join("warp-cuda/cuda"))
        .arg("-o")
        .arg(&exe)
        .arg(&src)
        .output()
    {
        Ok(o) => o,
        Err(_) => {
            println!("SKIPPED: no g++ ({cxx} could not be run)");
            return;
        }
    };
    assert!(
        build.status.success(),
        "the bf16 driver does not compile:\n{}",
        String::from_utf8_lossy(&build.stderr)
    );
    let run = Command::new(&exe).arg(&cases).output().expect("run");
    assert!(
        run.status.success(),
        "driver failed ({:?}): {}",
        run.status,
        String::from_utf8_lossy(&run.stderr)
    );
    let _ = std::fs::remove_dir_all(&dir);
    let out = String::from_utf8(run.stdout).expect("utf-8");
    let lines: Vec<&str> = out.lines().collect();
    assert_eq!(lines.len(), c.wants.len(), "one result line per case");
    let mut bad = Vec::new();
    for ((case, want), got) in c.wants.iter().zip(&lines) {
        if !same_result(case, want, got) {
            bad.push(format!("{case}: C++ {got}, Rust {want}"));
        }
    }
    println!("{} cases", c.wants.len());
    assert!(
        bad.is_empty(),
        "{} of {} cases differ; first ones:\n{}",
        bad.len(),
        c.wants.len(),
        bad[..bad.len().min(20)].join("\n")
    );
}

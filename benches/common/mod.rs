//! What the benchmarks share: timing, the Python sides (Warp's, PyTorch's) run in the same
//! process's run, and fixed random inputs.

#![allow(dead_code)] // each bench takes its own subset

use std::process::Command;
use std::time::{Duration, Instant};

use glam::Vec3;
use warp_lang as wp;

pub const REPS: usize = 15;

pub fn median_ms(mut f: impl FnMut() -> wp::Result<()>) -> wp::Result<f64> {
    f()?;
    wp::synchronize()?;
    let mut t = Vec::with_capacity(REPS);
    for _ in 0..REPS {
        wp::synchronize()?;
        let s = Instant::now();
        f()?;
        wp::synchronize()?;
        t.push(s.elapsed().as_secs_f64() * 1e3);
    }
    t.sort_by(f64::total_cmp);
    Ok(t[REPS / 2])
}

/// Median of `runs` timings of `f` (a CPU call: nothing to synchronise).
pub fn median(runs: usize, mut f: impl FnMut()) -> Duration {
    let mut t: Vec<Duration> = (0..runs)
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed()
        })
        .collect();
    t.sort();
    t[runs / 2]
}

/// Runs `script` with `args` under `python3`; its last line parsed as JSON, or why not.
pub fn python_side(script: &str, args: &[String]) -> Result<String, String> {
    let out = Command::new("python3")
        .arg(script)
        .args(args)
        .output()
        .map_err(|e| format!("python3: {e}"))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        return Err(err.lines().last().unwrap_or("failed").to_string());
    }
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    text.lines()
        .last()
        .map(str::to_string)
        .ok_or_else(|| "no output".into())
}

/// The number after `"key":` in a flat JSON text (the Python sides print flat objects, and
/// nested ones only under size keys, which the caller slices out first).
pub fn json_number(json: &str, key: &str) -> Option<f64> {
    let at = json.find(&format!("\"{key}\":"))? + key.len() + 3;
    let rest = json[at..].trim_start();
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | '-' | 'e' | 'E' | '+')))
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// The object under `"n"` in the PyTorch side's `sizes`.
pub fn size_section(json: &str, n: usize) -> Option<&str> {
    let at = json.find(&format!("\"{n}\":"))?;
    let end = json[at..].find('}')? + at;
    Some(&json[at..end])
}

pub fn ratio(ours: f64, theirs: Option<f64>) -> String {
    match theirs {
        Some(t) => format!("{t:8.3} ms   ratio {:.2}", ours / t),
        None => "       -".into(),
    }
}

/// A fixed xorshift sequence: the same inputs on every run.
pub struct XorShift(pub u64);

impl XorShift {
    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    /// Uniform in [0, 1), 24 bits.
    pub fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// `n` points uniform in a cube of side `side`.
pub fn uniform_points(n: usize, side: f32, seed: u64) -> Vec<Vec3> {
    let mut r = XorShift(seed);
    (0..n)
        .map(|_| Vec3::new(r.unit(), r.unit(), r.unit()) * side)
        .collect()
}

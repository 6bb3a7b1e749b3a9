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
pub fn python_side(script: &str, args: &[String]) -> Result<serde_json::Value, String> {
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
    let last = text.lines().last().ok_or("no output")?;
    serde_json::from_str(last).map_err(|e| format!("{script}: its last line is not JSON ({e})"))
}

/// The number under `key` in an object a Python side printed.
pub fn json_number(json: &serde_json::Value, key: &str) -> Option<f64> {
    json.get(key)?.as_f64()
}

/// The object under `sizes."n"` in the PyTorch side's output.
pub fn size_section(json: &serde_json::Value, n: usize) -> Option<&serde_json::Value> {
    json.get("sizes")?.get(n.to_string())
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

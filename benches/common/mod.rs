//! What the benchmarks share: timing, the Python sides (Warp's, PyTorch's) run in the same
//! process's run, and fixed random inputs.

#![allow(dead_code)] // each bench takes its own subset

use std::process::Command;
use std::time::{Duration, Instant};

use glam::Vec3;
use rand::Rng as _;
use warp_lang as wp;

pub const REPS: usize = 15;

/// The median of `samples`: the middle one after sorting (of an even count, the upper of the
/// two middle ones). Every bench's median is this one, so their tables agree on what a median
/// is. Timings are never NaN; one would sort as equal to its neighbours.
pub fn median_of<T: Copy + PartialOrd>(mut samples: Vec<T>) -> T {
    assert!(!samples.is_empty(), "median_of: no samples");
    samples.sort_by(|a, b| a.partial_cmp(b).unwrap_or(std::cmp::Ordering::Equal));
    samples[samples.len() / 2]
}

/// Median milliseconds of `REPS` runs of `f` after one warm-up run, the device synchronised
/// around each (GPU launches are asynchronous).
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
    Ok(median_of(t))
}

/// GPU milliseconds per call of `calls` calls of `f` queued back to back between two CUDA
/// events on the device's current stream: median of `REPS` after a warm-up (compilation and
/// scratch growth out of the timing). With one call the events also hold the host's dispatch
/// of it (the GPU waits for it); once the host queues calls faster than the GPU runs them, the
/// per-call figure of many is the device's time alone.
#[cfg(feature = "cuda")]
pub fn event_ms_per_call(
    dev: &wp::Device,
    calls: usize,
    mut f: impl FnMut() -> wp::Result<()>,
) -> wp::Result<f64> {
    let stream = wp::get_stream(dev)?;
    f()?;
    let mut times = Vec::with_capacity(REPS);
    for _ in 0..REPS {
        let start = stream.record_event()?;
        for _ in 0..calls {
            f()?;
        }
        let end = stream.record_event()?;
        times.push(start.elapsed_ms(&end)? as f64 / calls as f64);
    }
    Ok(median_of(times))
}

/// GPU milliseconds between CUDA events around one call of `f` ([`event_ms_per_call`] of 1),
/// as the Python sides time theirs.
#[cfg(feature = "cuda")]
pub fn event_ms(dev: &wp::Device, f: impl FnMut() -> wp::Result<()>) -> wp::Result<f64> {
    event_ms_per_call(dev, 1, f)
}

/// Median of `runs` timings of `f` on `state`, each after an untimed `setup` of it (a CPU
/// call: nothing to synchronise).
pub fn median_on<S>(
    runs: usize,
    state: &mut S,
    mut setup: impl FnMut(&mut S),
    mut f: impl FnMut(&mut S),
) -> Duration {
    median_of(
        (0..runs)
            .map(|_| {
                setup(state);
                let s = Instant::now();
                f(state);
                s.elapsed()
            })
            .collect(),
    )
}

/// Median of `runs` timings of `f`, each after an untimed `setup`.
pub fn median_after(runs: usize, mut setup: impl FnMut(), mut f: impl FnMut()) -> Duration {
    median_on(runs, &mut (), |_| setup(), |_| f())
}

/// Median of `runs` timings of `f` (a CPU call: nothing to synchronise).
pub fn median(runs: usize, f: impl FnMut()) -> Duration {
    median_after(runs, || {}, f)
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

/// The benches' random inputs: ChaCha8 (rand_chacha) with a fixed seed, the same inputs on
/// every run and platform (its stream is fixed by the algorithm). Samples come from
/// `rand::Rng::random` (a uniform `f32` in [0, 1), a `u64`, ...).
pub type Rng = rand_chacha::ChaCha8Rng;

/// The generator of `seed`.
pub fn rng(seed: u64) -> Rng {
    rand::SeedableRng::seed_from_u64(seed)
}

/// `n` points uniform in a cube of side `side`.
pub fn uniform_points(n: usize, side: f32, seed: u64) -> Vec<Vec3> {
    let mut r = rng(seed);
    (0..n)
        .map(|_| Vec3::new(r.random(), r.random(), r.random()) * side)
        .collect()
}

//! GPU benchmark of neighbour search and its parallel primitives, against PyTorch and NVIDIA
//! Warp timed on the same GPU in the same run (their sides are the Python scripts in
//! `benches/py/`, run by this binary; a side that cannot run is reported and skipped).
//!
//! ```text
//! cargo bench --bench spatial                  # needs a CUDA device; SKIPPED otherwise
//! # on the GPU machine, with Warp unpacked by ../shared/tools/warp-bundle:
//! PYTHONPATH=/root/warp-lang .gpu/bin/spatial-*
//! ```
//!
//! Primitives (PyTorch: torch.sort with stable=True and a gather of the values, torch.cumsum,
//! torch.sum): a stable key/value radix sort (i32 and f32 keys), inclusive scans and a sum, at
//! 1M and 16M elements. Each figure is a median of timed repetitions after a warm-up
//! (compilation excluded), synchronised around every repetition; every result is checked
//! against the CPU backend's.

use std::process::Command;
use std::time::Instant;
use warp_lang as wp;

const REPS: usize = 15;

fn median_ms(mut f: impl FnMut() -> wp::Result<()>) -> wp::Result<f64> {
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

/// Runs `script` with `args` under `python3`; its last line parsed as JSON, or why not.
fn python_side(script: &str, args: &[String]) -> Result<String, String> {
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
fn json_number(json: &str, key: &str) -> Option<f64> {
    let at = json.find(&format!("\"{key}\":"))? + key.len() + 3;
    let rest = json[at..].trim_start();
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || matches!(c, '.' | '-' | 'e' | 'E' | '+')))
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// The object under `"n"` in the PyTorch side's `sizes`.
fn size_section(json: &str, n: usize) -> Option<&str> {
    let at = json.find(&format!("\"{n}\":"))?;
    let end = json[at..].find('}')? + at;
    Some(&json[at..end])
}

fn ratio(ours: f64, theirs: Option<f64>) -> String {
    match theirs {
        Some(t) => format!("{t:8.3} ms   ratio {:.2}", ours / t),
        None => "       -".into(),
    }
}

fn main() -> wp::Result<()> {
    wp::init();
    let dev = match wp::get_device("cuda:0") {
        Ok(d) => d,
        Err(e) => {
            println!("spatial bench SKIPPED: no CUDA device ({e})");
            return Ok(());
        }
    };
    println!("spatial bench on {dev}");
    primitives(&dev)
}

fn primitives(dev: &wp::Device) -> wp::Result<()> {
    let sizes = [1usize << 20, 1 << 24];
    let torch = python_side(
        "benches/py/torch_primitives.py",
        &sizes.iter().map(|n| n.to_string()).collect::<Vec<_>>(),
    );
    match &torch {
        Ok(_) => println!("PyTorch side: ran in this process's run"),
        Err(e) => println!("PyTorch side not run: {e}"),
    }
    let cpu = wp::get_device("cpu")?;
    println!(
        "{:<28} {:>10}   {:>31}",
        "primitive (n)", "warp-lang", "PyTorch, ratio warp / torch"
    );
    for n in sizes {
        let section = torch.as_ref().ok().and_then(|t| size_section(t, n));
        let theirs = |k: &str| section.and_then(|s| json_number(s, k));
        // Keys: a fixed pseudo-random sequence (the same on every run).
        let mut s = 0x2545_f491u64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let ki: Vec<i32> = (0..n).map(|_| (next() >> 33) as i32).collect();
        let kf: Vec<f32> = (0..n)
            .map(|_| (next() >> 40) as f32 / (1u64 << 24) as f32)
            .collect();
        let vals: Vec<i32> = (0..n as i32).collect();
        let small: Vec<i32> = (0..n).map(|_| (next() % 100) as i32).collect();

        let ms = sort_case(&ki, &vals, dev, &cpu)?;
        println!(
            "{:<28} {ms:7.3} ms   {}",
            format!("sort pairs i32 ({n})"),
            ratio(ms, theirs("sort_pairs_i32_ms"))
        );
        let ms = sort_case(&kf, &vals, dev, &cpu)?;
        println!(
            "{:<28} {ms:7.3} ms   {}",
            format!("sort pairs f32 ({n})"),
            ratio(ms, theirs("sort_pairs_f32_ms"))
        );

        let a = wp::Array::from_slice(&small, dev)?;
        let out = wp::Array::<i32>::zeros(n, dev)?;
        wp::array_scan(&a, &out, true)?;
        let want: Vec<i32> = small
            .iter()
            .scan(0i32, |acc, x| {
                *acc = acc.wrapping_add(*x);
                Some(*acc)
            })
            .collect();
        assert_eq!(out.to_vec()?, want, "scan i32");
        let ms = median_ms(|| wp::array_scan(&a, &out, true))?;
        println!(
            "{:<28} {ms:7.3} ms   {}",
            format!("inclusive scan i32 ({n})"),
            ratio(ms, theirs("cumsum_i32_ms"))
        );

        let f = wp::Array::from_slice(&kf, dev)?;
        let fout = wp::Array::<f32>::zeros(n, dev)?;
        let ms = median_ms(|| wp::array_scan(&f, &fout, true))?;
        let last = fout.to_vec()?[n - 1] as f64;
        let exact: f64 = kf.iter().map(|&x| x as f64).sum();
        println!(
            "{:<28} {ms:7.3} ms   {}   last element rel err vs f64 {:.1e}",
            format!("inclusive scan f32 ({n})"),
            ratio(ms, theirs("cumsum_f32_ms")),
            ((last - exact) / exact).abs()
        );

        let sum = wp::Array::<f32>::zeros(1, dev)?;
        let ms = median_ms(|| wp::array_sum(&f, &sum))?;
        let got = sum.to_vec()?[0] as f64;
        println!(
            "{:<28} {ms:7.3} ms   {}   rel err vs f64 {:.1e}",
            format!("sum f32 ({n})"),
            ratio(ms, theirs("sum_f32_ms")),
            ((got - exact) / exact).abs()
        );
    }
    Ok(())
}

/// A stable key/value sort on the GPU, checked against the CPU backend's, then timed. The
/// timed repetitions sort the already sorted arrays again: a radix sort runs every pass
/// whatever the order, so this times the same work without re-uploading.
fn sort_case<K: wp::primitives::SortKey>(
    keys: &[K],
    vals: &[i32],
    dev: &wp::Device,
    cpu: &wp::Device,
) -> wp::Result<f64> {
    let n = keys.len();
    let (k, v) = (
        wp::Array::from_slice(keys, dev)?,
        wp::Array::from_slice(vals, dev)?,
    );
    let (kc, vc) = (
        wp::Array::from_slice(keys, cpu)?,
        wp::Array::from_slice(vals, cpu)?,
    );
    wp::radix_sort_pairs(&kc, &vc, n, None)?;
    wp::radix_sort_pairs(&k, &v, n, None)?;
    assert_eq!(v.to_vec()?, vc.to_vec()?, "GPU and CPU sorts disagree");
    median_ms(|| wp::radix_sort_pairs(&k, &v, n, None))
}

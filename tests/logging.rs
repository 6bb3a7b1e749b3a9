//! The diagnostics warp-lang sends to the `log` facade: a test logger (no logger crate)
//! captures every record, and the test checks the ones that initialisation, device selection
//! and the kernel cache must emit, and that CPU launches emit none.
//!
//! A test binary of its own because `log::set_logger` is process-wide and works once: one
//! `#[test]` installs the logger and runs the steps in order (the runtime, too, initialises
//! once per process).

use std::sync::Mutex;
use warp_lang as wp;
use wp::prelude::*;

/// One captured record.
#[derive(Clone, Debug)]
struct Rec {
    level: log::Level,
    target: String,
    message: String,
}

/// Keeps every record, from every thread.
struct Capture(Mutex<Vec<Rec>>);

impl log::Log for Capture {
    fn enabled(&self, _: &log::Metadata<'_>) -> bool {
        true
    }

    fn log(&self, record: &log::Record<'_>) {
        let rec = Rec {
            level: record.level(),
            target: record.target().to_string(),
            message: record.args().to_string(),
        };
        self.0.lock().unwrap_or_else(|p| p.into_inner()).push(rec);
    }

    fn flush(&self) {}
}

static LOGGER: Capture = Capture(Mutex::new(Vec::new()));

fn records() -> Vec<Rec> {
    LOGGER.0.lock().unwrap_or_else(|p| p.into_inner()).clone()
}

/// The first record of `target` at `level` whose message contains `text`, or a panic listing
/// what was captured.
#[track_caller]
fn find(target: &str, level: log::Level, text: &str) -> Rec {
    let all = records();
    all.iter()
        .find(|r| r.target == target && r.level == level && r.message.contains(text))
        .cloned()
        .unwrap_or_else(|| {
            panic!("no {level} record of {target} containing {text:?}; captured: {all:#?}")
        })
}

#[wp::kernel]
fn add_one(a: Array<f32>) {
    let i = tid();
    a[i] = a[i] + 1.0;
}

/// A fresh directory under the system's temporary one, removed on drop.
struct TempDir(std::path::PathBuf);

impl TempDir {
    fn new(tag: &str) -> Self {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        let dir = std::env::temp_dir().join(format!(
            "warp-lang-logging-{tag}-{}-{nanos}",
            std::process::id()
        ));
        std::fs::create_dir_all(&dir).unwrap();
        TempDir(dir)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn diagnostics_go_to_log() {
    log::set_logger(&LOGGER).expect("the only logger of this test binary");
    log::set_max_level(log::LevelFilter::Trace);

    // Initialisation: the banner at info (and nowhere else: nothing goes to stdout), once.
    let rt = wp::init();
    let banner = find("warp_runtime::device", log::Level::Info, "initialized:");
    assert_eq!(banner.message, rt.banner());
    // What the probe found or why not: info (devices, or no driver / no device) or a warning
    // (a driver that is there but unusable).
    if cfg!(feature = "cuda") {
        let probe = records()
            .into_iter()
            .find(|r| r.target == "warp_cuda::device" && r.message.contains("CUDA"))
            .expect("a record of the CUDA probe");
        assert!(
            matches!(probe.level, log::Level::Info | log::Level::Warn),
            "{probe:?}"
        );
    }
    let banners = |recs: &[Rec]| {
        recs.iter()
            .filter(|r| r.message.contains("initialized:"))
            .count()
    };
    wp::init();
    assert_eq!(banners(&records()), 1, "init logs its banner once");

    // Device selection, with the reason when it falls back to the CPU.
    let preferred = wp::get_preferred_device();
    let wanted = format!("preferred device: \"{}\"", preferred.alias());
    match wp::cpu_fallback_reason() {
        // A GPU without NVRTC (or `WARP_LANG_NO_NVRTC` set): a warning naming the GPU passed
        // over and why.
        Some(why) => {
            let said = find("warp_runtime::device", log::Level::Warn, &wanted);
            assert!(said.message.contains(&why), "{said:?}");
        }
        None => {
            let said = find("warp_runtime::device", log::Level::Info, &wanted);
            if preferred.is_cpu() {
                assert!(said.message.contains("no CUDA device"), "{said:?}");
            }
        }
    }

    // CPU launches are the hot path: no record at any level, even with trace enabled.
    let cpu = wp::cpu();
    let a = wp::Array::<f32>::zeros(64, &cpu).unwrap();
    let before = records().len();
    for _ in 0..100 {
        wp::launch(add_one, 64, (&a,), &cpu).unwrap();
    }
    assert_eq!(a.to_vec().unwrap(), vec![100.0; 64]);
    let after = records();
    assert_eq!(
        after.len(),
        before,
        "CPU launches logged {:#?}",
        &after[before..]
    );

    // The kernel cache: a hit under the NVRTC version of the cache's stamp needs no NVRTC, so
    // it runs on any machine. The stamp is the file `nvrtc-version` holding "major.minor".
    let dir = TempDir::new("cache");
    let cache = warp_cuda::KernelCache::new(&dir.0);
    let opts = warp_cuda::CompileOptions::default();
    let key = warp_cuda::cache_key("source", "logged", &opts, 90, (99, 7));
    cache.store("logged", key, b"cubin").unwrap();
    std::fs::write(dir.0.join("nvrtc-version"), "99.7\n").unwrap();
    let (_, outcome) = cache.compile_cached("source", "logged", &opts, 90).unwrap();
    assert_eq!(outcome, warp_cuda::CacheOutcome::Hit);
    find(
        "warp_cuda::cache",
        log::Level::Debug,
        "kernel cache hit: logged (sm_90",
    );

    gpu_records();
}

/// On a GPU, a first launch logs the module cache miss, the kernel cache miss, NVRTC's
/// compile time and the loaded kernel; the next launch only a trace record of the module
/// cache hit. Skipped without a device.
fn gpu_records() {
    let dev = match wp::get_device("cuda:0") {
        Ok(dev) => dev,
        Err(e) => {
            eprintln!("SKIPPED logging::gpu_records: no CUDA device ({e})");
            return;
        }
    };
    // These records are of a compile: without NVRTC there is none to log.
    if let Some(why) = wp::cpu_fallback_reason() {
        eprintln!("SKIPPED logging::gpu_records: {why}");
        return;
    }
    // An empty cache, so that the kernel is compiled here.
    let dir = TempDir::new("gpu");
    warp_cuda::set_cache_dir(Some(dir.0.clone()));
    let a = wp::Array::<f32>::zeros(64, &dev).unwrap();
    wp::launch(add_one, 64, (&a,), &dev).unwrap();
    wp::launch(add_one, 64, (&a,), &dev).unwrap();
    assert_eq!(a.to_vec().unwrap(), vec![2.0; 64]);
    warp_cuda::set_cache_dir(None);
    let module = "warp_runtime::cuda::module";
    find(
        module,
        log::Level::Debug,
        "module cache miss: logging::add_one on cuda:0",
    );
    find(
        "warp_cuda::cache",
        log::Level::Debug,
        "kernel cache miss: add_one",
    );
    let compiled = find(
        "warp_cuda::compile",
        log::Level::Info,
        "NVRTC compiled add_one",
    );
    assert!(compiled.message.contains(" ms "), "{compiled:?}");
    find(module, log::Level::Info, "loaded kernel logging::add_one");
    find(
        module,
        log::Level::Trace,
        "module cache hit: logging::add_one on cuda:0",
    );
}

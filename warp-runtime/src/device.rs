//! Devices: where arrays live and kernels run.
//!
//! Devices are named by Warp's aliases: `"cpu"`, `"cuda:0"`, `"cuda:1"`, ... This build has
//! only the CPU backend; asking for a CUDA device is an error that says so, and code written as
//! `get_device("cuda:0").unwrap_or(cpu())` runs on the CPU. No GPU is a normal situation.

use crate::error::{Error, Result};
use std::fmt;
use std::hash::{Hash, Hasher};
use std::sync::{Arc, OnceLock};

/// Why CUDA devices cannot be used by this build.
#[cfg(not(feature = "cuda"))]
pub(crate) const CUDA_UNAVAILABLE: &str =
    "this build of warp-lang has no CUDA support (the `cuda` feature is off)";

/// What kind of device a [`Device`] is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DeviceKind {
    /// The host CPU; kernels run on the rayon thread pool.
    Cpu,
    /// A CUDA GPU.
    Cuda {
        /// The CUDA device ordinal (the `N` of `"cuda:N"`).
        ordinal: usize,
    },
}

/// A device: the CPU or a CUDA GPU.
///
/// Cheap to clone (a shared handle). Two `Device`s are equal when they denote the same device,
/// i.e. when their [`kind`](Device::kind) is equal.
#[derive(Clone, Debug)]
pub struct Device {
    kind: DeviceKind,
    // Shared so that cloning a device (every `Array` holds one) never allocates.
    info: Arc<DeviceInfo>,
}

#[derive(Debug)]
struct DeviceInfo {
    alias: String,
    name: String,
}

impl PartialEq for Device {
    fn eq(&self, other: &Self) -> bool {
        // The kind identifies the device; the other fields are derived from it.
        self.kind == other.kind
    }
}

impl Eq for Device {}

impl Hash for Device {
    fn hash<H: Hasher>(&self, state: &mut H) {
        self.kind.hash(state);
    }
}

impl Device {
    fn new(kind: DeviceKind, name: String) -> Device {
        let alias = match kind {
            DeviceKind::Cpu => "cpu".to_string(),
            DeviceKind::Cuda { ordinal } => format!("cuda:{ordinal}"),
        };
        Device {
            kind,
            info: Arc::new(DeviceInfo { alias, name }),
        }
    }

    /// A CUDA device handle for tests of the code paths that reject it; no such device can be
    /// obtained through the public API of this build.
    #[cfg(test)]
    pub(crate) fn fake_cuda(ordinal: usize) -> Device {
        Device::new(DeviceKind::Cuda { ordinal }, "fake GPU".to_string())
    }

    /// The kind of device.
    pub fn kind(&self) -> DeviceKind {
        self.kind
    }

    /// Warp's alias: `"cpu"` or `"cuda:N"`.
    pub fn alias(&self) -> &str {
        &self.info.alias
    }

    /// A human-readable name: the CPU model (from `/proc/cpuinfo` where readable, else `"CPU"`)
    /// or the GPU's product name.
    pub fn name(&self) -> &str {
        &self.info.name
    }

    /// True for the CPU.
    pub fn is_cpu(&self) -> bool {
        self.kind == DeviceKind::Cpu
    }

    /// True for a CUDA GPU.
    pub fn is_cuda(&self) -> bool {
        matches!(self.kind, DeviceKind::Cuda { .. })
    }

    /// Free and total memory of a GPU as the driver reports them (`cuMemGetInfo`); `None` for
    /// the CPU, whose memory is the operating system's to report.
    ///
    /// The figure is the whole device's: other processes' allocations count, and so does
    /// memory that this crate's arrays freed but the stream-ordered pool keeps for reuse (a
    /// GPU opened by this crate never hands freed memory back to the driver, so `free` falls
    /// to the program's high-water mark and stays there). Opens the GPU (its context) if no
    /// array or launch has yet.
    ///
    /// # Errors
    /// [`Error::Cuda`] when the GPU cannot be opened or the query fails; [`Error::NoDevice`]
    /// for a GPU in a build without the `cuda` feature (no such device can be obtained).
    pub fn memory_info(&self) -> Result<Option<MemoryInfo>> {
        match self.kind {
            DeviceKind::Cpu => Ok(None),
            #[cfg(feature = "cuda")]
            DeviceKind::Cuda { ordinal } => {
                let gpu =
                    warp_cuda::Gpu::open(ordinal).map_err(|e| Error::cuda(self.alias(), e))?;
                let (free, total) = gpu.mem_info().map_err(|e| Error::cuda(self.alias(), e))?;
                Ok(Some(MemoryInfo { free, total }))
            }
            #[cfg(not(feature = "cuda"))]
            DeviceKind::Cuda { .. } => Err(Error::NoDevice {
                name: self.alias().to_string(),
                reason: CUDA_UNAVAILABLE.to_string(),
            }),
        }
    }
}

/// A GPU's free and total memory in bytes ([`Device::memory_info`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryInfo {
    /// Bytes the driver could still allocate on the device.
    pub free: usize,
    /// The device's memory.
    pub total: usize,
}

impl fmt::Display for Device {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.alias())
    }
}

/// The model name of the host CPU, read once.
fn cpu_model_name() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|text| {
            text.lines().find_map(|line| {
                let (key, value) = line.split_once(':')?;
                (key.trim() == "model name").then(|| value.trim().to_string())
            })
        })
        .filter(|name| !name.is_empty())
        .unwrap_or_else(|| "CPU".to_string())
}

/// The process-wide runtime state: the devices found at initialisation.
#[derive(Debug)]
pub struct Runtime {
    devices: Vec<Device>,
    cuda_status: String,
}

impl Runtime {
    /// All devices, the CPU first.
    pub fn devices(&self) -> &[Device] {
        &self.devices
    }

    /// Whether any CUDA device is usable.
    pub fn cuda_available(&self) -> bool {
        self.devices.iter().any(Device::is_cuda)
    }

    /// The warp-lang version, as the banner shows it.
    pub fn version(&self) -> &'static str {
        env!("CARGO_PKG_VERSION")
    }

    /// The banner [`init`] logs: the version, each device, and whether CUDA is available (why
    /// not, if not).
    pub fn banner(&self) -> String {
        let mut s = format!("warp-lang {} initialized:\n   Devices:\n", self.version());
        for d in &self.devices {
            let alias = format!("\"{}\"", d.alias());
            let extra = match d.kind() {
                DeviceKind::Cpu => format!("  ({} threads)", rayon::current_num_threads()),
                DeviceKind::Cuda { .. } => String::new(),
            };
            s.push_str(&format!("     {alias:<10} | {}{extra}\n", d.name()));
        }
        if self.cuda_available() {
            s.push_str("   CUDA: available");
        } else {
            s.push_str(&format!("   CUDA: not available ({})", self.cuda_status));
        }
        s
    }
}

/// The runtime, built on first use without printing anything.
fn runtime() -> &'static Runtime {
    static RUNTIME: OnceLock<Runtime> = OnceLock::new();
    RUNTIME.get_or_init(|| {
        let mut devices = vec![Device::new(DeviceKind::Cpu, cpu_model_name())];
        let (gpus, cuda_status) = cuda_devices();
        devices.extend(gpus);
        let rt = Runtime {
            devices,
            cuda_status,
        };
        // (Why there is no GPU, if none, warp-cuda's probe has said.)
        for d in &rt.devices {
            log::debug!("device \"{}\": {}", d.alias(), d.name());
        }
        rt
    })
}

/// The GPUs the CUDA driver reports, or why there are none. Never panics: no driver, no
/// device and an old driver are all ordinary answers.
#[cfg(feature = "cuda")]
fn cuda_devices() -> (Vec<Device>, String) {
    match warp_cuda::probe() {
        Ok(gpus) if !gpus.is_empty() => {
            let devices = gpus
                .iter()
                .map(|g| {
                    Device::new(
                        DeviceKind::Cuda { ordinal: g.ordinal },
                        format!("{} (sm_{})", g.name, g.arch()),
                    )
                })
                .collect();
            (devices, "available".to_string())
        }
        Ok(_) => (Vec::new(), "the driver reports no CUDA device".to_string()),
        Err(reason) => (Vec::new(), reason),
    }
}

#[cfg(not(feature = "cuda"))]
fn cuda_devices() -> (Vec<Device>, String) {
    (Vec::new(), CUDA_UNAVAILABLE.to_string())
}

/// Initialises the runtime and logs the device list once, like Warp's `wp.init()`.
///
/// The banner ([`Runtime::banner`]) goes to the `log` facade at info level (target
/// `warp_runtime::device`), never to stdout: a library does not write to the application's
/// output, and a program that wants the banner on screen installs a logger (`env_logger` with
/// `RUST_LOG=warp_runtime=info`, say) or prints [`Runtime::banner`] itself. Idempotent: later
/// calls return the same runtime and log nothing. Calling `init` is optional: the other
/// functions initialise the runtime on demand.
pub fn init() -> &'static Runtime {
    static LOGGED: OnceLock<()> = OnceLock::new();
    let rt = runtime();
    LOGGED.get_or_init(|| log::info!("{}", rt.banner()));
    rt
}

/// The CPU device.
pub fn cpu() -> Device {
    runtime().devices[0].clone()
}

/// All devices, the CPU first (only the CPU in this build).
pub fn devices() -> Vec<Device> {
    runtime().devices.clone()
}

/// The device Warp would pick by default: the first GPU, else the CPU.
///
/// A GPU counts only when kernels can run on it: when NVRTC (the CUDA toolkit's runtime
/// compiler, which compiles kernels at first launch) cannot be loaded and no ahead-of-time
/// cubin directory (`aot::set_aot_dir`, `WARP_LANG_AOT_DIR`) is
/// set, the preferred device is the CPU and [`cpu_fallback_reason`] says why. The GPU stays
/// reachable through [`get_device`], where a launch that needs NVRTC is an error naming it.
///
/// The first call says which device at info level, and why not a GPU when it falls back to the
/// CPU (at warn level when a GPU is present but unusable).
pub fn get_preferred_device() -> Device {
    static SAID: std::sync::Once = std::sync::Once::new();
    let rt = runtime();
    let gpu = rt.devices.iter().find(|d| d.is_cuda());
    let fallback = gpu.and_then(|_| jit_unusable_reason());
    let device = match (gpu, &fallback) {
        (Some(gpu), None) => gpu,
        _ => &rt.devices[0],
    };
    SAID.call_once(|| match (gpu, &fallback) {
        (Some(gpu), Some(why)) => log::warn!(
            "preferred device: \"cpu\", not \"{}\" ({}): {why}, and no ahead-of-time cubin \
             directory is set; get_device(\"{}\") still opens the GPU",
            gpu.alias(),
            gpu.name(),
            gpu.alias()
        ),
        _ if device.is_cpu() => log::info!(
            "preferred device: \"cpu\" (no CUDA device: {})",
            rt.cuda_status
        ),
        _ => log::info!(
            "preferred device: \"{}\" ({})",
            device.alias(),
            device.name()
        ),
    });
    device.clone()
}

/// Why [`get_preferred_device`] is the CPU although the driver reports a GPU: NVRTC cannot be
/// loaded (e.g. "NVRTC's libnvrtc.so not found (...)") and no ahead-of-time cubin directory
/// is set. `None` when the preferred device is a GPU, and when there is no GPU at all (then
/// [`Runtime::banner`] says why). For a program's one line to its user, such as the examples'
/// "warp-lang: no NVRTC: ...; running on the CPU".
///
/// The first call with a GPU present probes NVRTC (a `dlopen`, once per process); the
/// environment variable `WARP_LANG_NO_NVRTC=1` makes the probe fail, to try this path on a
/// machine that has NVRTC.
pub fn cpu_fallback_reason() -> Option<String> {
    runtime()
        .devices
        .iter()
        .any(Device::is_cuda)
        .then(jit_unusable_reason)
        .flatten()
}

/// Why kernels cannot be made for a GPU that is present (NVRTC probed now, once per process,
/// and the ahead-of-time directory in effect), or `None` when they can.
#[cfg(feature = "cuda")]
fn jit_unusable_reason() -> Option<String> {
    let nvrtc = match warp_cuda::nvrtc_version() {
        Ok(_) => Ok(()),
        // The bare reason (it names NVRTC), for the one line an example prints.
        Err(warp_cuda::CudaError::NoNvrtc(why)) => Err(why),
        Err(e) => Err(e.to_string()),
    };
    gpu_fallback_decision(nvrtc, crate::config::aot_dir().as_deref())
}

#[cfg(not(feature = "cuda"))]
fn jit_unusable_reason() -> Option<String> {
    // No GPU is ever listed in this build; nothing to fall back from.
    None
}

/// The decision behind [`get_preferred_device`] for a GPU that is present: `None` (use it)
/// when NVRTC loads or when an ahead-of-time directory exists (its cubins need no NVRTC; a
/// kernel missing from it then fails with an error naming NVRTC, which is the program's
/// packaging to fix, not a reason to ignore the GPU), else why not, starting "no NVRTC".
/// A directory that is named but does not exist counts as none: no cubin can come from it.
#[cfg(any(feature = "cuda", test))]
fn gpu_fallback_decision(
    nvrtc: std::result::Result<(), String>,
    aot_dir: Option<&std::path::Path>,
) -> Option<String> {
    let why = nvrtc.err()?;
    if aot_dir.is_some_and(std::path::Path::is_dir) {
        return None;
    }
    Some(format!("no NVRTC: {why}"))
}

/// The device named by `alias`: `"cpu"`, `"cuda"` (the first GPU) or `"cuda:N"`.
///
/// # Errors
/// [`Error::NoDevice`] for a CUDA alias when no such GPU is usable (always, in this build), and
/// for an alias that names no device at all (the message lists the valid ones).
pub fn get_device(alias: &str) -> Result<Device> {
    let rt = runtime();
    if let Some(d) = rt.devices.iter().find(|d| d.alias() == alias) {
        return Ok(d.clone());
    }
    let ordinal = match alias {
        "cuda" => Some(0),
        _ => alias
            .strip_prefix("cuda:")
            .and_then(|n| n.parse::<usize>().ok()),
    };
    let valid = || {
        rt.devices
            .iter()
            .map(|d| format!("\"{}\"", d.alias()))
            .collect::<Vec<_>>()
    };
    let reason = match ordinal {
        Some(n) => match rt
            .devices
            .iter()
            .find(|d| d.kind == DeviceKind::Cuda { ordinal: n })
        {
            Some(d) => return Ok(d.clone()),
            None if !rt.cuda_available() => {
                format!("CUDA is not available: {}; use \"cpu\"", rt.cuda_status)
            }
            None => format!(
                "no CUDA device with ordinal {n}; valid aliases: {}",
                valid().join(", ")
            ),
        },
        None => format!(
            "unknown device alias; valid aliases: {} (and \"cuda:N\" where CUDA is available)",
            valid().join(", ")
        ),
    };
    Err(Error::NoDevice {
        name: alias.to_string(),
        reason,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cpu_device() {
        let d = cpu();
        assert_eq!(d.kind(), DeviceKind::Cpu);
        assert_eq!(d.alias(), "cpu");
        assert_eq!(d.to_string(), "cpu");
        assert!(d.is_cpu() && !d.is_cuda());
        assert!(!d.name().is_empty());
        assert_eq!(get_device("cpu").unwrap(), d);
        // The CPU comes first; any other device is a GPU, and the preferred device is the
        // first GPU when there is one.
        let all = devices();
        assert_eq!(all[0], d);
        assert!(all[1..].iter().all(Device::is_cuda));
        assert_eq!(
            get_preferred_device(),
            all.get(1).cloned().unwrap_or(d.clone())
        );
        assert_ne!(d, Device::fake_cuda(0));
        // The CPU's memory is the operating system's to report.
        assert_eq!(d.memory_info().unwrap(), None);
    }

    #[test]
    fn gpu_fallback_needs_nvrtc_or_an_aot_dir() {
        let missing = || Err("NVRTC's libnvrtc.so not found".to_string());
        // NVRTC loads: the GPU, whatever the ahead-of-time directory.
        assert_eq!(gpu_fallback_decision(Ok(()), None), None);
        let dir = std::env::temp_dir();
        assert_eq!(gpu_fallback_decision(Ok(()), Some(&dir)), None);
        // No NVRTC but an existing ahead-of-time directory (examples/prebuilt): the GPU.
        assert_eq!(gpu_fallback_decision(missing(), Some(&dir)), None);
        // No NVRTC and no directory, or one that does not exist: the CPU, with the reason.
        let want = Some("no NVRTC: NVRTC's libnvrtc.so not found".to_string());
        assert_eq!(gpu_fallback_decision(missing(), None), want);
        let gone = dir.join("warp-lang-no-such-aot-dir-8c1f");
        assert_eq!(gpu_fallback_decision(missing(), Some(&gone)), want);
    }

    #[test]
    fn preferred_device_agrees_with_the_fallback_reason() {
        // Whatever this machine has: a reason exactly when a GPU is present but not preferred.
        let gpu = devices().into_iter().find(Device::is_cuda);
        let preferred = get_preferred_device();
        match (gpu, cpu_fallback_reason()) {
            (None, reason) => {
                assert!(preferred.is_cpu());
                assert_eq!(reason, None);
            }
            (Some(gpu), None) => assert_eq!(preferred, gpu),
            (Some(_), Some(why)) => {
                assert!(preferred.is_cpu());
                assert!(why.starts_with("no NVRTC: "), "{why}");
            }
        }
    }

    #[test]
    fn cuda_without_a_device_is_an_error_with_a_reason() {
        if runtime().cuda_available() {
            eprintln!(
                "SKIPPED cuda_without_a_device_is_an_error_with_a_reason: this machine has a GPU"
            );
            return;
        }
        for alias in ["cuda:0", "cuda", "cuda:3"] {
            let err = get_device(alias).unwrap_err();
            match &err {
                Error::NoDevice { name, reason } => {
                    assert_eq!(name, alias);
                    assert!(reason.contains(&runtime().cuda_status), "{reason}");
                }
                other => panic!("unexpected {other:?}"),
            }
            assert!(err
                .to_string()
                .starts_with(&format!("no device \"{alias}\": CUDA is not")));
        }
    }

    #[test]
    fn unknown_alias_lists_valid_ones() {
        let err = get_device("gpu7").unwrap_err();
        let valid: Vec<String> = devices()
            .iter()
            .map(|d| format!("\"{}\"", d.alias()))
            .collect();
        assert_eq!(
            err.to_string(),
            format!(
                "no device \"gpu7\": unknown device alias; valid aliases: {} (and \"cuda:N\" where CUDA \
                 is available)",
                valid.join(", ")
            )
        );
        assert!(get_device("cuda:x").is_err());
    }

    /// Run in a child process by [`init_writes_nothing_to_stdout`]: `init` and nothing else.
    #[test]
    fn init_alone() {
        if std::env::var_os("WARP_TEST_INIT_CHILD").is_some() {
            init();
        }
    }

    #[test]
    fn init_writes_nothing_to_stdout() {
        // The test harness captures `println!` inside a test, so the banner is looked for in
        // the real stdout of a child process running `init_alone` with capture off.
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["device::tests::init_alone", "--exact", "--nocapture"])
            .env("WARP_TEST_INIT_CHILD", "1")
            .output()
            .unwrap();
        assert!(out.status.success(), "{out:?}");
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            stdout.contains("1 passed"),
            "the child ran no test: {stdout}"
        );
        assert!(!stdout.contains("initialized"), "init printed: {stdout}");
    }

    #[test]
    fn init_is_idempotent_and_banner_lists_cpu() {
        let a = init() as *const Runtime;
        let b = init() as *const Runtime;
        assert_eq!(a, b);
        let banner = init().banner();
        assert!(banner.starts_with("warp-lang 0.1.0 initialized:\n   Devices:\n     \"cpu\""));
        assert!(banner.contains("threads)"));
        let rt = init();
        if rt.cuda_available() {
            assert!(banner.ends_with("CUDA: available"), "{banner}");
        } else {
            assert!(
                banner.ends_with(&format!("CUDA: not available ({})", rt.cuda_status)),
                "{banner}"
            );
        }
    }
}

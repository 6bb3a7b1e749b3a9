//! The on-disk kernel cache.
//!
//! A cold compile costs ~140 ms of NVRTC per kernel; a warm start must stay under 10 ms, so
//! cubins are kept on disk, keyed by a 128-bit hash of everything that determines them:
//! source, program name, NVRTC options, in-memory headers, architecture, NVRTC version and
//! this crate's version.
//!
//! Entries are `<kernel name>-<32 hex digits>.cubin`: the magic `WPCUBIN1`, the payload
//! length (u64 LE), an FNV-1a 64 checksum of the payload (u64 LE), then the payload. A damaged
//! or truncated entry (a crash mid-write on a file system without ordered rename, a full disk,
//! a stray edit) is never trusted: it counts as a miss and is rebuilt. Writes go to a unique
//! temporary file in the same directory and are renamed into place, so concurrent processes
//! never see a partial entry.

use std::ffi::OsString;
use std::fs;
use std::io::{ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{OnceLock, RwLock};

use crate::compile::{compile, nvrtc_version, CompileOptions, Compiled};
use crate::error::{CudaError, Result};

/// Environment variable naming the cache directory; wins over everything else.
pub const CACHE_DIR_ENV: &str = "WARP_LANG_CACHE_DIR";

const CRATE_VERSION: &str = env!("CARGO_PKG_VERSION");
const MAGIC: &[u8; 8] = b"WPCUBIN1";
const HEADER_LEN: usize = 24;

// ---------------------------------------------------------------------------------------------
// Hashing (no dependencies: FNV-1a, 64 and 128 bits)

const FNV64_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
const FNV64_PRIME: u64 = 0x0000_0100_0000_01b3;
const FNV128_OFFSET: u128 = 0x6c62_272e_07bb_0142_62b8_2175_6295_c58d;
const FNV128_PRIME: u128 = 0x0000_0000_0100_0000_0000_0000_0000_013b;

/// FNV-1a 64 of `bytes` (the entry checksum).
pub(crate) fn fnv1a_64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(FNV64_OFFSET, |h, &b| {
        (h ^ b as u64).wrapping_mul(FNV64_PRIME)
    })
}

/// Incremental FNV-1a 128 (the cache key).
#[derive(Clone)]
pub(crate) struct Fnv128(u128);

impl Fnv128 {
    pub(crate) fn new() -> Self {
        Fnv128(FNV128_OFFSET)
    }

    pub(crate) fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ b as u128).wrapping_mul(FNV128_PRIME);
        }
    }

    /// Writes a length-prefixed field, so that ("ab", "c") and ("a", "bc") hash differently.
    pub(crate) fn field(&mut self, bytes: &[u8]) {
        self.write(&(bytes.len() as u64).to_le_bytes());
        self.write(bytes);
    }

    pub(crate) fn finish(&self) -> u128 {
        self.0
    }
}

/// The cache key of a compile: a hash of every input that determines the cubin.
pub fn cache_key(
    source: &str,
    name: &str,
    opts: &CompileOptions,
    arch: u32,
    nvrtc_version: (i32, i32),
) -> u128 {
    let mut h = Fnv128::new();
    h.field(b"warp-lang kernel cache v1");
    h.field(&nvrtc_version.0.to_le_bytes());
    h.field(&nvrtc_version.1.to_le_bytes());
    hash_inputs(h, source, name, opts, arch)
}

/// The key of an ahead-of-time entry: as [`cache_key`] without the NVRTC version. A cubin
/// compiled ahead of time by any NVRTC runs on any driver at least as new, so the machine
/// that loads it need not have (or load) NVRTC at all; the cost is that a toolkit upgrade
/// does not rebuild the entries: compile them again with the build.
pub fn aot_key(source: &str, name: &str, opts: &CompileOptions, arch: u32) -> u128 {
    let mut h = Fnv128::new();
    h.field(b"warp-lang ahead-of-time v1");
    hash_inputs(h, source, name, opts, arch)
}

fn hash_inputs(mut h: Fnv128, source: &str, name: &str, opts: &CompileOptions, arch: u32) -> u128 {
    h.field(CRATE_VERSION.as_bytes());
    h.field(&arch.to_le_bytes());
    h.field(name.as_bytes());
    h.field(source.as_bytes());
    let args = opts.nvrtc_args(arch);
    h.field(&(args.len() as u64).to_le_bytes());
    for a in &args {
        h.field(a.as_bytes());
    }
    h.field(&(opts.headers.len() as u64).to_le_bytes());
    for header in opts.headers {
        h.field(&header_digest(header).to_le_bytes());
    }
    h.finish()
}

/// The digest of one in-memory header (its name and text). The library's own headers
/// ([`crate::HEADERS`], half a megabyte that every kernel passes to NVRTC) are hashed once per
/// process: a key is then computed in microseconds, which is what a first launch from the
/// disk cache or an ahead-of-time directory spends on it. Other headers are hashed each time.
fn header_digest(header: &(&str, &str)) -> u128 {
    let hash = |(name, text): &(&str, &str)| {
        let mut h = Fnv128::new();
        h.field(name.as_bytes());
        h.field(text.as_bytes());
        h.finish()
    };
    static LIBRARY: OnceLock<Vec<u128>> = OnceLock::new();
    // The same static text (same address and length) as a library header: its digest.
    match crate::HEADERS
        .iter()
        .position(|(n, t)| std::ptr::eq(*n, header.0) && std::ptr::eq(*t, header.1))
    {
        Some(k) => LIBRARY.get_or_init(|| crate::HEADERS.iter().map(hash).collect())[k],
        None => hash(header),
    }
}

// ---------------------------------------------------------------------------------------------
// Where the cache lives

static OVERRIDE: RwLock<Option<PathBuf>> = RwLock::new(None);

/// Sets (or with `None` clears) the process-wide cache directory. `WARP_LANG_CACHE_DIR`, when
/// set, still wins.
pub fn set_cache_dir(dir: Option<PathBuf>) {
    *OVERRIDE.write().unwrap_or_else(|e| e.into_inner()) = dir;
}

/// Picks the directory: the env variable, else the override, else
/// `$XDG_CACHE_HOME/warp-lang/<version>`, else `$HOME/.cache/warp-lang/<version>`, else
/// `<temp dir>/warp-lang/<version>`. Empty variables count as unset; a relative
/// `XDG_CACHE_HOME` is ignored (the XDG spec says so).
fn resolve_cache_dir(
    env: Option<OsString>,
    over: Option<PathBuf>,
    xdg: Option<OsString>,
    home: Option<OsString>,
    temp: PathBuf,
) -> PathBuf {
    let nonempty = |v: Option<OsString>| v.filter(|s| !s.is_empty());
    if let Some(dir) = nonempty(env) {
        return PathBuf::from(dir);
    }
    if let Some(dir) = over {
        return dir;
    }
    let base = nonempty(xdg)
        .map(PathBuf::from)
        .filter(|p| p.is_absolute())
        .or_else(|| nonempty(home).map(|h| PathBuf::from(h).join(".cache")))
        .unwrap_or(temp);
    base.join("warp-lang").join(CRATE_VERSION)
}

/// The kernel cache directory now in effect (see [`set_cache_dir`]).
pub fn cache_dir() -> PathBuf {
    resolve_cache_dir(
        std::env::var_os(CACHE_DIR_ENV),
        OVERRIDE.read().unwrap_or_else(|e| e.into_inner()).clone(),
        std::env::var_os("XDG_CACHE_HOME"),
        std::env::var_os("HOME"),
        std::env::temp_dir(),
    )
}

/// Removes every cache entry (and stray temporary file) from the current cache directory.
pub fn clear_kernel_cache() -> Result<()> {
    KernelCache::current().clear().map(|_| ())
}

// ---------------------------------------------------------------------------------------------
// Entries

/// How a cached compile was satisfied.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CacheOutcome {
    /// A valid entry was found; nothing was compiled.
    Hit,
    /// No entry; compiled and stored.
    Miss,
    /// An entry existed but was damaged; compiled and overwritten.
    Rebuilt,
}

/// What [`KernelCache::load`] found.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum CacheLookup {
    /// A verified payload.
    Hit(Vec<u8>),
    /// No entry.
    Absent,
    /// An entry that fails verification (or cannot be read).
    Damaged,
}

/// Where the cubin of a cached compile is: the key it is stored under and its file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct CacheEntry {
    /// The key ([`cache_key`], under the NVRTC version that served or compiled it): the 32 hex
    /// digits of the entry's file name. A change to the source (a kernel's body), the options
    /// or the versions gives a new key, so a new entry; the old one stays, unused.
    pub key: u128,
    /// The entry's file ([`KernelCache::path_for`]); `None` when a freshly compiled cubin could
    /// not be written (the compile still succeeds: see [`KernelCache::compile_cached`]).
    pub path: Option<PathBuf>,
}

/// A kernel cache in one directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KernelCache {
    dir: PathBuf,
}

/// Keeps file names portable and short: `[A-Za-z0-9_.-]`, at most 64 characters.
fn sanitize(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' || c == '-' || c == '.' {
                c
            } else {
                '_'
            }
        })
        .take(64)
        .collect();
    let s = s.trim_start_matches('.').to_string();
    if s.is_empty() {
        "kernel".to_string()
    } else {
        s
    }
}

fn encode(payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&fnv1a_64(payload).to_le_bytes());
    out.extend_from_slice(payload);
    out
}

/// Verifies an entry and returns its payload.
fn decode(mut file: Vec<u8>) -> Option<Vec<u8>> {
    if file.len() < HEADER_LEN || &file[..8] != MAGIC {
        return None;
    }
    let len = u64::from_le_bytes(file[8..16].try_into().ok()?);
    let sum = u64::from_le_bytes(file[16..24].try_into().ok()?);
    if len != (file.len() - HEADER_LEN) as u64 || fnv1a_64(&file[HEADER_LEN..]) != sum {
        return None;
    }
    file.drain(..HEADER_LEN);
    Some(file)
}

/// A name for a temporary file no other writer (thread or process) will pick.
fn unique_suffix() -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    let n = COUNTER.fetch_add(1, Ordering::Relaxed);
    let local = 0u8;
    let mut h = Fnv128::new();
    h.write(&nanos.to_le_bytes());
    h.write(&n.to_le_bytes());
    h.write(&(&local as *const u8 as usize).to_le_bytes());
    format!("{}.{:016x}", std::process::id(), h.finish() as u64)
}

impl KernelCache {
    /// A cache in `dir` (created on first store).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        KernelCache { dir: dir.into() }
    }

    /// The cache in [`cache_dir`].
    pub fn current() -> Self {
        Self::new(cache_dir())
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The entry path for a kernel name and key.
    pub fn path_for(&self, name: &str, key: u128) -> PathBuf {
        self.dir
            .join(format!("{}-{key:032x}.cubin", sanitize(name)))
    }

    /// Reads and verifies an entry.
    pub fn load(&self, name: &str, key: u128) -> CacheLookup {
        match fs::read(self.path_for(name, key)) {
            Ok(bytes) => decode(bytes).map_or(CacheLookup::Damaged, CacheLookup::Hit),
            Err(e) if e.kind() == ErrorKind::NotFound => CacheLookup::Absent,
            Err(_) => CacheLookup::Damaged,
        }
    }

    /// Writes an entry atomically (temporary file + rename) and returns its path.
    pub fn store(&self, name: &str, key: u128, payload: &[u8]) -> Result<PathBuf> {
        let path = self.path_for(name, key);
        fs::create_dir_all(&self.dir).map_err(|e| {
            CudaError::io(
                e,
                format!("creating cache directory {}", self.dir.display()),
            )
        })?;
        let mut tmp_name = path.file_name().map(OsString::from).unwrap_or_default();
        tmp_name.push(format!(".tmp.{}", unique_suffix()));
        let tmp = self.dir.join(tmp_name);
        let write = || -> std::io::Result<()> {
            let mut f = fs::File::create(&tmp)?;
            f.write_all(&encode(payload))?;
            drop(f);
            fs::rename(&tmp, &path)
        };
        write().map_err(|e| {
            let _ = fs::remove_file(&tmp);
            CudaError::io(e, format!("writing cache entry {}", path.display()))
        })?;
        Ok(path)
    }

    /// Removes all entries and temporary files; returns how many files were removed. Other
    /// files in the directory are left alone (the directory may be shared).
    pub fn clear(&self) -> Result<usize> {
        let entries = match fs::read_dir(&self.dir) {
            Ok(it) => it,
            Err(e) if e.kind() == ErrorKind::NotFound => return Ok(0),
            Err(e) => {
                return Err(CudaError::io(
                    e,
                    format!("listing cache directory {}", self.dir.display()),
                ))
            }
        };
        let mut removed = 0;
        for entry in entries.flatten() {
            let name = entry.file_name();
            let name = name.to_string_lossy();
            if name.ends_with(".cubin")
                || name.contains(".cubin.tmp.")
                || name.starts_with("nvrtc-version")
            {
                match fs::remove_file(entry.path()) {
                    Ok(()) => removed += 1,
                    Err(e) if e.kind() == ErrorKind::NotFound => {}
                    Err(e) => {
                        return Err(CudaError::io(
                            e,
                            format!("removing {}", entry.path().display()),
                        ))
                    }
                }
            }
        }
        Ok(removed)
    }

    /// Path of the stamp recording the NVRTC version that last compiled into this cache.
    fn stamp_path(&self) -> PathBuf {
        self.dir.join("nvrtc-version")
    }

    /// The NVRTC version in the stamp, if it is there and well formed.
    fn read_stamp(&self) -> Option<(i32, i32)> {
        let text = fs::read_to_string(self.stamp_path()).ok()?;
        let (major, minor) = text.trim().split_once('.')?;
        Some((major.parse().ok()?, minor.parse().ok()?))
    }

    /// Records `version` as the NVRTC of this cache (atomically; failures are ignored: the
    /// stamp only saves time).
    fn write_stamp(&self, version: (i32, i32)) {
        if self.read_stamp() == Some(version) {
            return;
        }
        let tmp = self
            .dir
            .join(format!("nvrtc-version.tmp.{}", unique_suffix()));
        let text = format!("{}.{}\n", version.0, version.1);
        if fs::write(&tmp, text).is_err() || fs::rename(&tmp, self.stamp_path()).is_err() {
            let _ = fs::remove_file(&tmp);
        }
    }

    /// Returns the cubin for this compile from the cache, or compiles and stores it.
    ///
    /// Loading NVRTC only to learn its version (part of the key) costs about 10 ms, nearly all
    /// of a warm first launch, so the cache first tries the key under the version recorded in
    /// its stamp by the last compile. A hit there never loads NVRTC. After a toolkit upgrade,
    /// such hits keep serving cubins of the previous NVRTC (valid: a cubin runs on any newer
    /// driver) until the first miss loads the new NVRTC and rewrites the stamp; from then on
    /// every kernel is keyed, and rebuilt, under the new version.
    ///
    /// A failure to write the entry is ignored (the compile result is still returned): a
    /// read-only cache must not stop kernels from running.
    pub fn compile_cached(
        &self,
        source: &str,
        name: &str,
        opts: &CompileOptions,
        arch: u32,
    ) -> Result<(Compiled, CacheOutcome)> {
        self.compile_cached_entry(source, name, opts, arch)
            .map(|(compiled, outcome, _)| (compiled, outcome))
    }

    /// [`compile_cached`](Self::compile_cached), also saying which entry served or now holds
    /// the cubin (for reports: the key and the file).
    pub fn compile_cached_entry(
        &self,
        source: &str,
        name: &str,
        opts: &CompileOptions,
        arch: u32,
    ) -> Result<(Compiled, CacheOutcome, CacheEntry)> {
        let hit = |cubin: Vec<u8>, key: u128| {
            let compiled = Compiled {
                cubin,
                log: String::new(),
                compile_ms: 0.0,
            };
            let entry = CacheEntry {
                key,
                path: Some(self.path_for(name, key)),
            };
            (compiled, CacheOutcome::Hit, entry)
        };
        if let Some(stamped) = self.read_stamp() {
            let key = cache_key(source, name, opts, arch, stamped);
            if let CacheLookup::Hit(cubin) = self.load(name, key) {
                log::debug!(
                    "kernel cache hit: {name} (sm_{arch}, NVRTC {}.{} by the stamp) from {}",
                    stamped.0,
                    stamped.1,
                    self.path_for(name, key).display()
                );
                return Ok(hit(cubin, key));
            }
        }
        let version = nvrtc_version()?;
        let key = cache_key(source, name, opts, arch, version);
        let path = self.path_for(name, key);
        let outcome = match self.load(name, key) {
            CacheLookup::Hit(cubin) => {
                log::debug!(
                    "kernel cache hit: {name} (sm_{arch}) from {}",
                    path.display()
                );
                return Ok(hit(cubin, key));
            }
            CacheLookup::Absent => {
                log::debug!(
                    "kernel cache miss: {name} (sm_{arch}): no {}",
                    path.display()
                );
                CacheOutcome::Miss
            }
            CacheLookup::Damaged => {
                log::warn!(
                    "kernel cache entry {} is damaged: compiling {name} (sm_{arch}) again",
                    path.display()
                );
                CacheOutcome::Rebuilt
            }
        };
        let compiled = compile(source, name, opts, arch)?;
        let path = match self.store(name, key, &compiled.cubin) {
            Ok(path) => {
                self.write_stamp(version);
                Some(path)
            }
            Err(e) => {
                // Handled: the kernel still runs, only the next process compiles it again.
                log::warn!("kernel cache: {e} (the compiled {name} is used but not kept)");
                None
            }
        };
        Ok((compiled, outcome, CacheEntry { key, path }))
    }
}

/// [`KernelCache::compile_cached`] in the current cache directory ([`cache_dir`]).
pub fn compile_cached(
    source: &str,
    name: &str,
    opts: &CompileOptions,
    arch: u32,
) -> Result<(Compiled, CacheOutcome)> {
    KernelCache::current().compile_cached(source, name, opts, arch)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A library header's digest, computed once per process, is the digest of its text: a
    /// copy of the same name and text (another address) gives the same key, and a changed
    /// text another.
    #[test]
    fn library_header_digests_are_their_texts() {
        let (name, text) = crate::HEADERS[0];
        let copy = (name.to_string(), text.to_string());
        assert_eq!(
            header_digest(&crate::HEADERS[0]),
            header_digest(&(copy.0.as_str(), copy.1.as_str()))
        );
        let changed = format!("{text} ");
        assert_ne!(
            header_digest(&crate::HEADERS[0]),
            header_digest(&(name, changed.as_str()))
        );
    }

    /// A fresh directory under the temp dir, removed on drop.
    pub(crate) struct TempDir(pub PathBuf);

    impl TempDir {
        pub(crate) fn new(tag: &str) -> Self {
            let p = std::env::temp_dir().join(format!("warp-cuda-test-{tag}-{}", unique_suffix()));
            fs::create_dir_all(&p).unwrap();
            TempDir(p)
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = fs::remove_dir_all(&self.0);
        }
    }

    fn files(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn fnv_reference_values() {
        assert_eq!(fnv1a_64(b""), 0xcbf29ce484222325);
        assert_eq!(fnv1a_64(b"a"), 0xaf63dc4c8601ec8c);
        assert_eq!(fnv1a_64(b"foobar"), 0x85944171f73967e8);
        let h = |s: &[u8]| {
            let mut f = Fnv128::new();
            f.write(s);
            f.finish()
        };
        assert_eq!(h(b""), 0x6c62272e07bb014262b821756295c58d);
        assert_eq!(h(b"a"), 0xd228cb696f1a8caf78912b704e4a8964);
    }

    #[test]
    fn key_is_deterministic_and_depends_on_every_input() {
        let src = "extern \"C\" __global__ void k() {}";
        let o = CompileOptions::default();
        let base = cache_key(src, "k", &o, 90, (13, 0));
        assert_eq!(base, cache_key(src, "k", &o, 90, (13, 0)));
        let mut keys = vec![base];
        keys.push(cache_key("// x\n", "k", &o, 90, (13, 0)));
        keys.push(cache_key(src, "k2", &o, 90, (13, 0)));
        keys.push(cache_key(src, "k", &o, 89, (13, 0)));
        keys.push(cache_key(src, "k", &o, 90, (13, 1)));
        keys.push(cache_key(src, "k", &o, 90, (12, 0)));
        keys.push(cache_key(
            src,
            "k",
            &CompileOptions {
                fmad: false,
                ..o.clone()
            },
            90,
            (13, 0),
        ));
        keys.push(cache_key(
            src,
            "k",
            &CompileOptions {
                fast_math: true,
                ..o.clone()
            },
            90,
            (13, 0),
        ));
        keys.push(cache_key(
            src,
            "k",
            &CompileOptions {
                line_info: true,
                ..o.clone()
            },
            90,
            (13, 0),
        ));
        keys.push(cache_key(
            src,
            "k",
            &CompileOptions {
                defines: &[("A", "1")],
                ..o.clone()
            },
            90,
            (13, 0),
        ));
        keys.push(cache_key(
            src,
            "k",
            &CompileOptions {
                defines: &[("A", "2")],
                ..o.clone()
            },
            90,
            (13, 0),
        ));
        keys.push(cache_key(
            src,
            "k",
            &CompileOptions {
                headers: &[("h.h", "")],
                ..o.clone()
            },
            90,
            (13, 0),
        ));
        keys.push(cache_key(
            src,
            "k",
            &CompileOptions {
                headers: &[("h.h", "x")],
                ..o.clone()
            },
            90,
            (13, 0),
        ));
        keys.push(cache_key(
            src,
            "k",
            &CompileOptions {
                extra_options: &["-G"],
                ..o.clone()
            },
            90,
            (13, 0),
        ));
        let mut dedup = keys.clone();
        dedup.sort();
        dedup.dedup();
        assert_eq!(dedup.len(), keys.len(), "some inputs do not change the key");
        // Field boundaries matter.
        let f = |a: &str, b: &str| {
            let mut h = Fnv128::new();
            h.field(a.as_bytes());
            h.field(b.as_bytes());
            h.finish()
        };
        assert_ne!(f("ab", "c"), f("a", "bc"));
    }

    #[test]
    fn round_trip_and_no_tmp_left() {
        let t = TempDir::new("roundtrip");
        let c = KernelCache::new(t.0.join("sub"));
        let key = 0x1234_5678_9abc_def0_1234_5678_9abc_def0u128;
        assert_eq!(c.load("k", key), CacheLookup::Absent);
        let payload: Vec<u8> = (0..5000u32).map(|i| (i * 7) as u8).collect();
        let path = c.store("k", key, &payload).unwrap();
        assert_eq!(path, c.path_for("k", key));
        assert_eq!(c.load("k", key), CacheLookup::Hit(payload.clone()));
        assert_eq!(files(c.dir()), ["k-123456789abcdef0123456789abcdef0.cubin"]);
        // Overwrite keeps one file and no temporaries.
        c.store("k", key, &payload[..10]).unwrap();
        assert_eq!(c.load("k", key), CacheLookup::Hit(payload[..10].to_vec()));
        assert_eq!(files(c.dir()).len(), 1);
        // Empty payloads are valid entries.
        c.store("e", 1, &[]).unwrap();
        assert_eq!(c.load("e", 1), CacheLookup::Hit(vec![]));
    }

    #[test]
    fn damaged_entries_are_misses() {
        let t = TempDir::new("damaged");
        let c = KernelCache::new(&t.0);
        let payload = vec![0xABu8; 1000];
        let path = c.store("k", 7, &payload).unwrap();
        let good = fs::read(&path).unwrap();

        // Corrupted payload byte.
        let mut bad = good.clone();
        bad[HEADER_LEN + 500] ^= 1;
        fs::write(&path, &bad).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);

        // Truncated file (payload and header).
        fs::write(&path, &good[..good.len() - 1]).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);
        fs::write(&path, &good[..10]).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);
        fs::write(&path, []).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);

        // Trailing garbage, wrong magic.
        let mut long = good.clone();
        long.push(0);
        fs::write(&path, &long).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);
        let mut magic = good.clone();
        magic[0] = b'X';
        fs::write(&path, &magic).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);

        // Rebuilding overwrites it.
        c.store("k", 7, &payload).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Hit(payload));
    }

    #[test]
    fn clear_removes_only_cache_files() {
        let t = TempDir::new("clear");
        let c = KernelCache::new(&t.0);
        c.store("a", 1, b"x").unwrap();
        c.store("b", 2, b"y").unwrap();
        fs::write(t.0.join("a-1.cubin.tmp.1.2"), b"").unwrap();
        fs::write(t.0.join("notes.txt"), b"keep").unwrap();
        c.write_stamp((13, 0));
        assert_eq!(c.clear().unwrap(), 4);
        assert_eq!(files(&t.0), ["notes.txt"]);
        assert_eq!(KernelCache::new(t.0.join("missing")).clear().unwrap(), 0);
    }

    /// A warm cache serves a hit under the NVRTC version of its stamp without loading NVRTC
    /// (this test passes on machines without NVRTC); a damaged stamp is ignored.
    #[test]
    fn stamped_version_hits_without_nvrtc() {
        let t = TempDir::new("stamp");
        let c = KernelCache::new(&t.0);
        let opts = CompileOptions::default();
        let stamped = (99, 7);
        let key = cache_key("src", "k", &opts, 90, stamped);
        c.store("k", key, b"cubin bytes").unwrap();
        c.write_stamp(stamped);
        assert_eq!(c.read_stamp(), Some(stamped));
        let (compiled, outcome) = c.compile_cached("src", "k", &opts, 90).unwrap();
        assert_eq!(
            (compiled.cubin.as_slice(), outcome),
            (&b"cubin bytes"[..], CacheOutcome::Hit)
        );
        // The entry that served it: the stamped version's key and its file.
        let (_, _, entry) = c.compile_cached_entry("src", "k", &opts, 90).unwrap();
        assert_eq!(
            entry,
            CacheEntry {
                key,
                path: Some(c.path_for("k", key))
            }
        );
        // Another source under the stamp misses and goes to NVRTC (an error where there is
        // none, never a wrong cubin).
        if nvrtc_version().is_err() {
            assert!(c.compile_cached("other", "k", &opts, 90).is_err());
        }
        for bad in ["", "13", "x.y", "13.0.1"] {
            fs::write(c.stamp_path(), bad).unwrap();
            assert_eq!(c.read_stamp(), None, "{bad:?}");
        }
    }

    /// A compile (a miss) reports the key it was stored under and the file; the next call
    /// hits that entry and reports the same. Needs NVRTC (not a GPU); skipped without it.
    #[test]
    fn compiled_entry_names_key_and_file() {
        let archs = match crate::compile::nvrtc_supported_archs() {
            Ok(a) if !a.is_empty() => a,
            other => {
                eprintln!("SKIPPED compiled_entry_names_key_and_file: no NVRTC ({other:?})");
                return;
            }
        };
        let arch = *archs.last().expect("not empty");
        let t = TempDir::new("entry");
        let c = KernelCache::new(&t.0);
        let opts = CompileOptions::default();
        let src = "extern \"C\" __global__ void k(float* a) { a[threadIdx.x] += 1.0f; }";
        let (_, outcome, entry) = c.compile_cached_entry(src, "k", &opts, arch).unwrap();
        let key = cache_key(src, "k", &opts, arch, nvrtc_version().unwrap());
        assert_eq!(outcome, CacheOutcome::Miss);
        assert_eq!(entry.key, key);
        let path = entry.path.clone().expect("written");
        assert_eq!(path, c.path_for("k", key));
        assert!(path.is_file());
        let (_, outcome, again) = c.compile_cached_entry(src, "k", &opts, arch).unwrap();
        assert_eq!((outcome, again), (CacheOutcome::Hit, entry));
    }

    #[test]
    fn names_are_sanitized() {
        assert_eq!(sanitize("add1.cu"), "add1.cu");
        assert_eq!(sanitize("../etc/passwd"), "_etc_passwd");
        assert_eq!(sanitize(""), "kernel");
        assert_eq!(sanitize("a b/c"), "a_b_c");
        assert_eq!(sanitize(&"x".repeat(100)).len(), 64);
    }

    #[test]
    fn cache_dir_precedence() {
        let v = CRATE_VERSION;
        let tmp = PathBuf::from("/tmp");
        let os = |s: &str| Some(OsString::from(s));
        assert_eq!(
            resolve_cache_dir(
                os("/env"),
                Some("/over".into()),
                os("/xdg"),
                os("/home/u"),
                tmp.clone()
            ),
            PathBuf::from("/env")
        );
        assert_eq!(
            resolve_cache_dir(
                os(""),
                Some("/over".into()),
                os("/xdg"),
                os("/home/u"),
                tmp.clone()
            ),
            PathBuf::from("/over")
        );
        assert_eq!(
            resolve_cache_dir(None, None, os("/xdg"), os("/home/u"), tmp.clone()),
            PathBuf::from(format!("/xdg/warp-lang/{v}"))
        );
        assert_eq!(
            resolve_cache_dir(None, None, os("rel"), os("/home/u"), tmp.clone()),
            PathBuf::from(format!("/home/u/.cache/warp-lang/{v}"))
        );
        assert_eq!(
            resolve_cache_dir(None, None, None, None, tmp.clone()),
            PathBuf::from(format!("/tmp/warp-lang/{v}"))
        );
    }

    #[test]
    fn unique_suffixes_differ() {
        let a = unique_suffix();
        let b = unique_suffix();
        assert_ne!(a, b);
        assert!(a.starts_with(&std::process::id().to_string()));
    }
}

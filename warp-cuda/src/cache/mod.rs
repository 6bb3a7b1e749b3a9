//! The on-disk kernel cache.
//!
//! A cold compile costs ~140 ms of NVRTC per kernel; a warm start must stay under 10 ms, so
//! cubins are kept on disk, keyed by a 128-bit hash of everything that determines them:
//! source, program name, NVRTC options, in-memory headers, architecture, NVRTC version and
//! this crate's version.
//!
//! Entries (`cache/entry.rs`) are `<kernel name>-<32 hex digits>.cubin`: the magic `WPCUBIN2`, the
//! payload length (u64 LE), a 32-byte MAC, then the payload. The MAC is BLAKE3 in keyed mode
//! over the entry's file name, the length and the payload, under a 32-byte key drawn from the
//! OS's random number generator on the first store and kept in the file `key` of the cache
//! directory. An entry whose MAC does not verify (truncated or damaged by a crash, a full disk
//! or a stray edit; planted by someone without the key; copied from another cache or renamed
//! from another entry; of the older `WPCUBIN1` format) is never trusted: it counts as damaged,
//! with a warning, and is rebuilt and replaced. Without a key file every entry counts as
//! absent. Writes go to a temporary file in the same directory, named with 64 random bits and
//! created exclusively and owner-only (a symlink or file planted at the name fails the write
//! instead of redirecting it), and are renamed into place, so concurrent processes never see
//! a partial entry.
//!
//! The key is written durably: to an exclusively created temporary file, flushed to disk,
//! then linked into place (of two processes creating it at once, one wins and both use its
//! key) and the directory flushed, so a crash leaves no key or a whole one. A key file of the
//! wrong length (an empty one left by a crash of an older version) is replaced by a new key
//! on the next store, with a warning; the entries it vouched for then fail their MAC and are
//! rebuilt one by one.
//!
//! Trust model (`cache/trust.rs`). The cache directory is `WARP_LANG_CACHE_DIR`, else
//! [`set_cache_dir`]'s, else `<platform cache dir>/warp-lang/<version>` (the `dirs` crate),
//! else `<temp dir>/warp-lang-<uid>/<version>`. Directories are created owner-only (0700). On
//! Unix every check is made on an open descriptor, with `fstat`, and the checked descriptor
//! is the one then used, so nothing can be swapped between a check and a use: the directory
//! is opened (for the default layouts its `warp-lang` parent first, and the version directory
//! through it without following a symlink) and used only when owned by this user or root and
//! writable by neither group nor others; the key file and each entry are opened through the
//! directory's descriptor with `O_NOFOLLOW` (a symlink at their name is refused, never
//! followed), checked on their own descriptors, and read from them. An entry must be a
//! regular file owned by this user or root and writable by neither group nor others, else it
//! counts as damaged (with a warning) and is rebuilt; the key must be a regular file owned by
//! this user or root, writable by neither group nor others, and, when this user's own,
//! readable by no one else (0600: whoever reads it can forge entries), else the cache in that
//! directory is off (with a warning, once) and kernels are compiled in memory. A cubin is code
//! the GPU runs with the user's rights: an entry someone else could plant or rewrite must
//! never be loaded. Off Unix no owner or mode check is made.
//!
//! Size (`cache/evict.rs`). The cache in [`cache_dir`] ([`KernelCache::current`]) is bounded, 1 GiB
//! by default, `WARP_LANG_CACHE_MAX_BYTES` or [`set_cache_max_bytes`] otherwise: an entry's
//! modification time is set to now on every hit, and after each store the least recently
//! used entries are removed until the entries fit. Processes sharing the directory share the
//! order through the files' times, with no index to lock. A cache made with
//! [`KernelCache::new`] (an ahead-of-time directory) is unbounded unless
//! [`KernelCache::with_max_bytes`] says otherwise.

mod entry;
mod evict;
mod trust;

use std::ffi::OsString;
use std::fs;
use std::io::{ErrorKind, Read};
use std::path::{Path, PathBuf};
use std::sync::{OnceLock, RwLock};

use crate::compile::{compile, loaded_nvrtc_version, nvrtc_version, CompileOptions, Compiled};
use crate::error::{CudaError, Result};
use entry::{entry_name, key_for_store, read_entry, read_key, write_atomically, KeyFile, KEY_FILE};
pub use evict::{
    cache_max_bytes, set_cache_max_bytes, CACHE_MAX_BYTES_ENV, DEFAULT_CACHE_MAX_BYTES,
};
use trust::{warn_distrusted, OpenDir};

/// Environment variable naming the cache directory; wins over everything else.
pub const CACHE_DIR_ENV: &str = "WARP_LANG_CACHE_DIR";

const CRATE_VERSION: &str = env!("CARGO_PKG_VERSION");
/// The stamp recording the NVRTC version that last compiled into a cache.
const STAMP_FILE: &str = "nvrtc-version";

// ---------------------------------------------------------------------------------------------
// Hashing: BLAKE3 (unkeyed) for the cache key, which names an entry and needs no secrecy (the
// entries themselves are authenticated with a keyed BLAKE3, see `mac`). The key is the first
// 128 bits of the hash: collisions are out of reach, and entry names stay 32 hex digits.

/// An incremental hash of the inputs that name a cache entry.
#[derive(Clone)]
pub(crate) struct KeyHasher(blake3::Hasher);

impl KeyHasher {
    pub(crate) fn new() -> Self {
        KeyHasher(blake3::Hasher::new())
    }

    pub(crate) fn write(&mut self, bytes: &[u8]) {
        self.0.update(bytes);
    }

    /// Writes a length-prefixed field, so that ("ab", "c") and ("a", "bc") hash differently.
    pub(crate) fn field(&mut self, bytes: &[u8]) {
        self.write(&(bytes.len() as u64).to_le_bytes());
        self.write(bytes);
    }

    /// The first 16 bytes of the hash, little-endian.
    pub(crate) fn finish(&self) -> u128 {
        let hash = self.0.finalize();
        let mut first = [0u8; 16];
        first.copy_from_slice(&hash.as_bytes()[..16]);
        u128::from_le_bytes(first)
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
    let mut h = KeyHasher::new();
    h.field(b"warp-lang kernel cache v2");
    h.field(&nvrtc_version.0.to_le_bytes());
    h.field(&nvrtc_version.1.to_le_bytes());
    hash_inputs(h, source, name, opts, arch)
}

/// The key of an ahead-of-time entry: as [`cache_key`] without the NVRTC version. A cubin
/// compiled ahead of time by any NVRTC runs on any driver at least as new, so the machine
/// that loads it need not have (or load) NVRTC at all; the cost is that a toolkit upgrade
/// does not rebuild the entries: compile them again with the build.
pub fn aot_key(source: &str, name: &str, opts: &CompileOptions, arch: u32) -> u128 {
    let mut h = KeyHasher::new();
    h.field(b"warp-lang ahead-of-time v2");
    hash_inputs(h, source, name, opts, arch)
}

fn hash_inputs(
    mut h: KeyHasher,
    source: &str,
    name: &str,
    opts: &CompileOptions,
    arch: u32,
) -> u128 {
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
        let mut h = KeyHasher::new();
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
/// `<platform cache dir>/warp-lang/<version>` (`platform` is [`dirs::cache_dir`]:
/// `$XDG_CACHE_HOME` or `~/.cache` on Linux, `~/Library/Caches` on macOS, `%LOCALAPPDATA%` on
/// Windows), else `<temp dir>/warp-lang-<uid>/<version>`: a directory per user, so that a
/// shared temp directory never gives two users the same cache (and one planted by another
/// user is refused by the trust check, see [`KernelCache`]). Empty variables count as unset.
///
/// Also returns the directory whose trust the default layouts hinge on besides the cache
/// directory itself: its `warp-lang` (or `warp-lang-<uid>`) parent, whose owner could swap
/// the version directory under it. `None` for a directory named by the variable or the
/// override (only that directory is checked).
fn resolve_cache_dir(
    env: Option<OsString>,
    over: Option<PathBuf>,
    platform: Option<PathBuf>,
    temp: PathBuf,
    uid: u32,
) -> (PathBuf, Option<PathBuf>) {
    if let Some(dir) = env.filter(|s| !s.is_empty()) {
        return (PathBuf::from(dir), None);
    }
    if let Some(dir) = over {
        return (dir, None);
    }
    let parent = match platform.filter(|p| p.is_absolute()) {
        Some(base) => base.join("warp-lang"),
        None => temp.join(format!("warp-lang-{uid}")),
    };
    (parent.join(CRATE_VERSION), Some(parent))
}

fn current_cache() -> KernelCache {
    let (dir, parent) = resolve_cache_dir(
        std::env::var_os(CACHE_DIR_ENV),
        OVERRIDE.read().unwrap_or_else(|e| e.into_inner()).clone(),
        dirs::cache_dir(),
        std::env::temp_dir(),
        trust::current_uid(),
    );
    let mut cache = KernelCache::new(dir).with_max_bytes(Some(cache_max_bytes()));
    cache.parent = parent;
    cache
}

/// The kernel cache directory now in effect (see [`set_cache_dir`]).
pub fn cache_dir() -> PathBuf {
    current_cache().dir
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
///
/// The directory is created owner-only (mode 0700) and, on Unix, used only when it is owned
/// by this user (or root) and writable by neither group nor others; otherwise nothing is
/// read from it or written to it ([`load`](Self::load) finds nothing, [`store`](Self::store)
/// A kernel cache in one directory.
///
/// The directory is created owner-only (mode 0700) and, on Unix, used only when it is owned
/// by this user (or root) and writable by neither group nor others, and its key file is
/// sound (see the [module docs](self)); otherwise nothing is read from it or written to it
/// ([`load`](Self::load) finds nothing, [`store`](Self::store) fails saying why, a warning is
/// logged once) and kernels are compiled in memory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KernelCache {
    dir: PathBuf,
    /// For the default layouts, the `warp-lang` parent of `dir`: checked first, and `dir`
    /// opened through it.
    parent: Option<PathBuf>,
    /// The size bound applied after each store; `None`: unbounded.
    max_bytes: Option<u64>,
}

impl KernelCache {
    /// A cache in `dir` (created on first store), unbounded in size.
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        KernelCache {
            dir: dir.into(),
            parent: None,
            max_bytes: None,
        }
    }

    /// The cache in [`cache_dir`], bounded by [`cache_max_bytes`].
    pub fn current() -> Self {
        current_cache()
    }

    /// This cache with a size bound in bytes (`None`: unbounded): after each store, the least
    /// recently used entries are removed until the entries total at most `max_bytes`.
    pub fn with_max_bytes(mut self, max_bytes: Option<u64>) -> Self {
        self.max_bytes = max_bytes;
        self
    }

    /// The size bound of this cache, if any.
    pub fn max_bytes(&self) -> Option<u64> {
        self.max_bytes
    }

    /// Opens and checks the directory (and, for the default layouts, its `warp-lang` parent):
    /// `Err` saying why not (also logged once). A missing directory is `NotFound`.
    fn open_dir(&self) -> std::io::Result<OpenDir> {
        OpenDir::open(&self.dir, self.parent.as_deref()).map_err(|(path, e)| {
            if e.kind() != ErrorKind::NotFound {
                warn_distrusted(&path, &e);
            }
            e
        })
    }

    /// Creates the directory (and missing parents) owner-only, then opens and checks it.
    fn open_for_writing(&self) -> Result<OpenDir> {
        let mut builder = fs::DirBuilder::new();
        builder.recursive(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::DirBuilderExt;
            builder.mode(0o700);
        }
        builder
            .create(&self.dir)
            .and_then(|()| self.open_dir())
            .map_err(|e| CudaError::io(e, format!("using cache directory {}", self.dir.display())))
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The entry path for a kernel name and key.
    pub fn path_for(&self, name: &str, key: u128) -> PathBuf {
        self.dir.join(entry_name(name, key))
    }

    /// Reads and verifies an entry (and marks it used, for eviction).
    pub fn load(&self, name: &str, key: u128) -> CacheLookup {
        let Ok(dir) = self.open_dir() else {
            return CacheLookup::Absent;
        };
        let mac_key = match read_key(&dir) {
            KeyFile::Key(key) => key,
            // No key yet: nothing here was stored by this cache (or the key was removed). A
            // damaged key vouches for nothing; the next store replaces it.
            KeyFile::Missing | KeyFile::Damaged(_) => return CacheLookup::Absent,
            KeyFile::Refused(e) => {
                warn_distrusted(&self.dir.join(KEY_FILE), &e);
                return CacheLookup::Absent;
            }
        };
        let file = entry_name(name, key);
        match read_entry(&dir, &file) {
            Ok(bytes) => {
                entry::decode(&mac_key, &file, bytes).map_or(CacheLookup::Damaged, CacheLookup::Hit)
            }
            Err(e) if e.kind() == ErrorKind::NotFound => CacheLookup::Absent,
            Err(e) => {
                log::warn!(
                    "kernel cache entry {} is not used: {e}",
                    self.dir.join(&file).display()
                );
                CacheLookup::Damaged
            }
        }
    }

    /// Writes an entry atomically (temporary file + rename) and returns its path; then, when
    /// the cache is bounded, evicts the least recently used entries over the bound.
    pub fn store(&self, name: &str, key: u128, payload: &[u8]) -> Result<PathBuf> {
        let path = self.path_for(name, key);
        let dir = self.open_for_writing()?;
        let key_path = self.dir.join(KEY_FILE);
        let mac_key = key_for_store(&dir).map_err(|e| {
            if e.kind() == ErrorKind::PermissionDenied {
                warn_distrusted(&key_path, &e);
            }
            CudaError::io(e, format!("cache key {}", key_path.display()))
        })?;
        let file = entry_name(name, key);
        // Not flushed to disk: an entry lost or cut short by a crash fails its MAC and is
        // rebuilt, so it is not worth an fsync per kernel.
        write_atomically(&dir, &file, &entry::encode(&mac_key, &file, payload), false)
            .map_err(|e| CudaError::io(e, format!("writing cache entry {}", path.display())))?;
        if let Some(limit) = self.max_bytes {
            // The entry is stored: a failed eviction only leaves the cache over its bound.
            if let Err(e) = evict::evict(&dir, limit, &file) {
                log::warn!(
                    "kernel cache: evicting entries of {} failed: {e}",
                    self.dir.display()
                );
            }
        }
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
                || name.starts_with("key.tmp.")
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

    /// The NVRTC version in the stamp, if the directory is trusted and the stamp there and
    /// well formed.
    fn read_stamp(&self) -> Option<(i32, i32)> {
        let dir = self.open_dir().ok()?;
        let mut text = String::new();
        dir.open_file(STAMP_FILE)
            .ok()?
            .take(64)
            .read_to_string(&mut text)
            .ok()?;
        let (major, minor) = text.trim().split_once('.')?;
        Some((major.parse().ok()?, minor.parse().ok()?))
    }

    /// Records `version` as the NVRTC of this cache (atomically; failures are ignored: the
    /// stamp only saves time).
    fn write_stamp(&self, version: (i32, i32)) {
        if self.read_stamp() == Some(version) {
            return;
        }
        let Ok(dir) = self.open_dir() else { return };
        let text = format!("{}.{}\n", version.0, version.1);
        let _ = write_atomically(&dir, STAMP_FILE, text.as_bytes(), false);
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
                    "kernel cache entry {} fails verification (damaged, truncated, of an older \
                     format, not written by this cache, or refused by the trust checks): \
                     compiling {name} (sm_{arch}) again and replacing it",
                    path.display()
                );
                CacheOutcome::Rebuilt
            }
        };
        let (compiled, entry) = self.compile_and_store(source, name, opts, arch, version)?;
        Ok((compiled, outcome, entry))
    }

    /// The cubin for this compile if the cache holds it, without compiling and without loading
    /// NVRTC: the key under the version in the stamp, and under the loaded NVRTC's version when
    /// NVRTC is loaded already and differs. `None` when absent (or damaged: the compile that
    /// follows replaces it, see [`compile_cached_entry`](Self::compile_cached_entry)). For a
    /// caller choosing between units by what is already compiled (the runtime compiles a
    /// kernel's forward and adjoint as one unit when neither is).
    pub fn lookup_entry(
        &self,
        source: &str,
        name: &str,
        opts: &CompileOptions,
        arch: u32,
    ) -> Option<(Compiled, CacheEntry)> {
        let stamped = self.read_stamp();
        let loaded = loaded_nvrtc_version().filter(|v| Some(*v) != stamped);
        stamped.into_iter().chain(loaded).find_map(|version| {
            let key = cache_key(source, name, opts, arch, version);
            match self.load(name, key) {
                CacheLookup::Hit(cubin) => {
                    log::debug!(
                        "kernel cache hit: {name} (sm_{arch}, NVRTC {}.{}) from {}",
                        version.0,
                        version.1,
                        self.path_for(name, key).display()
                    );
                    let compiled = Compiled {
                        cubin,
                        log: String::new(),
                        compile_ms: 0.0,
                    };
                    let path = Some(self.path_for(name, key));
                    Some((compiled, CacheEntry { key, path }))
                }
                CacheLookup::Absent | CacheLookup::Damaged => None,
            }
        })
    }

    /// Compiles with NVRTC `version` and stores the cubin under its key; a store that fails is
    /// logged, and the cubin still returned.
    fn compile_and_store(
        &self,
        source: &str,
        name: &str,
        opts: &CompileOptions,
        arch: u32,
        version: (i32, i32),
    ) -> Result<(Compiled, CacheEntry)> {
        let key = cache_key(source, name, opts, arch, version);
        let compiled = compile(source, name, opts, arch)?;
        let path = match self.store(name, key, &compiled.cubin) {
            Ok(path) => {
                self.write_stamp(version);
                Some(path)
            }
            Err(e) => {
                // Handled: the kernel still runs, only the next process compiles it again.
                log::warn!(
                    "kernel cache: {} (the compiled {name} is used but not kept)",
                    crate::error::Chain(&e)
                );
                None
            }
        };
        Ok((compiled, CacheEntry { key, path }))
    }

    /// Compiles again, with NVRTC, a kernel whose cached cubin the driver refused to load
    /// (`cuModuleLoadData` failed: a cubin the MAC vouches for can still be unusable, say one
    /// written by a buggy toolkit, or for a driver since downgraded), and stores the new cubin
    /// in place of the old. `bad` is the entry that failed; it is removed first when it lies in
    /// this cache's directory (an ahead-of-time file elsewhere is left alone), so that a failed
    /// compile or store does not leave it to fail again. The compile is under the NVRTC loaded
    /// now, whatever the stamp says.
    pub fn recompile_entry(
        &self,
        source: &str,
        name: &str,
        opts: &CompileOptions,
        arch: u32,
        bad: Option<&Path>,
    ) -> Result<(Compiled, CacheEntry)> {
        if let Some(bad) = bad.filter(|p| p.parent() == Some(self.dir.as_path())) {
            match fs::remove_file(bad) {
                Ok(()) => log::debug!("kernel cache: removed {}", bad.display()),
                Err(e) if e.kind() == ErrorKind::NotFound => {}
                Err(e) => log::warn!("kernel cache: cannot remove {}: {e}", bad.display()),
            }
        }
        self.compile_and_store(source, name, opts, arch, nvrtc_version()?)
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
pub(crate) mod tests;

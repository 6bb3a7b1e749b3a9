//! The on-disk kernel cache.
//!
//! A cold compile costs ~140 ms of NVRTC per kernel; a warm start must stay under 10 ms, so
//! cubins are kept on disk, keyed by a 128-bit hash of everything that determines them:
//! source, program name, NVRTC options, in-memory headers, architecture, NVRTC version and
//! this crate's version.
//!
//! Entries are `<kernel name>-<32 hex digits>.cubin`: the magic `WPCUBIN2`, the payload
//! length (u64 LE), a 32-byte MAC, then the payload. The MAC is BLAKE3 in keyed mode over the
//! entry's file name, the length and the payload, under a 32-byte key drawn from the OS's
//! random number generator on the first store and kept in the file `key` of the cache
//! directory (created exclusively, mode 0600). An entry whose MAC does not verify (truncated
//! or damaged by a crash, a full disk or a stray edit; planted by someone without the key;
//! copied from another cache or renamed from another entry; of the older `WPCUBIN1` format)
//! is never trusted: it counts as damaged, with a warning, and is rebuilt and replaced. Without
//! a key file every entry counts as absent. Writes go to a
//! temporary file in the same directory, named with 64 random bits and created exclusively and
//! owner-only (a symlink or file planted at the name fails the write instead of redirecting
//! it), and are renamed into place, so concurrent processes never see a partial entry.
//!
//! Trust model. The cache directory is `WARP_LANG_CACHE_DIR`, else [`set_cache_dir`]'s, else
//! `<platform cache dir>/warp-lang/<version>` (the `dirs` crate), else
//! `<temp dir>/warp-lang-<uid>/<version>`. Directories are created owner-only (0700); on Unix
//! the cache directory (and, for the two default layouts, its `warp-lang` parent) is used only
//! when owned by this user or root and writable by neither group nor others. Otherwise a
//! warning names the directory and the reason, nothing is read from or written to it, and
//! kernels are compiled in memory (a cubin is code the GPU runs with the user's rights: an
//! entry someone else could plant must never be loaded). Off Unix no owner check is made.

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
const MAGIC: &[u8; 8] = b"WPCUBIN2";
const MAC_LEN: usize = 32;
const HEADER_LEN: usize = 16 + MAC_LEN;
/// The file of the entries' MAC key, in the cache directory.
const KEY_FILE: &str = "key";

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

/// The effective user id (the owner a trusted cache directory must have); 0 off Unix, where
/// no owner check is made.
fn current_uid() -> u32 {
    #[cfg(unix)]
    {
        // SAFETY: geteuid takes no arguments, cannot fail and touches no memory of ours.
        unsafe { libc::geteuid() }
    }
    #[cfg(not(unix))]
    {
        0
    }
}

fn current_cache() -> KernelCache {
    let (dir, parent) = resolve_cache_dir(
        std::env::var_os(CACHE_DIR_ENV),
        OVERRIDE.read().unwrap_or_else(|e| e.into_inner()).clone(),
        dirs::cache_dir(),
        std::env::temp_dir(),
        current_uid(),
    );
    let mut cache = KernelCache::new(dir);
    cache.checked.extend(parent);
    cache
}

/// The kernel cache directory now in effect (see [`set_cache_dir`]).
pub fn cache_dir() -> PathBuf {
    current_cache().dir
}

// ---------------------------------------------------------------------------------------------
// Trust in a directory

/// Why a directory owned by `owner` with mode `mode` must not hold the cache of the user
/// `me`, or `None` when it may. Trusted: owned by this user or by root (root can replace
/// anything anyway; an installed ahead-of-time directory is often root's), and writable by
/// neither group nor others: anyone else who could write there could plant an entry, or swap
/// an entry's file, or a temporary file's name, between our check and our use.
#[cfg_attr(not(unix), allow(dead_code))] // only Unix has owners and modes to check
pub(crate) fn distrust_reason(owner: u32, mode: u32, me: u32) -> Option<String> {
    if owner != me && owner != 0 {
        return Some(format!(
            "it is owned by uid {owner}, neither this user (uid {me}) nor root"
        ));
    }
    let writers = match (mode & 0o020 != 0, mode & 0o002 != 0) {
        (true, true) => "its group and others",
        (true, false) => "its group",
        (false, true) => "others",
        (false, false) => return None,
    };
    Some(format!(
        "it is writable by {writers} (mode {:03o}; `chmod go-w` it, or remove it and let it \
         be created owner-only)",
        mode & 0o7777
    ))
}

/// Checks an existing directory: `Err` with the reason when it must not be used.
fn check_dir(dir: &Path) -> std::io::Result<()> {
    let meta = fs::metadata(dir)?;
    if !meta.is_dir() {
        return Err(std::io::Error::new(
            ErrorKind::InvalidInput,
            "it is not a directory",
        ));
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let Some(why) = distrust_reason(meta.uid(), meta.mode(), current_uid()) {
            return Err(std::io::Error::new(ErrorKind::PermissionDenied, why));
        }
    }
    Ok(())
}

/// Logs, once per directory and process, why a cache directory is not used.
fn warn_distrusted(dir: &Path, why: &std::io::Error) {
    static WARNED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    let mut warned = WARNED.lock().unwrap_or_else(|e| e.into_inner());
    if !warned.iter().any(|d| d == dir) {
        warned.push(dir.to_path_buf());
        log::warn!(
            "kernel cache directory {} is not used: {why}; kernels are compiled in memory",
            dir.display()
        );
    }
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
/// fails saying why, a warning is logged once) and kernels are compiled in memory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct KernelCache {
    dir: PathBuf,
    /// The directories that must pass [`check_dir`]: `dir`, and for the default layouts its
    /// `warp-lang` parent (first: checked from the outside in).
    checked: Vec<PathBuf>,
}

/// The file name of an entry.
fn entry_name(name: &str, key: u128) -> String {
    format!("{}-{key:032x}.cubin", sanitize(name))
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

/// The MAC of an entry: keyed BLAKE3 over its file name (so that an entry renamed to another
/// kernel's or key's name fails), its length and its payload.
fn mac(key: &[u8; 32], file_name: &str, payload: &[u8]) -> [u8; MAC_LEN] {
    let mut h = blake3::Hasher::new_keyed(key);
    h.update(b"warp-lang kernel cache entry v2\0");
    h.update(&(file_name.len() as u64).to_le_bytes());
    h.update(file_name.as_bytes());
    h.update(&(payload.len() as u64).to_le_bytes());
    h.update(payload);
    *h.finalize().as_bytes()
}

fn encode(key: &[u8; 32], file_name: &str, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&mac(key, file_name, payload));
    out.extend_from_slice(payload);
    out
}

/// Verifies an entry and returns its payload.
fn decode(key: &[u8; 32], file_name: &str, mut file: Vec<u8>) -> Option<Vec<u8>> {
    if file.len() < HEADER_LEN || &file[..8] != MAGIC {
        return None;
    }
    let len = u64::from_le_bytes(file[8..16].try_into().ok()?);
    if len != (file.len() - HEADER_LEN) as u64 {
        return None;
    }
    let stored = blake3::Hash::from_bytes(file[16..HEADER_LEN].try_into().ok()?);
    // blake3::Hash compares in constant time.
    if stored != blake3::Hash::from_bytes(mac(key, file_name, &file[HEADER_LEN..])) {
        return None;
    }
    file.drain(..HEADER_LEN);
    Some(file)
}

/// Creates `path` for writing, failing if anything (a file, or a symlink planted to redirect
/// the write) is already there; owner-only on Unix.
fn create_exclusive(path: &Path) -> std::io::Result<fs::File> {
    let mut options = fs::OpenOptions::new();
    options.write(true).create_new(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.mode(0o600);
    }
    options.open(path)
}

/// A name for a temporary file no other writer (thread or process) will pick, and no one
/// can predict: the process id (to tell stray files apart), then 64 random bits. Were the
/// random source to fail, a counter and the clock still keep names unique; the exclusive
/// create ([`create_exclusive`]) is what makes a guessed name harmless.
fn unique_suffix() -> String {
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let mut random = [0u8; 8];
    if getrandom::fill(&mut random).is_err() {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map(|d| d.as_nanos())
            .unwrap_or(0);
        let mut h = KeyHasher::new();
        h.write(&nanos.to_le_bytes());
        h.write(&COUNTER.fetch_add(1, Ordering::Relaxed).to_le_bytes());
        random = (h.finish() as u64).to_le_bytes();
    }
    format!("{}.{:016x}", std::process::id(), u64::from_le_bytes(random))
}

/// Writes `bytes` to `path` atomically: into `<path>.tmp.<unique suffix>`, created exclusively
/// (so a symlink or file planted at that name makes the write fail instead of being followed
/// or reused), then renamed over `path` (a rename replaces a symlink at `path`, never writes
/// through it). The temporary file is removed on failure, but only one this call created.
fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp_name = path.file_name().map(OsString::from).unwrap_or_default();
    tmp_name.push(format!(".tmp.{}", unique_suffix()));
    let tmp = path.with_file_name(tmp_name);
    let mut file = create_exclusive(&tmp)?;
    let written = file.write_all(bytes).and_then(|()| {
        drop(file);
        fs::rename(&tmp, path)
    });
    if written.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    written
}

impl KernelCache {
    /// A cache in `dir` (created on first store).
    pub fn new(dir: impl Into<PathBuf>) -> Self {
        let dir = dir.into();
        KernelCache {
            checked: vec![dir.clone()],
            dir,
        }
    }

    /// The cache in [`cache_dir`].
    pub fn current() -> Self {
        current_cache()
    }

    /// Whether the directory (and, for the default layouts, its `warp-lang` parent) may be
    /// used: `Err` saying why not (also logged once). A missing directory is `NotFound`.
    fn trusted(&self) -> std::io::Result<()> {
        for dir in self.checked.iter().rev() {
            if let Err(e) = check_dir(dir) {
                if e.kind() != ErrorKind::NotFound {
                    warn_distrusted(dir, &e);
                }
                return Err(e);
            }
        }
        Ok(())
    }

    /// Creates the directory (and missing parents) owner-only, then checks it.
    fn open_for_writing(&self) -> Result<()> {
        let mut builder = fs::DirBuilder::new();
        builder.recursive(true);
        #[cfg(unix)]
        {
            use std::os::unix::fs::DirBuilderExt;
            builder.mode(0o700);
        }
        builder
            .create(&self.dir)
            .and_then(|()| self.trusted())
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

    /// The MAC key of this cache, if its file is there and sound.
    fn read_mac_key(&self) -> std::io::Result<[u8; 32]> {
        let path = self.dir.join(KEY_FILE);
        let bytes = fs::read(&path)?;
        bytes.try_into().map_err(|b: Vec<u8>| {
            std::io::Error::new(
                ErrorKind::InvalidData,
                format!("{} holds {} bytes, not 32", path.display(), b.len()),
            )
        })
    }

    /// The MAC key of this cache, made on first use: 32 random bytes written to a temporary
    /// file created exclusively, then hard-linked to `key` (a link never replaces a file, so of
    /// two processes making one at once, the second reads the first one's, whole).
    fn mac_key(&self) -> Result<[u8; 32]> {
        let path = self.dir.join(KEY_FILE);
        let io = |e: std::io::Error| CudaError::io(e, format!("cache key {}", path.display()));
        match self.read_mac_key() {
            Ok(key) => return Ok(key),
            Err(e) if e.kind() == ErrorKind::NotFound => {}
            Err(e) => return Err(io(e)),
        }
        let mut key = [0u8; 32];
        getrandom::fill(&mut key).map_err(|e| io(std::io::Error::other(e.to_string())))?;
        let tmp = self.dir.join(format!("{KEY_FILE}.tmp.{}", unique_suffix()));
        let made = create_exclusive(&tmp)
            .and_then(|mut f| f.write_all(&key))
            .and_then(|()| fs::hard_link(&tmp, &path));
        let _ = fs::remove_file(&tmp);
        match made {
            Ok(()) => Ok(key),
            Err(e) if e.kind() == ErrorKind::AlreadyExists => self.read_mac_key().map_err(io),
            Err(e) => Err(io(e)),
        }
    }

    /// Reads and verifies an entry.
    pub fn load(&self, name: &str, key: u128) -> CacheLookup {
        if self.trusted().is_err() {
            return CacheLookup::Absent;
        }
        // No key yet: nothing here was stored by this cache (or the key was removed).
        let Ok(mac_key) = self.read_mac_key() else {
            return CacheLookup::Absent;
        };
        match fs::read(self.path_for(name, key)) {
            Ok(bytes) => decode(&mac_key, &entry_name(name, key), bytes)
                .map_or(CacheLookup::Damaged, CacheLookup::Hit),
            Err(e) if e.kind() == ErrorKind::NotFound => CacheLookup::Absent,
            Err(_) => CacheLookup::Damaged,
        }
    }

    /// Writes an entry atomically (temporary file + rename) and returns its path.
    pub fn store(&self, name: &str, key: u128, payload: &[u8]) -> Result<PathBuf> {
        let path = self.path_for(name, key);
        self.open_for_writing()?;
        let mac_key = self.mac_key()?;
        write_atomically(&path, &encode(&mac_key, &entry_name(name, key), payload))
            .map_err(|e| CudaError::io(e, format!("writing cache entry {}", path.display())))?;
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
        let text = format!("{}.{}\n", version.0, version.1);
        let _ = write_atomically(&self.stamp_path(), text.as_bytes());
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
                     format, or not written by this cache): compiling {name} (sm_{arch}) again \
                     and replacing it",
                    path.display()
                );
                CacheOutcome::Rebuilt
            }
        };
        let (compiled, entry) = self.compile_and_store(source, name, opts, arch, version)?;
        Ok((compiled, outcome, entry))
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

    /// The key is BLAKE3's hash (the crate's, not a hand-written one): its first 16 bytes for
    /// the reference input of the BLAKE3 specification's test vectors (the empty input).
    #[test]
    fn key_hasher_is_blake3() {
        let h = |s: &[u8]| {
            let mut f = KeyHasher::new();
            f.write(s);
            f.finish()
        };
        // BLAKE3("") = af1349b9f5f9a1a6a0404dea36dcc9499bcb25c9adc112b7cc9a93cae41f3262.
        assert_eq!(
            h(b""),
            u128::from_le_bytes(
                *b"\xaf\x13\x49\xb9\xf5\xf9\xa1\xa6\xa0\x40\x4d\xea\x36\xdc\xc9\x49"
            )
        );
        assert_ne!(h(b"a"), h(b""));
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
            let mut h = KeyHasher::new();
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
        assert_eq!(
            files(c.dir()),
            ["k-123456789abcdef0123456789abcdef0.cubin", "key"]
        );
        // Overwrite keeps one entry, the same key and no temporaries.
        let mac_key = fs::read(c.dir().join(KEY_FILE)).unwrap();
        c.store("k", key, &payload[..10]).unwrap();
        assert_eq!(c.load("k", key), CacheLookup::Hit(payload[..10].to_vec()));
        assert_eq!(files(c.dir()).len(), 2);
        assert_eq!(fs::read(c.dir().join(KEY_FILE)).unwrap(), mac_key);
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

    /// The key: 32 bytes, owner-only, made once and reused.
    #[test]
    fn mac_key_is_private_and_stable() {
        let t = TempDir::new("key");
        let c = KernelCache::new(&t.0);
        c.store("a", 1, b"x").unwrap();
        let path = t.0.join(KEY_FILE);
        let key = fs::read(&path).unwrap();
        assert_eq!(key.len(), 32);
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            assert_eq!(
                fs::metadata(&path).unwrap().permissions().mode() & 0o777,
                0o600
            );
        }
        c.store("b", 2, b"y").unwrap();
        assert_eq!(fs::read(&path).unwrap(), key);
        // Another cache has another key.
        let t2 = TempDir::new("key2");
        KernelCache::new(&t2.0).store("a", 1, b"x").unwrap();
        assert_ne!(fs::read(t2.0.join(KEY_FILE)).unwrap(), key);
    }

    /// Planted entries are never served: one of the old format with a correct FNV checksum,
    /// one of the new format whose MAC is made under another key (all a planter without the
    /// key can do), one copied from another cache, and a sound entry renamed to another
    /// kernel's file. A key file removed makes every entry absent (then rebuilt).
    #[test]
    fn planted_entries_are_not_used() {
        let t = TempDir::new("planted");
        let c = KernelCache::new(&t.0);
        c.store("other", 9, b"real").unwrap();
        let path = c.path_for("k", 7);

        // WPCUBIN1: magic, length, FNV-1a 64 of the payload, payload.
        let payload = b"evil cubin";
        let fnv = payload.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
            (h ^ b as u64).wrapping_mul(0x0000_0100_0000_01b3)
        });
        let mut old = b"WPCUBIN1".to_vec();
        old.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        old.extend_from_slice(&fnv.to_le_bytes());
        old.extend_from_slice(payload);
        fs::write(&path, &old).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);

        // The new format under a guessed key.
        fs::write(&path, encode(&[0u8; 32], &entry_name("k", 7), payload)).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);

        // A sound entry of another cache.
        let t2 = TempDir::new("planted2");
        let c2 = KernelCache::new(&t2.0);
        fs::copy(c2.store("k", 7, payload).unwrap(), &path).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);

        // A sound entry of this cache, under another name.
        fs::copy(c.path_for("other", 9), &path).unwrap();
        assert_eq!(c.load("k", 7), CacheLookup::Damaged);
        assert_eq!(c.load("other", 9), CacheLookup::Hit(b"real".to_vec()));

        // A compile replaces it (stamp of a version without NVRTC: the planted entry sits
        // where the stamp's key points, and must not be served).
        let opts = CompileOptions::default();
        let key = cache_key("src", "k", &opts, 90, (99, 7));
        fs::write(c.path_for("k", key), &old).unwrap();
        c.write_stamp((99, 7));
        if let Ok((compiled, outcome)) = c.compile_cached("src", "k", &opts, 90) {
            assert_ne!(outcome, CacheOutcome::Hit);
            assert_ne!(compiled.cubin, payload);
        }

        // No key: nothing here is trusted.
        fs::remove_file(t.0.join(KEY_FILE)).unwrap();
        assert_eq!(c.load("other", 9), CacheLookup::Absent);
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
        // The MAC key stays: entries stored later are still verified by it.
        assert_eq!(files(&t.0), ["key", "notes.txt"]);
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

    /// The entry a module load refused is removed before the recompile (which, without
    /// NVRTC, fails here: the entry is gone all the same); a file outside the cache (an
    /// ahead-of-time cubin) is never removed.
    #[test]
    fn recompile_removes_only_its_own_entry() {
        let t = TempDir::new("recompile");
        let c = KernelCache::new(t.0.join("cache"));
        let bad = c.store("k", 1, b"unloadable").unwrap();
        let outside = t.0.join("k-1.cubin");
        fs::write(&outside, b"aot").unwrap();
        let opts = CompileOptions::default();
        let src = "extern \"C\" __global__ void k() {}";
        let fresh = c.recompile_entry(src, "k", &opts, 90, Some(&outside));
        assert!(outside.is_file());
        let again = c.recompile_entry(src, "k", &opts, 90, Some(&bad));
        assert!(!bad.exists());
        if let (Ok((compiled, entry)), Ok(_)) = (again, fresh) {
            assert!(!compiled.cubin.is_empty());
            assert_eq!(
                c.load("k", entry.key),
                CacheLookup::Hit(compiled.cubin.clone())
            );
        }
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
        let plat = || Some(PathBuf::from("/home/u/.cache"));
        assert_eq!(
            resolve_cache_dir(os("/env"), Some("/over".into()), plat(), tmp.clone(), 7),
            (PathBuf::from("/env"), None)
        );
        assert_eq!(
            resolve_cache_dir(os(""), Some("/over".into()), plat(), tmp.clone(), 7),
            (PathBuf::from("/over"), None)
        );
        assert_eq!(
            resolve_cache_dir(None, None, plat(), tmp.clone(), 7),
            (
                PathBuf::from(format!("/home/u/.cache/warp-lang/{v}")),
                Some(PathBuf::from("/home/u/.cache/warp-lang"))
            )
        );
        // No platform directory (no HOME): a directory per user under the temp dir.
        for platform in [None, Some(PathBuf::from("relative"))] {
            assert_eq!(
                resolve_cache_dir(None, None, platform, tmp.clone(), 1234),
                (
                    PathBuf::from(format!("/tmp/warp-lang-1234/{v}")),
                    Some(PathBuf::from("/tmp/warp-lang-1234"))
                )
            );
        }
    }

    /// The ownership and mode rules, as a pure function: these tests run as root here, and a
    /// directory owned by another user cannot be made without being root.
    #[test]
    fn trust_rules() {
        let me = 1000;
        assert_eq!(distrust_reason(me, 0o40700, me), None);
        assert_eq!(distrust_reason(me, 0o40755, me), None);
        assert_eq!(distrust_reason(0, 0o40755, me), None, "root's is trusted");
        assert_eq!(distrust_reason(0, 0o40700, 0), None);
        let other = distrust_reason(1001, 0o40700, me).expect("another user's");
        assert!(
            other.contains("uid 1001") && other.contains("uid 1000"),
            "{other}"
        );
        for (mode, who) in [
            (0o40777, "its group and others"),
            (0o40770, "its group"),
            (0o40702, "others"),
            (0o41777, "its group and others"),
        ] {
            let why = distrust_reason(me, mode, me).expect("writable by others");
            assert!(why.contains(who) && why.contains(&format!("{:03o}", mode & 0o7777)));
        }
        // Both wrong: the owner is reported.
        assert!(distrust_reason(1001, 0o40777, me)
            .unwrap()
            .contains("owned by"));
    }

    /// A new cache directory (and its missing parents) is created owner-only.
    #[cfg(unix)]
    #[test]
    fn directories_are_created_owner_only() {
        use std::os::unix::fs::PermissionsExt;
        let t = TempDir::new("mode");
        let c = KernelCache::new(t.0.join("a").join("b"));
        c.store("k", 1, b"x").unwrap();
        for d in [t.0.join("a"), t.0.join("a").join("b")] {
            let mode = fs::metadata(&d).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o700, "{}", d.display());
        }
    }

    /// A world- or group-writable directory is refused: an entry planted there is not read
    /// (the lookup finds nothing, so the kernel is compiled in memory), and a store fails
    /// naming the directory and the reason.
    #[cfg(unix)]
    #[test]
    fn writable_by_others_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        for mode in [0o777, 0o770, 0o1777] {
            let t = TempDir::new("writable");
            let c = KernelCache::new(&t.0);
            c.store("k", 1, b"planted").unwrap();
            fs::set_permissions(&t.0, fs::Permissions::from_mode(mode)).unwrap();
            assert_eq!(c.load("k", 1), CacheLookup::Absent, "mode {mode:o}");
            // The message names the directory; the reason is its source (the chain says both).
            let e = crate::error::Chain(&c.store("k", 2, b"x").unwrap_err()).to_string();
            assert!(
                e.contains(&t.0.display().to_string()) && e.contains("writable by"),
                "{e}"
            );
            // compile_cached never reads it either: with the stamp's version the entry
            // would otherwise be a hit without NVRTC.
            let opts = CompileOptions::default();
            let key = cache_key("src", "k", &opts, 90, (99, 7));
            fs::set_permissions(&t.0, fs::Permissions::from_mode(0o700)).unwrap();
            c.store("k", key, b"planted").unwrap();
            c.write_stamp((99, 7));
            fs::set_permissions(&t.0, fs::Permissions::from_mode(mode)).unwrap();
            // Without NVRTC (or as "src" is no CUDA) this is an error: compiled, not read.
            if let Ok((compiled, outcome)) = c.compile_cached("src", "k", &opts, 90) {
                assert_ne!(outcome, CacheOutcome::Hit);
                assert_ne!(compiled.cubin, b"planted");
            }
        }
    }

    /// For the default layouts the `warp-lang-<uid>` parent is checked too: whoever can
    /// write it could swap the version directory below it (the planted-directory case of a
    /// shared temp dir).
    #[cfg(unix)]
    #[test]
    fn planted_parent_is_refused() {
        use std::os::unix::fs::PermissionsExt;
        let t = TempDir::new("parent");
        let (dir, parent) = resolve_cache_dir(None, None, None, t.0.clone(), current_uid());
        let mut c = KernelCache::new(dir);
        c.checked.extend(parent.clone());
        c.store("k", 1, b"x").unwrap();
        assert_eq!(c.load("k", 1), CacheLookup::Hit(b"x".to_vec()));
        let parent = parent.unwrap();
        fs::set_permissions(&parent, fs::Permissions::from_mode(0o777)).unwrap();
        assert_eq!(c.load("k", 1), CacheLookup::Absent);
        assert!(c.store("k", 1, b"x").is_err());
    }

    #[test]
    fn unique_suffixes_differ() {
        let a = unique_suffix();
        let b = unique_suffix();
        assert_ne!(a, b);
        assert!(a.starts_with(&std::process::id().to_string()));
    }

    /// A symlink (or any file) planted at a temporary file's name makes the exclusive create
    /// fail: the link's target is neither written nor truncated, and the failed write does not
    /// remove what it did not create. (The real names end in 64 random bits, so this plants at
    /// the name directly.)
    #[cfg(unix)]
    #[test]
    fn symlink_at_temp_name_is_not_followed() {
        let t = TempDir::new("symlink");
        let victim = t.0.join("victim");
        fs::write(&victim, b"precious").unwrap();
        let tmp = t.0.join("k-1.cubin.tmp.1.0123456789abcdef");
        std::os::unix::fs::symlink(&victim, &tmp).unwrap();
        let e = create_exclusive(&tmp).unwrap_err();
        assert_eq!(e.kind(), ErrorKind::AlreadyExists);
        fs::write(t.0.join("plain"), b"x").unwrap();
        assert_eq!(
            create_exclusive(&t.0.join("plain")).unwrap_err().kind(),
            ErrorKind::AlreadyExists
        );
        assert_eq!(fs::read(&victim).unwrap(), b"precious");
        assert!(fs::symlink_metadata(&tmp).unwrap().file_type().is_symlink());
        // Temporaries are created owner-only.
        use std::os::unix::fs::PermissionsExt;
        let fresh = t.0.join("fresh");
        drop(create_exclusive(&fresh).unwrap());
        assert_eq!(
            fs::metadata(&fresh).unwrap().permissions().mode() & 0o777,
            0o600
        );
        // An entry whose final name is a symlink: the rename replaces the link, the target
        // is untouched.
        let c = KernelCache::new(&t.0);
        std::os::unix::fs::symlink(&victim, c.path_for("k", 1)).unwrap();
        c.store("k", 1, b"cubin").unwrap();
        assert_eq!(fs::read(&victim).unwrap(), b"precious");
        assert_eq!(c.load("k", 1), CacheLookup::Hit(b"cubin".to_vec()));
    }
}

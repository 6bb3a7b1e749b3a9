//! The files of a cache directory: entries (their names, format and MAC), the MAC key, and
//! atomic writes, all through a checked [`OpenDir`].

use std::io::{self, ErrorKind, Read, Write};
use std::sync::atomic::{AtomicU64, Ordering};

use super::trust::{check_file, distrust_reason, key_distrust_reason, OpenDir};
use super::KeyHasher;

pub(super) const MAGIC: &[u8; 8] = b"WPCUBIN2";
pub(super) const MAC_LEN: usize = 32;
pub(super) const HEADER_LEN: usize = 16 + MAC_LEN;
/// The file of the entries' MAC key, in the cache directory.
pub(super) const KEY_FILE: &str = "key";
/// The suffix of an entry's file name.
pub(super) const ENTRY_SUFFIX: &str = ".cubin";

/// The file name of an entry.
pub(super) fn entry_name(name: &str, key: u128) -> String {
    format!("{}-{key:032x}{ENTRY_SUFFIX}", sanitize(name))
}

/// Whether `file` is the name of an entry (not a temporary file, the key, or anything else).
pub(super) fn is_entry(file: &str) -> bool {
    file.ends_with(ENTRY_SUFFIX) && !file.contains(".tmp.")
}

/// Keeps file names portable and short: `[A-Za-z0-9_.-]`, at most 64 characters.
pub(super) fn sanitize(name: &str) -> String {
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

pub(super) fn encode(key: &[u8; 32], file_name: &str, payload: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&mac(key, file_name, payload));
    out.extend_from_slice(payload);
    out
}

/// Verifies an entry and returns its payload.
pub(super) fn decode(key: &[u8; 32], file_name: &str, mut file: Vec<u8>) -> Option<Vec<u8>> {
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

/// A name for a temporary file no other writer (thread or process) will pick, and no one
/// can predict: the process id (to tell stray files apart), then 64 random bits. Were the
/// random source to fail, a counter and the clock still keep names unique; the exclusive
/// create ([`OpenDir::create_new`]) is what makes a guessed name harmless.
pub(super) fn unique_suffix() -> String {
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

/// Writes `bytes` to the file `name` of `dir` atomically: into `<name>.tmp.<unique suffix>`,
/// created exclusively (so a symlink or file planted at that name makes the write fail
/// instead of being followed or reused), flushed to disk when `durable`, then renamed over
/// `name` (a rename replaces a symlink at `name`, never writes through it). The temporary file
/// is removed on failure, but only one this call created.
pub(super) fn write_atomically(
    dir: &OpenDir,
    name: &str,
    bytes: &[u8],
    durable: bool,
) -> io::Result<()> {
    let tmp = format!("{name}.tmp.{}", unique_suffix());
    let mut file = dir.create_new(&tmp)?;
    let written = file
        .write_all(bytes)
        .and_then(|()| if durable { file.sync_all() } else { Ok(()) })
        .and_then(|()| {
            drop(file);
            dir.rename(&tmp, name)
        });
    if written.is_err() {
        let _ = dir.remove(&tmp);
    }
    written
}

/// Reads at most `limit` bytes of `file` (one more than a sound file holds tells a long one).
fn read_up_to(file: std::fs::File, limit: u64) -> io::Result<Vec<u8>> {
    let mut bytes = Vec::new();
    file.take(limit).read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// Opens the entry `file` of `dir`, checks it on its descriptor (a regular file, not a
/// symlink, owned by this user or root, writable by neither group nor others) and reads it
/// from that descriptor. `NotFound` when absent; another error says why it is refused.
/// The entry's modification time is set to now: eviction removes the entries least recently
/// used first, and the time on the file itself needs no index shared between processes (a
/// failure to set it only makes the entry look older).
pub(super) fn read_entry(dir: &OpenDir, file: &str) -> io::Result<Vec<u8>> {
    let f = dir.open_file(file)?;
    check_file(&f, distrust_reason)?;
    let _ = f.set_modified(std::time::SystemTime::now());
    let mut bytes = Vec::new();
    (&f).read_to_end(&mut bytes)?;
    Ok(bytes)
}

/// What the key file holds.
#[derive(Debug)]
pub(super) enum KeyFile {
    /// A sound key.
    Key([u8; 32]),
    /// No key file: nothing in the directory was stored by this cache.
    Missing,
    /// A key file of the wrong length (say an empty one left by a crash of an older version):
    /// replaced on the next store; the entries it vouched for then count as damaged.
    Damaged(String),
    /// A key file the cache must not use (a symlink, another user's, writable or readable by
    /// others): the cache in this directory is off (nothing read, nothing stored) while it
    /// stays so.
    Refused(io::Error),
}

/// Reads the key file of `dir`, checked on its descriptor ([`key_distrust_reason`]).
pub(super) fn read_key(dir: &OpenDir) -> KeyFile {
    let f = match dir.open_file(KEY_FILE) {
        Ok(f) => f,
        Err(e) if e.kind() == ErrorKind::NotFound => return KeyFile::Missing,
        Err(e) => return KeyFile::Refused(e),
    };
    if let Err(e) = check_file(&f, key_distrust_reason) {
        return KeyFile::Refused(e);
    }
    match read_up_to(f, 33) {
        Ok(bytes) => match <[u8; 32]>::try_from(bytes.as_slice()) {
            Ok(key) => KeyFile::Key(key),
            Err(_) => KeyFile::Damaged(format!("it holds {} bytes, not 32", bytes.len())),
        },
        Err(e) => KeyFile::Refused(e),
    }
}

/// The key of `dir` for a store: the one there, else a new one made durably. A new key is 32
/// bytes from the OS's RNG written to an exclusively created owner-only temporary file and
/// flushed to disk, then linked as `key` (a link never replaces a file: of two processes
/// making one at once, exactly one wins and both then use its key) and the directory flushed,
/// so that a crash at any point leaves either no key or a whole one, never a short one. A
/// damaged key is replaced by a rename of such a file (atomic: readers see the old file or
/// the new, whole); racing replacements each read back the key that ended up in place, and an
/// entry stored under a key that lost counts as damaged and is rebuilt.
pub(super) fn key_for_store(dir: &OpenDir) -> io::Result<[u8; 32]> {
    // Three rounds: a racing process may replace the key between our write and our read.
    for _ in 0..3 {
        let replace = match read_key(dir) {
            KeyFile::Key(key) => return Ok(key),
            KeyFile::Refused(e) => return Err(e),
            KeyFile::Missing => false,
            KeyFile::Damaged(why) => {
                log::warn!(
                    "kernel cache key {} is damaged ({why}): replacing it (entries stored \
                     under it are rebuilt)",
                    dir.path().join(KEY_FILE).display()
                );
                true
            }
        };
        let mut key = [0u8; 32];
        getrandom::fill(&mut key).map_err(|e| io::Error::other(e.to_string()))?;
        let tmp = format!("{KEY_FILE}.tmp.{}", unique_suffix());
        let mut file = dir.create_new(&tmp)?;
        let written = file.write_all(&key).and_then(|()| file.sync_all());
        drop(file);
        let placed = written.and_then(|()| {
            if replace {
                dir.rename(&tmp, KEY_FILE)
            } else {
                dir.link(&tmp, KEY_FILE)
            }
        });
        // After a link the temporary is a second name; after a failure, a leftover.
        if !replace || placed.is_err() {
            let _ = dir.remove(&tmp);
        }
        match placed {
            Ok(()) => dir.sync()?,
            Err(e) if e.kind() == ErrorKind::AlreadyExists => {}
            Err(e) => return Err(e),
        }
    }
    match read_key(dir) {
        KeyFile::Key(key) => Ok(key),
        KeyFile::Refused(e) => Err(e),
        other => Err(io::Error::other(format!(
            "the key file keeps changing under concurrent writers ({other:?})"
        ))),
    }
}

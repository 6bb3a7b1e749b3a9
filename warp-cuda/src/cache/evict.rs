//! The cache's size bound: least recently used entries are removed first.
//!
//! An entry's last use is its file's modification time: set when it is written, and set to
//! now on every hit ([`super::entry::read_entry`]), so concurrent processes share the
//! recency order through the directory itself, with no index to lock. After each store the
//! entries are summed and, while over the limit, the oldest are removed. Only entries are
//! counted and removed (never the key, the NVRTC stamp, or other files); an entry another
//! process removed meanwhile is simply gone; the entry just stored is kept even when it alone
//! is over the limit. Temporary files older than an hour (left by a crashed writer) are
//! removed at the same time. A process still holding an evicted entry open reads it whole (the
//! file lives on until closed).

use std::io::{self, ErrorKind};
use std::sync::RwLock;

use super::entry::is_entry;
use super::trust::OpenDir;

/// Environment variable bounding the size of the kernel cache, in bytes (a plain number, or
/// one with a binary suffix: `512M`, `2G`, `64KiB`). Wins over [`set_cache_max_bytes`].
pub const CACHE_MAX_BYTES_ENV: &str = "WARP_LANG_CACHE_MAX_BYTES";

/// The size bound of the kernel cache without [`CACHE_MAX_BYTES_ENV`] or
/// [`set_cache_max_bytes`]: 1 GiB (a cubin is tens of kilobytes to a few megabytes).
pub const DEFAULT_CACHE_MAX_BYTES: u64 = 1 << 30;

/// How old a temporary file must be to count as left by a crashed writer.
const STALE_TEMP: std::time::Duration = std::time::Duration::from_secs(3600);

static MAX_OVERRIDE: RwLock<Option<u64>> = RwLock::new(None);

/// Sets (or with `None` clears) the process-wide size bound of the kernel cache, in bytes.
/// `WARP_LANG_CACHE_MAX_BYTES`, when set, still wins.
pub fn set_cache_max_bytes(bytes: Option<u64>) {
    *MAX_OVERRIDE.write().unwrap_or_else(|e| e.into_inner()) = bytes;
}

/// The size bound of the kernel cache now in effect: `WARP_LANG_CACHE_MAX_BYTES`, else
/// [`set_cache_max_bytes`]'s, else [`DEFAULT_CACHE_MAX_BYTES`]. A variable that does not
/// parse is ignored, with a warning.
pub fn cache_max_bytes() -> u64 {
    resolve_max_bytes(
        std::env::var(CACHE_MAX_BYTES_ENV).ok(),
        *MAX_OVERRIDE.read().unwrap_or_else(|e| e.into_inner()),
    )
}

fn resolve_max_bytes(env: Option<String>, over: Option<u64>) -> u64 {
    static WARNED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    if let Some(text) = env.filter(|s| !s.trim().is_empty()) {
        match parse_bytes(&text) {
            Some(n) => return n,
            // Once per process: the bound is looked up at every compile.
            None if WARNED.swap(true, std::sync::atomic::Ordering::Relaxed) => {}
            None => log::warn!(
                "{CACHE_MAX_BYTES_ENV}={text:?} is not a size (bytes, or a number with K, M, \
                 G or T, optionally followed by iB); using {}",
                over.unwrap_or(DEFAULT_CACHE_MAX_BYTES)
            ),
        }
    }
    over.unwrap_or(DEFAULT_CACHE_MAX_BYTES)
}

/// A size: digits, optionally followed by a binary unit (`K`, `M`, `G`, `T`, alone or with
/// `iB`, any case). `None` for anything else or an overflow.
pub(super) fn parse_bytes(text: &str) -> Option<u64> {
    let text = text.trim();
    let digits = text
        .find(|c: char| !c.is_ascii_digit())
        .unwrap_or(text.len());
    let (number, unit) = text.split_at(digits);
    let number: u64 = number.parse().ok()?;
    let unit = unit.trim().to_ascii_lowercase();
    let shift = match unit.strip_suffix("ib").unwrap_or(&unit) {
        "" if !unit.ends_with("ib") => 0,
        "k" => 10,
        "m" => 20,
        "g" => 30,
        "t" => 40,
        _ => return None,
    };
    number.checked_mul(1u64 << shift)
}

/// Removes the least recently used entries of `dir` until they total at most `limit` bytes,
/// never the entry `keep` (the one just stored). Returns how many this call removed.
pub(super) fn evict(dir: &OpenDir, limit: u64, keep: &str) -> io::Result<usize> {
    let (temps, mut entries): (Vec<_>, Vec<_>) = dir
        .files(|name| is_entry(name) || name.contains(".tmp."))?
        .into_iter()
        .partition(|f| f.name.contains(".tmp."));
    // Temporary files a crashed writer left behind (a live one is renamed within moments of
    // its creation) would otherwise pile up outside the bound.
    let now = std::time::SystemTime::now();
    let stale = now.checked_sub(STALE_TEMP).unwrap_or(now);
    for temp in temps.iter().filter(|f| f.modified < stale) {
        match dir.remove(&temp.name) {
            Ok(()) => log::debug!(
                "kernel cache: removed stale temporary {}",
                dir.path().join(&temp.name).display()
            ),
            Err(e) if e.kind() == ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
    }
    let mut total: u64 = entries.iter().map(|f| f.len).sum();
    if total <= limit {
        return Ok(0);
    }
    // Oldest first; the name breaks ties so that the order is the same in every process.
    entries.sort_by(|a, b| {
        a.modified
            .cmp(&b.modified)
            .then_with(|| a.name.cmp(&b.name))
    });
    let mut removed = 0;
    for file in entries.iter().filter(|f| f.name != keep) {
        if total <= limit {
            break;
        }
        match dir.remove(&file.name) {
            Ok(()) => {
                removed += 1;
                log::debug!(
                    "kernel cache: evicted {} ({} bytes; the cache is bounded to {limit} bytes)",
                    dir.path().join(&file.name).display(),
                    file.len
                );
            }
            // Another process evicted or replaced it first.
            Err(e) if e.kind() == ErrorKind::NotFound => {}
            Err(e) => return Err(e),
        }
        total -= file.len;
    }
    Ok(removed)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_bytes("0"), Some(0));
        assert_eq!(parse_bytes(" 1234 "), Some(1234));
        assert_eq!(parse_bytes("64K"), Some(64 << 10));
        assert_eq!(parse_bytes("64KiB"), Some(64 << 10));
        assert_eq!(parse_bytes("512m"), Some(512 << 20));
        assert_eq!(parse_bytes("2 GiB"), Some(2 << 30));
        assert_eq!(parse_bytes("1T"), Some(1 << 40));
        for bad in [
            "",
            "G",
            "1.5G",
            "-1",
            "12 apples",
            "1iB",
            "99999999999999999999",
            "1e9",
        ] {
            assert_eq!(parse_bytes(bad), None, "{bad:?}");
        }
        assert_eq!(parse_bytes("17179869184G"), None, "overflow");
    }

    #[test]
    fn bound_precedence() {
        assert_eq!(resolve_max_bytes(None, None), DEFAULT_CACHE_MAX_BYTES);
        assert_eq!(resolve_max_bytes(None, Some(5)), 5);
        assert_eq!(resolve_max_bytes(Some("7".into()), Some(5)), 7);
        assert_eq!(resolve_max_bytes(Some("".into()), Some(5)), 5);
        assert_eq!(resolve_max_bytes(Some("lots".into()), Some(5)), 5);
        assert_eq!(
            resolve_max_bytes(Some("lots".into()), None),
            DEFAULT_CACHE_MAX_BYTES
        );
    }
}

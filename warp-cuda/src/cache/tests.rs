//! Tests of the kernel cache: keys, entries, trust, the key file and eviction (no NVRTC
//! or GPU needed, except where a test says it skips without NVRTC).

use super::entry::{encode, sanitize, unique_suffix, HEADER_LEN};
use super::trust::current_uid;
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
        u128::from_le_bytes(*b"\xaf\x13\x49\xb9\xf5\xf9\xa1\xa6\xa0\x40\x4d\xea\x36\xdc\xc9\x49")
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
        fs::write(c.dir().join(STAMP_FILE), bad).unwrap();
        assert_eq!(c.read_stamp(), None, "{bad:?}");
    }
}

/// A lookup finds what `compile_cached_entry` would serve, under the stamp's version, and
/// otherwise nothing: it never compiles (an absent or damaged entry, another source, another
/// architecture, options or name, or no stamp at all), so it passes without NVRTC.
#[test]
fn lookups_find_cached_cubins_and_never_compile() {
    let t = TempDir::new("lookup");
    let c = KernelCache::new(&t.0);
    let opts = CompileOptions::default();
    // No stamp yet: nothing compiled into this cache, nothing found.
    assert!(c.lookup_entry("src", "k", &opts, 90).is_none());
    let stamped = (99, 7);
    let key = cache_key("src", "k", &opts, 90, stamped);
    c.store("k", key, b"cubin bytes").unwrap();
    c.write_stamp(stamped);
    let (compiled, entry) = c.lookup_entry("src", "k", &opts, 90).expect("a hit");
    assert_eq!(compiled.cubin, b"cubin bytes");
    assert_eq!(compiled.compile_ms, 0.0);
    assert_eq!(
        entry,
        CacheEntry {
            key,
            path: Some(c.path_for("k", key))
        }
    );
    let fmad_off = CompileOptions {
        fmad: false,
        ..CompileOptions::default()
    };
    assert!(c.lookup_entry("other", "k", &opts, 90).is_none());
    assert!(c.lookup_entry("src", "k", &opts, 80).is_none());
    assert!(c.lookup_entry("src", "k2", &opts, 90).is_none());
    assert!(c.lookup_entry("src", "k", &fmad_off, 90).is_none());
    // A damaged entry is no hit (the compile that follows replaces it).
    let path = c.path_for("k", key);
    let mut bytes = fs::read(&path).unwrap();
    let last = bytes.len() - 1;
    bytes[last] ^= 1;
    fs::write(&path, bytes).unwrap();
    assert!(c.lookup_entry("src", "k", &opts, 90).is_none());
    // Nothing was written by the lookups.
    let mut want = vec![
        entry_name("k", key),
        KEY_FILE.to_string(),
        STAMP_FILE.to_string(),
    ];
    want.sort();
    assert_eq!(files(&t.0), want);
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
    c.parent = parent.clone();
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
    let dir = OpenDir::open(&t.0, None).unwrap();
    let e = dir
        .create_new("k-1.cubin.tmp.1.0123456789abcdef")
        .unwrap_err();
    assert_eq!(e.kind(), ErrorKind::AlreadyExists);
    fs::write(t.0.join("plain"), b"x").unwrap();
    assert_eq!(
        dir.create_new("plain").unwrap_err().kind(),
        ErrorKind::AlreadyExists
    );
    assert_eq!(fs::read(&victim).unwrap(), b"precious");
    assert!(fs::symlink_metadata(&tmp).unwrap().file_type().is_symlink());
    // Temporaries are created owner-only.
    use std::os::unix::fs::PermissionsExt;
    let fresh = t.0.join("fresh");
    drop(dir.create_new("fresh").unwrap());
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

#[cfg(unix)]
fn mode_of(path: &Path) -> u32 {
    use std::os::unix::fs::PermissionsExt;
    fs::symlink_metadata(path).unwrap().permissions().mode() & 0o777
}

#[cfg(unix)]
fn chmod(path: &Path, mode: u32) {
    use std::os::unix::fs::PermissionsExt;
    fs::set_permissions(path, fs::Permissions::from_mode(mode)).unwrap();
}

/// An entry writable by group or others (or owned by another user) is refused on its own
/// descriptor, even with a sound MAC: it counts as damaged, and the rebuild replaces it
/// with an owner-only file.
#[cfg(unix)]
#[test]
fn entry_writable_by_others_is_refused() {
    let t = TempDir::new("entry-mode");
    let c = KernelCache::new(&t.0);
    let path = c.store("k", 1, b"cubin").unwrap();
    assert_eq!(mode_of(&path), 0o600);
    for mode in [0o620, 0o602, 0o666] {
        chmod(&path, mode);
        assert_eq!(c.load("k", 1), CacheLookup::Damaged, "mode {mode:o}");
    }
    // Read-only for others is fine: only writers could have changed it.
    chmod(&path, 0o644);
    assert_eq!(c.load("k", 1), CacheLookup::Hit(b"cubin".to_vec()));
    chmod(&path, 0o666);
    c.store("k", 1, b"cubin").unwrap();
    assert_eq!(mode_of(&path), 0o600);
    assert_eq!(c.load("k", 1), CacheLookup::Hit(b"cubin".to_vec()));
    // Another user's entry (making one needs root; skipped otherwise).
    if std::os::unix::fs::chown(&path, Some(4242), None).is_ok() {
        assert_eq!(c.load("k", 1), CacheLookup::Damaged);
    }
}

/// A key file that others can read or write, or that is a symlink, switches the cache off
/// for that directory: nothing is loaded (even entries its MAC vouches for) and a store
/// fails saying why; the key file is left as it is for its owner to fix.
#[cfg(unix)]
#[test]
fn key_of_wrong_mode_is_refused() {
    let t = TempDir::new("key-mode");
    let c = KernelCache::new(&t.0);
    c.store("k", 1, b"cubin").unwrap();
    let key = t.0.join(KEY_FILE);
    for (mode, why) in [
        (0o644, "readable"),
        (0o640, "readable"),
        (0o620, "writable"),
    ] {
        chmod(&key, mode);
        assert_eq!(c.load("k", 1), CacheLookup::Absent, "mode {mode:o}");
        let e = crate::error::Chain(&c.store("k", 2, b"x").unwrap_err()).to_string();
        assert!(e.contains(why) && e.contains("key"), "{e}");
        assert_eq!(mode_of(&key), mode, "left alone");
    }
    chmod(&key, 0o600);
    assert_eq!(c.load("k", 1), CacheLookup::Hit(b"cubin".to_vec()));
    // A symlink at the key's name, even to the right key, is not followed.
    let elsewhere = t.0.join("elsewhere");
    fs::rename(&key, &elsewhere).unwrap();
    std::os::unix::fs::symlink(&elsewhere, &key).unwrap();
    assert_eq!(c.load("k", 1), CacheLookup::Absent);
    let e = crate::error::Chain(&c.store("k", 2, b"x").unwrap_err()).to_string();
    assert!(e.contains("symbolic link"), "{e}");
    assert!(fs::symlink_metadata(&key).unwrap().file_type().is_symlink());
}

/// A symlink at an entry's name is not followed, even to a sound entry: it counts as
/// damaged, and the rebuild replaces the link, never writing through it.
#[cfg(unix)]
#[test]
fn symlinked_entry_is_not_followed() {
    let t = TempDir::new("entry-link");
    let c = KernelCache::new(t.0.join("cache"));
    let path = c.store("k", 1, b"cubin").unwrap();
    let outside = t.0.join("outside.cubin");
    fs::rename(&path, &outside).unwrap();
    std::os::unix::fs::symlink(&outside, &path).unwrap();
    assert_eq!(c.load("k", 1), CacheLookup::Damaged);
    let sound = fs::read(&outside).unwrap();
    c.store("k", 1, b"fresh").unwrap();
    assert!(!fs::symlink_metadata(&path)
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(fs::read(&outside).unwrap(), sound);
    assert_eq!(c.load("k", 1), CacheLookup::Hit(b"fresh".to_vec()));
}

/// For the default layouts the version directory is opened through its checked parent
/// without following a symlink: one swapped in for it is refused.
#[cfg(unix)]
#[test]
fn symlinked_version_dir_is_refused() {
    let t = TempDir::new("dir-link");
    let (dir, parent) = resolve_cache_dir(None, None, None, t.0.clone(), current_uid());
    let mut c = KernelCache::new(&dir);
    c.parent = parent;
    c.store("k", 1, b"x").unwrap();
    let real = t.0.join("real");
    fs::rename(&dir, &real).unwrap();
    std::os::unix::fs::symlink(&real, &dir).unwrap();
    assert_eq!(c.load("k", 1), CacheLookup::Absent);
    assert!(c.store("k", 1, b"x").is_err());
    // The same directory named directly (the variable or set_cache_dir) may be a link:
    // what is checked is the directory it opens.
    assert_eq!(
        KernelCache::new(&dir).load("k", 1),
        CacheLookup::Hit(b"x".to_vec())
    );
}

/// A key file cut short (an empty one left by a crash before its data reached the disk)
/// no longer switches the cache off for good: the next store replaces it with a whole
/// key, owner-only; entries stored under the old key fail their MAC and are rebuilt.
#[test]
fn damaged_key_is_replaced() {
    for damaged in [&b""[..], &[7u8; 31][..], &[7u8; 33][..]] {
        let t = TempDir::new("key-damaged");
        let c = KernelCache::new(&t.0);
        c.store("a", 1, b"old").unwrap();
        let key = t.0.join(KEY_FILE);
        fs::write(&key, damaged).unwrap();
        assert_eq!(c.load("a", 1), CacheLookup::Absent);
        c.store("b", 2, b"new").unwrap();
        assert_eq!(fs::read(&key).unwrap().len(), 32);
        #[cfg(unix)]
        assert_eq!(mode_of(&key), 0o600);
        assert_eq!(c.load("b", 2), CacheLookup::Hit(b"new".to_vec()));
        assert_eq!(
            c.load("a", 1),
            CacheLookup::Damaged,
            "MAC'd under the old key"
        );
        c.store("a", 1, b"old").unwrap();
        assert_eq!(c.load("a", 1), CacheLookup::Hit(b"old".to_vec()));
        // No temporary left behind.
        assert_eq!(files(&t.0).len(), 3, "{:?}", files(&t.0));
    }
}

/// Processes (threads here) creating the key at once all end with the one key that won:
/// every entry any of them stored verifies.
#[test]
fn concurrent_key_creation_agrees() {
    let t = TempDir::new("key-race");
    let handles: Vec<_> = (0..8u128)
        .map(|i| {
            let c = KernelCache::new(t.0.join("cache"));
            std::thread::spawn(move || c.store("k", i, &[i as u8; 10]).map(|_| ()))
        })
        .collect();
    for h in handles {
        h.join().unwrap().unwrap();
    }
    let c = KernelCache::new(t.0.join("cache"));
    for i in 0..8u128 {
        assert_eq!(c.load("k", i), CacheLookup::Hit(vec![i as u8; 10]));
    }
    assert_eq!(files(c.dir()).len(), 9, "{:?}", files(c.dir()));
}

fn set_mtime(path: &Path, secs_after_epoch: u64) {
    let t = std::time::UNIX_EPOCH + std::time::Duration::from_secs(secs_after_epoch);
    fs::File::options()
        .write(true)
        .open(path)
        .unwrap()
        .set_modified(t)
        .unwrap();
}

/// A hit marks the entry used now (its modification time), for eviction.
#[test]
fn hit_marks_entry_used() {
    let t = TempDir::new("touch");
    let c = KernelCache::new(&t.0);
    let path = c.store("k", 1, b"x").unwrap();
    set_mtime(&path, 1_000_000);
    let before = fs::metadata(&path).unwrap().modified().unwrap();
    assert_eq!(c.load("k", 1), CacheLookup::Hit(b"x".to_vec()));
    let after = fs::metadata(&path).unwrap().modified().unwrap();
    assert!(after > before, "{before:?} -> {after:?}");
}

/// Over its bound, a store removes the least recently used entries first (a hit counts as
/// a use) until the entries fit, never the key, the stamp, other files, or the entry just
/// stored.
#[test]
fn eviction_removes_least_recently_used_first() {
    let t = TempDir::new("evict");
    let entry_len = (HEADER_LEN + 100) as u64;
    let c = KernelCache::new(&t.0).with_max_bytes(Some(4 * entry_len));
    assert_eq!(c.max_bytes(), Some(4 * entry_len));
    let mut paths = Vec::new();
    for (i, name) in ["a", "b", "c", "d"].into_iter().enumerate() {
        let path = c.store(name, 1, &[0u8; 100]).unwrap();
        set_mtime(&path, 1_000_000 + i as u64);
        paths.push(path);
    }
    c.write_stamp((13, 0));
    fs::write(t.0.join("notes.txt"), vec![0u8; 10_000]).unwrap();
    let entries = |c: &KernelCache| -> Vec<String> {
        files(c.dir())
            .into_iter()
            .filter(|f| f.ends_with(".cubin"))
            .map(|f| f[..1].to_string())
            .collect()
    };
    assert_eq!(
        entries(&c),
        ["a", "b", "c", "d"],
        "at the bound: nothing evicted"
    );
    // "a" is the oldest stored, but used now: "b" goes first.
    assert_eq!(c.load("a", 1), CacheLookup::Hit(vec![0u8; 100]));
    let e = c.store("e", 1, &[0u8; 100]).unwrap();
    assert_eq!(entries(&c), ["a", "c", "d", "e"]);
    // The load touched "a" (now, not its old stamp); "e" was stored after it. The file clock is
    // coarse enough for both to get the same mtime, and then eviction would fall to the
    // tie-break: give them distinct ones in their order.
    let touched = fs::metadata(&paths[0]).unwrap().modified().unwrap();
    assert!(touched > std::time::UNIX_EPOCH + std::time::Duration::from_secs(1_000_003));
    set_mtime(&paths[0], 2_000_000);
    set_mtime(&e, 2_000_001);
    // A tighter bound: down to what fits, oldest first.
    let small = c.clone().with_max_bytes(Some(2 * entry_len + 10));
    small.store("f", 1, &[0u8; 100]).unwrap();
    assert_eq!(entries(&c), ["e", "f"]);
    let total: u64 = ["e", "f"]
        .iter()
        .map(|n| fs::metadata(c.path_for(n, 1)).unwrap().len())
        .sum();
    assert!(total <= 2 * entry_len + 10);
    // An entry alone over the bound is still kept (it was just compiled for use).
    let tiny = c.clone().with_max_bytes(Some(10));
    tiny.store("g", 1, &[0u8; 100]).unwrap();
    assert_eq!(entries(&c), ["g"]);
    assert_eq!(tiny.load("g", 1), CacheLookup::Hit(vec![0u8; 100]));
    assert!(t.0.join(KEY_FILE).is_file() && t.0.join(STAMP_FILE).is_file());
    assert!(t.0.join("notes.txt").is_file());
    // A temporary file a crashed writer left an hour ago goes with the next eviction; a
    // fresh one (a writer at work) stays.
    let (old, fresh) = (
        t.0.join("x-1.cubin.tmp.1.00"),
        t.0.join("y-1.cubin.tmp.1.00"),
    );
    fs::write(&old, b"partial").unwrap();
    fs::write(&fresh, b"partial").unwrap();
    set_mtime(&old, 1_000_000);
    tiny.store("g", 1, &[0u8; 100]).unwrap();
    assert!(!old.exists() && fresh.exists());
    fs::remove_file(&fresh).unwrap();
    // Unbounded (an ahead-of-time directory): nothing is evicted.
    let unbounded = KernelCache::new(&t.0);
    assert_eq!(unbounded.max_bytes(), None);
    for name in ["h", "i", "j"] {
        unbounded.store(name, 1, &[0u8; 100]).unwrap();
    }
    assert_eq!(entries(&c), ["g", "h", "i", "j"]);
}

/// The current cache is bounded by the process-wide setting.
#[test]
fn current_cache_is_bounded() {
    assert_eq!(KernelCache::current().max_bytes(), Some(cache_max_bytes()));
}

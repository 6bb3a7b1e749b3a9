//! Trust in the cache's directory and files, checked on their open handles.
//!
//! Every check is made with `fstat` on the descriptor that is then used (the directory's, the
//! key file's, an entry's), never on a path looked up again later: a path swapped for a
//! symlink, or another file, between a check and an open cannot slip through. Files are
//! opened relative to the checked directory's descriptor (`openat`) with `O_NOFOLLOW`, so a
//! symlink planted at an entry's or the key's name is refused, not followed; for the default
//! layouts the version directory is opened relative to its checked `warp-lang` parent in the
//! same way. Off Unix there are no owners or modes to check and plain paths are used.

#[cfg(not(unix))]
use std::fs;
use std::fs::File;
use std::io::{self, ErrorKind};
use std::path::{Path, PathBuf};
use std::time::SystemTime;

#[cfg(unix)]
use rustix::fs::{AtFlags, Mode, OFlags};
#[cfg(unix)]
use std::os::fd::OwnedFd;

/// The effective user id (the owner the cache's directory and files must have, or root's); 0
/// off Unix, where no owner check is made.
pub(super) fn current_uid() -> u32 {
    #[cfg(unix)]
    {
        rustix::process::geteuid().as_raw()
    }
    #[cfg(not(unix))]
    {
        0
    }
}

/// Why a directory or file owned by `owner` with mode `mode` must not be part of the cache of
/// the user `me`, or `None` when it may. Trusted: owned by this user or by root (root can
/// replace anything anyway; an installed ahead-of-time directory is often root's), and
/// writable by neither group nor others: anyone else who could write there could plant an
/// entry, or swap an entry's file, or a temporary file's name, or (for an entry) rewrite the
/// cubin in place.
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

/// Why the MAC key file (owned by `owner`, mode `mode`) must not be used by the user `me`:
/// [`distrust_reason`], and, when it is this user's own, readable by group or others (whoever
/// reads the key can forge entries; the cache creates it 0600). A key owned by root and
/// readable by all is accepted: that is how an ahead-of-time directory installed by root is
/// shipped to every user, and root could replace the entries anyway.
#[cfg_attr(not(unix), allow(dead_code))]
pub(crate) fn key_distrust_reason(owner: u32, mode: u32, me: u32) -> Option<String> {
    distrust_reason(owner, mode, me).or_else(|| {
        (owner == me && mode & 0o044 != 0).then(|| {
            format!(
                "it is readable by others than its owner (mode {:03o}; `chmod 600` it, or \
                 remove it: the cache makes a new key and rebuilds its entries)",
                mode & 0o7777
            )
        })
    })
}

/// Checks an opened file's metadata (taken from its descriptor): a regular file, and trusted
/// by `rule` ([`distrust_reason`] for entries, [`key_distrust_reason`] for the key).
pub(super) fn check_file(file: &File, rule: fn(u32, u32, u32) -> Option<String>) -> io::Result<()> {
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(io::Error::new(
            ErrorKind::InvalidData,
            "it is not a regular file",
        ));
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        if let Some(why) = rule(meta.uid(), meta.mode(), current_uid()) {
            return Err(io::Error::new(ErrorKind::PermissionDenied, why));
        }
    }
    #[cfg(not(unix))]
    let _ = rule;
    Ok(())
}

/// Logs, once per path and process, why a cache directory or key file is not used.
pub(super) fn warn_distrusted(path: &Path, why: &io::Error) {
    static WARNED: std::sync::Mutex<Vec<PathBuf>> = std::sync::Mutex::new(Vec::new());
    let mut warned = WARNED.lock().unwrap_or_else(|e| e.into_inner());
    if !warned.iter().any(|d| d == path) {
        warned.push(path.to_path_buf());
        log::warn!(
            "kernel cache: {} is not used: {why}; kernels are compiled in memory",
            path.display()
        );
    }
}

/// A file of the directory, as [`OpenDir::files`] lists it.
pub(super) struct DirFile {
    pub(super) name: String,
    pub(super) len: u64,
    pub(super) modified: SystemTime,
}

/// A cache directory, opened and checked: every file operation goes through it.
#[derive(Debug)]
pub(super) struct OpenDir {
    path: PathBuf,
    #[cfg(unix)]
    fd: OwnedFd,
}

#[cfg(unix)]
fn errno(e: rustix::io::Errno) -> io::Error {
    if e == rustix::io::Errno::LOOP {
        // O_NOFOLLOW met a symlink: say so rather than "too many levels of symbolic links".
        return io::Error::new(
            ErrorKind::InvalidInput,
            "it is a symbolic link, which the cache does not follow",
        );
    }
    e.into()
}

impl OpenDir {
    /// Opens `dir` and checks it on its descriptor: a directory, owned by this user or root,
    /// writable by neither group nor others. When `parent` is `dir`'s parent (the default
    /// layouts), the parent is opened and checked first and `dir` opened through it without
    /// following a symlink. `Err` names the directory that failed and why; a missing
    /// directory is `NotFound`.
    pub(super) fn open(dir: &Path, parent: Option<&Path>) -> Result<OpenDir, (PathBuf, io::Error)> {
        #[cfg(unix)]
        {
            let flags = OFlags::RDONLY | OFlags::DIRECTORY | OFlags::CLOEXEC;
            let checked = |fd: OwnedFd, path: &Path| -> Result<OwnedFd, (PathBuf, io::Error)> {
                let fail = |e: io::Error| (path.to_path_buf(), e);
                let st = rustix::fs::fstat(&fd).map_err(|e| fail(e.into()))?;
                if let Some(why) = distrust_reason(st.st_uid, st.st_mode as u32, current_uid()) {
                    return Err(fail(io::Error::new(ErrorKind::PermissionDenied, why)));
                }
                Ok(fd)
            };
            let open_err = |path: &Path, e: rustix::io::Errno| {
                let e = if e == rustix::io::Errno::NOTDIR {
                    io::Error::new(ErrorKind::InvalidInput, "it is not a directory")
                } else {
                    errno(e)
                };
                (path.to_path_buf(), e)
            };
            let fd = match (parent, dir.file_name()) {
                (Some(p), Some(name)) if dir.parent() == Some(p) => {
                    let pfd =
                        rustix::fs::open(p, flags, Mode::empty()).map_err(|e| open_err(p, e))?;
                    let pfd = checked(pfd, p)?;
                    rustix::fs::openat(&pfd, name, flags | OFlags::NOFOLLOW, Mode::empty())
                        .map_err(|e| open_err(dir, e))?
                }
                _ => rustix::fs::open(dir, flags, Mode::empty()).map_err(|e| open_err(dir, e))?,
            };
            Ok(OpenDir {
                path: dir.to_path_buf(),
                fd: checked(fd, dir)?,
            })
        }
        #[cfg(not(unix))]
        {
            let _ = parent;
            match fs::metadata(dir) {
                Ok(m) if m.is_dir() => Ok(OpenDir {
                    path: dir.to_path_buf(),
                }),
                Ok(_) => Err((
                    dir.to_path_buf(),
                    io::Error::new(ErrorKind::InvalidInput, "it is not a directory"),
                )),
                Err(e) => Err((dir.to_path_buf(), e)),
            }
        }
    }

    /// The directory's path (for messages and the paths handed to callers).
    pub(super) fn path(&self) -> &Path {
        &self.path
    }

    /// Opens the file `name` of the directory for reading, never through a symlink (one at
    /// `name` is an error) and without blocking on a FIFO planted there.
    pub(super) fn open_file(&self, name: &str) -> io::Result<File> {
        #[cfg(unix)]
        {
            let flags = OFlags::RDONLY | OFlags::NOFOLLOW | OFlags::NONBLOCK | OFlags::CLOEXEC;
            rustix::fs::openat(&self.fd, name, flags, Mode::empty())
                .map(File::from)
                .map_err(errno)
        }
        #[cfg(not(unix))]
        {
            File::open(self.path.join(name))
        }
    }

    /// Creates the file `name` for writing, owner-only, failing if anything (a file, or a
    /// symlink planted to redirect the write) is already there.
    pub(super) fn create_new(&self, name: &str) -> io::Result<File> {
        #[cfg(unix)]
        {
            let flags =
                OFlags::WRONLY | OFlags::CREATE | OFlags::EXCL | OFlags::NOFOLLOW | OFlags::CLOEXEC;
            rustix::fs::openat(&self.fd, name, flags, Mode::from_raw_mode(0o600))
                .map(File::from)
                .map_err(errno)
        }
        #[cfg(not(unix))]
        {
            fs::OpenOptions::new()
                .write(true)
                .create_new(true)
                .open(self.path.join(name))
        }
    }

    /// Renames `from` to `to` in the directory, replacing `to` (a symlink there is replaced,
    /// never written through).
    pub(super) fn rename(&self, from: &str, to: &str) -> io::Result<()> {
        #[cfg(unix)]
        {
            rustix::fs::renameat(&self.fd, from, &self.fd, to).map_err(errno)
        }
        #[cfg(not(unix))]
        {
            fs::rename(self.path.join(from), self.path.join(to))
        }
    }

    /// Links `from` as `to`, failing with `AlreadyExists` if `to` is there (a link never
    /// replaces a file: of two processes linking at once, exactly one wins).
    pub(super) fn link(&self, from: &str, to: &str) -> io::Result<()> {
        #[cfg(unix)]
        {
            rustix::fs::linkat(&self.fd, from, &self.fd, to, AtFlags::empty()).map_err(errno)
        }
        #[cfg(not(unix))]
        {
            fs::hard_link(self.path.join(from), self.path.join(to))
        }
    }

    /// Removes the file `name` (a symlink itself, never its target).
    pub(super) fn remove(&self, name: &str) -> io::Result<()> {
        #[cfg(unix)]
        {
            rustix::fs::unlinkat(&self.fd, name, AtFlags::empty()).map_err(errno)
        }
        #[cfg(not(unix))]
        {
            fs::remove_file(self.path.join(name))
        }
    }

    /// Flushes the directory itself (its names) to disk: after this, a rename or link into it
    /// survives a crash.
    pub(super) fn sync(&self) -> io::Result<()> {
        #[cfg(unix)]
        {
            rustix::fs::fsync(&self.fd).map_err(errno)
        }
        #[cfg(not(unix))]
        {
            // No directory handle to flush through std off Unix; NTFS journals its names.
            Ok(())
        }
    }

    /// The regular files of the directory whose names satisfy `keep` (symlinks and other
    /// kinds are left out; a file removed meanwhile by another process is skipped).
    pub(super) fn files(&self, keep: impl Fn(&str) -> bool) -> io::Result<Vec<DirFile>> {
        let mut out = Vec::new();
        #[cfg(unix)]
        {
            for entry in rustix::fs::Dir::read_from(&self.fd).map_err(errno)? {
                let entry = entry.map_err(errno)?;
                let Ok(name) = entry.file_name().to_str() else {
                    continue;
                };
                if !keep(name) {
                    continue;
                }
                let Ok(st) = rustix::fs::statat(&self.fd, name, AtFlags::SYMLINK_NOFOLLOW) else {
                    continue;
                };
                if rustix::fs::FileType::from_raw_mode(st.st_mode)
                    != rustix::fs::FileType::RegularFile
                {
                    continue;
                }
                let modified = SystemTime::UNIX_EPOCH
                    .checked_add(std::time::Duration::new(
                        st.st_mtime.max(0) as u64,
                        st.st_mtime_nsec.clamp(0, 999_999_999) as u32,
                    ))
                    .unwrap_or(SystemTime::UNIX_EPOCH);
                out.push(DirFile {
                    name: name.to_string(),
                    len: st.st_size.max(0) as u64,
                    modified,
                });
            }
        }
        #[cfg(not(unix))]
        {
            for entry in fs::read_dir(&self.path)? {
                let entry = entry?;
                let name = entry.file_name();
                let Some(name) = name.to_str() else { continue };
                if !keep(name) {
                    continue;
                }
                let Ok(meta) = fs::symlink_metadata(entry.path()) else {
                    continue;
                };
                if meta.is_file() {
                    out.push(DirFile {
                        name: name.to_string(),
                        len: meta.len(),
                        modified: meta.modified().unwrap_or(SystemTime::UNIX_EPOCH),
                    });
                }
            }
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// The key's rules: the entries' rules, and private when it is this user's own.
    #[test]
    fn key_rules() {
        let me = 1000;
        assert_eq!(key_distrust_reason(me, 0o100600, me), None);
        assert_eq!(key_distrust_reason(me, 0o100400, me), None);
        for mode in [0o100640, 0o100604, 0o100644] {
            let why = key_distrust_reason(me, mode, me).expect("readable by others");
            assert!(why.contains("readable by others"), "{why}");
        }
        assert!(key_distrust_reason(me, 0o100620, me)
            .unwrap()
            .contains("writable by its group"));
        assert!(key_distrust_reason(1001, 0o100600, me).is_some());
        // Root's, readable by all: an installed ahead-of-time directory.
        assert_eq!(key_distrust_reason(0, 0o100644, me), None);
        assert!(key_distrust_reason(0, 0o100644, 0).is_some());
    }
}

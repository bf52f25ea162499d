//! The machine-wide store of unpacked FMUs, shared by every twinbench process of a user, and
//! its stat index: what lets a second process use an FMU without reading, hashing or
//! inflating its archive again.
//!
//! Layout of a store folder:
//! - `<sha256[..32]>/`: an unpacked FMU, keyed by the archive's content hash, with
//!   `.complete` inside (only ever renamed into place whole);
//! - `index/<key[..32]>`: one small text file per archive file seen, keyed by a hash of its
//!   canonical path and `stat` (device, inode, size, mtime and ctime in ns), holding the
//!   archive's content hash and a fingerprint of its central directory;
//! - `.<name>.tmp-*`: unpackings and index entries being written (a killed process may leave
//!   one; they are removed after a day).
//!
//! A process that unpacks into the store holds an exclusive `flock` on the store's folder.
//! Every unpacked folder holds its manifest (`.manifest`, see [`super::manifest`]); a
//! process that uses a folder holds a shared lock on its `.complete`, which `cache prune`
//! ([`prune`]) must take exclusively to remove it.

use sha2::{Digest, Sha256};
use std::ffi::OsString;
use std::fs::Metadata;
use std::io::{Read, Write};
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::MetadataExt;
use std::path::{Path, PathBuf};

/// The index's format: part of every key and the first line of every entry, so that an
/// entry of another format is never read as this one.
const INDEX_FORMAT: &str = "twinbench-unpack-index 1";
/// The index's folder in a store (never a content hash: those are hexadecimal).
pub(crate) const INDEX_DIR: &str = "index";
/// The largest index entry read (they are about 250 bytes).
const MAX_ENTRY_BYTES: u64 = 4096;
/// Temporaries older than this are left by a killed process (an unpacking takes seconds).
const STALE_AFTER: std::time::Duration = std::time::Duration::from_secs(24 * 3600);

/// Where the machine-wide store is: `$TWINBENCH_CACHE` if set, else
/// `$XDG_CACHE_HOME/twinbench/unpacked`, else `$HOME/.cache/twinbench/unpacked`. The first
/// of these that is set decides (a store named by `TWINBENCH_CACHE` that cannot be used is
/// not replaced by one in the home folder); `None` when none is set.
pub fn default_store_dir() -> Option<PathBuf> {
    store_dir_from(|k| std::env::var_os(k))
}

pub(crate) fn store_dir_from(var: impl Fn(&str) -> Option<OsString>) -> Option<PathBuf> {
    let set = |k: &str| var(k).filter(|v| !v.is_empty()).map(PathBuf::from);
    if let Some(p) = set("TWINBENCH_CACHE") {
        // Absolute, so that the unpacked folders' paths do not depend on the working folder.
        return std::path::absolute(p).ok();
    }
    // The XDG rules: a relative value is invalid and ignored.
    if let Some(p) = set("XDG_CACHE_HOME").filter(|p| p.is_absolute()) {
        return Some(p.join("twinbench").join("unpacked"));
    }
    set("HOME")
        .filter(|p| p.is_absolute())
        .map(|h| h.join(".cache").join("twinbench").join("unpacked"))
}

/// Creates the machine-wide store if needed (its own folder private to the user) and checks
/// that it can be trusted with libraries that twinbench loads: a folder of this user that
/// no other user can write into, and that this user can write into. The reason otherwise.
pub(crate) fn prepare(dir: &Path) -> Result<(), StoreError> {
    use std::os::unix::fs::{DirBuilderExt, PermissionsExt};
    if let Some(parent) = dir.parent() {
        std::fs::create_dir_all(parent).map_err(StoreError::Create)?;
    }
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(StoreError::Create(e)),
    }
    let meta = std::fs::metadata(dir).map_err(StoreError::Read)?;
    if !meta.is_dir() {
        return Err(StoreError::NotAFolder);
    }
    // SAFETY: geteuid has no preconditions and cannot fail.
    let me = unsafe { libc::geteuid() };
    if meta.uid() != me {
        return Err(StoreError::Owner {
            owner: meta.uid(),
            me,
        });
    }
    if meta.mode() & 0o022 != 0 {
        // Ours, made writable for others (a chmod by a process of this user, M1): repaired
        // to the mode it is created with (700: others can neither list nor read the
        // suppliers' binaries in it, P8), never replaced by another store. What others could
        // have written meanwhile is caught where it matters: every library is checked
        // against its FMU's archive before it is loaded.
        let repaired = 0o700;
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(repaired)).map_err(
            |source| StoreError::Repair {
                mode: meta.mode() & 0o7777,
                source,
            },
        )?;
        log::warn!(
            "{}: the store of unpacked FMUs was writable by other users (mode {:o}); repaired to mode {repaired:o}",
            dir.display(),
            meta.mode() & 0o7777
        );
    }
    let c = std::ffi::CString::new(dir.as_os_str().as_bytes()).map_err(|_| StoreError::NulByte)?;
    // SAFETY: access on a NUL-terminated path we own.
    if unsafe { libc::access(c.as_ptr(), libc::W_OK | libc::X_OK) } != 0 {
        return Err(StoreError::NotWritable);
    }
    Ok(())
}

/// Why the machine-wide store cannot be used (the message follows the store's path).
#[derive(Debug, thiserror::Error)]
pub(crate) enum StoreError {
    #[error("cannot create it: {0}")]
    Create(#[source] std::io::Error),
    #[error("cannot read it: {0}")]
    Read(#[source] std::io::Error),
    #[error("it is not a folder")]
    NotAFolder,
    #[error("it belongs to user id {owner}, not to this user ({me})")]
    Owner { owner: u32, me: u32 },
    /// Ours, writable by others, and the mode could not be set back.
    #[error("other users can write into it (mode {mode:o}) and it cannot be repaired: {source}")]
    Repair {
        mode: u32,
        #[source]
        source: std::io::Error,
    },
    #[error("its path holds a NUL byte")]
    NulByte,
    #[error("this user cannot write into it")]
    NotWritable,
}

/// One entry of an archive's central directory, as the index fingerprints it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct CdEntry {
    pub name: String,
    pub compressed: u64,
    pub size: u64,
    pub crc32: u32,
}

/// A hash of the central directory: every entry's name, compressed and uncompressed size
/// and CRC-32, in order. A change of any entry's content changes its CRC.
pub(crate) fn fingerprint(entries: &[CdEntry]) -> String {
    let mut h = Sha256::new();
    h.update((entries.len() as u64).to_le_bytes());
    for e in entries {
        h.update((e.name.len() as u64).to_le_bytes());
        h.update(e.name.as_bytes());
        h.update(e.compressed.to_le_bytes());
        h.update(e.size.to_le_bytes());
        h.update(e.crc32.to_le_bytes());
    }
    format!("{:x}", h.finalize())
}

/// The index key of a file: its canonical path and its `stat` identity (device, inode, size,
/// mtime and ctime to the nanosecond). A rewrite, a replacement or a move gives another key.
pub(crate) fn index_key(canonical: &Path, meta: &Metadata) -> String {
    let mut h = Sha256::new();
    h.update(INDEX_FORMAT.as_bytes());
    // Paths hold no NUL byte: the separator keeps the fields apart.
    h.update([0]);
    h.update(canonical.as_os_str().as_bytes());
    h.update([0]);
    for v in [meta.dev(), meta.ino(), meta.size()] {
        h.update(v.to_le_bytes());
    }
    for v in [
        meta.mtime(),
        meta.mtime_nsec(),
        meta.ctime(),
        meta.ctime_nsec(),
    ] {
        h.update(v.to_le_bytes());
    }
    format!("{:x}", h.finalize())
}

/// Whether two `stat`s of one open file show no change in between.
pub(crate) fn same_stat(a: &Metadata, b: &Metadata) -> bool {
    (a.dev(), a.ino(), a.size(), a.mtime(), a.mtime_nsec())
        == (b.dev(), b.ino(), b.size(), b.mtime(), b.mtime_nsec())
        && (a.ctime(), a.ctime_nsec()) == (b.ctime(), b.ctime_nsec())
}

/// What the index knows of one archive file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct IndexEntry {
    /// The full [`index_key`] (the file name holds only its first half).
    pub key: String,
    /// The archive's content hash: its unpacked folder is `<store>/<sha256[..32]>`.
    pub sha256: String,
    /// The central directory's entry count and [`fingerprint`].
    pub entries: usize,
    pub directory: String,
}

impl IndexEntry {
    fn to_text(&self) -> String {
        format!(
            "{INDEX_FORMAT}\nkey {}\nsha256 {}\nentries {}\ndirectory {}\n",
            self.key, self.sha256, self.entries, self.directory
        )
    }

    /// Strict: anything else than what [`IndexEntry::to_text`] writes is no entry. The
    /// hashes are checked to be hexadecimal, so that a damaged entry cannot name a folder
    /// outside the store.
    fn parse(text: &str) -> Option<IndexEntry> {
        let mut lines = text.strip_suffix('\n')?.split('\n');
        if lines.next()? != INDEX_FORMAT {
            return None;
        }
        let mut field = |name: &str| lines.next()?.strip_prefix(name)?.strip_prefix(' ');
        let key = hex64(field("key")?)?;
        let sha256 = hex64(field("sha256")?)?;
        let entries = field("entries")?.parse().ok()?;
        let directory = hex64(field("directory")?)?;
        if lines.next().is_some() {
            return None;
        }
        Some(IndexEntry {
            key,
            sha256,
            entries,
            directory,
        })
    }
}

fn hex64(s: &str) -> Option<String> {
    (s.len() == 64 && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))).then(|| s.into())
}

fn entry_path(store: &Path, key: &str) -> PathBuf {
    store.join(INDEX_DIR).join(&key[..32])
}

/// The index entry of `key`, if there is a valid one for exactly that key.
pub(crate) fn read_entry(store: &Path, key: &str) -> Option<IndexEntry> {
    let f = std::fs::File::open(entry_path(store, key)).ok()?;
    let mut text = String::new();
    f.take(MAX_ENTRY_BYTES).read_to_string(&mut text).ok()?;
    IndexEntry::parse(&text).filter(|e| e.key == key)
}

/// Writes an index entry atomically: a reader sees the old entry or the new one, whole.
/// The index folder is made private (0700) and the entry 0600, whatever the umask.
pub(crate) fn write_entry(store: &Path, entry: &IndexEntry) -> std::io::Result<()> {
    let path = entry_path(store, &entry.key);
    super::manifest::make_dir(&store.join(INDEX_DIR))?;
    let tmp = unique_sibling(&path);
    let written = (|| {
        let mut f = super::manifest::create_file(&tmp, super::manifest::FILE_MODE)?;
        f.write_all(entry.to_text().as_bytes())?;
        std::fs::rename(&tmp, &path)
    })();
    if written.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    written
}

/// Removes what killed processes left in the store: unpackings and index entries that were
/// being written (`.<name>.tmp-*`) more than a day ago. Only temporaries: an unpacked FMU
/// may be in use by any process at any time.
pub(crate) fn sweep_temporaries(store: &Path) {
    sweep_older_than(store, STALE_AFTER);
}

/// [`sweep_temporaries`] with another age; the number removed.
fn sweep_older_than(store: &Path, stale_after: std::time::Duration) -> usize {
    let mut removed = 0;
    for dir in [store.to_path_buf(), store.join(INDEX_DIR)] {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let name = e.file_name();
            let name = name.to_string_lossy();
            if !(name.starts_with('.') && name.contains(".tmp-")) {
                continue;
            }
            let old = e
                .metadata()
                .and_then(|m| m.modified())
                .ok()
                .and_then(|t| t.elapsed().ok())
                .is_some_and(|age| age > stale_after);
            if old {
                let p = e.path();
                if std::fs::remove_dir_all(&p)
                    .or_else(|_| std::fs::remove_file(&p))
                    .is_ok()
                {
                    removed += 1;
                }
            }
        }
    }
    removed
}

/// The store's unpack lock (the store's folder itself, flocked exclusively while one
/// process unpacks into it): processes that start together on a new FMU unpack it once, not
/// each a copy. `None` when it cannot be had (the unpacking goes on without it; after ten
/// minutes of waiting too: a stopped process must not stop every other).
pub(crate) fn unpack_lock(store: &Path) -> Option<std::fs::File> {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::OpenOptionsExt;
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_DIRECTORY | libc::O_CLOEXEC)
        .open(store)
        .ok()?;
    let until = std::time::Instant::now() + std::time::Duration::from_secs(600);
    loop {
        // SAFETY: flock on a descriptor we own.
        if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0 {
            return Some(f);
        }
        if std::time::Instant::now() > until {
            return None;
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
}

/// The unpack lock if no process holds it now.
fn try_unpack_lock(store: &Path) -> Option<std::fs::File> {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::OpenOptionsExt;
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_DIRECTORY | libc::O_CLOEXEC)
        .open(store)
        .ok()?;
    // SAFETY: flock on a descriptor we own.
    (unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0).then_some(f)
}

/// Whether a store entry's name is an unpacked FMU's folder (32 hexadecimal digits).
fn is_unpacked(name: &str) -> bool {
    name.len() == 32 && name.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// The bytes a folder's files take (their sizes; folders not counted).
fn size_of(dir: &Path) -> u64 {
    let mut total = 0;
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            match e.file_type() {
                Ok(t) if t.is_dir() => todo.push(e.path()),
                Ok(_) => total += e.metadata().map_or(0, |m| m.len()),
                Err(_) => {}
            }
        }
    }
    total
}

/// One unpacked FMU of a store, as `cache info` and `cache prune` see it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StoreFolder {
    pub path: PathBuf,
    pub bytes: u64,
    /// When a process last loaded it (the time of its `.complete`).
    pub last_used: std::time::SystemTime,
    /// A running process holds it (a shared lock on its `.complete`).
    pub in_use: bool,
    /// Without `.complete`: left by something else than an unpacking.
    pub incomplete: bool,
}

/// The unpacked FMUs of a store, least recently used first.
pub fn folders(store: &Path) -> std::io::Result<Vec<StoreFolder>> {
    use std::os::fd::AsRawFd;
    let mut out = Vec::new();
    for e in std::fs::read_dir(store)?.flatten() {
        let name = e.file_name();
        if !is_unpacked(&name.to_string_lossy()) || !e.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        let path = e.path();
        let complete = path.join(".complete");
        let (in_use, incomplete, last_used) = match std::fs::File::open(&complete) {
            Ok(f) => {
                // SAFETY: flock on a descriptor we own; released when `f` is closed.
                let free = unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_SH | libc::LOCK_NB) }
                    == 0
                    && unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } == 0;
                let t = f.metadata().and_then(|m| m.modified());
                (!free, false, t)
            }
            Err(_) => (false, true, e.metadata().and_then(|m| m.modified())),
        };
        out.push(StoreFolder {
            bytes: size_of(&path),
            path,
            last_used: last_used.unwrap_or(std::time::UNIX_EPOCH),
            in_use,
            incomplete,
        });
    }
    out.sort_by_key(|f| f.last_used);
    Ok(out)
}

/// What `cache prune` did.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Pruned {
    pub removed: Vec<StoreFolder>,
    /// Folders kept although the bound asked for their room: running processes use them.
    pub kept_in_use: usize,
    /// Index entries and temporaries removed.
    pub index_entries: usize,
    pub temporaries: usize,
    /// What the store's folders take afterwards.
    pub bytes_left: u64,
}

/// Removes from `store` the unpacked FMUs no running process uses that were last used more
/// than `older_than` ago, then, least recently used first, unused ones until the folders
/// take at most `max_bytes`; folders without `.complete`; temporaries of killed processes
/// (when no process is unpacking, else those a day old); index entries whose folder is
/// gone. A folder is removed
/// only while holding its `.complete` lock exclusively (a process that loads it takes it
/// shared, and after waiting for it finds the folder gone and unpacks again).
pub fn prune(
    store: &Path,
    older_than: Option<std::time::Duration>,
    max_bytes: Option<u64>,
) -> std::io::Result<Pruned> {
    use std::os::fd::AsRawFd;
    let mut report = Pruned::default();
    let all = folders(store)?;
    let mut total: u64 = all.iter().map(|f| f.bytes).sum();
    let now = std::time::SystemTime::now();
    for f in all {
        let old = older_than.is_some_and(|age| {
            now.duration_since(f.last_used)
                .is_ok_and(|since| since > age)
        });
        let over = max_bytes.is_some_and(|m| total > m);
        if !(old || over || f.incomplete) {
            continue;
        }
        let lock = std::fs::File::open(f.path.join(".complete")).ok();
        let free = lock.as_ref().is_none_or(|l| {
            // SAFETY: flock on a descriptor we own.
            unsafe { libc::flock(l.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
        });
        if !free {
            report.kept_in_use += 1;
            continue;
        }
        let aside = unique_sibling(&f.path);
        if std::fs::rename(&f.path, &aside).is_ok() {
            drop(lock);
            let _ = std::fs::remove_dir_all(&aside);
            total -= f.bytes;
            report.removed.push(f);
        }
    }
    // Temporaries: with the unpack lock no process is unpacking, and any unpacking left is
    // a killed one's (an index entry is written in microseconds: a minute is plenty);
    // without it (a process is unpacking) only those a day old.
    let stale_after = match try_unpack_lock(store) {
        Some(_lock) => std::time::Duration::from_secs(60),
        None => STALE_AFTER,
    };
    report.temporaries = sweep_older_than(store, stale_after);
    // Index entries whose folder is gone.
    if let Ok(entries) = std::fs::read_dir(store.join(INDEX_DIR)) {
        for e in entries.flatten() {
            let keep = std::fs::read_to_string(e.path())
                .ok()
                .and_then(|t| IndexEntry::parse(&t))
                .is_some_and(|entry| store.join(&entry.sha256[..32]).is_dir());
            let name = e.file_name();
            if !keep && !name.to_string_lossy().starts_with('.') {
                let _ = std::fs::remove_file(e.path());
                report.index_entries += 1;
            }
        }
    }
    report.bytes_left = total;
    Ok(report)
}

/// A scratch folder in the temporary directory, removed when dropped (the crate's tests
/// have no dependencies of their own).
#[cfg(test)]
pub(crate) struct TestDir(PathBuf);

#[cfg(test)]
impl TestDir {
    pub(crate) fn new() -> TestDir {
        let dir = std::env::temp_dir().join(unique_name("tb-fmi-test"));
        std::fs::create_dir_all(&dir).unwrap();
        TestDir(dir)
    }
    pub(crate) fn path(&self) -> &Path {
        &self.0
    }
}

#[cfg(test)]
impl Drop for TestDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// `<prefix>-<pid>-<counter>-<clock>`: a name no other thread or process uses (the clock
/// for processes in other PID namespaces, which may share the id).
pub(crate) fn unique_name(prefix: &str) -> String {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_nanos())
        .unwrap_or(0);
    format!(
        "{prefix}-{}-{}-{nanos:x}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

/// A sibling of `path` that no other thread or process uses.
pub(crate) fn unique_sibling(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or("x".into(), |n| n.to_string_lossy().into_owned());
    path.with_file_name(unique_name(&format!(".{name}.tmp")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_store_is_found_in_the_documented_order() {
        let env = |pairs: &'static [(&'static str, &'static str)]| {
            move |k: &str| {
                pairs
                    .iter()
                    .find(|(n, _)| *n == k)
                    .map(|(_, v)| OsString::from(*v))
            }
        };
        assert_eq!(
            store_dir_from(env(&[
                ("TWINBENCH_CACHE", "/s"),
                ("XDG_CACHE_HOME", "/x"),
                ("HOME", "/h")
            ])),
            Some(PathBuf::from("/s"))
        );
        assert_eq!(
            store_dir_from(env(&[("XDG_CACHE_HOME", "/x"), ("HOME", "/h")])),
            Some(PathBuf::from("/x/twinbench/unpacked"))
        );
        // Empty is unset; a relative XDG_CACHE_HOME is invalid.
        assert_eq!(
            store_dir_from(env(&[
                ("TWINBENCH_CACHE", ""),
                ("XDG_CACHE_HOME", "rel"),
                ("HOME", "/h")
            ])),
            Some(PathBuf::from("/h/.cache/twinbench/unpacked"))
        );
        assert_eq!(store_dir_from(env(&[("HOME", "")])), None);
        // A relative TWINBENCH_CACHE is taken from the working folder.
        let rel = store_dir_from(env(&[("TWINBENCH_CACHE", "target/s")])).unwrap();
        assert!(rel.is_absolute() && rel.ends_with("target/s"), "{rel:?}");
    }

    #[test]
    fn a_store_other_users_can_write_into_is_repaired_and_a_file_refused() {
        use std::os::unix::fs::PermissionsExt;
        let dir = TestDir::new();
        let store = dir.path().join("a/store");
        prepare(&store).unwrap();
        let mode = std::fs::metadata(&store).unwrap().permissions().mode();
        assert_eq!(mode & 0o777, 0o700);
        // Made writable for everyone (M1's chmod): repaired in place, not replaced, to the
        // mode it was created with (P8: it became 755, and others read every FMU in it).
        std::fs::set_permissions(&store, std::fs::Permissions::from_mode(0o777)).unwrap();
        prepare(&store).unwrap();
        let mode = std::fs::metadata(&store).unwrap().permissions().mode();
        assert_eq!(mode & 0o7777, 0o700);
        let file = dir.path().join("file");
        std::fs::write(&file, b"").unwrap();
        assert!(matches!(prepare(&file), Err(StoreError::NotAFolder)));
    }

    #[test]
    fn index_entries_round_trip_and_damaged_ones_are_none() {
        let h = |c: char| c.to_string().repeat(64);
        let e = IndexEntry {
            key: h('a'),
            sha256: h('b'),
            entries: 7,
            directory: h('c'),
        };
        let text = e.to_text();
        assert_eq!(IndexEntry::parse(&text), Some(e.clone()));
        for bad in [
            text.replace("sha256 b", "sha256 ../"),
            text.replace('b', "B"),
            text.replace("entries 7", "entries x"),
            text.replace(INDEX_FORMAT, "twinbench-unpack-index 0"),
            format!("{text}extra\n"),
            text[..text.len() - 1].to_string(),
            text[..text.len() / 2].to_string(),
            String::new(),
        ] {
            assert_eq!(IndexEntry::parse(&bad), None, "{bad:?}");
        }
        // Written and read back; another key in the same file is no entry.
        let dir = TestDir::new();
        write_entry(dir.path(), &e).unwrap();
        assert_eq!(read_entry(dir.path(), &e.key), Some(e.clone()));
        let other = format!("{}{}", &e.key[..32], "d".repeat(32));
        assert_eq!(read_entry(dir.path(), &other), None);
        // Nothing but the entry: the temporary was renamed.
        let names: Vec<_> = std::fs::read_dir(dir.path().join(INDEX_DIR))
            .unwrap()
            .flatten()
            .map(|e| e.file_name())
            .collect();
        assert_eq!(names, vec![OsString::from(&e.key[..32])]);
    }

    #[test]
    fn old_temporaries_are_swept_and_everything_else_kept() {
        let dir = TestDir::new();
        let s = dir.path();
        let old_dir = s.join(".abc.tmp-1-2-3");
        let new_dir = s.join(".abd.tmp-1-2-4");
        let old_entry = s.join(INDEX_DIR).join(".k.tmp-1-2-3");
        let fmu = s.join("0123456789abcdef0123456789abcdef");
        for d in [&old_dir, &new_dir, &fmu, &s.join(INDEX_DIR)] {
            std::fs::create_dir_all(d).unwrap();
        }
        std::fs::write(&old_entry, b"x").unwrap();
        let two_days_ago = std::time::SystemTime::now() - 2 * STALE_AFTER;
        for p in [&old_dir, &old_entry, &fmu] {
            std::fs::File::open(p)
                .unwrap()
                .set_modified(two_days_ago)
                .unwrap();
        }
        sweep_temporaries(s);
        assert!(!old_dir.exists() && !old_entry.exists());
        assert!(new_dir.exists() && fmu.exists());
    }
}

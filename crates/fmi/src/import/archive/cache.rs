//! The unpack cache: the store of unpacked FMUs, its locks and counters, and the loads
//! through it.

use super::*;
use crate::import::manifest::{self};
use crate::import::store::{self, CdEntry, IndexEntry};
use crate::import::store::{unique_name, unique_sibling};
use crate::FmuError;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::fs::{File, Metadata};
use std::io::{Read, Seek};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

/// The unpack cache. Unpacked FMUs live in a *store*, a folder per archive content hash:
/// the machine-wide one ([`default_store_dir`]) shared by every process, or one a caller
/// names. The store's stat index lets a load of an unchanged archive file skip reading,
/// hashing and inflating it (see `docs/robustness.md`, "The store of unpacked FMUs").
/// The cache's own folder (`root`) holds what lives only as long as the cache (SSP
/// packages); a temporary cache removes it when dropped, never the store.
///
/// Safe to share between threads and processes: one thread of a process unpacks a given
/// content while the others wait for it (a lock per content hash), and every unpacking
/// goes into a folder of its own that is renamed into place when complete.
pub struct FmuCache {
    root: PathBuf,
    keep: bool,
    /// Where FMUs are unpacked and indexed; `None`: into `root`, without an index.
    store: Option<PathBuf>,
    loaded: Mutex<HashMap<String, Arc<LoadedFmu>>>,
    /// One lock per content hash being loaded.
    loading: Mutex<HashMap<String, Arc<Mutex<()>>>>,
    limits: Limits,
    /// Whether an FMU must carry a binary for this platform (see
    /// [`FmuCache::description_only`]).
    binary_required: bool,
    /// Whether every unpacked file is verified on load (see [`FmuCache::verifying_all`]).
    verify_all: bool,
    counters: Counters,
    /// A temporary cache's lock file (`<root>.lock`, flocked while the cache lives).
    _owner: Option<OwnerLock>,
}

#[derive(Default)]
pub(crate) struct Counters {
    index_hits: AtomicUsize,
    archives_read: AtomicUsize,
    extractions: AtomicUsize,
}

/// What a cache has done so far (for tests and diagnostics).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CacheStats {
    /// Loads served by the stat index: only the archive's central directory was read.
    pub index_hits: usize,
    /// Archives read and hashed whole.
    pub archives_read: usize,
    /// Archives unpacked (the others were found unpacked already).
    pub extractions: usize,
}

/// The lock file beside a temporary cache folder: while it is locked the owner lives.
pub(crate) struct OwnerLock {
    path: PathBuf,
    _file: std::fs::File,
}

impl Drop for OwnerLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

pub(crate) fn lock_path(root: &Path) -> PathBuf {
    let mut name = root.as_os_str().to_owned();
    name.push(".lock");
    PathBuf::from(name)
}

pub(crate) fn try_flock(f: &std::fs::File) -> bool {
    use std::os::fd::AsRawFd;
    // SAFETY: flock on a descriptor we own.
    unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

/// Creates `<root>.lock` already locked: made and locked under a temporary name, then
/// renamed, so that no sweeper ever sees it unlocked.
pub(crate) fn owner_lock(root: &Path) -> Result<OwnerLock, FmuError> {
    let path = lock_path(root);
    let tmp = unique_sibling(&path);
    let file = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&tmp)
        .map_err(|e| arch(&tmp, format!("cannot create the cache's lock: {e}")))?;
    if !try_flock(&file) {
        let _ = std::fs::remove_file(&tmp);
        return Err(arch(&tmp, "cannot lock the cache's lock file"));
    }
    std::fs::rename(&tmp, &path)
        .map_err(|e| arch(&path, format!("cannot create the cache's lock: {e}")))?;
    Ok(OwnerLock { path, _file: file })
}

pub(crate) fn arch(path: &Path, message: impl Into<String>) -> FmuError {
    FmuError::Archive {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

/// Creates a cache's folder or a store: its parents as usual, itself private to the user
/// (mode 700 whatever the umask).
pub(crate) fn create_folder(dir: &Path) -> Result<(), FmuError> {
    let cannot = |e: std::io::Error| arch(dir, format!("cannot create cache folder: {e}"));
    if let Some(parent) = dir.parent() {
        std::fs::create_dir_all(parent).map_err(cannot)?;
    }
    manifest::make_dir(dir).map_err(cannot)
}

/// The machine-wide store, created if needed; `None` (FMUs unpacked per process, as without
/// a store) when there is no place for it or it cannot be trusted.
pub(crate) fn machine_store() -> Option<PathBuf> {
    let dir = default_store_dir()?;
    match store::prepare(&dir) {
        Ok(()) => Some(dir),
        Err(reason) => {
            // Not an error: the run goes on, only without sharing its unpacked FMUs.
            log::warn!(
                "{}: not used as the store of unpacked FMUs: {reason}; unpacking into a temporary folder",
                dir.display()
            );
            None
        }
    }
}

impl FmuCache {
    /// A fresh cache under the system temporary folder, removed on drop unless `keep`. Its
    /// FMUs come from the machine-wide store; a kept cache (`--keep-extracted`, for looking
    /// into the FMUs) unpacks them into its own folder instead, so that it shows them and
    /// nothing done there changes the store.
    pub fn temporary(keep: bool) -> Result<FmuCache, FmuError> {
        let store = if keep { None } else { machine_store() };
        Self::temporary_root(keep, store)
    }

    /// A temporary cache (removed on drop) whose FMUs come from the store `store` (created
    /// if needed, kept).
    pub fn temporary_with_store(store: &Path) -> Result<FmuCache, FmuError> {
        create_folder(store)?;
        Self::temporary_root(false, Some(store.to_path_buf()))
    }

    fn temporary_root(keep: bool, store: Option<PathBuf>) -> Result<FmuCache, FmuError> {
        remove_stale_caches();
        let root = std::env::temp_dir().join(unique_name("twinbench-fmu"));
        // The owner's lock, taken before anything is visible under the final names: held
        // for the cache's life, released by the kernel when the process ends however it ends.
        let lock = owner_lock(&root)?;
        create_folder(&root)?;
        Ok(Self::new(root, keep, store, Some(lock)))
    }

    /// A cache in `dir` that is kept (reused across runs): `dir` is its folder and its store.
    pub fn persistent(dir: &Path) -> Result<FmuCache, FmuError> {
        Self::with_store(dir, dir)
    }

    /// A kept cache in `root` whose FMUs come from the store `store` (both created if needed).
    pub fn with_store(root: &Path, store: &Path) -> Result<FmuCache, FmuError> {
        create_folder(root)?;
        create_folder(store)?;
        Ok(Self::new(
            root.to_path_buf(),
            true,
            Some(store.to_path_buf()),
            None,
        ))
    }

    /// A cache of nothing yet, with the default limits and checks.
    fn new(
        root: PathBuf,
        keep: bool,
        store: Option<PathBuf>,
        owner: Option<OwnerLock>,
    ) -> FmuCache {
        FmuCache {
            root,
            keep,
            store,
            _owner: owner,
            loaded: Mutex::new(HashMap::new()),
            loading: Mutex::new(HashMap::new()),
            limits: Limits::default(),
            binary_required: true,
            verify_all: false,
            counters: Counters::default(),
        }
    }

    /// The cache's own folder (SSP packages; FMUs too when it has no store).
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The store the FMUs are unpacked into, if any.
    pub fn store(&self) -> Option<&Path> {
        self.store.as_deref()
    }

    /// Where unpacked FMUs go.
    fn fmu_folder(&self) -> &Path {
        self.store.as_deref().unwrap_or(&self.root)
    }

    pub fn stats(&self) -> CacheStats {
        CacheStats {
            index_hits: self.counters.index_hits.load(Ordering::Relaxed),
            archives_read: self.counters.archives_read.load(Ordering::Relaxed),
            extractions: self.counters.extractions.load(Ordering::Relaxed),
        }
    }

    /// Other zip-bomb limits (tests use small ones).
    pub fn with_limits(mut self, limits: Limits) -> Self {
        self.limits = limits;
        self
    }

    /// A cache that also accepts FMUs without a binary for this platform, for hosts that run
    /// their models natively and read only the description (`tb-cosim`'s tests). Every other
    /// check stays; an instance that needs such an FMU's library fails when loading it.
    pub fn description_only(mut self) -> Self {
        self.binary_required = false;
        self
    }

    /// A cache that verifies every unpacked file of an FMU when it loads it, resources
    /// included (repairing a folder that differs), not only the description and, before
    /// it is loaded, the library: for a remote worker, whose input digest says which
    /// unpacked content it runs on.
    pub fn verifying_all(mut self) -> Self {
        self.verify_all = true;
        self
    }

    /// Check, unpack (once per content) and load an FMU.
    pub fn load(&self, fmu: &Path) -> Result<Arc<LoadedFmu>, FmuError> {
        let (file, meta) = open_regular(fmu, &self.limits, "an FMU is a zip archive")?;
        let indexed = match &self.store {
            Some(store) => self.load_indexed(fmu, &file, &meta, store),
            None => None,
        };
        let loaded = match indexed {
            Some(l) => {
                self.counters.index_hits.fetch_add(1, Ordering::Relaxed);
                l
            }
            None => self.load_full(fmu, &file, &meta)?,
        };
        if self.verify_all {
            loaded.verify_all()?;
        }
        Ok(loaded)
    }

    /// A load through the stat index: the file's `stat` finds its entry, the archive's
    /// central directory (read, nothing inflated) must match the entry's fingerprint and
    /// pass the entry checks again, the unpacked folder's manifest must name this archive
    /// and every file of its central directory (size and CRC-32), and the description is
    /// read from the unpacked folder, verified against the manifest and checked again.
    /// `None` on any doubt: the caller takes the full path (which repairs the folder).
    fn load_indexed(
        &self,
        fmu: &Path,
        file: &File,
        meta: &Metadata,
        store: &Path,
    ) -> Option<Arc<LoadedFmu>> {
        let canonical = std::fs::canonicalize(fmu).ok()?;
        let key = store::index_key(&canonical, meta);
        let entry = store::read_entry(store, &key)?;
        let rel = &entry.sha256[..32];
        let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file)).ok()?;
        let entries = check_entries_of(fmu, &mut zip, &self.limits).ok()?;
        if entries.len() != entry.entries || store::fingerprint(&entries) != entry.directory {
            return None;
        }
        let key_lock = lock(&self.loading)
            .entry(entry.sha256.clone())
            .or_default()
            .clone();
        let _loading = lock(&key_lock);
        if let Some(l) = lock(&self.loaded).get(&entry.sha256) {
            return Some(l.clone());
        }
        let in_use = in_use(&store.join(rel))?;
        let (manifest, xml) = check_folder(store, rel, &entry.sha256, &entries).ok()?;
        let xml = String::from_utf8(xml).ok()?;
        let names: Vec<String> = entries.into_iter().map(|e| e.name).collect();
        let (md, _id) = check_description(fmu, &xml, &names, self.binary_required).ok()?;
        let loaded = Arc::new(LoadedFmu {
            source: fmu.to_path_buf(),
            dir: store.join(rel),
            sha256: entry.sha256.clone(),
            description: md,
            base: store.to_path_buf(),
            shared: true,
            manifest,
            trusted: false,
            limits: self.limits,
            library_checked: Mutex::new(Vec::new()),
            _in_use: Some(in_use),
            library: Mutex::new(None),
            library3: Mutex::new(None),
            library_me: Mutex::new(None),
            binary_required: self.binary_required,
        });
        lock(&self.loaded).insert(entry.sha256, loaded.clone());
        Some(loaded)
    }

    /// The full path: read and hash the archive, check it whole, unpack it unless its
    /// content is unpacked already and its folder passes [`check_folder`] (a folder that
    /// does not is reported and unpacked again), and (re)write its index entry.
    fn load_full(
        &self,
        fmu: &Path,
        file: &File,
        meta: &Metadata,
    ) -> Result<Arc<LoadedFmu>, FmuError> {
        let bytes = read_regular(fmu, file, &self.limits)?;
        self.counters.archives_read.fetch_add(1, Ordering::Relaxed);
        let sha = format!("{:x}", Sha256::digest(&bytes));
        if let Some(l) = lock(&self.loaded).get(&sha) {
            return Ok(l.clone());
        }
        // One loader per content: the others wait here and then find it loaded.
        let key_lock = lock(&self.loading).entry(sha.clone()).or_default().clone();
        let _loading = lock(&key_lock);
        if let Some(l) = lock(&self.loaded).get(&sha) {
            return Ok(l.clone());
        }
        let (md, id, entries) =
            check_archive_entries(fmu, &bytes, &self.limits, self.binary_required)?;
        let base = self.fmu_folder();
        let rel = &sha[..32];
        let dir = base.join(rel);
        let mut held = in_use(&dir);
        let found = held
            .as_ref()
            .map(|_| check_folder(base, rel, &sha, &entries));
        let (manifest, trusted) = match found {
            Some(Ok((m, _))) => (m, false),
            found => {
                if let Some(Err(reason)) = &found {
                    if !dir.join(manifest::MANIFEST).exists() {
                        // A folder without a manifest was unpacked by a twinbench before
                        // manifests: unpacked again, nothing to report.
                        log::info!("{}: no manifest; unpacking again", dir.display());
                    } else {
                        log::warn!(
                        "{}: the unpacked FMU {} differs from what was unpacked ({reason}); unpacking it again",
                        dir.display(),
                        fmu.display()
                    );
                    }
                }
                drop(held);
                if let Some(store) = &self.store {
                    store::sweep_temporaries(store);
                }
                let exec = library_entry(&md.fmi_version, &id);
                let (m, ours) = replace_folder(
                    fmu,
                    &bytes,
                    &sha,
                    base,
                    rel,
                    &self.limits,
                    Some(&exec),
                    self.store.is_some(),
                    None,
                )?;
                if ours {
                    self.counters.extractions.fetch_add(1, Ordering::Relaxed);
                }
                held = in_use(&dir);
                (m, ours)
            }
        };
        if let Some(store) = &self.store {
            self.remember(store, fmu, file, meta, &sha, &entries);
        }
        let loaded = Arc::new(LoadedFmu {
            source: fmu.to_path_buf(),
            dir,
            sha256: sha.clone(),
            description: md,
            base: base.to_path_buf(),
            shared: self.store.is_some(),
            manifest,
            trusted,
            limits: self.limits,
            library_checked: Mutex::new(Vec::new()),
            _in_use: held,
            library: Mutex::new(None),
            library3: Mutex::new(None),
            library_me: Mutex::new(None),
            binary_required: self.binary_required,
        });
        lock(&self.loaded).insert(sha, loaded.clone());
        Ok(loaded)
    }

    /// Writes the index entry of an archive checked and unpacked in full. Skipped when the
    /// file changed while it was read (its `stat` then names other bytes) and for an FMU in
    /// this temporary cache's own folder (an SSP's: gone with the cache). A failure only
    /// costs the next load its shortcut.
    fn remember(
        &self,
        store: &Path,
        fmu: &Path,
        file: &File,
        before: &Metadata,
        sha: &str,
        entries: &[CdEntry],
    ) {
        let Ok(after) = file.metadata() else {
            return;
        };
        if !store::same_stat(before, &after) {
            return;
        }
        let Ok(canonical) = std::fs::canonicalize(fmu) else {
            return;
        };
        if !self.keep
            && std::fs::canonicalize(&self.root).is_ok_and(|root| canonical.starts_with(root))
        {
            return;
        }
        let entry = IndexEntry {
            key: store::index_key(&canonical, before),
            sha256: sha.to_string(),
            entries: entries.len(),
            directory: store::fingerprint(entries),
        };
        if let Err(e) = store::write_entry(store, &entry) {
            log::debug!(
                "{}: cannot write the unpack index entry of {}: {e}",
                store.display(),
                fmu.display()
            );
        }
    }
}

/// Opens `path` for reading if it is a regular file within the size limit. A FIFO would
/// hang the read, `/dev/zero` would fill the memory: the name is checked before anything is
/// opened, and the open file again (the name may point elsewhere by then; `O_NONBLOCK` so
/// that a FIFO swapped in cannot block the open).
pub(crate) fn open_regular(
    path: &Path,
    limits: &Limits,
    what: &str,
) -> Result<(File, Metadata), FmuError> {
    use std::os::unix::fs::OpenOptionsExt;
    let check = |meta: &Metadata| {
        if !meta.is_file() {
            return Err(arch(path, format!("not a regular file ({what})")));
        }
        if meta.len() > limits.max_total_bytes {
            return Err(arch(
                path,
                format!(
                    "{} bytes, more than the limit of {} bytes",
                    meta.len(),
                    limits.max_total_bytes
                ),
            ));
        }
        Ok(())
    };
    let meta = std::fs::metadata(path).map_err(|e| arch(path, format!("cannot read: {e}")))?;
    check(&meta)?;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(|e| arch(path, format!("cannot read: {e}")))?;
    let meta = file
        .metadata()
        .map_err(|e| arch(path, format!("cannot read: {e}")))?;
    check(&meta)?;
    Ok((file, meta))
}

/// The whole content of a file from [`open_regular`], bounded by the size limit (it may
/// have grown since its `stat`).
pub(crate) fn read_regular(
    path: &Path,
    mut file: &File,
    limits: &Limits,
) -> Result<Vec<u8>, FmuError> {
    let cannot = |e: std::io::Error| arch(path, format!("cannot read: {e}"));
    file.rewind().map_err(cannot)?;
    let mut bytes = Vec::new();
    file.take(limits.max_total_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(cannot)?;
    if bytes.len() as u64 > limits.max_total_bytes {
        return Err(arch(
            path,
            format!("more than the limit of {} bytes", limits.max_total_bytes),
        ));
    }
    Ok(bytes)
}

impl FmuCache {
    /// Check and unpack any zip package (an SSP) into this cache, once per content, with the
    /// FMU rules: a regular file within the size limit, [`check_entries`], the real
    /// decompressed size bounded. Returns the folder (`<root>/pkg-<hash>`), removed with the
    /// cache.
    pub fn unpack_package(&self, package: &Path) -> Result<PathBuf, FmuError> {
        let (file, _) = open_regular(package, &self.limits, "a package is a zip archive")?;
        let bytes = read_regular(package, &file, &self.limits)?;
        let sha = format!("{:x}", Sha256::digest(&bytes));
        let key_lock = lock(&self.loading)
            .entry(format!("pkg-{sha}"))
            .or_default()
            .clone();
        let _loading = lock(&key_lock);
        check_entries(package, &bytes, &self.limits)?;
        let dir = self.root.join(format!("pkg-{}", &sha[..32]));
        if !dir.join(".complete").exists() {
            extract(package, &bytes, &sha, &dir, &self.limits, None)?;
        }
        Ok(dir)
    }
}

/// A library error under the FMU's name and the library's entry in the archive (the
/// unpacked copy is in a store or temporary folder the user never named). Also used by the isolation
/// worker.
pub fn library_error(fmu: &Path, fmi_version: &str, id: &str, e: FmuError) -> FmuError {
    let entry = library_entry(fmi_version, id);
    let version = if fmi_version.starts_with("3.") {
        "3.0"
    } else {
        "2.0"
    };
    match e {
        FmuError::Load { path, message } => FmuError::Load {
            path: fmu.to_path_buf(),
            message: load_problem(&entry, &path, &message),
        },
        FmuError::MissingSymbol { symbol, .. } => FmuError::Archive {
            path: fmu.to_path_buf(),
            message: format!(
                "{entry} does not export the required FMI {version}{} function {symbol}",
                if crate::import::library::ME_FUNCTIONS.contains(&symbol) {
                    " Model Exchange"
                } else {
                    ""
                }
            ),
        },
        other => other,
    }
}

/// The loader's message for the library `entry` (loaded from `path`) in the archive's terms:
/// dlopen's text starts with the path it was given (a store folder, meaningless to the
/// user), then names the file that failed, which is a dependency of the library when the
/// library itself is present (`libSimulationRuntimeC.so: cannot open shared object file`).
pub(crate) fn load_problem(entry: &str, path: &Path, message: &str) -> String {
    let rest = message
        .strip_prefix(&format!("{}: ", path.display()))
        .unwrap_or(message);
    let own = Path::new(entry).file_name().and_then(|n| n.to_str());
    match rest.split_once(": ") {
        Some((dep, why)) if is_library_name(dep) && Some(dep) != own => {
            format!("{entry} needs the library {dep}, which cannot be loaded: {why} (the FMU does not bring it: install it or put its folder on LD_LIBRARY_PATH)")
        }
        _ => format!("{entry}: {rest}"),
    }
}

/// `libfoo.so`, `libfoo.so.3`, `/usr/lib/libfoo.so.1.2`: a shared library's name.
pub(crate) fn is_library_name(s: &str) -> bool {
    !s.contains(' ') && (s.ends_with(".so") || s.contains(".so."))
}

/// A poisoned lock only means another thread panicked while holding it; the maps stay
/// consistent (every insert is a single call), so go on.
pub(crate) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Remove temporary caches provably abandoned: a `twinbench-fmu-*.lock` that can be locked
/// has no owner any more (its process ended, killed or crashed; the kernel released the
/// lock). A process id says nothing here: another PID namespace (a container sharing /tmp)
/// may run the same number.
pub(crate) fn remove_stale_caches() {
    let Ok(entries) = std::fs::read_dir(std::env::temp_dir()) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(stem) = name
            .to_str()
            .filter(|n| n.starts_with("twinbench-fmu-"))
            .and_then(|n| n.strip_suffix(".lock"))
        else {
            continue;
        };
        let Ok(file) = std::fs::OpenOptions::new().write(true).open(e.path()) else {
            continue;
        };
        if try_flock(&file) {
            let _ = std::fs::remove_dir_all(std::env::temp_dir().join(stem));
            let _ = std::fs::remove_file(e.path());
        }
    }
}

impl Drop for FmuCache {
    fn drop(&mut self) {
        if !self.keep {
            // Libraries stay mapped until the process ends; removing their files is fine on Linux.
            let _ = std::fs::remove_dir_all(&self.root);
        }
        // Then the owner's lock goes (field drop): a kept cache's lock file goes too, and
        // with it nothing marks the folder for sweeping.
    }
}

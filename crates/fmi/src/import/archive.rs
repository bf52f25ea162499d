//! FMU archives: checked as untrusted input, unzipped once into a content-addressed store
//! shared by every twinbench process, their shared library loaded once and shared by every
//! instance.

use super::description::{self, Interface, ModelDescription};
use super::library::Library;
use super::library3::Library3;
use super::store::{self, CdEntry, IndexEntry};
use crate::FmuError;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::fs::{File, Metadata};
use std::io::{Read, Seek};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

pub use super::store::default_store_dir;

/// Limits against zip bombs.
pub const MAX_ENTRIES: usize = 10_000;
/// The largest modelDescription.xml read (64 MiB).
pub const MAX_DESCRIPTION_BYTES: u64 = 64 << 20;
pub const MAX_TOTAL_BYTES: u64 = 2 << 30;

/// The zip-bomb limits of a cache (the defaults are [`MAX_ENTRIES`] and [`MAX_TOTAL_BYTES`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limits {
    pub max_entries: usize,
    /// Total uncompressed size, declared and actually written.
    pub max_total_bytes: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            max_entries: MAX_ENTRIES,
            max_total_bytes: MAX_TOTAL_BYTES,
        }
    }
}

/// An unpacked, checked FMU. Its library is loaded into this process only when an
/// in-process instance first needs it ([`LoadedFmu::library`]): an FMU that runs isolated
/// never executes code in the host, not even `fmi2GetVersion`.
pub struct LoadedFmu {
    pub source: PathBuf,
    pub dir: PathBuf,
    pub sha256: String,
    pub description: ModelDescription,
    library: Mutex<Option<Arc<Library>>>,
    library3: Mutex<Option<Arc<Library3>>>,
    /// The FMI 2.0 library loaded for Model Exchange (its own `modelIdentifier`).
    library_me: Mutex<Option<Arc<Library>>>,
}

impl LoadedFmu {
    /// The unpacked library of the default interface (`binaries/linux64/<modelIdentifier>.so`,
    /// FMI 3.0: `binaries/x86_64-linux/`).
    pub fn library_path(&self) -> PathBuf {
        self.dir.join(self.library_entry())
    }

    /// The library's entry in the archive, for messages.
    pub fn library_entry(&self) -> String {
        library_entry(&self.description.fmi_version, self.model_identifier())
    }

    /// The interface an instance uses unless its system file chooses one (Co-Simulation
    /// when the FMU has it).
    pub fn default_interface(&self) -> Interface {
        self.description
            .default_interface()
            .expect("checked at load: Co-Simulation or Model Exchange")
    }

    /// The library entry of `interface` (None: the FMU does not declare it).
    pub fn library_entry_of(&self, interface: Interface) -> Option<String> {
        let id = self.description.model_identifier(interface)?;
        Some(library_entry(&self.description.fmi_version, id))
    }

    /// Whether an instance can run through `interface`: the FMU declares it, and has its
    /// library for this platform. Err: why not, in words for a message.
    pub fn check_interface(&self, interface: Interface) -> Result<(), String> {
        let Some(entry) = self.library_entry_of(interface) else {
            let has: Vec<&str> = Interface::ALL
                .into_iter()
                .filter(|i| self.description.supports(*i))
                .map(Interface::name)
                .collect();
            return Err(format!(
                "the FMU has no <{}> element (it supports {} only)",
                interface.element(),
                has.join(" and ")
            ));
        };
        if interface == Interface::ModelExchange && self.is_fmi3() {
            return Err(
                "twinbench runs FMI 3.0 FMUs through Co-Simulation only (FMI 2.0 Model Exchange FMUs are integrated with CVODE)"
                    .into(),
            );
        }
        if !self.dir.join(&entry).is_file() {
            return Err(format!(
                "no {entry}, the {} library (the FMU has no binary of it for this platform)",
                interface.element()
            ));
        }
        Ok(())
    }

    /// The FMI 2.0 library loaded for Model Exchange ([`Library::load_model_exchange`]),
    /// on the first call; errors name the .fmu and the library's entry.
    pub fn library_me(&self) -> Result<Arc<Library>, FmuError> {
        let id = self
            .description
            .model_identifier(Interface::ModelExchange)
            .ok_or_else(|| FmuError::Description {
                path: self.source.clone(),
                message: "the FMU has no <ModelExchange> element".into(),
            })?;
        let mut slot = lock(&self.library_me);
        if let Some(l) = &*slot {
            return Ok(l.clone());
        }
        let entry = library_entry(&self.description.fmi_version, id);
        let library = Library::load_model_exchange(&self.dir.join(entry))
            .map(Arc::new)
            .map_err(|e| library_error(&self.source, &self.description.fmi_version, id, e))?;
        *slot = Some(library.clone());
        Ok(library)
    }

    /// An FMI 3.0 FMU.
    pub fn is_fmi3(&self) -> bool {
        self.description.fmi_version.starts_with("3.")
    }

    /// The FMI 3.0 library, loaded into this process on the first call.
    pub fn library3(&self) -> Result<Arc<Library3>, FmuError> {
        self.load_once(&self.library3, Library3::load)
    }

    /// The library, loaded into this process on the first call (and checked: every
    /// required function, `fmi2GetVersion` = "2.0"). Errors name the .fmu and its entry.
    pub fn library(&self) -> Result<Arc<Library>, FmuError> {
        if self.is_fmi3() {
            return Err(FmuError::Load {
                path: self.source.clone(),
                message: "an FMI 3.0 FMU has no FMI 2.0 library".into(),
            });
        }
        self.load_once(&self.library, Library::load)
    }

    /// The library in `slot`, loaded by `load` on the first call; its errors name the .fmu
    /// and the library's entry (the unpacked copy is in a folder the user never saw).
    fn load_once<L>(
        &self,
        slot: &Mutex<Option<Arc<L>>>,
        load: impl FnOnce(&Path) -> Result<L, FmuError>,
    ) -> Result<Arc<L>, FmuError> {
        let mut slot = lock(slot);
        if let Some(l) = &*slot {
            return Ok(l.clone());
        }
        let library = load(&self.library_path()).map(Arc::new).map_err(|e| {
            library_error(
                &self.source,
                &self.description.fmi_version,
                self.model_identifier(),
                e,
            )
        })?;
        *slot = Some(library.clone());
        Ok(library)
    }

    pub fn resource_dir(&self) -> PathBuf {
        self.dir.join("resources")
    }
    /// The `modelIdentifier` of the default interface.
    pub fn model_identifier(&self) -> &str {
        self.description
            .model_identifier(self.default_interface())
            .expect("checked at load")
    }
}

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
    counters: Counters,
    /// A temporary cache's lock file (`<root>.lock`, flocked while the cache lives).
    _owner: Option<OwnerLock>,
}

#[derive(Default)]
struct Counters {
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
struct OwnerLock {
    path: PathBuf,
    _file: std::fs::File,
}

impl Drop for OwnerLock {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

fn lock_path(root: &Path) -> PathBuf {
    let mut name = root.as_os_str().to_owned();
    name.push(".lock");
    PathBuf::from(name)
}

fn try_flock(f: &std::fs::File) -> bool {
    use std::os::fd::AsRawFd;
    // SAFETY: flock on a descriptor we own.
    unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

/// Creates `<root>.lock` already locked: made and locked under a temporary name, then
/// renamed, so that no sweeper ever sees it unlocked.
fn owner_lock(root: &Path) -> Result<OwnerLock, FmuError> {
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

fn arch(path: &Path, message: impl Into<String>) -> FmuError {
    FmuError::Archive {
        path: path.to_path_buf(),
        message: message.into(),
    }
}

fn create_folder(dir: &Path) -> Result<(), FmuError> {
    std::fs::create_dir_all(dir).map_err(|e| arch(dir, format!("cannot create cache folder: {e}")))
}

/// The machine-wide store, created if needed; `None` (FMUs unpacked per process, as without
/// a store) when there is no place for it or it cannot be trusted.
fn machine_store() -> Option<PathBuf> {
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
        Ok(FmuCache {
            root,
            keep,
            store,
            _owner: Some(lock),
            loaded: Mutex::new(HashMap::new()),
            loading: Mutex::new(HashMap::new()),
            limits: Limits::default(),
            binary_required: true,
            counters: Counters::default(),
        })
    }

    /// A cache in `dir` that is kept (reused across runs): `dir` is its folder and its store.
    pub fn persistent(dir: &Path) -> Result<FmuCache, FmuError> {
        Self::with_store(dir, dir)
    }

    /// A kept cache in `root` whose FMUs come from the store `store` (both created if needed).
    pub fn with_store(root: &Path, store: &Path) -> Result<FmuCache, FmuError> {
        create_folder(root)?;
        create_folder(store)?;
        Ok(FmuCache {
            root: root.to_path_buf(),
            keep: true,
            store: Some(store.to_path_buf()),
            _owner: None,
            loaded: Mutex::new(HashMap::new()),
            loading: Mutex::new(HashMap::new()),
            limits: Limits::default(),
            binary_required: true,
            counters: Counters::default(),
        })
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

    /// Check, unpack (once per content) and load an FMU.
    pub fn load(&self, fmu: &Path) -> Result<Arc<LoadedFmu>, FmuError> {
        let (file, meta) = open_regular(fmu, &self.limits, "an FMU is a zip archive")?;
        if let Some(store) = &self.store {
            if let Some(l) = self.load_indexed(fmu, &file, &meta, store) {
                self.counters.index_hits.fetch_add(1, Ordering::Relaxed);
                return Ok(l);
            }
        }
        self.load_full(fmu, &file, &meta)
    }

    /// A load through the stat index: the file's `stat` finds its entry, the archive's
    /// central directory (read, nothing inflated) must match the entry's fingerprint and
    /// pass the entry checks again, and the description is read from the unpacked folder and
    /// checked again. `None` on any doubt: the caller takes the full path.
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
        let dir = store.join(&entry.sha256[..32]);
        if !dir.join(".complete").is_file() {
            return None;
        }
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
        let xml = read_unpacked_description(fmu, &dir).ok()?;
        let names: Vec<String> = entries.into_iter().map(|e| e.name).collect();
        let (md, _id) = check_description(fmu, &xml, &names, self.binary_required).ok()?;
        let loaded = Arc::new(LoadedFmu {
            source: fmu.to_path_buf(),
            dir,
            sha256: entry.sha256.clone(),
            description: md,
            library: Mutex::new(None),
            library3: Mutex::new(None),
            library_me: Mutex::new(None),
        });
        lock(&self.loaded).insert(entry.sha256, loaded.clone());
        Some(loaded)
    }

    /// The full path: read and hash the archive, check it whole, unpack it unless its
    /// content is unpacked already, and (re)write its index entry.
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
        let (md, _id, entries) =
            check_archive_entries(fmu, &bytes, &self.limits, self.binary_required)?;
        let dir = self.fmu_folder().join(&sha[..32]);
        if !dir.join(".complete").exists() {
            if let Some(store) = &self.store {
                store::sweep_temporaries(store);
            }
            extract(fmu, &bytes, &dir, &self.limits)?;
            self.counters.extractions.fetch_add(1, Ordering::Relaxed);
        }
        if let Some(store) = &self.store {
            self.remember(store, fmu, file, meta, &sha, &entries);
        }
        let loaded = Arc::new(LoadedFmu {
            source: fmu.to_path_buf(),
            dir,
            sha256: sha.clone(),
            description: md,
            library: Mutex::new(None),
            library3: Mutex::new(None),
            library_me: Mutex::new(None),
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
fn open_regular(path: &Path, limits: &Limits, what: &str) -> Result<(File, Metadata), FmuError> {
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
fn read_regular(path: &Path, mut file: &File, limits: &Limits) -> Result<Vec<u8>, FmuError> {
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

/// The modelDescription.xml of an unpacked FMU, read as from its archive (a regular file,
/// bounded, UTF-8); errors name the `.fmu`.
fn read_unpacked_description(fmu: &Path, dir: &Path) -> Result<String, FmuError> {
    use std::os::unix::fs::OpenOptionsExt;
    let path = dir.join("modelDescription.xml");
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK)
        .open(&path)
        .map_err(|e| {
            arch(
                fmu,
                format!("cannot read the unpacked modelDescription.xml: {e}"),
            )
        })?;
    if !f.metadata().is_ok_and(|m| m.is_file()) {
        return Err(arch(
            fmu,
            "the unpacked modelDescription.xml is not a regular file",
        ));
    }
    read_description(fmu, f)
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
            extract(package, &bytes, &dir, &self.limits)?;
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
        FmuError::Load { message, .. } => FmuError::Load {
            path: fmu.to_path_buf(),
            message: format!(
                "{entry}: {}",
                message
                    .rsplit_once(".so: ")
                    .map_or(message.as_str(), |(_, m)| m)
            ),
        },
        FmuError::MissingSymbol { symbol, .. } => FmuError::Archive {
            path: fmu.to_path_buf(),
            message: format!(
                "{entry} does not export the required FMI {version}{} function {symbol}",
                if super::library::ME_FUNCTIONS.contains(&symbol) {
                    " Model Exchange"
                } else {
                    ""
                }
            ),
        },
        other => other,
    }
}

/// A poisoned lock only means another thread panicked while holding it; the maps stay
/// consistent (every insert is a single call), so go on.
fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}

/// Remove temporary caches provably abandoned: a `twinbench-fmu-*.lock` that can be locked
/// has no owner any more (its process ended, killed or crashed; the kernel released the
/// lock). A process id says nothing here: another PID namespace (a container sharing /tmp)
/// may run the same number.
fn remove_stale_caches() {
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

/// An archive that passed [`check_entries`], and its entry names.
pub type CheckedArchive<'a> = (zip::ZipArchive<std::io::Cursor<&'a [u8]>>, Vec<String>);

/// The checks every archive twinbench unpacks passes before a byte is written (an FMU, an
/// SSP package): a valid zip, entry names inside the archive (no `..`, no absolute paths),
/// no symbolic links, the entry count and the declared uncompressed size within `limits`.
/// Returns the open archive and its entry names.
pub fn check_entries<'a>(
    fmu: &Path,
    bytes: &'a [u8],
    limits: &Limits,
) -> Result<CheckedArchive<'a>, FmuError> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| arch(fmu, format!("not a valid zip archive: {e}")))?;
    let entries = check_entries_of(fmu, &mut zip, limits)?;
    Ok((zip, entries.into_iter().map(|e| e.name).collect()))
}

/// [`check_entries`] on an open archive, in memory or a file (then only its central
/// directory and local headers are read). Returns the central directory's entries.
fn check_entries_of<R: Read + Seek>(
    fmu: &Path,
    zip: &mut zip::ZipArchive<R>,
    limits: &Limits,
) -> Result<Vec<CdEntry>, FmuError> {
    if zip.len() > limits.max_entries {
        return Err(arch(
            fmu,
            format!(
                "{} entries, more than the limit of {} (zip bomb?)",
                zip.len(),
                limits.max_entries
            ),
        ));
    }
    let mut total: u64 = 0;
    let mut entries = Vec::with_capacity(zip.len());
    for i in 0..zip.len() {
        let f = zip
            .by_index_raw(i)
            .map_err(|e| arch(fmu, format!("entry {i}: {e}")))?;
        let name = f.name().to_string();
        if f.enclosed_name().is_none()
            || name.starts_with('/')
            || name.split(['/', '\\']).any(|c| c == "..")
        {
            return Err(arch(
                fmu,
                format!("entry '{name}' escapes the archive (absolute path or '..')"),
            ));
        }
        if f.unix_mode().is_some_and(|m| m & 0o170000 == 0o120000) {
            return Err(arch(fmu, format!("entry '{name}' is a symbolic link")));
        }
        total = total.saturating_add(f.size());
        if total > limits.max_total_bytes {
            return Err(arch(
                fmu,
                format!(
                    "uncompressed size exceeds the limit of {} bytes (zip bomb?)",
                    limits.max_total_bytes
                ),
            ));
        }
        entries.push(CdEntry {
            compressed: f.compressed_size(),
            size: f.size(),
            crc32: f.crc32(),
            name,
        });
    }
    Ok(entries)
}

/// Everything checked before a byte is written: entry names (no `..`, no absolute paths),
/// no symbolic links, size and count limits, a UTF-8 FMI 2.0 Co-Simulation
/// modelDescription.xml, and the linux64 binary it names.
pub fn check_archive(fmu: &Path, bytes: &[u8]) -> Result<(ModelDescription, String), FmuError> {
    check_archive_with(fmu, bytes, &Limits::default())
}

/// [`check_archive`] with other limits.
pub fn check_archive_with(
    fmu: &Path,
    bytes: &[u8],
    limits: &Limits,
) -> Result<(ModelDescription, String), FmuError> {
    check_archive_entries(fmu, bytes, limits, true).map(|(md, id, _)| (md, id))
}

/// [`check_archive_with`], also returning the central directory's entries; the binary for
/// this platform only when `binary_required`.
fn check_archive_entries(
    fmu: &Path,
    bytes: &[u8],
    limits: &Limits,
    binary_required: bool,
) -> Result<(ModelDescription, String, Vec<CdEntry>), FmuError> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| arch(fmu, format!("not a valid zip archive: {e}")))?;
    let entries = check_entries_of(fmu, &mut zip, limits)?;
    let xml = {
        let f = zip
            .by_name("modelDescription.xml")
            .map_err(|_| arch(fmu, "no modelDescription.xml at the archive's root"))?;
        read_description(fmu, f)?
    };
    let names: Vec<String> = entries.iter().map(|e| e.name.clone()).collect();
    let (md, id) = check_description(fmu, &xml, &names, binary_required)?;
    Ok((md, id, entries))
}

/// A modelDescription.xml's text: at most [`MAX_DESCRIPTION_BYTES`] (an error past it,
/// not a cut), UTF-8.
fn read_description(fmu: &Path, r: impl Read) -> Result<String, FmuError> {
    let mut raw = Vec::new();
    r.take(MAX_DESCRIPTION_BYTES + 1)
        .read_to_end(&mut raw)
        .map_err(|e| arch(fmu, format!("cannot read modelDescription.xml: {e}")))?;
    if raw.len() as u64 > MAX_DESCRIPTION_BYTES {
        return Err(arch(
            fmu,
            format!(
                "modelDescription.xml is larger than {} MiB (the limit against a hostile archive)",
                MAX_DESCRIPTION_BYTES >> 20
            ),
        ));
    }
    String::from_utf8(raw).map_err(|e| {
        arch(
            fmu,
            format!(
                "modelDescription.xml is not UTF-8 (byte {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

/// The description's checks: FMI 2.0 or 3.0, Co-Simulation, nothing unsupported, a
/// `modelIdentifier` that is a C identifier, and (when `binary_required`) its library among
/// the archive's `names`. Returns the description and the model identifier.
fn check_description(
    fmu: &Path,
    xml: &str,
    names: &[String],
    binary_required: bool,
) -> Result<(ModelDescription, String), FmuError> {
    let md = description::parse(xml).map_err(|message| FmuError::Description {
        path: fmu.to_path_buf(),
        // An FMI 1.0 description may not even parse as 2.0: name the version then.
        message: match sniff_fmi_version(xml) {
            Some(v) if v != "2.0" && !v.starts_with("3.") => {
                format!("fmiVersion is \"{v}\"; twinbench runs FMI 2.0 and 3.0 FMUs")
            }
            _ => message,
        },
    })?;
    let fmi3 = md.fmi_version.starts_with("3.");
    if md.fmi_version != "2.0" && !fmi3 {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!(
                "fmiVersion is \"{}\"; twinbench runs FMI 2.0 and 3.0 FMUs",
                md.fmi_version
            ),
        });
    }
    // FMI 2.0: Co-Simulation, or Model Exchange (integrated by twinbench); FMI 3.0:
    // Co-Simulation.
    let interface = match (md.default_interface(), fmi3) {
        (Some(Interface::CoSimulation), _) => Interface::CoSimulation,
        (Some(Interface::ModelExchange), false) => Interface::ModelExchange,
        _ => {
            let kinds: Vec<&str> = [
                (md.model_exchange.is_some(), "Model Exchange"),
                (
                    md.unsupported.iter().any(|u| u.starts_with("Scheduled")),
                    "Scheduled Execution",
                ),
            ]
            .iter()
            .filter(|(has, _)| *has)
            .map(|(_, k)| *k)
            .collect();
            return Err(FmuError::Description {
                path: fmu.to_path_buf(),
                message: match (kinds.is_empty(), fmi3) {
                    (true, false) => "neither a <CoSimulation> nor a <ModelExchange> element".into(),
                    (true, true) => "no <CoSimulation> element".into(),
                    (false, _) => format!(
                        "the FMU supports {} only; twinbench needs Co-Simulation for FMI 3.0 FMUs (FMI 2.0 Model Exchange FMUs are integrated with CVODE)",
                        kinds.join(" and ")
                    ),
                },
            });
        }
    };
    let id = md
        .model_identifier(interface)
        .expect("the interface is declared")
        .to_string();
    // Used as a file name and a C symbol prefix: a path here would load a library from
    // outside the cache.
    if id.is_empty()
        || id.starts_with(|c: char| c.is_ascii_digit())
        || !id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!(
                "modelIdentifier \"{id}\" is not a valid C identifier (letters, digits, '_')"
            ),
        });
    }
    let so = library_entry(&md.fmi_version, &id);
    if binary_required && !names.contains(&so) {
        // Name the platforms the FMU has: a Windows- or macOS-only FMU is a common mistake.
        let mut platforms: Vec<&str> = names
            .iter()
            .filter_map(|n| n.strip_prefix("binaries/"))
            .filter_map(|n| n.split_once('/').map(|(p, _)| p))
            .filter(|p| !p.is_empty())
            .collect();
        platforms.sort();
        platforms.dedup();
        return Err(arch(
            fmu,
            format!(
                "no {so} (the FMU has no binary for this platform; it has {})",
                if platforms.is_empty() {
                    "no binaries at all".to_string()
                } else {
                    format!("binaries for {}", platforms.join(", "))
                }
            ),
        ));
    }
    Ok((md, id))
}

/// Where the Linux x86-64 library of an FMU lies in its archive: `binaries/linux64/` in
/// FMI 2.0, `binaries/x86_64-linux/` in FMI 3.0.
pub fn library_entry(fmi_version: &str, model_identifier: &str) -> String {
    if fmi_version.starts_with("3.") {
        format!("binaries/x86_64-linux/{model_identifier}.so")
    } else {
        format!("binaries/linux64/{model_identifier}.so")
    }
}

/// The `fmiVersion` attribute's value, found without parsing the XML.
pub(crate) fn sniff_fmi_version(xml: &str) -> Option<&str> {
    let i = xml.find("fmiVersion")?;
    let rest = xml[i + "fmiVersion".len()..].trim_start();
    let rest = rest.strip_prefix('=')?.trim_start();
    let q = rest.chars().next().filter(|c| *c == '"' || *c == '\'')?;
    let rest = &rest[1..];
    Some(&rest[..rest.find(q)?])
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

fn extract(fmu: &Path, bytes: &[u8], dir: &Path, limits: &Limits) -> Result<(), FmuError> {
    let tmp = unique_sibling(dir);
    // Nothing half-extracted stays behind in the cache.
    extract_into(fmu, bytes, &tmp, limits).inspect_err(|_| {
        let _ = std::fs::remove_dir_all(&tmp);
    })?;
    let mut moved = std::fs::rename(&tmp, dir);
    if moved.is_err() && dir.is_dir() && !dir.join(".complete").exists() {
        // A folder without `.complete` under the final name was not made by an unpacking
        // (those are renamed in whole); set it aside and take its place.
        let aside = unique_sibling(dir);
        if std::fs::rename(dir, &aside).is_ok() {
            let _ = std::fs::remove_dir_all(&aside);
        }
        moved = std::fs::rename(&tmp, dir);
    }
    match moved {
        Ok(()) => Ok(()),
        // Another process unpacked the same content first: use theirs.
        Err(_) if dir.join(".complete").exists() => {
            let _ = std::fs::remove_dir_all(&tmp);
            Ok(())
        }
        Err(e) => {
            let _ = std::fs::remove_dir_all(&tmp);
            Err(arch(
                dir,
                format!("cannot move the unpacked FMU into the cache: {e}"),
            ))
        }
    }
}

fn extract_into(fmu: &Path, bytes: &[u8], tmp: &Path, limits: &Limits) -> Result<(), FmuError> {
    let max = limits.max_total_bytes;
    let mut zip =
        zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| arch(fmu, e.to_string()))?;
    let mut written: u64 = 0;
    for i in 0..zip.len() {
        let mut f = zip
            .by_index(i)
            .map_err(|e| arch(fmu, format!("entry {i}: {e}")))?;
        let rel = f
            .enclosed_name()
            .ok_or_else(|| arch(fmu, format!("entry '{}' escapes the archive", f.name())))?;
        let out = tmp.join(&rel);
        if f.is_dir() {
            std::fs::create_dir_all(&out).map_err(|e| arch(&out, e.to_string()))?;
            continue;
        }
        if let Some(p) = out.parent() {
            std::fs::create_dir_all(p).map_err(|e| arch(p, e.to_string()))?;
        }
        let mut w = std::fs::File::create(&out).map_err(|e| arch(&out, e.to_string()))?;
        // Bound the real decompressed size too: declared sizes can lie.
        let n = std::io::copy(&mut f.by_ref().take(max - written + 1), &mut w)
            .map_err(|e| arch(fmu, format!("cannot extract '{}': {e}", rel.display())))?;
        written += n;
        if written > max {
            return Err(arch(
                fmu,
                format!(
                    "uncompressed size exceeds the limit of {max} bytes while extracting '{}' (its declared size is wrong: zip bomb?)",
                    rel.display()
                ),
            ));
        }
    }
    std::fs::write(tmp.join(".complete"), b"").map_err(|e| arch(tmp, e.to_string()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    /// A small FMU whose description's `description` attribute is `tag` (keep the length
    /// for a rewrite of the same size).
    fn fmu_bytes(tag: &str) -> Vec<u8> {
        fmu_bytes_with(tag, true)
    }

    /// [`fmu_bytes`], with or without its binary.
    fn fmu_bytes_with(tag: &str, binary: bool) -> Vec<u8> {
        let md = format!(
            r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{{g}}" description="{tag}">
  <CoSimulation modelIdentifier="m"/>
  <ModelVariables>
    <ScalarVariable name="y" valueReference="1" causality="output" initial="calculated"><Real/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1" dependencies=""/></Outputs><InitialUnknowns><Unknown index="1"/></InitialUnknowns></ModelStructure>
</fmiModelDescription>"#
        );
        let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
        // Stored and with a fixed time: a rewrite with an equal-length tag is the same size.
        let opt = zip::write::SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Stored)
            .last_modified_time(zip::DateTime::default());
        for (name, data) in [
            ("modelDescription.xml", md.as_bytes()),
            (
                "binaries/linux64/m.so",
                b"not loaded by these tests".as_slice(),
            ),
            ("resources/data.txt", tag.as_bytes()),
        ] {
            if name.starts_with("binaries/") && !binary {
                continue;
            }
            w.start_file(name, opt).unwrap();
            w.write_all(data).unwrap();
        }
        w.finish().unwrap().into_inner()
    }

    struct Scratch {
        dir: store::TestDir,
    }

    impl Scratch {
        fn new() -> Scratch {
            Scratch {
                dir: store::TestDir::new(),
            }
        }
        fn store(&self) -> PathBuf {
            self.dir.path().join("store")
        }
        /// A cache as a new process has it: nothing loaded, the shared store.
        fn cache(&self) -> FmuCache {
            FmuCache::with_store(&self.dir.path().join("root"), &self.store()).unwrap()
        }
        fn fmu(&self, tag: &str) -> PathBuf {
            let p = self.dir.path().join("m.fmu");
            std::fs::write(&p, fmu_bytes(tag)).unwrap();
            p
        }
        fn index_entries(&self) -> usize {
            std::fs::read_dir(self.store().join(store::INDEX_DIR))
                .map_or(0, |d| d.flatten().count())
        }
    }

    fn stats(index_hits: usize, archives_read: usize, extractions: usize) -> CacheStats {
        CacheStats {
            index_hits,
            archives_read,
            extractions,
        }
    }

    /// Sets a file's mtime (and atime) to the given one.
    fn set_mtime(path: &Path, mtime: std::time::SystemTime) {
        std::fs::File::options()
            .write(true)
            .open(path)
            .unwrap()
            .set_times(
                std::fs::FileTimes::new()
                    .set_modified(mtime)
                    .set_accessed(mtime),
            )
            .unwrap();
    }

    #[test]
    fn a_second_process_finds_the_fmu_through_the_index_without_reading_the_archive() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let a = s.cache();
        let la = a.load(&fmu).unwrap();
        assert_eq!(a.stats(), stats(0, 1, 1));
        assert_eq!(s.index_entries(), 1);
        // In-process, the same path again: through the index too.
        let again = a.load(&fmu).unwrap();
        assert!(Arc::ptr_eq(&la, &again));
        assert_eq!(a.stats(), stats(1, 1, 1));
        let b = s.cache();
        let lb = b.load(&fmu).unwrap();
        assert_eq!(b.stats(), stats(1, 0, 0));
        assert_eq!((&lb.dir, &lb.sha256), (&la.dir, &la.sha256));
        assert_eq!(lb.description.description, "first");
        assert_eq!(lb.source, fmu);
    }

    #[test]
    fn a_temporary_cache_on_a_store_removes_its_folder_and_keeps_the_store() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let cache = FmuCache::temporary_with_store(&s.store()).unwrap();
        let root = cache.root().to_path_buf();
        let l = cache.load(&fmu).unwrap();
        assert!(l.dir.starts_with(s.store()));
        assert!(root.is_dir());
        drop(cache);
        assert!(!root.exists());
        assert!(l.dir.join(".complete").is_file());
        assert!(l.dir.join("binaries/linux64/m.so").is_file());
    }

    #[test]
    fn a_rewrite_in_place_under_a_forged_stat_is_caught_by_the_central_directory() {
        // The stat key cannot match after a rewrite (the ctime changes); forge the index
        // entry of the rewritten file from the old one, so that only the central directory
        // check stands between the new bytes and the old unpacked folder.
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let mtime = std::fs::metadata(&fmu).unwrap().modified().unwrap();
        let old = s.cache().load(&fmu).unwrap();
        let old_key = store::index_key(
            &std::fs::canonicalize(&fmu).unwrap(),
            &std::fs::metadata(&fmu).unwrap(),
        );
        let old_entry = store::read_entry(&s.store(), &old_key).unwrap();
        let size = std::fs::metadata(&fmu).unwrap().len();
        std::fs::write(&fmu, fmu_bytes("secnd")).unwrap();
        set_mtime(&fmu, mtime);
        let meta = std::fs::metadata(&fmu).unwrap();
        assert_eq!((meta.len(), meta.modified().unwrap()), (size, mtime));
        let new_key = store::index_key(&std::fs::canonicalize(&fmu).unwrap(), &meta);
        store::write_entry(
            &s.store(),
            &IndexEntry {
                key: new_key.clone(),
                ..old_entry
            },
        )
        .unwrap();
        let cache = s.cache();
        let new = cache.load(&fmu).unwrap();
        assert_eq!(cache.stats(), stats(0, 1, 1));
        assert_eq!(new.description.description, "secnd");
        assert_ne!(new.dir, old.dir);
        assert_eq!(
            std::fs::read_to_string(new.dir.join("resources/data.txt")).unwrap(),
            "secnd"
        );
        // The entry was rewritten: the next process hits it.
        assert_eq!(
            store::read_entry(&s.store(), &new_key).unwrap().sha256,
            new.sha256
        );
        let next = s.cache();
        assert_eq!(next.load(&fmu).unwrap().dir, new.dir);
        assert_eq!(next.stats(), stats(1, 0, 0));
    }

    #[test]
    fn a_damaged_index_or_an_incomplete_folder_takes_the_full_path() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let first = s.cache().load(&fmu).unwrap();
        let entry_file = std::fs::read_dir(s.store().join(store::INDEX_DIR))
            .unwrap()
            .flatten()
            .next()
            .unwrap()
            .path();
        // A damaged entry: read again, not unpacked again, the entry rewritten.
        std::fs::write(&entry_file, b"twinbench-unpack-index 1\nkey zz\n").unwrap();
        let c = s.cache();
        assert_eq!(c.load(&fmu).unwrap().dir, first.dir);
        assert_eq!(c.stats(), stats(0, 1, 0));
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        // A folder without `.complete` (emptied behind its back): unpacked again in its place.
        std::fs::remove_file(first.dir.join(".complete")).unwrap();
        std::fs::remove_file(first.dir.join("binaries/linux64/m.so")).unwrap();
        let c = s.cache();
        let l = c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(0, 1, 1));
        assert_eq!(l.dir, first.dir);
        assert!(l.dir.join("binaries/linux64/m.so").is_file());
        // An unpacked description that is not the archive's: the full path (the content
        // hash keeps the folder; only an index hit would read it).
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        std::fs::write(l.dir.join("modelDescription.xml"), b"<not xml").unwrap();
        let c = s.cache();
        let e = c.load(&fmu).err();
        assert!(e.is_none(), "{e:?}");
        assert_eq!(c.stats(), stats(0, 1, 0));
        // No temporaries left in the store.
        let names: Vec<String> = std::fs::read_dir(s.store())
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains("tmp")), "{names:?}");
    }

    #[test]
    fn a_hit_still_applies_this_caches_limits() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        s.cache().load(&fmu).unwrap();
        let few = s.cache().with_limits(Limits {
            max_entries: 2,
            max_total_bytes: MAX_TOTAL_BYTES,
        });
        let e = few.load(&fmu).err().expect("refused").to_string();
        assert!(
            e.contains(&fmu.display().to_string())
                && e.contains("3 entries, more than the limit of 2"),
            "{e}"
        );
        assert_eq!(few.stats(), stats(0, 1, 0));
    }

    #[test]
    fn another_file_with_the_same_content_shares_the_folder_with_an_entry_of_its_own() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let copy = s.dir.path().join("copy.fmu");
        std::fs::copy(&fmu, &copy).unwrap();
        let a = s.cache().load(&fmu).unwrap();
        let c = s.cache();
        let b = c.load(&copy).unwrap();
        assert_eq!(a.dir, b.dir);
        assert_eq!(c.stats(), stats(0, 1, 0));
        assert_eq!(s.index_entries(), 2);
    }

    #[test]
    fn only_a_description_only_cache_takes_an_fmu_without_a_binary() {
        let s = Scratch::new();
        let fmu = s.dir.path().join("m.fmu");
        std::fs::write(&fmu, fmu_bytes_with("first", false)).unwrap();
        let refused = |c: &FmuCache| {
            let e = c.load(&fmu).err().expect("refused").to_string();
            assert!(
                e.contains("no binaries/linux64/m.so (the FMU has no binary for this platform; it has no binaries at all)"),
                "{e}"
            );
        };
        refused(&s.cache());
        let l = s.cache().description_only().load(&fmu).unwrap();
        assert_eq!(l.description.model_name, "m");
        // Its library is not there to load, and the error says which.
        let e = l.library().err().expect("no library").to_string();
        assert!(e.contains("binaries/linux64/m.so"), "{e}");
        // The store now indexes it: an ordinary cache on the same store still refuses it.
        assert_eq!(s.index_entries(), 1);
        refused(&s.cache());
    }
}

//! FMU archives: checked as untrusted input, unzipped once into a content-addressed store
//! shared by every twinbench process, their shared library loaded once and shared by every
//! instance.

use super::description::{self, Interface, ModelDescription};
use super::library::Library;
use super::library3::Library3;
use super::manifest::{self, Manifest, ManifestFile};
use super::model_exchange::MeLibrary;
use super::store::{self, CdEntry, IndexEntry};
use crate::FmuError;
use sha2::{Digest, Sha256};
use std::collections::{BTreeMap, HashMap};
use std::fs::{File, Metadata};
use std::io::{Read, Seek};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

pub use super::store::{
    default_store_dir, folders as store_folders, prune as prune_store, Pruned, StoreFolder,
};

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
/// never executes code in the host, not even `fmi2GetVersion`. Before the library is
/// loaded it is verified against the folder's manifest (and repaired when it differs).
pub struct LoadedFmu {
    pub source: PathBuf,
    pub dir: PathBuf,
    pub sha256: String,
    pub description: ModelDescription,
    /// The folder `dir` lies in: the store, or the cache's own folder.
    base: PathBuf,
    /// Whether `base` is a store that other processes share.
    shared: bool,
    /// What the unpacking wrote; `trusted` when this process unpacked it itself (the hashes
    /// then come from the archive's bytes, not from the store).
    manifest: Manifest,
    trusted: bool,
    limits: Limits,
    /// The libraries' checks that passed (one per interface's library).
    library_checked: Mutex<Vec<FileCheck>>,
    /// `.complete`, held with a shared lock while the FMU is loaded: `cache prune` leaves
    /// the folder alone.
    _in_use: Option<File>,
    library: Mutex<Option<Arc<Library>>>,
    library3: Mutex<Option<Arc<Library3>>>,
    /// The FMI 2.0 library loaded for Model Exchange (its own `modelIdentifier`).
    library_me: Mutex<Option<MeLibrary>>,
    /// Whether the cache it came from needs its binaries (not when it describes models
    /// that run natively: [`FmuCache::description_only`]).
    binary_required: bool,
}

/// What an unpacked file must be: where (a path relative to [`FileCheck::base`]), its
/// size, mode and BLAKE3 hash. What the host hands an isolated worker, which checks the
/// library again before it loads it.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FileCheck {
    /// The folder the permission check starts from (the store).
    pub base: PathBuf,
    /// The file, relative to `base`.
    pub rel: String,
    pub size: u64,
    pub mode: u32,
    pub hash: String,
}

impl FileCheck {
    /// The file's full path.
    pub fn path(&self) -> PathBuf {
        self.base.join(&self.rel)
    }

    /// Checks the file: every folder from `base` down and the file owned by this user and
    /// writable by no one else, no symbolic link, a regular file of the size, mode and
    /// hash. The reason otherwise.
    pub fn verify(&self) -> Result<(), String> {
        let (dir, name) = self.rel.split_once('/').ok_or("no folder")?;
        manifest::verify_file(
            &self.base,
            dir,
            &ManifestFile {
                path: name.to_string(),
                size: self.size,
                mode: self.mode,
                crc32: 0,
                hash: self.hash.clone(),
            },
        )
    }
}

impl LoadedFmu {
    /// The BLAKE3 of the unpacked folder's manifest: every file's path, size, mode and hash.
    pub fn manifest_digest(&self) -> String {
        self.manifest.digest()
    }

    /// The folder's name in `base`.
    fn dir_rel(&self) -> &str {
        &self.sha256[..32]
    }

    /// The check of an unpacked file of the manifest (`entry`: its name in the archive).
    pub fn unpacked_file(&self, entry: &str) -> Option<FileCheck> {
        let f = self.manifest.file(entry)?;
        Some(FileCheck {
            base: self.base.clone(),
            rel: format!("{}/{}", self.dir_rel(), f.path),
            size: f.size,
            mode: f.mode,
            hash: f.hash.clone(),
        })
    }

    /// Every unpacked file in the folder of `library` (itself and the dependencies it may
    /// load), as checks a worker verifies again before loading.
    pub fn beside(&self, library: &FileCheck) -> Vec<FileCheck> {
        let entry = library.rel.split_once('/').map_or("", |(_, e)| e);
        self.files_beside(entry)
            .into_iter()
            .map(|(c, _)| c)
            .collect()
    }

    /// Every file of the manifest in the folder of `entry`, with its check and its entry.
    fn files_beside(&self, entry: &str) -> Vec<(FileCheck, String)> {
        let folder_of = |path: &str| path.rsplit_once('/').map_or("", |(d, _)| d).to_string();
        let folder = folder_of(entry);
        self.manifest
            .files
            .iter()
            .filter(|f| folder_of(&f.path) == folder)
            .filter_map(|f| Some((self.unpacked_file(&f.path)?, f.path.clone())))
            .collect()
    }

    /// The library of the default interface, verified against the manifest (unpacked
    /// again when it differs): the only way to its path that code is loaded from, in this
    /// process or in a worker.
    pub fn checked_library(&self) -> Result<FileCheck, FmuError> {
        self.checked_entry(&self.library_entry())
    }

    /// The library of `interface` (Model Exchange may have its own `modelIdentifier`),
    /// verified as [`LoadedFmu::checked_library`].
    pub fn checked_library_of(&self, interface: Interface) -> Result<FileCheck, FmuError> {
        let entry = self
            .library_entry_of(interface)
            .ok_or_else(|| FmuError::Description {
                path: self.source.clone(),
                message: format!("the FMU has no <{}> element", interface.name()),
            })?;
        self.checked_entry(&entry)
    }

    /// `entry` (a library) and every file beside it in its folder (the dependencies it may
    /// load through `$ORIGIN`, M3), each checked against the FMU's archive and verified on
    /// disk (the folder unpacked again when one differs), before anything is loaded.
    fn checked_entry(&self, entry: &str) -> Result<FileCheck, FmuError> {
        let mut checked = lock(&self.library_checked);
        let Some(check) = self.unpacked_file(entry) else {
            return Err(FmuError::Load {
                path: self.source.clone(),
                message: format!("{entry}: the FMU has no such file"),
            });
        };
        if checked.contains(&check) {
            return Ok(check);
        }
        let beside = self.files_beside(entry);
        self.trust_from_archive(&beside)?;
        for (c, name) in &beside {
            if let Err(reason) = c.verify() {
                self.unpack_again(&reason)?;
                c.verify().map_err(|again| {
                    arch(
                        &self.source,
                        format!("{name}: unpacked again and still not the FMU's: {again}"),
                    )
                })?;
            }
        }
        checked.push(check.clone());
        Ok(check)
    }

    /// Every file of the unpacked folder verified against the manifest (unpacked again when
    /// one differs): what a remote worker runs on before it says which content it uses.
    pub fn verify_all(&self) -> Result<(), FmuError> {
        let bad = self
            .manifest
            .files
            .iter()
            .find_map(|f| manifest::verify_file(&self.base, self.dir_rel(), f).err());
        if let Some(reason) = bad {
            self.unpack_again(&reason)?;
            for f in &self.manifest.files {
                manifest::verify_file(&self.base, self.dir_rel(), f).map_err(|again| {
                    arch(
                        &self.source,
                        format!("unpacked again and still not the FMU's: {again}"),
                    )
                })?;
            }
        }
        Ok(())
    }

    /// A manifest read from a store is believed when this process unpacked the folder
    /// itself, or when no isolated FMU can have written the store (workers are confined
    /// here). Otherwise (no confinement, or `TWINBENCH_ISOLATE=crash-only`) the hashes of
    /// `entries` are taken from the archive before the manifest is: an unconfined FMU may
    /// have rewritten a library and its manifest together (M1).
    fn trust_from_archive(&self, entries: &[(FileCheck, String)]) -> Result<(), FmuError> {
        if self.trusted || entries.is_empty() || super::sandbox::available().is_ok() {
            return Ok(());
        }
        // The archive as it is now: if it changed since it was loaded, its library differs
        // and the repair below says so.
        let (file, _) = open_regular(&self.source, &self.limits, "an FMU is a zip archive")?;
        let bytes = read_regular(&self.source, &file, &self.limits)?;
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&bytes[..]))
            .map_err(|e| arch(&self.source, e.to_string()))?;
        for (check, entry) in entries {
            let mut f = zip
                .by_name(entry)
                .map_err(|e| arch(&self.source, format!("{entry}: {e}")))?;
            let mut h = manifest::Hashing {
                inner: std::io::sink(),
                hasher: blake3::Hasher::new(),
            };
            std::io::copy(&mut f.by_ref().take(self.limits.max_total_bytes), &mut h)
                .map_err(|e| arch(&self.source, format!("{entry}: {e}")))?;
            if h.hasher.finalize().to_hex().as_str() != check.hash {
                drop(f);
                return self.unpack_again(&format!(
                    "{}: its manifest does not name the FMU's {entry}",
                    self.dir.display()
                ));
            }
        }
        Ok(())
    }

    /// Reports a damaged folder once and unpacks the archive again into a fresh folder in
    /// its place. Fails when the archive is no longer the one loaded, or the new unpacking
    /// is not the same content.
    fn unpack_again(&self, reason: &str) -> Result<(), FmuError> {
        log::warn!(
            "{}: the unpacked FMU {} differs from what was unpacked ({reason}); unpacking it again",
            self.dir.display(),
            self.source.display()
        );
        let (file, _) = open_regular(&self.source, &self.limits, "an FMU is a zip archive")?;
        let bytes = read_regular(&self.source, &file, &self.limits)?;
        if format!("{:x}", Sha256::digest(&bytes)) != self.sha256 {
            return Err(changed_since(&self.source));
        }
        use std::os::unix::fs::MetadataExt;
        let exec = library_entry(&self.description.fmi_version, self.model_identifier());
        // Only this folder is replaced: one another process put in its place meanwhile is
        // used if good.
        let stale = std::fs::symlink_metadata(&self.dir).map_or(0, |m| m.ino());
        let (fresh, _) = replace_folder(
            &self.source,
            &bytes,
            &self.sha256,
            &self.base,
            self.dir_rel(),
            &self.limits,
            Some(&exec),
            self.shared,
            Some(stale),
        )?;
        if fresh != self.manifest {
            return Err(arch(
                &self.source,
                format!(
                    "{}: unpacked again, its manifest differs from the one loaded (the store was changed); run again",
                    self.dir.display()
                ),
            ));
        }
        Ok(())
    }

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
        // In the archive (the manifest of what was unpacked): a missing or changed file on
        // disk is repaired when the library is loaded (`checked_library_of`).
        if self.binary_required && self.unpacked_file(&entry).is_none() {
            return Err(format!(
                "no {entry}, the {} library (the FMU has no binary of it for this platform)",
                interface.element()
            ));
        }
        Ok(())
    }

    /// The library loaded for Model Exchange ([`Library::load_model_exchange`],
    /// [`Library3::load_model_exchange`]), on the first call; errors name the .fmu and the
    /// library's entry.
    pub fn library_me(&self) -> Result<MeLibrary, FmuError> {
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
        let check = self.checked_library_of(Interface::ModelExchange)?;
        let named = |e| library_error(&self.source, &self.description.fmi_version, id, e);
        let library = match self.is_fmi3() {
            true => MeLibrary::V3(Arc::new(
                Library3::load_model_exchange(&check.path()).map_err(named)?,
            )),
            false => MeLibrary::V2(Arc::new(
                Library::load_model_exchange(&check.path()).map_err(named)?,
            )),
        };
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
        let check = self.checked_library()?;
        let library = load(&check.path()).map(Arc::new).map_err(|e| {
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
    /// Whether every unpacked file is verified on load (see [`FmuCache::verifying_all`]).
    verify_all: bool,
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

/// Creates a cache's folder or a store: its parents as usual, itself private to the user
/// (mode 700 whatever the umask).
fn create_folder(dir: &Path) -> Result<(), FmuError> {
    let cannot = |e: std::io::Error| arch(dir, format!("cannot create cache folder: {e}"));
    if let Some(parent) = dir.parent() {
        std::fs::create_dir_all(parent).map_err(cannot)?;
    }
    manifest::make_dir(dir).map_err(cannot)
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
            verify_all: false,
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
            verify_all: false,
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

/// The loader's message for the library `entry` (loaded from `path`) in the archive's terms:
/// dlopen's text starts with the path it was given (a store folder, meaningless to the
/// user), then names the file that failed, which is a dependency of the library when the
/// library itself is present (`libSimulationRuntimeC.so: cannot open shared object file`).
fn load_problem(entry: &str, path: &Path, message: &str) -> String {
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
fn is_library_name(s: &str) -> bool {
    !s.contains(' ') && (s.ends_with(".so") || s.contains(".so."))
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
    // Co-Simulation, or Model Exchange (integrated by twinbench with CVODE); not FMI 3.0's
    // Scheduled Execution.
    let interface = match md.default_interface() {
        Some(i) => i,
        None => {
            let scheduled = md.unsupported.iter().any(|u| u.starts_with("Scheduled"));
            return Err(FmuError::Description {
                path: fmu.to_path_buf(),
                message: match scheduled {
                    false => "neither a <CoSimulation> nor a <ModelExchange> element".into(),
                    true => "the FMU supports Scheduled Execution only; twinbench runs FMUs through Co-Simulation or Model Exchange".into(),
                },
            });
        }
    };
    if let Some(what) = md.unsupported.first() {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!(
                "the FMU needs {what}; twinbench runs FMI 3.0 Co-Simulation and Model Exchange without clocks"
            ),
        });
    }
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
        // Name the platforms the FMU has binaries for (a Windows- or macOS-only FMU is a
        // common mistake); a platform folder with no file in it has none.
        let mut platforms: Vec<&str> = names
            .iter()
            .filter_map(|n| n.strip_prefix("binaries/"))
            .filter_map(|n| n.split_once('/'))
            .filter(|(p, rest)| !p.is_empty() && !rest.is_empty() && !rest.ends_with('/'))
            .map(|(p, _)| p)
            .collect();
        platforms.sort();
        platforms.dedup();
        let has = if platforms.is_empty() {
            "no binaries at all".to_string()
        } else {
            format!("binaries for {}", platforms.join(", "))
        };
        let dir = &so[..=so.rfind('/').expect("a folder")];
        let mut here: Vec<&str> = names
            .iter()
            .filter_map(|n| n.strip_prefix(dir))
            .filter(|n| !n.is_empty() && !n.ends_with('/'))
            .collect();
        here.sort();
        let why = if !here.is_empty() {
            let shown: Vec<&str> = here.iter().take(5).copied().collect();
            format!(
                "{dir} holds {}{} but not the library its modelIdentifier \"{id}\" names",
                shown.join(", "),
                if here.len() > 5 { ", ..." } else { "" }
            )
        } else if names.iter().any(|n| n.starts_with(dir)) {
            format!("the folder {dir} is empty (the FMU has {has})")
        } else {
            format!("the FMU has no binary for this platform; it has {has}")
        };
        return Err(arch(fmu, format!("no {so} ({why})")));
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

/// The error of an archive that changed since it was loaded (a repair needs its bytes).
fn changed_since(fmu: &Path) -> FmuError {
    arch(
        fmu,
        "the file changed since it was loaded; its unpacked copy cannot be repaired from it: run again",
    )
}

/// `.complete` of an unpacked folder, opened and held with a shared lock: the folder is in
/// use (`cache prune` takes the lock exclusively before it removes a folder). `None` when
/// the folder is not complete, or was removed while waiting for the lock. Its time is set
/// to now: the folder's last use.
fn in_use(dir: &Path) -> Option<File> {
    use std::os::fd::AsRawFd;
    use std::os::unix::fs::{MetadataExt, OpenOptionsExt};
    let path = dir.join(".complete");
    let f = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(&path)
        .ok()?;
    // SAFETY: flock on a descriptor we own.
    if unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_SH) } != 0 {
        return None;
    }
    let held = f.metadata().ok()?;
    let now = std::fs::symlink_metadata(&path).ok()?;
    if (held.dev(), held.ino()) != (now.dev(), now.ino()) {
        return None;
    }
    let _ = f.set_modified(std::time::SystemTime::now());
    Some(f)
}

/// An archive entry's name as the file it is unpacked to: its normal components joined by
/// `/` (the entry checks refused absolute names and `..`).
fn unpacked_name(name: &str) -> String {
    Path::new(name)
        .components()
        .filter_map(|c| match c {
            std::path::Component::Normal(n) => Some(n.to_string_lossy().into_owned()),
            _ => None,
        })
        .collect::<Vec<_>>()
        .join("/")
}

/// The manifest to be of an archive's central directory: its files by unpacked name (the
/// last of a repeated name wins, as when unpacking), without hashes.
fn archive_files(entries: &[CdEntry]) -> BTreeMap<String, &CdEntry> {
    entries
        .iter()
        .filter(|e| !e.name.ends_with('/'))
        .map(|e| (unpacked_name(&e.name), e))
        .collect()
}

/// Reads and checks an unpacked folder `base/rel` of the archive with content hash `sha`
/// and central directory `entries`: its manifest, opened through folders that only this
/// user can write, names this archive and exactly its files with their sizes and CRC-32s;
/// its `modelDescription.xml` is the manifest's (size, mode, hash). Returns the manifest
/// and the description's bytes, or why the folder cannot be used.
fn check_folder(
    base: &Path,
    rel: &str,
    sha: &str,
    entries: &[CdEntry],
) -> Result<(Manifest, Vec<u8>), String> {
    let (f, _) = manifest::open_checked(base, &format!("{rel}/{}", manifest::MANIFEST))?;
    let (text, _) = manifest::read_hashed(&f, manifest::MAX_MANIFEST_BYTES)
        .map_err(|e| format!("its manifest: {e}"))?;
    let m = std::str::from_utf8(&text)
        .ok()
        .and_then(Manifest::parse)
        .ok_or("its manifest is damaged")?;
    if m.archive != sha {
        return Err("its manifest is of another archive".into());
    }
    let files = archive_files(entries);
    let same = files.len() == m.files.len()
        && files
            .iter()
            .zip(&m.files)
            .all(|((name, e), f)| *name == f.path && e.size == f.size && e.crc32 == f.crc32);
    if !same {
        return Err("its manifest does not list the archive's files".into());
    }
    let md = m
        .file("modelDescription.xml")
        .ok_or("no modelDescription.xml")?;
    let (f, meta) = manifest::open_checked(base, &format!("{rel}/modelDescription.xml"))?;
    use std::os::unix::fs::MetadataExt;
    if meta.len() != md.size || meta.mode() & 0o7777 != md.mode {
        return Err(format!(
            "{}: {} bytes, mode {:o}; unpacked: {} bytes, mode {:o}",
            base.join(rel).join("modelDescription.xml").display(),
            meta.len(),
            meta.mode() & 0o7777,
            md.size,
            md.mode
        ));
    }
    let (bytes, hash) = manifest::read_hashed(&f, MAX_DESCRIPTION_BYTES)
        .map_err(|e| format!("modelDescription.xml: {e}"))?;
    if hash != md.hash {
        return Err(format!(
            "{}: its content is not the unpacked one",
            base.join(rel).join("modelDescription.xml").display()
        ));
    }
    Ok((m, bytes))
}

/// Unpacks `bytes` (the archive `fmu`, checked) into `base/rel` afresh: a folder there is
/// set aside and removed, unless another process has put a good one in its place meanwhile
/// (`stale`: the inode of the folder found damaged; `None`: any folder that passes
/// [`check_folder`] is good). In a shared store one process unpacks at a time (the store's
/// unpack lock), so that processes starting together do not each unpack a copy. Returns
/// the manifest of the folder in place and whether this process unpacked it.
#[allow(clippy::too_many_arguments)]
fn replace_folder(
    fmu: &Path,
    bytes: &[u8],
    sha: &str,
    base: &Path,
    rel: &str,
    limits: &Limits,
    exec: Option<&str>,
    shared: bool,
    stale: Option<u64>,
) -> Result<(Manifest, bool), FmuError> {
    use std::os::unix::fs::MetadataExt;
    let dir = base.join(rel);
    let _unpacking = if shared {
        store::unpack_lock(base)
    } else {
        None
    };
    let mut zip =
        zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| arch(fmu, e.to_string()))?;
    let entries = check_entries_of(fmu, &mut zip, limits)?;
    let current = std::fs::symlink_metadata(&dir).ok().map(|m| m.ino());
    let replaced_meanwhile = stale.is_none() || current != stale;
    if current.is_some() && replaced_meanwhile && dir.join(".complete").is_file() {
        if let Ok((m, _)) = check_folder(base, rel, sha, &entries) {
            return Ok((m, false));
        }
    }
    if current.is_some() {
        let aside = unique_sibling(&dir);
        if std::fs::rename(&dir, &aside).is_ok() {
            let _ = std::fs::remove_dir_all(&aside);
        }
    }
    match extract(fmu, bytes, sha, &dir, limits, exec)? {
        Some(m) => Ok((m, true)),
        None => check_folder(base, rel, sha, &entries)
            .map(|(m, _)| (m, false))
            .map_err(|why| arch(&dir, format!("cannot use the unpacked FMU: {why}"))),
    }
}

/// Unpacks into a folder of its own renamed into place as `dir`. Returns the manifest of
/// what was unpacked, `None` when another process renamed a complete unpacking into place
/// first (theirs is used).
fn extract(
    fmu: &Path,
    bytes: &[u8],
    sha: &str,
    dir: &Path,
    limits: &Limits,
    exec: Option<&str>,
) -> Result<Option<Manifest>, FmuError> {
    let tmp = unique_sibling(dir);
    // Nothing half-extracted stays behind in the cache.
    let manifest = extract_into(fmu, bytes, &tmp, limits, sha, exec).inspect_err(|_| {
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
        Ok(()) => Ok(Some(manifest)),
        // Another process unpacked the same content first: use theirs.
        Err(_) if dir.join(".complete").exists() => {
            let _ = std::fs::remove_dir_all(&tmp);
            Ok(None)
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

/// Unpacks every entry into `tmp` with modes set whatever the umask (folders 0700, files
/// 0600, the library `exec` 0700), hashing each file as it is written, then writes the
/// manifest and, last, `.complete`.
fn extract_into(
    fmu: &Path,
    bytes: &[u8],
    tmp: &Path,
    limits: &Limits,
    sha: &str,
    exec: Option<&str>,
) -> Result<Manifest, FmuError> {
    let max = limits.max_total_bytes;
    let mut zip =
        zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| arch(fmu, e.to_string()))?;
    manifest::make_dir(tmp).map_err(|e| arch(tmp, e.to_string()))?;
    let mut written: u64 = 0;
    let mut files: BTreeMap<String, ManifestFile> = BTreeMap::new();
    for i in 0..zip.len() {
        let mut f = zip
            .by_index(i)
            .map_err(|e| arch(fmu, format!("entry {i}: {e}")))?;
        let rel = f
            .enclosed_name()
            .ok_or_else(|| arch(fmu, format!("entry '{}' escapes the archive", f.name())))?;
        let out = tmp.join(&rel);
        if f.is_dir() {
            manifest::make_dirs(tmp, &rel).map_err(|e| arch(&out, e.to_string()))?;
            continue;
        }
        if let Some(p) = rel.parent() {
            manifest::make_dirs(tmp, p).map_err(|e| arch(&tmp.join(p), e.to_string()))?;
        }
        let name = unpacked_name(f.name());
        let mode = if exec == Some(name.as_str()) {
            manifest::EXEC_MODE
        } else {
            manifest::FILE_MODE
        };
        if files.contains_key(&name) {
            // A repeated name: the last entry wins, as it always did.
            let _ = std::fs::remove_file(&out);
        }
        let w = manifest::create_file(&out, mode).map_err(|e| arch(&out, e.to_string()))?;
        let mut w = manifest::Hashing {
            inner: w,
            hasher: blake3::Hasher::new(),
        };
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
        files.insert(
            name.clone(),
            ManifestFile {
                path: name,
                size: n,
                mode,
                crc32: f.crc32(),
                hash: w.hasher.finalize().to_hex().to_string(),
            },
        );
    }
    let manifest = Manifest {
        archive: sha.to_string(),
        files: files.into_values().collect(),
    };
    let write = |name: &str, text: &[u8]| -> Result<(), FmuError> {
        use std::io::Write;
        let p = tmp.join(name);
        manifest::create_file(&p, manifest::FILE_MODE)
            .and_then(|mut f| f.write_all(text))
            .map_err(|e| arch(&p, e.to_string()))
    };
    write(manifest::MANIFEST, manifest.to_text().as_bytes())?;
    write(".complete", b"")?;
    Ok(manifest)
}

#[cfg(test)]
mod load_messages {
    use super::*;

    #[test]
    fn a_missing_dependency_is_named_not_the_fmus_own_library() {
        let path = Path::new("/store/ab12/binaries/linux64/Model.so");
        let m = load_problem(
            "binaries/linux64/Model.so",
            path,
            "/store/ab12/binaries/linux64/Model.so: libSimulationRuntimeC.so: cannot open shared object file: No such file or directory",
        );
        assert!(
            m.starts_with("binaries/linux64/Model.so needs the library libSimulationRuntimeC.so, which cannot be loaded: cannot open shared object file"),
            "{m}"
        );
        // The library itself missing or broken: its own name and the reason.
        let m = load_problem(
            "binaries/linux64/Model.so",
            path,
            "/store/ab12/binaries/linux64/Model.so: cannot open shared object file: No such file or directory",
        );
        assert_eq!(
            m,
            "binaries/linux64/Model.so: cannot open shared object file: No such file or directory"
        );
        let m = load_problem(
            "binaries/linux64/Model.so",
            path,
            "/store/ab12/binaries/linux64/Model.so: undefined symbol: foo",
        );
        assert_eq!(m, "binaries/linux64/Model.so: undefined symbol: foo");
        let m = load_problem(
            "binaries/linux64/Model.so",
            path,
            "/store/ab12/binaries/linux64/Model.so: libgfortran.so.3: cannot open shared object file: No such file or directory",
        );
        assert!(m.contains("needs the library libgfortran.so.3,"), "{m}");
    }
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
        // An unpacked description that is not the manifest's: the full path, which finds
        // the folder damaged and unpacks it again.
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        let md = l.dir.join("modelDescription.xml");
        let good = std::fs::read(&md).unwrap();
        std::fs::write(&md, b"<not xml").unwrap();
        let c = s.cache();
        let e = c.load(&fmu).err();
        assert!(e.is_none(), "{e:?}");
        assert_eq!(c.stats(), stats(0, 1, 1));
        assert_eq!(std::fs::read(&md).unwrap(), good);
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        // No temporaries left in the store.
        let names: Vec<String> = std::fs::read_dir(s.store())
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        assert!(names.iter().all(|n| !n.contains("tmp")), "{names:?}");
    }

    /// The library's store copy with one byte changed, its size kept.
    fn flip_a_byte(path: &Path) {
        use std::os::unix::fs::PermissionsExt;
        let mut bytes = std::fs::read(path).unwrap();
        bytes[3] ^= 0x20;
        let mode = std::fs::metadata(path).unwrap().permissions().mode();
        std::fs::write(path, &bytes).unwrap();
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).unwrap();
    }

    #[test]
    fn n03_a_changed_byte_in_the_stores_library_is_found_before_loading_and_repaired() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let first = s.cache().load(&fmu).unwrap();
        let so = first.library_path();
        let good = std::fs::read(&so).unwrap();
        assert!(first.checked_library().is_ok());
        flip_a_byte(&so);
        // A later process: the index still hits (nothing of the archive changed), and the
        // library is verified before anything could load it.
        let c = s.cache();
        let l = c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(1, 0, 0));
        let checked = l.checked_library().unwrap();
        assert_eq!(checked.path(), so);
        assert_eq!(std::fs::read(&so).unwrap(), good);
        checked.verify().unwrap();
        // A resource changed: not read by the host (the FMU reads it), found by a full
        // verification (a remote worker's) and repaired too.
        let data = l.dir.join("resources/data.txt");
        flip_a_byte(&data);
        let l = s.cache().load(&fmu).unwrap();
        l.verify_all().unwrap();
        assert_eq!(std::fs::read_to_string(&data).unwrap(), "first");
    }

    #[test]
    fn n19_a_complete_folder_without_its_library_is_unpacked_again() {
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let first = s.cache().load(&fmu).unwrap();
        std::fs::remove_file(first.library_path()).unwrap();
        // After deleting the index and touching the FMU too: the full path finds the folder
        // complete, and the library is missing when it is checked.
        std::fs::remove_dir_all(s.store().join(store::INDEX_DIR)).unwrap();
        set_mtime(&fmu, std::time::SystemTime::now());
        let c = s.cache();
        let l = c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(0, 1, 0));
        l.checked_library().unwrap();
        assert!(l.library_path().is_file());
        // The manifest gone: the folder is not used as it is, but unpacked again.
        std::fs::remove_file(l.dir.join(manifest::MANIFEST)).unwrap();
        let c = s.cache();
        c.load(&fmu).unwrap();
        assert_eq!(c.stats(), stats(0, 1, 1));
        assert!(l.dir.join(manifest::MANIFEST).is_file());
    }

    #[test]
    fn n27_folders_and_files_anyone_else_can_write_are_not_used() {
        use std::os::unix::fs::PermissionsExt;
        let s = Scratch::new();
        let fmu = s.fmu("first");
        let first = s.cache().load(&fmu).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o7777;
        assert_eq!(mode(&first.dir), 0o700);
        assert_eq!(mode(&first.dir.join("binaries/linux64")), 0o700);
        assert_eq!(mode(&first.library_path()), 0o700);
        assert_eq!(mode(&first.dir.join("modelDescription.xml")), 0o600);
        assert_eq!(mode(&s.store().join(store::INDEX_DIR)), 0o700);
        // A folder on the way to the library that others can write: repaired, not used.
        let linux64 = first.dir.join("binaries/linux64");
        std::fs::set_permissions(&linux64, std::fs::Permissions::from_mode(0o777)).unwrap();
        let l = s.cache().load(&fmu).unwrap();
        l.checked_library().unwrap();
        assert_eq!(mode(&linux64), 0o700);
        // The library itself group-writable: the same.
        let so = l.library_path();
        std::fs::set_permissions(&so, std::fs::Permissions::from_mode(0o770)).unwrap();
        let l = s.cache().load(&fmu).unwrap();
        l.checked_library().unwrap();
        assert_eq!(mode(&so), 0o700);
        // The store's own folder: no repair can help, the library is refused with the path
        // and the mode.
        std::fs::set_permissions(s.store(), std::fs::Permissions::from_mode(0o775)).unwrap();
        let l = s.cache().load(&fmu).unwrap();
        let e = l.checked_library().unwrap_err().to_string();
        assert!(
            e.contains(&format!(
                "{}: mode 775: group or others can write it",
                s.store().display()
            )),
            "{e}"
        );
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

//! FMU archives: checked as untrusted input, unzipped once into a content-addressed cache,
//! their shared library loaded once and shared by every instance.

use crate::description::{self, ModelDescription};
use crate::instance3::Library3;
use crate::library::Library;
use crate::FmuError;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

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
}

impl LoadedFmu {
    /// The unpacked library (`binaries/linux64/<modelIdentifier>.so`, FMI 3.0:
    /// `binaries/x86_64-linux/`).
    pub fn library_path(&self) -> PathBuf {
        self.dir.join(self.library_entry())
    }

    /// The library's entry in the archive, for messages.
    pub fn library_entry(&self) -> String {
        library_entry(&self.description.fmi_version, self.model_identifier())
    }

    /// An FMI 3.0 FMU.
    pub fn is_fmi3(&self) -> bool {
        self.description.fmi_version.starts_with("3.")
    }

    /// The FMI 3.0 library, loaded into this process on the first call.
    pub fn library3(&self) -> Result<Arc<Library3>, FmuError> {
        let mut slot = lock(&self.library3);
        if let Some(l) = &*slot {
            return Ok(l.clone());
        }
        let library = Library3::load(&self.library_path())
            .map(Arc::new)
            .map_err(|e| {
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

    /// The library, loaded into this process on the first call (and checked: every
    /// required function, `fmi2GetVersion` = "2.0"). Errors name the .fmu and its entry.
    pub fn library(&self) -> Result<Arc<Library>, FmuError> {
        if self.is_fmi3() {
            return Err(FmuError::Load {
                path: self.source.clone(),
                message: "an FMI 3.0 FMU has no FMI 2.0 library".into(),
            });
        }
        let mut slot = lock(&self.library);
        if let Some(l) = &*slot {
            return Ok(l.clone());
        }
        let library = Library::load(&self.library_path())
            .map(Arc::new)
            .map_err(|e| {
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
    pub fn model_identifier(&self) -> &str {
        &self
            .description
            .co_simulation
            .as_ref()
            .expect("checked at load")
            .model_identifier
    }
}

/// The unpack cache: a folder per FMU content hash. A temporary cache is removed when
/// dropped; a kept one stays for later runs.
///
/// Safe to share between threads and processes: one thread of a process unpacks a given
/// content while the others wait for it (a lock per content hash), and every unpacking
/// goes into a folder of its own that is renamed into place when complete.
pub struct FmuCache {
    root: PathBuf,
    keep: bool,
    loaded: Mutex<HashMap<String, Arc<LoadedFmu>>>,
    /// One lock per content hash being loaded.
    loading: Mutex<HashMap<String, Arc<Mutex<()>>>>,
    limits: Limits,
    /// A temporary cache's lock file (`<root>.lock`, flocked while the cache lives).
    _owner: Option<OwnerLock>,
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

impl FmuCache {
    /// A fresh cache under the system temporary folder, removed on drop unless `keep`.
    pub fn temporary(keep: bool) -> Result<FmuCache, FmuError> {
        remove_stale_caches();
        let root = std::env::temp_dir().join(unique_name("twinbench-fmu"));
        // The owner's lock, taken before anything is visible under the final names: held
        // for the cache's life, released by the kernel when the process ends however it ends.
        let lock = owner_lock(&root)?;
        std::fs::create_dir_all(&root)
            .map_err(|e| arch(&root, format!("cannot create cache folder: {e}")))?;
        Ok(FmuCache {
            root,
            keep,
            _owner: Some(lock),
            loaded: Mutex::new(HashMap::new()),
            loading: Mutex::new(HashMap::new()),
            limits: Limits::default(),
        })
    }

    /// A cache in `dir` that is kept (reused across runs).
    pub fn persistent(dir: &Path) -> Result<FmuCache, FmuError> {
        std::fs::create_dir_all(dir)
            .map_err(|e| arch(dir, format!("cannot create cache folder: {e}")))?;
        Ok(FmuCache {
            root: dir.to_path_buf(),
            keep: true,
            _owner: None,
            loaded: Mutex::new(HashMap::new()),
            loading: Mutex::new(HashMap::new()),
            limits: Limits::default(),
        })
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Other zip-bomb limits (tests use small ones).
    pub fn with_limits(mut self, limits: Limits) -> Self {
        self.limits = limits;
        self
    }

    /// Check, unpack (once per content) and load an FMU.
    pub fn load(&self, fmu: &Path) -> Result<Arc<LoadedFmu>, FmuError> {
        // Only a regular file, and not larger than what may be unpacked: a FIFO would hang
        // the read, /dev/zero would fill the memory.
        let meta = std::fs::metadata(fmu).map_err(|e| arch(fmu, format!("cannot read: {e}")))?;
        if !meta.is_file() {
            return Err(arch(fmu, "not a regular file (an FMU is a zip archive)"));
        }
        if meta.len() > self.limits.max_total_bytes {
            return Err(arch(
                fmu,
                format!(
                    "{} bytes, more than the limit of {} bytes",
                    meta.len(),
                    self.limits.max_total_bytes
                ),
            ));
        }
        let bytes = std::fs::read(fmu).map_err(|e| arch(fmu, format!("cannot read: {e}")))?;
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
        let (md, _id) = check_archive_with(fmu, &bytes, &self.limits)?;
        let dir = self.root.join(&sha[..32]);
        if !dir.join(".complete").exists() {
            extract(fmu, &bytes, &dir, &self.limits)?;
        }
        let loaded = Arc::new(LoadedFmu {
            source: fmu.to_path_buf(),
            dir,
            sha256: sha.clone(),
            description: md,
            library: Mutex::new(None),
            library3: Mutex::new(None),
        });
        lock(&self.loaded).insert(sha, loaded.clone());
        Ok(loaded)
    }
}

impl FmuCache {
    /// Check and unpack any zip package (an SSP) into this cache, once per content, with the
    /// FMU rules: a regular file within the size limit, [`check_entries`], the real
    /// decompressed size bounded. Returns the folder (`<root>/pkg-<hash>`), removed with the
    /// cache.
    pub fn unpack_package(&self, package: &Path) -> Result<PathBuf, FmuError> {
        let meta =
            std::fs::metadata(package).map_err(|e| arch(package, format!("cannot read: {e}")))?;
        if !meta.is_file() {
            return Err(arch(
                package,
                "not a regular file (a package is a zip archive)",
            ));
        }
        if meta.len() > self.limits.max_total_bytes {
            return Err(arch(
                package,
                format!(
                    "{} bytes, more than the limit of {} bytes",
                    meta.len(),
                    self.limits.max_total_bytes
                ),
            ));
        }
        let bytes =
            std::fs::read(package).map_err(|e| arch(package, format!("cannot read: {e}")))?;
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
/// unpacked copy is in a temporary folder the user never saw). Also used by the isolation
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
                "{entry} does not export the required FMI {version} function {symbol}"
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
    let mut names = Vec::with_capacity(zip.len());
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
        names.push(name);
    }
    Ok((zip, names))
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
    let (mut zip, names) = check_entries(fmu, bytes, limits)?;
    let xml = {
        let mut f = zip
            .by_name("modelDescription.xml")
            .map_err(|_| arch(fmu, "no modelDescription.xml at the archive's root"))?;
        let mut raw = Vec::new();
        f.by_ref()
            .take(MAX_DESCRIPTION_BYTES + 1)
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
        })?
    };
    let md = description::parse(&xml).map_err(|message| FmuError::Description {
        path: fmu.to_path_buf(),
        // An FMI 1.0 description may not even parse as 2.0: name the version then.
        message: match sniff_fmi_version(&xml) {
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
    let Some(cs) = &md.co_simulation else {
        let kinds: Vec<&str> = [
            (md.has_model_exchange, "Model Exchange"),
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
            message: if kinds.is_empty() {
                "no <CoSimulation> element".into()
            } else {
                format!(
                    "the FMU supports {} only; twinbench needs Co-Simulation",
                    kinds.join(" and ")
                )
            },
        });
    };
    if let Some(what) = md.unsupported.first() {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!(
                "the FMU needs {what}; twinbench runs FMI 3.0 Co-Simulation without clocks"
            ),
        });
    }
    let id = cs.model_identifier.clone();
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
    if !names.contains(&so) {
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
fn unique_name(prefix: &str) -> String {
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
fn unique_sibling(path: &Path) -> PathBuf {
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
    match std::fs::rename(&tmp, dir) {
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

//! FMU archives: checked as untrusted input, unzipped once into a content-addressed store
//! shared by every twinbench process, their shared library loaded once and shared by every
//! instance.

use super::library::Library;
use super::library3::Library3;
use super::manifest::{self, Manifest, ManifestFile};
use super::model::{Interface, ModelDescription};
use super::model_exchange::MeLibrary;
use crate::import::error::{FileCheckError, InterfaceError};
use crate::FmuError;
use sha2::{Digest, Sha256};
use std::fs::File;
use std::io::Read;
use std::path::{Path, PathBuf};
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
    pub fn verify(&self) -> Result<(), FileCheckError> {
        let (dir, name) = self.rel.split_once('/').ok_or(FileCheckError::NoFolder)?;
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
    fn unpack_again(&self, reason: &dyn std::fmt::Display) -> Result<(), FmuError> {
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
    pub fn check_interface(&self, interface: Interface) -> Result<(), InterfaceError> {
        let Some(entry) = self.library_entry_of(interface) else {
            let has: Vec<&str> = Interface::ALL
                .into_iter()
                .filter(|i| self.description.supports(*i))
                .map(Interface::name)
                .collect();
            return Err(InterfaceError::NotDeclared {
                element: interface.element(),
                supported: has,
            });
        };
        // In the archive (the manifest of what was unpacked): a missing or changed file on
        // disk is repaired when the library is loaded (`checked_library_of`).
        if self.binary_required && self.unpacked_file(&entry).is_none() {
            return Err(InterfaceError::NoBinary {
                entry,
                element: interface.element(),
            });
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

mod cache;
mod entries;
mod extract;

pub use cache::*;
pub use entries::*;
pub(crate) use extract::*;

#[cfg(test)]
mod tests;

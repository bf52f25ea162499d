//! FMU archives: checked as untrusted input, unzipped once into a content-addressed cache,
//! their shared library loaded once and shared by every instance.

use super::description::{self, ModelDescription};
use super::library::Library;
use super::FmuError;
use sha2::{Digest, Sha256};
use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// Limits against zip bombs.
pub const MAX_ENTRIES: usize = 10_000;
pub const MAX_TOTAL_BYTES: u64 = 2 << 30;

/// An unpacked, checked FMU with its library loaded.
pub struct LoadedFmu {
    pub source: PathBuf,
    pub dir: PathBuf,
    pub sha256: String,
    pub description: ModelDescription,
    pub library: Arc<Library>,
}

impl LoadedFmu {
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
pub struct FmuCache {
    root: PathBuf,
    keep: bool,
    loaded: Mutex<HashMap<String, Arc<LoadedFmu>>>,
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
        let root = std::env::temp_dir().join(format!(
            "twinbench-fmu-{}-{:x}",
            std::process::id(),
            std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos())
                .unwrap_or(0)
        ));
        std::fs::create_dir_all(&root)
            .map_err(|e| arch(&root, format!("cannot create cache folder: {e}")))?;
        Ok(FmuCache {
            root,
            keep,
            loaded: Mutex::new(HashMap::new()),
        })
    }

    /// A cache in `dir` that is kept (reused across runs).
    pub fn persistent(dir: &Path) -> Result<FmuCache, FmuError> {
        std::fs::create_dir_all(dir)
            .map_err(|e| arch(dir, format!("cannot create cache folder: {e}")))?;
        Ok(FmuCache {
            root: dir.to_path_buf(),
            keep: true,
            loaded: Mutex::new(HashMap::new()),
        })
    }

    pub fn root(&self) -> &Path {
        &self.root
    }

    /// Check, unpack (once per content) and load an FMU.
    pub fn load(&self, fmu: &Path) -> Result<Arc<LoadedFmu>, FmuError> {
        let bytes = std::fs::read(fmu).map_err(|e| arch(fmu, format!("cannot read: {e}")))?;
        let sha = format!("{:x}", Sha256::digest(&bytes));
        if let Some(l) = self.loaded.lock().unwrap().get(&sha) {
            return Ok(l.clone());
        }
        let (md, id) = check_archive(fmu, &bytes)?;
        let dir = self.root.join(&sha[..32]);
        if !dir.join(".complete").exists() {
            extract(fmu, &bytes, &dir)?;
        }
        let lib_path = dir
            .join("binaries")
            .join("linux64")
            .join(format!("{id}.so"));
        let library = Arc::new(Library::load(&lib_path)?);
        let loaded = Arc::new(LoadedFmu {
            source: fmu.to_path_buf(),
            dir,
            sha256: sha.clone(),
            description: md,
            library,
        });
        self.loaded.lock().unwrap().insert(sha, loaded.clone());
        Ok(loaded)
    }
}

impl Drop for FmuCache {
    fn drop(&mut self) {
        if !self.keep {
            // Libraries stay mapped until the process ends; removing their files is fine on Linux.
            let _ = std::fs::remove_dir_all(&self.root);
        }
    }
}

/// Everything checked before a byte is written: entry names (no `..`, no absolute paths),
/// no symbolic links, size and count limits, a UTF-8 FMI 2.0 Co-Simulation
/// modelDescription.xml, and the linux64 binary it names.
pub fn check_archive(fmu: &Path, bytes: &[u8]) -> Result<(ModelDescription, String), FmuError> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| arch(fmu, format!("not a valid zip archive: {e}")))?;
    if zip.len() > MAX_ENTRIES {
        return Err(arch(
            fmu,
            format!(
                "{} entries, more than the limit of {MAX_ENTRIES}",
                zip.len()
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
        if total > MAX_TOTAL_BYTES {
            return Err(arch(
                fmu,
                format!("uncompressed size exceeds the limit of {MAX_TOTAL_BYTES} bytes"),
            ));
        }
        names.push(name);
    }
    let xml = {
        let mut f = zip
            .by_name("modelDescription.xml")
            .map_err(|_| arch(fmu, "no modelDescription.xml at the archive's root"))?;
        let mut raw = Vec::new();
        f.by_ref()
            .take(64 << 20)
            .read_to_end(&mut raw)
            .map_err(|e| arch(fmu, format!("cannot read modelDescription.xml: {e}")))?;
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
        message,
    })?;
    if md.fmi_version != "2.0" {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!(
                "fmiVersion is \"{}\"; twinbench runs FMI 2.0 FMUs only",
                md.fmi_version
            ),
        });
    }
    let Some(cs) = &md.co_simulation else {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: if md.has_model_exchange {
                "the FMU supports Model Exchange only; twinbench needs Co-Simulation".into()
            } else {
                "no <CoSimulation> element".into()
            },
        });
    };
    let id = cs.model_identifier.clone();
    let so = format!("binaries/linux64/{id}.so");
    if !names.contains(&so) {
        return Err(arch(
            fmu,
            format!("no {so} (the FMU has no binary for this platform)"),
        ));
    }
    Ok((md, id))
}

fn extract(fmu: &Path, bytes: &[u8], dir: &Path) -> Result<(), FmuError> {
    let tmp = dir.with_extension(format!("tmp{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&tmp);
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
        let n = std::io::copy(&mut f.by_ref().take(MAX_TOTAL_BYTES - written + 1), &mut w)
            .map_err(|e| arch(fmu, format!("cannot extract '{}': {e}", rel.display())))?;
        written += n;
        if written > MAX_TOTAL_BYTES {
            let _ = std::fs::remove_dir_all(&tmp);
            return Err(arch(
                fmu,
                format!("uncompressed size exceeds the limit of {MAX_TOTAL_BYTES} bytes"),
            ));
        }
    }
    std::fs::write(tmp.join(".complete"), b"").map_err(|e| arch(&tmp, e.to_string()))?;
    match std::fs::rename(&tmp, dir) {
        Ok(()) => Ok(()),
        // Another process unpacked the same content first: use theirs.
        Err(_) if dir.join(".complete").exists() => {
            let _ = std::fs::remove_dir_all(&tmp);
            Ok(())
        }
        Err(e) => Err(arch(
            dir,
            format!("cannot move the unpacked FMU into the cache: {e}"),
        )),
    }
}

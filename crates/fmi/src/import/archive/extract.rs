//! Extraction: an archive unpacked into a folder of its own, checked against its manifest,
//! and renamed into place.

use super::*;
use crate::import::error::FolderError;
use crate::import::manifest::{self, Manifest, ManifestFile};
use crate::import::store::{self, unique_sibling, CdEntry};
use crate::FmuError;
use std::collections::BTreeMap;
use std::fs::File;
use std::io::Read;
use std::path::Path;

/// The error of an archive that changed since it was loaded (a repair needs its bytes).
pub(crate) fn changed_since(fmu: &Path) -> FmuError {
    arch(
        fmu,
        "the file changed since it was loaded; its unpacked copy cannot be repaired from it: run again",
    )
}

/// `.complete` of an unpacked folder, opened and held with a shared lock: the folder is in
/// use (`cache prune` takes the lock exclusively before it removes a folder). `None` when
/// the folder is not complete, or was removed while waiting for the lock. Its time is set
/// to now: the folder's last use.
pub(crate) fn in_use(dir: &Path) -> Option<File> {
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
pub(crate) fn unpacked_name(name: &str) -> String {
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
pub(crate) fn archive_files(entries: &[CdEntry]) -> BTreeMap<String, &CdEntry> {
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
pub(crate) fn check_folder(
    base: &Path,
    rel: &str,
    sha: &str,
    entries: &[CdEntry],
) -> Result<(Manifest, Vec<u8>), FolderError> {
    let (f, _) = manifest::open_checked(base, &format!("{rel}/{}", manifest::MANIFEST))?;
    let (text, _) = manifest::read_hashed(&f, manifest::MAX_MANIFEST_BYTES)
        .map_err(FolderError::ManifestRead)?;
    let m = std::str::from_utf8(&text)
        .ok()
        .and_then(Manifest::parse)
        .ok_or(FolderError::ManifestDamaged)?;
    if m.archive != sha {
        return Err(FolderError::OtherArchive);
    }
    let files = archive_files(entries);
    let same = files.len() == m.files.len()
        && files
            .iter()
            .zip(&m.files)
            .all(|((name, e), f)| *name == f.path && e.size == f.size && e.crc32 == f.crc32);
    if !same {
        return Err(FolderError::OtherFiles);
    }
    let md = m
        .file("modelDescription.xml")
        .ok_or(FolderError::NoDescription)?;
    let (f, meta) = manifest::open_checked(base, &format!("{rel}/modelDescription.xml"))?;
    use std::os::unix::fs::MetadataExt;
    if meta.len() != md.size || meta.mode() & 0o7777 != md.mode {
        return Err(FolderError::DescriptionChanged {
            path: base.join(rel).join("modelDescription.xml"),
            size: meta.len(),
            mode: meta.mode() & 0o7777,
            unpacked_size: md.size,
            unpacked_mode: md.mode,
        });
    }
    let (bytes, hash) =
        manifest::read_hashed(&f, MAX_DESCRIPTION_BYTES).map_err(FolderError::DescriptionRead)?;
    if hash != md.hash {
        return Err(FolderError::DescriptionContent {
            path: base.join(rel).join("modelDescription.xml"),
        });
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
pub(crate) fn replace_folder(
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
pub(crate) fn extract(
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
pub(crate) fn extract_into(
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

//! The manifest of an unpacked FMU (`<store>/<hash>/.manifest`): every file's path, size,
//! mode, CRC-32 (the archive's) and BLAKE3 hash, written by the unpacking process before
//! `.complete`. A file is used only after it was opened through folders that only this user
//! can write ([`open_checked`]) and found as the manifest says ([`verify_file`]).

use super::error::FileCheckError;
use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsRawFd, FromRawFd};
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::MetadataExt;
use std::path::Path;

/// The manifest's file name in an unpacked folder.
pub(crate) const MANIFEST: &str = ".manifest";
/// First line of every manifest: a manifest of another format is no manifest.
const FORMAT: &str = "twinbench-unpacked 1";
/// The largest manifest read (10,000 entries of a few hundred bytes).
pub(crate) const MAX_MANIFEST_BYTES: u64 = 16 << 20;
/// Modes the unpacking sets whatever the umask: folders and the library 0700, files 0600.
pub(crate) const DIR_MODE: u32 = 0o700;
pub(crate) const FILE_MODE: u32 = 0o600;
pub(crate) const EXEC_MODE: u32 = 0o700;

/// One unpacked file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct ManifestFile {
    /// The entry's name in the archive (a relative path without `..`).
    pub path: String,
    pub size: u64,
    pub mode: u32,
    pub crc32: u32,
    /// BLAKE3, hexadecimal.
    pub hash: String,
}

/// What an unpacking wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Manifest {
    /// The archive's SHA-256 (its folder is named by the first 32 digits).
    pub archive: String,
    /// Sorted by path, one per path.
    pub files: Vec<ManifestFile>,
}

impl Manifest {
    pub fn to_text(&self) -> String {
        let mut s = format!("{FORMAT}\narchive {}\n", self.archive);
        for f in &self.files {
            s.push_str(&format!(
                "file {} {} {:o} {:08x} {}\n",
                f.hash,
                f.size,
                f.mode,
                f.crc32,
                escape(&f.path)
            ));
        }
        s
    }

    /// Strict: anything else than what [`Manifest::to_text`] writes is no manifest.
    pub fn parse(text: &str) -> Option<Manifest> {
        let mut lines = text.strip_suffix('\n')?.split('\n');
        if lines.next()? != FORMAT {
            return None;
        }
        let archive = lines.next()?.strip_prefix("archive ")?;
        if !is_hex(archive, 64) {
            return None;
        }
        let mut files: Vec<ManifestFile> = Vec::new();
        for line in lines {
            let mut f = line.strip_prefix("file ")?.splitn(5, ' ');
            let hash = f.next()?;
            let size = f.next()?.parse().ok()?;
            let mode = u32::from_str_radix(f.next()?, 8).ok()?;
            let crc = f.next()?;
            let path = unescape(f.next()?)?;
            if !is_hex(hash, 64) || crc.len() != 8 || !safe_relative(&path) {
                return None;
            }
            if files.last().is_some_and(|l| l.path >= path) {
                return None;
            }
            files.push(ManifestFile {
                path,
                size,
                mode,
                crc32: u32::from_str_radix(crc, 16).ok()?,
                hash: hash.to_string(),
            });
        }
        Some(Manifest {
            archive: archive.to_string(),
            files,
        })
    }

    /// BLAKE3 of the manifest's text: what the unpacked folder holds, in one hash.
    pub fn digest(&self) -> String {
        blake3::hash(self.to_text().as_bytes()).to_hex().to_string()
    }

    pub fn file(&self, path: &str) -> Option<&ManifestFile> {
        self.files
            .binary_search_by(|f| f.path.as_str().cmp(path))
            .ok()
            .map(|i| &self.files[i])
    }
}

fn is_hex(s: &str, len: usize) -> bool {
    s.len() == len && s.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'))
}

/// A path the manifest may name: relative, no `.`, `..` or empty component, no NUL.
pub(crate) fn safe_relative(path: &str) -> bool {
    !path.is_empty()
        && !path.contains('\0')
        && path
            .split('/')
            .all(|c| !c.is_empty() && c != "." && c != "..")
}

fn escape(path: &str) -> String {
    path.replace('\\', "\\\\").replace('\n', "\\n")
}

fn unescape(s: &str) -> Option<String> {
    let mut out = String::with_capacity(s.len());
    let mut chars = s.chars();
    while let Some(c) = chars.next() {
        if c == '\\' {
            match chars.next()? {
                '\\' => out.push('\\'),
                'n' => out.push('\n'),
                _ => return None,
            }
        } else {
            out.push(c);
        }
    }
    Some(out)
}

/// A writer that hashes (BLAKE3) and counts what it writes.
pub(crate) struct Hashing<W> {
    pub inner: W,
    pub hasher: blake3::Hasher,
}

impl<W: Write> Write for Hashing<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.hasher.update(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

fn euid() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

/// Why a folder or file of the store cannot be trusted: another owner, or group or other
/// write permission; `None` when it can.
pub(crate) fn untrusted(meta: &std::fs::Metadata, at: &Path) -> Option<FileCheckError> {
    let me = euid();
    if meta.uid() != me {
        return Some(FileCheckError::Owner {
            path: at.to_path_buf(),
            owner: meta.uid(),
            me,
        });
    }
    if meta.mode() & 0o022 != 0 {
        return Some(FileCheckError::Writable {
            path: at.to_path_buf(),
            mode: meta.mode() & 0o7777,
        });
    }
    None
}

fn openat(dir: &File, name: &[u8], flags: i32) -> std::io::Result<File> {
    let c = std::ffi::CString::new(name)
        .map_err(|_| std::io::Error::from(std::io::ErrorKind::InvalidInput))?;
    // SAFETY: openat on a descriptor we own and a NUL-terminated name; the result is owned.
    let fd = unsafe {
        libc::openat(
            dir.as_raw_fd(),
            c.as_ptr(),
            flags | libc::O_NOFOLLOW | libc::O_CLOEXEC,
        )
    };
    if fd < 0 {
        return Err(std::io::Error::last_os_error());
    }
    // SAFETY: a descriptor just opened and owned by nobody else.
    Ok(unsafe { File::from_raw_fd(fd) })
}

/// Opens `root/rel` for reading, one component at a time without following symbolic links,
/// checking every folder from `root` down and the file itself: owned by this user, not
/// writable by group or others, the file regular. The reason otherwise, naming the path
/// and its mode.
pub(crate) fn open_checked(
    root: &Path,
    rel: &str,
) -> Result<(File, std::fs::Metadata), FileCheckError> {
    let c = std::ffi::CString::new(root.as_os_str().as_bytes()).map_err(|_| {
        FileCheckError::NulByte {
            path: root.to_path_buf(),
        }
    })?;
    // SAFETY: open on a NUL-terminated path; the result is owned.
    let fd = unsafe {
        libc::open(
            c.as_ptr(),
            // O_PATH: the folders are only walked (fstat, openat), never read; a confined
            // worker may walk the store to its FMU's folder but read no other's.
            libc::O_PATH | libc::O_DIRECTORY | libc::O_CLOEXEC,
        )
    };
    if fd < 0 {
        return Err(FileCheckError::Open {
            path: root.to_path_buf(),
            source: std::io::Error::last_os_error(),
        });
    }
    // SAFETY: a descriptor just opened and owned by nobody else.
    let mut dir = unsafe { File::from_raw_fd(fd) };
    let mut at = root.to_path_buf();
    let check = |f: &File, at: &Path| -> Result<std::fs::Metadata, FileCheckError> {
        let meta = f.metadata().map_err(|source| FileCheckError::Read {
            path: at.to_path_buf(),
            source,
        })?;
        match untrusted(&meta, at) {
            Some(why) => Err(why),
            None => Ok(meta),
        }
    };
    check(&dir, &at)?;
    let mut parts = rel.split('/').peekable();
    while let Some(part) = parts.next() {
        at.push(part);
        let last = parts.peek().is_none();
        let flags = if last {
            libc::O_RDONLY | libc::O_NONBLOCK
        } else {
            libc::O_PATH | libc::O_DIRECTORY
        };
        let f = openat(&dir, part.as_bytes(), flags).map_err(|e| {
            // A link where a folder is expected fails as "not a folder" with O_PATH.
            let link = e.raw_os_error() == Some(libc::ELOOP)
                || (e.raw_os_error() == Some(libc::ENOTDIR)
                    && std::fs::symlink_metadata(&at).is_ok_and(|m| m.file_type().is_symlink()));
            let path = at.to_path_buf();
            if link {
                FileCheckError::Link { path }
            } else {
                FileCheckError::Open { path, source: e }
            }
        })?;
        let meta = check(&f, &at)?;
        if last {
            if !meta.is_file() {
                return Err(FileCheckError::NotRegular { path: at });
            }
            return Ok((f, meta));
        }
        dir = f;
    }
    Err(FileCheckError::NoFileNamed {
        path: root.to_path_buf(),
    })
}

/// Reads `f` whole (at most `max` bytes) and hashes it.
pub(crate) fn read_hashed(f: &File, max: u64) -> std::io::Result<(Vec<u8>, String)> {
    let mut bytes = Vec::new();
    f.take(max + 1).read_to_end(&mut bytes)?;
    let hash = blake3::hash(&bytes).to_hex().to_string();
    Ok((bytes, hash))
}

/// The BLAKE3 of a file's content, read in large blocks (the hash's SIMD needs them).
pub(crate) fn hash_file(mut f: &File) -> std::io::Result<(u64, String)> {
    let mut h = blake3::Hasher::new();
    let mut buf = vec![0u8; 256 << 10];
    let mut n = 0u64;
    loop {
        let k = match f.read(&mut buf) {
            Ok(0) => break,
            Ok(k) => k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        h.update(&buf[..k]);
        n += k as u64;
    }
    Ok((n, h.finalize().to_hex().to_string()))
}

/// Checks one unpacked file (`dir/<entry.path>`, opened through [`open_checked`] from
/// `root`) against its manifest entry: size, mode and hash. The reason otherwise.
pub(crate) fn verify_file(
    root: &Path,
    dir_rel: &str,
    entry: &ManifestFile,
) -> Result<(), FileCheckError> {
    let rel = format!("{dir_rel}/{}", entry.path);
    let (f, meta) = open_checked(root, &rel)?;
    let shown = root.join(&rel);
    if meta.mode() & 0o7777 != entry.mode {
        return Err(FileCheckError::Mode {
            path: shown,
            found: meta.mode() & 0o7777,
            expected: entry.mode,
        });
    }
    if meta.len() != entry.size {
        return Err(FileCheckError::Size {
            path: shown,
            found: meta.len(),
            expected: entry.size,
        });
    }
    let (n, hash) = hash_file(&f).map_err(|source| FileCheckError::Read {
        path: shown.clone(),
        source,
    })?;
    if n != entry.size || hash != entry.hash {
        return Err(FileCheckError::Content {
            path: shown,
            found: hash,
            expected: entry.hash.clone(),
        });
    }
    Ok(())
}

/// Creates a folder with exactly [`DIR_MODE`] (whatever the umask); an existing one is
/// left as it is.
pub(crate) fn make_dir(path: &Path) -> std::io::Result<()> {
    use std::os::unix::fs::{DirBuilderExt, PermissionsExt};
    match std::fs::DirBuilder::new().mode(DIR_MODE).create(path) {
        Ok(()) => std::fs::set_permissions(path, std::fs::Permissions::from_mode(DIR_MODE)),
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(e),
    }
}

/// [`make_dir`] for `rel`'s every component under `base` (which exists).
pub(crate) fn make_dirs(base: &Path, rel: &Path) -> std::io::Result<()> {
    let mut at = base.to_path_buf();
    for c in rel.components() {
        at.push(c);
        make_dir(&at)?;
    }
    Ok(())
}

/// Creates a new file with exactly `mode` (whatever the umask).
pub(crate) fn create_file(path: &Path, mode: u32) -> std::io::Result<File> {
    use std::os::unix::fs::{OpenOptionsExt, PermissionsExt};
    let f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(mode)
        .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
        .open(path)?;
    f.set_permissions(std::fs::Permissions::from_mode(mode))?;
    Ok(f)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn manifest() -> Manifest {
        Manifest {
            archive: "a".repeat(64),
            files: vec![
                ManifestFile {
                    path: "binaries/linux64/m.so".into(),
                    size: 12,
                    mode: 0o700,
                    crc32: 0xdeadbeef,
                    hash: "b".repeat(64),
                },
                ManifestFile {
                    path: "resources/a b\\c\nd".into(),
                    size: 0,
                    mode: 0o600,
                    crc32: 0,
                    hash: "c".repeat(64),
                },
            ],
        }
    }

    #[test]
    fn manifests_round_trip_and_damaged_ones_are_none() {
        let m = manifest();
        let text = m.to_text();
        assert_eq!(Manifest::parse(&text), Some(m.clone()));
        assert_eq!(m.file("binaries/linux64/m.so").unwrap().mode, 0o700);
        assert!(m.file("x").is_none());
        for bad in [
            text.replace("archive a", "archive A"),
            text.replace("binaries/linux64", "../linux64"),
            text.replace("binaries/linux64", "/abs"),
            text.replace(" 700 ", " 9 "),
            text.replace("deadbeef", "deadbee"),
            text.replace(FORMAT, "twinbench-unpacked 0"),
            format!("{text}junk\n"),
            text[..text.len() - 1].to_string(),
            String::new(),
        ] {
            assert_eq!(Manifest::parse(&bad), None, "{bad:?}");
        }
        // Unsorted or repeated paths.
        let mut twice = m.clone();
        twice.files.push(twice.files[0].clone());
        assert_eq!(Manifest::parse(&twice.to_text()), None);
        assert_ne!(m.digest(), twice.digest());
    }

    #[test]
    fn a_checked_open_refuses_links_foreign_modes_and_non_files() {
        use std::os::unix::fs::PermissionsExt;
        let d = super::super::store::TestDir::new();
        let root = d.path().join("store");
        make_dirs(d.path(), Path::new("store/x/sub")).unwrap();
        create_file(&root.join("x/sub/f"), FILE_MODE)
            .unwrap()
            .write_all(b"hi")
            .unwrap();
        let (_, meta) = open_checked(&root, "x/sub/f").unwrap();
        assert_eq!(meta.len(), 2);
        std::os::unix::fs::symlink(root.join("x/sub/f"), root.join("x/link")).unwrap();
        let e = open_checked(&root, "x/link").unwrap_err();
        assert!(
            matches!(&e, FileCheckError::Link { path } if path.ends_with("x/link")),
            "{e}"
        );
        let e = open_checked(&root, "x/sub").unwrap_err();
        assert!(matches!(e, FileCheckError::NotRegular { .. }), "{e}");
        std::fs::set_permissions(root.join("x"), std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = open_checked(&root, "x/sub/f").unwrap_err();
        assert!(
            matches!(&e, FileCheckError::Writable { path, mode: 0o777 } if path.ends_with("store/x")),
            "{e}"
        );
        std::fs::set_permissions(root.join("x"), std::fs::Permissions::from_mode(0o711)).unwrap();
        std::fs::set_permissions(root.join("x/sub/f"), std::fs::Permissions::from_mode(0o620))
            .unwrap();
        let e = open_checked(&root, "x/sub/f").unwrap_err();
        assert!(
            matches!(&e, FileCheckError::Writable { path, mode: 0o620 } if path.ends_with("sub/f")),
            "{e}"
        );
    }
}

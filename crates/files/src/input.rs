//! Input files opened safely: a system, study, channel map, measurement, replay, track,
//! target or simulation file is read only when it is a regular file no larger than the
//! limit of its kind, and never more than that is read or allocated. A FIFO, a device
//! (`/dev/zero`), a socket or a folder is refused before a byte is read: opening does not
//! wait for a FIFO's writer, and a device cannot feed the reader until memory runs out.
//!
//! The limits (`docs/robustness.md`, "Input files"):
//! - [`Limit::CONFIG`], 16 MiB: system, study and channel-map files (an SSP package's
//!   descriptions, unpacked from the package, have the limit of an FMU's description);
//! - [`Limit::DATA`], 2 GiB: measurements (CSV, MDF 4), replays, tracks, target speeds,
//!   simulation results.

use std::fs::File;
use std::io::{Error, ErrorKind, Read};
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::Path;

/// The largest input of a kind, in bytes, with the kind's name for messages.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Limit {
    pub bytes: u64,
    pub what: &'static str,
}

impl Limit {
    /// System, study and channel-map files; SSP descriptions and parameter sets.
    pub const CONFIG: Limit = Limit {
        bytes: 16 << 20,
        what: "a configuration file",
    };
    /// Measurements, replays, tracks, target speeds, simulation results.
    pub const DATA: Limit = Limit {
        bytes: 2 << 30,
        what: "a data file",
    };
}

fn refuse(path: &Path, kind: ErrorKind, why: impl std::fmt::Display) -> Error {
    Error::new(kind, format!("{}: {why}", path.display()))
}

/// What a file that is not a regular file is.
fn kind_of(t: std::fs::FileType) -> &'static str {
    if t.is_dir() {
        "a folder"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() || t.is_block_device() {
        "a device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

/// Opens `path` for reading if it is a regular file within `limit`; returns the file and its
/// size. Errors name the path and what is wrong.
pub fn open(path: &Path, limit: Limit) -> std::io::Result<(File, u64)> {
    // O_NONBLOCK: opening a FIFO does not wait for a writer (it is refused just below); for
    // a regular file it changes nothing.
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(path)
        .map_err(|e| refuse(path, e.kind(), format_args!("cannot read: {e}")))?;
    let meta = file
        .metadata()
        .map_err(|e| refuse(path, e.kind(), format_args!("cannot read: {e}")))?;
    if !meta.file_type().is_file() {
        return Err(refuse(
            path,
            ErrorKind::InvalidInput,
            format_args!(
                "is {}, not a regular file: refusing to read it",
                kind_of(meta.file_type())
            ),
        ));
    }
    if meta.len() > limit.bytes {
        return Err(too_large(path, meta.len(), limit));
    }
    Ok((file, meta.len()))
}

fn too_large(path: &Path, size: u64, limit: Limit) -> Error {
    refuse(
        path,
        ErrorKind::InvalidData,
        format_args!(
            "{} is more than the {} {} may have",
            bytes(size),
            bytes(limit.bytes),
            limit.what
        ),
    )
}

/// What is wrong, without the path every error of this module begins with: for an error
/// type that prints the path itself (`path: reason`), so that the path is said once.
pub fn reason(e: &Error, path: &Path) -> String {
    let text = e.to_string();
    match text.strip_prefix(&format!("{}: ", path.display())) {
        Some(rest) => rest.to_string(),
        None => text,
    }
}

/// A size for messages: `16 MiB`, `2.5 GiB`, `512 bytes`.
pub fn bytes(n: u64) -> String {
    const UNITS: [(&str, u64); 3] = [("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)];
    for (unit, size) in UNITS {
        if n >= size {
            let x = n as f64 / size as f64;
            return match x.fract() == 0.0 {
                true => format!("{x:.0} {unit}"),
                false => format!("{x:.1} {unit}"),
            };
        }
    }
    format!("{n} bytes")
}

/// The whole of a regular file within `limit` (read with the bound: a file that grows while
/// it is read is refused, not followed).
pub fn read(path: &Path, limit: Limit) -> std::io::Result<Vec<u8>> {
    let (file, size) = open(path, limit)?;
    let mut bytes = Vec::with_capacity(size as usize);
    file.take(limit.bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(|e| refuse(path, e.kind(), format_args!("cannot read: {e}")))?;
    if bytes.len() as u64 > limit.bytes {
        return Err(too_large(path, bytes.len() as u64, limit));
    }
    Ok(bytes)
}

/// [`read`] as UTF-8 text; the error names the byte where the text stops being UTF-8. A
/// UTF-8 byte order mark is dropped.
pub fn read_to_string(path: &Path, limit: Limit) -> std::io::Result<String> {
    let mut bytes = read(path, limit)?;
    if bytes.starts_with(b"\xEF\xBB\xBF") {
        bytes.drain(..3);
    }
    String::from_utf8(bytes).map_err(|e| {
        refuse(
            path,
            ErrorKind::InvalidData,
            format_args!(
                "is not a text file (byte {} is not UTF-8)",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const SMALL: Limit = Limit {
        bytes: 8,
        what: "a test file",
    };

    #[test]
    fn regular_files_within_the_limit_are_read() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.txt");
        std::fs::write(&p, "\u{feff}12345").unwrap();
        assert_eq!(read_to_string(&p, SMALL).unwrap(), "12345");
        std::fs::write(&p, "123456789").unwrap();
        let e = read(&p, SMALL).unwrap_err();
        assert!(matches!(e.kind(), ErrorKind::InvalidData), "{e}");
        assert!(
            e.to_string()
                .contains("9 bytes is more than the 8 bytes a test file may have"),
            "{e}"
        );
        std::fs::write(&p, b"ab\xffcd").unwrap();
        let e = read_to_string(&p, SMALL).unwrap_err();
        assert!(matches!(e.kind(), ErrorKind::InvalidData), "{e}");
        assert!(
            e.to_string()
                .contains("is not a text file (byte 2 is not UTF-8)"),
            "{e}"
        );
    }

    #[test]
    fn fifos_devices_and_folders_are_refused_without_waiting() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        // No writer: a plain open would block here for ever.
        let e = read(&fifo, Limit::CONFIG).unwrap_err();
        assert!(matches!(e.kind(), ErrorKind::InvalidInput), "{e}");
        assert!(
            e.to_string().contains("is a FIFO, not a regular file"),
            "{e}"
        );
        let e = read(Path::new("/dev/zero"), Limit::DATA).unwrap_err();
        assert!(matches!(e.kind(), ErrorKind::InvalidInput), "{e}");
        assert!(
            e.to_string()
                .contains("/dev/zero: is a device, not a regular file"),
            "{e}"
        );
        let e = read(dir.path(), Limit::CONFIG).unwrap_err();
        assert!(matches!(e.kind(), ErrorKind::InvalidInput), "{e}");
        assert!(e.to_string().contains("is a folder"), "{e}");
        let e = read(&dir.path().join("missing"), Limit::CONFIG).unwrap_err();
        assert!(matches!(e.kind(), ErrorKind::NotFound), "{e}");
        assert!(
            e.to_string().contains("missing: cannot read: No such file"),
            "{e}"
        );
        let why = reason(&e, &dir.path().join("missing"));
        assert!(why.starts_with("cannot read: No such file"), "{why}");
    }

    #[test]
    fn sizes_read_as_people_write_them() {
        assert_eq!(bytes(512), "512 bytes");
        assert_eq!(bytes(16 << 20), "16 MiB");
        assert_eq!(bytes(5 << 29), "2.5 GiB");
    }
}

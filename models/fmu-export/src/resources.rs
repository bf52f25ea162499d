//! Files a model reads: a resource's text, a data file parsed once per process and shared by
//! every instance that names it, the path a String parameter names, and the wrap of a
//! distance on a closed lap (the lookups of distance-based resources: track, target).

use crate::error::ModelError;
use std::any::Any;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// `s.rem_euclid(length)` for a distance on a closed lap, bit for bit, without libm's
/// `fmod` in the usual cases (it runs every step): s itself inside the lap, s − length on
/// the next lap (exact by Sterbenz's lemma, length ≤ s < 2·length).
#[inline]
pub fn wrap_distance(s: f64, length: f64) -> f64 {
    if (0.0..length).contains(&s) {
        s
    } else if s >= length && s < 2.0 * length {
        s - length
    } else {
        s.rem_euclid(length)
    }
}

/// The data lines of a model's CSV resource (a track, a target): each as (its line number
/// in the file, from 1; its text trimmed), blank lines and `#` comments skipped. The first
/// is the header.
pub fn csv_lines(text: &str) -> impl Iterator<Item = (usize, &str)> {
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim()))
        .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'))
}

/// The path a String parameter names: an absolute path or a `file://` URI. A relative path
/// is refused: the host resolves it (the orchestrator against the system file's folder).
pub fn parameter_path(parameter: &str, value: &str) -> Result<PathBuf, ModelError> {
    let path = if value.starts_with("file:") {
        resource_dir_from_uri(value).map_err(|e| ModelError::new(format!("'{parameter}': {e}")))?
    } else {
        PathBuf::from(value)
    };
    if !path.is_absolute() {
        return Err(ModelError::new(format!(
            "'{parameter}' = \"{}\" is a relative path; give an absolute path or a file:// URI (twinbench resolves a relative path in a system file against the file's folder)",
            tb_files::excerpt(value)
        )));
    }
    Ok(path)
}

/// Files parsed once per process, by the parsed type, the path, its size and modification
/// time (an edited file is read again).
type SharedFiles = HashMap<
    (
        std::any::TypeId,
        PathBuf,
        u64,
        Option<std::time::SystemTime>,
    ),
    Arc<dyn Any + Send + Sync>,
>;

/// A data file parsed once per process and shared by every instance that names it (and kept
/// across re-initialisation and fmi2Reset): `parse(path, text)` runs on the first request.
pub fn shared_file<T: Any + Send + Sync>(
    path: &Path,
    parse: impl FnOnce(&Path, &str) -> Result<T, ModelError>,
) -> Result<Arc<T>, ModelError> {
    static FILES: std::sync::OnceLock<Mutex<SharedFiles>> = std::sync::OnceLock::new();
    let meta = std::fs::metadata(path)
        .map_err(|e| ModelError::new(format!("cannot read {}: {e}", path.display())))?;
    let key = (
        std::any::TypeId::of::<T>(),
        path.to_path_buf(),
        meta.len(),
        meta.modified().ok(),
    );
    let files = FILES.get_or_init(Default::default);
    if let Some(hit) = files.lock().ok().and_then(|m| m.get(&key).cloned()) {
        if let Ok(t) = hit.downcast::<T>() {
            return Ok(t);
        }
    }
    let text = read_text(path)?;
    let value = Arc::new(parse(path, &text)?);
    if let Ok(mut m) = files.lock() {
        m.insert(key, value.clone());
    }
    Ok(value)
}

/// Read a text file with the path in the error message.
/// A file a parameter names, as text: a regular file within the data limit (never a FIFO,
/// which would hang the host, nor a device, which would fill its memory).
pub fn read_text(path: &Path) -> Result<String, ModelError> {
    tb_files::input::read_to_string(path, tb_files::Limit::DATA)
        .map_err(|e| ModelError::new(e.to_string()))
}

/// Decode `fmuResourceLocation` (a file URI, percent-encoded) into a folder path.
pub fn resource_dir_from_uri(uri: &str) -> Result<PathBuf, UriError> {
    // `file://host/path` names a file on another machine (N28: it was read as the local
    // path /host/path).
    if let Some(authority) = uri.strip_prefix("file://") {
        let host = authority.split('/').next().unwrap_or_default();
        if !host.is_empty() && host != "localhost" {
            return Err(UriError::OtherHost {
                uri: tb_files::excerpt(uri),
                host: tb_files::excerpt(host),
            });
        }
    }
    let rest = uri
        .strip_prefix("file://localhost/")
        .map(|r| format!("/{r}"))
        .or_else(|| uri.strip_prefix("file:///").map(|r| format!("/{r}")))
        .or_else(|| uri.strip_prefix("file:/").map(|r| format!("/{r}")))
        .ok_or_else(|| UriError::NotAFile {
            uri: uri.to_string(),
        })?;
    let bytes = rest.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| UriError::PercentEscape {
                    uri: uri.to_string(),
                    at: i,
                })?;
            out.push(hex);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    let s = String::from_utf8(out).map_err(|_| UriError::NotUtf8 {
        uri: uri.to_string(),
    })?;
    Ok(PathBuf::from(s))
}

/// Why a resource location (`fmuResourceLocation`, a `file:` parameter) names no local
/// folder.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum UriError {
    /// `uri` and `host` are shortened for the message.
    #[error(
        "'{uri}' names a file on the host '{host}': only local files (file:///path) can be read"
    )]
    OtherHost { uri: String, host: String },
    #[error("fmuResourceLocation '{uri}' is not a file URI")]
    NotAFile { uri: String },
    #[error("fmuResourceLocation '{uri}': bad percent escape at byte {at}")]
    PercentEscape { uri: String, at: usize },
    #[error("fmuResourceLocation '{uri}' is not UTF-8 after decoding")]
    NotUtf8 { uri: String },
}

#[cfg(test)]
mod tests {
    #[test]
    fn wrap_distance_is_rem_euclid_to_the_bit() {
        let length = 4284.25;
        let mut s: f64 = -3.0 * length;
        while s < 4.0 * length {
            for x in [
                s,
                s.next_up(),
                s.next_down(),
                -0.0,
                0.0,
                length,
                2.0 * length,
            ] {
                assert_eq!(
                    super::wrap_distance(x, length).to_bits(),
                    x.rem_euclid(length).to_bits(),
                    "s = {x}"
                );
            }
            s += 0.37;
        }
    }
}

//! What a confined worker may use: address space, scratch disk, open files and threads,
//! with the defaults, the setting that changes them (`--worker-limits` or
//! [`LIMITS_ENV`]), and the worker's own account of which one an FMU ran into.
//!
//! - memory: `RLIMIT_AS` (a `malloc` past it returns NULL, a Rust allocation aborts);
//! - scratch: the size of the tmpfs mounted on the scratch folder in the worker's own mount
//!   namespace (a write past it fails with `ENOSPC`), gone with the namespace;
//! - files: `RLIMIT_NOFILE`;
//! - threads: `RLIMIT_NPROC`, counted in the worker's own user namespace (the kernel does
//!   not apply it to root, whose threads the address-space limit bounds instead);
//! - processes: none; the seccomp filter refuses every new process (`fork`, `vfork`,
//!   `clone` without `CLONE_THREAD`) with `EAGAIN`, and counts the attempts
//!   ([`super::filter`]).

use super::{ConfineError, LimitsError};
use serde::{Deserialize, Serialize};

/// The environment variable that sets the limits (`memory=2G,scratch=64M,files=256,threads=64`).
pub const LIMITS_ENV: &str = "TWINBENCH_WORKER_LIMITS";

const KIB: u64 = 1024;
const MIB: u64 = 1024 * KIB;
const GIB: u64 = 1024 * MIB;

/// The limits of one confined worker.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Limits {
    /// Address space [bytes] (`RLIMIT_AS`).
    pub memory: u64,
    /// Size of the scratch folder [bytes] (a tmpfs).
    pub scratch: u64,
    /// Open files (`RLIMIT_NOFILE`).
    pub files: u64,
    /// Threads (`RLIMIT_NPROC` in the worker's user namespace).
    pub threads: u64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            memory: 4 * GIB,
            scratch: 256 * MIB,
            files: 1024,
            threads: 256,
        }
    }
}

/// Each limit's name, its bounds and whether it is a size, for parsing and messages.
const KEYS: &[(&str, u64, u64, bool)] = &[
    ("memory", 64 * MIB, 1 << 46, true),
    ("scratch", MIB, 1 << 40, true),
    ("files", 16, 1 << 20, false),
    ("threads", 1, 1 << 16, false),
];

impl Limits {
    /// The defaults with the settings of `text` (`key=value` separated by commas; sizes in
    /// bytes or with K, M, G or T: binary units).
    pub fn parse(text: &str) -> Result<Limits, LimitsError> {
        let mut l = Limits::default();
        for item in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (key, value) = item
                .split_once('=')
                .ok_or_else(|| LimitsError::NotKeyValue { item: item.into() })?;
            let key = key.trim();
            let Some(&(_, lo, hi, size)) = KEYS.iter().find(|k| k.0 == key) else {
                return Err(LimitsError::UnknownKey { key: key.into() });
            };
            let v = if size {
                parse_size(value.trim())
            } else {
                value.trim().parse::<u64>().ok()
            }
            .ok_or_else(|| LimitsError::NotANumber {
                key: key.into(),
                value: value.trim().into(),
                size,
            })?;
            if !(lo..=hi).contains(&v) {
                let shown = |x| if size { size_text(x) } else { x.to_string() };
                return Err(LimitsError::OutOfRange {
                    key: key.into(),
                    value: shown(v),
                    min: shown(lo),
                    max: shown(hi),
                });
            }
            match key {
                "memory" => l.memory = v,
                "scratch" => l.scratch = v,
                "files" => l.files = v,
                _ => l.threads = v,
            }
        }
        Ok(l)
    }

    /// The limits [`LIMITS_ENV`] sets, else the defaults.
    pub fn from_env() -> Result<Limits, LimitsError> {
        match std::env::var(LIMITS_ENV) {
            Ok(v) => Limits::parse(&v).map_err(|e| LimitsError::Environment(Box::new(e))),
            Err(_) => Ok(Limits::default()),
        }
    }

    /// The limits in words, for messages.
    pub fn describe(&self) -> String {
        format!(
            "address space {}, scratch folder {}, {} open files, {} threads, no child processes",
            size_text(self.memory),
            size_text(self.scratch),
            self.files,
            self.threads
        )
    }

    /// Sets this process's resource limits (in the worker, before anything is loaded). A
    /// limit is only ever lowered: where the system's own is lower, that one holds.
    pub(crate) fn apply(&self) -> Result<(), ConfineError> {
        for (resource, name, value) in [
            (libc::RLIMIT_AS, "RLIMIT_AS", self.memory),
            (libc::RLIMIT_NOFILE, "RLIMIT_NOFILE", self.files),
            (libc::RLIMIT_NPROC, "RLIMIT_NPROC", self.threads),
            // A crashing FMU writes no core file (into the scratch folder or a system's
            // handler).
            (libc::RLIMIT_CORE, "RLIMIT_CORE", 0),
        ] {
            let mut old = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            // SAFETY: getrlimit/setrlimit with a local structure.
            unsafe {
                if libc::getrlimit(resource, &mut old) != 0 {
                    let error = std::io::Error::last_os_error();
                    return Err(ConfineError::Call {
                        what: format!("getrlimit {name}"),
                        error,
                    });
                }
                let v = value.min(old.rlim_max);
                let new = libc::rlimit {
                    rlim_cur: v,
                    rlim_max: v,
                };
                if libc::setrlimit(resource, &new) != 0 {
                    let error = std::io::Error::last_os_error();
                    return Err(ConfineError::Call {
                        what: format!("cannot set {name} to {v}"),
                        error,
                    });
                }
            }
        }
        Ok(())
    }

    /// Which limits this worker has run into, in words (read in the worker after a failed
    /// call: its address space's peak, its scratch folder's free space, its open files, and
    /// the processes the filter refused).
    pub fn reached(&self, scratch: &std::path::Path) -> Vec<String> {
        let mut out = Vec::new();
        let attempts = super::filter::process_attempts();
        if attempts > 0 {
            out.push(format!(
                "the FMU tried to start {attempts} process{} (fork, vfork or clone), which a confined worker refuses: it runs no child processes",
                if attempts == 1 { "" } else { "es" }
            ));
        }
        let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
        let field = |name: &str| {
            status
                .lines()
                .find_map(|l| l.strip_prefix(name))
                .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        };
        if let Some(peak) = field("VmPeak:").map(|kb| kb * KIB) {
            if peak + 64 * MIB >= self.memory {
                out.push(format!(
                    "its address space reached {} of the worker's memory limit of {} (set with --worker-limits memory=… or {LIMITS_ENV})",
                    size_text(peak),
                    size_text(self.memory)
                ));
            }
        }
        if let Some(threads) = field("Threads:") {
            if threads + 2 >= self.threads {
                out.push(format!(
                    "it runs {threads} threads, the worker's limit is {} (threads=…)",
                    self.threads
                ));
            }
        }
        if let Ok(fds) = std::fs::read_dir("/proc/self/fd") {
            let open = fds.count() as u64;
            if open + 4 >= self.files {
                out.push(format!(
                    "it has {open} files open, the worker's limit is {} (files=…)",
                    self.files
                ));
            }
        }
        if let Some(free) = free_bytes(scratch) {
            if free < (self.scratch / 100).max(64 * KIB) {
                out.push(format!(
                    "its scratch folder is full: {} free of the limit of {} (scratch=…)",
                    size_text(free),
                    size_text(self.scratch)
                ));
            }
        }
        out
    }
}

/// Free bytes on the file system of `path`.
fn free_bytes(path: &std::path::Path) -> Option<u64> {
    use std::os::unix::ffi::OsStrExt;
    let c = std::ffi::CString::new(path.as_os_str().as_bytes()).ok()?;
    // SAFETY: statvfs into a zeroed local structure.
    let mut s: libc::statvfs = unsafe { std::mem::zeroed() };
    (unsafe { libc::statvfs(c.as_ptr(), &mut s) } == 0).then(|| s.f_bavail * s.f_frsize)
}

/// `2G`, `512M`, `1048576`: bytes.
fn parse_size(text: &str) -> Option<u64> {
    let (digits, unit) = match text.char_indices().find(|(_, c)| !c.is_ascii_digit()) {
        Some((i, _)) => text.split_at(i),
        None => (text, ""),
    };
    let n: u64 = digits.parse().ok()?;
    let scale = match unit.trim().trim_end_matches(['i', 'B']) {
        "" => 1,
        "K" | "k" => KIB,
        "M" | "m" => MIB,
        "G" | "g" => GIB,
        "T" | "t" => 1024 * GIB,
        _ => return None,
    };
    n.checked_mul(scale)
}

/// A size in words: `256 MiB`, `4 GiB`, `1000 bytes`.
pub fn size_text(bytes: u64) -> String {
    for (unit, scale) in [
        ("TiB", 1024 * GIB),
        ("GiB", GIB),
        ("MiB", MIB),
        ("KiB", KIB),
    ] {
        if bytes >= scale {
            let v = bytes as f64 / scale as f64;
            return if bytes.is_multiple_of(scale) {
                format!("{} {unit}", bytes / scale)
            } else {
                format!("{v:.1} {unit}")
            };
        }
    }
    format!("{bytes} bytes")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_change_only_the_limits_they_name() {
        let l = Limits::parse("memory=2G, scratch=64M").unwrap();
        assert_eq!(l.memory, 2 * GIB);
        assert_eq!(l.scratch, 64 * MIB);
        assert_eq!(l.files, Limits::default().files);
        assert_eq!(l.threads, Limits::default().threads);
        assert_eq!(Limits::parse("").unwrap(), Limits::default());
        assert_eq!(Limits::parse("files=64,threads=8").unwrap().threads, 8);
        assert_eq!(Limits::parse("scratch=1048576").unwrap().scratch, MIB);
        assert_eq!(Limits::parse("memory=3GiB").unwrap().memory, 3 * GIB);
    }

    #[test]
    fn bad_settings_name_the_key_and_what_was_expected() {
        // Each case: the setting, its kind of error, what the message says.
        type Kind = fn(&LimitsError) -> bool;
        let cases: [(&str, Kind, &str); 8] = [
            (
                "memory",
                |e| matches!(e, LimitsError::NotKeyValue { item } if item == "memory"),
                "is not key=value",
            ),
            (
                "disk=1G",
                |e| matches!(e, LimitsError::UnknownKey { key } if key == "disk"),
                "unknown limit 'disk'",
            ),
            (
                "memory=lots",
                |e| matches!(e, LimitsError::NotANumber { key, size: true, .. } if key == "memory"),
                "memory = 'lots' is not a size",
            ),
            (
                "files=1.5",
                |e| matches!(e, LimitsError::NotANumber { key, size: false, .. } if key == "files"),
                "files = '1.5' is not a whole number",
            ),
            (
                "memory=1K",
                |e| matches!(e, LimitsError::OutOfRange { key, .. } if key == "memory"),
                "memory = 1 KiB is outside [64 MiB, 64 TiB]",
            ),
            (
                "threads=0",
                |e| matches!(e, LimitsError::OutOfRange { key, .. } if key == "threads"),
                "threads = 0 is outside [1, 65536]",
            ),
            (
                "scratch=99999999999999999999",
                |e| matches!(e, LimitsError::NotANumber { key, size: true, .. } if key == "scratch"),
                "is not a size",
            ),
            (
                "scratch=18446744073709551615T",
                |e| matches!(e, LimitsError::NotANumber { key, size: true, .. } if key == "scratch"),
                "is not a size",
            ),
        ];
        for (text, kind, says) in cases {
            let e = Limits::parse(text).unwrap_err();
            assert!(kind(&e), "{text}: {e:?}");
            assert!(e.to_string().contains(says), "{text}: {e}");
        }
    }

    #[test]
    fn sizes_read_as_people_write_them() {
        assert_eq!(size_text(256 * MIB), "256 MiB");
        assert_eq!(size_text(4 * GIB), "4 GiB");
        assert_eq!(size_text(1536 * MIB), "1.5 GiB");
        assert_eq!(size_text(1000), "1000 bytes");
        assert!(Limits::default().describe().contains("no child processes"));
    }
}

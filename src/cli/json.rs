//! `--json`: stdout carries the JSON document and nothing else. An FMU run in this process
//! may print to stdout (its C code writes to file descriptor 1); with `--json` descriptor 1
//! is pointed at stderr for the whole command, and the document goes to the original
//! stdout, kept aside.

use std::fs::File;
use std::io::Write;
use std::os::fd::FromRawFd;
use std::sync::{Mutex, OnceLock};

static ORIGINAL_STDOUT: OnceLock<Mutex<File>> = OnceLock::new();

/// Keeps the original stdout for the JSON document and sends everything else written to
/// descriptor 1 to stderr. Called once, before the command runs.
pub fn protect() {
    // SAFETY: dup and dup2 on the process's standard descriptors; the duplicate is owned by
    // the File from here on.
    unsafe {
        let saved = libc::dup(1);
        if saved < 0 {
            return;
        }
        if libc::dup2(2, 1) < 0 {
            libc::close(saved);
            return;
        }
        let _ = ORIGINAL_STDOUT.set(Mutex::new(File::from_raw_fd(saved)));
    }
}

/// Writes the JSON document (and a line break) to the original stdout.
pub fn print(document: &str) -> std::io::Result<()> {
    match ORIGINAL_STDOUT.get() {
        Some(out) => {
            let mut out = out.lock().unwrap_or_else(|p| p.into_inner());
            writeln!(out, "{document}")?;
            out.flush()
        }
        None => {
            let mut out = std::io::stdout().lock();
            writeln!(out, "{document}")?;
            out.flush()
        }
    }
}

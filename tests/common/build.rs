//! Building the suite's C FMUs: one builder at a time across test processes, rebuilt only
//! when a source is newer, gcc's failures shown, the archive written.

use std::ffi::OsStr;
use std::fs::File;
use std::io::Write;
use std::path::Path;
use std::process::Command;

/// A lock on `dir/.lock` for one builder at a time across test processes, held until the
/// file is dropped.
pub fn lock(dir: &Path) -> File {
    use std::os::fd::AsRawFd;
    let lock = File::create(dir.join(".lock")).unwrap();
    // SAFETY: flock on a descriptor this function owns.
    assert_eq!(unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_EX) }, 0);
    lock
}

/// Whether `built` is there and no older than the newest of `sources` (of those there).
pub fn up_to_date(built: &Path, sources: &[&Path]) -> bool {
    let modified = |p: &Path| std::fs::metadata(p).and_then(|m| m.modified());
    let newest = sources
        .iter()
        .filter_map(|p| modified(p).ok())
        .max()
        .expect("a source");
    modified(built).is_ok_and(|t| t >= newest)
}

/// `gcc ARGS`, which must succeed (else the test fails naming `what`, with gcc's messages).
pub fn gcc<S: AsRef<OsStr>>(args: impl IntoIterator<Item = S>, what: &str) {
    let out = Command::new("gcc").args(args).output().expect("gcc runs");
    super::cli::succeeded(&out, format_args!("gcc {what}"));
}

/// A zip archive at `path` of `entries` (name, bytes), deflated.
pub fn zip(path: &Path, entries: &[(&str, &[u8])]) {
    let mut zip = zip::ZipWriter::new(File::create(path).unwrap());
    let o = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for (name, bytes) in entries {
        zip.start_file(*name, o).unwrap();
        zip.write_all(bytes).unwrap();
    }
    zip.finish().unwrap();
}

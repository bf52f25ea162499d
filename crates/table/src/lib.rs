//! The one time-series table of twinbench: named columns of `f64` with units and provenance
//! (file and line of every row, for error messages). A simulation's recording, a vehicle
//! measurement, a replayed file and a signal for bench analysis are all a [`Table`].

mod error;
mod table;

pub use error::{Result, TableError};
pub use table::Table;

use std::io::Write;
use std::path::Path;

/// Write a file atomically (temporary sibling, fsync, rename): a reader sees the old file
/// or the new one, never a part.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::create_dir_all(dir)?;
    let tmp = dir.join(format!(
        ".{}.tmp{}",
        path.file_name()
            .map(|f| f.to_string_lossy().into_owned())
            .unwrap_or_default(),
        std::process::id()
    ));
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

//! The one time-series table of twinbench: named columns of `f64` (or text) with units and
//! provenance (file and line of every row, for error messages). A simulation's recording, a
//! vehicle measurement, a replayed file and a signal for bench analysis are all a [`Table`].
//! On disk: CSV, or ASAM MDF 4 ([`mdf`]).

mod error;
pub mod mdf;
mod output;
mod table;

pub use error::{MdfError, Result, TableError};
pub use table::Table;

/// Whether a path names an MDF file (`.mf4`, `.mdf`, any case).
pub fn is_mdf(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("mf4") || e.eq_ignore_ascii_case("mdf"))
}

impl Table {
    /// Reads a table from an MDF 4 file (`.mf4`, `.mdf`) or a CSV file (anything else).
    pub fn read_any(path: &Path) -> Result<Table> {
        if is_mdf(path) {
            mdf::read(path)
        } else {
            Table::read_path(path)
        }
    }

    /// Writes the table atomically as MDF 4 (`.mf4`, `.mdf`) or CSV (anything else).
    pub fn write_any(&self, path: &Path) -> std::io::Result<()> {
        if is_mdf(path) {
            let bytes = mdf::to_bytes(self).map_err(std::io::Error::other)?;
            write_atomic(path, &bytes)
        } else {
            self.write_csv(path)
        }
    }
}

use std::path::Path;

pub use output::{check_output, remove_in_flight, write_atomic, FolderLock};

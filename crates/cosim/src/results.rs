//! Recorded signals: column-major in memory, CSV on disk (header of `instance.variable`
//! names, then a units row), written to a temporary file and renamed.

use std::io::Write;
use std::path::Path;

#[derive(Clone, Debug, Default)]
pub struct Recording {
    /// `time` first, then `instance.variable`.
    pub names: Vec<String>,
    pub units: Vec<String>,
    pub columns: Vec<Vec<f64>>,
}

impl Recording {
    pub fn new(names: Vec<String>, units: Vec<String>) -> Self {
        let columns = vec![Vec::new(); names.len()];
        Recording {
            names,
            units,
            columns,
        }
    }

    pub fn rows(&self) -> usize {
        self.columns.first().map_or(0, Vec::len)
    }

    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }

    pub fn clear(&mut self) {
        for c in &mut self.columns {
            c.clear();
        }
    }

    /// As a comparison table (names without units).
    pub fn to_table(&self, source: &str) -> Result<tb_compare::Table, tb_compare::Error> {
        tb_compare::Table::from_columns(source, self.names.clone(), self.columns.clone())
    }

    /// Write CSV atomically: nothing half-written is ever visible under `path`.
    pub fn write_csv(&self, path: &Path) -> std::io::Result<()> {
        let mut out = Vec::with_capacity(self.rows() * self.names.len() * 12 + 256);
        writeln!(out, "{}", self.names.join(","))?;
        writeln!(out, "{}", self.units.join(","))?;
        // `{}` of f64 is the shortest text that reads back to the same number.
        for r in 0..self.rows() {
            for (k, c) in self.columns.iter().enumerate() {
                if k > 0 {
                    out.push(b',');
                }
                write!(out, "{}", c[r])?;
            }
            out.push(b'\n');
        }
        write_atomic(path, &out)
    }
}

/// Write a file atomically (temporary sibling, fsync, rename).
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

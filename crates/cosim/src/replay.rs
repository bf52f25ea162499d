//! Replay of measurement channels (RLS/α and n/α modes): columns of a measurement CSV,
//! interpolated by time or by a distance signal of the system.

use super::config::{ReplayBasis, ReplayConfig};
use super::SystemError;
use std::path::PathBuf;
use tb_table::Table;

/// SI unit of the columns of the measurement format (data/README.md).
pub fn default_unit(column: &str) -> &'static str {
    match column {
        "time" => "s",
        "distance" => "m",
        "v" => "m/s",
        "a_x" | "a_y" => "m/s2",
        c if c.starts_with("Fz") => "N",
        c if c.starts_with("omega") => "rad/s",
        _ => "1",
    }
}

#[derive(Clone, Debug)]
pub struct ReplaySource {
    pub name: String,
    pub path: PathBuf,
    pub basis: ReplayBasis,
    /// The system signal giving the basis (distance mode).
    pub by: Option<String>,
    pub columns: Vec<String>,
    pub units: Vec<String>,
    /// The basis (time or distance, non-decreasing) first, then the replayed columns.
    pub table: Table,
}

impl ReplaySource {
    pub fn load(cfg: &ReplayConfig) -> Result<ReplaySource, SystemError> {
        let err = |m: String| SystemError::Replay {
            name: cfg.name.clone(),
            path: cfg.file.clone(),
            message: m,
        };
        let meas = tb_compare::Measurement::read_path(&cfg.file).map_err(|e| err(e.to_string()))?;
        let x = match cfg.basis {
            ReplayBasis::Time => meas.time().to_vec(),
            ReplayBasis::Distance => {
                if cfg.by.is_none() {
                    return Err(err("basis = \"distance\" needs `by`, the signal giving the distance (e.g. \"vehicle.distance\")".into()));
                }
                meas.distance().to_vec()
            }
        };
        if cfg.columns.is_empty() {
            return Err(err("no columns to replay".into()));
        }
        let mut data = vec![x];
        let mut units = Vec::new();
        for c in &cfg.columns {
            let col = meas
                .signal(c)
                .map_err(|e| err(e.to_string()))?
                .ok_or_else(|| err(format!("no column '{c}' in the file")))?;
            data.push(col.to_vec());
            units.push(
                cfg.units
                    .get(c)
                    .cloned()
                    .unwrap_or_else(|| default_unit(c).to_string()),
            );
        }
        let basis = match cfg.basis {
            ReplayBasis::Time => "time",
            ReplayBasis::Distance => "distance",
        };
        let mut names = vec![format!("{basis} (basis)")];
        names.extend(cfg.columns.iter().cloned());
        let table = Table::from_columns(cfg.file.display().to_string(), names, data)
            .map_err(|e| err(e.to_string()))?;
        Ok(ReplaySource {
            name: cfg.name.clone(),
            path: cfg.file.clone(),
            basis: cfg.basis,
            by: cfg.by.clone(),
            columns: cfg.columns.clone(),
            units,
            table,
        })
    }

    /// The basis values (time or distance), non-decreasing.
    #[inline]
    pub fn basis_values(&self) -> &[f64] {
        self.table.column_at(0)
    }

    /// The replayed column `c` (an index into [`ReplaySource::columns`]).
    #[inline]
    pub fn values(&self, c: usize) -> &[f64] {
        self.table.column_at(c + 1)
    }

    pub fn column_index(&self, name: &str) -> Option<usize> {
        self.columns.iter().position(|c| c == name)
    }
}

/// Linear interpolation with a moving cursor (the basis mostly moves forward); values
/// hold at the ends.
#[derive(Clone, Debug, Default)]
pub struct Cursor {
    i: usize,
}

impl Cursor {
    #[inline]
    pub fn locate(&mut self, x: &[f64], q: f64) -> (usize, f64) {
        let n = x.len();
        if n < 2 || q <= x[0] {
            self.i = 0;
            return (0, 0.0);
        }
        if q >= x[n - 1] {
            self.i = n - 2;
            return (n - 2, 1.0);
        }
        if !(x[self.i] <= q && q < x[self.i + 1]) {
            if self.i + 2 < n && x[self.i + 1] <= q && q < x[self.i + 2] {
                self.i += 1;
            } else {
                self.i = x.partition_point(|&v| v <= q).saturating_sub(1).min(n - 2);
            }
        }
        let (a, b) = (x[self.i], x[self.i + 1]);
        (self.i, if b > a { (q - a) / (b - a) } else { 0.0 })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cursor_interpolates_forward_and_backward() {
        let x = [0.0, 1.0, 2.0, 2.0, 4.0];
        let mut c = Cursor::default();
        assert_eq!(c.locate(&x, -1.0), (0, 0.0));
        assert_eq!(c.locate(&x, 0.5), (0, 0.5));
        assert_eq!(c.locate(&x, 1.5), (1, 0.5));
        assert_eq!(c.locate(&x, 3.0), (3, 0.5));
        assert_eq!(c.locate(&x, 0.25), (0, 0.25));
        assert_eq!(c.locate(&x, 9.0), (3, 1.0));
    }
}

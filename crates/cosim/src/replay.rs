//! Replay of measurement channels (RLS/α and n/α modes): columns of a measurement CSV,
//! interpolated by time or by a distance signal of the system.

use super::config::{Interpolation, ReplayBasis, ReplayConfig};
use super::SystemError;
use std::path::PathBuf;
use tb_table::Table;

#[derive(Clone, Debug)]
pub struct ReplaySource {
    pub name: String,
    pub path: PathBuf,
    pub basis: ReplayBasis,
    /// The system signal giving the basis (distance mode).
    pub by: Option<String>,
    pub columns: Vec<String>,
    /// Per column its unit; "" where neither the file, nor `units`, nor the measurement
    /// format names one (an FMPy input file): the column then takes the unit of the input
    /// it drives.
    pub units: Vec<String>,
    pub interpolation: Interpolation,
    /// Per column: hold the last row's value instead of interpolating (decided by the plan
    /// from `interpolation` and the inputs the column drives).
    pub hold: Vec<bool>,
    /// The basis (time or distance, non-decreasing) first, then the replayed columns.
    pub table: Table,
}

/// Why a replayed file cannot be replayed (in [`SystemError::Replay`], which names the
/// replay and its file).
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    #[error(transparent)]
    Measurement(#[from] tb_measurement::Error),
    #[error(transparent)]
    Table(#[from] tb_table::TableError),
    #[error("basis = \"distance\" needs `by`, the signal giving the distance (e.g. \"vehicle.distance\")")]
    DistanceWithoutBy,
    #[error("no columns to replay")]
    NoColumns,
    #[error("no column '{column}' in the file")]
    NoSignal { column: String },
    #[error("the time column '{column}' is not numeric")]
    TimeNotNumeric { column: String },
    #[error("the time column '{column}' is in '{unit}', not a unit of time (s, ms, min, h)")]
    TimeUnit { column: String, unit: String },
    #[error("line {line}: time {time} is not finite")]
    TimeNotFinite { line: u64, time: f64 },
    #[error("line {line}: time {time} after {before}: the time of an input file must not decrease (a repeated time is a step)")]
    TimeDecreases { line: u64, time: f64, before: f64 },
    #[error("no numeric column to replay besides the time")]
    NoNumericColumn,
    #[error("no column '{column}' in the file (columns: {columns})")]
    NoColumn { column: String, columns: String },
    #[error("column '{column}' is not numeric")]
    ColumnNotNumeric { column: String },
    #[error("line {line}, column '{column}': value {value} is not finite")]
    ValueNotFinite {
        line: u64,
        column: String,
        value: f64,
    },
}

impl ReplaySource {
    pub fn load(cfg: &ReplayConfig) -> Result<ReplaySource, SystemError> {
        let err = |error: ReplayError| SystemError::Replay {
            name: cfg.name.clone(),
            path: cfg.file.clone(),
            error: Box::new(error),
        };
        let (x, columns, data, file_units) = match cfg.basis {
            ReplayBasis::Time => Self::time_based(cfg).map_err(err)?,
            ReplayBasis::Distance => Self::measurement(cfg).map_err(err)?,
        };
        let units: Vec<String> = columns
            .iter()
            .zip(file_units)
            .map(|(c, declared)| {
                // A time-based file without a unit for a column named as a measurement's
                // signal (the bundled lap's CSV has no units row) is taken in the
                // measurement format's unit, as it always was; see docs/design.md.
                cfg.units
                    .get(c)
                    .cloned()
                    .or(declared)
                    .or_else(|| tb_measurement::si_unit(c).map(str::to_string))
                    .unwrap_or_default()
            })
            .collect();
        let basis = match cfg.basis {
            ReplayBasis::Time => "time",
            ReplayBasis::Distance => "distance",
        };
        let mut names = vec![format!("{basis} (basis)")];
        names.extend(columns.iter().cloned());
        let mut all = vec![x];
        all.extend(data);
        let table = Table::from_columns(cfg.file.display().to_string(), names, all)
            .map_err(|e| err(ReplayError::Table(e)))?;
        Ok(ReplaySource {
            name: cfg.name.clone(),
            path: cfg.file.clone(),
            basis: cfg.basis,
            by: cfg.by.clone(),
            hold: vec![cfg.interpolation == Interpolation::Hold; columns.len()],
            interpolation: cfg.interpolation,
            columns,
            units,
            table,
        })
    }

    /// A vehicle measurement replayed by distance (the measurement format, SI units).
    #[allow(clippy::type_complexity)]
    fn measurement(
        cfg: &ReplayConfig,
    ) -> Result<(Vec<f64>, Vec<String>, Vec<Vec<f64>>, Vec<Option<String>>), ReplayError> {
        let meas = tb_measurement::Measurement::read_path(&cfg.file)?;
        if cfg.by.is_none() {
            return Err(ReplayError::DistanceWithoutBy);
        }
        if cfg.columns.is_empty() {
            return Err(ReplayError::NoColumns);
        }
        let mut data = Vec::new();
        let mut units = Vec::new();
        for c in &cfg.columns {
            let col = meas
                .signal(c)?
                .ok_or_else(|| ReplayError::NoSignal { column: c.clone() })?;
            data.push(col.to_vec());
            // The measurement declares its signals' units (SI, converted on reading).
            units.push(meas.unit(c).map(str::to_string));
        }
        Ok((meas.distance().to_vec(), cfg.columns.clone(), data, units))
    }

    /// Any time-based file (CSV or MDF 4), as FMPy reads an input file: the `time` column
    /// (else the first), any column names, columns not replayed are not even parsed, a
    /// repeated time is a step (the value after it from that time on).
    #[allow(clippy::type_complexity)]
    fn time_based(
        cfg: &ReplayConfig,
    ) -> Result<(Vec<f64>, Vec<String>, Vec<Vec<f64>>, Vec<Option<String>>), ReplayError> {
        let wanted = |name: &str| {
            name == "time" || cfg.columns.is_empty() || cfg.columns.iter().any(|c| c == name)
        };
        let t = if tb_table::is_mdf(&cfg.file) {
            Table::read_any(&cfg.file)
        } else {
            // Only the columns replayed and the time (named so, or the first) are parsed.
            Table::read_path_keeping(&cfg.file, &|k, n| k == 0 || wanted(n))
        }?;
        let time_index = t.names().iter().position(|n| n == "time").unwrap_or(0);
        if t.is_text(time_index) {
            return Err(ReplayError::TimeNotNumeric {
                column: t.names()[time_index].clone(),
            });
        }
        let mut time = t.column_at(time_index).to_vec();
        // The time column's own unit (M8): seconds, or converted from another time unit;
        // anything else is refused rather than read as seconds.
        let time_unit = t
            .units()
            .and_then(|u| u.get(time_index))
            .map(|u| u.trim())
            .filter(|u| !u.is_empty());
        if let Some(u) = time_unit {
            let second = tb_fmi::units::lookup("s").expect("the second is a known unit");
            let def = tb_fmi::units::lookup(u).filter(|d| d.compatible(second) && d.offset == 0.0);
            let Some(def) = def else {
                return Err(ReplayError::TimeUnit {
                    column: t.names()[time_index].clone(),
                    unit: u.to_string(),
                });
            };
            if def.factor != 1.0 {
                time.iter_mut().for_each(|x| *x *= def.factor);
            }
        }
        for k in 0..time.len() {
            if !time[k].is_finite() {
                return Err(ReplayError::TimeNotFinite {
                    line: t.line_of(k),
                    time: time[k],
                });
            }
            if k > 0 && time[k] < time[k - 1] {
                return Err(ReplayError::TimeDecreases {
                    line: t.line_of(k),
                    time: time[k],
                    before: time[k - 1],
                });
            }
        }
        let columns: Vec<String> = if cfg.columns.is_empty() {
            (0..t.names().len())
                .filter(|&k| k != time_index && !t.is_text(k))
                .map(|k| t.names()[k].clone())
                .collect()
        } else {
            cfg.columns.clone()
        };
        if columns.is_empty() {
            return Err(ReplayError::NoNumericColumn);
        }
        let mut data = Vec::new();
        let mut units = Vec::new();
        for c in &columns {
            let k = t
                .names()
                .iter()
                .position(|n| n == c)
                .ok_or_else(|| ReplayError::NoColumn {
                    column: c.clone(),
                    columns: t.names().join(", "),
                })?;
            if t.is_text(k) {
                return Err(ReplayError::ColumnNotNumeric { column: c.clone() });
            }
            let col = t.column_at(k);
            if let Some(j) = col.iter().position(|x| !x.is_finite()) {
                return Err(ReplayError::ValueNotFinite {
                    line: t.line_of(j),
                    column: c.clone(),
                    value: col[j],
                });
            }
            data.push(col.to_vec());
            units.push(
                t.units()
                    .and_then(|u| u.get(k))
                    .filter(|u| !u.is_empty())
                    .cloned(),
            );
        }
        Ok((time, columns, data, units))
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

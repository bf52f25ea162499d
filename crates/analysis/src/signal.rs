//! Uniformly sampled time series: a [`Table`] (the CSV reader and the in-memory table every
//! part of twinbench shares) with one column as the time base, checked to be uniform.

use crate::error::{AnalysisError, Result};
use std::path::Path;
use tb_table::{Table, TableError};

/// Relative tolerance on the sampling step: a step that differs from the mean step by more
/// than this share is uneven sampling. Generous enough for times printed with few digits.
pub const SAMPLING_TOLERANCE: f64 = 0.01;

/// Named columns on a uniform time grid.
#[derive(Debug, Clone)]
pub struct TimeSeries {
    table: Table,
    /// Index of the time column.
    time: usize,
    /// Mean sampling step, s.
    pub dt: f64,
}

impl TimeSeries {
    /// Read a CSV file; `time` names the time column.
    pub fn read_csv(path: &Path, time: &str) -> Result<TimeSeries> {
        let table =
            Table::read_path(path).map_err(|e| table_error(e, &path.display().to_string()))?;
        TimeSeries::from_table(table, time)
    }

    /// Parse CSV text; `source` names it in error messages.
    pub fn parse_csv(text: &str, source: &str, time: &str) -> Result<TimeSeries> {
        let table =
            Table::from_reader(text.as_bytes(), source).map_err(|e| table_error(e, source))?;
        TimeSeries::from_table(table, time)
    }

    /// A table with `time` as its time base (checked: increasing, uniform).
    pub fn from_table(table: Table, time: &str) -> Result<TimeSeries> {
        let index = table
            .names()
            .iter()
            .position(|n| n == time)
            .ok_or_else(|| AnalysisError::MissingColumn {
                file: table.source().to_string(),
                column: time.to_string(),
                available: table.names().join(", "),
            })?;
        let mut ts = TimeSeries {
            table,
            time: index,
            dt: 0.0,
        };
        ts.check_time()?;
        Ok(ts)
    }

    /// Build from columns in memory (e.g. a simulation); checks the time grid.
    pub fn from_columns(
        source: &str,
        time: Vec<f64>,
        columns: Vec<(String, Vec<f64>)>,
    ) -> Result<TimeSeries> {
        for (name, c) in &columns {
            if c.len() != time.len() {
                return Err(AnalysisError::InvalidParameter(format!(
                    "{source}: column '{name}' has {} samples, time has {}",
                    c.len(),
                    time.len()
                )));
            }
        }
        let (mut names, mut data): (Vec<String>, Vec<Vec<f64>>) = columns.into_iter().unzip();
        names.insert(0, "time".to_string());
        data.insert(0, time);
        let table = Table::from_columns(source, names, data)
            .map_err(|e| AnalysisError::InvalidParameter(e.to_string()))?;
        TimeSeries::from_table(table, "time")
    }

    /// The table behind the series.
    pub fn table(&self) -> &Table {
        &self.table
    }

    /// Where the data came from (file name), for error messages.
    pub fn source(&self) -> &str {
        self.table.source()
    }

    /// The time base, s.
    pub fn time(&self) -> &[f64] {
        self.table.column_at(self.time)
    }

    fn check_time(&mut self) -> Result<()> {
        let time = self.time();
        let n = time.len();
        if n < 2 {
            return Err(AnalysisError::TooFewSamples {
                file: self.source().to_string(),
                samples: n,
                nperseg: 2,
            });
        }
        let line_of = |i: usize| self.table.line_of(i) as usize;
        for i in 1..n {
            if time[i] <= time[i - 1] || !time[i].is_finite() {
                return Err(AnalysisError::NonIncreasingTime {
                    file: self.source().to_string(),
                    line: line_of(i),
                });
            }
        }
        let mean = (time[n - 1] - time[0]) / (n - 1) as f64;
        for i in 1..n {
            let dt = time[i] - time[i - 1];
            if (dt - mean).abs() > SAMPLING_TOLERANCE * mean {
                return Err(AnalysisError::UnevenSampling {
                    file: self.source().to_string(),
                    line: line_of(i),
                    dt,
                    mean,
                });
            }
        }
        self.dt = mean;
        Ok(())
    }

    /// Sampling frequency, Hz.
    pub fn fs(&self) -> f64 {
        1.0 / self.dt
    }

    pub fn len(&self) -> usize {
        self.table.len()
    }

    pub fn is_empty(&self) -> bool {
        self.table.is_empty()
    }

    pub fn names(&self) -> &[String] {
        self.table.names()
    }

    /// A column by name, or an error naming the file and the columns there are.
    pub fn column(&self, name: &str) -> Result<&[f64]> {
        self.table
            .names()
            .iter()
            .position(|n| n == name)
            .map(|k| self.table.column_at(k))
            .ok_or_else(|| AnalysisError::MissingColumn {
                file: self.source().to_string(),
                column: name.to_string(),
                available: self.table.names().join(", "),
            })
    }
}

/// A table reader's error in this crate's words (file, line, what is wrong).
fn table_error(e: TableError, source: &str) -> AnalysisError {
    let csv = |line: u64, message: String| AnalysisError::Csv {
        file: source.to_string(),
        line: line as usize,
        message,
    };
    match e {
        TableError::Io { source: io, .. } => AnalysisError::Io {
            file: source.to_string(),
            source: io,
        },
        TableError::Empty { .. } => csv(
            1,
            "the file is empty (expected a header row and data)".into(),
        ),
        TableError::Malformed {
            row, column, value, ..
        } => csv(row, format!("column '{column}': '{value}' is not a number")),
        TableError::RaggedRow {
            row,
            expected,
            found,
            ..
        } => csv(
            row,
            format!("{found} fields, but the header has {expected} columns"),
        ),
        TableError::DuplicateColumn { column, .. } => {
            csv(1, format!("column name '{column}' appears twice"))
        }
        other => AnalysisError::InvalidParameter(other.to_string()),
    }
}

//! Uniformly sampled time series read from CSV (a header row of column names, then numbers;
//! comma- or semicolon-separated; `#` lines are comments).

use crate::error::{AnalysisError, Result};
use std::path::Path;

/// Relative tolerance on the sampling step: a step that differs from the mean step by more
/// than this share is uneven sampling. Generous enough for times printed with few digits.
pub const SAMPLING_TOLERANCE: f64 = 0.01;

/// Named columns on a uniform time grid.
#[derive(Debug, Clone)]
pub struct TimeSeries {
    /// Where the data came from (file name), for error messages.
    pub source: String,
    pub time: Vec<f64>,
    /// Mean sampling step, s.
    pub dt: f64,
    names: Vec<String>,
    columns: Vec<Vec<f64>>,
}

impl TimeSeries {
    /// Read a CSV file; `time` names the time column.
    pub fn read_csv(path: &Path, time: &str) -> Result<TimeSeries> {
        let file = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| AnalysisError::Io {
            file: file.clone(),
            source,
        })?;
        TimeSeries::parse_csv(&text, &file, time)
    }

    /// Parse CSV text; `source` names it in error messages.
    pub fn parse_csv(text: &str, source: &str, time: &str) -> Result<TimeSeries> {
        let csv_err = |line: usize, message: String| AnalysisError::Csv {
            file: source.to_string(),
            line,
            message,
        };
        let mut lines = text
            .lines()
            .enumerate()
            .map(|(i, l)| (i + 1, l.trim()))
            .filter(|(_, l)| !l.is_empty() && !l.starts_with('#'));
        let (header_line, header) = lines
            .next()
            .ok_or_else(|| csv_err(1, "the file is empty (expected a header row)".into()))?;
        let sep = if header.contains(',') || !header.contains(';') {
            ','
        } else {
            ';'
        };
        let names: Vec<String> = header
            .split(sep)
            .map(|s| s.trim().trim_matches('"').to_string())
            .collect();
        if names.iter().any(|n| n.is_empty()) {
            return Err(csv_err(
                header_line,
                "empty column name in the header".into(),
            ));
        }
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); names.len()];
        for (line, l) in lines {
            let fields: Vec<&str> = l.split(sep).collect();
            if fields.len() != names.len() {
                return Err(csv_err(
                    line,
                    format!(
                        "{} fields, but the header has {} columns",
                        fields.len(),
                        names.len()
                    ),
                ));
            }
            for (k, f) in fields.iter().enumerate() {
                let v: f64 = f.trim().parse().map_err(|_| {
                    csv_err(
                        line,
                        format!("column '{}': '{}' is not a number", names[k], f.trim()),
                    )
                })?;
                columns[k].push(v);
            }
        }
        let mut ts = TimeSeries {
            source: source.to_string(),
            time: Vec::new(),
            dt: 0.0,
            names,
            columns,
        };
        let time_values = ts.column(time)?.to_vec();
        ts.set_time(time_values, header_line)?;
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
        let (names, columns) = columns.into_iter().unzip();
        let mut ts = TimeSeries {
            source: source.to_string(),
            time: Vec::new(),
            dt: 0.0,
            names,
            columns,
        };
        ts.set_time(time, 0)?;
        Ok(ts)
    }

    fn set_time(&mut self, time: Vec<f64>, header_line: usize) -> Result<()> {
        let n = time.len();
        if n < 2 {
            return Err(AnalysisError::TooFewSamples {
                file: self.source.clone(),
                samples: n,
                nperseg: 2,
            });
        }
        // Line numbers for CSV rows: header line + row index (comment lines aside).
        let line_of = |i: usize| header_line + 1 + i;
        for i in 1..n {
            if time[i] <= time[i - 1] || !time[i].is_finite() {
                return Err(AnalysisError::NonIncreasingTime {
                    file: self.source.clone(),
                    line: line_of(i),
                });
            }
        }
        let mean = (time[n - 1] - time[0]) / (n - 1) as f64;
        for i in 1..n {
            let dt = time[i] - time[i - 1];
            if (dt - mean).abs() > SAMPLING_TOLERANCE * mean {
                return Err(AnalysisError::UnevenSampling {
                    file: self.source.clone(),
                    line: line_of(i),
                    dt,
                    mean,
                });
            }
        }
        self.time = time;
        self.dt = mean;
        Ok(())
    }

    /// Sampling frequency, Hz.
    pub fn fs(&self) -> f64 {
        1.0 / self.dt
    }

    pub fn len(&self) -> usize {
        self.time.len()
    }

    pub fn is_empty(&self) -> bool {
        self.time.is_empty()
    }

    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// A column by name, or an error naming the file and the columns there are.
    pub fn column(&self, name: &str) -> Result<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|k| self.columns[k].as_slice())
            .ok_or_else(|| AnalysisError::MissingColumn {
                file: self.source.clone(),
                column: name.to_string(),
                available: self.names.join(", "),
            })
    }
}

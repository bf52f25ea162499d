//! The vehicle measurement (format of `data/README.md`): a CSV sampled in time, one header
//! row, SI units.
//!
//! Required columns (by name): `time`, `v`, `Fz_fl`, `Fz_fr`, `Fz_rl`, `Fz_rr`. `distance`
//! is taken from its column when present, otherwise integrated from `v` over `time` by the
//! trapezoid rule starting at 0. Other columns (`a_x`, `a_y`, pedals, wheel speeds) are kept
//! and can be required by the caller with [`Measurement::require`].
//!
//! Rejected, with the 1-based line in the file and the column: a NaN or Inf anywhere, a time
//! that does not strictly increase, a distance that decreases (equal is allowed: standstill).

use crate::error::{Error, Result};
use std::path::Path;
use tb_table::Table;

/// Columns that must be present in a measurement.
pub const REQUIRED_COLUMNS: [&str; 6] = ["time", "v", "Fz_fl", "Fz_fr", "Fz_rl", "Fz_rr"];

/// Where the distance came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DistanceSource {
    /// The file's `distance` column.
    Column,
    /// Integrated from `v` (trapezoid), appended to the table as `distance`.
    IntegratedFromSpeed,
}

/// A validated measurement.
#[derive(Debug, Clone)]
pub struct Measurement {
    table: Table,
    time: usize,
    distance: usize,
    distance_source: DistanceSource,
}

impl Measurement {
    /// Reads and validates a measurement CSV.
    pub fn read_path(path: impl AsRef<Path>) -> Result<Self> {
        Self::from_table(Table::read_path(path)?)
    }

    /// Validates a table as a measurement.
    pub fn from_table(mut table: Table) -> Result<Self> {
        for c in REQUIRED_COLUMNS {
            table.require(c)?;
        }
        // Every number finite (text columns aside: labels a logger writes); report the
        // earliest row (then the leftmost column).
        let first_bad = (0..table.names().len())
            .filter(|&c| !table.is_text(c))
            .filter_map(|c| {
                table
                    .column_at(c)
                    .iter()
                    .position(|v| !v.is_finite())
                    .map(|r| (r, c))
            })
            .min();
        if let Some((r, c)) = first_bad {
            return Err(table.non_finite(c, r).into());
        }
        let time = table.require_index("time")?;
        check_increasing_time(&table, time)?;
        let (distance, distance_source) = match table.find("distance")? {
            Some(d) => (d, DistanceSource::Column),
            None => {
                let d = cumulative_trapezoid(table.column_at(time), table.require("v")?);
                table.push_column("distance", d)?;
                (table.names().len() - 1, DistanceSource::IntegratedFromSpeed)
            }
        };
        check_distance_forward(&table, distance)?;
        Ok(Self {
            table,
            time,
            distance,
            distance_source,
        })
    }

    /// The underlying table (all columns, including an integrated `distance`).
    pub fn table(&self) -> &Table {
        &self.table
    }

    /// Time [s].
    pub fn time(&self) -> &[f64] {
        self.table.column_at(self.time)
    }

    /// Distance driven [m].
    pub fn distance(&self) -> &[f64] {
        self.table.column_at(self.distance)
    }

    /// Where [`Measurement::distance`] came from.
    pub fn distance_source(&self) -> DistanceSource {
        self.distance_source
    }

    /// A column by name, or `Ok(None)`.
    pub fn signal(&self, name: &str) -> Result<Option<&[f64]>> {
        Ok(self.table.column(name)?)
    }

    /// A column by name, or a missing-column error (for callers that need e.g. the pedals).
    pub fn require(&self, name: &str) -> Result<&[f64]> {
        Ok(self.table.require(name)?)
    }
}

/// Strictly increasing time, else an error naming the first offending line.
pub(crate) fn check_increasing_time(table: &Table, col: usize) -> Result<()> {
    let t = table.column_at(col);
    match t.windows(2).position(|w| w[1] <= w[0]) {
        None => Ok(()),
        Some(i) => Err(Error::NonIncreasingTime {
            file: table.source().into(),
            row: table.line_of(i + 1),
            column: table.name_at(col).into(),
            previous: t[i],
            value: t[i + 1],
        }),
    }
}

/// Non-decreasing distance, else an error naming the first offending line.
pub(crate) fn check_distance_forward(table: &Table, col: usize) -> Result<()> {
    check_forward(table.column_at(col), |i| {
        (
            table.source().into(),
            table.line_of(i),
            table.name_at(col).into(),
        )
    })
}

pub(crate) fn check_forward(
    d: &[f64],
    locate: impl Fn(usize) -> (String, u64, String),
) -> Result<()> {
    match d.windows(2).position(|w| w[1] < w[0]) {
        None => Ok(()),
        Some(i) => {
            let (file, row, column) = locate(i + 1);
            Err(Error::DistanceBackwards {
                file,
                row,
                column,
                previous: d[i],
                value: d[i + 1],
            })
        }
    }
}

/// Cumulative trapezoid integral of `y` over `x`, starting at 0.
pub fn cumulative_trapezoid(x: &[f64], y: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(x.len());
    cumulative_trapezoid_into(x, y, &mut out);
    out
}

/// As [`cumulative_trapezoid`], into a reused buffer.
pub fn cumulative_trapezoid_into(x: &[f64], y: &[f64], out: &mut Vec<f64>) {
    out.clear();
    if x.is_empty() {
        return;
    }
    let mut acc = 0.0;
    out.push(acc);
    for i in 1..x.len().min(y.len()) {
        acc += 0.5 * (y[i] + y[i - 1]) * (x[i] - x[i - 1]);
        out.push(acc);
    }
}

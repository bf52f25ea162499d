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
use tb_table::{Table, TableError};

/// Columns that must be present in a measurement.
pub const REQUIRED_COLUMNS: [&str; 6] = ["time", "v", "Fz_fl", "Fz_fr", "Fz_rl", "Fz_rr"];

/// Every signal a channel map can name: the required ones, the distance, the accelerations,
/// the pedals and the wheel speeds (`data/README.md`).
pub const SIGNALS: [&str; 15] = [
    "time",
    "distance",
    "v",
    "a_x",
    "a_y",
    "Fz_fl",
    "Fz_fr",
    "Fz_rl",
    "Fz_rr",
    "accel_pedal",
    "brake_pedal",
    "omega_fl",
    "omega_fr",
    "omega_rl",
    "omega_rr",
];

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
    /// Reads and validates a measurement file (MDF 4 or CSV; declared units converted to
    /// SI), its channels under twinbench's names.
    pub fn read_path(path: impl AsRef<Path>) -> Result<Self> {
        Self::load(path.as_ref(), &ChannelMap::default())
    }

    /// Validates a table as a measurement.
    pub fn from_table(mut table: Table) -> Result<Self> {
        for c in REQUIRED_COLUMNS {
            if table.find(c)?.is_none() {
                return Err(missing_signal(&table, c));
            }
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

    /// The unit of a signal as the format declares it (SI, [`si_unit`]: the file's units
    /// were converted to it); None for a column the format does not know (its file's unit,
    /// if any, was not converted, so it is not vouched for).
    pub fn unit(&self, signal: &str) -> Option<&'static str> {
        si_unit(signal)
    }

    /// A column by name, or a missing-column error (for callers that need e.g. the pedals).
    pub fn require(&self, name: &str) -> Result<&[f64]> {
        Ok(self.table.require(name)?)
    }
}

/// A required signal the table lacks, with the channel map entry that would supply it: the
/// column that differs only in case (`time = "Time"`), else the closest names.
fn missing_signal(table: &Table, signal: &str) -> Error {
    let names = table.names();
    let same_but_case = names.iter().find(|n| n.eq_ignore_ascii_case(signal));
    let hint = match same_but_case {
        Some(n) => format!(
            "the column `{n}` differs only in case: map it with `{signal} = \"{n}\"` in the channel map ([channels] of `lap --channels`, [measurement.channels] in a study)"
        ),
        None => format!(
            "map the file's channel to it with `{signal} = \"<channel>\"` in the channel map ([channels] of `lap --channels`, [measurement.channels] in a study); closest columns: {}",
            tb_files::names::closest(
                signal,
                names.iter().map(String::as_str),
                3
            )
            .join(", ")
        ),
    };
    Error::MissingSignal {
        file: table.source().into(),
        signal: signal.into(),
        available: names.join(", "),
        hint,
    }
}

/// Strictly increasing time, else an error naming the first offending line.
pub fn check_increasing_time(table: &Table, col: usize) -> Result<()> {
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
pub fn check_distance_forward(table: &Table, col: usize) -> Result<()> {
    check_forward(table.column_at(col), |i| {
        (
            table.source().into(),
            table.line_of(i),
            table.name_at(col).into(),
        )
    })
}

pub fn check_forward(d: &[f64], locate: impl Fn(usize) -> (String, u64, String)) -> Result<()> {
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

/// The SI unit twinbench expects of a measurement signal, if it knows the signal.
pub fn si_unit(signal: &str) -> Option<&'static str> {
    Some(match signal {
        "time" => "s",
        "distance" => "m",
        "v" => "m/s",
        "a_x" | "a_y" => "m/s2",
        "accel_pedal" | "brake_pedal" => "1",
        s if s.starts_with("Fz") => "N",
        s if s.starts_with("omega") => "rad/s",
        _ => return None,
    })
}

/// Which channel of a file each twinbench signal is (`v = "GPS_Speed"`, ...); unmapped
/// signals are looked up under their own name.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(transparent)]
pub struct ChannelMap(pub std::collections::BTreeMap<String, String>);

impl ChannelMap {
    /// A map file: a `[channels]` table of `signal = "channel"`.
    pub fn read_path(path: &Path) -> Result<ChannelMap> {
        #[derive(serde::Deserialize)]
        #[serde(deny_unknown_fields)]
        struct File {
            channels: ChannelMap,
        }
        let text =
            tb_files::input::read_to_string(path, tb_files::Limit::CONFIG).map_err(|source| {
                Error::Table(TableError::Io {
                    path: path.to_path_buf(),
                    source,
                })
            })?;
        let f: File = toml::from_str(&text)
            .map_err(|e| Error::ChannelMap(format!("{}: {e}", path.display())))?;
        f.channels.check(&path.display().to_string())?;
        Ok(f.channels)
    }

    /// Every key is a signal twinbench knows ([`SIGNALS`]): `speed = "GPS_Speed"` is refused
    /// with the keys a map can have, not ignored until `v` is found missing. `source` names
    /// the map (its file, or the study) in the message.
    pub fn check(&self, source: &str) -> Result<()> {
        for key in self.0.keys() {
            if !SIGNALS.contains(&key.as_str()) {
                use tb_files::names::{closest, edit_distance};
                let near = closest(key, SIGNALS, 1)
                    .into_iter()
                    .find(|c| edit_distance(key, c) <= 2.max(key.len() / 3));
                return Err(Error::ChannelMap(format!(
                    "{source}: channel map: unknown signal `{key}`{} (the signals a map names: {})",
                    match near {
                        Some(c) => format!(" (did you mean `{c}`?)"),
                        None => String::new(),
                    },
                    SIGNALS.join(", ")
                )));
            }
        }
        Ok(())
    }
}

impl Measurement {
    /// Reads a measurement in its own format (MDF 4 or CSV), its channels renamed to
    /// twinbench's signals by `map` and converted from the units the file declares (MDF 4
    /// channel units, a CSV units row) to SI; then validated as [`Measurement::from_table`]
    /// does. A missing channel, an unknown or incompatible unit name the file and channel.
    pub fn load(path: &Path, map: &ChannelMap) -> Result<Self> {
        let file = path.display().to_string();
        map.check(&format!("channel map for {file}"))?;
        let mut table = Table::read_any(path)?;
        // Looked up among the file's own names (a map that swaps two channels works, and a
        // missing channel is told with the file's channels, not the renamed ones).
        let original: Vec<String> = table.names().to_vec();
        let mut renames: Vec<(usize, String)> = Vec::new();
        for (signal, channel) in &map.0 {
            let i = original.iter().position(|n| n == channel).ok_or_else(|| {
                Error::MissingChannel {
                    file: file.clone(),
                    signal: signal.clone(),
                    channel: channel.clone(),
                    closest: tb_files::names::closest(
                        channel,
                        original.iter().map(String::as_str),
                        3,
                    )
                    .join(", "),
                    available: original.join(", "),
                }
            })?;
            if let Some((_, other)) = renames.iter().find(|(k, _)| *k == i) {
                return Err(Error::ChannelMap(format!(
                    "{file}: the channel map gives channel `{channel}` to two signals, `{other}` and `{signal}`"
                )));
            }
            renames.push((i, signal.clone()));
        }
        table.rename_many(&renames)?;
        let in_file = |e: Error| file_channels(e, map);
        to_si(&mut table, &file, map).map_err(in_file)?;
        Self::from_table(table).map_err(in_file)
    }
}

/// An error about a column that the channel map renamed names the file's own channel (what
/// the user sees in the file), not twinbench's signal.
fn file_channels(mut e: Error, map: &ChannelMap) -> Error {
    match &mut e {
        Error::Table(TableError::NonFinite { column, .. })
        | Error::Table(TableError::Malformed { column, .. })
        | Error::NonIncreasingTime { column, .. }
        | Error::DistanceBackwards { column, .. } => {
            if let Some(channel) = map.0.get(column.as_str()) {
                *column = channel.clone();
            }
        }
        _ => {}
    }
    e
}

/// Converts every known signal from its declared unit to SI (no unit declared: SI assumed).
fn to_si(table: &mut Table, file: &str, map: &ChannelMap) -> Result<()> {
    let Some(units) = table.units().map(<[String]>::to_vec) else {
        return Ok(());
    };
    for (i, declared) in units.iter().enumerate() {
        let name = table.name_at(i).to_string();
        let Some(target) = si_unit(&name) else {
            continue;
        };
        let declared = declared.trim();
        if declared.is_empty() || declared == target || table.is_text(i) {
            continue;
        }
        let channel = map.0.get(&name).cloned().unwrap_or(name.clone());
        let what = if channel == name {
            format!("channel `{name}`")
        } else {
            format!("channel `{channel}` ({name})")
        };
        let from = tb_fmi::units::lookup(declared).ok_or_else(|| {
            Error::Unit(format!(
                "{file}: {what}: unknown unit '{declared}' (known: {})",
                tb_fmi::units::UNITS
                    .iter()
                    .map(|u| u.name)
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?;
        let to = tb_fmi::units::lookup(target).expect("SI units are in the table");
        if !from.compatible(to) {
            return Err(Error::Unit(format!(
                "{file}: {what}: unit '{declared}' cannot be converted to '{target}'"
            )));
        }
        let (scale, offset) = (
            from.factor / to.factor,
            (from.offset - to.offset) / to.factor,
        );
        for x in table.values_mut(i) {
            *x = scale * *x + offset;
        }
        table.set_unit(i, target);
    }
    Ok(())
}

//! ASAM MDF 4 (`.mf4`) in and out, through the `mdf4-rs` crate.
//!
//! Reading: every channel group's master channel is its time; the channels of all groups
//! become columns on one time base, that of the group with the most samples (the other
//! groups are interpolated linearly onto it, held at their ends). Channel units become the
//! table's units row; conversions stored in the file are applied. A channel name that
//! appears in two groups keeps its first group's values.
//!
//! Writing: one channel group, `time` as the master channel, every numeric column as a
//! 64-bit float channel with its unit (text columns are not written).

use crate::error::{Result, TableError};
use crate::Table;
use mdf4_rs::{DataType, DecodedValue, MdfWriter, MDF};
use std::path::Path;

fn mdf_error(path: &Path, what: impl std::fmt::Display) -> TableError {
    TableError::Shape(format!("{}: MDF 4: {what}", path.display()))
}

fn number(v: &Option<DecodedValue>) -> f64 {
    match v {
        Some(DecodedValue::Float(x)) => *x,
        Some(DecodedValue::SignedInteger(i)) => *i as f64,
        Some(DecodedValue::UnsignedInteger(u)) => *u as f64,
        _ => f64::NAN,
    }
}

/// One channel group: its time and its channels (name, unit, values).
struct Group {
    time: Vec<f64>,
    channels: Vec<(String, String, Vec<f64>)>,
}

/// Reads an MDF 4 file into a table (see the module's documentation).
pub fn read(path: &Path) -> Result<Table> {
    // A regular file within the data limit (the crate would read whatever the path gives,
    // a device included): opened and checked here, and the crate reads that same open file
    // through /proc, so it cannot be swapped in between.
    let (file, _) =
        tb_files::input::open(path, tb_files::Limit::DATA).map_err(|source| TableError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    use std::os::fd::AsRawFd;
    let opened = format!("/proc/self/fd/{}", file.as_raw_fd());
    let mdf = MDF::from_file(&opened).map_err(|e| mdf_error(path, e))?;
    drop(file);
    let mut groups = Vec::new();
    for g in mdf.channel_groups() {
        let mut time = None;
        let mut channels = Vec::new();
        for c in g.channels() {
            let name = c
                .name()
                .map_err(|e| mdf_error(path, e))?
                .unwrap_or_default();
            let unit = c
                .unit()
                .map_err(|e| mdf_error(path, e))?
                .unwrap_or_default();
            let values: Vec<f64> = c
                .values()
                .map_err(|e| mdf_error(path, format!("channel '{name}': {e}")))?
                .iter()
                .map(number)
                .collect();
            // Master channel (cn_type 2, or 3 virtual master) with time synchronisation.
            if matches!(c.block().channel_type, 2 | 3) && time.is_none() {
                time = Some(values);
            } else if !name.is_empty() {
                channels.push((name, unit, values));
            }
        }
        if let Some(time) = time {
            if !channels.is_empty() {
                groups.push(Group { time, channels });
            }
        }
    }
    let base = groups
        .iter()
        .max_by_key(|g| g.time.len())
        .ok_or_else(|| mdf_error(path, "no channel group with a time channel and data"))?;
    let time = base.time.clone();
    let mut names = vec!["time".to_string()];
    let mut units = vec!["s".to_string()];
    let mut columns = vec![time.clone()];
    for g in &groups {
        let same = g.time == time;
        for (name, unit, values) in &g.channels {
            if names.contains(name) {
                continue;
            }
            names.push(name.clone());
            units.push(unit.clone());
            columns.push(if same {
                values.clone()
            } else {
                time.iter()
                    .map(|&t| interpolate(&g.time, values, t))
                    .collect()
            });
        }
    }
    Table::from_columns(path.display().to_string(), names, columns)?.with_units(units)
}

/// Linear interpolation of `y(x)` at `q`, held at the ends.
fn interpolate(x: &[f64], y: &[f64], q: f64) -> f64 {
    let n = x.len().min(y.len());
    if n == 0 {
        return f64::NAN;
    }
    if q <= x[0] {
        return y[0];
    }
    if q >= x[n - 1] {
        return y[n - 1];
    }
    let i = x[..n]
        .partition_point(|&v| v <= q)
        .saturating_sub(1)
        .min(n - 2);
    let (a, b) = (x[i], x[i + 1]);
    if b > a {
        y[i] + (q - a) / (b - a) * (y[i + 1] - y[i])
    } else {
        y[i]
    }
}

/// The table as MDF 4 bytes: `time` (the first column) is the master channel.
pub fn to_bytes(table: &Table) -> Result<Vec<u8>> {
    let err = |e: mdf4_rs::Error| TableError::Shape(format!("{}: MDF 4: {e}", table.source()));
    let mut w = MdfWriter::in_memory();
    w.init_mdf_file().map_err(err)?;
    let cg = w.add_channel_group(None, |_| {}).map_err(err)?;
    let numeric: Vec<usize> = (0..table.names().len())
        .filter(|&i| !table.is_text(i))
        .collect();
    let units = table.units();
    let mut prev: Option<String> = None;
    for (k, &i) in numeric.iter().enumerate() {
        let name = table.name_at(i).to_string();
        let cn = w
            .add_channel(&cg, prev.as_deref(), |ch| {
                ch.data_type = DataType::FloatLE;
                ch.name = Some(name.clone());
                ch.bit_count = 64;
            })
            .map_err(err)?;
        if k == 0 {
            w.set_time_channel(&cn).map_err(err)?;
        }
        if let Some(u) = units.and_then(|u| u.get(i)).filter(|u| !u.is_empty()) {
            w.set_channel_unit(&cn, u).map_err(err)?;
        }
        prev = Some(cn);
    }
    w.start_data_block_for_cg(&cg, 0).map_err(err)?;
    let mut record = Vec::with_capacity(numeric.len());
    for r in 0..table.len() {
        record.clear();
        record.extend(
            numeric
                .iter()
                .map(|&i| DecodedValue::Float(table.column_at(i)[r])),
        );
        w.write_record(&cg, &record).map_err(err)?;
    }
    w.finish_data_block(&cg).map_err(err)?;
    w.finalize().map_err(err)?;
    Ok(w.into_inner().into_inner())
}

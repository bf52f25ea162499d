//! ASAM MDF 4 (`.mf4`) in and out, through the `mdf4-rs` crate.
//!
//! Reading: every channel group's master channel is its time; the channels of all groups
//! become columns on one time base, that of the group with the most samples (the other
//! groups are interpolated linearly onto it, held at their ends). Channel units become the
//! table's units row; conversions stored in the file are applied. A channel name that
//! appears in two groups keeps its first group's values. Only numbers are read: channels of
//! variable length, strings and byte arrays, and channels with a conversion to text are
//! skipped (`check::reads_channel`).
//!
//! The file is untrusted input: it is read once (a regular file within the data limit),
//! its block graph is checked (`mdf/check.rs`: links inside the file at block headers, no
//! cycle, bounded work and memory) and only then handed to the crate, as an in-memory copy
//! of the bytes checked. A panic inside the crate that the check did not foresee is caught and
//! becomes an error naming the file.
//!
//! Writing: one channel group, `time` as the master channel, every numeric column as a
//! 64-bit float channel with its unit (text columns are not written).

use crate::error::{Result, TableError};
use crate::Table;
use mdf4_rs::{DataType, DecodedValue, MdfWriter, MDF};
use std::collections::HashSet;
use std::io::Write;
use std::path::Path;

mod check;
pub use crate::error::MdfError;
pub use check::{MAX_CELLS, MAX_FORMULA, MAX_METADATA, MAX_WORK};

fn mdf_error(name: &str, what: impl std::fmt::Display) -> TableError {
    TableError::Shape(format!("{name}: MDF 4: {what}"))
}

/// A refusal of the check, or a failed copy, naming the file.
fn refused(name: &str) -> impl FnOnce(MdfError) -> TableError + '_ {
    move |source| TableError::Mdf {
        file: name.to_string(),
        source,
    }
}

fn number(v: &Option<DecodedValue>) -> f64 {
    match v {
        Some(DecodedValue::Float(x)) => *x,
        Some(DecodedValue::SignedInteger(i)) => *i as f64,
        Some(DecodedValue::UnsignedInteger(u)) => *u as f64,
        _ => f64::NAN,
    }
}

/// The data type as its number in the file, 255 for one the crate does not know.
fn type_code(t: &DataType) -> u8 {
    match t {
        DataType::Unknown(()) => 255,
        t => t.to_u8(),
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
    // a device included), read once: the bytes checked are the bytes the crate reads.
    let bytes =
        tb_files::input::read(path, tb_files::Limit::DATA).map_err(|source| TableError::Io {
            path: path.to_path_buf(),
            source,
        })?;
    let name = path.display().to_string();
    check::check(&bytes).map_err(refused(&name))?;
    let file = in_memory(&bytes).map_err(refused(&name))?;
    drop(bytes);
    read_checked(&file, &name)
}

/// Reads MDF 4 bytes into a table named `name` (in errors too), with the same checks as
/// [`read`].
pub fn read_bytes(bytes: &[u8], name: &str) -> Result<Table> {
    check::check(bytes).map_err(refused(name))?;
    let file = in_memory(bytes).map_err(refused(name))?;
    read_checked(&file, name)
}

/// The checked bytes as an anonymous in-memory file (`memfd_create`): the crate opens files
/// by path only, and through `/proc/self/fd/N` it reads exactly these bytes, which nobody
/// else can change.
fn in_memory(bytes: &[u8]) -> std::result::Result<std::fs::File, MdfError> {
    use std::os::fd::FromRawFd;
    // SAFETY: a plain system call with a NUL-terminated name; the descriptor it returns is
    // owned by the File from here on.
    let fd = unsafe { libc::memfd_create(c"twinbench-mdf".as_ptr(), libc::MFD_CLOEXEC) };
    if fd < 0 {
        return Err(MdfError::InMemory(std::io::Error::last_os_error()));
    }
    let mut file = unsafe { std::fs::File::from_raw_fd(fd) };
    file.write_all(bytes).map_err(MdfError::InMemory)?;
    Ok(file)
}

/// Reads a checked file through the crate. A panic inside the crate (a damage the check
/// does not know of) becomes an error naming the file.
fn read_checked(file: &std::fs::File, name: &str) -> Result<Table> {
    use std::os::fd::AsRawFd;
    let opened = format!("/proc/self/fd/{}", file.as_raw_fd());
    let groups = std::panic::catch_unwind(|| read_groups(&opened, name)).map_err(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        mdf_error(
            name,
            format!("the MDF reader (mdf4-rs) failed on this file: {why}"),
        )
    })??;
    table(groups, name)
}

/// The channel groups with a time channel and data, as the crate reads them.
fn read_groups(opened: &str, name: &str) -> Result<Vec<Group>> {
    let mdf = MDF::from_file(opened).map_err(|e| mdf_error(name, e))?;
    let mut groups = Vec::new();
    for g in mdf.channel_groups() {
        let mut time = None;
        let mut channels = Vec::new();
        for c in g.channels() {
            let b = c.block();
            let conversion = b.conversion.as_ref().map(|cc| cc.conversion_type.to_u8());
            if !check::reads_channel(b.channel_type, type_code(&b.data_type), conversion) {
                continue;
            }
            let name_of = c
                .name()
                .map_err(|e| mdf_error(name, e))?
                .unwrap_or_default();
            let unit = c
                .unit()
                .map_err(|e| mdf_error(name, e))?
                .unwrap_or_default();
            let values: Vec<f64> = c
                .iter_values()
                .and_then(|v| v.map(|x| x.map(|x| number(&x))).collect())
                .map_err(|e| mdf_error(name, format!("channel '{name_of}': {e}")))?;
            // Master channel (cn_type 2, or 3 virtual master) with time synchronisation.
            if matches!(b.channel_type, 2 | 3) && time.is_none() {
                time = Some(values);
            } else if !name_of.is_empty() {
                channels.push((name_of, unit, values));
            }
        }
        if let Some(time) = time {
            if !channels.is_empty() {
                groups.push(Group { time, channels });
            }
        }
    }
    Ok(groups)
}

/// The table of the groups: on the time base of the longest.
fn table(groups: Vec<Group>, name: &str) -> Result<Table> {
    let base = groups
        .iter()
        .max_by_key(|g| g.time.len())
        .ok_or_else(|| mdf_error(name, "no channel group with a time channel and data"))?;
    let time = base.time.clone();
    let mut names = vec!["time".to_string()];
    let mut units = vec!["s".to_string()];
    let mut columns = vec![time.clone()];
    let mut seen: HashSet<String> = names.iter().cloned().collect();
    for g in &groups {
        let same = g.time == time;
        for (channel, unit, values) in &g.channels {
            if !seen.insert(channel.clone()) {
                continue;
            }
            names.push(channel.clone());
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
    Table::from_columns(name.to_string(), names, columns)?.with_units(units)
}

/// Linear interpolation of `y(x)` at `q`, held at the ends.
fn interpolate(x: &[f64], y: &[f64], q: f64) -> f64 {
    let n = x.len().min(y.len());
    // A time that is not a number has no place on the other time base (NaN fails every
    // comparison below, and with one sample the search below has no interval).
    if n == 0 || q.is_nan() {
        return f64::NAN;
    }
    if n == 1 || q <= x[0] {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolation_takes_nan_times_and_single_samples() {
        // Found by the mdf4 fuzz target: a NaN time on the base and a group of one sample
        // indexed past the group's end (fuzz/corpus/mdf4/crash-interpolate-nan-time.mf4).
        assert!(interpolate(&[1.0], &[5.0], f64::NAN).is_nan());
        assert_eq!(interpolate(&[1.0], &[5.0], 3.0), 5.0);
        assert_eq!(interpolate(&[f64::NAN], &[5.0], 3.0), 5.0);
        assert!(interpolate(&[0.0, 1.0], &[0.0, 2.0], f64::NAN).is_nan());
        assert_eq!(
            interpolate(&[0.0, f64::NAN, 2.0], &[0.0, 1.0, 2.0], 1.5),
            0.0
        );
        assert_eq!(interpolate(&[0.0, 1.0], &[0.0, 2.0], 0.25), 0.5);
        assert!(interpolate(&[], &[], 1.0).is_nan());
    }

    #[test]
    fn a_panic_inside_the_crate_is_an_error_naming_the_file() {
        // The last line of defence, without the check: a data link past the end of the file
        // makes mdf4-rs 0.3.0 index out of bounds.
        let t = Table::from_columns(
            "lap",
            vec!["time".into(), "v".into()],
            vec![vec![0.0, 1.0], vec![2.0, 3.0]],
        )
        .unwrap();
        let mut b = to_bytes(&t).unwrap();
        let dg = u64::from_le_bytes(b[88..96].try_into().unwrap()) as usize;
        let past = b.len() as u64 + 4096;
        b[dg + 40..dg + 48].copy_from_slice(&past.to_le_bytes());
        assert!(matches!(check::check(&b), Err(MdfError::PastEnd { .. })));
        let file = in_memory(&b).unwrap();
        let e = read_checked(&file, "lap.mf4").unwrap_err().to_string();
        assert!(
            e.starts_with("lap.mf4: MDF 4: the MDF reader (mdf4-rs) failed on this file: "),
            "{e}"
        );
    }
}

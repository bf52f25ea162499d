//! Stages "record", "report", "checks" and the replays' distance basis: what reads the
//! system's signals besides the connections, and [`Reader`], the declaration of what each
//! reader fetches and when (libcosim's observers). The master derives from the readers
//! which outputs it reads after every step and which only at recorded steps: a new reader
//! declares itself here and is fed, nothing else to keep in step.

use super::instances::{default_record, Units};
use super::{Check, ConnectionDef, Endpoint, SignalTable, Stop};
use crate::config::SystemFile;
use crate::{invalid, SystemError};
use tb_fmi::ScalarType;

/// When a reader needs its signals.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cadence {
    /// After every macro step (connections, the stop condition, a replay's basis).
    EveryStep,
    /// At the steps the recording keeps (every `decimation`-th, and the last).
    Recorded,
}

/// Something that reads exchange slots while a run goes on.
#[derive(Clone, Debug, PartialEq)]
pub struct Reader {
    /// What it is, for a reader of the plan (`connections`, `stop condition`, ...).
    pub what: &'static str,
    pub slots: Vec<usize>,
    pub cadence: Cadence,
}

/// Every reader of a plan's slots.
pub(super) fn readers(
    connections: &[ConnectionDef],
    stop: &Stop,
    replay_basis: &[Option<usize>],
    record: &[usize],
) -> Vec<Reader> {
    let mut readers = vec![Reader {
        what: "connections",
        slots: connections.iter().map(|c| c.from_slot).collect(),
        cadence: Cadence::EveryStep,
    }];
    if let Stop::When { condition, .. } = stop {
        readers.push(Reader {
            what: "stop condition",
            slots: vec![condition.slot],
            cadence: Cadence::EveryStep,
        });
    }
    readers.push(Reader {
        what: "replay distance basis",
        slots: replay_basis.iter().flatten().copied().collect(),
        cadence: Cadence::EveryStep,
    });
    readers.push(Reader {
        what: "recording",
        slots: record.to_vec(),
        cadence: Cadence::Recorded,
    });
    readers
}

/// Stage "record": the recorded signals' slots and column names (as listed, or every
/// output and replayed column).
pub(super) fn record(
    file: &SystemFile,
    units: Units<'_>,
    signals: &mut SignalTable,
    ctx_file: &str,
) -> Result<(Vec<usize>, Vec<String>), SystemError> {
    let names = match file.record.signals.is_empty() {
        // An FMI 3.0 array listed by its name records each of its elements.
        false => file
            .record
            .signals
            .iter()
            .flat_map(|n| match units.array_elements(n) {
                e if e.is_empty() => vec![n.clone()],
                e => e,
            })
            .collect(),
        true => default_record(units),
    };
    let mut record = Vec::with_capacity(names.len());
    // A set of the names so far (a scan per name was quadratic for 100k aliases, M11).
    let mut seen = std::collections::HashSet::with_capacity(names.len());
    for n in names.iter() {
        if !seen.insert(n.as_str()) || n == "time" {
            return Err(invalid(
                ctx_file,
                format!("record: '{n}' is listed twice (a result file has one column per name)"),
            ));
        }
        let e = units.endpoint(&format!("{ctx_file}: record"), n)?;
        record.push(signals.slot(&e, n));
    }
    Ok((record, names))
}

/// Stage "report": the FMU variables read at the end of a run for its summary.
pub(super) fn report(
    file: &SystemFile,
    units: Units<'_>,
    ctx_file: &str,
) -> Result<Vec<(String, Endpoint)>, SystemError> {
    let ctx = format!("{ctx_file}: experiment.report");
    let mut report = Vec::new();
    for n in &file.experiment.report {
        let e = units.endpoint(&ctx, n)?;
        match &e {
            Endpoint::Fmu {
                ty: ScalarType::String,
                ..
            } => return Err(invalid(&ctx, format!("'{n}' is a String, not a number"))),
            Endpoint::Replay { .. } => {
                return Err(invalid(
                    &ctx,
                    format!("'{n}' is a replayed column; report FMU variables"),
                ))
            }
            Endpoint::Fmu { .. } => {}
        }
        report.push((n.clone(), e));
    }
    Ok(report)
}

/// Stage "checks": signals that must agree after initialisation.
pub(super) fn checks(
    file: &SystemFile,
    units: Units<'_>,
    ctx_file: &str,
) -> Result<Vec<Check>, SystemError> {
    let mut checks = Vec::new();
    for (k, c) in file.checks.iter().enumerate() {
        let ctx = format!("{ctx_file}: check {}", k + 1);
        if c.equal.len() < 2 {
            return Err(invalid(&ctx, "`equal` needs two or more signals"));
        }
        if !(c.relative_tolerance.is_finite() && c.relative_tolerance >= 0.0) {
            return Err(invalid(
                &ctx,
                format!(
                    "relative_tolerance must be a non-negative number, got {}",
                    c.relative_tolerance
                ),
            ));
        }
        let mut signals = Vec::new();
        for n in &c.equal {
            let e = units.endpoint(&ctx, n)?;
            match &e {
                Endpoint::Fmu {
                    ty: ScalarType::Real | ScalarType::Integer | ScalarType::Enumeration,
                    ..
                } => {}
                _ => {
                    return Err(invalid(
                        &ctx,
                        format!("'{n}' is not a numeric FMU variable"),
                    ))
                }
            }
            signals.push((n.clone(), e));
        }
        checks.push(Check {
            signals,
            tolerance: c.relative_tolerance,
            why: c.why.clone(),
        });
    }
    Ok(checks)
}

/// The slot of the signal each distance-based replay follows (None: by time).
pub(super) fn replay_basis(
    units: Units<'_>,
    signals: &mut SignalTable,
    ctx_file: &str,
) -> Result<Vec<Option<usize>>, SystemError> {
    let mut basis = Vec::with_capacity(units.replays.len());
    for r in units.replays {
        let Some(by) = &r.by else {
            basis.push(None);
            continue;
        };
        let ctx = format!("{ctx_file}: replay '{}'", r.name);
        let e = units.endpoint(&ctx, by)?;
        if let Endpoint::Replay { .. } = e {
            return Err(invalid(&ctx, "a replay cannot be driven by another replay"));
        }
        if let Endpoint::Fmu {
            ty: ScalarType::String,
            ..
        } = e
        {
            return Err(invalid(&ctx, format!("'{by}' is a String, not a distance")));
        }
        basis.push(Some(signals.slot(&e, by)));
    }
    Ok(basis)
}

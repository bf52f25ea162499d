//! What a run of the bench and its comparison need beside the libraries, shared by the
//! command line and the Python package: setting a parameter by its system name, the lap
//! time of a run, a simulation compared with a measurement file, and an error as one line.

use anyhow::Context;
use std::path::Path;
use tb_compare::{
    ChannelMap, CompareSettings, Comparison, Measurement, PreparedMeasurement, Table, Workspace,
};
use tb_cosim::{Plan, Simulation};

/// Sets a parameter of a run by its system name, checked against its variable (type,
/// range); a relative path is relative to the working directory.
pub fn set_parameter(
    system: &Plan,
    sim: &mut Simulation,
    name: &str,
    value: &toml::Value,
) -> anyhow::Result<()> {
    let slot = system.parameter(name)?;
    let v = slot.value_from_toml(value, &format!("parameter \"{name}\""))?;
    sim.set(
        &slot,
        slot.resolve_path(v, &tb_files::absolute(Path::new("."))),
    );
    Ok(())
}

/// The bench's lap time of a run: a reported `*.lap_time` signal (the vehicle interpolates
/// the line crossing inside its step), else the simulated time when the run stopped on a
/// condition, else none.
pub fn lap_time(summary: &tb_cosim::RunSummary, plan: &tb_cosim::Plan) -> Option<f64> {
    summary
        .reported
        .iter()
        .find(|(n, _)| n.ends_with(".lap_time"))
        .map(|r| r.1)
        .or(match plan.stop {
            tb_cosim::Stop::When { .. } => Some(summary.simulated_time),
            tb_cosim::Stop::Time(_) => None,
        })
}

/// A simulation (as a table) against a measurement file: what `compare` prints, and what
/// the Python package's `compare` returns.
pub fn compare_table(
    sim: &Table,
    measurement: &std::path::Path,
    channels: Option<&std::path::Path>,
    signals: &[String],
    settings: &CompareSettings,
) -> anyhow::Result<Comparison> {
    let signals: Vec<&str> = signals
        .iter()
        .map(|s| s.trim())
        .filter(|s| !s.is_empty())
        .collect();
    anyhow::ensure!(!signals.is_empty(), "--signals names no signal");
    let map = match channels {
        Some(p) => ChannelMap::read_path(p)?,
        None => ChannelMap::default(),
    };
    let meas = Measurement::load(measurement, &map)?;
    let prepared =
        PreparedMeasurement::new(&meas, &signals, settings).context("preparing the measurement")?;
    prepared
        .compare(sim, &mut Workspace::new())
        .context("comparing")
}

/// An error and its causes in one line, each part said once. Errors print as
/// `path: what: why` and many also carry their cause, which prints again (`path: No such
/// file` under `path: cannot read: No such file`): the line is built from the `": "`-separated
/// parts of the error and of every cause, leaving out a part already said.
pub fn message(e: &anyhow::Error) -> String {
    let mut parts: Vec<String> = Vec::new();
    for cause in e.chain() {
        for part in cause.to_string().split(": ") {
            let part = part.trim();
            if !part.is_empty() && !parts.iter().any(|p| p == part) {
                parts.push(part.to_string());
            }
        }
    }
    parts.join(": ")
}

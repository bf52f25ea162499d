//! `twinbench compare SIM.csv MEAS.csv --signals Fz_sum,Fz_rl --cutoff 2 [--order 2]
//! [--step 1.0] [--json]`: compares a simulation result with a vehicle measurement on a
//! distance basis (paper §4.2) and prints m, intercept, R², e (Eq. 16), bias and RMS per
//! signal.

pub use crate::bench::compare_table;
use anyhow::Context;
use std::io::Write;
use std::path::PathBuf;
use tb_compare::{CompareSettings, Comparison, Table};

#[derive(clap::Args, Debug)]
pub struct CompareArgs {
    /// Simulation result, CSV or MDF 4 (`time`, `instance.variable`, ...; a distance
    /// column, or speed to integrate).
    pub sim: PathBuf,
    /// Vehicle measurement, CSV or MDF 4 (units converted to SI from its units row or its
    /// channels' units).
    pub measurement: PathBuf,
    /// The channel of each signal in the measurement: a TOML file with a `[channels]`
    /// table, `v = "GPS_Speed"`, ...
    #[arg(long, value_name = "MAP.toml")]
    pub channels: Option<PathBuf>,
    /// Signals to compare, comma separated; derived: Fz_sum, Fz_front, Fz_rear.
    #[arg(long, value_delimiter = ',', default_value = "Fz_sum")]
    pub signals: Vec<String>,
    /// Low-pass cutoff [Hz], applied alike to both (zero-phase Butterworth).
    #[arg(long, default_value_t = 2.0)]
    pub cutoff: f64,
    /// Butterworth order of one pass.
    #[arg(long, default_value_t = 2)]
    pub order: usize,
    /// Distance grid step [m].
    #[arg(long, default_value_t = 1.0)]
    pub step: f64,
    /// Least fraction of the measured distance the simulation must cover.
    #[arg(long, default_value_t = 0.9)]
    pub min_coverage: f64,
    /// Print JSON instead of a table.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: CompareArgs) -> anyhow::Result<()> {
    let settings = CompareSettings {
        cutoff_hz: args.cutoff,
        filter_order: args.order,
        distance_step_m: args.step,
        min_coverage: args.min_coverage,
        ..CompareSettings::default()
    };
    let sim = Table::read_any(&args.sim).context("reading the simulation")?;
    let cmp = compare_table(
        &sim,
        &args.measurement,
        args.channels.as_deref(),
        &args.signals,
        &settings,
    )?;
    match print(&args, &settings, &cmp) {
        // `twinbench compare ... | head` is not an error.
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        r => Ok(r?),
    }
}

fn print(args: &CompareArgs, settings: &CompareSettings, cmp: &Comparison) -> std::io::Result<()> {
    let mut out = std::io::stdout().lock();
    if args.json {
        #[derive(serde::Serialize)]
        struct Doc<'a> {
            simulation: &'a std::path::Path,
            measurement: &'a std::path::Path,
            settings: &'a CompareSettings,
            comparison: &'a Comparison,
        }
        let doc = Doc {
            simulation: &args.sim,
            measurement: &args.measurement,
            settings,
            comparison: cmp,
        };
        drop(out);
        super::json::print(&serde_json::to_string_pretty(&doc)?)?;
    } else {
        out.write_all(render_table(cmp, settings).as_bytes())?;
    }
    Ok(())
}

/// The plain-text table.
pub fn render_table(cmp: &Comparison, settings: &CompareSettings) -> String {
    let mut s = format!(
        "distance {:.1}..{:.1} m (coverage {:.1} %), step {} m, Butterworth order {} at {} Hz, zero-phase\n",
        cmp.distance_range_m[0],
        cmp.distance_range_m[1],
        cmp.coverage * 100.0,
        settings.distance_step_m,
        settings.filter_order,
        settings.cutoff_hz,
    );
    let w = cmp
        .signals
        .iter()
        .map(|c| c.signal.len())
        .max()
        .unwrap_or(0)
        .max(6);
    s += &format!(
        "{:<w$}  {:>8}  {:>11}  {:>8}  {:>8}  {:>9}  {:>10}\n",
        "signal", "m", "intercept", "R²", "e", "bias %", "RMS"
    );
    for c in &cmp.signals {
        let m = &c.metrics;
        s += &format!(
            "{:<w$}  {:>8.4}  {:>11.2}  {:>8.4}  {:>8.4}  {:>9.3}  {:>10.2}\n",
            c.signal,
            m.slope,
            m.intercept,
            m.r_squared,
            m.e,
            m.bias * 100.0,
            m.rms
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fixture(name: &str) -> PathBuf {
        PathBuf::from(env!("CARGO_MANIFEST_DIR"))
            .join("crates/compare/tests/fixtures")
            .join(name)
    }

    #[test]
    fn run_prints_and_fails_cleanly() {
        let args = CompareArgs {
            sim: fixture("pipeline_sim.csv"),
            measurement: fixture("pipeline_meas.csv"),
            channels: None,
            signals: vec!["Fz_sum".into(), "Fz_rl".into()],
            cutoff: 2.0,
            order: 2,
            step: 1.0,
            min_coverage: 0.9,
            json: true,
        };
        run(args).unwrap();
        let args = CompareArgs {
            sim: fixture("pipeline_sim.csv"),
            measurement: fixture("pipeline_meas.csv"),
            channels: None,
            signals: vec!["Fz_nope".into()],
            cutoff: 2.0,
            order: 2,
            step: 1.0,
            min_coverage: 0.9,
            json: false,
        };
        let e = format!("{:#}", run(args).unwrap_err());
        assert!(e.contains("no signal `Fz_nope`; closest: "), "{e}");
    }

    #[test]
    fn table_has_every_signal() {
        let settings = CompareSettings::default();
        let cmp = tb_compare::compare_files(
            fixture("pipeline_sim.csv"),
            fixture("pipeline_meas.csv"),
            &["Fz_sum", "Fz_front"],
            &settings,
        )
        .unwrap();
        let t = render_table(&cmp, &settings);
        assert!(t.lines().count() == 4 && t.contains("Fz_front"), "{t}");
    }
}

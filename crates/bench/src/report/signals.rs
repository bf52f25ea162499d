//! report.html's comparison of every signal the study fits, the four wheel loads too: the
//! measured lap against the twin with the initial and with the optimised parameters, over
//! distance, filtered as the comparison sees them (what e, m and bias of Tab. 1 measure).
//! Drawn as SVG text for the page only: the study's own plots stay the files they were.

use super::{points, ReportError};
use tb_compare::{PreparedMeasurement, Table, Workspace, DERIVED_SIGNALS};
use tb_optimize::Study;
use tb_plot::{LinePlot, Style};

/// Shown whether or not a step fits them: how the load spreads over the wheels is what an
/// engineer checks first.
pub const WHEEL_LOADS: [&str; 4] = ["Fz_fl", "Fz_fr", "Fz_rl", "Fz_rr"];

/// One signal's figure, or why there is none.
#[derive(Clone, Debug)]
pub enum SignalFigure {
    Plot { signal: String, svg: String },
    Missing { signal: String, why: String },
}

/// The study's compared signals in its steps' order, then the wheel loads it does not fit.
pub fn signals_to_show(study: &Study) -> Vec<String> {
    let (mut signals, _) = study.joint_signals();
    for w in WHEEL_LOADS {
        if !signals.iter().any(|s| s == w) {
            signals.push(w.to_string());
        }
    }
    signals
}

/// Whether `table` has the signal: a column, or every column of a derived sum.
fn has(table: &Table, signal: &str) -> bool {
    let column = |n: &str| matches!(table.find(n), Ok(Some(_)));
    column(signal)
        || DERIVED_SIGNALS
            .iter()
            .any(|(n, parts)| *n == signal && parts.iter().all(|p| column(p)))
}

/// The figures, in [`signals_to_show`]'s order. A signal the measurement or the twin's
/// recording lacks gets a sentence saying so instead of a plot.
pub fn figures(
    study: &Study,
    prepared: &PreparedMeasurement,
    laps: [&Table; 3],
    ws: &mut Workspace,
) -> Result<Vec<SignalFigure>, ReportError> {
    let [measured, initial, optimised] = laps;
    let mut out = Vec::new();
    for signal in signals_to_show(study) {
        let why = if !has(measured, &signal) {
            Some(format!(
                "{signal} is not in the measurement ({}): there is nothing to compare the twin with.",
                study.measurement_path.display()
            ))
        } else if !has(initial, &signal) || !has(optimised, &signal) {
            Some(format!(
                "The twin's laps do not record {signal}: add it to the study's [record] signals."
            ))
        } else {
            None
        };
        if let Some(why) = why {
            out.push(SignalFigure::Missing { signal, why });
            continue;
        }
        let plot = signal_plot(study, prepared, &signal, laps, ws)?;
        out.push(SignalFigure::Plot {
            svg: plot.svg_string()?,
            signal,
        });
    }
    Ok(out)
}

/// One signal over distance, as the Fz_sum plot of the report draws it.
fn signal_plot(
    study: &Study,
    prepared: &PreparedMeasurement,
    signal: &str,
    [measured, initial, optimised]: [&Table; 3],
    ws: &mut Workspace,
) -> Result<LinePlot, ReportError> {
    let grid = prepared.grid();
    let (rm, m) = prepared.on_grid(measured, signal, true, ws)?;
    let (ri, i) = prepared.on_grid(initial, signal, true, ws)?;
    let (ro, o) = prepared.on_grid(optimised, signal, true, ws)?;
    let unit = tb_compare::measurement::si_unit(signal)
        .filter(|u| *u != "1")
        .map(|u| format!(" [{}]", u.replace("m/s2", "m/s²")))
        .unwrap_or_default();
    Ok(LinePlot::new(
        format!(
            "{signal} over the lap, low-pass filtered at {} Hz as the comparison sees it: vehicle against twin",
            study.file.compare.cutoff_hz
        ),
        "distance [m]",
        format!("{signal}{unit}"),
    )
    .size(1200, 420)
    .styled("twin, initial parameters", &points(grid, ri, &i), Style::Faint)
    .series("twin, optimised parameters", &points(grid, ro, &o))
    .reference("vehicle (measured)", &points(grid, rm, &m)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_signal_is_there_as_a_column_or_as_the_sum_of_its_parts() {
        let names = ["time", "distance", "Fz_fl", "vehicle.Fz_fr"].map(String::from);
        let t = Table::new("lap.csv", names.to_vec(), vec![String::new(); 4]).unwrap();
        assert!(has(&t, "Fz_fl") && has(&t, "Fz_front"));
        assert!(!has(&t, "Fz_rl") && !has(&t, "Fz_sum") && !has(&t, "Fz_rear"));
    }
}

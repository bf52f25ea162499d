//! The experiment: the default experiment and twinbench's or the Open Simulation
//! Platform's annotation.

use super::error::SspImportError;
use super::importer::*;
use super::xml::*;
use crate::config::CheckConfig;
use crate::config::{Algorithm, ExperimentConfig, RecordConfig, StopConfig};
use std::collections::BTreeMap;

/// What `<ssd:DefaultExperiment>` gives: the experiment, the recording, the checks and the
/// instances' own tolerances.
pub(super) type Experiment = (
    ExperimentConfig,
    RecordConfig,
    Vec<CheckConfig>,
    BTreeMap<String, f64>,
);

/// `<ssd:DefaultExperiment>`: start and stop, the step (twinbench's annotation, else the
/// Open Simulation Platform's), and what twinbench's annotation adds (record, report,
/// checks, a stop condition).
pub(super) fn read_experiment(
    imp: &Importer<'_>,
    top: &[&Node],
    root: &Node,
) -> Result<Experiment, SspImportError> {
    let f = SSD;
    let mut tolerances = BTreeMap::new();
    let mut experiment = ExperimentConfig {
        start: 0.0,
        step: f64::NAN,
        stop: StopConfig::Time(f64::NAN),
        lap_signal: None,
        lap_count: 1.0,
        max_time: 600.0,
        report: Vec::new(),
        algorithm: Algorithm::GaussSeidel,
        order: Vec::new(),
        tolerance: None,
        step_convention: Default::default(),
    };
    let mut record = RecordConfig::default();
    let mut checks = Vec::new();
    let mut stop_time = None;
    let mut tb_stop: Option<(String, usize)> = None;
    let mut osp_step = None;
    let mut exp_line = root.line;
    for de in top.iter().filter(|n| n.name == "DefaultExperiment") {
        exp_line = de.line;
        imp.children(f, de, &[], &[])?;
        if let Some(t) = imp.f64_attr(f, de, "startTime")? {
            experiment.start = t;
        }
        stop_time = imp.f64_attr(f, de, "stopTime")?;
        for anns in de.children.iter().filter(|n| n.name == "Annotations") {
            for x in anns.children.iter().flat_map(|ann| &ann.children) {
                if x.ns == NS_OSP {
                    if let Some(fixed) = x.children.iter().find(|n| n.name == "FixedStepAlgorithm")
                    {
                        osp_step = imp.f64_attr(f, fixed, "baseStepSize")?;
                    }
                }
                if x.ns == NS_TB && x.name == "Experiment" {
                    tb_experiment(
                        imp,
                        x,
                        &mut experiment,
                        &mut record,
                        &mut checks,
                        &mut tb_stop,
                        &mut tolerances,
                    )?;
                }
            }
        }
    }
    if experiment.step.is_nan() {
        experiment.step = osp_step.ok_or_else(|| {
            imp.invalid(
                f,
                exp_line,
                "no step size: twinbench needs its own annotation (org.twinbench.experiment, stepSize) or the Open Simulation Platform's <osp:FixedStepAlgorithm baseStepSize> in <ssd:DefaultExperiment>",
            )
        })?;
    }
    experiment.stop = match (stop_time, tb_stop) {
        // A condition (a lap) is twinbench's; a time is the standard's stopTime.
        (_, Some((s, _))) if parse_double(&s).is_none() => StopConfig::Word(s),
        (Some(t), _) => StopConfig::Time(t),
        (None, Some((s, line))) => StopConfig::Time(
            parse_double(&s)
                .ok_or_else(|| imp.invalid(f, line, format!("stop=\"{s}\" is not a time")))?,
        ),
        (None, None) => {
            return Err(imp.invalid(
                f,
                exp_line,
                "no stop time: <ssd:DefaultExperiment stopTime=...> (or twinbench's annotation) is needed",
            ))
        }
    };
    Ok((experiment, record, checks, tolerances))
}

/// twinbench's experiment annotation.
pub(super) fn tb_experiment(
    imp: &Importer<'_>,
    x: &Node,
    experiment: &mut ExperimentConfig,
    record: &mut RecordConfig,
    checks: &mut Vec<CheckConfig>,
    stop: &mut Option<(String, usize)>,
    tolerances: &mut BTreeMap<String, f64>,
) -> Result<(), SspImportError> {
    let f = SSD;
    if let Some(h) = imp.f64_attr(f, x, "stepSize")? {
        experiment.step = h;
    }
    experiment.tolerance = imp.f64_attr(f, x, "tolerance")?;
    if let Some(c) = x.attr("stepConvention") {
        experiment.step_convention = crate::config::StepConvention::from_name(c)
            .map_err(|m| imp.invalid(f, x.line, m.to_string()))?;
    }
    if let Some(a) = x.attr("algorithm") {
        experiment.algorithm =
            Algorithm::from_name(a).map_err(|m| imp.invalid(f, x.line, m.to_string()))?;
    }
    if let Some(o) = x.attr("order") {
        experiment.order = o.split_whitespace().map(str::to_string).collect();
    }
    if let Some(s) = x.attr("stop") {
        *stop = Some((s.to_string(), x.line));
    }
    if let Some(m) = imp.f64_attr(f, x, "maxTime")? {
        experiment.max_time = m;
    }
    let names = |n: &Node| -> Vec<String> {
        n.children
            .iter()
            .filter(|s| s.ns == NS_TB && s.name == "Signal")
            .filter_map(|s| s.attr("name").map(str::to_string))
            .collect()
    };
    for c in x.children.iter().filter(|c| c.ns == NS_TB) {
        match c.name.as_str() {
            "Record" => {
                record.signals = names(c);
                if let Some(d) = c.attr("decimation") {
                    record.decimation = d.trim().parse().map_err(|_| {
                        imp.invalid(
                            f,
                            c.line,
                            format!("decimation=\"{d}\" is not a whole number"),
                        )
                    })?;
                }
            }
            "Report" => experiment.report.extend(names(c)),
            "Tolerance" => {
                let instance = c.attr("instance").unwrap_or_default().to_string();
                let value = imp
                    .f64_attr(f, c, "value")?
                    .ok_or_else(|| imp.invalid(f, c.line, "<tb:Tolerance> without a value"))?;
                tolerances.insert(instance, value);
            }
            "Check" => checks.push(CheckConfig {
                equal: names(c),
                relative_tolerance: imp.f64_attr(f, c, "relativeTolerance")?.unwrap_or(0.005),
                why: c.attr("why").map(str::to_string),
            }),
            _ => {}
        }
    }
    Ok(())
}

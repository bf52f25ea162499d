//! The command line's other jobs: compare, pack, export-twin, realtime-check.

use pyo3::prelude::*;
use std::path::PathBuf;

use crate::errors::{error, TwinbenchError};

/// Compares named columns (little-endian float64 bytes each) with a measurement file;
/// returns the comparison as JSON.
#[pyfunction]
#[pyo3(signature = (names, columns, measurement, signals, cutoff_hz, filter_order, distance_step_m, min_coverage, channels=None))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn compare(
    py: Python<'_>,
    names: Vec<String>,
    columns: Vec<Vec<u8>>,
    measurement: PathBuf,
    signals: Vec<String>,
    cutoff_hz: f64,
    filter_order: usize,
    distance_step_m: f64,
    min_coverage: f64,
    channels: Option<PathBuf>,
) -> PyResult<String> {
    py.detach(move || -> anyhow::Result<String> {
        let columns: Vec<Vec<f64>> = columns
            .iter()
            .map(|b| {
                b.chunks_exact(8)
                    .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
                    .collect()
            })
            .collect();
        let sim = tb_table::Table::from_columns("simulation", names, columns)?;
        let settings = tb_compare::CompareSettings {
            cutoff_hz,
            filter_order,
            distance_step_m,
            min_coverage,
            ..tb_compare::CompareSettings::default()
        };
        let cmp = tb_bench::bench::compare_table(
            &sim,
            &measurement,
            channels.as_deref(),
            &signals,
            &settings,
        )?;
        Ok(serde_json::to_string(&cmp)?)
    })
    .map_err(error)
}

/// Packs twinbench's FMUs (`vehicle`, `driver`, `dyno`, `edu`, or those named) into `out`
/// (default: the folder `twinbench pack` writes to); returns their paths.
#[pyfunction]
#[pyo3(signature = (out=None, models=None))]
pub(crate) fn pack(
    py: Python<'_>,
    out: Option<PathBuf>,
    models: Option<Vec<String>>,
) -> PyResult<Vec<PathBuf>> {
    let out = out.unwrap_or_else(tb_bench::pack::default_fmu_dir);
    let models = models.unwrap_or_default();
    py.detach(|| tb_bench::pack::pack(&models, &out))
        .map_err(error)
}

/// The fitted twin of the study result at `result` handed on into `out` (as `twinbench
/// export-twin`): FMUs with the answer as start values (FMI `versions`, 2 and/or 3), SSP,
/// SSV, the system file and the parameter table; returns the summary as JSON.
#[pyfunction]
#[pyo3(signature = (result, out, versions))]
pub(crate) fn export_twin(
    py: Python<'_>,
    result: PathBuf,
    out: PathBuf,
    versions: Vec<u32>,
) -> PyResult<String> {
    let mut v = Vec::new();
    for x in versions {
        v.push(
            tb_bench::pack::FmiVersion::parse(&x.to_string()).ok_or_else(|| {
                TwinbenchError::new_err(format!("fmi: {x} is not an FMI version (2 or 3)"))
            })?,
        );
    }
    v.sort();
    v.dedup();
    let ex = py
        .detach(|| {
            tb_bench::export_twin::export_twin(
                &result,
                &out,
                &tb_bench::export_twin::ExportOptions { versions: v },
            )
        })
        .map_err(error)?;
    serde_json::to_string(&ex).map_err(error)
}

/// `twinbench realtime-check` of an FMU, or of every FMU of a bench (a `.toml` system):
/// the report as JSON (a list of `{instance, report}` for a bench). `worker` is the
/// `twinbench` executable the FMU runs in (only it counts allocations).
#[pyfunction]
#[pyo3(signature = (fmu, worker, step=None, duration=None, input=None, passes=10, budget=None, instructions=false, isolate="confined", timeout=600.0, preload=Vec::new()))]
#[allow(clippy::too_many_arguments)]
pub(crate) fn realtime_check(
    py: Python<'_>,
    fmu: PathBuf,
    worker: PathBuf,
    step: Option<f64>,
    duration: Option<f64>,
    input: Option<PathBuf>,
    passes: u32,
    budget: Option<f64>,
    instructions: bool,
    isolate: &str,
    timeout: f64,
    preload: Vec<PathBuf>,
) -> PyResult<String> {
    let mode = match isolate {
        "confined" => tb_cosim::isolated::confine::Mode::Confined,
        "crash-only" => tb_cosim::isolated::confine::Mode::CrashOnly,
        other => {
            return Err(TwinbenchError::new_err(format!(
                "isolate={other:?}: expected \"confined\" or \"crash-only\""
            )))
        }
    };
    let o = tb_bench::realtime_check::Options {
        fmu: fmu.clone(),
        step,
        duration,
        input,
        passes,
        budget,
        instructions,
        mode,
        timeout,
        preload,
        worker_exe: Some(worker),
    };
    let json = py.detach(|| -> anyhow::Result<String> {
        if fmu.extension().is_some_and(|e| e == "toml") {
            Ok(serde_json::to_string(
                &tb_bench::realtime_check::check_bench(&fmu, &o)?,
            )?)
        } else {
            Ok(serde_json::to_string(&tb_bench::realtime_check::check(
                &o,
            )?)?)
        }
    });
    json.map_err(error)
}

/// Take `root` as a mirror of the coordinator's files (a cluster worker's copy of a
/// study, each file at the coordinator's absolute path below it): names in the files
/// below it resolve inside it, and digests name the files as the coordinator does.
#[pyfunction]
pub(crate) fn register_mirror(root: PathBuf) {
    tb_files::register_mirror(&root);
}

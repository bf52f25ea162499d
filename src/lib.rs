//! twinbench, the command line ([`cli`]: one module per subcommand) over the library
//! `tb-bench`, whose modules are re-exported here under the paths they always had
//! (`twinbench::pack`, `twinbench::study`, ...): the test suite and other callers keep them.
//! The Python package uses `tb-bench` directly, never `cli`.
//!
//! The libraries: `tb-bench` (registry, pack, lap, report, study, validate, export-twin,
//! realtime-check), `tb-fmi` (FMI vocabulary and import), `tb-cosim` (system, plan, master,
//! backends, results), `tb-compare` (distance-based comparison), `tb-optimize` (studies),
//! `tb-analysis` (modal analysis, identification), `tb-plot` (plots); the models under
//! `models/` over the `fmu-export` framework. `docs/design.md` maps them.

pub use tb_bench::{
    bench, export_twin, lap, pack, realtime_check, registry, report, run_fmu, study, validate,
};

pub mod cli;

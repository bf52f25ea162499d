//! twinbench, the command line over the libraries:
//!
//! - [`registry`]: the models twinbench ships (one list for packing and the native backend);
//! - [`pack`]: builds the model crates and writes FMI 2.0 Co-Simulation FMUs;
//! - [`lap`]: a new lap for the packed FMUs from a measurement (target, track, system, study);
//! - [`report`]: Tab. 1 and plots of an optimisation study, from its stored results;
//! - [`bench`]: setting a parameter, a run's lap time, a comparison, an error's message;
//! - [`study`]: an optimisation study run to its files (result, report, checkpoint);
//! - [`validate`]: the fitted twin on a lap it was not fitted on;
//! - [`export_twin`]: the fitted twin handed on (FMUs with its start values, SSP, SSV, a
//!   system file, a parameter table);
//! - [`cli`]: one module per subcommand, over the modules above (the Python package uses
//!   them directly, never `cli`).
//!
//! The libraries: `tb-fmi` (FMI vocabulary and import), `tb-cosim` (system, plan, master,
//! backends, results), `tb-compare` (distance-based comparison), `tb-optimize` (studies),
//! `tb-analysis` (modal analysis, identification), `tb-plot` (plots); the models under
//! `models/` over the `fmu-export` framework. `docs/design.md` maps them.

pub mod bench;
pub mod cli;
pub mod export_twin;
pub mod lap;
pub mod pack;
pub mod realtime_check;
pub mod registry;
pub mod report;
pub mod study;
pub mod validate;

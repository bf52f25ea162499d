//! The bench's jobs, shared by the `twinbench` command line and the Python package (neither
//! depends on the other; this crate has no command-line parsing, progress bars or logger):
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
//! - [`realtime_check`]: an FMU's steps counted and timed for a real-time target;
//! - [`run_fmu`]: one FMU run on its own, as `fmpy simulate` runs it ([`run_fmu::FmuRun`]
//!   holds its options).
//!
//! The libraries below: `tb-fmi` (FMI vocabulary and import), `tb-cosim` (system, plan,
//! master, backends, results), `tb-compare` (distance-based comparison), `tb-optimize`
//! (studies), `tb-plot` (plots); the models under `models/` over the `fmu-export`
//! framework. `docs/design.md` maps them.

pub mod bench;
pub mod export_twin;
pub mod lap;
pub mod pack;
pub mod realtime_check;
pub mod registry;
pub mod report;
pub mod run_fmu;
pub mod study;
pub mod validate;

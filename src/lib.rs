//! twinbench: the digital twin of a powertrain test bench.
//!
//! - `pack`: builds the model crates and writes FMI 2.0 Co-Simulation FMUs.
//! - `cli`: the command line (one module per subcommand).
//!
//! The models live in `models/` (one crate each, over the `fmu-export` crate); signal
//! processing and comparison in `crates/compare`, bench analysis in `crates/analysis`.

pub mod cli;
pub mod fmu;
pub mod optimize;
pub mod pack;
pub mod report;
pub mod ssp;
pub mod system;

//! Distance-based comparison of a simulation with a vehicle measurement (paper ch. 4.2;
//! `docs/compare.md`).
//!
//! - [`Table`]: the column table (from `tb-table`, shared with results, replays, analysis).
//! - [`measurement`]: the vehicle measurement format, validated (the crate
//!   `tb-measurement`, re-exported: the co-simulation's replays read it without this crate).
//! - [`filter`]: Butterworth low-pass (bilinear transform, prewarped) as second-order
//!   sections; zero-phase forward-backward filtering with scipy's default odd padding.
//! - [`resample`]: linearly spaced distance grid and linear interpolation (Fig. 6).
//! - [`metrics`]: regression slope m, intercept, R², e (Eq. 16), bias, RMS.
//! - [`compare`]: the pipeline; [`PreparedMeasurement`] holds what depends on the
//!   measurement only, [`Workspace`] the per-thread buffers.
//! - [`error`]: the crate's error type (table errors wrapped as they are).
//!
//! ```no_run
//! use tb_compare::{CompareSettings, PreparedMeasurement, Table, Workspace};
//! let settings = CompareSettings::default();
//! let prepared =
//!     PreparedMeasurement::from_path("data/spielberg_lap.csv", &["Fz_sum", "Fz_rl"], &settings)?;
//! let mut ws = Workspace::new();
//! let sim = Table::read_path("result.csv")?;
//! let cmp = prepared.compare(&sim, &mut ws)?;
//! println!("e(Fz_sum) = {}", cmp.get("Fz_sum").unwrap().e);
//! # Ok::<(), tb_compare::Error>(())
//! ```

pub mod compare;
pub mod error;
pub mod filter;
pub mod metrics;
pub mod resample;

pub use compare::{
    compare_files, CompareSettings, Comparison, PreparedMeasurement, SignalComparison, Workspace,
    DERIVED_SIGNALS,
};
pub use error::{Error, Result};
pub use filter::Butterworth;
pub use metrics::{error_measure, metrics, Metrics};
pub use resample::DistanceGrid;
pub use tb_measurement as measurement;
pub use tb_measurement::{
    si_unit, ChannelMap, DistanceSource, Measurement, REQUIRED_COLUMNS, SIGNALS,
};
pub use tb_table::Table;

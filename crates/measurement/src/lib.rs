//! The vehicle measurement (`data/README.md`): read from MDF 4 or CSV, its channels mapped
//! to twinbench's signals ([`ChannelMap`]), their declared units converted to SI
//! ([`si_unit`]: the unit of each signal of the format), validated ([`Measurement`]).
//!
//! Below both the comparison (`tb-compare`, which re-exports this crate) and the
//! co-simulation's replays (`tb-cosim`, which replays a measurement by distance), so that
//! replaying a measurement does not need the comparison.

pub mod error;
pub mod measurement;

pub use error::{Error, Result};
pub use measurement::{
    check_distance_forward, check_forward, check_increasing_time, cumulative_trapezoid,
    cumulative_trapezoid_into, si_unit, ChannelMap, DistanceSource, Measurement, REQUIRED_COLUMNS,
    SIGNALS,
};
pub use tb_table::Table;

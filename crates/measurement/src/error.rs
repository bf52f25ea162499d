//! The crate's error type. Every error about a data cell names the source (file path, or
//! the label of an in-memory table), the row as the 1-based line in the file, and the
//! column. Errors of the table itself (reading, parsing, its shape) are `tb-table`'s,
//! wrapped as they are in [`Error::Table`].

use tb_table::TableError;

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong while reading a measurement (and checking a time or
/// distance column of any table, which the comparison shares).
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or checking the table: the table's own error, message and source as they are.
    #[error(transparent)]
    Table(#[from] TableError),

    #[error(
        "{file}: line {row}, column `{column}`: time does not increase ({value} after {previous})"
    )]
    NonIncreasingTime {
        file: String,
        row: u64,
        column: String,
        previous: f64,
        value: f64,
    },

    #[error(
        "{file}: line {row}, column `{column}`: distance runs backwards ({value} after {previous})"
    )]
    DistanceBackwards {
        file: String,
        row: u64,
        column: String,
        previous: f64,
        value: f64,
    },

    /// A channel map names a channel the file does not have.
    #[error("{file}: no channel `{channel}` (the channel map's name for signal `{signal}`); closest channels: {closest} (channels in the file: {available})")]
    MissingChannel {
        file: String,
        signal: String,
        channel: String,
        closest: String,
        available: String,
    },

    /// A measurement without one of the signals every measurement needs: the channel map
    /// entry that would supply it is suggested.
    #[error("{file}: missing required column `{signal}` (columns present: {available}); {hint}")]
    MissingSignal {
        file: String,
        signal: String,
        available: String,
        hint: String,
    },

    /// A channel map that cannot be used (its file, an unknown signal, one channel for two
    /// signals); the message names the map and what was expected.
    #[error("{0}")]
    ChannelMap(String),

    /// A channel's declared unit that is unknown or not convertible to the signal's SI
    /// unit; the message names the file and the channel.
    #[error("{0}")]
    Unit(String),
}

//! The crate's error type. Every error about a data cell names the source (file path, or
//! the label of an in-memory table), the row as the 1-based line in the file, and the
//! column.

use std::path::PathBuf;

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong while importing, filtering and comparing.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    #[error("{}: cannot read: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error("{file}: empty file: {what}")]
    Empty { file: String, what: &'static str },

    #[error("{file}: line {row}: expected {expected} fields as in the header, found {found}")]
    RaggedRow {
        file: String,
        row: u64,
        expected: usize,
        found: usize,
    },

    #[error("{file}: line 1: duplicate column name `{column}`")]
    DuplicateColumn { file: String, column: String },

    #[error("{file}: line {row}, column `{column}`: malformed number {value:?}")]
    Malformed {
        file: String,
        row: u64,
        column: String,
        value: String,
    },

    #[error("{file}: line {row}, column `{column}`: value {value} is not finite (NaN or Inf)")]
    NonFinite {
        file: String,
        row: u64,
        column: String,
        value: f64,
    },

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

    #[error("{file}: missing required column `{column}` (columns present: {available})")]
    MissingColumn {
        file: String,
        column: String,
        available: String,
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

    #[error("{file}: column `{column}` is ambiguous: matches {candidates}")]
    AmbiguousColumn {
        file: String,
        column: String,
        candidates: String,
    },

    #[error(
        "{file}: line {row}, column `{column}`: non-uniform sampling (step {step} s, expected {expected} s within 1 %); the zero-phase filter needs a uniform time base: resample first"
    )]
    NonUniformSampling {
        file: String,
        row: u64,
        column: String,
        step: f64,
        expected: f64,
    },

    #[error("{file}: {samples} samples are too few: {needed}")]
    TooShort {
        file: String,
        samples: usize,
        needed: String,
    },

    #[error("{file}: covers only {:.1} % of the measured distance ({covered_m:.1} of {total_m:.1} m; at least {:.1} % required)", coverage * 100.0, min_coverage * 100.0)]
    InsufficientOverlap {
        file: String,
        coverage: f64,
        min_coverage: f64,
        covered_m: f64,
        total_m: f64,
    },

    #[error("signal `{signal}`: {reason}")]
    Degenerate { signal: String, reason: String },

    #[error("invalid settings: {0}")]
    Settings(String),
}

/// Table errors keep their message (the same variants, converted one to one).
impl From<tb_table::TableError> for Error {
    fn from(e: tb_table::TableError) -> Self {
        use tb_table::TableError as T;
        match e {
            T::Io { path, source } => Error::Io { path, source },
            T::Empty { file, what } => Error::Empty { file, what },
            T::RaggedRow {
                file,
                row,
                expected,
                found,
            } => Error::RaggedRow {
                file,
                row,
                expected,
                found,
            },
            T::DuplicateColumn { file, column } => Error::DuplicateColumn { file, column },
            T::Malformed {
                file,
                row,
                column,
                value,
            } => Error::Malformed {
                file,
                row,
                column,
                value,
            },
            T::NonFinite {
                file,
                row,
                column,
                value,
            } => Error::NonFinite {
                file,
                row,
                column,
                value,
            },
            T::MissingColumn {
                file,
                column,
                available,
            } => Error::MissingColumn {
                file,
                column,
                available,
            },
            T::AmbiguousColumn {
                file,
                column,
                candidates,
            } => Error::AmbiguousColumn {
                file,
                column,
                candidates,
            },
            T::Shape(m) => Error::Settings(m),
            other => Error::Settings(other.to_string()),
        }
    }
}

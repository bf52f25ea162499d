//! The crate's error type. Every error about a data cell names the source (file path, or
//! the label of an in-memory table), the row as the 1-based line in the file, and the
//! column. Errors of the table itself (reading, parsing, its shape) are `tb-table`'s,
//! wrapped as they are in [`Error::Table`]; the measurement's are `tb-measurement`'s, in
//! [`Error::Measurement`].

use tb_table::TableError;

/// Result alias of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Everything that can go wrong while importing, filtering and comparing.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// Reading or checking a table (a file, a simulation result): the table's own error,
    /// message and source as they are.
    #[error(transparent)]
    Table(#[from] TableError),

    /// Reading or validating the measurement (`tb-measurement`), or a time or distance of a
    /// simulation checked as a measurement's: its error, message as it is. Boxed: it names
    /// the file, the channel and the channels present, and every comparison returns this.
    #[error(transparent)]
    Measurement(Box<tb_measurement::Error>),

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

    /// A setting or file that cannot be used; the message names the file and what was
    /// expected.
    #[error("{0}")]
    Settings(String),

    /// A signal to compare that is neither a column nor a derived signal.
    #[error("{file}: no signal `{signal}`; closest: {closest} (columns: {available}; derived: Fz_sum, Fz_front, Fz_rear)")]
    UnknownSignal {
        file: String,
        signal: String,
        closest: String,
        available: String,
    },
}

impl From<tb_measurement::Error> for Error {
    fn from(e: tb_measurement::Error) -> Self {
        Error::Measurement(Box::new(e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_table_error_keeps_its_message_and_source() {
        let shape = Error::from(TableError::Shape("lap.mf4: MDF 4: no data group".into()));
        assert_eq!(shape.to_string(), "lap.mf4: MDF 4: no data group");
        let io = Error::from(TableError::Io {
            path: "lap.csv".into(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "gone"),
        });
        assert_eq!(io.to_string(), "lap.csv: cannot read: gone");
        let source = std::error::Error::source(&io).expect("the io error");
        assert_eq!(source.to_string(), "gone");
    }
}

//! Errors about tabular data. Every error about a data cell names the source (file path, or
//! the label of an in-memory table), the row as the 1-based line in the file, and the
//! column.

use std::path::PathBuf;

/// Result alias of this crate.
pub type Result<T, E = TableError> = std::result::Result<T, E>;

#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TableError {
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

    #[error("{file}: missing required column `{column}` (columns present: {available})")]
    MissingColumn {
        file: String,
        column: String,
        available: String,
    },

    #[error("{file}: column `{column}` is ambiguous: matches {candidates}")]
    AmbiguousColumn {
        file: String,
        column: String,
        candidates: String,
    },

    /// An MDF 4 file refused before the reader sees it.
    #[error("{file}: MDF 4: {source}")]
    Mdf {
        file: String,
        #[source]
        source: crate::mdf::MdfError,
    },

    /// Columns of different lengths, names that do not match the columns, and the like.
    #[error("{0}")]
    Shape(String),
}

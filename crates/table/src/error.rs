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
        source: MdfError,
    },

    /// Columns of different lengths, names that do not match the columns, and the like.
    #[error("{0}")]
    Shape(String),
}

/// What is wrong with an MDF 4 file: the block (its type and offset, as `the ##DG at offset
/// 336`), the link that leads to it, and the numbers found. [`TableError::Mdf`] adds the
/// file.
/// An MDF 4 file refused by the check, or not copied for the crate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MdfError {
    /// `from`: the link (its block, number and field) or the identification block.
    #[error("{from} points to offset {at}, past the end of the file ({size} bytes; truncated?)")]
    PastEnd { from: String, at: u64, size: u64 },
    /// `found`: the four bytes there, escaped.
    #[error(
        "{from} points to offset {at}, where no block starts (the bytes there are \"{found}\", not \"##\" and a block type)"
    )]
    NoBlock {
        from: String,
        at: u64,
        found: String,
    },
    #[error("{block} has a length of {length} bytes, less than its 24-byte header")]
    ShortBlock { block: String, length: u64 },
    #[error("{block} is {length} bytes long, past the end of the file ({size} bytes; truncated?)")]
    LongBlock {
        block: String,
        length: u64,
        size: u64,
    },
    #[error("{block} has {links} links, more than its {length} bytes hold")]
    LinksOverflow {
        block: String,
        links: u64,
        length: u64,
    },
    /// A block shorter than the fields the crate reads at fixed offsets.
    #[error(
        "{block} has {links} links and {length} bytes; its fields need at least {links_needed} links and {length_needed} bytes"
    )]
    Layout {
        block: String,
        links: u64,
        length: u64,
        links_needed: u64,
        length_needed: u64,
    },
    #[error(
        "the file is {size} bytes long, shorter than the identification and header blocks of an MDF 4 file (168 bytes)"
    )]
    ShortFile { size: u64 },
    /// `found`: the first eight bytes, escaped.
    #[error("not an MDF file (it starts with \"{found}\", not \"MDF     \")")]
    NotMdf { found: String },
    #[error("version \"{found}\": twinbench reads MDF 4.10 and later 4.x files")]
    Version { found: String },
    #[error("{block} where the header block (##HD) must be")]
    NoHeader { block: String },
    #[error(
        "more than {limit} blocks reachable in a file of {size} bytes (one per 24 bytes at most)"
    )]
    TooManyBlocks { limit: u64, size: u64 },
    /// `target`: the block led back to (`the same block` for a link to itself); `cycle`:
    /// the blocks round the cycle, shortened in the middle when long.
    #[error(
        "{from} leads back to {target}: a cycle in the file's links ({})",
        cycle.join(" -> ")
    )]
    Cycle {
        from: String,
        target: String,
        cycle: Vec<String>,
    },
    #[error("{from} leads to {block}, where a {expected} must be")]
    Unexpected {
        from: String,
        block: String,
        expected: String,
    },
    /// `what`: the chain (`a data group`, `a channel group`, `a channel`, `data`).
    #[error("{block} is linked twice as {what}: each belongs to one chain")]
    LinkedTwice { block: String, what: &'static str },
    #[error("{block} has record IDs of {size} bytes; MDF 4 allows 0, 1, 2, 4 or 8")]
    RecordIdSize { block: String, size: u64 },
    #[error("{block} has records of 0 bytes (record ID, data and invalidation bytes)")]
    EmptyRecords { block: String },
    #[error(
        "{block} says it has {cycles} records (its cycle count) of {record} bytes, but its data holds {records}"
    )]
    CycleCount {
        block: String,
        cycles: u64,
        record: u64,
        records: u64,
    },
    #[error(
        "{channel}: the formula of its algebraic conversion ({conversion}) is {length} bytes long, more than {limit}"
    )]
    Formula {
        channel: String,
        conversion: String,
        length: u64,
        limit: u64,
    },
    #[error("{channel} is an integer of {bits} bits; MDF 4 integers have 1 to 64")]
    IntegerBits { channel: String, bits: u64 },
    #[error("{channel} has a bit offset of {offset}; it is 0 to 7")]
    BitOffset { channel: String, offset: u8 },
    #[error("{block} links to no data block")]
    NoDataBlock { block: String },
    #[error(
        "{from} leads to {block}: compressed data is not read by twinbench's MDF reader (write the file uncompressed)"
    )]
    Compressed { from: String, block: String },
    #[error(
        "{from} leads to {block}: data without invalidation bytes (MDF 4.2) is not read by twinbench's MDF reader"
    )]
    NoInvalidation { from: String, block: String },
    #[error(
        "{from} leads to {block}, where data (##DT, or ##DL or ##HL from a data group) must be"
    )]
    NotData { from: String, block: String },
    /// Two channel groups of one unsorted data group (`block`) with one record ID.
    #[error(
        "two channel groups of {block} have the record ID {record_id} ({second} is the second)"
    )]
    SharedRecordId {
        block: String,
        record_id: u64,
        second: String,
    },
    #[error(
        "the channels hold {cells} samples and make a table of {table} values; twinbench reads at most {limit} from one file"
    )]
    Cells { cells: u64, table: u64, limit: u64 },
    #[error(
        "reading its channels takes {steps} steps (samples times their conversion's table or formula, data blocks and records scanned per channel), more than {limit}"
    )]
    Work { steps: u64, limit: u64 },
    #[error(
        "its channels, conversions, names and units take {bytes} bytes to hold, more than {limit}"
    )]
    Metadata { bytes: u64, limit: u64 },
    #[error("cannot make an in-memory copy for the MDF reader: {0}")]
    InMemory(#[source] std::io::Error),
}

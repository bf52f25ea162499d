//! One error type for the whole crate; every message names the cause and, where there is
//! one, the file, the chain, the component or the column.

/// Everything that can go wrong in bench analysis.
#[derive(Debug, thiserror::Error)]
pub enum AnalysisError {
    #[error("{file}: cannot read: {source}")]
    Io {
        file: String,
        #[source]
        source: std::io::Error,
    },
    #[error("{file}: invalid chain description: {message}")]
    ChainFormat { file: String, message: String },
    #[error(
        "chain '{chain}': inertia of '{component}' must be positive and finite, got {value} kg·m²"
    )]
    NonPositiveInertia {
        chain: String,
        component: String,
        value: f64,
    },
    #[error("chain '{chain}': stiffness of '{component}' must be positive and finite, got {value} N·m/rad")]
    NonPositiveStiffness {
        chain: String,
        component: String,
        value: f64,
    },
    #[error("chain '{chain}': damping of '{component}' must be non-negative and finite, got {value} N·m·s/rad")]
    NegativeDamping {
        chain: String,
        component: String,
        value: f64,
    },
    #[error("chain '{chain}' has {count} inertia(s); a torsional chain needs at least two (an inertia alone has no elastic mode to analyse)")]
    TooFewInertias { chain: String, count: usize },
    #[error("chain '{chain}': {inertias} inertias need exactly {expected} springs between them ([[spring]] tables), found {found}")]
    SpringCount {
        chain: String,
        inertias: usize,
        expected: usize,
        found: usize,
    },
    #[error("chain '{chain}': component name '{name}' is used twice; names identify components in the sensitivity tables and in --compare")]
    DuplicateName { chain: String, name: String },
    #[error("chain '{chain}': the eigenproblem could not be solved ({message})")]
    Eigen { chain: String, message: String },
    #[error("{file}: column '{column}' not found (columns: {available})")]
    MissingColumn {
        file: String,
        column: String,
        available: String,
    },
    #[error("{file}, line {line}: {message}")]
    Csv {
        file: String,
        line: usize,
        message: String,
    },
    #[error("{file}: uneven sampling: the time step before line {line} is {dt} s, but the mean step is {mean} s (resample the data onto a uniform grid first)")]
    UnevenSampling {
        file: String,
        line: usize,
        dt: f64,
        mean: f64,
    },
    #[error("{file}: time must increase strictly; it does not at line {line}")]
    NonIncreasingTime { file: String, line: usize },
    #[error("{file}: {samples} samples are too few for the requested window of {nperseg} samples (shorten --nperseg or record longer)")]
    TooFewSamples {
        file: String,
        samples: usize,
        nperseg: usize,
    },
    #[error("{0}")]
    InvalidParameter(String),
    #[error("{file}: no step in setpoint column '{column}': it is constant")]
    NoStep { file: String, column: String },
    #[error("{file}: {message}")]
    StepResponse { file: String, message: String },
    #[error("FRF fit: {0}")]
    Fit(String),
}

/// Result with [`AnalysisError`].
pub type Result<T> = std::result::Result<T, AnalysisError>;

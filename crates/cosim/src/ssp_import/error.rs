//! What can go wrong importing an SSP package.

use std::path::PathBuf;
use tb_fmi::FmuError;

/// Why an SSP package cannot be run. Every message names the package; those about its XML
/// also name the file inside it and the line.
#[derive(Debug, thiserror::Error)]
pub enum SspImportError {
    /// The package as an archive (not a zip, an entry escaping it, a link, too large).
    #[error(transparent)]
    Archive(Box<FmuError>),
    /// A file the package must hold is not there, or cannot be read.
    #[error("{ssp}: {message}")]
    Package { ssp: PathBuf, message: String },
    #[error("{ssp}: {file}, line {line}: malformed XML: {message}")]
    Xml {
        ssp: PathBuf,
        file: String,
        line: usize,
        message: String,
    },
    #[error("{ssp}: {file}, line {line}: <{element}> is not supported by twinbench's SSP 1.0 import: {supported}")]
    Unsupported {
        ssp: PathBuf,
        file: String,
        line: usize,
        element: String,
        supported: String,
    },
    #[error("{ssp}: component '{component}': its FMU '{fmu}' is not in the package (FMUs in it: {available})")]
    MissingFmu {
        ssp: PathBuf,
        component: String,
        fmu: String,
        available: String,
    },
    #[error("{ssp}: {entry}: {error}")]
    Fmu {
        ssp: PathBuf,
        entry: String,
        error: Box<FmuError>,
    },
    #[error("{ssp}: {file}, line {line}: {message}")]
    Invalid {
        ssp: PathBuf,
        file: String,
        line: usize,
        message: String,
    },
}

impl SspImportError {
    /// This error, where it refuses an element that `refused` picks out, with what is
    /// supported replaced by what `why` makes of it (why that element is refused).
    pub(super) fn explained(
        self,
        refused: impl Fn(&str) -> bool,
        why: impl FnOnce(String) -> String,
    ) -> SspImportError {
        match self {
            SspImportError::Unsupported {
                ssp,
                file,
                line,
                element,
                supported,
            } if refused(&element) => SspImportError::Unsupported {
                ssp,
                file,
                line,
                element,
                supported: why(supported),
            },
            other => other,
        }
    }
}

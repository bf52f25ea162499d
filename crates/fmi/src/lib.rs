//! FMI 2.0 for twinbench: one vocabulary for the export framework and the importer.
//!
//! Always available (no dependencies; the export framework of the models uses these):
//! - [`fmi2`]: the C types and function signatures of the standard's headers;
//! - [`schema`]: causality, variability, initial and the scalar types as typed enums;
//! - [`functions`]: the function table (symbol, C type, required, allowed states);
//! - [`status`]: what an `fmi2Status` means to a caller;
//! - [`units`]: the unit table with SI base-unit exponents.
//!
//! With the `import` feature (the default), the importer:
//! - [`description`]: the modelDescription.xml reader;
//! - [`archive`]: archive checks (untrusted input), the unpack cache and the machine-wide
//!   store of unpacked FMUs with its stat index;
//! - [`library`]: a loaded shared library with its function table resolved;
//! - [`instance`]: a safe handle on one FMU instance;
//! - [`log`]: the log sink every backend's messages go to;
//! - [`FmuError`]: the importer's errors.

pub mod fmi2;
pub mod functions;
pub mod schema;
pub mod status;
pub mod units;

#[cfg(feature = "import")]
#[path = "import/archive.rs"]
pub mod archive;
#[cfg(feature = "import")]
#[path = "import/description.rs"]
pub mod description;
#[cfg(feature = "import")]
#[path = "import/description3.rs"]
pub mod description3;
#[cfg(feature = "import")]
#[path = "import/error.rs"]
mod error;
#[cfg(feature = "import")]
#[path = "import/instance.rs"]
pub mod instance;
#[cfg(feature = "import")]
#[path = "import/instance3.rs"]
pub mod instance3;
#[cfg(feature = "import")]
#[path = "import/library.rs"]
pub mod library;
#[cfg(feature = "import")]
#[path = "import/log.rs"]
pub mod log;
#[cfg(feature = "import")]
#[path = "import/store.rs"]
mod store;

pub use functions::{Function, FunctionSpec, Phase, PhaseSet, FUNCTIONS};
pub use schema::{Causality, Initial, ScalarType, Variability};

#[cfg(feature = "import")]
pub use archive::{FmuCache, LoadedFmu};
#[cfg(feature = "import")]
pub use description::ModelDescription;
#[cfg(feature = "import")]
pub use error::FmuError;
#[cfg(feature = "import")]
pub use instance::{FmuState, Instance};
#[cfg(feature = "import")]
pub use instance3::{Instance3, Library3};
#[cfg(feature = "import")]
pub use library::Library;

//! FMI 2.0 and FMI 3.0 for twinbench: one vocabulary for the export framework and the
//! importer of FMI 2.0 and 3.0 Co-Simulation FMUs.
//!
//! Always available (no dependencies; the export framework of the models uses these):
//! - [`fmi2`]: the C types and function signatures of the standard's headers;
//! - [`schema`]: causality, variability, initial and the scalar types as typed enums;
//! - [`functions`]: the function table (symbol, C type, required, allowed states);
//! - [`status`]: what an `fmi2Status` means to a caller;
//! - [`units`]: the unit table with SI base-unit exponents.
//!
//! With the `import` feature (the default), [`import`]: the importer of FMI 2.0 and 3.0 FMUs
//! (archive checks and the unpack store, the two model-description readers, libraries,
//! instances, the log, errors); its main types are re-exported here.

pub mod fmi2;
pub mod functions;
pub mod schema;
pub mod status;
pub mod units;

#[cfg(feature = "import")]
pub mod import;

pub use functions::{Function, FunctionSpec, Phase, PhaseSet, FUNCTIONS};
pub use schema::{Causality, Initial, ScalarType, Variability};
pub use status::{CallStatus, FmiFunction};

#[cfg(feature = "import")]
pub use import::archive::{FmuCache, LoadedFmu};
#[cfg(feature = "import")]
pub use import::instance::{FmuState, Instance};
#[cfg(feature = "import")]
pub use import::instance3::Instance3;
#[cfg(feature = "import")]
pub use import::library::Library;
#[cfg(feature = "import")]
pub use import::library3::Library3;
#[cfg(feature = "import")]
pub use import::model::{Interface, ModelDescription, VarKey};
#[cfg(feature = "import")]
pub use import::model_exchange::{CallTrace, MeInstance, MeLibrary, MeSettings, MeStop};
#[cfg(feature = "import")]
pub use import::{Experiment, FmuError, FmuInstance};

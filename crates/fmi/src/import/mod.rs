//! The importer: FMI 2.0 and FMI 3.0 Co-Simulation FMUs from archive to running instance.
//!
//! - [`archive`]: archive checks (untrusted input), the unpack cache and the machine-wide
//!   store of unpacked FMUs with its stat index ([`store`]);
//! - [`description`]: what twinbench knows of an FMU, and the FMI 2.0 modelDescription.xml
//!   reader; [`description3`]: the FMI 3.0 reader; [`reader`]: what both share;
//! - [`library`] and [`library3`]: a loaded shared library with its functions resolved;
//! - [`instance`] and [`instance3`]: a safe handle on one FMU instance (the same calls for
//!   both versions);
//! - [`log`]: the log sink every backend's messages go to; [`FmuError`]: the errors.

pub mod archive;
pub mod description;
pub mod description3;
mod error;
pub mod instance;
pub mod instance3;
pub mod library;
pub mod library3;
pub mod log;
pub(crate) mod reader;
mod store;

pub use error::FmuError;

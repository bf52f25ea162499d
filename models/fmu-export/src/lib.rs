//! FMI 2.0 Co-Simulation export framework for twinbench models.
//!
//! A model crate declares its variables with [`variables!`], implements the safe
//! [`Model`] trait, and calls [`export_fmu!`] (behind its `fmu` feature) to get every
//! `fmi2*` C entry point. Nothing else in the models touches FFI.
//!
//! - [`fmi2`], [`units`], [`Phase`], [`Function`]: re-exported from `tb-fmi`, the FMI vocabulary
//!   shared with the importer (C types, unit table, states and the function table).
//! - [`variables`]: the variable table, one source of truth per variable.
//! - [`model`]: the trait a model implements.
//! - [`runtime`]: the safe instance and its FMI state machine (also usable natively).
//! - [`description`]: modelDescription.xml, documentation and GUID from the table.
//! - [`ffi`]: the panic-guarded C entry points.

pub mod description;
pub mod ffi;
pub mod model;
pub mod runtime;
pub mod sidecar;
pub mod variables;

pub use tb_fmi::{fmi2, units, Function, Phase, PhaseSet};

pub use model::{
    Context, DefaultExperiment, Model, ModelError, ModelInfo, Resource, Severity, StateReader,
    StateWriter,
};
pub use runtime::{Logger, NullLogger, Runtime};
pub use variables::{Value, VarInfo, VarTable};

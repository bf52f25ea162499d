//! FMI 2.0 and 3.0 Co-Simulation export framework for twinbench models.
//!
//! A model crate declares its variables with [`variables!`], implements the safe
//! [`Model`] trait, and calls [`export_fmu!`] (behind its `fmu` feature) to get every
//! `fmi2*` and `fmi3*` C entry point. Nothing else in the models touches FFI.
//!
//! - [`fmi2`], [`units`], [`Phase`], [`Function`]: re-exported from `tb-fmi`, the FMI vocabulary
//!   shared with the importer (C types, unit table, states and the function table).
//! - [`variables`]: the variable table, one source of truth per variable; [`check`]: its
//!   rules, evaluated at compile time.
//! - [`model`]: the trait a model implements and [`ModelInfo`]; [`error`]: [`ModelError`].
//! - [`context`]: what a model knows of its instance (resource folder, start time, the
//!   resources it parsed).
//! - [`state`]: the writer and reader of serialized FMU states.
//! - [`resources`]: files a model reads (resource text, data files shared by instances,
//!   paths named by parameters, the resource folder's URI).
//! - [`preparsed`]: bundled CSV resources parsed at build time by the model's own parser.
//! - [`runtime`]: the safe instance and its FMI state machine (also usable natively), by job:
//!   the life cycle and the step, the get and set calls, FMU states.
//! - [`description`]: modelDescription.xml, documentation and GUID from the table.
//! - [`description3`]: the FMI 3.0 modelDescription.xml and instantiation token from the
//!   same table.
//! - [`ffi`]: the panic-guarded C entry points; [`ffi3`]: FMI 3.0's, on the same runtime.

pub mod check;
pub mod context;
pub mod description;
pub mod description3;
mod entry_points;
mod enumeration;
pub mod error;
pub mod ffi;
pub mod ffi3;
pub mod fitted;
pub mod model;
pub mod preparsed;
pub mod resources;
pub mod runtime;
pub mod state;
pub mod variables;

pub use tb_fmi::{fmi2, units, Function, Phase, PhaseSet};

pub use context::{Context, ResourceCache};
pub use model::{DefaultExperiment, Model, ModelError, ModelInfo, Resource, Severity};
pub use runtime::{Logger, NullLogger, Runtime};
pub use state::{HoldsState, ModelState, StateReader, StateWriter, Stateless};
/// A short, escaped excerpt of user text for a message (a field of a file, a value).
pub use tb_files::excerpt;
pub use variables::{Value, VarInfo, VarTable};

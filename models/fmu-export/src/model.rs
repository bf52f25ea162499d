//! The safe trait a model crate implements, and the static facts about a model. No FFI
//! here: the runtime and the generated entry points call these methods. What a model is
//! handed lives beside it: [`crate::context`] (its instance), [`crate::state`] (serialized
//! FMU states), [`crate::resources`] (files and their parsing).

pub use crate::error::{ModelError, Severity};
use crate::state::ModelState;
use crate::variables::VarTable;

// What lived in this module before context.rs, state.rs and resources.rs, still reachable
// by its old path (`fmu_export::model::shared_file`, ...); new code names those modules.
pub use crate::context::{Context, ResourceCache};
pub use crate::resources::{parameter_path, read_text, shared_file, wrap_distance};
pub use crate::state::{StateReader, StateWriter};

/// Static facts about a model, written to modelDescription.xml and the documentation.
#[derive(Clone, Copy, Debug)]
pub struct ModelInfo {
    /// `modelName` and the FMU file name (`<name>.fmu`).
    pub name: &'static str,
    /// `modelIdentifier`: the shared library's name and the C symbol prefix.
    pub identifier: &'static str,
    pub description: &'static str,
    pub version: &'static str,
    pub default_experiment: DefaultExperiment,
    /// HTML fragment for documentation/index.html: equations and notes.
    pub documentation: &'static str,
    /// Files (relative to the model crate) shipped in the FMU's `resources/`.
    pub resources: &'static [Resource],
}

impl ModelInfo {
    /// A model's facts, with what most models leave as it is: the name is also the
    /// `modelIdentifier` (the shared library's name), the default experiment runs from 0 s
    /// to 1 s in steps of 1 ms, and there is no documentation and no resource until
    /// [`ModelInfo::experiment`], [`ModelInfo::documentation`] and
    /// [`ModelInfo::resources`] say otherwise. A model crate passes
    /// `env!("CARGO_PKG_VERSION")` as its version.
    pub const fn new(name: &'static str, description: &'static str, version: &'static str) -> Self {
        ModelInfo {
            name,
            identifier: name,
            description,
            version,
            default_experiment: DefaultExperiment {
                start_time: 0.0,
                stop_time: 1.0,
                step_size: 1e-3,
            },
            documentation: "",
            resources: &[],
        }
    }

    /// The default experiment: from 0 s to `stop_time` in steps of `step_size` [s].
    pub const fn experiment(mut self, stop_time: f64, step_size: f64) -> Self {
        self.default_experiment = DefaultExperiment {
            start_time: 0.0,
            stop_time,
            step_size,
        };
        self
    }

    /// The HTML fragment for documentation/index.html.
    pub const fn documentation(mut self, html: &'static str) -> Self {
        self.documentation = html;
        self
    }

    /// The files shipped in `resources/`.
    pub const fn resources(mut self, files: &'static [Resource]) -> Self {
        self.resources = files;
        self
    }
}

/// A file shipped in `resources/`: its name there and its content.
#[derive(Clone, Copy, Debug)]
pub struct Resource {
    pub name: &'static str,
    pub content: &'static [u8],
    /// The String parameter (a `*_file` path) whose empty value means this file: where
    /// `twinbench export-twin` puts a fitted twin's own file (its track, its target), so
    /// that the FMU needs no path set by any host.
    pub default_of: Option<&'static str>,
}

impl Resource {
    /// A file shipped as it is (no parameter defaults to it).
    pub const fn file(name: &'static str, content: &'static [u8]) -> Self {
        Resource {
            name,
            content,
            default_of: None,
        }
    }

    /// The file that the empty value of the String parameter `parameter` means.
    pub const fn default_of(mut self, parameter: &'static str) -> Self {
        self.default_of = Some(parameter);
        self
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DefaultExperiment {
    pub start_time: f64,
    pub stop_time: f64,
    pub step_size: f64,
}

/// A model: its variable table, and the equations.
///
/// The runtime owns the variables (`Self::Vars`), checks every set against causality,
/// variability and min/max, and calls the model: [`Model::initialize`] to build it,
/// [`Model::do_step`] to advance its state, and [`Model::calculate_outputs`] after each of
/// them (and when the host changed inputs an output depends on directly), so that an
/// output's formula is written once. Its dynamic state for serialized FMU states comes
/// from [`ModelState`] (`impl Stateless for M {}` for a model without one).
pub trait Model: ModelState + Clone + Send + Sized + 'static {
    type Vars: VarTable;
    const INFO: ModelInfo;

    /// Check parameters, load resources and set the initial state (and any local the state
    /// gives). The runtime then calls [`Model::calculate_outputs`]. Called in initialization
    /// mode (when outputs are read) and at fmi2ExitInitializationMode, again whenever
    /// parameters or inputs changed in between.
    fn initialize(vars: &mut Self::Vars, ctx: &Context) -> Result<Self, ModelError>;

    /// Advance the state from `time` by `step` (> 0) with the inputs in `vars`. After a
    /// step that succeeded the runtime calls [`Model::calculate_outputs`]; a step that
    /// computes an output as part of its integration (a state exposed as it is) may write
    /// it here. Must not allocate.
    fn do_step(&mut self, vars: &mut Self::Vars, time: f64, step: f64) -> Result<(), ModelError>;

    /// How many internal steps [`Model::do_step`] takes for a step of `step` seconds (1 for
    /// a model that takes a step whole). The runtime refuses a step of more than
    /// [`crate::runtime::MAX_INTERNAL_STEPS`] before the model runs it: a host's
    /// `doStep(t, 1e300)` would otherwise never return.
    fn internal_steps(&self, _step: f64) -> f64 {
        1.0
    }

    /// Write the outputs (and the exposed locals) computed from the state, the parameters
    /// and the inputs in `vars`: the Modelica Reference FMUs' `calculateValues`. The runtime
    /// calls it after [`Model::initialize`], after every [`Model::do_step`] that succeeded,
    /// and, for a model that declares direct feed-through (`depends_on`), before outputs are
    /// read after the host set inputs between steps. Must not allocate.
    fn calculate_outputs(&mut self, vars: &mut Self::Vars);

    /// A tunable parameter changed between steps: refresh anything derived from it.
    fn parameters_changed(&mut self, _vars: &Self::Vars) -> Result<(), ModelError> {
        Ok(())
    }

    /// fmi2Terminate: the run is over (flush, check what only the end can tell).
    fn terminate(&mut self, _vars: &Self::Vars) -> Result<(), ModelError> {
        Ok(())
    }
}

//! The safe FMI 2.0 Co-Simulation instance: call-order state machine, variable access with
//! causality/variability/range checks, stepping, FMU states. The FFI layer is a thin,
//! panic-guarded shell around this; tests and native hosts can use it directly.
//!
//! The instance is spread over this folder by job: `slots` (what each value reference
//! allows, and where the instance stands), `values` (the get and set calls), `snapshot` and
//! `states` (FMU states), this file (the life cycle and the step).

mod slots;
mod snapshot;
mod states;
mod values;

use crate::context::Context;
use crate::description::LOG_CATEGORIES;
use crate::fmi2::fmi2Status;
use crate::model::{Model, ModelError, Severity};
use crate::variables::{Causality, VarInfo, VarTable, Variability};
use std::path::PathBuf;
use tb_fmi::{Function, Phase, PhaseSet};

use slots::{RunState, Slot, NO_SLOT};
pub use snapshot::Snapshot;

const LOG_ERROR: u8 = 1;
const LOG_WARNING: u8 = 2;
const LOG_EVENTS: u8 = 4;
const LOG_EVERYTHING: u8 = LOG_ERROR | LOG_WARNING | LOG_EVENTS;

/// Receives the instance's log messages (the FFI layer forwards to the host's callback).
pub trait Logger: Send {
    fn log(&self, status: fmi2Status, category: &str, message: &str);
}

/// How far (relative to the bound, at least to 1) a Real input may lie outside its declared
/// range and still be accepted, as the bound: a float32 rounding is 6e-8 relative.
pub const RANGE_SLACK: f64 = 1e-6;

/// The parameter a model declares to let hosts choose what an input outside its range does.
pub const RANGE_CHECK: &str = "range_check";

/// A logger that drops everything.
pub struct NullLogger;
impl Logger for NullLogger {
    fn log(&self, _: fmi2Status, _: &str, _: &str) {}
}

/// The most internal steps one doStep may take ([`Model::internal_steps`]): a million
/// (a 1000 s step of the vehicle's 1 ms sub-steps, about a second of computing).
pub const MAX_INTERNAL_STEPS: f64 = 1e6;

pub struct Runtime<M: Model> {
    pub vars: M::Vars,
    model: Option<M>,
    run: RunState,
    /// The last lazy initialisation (by a getter in initialization mode) failed.
    init_failed: bool,
    /// A panic left the model in an unknown state: only reset, restore or free.
    poisoned: Option<String>,
    ctx: Context,
    guid: String,
    /// A fitted twin's start values (`resources/fitted_start_values.toml`), applied after
    /// the table's defaults at instantiation and at reset.
    fitted: Option<std::sync::Arc<crate::fitted::FittedStarts>>,
    /// value reference -> table index + 1 (0: unknown).
    vr_index: Vec<u32>,
    /// value reference -> checks of the fast get/set path.
    slots: Vec<Slot>,
    /// FMI 3.0: the value reference of the independent variable `time` ([`Runtime::expose_time`]).
    independent_time: Option<u32>,
    /// Index of the model's `range_check` parameter, if it declares one (0: an input
    /// outside its range is accepted with a warning; 1, the default: refused).
    range_check: Option<usize>,
    logger: Box<dyn Logger>,
    logging_on: bool,
    categories: u8,
}

impl<M: Model> Runtime<M> {
    pub fn new(
        instance_name: &str,
        resource_dir: Option<PathBuf>,
        logger: Box<dyn Logger>,
        logging_on: bool,
    ) -> Self {
        let table = M::Vars::VARIABLES;
        let max_vr = table.iter().map(|v| v.value_reference).max().unwrap_or(0) as usize;
        let mut vr_index = vec![0u32; max_vr + 1];
        let mut slots = vec![NO_SLOT; max_vr + 1];
        for (i, v) in table.iter().enumerate() {
            vr_index[v.value_reference as usize] = i as u32 + 1;
            slots[v.value_reference as usize] = Slot {
                index: i as u32,
                // An Enumeration is got and set as an Integer.
                ty: v.var_type().value_space(),
                has_start: v.has_start(),
                settable_init: v.variability != Variability::Constant
                    && (v.causality == Causality::Input || v.has_start()),
                settable_run: v.causality == Causality::Input
                    || (v.causality == Causality::Parameter
                        && v.variability == Variability::Tunable),
                is_input: v.causality == Causality::Input,
                min: v.min.unwrap_or(f64::NEG_INFINITY),
                max: v.max.unwrap_or(f64::INFINITY),
                offset: M::Vars::REAL_OFFSETS[i],
            };
        }
        Runtime {
            vars: M::Vars::default(),
            model: None,
            run: RunState::INSTANTIATED,
            init_failed: false,
            poisoned: None,
            independent_time: None,
            ctx: Context {
                instance_name: instance_name.to_string(),
                resource_dir,
                start_time: 0.0,
                cache: Default::default(),
            },
            guid: crate::description::guid::<M>(),
            fitted: None,
            vr_index,
            slots,
            range_check: table
                .iter()
                .position(|v| v.name == RANGE_CHECK && v.causality == Causality::Parameter),
            logger,
            logging_on,
            categories: LOG_EVERYTHING,
        }
    }

    /// A fitted twin's instance: its start values over the table's, its own GUID.
    pub fn with_fitted(mut self, fitted: crate::fitted::FittedStarts) -> Self {
        fitted.apply(&mut self.vars);
        self.guid = fitted.token.clone();
        self.fitted = Some(std::sync::Arc::new(fitted));
        self
    }

    pub fn phase(&self) -> Phase {
        self.run.phase
    }
    pub fn time(&self) -> f64 {
        self.run.time
    }
    pub fn guid(&self) -> &str {
        &self.guid
    }
    /// The value reference after the table's largest: FMI 3.0's independent variable
    /// `time` ([`crate::description3::time_value_reference`]).
    #[inline]
    pub fn time_value_reference(&self) -> u32 {
        self.vr_index.len() as u32
    }

    /// The variable of value reference `vr`, if the table has one.
    pub fn var_info(&self, vr: u32) -> Option<&'static VarInfo> {
        match self.vr_index.get(vr as usize) {
            Some(&i) if i > 0 => Some(&M::Vars::VARIABLES[i as usize - 1]),
            _ => None,
        }
    }
    pub fn instance_name(&self) -> &str {
        &self.ctx.instance_name
    }
    pub fn model(&self) -> Option<&M> {
        self.model.as_ref()
    }

    // ---- logging ----

    /// Log an error (always forwarded: errors are not debug output) and return fmi2Error.
    pub fn error(&self, message: &str) -> fmi2Status {
        self.logger
            .log(fmi2Status::ERROR, "logStatusError", message);
        fmi2Status::ERROR
    }

    pub fn warning(&self, message: &str) {
        if self.logging_on && self.categories & LOG_WARNING != 0 {
            self.logger
                .log(fmi2Status::WARNING, "logStatusWarning", message);
        }
    }

    pub fn event(&self, message: &str) {
        if self.logging_on && self.categories & LOG_EVENTS != 0 {
            self.logger.log(fmi2Status::OK, "logEvents", message);
        }
    }

    /// Record a panic: log it and poison the instance.
    pub fn poison(&mut self, function: &str, panic_message: &str) -> fmi2Status {
        let msg = format!(
            "{function}: the model panicked: {panic_message}; the instance is unusable until fmi2Reset or fmi2SetFMUstate"
        );
        self.error(&msg);
        self.poisoned = Some(msg);
        self.run.phase = Phase::Error;
        fmi2Status::ERROR
    }

    pub fn set_debug_logging(&mut self, on: bool, categories: &[&str]) -> fmi2Status {
        let mut mask = 0u8;
        for c in categories {
            match LOG_CATEGORIES.iter().position(|(n, _)| n == c) {
                Some(3) => mask |= LOG_EVERYTHING,
                Some(i) => mask |= 1 << i,
                None => {
                    return self.error(&format!(
                        "fmi2SetDebugLogging: unknown log category '{c}' (known: {})",
                        LOG_CATEGORIES
                            .iter()
                            .map(|c| c.0)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                }
            }
        }
        self.logging_on = on;
        self.categories = if categories.is_empty() {
            LOG_EVERYTHING
        } else {
            mask
        };
        fmi2Status::OK
    }

    // ---- state machine ----

    /// The call-order check: the phases of [`tb_fmi::FUNCTIONS`], and no poisoned instance.
    #[inline]
    fn require(&self, function: Function) -> Result<(), fmi2Status> {
        self.require_named(function.name(), function.allowed())
    }

    #[inline]
    fn require_named(&self, name: &str, allowed: PhaseSet) -> Result<(), fmi2Status> {
        if self.poisoned.is_none() && allowed.contains(self.run.phase) {
            Ok(())
        } else {
            Err(self.refuse(name, allowed))
        }
    }

    /// The message of a call refused in this state (off the fast path).
    #[cold]
    fn refuse(&self, function: &str, allowed: PhaseSet) -> fmi2Status {
        if let Some(p) = &self.poisoned {
            return self.error(&format!("{function} refused: {p}"));
        }
        self.error(&format!(
            "{function} is not allowed in state '{}' (allowed in: {})",
            self.run.phase.name(),
            allowed.describe()
        ))
    }

    fn fail(&mut self, function: &str, e: ModelError) -> fmi2Status {
        self.run.phase = Phase::Error;
        let msg = format!("{function}: {e}");
        if e.severity() == Severity::Fatal {
            // Irreparable: every later call is refused until the instance is reset.
            self.logger.log(fmi2Status::FATAL, "logStatusError", &msg);
            self.poisoned = Some(msg);
            return fmi2Status::FATAL;
        }
        self.error(&msg)
    }

    pub fn setup_experiment(&mut self, start_time: f64, stop_time: Option<f64>) -> fmi2Status {
        if let Err(s) = self.require(Function::SetupExperiment) {
            return s;
        }
        if !start_time.is_finite() {
            return self.error(&format!(
                "fmi2SetupExperiment: startTime {start_time} is not finite"
            ));
        }
        if let Some(stop) = stop_time {
            if stop < start_time || stop.is_nan() {
                return self.error(&format!(
                    "fmi2SetupExperiment: stopTime {stop} is before startTime {start_time}"
                ));
            }
        }
        self.run.time = start_time;
        self.run.start_time = start_time;
        self.run.stop_time = stop_time;
        fmi2Status::OK
    }

    pub fn enter_initialization_mode(&mut self) -> fmi2Status {
        if let Err(s) = self.require(Function::EnterInitializationMode) {
            return s;
        }
        self.run.phase = Phase::InitializationMode;
        self.run.init_dirty = true;
        fmi2Status::OK
    }

    /// (Re)initialise the model from the current parameters and inputs if they changed.
    fn ensure_initialized(&mut self, function: &str) -> fmi2Status {
        if self.model.is_some() && !self.run.init_dirty {
            return fmi2Status::OK;
        }
        self.init_failed = false;
        match self.initialize_model() {
            Ok(()) => fmi2Status::OK,
            Err(e) => self.fail(function, e),
        }
    }

    /// Build the model from the variables as they are and calculate its outputs (no model
    /// when that fails).
    fn initialize_model(&mut self) -> Result<(), ModelError> {
        self.model = None;
        self.ctx.start_time = self.run.start_time;
        let mut m = M::initialize(&mut self.vars, &self.ctx)?;
        m.calculate_outputs(&mut self.vars);
        self.model = Some(m);
        self.run.initialized();
        Ok(())
    }

    /// A getter in initialization mode initialises the model lazily (a host propagating
    /// outputs to inputs reads them). A failure there is not the getter's: the values stay
    /// as they are and fmi2ExitInitializationMode, which initialises again, reports it once.
    fn try_initialize(&mut self) {
        if (self.model.is_some() || self.init_failed) && !self.run.init_dirty {
            return;
        }
        self.init_failed = self.initialize_model().is_err();
        self.run.init_dirty = false;
    }

    pub fn exit_initialization_mode(&mut self) -> fmi2Status {
        if let Err(s) = self.require(Function::ExitInitializationMode) {
            return s;
        }
        let s = self.ensure_initialized("fmi2ExitInitializationMode");
        if s == fmi2Status::OK {
            self.run.phase = Phase::StepComplete;
            self.event("initialized");
        }
        s
    }

    pub fn terminate(&mut self) -> fmi2Status {
        // Hosts (OMSimulator, libcosim) end an instance whose initialisation or step failed
        // with fmi2Terminate. FMI 2.0 allows only fmi2Reset and fmi2FreeInstance there; the
        // call changes nothing, so it is answered with a warning instead of an error and the
        // instance stays where it is (ready to be freed or reset).
        if self.poisoned.is_some()
            || matches!(
                self.run.phase,
                Phase::Error | Phase::Instantiated | Phase::InitializationMode
            )
        {
            let why = self.poisoned.as_deref().unwrap_or(match self.run.phase {
                Phase::Error => "the instance is in the error state",
                _ => "the instance was never initialised",
            });
            self.warning(&format!(
                "fmi2Terminate in state '{}' ignored ({why}): FMI 2.0 allows only fmi2Reset or fmi2FreeInstance here",
                self.run.phase.name()
            ));
            return fmi2Status::WARNING;
        }
        if let Err(s) = self.require(Function::Terminate) {
            return s;
        }
        let r = match self.model.as_mut() {
            Some(m) => m.terminate(&self.vars),
            None => Ok(()),
        };
        if let Err(e) = r {
            return self.fail("fmi2Terminate", e);
        }
        self.run.phase = Phase::Terminated;
        fmi2Status::OK
    }

    /// fmi2Reset: back to freshly instantiated, start values restored.
    pub fn reset(&mut self) -> fmi2Status {
        self.vars = M::Vars::default();
        if let Some(f) = &self.fitted {
            f.apply(&mut self.vars);
        }
        self.model = None;
        self.run = RunState::INSTANTIATED;
        self.init_failed = false;
        self.poisoned = None;
        self.event("reset");
        fmi2Status::OK
    }

    pub fn do_step(&mut self, current_time: f64, step: f64) -> fmi2Status {
        if let Err(s) = self.require(Function::DoStep) {
            return s;
        }
        // A host that sums its steps overshoots by accumulated rounding (1e5 steps of 1 ms:
        // 1.1e-10 s past 100 s): a step may end up to 1e-9·max(|stopTime|, 1 s) past stopTime.
        let past_stop = self
            .run
            .stop_time
            .is_some_and(|stop| current_time + step > stop + 1e-9 * stop.abs().max(1.0));
        if step <= 0.0 || !step.is_finite() || !current_time.is_finite() || past_stop {
            return self.refuse_step(current_time, step);
        }
        if self.run.params_changed {
            self.run.params_changed = false;
            let r = match self.model.as_mut() {
                Some(m) => m.parameters_changed(&self.vars),
                None => Ok(()),
            };
            if let Err(e) = r {
                return self.fail("fmi2DoStep", e);
            }
        }
        let Some(m) = self.model.as_mut() else {
            return self.step_failed(current_time, ModelError::new("model not initialised"));
        };
        let internal = m.internal_steps(step);
        if internal.is_nan() || internal > MAX_INTERNAL_STEPS {
            return self.refuse_long_step(current_time, step, internal);
        }
        match m.do_step(&mut self.vars, current_time, step) {
            Ok(()) => {
                m.calculate_outputs(&mut self.vars);
                self.run.time = current_time + step;
                self.run.inputs_changed = false;
                fmi2Status::OK
            }
            Err(e) => self.step_failed(current_time, e),
        }
    }

    /// The message of a step refused for its arguments (off the fast path).
    #[cold]
    fn refuse_step(&self, current_time: f64, step: f64) -> fmi2Status {
        if step <= 0.0 || !step.is_finite() {
            return self.error(&format!(
                "fmi2DoStep: communicationStepSize must be positive and finite, got {step}"
            ));
        }
        if !current_time.is_finite() {
            return self.error(&format!(
                "fmi2DoStep: currentCommunicationPoint {current_time} is not finite"
            ));
        }
        let stop = self.run.stop_time.unwrap_or(f64::NAN);
        self.error(&format!(
            "fmi2DoStep: step from {current_time} by {step} ends after stopTime {stop}"
        ))
    }

    /// A step that would take more internal steps than the limit (off the fast path).
    #[cold]
    fn refuse_long_step(&self, current_time: f64, step: f64, internal: f64) -> fmi2Status {
        self.error(&format!(
            "fmi2DoStep: the step from {current_time} s by {step} s would take {internal:.3e} internal steps of model '{}', more than the {MAX_INTERNAL_STEPS:.0e} one step may take; refused (split it into shorter communication steps)",
            M::INFO.name
        ))
    }

    /// A step the model did not complete (off the fast path).
    #[cold]
    fn step_failed(&mut self, current_time: f64, e: ModelError) -> fmi2Status {
        if e.severity() == Severity::Discard {
            // The step was not completed: time stays at the last successful point and the
            // instance stays usable (read, terminate, reset, restore a state).
            let msg = format!("fmi2DoStep: at t = {current_time} s: {e}");
            self.logger
                .log(fmi2Status::DISCARD, "logStatusWarning", &msg);
            return fmi2Status::DISCARD;
        }
        let msg = format!("at t = {current_time} s: {e}");
        self.fail("fmi2DoStep", ModelError(msg, e.severity()))
    }
}

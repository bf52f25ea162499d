//! The safe FMI 2.0 Co-Simulation instance: call-order state machine, variable access with
//! causality/variability/range checks, stepping, FMU states. The FFI layer is a thin,
//! panic-guarded shell around this; tests and native hosts can use it directly.

use crate::context::Context;
use crate::fmi2::fmi2Status;
use crate::model::{Model, ModelError, Severity};
use crate::state::{StateReader, StateWriter};
use crate::variables::{Causality, ScalarType, Value, VarInfo, VarTable, Variability};
use std::path::PathBuf;
use tb_fmi::{Function, Phase, PhaseSet};

/// Log categories declared in modelDescription.xml, in bit order.
pub const LOG_CATEGORIES: &[(&str, &str)] = &[
    (
        "logStatusError",
        "Errors: bad calls, bad values, model failures",
    ),
    ("logStatusWarning", "Warnings"),
    ("logEvents", "Information: initialisation, resets, states"),
    ("logAll", "All of the above"),
];
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

/// A saved FMU state (fmi2GetFMUstate): the variables, the model and the run state.
#[derive(Clone)]
pub struct Snapshot<M: Model> {
    vars: M::Vars,
    model: Option<M>,
    run: RunState,
}

/// Where an instance stands, besides its variables and its model: the phase, the time and
/// what changed since the model last saw it. An FMU state saves and restores it whole, and
/// (de)serialises it in one place ([`RunState::write`], [`RunState::read`]).
#[derive(Clone, Copy, Debug, PartialEq)]
struct RunState {
    phase: Phase,
    time: f64,
    /// `startTime` of fmi2SetupExperiment (the model sees it as `Context::start_time`).
    start_time: f64,
    stop_time: Option<f64>,
    /// Parameters or inputs changed in initialization mode since the model was initialised.
    init_dirty: bool,
    /// Inputs set since the last step (feed-through outputs need recomputing).
    inputs_changed: bool,
    /// Tunable parameters set since the last step.
    params_changed: bool,
}

impl RunState {
    /// A freshly instantiated (or reset) instance.
    const INSTANTIATED: RunState = RunState {
        phase: Phase::Instantiated,
        time: 0.0,
        start_time: 0.0,
        stop_time: None,
        init_dirty: true,
        inputs_changed: false,
        params_changed: false,
    };

    /// Whether sets now are those of instantiated / initialization mode.
    #[inline(always)]
    fn initializing(&self) -> bool {
        matches!(self.phase, Phase::Instantiated | Phase::InitializationMode)
    }

    /// A variable was set (`init`: in instantiated / initialization mode): what must be
    /// redone before it takes effect.
    #[inline(always)]
    fn mark_set(&mut self, init: bool, is_input: bool) {
        if init {
            self.init_dirty = true;
        } else if is_input {
            self.inputs_changed = true;
        } else {
            self.params_changed = true;
        }
    }

    /// The model was (re)initialised from the variables as they are.
    fn initialized(&mut self) {
        self.init_dirty = false;
        self.inputs_changed = false;
        self.params_changed = false;
    }

    fn write(&self, w: &mut StateWriter) {
        w.u64(self.phase as u8 as u64);
        w.f64(self.time);
        w.f64(self.start_time);
        w.bool(self.stop_time.is_some());
        w.f64(self.stop_time.unwrap_or(0.0));
        w.bool(self.init_dirty);
        w.bool(self.inputs_changed);
        w.bool(self.params_changed);
    }

    fn read(r: &mut StateReader<'_>) -> Result<RunState, ModelError> {
        let p = r.u64()?;
        let phase = u8::try_from(p)
            .ok()
            .and_then(Phase::from_u8)
            .ok_or_else(|| ModelError::new(format!("bad phase {p}")))?;
        let time = r.f64()?;
        let start_time = r.f64()?;
        let has_stop = r.bool()?;
        let stop = r.f64()?;
        Ok(RunState {
            phase,
            time,
            start_time,
            stop_time: has_stop.then_some(stop),
            init_dirty: r.bool()?,
            inputs_changed: r.bool()?,
            params_changed: r.bool()?,
        })
    }
}

/// Per value reference, what get/set must check: precomputed so the numeric calls of
/// every step are a lookup and a few compares.
#[derive(Clone, Copy, Debug)]
struct Slot {
    index: u32,
    ty: ScalarType,
    has_start: bool,
    /// Settable in instantiated / initialization mode.
    settable_init: bool,
    /// Settable in step complete (inputs and tunable parameters).
    settable_run: bool,
    is_input: bool,
    min: f64,
    max: f64,
    /// A Real's byte offset in `M::Vars` (`usize::MAX`: not a Real).
    offset: usize,
}

impl Slot {
    /// Whether a get may read the variable (a calculated one has no value before
    /// initialisation).
    #[inline(always)]
    fn readable(&self, instantiated: bool) -> bool {
        self.has_start || !instantiated
    }

    /// Whether a set may write the variable (`init`: in instantiated / initialization mode).
    #[inline(always)]
    fn settable(&self, init: bool) -> bool {
        if init {
            self.settable_init
        } else {
            self.settable_run
        }
    }

    /// The rules every set obeys, as the fast path and [`Runtime::set`] both check them:
    /// settable now, finite, within min/max. A value they refuse may still be taken by
    /// [`Runtime::set`]'s exceptions (a rounding just outside an input's range, `range_check
    /// = 0`).
    #[inline(always)]
    fn accepts(&self, x: f64, init: bool) -> bool {
        self.settable(init) && x.is_finite() && (self.min..=self.max).contains(&x)
    }
}

const NO_SLOT: Slot = Slot {
    offset: usize::MAX,
    index: u32::MAX,
    ty: ScalarType::Real,
    has_start: false,
    settable_init: false,
    settable_run: false,
    is_input: false,
    min: f64::NEG_INFINITY,
    max: f64::INFINITY,
};

const STATE_MAGIC: &[u8; 8] = b"TBFMUST1";

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

    // ---- variables ----

    fn index(&self, function: &str, vr: u32) -> Result<usize, fmi2Status> {
        match self.vr_index.get(vr as usize) {
            Some(&i) if i > 0 => Ok(i as usize - 1),
            _ => Err(self.error(&format!(
                "{function}: unknown value reference {vr} (model '{}')",
                M::INFO.name
            ))),
        }
    }

    fn check_type(&self, function: &str, info: &VarInfo, ty: ScalarType) -> Result<(), fmi2Status> {
        if info.var_type().value_space() == ty.value_space() {
            Ok(())
        } else {
            Err(self.error(&format!(
                "{function}: variable '{}' (vr {}) is {}, not {}",
                info.name,
                info.value_reference,
                info.var_type().xml_name(),
                ty.xml_name()
            )))
        }
    }

    /// What every get does first: the state check, the array lengths, a pending (lazy)
    /// initialisation or output update. Returns whether the instance is only instantiated.
    #[inline(always)]
    fn before_get(&mut self, function: &str, vrs: usize, out: usize) -> Result<bool, fmi2Status> {
        self.require_named(function, Function::GetReal.allowed())?;
        if vrs != out {
            return Err(self.length_mismatch(function, vrs, out));
        }
        match self.run.phase {
            Phase::InitializationMode => self.try_initialize(),
            Phase::StepComplete if M::Vars::HAS_FEEDTHROUGH && self.run.inputs_changed => {
                if let Some(m) = self.model.as_mut() {
                    m.calculate_outputs(&mut self.vars);
                }
                self.run.inputs_changed = false;
            }
            _ => {}
        }
        Ok(self.run.phase == Phase::Instantiated)
    }

    /// Read variables of type `ty` into `out`, converted by `conv`.
    pub fn get<T>(
        &mut self,
        function: &str,
        ty: ScalarType,
        vrs: &[u32],
        out: &mut [T],
        conv: impl Fn(Value) -> T,
    ) -> fmi2Status {
        let instantiated = match self.before_get(function, vrs.len(), out.len()) {
            Ok(i) => i,
            Err(s) => return s,
        };
        for (k, &vr) in vrs.iter().enumerate() {
            match self.slots.get(vr as usize) {
                Some(sl) if sl.index != u32::MAX && sl.ty == ty && sl.readable(instantiated) => {
                    out[k] = conv(self.vars.get(sl.index as usize));
                }
                _ => return self.get_error(function, ty, vr),
            }
        }
        fmi2Status::OK
    }

    /// fmi2GetReal: [`Runtime::get`] with each value read straight from its field.
    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> fmi2Status {
        const F: &str = "fmi2GetReal";
        let instantiated = match self.before_get(F, vrs.len(), out.len()) {
            Ok(i) => i,
            Err(s) => return s,
        };
        let base = (&self.vars as *const M::Vars).cast::<u8>();
        for (k, &vr) in vrs.iter().enumerate() {
            match self.slots.get(vr as usize) {
                Some(sl) if sl.offset != usize::MAX && sl.readable(instantiated) => {
                    // SAFETY: `offset` is `offset_of!` of an f64 field of M::Vars
                    // (REAL_OFFSETS), so the pointer is in bounds and aligned.
                    out[k] = unsafe { base.add(sl.offset).cast::<f64>().read() };
                }
                // FMI 3.0's independent variable: the time (off the fast path).
                _ if self.independent_time == Some(vr) => out[k] = self.run.time,
                _ => return self.get_error(F, ScalarType::Real, vr),
            }
        }
        fmi2Status::OK
    }

    /// Expose the time as the variable of value reference
    /// [`Runtime::time_value_reference`] (FMI 3.0's independent variable): read by
    /// [`Runtime::get_real`], refused by every set.
    pub fn expose_time(&mut self) {
        self.independent_time = Some(self.time_value_reference());
    }

    /// fmi2SetReal: [`Runtime::set`] with each accepted value written straight to its
    /// field; the first value that needs more (a rounding outside its range, a refusal, a
    /// warning) and every later one go through [`Runtime::set`].
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> fmi2Status {
        const F: &str = "fmi2SetReal";
        if let Err(s) = self.before_set(F, vrs.len(), values.len()) {
            return s;
        }
        let init = self.run.initializing();
        let base = (&mut self.vars as *mut M::Vars).cast::<u8>();
        for (k, (&vr, &x)) in vrs.iter().zip(values).enumerate() {
            match self.slots.get(vr as usize) {
                Some(sl) if sl.offset != usize::MAX && sl.accepts(x, init) => {
                    // SAFETY: `offset` is `offset_of!` of an f64 field of M::Vars
                    // (REAL_OFFSETS), so the pointer is in bounds and aligned.
                    unsafe { base.add(sl.offset).cast::<f64>().write(x) };
                    self.run.mark_set(init, sl.is_input);
                }
                _ => {
                    return self.set(
                        F,
                        ScalarType::Real,
                        &vrs[k..],
                        values[k..].iter().map(|&x| Value::Real(x)),
                    )
                }
            }
        }
        fmi2Status::OK
    }

    /// The message of a refused get (off the fast path).
    #[cold]
    fn get_error(&self, function: &str, ty: ScalarType, vr: u32) -> fmi2Status {
        let i = match self.index(function, vr) {
            Ok(i) => i,
            Err(s) => return s,
        };
        let info = &M::Vars::VARIABLES[i];
        if let Err(s) = self.check_type(function, info, ty) {
            return s;
        }
        self.error(&format!(
            "{function}: '{}' is calculated and has no value before initialization",
            info.name
        ))
    }

    /// What every set does first: the state check and the array lengths.
    #[inline(always)]
    fn before_set(&self, function: &str, vrs: usize, values: usize) -> Result<(), fmi2Status> {
        self.require_named(function, Function::SetReal.allowed())?;
        if vrs != values {
            return Err(self.length_mismatch(function, vrs, values));
        }
        Ok(())
    }

    #[cold]
    fn length_mismatch(&self, function: &str, vrs: usize, values: usize) -> fmi2Status {
        self.error(&format!(
            "{function}: {vrs} value references but {values} values"
        ))
    }

    /// Set variables of type `ty` from `values`, each checked for causality, variability,
    /// finiteness and declared min/max.
    pub fn set(
        &mut self,
        function: &str,
        ty: ScalarType,
        vrs: &[u32],
        values: impl ExactSizeIterator<Item = Value>,
    ) -> fmi2Status {
        if let Err(s) = self.before_set(function, vrs.len(), values.len()) {
            return s;
        }
        let init = self.run.initializing();
        let mut status = fmi2Status::OK;
        for (&vr, value) in vrs.iter().zip(values) {
            let sl = match self.slots.get(vr as usize) {
                Some(sl) if sl.index != u32::MAX && sl.ty == ty => *sl,
                _ => return self.set_error(function, ty, vr, value),
            };
            let value = if sl.accepts(value.as_f64(), init) {
                value
            } else {
                match self.accept_out_of_range(function, &sl, value, init) {
                    Some((value, s)) => {
                        if s == fmi2Status::WARNING {
                            status = s;
                        }
                        value
                    }
                    None => return self.set_error(function, ty, vr, value),
                }
            };
            self.vars.set(sl.index as usize, value);
            self.run.mark_set(init, sl.is_input);
        }
        status
    }

    /// The exceptions to [`Slot::accepts`], for a finite value of an input that may be set
    /// now: a Real a hair outside its range (a host's float32 rounding: 1 arrives as
    /// 1.0000000149011612) is taken as the bound, up to RANGE_SLACK of the bound's size (at
    /// least of 1) beyond it; with `range_check` = 0 any value is used as it is, with a
    /// warning. `None`: refused.
    #[cold]
    fn accept_out_of_range(
        &self,
        function: &str,
        sl: &Slot,
        value: Value,
        init: bool,
    ) -> Option<(Value, fmi2Status)> {
        let x = value.as_f64();
        if !(sl.settable(init) && sl.is_input && x.is_finite()) {
            return None;
        }
        if sl.ty == ScalarType::Real {
            let slack = |b: f64| RANGE_SLACK * b.abs().max(1.0);
            if x < sl.min && sl.min - x <= slack(sl.min) {
                return Some((Value::Real(sl.min), fmi2Status::OK));
            }
            if x > sl.max && x - sl.max <= slack(sl.max) {
                return Some((Value::Real(sl.max), fmi2Status::OK));
            }
        }
        if self.range_checked() {
            return None;
        }
        self.logger.log(
            fmi2Status::WARNING,
            "logStatusWarning",
            &format!(
                "{function}: '{}' = {x} is outside its range [{}, {}]; used as it is (range_check = 0)",
                M::Vars::VARIABLES[sl.index as usize].name,
                sl.min,
                sl.max
            ),
        );
        Some((value, fmi2Status::WARNING))
    }

    /// Whether inputs outside their range are refused (no `range_check`, or it is not 0).
    fn range_checked(&self) -> bool {
        self.range_check
            .is_none_or(|i| self.vars.get(i).as_f64() != 0.0)
    }

    /// The message of a refused set (off the fast path).
    #[cold]
    fn set_error(&self, function: &str, ty: ScalarType, vr: u32, value: Value) -> fmi2Status {
        if self.independent_time == Some(vr) {
            return self.error(&format!(
                "{function}: the independent variable 'time' cannot be set (vr {vr})"
            ));
        }
        let i = match self.index(function, vr) {
            Ok(i) => i,
            Err(s) => return s,
        };
        let info = &M::Vars::VARIABLES[i];
        if let Err(s) = self.check_type(function, info, ty) {
            return s;
        }
        if !self.slots[vr as usize].settable(self.run.initializing()) {
            return self.error(&format!(
                "{function}: '{}' ({} {}) cannot be set in state '{}'",
                info.name,
                info.variability.xml_name(),
                info.causality.xml_name(),
                self.run.phase.name()
            ));
        }
        if let Value::Real(r) = value {
            if !r.is_finite() {
                return self.error(&format!(
                    "{function}: '{}' set to {r}, expected a finite number",
                    info.name
                ));
            }
        }
        if let Some(t) = info.enumeration {
            return self.error(&format!(
                "{function}: '{}' = {} is not an item of the Enumeration {} ({})",
                info.name,
                value.xml_text(),
                t.name,
                t.listed()
            ));
        }
        self.error(&format!(
            "{function}: '{}' = {} is outside its range [{}, {}]{}",
            info.name,
            value.xml_text(),
            info.min
                .map_or("-inf".into(), crate::variables::format_real),
            info.max.map_or("inf".into(), crate::variables::format_real),
            info.unit.map(|u| format!(" {u}")).unwrap_or_default()
        ))
    }

    /// Read String variables; `out(k, value)` receives the value of `vrs[k]`.
    pub fn get_strings(
        &mut self,
        function: &str,
        vrs: &[u32],
        mut out: impl FnMut(usize, &str),
    ) -> fmi2Status {
        if let Err(s) = self.require_named(function, Function::GetString.allowed()) {
            return s;
        }
        if self.run.phase == Phase::InitializationMode {
            self.try_initialize();
        }
        let instantiated = self.run.phase == Phase::Instantiated;
        for (k, &vr) in vrs.iter().enumerate() {
            match self.slots.get(vr as usize) {
                Some(sl)
                    if sl.index != u32::MAX
                        && sl.ty == ScalarType::String
                        && sl.readable(instantiated) =>
                {
                    out(k, self.vars.get_str(sl.index as usize).unwrap_or(""));
                }
                _ => return self.get_error(function, ScalarType::String, vr),
            }
        }
        fmi2Status::OK
    }

    /// Set String variables, each checked for causality, variability and state.
    pub fn set_strings(&mut self, function: &str, vrs: &[u32], values: &[&str]) -> fmi2Status {
        if let Err(s) = self.require_named(function, Function::SetString.allowed()) {
            return s;
        }
        if vrs.len() != values.len() {
            return self.error(&format!(
                "{function}: {} value references but {} values",
                vrs.len(),
                values.len()
            ));
        }
        let init = self.run.initializing();
        for (&vr, value) in vrs.iter().zip(values) {
            let sl = match self.slots.get(vr as usize) {
                Some(sl) if sl.index != u32::MAX && sl.ty == ScalarType::String => *sl,
                _ => return self.set_error(function, ScalarType::String, vr, Value::Str("")),
            };
            if !sl.settable(init) {
                return self.set_error(function, ScalarType::String, vr, Value::Str(""));
            }
            self.vars.set_str(sl.index as usize, value);
            self.run.mark_set(init, sl.is_input);
        }
        fmi2Status::OK
    }

    /// Set one String variable by name (tests and native hosts).
    pub fn set_string_by_name(&mut self, name: &str, value: &str) -> fmi2Status {
        match M::Vars::vr_of(name) {
            Some(vr) => self.set_strings("set", &[vr], &[value]),
            None => self.error(&format!(
                "no variable named '{name}' in model '{}'",
                M::INFO.name
            )),
        }
    }

    /// Read one String variable by name (tests and native hosts).
    pub fn get_string_by_name(&mut self, name: &str) -> Option<String> {
        let vr = M::Vars::vr_of(name)?;
        let mut value = None;
        (self.get_strings("get", &[vr], |_, s| value = Some(s.to_string())) == fmi2Status::OK)
            .then_some(value)
            .flatten()
    }

    /// Set one variable by name (tests and native hosts).
    pub fn set_by_name(&mut self, name: &str, value: Value) -> fmi2Status {
        if let Value::Str(s) = value {
            return self.set_string_by_name(name, s);
        }
        match M::Vars::vr_of(name) {
            Some(vr) => self.set("set", value.var_type(), &[vr], std::iter::once(value)),
            None => self.error(&format!(
                "no variable named '{name}' in model '{}'",
                M::INFO.name
            )),
        }
    }

    /// Read one variable by name (tests and native hosts).
    pub fn get_by_name(&mut self, name: &str) -> Option<Value> {
        let i = M::Vars::index_of(name)?;
        let vr = M::Vars::VARIABLES[i].value_reference;
        let ty = M::Vars::VARIABLES[i].var_type().value_space();
        let mut out = [Value::Real(0.0)];
        (self.get("get", ty, &[vr], &mut out, |v| v) == fmi2Status::OK).then_some(out[0])
    }

    // ---- FMU states ----

    pub fn snapshot(&self) -> Result<Snapshot<M>, fmi2Status> {
        if let Some(p) = &self.poisoned {
            return Err(self.error(&format!("fmi2GetFMUstate refused: {p}")));
        }
        Ok(Snapshot {
            vars: self.vars.clone(),
            model: self.model.clone(),
            run: self.run,
        })
    }

    /// Overwrite `snap` in place (reuses its allocation where the types allow).
    pub fn snapshot_into(&self, snap: &mut Snapshot<M>) -> fmi2Status {
        if let Some(p) = &self.poisoned {
            return self.error(&format!("fmi2GetFMUstate refused: {p}"));
        }
        snap.vars.clone_from(&self.vars);
        snap.model.clone_from(&self.model);
        snap.run = self.run;
        fmi2Status::OK
    }

    pub fn restore(&mut self, snap: &Snapshot<M>) -> fmi2Status {
        if snap.run.phase == Phase::Error {
            return self.error("fmi2SetFMUstate: the state was saved in the error state");
        }
        self.vars.clone_from(&snap.vars);
        self.model.clone_from(&snap.model);
        self.run = snap.run;
        self.poisoned = None;
        fmi2Status::OK
    }

    /// Serialize a snapshot: magic, GUID, run state, variables, model state.
    pub fn serialize(&self, snap: &Snapshot<M>) -> Vec<u8> {
        let mut w = StateWriter::default();
        w.bytes.extend_from_slice(STATE_MAGIC);
        w.bytes(self.guid.as_bytes());
        snap.run.write(&mut w);
        for i in 0..M::Vars::VARIABLES.len() {
            match snap.vars.get(i) {
                Value::Real(x) => w.f64(x),
                Value::Integer(x) => w.i32(x),
                Value::Boolean(x) => w.bool(x),
                Value::Str(_) => w.bytes(snap.vars.get_str(i).unwrap_or("").as_bytes()),
            }
        }
        w.bool(snap.model.is_some());
        if let Some(m) = &snap.model {
            m.save_state(&mut w);
        }
        w.bytes
    }

    /// Rebuild a snapshot from bytes written by [`Runtime::serialize`]. The model part is
    /// re-initialised from the saved parameters (loading resources) and then overwritten.
    pub fn deserialize(&self, bytes: &[u8]) -> Result<Snapshot<M>, fmi2Status> {
        if bytes.len() < 8 || &bytes[..8] != STATE_MAGIC {
            return Err(self.error(
                "fmi2DeSerializeFMUstate: not a serialized twinbench FMU state (bad magic)",
            ));
        }
        self.read_snapshot(&mut StateReader::new(&bytes[8..]))
            .map_err(|m| self.error(&format!("fmi2DeSerializeFMUstate: {}", m.0)))
    }

    /// What [`Runtime::deserialize`] reads after the magic.
    fn read_snapshot(&self, r: &mut StateReader<'_>) -> Result<Snapshot<M>, ModelError> {
        let guid = r.bytes()?;
        if guid != self.guid.as_bytes() {
            return Err(ModelError::new(format!(
                "state belongs to another model (GUID {}, this FMU is {})",
                String::from_utf8_lossy(guid),
                self.guid
            )));
        }
        let run = RunState::read(r)?;
        let vars = read_variables::<M::Vars>(r)?;
        let model = if r.bool()? {
            let mut scratch = vars.clone();
            let mut ctx = self.ctx.clone();
            ctx.start_time = run.start_time;
            let mut m = M::initialize(&mut scratch, &ctx)?;
            m.load_state(r)?;
            Some(m)
        } else {
            None
        };
        if !r.is_at_end() {
            return Err(ModelError::new(
                "trailing bytes after the model state".to_string(),
            ));
        }
        Ok(Snapshot { vars, model, run })
    }

    pub fn last_successful_time(&self) -> f64 {
        self.run.time
    }
}

/// Every variable of a serialized state, in table order.
fn read_variables<V: VarTable>(r: &mut StateReader<'_>) -> Result<V, ModelError> {
    let mut vars = V::default();
    for (i, info) in V::VARIABLES.iter().enumerate() {
        let v = match info.var_type() {
            ScalarType::Real => Value::Real(r.f64()?),
            ScalarType::Integer | ScalarType::Enumeration => Value::Integer(r.i32()?),
            ScalarType::Boolean => Value::Boolean(r.bool()?),
            ScalarType::String => {
                let text = std::str::from_utf8(r.bytes()?).map_err(|_| {
                    ModelError::new(format!("'{}': the saved string is not UTF-8", info.name))
                })?;
                vars.set_str(i, text);
                continue;
            }
        };
        vars.set(i, v);
    }
    Ok(vars)
}

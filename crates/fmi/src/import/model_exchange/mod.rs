//! FMI 2.0 Model Exchange: an instance that twinbench integrates itself, with SUNDIALS
//! CVODE ([`cvode`]) between communication points, so that to the master it is one more
//! Co-Simulation unit: [`MeInstance::do_step`]`(t, h)` integrates from t to t + h and
//! handles the events inside (FMI 2.0 §3.1, the calling sequence of §3.2.3):
//!
//! - **time events**: the integration stops at `nextEventTime` of the last
//!   `fmi2NewDiscreteStates`;
//! - **state events**: CVODE's root finding on the event indicators
//!   (`fmi2GetEventIndicators`) stops it where one changes sign;
//! - **step events**: `fmi2CompletedIntegratorStep` after each integration (unless the FMU
//!   says `completedIntegratorStepNotNeeded`) may ask for event mode, or to terminate;
//! - **event iteration**: `fmi2EnterEventMode`, then `fmi2NewDiscreteStates` until
//!   `newDiscreteStatesNeeded` is false, then `fmi2EnterContinuousTimeMode`; CVODE then
//!   starts again from the states after the event (after every event, as FMPy does, which
//!   covers `valuesOfContinuousStatesChanged`), with new absolute tolerances when
//!   `nominalsOfContinuousStatesChanged`;
//! - **terminateSimulation** ends the run at the time reached (the master is told as by a
//!   Co-Simulation FMU: the step reports `fmi2Discard`, [`MeInstance::terminated_by_fmu`]
//!   gives the time);
//! - **inputs**: a continuous Real input may be set in continuous-time mode (FMI 2.0
//!   §3.2.3); a changed one restarts CVODE at the next step (the inputs are held over a
//!   communication step: the trajectory has a kink there), after handling an event when an
//!   event indicator changed sign with it. Any other variable (a discrete input, a
//!   parameter) may be set in event mode only: the instance enters event mode for it, and
//!   the event iteration runs before the next get or step.
//!
//! The solver is set up as FMPy 0.3.32's `simulate_fmu(..., fmi_type='ModelExchange',
//! solver='CVode')`: BDF, Newton, the dense linear solver, relative tolerance = the
//! system's, else the DefaultExperiment's, else 1e-5 (FMPy's `simulateME` default); the
//! absolute tolerance of each state its nominal (`fmi2GetNominalsOfContinuousStates`)
//! times the relative tolerance; the largest step (stop − start)/50; at most 500 internal
//! steps per integration; an FMU without continuous states gets one dummy state (ẋ = 0), so
//! that root finding still watches its event indicators.

mod calls;
pub(crate) mod cvode;
mod system;
mod unit;

use super::instance::Instance;
use super::instance3::Instance3;
use super::model::ModelDescription;
use crate::fmi2::*;
use crate::functions::Function;
use crate::{Causality, FmuError, Variability};
pub use calls::CallTrace;
use calls::{shown_values, Call, EventUpdate, MeCalls, Vector};
use cvode::{Cvode, Reached, Settings};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use system::FmuSystem;
pub use unit::MeLibrary;
use unit::Unit;

/// Whether this build integrates Model Exchange FMUs: SUNDIALS CVODE was found when it was
/// built (else an instance is refused at instantiation with what to install).
pub const SOLVER_AVAILABLE: bool = cvode::AVAILABLE;

/// FMPy's relative tolerance when neither the system nor the FMU gives one.
pub const DEFAULT_RELATIVE_TOLERANCE: f64 = 1e-5;
/// The most internal steps of one integration (FMPy's, CVODE's default).
pub const MAX_NUM_STEPS: i64 = 500;
/// The most event iterations (`fmi2NewDiscreteStates` calls) of one event, and the most
/// events at one time: beyond, the FMU does not settle and the run stops with an error.
pub const MAX_EVENT_ITERATIONS: usize = 10_000;
/// The most event indicators and continuous states accepted (a description is untrusted:
/// a huge count would allocate that much).
pub const MAX_SIZE: usize = 1 << 20;
/// The most continuous states integrated: the solver's Jacobian is dense (n² numbers, and
/// n difference quotients per evaluation), so 15,000 states took 3.5 GB and 50 s for 0.01 s
/// (M12). 4,000 states are 128 MB.
pub const MAX_STATES: usize = 4000;

/// What an instance's solver is given by the system.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MeSettings {
    /// The solver's relative tolerance (None: the FMU's DefaultExperiment tolerance, else
    /// [`DEFAULT_RELATIVE_TOLERANCE`]).
    pub relative_tolerance: Option<f64>,
}

impl MeSettings {
    /// The relative tolerance for an FMU: the system's, the FMU's DefaultExperiment's,
    /// FMPy's default, in this order.
    pub fn relative_tolerance_for(&self, md: &ModelDescription) -> f64 {
        self.relative_tolerance
            .or(md.default_experiment.and_then(|d| d.tolerance))
            .unwrap_or(DEFAULT_RELATIVE_TOLERANCE)
    }
}

/// FMPy's `isclose` (Python's `math.isclose` with its default relative tolerance 1e-9).
pub fn isclose(a: f64, b: f64) -> bool {
    isclose_in(a, b, f64::INFINITY)
}

/// Two times are one: FMPy's `isclose` (relative 1e-9) where the times are within `span`
/// of 0 (every run that starts at 0: the same decisions as FMPy), and never coarser than
/// 1e-9 of `span` (the run's length): at a start time of 1.7e9 s (a Unix time) a relative
/// 1e-9 would be 1.7 s wide (M7). An infinite time is close only to itself (M6).
pub fn isclose_in(a: f64, b: f64, span: f64) -> bool {
    if a == b {
        return true;
    }
    if !(a.is_finite() && b.is_finite()) {
        return false;
    }
    (a - b).abs() <= 1e-9 * a.abs().max(b.abs()).min(span)
}

/// Where the instance is in the Model Exchange state machine (FMI 2.0 §3.2.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Mode {
    Instantiated,
    Initialization,
    Event,
    ContinuousTime,
    Terminated,
}

/// One FMI 2.0 Model Exchange instance with its integrator. Its calls are those of a
/// Co-Simulation [`Instance`] (the backend of a system instance); errors are
/// [`FmuError::ModelExchange`], naming the .fmu, the instance, the time and the call.
pub struct MeInstance {
    /// Declared first: the integrator (which calls the FMU) goes before the instance.
    solver: Option<Cvode<FmuSystem>>,
    inst: Unit,
    api: MeCalls,
    fmu: PathBuf,
    nx: usize,
    nz: usize,
    rtol: f64,
    /// The tolerance the FMU is told in `fmi2SetupExperiment`: the system's, when it gave one.
    told_tolerance: Option<f64>,
    completed_step_needed: bool,
    /// The continuous Real inputs (settable in continuous-time mode).
    continuous_inputs: HashMap<u32, ()>,
    /// The derivatives' names in state order (`der(x)`), for messages.
    derivative_names: Vec<String>,
    mode: Mode,
    start: f64,
    stop: Option<f64>,
    next_event: Option<f64>,
    /// The states (at least one: the dummy of an FMU without states), nominals and the
    /// absolute tolerances.
    x: Vec<f64>,
    atol: Vec<f64>,
    /// The event indicators at the end of the last step, roots found.
    z: Vec<f64>,
    roots: Vec<i32>,
    /// The continuous inputs' values as last set (bits), and whether one changed since the
    /// integrator last started.
    inputs: HashMap<u32, u64>,
    inputs_changed: bool,
    /// Event mode entered for a set that needs it; the iteration runs before the next call.
    event_pending: bool,
    /// Set when the FMU asked to end the simulation: the time reached.
    terminated_at: Option<f64>,
    /// The end of the step under way ([`MeInstance::step_to_event`] stopped at an event
    /// before it), the events at one time so far, and an event found but not yet handled
    /// (with the time its integration started from).
    step_target: Option<f64>,
    /// The call trace ([`MeInstance::set_call_trace`]).
    trace: Option<CallTrace>,
    events_here: usize,
    event_detected: bool,
    event_start: f64,
    /// The times of the events handled since initialisation (the first [`MAX_EVENTS_KEPT`]).
    events: Vec<f64>,
}

/// Where [`MeInstance::step_to_event`] stopped.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MeStop {
    /// The end of the step.
    Reached,
    /// An event at this time, not yet handled: the values are its left limits.
    BeforeEvent(f64),
    /// The event at this time handled, before the end of the step.
    AfterEvent(f64),
}

/// The most event times an instance keeps ([`MeInstance::events`]).
pub const MAX_EVENTS_KEPT: usize = 100_000;

// One instance is used by one thread at a time; FMI 2.0 allows moving it between threads,
// and CVODE's memory belongs to this instance alone.
unsafe impl Send for MeInstance {}

impl MeInstance {
    /// Instantiate an FMU for Model Exchange: `lib` loaded with
    /// [`Library::load_model_exchange`], `md` its description, `fmu` the .fmu (for
    /// messages).
    pub fn instantiate(
        lib: impl Into<MeLibrary>,
        md: &ModelDescription,
        fmu: &Path,
        name: &str,
        resource_dir: Option<&Path>,
        logging_on: bool,
        settings: MeSettings,
    ) -> Result<MeInstance, FmuError> {
        let bad = |message: String| FmuError::Instantiate {
            instance: name.into(),
            message,
        };
        if !SOLVER_AVAILABLE {
            return Err(bad(format!(
                "{}: a Model Exchange FMU, but {}",
                fmu.display(),
                cvode::MISSING
            )));
        }
        let lib = lib.into();
        let not_loaded = || bad("the library was not loaded for Model Exchange".into());
        let api = match &lib {
            MeLibrary::V2(l) => MeCalls::V2(l.me.ok_or_else(not_loaded)?),
            MeLibrary::V3(l) => MeCalls::V3(l.me.ok_or_else(not_loaded)?),
        };
        let me = md
            .model_exchange
            .as_ref()
            .ok_or_else(|| bad(format!("{}: no <ModelExchange> element", fmu.display())))?;
        let (nx, nz) = (
            md.number_of_continuous_states(),
            md.number_of_event_indicators,
        );
        if nx > MAX_SIZE || nz > MAX_SIZE {
            return Err(bad(format!(
                "{}: {nx} continuous states and {nz} event indicators; twinbench integrates at most {MAX_SIZE} of each",
                fmu.display()
            )));
        }
        if nx > MAX_STATES {
            return Err(bad(format!(
                "{}: {nx} continuous states; twinbench's Model Exchange solver uses a dense Jacobian ({:.1} GB for these) and integrates at most {MAX_STATES} states: run the FMU as Co-Simulation if it has that interface",
                fmu.display(),
                (nx as f64).powi(2) * 8.0 / 1e9
            )));
        }
        let rtol = settings.relative_tolerance_for(md);
        if !(rtol.is_finite() && rtol > 0.0 && rtol < 1.0) {
            return Err(bad(format!(
                "the relative tolerance {rtol:e} of the Model Exchange solver is not in (0, 1)"
            )));
        }
        let inst = match lib {
            MeLibrary::V2(lib) => Unit::V2(Instance::instantiate_as(
                lib,
                name,
                &md.guid,
                resource_dir,
                logging_on,
                fmi2Type::MODEL_EXCHANGE,
            )?),
            MeLibrary::V3(lib) => Unit::V3(Instance3::instantiate_as(
                lib,
                md,
                name,
                resource_dir,
                logging_on,
                true,
            )?),
        };
        if let MeCalls::V3(calls) = api {
            // FMI 3.0 declares no counts: they are the elements of the model structure's
            // derivatives and event indicators (an array counts by its elements, its
            // dimensions from their start values). An FMU that says otherwise would have
            // its vectors read short or past their end.
            let fmu_counts = [
                (
                    calls.get_number_of_continuous_states,
                    nx,
                    "fmi3GetNumberOfContinuousStates",
                    "continuous states (the elements of its <ContinuousStateDerivative> variables)",
                ),
                (
                    calls.get_number_of_event_indicators,
                    nz,
                    "fmi3GetNumberOfEventIndicators",
                    "event indicators (the elements of its <EventIndicator> variables)",
                ),
            ];
            for (get, declared, call, what) in fmu_counts {
                let mut n = 0usize;
                let s = unsafe { get(inst.raw(), &mut n) };
                if s > 1 {
                    return Err(bad(format!(
                        "{}: {call} returned {}",
                        fmu.display(),
                        api.status_name(fmi2Status(s))
                    )));
                }
                if n != declared {
                    return Err(bad(format!(
                        "{}: the model description declares {declared} {what}, but {call} returns {n}",
                        fmu.display()
                    )));
                }
            }
        }
        let continuous_inputs = md
            .variables
            .iter()
            .filter(|v| {
                v.causality == Causality::Input
                    && v.variability == Variability::Continuous
                    && v.ty == crate::ScalarType::Real
            })
            .map(|v| (v.value_reference, ()))
            .collect();
        let derivative_names = (0..nx)
            .map(|k| {
                md.derivatives
                    .get(k)
                    .and_then(|u| md.variables.get(u.index.wrapping_sub(1)))
                    .map_or_else(
                        || format!("derivative {} of {nx}", k + 1),
                        |v| v.name.clone(),
                    )
            })
            .collect();
        let n = nx.max(1);
        Ok(MeInstance {
            solver: None,
            inst,
            api,
            fmu: fmu.to_path_buf(),
            nx,
            nz,
            rtol,
            told_tolerance: settings.relative_tolerance,
            completed_step_needed: !me.completed_integrator_step_not_needed,
            continuous_inputs,
            derivative_names,
            mode: Mode::Instantiated,
            start: 0.0,
            stop: None,
            next_event: None,
            x: vec![1.0; n],
            atol: vec![rtol; n],
            z: vec![0.0; nz],
            roots: vec![0; nz],
            inputs: HashMap::new(),
            inputs_changed: false,
            event_pending: false,
            terminated_at: None,
            step_target: None,
            trace: None,
            events_here: 0,
            event_detected: false,
            event_start: 0.0,
            events: Vec::new(),
        })
    }

    /// The times of the events handled since initialisation (time, state, step and input
    /// events, after the initial one; at most [`MAX_EVENTS_KEPT`]).
    pub fn events(&self) -> &[f64] {
        &self.events
    }

    pub fn name(&self) -> &str {
        self.inst.name()
    }

    /// The FMU's time (for messages).
    pub fn time(&self) -> f64 {
        self.inst.time()
    }

    /// The solver's relative tolerance.
    pub fn relative_tolerance(&self) -> f64 {
        self.rtol
    }

    pub fn last_log_lines(&self) -> Vec<String> {
        self.inst.last_log_lines()
    }

    pub fn set_echo(&mut self, on: bool) {
        self.inst.set_echo(on)
    }

    /// An error of this instance's `call`.
    #[cold]
    fn error(&self, call: &str, problem: String) -> FmuError {
        FmuError::ModelExchange {
            fmu: self.fmu.clone().into_boxed_path(),
            instance: self.inst.name().to_string(),
            time: self.inst.time(),
            call: call.into(),
            problem,
            log: self.inst.last_log_lines(),
        }
    }

    /// A common call's error (from [`Instance`] or [`Instance3`]) as this instance's.
    fn wrap(&self, e: FmuError) -> FmuError {
        let (call, status, time, log): (Box<str>, String, f64, Vec<String>) = match e {
            FmuError::Call {
                function,
                status,
                time,
                log,
                ..
            } => (function.name().into(), status.to_string(), time, log),
            FmuError::Call3 {
                function,
                status,
                time,
                log,
                ..
            } => (function.into(), status, time, log),
            other => return other,
        };
        FmuError::ModelExchange {
            fmu: self.fmu.clone().into_boxed_path(),
            instance: self.inst.name().to_string(),
            time,
            call,
            problem: format!("returned {status}"),
            log,
        }
    }

    /// Report each FMI call the instance makes on its own (event mode, the event
    /// iteration, time, states, derivatives and event indicators, CVODE's callbacks
    /// included) to `trace`.
    pub fn set_call_trace(&mut self, trace: Option<CallTrace>) {
        self.trace = trace;
    }

    /// A Model Exchange call's status: OK and Warning go on.
    fn check(&self, call: &str, status: fmi2Status) -> Result<(), FmuError> {
        self.check_with(call, String::new, status)
    }

    /// As [`Self::check`], with the call's arguments for the trace.
    fn check_with(
        &self,
        call: &str,
        args: impl FnOnce() -> String,
        status: fmi2Status,
    ) -> Result<(), FmuError> {
        if let Some(trace) = &self.trace {
            trace(self.inst.time(), call, &args(), status);
        }
        match status.ok() {
            Ok(()) => Ok(()),
            Err(s) => Err(self.error(call, format!("returned {}", self.api.status_name(s)))),
        }
    }

    pub fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        self.inst.set_debug_logging(on).map_err(|e| self.wrap(e))
    }

    /// As FMPy 0.3.32's Model Exchange loop, `toleranceDefined = false` unless the system
    /// gives a tolerance (the instance's, the experiment's, `run --tolerance`): then the FMU
    /// is told it. Either way the solver integrates with [`MeInstance::relative_tolerance`].
    /// The run's length, the scale of its time comparisons ([`isclose_in`]): unbounded
    /// without a stop time.
    fn span(&self) -> f64 {
        self.stop
            .map_or(f64::INFINITY, |stop| (stop - self.start).abs().max(1.0))
    }

    pub fn setup_experiment(&mut self, start: f64, stop: Option<f64>) -> Result<(), FmuError> {
        self.start = start;
        self.stop = stop;
        let r = self.inst.setup_experiment(start, stop, self.told_tolerance);
        // FMI 3.0 has no such call: its arguments go with fmi3EnterInitializationMode.
        if let (Some(trace), false) = (&self.trace, self.api.is_fmi3()) {
            let stop = stop.map_or("undefined".to_string(), |s| format!("{s:?}"));
            let args = match self.told_tolerance {
                Some(tol) => format!("toleranceDefined=true, tolerance={tol:?}, startTime={start:?}, stopTime={stop}"),
                None => format!("toleranceDefined=false, startTime={start:?}, stopTime={stop}"),
            };
            let status = match &r {
                Ok(()) => fmi2Status::OK,
                Err(FmuError::Call { status, .. }) => *status,
                Err(_) => fmi2Status::ERROR,
            };
            trace(self.inst.time(), "fmi2SetupExperiment", &args, status);
        }
        r.map_err(|e| self.wrap(e))
    }

    pub fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.inst
            .enter_initialization_mode()
            .map_err(|e| self.wrap(e))?;
        self.mode = Mode::Initialization;
        Ok(())
    }

    /// Leave initialization mode: the FMU is then in event mode (FMI 2.0 §3.2.3), so the
    /// initial event iteration runs, then continuous-time mode is entered and the
    /// integrator starts at the start time.
    pub fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.inst
            .exit_initialization_mode()
            .map_err(|e| self.wrap(e))?;
        self.mode = Mode::Event;
        let info = self.iterate_discrete_states()?;
        if info.terminate {
            // As FMPy: an error ("Model requested termination during initial event update").
            return Err(self.error(
                self.api.name(Call::UpdateDiscreteStates),
                "set terminateSimulation in the initial event iteration, before the first step"
                    .into(),
            ));
        }
        self.enter_continuous_time_mode()?;
        self.start_solver()
    }

    pub fn terminate(&mut self) -> Result<(), FmuError> {
        self.solver = None;
        self.mode = Mode::Terminated;
        self.inst.terminate().map_err(|e| self.wrap(e))
    }

    pub fn reset(&mut self) -> Result<(), FmuError> {
        self.solver = None;
        self.events.clear();
        self.mode = Mode::Instantiated;
        self.next_event = None;
        self.terminated_at = None;
        self.step_target = None;
        self.event_detected = false;
        self.event_pending = false;
        self.inputs.clear();
        self.inputs_changed = false;
        self.inst.reset().map_err(|e| self.wrap(e))
    }

    /// After a step reported `fmi2Discard`: the time at which the FMU asked to end the
    /// simulation (`terminateSimulation`).
    pub fn terminated_by_fmu(&mut self) -> Option<f64> {
        self.terminated_at
    }

    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        self.settle()?;
        self.inst.get_real(vrs, out).map_err(|e| self.wrap(e))
    }

    pub fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.settle()?;
        self.inst.get_integer(vrs, out).map_err(|e| self.wrap(e))
    }

    pub fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.settle()?;
        self.inst.get_boolean(vrs, out).map_err(|e| self.wrap(e))
    }

    pub fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        self.settle()?;
        self.inst.get_string(vrs, out).map_err(|e| self.wrap(e))
    }

    /// Set Reals: continuous inputs as they are (a change restarts the integrator), any
    /// other in event mode.
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        let all_continuous = vrs.iter().all(|vr| self.continuous_inputs.contains_key(vr));
        if !all_continuous {
            self.event_mode_for_set()?;
        }
        self.inst.set_real(vrs, values).map_err(|e| self.wrap(e))?;
        for (vr, v) in vrs.iter().zip(values) {
            if self.continuous_inputs.contains_key(vr) {
                let old = self.inputs.insert(*vr, v.to_bits());
                self.inputs_changed |= old.is_some_and(|o| o != v.to_bits());
            }
        }
        Ok(())
    }

    pub fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.event_mode_for_set()?;
        self.inst.set_integer(vrs, values).map_err(|e| self.wrap(e))
    }

    pub fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.event_mode_for_set()?;
        self.inst.set_boolean(vrs, values).map_err(|e| self.wrap(e))
    }

    pub fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        self.event_mode_for_set()?;
        self.inst.set_string(vrs, values).map_err(|e| self.wrap(e))
    }

    /// Discrete inputs and tunable parameters may be set in event mode only (FMI 2.0
    /// §3.2.3): in continuous-time mode, enter it; the event iteration follows before the
    /// next get or step ([`MeInstance::settle`]).
    fn event_mode_for_set(&mut self) -> Result<(), FmuError> {
        if self.mode == Mode::ContinuousTime {
            let s = unsafe { self.api.enter_event_mode(self.inst.raw()) };
            self.check(self.api.name(Call::EnterEventMode), s)?;
            self.mode = Mode::Event;
            self.event_pending = true;
        }
        Ok(())
    }

    /// After sets in event mode: the event iteration, back to continuous-time mode, and the
    /// integrator started again.
    fn settle(&mut self) -> Result<(), FmuError> {
        if !self.event_pending {
            return Ok(());
        }
        self.event_pending = false;
        // Ended by the FMU: the master learns it at the step (terminated_at is set).
        self.event_iteration(false)?;
        Ok(())
    }

    /// `fmi2NewDiscreteStates` until the FMU needs no more (FMI 2.0 §3.2.2, the event
    /// iteration), or asks to terminate; the next time event from the last call.
    fn iterate_discrete_states(&mut self) -> Result<EventUpdate, FmuError> {
        let call = self.api.name(Call::UpdateDiscreteStates);
        let mut info = EventUpdate {
            needs_update: true,
            ..Default::default()
        };
        let mut nominals_changed = false;
        let mut iterations = 0;
        while info.needs_update && !info.terminate {
            iterations += 1;
            if iterations > MAX_EVENT_ITERATIONS {
                return Err(self.error(
                    call,
                    format!("still asks for new discrete states after {MAX_EVENT_ITERATIONS} iterations of one event (the event iteration does not converge)"),
                ));
            }
            let s;
            (s, info) = unsafe { self.api.update_discrete_states(self.inst.raw()) };
            let shown = || {
                format!(
                    "{}={}, terminateSimulation={}, nominalsOfContinuousStatesChanged={}, valuesOfContinuousStatesChanged={}, nextEventTimeDefined={}, nextEventTime={:?}",
                    self.api.needs_update_flag(),
                    info.needs_update,
                    info.terminate,
                    info.nominals_changed,
                    info.values_changed,
                    info.next_event_time_defined,
                    info.next_event_time
                )
            };
            self.check_with(call, shown, s)?;
            nominals_changed |= info.nominals_changed;
        }
        info.nominals_changed = nominals_changed;
        self.next_event = None;
        if info.next_event_time_defined {
            let te = info.next_event_time;
            let now = self.inst.time();
            // +inf: no time event (M6). A time event that is not a time, or one before now,
            // would have the integration loop wait for it for ever (M5).
            if te.is_nan() || te == f64::NEG_INFINITY {
                return Err(self.error(
                    call,
                    format!("nextEventTime = {te:?} is not a time (at t = {now:?} s)"),
                ));
            }
            if te < now && !isclose_in(te, now, self.span()) {
                return Err(self.error(
                    call,
                    format!(
                        "nextEventTime = {te:?} s lies before the current time {now:?} s: a time event must not be in the past"
                    ),
                ));
            }
            if te.is_finite() {
                self.next_event = Some(te);
            }
        }
        Ok(info)
    }

    fn enter_continuous_time_mode(&mut self) -> Result<(), FmuError> {
        let s = unsafe { self.api.enter_continuous_time_mode(self.inst.raw()) };
        self.check(self.api.name(Call::EnterContinuousTimeMode), s)?;
        self.mode = Mode::ContinuousTime;
        Ok(())
    }

    /// One event at the current time: event mode (unless already entered), the iteration,
    /// continuous-time mode, the integrator started again from the states after the event.
    /// True when the FMU asked to end the simulation.
    fn event_iteration(&mut self, enter: bool) -> Result<bool, FmuError> {
        if self.events.len() < MAX_EVENTS_KEPT {
            self.events.push(self.inst.time());
        }
        if enter {
            let s = unsafe { self.api.enter_event_mode(self.inst.raw()) };
            self.check(self.api.name(Call::EnterEventMode), s)?;
            self.mode = Mode::Event;
        }
        let info = self.iterate_discrete_states()?;
        if info.terminate {
            self.terminated_at = Some(self.inst.time());
            return Ok(true);
        }
        self.enter_continuous_time_mode()?;
        self.restart_solver(info.nominals_changed)?;
        Ok(false)
    }

    /// A vector the FMU fills (`fmi2GetContinuousStates`, ...), into `out`.
    fn get_vector(&self, v: Vector, out: &mut [f64]) -> Result<(), FmuError> {
        let s = unsafe { self.api.get(self.inst.raw(), v, out) };
        self.check_with(self.api.name(Call::Get(v)), || shown_values(out), s)
    }

    /// The states into `self.x` and, when `nominals`, the absolute tolerances from the
    /// nominals: rtol · nominal (FMPy; a nominal that is not a positive number counts as 1).
    fn read_states(&mut self, nominals: bool) -> Result<(), FmuError> {
        if self.nx == 0 {
            return Ok(());
        }
        let mut x = std::mem::take(&mut self.x);
        let r = self.get_vector(Vector::States, &mut x);
        self.x = x;
        r?;
        if nominals {
            let mut atol = std::mem::take(&mut self.atol);
            let r = self.get_vector(Vector::Nominals, &mut atol);
            for a in atol.iter_mut() {
                *a = self.rtol * if a.is_finite() && *a > 0.0 { *a } else { 1.0 };
            }
            self.atol = atol;
            r?;
        }
        Ok(())
    }

    /// The event indicators into `self.z`.
    fn read_indicators(&mut self) -> Result<(), FmuError> {
        if self.nz == 0 {
            return Ok(());
        }
        let mut z = std::mem::take(&mut self.z);
        let r = self.get_vector(Vector::EventIndicators, &mut z);
        self.z = z;
        r?;
        // A NaN indicator has no sign: its event could never be found.
        match self.z.iter().position(|v| v.is_nan()) {
            Some(k) => Err(self.error(
                self.api.name(Call::Get(Vector::EventIndicators)),
                format!(
                    "returned NaN for event indicator {} of {}, which has no sign to watch for a crossing",
                    k + 1,
                    self.nz
                ),
            )),
            None => Ok(()),
        }
    }

    /// A solver error as this instance's: the FMI call that failed inside CVODE's
    /// callbacks when one did, else CVODE's flag and message.
    fn solver_error(&mut self, e: cvode::SolverError) -> FmuError {
        if let Some(f) = self.solver.as_mut().and_then(|s| s.system().failure.take()) {
            self.inst.set_time(f.time);
            return self.error(
                f.call,
                format!(
                    "{} (called by CVODE, which then {})",
                    f.problem,
                    e.problem().trim_start_matches("returned ")
                ),
            );
        }
        // CVODE gave up on its own after retrying a failed call: that call is the likely
        // cause (a derivative that is NaN beyond some time makes it shrink its step to
        // nothing).
        if let Some(f) = self.solver.as_mut().and_then(|s| s.system().retried.take()) {
            return self.error(
                e.function,
                format!(
                    "{}; it had retried with ever smaller steps since {} {} at t = {} s",
                    e.problem(),
                    f.call,
                    f.problem,
                    f.time
                ),
            );
        }
        self.error(e.function, e.problem())
    }

    /// CVODE's warnings into the instance's log.
    fn log_solver_warnings(&mut self) {
        if let Some(s) = self.solver.as_mut() {
            for w in s.take_warnings() {
                self.inst
                    .sink()
                    .push(fmi2Status::WARNING, "CVODE", &format!("CVODE warning: {w}"));
            }
        }
    }

    /// The integrator, created at the current time from the FMU's states.
    fn start_solver(&mut self) -> Result<(), FmuError> {
        self.solver = None;
        self.read_states(true)?;
        self.read_indicators()?;
        let max_step = match self.stop {
            Some(stop) if stop > self.start => (stop - self.start) / 50.0,
            _ => 0.0,
        };
        let settings = Settings {
            relative_tolerance: self.rtol,
            max_step,
            max_num_steps: MAX_NUM_STEPS,
        };
        let system = FmuSystem::new(
            self.inst.raw(),
            self.api,
            self.derivative_names.clone(),
            self.trace.clone(),
        );
        let solver = Cvode::new(
            system,
            self.inst.time(),
            &self.x,
            &self.atol,
            self.nz,
            settings,
        )
        .map_err(|e| self.error(e.function, e.problem()))?;
        self.solver = Some(solver);
        self.inputs_changed = false;
        Ok(())
    }

    /// The integrator started again at the current time from the FMU's states (after an
    /// event or a changed input).
    fn restart_solver(&mut self, nominals_changed: bool) -> Result<(), FmuError> {
        self.read_states(nominals_changed)?;
        self.read_indicators()?;
        self.inputs_changed = false;
        let (t, rtol) = (self.inst.time(), self.rtol);
        let Some(solver) = self.solver.as_mut() else {
            return self.start_solver();
        };
        let atol = nominals_changed.then_some((self.atol.as_slice(), rtol));
        let r = solver.reinit(t, &self.x, atol);
        r.map_err(|e| self.solver_error(e))
    }

    /// Integrate from the current time to `t + h` (FMPy's `simulateME` loop between two
    /// output points), handling every event on the way. When the FMU asks to end the
    /// simulation the step reports `fmi2Discard` and [`MeInstance::terminated_by_fmu`]
    /// gives the time reached.
    pub fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        while self.advance(t, h, false)? != MeStop::Reached {}
        Ok(())
    }

    /// As [`MeInstance::do_step`], but stopping at each event twice, as FMPy's
    /// `record_events` samples it: before it is handled ([`MeStop::BeforeEvent`], the
    /// left limit) and after ([`MeStop::AfterEvent`], unless the event is at `t + h`, whose
    /// values the step's end gives). Called again with the same `t` and `h` until it
    /// returns [`MeStop::Reached`].
    pub fn step_to_event(&mut self, t: f64, h: f64) -> Result<MeStop, FmuError> {
        self.advance(t, h, true)
    }

    fn advance(&mut self, t: f64, h: f64, stop_at_events: bool) -> Result<MeStop, FmuError> {
        let target = t + h;
        if self.step_target != Some(target) {
            self.begin_step()?;
            self.step_target = Some(target);
            self.events_here = 0;
        }
        let r = self.advance_to(target, stop_at_events);
        if !matches!(r, Ok(MeStop::BeforeEvent(_) | MeStop::AfterEvent(_))) {
            self.step_target = None;
            self.event_detected = false;
        }
        if r.as_ref().is_ok_and(|s| *s == MeStop::Reached) && !self.continuous_inputs.is_empty() {
            // The indicators as the step left them: a changed input is compared to these.
            self.read_indicators()?;
        }
        r
    }

    /// The checks and pending work before a step's integration.
    fn begin_step(&mut self) -> Result<(), FmuError> {
        if self.terminated_at.is_some() {
            return Err(self.ended());
        }
        if self.mode != Mode::ContinuousTime && !self.event_pending {
            return Err(self.error(
                Function::DoStep.name(),
                format!(
                    "a step is not possible in {} (the instance is not initialised)",
                    self.mode_name()
                ),
            ));
        }
        self.settle()?;
        if self.terminated_at.is_some() {
            return Err(self.ended());
        }
        if self.inputs_changed && self.input_event()? {
            return Err(self.ended());
        }
        Ok(())
    }

    /// The event detected at the current time, handled (event iteration).
    fn handle_event(&mut self, before: f64) -> Result<(), FmuError> {
        self.events_here = if self.inst.time() == before {
            self.events_here + 1
        } else {
            0
        };
        if self.events_here > MAX_EVENT_ITERATIONS {
            return Err(self.error(
                self.api.name(Call::UpdateDiscreteStates),
                format!("{MAX_EVENT_ITERATIONS} events at one time: the FMU sets its next event time to the current time again and again"),
            ));
        }
        if self.event_iteration(true)? {
            return Err(self.ended());
        }
        Ok(())
    }

    fn advance_to(&mut self, target: f64, stop_at_events: bool) -> Result<MeStop, FmuError> {
        let span = self.span();
        let isclose = |a: f64, b: f64| isclose_in(a, b, span);
        if self.event_detected {
            // Stopped before this event (BeforeEvent): handle it now.
            self.event_detected = false;
            let before = self.event_start;
            self.handle_event(before)?;
            let te = self.inst.time();
            if !(te > target || isclose(te, target)) {
                return Ok(MeStop::AfterEvent(te));
            }
        }
        while !(self.inst.time() > target || isclose(self.inst.time(), target)) {
            let mut t_next = target;
            if let Some(te) = self.next_event {
                if t_next > te && !isclose(t_next, te) {
                    t_next = te;
                }
            }
            let time_event = self.next_event.is_some_and(|te| isclose(t_next, te));
            let before = self.inst.time();
            let state_event = if t_next <= before || isclose(t_next, before) {
                // A time event now (or one the FMU set in the past): no integration.
                false
            } else {
                self.integrate_to(t_next)?
            };
            let (step_event, terminate) = self.completed_integrator_step()?;
            if terminate {
                self.terminated_at = Some(self.inst.time());
                return Err(self.ended());
            }
            let time_event = time_event && isclose(self.inst.time(), t_next);
            if time_event || state_event || step_event {
                if stop_at_events {
                    self.event_detected = true;
                    self.event_start = before;
                    return Ok(MeStop::BeforeEvent(self.inst.time()));
                }
                self.handle_event(before)?;
            }
        }
        Ok(MeStop::Reached)
    }

    /// CVODE from the current time to `t_next`, stopping at a root; the FMU then holds the
    /// time and states reached (`fmi2SetContinuousStates`, `fmi2SetTime`, as FMPy). True at
    /// a state event.
    fn integrate_to(&mut self, t_next: f64) -> Result<bool, FmuError> {
        let solver = self.solver.as_mut().expect("started at initialisation");
        let r = solver.advance(t_next, &mut self.x, &mut self.roots);
        self.log_solver_warnings();
        let reached = r.map_err(|e| self.solver_error(e))?;
        let (t, state_event) = match reached {
            Reached::Time(t) => (t, false),
            Reached::Root(t) => (t, true),
        };
        if self.nx > 0 {
            let s = unsafe { self.api.set_states(self.inst.raw(), &self.x[..self.nx]) };
            self.check_with(
                self.api.name(Call::SetContinuousStates),
                || shown_values(&self.x[..self.nx]),
                s,
            )?;
        }
        self.inst.set_time(t);
        let s = unsafe { self.api.set_time(self.inst.raw(), t) };
        self.check_with(self.api.name(Call::SetTime), || format!("time={t:?}"), s)?;
        Ok(state_event)
    }

    /// `fmi2CompletedIntegratorStep` (unless the FMU does not need it): whether it asks
    /// for event mode, and whether to end the simulation.
    fn completed_integrator_step(&mut self) -> Result<(bool, bool), FmuError> {
        if !self.completed_step_needed {
            return Ok((false, false));
        }
        let (s, enter, terminate) = unsafe { self.api.completed_integrator_step(self.inst.raw()) };
        self.check_with(
            self.api.name(Call::CompletedIntegratorStep),
            || {
                format!(
                    "noSetFMUStatePriorToCurrentPoint=true, enterEventMode={enter}, terminateSimulation={terminate}"
                )
            },
            s,
        )?;
        Ok((enter, terminate))
    }

    /// A continuous input changed since the integrator started: an event when an event
    /// indicator changed sign with it (compared with the end of the last step), then the
    /// integrator starts again. True when the FMU asked to end the simulation.
    fn input_event(&mut self) -> Result<bool, FmuError> {
        let before = self.z.clone();
        self.read_indicators()?;
        let crossed = before
            .iter()
            .zip(&self.z)
            .any(|(a, b)| (*a > 0.0) != (*b > 0.0));
        if crossed {
            return self.event_iteration(true);
        }
        self.restart_solver(false)?;
        Ok(false)
    }

    /// The step's error when the FMU asked to end the simulation: `fmi2Discard` as a
    /// Co-Simulation FMU would say it (the master then asks [`Self::terminated_by_fmu`]).
    fn ended(&self) -> FmuError {
        FmuError::call(
            self.inst.name(),
            Function::DoStep,
            fmi2Status::DISCARD,
            self.terminated_at.unwrap_or(self.inst.time()),
            Vec::new(),
        )
    }

    fn mode_name(&self) -> &'static str {
        match self.mode {
            Mode::Instantiated => "the instantiated state",
            Mode::Initialization => "initialization mode",
            Mode::Event => "event mode",
            Mode::ContinuousTime => "continuous-time mode",
            Mode::Terminated => "the terminated state",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Times within a run that starts at 0 are compared as FMPy does; at a Unix-time start
    /// the comparison stays 1e-9 of the run's length wide, not 1.7 s (M7); an infinite time
    /// is close only to itself (M6).
    #[test]
    fn times_are_compared_at_the_runs_resolution() {
        // As FMPy within a run from 0 to 10 s.
        for (a, b) in [(5.0, 5.0 + 4e-9), (9.9, 9.9 + 9e-9), (1e-3, 1e-3 + 1e-13)] {
            assert_eq!(isclose_in(a, b, 10.0), isclose(a, b), "{a} {b}");
        }
        assert!(isclose_in(5.0, 5.0 + 4e-9, 10.0));
        // 1.7e9 s and 1.7e9 + 1 s are relatively within 1e-9, but 1 s apart in a 2 s run.
        assert!(isclose(1.7e9, 1.7e9 + 1.0));
        assert!(!isclose_in(1.7e9, 1.7e9 + 1.0, 2.0));
        assert!(isclose_in(1.7e9, 1.7e9 + 1e-9, 2.0));
        for t in [0.0, 1.0, 1e300] {
            assert!(!isclose_in(f64::INFINITY, t, f64::INFINITY));
            assert!(!isclose_in(t, f64::NEG_INFINITY, 10.0));
        }
        assert!(isclose_in(f64::INFINITY, f64::INFINITY, 10.0));
        assert!(!isclose_in(f64::NAN, f64::NAN, 10.0));
    }
}

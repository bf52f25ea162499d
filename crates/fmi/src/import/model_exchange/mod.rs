//! FMI 2.0 Model Exchange: an instance that twinbench integrates itself, with SUNDIALS
//! CVODE (`cvode.rs`) between communication points, so that to the master it is one more
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
//!
//! Here: the settings, the limits and the time comparison, and the instance ([`MeInstance`])
//! with its state and how its errors are told. Its calls, by job: `lifecycle.rs`
//! (instantiation to reset), `values.rs` (get and set), `step.rs` (a communication step),
//! `events.rs` (event mode and the event iteration), `solver.rs` (CVODE driven from the
//! instance). Below them: `calls.rs` and `unit.rs` (the FMI version's calls and instance),
//! `system.rs` (the FMU as CVODE's system) and `cvode.rs` (the binding).

mod calls;
pub(crate) mod cvode;
mod events;
mod instance;
mod lifecycle;
mod solver;
mod step;
mod system;
mod unit;
mod values;

use super::model::ModelDescription;
use crate::fmi2::*;
use crate::FmuError;
pub use calls::CallTrace;
use calls::MeCalls;
use cvode::Cvode;
use std::collections::HashMap;
use std::path::PathBuf;
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
/// Co-Simulation [`Instance`](crate::Instance) (the backend of a system instance); errors are
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

    /// A common call's error (from [`Instance`](crate::Instance) or
    /// [`Instance3`](crate::Instance3)) as this instance's.
    fn wrap(&self, e: FmuError) -> FmuError {
        let (call, status, time, log): (Box<str>, String, f64, Vec<String>) = match e {
            FmuError::Call {
                function,
                status,
                time,
                log,
                ..
            } => (function.name().into(), status.to_string(), time, log),
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

    /// The run's length, the scale of its time comparisons ([`isclose_in`]): unbounded
    /// without a stop time.
    fn span(&self) -> f64 {
        self.stop
            .map_or(f64::INFINITY, |stop| (stop - self.start).abs().max(1.0))
    }

    /// After a step reported `fmi2Discard`: the time at which the FMU asked to end the
    /// simulation (`terminateSimulation`).
    pub fn terminated_by_fmu(&mut self) -> Option<f64> {
        self.terminated_at
    }

    /// The step's error when the FMU asked to end the simulation: `fmi2Discard` as a
    /// Co-Simulation FMU would say it (the master then asks [`Self::terminated_by_fmu`]).
    fn ended(&self) -> FmuError {
        FmuError::step_discarded(
            self.inst.name(),
            self.terminated_at.unwrap_or(self.inst.time()),
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

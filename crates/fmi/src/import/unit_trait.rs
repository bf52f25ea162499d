//! The one seam between an importer and a running FMU: [`FmuInstance`], what every
//! co-simulation unit answers, whichever FMI version and interface it speaks. The FMI 2.0
//! and 3.0 Co-Simulation instances implement it with their calls, the Model Exchange
//! instance with its integration; an orchestrator drives any of them (and its own units,
//! a natively linked model or a worker process) through it, with no version in sight.

use super::model_exchange::{CallTrace, MeStop};
use super::FmuError;

/// What `fmi2SetupExperiment` tells an instance, and FMI 3.0 passes to
/// `fmi3EnterInitializationMode`: the start time, the stop time if defined, and the relative
/// tolerance an FMU with an internal solver should use if defined (`toleranceDefined`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Experiment {
    pub start: f64,
    pub stop: Option<f64>,
    pub tolerance: Option<f64>,
}

impl From<f64> for Experiment {
    /// From `start`, without a stop time or a tolerance.
    fn from(start: f64) -> Experiment {
        Experiment {
            start,
            stop: None,
            tolerance: None,
        }
    }
}

/// One running instance, in FMI 2.0 Co-Simulation terms (an FMI 3.0 or Model Exchange
/// instance maps its calls onto these).
pub trait FmuInstance: Send {
    fn name(&self) -> &str;
    /// Simulation time reached (for error messages).
    fn time(&self) -> f64;
    /// Echo status-OK log messages to the `log` crate (errors are always kept).
    fn set_echo(&mut self, on: bool);
    fn last_log_lines(&self) -> Vec<String>;
    /// Debug logging of every category on or off.
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError>;
    /// `fmi2SetupExperiment`, or what FMI 3.0 passes to `fmi3EnterInitializationMode`.
    fn setup_experiment(&mut self, e: Experiment) -> Result<(), FmuError>;
    fn enter_initialization_mode(&mut self) -> Result<(), FmuError>;
    fn exit_initialization_mode(&mut self) -> Result<(), FmuError>;
    fn terminate(&mut self) -> Result<(), FmuError>;
    fn reset(&mut self) -> Result<(), FmuError>;
    fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError>;
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError>;
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError>;
    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError>;
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError>;
    fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError>;
    /// String values into `out` (cleared first), one per value reference.
    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError>;
    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError>;
    /// One communication step from `t` by `h`; on success the instance's time advances.
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError>;
    /// Give the unit a trace for the FMI calls it makes on its own inside a step (a Model
    /// Exchange instance's integration: time, states, derivatives, event indicators, event
    /// mode); false when it makes none (a Co-Simulation FMU's step is the one call).
    fn set_call_trace(&mut self, _trace: CallTrace) -> bool {
        false
    }
    /// Whether [`FmuInstance::step_to_event`] stops at events (an in-process Model
    /// Exchange instance); the master records event rows only from such a unit.
    fn stops_at_events(&self) -> bool {
        false
    }
    /// The step from `t` by `h`, stopping before and after each event inside it (FMPy's
    /// `record_events`); called again with the same `t` and `h` until it returns
    /// [`MeStop::Reached`]. A unit that does not stop at events makes the whole step.
    fn step_to_event(&mut self, t: f64, h: f64) -> Result<MeStop, FmuError> {
        self.do_step(t, h).map(|()| MeStop::Reached)
    }
    /// After a step returned `fmi2Discard`: `Some(last successful time)` when the FMU asks
    /// to end the simulation (`fmi2Terminated`, FMI 3.0's `terminateSimulation`), as FMPy's
    /// master asks it.
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        None
    }
}

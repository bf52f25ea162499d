//! [`FmuInstance`] for the Model Exchange instance: the master's calls onto its integration
//! (a step is CVODE's integration over it, events inside it included).

use super::{CallTrace, MeInstance, MeStop};
use crate::{Experiment, FmuError, FmuInstance};

impl FmuInstance for MeInstance {
    fn name(&self) -> &str {
        MeInstance::name(self)
    }
    fn time(&self) -> f64 {
        MeInstance::time(self)
    }
    fn set_echo(&mut self, on: bool) {
        MeInstance::set_echo(self, on)
    }
    fn last_log_lines(&self) -> Vec<String> {
        MeInstance::last_log_lines(self)
    }
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        MeInstance::set_debug_logging(self, on)
    }
    /// The tolerance was resolved when the instance was made (it is CVODE's too).
    fn setup_experiment(&mut self, e: Experiment) -> Result<(), FmuError> {
        MeInstance::setup_experiment(self, e.start, e.stop)
    }
    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        MeInstance::enter_initialization_mode(self)
    }
    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        MeInstance::exit_initialization_mode(self)
    }
    fn terminate(&mut self) -> Result<(), FmuError> {
        MeInstance::terminate(self)
    }
    fn reset(&mut self) -> Result<(), FmuError> {
        MeInstance::reset(self)
    }
    fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        MeInstance::get_real(self, vrs, out)
    }
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        MeInstance::set_real(self, vrs, values)
    }
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        MeInstance::get_integer(self, vrs, out)
    }
    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        MeInstance::set_integer(self, vrs, values)
    }
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        MeInstance::get_boolean(self, vrs, out)
    }
    fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        MeInstance::set_boolean(self, vrs, values)
    }
    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        MeInstance::get_string(self, vrs, out)
    }
    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        MeInstance::set_string(self, vrs, values)
    }
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        MeInstance::do_step(self, t, h)
    }
    fn stops_at_events(&self) -> bool {
        true
    }
    fn set_call_trace(&mut self, trace: CallTrace) -> bool {
        MeInstance::set_call_trace(self, Some(trace));
        true
    }
    fn step_to_event(&mut self, t: f64, h: f64) -> Result<MeStop, FmuError> {
        MeInstance::step_to_event(self, t, h)
    }
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        MeInstance::terminated_by_fmu(self)
    }
}

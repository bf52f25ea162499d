//! What the master drives: a running co-simulation unit behind one small trait, so that an
//! FMU loaded in-process, a model linked natively, or an FMU isolated in a worker process
//! are interchangeable. Each system instance has a factory that creates (and recreates)
//! its unit.

use std::sync::Arc;
use tb_fmi::{FmuError, Instance, Instance3, Interface, LoadedFmu, MeInstance, MeSettings, MeStop};

/// One running instance, in FMI 2.0 Co-Simulation terms.
pub trait Backend: Send {
    fn name(&self) -> &str;
    /// Simulation time reached (for error messages).
    fn time(&self) -> f64;
    /// Echo status-OK log messages to the `log` crate (errors are always kept).
    fn set_echo(&mut self, on: bool);
    fn last_log_lines(&self) -> Vec<String>;
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError>;
    /// `tolerance`: the relative tolerance an FMU with an internal solver should use
    /// (`toleranceDefined` when Some).
    fn setup_experiment(
        &mut self,
        start: f64,
        stop: Option<f64>,
        tolerance: Option<f64>,
    ) -> Result<(), FmuError>;
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
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError>;
    /// Give the unit a trace for the FMI calls it makes on its own inside a step (a Model
    /// Exchange instance's integration: time, states, derivatives, event indicators, event
    /// mode); false when it makes none (a Co-Simulation FMU's step is the one call).
    fn set_call_trace(&mut self, _trace: tb_fmi::CallTrace) -> bool {
        false
    }
    /// Whether [`Backend::step_to_event`] stops at events (an in-process Model Exchange
    /// instance); the master records event rows only from such a unit.
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
    /// to end the simulation (`fmi2Terminated`), as FMPy's master asks it.
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        None
    }
}

/// Creates the running unit of one system instance.
pub trait BackendFactory: Send + Sync {
    /// "fmu", "native", "isolated", ...
    fn kind(&self) -> &'static str;
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError>;
}

/// How an instance runs its FMU: through which interface and, for Model Exchange, with
/// which solver settings. The isolated worker is given the same, so that it runs the same
/// backend (the whole integration happens in the worker).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunAs {
    pub interface: Interface,
    pub me: MeSettings,
}

impl RunAs {
    /// The FMU's default interface (Co-Simulation when it has it), default settings.
    pub fn default_for(fmu: &LoadedFmu) -> RunAs {
        RunAs {
            interface: fmu.default_interface(),
            me: MeSettings::default(),
        }
    }
}

/// The default: the FMU's shared library loaded in this process.
pub struct FmuFactory {
    pub fmu: Arc<LoadedFmu>,
    pub run: RunAs,
}

impl FmuFactory {
    /// Through the FMU's default interface.
    pub fn new(fmu: Arc<LoadedFmu>) -> FmuFactory {
        let run = RunAs::default_for(&fmu);
        FmuFactory { fmu, run }
    }
}

/// A Model Exchange instance of `fmu` in this process (its library loaded for Model
/// Exchange), debug logging on when asked.
pub fn model_exchange(
    fmu: &LoadedFmu,
    instance_name: &str,
    logging: bool,
    settings: MeSettings,
) -> Result<MeInstance, FmuError> {
    let mut inst = MeInstance::instantiate(
        fmu.library_me()?,
        &fmu.description,
        &fmu.source,
        instance_name,
        Some(&fmu.resource_dir()),
        logging,
        settings,
    )?;
    if logging {
        inst.set_debug_logging(true)?;
    }
    Ok(inst)
}

impl BackendFactory for FmuFactory {
    fn kind(&self) -> &'static str {
        "fmu"
    }
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError> {
        let fmu = &self.fmu;
        if self.run.interface == Interface::ModelExchange {
            let inst = model_exchange(fmu, instance_name, logging, self.run.me)?;
            return Ok(Box::new(inst));
        }
        if fmu.is_fmi3() {
            let mut inst = Instance3::instantiate(
                fmu.library3()?,
                &fmu.description,
                instance_name,
                Some(&fmu.resource_dir()),
                logging,
            )?;
            if logging {
                inst.set_debug_logging(true)?;
            }
            return Ok(Box::new(inst));
        }
        let mut inst = Instance::instantiate(
            fmu.library()?,
            instance_name,
            &fmu.description.guid,
            Some(&fmu.resource_dir()),
            logging,
        )?;
        if logging {
            inst.set_debug_logging(true, &[])?;
        }
        Ok(Box::new(inst))
    }
}

impl Backend for Instance {
    fn name(&self) -> &str {
        &self.name
    }
    fn time(&self) -> f64 {
        self.time
    }
    fn set_echo(&mut self, on: bool) {
        Instance::set_echo(self, on)
    }
    fn last_log_lines(&self) -> Vec<String> {
        Instance::last_log_lines(self)
    }
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        Instance::set_debug_logging(self, on, &[])
    }
    fn setup_experiment(
        &mut self,
        start: f64,
        stop: Option<f64>,
        tolerance: Option<f64>,
    ) -> Result<(), FmuError> {
        Instance::setup_experiment(self, start, stop, tolerance)
    }
    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        Instance::enter_initialization_mode(self)
    }
    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        Instance::exit_initialization_mode(self)
    }
    fn terminate(&mut self) -> Result<(), FmuError> {
        Instance::terminate(self)
    }
    fn reset(&mut self) -> Result<(), FmuError> {
        Instance::reset(self)
    }
    #[inline]
    fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        Instance::get_real(self, vrs, out)
    }
    #[inline]
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        Instance::set_real(self, vrs, values)
    }
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        Instance::get_integer(self, vrs, out)
    }
    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        Instance::set_integer(self, vrs, values)
    }
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        Instance::get_boolean(self, vrs, out)
    }
    fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        Instance::set_boolean(self, vrs, values)
    }
    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        Instance::get_string(self, vrs, out)
    }
    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        Instance::set_string(self, vrs, values)
    }
    #[inline]
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        Instance::do_step(self, t, h)
    }
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        Instance::terminated_by_fmu(self)
    }
}

impl Backend for Instance3 {
    fn name(&self) -> &str {
        &self.name
    }
    fn time(&self) -> f64 {
        self.time
    }
    fn set_echo(&mut self, on: bool) {
        Instance3::set_echo(self, on)
    }
    fn last_log_lines(&self) -> Vec<String> {
        Instance3::last_log_lines(self)
    }
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        Instance3::set_debug_logging(self, on)
    }
    fn setup_experiment(
        &mut self,
        start: f64,
        stop: Option<f64>,
        tolerance: Option<f64>,
    ) -> Result<(), FmuError> {
        Instance3::setup_experiment(self, start, stop, tolerance)
    }
    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        Instance3::enter_initialization_mode(self)
    }
    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        Instance3::exit_initialization_mode(self)
    }
    fn terminate(&mut self) -> Result<(), FmuError> {
        Instance3::terminate(self)
    }
    fn reset(&mut self) -> Result<(), FmuError> {
        Instance3::reset(self)
    }
    #[inline]
    fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        Instance3::get_real(self, vrs, out)
    }
    #[inline]
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        Instance3::set_real(self, vrs, values)
    }
    #[inline]
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        Instance3::get_int(self, vrs, out)
    }
    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        Instance3::set_int(self, vrs, values)
    }
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        Instance3::get_int(self, vrs, out)
    }
    fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        Instance3::set_int(self, vrs, values)
    }
    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        Instance3::get_string(self, vrs, out)
    }
    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        Instance3::set_string(self, vrs, values)
    }
    #[inline]
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        Instance3::do_step(self, t, h)
    }
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        Instance3::terminated_by_fmu(self)
    }
}

impl Backend for MeInstance {
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
    fn setup_experiment(
        &mut self,
        start: f64,
        stop: Option<f64>,
        _tolerance: Option<f64>,
    ) -> Result<(), FmuError> {
        MeInstance::setup_experiment(self, start, stop)
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
    fn set_call_trace(&mut self, trace: tb_fmi::CallTrace) -> bool {
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

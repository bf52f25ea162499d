//! An instance's life as the master leads it, through the calls of a Co-Simulation
//! instance: instantiation (the library, the description's sizes and the tolerance checked
//! before the FMU is instantiated), the experiment, initialisation (after which the
//! integrator starts), termination and reset.

use super::calls::{Call, MeCalls};
use super::unit::{MeLibrary, Unit};
use super::{cvode, MeInstance, MeSettings, Mode, MAX_SIZE, MAX_STATES, SOLVER_AVAILABLE};
use crate::fmi2::{fmi2Status, fmi2Type};
use crate::import::instance::Instance;
use crate::import::instance3::Instance3;
use crate::import::model::ModelDescription;
use crate::{CallStatus, Causality, Experiment, FmuError, Variability};
use std::collections::HashMap;
use std::path::Path;

impl MeInstance {
    /// Instantiate an FMU for Model Exchange: `lib` loaded with
    /// [`Library::load_model_exchange`](crate::import::library::Library::load_model_exchange), `md` its description, `fmu` the .fmu (for
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
        let api = me_calls(&lib, &bad)?;
        let me = md
            .model_exchange
            .as_ref()
            .ok_or_else(|| bad(format!("{}: no <ModelExchange> element", fmu.display())))?;
        let (nx, nz) = checked_sizes(md, fmu, &bad)?;
        let rtol = checked_tolerance(&settings, md, &bad)?;
        let inst = instantiate_unit(lib, md, name, resource_dir, logging_on)?;
        check_fmi3_counts(api, &inst, (nx, nz), fmu, &bad)?;
        let continuous_inputs = continuous_inputs(md);
        let derivative_names = derivative_names(md, nx);
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

    pub fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        self.inst.set_debug_logging(on).map_err(|e| self.wrap(e))
    }

    /// As FMPy 0.3.32's Model Exchange loop, `toleranceDefined = false` unless the system
    /// gives a tolerance (the instance's, the experiment's, `run --tolerance`): then the FMU
    /// is told it. Either way the solver integrates with [`MeInstance::relative_tolerance`].
    pub fn setup_experiment(&mut self, start: f64, stop: Option<f64>) -> Result<(), FmuError> {
        self.start = start;
        self.stop = stop;
        let r = self.inst.setup_experiment(Experiment {
            start,
            stop,
            tolerance: self.told_tolerance,
        });
        // FMI 3.0 has no such call: its arguments go with fmi3EnterInitializationMode.
        if let (Some(trace), false) = (&self.trace, self.api.is_fmi3()) {
            let stop = stop.map_or("undefined".to_string(), |s| format!("{s:?}"));
            let args = match self.told_tolerance {
                Some(tol) => format!("toleranceDefined=true, tolerance={tol:?}, startTime={start:?}, stopTime={stop}"),
                None => format!("toleranceDefined=false, startTime={start:?}, stopTime={stop}"),
            };
            let status = match &r {
                Ok(()) => fmi2Status::OK,
                Err(FmuError::Call {
                    status: CallStatus::Fmi2(status),
                    ..
                }) => *status,
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
}

// The steps of [`MeInstance::instantiate`], in its order: the checks before the FMU is
// instantiated, the instantiation, the FMU's own counts, what the instance keeps.

/// The Model Exchange functions of `lib`, which must have been loaded for Model Exchange.
fn me_calls(lib: &MeLibrary, bad: &impl Fn(String) -> FmuError) -> Result<MeCalls, FmuError> {
    let not_loaded = || bad("the library was not loaded for Model Exchange".into());
    Ok(match lib {
        MeLibrary::V2(l) => MeCalls::V2(l.me.ok_or_else(not_loaded)?),
        MeLibrary::V3(l) => MeCalls::V3(l.me.ok_or_else(not_loaded)?),
    })
}

/// The numbers of continuous states and event indicators: at most [`MAX_SIZE`] of each (a
/// description is untrusted), and at most [`MAX_STATES`] states (the dense Jacobian).
fn checked_sizes(
    md: &ModelDescription,
    fmu: &Path,
    bad: &impl Fn(String) -> FmuError,
) -> Result<(usize, usize), FmuError> {
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
    Ok((nx, nz))
}

/// The solver's relative tolerance ([`MeSettings::relative_tolerance_for`]), in (0, 1).
fn checked_tolerance(
    settings: &MeSettings,
    md: &ModelDescription,
    bad: &impl Fn(String) -> FmuError,
) -> Result<f64, FmuError> {
    let rtol = settings.relative_tolerance_for(md);
    if !(rtol.is_finite() && rtol > 0.0 && rtol < 1.0) {
        return Err(bad(format!(
            "the relative tolerance {rtol:e} of the Model Exchange solver is not in (0, 1)"
        )));
    }
    Ok(rtol)
}

/// The FMU instantiated for Model Exchange, in the version of its library.
fn instantiate_unit(
    lib: MeLibrary,
    md: &ModelDescription,
    name: &str,
    resource_dir: Option<&Path>,
    logging_on: bool,
) -> Result<Unit, FmuError> {
    Ok(match lib {
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
    })
}

/// An FMI 3.0 FMU's own counts of continuous states and event indicators, as the
/// description declares them (`nx`, `nz`); nothing to check in FMI 2.0.
fn check_fmi3_counts(
    api: MeCalls,
    inst: &Unit,
    (nx, nz): (usize, usize),
    fmu: &Path,
    bad: &impl Fn(String) -> FmuError,
) -> Result<(), FmuError> {
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
    Ok(())
}

/// The continuous Real inputs (settable in continuous-time mode), by value reference.
fn continuous_inputs(md: &ModelDescription) -> HashMap<u32, ()> {
    md.variables
        .iter()
        .filter(|v| {
            v.causality == Causality::Input
                && v.variability == Variability::Continuous
                && v.ty == crate::ScalarType::Real
        })
        .map(|v| (v.value_reference, ()))
        .collect()
}

/// The derivatives' names in state order (`der(x)`), for messages.
fn derivative_names(md: &ModelDescription, nx: usize) -> Vec<String> {
    (0..nx)
        .map(|k| {
            md.derivatives
                .get(k)
                .and_then(|u| md.variables.get(u.index.wrapping_sub(1)))
                .map_or_else(
                    || format!("derivative {} of {nx}", k + 1),
                    |v| v.name.clone(),
                )
        })
        .collect()
}

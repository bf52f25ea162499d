//! The Model Exchange calls of either FMI version ([`MeCalls`]: time, states, derivatives,
//! event indicators, the event iteration), by what they do ([`Call`]), and how an instance
//! reports them ([`CallTrace`]). FMI 2.0 and FMI 3.0 differ here in names and in a few
//! arguments only (FMI 3.0 §3.2: `fmi3UpdateDiscreteStates` for `fmi2NewDiscreteStates`,
//! its `fmi3GetContinuousStateDerivatives` for `fmi2GetDerivatives`, C `bool` flags), so the
//! event handling and CVODE's set-up are one code for both.

use super::super::library::MeApi;
use super::super::library3::Me3Api;
use crate::fmi2::*;
use std::ffi::c_void;
use std::sync::Arc;

/// The FMU's instance pointer (`fmi2Component`, `fmi3Instance`).
pub(crate) type Component = *mut c_void;

/// A vector of the continuous-time interface, read from the FMU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Vector {
    States,
    Nominals,
    Derivatives,
    EventIndicators,
}

/// The Model Exchange calls, by what they do (their names differ by version).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Call {
    SetTime,
    SetContinuousStates,
    Get(Vector),
    EnterEventMode,
    UpdateDiscreteStates,
    EnterContinuousTimeMode,
    CompletedIntegratorStep,
}

/// What the event iteration's call returned (`fmi2EventInfo`, the outputs of
/// `fmi3UpdateDiscreteStates`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct EventUpdate {
    /// `newDiscreteStatesNeeded` (FMI 2.0), `discreteStatesNeedUpdate` (FMI 3.0).
    pub needs_update: bool,
    pub terminate: bool,
    pub nominals_changed: bool,
    pub values_changed: bool,
    pub next_event_time_defined: bool,
    pub next_event_time: f64,
}

/// The Model Exchange functions of one FMU, in its version.
#[derive(Clone, Copy)]
pub(crate) enum MeCalls {
    V2(MeApi),
    V3(Me3Api),
}

/// An FMI 3.0 status as the FMI 2.0 one of the same number (the enumerations agree:
/// OK, Warning, Discard, Error, Fatal).
fn status3(s: i32) -> fmi2Status {
    fmi2Status(s)
}

impl MeCalls {
    pub fn is_fmi3(&self) -> bool {
        matches!(self, MeCalls::V3(_))
    }

    /// The function's name in this FMU's version.
    pub fn name(&self, call: Call) -> &'static str {
        let (v2, v3) = match call {
            Call::SetTime => ("fmi2SetTime", "fmi3SetTime"),
            Call::SetContinuousStates => ("fmi2SetContinuousStates", "fmi3SetContinuousStates"),
            Call::Get(Vector::States) => ("fmi2GetContinuousStates", "fmi3GetContinuousStates"),
            Call::Get(Vector::Nominals) => (
                "fmi2GetNominalsOfContinuousStates",
                "fmi3GetNominalsOfContinuousStates",
            ),
            Call::Get(Vector::Derivatives) => {
                ("fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives")
            }
            Call::Get(Vector::EventIndicators) => {
                ("fmi2GetEventIndicators", "fmi3GetEventIndicators")
            }
            Call::EnterEventMode => ("fmi2EnterEventMode", "fmi3EnterEventMode"),
            Call::UpdateDiscreteStates => ("fmi2NewDiscreteStates", "fmi3UpdateDiscreteStates"),
            Call::EnterContinuousTimeMode => {
                ("fmi2EnterContinuousTimeMode", "fmi3EnterContinuousTimeMode")
            }
            Call::CompletedIntegratorStep => {
                ("fmi2CompletedIntegratorStep", "fmi3CompletedIntegratorStep")
            }
        };
        if self.is_fmi3() {
            v3
        } else {
            v2
        }
    }

    /// A status by its name in this FMU's version (`fmi3Error`).
    pub fn status_name(&self, s: fmi2Status) -> String {
        let name = s.to_string();
        match self.is_fmi3() {
            true => name.replacen("fmi2", "fmi3", 1),
            false => name,
        }
    }

    /// The name of the flag that asks for another event iteration.
    pub fn needs_update_flag(&self) -> &'static str {
        if self.is_fmi3() {
            "discreteStatesNeedUpdate"
        } else {
            "newDiscreteStatesNeeded"
        }
    }

    /// # Safety
    /// `c` is this library's live instance.
    pub unsafe fn set_time(&self, c: Component, t: f64) -> fmi2Status {
        match self {
            MeCalls::V2(a) => (a.fmi2SetTime)(c, t),
            MeCalls::V3(a) => status3((a.set_time)(c, t)),
        }
    }

    /// # Safety
    /// As [`Self::set_time`].
    pub unsafe fn set_states(&self, c: Component, x: &[f64]) -> fmi2Status {
        match self {
            MeCalls::V2(a) => (a.fmi2SetContinuousStates)(c, x.as_ptr(), x.len()),
            MeCalls::V3(a) => status3((a.set_continuous_states)(c, x.as_ptr(), x.len())),
        }
    }

    /// # Safety
    /// As [`Self::set_time`].
    pub unsafe fn get(&self, c: Component, v: Vector, out: &mut [f64]) -> fmi2Status {
        let (p, n) = (out.as_mut_ptr(), out.len());
        match self {
            MeCalls::V2(a) => match v {
                Vector::States => (a.fmi2GetContinuousStates)(c, p, n),
                Vector::Nominals => (a.fmi2GetNominalsOfContinuousStates)(c, p, n),
                Vector::Derivatives => (a.fmi2GetDerivatives)(c, p, n),
                Vector::EventIndicators => (a.fmi2GetEventIndicators)(c, p, n),
            },
            MeCalls::V3(a) => status3(match v {
                Vector::States => (a.get_continuous_states)(c, p, n),
                Vector::Nominals => (a.get_nominals_of_continuous_states)(c, p, n),
                Vector::Derivatives => (a.get_continuous_state_derivatives)(c, p, n),
                Vector::EventIndicators => (a.get_event_indicators)(c, p, n),
            }),
        }
    }

    /// # Safety
    /// As [`Self::set_time`].
    pub unsafe fn enter_event_mode(&self, c: Component) -> fmi2Status {
        match self {
            MeCalls::V2(a) => (a.fmi2EnterEventMode)(c),
            MeCalls::V3(a) => status3((a.enter_event_mode)(c)),
        }
    }

    /// # Safety
    /// As [`Self::set_time`].
    pub unsafe fn enter_continuous_time_mode(&self, c: Component) -> fmi2Status {
        match self {
            MeCalls::V2(a) => (a.fmi2EnterContinuousTimeMode)(c),
            MeCalls::V3(a) => status3((a.enter_continuous_time_mode)(c)),
        }
    }

    /// # Safety
    /// As [`Self::set_time`].
    pub unsafe fn update_discrete_states(&self, c: Component) -> (fmi2Status, EventUpdate) {
        match self {
            MeCalls::V2(a) => {
                let mut info = fmi2EventInfo::default();
                let s = (a.fmi2NewDiscreteStates)(c, &mut info);
                let update = EventUpdate {
                    needs_update: info.newDiscreteStatesNeeded != fmi2False,
                    terminate: info.terminateSimulation != fmi2False,
                    nominals_changed: info.nominalsOfContinuousStatesChanged != fmi2False,
                    values_changed: info.valuesOfContinuousStatesChanged != fmi2False,
                    next_event_time_defined: info.nextEventTimeDefined != fmi2False,
                    next_event_time: info.nextEventTime,
                };
                (s, update)
            }
            MeCalls::V3(a) => {
                let (mut needs, mut terminate, mut nominals, mut values, mut defined) =
                    (false, false, false, false, false);
                let mut next = 0.0;
                let s = (a.update_discrete_states)(
                    c,
                    &mut needs,
                    &mut terminate,
                    &mut nominals,
                    &mut values,
                    &mut defined,
                    &mut next,
                );
                let update = EventUpdate {
                    needs_update: needs,
                    terminate,
                    nominals_changed: nominals,
                    values_changed: values,
                    next_event_time_defined: defined,
                    next_event_time: next,
                };
                (status3(s), update)
            }
        }
    }

    /// `noSetFMUStatePriorToCurrentPoint` = true: whether the FMU asks for event mode and
    /// whether to end the simulation.
    ///
    /// # Safety
    /// As [`Self::set_time`].
    pub unsafe fn completed_integrator_step(&self, c: Component) -> (fmi2Status, bool, bool) {
        match self {
            MeCalls::V2(a) => {
                let (mut enter, mut terminate) = (fmi2False, fmi2False);
                let s = (a.fmi2CompletedIntegratorStep)(c, fmi2True, &mut enter, &mut terminate);
                (s, enter != fmi2False, terminate != fmi2False)
            }
            MeCalls::V3(a) => {
                let (mut enter, mut terminate) = (false, false);
                let s = (a.completed_integrator_step)(c, true, &mut enter, &mut terminate);
                (status3(s), enter, terminate)
            }
        }
    }
}

/// Where an instance reports each FMI call it makes on its own between the master's calls
/// (`--trace-fmi`): the instance's time, the function, its arguments and the status. The
/// calls the master makes through the instance (get, set, initialisation) are the master's
/// to trace.
pub type CallTrace = Arc<dyn Fn(f64, &str, &str, fmi2Status) + Send + Sync>;

/// `[1.0, 2.5]`: values as their shortest round-trip text.
pub(crate) fn shown_values(x: &[f64]) -> String {
    let items: Vec<String> = x.iter().map(|v| format!("{v:?}")).collect();
    format!("[{}]", items.join(", "))
}

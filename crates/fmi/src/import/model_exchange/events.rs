//! Events: event mode for a set that needs it, the event iteration (`fmi2NewDiscreteStates`
//! until the FMU needs no more, its next time event checked), continuous-time mode again with
//! the integrator started again; the step events of `fmi2CompletedIntegratorStep`, and a
//! changed input that made an event indicator change sign.

use super::calls::{Call, EventUpdate};
use super::{isclose_in, MeInstance, Mode, MAX_EVENTS_KEPT, MAX_EVENT_ITERATIONS};
use crate::FmuError;

impl MeInstance {
    /// Discrete inputs and tunable parameters may be set in event mode only (FMI 2.0
    /// §3.2.3): in continuous-time mode, enter it; the event iteration follows before the
    /// next get or step ([`MeInstance::settle`]).
    pub(super) fn event_mode_for_set(&mut self) -> Result<(), FmuError> {
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
    pub(super) fn settle(&mut self) -> Result<(), FmuError> {
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
    pub(super) fn iterate_discrete_states(&mut self) -> Result<EventUpdate, FmuError> {
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

    pub(super) fn enter_continuous_time_mode(&mut self) -> Result<(), FmuError> {
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

    /// The event detected at the current time, handled (event iteration).
    pub(super) fn handle_event(&mut self, before: f64) -> Result<(), FmuError> {
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

    /// `fmi2CompletedIntegratorStep` (unless the FMU does not need it): whether it asks
    /// for event mode, and whether to end the simulation.
    pub(super) fn completed_integrator_step(&mut self) -> Result<(bool, bool), FmuError> {
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
    pub(super) fn input_event(&mut self) -> Result<bool, FmuError> {
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
}

//! A communication step: from the current time to `t + h`, every time, state and step event
//! on the way handled, or (for [`MeInstance::step_to_event`]) stopped at to show the values
//! before and after it.

use super::{isclose_in, MeInstance, MeStop, Mode};
use crate::functions::Function;
use crate::FmuError;

impl MeInstance {
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
}

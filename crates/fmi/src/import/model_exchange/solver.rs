//! CVODE driven from the instance: the states, nominals and event indicators read from the
//! FMU, the integrator started and started again, one integration to the next stop (a time,
//! or a root: a state event) with the FMU then set to it, and CVODE's errors and warnings
//! told as the instance's.

use super::calls::{shown_values, Call, Vector};
use super::cvode::{Cvode, Reached, Settings};
use super::system::FmuSystem;
use super::{cvode, MeInstance, MAX_NUM_STEPS};
use crate::fmi2::fmi2Status;
use crate::FmuError;

impl MeInstance {
    /// A vector the FMU fills (`fmi2GetContinuousStates`, ...), into `out`.
    fn get_vector(&self, v: Vector, out: &mut [f64]) -> Result<(), FmuError> {
        let s = unsafe { self.api.get(self.inst.raw(), v, out) };
        self.check_with(self.api.name(Call::Get(v)), || shown_values(out), s)
    }

    /// A vector the FMU fills into one of this instance's own buffers (`buffer` picks it).
    fn get_into(
        &mut self,
        v: Vector,
        buffer: fn(&mut MeInstance) -> &mut Vec<f64>,
    ) -> Result<(), FmuError> {
        let mut out = std::mem::take(buffer(self));
        let r = self.get_vector(v, &mut out);
        *buffer(self) = out;
        r
    }

    /// The states into `self.x` and, when `nominals`, the absolute tolerances from the
    /// nominals: rtol · nominal (FMPy; a nominal that is not a positive number counts as 1).
    fn read_states(&mut self, nominals: bool) -> Result<(), FmuError> {
        if self.nx == 0 {
            return Ok(());
        }
        self.get_into(Vector::States, |me| &mut me.x)?;
        if nominals {
            let r = self.get_into(Vector::Nominals, |me| &mut me.atol);
            let rtol = self.rtol;
            for a in self.atol.iter_mut() {
                *a = rtol * if a.is_finite() && *a > 0.0 { *a } else { 1.0 };
            }
            r?;
        }
        Ok(())
    }

    /// The event indicators into `self.z`.
    pub(super) fn read_indicators(&mut self) -> Result<(), FmuError> {
        if self.nz == 0 {
            return Ok(());
        }
        self.get_into(Vector::EventIndicators, |me| &mut me.z)?;
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
    pub(super) fn start_solver(&mut self) -> Result<(), FmuError> {
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
    pub(super) fn restart_solver(&mut self, nominals_changed: bool) -> Result<(), FmuError> {
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

    /// CVODE from the current time to `t_next`, stopping at a root; the FMU then holds the
    /// time and states reached (`fmi2SetContinuousStates`, `fmi2SetTime`, as FMPy). True at
    /// a state event.
    pub(super) fn integrate_to(&mut self, t_next: f64) -> Result<bool, FmuError> {
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
}

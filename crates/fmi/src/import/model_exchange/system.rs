//! The FMU as CVODE's system: the right-hand side and the root functions call the FMU
//! (FMPy's `CVodeSolver.f` and `.g`): `fmi2SetTime`, `fmi2SetContinuousStates`, then
//! `fmi2GetDerivatives` or `fmi2GetEventIndicators` (FMI 3.0: the same with `fmi3`, and
//! `fmi3GetContinuousStateDerivatives`). An FMU without continuous states has one dummy
//! state with ẋ = 0 (FMPy's `discrete` case), never set into the FMU.

use super::calls::{shown_values, Call, CallTrace, Component, MeCalls, Vector};
use super::cvode::System;
use crate::fmi2::*;

/// The FMI call that failed in the last callback, for the error message: `problem` is what
/// it did (`returned fmi2Error`, `returned NaN for der(x)`).
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    pub call: &'static str,
    pub problem: String,
    pub time: f64,
}

pub struct FmuSystem {
    comp: Component,
    api: MeCalls,
    nx: usize,
    /// The derivatives' names (`der(x)`), for a message about one of them.
    derivative_names: Vec<String>,
    pub failure: Option<Failure>,
    /// The last failure CVODE retried with a smaller step (fmi2Discard, a NaN derivative):
    /// the likely cause when it later gives up for another reason.
    pub retried: Option<Failure>,
    trace: Option<CallTrace>,
}

impl FmuSystem {
    pub fn new(
        comp: Component,
        api: MeCalls,
        derivative_names: Vec<String>,
        trace: Option<CallTrace>,
    ) -> FmuSystem {
        FmuSystem {
            comp,
            api,
            nx: derivative_names.len(),
            derivative_names,
            failure: None,
            retried: None,
            trace,
        }
    }

    /// The call to the trace, when there is one.
    fn traced(&self, t: f64, call: &str, args: impl FnOnce() -> String, status: fmi2Status) {
        if let Some(trace) = &self.trace {
            trace(t, call, &args(), status);
        }
    }

    /// A status as a callback's result: 0 for OK and Warning; fmi2Discard is an error CVODE
    /// may recover from with a smaller step (1), anything else stops it (−1). The failure of
    /// the last callback is kept: when CVODE gives up, it is the one that made it.
    fn status(&mut self, call: &'static str, status: fmi2Status, time: f64) -> i32 {
        if status.is_ok() {
            self.failure = None;
            return 0;
        }
        self.failure = Some(Failure {
            call,
            problem: format!("returned {}", self.api.status_name(status)),
            time,
        });
        if status == fmi2Status::DISCARD {
            self.retried = self.failure.clone();
            1
        } else {
            -1
        }
    }

    /// A value that is not a number (red team M17: a NaN derivative only showed as CVODE's
    /// "t + h = t", a NaN event indicator silently missed its event).
    fn not_a_number(&mut self, call: &'static str, what: String, v: f64, time: f64) {
        self.failure = Some(Failure {
            call,
            problem: format!("returned {v} for {what}"),
            time,
        });
    }

    /// The time into the FMU (`fmi2SetTime`).
    fn set_time(&mut self, t: f64) -> i32 {
        // SAFETY: the component is alive while the integrator is (the instance owns both
        // and drops the integrator first).
        let s = unsafe { self.api.set_time(self.comp, t) };
        let call = self.api.name(Call::SetTime);
        self.traced(t, call, || format!("time={t:?}"), s);
        self.status(call, s, t)
    }

    /// `fmi2SetTime` and, with states, `fmi2SetContinuousStates`.
    fn set(&mut self, t: f64, x: &[f64]) -> i32 {
        let r = self.set_time(t);
        if r != 0 || self.nx == 0 {
            return r;
        }
        // SAFETY: as set_time; x has nx values.
        let s = unsafe { self.api.set_states(self.comp, &x[..self.nx]) };
        let call = self.api.name(Call::SetContinuousStates);
        self.traced(t, call, || shown_values(&x[..self.nx]), s);
        self.status(call, s, t)
    }

    /// A vector from the FMU into `out`, traced; its status as a callback's result.
    fn get(&mut self, t: f64, v: Vector, out: &mut [f64]) -> i32 {
        // SAFETY: as set_time.
        let s = unsafe { self.api.get(self.comp, v, out) };
        let call = self.api.name(Call::Get(v));
        self.traced(t, call, || shown_values(out), s);
        self.status(call, s, t)
    }

    /// The time and states set, then one vector got (CVODE's right-hand side, its roots):
    /// 0, or the first call's non-zero flag.
    fn set_then_get(&mut self, t: f64, x: &[f64], v: Vector, out: &mut [f64]) -> i32 {
        let r = self.set(t, x);
        if r != 0 {
            return r;
        }
        self.get(t, v, out)
    }
}

impl System for FmuSystem {
    fn rhs(&mut self, t: f64, x: &[f64], dx: &mut [f64]) -> i32 {
        if self.nx == 0 {
            dx.iter_mut().for_each(|d| *d = 0.0);
            return self.set_time(t);
        }
        let r = self.set_then_get(t, x, Vector::Derivatives, dx);
        if r != 0 {
            return r;
        }
        // An infinite or NaN derivative: CVODE may retry with a smaller step (a trial
        // point outside the model's domain), and stops when it keeps coming back.
        if let Some(k) = dx.iter().position(|d| !d.is_finite()) {
            let what = self.derivative_names[k].clone();
            let call = self.api.name(Call::Get(Vector::Derivatives));
            self.not_a_number(call, what, dx[k], t);
            self.retried = self.failure.clone();
            return 1;
        }
        0
    }

    fn roots(&mut self, t: f64, x: &[f64], g: &mut [f64]) -> i32 {
        let r = self.set_then_get(t, x, Vector::EventIndicators, g);
        if r != 0 {
            return r;
        }
        // A NaN indicator has no sign: its crossing could never be found.
        if let Some(k) = g.iter().position(|z| z.is_nan()) {
            let what = format!("event indicator {} of {}", k + 1, g.len());
            let call = self.api.name(Call::Get(Vector::EventIndicators));
            self.not_a_number(call, what, g[k], t);
            return -1;
        }
        0
    }
}

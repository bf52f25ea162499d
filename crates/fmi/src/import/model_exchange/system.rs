//! The FMU as CVODE's system: the right-hand side and the root functions call the FMU
//! (FMPy's `CVodeSolver.f` and `.g`): `fmi2SetTime`, `fmi2SetContinuousStates`, then
//! `fmi2GetDerivatives` or `fmi2GetEventIndicators`. An FMU without continuous states has
//! one dummy state with ẋ = 0 (FMPy's `discrete` case), never set into the FMU.

use super::cvode::System;
use super::{shown_values, CallTrace};
use crate::fmi2::*;
use crate::import::library::MeApi;

/// The FMI call that failed in the last callback, for the error message: `problem` is what
/// it did (`returned fmi2Error`, `returned NaN for der(x)`).
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    pub call: &'static str,
    pub problem: String,
    pub time: f64,
}

pub struct FmuSystem {
    comp: fmi2Component,
    api: MeApi,
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
        comp: fmi2Component,
        api: MeApi,
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
            problem: format!("returned {status}"),
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

    /// `fmi2SetTime` and, with states, `fmi2SetContinuousStates`.
    fn set(&mut self, t: f64, x: &[f64]) -> i32 {
        // SAFETY: the component is alive while the integrator is (the instance owns both
        // and drops the integrator first); x has nx values.
        let s = unsafe { (self.api.fmi2SetTime)(self.comp, t) };
        self.traced(t, "fmi2SetTime", || format!("time={t:?}"), s);
        let r = self.status("fmi2SetTime", s, t);
        if r != 0 || self.nx == 0 {
            return r;
        }
        let s = unsafe { (self.api.fmi2SetContinuousStates)(self.comp, x.as_ptr(), self.nx) };
        self.traced(
            t,
            "fmi2SetContinuousStates",
            || shown_values(&x[..self.nx]),
            s,
        );
        self.status("fmi2SetContinuousStates", s, t)
    }
}

impl System for FmuSystem {
    fn rhs(&mut self, t: f64, x: &[f64], dx: &mut [f64]) -> i32 {
        if self.nx == 0 {
            dx.iter_mut().for_each(|d| *d = 0.0);
            let s = unsafe { (self.api.fmi2SetTime)(self.comp, t) };
            self.traced(t, "fmi2SetTime", || format!("time={t:?}"), s);
            return self.status("fmi2SetTime", s, t);
        }
        let r = self.set(t, x);
        if r != 0 {
            return r;
        }
        let s = unsafe { (self.api.fmi2GetDerivatives)(self.comp, dx.as_mut_ptr(), self.nx) };
        self.traced(t, "fmi2GetDerivatives", || shown_values(dx), s);
        let r = self.status("fmi2GetDerivatives", s, t);
        if r != 0 {
            return r;
        }
        // An infinite or NaN derivative: CVODE may retry with a smaller step (a trial
        // point outside the model's domain), and stops when it keeps coming back.
        if let Some(k) = dx.iter().position(|d| !d.is_finite()) {
            let what = self.derivative_names[k].clone();
            self.not_a_number("fmi2GetDerivatives", what, dx[k], t);
            self.retried = self.failure.clone();
            return 1;
        }
        0
    }

    fn roots(&mut self, t: f64, x: &[f64], g: &mut [f64]) -> i32 {
        let r = self.set(t, x);
        if r != 0 {
            return r;
        }
        let s = unsafe { (self.api.fmi2GetEventIndicators)(self.comp, g.as_mut_ptr(), g.len()) };
        self.traced(t, "fmi2GetEventIndicators", || shown_values(g), s);
        let r = self.status("fmi2GetEventIndicators", s, t);
        if r != 0 {
            return r;
        }
        // A NaN indicator has no sign: its crossing could never be found.
        if let Some(k) = g.iter().position(|z| z.is_nan()) {
            let what = format!("event indicator {} of {}", k + 1, g.len());
            self.not_a_number("fmi2GetEventIndicators", what, g[k], t);
            return -1;
        }
        0
    }
}

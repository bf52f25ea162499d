//! The FMU as CVODE's system: the right-hand side and the root functions call the FMU
//! (FMPy's `CVodeSolver.f` and `.g`): `fmi2SetTime`, `fmi2SetContinuousStates`, then
//! `fmi2GetDerivatives` or `fmi2GetEventIndicators`. An FMU without continuous states has
//! one dummy state with ẋ = 0 (FMPy's `discrete` case), never set into the FMU.

use super::cvode::System;
use super::{shown_values, CallTrace};
use crate::fmi2::*;
use crate::import::library::MeApi;

/// The first FMI call that failed inside a callback, for the error message.
#[derive(Clone, Debug, PartialEq)]
pub struct Failure {
    pub call: &'static str,
    pub status: fmi2Status,
    pub time: f64,
}

pub struct FmuSystem {
    comp: fmi2Component,
    api: MeApi,
    nx: usize,
    pub failure: Option<Failure>,
    trace: Option<CallTrace>,
}

impl FmuSystem {
    pub fn new(comp: fmi2Component, api: MeApi, nx: usize, trace: Option<CallTrace>) -> FmuSystem {
        FmuSystem {
            comp,
            api,
            nx,
            failure: None,
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
    /// may recover from with a smaller step (1), anything else stops it (−1). The first
    /// failure is kept.
    fn status(&mut self, call: &'static str, status: fmi2Status, time: f64) -> i32 {
        if status.is_ok() {
            return 0;
        }
        if self.failure.is_none() {
            self.failure = Some(Failure { call, status, time });
        }
        if status == fmi2Status::DISCARD {
            1
        } else {
            -1
        }
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
        self.status("fmi2GetDerivatives", s, t)
    }

    fn roots(&mut self, t: f64, x: &[f64], g: &mut [f64]) -> i32 {
        let r = self.set(t, x);
        if r != 0 {
            return r;
        }
        let s = unsafe { (self.api.fmi2GetEventIndicators)(self.comp, g.as_mut_ptr(), g.len()) };
        self.traced(t, "fmi2GetEventIndicators", || shown_values(g), s);
        self.status("fmi2GetEventIndicators", s, t)
    }
}

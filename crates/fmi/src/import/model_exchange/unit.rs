//! What the integrator drives, in either FMI version: the instance ([`Unit`], for the
//! calls a Co-Simulation instance has too: values, initialisation, reset), made from the
//! library loaded for Model Exchange ([`MeLibrary`]). Its Model Exchange calls (time,
//! states, derivatives, event indicators, the event iteration) are [`super::calls`].

use super::super::instance::Instance;
use super::super::instance3::Instance3;
use super::super::library::Library;
use super::super::library3::Library3;
use super::super::log::LogSink;
use super::calls::Component;
use crate::FmuError;
use std::sync::Arc;

/// The library a Model Exchange instance is made from, loaded for Model Exchange
/// ([`Library::load_model_exchange`], [`Library3::load_model_exchange`]).
#[derive(Clone)]
pub enum MeLibrary {
    V2(Arc<Library>),
    V3(Arc<Library3>),
}

impl From<Arc<Library>> for MeLibrary {
    fn from(l: Arc<Library>) -> MeLibrary {
        MeLibrary::V2(l)
    }
}

impl From<Arc<Library3>> for MeLibrary {
    fn from(l: Arc<Library3>) -> MeLibrary {
        MeLibrary::V3(l)
    }
}

/// The FMU instance itself: its values, initialisation and reset, as a Co-Simulation
/// instance of its version has them.
pub(crate) enum Unit {
    V2(Instance),
    V3(Instance3),
}

/// The same expression for the instance of either version.
macro_rules! both {
    ($unit:expr, $i:ident => $e:expr) => {
        match $unit {
            Unit::V2($i) => $e,
            Unit::V3($i) => $e,
        }
    };
}

impl Unit {
    pub fn name(&self) -> &str {
        both!(self, i => &i.name)
    }
    pub fn time(&self) -> f64 {
        both!(self, i => i.time)
    }
    /// Where the integration stands (the instance's time for messages and steps).
    pub fn set_time(&mut self, t: f64) {
        both!(self, i => i.time = t)
    }
    pub fn raw(&self) -> Component {
        match self {
            Unit::V2(i) => i.raw() as Component,
            Unit::V3(i) => i.raw(),
        }
    }
    pub fn sink(&self) -> &LogSink {
        both!(self, i => i.sink())
    }
    pub fn last_log_lines(&self) -> Vec<String> {
        both!(self, i => i.last_log_lines())
    }
    pub fn set_echo(&mut self, on: bool) {
        both!(self, i => i.set_echo(on))
    }
    pub fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        match self {
            Unit::V2(i) => i.set_debug_logging(on, &[]),
            Unit::V3(i) => i.set_debug_logging(on),
        }
    }
    /// FMI 2.0: `fmi2SetupExperiment`; FMI 3.0: kept for `fmi3EnterInitializationMode`.
    pub fn setup_experiment(
        &mut self,
        start: f64,
        stop: Option<f64>,
        tolerance: Option<f64>,
    ) -> Result<(), FmuError> {
        both!(self, i => i.setup_experiment(start, stop, tolerance))
    }
    pub fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        both!(self, i => i.enter_initialization_mode())
    }
    pub fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        both!(self, i => i.exit_initialization_mode())
    }
    pub fn terminate(&mut self) -> Result<(), FmuError> {
        both!(self, i => i.terminate())
    }
    pub fn reset(&mut self) -> Result<(), FmuError> {
        both!(self, i => i.reset())
    }
    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        both!(self, i => i.get_real(vrs, out))
    }
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        both!(self, i => i.set_real(vrs, values))
    }
    pub fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        match self {
            Unit::V2(i) => i.get_integer(vrs, out),
            Unit::V3(i) => i.get_int(vrs, out),
        }
    }
    pub fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        match self {
            Unit::V2(i) => i.set_integer(vrs, values),
            Unit::V3(i) => i.set_int(vrs, values),
        }
    }
    pub fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        match self {
            Unit::V2(i) => i.get_boolean(vrs, out),
            Unit::V3(i) => i.get_int(vrs, out),
        }
    }
    pub fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        match self {
            Unit::V2(i) => i.set_boolean(vrs, values),
            Unit::V3(i) => i.set_int(vrs, values),
        }
    }
    pub fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        both!(self, i => i.get_string(vrs, out))
    }
    pub fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        both!(self, i => i.set_string(vrs, values))
    }
}

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
use crate::FmuInstance;
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

/// The instance of either version is the one seam, [`FmuInstance`]: what Model Exchange
/// asks of it beyond its own calls (values, initialisation, reset) goes through it, so
/// that `unit.get_real(…)` reads alike for both.
impl std::ops::Deref for Unit {
    type Target = dyn FmuInstance;
    fn deref(&self) -> &Self::Target {
        match self {
            Unit::V2(i) => i,
            Unit::V3(i) => i,
        }
    }
}

impl std::ops::DerefMut for Unit {
    fn deref_mut(&mut self) -> &mut Self::Target {
        match self {
            Unit::V2(i) => i,
            Unit::V3(i) => i,
        }
    }
}

impl Unit {
    /// Where the integration stands (the instance's time for messages and steps).
    pub fn set_time(&mut self, t: f64) {
        match self {
            Unit::V2(i) => i.time = t,
            Unit::V3(i) => i.time = t,
        }
    }
    pub fn raw(&self) -> Component {
        match self {
            Unit::V2(i) => i.raw() as Component,
            Unit::V3(i) => i.raw(),
        }
    }
    pub fn sink(&self) -> &LogSink {
        match self {
            Unit::V2(i) => i.sink(),
            Unit::V3(i) => i.sink(),
        }
    }
}

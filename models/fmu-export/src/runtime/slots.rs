//! What get and set check per value reference, and where an instance stands between its
//! calls.

use crate::model::ModelError;
use crate::state::{StateReader, StateWriter};
use crate::variables::ScalarType;
use tb_fmi::Phase;

/// Where an instance stands, besides its variables and its model: the phase, the time and
/// what changed since the model last saw it. An FMU state saves and restores it whole, and
/// (de)serialises it in one place ([`RunState::write`], [`RunState::read`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct RunState {
    pub(super) phase: Phase,
    pub(super) time: f64,
    /// `startTime` of fmi2SetupExperiment (the model sees it as `Context::start_time`).
    pub(super) start_time: f64,
    pub(super) stop_time: Option<f64>,
    /// Parameters or inputs changed in initialization mode since the model was initialised.
    pub(super) init_dirty: bool,
    /// Inputs set since the last step (feed-through outputs need recomputing).
    pub(super) inputs_changed: bool,
    /// Tunable parameters set since the last step.
    pub(super) params_changed: bool,
}

impl RunState {
    /// A freshly instantiated (or reset) instance.
    pub(super) const INSTANTIATED: RunState = RunState {
        phase: Phase::Instantiated,
        time: 0.0,
        start_time: 0.0,
        stop_time: None,
        init_dirty: true,
        inputs_changed: false,
        params_changed: false,
    };

    /// Whether sets now are those of instantiated / initialization mode.
    #[inline(always)]
    pub(super) fn initializing(&self) -> bool {
        matches!(self.phase, Phase::Instantiated | Phase::InitializationMode)
    }

    /// A variable was set (`init`: in instantiated / initialization mode): what must be
    /// redone before it takes effect.
    #[inline(always)]
    pub(super) fn mark_set(&mut self, init: bool, is_input: bool) {
        if init {
            self.init_dirty = true;
        } else if is_input {
            self.inputs_changed = true;
        } else {
            self.params_changed = true;
        }
    }

    /// The model was (re)initialised from the variables as they are.
    pub(super) fn initialized(&mut self) {
        self.init_dirty = false;
        self.inputs_changed = false;
        self.params_changed = false;
    }

    pub(super) fn write(&self, w: &mut StateWriter) {
        w.u64(self.phase as u8 as u64);
        w.f64(self.time);
        w.f64(self.start_time);
        w.bool(self.stop_time.is_some());
        w.f64(self.stop_time.unwrap_or(0.0));
        w.bool(self.init_dirty);
        w.bool(self.inputs_changed);
        w.bool(self.params_changed);
    }

    pub(super) fn read(r: &mut StateReader<'_>) -> Result<RunState, ModelError> {
        let p = r.u64()?;
        let phase = u8::try_from(p)
            .ok()
            .and_then(Phase::from_u8)
            .ok_or_else(|| ModelError::new(format!("bad phase {p}")))?;
        let time = r.f64()?;
        let start_time = r.f64()?;
        let has_stop = r.bool()?;
        let stop = r.f64()?;
        Ok(RunState {
            phase,
            time,
            start_time,
            stop_time: has_stop.then_some(stop),
            init_dirty: r.bool()?,
            inputs_changed: r.bool()?,
            params_changed: r.bool()?,
        })
    }
}

/// Per value reference, what get/set must check: precomputed so the numeric calls of
/// every step are a lookup and a few compares.
#[derive(Clone, Copy, Debug)]
pub(super) struct Slot {
    pub(super) index: u32,
    pub(super) ty: ScalarType,
    pub(super) has_start: bool,
    /// Settable in instantiated / initialization mode.
    pub(super) settable_init: bool,
    /// Settable in step complete (inputs and tunable parameters).
    pub(super) settable_run: bool,
    pub(super) is_input: bool,
    pub(super) min: f64,
    pub(super) max: f64,
    /// A Real's byte offset in `M::Vars` (`usize::MAX`: not a Real).
    pub(super) offset: usize,
}

impl Slot {
    /// Whether a get may read the variable (a calculated one has no value before
    /// initialisation).
    #[inline(always)]
    pub(super) fn readable(&self, instantiated: bool) -> bool {
        self.has_start || !instantiated
    }

    /// Whether a set may write the variable (`init`: in instantiated / initialization mode).
    #[inline(always)]
    pub(super) fn settable(&self, init: bool) -> bool {
        if init {
            self.settable_init
        } else {
            self.settable_run
        }
    }

    /// The rules every set obeys, as the fast path and [`Runtime::set`] both check them:
    /// settable now, finite, within min/max. A value they refuse may still be taken by
    /// [`Runtime::set`]'s exceptions (a rounding just outside an input's range, `range_check
    /// = 0`).
    #[inline(always)]
    pub(super) fn accepts(&self, x: f64, init: bool) -> bool {
        self.settable(init) && x.is_finite() && (self.min..=self.max).contains(&x)
    }
}

pub(super) const NO_SLOT: Slot = Slot {
    offset: usize::MAX,
    index: u32::MAX,
    ty: ScalarType::Real,
    has_start: false,
    settable_init: false,
    settable_run: false,
    is_input: false,
    min: f64::NEG_INFINITY,
    max: f64::INFINITY,
};

//! Observers of a run (libcosim's observers): what watches a [`Simulation`] while it runs.
//! The master tells every observer of each moment of a run ([`Moment`]: the start, each
//! macro step, each event row of a Model Exchange instance, an FMU's own end) through one
//! small trait, [`RunObserver`]; an observer may end the run ([`ControlFlow::Break`] with
//! the reason the summary reports) or fail it (an error). The master's own are observers
//! too: the recording ([`Recording`]) and the plan's stop condition ([`StopWhen`]); a
//! caller attaches its own with [`Simulation::observe`] (a progress bar, a live plot,
//! a condition of its own).
//!
//! An observer reads the exchange through a [`RunView`]. The outputs only the recording
//! needs are not read from the FMUs after every step (a tenth of the steps at 1 ms and
//! 100 Hz): [`RunView::signals`] reads them when an observer first asks at that moment.
//!
//! [`Simulation`]: crate::Simulation
//! [`Simulation::observe`]: crate::Simulation::observe

use crate::exchange::Exchange;
use crate::plan::{Condition, Plan};
use crate::SystemError;
use std::ops::ControlFlow;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use tb_table::Table;

/// Where in a run an observer is called.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Moment {
    /// After initialisation, at the start time, before the first step.
    Start,
    /// After macro step `k` (1 for the first). `last`: the step that reaches a fixed stop
    /// time (a run that ends on a condition does not know its last step in advance).
    Step { k: u64, last: bool },
    /// Just before or just after an event inside a step, at the event's time (a Model
    /// Exchange instance with event rows, `Simulation::record_events`).
    Event,
    /// An FMU asked to end the run; the time is its last successful one.
    EndedByFmu,
}

/// How a run ended, for [`RunObserver::finished`].
#[derive(Clone, Debug, PartialEq)]
pub enum Ended {
    /// It reached its horizon: the stop time, or a stop condition's `max_time`.
    Horizon,
    /// An observer ended it; the reason it gave (e.g. the stop condition, "vehicle.lap >= 1").
    Observer(String),
    /// An FMU asked to end it.
    Fmu { instance: String },
}

/// The exchange at one moment of a run, as an observer sees it.
pub struct RunView<'a> {
    ex: &'a mut Exchange,
    time: f64,
    moment: Moment,
    start: f64,
    horizon: f64,
    /// The record-only outputs were read at this moment.
    recorded_read: bool,
}

impl<'a> RunView<'a> {
    pub(crate) fn new(
        ex: &'a mut Exchange,
        time: f64,
        moment: Moment,
        (start, horizon): (f64, f64),
    ) -> RunView<'a> {
        RunView {
            ex,
            time,
            moment,
            start,
            horizon,
            recorded_read: false,
        }
    }

    /// The simulated time of this moment, s.
    #[inline]
    pub fn time(&self) -> f64 {
        self.time
    }

    #[inline]
    pub fn moment(&self) -> Moment {
        self.moment
    }

    /// The run's start time, s.
    pub fn start(&self) -> f64 {
        self.start
    }

    /// The latest time the run can reach, s: the stop time, or the stop condition's
    /// `max_time` after the start.
    pub fn horizon(&self) -> f64 {
        self.horizon
    }

    pub fn plan(&self) -> &Arc<Plan> {
        self.ex.plan()
    }

    /// Every how many steps the recording keeps a row (`[record] decimation`): an observer
    /// that writes beside the recording keeps the same rows with it as its
    /// [`RunObserver::step_interval`].
    pub fn record_decimation(&self) -> u64 {
        self.ex.plan().file.record.decimation as u64
    }

    /// A value read after every step without asking any FMU: a slot a connection, the
    /// stop condition or a replay's distance basis reads ([`Plan::read_every_step`]). A
    /// record-only slot holds its value of the last moment its outputs were read.
    #[inline]
    pub fn current(&self, slot: usize) -> f64 {
        self.ex.signals()[slot]
    }

    /// Every signal's value now, by slot (`plan().signals`). The first observer that asks
    /// at a moment has the FMUs' record-only outputs read.
    #[inline]
    pub fn signals(&mut self) -> Result<&[f64], SystemError> {
        self.read_recorded()?;
        Ok(self.ex.signals())
    }

    /// The String signals' values now, by slot (empty for a slot of another type).
    pub fn texts(&mut self) -> Result<&[String], SystemError> {
        self.read_recorded()?;
        Ok(self.ex.texts())
    }

    #[inline]
    fn read_recorded(&mut self) -> Result<(), SystemError> {
        if !self.recorded_read {
            self.ex.publish_recorded()?;
            self.recorded_read = true;
        }
        Ok(())
    }
}

/// Something that watches a run. Each observer is told of the moments it asks for (every
/// one but the steps it skips, [`RunObserver::step_interval`]), in the order the observers
/// were attached: the recording first, then the stop condition, then the caller's.
pub trait RunObserver: Send {
    /// A moment of the run. `Break(reason)` ends the run after this moment (after the
    /// step an event row is part of): every observer still sees it, the first reason
    /// given is the summary's `stopped_by`. An error fails the run with that error.
    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError>;

    /// Every how many steps this observer sees one (1: each): with `n` it sees steps n,
    /// 2n, 3n... (counted from its last one when `n` changes); the start, events, an FMU's
    /// end and the end are always told. Asked again after every step it sees, so it may
    /// change as the run goes on (the CLI's Ctrl-C adapts it to the steps' wall time). The
    /// recording and the stop condition see every step.
    fn step_interval(&self) -> u64 {
        1
    }

    /// A flag that, once set (by a signal handler, by another thread: a stop button), has
    /// the master call this observer at the next step whatever its `step_interval`: an
    /// observer that must answer at once but has nothing to do until then asks for no
    /// steps (`u64::MAX`) and gives its flag, which the master reads at every step (an
    /// atomic load). Asked at the start of each run.
    fn wake_flag(&self) -> Option<Arc<AtomicBool>> {
        None
    }

    /// The run completed (not called for a run that failed), with the values at its end.
    fn finished(&mut self, _now: &mut RunView<'_>, _how: &Ended) -> Result<(), SystemError> {
        Ok(())
    }
}

/// The steps an observer that must answer promptly but cheaply (Ctrl-C) lets pass between
/// two looks: about a millisecond of wall time, from 1 to 4096 steps, doubled while its
/// calls come faster and halved when they come slower than every 20 ms. So a lap's loop
/// (a microsecond per step) is not slowed, and a slow FMU's run is still looked at after
/// each step.
pub struct WallClockInterval {
    steps: u64,
    last_call: std::time::Instant,
}

impl Default for WallClockInterval {
    fn default() -> Self {
        WallClockInterval {
            steps: 1,
            last_call: std::time::Instant::now(),
        }
    }
}

impl WallClockInterval {
    /// The steps to let pass now ([`RunObserver::step_interval`]).
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// At each call: adapt to the wall time since the last one.
    pub fn called(&mut self) {
        let wall = std::time::Instant::now();
        let since = wall.duration_since(self.last_call).as_secs_f64();
        self.last_call = wall;
        if since < 1e-3 {
            self.steps = (self.steps * 2).min(4096);
        } else if since > 20e-3 {
            self.steps = (self.steps / 2).max(1);
        }
    }
}

/// The recording: a row of the plan's recorded signals at the start, at every
/// `decimation`-th step (a uniform time base for filters), at a fixed stop time, at each
/// event row and at an FMU's own end.
pub struct Recording {
    table: Table,
    /// The recorded slots, in column order after time.
    slots: Vec<usize>,
    /// The recording has text columns (String signals).
    has_text: bool,
    decimation: u64,
    /// Rows before and after events are recorded (`Simulation::record_events`; the master
    /// then steps event by event).
    pub(crate) event_rows: bool,
}

impl Recording {
    pub(crate) fn new(plan: &Plan) -> Result<Recording, SystemError> {
        let (names, record_units) = plan.record_columns();
        let mut table = Table::new(plan.path.display().to_string(), names, record_units)
            .map_err(|e| crate::invalid(plan.path.display().to_string(), format!("record: {e}")))?;
        for (k, &slot) in plan.record.iter().enumerate() {
            if plan.signals.signals[slot].is_text() {
                table.set_text(k + 1);
            }
        }
        Ok(Recording {
            has_text: (0..table.names().len()).any(|k| table.is_text(k)),
            table,
            slots: plan.record.clone(),
            decimation: plan.file.record.decimation as u64,
            event_rows: false,
        })
    }

    /// The recorded rows (time first).
    pub fn table(&self) -> &Table {
        &self.table
    }

    pub fn table_mut(&mut self) -> &mut Table {
        &mut self.table
    }

    fn push_row(&mut self, now: &mut RunView<'_>) -> Result<(), SystemError> {
        let t = now.time();
        let signals = now.signals()?;
        let slots = &self.slots;
        self.table
            .push_row(std::iter::once(t).chain(slots.iter().map(|&s| signals[s])));
        if self.has_text {
            let texts = now.texts()?;
            for (k, &s) in self.slots.iter().enumerate() {
                if self.table.is_text(k + 1) {
                    self.table.push_text(k + 1, &texts[s]);
                }
            }
        }
        Ok(())
    }
}

impl RunObserver for Recording {
    #[inline(always)]
    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        let row = match now.moment() {
            Moment::Start => {
                self.table.clear();
                true
            }
            Moment::Step { k, last } => k.is_multiple_of(self.decimation) || last,
            Moment::Event => true,
            // With event rows an FMU's end in an event follows the row before that event,
            // at the same time: as FMPy's `record_events`, that row is the last.
            Moment::EndedByFmu => {
                !(self.event_rows && self.table.column_at(0).last() == Some(&now.time()))
            }
        };
        if row {
            self.push_row(now)?;
        }
        Ok(ControlFlow::Continue(()))
    }
}

/// The plan's stop condition (`stop = "vehicle.lap >= 1"`): ends the run after the first
/// step at which it holds; a run that reaches `max_time` without it fails.
pub struct StopWhen {
    condition: Condition,
    max_time: f64,
    /// The system file, for the error.
    path: String,
    held: bool,
}

impl StopWhen {
    pub(crate) fn new(plan: &Plan) -> Option<StopWhen> {
        match &plan.stop {
            crate::plan::Stop::Time(_) => None,
            crate::plan::Stop::When {
                condition,
                max_time,
            } => Some(StopWhen {
                condition: condition.clone(),
                max_time: *max_time,
                path: plan.path.display().to_string(),
                held: false,
            }),
        }
    }
}

impl RunObserver for StopWhen {
    #[inline(always)]
    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        match now.moment() {
            Moment::Start => self.held = false,
            Moment::Step { .. } => {
                // Read every step by the plan (its reader "stop condition").
                self.held = self.condition.holds(now.current(self.condition.slot));
                if self.held {
                    return Ok(ControlFlow::Break(self.condition.to_string()));
                }
            }
            Moment::Event | Moment::EndedByFmu => {}
        }
        Ok(ControlFlow::Continue(()))
    }

    fn finished(&mut self, now: &mut RunView<'_>, how: &Ended) -> Result<(), SystemError> {
        if *how == Ended::Horizon && !self.held {
            let c = &self.condition;
            return Err(SystemError::Stop(format!(
                "{}: the run did not complete within max_time = {} s: the stop condition {c} never held ({} = {} at the end)",
                self.path,
                self.max_time,
                c.signal,
                now.current(c.slot)
            )));
        }
        Ok(())
    }
}

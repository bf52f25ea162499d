//! The master: runs a [`Plan`] on a fixed macro step with an integer tick base. The
//! exchange of values between units ([`Exchange`]) is shared; how the units are stepped
//! within one macro step is a [`MasterAlgorithm`] ([`GaussSeidel`] in the plan's stepping
//! order, [`Jacobi`] all from the same values). Initialisation propagates outputs to inputs
//! to a fixed point. After each moment of a run the observers are told
//! ([`crate::observe`]): the recording, the plan's stop condition, a caller's own; the run
//! ends at the stop time or when one of them ends it. Instances are created once and reset
//! between runs.

use crate::config::Algorithm;
use crate::exchange::{Exchange, Unit};
use crate::observe::{Ended, Moment, Recording, RunObserver, RunView, StopWhen};
use crate::plan::{Endpoint, ParamSlot, ParamValue, Plan, Stop};
use crate::replay::Cursor;
use crate::{invalid, SystemError};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;
use tb_fmi::{MeStop, ScalarType};
use tb_table::Table;

/// How the units are advanced over one macro step.
pub trait MasterAlgorithm: Send + Sync {
    /// Which algorithm it is (its name in the system file and in messages:
    /// [`Algorithm::name`]).
    fn kind(&self) -> Algorithm;
    fn name(&self) -> &'static str {
        self.kind().name()
    }
    /// Advance every unit in `order` from `t` by `h`; the exchange buffer holds the outputs
    /// at `t + h` afterwards.
    fn step(&self, ex: &mut Exchange, order: &[usize], t: f64, h: f64) -> Result<(), SystemError>;
}

/// Gauss-Seidel: each unit in turn, with the outputs its predecessors produced this step.
pub struct GaussSeidel;

impl MasterAlgorithm for GaussSeidel {
    fn kind(&self) -> Algorithm {
        Algorithm::GaussSeidel
    }
    #[inline]
    fn step(&self, ex: &mut Exchange, order: &[usize], t: f64, h: f64) -> Result<(), SystemError> {
        for &u in order {
            ex.set_inputs(u)?;
            ex.do_step(u, t, h)?;
            ex.publish(u, t + h)?;
        }
        Ok(())
    }
}

/// Jacobi: every unit from the outputs at `t` (parallel stepping, as libcosim and FMPy's
/// SSP master do).
pub struct Jacobi;

impl MasterAlgorithm for Jacobi {
    fn kind(&self) -> Algorithm {
        Algorithm::Jacobi
    }
    #[inline]
    fn step(&self, ex: &mut Exchange, order: &[usize], t: f64, h: f64) -> Result<(), SystemError> {
        for &u in order {
            ex.gather(u);
        }
        for &u in order {
            ex.set_gathered(u)?;
            ex.do_step(u, t, h)?;
        }
        for &u in order {
            ex.publish(u, t + h)?;
        }
        Ok(())
    }
}

/// The algorithm a system file names.
pub fn algorithm(a: Algorithm) -> Box<dyn MasterAlgorithm> {
    match a {
        Algorithm::GaussSeidel => Box::new(GaussSeidel),
        Algorithm::Jacobi => Box::new(Jacobi),
    }
}

/// What a run did.
#[derive(Clone, Debug)]
pub struct RunSummary {
    pub steps: u64,
    pub simulated_time: f64,
    pub wall_time: f64,
    /// "stop time 10 s" or the condition that held, e.g. "vehicle.lap >= 1".
    pub stopped_by: String,
    /// The plan's reported signals at the end of the run, in the system file's order.
    pub reported: Vec<(String, f64)>,
}

impl RunSummary {
    /// A reported signal's final value.
    pub fn value(&self, name: &str) -> Option<f64> {
        self.reported.iter().find(|(n, _)| n == name).map(|r| r.1)
    }
}

/// What one run keeps while it goes on, besides the simulation.
struct RunState {
    /// Start time and horizon, s.
    span: (f64, f64),
    /// The plan's stop condition, an observer of this run.
    stop: Option<StopWhen>,
    /// The first reason an observer gave to end the run.
    ended: Option<String>,
    /// The last moment the observers were told of.
    last: Moment,
    /// The step at which each of the caller's observers is next due, and the first of
    /// those.
    due: Vec<u64>,
    next_due: u64,
    /// The caller's observers that a flag wakes ([`RunObserver::wake_flag`]): index, flag.
    wake: Vec<(usize, Arc<AtomicBool>)>,
}

/// The caller's observers, once [`RunState::callers_due`]: each at every moment but the
/// steps it lets pass ([`RunObserver::step_interval`], counted from the start or its last
/// step) unless its flag woke it.
#[inline(never)]
fn notify_callers(
    observers: &mut [Box<dyn RunObserver>],
    moment: Moment,
    now: &mut RunView<'_>,
    run: &mut RunState,
    mut flow: ControlFlow<String>,
) -> Result<ControlFlow<String>, SystemError> {
    let k = match moment {
        Moment::Step { k, .. } => {
            // One woken by its flag is due now (an atomic load per flag and step).
            let mut woken = false;
            for &(i, ref flag) in &run.wake {
                if flag.load(Ordering::Relaxed) {
                    run.due[i] = k;
                    woken = true;
                }
            }
            debug_assert!(k >= run.next_due || woken, "callers_due said so");
            Some(k)
        }
        Moment::Start => {
            run.due.clear();
            run.due.resize(observers.len(), 0);
            run.wake = (observers.iter().enumerate())
                .filter_map(|(i, o)| o.wake_flag().map(|f| (i, f)))
                .collect();
            Some(0)
        }
        Moment::Event | Moment::EndedByFmu => None,
    };
    let mut next_due = u64::MAX;
    for (o, due) in observers.iter_mut().zip(&mut run.due) {
        match k {
            Some(k) if k >= *due => {
                flow = first_break(flow, o.observe(now)?);
                *due = k.saturating_add(o.step_interval().max(1));
            }
            Some(_) => {}
            None => flow = first_break(flow, o.observe(now)?),
        }
        next_due = next_due.min(*due);
    }
    run.next_due = next_due;
    Ok(flow)
}

impl RunState {
    /// Whether a caller's observer is to be told of this moment: the lap loop's check, a
    /// comparison and a load per wake flag while none is.
    #[inline(always)]
    fn callers_due(&self, moment: Moment) -> bool {
        match moment {
            Moment::Step { k, .. } => {
                k >= self.next_due || self.wake.iter().any(|(_, f)| f.load(Ordering::Relaxed))
            }
            _ => true,
        }
    }
}

/// `a` unless it continues: the first reason to end a run wins.
#[inline]
fn first_break(a: ControlFlow<String>, b: ControlFlow<String>) -> ControlFlow<String> {
    match a {
        ControlFlow::Break(_) => a,
        ControlFlow::Continue(()) => b,
    }
}

/// A runnable system: a [`Plan`] plus its instances and exchange buffers.
pub struct Simulation {
    plan: Arc<Plan>,
    ex: Exchange,
    algorithm: Box<dyn MasterAlgorithm>,
    /// The recorded signals of the last run (time first): the first observer.
    recording: Recording,
    /// The caller's observers ([`Simulation::observe`]), after the recording and the stop
    /// condition.
    observers: Vec<Box<dyn RunObserver>>,
    /// Echo FMU messages with status OK to the log (off: kept only for error reports).
    pub echo_fmu_log: bool,
}

impl Simulation {
    /// Prepare the exchange tables of a plan; instances are created at the first run.
    pub fn new(plan: impl Into<Arc<Plan>>) -> Result<Simulation, SystemError> {
        let plan: Arc<Plan> = plan.into();
        Ok(Simulation {
            recording: Recording::new(&plan)?,
            observers: Vec::new(),
            algorithm: algorithm(plan.file.experiment.algorithm),
            ex: Exchange::new(&plan),
            plan,
            echo_fmu_log: true,
        })
    }

    /// Record a row before and after each event inside a step, as FMPy's `record_events`
    /// (`twinbench run model.fmu --record-events`): the values just before the event (its
    /// left limits) and just after it, both at the event's time; an event at a step's end
    /// adds the row before it. Only a unit that stops at events ([`Backend::stops_at_events`]:
    /// an in-process Model Exchange instance) has event rows; a system of more than one
    /// instance is refused (the others' values between their steps are not defined).
    pub fn record_events(&mut self, on: bool) -> Result<(), SystemError> {
        if on && self.plan.instances.len() != 1 {
            return Err(invalid(
                self.plan.path.display().to_string(),
                format!(
                    "event rows (record_events) are for a system of one instance; this one has {}",
                    self.plan.instances.len()
                ),
            ));
        }
        self.recording.event_rows = on;
        Ok(())
    }

    /// One step of the units in `order` (Gauss-Seidel), with the observers told of each
    /// event inside it (the recording's rows before and after it).
    fn step_recording_events(
        &mut self,
        order: &[usize],
        t: f64,
        h: f64,
        run: &mut RunState,
    ) -> Result<(), SystemError> {
        for &u in order {
            self.ex.set_inputs(u)?;
            loop {
                match self.ex.step_to_event(u, t, h)? {
                    MeStop::Reached => break,
                    MeStop::BeforeEvent(te) | MeStop::AfterEvent(te) => {
                        self.ex.time_replays_at(te);
                        self.ex.publish(u, te)?;
                        self.notify(Moment::Event, te, run)?;
                    }
                }
            }
            self.ex.publish(u, t + h)?;
        }
        Ok(())
    }

    /// Tell every observer of a moment: the recording, the stop condition, the caller's.
    /// The first reason to end the run is kept in `run`.
    #[inline(always)]
    fn notify(&mut self, moment: Moment, t: f64, run: &mut RunState) -> Result<(), SystemError> {
        run.last = moment;
        let mut now = RunView::new(&mut self.ex, t, moment, run.span);
        let mut flow = self.recording.observe(&mut now)?;
        if let Some(stop) = &mut run.stop {
            flow = first_break(flow, stop.observe(&mut now)?);
        }
        if !self.observers.is_empty() && run.callers_due(moment) {
            flow = notify_callers(&mut self.observers, moment, &mut now, run, flow)?;
        }
        if let ControlFlow::Break(reason) = flow {
            run.ended.get_or_insert(reason);
        }
        Ok(())
    }

    /// Tell every observer the run completed.
    fn notify_finished(
        &mut self,
        t: f64,
        run: &mut RunState,
        how: &Ended,
    ) -> Result<(), SystemError> {
        let mut now = RunView::new(&mut self.ex, t, run.last, run.span);
        self.recording.finished(&mut now, how)?;
        if let Some(stop) = &mut run.stop {
            stop.finished(&mut now, how)?;
        }
        for o in &mut self.observers {
            o.finished(&mut now, how)?;
        }
        Ok(())
    }

    /// Attach an observer of every later run ([`RunObserver`]): it sees each moment after
    /// the recording and the stop condition, in the order attached.
    pub fn observe(&mut self, observer: Box<dyn RunObserver>) {
        self.observers.push(observer);
    }

    /// Take the caller's observers off (returned in the order attached).
    pub fn take_observers(&mut self) -> Vec<Box<dyn RunObserver>> {
        std::mem::take(&mut self.observers)
    }

    /// The recorded signals of the last run (time first).
    pub fn recording(&self) -> &Table {
        self.recording.table()
    }

    /// The recording, to rename its columns before a run (`twinbench run model.fmu`).
    pub fn recording_mut(&mut self) -> &mut Table {
        self.recording.table_mut()
    }

    /// The plan this simulation runs.
    pub fn plan(&self) -> &Arc<Plan> {
        &self.plan
    }

    /// Run with another master algorithm.
    pub fn set_algorithm(&mut self, algorithm: Box<dyn MasterAlgorithm>) {
        self.algorithm = algorithm;
    }

    /// Set (or change, between runs) a parameter or input start value, resolved with
    /// [`Plan::parameter`] and checked with [`ParamSlot::check`].
    pub fn set(&mut self, slot: &ParamSlot, value: ParamValue) {
        if let Unit::Fmu(f) = &mut self.ex.units[slot.unit] {
            match f
                .params
                .iter_mut()
                .find(|p| p.0 == slot.vr && p.1.space() == slot.ty.value_space())
            {
                Some(p) => p.1 = value,
                None => f.params.push((slot.vr, value)),
            }
        }
    }

    /// Set a parameter by name from a TOML value (`--set`, files): resolved and checked.
    pub fn set_parameter(&mut self, name: &str, value: toml::Value) -> Result<(), SystemError> {
        let slot = self.plan.parameter(name)?;
        let v = slot.value_from_toml(&value, &format!("parameter \"{name}\""))?;
        self.set(&slot, v);
        Ok(())
    }

    /// Current value of a parameter set through the system (else the FMU's start value).
    pub fn value_of(&self, slot: &ParamSlot) -> Option<f64> {
        if let Unit::Fmu(f) = &self.ex.units[slot.unit] {
            let key = slot.key();
            if let Some(p) = f.params.iter().find(|p| (p.1.space(), p.0) == key) {
                return p.1.as_f64();
            }
        }
        slot.start
    }

    /// [`Simulation::value_of`] by name (None: not a settable variable).
    pub fn parameter(&self, name: &str) -> Option<f64> {
        let slot = self.plan.parameter(name).ok()?;
        self.value_of(&slot)
    }

    /// Free every instance now (a later run creates them again). The recording stays.
    pub fn free_instances(&mut self) {
        for unit in &mut self.ex.units {
            if let Unit::Fmu(f) = unit {
                f.instance = None;
            }
        }
    }

    /// Names of the exchange slots.
    pub fn signal_names(&self) -> Vec<String> {
        self.plan
            .signals
            .signals
            .iter()
            .map(|s| s.name.clone())
            .collect()
    }

    fn instantiate_all(&mut self, start: f64, stop: Option<f64>) -> Result<(), SystemError> {
        let echo = self.echo_fmu_log;
        for (k, unit) in self.ex.units.iter_mut().enumerate() {
            let Unit::Fmu(f) = unit else { continue };
            let def = &self.plan.instances[k];
            let reuse = match f.instance.as_mut() {
                Some(i) => i.reset().is_ok(),
                None => false,
            };
            if !reuse {
                f.instance = None;
                f.instance = Some(def.factory.create(&def.name, def.logging)?);
            }
            let inst = f.backend();
            inst.set_echo(echo);
            inst.setup_experiment(tb_fmi::Experiment {
                start,
                stop,
                tolerance: def.tolerance,
            })?;
            for (vr, v) in &f.params {
                let inst = f.instance.as_deref_mut().expect("created above");
                match v {
                    ParamValue::Real(x) => inst.set_real(&[*vr], &[*x])?,
                    ParamValue::Integer(i) => inst.set_integer(&[*vr], &[*i])?,
                    ParamValue::Boolean(b) => inst.set_boolean(&[*vr], &[*b as i32])?,
                    ParamValue::String(t) => inst.set_string(&[*vr], &[t.as_str()])?,
                }
            }
        }
        Ok(())
    }

    /// Initialisation mode for all, outputs propagated to inputs until nothing changes.
    fn initialize(&mut self, start: f64) -> Result<(), SystemError> {
        for u in &mut self.ex.units {
            if let Unit::Fmu(f) = u {
                f.backend().enter_initialization_mode()?;
            }
        }
        let plan = self.plan.clone();
        let order = &plan.order;
        let mut previous = vec![f64::NAN; self.ex.signals.len()];
        let mut previous_texts: Option<Vec<String>> = None;
        let mut converged = false;
        self.ex.time_replays_at(start);
        for _ in 0..50 {
            for &u in order {
                self.ex.set_inputs(u)?;
                self.ex.publish(u, start)?;
            }
            if previous
                .iter()
                .zip(&self.ex.signals)
                .all(|(a, b)| a.to_bits() == b.to_bits())
                && previous_texts.as_ref() == Some(&self.ex.texts)
            {
                converged = true;
                break;
            }
            previous.copy_from_slice(&self.ex.signals);
            previous_texts = Some(self.ex.texts.clone());
        }
        if !converged {
            log::warn!(
                "{}: initialisation did not reach a fixed point in 50 sweeps",
                plan.path.display()
            );
        }
        for &u in order {
            if let Unit::Fmu(f) = &mut self.ex.units[u] {
                f.gather(&self.ex.signals, &self.ex.texts);
                f.set_inputs()?;
                f.backend().exit_initialization_mode()?;
                f.get_outputs(&mut self.ex.signals, &mut self.ex.texts, &plan)?;
            }
        }
        Ok(())
    }

    /// The plan's consistency checks, after initialisation.
    fn check_consistency(&mut self) -> Result<(), SystemError> {
        let plan = self.plan.clone();
        for check in &plan.checks {
            let (signals, tolerance, why) = (&check.signals, &check.tolerance, &check.why);
            let values = self.read_values(signals)?;
            let (mut lo, mut hi) = (&values[0], &values[0]);
            for v in &values {
                if v.1 < lo.1 {
                    lo = v;
                }
                if v.1 > hi.1 {
                    hi = v;
                }
            }
            let scale = lo.1.abs().max(hi.1.abs());
            let rel = if scale > 0.0 {
                (hi.1 - lo.1) / scale
            } else {
                0.0
            };
            // NaN fails too.
            if rel.is_nan() || rel > *tolerance {
                return Err(SystemError::Stop(format!(
                    "{}: check failed after initialisation: {} = {} and {} = {} differ by {:.3} % (at most {} % allowed){}",
                    plan.path.display(),
                    lo.0,
                    lo.1,
                    hi.0,
                    hi.1,
                    rel * 100.0,
                    tolerance * 100.0,
                    why.as_ref().map(|w| format!(": {w}")).unwrap_or_default()
                )));
            }
        }
        Ok(())
    }

    /// The reported signals' values now.
    fn read_reported(&mut self) -> Result<Vec<(String, f64)>, SystemError> {
        let plan = self.plan.clone();
        self.read_values(&plan.report)
    }

    /// Current values of FMU variables, read directly from the units.
    fn read_values(
        &mut self,
        signals: &[(String, Endpoint)],
    ) -> Result<Vec<(String, f64)>, SystemError> {
        let mut out = Vec::with_capacity(signals.len());
        for (name, e) in signals {
            let x = match e {
                Endpoint::Fmu { unit, vr, ty, .. } => {
                    let Unit::Fmu(f) = &mut self.ex.units[*unit] else {
                        continue;
                    };
                    let i = f.backend();
                    match ty {
                        ScalarType::Real => {
                            let mut v = [0.0];
                            i.get_real(&[*vr], &mut v)?;
                            v[0]
                        }
                        ScalarType::Integer | ScalarType::Enumeration => {
                            let mut v = [0];
                            i.get_integer(&[*vr], &mut v)?;
                            v[0] as f64
                        }
                        ScalarType::Boolean => {
                            let mut v = [0];
                            i.get_boolean(&[*vr], &mut v)?;
                            v[0] as f64
                        }
                        ScalarType::String => continue,
                    }
                }
                Endpoint::Replay { .. } => continue,
            };
            out.push((name.clone(), x));
        }
        Ok(out)
    }

    /// Before a run: no rows, values or replay positions of an earlier one (a run that fails
    /// before its start keeps none of them).
    fn clear_last_run(&mut self) {
        self.recording.table_mut().clear();
        self.ex.signals.iter_mut().for_each(|s| *s = 0.0);
        for u in &mut self.ex.units {
            if let Unit::Replay(r) = u {
                r.cursor = Cursor::default();
            }
        }
    }

    /// After a run: every instance is ended, even after one fails to end; the first error
    /// is reported with the (complete) run's summary.
    fn terminate_all(&mut self, summary: RunSummary) -> Result<RunSummary, SystemError> {
        let mut first_error = None;
        for u in &mut self.ex.units {
            if let Unit::Fmu(f) = u {
                if let Err(e) = f.backend().terminate() {
                    first_error.get_or_insert(e);
                }
            }
        }
        match first_error {
            None => Ok(summary),
            Some(e) => Err(SystemError::AfterRun {
                summary: Box::new(summary),
                error: Box::new(e.into()),
            }),
        }
    }

    /// Run the experiment once (again: instances are reset and reused).
    pub fn run(&mut self) -> Result<RunSummary, SystemError> {
        let wall = Instant::now();
        let plan = self.plan.clone();
        let exp = &plan.file.experiment;
        let (start, h) = (exp.start, exp.step);
        let (fixed_stop, max_time) = match &plan.stop {
            Stop::Time(t) => (Some(*t), None),
            Stop::When { max_time, .. } => (None, Some(*max_time)),
        };
        self.clear_last_run();
        // Integer ticks: t_k = start + k·h exactly, no accumulated drift.
        let span = fixed_stop.unwrap_or(start + max_time.unwrap_or(0.0)) - start;
        let mut run = RunState {
            span: (start, start + span),
            stop: StopWhen::new(&plan),
            ended: None,
            last: Moment::Start,
            due: Vec::new(),
            next_due: 0,
            wake: Vec::new(),
        };
        self.instantiate_all(start, fixed_stop)?;
        self.initialize(start)?;
        self.check_consistency()?;
        self.notify(Moment::Start, start, &mut run)?;
        let full_steps = (span / h * (1.0 + 1e-12)).floor() as u64;
        let last = span - full_steps as f64 * h;
        let total_steps = full_steps + u64::from(last > h * 1e-9);
        let grid = plan.file.experiment.step_convention == crate::config::StepConvention::Grid;
        let order = &plan.order;
        let mut k = 0u64;
        let mut t_end = start;
        let mut ended = Ended::Horizon;
        while k < total_steps && run.ended.is_none() {
            let t = start + k as f64 * h;
            let step = match (grid, k == full_steps) {
                (false, false) => h,
                (false, true) => last,
                // FMPy's: the difference of the grid's times (the stop time last).
                (true, false) => (start + (k + 1) as f64 * h) - t,
                (true, true) => (start + span) - t,
            };
            self.ex.time_replays_at(t);
            let stepped = match self.recording.event_rows {
                true => self.step_recording_events(order, t, step, &mut run),
                false => self.algorithm.step(&mut self.ex, order, t, step),
            };
            if let Err(e) = stepped {
                let SystemError::EndedByFmu { instance, time } = e else {
                    return Err(e);
                };
                // As FMPy: the outputs at the FMU's last successful time, a last row, done.
                self.ex.publish_all(time)?;
                k += 1;
                t_end = time;
                self.notify(Moment::EndedByFmu, t_end, &mut run)?;
                ended = Ended::Fmu { instance };
                break;
            }
            k += 1;
            let last = k == total_steps && fixed_stop.is_some();
            t_end = if last {
                start + span
            } else {
                start + k as f64 * h
            };
            self.ex.time_replays_at(t_end);
            self.notify(Moment::Step { k, last }, t_end, &mut run)?;
        }
        if let (Ended::Horizon, Some(reason)) = (&ended, run.ended.take()) {
            ended = Ended::Observer(reason);
        }
        self.notify_finished(t_end, &mut run, &ended)?;
        let stopped_by = stopped_by(&ended, start + span, t_end);
        let reported = self.read_reported()?;
        let summary = RunSummary {
            steps: k,
            simulated_time: t_end - start,
            wall_time: wall.elapsed().as_secs_f64(),
            stopped_by,
            reported,
        };
        self.terminate_all(summary)
    }
}

/// What ended a run, as its summary says it.
fn stopped_by(ended: &Ended, stop_time: f64, t_end: f64) -> String {
    match ended {
        Ended::Horizon => format!("stop time {} s", stop_time),
        Ended::Observer(reason) => reason.clone(),
        Ended::Fmu { instance } => format!(
            "instance '{instance}' asked to end the simulation at t = {t_end} s (fmi2Discard with fmi2Terminated, or fmi3DoStep's terminateSimulation)"
        ),
    }
}

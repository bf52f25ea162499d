//! A paced run (`twinbench run --realtime [FACTOR]`): each macro step is held to an absolute
//! wall-clock deadline, `start + (t − t_start) / factor`, as a real-time target's frame
//! scheduler holds it (NASA Trick's frames, libcosim's real-time timer). Absolute deadlines
//! (`clock_nanosleep` with `TIMER_ABSTIME` on `CLOCK_MONOTONIC`) do not drift: a sleep that
//! wakes late does not push the later deadlines back, as a relative sleep would.
//!
//! [`Pacer`] is the schedule and its bookkeeping, over a [`Clock`] (the monotonic clock, or
//! a fake one in the tests): after each step it measures the step's lateness (the wall time
//! when the step finished minus its deadline; negative is slack), sleeps to the deadline
//! when there is slack, and applies the [`OverrunPolicy`] when there is none. [`PacedRun`]
//! is the pacer as a [`RunObserver`] of every step. [`prepare`] asks the system for what a
//! real-time run wants besides (`SCHED_FIFO`, `mlockall`, a CPU of its own) and says what it
//! got and what it did not.
//!
//! Nothing here is on the path of an unpaced run: the observer exists only when a run is
//! paced.

use crate::observe::{Moment, RunObserver, RunView};
use crate::SystemError;
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// A wall-clock instant or duration, ns of a monotonic clock.
pub type Nanos = i64;

/// A real-time factor or policy that cannot be used.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PacingError {
    #[error("the real-time factor {0} is not a finite number above 0 (1 = the wall clock keeps simulated time, 2 = twice as fast)")]
    Factor(f64),
    #[error("unknown overrun policy '{0}' (continue, skip or stop)")]
    Policy(String),
}

/// Simulated seconds per wall-clock second: 1 keeps real time, 2 runs twice as fast.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RealTimeFactor(f64);

impl RealTimeFactor {
    pub fn new(factor: f64) -> Result<RealTimeFactor, PacingError> {
        match factor.is_finite() && factor > 0.0 {
            true => Ok(RealTimeFactor(factor)),
            false => Err(PacingError::Factor(factor)),
        }
    }

    pub fn get(self) -> f64 {
        self.0
    }
}

/// What a step that finishes after its deadline does to the schedule.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OverrunPolicy {
    /// Go on; the later deadlines stay on the original schedule, so the run catches up
    /// (the next steps run without sleeping until one finishes early again).
    #[default]
    Continue,
    /// Re-anchor the schedule at the late step: the next deadline is one macro step after
    /// now. The frames the schedule slipped are lost (counted), as a frame scheduler skips.
    Skip,
    /// End the run at the first overrun (its rows kept, `stopped_by` says why).
    Stop,
}

impl OverrunPolicy {
    pub fn from_name(name: &str) -> Result<OverrunPolicy, PacingError> {
        match name {
            "continue" => Ok(OverrunPolicy::Continue),
            "skip" => Ok(OverrunPolicy::Skip),
            "stop" => Ok(OverrunPolicy::Stop),
            other => Err(PacingError::Policy(other.to_string())),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            OverrunPolicy::Continue => "continue",
            OverrunPolicy::Skip => "skip",
            OverrunPolicy::Stop => "stop",
        }
    }
}

/// How a sleep ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wake {
    /// The deadline was reached.
    Reached,
    /// A signal woke the sleeper first (`EINTR`).
    Interrupted,
}

/// The pacer's clock: now, and a sleep to an absolute instant.
pub trait Clock: Send {
    fn now(&mut self) -> Nanos;
    /// Sleep until `deadline` (this clock's ns), or until a signal arrives.
    fn sleep_until(&mut self, deadline: Nanos) -> Wake;
}

/// `CLOCK_MONOTONIC`: not set back or forward with the time of day (NTP, the user), the
/// clock `clock_nanosleep` sleeps on. Reading it is a vDSO call, no system call.
#[derive(Clone, Copy, Debug, Default)]
pub struct Monotonic;

impl Clock for Monotonic {
    fn now(&mut self) -> Nanos {
        let mut ts = libc::timespec {
            tv_sec: 0,
            tv_nsec: 0,
        };
        // SAFETY: `ts` is a valid timespec to write; CLOCK_MONOTONIC always exists on Linux.
        unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
        // time_t and c_long are i64 on the 64-bit Linux targets twinbench builds for.
        Nanos::from(ts.tv_sec) * 1_000_000_000 + Nanos::from(ts.tv_nsec)
    }

    fn sleep_until(&mut self, deadline: Nanos) -> Wake {
        let ts = libc::timespec {
            tv_sec: deadline.div_euclid(1_000_000_000) as libc::time_t,
            tv_nsec: deadline.rem_euclid(1_000_000_000) as libc::c_long,
        };
        // SAFETY: a valid timespec; no remaining time is asked for (absolute sleep: the
        // same deadline is simply asked again).
        let r = unsafe {
            libc::clock_nanosleep(
                libc::CLOCK_MONOTONIC,
                libc::TIMER_ABSTIME,
                &ts,
                std::ptr::null_mut(),
            )
        };
        // clock_nanosleep returns the error number itself (not -1 and errno). EINVAL
        // cannot come from a normalised timespec; anything but EINTR ends the sleep.
        match r {
            libc::EINTR => Wake::Interrupted,
            _ => Wake::Reached,
        }
    }
}

/// The schedule of a paced run and what it measured.
pub struct Pacer<C: Clock> {
    clock: C,
    factor: f64,
    policy: OverrunPolicy,
    /// Set by Ctrl-C: a sleep it interrupts ends at once (the run's own interrupt observer
    /// then ends the run at the next step) instead of being resumed.
    interrupt: Option<Arc<AtomicBool>>,
    /// The schedule: deadline(t) = anchor_wall + (t − anchor_time) / factor.
    anchor_wall: Nanos,
    anchor_time: f64,
    /// The start (wall, simulated) and the last step's end (after its sleep) and time.
    start_wall: Nanos,
    start_time: f64,
    end_wall: Nanos,
    last_time: f64,
    lateness: Histogram,
    /// Each step's execution time: from the previous step's end (its wake-up) to its own.
    step_time: Histogram,
    /// How long after its deadline each sleep returned (the system's timer latency).
    wake_up: Histogram,
    overruns: u64,
    frames_lost: u64,
    first_overrun: Option<(f64, Nanos)>,
    stopped: bool,
}

/// The longest single sleep: a longer wait (a slowed-down run, factor < 1) is cut into
/// sleeps of this length, so that Ctrl-C ends it promptly even when its signal is delivered
/// to another thread than the sleeping one (no EINTR here then).
const LONGEST_SLEEP: Nanos = 50_000_000;

impl<C: Clock> Pacer<C> {
    pub fn new(clock: C, factor: RealTimeFactor, policy: OverrunPolicy) -> Pacer<C> {
        Pacer {
            clock,
            factor: factor.get(),
            policy,
            interrupt: None,
            anchor_wall: 0,
            anchor_time: 0.0,
            start_wall: 0,
            start_time: 0.0,
            end_wall: 0,
            last_time: 0.0,
            lateness: Histogram::default(),
            step_time: Histogram::default(),
            wake_up: Histogram::default(),
            overruns: 0,
            frames_lost: 0,
            first_overrun: None,
            stopped: false,
        }
    }

    /// The flag Ctrl-C sets ([`Pacer::interrupt`]).
    pub fn with_interrupt(mut self, flag: Arc<AtomicBool>) -> Pacer<C> {
        self.interrupt = Some(flag);
        self
    }

    /// The run starts at simulated time `t`, now: the schedule's anchor (after
    /// initialisation, so that instantiating the FMUs costs no step its slack).
    pub fn start(&mut self, t: f64) {
        let now = self.clock.now();
        // A run again (a Simulation runs more than once): a fresh measure.
        self.lateness = Histogram::default();
        self.step_time = Histogram::default();
        self.wake_up = Histogram::default();
        (self.overruns, self.frames_lost) = (0, 0);
        (self.first_overrun, self.stopped) = (None, false);
        (self.anchor_wall, self.anchor_time) = (now, t);
        (self.start_wall, self.start_time) = (now, t);
        (self.end_wall, self.last_time) = (now, t);
    }

    /// A step reached simulated time `t`: its lateness measured, then a sleep to its
    /// deadline, or the overrun policy. `Break(reason)` ends the run (policy stop).
    pub fn step_done(&mut self, t: f64) -> ControlFlow<String> {
        let now = self.clock.now();
        let deadline = self.deadline(t);
        let late = now - deadline;
        self.lateness.add(late);
        self.step_time.add(now - self.end_wall);
        let period = (t - self.last_time) / self.factor;
        self.last_time = t;
        if late <= 0 {
            self.sleep_until(deadline);
            let woke = self.clock.now();
            self.wake_up.add(woke - deadline);
            self.end_wall = woke.max(deadline);
            return ControlFlow::Continue(());
        }
        self.end_wall = now;
        self.overruns += 1;
        self.first_overrun.get_or_insert((t, late));
        match self.policy {
            OverrunPolicy::Continue => ControlFlow::Continue(()),
            OverrunPolicy::Skip => {
                // The schedule slipped by `late`: the frames it slipped over are lost.
                let period_ns = (period * 1e9).max(1.0);
                self.frames_lost += (late as f64 / period_ns).ceil() as u64;
                self.anchor_wall = now;
                self.anchor_time = t;
                ControlFlow::Continue(())
            }
            OverrunPolicy::Stop => {
                self.stopped = true;
                ControlFlow::Break(format!(
                    "overrun at t = {} s: the step finished {} after its deadline (overrun policy stop)",
                    tb_files::number(t),
                    duration_words(late)
                ))
            }
        }
    }

    /// The deadline of simulated time `t`, ns.
    fn deadline(&self, t: f64) -> Nanos {
        self.anchor_wall + ((t - self.anchor_time) / self.factor * 1e9).round() as Nanos
    }

    /// Sleep to `deadline`: resumed after a signal, unless Ctrl-C's flag is set.
    fn sleep_until(&mut self, deadline: Nanos) {
        loop {
            let now = self.clock.now();
            if now >= deadline || self.interrupted() {
                return;
            }
            let until = deadline.min(now.saturating_add(LONGEST_SLEEP));
            if self.clock.sleep_until(until) == Wake::Reached && until == deadline {
                return;
            }
        }
    }

    fn interrupted(&self) -> bool {
        (self.interrupt.as_ref()).is_some_and(|f| f.load(Ordering::Relaxed))
    }

    pub fn lateness(&self) -> &Histogram {
        &self.lateness
    }

    /// What the run measured, in seconds.
    pub fn report(&self) -> PacingReport {
        let l = &self.lateness;
        let simulated = self.last_time - self.start_time;
        PacingReport {
            factor: self.factor,
            overrun_policy: self.policy.name(),
            steps: l.count(),
            overruns: self.overruns,
            frames_lost: self.frames_lost,
            stopped_at_overrun: self.stopped,
            first_overrun: self.first_overrun.map(|(time, late)| FirstOverrun {
                time,
                lateness: late as f64 / 1e9,
            }),
            lateness: Quantiles::of(l),
            step_time: Quantiles::of(&self.step_time),
            wake_up_latency: Quantiles::of(&self.wake_up),
            histogram: LatenessHistogram::from(l.coarse()),
            simulated_time: simulated,
            scheduled_wall_time: simulated / self.factor,
            wall_time: (self.end_wall - self.start_wall) as f64 / 1e9,
        }
    }
}

/// What a paced run measured; times in seconds (lateness: the wall time a step finished
/// minus its deadline, negative when it had slack).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct PacingReport {
    pub factor: f64,
    pub overrun_policy: &'static str,
    /// Steps paced (each has a deadline).
    pub steps: u64,
    /// Steps that finished after their deadline.
    pub overruns: u64,
    /// Policy skip: the frames the re-anchored schedule slipped over.
    pub frames_lost: u64,
    /// Policy stop ended the run.
    pub stopped_at_overrun: bool,
    pub first_overrun: Option<FirstOverrun>,
    pub lateness: Quantiles,
    /// Each step's execution time (with the other observers' work, the recording's).
    pub step_time: Quantiles,
    /// How long after their deadlines the sleeps returned: the system's timer and
    /// scheduling latency, which a step's slack must cover too.
    pub wake_up_latency: Quantiles,
    pub histogram: LatenessHistogram,
    /// Simulated time paced, s, and the wall time it was to take (÷ factor) and took: from
    /// the start (after initialisation) to the last step's end.
    pub simulated_time: f64,
    pub scheduled_wall_time: f64,
    pub wall_time: f64,
}

#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FirstOverrun {
    /// Simulated time the late step reached, s.
    pub time: f64,
    pub lateness: f64,
}

/// A distribution's statistics, s; quantiles within 1.6 % (never below the true value).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Quantiles {
    pub max: Option<f64>,
    pub p99_99: Option<f64>,
    pub p99_9: Option<f64>,
    pub p99: Option<f64>,
    pub median: Option<f64>,
    pub min: Option<f64>,
}

impl Quantiles {
    fn of(h: &Histogram) -> Quantiles {
        // ns ÷ 1e9, not × 1e-9: the division of a whole number is rounded once (0.00094208,
        // not 0.0009420800000000001).
        let s = |ns: Option<Nanos>| ns.map(|n| n as f64 / 1e9);
        Quantiles {
            max: s(h.max()),
            p99_99: s(h.quantile(0.9999)),
            p99_9: s(h.quantile(0.999)),
            p99: s(h.quantile(0.99)),
            median: s(h.quantile(0.5)),
            min: s(h.min()),
        }
    }
}

impl PacingReport {
    /// The report as lines of the run's text summary (without a trailing newline).
    pub fn text(&self) -> String {
        let w = |x: Option<f64>| match x {
            Some(x) => duration_words((x * 1e9).round() as Nanos),
            None => "-".to_string(),
        };
        let l = &self.lateness;
        let mut s = format!(
            "paced           factor {}, overrun policy {}: wall {:.3} s for {:.3} s scheduled ({:+.3} %)\n",
            tb_files::number(self.factor),
            self.overrun_policy,
            self.wall_time,
            self.scheduled_wall_time,
            (self.wall_time / self.scheduled_wall_time.max(1e-12) - 1.0) * 100.0
        );
        s += &format!(
            "lateness        median {}, p99 {}, p99.9 {}, max {} ({} steps, {} overruns",
            w(l.median),
            w(l.p99),
            w(l.p99_9),
            w(l.max),
            self.steps,
            self.overruns
        );
        if self.frames_lost > 0 {
            s += &format!(", {} frames lost", self.frames_lost);
        }
        s += ")\n";
        let bins: Vec<String> = (self.histogram.bins().iter())
            .map(|(name, n)| format!("{name} {n}"))
            .collect();
        s += &format!("lateness bins   {}\n", bins.join(", "));
        let (st, wu) = (&self.step_time, &self.wake_up_latency);
        s += &format!(
            "step time       median {}, p99.9 {}, p99.99 {}, max {}; woken after the deadline by median {}, p99.9 {}, max {}",
            w(st.median),
            w(st.p99_9),
            w(st.p99_99),
            w(st.max),
            w(wu.median),
            w(wu.p99_9),
            w(wu.max)
        );
        s
    }
}

/// A signed duration in words: `-987.6 µs`, `12 ns`, `1.25 ms`, `2.000 s`.
pub fn duration_words(ns: Nanos) -> String {
    let m = ns.unsigned_abs() as f64;
    let sign = if ns < 0 { "-" } else { "" };
    match m {
        m if m < 1e3 => format!("{sign}{m} ns"),
        m if m < 1e6 => format!("{sign}{:.1} µs", m * 1e-3),
        m if m < 1e9 => format!("{sign}{:.2} ms", m * 1e-6),
        m => format!("{sign}{:.3} s", m * 1e-9),
    }
}

/// The pacer as an observer of every step of a run. Its report is published into the
/// handle [`PacedRun::new`] returns when the observer is dropped (after the run, when the
/// caller takes its observers off), so the run's loop takes no lock for it.
pub struct PacedRun {
    pacer: Pacer<Monotonic>,
    report: Arc<Mutex<Option<PacingReport>>>,
}

impl PacedRun {
    pub fn new(pacer: Pacer<Monotonic>) -> (PacedRun, Arc<Mutex<Option<PacingReport>>>) {
        let report = Arc::new(Mutex::new(None));
        let run = PacedRun {
            pacer,
            report: report.clone(),
        };
        (run, report)
    }
}

impl RunObserver for PacedRun {
    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        Ok(match now.moment() {
            Moment::Start => {
                self.pacer.start(now.time());
                ControlFlow::Continue(())
            }
            Moment::Step { .. } => self.pacer.step_done(now.time()),
            // An event row is inside a step; an FMU's end has no deadline.
            Moment::Event | Moment::EndedByFmu => ControlFlow::Continue(()),
        })
    }
}

impl Drop for PacedRun {
    fn drop(&mut self) {
        let report = self.pacer.report();
        *self.report.lock().unwrap_or_else(|p| p.into_inner()) = Some(report);
    }
}

mod histogram;
mod system;

pub use histogram::{Histogram, LatenessHistogram};
pub use system::{prepare, Attempt, CpuRequest, Prepared, RealtimeRequest};

#[cfg(test)]
mod tests;

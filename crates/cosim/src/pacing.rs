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

/// The log-linear histogram's resolution: 2^SUB_BITS buckets per octave of lateness, so a
/// quantile read from it is within 1/64 (1.6 %) of the true one (values under 64 ns exact).
const SUB_BITS: u32 = 6;
const SUB: u64 = 1 << SUB_BITS;
/// Octaves up to 2^41 ns (about 37 min): a later step is counted in the last bucket (the
/// maximum is kept exactly besides).
const MAX_EXPONENT: u32 = 40;
const BUCKETS: usize = (SUB * (MAX_EXPONENT - SUB_BITS + 2) as u64) as usize;

/// The bucket of a magnitude, ns.
fn bucket(m: u64) -> usize {
    let m = m.min((1u64 << (MAX_EXPONENT + 1)) - 1);
    if m < SUB {
        return m as usize;
    }
    let e = 63 - m.leading_zeros();
    (SUB * u64::from(e - SUB_BITS + 1) + ((m >> (e - SUB_BITS)) - SUB)) as usize
}

/// The smallest and largest magnitude of a bucket, ns.
fn bucket_range(i: usize) -> (u64, u64) {
    let i = i as u64;
    if i < SUB {
        return (i, i);
    }
    let e = i / SUB + u64::from(SUB_BITS) - 1;
    let low = (i % SUB + SUB) << (e - u64::from(SUB_BITS));
    (low, low + (1 << (e - u64::from(SUB_BITS))) - 1)
}

/// The summary's small histogram of lateness: steps with slack (lateness ≤ 0), then late
/// by up to 10 µs, 100 µs, 1 ms, and more.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct LatenessHistogram {
    pub slack: u64,
    pub late_0_to_10us: u64,
    pub late_10_to_100us: u64,
    pub late_100us_to_1ms: u64,
    pub late_over_1ms: u64,
}

impl From<[u64; 5]> for LatenessHistogram {
    fn from(c: [u64; 5]) -> Self {
        LatenessHistogram {
            slack: c[0],
            late_0_to_10us: c[1],
            late_10_to_100us: c[2],
            late_100us_to_1ms: c[3],
            late_over_1ms: c[4],
        }
    }
}

impl LatenessHistogram {
    /// (label, count) in order, for text.
    pub fn bins(&self) -> [(&'static str, u64); 5] {
        [
            ("slack", self.slack),
            ("0-10 µs late", self.late_0_to_10us),
            ("10-100 µs", self.late_10_to_100us),
            ("0.1-1 ms", self.late_100us_to_1ms),
            ("> 1 ms", self.late_over_1ms),
        ]
    }
}

/// A distribution of signed durations (the steps' lateness, their execution time, the
/// sleeps' wake-up latency), kept without allocating per step: counts in preallocated
/// log-linear buckets (for the quantiles), the coarse lateness bins, the exact extremes.
pub struct Histogram {
    /// Values ≤ 0 (a step on time: its slack) by magnitude; values > 0 (late) by value.
    slack: Box<[u64]>,
    late: Box<[u64]>,
    coarse: [u64; 5],
    count: u64,
    max: Nanos,
    min: Nanos,
}

impl Default for Histogram {
    fn default() -> Self {
        Histogram {
            slack: vec![0; BUCKETS].into_boxed_slice(),
            late: vec![0; BUCKETS].into_boxed_slice(),
            coarse: [0; 5],
            count: 0,
            max: Nanos::MIN,
            min: Nanos::MAX,
        }
    }
}

impl Histogram {
    #[inline]
    pub fn add(&mut self, lateness: Nanos) {
        self.count += 1;
        self.max = self.max.max(lateness);
        self.min = self.min.min(lateness);
        let m = lateness.unsigned_abs();
        match lateness <= 0 {
            true => self.slack[bucket(m)] += 1,
            false => self.late[bucket(m)] += 1,
        }
        let bin = match lateness {
            ..=0 => 0,
            1..=10_000 => 1,
            10_001..=100_000 => 2,
            100_001..=1_000_000 => 3,
            _ => 4,
        };
        self.coarse[bin] += 1;
    }

    pub fn count(&self) -> u64 {
        self.count
    }

    /// The value at quantile `q` (0 to 1), ns: the largest value of its bucket, so never
    /// below the true quantile and at most 1.6 % later (bounded by the exact
    /// maximum). None without steps.
    pub fn quantile(&self, q: f64) -> Option<Nanos> {
        if self.count == 0 {
            return None;
        }
        // The rank (1-based) of the quantile's value in ascending order.
        let rank = ((q.clamp(0.0, 1.0) * self.count as f64).ceil() as u64).max(1);
        let mut seen = 0;
        // Ascending: the largest slack first, then the smallest lateness.
        let ascending = (self.slack.iter().enumerate().rev())
            .map(|(i, &n)| (n, -(bucket_range(i).0 as Nanos)))
            .chain((self.late.iter().enumerate()).map(|(i, &n)| (n, bucket_range(i).1 as Nanos)));
        for (n, latest) in ascending {
            seen += n;
            if seen >= rank {
                return Some(latest.min(self.max));
            }
        }
        Some(self.max)
    }

    pub fn max(&self) -> Option<Nanos> {
        (self.count > 0).then_some(self.max)
    }

    pub fn min(&self) -> Option<Nanos> {
        (self.count > 0).then_some(self.min)
    }

    /// The coarse bins' counts, in the order of [`LatenessHistogram`]'s fields.
    pub fn coarse(&self) -> [u64; 5] {
        self.coarse
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

/// What a paced run asks of the system besides its schedule, for the thread that runs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RealtimeRequest {
    /// `SCHED_FIFO` at this priority (1 to 99); None: the normal scheduler, not asked.
    pub fifo_priority: Option<i32>,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`: no page fault or swap-in during the run.
    pub lock_memory: bool,
    /// A CPU of its own.
    pub cpu: CpuRequest,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CpuRequest {
    /// Not asked: the scheduler places the run.
    Any,
    /// The last CPU this process may use (the one least likely to take the system's
    /// interrupts and housekeeping, which go to CPU 0 first).
    Last,
    Cpu(usize),
}

/// One thing asked of the system, and whether it was obtained.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Attempt {
    /// What was asked, e.g. "SCHED_FIFO priority 80".
    pub asked: String,
    pub obtained: bool,
    /// Why not (the system's error and what it usually means).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
    /// What the refusal means for the run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub consequence: Option<&'static str>,
}

impl Attempt {
    fn obtained(asked: String) -> Attempt {
        Attempt {
            asked,
            obtained: true,
            refused: None,
            consequence: None,
        }
    }

    fn refused(asked: String, why: String, consequence: &'static str) -> Attempt {
        Attempt {
            asked,
            obtained: false,
            refused: Some(why),
            consequence: Some(consequence),
        }
    }

    /// One line for stderr: what was asked and got, or what failed, why and what it means.
    pub fn line(&self) -> String {
        match (&self.refused, self.consequence) {
            (Some(why), Some(means)) => {
                format!("realtime: {} refused: {why}; {means}", self.asked)
            }
            _ => format!("realtime: {} obtained", self.asked),
        }
    }
}

/// What [`prepare`] changed, to be undone by [`Prepared::restore`] after the run (the
/// results are then written at normal priority, on any CPU, without locked memory).
pub struct Prepared {
    pub attempts: Vec<Attempt>,
    policy: Option<(libc::c_int, libc::sched_param)>,
    affinity: Option<libc::cpu_set_t>,
    locked: bool,
    timer_slack: Option<libc::c_ulong>,
}

const FIFO_MEANS: &str =
    "the run is paced at normal priority: deadlines may be missed by scheduler latency";
const LOCK_MEANS: &str =
    "pages may be faulted in during the run: deadlines may be missed by paging latency";
const CPU_MEANS: &str =
    "the run shares its CPUs and may migrate: deadlines may be missed by scheduler latency";

/// The last error's text with its number, e.g. "Operation not permitted (os error 1)".
fn os_error() -> (std::io::Error, Option<i32>) {
    let e = std::io::Error::last_os_error();
    let code = e.raw_os_error();
    (e, code)
}

/// The calling thread's CPUs.
fn affinity() -> Option<libc::cpu_set_t> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; the size passed is its own.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        let r = libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
        (r == 0).then_some(set)
    }
}

fn cpus_of(set: &libc::cpu_set_t) -> Vec<usize> {
    // SAFETY: CPU_ISSET reads the set within CPU_SETSIZE.
    (0..libc::CPU_SETSIZE as usize)
        .filter(|&c| unsafe { libc::CPU_ISSET(c, set) })
        .collect()
}

/// A list of CPUs in words: `0-3`, `0,2`.
fn cpu_list(cpus: &[usize]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut k = 0;
    while k < cpus.len() {
        let mut j = k;
        while j + 1 < cpus.len() && cpus[j + 1] == cpus[j] + 1 {
            j += 1;
        }
        parts.push(match j > k {
            true => format!("{}-{}", cpus[k], cpus[j]),
            false => cpus[k].to_string(),
        });
        k = j + 1;
    }
    parts.join(",")
}

/// The capability to lock memory beyond RLIMIT_MEMLOCK (linux/capability.h; the libc
/// crate does not define it).
const CAP_IPC_LOCK: u32 = 14;

/// Whether this process may lock more memory than RLIMIT_MEMLOCK (CAP_IPC_LOCK in its
/// effective set), and that limit in bytes (None: unlimited).
fn memlock_allowance() -> (bool, Option<u64>) {
    let cap_ipc_lock = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            let hex = s.lines().find_map(|l| l.strip_prefix("CapEff:"))?.trim();
            u64::from_str_radix(hex, 16).ok()
        })
        .is_some_and(|caps| caps & (1 << CAP_IPC_LOCK) != 0);
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: a valid rlimit to write.
    let r = unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut lim) };
    let limit = match r == 0 && lim.rlim_cur != libc::RLIM_INFINITY {
        true => Some(lim.rlim_cur),
        false => None,
    };
    (cap_ipc_lock, limit)
}

/// Ask the system for what `request` names, for the calling thread (the scheduling policy
/// and the CPU are per thread on Linux; the memory lock is the process's). Each is tried;
/// what is refused is said in its [`Attempt`], never dropped in silence. Processes started
/// from this thread afterwards (isolated FMU workers) inherit its policy and CPU, not the
/// memory lock.
pub fn prepare(request: &RealtimeRequest) -> Prepared {
    let mut prepared = Prepared {
        attempts: Vec::new(),
        policy: None,
        affinity: None,
        locked: false,
        timer_slack: None,
    };
    // Always: a normal thread's sleeps may end up to its timer slack (50 µs by default)
    // late, so that the kernel can batch wake-ups; a paced run wants its deadline. (A
    // SCHED_FIFO thread has no slack; this matters when that is refused or not asked.)
    {
        let asked = "timer slack 1 ns (prctl PR_SET_TIMERSLACK)".to_string();
        // SAFETY: prctl with integer arguments only.
        let old = unsafe { libc::prctl(libc::PR_GET_TIMERSLACK, 0, 0, 0, 0) };
        let r = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
        match r {
            0 => {
                prepared.timer_slack = (old > 0).then_some(old as libc::c_ulong);
                prepared.attempts.push(Attempt::obtained(asked));
            }
            _ => {
                let (e, _) = os_error();
                prepared.attempts.push(Attempt::refused(
                    asked,
                    format!("prctl: {e}"),
                    "sleeps may end up to 50 µs late: deadlines may be missed by timer slack",
                ));
            }
        }
    }
    if request.lock_memory {
        let asked = "mlockall(MCL_CURRENT|MCL_FUTURE)".to_string();
        let (capable, limit) = memlock_allowance();
        match (capable, limit) {
            // Under a limit, locking future pages too would turn the run's later
            // allocations (the recording growing) into failures once it is reached.
            (false, Some(limit)) => prepared.attempts.push(Attempt::refused(
                asked,
                format!(
                    "not attempted: RLIMIT_MEMLOCK is {} KiB (`ulimit -l`) and the process lacks CAP_IPC_LOCK; locking its future pages under that limit would make the run's later allocations fail (raise it: `ulimit -l unlimited`)",
                    limit / 1024
                ),
                LOCK_MEANS,
            )),
            _ => {
                // SAFETY: mlockall has no memory-safety preconditions.
                let r = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
                match r {
                    0 => {
                        prepared.locked = true;
                        prepared.attempts.push(Attempt::obtained(asked));
                    }
                    _ => {
                        let (e, _) = os_error();
                        prepared.attempts.push(Attempt::refused(
                            asked,
                            format!("mlockall: {e}"),
                            LOCK_MEANS,
                        ))
                    }
                }
            }
        }
    }
    if let Some(priority) = request.fifo_priority {
        let asked = format!("SCHED_FIFO priority {priority}");
        // SAFETY: querying this thread's policy and parameters into a valid struct.
        let old = unsafe {
            let mut p: libc::sched_param = std::mem::zeroed();
            let policy = libc::sched_getscheduler(0);
            (policy >= 0 && libc::sched_getparam(0, &mut p) == 0).then_some((policy, p))
        };
        let param = libc::sched_param {
            sched_priority: priority,
        };
        // SAFETY: a valid sched_param; 0 is the calling thread.
        let r = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
        match r {
            0 => {
                prepared.policy = old;
                prepared.attempts.push(Attempt::obtained(asked));
            }
            _ => {
                let (e, code) = os_error();
                let hint = match code {
                    Some(libc::EPERM) => {
                        " (needs CAP_SYS_NICE, or an RLIMIT_RTPRIO of at least the priority: `ulimit -r`; in a container, a real-time CPU budget too)"
                    }
                    Some(libc::EINVAL) => " (SCHED_FIFO priorities are 1 to 99)",
                    _ => "",
                };
                prepared.attempts.push(Attempt::refused(
                    asked,
                    format!("sched_setscheduler: {e}{hint}"),
                    FIFO_MEANS,
                ))
            }
        }
    }
    let allowed = affinity();
    let cpu = match (request.cpu, &allowed) {
        (CpuRequest::Any, _) => None,
        (CpuRequest::Cpu(c), _) => Some(Ok(c)),
        (CpuRequest::Last, Some(set)) => Some(cpus_of(set).last().copied().ok_or(())),
        (CpuRequest::Last, None) => Some(Err(())),
    };
    match cpu {
        None => {}
        Some(Err(())) => {
            let (e, _) = os_error();
            prepared.attempts.push(Attempt::refused(
                "a CPU of its own (the last one)".to_string(),
                format!("sched_getaffinity: {e}"),
                CPU_MEANS,
            ));
        }
        Some(Ok(c)) => {
            let asked = format!("CPU {c} alone (sched_setaffinity)");
            let set_to = (c < libc::CPU_SETSIZE as usize).then(|| {
                // SAFETY: a zeroed set is empty; `c` is within CPU_SETSIZE.
                unsafe {
                    let mut set: libc::cpu_set_t = std::mem::zeroed();
                    libc::CPU_SET(c, &mut set);
                    libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
                }
            });
            match set_to {
                Some(0) => {
                    prepared.affinity = allowed;
                    prepared.attempts.push(Attempt::obtained(asked));
                }
                _ => {
                    let (e, code) = os_error();
                    let may = allowed.as_ref().map(|s| cpu_list(&cpus_of(s)));
                    let why = match (set_to, code, may) {
                        (None, _, _) => format!("CPU {c} is beyond the system's CPU set size"),
                        (_, Some(libc::EINVAL), Some(may)) => format!(
                            "sched_setaffinity: {e} (CPU {c} is not one this process may use: {may})"
                        ),
                        _ => format!("sched_setaffinity: {e}"),
                    };
                    prepared
                        .attempts
                        .push(Attempt::refused(asked, why, CPU_MEANS));
                }
            }
        }
    }
    prepared
}

impl Prepared {
    /// Undo what was obtained: the thread's former policy and CPUs, the memory unlocked.
    pub fn restore(self) {
        // SAFETY: setting back values read from the system for this thread; munlockall
        // has no preconditions.
        unsafe {
            if let Some((policy, param)) = self.policy {
                libc::sched_setscheduler(0, policy, &param);
            }
            if let Some(set) = self.affinity {
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
            }
            if self.locked {
                libc::munlockall();
            }
            if let Some(slack) = self.timer_slack {
                libc::prctl(libc::PR_SET_TIMERSLACK, slack, 0, 0, 0);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A clock that advances only when told: a step "takes" what the test says, a sleep
    /// jumps to its deadline (or is interrupted when the test asks).
    #[derive(Default)]
    struct FakeClock {
        now: Nanos,
        sleeps: Vec<Nanos>,
        /// The next sleeps return Interrupted without advancing (a signal).
        interrupts: u32,
    }

    impl Clock for &mut FakeClock {
        fn now(&mut self) -> Nanos {
            self.now
        }
        fn sleep_until(&mut self, deadline: Nanos) -> Wake {
            self.sleeps.push(deadline);
            if self.interrupts > 0 {
                self.interrupts -= 1;
                return Wake::Interrupted;
            }
            self.now = self.now.max(deadline);
            Wake::Reached
        }
    }

    const MS: Nanos = 1_000_000;

    fn factor(f: f64) -> RealTimeFactor {
        RealTimeFactor::new(f).unwrap()
    }

    #[test]
    fn a_factor_is_finite_and_above_zero() {
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, -0.0] {
            assert!(RealTimeFactor::new(bad).is_err(), "{bad}");
        }
        assert_eq!(RealTimeFactor::new(2.0).unwrap().get(), 2.0);
        assert!(OverrunPolicy::from_name("skip").is_ok());
        assert!(OverrunPolicy::from_name("drop").is_err());
    }

    /// Steps that take 0.2 ms of a 1 ms period sleep to absolute deadlines: the schedule
    /// does not drift with the steps' cost.
    #[test]
    fn steps_with_slack_sleep_to_absolute_deadlines() {
        let mut clock = FakeClock {
            now: 5 * MS,
            ..FakeClock::default()
        };
        let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Continue);
        p.start(10.0);
        for k in 1..=3 {
            p.clock.now += MS / 5;
            assert_eq!(
                p.step_done(10.0 + k as f64 * 1e-3),
                ControlFlow::Continue(())
            );
        }
        let r = p.report();
        assert_eq!(r.steps, 3);
        assert_eq!(r.overruns, 0);
        assert_eq!(r.histogram.slack, 3);
        assert_eq!(r.lateness.max, Some(-0.8e-3));
        assert!((r.wall_time - 3e-3).abs() < 1e-12, "{}", r.wall_time);
        assert_eq!(r.step_time.max, Some(0.2e-3));
        assert_eq!(r.wake_up_latency.max, Some(0.0));
        drop(p);
        assert_eq!(clock.sleeps, vec![6 * MS, 7 * MS, 8 * MS]);
    }

    /// Factor 2: a 1 ms step has 0.5 ms of wall time.
    #[test]
    fn the_factor_scales_the_deadlines() {
        let mut clock = FakeClock::default();
        let mut p = Pacer::new(&mut clock, factor(2.0), OverrunPolicy::Continue);
        p.start(0.0);
        let _ = p.step_done(1e-3);
        let _ = p.step_done(2e-3);
        assert!((p.report().scheduled_wall_time - 1e-3).abs() < 1e-15);
        drop(p);
        assert_eq!(clock.sleeps, vec![MS / 2, MS]);
    }

    /// Continue: a late step does not move the later deadlines; the next steps run at once
    /// until one is early again.
    #[test]
    fn continue_catches_up_on_the_original_schedule() {
        let mut clock = FakeClock::default();
        let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Continue);
        p.start(0.0);
        p.clock.now += 2_500_000; // the first step takes 2.5 ms
        assert_eq!(p.step_done(1e-3), ControlFlow::Continue(()));
        p.clock.now += 100_000;
        let _ = p.step_done(2e-3); // finished at 2.6 ms: 0.6 ms late, no sleep
        p.clock.now += 100_000;
        let _ = p.step_done(3e-3); // 2.7 ms: 0.3 ms of slack, sleeps to 3 ms
        let r = p.report();
        assert_eq!((r.overruns, r.frames_lost), (2, 0));
        assert_eq!(r.first_overrun.as_ref().unwrap().time, 1e-3);
        assert!((r.first_overrun.unwrap().lateness - 1.5e-3).abs() < 1e-12);
        assert_eq!(r.histogram.late_over_1ms, 1);
        assert_eq!(r.histogram.late_100us_to_1ms, 1);
        assert_eq!(r.histogram.slack, 1);
        drop(p);
        assert_eq!(clock.sleeps, vec![3 * MS]);
    }

    /// Skip: the schedule restarts from the late step; the frames it slipped are counted.
    #[test]
    fn skip_re_anchors_the_schedule_one_step_after_now() {
        let mut clock = FakeClock::default();
        let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Skip);
        p.start(0.0);
        p.clock.now += 2_500_000; // 1.5 ms late: two frames lost
        let _ = p.step_done(1e-3);
        p.clock.now += 100_000;
        let _ = p.step_done(2e-3); // deadline 2.5 + 1 = 3.5 ms
        let r = p.report();
        assert_eq!((r.overruns, r.frames_lost), (1, 2));
        drop(p);
        assert_eq!(clock.sleeps, vec![3_500_000]);
    }

    /// Stop: the first late step ends the run with its reason.
    #[test]
    fn stop_ends_at_the_first_overrun() {
        let mut clock = FakeClock::default();
        let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Stop);
        p.start(0.0);
        p.clock.now += MS / 2;
        assert_eq!(p.step_done(1e-3), ControlFlow::Continue(()));
        p.clock.now += 1_250_000;
        let ControlFlow::Break(why) = p.step_done(2e-3) else {
            panic!("no stop at an overrun")
        };
        assert_eq!(
            why,
            "overrun at t = 0.002 s: the step finished 250.0 µs after its deadline (overrun policy stop)"
        );
        assert!(p.report().stopped_at_overrun);
    }

    /// A signal resumes the sleep to the same deadline; with Ctrl-C's flag set it ends it.
    #[test]
    fn a_sleep_a_signal_interrupts_resumes_unless_ctrl_c() {
        let mut clock = FakeClock {
            interrupts: 2,
            ..FakeClock::default()
        };
        let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Continue);
        p.start(0.0);
        let _ = p.step_done(1e-3);
        drop(p);
        assert_eq!(clock.sleeps, vec![MS; 3]);
        assert_eq!(clock.now, MS);

        let flag = Arc::new(AtomicBool::new(false));
        let mut clock = FakeClock {
            interrupts: 1,
            ..FakeClock::default()
        };
        let mut p = Pacer::new(&mut clock, factor(1.0), OverrunPolicy::Continue)
            .with_interrupt(flag.clone());
        p.start(0.0);
        flag.store(true, Ordering::Relaxed);
        let _ = p.step_done(1e-3);
        drop(p);
        // Set before the sleep: no sleep at all.
        assert!(clock.sleeps.is_empty());
    }

    /// A slowed-down run (factor < 1) sleeps in slices, looking at Ctrl-C's flag between.
    #[test]
    fn a_long_wait_is_cut_into_slices() {
        let mut clock = FakeClock::default();
        let mut p = Pacer::new(&mut clock, factor(0.01), OverrunPolicy::Continue);
        p.start(0.0);
        let _ = p.step_done(1e-3); // 100 ms of wall time
        drop(p);
        assert_eq!(clock.sleeps, vec![50 * MS, 100 * MS]);
    }

    #[test]
    fn quantiles_are_within_the_histograms_resolution_and_never_early() {
        let mut l = Histogram::default();
        // 1000 steps: slack from -999 µs to 0 in 1 µs steps.
        let values: Vec<Nanos> = (0..1000).map(|k| -(k as Nanos) * 1000).collect();
        for &v in &values {
            l.add(v);
        }
        l.add(3_000_000); // one step 3 ms late
        let mut sorted = values.clone();
        sorted.push(3_000_000);
        sorted.sort();
        for q in [0.5, 0.99, 0.999] {
            let exact = sorted[((q * sorted.len() as f64).ceil() as usize).max(1) - 1];
            let got = l.quantile(q).unwrap();
            assert!(got >= exact, "q {q}: {got} < {exact}");
            assert!(
                (got - exact) as f64 <= exact.unsigned_abs() as f64 / 64.0 + 1.0,
                "q {q}: {got} vs {exact}"
            );
        }
        assert_eq!(l.max(), Some(3_000_000));
        assert_eq!(l.quantile(1.0), Some(3_000_000));
        assert_eq!(l.min(), Some(-999_000));
        assert_eq!(l.coarse(), [1000, 0, 0, 0, 1]);
    }

    #[test]
    fn buckets_cover_their_ranges_in_order() {
        let mut last = None;
        for m in (0..5000u64).chain([1 << 20, (1 << 20) + 1, 1 << 40, u64::MAX]) {
            let b = bucket(m);
            assert!(b < BUCKETS, "{m}");
            let (lo, hi) = bucket_range(b);
            if m < 1 << 41 {
                assert!(lo <= m && m <= hi, "{m}: {lo}..{hi}");
            }
            if let Some(l) = last {
                assert!(b >= l);
            }
            last = Some(b);
        }
        assert_eq!(bucket_range(BUCKETS - 1).1, (1 << 41) - 1);
    }

    #[test]
    fn durations_in_words() {
        assert_eq!(duration_words(-987_600), "-987.6 µs");
        assert_eq!(duration_words(12), "12 ns");
        assert_eq!(duration_words(1_250_000), "1.25 ms");
        assert_eq!(cpu_list(&[0, 1, 2, 5, 7, 8]), "0-2,5,7-8");
    }
}

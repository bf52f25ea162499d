//! The CLI's observers: progress bars (indicatif) of an optimisation study
//! ([`StudyObserver`]) and of a run ([`RunObserver`]), and a run's interruption.

use indicatif::{ProgressBar, ProgressStyle};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use tb_cosim::{Ended, Moment, RunObserver, RunView, SystemError};
use tb_optimize::{GenerationDone, PhaseProgress, StudyObserver};

/// Where plain progress lines go.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Lines {
    Stdout,
    Stderr,
}

/// One bar per step on stderr when it is a terminal, and a plain line per generation with
/// an ETA where no bar can be seen (`optimize … > log.txt`, `nohup`, CI, a batch job).
#[derive(Default)]
pub struct Bars {
    bar: Mutex<Option<ProgressBar>>,
    lines: Option<Lines>,
    /// The current step's start here (wall clock, generations done then), for the ETA.
    clock: Mutex<Option<(std::time::Instant, usize)>>,
    /// The phase after the steps: its spinner on a terminal, and when its last plain line
    /// was printed (one every [`PHASE_LINE_S`] at most).
    phase: Mutex<Option<(&'static str, Option<ProgressBar>, std::time::Instant)>>,
}

/// The least time between two plain lines of a phase after the steps (its end is always
/// said): a profile's hundreds of batches do not flood a log.
const PHASE_LINE_S: f64 = 5.0;

/// A phase's name in words.
fn phase_words(phase: &str) -> &str {
    match phase {
        "refinement" => "joint refinement",
        "profiles" => "profile likelihood",
        "bootstrap" => "bootstrap refits",
        other => other,
    }
}

impl Bars {
    /// The bars for the CLI: a bar on a terminal's stderr; plain lines on stdout when it is
    /// not a terminal (it holds the log; not with `--json`, whose stdout is the document),
    /// else on stderr when that is not a terminal.
    pub fn for_cli(json: bool) -> Arc<dyn StudyObserver> {
        use std::io::IsTerminal;
        let lines = if !json && !std::io::stdout().is_terminal() {
            Some(Lines::Stdout)
        } else if !std::io::stderr().is_terminal() {
            Some(Lines::Stderr)
        } else {
            None
        };
        Arc::new(Bars {
            lines,
            ..Bars::default()
        })
    }
}

/// A duration in words for a log line: `42 s`, `3 min 5 s`, `1 h 12 min`.
pub fn duration(seconds: f64) -> String {
    let s = seconds.max(0.0).round() as u64;
    match s {
        0..=59 => format!("{s} s"),
        60..=3599 => format!("{} min {} s", s / 60, s % 60),
        _ => format!("{} h {} min", s / 3600, (s % 3600) / 60),
    }
}

/// Writes one progress line and flushes it (a log read while the study runs).
pub fn print_line(to: Lines, line: &str) {
    use std::io::Write;
    match to {
        Lines::Stdout => {
            let mut out = std::io::stdout().lock();
            let _ = writeln!(out, "{line}");
            let _ = out.flush();
        }
        Lines::Stderr => {
            let mut out = std::io::stderr().lock();
            let _ = writeln!(out, "{line}");
            let _ = out.flush();
        }
    }
}

impl StudyObserver for Bars {
    fn step_started(&self, step: usize, name: &str, generations: usize, done: usize) {
        if let Ok(mut c) = self.clock.lock() {
            *c = Some((std::time::Instant::now(), done));
        }
        if let Some(to) = self.lines {
            let resumed = if done > 0 {
                format!(", resumed at generation {done}")
            } else {
                String::new()
            };
            print_line(
                to,
                &format!("step {step} {name}: {generations} generations{resumed}"),
            );
        }
        if self.lines.is_some() && !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
            return;
        }
        let pb = ProgressBar::new(generations as u64);
        pb.set_style(
            ProgressStyle::with_template(
                "{prefix} [{bar:30}] {pos}/{len} generations  {msg}  ({elapsed})",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
        pb.set_prefix(format!("step {step} {name}"));
        pb.set_position(done as u64);
        // An interrupted step's bar stays where it stopped (a dropped bar would be
        // finished: "22/22" after an interrupt at generation 1).
        let pb = pb.with_finish(indicatif::ProgressFinish::Abandon);
        if let Ok(mut b) = self.bar.lock() {
            *b = Some(pb);
        }
    }

    fn generation(&self, g: &GenerationDone<'_>) -> ControlFlow<()> {
        if let Some(to) = self.lines {
            let record = g.record;
            let eta = self
                .clock
                .lock()
                .ok()
                .and_then(|c| *c)
                .map(|(start, from)| {
                    let elapsed = start.elapsed().as_secs_f64();
                    let per = elapsed / (g.done.saturating_sub(from)).max(1) as f64;
                    let left = g.generations.saturating_sub(g.done);
                    format!(
                        "{} elapsed, ETA {} for the step",
                        duration(elapsed),
                        duration(per * left as f64)
                    )
                })
                .unwrap_or_default();
            let workers = g
                .workers
                .map_or(String::new(), |w| format!(", {w} workers"));
            print_line(
                to,
                &format!(
                    "step {} {}: generation {}/{}, best cost {:.5} ({} evaluations{workers}), {eta}",
                    g.step, g.name, g.done, g.generations, record.best_cost, record.evaluations
                ),
            );
        }
        if let Ok(b) = self.bar.lock() {
            if let Some(pb) = b.as_ref() {
                let record = g.record;
                pb.set_position(record.generation as u64);
                let workers = g
                    .workers
                    .map_or(String::new(), |w| format!(", {w} workers"));
                pb.set_message(format!(
                    "best cost {:.5}  ({} evaluations{workers})",
                    record.best_cost, record.evaluations
                ));
            }
        }
        ControlFlow::Continue(())
    }

    fn step_finished(&self) {
        if let Ok(mut b) = self.bar.lock() {
            if let Some(pb) = b.take() {
                pb.abandon();
            }
        }
    }

    fn phase(&self, p: &PhaseProgress<'_>) {
        let Ok(mut now) = self.phase.lock() else {
            return;
        };
        let fresh = !matches!(now.as_ref(), Some((name, ..)) if *name == p.phase);
        if fresh {
            if let Some((_, Some(old), _)) = now.take() {
                old.abandon();
            }
            let spinner = (self.lines.is_none()
                || std::io::IsTerminal::is_terminal(&std::io::stderr()))
            .then(|| {
                let pb = ProgressBar::new_spinner().with_finish(indicatif::ProgressFinish::Abandon);
                pb.set_style(
                    ProgressStyle::with_template("{spinner} {prefix}: {msg}  ({elapsed})")
                        .expect("valid template"),
                );
                pb.set_prefix(phase_words(p.phase).to_string());
                pb.enable_steady_tick(std::time::Duration::from_millis(200));
                pb
            });
            // Long enough ago that the first batch gets its line.
            let before = std::time::Instant::now()
                .checked_sub(std::time::Duration::from_secs_f64(PHASE_LINE_S))
                .unwrap_or_else(std::time::Instant::now);
            *now = Some((p.phase, spinner, before));
        }
        let Some((_, spinner, last_line)) = now.as_mut() else {
            return;
        };
        let text = format!(
            "{} laps of {} parameters, {}{}",
            p.laps,
            p.parameters.len(),
            duration(p.seconds),
            if p.done { ", done" } else { "" }
        );
        if let Some(pb) = spinner {
            pb.set_message(text.clone());
            if p.done {
                pb.abandon();
            }
        }
        if let Some(to) = self.lines {
            if p.done || last_line.elapsed().as_secs_f64() >= PHASE_LINE_S {
                print_line(to, &format!("{}: {text}", phase_words(p.phase)));
                *last_line = std::time::Instant::now();
            }
        }
        if p.done {
            *now = None;
        }
    }
}

/// The progress of one run (`twinbench run`) on stderr: simulated time against the stop
/// time (or the stop condition's `max_time`). Shown only for a run still going after half a
/// second of wall time, updated every 16 steps: a lap of 0.08 s draws nothing.
pub struct RunBar {
    started: std::time::Instant,
    bar: Option<ProgressBar>,
    /// What ends the run, for the bar's text: "of 90 s", "until vehicle.lap >= 1 (at most
    /// 200 s)".
    until: String,
    /// Where no bar can be seen: a plain line per tenth of the run, here.
    lines: Option<Lines>,
    /// The tenths already said.
    said: u64,
}

impl RunBar {
    /// A bar on a terminal's stderr, or with `lines` a plain line per tenth of the run
    /// (`run … > log.txt`, a batch job), each with an ETA.
    pub fn new(until: String, lines: Option<Lines>) -> RunBar {
        RunBar {
            started: std::time::Instant::now(),
            bar: None,
            until,
            lines,
            said: 0,
        }
    }

    /// Where a run's plain lines go: stdout when it is not a terminal (it holds the log; not
    /// with `--json`, whose stdout is the document), else stderr when that is not one;
    /// None on a terminal (the bar).
    pub fn lines_for_cli(json: bool) -> Option<Lines> {
        use std::io::IsTerminal;
        if !std::io::stderr().is_terminal() {
            Some(if !json && !std::io::stdout().is_terminal() {
                Lines::Stdout
            } else {
                Lines::Stderr
            })
        } else {
            None
        }
    }

    fn update(&mut self, now: &RunView<'_>) {
        let span = now.horizon() - now.start();
        let done = ((now.time() - now.start()) / span * 1000.0).clamp(0.0, 1000.0) as u64;
        let elapsed = self.started.elapsed().as_secs_f64();
        if let Some(to) = self.lines {
            let tenth = done / 100;
            if tenth > self.said && elapsed >= 0.5 {
                self.said = tenth;
                let left = elapsed / (done.max(1) as f64) * (1000 - done) as f64;
                print_line(
                    to,
                    &format!(
                        "run: {} %, t = {:.1} s {}, {} elapsed, ETA {} (at most)",
                        tenth * 10,
                        now.time(),
                        self.until,
                        duration(elapsed),
                        duration(left)
                    ),
                );
            }
            return;
        }
        if self.bar.is_none() {
            if self.started.elapsed().as_secs_f64() < 0.5 {
                return;
            }
            let pb = ProgressBar::new(1000);
            pb.set_style(
                ProgressStyle::with_template("run [{bar:30}] {msg}  ({elapsed})")
                    .expect("valid template")
                    .progress_chars("=> "),
            );
            self.bar = Some(pb);
        }
        if let Some(pb) = &self.bar {
            pb.set_position(done);
            pb.set_message(format!("t = {:.1} s {}", now.time(), self.until.as_str()));
        }
    }
}

impl RunObserver for RunBar {
    fn step_interval(&self) -> u64 {
        16
    }

    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        // Every 16th step (`step_interval`), and the start.
        if let Moment::Step { .. } = now.moment() {
            self.update(now);
        }
        Ok(ControlFlow::Continue(()))
    }

    fn finished(&mut self, _now: &mut RunView<'_>, _how: &Ended) -> Result<(), SystemError> {
        if let Some(pb) = self.bar.take() {
            pb.finish_and_clear();
        }
        Ok(())
    }
}

impl Drop for RunBar {
    /// A failed run clears its bar too (its error follows on stderr).
    fn drop(&mut self) {
        if let Some(pb) = self.bar.take() {
            pb.finish_and_clear();
        }
    }
}

/// Ends a run at the first SIGINT or SIGTERM ([`super::interrupt::run_flag`]): the run
/// fails after the step under way, so its rows are kept as an incomplete result. It sees
/// no step until the signal's flag wakes it ([`RunObserver::wake_flag`]): the master reads
/// the flag at every step, and nothing else is done.
pub struct StopRunOnFlag(pub Arc<AtomicBool>);

impl RunObserver for StopRunOnFlag {
    fn step_interval(&self) -> u64 {
        u64::MAX
    }

    fn wake_flag(&self) -> Option<Arc<AtomicBool>> {
        Some(self.0.clone())
    }

    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        if self.0.load(Ordering::Relaxed) {
            return Err(SystemError::Stop(format!(
                "interrupted by SIGINT or SIGTERM (Ctrl-C) at t = {} s",
                tb_files::number(now.time())
            )));
        }
        Ok(ControlFlow::Continue(()))
    }
}

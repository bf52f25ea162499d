//! The CLI's observers: progress bars (indicatif) of an optimisation study
//! ([`StudyObserver`]) and of a run ([`RunObserver`]), and a run's interruption.

use indicatif::{ProgressBar, ProgressStyle};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use tb_cosim::{Ended, Moment, RunObserver, RunView, SystemError};
use tb_optimize::{GenerationDone, StudyObserver};

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
}

impl RunBar {
    pub fn new(until: String) -> RunBar {
        RunBar {
            started: std::time::Instant::now(),
            bar: None,
            until,
        }
    }

    fn update(&mut self, now: &RunView<'_>) {
        let span = now.horizon() - now.start();
        let done = ((now.time() - now.start()) / span * 1000.0).clamp(0.0, 1000.0) as u64;
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

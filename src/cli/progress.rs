//! The CLI's observers: progress bars (indicatif) of an optimisation study
//! ([`StudyObserver`]) and of a run ([`RunObserver`]), and a run's interruption.

use indicatif::{ProgressBar, ProgressStyle};
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use tb_cosim::{Ended, Moment, RunObserver, RunView, SystemError};
use tb_optimize::{GenerationDone, StudyObserver};

/// One bar per step on stderr.
#[derive(Default)]
pub struct Bars {
    bar: Mutex<Option<ProgressBar>>,
}

impl Bars {
    pub fn shared() -> Arc<dyn StudyObserver> {
        Arc::new(Bars::default())
    }
}

impl StudyObserver for Bars {
    fn step_started(&self, step: usize, name: &str, generations: usize, done: usize) {
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
                pb.finish();
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

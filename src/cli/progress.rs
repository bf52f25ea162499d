//! Progress bars (indicatif) for optimisation studies: the CLI's [`StudyObserver`].

use indicatif::{ProgressBar, ProgressStyle};
use std::ops::ControlFlow;
use std::sync::{Arc, Mutex};
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

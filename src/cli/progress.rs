//! Progress bars (indicatif) for optimisation studies: the CLI's [`Progress`] observer.

use indicatif::{ProgressBar, ProgressStyle};
use std::sync::{Arc, Mutex};
use tb_optimize::{GenerationRecord, Progress};

/// One bar per step on stderr.
#[derive(Default)]
pub struct Bars {
    bar: Mutex<Option<ProgressBar>>,
}

impl Bars {
    pub fn shared() -> Arc<dyn Progress> {
        Arc::new(Bars::default())
    }
}

impl Progress for Bars {
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

    fn generation(&self, record: &GenerationRecord) {
        if let Ok(b) = self.bar.lock() {
            if let Some(pb) = b.as_ref() {
                pb.set_position(record.generation as u64);
                pb.set_message(format!(
                    "best cost {:.5}  ({} evaluations)",
                    record.best_cost, record.evaluations
                ));
            }
        }
    }

    fn step_finished(&self) {
        if let Ok(mut b) = self.bar.lock() {
            if let Some(pb) = b.take() {
                pb.finish();
            }
        }
    }
}

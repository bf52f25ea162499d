//! Observers of a run: a caller's observer sees every moment (the start, each step, the
//! end) with the values of that moment, record-only outputs included; it can end the run
//! with its reason or fail it with its error; the recording and the stop condition, the
//! master's own observers, are unchanged by it. Binary fractions make every value exact.

mod support;

use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use support::{column, instances, Bench};
use tb_cosim::{Ended, Moment, RunObserver, RunView, Simulation, SystemError};
use tb_testkit::assert_contains;

/// integrator (u = 0.5, x0 = 1) -> g (k = 2), h = 1/8, stop 2 s, every 4th step recorded.
/// `g.y` is read by the recording only (no connection reads it).
fn system(experiment: &str) -> String {
    let instances = instances(&[("int", "integrator"), ("g", "gain")]);
    format!(
        r#"connections = ["int.x -> g.u"]

{instances}[parameters]
"int.x0" = 1.0
"int.u" = 0.5
"g.k" = 2.0

[experiment]
step = 0.125
{experiment}

[record]
signals = ["int.x", "g.y"]
decimation = 4
"#
    )
}

/// What a watcher saw: (moment, time, int.x, g.y) at each moment, and how the run ended.
#[derive(Default)]
struct Seen {
    moments: Vec<(Moment, f64, f64, f64)>,
    finished: Vec<(Ended, f64, f64)>,
}

/// An observer that writes down what it sees, and ends or fails the run when told to.
struct Watcher {
    seen: Arc<Mutex<Seen>>,
    slots: (usize, usize),
    /// End the run once int.x reaches this.
    end_at: Option<f64>,
    /// Fail the run at this step.
    fail_at: Option<u64>,
    /// The steps it can do without seeing.
    interval: u64,
}

impl Watcher {
    fn new(sim: &tb_cosim::Simulation) -> (Watcher, Arc<Mutex<Seen>>) {
        let slot = |name: &str| sim.plan().slot_of(name).expect(name);
        let seen = Arc::new(Mutex::new(Seen::default()));
        let w = Watcher {
            seen: seen.clone(),
            slots: (slot("int.x"), slot("g.y")),
            end_at: None,
            fail_at: None,
            interval: 1,
        };
        (w, seen)
    }
}

/// A simulation of `text` observed by one watcher, as `set` makes it; and what it sees.
fn watched(
    b: &Bench,
    text: &str,
    set: impl FnOnce(&mut Watcher),
) -> (Simulation, Arc<Mutex<Seen>>) {
    let mut sim = b.sim(text);
    let (mut watcher, seen) = Watcher::new(&sim);
    set(&mut watcher);
    sim.observe(Box::new(watcher));
    (sim, seen)
}

impl RunObserver for Watcher {
    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        let (t, moment) = (now.time(), now.moment());
        let signals = now.signals()?;
        let (x, y) = (signals[self.slots.0], signals[self.slots.1]);
        self.seen.lock().unwrap().moments.push((moment, t, x, y));
        if let (Moment::Step { k, .. }, Some(at)) = (moment, self.fail_at) {
            if k == at {
                return Err(SystemError::Observer {
                    observer: "watcher".into(),
                    error: std::io::Error::other(format!("cannot write step {k}")),
                });
            }
        }
        match self.end_at {
            Some(x_end) if x >= x_end => Ok(ControlFlow::Break(format!("int.x reached {x}"))),
            _ => Ok(ControlFlow::Continue(())),
        }
    }

    fn step_interval(&self) -> u64 {
        self.interval
    }

    fn finished(&mut self, now: &mut RunView<'_>, how: &Ended) -> Result<(), SystemError> {
        let x = now.signals()?[self.slots.0];
        self.seen
            .lock()
            .unwrap()
            .finished
            .push((how.clone(), now.time(), x));
        Ok(())
    }
}

#[test]
fn an_observer_sees_every_moment_with_its_values_and_changes_nothing() {
    let b = Bench::new();
    let text = system("stop = 2.0");
    let (plain, plain_summary) = b.run(&text);
    let (mut sim, seen) = watched(&b, &text, |_| {});
    let summary = sim.run().unwrap();
    // The recording and the summary are those of a run without the observer, bit for bit.
    assert_eq!(sim.recording().to_csv(), plain.recording().to_csv());
    assert_eq!(summary.steps, plain_summary.steps);
    assert_eq!(summary.stopped_by, "stop time 2 s");
    let seen = seen.lock().unwrap();
    // The start, then each of the 16 steps, the last one marked.
    assert_eq!(seen.moments.len(), 17);
    assert_eq!(seen.moments[0].0, Moment::Start);
    for (k, &(moment, t, x, y)) in seen.moments.iter().enumerate().skip(1) {
        let k = k as u64;
        assert_eq!(moment, Moment::Step { k, last: k == 16 });
        assert_eq!(t, k as f64 * 0.125);
        // x_k = 1 + k·u·h exactly; g.y = 2·x at every step, recorded (every 4th) or not:
        // the observer's question read the record-only output at that step.
        assert_eq!(x, 1.0 + k as f64 * 0.0625, "step {k}");
        assert_eq!(y, 2.0 * x, "step {k}");
    }
    assert_eq!(seen.finished, [(Ended::Horizon, 2.0, 2.0)]);
    // The recording kept its own rows only: every 4th step.
    assert_eq!(column(&sim, "time"), [0.0, 0.5, 1.0, 1.5, 2.0]);
}

#[test]
fn an_observer_ends_the_run_with_its_reason_and_every_observer_sees_that_step() {
    let b = Bench::new();
    let mut sim = b.sim(&system("stop = 2.0"));
    let (mut ender, _) = Watcher::new(&sim);
    ender.end_at = Some(1.375);
    let (after, seen) = Watcher::new(&sim);
    sim.observe(Box::new(ender));
    sim.observe(Box::new(after));
    let summary = sim.run().unwrap();
    // x = 1 + k/16 reaches 1.375 at step 6 (t = 0.75 s): the run ends there.
    assert_eq!(summary.steps, 6);
    assert_eq!(summary.simulated_time, 0.75);
    assert_eq!(summary.stopped_by, "int.x reached 1.375");
    let seen = seen.lock().unwrap();
    assert_eq!(seen.moments.last().unwrap().1, 0.75);
    assert_eq!(
        seen.finished,
        [(Ended::Observer("int.x reached 1.375".into()), 0.75, 1.375)]
    );
    // The recording's rows stay on its grid: the steps of the run that are every 4th.
    assert_eq!(column(&sim, "time"), [0.0, 0.5]);
}

#[test]
fn the_plans_stop_condition_is_an_observer_before_the_callers() {
    let b = Bench::new();
    // The condition holds at step 4 (x = 1.25); the caller would end the run at step 6.
    let text = system("stop = \"int.x >= 1.25\"\nmax_time = 10.0");
    let (mut sim, seen) = watched(&b, &text, |w| w.end_at = Some(1.375));
    let summary = sim.run().unwrap();
    assert_eq!(summary.steps, 4);
    assert_eq!(summary.stopped_by, "int.x >= 1.25");
    assert_eq!(
        seen.lock().unwrap().finished,
        [(Ended::Observer("int.x >= 1.25".into()), 0.5, 1.25)]
    );
    // Both reasons at the same step: the plan's condition is told first, its reason wins.
    let (mut sim, _) = watched(&b, &text, |w| w.end_at = Some(1.25));
    assert_eq!(sim.run().unwrap().stopped_by, "int.x >= 1.25");
    // A condition that never holds still fails the run at max_time, observed or not.
    let text = system("stop = \"int.x < 0\"\nmax_time = 0.5");
    let (mut sim, seen) = watched(&b, &text, |_| {});
    let e = sim.run().unwrap_err();
    assert!(matches!(e, SystemError::Stop(_)), "{e:?}");
    assert_contains(
        &e.to_string(),
        &["did not complete within max_time = 0.5 s"],
    );
    // The caller's observer was not told of a finish: the run failed.
    assert!(seen.lock().unwrap().finished.is_empty());
}

#[test]
fn an_observers_error_fails_the_run_and_taking_it_off_runs_again() {
    let b = Bench::new();
    let text = system("stop = 2.0");
    let (mut sim, seen) = watched(&b, &text, |w| w.fail_at = Some(3));
    let e = sim.run().unwrap_err();
    assert!(matches!(&e, SystemError::Observer { observer, .. } if observer == "watcher"));
    assert_eq!(e.to_string(), "observer 'watcher': cannot write step 3");
    assert!(seen.lock().unwrap().finished.is_empty());
    assert_eq!(sim.take_observers().len(), 1);
    let (plain, _) = b.run(&text);
    sim.run().unwrap();
    assert_eq!(sim.recording().to_csv(), plain.recording().to_csv());
}

#[test]
fn each_observer_sees_the_steps_it_asks_for_and_every_other_moment() {
    let b = Bench::new();
    let mut sim = b.sim(&system("stop = 2.0"));
    let (mut sparse, sparse_seen) = Watcher::new(&sim);
    sparse.interval = 5;
    sim.observe(Box::new(sparse));
    sim.run().unwrap();
    let steps = |seen: &Arc<Mutex<Seen>>| -> Vec<Moment> {
        seen.lock().unwrap().moments.iter().map(|m| m.0).collect()
    };
    // Every 5th step of 16, after the start; the end is told by `finished`.
    let step = |k: u64| Moment::Step { k, last: k == 16 };
    assert_eq!(
        steps(&sparse_seen),
        [Moment::Start, step(5), step(10), step(15)]
    );
    assert_eq!(sparse_seen.lock().unwrap().finished.len(), 1);
    // Beside another that asks for every 2nd step, each sees exactly its own.
    let mut sim = b.sim(&system("stop = 2.0"));
    let (mut sparse, sparse_seen) = Watcher::new(&sim);
    sparse.interval = 5;
    let (mut half, half_seen) = Watcher::new(&sim);
    half.interval = 2;
    sim.observe(Box::new(sparse));
    sim.observe(Box::new(half));
    sim.run().unwrap();
    assert_eq!(
        steps(&sparse_seen),
        [Moment::Start, step(5), step(10), step(15)]
    );
    let expected: Vec<Moment> = std::iter::once(Moment::Start)
        .chain((2..=16).step_by(2).map(step))
        .collect();
    assert_eq!(steps(&half_seen), expected);
}

/// Sees no step until its flag is set; then ends the run.
struct Sleeper {
    flag: Arc<AtomicBool>,
    seen: Arc<Mutex<Vec<Moment>>>,
}

impl RunObserver for Sleeper {
    fn step_interval(&self) -> u64 {
        u64::MAX
    }

    fn wake_flag(&self) -> Option<Arc<AtomicBool>> {
        Some(self.flag.clone())
    }

    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        self.seen.lock().unwrap().push(now.moment());
        match self.flag.load(Ordering::Relaxed) {
            true => Ok(ControlFlow::Break("woken".into())),
            false => Ok(ControlFlow::Continue(())),
        }
    }
}

/// Sets a flag at one step (as a signal handler or a stop button would).
struct Setter(Arc<AtomicBool>, u64);

impl RunObserver for Setter {
    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        if now.moment()
            == (Moment::Step {
                k: self.1,
                last: false,
            })
        {
            self.0.store(true, Ordering::Relaxed);
        }
        Ok(ControlFlow::Continue(()))
    }
}

#[test]
fn an_observer_that_asks_for_no_steps_is_woken_by_its_flag_at_the_next_step() {
    let b = Bench::new();
    let mut sim = b.sim(&system("stop = 2.0"));
    let (flag, seen) = (Arc::new(AtomicBool::new(false)), Arc::default());
    sim.observe(Box::new(Setter(flag.clone(), 6)));
    sim.observe(Box::new(Sleeper {
        flag,
        seen: Arc::clone(&seen),
    }));
    let summary = sim.run().unwrap();
    // Set during step 6's calls: the sleeper sees step 7, its first, and ends the run.
    assert_eq!(
        *seen.lock().unwrap(),
        [Moment::Start, Moment::Step { k: 7, last: false }]
    );
    assert_eq!((summary.steps, summary.stopped_by.as_str()), (7, "woken"));
}

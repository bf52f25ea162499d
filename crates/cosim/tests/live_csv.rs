//! A caller's own observer, written the way a user extends a run: a live CSV of one signal,
//! a line per recorded row, flushed as it is written (so `tail -f` follows the run), and
//! its own write failure reported as the observer's. Nothing of tb-cosim is changed for
//! it: the observer is this file.

mod support;

use std::io::Write;
use std::ops::ControlFlow;
use support::{column, instances, Bench};
use tb_cosim::{RunObserver, RunView, SystemError};

/// `time,<signal>` lines of one signal on the recording's rows.
struct LiveCsv {
    name: String,
    slot: usize,
    out: Box<dyn Write + Send>,
    /// The recording's decimation, read at the start: the same rows as the recording.
    every: u64,
}

impl LiveCsv {
    fn new(sim: &tb_cosim::Simulation, name: &str, out: Box<dyn Write + Send>) -> LiveCsv {
        LiveCsv {
            name: name.into(),
            slot: sim.plan().slot_of(name).expect(name),
            out,
            every: 1,
        }
    }

    /// The write failure as this observer's.
    fn failed(&self, error: std::io::Error) -> SystemError {
        SystemError::Observer {
            observer: format!("live CSV of {}", self.name),
            error,
        }
    }

    fn line(&mut self, now: &mut RunView<'_>) -> Result<(), SystemError> {
        let value = now.signals()?[self.slot];
        writeln!(self.out, "{},{value}", now.time())
            .and_then(|()| self.out.flush())
            .map_err(|e| self.failed(e))
    }
}

impl RunObserver for LiveCsv {
    fn observe(&mut self, now: &mut RunView<'_>) -> Result<ControlFlow<String>, SystemError> {
        if now.moment() == tb_cosim::Moment::Start {
            self.every = now.record_decimation();
            writeln!(self.out, "time,{}", self.name).map_err(|e| self.failed(e))?;
        }
        self.line(now)?;
        Ok(ControlFlow::Continue(()))
    }

    fn step_interval(&self) -> u64 {
        self.every
    }
}

/// A writer into a shared buffer (what a file would hold).
#[derive(Clone, Default)]
struct Shared(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);

impl Write for Shared {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// A writer that fails, as a full disk does.
struct Full;

impl Write for Full {
    fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
        Err(std::io::Error::from(std::io::ErrorKind::StorageFull))
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// integrator (u = 0.5, x0 = 1), h = 1/8, stop 2 s, every 4th step recorded.
fn system() -> String {
    let instances = instances(&[("int", "integrator")]);
    format!(
        r#"{instances}[parameters]
"int.x0" = 1.0
"int.u" = 0.5

[experiment]
step = 0.125
stop = 2.0

[record]
signals = ["int.x"]
decimation = 4
"#
    )
}

#[test]
fn the_live_csv_has_the_recordings_rows_and_values() {
    let b = Bench::new();
    let mut sim = b.sim(&system());
    let file = Shared::default();
    sim.observe(Box::new(LiveCsv::new(
        &sim,
        "int.x",
        Box::new(file.clone()),
    )));
    sim.run().unwrap();
    let text = String::from_utf8(file.0.lock().unwrap().clone()).unwrap();
    let mut want = String::from("time,int.x\n");
    for (t, x) in column(&sim, "time").iter().zip(column(&sim, "int.x")) {
        want.push_str(&format!("{t},{x}\n"));
    }
    // Rows at 0, 0.5, 1, 1.5, 2 s (x = 1 + t/2 exactly: binary fractions).
    assert_eq!(text, want);
    assert_eq!(text.lines().count(), 6);
    assert!(text.ends_with("2,2\n"), "{text}");
}

#[test]
fn the_observers_write_failure_fails_the_run_naming_it() {
    let b = Bench::new();
    let mut sim = b.sim(&system());
    sim.observe(Box::new(LiveCsv::new(&sim, "int.x", Box::new(Full))));
    let e = sim.run().unwrap_err();
    assert!(
        matches!(&e, SystemError::Observer { observer, error }
            if observer == "live CSV of int.x" && error.kind() == std::io::ErrorKind::StorageFull),
        "{e}"
    );
}

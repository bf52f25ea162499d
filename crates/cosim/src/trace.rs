//! The FMI call trace (`--trace-fmi FILE`): every call twinbench makes on the chosen
//! instances, with its arguments, values and status, one line per call, as FMPy's
//! `fmiCallLogger` prints them. A traced instance's backend is wrapped in [`Traced`];
//! an untraced one is not wrapped at all, so tracing costs nothing when it is off.
//!
//! A line: `t=0.1 edu: fmi2SetReal(vr=[3 accel_pedal=0.25]) -> fmi2OK`. FMI 3.0 instances
//! show the 3.0 names, each value with its variable's type (`fmi3Set*(vr=[7
//! Float64_continuous_input:Float64=0.5])`: the typed call that serves it). `t` is the
//! instance's time before the call.

use crate::backend::{Backend, BackendFactory};
use std::collections::HashMap;
use std::fmt::Write as _;
use std::io::Write;
use std::sync::{Arc, Mutex};
use tb_fmi::{FmuError, LoadedFmu, ScalarType};

/// Where trace lines go (shared by every traced instance of a run).
pub struct TraceSink {
    out: Mutex<(Box<dyn Write + Send>, Option<std::io::Error>)>,
}

impl TraceSink {
    pub fn new(out: Box<dyn Write + Send>) -> Arc<TraceSink> {
        Arc::new(TraceSink {
            out: Mutex::new((out, None)),
        })
    }

    fn line(&self, text: &str) {
        let mut g = self.out.lock().unwrap_or_else(|e| e.into_inner());
        if g.1.is_none() {
            if let Err(e) = writeln!(g.0, "{text}") {
                g.1 = Some(e);
            }
        }
    }

    /// One call's line: `t=0.1 edu: fmi2SetReal(vr=[...]) -> fmi2OK`.
    fn call(&self, t: f64, instance: &str, function: &str, args: &str, status: &str) {
        self.line(&format!("t={t} {instance}: {function}({args}) -> {status}"));
    }

    /// Flush; the first write error of the run, if any (a trace is never cut silently).
    pub fn finish(&self) -> std::io::Result<()> {
        let mut g = self.out.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(e) = g.1.take() {
            return Err(e);
        }
        g.0.flush()
    }
}

/// A trace file opened on its first line (after the caller has checked that the path
/// names none of the run's inputs), written through a buffer.
pub struct TraceFile {
    path: std::path::PathBuf,
    file: Option<std::io::BufWriter<std::fs::File>>,
}

impl TraceFile {
    pub fn new(path: &std::path::Path) -> TraceFile {
        TraceFile {
            path: path.to_path_buf(),
            file: None,
        }
    }
}

impl Write for TraceFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if self.file.is_none() {
            let f = std::fs::File::create(&self.path).map_err(|e| {
                std::io::Error::new(e.kind(), format!("{}: {e}", self.path.display()))
            })?;
            self.file = Some(std::io::BufWriter::new(f));
        }
        self.file.as_mut().expect("opened above").write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        match &mut self.file {
            Some(f) => f.flush(),
            None => Ok(()),
        }
    }
}

/// Which instances to trace, and where.
#[derive(Clone)]
pub struct TraceOptions {
    pub sink: Arc<TraceSink>,
    /// Instance names; empty: every instance.
    pub instances: Vec<String>,
}

impl std::fmt::Debug for TraceOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TraceOptions")
            .field("instances", &self.instances)
            .finish_non_exhaustive()
    }
}

/// Wraps a factory: its units are traced.
pub struct TracedFactory {
    pub inner: Arc<dyn BackendFactory>,
    pub sink: Arc<TraceSink>,
    pub fmu: Arc<LoadedFmu>,
}

impl BackendFactory for TracedFactory {
    fn kind(&self) -> &'static str {
        self.inner.kind()
    }
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError> {
        let fmi3 = self.fmu.is_fmi3();
        let p = if fmi3 { "fmi3" } else { "fmi2" };
        let sink = self.sink.clone();
        let r = self.inner.create(instance_name, logging);
        sink.line(&format!(
            "{instance_name}: {p}Instantiate{}(instanceName=\"{instance_name}\", token=\"{}\", loggingOn={logging}) -> {}",
            if fmi3 { "CoSimulation" } else { "" },
            self.fmu.description.guid,
            match &r {
                Ok(_) => "OK".to_string(),
                Err(e) => format!("error: {e}"),
            }
        ));
        // FMI 3.0 names carry the variable's own type (the typed call that serves it).
        let names = self
            .fmu
            .description
            .variables
            .iter()
            .rev() // the first name of a value reference wins
            .map(|v| match v.fmi3 {
                // FMI 3.0 value references are unique over every type.
                Some(s) if fmi3 => (
                    (None, v.value_reference),
                    format!("{}:{}", v.name, s.ty.name()),
                ),
                // FMI 2.0: one per value space (a Real and a Boolean may share one).
                _ => (
                    (Some(v.ty.value_space()), v.value_reference),
                    v.name.clone(),
                ),
            })
            .collect();
        let mut inner = r?;
        // A Model Exchange instance's own calls inside a step, in the same form; its step is
        // then no fmi2DoStep (the FMU never receives one).
        let line_sink = sink.clone();
        let name = instance_name.to_string();
        let steps_traced_inside =
            inner.set_call_trace(Arc::new(move |t, function, args, status| {
                // The status by its name in the FMU's version.
                let status = match fmi3 {
                    true => status.to_string().replacen("fmi2", "fmi3", 1),
                    false => status.to_string(),
                };
                line_sink.call(t, &name, function, args, &status);
            }));
        Ok(Box::new(Traced {
            inner,
            sink,
            names,
            fmi3,
            steps_traced_inside,
        }))
    }
}

/// A traced unit: forwards every call and writes a line for it.
pub struct Traced {
    inner: Box<dyn Backend>,
    sink: Arc<TraceSink>,
    /// Variable names by (value space, value reference); FMI 3.0: by value reference.
    names: HashMap<(Option<ScalarType>, u32), String>,
    fmi3: bool,
    /// The unit traces the calls of its steps itself (Model Exchange).
    steps_traced_inside: bool,
}

impl Traced {
    fn name2(&self, fmi2: &str, fmi3: &str) -> String {
        if self.fmi3 {
            fmi3.to_string()
        } else {
            fmi2.to_string()
        }
    }

    fn status<T>(&self, r: &Result<T, FmuError>) -> String {
        let ok = if self.fmi3 { "fmi3OK" } else { "fmi2OK" };
        match r {
            Ok(_) => ok.into(),
            Err(FmuError::Call { status, .. }) => status.to_string(),
            Err(e) => format!("error ({e})"),
        }
    }

    /// One line; `t` is the instance's time before the call.
    fn emit(&self, t: f64, function: &str, args: &str, status: &str) {
        self.sink.call(t, self.inner.name(), function, args, status);
    }

    /// `vr=[...]` with each value reference's name in the value space of the call.
    fn values<T: std::fmt::Display>(&self, space: ScalarType, vrs: &[u32], values: &[T]) -> String {
        let space = (!self.fmi3).then_some(space);
        let mut s = String::from("vr=[");
        for (k, vr) in vrs.iter().enumerate() {
            if k > 0 {
                s.push_str(", ");
            }
            let name = self.names.get(&(space, *vr)).map_or("?", String::as_str);
            match values.get(k) {
                Some(v) => {
                    let _ = write!(s, "{vr} {name}={v}");
                }
                None => {
                    let _ = write!(s, "{vr} {name}");
                }
            }
        }
        s.push(']');
        s
    }

    /// A get: the values read (or none when it failed) and the status.
    #[allow(clippy::too_many_arguments)]
    fn traced_get<O: ?Sized, T: std::fmt::Display>(
        &mut self,
        space: ScalarType,
        fmi2: &str,
        fmi3: &str,
        vrs: &[u32],
        out: &mut O,
        call: impl FnOnce(&mut dyn Backend, &mut O) -> Result<(), FmuError>,
        show: impl FnOnce(&O) -> Vec<T>,
    ) -> Result<(), FmuError> {
        let t = self.inner.time();
        let r = call(&mut *self.inner, out);
        let args = match r {
            Ok(()) => self.values(space, vrs, &show(out)),
            Err(_) => self.values::<T>(space, vrs, &[]),
        };
        let f = self.name2(fmi2, fmi3);
        let status = self.status(&r);
        self.emit(t, &f, &args, &status);
        r
    }

    fn traced<T>(
        &mut self,
        function: String,
        args: String,
        call: impl FnOnce(&mut dyn Backend) -> Result<T, FmuError>,
    ) -> Result<T, FmuError> {
        let t = self.inner.time();
        let r = call(&mut *self.inner);
        let status = self.status(&r);
        self.emit(t, &function, &args, &status);
        r
    }
}

/// Reals as their shortest round-trip text.
struct R(f64);
impl std::fmt::Display for R {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{:?}", self.0)
    }
}

/// The steps from `t` by `h` (the line of `fmi2DoStep`/`fmi3DoStep`), traced here unless
/// the backend traces its steps itself.
macro_rules! traced_steps {
    ($($call:ident -> $r:ty;)*) => {$(
        fn $call(&mut self, t: f64, h: f64) -> Result<$r, FmuError> {
            if self.steps_traced_inside {
                return self.inner.$call(t, h);
            }
            let f = self.name2("fmi2DoStep", "fmi3DoStep");
            let args = format!("currentCommunicationPoint={t:?}, communicationStepSize={h:?}");
            self.traced(f, args, |b| b.$call(t, h))
        }
    )*};
}

/// The traced calls without arguments: the names of the call in FMI 2.0 and 3.0.
macro_rules! traced_calls {
    ($($call:ident: $fmi2:literal, $fmi3:literal;)*) => {$(
        fn $call(&mut self) -> Result<(), FmuError> {
            let f = self.name2($fmi2, $fmi3);
            self.traced(f, String::new(), |b| b.$call())
        }
    )*};
}

/// The traced get and set of one value type: the names of the calls in FMI 2.0 and 3.0,
/// and `$show`, each value as the line shows it.
macro_rules! traced_values {
    ($($get:ident / $set:ident: $out:ty, $in:ty, $space:ident,
        [$g2:literal, $g3:literal], [$s2:literal, $s3:literal], $show:expr;)*) => {$(
        fn $get(&mut self, vrs: &[u32], out: $out) -> Result<(), FmuError> {
            self.traced_get(
                ScalarType::$space,
                $g2,
                $g3,
                vrs,
                out,
                |b, o| b.$get(vrs, o),
                |o| o.iter().map($show).collect(),
            )
        }
        fn $set(&mut self, vrs: &[u32], values: $in) -> Result<(), FmuError> {
            let shown: Vec<_> = values.iter().map($show).collect();
            let args = self.values(ScalarType::$space, vrs, &shown);
            let f = self.name2($s2, $s3);
            self.traced(f, args, |b| b.$set(vrs, values))
        }
    )*};
}

impl Backend for Traced {
    fn name(&self) -> &str {
        self.inner.name()
    }
    fn time(&self) -> f64 {
        self.inner.time()
    }
    fn set_echo(&mut self, on: bool) {
        self.inner.set_echo(on)
    }
    fn last_log_lines(&self) -> Vec<String> {
        self.inner.last_log_lines()
    }
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        let f = self.name2("fmi2SetDebugLogging", "fmi3SetDebugLogging");
        self.traced(f, format!("loggingOn={on}"), |b| b.set_debug_logging(on))
    }
    fn setup_experiment(&mut self, e: tb_fmi::Experiment) -> Result<(), FmuError> {
        let stop_text = e.stop.map_or("undefined".to_string(), |s| format!("{s:?}"));
        if self.fmi3 || self.steps_traced_inside {
            // FMI 3.0 passes these to fmi3EnterInitializationMode; a Model Exchange instance
            // traces the call with the tolerance it tells the FMU (its own, not the master's).
            return self.inner.setup_experiment(e);
        }
        let start = e.start;
        self.traced(
            "fmi2SetupExperiment".into(),
            match e.tolerance {
                Some(tol) => {
                    format!("tolerance={tol:?}, startTime={start:?}, stopTime={stop_text}")
                }
                None => format!("startTime={start:?}, stopTime={stop_text}"),
            },
            |b| b.setup_experiment(e),
        )
    }
    traced_calls! {
        enter_initialization_mode: "fmi2EnterInitializationMode", "fmi3EnterInitializationMode";
        exit_initialization_mode: "fmi2ExitInitializationMode", "fmi3ExitInitializationMode";
        terminate: "fmi2Terminate", "fmi3Terminate";
        reset: "fmi2Reset", "fmi3Reset";
    }
    traced_values! {
        get_real / set_real: &mut [f64], &[f64], Real,
            ["fmi2GetReal", "fmi3Get*"], ["fmi2SetReal", "fmi3Set*"], |x| R(*x);
        get_integer / set_integer: &mut [i32], &[i32], Integer,
            ["fmi2GetInteger", "fmi3Get*"], ["fmi2SetInteger", "fmi3Set*"], |x| *x;
        get_boolean / set_boolean: &mut [i32], &[i32], Boolean,
            ["fmi2GetBoolean", "fmi3GetBoolean"], ["fmi2SetBoolean", "fmi3SetBoolean"], |x| *x;
        get_string / set_string: &mut Vec<String>, &[&str], String,
            ["fmi2GetString", "fmi3Get*"], ["fmi2SetString", "fmi3Set*"], |s| format!("{s:?}");
    }
    traced_steps! {
        do_step -> ();
        step_to_event -> tb_fmi::MeStop;
    }
    fn stops_at_events(&self) -> bool {
        self.inner.stops_at_events()
    }
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        let t = self.inner.time();
        let r = self.inner.terminated_by_fmu();
        let what = if self.fmi3 {
            "fmi3DoStep terminateSimulation"
        } else {
            "fmi2GetBooleanStatus(fmi2Terminated), fmi2GetRealStatus(fmi2LastSuccessfulTime)"
        };
        self.sink.line(&format!(
            "t={t} {}: {what} -> {}",
            self.inner.name(),
            match r {
                Some(t) => format!("terminated at {t:?}"),
                None => "not terminated".into(),
            }
        ));
        r
    }
}

impl Drop for Traced {
    fn drop(&mut self) {
        let f = self.name2("fmi2FreeInstance", "fmi3FreeInstance");
        self.sink.line(&format!(
            "t={} {}: {f}()",
            self.inner.time(),
            self.inner.name()
        ));
    }
}

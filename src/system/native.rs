//! Models linked into twinbench and called directly, without the FMI boundary: the same
//! [`fmu_export::Runtime`] state machine the FMUs run (same checks, same code), driven
//! through Rust calls instead of `fmi2*` C symbols. It is the floor that the orchestration
//! overhead of the FMU backend is measured against, and it must give bit-identical results
//! (tests/native.rs).
//!
//! An instance runs natively when its FMU's `modelName` is one of the linked model crates
//! and the FMU's GUID matches the linked crate's (the GUID hashes the variable interface);
//! the resources are the unpacked FMU's `resources/` folder, as for the FMU itself.

use super::backend::{Backend, BackendFactory};
use crate::fmu::{FmuError, LoadedFmu};
use fmu_export::fmi2::fmi2Status;
use fmu_export::variables::{Value, VarType};
use fmu_export::{Logger, Model, Runtime};
use std::collections::VecDeque;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

/// The model names that can run natively.
pub const NATIVE_MODELS: &[&str] = &["vehicle", "driver", "dyno", "edu", "faulty"];

/// Kept log lines and the echo switch of one native instance.
struct Sink {
    instance: String,
    lines: Mutex<VecDeque<String>>,
    echo: AtomicBool,
}

impl Sink {
    fn push(&self, status: fmi2Status, category: &str, message: &str) {
        let line = format!("[{}] {category}: {message}", status.name());
        if self.echo.load(Ordering::Relaxed) {
            let level = match status {
                fmi2Status::OK => log::Level::Debug,
                fmi2Status::WARNING | fmi2Status::DISCARD => log::Level::Warn,
                _ => log::Level::Error,
            };
            log::log!(target: "fmu", level, "{}: {line}", self.instance);
        }
        if let Ok(mut l) = self.lines.lock() {
            if l.len() == crate::fmu::logger::KEPT_LINES {
                l.pop_front();
            }
            l.push_back(line);
        }
    }
}

struct SinkLogger(Arc<Sink>);

impl Logger for SinkLogger {
    fn log(&self, status: fmi2Status, category: &str, message: &str) {
        self.0.push(status, category, message)
    }
}

/// One model instance called directly.
pub struct NativeBackend<M: Model> {
    rt: Runtime<M>,
    name: String,
    sink: Arc<Sink>,
    time: f64,
}

impl<M: Model> NativeBackend<M> {
    pub fn new(name: &str, resource_dir: Option<PathBuf>, logging: bool) -> Self {
        let sink = Arc::new(Sink {
            instance: name.to_string(),
            lines: Mutex::new(VecDeque::new()),
            echo: AtomicBool::new(true),
        });
        let rt = Runtime::<M>::new(
            name,
            resource_dir,
            Box::new(SinkLogger(sink.clone())),
            logging,
        );
        NativeBackend {
            rt,
            name: name.to_string(),
            sink,
            time: 0.0,
        }
    }

    /// Run a runtime call like the FFI layer does: a panic poisons the instance and
    /// becomes fmi2Error; OK and Warning pass.
    #[inline]
    fn call(
        &mut self,
        function: &'static str,
        f: impl FnOnce(&mut Runtime<M>) -> fmi2Status,
    ) -> Result<(), FmuError> {
        let rt = &mut self.rt;
        let status = match catch_unwind(AssertUnwindSafe(|| f(rt))) {
            Ok(s) => s,
            Err(payload) => {
                let text = fmu_export::ffi::panic_text(&*payload);
                self.rt.poison(function, &text)
            }
        };
        if status == fmi2Status::OK || status == fmi2Status::WARNING {
            Ok(())
        } else {
            Err(self.call_error(function, status))
        }
    }

    #[cold]
    fn call_error(&self, function: &'static str, status: fmi2Status) -> FmuError {
        FmuError::Call {
            instance: self.name.clone(),
            function,
            status: status.name(),
            time: self.time,
            log: self.last_log_lines(),
        }
    }
}

impl<M: Model> Backend for NativeBackend<M> {
    fn name(&self) -> &str {
        &self.name
    }
    fn time(&self) -> f64 {
        self.time
    }
    fn set_echo(&mut self, on: bool) {
        self.sink.echo.store(on, Ordering::Relaxed);
    }
    fn last_log_lines(&self) -> Vec<String> {
        self.sink
            .lines
            .lock()
            .map(|l| l.iter().cloned().collect())
            .unwrap_or_default()
    }
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        self.call("fmi2SetDebugLogging", |rt| rt.set_debug_logging(on, &[]))
    }
    fn setup_experiment(&mut self, start: f64, stop: Option<f64>) -> Result<(), FmuError> {
        self.time = start;
        self.call("fmi2SetupExperiment", |rt| rt.setup_experiment(start, stop))
    }
    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.call("fmi2EnterInitializationMode", |rt| {
            rt.enter_initialization_mode()
        })
    }
    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.call("fmi2ExitInitializationMode", |rt| {
            rt.exit_initialization_mode()
        })
    }
    fn terminate(&mut self) -> Result<(), FmuError> {
        self.call("fmi2Terminate", |rt| rt.terminate())
    }
    fn reset(&mut self) -> Result<(), FmuError> {
        if let Ok(mut l) = self.sink.lines.lock() {
            l.clear();
        }
        self.time = 0.0;
        self.call("fmi2Reset", |rt| rt.reset())
    }
    #[inline]
    fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        self.call("fmi2GetReal", |rt| {
            rt.get("fmi2GetReal", VarType::Real, vrs, out, |v| v.as_f64())
        })
    }
    #[inline]
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        self.call("fmi2SetReal", |rt| {
            rt.set(
                "fmi2SetReal",
                VarType::Real,
                vrs,
                values.iter().map(|x| Value::Real(*x)),
            )
        })
    }
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.call("fmi2GetInteger", |rt| {
            rt.get("fmi2GetInteger", VarType::Integer, vrs, out, |v| {
                v.as_f64() as i32
            })
        })
    }
    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.call("fmi2SetInteger", |rt| {
            rt.set(
                "fmi2SetInteger",
                VarType::Integer,
                vrs,
                values.iter().map(|x| Value::Integer(*x)),
            )
        })
    }
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.call("fmi2GetBoolean", |rt| {
            rt.get("fmi2GetBoolean", VarType::Boolean, vrs, out, |v| {
                v.as_f64() as i32
            })
        })
    }
    fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.call("fmi2SetBoolean", |rt| {
            rt.set(
                "fmi2SetBoolean",
                VarType::Boolean,
                vrs,
                values.iter().map(|x| Value::Boolean(*x != 0)),
            )
        })
    }
    #[inline]
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        self.time = t;
        self.call("fmi2DoStep", |rt| rt.do_step(t, h))?;
        self.time = t + h;
        Ok(())
    }
}

/// Creates one boxed native instance: (instance name, resource folder, logging).
type Create = fn(&str, Option<PathBuf>, bool) -> Box<dyn Backend>;

/// Creates [`NativeBackend`]s of one linked model, with the FMU's resources.
pub struct NativeFactory {
    model: &'static str,
    resource_dir: PathBuf,
    create: Create,
}

fn boxed<M: Model>(name: &str, res: Option<PathBuf>, logging: bool) -> Box<dyn Backend> {
    Box::new(NativeBackend::<M>::new(name, res, logging))
}

fn linked<M: Model>(fmu: &LoadedFmu) -> Result<Create, String> {
    let guid = fmu_export::description::guid::<M>();
    if fmu.description.guid != guid {
        return Err(format!(
            "{}: GUID {} differs from the linked '{}' model's {guid} (the FMU was built from other sources; repack it)",
            fmu.source.display(),
            fmu.description.guid,
            M::INFO.name
        ));
    }
    Ok(boxed::<M>)
}

impl NativeFactory {
    /// The native twin of an FMU, or why there is none.
    pub fn for_fmu(fmu: &LoadedFmu) -> Result<NativeFactory, String> {
        let name = fmu.description.model_name.as_str();
        let (model, create) = match name {
            "vehicle" => ("vehicle", linked::<vehicle::Vehicle>(fmu)?),
            "driver" => ("driver", linked::<driver::Driver>(fmu)?),
            "dyno" => ("dyno", linked::<dyno::Dyno>(fmu)?),
            "edu" => ("edu", linked::<edu::Edu>(fmu)?),
            "faulty" => ("faulty", linked::<faulty::Faulty>(fmu)?),
            other => {
                return Err(format!(
                    "{}: model '{other}' is not linked into twinbench (native models: {})",
                    fmu.source.display(),
                    NATIVE_MODELS.join(", ")
                ))
            }
        };
        Ok(NativeFactory {
            model,
            resource_dir: fmu.resource_dir(),
            create,
        })
    }

    pub fn model(&self) -> &'static str {
        self.model
    }
}

impl BackendFactory for NativeFactory {
    fn kind(&self) -> &'static str {
        "native"
    }
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError> {
        // Same resource rule as the FFI layer: a missing folder is passed as is (the model
        // reports what it cannot find).
        let mut b = (self.create)(instance_name, Some(self.resource_dir.clone()), logging);
        if logging {
            b.set_debug_logging(true)?;
        }
        Ok(b)
    }
}

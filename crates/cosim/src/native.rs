//! Models linked into twinbench and called directly, without the FMI boundary: the same
//! [`fmu_export::Runtime`] state machine the FMUs run (same checks, same code), driven
//! through Rust calls instead of `fmi2*` C symbols. It is the floor that the orchestration
//! overhead of the FMU backend is measured against, and it must give bit-identical results
//! (tests/native.rs).
//!
//! The host decides which models are linked (a list of [`NativeModel`], the host's model
//! registry); an instance runs natively when its FMU's `modelName` is one of them and the
//! FMU's GUID matches the linked crate's (the GUID hashes the variable interface). The
//! resources are the unpacked FMU's `resources/` folder, as for the FMU itself.

use super::backend::{Backend, BackendFactory};
use fmu_export::fmi2::fmi2Status;
use fmu_export::variables::{ScalarType, Value};
use fmu_export::{Logger, Model, Runtime};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::Arc;
use tb_fmi::import::log::LogSink;
use tb_fmi::{FmuError, Function, LoadedFmu};

/// Forwards the runtime's messages to the instance's log sink.
struct SinkLogger(Arc<LogSink>);

impl Logger for SinkLogger {
    fn log(&self, status: fmi2Status, category: &str, message: &str) {
        self.0.push(status, category, message)
    }
}

/// One model instance called directly.
pub struct NativeBackend<M: Model> {
    rt: Runtime<M>,
    name: String,
    sink: Arc<LogSink>,
    time: f64,
}

impl<M: Model> NativeBackend<M> {
    pub fn new(name: &str, resource_dir: Option<PathBuf>, logging: bool) -> Self {
        let sink = Arc::new(LogSink::new(name));
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
        function: Function,
        f: impl FnOnce(&mut Runtime<M>) -> fmi2Status,
    ) -> Result<(), FmuError> {
        let rt = &mut self.rt;
        let status = match catch_unwind(AssertUnwindSafe(|| f(rt))) {
            Ok(s) => s,
            Err(payload) => {
                let text = fmu_export::ffi::panic_text(&*payload);
                self.rt.poison(function.name(), &text)
            }
        };
        status
            .ok()
            .map_err(|s| FmuError::call(&self.name, function, s, self.time, self.sink.last_lines()))
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
        self.sink.set_echo(on);
    }
    fn last_log_lines(&self) -> Vec<String> {
        self.sink.last_lines()
    }
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        self.call(Function::SetDebugLogging, |rt| {
            rt.set_debug_logging(on, &[])
        })
    }
    fn setup_experiment(
        &mut self,
        start: f64,
        stop: Option<f64>,
        _tolerance: Option<f64>,
    ) -> Result<(), FmuError> {
        // Our models have no internal solver with a tolerance.
        self.time = start;
        self.call(Function::SetupExperiment, |rt| {
            rt.setup_experiment(start, stop)
        })
    }
    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.call(Function::EnterInitializationMode, |rt| {
            rt.enter_initialization_mode()
        })
    }
    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.call(Function::ExitInitializationMode, |rt| {
            rt.exit_initialization_mode()
        })
    }
    fn terminate(&mut self) -> Result<(), FmuError> {
        self.call(Function::Terminate, |rt| rt.terminate())
    }
    fn reset(&mut self) -> Result<(), FmuError> {
        self.sink.clear();
        self.time = 0.0;
        self.call(Function::Reset, |rt| rt.reset())
    }
    #[inline]
    fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        // The FMU's own path (fields read directly, FMI 3.0's `time` when exposed).
        self.call(Function::GetReal, |rt| rt.get_real(vrs, out))
    }
    #[inline]
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        self.call(Function::SetReal, |rt| {
            rt.set(
                "fmi2SetReal",
                ScalarType::Real,
                vrs,
                values.iter().map(|x| Value::Real(*x)),
            )
        })
    }
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.call(Function::GetInteger, |rt| {
            rt.get("fmi2GetInteger", ScalarType::Integer, vrs, out, |v| {
                v.as_f64() as i32
            })
        })
    }
    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.call(Function::SetInteger, |rt| {
            rt.set(
                "fmi2SetInteger",
                ScalarType::Integer,
                vrs,
                values.iter().map(|x| Value::Integer(*x)),
            )
        })
    }
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.call(Function::GetBoolean, |rt| {
            rt.get("fmi2GetBoolean", ScalarType::Boolean, vrs, out, |v| {
                v.as_f64() as i32
            })
        })
    }
    fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.call(Function::SetBoolean, |rt| {
            rt.set(
                "fmi2SetBoolean",
                ScalarType::Boolean,
                vrs,
                values.iter().map(|x| Value::Boolean(*x != 0)),
            )
        })
    }
    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        out.clear();
        self.call(Function::GetString, |rt| {
            rt.get_strings("fmi2GetString", vrs, |_, s| out.push(s.to_string()))
        })
    }
    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        self.call(Function::SetString, |rt| {
            rt.set_strings("fmi2SetString", vrs, values)
        })
    }
    #[inline]
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        self.time = t;
        self.call(Function::DoStep, |rt| rt.do_step(t, h))?;
        self.time = t + h;
        Ok(())
    }
}

/// Creates one boxed native instance: (instance name, resource folder, logging, the
/// independent variable `time` of an FMI 3.0 FMU exposed).
type Create = fn(&str, Option<PathBuf>, bool, bool) -> Box<dyn Backend>;

fn boxed<M: Model>(
    name: &str,
    res: Option<PathBuf>,
    logging: bool,
    fmi3_time: bool,
) -> Box<dyn Backend> {
    let mut b = NativeBackend::<M>::new(name, res, logging);
    if fmi3_time {
        b.rt.expose_time();
    }
    Box::new(b)
}

/// A model linked into the host: one row of the host's model registry.
#[derive(Clone, Copy)]
pub struct NativeModel {
    /// The model's name (`modelName` of its FMU).
    pub name: &'static str,
    /// The GUID its FMI 2.0 FMU carries when built from the linked sources.
    pub guid: fn() -> String,
    /// The instantiation token its FMI 3.0 FMU carries (the same table, another version).
    pub token: fn() -> String,
    create: Create,
}

impl NativeModel {
    pub fn of<M: Model>() -> NativeModel {
        NativeModel {
            name: M::INFO.name,
            guid: fmu_export::description::guid::<M>,
            token: fmu_export::description3::instantiation_token::<M>,
            create: boxed::<M>,
        }
    }
}

impl std::fmt::Debug for NativeModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NativeModel")
            .field("name", &self.name)
            .finish()
    }
}

/// Creates [`NativeBackend`]s of one linked model, with the FMU's resources.
pub struct NativeFactory {
    model: &'static str,
    resource_dir: PathBuf,
    create: Create,
    /// In place of an FMI 3.0 FMU: its independent variable `time` is read as the FMU's.
    fmi3: bool,
}

impl NativeFactory {
    /// The native twin of an FMU among the `linked` models, or why there is none.
    pub fn for_fmu(fmu: &LoadedFmu, linked: &[NativeModel]) -> Result<NativeFactory, String> {
        let name = fmu.description.model_name.as_str();
        let Some(m) = linked.iter().find(|m| m.name == name) else {
            return Err(format!(
                "{}: model '{name}' is not linked into twinbench (native models: {})",
                fmu.source.display(),
                linked.iter().map(|m| m.name).collect::<Vec<_>>().join(", ")
            ));
        };
        // An FMI 3.0 FMU of the model has the same variables under the same value
        // references, and `time` one past them, which the native instance then exposes.
        let (what, guid) = match fmu.is_fmi3() {
            true => ("instantiation token", (m.token)()),
            false => ("GUID", (m.guid)()),
        };
        if fmu.description.guid != guid {
            return Err(format!(
                "{}: {what} {} differs from the linked '{}' model's {guid} (the FMU was built from other sources; repack it)",
                fmu.source.display(),
                fmu.description.guid,
                m.name
            ));
        }
        Ok(NativeFactory {
            model: m.name,
            resource_dir: fmu.resource_dir(),
            create: m.create,
            fmi3: fmu.is_fmi3(),
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
        let mut b = (self.create)(
            instance_name,
            Some(self.resource_dir.clone()),
            logging,
            self.fmi3,
        );
        if logging {
            b.set_debug_logging(true)?;
        }
        Ok(b)
    }
}

//! The backend of a model linked into twinbench: its [`Runtime`] driven through Rust
//! calls, with the FFI layer's panic guard.

use super::NativeModel;
use crate::backend::Backend;
use fmu_export::fmi2::fmi2Status;
use fmu_export::variables::{ScalarType, Value};
use fmu_export::{Logger, Model, Runtime};
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;
use std::sync::Arc;
use tb_fmi::import::log::LogSink;
use tb_fmi::{CallStatus, FmiFunction, FmuError, Function};

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
        status.ok().map_err(|s| {
            let (function, status) = (FmiFunction::Fmi2(function), CallStatus::Fmi2(s));
            FmuError::call(
                &self.name,
                function,
                status,
                self.time,
                self.sink.last_lines(),
            )
        })
    }

    /// Integers or Booleans (`ty`) read as i32, as the FFI layer reads them.
    fn get_int(
        &mut self,
        function: Function,
        ty: ScalarType,
        vrs: &[u32],
        out: &mut [i32],
    ) -> Result<(), FmuError> {
        self.call(function, |rt| {
            rt.get(function.name(), ty, vrs, out, |v| v.as_f64() as i32)
        })
    }
}

/// The typed sets of [`Backend`], each value made a [`Value`] by `$value` and set as the FFI
/// layer sets it.
macro_rules! typed_sets {
    ($($(#[$a:meta])* $set:ident($t:ty) $function:ident, $ty:ident, $value:expr;)*) => {$(
        $(#[$a])*
        fn $set(&mut self, vrs: &[u32], values: &[$t]) -> Result<(), FmuError> {
            self.call(Function::$function, |rt| {
                let values = values.iter().map(|x| $value(*x));
                rt.set(const { Function::$function.name() }, ScalarType::$ty, vrs, values)
            })
        }
    )*};
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
    fn setup_experiment(&mut self, e: tb_fmi::Experiment) -> Result<(), FmuError> {
        // Our models have no internal solver with a tolerance.
        self.time = e.start;
        self.call(Function::SetupExperiment, |rt| {
            rt.setup_experiment(e.start, e.stop)
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
    typed_sets! {
        #[inline] set_real(f64) SetReal, Real, Value::Real;
        set_integer(i32) SetInteger, Integer, Value::Integer;
        set_boolean(i32) SetBoolean, Boolean, |x: i32| Value::Boolean(x != 0);
    }
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.get_int(Function::GetInteger, ScalarType::Integer, vrs, out)
    }
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.get_int(Function::GetBoolean, ScalarType::Boolean, vrs, out)
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

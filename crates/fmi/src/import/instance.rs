//! A safe handle on one FMU instance: every call checked, errors carry the instance name,
//! the simulation time and the FMU's last log lines.

use super::library::Library;
use super::log::{fmi2_logger, log_env, LogEnv, LogSink};
use crate::fmi2::*;
use crate::functions::Function;
use crate::status::{CallStatus, FmiFunction};
use crate::{Experiment, FmuError, FmuInstance};
use std::ffi::{c_void, CString};
use std::path::Path;
use std::sync::Arc;

extern "C" {
    fn calloc(n: usize, size: usize) -> *mut c_void;
    fn free(p: *mut c_void);
}

unsafe extern "C" fn allocate_memory(n: usize, size: usize) -> *mut c_void {
    calloc(n, size)
}
unsafe extern "C" fn free_memory(p: *mut c_void) {
    free(p)
}

/// `file://` URI of a folder, percent-encoded (FMI 2.0 fmuResourceLocation).
pub fn file_uri(path: &Path) -> String {
    let mut s = String::from("file://");
    for b in path.to_string_lossy().bytes() {
        if b.is_ascii_alphanumeric() || b"/-._~".contains(&b) {
            s.push(b as char);
        } else {
            s.push_str(&format!("%{b:02X}"));
        }
    }
    if !s.ends_with('/') {
        s.push('/');
    }
    s
}

/// An opaque saved FMU state; free it with [`Instance::free_state`].
pub struct FmuState(fmi2FMUstate);

unsafe impl Send for FmuState {}

pub struct Instance {
    lib: Arc<Library>,
    comp: fmi2Component,
    pub name: String,
    /// Simulation time of the last successful step (for error messages).
    pub time: f64,
    sink: Box<LogSink>,
    // The FMU may keep pointers to these until fmi2FreeInstance.
    _env: Box<LogEnv>,
    _callbacks: Box<fmi2CallbackFunctions>,
}

// One instance is used by one thread at a time; FMI 2.0 allows moving it between threads.
unsafe impl Send for Instance {}

impl Instance {
    /// A Co-Simulation instance.
    pub fn instantiate(
        lib: Arc<Library>,
        name: &str,
        guid: &str,
        resource_dir: Option<&Path>,
        logging_on: bool,
    ) -> Result<Instance, FmuError> {
        Self::instantiate_as(
            lib,
            name,
            guid,
            resource_dir,
            logging_on,
            fmi2Type::CO_SIMULATION,
        )
    }

    /// An instance of `kind` (Model Exchange instances are driven by
    /// [`crate::import::model_exchange::MeInstance`]).
    pub fn instantiate_as(
        lib: Arc<Library>,
        name: &str,
        guid: &str,
        resource_dir: Option<&Path>,
        logging_on: bool,
        kind: fmi2Type,
    ) -> Result<Instance, FmuError> {
        let sink = Box::new(LogSink::new(name));
        let env = log_env(&sink);
        let callbacks = Box::new(fmi2CallbackFunctions {
            logger: Some(fmi2_logger()),
            allocateMemory: Some(allocate_memory),
            freeMemory: Some(free_memory),
            stepFinished: None,
            componentEnvironment: &*env as *const LogEnv as *mut c_void,
        });
        let c_name = CString::new(name).map_err(|_| FmuError::Instantiate {
            instance: name.into(),
            message: "instance name contains a NUL byte".into(),
        })?;
        let c_guid = CString::new(guid).unwrap_or_default();
        let c_res = resource_dir.map(|d| CString::new(file_uri(d)).unwrap_or_default());
        let comp = unsafe {
            (lib.api.fmi2Instantiate)(
                c_name.as_ptr(),
                kind,
                c_guid.as_ptr(),
                c_res.as_ref().map_or(std::ptr::null(), |c| c.as_ptr()),
                &*callbacks,
                fmi2False,
                if logging_on { fmi2True } else { fmi2False },
            )
        };
        if comp.is_null() {
            return Err(FmuError::Instantiate {
                instance: name.into(),
                message: format!(
                    "fmi2Instantiate returned NULL; the FMU's log: {}",
                    sink.last_lines().join(" | ")
                ),
            });
        }
        Ok(Instance {
            lib,
            comp,
            name: name.to_string(),
            time: 0.0,
            sink,
            _env: env,
            _callbacks: callbacks,
        })
    }

    /// The raw component (for tests of FFI edge cases).
    pub fn raw(&self) -> fmi2Component {
        self.comp
    }

    pub fn library(&self) -> &Arc<Library> {
        &self.lib
    }

    #[inline]
    fn check(&self, function: Function, status: fmi2Status) -> Result<(), FmuError> {
        match status.ok() {
            Ok(()) => Ok(()),
            Err(s) => Err(self.call_error(function, s)),
        }
    }

    /// The FMU writes or reads as many values as references: a shorter slice would let it
    /// past its end, so a difference is refused.
    #[cold]
    fn lengths(&self, function: Function, references: usize, values: usize) -> FmuError {
        FmuError::Lengths {
            instance: self.name.clone(),
            function,
            references,
            values,
        }
    }

    /// `fmi2Get<Type>` or `fmi2Set<Type>` with `count` values at `values`, one a reference:
    /// the lengths are checked before the FMU writes or reads.
    #[inline]
    fn values<P>(
        &self,
        call: fmi2ValuesTYPE<P>,
        function: Function,
        vrs: &[u32],
        count: usize,
        values: P,
    ) -> Result<(), FmuError> {
        if vrs.len() != count {
            return Err(self.lengths(function, vrs.len(), count));
        }
        // SAFETY: the component is live and `values` points at one value per reference.
        let s = unsafe { call(self.comp, vrs.as_ptr(), vrs.len(), values) };
        self.check(function, s)
    }

    #[cold]
    fn call_error(&self, function: Function, status: fmi2Status) -> FmuError {
        FmuError::call(
            &self.name,
            FmiFunction::Fmi2(function),
            CallStatus::Fmi2(status),
            self.time,
            self.sink.last_lines(),
        )
    }

    /// The instance's log sink (kept lines, echo switch).
    pub fn sink(&self) -> &LogSink {
        &self.sink
    }

    /// `fmi2SetDebugLogging` for the given categories (none: all of them).
    pub fn set_debug_categories(&mut self, on: bool, categories: &[&str]) -> Result<(), FmuError> {
        let c: Vec<CString> = categories
            .iter()
            .map(|s| CString::new(*s).unwrap_or_default())
            .collect();
        let p: Vec<fmi2String> = c.iter().map(|s| s.as_ptr()).collect();
        let s = unsafe {
            (self.lib.api.fmi2SetDebugLogging)(self.comp, on as fmi2Boolean, p.len(), p.as_ptr())
        };
        self.check(Function::SetDebugLogging, s)
    }

    fn unsupported(&self, function: Function) -> FmuError {
        FmuError::Unsupported {
            instance: self.name.clone(),
            what: function.name(),
        }
    }

    /// An optional function of the FMU (the state functions), or the error that it has none.
    fn optional<F>(&self, f: Option<F>, function: Function) -> Result<F, FmuError> {
        f.ok_or_else(|| self.unsupported(function))
    }

    /// A call of the component alone (`fmi2EnterInitializationMode`, `fmi2Terminate`, …).
    fn call(
        &mut self,
        f: unsafe extern "C" fn(fmi2Component) -> fmi2Status,
        function: Function,
    ) -> Result<(), FmuError> {
        let s = unsafe { f(self.comp) };
        self.check(function, s)
    }

    pub fn get_state(&mut self) -> Result<FmuState, FmuError> {
        let f = self.optional(self.lib.api.fmi2GetFMUstate, Function::GetFMUstate)?;
        let mut st: fmi2FMUstate = std::ptr::null_mut();
        let s = unsafe { f(self.comp, &mut st) };
        self.check(Function::GetFMUstate, s)?;
        Ok(FmuState(st))
    }

    /// Save into an existing state (reuses its memory).
    pub fn update_state(&mut self, state: &mut FmuState) -> Result<(), FmuError> {
        let f = self.optional(self.lib.api.fmi2GetFMUstate, Function::GetFMUstate)?;
        let s = unsafe { f(self.comp, &mut state.0) };
        self.check(Function::GetFMUstate, s)
    }

    pub fn set_state(&mut self, state: &FmuState, time: f64) -> Result<(), FmuError> {
        let f = self.optional(self.lib.api.fmi2SetFMUstate, Function::SetFMUstate)?;
        let s = unsafe { f(self.comp, state.0) };
        self.time = time;
        self.check(Function::SetFMUstate, s)
    }

    pub fn free_state(&mut self, mut state: FmuState) -> Result<(), FmuError> {
        let f = self.optional(self.lib.api.fmi2FreeFMUstate, Function::FreeFMUstate)?;
        let s = unsafe { f(self.comp, &mut state.0) };
        self.check(Function::FreeFMUstate, s)
    }

    pub fn serialize_state(&mut self, state: &FmuState) -> Result<Vec<u8>, FmuError> {
        let size_f = self
            .lib
            .api
            .fmi2SerializedFMUstateSize
            .ok_or_else(|| self.unsupported(Function::SerializedFMUstateSize))?;
        let ser = self
            .lib
            .api
            .fmi2SerializeFMUstate
            .ok_or_else(|| self.unsupported(Function::SerializeFMUstate))?;
        let mut n = 0usize;
        let s = unsafe { size_f(self.comp, state.0, &mut n) };
        self.check(Function::SerializedFMUstateSize, s)?;
        let mut buf = vec![0u8; n];
        let s = unsafe { ser(self.comp, state.0, buf.as_mut_ptr() as *mut fmi2Byte, n) };
        self.check(Function::SerializeFMUstate, s)?;
        Ok(buf)
    }

    pub fn deserialize_state(&mut self, bytes: &[u8]) -> Result<FmuState, FmuError> {
        let f = self.optional(
            self.lib.api.fmi2DeSerializeFMUstate,
            Function::DeSerializeFMUstate,
        )?;
        let mut st: fmi2FMUstate = std::ptr::null_mut();
        let s = unsafe {
            f(
                self.comp,
                bytes.as_ptr() as *const fmi2Byte,
                bytes.len(),
                &mut st,
            )
        };
        self.check(Function::DeSerializeFMUstate, s)?;
        Ok(FmuState(st))
    }
}

/// The typed get and set of [`FmuInstance`] for Real, Integer and Boolean: the whole list
/// in one `fmi2Get…`/`fmi2Set…` call (with its attributes, e.g. `#[inline]`).
macro_rules! typed_values {
    ($($(#[$a:meta])* $get:ident, $set:ident, $t:ty, $fget:ident, $fset:ident, $g:ident, $s:ident;)*) => {$(
        $(#[$a])*
        fn $get(&mut self, vrs: &[u32], out: &mut [$t]) -> Result<(), FmuError> {
            let (n, p) = (out.len(), out.as_mut_ptr());
            self.values(self.lib.api.$fget, Function::$g, vrs, n, p)
        }

        $(#[$a])*
        fn $set(&mut self, vrs: &[u32], values: &[$t]) -> Result<(), FmuError> {
            let (n, p) = (values.len(), values.as_ptr());
            self.values(self.lib.api.$fset, Function::$s, vrs, n, p)
        }
    )*};
}

impl FmuInstance for Instance {
    fn name(&self) -> &str {
        &self.name
    }

    fn time(&self) -> f64 {
        self.time
    }

    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        self.set_debug_categories(on, &[])
    }

    fn last_log_lines(&self) -> Vec<String> {
        self.sink.last_lines()
    }

    /// Stop echoing OK-status messages to the `log` crate (they are still kept).
    fn set_echo(&mut self, on: bool) {
        self.sink.set_echo(on);
    }

    /// `fmi2SetupExperiment`; `tolerance` Some: `toleranceDefined = fmi2True` with it.
    fn setup_experiment(&mut self, e: Experiment) -> Result<(), FmuError> {
        self.time = e.start;
        let s = unsafe {
            (self.lib.api.fmi2SetupExperiment)(
                self.comp,
                e.tolerance.is_some() as fmi2Boolean,
                e.tolerance.unwrap_or(0.0),
                e.start,
                e.stop.is_some() as fmi2Boolean,
                e.stop.unwrap_or(0.0),
            )
        };
        self.check(Function::SetupExperiment, s)
    }

    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.call(
            self.lib.api.fmi2EnterInitializationMode,
            Function::EnterInitializationMode,
        )
    }

    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.call(
            self.lib.api.fmi2ExitInitializationMode,
            Function::ExitInitializationMode,
        )
    }

    fn terminate(&mut self) -> Result<(), FmuError> {
        self.call(self.lib.api.fmi2Terminate, Function::Terminate)
    }

    fn reset(&mut self) -> Result<(), FmuError> {
        let s = unsafe { (self.lib.api.fmi2Reset)(self.comp) };
        self.sink.clear();
        self.time = 0.0;
        self.check(Function::Reset, s)
    }

    typed_values! {
        #[inline] get_real, set_real, f64, fmi2GetReal, fmi2SetReal, GetReal, SetReal;
        get_integer, set_integer, i32, fmi2GetInteger, fmi2SetInteger, GetInteger, SetInteger;
        get_boolean, set_boolean, i32, fmi2GetBoolean, fmi2SetBoolean, GetBoolean, SetBoolean;
    }

    /// Read String variables into `out` (one per value reference). The FMU's strings are
    /// copied at once: the standard keeps them valid only until the next call.
    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        let mut ptrs: Vec<fmi2String> = vec![std::ptr::null(); vrs.len()];
        let s = unsafe {
            (self.lib.api.fmi2GetString)(self.comp, vrs.as_ptr(), vrs.len(), ptrs.as_mut_ptr())
        };
        self.check(Function::GetString, s)?;
        out.clear();
        for (p, vr) in ptrs.into_iter().zip(vrs) {
            // SAFETY: the FMU keeps its strings valid until its next call.
            out.push(unsafe { super::string_from_fmu(p, &self.name, "fmi2GetString", *vr) }?);
        }
        Ok(())
    }

    /// Set String variables (a NUL inside a value is refused).
    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        if vrs.len() != values.len() {
            return Err(self.lengths(Function::SetString, vrs.len(), values.len()));
        }
        let c: Vec<CString> = values
            .iter()
            .map(|v| CString::new(*v))
            .collect::<Result<_, _>>()
            .map_err(|_| FmuError::Instantiate {
                instance: self.name.clone(),
                message: "fmi2SetString: a value contains a NUL byte".into(),
            })?;
        let p: Vec<fmi2String> = c.iter().map(|s| s.as_ptr()).collect();
        let s =
            unsafe { (self.lib.api.fmi2SetString)(self.comp, vrs.as_ptr(), vrs.len(), p.as_ptr()) };
        self.check(Function::SetString, s)
    }

    /// One communication step; on success the instance's time advances.
    #[inline]
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        let s = unsafe { (self.lib.api.fmi2DoStep)(self.comp, t, h, fmi2True) };
        if s == fmi2Status::OK {
            self.time = t + h;
            Ok(())
        } else {
            self.time = t;
            self.check(Function::DoStep, s).map(|_| self.time = t + h)
        }
    }

    /// After a step returned `fmi2Discard`: whether the FMU asks to end the simulation
    /// (`fmi2GetBooleanStatus(fmi2Terminated)`), and then its last successful time
    /// (`fmi2GetRealStatus(fmi2LastSuccessfulTime)`, else the step's start). `None` when
    /// it does not ask, or cannot say (the optional functions are missing or fail).
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        let get_bool = self.lib.api.fmi2GetBooleanStatus?;
        let mut terminated: fmi2Boolean = fmi2False;
        let s = unsafe { get_bool(self.comp, fmi2StatusKind::TERMINATED, &mut terminated) };
        if !s.is_ok() || terminated == fmi2False {
            return None;
        }
        let mut last = self.time;
        if let Some(get_real) = self.lib.api.fmi2GetRealStatus {
            let mut t: fmi2Real = self.time;
            let s = unsafe { get_real(self.comp, fmi2StatusKind::LAST_SUCCESSFUL_TIME, &mut t) };
            if s.is_ok() && t.is_finite() {
                last = t;
            }
        }
        self.time = last;
        Some(last)
    }
}

impl Drop for Instance {
    fn drop(&mut self) {
        unsafe { (self.lib.api.fmi2FreeInstance)(self.comp) };
    }
}

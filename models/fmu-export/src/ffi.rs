//! The FMI 2.0 Co-Simulation C entry points, generic over the model. [`export_fmu!`]
//! instantiates them as `#[no_mangle]` symbols in a model's `cdylib`.
//!
//! Every entry point checks its pointers, runs inside `catch_unwind` (a panicking model
//! returns fmi2Error, logs the panic and poisons the instance) and never unwinds into C.
#![allow(clippy::missing_safety_doc, clippy::too_many_arguments)]

use crate::fmi2::*;
use crate::model::Model;
use crate::runtime::{Logger, Runtime, Snapshot};
use crate::variables::{Value, VarType};
use std::ffi::{CStr, CString};
use std::os::raw::c_char;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;

/// Forwards log messages to the host's `fmi2CallbackLogger`.
struct CLogger {
    callback: Option<fmi2CallbackLogger>,
    env: fmi2ComponentEnvironment,
    instance_name: CString,
}

// The host's environment pointer is opaque to us and only handed back to the host.
unsafe impl Send for CLogger {}

/// `message` goes through the host's printf: `%` must be doubled, NULs cannot pass.
fn c_message(message: &str) -> CString {
    CString::new(message.replace('%', "%%").replace('\0', "\\0")).unwrap_or_default()
}

impl Logger for CLogger {
    fn log(&self, status: fmi2Status, category: &str, message: &str) {
        if let Some(cb) = self.callback {
            let cat = CString::new(category).unwrap_or_default();
            let msg = c_message(message);
            unsafe {
                cb(
                    self.env,
                    self.instance_name.as_ptr(),
                    status,
                    cat.as_ptr(),
                    msg.as_ptr(),
                )
            };
        }
    }
}

/// The component handed to the host.
pub struct Instance<M: Model> {
    pub runtime: Runtime<M>,
}

/// The message of a caught panic (for the log and the poisoned instance).
pub fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "non-string panic payload".to_string()
    }
}

/// Run `f` on the instance behind `c`, catching panics.
unsafe fn guarded<M: Model>(
    c: fmi2Component,
    function: &str,
    f: impl FnOnce(&mut Runtime<M>) -> fmi2Status,
) -> fmi2Status {
    if c.is_null() {
        return fmi2Status::ERROR;
    }
    let inst = &mut *(c as *mut Instance<M>);
    match catch_unwind(AssertUnwindSafe(|| f(&mut inst.runtime))) {
        Ok(s) => s,
        Err(payload) => {
            let text = panic_text(&*payload);
            catch_unwind(AssertUnwindSafe(|| inst.runtime.poison(function, &text)))
                .unwrap_or(fmi2Status::ERROR)
        }
    }
}

/// Decode `fmuResourceLocation` (a file URI, percent-encoded) into a folder path.
pub fn resource_dir_from_uri(uri: &str) -> Result<PathBuf, String> {
    let rest = uri
        .strip_prefix("file://localhost/")
        .map(|r| format!("/{r}"))
        .or_else(|| uri.strip_prefix("file:///").map(|r| format!("/{r}")))
        .or_else(|| uri.strip_prefix("file:/").map(|r| format!("/{r}")))
        .ok_or_else(|| format!("fmuResourceLocation '{uri}' is not a file URI"))?;
    let bytes = rest.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' {
            let hex = bytes
                .get(i + 1..i + 3)
                .and_then(|h| std::str::from_utf8(h).ok())
                .and_then(|h| u8::from_str_radix(h, 16).ok())
                .ok_or_else(|| {
                    format!("fmuResourceLocation '{uri}': bad percent escape at byte {i}")
                })?;
            out.push(hex);
            i += 3;
        } else {
            out.push(bytes[i]);
            i += 1;
        }
    }
    let s = String::from_utf8(out)
        .map_err(|_| format!("fmuResourceLocation '{uri}' is not UTF-8 after decoding"))?;
    Ok(PathBuf::from(s))
}

unsafe fn opt_str<'a>(p: *const c_char) -> Option<std::borrow::Cow<'a, str>> {
    (!p.is_null()).then(|| CStr::from_ptr(p).to_string_lossy())
}

pub unsafe fn instantiate<M: Model>(
    instance_name: fmi2String,
    fmu_type: fmi2Type,
    guid: fmi2String,
    resource_location: fmi2String,
    functions: *const fmi2CallbackFunctions,
    _visible: fmi2Boolean,
    logging_on: fmi2Boolean,
) -> fmi2Component {
    // This library's own copy of std: silence its default panic printing (panics are caught
    // and reported through the FMI logger instead). The host's panic hook is not affected.
    static QUIET_PANICS: std::sync::Once = std::sync::Once::new();
    QUIET_PANICS.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let r = catch_unwind(AssertUnwindSafe(|| {
        let callbacks = if functions.is_null() {
            None
        } else {
            Some(*functions)
        };
        let name = opt_str(instance_name).map(|s| s.into_owned());
        let logger = CLogger {
            callback: callbacks.and_then(|f| f.logger),
            env: callbacks.map_or(std::ptr::null_mut(), |f| f.componentEnvironment),
            instance_name: CString::new(name.clone().unwrap_or_default()).unwrap_or_default(),
        };
        let fail = |msg: String| {
            logger.log(
                fmi2Status::ERROR,
                "logStatusError",
                &format!("fmi2Instantiate: {msg}"),
            );
            std::ptr::null_mut()
        };
        let Some(name) = name else {
            return fail("instanceName is NULL".into());
        };
        if callbacks.is_none() {
            return std::ptr::null_mut();
        }
        if fmu_type != fmi2Type::CO_SIMULATION {
            return fail(format!(
                "model '{}' supports Co-Simulation only (fmuType {} requested)",
                M::INFO.name,
                fmu_type.0
            ));
        }
        let expected = crate::description::guid::<M>();
        match opt_str(guid) {
            Some(g) if g == expected => {}
            Some(g) => {
                return fail(format!(
                    "GUID mismatch: the host passed {g}, this binary of '{}' is {expected} (modelDescription.xml and binary differ)",
                    M::INFO.name
                ))
            }
            None => return fail("fmuGUID is NULL".into()),
        }
        let resource_dir = match opt_str(resource_location) {
            None => None,
            Some(uri) if uri.is_empty() => None,
            Some(uri) => match resource_dir_from_uri(&uri) {
                Ok(p) => Some(p),
                Err(e) => return fail(e),
            },
        };
        let runtime = Runtime::<M>::new(&name, resource_dir, Box::new(logger), logging_on != 0);
        Box::into_raw(Box::new(Instance { runtime })) as fmi2Component
    }));
    r.unwrap_or(std::ptr::null_mut())
}

pub unsafe fn free_instance<M: Model>(c: fmi2Component) {
    if !c.is_null() {
        let _ = catch_unwind(AssertUnwindSafe(|| {
            drop(Box::from_raw(c as *mut Instance<M>))
        }));
    }
}

pub unsafe fn set_debug_logging<M: Model>(
    c: fmi2Component,
    on: fmi2Boolean,
    n: usize,
    categories: *const fmi2String,
) -> fmi2Status {
    guarded::<M>(c, "fmi2SetDebugLogging", |rt| {
        if n > 0 && categories.is_null() {
            return rt.error("fmi2SetDebugLogging: categories is NULL");
        }
        let mut names = Vec::with_capacity(n);
        for i in 0..n {
            match opt_str(*categories.add(i)) {
                Some(s) => names.push(s.into_owned()),
                None => return rt.error("fmi2SetDebugLogging: a category is NULL"),
            }
        }
        let refs: Vec<&str> = names.iter().map(String::as_str).collect();
        rt.set_debug_logging(on != 0, &refs)
    })
}

pub unsafe fn setup_experiment<M: Model>(
    c: fmi2Component,
    _tolerance_defined: fmi2Boolean,
    _tolerance: fmi2Real,
    start: fmi2Real,
    stop_defined: fmi2Boolean,
    stop: fmi2Real,
) -> fmi2Status {
    guarded::<M>(c, "fmi2SetupExperiment", |rt| {
        rt.setup_experiment(start, (stop_defined != 0).then_some(stop))
    })
}

pub unsafe fn enter_initialization_mode<M: Model>(c: fmi2Component) -> fmi2Status {
    guarded::<M>(c, "fmi2EnterInitializationMode", |rt| {
        rt.enter_initialization_mode()
    })
}

pub unsafe fn exit_initialization_mode<M: Model>(c: fmi2Component) -> fmi2Status {
    guarded::<M>(c, "fmi2ExitInitializationMode", |rt| {
        rt.exit_initialization_mode()
    })
}

pub unsafe fn terminate<M: Model>(c: fmi2Component) -> fmi2Status {
    guarded::<M>(c, "fmi2Terminate", |rt| rt.terminate())
}

pub unsafe fn reset<M: Model>(c: fmi2Component) -> fmi2Status {
    guarded::<M>(c, "fmi2Reset", |rt| rt.reset())
}

/// Borrow the (vr, value) arrays, NULL-checked (NULL is fine when n is 0).
unsafe fn arrays<'a, T>(
    rt: &Runtime<impl Model>,
    function: &str,
    vr: *const fmi2ValueReference,
    n: usize,
    values: *const T,
) -> Result<(&'a [u32], *const T), fmi2Status> {
    if n == 0 {
        return Ok((&[], values));
    }
    if vr.is_null() || values.is_null() {
        return Err(rt.error(&format!("{function}: NULL array with nvr = {n}")));
    }
    Ok((std::slice::from_raw_parts(vr, n), values))
}

macro_rules! getter {
    ($fn:ident, $cname:literal, $t:ty, $vt:expr, $conv:expr) => {
        pub unsafe fn $fn<M: Model>(
            c: fmi2Component,
            vr: *const fmi2ValueReference,
            n: usize,
            value: *mut $t,
        ) -> fmi2Status {
            guarded::<M>(c, $cname, |rt| {
                let (vrs, ptr) = match arrays(rt, $cname, vr, n, value as *const $t) {
                    Ok(x) => x,
                    Err(s) => return s,
                };
                let out: &mut [$t] = if n == 0 {
                    &mut []
                } else {
                    std::slice::from_raw_parts_mut(ptr as *mut $t, n)
                };
                rt.get($cname, $vt, vrs, out, $conv)
            })
        }
    };
}

macro_rules! setter {
    ($fn:ident, $cname:literal, $t:ty, $vt:expr, $conv:expr) => {
        pub unsafe fn $fn<M: Model>(
            c: fmi2Component,
            vr: *const fmi2ValueReference,
            n: usize,
            value: *const $t,
        ) -> fmi2Status {
            guarded::<M>(c, $cname, |rt| {
                let (vrs, ptr) = match arrays(rt, $cname, vr, n, value) {
                    Ok(x) => x,
                    Err(s) => return s,
                };
                let vals: &[$t] = if n == 0 {
                    &[]
                } else {
                    std::slice::from_raw_parts(ptr, n)
                };
                rt.set($cname, $vt, vrs, vals.iter().map($conv))
            })
        }
    };
}

getter!(
    get_real,
    "fmi2GetReal",
    fmi2Real,
    VarType::Real,
    |v: Value| v.as_f64()
);
getter!(
    get_integer,
    "fmi2GetInteger",
    fmi2Integer,
    VarType::Integer,
    |v: Value| v.as_f64() as i32
);
getter!(
    get_boolean,
    "fmi2GetBoolean",
    fmi2Boolean,
    VarType::Boolean,
    |v: Value| v.as_f64() as i32
);
setter!(
    set_real,
    "fmi2SetReal",
    fmi2Real,
    VarType::Real,
    |x: &f64| Value::Real(*x)
);
setter!(
    set_integer,
    "fmi2SetInteger",
    fmi2Integer,
    VarType::Integer,
    |x: &i32| Value::Integer(*x)
);
setter!(
    set_boolean,
    "fmi2SetBoolean",
    fmi2Boolean,
    VarType::Boolean,
    |x: &i32| Value::Boolean(*x != 0)
);

pub unsafe fn get_string<M: Model>(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    n: usize,
    _value: *mut fmi2String,
) -> fmi2Status {
    guarded::<M>(c, "fmi2GetString", |rt| {
        if n == 0 {
            fmi2Status::OK
        } else {
            rt.error(&format!(
                "fmi2GetString: model '{}' has no String variables",
                M::INFO.name
            ))
        }
    })
}

pub unsafe fn set_string<M: Model>(
    c: fmi2Component,
    _vr: *const fmi2ValueReference,
    n: usize,
    _value: *const fmi2String,
) -> fmi2Status {
    guarded::<M>(c, "fmi2SetString", |rt| {
        if n == 0 {
            fmi2Status::OK
        } else {
            rt.error(&format!(
                "fmi2SetString: model '{}' has no String variables",
                M::INFO.name
            ))
        }
    })
}

pub unsafe fn get_fmu_state<M: Model>(c: fmi2Component, state: *mut fmi2FMUstate) -> fmi2Status {
    guarded::<M>(c, "fmi2GetFMUstate", |rt| {
        if state.is_null() {
            return rt.error("fmi2GetFMUstate: FMUstate pointer is NULL");
        }
        if (*state).is_null() {
            match rt.snapshot() {
                Ok(s) => {
                    *state = Box::into_raw(Box::new(s)) as fmi2FMUstate;
                    fmi2Status::OK
                }
                Err(s) => s,
            }
        } else {
            rt.snapshot_into(&mut *(*state as *mut Snapshot<M>))
        }
    })
}

pub unsafe fn set_fmu_state<M: Model>(c: fmi2Component, state: fmi2FMUstate) -> fmi2Status {
    guarded::<M>(c, "fmi2SetFMUstate", |rt| {
        if state.is_null() {
            return rt.error("fmi2SetFMUstate: FMUstate is NULL");
        }
        rt.restore(&*(state as *const Snapshot<M>))
    })
}

pub unsafe fn free_fmu_state<M: Model>(c: fmi2Component, state: *mut fmi2FMUstate) -> fmi2Status {
    guarded::<M>(c, "fmi2FreeFMUstate", |_rt| {
        if !state.is_null() && !(*state).is_null() {
            drop(Box::from_raw(*state as *mut Snapshot<M>));
            *state = std::ptr::null_mut();
        }
        fmi2Status::OK
    })
}

pub unsafe fn serialized_fmu_state_size<M: Model>(
    c: fmi2Component,
    state: fmi2FMUstate,
    size: *mut usize,
) -> fmi2Status {
    guarded::<M>(c, "fmi2SerializedFMUstateSize", |rt| {
        if state.is_null() || size.is_null() {
            return rt.error("fmi2SerializedFMUstateSize: NULL argument");
        }
        *size = rt.serialize(&*(state as *const Snapshot<M>)).len();
        fmi2Status::OK
    })
}

pub unsafe fn serialize_fmu_state<M: Model>(
    c: fmi2Component,
    state: fmi2FMUstate,
    bytes: *mut fmi2Byte,
    size: usize,
) -> fmi2Status {
    guarded::<M>(c, "fmi2SerializeFMUstate", |rt| {
        if state.is_null() || bytes.is_null() {
            return rt.error("fmi2SerializeFMUstate: NULL argument");
        }
        let data = rt.serialize(&*(state as *const Snapshot<M>));
        if data.len() > size {
            return rt.error(&format!(
                "fmi2SerializeFMUstate: buffer of {size} bytes, the state needs {}",
                data.len()
            ));
        }
        std::ptr::copy_nonoverlapping(data.as_ptr(), bytes as *mut u8, data.len());
        fmi2Status::OK
    })
}

pub unsafe fn deserialize_fmu_state<M: Model>(
    c: fmi2Component,
    bytes: *const fmi2Byte,
    size: usize,
    state: *mut fmi2FMUstate,
) -> fmi2Status {
    guarded::<M>(c, "fmi2DeSerializeFMUstate", |rt| {
        if bytes.is_null() || state.is_null() {
            return rt.error("fmi2DeSerializeFMUstate: NULL argument");
        }
        let data = std::slice::from_raw_parts(bytes as *const u8, size);
        match rt.deserialize(data) {
            Ok(snap) => {
                if (*state).is_null() {
                    *state = Box::into_raw(Box::new(snap)) as fmi2FMUstate;
                } else {
                    *(*state as *mut Snapshot<M>) = snap;
                }
                fmi2Status::OK
            }
            Err(s) => s,
        }
    })
}

pub unsafe fn unsupported<M: Model>(c: fmi2Component, function: &str, why: &str) -> fmi2Status {
    guarded::<M>(c, function, |rt| rt.error(&format!("{function}: {why}")))
}

pub unsafe fn do_step<M: Model>(
    c: fmi2Component,
    current: fmi2Real,
    step: fmi2Real,
    _no_prior: fmi2Boolean,
) -> fmi2Status {
    guarded::<M>(c, "fmi2DoStep", |rt| rt.do_step(current, step))
}

pub unsafe fn get_real_status<M: Model>(
    c: fmi2Component,
    kind: fmi2StatusKind,
    value: *mut fmi2Real,
) -> fmi2Status {
    guarded::<M>(c, "fmi2GetRealStatus", |rt| {
        if value.is_null() {
            return rt.error("fmi2GetRealStatus: value is NULL");
        }
        if kind == fmi2StatusKind::LAST_SUCCESSFUL_TIME {
            *value = rt.last_successful_time();
            fmi2Status::OK
        } else {
            rt.error(&format!(
                "fmi2GetRealStatus: status kind {} not provided",
                kind.0
            ))
        }
    })
}

pub unsafe fn get_boolean_status<M: Model>(
    c: fmi2Component,
    kind: fmi2StatusKind,
    value: *mut fmi2Boolean,
) -> fmi2Status {
    guarded::<M>(c, "fmi2GetBooleanStatus", |rt| {
        if value.is_null() {
            return rt.error("fmi2GetBooleanStatus: value is NULL");
        }
        if kind == fmi2StatusKind::TERMINATED {
            *value = fmi2False;
            fmi2Status::OK
        } else {
            rt.error(&format!(
                "fmi2GetBooleanStatus: status kind {} not provided",
                kind.0
            ))
        }
    })
}

pub const TYPES_PLATFORM: &CStr = c"default";
pub const VERSION: &CStr = c"2.0";

/// Export a model as an FMI 2.0 Co-Simulation FMU: defines every `fmi2*` C symbol.
/// Use once per `cdylib`, behind the model crate's `fmu` feature.
#[macro_export]
macro_rules! export_fmu {
    ($model:ty) => {
        #[allow(non_snake_case, clippy::missing_safety_doc)]
        mod __fmi2_exports {
            use super::*;
            use $crate::ffi;
            use $crate::fmi2::*;
            type M = $model;

            #[no_mangle]
            pub extern "C" fn fmi2GetTypesPlatform() -> *const ::std::os::raw::c_char {
                ffi::TYPES_PLATFORM.as_ptr()
            }
            #[no_mangle]
            pub extern "C" fn fmi2GetVersion() -> *const ::std::os::raw::c_char {
                ffi::VERSION.as_ptr()
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SetDebugLogging(
                c: fmi2Component,
                on: fmi2Boolean,
                n: usize,
                cat: *const fmi2String,
            ) -> fmi2Status {
                ffi::set_debug_logging::<M>(c, on, n, cat)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2Instantiate(
                name: fmi2String,
                ty: fmi2Type,
                guid: fmi2String,
                res: fmi2String,
                f: *const fmi2CallbackFunctions,
                visible: fmi2Boolean,
                log: fmi2Boolean,
            ) -> fmi2Component {
                ffi::instantiate::<M>(name, ty, guid, res, f, visible, log)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2FreeInstance(c: fmi2Component) {
                ffi::free_instance::<M>(c)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SetupExperiment(
                c: fmi2Component,
                td: fmi2Boolean,
                tol: fmi2Real,
                start: fmi2Real,
                sd: fmi2Boolean,
                stop: fmi2Real,
            ) -> fmi2Status {
                ffi::setup_experiment::<M>(c, td, tol, start, sd, stop)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2EnterInitializationMode(c: fmi2Component) -> fmi2Status {
                ffi::enter_initialization_mode::<M>(c)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2ExitInitializationMode(c: fmi2Component) -> fmi2Status {
                ffi::exit_initialization_mode::<M>(c)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2Terminate(c: fmi2Component) -> fmi2Status {
                ffi::terminate::<M>(c)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2Reset(c: fmi2Component) -> fmi2Status {
                ffi::reset::<M>(c)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetReal(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                n: usize,
                v: *mut fmi2Real,
            ) -> fmi2Status {
                ffi::get_real::<M>(c, vr, n, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetInteger(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                n: usize,
                v: *mut fmi2Integer,
            ) -> fmi2Status {
                ffi::get_integer::<M>(c, vr, n, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetBoolean(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                n: usize,
                v: *mut fmi2Boolean,
            ) -> fmi2Status {
                ffi::get_boolean::<M>(c, vr, n, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetString(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                n: usize,
                v: *mut fmi2String,
            ) -> fmi2Status {
                ffi::get_string::<M>(c, vr, n, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SetReal(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                n: usize,
                v: *const fmi2Real,
            ) -> fmi2Status {
                ffi::set_real::<M>(c, vr, n, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SetInteger(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                n: usize,
                v: *const fmi2Integer,
            ) -> fmi2Status {
                ffi::set_integer::<M>(c, vr, n, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SetBoolean(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                n: usize,
                v: *const fmi2Boolean,
            ) -> fmi2Status {
                ffi::set_boolean::<M>(c, vr, n, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SetString(
                c: fmi2Component,
                vr: *const fmi2ValueReference,
                n: usize,
                v: *const fmi2String,
            ) -> fmi2Status {
                ffi::set_string::<M>(c, vr, n, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetFMUstate(
                c: fmi2Component,
                s: *mut fmi2FMUstate,
            ) -> fmi2Status {
                ffi::get_fmu_state::<M>(c, s)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SetFMUstate(
                c: fmi2Component,
                s: fmi2FMUstate,
            ) -> fmi2Status {
                ffi::set_fmu_state::<M>(c, s)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2FreeFMUstate(
                c: fmi2Component,
                s: *mut fmi2FMUstate,
            ) -> fmi2Status {
                ffi::free_fmu_state::<M>(c, s)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SerializedFMUstateSize(
                c: fmi2Component,
                s: fmi2FMUstate,
                size: *mut usize,
            ) -> fmi2Status {
                ffi::serialized_fmu_state_size::<M>(c, s, size)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SerializeFMUstate(
                c: fmi2Component,
                s: fmi2FMUstate,
                b: *mut fmi2Byte,
                size: usize,
            ) -> fmi2Status {
                ffi::serialize_fmu_state::<M>(c, s, b, size)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2DeSerializeFMUstate(
                c: fmi2Component,
                b: *const fmi2Byte,
                size: usize,
                s: *mut fmi2FMUstate,
            ) -> fmi2Status {
                ffi::deserialize_fmu_state::<M>(c, b, size, s)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetDirectionalDerivative(
                c: fmi2Component,
                _u: *const fmi2ValueReference,
                _nu: usize,
                _z: *const fmi2ValueReference,
                _nz: usize,
                _dv: *const fmi2Real,
                _dz: *mut fmi2Real,
            ) -> fmi2Status {
                ffi::unsupported::<M>(
                    c,
                    "fmi2GetDirectionalDerivative",
                    "not provided (providesDirectionalDerivative=false)",
                )
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2SetRealInputDerivatives(
                c: fmi2Component,
                _vr: *const fmi2ValueReference,
                _n: usize,
                _o: *const fmi2Integer,
                _v: *const fmi2Real,
            ) -> fmi2Status {
                ffi::unsupported::<M>(
                    c,
                    "fmi2SetRealInputDerivatives",
                    "not provided (canInterpolateInputs=false)",
                )
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetRealOutputDerivatives(
                c: fmi2Component,
                _vr: *const fmi2ValueReference,
                _n: usize,
                _o: *const fmi2Integer,
                _v: *mut fmi2Real,
            ) -> fmi2Status {
                ffi::unsupported::<M>(
                    c,
                    "fmi2GetRealOutputDerivatives",
                    "not provided (maxOutputDerivativeOrder=0)",
                )
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2DoStep(
                c: fmi2Component,
                t: fmi2Real,
                h: fmi2Real,
                np: fmi2Boolean,
            ) -> fmi2Status {
                ffi::do_step::<M>(c, t, h, np)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2CancelStep(c: fmi2Component) -> fmi2Status {
                ffi::unsupported::<M>(
                    c,
                    "fmi2CancelStep",
                    "steps are synchronous (canRunAsynchronuously=false)",
                )
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetStatus(
                c: fmi2Component,
                _k: fmi2StatusKind,
                _v: *mut fmi2Status,
            ) -> fmi2Status {
                ffi::unsupported::<M>(
                    c,
                    "fmi2GetStatus",
                    "steps are synchronous, there is no pending status",
                )
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetRealStatus(
                c: fmi2Component,
                k: fmi2StatusKind,
                v: *mut fmi2Real,
            ) -> fmi2Status {
                ffi::get_real_status::<M>(c, k, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetIntegerStatus(
                c: fmi2Component,
                _k: fmi2StatusKind,
                _v: *mut fmi2Integer,
            ) -> fmi2Status {
                ffi::unsupported::<M>(c, "fmi2GetIntegerStatus", "no integer status is provided")
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetBooleanStatus(
                c: fmi2Component,
                k: fmi2StatusKind,
                v: *mut fmi2Boolean,
            ) -> fmi2Status {
                ffi::get_boolean_status::<M>(c, k, v)
            }
            #[no_mangle]
            pub unsafe extern "C" fn fmi2GetStringStatus(
                c: fmi2Component,
                _k: fmi2StatusKind,
                _v: *mut fmi2String,
            ) -> fmi2Status {
                ffi::unsupported::<M>(c, "fmi2GetStringStatus", "no string status is provided")
            }
        }
    };
}

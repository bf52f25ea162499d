//! The FMI 3.0 Co-Simulation C entry points, generic over the model, on the same
//! [`Runtime`] (state machine, checks, states) as FMI 2.0's: one model, two FMUs that
//! behave the same. [`export_fmu!`](crate::export_fmu) defines them as `fmi3*` symbols
//! beside the `fmi2*` ones in a model's `cdylib`.
//!
//! What differs from FMI 2.0: the instance is made by `fmi3InstantiateCoSimulation` with a
//! resource *path* and a logger that takes plain text; `fmi3EnterInitializationMode`
//! carries the experiment; Reals are `Float64`, Integers `Int32`, an Enumeration `Int64`, a
//! Boolean a one-byte `bool`; every get and set says how many values it passes; the
//! independent variable `time` has a value reference of its own
//! ([`crate::description3::time_value_reference`]); `fmi3DoStep` reports through flags.
//! Event mode, clocks, Model Exchange, Scheduled Execution, derivatives and the
//! configuration mode are not provided (`hasEventMode="false"`, …): each of those calls
//! answers `fmi3Error` naming what is missing. Messages name the FMI 3.0 functions.
#![allow(clippy::missing_safety_doc, clippy::too_many_arguments)]

pub mod export;
pub mod types;

pub use types::*;

use crate::ffi::{guarded, guarded_instance, opt_str, values_at, values_at_mut, Instance};
use crate::fmi2::fmi2Status;
use crate::model::Model;
use crate::runtime::{Logger, Runtime};
use crate::variables::{ScalarType, Value};
use std::ffi::{c_char, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

pub const VERSION: &CStr = c"3.0";

/// The runtime's messages name FMI 2.0's functions; an FMI 3.0 host is told FMI 3.0's.
pub fn fmi3_names(message: &str) -> String {
    const NAMES: [(&str, &str); 10] = [
        ("fmi2GetReal", "fmi3GetFloat64"),
        ("fmi2SetReal", "fmi3SetFloat64"),
        ("fmi2GetInteger", "fmi3GetInt32"),
        ("fmi2SetInteger", "fmi3SetInt32"),
        ("fmi2SetupExperiment", "fmi3EnterInitializationMode"),
        ("fmi2Instantiate", "fmi3InstantiateCoSimulation"),
        ("fmi2GetFMUstate", "fmi3GetFMUState"),
        ("fmi2SetFMUstate", "fmi3SetFMUState"),
        ("fmi2FreeFMUstate", "fmi3FreeFMUState"),
        ("fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"),
    ];
    if !message.contains("fmi2") {
        return message.to_string();
    }
    let mut m = message.to_string();
    for (two, three) in NAMES {
        m = m.replace(two, three);
    }
    m.replace("fmi2", "fmi3")
}

/// Forwards log messages to the host's `fmi3LogMessageCallback` (none: not logged).
struct CLogger3 {
    callback: Option<fmi3LogMessageCallback>,
    env: *mut c_void,
}

// The host's environment pointer is opaque to us and only handed back to the host.
unsafe impl Send for CLogger3 {}

impl Logger for CLogger3 {
    fn log(&self, status: fmi2Status, category: &str, message: &str) {
        if let Some(cb) = self.callback {
            let cat = CString::new(category).unwrap_or_default();
            let msg = CString::new(fmi3_names(message).replace('\0', "\\0")).unwrap_or_default();
            unsafe { cb(self.env, status.0, cat.as_ptr(), msg.as_ptr()) };
        }
    }
}

/// A Runtime call's status as FMI 3.0's: the same numbers (the runtime never answers
/// FMI 2.0's Pending, which FMI 3.0 lacks).
#[inline(always)]
fn status(s: fmi2Status) -> fmi3Status {
    debug_assert!(s.0 <= 4, "the runtime answered {s:?}");
    s.0
}

#[allow(clippy::too_many_arguments)]
pub unsafe fn instantiate_co_simulation<M: Model>(
    instance_name: *const c_char,
    token: *const c_char,
    resource_path: *const c_char,
    _visible: bool,
    logging_on: bool,
    event_mode_used: bool,
    _early_return_allowed: bool,
    _required_intermediate: *const fmi3ValueReference,
    n_required_intermediate: usize,
    env: *mut c_void,
    log_message: Option<fmi3LogMessageCallback>,
    _intermediate_update: *const c_void,
) -> fmi3Instance {
    static QUIET_PANICS: std::sync::Once = std::sync::Once::new();
    QUIET_PANICS.call_once(|| std::panic::set_hook(Box::new(|_| {})));
    let r = catch_unwind(AssertUnwindSafe(|| {
        let logger = CLogger3 {
            callback: log_message,
            env,
        };
        let fail = |msg: String| crate::ffi::refused(&logger, "fmi3InstantiateCoSimulation", &msg);
        let Some(name) = opt_str(instance_name).map(|s| s.into_owned()) else {
            return fail("instanceName is NULL".into());
        };
        // The standard lets an FMU without event mode refuse a host that wants it.
        if event_mode_used {
            return fail(format!(
                "model '{}' has no event mode (hasEventMode=\"false\"): instantiate it with eventModeUsed = false",
                M::INFO.name
            ));
        }
        if n_required_intermediate > 0 {
            return fail(format!(
                "model '{}' provides no intermediate update (providesIntermediateUpdate=\"false\"): {n_required_intermediate} required intermediate variables cannot be served",
                M::INFO.name
            ));
        }
        // FMI 3.0 hands a path (with a trailing separator), not a URI.
        let resource_dir = opt_str(resource_path)
            .filter(|p| !p.is_empty())
            .map(|p| std::path::PathBuf::from(p.into_owned()));
        // A fitted twin's start values, and the token its description has.
        let expected = crate::description3::instantiation_token::<M>();
        let dir = resource_dir.as_deref();
        let what = ("instantiationToken", "instantiationToken");
        let fitted = match crate::ffi::fitted_starts::<M>(dir, opt_str(token), &expected, what) {
            Ok(f) => f,
            Err(refusal) => return fail(refusal.to_string()),
        };
        let kept = match logger.callback {
            Some(f) => crate::ffi::handles::SlotLogger::Fmi3(f, logger.env),
            None => crate::ffi::handles::SlotLogger::None,
        };
        let mut runtime = Runtime::<M>::new(&name, resource_dir, Box::new(logger), logging_on);
        if let Some(f) = fitted {
            runtime = runtime.with_fitted(f);
        }
        runtime.expose_time();
        crate::ffi::handle_for(Instance::new(runtime), kept) as fmi3Instance
    }));
    r.unwrap_or(std::ptr::null_mut())
}

/// `fmi3InstantiateModelExchange` and `fmi3InstantiateScheduledExecution`: not provided.
pub unsafe fn instantiate_unsupported<M: Model>(
    kind: &str,
    env: *mut c_void,
    log_message: Option<fmi3LogMessageCallback>,
) -> fmi3Instance {
    let _ = catch_unwind(AssertUnwindSafe(|| {
        CLogger3 {
            callback: log_message,
            env,
        }
        .log(
            fmi2Status::ERROR,
            "logStatusError",
            &format!(
                "fmi3Instantiate{kind}: model '{}' is a Co-Simulation FMU only",
                M::INFO.name
            ),
        )
    }));
    std::ptr::null_mut()
}

pub unsafe fn free_instance<M: Model>(c: fmi3Instance) {
    crate::ffi::free_instance::<M>(c, "fmi3FreeInstance")
}

pub unsafe fn set_debug_logging<M: Model>(
    c: fmi3Instance,
    on: bool,
    n: usize,
    categories: *const *const c_char,
) -> fmi3Status {
    status(crate::ffi::set_debug_logging::<M>(
        c, on as i32, n, categories,
    ))
}

pub unsafe fn enter_initialization_mode<M: Model>(
    c: fmi3Instance,
    _tolerance_defined: bool,
    _tolerance: f64,
    start: f64,
    stop_defined: bool,
    stop: f64,
) -> fmi3Status {
    status(guarded::<M>(c, "fmi3EnterInitializationMode", |rt| {
        let s = rt.setup_experiment(start, stop_defined.then_some(stop));
        if s != fmi2Status::OK {
            return s;
        }
        rt.enter_initialization_mode()
    }))
}

pub unsafe fn exit_initialization_mode<M: Model>(c: fmi3Instance) -> fmi3Status {
    status(crate::ffi::exit_initialization_mode::<M>(c))
}

pub unsafe fn terminate<M: Model>(c: fmi3Instance) -> fmi3Status {
    status(crate::ffi::terminate::<M>(c))
}

pub unsafe fn reset<M: Model>(c: fmi3Instance) -> fmi3Status {
    status(crate::ffi::reset::<M>(c))
}

/// A call FMI 3.0 requires to exist that this FMU does not provide: `fmi3Error` with why.
pub unsafe fn unsupported<M: Model>(c: fmi3Instance, function: &str, why: &str) -> fmi3Status {
    status(guarded::<M>(c, function, |rt| {
        rt.error(&format!("{function}: {why}"))
    }))
}

/// Whether a get's or set's arrays can be used: every variable is a scalar, so
/// `n_values` must equal `n_vr`, and neither may be NULL when there are values. Checked
/// before the guard, so that the usual call costs what FMI 2.0's does.
#[inline(always)]
fn arrays_ok<T>(
    vr: *const fmi3ValueReference,
    n_vr: usize,
    values: *const T,
    n_values: usize,
) -> bool {
    n_values == n_vr && (n_vr == 0 || !(vr.is_null() || values.is_null()))
}

/// The refusal of arrays that cannot be used ([`arrays_ok`]), logged through the guard.
#[cold]
#[inline(never)]
unsafe fn refuse_arrays<M: Model>(
    c: fmi3Instance,
    function: &str,
    n_vr: usize,
    n_values: usize,
) -> fmi3Status {
    status(guarded::<M>(c, function, move |rt| {
        bad_arrays(rt, function, n_vr, n_values)
    }))
}

#[cold]
fn bad_arrays(
    rt: &Runtime<impl Model>,
    function: &str,
    n_vr: usize,
    n_values: usize,
) -> fmi2Status {
    if n_values != n_vr {
        rt.error(&format!(
            "{function}: {n_values} values for {n_vr} value references (every variable of this FMU is a scalar)"
        ))
    } else {
        rt.error(&format!(
            "{function}: NULL array with nValueReferences = {n_vr}"
        ))
    }
}

/// Each of `vrs` is a variable of type `want` (FMI 3.0 tells Int32 from an Enumeration's
/// Int64, which FMI 2.0 both gets as Integer).
#[inline(always)]
fn of_type<M: Model>(
    rt: &Runtime<M>,
    function: &str,
    vrs: &[u32],
    want: ScalarType,
) -> Result<(), fmi2Status> {
    match vrs
        .iter()
        .find(|&&vr| rt.var_info(vr).is_some_and(|v| v.var_type() != want))
    {
        None => Ok(()),
        Some(&vr) => Err(not_of_type(rt, function, vr, want)),
    }
}

#[cold]
fn not_of_type<M: Model>(rt: &Runtime<M>, function: &str, vr: u32, want: ScalarType) -> fmi2Status {
    let v = rt.var_info(vr).expect("found by of_type");
    rt.error(&format!(
        "{function}: variable '{}' (vr {vr}) is {}, not {}",
        v.name,
        super::description3::element_name(v.var_type()),
        super::description3::element_name(want)
    ))
}

/// The typed gets and sets, each `fn name("fmi3Name", values pointer, slice of it) guard
/// |runtime or instance, value references, values| call`: the arrays checked (a refusal
/// names the function), then the call in the guard.
macro_rules! typed_access {
    ($($(#[$a:meta])* fn $name:ident($function:literal, $ptr:ty, $at:ident) $guard:ident
        |$rt:ident, $vrs:ident, $vals:ident| $body:expr;)*) => {$(
        $(#[$a])*
        pub unsafe fn $name<M: Model>(
            c: fmi3Instance,
            vr: *const fmi3ValueReference,
            n_vr: usize,
            values: $ptr,
            n_values: usize,
        ) -> fmi3Status {
            const F: &str = $function;
            if !arrays_ok(vr, n_vr, values, n_values) {
                return refuse_arrays::<M>(c, F, n_vr, n_values);
            }
            let ($vrs, $vals) = (values_at(vr, n_vr), $at(values, n_vr));
            status($guard::<M>(c, F, move |$rt| $body))
        }
    )*};
}

typed_access! {
    // The independent variable `time` is read there too (Runtime::expose_time).
    #[inline(always)]
    fn get_float64("fmi3GetFloat64", *mut f64, values_at_mut) guarded
        |rt, vrs, out| rt.get_real(vrs, out);
    // The independent variable `time` is refused there (Runtime::expose_time).
    #[inline(always)]
    fn set_float64("fmi3SetFloat64", *const f64, values_at) guarded
        |rt, vrs, vals| rt.set_real(vrs, vals);
    fn get_int32("fmi3GetInt32", *mut i32, values_at_mut) guarded
        |rt, vrs, out| get_integers(rt, F, ScalarType::Integer, vrs, out, |v| v.as_f64() as i32);
    fn get_int64("fmi3GetInt64", *mut i64, values_at_mut) guarded
        |rt, vrs, out| get_integers(rt, F, ScalarType::Enumeration, vrs, out, |v| v.as_f64() as i64);
    fn set_int32("fmi3SetInt32", *const i32, values_at) guarded
        |rt, vrs, vals| set_integers(rt, F, ScalarType::Integer, vrs, vals, |x| x);
    // An Int64 outside i32 is no item of any Enumeration here: refused as out of range.
    fn set_int64("fmi3SetInt64", *const i64, values_at) guarded
        |rt, vrs, vals| set_integers(rt, F, ScalarType::Enumeration, vrs, vals, |x| {
            i32::try_from(x).unwrap_or(i32::MIN)
        });
    fn get_boolean("fmi3GetBoolean", *mut u8, values_at_mut) guarded
        |rt, vrs, out| rt.get(F, ScalarType::Boolean, vrs, out, |v| (v.as_f64() != 0.0) as u8);
    fn set_boolean("fmi3SetBoolean", *const u8, values_at) guarded |rt, vrs, vals| {
        let values = vals.iter().map(|x| Value::Boolean(*x != 0));
        rt.set(F, ScalarType::Boolean, vrs, values)
    };
    fn get_string("fmi3GetString", *mut *const c_char, values_at_mut) guarded_instance
        |inst, vrs, out| {
            // The host reads the strings until its next call: kept in the instance.
            let strings = &mut inst.strings;
            strings.clear();
            let s = inst.runtime.get_strings(F, vrs, |_, s| {
                strings.push(CString::new(s.replace('\0', "")).unwrap_or_default())
            });
            if s == fmi2Status::OK {
                for (o, s) in out.iter_mut().zip(strings.iter()) {
                    *o = s.as_ptr();
                }
            }
            s
        };
    fn set_string("fmi3SetString", *const *const c_char, values_at) guarded |rt, vrs, ptrs| {
        let mut texts = Vec::with_capacity(vrs.len());
        for (k, (vr, p)) in vrs.iter().zip(ptrs).enumerate() {
            match opt_str(*p) {
                Some(t) => texts.push(t),
                None => return rt.error(&format!("{F}: value {k} (vr {vr}) is NULL")),
            }
        }
        let refs: Vec<&str> = texts.iter().map(|t| t.as_ref()).collect();
        rt.set_strings(F, vrs, &refs)
    };
}

/// An integer get (`Int32` of Integers, `Int64` of Enumerations) in the guard.
fn get_integers<M: Model, T: Copy>(
    rt: &mut Runtime<M>,
    function: &str,
    want: ScalarType,
    vrs: &[u32],
    out: &mut [T],
    conv: impl Fn(Value) -> T,
) -> fmi2Status {
    if let Err(s) = of_type(rt, function, vrs, want) {
        return s;
    }
    rt.get(function, ScalarType::Integer, vrs, out, conv)
}

/// An integer set (`Int32` of Integers, `Int64` of Enumerations) in the guard, each value
/// converted.
fn set_integers<M: Model, T: Copy>(
    rt: &mut Runtime<M>,
    function: &str,
    want: ScalarType,
    vrs: &[u32],
    vals: &[T],
    conv: impl Fn(T) -> i32,
) -> fmi2Status {
    if let Err(s) = of_type(rt, function, vrs, want) {
        return s;
    }
    let values = vals.iter().map(|x| Value::Integer(conv(*x)));
    rt.set(function, ScalarType::Integer, vrs, values)
}

/// A get or set of a type this FMU has no variable of (Float32, Int8, …, Binary, Clock):
/// nothing to do for no value reference, else an error naming the first.
pub unsafe fn no_variable_of_type<M: Model>(
    c: fmi3Instance,
    function: &str,
    vr: *const fmi3ValueReference,
    n_vr: usize,
) -> fmi3Status {
    status(guarded::<M>(c, function, |rt| {
        if n_vr == 0 {
            return fmi2Status::OK;
        }
        let first = if vr.is_null() { 0 } else { *vr };
        match rt.var_info(first) {
            Some(v) => rt.error(&format!(
                "{function}: variable '{}' (vr {first}) is {}",
                v.name,
                super::description3::element_name(v.var_type())
            )),
            None => rt.error(&format!(
                "{function}: unknown value reference {first} (model '{}' has no variable of this type)",
                M::INFO.name
            )),
        }
    }))
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub unsafe fn do_step<M: Model>(
    c: fmi3Instance,
    current: f64,
    step: f64,
    _no_set_prior: bool,
    event_handling_needed: *mut bool,
    terminate_simulation: *mut bool,
    early_return: *mut bool,
    last_successful_time: *mut f64,
) -> fmi3Status {
    const F: &str = "fmi3DoStep";
    if event_handling_needed.is_null()
        || terminate_simulation.is_null()
        || early_return.is_null()
        || last_successful_time.is_null()
    {
        return null_output::<M>(c);
    }
    // The step alone in the guard, as FMI 2.0's; the flags are plain writes.
    let s = status(guarded::<M>(c, F, move |rt| rt.do_step(current, step)));
    if let Ok(p) = crate::ffi::handles::resolve(c) {
        // No event mode and no early return; a model never ends the run on its own.
        *event_handling_needed = false;
        *terminate_simulation = false;
        *early_return = false;
        // SAFETY: the instance behind the handle the host was given (a getter: nothing can
        // panic).
        *last_successful_time = (*(p as *mut Instance<M>)).runtime.last_successful_time();
    }
    s
}

#[cold]
#[inline(never)]
unsafe fn null_output<M: Model>(c: fmi3Instance) -> fmi3Status {
    status(guarded::<M>(c, "fmi3DoStep", |rt| {
        rt.error("fmi3DoStep: an output argument is NULL")
    }))
}

pub unsafe fn get_fmu_state<M: Model>(c: fmi3Instance, state: *mut fmi3FMUState) -> fmi3Status {
    status(crate::ffi::get_fmu_state::<M>(c, state))
}

pub unsafe fn set_fmu_state<M: Model>(c: fmi3Instance, state: fmi3FMUState) -> fmi3Status {
    status(crate::ffi::set_fmu_state::<M>(c, state))
}

pub unsafe fn free_fmu_state<M: Model>(c: fmi3Instance, state: *mut fmi3FMUState) -> fmi3Status {
    status(crate::ffi::free_fmu_state::<M>(c, state))
}

pub unsafe fn serialized_fmu_state_size<M: Model>(
    c: fmi3Instance,
    state: fmi3FMUState,
    size: *mut usize,
) -> fmi3Status {
    status(crate::ffi::serialized_fmu_state_size::<M>(c, state, size))
}

pub unsafe fn serialize_fmu_state<M: Model>(
    c: fmi3Instance,
    state: fmi3FMUState,
    bytes: *mut u8,
    size: usize,
) -> fmi3Status {
    status(crate::ffi::serialize_fmu_state::<M>(
        c,
        state,
        bytes as *mut _,
        size,
    ))
}

pub unsafe fn deserialize_fmu_state<M: Model>(
    c: fmi3Instance,
    bytes: *const u8,
    size: usize,
    state: *mut fmi3FMUState,
) -> fmi3Status {
    status(crate::ffi::deserialize_fmu_state::<M>(
        c,
        bytes as *const _,
        size,
        state,
    ))
}

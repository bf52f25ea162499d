//! The FMI 2.0 entry points, generic over the model: each checks its pointers and runs the
//! safe [`Runtime`] call inside [`guarded`].
#![allow(clippy::missing_safety_doc, clippy::too_many_arguments)]

use super::{
    guarded, guarded_instance, opt_str, resource_dir_from_uri, values_at, values_at_mut, CLogger,
    Instance,
};
use crate::fmi2::*;
use crate::model::Model;
use crate::runtime::{Runtime, Snapshot};
use crate::variables::{ScalarType, Value};
use std::ffi::{CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

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
        let fail = |msg: String| super::refused(&logger, "fmi2Instantiate", &msg);
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
        let resource_dir = match opt_str(resource_location) {
            None => None,
            Some(uri) if uri.is_empty() => None,
            Some(uri) => match resource_dir_from_uri(&uri) {
                Ok(p) => Some(p),
                Err(e) => return fail(e.to_string()),
            },
        };
        // A fitted twin's start values, and the GUID its description has.
        let expected = crate::description::guid::<M>();
        let dir = resource_dir.as_deref();
        let what = ("GUID", "fmuGUID");
        let fitted = match super::fitted_starts::<M>(dir, opt_str(guid), &expected, what) {
            Ok(f) => f,
            Err(refusal) => return fail(refusal.to_string()),
        };
        let kept = match logger.callback {
            Some(f) => super::handles::SlotLogger::Fmi2(f, logger.env),
            None => super::handles::SlotLogger::None,
        };
        let mut runtime = Runtime::<M>::new(&name, resource_dir, Box::new(logger), logging_on != 0);
        if let Some(f) = fitted {
            runtime = runtime.with_fitted(f);
        }
        super::handle_for(Instance::new(runtime), kept) as fmi2Component
    }));
    r.unwrap_or(std::ptr::null_mut())
}

/// Frees the instance behind `c` (and the states it gave out that the host did not free);
/// a second free, or a handle this library did not give out, is logged and ignored.
pub unsafe fn free_instance<M: Model>(c: fmi2Component, function: &str) {
    match super::handles::release(c) {
        Ok(p) => {
            let _ = catch_unwind(AssertUnwindSafe(|| {
                drop(Box::from_raw(p as *mut Instance<M>))
            }));
        }
        // FMI allows NULL (nothing to free).
        Err(_) if c.is_null() => {}
        Err(why) => super::handles::log_stale(c, function, why),
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
#[inline(always)]
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
        return Err(null_arrays(rt, function, n));
    }
    Ok((std::slice::from_raw_parts(vr, n), values))
}

#[cold]
fn null_arrays(rt: &Runtime<impl Model>, function: &str, n: usize) -> fmi2Status {
    rt.error(&format!("{function}: NULL array with nvr = {n}"))
}

/// The `fmi2Get<Type>` and `fmi2Set<Type>` of `$t`, each `$fn("fmi2Name", $t, pointer,
/// slice of it) |runtime, value references, values| call`: the arrays checked, then the
/// call with the values to read (`values_at`) or to fill (`values_at_mut`).
macro_rules! accessors {
    ($($fn:ident($cname:literal, $t:ty, $ptr:ty, $slice:ident)
        |$rt:ident, $vrs:ident, $vals:ident| $call:expr;)*) => {$(
        pub unsafe fn $fn<M: Model>(
            c: fmi2Component,
            vr: *const fmi2ValueReference,
            n: usize,
            value: $ptr,
        ) -> fmi2Status {
            guarded::<M>(c, $cname, |$rt| {
                let ($vrs, _) = match arrays($rt, $cname, vr, n, value as *const $t) {
                    Ok(x) => x,
                    Err(s) => return s,
                };
                let $vals = $slice(value, n);
                $call
            })
        }
    )*};
}

accessors! {
    // Reals take the runtime's direct path (each value at its field's offset).
    get_real("fmi2GetReal", fmi2Real, *mut fmi2Real, values_at_mut)
        |rt, vrs, out| rt.get_real(vrs, out);
    set_real("fmi2SetReal", fmi2Real, *const fmi2Real, values_at)
        |rt, vrs, vals| rt.set_real(vrs, vals);
    get_integer("fmi2GetInteger", fmi2Integer, *mut fmi2Integer, values_at_mut) |rt, vrs, out| {
        rt.get("fmi2GetInteger", ScalarType::Integer, vrs, out, |v| v.as_f64() as i32)
    };
    set_integer("fmi2SetInteger", fmi2Integer, *const fmi2Integer, values_at) |rt, vrs, vals| {
        let values = vals.iter().map(|x| Value::Integer(*x));
        rt.set("fmi2SetInteger", ScalarType::Integer, vrs, values)
    };
    get_boolean("fmi2GetBoolean", fmi2Boolean, *mut fmi2Boolean, values_at_mut) |rt, vrs, out| {
        rt.get("fmi2GetBoolean", ScalarType::Boolean, vrs, out, |v| v.as_f64() as i32)
    };
    set_boolean("fmi2SetBoolean", fmi2Boolean, *const fmi2Boolean, values_at) |rt, vrs, vals| {
        let values = vals.iter().map(|x| Value::Boolean(*x != 0));
        rt.set("fmi2SetBoolean", ScalarType::Boolean, vrs, values)
    };
}

pub unsafe fn get_string<M: Model>(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    n: usize,
    value: *mut fmi2String,
) -> fmi2Status {
    guarded_instance::<M>(c, "fmi2GetString", |inst| {
        let (vrs, ptr) = match arrays(
            &inst.runtime,
            "fmi2GetString",
            vr,
            n,
            value as *const fmi2String,
        ) {
            Ok(x) => x,
            Err(s) => return s,
        };
        // The host reads the strings until its next call: keep them in the instance.
        let strings = &mut inst.strings;
        strings.clear();
        let status = inst.runtime.get_strings("fmi2GetString", vrs, |_, s| {
            strings.push(CString::new(s.replace('\0', "")).unwrap_or_default())
        });
        if status == fmi2Status::OK {
            let out = ptr as *mut fmi2String;
            for (k, s) in strings.iter().enumerate() {
                *out.add(k) = s.as_ptr();
            }
        }
        status
    })
}

pub unsafe fn set_string<M: Model>(
    c: fmi2Component,
    vr: *const fmi2ValueReference,
    n: usize,
    value: *const fmi2String,
) -> fmi2Status {
    guarded::<M>(c, "fmi2SetString", |rt| {
        let (vrs, ptr) = match arrays(rt, "fmi2SetString", vr, n, value) {
            Ok(x) => x,
            Err(s) => return s,
        };
        let mut texts = Vec::with_capacity(n);
        for (k, vr) in vrs.iter().enumerate() {
            match opt_str(*ptr.add(k)) {
                Some(t) => texts.push(t),
                None => return rt.error(&format!("fmi2SetString: value {k} (vr {vr}) is NULL")),
            }
        }
        let refs: Vec<&str> = texts.iter().map(|t| t.as_ref()).collect();
        rt.set_strings("fmi2SetString", vrs, &refs)
    })
}

pub unsafe fn get_fmu_state<M: Model>(c: fmi2Component, state: *mut fmi2FMUstate) -> fmi2Status {
    guarded_instance::<M>(c, "fmi2GetFMUstate", |inst| {
        if state.is_null() {
            return inst
                .runtime
                .error("fmi2GetFMUstate: FMUstate pointer is NULL");
        }
        if (*state).is_null() {
            match inst.runtime.snapshot() {
                Ok(s) => {
                    let p = Box::into_raw(Box::new(s));
                    inst.states.push(p);
                    *state = p as fmi2FMUstate;
                    fmi2Status::OK
                }
                Err(s) => s,
            }
        } else if inst.owns(*state) {
            inst.runtime
                .snapshot_into(&mut *(*state as *mut Snapshot<M>))
        } else {
            not_a_state(inst, "fmi2GetFMUstate")
        }
    })
}

/// A state pointer this instance did not give out, or one freed: refused, never followed.
#[cold]
fn not_a_state<M: Model>(inst: &Instance<M>, function: &str) -> fmi2Status {
    inst.runtime.error(&format!(
        "{function}: the FMUstate is not one of this instance's (freed already, another instance's, or not an FMU state at all); refused"
    ))
}

/// The state `state` names, if this instance gave it out.
unsafe fn own_state<'a, M: Model>(
    inst: &Instance<M>,
    function: &str,
    state: fmi2FMUstate,
) -> Result<&'a Snapshot<M>, fmi2Status> {
    if state.is_null() {
        return Err(inst.runtime.error(&format!("{function}: FMUstate is NULL")));
    }
    if !inst.owns(state) {
        return Err(not_a_state(inst, function));
    }
    Ok(&*(state as *const Snapshot<M>))
}

pub unsafe fn set_fmu_state<M: Model>(c: fmi2Component, state: fmi2FMUstate) -> fmi2Status {
    guarded_instance::<M>(c, "fmi2SetFMUstate", |inst| {
        match own_state(inst, "fmi2SetFMUstate", state) {
            Ok(s) => inst.runtime.restore(s),
            Err(status) => status,
        }
    })
}

pub unsafe fn free_fmu_state<M: Model>(c: fmi2Component, state: *mut fmi2FMUstate) -> fmi2Status {
    guarded_instance::<M>(c, "fmi2FreeFMUstate", |inst| {
        if state.is_null() || (*state).is_null() {
            return fmi2Status::OK;
        }
        let Some(k) = inst
            .states
            .iter()
            .position(|&s| s as fmi2FMUstate == *state)
        else {
            return not_a_state(inst, "fmi2FreeFMUstate");
        };
        drop(Box::from_raw(inst.states.swap_remove(k)));
        *state = std::ptr::null_mut();
        fmi2Status::OK
    })
}

pub unsafe fn serialized_fmu_state_size<M: Model>(
    c: fmi2Component,
    state: fmi2FMUstate,
    size: *mut usize,
) -> fmi2Status {
    guarded_instance::<M>(c, "fmi2SerializedFMUstateSize", |inst| {
        if size.is_null() {
            return inst
                .runtime
                .error("fmi2SerializedFMUstateSize: NULL argument");
        }
        match own_state(inst, "fmi2SerializedFMUstateSize", state) {
            Ok(s) => {
                *size = inst.runtime.serialize(s).len();
                fmi2Status::OK
            }
            Err(status) => status,
        }
    })
}

pub unsafe fn serialize_fmu_state<M: Model>(
    c: fmi2Component,
    state: fmi2FMUstate,
    bytes: *mut fmi2Byte,
    size: usize,
) -> fmi2Status {
    guarded_instance::<M>(c, "fmi2SerializeFMUstate", |inst| {
        if bytes.is_null() {
            return inst.runtime.error("fmi2SerializeFMUstate: NULL argument");
        }
        let s = match own_state(inst, "fmi2SerializeFMUstate", state) {
            Ok(s) => s,
            Err(status) => return status,
        };
        let data = inst.runtime.serialize(s);
        if data.len() > size {
            return inst.runtime.error(&format!(
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
    guarded_instance::<M>(c, "fmi2DeSerializeFMUstate", |inst| {
        if bytes.is_null() || state.is_null() {
            return inst.runtime.error("fmi2DeSerializeFMUstate: NULL argument");
        }
        if !(*state).is_null() && !inst.owns(*state) {
            return not_a_state(inst, "fmi2DeSerializeFMUstate");
        }
        let data = std::slice::from_raw_parts(bytes as *const u8, size);
        match inst.runtime.deserialize(data) {
            Ok(snap) => {
                if (*state).is_null() {
                    let p = Box::into_raw(Box::new(snap));
                    inst.states.push(p);
                    *state = p as fmi2FMUstate;
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

/// The status queries `fmi2Get<Type>Status`, each answering its one status kind (with
/// `$answer` of the runtime); another kind, or a NULL `value`, is an error.
macro_rules! status_queries {
    ($($fn:ident($function:literal, $t:ty) $provided:ident => $answer:expr;)*) => {$(
        pub unsafe fn $fn<M: Model>(
            c: fmi2Component,
            kind: fmi2StatusKind,
            value: *mut $t,
        ) -> fmi2Status {
            guarded::<M>(c, $function, |rt| {
                if value.is_null() {
                    return rt.error(concat!($function, ": value is NULL"));
                }
                if kind == fmi2StatusKind::$provided {
                    *value = $answer(rt);
                    fmi2Status::OK
                } else {
                    rt.error(&format!(
                        concat!($function, ": status kind {} not provided"),
                        kind.0
                    ))
                }
            })
        }
    )*};
}

status_queries! {
    get_real_status("fmi2GetRealStatus", fmi2Real)
        LAST_SUCCESSFUL_TIME => |rt: &mut Runtime<M>| rt.last_successful_time();
    get_boolean_status("fmi2GetBooleanStatus", fmi2Boolean)
        TERMINATED => |_: &mut Runtime<M>| fmi2False;
}

pub const TYPES_PLATFORM: &CStr = c"default";
pub const VERSION: &CStr = c"2.0";

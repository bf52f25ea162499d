//! The `fmi3*` C symbols of a model's `cdylib`, defined by [`export_fmu!`](crate::export_fmu)
//! beside the `fmi2*` ones: every function FMI 3.0 declares, those this FMU does not
//! provide answering `fmi3Error` with the reason.

/// Define every `fmi3*` symbol for `$model` (used by [`export_fmu!`](crate::export_fmu)).
#[doc(hidden)]
#[macro_export]
macro_rules! export_fmu3 {
    ($model:ty) => {
        #[allow(non_snake_case, clippy::missing_safety_doc, clippy::too_many_arguments)]
        mod __fmi3_exports {
            use super::*;
            use $crate::ffi3::*;
            use ::std::ffi::{c_char, c_void};
            type M = $model;
            type Vr = fmi3ValueReference;

            $crate::__fmi_entry_points! {
                fmi3GetVersion() -> *const c_char => VERSION.as_ptr();
                fmi3SetDebugLogging(c: fmi3Instance, on: bool, n: usize, cat: *const *const c_char)
                    -> fmi3Status => set_debug_logging::<M>(c, on, n, cat);
                fmi3InstantiateCoSimulation(name: *const c_char, token: *const c_char,
                    resources: *const c_char, visible: bool, logging_on: bool, event_mode_used: bool,
                    early_return_allowed: bool, required: *const Vr, n_required: usize,
                    env: *mut c_void, log: Option<fmi3LogMessageCallback>, intermediate: *const c_void)
                    -> fmi3Instance => instantiate_co_simulation::<M>(
                        name, token, resources, visible, logging_on, event_mode_used,
                        early_return_allowed, required, n_required, env, log, intermediate,
                    );
                fmi3InstantiateModelExchange(_name: *const c_char, _token: *const c_char,
                    _resources: *const c_char, _visible: bool, _logging_on: bool, env: *mut c_void,
                    log: Option<fmi3LogMessageCallback>)
                    -> fmi3Instance => instantiate_unsupported::<M>("ModelExchange", env, log);
                fmi3InstantiateScheduledExecution(_name: *const c_char, _token: *const c_char,
                    _resources: *const c_char, _visible: bool, _logging_on: bool, env: *mut c_void,
                    log: Option<fmi3LogMessageCallback>, _clock_update: *const c_void,
                    _lock: *const c_void, _unlock: *const c_void)
                    -> fmi3Instance => instantiate_unsupported::<M>("ScheduledExecution", env, log);
                fmi3FreeInstance(c: fmi3Instance) => free_instance::<M>(c);
                fmi3EnterInitializationMode(c: fmi3Instance, td: bool, tol: f64, start: f64, sd: bool,
                    stop: f64)
                    -> fmi3Status => enter_initialization_mode::<M>(c, td, tol, start, sd, stop);
                fmi3ExitInitializationMode(c: fmi3Instance)
                    -> fmi3Status => exit_initialization_mode::<M>(c);
                fmi3Terminate(c: fmi3Instance) -> fmi3Status => terminate::<M>(c);
                fmi3Reset(c: fmi3Instance) -> fmi3Status => reset::<M>(c);
                fmi3GetFloat64(c: fmi3Instance, vr: *const Vr, n: usize, v: *mut f64, nv: usize)
                    -> fmi3Status => get_float64::<M>(c, vr, n, v, nv);
                fmi3SetFloat64(c: fmi3Instance, vr: *const Vr, n: usize, v: *const f64, nv: usize)
                    -> fmi3Status => set_float64::<M>(c, vr, n, v, nv);
                fmi3GetInt32(c: fmi3Instance, vr: *const Vr, n: usize, v: *mut i32, nv: usize)
                    -> fmi3Status => get_int32::<M>(c, vr, n, v, nv);
                fmi3SetInt32(c: fmi3Instance, vr: *const Vr, n: usize, v: *const i32, nv: usize)
                    -> fmi3Status => set_int32::<M>(c, vr, n, v, nv);
                fmi3GetInt64(c: fmi3Instance, vr: *const Vr, n: usize, v: *mut i64, nv: usize)
                    -> fmi3Status => get_int64::<M>(c, vr, n, v, nv);
                fmi3SetInt64(c: fmi3Instance, vr: *const Vr, n: usize, v: *const i64, nv: usize)
                    -> fmi3Status => set_int64::<M>(c, vr, n, v, nv);
                fmi3GetBoolean(c: fmi3Instance, vr: *const Vr, n: usize, v: *mut u8, nv: usize)
                    -> fmi3Status => get_boolean::<M>(c, vr, n, v, nv);
                fmi3SetBoolean(c: fmi3Instance, vr: *const Vr, n: usize, v: *const u8, nv: usize)
                    -> fmi3Status => set_boolean::<M>(c, vr, n, v, nv);
                fmi3GetString(c: fmi3Instance, vr: *const Vr, n: usize, v: *mut *const c_char,
                    nv: usize)
                    -> fmi3Status => get_string::<M>(c, vr, n, v, nv);
                fmi3SetString(c: fmi3Instance, vr: *const Vr, n: usize, v: *const *const c_char,
                    nv: usize)
                    -> fmi3Status => set_string::<M>(c, vr, n, v, nv);
            }
            $crate::__fmi3_none_of_type!(M, fmi3GetFloat32, fmi3SetFloat32, f32);
            $crate::__fmi3_none_of_type!(M, fmi3GetInt8, fmi3SetInt8, i8);
            $crate::__fmi3_none_of_type!(M, fmi3GetUInt8, fmi3SetUInt8, u8);
            $crate::__fmi3_none_of_type!(M, fmi3GetInt16, fmi3SetInt16, i16);
            $crate::__fmi3_none_of_type!(M, fmi3GetUInt16, fmi3SetUInt16, u16);
            $crate::__fmi3_none_of_type!(M, fmi3GetUInt32, fmi3SetUInt32, u32);
            $crate::__fmi3_none_of_type!(M, fmi3GetUInt64, fmi3SetUInt64, u64);
            $crate::__fmi_entry_points! {
                fmi3GetBinary(c: fmi3Instance, vr: *const Vr, n: usize, _sizes: *mut usize,
                    _v: *mut *const u8, _nv: usize)
                    -> fmi3Status => no_variable_of_type::<M>(c, "fmi3GetBinary", vr, n);
                fmi3SetBinary(c: fmi3Instance, vr: *const Vr, n: usize, _sizes: *const usize,
                    _v: *const *const u8, _nv: usize)
                    -> fmi3Status => no_variable_of_type::<M>(c, "fmi3SetBinary", vr, n);
                fmi3GetClock(c: fmi3Instance, vr: *const Vr, n: usize, _v: *mut bool)
                    -> fmi3Status => no_variable_of_type::<M>(c, "fmi3GetClock", vr, n);
                fmi3SetClock(c: fmi3Instance, vr: *const Vr, n: usize, _v: *const bool)
                    -> fmi3Status => no_variable_of_type::<M>(c, "fmi3SetClock", vr, n);
                fmi3DoStep(c: fmi3Instance, current: f64, step: f64, no_set_prior: bool,
                    event_handling_needed: *mut bool, terminate_simulation: *mut bool,
                    early_return: *mut bool, last_successful_time: *mut f64)
                    -> fmi3Status => do_step::<M>(c, current, step, no_set_prior,
                        event_handling_needed, terminate_simulation, early_return,
                        last_successful_time);
                fmi3GetFMUState(c: fmi3Instance, s: *mut fmi3FMUState)
                    -> fmi3Status => get_fmu_state::<M>(c, s);
                fmi3SetFMUState(c: fmi3Instance, s: fmi3FMUState)
                    -> fmi3Status => set_fmu_state::<M>(c, s);
                fmi3FreeFMUState(c: fmi3Instance, s: *mut fmi3FMUState)
                    -> fmi3Status => free_fmu_state::<M>(c, s);
                fmi3SerializedFMUStateSize(c: fmi3Instance, s: fmi3FMUState, size: *mut usize)
                    -> fmi3Status => serialized_fmu_state_size::<M>(c, s, size);
                fmi3SerializeFMUState(c: fmi3Instance, s: fmi3FMUState, b: *mut u8, size: usize)
                    -> fmi3Status => serialize_fmu_state::<M>(c, s, b, size);
                fmi3DeserializeFMUState(c: fmi3Instance, b: *const u8, size: usize,
                    s: *mut fmi3FMUState)
                    -> fmi3Status => deserialize_fmu_state::<M>(c, b, size, s);
            }
            $crate::__fmi3_not_provided!(M, fmi3EnterEventMode(), "this FMU has no event mode (hasEventMode=\"false\")");
            $crate::__fmi3_not_provided!(M, fmi3EnterStepMode(), "step mode is entered by fmi3ExitInitializationMode: this FMU has no event mode (hasEventMode=\"false\")");
            $crate::__fmi3_not_provided!(M, fmi3EnterConfigurationMode(), "this FMU has no structural parameters to configure");
            $crate::__fmi3_not_provided!(M, fmi3ExitConfigurationMode(), "this FMU has no structural parameters to configure");
            $crate::__fmi3_not_provided!(M, fmi3EvaluateDiscreteStates(), "this FMU does not provide it (providesEvaluateDiscreteStates=\"false\")");
            $crate::__fmi3_not_provided!(M, fmi3UpdateDiscreteStates(a: *mut bool, b: *mut bool, d: *mut bool, e: *mut bool, f: *mut bool, g: *mut f64), "this FMU has no event mode (hasEventMode=\"false\")");
            $crate::__fmi3_not_provided!(M, fmi3GetNumberOfVariableDependencies(vr: Vr, n: *mut usize), "the dependencies are in modelDescription.xml's ModelStructure");
            $crate::__fmi3_not_provided!(M, fmi3GetVariableDependencies(vr: Vr, a: *mut usize, b: *mut Vr, d: *mut usize, e: *mut i32, n: usize), "the dependencies are in modelDescription.xml's ModelStructure");
            $crate::__fmi3_not_provided!(M, fmi3GetDirectionalDerivative(u: *const Vr, nu: usize, k: *const Vr, nk: usize, s: *const f64, ns: usize, o: *mut f64, no: usize), "this FMU provides no directional derivatives (providesDirectionalDerivatives=\"false\")");
            $crate::__fmi3_not_provided!(M, fmi3GetAdjointDerivative(u: *const Vr, nu: usize, k: *const Vr, nk: usize, s: *const f64, ns: usize, o: *mut f64, no: usize), "this FMU provides no adjoint derivatives (providesAdjointDerivatives=\"false\")");
            $crate::__fmi3_not_provided!(M, fmi3GetOutputDerivatives(vr: *const Vr, n: usize, o: *const i32, v: *mut f64, nv: usize), "this FMU provides no output derivatives (maxOutputDerivativeOrder=\"0\")");
            $crate::__fmi3_not_provided!(M, fmi3GetIntervalDecimal(vr: *const Vr, n: usize, i: *mut f64, q: *mut i32), "this FMU has no clocks");
            $crate::__fmi3_not_provided!(M, fmi3GetIntervalFraction(vr: *const Vr, n: usize, a: *mut u64, b: *mut u64, q: *mut i32), "this FMU has no clocks");
            $crate::__fmi3_not_provided!(M, fmi3GetShiftDecimal(vr: *const Vr, n: usize, s: *mut f64), "this FMU has no clocks");
            $crate::__fmi3_not_provided!(M, fmi3GetShiftFraction(vr: *const Vr, n: usize, a: *mut u64, b: *mut u64), "this FMU has no clocks");
            $crate::__fmi3_not_provided!(M, fmi3SetIntervalDecimal(vr: *const Vr, n: usize, i: *const f64), "this FMU has no clocks");
            $crate::__fmi3_not_provided!(M, fmi3SetIntervalFraction(vr: *const Vr, n: usize, a: *const u64, b: *const u64), "this FMU has no clocks");
            $crate::__fmi3_not_provided!(M, fmi3SetShiftDecimal(vr: *const Vr, n: usize, s: *const f64), "this FMU has no clocks");
            $crate::__fmi3_not_provided!(M, fmi3SetShiftFraction(vr: *const Vr, n: usize, a: *const u64, b: *const u64), "this FMU has no clocks");
            $crate::__fmi3_not_provided!(M, fmi3ActivateModelPartition(clock: Vr, t: f64), "this FMU is a Co-Simulation FMU only (no Scheduled Execution)");
            $crate::__fmi3_not_provided!(M, fmi3EnterContinuousTimeMode(), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3CompletedIntegratorStep(p: bool, a: *mut bool, b: *mut bool), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3SetTime(t: f64), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3SetContinuousStates(x: *const f64, n: usize), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3GetContinuousStateDerivatives(x: *mut f64, n: usize), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3GetEventIndicators(x: *mut f64, n: usize), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3GetContinuousStates(x: *mut f64, n: usize), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3GetNominalsOfContinuousStates(x: *mut f64, n: usize), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3GetNumberOfEventIndicators(n: *mut usize), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
            $crate::__fmi3_not_provided!(M, fmi3GetNumberOfContinuousStates(n: *mut usize), "this FMU is a Co-Simulation FMU only (no Model Exchange)");
        }
    };
}

/// Getters and setters of a type the model has no variable of (in [`export_fmu3!`]).
#[doc(hidden)]
#[macro_export]
macro_rules! __fmi3_none_of_type {
    ($m:ty, $get:ident, $set:ident, $t:ty) => {
        $crate::__fmi_entry_points! {
            $get(c: $crate::ffi3::fmi3Instance, vr: *const u32, n: usize, _v: *mut $t, _nv: usize)
                -> $crate::ffi3::fmi3Status
                => $crate::ffi3::no_variable_of_type::<$m>(c, stringify!($get), vr, n);
            $set(c: $crate::ffi3::fmi3Instance, vr: *const u32, n: usize, _v: *const $t, _nv: usize)
                -> $crate::ffi3::fmi3Status
                => $crate::ffi3::no_variable_of_type::<$m>(c, stringify!($set), vr, n);
        }
    };
}

/// A call of what the model does not provide: fmi3Error with the reason (in
/// [`export_fmu3!`]).
#[doc(hidden)]
#[macro_export]
macro_rules! __fmi3_not_provided {
    ($m:ty, $name:ident ($($arg:ident : $t:ty),*), $why:literal) => {
        $crate::__fmi_entry_points! {
            $name(c: $crate::ffi3::fmi3Instance $(, $arg: $t)*) -> $crate::ffi3::fmi3Status => {
                $(let _ = $arg;)*
                $crate::ffi3::unsupported::<$m>(c, stringify!($name), $why)
            };
        }
    };
}

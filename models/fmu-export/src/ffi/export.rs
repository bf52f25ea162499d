//! [`export_fmu!`](crate::export_fmu): the `#[no_mangle]` C symbols of a model's `cdylib`.

/// Export a model as an FMI 2.0 and FMI 3.0 Co-Simulation FMU: defines every `fmi2*` and
/// every `fmi3*` C symbol (one library serves both model descriptions).
/// Use once per `cdylib`, behind the model crate's `fmu` feature.
#[macro_export]
macro_rules! export_fmu {
    ($model:ty) => {
        $crate::export_fmu3!($model);
        #[allow(non_snake_case, clippy::missing_safety_doc)]
        mod __fmi2_exports {
            use super::*;
            use $crate::ffi;
            use $crate::fmi2::*;
            use ::std::os::raw::c_char;
            type M = $model;
            type Vr = fmi2ValueReference;

            $crate::__fmi_entry_points! {
                fmi2GetTypesPlatform() -> *const c_char => ffi::TYPES_PLATFORM.as_ptr();
                fmi2GetVersion() -> *const c_char => ffi::VERSION.as_ptr();
                fmi2SetDebugLogging(c: fmi2Component, on: fmi2Boolean, n: usize, cat: *const fmi2String)
                    -> fmi2Status => ffi::set_debug_logging::<M>(c, on, n, cat);
                fmi2Instantiate(name: fmi2String, ty: fmi2Type, guid: fmi2String, res: fmi2String,
                    f: *const fmi2CallbackFunctions, visible: fmi2Boolean, log: fmi2Boolean)
                    -> fmi2Component => ffi::instantiate::<M>(name, ty, guid, res, f, visible, log);
                fmi2FreeInstance(c: fmi2Component) => ffi::free_instance::<M>(c, "fmi2FreeInstance");
                fmi2SetupExperiment(c: fmi2Component, td: fmi2Boolean, tol: fmi2Real, start: fmi2Real,
                    sd: fmi2Boolean, stop: fmi2Real)
                    -> fmi2Status => ffi::setup_experiment::<M>(c, td, tol, start, sd, stop);
                fmi2EnterInitializationMode(c: fmi2Component)
                    -> fmi2Status => ffi::enter_initialization_mode::<M>(c);
                fmi2ExitInitializationMode(c: fmi2Component)
                    -> fmi2Status => ffi::exit_initialization_mode::<M>(c);
                fmi2Terminate(c: fmi2Component) -> fmi2Status => ffi::terminate::<M>(c);
                fmi2Reset(c: fmi2Component) -> fmi2Status => ffi::reset::<M>(c);
                fmi2GetReal(c: fmi2Component, vr: *const Vr, n: usize, v: *mut fmi2Real)
                    -> fmi2Status => ffi::get_real::<M>(c, vr, n, v);
                fmi2GetInteger(c: fmi2Component, vr: *const Vr, n: usize, v: *mut fmi2Integer)
                    -> fmi2Status => ffi::get_integer::<M>(c, vr, n, v);
                fmi2GetBoolean(c: fmi2Component, vr: *const Vr, n: usize, v: *mut fmi2Boolean)
                    -> fmi2Status => ffi::get_boolean::<M>(c, vr, n, v);
                fmi2GetString(c: fmi2Component, vr: *const Vr, n: usize, v: *mut fmi2String)
                    -> fmi2Status => ffi::get_string::<M>(c, vr, n, v);
                fmi2SetReal(c: fmi2Component, vr: *const Vr, n: usize, v: *const fmi2Real)
                    -> fmi2Status => ffi::set_real::<M>(c, vr, n, v);
                fmi2SetInteger(c: fmi2Component, vr: *const Vr, n: usize, v: *const fmi2Integer)
                    -> fmi2Status => ffi::set_integer::<M>(c, vr, n, v);
                fmi2SetBoolean(c: fmi2Component, vr: *const Vr, n: usize, v: *const fmi2Boolean)
                    -> fmi2Status => ffi::set_boolean::<M>(c, vr, n, v);
                fmi2SetString(c: fmi2Component, vr: *const Vr, n: usize, v: *const fmi2String)
                    -> fmi2Status => ffi::set_string::<M>(c, vr, n, v);
                fmi2GetFMUstate(c: fmi2Component, s: *mut fmi2FMUstate)
                    -> fmi2Status => ffi::get_fmu_state::<M>(c, s);
                fmi2SetFMUstate(c: fmi2Component, s: fmi2FMUstate)
                    -> fmi2Status => ffi::set_fmu_state::<M>(c, s);
                fmi2FreeFMUstate(c: fmi2Component, s: *mut fmi2FMUstate)
                    -> fmi2Status => ffi::free_fmu_state::<M>(c, s);
                fmi2SerializedFMUstateSize(c: fmi2Component, s: fmi2FMUstate, size: *mut usize)
                    -> fmi2Status => ffi::serialized_fmu_state_size::<M>(c, s, size);
                fmi2SerializeFMUstate(c: fmi2Component, s: fmi2FMUstate, b: *mut fmi2Byte, size: usize)
                    -> fmi2Status => ffi::serialize_fmu_state::<M>(c, s, b, size);
                fmi2DeSerializeFMUstate(c: fmi2Component, b: *const fmi2Byte, size: usize,
                    s: *mut fmi2FMUstate)
                    -> fmi2Status => ffi::deserialize_fmu_state::<M>(c, b, size, s);
                fmi2GetDirectionalDerivative(c: fmi2Component, _u: *const Vr, _nu: usize,
                    _z: *const Vr, _nz: usize, _dv: *const fmi2Real, _dz: *mut fmi2Real)
                    -> fmi2Status => ffi::unsupported::<M>(c, "fmi2GetDirectionalDerivative",
                        "not provided (providesDirectionalDerivative=false)");
                fmi2SetRealInputDerivatives(c: fmi2Component, _vr: *const Vr, _n: usize,
                    _o: *const fmi2Integer, _v: *const fmi2Real)
                    -> fmi2Status => ffi::unsupported::<M>(c, "fmi2SetRealInputDerivatives",
                        "not provided (canInterpolateInputs=false)");
                fmi2GetRealOutputDerivatives(c: fmi2Component, _vr: *const Vr, _n: usize,
                    _o: *const fmi2Integer, _v: *mut fmi2Real)
                    -> fmi2Status => ffi::unsupported::<M>(c, "fmi2GetRealOutputDerivatives",
                        "not provided (maxOutputDerivativeOrder=0)");
                fmi2DoStep(c: fmi2Component, t: fmi2Real, h: fmi2Real, np: fmi2Boolean)
                    -> fmi2Status => ffi::do_step::<M>(c, t, h, np);
                fmi2CancelStep(c: fmi2Component) -> fmi2Status => ffi::unsupported::<M>(c,
                    "fmi2CancelStep", "steps are synchronous (canRunAsynchronuously=false)");
                fmi2GetStatus(c: fmi2Component, _k: fmi2StatusKind, _v: *mut fmi2Status)
                    -> fmi2Status => ffi::unsupported::<M>(c, "fmi2GetStatus",
                        "steps are synchronous, there is no pending status");
                fmi2GetRealStatus(c: fmi2Component, k: fmi2StatusKind, v: *mut fmi2Real)
                    -> fmi2Status => ffi::get_real_status::<M>(c, k, v);
                fmi2GetIntegerStatus(c: fmi2Component, _k: fmi2StatusKind, _v: *mut fmi2Integer)
                    -> fmi2Status => ffi::unsupported::<M>(c, "fmi2GetIntegerStatus",
                        "no integer status is provided");
                fmi2GetBooleanStatus(c: fmi2Component, k: fmi2StatusKind, v: *mut fmi2Boolean)
                    -> fmi2Status => ffi::get_boolean_status::<M>(c, k, v);
                fmi2GetStringStatus(c: fmi2Component, _k: fmi2StatusKind, _v: *mut fmi2String)
                    -> fmi2Status => ffi::unsupported::<M>(c, "fmi2GetStringStatus",
                        "no string status is provided");
            }
        }
    };
}

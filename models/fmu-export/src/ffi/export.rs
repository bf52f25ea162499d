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
                ffi::free_instance::<M>(c, "fmi2FreeInstance")
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

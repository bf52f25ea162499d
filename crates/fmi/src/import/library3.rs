//! A loaded FMI 3.0 library with its functions resolved (beside [`super::library`], the
//! FMI 2.0 one): every function FMI 3.0 requires of a Co-Simulation FMU or, loaded for
//! Model Exchange, of a Model Exchange FMU ([`Me3Api`]), and the check of `fmi3GetVersion`.

use crate::FmuError;
use std::ffi::{c_char, c_void};
use std::path::{Path, PathBuf};

pub(crate) type Inst = *mut c_void;
type Vr = u32;
pub(crate) type Status = i32;
pub(crate) type Logger = unsafe extern "C" fn(*mut c_void, Status, *const c_char, *const c_char);

macro_rules! api {
    ($($field:ident : $sym:literal : fn($($arg:ty),*) $(-> $ret:ty)?;)*) => {
        /// The FMI 3.0 functions twinbench calls, resolved once.
        #[allow(non_snake_case)]
        pub struct Fmi3Api {
            $(pub $field: unsafe extern "C" fn($($arg),*) $(-> $ret)?,)*
        }
        impl Fmi3Api {
            /// Every function from `lib`, or `stand_in`'s for one it lacks; Err: the first
            /// one missing without a stand-in.
            fn resolve(
                lib: &libloading::Library,
                stand_in: impl Fn(&str) -> Option<*mut c_void>,
            ) -> Result<Fmi3Api, &'static str> {
                Ok(Fmi3Api {
                    $($field: unsafe {
                        match lib.get::<unsafe extern "C" fn($($arg),*) $(-> $ret)?>(concat!($sym, "\0").as_bytes()) {
                            Ok(f) => *f,
                            // SAFETY: a stand-in has the type of the function it stands for.
                            Err(_) => std::mem::transmute::<*mut c_void, unsafe extern "C" fn($($arg),*) $(-> $ret)?>(
                                stand_in($sym).ok_or($sym)?,
                            ),
                        }
                    },)*
                })
            }
        }
    };
}

api! {
    get_version: "fmi3GetVersion": fn() -> *const c_char;
    set_debug_logging: "fmi3SetDebugLogging": fn(Inst, bool, usize, *const *const c_char) -> Status;
    instantiate_co_simulation: "fmi3InstantiateCoSimulation": fn(
        *const c_char, *const c_char, *const c_char, bool, bool, bool, bool,
        *const Vr, usize, *mut c_void, Option<Logger>, *const c_void) -> Inst;
    free_instance: "fmi3FreeInstance": fn(Inst);
    enter_initialization_mode: "fmi3EnterInitializationMode": fn(Inst, bool, f64, f64, bool, f64) -> Status;
    exit_initialization_mode: "fmi3ExitInitializationMode": fn(Inst) -> Status;
    terminate: "fmi3Terminate": fn(Inst) -> Status;
    reset: "fmi3Reset": fn(Inst) -> Status;
    get_float32: "fmi3GetFloat32": fn(Inst, *const Vr, usize, *mut f32, usize) -> Status;
    get_float64: "fmi3GetFloat64": fn(Inst, *const Vr, usize, *mut f64, usize) -> Status;
    get_int8: "fmi3GetInt8": fn(Inst, *const Vr, usize, *mut i8, usize) -> Status;
    get_uint8: "fmi3GetUInt8": fn(Inst, *const Vr, usize, *mut u8, usize) -> Status;
    get_int16: "fmi3GetInt16": fn(Inst, *const Vr, usize, *mut i16, usize) -> Status;
    get_uint16: "fmi3GetUInt16": fn(Inst, *const Vr, usize, *mut u16, usize) -> Status;
    get_int32: "fmi3GetInt32": fn(Inst, *const Vr, usize, *mut i32, usize) -> Status;
    get_uint32: "fmi3GetUInt32": fn(Inst, *const Vr, usize, *mut u32, usize) -> Status;
    get_int64: "fmi3GetInt64": fn(Inst, *const Vr, usize, *mut i64, usize) -> Status;
    get_uint64: "fmi3GetUInt64": fn(Inst, *const Vr, usize, *mut u64, usize) -> Status;
    get_boolean: "fmi3GetBoolean": fn(Inst, *const Vr, usize, *mut u8, usize) -> Status;
    get_string: "fmi3GetString": fn(Inst, *const Vr, usize, *mut *const c_char, usize) -> Status;
    set_float32: "fmi3SetFloat32": fn(Inst, *const Vr, usize, *const f32, usize) -> Status;
    set_float64: "fmi3SetFloat64": fn(Inst, *const Vr, usize, *const f64, usize) -> Status;
    set_int8: "fmi3SetInt8": fn(Inst, *const Vr, usize, *const i8, usize) -> Status;
    set_uint8: "fmi3SetUInt8": fn(Inst, *const Vr, usize, *const u8, usize) -> Status;
    set_int16: "fmi3SetInt16": fn(Inst, *const Vr, usize, *const i16, usize) -> Status;
    set_uint16: "fmi3SetUInt16": fn(Inst, *const Vr, usize, *const u16, usize) -> Status;
    set_int32: "fmi3SetInt32": fn(Inst, *const Vr, usize, *const i32, usize) -> Status;
    set_uint32: "fmi3SetUInt32": fn(Inst, *const Vr, usize, *const u32, usize) -> Status;
    set_int64: "fmi3SetInt64": fn(Inst, *const Vr, usize, *const i64, usize) -> Status;
    set_uint64: "fmi3SetUInt64": fn(Inst, *const Vr, usize, *const u64, usize) -> Status;
    set_boolean: "fmi3SetBoolean": fn(Inst, *const Vr, usize, *const u8, usize) -> Status;
    set_string: "fmi3SetString": fn(Inst, *const Vr, usize, *const *const c_char, usize) -> Status;
    get_binary: "fmi3GetBinary": fn(Inst, *const Vr, usize, *mut usize, *mut *const u8, usize) -> Status;
    set_binary: "fmi3SetBinary": fn(Inst, *const Vr, usize, *const usize, *const *const u8, usize) -> Status;
    do_step: "fmi3DoStep": fn(Inst, f64, f64, bool, *mut u8, *mut u8, *mut u8, *mut f64) -> Status;
    get_fmu_state: "fmi3GetFMUState": fn(Inst, *mut *mut c_void) -> Status;
    set_fmu_state: "fmi3SetFMUState": fn(Inst, *mut c_void) -> Status;
    free_fmu_state: "fmi3FreeFMUState": fn(Inst, *mut *mut c_void) -> Status;
    serialized_fmu_state_size: "fmi3SerializedFMUStateSize": fn(Inst, *mut c_void, *mut usize) -> Status;
    serialize_fmu_state: "fmi3SerializeFMUState": fn(Inst, *mut c_void, *mut u8, usize) -> Status;
    deserialize_fmu_state: "fmi3DeserializeFMUState": fn(Inst, *const u8, usize, *mut *mut c_void) -> Status;
}

macro_rules! me3_api {
    ($($field:ident : $sym:literal : $ty:ty;)*) => {
        /// The functions of FMI 3.0's Model Exchange interface (FMI 3.0 §3.2), each required
        /// of an FMU that declares `<ModelExchange>`: what twinbench's integrator calls.
        #[derive(Clone, Copy)]
        pub struct Me3Api {
            $(pub $field: $ty,)*
        }
        impl Me3Api {
            /// Every Model Exchange function from `lib`; Err: the first one missing.
            fn resolve(lib: &libloading::Library) -> Result<Me3Api, &'static str> {
                Ok(Me3Api {
                    // SAFETY: each symbol has the standard's C type for its name
                    // (fmi3FunctionTypes.h; fmi3Boolean is C's bool).
                    $($field: unsafe {
                        *lib.get::<$ty>(concat!($sym, "\0").as_bytes()).map_err(|_| $sym)?
                    },)*
                })
            }
        }
    };
}

me3_api! {
    instantiate_model_exchange: "fmi3InstantiateModelExchange": unsafe extern "C" fn(
        *const c_char, *const c_char, *const c_char, bool, bool, *mut c_void, Option<Logger>) -> Inst;
    enter_event_mode: "fmi3EnterEventMode": unsafe extern "C" fn(Inst) -> Status;
    update_discrete_states: "fmi3UpdateDiscreteStates": unsafe extern "C" fn(
        Inst, *mut bool, *mut bool, *mut bool, *mut bool, *mut bool, *mut f64) -> Status;
    enter_continuous_time_mode: "fmi3EnterContinuousTimeMode": unsafe extern "C" fn(Inst) -> Status;
    completed_integrator_step: "fmi3CompletedIntegratorStep": unsafe extern "C" fn(
        Inst, bool, *mut bool, *mut bool) -> Status;
    set_time: "fmi3SetTime": unsafe extern "C" fn(Inst, f64) -> Status;
    set_continuous_states: "fmi3SetContinuousStates": unsafe extern "C" fn(Inst, *const f64, usize) -> Status;
    get_continuous_state_derivatives: "fmi3GetContinuousStateDerivatives": unsafe extern "C" fn(Inst, *mut f64, usize) -> Status;
    get_event_indicators: "fmi3GetEventIndicators": unsafe extern "C" fn(Inst, *mut f64, usize) -> Status;
    get_continuous_states: "fmi3GetContinuousStates": unsafe extern "C" fn(Inst, *mut f64, usize) -> Status;
    get_nominals_of_continuous_states: "fmi3GetNominalsOfContinuousStates": unsafe extern "C" fn(Inst, *mut f64, usize) -> Status;
    get_number_of_event_indicators: "fmi3GetNumberOfEventIndicators": unsafe extern "C" fn(Inst, *mut usize) -> Status;
    get_number_of_continuous_states: "fmi3GetNumberOfContinuousStates": unsafe extern "C" fn(Inst, *mut usize) -> Status;
}

/// Stand in for the Co-Simulation functions in a library loaded for Model Exchange that
/// does not export them (an FMU without `<CoSimulation>` need not): never called, as a
/// Model Exchange instance is instantiated and stepped through [`Me3Api`]; an error if
/// one ever were.
unsafe extern "C" fn no_instantiate_co_simulation(
    _: *const c_char,
    _: *const c_char,
    _: *const c_char,
    _: bool,
    _: bool,
    _: bool,
    _: bool,
    _: *const Vr,
    _: usize,
    _: *mut c_void,
    _: Option<Logger>,
    _: *const c_void,
) -> Inst {
    std::ptr::null_mut()
}

unsafe extern "C" fn no_do_step(
    _: Inst,
    _: f64,
    _: f64,
    _: bool,
    _: *mut u8,
    _: *mut u8,
    _: *mut u8,
    _: *mut f64,
) -> Status {
    3
}

/// A loaded FMI 3.0 library.
pub struct Library3 {
    pub path: PathBuf,
    /// What `fmi3GetVersion` returned (a "3.x" is required).
    pub version: String,
    pub api: Fmi3Api,
    /// The Model Exchange functions, when loaded for Model Exchange
    /// ([`Library3::load_model_exchange`]).
    pub me: Option<Me3Api>,
    _lib: libloading::Library,
}

impl Library3 {
    /// Load the library, resolve the functions (every one is required by FMI 3.0 for a
    /// Co-Simulation FMU) and check `fmi3GetVersion`.
    pub fn load(path: &Path) -> Result<Library3, FmuError> {
        Self::load_as(path, false)
    }

    /// Load the library for Model Exchange: the common functions as [`Library3::load`] and
    /// every Model Exchange function ([`Me3Api`]); `fmi3InstantiateCoSimulation` and
    /// `fmi3DoStep` may be missing. A missing function is named.
    pub fn load_model_exchange(path: &Path) -> Result<Library3, FmuError> {
        Self::load_as(path, true)
    }

    fn load_as(path: &Path, model_exchange: bool) -> Result<Library3, FmuError> {
        let lib = super::open_library(path)?;
        let missing = |symbol| FmuError::MissingSymbol {
            path: path.to_path_buf(),
            symbol,
        };
        let api = Fmi3Api::resolve(&lib, |symbol| match (model_exchange, symbol) {
            (true, "fmi3InstantiateCoSimulation") => {
                Some(no_instantiate_co_simulation as *mut c_void)
            }
            (true, "fmi3DoStep") => Some(no_do_step as *mut c_void),
            _ => None,
        })
        .map_err(missing)?;
        let me = match model_exchange {
            true => Some(Me3Api::resolve(&lib).map_err(missing)?),
            false => None,
        };
        let version = unsafe { super::version_text((api.get_version)()) };
        if !version.starts_with("3.") {
            return Err(FmuError::Load {
                path: path.to_path_buf(),
                message: format!("fmi3GetVersion returned '{version}', expected '3.0'"),
            });
        }
        Ok(Library3 {
            path: path.to_path_buf(),
            version,
            api,
            me,
            _lib: lib,
        })
    }
}

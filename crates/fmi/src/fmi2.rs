//! FMI 2.0 C types and function signatures (fmi2TypesPlatform.h, fmi2FunctionTypes.h).
//!
//! Shared by the export side (our models) and the importer; [`crate::functions`] lists every
//! function with its type. Status and
//! enumeration values are plain integers wrapped in `repr(transparent)` structs: a foreign
//! FMU may return any integer, and an out-of-range Rust enum would be undefined behaviour.
#![allow(non_camel_case_types, non_snake_case, non_upper_case_globals)]

use std::os::raw::{c_char, c_int, c_uint, c_void};

pub type fmi2Component = *mut c_void;
pub type fmi2ComponentEnvironment = *mut c_void;
pub type fmi2FMUstate = *mut c_void;
pub type fmi2ValueReference = c_uint;
pub type fmi2Real = f64;
pub type fmi2Integer = c_int;
pub type fmi2Boolean = c_int;
pub type fmi2Char = c_char;
pub type fmi2String = *const fmi2Char;
pub type fmi2Byte = c_char;

pub const fmi2True: fmi2Boolean = 1;
pub const fmi2False: fmi2Boolean = 0;

/// A C enumeration of FMI 2.0: a `c_int` in a `repr(transparent)` struct, with a constant
/// for each value the standard names.
macro_rules! c_enum {
    ($(#[$meta:meta])* $name:ident { $($value:ident = $n:literal,)* }) => {
        $(#[$meta])*
        #[repr(transparent)]
        pub struct $name(pub c_int);

        impl $name {
            $(pub const $value: Self = Self($n);)*
        }
    };
}

c_enum! {
    /// `fmi2Status`.
    #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
    fmi2Status { OK = 0, WARNING = 1, DISCARD = 2, ERROR = 3, FATAL = 4, PENDING = 5, }
}

impl fmi2Status {
    /// The name used in FMI log categories and messages.
    pub fn name(self) -> &'static str {
        match self.0 {
            0 => "fmi2OK",
            1 => "fmi2Warning",
            2 => "fmi2Discard",
            3 => "fmi2Error",
            4 => "fmi2Fatal",
            5 => "fmi2Pending",
            _ => "unknown fmi2Status",
        }
    }
}

c_enum! {
    /// `fmi2Type`.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    fmi2Type { MODEL_EXCHANGE = 0, CO_SIMULATION = 1, }
}

c_enum! {
    /// `fmi2StatusKind`.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    fmi2StatusKind {
        DO_STEP_STATUS = 0,
        PENDING_STATUS = 1,
        LAST_SUCCESSFUL_TIME = 2,
        TERMINATED = 3,
    }
}

/// The variadic logger; `message` is a printf format string.
pub type fmi2CallbackLogger = unsafe extern "C" fn(
    componentEnvironment: fmi2ComponentEnvironment,
    instanceName: fmi2String,
    status: fmi2Status,
    category: fmi2String,
    message: fmi2String,
    ...
);
pub type fmi2CallbackAllocateMemory = unsafe extern "C" fn(nobj: usize, size: usize) -> *mut c_void;
pub type fmi2CallbackFreeMemory = unsafe extern "C" fn(obj: *mut c_void);
pub type fmi2StepFinished =
    unsafe extern "C" fn(componentEnvironment: fmi2ComponentEnvironment, status: fmi2Status);

#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct fmi2CallbackFunctions {
    pub logger: Option<fmi2CallbackLogger>,
    pub allocateMemory: Option<fmi2CallbackAllocateMemory>,
    pub freeMemory: Option<fmi2CallbackFreeMemory>,
    pub stepFinished: Option<fmi2StepFinished>,
    pub componentEnvironment: fmi2ComponentEnvironment,
}

// Function types of every FMI 2.0 function a Co-Simulation FMU exports.
pub type fmi2GetTypesPlatformTYPE = unsafe extern "C" fn() -> *const c_char;
pub type fmi2GetVersionTYPE = unsafe extern "C" fn() -> *const c_char;
pub type fmi2SetDebugLoggingTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2Boolean, usize, *const fmi2String) -> fmi2Status;
pub type fmi2InstantiateTYPE = unsafe extern "C" fn(
    fmi2String,
    fmi2Type,
    fmi2String,
    fmi2String,
    *const fmi2CallbackFunctions,
    fmi2Boolean,
    fmi2Boolean,
) -> fmi2Component;
pub type fmi2FreeInstanceTYPE = unsafe extern "C" fn(fmi2Component);
pub type fmi2SetupExperimentTYPE = unsafe extern "C" fn(
    fmi2Component,
    fmi2Boolean,
    fmi2Real,
    fmi2Real,
    fmi2Boolean,
    fmi2Real,
) -> fmi2Status;
pub type fmi2EnterInitializationModeTYPE = unsafe extern "C" fn(fmi2Component) -> fmi2Status;
pub type fmi2ExitInitializationModeTYPE = unsafe extern "C" fn(fmi2Component) -> fmi2Status;
pub type fmi2TerminateTYPE = unsafe extern "C" fn(fmi2Component) -> fmi2Status;
pub type fmi2ResetTYPE = unsafe extern "C" fn(fmi2Component) -> fmi2Status;
/// `fmi2Get<Type>` and `fmi2Set<Type>`: the values of `nvr` value references at `value`
/// (`*mut T` to get, `*const T` to set).
pub type fmi2ValuesTYPE<P> =
    unsafe extern "C" fn(fmi2Component, *const fmi2ValueReference, usize, P) -> fmi2Status;
pub type fmi2GetTYPE<T> = fmi2ValuesTYPE<*mut T>;
pub type fmi2SetTYPE<T> = fmi2ValuesTYPE<*const T>;
pub type fmi2GetRealTYPE = fmi2GetTYPE<fmi2Real>;
pub type fmi2GetIntegerTYPE = fmi2GetTYPE<fmi2Integer>;
pub type fmi2GetBooleanTYPE = fmi2GetTYPE<fmi2Boolean>;
pub type fmi2GetStringTYPE = fmi2GetTYPE<fmi2String>;
pub type fmi2SetRealTYPE = fmi2SetTYPE<fmi2Real>;
pub type fmi2SetIntegerTYPE = fmi2SetTYPE<fmi2Integer>;
pub type fmi2SetBooleanTYPE = fmi2SetTYPE<fmi2Boolean>;
pub type fmi2SetStringTYPE = fmi2SetTYPE<fmi2String>;
pub type fmi2GetFMUstateTYPE = unsafe extern "C" fn(fmi2Component, *mut fmi2FMUstate) -> fmi2Status;
pub type fmi2SetFMUstateTYPE = unsafe extern "C" fn(fmi2Component, fmi2FMUstate) -> fmi2Status;
pub type fmi2FreeFMUstateTYPE =
    unsafe extern "C" fn(fmi2Component, *mut fmi2FMUstate) -> fmi2Status;
pub type fmi2SerializedFMUstateSizeTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2FMUstate, *mut usize) -> fmi2Status;
pub type fmi2SerializeFMUstateTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2FMUstate, *mut fmi2Byte, usize) -> fmi2Status;
pub type fmi2DeSerializeFMUstateTYPE =
    unsafe extern "C" fn(fmi2Component, *const fmi2Byte, usize, *mut fmi2FMUstate) -> fmi2Status;
pub type fmi2GetDirectionalDerivativeTYPE = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *const fmi2ValueReference,
    usize,
    *const fmi2Real,
    *mut fmi2Real,
) -> fmi2Status;
pub type fmi2SetRealInputDerivativesTYPE = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *const fmi2Integer,
    *const fmi2Real,
) -> fmi2Status;
pub type fmi2GetRealOutputDerivativesTYPE = unsafe extern "C" fn(
    fmi2Component,
    *const fmi2ValueReference,
    usize,
    *const fmi2Integer,
    *mut fmi2Real,
) -> fmi2Status;
pub type fmi2DoStepTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean) -> fmi2Status;
pub type fmi2CancelStepTYPE = unsafe extern "C" fn(fmi2Component) -> fmi2Status;
pub type fmi2GetStatusTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2StatusKind, *mut fmi2Status) -> fmi2Status;
pub type fmi2GetRealStatusTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2StatusKind, *mut fmi2Real) -> fmi2Status;
pub type fmi2GetIntegerStatusTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2StatusKind, *mut fmi2Integer) -> fmi2Status;
pub type fmi2GetBooleanStatusTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2StatusKind, *mut fmi2Boolean) -> fmi2Status;
pub type fmi2GetStringStatusTYPE =
    unsafe extern "C" fn(fmi2Component, fmi2StatusKind, *mut fmi2String) -> fmi2Status;

// Model Exchange (FMI 2.0 §3.2): the event information and the functions of the interface.

/// `fmi2EventInfo`, filled by `fmi2NewDiscreteStates` (FMI 2.0 §3.2.2).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct fmi2EventInfo {
    pub newDiscreteStatesNeeded: fmi2Boolean,
    pub terminateSimulation: fmi2Boolean,
    pub nominalsOfContinuousStatesChanged: fmi2Boolean,
    pub valuesOfContinuousStatesChanged: fmi2Boolean,
    pub nextEventTimeDefined: fmi2Boolean,
    pub nextEventTime: fmi2Real,
}

pub type fmi2EnterEventModeTYPE = unsafe extern "C" fn(fmi2Component) -> fmi2Status;
pub type fmi2NewDiscreteStatesTYPE =
    unsafe extern "C" fn(fmi2Component, *mut fmi2EventInfo) -> fmi2Status;
pub type fmi2EnterContinuousTimeModeTYPE = unsafe extern "C" fn(fmi2Component) -> fmi2Status;
pub type fmi2CompletedIntegratorStepTYPE = unsafe extern "C" fn(
    fmi2Component,
    fmi2Boolean,
    *mut fmi2Boolean,
    *mut fmi2Boolean,
) -> fmi2Status;
pub type fmi2SetTimeTYPE = unsafe extern "C" fn(fmi2Component, fmi2Real) -> fmi2Status;
pub type fmi2SetContinuousStatesTYPE =
    unsafe extern "C" fn(fmi2Component, *const fmi2Real, usize) -> fmi2Status;
/// `fmi2GetDerivatives`, `fmi2GetEventIndicators`, `fmi2GetContinuousStates` and
/// `fmi2GetNominalsOfContinuousStates` share this type.
pub type fmi2GetRealVectorTYPE =
    unsafe extern "C" fn(fmi2Component, *mut fmi2Real, usize) -> fmi2Status;

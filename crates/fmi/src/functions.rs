//! The FMI 2.0 Co-Simulation function table: every function's C symbol, its C type, whether a
//! Co-Simulation FMU must export it, and the states of the instance in which twinbench's
//! FMUs accept it. One table drives the export runtime's call-order checks, the importer's
//! symbol loading, the isolation worker's protocol and the tests.

use std::fmt;

/// Where an instance is in the FMI 2.0 Co-Simulation state machine (FMI 2.0 §4.2.4).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Phase {
    Instantiated = 0,
    InitializationMode = 1,
    StepComplete = 2,
    Terminated = 3,
    Error = 4,
}

impl Phase {
    pub const ALL: [Phase; 5] = [
        Phase::Instantiated,
        Phase::InitializationMode,
        Phase::StepComplete,
        Phase::Terminated,
        Phase::Error,
    ];

    /// The name messages use.
    pub const fn name(self) -> &'static str {
        match self {
            Phase::Instantiated => "instantiated",
            Phase::InitializationMode => "initialization mode",
            Phase::StepComplete => "step complete",
            Phase::Terminated => "terminated",
            Phase::Error => "error",
        }
    }

    /// The phase with this number (serialized states).
    pub fn from_u8(x: u8) -> Option<Phase> {
        Phase::ALL.get(x as usize).copied()
    }
}

impl fmt::Display for Phase {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A set of phases (a bit per phase).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct PhaseSet(u8);

impl PhaseSet {
    pub const ANY: PhaseSet = PhaseSet(0b1_1111);

    pub const fn of(phases: &[Phase]) -> PhaseSet {
        let mut bits = 0u8;
        let mut i = 0;
        while i < phases.len() {
            bits |= 1 << phases[i] as u8;
            i += 1;
        }
        PhaseSet(bits)
    }

    #[inline]
    pub const fn contains(self, phase: Phase) -> bool {
        self.0 & (1 << phase as u8) != 0
    }

    /// The phases in the set, in the state machine's order.
    pub fn phases(self) -> impl Iterator<Item = Phase> {
        Phase::ALL.into_iter().filter(move |p| self.contains(*p))
    }

    /// "instantiated, initialization mode" (for messages).
    pub fn describe(self) -> String {
        self.phases()
            .map(Phase::name)
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// One row of the table.
#[derive(Clone, Copy, Debug)]
pub struct FunctionSpec {
    pub function: Function,
    /// The C symbol, e.g. `fmi2DoStep`.
    pub name: &'static str,
    /// A Co-Simulation FMU must export it (the others are optional by capability flags).
    pub required: bool,
    /// The phases in which twinbench's FMUs accept the call.
    pub allowed: PhaseSet,
}

macro_rules! fmi2_functions {
    ($( $variant:ident = $symbol:ident : $ty:ident, $req:ident, $allowed:expr; )*) => {
        /// An FMI 2.0 function (common and Co-Simulation), in the standard header's order.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        #[repr(u8)]
        pub enum Function {
            $($variant),*
        }

        /// Every FMI 2.0 function a Co-Simulation FMU can export, in [`Function`] order.
        pub const FUNCTIONS: &[FunctionSpec] = &[
            $(FunctionSpec {
                function: Function::$variant,
                name: stringify!($symbol),
                required: fmi2_functions!(@required $req),
                allowed: $allowed,
            }),*
        ];

        /// The functions of one loaded FMU library: required ones as function pointers,
        /// optional ones as `Option`. Built by [`Fmi2Api::resolve`] from [`FUNCTIONS`].
        #[cfg(feature = "import")]
        #[allow(non_snake_case)]
        pub struct Fmi2Api {
            $(pub $symbol: fmi2_functions!(@field $req $ty),)*
        }

        #[cfg(feature = "import")]
        impl Fmi2Api {
            /// Look every function of the table up with `lookup` (symbol name → address).
            /// Err: the first required function that is missing.
            pub fn resolve(
                mut lookup: impl FnMut(&FunctionSpec) -> Option<*mut std::ffi::c_void>,
            ) -> Result<Fmi2Api, &'static FunctionSpec> {
                Ok(Fmi2Api {
                    $($symbol: {
                        let spec = Function::$variant.spec();
                        let address = lookup(spec);
                        fmi2_functions!(@convert $req $ty, address, spec)
                    },)*
                })
            }
        }
    };
    (@required req) => { true };
    (@required opt) => { false };
    (@field req $ty:ident) => { $crate::fmi2::$ty };
    (@field opt $ty:ident) => { Option<$crate::fmi2::$ty> };
    (@convert req $ty:ident, $address:ident, $spec:ident) => {
        match $address {
            // SAFETY: the symbol has the standard's C type for this name.
            Some(p) if !p.is_null() => unsafe {
                std::mem::transmute::<*mut std::ffi::c_void, $crate::fmi2::$ty>(p)
            },
            _ => return Err($spec),
        }
    };
    (@convert opt $ty:ident, $address:ident, $spec:ident) => {
        match $address {
            Some(p) if !p.is_null() => Some(unsafe {
                std::mem::transmute::<*mut std::ffi::c_void, $crate::fmi2::$ty>(p)
            }),
            _ => None,
        }
    };
}

use Phase::*;

const GET: PhaseSet = PhaseSet::of(&[
    Instantiated,
    InitializationMode,
    StepComplete,
    Terminated,
    Error,
]);
const SET: PhaseSet = PhaseSet::of(&[Instantiated, InitializationMode, StepComplete]);

fmi2_functions! {
    GetTypesPlatform = fmi2GetTypesPlatform: fmi2GetTypesPlatformTYPE, req, PhaseSet::ANY;
    GetVersion = fmi2GetVersion: fmi2GetVersionTYPE, req, PhaseSet::ANY;
    SetDebugLogging = fmi2SetDebugLogging: fmi2SetDebugLoggingTYPE, req, PhaseSet::ANY;
    Instantiate = fmi2Instantiate: fmi2InstantiateTYPE, req, PhaseSet::ANY;
    FreeInstance = fmi2FreeInstance: fmi2FreeInstanceTYPE, req, PhaseSet::ANY;
    SetupExperiment = fmi2SetupExperiment: fmi2SetupExperimentTYPE, req, PhaseSet::of(&[Instantiated]);
    EnterInitializationMode = fmi2EnterInitializationMode: fmi2EnterInitializationModeTYPE, req, PhaseSet::of(&[Instantiated]);
    ExitInitializationMode = fmi2ExitInitializationMode: fmi2ExitInitializationModeTYPE, req, PhaseSet::of(&[InitializationMode]);
    Terminate = fmi2Terminate: fmi2TerminateTYPE, req, PhaseSet::of(&[StepComplete]);
    Reset = fmi2Reset: fmi2ResetTYPE, req, PhaseSet::ANY;
    GetReal = fmi2GetReal: fmi2GetRealTYPE, req, GET;
    GetInteger = fmi2GetInteger: fmi2GetIntegerTYPE, req, GET;
    GetBoolean = fmi2GetBoolean: fmi2GetBooleanTYPE, req, GET;
    GetString = fmi2GetString: fmi2GetStringTYPE, req, GET;
    SetReal = fmi2SetReal: fmi2SetRealTYPE, req, SET;
    SetInteger = fmi2SetInteger: fmi2SetIntegerTYPE, req, SET;
    SetBoolean = fmi2SetBoolean: fmi2SetBooleanTYPE, req, SET;
    SetString = fmi2SetString: fmi2SetStringTYPE, req, SET;
    GetFMUstate = fmi2GetFMUstate: fmi2GetFMUstateTYPE, opt, PhaseSet::ANY;
    SetFMUstate = fmi2SetFMUstate: fmi2SetFMUstateTYPE, opt, PhaseSet::ANY;
    FreeFMUstate = fmi2FreeFMUstate: fmi2FreeFMUstateTYPE, opt, PhaseSet::ANY;
    SerializedFMUstateSize = fmi2SerializedFMUstateSize: fmi2SerializedFMUstateSizeTYPE, opt, PhaseSet::ANY;
    SerializeFMUstate = fmi2SerializeFMUstate: fmi2SerializeFMUstateTYPE, opt, PhaseSet::ANY;
    DeSerializeFMUstate = fmi2DeSerializeFMUstate: fmi2DeSerializeFMUstateTYPE, opt, PhaseSet::ANY;
    GetDirectionalDerivative = fmi2GetDirectionalDerivative: fmi2GetDirectionalDerivativeTYPE, opt, PhaseSet::ANY;
    SetRealInputDerivatives = fmi2SetRealInputDerivatives: fmi2SetRealInputDerivativesTYPE, opt, PhaseSet::ANY;
    GetRealOutputDerivatives = fmi2GetRealOutputDerivatives: fmi2GetRealOutputDerivativesTYPE, opt, PhaseSet::ANY;
    DoStep = fmi2DoStep: fmi2DoStepTYPE, req, PhaseSet::of(&[StepComplete]);
    CancelStep = fmi2CancelStep: fmi2CancelStepTYPE, opt, PhaseSet::ANY;
    GetStatus = fmi2GetStatus: fmi2GetStatusTYPE, opt, PhaseSet::ANY;
    GetRealStatus = fmi2GetRealStatus: fmi2GetRealStatusTYPE, opt, PhaseSet::ANY;
    GetIntegerStatus = fmi2GetIntegerStatus: fmi2GetIntegerStatusTYPE, opt, PhaseSet::ANY;
    GetBooleanStatus = fmi2GetBooleanStatus: fmi2GetBooleanStatusTYPE, opt, PhaseSet::ANY;
    GetStringStatus = fmi2GetStringStatus: fmi2GetStringStatusTYPE, opt, PhaseSet::ANY;
}

impl Function {
    #[inline]
    pub const fn spec(self) -> &'static FunctionSpec {
        &FUNCTIONS[self as usize]
    }

    /// The C symbol's name, e.g. `fmi2DoStep`.
    #[inline]
    pub const fn name(self) -> &'static str {
        self.spec().name
    }

    #[inline]
    pub const fn allowed(self) -> PhaseSet {
        self.spec().allowed
    }

    /// The function with this number (wire codes).
    pub fn from_u8(x: u8) -> Option<Function> {
        FUNCTIONS.get(x as usize).map(|s| s.function)
    }

    /// The function with this C name.
    pub fn from_name(name: &str) -> Option<Function> {
        FUNCTIONS
            .iter()
            .find(|s| s.name == name)
            .map(|s| s.function)
    }
}

impl fmt::Display for Function {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_table_is_in_enum_order_and_names_are_unique() {
        for (i, s) in FUNCTIONS.iter().enumerate() {
            assert_eq!(s.function as usize, i, "{}", s.name);
            assert_eq!(Function::from_u8(i as u8), Some(s.function));
            assert_eq!(Function::from_name(s.name), Some(s.function));
        }
        assert_eq!(FUNCTIONS.len(), 34);
        assert_eq!(FUNCTIONS.iter().filter(|s| s.required).count(), 19);
        assert_eq!(Function::from_u8(34), None);
    }

    #[test]
    fn phase_sets_describe_themselves_in_state_order() {
        assert_eq!(
            Function::SetReal.allowed().describe(),
            "instantiated, initialization mode, step complete"
        );
        assert!(Function::DoStep.allowed().contains(Phase::StepComplete));
        assert!(!Function::DoStep.allowed().contains(Phase::Terminated));
        assert_eq!(PhaseSet::ANY.phases().count(), 5);
    }
}

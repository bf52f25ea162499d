//! A loaded FMU shared library with every FMI 2.0 symbol resolved once.

use super::FmuError;
use fmu_export::fmi2::*;
use std::path::{Path, PathBuf};

/// Function pointers of one FMI 2.0 Co-Simulation library. Functions the standard makes
/// optional through capability flags are `Option`.
#[allow(non_snake_case)]
pub struct Fmi2Api {
    pub fmi2GetTypesPlatform: fmi2GetTypesPlatformTYPE,
    pub fmi2GetVersion: fmi2GetVersionTYPE,
    pub fmi2SetDebugLogging: fmi2SetDebugLoggingTYPE,
    pub fmi2Instantiate: fmi2InstantiateTYPE,
    pub fmi2FreeInstance: fmi2FreeInstanceTYPE,
    pub fmi2SetupExperiment: fmi2SetupExperimentTYPE,
    pub fmi2EnterInitializationMode: fmi2EnterInitializationModeTYPE,
    pub fmi2ExitInitializationMode: fmi2ExitInitializationModeTYPE,
    pub fmi2Terminate: fmi2TerminateTYPE,
    pub fmi2Reset: fmi2ResetTYPE,
    pub fmi2GetReal: fmi2GetRealTYPE,
    pub fmi2GetInteger: fmi2GetIntegerTYPE,
    pub fmi2GetBoolean: fmi2GetBooleanTYPE,
    pub fmi2GetString: fmi2GetStringTYPE,
    pub fmi2SetReal: fmi2SetRealTYPE,
    pub fmi2SetInteger: fmi2SetIntegerTYPE,
    pub fmi2SetBoolean: fmi2SetBooleanTYPE,
    pub fmi2SetString: fmi2SetStringTYPE,
    pub fmi2DoStep: fmi2DoStepTYPE,
    pub fmi2GetFMUstate: Option<fmi2GetFMUstateTYPE>,
    pub fmi2SetFMUstate: Option<fmi2SetFMUstateTYPE>,
    pub fmi2FreeFMUstate: Option<fmi2FreeFMUstateTYPE>,
    pub fmi2SerializedFMUstateSize: Option<fmi2SerializedFMUstateSizeTYPE>,
    pub fmi2SerializeFMUstate: Option<fmi2SerializeFMUstateTYPE>,
    pub fmi2DeSerializeFMUstate: Option<fmi2DeSerializeFMUstateTYPE>,
    pub fmi2GetRealStatus: Option<fmi2GetRealStatusTYPE>,
    pub fmi2GetBooleanStatus: Option<fmi2GetBooleanStatusTYPE>,
}

pub struct Library {
    pub path: PathBuf,
    pub api: Fmi2Api,
    // Declared last: dropped after nothing can call through `api` any more.
    _lib: libloading::Library,
}

/// Load a shared library with RTLD_GLOBAL so that its symbols serve libraries loaded later
/// (FMUs built with pythonfmu need libpython loaded this way by a native host).
pub fn preload_global(path: &Path) -> Result<(), FmuError> {
    use libloading::os::unix::{Library as UnixLibrary, RTLD_GLOBAL, RTLD_NOW};
    let lib = unsafe { UnixLibrary::open(Some(path), RTLD_NOW | RTLD_GLOBAL) }.map_err(|e| {
        FmuError::Load {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    })?;
    // Kept for the life of the process: FMUs loaded later may depend on it.
    std::mem::forget(lib);
    Ok(())
}

impl Library {
    pub fn load(path: &Path) -> Result<Library, FmuError> {
        let lib = unsafe { libloading::Library::new(path) }.map_err(|e| FmuError::Load {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        macro_rules! req {
            ($name:ident) => {
                *unsafe { lib.get(concat!(stringify!($name), "\0").as_bytes()) }.map_err(|_| {
                    FmuError::MissingSymbol {
                        path: path.to_path_buf(),
                        symbol: stringify!($name),
                    }
                })?
            };
        }
        macro_rules! opt {
            ($name:ident) => {
                unsafe { lib.get(concat!(stringify!($name), "\0").as_bytes()) }
                    .ok()
                    .map(|s| *s)
            };
        }
        let api = Fmi2Api {
            fmi2GetTypesPlatform: req!(fmi2GetTypesPlatform),
            fmi2GetVersion: req!(fmi2GetVersion),
            fmi2SetDebugLogging: req!(fmi2SetDebugLogging),
            fmi2Instantiate: req!(fmi2Instantiate),
            fmi2FreeInstance: req!(fmi2FreeInstance),
            fmi2SetupExperiment: req!(fmi2SetupExperiment),
            fmi2EnterInitializationMode: req!(fmi2EnterInitializationMode),
            fmi2ExitInitializationMode: req!(fmi2ExitInitializationMode),
            fmi2Terminate: req!(fmi2Terminate),
            fmi2Reset: req!(fmi2Reset),
            fmi2GetReal: req!(fmi2GetReal),
            fmi2GetInteger: req!(fmi2GetInteger),
            fmi2GetBoolean: req!(fmi2GetBoolean),
            fmi2GetString: req!(fmi2GetString),
            fmi2SetReal: req!(fmi2SetReal),
            fmi2SetInteger: req!(fmi2SetInteger),
            fmi2SetBoolean: req!(fmi2SetBoolean),
            fmi2SetString: req!(fmi2SetString),
            fmi2DoStep: req!(fmi2DoStep),
            fmi2GetFMUstate: opt!(fmi2GetFMUstate),
            fmi2SetFMUstate: opt!(fmi2SetFMUstate),
            fmi2FreeFMUstate: opt!(fmi2FreeFMUstate),
            fmi2SerializedFMUstateSize: opt!(fmi2SerializedFMUstateSize),
            fmi2SerializeFMUstate: opt!(fmi2SerializeFMUstate),
            fmi2DeSerializeFMUstate: opt!(fmi2DeSerializeFMUstate),
            fmi2GetRealStatus: opt!(fmi2GetRealStatus),
            fmi2GetBooleanStatus: opt!(fmi2GetBooleanStatus),
        };
        let version = unsafe { std::ffi::CStr::from_ptr((api.fmi2GetVersion)()) }
            .to_string_lossy()
            .into_owned();
        if version != "2.0" {
            return Err(FmuError::Load {
                path: path.to_path_buf(),
                message: format!("fmi2GetVersion returned '{version}', expected '2.0'"),
            });
        }
        Ok(Library {
            path: path.to_path_buf(),
            api,
            _lib: lib,
        })
    }

    /// Whether the library exports `symbol` (for tests and `twinbench info`).
    pub fn has_symbol(path: &Path, symbol: &str) -> bool {
        match unsafe { libloading::Library::new(path) } {
            Ok(lib) => unsafe { lib.get::<*const ()>(format!("{symbol}\0").as_bytes()) }.is_ok(),
            Err(_) => false,
        }
    }
}

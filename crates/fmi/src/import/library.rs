//! A loaded FMU shared library with the function table resolved once.

use crate::fmi2::*;
use crate::functions::{Fmi2Api, Function};
use crate::FmuError;
use std::path::{Path, PathBuf};

pub struct Library {
    pub path: PathBuf,
    /// What `fmi2GetVersion` returned ("2.0": anything else is refused).
    pub version: String,
    /// The optional functions of [`crate::FUNCTIONS`] the library does not export.
    pub missing_optional: Vec<&'static str>,
    pub api: Fmi2Api,
    /// The Model Exchange functions, when loaded for Model Exchange
    /// ([`Library::load_model_exchange`]).
    pub me: Option<MeApi>,
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

/// The functions of the FMI 2.0 Model Exchange interface (FMI 2.0 §3.2.1), each required of
/// an FMU that declares `<ModelExchange>`.
#[derive(Clone, Copy)]
#[allow(non_snake_case)]
pub struct MeApi {
    pub fmi2EnterEventMode: fmi2EnterEventModeTYPE,
    pub fmi2NewDiscreteStates: fmi2NewDiscreteStatesTYPE,
    pub fmi2EnterContinuousTimeMode: fmi2EnterContinuousTimeModeTYPE,
    pub fmi2CompletedIntegratorStep: fmi2CompletedIntegratorStepTYPE,
    pub fmi2SetTime: fmi2SetTimeTYPE,
    pub fmi2SetContinuousStates: fmi2SetContinuousStatesTYPE,
    pub fmi2GetDerivatives: fmi2GetRealVectorTYPE,
    pub fmi2GetEventIndicators: fmi2GetRealVectorTYPE,
    pub fmi2GetContinuousStates: fmi2GetRealVectorTYPE,
    pub fmi2GetNominalsOfContinuousStates: fmi2GetRealVectorTYPE,
}

/// The symbols of [`MeApi`], in its order.
pub const ME_FUNCTIONS: [&str; 10] = [
    "fmi2EnterEventMode",
    "fmi2NewDiscreteStates",
    "fmi2EnterContinuousTimeMode",
    "fmi2CompletedIntegratorStep",
    "fmi2SetTime",
    "fmi2SetContinuousStates",
    "fmi2GetDerivatives",
    "fmi2GetEventIndicators",
    "fmi2GetContinuousStates",
    "fmi2GetNominalsOfContinuousStates",
];

impl MeApi {
    /// Every Model Exchange function from `lib`; Err: the first one missing.
    fn resolve(lib: &libloading::Library) -> Result<MeApi, &'static str> {
        let mut addresses = [std::ptr::null_mut::<std::ffi::c_void>(); ME_FUNCTIONS.len()];
        for (slot, symbol) in addresses.iter_mut().zip(ME_FUNCTIONS) {
            *slot = unsafe { lib.get::<*mut std::ffi::c_void>(format!("{symbol}\0").as_bytes()) }
                .ok()
                .map(|s| *s)
                .filter(|p| !p.is_null())
                .ok_or(symbol)?;
        }
        // SAFETY: each symbol has the standard's C type for its name (fmi2FunctionTypes.h).
        unsafe {
            use std::mem::transmute as f;
            let a = addresses;
            Ok(MeApi {
                fmi2EnterEventMode: f::<*mut std::ffi::c_void, fmi2EnterEventModeTYPE>(a[0]),
                fmi2NewDiscreteStates: f::<*mut std::ffi::c_void, fmi2NewDiscreteStatesTYPE>(a[1]),
                fmi2EnterContinuousTimeMode: f::<
                    *mut std::ffi::c_void,
                    fmi2EnterContinuousTimeModeTYPE,
                >(a[2]),
                fmi2CompletedIntegratorStep: f::<
                    *mut std::ffi::c_void,
                    fmi2CompletedIntegratorStepTYPE,
                >(a[3]),
                fmi2SetTime: f::<*mut std::ffi::c_void, fmi2SetTimeTYPE>(a[4]),
                fmi2SetContinuousStates: f::<*mut std::ffi::c_void, fmi2SetContinuousStatesTYPE>(
                    a[5],
                ),
                fmi2GetDerivatives: f::<*mut std::ffi::c_void, fmi2GetRealVectorTYPE>(a[6]),
                fmi2GetEventIndicators: f::<*mut std::ffi::c_void, fmi2GetRealVectorTYPE>(a[7]),
                fmi2GetContinuousStates: f::<*mut std::ffi::c_void, fmi2GetRealVectorTYPE>(a[8]),
                fmi2GetNominalsOfContinuousStates: f::<*mut std::ffi::c_void, fmi2GetRealVectorTYPE>(
                    a[9],
                ),
            })
        }
    }
}

/// Stands in for `fmi2DoStep` in a library loaded for Model Exchange that does not export
/// it (an FMU without Co-Simulation need not): never called, as a Model Exchange instance
/// is stepped by twinbench's integrator; an error if it ever were.
unsafe extern "C" fn no_do_step(
    _c: fmi2Component,
    _t: fmi2Real,
    _h: fmi2Real,
    _new_step: fmi2Boolean,
) -> fmi2Status {
    fmi2Status::ERROR
}

impl Library {
    /// Load the library, resolve every function of [`crate::FUNCTIONS`] (the required ones
    /// must be there) and check `fmi2GetVersion`.
    pub fn load(path: &Path) -> Result<Library, FmuError> {
        Self::load_as(path, false)
    }

    /// Load the library for Model Exchange: the common functions as [`Library::load`] and
    /// every Model Exchange function ([`MeApi`]); `fmi2DoStep`, a Co-Simulation function,
    /// may be missing. A missing function is named ([`FmuError::MissingSymbol`]).
    pub fn load_model_exchange(path: &Path) -> Result<Library, FmuError> {
        Self::load_as(path, true)
    }

    fn load_as(path: &Path, model_exchange: bool) -> Result<Library, FmuError> {
        let lib = super::open_library(path)?;
        let mut missing_optional = Vec::new();
        let api = Fmi2Api::resolve(|spec| {
            let symbol = format!("{}\0", spec.name);
            let address = unsafe { lib.get::<*mut std::ffi::c_void>(symbol.as_bytes()) }
                .ok()
                .map(|s| *s)
                .filter(|p| !p.is_null());
            if address.is_none() && !spec.required {
                missing_optional.push(spec.name);
            }
            if address.is_none() && model_exchange && spec.function == Function::DoStep {
                return Some(no_do_step as *mut std::ffi::c_void);
            }
            address
        })
        .map_err(|spec| FmuError::MissingSymbol {
            path: path.to_path_buf(),
            symbol: spec.name,
        })?;
        let me = match model_exchange {
            true => Some(
                MeApi::resolve(&lib).map_err(|symbol| FmuError::MissingSymbol {
                    path: path.to_path_buf(),
                    symbol,
                })?,
            ),
            false => None,
        };
        let version = unsafe { super::version_text((api.fmi2GetVersion)()) };
        if version != "2.0" {
            return Err(FmuError::Load {
                path: path.to_path_buf(),
                message: format!("fmi2GetVersion returned '{version}', expected '2.0'"),
            });
        }
        Ok(Library {
            path: path.to_path_buf(),
            version,
            missing_optional,
            api,
            me,
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

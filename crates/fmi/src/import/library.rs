//! A loaded FMU shared library with the function table resolved once.

use crate::functions::Fmi2Api;
use crate::FmuError;
use std::path::{Path, PathBuf};

pub struct Library {
    pub path: PathBuf,
    /// What `fmi2GetVersion` returned ("2.0": anything else is refused).
    pub version: String,
    /// The optional functions of [`crate::FUNCTIONS`] the library does not export.
    pub missing_optional: Vec<&'static str>,
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
    /// Load the library, resolve every function of [`crate::FUNCTIONS`] (the required ones
    /// must be there) and check `fmi2GetVersion`.
    pub fn load(path: &Path) -> Result<Library, FmuError> {
        super::check_elf(path)?;
        let lib = unsafe { libloading::Library::new(path) }.map_err(|e| FmuError::Load {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
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
            address
        })
        .map_err(|spec| FmuError::MissingSymbol {
            path: path.to_path_buf(),
            symbol: spec.name,
        })?;
        let version = unsafe { (api.fmi2GetVersion)() };
        let version = if version.is_null() {
            "NULL".to_string()
        } else {
            unsafe { std::ffi::CStr::from_ptr(version) }
                .to_string_lossy()
                .into_owned()
        };
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

//! Models linked into twinbench and called directly, without the FMI boundary: the same
//! [`fmu_export::Runtime`] state machine the FMUs run (same checks, same code), driven
//! through Rust calls instead of `fmi2*` C symbols. It is the floor that the orchestration
//! overhead of the FMU backend is measured against, and it must give bit-identical results
//! (tests/native.rs).
//!
//! The host decides which models are linked (a list of [`NativeModel`], the host's model
//! registry); an instance runs natively when its FMU's `modelName` is one of them and the
//! FMU's GUID matches the linked crate's (the GUID hashes the variable interface). The
//! resources are the unpacked FMU's `resources/` folder, as for the FMU itself.
//!
//! This module needs nothing of the export framework (`fmu-export`): the backend that runs
//! a linked model ([`backend`], the `native` feature, on by default) does.

use super::backend::{Backend, BackendFactory};
use std::path::PathBuf;
use tb_fmi::{FmuError, LoadedFmu};

#[cfg(feature = "native")]
pub mod backend;
#[cfg(feature = "native")]
pub use backend::NativeBackend;

/// Creates one boxed native instance: (instance name, resource folder, logging, the
/// independent variable `time` of an FMI 3.0 FMU exposed).
type Create = fn(&str, Option<PathBuf>, bool, bool) -> Box<dyn Backend>;

/// A model linked into the host: one row of the host's model registry.
#[derive(Clone, Copy)]
pub struct NativeModel {
    /// The model's name (`modelName` of its FMU).
    pub name: &'static str,
    /// The GUID its FMI 2.0 FMU carries when built from the linked sources.
    pub guid: fn() -> String,
    /// The instantiation token its FMI 3.0 FMU carries (the same table, another version).
    pub token: fn() -> String,
    create: Create,
}

impl std::fmt::Debug for NativeModel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("NativeModel")
            .field("name", &self.name)
            .finish()
    }
}

/// Creates the native instances of one linked model, with the FMU's resources.
pub struct NativeFactory {
    model: &'static str,
    resource_dir: PathBuf,
    create: Create,
    /// In place of an FMI 3.0 FMU: its independent variable `time` is read as the FMU's.
    fmi3: bool,
}

/// Why an FMU has no native twin (it then runs as an FMU).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NoTwin {
    /// `linked`: the names of the models linked in.
    #[error("{}: model '{model}' is not linked into twinbench (native models: {linked})", fmu.display())]
    NotLinked {
        fmu: PathBuf,
        model: String,
        linked: String,
    },
    /// `what`: the GUID (FMI 2.0) or the instantiation token (FMI 3.0).
    #[error("{}: {what} {theirs} differs from the linked '{model}' model's {ours} (the FMU was built from other sources; repack it)", fmu.display())]
    Differs {
        fmu: PathBuf,
        what: &'static str,
        theirs: String,
        model: &'static str,
        ours: String,
    },
}

impl NativeFactory {
    /// The native twin of an FMU among the `linked` models, or why there is none.
    pub fn for_fmu(fmu: &LoadedFmu, linked: &[NativeModel]) -> Result<NativeFactory, NoTwin> {
        let name = fmu.description.model_name.as_str();
        let Some(m) = linked.iter().find(|m| m.name == name) else {
            return Err(NoTwin::NotLinked {
                fmu: fmu.source.clone(),
                model: name.into(),
                linked: linked.iter().map(|m| m.name).collect::<Vec<_>>().join(", "),
            });
        };
        // An FMI 3.0 FMU of the model has the same variables under the same value
        // references, and `time` one past them, which the native instance then exposes.
        let (what, guid) = match fmu.is_fmi3() {
            true => ("instantiation token", (m.token)()),
            false => ("GUID", (m.guid)()),
        };
        if fmu.description.guid != guid {
            return Err(NoTwin::Differs {
                fmu: fmu.source.clone(),
                what,
                theirs: fmu.description.guid.clone(),
                model: m.name,
                ours: guid.to_string(),
            });
        }
        Ok(NativeFactory {
            model: m.name,
            resource_dir: fmu.resource_dir(),
            create: m.create,
            fmi3: fmu.is_fmi3(),
        })
    }

    pub fn model(&self) -> &'static str {
        self.model
    }
}

impl BackendFactory for NativeFactory {
    fn kind(&self) -> &'static str {
        "native"
    }
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError> {
        // Same resource rule as the FFI layer: a missing folder is passed as is (the model
        // reports what it cannot find).
        let mut b = (self.create)(
            instance_name,
            Some(self.resource_dir.clone()),
            logging,
            self.fmi3,
        );
        if logging {
            b.set_debug_logging(true)?;
        }
        Ok(b)
    }
}

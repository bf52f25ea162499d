//! What the master drives: a running co-simulation unit behind one small trait, so that an
//! FMU loaded in-process, a model linked natively, or an FMU isolated in a worker process
//! are interchangeable. Each system instance has a factory that creates (and recreates)
//! its unit.

use std::sync::Arc;
use tb_fmi::{FmuError, Instance, Instance3, Interface, LoadedFmu, MeInstance, MeSettings};

/// One running instance: tb-fmi's one seam, [`tb_fmi::FmuInstance`]. The FMI 2.0 and 3.0
/// Co-Simulation instances and the Model Exchange instance implement it where their calls
/// are; the natively linked model, the isolated worker and the call trace implement it here.
pub use tb_fmi::FmuInstance as Backend;

/// Creates the running unit of one system instance.
pub trait BackendFactory: Send + Sync {
    /// "fmu", "native", "isolated", ...
    fn kind(&self) -> &'static str;
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError>;
}

/// How an instance runs its FMU: through which interface and, for Model Exchange, with
/// which solver settings. The isolated worker is given the same, so that it runs the same
/// backend (the whole integration happens in the worker).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RunAs {
    pub interface: Interface,
    pub me: MeSettings,
}

impl RunAs {
    /// The FMU's default interface (Co-Simulation when it has it), default settings.
    pub fn default_for(fmu: &LoadedFmu) -> RunAs {
        RunAs {
            interface: fmu.default_interface(),
            me: MeSettings::default(),
        }
    }
}

/// The default: the FMU's shared library loaded in this process.
pub struct FmuFactory {
    pub fmu: Arc<LoadedFmu>,
    pub run: RunAs,
}

impl FmuFactory {
    /// Through the FMU's default interface.
    pub fn new(fmu: Arc<LoadedFmu>) -> FmuFactory {
        let run = RunAs::default_for(&fmu);
        FmuFactory { fmu, run }
    }
}

/// A Model Exchange instance of `fmu` in this process (its library loaded for Model
/// Exchange), debug logging on when asked.
pub fn model_exchange(
    fmu: &LoadedFmu,
    instance_name: &str,
    logging: bool,
    settings: MeSettings,
) -> Result<MeInstance, FmuError> {
    let mut inst = MeInstance::instantiate(
        fmu.library_me()?,
        &fmu.description,
        &fmu.source,
        instance_name,
        Some(&fmu.resource_dir()),
        logging,
        settings,
    )?;
    if logging {
        inst.set_debug_logging(true)?;
    }
    Ok(inst)
}

impl BackendFactory for FmuFactory {
    fn kind(&self) -> &'static str {
        "fmu"
    }
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError> {
        let fmu = &self.fmu;
        if self.run.interface == Interface::ModelExchange {
            let inst = model_exchange(fmu, instance_name, logging, self.run.me)?;
            return Ok(Box::new(inst));
        }
        if fmu.is_fmi3() {
            let mut inst = Instance3::instantiate(
                fmu.library3()?,
                &fmu.description,
                instance_name,
                Some(&fmu.resource_dir()),
                logging,
            )?;
            if logging {
                inst.set_debug_logging(true)?;
            }
            return Ok(Box::new(inst));
        }
        let mut inst = Instance::instantiate(
            fmu.library()?,
            instance_name,
            &fmu.description.guid,
            Some(&fmu.resource_dir()),
            logging,
        )?;
        if logging {
            inst.set_debug_categories(true, &[])?;
        }
        Ok(Box::new(inst))
    }
}

//! What a model may know of its instance: its name, its resource folder, the start time, and
//! the resources it parsed (kept across re-initialisation and fmi2Reset).

use crate::error::ModelError;
use crate::resources::read_text;
use std::any::Any;
use std::collections::HashMap;
use std::fmt;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

/// Parsed resources of one instance, kept across re-initialisation and fmi2Reset: a host
/// that resets and reruns (an optimiser) or iterates initialisation does not re-parse files.
#[derive(Clone, Default)]
pub struct ResourceCache(Arc<Mutex<HashMap<String, Arc<dyn Any + Send + Sync>>>>);

impl fmt::Debug for ResourceCache {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let n = self.0.lock().map(|m| m.len()).unwrap_or(0);
        write!(f, "ResourceCache({n} entries)")
    }
}

/// What a model may know of its instance.
#[derive(Clone, Debug, Default)]
pub struct Context {
    pub instance_name: String,
    /// The FMU's unpacked `resources/` folder (from `fmuResourceLocation`), if given.
    pub resource_dir: Option<PathBuf>,
    /// `startTime` of fmi2SetupExperiment.
    pub start_time: f64,
    /// Parsed resources, shared by re-initialisations of this instance.
    pub cache: ResourceCache,
}

impl Context {
    /// Path of a resource file; a clear error when the host gave no resource location.
    pub fn resource(&self, name: &str) -> Result<PathBuf, ModelError> {
        match &self.resource_dir {
            Some(dir) => Ok(dir.join(name)),
            None => Err(ModelError::new(format!(
                "resource '{name}' needed but the host passed no fmuResourceLocation"
            ))),
        }
    }

    /// A resource parsed once per instance: `load` runs on the first request for `key`
    /// (and again only if it failed).
    pub fn cached<T: Any + Send + Sync>(
        &self,
        key: &str,
        load: impl FnOnce() -> Result<T, ModelError>,
    ) -> Result<Arc<T>, ModelError> {
        if let Some(hit) = self.cache.0.lock().ok().and_then(|m| m.get(key).cloned()) {
            if let Ok(t) = hit.downcast::<T>() {
                return Ok(t);
            }
        }
        let value = Arc::new(load()?);
        if let Ok(mut m) = self.cache.0.lock() {
            m.insert(key.to_string(), value.clone());
        }
        Ok(value)
    }

    /// A resource file's text, with the path in the error.
    pub fn read_resource(&self, name: &str) -> Result<(PathBuf, String), ModelError> {
        let path = self.resource(name)?;
        let text = read_text(&path)?;
        Ok((path, text))
    }
}

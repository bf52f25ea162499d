//! The safe trait a model crate implements. No FFI here: the runtime and the generated
//! entry points call these methods.

use crate::variables::VarTable;
use std::any::Any;
use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};
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

/// Static facts about a model, written to modelDescription.xml and the documentation.
#[derive(Clone, Copy, Debug)]
pub struct ModelInfo {
    /// `modelName` and the FMU file name (`<name>.fmu`).
    pub name: &'static str,
    /// `modelIdentifier`: the shared library's name and the C symbol prefix.
    pub identifier: &'static str,
    pub description: &'static str,
    pub version: &'static str,
    pub default_experiment: DefaultExperiment,
    /// HTML fragment for documentation/index.html: equations and notes.
    pub documentation: &'static str,
    /// Files (relative to the model crate) shipped in the FMU's `resources/`.
    pub resources: &'static [Resource],
}

/// A file shipped in `resources/`: its name there and its content.
#[derive(Clone, Copy, Debug)]
pub struct Resource {
    pub name: &'static str,
    pub content: &'static [u8],
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DefaultExperiment {
    pub start_time: f64,
    pub stop_time: f64,
    pub step_size: f64,
}

/// How bad a [`ModelError`] is, i.e. the FMI status the runtime returns for it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Severity {
    /// fmi2Error: the instance is in the error state (reset or restore to go on).
    #[default]
    Error,
    /// fmi2Discard: the step was not completed (e.g. a solver gave up); the instance stays
    /// usable for reading, terminating or restoring a state, and the host decides.
    Discard,
    /// fmi2Fatal: the model's computations are irreparably corrupted.
    Fatal,
}

/// An error from a model: the message names the variable, file or row at fault.
#[derive(Clone, Debug, PartialEq)]
pub struct ModelError(pub String, pub Severity);

impl ModelError {
    /// An error (fmi2Error).
    pub fn new(msg: impl Into<String>) -> Self {
        ModelError(msg.into(), Severity::Error)
    }
    /// The step could not be completed (fmi2Discard from fmi2DoStep).
    pub fn discard(msg: impl Into<String>) -> Self {
        ModelError(msg.into(), Severity::Discard)
    }
    /// The model is irreparably corrupted (fmi2Fatal).
    pub fn fatal(msg: impl Into<String>) -> Self {
        ModelError(msg.into(), Severity::Fatal)
    }
    pub fn severity(&self) -> Severity {
        self.1
    }
}

impl fmt::Display for ModelError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for ModelError {}

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

/// `s.rem_euclid(length)` for a distance on a closed lap, bit for bit, without libm's
/// `fmod` in the usual cases (it runs every step): s itself inside the lap, s − length on
/// the next lap (exact by Sterbenz's lemma, length ≤ s < 2·length).
#[inline]
pub fn wrap_distance(s: f64, length: f64) -> f64 {
    if (0.0..length).contains(&s) {
        s
    } else if s >= length && s < 2.0 * length {
        s - length
    } else {
        s.rem_euclid(length)
    }
}

/// The path a String parameter names: an absolute path or a `file://` URI. A relative path
/// is refused: the host resolves it (the orchestrator against the system file's folder).
pub fn parameter_path(parameter: &str, value: &str) -> Result<PathBuf, ModelError> {
    let path = if value.starts_with("file:") {
        crate::ffi::resource_dir_from_uri(value)
            .map_err(|e| ModelError::new(format!("'{parameter}': {e}")))?
    } else {
        PathBuf::from(value)
    };
    if !path.is_absolute() {
        return Err(ModelError::new(format!(
            "'{parameter}' = \"{value}\" is a relative path; give an absolute path or a file:// URI (twinbench resolves a relative path in a system file against the file's folder)"
        )));
    }
    Ok(path)
}

/// Files parsed once per process, by the parsed type, the path, its size and modification
/// time (an edited file is read again).
type SharedFiles = HashMap<
    (
        std::any::TypeId,
        PathBuf,
        u64,
        Option<std::time::SystemTime>,
    ),
    Arc<dyn Any + Send + Sync>,
>;

/// A data file parsed once per process and shared by every instance that names it (and kept
/// across re-initialisation and fmi2Reset): `parse(path, text)` runs on the first request.
pub fn shared_file<T: Any + Send + Sync>(
    path: &Path,
    parse: impl FnOnce(&Path, &str) -> Result<T, ModelError>,
) -> Result<Arc<T>, ModelError> {
    static FILES: std::sync::OnceLock<Mutex<SharedFiles>> = std::sync::OnceLock::new();
    let meta = std::fs::metadata(path)
        .map_err(|e| ModelError::new(format!("cannot read {}: {e}", path.display())))?;
    let key = (
        std::any::TypeId::of::<T>(),
        path.to_path_buf(),
        meta.len(),
        meta.modified().ok(),
    );
    let files = FILES.get_or_init(Default::default);
    if let Some(hit) = files.lock().ok().and_then(|m| m.get(&key).cloned()) {
        if let Ok(t) = hit.downcast::<T>() {
            return Ok(t);
        }
    }
    let text = read_text(path)?;
    let value = Arc::new(parse(path, &text)?);
    if let Ok(mut m) = files.lock() {
        m.insert(key, value.clone());
    }
    Ok(value)
}

/// Read a text file with the path in the error message.
pub fn read_text(path: &Path) -> Result<String, ModelError> {
    std::fs::read_to_string(path)
        .map_err(|e| ModelError::new(format!("cannot read {}: {e}", path.display())))
}

/// A model: its variable table, and the equations.
///
/// The runtime owns the variables (`Self::Vars`), checks every set against causality,
/// variability and min/max, and calls the model at initialisation and at each step.
pub trait Model: Clone + Send + Sized + 'static {
    type Vars: VarTable;
    const INFO: ModelInfo;

    /// Check parameters, load resources, set the initial state and write the initial outputs
    /// into `vars`. Called in initialization mode (when outputs are read) and at
    /// fmi2ExitInitializationMode, again whenever parameters or inputs changed in between.
    fn initialize(vars: &mut Self::Vars, ctx: &Context) -> Result<Self, ModelError>;

    /// Advance from `time` by `step` (> 0) with the inputs in `vars`; write the outputs.
    /// Must not allocate.
    fn do_step(&mut self, vars: &mut Self::Vars, time: f64, step: f64) -> Result<(), ModelError>;

    /// Recompute outputs that depend directly on inputs (those with `depends_on`), after the
    /// host set inputs between steps. The default does nothing (no feed-through).
    fn update_outputs(&mut self, _vars: &mut Self::Vars) {}

    /// A tunable parameter changed between steps: refresh anything derived from it.
    fn parameters_changed(&mut self, _vars: &Self::Vars) -> Result<(), ModelError> {
        Ok(())
    }

    /// fmi2Terminate: the run is over (flush, check what only the end can tell).
    fn terminate(&mut self, _vars: &Self::Vars) -> Result<(), ModelError> {
        Ok(())
    }

    /// Append the dynamic state (not the variables, not resources) to `w`.
    fn save_state(&self, w: &mut StateWriter);

    /// Read back what [`Model::save_state`] wrote, into a model initialised with the same
    /// parameters and resources.
    fn load_state(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError>;
}

/// Little-endian writer for serialized FMU states.
#[derive(Default, Debug)]
pub struct StateWriter {
    pub bytes: Vec<u8>,
}

impl StateWriter {
    pub fn f64(&mut self, x: f64) {
        self.bytes.extend_from_slice(&x.to_le_bytes());
    }
    pub fn u64(&mut self, x: u64) {
        self.bytes.extend_from_slice(&x.to_le_bytes());
    }
    pub fn i32(&mut self, x: i32) {
        self.bytes.extend_from_slice(&x.to_le_bytes());
    }
    pub fn bool(&mut self, x: bool) {
        self.bytes.push(x as u8);
    }
    pub fn bytes(&mut self, b: &[u8]) {
        self.u64(b.len() as u64);
        self.bytes.extend_from_slice(b);
    }
    /// A slice of f64, length-prefixed.
    pub fn f64s(&mut self, xs: impl ExactSizeIterator<Item = f64>) {
        self.u64(xs.len() as u64);
        for x in xs {
            self.f64(x);
        }
    }
}

/// Reader matching [`StateWriter`]; truncated or malformed input is an error, not a panic.
#[derive(Debug)]
pub struct StateReader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> StateReader<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, pos: 0 }
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], ModelError> {
        if self.bytes.len() - self.pos < n {
            return Err(ModelError::new(format!(
                "serialized FMU state truncated: need {n} bytes at offset {}, have {}",
                self.pos,
                self.bytes.len() - self.pos
            )));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    pub fn f64(&mut self) -> Result<f64, ModelError> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    pub fn u64(&mut self) -> Result<u64, ModelError> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    pub fn i32(&mut self) -> Result<i32, ModelError> {
        Ok(i32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    pub fn bool(&mut self) -> Result<bool, ModelError> {
        match self.take(1)?[0] {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(ModelError::new(format!(
                "serialized FMU state: bad boolean byte {b}"
            ))),
        }
    }
    pub fn bytes(&mut self) -> Result<&'a [u8], ModelError> {
        let n = self.len_prefix(1)?;
        self.take(n)
    }
    /// Length prefix, checked against what remains (each element at least `elem` bytes).
    pub fn len_prefix(&mut self, elem: usize) -> Result<usize, ModelError> {
        let n = self.u64()? as usize;
        if n.saturating_mul(elem) > self.bytes.len() - self.pos {
            return Err(ModelError::new(format!(
                "serialized FMU state: length {n} at offset {} exceeds the data",
                self.pos - 8
            )));
        }
        Ok(n)
    }
    /// Read a length-prefixed f64 sequence into `out` (cleared first).
    pub fn f64s_into(&mut self, out: &mut Vec<f64>) -> Result<(), ModelError> {
        let n = self.len_prefix(8)?;
        out.clear();
        for _ in 0..n {
            out.push(self.f64()?);
        }
        Ok(())
    }
    pub fn is_at_end(&self) -> bool {
        self.pos == self.bytes.len()
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn wrap_distance_is_rem_euclid_to_the_bit() {
        let length = 4284.25;
        let mut s: f64 = -3.0 * length;
        while s < 4.0 * length {
            for x in [
                s,
                s.next_up(),
                s.next_down(),
                -0.0,
                0.0,
                length,
                2.0 * length,
            ] {
                assert_eq!(
                    super::wrap_distance(x, length).to_bits(),
                    x.rem_euclid(length).to_bits(),
                    "s = {x}"
                );
            }
            s += 0.37;
        }
    }
}

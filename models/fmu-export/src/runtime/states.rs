//! FMU states: taken, restored, serialised and read back, whole (variables, model and run
//! state) or refused.

use crate::fmi2::fmi2Status;
use crate::model::{Model, ModelError};
use crate::state::{StateReader, StateWriter};
use crate::variables::{ScalarType, Value, VarTable};
use tb_fmi::Phase;

use super::slots::RunState;
use super::{Runtime, Snapshot};

const STATE_MAGIC: &[u8; 8] = b"TBFMUST1";

impl<M: Model> Runtime<M> {
    pub fn snapshot(&self) -> Result<Snapshot<M>, fmi2Status> {
        if let Some(p) = &self.poisoned {
            return Err(self.error(&format!("fmi2GetFMUstate refused: {p}")));
        }
        Ok(Snapshot {
            vars: self.vars.clone(),
            model: self.model.clone(),
            run: self.run,
        })
    }

    /// Overwrite `snap` in place (reuses its allocation where the types allow).
    pub fn snapshot_into(&self, snap: &mut Snapshot<M>) -> fmi2Status {
        if let Some(p) = &self.poisoned {
            return self.error(&format!("fmi2GetFMUstate refused: {p}"));
        }
        snap.vars.clone_from(&self.vars);
        snap.model.clone_from(&self.model);
        snap.run = self.run;
        fmi2Status::OK
    }

    pub fn restore(&mut self, snap: &Snapshot<M>) -> fmi2Status {
        if snap.run.phase == Phase::Error {
            return self.error("fmi2SetFMUstate: the state was saved in the error state");
        }
        self.vars.clone_from(&snap.vars);
        self.model.clone_from(&snap.model);
        self.run = snap.run;
        self.poisoned = None;
        fmi2Status::OK
    }

    /// Serialize a snapshot: magic, GUID, run state, variables, model state.
    pub fn serialize(&self, snap: &Snapshot<M>) -> Vec<u8> {
        let mut w = StateWriter::default();
        w.bytes.extend_from_slice(STATE_MAGIC);
        w.bytes(self.guid.as_bytes());
        snap.run.write(&mut w);
        for i in 0..M::Vars::VARIABLES.len() {
            match snap.vars.get(i) {
                Value::Real(x) => w.f64(x),
                Value::Integer(x) => w.i32(x),
                Value::Boolean(x) => w.bool(x),
                Value::Str(_) => w.bytes(snap.vars.get_str(i).unwrap_or("").as_bytes()),
            }
        }
        w.bool(snap.model.is_some());
        if let Some(m) = &snap.model {
            m.save_state(&mut w);
        }
        w.bytes
    }

    /// Rebuild a snapshot from bytes written by [`Runtime::serialize`]. The model part is
    /// re-initialised from the saved parameters (loading resources) and then overwritten.
    pub fn deserialize(&self, bytes: &[u8]) -> Result<Snapshot<M>, fmi2Status> {
        if bytes.len() < 8 || &bytes[..8] != STATE_MAGIC {
            return Err(self.error(
                "fmi2DeSerializeFMUstate: not a serialized twinbench FMU state (bad magic)",
            ));
        }
        self.read_snapshot(&mut StateReader::new(&bytes[8..]))
            .map_err(|m| self.error(&format!("fmi2DeSerializeFMUstate: {}", m.0)))
    }

    /// What [`Runtime::deserialize`] reads after the magic.
    pub(super) fn read_snapshot(&self, r: &mut StateReader<'_>) -> Result<Snapshot<M>, ModelError> {
        let guid = r.bytes()?;
        if guid != self.guid.as_bytes() {
            return Err(ModelError::new(format!(
                "state belongs to another model (GUID {}, this FMU is {})",
                String::from_utf8_lossy(guid),
                self.guid
            )));
        }
        let run = RunState::read(r)?;
        let vars = read_variables::<M::Vars>(r)?;
        let model = if r.bool()? {
            let mut scratch = vars.clone();
            let mut ctx = self.ctx.clone();
            ctx.start_time = run.start_time;
            let mut m = M::initialize(&mut scratch, &ctx)?;
            m.load_state(r)?;
            Some(m)
        } else {
            None
        };
        if !r.is_at_end() {
            return Err(ModelError::new(
                "trailing bytes after the model state".to_string(),
            ));
        }
        Ok(Snapshot { vars, model, run })
    }

    pub fn last_successful_time(&self) -> f64 {
        self.run.time
    }
}

/// Every variable of a serialized state, in table order.
fn read_variables<V: VarTable>(r: &mut StateReader<'_>) -> Result<V, ModelError> {
    let mut vars = V::default();
    for (i, info) in V::VARIABLES.iter().enumerate() {
        let v = match info.var_type() {
            ScalarType::Real => Value::Real(r.f64()?),
            ScalarType::Integer | ScalarType::Enumeration => Value::Integer(r.i32()?),
            ScalarType::Boolean => Value::Boolean(r.bool()?),
            ScalarType::String => {
                let text = std::str::from_utf8(r.bytes()?).map_err(|_| {
                    ModelError::new(format!("'{}': the saved string is not UTF-8", info.name))
                })?;
                vars.set_str(i, text);
                continue;
            }
        };
        vars.set(i, v);
    }
    Ok(vars)
}

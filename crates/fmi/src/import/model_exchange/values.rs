//! Values in and out: a get first runs the event iteration a set left pending; a continuous
//! Real input is set as it is (a change restarts the integrator at the next step), any other
//! value in event mode (FMI 2.0 §3.2.3).

use super::MeInstance;
use crate::FmuError;

impl MeInstance {
    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        self.settle()?;
        self.inst.get_real(vrs, out).map_err(|e| self.wrap(e))
    }

    pub fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.settle()?;
        self.inst.get_integer(vrs, out).map_err(|e| self.wrap(e))
    }

    pub fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.settle()?;
        self.inst.get_boolean(vrs, out).map_err(|e| self.wrap(e))
    }

    pub fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        self.settle()?;
        self.inst.get_string(vrs, out).map_err(|e| self.wrap(e))
    }

    /// Set Reals: continuous inputs as they are (a change restarts the integrator), any
    /// other in event mode.
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        let all_continuous = vrs.iter().all(|vr| self.continuous_inputs.contains_key(vr));
        if !all_continuous {
            self.event_mode_for_set()?;
        }
        self.inst.set_real(vrs, values).map_err(|e| self.wrap(e))?;
        for (vr, v) in vrs.iter().zip(values) {
            if self.continuous_inputs.contains_key(vr) {
                let old = self.inputs.insert(*vr, v.to_bits());
                self.inputs_changed |= old.is_some_and(|o| o != v.to_bits());
            }
        }
        Ok(())
    }

    pub fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.event_mode_for_set()?;
        self.inst.set_integer(vrs, values).map_err(|e| self.wrap(e))
    }

    pub fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.event_mode_for_set()?;
        self.inst.set_boolean(vrs, values).map_err(|e| self.wrap(e))
    }

    pub fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        self.event_mode_for_set()?;
        self.inst.set_string(vrs, values).map_err(|e| self.wrap(e))
    }
}

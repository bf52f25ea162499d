//! The exchange between units: each FMU instance's and replay's tables of value
//! references, and the buffer of every signal's current value that the master algorithms
//! ([`crate::master`]) move values through and the observers ([`crate::observe`]) read.

use crate::config::ReplayBasis;
use crate::plan::{Endpoint, ParamValue, Plan};
use crate::replay::Cursor;
use crate::{backend::Backend, SystemError};
use std::sync::Arc;
use tb_fmi::{FmuError, MeStop, ScalarType};

#[derive(Default)]
pub(crate) struct Batch<T> {
    vr: Vec<u32>,
    sig: Vec<usize>,
    buf: Vec<T>,
}

impl<T: Default + Clone> Batch<T> {
    fn push(&mut self, vr: u32, sig: usize) {
        self.vr.push(vr);
        self.sig.push(sig);
        self.buf.push(T::default());
    }
}

/// One FMU instance at run time: its backend and its exchange tables.
pub(crate) struct FmuUnit {
    pub(crate) name: String,
    pub(crate) instance: Option<Box<dyn Backend>>,
    pub(crate) in_real: Batch<f64>,
    pub(crate) in_real_scale: Vec<f64>,
    pub(crate) in_real_offset: Vec<f64>,
    pub(crate) in_int: Batch<i32>,
    pub(crate) in_bool: Batch<i32>,
    /// Real outputs read after every step: what connections, the stop condition or a
    /// replay's distance basis read.
    pub(crate) out_real: Batch<f64>,
    /// Real outputs only the recording reads: read at recorded steps only.
    pub(crate) rec_real: Batch<f64>,
    pub(crate) out_int: Batch<i32>,
    pub(crate) out_bool: Batch<i32>,
    pub(crate) in_str: Batch<String>,
    pub(crate) out_str: Batch<String>,
    /// (value reference, value) applied before each initialisation.
    pub(crate) params: Vec<(u32, ParamValue)>,
}

/// One replayed file at run time.
pub(crate) struct ReplayUnit {
    pub(crate) source: usize,
    pub(crate) basis_sig: Option<usize>,
    pub(crate) out_sig: Vec<usize>,
    pub(crate) cursor: Cursor,
}

pub(crate) enum Unit {
    Fmu(Box<FmuUnit>),
    Replay(ReplayUnit),
}

/// The units and the exchange buffer of one simulation: what a master algorithm moves.
pub struct Exchange {
    pub(crate) plan: Arc<Plan>,
    pub(crate) units: Vec<Unit>,
    pub(crate) signals: Vec<f64>,
    /// The values of String slots (same numbering as `signals`; empty elsewhere).
    pub(crate) texts: Vec<String>,
}

impl FmuUnit {
    #[inline]
    pub(crate) fn backend(&mut self) -> &mut dyn Backend {
        self.instance
            .as_deref_mut()
            .expect("instances are created before the first step")
    }

    #[inline]
    pub(crate) fn gather(&mut self, signals: &[f64], texts: &[String]) {
        for k in 0..self.in_str.vr.len() {
            self.in_str.buf[k].clone_from(&texts[self.in_str.sig[k]]);
        }
        for (((b, &sig), &scale), &offset) in self
            .in_real
            .buf
            .iter_mut()
            .zip(&self.in_real.sig)
            .zip(&self.in_real_scale)
            .zip(&self.in_real_offset)
        {
            *b = scale * signals[sig] + offset;
        }
        for k in 0..self.in_int.vr.len() {
            self.in_int.buf[k] = signals[self.in_int.sig[k]].round() as i32;
        }
        for k in 0..self.in_bool.vr.len() {
            self.in_bool.buf[k] = (signals[self.in_bool.sig[k]] != 0.0) as i32;
        }
    }

    #[inline]
    pub(crate) fn set_inputs(&mut self) -> Result<(), SystemError> {
        let i = self
            .instance
            .as_deref_mut()
            .expect("instances are created before the first step");
        if !self.in_real.vr.is_empty() {
            i.set_real(&self.in_real.vr, &self.in_real.buf)?;
        }
        if !self.in_int.vr.is_empty() {
            i.set_integer(&self.in_int.vr, &self.in_int.buf)?;
        }
        if !self.in_bool.vr.is_empty() {
            i.set_boolean(&self.in_bool.vr, &self.in_bool.buf)?;
        }
        if !self.in_str.vr.is_empty() {
            let refs: Vec<&str> = self.in_str.buf.iter().map(String::as_str).collect();
            i.set_string(&self.in_str.vr, &refs)?;
        }
        Ok(())
    }

    #[inline]
    pub(crate) fn get_outputs(
        &mut self,
        signals: &mut [f64],
        texts: &mut [String],
        plan: &Plan,
    ) -> Result<(), SystemError> {
        let i = self
            .instance
            .as_deref_mut()
            .expect("instances are created before the first step");
        read_reals(i, &mut self.out_real, &self.name, signals, plan)?;
        if !self.out_int.vr.is_empty() {
            i.get_integer(&self.out_int.vr, &mut self.out_int.buf)?;
            for k in 0..self.out_int.vr.len() {
                signals[self.out_int.sig[k]] = self.out_int.buf[k] as f64;
            }
        }
        if !self.out_bool.vr.is_empty() {
            i.get_boolean(&self.out_bool.vr, &mut self.out_bool.buf)?;
            for k in 0..self.out_bool.vr.len() {
                signals[self.out_bool.sig[k]] = (self.out_bool.buf[k] != 0) as i32 as f64;
            }
        }
        if !self.out_str.vr.is_empty() {
            i.get_string(&self.out_str.vr, &mut self.out_str.buf)?;
            for k in 0..self.out_str.vr.len() {
                texts[self.out_str.sig[k]].clone_from(&self.out_str.buf[k]);
            }
        }
        Ok(())
    }
}

/// A step's error: a discarded step may be the FMU's way to end the simulation (FMI 2.0,
/// 4.2.3), and the run then ends there, normally.
#[inline]
fn step_error(f: &mut FmuUnit, e: FmuError) -> SystemError {
    if e.is_discarded_fmi2_step() {
        if let Some(time) = f.backend().terminated_by_fmu() {
            return SystemError::EndedByFmu {
                instance: f.name.clone(),
                time,
            };
        }
    }
    e.into()
}

/// Reads a batch of Real outputs into the exchange buffer; a value that is not finite is
/// an error naming the instance, the signal and the time.
#[inline(always)]
fn read_reals(
    i: &mut dyn Backend,
    batch: &mut Batch<f64>,
    name: &str,
    signals: &mut [f64],
    plan: &Plan,
) -> Result<(), SystemError> {
    if batch.vr.is_empty() {
        return Ok(());
    }
    i.get_real(&batch.vr, &mut batch.buf)?;
    for (&x, &sig) in batch.buf.iter().zip(&batch.sig) {
        if !x.is_finite() {
            return Err(not_finite(i, name, plan, sig, x));
        }
        signals[sig] = x;
    }
    Ok(())
}

#[cold]
fn not_finite(i: &dyn Backend, name: &str, plan: &Plan, sig: usize, x: f64) -> SystemError {
    SystemError::NotFinite {
        instance: name.to_string(),
        signal: plan.signals.signals[sig].name.clone(),
        value: x,
        time: i.time(),
    }
}

impl Exchange {
    /// The exchange tables of a plan: one unit per instance and replay, each with the
    /// batches of value references it sets and reads; instances are created at the first
    /// run.
    pub(crate) fn new(plan: &Arc<Plan>) -> Exchange {
        let n_fmu = plan.instances.len();
        let mut units: Vec<Unit> = plan
            .instances
            .iter()
            .map(|inst| {
                Unit::Fmu(Box::new(FmuUnit {
                    name: inst.name.clone(),
                    instance: None,
                    in_real: Batch::default(),
                    in_real_scale: Vec::new(),
                    in_real_offset: Vec::new(),
                    in_int: Batch::default(),
                    in_bool: Batch::default(),
                    out_real: Batch::default(),
                    rec_real: Batch::default(),
                    out_int: Batch::default(),
                    out_bool: Batch::default(),
                    in_str: Batch::default(),
                    out_str: Batch::default(),
                    params: Vec::new(),
                }))
            })
            .collect();
        for (k, r) in plan.replays.iter().enumerate() {
            let out_sig = (0..r.columns.len())
                .map(|c| {
                    plan.signals
                        .signals
                        .iter()
                        .position(|s| {
                            matches!(s.source, Endpoint::Replay { unit, column, .. } if unit == n_fmu + k && column == c)
                        })
                        .unwrap_or(usize::MAX)
                })
                .collect();
            units.push(Unit::Replay(ReplayUnit {
                source: k,
                basis_sig: plan.replay_basis[k],
                out_sig,
                cursor: Cursor::default(),
            }));
        }
        // The slots a reader needs between steps; every other Real output is read for the
        // recording only, at the recorded steps (a tenth of them at 1 ms and 100 Hz).
        let every_step = plan.read_every_step();
        for (slot, s) in plan.signals.signals.iter().enumerate() {
            if let Endpoint::Fmu { unit, vr, ty, .. } = s.source {
                if let Unit::Fmu(f) = &mut units[unit] {
                    match ty {
                        ScalarType::Real if !every_step[slot] => f.rec_real.push(vr, slot),
                        ScalarType::Real => f.out_real.push(vr, slot),
                        ScalarType::Integer | ScalarType::Enumeration => f.out_int.push(vr, slot),
                        ScalarType::Boolean => f.out_bool.push(vr, slot),
                        ScalarType::String => f.out_str.push(vr, slot),
                    }
                }
            }
        }
        for c in &plan.connections {
            if let Unit::Fmu(f) = &mut units[c.to_unit] {
                match c.to_ty {
                    ScalarType::Real => {
                        f.in_real.push(c.to_vr, c.from_slot);
                        f.in_real_scale.push(c.scale);
                        f.in_real_offset.push(c.offset);
                    }
                    ScalarType::Integer | ScalarType::Enumeration => {
                        f.in_int.push(c.to_vr, c.from_slot)
                    }
                    ScalarType::Boolean => f.in_bool.push(c.to_vr, c.from_slot),
                    ScalarType::String => f.in_str.push(c.to_vr, c.from_slot),
                }
            }
        }
        for (slot, value) in &plan.parameters {
            if let Unit::Fmu(f) = &mut units[slot.unit] {
                f.params.push((slot.vr, value.clone()));
            }
        }
        Exchange {
            signals: vec![0.0; plan.signals.len()],
            texts: vec![String::new(); plan.signals.len()],
            plan: plan.clone(),
            units,
        }
    }

    pub fn plan(&self) -> &Arc<Plan> {
        &self.plan
    }

    /// The exchange buffer, by slot.
    #[inline]
    pub fn signals(&self) -> &[f64] {
        &self.signals
    }

    /// The String slots' values (empty for other slots).
    pub fn texts(&self) -> &[String] {
        &self.texts
    }

    /// Read every unit's record-only outputs (before a recorded row: the values at the
    /// same communication point as the others', as no input changed since each unit's step).
    pub fn publish_recorded(&mut self) -> Result<(), SystemError> {
        for u in &mut self.units {
            if let Unit::Fmu(f) = u {
                if f.rec_real.vr.is_empty() {
                    continue;
                }
                let i = f
                    .instance
                    .as_deref_mut()
                    .expect("instances are created before the first step");
                read_reals(i, &mut f.rec_real, &f.name, &mut self.signals, &self.plan)?;
            }
        }
        Ok(())
    }

    /// Set unit `u`'s inputs from the exchange buffer (a replay has none).
    #[inline]
    pub fn set_inputs(&mut self, u: usize) -> Result<(), SystemError> {
        if let Unit::Fmu(f) = &mut self.units[u] {
            f.gather(&self.signals, &self.texts);
            f.set_inputs()?;
        }
        Ok(())
    }

    /// Compute unit `u`'s inputs into its own buffer without setting them (Jacobi: every
    /// unit sees the values of before the step).
    #[inline]
    pub fn gather(&mut self, u: usize) {
        if let Unit::Fmu(f) = &mut self.units[u] {
            f.gather(&self.signals, &self.texts);
        }
    }

    /// Set the inputs gathered before.
    #[inline]
    pub fn set_gathered(&mut self, u: usize) -> Result<(), SystemError> {
        if let Unit::Fmu(f) = &mut self.units[u] {
            f.set_inputs()?;
        }
        Ok(())
    }

    /// Step unit `u` from `t` by `h` (a replay does nothing here).
    #[inline]
    pub fn do_step(&mut self, u: usize, t: f64, h: f64) -> Result<(), SystemError> {
        if let Unit::Fmu(f) = &mut self.units[u] {
            if let Err(e) = f.backend().do_step(t, h) {
                return Err(step_error(f, e));
            }
        }
        Ok(())
    }

    /// Step unit `u` from `t` by `h`, stopping before and after each event inside the step
    /// ([`Backend::step_to_event`]; a replay, or a unit that does not stop at events, makes
    /// the whole step).
    pub fn step_to_event(&mut self, u: usize, t: f64, h: f64) -> Result<MeStop, SystemError> {
        match &mut self.units[u] {
            Unit::Fmu(f) => f
                .backend()
                .step_to_event(t, h)
                .map_err(|e| step_error(f, e)),
            Unit::Replay(_) => Ok(MeStop::Reached),
        }
    }

    /// Read unit `u`'s outputs into the exchange buffer. A replay by distance takes its
    /// values at the distance signal's current value; a replay by time does nothing here:
    /// the run sets it at the start of each step ([`Exchange::time_replays_at`]).
    #[inline]
    pub fn publish(&mut self, u: usize, t: f64) -> Result<(), SystemError> {
        match &mut self.units[u] {
            Unit::Fmu(f) => f.get_outputs(&mut self.signals, &mut self.texts, &self.plan),
            Unit::Replay(r) => {
                if self.plan.replays[r.source].basis == ReplayBasis::Distance {
                    self.step_replay(u, t);
                }
                Ok(())
            }
        }
    }

    /// Set every replay by time to its value at `t`. The run calls it at the start of each
    /// step, so that the step t → t+h sees the input at t whatever the stepping order (as
    /// FMPy applies an input file), and after it, for the recording.
    #[inline]
    pub fn time_replays_at(&mut self, t: f64) {
        for u in self.plan.instances.len()..self.units.len() {
            if let Unit::Replay(r) = &self.units[u] {
                if self.plan.replays[r.source].basis == ReplayBasis::Time {
                    self.step_replay(u, t);
                }
            }
        }
    }

    /// Read every unit's outputs read between steps at `t` (the end of a run an FMU ended
    /// early; the recorded row that follows reads the record-only ones).
    pub fn publish_all(&mut self, t: f64) -> Result<(), SystemError> {
        self.time_replays_at(t);
        for u in 0..self.units.len() {
            self.publish(u, t)?;
        }
        Ok(())
    }

    fn step_replay(&mut self, u: usize, t: f64) {
        let Unit::Replay(r) = &mut self.units[u] else {
            return;
        };
        let src = &self.plan.replays[r.source];
        let q = match (src.basis, r.basis_sig) {
            (ReplayBasis::Distance, Some(s)) => self.signals[s],
            _ => t,
        };
        let x = src.basis_values();
        let (mut i, mut w) = r.cursor.locate(x, q);
        // A point within 1e-9 (relative) of the next row is at that row (FMPy's `isclose`):
        // t = k·h lands a hair before a row's time, and a step there must take effect.
        if i + 1 < x.len() && w < 1.0 {
            let next = x[i + 1];
            if (next - q).abs() <= 1e-9 * next.abs().max(q.abs()) {
                (i, w) = r.cursor.locate(x, next);
            }
        }
        for (c, &sig) in r.out_sig.iter().enumerate() {
            if sig != usize::MAX {
                let col = src.values(c);
                self.signals[sig] = if col.len() < 2 {
                    col[0]
                } else if src.hold[c] {
                    // The last row at or before the point (after a step, its new value).
                    if w >= 1.0 {
                        col[i + 1]
                    } else {
                        col[i]
                    }
                } else {
                    let rise = col[i + 1] - col[i];
                    if rise.is_finite() {
                        col[i] + w * rise
                    } else {
                        // Rows near ±f64::MAX of opposite signs (red team M17): their
                        // difference overflows; weighted separately they do not.
                        col[i] * (1.0 - w) + col[i + 1] * w
                    }
                };
            }
        }
    }
}

//! The master algorithm: fixed macro step on an integer tick base, Gauss-Seidel in the
//! system's stepping order or Jacobi, initialisation to a fixed point, recording, a stop
//! condition on a signal. Instances are created once and reset between runs.

use super::backend::Backend;
use super::config::{Algorithm, ReplayBasis, StopConfig};
use super::replay::Cursor;
use super::results::Recording;
use super::{check_parameter, invalid, split_name, Endpoint, System, SystemError};
use std::collections::HashMap;
use std::time::Instant;
use tb_fmi::{Causality, ScalarType};

/// Where a signal's value comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Source {
    Fmu(usize, u32),
    Replay(usize, usize),
}

#[derive(Default)]
struct Batch<T> {
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

struct FmuRt {
    name: String,
    instance: Option<Box<dyn Backend>>,
    in_real: Batch<f64>,
    in_real_scale: Vec<f64>,
    in_real_offset: Vec<f64>,
    in_int: Batch<i32>,
    in_bool: Batch<i32>,
    out_real: Batch<f64>,
    out_int: Batch<i32>,
    out_bool: Batch<i32>,
    /// (vr, type, value) applied before each initialisation.
    params: Vec<(u32, ScalarType, toml::Value)>,
}

struct ReplayRt {
    source: usize,
    basis_sig: Option<usize>,
    out_sig: Vec<usize>,
    cursor: Cursor,
}

enum UnitRt {
    Fmu(Box<FmuRt>),
    Replay(ReplayRt),
}

/// What a run did.
#[derive(Clone, Debug)]
pub struct RunSummary {
    pub steps: u64,
    pub simulated_time: f64,
    pub wall_time: f64,
    /// Duration of the completed lap, when the run stopped on a lap.
    pub lap_time: Option<f64>,
    pub stopped_by: String,
}

/// A runnable system: the loaded [`System`] plus its instances and exchange buffers.
pub struct Simulation {
    pub system: System,
    units: Vec<UnitRt>,
    signals: Vec<f64>,
    signal_names: Vec<String>,
    record_sigs: Vec<usize>,
    lap_sig: Option<usize>,
    lap_time_source: Option<(usize, u32)>,
    pub recording: Recording,
    /// Echo FMU messages with status OK to the log (off: kept only for error reports).
    pub echo_fmu_log: bool,
}

impl FmuRt {
    #[inline]
    fn gather(&mut self, signals: &[f64]) {
        for k in 0..self.in_real.vr.len() {
            self.in_real.buf[k] =
                self.in_real_scale[k] * signals[self.in_real.sig[k]] + self.in_real_offset[k];
        }
        for k in 0..self.in_int.vr.len() {
            self.in_int.buf[k] = signals[self.in_int.sig[k]].round() as i32;
        }
        for k in 0..self.in_bool.vr.len() {
            self.in_bool.buf[k] = (signals[self.in_bool.sig[k]] != 0.0) as i32;
        }
    }

    #[inline]
    fn set_inputs(&mut self) -> Result<(), SystemError> {
        let i = self.instance.as_mut().expect("instantiated");
        if !self.in_real.vr.is_empty() {
            i.set_real(&self.in_real.vr, &self.in_real.buf)?;
        }
        if !self.in_int.vr.is_empty() {
            i.set_integer(&self.in_int.vr, &self.in_int.buf)?;
        }
        if !self.in_bool.vr.is_empty() {
            i.set_boolean(&self.in_bool.vr, &self.in_bool.buf)?;
        }
        Ok(())
    }

    #[inline]
    fn get_outputs(&mut self, signals: &mut [f64], names: &[String]) -> Result<(), SystemError> {
        let i = self.instance.as_mut().expect("instantiated");
        if !self.out_real.vr.is_empty() {
            i.get_real(&self.out_real.vr, &mut self.out_real.buf)?;
            for k in 0..self.out_real.vr.len() {
                let x = self.out_real.buf[k];
                if !x.is_finite() {
                    return Err(SystemError::NotFinite {
                        instance: self.name.clone(),
                        signal: names[self.out_real.sig[k]].clone(),
                        value: x,
                        time: i.time(),
                    });
                }
                signals[self.out_real.sig[k]] = x;
            }
        }
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
        Ok(())
    }
}

impl Simulation {
    /// Prepare the exchange tables; instances are created at the first run.
    pub fn new(system: System) -> Result<Simulation, SystemError> {
        let n_fmu = system.instances.len();
        let mut slots: HashMap<Source, usize> = HashMap::new();
        let mut signal_names = Vec::new();
        let mut signal_units = Vec::new();
        let mut sources: Vec<(Source, ScalarType)> = Vec::new();
        let mut slot_of = |src: Source, ty: ScalarType, name: String, unit: String| -> usize {
            *slots.entry(src).or_insert_with(|| {
                signal_names.push(name);
                signal_units.push(unit);
                sources.push((src, ty));
                sources.len() - 1
            })
        };
        let ctx = system.path.display().to_string();
        let endpoint_slot =
            |e: &Endpoint,
             name: &str,
             slot_of: &mut dyn FnMut(Source, ScalarType, String, String) -> usize| {
                match e {
                    Endpoint::Fmu {
                        unit,
                        vr,
                        ty,
                        unit_name,
                    } => slot_of(
                        Source::Fmu(*unit, *vr),
                        *ty,
                        name.to_string(),
                        unit_name.clone().unwrap_or_default(),
                    ),
                    Endpoint::Replay {
                        unit,
                        column,
                        unit_name,
                    } => slot_of(
                        Source::Replay(*unit, *column),
                        ScalarType::Real,
                        name.to_string(),
                        unit_name.clone(),
                    ),
                }
            };
        // Resolve a name to an endpoint (the rules the system's validation used).
        let resolve =
            |full: &str| super::resolve_endpoint(&system.instances, &system.replays, &ctx, full);
        // Connection sources.
        let mut conn_slots = Vec::new();
        for c in &system.connections {
            conn_slots.push(endpoint_slot(&c.from, &c.from_name, &mut slot_of));
        }
        // Recorded signals: as listed, or every output and replayed column.
        let mut record_names: Vec<String> = system.file.record.signals.clone();
        if record_names.is_empty() {
            for inst in &system.instances {
                for v in inst
                    .description()
                    .variables
                    .iter()
                    .filter(|v| v.causality == Causality::Output && v.ty != ScalarType::String)
                {
                    let ours = inst
                        .ports
                        .iter()
                        .find(|(_, t)| *t == &v.name)
                        .map(|(o, _)| o.clone())
                        .unwrap_or(v.name.clone());
                    record_names.push(format!("{}.{ours}", inst.name));
                }
            }
            for r in &system.replays {
                for c in &r.columns {
                    record_names.push(format!("{}.{c}", r.name));
                }
            }
        }
        let mut record_sigs = Vec::new();
        for n in &record_names {
            let e = resolve(n)?;
            if let Endpoint::Fmu {
                ty: ScalarType::String,
                ..
            } = e
            {
                return Err(invalid(&ctx, format!("record: '{n}' is a String")));
            }
            record_sigs.push(endpoint_slot(&e, n, &mut slot_of));
        }
        let lap_sig = if system.file.experiment.stop == StopConfig::Word("lap".into()) {
            let e = resolve(&system.file.experiment.lap_signal)?;
            Some(endpoint_slot(
                &e,
                &system.file.experiment.lap_signal,
                &mut slot_of,
            ))
        } else {
            None
        };
        let lap_time_source = lap_sig.and_then(|_| {
            let (u, _) = split_name(&system.file.experiment.lap_signal)?;
            let k = system.instances.iter().position(|i| i.name == u)?;
            let sv = system.instances[k].description().variable("lap_time")?;
            (sv.ty == ScalarType::Real).then_some((k, sv.value_reference))
        });
        let mut replay_basis = Vec::new();
        for r in &system.replays {
            replay_basis.push(match &r.by {
                Some(by) => {
                    let e = resolve(by)?;
                    Some(endpoint_slot(&e, by, &mut slot_of))
                }
                None => None,
            });
        }
        // Per-unit exchange tables.
        let mut units: Vec<UnitRt> = Vec::new();
        for inst in &system.instances {
            units.push(UnitRt::Fmu(Box::new(FmuRt {
                name: inst.name.clone(),
                instance: None,
                in_real: Batch::default(),
                in_real_scale: Vec::new(),
                in_real_offset: Vec::new(),
                in_int: Batch::default(),
                in_bool: Batch::default(),
                out_real: Batch::default(),
                out_int: Batch::default(),
                out_bool: Batch::default(),
                params: Vec::new(),
            })));
        }
        for (k, r) in system.replays.iter().enumerate() {
            units.push(UnitRt::Replay(ReplayRt {
                source: k,
                basis_sig: replay_basis[k],
                out_sig: (0..r.columns.len())
                    .map(|c| {
                        slots
                            .get(&Source::Replay(n_fmu + k, c))
                            .copied()
                            .unwrap_or(usize::MAX)
                    })
                    .collect(),
                cursor: Cursor::default(),
            }));
        }
        for (slot, (src, ty)) in sources.iter().enumerate() {
            if let Source::Fmu(u, vr) = *src {
                if let UnitRt::Fmu(f) = &mut units[u] {
                    match ty {
                        ScalarType::Real => f.out_real.push(vr, slot),
                        ScalarType::Integer | ScalarType::Enumeration => f.out_int.push(vr, slot),
                        ScalarType::Boolean => f.out_bool.push(vr, slot),
                        ScalarType::String => {}
                    }
                }
            }
        }
        for (c, &slot) in system.connections.iter().zip(&conn_slots) {
            if let UnitRt::Fmu(f) = &mut units[c.to_unit] {
                match c.to_ty {
                    ScalarType::Real => {
                        f.in_real.push(c.to_vr, slot);
                        f.in_real_scale.push(c.scale);
                        f.in_real_offset.push(c.offset);
                    }
                    ScalarType::Integer | ScalarType::Enumeration => f.in_int.push(c.to_vr, slot),
                    ScalarType::Boolean => f.in_bool.push(c.to_vr, slot),
                    ScalarType::String => {}
                }
            }
        }
        let mut record_names_full = vec!["time".to_string()];
        let mut record_units = vec!["s".to_string()];
        for &s in &record_sigs {
            record_names_full.push(signal_names[s].clone());
            record_units.push(signal_units[s].clone());
        }
        let n_sig = signal_names.len();
        let mut sim = Simulation {
            system,
            units,
            signals: vec![0.0; n_sig],
            signal_names,
            record_sigs,
            lap_sig,
            lap_time_source,
            recording: Recording::new(record_names_full, record_units),
            echo_fmu_log: true,
        };
        let params: Vec<(String, toml::Value)> = sim
            .system
            .file
            .parameters
            .iter()
            .map(|(k, v)| (k.clone(), v.clone()))
            .collect();
        for (k, v) in params {
            sim.set_parameter(&k, v)?;
        }
        Ok(sim)
    }

    /// Set (or change, between runs) a parameter or input start value: `instance.variable`.
    pub fn set_parameter(&mut self, name: &str, value: toml::Value) -> Result<(), SystemError> {
        let ctx = format!("parameter \"{name}\"");
        let (k, sv) = check_parameter(&self.system.instances, name, &value, &ctx)?;
        let (vr, ty) = (sv.value_reference, sv.ty);
        if let UnitRt::Fmu(f) = &mut self.units[k] {
            match f.params.iter_mut().find(|p| p.0 == vr) {
                Some(p) => p.2 = value,
                None => f.params.push((vr, ty, value)),
            }
        }
        Ok(())
    }

    /// Current value of a parameter set through the system (None: the FMU's start value).
    pub fn parameter(&self, name: &str) -> Option<f64> {
        let (u, var) = split_name(name)?;
        let k = self.system.instances.iter().position(|i| i.name == u)?;
        let sv = self.system.instances[k].variable(var, "").ok()?;
        if let UnitRt::Fmu(f) = &self.units[k] {
            if let Some(p) = f.params.iter().find(|p| p.0 == sv.value_reference) {
                return p
                    .2
                    .as_float()
                    .or_else(|| p.2.as_integer().map(|i| i as f64));
            }
        }
        sv.start_f64()
    }

    pub fn signal_names(&self) -> &[String] {
        &self.signal_names
    }

    fn step_replay(&mut self, u: usize, t: f64) {
        let UnitRt::Replay(r) = &mut self.units[u] else {
            return;
        };
        let src = &self.system.replays[r.source];
        let q = match (src.basis, r.basis_sig) {
            (ReplayBasis::Distance, Some(s)) => self.signals[s],
            _ => t,
        };
        let (i, w) = r.cursor.locate(&src.x, q);
        for (c, &sig) in r.out_sig.iter().enumerate() {
            if sig != usize::MAX {
                let col = &src.data[c];
                self.signals[sig] = if col.len() > 1 {
                    col[i] + w * (col[i + 1] - col[i])
                } else {
                    col[0]
                };
            }
        }
    }

    fn instantiate_all(&mut self, start: f64, stop: Option<f64>) -> Result<(), SystemError> {
        let echo = self.echo_fmu_log;
        for (k, unit) in self.units.iter_mut().enumerate() {
            let UnitRt::Fmu(f) = unit else { continue };
            let def = &self.system.instances[k];
            let reuse = match f.instance.as_mut() {
                Some(i) => i.reset().is_ok(),
                None => false,
            };
            if !reuse {
                f.instance = None;
                f.instance = Some(def.factory.create(&def.name, def.logging)?);
            }
            let inst = f.instance.as_mut().unwrap();
            inst.set_echo(echo);
            inst.setup_experiment(start, stop)?;
            for (vr, ty, v) in &f.params {
                match ty {
                    ScalarType::Real => inst.set_real(
                        &[*vr],
                        &[v.as_float()
                            .or_else(|| v.as_integer().map(|i| i as f64))
                            .unwrap_or(0.0)],
                    )?,
                    ScalarType::Integer | ScalarType::Enumeration => {
                        inst.set_integer(&[*vr], &[v.as_integer().unwrap_or(0) as i32])?
                    }
                    ScalarType::Boolean => {
                        inst.set_boolean(&[*vr], &[v.as_bool().unwrap_or(false) as i32])?
                    }
                    ScalarType::String => {}
                }
            }
        }
        Ok(())
    }

    /// Initialisation mode for all, outputs propagated to inputs until nothing changes.
    fn initialize(&mut self, start: f64) -> Result<(), SystemError> {
        for u in &mut self.units {
            if let UnitRt::Fmu(f) = u {
                f.instance.as_mut().unwrap().enter_initialization_mode()?;
            }
        }
        let order = self.system.order.clone();
        let mut previous = vec![f64::NAN; self.signals.len()];
        let mut converged = false;
        for _ in 0..50 {
            for &u in &order {
                match &mut self.units[u] {
                    UnitRt::Fmu(f) => {
                        f.gather(&self.signals);
                        f.set_inputs()?;
                        f.get_outputs(&mut self.signals, &self.signal_names)?;
                    }
                    UnitRt::Replay(_) => self.step_replay(u, start),
                }
            }
            if previous
                .iter()
                .zip(&self.signals)
                .all(|(a, b)| a.to_bits() == b.to_bits())
            {
                converged = true;
                break;
            }
            previous.copy_from_slice(&self.signals);
        }
        if !converged {
            log::warn!(
                "{}: initialisation did not reach a fixed point in 50 sweeps",
                self.system.path.display()
            );
        }
        for &u in &order {
            if let UnitRt::Fmu(f) = &mut self.units[u] {
                f.gather(&self.signals);
                f.set_inputs()?;
                f.instance.as_mut().unwrap().exit_initialization_mode()?;
                f.get_outputs(&mut self.signals, &self.signal_names)?;
            }
        }
        Ok(())
    }

    fn record(&mut self, t: f64) {
        self.recording.columns[0].push(t);
        for (k, &s) in self.record_sigs.iter().enumerate() {
            self.recording.columns[k + 1].push(self.signals[s]);
        }
    }

    /// Run the experiment once (again: instances are reset and reused).
    pub fn run(&mut self) -> Result<RunSummary, SystemError> {
        let wall = Instant::now();
        let exp = self.system.file.experiment.clone();
        let (start, h) = (exp.start, exp.step);
        let fixed_stop = match exp.stop {
            StopConfig::Time(t) => Some(t),
            StopConfig::Word(_) => None,
        };
        self.recording.clear();
        self.signals.iter_mut().for_each(|s| *s = 0.0);
        for u in &mut self.units {
            if let UnitRt::Replay(r) = u {
                r.cursor = Cursor::default();
            }
        }
        self.instantiate_all(start, fixed_stop)?;
        self.initialize(start)?;
        self.record(start);
        // Integer ticks: t_k = start + k·h exactly, no accumulated drift.
        let span = fixed_stop.unwrap_or(start + exp.max_time) - start;
        let full_steps = (span / h * (1.0 + 1e-12)).floor() as u64;
        let last = span - full_steps as f64 * h;
        let total_steps = full_steps + u64::from(last > h * 1e-9);
        let decimation = self.system.file.record.decimation as u64;
        let order = self.system.order.clone();
        let jacobi = exp.algorithm == Algorithm::Jacobi;
        let mut stopped_by = format!("stop time {} s", start + span);
        let mut k = 0u64;
        let mut t_end = start;
        while k < total_steps {
            let t = start + k as f64 * h;
            let step = if k == full_steps { last } else { h };
            if jacobi {
                for &u in &order {
                    if let UnitRt::Fmu(f) = &mut self.units[u] {
                        f.gather(&self.signals);
                    }
                }
                for &u in &order {
                    match &mut self.units[u] {
                        UnitRt::Fmu(f) => {
                            f.set_inputs()?;
                            f.instance.as_mut().unwrap().do_step(t, step)?;
                        }
                        UnitRt::Replay(_) => {}
                    }
                }
                for &u in &order {
                    match &mut self.units[u] {
                        UnitRt::Fmu(f) => f.get_outputs(&mut self.signals, &self.signal_names)?,
                        UnitRt::Replay(_) => self.step_replay(u, t + step),
                    }
                }
            } else {
                for &u in &order {
                    match &mut self.units[u] {
                        UnitRt::Fmu(f) => {
                            f.gather(&self.signals);
                            f.set_inputs()?;
                            f.instance.as_mut().unwrap().do_step(t, step)?;
                            f.get_outputs(&mut self.signals, &self.signal_names)?;
                        }
                        UnitRt::Replay(_) => self.step_replay(u, t + step),
                    }
                }
            }
            k += 1;
            t_end = if k == total_steps && fixed_stop.is_some() {
                start + span
            } else {
                start + k as f64 * h
            };
            let lap_done = self
                .lap_sig
                .is_some_and(|s| self.signals[s] >= exp.lap_count);
            // Rows stay on the decimation grid (a uniform time base for filters); only a
            // fixed stop time adds its final row.
            if k.is_multiple_of(decimation) || (k == total_steps && fixed_stop.is_some()) {
                self.record(t_end);
            }
            if lap_done {
                stopped_by = format!("{} >= {}", exp.lap_signal, exp.lap_count);
                break;
            }
        }
        if fixed_stop.is_none()
            && !self
                .lap_sig
                .is_some_and(|s| self.signals[s] >= exp.lap_count)
        {
            return Err(SystemError::Stop(format!(
                "{}: the lap did not complete within max_time = {} s ({} stayed below {})",
                self.system.path.display(),
                exp.max_time,
                exp.lap_signal,
                exp.lap_count
            )));
        }
        let lap_time = match (self.lap_sig, self.lap_time_source) {
            (Some(_), Some((u, vr))) => {
                let UnitRt::Fmu(f) = &mut self.units[u] else {
                    unreachable!()
                };
                let mut v = [0.0];
                f.instance.as_mut().unwrap().get_real(&[vr], &mut v)?;
                Some(v[0])
            }
            (Some(_), None) => Some(t_end - start),
            _ => None,
        };
        for u in &mut self.units {
            if let UnitRt::Fmu(f) = u {
                f.instance.as_mut().unwrap().terminate()?;
            }
        }
        Ok(RunSummary {
            steps: k,
            simulated_time: t_end - start,
            wall_time: wall.elapsed().as_secs_f64(),
            lap_time,
            stopped_by,
        })
    }
}

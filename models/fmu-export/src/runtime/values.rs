//! The get and set calls: each value checked against its variable's causality,
//! variability, type and range, Reals of the fast path read and written in place.

use crate::fmi2::fmi2Status;
use crate::model::Model;
use crate::variables::{ScalarType, Value, VarInfo, VarTable};
use tb_fmi::{Function, Phase};

use super::*;

impl<M: Model> Runtime<M> {
    pub(super) fn index(&self, function: &str, vr: u32) -> Result<usize, fmi2Status> {
        match self.vr_index.get(vr as usize) {
            Some(&i) if i > 0 => Ok(i as usize - 1),
            _ => Err(self.error(&format!(
                "{function}: unknown value reference {vr} (model '{}')",
                M::INFO.name
            ))),
        }
    }

    /// The variable of `vr`, refused (with the message) when there is none or it is not of
    /// type `ty`.
    fn variable_of_type(
        &self,
        function: &str,
        vr: u32,
        ty: ScalarType,
    ) -> Result<&'static VarInfo, fmi2Status> {
        let info = &M::Vars::VARIABLES[self.index(function, vr)?];
        self.check_type(function, info, ty)?;
        Ok(info)
    }

    pub(super) fn check_type(
        &self,
        function: &str,
        info: &VarInfo,
        ty: ScalarType,
    ) -> Result<(), fmi2Status> {
        if info.var_type().value_space() == ty.value_space() {
            Ok(())
        } else {
            Err(self.error(&format!(
                "{function}: variable '{}' (vr {}) is {}, not {}",
                info.name,
                info.value_reference,
                info.var_type().xml_name(),
                ty.xml_name()
            )))
        }
    }

    /// What every get does first: the state check, the array lengths, a pending (lazy)
    /// initialisation or output update. Returns whether the instance is only instantiated.
    #[inline(always)]
    pub(super) fn before_get(
        &mut self,
        function: &str,
        vrs: usize,
        out: usize,
    ) -> Result<bool, fmi2Status> {
        self.require_named(function, Function::GetReal.allowed())?;
        if vrs != out {
            return Err(self.length_mismatch(function, vrs, out));
        }
        match self.run.phase {
            Phase::InitializationMode => self.try_initialize(),
            Phase::StepComplete if M::Vars::HAS_FEEDTHROUGH && self.run.inputs_changed => {
                if let Some(m) = self.model.as_mut() {
                    m.calculate_outputs(&mut self.vars);
                }
                self.run.inputs_changed = false;
            }
            _ => {}
        }
        Ok(self.run.phase == Phase::Instantiated)
    }

    /// Read variables of type `ty` into `out`, converted by `conv`.
    pub fn get<T>(
        &mut self,
        function: &str,
        ty: ScalarType,
        vrs: &[u32],
        out: &mut [T],
        conv: impl Fn(Value) -> T,
    ) -> fmi2Status {
        let instantiated = match self.before_get(function, vrs.len(), out.len()) {
            Ok(i) => i,
            Err(s) => return s,
        };
        for (k, &vr) in vrs.iter().enumerate() {
            match self.slots.get(vr as usize) {
                Some(sl) if sl.index != u32::MAX && sl.ty == ty && sl.readable(instantiated) => {
                    out[k] = conv(self.vars.get(sl.index as usize));
                }
                _ => return self.get_error(function, ty, vr),
            }
        }
        fmi2Status::OK
    }

    /// fmi2GetReal: [`Runtime::get`] with each value read straight from its field.
    pub fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> fmi2Status {
        const F: &str = "fmi2GetReal";
        let instantiated = match self.before_get(F, vrs.len(), out.len()) {
            Ok(i) => i,
            Err(s) => return s,
        };
        let base = (&self.vars as *const M::Vars).cast::<u8>();
        for (k, &vr) in vrs.iter().enumerate() {
            match self.slots.get(vr as usize) {
                Some(sl) if sl.offset != usize::MAX && sl.readable(instantiated) => {
                    // SAFETY: `offset` is `offset_of!` of an f64 field of M::Vars
                    // (REAL_OFFSETS), so the pointer is in bounds and aligned.
                    out[k] = unsafe { base.add(sl.offset).cast::<f64>().read() };
                }
                // FMI 3.0's independent variable: the time (off the fast path).
                _ if self.independent_time == Some(vr) => out[k] = self.run.time,
                _ => return self.get_error(F, ScalarType::Real, vr),
            }
        }
        fmi2Status::OK
    }

    /// Expose the time as the variable of value reference
    /// [`Runtime::time_value_reference`] (FMI 3.0's independent variable): read by
    /// [`Runtime::get_real`], refused by every set.
    pub fn expose_time(&mut self) {
        self.independent_time = Some(self.time_value_reference());
    }

    /// fmi2SetReal: [`Runtime::set`] with each accepted value written straight to its
    /// field; the first value that needs more (a rounding outside its range, a refusal, a
    /// warning) and every later one go through [`Runtime::set`].
    pub fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> fmi2Status {
        const F: &str = "fmi2SetReal";
        if let Err(s) = self.before_set(F, vrs.len(), values.len()) {
            return s;
        }
        let init = self.run.initializing();
        let base = (&mut self.vars as *mut M::Vars).cast::<u8>();
        for (k, (&vr, &x)) in vrs.iter().zip(values).enumerate() {
            match self.slots.get(vr as usize) {
                Some(sl) if sl.offset != usize::MAX && sl.accepts(x, init) => {
                    // SAFETY: `offset` is `offset_of!` of an f64 field of M::Vars
                    // (REAL_OFFSETS), so the pointer is in bounds and aligned.
                    unsafe { base.add(sl.offset).cast::<f64>().write(x) };
                    self.run.mark_set(init, sl.is_input);
                }
                _ => {
                    return self.set(
                        F,
                        ScalarType::Real,
                        &vrs[k..],
                        values[k..].iter().map(|&x| Value::Real(x)),
                    )
                }
            }
        }
        fmi2Status::OK
    }

    /// The message of a refused get (off the fast path).
    #[cold]
    pub(super) fn get_error(&self, function: &str, ty: ScalarType, vr: u32) -> fmi2Status {
        let info = match self.variable_of_type(function, vr, ty) {
            Ok(info) => info,
            Err(s) => return s,
        };
        self.error(&format!(
            "{function}: '{}' is calculated and has no value before initialization",
            info.name
        ))
    }

    /// What every set does first: the state check and the array lengths.
    #[inline(always)]
    pub(super) fn before_set(
        &self,
        function: &str,
        vrs: usize,
        values: usize,
    ) -> Result<(), fmi2Status> {
        self.require_named(function, Function::SetReal.allowed())?;
        if vrs != values {
            return Err(self.length_mismatch(function, vrs, values));
        }
        Ok(())
    }

    #[cold]
    pub(super) fn length_mismatch(&self, function: &str, vrs: usize, values: usize) -> fmi2Status {
        self.error(&format!(
            "{function}: {vrs} value references but {values} values"
        ))
    }

    /// Set variables of type `ty` from `values`, each checked for causality, variability,
    /// finiteness and declared min/max.
    pub fn set(
        &mut self,
        function: &str,
        ty: ScalarType,
        vrs: &[u32],
        values: impl ExactSizeIterator<Item = Value>,
    ) -> fmi2Status {
        if let Err(s) = self.before_set(function, vrs.len(), values.len()) {
            return s;
        }
        let init = self.run.initializing();
        let mut status = fmi2Status::OK;
        for (&vr, value) in vrs.iter().zip(values) {
            let sl = match self.slots.get(vr as usize) {
                Some(sl) if sl.index != u32::MAX && sl.ty == ty => *sl,
                _ => return self.set_error(function, ty, vr, value),
            };
            let value = if sl.accepts(value.as_f64(), init) {
                value
            } else {
                match self.accept_out_of_range(function, &sl, value, init) {
                    Some((value, s)) => {
                        if s == fmi2Status::WARNING {
                            status = s;
                        }
                        value
                    }
                    None => return self.set_error(function, ty, vr, value),
                }
            };
            self.vars.set(sl.index as usize, value);
            self.run.mark_set(init, sl.is_input);
        }
        status
    }

    /// The exceptions to [`Slot::accepts`], for a finite value of an input that may be set
    /// now: a Real a hair outside its range (a host's float32 rounding: 1 arrives as
    /// 1.0000000149011612) is taken as the bound, up to RANGE_SLACK of the bound's size (at
    /// least of 1) beyond it; with `range_check` = 0 any value is used as it is, with a
    /// warning. `None`: refused.
    #[cold]
    pub(super) fn accept_out_of_range(
        &self,
        function: &str,
        sl: &Slot,
        value: Value,
        init: bool,
    ) -> Option<(Value, fmi2Status)> {
        let x = value.as_f64();
        if !(sl.settable(init) && sl.is_input && x.is_finite()) {
            return None;
        }
        if sl.ty == ScalarType::Real {
            let slack = |b: f64| RANGE_SLACK * b.abs().max(1.0);
            if x < sl.min && sl.min - x <= slack(sl.min) {
                return Some((Value::Real(sl.min), fmi2Status::OK));
            }
            if x > sl.max && x - sl.max <= slack(sl.max) {
                return Some((Value::Real(sl.max), fmi2Status::OK));
            }
        }
        if self.range_checked() {
            return None;
        }
        self.logger.log(
            fmi2Status::WARNING,
            "logStatusWarning",
            &format!(
                "{function}: '{}' = {x} is outside its range [{}, {}]; used as it is (range_check = 0)",
                M::Vars::VARIABLES[sl.index as usize].name,
                sl.min,
                sl.max
            ),
        );
        Some((value, fmi2Status::WARNING))
    }

    /// Whether inputs outside their range are refused (no `range_check`, or it is not 0).
    pub(super) fn range_checked(&self) -> bool {
        self.range_check
            .is_none_or(|i| self.vars.get(i).as_f64() != 0.0)
    }

    /// The message of a refused set (off the fast path).
    #[cold]
    pub(super) fn set_error(
        &self,
        function: &str,
        ty: ScalarType,
        vr: u32,
        value: Value,
    ) -> fmi2Status {
        if self.independent_time == Some(vr) {
            return self.error(&format!(
                "{function}: the independent variable 'time' cannot be set (vr {vr})"
            ));
        }
        let info = match self.variable_of_type(function, vr, ty) {
            Ok(info) => info,
            Err(s) => return s,
        };
        if !self.slots[vr as usize].settable(self.run.initializing()) {
            return self.error(&format!(
                "{function}: '{}' ({} {}) cannot be set in state '{}'",
                info.name,
                info.variability.xml_name(),
                info.causality.xml_name(),
                self.run.phase.name()
            ));
        }
        if let Value::Real(r) = value {
            if !r.is_finite() {
                return self.error(&format!(
                    "{function}: '{}' set to {r}, expected a finite number",
                    info.name
                ));
            }
        }
        if let Some(t) = info.enumeration {
            return self.error(&format!(
                "{function}: '{}' = {} is not an item of the Enumeration {} ({})",
                info.name,
                value.xml_text(),
                t.name,
                t.listed()
            ));
        }
        self.error(&format!(
            "{function}: '{}' = {} is outside its range [{}, {}]{}",
            info.name,
            value.xml_text(),
            info.min
                .map_or("-inf".into(), crate::variables::format_real),
            info.max.map_or("inf".into(), crate::variables::format_real),
            info.unit.map(|u| format!(" {u}")).unwrap_or_default()
        ))
    }

    /// Read String variables; `out(k, value)` receives the value of `vrs[k]`.
    pub fn get_strings(
        &mut self,
        function: &str,
        vrs: &[u32],
        mut out: impl FnMut(usize, &str),
    ) -> fmi2Status {
        if let Err(s) = self.require_named(function, Function::GetString.allowed()) {
            return s;
        }
        if self.run.phase == Phase::InitializationMode {
            self.try_initialize();
        }
        let instantiated = self.run.phase == Phase::Instantiated;
        for (k, &vr) in vrs.iter().enumerate() {
            match self.slots.get(vr as usize) {
                Some(sl)
                    if sl.index != u32::MAX
                        && sl.ty == ScalarType::String
                        && sl.readable(instantiated) =>
                {
                    out(k, self.vars.get_str(sl.index as usize).unwrap_or(""));
                }
                _ => return self.get_error(function, ScalarType::String, vr),
            }
        }
        fmi2Status::OK
    }

    /// Set String variables, each checked for causality, variability and state.
    pub fn set_strings(&mut self, function: &str, vrs: &[u32], values: &[&str]) -> fmi2Status {
        if let Err(s) = self.require_named(function, Function::SetString.allowed()) {
            return s;
        }
        if vrs.len() != values.len() {
            return self.error(&format!(
                "{function}: {} value references but {} values",
                vrs.len(),
                values.len()
            ));
        }
        let init = self.run.initializing();
        for (&vr, value) in vrs.iter().zip(values) {
            let sl = match self.slots.get(vr as usize) {
                Some(sl) if sl.index != u32::MAX && sl.ty == ScalarType::String => *sl,
                _ => return self.set_error(function, ScalarType::String, vr, Value::Str("")),
            };
            if !sl.settable(init) {
                return self.set_error(function, ScalarType::String, vr, Value::Str(""));
            }
            self.vars.set_str(sl.index as usize, value);
            self.run.mark_set(init, sl.is_input);
        }
        fmi2Status::OK
    }

    /// Set one String variable by name (tests and native hosts).
    pub fn set_string_by_name(&mut self, name: &str, value: &str) -> fmi2Status {
        match M::Vars::vr_of(name) {
            Some(vr) => self.set_strings("set", &[vr], &[value]),
            None => self.error(&format!(
                "no variable named '{name}' in model '{}'",
                M::INFO.name
            )),
        }
    }

    /// Read one String variable by name (tests and native hosts).
    pub fn get_string_by_name(&mut self, name: &str) -> Option<String> {
        let vr = M::Vars::vr_of(name)?;
        let mut value = None;
        (self.get_strings("get", &[vr], |_, s| value = Some(s.to_string())) == fmi2Status::OK)
            .then_some(value)
            .flatten()
    }

    /// Set one variable by name (tests and native hosts).
    pub fn set_by_name(&mut self, name: &str, value: Value) -> fmi2Status {
        if let Value::Str(s) = value {
            return self.set_string_by_name(name, s);
        }
        match M::Vars::vr_of(name) {
            Some(vr) => self.set("set", value.var_type(), &[vr], std::iter::once(value)),
            None => self.error(&format!(
                "no variable named '{name}' in model '{}'",
                M::INFO.name
            )),
        }
    }

    /// Read one variable by name (tests and native hosts).
    pub fn get_by_name(&mut self, name: &str) -> Option<Value> {
        let i = M::Vars::index_of(name)?;
        let vr = M::Vars::VARIABLES[i].value_reference;
        let ty = M::Vars::VARIABLES[i].var_type().value_space();
        let mut out = [Value::Real(0.0)];
        (self.get("get", ty, &[vr], &mut out, |v| v) == fmi2Status::OK).then_some(out[0])
    }
}

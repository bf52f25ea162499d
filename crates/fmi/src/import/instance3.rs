//! FMI 3.0 Co-Simulation: a safe instance with the same calls as an FMI 2.0
//! [`crate::Instance`], so every backend and the master stay version-blind (the library and
//! its functions: [`super::library3`]).
//!
//! Values travel as twinbench's kinds (Real as f64, Integer and Boolean as i32, String);
//! each value reference is one variable of the [`ModelDescription`] (array elements have
//! their own, see [`super::description3`]) and its [`Fmi3Slot`] says which typed call and
//! which element it is. Instances are created with event mode and early return off, as
//! FMPy's master does; `terminateSimulation` from `fmi3DoStep` ends the run at the step's end.

use super::log::LogSink;
use super::model::{Fmi3Slot, Fmi3Type, ModelDescription, ScalarVariable};
use crate::status::{CallStatus, FmiFunction};
use crate::{Experiment, FmuError, FmuInstance};
use std::collections::HashMap;
use std::ffi::{c_char, c_void, CString};
use std::path::Path;
use std::sync::Arc;

use super::library3::{Inst, Library3, Status};
use super::slots3::Slots;

/// The FMI 3.0 logger: no format string, so it is plain Rust (panics never cross into C).
unsafe extern "C" fn logger(
    env: *mut c_void,
    status: Status,
    category: *const c_char,
    message: *const c_char,
) {
    super::log::forward(env, status, category, message);
}

/// Hexadecimal text (FMI 3.0's notation of Binary values, spaces allowed) to bytes.
fn hex_bytes(text: &str) -> Option<Vec<u8>> {
    let digits: Vec<u8> = text.bytes().filter(|b| !b.is_ascii_whitespace()).collect();
    if !digits.len().is_multiple_of(2) {
        return None;
    }
    digits
        .chunks(2)
        .map(|p| u8::from_str_radix(std::str::from_utf8(p).ok()?, 16).ok())
        .collect()
}

/// A saved FMI 3.0 state; free it with [`Instance3::free_state`].
pub struct Fmu3State(*mut c_void);
unsafe impl Send for Fmu3State {}

/// The one-call get and set of a scalar FMI 3.0 type (`fmi3GetFloat64`, `fmi3SetInt32`):
/// the master's whole list in one call, as FMI 2.0's typed calls take it.
macro_rules! one_call {
    ($get:ident, $set:ident, $t:ty, $name:literal) => {
        one_call!(@ $get, &mut [$t], as_mut_ptr, concat!("fmi3Get", $name));
        one_call!(@ $set, &[$t], as_ptr, concat!("fmi3Set", $name));
    };
    (@ $f:ident, $slice:ty, $ptr:ident, $function:expr) => {
        #[inline]
        fn $f(&mut self, vrs: &[u32], values: $slice) -> Result<(), FmuError> {
            self.values(self.lib.api.$f, $function, vrs, values.$ptr(), values.len())
        }
    };
}

pub struct Instance3 {
    lib: Arc<Library3>,
    inst: Inst,
    pub name: String,
    /// Simulation time of the last successful step.
    pub time: f64,
    slots: Slots,
    /// Every variable exchanged as a Real is a scalar Float64, every one exchanged as an
    /// Integer a scalar Int32: the master's lists (typed by the plan) then go to the FMU in
    /// one call without a look at each reference, as FMI 2.0's do.
    reals_are_float64: bool,
    ints_are_int32: bool,
    names: HashMap<u32, String>,
    /// Set when `fmi3DoStep` asked to end the simulation: the time reached.
    terminate_requested: Option<f64>,
    start: f64,
    stop: Option<f64>,
    /// The relative tolerance passed to `fmi3EnterInitializationMode`.
    tolerance: Option<f64>,
    sink: Box<LogSink>,
}

// One instance is used by one thread at a time.
unsafe impl Send for Instance3 {}

/// The `resourcePath` of FMI 3.0: a native path ending in a separator.
fn resource_path(dir: &Path) -> String {
    let mut s = dir.to_string_lossy().into_owned();
    if !s.ends_with('/') {
        s.push('/');
    }
    s
}

/// Each variable's slot and name, by its value reference (an array element's internal one).
fn value_slots(md: &ModelDescription) -> (Vec<(u32, Fmi3Slot)>, HashMap<u32, String>) {
    let mut slots = Vec::new();
    let mut names = HashMap::new();
    for v in &md.variables {
        if let Some(s) = v.fmi3 {
            slots.push((v.value_reference, s));
            names.insert(v.value_reference, v.name.clone());
        }
    }
    (slots, names)
}

/// Whether every variable exchanged as a Real is a scalar Float64, and whether every one
/// exchanged as an Integer is a scalar Int32 (the one-call paths of [`Instance3`]).
fn one_call_types(md: &ModelDescription) -> (bool, bool) {
    let scalar = |v: &ScalarVariable, ty: Fmi3Type| {
        v.fmi3
            .is_some_and(|s| s.ty == ty && s.len == 1 && !s.element && s.vr == v.value_reference)
    };
    let reals_are_float64 = md
        .variables
        .iter()
        .filter(|v| v.ty == crate::ScalarType::Real)
        .all(|v| scalar(v, Fmi3Type::Float64));
    let ints_are_int32 = md
        .variables
        .iter()
        .filter(|v| {
            matches!(
                v.ty,
                crate::ScalarType::Integer | crate::ScalarType::Enumeration
            )
        })
        .all(|v| scalar(v, Fmi3Type::Int32));
    (reals_are_float64, ints_are_int32)
}

impl Instance3 {
    pub fn instantiate(
        lib: Arc<Library3>,
        md: &ModelDescription,
        name: &str,
        resource_dir: Option<&Path>,
        logging_on: bool,
    ) -> Result<Instance3, FmuError> {
        Self::instantiate_as(lib, md, name, resource_dir, logging_on, false)
    }

    /// Instantiate for Co-Simulation, or for Model Exchange (`fmi3InstantiateModelExchange`,
    /// the library loaded with [`Library3::load_model_exchange`]): the instance that
    /// [`crate::MeInstance`] integrates.
    pub(crate) fn instantiate_as(
        lib: Arc<Library3>,
        md: &ModelDescription,
        name: &str,
        resource_dir: Option<&Path>,
        logging_on: bool,
        model_exchange: bool,
    ) -> Result<Instance3, FmuError> {
        let sink = Box::new(LogSink::new3(name));
        let bad = |m: &str| FmuError::Instantiate {
            instance: name.into(),
            message: m.into(),
        };
        let c_name = CString::new(name).map_err(|_| bad("instance name contains a NUL byte"))?;
        let c_token = CString::new(md.guid.as_str()).unwrap_or_default();
        let c_res = resource_dir.map(|d| CString::new(resource_path(d)).unwrap_or_default());
        let env = &*sink as *const LogSink as *mut c_void;
        let res = c_res.as_ref().map_or(std::ptr::null(), |c| c.as_ptr());
        let (inst, call) = match (model_exchange, lib.me) {
            (true, Some(me)) => (
                unsafe {
                    (me.instantiate_model_exchange)(
                        c_name.as_ptr(),
                        c_token.as_ptr(),
                        res,
                        false,
                        logging_on,
                        env,
                        Some(logger),
                    )
                },
                "fmi3InstantiateModelExchange",
            ),
            (true, None) => {
                return Err(bad("the library was not loaded for Model Exchange"));
            }
            (false, _) => (
                unsafe {
                    (lib.api.instantiate_co_simulation)(
                        c_name.as_ptr(),
                        c_token.as_ptr(),
                        res,
                        false,
                        logging_on,
                        false, // eventModeUsed
                        false, // earlyReturnAllowed
                        std::ptr::null(),
                        0,
                        env,
                        Some(logger),
                        std::ptr::null(),
                    )
                },
                "fmi3InstantiateCoSimulation",
            ),
        };
        if inst.is_null() {
            return Err(bad(&format!(
                "{call} returned NULL; the FMU's log: {}",
                sink.last_lines().join(" | ")
            )));
        }
        let (slots, names) = value_slots(md);
        let (reals_are_float64, ints_are_int32) = one_call_types(md);
        let slots = Slots::new(slots);
        Ok(Instance3 {
            lib,
            inst,
            name: name.to_string(),
            time: 0.0,
            slots,
            reals_are_float64,
            ints_are_int32,
            names,
            terminate_requested: None,
            start: 0.0,
            stop: None,
            tolerance: None,
            sink,
        })
    }

    /// The FMU's instance, for the Model Exchange calls.
    pub(crate) fn raw(&self) -> Inst {
        self.inst
    }

    pub(crate) fn sink(&self) -> &LogSink {
        &self.sink
    }

    pub fn library(&self) -> &Arc<Library3> {
        &self.lib
    }

    #[inline]
    fn check(&self, function: &'static str, status: Status) -> Result<(), FmuError> {
        if status == 0 || status == 1 {
            Ok(())
        } else {
            Err(self.call_error(function, status))
        }
    }

    #[cold]
    #[inline(never)]
    fn call_error(&self, function: &'static str, status: Status) -> FmuError {
        FmuError::call(
            &self.name,
            FmiFunction::Fmi3(function.into()),
            CallStatus::Fmi3(status),
            self.time,
            self.sink.last_lines(),
        )
    }

    fn other(&self, message: String) -> FmuError {
        FmuError::Instantiate {
            instance: self.name.clone(),
            message,
        }
    }

    fn slot(&self, vr: u32) -> Result<Fmi3Slot, FmuError> {
        self.slots
            .get(vr)
            .ok_or_else(|| self.other(format!("no FMI 3.0 variable has value reference {vr}")))
    }

    fn name_of(&self, vr: u32) -> &str {
        self.names.get(&vr).map_or("?", String::as_str)
    }

    /// Read one variable (an array element reads its whole array) as f64.
    fn get_one(&mut self, slot: Fmi3Slot) -> Result<f64, FmuError> {
        let n = slot.len as usize;
        let vr = [slot.vr];
        macro_rules! get {
            ($f:ident, $t:ty, $name:literal) => {{
                // A scalar on the stack: nothing allocated in the step loop.
                if n == 1 {
                    let mut one: [$t; 1] = [Default::default()];
                    let s = unsafe {
                        (self.lib.api.$f)(self.inst, vr.as_ptr(), 1, one.as_mut_ptr(), 1)
                    };
                    self.check(concat!("fmi3Get", $name), s)?;
                    one[0]
                } else {
                    let mut buf: Vec<$t> = vec![Default::default(); n];
                    let s = unsafe {
                        (self.lib.api.$f)(self.inst, vr.as_ptr(), 1, buf.as_mut_ptr(), n)
                    };
                    self.check(concat!("fmi3Get", $name), s)?;
                    buf[slot.index as usize]
                }
            }};
        }
        Ok(match slot.ty {
            Fmi3Type::Float32 => get!(get_float32, f32, "Float32") as f64,
            Fmi3Type::Float64 => get!(get_float64, f64, "Float64"),
            Fmi3Type::Int8 => get!(get_int8, i8, "Int8") as f64,
            Fmi3Type::UInt8 => get!(get_uint8, u8, "UInt8") as f64,
            Fmi3Type::Int16 => get!(get_int16, i16, "Int16") as f64,
            Fmi3Type::UInt16 => get!(get_uint16, u16, "UInt16") as f64,
            Fmi3Type::Int32 => get!(get_int32, i32, "Int32") as f64,
            Fmi3Type::UInt32 => get!(get_uint32, u32, "UInt32") as f64,
            Fmi3Type::Enumeration => get!(get_int64, i64, "Int64") as f64,
            Fmi3Type::Int64 => {
                let x = get!(get_int64, i64, "Int64");
                self.exact(slot, x, x as f64, |f| f as i64)?
            }
            Fmi3Type::UInt64 => {
                let x = get!(get_uint64, u64, "UInt64");
                self.exact(slot, x, x as f64, |f| f as u64)?
            }
            Fmi3Type::Boolean => (get!(get_boolean, u8, "Boolean") != 0) as i32 as f64,
            Fmi3Type::String | Fmi3Type::Binary => {
                return Err(self.other("a String read as a number".into()))
            }
        })
    }

    /// A 64-bit integer as f64, when the f64 carries it exactly (it does up to 2^53, and at
    /// the type's limits, where the conversion back saturates to the same value).
    /// `f` is `x` as f64, `back` the conversion back to the integer type.
    fn exact<T: PartialEq + std::fmt::Display>(
        &self,
        slot: Fmi3Slot,
        x: T,
        f: f64,
        back: fn(f64) -> T,
    ) -> Result<f64, FmuError> {
        if back(f) == x {
            Ok(f)
        } else {
            Err(self.not_exact(slot, &x.to_string()))
        }
    }

    #[cold]
    fn not_exact(&self, slot: Fmi3Slot, x: &str) -> FmuError {
        let name = self
            .slots
            .iter()
            .find(|(_, s)| *s == slot)
            .map_or("?", |(vr, _)| self.name_of(vr));
        self.other(format!(
            "'{name}' ({}) is {x}, which twinbench cannot carry exactly (64-bit integers travel as doubles, exact up to 2^53)",
            slot.ty.name()
        ))
    }

    /// Write one variable from f64 (an array element: read the array, change it, write it).
    fn set_one(&mut self, vr_tb: u32, slot: Fmi3Slot, value: f64) -> Result<(), FmuError> {
        if slot.structural {
            return Err(self.other(format!(
                "'{}' is a structural parameter (it sizes arrays); twinbench does not change it",
                self.name_of(vr_tb)
            )));
        }
        // fmi3Boolean is a C bool: only 0 or 1 may be written.
        let value = if slot.ty == Fmi3Type::Boolean {
            (value != 0.0) as u8 as f64
        } else {
            value
        };
        self.check_fits(vr_tb, slot.ty, value)?;
        self.write_one(slot, value)
    }

    /// A value set into an integer variable must fit its FMI 3.0 type.
    fn check_fits(&self, vr_tb: u32, ty: Fmi3Type, value: f64) -> Result<(), FmuError> {
        // An integer value must fit the FMU's type exactly: no wrapping, no truncation.
        let fits = |lo: f64, hi: f64| value.fract() == 0.0 && value >= lo && value <= hi;
        let in_range = match ty {
            Fmi3Type::Int8 => fits(i8::MIN as f64, i8::MAX as f64),
            Fmi3Type::UInt8 => fits(0.0, u8::MAX as f64),
            Fmi3Type::Int16 => fits(i16::MIN as f64, i16::MAX as f64),
            Fmi3Type::UInt16 => fits(0.0, u16::MAX as f64),
            Fmi3Type::Int32 => fits(i32::MIN as f64, i32::MAX as f64),
            Fmi3Type::UInt32 => fits(0.0, u32::MAX as f64),
            Fmi3Type::UInt64 => fits(0.0, f64::MAX),
            Fmi3Type::Int64 | Fmi3Type::Enumeration => fits(f64::MIN, f64::MAX),
            _ => true,
        };
        if !in_range {
            return Err(self.other(format!(
                "{value} does not fit '{}' ({})",
                self.name_of(vr_tb),
                ty.name()
            )));
        }
        Ok(())
    }

    /// `value` (in range) into `slot` by the typed call of its type: a scalar from the
    /// stack, an array element by reading the array, changing it and writing it back.
    fn write_one(&mut self, slot: Fmi3Slot, value: f64) -> Result<(), FmuError> {
        let n = slot.len as usize;
        let vr = [slot.vr];
        macro_rules! set {
            ($get:ident, $set:ident, $t:ty, $name:literal) => {{
                if n == 1 {
                    // A scalar from the stack: nothing allocated in the step loop.
                    let one: [$t; 1] = [value as $t];
                    let s =
                        unsafe { (self.lib.api.$set)(self.inst, vr.as_ptr(), 1, one.as_ptr(), 1) };
                    return self.check(concat!("fmi3Set", $name), s);
                }
                let mut buf: Vec<$t> = vec![Default::default(); n];
                if n > 1 {
                    let s = unsafe {
                        (self.lib.api.$get)(self.inst, vr.as_ptr(), 1, buf.as_mut_ptr(), n)
                    };
                    self.check(concat!("fmi3Get", $name), s)?;
                }
                buf[slot.index as usize] = value as $t;
                let s = unsafe { (self.lib.api.$set)(self.inst, vr.as_ptr(), 1, buf.as_ptr(), n) };
                self.check(concat!("fmi3Set", $name), s)
            }};
        }
        match slot.ty {
            Fmi3Type::Float32 => set!(get_float32, set_float32, f32, "Float32"),
            Fmi3Type::Float64 => set!(get_float64, set_float64, f64, "Float64"),
            Fmi3Type::Int8 => set!(get_int8, set_int8, i8, "Int8"),
            Fmi3Type::UInt8 => set!(get_uint8, set_uint8, u8, "UInt8"),
            Fmi3Type::Int16 => set!(get_int16, set_int16, i16, "Int16"),
            Fmi3Type::UInt16 => set!(get_uint16, set_uint16, u16, "UInt16"),
            Fmi3Type::Int32 => set!(get_int32, set_int32, i32, "Int32"),
            Fmi3Type::UInt32 => set!(get_uint32, set_uint32, u32, "UInt32"),
            Fmi3Type::Int64 | Fmi3Type::Enumeration => {
                set!(get_int64, set_int64, i64, "Int64")
            }
            Fmi3Type::UInt64 => set!(get_uint64, set_uint64, u64, "UInt64"),
            Fmi3Type::Boolean => {
                set!(get_boolean, set_boolean, u8, "Boolean")
            }
            Fmi3Type::String | Fmi3Type::Binary => {
                Err(self.other("a String set from a number".into()))
            }
        }
    }

    /// One typed call: `values` points at `n` values for the references `vrs`.
    #[inline]
    fn values<P>(
        &self,
        call: unsafe extern "C" fn(Inst, *const u32, usize, P, usize) -> Status,
        function: &'static str,
        vrs: &[u32],
        values: P,
        n: usize,
    ) -> Result<(), FmuError> {
        // SAFETY: the instance is live and `values` points at `n` values.
        let s = unsafe { call(self.inst, vrs.as_ptr(), vrs.len(), values, n) };
        self.check(function, s)
    }

    one_call!(get_float64, set_float64, f64, "Float64");
    one_call!(get_int32, set_int32, i32, "Int32");

    /// Whether every reference is a scalar of type `ty` (one call of its type then).
    #[inline]
    fn all_scalar(&self, vrs: &[u32], ty: Fmi3Type) -> bool {
        vrs.iter().all(|&vr| self.slots.scalar_type(vr) == Some(ty))
    }

    /// Values exchanged as `T` (Reals of other types or array elements, Integers of other
    /// types): one call (`one_call`) when these are all scalars of type `ty` after all,
    /// else one per value, each converted by `from` (which refuses what `T` cannot carry).
    #[inline(never)]
    fn get_mixed<T>(
        &mut self,
        vrs: &[u32],
        out: &mut [T],
        ty: Fmi3Type,
        one_call: impl FnOnce(&mut Self, &[u32], &mut [T]) -> Result<(), FmuError>,
        from: impl Fn(&Self, u32, Fmi3Slot, f64) -> Result<T, FmuError>,
    ) -> Result<(), FmuError> {
        if self.all_scalar(vrs, ty) {
            return one_call(self, vrs, out);
        }
        for (vr, o) in vrs.iter().zip(out.iter_mut()) {
            let slot = self.slot(*vr)?;
            let x = self.get_one(slot)?;
            *o = from(self, *vr, slot, x)?;
        }
        Ok(())
    }

    /// The setting side of [`Self::get_mixed`].
    #[inline(never)]
    fn set_mixed<T: Copy + Into<f64>>(
        &mut self,
        vrs: &[u32],
        values: &[T],
        ty: Fmi3Type,
        one_call: impl FnOnce(&mut Self, &[u32], &[T]) -> Result<(), FmuError>,
    ) -> Result<(), FmuError> {
        if self.all_scalar(vrs, ty) {
            return one_call(self, vrs, values);
        }
        self.set_each(vrs, values.iter().map(|&v| v.into()))
    }

    /// Values of other types or array elements: one call per value (off the fast path).
    #[cold]
    #[inline(never)]
    fn set_each(&mut self, vrs: &[u32], values: impl Iterator<Item = f64>) -> Result<(), FmuError> {
        for (vr, v) in vrs.iter().zip(values) {
            let slot = self.slot(*vr)?;
            self.set_one(*vr, slot, v)?;
        }
        Ok(())
    }

    /// Integer, Enumeration and Boolean values as i32; a value beyond 32 bits is an error
    /// naming the variable (never wrapped).
    #[inline]
    pub fn get_int(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        if !self.ints_are_int32 {
            return self.get_mixed(vrs, out, Fmi3Type::Int32, Self::get_int32, Self::int32_of);
        }
        self.get_int32(vrs, out)
    }

    /// An integer of another type as i32, checked to fit 32 bits.
    fn int32_of(&self, vr: u32, slot: Fmi3Slot, x: f64) -> Result<i32, FmuError> {
        if x < i32::MIN as f64 || x > i32::MAX as f64 {
            return Err(self.other(format!(
                "'{}' ({}) is {x}, beyond the 32-bit integers twinbench exchanges",
                self.name_of(vr),
                slot.ty.name()
            )));
        }
        Ok(x as i32)
    }

    #[inline]
    pub fn set_int(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        if !self.ints_are_int32 {
            return self.set_mixed(vrs, values, Fmi3Type::Int32, Self::set_int32);
        }
        self.set_int32(vrs, values)
    }

    /// A step that did more than complete: its error, early return or end of the run.
    #[cold]
    #[inline(never)]
    fn step_outcome(
        &mut self,
        t: f64,
        h: f64,
        s: Status,
        terminate: u8,
        early: u8,
        last: f64,
    ) -> Result<(), FmuError> {
        self.time = t;
        self.check("fmi3DoStep", s)?;
        let reached = if early != 0 && last.is_finite() && last < t + h {
            last
        } else {
            t + h
        };
        // Instantiated with earlyReturnAllowed = false: a step that returns early anyway
        // (and does not end the run) did not reach t + h, and taking it as if it had would
        // be a silent wrong result.
        if early != 0 && terminate == 0 {
            return Err(FmuError::EarlyReturn {
                instance: self.name.clone(),
                time: t,
                last,
                target: t + h,
                log: self.sink.last_lines(),
            });
        }
        self.time = reached;
        if terminate != 0 {
            self.terminate_requested = Some(reached);
            return Err(FmuError::step_discarded(&self.name, reached));
        }
        Ok(())
    }

    pub fn get_state(&mut self) -> Result<Fmu3State, FmuError> {
        let mut st = std::ptr::null_mut();
        let s = unsafe { (self.lib.api.get_fmu_state)(self.inst, &mut st) };
        self.check("fmi3GetFMUState", s)?;
        Ok(Fmu3State(st))
    }

    pub fn set_state(&mut self, state: &Fmu3State, time: f64) -> Result<(), FmuError> {
        let s = unsafe { (self.lib.api.set_fmu_state)(self.inst, state.0) };
        self.time = time;
        self.check("fmi3SetFMUState", s)
    }

    pub fn free_state(&mut self, mut state: Fmu3State) -> Result<(), FmuError> {
        let s = unsafe { (self.lib.api.free_fmu_state)(self.inst, &mut state.0) };
        self.check("fmi3FreeFMUState", s)
    }

    pub fn serialize_state(&mut self, state: &Fmu3State) -> Result<Vec<u8>, FmuError> {
        let mut n = 0usize;
        let s = unsafe { (self.lib.api.serialized_fmu_state_size)(self.inst, state.0, &mut n) };
        self.check("fmi3SerializedFMUStateSize", s)?;
        let mut buf = vec![0u8; n];
        let s =
            unsafe { (self.lib.api.serialize_fmu_state)(self.inst, state.0, buf.as_mut_ptr(), n) };
        self.check("fmi3SerializeFMUState", s)?;
        Ok(buf)
    }

    pub fn deserialize_state(&mut self, bytes: &[u8]) -> Result<Fmu3State, FmuError> {
        let mut st = std::ptr::null_mut();
        let s = unsafe {
            (self.lib.api.deserialize_fmu_state)(self.inst, bytes.as_ptr(), bytes.len(), &mut st)
        };
        self.check("fmi3DeserializeFMUState", s)?;
        Ok(Fmu3State(st))
    }
}

impl FmuInstance for Instance3 {
    fn name(&self) -> &str {
        &self.name
    }

    fn time(&self) -> f64 {
        self.time
    }

    /// FMI 3.0's Int32, Int64, UInt… and Enumeration all travel as an FMI 2.0 Integer.
    #[inline]
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.get_int(vrs, out)
    }

    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.set_int(vrs, values)
    }

    /// A Boolean travels as an FMI 2.0 Boolean (an integer); `get_int` reads FMI 3.0's.
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        self.get_int(vrs, out)
    }

    fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.set_int(vrs, values)
    }

    fn last_log_lines(&self) -> Vec<String> {
        self.sink.last_lines()
    }

    fn set_echo(&mut self, on: bool) {
        self.sink.set_echo(on)
    }

    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        let s = unsafe { (self.lib.api.set_debug_logging)(self.inst, on, 0, std::ptr::null()) };
        self.check("fmi3SetDebugLogging", s)
    }

    /// FMI 3.0 has no fmi2SetupExperiment: start and stop go with the initialization mode.
    fn setup_experiment(&mut self, e: Experiment) -> Result<(), FmuError> {
        self.tolerance = e.tolerance;
        self.start = e.start;
        self.time = e.start;
        self.stop = e.stop;
        Ok(())
    }

    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        let s = unsafe {
            (self.lib.api.enter_initialization_mode)(
                self.inst,
                self.tolerance.is_some(),
                self.tolerance.unwrap_or(0.0),
                self.start,
                self.stop.is_some(),
                self.stop.unwrap_or(0.0),
            )
        };
        self.check("fmi3EnterInitializationMode", s)
    }

    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        let s = unsafe { (self.lib.api.exit_initialization_mode)(self.inst) };
        self.check("fmi3ExitInitializationMode", s)
    }

    fn terminate(&mut self) -> Result<(), FmuError> {
        let s = unsafe { (self.lib.api.terminate)(self.inst) };
        self.check("fmi3Terminate", s)
    }

    fn reset(&mut self) -> Result<(), FmuError> {
        let s = unsafe { (self.lib.api.reset)(self.inst) };
        self.sink.clear();
        self.time = 0.0;
        self.terminate_requested = None;
        self.check("fmi3Reset", s)
    }

    /// The usual call when every Real is a scalar Float64: as short as FMI 2.0's, the
    /// rest (`get_mixed`) off the fast path.
    #[inline]
    fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        if !self.reals_are_float64 {
            return self.get_mixed(
                vrs,
                out,
                Fmi3Type::Float64,
                Self::get_float64,
                |_, _, _, x| Ok(x),
            );
        }
        self.get_float64(vrs, out)
    }

    /// As [`Self::get_real`].
    #[inline]
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        if !self.reals_are_float64 {
            return self.set_mixed(vrs, values, Fmi3Type::Float64, Self::set_float64);
        }
        self.set_float64(vrs, values)
    }

    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        out.clear();
        for vr in vrs {
            let slot = self.slot(*vr)?;
            let n = slot.len as usize;
            if slot.ty == Fmi3Type::Binary {
                let mut sizes = vec![0usize; n];
                let mut ptrs: Vec<*const u8> = vec![std::ptr::null(); n];
                let s = unsafe {
                    (self.lib.api.get_binary)(
                        self.inst,
                        &slot.vr,
                        1,
                        sizes.as_mut_ptr(),
                        ptrs.as_mut_ptr(),
                        n,
                    )
                };
                self.check("fmi3GetBinary", s)?;
                let (p, len) = (ptrs[slot.index as usize], sizes[slot.index as usize]);
                super::too_long(len, &self.name, "fmi3GetBinary", *vr)?;
                let bytes = if p.is_null() || len == 0 {
                    &[][..]
                } else {
                    unsafe { std::slice::from_raw_parts(p, len) }
                };
                out.push(bytes.iter().map(|b| format!("{b:02x}")).collect());
                continue;
            }
            let mut ptrs: Vec<*const c_char> = vec![std::ptr::null(); n];
            let s =
                unsafe { (self.lib.api.get_string)(self.inst, &slot.vr, 1, ptrs.as_mut_ptr(), n) };
            self.check("fmi3GetString", s)?;
            // SAFETY: the FMU keeps its strings valid until its next call.
            out.push(unsafe {
                super::string_from_fmu(ptrs[slot.index as usize], &self.name, "fmi3GetString", *vr)
            }?);
        }
        Ok(())
    }

    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        for (vr, v) in vrs.iter().zip(values) {
            let slot = self.slot(*vr)?;
            if slot.len != 1 {
                return Err(self.other(format!(
                    "'{}': String arrays are not supported",
                    self.name_of(*vr)
                )));
            }
            if slot.ty == Fmi3Type::Binary {
                let bytes = hex_bytes(v).ok_or_else(|| {
                    self.other(format!(
                        "'{}' is Binary: \"{v}\" is not an even number of hexadecimal digits",
                        self.name_of(*vr)
                    ))
                })?;
                let (p, len) = (bytes.as_ptr(), bytes.len());
                let s = unsafe { (self.lib.api.set_binary)(self.inst, &slot.vr, 1, &len, &p, 1) };
                self.check("fmi3SetBinary", s)?;
                continue;
            }
            let c = CString::new(*v)
                .map_err(|_| self.other("fmi3SetString: a value contains a NUL byte".into()))?;
            let p = c.as_ptr();
            let s = unsafe { (self.lib.api.set_string)(self.inst, &slot.vr, 1, &p, 1) };
            self.check("fmi3SetString", s)?;
        }
        Ok(())
    }

    /// One communication step. When the FMU asks to end the simulation the step still
    /// counts (FMPy records its end and stops): the call then reports `fmi2Discard` so that
    /// the master asks [`Instance3::terminated_by_fmu`], which gives the time reached.
    #[inline]
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        // eventHandlingNeeded, terminateSimulation, earlyReturn: read back as one word.
        let mut flags = [0u8; 4];
        let mut last = t + h;
        let [event, terminate, early, _] = flags.each_mut();
        let s = unsafe {
            (self.lib.api.do_step)(self.inst, t, h, true, event, terminate, early, &mut last)
        };
        // The usual step: completed, no event, no early return, not the end.
        if s == 0 && u32::from_ne_bytes(flags) == 0 {
            self.time = t + h;
            return Ok(());
        }
        let [_, terminate, early, _] = flags;
        self.step_outcome(t, h, s, terminate, early, last)
    }

    /// After `fmi3DoStep` set `terminateSimulation`: the time reached.
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        self.terminate_requested
    }
}

impl Drop for Instance3 {
    fn drop(&mut self) {
        unsafe { (self.lib.api.free_instance)(self.inst) };
    }
}

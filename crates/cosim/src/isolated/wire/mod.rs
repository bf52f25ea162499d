//! The worker protocol, described once: the operations a host asks for ([`Request`]) and
//! the worker's answer ([`Response`]), each with its encoding. The host ([`super::host`])
//! and the worker ([`super::worker`]) both use them; nothing else reads or writes the wire.
//!
//! Frames are length-prefixed (`u32`, little-endian), at most [`MAX_FRAME`] bytes. A
//! request frame is a sequence of operations, run in order until the first error; each
//! starts with its code: an FMI call's code is its number in [`tb_fmi::FUNCTIONS`]
//! (`Function as u8`), so the table that loads an FMU's symbols also names the calls on the
//! wire; the protocol's own codes are [`op::INSTANTIATE`], [`op::PROBE`], [`op::QUIT`] and
//! [`op::FMU_TERMINATED`]. Numbers are little-endian, a string is its length (`u32`) and
//! its UTF-8 bytes, an array of value references its count (`u32`) and the references;
//! the values of a set follow without a count (one per value reference).
//!
//! A response: `ok: u8` (0: ok), the number of completed gets `u32`, the instance's time
//! `f64`, each completed get's values (as many as it asked for, no count), then (when not
//! ok) the error: a [`kind`] and its fields ([`Failure`]).

use std::borrow::Cow;
use tb_fmi::fmi2::fmi2Status;
pub use tb_fmi::import::archive::FileCheck;
use tb_fmi::{CallStatus, FmiFunction, FmuError, Function};

/// Operation codes.
pub mod op {
    use tb_fmi::Function;

    /// Load the FMU's library (a [`super::LibraryTarget`]), then instantiate (name, GUID,
    /// resource folder, logging).
    pub const INSTANTIATE: u8 = 200;
    /// Free the instance and end the worker.
    pub const QUIT: u8 = 201;
    /// Load the FMU's library (a [`super::LibraryTarget`]) and answer with two strings:
    /// what `fmi2GetVersion` returned and the missing optional functions (comma-separated).
    pub const PROBE: u8 = 202;
    /// After a discarded step: two Reals, whether the FMU asks to end the simulation (1 or
    /// 0) and its last successful time.
    pub const FMU_TERMINATED: u8 = 203;
    /// A real-time check of the instance (its settings as JSON, `tb_cosim::realtime`):
    /// answered with one string, the measurement as JSON.
    pub const REALTIME: u8 = 204;

    pub const SET_DEBUG_LOGGING: u8 = Function::SetDebugLogging as u8;
    pub const SETUP_EXPERIMENT: u8 = Function::SetupExperiment as u8;
    pub const ENTER_INIT: u8 = Function::EnterInitializationMode as u8;
    pub const EXIT_INIT: u8 = Function::ExitInitializationMode as u8;
    pub const TERMINATE: u8 = Function::Terminate as u8;
    pub const RESET: u8 = Function::Reset as u8;
    pub const SET_REAL: u8 = Function::SetReal as u8;
    pub const SET_INTEGER: u8 = Function::SetInteger as u8;
    pub const SET_BOOLEAN: u8 = Function::SetBoolean as u8;
    pub const GET_REAL: u8 = Function::GetReal as u8;
    pub const GET_INTEGER: u8 = Function::GetInteger as u8;
    pub const GET_BOOLEAN: u8 = Function::GetBoolean as u8;
    pub const GET_STRING: u8 = Function::GetString as u8;
    pub const SET_STRING: u8 = Function::SetString as u8;
    pub const DO_STEP: u8 = Function::DoStep as u8;
}

/// Error kinds in a response.
pub mod kind {
    /// An FMI call (either version) returned a status that stops the caller: the function
    /// (FMI 2.0's code or FMI 3.0's name), the status, time, log.
    pub const CALL: u8 = 0;
    /// `fmi2Instantiate` failed: the message.
    pub const INSTANTIATE: u8 = 1;
    /// An optional function the FMU does not export: its code.
    pub const UNSUPPORTED: u8 = 2;
    /// Anything else: a message.
    pub const OTHER: u8 = 3;
    /// An FMI 3.0 step returned early although it may not: time, last successful time,
    /// the step's end, log.
    pub const EARLY_RETURN: u8 = 4;
    /// A Model Exchange instance's call or its solver failed: the .fmu, the call, what
    /// went wrong, time, log.
    pub const MODEL_EXCHANGE: u8 = 5;
}

/// The function an operation code stands for (for messages).
pub fn function_of(code: u8) -> Option<Function> {
    match code {
        op::INSTANTIATE => Some(Function::Instantiate),
        op::PROBE => Some(Function::GetVersion),
        op::FMU_TERMINATED => Some(Function::GetBooleanStatus),
        op::QUIT => Some(Function::FreeInstance),
        c => Function::from_u8(c),
    }
}

/// Why a frame cannot be read: what the reader expected and where, never the frame's bytes.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum WireError {
    #[error("truncated message: {needed} bytes needed at offset {offset}")]
    Truncated { needed: usize, offset: usize },
    #[error("count {count} exceeds the message")]
    Count { count: usize },
    #[error("unknown operation {0}")]
    UnknownOperation(u8),
    #[error("unknown function code {0}")]
    UnknownFunction(u8),
    #[error("unknown error kind {0}")]
    UnknownKind(u8),
    #[error("unknown FMI version {0} of a failed call")]
    UnknownVersion(u8),
    #[error("{results} results for {gets} gets")]
    Results { results: usize, gets: usize },
    #[error("trailing bytes")]
    Trailing,
}

/// Largest frame accepted (a corrupted or forged length must not allocate gigabytes).
/// A step's answer is a few kilobytes; 64 MiB leaves room for huge string outputs.
pub const MAX_FRAME: usize = 64 << 20;

/// The FMU library a worker loads, with what it needs to name it in messages.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LibraryTarget {
    /// The unpacked library.
    pub path: String,
    /// The .fmu the user gave.
    pub source: String,
    pub model_identifier: String,
    /// Libraries loaded with RTLD_GLOBAL first (the system file's `preload`).
    pub preload: Vec<String>,
    /// FMI 3.0 and Model Exchange: the unpacked modelDescription.xml (the worker needs its
    /// variables' types, its states and event indicators); empty otherwise.
    pub description: String,
    /// Model Exchange: the worker runs the whole integration (the instance the master
    /// steps is the same backend as in-process). False: Co-Simulation.
    pub model_exchange: bool,
    /// Model Exchange: the solver's relative tolerance from the system (NaN: none).
    pub tolerance: f64,
    /// The unpacked files the worker verifies before it loads anything (the library, and
    /// FMI 3.0's description): where, size, mode, BLAKE3.
    pub checks: Vec<FileCheck>,
}

impl LibraryTarget {
    pub fn encode(&self, e: &mut Enc) {
        e.str(&self.path);
        e.str(&self.source);
        e.str(&self.model_identifier);
        e.u32(self.preload.len() as u32);
        self.preload.iter().for_each(|p| e.str(p));
        e.str(&self.description);
        e.u8(self.model_exchange as u8);
        e.f64(self.tolerance);
        e.u32(self.checks.len() as u32);
        for c in &self.checks {
            e.str(&c.base.to_string_lossy());
            e.str(&c.rel);
            // Sizes are within the unpack limit (2 GiB): exact as a double.
            e.f64(c.size as f64);
            e.u32(c.mode);
            e.str(&c.hash);
        }
    }
    pub fn decode(d: &mut Dec) -> Result<LibraryTarget, WireError> {
        let path = d.str()?;
        let source = d.str()?;
        let model_identifier = d.str()?;
        let n = d.count(4)?;
        let preload = (0..n).map(|_| d.str()).collect::<Result<_, _>>()?;
        let description = d.str()?;
        let model_exchange = d.u8()? != 0;
        let tolerance = d.f64()?;
        let n = d.count(4 + 4 + 8 + 4 + 4)?;
        let checks = d.each(n, |d| {
            Ok(FileCheck {
                base: d.str()?.into(),
                rel: d.str()?,
                size: d.f64()? as u64,
                mode: d.u32()?,
                hash: d.str()?,
            })
        })?;
        Ok(LibraryTarget {
            path,
            source,
            model_identifier,
            preload,
            description,
            model_exchange,
            tolerance,
            checks,
        })
    }
}

/// One operation of a request. Arrays are borrowed where the host encodes them and owned
/// where the worker decodes them.
#[derive(Clone, Debug, PartialEq)]
pub enum Request<'a> {
    /// Load the FMU's library (once per worker), then `fmi2Instantiate`.
    Instantiate {
        library: LibraryTarget,
        name: String,
        guid: String,
        /// The resource folder.
        resources: String,
        logging: bool,
    },
    /// Load the FMU's library and report on it; answered with [`Answer::Texts`] (2).
    Probe(LibraryTarget),
    /// Free the instance and end the worker (not answered).
    Quit,
    SetDebugLogging(bool),
    SetupExperiment {
        start: f64,
        stop: Option<f64>,
        tolerance: Option<f64>,
    },
    EnterInit,
    ExitInit,
    Terminate,
    Reset,
    SetReal {
        vrs: Cow<'a, [u32]>,
        values: Cow<'a, [f64]>,
    },
    SetInteger {
        vrs: Cow<'a, [u32]>,
        values: Cow<'a, [i32]>,
    },
    SetBoolean {
        vrs: Cow<'a, [u32]>,
        values: Cow<'a, [i32]>,
    },
    SetString {
        vrs: Cow<'a, [u32]>,
        values: Vec<Cow<'a, str>>,
    },
    GetReal {
        vrs: Cow<'a, [u32]>,
    },
    GetInteger {
        vrs: Cow<'a, [u32]>,
    },
    GetBoolean {
        vrs: Cow<'a, [u32]>,
    },
    GetString {
        vrs: Cow<'a, [u32]>,
    },
    /// After a discarded step: whether the FMU asks to end the simulation, and its last
    /// successful time; answered with [`Answer::Reals`] (2: 1 or 0, the time).
    FmuTerminated,
    DoStep {
        t: f64,
        h: f64,
    },
    /// Step the initialised instance under the real-time check's counters
    /// ([`crate::realtime::CheckSpec`] as JSON); answered with [`Answer::Texts`] (1: the
    /// [`crate::realtime::Measurement`] as JSON).
    Realtime(String),
}

/// What a get is answered with: so many values of one kind (the answer has no count).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Answer {
    Reals(usize),
    Ints(usize),
    Texts(usize),
}

impl Request<'_> {
    /// The operation's code on the wire.
    pub fn code(&self) -> u8 {
        match self {
            Request::Instantiate { .. } => op::INSTANTIATE,
            Request::Probe(_) => op::PROBE,
            Request::Quit => op::QUIT,
            Request::SetDebugLogging(_) => op::SET_DEBUG_LOGGING,
            Request::SetupExperiment { .. } => op::SETUP_EXPERIMENT,
            Request::EnterInit => op::ENTER_INIT,
            Request::ExitInit => op::EXIT_INIT,
            Request::Terminate => op::TERMINATE,
            Request::Reset => op::RESET,
            Request::SetReal { .. } => op::SET_REAL,
            Request::SetInteger { .. } => op::SET_INTEGER,
            Request::SetBoolean { .. } => op::SET_BOOLEAN,
            Request::SetString { .. } => op::SET_STRING,
            Request::GetReal { .. } => op::GET_REAL,
            Request::GetInteger { .. } => op::GET_INTEGER,
            Request::GetBoolean { .. } => op::GET_BOOLEAN,
            Request::GetString { .. } => op::GET_STRING,
            Request::FmuTerminated => op::FMU_TERMINATED,
            Request::DoStep { .. } => op::DO_STEP,
            Request::Realtime(_) => op::REALTIME,
        }
    }

    /// What the operation is answered with when it completes (None: nothing).
    pub fn answer(&self) -> Option<Answer> {
        match self {
            Request::GetReal { vrs } => Some(Answer::Reals(vrs.len())),
            Request::GetInteger { vrs } | Request::GetBoolean { vrs } => {
                Some(Answer::Ints(vrs.len()))
            }
            Request::GetString { vrs } => Some(Answer::Texts(vrs.len())),
            Request::Probe(_) => Some(Answer::Texts(2)),
            Request::Realtime(_) => Some(Answer::Texts(1)),
            Request::FmuTerminated => Some(Answer::Reals(2)),
            _ => None,
        }
    }

    /// Append the operation to a request.
    pub fn encode(&self, e: &mut Enc) {
        e.u8(self.code());
        match self {
            Request::Instantiate {
                library,
                name,
                guid,
                resources,
                logging,
            } => {
                library.encode(e);
                e.str(name);
                e.str(guid);
                e.str(resources);
                e.u8(*logging as u8);
            }
            Request::Probe(library) => library.encode(e),
            Request::Realtime(spec) => e.str(spec),
            Request::SetDebugLogging(on) => e.u8(*on as u8),
            Request::SetupExperiment {
                start,
                stop,
                tolerance,
            } => {
                e.f64(*start);
                e.u8(stop.is_some() as u8);
                e.f64(stop.unwrap_or(0.0));
                e.u8(tolerance.is_some() as u8);
                e.f64(tolerance.unwrap_or(0.0));
            }
            Request::SetReal { vrs, values } => {
                e.vrs(vrs);
                values.iter().for_each(|&x| e.f64(x));
            }
            Request::SetInteger { vrs, values } | Request::SetBoolean { vrs, values } => {
                e.vrs(vrs);
                values.iter().for_each(|&x| e.i32(x));
            }
            Request::SetString { vrs, values } => {
                e.vrs(vrs);
                values.iter().for_each(|s| e.str(s));
            }
            Request::GetReal { vrs }
            | Request::GetInteger { vrs }
            | Request::GetBoolean { vrs }
            | Request::GetString { vrs } => e.vrs(vrs),
            Request::DoStep { t, h } => {
                e.f64(*t);
                e.f64(*h);
            }
            Request::Quit
            | Request::EnterInit
            | Request::ExitInit
            | Request::Terminate
            | Request::Reset
            | Request::FmuTerminated => {}
        }
    }

    /// The next operation of a request; every count and length is checked against it.
    pub fn decode(d: &mut Dec) -> Result<Request<'static>, WireError> {
        let code = d.u8()?;
        Ok(match code {
            op::INSTANTIATE => Request::Instantiate {
                library: LibraryTarget::decode(d)?,
                name: d.str()?,
                guid: d.str()?,
                resources: d.str()?,
                logging: d.u8()? != 0,
            },
            op::PROBE => Request::Probe(LibraryTarget::decode(d)?),
            op::REALTIME => Request::Realtime(d.str()?),
            op::QUIT => Request::Quit,
            op::SET_DEBUG_LOGGING => Request::SetDebugLogging(d.u8()? != 0),
            op::SETUP_EXPERIMENT => {
                let start = d.f64()?;
                let has_stop = d.u8()? != 0;
                let stop = d.f64()?;
                let has_tolerance = d.u8()? != 0;
                let tolerance = d.f64()?;
                Request::SetupExperiment {
                    start,
                    stop: has_stop.then_some(stop),
                    tolerance: has_tolerance.then_some(tolerance),
                }
            }
            op::ENTER_INIT => Request::EnterInit,
            op::EXIT_INIT => Request::ExitInit,
            op::TERMINATE => Request::Terminate,
            op::RESET => Request::Reset,
            op::SET_REAL => {
                let vrs = d.vrs()?;
                let values = d.each(vrs.len(), Dec::f64)?;
                Request::SetReal {
                    vrs: vrs.into(),
                    values: values.into(),
                }
            }
            op::SET_INTEGER | op::SET_BOOLEAN => {
                let vrs = d.vrs()?;
                let values = d.each(vrs.len(), Dec::i32)?.into();
                let vrs = vrs.into();
                match code {
                    op::SET_INTEGER => Request::SetInteger { vrs, values },
                    _ => Request::SetBoolean { vrs, values },
                }
            }
            op::SET_STRING => {
                let vrs = d.vrs()?;
                let values = d.each(vrs.len(), |d| d.str().map(Cow::Owned))?;
                Request::SetString {
                    vrs: vrs.into(),
                    values,
                }
            }
            op::GET_REAL => Request::GetReal {
                vrs: d.vrs()?.into(),
            },
            op::GET_INTEGER => Request::GetInteger {
                vrs: d.vrs()?.into(),
            },
            op::GET_BOOLEAN => Request::GetBoolean {
                vrs: d.vrs()?.into(),
            },
            op::GET_STRING => Request::GetString {
                vrs: d.vrs()?.into(),
            },
            op::FMU_TERMINATED => Request::FmuTerminated,
            op::DO_STEP => Request::DoStep {
                t: d.f64()?,
                h: d.f64()?,
            },
            c => return Err(WireError::UnknownOperation(c)),
        })
    }

    /// The same operation owning its arrays.
    pub fn into_owned(self) -> Request<'static> {
        let own = |vrs: Cow<'_, [u32]>| Cow::Owned(vrs.into_owned());
        match self {
            Request::Instantiate {
                library,
                name,
                guid,
                resources,
                logging,
            } => Request::Instantiate {
                library,
                name,
                guid,
                resources,
                logging,
            },
            Request::Probe(library) => Request::Probe(library),
            Request::Realtime(spec) => Request::Realtime(spec),
            Request::Quit => Request::Quit,
            Request::SetDebugLogging(on) => Request::SetDebugLogging(on),
            Request::SetupExperiment {
                start,
                stop,
                tolerance,
            } => Request::SetupExperiment {
                start,
                stop,
                tolerance,
            },
            Request::EnterInit => Request::EnterInit,
            Request::ExitInit => Request::ExitInit,
            Request::Terminate => Request::Terminate,
            Request::Reset => Request::Reset,
            Request::SetReal { vrs, values } => Request::SetReal {
                vrs: own(vrs),
                values: Cow::Owned(values.into_owned()),
            },
            Request::SetInteger { vrs, values } => Request::SetInteger {
                vrs: own(vrs),
                values: Cow::Owned(values.into_owned()),
            },
            Request::SetBoolean { vrs, values } => Request::SetBoolean {
                vrs: own(vrs),
                values: Cow::Owned(values.into_owned()),
            },
            Request::SetString { vrs, values } => Request::SetString {
                vrs: own(vrs),
                values: values
                    .into_iter()
                    .map(|s| Cow::Owned(s.into_owned()))
                    .collect(),
            },
            Request::GetReal { vrs } => Request::GetReal { vrs: own(vrs) },
            Request::GetInteger { vrs } => Request::GetInteger { vrs: own(vrs) },
            Request::GetBoolean { vrs } => Request::GetBoolean { vrs: own(vrs) },
            Request::GetString { vrs } => Request::GetString { vrs: own(vrs) },
            Request::FmuTerminated => Request::FmuTerminated,
            Request::DoStep { t, h } => Request::DoStep { t, h },
        }
    }
}

/// The values a completed get answered with.
#[derive(Clone, Debug, PartialEq)]
pub enum Values {
    Real(Vec<f64>),
    Int(Vec<i32>),
    Text(Vec<String>),
}

/// Why a request stopped.
#[derive(Clone, Debug, PartialEq)]
pub enum Failure {
    /// An FMI call of either version returned a status that stops the caller (with the
    /// instance's last log lines).
    Call {
        function: FmiFunction,
        status: CallStatus,
        time: f64,
        log: Vec<String>,
    },
    /// An FMI 3.0 step returned early although the instance may not.
    EarlyReturn {
        time: f64,
        last: f64,
        target: f64,
        log: Vec<String>,
    },
    /// A Model Exchange instance's FMI call or its solver (CVODE) failed.
    ModelExchange {
        fmu: String,
        call: String,
        problem: String,
        time: f64,
        log: Vec<String>,
    },
    /// `fmi2Instantiate` failed.
    Instantiate(String),
    /// An optional function the FMU does not export (None: a code the host does not know).
    Unsupported(Option<Function>),
    /// Anything else (a library that does not load, a malformed request, ...).
    Other(String),
}

impl Failure {
    /// Adds `notes` (the worker's limits a failed call ran into) to what the host reports:
    /// to the FMU's log lines, or to the message.
    pub fn add_notes(&mut self, notes: Vec<String>) {
        if notes.is_empty() {
            return;
        }
        let said = |n: &str| format!("[twinbench worker] {n}");
        match self {
            Failure::Call { log, .. }
            | Failure::EarlyReturn { log, .. }
            | Failure::ModelExchange { log, .. } => log.extend(notes.iter().map(|n| said(n))),
            Failure::Instantiate(m) | Failure::Other(m) => {
                m.push_str(&format!(" ({})", notes.join("; ")))
            }
            Failure::Unsupported(_) => {}
        }
    }
}

impl From<FmuError> for Failure {
    fn from(e: FmuError) -> Failure {
        match e {
            FmuError::Call {
                function,
                status,
                time,
                log,
                ..
            } => Failure::Call {
                function,
                status,
                time,
                log,
            },
            FmuError::EarlyReturn {
                time,
                last,
                target,
                log,
                ..
            } => Failure::EarlyReturn {
                time,
                last,
                target,
                log,
            },
            FmuError::ModelExchange {
                fmu,
                call,
                problem,
                time,
                log,
                ..
            } => Failure::ModelExchange {
                fmu: fmu.to_string_lossy().into_owned(),
                call: call.into_string(),
                problem,
                time,
                log,
            },
            FmuError::Instantiate { message, .. } => Failure::Instantiate(message),
            FmuError::Unsupported { what, .. } => Failure::Unsupported(Function::from_name(what)),
            FmuError::Isolated { cause, .. } => Failure::Other(cause),
            other => Failure::Other(other.to_string()),
        }
    }
}

impl Failure {
    fn encode(&self, e: &mut Enc) {
        match self {
            Failure::Call {
                function,
                status,
                time,
                log,
            } => {
                e.u8(kind::CALL);
                match function {
                    FmiFunction::Fmi2(f) => {
                        e.u8(2);
                        e.u8(*f as u8);
                    }
                    FmiFunction::Fmi3(name) => {
                        e.u8(3);
                        e.str(name);
                    }
                }
                match status {
                    CallStatus::Fmi2(_) => e.u8(2),
                    CallStatus::Fmi3(_) => e.u8(3),
                }
                e.i32(status.code());
                e.f64(*time);
                e.u32(log.len() as u32);
                log.iter().for_each(|l| e.str(l));
            }
            Failure::EarlyReturn {
                time,
                last,
                target,
                log,
            } => {
                e.u8(kind::EARLY_RETURN);
                e.f64(*time);
                e.f64(*last);
                e.f64(*target);
                e.u32(log.len() as u32);
                log.iter().for_each(|l| e.str(l));
            }
            Failure::ModelExchange {
                fmu,
                call,
                problem,
                time,
                log,
            } => {
                e.u8(kind::MODEL_EXCHANGE);
                e.str(fmu);
                e.str(call);
                e.str(problem);
                e.f64(*time);
                e.u32(log.len() as u32);
                log.iter().for_each(|l| e.str(l));
            }
            Failure::Instantiate(message) => {
                e.u8(kind::INSTANTIATE);
                e.str(message);
            }
            Failure::Unsupported(function) => {
                e.u8(kind::UNSUPPORTED);
                e.u8(function.map_or(u8::MAX, |f| f as u8));
            }
            Failure::Other(message) => {
                e.u8(kind::OTHER);
                e.str(message);
            }
        }
    }

    fn decode(d: &mut Dec) -> Result<Failure, WireError> {
        Ok(match d.u8()? {
            kind::CALL => {
                let function = match d.u8()? {
                    2 => {
                        let code = d.u8()?;
                        FmiFunction::Fmi2(
                            function_of(code).ok_or(WireError::UnknownFunction(code))?,
                        )
                    }
                    3 => FmiFunction::Fmi3(d.str()?.into()),
                    v => return Err(WireError::UnknownVersion(v)),
                };
                let status = match (d.u8()?, d.i32()?) {
                    (2, code) => CallStatus::Fmi2(fmi2Status(code)),
                    (3, code) => CallStatus::Fmi3(code),
                    (v, _) => return Err(WireError::UnknownVersion(v)),
                };
                let time = d.f64()?;
                let n = d.count(4)?;
                Failure::Call {
                    function,
                    status,
                    time,
                    log: d.each(n, Dec::str)?,
                }
            }
            kind::EARLY_RETURN => {
                let (time, last, target) = (d.f64()?, d.f64()?, d.f64()?);
                let n = d.count(4)?;
                Failure::EarlyReturn {
                    time,
                    last,
                    target,
                    log: d.each(n, Dec::str)?,
                }
            }
            kind::MODEL_EXCHANGE => {
                let (fmu, call, problem) = (d.str()?, d.str()?, d.str()?);
                let time = d.f64()?;
                let n = d.count(4)?;
                Failure::ModelExchange {
                    fmu,
                    call,
                    problem,
                    time,
                    log: d.each(n, Dec::str)?,
                }
            }
            kind::INSTANTIATE => Failure::Instantiate(d.str()?),
            kind::UNSUPPORTED => Failure::Unsupported(function_of(d.u8()?)),
            kind::OTHER => Failure::Other(d.str()?),
            k => return Err(WireError::UnknownKind(k)),
        })
    }
}

/// The answer to a request.
#[derive(Clone, Debug, PartialEq)]
pub struct Response {
    /// The instance's time after the request (0 without an instance).
    pub time: f64,
    /// The values of the gets that completed, in order.
    pub results: Vec<Values>,
    /// Why the request stopped before its end, if it did.
    pub error: Option<Failure>,
}

impl Response {
    pub fn encode(&self, e: &mut Enc) {
        e.u8(self.error.is_some() as u8);
        e.u32(self.results.len() as u32);
        e.f64(self.time);
        for r in &self.results {
            match r {
                Values::Real(v) => v.iter().for_each(|&x| e.f64(x)),
                Values::Int(v) => v.iter().for_each(|&x| e.i32(x)),
                Values::Text(v) => v.iter().for_each(|s| e.str(s)),
            }
        }
        if let Some(f) = &self.error {
            f.encode(e);
        }
    }

    /// The answer to a request whose operations with an answer are among `ops`, in order
    /// (the others are skipped): each completed get's values are read as it asked for them.
    pub fn decode(body: &[u8], ops: &[Request<'_>]) -> Result<Response, WireError> {
        let mut d = Dec::new(body);
        let ok = d.u8()? == 0;
        let n = d.u32()? as usize;
        let time = d.f64()?;
        let mut answers = ops.iter().filter_map(Request::answer);
        let asked = answers.clone().count();
        if n > asked {
            return Err(WireError::Results {
                results: n,
                gets: asked,
            });
        }
        let results = answers
            .by_ref()
            .take(n)
            .map(|a| {
                Ok(match a {
                    Answer::Reals(k) => Values::Real(d.each(k, Dec::f64)?),
                    Answer::Ints(k) => Values::Int(d.each(k, Dec::i32)?),
                    Answer::Texts(k) => Values::Text(d.each(k, Dec::str)?),
                })
            })
            .collect::<Result<_, WireError>>()?;
        let error = match ok {
            true => None,
            false => Some(Failure::decode(&mut d)?),
        };
        if !d.at_end() {
            return Err(WireError::Trailing);
        }
        Ok(Response {
            time,
            results,
            error,
        })
    }
}

/// Writes values in the protocol's encoding.
#[derive(Default)]
pub struct Enc(pub Vec<u8>);

impl Enc {
    /// An empty frame: room for the length, which [`Enc::finish_frame`] fills in.
    pub fn start_frame(&mut self) {
        self.0.clear();
        self.0.extend_from_slice(&[0; 4]);
    }
    /// The frame's bytes, its length filled in (after [`Enc::start_frame`]).
    pub fn finish_frame(&mut self) -> &[u8] {
        let n = (self.0.len() - 4) as u32;
        self.0[..4].copy_from_slice(&n.to_le_bytes());
        &self.0
    }
    pub fn u8(&mut self, x: u8) {
        self.0.push(x);
    }
    pub fn u32(&mut self, x: u32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub fn f64(&mut self, x: f64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub fn i32(&mut self, x: i32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub fn str(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.0.extend_from_slice(s.as_bytes());
    }
    pub fn vrs(&mut self, vrs: &[u32]) {
        self.u32(vrs.len() as u32);
        for &v in vrs {
            self.u32(v);
        }
    }
}

/// Reads values in the protocol's encoding; every read is checked against the frame.
pub struct Dec<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Dec<'a> {
    pub fn new(b: &'a [u8]) -> Self {
        Dec { b, pos: 0 }
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], WireError> {
        if self.b.len() - self.pos < n {
            return Err(WireError::Truncated {
                needed: n,
                offset: self.pos,
            });
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], WireError> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub fn u8(&mut self) -> Result<u8, WireError> {
        Ok(self.take(1)?[0])
    }
    pub fn u32(&mut self) -> Result<u32, WireError> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub fn f64(&mut self) -> Result<f64, WireError> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    pub fn i32(&mut self) -> Result<i32, WireError> {
        Ok(i32::from_le_bytes(self.array()?))
    }
    pub fn str(&mut self) -> Result<String, WireError> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.take(n)?).into_owned())
    }
    /// A count of elements of `size` bytes each, checked against what remains.
    pub fn count(&mut self, size: usize) -> Result<usize, WireError> {
        let n = self.u32()? as usize;
        if n.saturating_mul(size) > self.b.len() - self.pos {
            return Err(WireError::Count { count: n });
        }
        Ok(n)
    }
    pub fn vrs(&mut self) -> Result<Vec<u32>, WireError> {
        let n = self.count(4)?;
        self.each(n, Dec::u32)
    }
    /// `n` values read by `read` (`n` is checked by the reads, not trusted for memory).
    pub fn each<T>(
        &mut self,
        n: usize,
        mut read: impl FnMut(&mut Self) -> Result<T, WireError>,
    ) -> Result<Vec<T>, WireError> {
        let mut out = Vec::with_capacity(n.min(self.b.len() - self.pos));
        for _ in 0..n {
            out.push(read(self)?);
        }
        Ok(out)
    }
    pub fn at_end(&self) -> bool {
        self.pos == self.b.len()
    }
}

#[cfg(test)]
mod tests;

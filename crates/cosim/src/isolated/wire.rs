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
use tb_fmi::{FmuError, Function};

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
    /// An FMI call returned a status that stops the caller: function code, status, time, log.
    pub const CALL: u8 = 0;
    /// `fmi2Instantiate` failed: the message.
    pub const INSTANTIATE: u8 = 1;
    /// An optional function the FMU does not export: its code.
    pub const UNSUPPORTED: u8 = 2;
    /// Anything else: a message.
    pub const OTHER: u8 = 3;
    /// An FMI 3.0 call returned a status that stops the caller: function name, status
    /// name, time, log.
    pub const CALL3: u8 = 4;
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
    pub fn decode(d: &mut Dec) -> Result<LibraryTarget, String> {
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
    pub fn decode(d: &mut Dec) -> Result<Request<'static>, String> {
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
            c => return Err(format!("unknown operation {c}")),
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
    /// An FMI call returned a status that stops the caller (with the instance's last log
    /// lines).
    Call {
        function: Function,
        status: fmi2Status,
        time: f64,
        log: Vec<String>,
    },
    /// An FMI 3.0 call did (named as the FMU's functions are, with its status's name).
    Call3 {
        function: String,
        status: String,
        time: f64,
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
            | Failure::Call3 { log, .. }
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
            FmuError::Call3 {
                function,
                status,
                time,
                log,
                ..
            } => Failure::Call3 {
                function,
                status,
                time,
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
                e.u8(*function as u8);
                e.i32(status.0);
                e.f64(*time);
                e.u32(log.len() as u32);
                log.iter().for_each(|l| e.str(l));
            }
            Failure::Call3 {
                function,
                status,
                time,
                log,
            } => {
                e.u8(kind::CALL3);
                e.str(function);
                e.str(status);
                e.f64(*time);
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

    fn decode(d: &mut Dec) -> Result<Failure, String> {
        Ok(match d.u8()? {
            kind::CALL => {
                let code = d.u8()?;
                let function =
                    function_of(code).ok_or_else(|| format!("unknown function code {code}"))?;
                let status = fmi2Status(d.i32()?);
                let time = d.f64()?;
                let n = d.count(4)?;
                Failure::Call {
                    function,
                    status,
                    time,
                    log: d.each(n, Dec::str)?,
                }
            }
            kind::CALL3 => {
                let function = d.str()?;
                let status = d.str()?;
                let time = d.f64()?;
                let n = d.count(4)?;
                Failure::Call3 {
                    function,
                    status,
                    time,
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
            k => return Err(format!("unknown error kind {k}")),
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
    pub fn decode(body: &[u8], ops: &[Request<'_>]) -> Result<Response, String> {
        let mut d = Dec::new(body);
        let ok = d.u8()? == 0;
        let n = d.u32()? as usize;
        let time = d.f64()?;
        let mut answers = ops.iter().filter_map(Request::answer);
        let asked = answers.clone().count();
        if n > asked {
            return Err(format!("{n} results for {asked} gets"));
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
            .collect::<Result<_, String>>()?;
        let error = match ok {
            true => None,
            false => Some(Failure::decode(&mut d)?),
        };
        if !d.at_end() {
            return Err("trailing bytes".into());
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
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if self.b.len() - self.pos < n {
            return Err(format!(
                "truncated message: {n} bytes needed at offset {}",
                self.pos
            ));
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    pub fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    pub fn i32(&mut self) -> Result<i32, String> {
        Ok(i32::from_le_bytes(self.array()?))
    }
    pub fn str(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.take(n)?).into_owned())
    }
    /// A count of elements of `size` bytes each, checked against what remains.
    pub fn count(&mut self, size: usize) -> Result<usize, String> {
        let n = self.u32()? as usize;
        if n.saturating_mul(size) > self.b.len() - self.pos {
            return Err(format!("count {n} exceeds the message"));
        }
        Ok(n)
    }
    pub fn vrs(&mut self) -> Result<Vec<u32>, String> {
        let n = self.count(4)?;
        self.each(n, Dec::u32)
    }
    /// `n` values read by `read` (`n` is checked by the reads, not trusted for memory).
    pub fn each<T>(
        &mut self,
        n: usize,
        mut read: impl FnMut(&mut Self) -> Result<T, String>,
    ) -> Result<Vec<T>, String> {
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
mod tests {
    use super::*;

    #[test]
    fn decoder_refuses_truncated_and_oversized_counts() {
        let mut d = Dec::new(&[5, 0, 0, 0, 1, 2]);
        assert!(d.count(4).unwrap_err().contains("exceeds"));
        let mut d = Dec::new(&[1, 0]);
        assert!(d.u32().unwrap_err().contains("truncated"));
    }

    fn target() -> LibraryTarget {
        LibraryTarget {
            path: "/c/x.so".into(),
            source: "x.fmu".into(),
            model_identifier: "x".into(),
            preload: vec!["libpython3.11.so".into(), "b".into()],
            description: "/c/modelDescription.xml".into(),
            model_exchange: true,
            tolerance: 1e-6,
            checks: vec![FileCheck {
                base: "/c".into(),
                rel: "0123/x.so".into(),
                size: 1 << 31,
                mode: 0o700,
                hash: "ab".repeat(32),
            }],
        }
    }

    #[test]
    fn library_targets_round_trip_and_truncation_is_refused() {
        let t = target();
        let mut e = Enc::default();
        t.encode(&mut e);
        assert_eq!(LibraryTarget::decode(&mut Dec::new(&e.0)).unwrap(), t);
        let cut = &e.0[..e.0.len() - 3];
        assert!(LibraryTarget::decode(&mut Dec::new(cut)).is_err());
    }

    #[test]
    fn fmi_calls_are_coded_by_the_function_table() {
        assert_eq!(function_of(op::DO_STEP), Some(Function::DoStep));
        assert_eq!(function_of(op::GET_REAL).unwrap().name(), "fmi2GetReal");
        assert_eq!(function_of(op::INSTANTIATE), Some(Function::Instantiate));
        assert_eq!(function_of(150), None);
        // The protocol's own codes are outside the table.
        assert!(Function::from_u8(op::INSTANTIATE).is_none());
        assert!(Function::from_u8(op::PROBE).is_none());
        assert!(Function::from_u8(op::QUIT).is_none());
    }

    /// The variant's number (no wildcard: a new variant does not compile until it is
    /// numbered here and given an example in [`every_request`]).
    fn variant(r: &Request) -> usize {
        match r {
            Request::Instantiate { .. } => 0,
            Request::Probe(_) => 1,
            Request::Quit => 2,
            Request::SetDebugLogging(_) => 3,
            Request::SetupExperiment { .. } => 4,
            Request::EnterInit => 5,
            Request::ExitInit => 6,
            Request::Terminate => 7,
            Request::Reset => 8,
            Request::SetReal { .. } => 9,
            Request::SetInteger { .. } => 10,
            Request::SetBoolean { .. } => 11,
            Request::SetString { .. } => 12,
            Request::GetReal { .. } => 13,
            Request::GetInteger { .. } => 14,
            Request::GetBoolean { .. } => 15,
            Request::GetString { .. } => 16,
            Request::FmuTerminated => 17,
            Request::DoStep { .. } => 18,
            Request::Realtime(_) => 19,
        }
    }
    const VARIANTS: usize = 20;

    /// At least one request of every variant.
    fn every_request() -> Vec<Request<'static>> {
        vec![
            Request::Instantiate {
                library: target(),
                name: "dyno_rl".into(),
                guid: "{1-2}".into(),
                resources: "/c/resources".into(),
                logging: true,
            },
            Request::Probe(target()),
            Request::Quit,
            Request::SetDebugLogging(true),
            Request::SetDebugLogging(false),
            Request::SetupExperiment {
                start: 0.5,
                stop: Some(98.5),
                tolerance: Some(1e-6),
            },
            Request::SetupExperiment {
                start: -1.0,
                stop: None,
                tolerance: None,
            },
            Request::EnterInit,
            Request::ExitInit,
            Request::Terminate,
            Request::Reset,
            Request::SetReal {
                vrs: vec![1, 7].into(),
                values: vec![1.5, -0.0].into(),
            },
            Request::SetInteger {
                vrs: vec![3].into(),
                values: vec![i32::MIN].into(),
            },
            Request::SetBoolean {
                vrs: vec![4, 5].into(),
                values: vec![1, 0].into(),
            },
            Request::SetString {
                vrs: vec![8, 9].into(),
                values: vec!["lap \u{e9}".into(), "".into()],
            },
            Request::GetReal {
                vrs: vec![100, 101, 102].into(),
            },
            Request::GetInteger { vrs: vec![].into() },
            Request::GetBoolean {
                vrs: vec![6].into(),
            },
            Request::GetString {
                vrs: vec![9, 9].into(),
            },
            Request::FmuTerminated,
            Request::DoStep { t: 1.25, h: 1e-3 },
            Request::Realtime("{\"steps\": 3}".into()),
        ]
    }

    #[test]
    fn every_request_round_trips_alone_and_in_sequence() {
        let all = every_request();
        let mut seen: Vec<usize> = all.iter().map(variant).collect();
        seen.dedup();
        assert_eq!(
            seen,
            (0..VARIANTS).collect::<Vec<_>>(),
            "every variant, in order"
        );
        // Each has a code of its own.
        let mut codes: Vec<u8> = all.iter().map(Request::code).collect();
        codes.sort();
        codes.dedup();
        assert_eq!(codes.len(), VARIANTS);
        let mut whole = Enc::default();
        for r in &all {
            let mut e = Enc::default();
            r.encode(&mut e);
            assert_eq!(e.0[0], r.code());
            let mut d = Dec::new(&e.0);
            assert_eq!(&Request::decode(&mut d).unwrap(), r);
            assert!(d.at_end(), "{r:?}");
            // Every proper prefix is refused, never misread.
            for cut in 0..e.0.len() {
                let mut d = Dec::new(&e.0[..cut]);
                assert!(Request::decode(&mut d).is_err(), "{r:?} cut at {cut}");
            }
            r.encode(&mut whole);
        }
        let mut d = Dec::new(&whole.0);
        for r in &all {
            assert_eq!(&Request::decode(&mut d).unwrap(), r);
        }
        assert!(d.at_end());
        // Borrowed arrays encode as owned ones do.
        let (vrs, values) = ([1u32, 2], [0.5, 0.25]);
        let (mut a, mut b) = (Enc::default(), Enc::default());
        Request::SetReal {
            vrs: Cow::Borrowed(&vrs),
            values: Cow::Borrowed(&values),
        }
        .encode(&mut a);
        Request::SetReal {
            vrs: vrs.to_vec().into(),
            values: values.to_vec().into(),
        }
        .encode(&mut b);
        assert_eq!(a.0, b.0);
    }

    #[test]
    fn over_long_counts_and_unknown_codes_are_refused() {
        // A count of value references beyond the frame.
        let mut e = Enc::default();
        e.u8(op::GET_REAL);
        e.u32(u32::MAX);
        e.u32(1);
        let err = Request::decode(&mut Dec::new(&e.0)).unwrap_err();
        assert!(
            err.contains("count 4294967295 exceeds the message"),
            "{err}"
        );
        // A set with fewer values than value references.
        let mut e = Enc::default();
        e.u8(op::SET_REAL);
        e.vrs(&[1, 2]);
        e.f64(1.0);
        let err = Request::decode(&mut Dec::new(&e.0)).unwrap_err();
        assert!(err.contains("truncated message"), "{err}");
        // A string longer than the frame.
        let mut e = Enc::default();
        e.u8(op::SET_STRING);
        e.vrs(&[1]);
        e.u32(1000);
        let err = Request::decode(&mut Dec::new(&e.0)).unwrap_err();
        assert!(err.contains("truncated message"), "{err}");
        assert_eq!(
            Request::decode(&mut Dec::new(&[150])).unwrap_err(),
            "unknown operation 150"
        );
    }

    /// A request with one get of each answer, and responses to it.
    fn gets() -> Vec<Request<'static>> {
        vec![
            Request::SetReal {
                vrs: vec![1].into(),
                values: vec![2.0].into(),
            },
            Request::DoStep { t: 0.0, h: 0.5 },
            Request::GetReal {
                vrs: vec![1, 2].into(),
            },
            Request::GetInteger {
                vrs: vec![3].into(),
            },
            Request::GetBoolean {
                vrs: vec![4, 4].into(),
            },
            Request::GetString {
                vrs: vec![5, 6].into(),
            },
            Request::FmuTerminated,
        ]
    }

    fn every_response() -> Vec<Response> {
        let complete = vec![
            Values::Real(vec![0.5, -2.0]),
            Values::Int(vec![7]),
            Values::Int(vec![1, 0]),
            Values::Text(vec!["a".into(), "".into()]),
            Values::Real(vec![1.0, 0.25]),
        ];
        let failures = [
            Failure::Call {
                function: Function::DoStep,
                status: fmi2Status::ERROR,
                time: 0.5,
                log: vec!["[Error] it failed".into(), "".into()],
            },
            Failure::Call {
                function: Function::GetReal,
                status: fmi2Status(77),
                time: 0.0,
                log: vec![],
            },
            Failure::Call3 {
                function: "fmi3DoStep".into(),
                status: "fmi3Error".into(),
                time: 0.25,
                log: vec!["[Error] a step of an FMI 3.0 FMU".into()],
            },
            Failure::ModelExchange {
                fmu: "m.fmu".into(),
                call: "CVode".into(),
                problem: "returned CV_CONV_FAILURE (-4): failed".into(),
                time: 0.125,
                log: vec!["[Error] no".into()],
            },
            Failure::Instantiate("GUID {a} differs".into()),
            Failure::Unsupported(Some(Function::GetBooleanStatus)),
            Failure::Unsupported(None),
            Failure::Other("no instance: instantiate first".into()),
        ];
        let mut all = vec![
            Response {
                time: 0.5,
                results: complete.clone(),
                error: None,
            },
            Response {
                time: 0.0,
                results: vec![],
                error: None,
            },
        ];
        for (k, f) in failures.into_iter().enumerate() {
            all.push(Response {
                time: k as f64,
                results: complete[..k.min(complete.len())].to_vec(),
                error: Some(f),
            });
        }
        all
    }

    #[test]
    fn every_response_round_trips_and_a_cut_one_is_refused() {
        let ops = gets();
        for r in every_response() {
            let mut e = Enc::default();
            r.encode(&mut e);
            assert_eq!(Response::decode(&e.0, &ops).unwrap(), r);
            for cut in 0..e.0.len() {
                assert!(
                    Response::decode(&e.0[..cut], &ops).is_err(),
                    "{r:?} cut at {cut}"
                );
            }
            let mut longer = e.0.clone();
            longer.push(0);
            assert_eq!(
                Response::decode(&longer, &ops).unwrap_err(),
                "trailing bytes"
            );
        }
    }

    #[test]
    fn forged_responses_are_refused() {
        let ops = gets();
        let head = |ok: u8, n: u32| {
            let mut e = Enc::default();
            e.u8(ok);
            e.u32(n);
            e.f64(0.0);
            e
        };
        // More results than gets.
        let e = head(0, 6);
        assert_eq!(
            Response::decode(&e.0, &ops).unwrap_err(),
            "6 results for 5 gets"
        );
        // A function code outside the table, an unknown error kind.
        let mut e = head(1, 0);
        e.u8(kind::CALL);
        e.u8(250);
        assert_eq!(
            Response::decode(&e.0, &ops).unwrap_err(),
            "unknown function code 250"
        );
        let mut e = head(1, 0);
        e.u8(9);
        assert_eq!(
            Response::decode(&e.0, &ops).unwrap_err(),
            "unknown error kind 9"
        );
        // A log count beyond the frame.
        let mut e = head(1, 0);
        e.u8(kind::CALL);
        e.u8(Function::GetReal as u8);
        e.i32(3);
        e.f64(0.0);
        e.u32(u32::MAX);
        let err = Response::decode(&e.0, &ops).unwrap_err();
        assert!(err.contains("exceeds the message"), "{err}");
    }

    #[test]
    fn frames_carry_their_length() {
        let mut e = Enc::default();
        e.start_frame();
        Request::DoStep { t: 0.0, h: 1.0 }.encode(&mut e);
        let bytes = e.finish_frame().to_vec();
        assert_eq!(bytes.len(), 4 + 17);
        assert_eq!(u32::from_le_bytes(bytes[..4].try_into().unwrap()), 17);
        // Started again, the frame is empty (its buffer kept).
        e.start_frame();
        assert_eq!(e.finish_frame(), [0, 0, 0, 0]);
    }
}

//! Isolation mode: an FMU instance runs in a worker process (`twinbench worker`, a hidden
//! subcommand of this very executable), so that a segfault, an abort or a hang inside a
//! third-party FMU ends that run with an error naming the instance, the time and the
//! cause, and the host lives on.
//!
//! Transport: a Unix socket pair whose worker end is the worker's stdin (the worker moves
//! it away from fd 0/1 at once, so an FMU printing to stdout cannot corrupt the protocol).
//! Protocol: length-prefixed little-endian frames. A request is a list of operations run in
//! order, stopping at the first error; the response carries the results of the operations
//! that completed. Sets are queued on the host and sent with the next call, and the gets
//! that followed the previous step are sent with each step, so that a Gauss-Seidel step
//! (set inputs, step, get outputs) is one round trip. Every round trip has a watchdog: no
//! complete answer in time, and the worker is killed.

use super::backend::{Backend, BackendFactory};
use crate::fmu::{FmuError, Instance, LoadedFmu};
use std::collections::VecDeque;
use std::io::{BufRead, Read, Write};
use std::os::fd::{AsRawFd, OwnedFd};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The default per-call watchdog.
pub const DEFAULT_TIMEOUT: Duration = Duration::from_secs(10);
/// Environment variable naming the executable that serves `worker` (default: this one).
pub const WORKER_EXE_ENV: &str = "TWINBENCH_WORKER_EXE";
/// Lines of the worker's stderr kept for crash reports.
const STDERR_LINES: usize = 20;

/// How isolated instances are run.
#[derive(Clone, Debug)]
pub struct IsolationOptions {
    /// Longest wait for one answer of the worker (one step, one initialisation, ...).
    pub timeout: Duration,
    /// The executable to run as `<exe> worker`; default: [`WORKER_EXE_ENV`], else this
    /// executable (or, from a test binary, `target/<profile>/twinbench`).
    pub worker_exe: Option<PathBuf>,
}

impl Default for IsolationOptions {
    fn default() -> Self {
        IsolationOptions {
            timeout: DEFAULT_TIMEOUT,
            worker_exe: None,
        }
    }
}

impl IsolationOptions {
    pub fn resolve_exe(&self) -> Result<PathBuf, String> {
        if let Some(p) = &self.worker_exe {
            return Ok(p.clone());
        }
        if let Some(p) = std::env::var_os(WORKER_EXE_ENV) {
            return Ok(PathBuf::from(p));
        }
        let me =
            std::env::current_exe().map_err(|e| format!("cannot find this executable: {e}"))?;
        if me.file_stem().is_some_and(|s| s == "twinbench") {
            return Ok(me);
        }
        // A test or bench binary in target/<profile>/deps.
        if let Some(p) = me
            .parent()
            .and_then(Path::parent)
            .map(|d| d.join("twinbench"))
            .filter(|p| p.is_file())
        {
            return Ok(p);
        }
        Err(format!(
            "cannot find the twinbench executable to run the worker (this is {}); set {WORKER_EXE_ENV}",
            me.display()
        ))
    }
}

/// Creates instances that run in their own worker process.
pub struct IsolatedFactory {
    pub fmu: Arc<LoadedFmu>,
    pub options: IsolationOptions,
}

impl BackendFactory for IsolatedFactory {
    fn kind(&self) -> &'static str {
        "isolated"
    }
    fn create(&self, instance_name: &str, logging: bool) -> Result<Box<dyn Backend>, FmuError> {
        let mut b = IsolatedBackend::spawn(instance_name, &self.options)?;
        let mut e = Enc::default();
        e.u8(op::INSTANTIATE);
        e.str(&self.fmu.library.path.to_string_lossy());
        e.str(instance_name);
        e.str(&self.fmu.description.guid);
        e.str(&self.fmu.resource_dir().to_string_lossy());
        e.u8(logging as u8);
        b.call("fmi2Instantiate", e.0, &[])?;
        if logging {
            b.set_debug_logging(true)?;
        }
        Ok(Box::new(b))
    }
}

/// Operation codes.
mod op {
    pub const INSTANTIATE: u8 = 1;
    pub const SET_DEBUG_LOGGING: u8 = 2;
    pub const SETUP_EXPERIMENT: u8 = 3;
    pub const ENTER_INIT: u8 = 4;
    pub const EXIT_INIT: u8 = 5;
    pub const TERMINATE: u8 = 6;
    pub const RESET: u8 = 7;
    pub const SET_REAL: u8 = 8;
    pub const SET_INTEGER: u8 = 9;
    pub const SET_BOOLEAN: u8 = 10;
    pub const GET_REAL: u8 = 11;
    pub const GET_INTEGER: u8 = 12;
    pub const GET_BOOLEAN: u8 = 13;
    pub const DO_STEP: u8 = 14;
    pub const QUIT: u8 = 15;
}

/// Error kinds in a response.
mod kind {
    pub const CALL: u8 = 0;
    pub const INSTANTIATE: u8 = 1;
    pub const UNSUPPORTED: u8 = 2;
    pub const OTHER: u8 = 3;
}

const STATUS_NAMES: &[&str] = &[
    "fmi2OK",
    "fmi2Warning",
    "fmi2Discard",
    "fmi2Error",
    "fmi2Fatal",
    "fmi2Pending",
];

const FUNCTION_NAMES: &[&str] = &[
    "fmi2SetDebugLogging",
    "fmi2SetupExperiment",
    "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode",
    "fmi2Terminate",
    "fmi2Reset",
    "fmi2GetReal",
    "fmi2SetReal",
    "fmi2GetInteger",
    "fmi2SetInteger",
    "fmi2GetBoolean",
    "fmi2SetBoolean",
    "fmi2DoStep",
    "fmi2GetFMUstate",
    "fmi2SetFMUstate",
    "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize",
    "fmi2SerializeFMUstate",
    "fmi2DeSerializeFMUstate",
];

fn static_name(table: &[&'static str], s: &str, other: &'static str) -> &'static str {
    table.iter().find(|n| **n == s).copied().unwrap_or(other)
}

// ---- encoding ----

#[derive(Default)]
struct Enc(Vec<u8>);

impl Enc {
    fn u8(&mut self, x: u8) {
        self.0.push(x);
    }
    fn u32(&mut self, x: u32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn f64(&mut self, x: f64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn i32(&mut self, x: i32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn str(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.0.extend_from_slice(s.as_bytes());
    }
    fn vrs(&mut self, vrs: &[u32]) {
        self.u32(vrs.len() as u32);
        for &v in vrs {
            self.u32(v);
        }
    }
}

struct Dec<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Dec<'a> {
    fn new(b: &'a [u8]) -> Self {
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
    fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    fn i32(&mut self) -> Result<i32, String> {
        Ok(i32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    fn str(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.take(n)?).into_owned())
    }
    /// A count of elements of `size` bytes each, checked against what remains.
    fn count(&mut self, size: usize) -> Result<usize, String> {
        let n = self.u32()? as usize;
        if n.saturating_mul(size) > self.b.len() - self.pos {
            return Err(format!("count {n} exceeds the message"));
        }
        Ok(n)
    }
    fn vrs(&mut self) -> Result<Vec<u32>, String> {
        let n = self.count(4)?;
        (0..n).map(|_| self.u32()).collect()
    }
    fn at_end(&self) -> bool {
        self.pos == self.b.len()
    }
}

/// Largest frame accepted (a corrupted length must not allocate gigabytes).
const MAX_FRAME: usize = 256 << 20;

fn frame(payload: &[u8]) -> Vec<u8> {
    let mut v = Vec::with_capacity(payload.len() + 4);
    v.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    v.extend_from_slice(payload);
    v
}

// ---- host side ----

/// A kind of get, with the value references asked for.
#[derive(Clone, Debug, PartialEq)]
struct GetSpec {
    op: u8,
    vrs: Vec<u32>,
}

enum Values {
    Real(Vec<f64>),
    Int(Vec<i32>),
}

/// One instance in a worker process.
pub struct IsolatedBackend {
    name: String,
    time: f64,
    sock: UnixStream,
    child: Option<Child>,
    stderr_tail: Arc<Mutex<VecDeque<String>>>,
    stderr_done: Arc<std::sync::atomic::AtomicBool>,
    timeout: Duration,
    /// Queued set operations (sent with the next call).
    pending: Enc,
    /// Gets made since the last step (the prediction for the next step).
    observed: Vec<GetSpec>,
    /// Results of the gets sent with the last step, in order.
    prefetched: VecDeque<(GetSpec, Values)>,
    /// Why the worker is gone; every later call fails at once.
    dead: Option<String>,
    last_log: Vec<String>,
}

impl IsolatedBackend {
    fn spawn(name: &str, options: &IsolationOptions) -> Result<IsolatedBackend, FmuError> {
        let fail = |cause: String| FmuError::Isolated {
            instance: name.to_string(),
            function: "starting the worker".into(),
            time: 0.0,
            cause,
            log: Vec::new(),
        };
        let exe = options.resolve_exe().map_err(fail)?;
        let (host, worker) = UnixStream::pair().map_err(|e| fail(format!("socketpair: {e}")))?;
        let mut cmd = Command::new(&exe);
        cmd.arg("worker")
            .stdin(Stdio::from(OwnedFd::from(worker)))
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        let mut child = cmd
            .spawn()
            .map_err(|e| fail(format!("cannot run {} worker: {e}", exe.display())))?;
        // Our copy of the worker's end is closed with `cmd`: its death is then EOF here.
        drop(cmd);
        let stderr_tail = Arc::new(Mutex::new(VecDeque::new()));
        let stderr_done = Arc::new(std::sync::atomic::AtomicBool::new(false));
        if let Some(err) = child.stderr.take() {
            let (tail, done, who) = (stderr_tail.clone(), stderr_done.clone(), name.to_string());
            std::thread::Builder::new()
                .name(format!("worker-stderr-{name}"))
                .spawn(move || {
                    for line in std::io::BufReader::new(err).lines() {
                        let Ok(line) = line else { break };
                        log::warn!(target: "worker", "{who}: {line}");
                        let mut t = tail.lock().unwrap();
                        if t.len() == STDERR_LINES {
                            t.pop_front();
                        }
                        t.push_back(line);
                    }
                    done.store(true, std::sync::atomic::Ordering::Release);
                })
                .map_err(|e| fail(format!("cannot start a thread: {e}")))?;
        }
        Ok(IsolatedBackend {
            name: name.to_string(),
            time: 0.0,
            sock: host,
            child: Some(child),
            stderr_tail,
            stderr_done,
            timeout: options.timeout,
            pending: Enc::default(),
            observed: Vec::new(),
            prefetched: VecDeque::new(),
            dead: None,
            last_log: Vec::new(),
        })
    }

    /// The worker's process id (tests).
    pub fn pid(&self) -> Option<u32> {
        self.child.as_ref().map(Child::id)
    }

    fn isolated_error(&self, function: &str, cause: String, log: Vec<String>) -> FmuError {
        FmuError::Isolated {
            instance: self.name.clone(),
            function: function.to_string(),
            time: self.time,
            cause,
            log,
        }
    }

    /// The worker's end: kill it if needed, reap it, and say how it ended.
    fn bury(&mut self, kill: bool) -> String {
        let Some(mut child) = self.child.take() else {
            return "the worker process is gone".into();
        };
        if kill {
            let _ = child.kill();
        }
        let status = match child.wait() {
            Ok(s) => s,
            Err(e) => return format!("cannot wait for the worker process: {e}"),
        };
        // Let the stderr reader drain what the worker wrote before dying.
        let until = Instant::now() + Duration::from_millis(500);
        while !self.stderr_done.load(std::sync::atomic::Ordering::Acquire) && Instant::now() < until
        {
            std::thread::sleep(Duration::from_millis(5));
        }
        use std::os::unix::process::ExitStatusExt;
        match (status.code(), status.signal()) {
            (Some(c), _) => format!("the worker process exited with code {c}"),
            (None, Some(sig)) => format!(
                "the worker process was killed by signal {sig} ({})",
                signal_name(sig)
            ),
            _ => format!("the worker process ended: {status}"),
        }
    }

    fn stderr_lines(&self) -> Vec<String> {
        self.stderr_tail
            .lock()
            .map(|t| t.iter().map(|l| format!("[worker stderr] {l}")).collect())
            .unwrap_or_default()
    }

    fn send(&self, bytes: &[u8]) -> std::io::Result<()> {
        let mut off = 0;
        while off < bytes.len() {
            // MSG_NOSIGNAL: a dead worker is an error here, never a SIGPIPE.
            let n = unsafe {
                libc::send(
                    self.sock.as_raw_fd(),
                    bytes[off..].as_ptr().cast(),
                    bytes.len() - off,
                    libc::MSG_NOSIGNAL,
                )
            };
            if n < 0 {
                let e = std::io::Error::last_os_error();
                if e.kind() == std::io::ErrorKind::Interrupted {
                    continue;
                }
                return Err(e);
            }
            off += n as usize;
        }
        Ok(())
    }

    /// Read exactly `buf.len()` bytes before `deadline`. Err(None): timed out.
    fn recv_exact(&mut self, buf: &mut [u8], deadline: Instant) -> Result<(), Option<String>> {
        let mut off = 0;
        while off < buf.len() {
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(None);
            }
            self.sock
                .set_read_timeout(Some(left))
                .map_err(|e| Some(e.to_string()))?;
            match self.sock.read(&mut buf[off..]) {
                Ok(0) => return Err(Some("end of stream".into())),
                Ok(n) => off += n,
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    return Err(None)
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Some(e.to_string())),
            }
        }
        Ok(())
    }

    /// Send the queued sets plus `ops`, and decode the answer. `gets` lists the get
    /// operations among `ops`, in order, with their counts (to decode their results).
    fn call(
        &mut self,
        function: &str,
        ops: Vec<u8>,
        gets: &[GetSpec],
    ) -> Result<Vec<Values>, FmuError> {
        if let Some(cause) = &self.dead {
            return Err(self.isolated_error(function, cause.clone(), self.stderr_lines()));
        }
        let mut payload = std::mem::take(&mut self.pending).0;
        payload.extend_from_slice(&ops);
        let deadline = Instant::now() + self.timeout;
        let sent = self.send(&frame(&payload));
        let mut len = [0u8; 4];
        let got = match sent {
            Ok(()) => self.recv_exact(&mut len, deadline),
            Err(e) => Err(Some(format!("cannot write to the worker: {e}"))),
        };
        let mut body = Vec::new();
        let got = got.and_then(|()| {
            let n = u32::from_le_bytes(len) as usize;
            if n > MAX_FRAME {
                return Err(Some(format!("answer of {n} bytes is too large")));
            }
            body.resize(n, 0);
            self.recv_exact(&mut body, deadline)
        });
        if let Err(why) = got {
            let cause = match why {
                None => {
                    let end = self.bury(true);
                    format!(
                        "no answer within {:?} (watchdog): the FMU hangs; killed ({end})",
                        self.timeout
                    )
                }
                Some(_) => {
                    let end = self.bury(false);
                    format!("{end} (crashed)")
                }
            };
            self.dead = Some(cause.clone());
            return Err(self.isolated_error(function, cause, self.stderr_lines()));
        }
        self.decode(function, &body, gets).map_err(|e| match e {
            Decoded::Fmu(e) => e,
            Decoded::Protocol(m) => {
                let end = self.bury(true);
                let cause = format!("protocol error ({m}); killed ({end})");
                self.dead = Some(cause.clone());
                self.isolated_error(function, cause, self.stderr_lines())
            }
        })
    }

    fn decode(
        &mut self,
        function: &str,
        body: &[u8],
        gets: &[GetSpec],
    ) -> Result<Vec<Values>, Decoded> {
        let mut d = Dec::new(body);
        let p = |m: String| Decoded::Protocol(m);
        let ok = d.u8().map_err(p)? == 0;
        let n_gets = d.u32().map_err(p)? as usize;
        let time = d.f64().map_err(p)?;
        if n_gets > gets.len() {
            return Err(p(format!("{n_gets} results for {} gets", gets.len())));
        }
        let mut out = Vec::with_capacity(n_gets);
        for g in &gets[..n_gets] {
            out.push(if g.op == op::GET_REAL {
                Values::Real(
                    (0..g.vrs.len())
                        .map(|_| d.f64())
                        .collect::<Result<_, _>>()
                        .map_err(p)?,
                )
            } else {
                Values::Int(
                    (0..g.vrs.len())
                        .map(|_| d.i32())
                        .collect::<Result<_, _>>()
                        .map_err(p)?,
                )
            });
        }
        if ok {
            if !d.at_end() {
                return Err(p("trailing bytes".into()));
            }
            return Ok(out);
        }
        let _ = time;
        let k = d.u8().map_err(p)?;
        let e = match k {
            kind::CALL => {
                let f = d.str().map_err(p)?;
                let status = d.str().map_err(p)?;
                let t = d.f64().map_err(p)?;
                let n = d.count(4).map_err(p)?;
                let log = (0..n)
                    .map(|_| d.str())
                    .collect::<Result<_, _>>()
                    .map_err(p)?;
                self.last_log.clone_from(&log);
                FmuError::Call {
                    instance: self.name.clone(),
                    function: static_name(FUNCTION_NAMES, &f, "fmi2 function"),
                    status: static_name(STATUS_NAMES, &status, "unknown fmi2Status"),
                    time: t,
                    log,
                }
            }
            kind::INSTANTIATE => FmuError::Instantiate {
                instance: self.name.clone(),
                message: d.str().map_err(p)?,
            },
            kind::UNSUPPORTED => FmuError::Unsupported {
                instance: self.name.clone(),
                what: static_name(FUNCTION_NAMES, &d.str().map_err(p)?, "a function"),
            },
            _ => {
                let m = d.str().map_err(p)?;
                self.isolated_error(function, m, Vec::new())
            }
        };
        Err(Decoded::Fmu(e))
    }

    fn control(
        &mut self,
        function: &str,
        code: u8,
        args: impl FnOnce(&mut Enc),
    ) -> Result<(), FmuError> {
        self.prefetched.clear();
        // Gets before a state change are no guide to those after the next step.
        self.observed.clear();
        let mut e = Enc::default();
        e.u8(code);
        args(&mut e);
        self.call(function, e.0, &[]).map(|_| ())
    }

    fn queue_set(&mut self, code: u8, vrs: &[u32], write: impl FnOnce(&mut Enc)) {
        // A set may change outputs (direct feed-through): what was fetched is stale.
        self.prefetched.clear();
        self.pending.u8(code);
        self.pending.vrs(vrs);
        write(&mut self.pending);
    }

    fn get(&mut self, function: &str, code: u8, vrs: &[u32]) -> Result<Values, FmuError> {
        let spec = GetSpec {
            op: code,
            vrs: vrs.to_vec(),
        };
        let hit = self.prefetched.front().is_some_and(|(s, _)| *s == spec);
        let values = if hit {
            self.prefetched.pop_front().unwrap().1
        } else {
            self.prefetched.clear();
            let mut e = Enc::default();
            e.u8(code);
            e.vrs(vrs);
            let mut r = self.call(function, e.0, std::slice::from_ref(&spec))?;
            r.pop().expect("one result")
        };
        self.observed.push(spec);
        Ok(values)
    }

    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        self.control("fmi2SetDebugLogging", op::SET_DEBUG_LOGGING, |e| {
            e.u8(on as u8)
        })
    }
}

enum Decoded {
    Fmu(FmuError),
    Protocol(String),
}

fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGABRT => "SIGABRT: abort",
        libc::SIGSEGV => "SIGSEGV: segmentation fault",
        libc::SIGBUS => "SIGBUS: bus error",
        libc::SIGFPE => "SIGFPE: arithmetic exception",
        libc::SIGILL => "SIGILL: illegal instruction",
        libc::SIGKILL => "SIGKILL",
        libc::SIGTERM => "SIGTERM",
        _ => "signal",
    }
}

fn copy_real(v: Values, out: &mut [f64]) {
    if let Values::Real(v) = v {
        out.copy_from_slice(&v);
    }
}

fn copy_int(v: Values, out: &mut [i32]) {
    if let Values::Int(v) = v {
        out.copy_from_slice(&v);
    }
}

impl Backend for IsolatedBackend {
    fn name(&self) -> &str {
        &self.name
    }
    fn time(&self) -> f64 {
        self.time
    }
    fn set_echo(&mut self, _on: bool) {
        // The worker keeps the FMU's messages for error reports; nothing is echoed.
    }
    fn last_log_lines(&self) -> Vec<String> {
        self.last_log.clone()
    }
    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        IsolatedBackend::set_debug_logging(self, on)
    }
    fn setup_experiment(&mut self, start: f64, stop: Option<f64>) -> Result<(), FmuError> {
        self.time = start;
        self.control("fmi2SetupExperiment", op::SETUP_EXPERIMENT, |e| {
            e.f64(start);
            e.u8(stop.is_some() as u8);
            e.f64(stop.unwrap_or(0.0));
        })
    }
    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.control("fmi2EnterInitializationMode", op::ENTER_INIT, |_| {})
    }
    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.control("fmi2ExitInitializationMode", op::EXIT_INIT, |_| {})
    }
    fn terminate(&mut self) -> Result<(), FmuError> {
        self.control("fmi2Terminate", op::TERMINATE, |_| {})
    }
    fn reset(&mut self) -> Result<(), FmuError> {
        self.pending = Enc::default();
        self.observed.clear();
        let r = self.control("fmi2Reset", op::RESET, |_| {});
        self.time = 0.0;
        r
    }
    fn get_real(&mut self, vrs: &[u32], out: &mut [f64]) -> Result<(), FmuError> {
        copy_real(self.get("fmi2GetReal", op::GET_REAL, vrs)?, out);
        Ok(())
    }
    fn set_real(&mut self, vrs: &[u32], values: &[f64]) -> Result<(), FmuError> {
        self.queue_set(op::SET_REAL, vrs, |e| values.iter().for_each(|&x| e.f64(x)));
        Ok(())
    }
    fn get_integer(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        copy_int(self.get("fmi2GetInteger", op::GET_INTEGER, vrs)?, out);
        Ok(())
    }
    fn set_integer(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.queue_set(op::SET_INTEGER, vrs, |e| {
            values.iter().for_each(|&x| e.i32(x))
        });
        Ok(())
    }
    fn get_boolean(&mut self, vrs: &[u32], out: &mut [i32]) -> Result<(), FmuError> {
        copy_int(self.get("fmi2GetBoolean", op::GET_BOOLEAN, vrs)?, out);
        Ok(())
    }
    fn set_boolean(&mut self, vrs: &[u32], values: &[i32]) -> Result<(), FmuError> {
        self.queue_set(op::SET_BOOLEAN, vrs, |e| {
            values.iter().for_each(|&x| e.i32(x))
        });
        Ok(())
    }
    fn do_step(&mut self, t: f64, h: f64) -> Result<(), FmuError> {
        // The step, then the gets that followed the previous step: one round trip.
        let predicted = std::mem::take(&mut self.observed);
        let mut e = Enc::default();
        e.u8(op::DO_STEP);
        e.f64(t);
        e.f64(h);
        for g in &predicted {
            e.u8(g.op);
            e.vrs(&g.vrs);
        }
        self.prefetched.clear();
        self.time = t;
        // Results are counted over the gets only; the step itself yields none.
        let r = self.call("fmi2DoStep", e.0, &predicted);
        match r {
            Ok(values) => {
                self.time = t + h;
                self.prefetched = predicted.into_iter().zip(values).collect();
                Ok(())
            }
            Err(e) => {
                if let FmuError::Call { function, .. } = &e {
                    if *function != "fmi2DoStep" && !function.starts_with("fmi2Set") {
                        // The step completed; a get after it failed.
                        self.time = t + h;
                    }
                }
                Err(e)
            }
        }
    }
}

impl Drop for IsolatedBackend {
    fn drop(&mut self) {
        if self.child.is_none() {
            return;
        }
        // Ask the worker to free the instance and leave; kill it if it does not.
        let _ = self.send(&frame(&[op::QUIT]));
        let _ = self.sock.shutdown(std::net::Shutdown::Write);
        let until = Instant::now() + Duration::from_secs(1);
        if let Some(child) = self.child.as_mut() {
            loop {
                match child.try_wait() {
                    Ok(Some(_)) => return,
                    Ok(None) if Instant::now() < until => {
                        std::thread::sleep(Duration::from_millis(2))
                    }
                    _ => break,
                }
            }
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

// ---- worker side ----

/// Serve the protocol on stdin until the host closes it or says quit. Returns the exit code.
pub fn serve_stdio() -> i32 {
    // Take the socket off fd 0, and point fd 0 at /dev/null and fd 1 at stderr, so that
    // an FMU that reads stdin or prints to stdout cannot touch the protocol.
    let fd = unsafe { libc::fcntl(0, libc::F_DUPFD_CLOEXEC, 3) };
    if fd < 0 {
        eprintln!("twinbench worker: no protocol socket on stdin");
        return 2;
    }
    unsafe {
        let null = libc::open(c"/dev/null".as_ptr(), libc::O_RDONLY);
        if null >= 0 {
            libc::dup2(null, 0);
            libc::close(null);
        }
        libc::dup2(2, 1);
    }
    // Die with the host even when stuck inside the FMU (a closed socket is noticed only
    // between calls). Not PR_SET_PDEATHSIG: that fires when the host *thread* that started
    // the worker ends, and hosts move simulations between threads.
    let parent = unsafe { libc::getppid() };
    let _ = std::thread::Builder::new()
        .name("host-watch".into())
        .spawn(move || loop {
            std::thread::sleep(Duration::from_millis(250));
            if unsafe { libc::getppid() } != parent {
                unsafe { libc::_exit(4) };
            }
        });
    let stream = unsafe { <UnixStream as std::os::fd::FromRawFd>::from_raw_fd(fd) };
    serve(stream)
}

fn serve(mut stream: UnixStream) -> i32 {
    let mut inst: Option<Instance> = None;
    let mut lib_cache: Option<Arc<crate::fmu::Library>> = None;
    let mut buf = Vec::new();
    loop {
        let mut len = [0u8; 4];
        if stream.read_exact(&mut len).is_err() {
            return 0; // the host is gone
        }
        let n = u32::from_le_bytes(len) as usize;
        if n > MAX_FRAME {
            eprintln!("twinbench worker: request of {n} bytes refused");
            return 2;
        }
        buf.resize(n, 0);
        if stream.read_exact(&mut buf).is_err() {
            return 0;
        }
        let mut out = Enc::default();
        let quit = run_ops(&buf, &mut inst, &mut lib_cache, &mut out);
        if quit {
            drop(inst);
            return 0;
        }
        if stream.write_all(&frame(&out.0)).is_err() {
            return 0;
        }
    }
}

/// Run one request; write the response into `out`. Returns true on quit.
fn run_ops(
    req: &[u8],
    inst: &mut Option<Instance>,
    lib_cache: &mut Option<Arc<crate::fmu::Library>>,
    out: &mut Enc,
) -> bool {
    let mut d = Dec::new(req);
    let mut results = Enc::default();
    let mut n_gets = 0u32;
    let mut reals = Vec::new();
    let mut ints = Vec::new();
    let err: Option<FmuError> = loop {
        if d.at_end() {
            break None;
        }
        let r = (|| -> Result<bool, Result<FmuError, String>> {
            let code = d.u8().map_err(Err)?;
            if code == op::QUIT {
                return Ok(true);
            }
            if code == op::INSTANTIATE {
                let lib = PathBuf::from(d.str().map_err(Err)?);
                let name = d.str().map_err(Err)?;
                let guid = d.str().map_err(Err)?;
                let res = PathBuf::from(d.str().map_err(Err)?);
                let logging = d.u8().map_err(Err)? != 0;
                let library = match lib_cache {
                    Some(l) => l.clone(),
                    None => Arc::new(crate::fmu::Library::load(&lib).map_err(Ok)?),
                };
                *lib_cache = Some(library.clone());
                *inst = None;
                let mut i = Instance::instantiate(library, &name, &guid, Some(&res), logging)
                    .map_err(Ok)?;
                i.set_echo(false);
                *inst = Some(i);
                return Ok(false);
            }
            let i = inst
                .as_mut()
                .ok_or_else(|| Err("no instance: instantiate first".to_string()))?;
            match code {
                op::SET_DEBUG_LOGGING => {
                    let on = d.u8().map_err(Err)? != 0;
                    i.set_debug_logging(on, &[]).map_err(Ok)?
                }
                op::SETUP_EXPERIMENT => {
                    let start = d.f64().map_err(Err)?;
                    let has = d.u8().map_err(Err)? != 0;
                    let stop = d.f64().map_err(Err)?;
                    i.setup_experiment(start, has.then_some(stop)).map_err(Ok)?
                }
                op::ENTER_INIT => i.enter_initialization_mode().map_err(Ok)?,
                op::EXIT_INIT => i.exit_initialization_mode().map_err(Ok)?,
                op::TERMINATE => i.terminate().map_err(Ok)?,
                op::RESET => i.reset().map_err(Ok)?,
                op::SET_REAL => {
                    let vrs = d.vrs().map_err(Err)?;
                    reals.clear();
                    for _ in 0..vrs.len() {
                        reals.push(d.f64().map_err(Err)?);
                    }
                    i.set_real(&vrs, &reals).map_err(Ok)?
                }
                op::SET_INTEGER | op::SET_BOOLEAN => {
                    let vrs = d.vrs().map_err(Err)?;
                    ints.clear();
                    for _ in 0..vrs.len() {
                        ints.push(d.i32().map_err(Err)?);
                    }
                    if code == op::SET_INTEGER {
                        i.set_integer(&vrs, &ints).map_err(Ok)?
                    } else {
                        i.set_boolean(&vrs, &ints).map_err(Ok)?
                    }
                }
                op::GET_REAL => {
                    let vrs = d.vrs().map_err(Err)?;
                    reals.clear();
                    reals.resize(vrs.len(), 0.0);
                    i.get_real(&vrs, &mut reals).map_err(Ok)?;
                    reals.iter().for_each(|&x| results.f64(x));
                    n_gets += 1;
                }
                op::GET_INTEGER | op::GET_BOOLEAN => {
                    let vrs = d.vrs().map_err(Err)?;
                    ints.clear();
                    ints.resize(vrs.len(), 0);
                    if code == op::GET_INTEGER {
                        i.get_integer(&vrs, &mut ints).map_err(Ok)?
                    } else {
                        i.get_boolean(&vrs, &mut ints).map_err(Ok)?
                    }
                    ints.iter().for_each(|&x| results.i32(x));
                    n_gets += 1;
                }
                op::DO_STEP => {
                    let t = d.f64().map_err(Err)?;
                    let h = d.f64().map_err(Err)?;
                    i.do_step(t, h).map_err(Ok)?
                }
                c => return Err(Err(format!("unknown operation {c}"))),
            }
            Ok(false)
        })();
        match r {
            Ok(true) => return true,
            Ok(false) => {}
            Err(Ok(e)) => break Some(e),
            Err(Err(m)) => {
                break Some(FmuError::Isolated {
                    instance: String::new(),
                    function: "the protocol".into(),
                    time: 0.0,
                    cause: m,
                    log: Vec::new(),
                })
            }
        }
    };
    out.u8(err.is_some() as u8);
    out.u32(n_gets);
    out.f64(inst.as_ref().map_or(0.0, |i| i.time));
    out.0.extend_from_slice(&results.0);
    if let Some(e) = err {
        match e {
            FmuError::Call {
                function,
                status,
                time,
                log,
                ..
            } => {
                out.u8(kind::CALL);
                out.str(function);
                out.str(status);
                out.f64(time);
                out.u32(log.len() as u32);
                log.iter().for_each(|l| out.str(l));
            }
            FmuError::Instantiate { message, .. } => {
                out.u8(kind::INSTANTIATE);
                out.str(&message);
            }
            FmuError::Unsupported { what, .. } => {
                out.u8(kind::UNSUPPORTED);
                out.str(what);
            }
            FmuError::Isolated { cause, .. } => {
                out.u8(kind::OTHER);
                out.str(&cause);
            }
            other => {
                out.u8(kind::OTHER);
                out.str(&other.to_string());
            }
        }
    }
    false
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

    #[test]
    fn a_request_without_an_instance_is_an_error_not_a_panic() {
        let mut out = Enc::default();
        let mut e = Enc::default();
        e.u8(op::DO_STEP);
        e.f64(0.0);
        e.f64(1.0);
        assert!(!run_ops(&e.0, &mut None, &mut None, &mut out));
        assert_eq!(out.0[0], 1);
        let mut out = Enc::default();
        assert!(!run_ops(&[200], &mut None, &mut None, &mut out));
        assert_eq!(out.0[0], 1);
    }
}

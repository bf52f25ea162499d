//! The host's end: an instance whose calls go to a worker process. Sets are queued and sent
//! with the next call; the gets that followed the previous step are sent with each step
//! (their results prefetched), so that a Gauss-Seidel step is one round trip. Every answer
//! is checked (a malformed one kills the worker with a protocol error) and every round trip
//! has a watchdog.

use super::wire::{frame, function_of, kind, op, Dec, Enc, LibraryTarget, MAX_FRAME};
use super::{IsolationOptions, LibraryReport, STDERR_LINES};
use crate::backend::Backend;
use std::collections::VecDeque;
use std::io::Read;
use std::os::fd::{AsRawFd, OwnedFd};
use std::os::unix::net::UnixStream;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tb_fmi::fmi2::fmi2Status;
use tb_fmi::import::log::LogSink;
use tb_fmi::{FmuError, Function, LoadedFmu};

/// A kind of get, with the value references asked for.
#[derive(Clone, Debug, PartialEq)]
struct GetSpec {
    op: u8,
    vrs: Vec<u32>,
}

enum Values {
    Real(Vec<f64>),
    Int(Vec<i32>),
    Text(Vec<String>),
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
    /// The FMU's last messages, as the worker reported them with an error.
    sink: LogSink,
}

impl IsolatedBackend {
    /// A worker process with the FMU's library loaded and one instance created in it.
    pub(super) fn start(
        name: &str,
        fmu: &LoadedFmu,
        options: &IsolationOptions,
        logging: bool,
    ) -> Result<IsolatedBackend, FmuError> {
        let mut b = IsolatedBackend::spawn(name, options)?;
        let mut e = Enc::default();
        e.u8(op::INSTANTIATE);
        library_target(fmu, options).encode(&mut e);
        e.str(name);
        e.str(&fmu.description.guid);
        e.str(&fmu.resource_dir().to_string_lossy());
        e.u8(logging as u8);
        b.call(Function::Instantiate.name(), e.0, &[])?;
        if logging {
            b.set_debug_logging(true)?;
        }
        Ok(b)
    }

    /// Load the FMU's library in a fresh worker and report on it.
    pub(super) fn probe(
        fmu: &LoadedFmu,
        options: &IsolationOptions,
    ) -> Result<LibraryReport, FmuError> {
        let name = fmu.model_identifier().to_string();
        let mut b = IsolatedBackend::spawn(&name, options)?;
        let mut e = Enc::default();
        e.u8(op::PROBE);
        library_target(fmu, options).encode(&mut e);
        let spec = GetSpec {
            op: op::PROBE,
            vrs: vec![0, 0],
        };
        let answer = b.call(Function::GetVersion.name(), e.0, &[spec])?;
        match answer.as_slice() {
            [Values::Text(t)] if t.len() == 2 => Ok(LibraryReport {
                version: t[0].clone(),
                missing_optional: t[1]
                    .split(',')
                    .filter(|s| !s.is_empty())
                    .map(String::from)
                    .collect(),
            }),
            _ => Err(b.isolated_error(
                Function::GetVersion.name(),
                "protocol error (no report on the library)".into(),
                Vec::new(),
            )),
        }
    }

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
                    read_stderr(
                        err,
                        |line| {
                            let mut t = tail.lock().unwrap_or_else(|p| p.into_inner());
                            if t.len() == STDERR_LINES {
                                t.pop_front();
                            }
                            t.push_back(line);
                        },
                        &who,
                    );
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
            sink: LogSink::new(name),
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
        } else {
            // A worker that closed its socket should be dying; one that lingers is killed
            // (a hostile worker must not keep the host waiting).
            let until = Instant::now() + Duration::from_secs(2);
            while matches!(child.try_wait(), Ok(None)) && Instant::now() < until {
                std::thread::sleep(Duration::from_millis(5));
            }
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
        let n = u32::from_le_bytes(len) as usize;
        if got.is_ok() && n > MAX_FRAME {
            let end = self.bury(true);
            let cause = format!(
                "protocol error (answer of {n} bytes is too large, the limit is {MAX_FRAME}); killed ({end})"
            );
            self.dead = Some(cause.clone());
            return Err(self.isolated_error(function, cause, self.stderr_lines()));
        }
        let got = got.and_then(|()| {
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
            out.push(if g.op == op::GET_REAL || g.op == op::FMU_TERMINATED {
                Values::Real(
                    (0..g.vrs.len())
                        .map(|_| d.f64())
                        .collect::<Result<_, _>>()
                        .map_err(p)?,
                )
            } else if g.op == op::GET_STRING || g.op == op::PROBE {
                Values::Text(
                    (0..g.vrs.len())
                        .map(|_| d.str())
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
                let code = d.u8().map_err(p)?;
                let f =
                    function_of(code).ok_or_else(|| p(format!("unknown function code {code}")))?;
                let status = fmi2Status(d.i32().map_err(p)?);
                let t = d.f64().map_err(p)?;
                let n = d.count(4).map_err(p)?;
                let log: Vec<String> = (0..n)
                    .map(|_| d.str())
                    .collect::<Result<_, _>>()
                    .map_err(p)?;
                self.sink.clear();
                for l in &log {
                    self.sink.keep(l.clone());
                }
                FmuError::call(&self.name, f, status, t, log)
            }
            kind::INSTANTIATE => FmuError::Instantiate {
                instance: self.name.clone(),
                message: d.str().map_err(p)?,
            },
            kind::UNSUPPORTED => {
                let code = d.u8().map_err(p)?;
                FmuError::Unsupported {
                    instance: self.name.clone(),
                    what: function_of(code).map_or("a function", Function::name),
                }
            }
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
            match r.pop() {
                Some(v) => v,
                // A worker that answers a get with no result is broken or hostile.
                None => {
                    let end = self.bury(true);
                    let cause = format!("protocol error (no result for the get); killed ({end})");
                    self.dead = Some(cause.clone());
                    return Err(self.isolated_error(function, cause, self.stderr_lines()));
                }
            }
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

/// The longest line of a worker's stderr kept (longer ones are cut): a worker that writes
/// without newlines must not grow the host's memory.
const STDERR_LINE_BYTES: usize = 4096;
/// Lines of a worker's stderr echoed to the log; later ones are only kept in the tail.
const STDERR_ECHOED: usize = 200;

/// Read a worker's stderr in bounded chunks, handing each (possibly cut) line to `keep`.
fn read_stderr(mut err: impl Read, mut keep: impl FnMut(String), who: &str) {
    let mut chunk = [0u8; 8192];
    let mut line: Vec<u8> = Vec::new();
    let mut cut = false;
    let mut echoed = 0usize;
    let mut emit = |line: &mut Vec<u8>, cut: &mut bool| {
        let mut text = String::from_utf8_lossy(line).into_owned();
        if *cut {
            text.push_str(" [line cut]");
        }
        line.clear();
        *cut = false;
        match echoed.cmp(&STDERR_ECHOED) {
            std::cmp::Ordering::Less => log::warn!(target: "worker", "{who}: {text}"),
            std::cmp::Ordering::Equal => log::warn!(
                target: "worker",
                "{who}: more than {STDERR_ECHOED} lines on stderr; the rest is not shown"
            ),
            std::cmp::Ordering::Greater => {}
        }
        echoed = echoed.saturating_add(1);
        keep(text);
    };
    loop {
        let n = match err.read(&mut chunk) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(_) => break,
        };
        for &b in &chunk[..n] {
            if b == b'\n' {
                emit(&mut line, &mut cut);
            } else if line.len() < STDERR_LINE_BYTES {
                line.push(b);
            } else {
                cut = true;
            }
        }
    }
    if !line.is_empty() || cut {
        emit(&mut line, &mut cut);
    }
}

fn library_target(fmu: &LoadedFmu, options: &IsolationOptions) -> LibraryTarget {
    LibraryTarget {
        path: fmu.library_path().to_string_lossy().into_owned(),
        source: fmu.source.to_string_lossy().into_owned(),
        model_identifier: fmu.model_identifier().to_string(),
        preload: options
            .preload
            .iter()
            .map(|p| p.to_string_lossy().into_owned())
            .collect(),
        description: if fmu.is_fmi3() {
            fmu.dir
                .join("modelDescription.xml")
                .to_string_lossy()
                .into_owned()
        } else {
            String::new()
        },
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
        self.sink.last_lines()
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
    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        match self.get("fmi2GetString", op::GET_STRING, vrs)? {
            Values::Text(t) if t.len() == vrs.len() => {
                *out = t;
                Ok(())
            }
            _ => Err(self.isolated_error(
                "fmi2GetString",
                "protocol error (the answer is not one string per value reference)".into(),
                Vec::new(),
            )),
        }
    }
    fn set_string(&mut self, vrs: &[u32], values: &[&str]) -> Result<(), FmuError> {
        self.queue_set(op::SET_STRING, vrs, |e| {
            values.iter().for_each(|v| e.str(v))
        });
        Ok(())
    }
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        let spec = GetSpec {
            op: op::FMU_TERMINATED,
            vrs: vec![0, 0],
        };
        self.prefetched.clear();
        match self
            .call(
                Function::GetBooleanStatus.name(),
                vec![op::FMU_TERMINATED],
                std::slice::from_ref(&spec),
            )
            .ok()?
            .pop()
        {
            Some(Values::Real(v)) if v.len() == 2 && v[0] != 0.0 => {
                self.time = v[1];
                Some(v[1])
            }
            _ => None,
        }
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
                    if !matches!(
                        function,
                        Function::DoStep
                            | Function::SetReal
                            | Function::SetInteger
                            | Function::SetBoolean
                            | Function::SetString
                    ) {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stderr_without_newlines_is_kept_in_bounded_lines() {
        // 10 MB without a newline, then a short line: the kept text is bounded.
        let mut input = vec![b'x'; 10_000_000];
        input.extend_from_slice(b"\nlast words\n");
        let mut kept = Vec::new();
        read_stderr(input.as_slice(), |l| kept.push(l), "test");
        assert_eq!(kept.len(), 2);
        assert!(kept[0].len() <= STDERR_LINE_BYTES + 16, "{}", kept[0].len());
        assert!(kept[0].ends_with("[line cut]"));
        assert_eq!(kept[1], "last words");
    }

    #[test]
    fn a_last_line_without_newline_is_kept() {
        let mut kept = Vec::new();
        read_stderr(&b"a\nb"[..], |l| kept.push(l), "test");
        assert_eq!(kept, ["a", "b"]);
    }
}

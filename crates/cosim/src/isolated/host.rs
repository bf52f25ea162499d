//! The host's end: an instance whose calls go to a worker process. Sets are queued and sent
//! with the next call; the gets that followed the previous step are sent with each step
//! (their results prefetched), so that a Gauss-Seidel step is one round trip. Every answer
//! is checked (a malformed one kills the worker with a protocol error) and every round trip
//! has a watchdog.

use super::wire::{Enc, Failure, LibraryTarget, Request, Response, Values, MAX_FRAME};
use super::{IsolationOptions, LibraryReport, WorkerLost, STDERR_LINES};
use crate::backend::{Backend, RunAs};
use std::collections::VecDeque;
use std::io::Read;
use std::os::fd::{AsRawFd, OwnedFd};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tb_fmi::import::log::LogSink;
use tb_fmi::{FmiFunction, FmuError, Function, Interface, LoadedFmu};

/// One instance in a worker process.
pub struct IsolatedBackend {
    name: String,
    time: f64,
    sock: UnixStream,
    child: Option<Child>,
    stderr_tail: Arc<Mutex<VecDeque<String>>>,
    stderr_done: Arc<std::sync::atomic::AtomicBool>,
    timeout: Duration,
    /// The next request's frame: the queued sets, sent with the next call (reused).
    request: Enc,
    /// The last answer's bytes (reused).
    answer: Vec<u8>,
    /// Gets made since the last step (the prediction for the next step).
    observed: Vec<Request<'static>>,
    /// Results of the gets sent with the last step, in order.
    prefetched: VecDeque<(Request<'static>, Values)>,
    /// Why the worker is gone; every later call fails at once.
    dead: Option<String>,
    /// The FMU's last messages, as the worker reported them with an error.
    sink: LogSink,
    /// A confined worker's scratch folder, removed after the worker (dropped last), and its
    /// limits (named when it dies).
    _scratch: Option<(super::confine::Scratch, super::confine::Limits)>,
}

impl IsolatedBackend {
    /// A worker process with the FMU's library loaded and one instance created in it.
    pub(super) fn start(
        name: &str,
        fmu: &LoadedFmu,
        options: &IsolationOptions,
        logging: bool,
        run: RunAs,
    ) -> Result<IsolatedBackend, FmuError> {
        let library = library_target(fmu, options, run)?;
        let mut b = IsolatedBackend::spawn(name, options, &fmu.dir)?;
        b.queue(&Request::Instantiate {
            library,
            name: name.to_string(),
            guid: fmu.description.guid.clone(),
            resources: fmu.resource_dir().to_string_lossy().into_owned(),
            logging,
        });
        b.call(Function::Instantiate.name(), &[])?;
        if logging {
            b.set_debug_logging(true)?;
        }
        Ok(b)
    }

    /// A real-time check of the initialised instance ([`crate::realtime`]): the worker's
    /// measurement.
    pub(super) fn realtime(
        &mut self,
        spec: &crate::realtime::CheckSpec,
    ) -> Result<crate::realtime::Measurement, FmuError> {
        let function = "realtime-check";
        let json = serde_json::to_string(spec).expect("a check's settings serialise");
        let op = Request::Realtime(json);
        self.queue(&op);
        let answer = self.call(function, std::slice::from_ref(&op))?;
        match answer.into_iter().next() {
            Some(Values::Text(t)) if t.len() == 1 => serde_json::from_str(&t[0]).map_err(|e| {
                self.isolated_error(function, format!("protocol error ({e})"), Vec::new())
            }),
            _ => Err(self.isolated_error(
                function,
                "protocol error (no measurement)".into(),
                Vec::new(),
            )),
        }
    }

    /// Load the FMU's library in a fresh worker and report on it.
    pub(super) fn probe(
        fmu: &LoadedFmu,
        options: &IsolationOptions,
    ) -> Result<LibraryReport, FmuError> {
        let name = fmu.model_identifier().to_string();
        let library = library_target(fmu, options, RunAs::default_for(fmu))?;
        let mut b = IsolatedBackend::spawn(&name, options, &fmu.dir)?;
        let probe = Request::Probe(library);
        b.queue(&probe);
        let answer = b.call(Function::GetVersion.name(), std::slice::from_ref(&probe))?;
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

    /// A worker process; `store`, the store of unpacked FMUs it is to make read-only for
    /// itself before it loads anything.
    fn spawn(
        name: &str,
        options: &IsolationOptions,
        fmu_dir: &Path,
    ) -> Result<IsolatedBackend, FmuError> {
        let fail = |cause: String| FmuError::Isolated {
            instance: name.to_string(),
            function: "starting the worker".into(),
            time: 0.0,
            cause,
            log: Vec::new(),
        };
        let exe = options.resolve_exe().map_err(|e| fail(e.to_string()))?;
        let (host, worker) = UnixStream::pair().map_err(|e| fail(format!("socketpair: {e}")))?;
        let mut cmd = Command::new(&exe);
        // A process group of its own: a terminal's Ctrl-C reaches the host, which stops the
        // study cleanly, not the worker; and killing the group ends the worker and its
        // guard together.
        std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
        // Confined unless the user asked for crash isolation only: a scratch folder of its
        // own, and what it may read (its FMU's folder, the preloads, the files of `*_file`
        // parameters).
        let scratch = match options.mode.effective() {
            super::confine::Mode::CrashOnly => {
                static ONCE: std::sync::Once = std::sync::Once::new();
                ONCE.call_once(|| {
                    log::warn!(
                        "isolated workers are not confined (crash-only isolation): an FMU run so can read and write whatever this user can, the store of unpacked FMUs included"
                    )
                });
                cmd.env_remove(super::confine::SPEC_ENV);
                None
            }
            super::confine::Mode::Confined => {
                Some(confine(&mut cmd, options, fmu_dir).map_err(|e| fail(e.to_string()))?)
            }
        };
        cmd.arg("worker")
            .stdin(Stdio::from(OwnedFd::from(worker)))
            .stdout(Stdio::null())
            .stderr(Stdio::piped());
        // No descriptor the host inherited or opened (a CI runner's, a shell's `3>>file`, a
        // Python host's) reaches the worker: all but stdio closed at the exec.
        let fd_limit = super::confine::inherit::descriptor_limit();
        // SAFETY: the closure makes system calls only (no allocation, no lock): safe between
        // fork and exec.
        unsafe {
            std::os::unix::process::CommandExt::pre_exec(&mut cmd, move || {
                super::confine::inherit::cloexec_from(3, fd_limit);
                Ok(())
            });
        }
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
        let mut b = IsolatedBackend {
            name: name.to_string(),
            time: 0.0,
            sock: host,
            child: Some(child),
            stderr_tail,
            stderr_done,
            timeout: options.timeout,
            request: Enc::default(),
            answer: Vec::new(),
            observed: Vec::new(),
            prefetched: VecDeque::new(),
            dead: None,
            sink: LogSink::new(name),
            _scratch: scratch,
        };
        b.request.start_frame();
        Ok(b)
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
        // The worker runs in a child of the process started here (its guard), in their
        // own process group: the whole group is killed.
        let kill_group = |child: &Child| {
            // SAFETY: a signal to the process group we created.
            unsafe { libc::kill(-(child.id() as libc::pid_t), libc::SIGKILL) };
        };
        if kill {
            kill_group(&child);
        } else {
            // A worker that closed its socket should be dying; one that lingers is killed
            // (a hostile worker must not keep the host waiting).
            let until = Instant::now() + Duration::from_secs(2);
            while matches!(child.try_wait(), Ok(None)) && Instant::now() < until {
                std::thread::sleep(Duration::from_millis(5));
            }
            kill_group(&child);
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
            (Some(super::confine::CANNOT_CONFINE), _) => {
                let why = self
                    .stderr_lines()
                    .into_iter()
                    .find_map(|l| {
                        l.split_once("cannot confine the FMU: ")
                            .map(|(_, w)| w.to_string())
                    })
                    .unwrap_or_else(|| "(no reason given)".into());
                format!(
                    "the FMU was not loaded: its worker cannot be confined here ({why}); run it with --isolate=crash-only (or {}=crash-only) to isolate it for crashes and hangs only, without confinement",
                    super::confine::MODE_ENV
                )
            }
            (Some(c), _) => format!("the worker process exited with code {c}"),
            (None, Some(sig)) => format!(
                "the worker process was killed by signal {sig} ({})",
                signal_name(sig),
            ),
            _ => format!("the worker process ended: {status}"),
        }
    }

    /// A confined worker's limits, for the message of its end: an FMU that died or hung may
    /// have run into one.
    fn limits_note(&self) -> String {
        match &self._scratch {
            Some((_, l)) => format!(
                "; a confined worker's limits: {} (--worker-limits or {})",
                l.describe(),
                super::confine::LIMITS_ENV
            ),
            None => String::new(),
        }
    }

    fn stderr_lines(&self) -> Vec<String> {
        self.stderr_tail
            .lock()
            .map(|t| t.iter().map(|l| format!("[worker stderr] {l}")).collect())
            .unwrap_or_default()
    }

    /// Send the request (the queued sets and what was queued since) and take its answer
    /// into `self.answer`; the worker killed, and why, when it fails to answer in time or
    /// in form. The next request starts empty either way.
    fn exchange(&mut self) -> Result<(), WorkerLost> {
        let deadline = Instant::now() + self.timeout;
        let sent = send(&self.sock, self.request.finish_frame());
        self.request.start_frame();
        let mut len = [0u8; 4];
        let got = match sent {
            Ok(()) => recv_exact(&self.sock, &mut len, deadline),
            Err(e) => Err(Some(format!("cannot write to the worker: {e}"))),
        };
        let n = u32::from_le_bytes(len) as usize;
        if got.is_ok() && n > MAX_FRAME {
            let end = self.bury(true);
            return Err(WorkerLost::TooLarge { size: n, end });
        }
        let got = got.and_then(|()| {
            self.answer.resize(n, 0);
            recv_exact(&self.sock, &mut self.answer, deadline)
        });
        match got {
            Ok(()) => Ok(()),
            Err(None) => {
                let end = self.bury(true);
                Err(WorkerLost::Hung {
                    timeout: self.timeout,
                    end,
                })
            }
            Err(Some(_)) => {
                let end = self.bury(false);
                // A worker that died of a signal by itself may have run into a limit (a
                // crash after a failed allocation).
                let note = if end.contains("killed by signal") {
                    self.limits_note()
                } else {
                    String::new()
                };
                Err(WorkerLost::Crashed { end, note })
            }
        }
    }

    /// Send the request and decode its answer: the values of the gets among `answered`
    /// (the operations queued since the last call that are answered, in order).
    fn call(&mut self, function: &str, answered: &[Request<'_>]) -> Result<Vec<Values>, FmuError> {
        if let Some(cause) = &self.dead {
            self.request.start_frame();
            return Err(self.isolated_error(function, cause.clone(), self.stderr_lines()));
        }
        let response = self
            .exchange()
            .and_then(|()| {
                Response::decode(&self.answer, answered).map_err(|error| {
                    let end = self.bury(true);
                    WorkerLost::Protocol { error, end }
                })
            })
            .map_err(|lost| self.died(function, lost.to_string()))?;
        match response.error {
            None => Ok(response.results),
            Some(f) => Err(self.failure(function, f)),
        }
    }

    /// The worker is gone for `cause`: this call's error, and every later call's.
    fn died(&mut self, function: &str, cause: String) -> FmuError {
        self.dead = Some(cause.clone());
        self.isolated_error(function, cause, self.stderr_lines())
    }

    /// The FMU's log lines of a failed call, kept for reports in place of earlier ones.
    fn keep_log(&mut self, log: &[String]) {
        self.sink.clear();
        for l in log {
            self.sink.keep(l.clone());
        }
    }

    /// The error a request stopped with, as the FMU's (its log kept for reports).
    fn failure(&mut self, function: &str, f: Failure) -> FmuError {
        match f {
            Failure::Call {
                function,
                status,
                time,
                log,
            } => {
                self.keep_log(&log);
                FmuError::call(&self.name, function, status, time, log)
            }
            Failure::EarlyReturn {
                time,
                last,
                target,
                log,
            } => {
                self.keep_log(&log);
                FmuError::EarlyReturn {
                    instance: self.name.clone(),
                    time,
                    last,
                    target,
                    log,
                }
            }
            Failure::ModelExchange {
                fmu,
                call,
                problem,
                time,
                log,
            } => {
                self.keep_log(&log);
                FmuError::ModelExchange {
                    fmu: std::path::PathBuf::from(fmu).into_boxed_path(),
                    instance: self.name.clone(),
                    time,
                    call: call.into(),
                    problem,
                    log,
                }
            }
            Failure::Instantiate(message) => FmuError::Instantiate {
                instance: self.name.clone(),
                message,
            },
            Failure::Unsupported(f) => FmuError::Unsupported {
                instance: self.name.clone(),
                what: f.map_or("a function", Function::name),
            },
            Failure::Other(m) => self.isolated_error(function, m, Vec::new()),
        }
    }

    /// Add an operation to the next request.
    fn queue(&mut self, op: &Request<'_>) {
        op.encode(&mut self.request);
    }

    /// A call that changes the instance's state (no answer but its status).
    fn control(&mut self, function: &str, op: Request<'_>) -> Result<(), FmuError> {
        self.prefetched.clear();
        // Gets before a state change are no guide to those after the next step.
        self.observed.clear();
        self.queue(&op);
        self.call(function, &[]).map(|_| ())
    }

    /// A set, sent with the next call.
    fn queue_set(&mut self, op: Request<'_>) {
        // A set may change outputs (direct feed-through): what was fetched is stale.
        self.prefetched.clear();
        self.queue(&op);
    }

    /// A get: its prefetched values when it is the one predicted, else a round trip.
    fn get(&mut self, function: &str, op: Request<'_>) -> Result<Values, FmuError> {
        if self.prefetched.front().is_some_and(|(p, _)| *p == op) {
            let (op, values) = self.prefetched.pop_front().expect("a prefetched get");
            self.observed.push(op);
            return Ok(values);
        }
        self.prefetched.clear();
        self.queue(&op);
        let Some(values) = self.call(function, std::slice::from_ref(&op))?.pop() else {
            // A worker that answers a get with no result is broken or hostile.
            let end = self.bury(true);
            let cause = format!("protocol error (no result for the get); killed ({end})");
            return Err(self.died(function, cause));
        };
        self.observed.push(op.into_owned());
        Ok(values)
    }

    fn set_debug_logging(&mut self, on: bool) -> Result<(), FmuError> {
        self.control("fmi2SetDebugLogging", Request::SetDebugLogging(on))
    }
}

/// The confinement of a worker about to start: a scratch folder of its own, and what it
/// may read (its FMU's folder, the preloads and their installations, an embedded Python's
/// search path, the files of `*_file` parameters), passed to it in its environment, which
/// is the allowlist's, never the host's. Why it cannot be set up, as the cause of the
/// worker's failure to start.
fn confine(
    cmd: &mut Command,
    options: &IsolationOptions,
    fmu_dir: &Path,
) -> Result<(super::confine::Scratch, super::confine::Limits), super::confine::ConfineError> {
    let scratch =
        super::confine::Scratch::new().map_err(super::confine::ConfineError::MakeScratch)?;
    let mut read: Vec<PathBuf> = vec![fmu_dir.to_path_buf()];
    for p in &options.preload {
        // A preloaded interpreter reads its installation (libpython: its
        // standard library beside `lib/`), found where the library really is.
        let real = std::fs::canonicalize(p).unwrap_or_else(|_| p.clone());
        for lib in [p.clone(), real] {
            if let Some(prefix) = lib.parent().and_then(Path::parent) {
                read.push(prefix.to_path_buf());
            }
            read.push(lib);
        }
    }
    // An embedded Python's own search path, when the user set one.
    for var in ["PYTHONHOME", "PYTHONPATH"] {
        if let Some(v) = std::env::var_os(var) {
            read.extend(std::env::split_paths(&v));
        }
    }
    read.extend(
        options
            .readable
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .cloned(),
    );
    let limits = match options.limits {
        Some(l) => l,
        None => super::confine::Limits::from_env()?,
    };
    let env = super::confine::inherit::passed_names();
    let spec = super::confine::Spec {
        scratch: scratch.path.clone(),
        read: super::confine::existing(read),
        limits,
        env: env.clone(),
    };
    let json = serde_json::to_string(&spec).map_err(super::confine::ConfineError::Describe)?;
    // An environment from the allowlist, never the host's (its keys, tokens,
    // agent sockets).
    cmd.env_clear()
        .envs(super::confine::inherit::environment(&env))
        .env(super::confine::SPEC_ENV, json);
    Ok((scratch, limits))
}

/// Write all of `bytes`.
fn send(sock: &UnixStream, bytes: &[u8]) -> std::io::Result<()> {
    let mut off = 0;
    while off < bytes.len() {
        // MSG_NOSIGNAL: a dead worker is an error here, never a SIGPIPE.
        let n = unsafe {
            libc::send(
                sock.as_raw_fd(),
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
fn recv_exact(
    mut sock: &UnixStream,
    buf: &mut [u8],
    deadline: Instant,
) -> Result<(), Option<String>> {
    let mut off = 0;
    while off < buf.len() {
        let left = deadline.saturating_duration_since(Instant::now());
        if left.is_zero() {
            return Err(None);
        }
        sock.set_read_timeout(Some(left))
            .map_err(|e| Some(e.to_string()))?;
        match sock.read(&mut buf[off..]) {
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
        // Control characters escaped: a worker must not drive the user's terminal.
        let mut text = tb_files::shown(&String::from_utf8_lossy(line), STDERR_LINE_BYTES, false);
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

/// What the worker loads, with the checks it makes first: the library of the interface the
/// instance runs through, verified here (repaired when it differs from its manifest), and
/// again by the worker; the description too where the worker reads it (FMI 3.0, Model
/// Exchange).
fn library_target(
    fmu: &LoadedFmu,
    options: &IsolationOptions,
    run: RunAs,
) -> Result<LibraryTarget, FmuError> {
    let me = run.interface == Interface::ModelExchange;
    let id = fmu
        .description
        .model_identifier(run.interface)
        .unwrap_or(fmu.model_identifier());
    let library = fmu.checked_library_of(run.interface)?;
    // The library first, then the files beside it (its dependencies, M3): the worker
    // verifies each again before it loads anything.
    let mut checks = vec![library.clone()];
    checks.extend(fmu.beside(&library).into_iter().filter(|c| *c != library));
    if fmu.is_fmi3() || me {
        checks.extend(fmu.unpacked_file("modelDescription.xml"));
    }
    Ok(LibraryTarget {
        path: library.path().to_string_lossy().into_owned(),
        source: fmu.source.to_string_lossy().into_owned(),
        model_identifier: id.to_string(),
        preload: options
            .preload
            .iter()
            .map(|p| p.to_string_lossy().into_owned())
            .collect(),
        model_exchange: me,
        tolerance: run.me.relative_tolerance.unwrap_or(f64::NAN),
        description: if fmu.is_fmi3() || me {
            fmu.dir
                .join("modelDescription.xml")
                .to_string_lossy()
                .into_owned()
        } else {
            String::new()
        },
        checks,
    })
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
        libc::SIGSYS => "SIGSYS: a system call the confinement refuses",
        libc::SIGXFSZ => "SIGXFSZ: file size limit exceeded",
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

/// The typed get and set of [`Backend`] for Real, Integer and Boolean: a get is one request
/// answered at once (its values copied out by `$copy`), a set is queued for the next frame.
macro_rules! typed_values {
    ($($get:ident, $set:ident, $t:ty, $g:ident, $s:ident, $copy:ident;)*) => {$(
        fn $get(&mut self, vrs: &[u32], out: &mut [$t]) -> Result<(), FmuError> {
            let op = Request::$g { vrs: vrs.into() };
            $copy(self.get(concat!("fmi2", stringify!($g)), op)?, out);
            Ok(())
        }
        fn $set(&mut self, vrs: &[u32], values: &[$t]) -> Result<(), FmuError> {
            self.queue_set(Request::$s {
                vrs: vrs.into(),
                values: values.into(),
            });
            Ok(())
        }
    )*};
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
    fn setup_experiment(&mut self, e: tb_fmi::Experiment) -> Result<(), FmuError> {
        self.time = e.start;
        self.control(
            "fmi2SetupExperiment",
            Request::SetupExperiment {
                start: e.start,
                stop: e.stop,
                tolerance: e.tolerance,
            },
        )
    }
    fn enter_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.control("fmi2EnterInitializationMode", Request::EnterInit)
    }
    fn exit_initialization_mode(&mut self) -> Result<(), FmuError> {
        self.control("fmi2ExitInitializationMode", Request::ExitInit)
    }
    fn terminate(&mut self) -> Result<(), FmuError> {
        self.control("fmi2Terminate", Request::Terminate)
    }
    fn reset(&mut self) -> Result<(), FmuError> {
        // Sets queued before a reset would land after it.
        self.request.start_frame();
        self.observed.clear();
        let r = self.control("fmi2Reset", Request::Reset);
        self.time = 0.0;
        r
    }
    typed_values! {
        get_real, set_real, f64, GetReal, SetReal, copy_real;
        get_integer, set_integer, i32, GetInteger, SetInteger, copy_int;
        get_boolean, set_boolean, i32, GetBoolean, SetBoolean, copy_int;
    }
    fn get_string(&mut self, vrs: &[u32], out: &mut Vec<String>) -> Result<(), FmuError> {
        let op = Request::GetString { vrs: vrs.into() };
        match self.get("fmi2GetString", op)? {
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
        self.queue_set(Request::SetString {
            vrs: vrs.into(),
            values: values.iter().map(|&v| v.into()).collect(),
        });
        Ok(())
    }
    fn terminated_by_fmu(&mut self) -> Option<f64> {
        self.prefetched.clear();
        self.queue(&Request::FmuTerminated);
        let answered = [Request::FmuTerminated];
        match self
            .call(Function::GetBooleanStatus.name(), &answered)
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
        let mut predicted = std::mem::take(&mut self.observed);
        self.queue(&Request::DoStep { t, h });
        for g in &predicted {
            self.queue(g);
        }
        self.prefetched.clear();
        self.time = t;
        // Results are counted over the gets only; the step itself yields none.
        match self.call("fmi2DoStep", &predicted) {
            Ok(values) => {
                self.time = t + h;
                self.prefetched.extend(predicted.drain(..).zip(values));
                // The emptied list keeps its room for this step's gets.
                self.observed = predicted;
                Ok(())
            }
            Err(e) => {
                if let Some(function) = e.call_function().and_then(FmiFunction::fmi2) {
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
        self.request.start_frame();
        self.queue(&Request::Quit);
        let _ = send(&self.sock, self.request.finish_frame());
        let _ = self.sock.shutdown(std::net::Shutdown::Write);
        let until = Instant::now() + Duration::from_secs(1);
        if let Some(child) = self.child.as_mut() {
            loop {
                match child.try_wait() {
                    Ok(None) if Instant::now() < until => {
                        std::thread::sleep(Duration::from_millis(2))
                    }
                    _ => break,
                }
            }
            // The group, not only the guard (a guard the FMU killed leaves the worker):
            // before the guard is reaped, so that its group id cannot have been reused.
            // SAFETY: a signal to the process group we created.
            unsafe { libc::kill(-(child.id() as libc::pid_t), libc::SIGKILL) };
            let _ = child.wait();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_workers_stderr_reaches_the_log_escaped_and_cut() {
        let mut kept = Vec::new();
        let mut bytes = b"plain\n\x1b[2J\x1b]0;owned\x07 cleared\r\n".to_vec();
        bytes.extend(std::iter::repeat_n(b'x', STDERR_LINE_BYTES + 10));
        read_stderr(&bytes[..], |l| kept.push(l), "w");
        assert_eq!(kept[0], "plain");
        assert_eq!(kept[1], "\\u{1b}[2J\\u{1b}]0;owned\\u{7} cleared\\u{d}");
        assert!(kept[2].ends_with(" [line cut]") && kept[2].len() < STDERR_LINE_BYTES + 64);
        assert!(kept.iter().all(|l| !l.chars().any(char::is_control)));
    }

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

//! The log sink of one instance, whatever runs it (a loaded FMU through the C logger shim, a
//! model linked natively, an isolated worker): messages are forwarded to the `log` crate
//! with the instance name and the last lines are kept for error reports.

use crate::fmi2::{fmi2CallbackLogger, fmi2Status};
use std::collections::VecDeque;
use std::ffi::{c_char, c_int, c_void, CStr};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

/// How many of an instance's last log lines an error report carries.
pub const KEPT_LINES: usize = 20;
/// The longest message of an FMU's shown (in characters; more is cut, saying how much).
pub const MAX_LINE_CHARS: usize = 4096;

/// Where one instance's messages go.
pub struct LogSink {
    pub instance: String,
    /// The FMI version whose status names the lines carry (`fmi2Error`, `fmi3Error`).
    fmi3: bool,
    lines: Mutex<VecDeque<String>>,
    /// Forward messages to `log` (off: kept only for error reports).
    echo: AtomicBool,
}

impl LogSink {
    pub fn new(instance: &str) -> Self {
        LogSink {
            instance: instance.to_string(),
            fmi3: false,
            lines: Mutex::new(VecDeque::new()),
            echo: AtomicBool::new(true),
        }
    }

    /// The sink of an FMI 3.0 instance: its lines carry FMI 3.0's status names.
    pub fn new3(instance: &str) -> Self {
        LogSink {
            fmi3: true,
            ..LogSink::new(instance)
        }
    }

    /// A status's name in this instance's FMI version.
    fn status_name(&self, status: fmi2Status) -> std::borrow::Cow<'static, str> {
        match self.fmi3 {
            true => status.name().replacen("fmi2", "fmi3", 1).into(),
            false => status.name().into(),
        }
    }

    pub fn set_echo(&self, on: bool) {
        self.echo.store(on, Ordering::Relaxed);
    }

    /// A message of the FMU's, cut at [`MAX_LINE_CHARS`] and with control characters
    /// escaped (an FMU's text reaches a terminal: no escape sequences, no 10 MB lines).
    pub fn push(&self, status: fmi2Status, category: &str, message: &str) {
        // A real-time check counts the message; what the host does with it is not the FMU's.
        let _paused = tb_rtcount::log_message();
        let line = format!(
            "[{}] {}: {}",
            self.status_name(status),
            tb_files::shown(category, 64, false),
            tb_files::shown(message, MAX_LINE_CHARS, true)
        );
        // Errors are not echoed: the call that failed reports them with its error (once).
        let level = match status {
            fmi2Status::OK => Some(log::Level::Debug),
            fmi2Status::WARNING | fmi2Status::DISCARD => Some(log::Level::Warn),
            _ => None,
        };
        if let (true, Some(level)) = (self.echo.load(Ordering::Relaxed), level) {
            log::log!(target: "fmu", level, "{}: {line}", self.instance);
        }
        self.keep(line);
    }

    /// Keep a line for error reports without echoing it.
    pub fn keep(&self, line: String) {
        if let Ok(mut l) = self.lines.lock() {
            if l.len() == KEPT_LINES {
                l.pop_front();
            }
            l.push_back(line);
        }
    }

    /// The last lines logged by the instance.
    pub fn last_lines(&self) -> Vec<String> {
        self.lines
            .lock()
            .map(|l| l.iter().cloned().collect())
            .unwrap_or_default()
    }

    pub fn clear(&self) {
        if let Ok(mut l) = self.lines.lock() {
            l.clear();
        }
    }
}

extern "C" {
    fn twinbench_fmi2_logger(
        env: *mut c_void,
        instance: *const c_char,
        status: fmi2Status,
        category: *const c_char,
        message: *const c_char,
        ...
    );
}

/// The C shim as the FMI logger callback.
pub fn fmi2_logger() -> fmi2CallbackLogger {
    twinbench_fmi2_logger
}

/// Layout shared with `twinbench_log_env` in logger_shim.c.
#[repr(C)]
pub struct LogEnv {
    sink: unsafe extern "C" fn(*mut c_void, *const c_char, c_int, *const c_char, *const c_char),
    ctx: *mut c_void,
}

unsafe extern "C" fn sink(
    ctx: *mut c_void,
    _instance: *const c_char,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    forward(ctx, status, category, message);
}

/// One message from C to the [`LogSink`] at `ctx` (nothing when it is NULL), the end of
/// both versions' loggers. Never unwinds into the FMU's C frames.
///
/// # Safety
/// `ctx` is NULL or points at a live `LogSink`; `category` and `message` are NULL or
/// NUL-terminated.
pub(super) unsafe fn forward(
    ctx: *mut c_void,
    status: c_int,
    category: *const c_char,
    message: *const c_char,
) {
    let _ = std::panic::catch_unwind(|| {
        if ctx.is_null() {
            return;
        }
        let s = &*(ctx as *const LogSink);
        let text = |p: *const c_char| {
            if p.is_null() {
                String::new()
            } else {
                CStr::from_ptr(p).to_string_lossy().into_owned()
            }
        };
        s.push(fmi2Status(status), &text(category), &text(message));
    });
}

/// A boxed environment pointing at `sink_ref`; keep both alive as long as the instance.
pub fn log_env(sink_ref: &LogSink) -> Box<LogEnv> {
    Box::new(LogEnv {
        sink,
        ctx: sink_ref as *const LogSink as *mut c_void,
    })
}

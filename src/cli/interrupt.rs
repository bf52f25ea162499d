//! Ctrl-C (or SIGTERM, as a cluster's scheduler sends before it kills a job) during a
//! study: the first asks the study to stop once the generation under way is done and
//! checkpointed, so that `--resume` continues it; a second ends the process at once (the
//! checkpoint of the last finished generation is still there). During a run
//! (`twinbench run`) the first ends the run after the step under way and keeps its rows as
//! an incomplete result; a second ends the process at once.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// The exit code of an interrupted command (128 + SIGINT, as a shell reports it).
pub const EXIT_INTERRUPTED: u8 = 130;

pub use crate::study::{shell_word, Interrupted};

/// The handlers of every command but a study's: a SIGINT or SIGTERM ends the process at
/// once, with the result files being written removed (nothing half-written stays behind).
static DEFAULT_HANDLERS: std::sync::Mutex<Vec<signal_hook::SigId>> =
    std::sync::Mutex::new(Vec::new());

/// The handlers of a study or a run ([`flag`], [`run_flag`]), while they are installed.
static FLAG_HANDLERS: std::sync::Mutex<Vec<signal_hook::SigId>> = std::sync::Mutex::new(Vec::new());

/// Installs the default handlers (see [`DEFAULT_HANDLERS`]) in place of a study's or a
/// run's (after a run, while its results are written); a run file size limit
/// (`ulimit -f`) becomes a write error naming the file instead of a silent SIGXFSZ death.
pub fn install_default() {
    // SAFETY: setting a signal's disposition to ignore has no preconditions.
    unsafe { libc::signal(libc::SIGXFSZ, libc::SIG_IGN) };
    for id in FLAG_HANDLERS
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .drain(..)
    {
        signal_hook::low_level::unregister(id);
    }
    let mut ids = DEFAULT_HANDLERS.lock().unwrap_or_else(|p| p.into_inner());
    if !ids.is_empty() {
        return;
    }
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        // SAFETY: the handler only removes files (unlink), writes to stderr and exits: all
        // async-signal-safe.
        let id = unsafe {
            signal_hook::low_level::register(signal, move || {
                tb_table::remove_in_flight();
                let m = b"\ninterrupted\n";
                libc::write(2, m.as_ptr().cast(), m.len());
                libc::_exit(128 + signal);
            })
        };
        ids.extend(id.ok());
    }
}

/// Installs the handlers of a study; the flag is set on the first SIGINT or SIGTERM.
pub fn flag() -> anyhow::Result<Arc<AtomicBool>> {
    flag_saying(
        b"\ninterrupt: stopping after the generation under way (Ctrl-C again to stop at once)\n",
        b"\ninterrupted again: stopping now (the checkpoint of the last finished generation is kept)\n",
    )
}

/// Installs the handlers of a run (`twinbench run`): the first SIGINT or SIGTERM ends it
/// after the step under way, its rows kept as an incomplete result.
pub fn run_flag() -> anyhow::Result<Arc<AtomicBool>> {
    flag_saying(
        b"\ninterrupt: ending the run after the step under way, its rows kept (Ctrl-C again to stop at once)\n",
        b"\ninterrupted again: stopping now\n",
    )
}

/// The handlers behind [`flag`] and [`run_flag`]: `first` is written on the first signal,
/// `again` on the second, which ends the process at once.
fn flag_saying(first: &'static [u8], again: &'static [u8]) -> anyhow::Result<Arc<AtomicBool>> {
    for id in DEFAULT_HANDLERS
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .drain(..)
    {
        signal_hook::low_level::unregister(id);
    }
    let flag = Arc::new(AtomicBool::new(false));
    for signal in [signal_hook::consts::SIGINT, signal_hook::consts::SIGTERM] {
        let f = flag.clone();
        // SAFETY: the handler only swaps an atomic, writes to stderr and exits: all
        // async-signal-safe.
        let id = unsafe {
            signal_hook::low_level::register(signal, move || {
                if f.swap(true, Ordering::SeqCst) {
                    tb_table::remove_in_flight();
                    libc::write(2, again.as_ptr().cast(), again.len());
                    libc::_exit(i32::from(EXIT_INTERRUPTED));
                }
                libc::write(2, first.as_ptr().cast(), first.len());
            })?
        };
        FLAG_HANDLERS
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .push(id);
    }
    Ok(flag)
}

/// A run (`twinbench run`) ended by SIGINT or SIGTERM: the message says where its rows are
/// kept; the exit code is [`EXIT_INTERRUPTED`].
#[derive(Debug)]
pub struct RunInterrupted(pub String);

impl std::fmt::Display for RunInterrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for RunInterrupted {}

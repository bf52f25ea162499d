//! Counters of what an FMU does while `twinbench realtime-check` watches it.
//!
//! A real-time target asks of a model's step that it never allocates, never takes a lock
//! and never makes a system call. Three writers count those here, each only while the
//! counters are [armed](arm) (around the FMI calls of a step, nowhere else):
//!
//! - the allocator functions the `twinbench` executable interposes over the C library's
//!   (`malloc`, `free`, ...: every library the worker loads, the FMU's among them, calls
//!   them), and its `pthread_*_lock` functions;
//! - the host's FMI logger, which counts a message and pauses the counters while it
//!   formats it (its own allocations are the host's, not the FMU's);
//! - the worker's system-call trap (`tb_cosim::realtime`), per call number.
//!
//! Plain atomics and no dependency: the writers run inside `malloc` and a signal handler,
//! where nothing may allocate, lock or call the system.

use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

/// What an interposed function counts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub enum Event {
    Malloc,
    Calloc,
    Realloc,
    /// `posix_memalign`, `aligned_alloc`, `memalign`, `valloc`, `pvalloc`.
    AlignedAlloc,
    /// `free` of a pointer other than null.
    Free,
    /// `pthread_mutex_lock`/`trylock`, `pthread_rwlock_rdlock`/`wrlock`,
    /// `pthread_spin_lock`: a lock taken, contended or not (a contended one also shows as
    /// a `futex` call).
    Lock,
    /// A message to the host's logger.
    Log,
}

/// The events' names in reports, in the order of [`Event`].
pub const EVENT_NAMES: [&str; EVENTS] = [
    "malloc",
    "calloc",
    "realloc",
    "aligned_alloc",
    "free",
    "lock",
    "log",
];
const EVENTS: usize = 7;

/// System-call numbers counted one by one; a higher number counts in the last slot.
pub const SYSCALL_SLOTS: usize = 512;

static ARMED: AtomicBool = AtomicBool::new(false);
/// Set by the executable that interposes the allocator (before it serves anything), so
/// that a check can tell "no allocation" from "no allocation could be seen".
static INTERPOSED: AtomicBool = AtomicBool::new(false);
static EVENTS_SEEN: [AtomicU64; EVENTS] = [const { AtomicU64::new(0) }; EVENTS];
static SYSCALLS: [AtomicU64; SYSCALL_SLOTS] = [const { AtomicU64::new(0) }; SYSCALL_SLOTS];

/// Count from now on (the FMU's calls of a step follow).
#[inline]
pub fn arm() {
    ARMED.store(true, Ordering::SeqCst);
}

/// Stop counting (the step's calls returned).
#[inline]
pub fn disarm() {
    ARMED.store(false, Ordering::SeqCst);
}

#[inline]
pub fn armed() -> bool {
    ARMED.load(Ordering::Relaxed)
}

/// Counts `event` if armed. Called from inside `malloc` and `free`: an atomic add only.
#[inline]
pub fn count(event: Event) {
    if ARMED.load(Ordering::Relaxed) {
        EVENTS_SEEN[event as usize].fetch_add(1, Ordering::Relaxed);
    }
}

/// Counts system call `nr` if armed. Called from a signal handler: an atomic add only.
#[inline]
pub fn count_syscall(nr: i64) {
    if ARMED.load(Ordering::Relaxed) {
        let slot = (nr.max(0) as usize).min(SYSCALL_SLOTS - 1);
        SYSCALLS[slot].fetch_add(1, Ordering::Relaxed);
    }
}

/// Says that this process's allocator functions are the counting ones.
pub fn set_interposed() {
    INTERPOSED.store(true, Ordering::SeqCst);
}

pub fn interposed() -> bool {
    INTERPOSED.load(Ordering::SeqCst)
}

/// While it lives the counters do not count (the host's own work inside an FMU's call,
/// such as formatting a log message); they count again as before when it is dropped.
pub struct Paused {
    was_armed: bool,
}

impl Paused {
    pub fn new() -> Paused {
        Paused {
            was_armed: ARMED.swap(false, Ordering::SeqCst),
        }
    }
}

impl Default for Paused {
    fn default() -> Self {
        Paused::new()
    }
}

impl Drop for Paused {
    fn drop(&mut self) {
        if self.was_armed {
            ARMED.store(true, Ordering::SeqCst);
        }
    }
}

/// A message to the host's logger: counted if armed, and the counters paused while the
/// host handles it.
pub fn log_message() -> Paused {
    count(Event::Log);
    Paused::new()
}

/// The counts so far.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Snapshot {
    /// Per [`Event`], in [`EVENT_NAMES`]' order.
    pub events: [u64; EVENTS],
    /// `(number, calls)` of every system call counted, by number.
    pub syscalls: Vec<(i64, u64)>,
}

impl Snapshot {
    pub fn event(&self, e: Event) -> u64 {
        self.events[e as usize]
    }

    /// Allocations of any kind (not counting frees).
    pub fn allocations(&self) -> u64 {
        self.event(Event::Malloc)
            + self.event(Event::Calloc)
            + self.event(Event::Realloc)
            + self.event(Event::AlignedAlloc)
    }
}

/// Reads the counters (not while armed: it allocates).
pub fn snapshot() -> Snapshot {
    let mut s = Snapshot::default();
    for (k, e) in EVENTS_SEEN.iter().enumerate() {
        s.events[k] = e.load(Ordering::SeqCst);
    }
    s.syscalls = SYSCALLS
        .iter()
        .enumerate()
        .map(|(nr, c)| (nr as i64, c.load(Ordering::SeqCst)))
        .filter(|(_, c)| *c > 0)
        .collect();
    s
}

/// Sets every counter to zero.
pub fn reset() {
    for e in &EVENTS_SEEN {
        e.store(0, Ordering::SeqCst);
    }
    for c in &SYSCALLS {
        c.store(0, Ordering::SeqCst);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    // One test: the counters are process-wide, and tests run in parallel threads.
    #[test]
    fn counts_only_while_armed_and_not_while_paused() {
        reset();
        count(Event::Malloc);
        count_syscall(1);
        assert_eq!(snapshot(), Snapshot::default());
        arm();
        count(Event::Malloc);
        count(Event::Free);
        count_syscall(1);
        count_syscall(100_000);
        {
            let _p = log_message();
            assert!(!armed());
            count(Event::Malloc);
        }
        assert!(armed());
        disarm();
        let s = snapshot();
        assert_eq!(s.event(Event::Malloc), 1);
        assert_eq!(s.event(Event::Free), 1);
        assert_eq!(s.event(Event::Log), 1);
        assert_eq!(s.allocations(), 1);
        assert_eq!(s.syscalls, vec![(1, 1), (SYSCALL_SLOTS as i64 - 1, 1)]);
        reset();
        assert_eq!(snapshot(), Snapshot::default());
    }
}

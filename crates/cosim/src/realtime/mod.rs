//! The real-time check of an FMU (`twinbench realtime-check`): after initialisation, does a
//! step (the inputs set, `doStep`, the outputs read) allocate, take a lock, log, or call
//! the system, and how long does it take?
//!
//! The host initialises the instance in an isolated worker as for a run, then hands the
//! worker a [`CheckSpec`]; the worker ([`measure`]) sets its [system-call trap](trap),
//! steps the instance with the counters of [`tb_rtcount`] armed around each step's FMI
//! calls only, times each step, and answers with a [`Measurement`]. The allocator
//! functions that count are the `twinbench` executable's: the worker is that executable.

pub mod measure;
pub mod report;
pub mod trap;

pub use measure::measure;
pub use report::{Item, Verdict};

use serde::{Deserialize, Serialize};

/// What the worker is to do.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct CheckSpec {
    /// Time of the first step [s].
    pub start: f64,
    /// The communication step [s].
    pub step: f64,
    /// Steps of one pass.
    pub steps: u64,
    /// Passes: after the first the instance is reset and initialised again (outside the
    /// measured steps) and stepped from `start` again.
    pub passes: u32,
    /// The Real inputs set before every step, interpolated linearly in `inputs`.
    pub inputs: Inputs,
    /// The Real outputs read after every step.
    pub outputs: Vec<u32>,
    /// Real parameters set after instantiation, before initialisation (value reference,
    /// value): a bench's own values.
    pub parameters: Vec<(u32, f64)>,
    /// Count system calls (the trap); off for an instruction count under valgrind, which
    /// does not run seccomp filters of its guest.
    pub count_syscalls: bool,
}

/// Inputs over time: one column per value reference.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Inputs {
    pub vrs: Vec<u32>,
    /// Non-decreasing; empty: the inputs keep `columns`' single value.
    pub time: Vec<f64>,
    pub columns: Vec<Vec<f64>>,
}

impl Inputs {
    /// The inputs at `t` into `out` (linear, held beyond the ends); `cursor` is where the
    /// last look-up ended (steps go forward: no search, no allocation).
    pub fn at(&self, t: f64, cursor: &mut usize, out: &mut [f64]) {
        let n = self.time.len();
        if n < 2 {
            for (o, c) in out.iter_mut().zip(&self.columns) {
                *o = c.first().copied().unwrap_or(0.0);
            }
            return;
        }
        if t < self.time[*cursor] {
            *cursor = 0;
        }
        while *cursor + 2 < n && self.time[*cursor + 1] <= t {
            *cursor += 1;
        }
        let (k, t0, t1) = (*cursor, self.time[*cursor], self.time[*cursor + 1]);
        let w = if t1 > t0 {
            ((t - t0) / (t1 - t0)).clamp(0.0, 1.0)
        } else {
            1.0
        };
        for (o, c) in out.iter_mut().zip(&self.columns) {
            *o = c[k] + w * (c[k + 1] - c[k]);
        }
    }
}

/// Counts of what the FMU did during the measured steps.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Counts {
    pub malloc: u64,
    pub calloc: u64,
    pub realloc: u64,
    pub aligned_alloc: u64,
    pub free: u64,
    /// pthread locks taken (contended ones also show as `futex` calls).
    pub locks: u64,
    /// Messages to the host's logger.
    pub log_messages: u64,
    /// System calls by name, most frequent first.
    pub syscalls: Vec<SyscallCount>,
}

#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SyscallCount {
    pub name: String,
    pub number: i64,
    pub calls: u64,
}

impl Counts {
    pub fn allocations(&self) -> u64 {
        self.malloc + self.calloc + self.realloc + self.aligned_alloc
    }

    pub fn syscalls_total(&self) -> u64 {
        self.syscalls.iter().map(|s| s.calls).sum()
    }

    fn from_snapshot(s: &tb_rtcount::Snapshot) -> Counts {
        use tb_rtcount::Event;
        let mut syscalls: Vec<SyscallCount> = s
            .syscalls
            .iter()
            .map(|&(number, calls)| SyscallCount {
                name: syscall_name(number),
                number,
                calls,
            })
            .collect();
        syscalls.sort_by(|a, b| b.calls.cmp(&a.calls).then(a.number.cmp(&b.number)));
        Counts {
            malloc: s.event(Event::Malloc),
            calloc: s.event(Event::Calloc),
            realloc: s.event(Event::Realloc),
            aligned_alloc: s.event(Event::AlignedAlloc),
            free: s.event(Event::Free),
            locks: s.event(Event::Lock),
            log_messages: s.event(Event::Log),
            syscalls,
        }
    }
}

/// A system call's name on this architecture (the kernel's table, from `syscalls`).
pub fn syscall_name(number: i64) -> String {
    if number == tb_rtcount::SYSCALL_SLOTS as i64 - 1 {
        return "other ABI or number".into();
    }
    match syscalls::Sysno::new(number as usize) {
        Some(s) => s.name().to_string(),
        None => format!("syscall {number}"),
    }
}

/// Step times [s].
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct TimeStats {
    pub steps: u64,
    pub mean: f64,
    pub median: f64,
    pub p99_9: f64,
    pub p99_99: f64,
    pub max: f64,
}

impl TimeStats {
    /// Of `ns` (sorted here).
    pub fn of(ns: &mut [u32]) -> TimeStats {
        if ns.is_empty() {
            return TimeStats::default();
        }
        ns.sort_unstable();
        let q = |p: f64| {
            let k = ((p * ns.len() as f64).ceil() as usize).clamp(1, ns.len()) - 1;
            ns[k] as f64 * 1e-9
        };
        TimeStats {
            steps: ns.len() as u64,
            mean: ns.iter().map(|&x| x as f64).sum::<f64>() / ns.len() as f64 * 1e-9,
            median: q(0.5),
            p99_9: q(0.999),
            p99_99: q(0.9999),
            max: ns[ns.len() - 1] as f64 * 1e-9,
        }
    }
}

/// One of the slowest steps.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct SlowStep {
    pub pass: u32,
    /// Its time in the simulation [s].
    pub t: f64,
    pub seconds: f64,
}

/// What the worker measured.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Measurement {
    /// Passes completed (fewer than asked when the FMU cannot be reset: said in `notes`).
    pub passes: u32,
    pub counts: Counts,
    /// The allocator functions counted (the worker is the `twinbench` executable).
    pub allocations_seen: bool,
    /// System calls counted (the trap was set).
    pub syscalls_seen: bool,
    /// The step's time: the inputs set, `doStep`, the outputs read.
    pub step_time: TimeStats,
    /// The same measurement around no call at all: the clock's and the machine's noise.
    pub noise: TimeStats,
    /// The five slowest steps.
    pub slowest: Vec<SlowStep>,
    pub notes: Vec<String>,
}

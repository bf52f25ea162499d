//! The verdicts of a real-time check and how they are said.

use super::{Counts, Measurement, TimeStats};
use serde::{Deserialize, Serialize};

/// An item's verdict.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    Clean,
    Fails,
    /// Could not be seen here (said why): not clean.
    NotSeen,
    /// A figure, not judged (the step's time without `--budget`: a desktop's clock is not
    /// the target's).
    Measured,
}

impl Verdict {
    /// Whether the item lets the check pass: clean, or a figure that is not judged.
    pub fn passes(self) -> bool {
        matches!(self, Verdict::Clean | Verdict::Measured)
    }
}

/// One item of the check.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Item {
    pub name: String,
    pub verdict: Verdict,
    pub says: String,
}

/// Instructions of `doStep` per step (callgrind), machine-independent.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Instructions {
    pub steps: u64,
    pub mean: f64,
    pub median: u64,
    pub max: u64,
    /// Simulation time of the most expensive step [s].
    pub max_at: f64,
    /// The first step's (often the one that finishes setting up).
    pub first: u64,
    /// The most expensive step after the first, and its time [s].
    pub max_after_first: u64,
    pub max_after_first_at: f64,
}

/// The ratio of the most expensive step to the mean that still counts as no hidden slow
/// path.
pub const MAX_OVER_MEAN: f64 = 3.0;

/// Everything judged, in order.
pub fn judge(
    m: &Measurement,
    step: f64,
    budget: Option<f64>,
    instructions: Option<&Instructions>,
) -> Vec<Item> {
    let steps = m.step_time.steps;
    let mut items = vec![
        allocations(&m.counts, m.allocations_seen, steps),
        syscalls(&m.counts, m.syscalls_seen, steps),
        locks(&m.counts, m.allocations_seen, m.syscalls_seen, steps),
        item(
            "log messages",
            m.counts.log_messages == 0,
            format!("{} in {steps} steps", m.counts.log_messages),
        ),
        time(&m.step_time, &m.noise, step, budget),
    ];
    if let Some(ins) = instructions {
        items.push(instructions_item(ins));
    }
    items
}

/// The most expensive step against the mean. The first step alone above the limit is the
/// one exception said by name (work an FMU leaves from initialisation to its first step:
/// a target's first cycle must allow for it); any later step above it fails.
fn instructions_item(ins: &Instructions) -> Item {
    let mean = ins.mean.max(1.0);
    let ratio = ins.max as f64 / mean;
    let later = ins.max_after_first as f64 / mean;
    let mut says = format!(
        "doStep: mean {:.0}, median {}, max {} at t = {:.4} s ({ratio:.2} × the mean; at most {MAX_OVER_MEAN}) over {} steps (callgrind)",
        ins.mean, ins.median, ins.max, ins.max_at, ins.steps
    );
    if ratio > MAX_OVER_MEAN && later <= MAX_OVER_MEAN {
        says.push_str(&format!(
            "; the one exception is the first step ({}, {:.1} × the mean: work left from initialisation to the first step, which a target's first cycle must allow for); after it the max is {} ({later:.2} ×)",
            ins.first,
            ins.first as f64 / mean,
            ins.max_after_first
        ));
    }
    item("instructions", later <= MAX_OVER_MEAN, says)
}

fn item(name: &str, clean: bool, says: String) -> Item {
    Item {
        name: name.into(),
        verdict: if clean {
            Verdict::Clean
        } else {
            Verdict::Fails
        },
        says,
    }
}

fn not_seen(name: &str, says: &str) -> Item {
    Item {
        name: name.into(),
        verdict: Verdict::NotSeen,
        says: says.into(),
    }
}

fn allocations(c: &Counts, seen: bool, steps: u64) -> Item {
    if !seen {
        return not_seen(
            "allocations",
            "not counted (the worker is not the twinbench executable)",
        );
    }
    let n = c.allocations() + c.free;
    let says = if n == 0 {
        format!("none in {steps} steps")
    } else {
        let parts: Vec<String> = [
            ("malloc", c.malloc),
            ("calloc", c.calloc),
            ("realloc", c.realloc),
            ("aligned_alloc", c.aligned_alloc),
            ("free", c.free),
        ]
        .iter()
        .filter(|(_, k)| *k > 0)
        .map(|(f, k)| format!("{f} ×{k}"))
        .collect();
        format!("{} in {steps} steps", parts.join(", "))
    };
    item("allocations", n == 0, says)
}

/// What a system call is, for the reader.
fn kind(name: &str) -> &'static str {
    match name {
        "nanosleep" | "clock_nanosleep" | "select" | "pselect6" | "poll" | "ppoll"
        | "epoll_wait" | "epoll_pwait" | "pause" | "sched_yield" => "a sleep or wait",
        "read" | "write" | "pread64" | "pwrite64" | "readv" | "writev" | "openat" | "open"
        | "close" | "lseek" | "fsync" | "fdatasync" | "creat" | "unlink" | "unlinkat"
        | "newfstatat" | "fstat" | "stat" | "statx" | "ftruncate" | "rename" | "renameat" => {
            "file or terminal I/O"
        }
        "mmap" | "munmap" | "brk" | "mprotect" | "mremap" | "madvise" => "memory",
        "futex" => "a contended lock",
        "clock_gettime" | "gettimeofday" | "time" => "the clock (not served by the vDSO here)",
        "clone" | "clone3" | "fork" | "vfork" | "execve" | "execveat" => {
            "a new thread or process (refused)"
        }
        _ => "",
    }
}

fn syscalls(c: &Counts, seen: bool, steps: u64) -> Item {
    if !seen {
        return not_seen("system calls", "not counted (no trap on this system)");
    }
    if c.syscalls.is_empty() {
        return item("system calls", true, format!("none in {steps} steps"));
    }
    let parts: Vec<String> = c
        .syscalls
        .iter()
        .map(|s| match kind(&s.name) {
            "" => format!("{} ×{}", s.name, s.calls),
            k => format!("{} ×{} ({k})", s.name, s.calls),
        })
        .collect();
    item(
        "system calls",
        false,
        format!("{} in {steps} steps", parts.join(", ")),
    )
}

fn locks(c: &Counts, allocations_seen: bool, syscalls_seen: bool, steps: u64) -> Item {
    let futex = c
        .syscalls
        .iter()
        .find(|s| s.name == "futex")
        .map_or(0, |s| s.calls);
    if !allocations_seen && !syscalls_seen {
        return not_seen("locks", "not counted");
    }
    let n = c.locks + futex;
    let says = if n == 0 {
        format!("none seen in {steps} steps (pthread locks and contended futexes; an uncontended lock of the FMU's own making is not seen)")
    } else {
        format!(
            "pthread locks ×{}, futex calls ×{futex} in {steps} steps",
            c.locks
        )
    };
    item("locks", n == 0, says)
}

fn micro(s: f64) -> String {
    format!("{:.1} µs", s * 1e6)
}

fn time(t: &TimeStats, noise: &TimeStats, step: f64, budget: Option<f64>) -> Item {
    let share = t.max / step * 100.0;
    let mut says = format!(
        "median {}, p99.9 {}, p99.99 {}, max {} ({share:.1} % of the {} cycle); the clock and the machine alone: median {}, max {}",
        micro(t.median),
        micro(t.p99_9),
        micro(t.p99_99),
        micro(t.max),
        micro(step),
        micro(noise.median),
        micro(noise.max),
    );
    match budget {
        None => Item {
            name: "step time".into(),
            verdict: Verdict::Measured,
            says,
        },
        Some(b) => {
            says.push_str(&format!("; budget {}", micro(b)));
            item("step time", t.max <= b, says)
        }
    }
}

/// Whether every judged item is clean.
pub fn clean(items: &[Item]) -> bool {
    items.iter().all(|i| i.verdict.passes())
}

/// The items as text lines.
pub fn lines(items: &[Item]) -> Vec<String> {
    items
        .iter()
        .map(|i| {
            let v = match i.verdict {
                Verdict::Clean => "clean",
                Verdict::Fails => "FAILS",
                Verdict::NotSeen => "NOT SEEN",
                Verdict::Measured => "measured",
            };
            format!("  {:<13} {:<9} {}", i.name, v, i.says)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::realtime::SyscallCount;

    fn measured(counts: Counts) -> Measurement {
        Measurement {
            passes: 1,
            counts,
            allocations_seen: true,
            syscalls_seen: true,
            step_time: TimeStats {
                steps: 100,
                mean: 2e-6,
                median: 2e-6,
                p99_9: 5e-6,
                p99_99: 6e-6,
                max: 8e-6,
            },
            ..Default::default()
        }
    }

    #[test]
    fn a_clean_step_is_clean_and_each_fault_is_named() {
        let m = measured(Counts::default());
        let items = judge(&m, 1e-3, None, None);
        assert!(clean(&items), "{items:?}");
        let bad = measured(Counts {
            malloc: 100,
            free: 100,
            syscalls: vec![
                SyscallCount {
                    name: "write".into(),
                    number: 1,
                    calls: 100,
                },
                SyscallCount {
                    name: "clock_nanosleep".into(),
                    number: 230,
                    calls: 100,
                },
            ],
            ..Default::default()
        });
        let items = judge(&bad, 1e-3, None, None);
        assert!(!clean(&items));
        let by = |n: &str| items.iter().find(|i| i.name == n).unwrap();
        assert_eq!(by("allocations").verdict, Verdict::Fails);
        assert!(by("allocations").says.contains("malloc ×100, free ×100"));
        assert_eq!(by("system calls").verdict, Verdict::Fails);
        assert!(by("system calls")
            .says
            .contains("write ×100 (file or terminal I/O)"));
        assert!(by("system calls")
            .says
            .contains("clock_nanosleep ×100 (a sleep or wait)"));
        assert_eq!(by("locks").verdict, Verdict::Clean);
    }

    #[test]
    fn time_is_judged_only_against_a_budget_and_unseen_items_are_not_clean() {
        let m = measured(Counts::default());
        assert_eq!(judge(&m, 1e-3, None, None)[4].verdict, Verdict::Measured);
        assert_eq!(judge(&m, 1e-3, Some(1e-5), None)[4].verdict, Verdict::Clean);
        assert_eq!(judge(&m, 1e-3, Some(1e-6), None)[4].verdict, Verdict::Fails);
        let blind = Measurement {
            syscalls_seen: false,
            ..m
        };
        let items = judge(&blind, 1e-3, None, None);
        assert_eq!(items[1].verdict, Verdict::NotSeen);
        assert!(!clean(&items));
    }

    #[test]
    fn a_slow_path_of_more_than_three_times_the_mean_fails() {
        let m = measured(Counts::default());
        let ins = |max| Instructions {
            steps: 1000,
            mean: 1000.0,
            median: 990,
            max,
            max_at: 0.5,
            first: 1200,
            max_after_first: max,
            max_after_first_at: 0.5,
        };
        assert!(clean(&judge(&m, 1e-3, None, Some(&ins(2900)))));
        assert!(!clean(&judge(&m, 1e-3, None, Some(&ins(3100)))));
        // The first step alone above the limit: clean, and said.
        let first = Instructions {
            max: 9000,
            max_at: 0.0,
            first: 9000,
            max_after_first: 1100,
            ..ins(1100)
        };
        let items = judge(&m, 1e-3, None, Some(&first));
        assert!(clean(&items));
        assert!(items[5]
            .says
            .contains("the one exception is the first step (9000, 9.0 × the mean"));
        // Another step above it is not.
        let later = Instructions {
            max_after_first: 3500,
            ..first
        };
        assert!(!clean(&judge(&m, 1e-3, None, Some(&later))));
    }
}

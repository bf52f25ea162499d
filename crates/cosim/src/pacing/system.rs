//! What a paced run asks of the system (`SCHED_FIFO`, `mlockall`, a CPU of its own, the
//! timer slack), each attempt said, and given back after the run.

/// What a paced run asks of the system besides its schedule, for the thread that runs it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RealtimeRequest {
    /// `SCHED_FIFO` at this priority (1 to 99); None: the normal scheduler, not asked.
    pub fifo_priority: Option<i32>,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)`: no page fault or swap-in during the run.
    pub lock_memory: bool,
    /// A CPU of its own.
    pub cpu: CpuRequest,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CpuRequest {
    /// Not asked: the scheduler places the run.
    Any,
    /// The last CPU this process may use (the one least likely to take the system's
    /// interrupts and housekeeping, which go to CPU 0 first).
    Last,
    Cpu(usize),
}

/// One thing asked of the system, and whether it was obtained.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Attempt {
    /// What was asked, e.g. "SCHED_FIFO priority 80".
    pub asked: String,
    pub obtained: bool,
    /// Why not (the system's error and what it usually means).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refused: Option<String>,
    /// What the refusal means for the run.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub consequence: Option<&'static str>,
}

impl Attempt {
    fn obtained(asked: String) -> Attempt {
        Attempt {
            asked,
            obtained: true,
            refused: None,
            consequence: None,
        }
    }

    fn refused(asked: String, why: String, consequence: &'static str) -> Attempt {
        Attempt {
            asked,
            obtained: false,
            refused: Some(why),
            consequence: Some(consequence),
        }
    }

    /// One line for stderr: what was asked and got, or what failed, why and what it means.
    pub fn line(&self) -> String {
        match (&self.refused, self.consequence) {
            (Some(why), Some(means)) => {
                format!("realtime: {} refused: {why}; {means}", self.asked)
            }
            _ => format!("realtime: {} obtained", self.asked),
        }
    }
}

/// What [`prepare`] changed, to be undone by [`Prepared::restore`] after the run (the
/// results are then written at normal priority, on any CPU, without locked memory).
pub struct Prepared {
    pub attempts: Vec<Attempt>,
    policy: Option<(libc::c_int, libc::sched_param)>,
    affinity: Option<libc::cpu_set_t>,
    locked: bool,
    timer_slack: Option<libc::c_ulong>,
}

const FIFO_MEANS: &str =
    "the run is paced at normal priority: deadlines may be missed by scheduler latency";
const LOCK_MEANS: &str =
    "pages may be faulted in during the run: deadlines may be missed by paging latency";
const CPU_MEANS: &str =
    "the run shares its CPUs and may migrate: deadlines may be missed by scheduler latency";

/// The last error's text with its number, e.g. "Operation not permitted (os error 1)".
fn os_error() -> (std::io::Error, Option<i32>) {
    let e = std::io::Error::last_os_error();
    let code = e.raw_os_error();
    (e, code)
}

/// The calling thread's CPUs.
fn affinity() -> Option<libc::cpu_set_t> {
    // SAFETY: a zeroed cpu_set_t is a valid empty set; the size passed is its own.
    unsafe {
        let mut set: libc::cpu_set_t = std::mem::zeroed();
        let r = libc::sched_getaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &mut set);
        (r == 0).then_some(set)
    }
}

fn cpus_of(set: &libc::cpu_set_t) -> Vec<usize> {
    // SAFETY: CPU_ISSET reads the set within CPU_SETSIZE.
    (0..libc::CPU_SETSIZE as usize)
        .filter(|&c| unsafe { libc::CPU_ISSET(c, set) })
        .collect()
}

/// A list of CPUs in words: `0-3`, `0,2`.
pub(super) fn cpu_list(cpus: &[usize]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut k = 0;
    while k < cpus.len() {
        let mut j = k;
        while j + 1 < cpus.len() && cpus[j + 1] == cpus[j] + 1 {
            j += 1;
        }
        parts.push(match j > k {
            true => format!("{}-{}", cpus[k], cpus[j]),
            false => cpus[k].to_string(),
        });
        k = j + 1;
    }
    parts.join(",")
}

/// The capability to lock memory beyond RLIMIT_MEMLOCK (linux/capability.h; the libc
/// crate does not define it).
const CAP_IPC_LOCK: u32 = 14;

/// Whether this process may lock more memory than RLIMIT_MEMLOCK (CAP_IPC_LOCK in its
/// effective set), and that limit in bytes (None: unlimited).
fn memlock_allowance() -> (bool, Option<u64>) {
    let cap_ipc_lock = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            let hex = s.lines().find_map(|l| l.strip_prefix("CapEff:"))?.trim();
            u64::from_str_radix(hex, 16).ok()
        })
        .is_some_and(|caps| caps & (1 << CAP_IPC_LOCK) != 0);
    let mut lim = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: a valid rlimit to write.
    let r = unsafe { libc::getrlimit(libc::RLIMIT_MEMLOCK, &mut lim) };
    let limit = match r == 0 && lim.rlim_cur != libc::RLIM_INFINITY {
        true => Some(lim.rlim_cur),
        false => None,
    };
    (cap_ipc_lock, limit)
}

/// Ask the system for what `request` names, for the calling thread (the scheduling policy
/// and the CPU are per thread on Linux; the memory lock is the process's). Each is tried;
/// what is refused is said in its [`Attempt`], never dropped in silence. Processes started
/// from this thread afterwards (isolated FMU workers) inherit its policy and CPU, not the
/// memory lock.
pub fn prepare(request: &RealtimeRequest) -> Prepared {
    let mut prepared = Prepared {
        attempts: Vec::new(),
        policy: None,
        affinity: None,
        locked: false,
        timer_slack: None,
    };
    // Always: a normal thread's sleeps may end up to its timer slack (50 µs by default)
    // late, so that the kernel can batch wake-ups; a paced run wants its deadline. (A
    // SCHED_FIFO thread has no slack; this matters when that is refused or not asked.)
    prepared.ask_timer_slack();
    if request.lock_memory {
        prepared.ask_memory_lock();
    }
    if let Some(priority) = request.fifo_priority {
        prepared.ask_fifo(priority);
    }
    prepared.ask_cpu(request.cpu);
    prepared
}

impl Prepared {
    /// A timer slack of 1 ns.
    fn ask_timer_slack(&mut self) {
        let asked = "timer slack 1 ns (prctl PR_SET_TIMERSLACK)".to_string();
        // SAFETY: prctl with integer arguments only.
        let old = unsafe { libc::prctl(libc::PR_GET_TIMERSLACK, 0, 0, 0, 0) };
        let r = unsafe { libc::prctl(libc::PR_SET_TIMERSLACK, 1 as libc::c_ulong, 0, 0, 0) };
        let means = "sleeps may end up to 50 µs late: deadlines may be missed by timer slack";
        if self.record(r, asked, "prctl", means) {
            self.timer_slack = (old > 0).then_some(old as libc::c_ulong);
        }
    }

    /// The outcome of a call asked for (`r`, its return: 0 when it was granted, else the
    /// error in errno), recorded; whether it was granted.
    fn record(&mut self, r: libc::c_int, asked: String, call: &str, means: &'static str) -> bool {
        if r == 0 {
            self.attempts.push(Attempt::obtained(asked));
            return true;
        }
        let (e, _) = os_error();
        let why = format!("{call}: {e}");
        self.attempts.push(Attempt::refused(asked, why, means));
        false
    }

    /// Every page locked, now and later (unless a limit would make later allocations fail).
    fn ask_memory_lock(&mut self) {
        let asked = "mlockall(MCL_CURRENT|MCL_FUTURE)".to_string();
        let (capable, limit) = memlock_allowance();
        match (capable, limit) {
            // Under a limit, locking future pages too would turn the run's later
            // allocations (the recording growing) into failures once it is reached.
            (false, Some(limit)) => self.attempts.push(Attempt::refused(
                asked,
                format!(
                    "not attempted: RLIMIT_MEMLOCK is {} KiB (`ulimit -l`) and the process lacks CAP_IPC_LOCK; locking its future pages under that limit would make the run's later allocations fail (raise it: `ulimit -l unlimited`)",
                    limit / 1024
                ),
                LOCK_MEANS,
            )),
            _ => {
                // SAFETY: mlockall has no memory-safety preconditions.
                let r = unsafe { libc::mlockall(libc::MCL_CURRENT | libc::MCL_FUTURE) };
                if self.record(r, asked, "mlockall", LOCK_MEANS) {
                    self.locked = true;
                }
            }
        }
    }

    /// `SCHED_FIFO` at `priority`, the former policy kept to restore.
    fn ask_fifo(&mut self, priority: i32) {
        let asked = format!("SCHED_FIFO priority {priority}");
        // SAFETY: querying this thread's policy and parameters into a valid struct.
        let old = unsafe {
            let mut p: libc::sched_param = std::mem::zeroed();
            let policy = libc::sched_getscheduler(0);
            (policy >= 0 && libc::sched_getparam(0, &mut p) == 0).then_some((policy, p))
        };
        let param = libc::sched_param {
            sched_priority: priority,
        };
        // SAFETY: a valid sched_param; 0 is the calling thread.
        let r = unsafe { libc::sched_setscheduler(0, libc::SCHED_FIFO, &param) };
        match r {
            0 => {
                self.policy = old;
                self.attempts.push(Attempt::obtained(asked));
            }
            _ => {
                let (e, code) = os_error();
                let hint = match code {
                    Some(libc::EPERM) => {
                        " (needs CAP_SYS_NICE, or an RLIMIT_RTPRIO of at least the priority: `ulimit -r`; in a container, a real-time CPU budget too)"
                    }
                    Some(libc::EINVAL) => " (SCHED_FIFO priorities are 1 to 99)",
                    _ => "",
                };
                self.attempts.push(Attempt::refused(
                    asked,
                    format!("sched_setscheduler: {e}{hint}"),
                    FIFO_MEANS,
                ))
            }
        }
    }

    /// One CPU for the calling thread, the former set kept to restore.
    fn ask_cpu(&mut self, cpu_request: CpuRequest) {
        let allowed = affinity();
        let cpu = match (cpu_request, &allowed) {
            (CpuRequest::Any, _) => None,
            (CpuRequest::Cpu(c), _) => Some(Ok(c)),
            (CpuRequest::Last, Some(set)) => Some(cpus_of(set).last().copied().ok_or(())),
            (CpuRequest::Last, None) => Some(Err(())),
        };
        match cpu {
            None => {}
            Some(Err(())) => {
                let (e, _) = os_error();
                self.attempts.push(Attempt::refused(
                    "a CPU of its own (the last one)".to_string(),
                    format!("sched_getaffinity: {e}"),
                    CPU_MEANS,
                ));
            }
            Some(Ok(c)) => {
                let asked = format!("CPU {c} alone (sched_setaffinity)");
                let set_to = (c < libc::CPU_SETSIZE as usize).then(|| {
                    // SAFETY: a zeroed set is empty; `c` is within CPU_SETSIZE.
                    unsafe {
                        let mut set: libc::cpu_set_t = std::mem::zeroed();
                        libc::CPU_SET(c, &mut set);
                        libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set)
                    }
                });
                match set_to {
                    Some(0) => {
                        self.affinity = allowed;
                        self.attempts.push(Attempt::obtained(asked));
                    }
                    _ => {
                        let (e, code) = os_error();
                        let may = allowed.as_ref().map(|s| cpu_list(&cpus_of(s)));
                        let why = match (set_to, code, may) {
                            (None, _, _) => format!("CPU {c} is beyond the system's CPU set size"),
                            (_, Some(libc::EINVAL), Some(may)) => format!(
                                "sched_setaffinity: {e} (CPU {c} is not one this process may use: {may})"
                            ),
                            _ => format!("sched_setaffinity: {e}"),
                        };
                        self.attempts.push(Attempt::refused(asked, why, CPU_MEANS));
                    }
                }
            }
        }
    }
}

impl Prepared {
    /// Undo what was obtained: the thread's former policy and CPUs, the memory unlocked.
    pub fn restore(self) {
        // SAFETY: setting back values read from the system for this thread; munlockall
        // has no preconditions.
        unsafe {
            if let Some((policy, param)) = self.policy {
                libc::sched_setscheduler(0, policy, &param);
            }
            if let Some(set) = self.affinity {
                libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
            }
            if self.locked {
                libc::munlockall();
            }
            if let Some(slack) = self.timer_slack {
                libc::prctl(libc::PR_SET_TIMERSLACK, slack, 0, 0, 0);
            }
        }
    }
}

//! The errors the tests expect, each checked by its variant and the fields that say which
//! one it is (the call, its status, the instance, the time): one line in a test.

use tb_cosim::SystemError;
use tb_fmi::fmi2::fmi2Status;
use tb_fmi::{CallStatus, FmiFunction, FmuError, Function};

// tb-cosim's tests check a refused system the same way: one file for both.
#[path = "../../crates/cosim/tests/support/kinds.rs"]
mod system;
// Each test binary uses some of them.
#[allow(unused_imports)]
pub use system::{algebraic_loop, invalid};

/// An FMI 2.0 call that returned `status` (the FMU's log says why).
pub fn refused(e: &FmuError, function: Function, status: fmi2Status) -> bool {
    matches!(
        e,
        FmuError::Call {
            function: FmiFunction::Fmi2(f),
            status: CallStatus::Fmi2(s),
            ..
        } if *f == function && *s == status
    )
}

/// An FMI 2.0 call of `instance` that returned `status` at `time`.
pub fn refused_at(
    e: &FmuError,
    instance: &str,
    function: Function,
    status: fmi2Status,
    time: f64,
) -> bool {
    matches!(
        e,
        FmuError::Call {
            instance: i,
            function: FmiFunction::Fmi2(f),
            status: CallStatus::Fmi2(s),
            time: t,
            ..
        } if i == instance && *f == function && *s == status && *t == time
    )
}

/// A run stopped by an FMI 2.0 call of `instance` that returned `status` at `time`.
pub fn stopped_by(
    e: &SystemError,
    instance: &str,
    function: Function,
    status: fmi2Status,
    time: f64,
) -> bool {
    matches!(e, SystemError::Fmu(call) if refused_at(call, instance, function, status, time))
}

/// A run stopped by `instance`'s isolated worker (it crashed, hung or broke the protocol)
/// in `function` at `time`.
pub fn worker_failed(e: &SystemError, instance: &str, function: &str, time: f64) -> bool {
    matches!(
        e,
        SystemError::Fmu(FmuError::Isolated { instance: i, function: f, time: t, .. })
            if i == instance && f == function && *t == time
    )
}

/// An FMI 3.0 call of `instance` that returned `status` (3: fmi3Error) at `time`.
pub fn refused3(e: &FmuError, instance: &str, function: &str, status: i32, time: f64) -> bool {
    matches!(
        e,
        FmuError::Call {
            instance: i,
            function: FmiFunction::Fmi3(f),
            status: CallStatus::Fmi3(s),
            time: t,
            ..
        } if i == instance && f == function && *s == status && *t == time
    )
}

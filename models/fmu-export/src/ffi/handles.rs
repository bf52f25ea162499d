//! The instance handles given to the host: never the instance's own address, but the
//! address of a slot in a static table that holds it. A handle therefore stays valid memory
//! after its instance is freed, so that a hostile or broken host's double free, call after
//! free or made-up pointer is found and refused (fmi2Error/fmi3Error, logged through the
//! freed instance's logger where there was one) instead of freeing twice, reading freed
//! memory or following a stray pointer.
//!
//! Finding an instance is a range check and one atomic load: no lock, no allocation (the
//! entry points are meant for real-time targets). Slots are handed out round-robin, so a
//! handle freed long ago names another instance only after [`SLOTS`] more instantiations.

use std::ffi::{c_char, c_void, CString};
use std::sync::atomic::{AtomicPtr, AtomicU8, AtomicUsize, Ordering};

/// The most instances alive at once in one process (per model library).
pub const SLOTS: usize = 4096;

/// The logger a slot keeps for calls after its instance is freed.
#[derive(Clone, Copy)]
pub(crate) enum SlotLogger {
    None,
    /// FMI 2.0's `fmi2CallbackLogger` and its environment.
    Fmi2(crate::fmi2::fmi2CallbackLogger, *mut c_void),
    /// FMI 3.0's `fmi3LogMessageCallback` and its environment.
    Fmi3(crate::ffi3::types::fmi3LogMessageCallback, *mut c_void),
}

/// 32 bytes, aligned to 32: a handle is checked with one subtraction, one comparison and
/// one bit test, and the slot is the handle itself.
#[repr(C, align(32))]
struct Slot {
    /// The instance (a `Box<Instance<M>>`), or null.
    instance: AtomicPtr<c_void>,
    /// 0 never used, 1 in use, 2 freed.
    state: AtomicU8,
    /// The logger kept: 0 none, 1 FMI 2.0, 2 FMI 3.0, with its function and environment.
    log_kind: AtomicU8,
    log_fn: AtomicUsize,
    log_env: AtomicPtr<c_void>,
}

const FREE: u8 = 0;
const IN_USE: u8 = 1;
const FREED: u8 = 2;

#[allow(clippy::declare_interior_mutable_const)]
const EMPTY: Slot = Slot {
    instance: AtomicPtr::new(std::ptr::null_mut()),
    state: AtomicU8::new(FREE),
    log_kind: AtomicU8::new(0),
    log_fn: AtomicUsize::new(0),
    log_env: AtomicPtr::new(std::ptr::null_mut()),
};

static TABLE: [Slot; SLOTS] = [EMPTY; SLOTS];
static NEXT: AtomicUsize = AtomicUsize::new(0);

/// Why a handle names no instance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stale {
    /// Not a handle this library gave out (a made-up or foreign pointer).
    Foreign,
    /// Its instance was freed (fmi2FreeInstance/fmi3FreeInstance).
    Freed,
}

const _: () = assert!(std::mem::size_of::<Slot>() == 32);

/// The slot a handle is the address of, if any.
#[inline(always)]
fn slot_of(handle: *mut c_void) -> Option<&'static Slot> {
    let base = TABLE.as_ptr() as usize;
    let at = (handle as usize).wrapping_sub(base);
    if at < SLOTS * 32 && at & 31 == 0 {
        // SAFETY: inside the table and at a slot's start: the slot itself, static.
        Some(unsafe { &*(handle as *const Slot) })
    } else {
        None
    }
}

/// A handle for `instance` (a `Box` turned into a raw pointer), with the logger to keep;
/// `None` when every slot is in use.
pub(crate) fn register(instance: *mut c_void, logger: SlotLogger) -> Option<*mut c_void> {
    let start = NEXT.fetch_add(1, Ordering::Relaxed);
    for k in 0..SLOTS {
        let slot = &TABLE[(start + k) % SLOTS];
        let s = slot.state.load(Ordering::Relaxed);
        if s != IN_USE
            && slot
                .state
                .compare_exchange(s, IN_USE, Ordering::AcqRel, Ordering::Relaxed)
                .is_ok()
        {
            let (kind, f, env) = match logger {
                SlotLogger::None => (0, 0, std::ptr::null_mut()),
                SlotLogger::Fmi2(f, env) => (1, f as usize, env),
                SlotLogger::Fmi3(f, env) => (2, f as usize, env),
            };
            slot.log_kind.store(kind, Ordering::Relaxed);
            slot.log_fn.store(f, Ordering::Relaxed);
            slot.log_env.store(env, Ordering::Relaxed);
            slot.instance.store(instance, Ordering::Release);
            NEXT.store((start + k + 1) % SLOTS, Ordering::Relaxed);
            return Some(slot as *const Slot as *mut c_void);
        }
    }
    None
}

/// The instance behind `handle`.
#[inline(always)]
pub(crate) fn resolve(handle: *mut c_void) -> Result<*mut c_void, Stale> {
    let Some(slot) = slot_of(handle) else {
        return Err(Stale::Foreign);
    };
    let p = slot.instance.load(Ordering::Acquire);
    if p.is_null() {
        return Err(if slot.state.load(Ordering::Relaxed) == FREED {
            Stale::Freed
        } else {
            Stale::Foreign
        });
    }
    Ok(p)
}

/// Takes the instance out of its slot (to free it): the handle names no instance after.
pub(crate) fn release(handle: *mut c_void) -> Result<*mut c_void, Stale> {
    let Some(slot) = slot_of(handle) else {
        return Err(Stale::Foreign);
    };
    let p = slot.instance.swap(std::ptr::null_mut(), Ordering::AcqRel);
    if p.is_null() {
        return Err(if slot.state.load(Ordering::Relaxed) == FREED {
            Stale::Freed
        } else {
            Stale::Foreign
        });
    }
    slot.state.store(FREED, Ordering::Release);
    Ok(p)
}

/// Says through the logger a freed instance's slot kept why `function` was refused.
#[cold]
pub(crate) fn log_stale(handle: *mut c_void, function: &str, why: Stale) {
    let Some(slot) = slot_of(handle) else {
        // A made-up pointer has no logger to tell.
        return;
    };
    let text = match why {
        Stale::Freed => format!(
            "{function}: the instance was freed (FreeInstance); no call may follow it, and this one is refused"
        ),
        Stale::Foreign => format!("{function}: not an instance of this FMU; refused"),
    };
    let msg = CString::new(text.replace('%', "%%")).unwrap_or_default();
    let plain = CString::new(text).unwrap_or_default();
    let env = slot.log_env.load(Ordering::Relaxed);
    let f = slot.log_fn.load(Ordering::Relaxed);
    // SAFETY: the function pointer was stored from a logger of the kind recorded beside it.
    unsafe {
        match slot.log_kind.load(Ordering::Relaxed) {
            1 if f != 0 => {
                let cb: crate::fmi2::fmi2CallbackLogger = std::mem::transmute(f);
                cb(
                    env,
                    c"(freed instance)".as_ptr(),
                    crate::fmi2::fmi2Status::ERROR,
                    c"logStatusError".as_ptr() as *const c_char,
                    msg.as_ptr(),
                );
            }
            2 if f != 0 => {
                let cb: crate::ffi3::types::fmi3LogMessageCallback = std::mem::transmute(f);
                cb(
                    env,
                    crate::ffi3::types::FMI3_ERROR,
                    c"logStatusError".as_ptr(),
                    plain.as_ptr(),
                );
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_handle_is_refused_after_its_instance_is_freed_and_a_made_up_one_always() {
        let thing = Box::into_raw(Box::new(7u64)) as *mut c_void;
        let h = register(thing, SlotLogger::None).unwrap();
        assert_ne!(h, thing, "the handle is the slot, not the instance");
        assert_eq!(resolve(h), Ok(thing));
        assert_eq!(release(h), Ok(thing));
        // SAFETY: the box made above, taken back once.
        drop(unsafe { Box::from_raw(thing as *mut u64) });
        assert_eq!(resolve(h), Err(Stale::Freed));
        assert_eq!(release(h), Err(Stale::Freed), "a double free");
        let made_up = 0x1234_5678usize as *mut c_void;
        assert_eq!(resolve(made_up), Err(Stale::Foreign));
        // Inside the table but not at a slot's start.
        assert_eq!(
            resolve((h as usize + 1) as *mut c_void),
            Err(Stale::Foreign)
        );
        log_stale(made_up, "fmi2DoStep", Stale::Foreign);
    }
}

//! The FMI 2.0 Co-Simulation C entry points, generic over the model. [`export_fmu!`]
//! instantiates them as `#[no_mangle]` symbols in a model's `cdylib`.
//!
//! Every entry point checks its pointers, runs inside `catch_unwind` (a panicking model
//! returns fmi2Error, logs the panic and poisons the instance) and never unwinds into C.
//!
//! - this module: the guard around every call, the host's logger, the resource URI;
//! - [`entry`]: one generic function per `fmi2*` entry point;
//! - `export`: the [`export_fmu!`](crate::export_fmu) macro that instantiates them as C symbols.
#![allow(clippy::missing_safety_doc, clippy::too_many_arguments)]

use crate::fmi2::*;
use crate::model::Model;
pub use crate::resources::resource_dir_from_uri;
use crate::runtime::{Logger, Runtime};
use std::ffi::{c_void, CStr, CString};
use std::os::raw::c_char;
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Forwards log messages to the host's `fmi2CallbackLogger`.
pub(crate) struct CLogger {
    callback: Option<fmi2CallbackLogger>,
    env: fmi2ComponentEnvironment,
    instance_name: CString,
}

// The host's environment pointer is opaque to us and only handed back to the host.
unsafe impl Send for CLogger {}

/// `message` goes through the host's printf: `%` must be doubled, NULs cannot pass.
fn c_message(message: &str) -> CString {
    CString::new(message.replace('%', "%%").replace('\0', "\\0")).unwrap_or_default()
}

impl Logger for CLogger {
    fn log(&self, status: fmi2Status, category: &str, message: &str) {
        if let Some(cb) = self.callback {
            let cat = CString::new(category).unwrap_or_default();
            let msg = c_message(message);
            unsafe {
                cb(
                    self.env,
                    self.instance_name.as_ptr(),
                    status,
                    cat.as_ptr(),
                    msg.as_ptr(),
                )
            };
        }
    }
}

/// The component behind a handle given to the host ([`handles`]).
pub struct Instance<M: Model> {
    pub runtime: Runtime<M>,
    /// The strings of the last fmi2GetString: the host may read them until the next call.
    pub strings: Vec<CString>,
    /// The FMU states this instance gave out and the host has not freed: a state pointer
    /// the host passes is used only if it is one of them (a foreign or freed one is
    /// refused, never followed).
    pub states: Vec<*mut crate::runtime::Snapshot<M>>,
}

impl<M: Model> Instance<M> {
    pub fn new(runtime: Runtime<M>) -> Self {
        Instance {
            runtime,
            strings: Vec::new(),
            states: Vec::new(),
        }
    }

    /// Whether `state` is one this instance gave out and that is not freed.
    pub fn owns(&self, state: *mut c_void) -> bool {
        self.states.iter().any(|&s| s as *mut c_void == state)
    }
}

impl<M: Model> Drop for Instance<M> {
    fn drop(&mut self) {
        // States the host did not free go with their instance.
        for s in self.states.drain(..) {
            // SAFETY: each was made by Box::into_raw here and is listed once.
            drop(unsafe { Box::from_raw(s) });
        }
    }
}

/// The handle for a new instance (None: [`handles::SLOTS`] instances are alive).
pub(crate) fn handle_for<M: Model>(
    instance: Instance<M>,
    logger: handles::SlotLogger,
) -> *mut c_void {
    let p = Box::into_raw(Box::new(instance));
    match handles::register(p as *mut c_void, logger) {
        Some(h) => h,
        None => {
            // SAFETY: the box made above, never handed out.
            let i = unsafe { Box::from_raw(p) };
            i.runtime.error(&format!(
                "fmi2Instantiate: {} instances of this FMU are alive in this process, the most it serves",
                handles::SLOTS
            ));
            std::ptr::null_mut()
        }
    }
}

/// The instance behind the handle `c`; a stale or made-up handle is logged (where its slot
/// kept a logger) and refused.
#[inline(always)]
unsafe fn instance_of<'a, M: Model>(
    c: fmi2Component,
    function: &str,
) -> Result<&'a mut Instance<M>, fmi2Status> {
    match handles::resolve(c) {
        Ok(p) => Ok(&mut *(p as *mut Instance<M>)),
        Err(why) => {
            handles::log_stale(c, function, why);
            Err(fmi2Status::ERROR)
        }
    }
}

/// An instantiation refused: `message` logged as an error of `function`; no instance.
pub(crate) fn refused<T>(logger: &impl Logger, function: &str, message: &str) -> *mut T {
    logger.log(
        fmi2Status::ERROR,
        "logStatusError",
        &format!("{function}: {message}"),
    );
    std::ptr::null_mut()
}

/// Why an instantiation is refused before an instance exists.
#[derive(Debug, thiserror::Error)]
pub(crate) enum Refusal {
    /// The fitted twin's start values among the resources could not be read.
    #[error(transparent)]
    Fitted(#[from] crate::fitted::FittedError),
    /// The host's GUID or instantiation token is neither the description's nor the
    /// fitted twin's.
    #[error("{what} mismatch: the host passed {given}, this binary of '{model}' is {expected} (modelDescription.xml and binary differ)")]
    Mismatch {
        what: &'static str,
        given: String,
        model: &'static str,
        expected: String,
    },
    /// The host passed no GUID or token.
    #[error("{argument} is NULL")]
    Null { argument: &'static str },
}

/// The fitted twin's start values among the resources (None: the description's own), once
/// the identity the host passed (`given`: a `what`, GUID or instantiation token, in the
/// argument `argument`) is the description's `expected` or the fitted twin's.
pub(crate) fn fitted_starts<M: Model>(
    resource_dir: Option<&std::path::Path>,
    given: Option<std::borrow::Cow<'_, str>>,
    expected: &str,
    (what, argument): (&'static str, &'static str),
) -> Result<Option<crate::fitted::FittedStarts>, Refusal> {
    use crate::fitted::FittedStarts;
    let fitted = FittedStarts::of_instance::<M::Vars>(resource_dir)?;
    match given {
        Some(g) if FittedStarts::accepts(fitted.as_ref(), &g, expected) => Ok(fitted),
        Some(g) => Err(Refusal::Mismatch {
            what,
            given: g.into_owned(),
            model: M::INFO.name,
            expected: expected.to_string(),
        }),
        None => Err(Refusal::Null { argument }),
    }
}

/// `n` values at `p` (its arrays checked; none when `n` is 0, whatever `p` is).
#[inline(always)]
pub(crate) unsafe fn values_at<'a, T>(p: *const T, n: usize) -> &'a [T] {
    if n == 0 {
        &[]
    } else {
        std::slice::from_raw_parts(p, n)
    }
}

/// As [`values_at`], to be written.
#[inline(always)]
pub(crate) unsafe fn values_at_mut<'a, T>(p: *mut T, n: usize) -> &'a mut [T] {
    if n == 0 {
        &mut []
    } else {
        std::slice::from_raw_parts_mut(p, n)
    }
}

/// The message of a caught panic (for the log and the poisoned instance).
pub fn panic_text(payload: &(dyn std::any::Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "non-string panic payload".to_string()
    }
}

/// Run `f` on the whole instance behind `c` (runtime and string buffer), catching panics.
pub(crate) unsafe fn guarded_instance<M: Model>(
    c: fmi2Component,
    function: &str,
    f: impl FnOnce(&mut Instance<M>) -> fmi2Status,
) -> fmi2Status {
    let inst = match instance_of::<M>(c, function) {
        Ok(i) => i,
        Err(s) => return s,
    };
    match catch_unwind(AssertUnwindSafe(|| f(inst))) {
        Ok(s) => s,
        Err(payload) => {
            let text = panic_text(&*payload);
            catch_unwind(AssertUnwindSafe(|| inst.runtime.poison(function, &text)))
                .unwrap_or(fmi2Status::ERROR)
        }
    }
}

/// Run `f` on the instance behind `c`, catching panics.
#[inline]
pub(crate) unsafe fn guarded<M: Model>(
    c: fmi2Component,
    function: &str,
    f: impl FnOnce(&mut Runtime<M>) -> fmi2Status,
) -> fmi2Status {
    guarded_instance::<M>(c, function, |inst| f(&mut inst.runtime))
}

pub(crate) unsafe fn opt_str<'a>(p: *const c_char) -> Option<std::borrow::Cow<'a, str>> {
    (!p.is_null()).then(|| CStr::from_ptr(p).to_string_lossy())
}

pub mod entry;
mod export;
pub mod handles;

pub use entry::*;

#[cfg(test)]
mod tests {
    use super::resource_dir_from_uri;
    use std::path::Path;

    #[test]
    fn file_uris_name_local_files_only() {
        for (uri, path) in [
            ("file:///a/b%20c", "/a/b c"),
            ("file://localhost/a", "/a"),
            ("file:/a", "/a"),
        ] {
            assert_eq!(
                resource_dir_from_uri(uri).unwrap(),
                Path::new(path),
                "{uri}"
            );
        }
        // Red team N28: another host's file was read as a local path.
        let e = resource_dir_from_uri("file://server/etc/data").unwrap_err();
        assert!(
            matches!(&e, crate::resources::UriError::OtherHost { host, .. } if host == "server"),
            "{e}"
        );
        assert!(matches!(
            resource_dir_from_uri("http://x/y"),
            Err(crate::resources::UriError::NotAFile { .. })
        ));
    }
}

//! FMI 3.0's C types and status values that the entry points and the slot table share.

use std::ffi::{c_char, c_void};

#[allow(non_camel_case_types)]
pub type fmi3Instance = *mut c_void;
#[allow(non_camel_case_types)]
pub type fmi3Status = i32;
#[allow(non_camel_case_types)]
pub type fmi3FMUState = *mut c_void;
#[allow(non_camel_case_types)]
pub type fmi3ValueReference = u32;
/// `fmi3LogMessageCallback`: the message is plain text (no format string, unlike FMI 2.0).
#[allow(non_camel_case_types)]
pub type fmi3LogMessageCallback = unsafe extern "C" fn(
    env: *mut c_void,
    status: fmi3Status,
    category: *const c_char,
    message: *const c_char,
);

pub const FMI3_ERROR: fmi3Status = 3;

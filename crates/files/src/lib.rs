//! Files as twinbench reads them.
//!
//! [`paths`]: a path written in a system, study or lap file is relative to that file's
//! folder, whatever folder the command runs from; every resolved path is absolute and
//! printed without `.` or `a/..` steps.

pub mod paths;

pub use paths::{absolute, folder_of, normalize, relative_to, resolve};

//! Files as twinbench reads them.
//!
//! [`paths`]: a path written in a system, study or lap file is relative to that file's
//! folder, whatever folder the command runs from; every resolved path is absolute and
//! printed without `.` or `a/..` steps; a cluster worker holds a study's files in a mirror
//! of the coordinator's paths.
//!
//! [`input`]: an input file is read only when it is a regular file within the limit of
//! its kind (never a FIFO, a device or a file that grows without end).
//!
//! [`names`]: the names closest to a wrong one, for messages.
//!
//! [`shown`]: what a message may show of text twinbench did not write (cut, control
//! characters escaped).
//!
//! [`markup`]: text made safe for XML and HTML.

pub mod input;
pub mod markup;
pub mod names;
pub mod paths;
pub mod shown;

pub use input::Limit;
pub use paths::{absolute, folder_of, normalize, register_mirror, relative_to, resolve, unmirror};
pub use shown::{excerpt, number, shown};

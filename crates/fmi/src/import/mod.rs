//! The importer: FMI 2.0 and FMI 3.0 Co-Simulation FMUs from archive to running instance.
//!
//! - [`archive`]: archive checks (untrusted input), the unpack cache and the machine-wide
//!   store of unpacked FMUs with its stat index ([`store`]) and the manifests that every
//!   file is verified against before use ([`manifest`]); [`sandbox`]: the isolated worker's
//!   read-only store;
//! - [`description`]: what twinbench knows of an FMU, and the FMI 2.0 modelDescription.xml
//!   reader; [`description3`]: the FMI 3.0 reader; [`reader`]: what both share;
//! - [`library`] and [`library3`]: a loaded shared library with its functions resolved;
//! - [`instance`] and [`instance3`]: a safe handle on one FMU instance (the same calls for
//!   both versions);
//! - [`log`]: the log sink every backend's messages go to; [`FmuError`]: the errors.

pub mod archive;
pub mod description;
pub mod description3;
mod error;
pub mod instance;
pub mod instance3;
pub mod library;
pub mod library3;
pub mod log;
mod manifest;
pub(crate) mod reader;
pub mod sandbox;
mod store;

pub use error::FmuError;

/// The longest String (or Binary, in bytes) value read from an FMU: a value is copied into
/// every recorded row, so an FMU handing out 100 MB strings would exhaust memory.
pub const MAX_STRING_BYTES: usize = 1 << 20;

/// A String value read from an FMU, or an error naming the instance, the value reference
/// and the length when it is longer than [`MAX_STRING_BYTES`].
///
/// # Safety
/// `p` is NULL or a NUL-terminated string the FMU keeps valid during the call.
pub(crate) unsafe fn string_from_fmu(
    p: *const std::ffi::c_char,
    instance: &str,
    function: &str,
    vr: u32,
) -> Result<String, FmuError> {
    if p.is_null() {
        return Ok(String::new());
    }
    let bytes = std::ffi::CStr::from_ptr(p).to_bytes();
    too_long(bytes.len(), instance, function, vr)?;
    Ok(String::from_utf8_lossy(bytes).into_owned())
}

/// A String or Binary value of `len` bytes is refused when longer than [`MAX_STRING_BYTES`].
pub(crate) fn too_long(
    len: usize,
    instance: &str,
    function: &str,
    vr: u32,
) -> Result<(), FmuError> {
    if len > MAX_STRING_BYTES {
        return Err(FmuError::Instantiate {
            instance: instance.to_string(),
            message: format!(
                "{function}: value reference {vr} holds {len} bytes, more than the {} MiB twinbench exchanges and records",
                MAX_STRING_BYTES >> 20
            ),
        });
    }
    Ok(())
}

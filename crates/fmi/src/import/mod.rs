//! The importer: FMI 2.0 and FMI 3.0 Co-Simulation FMUs, and FMI 2.0 Model Exchange FMUs,
//! from archive to running instance.
//!
//! - [`archive`]: archive checks (untrusted input), the unpack cache and the machine-wide
//!   store of unpacked FMUs with its stat index (`store.rs`) and the manifests that every
//!   file is verified against before use (`manifest.rs`); [`sandbox`]: the isolated worker's
//!   read-only store;
//! - [`model`]: what twinbench knows of an FMU (the model description's types);
//!   [`description`]: the modelDescription.xml reader, which hands the text to the one of
//!   its version, [`description2`] (FMI 2.0) or [`description3`] (FMI 3.0); `reader.rs`: what
//!   both share;
//! - [`library`] and [`library3`]: a loaded shared library with its functions resolved;
//! - [`instance`] and [`instance3`]: a safe handle on one FMU instance (the same calls for
//!   both versions);
//! - [`model_exchange`]: an FMI 2.0 Model Exchange instance integrated with CVODE, with
//!   the calls of a Co-Simulation one;
//! - [`log`]: the log sink every backend's messages go to; [`FmuError`]: the errors.

pub mod archive;
pub mod description;
pub mod description2;
pub mod description3;
mod error;
pub mod instance;
pub mod instance3;
pub mod library;
pub mod library3;
pub mod log;
mod manifest;
pub mod model;
pub mod model_exchange;
pub(crate) mod reader;
pub mod sandbox;
mod slots3;
mod store;
pub mod unit_trait;

pub use error::{DescriptionError, FileCheckError, FmuError, FolderError, InterfaceError};
pub use unit_trait::{Experiment, FmuInstance};

/// Whether `path` is a shared library this process can load, read from its ELF header:
/// an x86-64 library, 64-bit, little-endian. The dynamic loader reports a library for
/// another machine as "No such file or directory" (N28); this says what it is.
pub(crate) fn check_elf(path: &std::path::Path) -> Result<(), FmuError> {
    use std::io::Read;
    let bad = |message: String| FmuError::Load {
        path: path.to_path_buf(),
        message,
    };
    let mut head = [0u8; 20];
    let n = std::fs::File::open(path)
        .and_then(|f| f.take(20).read(&mut head))
        .map_err(|e| bad(format!("cannot read: {e}")))?;
    if n < 20 || &head[..4] != b"\x7fELF" {
        return Err(bad("not an ELF shared library".into()));
    }
    let machine = u16::from_le_bytes([head[18], head[19]]);
    const EM_X86_64: u16 = 62;
    if head[4] != 2 || head[5] != 1 || machine != EM_X86_64 {
        let name = match machine {
            3 => "x86 (32-bit)",
            40 => "ARM (32-bit)",
            183 => "aarch64",
            243 => "RISC-V",
            62 => "x86-64 but not 64-bit little-endian",
            _ => "another machine",
        };
        return Err(bad(format!(
            "a library for {name} (ELF machine {machine}), not for this x86-64 machine: the FMU has no binary this host can run"
        )));
    }
    Ok(())
}

/// The FMU's shared library at `path`, checked by [`check_elf`] first and then opened (both
/// versions' libraries load this way).
pub(crate) fn open_library(path: &std::path::Path) -> Result<libloading::Library, FmuError> {
    check_elf(path)?;
    // SAFETY: loading runs the library's initialisers: that is what importing an FMU means;
    // a hostile one is run under `--isolate`.
    unsafe { libloading::Library::new(path) }.map_err(|e| FmuError::Load {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// What `fmi2GetVersion` or `fmi3GetVersion` returned, as text (`NULL` for a NULL pointer).
///
/// # Safety
/// `p` is NULL or a NUL-terminated string.
pub(crate) unsafe fn version_text(p: *const std::ffi::c_char) -> String {
    if p.is_null() {
        "NULL".to_string()
    } else {
        std::ffi::CStr::from_ptr(p).to_string_lossy().into_owned()
    }
}

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

#[cfg(test)]
mod tests {
    use super::FmuError;

    #[test]
    fn a_library_for_another_machine_is_named_as_such() {
        let dir = std::env::temp_dir().join(format!("tb-elf-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut head = vec![0u8; 64];
        head[..4].copy_from_slice(b"\x7fELF");
        head[4] = 2; // 64-bit
        head[5] = 1; // little-endian
        head[18..20].copy_from_slice(&183u16.to_le_bytes()); // aarch64
        let so = dir.join("arm.so");
        std::fs::write(&so, &head).unwrap();
        let e = super::check_elf(&so).unwrap_err();
        assert!(
            matches!(&e, FmuError::Load { path, .. } if *path == so),
            "{e}"
        );
        assert!(
            e.to_string()
                .contains("a library for aarch64 (ELF machine 183)"),
            "{e}"
        );
        std::fs::write(&so, b"not a library at all, just text").unwrap();
        let e = super::check_elf(&so).unwrap_err();
        assert!(
            matches!(&e, FmuError::Load { path, .. } if *path == so),
            "{e}"
        );
        assert!(e.to_string().contains("not an ELF shared library"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

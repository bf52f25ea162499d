//! The checks of an archive's entries and of its modelDescription.xml, before a byte is
//! written.

use super::*;
use crate::import::description;
use crate::import::model::{Interface, ModelDescription};
use crate::import::reader::sniff_fmi_version;
use crate::import::store::CdEntry;
use crate::FmuError;
use std::io::{Read, Seek};
use std::path::Path;

/// An archive that passed [`check_entries`], and its entry names.
pub type CheckedArchive<'a> = (zip::ZipArchive<std::io::Cursor<&'a [u8]>>, Vec<String>);

/// The checks every archive twinbench unpacks passes before a byte is written (an FMU, an
/// SSP package): a valid zip, entry names inside the archive (no `..`, no absolute paths),
/// no symbolic links, the entry count and the declared uncompressed size within `limits`.
/// Returns the open archive and its entry names.
pub fn check_entries<'a>(
    fmu: &Path,
    bytes: &'a [u8],
    limits: &Limits,
) -> Result<CheckedArchive<'a>, FmuError> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| arch(fmu, format!("not a valid zip archive: {e}")))?;
    let entries = check_entries_of(fmu, &mut zip, limits)?;
    Ok((zip, entries.into_iter().map(|e| e.name).collect()))
}

/// [`check_entries`] on an open archive, in memory or a file (then only its central
/// directory and local headers are read). Returns the central directory's entries.
pub(crate) fn check_entries_of<R: Read + Seek>(
    fmu: &Path,
    zip: &mut zip::ZipArchive<R>,
    limits: &Limits,
) -> Result<Vec<CdEntry>, FmuError> {
    if zip.len() > limits.max_entries {
        return Err(arch(
            fmu,
            format!(
                "{} entries, more than the limit of {} (zip bomb?)",
                zip.len(),
                limits.max_entries
            ),
        ));
    }
    let mut total: u64 = 0;
    let mut entries = Vec::with_capacity(zip.len());
    for i in 0..zip.len() {
        let f = zip
            .by_index_raw(i)
            .map_err(|e| arch(fmu, format!("entry {i}: {e}")))?;
        let name = f.name().to_string();
        if f.enclosed_name().is_none()
            || name.starts_with('/')
            || name.split(['/', '\\']).any(|c| c == "..")
        {
            return Err(arch(
                fmu,
                format!("entry '{name}' escapes the archive (absolute path or '..')"),
            ));
        }
        if f.unix_mode().is_some_and(|m| m & 0o170000 == 0o120000) {
            return Err(arch(fmu, format!("entry '{name}' is a symbolic link")));
        }
        total = total.saturating_add(f.size());
        if total > limits.max_total_bytes {
            return Err(arch(
                fmu,
                format!(
                    "uncompressed size exceeds the limit of {} bytes (zip bomb?)",
                    limits.max_total_bytes
                ),
            ));
        }
        entries.push(CdEntry {
            compressed: f.compressed_size(),
            size: f.size(),
            crc32: f.crc32(),
            name,
        });
    }
    Ok(entries)
}

/// Everything checked before a byte is written: entry names (no `..`, no absolute paths),
/// no symbolic links, size and count limits, a UTF-8 FMI 2.0 Co-Simulation
/// modelDescription.xml, and the linux64 binary it names.
pub fn check_archive(fmu: &Path, bytes: &[u8]) -> Result<(ModelDescription, String), FmuError> {
    check_archive_with(fmu, bytes, &Limits::default())
}

/// [`check_archive`] with other limits.
pub fn check_archive_with(
    fmu: &Path,
    bytes: &[u8],
    limits: &Limits,
) -> Result<(ModelDescription, String), FmuError> {
    check_archive_entries(fmu, bytes, limits, true).map(|(md, id, _)| (md, id))
}

/// [`check_archive_with`], also returning the central directory's entries; the binary for
/// this platform only when `binary_required`.
pub(crate) fn check_archive_entries(
    fmu: &Path,
    bytes: &[u8],
    limits: &Limits,
    binary_required: bool,
) -> Result<(ModelDescription, String, Vec<CdEntry>), FmuError> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| arch(fmu, format!("not a valid zip archive: {e}")))?;
    let entries = check_entries_of(fmu, &mut zip, limits)?;
    let xml = {
        let f = zip
            .by_name("modelDescription.xml")
            .map_err(|_| arch(fmu, "no modelDescription.xml at the archive's root"))?;
        read_description(fmu, f)?
    };
    let names: Vec<String> = entries.iter().map(|e| e.name.clone()).collect();
    let (md, id) = check_description(fmu, &xml, &names, binary_required)?;
    Ok((md, id, entries))
}

/// A modelDescription.xml's text: at most [`MAX_DESCRIPTION_BYTES`] (an error past it,
/// not a cut), UTF-8.
pub(crate) fn read_description(fmu: &Path, r: impl Read) -> Result<String, FmuError> {
    let mut raw = Vec::new();
    r.take(MAX_DESCRIPTION_BYTES + 1)
        .read_to_end(&mut raw)
        .map_err(|e| arch(fmu, format!("cannot read modelDescription.xml: {e}")))?;
    if raw.len() as u64 > MAX_DESCRIPTION_BYTES {
        return Err(arch(
            fmu,
            format!(
                "modelDescription.xml is larger than {} MiB (the limit against a hostile archive)",
                MAX_DESCRIPTION_BYTES >> 20
            ),
        ));
    }
    String::from_utf8(raw).map_err(|e| {
        arch(
            fmu,
            format!(
                "modelDescription.xml is not UTF-8 (byte {})",
                e.utf8_error().valid_up_to()
            ),
        )
    })
}

/// The description's checks: FMI 2.0 or 3.0, Co-Simulation, nothing unsupported, a
/// `modelIdentifier` that is a C identifier, and (when `binary_required`) its library among
/// the archive's `names`. Returns the description and the model identifier.
pub(crate) fn check_description(
    fmu: &Path,
    xml: &str,
    names: &[String],
    binary_required: bool,
) -> Result<(ModelDescription, String), FmuError> {
    let md = parse_description(fmu, xml)?;
    check_fmi_version(fmu, &md)?;
    let interface = runnable_interface(fmu, &md)?;
    let id = md
        .model_identifier(interface)
        .expect("the interface is declared")
        .to_string();
    check_model_identifier(fmu, &id)?;
    let so = library_entry(&md.fmi_version, &id);
    if binary_required && !names.contains(&so) {
        return Err(missing_library(fmu, &so, &id, names));
    }
    Ok((md, id))
}

/// The description read (an FMI 1.0 one named by its version when it does not read).
fn parse_description(fmu: &Path, xml: &str) -> Result<ModelDescription, FmuError> {
    description::parse(xml).map_err(|source| match sniff_fmi_version(xml) {
        // An FMI 1.0 description may not even parse as 2.0: name the version then.
        Some(v) if v != "2.0" && !v.starts_with("3.") => FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!("fmiVersion is \"{v}\"; twinbench runs FMI 2.0 and 3.0 FMUs"),
        },
        _ => FmuError::DescriptionParse {
            path: fmu.to_path_buf(),
            source: Box::new(source),
        },
    })
}

/// FMI 2.0 or 3.0.
fn check_fmi_version(fmu: &Path, md: &ModelDescription) -> Result<(), FmuError> {
    let fmi3 = md.fmi_version.starts_with("3.");
    if md.fmi_version != "2.0" && !fmi3 {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!(
                "fmiVersion is \"{}\"; twinbench runs FMI 2.0 and 3.0 FMUs",
                md.fmi_version
            ),
        });
    }
    Ok(())
}

/// The interface the FMU runs through by default, when twinbench can run it: Co-Simulation
/// or Model Exchange, and nothing the description lists as unsupported (clocks).
fn runnable_interface(fmu: &Path, md: &ModelDescription) -> Result<Interface, FmuError> {
    // Co-Simulation, or Model Exchange (integrated by twinbench with CVODE); not FMI 3.0's
    // Scheduled Execution.
    let interface = match md.default_interface() {
        Some(i) => i,
        None => {
            let scheduled = md.unsupported.iter().any(|u| u.starts_with("Scheduled"));
            return Err(FmuError::Description {
                path: fmu.to_path_buf(),
                message: match scheduled {
                    false => "neither a <CoSimulation> nor a <ModelExchange> element".into(),
                    true => "the FMU supports Scheduled Execution only; twinbench runs FMUs through Co-Simulation or Model Exchange".into(),
                },
            });
        }
    };
    if let Some(what) = md.unsupported.first() {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!(
                "the FMU needs {what}; twinbench runs FMI 3.0 Co-Simulation and Model Exchange without clocks"
            ),
        });
    }
    Ok(interface)
}

/// A `modelIdentifier` that is a C identifier.
fn check_model_identifier(fmu: &Path, id: &str) -> Result<(), FmuError> {
    // Used as a file name and a C symbol prefix: a path here would load a library from
    // outside the cache.
    if id.is_empty()
        || id.starts_with(|c: char| c.is_ascii_digit())
        || !id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    {
        return Err(FmuError::Description {
            path: fmu.to_path_buf(),
            message: format!(
                "modelIdentifier \"{id}\" is not a valid C identifier (letters, digits, '_')"
            ),
        });
    }
    Ok(())
}

/// The error of an archive without the library `so` that the `modelIdentifier` `id` names:
/// what its `names` hold instead.
fn missing_library(fmu: &Path, so: &str, id: &str, names: &[String]) -> FmuError {
    // Name the platforms the FMU has binaries for (a Windows- or macOS-only FMU is a
    // common mistake); a platform folder with no file in it has none.
    let mut platforms: Vec<&str> = names
        .iter()
        .filter_map(|n| n.strip_prefix("binaries/"))
        .filter_map(|n| n.split_once('/'))
        .filter(|(p, rest)| !p.is_empty() && !rest.is_empty() && !rest.ends_with('/'))
        .map(|(p, _)| p)
        .collect();
    platforms.sort();
    platforms.dedup();
    let has = if platforms.is_empty() {
        "no binaries at all".to_string()
    } else {
        format!("binaries for {}", platforms.join(", "))
    };
    let dir = &so[..=so.rfind('/').expect("a folder")];
    let mut here: Vec<&str> = names
        .iter()
        .filter_map(|n| n.strip_prefix(dir))
        .filter(|n| !n.is_empty() && !n.ends_with('/'))
        .collect();
    here.sort();
    let why = if !here.is_empty() {
        let shown: Vec<&str> = here.iter().take(5).copied().collect();
        format!(
            "{dir} holds {}{} but not the library its modelIdentifier \"{id}\" names",
            shown.join(", "),
            if here.len() > 5 { ", ..." } else { "" }
        )
    } else if names.iter().any(|n| n.starts_with(dir)) {
        format!("the folder {dir} is empty (the FMU has {has})")
    } else {
        format!("the FMU has no binary for this platform; it has {has}")
    };
    arch(fmu, format!("no {so} ({why})"))
}

/// Where the Linux x86-64 library of an FMU lies in its archive: `binaries/linux64/` in
/// FMI 2.0, `binaries/x86_64-linux/` in FMI 3.0.
pub fn library_entry(fmi_version: &str, model_identifier: &str) -> String {
    if fmi_version.starts_with("3.") {
        format!("binaries/x86_64-linux/{model_identifier}.so")
    } else {
        format!("binaries/linux64/{model_identifier}.so")
    }
}

//! Packing: write `<model>.fmu` with modelDescription.xml, the model's library, resources
//! and documentation. The libraries are built by the build script (release, the models'
//! `fmu` feature) and embedded in this library (and so in the binary and the Python
//! package), so packing needs no sources and no cargo.
//! The output is deterministic: same sources, byte-identical FMUs.

pub use crate::registry::ModelSpec;
use std::io::Write;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum PackError {
    #[error("model '{model}': inconsistent variable table: {reason}")]
    Table {
        model: String,
        reason: fmu_export::description::InvalidTable,
    },
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("zip: {0}")]
    Zip(#[from] zip::result::ZipError),
    #[error("unknown model '{0}' (known: {1})")]
    UnknownModel(String, String),
}

/// Every model twinbench ships, and the test FMUs (from [`crate::registry`]).
pub fn models() -> Vec<ModelSpec> {
    crate::registry::models()
        .into_iter()
        .map(|m| m.pack)
        .collect()
}

/// Where twinbench was built from (the workspace's `Cargo.toml`, two folders above this
/// crate's): the tests use it; the commands do not (an installed binary needs no sources).
pub fn workspace_root() -> PathBuf {
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    here.ancestors()
        .nth(2)
        .expect("crates/bench is two folders below the workspace root")
        .to_path_buf()
}

/// Default output folder of `pack`, the same for every binary wherever it was built:
/// `$XDG_DATA_HOME/twinbench/fmu`, that is `~/.local/share/twinbench/fmu` (`fmu` in the
/// working directory when neither `XDG_DATA_HOME` nor `HOME` is set).
pub fn default_fmu_dir() -> PathBuf {
    let data = std::env::var_os("XDG_DATA_HOME")
        .filter(|d| Path::new(d).is_absolute())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/share")));
    match data {
        Some(d) => d.join("twinbench").join("fmu"),
        None => PathBuf::from("fmu"),
    }
}

/// Which FMI version an archive is for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum FmiVersion {
    V2,
    V3,
}

impl FmiVersion {
    /// `2` or `3` (as `pack --fmi 2,3` names them).
    pub fn parse(s: &str) -> Option<FmiVersion> {
        match s.trim() {
            "2" | "2.0" => Some(FmiVersion::V2),
            "3" | "3.0" => Some(FmiVersion::V3),
            _ => None,
        }
    }
}

/// Path of a packed FMU (test FMUs under `test/`): `<name>.fmu` for FMI 2.0,
/// `<name>-fmi3.fmu` for FMI 3.0.
pub fn fmu_path(out_dir: &Path, spec: &ModelSpec) -> PathBuf {
    fmu_path_of(out_dir, spec, FmiVersion::V2)
}

/// [`fmu_path`] of either version.
pub fn fmu_path_of(out_dir: &Path, spec: &ModelSpec, version: FmiVersion) -> PathBuf {
    let dir = if spec.test_only {
        out_dir.join("test")
    } else {
        out_dir.to_path_buf()
    };
    match version {
        FmiVersion::V2 => dir.join(format!("{}.fmu", spec.info.name)),
        FmiVersion::V3 => dir.join(format!("{}-fmi3.fmu", spec.info.name)),
    }
}

/// Write `bytes` to `path` atomically (see [`tb_table::write_atomic`]).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), PackError> {
    tb_table::write_atomic(path, bytes).map_err(|source| PackError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Assemble one FMI 2.0 FMU archive in memory.
pub fn fmu_archive(spec: &ModelSpec, library: &[u8]) -> Result<Vec<u8>, PackError> {
    fmu_archive_of(spec, library, FmiVersion::V2)
}

/// Assemble one FMU archive of either version in memory: the same library, the version's
/// model description and platform folder (`linux64`, FMI 3.0's `x86_64-linux`).
pub fn fmu_archive_of(
    spec: &ModelSpec,
    library: &[u8],
    version: FmiVersion,
) -> Result<Vec<u8>, PackError> {
    let description = match version {
        FmiVersion::V2 => (spec.model_description)(),
        FmiVersion::V3 => (spec.model_description3)(),
    };
    archive(spec, library, version, description, &[])
}

/// A fitted twin's FMU ([`crate::export_twin`]): the model's archive with the fitted
/// description, and `resources` added or put in place of the bundled ones of that name.
pub fn fitted_archive(
    spec: &ModelSpec,
    library: &[u8],
    version: FmiVersion,
    fitting: &fmu_export::description::Fitting,
    resources: &[(String, Vec<u8>)],
) -> Result<Vec<u8>, PackError> {
    let description = match version {
        FmiVersion::V2 => (spec.fitted_description)(fitting),
        FmiVersion::V3 => (spec.fitted_description3)(fitting),
    };
    archive(spec, library, version, description, resources)
}

fn archive(
    spec: &ModelSpec,
    library: &[u8],
    version: FmiVersion,
    description: String,
    resources: &[(String, Vec<u8>)],
) -> Result<Vec<u8>, PackError> {
    use zip::write::SimpleFileOptions;
    let platform = match version {
        FmiVersion::V2 => "linux64",
        FmiVersion::V3 => "x86_64-linux",
    };
    let mut entries: Vec<(String, Vec<u8>, u32)> = vec![
        (
            "modelDescription.xml".into(),
            description.into_bytes(),
            0o644,
        ),
        (
            format!("binaries/{platform}/{}.so", spec.info.identifier),
            library.to_vec(),
            0o755,
        ),
        (
            "documentation/index.html".into(),
            (spec.documentation)().into_bytes(),
            0o644,
        ),
    ];
    for r in spec.info.resources {
        if !resources.iter().any(|(n, _)| n == r.name) {
            entries.push((format!("resources/{}", r.name), r.content.to_vec(), 0o644));
        }
    }
    for (name, content) in resources {
        entries.push((format!("resources/{name}"), content.clone(), 0o644));
    }
    entries.sort_by(|a, b| a.0.cmp(&b.0));
    let mut zip = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    for (name, data, mode) in entries {
        let opts = SimpleFileOptions::default()
            .compression_method(zip::CompressionMethod::Deflated)
            .last_modified_time(zip::DateTime::default())
            .unix_permissions(mode);
        zip.start_file(name, opts)?;
        zip.write_all(&data).map_err(|e| PackError::Zip(e.into()))?;
    }
    Ok(zip.finish()?.into_inner())
}

/// Whether the FMI 2.0 FMU at `path` holds this binary's `spec`: its library and every
/// resource byte for byte (a missing, unreadable or older FMU is not current). What the
/// demo checks before it runs a bundle packed by an earlier build.
pub fn is_current(spec: &ModelSpec, path: &Path) -> bool {
    use std::io::Read;
    let Ok(file) = std::fs::File::open(path) else {
        return false;
    };
    let Ok(mut zip) = zip::ZipArchive::new(std::io::BufReader::new(file)) else {
        return false;
    };
    let mut same = |name: &str, want: &[u8]| -> bool {
        let Ok(mut entry) = zip.by_name(name) else {
            return false;
        };
        if entry.size() != want.len() as u64 {
            return false;
        }
        let mut got = Vec::with_capacity(want.len());
        entry.read_to_end(&mut got).is_ok() && got == want
    };
    same(
        &format!("binaries/linux64/{}.so", spec.info.identifier),
        spec.library,
    ) && spec
        .info
        .resources
        .iter()
        .all(|r| same(&format!("resources/{}", r.name), r.content))
}

/// Pack the given models (when `names` is empty: every shipped model, not the test FMUs)
/// into `out_dir` as FMI 2.0 FMUs; returns the FMU paths.
pub fn pack(names: &[String], out_dir: &Path) -> Result<Vec<PathBuf>, PackError> {
    pack_versions(names, out_dir, &[FmiVersion::V2])
}

/// [`pack`] for each of `versions`: one archive per model and version.
pub fn pack_versions(
    names: &[String],
    out_dir: &Path,
    versions: &[FmiVersion],
) -> Result<Vec<PathBuf>, PackError> {
    let all = models();
    let specs: Vec<ModelSpec> = if names.is_empty() {
        all.into_iter().filter(|s| !s.test_only).collect()
    } else {
        names
            .iter()
            .map(|n| {
                all.iter()
                    .find(|s| s.info.name == n)
                    .copied()
                    .ok_or_else(|| {
                        PackError::UnknownModel(
                            n.clone(),
                            all.iter()
                                .map(|s| s.info.name)
                                .collect::<Vec<_>>()
                                .join(", "),
                        )
                    })
            })
            .collect::<Result<_, _>>()?
    };
    for s in &specs {
        (s.validate)().map_err(|reason| PackError::Table {
            model: s.info.name.into(),
            reason,
        })?;
    }
    let mut written = Vec::new();
    for s in &specs {
        for &v in versions {
            let bytes = fmu_archive_of(s, s.library, v)?;
            let path = fmu_path_of(out_dir, s, v);
            write_atomic(&path, &bytes)?;
            written.push(path);
        }
    }
    Ok(written)
}

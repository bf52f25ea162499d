//! Packing: build the model crates as `cdylib`s (release, `fmu` feature) and write
//! `target/fmu/<model>.fmu` with modelDescription.xml, the binary, resources and
//! documentation. The output is deterministic: same sources, byte-identical FMUs.

use fmu_export::Model;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

const MODEL_DESCRIPTION_TEMPLATE: &str = include_str!("../fmu-templates/modelDescription.xml");
const DOCUMENTATION_TEMPLATE: &str = include_str!("../fmu-templates/documentation/index.html");

#[derive(Debug, thiserror::Error)]
pub enum PackError {
    #[error("cargo build of the model crates failed ({0}); see its output above")]
    Build(String),
    #[error("cannot run cargo: {0}")]
    Cargo(std::io::Error),
    #[error("model '{model}': inconsistent variable table: {reason}")]
    Table { model: String, reason: String },
    #[error("model '{model}': built library {path} not found")]
    MissingBinary { model: String, path: PathBuf },
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

/// What the packer needs of one model crate.
#[derive(Clone, Copy)]
pub struct ModelSpec {
    /// Cargo package name (also the library's file stem).
    pub package: &'static str,
    /// A test FMU for the suite, written under `target/fmu/test/`.
    pub test_only: bool,
    pub info: fmu_export::ModelInfo,
    pub model_description: fn() -> String,
    pub documentation: fn() -> String,
    pub validate: fn() -> Result<(), String>,
    pub guid: fn() -> String,
}

impl ModelSpec {
    pub fn of<M: Model>(package: &'static str, test_only: bool) -> Self {
        ModelSpec {
            package,
            test_only,
            info: M::INFO,
            model_description: || {
                fmu_export::description::render_model_description::<M>(
                    MODEL_DESCRIPTION_TEMPLATE,
                    concat!("twinbench ", env!("CARGO_PKG_VERSION")),
                )
            },
            documentation: || {
                fmu_export::description::render_documentation::<M>(DOCUMENTATION_TEMPLATE)
            },
            validate: fmu_export::description::validate_table::<M::Vars>,
            guid: fmu_export::description::guid::<M>,
        }
    }
}

/// Every model twinbench ships, and the test FMUs (from [`crate::registry`]).
pub fn models() -> Vec<ModelSpec> {
    crate::registry::models()
        .into_iter()
        .map(|m| m.pack)
        .collect()
}

/// The workspace root (where `Cargo.toml` of twinbench lives).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Default output folder of `pack`.
pub fn default_fmu_dir() -> PathBuf {
    workspace_root().join("target").join("fmu")
}

/// Path of a packed FMU (test FMUs under `test/`).
pub fn fmu_path(out_dir: &Path, spec: &ModelSpec) -> PathBuf {
    let dir = if spec.test_only {
        out_dir.join("test")
    } else {
        out_dir.to_path_buf()
    };
    dir.join(format!("{}.fmu", spec.info.name))
}

/// Build the cdylibs of `specs` in release mode with the `fmu` feature, in a target folder
/// of their own (so that native builds without the feature never overwrite them).
pub fn build_libraries(specs: &[ModelSpec]) -> Result<PathBuf, PackError> {
    let root = workspace_root();
    let target = root.join("target").join("fmu-build");
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(&root)
        .arg("build")
        .arg("--release")
        .arg("--target-dir")
        .arg(&target);
    let mut features = Vec::new();
    for s in specs {
        cmd.arg("-p").arg(s.package);
        features.push(format!("{}/fmu", s.package));
    }
    cmd.arg("--features").arg(features.join(","));
    let status = cmd.status().map_err(PackError::Cargo)?;
    if !status.success() {
        return Err(PackError::Build(status.to_string()));
    }
    Ok(target.join("release"))
}

/// Write `bytes` to `path` atomically (temporary file in the same folder, then rename).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), PackError> {
    let io = |source| PackError::Io {
        path: path.to_path_buf(),
        source,
    };
    let dir = path.parent().unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(io)?;
    let tmp = dir.join(format!(
        ".{}.tmp{}",
        path.file_name().unwrap_or_default().to_string_lossy(),
        std::process::id()
    ));
    std::fs::write(&tmp, bytes).map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// Assemble one FMU archive in memory.
pub fn fmu_archive(spec: &ModelSpec, library: &[u8]) -> Result<Vec<u8>, PackError> {
    use zip::write::SimpleFileOptions;
    let mut entries: Vec<(String, Vec<u8>, u32)> = vec![
        (
            "modelDescription.xml".into(),
            (spec.model_description)().into_bytes(),
            0o644,
        ),
        (
            format!("binaries/linux64/{}.so", spec.info.identifier),
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
        entries.push((format!("resources/{}", r.name), r.content.to_vec(), 0o644));
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

/// Pack the given models (all when `names` is empty) into `out_dir`; returns the FMU paths.
pub fn pack(names: &[String], out_dir: &Path) -> Result<Vec<PathBuf>, PackError> {
    let all = models();
    let specs: Vec<ModelSpec> = if names.is_empty() {
        all
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
    let lib_dir = build_libraries(&specs)?;
    let mut written = Vec::new();
    for s in &specs {
        let lib_path = lib_dir.join(format!("lib{}.so", s.package.replace('-', "_")));
        let lib = std::fs::read(&lib_path).map_err(|_| PackError::MissingBinary {
            model: s.info.name.into(),
            path: lib_path.clone(),
        })?;
        let bytes = fmu_archive(s, &lib)?;
        let path = fmu_path(out_dir, s);
        write_atomic(&path, &bytes)?;
        written.push(path);
    }
    Ok(written)
}

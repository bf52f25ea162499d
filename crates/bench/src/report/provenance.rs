//! What report.html says of its own making: which twinbench wrote it, when, from which
//! study, and the SHA-256 of every input (the study, each lap's system and measurement,
//! the FMUs and replayed files the systems name, the lap's truth), so that a colleague
//! handed the page can tell whether the files before them are the ones it was made from.

use sha2::{Digest, Sha256};
use std::path::{Path, PathBuf};
use tb_optimize::Study;

/// One input file: what it is to the study, where, its size and SHA-256 (or why it could
/// not be read: a file moved since the study ran does not stop the report).
#[derive(Clone, Debug)]
pub struct Input {
    pub role: String,
    pub path: PathBuf,
    pub digest: Result<(u64, String), String>,
}

#[derive(Clone, Debug)]
pub struct Provenance {
    /// twinbench's version (the build exposes no commit).
    pub version: &'static str,
    /// When the report was written, UTC.
    pub date: String,
    pub study: PathBuf,
    pub inputs: Vec<Input>,
}

/// The provenance of a report of `study` written now; `truth`: the truth file it marks.
pub fn collect(study: &Study, truth: Option<&Path>) -> Provenance {
    let mut files: Vec<(String, PathBuf)> = vec![("study".into(), study.path.clone())];
    let several = study.laps.len() > 1;
    for lap in &study.laps {
        let of = |what: &str| match several {
            true => format!("{what} (lap {})", lap.name),
            false => what.to_string(),
        };
        files.push((of("system"), lap.system_path.clone()));
        files.extend(system_inputs(&lap.system_path));
        files.push((of("measurement"), lap.measurement_path.clone()));
    }
    files.extend(truth.map(|t| ("truth of the lap".to_string(), t.to_path_buf())));
    // A file shared by several laps (one system, its FMUs) is listed once.
    let mut seen = std::collections::BTreeSet::new();
    files.retain(|(_, p)| seen.insert(absolute(p)));
    Provenance {
        version: env!("CARGO_PKG_VERSION"),
        date: jiff::Timestamp::now()
            .strftime("%Y-%m-%d %H:%M:%S UTC")
            .to_string(),
        study: absolute(&study.path),
        inputs: files
            .into_iter()
            .map(|(role, path)| Input {
                digest: sha256(&path).map_err(|e| e.to_string()),
                path: absolute(&path),
                role,
            })
            .collect(),
    }
}

/// The FMUs and replayed files a system file names. An SSP package carries its FMUs
/// inside (its own digest covers them); a system that no longer reads adds nothing.
fn system_inputs(system: &Path) -> Vec<(String, PathBuf)> {
    if system
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("ssp"))
    {
        return Vec::new();
    }
    let Ok(sys) = tb_cosim::SystemFile::load(system) else {
        return Vec::new();
    };
    let fmus = sys
        .fmus
        .into_iter()
        .map(|(name, path)| (format!("FMU {name}"), path));
    let replayed = sys
        .replay
        .into_iter()
        .map(|r| ("replayed measurement".to_string(), r.file));
    fmus.chain(replayed).collect()
}

/// The path as a colleague can find it (absolute, `..` resolved where the file exists).
fn absolute(path: &Path) -> PathBuf {
    std::fs::canonicalize(path)
        .or_else(|_| std::path::absolute(path))
        .unwrap_or_else(|_| path.to_path_buf())
}

/// Size and SHA-256 (lower-case hex) of a file, streamed: FMUs can be large.
pub fn sha256(path: &Path) -> std::io::Result<(u64, String)> {
    let mut file = std::fs::File::open(path)?;
    let mut hasher = Sha256::new();
    let size = std::io::copy(&mut file, &mut hasher)?;
    Ok((size, format!("{:x}", hasher.finalize())))
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_digest_is_sha256_of_the_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("abc.txt");
        std::fs::write(&p, b"abc").unwrap();
        let (size, hex) = super::sha256(&p).unwrap();
        assert_eq!(size, 3);
        assert_eq!(
            hex,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
    }
}

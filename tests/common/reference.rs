//! The Modelica Reference FMUs, built here from their sources (`../shared/reference-fmus`,
//! or `TWINBENCH_REFERENCE_FMUS`) with gcc, as FMI 2.0 and FMI 3.0 Co-Simulation FMUs:
//! the importer's conformance suite. Built once into `target/reference-fmus/fmi<N>/`
//! (a lock file serialises test binaries that build at the same time).

use super::build;
use crate::args;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The models with Co-Simulation in FMI 2.0.
pub const FMI2_MODELS: &[&str] = &[
    "BouncingBall",
    "Dahlquist",
    "Feedthrough",
    "Resource",
    "Stair",
    "VanDerPol",
];

/// The sources; a clear failure (not a skip) when they are missing.
pub fn sources() -> PathBuf {
    let dir = std::env::var_os("TWINBENCH_REFERENCE_FMUS")
        .map(PathBuf::from)
        .unwrap_or_else(|| twinbench::pack::workspace_root().join("../shared/reference-fmus"));
    assert!(
        dir.join("src").is_dir() && dir.join("include").is_dir(),
        "the Reference FMUs' sources are not at {} (set TWINBENCH_REFERENCE_FMUS)",
        dir.display()
    );
    dir
}

/// `<Model>.fmu` for FMI `version` (2 or 3), built when missing or older than its sources.
pub fn fmu(model: &str, version: u8) -> PathBuf {
    let src = sources();
    let out = twinbench::pack::workspace_root()
        .join("target/reference-fmus")
        .join(format!("fmi{version}"));
    std::fs::create_dir_all(&out).unwrap();
    let fmu = out.join(format!("{model}.fmu"));
    let _lock = build::lock(&out);
    let xml = src.join(model).join(format!("FMI{version}.xml"));
    let model_c = src.join(model).join("model.c");
    let config = src.join(model).join("config.h");
    if build::up_to_date(&fmu, &[&xml, &model_c, &config]) {
        return fmu;
    }
    let so = out.join(format!("{model}.so"));
    let functions = if version == 2 {
        "fmi2Functions.c"
    } else {
        "fmi3Functions.c"
    };
    let define = format!("-DFMI_VERSION={version}");
    let include = |d: &Path| format!("-I{}", d.display());
    let (headers, own) = (include(&src.join("include")), include(&src.join(model)));
    let functions = src.join("src").join(functions);
    let cosimulation = src.join("src/cosimulation.c");
    let flags = args![
        "-shared",
        "-fPIC",
        "-O2",
        "-DDISABLE_PREFIX",
        define,
        headers,
        own
    ];
    let files = args!["-o", so, model_c, functions, cosimulation, "-lm"];
    build::gcc(
        flags.iter().chain(&files),
        &format!("{model} (FMI {version})"),
    );
    let platform = if version == 2 {
        "linux64"
    } else {
        "x86_64-linux"
    };
    let tmp = out.join(format!(".{model}.fmu.tmp"));
    let (md, library) = (std::fs::read(&xml).unwrap(), std::fs::read(&so).unwrap());
    let library_entry = format!("binaries/{platform}/{model}.so");
    let mut entries = vec![
        ("modelDescription.xml", &md[..]),
        (&library_entry, &library),
    ];
    // Resource reads resources/y.txt.
    let y = src.join(model).join("y.txt");
    let resource = y.exists().then(|| std::fs::read(&y).unwrap());
    if let Some(bytes) = &resource {
        entries.push(("resources/y.txt", bytes));
    }
    build::zip(&tmp, &entries);
    std::fs::rename(&tmp, &fmu).unwrap();
    std::fs::remove_file(&so).unwrap();
    fmu
}

/// A copy of `fmu` as `dir/<name>.fmu` with its modelDescription.xml edited by `xml` and
/// each entry renamed by `rename` (`None` drops it): a supplier's variant of a model.
pub fn variant(
    fmu: &Path,
    dir: &Path,
    name: &str,
    xml: impl Fn(&str) -> String,
    rename: impl Fn(&str) -> Option<String>,
) -> PathBuf {
    use std::io::Read;
    let mut zin = zip::ZipArchive::new(std::fs::File::open(fmu).unwrap()).unwrap();
    let out = dir.join(format!("{name}.fmu"));
    let mut zout = zip::ZipWriter::new(std::fs::File::create(&out).unwrap());
    let o = zip::write::SimpleFileOptions::default()
        .compression_method(zip::CompressionMethod::Deflated);
    for k in 0..zin.len() {
        let mut entry = zin.by_index(k).unwrap();
        let mut bytes = Vec::new();
        entry.read_to_end(&mut bytes).unwrap();
        let entry_name = entry.name().to_string();
        if entry_name == "modelDescription.xml" {
            bytes = xml(&String::from_utf8(bytes).unwrap()).into_bytes();
        }
        let Some(new_name) = rename(&entry_name) else {
            continue;
        };
        zout.start_file(new_name, o).unwrap();
        zout.write_all(&bytes).unwrap();
    }
    zout.finish().unwrap();
    out
}

/// A copy of `fmu` as `dir/<name>.fmu` with its modelDescription.xml edited by `xml`, every
/// other entry as it is ([`variant`]).
pub fn with_description(
    fmu: &Path,
    dir: &Path,
    name: &str,
    xml: impl Fn(&str) -> String,
) -> PathBuf {
    variant(fmu, dir, name, xml, |entry| Some(entry.to_string()))
}

/// Per column FMPy recorded (`theirs`, the FMU's own names) against twinbench's recording
/// of the instance `m` (`ours`, with as many rows, else the test fails): (name, the largest
/// absolute difference, the largest |value| FMPy recorded).
pub fn worst_differences(
    model: &str,
    ours: &tb_cosim::Table,
    theirs: &tb_cosim::Table,
) -> Vec<(String, f64, f64)> {
    assert_eq!(
        ours.len(),
        theirs.len(),
        "{model}: {} rows in twinbench, {} in FMPy",
        ours.len(),
        theirs.len()
    );
    let mut out = Vec::new();
    for name in theirs.names() {
        let ours_name = if name == "time" {
            "time".to_string()
        } else {
            format!("m.{name}")
        };
        let a = ours
            .require(&ours_name)
            .unwrap_or_else(|e| panic!("{model}: {e}"));
        let b = theirs.require(name).unwrap();
        let largest = b.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let worst = a
            .iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f64, f64::max);
        out.push((name.clone(), worst, largest));
    }
    out
}

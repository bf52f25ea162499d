//! Shared helpers of the integration tests: the packed FMUs and a cache to load them.
#![allow(dead_code)]

pub mod build;
pub mod cli;
pub mod hostile;
pub mod kinds;
pub mod study;
pub mod synthetic;

// Each test binary uses some of them.
#[allow(unused_imports)]
pub use cli::{fails, fails_in, ok, ok_in, run_ok, run_ok_in, twinbench, twinbench_in};

use std::path::{Path, PathBuf};
use std::sync::{Arc, OnceLock};
use tb_fmi::{FmuCache, LoadedFmu};

/// Pack every model and test FMU once per test binary into `target/fmu` (where the
/// repository's system files find them), as FMI 2.0 and FMI 3.0 FMUs (`<model>-fmi3.fmu`),
/// so that the tests always run the FMUs of the current sources.
pub fn fmu_dir() -> PathBuf {
    static PACKED: OnceLock<PathBuf> = OnceLock::new();
    PACKED
        .get_or_init(|| {
            let dir = twinbench::pack::workspace_root().join("target/fmu");
            let all: Vec<String> = twinbench::pack::models()
                .iter()
                .map(|s| s.info.name.to_string())
                .collect();
            use twinbench::pack::FmiVersion;
            twinbench::pack::pack_versions(&all, &dir, &[FmiVersion::V2, FmiVersion::V3])
                .expect("packing the FMUs failed");
            dir
        })
        .clone()
}

/// Path of a packed FMU by model name (test FMUs under test/).
pub fn fmu(name: &str) -> PathBuf {
    fmu_of(name, twinbench::pack::FmiVersion::V2)
}

/// Path of a packed FMI 3.0 FMU by model name (test FMUs under test/).
pub fn fmu3(name: &str) -> PathBuf {
    fmu_of(name, twinbench::pack::FmiVersion::V3)
}

fn fmu_of(name: &str, version: twinbench::pack::FmiVersion) -> PathBuf {
    let dir = fmu_dir();
    let spec = twinbench::pack::models()
        .into_iter()
        .find(|s| s.info.name == name)
        .unwrap_or_else(|| panic!("no model named {name}"));
    twinbench::pack::fmu_path_of(&dir, &spec, version)
}

/// One unpack cache for all tests of a binary, kept under `target/` (content-addressed and
/// safe for concurrent processes). A static is never dropped: a temporary cache held by one
/// would stay behind in the system's temporary folder.
pub fn shared_cache() -> Arc<FmuCache> {
    static CACHE: OnceLock<Arc<FmuCache>> = OnceLock::new();
    CACHE
        .get_or_init(|| {
            let dir = twinbench::pack::workspace_root().join("target/test-fmu-cache");
            Arc::new(FmuCache::persistent(&dir).unwrap())
        })
        .clone()
}

pub fn cache() -> &'static FmuCache {
    static CACHE: OnceLock<Arc<FmuCache>> = OnceLock::new();
    CACHE.get_or_init(shared_cache)
}

pub fn load(name: &str) -> Arc<LoadedFmu> {
    cache().load(&fmu(name)).unwrap()
}

pub fn vr(fmu: &LoadedFmu, name: &str) -> u32 {
    fmu.description
        .variable(name)
        .unwrap_or_else(|| panic!("{}: no variable {name}", fmu.description.model_name))
        .value_reference
}

/// A scratch folder `tag` holding the `files` (name, text).
pub fn scratch_with(tag: &str, files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = tb_testkit::scratch(tag);
    for (name, text) in files {
        std::fs::write(dir.path().join(name), text).unwrap();
    }
    dir
}

/// A system file's text: the top-level keys `top`, `[fmus]` naming each (name, FMU file),
/// then the tables `body`.
pub fn system_text(top: &str, fmus: &[(&str, &Path)], body: &str) -> String {
    let mut text = format!("{top}\n[fmus]\n");
    for (name, fmu) in fmus {
        text.push_str(&format!("{name} = {:?}\n", fmu.display().to_string()));
    }
    text.push('\n');
    text.push_str(body);
    text
}

/// The [`system_text`] written as the system file `path`.
pub fn system_file(path: &Path, top: &str, fmus: &[(&str, &Path)], body: &str) -> PathBuf {
    std::fs::write(path, system_text(top, fmus, body)).unwrap();
    path.to_path_buf()
}

/// `systems/rls_v.toml` with its FMUs those [`fmu_dir`] packs (by absolute path), edited by
/// `edit`, written as `path`.
pub fn bench_file(path: &Path, edit: impl FnOnce(String) -> String) -> PathBuf {
    let root = twinbench::pack::workspace_root();
    let text = std::fs::read_to_string(root.join("systems/rls_v.toml"))
        .unwrap()
        .replace("../target/fmu", &fmu_dir().display().to_string());
    std::fs::write(path, edit(text)).unwrap();
    path.to_path_buf()
}

/// The [`bench_file`] `path` run in process (the FMUs unpacked anew, their messages kept for
/// errors).
pub fn run_bench(
    path: &Path,
    edit: impl FnOnce(String) -> String,
) -> Result<tb_cosim::RunSummary, tb_cosim::SystemError> {
    bench_file(path, edit);
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let mut sim = tb_cosim::Simulation::new(tb_cosim::Plan::load(path, cache).unwrap()).unwrap();
    sim.echo_fmu_log = false;
    sim.run()
}

/// An instance `name` of `fmu` through its C API, with its resources (`logging`: the
/// FMU's debug logging on).
pub fn instantiate(fmu: &LoadedFmu, name: &str, logging: bool) -> tb_fmi::Instance {
    tb_fmi::Instance::instantiate(
        fmu.library().unwrap(),
        name,
        &fmu.description.guid,
        Some(&fmu.resource_dir()),
        logging,
    )
    .unwrap()
}

/// The plan of the system file `file` read from `path`: its FMUs unpacked anew, its
/// isolated instances run in this build's `twinbench worker`.
pub fn compile(
    file: tb_cosim::SystemFile,
    path: &Path,
) -> Result<tb_cosim::Plan, tb_cosim::SystemError> {
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    tb_cosim::Plan::compile(file, path, cache, &worker_options())
}

/// Load options whose isolated instances run in this build's `twinbench worker`.
pub fn worker_options() -> tb_cosim::LoadOptions {
    tb_cosim::LoadOptions {
        isolation: tb_cosim::isolated::IsolationOptions {
            worker_exe: Some(env!("CARGO_BIN_EXE_twinbench").into()),
            ..Default::default()
        },
        ..Default::default()
    }
}

pub mod cfmu;
pub mod python;
pub mod reference;

/// OMSimulator 3.0: TWINBENCH_OMSIMULATOR, else built from source by tools/omsimulator.sh.
pub fn omsimulator() -> PathBuf {
    let exe = std::env::var_os("TWINBENCH_OMSIMULATOR")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            let out = std::process::Command::new(
                twinbench::pack::workspace_root().join("tools/omsimulator.sh"),
            )
            .output()
            .expect("tools/omsimulator.sh runs");
            cli::succeeded(&out, "tools/omsimulator.sh");
            PathBuf::from(String::from_utf8_lossy(&out.stdout).trim())
        });
    assert!(exe.is_file(), "no OMSimulator at {}", exe.display());
    exe
}

/// `OMSimulator ARGS` run in `dir` (its temporary folders go there) must succeed and log no
/// error: its log (standard output and error).
pub fn run_omsimulator<S: AsRef<std::ffi::OsStr>>(
    dir: &std::path::Path,
    args: impl IntoIterator<Item = S>,
) -> String {
    let out = cli::output_ok(
        std::process::Command::new(omsimulator())
            .current_dir(dir)
            .args(args),
    );
    let log = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(!log.contains("error:"), "{log}");
    log
}

//! The hostile C FMU (`tests/hostile/hostile.c`, one fault compiled in with gcc), its
//! system file, and `twinbench run` on it with a store of the test's own.

use super::build;
use crate::args;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

pub const MODEL_DESCRIPTION: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="hostile" guid="{8c4e810f-3df3-4a00-8276-176fa3c9f000}" generationTool="twinbench tests (gcc)">
  <CoSimulation modelIdentifier="hostile" canHandleVariableCommunicationStepSize="true"/>
  <ModelVariables>
    <ScalarVariable name="u" valueReference="0" causality="input" variability="continuous"><Real start="1"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="1" causality="output" variability="continuous" initial="calculated"><Real/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="2" dependencies=""/></Outputs>
    <InitialUnknowns><Unknown index="2" dependencies="1"/></InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"#;

/// `tests/hostile/hostile.c` built with `-DFAULT=<fault>`, and its FMU, in `dir`: the
/// FMU's path and its library's bytes.
pub fn fmu(dir: &Path, fault: &str) -> (PathBuf, Vec<u8>) {
    let source = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/hostile/hostile.c");
    let so = dir.join(format!("hostile-{fault}.so"));
    let define = format!("-DFAULT={fault}");
    let flags = args!["-shared", "-fPIC", "-O1", "-Wall", "-Werror", define];
    build::gcc(flags.iter().chain(&args!["-o", so, source]), fault);
    let library = std::fs::read(&so).unwrap();
    let fmu = dir.join(format!("hostile-{fault}.fmu"));
    let md = MODEL_DESCRIPTION.as_bytes();
    build::zip(
        &fmu,
        &[
            ("modelDescription.xml", md),
            ("binaries/linux64/hostile.so", &library),
        ],
    );
    (fmu, library)
}

/// The system file of one instance `h` of `fmu` (a lap of 1 s in steps of 0.1 s,
/// recording `h.y`), beside it in `dir`.
pub fn system(dir: &Path, fmu: &Path) -> PathBuf {
    let sys = dir.join(format!(
        "{}.toml",
        fmu.file_stem().unwrap().to_string_lossy()
    ));
    std::fs::write(
        &sys,
        format!(
            "[fmus]\nhostile = \"{}\"\n\n[[instance]]\nname = \"h\"\nfmu = \"hostile\"\n\n[experiment]\nstep = 0.1\nstop = 1.0\n\n[record]\nsignals = [\"h.y\"]\n",
            fmu.display()
        ),
    )
    .unwrap();
    sys
}

/// `twinbench run SYSTEM` on the store `store` (and `--isolate`), with `env` set, and
/// `shell` (a shell line run before twinbench in the same process, `umask 000`): its
/// output, stderr, and the last recorded y.
pub fn run(
    store: &Path,
    sys: &Path,
    isolate: bool,
    env: &[(&str, &str)],
    shell: Option<&str>,
) -> (Output, String, Option<f64>) {
    let (cmd, csv) = command(store, sys, isolate, env, shell);
    finish(cmd, &csv)
}

/// The command [`run`] runs, to be changed before it runs, and its CSV.
pub fn command(
    store: &Path,
    sys: &Path,
    isolate: bool,
    env: &[(&str, &str)],
    shell: Option<&str>,
) -> (Command, PathBuf) {
    let csv = sys.with_extension(format!("{isolate}.csv"));
    let _ = std::fs::remove_file(&csv);
    let exe = env!("CARGO_BIN_EXE_twinbench");
    let mut args = vec![
        "run".to_string(),
        sys.display().to_string(),
        "--out".into(),
        csv.display().to_string(),
    ];
    if isolate {
        args.push("--isolate".into());
    }
    let mut cmd = match shell {
        Some(line) => {
            let mut c = Command::new("sh");
            c.arg("-c")
                .arg(format!("{line}; exec \"$0\" \"$@\""))
                .arg(exe)
                .args(&args);
            c
        }
        None => {
            let mut c = Command::new(exe);
            c.args(&args);
            c
        }
    };
    cmd.env("TWINBENCH_CACHE", store)
        .env_remove("TWINBENCH_WORKER_SANDBOX")
        .env_remove("TWINBENCH_ISOLATE")
        .env_remove("HOSTILE_PLANT");
    for (k, v) in env {
        cmd.env(k, v);
    }
    (cmd, csv)
}

/// Runs `cmd` ([`command`]): its output, stderr, and the last y of `csv`.
pub fn finish(mut cmd: Command, csv: &Path) -> (Output, String, Option<f64>) {
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    let y = std::fs::read_to_string(csv).ok().and_then(|t| {
        t.lines()
            .last()
            .and_then(|l| l.rsplit(',').next())
            .and_then(|v| v.parse().ok())
    });
    (out, err, y)
}

/// Whether isolated workers can be confined here; skipping says why, and never under CI.
pub fn confinement_here() -> bool {
    match tb_fmi::import::sandbox::available() {
        Ok(()) => true,
        Err(why) => {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI is set, and workers cannot be confined here: {why}"
            );
            eprintln!("skipped: workers cannot be confined here ({why})");
            false
        }
    }
}

//! Every packed FMU passes `fmpy validate` and runs in FMPy's co-simulation master.

mod common;

use std::path::PathBuf;
use std::process::Output;

/// `python tools/SCRIPT FMUS...`: its output, and the JSON object it printed a line for each
/// of `count` FMUs (else the test fails with what it printed).
fn run_check(script: &str, fmus: &[PathBuf], count: usize) -> (Output, Vec<serde_json::Value>) {
    let script = twinbench::pack::workspace_root().join("tools").join(script);
    let out = std::process::Command::new(common::python::python())
        .arg(&script)
        .args(fmus)
        .output()
        .expect("cannot run python");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        lines.len(),
        count,
        "stdout: {stdout}\nstderr: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    (out, lines)
}

#[test]
fn fmpy_validates_and_simulates_every_fmu() {
    let names: Vec<&str> = twinbench::pack::models()
        .iter()
        .map(|s| s.info.name)
        .collect();
    let fmus: Vec<PathBuf> = names.iter().map(|n| common::fmu(n)).collect();
    let (out, lines) = run_check("fmpy_check.py", &fmus, fmus.len());
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    for (name, r) in names.iter().zip(&lines) {
        assert_eq!(
            r["problems"].as_array().map(|a| a.len()),
            Some(0),
            "{name}: fmpy validate: {r}"
        );
        assert_eq!(
            r["simulated"],
            serde_json::Value::Bool(true),
            "{name}: FMPy simulation: {r}\n{stderr}"
        );
    }
    assert!(out.status.success(), "{stdout}\n{stderr}");
}

/// Issue #35: each shipped model's FMI 3.0 FMU passes FMPy's validation and, simulated
/// alone in FMPy (FMI 3.0), gives every output of its FMI 2.0 FMU bit for bit.
#[test]
fn fmpy_validates_each_fmi3_fmu_and_it_equals_its_fmi2_fmu_bit_for_bit() {
    let names: Vec<&str> = twinbench::pack::models()
        .iter()
        .filter(|s| !s.test_only)
        .map(|s| s.info.name)
        .collect();
    let fmus: Vec<PathBuf> = names
        .iter()
        .flat_map(|n| [common::fmu(n), common::fmu3(n)])
        .collect();
    let (out, lines) = run_check("fmpy_fmi3_check.py", &fmus, names.len());
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    for (name, r) in names.iter().zip(&lines) {
        assert_eq!(r["fmi_version"], "3.0", "{name}: {r}");
        assert_eq!(
            r["problems"].as_array().map(|a| a.len()),
            Some(0),
            "{name}: fmpy validate: {r}"
        );
        assert_eq!(
            r["bitwise_equal"],
            serde_json::Value::Bool(true),
            "{name}: FMI 3.0 against FMI 2.0 in FMPy: {r}\n{stderr}"
        );
        eprintln!(
            "{name}: FMI 3.0 = FMI 2.0 in FMPy, {} outputs, {} rows, bit for bit",
            r["signals"], r["rows"][0]
        );
    }
    assert!(out.status.success(), "{stdout}\n{stderr}");
}

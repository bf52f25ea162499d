//! Every packed FMU passes `fmpy validate` and runs in FMPy's co-simulation master.

mod common;

#[test]
fn fmpy_validates_and_simulates_every_fmu() {
    let names: Vec<&str> = twinbench::pack::models()
        .iter()
        .map(|s| s.info.name)
        .collect();
    let fmus: Vec<std::path::PathBuf> = names.iter().map(|n| common::fmu(n)).collect();
    let script = twinbench::pack::workspace_root().join("tools/fmpy_check.py");
    let out = std::process::Command::new(common::python::python())
        .arg(&script)
        .args(&fmus)
        .output()
        .expect("cannot run python");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        lines.len(),
        fmus.len(),
        "stdout: {stdout}\nstderr: {stderr}"
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

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

/// Issue #35: each shipped model's FMI 3.0 FMU passes FMPy's validation and, simulated
/// alone in FMPy (FMI 3.0), gives every output of its FMI 2.0 FMU bit for bit.
#[test]
fn fmpy_validates_each_fmi3_fmu_and_it_equals_its_fmi2_fmu_bit_for_bit() {
    let names: Vec<&str> = twinbench::pack::models()
        .iter()
        .filter(|s| !s.test_only)
        .map(|s| s.info.name)
        .collect();
    let script = twinbench::pack::workspace_root().join("tools/fmpy_fmi3_check.py");
    let mut cmd = std::process::Command::new(common::python::python());
    cmd.arg(&script);
    for n in &names {
        cmd.arg(common::fmu(n)).arg(common::fmu3(n));
    }
    let out = cmd.output().expect("cannot run python");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(
        lines.len(),
        names.len(),
        "stdout: {stdout}\nstderr: {stderr}"
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

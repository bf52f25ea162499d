//! The demo's fitted twin (`twinbench export-twin` on the demo's result) in other tools:
//! FMPy's master over the fitted FMUs alone (no value set) gives the lap `twinbench run
//! --set <answer>` gives, bit for bit; the fitted SSP gives in FMPy's `simulate_ssp` and in
//! OMSimulator, bit for bit, what the study's bench with the answer set gives in the same
//! tool (each tool has its own master: docs/cross_validation.md).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn python(args: &[&str]) -> serde_json::Value {
    let o = common::cli::output_ok(Command::new(common::python::python()).args(args));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn tool(name: &str) -> String {
    twinbench::pack::workspace_root()
        .join("tools")
        .join(name)
        .display()
        .to_string()
}

/// The study's bench with the answer written into its `[parameters]`, exported as an SSP.
fn bench_ssp_with_answer(d: &Path, system: &Path, answer: &[(String, f64)]) -> PathBuf {
    let mut text = std::fs::read_to_string(system).unwrap();
    let mut lines = String::new();
    for (name, value) in answer {
        lines.push_str(&format!("\"{name}\" = {value:?}\n"));
    }
    text = text.replacen("[parameters]\n", &format!("[parameters]\n{lines}"), 1);
    let path = system.with_file_name("with_answer.toml");
    std::fs::write(&path, text).unwrap();
    let ssp = d.join("with_answer.ssp");
    common::ok_in(d, args!["export-ssp", path, "-o", ssp]);
    ssp
}

#[test]
fn the_demos_fitted_twin_runs_bit_for_bit_in_fmpy_and_omsimulator() {
    common::fmu_dir();
    let dir = tb_testkit::scratch("export-twin-tools");
    let d = dir.path();
    common::ok_in(d, ["demo", "--out", "demo"]);
    common::ok_in(
        d,
        [
            "export-twin",
            "demo/result.json",
            "--out",
            "twin",
            "--fmi",
            "2",
        ],
    );
    let result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("demo/result.json")).unwrap())
            .unwrap();
    let system = PathBuf::from(result["system"].as_str().unwrap());
    let answer: Vec<(String, f64)> = result["parameters_final"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| (p[0].as_str().unwrap().to_string(), p[1].as_f64().unwrap()))
        .collect();
    let mut args = vec!["run".to_string(), system.display().to_string()];
    for (n, v) in &answer {
        args.extend(["--set".into(), format!("{n}={v:?}")]);
    }
    args.extend(["-o".into(), "set.csv".into()]);
    common::ok_in(d, &args);

    // FMPy's FMU2Slave over the fitted FMUs alone, the whole lap.
    let text = std::fs::read_to_string(d.join("twin/fitted_system.toml")).unwrap();
    let (head, tail) = text.split_at(text.find("[parameters]").unwrap());
    let bare = format!("{head}{}", &tail[tail.find("\n[").unwrap() + 1..]);
    std::fs::write(d.join("twin/bare.toml"), bare).unwrap();
    let j = python(&[
        &tool("fmpy_cosim.py"),
        d.join("twin/bare.toml").to_str().unwrap(),
        "--compare",
        d.join("set.csv").to_str().unwrap(),
        "--json",
    ]);
    let cmp = j["compare"].as_object().unwrap();
    assert!(cmp.len() > 20, "{cmp:?}");
    for (name, c) in cmp {
        assert_eq!(
            c["bitwise_equal"], true,
            "FMPy over the fitted FMUs, {name}: {c}"
        );
    }

    // The fitted SSP against the bench with the answer set, 10 s, in each tool.
    let with_answer = bench_ssp_with_answer(d, &system, &answer);
    let fitted = d.join("twin/fitted_twin.ssp");
    let fmpy = |ssp: &Path, out: &str| {
        python(&[
            &tool("ssp_check.py"),
            ssp.to_str().unwrap(),
            "--fmpy",
            "--stop",
            "10",
            "--save",
            d.join(out).to_str().unwrap(),
            "--json",
        ]);
        std::fs::read(d.join(out)).unwrap()
    };
    assert!(
        fmpy(&fitted, "fmpy_fitted.csv") == fmpy(&with_answer, "fmpy_answer.csv"),
        "FMPy's simulate_ssp: the fitted SSP's run differs from the bench's with the answer"
    );
    let oms = |ssp: &Path, out: &str| {
        common::run_omsimulator(
            d,
            args![
                ssp,
                "--stopTime=10",
                format!("--resultFile={}", d.join(out).display())
            ],
        );
        std::fs::read(d.join(out)).unwrap()
    };
    let (a, b) = (
        oms(&fitted, "oms_fitted.csv"),
        oms(&with_answer, "oms_answer.csv"),
    );
    assert!(a.len() > 100_000, "OMSimulator wrote {} bytes", a.len());
    assert!(
        a == b,
        "OMSimulator: the fitted SSP's run differs from the bench's with the answer"
    );
}

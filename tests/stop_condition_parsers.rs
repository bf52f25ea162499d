//! `tools/fmpy_cosim.py` (FMPy's master as twinbench runs it, the cross-check) keeps its own
//! copy of two lists: the master algorithms and the stop condition's parser. Both must
//! agree with the Rust ones, or the cross-check silently runs something else.

mod common;

use std::io::Write;
use std::process::{Command, Stdio};
use tb_cosim::plan::Condition;
use tb_cosim::Algorithm;

/// Conditions, good and bad, that tell parsers apart.
const CASES: &[&str] = &[
    "vehicle.lap >= 1",
    " vehicle.lap>=1 ",
    "a.b <= -2.5",
    "a.b > 1e3",
    "a.b < .5",
    "a.b >= 5.",
    "a.b >= +7",
    "a.b > 1E-3",
    "a.b >=1",
    "a.b.c >= 1",
    "a.b >= inf",
    "a.b >= nan",
    "a.b >= 1_000",
    "a.b >= ١",
    "a.b >= ",
    "a.b = 1",
    "lap >= 1",
    ".b >= 1",
    "a. >= 1",
    "a.b >= 1 >= 2",
    "a.b <> 1",
    "a.b => 1",
    "lap",
    "",
];

const SCRIPT: &str = r#"
import json, sys
sys.path.insert(0, sys.argv[1])
import fmpy_cosim as f
cases = json.load(sys.stdin)
print(json.dumps({"algorithms": list(f.ALGORITHMS), "parsed": [f.parse_condition(c) for c in cases]}))
"#;

#[test]
fn fmpy_cosim_parses_conditions_and_names_algorithms_as_twinbench_does() {
    let tools = twinbench::pack::workspace_root().join("tools");
    let mut child = Command::new(common::python::python())
        .args(["-c", SCRIPT, tools.to_str().unwrap()])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(serde_json::to_string(CASES).unwrap().as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    common::cli::assert_success(&out);
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let names: Vec<&str> = Algorithm::ALL.iter().map(|a| a.name()).collect();
    let theirs: Vec<&str> = v["algorithms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|a| a.as_str().unwrap())
        .collect();
    assert_eq!(theirs, names, "tools/fmpy_cosim.py ALGORITHMS");
    for (case, theirs) in CASES.iter().zip(v["parsed"].as_array().unwrap()) {
        let ours = Condition::parse(case).map(|(s, op, t)| serde_json::json!([s, op.symbol(), t]));
        assert_eq!(
            ours.as_ref().unwrap_or(&serde_json::Value::Null),
            theirs,
            "the parsers disagree on {case:?}"
        );
    }
}

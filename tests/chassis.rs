//! The vehicle's `chassis_model` (an FMI Enumeration) through the orchestrator: set by an
//! item's name or its number in `--set` (a system file and a study take the same values),
//! and anything else refused naming the two items.

mod common;

use std::process::Command;

/// `twinbench run systems/rls_v.toml --set <set>` (one lap): its output, and the CSV's text.
fn run(dir: &std::path::Path, tag: &str, set: Option<&str>) -> (std::process::Output, String) {
    common::fmu_dir();
    let csv = dir.join(format!("{tag}.csv"));
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_twinbench"));
    cmd.arg("run")
        .arg(twinbench::pack::workspace_root().join("systems/rls_v.toml"))
        .arg("--out")
        .arg(&csv);
    if let Some(s) = set {
        cmd.args(["--set", s]);
    }
    let out = cmd.output().unwrap();
    let text = std::fs::read_to_string(&csv).unwrap_or_default();
    (out, text)
}

#[test]
fn chassis_model_is_set_by_name_or_number_and_anything_else_is_refused() {
    let dir = tb_testkit::scratch("chassis-model");
    let (o, first) = run(dir.path(), "default", None);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, by_name) = run(
        dir.path(),
        "name",
        Some("vehicle.chassis_model=second_order"),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (o, by_number) = run(dir.path(), "number", Some("vehicle.chassis_model=2"));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The same run either way, and another than the first-order chassis'.
    assert_eq!(by_name, by_number);
    assert_ne!(by_name, first);
    let (o, one) = run(dir.path(), "one", Some("vehicle.chassis_model=first_order"));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(one, first, "first_order is the default");
    for (bad, said) in [
        (
            "third_order",
            "'third_order' is not an item of the Enumeration 'vehicle.chassis_model'",
        ),
        (
            "3",
            "3 is not an item of the Enumeration 'vehicle.chassis_model'",
        ),
        (
            "0",
            "0 is not an item of the Enumeration 'vehicle.chassis_model'",
        ),
    ] {
        let (o, _) = run(
            dir.path(),
            "bad",
            Some(&format!("vehicle.chassis_model={bad}")),
        );
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{bad} was taken");
        assert!(err.contains(said), "{err}");
        assert!(err.contains("1 'first_order', 2 'second_order'"), "{err}");
    }
}

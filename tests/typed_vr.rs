//! FMI 2.0 value references are unique per base type only (section 2.2.7): a supplier FMU
//! (`tests/cfmus/typed_vr.c`) with a Real, an Integer and a Boolean on each of value
//! references 0 (outputs y, n, b), 1 (inputs u, k, on) and 2 (parameters gain, count, flag),
//! and OpenModelica-style aliases (a local alias of the parameter gain, an output alias of
//! the input u). Each path that keys a variable proves it keeps the three apart: signal
//! slots and recording, connection checks, parameters, replays, traces, isolated workers,
//! SSP export and import; and the instance alone equals FMPy.

mod common;

use common::run_ok_in;
use std::path::{Path, PathBuf};
use std::process::Command;
use tb_cosim::Table;

/// Inputs of instance `a`: u a ramp, k and on switching at 0.5 s (two rows: the value
/// before and the value from then on).
const INPUT: &str = "time,u,k,on\n0,1,2,0\n0.5,1.5,2,0\n0.5,1.5,7,1\n1,2,7,1\n";

/// Two instances of the FMU: `a` driven by a replay, `b` by `a`'s three outputs on value
/// reference 0, into its three inputs on value reference 1.
fn system(dir: &Path) -> PathBuf {
    let fmu = common::cfmu::fmu("typed_vr");
    std::fs::write(dir.join("in.csv"), INPUT).unwrap();
    let text = format!(
        r#"connections = [
    "in.u -> a.u", "in.k -> a.k", "in.on -> a.on",
    "a.y -> b.u", "a.n -> b.k", "a.b -> b.on",
]

[fmus]
typed = "{}"

[[instance]]
name = "a"
fmu = "typed"

[[instance]]
name = "b"
fmu = "typed"

[[replay]]
name = "in"
file = "in.csv"
basis = "time"

[parameters]
"a.gain" = 3.0
"a.count" = 5
"a.flag" = true

[experiment]
step = 0.1
stop = 1.0

[record]
signals = ["a.y", "a.n", "a.b", "a.u_echo", "a._D_gainAlias", "b.y", "b.n", "b.b", "b.u_echo", "b._D_gainAlias"]
"#,
        fmu.display()
    );
    let path = dir.join("typed.toml");
    std::fs::write(&path, text).unwrap();
    path
}

fn column<'a>(t: &'a Table, name: &str) -> &'a [f64] {
    t.require(name).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn a_real_an_integer_and_a_boolean_on_one_value_reference_are_three_signals() {
    let dir = tb_testkit::scratch("typed-vr");
    let sys = system(dir.path());
    run_ok_in(dir.path(), ["run", "typed.toml", "--out", "out.csv"]);
    let t = Table::read_any(&dir.path().join("out.csv")).unwrap();
    let time = column(&t, "time");
    assert_eq!(time.len(), 11);
    let xor = |a: f64, b: f64| ((a != 0.0) ^ (b != 0.0)) as i32 as f64;
    let late = |t: f64| (t >= 0.5) as i32 as f64;
    let (gain, count, flag) = (3.0, 5.0, 1.0);
    let (mut a_y, mut a_n, mut a_b) = (vec![], vec![], vec![]);
    for (k, &tk) in time.iter().enumerate() {
        // A step from t_{k-1} to t_k computes the outputs from the inputs set at t_{k-1}
        // (at 0.5 s the replay gives the value from then on, as FMPy does).
        let tp = if k == 0 { 0.0 } else { time[k - 1] };
        let u = 1.0 + tp;
        let (kin, on) = if tp >= 0.5 { (7.0, 1.0) } else { (2.0, 0.0) };
        a_y.push(gain * u + tk);
        a_n.push(count * kin + k as f64);
        a_b.push(xor(xor(on, flag), late(tk)));
        let at = |c: &str| column(&t, c)[k];
        assert!(
            (at("a.y") - a_y[k]).abs() < 1e-12,
            "a.y at {tk}: {}",
            at("a.y")
        );
        assert_eq!(at("a.n"), a_n[k], "a.n at {tk}");
        assert_eq!(at("a.b"), a_b[k], "a.b at {tk}");
        // The aliases: one value under two names.
        assert_eq!(at("a._D_gainAlias"), gain);
        assert_eq!(at("b._D_gainAlias"), 2.0, "b keeps its start value");
        // b's inputs: a's outputs at t_k (Gauss-Seidel: a steps first; b's own start
        // values gain 2, count 3).
        assert!(
            (at("b.y") - (2.0 * a_y[k] + tk)).abs() < 1e-12,
            "b.y at {tk}: {}",
            at("b.y")
        );
        assert_eq!(at("b.n"), 3.0 * a_n[k] + k as f64, "b.n at {tk}");
        assert_eq!(at("b.b"), xor(a_b[k], late(tk)), "b.b at {tk}");
        // u_echo is u: what was set last (a's input of the next step, or of this one).
        let a_u = at("a.u_echo");
        assert!(
            a_u == 1.0 + tk || a_u == 1.0 + tp,
            "a.u_echo at {tk}: {a_u}"
        );
        assert_eq!(at("b.u_echo"), a_y[k], "b.u_echo at {tk}");
    }

    // Isolated: the same bits.
    run_ok_in(
        dir.path(),
        ["run", "typed.toml", "--isolate", "--out", "isolated.csv"],
    );
    assert_eq!(
        std::fs::read(dir.path().join("out.csv")).unwrap(),
        std::fs::read(dir.path().join("isolated.csv")).unwrap(),
        "isolated run differs"
    );

    // SSP export and import (SSP has no replays: a's inputs are start values here; the
    // parameters of three types on value reference 2 and the connections between value
    // references 0 and 1 go through the SSD and SSV): the package runs to the same bits.
    let text = std::fs::read_to_string(&sys).unwrap();
    let text = text
        .replace("\"in.u -> a.u\", \"in.k -> a.k\", \"in.on -> a.on\",", "")
        .replace(
            "[[replay]]\nname = \"in\"\nfile = \"in.csv\"\nbasis = \"time\"\n",
            "",
        )
        .replace(
            "\"a.flag\" = true",
            "\"a.flag\" = true\n\"a.u\" = 1.5\n\"a.k\" = 4\n\"a.on\" = true",
        );
    std::fs::write(dir.path().join("inputs.toml"), text).unwrap();
    run_ok_in(dir.path(), ["run", "inputs.toml", "--out", "inputs.csv"]);
    run_ok_in(
        dir.path(),
        ["export-ssp", "inputs.toml", "--out", "typed.ssp"],
    );
    run_ok_in(dir.path(), ["run", "typed.ssp", "--out", "ssp.csv"]);
    let direct = Table::read_any(&dir.path().join("inputs.csv")).unwrap();
    let ssp = Table::read_any(&dir.path().join("ssp.csv")).unwrap();
    // a.n = count·k + steps = 5·4 + k; b.n = 3·a.n + k.
    assert_eq!(column(&direct, "a.n")[3], 23.0);
    assert_eq!(column(&direct, "b.n")[3], 72.0);
    for name in direct.names() {
        assert_eq!(
            column(&ssp, name),
            column(&direct, name),
            "{name} through SSP"
        );
    }

    // The trace names each value by its own type's variable.
    run_ok_in(
        dir.path(),
        [
            "run",
            "typed.toml",
            "--trace-fmi",
            "trace.txt",
            "--trace-instances",
            "b",
        ],
    );
    let trace = std::fs::read_to_string(dir.path().join("trace.txt")).unwrap();
    for expected in [
        "fmi2SetReal(vr=[1 u=",
        "fmi2SetInteger(vr=[1 k=",
        "fmi2SetBoolean(vr=[1 on=",
        "fmi2GetInteger(vr=[0 n=",
        "fmi2GetBoolean(vr=[0 b=",
    ] {
        assert!(trace.contains(expected), "no '{expected}' in\n{trace}");
    }
    drop(sys);
}

#[test]
fn the_instance_alone_equals_fmpy_with_parameters_of_three_types_on_one_value_reference() {
    let dir = tb_testkit::scratch("typed-vr-fmpy");
    let fmu = common::cfmu::fmu("typed_vr");
    std::fs::write(dir.path().join("in.csv"), INPUT).unwrap();
    let theirs = dir.path().join("fmpy.csv");
    let r = Command::new(common::python::python())
        .arg(twinbench::pack::workspace_root().join("tools/fmpy_simulate.py"))
        .arg(&fmu)
        .arg(&theirs)
        .args(["--stop", "1", "--step", "0.1", "--input"])
        .arg(dir.path().join("in.csv"))
        .args(["--set", "gain=3", "--set", "count=5", "--set", "flag=1"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let sys = system(dir.path());
    // Only instance a, whose outputs FMPy records.
    let text = std::fs::read_to_string(&sys).unwrap().replace(
        "signals = [\"a.y\", \"a.n\", \"a.b\", \"a.u_echo\", \"a._D_gainAlias\", \"b.y\", \"b.n\", \"b.b\", \"b.u_echo\", \"b._D_gainAlias\"]",
        "signals = [\"a.y\", \"a.n\", \"a.b\", \"a.u_echo\"]",
    );
    std::fs::write(&sys, text).unwrap();
    run_ok_in(dir.path(), ["run", "typed.toml", "--out", "ours.csv"]);
    let ours = Table::read_any(&dir.path().join("ours.csv")).unwrap();
    let theirs = Table::read_any(&theirs).unwrap();
    assert_eq!(ours.len(), theirs.len());
    for name in ["y", "n", "b", "u_echo"] {
        let (a, b) = (column(&ours, &format!("a.{name}")), column(&theirs, name));
        for (k, (x, y)) in a.iter().zip(b).enumerate() {
            // Integers and Booleans exactly; Reals to 1e-12 (FMPy interpolates the input as
            // w0·v0 + w1·v1, twinbench as v0 + w·(v1 − v0): a few ulp apart).
            assert!(
                (x - y).abs() <= 1e-12 * y.abs().max(1.0),
                "{name} row {k}: twinbench {x}, FMPy {y}"
            );
        }
    }
}

#[test]
fn one_value_reference_of_two_types_is_connected_twice_and_set_twice() {
    // "already connected" and a parameter of one type overwriting another's were the
    // symptoms of keying on the value reference alone.
    let dir = tb_testkit::scratch("typed-vr-set");
    system(dir.path());
    let o = run_ok_in(
        dir.path(),
        [
            "run",
            "typed.toml",
            "--set",
            "a.count=4",
            "--set",
            "a.gain=0.5",
            "--json",
            "--out",
            "set.csv",
        ],
    );
    assert!(o.status.success());
    let t = Table::read_any(&dir.path().join("set.csv")).unwrap();
    assert_eq!(column(&t, "a._D_gainAlias")[0], 0.5);
    // n = count·k + steps at t = 0: 4·2.
    assert_eq!(column(&t, "a.n")[0], 8.0);
    // flag = true from the file still holds (a Boolean on the same value reference).
    assert_eq!(column(&t, "a.b")[0], 1.0);
}

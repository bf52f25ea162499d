//! FMI 3.0 beside FMI 2.0: a system mixing a Reference FMU built as FMI 3.0 with
//! twinbench's own FMI 2.0 FMUs, unit conversion across them, FMU state save/restore and
//! serialization through the 3.0 API, and what is refused before the first step (clocks,
//! Scheduled Execution, another platform's binary).

mod common;

use common::kinds::{invalid, refused3};

use common::reference;
use std::path::{Path, PathBuf};
use tb_cosim::{Simulation, SystemError, SystemFile};
use tb_fmi::{FmuCache, FmuError, FmuInstance};
use tb_testkit::assert_contains;

/// FMI 3.0 Feedthrough as a supplier's speed sensor: its continuous Float64 input and output
/// declared in `unit`, an angular speed of `factor` (else 1) rad/s (the C code passes the
/// value through whatever the unit).
fn sensor(dir: &Path, name: &str, unit: &str, factor: Option<&str>) -> PathBuf {
    let factor = factor.map_or(String::new(), |f| format!(" factor=\"{f}\""));
    let base = format!("s=\"-1\" rad=\"1\"{factor}");
    let fmu = reference::fmu("Feedthrough", 3);
    reference::with_description(&fmu, dir, name, |xml| {
        xml.replacen(
                "<TypeDefinitions>",
                &format!(
                    "<UnitDefinitions><Unit name=\"{unit}\"><BaseUnit {base}/></Unit></UnitDefinitions>\n  <TypeDefinitions>"
                ),
                1,
            )
            .replace(
                "name=\"Float64_continuous_input\"",
                &format!("name=\"Float64_continuous_input\" unit=\"{unit}\""),
            )
            .replace(
                "name=\"Float64_continuous_output\"",
                &format!("name=\"Float64_continuous_output\" unit=\"{unit}\""),
            )
    })
}

fn run(dir: &Path, text: &str) -> Result<(tb_cosim::Table, Vec<String>), SystemError> {
    let path = dir.join("system.toml");
    let file = SystemFile::parse(text, &path)?;
    let plan = common::compile(file, &path)?;
    let notes = plan.notes.clone();
    let mut sim = Simulation::new(plan)?;
    sim.echo_fmu_log = false;
    sim.run()?;
    Ok((sim.recording().clone(), notes))
}

/// The dyno (our FMI 2.0 FMU, rad/s) drives an FMI 3.0 sensor in rpm, whose output drives
/// a second FMI 3.0 sensor in rad/s: the value arrives converted, and back to rad/s it
/// equals the dyno's speed. Once in process, once with the FMI 3.0 units isolated.
#[test]
fn fmi3_and_fmi2_in_one_system_with_unit_conversion() {
    let dir = tb_testkit::scratch("fmi3-mixed");
    let rpm = sensor(dir.path(), "sensor_rpm", "rpm", Some("0.10471975511965977"));
    let rad_s = sensor(dir.path(), "sensor_rad_s", "rad/s", None);
    for isolate in [false, true] {
        let text = format!(
            r#"connections = [
    "dyno.omega -> rpm.Float64_continuous_input",
    "rpm.Float64_continuous_output -> back.Float64_continuous_input",
]
[fmus]
dyno = "{dyno}"
rpm = "{rpm}"
back = "{back}"

[[instance]]
name = "dyno"
fmu = "dyno"

[[instance]]
name = "rpm"
fmu = "rpm"
isolate = {isolate}

[[instance]]
name = "back"
fmu = "back"
isolate = {isolate}

[parameters]
"dyno.omega_start" = 151.971
"dyno.torque_setpoint" = 0.0

[experiment]
step = 1e-3
stop = 0.05
algorithm = "gauss-seidel"

[record]
signals = ["dyno.omega", "rpm.Float64_continuous_output", "back.Float64_continuous_output"]
"#,
            dyno = common::fmu("dyno").display(),
            rpm = rpm.display(),
            back = rad_s.display(),
        );
        let (t, _) = run(dir.path(), &text).unwrap();
        let omega = t.require("dyno.omega").unwrap();
        let in_rpm = t.require("rpm.Float64_continuous_output").unwrap();
        let back = t.require("back.Float64_continuous_output").unwrap();
        // Torque-free, the dyno keeps its speed: every row compares with the same value
        // whatever the exchange's one-step lag.
        assert!(
            omega.iter().all(|w| (w - 151.971).abs() < 1e-9),
            "{omega:?}"
        );
        for k in 1..t.len() {
            let expected = omega[k] * 60.0 / (2.0 * std::f64::consts::PI);
            assert!(
                (in_rpm[k] - expected).abs() <= 1e-12 * expected,
                "row {k}: {} rpm, expected {expected} (isolate {isolate})",
                in_rpm[k]
            );
            assert!(
                (back[k] - omega[k]).abs() <= 1e-12 * omega[k],
                "row {k}: {} rad/s back, dyno {} (isolate {isolate})",
                back[k],
                omega[k]
            );
        }
    }
}

/// Save, restore and serialize through fmi3GetFMUState/SetFMUState/SerializeFMUState: a
/// restored run repeats the original bit for bit; reset starts over.
#[test]
fn fmi3_state_save_restore_serialize_and_reset() {
    let cache = FmuCache::temporary(false).unwrap();
    let fmu = cache.load(&reference::fmu("VanDerPol", 3)).unwrap();
    let md = &fmu.description;
    let x0 = md.variable("x0").unwrap().value_reference;
    let mut i = tb_fmi::Instance3::instantiate(
        fmu.library3().unwrap(),
        md,
        "vdp",
        Some(&fmu.resource_dir()),
        false,
    )
    .unwrap();
    i.setup_experiment(0.0.into()).unwrap();
    i.enter_initialization_mode().unwrap();
    i.exit_initialization_mode().unwrap();
    let h = 0.01;
    let steps = |i: &mut tb_fmi::Instance3, from: usize, n: usize| -> Vec<f64> {
        let mut out = Vec::new();
        for k in from..from + n {
            i.do_step(k as f64 * h, h).unwrap();
            let mut x = [0.0];
            i.get_real(&[x0], &mut x).unwrap();
            out.push(x[0]);
        }
        out
    };
    steps(&mut i, 0, 50);
    let state = i.get_state().unwrap();
    let bytes = i.serialize_state(&state).unwrap();
    assert!(!bytes.is_empty());
    let first = steps(&mut i, 50, 50);
    i.set_state(&state, 0.5).unwrap();
    let again = steps(&mut i, 50, 50);
    assert_eq!(
        first.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        again.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
    let restored = i.deserialize_state(&bytes).unwrap();
    i.set_state(&restored, 0.5).unwrap();
    let third = steps(&mut i, 50, 50);
    assert_eq!(first, third);
    i.free_state(state).unwrap();
    i.free_state(restored).unwrap();
    // Reset: back to the start values (x0 = 2).
    i.reset().unwrap();
    let mut x = [0.0];
    i.get_real(&[x0], &mut x).unwrap();
    assert_eq!(x[0], 2.0);
    i.terminate().ok();
}

/// What twinbench cannot run is refused when the system loads, naming the .fmu and what
/// it needs.
fn refused(fmu: &Path, dir: &Path) -> SystemError {
    let text = format!(
        "[fmus]\nm = \"{}\"\n\n[[instance]]\nname = \"m\"\nfmu = \"m\"\n\n[experiment]\nstep = 0.1\nstop = 1.0\n",
        fmu.display()
    );
    let Err(e) = run(dir, &text) else {
        panic!("{} was not refused", fmu.display())
    };
    assert!(
        e.to_string().contains(&fmu.display().to_string()),
        "names the file: {e}"
    );
    e
}

#[test]
fn an_fmi3_fmu_that_needs_clocks_is_refused_before_the_first_step() {
    let dir = tb_testkit::scratch("fmi3-clocks");
    let vdp = reference::fmu("VanDerPol", 3);
    let clocked = reference::with_description(&vdp, dir.path(), "clocked", |xml| {
        xml.replacen(
                "</ModelVariables>",
                "  <Clock name=\"tick\" valueReference=\"1001\" causality=\"input\" intervalVariability=\"constant\" intervalDecimal=\"0.1\"/>\n  </ModelVariables>",
                1,
            )
    });
    let e = refused(&clocked, dir.path());
    assert!(
        matches!(&e, SystemError::Fmu(FmuError::Description { path, .. }) if *path == clocked),
        "{e}"
    );
    assert_contains(&e.to_string(), &["clocks", "'tick' is a Clock"]);
    // The Clocks Reference FMU: Scheduled Execution only.
    let clocks = reference::variant(
        &vdp,
        dir.path(),
        "scheduled",
        |_| std::fs::read_to_string(reference::sources().join("Clocks/FMI3.xml")).unwrap(),
        |n| Some(n.replace("VanDerPol", "Clocks")),
    );
    let e = refused(&clocks, dir.path());
    assert!(
        matches!(&e, SystemError::Fmu(FmuError::Description { path, .. }) if *path == clocks),
        "{e}"
    );
    assert_contains(&e.to_string(), &["supports Scheduled Execution only; twinbench runs FMUs through Co-Simulation or Model Exchange"]);
}

#[test]
fn an_fmi3_fmu_built_for_another_platform_is_refused() {
    let dir = tb_testkit::scratch("fmi3-platform");
    let vdp = reference::fmu("VanDerPol", 3);
    let windows = reference::variant(
        &vdp,
        dir.path(),
        "windows",
        |xml| xml.to_string(),
        |n| {
            Some(
                n.replace("x86_64-linux", "x86_64-windows")
                    .replace(".so", ".dll"),
            )
        },
    );
    let e = refused(&windows, dir.path());
    assert!(
        matches!(&e, SystemError::Fmu(FmuError::Archive { path, .. }) if *path == windows),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &[
            "no binaries/x86_64-linux/VanDerPol.so",
            "it has binaries for x86_64-windows",
        ],
    );
}

/// A 64-bit integer beyond 2^53 cannot travel exactly as a double: an error naming the
/// variable, never a rounded value.
#[test]
fn a_64_bit_integer_an_f64_cannot_carry_is_an_error_naming_it() {
    let dir = tb_testkit::scratch("fmi3-int64");
    let fmu = reference::fmu("Feedthrough", 3);
    let text = common::system_text(
        "",
        &[("m", &fmu)],
        "[[instance]]\nname = \"m\"\nfmu = \"m\"\n\n[parameters]\n\"m.Int64_input\" = 9007199254740993\n\n[experiment]\nstep = 0.1\nstop = 1.0\n\n[record]\nsignals = [\"m.Int64_output\"]\n",
    );
    let Err(e) = run(dir.path(), &text) else {
        panic!("not refused")
    };
    assert!(invalid(&e, "parameter \"m.Int64_input\""), "{e}");
    assert_contains(
        &e.to_string(),
        &["'m.Int64_input': 9007199254740993 cannot be carried exactly"],
    );
}

/// Binary values travel as hexadecimal text: set from the system file, connected from one
/// instance to another and recorded; text that is not hexadecimal is refused naming the
/// variable.
#[test]
fn binary_variables_are_set_connected_and_recorded_as_hex_text() {
    let dir = tb_testkit::scratch("fmi3-binary");
    let fmu = reference::fmu("Feedthrough", 3);
    let text = |value: &str| {
        format!(
            "connections = [\"a.Binary_output -> b.Binary_input\"]\n[fmus]\nm = \"{}\"\n\n[[instance]]\nname = \"a\"\nfmu = \"m\"\n\n[[instance]]\nname = \"b\"\nfmu = \"m\"\n\n[parameters]\n\"a.Binary_input\" = \"{value}\"\n\n[experiment]\nstep = 0.5\nstop = 1.0\n\n[record]\nsignals = [\"a.Binary_output\", \"b.Binary_output\"]\n",
            fmu.display()
        )
    };
    let (t, _) = run(dir.path(), &text("00ff 7F")).unwrap();
    for k in [1, 2] {
        let col = t.text_at(k).unwrap();
        assert_eq!(col.len(), 3);
        assert!(col.iter().all(|v| v == "00ff7f"), "{col:?}");
    }
    let Err(e) = run(dir.path(), &text("abc")) else {
        panic!("odd hex digits accepted")
    };
    // Refused by twinbench before the FMU sees it.
    assert!(
        matches!(&e, SystemError::Fmu(FmuError::Instantiate { instance, .. }) if instance == "a"),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["'Binary_input' is Binary: \"abc\" is not an even number of hexadecimal digits"],
    );
}

/// The FMU's log messages reach the error of a refused call (the FMI 3.0 logger).
#[test]
fn an_fmi3_error_carries_the_fmus_log() {
    let cache = FmuCache::temporary(false).unwrap();
    let fmu = cache.load(&reference::fmu("Dahlquist", 3)).unwrap();
    let mut i = tb_fmi::Instance3::instantiate(
        fmu.library3().unwrap(),
        &fmu.description,
        "d",
        Some(&fmu.resource_dir()),
        true,
    )
    .unwrap();
    i.set_echo(false);
    // A step before initialisation is an illegal call sequence.
    let e = i.do_step(0.0, 0.1).unwrap_err();
    assert!(refused3(&e, "d", "fmi3DoStep", 3, 0.0), "{e}");
    assert!(
        matches!(&e, FmuError::Call { log, .. } if !log.is_empty()),
        "{e}"
    );
    assert_contains(&e.to_string(), &["the FMU's last messages"]);
}

/// Red team N28: an isolated FMI 3.0 FMU's error was named `fmi2DoStep` and `[fmi2Error]`.
#[test]
fn an_isolated_fmi3_error_names_the_fmi3_call_and_status() {
    use tb_cosim::backend::BackendFactory;
    let cache = FmuCache::temporary(false).unwrap();
    let fmu = cache.load(&reference::fmu("Dahlquist", 3)).unwrap();
    let factory = tb_cosim::isolated::IsolatedFactory {
        run: tb_cosim::backend::RunAs::default_for(&fmu),
        fmu,
        options: common::worker_options().isolation,
    };
    let mut b = factory.create("d", true).unwrap();
    // A step before initialisation is an illegal call sequence.
    let e = b.do_step(0.0, 0.1).unwrap_err();
    assert!(refused3(&e, "d", "fmi3DoStep", 3, 0.0), "{e}");
    assert!(!e.to_string().contains("fmi2"), "{e}");
}

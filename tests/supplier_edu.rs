//! The supplier EDU (a pythonfmu FMU with its own names and units, tools/supplier_edu/)
//! swapped into the bench through the port map: the lap, the unit conversions, and the
//! same physics as the reference EDU open-loop.
//!
//! The FMU and the libpython link are built by `tools/test.sh` (tools/supplier_edu/build.py).
//! Every test of this binary shares one FMU cache, so that pythonfmu's library (and the
//! Python interpreter it starts) is loaded once per process.

mod common;

use std::f64::consts::PI;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tb_cosim::{Plan, RunSummary, Simulation, SystemFile, Table};
use tb_fmi::FmuCache;
use tb_testkit::assert_contains;

const RPM: f64 = PI / 30.0;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

/// The built supplier FMU and the libpython link beside it; a clear failure when missing.
fn supplier_fmu() -> (PathBuf, PathBuf) {
    let fmu = root().join("target/fmu/supplier_edu.fmu");
    let lib = root().join("target/fmu/libpython.so");
    assert!(
        fmu.exists() && lib.exists(),
        "{} or {} is missing: build the pythonfmu supplier EDU with \
         `target/venv/bin/python tools/supplier_edu/build.py` (tools/test.sh does)",
        fmu.display(),
        lib.display()
    );
    (fmu, lib)
}

fn cache() -> Arc<FmuCache> {
    common::shared_cache()
}

fn run(system: Plan) -> (RunSummary, Table) {
    let mut sim = Simulation::new(system).unwrap();
    sim.echo_fmu_log = false;
    let s = sim.run().unwrap();
    (s, sim.recording().clone())
}

fn load(path: &Path) -> Plan {
    common::fmu_dir();
    supplier_fmu();
    Plan::load(path, cache()).unwrap()
}

#[test]
fn the_supplier_edu_drives_the_lap_within_one_percent_of_the_reference() {
    let sup = load(&root().join("systems/rls_v_supplier.toml"));
    // The conversions derived from the declared units: 1 -> % and rad/s -> rpm.
    let conv = |text: &str| {
        let c = sup
            .connections
            .iter()
            .find(|c| c.text == text)
            .unwrap_or_else(|| panic!("no connection {text}"));
        (c.scale, c.offset)
    };
    assert_eq!(conv("driver.accel_pedal -> edu.accel_pedal"), (100.0, 0.0));
    for side in [
        "dyno_rl.omega -> edu.omega_left",
        "dyno_rr.omega -> edu.omega_right",
    ] {
        let (scale, offset) = conv(side);
        assert!(
            (scale - 30.0 / PI).abs() < 1e-12 && offset == 0.0,
            "{side}: {scale}"
        );
    }
    assert_eq!(conv("edu.torque_left -> dyno_rl.shaft_torque"), (1.0, 0.0));

    let (s_sup, r_sup) = run(sup);
    let (s_ref, r_ref) = run(load(&root().join("systems/rls_v.toml")));
    let (lap_sup, lap_ref) = (
        s_sup.value("vehicle.lap_time").unwrap(),
        s_ref.value("vehicle.lap_time").unwrap(),
    );
    eprintln!(
        "lap time: reference EDU {lap_ref:.4} s, supplier EDU {lap_sup:.4} s ({:+.2e} relative); \
         wall time {:.2} s vs {:.2} s",
        lap_sup / lap_ref - 1.0,
        s_ref.wall_time,
        s_sup.wall_time
    );
    // Within 1% (acceptance); the same equations and sub-steps make it agree to ~1e-10.
    assert!(
        (lap_sup / lap_ref - 1.0).abs() < 0.01,
        "supplier {lap_sup} s vs reference {lap_ref} s"
    );

    // The recorded supplier ports are in its own units (the units row says so).
    let unit = |name: &str| {
        let k = r_sup.names().iter().position(|n| n == name).unwrap();
        r_sup.units().unwrap()[k].clone()
    };
    assert_eq!(unit("edu.motor_speed"), "rpm");
    assert_eq!(unit("edu.accel_pedal"), "%");
    assert_eq!(unit("edu.electric_power"), "kW");
    let col = |name: &str| r_sup.require(name).unwrap();
    // The pedal arrives in percent.
    for (p_pct, p) in col("edu.accel_pedal").iter().zip(col("driver.accel_pedal")) {
        assert!((p_pct - 100.0 * p).abs() < 1e-9, "{p_pct} % vs {p}");
    }
    // Motor speed [rpm]·π/30 = 17.86 × wheel speed [rad/s] up to the side shafts' twist
    // rate: the shaft mode (~14 Hz) rings after pedal steps (measured here: RMS 3.6 rad/s,
    // at most 47 rad/s, of ~2700 rad/s).
    let (wl, wr) = (col("dyno_rl.omega"), col("dyno_rr.omega"));
    let n_motor = col("edu.motor_speed");
    let (mut sq, mut worst, mut mean) = (0.0f64, 0.0f64, 0.0f64);
    for (k, n) in n_motor.iter().enumerate() {
        let d = n * RPM - 17.86 * 0.5 * (wl[k] + wr[k]);
        sq += d * d;
        worst = worst.max(d.abs());
        mean += n * RPM / n_motor.len() as f64;
    }
    let rms = (sq / n_motor.len() as f64).sqrt();
    assert!(
        rms < 0.005 * mean && worst < 0.03 * mean,
        "motor speed vs 17.86 x wheel speed: RMS {rms} rad/s, max {worst} rad/s (mean motor speed {mean} rad/s)"
    );
    // And the supplier's motor speed is the reference EDU's, converted.
    let rows = r_sup.len().min(r_ref.len());
    let (n_sup, w_ref) = (
        col("edu.motor_speed"),
        r_ref.require("edu.motor_speed").unwrap(),
    );
    let (p_sup, p_ref) = (
        col("edu.electric_power"),
        r_ref.require("edu.electric_power").unwrap(),
    );
    for k in 0..rows {
        assert!(
            (n_sup[k] * RPM - w_ref[k]).abs() < 1e-3,
            "row {k}: {} rpm vs {} rad/s",
            n_sup[k],
            w_ref[k]
        );
        assert!(
            (p_sup[k] * 1000.0 - p_ref[k]).abs() < 1.0,
            "row {k}: {} kW vs {} W",
            p_sup[k],
            p_ref[k]
        );
    }
}

/// Reference and supplier EDU side by side, inputs held (set in each FMU's own unit).
fn open_loop(pedal: f64, omega_wheel: f64, omega_start: f64) -> Table {
    let text = open_loop_system(pedal, omega_wheel, omega_start);
    let path = std::env::temp_dir().join(format!("tb-supplier-open-{}.toml", std::process::id()));
    let file = SystemFile::parse(&text, &path).unwrap();
    let sys = Plan::from_file(file, &path, cache()).unwrap();
    assert!(sys.warnings.is_empty(), "{:?}", sys.warnings);
    run(sys).1
}

/// The open-loop system file (both EDUs, inputs held, libpython preloaded).
fn open_loop_system(pedal: f64, omega_wheel: f64, omega_start: f64) -> String {
    let (fmu, lib) = supplier_fmu();
    format!(
        r#"preload = ["{lib}"]
[fmus]
edu = "{edu}"
supplier_edu = "{fmu}"

[[instance]]
name = "ref"
fmu = "edu"

[[instance]]
name = "sup"
fmu = "supplier_edu"

[parameters]
"ref.accel_pedal" = {pedal}
"ref.omega_left" = {omega_wheel}
"ref.omega_right" = {omega_wheel}
"ref.omega_wheel_start" = {omega_start}
"sup.PedalPosition" = {pct}
"sup.n_WheelLeft" = {n}
"sup.n_WheelRight" = {n}
"sup.n_WheelStart" = {n0}

[experiment]
step = 1e-3
stop = 0.5

[record]
signals = ["ref.motor_speed", "ref.motor_torque", "ref.torque_left", "ref.torque_right",
    "ref.electric_power", "sup.n_Motor", "sup.T_Motor", "sup.T_ShaftLeft", "sup.T_ShaftRight",
    "sup.P_Electric"]
"#,
        lib = lib.display(),
        edu = common::fmu("edu").display(),
        fmu = fmu.display(),
        pct = 100.0 * pedal,
        n = omega_wheel / RPM,
        n0 = omega_start / RPM,
    )
}

#[test]
fn isolated_the_supplier_edu_is_preloaded_and_loaded_only_in_its_worker() {
    // `preload` is applied in each worker; the host loads neither libpython nor the FMU's
    // library (glibc's loader, with LD_DEBUG=files, names every library each process loads).
    let dir = tb_testkit::scratch("supplier-iso");
    let sys = dir.path().join("open.toml");
    std::fs::write(&sys, open_loop_system(0.6, 150.0, 150.0)).unwrap();
    let csv = dir.path().join("open.csv");
    let child = std::process::Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args(["run", sys.to_str().unwrap(), "--isolate", "--out"])
        .arg(&csv)
        .env("LD_DEBUG", "files")
        // The confined worker's environment is an allowlist: the loader's debugging asked
        // for by name.
        .env("TWINBENCH_WORKER_ENV", "LD_DEBUG")
        .stderr(std::process::Stdio::piped())
        .stdout(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let host = child.id();
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success(),
        "{}",
        &err[err.len().saturating_sub(3000)..]
    );
    let loads = |pid: u32, what: &str| {
        err.lines().any(|l| {
            l.trim_start().starts_with(&format!("{pid}:"))
                && l.contains("file=")
                && l.contains(what)
        })
    };
    assert!(
        !loads(host, "SupplierEdu.so") && !loads(host, "libpython"),
        "the host loaded FMU code"
    );
    assert!(
        err.contains("SupplierEdu.so") && err.contains("libpython"),
        "no worker loaded it"
    );
    // `info` checks the library in a worker too, with the preload; without it, the missing
    // Python symbols are named with the .fmu (not the unpacked copy).
    let (fmu, lib) = supplier_fmu();
    let info = |args: &[&std::ffi::OsStr]| {
        std::process::Command::new(env!("CARGO_BIN_EXE_twinbench"))
            .arg("info")
            .args(args)
            .output()
            .unwrap()
    };
    let out = info(&[
        "--isolate".as_ref(),
        "--preload".as_ref(),
        lib.as_os_str(),
        fmu.as_os_str(),
    ]);
    common::cli::assert_success(&out);
    assert!(String::from_utf8_lossy(&out.stdout)
        .contains("library: binaries/linux64/SupplierEdu.so loads; fmi2GetVersion \"2.0\""));
    let out = info(&["--isolate".as_ref(), fmu.as_os_str()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_contains(
        &err,
        &[&format!(
            "{}: cannot load shared library: binaries/linux64/SupplierEdu.so: undefined symbol",
            fmu.display()
        )],
    );
    // The same numbers as in-process.
    let isolated = Table::read_any(&csv).unwrap();
    let in_process = open_loop(0.6, 150.0, 150.0);
    for name in ["sup.n_Motor", "sup.T_Motor", "ref.motor_speed"] {
        assert_eq!(
            isolated.require(name).unwrap(),
            in_process.require(name).unwrap(),
            "{name}"
        );
    }
}

#[test]
fn open_loop_the_supplier_edu_has_the_reference_physics() {
    common::fmu_dir();
    // Driving into the power limit, regenerative braking (the gearbox loss changes side),
    // and a motor starting slower than the wheels (the shafts drive it up).
    for (pedal, omega, omega0) in [(0.6, 150.0, 150.0), (-0.4, 150.0, 150.0), (1.0, 20.0, 15.0)] {
        let rec = open_loop(pedal, omega, omega0);
        let c = |n: &str| rec.require(n).unwrap();
        let pairs: [(&str, &str, f64); 5] = [
            ("ref.motor_speed", "sup.n_Motor", RPM),
            ("ref.motor_torque", "sup.T_Motor", 1.0),
            ("ref.torque_left", "sup.T_ShaftLeft", 1.0),
            ("ref.torque_right", "sup.T_ShaftRight", 1.0),
            ("ref.electric_power", "sup.P_Electric", 1000.0),
        ];
        assert_eq!(rec.len(), 501);
        for (ours, theirs, factor) in pairs {
            let (a, b) = (c(ours), c(theirs));
            let scale = a.iter().fold(1.0f64, |m, x| m.max(x.abs()));
            for k in 0..rec.len() {
                assert!(
                    (a[k] - factor * b[k]).abs() <= 1e-9 * scale,
                    "pedal {pedal}, row {k}: {ours} = {} vs {theirs} = {} (x{factor})",
                    a[k],
                    b[k]
                );
            }
        }
        // Something happened: the motor torque went to the request.
        let t_end = *c("sup.T_Motor").last().unwrap();
        assert!(
            t_end.abs() > 10.0 && t_end.signum() == pedal.signum(),
            "{t_end}"
        );
    }
}

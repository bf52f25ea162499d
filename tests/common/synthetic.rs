//! Synthetic laps the suite makes with the twin itself: a circuit unlike Spielberg
//! (straights and constant-radius corners) or Spielberg's own, the twin's lap there with
//! known parameters, and that lap as a logger would give it (plain names, SI units), with
//! measurement noise of a realistic autocorrelation when asked.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

pub const WHEEL_RADIUS: f64 = 0.345;

/// The car the synthetic laps are made with: lift coefficients and geometry (the FMUs'
/// defaults are 1.653, 2.027, 3.10, 1.55, 1.50: a study starts there).
pub const TRUTH: [(&str, f64); 5] = [
    ("vehicle.c_lift_front", 0.95),
    ("vehicle.c_lift_rear", 1.25),
    ("vehicle.l", 2.85),
    ("vehicle.b_front", 1.45),
    ("vehicle.b_rear", 1.40),
];

/// A circuit: its track and target files (None: the bench's bundled Spielberg) and the
/// start speed [m/s].
pub struct Circuit {
    pub track: Option<PathBuf>,
    pub target: Option<PathBuf>,
    pub v0: f64,
}

/// The suite's own circuit, written into `dir`.
pub fn own_circuit(dir: &Path) -> Circuit {
    let (track, target, v0) = circuit();
    write_circuit(dir, &track, &target, v0)
}

/// A circuit of this track and target (files written into `dir`) and start speed.
fn write_circuit(dir: &Path, track: &str, target: &str, v0: f64) -> Circuit {
    let track_p = dir.join("circuit_track.csv");
    let target_p = dir.join("truth_target.csv");
    std::fs::write(&track_p, track).unwrap();
    std::fs::write(&target_p, target).unwrap();
    Circuit {
        track: Some(track_p),
        target: Some(target_p),
        v0,
    }
}

/// Spielberg, the bench's bundled circuit (its track is `data/spielberg_lap_track.csv`).
pub fn spielberg() -> Circuit {
    Circuit {
        track: None,
        target: None,
        v0: 52.43,
    }
}

/// A closed circuit of straights and constant-radius corners (curvature per 1 m row) and a
/// feasible target speed over it.
pub fn circuit() -> (String, String, f64) {
    let segments: [(usize, f64); 12] = [
        (420, 0.0),
        (140, 1.0 / 55.0),
        (260, 0.0),
        (190, -1.0 / 95.0),
        (380, 0.0),
        (110, 1.0 / 40.0),
        (230, 0.0),
        (170, -1.0 / 70.0),
        (150, 0.0),
        (200, 1.0 / 120.0),
        (300, 0.0),
        (90, -1.0 / 35.0),
    ];
    let kappa: Vec<f64> = segments
        .iter()
        .flat_map(|&(n, k)| std::iter::repeat_n(k, n))
        .collect();
    let n = kappa.len();
    // Corner speed from a lateral acceleration of 11 m/s², at most 62 m/s; then braking at
    // 11 m/s² and accelerating at 5 m/s², twice round the lap (it is periodic).
    let mut v: Vec<f64> = kappa
        .iter()
        .map(|k| {
            if *k == 0.0 {
                62.0
            } else {
                (11.0 / k.abs()).sqrt().min(62.0)
            }
        })
        .collect();
    for _ in 0..2 {
        for i in (0..2 * n).rev() {
            let (a, b) = (i % n, (i + 1) % n);
            v[a] = v[a].min((v[b] * v[b] + 2.0 * 11.0).sqrt());
        }
        for i in 1..2 * n {
            let (a, b) = (i % n, (i - 1) % n);
            v[a] = v[a].min((v[b] * v[b] + 2.0 * 5.0).sqrt());
        }
    }
    let mut track = String::from("s,curvature,grade,z_road_left,z_road_right\n");
    for (i, k) in kappa.iter().enumerate() {
        let _ = writeln!(track, "{i},{k},0,0,0");
    }
    let mut target = String::from("s,v\n");
    for (i, x) in v.iter().enumerate() {
        let _ = writeln!(target, "{i},{x}");
    }
    let _ = writeln!(target, "{n},{}", v[0]);
    (track, target, v[0])
}

/// The suite's own circuit with a road under it: both wheel tracks' heights a smooth random
/// profile (AR(1) over distance with a 5 m correlation length, the two tracks half
/// correlated) of `rms` [m], from `seed`; written into `dir`.
pub fn own_circuit_with_road(dir: &Path, rms: f64, seed: u64) -> Circuit {
    let (track, target, v0) = circuit();
    let mut rng = tb_testkit::Noise::new(seed);
    let rho: f64 = (-1.0f64 / 5.0).exp();
    let gain = (1.0 - rho * rho).sqrt();
    let (mut common, mut left, mut right) = (0.0, 0.0, 0.0);
    let mut text = String::new();
    for (i, line) in track.lines().enumerate() {
        if i == 0 {
            text.push_str(line);
            text.push('\n');
            continue;
        }
        common = rho * common + gain * rng.gauss();
        left = rho * left + gain * rng.gauss();
        right = rho * right + gain * rng.gauss();
        let f: Vec<&str> = line.split(',').collect();
        let half = std::f64::consts::FRAC_1_SQRT_2;
        let _ = writeln!(
            text,
            "{},{},{},{},{}",
            f[0],
            f[1],
            f[2],
            rms * half * (common + left),
            rms * half * (common + right)
        );
    }
    write_circuit(dir, &text, &target, v0)
}

/// The twin's lap on `circuit` with `truth` set: its recording.
pub fn truth_lap(dir: &Path, circuit: &Circuit, truth: &[(&str, f64)]) -> tb_table::Table {
    truth_lap_with(dir, circuit, truth, "")
}

/// [`truth_lap`] with further `[parameters]` lines (`"vehicle.chassis_model" = "second_order"`).
pub fn truth_lap_with(
    dir: &Path,
    circuit: &Circuit,
    truth: &[(&str, f64)],
    lines: &str,
) -> tb_table::Table {
    let fmu_dir = super::fmu_dir();
    let mut params = String::new();
    if let (Some(track), Some(target)) = (&circuit.track, &circuit.target) {
        let _ = writeln!(
            params,
            "\"vehicle.track_file\" = {:?}\n\"driver.target_speed_file\" = {:?}",
            track.display().to_string(),
            target.display().to_string()
        );
    }
    let _ = writeln!(
        params,
        "\"vehicle.v_start\" = {v0:?}\n\"dyno_rl.omega_start\" = {w:?}\n\"dyno_rr.omega_start\" = {w:?}\n\"edu.omega_wheel_start\" = {w:?}",
        v0 = circuit.v0,
        w = circuit.v0 / WHEEL_RADIUS,
    );
    for (n, x) in truth {
        let _ = writeln!(params, "\"{n}\" = {x:?}");
    }
    params.push_str(lines);
    let bundled =
        std::fs::read_to_string(twinbench::pack::workspace_root().join("systems/rls_v.toml"))
            .unwrap();
    let start = bundled.find("[parameters]").unwrap();
    let end = bundled.find("# The vehicle's track and").unwrap();
    // The bench's own parameters (the car's driveline, the driver's feed-forward) stay, as
    // `twinbench lap` keeps them; the start values are the circuit's.
    let kept: String = bundled[start + "[parameters]".len()..end]
        .lines()
        .filter(|l| l.starts_with('"') && !l.contains("_start\""))
        .filter(|l| !params.contains(l.split('=').next().unwrap_or("").trim()))
        .map(|l| format!("{l}\n"))
        .collect();
    let text = format!(
        "{}[parameters]\n{kept}{params}\n{}",
        &bundled[..start],
        &bundled[end..]
    )
    .replace("\"../target/fmu/", &format!("\"{}/", fmu_dir.display()));
    let sys = dir.join("truth.toml");
    std::fs::write(&sys, text).unwrap();
    let raw = dir.join("truth_run.csv");
    super::run_ok(crate::args!["run", sys, "--out", raw]);
    tb_table::Table::read_path(&raw).unwrap()
}

/// Measurement noise on the wheel loads: AR(1) in time with correlation `rho` per sample
/// and standard deviation `sigma` [N], from `seed`.
#[derive(Clone, Copy, Debug)]
pub struct Noise {
    pub sigma: f64,
    pub rho: f64,
    pub seed: u64,
}

/// The lap as a logger's measurement file (CSV, plain names, SI units row) at `path`.
pub fn measurement(lap: &tb_table::Table, path: &Path, noise: Option<Noise>) -> PathBuf {
    let cols = [
        ("time", "time", "s"),
        ("distance", "vehicle.distance", "m"),
        ("v", "vehicle.v", "m/s"),
        ("a_x", "vehicle.a_x", "m/s2"),
        ("a_y", "vehicle.a_y", "m/s2"),
        ("Fz_fl", "vehicle.Fz_fl", "N"),
        ("Fz_fr", "vehicle.Fz_fr", "N"),
        ("Fz_rl", "vehicle.Fz_rl", "N"),
        ("Fz_rr", "vehicle.Fz_rr", "N"),
    ];
    let mut columns: Vec<Vec<f64>> = cols
        .iter()
        .map(|c| lap.require(c.1).unwrap().to_vec())
        .collect();
    if let Some(n) = noise {
        let mut rng = tb_testkit::Noise::new(n.seed);
        for col in columns.iter_mut().skip(5) {
            let mut e = 0.0;
            for x in col.iter_mut() {
                e = n.rho * e + (1.0 - n.rho * n.rho).sqrt() * rng.gauss();
                *x += n.sigma * e;
            }
        }
    }
    let meas = tb_table::Table::from_columns(
        "measurement",
        cols.iter().map(|c| c.0.to_string()).collect(),
        columns,
    )
    .unwrap()
    .with_units(cols.iter().map(|c| c.2.to_string()).collect())
    .unwrap();
    meas.write_csv(path).unwrap();
    path.to_path_buf()
}

/// `twinbench ARGS...` must succeed: its standard output (else the test fails with its
/// standard error).
pub fn twinbench(args: &[&str]) -> Vec<u8> {
    super::run_ok(args).stdout
}

/// `twinbench lap MEASUREMENT... [--track TRACK]... --out OUT --fmus <the packed FMUs>
/// EXTRA...` must succeed.
pub fn lap(measurements: &[&Path], tracks: &[&Path], out: &Path, extra: &[&str]) {
    let mut args = vec!["lap".to_string()];
    args.extend(measurements.iter().map(|m| m.display().to_string()));
    for t in tracks {
        args.extend(["--track".to_string(), t.display().to_string()]);
    }
    let fmus = super::fmu_dir();
    args.extend([
        "--out".to_string(),
        out.display().to_string(),
        "--fmus".to_string(),
        fmus.display().to_string(),
    ]);
    args.extend(extra.iter().map(|a| a.to_string()));
    super::run_ok(&args);
}

/// `twinbench optimize STUDY --json EXTRA... --out OUT` must succeed: its JSON answer.
pub fn optimize(study: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["optimize", study.to_str().unwrap(), "--json"];
    args.extend(extra);
    args.extend(["--out", out.to_str().unwrap()]);
    serde_json::from_slice(&twinbench(&args)).unwrap()
}

/// The driver of a system `twinbench lap` wrote follows the truth lap's own target (its
/// circuit's file; `None`: the bundled Spielberg target) instead of the one derived from
/// the measured speed: the twin is then exactly the model that made the lap.
pub fn drive_truth_target(system: &Path, target: Option<&Path>) {
    let text = std::fs::read_to_string(system).unwrap();
    let line = "\"driver.target_speed_file\" = \"target_speed.csv\"";
    assert!(text.contains(line), "{text}");
    let with = match target {
        Some(t) => format!(
            "\"driver.target_speed_file\" = {:?}",
            t.display().to_string()
        ),
        None => String::new(),
    };
    std::fs::write(system, text.replace(line, &with)).unwrap();
}

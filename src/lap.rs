//! A new lap for the packed FMUs (`twinbench lap`): from a vehicle measurement of any
//! circuit, the driver's target speed, the vehicle's track (a given one, or one derived from
//! the measurement), a system file of the RLS/v bench with every start value set from the
//! measurement, and the paper's two-step study against it. Nothing is rebuilt: the FMUs read
//! the files through `vehicle.track_file` and `driver.target_speed_file`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use tb_compare::{ChannelMap, Measurement};

/// Spacing of the target speed and of a derived track [m].
pub const SPACING_M: f64 = 1.0;
/// Centred moving average of the target speed [samples of `SPACING_M`]: drops the
/// measurement's sample-to-sample noise, keeps braking points sharp (9 m is about 0.2 s at
/// braking speeds).
pub const TARGET_WINDOW: usize = 9;
/// Centred moving average of a derived track's curvature [samples]: a_y/v² carries the
/// logger's noise; 9 m (as the target speed) keeps corner entries where they are (with 25 m
/// the track widths fitted on a derived track were 1 % further off).
pub const TRACK_WINDOW: usize = 9;
/// Below this speed a_y/v² says nothing about the curvature [m/s].
pub const MIN_SPEED_FOR_CURVATURE: f64 = 5.0;

#[derive(Debug, thiserror::Error)]
pub enum LapError {
    #[error(transparent)]
    Measurement(#[from] tb_compare::Error),
    #[error("{0}")]
    Invalid(String),
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// What `lap` is given.
#[derive(Clone, Debug)]
pub struct LapOptions {
    pub measurement: PathBuf,
    pub channels: ChannelMap,
    /// A track file to use; None: derive one from the measurement.
    pub track: Option<PathBuf>,
    pub out: PathBuf,
    /// Where the packed FMUs are.
    pub fmu_dir: PathBuf,
}

/// What `lap` wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LapFiles {
    pub target_speed: PathBuf,
    pub track: PathBuf,
    pub system: PathBuf,
    pub study: PathBuf,
    /// Measured lap length [m] and time [s].
    pub lap_length: f64,
    pub lap_time: f64,
    /// The start values set from the measurement's first sample.
    pub v_start: f64,
    pub omega_start: f64,
    pub track_derived: bool,
    pub warnings: Vec<String>,
}

/// The lap's length: the last distance plus the last sample's travel (the lap closes one
/// sample after the last one).
pub fn lap_length(m: &Measurement) -> Result<f64, LapError> {
    let (t, d) = (m.time(), m.distance());
    let v = m.require("v")?;
    let n = t.len();
    if n < 3 {
        return Err(LapError::Invalid(format!(
            "{}: {n} samples are too few for a lap",
            m.table().source()
        )));
    }
    Ok(d[n - 1] + v[n - 1] * (t[n - 1] - t[n - 2]))
}

/// `v` resampled onto `grid` by distance (linear, held at the ends).
fn speed_on(d: &[f64], v: &[f64], grid: &[f64]) -> Vec<f64> {
    let mut j = 0;
    grid.iter()
        .map(|&s| {
            while j + 1 < d.len() - 1 && d[j + 1] < s {
                j += 1;
            }
            let span = d[j + 1] - d[j];
            let w = if span > 0.0 {
                ((s - d[j]) / span).clamp(0.0, 1.0)
            } else {
                0.0
            };
            v[j] + w * (v[j + 1] - v[j])
        })
        .collect()
}

/// Centred moving average over `window` samples, the series taken as periodic (a flying
/// lap ends where it starts).
fn periodic_average(x: &[f64], window: usize) -> Vec<f64> {
    let half = (window / 2) as isize;
    let m = x.len() as isize;
    (0..m)
        .map(|k| {
            (-half..=half)
                .map(|i| x[(k + i).rem_euclid(m) as usize])
                .sum::<f64>()
                / (2 * half + 1) as f64
        })
        .collect()
}

/// The driver's target speed over distance: v on a 1 m grid, smoothed over 9 m periodically,
/// rows `s,v` from 0 to the lap length, the last repeating the first speed so that the
/// target closes on itself.
pub fn target_speed_csv(m: &Measurement) -> Result<String, LapError> {
    let (d, v) = (m.distance(), m.require("v")?);
    let lap = lap_length(m)?;
    let mut n = (lap / SPACING_M).floor() as usize;
    if lap - n as f64 * SPACING_M < 0.5 * SPACING_M {
        n -= 1; // the closing row at least half a spacing after the last grid row
    }
    let grid: Vec<f64> = (0..=n).map(|k| k as f64 * SPACING_M).collect();
    let smooth = periodic_average(&speed_on(d, v, &grid), TARGET_WINDOW);
    let mut out = String::from("s,v\n");
    for (s, x) in grid.iter().zip(&smooth) {
        let _ = writeln!(out, "{s:.3},{x:.4}");
    }
    let _ = writeln!(out, "{lap:.3},{:.4}", smooth[0]);
    Ok(out)
}

/// A track derived from the measurement: curvature a_y/v² (where v is above 5 m/s) on an
/// even grid that closes the lap, smoothed over 25 m; no grade, no road profile.
pub fn derived_track_csv(m: &Measurement) -> Result<String, LapError> {
    let (d, v) = (m.distance(), m.require("v")?);
    let a_y = m.signal("a_y")?.ok_or_else(|| {
        LapError::Invalid(format!(
            "{}: no track given (--track) and no a_y to derive one from",
            m.table().source()
        ))
    })?;
    let lap = lap_length(m)?;
    let n = (lap / SPACING_M).round().max(2.0) as usize;
    let ds = lap / n as f64;
    let curvature: Vec<f64> = v
        .iter()
        .zip(a_y)
        .map(|(&v, &a)| {
            if v.abs() >= MIN_SPEED_FOR_CURVATURE {
                a / (v * v)
            } else {
                0.0
            }
        })
        .collect();
    let grid: Vec<f64> = (0..n).map(|k| k as f64 * ds).collect();
    let kappa = periodic_average(&speed_on(d, &curvature, &grid), TRACK_WINDOW);
    let mut out = String::from("s,curvature,grade,z_road_left,z_road_right\n");
    for (s, k) in grid.iter().zip(&kappa) {
        let _ = writeln!(out, "{s:.4},{k:.8},0,0,0");
    }
    Ok(out)
}

fn write(path: &Path, text: &str) -> Result<(), LapError> {
    tb_table::write_atomic(path, text.as_bytes()).map_err(|source| LapError::Io {
        path: path.to_path_buf(),
        source,
    })
}

fn toml_string(s: &str) -> String {
    toml::Value::String(s.to_string()).to_string()
}

/// The system file of the RLS/v bench for the lap.
fn system_toml(o: &LapOptions, name: &str, v0: f64, w0: f64, lap_time: f64) -> String {
    let fmu = |f: &str| toml_string(&o.fmu_dir.join(f).display().to_string());
    format!(
        r#"# The RLS/v bench on a lap of its own: prepared by `twinbench lap` from
# {meas}. The FMUs are the packed ones; the track and the driver's target speed are the
# files beside this one (a relative *_file path is relative to this file).
name = {name}

connections = [
    "vehicle.v -> driver.v",
    "vehicle.s -> driver.s",
    "driver.accel_pedal -> edu.accel_pedal",
    "driver.brake_pedal -> vehicle.brake_pedal",
    "vehicle.torque_setpoint_rl -> dyno_rl.torque_setpoint",
    "vehicle.torque_setpoint_rr -> dyno_rr.torque_setpoint",
    "edu.torque_left -> dyno_rl.shaft_torque",
    "edu.torque_right -> dyno_rr.shaft_torque",
    "dyno_rl.omega -> vehicle.omega_rl",
    "dyno_rr.omega -> vehicle.omega_rr",
    "dyno_rl.omega -> edu.omega_left",
    "dyno_rr.omega -> edu.omega_right",
]

[fmus]
vehicle = {vehicle}
driver = {driver}
dyno = {dyno}
edu = {edu}

[[instance]]
name = "vehicle"
fmu = "vehicle"

[[instance]]
name = "driver"
fmu = "driver"

[[instance]]
name = "dyno_rl"
fmu = "dyno"

[[instance]]
name = "dyno_rr"
fmu = "dyno"

[[instance]]
name = "edu"
fmu = "edu"

# The flying lap starts at the measured speed: vehicle, wheels and EDU.
[parameters]
"vehicle.track_file" = "track.csv"
"driver.target_speed_file" = "target_speed.csv"
"vehicle.v_start" = {v0:?}
"dyno_rl.omega_start" = {w0:?}
"dyno_rr.omega_start" = {w0:?}
"edu.omega_wheel_start" = {w0:?}

# The vehicle's track and the driver's target speed must be the same lap.
[[check]]
equal = ["vehicle.lap_length", "driver.lap_length"]
relative_tolerance = 0.005
why = "the vehicle's track and the driver's target speed are not the same lap"

[experiment]
step = 1e-3
stop = "vehicle.lap >= 1"
report = ["vehicle.lap_time"]
max_time = {max_time:?}
algorithm = "gauss-seidel"

[record]
signals = [
    "vehicle.distance", "vehicle.s", "vehicle.v", "vehicle.a_x", "vehicle.a_y",
    "vehicle.Fz_fl", "vehicle.Fz_fr", "vehicle.Fz_rl", "vehicle.Fz_rr", "vehicle.Fz_sum",
    "driver.v_target", "driver.accel_pedal", "driver.brake_pedal",
    "dyno_rl.omega", "dyno_rr.omega", "edu.motor_speed", "edu.motor_torque",
]
decimation = 5
"#,
        meas = o.measurement.display(),
        name = toml_string(name),
        vehicle = fmu("vehicle.fmu"),
        driver = fmu("driver.fmu"),
        dyno = fmu("dyno.fmu"),
        edu = fmu("edu.fmu"),
        max_time = (2.0 * lap_time + 30.0).ceil(),
    )
}

/// The paper's two-step study against the measurement.
fn study_toml(o: &LapOptions, name: &str) -> String {
    let mut channels = String::new();
    for (signal, channel) in &o.channels.0 {
        let _ = writeln!(
            channels,
            "{} = {}",
            toml_string(signal),
            toml_string(channel)
        );
    }
    format!(
        r#"# The paper's two-step optimisation on this lap: prepared by `twinbench lap`. Run it with
#   twinbench optimize {study_path}
name = {name}
system = "system.toml"
seed = 2024
penalty = 10.0
bias_weight = 1.0

[measurement]
file = {file}

[measurement.channels]
{channels}
[compare]
cutoff_hz = 2.0
filter_order = 2
distance_step_m = 1.0

[record]
signals = [
    "vehicle.distance", "vehicle.v", "vehicle.a_x", "vehicle.a_y",
    "vehicle.Fz_fl", "vehicle.Fz_fr", "vehicle.Fz_rl", "vehicle.Fz_rr",
]
decimation = 10

[optimizer]
kind = "cmaes"
generations = 22

[optimizer.cmaes]
population = 8
sigma0 = 0.2

# Step 1: the lift coefficients, validated on the axle sums.
[[step]]
name = "lift"
signals = ["Fz_front", "Fz_rear", "Fz_sum"]
[[step.parameter]]
name = "vehicle.c_lift_front"
min = 0.2
max = 2.5
[[step.parameter]]
name = "vehicle.c_lift_rear"
min = 0.2
max = 2.5

# Step 2: the virtual geometry, validated on the four wheel loads.
[[step]]
name = "geometry"
signals = ["Fz_rl", "Fz_rr", "Fz_fl", "Fz_fr"]
[[step.parameter]]
name = "vehicle.l"
min = 2.0
max = 4.5
[[step.parameter]]
name = "vehicle.b_front"
min = 0.9
max = 2.0
[[step.parameter]]
name = "vehicle.b_rear"
min = 0.9
max = 2.0
"#,
        study_path = o.out.join("study.toml").display(),
        name = toml_string(name),
        file = toml_string(&absolute(&o.measurement).display().to_string()),
    )
}

fn absolute(p: &Path) -> PathBuf {
    if p.is_absolute() {
        p.to_path_buf()
    } else {
        std::env::current_dir().unwrap_or_default().join(p)
    }
}

/// The wheel radius the vehicle model starts with (the start values of the wheels' speeds).
fn wheel_radius() -> f64 {
    vehicle::VehicleVars::default().wheel_radius
}

/// Writes the lap's files into `o.out` (created if needed).
pub fn prepare(o: &LapOptions) -> Result<LapFiles, LapError> {
    let m = Measurement::load(&o.measurement, &o.channels)?;
    let mut warnings = Vec::new();
    std::fs::create_dir_all(&o.out).map_err(|source| LapError::Io {
        path: o.out.clone(),
        source,
    })?;
    let mut inputs = vec![o.measurement.as_path()];
    if let Some(t) = &o.track {
        inputs.push(t.as_path());
    }
    for name in ["target_speed.csv", "track.csv", "system.toml", "study.toml"] {
        tb_table::check_output(&o.out.join(name), &inputs).map_err(|source| LapError::Io {
            path: o.out.join(name),
            source,
        })?;
    }
    let lap = lap_length(&m)?;
    let t = m.time();
    let lap_time = t[t.len() - 1] - t[0];
    let target_speed = o.out.join("target_speed.csv");
    write(&target_speed, &target_speed_csv(&m)?)?;
    let track = o.out.join("track.csv");
    let track_derived = o.track.is_none();
    match &o.track {
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|source| LapError::Io {
                path: p.clone(),
                source,
            })?;
            write(&track, &text)?;
        }
        None => {
            write(&track, &derived_track_csv(&m)?)?;
            warnings.push(format!(
                "no --track: {} is derived from the measurement (curvature a_y/v², smoothed over {TRACK_WINDOW} m; no grade, no road profile): give the circuit's track for grade and road excitation",
                track.display()
            ));
        }
    }
    let v0 = m.require("v")?[0];
    let w0 = v0 / wheel_radius();
    let name = o
        .out
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_else(|| "lap".into());
    let system = o.out.join("system.toml");
    write(&system, &system_toml(o, &name, v0, w0, lap_time))?;
    let study = o.out.join("study.toml");
    write(&study, &study_toml(o, &name))?;
    Ok(LapFiles {
        target_speed,
        track,
        system,
        study,
        lap_length: lap,
        lap_time,
        v_start: v0,
        omega_start: w0,
        track_derived,
        warnings,
    })
}

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
/// The shortest lap `lap` prepares [m]: shorter is a car that did not drive a lap (a
/// standing measurement, a few metres of a pit lane).
pub const MIN_LAP_LENGTH_M: f64 = 100.0;
/// The fastest speed a measured sample may have [m/s] (720 km/h): faster is a logger's
/// error value, not a car, and would become the driver's target.
pub const MAX_SPEED_M_S: f64 = 200.0;

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

/// The measurement's reader is `tb-measurement` (below the comparison): its errors are
/// `Measurement` as before, wrapped as the comparison wraps them.
impl From<tb_compare::measurement::Error> for LapError {
    fn from(e: tb_compare::measurement::Error) -> Self {
        LapError::Measurement(e.into())
    }
}

/// What `lap` is given.
#[derive(Clone, Debug)]
pub struct LapOptions {
    pub measurement: PathBuf,
    pub channels: ChannelMap,
    /// A track file to use; None: derive one from the measurement.
    pub track: Option<PathBuf>,
    pub out: PathBuf,
    /// Where the packed FMUs are; None: pack them into `<out>/fmu`, so that the lap's folder
    /// needs nothing else (it survives the removal of the checkout twinbench was built in).
    pub fmu_dir: Option<PathBuf>,
    /// The vehicle's chassis in the system, and whether the study fits its modes.
    pub chassis: Chassis,
}

/// The vehicle model's chassis (`vehicle.chassis_model`) for a prepared lap.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum Chassis {
    /// The first-order low-pass (the model's default); the study fits lift and geometry.
    #[default]
    FirstOrder,
    /// Sprung pitch and roll modes; the study gets a third step fitting their frequencies
    /// and dampings.
    SecondOrder,
}

impl Chassis {
    /// The four parameters of the second-order chassis (the chassis step's).
    pub const MODE_PARAMETERS: [&'static str; 4] = [
        "vehicle.pitch_frequency",
        "vehicle.pitch_damping",
        "vehicle.roll_frequency",
        "vehicle.roll_damping",
    ];

    /// The chassis a fitted parameter set needs: second order when it has a mode parameter.
    pub fn of_parameters<'a>(names: impl IntoIterator<Item = &'a str>) -> Chassis {
        match names
            .into_iter()
            .any(|n| Chassis::MODE_PARAMETERS.contains(&n))
        {
            true => Chassis::SecondOrder,
            false => Chassis::FirstOrder,
        }
    }
}

/// What `lap` wrote.
#[derive(Clone, Debug, serde::Serialize)]
pub struct LapFiles {
    pub target_speed: PathBuf,
    pub track: PathBuf,
    pub system: PathBuf,
    pub study: PathBuf,
    /// The FMUs packed beside the lap (empty when `--fmus` named packed ones).
    pub fmus: Vec<PathBuf>,
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
    if let Some(k) = v.iter().position(|x| x.abs() > MAX_SPEED_M_S) {
        return Err(LapError::Invalid(format!(
            "{}: sample {} (t = {} s) has v = {:?} m/s, more than the {MAX_SPEED_M_S} m/s a car's lap may have: a logger's error value, or a speed in km/h or mph without its unit declared?",
            m.table().source(),
            k + 1,
            t[k],
            v[k]
        )));
    }
    let length = d[n - 1] + v[n - 1] * (t[n - 1] - t[n - 2]);
    if length.is_nan() || length < MIN_LAP_LENGTH_M {
        return Err(LapError::Invalid(format!(
            "{}: the car covers {length:.1} m in {:.1} s: not a lap (at least {MIN_LAP_LENGTH_M} m; a standing measurement?)",
            m.table().source(),
            t[n - 1] - t[0]
        )));
    }
    Ok(length)
}

/// The units a logger writes wheel loads in, by the factor from newtons: a load channel in
/// one of them without its unit declared reads as that factor times the car's weight.
const LOAD_UNITS: [(&str, f64); 4] = [
    ("N", 1.0),
    ("daN", 0.1),
    ("lbf", 1.0 / 4.448_221_615_260_5),
    ("kN", 1e-3),
];

/// Each load signal's share of the car's weight at rest.
const LOAD_SHARES: [(&str, f64); 7] = [
    ("Fz_sum", 1.0),
    ("Fz_front", 0.5),
    ("Fz_rear", 0.5),
    ("Fz_fl", 0.25),
    ("Fz_fr", 0.25),
    ("Fz_rl", 0.25),
    ("Fz_rr", 0.25),
];

/// A load channel whose scale is not newtons: its mean over the slowest quarter of the lap
/// (little downforce) against its share of the twin's weight m·g. The car's own mass,
/// weight distribution and downforce move that ratio by well under a factor of two; a
/// load in kN, daN or lbf moves it by 1000, 10 or 4.45, so a ratio nearer one of those
/// than 1 refuses the lap with the likely unit named, the file's own channel and the
/// signal it maps to. (A whole study in kN ran to a bias of +119,339 % with every
/// parameter on a bound before this check.)
pub fn check_load_unit(m: &Measurement, map: &ChannelMap, mass: f64) -> Result<(), LapError> {
    let table = m.table();
    let Some(v) = m.signal("v")? else {
        return Ok(());
    };
    let mut sorted: Vec<f64> = v.iter().copied().filter(|x| x.is_finite()).collect();
    if sorted.len() < 8 {
        return Ok(());
    }
    sorted.sort_by(f64::total_cmp);
    let slow = sorted[sorted.len() / 4];
    let weight = mass * 9.81;
    for (signal, share) in LOAD_SHARES {
        let Some(fz) = m.signal(signal)? else {
            continue;
        };
        let (sum, n) = fz
            .iter()
            .zip(v)
            .filter(|(f, v)| **v <= slow && f.is_finite())
            .fold((0.0, 0usize), |(s, n), (f, _)| (s + f, n + 1));
        if n == 0 {
            continue;
        }
        let ratio = sum / n as f64 / (share * weight);
        if ratio.is_nan() || ratio <= 0.0 {
            continue;
        }
        let (unit, factor) = LOAD_UNITS
            .iter()
            .min_by(|a, b| {
                (ratio / a.1)
                    .ln()
                    .abs()
                    .total_cmp(&(ratio / b.1).ln().abs())
            })
            .copied()
            .expect("units listed");
        if unit == "N" {
            continue;
        }
        let channel = match map.0.get(signal) {
            Some(c) => format!("channel `{c}` (the study's {signal})"),
            None => format!("channel `{signal}`"),
        };
        let declared = table
            .names()
            .iter()
            .position(|n| n == signal)
            .and_then(|i| table.units().and_then(|u| u.get(i)))
            .map(|u| u.trim().to_string())
            .filter(|u| !u.is_empty());
        return Err(LapError::Invalid(format!(
            "{}: {channel} looks like {unit}, not N: over the slowest quarter of the lap (v ≤ {slow:.1} m/s) it averages {:.4} of its share ({share}) of the car's weight (m·g = {mass} kg · 9.81 m/s² = {weight:.0} N), about the factor {factor:.4} of {unit}; {}",
            table.source(),
            ratio,
            match declared {
                Some(u) => format!("the file declares `{u}`: correct the unit row (or the MDF channel's unit) to `{unit}`"),
                None => format!("declare its unit (a units row under the CSV header with `{unit}` under it, or the MDF channel's unit)"),
            }
        )));
    }
    Ok(())
}

/// How a speed logged in km/h or mph without a declared unit shows against the other
/// signals: the ratio of the speed read as m/s to the speed the distance or a_x implies.
const SPEED_UNITS: [(&str, f64); 2] = [("km/h", 3.6), ("mph", 3600.0 / 1609.344)];

/// A speed whose unit the file does not declare (no units row, an empty unit) is taken as
/// m/s; one logged in km/h or mph would then be a target 3.6 or 2.24 times too fast. The
/// file's distance column (∫v dt against it) or a_x (dv/dt against it, least squares) shows
/// the factor: within 10 % of km/h's or mph's, the lap is refused with its unit named.
/// Whatever the unit, a speed that disagrees with the file's own distance by more than
/// [`SPEED_AGREEMENT`] (with a_x: twice that) is refused too: a wrong channel or a scale
/// would be a wrong target for the whole study.
pub fn check_speed_unit(m: &Measurement) -> Result<(), LapError> {
    let table = m.table();
    let Some(iv) = table.names().iter().position(|n| n == "v") else {
        return Ok(());
    };
    let declared = table
        .units()
        .is_some_and(|u| u.get(iv).is_some_and(|u| !u.trim().is_empty()));
    let Some((ratio, against, tolerance)) = speed_ratio(m)? else {
        return Ok(());
    };
    let unit = SPEED_UNITS
        .iter()
        .find(|(_, f)| (ratio / f - 1.0).abs() < 0.1);
    match unit {
        Some((unit, f)) if !declared => Err(LapError::Invalid(format!(
            "{}: v has no unit and looks like {unit}, not m/s: read as m/s it is {ratio:.2} times the speed {against} implies ({unit}: {f:.2}); declare its unit (a units row under the CSV header with `{unit}` under v, or the MDF channel's unit)",
            table.source(),
        ))),
        // A logger's error value (1e308) in one sample: named by its sample in
        // [`lap_length`], which says more than the ratio it throws off.
        _ if m.require("v")?.iter().any(|x| x.abs() > MAX_SPEED_M_S) => Ok(()),
        _ if (ratio - 1.0).abs() > tolerance => Err(LapError::Invalid(format!(
            "{}: v is {ratio:.2} times the speed {against} implies (they agree within {:.0} % on a logger's lap): a wrong channel for v, or a speed scaled by a wrong factor{}; check the channel map and the units row",
            table.source(),
            100.0 * tolerance,
            if declared { "" } else { " or in a unit not declared" }
        ))),
        _ => Ok(()),
    }
}

/// How far v may stray from the speed the distance column implies (a logger's distance
/// and speed come from one sensor or from GPS and wheel speed: a few per cent apart).
const SPEED_AGREEMENT: f64 = 0.1;

/// v read as it is against the speed the file's distance column (∫v dt over the distance
/// driven) or a_x (dv/dt against a_x, least squares, both averaged over half a second so
/// that a_x's vibration does not dilute the slope) implies: the ratio, what it was taken
/// against, and how far from 1 it may lie.
fn speed_ratio(m: &Measurement) -> Result<Option<(f64, &'static str, f64)>, LapError> {
    let (t, v) = (m.time(), m.require("v")?);
    let found = match (m.distance_source(), m.signal("a_x")?) {
        (tb_compare::DistanceSource::Column, _) => {
            let d = m.distance();
            // ∫v dt by the trapezoid rule (only its total is needed).
            let integrated: f64 = (1..t.len())
                .map(|k| 0.5 * (v[k] + v[k - 1]) * (t[k] - t[k - 1]))
                .sum();
            let driven = d[d.len() - 1] - d[0];
            (driven > 0.0).then(|| (integrated / driven, "the distance column", SPEED_AGREEMENT))
        }
        (_, Some(ax)) if t.len() > 2 => {
            let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
            let w = ((0.25 / dt).round() as usize).clamp(1, t.len() / 4 + 1);
            let (mut num, mut den) = (0.0, 0.0);
            for k in w..t.len().saturating_sub(w) {
                let dv = (v[k + w] - v[k - w]) / (t[k + w] - t[k - w]);
                let a = ax[k - w..=k + w].iter().sum::<f64>() / (2 * w + 1) as f64;
                num += dv * a;
                den += a * a;
            }
            (den > 0.0).then(|| (num / den, "a_x", 2.0 * SPEED_AGREEMENT))
        }
        _ => None,
    };
    Ok(found.filter(|(r, ..)| r.is_finite()))
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

/// Centred moving average of the target's acceleration [samples]: a_x is measured, not
/// differentiated, and carries little noise; 3 m keep a braking point where it is.
pub const ACCELERATION_WINDOW: usize = 3;

/// The driver's target speed over distance: v on a 1 m grid, with the car's own
/// acceleration (the measured a_x, over 3 m) where the measurement has one, so that the
/// driver's feed-forward is what the car did rather than the slope of a smoothed speed
/// (which rounds every braking point off by the smoothing's length). The speed is smoothed
/// over 3 m as well then (a speed smoothed over 9 m lies 0.2 m/s under the car's at a
/// braking point, and the speed loop braked 2 m early: on a lap the twin made itself the
/// filtered wheel loads of the twin with the true parameters were 9 N RMS, 70 N at most, off
/// the lap's, and 5.5 N, 38 N with 3 m), and over 9 m without a_x (where its slope is the
/// feed-forward and the speed's noise would be differentiated); rows
/// `s,v[,a]` from 0 to the lap length, the last repeating the first so that the target
/// closes on itself.
pub fn target_speed_csv(m: &Measurement) -> Result<String, LapError> {
    let (d, v) = (m.distance(), m.require("v")?);
    let lap = lap_length(m)?;
    let mut n = (lap / SPACING_M).floor() as usize;
    if lap - n as f64 * SPACING_M < 0.5 * SPACING_M {
        n -= 1; // the closing row at least half a spacing after the last grid row
    }
    let grid: Vec<f64> = (0..=n).map(|k| k as f64 * SPACING_M).collect();
    let acceleration = m
        .signal("a_x")?
        .map(|a_x| periodic_average(&speed_on(d, a_x, &grid), ACCELERATION_WINDOW));
    let window = match acceleration {
        Some(_) => ACCELERATION_WINDOW,
        None => TARGET_WINDOW,
    };
    let smooth = periodic_average(&speed_on(d, v, &grid), window);
    let mut out = String::from(if acceleration.is_some() {
        "s,v,a\n"
    } else {
        "s,v\n"
    });
    for (k, (s, x)) in grid.iter().zip(&smooth).enumerate() {
        match &acceleration {
            Some(a) => {
                let _ = writeln!(out, "{s:.3},{x:.4},{:.4}", a[k]);
            }
            None => {
                let _ = writeln!(out, "{s:.3},{x:.4}");
            }
        }
    }
    match &acceleration {
        Some(a) => {
            let _ = writeln!(out, "{lap:.3},{:.4},{:.4}", smooth[0], a[0]);
        }
        None => {
            let _ = writeln!(out, "{lap:.3},{:.4}", smooth[0]);
        }
    }
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

/// The bench's own RLS/v system file, which `lap` edits for a lap (one copy of the bench:
/// a connection or a recorded signal added there is in every lap's system too).
const BENCH_SYSTEM: &str = include_str!("../../../systems/rls_v.toml");

/// The system file of the RLS/v bench for the lap: `systems/rls_v.toml` with the lap's
/// FMUs, files, start values and time budget.
fn system_toml(
    fmu_dir: &Path,
    o: &LapOptions,
    name: &str,
    v0: f64,
    w0: f64,
    lap_time: f64,
) -> String {
    use toml_edit::{value, DocumentMut};
    let mut doc: DocumentMut = BENCH_SYSTEM
        .parse()
        .expect("systems/rls_v.toml is valid TOML (tests/registry.rs parses it)");
    doc["name"] = value(name);
    if let Some(mut key) = doc.key_mut("name") {
        key.leaf_decor_mut().set_prefix(format!(
            "# The RLS/v bench on a lap of its own: prepared by `twinbench lap` from\n# {}.\n# Paths are relative to this file's folder.\n",
            one_line(&o.measurement.display().to_string())
        ));
    }
    let fmus = doc["fmus"]
        .as_table_mut()
        .expect("systems/rls_v.toml has [fmus]");
    let models: Vec<String> = fmus.iter().map(|(k, _)| k.to_string()).collect();
    for model in models {
        fmus[model.as_str()] = value(fmu_dir.join(format!("{model}.fmu")).display().to_string());
    }
    let parameters = doc["parameters"]
        .as_table_mut()
        .expect("systems/rls_v.toml has [parameters]");
    // The bench's own parameters stay (the car the twin stands for: its driveline, the
    // driver's feed-forward); the start values and files are the lap's.
    for start in [
        "vehicle.v_start",
        "dyno_rl.omega_start",
        "dyno_rr.omega_start",
        "edu.omega_wheel_start",
    ] {
        parameters.remove(start);
    }
    parameters.decor_mut().set_prefix(
        "\n# The lap's track and target speed; the flying lap starts at the measured speed.\n",
    );
    parameters["vehicle.track_file"] = value("track.csv");
    parameters["driver.target_speed_file"] = value("target_speed.csv");
    parameters["vehicle.v_start"] = value(v0);
    if o.chassis == Chassis::SecondOrder {
        parameters["vehicle.chassis_model"] = value("second_order");
    }
    for p in [
        "dyno_rl.omega_start",
        "dyno_rr.omega_start",
        "edu.omega_wheel_start",
    ] {
        parameters[p] = value(w0);
    }
    doc["experiment"]["max_time"] = value((2.0 * lap_time + 30.0).ceil());
    doc.to_string()
}

/// A name for a comment line: no line breaks.
fn one_line(s: &str) -> String {
    s.replace(['\n', '\r'], " ")
}

/// A channel map as the lines of a TOML table.
fn channel_lines(channels: &ChannelMap) -> String {
    let mut out = String::new();
    for (signal, channel) in &channels.0 {
        let _ = writeln!(out, "{} = {}", toml_string(signal), toml_string(channel));
    }
    out
}

/// The paper's two-step study against the measurement.
fn study_toml(o: &LapOptions, name: &str) -> String {
    let measurement = format!(
        "[measurement]\nfile = {}\n\n[measurement.channels]\n{}",
        toml_string(
            &as_written_from(&o.out, &o.measurement)
                .display()
                .to_string()
        ),
        channel_lines(&o.channels)
    );
    study_text(
        &o.out.join("study.toml"),
        name,
        "system.toml",
        &measurement,
        o.chassis,
    )
}

/// A `[[step]]` of the paper's study: the comment above it, its name, the signals it is
/// validated on and its parameters with their bounds (as the study file writes them).
struct StudyStep {
    comment: &'static str,
    name: &'static str,
    signals: &'static [&'static str],
    parameters: &'static [(&'static str, &'static str, &'static str)],
}

const LIFT_STEP: StudyStep = StudyStep {
    comment: "# Step 1: the lift coefficients, validated on the axle sums.",
    name: "lift",
    signals: &["Fz_front", "Fz_rear", "Fz_sum"],
    parameters: &[
        ("vehicle.c_lift_front", "0.2", "2.5"),
        ("vehicle.c_lift_rear", "0.2", "2.5"),
    ],
};

const GEOMETRY_STEP: StudyStep = StudyStep {
    comment: "# Step 2: the virtual geometry, validated on the four wheel loads.",
    name: "geometry",
    signals: &["Fz_rl", "Fz_rr", "Fz_fl", "Fz_fr"],
    parameters: &[
        ("vehicle.l", "2.0", "4.5"),
        ("vehicle.b_front", "0.9", "2.0"),
        ("vehicle.b_rear", "0.9", "2.0"),
    ],
};

/// The third step of a study on the second-order chassis: its pitch and roll modes.
const CHASSIS_STEP: StudyStep = StudyStep {
    comment: "# Step 3: the second-order chassis' pitch and roll modes (system.toml sets\n\
              # vehicle.chassis_model = \"second_order\"), validated on the four wheel loads and the\n\
              # accelerations the loads follow.",
    name: "chassis",
    signals: &["Fz_rl", "Fz_rr", "Fz_fl", "Fz_fr"],
    parameters: &[
        ("vehicle.pitch_frequency", "0.5", "8.0"),
        ("vehicle.pitch_damping", "0.1", "1.5"),
        ("vehicle.roll_frequency", "0.5", "8.0"),
        ("vehicle.roll_damping", "0.1", "1.5"),
    ],
};

impl StudyStep {
    /// The step's text, after a blank line.
    fn toml(&self) -> String {
        let signals: Vec<String> = self.signals.iter().map(|s| format!("\"{s}\"")).collect();
        let mut text = format!(
            "\n{}\n[[step]]\nname = \"{}\"\nsignals = [{}]\n",
            self.comment,
            self.name,
            signals.join(", ")
        );
        for (parameter, min, max) in self.parameters {
            let _ = write!(
                text,
                "[[step.parameter]]\nname = \"{parameter}\"\nmin = {min}\nmax = {max}\n"
            );
        }
        text
    }
}

/// The study file's text: its measurement part given (one `[measurement]` or several
/// `[[measurement]]`), the rest the paper's two steps, and with the second-order chassis a
/// third that fits its modes.
fn study_text(
    study_path: &Path,
    name: &str,
    system: &str,
    measurement: &str,
    chassis: Chassis,
) -> String {
    let mut text = format!(
        r#"# The paper's two-step optimisation on this lap: prepared by `twinbench lap`. Run it with
#   twinbench optimize {study_path}
name = {name}
system = {system}
seed = 2024
penalty = 10.0
bias_weight = 1.0

{measurement}
[compare]
cutoff_hz = {cutoff}
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
"#,
        study_path = study_path.display(),
        name = toml_string(name),
        system = toml_string(system),
        // The pitch and roll modes ring at 1.5–3 Hz: a comparison that filters them away
        // (2 Hz, the paper's) could not tell their frequencies apart.
        cutoff = match chassis {
            Chassis::FirstOrder => "2.0",
            Chassis::SecondOrder => "5.0",
        },
    );
    text.push_str(&LIFT_STEP.toml());
    text.push_str(&GEOMETRY_STEP.toml());
    if chassis == Chassis::SecondOrder {
        text.push_str(&CHASSIS_STEP.toml());
    }
    text
}

/// What `lap` wrote for several measurements: each lap in a folder of its own (named after
/// its file), and one study over all of them.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SeveralLaps {
    pub laps: Vec<LapFiles>,
    pub study: PathBuf,
}

/// Several measurements into one study: each prepared as [`prepare`] does into
/// `<out>/<its file's stem>/` (the FMUs packed once into `<out>/fmu`, or `fmu_dir`), and
/// `<out>/study.toml` with a `[[measurement]]` entry per lap (its file, system and
/// channels), fitting the study's parameters on all of them. `tracks`: one for every
/// lap, or one per measurement, or none (each derived from its measurement).
pub fn prepare_several(
    measurements: &[(PathBuf, ChannelMap)],
    tracks: &[PathBuf],
    out: &Path,
    fmu_dir: Option<&Path>,
    chassis: Chassis,
) -> Result<SeveralLaps, LapError> {
    if tracks.len() > 1 && tracks.len() != measurements.len() {
        return Err(LapError::Invalid(format!(
            "{} tracks for {} measurements: give one track for all, or one per measurement in the same order",
            tracks.len(),
            measurements.len()
        )));
    }
    let mut names: Vec<String> = Vec::new();
    for (m, _) in measurements {
        let stem = m
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "lap".into());
        if names.contains(&stem) {
            return Err(LapError::Invalid(format!(
                "{}: another measurement has the same file name '{stem}' (each lap gets a folder of that name): rename one",
                m.display()
            )));
        }
        names.push(stem);
    }
    let created = !out.exists();
    let r = (|| {
        let fmus = match fmu_dir {
            Some(d) => tb_files::absolute(d),
            None => {
                let d = out.join("fmu");
                crate::pack::pack(&[], &d).map_err(|e| LapError::Invalid(e.to_string()))?;
                tb_files::absolute(&d)
            }
        };
        let mut laps = Vec::new();
        let mut entries = String::new();
        for (k, ((m, channels), name)) in measurements.iter().zip(&names).enumerate() {
            let o = LapOptions {
                // As given: a relative one stays relative in the studies (a tree moved as
                // a whole still finds it).
                measurement: m.clone(),
                channels: channels.clone(),
                track: match tracks.len() {
                    0 => None,
                    1 => Some(tracks[0].clone()),
                    _ => Some(tracks[k].clone()),
                },
                out: out.join(name),
                fmu_dir: Some(fmus.clone()),
                chassis,
            };
            let files = prepare(&o)?;
            let _ = write!(
                entries,
                "[[measurement]]\nname = {}\nfile = {}\nsystem = {}\n\n[measurement.channels]\n{}\n",
                toml_string(name),
                toml_string(&as_written_from(out, &o.measurement).display().to_string()),
                toml_string(&format!("{name}/system.toml")),
                channel_lines(channels)
            );
            laps.push(files);
        }
        let study = out.join("study.toml");
        let name = out
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "laps".into());
        let first_system = format!("{}/system.toml", names[0]);
        write(
            &study,
            &study_text(&study, &name, &first_system, &entries, chassis),
        )?;
        Ok(SeveralLaps { laps, study })
    })();
    if r.is_err() && created && out.is_dir() {
        let _ = std::fs::remove_dir_all(out);
    }
    r
}

/// `path` (as given on the command line) as a file in folder `out` must name it: an
/// absolute path as it is, a relative one made relative to `out`, so that the lap's files
/// find it from any working directory (and a tree moved as a whole still does).
fn as_written_from(out: &Path, path: &Path) -> PathBuf {
    if path.is_absolute() {
        return tb_files::normalize(path);
    }
    tb_files::relative_to(&tb_files::absolute(path), &tb_files::absolute(out))
}

/// The bench's check that the vehicle's track and the driver's target are one lap: its
/// relative tolerance, which `lap` also holds a given track to.
fn lap_length_tolerance() -> f64 {
    let doc: toml::Value = toml::from_str(BENCH_SYSTEM).expect("systems/rls_v.toml is valid TOML");
    doc.get("check")
        .and_then(|c| c.as_array())
        .into_iter()
        .flatten()
        .find(|c| {
            c.get("equal")
                .is_some_and(|e| e.to_string().contains("lap_length"))
        })
        .and_then(|c| c.get("relative_tolerance"))
        .and_then(|t| t.as_float())
        .expect("systems/rls_v.toml checks the lap lengths with a relative_tolerance")
}

/// A given track, read and held to the measured lap: a track whose length is not the
/// measured lap's (within the bench's check) is another circuit, or another line on it.
fn given_track(path: &Path, lap: f64) -> Result<String, LapError> {
    let text = tb_files::input::read_to_string(path, tb_files::Limit::DATA).map_err(|source| {
        LapError::Io {
            path: path.to_path_buf(),
            source,
        }
    })?;
    let track = vehicle::track::Track::parse(&path.display().to_string(), &text)
        .map_err(|e| LapError::Invalid(e.to_string()))?;
    let tolerance = lap_length_tolerance();
    let deviation = (track.length() - lap) / lap;
    if deviation.is_nan() || deviation.abs() > tolerance {
        return Err(LapError::Invalid(format!(
            "{}: the track is {:.1} m long, the measured lap {lap:.1} m ({:+.1} %, the bench accepts ±{:.1} %): give the track of the measured circuit, or leave out --track to derive one from the measurement",
            path.display(),
            track.length(),
            100.0 * deviation,
            100.0 * tolerance
        )));
    }
    Ok(text)
}

/// The wheel radius the vehicle model starts with (the start values of the wheels' speeds).
fn wheel_radius() -> f64 {
    vehicle::VehicleVars::default().wheel_radius
}

/// Writes the lap's files into `o.out` (created if needed). A lap refused leaves no
/// folder behind that this call created.
pub fn prepare(o: &LapOptions) -> Result<LapFiles, LapError> {
    let created = !o.out.exists();
    let r = prepare_in(o);
    if r.is_err() && created && o.out.is_dir() {
        let _ = std::fs::remove_dir_all(&o.out);
    }
    r
}

fn prepare_in(o: &LapOptions) -> Result<LapFiles, LapError> {
    let m = Measurement::load(&o.measurement, &o.channels)?;
    check_speed_unit(&m)?;
    check_load_unit(&m, &o.channels, vehicle::VehicleVars::default().m)?;
    // Everything that can refuse the lap before its folder is made.
    let lap = lap_length(&m)?;
    let track_text = match &o.track {
        Some(p) => Some(given_track(p, lap)?),
        None => None,
    };
    let mut warnings = Vec::new();
    if o.chassis == Chassis::SecondOrder {
        warnings.push(format!(
            "--chassis second-order: the study gets a third step fitting the chassis' pitch and roll modes ({}) and compares at 5 Hz; a mode this lap's braking or cornering does not excite runs to its range's end, and Tab. 1 then gives no interval for it (docs/optimize.md, 'The second-order chassis')",
            Chassis::MODE_PARAMETERS.join(", ")
        ));
    }
    std::fs::create_dir_all(&o.out).map_err(|e| {
        LapError::Invalid(format!(
            "{}: cannot create the output folder: {e}",
            o.out.display()
        ))
    })?;
    let mut inputs = vec![o.measurement.as_path()];
    if let Some(t) = &o.track {
        inputs.push(t.as_path());
    }
    let packed: Vec<PathBuf> = match &o.fmu_dir {
        Some(_) => Vec::new(),
        None => crate::pack::models()
            .iter()
            .filter(|s| !s.test_only)
            .map(|s| crate::pack::fmu_path(&o.out.join("fmu"), s))
            .collect(),
    };
    let names = ["target_speed.csv", "track.csv", "system.toml", "study.toml"];
    for path in names
        .iter()
        .map(|n| o.out.join(n))
        .chain(packed.iter().cloned())
    {
        tb_table::check_output(&path, &inputs).map_err(|source| LapError::Io {
            path: path.clone(),
            source,
        })?;
    }
    let t = m.time();
    let lap_time = t[t.len() - 1] - t[0];
    let target_speed = o.out.join("target_speed.csv");
    write(&target_speed, &target_speed_csv(&m)?)?;
    let track = o.out.join("track.csv");
    let track_derived = o.track.is_none();
    match &track_text {
        Some(text) => write(&track, text)?,
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
    let fmu_dir = match &o.fmu_dir {
        Some(d) => as_written_from(&o.out, d),
        None => {
            crate::pack::pack(&[], &o.out.join("fmu"))
                .map_err(|e| LapError::Invalid(e.to_string()))?;
            PathBuf::from("fmu")
        }
    };
    let system = o.out.join("system.toml");
    write(&system, &system_toml(&fmu_dir, o, &name, v0, w0, lap_time))?;
    let study = o.out.join("study.toml");
    write(&study, &study_toml(o, &name))?;
    Ok(LapFiles {
        target_speed,
        track,
        system,
        study,
        fmus: packed,
        lap_length: lap,
        lap_time,
        v_start: v0,
        omega_start: w0,
        track_derived,
        warnings,
    })
}

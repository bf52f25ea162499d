//! `twinbench lap MEASUREMENT... [--track TRACK.csv]... [--channels MAP.toml] --out DIR`:
//! prepares a lap of any circuit for the packed FMUs, or several laps into one study
//! (docs/lap.md).

use std::path::PathBuf;
use tb_compare::ChannelMap;

#[derive(clap::Args, Debug)]
pub struct LapArgs {
    /// The vehicle measurement of the lap: MDF 4 (.mf4) or CSV. Several: each lap is
    /// prepared into a folder of its own and one study fits them all together.
    #[arg(required = true)]
    pub measurements: Vec<PathBuf>,
    /// The circuit's track (CSV: s, curvature, grade, z_road_left, z_road_right); without
    /// it, one is derived from the measurement's a_y/v² (no grade, no road profile). With
    /// several measurements: one track for all, or `--track` once per measurement.
    #[arg(long)]
    pub track: Vec<PathBuf>,
    /// The channel of each signal in the measurement (a TOML file with a `[channels]`
    /// table: v = "GPS_Speed", Fz_rl = "LoadRL", ...).
    #[arg(long, value_name = "MAP.toml")]
    pub channels: Option<PathBuf>,
    /// The folder to write target_speed.csv, track.csv, system.toml and study.toml into.
    #[arg(long, short)]
    pub out: PathBuf,
    /// Where packed FMUs are, to use instead of packing them into `<out>/fmu` (the
    /// default: the lap's folder then needs nothing else). A relative path is written
    /// relative to the output folder, so that it resolves from there.
    #[arg(long)]
    pub fmus: Option<PathBuf>,
    /// The vehicle's chassis: `first-order` (the low-pass; the study fits lift and
    /// geometry) or `second-order` (sprung pitch and roll modes; the study gets a third
    /// step fitting their frequencies and dampings).
    #[arg(long, value_enum, default_value_t = ChassisArg::FirstOrder)]
    pub chassis: ChassisArg,
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
}

/// `--chassis`: [`crate::lap::Chassis`] as the command line spells it (the library has no
/// clap; the names and the help are the ones the enum always had).
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ChassisArg {
    /// The first-order low-pass (the model's default); the study fits lift and geometry.
    FirstOrder,
    /// Sprung pitch and roll modes; the study gets a third step fitting their frequencies
    /// and dampings.
    SecondOrder,
}

impl From<ChassisArg> for crate::lap::Chassis {
    fn from(c: ChassisArg) -> Self {
        match c {
            ChassisArg::FirstOrder => crate::lap::Chassis::FirstOrder,
            ChassisArg::SecondOrder => crate::lap::Chassis::SecondOrder,
        }
    }
}

pub fn run(args: LapArgs) -> anyhow::Result<()> {
    let channels = match &args.channels {
        Some(p) => ChannelMap::read_path(p)?,
        None => ChannelMap::default(),
    };
    if args.measurements.len() > 1 {
        let measurements: Vec<(PathBuf, ChannelMap)> = args
            .measurements
            .iter()
            .map(|m| (m.clone(), channels.clone()))
            .collect();
        let several = crate::lap::prepare_several(
            &measurements,
            &args.track,
            &args.out,
            args.fmus.as_deref(),
            args.chassis.into(),
        )?;
        for w in several.laps.iter().flat_map(|l| &l.warnings) {
            eprintln!("warning: {w}");
        }
        if args.json {
            super::json::print(&serde_json::to_string_pretty(&several)?)?;
        } else {
            for (m, files) in args.measurements.iter().zip(&several.laps) {
                println!(
                    "lap of {}: {:.1} m in {:.3} s, system {}",
                    m.display(),
                    files.lap_length,
                    files.lap_time,
                    files.system.display()
                );
            }
            println!("  study         {}", several.study.display());
            println!("next: twinbench optimize {}", several.study.display());
        }
        return Ok(());
    }
    if args.track.len() > 1 {
        anyhow::bail!(
            "{} tracks for one measurement: give --track once",
            args.track.len()
        );
    }
    let options = crate::lap::LapOptions {
        measurement: args.measurements[0].clone(),
        channels,
        track: args.track.first().cloned(),
        out: args.out.clone(),
        fmu_dir: args.fmus.clone(),
        chassis: args.chassis.into(),
    };
    let files = crate::lap::prepare(&options)?;
    for w in &files.warnings {
        eprintln!("warning: {w}");
    }
    if args.json {
        super::json::print(&serde_json::to_string_pretty(&files)?)?;
    } else {
        println!("lap of {}", args.measurements[0].display());
        println!(
            "  measured      {:.1} m in {:.3} s, starting at {:.3} m/s ({:.3} rad/s at the wheels)",
            files.lap_length, files.lap_time, files.v_start, files.omega_start
        );
        println!("  target speed  {}", files.target_speed.display());
        println!(
            "  track         {}{}",
            files.track.display(),
            if files.track_derived {
                " (derived from the measurement)"
            } else {
                ""
            }
        );
        if let Some(first) = files.fmus.first() {
            println!(
                "  FMUs          {} ({} packed)",
                first.parent().unwrap_or(first).display(),
                files.fmus.len()
            );
        }
        println!("  system        {}", files.system.display());
        println!("  study         {}", files.study.display());
        println!("next: twinbench optimize {}", files.study.display());
    }
    Ok(())
}

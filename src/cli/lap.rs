//! `twinbench lap MEASUREMENT [--track TRACK.csv] [--channels MAP.toml] --out DIR`: prepares
//! a lap of any circuit for the packed FMUs (docs/lap.md).

use std::path::PathBuf;
use tb_compare::ChannelMap;

#[derive(clap::Args, Debug)]
pub struct LapArgs {
    /// The vehicle measurement of the lap: MDF 4 (.mf4) or CSV.
    pub measurement: PathBuf,
    /// The circuit's track (CSV: s, curvature, grade, z_road_left, z_road_right); without
    /// it, one is derived from the measurement's a_y/v² (no grade, no road profile).
    #[arg(long)]
    pub track: Option<PathBuf>,
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
    /// Print a JSON summary.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: LapArgs) -> anyhow::Result<()> {
    let channels = match &args.channels {
        Some(p) => ChannelMap::read_path(p)?,
        None => ChannelMap::default(),
    };
    let options = crate::lap::LapOptions {
        measurement: args.measurement.clone(),
        channels,
        track: args.track.clone(),
        out: args.out.clone(),
        fmu_dir: args.fmus.clone(),
    };
    let files = crate::lap::prepare(&options)?;
    for w in &files.warnings {
        eprintln!("warning: {w}");
    }
    if args.json {
        super::json::print(&serde_json::to_string_pretty(&files)?)?;
    } else {
        println!("lap of {}", args.measurement.display());
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

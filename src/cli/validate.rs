//! `twinbench validate RESULT.json MEASUREMENT [--track TRACK.csv] [--channels MAP.toml]
//! [--out DIR]`: the fitted twin on a lap it was not fitted on (docs/optimize.md).

use std::path::PathBuf;
use tb_compare::ChannelMap;

#[derive(clap::Args, Debug)]
pub struct ValidateArgs {
    /// A study's result (result.json, as `twinbench optimize` writes it).
    pub result: PathBuf,
    /// The measurement of a lap the study did not fit: MDF 4 or CSV.
    pub measurement: PathBuf,
    /// The lap's circuit (CSV: s, curvature, grade, z_road_left, z_road_right); without it,
    /// one derived from the measurement.
    #[arg(long)]
    pub track: Option<PathBuf>,
    /// The channel of each signal in the measurement (a TOML file with `[channels]`).
    #[arg(long, value_name = "MAP.toml")]
    pub channels: Option<PathBuf>,
    /// Output folder: the lap's files (lap/), validation.md, validation.json, the plot.
    #[arg(long, short, default_value = "target/validate")]
    pub out: PathBuf,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: ValidateArgs) -> anyhow::Result<()> {
    let channels = match &args.channels {
        Some(p) => ChannelMap::read_path(p)?,
        None => ChannelMap::default(),
    };
    let v = crate::validate::validate(&crate::validate::ValidateOptions {
        result: args.result.clone(),
        measurement: args.measurement.clone(),
        channels,
        track: args.track.clone(),
        out: args.out.clone(),
    })?;
    if args.json {
        super::json::print(&serde_json::to_string_pretty(&v)?)?;
    } else {
        println!("{}", crate::validate::markdown(&v));
        println!("system      {}", v.system.display());
        for f in &v.files {
            println!("  {}", f.display());
        }
    }
    Ok(())
}

//! Small studies on the co-simulated bench against the shipped Spielberg lap.

use std::path::Path;

/// The head of a small study of `system` against the shipped Spielberg lap: its `name`, the
/// system and the measurement, its `settings` (seed and the like), and what it records: the
/// lap's distance, speed and wheel loads (and `also`), every 10th sample. The optimizer and
/// the steps follow.
pub fn head(name: &str, system: &Path, settings: &str, also: &[&str]) -> String {
    let measurement = twinbench::pack::workspace_root().join("data/spielberg_lap.csv");
    let mut signals = vec![
        "vehicle.distance",
        "vehicle.v",
        "vehicle.Fz_fl",
        "vehicle.Fz_fr",
        "vehicle.Fz_rl",
        "vehicle.Fz_rr",
    ];
    signals.extend(also);
    format!(
        "\nname = \"{name}\"\nsystem = \"{}\"\nmeasurement = \"{}\"\n{settings}\n[record]\nsignals = {signals:?}\ndecimation = 10\n",
        system.display(),
        measurement.display(),
    )
}

/// The bench's system file: the RLS with the vehicle on Spielberg.
pub fn rls_v() -> std::path::PathBuf {
    twinbench::pack::workspace_root().join("systems/rls_v.toml")
}

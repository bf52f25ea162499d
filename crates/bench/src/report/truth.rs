//! The truth of a synthetic lap, where the lap carries one: the parameters of the car that
//! made the measurement, in `<lap>_truth.json` beside the lap (`data/spielberg_lap.csv` has
//! `data/spielberg_lap_truth.json`), its object `truth` mapping names to values. The HTML
//! report marks it in the parameters' picture: on such a lap an engineer can see whether
//! each interval holds it. A real lap has no such file, and the report says nothing of it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Why a truth file is passed over (the report says so in a warning).
#[derive(Debug, thiserror::Error)]
pub enum TruthError {
    #[error(transparent)]
    Read(#[from] std::io::Error),
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error("no object \"truth\"")]
    NoTruth,
}

/// A lap's truth: name → value, and the file it came from (an input of the report).
#[derive(Clone, Debug, PartialEq)]
pub struct Truth {
    pub path: PathBuf,
    values: BTreeMap<String, f64>,
}

impl Truth {
    /// The truth file beside `measurement`, if there is one and it reads as a truth; a
    /// file that does not is passed over with a warning (the report is not the place to
    /// fail a study for a side file).
    pub fn beside(measurement: &Path) -> Option<Truth> {
        let stem = measurement.file_stem()?.to_string_lossy();
        let path = measurement.with_file_name(format!("{stem}_truth.json"));
        if !path.is_file() {
            return None;
        }
        let parsed = tb_files::input::read_to_string(&path, tb_files::Limit::CONFIG)
            .map_err(TruthError::from)
            .and_then(|text| Truth::parse(&text, &path));
        match parsed {
            Ok(t) => Some(t),
            Err(e) => {
                log::warn!("{}: not used as the lap's truth: {e}", path.display());
                None
            }
        }
    }

    /// Reads the `truth` object's numbers (other entries, such as text, are not values).
    pub fn parse(text: &str, path: &Path) -> Result<Truth, TruthError> {
        let json: serde_json::Value = serde_json::from_str(text)?;
        let object = json
            .get("truth")
            .and_then(|t| t.as_object())
            .ok_or(TruthError::NoTruth)?;
        let values = object
            .iter()
            .filter_map(|(k, v)| Some((k.clone(), v.as_f64()?)))
            .collect();
        Ok(Truth {
            path: path.to_path_buf(),
            values,
        })
    }

    /// The true value of a study's parameter (`vehicle.b_front`): under its full name, else
    /// its effective value (`b_front_effective`: what a twin of simpler geometry should
    /// find, data/README.md), else its bare name.
    pub fn of(&self, name: &str) -> Option<f64> {
        let bare = name.split_once('.').map_or(name, |(_, v)| v);
        [
            name.to_string(),
            format!("{bare}_effective"),
            bare.to_string(),
        ]
        .iter()
        .find_map(|k| self.values.get(k).copied())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_parameter_finds_its_full_name_then_its_effective_value_then_its_bare_name() {
        let t = Truth::parse(
            r#"{"seed": 7, "truth": {"c_lift_front": 0.827, "b_front_nominal": 1.55,
                "b_front_effective": 1.209, "b_front": 1.0, "vehicle.m": 880.0, "note": "x"}}"#,
            Path::new("lap_truth.json"),
        )
        .unwrap();
        assert_eq!(t.of("vehicle.c_lift_front"), Some(0.827));
        assert_eq!(t.of("vehicle.b_front"), Some(1.209));
        assert_eq!(t.of("vehicle.m"), Some(880.0));
        assert_eq!(t.of("vehicle.l"), None);
        assert!(Truth::parse("{}", Path::new("x")).is_err());
    }
}

//! The track: distance-based curvature, grade and road heights, read from a CSV resource.

use fmu_export::ModelError;

/// Columns the track file must have (in any order; extra columns are ignored).
pub const COLUMNS: [&str; 5] = ["s", "curvature", "grade", "z_road_left", "z_road_right"];
/// What a row of a circuit may hold, per column after `s` (a logger's error value or a
/// unit mix-up gives absurd physics, not an error, if taken): |curvature| ≤ 1 1/m (a 1 m
/// radius), |grade| ≤ 1 rad (57°), |z_road| ≤ 1 m.
pub const LIMITS: [f64; 4] = [1.0, 1.0, 1.0, 1.0];
/// The shortest lap a track may describe [m].
pub const MIN_LENGTH: f64 = 10.0;

/// One interpolated track sample.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TrackPoint {
    pub curvature: f64,
    pub grade: f64,
    pub z_left: f64,
    pub z_right: f64,
}

/// A closed track over `[0, length)`: rows at increasing `s`, the lap length is the last `s`
/// plus the last spacing, and the last interval interpolates back to the first row.
#[derive(Clone, Debug, PartialEq)]
pub struct Track {
    s: Vec<f64>,
    rows: Vec<TrackPoint>,
    length: f64,
    /// A lookup this far from its cursor bisects instead of walking (50 mean row spacings).
    far: f64,
}

impl Track {
    /// Parse the CSV text of `file` (the name is only used in error messages).
    pub fn parse(file: &str, text: &str) -> Result<Track, ModelError> {
        let err = |line: usize, msg: String| ModelError::new(format!("{file}: row {line}: {msg}"));
        let mut lines = fmu_export::resources::csv_lines(text);
        let (hline, header) = lines.next().ok_or_else(|| {
            ModelError::new(format!("{file}: empty track file (expected a header row)"))
        })?;
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let mut col = [0usize; 5];
        for (k, want) in COLUMNS.iter().enumerate() {
            col[k] = names.iter().position(|n| n == want).ok_or_else(|| {
                err(
                    hline,
                    format!(
                        "missing column '{want}' in the header (need {})",
                        COLUMNS.join(", ")
                    ),
                )
            })?;
        }
        let mut s = Vec::new();
        let mut rows = Vec::new();
        let mut fields = Vec::with_capacity(names.len());
        for (line, l) in lines {
            fields.clear();
            fields.extend(l.split(',').map(str::trim));
            if fields.len() != names.len() {
                return Err(err(
                    line,
                    format!("{} fields, the header has {}", fields.len(), names.len()),
                ));
            }
            let x = row_values(file, line, &fields, &col)?;
            if let Some(&prev) = s.last() {
                if x[0] <= prev {
                    return Err(err(
                        line,
                        format!("s = {} does not increase (previous row s = {prev})", x[0]),
                    ));
                }
            } else if x[0] != 0.0 {
                return Err(err(
                    line,
                    format!("the first row must be at s = 0, found {}", x[0]),
                ));
            }
            s.push(x[0]);
            rows.push(TrackPoint {
                curvature: x[1],
                grade: x[2],
                z_left: x[3],
                z_right: x[4],
            });
        }
        if s.len() < 2 {
            return Err(ModelError::new(format!(
                "{file}: needs at least two data rows, found {}",
                s.len()
            )));
        }
        let track = Track::from_rows(s, rows);
        if track.length.is_nan() || track.length < MIN_LENGTH {
            return Err(ModelError::new(format!(
                "{file}: a lap of {:?} m is not a circuit (at least {MIN_LENGTH} m)",
                track.length
            )));
        }
        Ok(track)
    }

    fn from_rows(s: Vec<f64>, rows: Vec<TrackPoint>) -> Track {
        let n = s.len();
        let length = s[n - 1] + (s[n - 1] - s[n - 2]);
        let far = 50.0 * (length / n as f64);
        Track {
            s,
            rows,
            length,
            far,
        }
    }

    /// The rows as numbers, `COLUMNS` order (a build script stores them: `preparsed`).
    pub fn values(&self) -> Vec<f64> {
        self.s
            .iter()
            .zip(&self.rows)
            .flat_map(|(&s, r)| [s, r.curvature, r.grade, r.z_left, r.z_right])
            .collect()
    }

    /// A track from [`Track::values`] of a parsed file (the same numbers, the same track).
    pub fn from_values(values: &[f64]) -> Option<Track> {
        if !values.len().is_multiple_of(5) || values.len() < 10 {
            return None;
        }
        let s: Vec<f64> = values.chunks_exact(5).map(|r| r[0]).collect();
        let rows = values
            .chunks_exact(5)
            .map(|r| TrackPoint {
                curvature: r[1],
                grade: r[2],
                z_left: r[3],
                z_right: r[4],
            })
            .collect();
        Some(Track::from_rows(s, rows))
    }

    /// Number of data rows.
    pub fn rows(&self) -> usize {
        self.s.len()
    }

    pub fn length(&self) -> f64 {
        self.length
    }

    /// Map any distance into `[0, length)`.
    pub fn wrap(&self, s: f64) -> f64 {
        let w = fmu_export::resources::wrap_distance(s, self.length);
        // rem_euclid can round up to exactly `length`.
        if w >= self.length {
            0.0
        } else {
            w
        }
    }

    /// Linear interpolation at `s` (any value; wrapped). `cursor` is the row index of the last
    /// lookup: positions move little between calls, so walking from it is O(1) and allocation-free.
    pub fn at(&self, s: f64, cursor: &mut usize) -> TrackPoint {
        let s = self.wrap(s);
        let n = self.s.len();
        let mut i = (*cursor).min(n - 1);
        // Far jumps (wrap, restore): bisect instead of walking.
        if (self.s[i] - s).abs() > self.far {
            i = self.s.partition_point(|&x| x <= s).saturating_sub(1);
        }
        while i + 1 < n && self.s[i + 1] <= s {
            i += 1;
        }
        while i > 0 && self.s[i] > s {
            i -= 1;
        }
        *cursor = i;
        let (s1, j) = if i + 1 < n {
            (self.s[i + 1], i + 1)
        } else {
            (self.length, 0)
        };
        let t = (s - self.s[i]) / (s1 - self.s[i]);
        let (a, b) = (&self.rows[i], &self.rows[j]);
        let lerp = |x: f64, y: f64| x + t * (y - x);
        TrackPoint {
            curvature: lerp(a.curvature, b.curvature),
            grade: lerp(a.grade, b.grade),
            z_left: lerp(a.z_left, b.z_left),
            z_right: lerp(a.z_right, b.z_right),
        }
    }
}

/// The five numbers of a data row (`col`: where each of [`COLUMNS`] is among the fields),
/// each finite and of a circuit's size.
fn row_values(
    file: &str,
    line: usize,
    fields: &[&str],
    col: &[usize; 5],
) -> Result<[f64; 5], ModelError> {
    let err = |line: usize, msg: String| ModelError::new(format!("{file}: row {line}: {msg}"));
    let mut x = [0.0; 5];
    for k in 0..5 {
        let f = fields[col[k]];
        x[k] = f.parse::<f64>().map_err(|_| {
            err(
                line,
                format!(
                    "column '{}': '{}' is not a number",
                    COLUMNS[k],
                    fmu_export::excerpt(f)
                ),
            )
        })?;
        if !x[k].is_finite() {
            return Err(err(
                line,
                format!("column '{}': {f} is not finite", COLUMNS[k]),
            ));
        }
    }
    if let Some(k) = (1..5).find(|&k| x[k].abs() > LIMITS[k - 1]) {
        return Err(err(
            line,
            format!(
                "column '{}': {:?} is more than a circuit has (at most {} in size)",
                COLUMNS[k],
                x[k],
                LIMITS[k - 1]
            ),
        ));
    }
    Ok(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_preparsed_blob_is_the_bundled_track_parsed() {
        use fmu_export::preparsed::{decode, digest};
        let text = std::str::from_utf8(include_bytes!("../resources/track.csv")).unwrap();
        let parsed = Track::parse("track.csv", text).unwrap();
        let values = decode(crate::TRACK_PREPARSED, digest(text.as_bytes()), 5)
            .expect("the build embeds the bundled track");
        let bits = |v: Vec<f64>| v.into_iter().map(f64::to_bits).collect::<Vec<_>>();
        let from = Track::from_values(&values).unwrap();
        assert_eq!(bits(from.values()), bits(parsed.values()));
        assert_eq!(from.length().to_bits(), parsed.length().to_bits());
        // A changed file is parsed, not taken from the preparsed blob.
        let changed = text.replacen("\n0.25,", "\n0.26,", 1);
        assert_ne!(changed, text);
        assert!(decode(crate::TRACK_PREPARSED, digest(changed.as_bytes()), 5).is_none());
    }

    const GOOD: &str =
        "s,curvature,grade,z_road_left,z_road_right\n0,0.01,0,0,0\n10,0.02,0,0.1,0\n20,0.03,0,0,0\n";

    #[test]
    fn interpolates_and_wraps() {
        let t = Track::parse("t.csv", GOOD).unwrap();
        assert_eq!(t.length(), 30.0);
        let mut c = 0;
        assert!((t.at(5.0, &mut c).curvature - 0.015).abs() < 1e-15);
        // The last interval runs back to row 0.
        assert!((t.at(25.0, &mut c).curvature - 0.02).abs() < 1e-15);
        assert!((t.at(35.0, &mut c).curvature - 0.015).abs() < 1e-15);
        assert!((t.at(-5.0, &mut c).curvature - 0.02).abs() < 1e-15);
        assert!((t.at(10.0, &mut c).z_left - 0.1).abs() < 1e-15);
    }

    #[test]
    fn cursor_does_not_change_results() {
        let t = Track::parse("t.csv", GOOD).unwrap();
        for s in [0.0, 3.0, 17.0, 29.0, 11.0, 2.0] {
            let mut c0 = 0;
            let mut c2 = 2;
            assert_eq!(t.at(s, &mut c0), t.at(s, &mut c2));
        }
    }

    #[test]
    fn bad_files_name_file_and_row() {
        let cases = [
            (
                "s,curvature,grade,z_road_left\n0,0,0,0\n1,0,0,0\n",
                "row 1: missing column 'z_road_right'",
            ),
            (
                "s,curvature,grade,z_road_left,z_road_right\n0,0,0,0,0\n1,0,0,0,0\n1,0,0,0,0\n",
                "row 4: s = 1 does not increase",
            ),
            (
                "s,curvature,grade,z_road_left,z_road_right\n0,0,0,0,0\n1,NaN,0,0,0\n2,0,0,0,0\n",
                "row 3: column 'curvature': NaN is not finite",
            ),
            (
                "s,curvature,grade,z_road_left,z_road_right\n0,0,0,0,0\n1,x,0,0,0\n",
                "row 3: column 'curvature': 'x' is not a number",
            ),
            (
                "s,curvature,grade,z_road_left,z_road_right\n0,0,0,0,0\n1,0,0,0\n",
                "row 3: 4 fields",
            ),
            (
                "s,curvature,grade,z_road_left,z_road_right\n0,0,0,0,0\n",
                "at least two data rows",
            ),
        ];
        for (text, want) in cases {
            let e = Track::parse("bad.csv", text).unwrap_err().0;
            assert!(e.starts_with("bad.csv: "), "{e}");
            assert!(e.contains(want), "{e} should contain {want}");
        }
    }

    #[test]
    fn bundled_track_parses() {
        let text = std::str::from_utf8(include_bytes!("../resources/track.csv")).unwrap();
        let t = Track::parse("track.csv", text).unwrap();
        assert!((t.length() - 4285.0).abs() < 1e-9);
    }
}

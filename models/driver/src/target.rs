//! The distance-based target speed: a periodic, piecewise-linear `v(s)` from a CSV file.

use fmu_export::ModelError;
use std::cell::Cell;

/// The fastest target speed a lap may hold [m/s] (720 km/h): faster is an error value.
pub const MAX_SPEED: f64 = 200.0;
/// The largest acceleration a target may ask for [m/s²] (10 g): more is a logger's error.
pub const MAX_ACCELERATION: f64 = 100.0;
/// The shortest lap a target may describe [m].
pub const MIN_LAP_LENGTH: f64 = 10.0;

/// Target speed over distance; periodic with the lap length (the file's last `s`). With
/// the optional column `a` [m/s²], the target's own acceleration (a measured lap's a_x): the
/// driver's feed-forward takes it instead of differentiating the speed.
#[derive(Debug, PartialEq)]
pub struct TargetSpeed {
    s: Vec<f64>,
    v: Vec<f64>,
    /// The acceleration at each row (empty: the file has none).
    a: Vec<f64>,
    /// 1/spacing when the rows are evenly spaced: the segment is then found by one
    /// multiplication instead of a binary search (the same segment, checked).
    inv_spacing: Option<f64>,
}

impl TargetSpeed {
    /// Parse CSV text with a header naming the columns `s` [m] and `v` [m/s] (other
    /// columns are ignored; blank lines and lines starting with `#` are skipped). `file`
    /// names the source in errors; rows are counted as lines of the file, from 1.
    pub fn parse(text: &str, file: &str) -> Result<Self, ModelError> {
        let err = |line: usize, msg: String| ModelError::new(format!("{file}, row {line}: {msg}"));
        let mut lines = fmu_export::resources::csv_lines(text);
        let (header_line, header) = lines.next().ok_or_else(|| {
            ModelError::new(format!("{file}: empty file, expected a header 's,v'"))
        })?;
        let names: Vec<&str> = header.split(',').map(str::trim).collect();
        let column = |name: &str| {
            names.iter().position(|n| *n == name).ok_or_else(|| {
                err(
                    header_line,
                    format!(
                        "no column '{name}' in the header '{}' (expected 's,v')",
                        fmu_export::excerpt(header)
                    ),
                )
            })
        };
        let (is, iv) = (column("s")?, column("v")?);
        let ia = names.iter().position(|n| *n == "a");

        let (mut s, mut v, mut a) = (Vec::new(), Vec::new(), Vec::new());
        for (line, row) in lines {
            let fields: Vec<&str> = row.split(',').map(str::trim).collect();
            let field = |i: usize, name: &str| -> Result<f64, ModelError> {
                let text = fields.get(i).ok_or_else(|| {
                    err(
                        line,
                        format!("missing value of '{name}' ({} fields)", fields.len()),
                    )
                })?;
                let x: f64 = text.parse().map_err(|_| {
                    err(
                        line,
                        format!("'{name}' = '{}' is not a number", fmu_export::excerpt(text)),
                    )
                })?;
                if !x.is_finite() {
                    return Err(err(line, format!("'{name}' = {x} is not finite")));
                }
                Ok(x)
            };
            let (si, vi) = (field(is, "s")?, field(iv, "v")?);
            if let Some(&prev) = s.last() {
                if si <= prev {
                    return Err(err(
                        line,
                        format!("s = {si} m does not increase (previous row {prev} m)"),
                    ));
                }
            } else if si < 0.0 {
                return Err(err(line, format!("first s = {si} m is negative")));
            }
            if vi < 0.0 {
                return Err(err(line, format!("v = {vi} m/s is negative")));
            }
            if vi > MAX_SPEED {
                return Err(err(
                    line,
                    format!(
                        "v = {vi:?} m/s is faster than a car's target may be ({MAX_SPEED} m/s)"
                    ),
                ));
            }
            if let Some(ia) = ia {
                let ai = field(ia, "a")?;
                if ai.abs() > MAX_ACCELERATION {
                    return Err(err(
                        line,
                        format!("a = {ai:?} m/s2 is beyond what a car's target may ask ({MAX_ACCELERATION} m/s2)"),
                    ));
                }
                a.push(ai);
            }
            s.push(si);
            v.push(vi);
        }
        if s.len() < 2 {
            return Err(ModelError::new(format!(
                "{file}: {} data rows, at least 2 needed for a target speed over distance",
                s.len()
            )));
        }
        let lap = s[s.len() - 1];
        if lap < MIN_LAP_LENGTH {
            return Err(ModelError::new(format!(
                "{file}: a lap of {lap:?} m is not a circuit (at least {MIN_LAP_LENGTH} m)"
            )));
        }
        Ok(Self::from_columns(s, v, a))
    }

    fn from_columns(s: Vec<f64>, v: Vec<f64>, a: Vec<f64>) -> TargetSpeed {
        let spacing = (s[s.len() - 1] - s[0]) / (s.len() - 1) as f64;
        let even = s
            .windows(2)
            .all(|w| ((w[1] - w[0]) - spacing).abs() <= 1e-9 * spacing);
        let inv_spacing = even.then_some(1.0 / spacing);
        TargetSpeed {
            s,
            v,
            a,
            inv_spacing,
        }
    }

    /// The rows as numbers, (s, v, a) triples, a NaN without an acceleration column (a build
    /// script stores them: `preparsed`).
    pub fn values(&self) -> Vec<f64> {
        (0..self.s.len())
            .flat_map(|k| {
                [
                    self.s[k],
                    self.v[k],
                    self.a.get(k).copied().unwrap_or(f64::NAN),
                ]
            })
            .collect()
    }

    /// A target from [`TargetSpeed::values`] of a parsed file (the same numbers, the
    /// same target).
    pub fn from_values(values: &[f64]) -> Option<TargetSpeed> {
        if !values.len().is_multiple_of(3) || values.len() < 6 {
            return None;
        }
        let s = values.chunks_exact(3).map(|r| r[0]).collect();
        let v = values.chunks_exact(3).map(|r| r[1]).collect();
        let a: Vec<f64> = values.chunks_exact(3).map(|r| r[2]).collect();
        let a = if a.iter().all(|x| x.is_nan()) {
            Vec::new()
        } else {
            a
        };
        Some(Self::from_columns(s, v, a))
    }

    /// Whether the target carries its own acceleration.
    pub fn has_acceleration(&self) -> bool {
        !self.a.is_empty()
    }

    /// The target's acceleration at `s` (linear between rows; the column `a`), with the
    /// segment found from `hint` as [`TargetSpeed::at_near`] does. 0 without the column.
    /// The driver takes it with the speed ([`TargetSpeed::speed_and_acceleration_near`]);
    /// the tests hold that against this lookup on its own.
    #[cfg(test)]
    pub(crate) fn acceleration_near(&self, s: f64, hint: &Cell<usize>) -> f64 {
        if self.a.is_empty() {
            return 0.0;
        }
        let (k, x) = self.locate(s, hint);
        self.acceleration_in(k, x)
    }

    /// The driver's preview: the target speed at `s` and the acceleration the target asks
    /// for there (its own column `a` where it has one, else v·dv/ds), from one search of the
    /// segment: the same bits as [`TargetSpeed::at_near`] and a lookup of the column `a`
    /// with the same hint, called one after the other.
    pub fn speed_and_acceleration_near(&self, s: f64, hint: &Cell<usize>) -> (f64, f64) {
        let (k, x) = self.locate(s, hint);
        let (v, slope) = self.speed_in(k, x);
        if self.a.is_empty() {
            (v, v * slope)
        } else {
            (v, self.acceleration_in(k, x))
        }
    }

    /// The column `a` interpolated in the segment `k` (as [`TargetSpeed::locate`] gives it).
    fn acceleration_in(&self, k: usize, x: f64) -> f64 {
        if k == 0 {
            return self.a[0];
        }
        let k = (k - 1).min(self.s.len() - 2);
        let w = ((x - self.s[k]) / (self.s[k + 1] - self.s[k])).clamp(0.0, 1.0);
        self.a[k] + w * (self.a[k + 1] - self.a[k])
    }

    /// Lap length: the last `s` of the file; positions wrap modulo it.
    pub fn lap_length(&self) -> f64 {
        self.s[self.s.len() - 1]
    }

    /// Target speed and its slope dv/ds at distance `s` (any real; wrapped into the lap).
    /// Before the file's first `s` the first value holds.
    pub fn at(&self, s: f64) -> (f64, f64) {
        self.at_near(s, &Cell::new(0))
    }

    /// [`TargetSpeed::at`] starting the search at the segment of the last lookup (`hint`,
    /// updated): the driver moves a few centimetres per step, so the segment is almost
    /// always the same or the next one. Same segment, same bits as without the hint.
    pub fn at_near(&self, s: f64, hint: &Cell<usize>) -> (f64, f64) {
        let (k, x) = self.locate(s, hint);
        self.speed_in(k, x)
    }

    /// `s` wrapped into the lap (x) and the number k of rows with s_k <= x, searched from
    /// `hint` (updated to k).
    #[inline]
    fn locate(&self, s: f64, hint: &Cell<usize>) -> (usize, f64) {
        let x = fmu_export::resources::wrap_distance(s, self.lap_length());
        let n = self.s.len();
        let h = hint.get();
        let k = if h > 0 && h < n && self.s[h - 1] <= x && x < self.s[h] {
            h
        } else if h < n && self.s[h] <= x && (h + 1 == n || x < self.s[h + 1]) {
            h + 1
        } else {
            self.segment(x)
        };
        hint.set(k);
        (k, x)
    }

    /// The target speed and its slope in the segment `k` at `x` (as [`TargetSpeed::locate`]
    /// gives them).
    #[inline]
    fn speed_in(&self, k: usize, x: f64) -> (f64, f64) {
        if k == 0 {
            return (self.v[0], 0.0);
        }
        let k = (k - 1).min(self.s.len() - 2);
        let slope = (self.v[k + 1] - self.v[k]) / (self.s[k + 1] - self.s[k]);
        (self.v[k] + slope * (x - self.s[k]), slope)
    }

    /// The number of rows with s_k <= x, found directly on an even grid (the guess is
    /// corrected by a step if rounding missed), else by bisection.
    fn segment(&self, x: f64) -> usize {
        let n = self.s.len();
        match self.inv_spacing {
            Some(inv) if x >= self.s[0] => {
                let mut k = (((x - self.s[0]) * inv) as usize + 1).min(n);
                while k < n && self.s[k] <= x {
                    k += 1;
                }
                while k > 0 && self.s[k - 1] > x {
                    k -= 1;
                }
                k
            }
            _ => self.s.partition_point(|&sk| sk <= x),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_preparsed_blob_is_the_bundled_target_parsed() {
        use fmu_export::preparsed::{decode, digest};
        let text = std::str::from_utf8(include_bytes!("../resources/target_speed.csv")).unwrap();
        let parsed = TargetSpeed::parse(text, "target_speed.csv").unwrap();
        let values = decode(crate::TARGET_PREPARSED, digest(text.as_bytes()), 3)
            .expect("the build embeds the bundled target");
        let from = TargetSpeed::from_values(&values).unwrap();
        assert_eq!(from, parsed);
        // Any edit of the file (here its first speed) is another digest.
        let changed = text.replacen("\n0.000,", "\n0.000,1", 1);
        assert_ne!(changed, text);
        assert!(decode(crate::TARGET_PREPARSED, digest(changed.as_bytes()), 3).is_none());
    }

    #[test]
    fn a_lookup_from_any_hint_is_the_lookup_without_one() {
        let t = TargetSpeed::parse("s,v\n0,10\n10,12\n25,11\n40,15\n", "t.csv").unwrap();
        for k in 0..=80 {
            let s = -10.0 + 1.0 * k as f64;
            // A hint past the end takes the search path (bisection or the even grid).
            let plain = t.at_near(s, &Cell::new(usize::MAX));
            for h in 0..6 {
                let got = t.at_near(s, &Cell::new(h));
                assert_eq!(
                    (got.0.to_bits(), got.1.to_bits()),
                    (plain.0.to_bits(), plain.1.to_bits()),
                    "s = {s}, hint {h}"
                );
            }
        }
    }

    fn msg(text: &str) -> String {
        TargetSpeed::parse(text, "t.csv").unwrap_err().0
    }

    #[test]
    fn malformed_files_name_file_and_row() {
        assert!(
            msg("s,v\n0,10\n5,11\n5,12\n").starts_with("t.csv, row 4: s = 5 m does not increase")
        );
        assert!(msg("s,v\n0,10\n5,NaN\n").starts_with("t.csv, row 3: 'v' = NaN is not finite"));
        assert!(msg("s,v\n0,10\n5,abc\n").starts_with("t.csv, row 3: 'v' = 'abc' is not a number"));
        assert!(msg("s,speed\n0,10\n5,11\n").starts_with("t.csv, row 1: no column 'v'"));
        assert!(msg("s,v\n0,10\n5\n").starts_with("t.csv, row 3: missing value of 'v'"));
        assert!(msg("s,v\n0,10\n").starts_with("t.csv: 1 data rows"));
        assert!(msg("").starts_with("t.csv: empty file"));
        assert!(msg("s,v\n0,10\n5,-1\n").starts_with("t.csv, row 3: v = -1 m/s is negative"));
    }

    #[test]
    fn interpolates_and_wraps() {
        let t = TargetSpeed::parse("# comment\nv,s,x\n10,0,1\n20,100,1\n\n10,200,1\n", "t.csv")
            .unwrap();
        assert_eq!(t.lap_length(), 200.0);
        assert_eq!(t.at(50.0), (15.0, 0.1));
        assert_eq!(t.at(150.0), (15.0, -0.1));
        // Periodic: one lap on, and one lap back.
        assert_eq!(t.at(250.0), t.at(50.0));
        assert_eq!(t.at(-150.0), t.at(50.0));
        assert_eq!(t.at(200.0).0, 10.0);
    }
}

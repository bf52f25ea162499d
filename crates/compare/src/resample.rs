//! Linearly spaced distance vector and linear interpolation onto it (paper Fig. 6): data
//! recorded at linearly spaced times are not linearly spaced in distance, so both the
//! measurement and the simulation are interpolated onto one distance grid before comparing.

use crate::error::{Error, Result};
use std::ops::Range;

/// `start + i·step`, i = 0..len.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DistanceGrid {
    start: f64,
    step: f64,
    len: usize,
}

impl DistanceGrid {
    /// The grid from `start` in steps of `step` up to and including `end` (within 1e-9 step).
    pub fn over(start: f64, end: f64, step: f64) -> Result<Self> {
        if !(step.is_finite() && step > 0.0) {
            return Err(Error::Settings(format!(
                "distance step {step} m is not positive"
            )));
        }
        if !(start.is_finite() && end.is_finite() && end >= start) {
            return Err(Error::Settings(format!(
                "distance range [{start}, {end}] m is empty"
            )));
        }
        let len = ((end - start) / step + 1e-9).floor() as usize + 1;
        Ok(Self { start, step, len })
    }

    pub fn start(&self) -> f64 {
        self.start
    }

    pub fn step(&self) -> f64 {
        self.step
    }

    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The i-th distance.
    #[inline]
    pub fn at(&self, i: usize) -> f64 {
        self.start + i as f64 * self.step
    }

    /// All distances.
    pub fn values(&self) -> Vec<f64> {
        (0..self.len).map(|i| self.at(i)).collect()
    }

    /// The indices of the grid points within `[lo, hi]`.
    pub fn range_within(&self, lo: f64, hi: f64) -> Range<usize> {
        let idx = |d: f64| ((d - self.start) / self.step).clamp(0.0, self.len as f64);
        let mut first = idx(lo).ceil() as usize;
        while first > 0 && self.at(first - 1) >= lo {
            first -= 1;
        }
        while first < self.len && self.at(first) < lo {
            first += 1;
        }
        let mut last = (idx(hi).floor() as usize + 1).min(self.len);
        while last < self.len && self.at(last) <= hi {
            last += 1;
        }
        while last > first && self.at(last - 1) > hi {
            last -= 1;
        }
        first..last.max(first)
    }
}

/// Linear interpolation of `y(x)` at the grid points `range`, appended to `out` (cleared
/// first). `x` must be non-decreasing and cover the points; points outside `[x0, x_end]`
/// take the end values. Repeated `x` (standstill) are allowed. One pass, O(len x + points).
pub fn interpolate_onto(
    x: &[f64],
    y: &[f64],
    grid: &DistanceGrid,
    range: Range<usize>,
    out: &mut Vec<f64>,
) {
    out.clear();
    out.reserve(range.len());
    let n = x.len().min(y.len());
    if n == 0 {
        out.extend(range.map(|_| f64::NAN));
        return;
    }
    let mut j = 0; // invariant: x[j] <= q, or j == 0
    for i in range {
        let q = grid.at(i);
        while j + 1 < n && x[j + 1] <= q {
            j += 1;
        }
        let v = if q <= x[0] {
            y[0]
        } else if j + 1 >= n {
            y[n - 1]
        } else {
            let (x0, x1) = (x[j], x[j + 1]);
            let t = (q - x0) / (x1 - x0);
            y[j] + t * (y[j + 1] - y[j])
        };
        out.push(v);
    }
}

/// Linear interpolation of `y(x)` at arbitrary increasing points `xq` (like `numpy.interp`).
pub fn interp(x: &[f64], y: &[f64], xq: &[f64]) -> Vec<f64> {
    let n = x.len().min(y.len());
    let mut j = 0;
    xq.iter()
        .map(|&q| {
            if n == 0 {
                return f64::NAN;
            }
            while j + 1 < n && x[j + 1] <= q {
                j += 1;
            }
            if q <= x[0] {
                y[0]
            } else if j + 1 >= n {
                y[n - 1]
            } else {
                y[j] + (q - x[j]) / (x[j + 1] - x[j]) * (y[j + 1] - y[j])
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_and_range() {
        let g = DistanceGrid::over(0.0, 10.0, 1.0).unwrap();
        assert_eq!(g.len(), 11);
        assert_eq!(g.range_within(0.5, 9.5), 1..10);
        assert_eq!(g.range_within(-1.0, 20.0), 0..11);
        assert_eq!(g.range_within(3.0, 3.0), 3..4);
        let g = DistanceGrid::over(0.0, 0.3, 0.1).unwrap();
        assert_eq!(g.len(), 4, "0.3/0.1 rounds to 2.9999…");
    }

    #[test]
    fn interpolation_is_linear_and_handles_standstill() {
        let x = [0.0, 1.0, 1.0, 3.0];
        let y = [0.0, 10.0, 10.0, 30.0];
        let g = DistanceGrid::over(0.0, 3.0, 0.5).unwrap();
        let mut out = Vec::new();
        interpolate_onto(&x, &y, &g, 0..g.len(), &mut out);
        assert_eq!(out, vec![0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0]);
        assert_eq!(interp(&x, &y, &[0.25, 2.0]), vec![2.5, 20.0]);
    }
}

//! Quality figures of a simulated signal against the measured one (paper §4.2, Eq. 16).
//!
//! The regression is of the simulated values (y) on the measured ones (x), least squares:
//! slope `m = Sxy/Sxx`, intercept `ȳ − m·x̄`, `R² = Sxy²/(Sxx·Syy)` (0 when the simulation is
//! constant, as `scipy.stats.linregress` does). Sums are taken about the means (two passes).
//!
//! `e = (1 − R²)/2 + |m − 1|/2` (Eq. 16) cannot see a constant offset (a shifted copy has
//! m = 1 and R² = 1), so two more figures: `bias = mean(sim − meas)/mean(meas)` and the RMS
//! of `sim − meas`.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// Regression and error figures of one signal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Regression slope m of simulated on measured.
    pub slope: f64,
    /// Regression intercept, in the signal's unit.
    pub intercept: f64,
    /// Coefficient of determination R².
    pub r_squared: f64,
    /// Eq. 16: (1 − R²)/2 + |m − 1|/2.
    pub e: f64,
    /// mean(sim − meas) / mean(meas).
    pub bias: f64,
    /// √mean((sim − meas)²), in the signal's unit.
    pub rms: f64,
    /// Number of (distance grid) points compared.
    pub points: usize,
}

/// Eq. 16.
#[inline]
pub fn error_measure(slope: f64, r_squared: f64) -> f64 {
    (1.0 - r_squared) / 2.0 + (slope - 1.0).abs() / 2.0
}

/// The figures of `sim` against `meas` (same length, ≥ 3 points). `signal` names the
/// signal in errors.
pub fn metrics(signal: &str, meas: &[f64], sim: &[f64]) -> Result<Metrics> {
    let n = meas.len();
    if sim.len() != n {
        return Err(Error::Degenerate {
            signal: signal.into(),
            reason: format!("{} simulated points against {n} measured", sim.len()),
        });
    }
    if n < 3 {
        return Err(Error::Degenerate {
            signal: signal.into(),
            reason: format!("{n} points are too few for a regression"),
        });
    }
    let nf = n as f64;
    let (mut sx, mut sy) = (0.0, 0.0);
    for (&x, &y) in meas.iter().zip(sim) {
        sx += x;
        sy += y;
    }
    let (mx, my) = (sx / nf, sy / nf);
    let (mut sxx, mut syy, mut sxy, mut sdd) = (0.0, 0.0, 0.0, 0.0);
    for (&x, &y) in meas.iter().zip(sim) {
        let (dx, dy) = (x - mx, y - my);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
        let d = y - x;
        sdd += d * d;
    }
    if sxx.is_nan() || sxx <= 0.0 || sxx.is_infinite() {
        return Err(Error::Degenerate {
            signal: signal.into(),
            reason: "the measured signal is constant (or not finite): no regression".into(),
        });
    }
    let slope = sxy / sxx;
    let r_squared = if syy > 0.0 {
        // Clamp rounding just outside [0, 1].
        ((sxy / sxx) * (sxy / syy)).clamp(0.0, 1.0)
    } else {
        0.0
    };
    Ok(Metrics {
        slope,
        intercept: my - slope * mx,
        r_squared,
        e: error_measure(slope, r_squared),
        bias: (my - mx) / mx,
        rms: (sdd / nf).sqrt(),
        points: n,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identical_and_scaled_and_offset() {
        let x: Vec<f64> = (0..100).map(|i| (i as f64 * 0.1).sin() + 2.0).collect();
        let m = metrics("s", &x, &x).unwrap();
        assert!((m.slope - 1.0).abs() < 1e-14 && m.e.abs() < 1e-14 && m.rms == 0.0);
        let y: Vec<f64> = x.iter().map(|v| 1.5 * v).collect();
        let m = metrics("s", &x, &y).unwrap();
        assert!((m.slope - 1.5).abs() < 1e-12 && (m.e - 0.25).abs() < 1e-12);
        let y: Vec<f64> = x.iter().map(|v| v + 0.2).collect();
        let m = metrics("s", &x, &y).unwrap();
        assert!(m.e.abs() < 1e-12, "e is blind to an offset");
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        assert!((m.bias - 0.2 / mean).abs() < 1e-12 && (m.rms - 0.2).abs() < 1e-12);
    }

    #[test]
    fn constant_measurement_is_an_error() {
        let e = metrics("Fz_sum", &[1.0; 5], &[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap_err();
        assert!(
            matches!(&e, Error::Degenerate { signal, .. } if signal == "Fz_sum"),
            "{e}"
        );
        assert!(e.to_string().contains("constant"), "{e}");
    }
}

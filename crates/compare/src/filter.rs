//! Butterworth low-pass as second-order sections, and its zero-phase (forward-backward)
//! application.
//!
//! Design: the analog Butterworth prototype of order N, its cutoff prewarped to
//! `Ωc = 2·fs·tan(π·fc/fs)`, mapped to z by the bilinear transform `s = 2·fs·(1−z⁻¹)/(1+z⁻¹)`.
//! Each conjugate pole pair gives one section, an odd order one first-order section
//! (stored with `b2 = a2 = 0`). Every section has unit gain at DC. The digital magnitude is
//! then exactly `|H(f)| = 1/√(1 + (tan(πf/fs)/tan(πfc/fs))^(2N))`
//! ([`Butterworth::analytic_magnitude`]).
//!
//! Zero-phase filtering ([`Butterworth::filtfilt`]) is what `scipy.signal.sosfiltfilt` does
//! with its defaults: the signal is extended at both ends by **odd reflection** about the
//! end values (`2·x[0] − x[k]`, k = padlen..1, and likewise at the end) with
//! `padlen = 3·(2·sections + 1 − [last section first-order])` = 3·(N+1); each pass starts
//! from the sections' steady-state initial conditions (`sosfilt_zi`) scaled by the first
//! sample it sees; forward pass, backward pass, then the padding is cut off. The result has
//! magnitude `|H|²` and zero phase. Sections run in transposed direct form II.

use crate::error::{Error, Result};
use std::f64::consts::PI;

/// One second-order section `(b0 + b1 z⁻¹ + b2 z⁻²) / (1 + a1 z⁻¹ + a2 z⁻²)`; `a[0]` is 1.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sos {
    pub b: [f64; 3],
    pub a: [f64; 3],
}

impl Sos {
    /// Steady-state state of a transposed-direct-form-II section for a unit step input
    /// (scipy's `lfilter_zi` for this section).
    fn step_state(&self) -> [f64; 2] {
        let [b0, b1, b2] = self.b;
        let [_, a1, a2] = self.a;
        let g = (b0 + b1 + b2) / (1.0 + a1 + a2);
        [b1 + b2 - (a1 + a2) * g, b2 - a2 * g]
    }

    fn dc_gain(&self) -> f64 {
        self.b.iter().sum::<f64>() / self.a.iter().sum::<f64>()
    }
}

/// A digital Butterworth low-pass.
#[derive(Debug, Clone, PartialEq)]
pub struct Butterworth {
    order: usize,
    cutoff_hz: f64,
    sample_rate_hz: f64,
    sections: Vec<Sos>,
    /// Initial state per section for a unit-step start (scipy's `sosfilt_zi`).
    zi: Vec<[f64; 2]>,
}

impl Butterworth {
    /// Designs a low-pass of `order` ≥ 1 with cutoff (−3 dB) `cutoff_hz` for a signal
    /// sampled at `sample_rate_hz`; `0 < cutoff_hz < sample_rate_hz / 2`.
    pub fn lowpass(order: usize, cutoff_hz: f64, sample_rate_hz: f64) -> Result<Self> {
        if order == 0 || order > 16 {
            return Err(Error::Settings(format!(
                "filter order {order} outside 1..=16"
            )));
        }
        if !(sample_rate_hz.is_finite() && sample_rate_hz > 0.0) {
            return Err(Error::Settings(format!(
                "sample rate {sample_rate_hz} Hz is not positive"
            )));
        }
        if !(cutoff_hz > 0.0 && cutoff_hz < 0.5 * sample_rate_hz) {
            return Err(Error::Settings(format!(
                "cutoff {cutoff_hz} Hz must lie in (0, {}) Hz, half the sample rate {sample_rate_hz} Hz",
                0.5 * sample_rate_hz
            )));
        }
        // Prewarped cutoff, normalised by 2·fs: Ω = tan(π fc / fs).
        let w = (PI * cutoff_hz / sample_rate_hz).tan();
        let w2 = w * w;
        let mut sections = Vec::with_capacity(order.div_ceil(2));
        for k in 0..order / 2 {
            // Analog pole pair s² + 2ζΩc s + Ωc², ζ = sin(π(2k+1)/(2N)).
            let zeta = (PI * (2 * k + 1) as f64 / (2 * order) as f64).sin();
            let a0 = 1.0 + 2.0 * zeta * w + w2;
            sections.push(Sos {
                b: [w2 / a0, 2.0 * w2 / a0, w2 / a0],
                a: [1.0, (2.0 * w2 - 2.0) / a0, (1.0 - 2.0 * zeta * w + w2) / a0],
            });
        }
        if order % 2 == 1 {
            // Real pole s = −Ωc.
            let a0 = 1.0 + w;
            sections.push(Sos {
                b: [w / a0, w / a0, 0.0],
                a: [1.0, (w - 1.0) / a0, 0.0],
            });
        }
        let mut scale = 1.0;
        let zi = sections
            .iter()
            .map(|s| {
                let z = s.step_state();
                let out = [z[0] * scale, z[1] * scale];
                scale *= s.dc_gain();
                out
            })
            .collect();
        Ok(Self {
            order,
            cutoff_hz,
            sample_rate_hz,
            sections,
            zi,
        })
    }

    pub fn order(&self) -> usize {
        self.order
    }

    pub fn cutoff_hz(&self) -> f64 {
        self.cutoff_hz
    }

    pub fn sample_rate_hz(&self) -> f64 {
        self.sample_rate_hz
    }

    /// The second-order sections, in the order they are applied.
    pub fn sections(&self) -> &[Sos] {
        &self.sections
    }

    /// Magnitude of a digital Butterworth designed by the bilinear transform with prewarping:
    /// `1/√(1 + (tan(πf/fs)/tan(πfc/fs))^(2N))`.
    pub fn analytic_magnitude(order: usize, cutoff_hz: f64, sample_rate_hz: f64, f_hz: f64) -> f64 {
        let r = (PI * f_hz / sample_rate_hz).tan() / (PI * cutoff_hz / sample_rate_hz).tan();
        1.0 / (1.0 + r.powi(2 * order as i32)).sqrt()
    }

    /// `|H(e^{jω})|` of the sections at `f_hz`, evaluated from their coefficients.
    pub fn magnitude(&self, f_hz: f64) -> f64 {
        let w = 2.0 * PI * f_hz / self.sample_rate_hz;
        let (c1, s1, c2, s2) = (w.cos(), -w.sin(), (2.0 * w).cos(), -(2.0 * w).sin());
        self.sections
            .iter()
            .map(|s| {
                let nr = s.b[0] + s.b[1] * c1 + s.b[2] * c2;
                let ni = s.b[1] * s1 + s.b[2] * s2;
                let dr = s.a[0] + s.a[1] * c1 + s.a[2] * c2;
                let di = s.a[1] * s1 + s.a[2] * s2;
                ((nr * nr + ni * ni) / (dr * dr + di * di)).sqrt()
            })
            .product()
    }

    /// Padding length of [`Butterworth::filtfilt`] at each end (scipy's default).
    pub fn padlen(&self) -> usize {
        let first_order = self
            .sections
            .last()
            .is_some_and(|s| s.b[2] == 0.0 && s.a[2] == 0.0);
        3 * (2 * self.sections.len() + 1 - usize::from(first_order))
    }

    /// One causal pass in place from rest (zero initial state), like `scipy.signal.sosfilt`.
    pub fn filter_in_place(&self, x: &mut [f64]) {
        for s in &self.sections {
            run_section(s, [0.0, 0.0], x);
        }
    }

    /// Zero-phase forward-backward filtering of `x` into `out` (resized to `x.len()`);
    /// `scratch` is a reused work buffer. Needs `x.len() > padlen()`.
    pub fn filtfilt(&self, x: &[f64], out: &mut Vec<f64>, scratch: &mut Vec<f64>) -> Result<()> {
        let n = x.len();
        let pad = self.padlen();
        if n <= pad {
            return Err(Error::TooShort {
                file: String::from("signal"),
                samples: n,
                needed: format!(
                    "the zero-phase filter of order {} needs more than {pad}",
                    self.order
                ),
            });
        }
        // Odd extension: [2x0 − x[pad..1], x, 2x_{n−1} − x[n−2..n−2−pad]].
        let ext = scratch;
        ext.clear();
        ext.reserve(n + 2 * pad);
        let (x0, xn) = (x[0], x[n - 1]);
        ext.extend((1..=pad).rev().map(|k| 2.0 * x0 - x[k]));
        ext.extend_from_slice(x);
        ext.extend((2..=pad + 1).map(|k| 2.0 * xn - x[n - k]));

        // Forward.
        let start = ext[0];
        for (s, zi) in self.sections.iter().zip(&self.zi) {
            run_section(s, [zi[0] * start, zi[1] * start], ext);
        }
        // Backward: run on the reversed sequence.
        ext.reverse();
        let start = ext[0];
        for (s, zi) in self.sections.iter().zip(&self.zi) {
            run_section(s, [zi[0] * start, zi[1] * start], ext);
        }
        // ext is reversed: the kept part is ext[pad..pad+n] read backwards.
        out.clear();
        out.extend(ext[pad..pad + n].iter().rev());
        Ok(())
    }
}

/// Transposed direct form II, in place.
#[inline]
fn run_section(s: &Sos, z: [f64; 2], x: &mut [f64]) {
    let [b0, b1, b2] = s.b;
    let [_, a1, a2] = s.a;
    let [mut z1, mut z2] = z;
    for v in x.iter_mut() {
        let xi = *v;
        let y = b0 * xi + z1;
        z1 = b1 * xi - a1 * y + z2;
        z2 = b2 * xi - a2 * y;
        *v = y;
    }
}

/// Sample rate of a uniform time base, `(n−1)/(t_end − t_0)`; the index of the first step
/// that deviates from the mean step by more than 1 % otherwise (as `Err(index)` of the later
/// sample).
pub fn uniform_sample_rate(time: &[f64]) -> std::result::Result<f64, (usize, f64, f64)> {
    let n = time.len();
    if n < 2 {
        return Err((0, f64::NAN, f64::NAN));
    }
    let dt = (time[n - 1] - time[0]) / (n - 1) as f64;
    let tol = 0.01 * dt;
    match time
        .windows(2)
        .position(|w| ((w[1] - w[0]) - dt).abs() > tol)
    {
        None => Ok(1.0 / dt),
        Some(i) => Err((i + 1, time[i + 1] - time[i], dt)),
    }
}

//! Frequency response by Welch's method, paper Eq. 9–10.
//!
//! The estimators follow `scipy.signal.welch`/`csd`/`coherence` exactly (periodic Hann
//! window, segments of `nperseg` samples advanced by `nperseg − noverlap`, trailing samples
//! that do not fill a segment dropped, optional per-segment mean removal, one-sided
//! spectra with `scaling='density'`, mean over segments), so that results can be checked
//! against scipy to rounding error. Cross spectra are `P_xy = mean(conj(X)·Y)·scale`.

use crate::error::{AnalysisError, Result};
use rustfft::num_complex::Complex64;
use rustfft::FftPlanner;
use serde::Serialize;
use std::f64::consts::PI;

/// Per-segment detrending (scipy's `detrend`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Detrend {
    /// `detrend=False`
    None,
    /// `detrend='constant'` (scipy's default): remove each segment's mean.
    Constant,
}

/// Welch parameters.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WelchConfig {
    /// Segment length (samples).
    pub nperseg: usize,
    /// Overlap (samples); `None` = `nperseg / 2` as in scipy.
    pub noverlap: Option<usize>,
    pub detrend: Detrend,
}

impl WelchConfig {
    pub fn new(nperseg: usize) -> Self {
        WelchConfig {
            nperseg,
            noverlap: None,
            detrend: Detrend::Constant,
        }
    }

    pub fn overlap(&self) -> usize {
        self.noverlap.unwrap_or(self.nperseg / 2)
    }
}

/// Auto and cross spectral densities of an input `u` and an output `y`.
#[derive(Debug, Clone, Serialize)]
pub struct Spectra {
    /// Frequencies, Hz (0 … fs/2).
    pub freq: Vec<f64>,
    /// P_uu, unit²/Hz.
    pub puu: Vec<f64>,
    /// P_yy.
    pub pyy: Vec<f64>,
    /// P_uy = mean(conj(U)·Y)·scale.
    #[serde(skip)]
    pub puy: Vec<Complex64>,
    /// Number of averaged segments.
    pub segments: usize,
}

/// The periodic ("DFT-even") Hann window of scipy's `get_window('hann', n)`.
pub fn hann(n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| 0.5 - 0.5 * (2.0 * PI * k as f64 / n as f64).cos())
        .collect()
}

fn check(samples: usize, cfg: &WelchConfig, source: &str) -> Result<usize> {
    if cfg.nperseg < 2 {
        return Err(AnalysisError::InvalidParameter(format!(
            "nperseg must be at least 2, got {}",
            cfg.nperseg
        )));
    }
    let noverlap = cfg.overlap();
    if noverlap >= cfg.nperseg {
        return Err(AnalysisError::InvalidParameter(format!(
            "noverlap ({noverlap}) must be smaller than nperseg ({})",
            cfg.nperseg
        )));
    }
    if samples < cfg.nperseg {
        return Err(AnalysisError::TooFewSamples {
            file: source.to_string(),
            samples,
            nperseg: cfg.nperseg,
        });
    }
    let step = cfg.nperseg - noverlap;
    Ok((samples - noverlap) / step)
}

/// Welch estimate of the spectra of `u` and `y` (same length) sampled at `fs`.
/// `source` names the data in error messages.
pub fn spectra(u: &[f64], y: &[f64], fs: f64, cfg: &WelchConfig, source: &str) -> Result<Spectra> {
    if u.len() != y.len() {
        return Err(AnalysisError::InvalidParameter(format!(
            "{source}: input and output have different lengths ({} and {})",
            u.len(),
            y.len()
        )));
    }
    if !(fs.is_finite() && fs > 0.0) {
        return Err(AnalysisError::InvalidParameter(format!(
            "sampling frequency must be positive, got {fs}"
        )));
    }
    let segments = check(u.len(), cfg, source)?;
    let n = cfg.nperseg;
    let step = n - cfg.overlap();
    let win = hann(n);
    let scale = 1.0 / (fs * win.iter().map(|w| w * w).sum::<f64>());
    let fft = FftPlanner::<f64>::new().plan_fft_forward(n);
    let nf = n / 2 + 1;
    let mut puu = vec![0.0; nf];
    let mut pyy = vec![0.0; nf];
    let mut puy = vec![Complex64::new(0.0, 0.0); nf];
    let mut bu = vec![Complex64::new(0.0, 0.0); n];
    let mut by = vec![Complex64::new(0.0, 0.0); n];
    let prepare = |seg: &[f64], buf: &mut [Complex64]| {
        let mean = match cfg.detrend {
            Detrend::None => 0.0,
            Detrend::Constant => seg.iter().sum::<f64>() / seg.len() as f64,
        };
        for ((b, x), w) in buf.iter_mut().zip(seg).zip(&win) {
            *b = Complex64::new((x - mean) * w, 0.0);
        }
    };
    for s in 0..segments {
        let range = s * step..s * step + n;
        prepare(&u[range.clone()], &mut bu);
        prepare(&y[range], &mut by);
        fft.process(&mut bu);
        fft.process(&mut by);
        for k in 0..nf {
            puu[k] += bu[k].norm_sqr();
            pyy[k] += by[k].norm_sqr();
            puy[k] += bu[k].conj() * by[k];
        }
    }
    // One-sided: double everything but DC and, for even n, Nyquist.
    let last_doubled = if n.is_multiple_of(2) { nf - 1 } else { nf };
    let norm = scale / segments as f64;
    for k in 0..nf {
        let f = if k > 0 && k < last_doubled { 2.0 } else { 1.0 };
        puu[k] *= f * norm;
        pyy[k] *= f * norm;
        puy[k] *= f * norm;
    }
    Ok(Spectra {
        freq: (0..nf).map(|k| k as f64 * fs / n as f64).collect(),
        puu,
        pyy,
        puy,
        segments,
    })
}

/// Welch power spectral density of one signal: `(freq, Pxx)`.
pub fn welch(x: &[f64], fs: f64, cfg: &WelchConfig) -> Result<(Vec<f64>, Vec<f64>)> {
    let s = spectra(x, x, fs, cfg, "signal")?;
    Ok((s.freq, s.puu))
}

/// A frequency response estimate.
#[derive(Debug, Clone, Serialize)]
pub struct Frf {
    /// Hz
    pub freq: Vec<f64>,
    /// H1 = P_uy / P_uu, real parts.
    pub re: Vec<f64>,
    /// H1 imaginary parts.
    pub im: Vec<f64>,
    /// |H1|
    pub magnitude: Vec<f64>,
    /// Unwrapped phase arg(H1) = arg(Y) − arg(U), rad (Eq. 9).
    pub phase: Vec<f64>,
    /// Group delay −dφ/dω, s (Eq. 10).
    pub group_delay: Vec<f64>,
    /// Magnitude-squared coherence |P_uy|² / (P_uu P_yy).
    pub coherence: Vec<f64>,
    pub segments: usize,
    /// Sampling frequency of the data, Hz (0 when unknown).
    pub fs: f64,
}

impl Frf {
    /// The complex H1 values.
    pub fn h(&self) -> Vec<Complex64> {
        self.re
            .iter()
            .zip(&self.im)
            .map(|(r, i)| Complex64::new(*r, *i))
            .collect()
    }

    /// Build from complex values (no coherence known: set to 1).
    pub fn from_response(freq: Vec<f64>, h: &[Complex64]) -> Frf {
        let phase = unwrap(&h.iter().map(|z| z.arg()).collect::<Vec<_>>());
        Frf {
            group_delay: group_delay(&freq, &phase),
            re: h.iter().map(|z| z.re).collect(),
            im: h.iter().map(|z| z.im).collect(),
            magnitude: h.iter().map(|z| z.norm()).collect(),
            coherence: vec![1.0; h.len()],
            freq,
            phase,
            segments: 0,
            fs: 0.0,
        }
    }
}

/// H1 estimate of the FRF from `u` to `y` with coherence, unwrapped phase and group delay.
/// The DC bin is dropped when the segments are mean-detrended (it carries no information).
pub fn h1(u: &[f64], y: &[f64], fs: f64, cfg: &WelchConfig, source: &str) -> Result<Frf> {
    let s = spectra(u, y, fs, cfg, source)?;
    let start = usize::from(cfg.detrend == Detrend::Constant);
    let h: Vec<Complex64> = (start..s.freq.len()).map(|k| s.puy[k] / s.puu[k]).collect();
    let coherence = (start..s.freq.len())
        .map(|k| s.puy[k].norm_sqr() / (s.puu[k] * s.pyy[k]))
        .collect();
    let mut frf = Frf::from_response(s.freq[start..].to_vec(), &h);
    frf.coherence = coherence;
    frf.segments = s.segments;
    frf.fs = fs;
    Ok(frf)
}

/// Phase unwrapping as numpy's `unwrap`: add multiples of 2π so that consecutive
/// differences lie in [−π, π].
pub fn unwrap(phase: &[f64]) -> Vec<f64> {
    let mut out = Vec::with_capacity(phase.len());
    let mut offset = 0.0;
    for (k, &p) in phase.iter().enumerate() {
        if k > 0 {
            let d = p - phase[k - 1];
            let mut dm = (d + PI).rem_euclid(2.0 * PI) - PI;
            if dm == -PI && d > 0.0 {
                dm = PI;
            }
            offset += dm - d;
        }
        out.push(p + offset);
    }
    out
}

/// Group delay −dφ/dω (Eq. 10) by second-order differences (numpy's `gradient`:
/// central inside, one-sided at the ends; non-uniform spacing allowed).
pub fn group_delay(freq: &[f64], phase: &[f64]) -> Vec<f64> {
    let n = freq.len();
    if n < 2 {
        return vec![f64::NAN; n];
    }
    let w: Vec<f64> = freq.iter().map(|f| 2.0 * PI * f).collect();
    (0..n)
        .map(|k| {
            let d = if k == 0 {
                (phase[1] - phase[0]) / (w[1] - w[0])
            } else if k == n - 1 {
                (phase[n - 1] - phase[n - 2]) / (w[n - 1] - w[n - 2])
            } else {
                let h1 = w[k] - w[k - 1];
                let h2 = w[k + 1] - w[k];
                (h1 * h1 * phase[k + 1] - h2 * h2 * phase[k - 1] + (h2 * h2 - h1 * h1) * phase[k])
                    / (h1 * h2 * (h1 + h2))
            };
            -d
        })
        .collect()
}

//! Step response analysis (paper Fig. 2): dead time T_d, rise time (10–90 %) and transient
//! (settling) time, plus a least-squares fit of dead time + first-order lag.
//!
//! Conventions: the step instant `t0` is the time of the first sample at which the
//! setpoint shows its new value. The initial level is the mean of the response before the
//! step, the final level the mean over the last 10 % of the record (so the record must end
//! settled). T_d is the dead time of a least-squares fit of dead time + first-order lag
//! (it uses the whole response, so noise hardly moves it); the model-free *response start*
//! is where the response first leaves the initial level by more than
//! `max(start_threshold·|Δy|, 4σ)` (σ the noise before the step). Rise and band crossings
//! are interpolated linearly between samples.

use crate::error::{AnalysisError, Result};
use crate::optim::nelder_mead;
use crate::signal::TimeSeries;
use serde::Serialize;

/// Step analysis settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct StepConfig {
    /// Settling band, share of the step height (paper: ±2 %).
    pub band: f64,
    /// Rise time between these shares of the step height.
    pub rise_low: f64,
    pub rise_high: f64,
    /// Minimum departure (share of the step height) that counts as the start of the response.
    pub start_threshold: f64,
}

impl Default for StepConfig {
    fn default() -> Self {
        StepConfig {
            band: 0.02,
            rise_low: 0.1,
            rise_high: 0.9,
            start_threshold: 0.02,
        }
    }
}

/// Dead time + first-order lag fitted to the step response in the time domain.
#[derive(Debug, Clone, Serialize)]
pub struct StepFit {
    pub dead_time: f64,
    pub time_constant: f64,
    pub gain: f64,
    /// RMS of the residual, response units.
    pub rms_residual: f64,
}

/// Result of a step analysis. Times in s, relative to the step instant unless named `t_…`.
#[derive(Debug, Clone, Serialize)]
pub struct StepResult {
    /// Step instant, s (absolute).
    pub t_step: f64,
    pub setpoint_before: f64,
    pub setpoint_after: f64,
    pub response_before: f64,
    pub response_after: f64,
    /// Standard deviation of the response before the step (noise).
    pub noise_std: f64,
    /// Sampling step, s.
    pub dt: f64,
    /// Dead time T_d: the apparent dead time of the least-squares fit of dead time +
    /// first-order lag (robust against noise; exact for a first-order loop).
    pub dead_time: f64,
    /// Time from the step to the response's first departure from its initial level
    /// beyond `max(start_threshold, 4σ)`: a model-free upper bound of the dead time.
    pub response_start: f64,
    /// Rise time (default 10–90 %).
    pub rise_time: f64,
    /// Time from the step to the response entering the settling band for good; None when the
    /// record ends outside it.
    pub transient_time: Option<f64>,
    /// Overshoot beyond the final value, share of the step height (0 if none).
    pub overshoot: f64,
    /// The noise (3σ) is wider than the settling band: the transient time is then
    /// lengthened by noise excursions (filter the data or widen the band).
    pub noise_limited: bool,
    pub fit: StepFit,
}

/// Analyse a step of `setpoint` with `response` in a time series.
pub fn analyse(
    ts: &TimeSeries,
    setpoint: &str,
    response: &str,
    cfg: &StepConfig,
) -> Result<StepResult> {
    let u = ts.column(setpoint)?;
    let y = ts.column(response)?;
    let t = ts.time();
    let err = |message: String| step_error(ts.source(), message);
    let n = t.len();
    let k = find_step(ts, u, n, setpoint)?;
    let t0 = t[k];
    let tail = ((n - k) / 10).max(1);
    if n - k < 10 {
        return Err(err(format!(
            "the step at t = {t0} s leaves only {} samples after it",
            n - k
        )));
    }
    let (y0, sigma, y1) = levels(y, k, n, tail);
    let dy = y1 - y0;
    if dy.abs() <= 4.0 * sigma || dy == 0.0 {
        return Err(err(format!(
            "response '{response}' does not follow the step (change {dy:.4e}, noise σ {sigma:.4e})"
        )));
    }
    // Normalised response after the step.
    let r: Vec<f64> = y.iter().map(|v| (v - y0) / dy).collect();
    let start_level = cfg.start_threshold.max(4.0 * sigma / dy.abs());
    let (t_start, t_lo, t_hi) = response_times(&r, t, k, start_level, cfg, ts.source())?;
    let transient_time = transient_time(&r, t, k, cfg.band, t0);
    let overshoot = r[k..].iter().fold(0.0_f64, |a, v| a.max(v - 1.0));
    let fit = fit_step(&t[k..], &y[k..], t0, (t_start - t0, t_hi - t_lo))?;
    Ok(StepResult {
        t_step: t0,
        setpoint_before: u[k - 1],
        setpoint_after: u[k],
        response_before: y0,
        response_after: y1,
        noise_std: sigma,
        dt: ts.dt,
        dead_time: fit.dead_time,
        response_start: t_start - t0,
        rise_time: t_hi - t_lo,
        transient_time,
        overshoot,
        noise_limited: 3.0 * sigma > cfg.band * dy.abs(),
        fit: StepFit {
            gain: fit.gain / (u[k] - u[k - 1]),
            ..fit
        },
    })
}

/// An error in the step response of the file `source`.
fn step_error(source: &str, message: String) -> AnalysisError {
    AnalysisError::StepResponse {
        file: source.to_string(),
        message,
    }
}

/// The step: the sample (of the first `n`) at which the setpoint `u` changes most; an
/// error when it never changes.
fn find_step(ts: &TimeSeries, u: &[f64], n: usize, setpoint: &str) -> Result<usize> {
    let (k, du) = (1..n)
        .map(|k| (k, u[k] - u[k - 1]))
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .unwrap_or((0, 0.0));
    if du == 0.0 {
        return Err(AnalysisError::NoStep {
            file: ts.source().to_string(),
            column: setpoint.to_string(),
        });
    }
    Ok(k)
}

/// The response's levels around the step at sample `k`: `(y0, σ, y1)`, the mean before the
/// step, the noise's standard deviation before it, and the mean over the last `tail` of
/// the `n` samples.
fn levels(y: &[f64], k: usize, n: usize, tail: usize) -> (f64, f64, f64) {
    let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
    let pre = &y[..k];
    let y0 = mean(pre);
    let sigma = if pre.len() > 2 {
        (pre.iter().map(|v| (v - y0).powi(2)).sum::<f64>() / (pre.len() - 1) as f64).sqrt()
    } else {
        0.0
    };
    let y1 = mean(&y[n - tail..]);
    (y0, sigma, y1)
}

/// When the normalised response `r` first reaches `level` from sample `from` on (at least
/// 1), interpolated linearly between samples.
fn crossing(r: &[f64], t: &[f64], level: f64, from: usize) -> Option<f64> {
    let n = t.len();
    (from.max(1)..n).find(|&j| r[j] >= level).map(|j| {
        if j == 0 || r[j - 1] >= level {
            t[j]
        } else {
            t[j - 1] + (level - r[j - 1]) / (r[j] - r[j - 1]) * (t[j] - t[j - 1])
        }
    })
}

/// The absolute times the normalised response `r` starts (reaches `start_level`) and
/// crosses the rise time's low and high shares after the step at sample `k`; an error for
/// the first it never reaches.
fn response_times(
    r: &[f64],
    t: &[f64],
    k: usize,
    start_level: f64,
    cfg: &StepConfig,
    source: &str,
) -> Result<(f64, f64, f64)> {
    let err = |message: String| step_error(source, message);
    let t_start =
        crossing(r, t, start_level, k).ok_or_else(|| err("the response never starts".into()))?;
    let t_lo = crossing(r, t, cfg.rise_low, k).ok_or_else(|| {
        err(format!(
            "the response never reaches {} %",
            cfg.rise_low * 100.0
        ))
    })?;
    let t_hi = crossing(r, t, cfg.rise_high, k).ok_or_else(|| {
        err(format!(
            "the response never reaches {} %",
            cfg.rise_high * 100.0
        ))
    })?;
    Ok((t_start, t_lo, t_hi))
}

/// Time from the step (at `t0`, sample `k`) to the normalised response `r` entering the
/// settling band `±band` for good, the band edge interpolated; `None` when the record ends
/// outside it.
fn transient_time(r: &[f64], t: &[f64], k: usize, band: f64, t0: f64) -> Option<f64> {
    let n = t.len();
    match (k..n).rev().find(|&j| (r[j] - 1.0).abs() > band) {
        None => Some(0.0),
        Some(j) if j + 1 < n => {
            // interpolate the band edge between the last outside sample and the next
            let edge = if r[j] > 1.0 { 1.0 + band } else { 1.0 - band };
            let tc = t[j] + (edge - r[j]) / (r[j + 1] - r[j]) * (t[j + 1] - t[j]);
            Some(tc - t0)
        }
        Some(_) => None,
    }
}

/// Fit `y = a + b·(1 − exp(−(t − t0 − T_d)/T))` (0 before `t0 + T_d`) to the samples after
/// the step; `a`, `b` by linear least squares, `T_d`, `T` by Nelder–Mead.
fn fit_step(t: &[f64], y: &[f64], t0: f64, (td0, rise): (f64, f64)) -> Result<StepFit> {
    let shape = |td: f64, tau: f64, tk: f64| -> f64 {
        let x = tk - t0 - td;
        if x <= 0.0 {
            0.0
        } else {
            1.0 - (-x / tau).exp()
        }
    };
    let solve = |td: f64, tau: f64| -> (f64, f64, f64) {
        let s: Vec<f64> = t.iter().map(|&tk| shape(td, tau, tk)).collect();
        let ones = vec![1.0; s.len()];
        let (a, b) = crate::fit::linear_fit(&s, y, &ones);
        let sse = s
            .iter()
            .zip(y)
            .map(|(sk, yk)| (a + b * sk - yk).powi(2))
            .sum::<f64>();
        (sse, a, b)
    };
    // For a first-order lag the 10–90 % rise time is T·ln 9.
    let tau0 = (rise / 9f64.ln()).max(1e-12);
    let f = |x: &[f64]| solve(x[0], x[1].exp()).0;
    let dt = (t[t.len() - 1] - t[0]) / (t.len() - 1) as f64;
    let (x, _) = nelder_mead(&f, &[td0.max(0.0), tau0.ln()], &[dt, 0.2], 3000, 1e-14);
    let (x, _) = nelder_mead(&f, &x, &[0.2 * dt, 0.05], 3000, 1e-14);
    let (sse, _a, b) = solve(x[0], x[1].exp());
    Ok(StepFit {
        dead_time: x[0],
        time_constant: x[1].exp(),
        gain: b,
        rms_residual: (sse / t.len() as f64).sqrt(),
    })
}

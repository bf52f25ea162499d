//! Least-squares fit of a dead time plus a lag to an FRF, and the dyno parameters it gives.
//!
//! Models: `G(s) = K e^{−sT_d} / (1 + sT)` (first order, the dyno's default) or
//! `G(s) = K e^{−sT_d} ω_n² / (s² + 2ζω_n s + ω_n²)` (second order). The residual is the
//! complex logarithm of the ratio `G(jω)/H(jω)`: its real part is the magnitude error in
//! nepers, its imaginary part the phase error in radians, so that decades of magnitude and
//! the phase weigh alike. Each bin is weighted by its coherence; the gain `K` follows in
//! closed form; the time parameters by a Nelder–Mead search started from a linear fit of
//! the unwrapped phase.

use crate::error::{AnalysisError, Result};
use crate::frf::Frf;
use crate::optim::nelder_mead;
use rustfft::num_complex::Complex64;
use serde::Serialize;
use std::f64::consts::PI;

/// Which lag follows the dead time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum LagOrder {
    First,
    Second,
}

/// Fit settings.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct FitConfig {
    pub order: LagOrder,
    /// Lowest frequency used, Hz (bins at 0 are always skipped).
    pub f_min: f64,
    /// Highest frequency used, Hz (`INFINITY` = up to Nyquist).
    pub f_max: f64,
    /// Bins with lower coherence are ignored.
    pub min_coherence: f64,
    /// How the data were sampled; decides between the continuous and a sampled model.
    pub sampling: Sampling,
}

/// Which form of the model is compared with the FRF.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
#[serde(rename_all = "snake_case", tag = "kind")]
pub enum Sampling {
    /// `G(jω)` itself: for an input that varies between samples. On data whose input is
    /// held between samples the dead time then includes half a sampling step.
    Continuous,
    /// The input is held between samples (a setpoint sent at the sampling rate) and the
    /// loop's delay and lag act continuously: the exact sampled model (zero-order hold,
    /// modified z-transform for a dead time that is not a whole number of samples).
    HeldInput,
    /// The dyno FMU's own discrete loop: demand sampled every `cycle_time` (which must
    /// equal the sampling step), dead time interpolated linearly between cycles, lag
    /// discretised with a zero-order hold. Recovers the FMU's parameters exactly.
    DynoCycle { cycle_time: f64 },
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            order: LagOrder::First,
            f_min: 0.0,
            f_max: f64::INFINITY,
            min_coherence: 0.8,
            sampling: Sampling::Continuous,
        }
    }
}

/// A fitted dead time + lag model.
#[derive(Debug, Clone, Serialize)]
pub struct FrfFit {
    pub order: LagOrder,
    /// Static gain K.
    pub gain: f64,
    /// Dead time T_d, s.
    pub dead_time: f64,
    /// First order: time constant T, s.
    pub time_constant: Option<f64>,
    /// Second order: natural frequency ω_n, rad/s.
    pub natural_frequency: Option<f64>,
    /// Second order: damping ratio ζ.
    pub damping_ratio: Option<f64>,
    /// Frequency band actually used, Hz, and number of bins.
    pub f_lo: f64,
    pub f_hi: f64,
    pub bins: usize,
    /// Weighted RMS of the log residual (≈ relative error).
    pub rms_residual: f64,
    /// The model form that was fitted.
    pub sampling: Sampling,
    /// Sampling step of the data, s (for the sampled forms).
    pub dt: f64,
}

impl FrfFit {
    /// The model's response at `f` Hz.
    pub fn response(&self, f: f64) -> Complex64 {
        let p = match self.order {
            LagOrder::First => [self.dead_time, self.time_constant.unwrap_or(0.0), 0.0],
            LagOrder::Second => [
                self.dead_time,
                self.natural_frequency.unwrap_or(1.0),
                self.damping_ratio.unwrap_or(1.0),
            ],
        };
        Evaluator::new(self.order, &p, self.sampling, self.dt).at(2.0 * PI * f) * self.gain
    }

    /// The dyno FMU's parameters as a system-file snippet for instance `instance`.
    pub fn parameters_toml(&self, instance: &str) -> String {
        let mut s = format!(
            "# dyno loop identified by twinbench identify frf ({} order lag, {:.1}–{:.1} Hz, {} bins)\n[parameters]\n\"{instance}.dead_time\" = {}\n",
            match self.order {
                LagOrder::First => "first",
                LagOrder::Second => "second",
            },
            self.f_lo,
            self.f_hi,
            self.bins,
            fmt_param(self.dead_time.max(0.0)),
        );
        match self.order {
            LagOrder::First => {
                s += &format!(
                    "\"{instance}.lag_order\" = 1\n\"{instance}.time_constant\" = {}\n",
                    fmt_param(self.time_constant.unwrap_or(0.0))
                );
            }
            LagOrder::Second => {
                // The dyno's second-order lag: ω_n = 1/time_constant, ζ = damping.
                s += &format!(
                    "\"{instance}.lag_order\" = 2\n\"{instance}.time_constant\" = {}\n\"{instance}.damping\" = {}\n",
                    fmt_param(1.0 / self.natural_frequency.unwrap_or(f64::INFINITY)),
                    fmt_param(self.damping_ratio.unwrap_or(0.0))
                );
            }
        }
        s
    }
}

/// Four significant digits, plain decimal where sensible (valid TOML float either way).
fn fmt_param(v: f64) -> String {
    if v == 0.0 {
        return "0.0".into();
    }
    let digits = (3 - v.abs().log10().floor() as i32).max(1) as usize;
    if v.abs() >= 1e-6 && v.abs() < 1e7 {
        let s = format!("{v:.digits$}");
        if s.contains('.') {
            s
        } else {
            s + ".0"
        }
    } else {
        format!("{v:.3e}")
    }
}

/// Evaluates `G(jω)/K` for parameters `[T_d, T, _]` (first order) or `[T_d, ω_n, ζ]`
/// (second order) in the chosen form; the discretisation is done once per parameter set.
enum Evaluator {
    Continuous { order: LagOrder, p: [f64; 3] },
    Sampled(Discrete),
}

/// `H(z) = z^{−i} · C (zI − Φ)⁻¹ (Γ₀ + Γ₁ z⁻¹)` with `z = e^{jωh}` (n = 1 or 2 states).
struct Discrete {
    h: f64,
    whole: f64,
    phi: nalgebra::Matrix2<f64>,
    g0: nalgebra::Vector2<f64>,
    g1: nalgebra::Vector2<f64>,
    states: usize,
}

impl Discrete {
    fn at(&self, w: f64) -> Complex64 {
        let (h, phi, g0, g1) = (self.h, &self.phi, &self.g0, &self.g1);
        let z = Complex64::from_polar(1.0, w * h);
        let zi = 1.0 / z;
        let v0 = Complex64::from(g0[0]) + zi * g1[0];
        let lag = if self.states == 1 {
            v0 / (z - phi[(0, 0)])
        } else {
            let v1 = Complex64::from(g0[1]) + zi * g1[1];
            let (p00, p01, p10, p11) = (phi[(0, 0)], phi[(0, 1)], phi[(1, 0)], phi[(1, 1)]);
            let det = (z - p00) * (z - p11) - p01 * p10;
            ((z - p11) * v0 + p01 * v1) / det
        };
        Complex64::from_polar(1.0, -w * h * self.whole) * lag
    }
}

/// `(e^{Aτ}, ∫₀^τ e^{Aσ} dσ · B)` by the exponential of the augmented matrix.
fn zoh(
    a: &nalgebra::Matrix2<f64>,
    b: &nalgebra::Vector2<f64>,
    tau: f64,
) -> (nalgebra::Matrix2<f64>, nalgebra::Vector2<f64>) {
    let mut m = nalgebra::Matrix3::zeros();
    m.fixed_view_mut::<2, 2>(0, 0).copy_from(&(a * tau));
    m.fixed_view_mut::<2, 1>(0, 2).copy_from(&(b * tau));
    let e = m.exp();
    (
        e.fixed_view::<2, 2>(0, 0).into_owned(),
        e.fixed_view::<2, 1>(0, 2).into_owned(),
    )
}

impl Evaluator {
    fn new(order: LagOrder, p: &[f64; 3], sampling: Sampling, dt: f64) -> Evaluator {
        use nalgebra::{Matrix2, Vector2};
        let (h, interpolate) = match sampling {
            Sampling::Continuous => return Evaluator::Continuous { order, p: *p },
            Sampling::HeldInput => (dt, false),
            Sampling::DynoCycle { cycle_time } => (cycle_time, true),
        };
        let d = (p[0] / h).max(0.0);
        let whole = d.floor();
        let frac = d - whole;
        // State space of the lag: first order in the first component only.
        let (a, b, states) = match order {
            LagOrder::First => {
                let t = p[1].max(1e-12 * h);
                (
                    Matrix2::new(-1.0 / t, 0.0, 0.0, -1.0),
                    Vector2::new(1.0 / t, 0.0),
                    1,
                )
            }
            LagOrder::Second => {
                let (wn, z) = (p[1], p[2]);
                (
                    Matrix2::new(0.0, 1.0, -wn * wn, -2.0 * z * wn),
                    Vector2::new(0.0, wn * wn),
                    2,
                )
            }
        };
        let (phi, g) = zoh(&a, &b, h);
        let (g0, g1) = if interpolate {
            // the dyno feeds (1−φ)u_{k−i} + φu_{k−i−1}, held for the whole cycle
            (g * (1.0 - frac), g * frac)
        } else {
            // u_{k−i−1} for the first φh of the interval, u_{k−i} for the rest
            let (phi2, g2) = zoh(&a, &b, (1.0 - frac) * h);
            let (_, g1) = zoh(&a, &b, frac * h);
            (g2, phi2 * g1)
        };
        Evaluator::Sampled(Discrete {
            h,
            whole,
            phi,
            g0,
            g1,
            states,
        })
    }

    fn at(&self, w: f64) -> Complex64 {
        match self {
            Evaluator::Continuous { order, p } => {
                let delay = Complex64::from_polar(1.0, -w * p[0]);
                let s = Complex64::new(0.0, w);
                let lag = match order {
                    LagOrder::First => 1.0 / (1.0 + s * p[1]),
                    LagOrder::Second => {
                        let (wn, z) = (p[1], p[2]);
                        wn * wn / (s * s + 2.0 * z * wn * s + wn * wn)
                    }
                };
                delay * lag
            }
            Evaluator::Sampled(d) => d.at(w),
        }
    }
}

/// Fit a dead time + lag to an FRF estimate.
pub fn fit(frf: &Frf, cfg: &FitConfig) -> Result<FrfFit> {
    check_sampling(frf, cfg)?;
    let dt = if frf.fs > 0.0 { 1.0 / frf.fs } else { 0.0 };
    let h = frf.h();
    let sel = fitted_bins(frf, &h, cfg)?;
    let bins = Bins::new(frf, &h, &sel, cfg.sampling, dt);
    let first = bins.first_order();
    let params = match cfg.order {
        LagOrder::First => first,
        LagOrder::Second => bins.second_order(&first),
    };
    let (c, ln_k) = bins.cost(cfg.order, &params);
    Ok(FrfFit {
        order: cfg.order,
        gain: ln_k.exp(),
        dead_time: params[0],
        time_constant: (cfg.order == LagOrder::First).then_some(params[1]),
        natural_frequency: (cfg.order == LagOrder::Second).then_some(params[1]),
        damping_ratio: (cfg.order == LagOrder::Second).then_some(params[2]),
        f_lo: frf.freq[sel[0]],
        f_hi: frf.freq[sel[sel.len() - 1]],
        bins: sel.len(),
        rms_residual: (c / bins.wsum).sqrt(),
        sampling: cfg.sampling,
        dt,
    })
}

/// The data suit the model form: the sampled forms need the sampling frequency, and the
/// dyno-cycle form data sampled at its (positive) controller cycle.
fn check_sampling(frf: &Frf, cfg: &FitConfig) -> Result<()> {
    match cfg.sampling {
        Sampling::Continuous => {}
        Sampling::HeldInput if !frf.fs.is_finite() || frf.fs <= 0.0 => {
            return Err(AnalysisError::Fit(
                "the held-input model needs the sampling frequency of the data".into(),
            ))
        }
        Sampling::HeldInput => {}
        Sampling::DynoCycle { cycle_time: c } => {
            if !(c.is_finite() && c > 0.0) {
                return Err(AnalysisError::Fit(format!(
                    "cycle time must be positive, got {c} s"
                )));
            }
            if !frf.fs.is_finite() || frf.fs <= 0.0 || (c * frf.fs - 1.0).abs() > 1e-6 {
                return Err(AnalysisError::Fit(format!(
                    "the dyno-cycle model needs data sampled at the controller cycle: cycle time {c} s, but the sampling step is {} s (fit the held-input model instead)",
                    1.0 / frf.fs
                )));
            }
        }
    }
    Ok(())
}

/// The bins the fit uses (indices into the FRF): above 0 Hz, in the configured band, coherent
/// enough, with a finite non-zero response; at least 4 of them.
fn fitted_bins(frf: &Frf, h: &[Complex64], cfg: &FitConfig) -> Result<Vec<usize>> {
    let sel: Vec<usize> = (0..frf.freq.len())
        .filter(|&k| {
            let f = frf.freq[k];
            f > 0.0
                && f >= cfg.f_min
                && f <= cfg.f_max
                && frf.coherence[k] >= cfg.min_coherence
                && h[k].norm() > 0.0
                && h[k].norm().is_finite()
        })
        .collect();
    if sel.len() < 4 {
        return Err(AnalysisError::Fit(format!(
            "only {} frequency bins in {}–{} Hz with coherence ≥ {}; need at least 4 (excite more, average longer or lower --min-coherence)",
            sel.len(),
            cfg.f_min,
            cfg.f_max,
            cfg.min_coherence
        )));
    }
    Ok(sel)
}

/// The fitted bins and the model form compared with them: what the cost of a parameter
/// set is computed from.
struct Bins {
    /// Angular frequency of each bin, rad/s.
    w: Vec<f64>,
    /// The FRF at each bin.
    hs: Vec<Complex64>,
    /// Each bin's weight, its coherence, and their sum.
    wt: Vec<f64>,
    wsum: f64,
    sampling: Sampling,
    dt: f64,
}

impl Bins {
    fn new(frf: &Frf, h: &[Complex64], sel: &[usize], sampling: Sampling, dt: f64) -> Bins {
        let w: Vec<f64> = sel.iter().map(|&k| 2.0 * PI * frf.freq[k]).collect();
        let hs: Vec<Complex64> = sel.iter().map(|&k| h[k]).collect();
        let wt: Vec<f64> = sel.iter().map(|&k| frf.coherence[k]).collect();
        let wsum: f64 = wt.iter().sum();
        Bins {
            w,
            hs,
            wt,
            wsum,
            sampling,
            dt,
        }
    }

    /// Cost for given time parameters, with the optimal log-gain in closed form:
    /// `(cost, ln K)`.
    fn cost(&self, order: LagOrder, p: &[f64; 3]) -> (f64, f64) {
        let (w, hs, wt, wsum) = (&self.w, &self.hs, &self.wt, self.wsum);
        let ev = Evaluator::new(order, p, self.sampling, self.dt);
        let r: Vec<Complex64> = w
            .iter()
            .zip(hs)
            .map(|(&wk, hk)| (ev.at(wk) / hk).ln())
            .collect();
        let ln_k = -r.iter().zip(wt).map(|(z, q)| z.re * q).sum::<f64>() / wsum;
        let c = r
            .iter()
            .zip(wt)
            .map(|(z, q)| q * ((z.re + ln_k).powi(2) + z.im.powi(2)))
            .sum::<f64>();
        (c, ln_k)
    }

    /// The start of the time constant, from the magnitude: 1/|H|² = (1 + ω²T²)/K², linear
    /// in ω² (else the period of the highest bin).
    fn start_time_constant(&self) -> f64 {
        let (w, hs, wt) = (&self.w, &self.hs, &self.wt);
        let xs: Vec<f64> = w.iter().map(|x| x * x).collect();
        let ys: Vec<f64> = hs.iter().map(|z| 1.0 / z.norm_sqr()).collect();
        let (a, b) = linear_fit(&xs, &ys, wt);
        if a > 0.0 && b > 0.0 {
            (b / a).sqrt()
        } else {
            1.0 / w[w.len() - 1]
        }
    }

    /// The dead time that goes with time constant `t`, from the unwrapped `phase` of H:
    /// least squares through the origin of −φ − atan(ωT) against ω.
    fn dead_time_for(&self, phase: &[f64], t: f64) -> f64 {
        let (w, wt) = (&self.w, &self.wt);
        let num: f64 = w
            .iter()
            .zip(phase)
            .zip(wt)
            .map(|((wk, ph), q)| q * wk * (-ph - (wk * t).atan()))
            .sum();
        let den: f64 = w.iter().zip(wt).map(|(wk, q)| q * wk * wk).sum();
        (num / den).max(0.0)
    }

    /// The first-order fit `[T_d, T, 0]`: a Nelder–Mead search, then a finer one, started
    /// from the phase and the magnitude.
    fn first_order(&self) -> [f64; 3] {
        let w = &self.w;
        // Start: phase of H (unwrapped over the selected bins) ≈ −ωT_d − atan(ωT).
        let phase = crate::frf::unwrap(&self.hs.iter().map(|z| z.arg()).collect::<Vec<_>>());
        let t0 = self.start_time_constant();
        let start = [self.dead_time_for(&phase, t0), t0.max(1e-9).ln()];
        let f = |x: &[f64]| self.cost(LagOrder::First, &[x[0], x[1].exp(), 0.0]).0;
        let scale = 1.0 / w[w.len() - 1];
        let (x, _) = nelder_mead(&f, &start, &[scale, 0.3], 4000, 1e-15);
        let (x, _) = nelder_mead(&f, &x, &[scale * 0.1, 0.05], 4000, 1e-15);
        [x[0], x[1].exp(), 0.0]
    }

    /// The second-order fit `[T_d, ω_n, ζ]`: the best of searches started at several
    /// damping ratios from the first-order fit `first`.
    fn second_order(&self, first: &[f64; 3]) -> [f64; 3] {
        let w = &self.w;
        let mut best: Option<([f64; 3], f64)> = None;
        for zeta in [0.3, 0.7, 1.0, 1.5] {
            // a second-order lag with the same low-frequency delay as the first-order fit
            let wn = 2.0 * zeta / first[1].max(1e-9);
            let start = [first[0], wn.ln(), f64::ln(zeta)];
            let f = |x: &[f64]| {
                self.cost(LagOrder::Second, &[x[0], x[1].exp(), x[2].exp()])
                    .0
            };
            let scale = 1.0 / w[w.len() - 1];
            let (x, v) = nelder_mead(&f, &start, &[scale, 0.3, 0.3], 6000, 1e-15);
            let (x, v2) = nelder_mead(&f, &x, &[scale * 0.1, 0.05, 0.05], 6000, 1e-15);
            let v = v.min(v2);
            if best.as_ref().is_none_or(|b| v < b.1) {
                best = Some(([x[0], x[1].exp(), x[2].exp()], v));
            }
        }
        best.expect("at least one start").0
    }
}

/// Weighted least squares `y = a + b x`; returns `(a, b)`.
pub(crate) fn linear_fit(x: &[f64], y: &[f64], wt: &[f64]) -> (f64, f64) {
    let sw: f64 = wt.iter().sum();
    let mx = x.iter().zip(wt).map(|(a, q)| a * q).sum::<f64>() / sw;
    let my = y.iter().zip(wt).map(|(a, q)| a * q).sum::<f64>() / sw;
    let sxx: f64 = x.iter().zip(wt).map(|(a, q)| q * (a - mx) * (a - mx)).sum();
    let sxy: f64 = x
        .iter()
        .zip(y)
        .zip(wt)
        .map(|((a, b), q)| q * (a - mx) * (b - my))
        .sum();
    let b = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    (my - b * mx, b)
}

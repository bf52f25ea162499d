//! The long-run covariance of the scores from the residuals' autocovariance in time: the
//! meat of the sandwich where the measurement's noise is the same over the lap.
//!
//! **Why.** The scores' own long-run covariance (Newey–West, prewhitened: see
//! [`crate::interval`]) is estimated from the scores alone, and a parameter's scores are
//! large only where the signals see it: c_lift_front's on the straights at speed, a few
//! correlation times of a logger's noise per lap. Its standard error then rested on some
//! twenty effective samples and varied twofold between replicates of one lap; the twin's
//! own laps showed its errors spreading 1.6–2 times the standard error (13 of 20 intervals
//! holding the truth) on a circuit with long straights. A logger's noise (a load cell's
//! drift, the road, the filter) persists in *time* and is the same on a straight as in a
//! hairpin: its autocovariance Γ(τ) is estimated from every residual of every signal, and
//! the scores' covariance follows from it,
//!
//!   M = Σ_b Σ_b' Ĵ_bᵀ Γ(t_b' − t_b) Ĵ_b',
//!
//! Ĵ_b the weighted sensitivities summed over time bin b (every signal), Γ between every
//! pair of signals (the axle sums share the wheels' noise). Estimated from thousands of
//! residuals, not the few where a parameter is seen, it is precise: a standard error from
//! it varies with the lap's shape, not with the noise's draw.
//!
//! **The window.** Γ is cut with the flat-top taper of Politis (2003): flat to the lag m̂
//! after which the residuals' pooled autocorrelation stays within 2·√(log₁₀ n / n) of 0
//! for 5 lags, falling linearly to 0 at 2m̂ (a flat top keeps Γ's slowly decaying shoulder
//! whole, where a Bartlett taper would shave it). At most a quarter of the lap.
//!
//! **Where it does not hold**: a noise that grows with speed (the road at 80 m/s), or a
//! residual that is the twin's discrepancy rather than noise. The scores' own standard
//! error is kept beside it in the results (`std_error_scores`); the model check says when
//! the residual is the twin's, and the interval with the model's share then covers it.
//! (The larger of the two per parameter was tried: it made the track widths' intervals
//! too wide on the twin's own laps, sd(z) 0.76.)

use crate::block::Block;

/// The width of a time bin as a share of the compare filter's period: the filtered
/// residual is nearly constant over a tenth of a period, so a bin's mean stands for it.
pub(crate) const BIN_OF_PERIOD: f64 = 0.1;
/// Politis' rule: the autocorrelation within `C·√(log₁₀ n / n)` for `K` lags.
const C: f64 = 2.0;
const K: usize = 5;

/// The laps' clocks: per segment (a lap), the time at each of its grid points (from grid
/// point 0), and the width of a time bin.
pub(crate) struct Clocks<'a> {
    pub times: &'a [Vec<f64>],
    pub bin_s: f64,
}

/// What [`meat`] found: the scores' covariance (range-scaled parameters, as
/// [`crate::interval`] works), and whether a quarter of a lap cut the window.
pub(crate) struct NoiseMeat {
    pub meat: Vec<Vec<f64>>,
    pub capped: bool,
}

/// M from the residuals' autocovariance in time, over the laps (independent: summed).
/// `span` scales the parameters as [`crate::interval::sandwich`] does; `factor(b)` is
/// block b's weight w_s/σ_s². `None` where a lap has no clock or too few bins.
pub(crate) fn meat(
    blocks: &[Block],
    span: &[f64],
    factor: impl Fn(&Block) -> f64,
    clocks: &Clocks,
) -> Option<NoiseMeat> {
    let p = span.len();
    let mut segments: Vec<usize> = blocks.iter().map(|b| b.segment).collect();
    segments.sort_unstable();
    segments.dedup();
    let mut total = vec![vec![0.0; p]; p];
    let mut capped = false;
    for seg in segments {
        let of: Vec<&Block> = blocks.iter().filter(|b| b.segment == seg).collect();
        let lap = Binned::of(&of, clocks.times.get(seg)?, clocks.bin_s, span, &factor)?;
        let window = Window::of(&lap)?;
        capped |= window.capped;
        lap.add_meat(&window, &mut total);
    }
    Some(NoiseMeat {
        meat: total,
        capped,
    })
}

/// One lap in time bins: per signal, the bins' mean residual (NaN where a bin has none) and
/// the summed weighted, range-scaled sensitivities.
struct Binned {
    mean: Vec<Vec<f64>>,
    jsum: Vec<Vec<Vec<f64>>>,
    /// Bins.
    n: usize,
}

impl Binned {
    fn of(
        of: &[&Block],
        times: &[f64],
        bin_s: f64,
        span: &[f64],
        factor: &impl Fn(&Block) -> f64,
    ) -> Option<Binned> {
        let p = span.len();
        let start = of.iter().map(|b| b.start).min()?;
        let end = of.iter().map(|b| b.start + b.residual.len()).max()?;
        if end > times.len() || start >= end {
            return None;
        }
        let t0 = times[start];
        let bin = |g: usize| ((times[g] - t0) / bin_s).max(0.0) as usize;
        let n = bin(end - 1) + 1;
        let mut mean = vec![vec![f64::NAN; n]; of.len()];
        let mut jsum = vec![vec![vec![0.0; p]; n]; of.len()];
        for (s, b) in of.iter().enumerate() {
            let c = factor(b);
            let (mut sum, mut count) = (vec![0.0; n], vec![0usize; n]);
            for (k, (row, e)) in b.rows.iter().zip(&b.residual).enumerate() {
                let i = bin(b.start + k);
                sum[i] += e;
                count[i] += 1;
                for ((acc, j), sp) in jsum[s][i].iter_mut().zip(row).zip(span) {
                    *acc += c * j * sp;
                }
            }
            for i in 0..n {
                if count[i] > 0 {
                    mean[s][i] = sum[i] / count[i] as f64;
                }
            }
        }
        Some(Binned { mean, jsum, n })
    }

    /// Γ(k) between every pair of signals, each from the bin pairs both have.
    fn gamma_at(&self, k: usize) -> Vec<Vec<f64>> {
        let signals = self.mean.len();
        (0..signals)
            .map(|a| {
                (0..signals)
                    .map(|b| {
                        let (mut sum, mut pairs) = (0.0, 0usize);
                        for i in 0..self.n - k {
                            let v = self.mean[a][i] * self.mean[b][i + k];
                            if v.is_finite() {
                                sum += v;
                                pairs += 1;
                            }
                        }
                        if pairs > 0 {
                            sum / pairs as f64
                        } else {
                            0.0
                        }
                    })
                    .collect()
            })
            .collect()
    }

    /// Adds M = Σ_i Ĵ_iᵀ Σ_k w_k Γ(k) Ĵ_{i+k} (and its transpose for k > 0) to `total`.
    fn add_meat(&self, window: &Window, total: &mut [Vec<f64>]) {
        let p = total.len();
        for (k, g) in window.gamma.iter().enumerate().take(window.width + 1) {
            let w = window.weight(k);
            if w == 0.0 {
                continue;
            }
            let mut lagged = vec![vec![0.0; p]; p];
            for i in 0..self.n - k {
                for (lane, g_row) in self.jsum.iter().zip(g) {
                    let ja = &lane[i];
                    if ja.iter().all(|v| *v == 0.0) {
                        continue;
                    }
                    for (&gab, other) in g_row.iter().zip(&self.jsum) {
                        if gab == 0.0 {
                            continue;
                        }
                        let jb = &other[i + k];
                        for (x, row) in lagged.iter_mut().enumerate() {
                            let f = w * gab * ja[x];
                            for (y, cell) in row.iter_mut().enumerate() {
                                *cell += f * jb[y];
                            }
                        }
                    }
                }
            }
            for x in 0..p {
                for y in 0..p {
                    total[x][y] += lagged[x][y];
                    if k > 0 {
                        total[y][x] += lagged[x][y];
                    }
                }
            }
        }
    }
}

/// Politis' flat-top window of a lap's Γ: flat to `m`, zero at `width` (2m, at most a
/// quarter of the lap); Γ(0..=width) computed.
struct Window {
    gamma: Vec<Vec<Vec<f64>>>,
    m: usize,
    width: usize,
    /// No lag stayed within the band before a quarter of the lap.
    capped: bool,
}

impl Window {
    fn of(lap: &Binned) -> Option<Window> {
        let (n, signals) = (lap.n, lap.mean.len());
        let cap = n / 4;
        if cap < 2 * K {
            return None;
        }
        let trace = |g: &[Vec<f64>]| (0..signals).map(|s| g[s][s]).sum::<f64>();
        let mut gamma = vec![lap.gamma_at(0)];
        let var = trace(&gamma[0]);
        if !(var > 0.0 && var.is_finite()) {
            return None;
        }
        let band = C * ((n as f64).log10() / n as f64).sqrt();
        // m̂: the first lag after which K in a row stay within the band.
        let mut m = None;
        let mut quiet = 0;
        let mut k = 1;
        while k <= cap {
            gamma.push(lap.gamma_at(k));
            if (trace(&gamma[k]) / var).abs() < band {
                quiet += 1;
                if quiet == K {
                    m = Some(k - K);
                    break;
                }
            } else {
                quiet = 0;
            }
            k += 1;
        }
        let (m, capped) = match m {
            Some(m) => (m.max(1), false),
            None => (cap / 2, true),
        };
        let width = (2 * m).min(cap);
        while gamma.len() <= width {
            gamma.push(lap.gamma_at(gamma.len()));
        }
        Some(Window {
            gamma,
            m,
            width,
            capped,
        })
    }

    fn weight(&self, k: usize) -> f64 {
        if k <= self.m {
            1.0
        } else {
            (2.0 - k as f64 / self.m as f64).max(0.0)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::interval::{sandwich, sandwich_with};

    /// A lap of 200 m stretches, straights at 70 m/s and corners at 20 m/s, on a 1 m grid;
    /// a load y = a + b·(v/70)² (b seen on the straights, as a lift coefficient is) with a
    /// noise that persists 1 s in time (AR(1)), the same on a straight as in a corner. The
    /// interval of b from the noise in time covers the truth at the level with standard
    /// errors that spread as they should (sd(z) within [0.8, 1.25]) over 200 replicates.
    #[test]
    fn a_noise_that_persists_in_time_is_covered_with_a_calibrated_standard_error() {
        let (n, tau, truth) = (4000usize, 1.0f64, [1.0, 0.5]);
        let v: Vec<f64> = (0..n)
            .map(|g| if (g / 200) % 2 == 0 { 70.0 } else { 20.0 })
            .collect();
        let x: Vec<f64> = v.iter().map(|v| (v / 70.0).powi(2)).collect();
        let mut times = Vec::with_capacity(n);
        let mut now = 0.0;
        for v in &v {
            times.push(now);
            now += 1.0 / v;
        }
        let clocks_times = vec![times.clone()];
        let clocks = Clocks {
            times: &clocks_times,
            bin_s: 0.05,
        };
        let mut rng = crate::rng::Rng::new(4242);
        let mut gauss = || rng.normal();
        let (cases, mut covered) = (200, 0);
        let (mut z, mut z_scores) = (Vec::new(), Vec::new());
        for _ in 0..cases {
            let mut e = 0.0;
            let y: Vec<f64> = (0..n)
                .map(|g| {
                    let rho = (-(1.0 / v[g]) / tau).exp();
                    e = rho * e + (1.0 - rho * rho).sqrt() * gauss();
                    truth[0] + truth[1] * x[g] + 0.1 * e
                })
                .collect();
            let nf = n as f64;
            let (sx, sy) = (x.iter().sum::<f64>(), y.iter().sum::<f64>());
            let sxx = x.iter().map(|x| x * x).sum::<f64>();
            let sxy = x.iter().zip(&y).map(|(x, y)| x * y).sum::<f64>();
            let b = (nf * sxy - sx * sy) / (nf * sxx - sx * sx);
            let a = (sy - b * sx) / nf;
            let block = || Block {
                start: 0,
                residual: x.iter().zip(&y).map(|(x, y)| a + b * x - y).collect(),
                rows: x.iter().map(|&x| vec![1.0, x]).collect(),
                weight: 1.0,
                factor: None,
                segment: 0,
            };
            let names = vec!["a".to_string(), "b".to_string()];
            let bounds = [(-10.0, 10.0), (-10.0, 10.0)];
            let iv = sandwich_with(&names, &[a, b], &bounds, &[block()], 0, Some(&clocks));
            let pb = &iv.parameters[1];
            z.push((b - truth[1]) / pb.std_error.expect("a standard error"));
            if pb.lo.is_some_and(|lo| lo <= truth[1]) && pb.hi.is_some_and(|hi| truth[1] <= hi) {
                covered += 1;
            }
            let on_grid = sandwich(&names, &[a, b], &bounds, &[block()], 0);
            z_scores.push((b - truth[1]) / on_grid.parameters[1].std_error.expect("one"));
        }
        let sd = |z: &[f64]| (z.iter().map(|z| z * z).sum::<f64>() / z.len() as f64).sqrt();
        let share = covered as f64 / cases as f64;
        eprintln!(
            "in time: coverage {share}, sd(z) {:.3}; the scores' own on the grid: sd(z) {:.3}",
            sd(&z),
            sd(&z_scores)
        );
        assert!(share >= 0.9, "coverage {share}");
        assert!((0.8..=1.25).contains(&sd(&z)), "sd(z) {}", sd(&z));
    }

    /// A lap shorter than four windows' worth of bins gives no estimate (the scores' own
    /// long-run covariance is then the interval's).
    #[test]
    fn a_short_lap_gives_no_estimate() {
        let times = vec![(0..30).map(|g| g as f64 * 0.05).collect::<Vec<_>>()];
        let block = Block {
            start: 0,
            residual: (0..30).map(|g| (g as f64).sin()).collect(),
            rows: (0..30).map(|g| vec![1.0, g as f64]).collect(),
            weight: 1.0,
            factor: Some(1.0),
            segment: 0,
        };
        let clocks = Clocks {
            times: &times,
            bin_s: 0.05,
        };
        assert!(meat(&[block], &[1.0, 1.0], |_| 1.0, &clocks).is_none());
    }
}

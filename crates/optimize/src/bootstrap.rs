//! A moving-block bootstrap of the joint answer (`--bootstrap N`): N refits from the answer
//! to laps whose residuals are resampled in blocks, a check of the sandwich's standard
//! errors that rests on no linearisation of the noise's covariance.
//!
//! **How.** At the answer θ̂ the twin's signals y(θ̂) and the residuals e = y(θ̂) − ŷ are
//! known (no lap). A replicate draws, per lap, blocks of `block` grid points at random
//! starts and strings them together over the lap: e* (the same draw for every signal of a
//! lap, so the wheels' and axles' shared noise stays shared). Its measurement is
//! ŷ* = y(θ̂) − e*, and the refinement starts at θ̂ with the sensitivities there (its first
//! residual is e*, no lap), Levenberg–Marquardt as the answer's own ([`crate::fit`], at
//! most 4 iterations: each a trial batch and 2 laps per parameter). The spread of the N
//! answers is the bootstrap standard error; their 2.5 and 97.5 % quantiles its percentile
//! interval.
//!
//! **The block**: four times the lag at which the residuals' pooled autocorrelation falls
//! below 0.05 (the rule of the sandwich's bandwidth, [`crate::interval`]), at least 10 and
//! at most a quarter of the lap: a block must hold the residual's persistence, or the
//! bootstrap sees white noise and is too narrow.
//!
//! **What it is for**: a second opinion on the sandwich where the noise is what limits the
//! answer. Where the model check fires, neither is the answer's whole uncertainty (the
//! interval with the model's share is).

use crate::fit::{Frame, Laps, Limits, Solution};
use crate::long_run::{bandwidth_of_one, CUT, LAGS, MAX_SHARE, MIN_BANDWIDTH};
use serde::{Deserialize, Serialize};

/// A replicate's refit: at most 4 iterations, converged within 0.3 standard errors.
const REFIT: Limits = Limits {
    max_iterations: 4,
    close: 0.3,
};

/// The bootstrap's outcome, per parameter in the study's order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Bootstrap {
    /// Refits asked for, and those that ended with an answer.
    pub replicates: usize,
    pub completed: usize,
    /// The block length [grid points] and laps run.
    pub block: usize,
    pub laps: usize,
    pub parameters: Vec<BootstrapParameter>,
}

/// One parameter's bootstrap figures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BootstrapParameter {
    pub name: String,
    /// The spread of the refits' answers (`None` with fewer than 2).
    pub std_error: Option<f64>,
    /// The bootstrap standard error over the sandwich's (`None` where either is missing).
    pub ratio: Option<f64>,
    /// The 2.5 and 97.5 % quantiles of the refits' answers.
    pub interval: Option<[f64; 2]>,
}

/// Runs `replicates` refits from the answer `solution` on `frame` (its measurements
/// shifted per replicate, put back afterwards); `std_errors` the sandwich's, by parameter.
pub(crate) fn run<F: Laps>(
    frame: &mut Frame<'_, F>,
    solution: &Solution,
    names: &[String],
    std_errors: &[Option<f64>],
    replicates: usize,
    seed: u64,
) -> Bootstrap {
    let p = solution.x.len();
    let raw = &solution.raw;
    let laps_before = frame.laps();
    // The block from the residuals' persistence (every series a segment of its own).
    let n = raw.iter().map(Vec::len).min().unwrap_or(0);
    let block = bandwidth_of_one(raw, n, LAGS, CUT, MIN_BANDWIDTH, MAX_SHARE).max(1);
    let mut rng = crate::rng::Rng::new(seed);
    let free = vec![true; p];
    let mut answers: Vec<Vec<f64>> = Vec::with_capacity(replicates);
    for _ in 0..replicates {
        let resampled = frame.resample(raw, block, &mut rng);
        let shift: Vec<Vec<f64>> = raw
            .iter()
            .zip(&resampled)
            .map(|(e, r)| e.iter().zip(r).map(|(e, r)| e - r).collect())
            .collect();
        frame.set_shift(Some(shift));
        let refit = frame.minimise(
            &solution.x,
            resampled,
            solution.sensitivities.clone(),
            &free,
            REFIT,
        );
        // A refit that ran out of iterations is kept (it is near its point); one whose lap
        // failed is not.
        let failed = refit
            .statement
            .as_deref()
            .is_some_and(|s| s.starts_with("stopped"));
        if refit.x.iter().all(|v| v.is_finite()) && !failed {
            answers.push(refit.x);
        }
    }
    frame.set_shift(None);
    let parameters = (0..p)
        .map(|i| {
            let mut v: Vec<f64> = answers.iter().map(|a| a[i]).collect();
            let std_error = (v.len() >= 2).then(|| {
                let m = v.iter().sum::<f64>() / v.len() as f64;
                (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
            });
            v.sort_by(f64::total_cmp);
            let q = |f: f64| v[((f * (v.len() - 1) as f64).round() as usize).min(v.len() - 1)];
            BootstrapParameter {
                name: names[i].clone(),
                ratio: std_error
                    .zip(std_errors.get(i).copied().flatten())
                    .filter(|(_, s)| *s > 0.0)
                    .map(|(b, s)| b / s),
                std_error,
                interval: (v.len() >= 2).then(|| [q(0.025), q(0.975)]),
            }
        })
        .collect();
    Bootstrap {
        replicates,
        completed: answers.len(),
        block,
        laps: frame.laps() - laps_before,
        parameters,
    }
}

impl Bootstrap {
    /// One line for Tab. 1 and the run's summary.
    pub fn summary(&self, short: impl Fn(&str) -> String) -> String {
        let ratios: Vec<String> = self
            .parameters
            .iter()
            .map(|p| match p.ratio {
                Some(r) => format!("{} {:.2}×", short(&p.name), r),
                None => format!("{} –", short(&p.name)),
            })
            .collect();
        format!(
            "Bootstrap ({} of {} refits from the answer, moving blocks of {} grid points, {} laps): the standard error against the sandwich's: {}",
            self.completed,
            self.replicates,
            self.block,
            self.laps,
            ratios.join(", ")
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{on_pool, Frame, Series, ANSWER};

    /// y = 2·exp(−0.7·t) + AR(1) noise (ρ = 0.9 per point) on 1500 points.
    fn lap(t: &[f64], seed: u64) -> Vec<f64> {
        let mut rng = crate::rng::Rng::new(seed);
        let mut e = 0.0;
        t.iter()
            .map(|t| {
                e = 0.9 * e + (1.0f64 - 0.81).sqrt() * rng.normal();
                2.0 * (-0.7 * t).exp() + 0.02 * e
            })
            .collect()
    }

    /// On a curve with correlated noise the bootstrap's standard errors are within 30 % of
    /// the estimates' true spread (200 laps of the same noise, fitted), its percentile
    /// interval holds the answer, and the measurement is the file's again afterwards.
    #[test]
    fn the_bootstrap_standard_error_matches_the_spread_of_refitted_laps() {
        let n = 1500;
        let t: Vec<f64> = (0..n).map(|g| g as f64 / 300.0).collect();
        let pool = crate::test_curve::pool(2);
        let simulate = |x: &[f64]| crate::test_curve::simulate_decay(&t, x);
        let (x0, bounds) = ([1.5, 0.5], vec![(0.1, 10.0), (0.01, 5.0)]);
        fn series(measured: &[f64]) -> Vec<Series<'_>> {
            vec![Series {
                name: "y".into(),
                weight: 1.0,
                measured,
                segment: 0,
            }]
        }
        // The truth: the spread of the answers over 200 laps.
        let answers: Vec<Vec<f64>> = (0..200)
            .map(|k| {
                let measured = lap(&t, 1000 + k);
                let (frame, raw, sens) = Frame::new(
                    series(&measured),
                    bounds.clone(),
                    &x0,
                    on_pool(&pool, simulate),
                )
                .unwrap();
                frame.minimise(&x0, raw, sens, &[true, true], ANSWER).x
            })
            .collect();
        let spread = |k: usize| {
            let m = answers.iter().map(|x| x[k]).sum::<f64>() / answers.len() as f64;
            (answers.iter().map(|x| (x[k] - m).powi(2)).sum::<f64>() / (answers.len() - 1) as f64)
                .sqrt()
        };
        let measured = lap(&t, 7);
        let (mut frame, raw, sens) = Frame::new(
            series(&measured),
            bounds.clone(),
            &x0,
            on_pool(&pool, simulate),
        )
        .unwrap();
        let sol = frame.minimise(&x0, raw, sens, &[true, true], ANSWER);
        let s_before = frame.objective(&sol.raw);
        let names = vec!["a".to_string(), "b".to_string()];
        let (_, var) = frame.covariances(&sol);
        let se: Vec<Option<f64>> = var.iter().map(|v| Some(v.sqrt())).collect();
        let b = run(&mut frame, &sol, &names, &se, 200, 11);
        assert_eq!(b.completed, 200, "{b:?}");
        for (k, p) in b.parameters.iter().enumerate() {
            let boot = p.std_error.expect("a bootstrap standard error");
            let ratio = boot / spread(k);
            eprintln!(
                "{}: bootstrap {boot:.5}, spread of 200 laps {:.5}, this lap's sandwich {:.5}",
                p.name,
                spread(k),
                se[k].unwrap()
            );
            assert!((0.7..=1.3).contains(&ratio), "{}: ratio {ratio}", p.name);
            let [lo, hi] = p.interval.expect("an interval");
            assert!(lo < sol.x[k] && sol.x[k] < hi, "{}: {lo}..{hi}", p.name);
        }
        // The measurement is the file's again: a lap at the answer has its residuals.
        let (again, _) = frame.start(&sol.x, &[false, false]).unwrap();
        assert_eq!(frame.objective(&again).to_bits(), s_before.to_bits());
    }
}

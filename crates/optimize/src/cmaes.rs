//! CMA-ES, (μ/μ_w, λ) with cumulative step-size adaptation and rank-one + rank-μ covariance
//! updates (the standard parameter setting of Hansen's tutorial), in the unit box.
//!
//! Bounds: a sample outside the box is evaluated at its projection onto the box, and the
//! projected point (not the raw sample) enters the update, so the mean stays inside.
//! The covariance is decomposed every generation (cyclic Jacobi; n is small here).

use super::exact;
use super::optimizer::{all_finite, state_methods, Optimizer, SavedState};
use super::rng::Rng;
use crate::error::OptimizeError;
use serde::{Deserialize, Serialize};

/// Settings (the study file's `[optimizer]` table for `kind = "cmaes"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CmaesSettings {
    /// λ, samples per generation; default 4 + ⌊3 ln n⌋.
    pub population: Option<usize>,
    /// Initial step size in the unit box.
    pub sigma0: f64,
}

impl Default for CmaesSettings {
    fn default() -> Self {
        CmaesSettings {
            population: None,
            sigma0: 0.25,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct CmaState {
    rng: Rng,
    generation: usize,
    #[serde(with = "exact::vec")]
    mean: Vec<f64>,
    #[serde(with = "exact::f64")]
    sigma: f64,
    /// Covariance, its eigenvectors (columns) and the square roots of its eigenvalues.
    #[serde(with = "exact::vecvec")]
    c: Vec<Vec<f64>>,
    #[serde(with = "exact::vecvec")]
    b: Vec<Vec<f64>>,
    #[serde(with = "exact::vec")]
    d: Vec<f64>,
    #[serde(with = "exact::vec")]
    pc: Vec<f64>,
    #[serde(with = "exact::vec")]
    ps: Vec<f64>,
    #[serde(with = "exact::vecvec")]
    pending: Vec<Vec<f64>>,
    #[serde(with = "exact::vec")]
    best_x: Vec<f64>,
    #[serde(with = "exact::f64")]
    best_cost: f64,
}

pub struct Cmaes {
    n: usize,
    lambda: usize,
    mu: usize,
    weights: Vec<f64>,
    mueff: f64,
    cc: f64,
    cs: f64,
    c1: f64,
    cmu: f64,
    damps: f64,
    chi_n: f64,
    s: CmaState,
}

impl Cmaes {
    /// `start`: the initial mean in the unit box (default: the centre).
    pub fn new(
        dim: usize,
        settings: CmaesSettings,
        seed: u64,
        start: Option<Vec<f64>>,
    ) -> Result<Self, OptimizeError> {
        if dim == 0 {
            return Err(OptimizeError::Invalid("CMA-ES: no parameters".into()));
        }
        if !(settings.sigma0 > 0.0 && settings.sigma0.is_finite()) {
            return Err(OptimizeError::Invalid(format!(
                "CMA-ES: sigma0 = {} must be positive",
                settings.sigma0
            )));
        }
        if let Some(p) = settings.population.filter(|&p| p < 4) {
            return Err(OptimizeError::Invalid(format!(
                "CMA-ES: population {p}: at least 4 candidates per generation"
            )));
        }
        let n = dim;
        let nf = n as f64;
        let lambda = settings
            .population
            .unwrap_or(4 + (3.0 * nf.ln()).floor() as usize)
            .max(4);
        let mu = lambda / 2;
        let raw: Vec<f64> = (0..mu)
            .map(|i| (mu as f64 + 0.5).ln() - ((i + 1) as f64).ln())
            .collect();
        let sum: f64 = raw.iter().sum();
        let weights: Vec<f64> = raw.iter().map(|w| w / sum).collect();
        let mueff = 1.0 / weights.iter().map(|w| w * w).sum::<f64>();
        let cc = (4.0 + mueff / nf) / (nf + 4.0 + 2.0 * mueff / nf);
        let cs = (mueff + 2.0) / (nf + mueff + 5.0);
        let c1 = 2.0 / ((nf + 1.3).powi(2) + mueff);
        let cmu = (1.0 - c1).min(2.0 * (mueff - 2.0 + 1.0 / mueff) / ((nf + 2.0).powi(2) + mueff));
        let damps = 1.0 + 2.0 * (((mueff - 1.0) / (nf + 1.0)).sqrt() - 1.0).max(0.0) + cs;
        let chi_n = nf.sqrt() * (1.0 - 1.0 / (4.0 * nf) + 1.0 / (21.0 * nf * nf));
        let mean = start
            .map(|s| s.iter().map(|v| v.clamp(0.0, 1.0)).collect())
            .unwrap_or(vec![0.5; n]);
        let eye: Vec<Vec<f64>> = (0..n)
            .map(|i| (0..n).map(|j| f64::from(u8::from(i == j))).collect())
            .collect();
        Ok(Cmaes {
            n,
            lambda,
            mu,
            weights,
            mueff,
            cc,
            cs,
            c1,
            cmu,
            damps,
            chi_n,
            s: CmaState {
                rng: Rng::new(seed),
                generation: 0,
                mean,
                sigma: settings.sigma0,
                c: eye.clone(),
                b: eye,
                d: vec![1.0; n],
                pc: vec![0.0; n],
                ps: vec![0.0; n],
                pending: Vec::new(),
                best_x: Vec::new(),
                best_cost: f64::INFINITY,
            },
        })
    }

    pub fn lambda(&self) -> usize {
        self.lambda
    }

    /// C^{-1/2}·v = B·D^{-1}·Bᵀ·v.
    fn inv_sqrt_c(&self, v: &[f64]) -> Vec<f64> {
        let n = self.n;
        let b = &self.s.b;
        let t: Vec<f64> = (0..n)
            .map(|k| (0..n).map(|i| b[i][k] * v[i]).sum::<f64>() / self.s.d[k])
            .collect();
        (0..n)
            .map(|i| (0..n).map(|k| b[i][k] * t[k]).sum())
            .collect()
    }
}

/// Eigen-decomposition of a symmetric matrix by cyclic Jacobi rotations: returns the
/// eigenvalues and the eigenvectors as the columns of a matrix.
#[allow(clippy::needless_range_loop)] // index arithmetic on rows and columns
pub fn symmetric_eigen(a: &[Vec<f64>]) -> (Vec<f64>, Vec<Vec<f64>>) {
    let n = a.len();
    let mut a: Vec<Vec<f64>> = a.to_vec();
    let mut v: Vec<Vec<f64>> = (0..n)
        .map(|i| (0..n).map(|j| f64::from(u8::from(i == j))).collect())
        .collect();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[i][j] * a[i][j])
            .sum();
        let diag: f64 = (0..n).map(|i| a[i][i] * a[i][i]).sum();
        if off <= 1e-30 * diag.max(f64::MIN_POSITIVE) {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                if a[p][q].abs() < 1e-300 {
                    continue;
                }
                let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k][p], a[k][q]);
                    a[k][p] = c * akp - s * akq;
                    a[k][q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p][k], a[q][k]);
                    a[p][k] = c * apk - s * aqk;
                    a[q][k] = s * apk + c * aqk;
                }
                for row in v.iter_mut() {
                    let (vkp, vkq) = (row[p], row[q]);
                    row[p] = c * vkp - s * vkq;
                    row[q] = s * vkp + c * vkq;
                }
            }
        }
    }
    ((0..n).map(|i| a[i][i]).collect(), v)
}

impl Optimizer for Cmaes {
    fn name(&self) -> &'static str {
        "cmaes"
    }

    fn dim(&self) -> usize {
        self.n
    }

    fn ask(&mut self) -> Vec<Vec<f64>> {
        let n = self.n;
        let mut out = Vec::with_capacity(self.lambda);
        for _ in 0..self.lambda {
            let z: Vec<f64> = (0..n).map(|_| self.s.rng.normal()).collect();
            let x: Vec<f64> = (0..n)
                .map(|i| {
                    let y: f64 = (0..n).map(|k| self.s.b[i][k] * self.s.d[k] * z[k]).sum();
                    (self.s.mean[i] + self.s.sigma * y).clamp(0.0, 1.0)
                })
                .collect();
            out.push(x);
        }
        self.s.pending = out.clone();
        out
    }

    #[allow(clippy::needless_range_loop)] // vector algebra written out by index
    fn tell(&mut self, costs: &[f64]) {
        assert_eq!(
            costs.len(),
            self.s.pending.len(),
            "tell: one cost per asked candidate"
        );
        let n = self.n;
        let xs = std::mem::take(&mut self.s.pending);
        let mut order: Vec<usize> = (0..xs.len()).collect();
        order.sort_by(|&a, &b| costs[a].total_cmp(&costs[b]));
        if costs[order[0]] < self.s.best_cost {
            self.s.best_cost = costs[order[0]];
            self.s.best_x = xs[order[0]].clone();
        }
        let old = self.s.mean.clone();
        let sigma = self.s.sigma;
        let ys: Vec<Vec<f64>> = order[..self.mu]
            .iter()
            .map(|&k| (0..n).map(|i| (xs[k][i] - old[i]) / sigma).collect())
            .collect();
        let yw: Vec<f64> = (0..n)
            .map(|i| (0..self.mu).map(|j| self.weights[j] * ys[j][i]).sum())
            .collect();
        for i in 0..n {
            self.s.mean[i] = old[i] + sigma * yw[i];
        }
        // Step-size path and step size.
        let cy = self.inv_sqrt_c(&yw);
        let a = (self.cs * (2.0 - self.cs) * self.mueff).sqrt();
        for i in 0..n {
            self.s.ps[i] = (1.0 - self.cs) * self.s.ps[i] + a * cy[i];
        }
        let ps_norm = self.s.ps.iter().map(|v| v * v).sum::<f64>().sqrt();
        let g = (self.s.generation + 1) as f64;
        let hsig = ps_norm / (1.0 - (1.0 - self.cs).powf(2.0 * g)).sqrt() / self.chi_n
            < 1.4 + 2.0 / (n as f64 + 1.0);
        let hs = f64::from(u8::from(hsig));
        let ac = (self.cc * (2.0 - self.cc) * self.mueff).sqrt();
        for i in 0..n {
            self.s.pc[i] = (1.0 - self.cc) * self.s.pc[i] + hs * ac * yw[i];
        }
        // Covariance: rank-one and rank-μ.
        let keep = 1.0 - self.c1 - self.cmu + (1.0 - hs) * self.c1 * self.cc * (2.0 - self.cc);
        for i in 0..n {
            for j in 0..n {
                let rank_mu: f64 = (0..self.mu)
                    .map(|k| self.weights[k] * ys[k][i] * ys[k][j])
                    .sum();
                self.s.c[i][j] = keep * self.s.c[i][j]
                    + self.c1 * self.s.pc[i] * self.s.pc[j]
                    + self.cmu * rank_mu;
            }
        }
        for i in 0..n {
            for j in 0..i {
                let m = 0.5 * (self.s.c[i][j] + self.s.c[j][i]);
                self.s.c[i][j] = m;
                self.s.c[j][i] = m;
            }
        }
        self.s.sigma *= ((self.cs / self.damps) * (ps_norm / self.chi_n - 1.0)).exp();
        self.s.sigma = self.s.sigma.min(1.0);
        let (eig, vecs) = symmetric_eigen(&self.s.c);
        self.s.d = eig.iter().map(|e| e.max(1e-300).sqrt()).collect();
        self.s.b = vecs;
        self.s.generation += 1;
    }

    fn best(&self) -> Option<(&[f64], f64)> {
        (!self.s.best_x.is_empty()).then_some((self.s.best_x.as_slice(), self.s.best_cost))
    }

    state_methods!(n);
}

impl SavedState for CmaState {
    const LABEL: &'static str = "CMA-ES";

    fn has_dim(&self, dim: usize) -> bool {
        self.mean.len() == dim
    }

    fn damage(&self, dim: usize) -> Option<String> {
        let square =
            |m: &[Vec<f64>]| m.len() == dim && m.iter().all(|r| r.len() == dim && all_finite(r));
        if !(self.sigma.is_finite() && self.sigma > 0.0) {
            return Some(format!(
                "CMA-ES state: sigma = {} is not a positive number",
                self.sigma
            ));
        }
        if !(all_finite(&self.mean)
            && square(&self.c)
            && square(&self.b)
            && self.d.len() == dim
            && all_finite(&self.d)
            && all_finite(&self.pc)
            && all_finite(&self.ps)
            && self.pending.iter().all(|x| all_finite(x)))
        {
            return Some(
                "CMA-ES state holds a non-finite or misshapen mean, covariance or path".into(),
            );
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_damaged_checkpoint_state_is_refused() {
        let (good, mut fresh) = crate::optimizer::saved_after_one_generation(|| {
            Cmaes::new(2, CmaesSettings::default(), 7, None).unwrap()
        });
        // Floats are kept as their bits: a NaN is what a damaged file can hold.
        let bits = |x: f64| serde_json::json!(crate::exact::encode(x));
        for (edit, expected) in [
            (
                bits(f64::NAN),
                "checkpoint: CMA-ES state: sigma = NaN is not a positive number (a damaged checkpoint: start without --resume)",
            ),
            (bits(0.0), "sigma = 0 is not a positive number"),
            (bits(-1.0), "sigma = -1 is not a positive number"),
            (serde_json::json!("zz"), "is not a 16-digit hex float"),
        ] {
            let mut bad = good.clone();
            bad["sigma"] = edit;
            let e = fresh.restore(&bad).unwrap_err();
            assert!(matches!(e, OptimizeError::Checkpoint(_)), "{e}");
            assert!(e.to_string().contains(expected), "{e}");
        }
        let mut bad = good.clone();
        bad["mean"][0] = bits(f64::INFINITY);
        let e = fresh.restore(&bad).unwrap_err().to_string();
        assert_eq!(
            e,
            "checkpoint: CMA-ES state holds a non-finite or misshapen mean, covariance or path (a damaged checkpoint: start without --resume)"
        );
        let mut bad = good;
        bad["c"][0] = serde_json::json!([crate::exact::encode(1.0)]);
        let e = fresh.restore(&bad).unwrap_err();
        assert!(matches!(e, OptimizeError::Checkpoint(_)), "{e}");
    }

    #[test]
    fn jacobi_eigen_reconstructs() {
        let a = vec![
            vec![4.0, 1.0, 0.5],
            vec![1.0, 3.0, 0.2],
            vec![0.5, 0.2, 1.0],
        ];
        let (l, v) = symmetric_eigen(&a);
        for i in 0..3 {
            for j in 0..3 {
                let r: f64 = (0..3).map(|k| v[i][k] * l[k] * v[j][k]).sum();
                assert!((r - a[i][j]).abs() < 1e-12, "{i} {j}: {r}");
            }
        }
    }
}

//! A real-coded genetic algorithm in the unit box: binary tournament selection, simulated
//! binary crossover (SBX, bounded form), polynomial mutation (bounded form), elitism.
//!
//! Generation 0 is the start point (when given) plus uniform random points; each later
//! generation keeps the `elites` best individuals unevaluated and breeds the rest, so a
//! generation costs `population − elites` evaluations.

use super::exact;
use super::optimizer::{all_finite, state_methods, Optimizer, SavedState};
use super::rng::Rng;
use crate::error::OptimizeError;
use serde::{Deserialize, Serialize};

/// Settings (the study file's `[optimizer]` table for `kind = "ga"`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GaSettings {
    pub population: usize,
    pub elites: usize,
    pub tournament: usize,
    pub crossover_probability: f64,
    /// SBX distribution index (larger: children closer to the parents).
    pub eta_crossover: f64,
    /// Per-variable mutation probability; default 1/n.
    pub mutation_probability: Option<f64>,
    /// Polynomial mutation distribution index.
    pub eta_mutation: f64,
}

impl Default for GaSettings {
    fn default() -> Self {
        GaSettings {
            population: 20,
            elites: 2,
            tournament: 2,
            crossover_probability: 0.9,
            eta_crossover: 15.0,
            mutation_probability: None,
            eta_mutation: 20.0,
        }
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Individual {
    #[serde(with = "exact::vec")]
    x: Vec<f64>,
    #[serde(with = "exact::f64")]
    cost: f64,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct GaState {
    rng: Rng,
    generation: usize,
    population: Vec<Individual>,
    #[serde(with = "exact::vecvec")]
    pending: Vec<Vec<f64>>,
    best: Option<Individual>,
}

pub struct Ga {
    settings: GaSettings,
    dim: usize,
    start: Option<Vec<f64>>,
    s: GaState,
}

impl Ga {
    /// `start`: a point of the unit box put into the first generation.
    pub fn new(
        dim: usize,
        settings: GaSettings,
        seed: u64,
        start: Option<Vec<f64>>,
    ) -> Result<Self, OptimizeError> {
        if dim == 0 {
            return Err(OptimizeError::Invalid("GA: no parameters".into()));
        }
        if settings.population < 4 || settings.elites >= settings.population {
            return Err(OptimizeError::Invalid(format!(
                "GA: population {} must be at least 4 and larger than elites {}",
                settings.population, settings.elites
            )));
        }
        if settings.tournament == 0 {
            return Err(OptimizeError::Invalid(
                "GA: tournament must be at least 1".into(),
            ));
        }
        Ok(Ga {
            settings,
            dim,
            start,
            s: GaState {
                rng: Rng::new(seed),
                generation: 0,
                population: Vec::new(),
                pending: Vec::new(),
                best: None,
            },
        })
    }

    /// Index into the population of the tournament's winner (ties: the first drawn).
    fn tournament(&mut self) -> usize {
        let n = self.s.population.len();
        let mut best = self.s.rng.below(n);
        for _ in 1..self.settings.tournament {
            let k = self.s.rng.below(n);
            if self.s.population[k].cost < self.s.population[best].cost {
                best = k;
            }
        }
        best
    }

    /// SBX on [0, 1] (Deb & Agrawal's bounded form), variable by variable.
    fn crossover(&mut self, a: &[f64], b: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (mut c1, mut c2) = (a.to_vec(), b.to_vec());
        if self.s.rng.uniform() > self.settings.crossover_probability {
            return (c1, c2);
        }
        let eta = self.settings.eta_crossover;
        for i in 0..self.dim {
            if self.s.rng.uniform() > 0.5 || (a[i] - b[i]).abs() < 1e-14 {
                continue;
            }
            let (y1, y2) = if a[i] < b[i] {
                (a[i], b[i])
            } else {
                (b[i], a[i])
            };
            let span = y2 - y1;
            let u = self.s.rng.uniform();
            let spread = |beta: f64| {
                let alpha = 2.0 - beta.powf(-(eta + 1.0));
                if u <= 1.0 / alpha {
                    (u * alpha).powf(1.0 / (eta + 1.0))
                } else {
                    (1.0 / (2.0 - u * alpha)).powf(1.0 / (eta + 1.0))
                }
            };
            let bq1 = spread(1.0 + 2.0 * y1 / span);
            let bq2 = spread(1.0 + 2.0 * (1.0 - y2) / span);
            let mut v1 = (0.5 * (y1 + y2 - bq1 * span)).clamp(0.0, 1.0);
            let mut v2 = (0.5 * (y1 + y2 + bq2 * span)).clamp(0.0, 1.0);
            if self.s.rng.uniform() < 0.5 {
                std::mem::swap(&mut v1, &mut v2);
            }
            c1[i] = v1;
            c2[i] = v2;
        }
        (c1, c2)
    }

    /// Polynomial mutation on [0, 1] (bounded form).
    fn mutate(&mut self, x: &mut [f64]) {
        let pm = self
            .settings
            .mutation_probability
            .unwrap_or(1.0 / self.dim as f64);
        let eta = self.settings.eta_mutation;
        let p = 1.0 / (eta + 1.0);
        for xi in x.iter_mut() {
            if self.s.rng.uniform() >= pm {
                continue;
            }
            let y = *xi;
            let u = self.s.rng.uniform();
            let dq = if u < 0.5 {
                let v = 2.0 * u + (1.0 - 2.0 * u) * (1.0 - y).powf(eta + 1.0);
                v.powf(p) - 1.0
            } else {
                let v = 2.0 * (1.0 - u) + 2.0 * (u - 0.5) * y.powf(eta + 1.0);
                1.0 - v.powf(p)
            };
            *xi = (y + dq).clamp(0.0, 1.0);
        }
    }

    fn sorted_population(&self) -> Vec<Individual> {
        let mut p = self.s.population.clone();
        // Stable: ties keep their order, so the result does not depend on anything else.
        p.sort_by(|a, b| a.cost.total_cmp(&b.cost));
        p
    }
}

impl Optimizer for Ga {
    fn name(&self) -> &'static str {
        "ga"
    }

    fn dim(&self) -> usize {
        self.dim
    }

    fn ask(&mut self) -> Vec<Vec<f64>> {
        let n = self.settings.population;
        let mut pending = Vec::with_capacity(n);
        if self.s.population.is_empty() {
            if let Some(s) = &self.start {
                pending.push(s.iter().map(|v| v.clamp(0.0, 1.0)).collect());
            }
            while pending.len() < n {
                pending.push((0..self.dim).map(|_| self.s.rng.uniform()).collect());
            }
        } else {
            let want = n - self.settings.elites;
            while pending.len() < want {
                let ia = self.tournament();
                let ib = self.tournament();
                let a = self.s.population[ia].x.clone();
                let b = self.s.population[ib].x.clone();
                let (mut c1, mut c2) = self.crossover(&a, &b);
                self.mutate(&mut c1);
                self.mutate(&mut c2);
                pending.push(c1);
                if pending.len() < want {
                    pending.push(c2);
                }
            }
        }
        self.s.pending = pending.clone();
        pending
    }

    fn tell(&mut self, costs: &[f64]) {
        assert_eq!(
            costs.len(),
            self.s.pending.len(),
            "tell: one cost per asked candidate"
        );
        let evaluated: Vec<Individual> = std::mem::take(&mut self.s.pending)
            .into_iter()
            .zip(costs)
            .map(|(x, &cost)| Individual { x, cost })
            .collect();
        let mut next = if self.s.population.is_empty() {
            Vec::new()
        } else {
            let mut elites = self.sorted_population();
            elites.truncate(self.settings.elites);
            elites
        };
        next.extend(evaluated);
        for ind in &next {
            if self.s.best.as_ref().is_none_or(|b| ind.cost < b.cost) {
                self.s.best = Some(ind.clone());
            }
        }
        self.s.population = next;
        self.s.generation += 1;
    }

    fn best(&self) -> Option<(&[f64], f64)> {
        self.s.best.as_ref().map(|b| (b.x.as_slice(), b.cost))
    }

    state_methods!(dim);
}

impl SavedState for GaState {
    const LABEL: &'static str = "GA";

    fn has_dim(&self, dim: usize) -> bool {
        self.population.iter().all(|i| i.x.len() == dim)
    }

    fn damage(&self, _dim: usize) -> Option<String> {
        let usable = self
            .population
            .iter()
            .all(|i| all_finite(&i.x) && !i.cost.is_nan())
            && self.pending.iter().all(|x| all_finite(x));
        (!usable).then(|| "GA state holds a non-finite candidate or cost".into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_damaged_checkpoint_state_is_refused() {
        let (good, mut fresh) = crate::optimizer::saved_after_one_generation(|| {
            Ga::new(2, GaSettings::default(), 7, None).unwrap()
        });
        let mut bad = good.clone();
        bad["population"][0]["x"][0] = serde_json::json!(crate::exact::encode(f64::NAN));
        let e = fresh.restore(&bad).unwrap_err().to_string();
        assert_eq!(
            e,
            "checkpoint: GA state holds a non-finite candidate or cost (a damaged checkpoint: start without --resume)"
        );
        let mut bad = good;
        bad["population"][0]["x"] = serde_json::json!([crate::exact::encode(0.5)]);
        let e = fresh.restore(&bad).unwrap_err().to_string();
        assert_eq!(
            e,
            "checkpoint: GA state has a different number of parameters"
        );
    }
}

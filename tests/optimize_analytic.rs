//! The optimisers on analytic functions, through the same parallel generation loop as the
//! studies: convergence to stated tolerances, the same result with 1 and 2 threads,
//! checkpoint/restore equal to an uninterrupted run, failures penalised.

use std::ops::ControlFlow;
use tb_optimize::optimizer::to_unit;
use tb_optimize::{
    minimize, Cmaes, CmaesSettings, Ga, GaSettings, Optimizer, Problem, RunError, RunSettings,
    RunState,
};

struct Sphere {
    centre: Vec<f64>,
}
impl Problem for Sphere {
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(-5.0, 5.0); self.centre.len()]
    }
    fn evaluate(&self, x: &[f64]) -> Result<f64, RunError> {
        Ok(x.iter()
            .zip(&self.centre)
            .map(|(a, b)| (a - b).powi(2))
            .sum())
    }
}

struct Rosenbrock;
impl Problem for Rosenbrock {
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(-2.0, 2.0); 2]
    }
    fn evaluate(&self, x: &[f64]) -> Result<f64, RunError> {
        Ok(100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2))
    }
}

/// Fails (an Err) on part of the box; the cost is a sphere around (0.5, 0.5) elsewhere.
struct Holes;
impl Problem for Holes {
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(0.0, 1.0); 2]
    }
    fn evaluate(&self, x: &[f64]) -> Result<f64, RunError> {
        if x[0] > 0.65 {
            return Err(RunError::Problem(
                format!("instance 'model' at t = 1.5 s: x0 = {} too large", x[0]).into(),
            ));
        }
        Ok((x[0] - 0.5).powi(2) + (x[1] - 0.5).powi(2))
    }
}

fn settings(generations: usize, threads: usize) -> RunSettings {
    RunSettings {
        max_generations: generations,
        threads,
        penalty: 1e3,
    }
}

fn run(
    opt: &mut dyn Optimizer,
    p: &dyn ProblemDyn,
    generations: usize,
    threads: usize,
) -> (Vec<f64>, f64, RunState) {
    let mut state = RunState::default();
    let (x, c) = p.minimize(opt, &settings(generations, threads), &mut state);
    (x, c, state)
}

/// Object-safe helper so that one `run` serves every problem.
trait ProblemDyn {
    fn minimize(
        &self,
        opt: &mut dyn Optimizer,
        s: &RunSettings,
        st: &mut RunState,
    ) -> (Vec<f64>, f64);
}
impl<P: Problem> ProblemDyn for P {
    fn minimize(
        &self,
        opt: &mut dyn Optimizer,
        s: &RunSettings,
        st: &mut RunState,
    ) -> (Vec<f64>, f64) {
        minimize(opt, self, s, st, |_, _| ControlFlow::Continue(())).unwrap()
    }
}

fn ga(dim: usize, population: usize, seed: u64) -> Ga {
    Ga::new(
        dim,
        GaSettings {
            population,
            ..GaSettings::default()
        },
        seed,
        None,
    )
    .unwrap()
}

fn cmaes(dim: usize, seed: u64) -> Cmaes {
    Cmaes::new(dim, CmaesSettings::default(), seed, None).unwrap()
}

#[test]
fn ga_sphere_and_rosenbrock() {
    // Sphere in 3-D on [-5, 5]³, optimum (1, −2, 0.5): 40 generations of 30.
    let p = Sphere {
        centre: vec![1.0, -2.0, 0.5],
    };
    let (x, c, _) = run(&mut ga(3, 30, 7), &p, 40, 2);
    assert!(c < 1e-3, "GA sphere: cost {c} at {x:?}");
    for (a, b) in x.iter().zip(&p.centre) {
        assert!((a - b).abs() < 0.03, "GA sphere: {x:?}");
    }
    // Rosenbrock on [-2, 2]²: 150 generations of 40; within 0.1 of (1, 1), cost < 1e-2.
    let (x, c, _) = run(&mut ga(2, 40, 11), &Rosenbrock, 150, 2);
    assert!(c < 1e-2, "GA Rosenbrock: cost {c} at {x:?}");
    assert!(
        (x[0] - 1.0).abs() < 0.1 && (x[1] - 1.0).abs() < 0.2,
        "GA Rosenbrock: {x:?}"
    );
}

#[test]
fn cmaes_sphere_and_rosenbrock() {
    let p = Sphere {
        centre: vec![1.0, -2.0, 0.5, 3.0, -4.0],
    };
    let (x, c, st) = run(&mut cmaes(5, 3), &p, 150, 2);
    assert!(
        c < 1e-10,
        "CMA-ES sphere 5-D: cost {c} at {x:?} after {} evaluations",
        st.evaluations
    );
    let (x, c, _) = run(&mut cmaes(2, 5), &Rosenbrock, 250, 2);
    assert!(c < 1e-10, "CMA-ES Rosenbrock: cost {c} at {x:?}");
    assert!(
        (x[0] - 1.0).abs() < 1e-4 && (x[1] - 1.0).abs() < 1e-4,
        "{x:?}"
    );
}

#[test]
fn same_seed_same_result_with_1_and_2_threads() {
    for kind in ["ga", "cmaes"] {
        let make = || -> Box<dyn Optimizer> {
            match kind {
                "ga" => Box::new(ga(2, 12, 99)),
                _ => Box::new(cmaes(2, 99)),
            }
        };
        let (x1, c1, s1) = run(make().as_mut(), &Rosenbrock, 30, 1);
        let (x2, c2, s2) = run(make().as_mut(), &Rosenbrock, 30, 2);
        assert_eq!(c1.to_bits(), c2.to_bits(), "{kind}");
        assert_eq!(x1, x2, "{kind}");
        assert_eq!(s1, s2, "{kind}: the whole history");
        // Another seed gives another path.
        let other: Box<dyn Optimizer> = match kind {
            "ga" => Box::new(ga(2, 12, 100)),
            _ => Box::new(cmaes(2, 100)),
        };
        let mut other = other;
        let (_, c3, _) = run(other.as_mut(), &Rosenbrock, 30, 2);
        assert_ne!(c1.to_bits(), c3.to_bits(), "{kind}: the seed matters");
    }
}

#[test]
fn saved_state_continues_like_an_uninterrupted_run() {
    for kind in ["ga", "cmaes"] {
        let make = || -> Box<dyn Optimizer> {
            match kind {
                "ga" => Box::new(
                    Ga::new(
                        2,
                        GaSettings::default(),
                        5,
                        Some(to_unit(&[-1.0, 1.5], &Rosenbrock.bounds())),
                    )
                    .unwrap(),
                ),
                _ => Box::new(
                    Cmaes::new(2, CmaesSettings::default(), 5, Some(vec![0.2, 0.8])).unwrap(),
                ),
            }
        };
        let (x_full, c_full, st_full) = run(make().as_mut(), &Rosenbrock, 25, 2);
        // Stop after 9 generations, save through JSON text, restore into a fresh optimiser.
        let mut first = make();
        let mut state = RunState::default();
        minimize(
            first.as_mut(),
            &Rosenbrock,
            &settings(25, 2),
            &mut state,
            |o, _| {
                if o.generation() == 9 {
                    ControlFlow::Break(())
                } else {
                    ControlFlow::Continue(())
                }
            },
        )
        .unwrap();
        let text = serde_json::to_string(&first.save()).unwrap();
        let state_text = serde_json::to_string(&state).unwrap();
        drop(first);
        let mut second = make();
        second
            .restore(&serde_json::from_str(&text).unwrap())
            .unwrap();
        let mut state: RunState = serde_json::from_str(&state_text).unwrap();
        let (x, c) = minimize(
            second.as_mut(),
            &Rosenbrock,
            &settings(25, 1),
            &mut state,
            |_, _| ControlFlow::Continue(()),
        )
        .unwrap();
        assert_eq!(c.to_bits(), c_full.to_bits(), "{kind}");
        assert_eq!(x, x_full, "{kind}");
        assert_eq!(state.evaluations, st_full.evaluations);
        assert_eq!(state.history.len(), 25);
    }
}

#[test]
fn failed_candidates_are_penalised_and_the_run_goes_on() {
    for mut opt in [
        Box::new(ga(2, 16, 1)) as Box<dyn Optimizer>,
        Box::new(cmaes(2, 1)) as Box<dyn Optimizer>,
    ] {
        let (x, c, st) = run(opt.as_mut(), &Holes, 30, 2);
        assert!(st.failures > 0, "{}: some candidates fail", opt.name());
        assert!(
            st.failure_reasons[0].contains("instance 'model' at t = 1.5 s"),
            "{:?}",
            st.failure_reasons
        );
        assert!(c < 1e-3 && x[0] <= 0.65, "{}: {c} at {x:?}", opt.name());
    }
}

//! The study's joint answer: all its parameters refined together on all its signals
//! ([`crate::fit`]), the intervals there, and what is made at that point on request or
//! where it can be (the profiles, the bootstrap, the model check).

use super::bootstrap::Bootstrap;
use super::fit::{Frame, Laps, Refinement, Series, Solution};
use super::interval::Intervals;
use super::observe::Phases;
use super::optimizer::thread_pool;
use super::profile::Profiles;
use super::remote::Evaluator;
use super::results::StepResult;
use super::session::{Session, StudyState};
use super::study::Study;
use crate::error::OptimizeError;
use tb_compare::PreparedMeasurement;

/// Every parameter the steps fit (first appearance: its bounds and its value before its
/// step) and every signal they compare (its weight where it first appears).
pub(crate) struct JointProblem {
    pub(crate) names: Vec<String>,
    pub(crate) bounds: Vec<(f64, f64)>,
    pub(crate) before: Vec<f64>,
    pub(crate) signals: Vec<String>,
    pub(crate) weights: Vec<f64>,
}

impl JointProblem {
    pub(crate) fn of(study: &Study, steps: &[StepResult]) -> JointProblem {
        let (signals, weights) = study.joint_signals();
        let mut j = JointProblem {
            names: Vec::new(),
            bounds: Vec::new(),
            before: Vec::new(),
            signals,
            weights,
        };
        for (step, done) in study.file.steps.iter().zip(steps) {
            for (p, change) in step.parameters.iter().zip(&done.parameters) {
                if !j.names.contains(&p.name) {
                    j.names.push(p.name.clone());
                    j.bounds.push((p.min, p.max));
                    j.before.push(change.before);
                }
            }
        }
        j
    }
}

/// The study's joint answer: the refinement of all its parameters together on all its
/// signals ([`crate::fit`], unless the study says `refine = false`) and the 95 % intervals
/// there, from the sensitivities at that point (each step's own intervals are conditional
/// on the other steps' values). Puts the refined values in the state's assignment.
pub(crate) fn joint_answer(
    session: &Session,
    state: &mut StudyState,
    j: &JointProblem,
    prepared: &[PreparedMeasurement],
) -> Result<JointAnswer, OptimizeError> {
    let (study, bench) = (session.study, &session.bench);
    let workers = bench.workers();
    let all: Vec<f64> = state.assignment.iter().map(|p| p.1).collect();
    let index: Vec<usize> = j
        .names
        .iter()
        .map(|n| workers.index_of(n).expect("a study parameter has a slot"))
        .collect();
    let x: Vec<f64> = index.iter().map(|&i| all[i]).collect();
    let values = |y: &[f64]| {
        let mut values = all.clone();
        for (k, &i) in index.iter().enumerate() {
            values[i] = y[k];
        }
        values
    };
    if !study.file.refine {
        // One fitted lap (the study's check): the intervals at the steps' answer.
        let iv = intervals_at_steps_answer(session, state, j, prepared, &x, &values);
        return Ok((None, iv, None, None, None));
    }
    let series = joint_series(session, j, prepared);
    let simulate_points = joint_laps(session, j, prepared, &values);
    let phases = Phases::new(&session.options.observers, &j.names, prepared.len());
    let simulate = |points: &[Vec<f64>]| -> Vec<crate::fit::Simulated> {
        let runs = simulate_points(points);
        phases.ran(points.len(), false);
        runs
    };
    let (mut frame, raw, sens) = match Frame::new(series, j.bounds.clone(), &x, simulate) {
        Ok(f) => f,
        Err(why) => {
            let why = format!("no joint refinement and no interval: {why}");
            let iv = crate::interval::Intervals::none(&j.names, &x, why, 2 * x.len() + 1);
            return Ok((None, iv, None, None, None));
        }
    };
    if let Some(times) = lap_clocks(session) {
        let bin_s = crate::noise_time::BIN_OF_PERIOD / session.study.file.compare.cutoff_hz;
        frame.set_clocks(times, bin_s);
    }
    let objective_before = frame.per_point(frame.objective(&raw));
    let solution = frame.minimise(&x, raw, sens, &vec![true; x.len()], crate::fit::ANSWER);
    phases.ran(0, true);
    let laps = frame.laps();
    let blocks = frame.blocks(&solution);
    let iv = frame.sandwich(&j.names, &solution.x, &j.bounds, &blocks, laps);
    let iv = noise_floor(iv, &blocks, j, &solution.x);
    let checked = model_check(session, j, &blocks, &solution.x, &iv);
    let refinement = Refinement {
        method: crate::fit::METHOD.into(),
        parameters: j.names.clone(),
        signals: j.signals.clone(),
        weights: j.weights.clone(),
        before: x,
        after: solution.x.clone(),
        objective_before,
        objective_after: frame.per_point(solution.objective),
        iterations: solution.iterations,
        laps,
        converged: solution.converged,
        statement: solution.statement.clone(),
    };
    let profiles = (study.file.profiles || session.options.profiles)
        .then(|| joint_profiles(session, j, &frame, &solution, &iv, &phases));
    let replicates = study.file.bootstrap.max(session.options.bootstrap);
    let bootstrap = (replicates > 0)
        .then(|| joint_bootstrap(session, j, &mut frame, &solution, &iv, &phases, replicates));
    state.set(&index, &solution.x);
    Ok((Some(refinement), iv, profiles, checked, bootstrap))
}

/// Without the refinement (`refine = false`): the intervals at the steps' answer `x`,
/// around the final lap the study already ran. `values(y)` is every parameter's value with
/// the study's parameters at `y`.
fn intervals_at_steps_answer<V>(
    session: &Session,
    state: &StudyState,
    j: &JointProblem,
    prepared: &[PreparedMeasurement],
    x: &[f64],
    values: &V,
) -> Intervals
where
    V: Fn(&[f64]) -> Vec<f64> + Sync,
{
    let workers = session.bench.workers();
    let run = |y: &[f64]| workers.run(&values(y), &prepared[0]).map(|o| o.table);
    let best = state
        .laps
        .optimized
        .as_ref()
        .expect("the final lap is run before the intervals");
    crate::interval::at_optimum(
        &j.names,
        &j.signals,
        &j.weights,
        x,
        &j.bounds,
        &prepared[0],
        best,
        &session.pool,
        run,
    )
}

/// One series per lap and signal; each lap a segment of its own for the long-run
/// covariance (laps are independent of each other).
fn joint_series<'a>(
    session: &Session,
    j: &'a JointProblem,
    prepared: &'a [PreparedMeasurement],
) -> Vec<Series<'a>> {
    let bench = &session.bench;
    prepared
        .iter()
        .enumerate()
        .flat_map(|(k, p)| {
            let label = bench.label(k);
            j.signals.iter().zip(&j.weights).map(move |(s, &w)| Series {
                name: match &label {
                    Some(l) => format!("{s} of lap '{l}'"),
                    None => s.clone(),
                },
                weight: w,
                measured: p.measured(s).unwrap_or(&[]),
                segment: k,
            })
        })
        .collect()
}

/// The laps of a batch of points: on the evaluator's workers when the study has one
/// (each point one task, which runs its laps and returns the filtered signals), else
/// on this process's threads; the same signals to the bit either way. `values(y)` is
/// every parameter's value with the study's parameters at `y`.
fn joint_laps<'a, V>(
    session: &'a Session,
    j: &'a JointProblem,
    prepared: &'a [PreparedMeasurement],
    values: &'a V,
) -> impl Laps + 'a
where
    V: Fn(&[f64]) -> Vec<f64> + Sync,
{
    let bench = &session.bench;
    let remote: Option<&'a dyn Evaluator> = session.options.evaluator.as_deref();
    let local = crate::fit::on_pool(&session.pool, move |y: &[f64]| {
        bench.signals(&values(y), prepared, &j.signals)
    });
    move |points: &[Vec<f64>]| -> Vec<crate::fit::Simulated> {
        let Some(remote) = remote else {
            return local(points);
        };
        let all: Vec<Vec<f64>> = points.iter().map(|y| values(y)).collect();
        match remote.signals(&all) {
            Ok(runs) => runs
                .into_iter()
                .map(|r| {
                    r.map(|series| {
                        series
                            .into_iter()
                            .map(|(start, v)| (start..start + v.len(), v))
                            .collect()
                    })
                })
                .collect(),
            Err(why) => {
                let why = std::sync::Arc::new(why);
                (0..points.len())
                    .map(|_| Err(crate::RunError::Evaluator(why.clone())))
                    .collect()
            }
        }
    }
}

/// The profile likelihood of every parameter at the answer ([`crate::profile`]), its walks
/// on the evaluator's workers where the study has one.
fn joint_profiles<F: Laps>(
    session: &Session,
    j: &JointProblem,
    frame: &Frame<'_, F>,
    solution: &Solution,
    iv: &Intervals,
    phases: &Phases,
) -> Profiles {
    let remote = session.options.evaluator.as_deref();
    let units: Vec<Option<String>> = j
        .names
        .iter()
        .map(|n| {
            session
                .bench
                .workers()
                .parameter_unit(n)
                .map(str::to_string)
        })
        .collect();
    // On an evaluator every walk (two per parameter) waits on its own tasks, so all of
    // them run at once and the cluster gets every walk's laps together.
    let walks = remote.and_then(|_| thread_pool(2 * j.names.len()).ok());
    phases.begin("profiles");
    let profiles = crate::profile::profiles(
        frame,
        &j.names,
        &units,
        solution,
        iv.critical_value,
        walks.as_ref().unwrap_or(&session.pool),
    );
    phases.ran(0, true);
    profiles
}

/// The moving-block bootstrap of the answer with `replicates` refits
/// ([`crate::bootstrap`]), from the study's seed.
fn joint_bootstrap<F: Laps>(
    session: &Session,
    j: &JointProblem,
    frame: &mut Frame<'_, F>,
    solution: &Solution,
    iv: &Intervals,
    phases: &Phases,
    replicates: usize,
) -> Bootstrap {
    let se: Vec<Option<f64>> = j
        .names
        .iter()
        .map(|n| iv.get(n).and_then(|p| p.std_error))
        .collect();
    phases.begin("bootstrap");
    let bootstrap = crate::bootstrap::run(
        frame,
        solution,
        &j.names,
        &se,
        replicates,
        session.study.file.seed,
    );
    phases.ran(0, true);
    bootstrap
}

/// A residual of the wheel loads below this RMS [N] is no spread to estimate (a lap the
/// twin made itself without noise: what is left is the CSV's rounding and the objective's
/// numerical roughness, which would give a collapsed interval).
const LOAD_NOISE_FLOOR_N: f64 = 2.0;

/// The intervals, unless every load signal's residual is below [`LOAD_NOISE_FLOOR_N`]:
/// then none, saying why.
fn noise_floor(
    iv: crate::interval::Intervals,
    blocks: &[crate::block::Block],
    j: &JointProblem,
    x: &[f64],
) -> crate::interval::Intervals {
    let n = j.signals.len().max(1);
    let loads: Vec<f64> = blocks
        .iter()
        .enumerate()
        .filter(|(b, _)| j.signals[b % n].starts_with("Fz"))
        .map(|(_, b)| {
            (b.residual.iter().map(|e| e * e).sum::<f64>() / b.residual.len().max(1) as f64).sqrt()
        })
        .collect();
    if loads.is_empty() || loads.iter().any(|&r| r.is_nan() || r >= LOAD_NOISE_FLOOR_N) {
        return iv;
    }
    let worst = loads.iter().cloned().fold(0.0f64, f64::max);
    crate::interval::Intervals::none(
        &j.names,
        x,
        format!(
            "no interval: the twin matches the measured wheel loads to {worst:.2} N RMS, below the floor of {LOAD_NOISE_FLOOR_N} N at which a spread can be estimated (a lap without noise, made by the twin itself)"
        ),
        iv.laps,
    )
}

/// Per lap, the time at each grid point, from its measured speed (Σ step/v, the speed held
/// at 0.5 m/s or more: a standing start counts as slow, not as forever). `None` where a
/// lap has no speed: the intervals are then estimated on the distance grid.
fn lap_clocks(session: &Session) -> Option<Vec<Vec<f64>>> {
    let compare = &session.study.file.compare;
    session
        .bench
        .laps
        .iter()
        .map(|l| {
            let p = PreparedMeasurement::new(&l.measurement, &["v"], compare).ok()?;
            let step = p.grid().step();
            let mut t = 0.0;
            let times = p
                .measured("v")?
                .iter()
                .map(|v| {
                    let now = t;
                    t += step / v.abs().max(0.5);
                    now
                })
                .collect();
            Some(times)
        })
        .collect()
}

/// The model check at the answer ([`crate::model_check`]), from the laps' measured
/// kinematics; `None` where a lap has no a_x or a_y, or the check cannot be made.
fn model_check(
    session: &Session,
    j: &JointProblem,
    blocks: &[crate::block::Block],
    x: &[f64],
    iv: &crate::interval::Intervals,
) -> Option<crate::model_check::Outcome> {
    let study = session.study;
    let kinematics: Vec<crate::model_check::Kinematics> = session
        .bench
        .laps
        .iter()
        .map(|l| {
            let p =
                PreparedMeasurement::new(&l.measurement, &["v", "a_x", "a_y"], &study.file.compare)
                    .ok()?;
            Some(crate::model_check::Kinematics {
                start: 0,
                v: p.measured("v")?.to_vec(),
                a_x: p.measured("a_x")?.to_vec(),
                a_y: p.measured("a_y")?.to_vec(),
                step_m: p.grid().step(),
            })
        })
        .collect::<Option<_>>()?;
    let n = j.signals.len().max(1);
    let signals: Vec<&str> = (0..blocks.len())
        .map(|b| j.signals[b % n].as_str())
        .collect();
    crate::model_check::check(blocks, &signals, &kinematics, x, &j.bounds, &j.names, iv)
}

/// The refinement, the intervals at the answer, the profiles when asked for, the model
/// check.
pub(crate) type JointAnswer = (
    Option<Refinement>,
    crate::interval::Intervals,
    Option<crate::profile::Profiles>,
    Option<crate::model_check::Outcome>,
    Option<crate::bootstrap::Bootstrap>,
);

//! The finishing of a step (its result: e after, each parameter's change, its intervals)
//! and of the study (its result: the joint answer, the joint row of Tab. 1, the held-out
//! laps, the laps a report draws).

use super::bench::Bench;
use super::interval::Intervals;
use super::joint::{joint_answer, JointProblem};
use super::optimizer::RunState;
use super::pool::Outcome;
use super::profile::Profiles;
use super::results::{JointResult, ParameterChange, SignalChange, StepResult, StudyResult};
use super::session::{Session, StudyState};
use super::step::{Step, StepBegun};
use super::study::StepConfig;
use crate::error::OptimizeError;
use std::time::Instant;
use tb_compare::{Comparison, PreparedMeasurement, Table, Workspace};

/// The step's result: the best point run once more for e after, each parameter's change
/// and each signal's e before and after. With it the best point's lap.
pub(crate) fn finish_step(
    step: &Step,
    begun: StepBegun,
    best: Vec<f64>,
    best_cost: f64,
    pool: &rayon::ThreadPool,
    refine: bool,
) -> Result<(StepResult, Table), OptimizeError> {
    let (config, problem) = (step.config, &step.problem);
    refuse_if_nothing_found(config, &begun.run)?;
    let mut after = problem
        .outcomes(&best)
        .map_err(|reason| OptimizeError::BestPoint {
            step: config.name.clone(),
            reason: Box::new(reason),
        })?;
    let weights = config.weights();
    let bias_weight = problem.cost.bias_weight;
    let cost_after = problem.cost_of_laps(
        config,
        &after.iter().map(|o| &o.comparison).collect::<Vec<_>>(),
    );
    if cost_after.to_bits() != best_cost.to_bits() {
        log::warn!(
            "step '{}': the best point re-evaluated to {cost_after} (optimiser saw {best_cost})",
            config.name
        );
    }
    // How sure the optimum is: 2 laps per parameter around it (crate::interval); with the
    // joint refinement after the steps, its intervals are the answer's and the step's own
    // (conditional on the other steps' values) are not made.
    let intervals = (!refine).then(|| {
        crate::interval::at_optimum(
            &config.parameter_names(),
            &config.signals,
            &weights,
            &best,
            &problem.bounds,
            &problem.prepared[0],
            &after[0].table,
            pool,
            |x| problem.outcome(x).map(|o| o.table),
        )
    });
    let StepBegun {
        start,
        optimizer,
        run,
    } = begun;
    let parameters = step_parameter_changes(step, &start.x0, &best, intervals.as_ref());
    let before: Vec<&Comparison> = std::iter::once(&start.before)
        .chain(&start.before_other_laps)
        .collect();
    let e = step_signal_changes(step, &before, &after, &weights);
    let result = StepResult {
        intervals,
        step: problem.step + 1,
        name: config.name.clone(),
        signals: config.signals.clone(),
        bias_weight,
        optimizer: optimizer.name().into(),
        seed: step.seed,
        parameters,
        e,
        cost_before: start.cost_before,
        cost_after,
        identifiability: start.identifiability,
        history: run.history,
        evaluations: run.evaluations,
        failures: run.failures,
        failure_reasons: run.failure_reasons,
        after_exact: best,
    };
    Ok((result, after.swap_remove(0).table))
}

/// A step whose every candidate failed found nothing: its "best" is a failure's penalty,
/// and the step fails with the first reasons.
fn refuse_if_nothing_found(config: &StepConfig, run: &RunState) -> Result<(), OptimizeError> {
    if run.evaluations > 0 && run.failures == run.evaluations {
        return Err(OptimizeError::StepFailed {
            step: config.name.clone(),
            reason: format!(
                "every one of its {} candidates failed, nothing was optimised; the first reasons: {}",
                run.evaluations,
                run.failure_reasons
                    .iter()
                    .take(3)
                    .cloned()
                    .collect::<Vec<_>>()
                    .join("; ")
            ),
        });
    }
    Ok(())
}

/// Each of the step's parameters from its start `x0` to the `best` point, with the step's
/// own interval where it made one.
fn step_parameter_changes(
    step: &Step,
    x0: &[f64],
    best: &[f64],
    intervals: Option<&Intervals>,
) -> Vec<ParameterChange> {
    let (config, problem) = (step.config, &step.problem);
    config
        .parameters
        .iter()
        .enumerate()
        .map(|(j, p)| ParameterChange {
            name: p.name.clone(),
            unit: problem
                .bench
                .workers()
                .parameter_unit(&p.name)
                .map(str::to_string),
            min: p.min,
            max: p.max,
            before: x0[j],
            after: best[j],
            change_percent: if x0[j] != 0.0 {
                (best[j] / x0[j] - 1.0) * 100.0
            } else {
                f64::NAN
            },
            interval: intervals
                .and_then(|iv| iv.get(&p.name))
                .filter(|i| i.std_error.is_some())
                .map(|i| (i.lo, i.hi)),
            interval_method: intervals.map(|iv| iv.method.clone()),
            interval_statement: intervals
                .and_then(|iv| iv.get(&p.name))
                .and_then(|i| i.statement.clone()),
            std_error: intervals
                .and_then(|iv| iv.get(&p.name))
                .and_then(|i| i.std_error),
            interval_with_model: None,
        })
        .collect()
}

/// Each of the step's signals on every lap: e before (each lap's comparison at the
/// step's start, `before`) and after (the best point's runs, `after`), with its weight.
fn step_signal_changes(
    step: &Step,
    before: &[&Comparison],
    after: &[Outcome],
    weights: &[f64],
) -> Vec<SignalChange> {
    let (config, problem) = (step.config, &step.problem);
    after
        .iter()
        .enumerate()
        .flat_map(|(k, a)| {
            let (before, lap) = (before[k], problem.bench.label(k));
            config
                .signals
                .iter()
                .zip(weights)
                .map(move |(s, &w)| SignalChange {
                    lap: lap.clone(),
                    signal: s.clone(),
                    weight: w,
                    before: before.get(s).cloned().expect("compared"),
                    after: a.comparison.get(s).cloned().expect("compared"),
                })
        })
        .collect()
}

/// Every parameter's value at the study's start: the first step's start point, the others
/// as the system has them (Tab. 1's "initial").
fn initial_values(session: &Session, state: &StudyState) -> Vec<f64> {
    let mut values: Vec<f64> = state.initial.iter().map(|p| p.1).collect();
    if let Some(x0) = &state.first_x0 {
        for (j, p) in session.study.file.steps[0].parameters.iter().enumerate() {
            if let Some(i) = session.bench.workers().index_of(&p.name) {
                values[i] = x0[j];
            }
        }
    }
    values
}

/// The study's result, with the laps a resumed session did not run itself made once each
/// (before the runs are counted).
pub(crate) fn finish_study(
    session: &Session,
    mut state: StudyState,
    wall: Instant,
) -> Result<StudyResult, OptimizeError> {
    let study = session.study;
    make_missing_laps(session, &mut state)?;
    let j = JointProblem::of(study, &state.checkpoint.completed);
    let prepared = session.bench.prepare(&j.signals, &study.file.compare)?;
    let sequential: Vec<f64> = state.assignment.iter().map(|p| p.1).collect();
    let (refinement, intervals, profiles, checked, bootstrap) =
        joint_answer(session, &mut state, &j, &prepared)?;
    // The joint row of Tab. 1: every signal of every lap at the study's start and at its
    // answer (a study of one lap has both laps already).
    let all: Vec<f64> = state.assignment.iter().map(|p| p.1).collect();
    let initial_values = initial_values(session, &state);
    let (before, after) = fitted_comparisons(
        session,
        &mut state,
        &prepared,
        &initial_values,
        &all,
        &sequential,
    )?;
    // Held-out laps: run at the start and with the answer, compared, never fitted.
    let hold_out = held_out_rows(session, &j, &initial_values, &all)?;
    let joint = JointResult {
        parameters: joint_parameter_changes(
            session,
            &state,
            &j,
            &sequential,
            &intervals,
            profiles.as_ref(),
            checked.as_ref(),
        ),
        e: signal_rows(&j, &|k| session.bench.label(k), &before, &after),
        refinement,
        model_check: checked.map(|c| c.check),
        bootstrap,
    };
    let joint_intervals = Some(intervals);
    let (simulations, simulation_seconds) = session.bench.runs();
    Ok(StudyResult {
        hold_out,
        profiles,
        joint: Some(joint),
        joint_intervals,
        study: study.name(),
        system: study.system_path.clone(),
        measurement: study.measurement_path.clone(),
        seed: study.file.seed,
        threads: session.pool.current_num_threads(),
        compare: Some(study.file.compare.clone()),
        steps: state.checkpoint.completed,
        parameters_initial: state.initial,
        parameters_final: state.assignment,
        simulations,
        simulation_seconds,
        wall_seconds: wall.elapsed().as_secs_f64(),
        workers_created: session.bench.workers_created(),
        resumed: state.resumed,
        laps: state.laps,
    })
}

/// A run or a comparison for the study's result that failed.
fn report_failed(reason: crate::failure::RunError) -> OptimizeError {
    OptimizeError::Start {
        step: "report".into(),
        reason: Box::new(reason),
    }
}

/// The laps a report draws that this session did not run itself (a resumed study's): the
/// optimised lap, and the initial one where the first step's start is known.
fn make_missing_laps(session: &Session, state: &mut StudyState) -> Result<(), OptimizeError> {
    let (study, workers) = (session.study, session.bench.workers());
    let lap = |values: &[f64]| -> Result<Table, OptimizeError> {
        let prepared = PreparedMeasurement::new(
            &session.bench.laps[0].measurement,
            &["Fz_sum"],
            &study.file.compare,
        )?;
        workers
            .run(values, &prepared)
            .map(|o| o.table)
            .map_err(report_failed)
    };
    if state.laps.optimized.is_none() {
        let all: Vec<f64> = state.assignment.iter().map(|p| p.1).collect();
        state.laps.optimized = Some(lap(&all)?);
    }
    if state.laps.initial.is_none() && state.first_x0.is_some() {
        state.laps.initial = Some(lap(&initial_values(session, state))?);
    }
    Ok(())
}

/// Every fitted lap compared at the study's start (`initial_values`) and at its answer
/// (`all`); the optimised lap a report draws becomes the answer's. A study of one lap
/// compares the laps it has, and runs the answer again only where it is not the steps'
/// (`sequential`).
fn fitted_comparisons(
    session: &Session,
    state: &mut StudyState,
    prepared: &[PreparedMeasurement],
    initial_values: &[f64],
    all: &[f64],
    sequential: &[f64],
) -> Result<(Vec<Comparison>, Vec<Comparison>), OptimizeError> {
    let compare = |table: &Table| {
        prepared[0]
            .compare(table, &mut Workspace::new())
            .map_err(|e| report_failed(crate::RunError::Comparison(Box::new(e))))
    };
    if session.bench.laps.len() == 1 {
        let before = compare(state.laps.initial.as_ref().expect("made above"))?;
        let after = if all == sequential {
            compare(state.laps.optimized.as_ref().expect("made above"))?
        } else {
            let o = session
                .bench
                .workers()
                .run(all, &prepared[0])
                .map_err(report_failed)?;
            state.laps.optimized = Some(o.table);
            o.comparison
        };
        return Ok((vec![before], vec![after]));
    }
    let before = session
        .bench
        .outcomes(initial_values, prepared)
        .map_err(report_failed)?;
    let mut after = session
        .bench
        .outcomes(all, prepared)
        .map_err(report_failed)?;
    state.laps.optimized = Some(after[0].table.clone());
    Ok((
        before.into_iter().map(|o| o.comparison).collect(),
        after.drain(..).map(|o| o.comparison).collect(),
    ))
}

/// Each joint signal of every lap (`labels(k)` names lap k) at the study's start and at its
/// answer, with its weight.
fn signal_rows(
    j: &JointProblem,
    labels: &dyn Fn(usize) -> Option<String>,
    before: &[Comparison],
    after: &[Comparison],
) -> Vec<SignalChange> {
    before
        .iter()
        .zip(after)
        .enumerate()
        .flat_map(|(k, (b, a))| {
            let lap = labels(k);
            j.signals
                .iter()
                .zip(&j.weights)
                .map(move |(s, &w)| SignalChange {
                    lap: lap.clone(),
                    signal: s.clone(),
                    weight: w,
                    before: b.get(s).cloned().expect("compared"),
                    after: a.get(s).cloned().expect("compared"),
                })
        })
        .collect::<Vec<_>>()
}

/// The held-out laps (`hold_out = true`) run at the study's start and with its answer,
/// compared, never fitted; none where the study holds no lap out.
fn held_out_rows(
    session: &Session,
    j: &JointProblem,
    initial_values: &[f64],
    all: &[f64],
) -> Result<Vec<SignalChange>, OptimizeError> {
    let study = session.study;
    if !study.laps.iter().any(|l| l.hold_out) {
        return Ok(Vec::new());
    }
    let held = Bench::new(study, session.cache.clone(), true)?;
    let prepared = held.prepare(&j.signals, &study.file.compare)?;
    let before = held
        .outcomes(initial_values, &prepared)
        .map_err(report_failed)?;
    let after = held.outcomes(all, &prepared).map_err(report_failed)?;
    let names = |k: usize| Some(held.laps[k].lap.name.clone());
    Ok(signal_rows(
        j,
        &names,
        &before.into_iter().map(|o| o.comparison).collect::<Vec<_>>(),
        &after.into_iter().map(|o| o.comparison).collect::<Vec<_>>(),
    ))
}

/// Each of the study's parameters from before its (first) step to the answer, with the
/// joint interval: the profile's where there is one, else the sandwich's (`intervals`);
/// and the interval with the twin's share where the model check made one.
fn joint_parameter_changes(
    session: &Session,
    state: &StudyState,
    j: &JointProblem,
    sequential: &[f64],
    intervals: &Intervals,
    profiles: Option<&Profiles>,
    checked: Option<&crate::model_check::Outcome>,
) -> Vec<ParameterChange> {
    let workers = session.bench.workers();
    j.names
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let slot = workers.index_of(name).expect("a slot");
            let value = state.assignment[slot].1;
            let iv = intervals.get(name);
            let profile = profiles.and_then(|p| p.get(name));
            let interval = match profile {
                Some(p) => (p.lo.is_some() || p.hi.is_some()).then_some((p.lo, p.hi)),
                None => iv.filter(|i| i.std_error.is_some()).map(|i| (i.lo, i.hi)),
            };
            let statement = match profile {
                Some(p) => p.statement.clone(),
                None => iv.and_then(|i| i.statement.clone()),
            };
            // Where the model check finds the twin wanting, the steps' own answer (the
            // same twin under another objective, e + β·|bias|) is part of what the lap
            // leaves open: the spread across objectives joins the regimes' spread.
            let fired = checked.is_some_and(|c| c.check.discrepancy);
            let steps_value = sequential[slot];
            let with_model = checked
                .and_then(|c| c.with_model.get(k).copied().flatten())
                .map(|(lo, hi)| match fired {
                    true => (
                        lo.map(|lo| lo.min(steps_value)),
                        hi.map(|hi| hi.max(steps_value)),
                    ),
                    false => (lo, hi),
                });
            ParameterChange {
                name: name.clone(),
                unit: workers.parameter_unit(name).map(str::to_string),
                min: j.bounds[k].0,
                max: j.bounds[k].1,
                before: j.before[k],
                after: value,
                change_percent: if j.before[k] != 0.0 {
                    (value / j.before[k] - 1.0) * 100.0
                } else {
                    f64::NAN
                },
                interval,
                interval_method: Some(match profile {
                    Some(_) => crate::profile::METHOD.to_string(),
                    None => intervals.method.clone(),
                }),
                interval_statement: statement,
                std_error: iv.and_then(|i| i.std_error),
                interval_with_model: with_model,
            }
        })
        .collect()
}

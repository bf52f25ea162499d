//! The step loop: each step run, resumed from the checkpoint or passed over when the
//! checkpoint has it completed (and checked); a new step's start (plausibility,
//! identifiability, e before), its generations with a checkpoint after every one, and its
//! result recorded.

use super::bench::LapBench;
use super::checkpoint::{Checkpoint, Current, StepStart};
use super::finish::finish_step;
use super::identifiability;
use super::observe::GenerationDone;
use super::optimizer::{minimize, to_unit, Problem, RunSettings, RunState};
use super::results::{StepResult, StudyLaps};
use super::session::{Session, StudyState};
use super::step::{make_optimizer, Step, StepBegun};
use super::study::{StepConfig, Study};
use crate::error::OptimizeError;
use std::ops::ControlFlow;
use tb_compare::{Comparison, PreparedMeasurement, Table, Workspace};

/// The lap's `what` (in `unit`, written with `decimals`) of the twin against the
/// measurement's, when they are more than the share `at_most` apart.
fn apart(
    what: &str,
    unit: &str,
    decimals: usize,
    twin: f64,
    measured: f64,
    at_most: f64,
) -> Option<String> {
    let rel = (twin - measured).abs() / measured.abs().max(1e-12);
    (rel > at_most).then(|| {
        format!(
            "lap {what} {twin:.decimals$} {unit} (twin) against {measured:.decimals$} {unit} (measured), {:.1} % apart (at most {} %)",
            100.0 * rel,
            100.0 * at_most
        )
    })
}

/// Do the measurement and the twin's first run belong together? Lap length, lap time and
/// the speed over distance, each against the study's `[plausibility]` bounds.
fn check_plausible(study: &Study, bench: &LapBench, lap: &Table) -> Result<(), OptimizeError> {
    let measurement = &bench.measurement;
    let p = &study.file.plausibility;
    let mut problems = Vec::new();
    let (mt, md) = (measurement.time(), measurement.distance());
    let measured_length = md[md.len() - 1] - md[0];
    let measured_time = mt[mt.len() - 1] - mt[0];
    if let Ok(d) = lap.require("distance") {
        let twin = d[d.len() - 1] - d[0];
        problems.extend(apart("length", "m", 1, twin, measured_length, p.lap_length));
    }
    let t = lap.column_at(0);
    let twin_time = t[t.len() - 1] - t[0];
    problems.extend(apart("time", "s", 2, twin_time, measured_time, p.lap_time));
    if lap.find("v").ok().flatten().is_some() {
        let speed = PreparedMeasurement::new(measurement, &["v"], &study.file.compare)
            .and_then(|prep| prep.compare(lap, &mut Workspace::new()));
        match speed.as_ref().map(|c| c.get("v").map(|m| m.r_squared)) {
            Ok(Some(r2)) if r2 < p.r_squared_v => problems.push(format!(
                "the speed over distance agrees with R² = {r2:.3} (at least {} required)",
                p.r_squared_v
            )),
            Err(e) => problems.push(format!("the speeds cannot be compared: {e}")),
            _ => {}
        }
    }
    if problems.is_empty() {
        return Ok(());
    }
    Err(OptimizeError::Implausible(format!(
        "{} and the twin of {} do not belong together: {}. Is the measurement of this circuit, and are the track and the target speed its own (twinbench lap)? `--force` optimises anyway",
        bench.lap.measurement_path.display(),
        bench.lap.system_path.display(),
        problems.join("; ")
    )))
}

/// A completed step of a resumed checkpoint, checked before it is used (M14: a checkpoint
/// edited and its digest recomputed is a file like any other): its cost before and after
/// are computed again (two laps) at its `before` values and its answer, and must be what
/// the checkpoint says.
fn verify_completed(
    session: &Session,
    state: &StudyState,
    k: usize,
    index: &[usize],
    done: &StepResult,
) -> Result<(), OptimizeError> {
    let config = &session.study.file.steps[k];
    let prepared = session
        .bench
        .prepare(&config.signals, &session.study.file.compare)?;
    let step = Step::new(
        session,
        k,
        index.to_vec(),
        &prepared,
        state.assignment.clone(),
    );
    let before: Vec<f64> = done.parameters.iter().map(|p| p.before).collect();
    for (what, x, recorded) in [
        ("before", &before, done.cost_before),
        ("after", &done.after_exact, done.cost_after),
    ] {
        let again = step
            .problem
            .evaluate(x)
            .unwrap_or(session.study.file.penalty);
        if (again - recorded).abs() > 1e-9 * recorded.abs().max(1.0) || x.len() != index.len() {
            return Err(OptimizeError::Checkpoint(format!(
                "step {} '{}' of the checkpoint says its cost {what} was {recorded:?}, and the study computes {again:?} there: the checkpoint was changed, or its study's files were; run without --resume (or remove the checkpoint) to start afresh",
                k + 1,
                config.name
            )));
        }
    }
    Ok(())
}

/// Runs step `k`, or passes over it when the checkpoint has it completed. `Break` when the
/// session stops before the step is done (its checkpoint kept).
pub(crate) fn run_step(
    session: &Session,
    state: &mut StudyState,
    k: usize,
) -> Result<ControlFlow<()>, OptimizeError> {
    let config = &session.study.file.steps[k];
    let index = parameter_index(session, config)?;
    if let Some(done) = state.checkpoint.completed.get(k) {
        let done = done.clone();
        verify_completed(session, state, k, &index, &done)?;
        if k == 0 {
            state.first_x0 = Some(done.parameters.iter().map(|p| p.before).collect());
        }
        state.set(&index, &done.after_exact);
        return Ok(ControlFlow::Continue(()));
    }
    let prepared = session
        .bench
        .prepare(&config.signals, &session.study.file.compare)?;
    let mut step = Step::new(session, k, index, &prepared, state.assignment.clone());
    let mut begun = match state.checkpoint.current.take().filter(|c| c.step == k) {
        Some(current) => resume_step(session, &step, current)?,
        None => start_step(session, &mut step, &mut state.laps)?,
    };
    step.problem.set(&begun.start.x0);
    if k == 0 {
        state.first_x0 = Some(begun.start.x0.clone());
    }
    if session.options.verbose {
        eprintln!("step {} '{}': identifiability", k + 1, config.name);
        for l in begun.start.identifiability.report_lines() {
            eprintln!("  {l}");
        }
    }
    let Some((best, best_cost)) = run_generations(session, state, &step, &mut begun)? else {
        return Ok(ControlFlow::Break(()));
    };
    let (result, after) = finish_step(
        &step,
        begun,
        best,
        best_cost,
        &session.pool,
        session.study.file.refine,
    )?;
    if session.options.verbose {
        if let Some(iv) = &result.intervals {
            eprintln!(
                "step {} '{}': 95 % intervals ({} laps, {} grid points, correlation bandwidth {})",
                k + 1,
                config.name,
                iv.laps,
                iv.grid_points,
                iv.bandwidth
            );
            for p in &iv.parameters {
                let unit = step
                    .problem
                    .bench
                    .workers()
                    .parameter_unit(&p.name)
                    .filter(|u| !u.is_empty() && *u != "1");
                let short = p.name.split_once('.').map_or(p.name.as_str(), |(_, v)| v);
                match &p.statement {
                    Some(why) => eprintln!("  {short}: {} ({why})", p.shown(unit)),
                    None => eprintln!("  {short}: {}", p.shown(unit)),
                }
            }
            for n in &iv.notes {
                eprintln!("  note: {n}");
            }
        }
    }
    if k + 1 == session.study.file.steps.len() {
        state.laps.optimized = Some(after);
    }
    state.set(&step.problem.index, &result.after_exact);
    state.checkpoint.completed.push(result);
    state.checkpoint.current = None;
    if let Some(path) = &session.options.checkpoint {
        state.checkpoint.write(path)?;
    }
    Ok(ControlFlow::Continue(()))
}

/// Where each of the step's parameters sits in the worker pool's assignment.
fn parameter_index(session: &Session, config: &StepConfig) -> Result<Vec<usize>, OptimizeError> {
    config
        .parameter_names()
        .iter()
        .map(|n| {
            session.bench.workers().index_of(n).ok_or_else(|| {
                OptimizeError::Invalid(format!("step '{}': unknown parameter '{n}'", config.name))
            })
        })
        .collect()
}

/// The step under way in the checkpoint: its start as it was, the optimiser restored.
fn resume_step(
    session: &Session,
    step: &Step,
    current: Current,
) -> Result<StepBegun, OptimizeError> {
    let start = to_unit(&current.start.x0, &step.problem.bounds);
    let dim = step.config.parameters.len();
    let mut optimizer = make_optimizer(session.study, session.kind, dim, step.seed, start)?;
    optimizer.restore(&current.optimizer)?;
    if session.options.verbose {
        eprintln!(
            "resuming step {} '{}' from generation {} of {} (checkpoint {})",
            step.problem.step + 1,
            step.config.name,
            optimizer.generation() + 1,
            step.generations,
            session
                .options
                .checkpoint
                .as_deref()
                .map(|p| p.display().to_string())
                .unwrap_or_default()
        );
    }
    Ok(StepBegun {
        start: current.start,
        optimizer,
        run: current.run,
    })
}

/// A new step: its start point; before the first step, whether the measurement and the
/// twin belong together at all; the identifiability check; e before (the first step's run
/// is the initial lap, kept beside the checkpoint); a new optimiser.
fn start_step(
    session: &Session,
    step: &mut Step,
    laps: &mut StudyLaps,
) -> Result<StepBegun, OptimizeError> {
    let (study, options, config) = (session.study, session.options, step.config);
    let problem = &mut step.problem;
    let k = problem.step;
    let x0: Vec<f64> = config
        .parameters
        .iter()
        .zip(&problem.index)
        .map(|(p, &i)| {
            p.start
                .unwrap_or(problem.assignment[i].1)
                .clamp(p.min, p.max)
        })
        .collect();
    problem.set(&x0);
    let failed = |reason| OptimizeError::Start {
        step: config.name.clone(),
        reason: Box::new(reason),
    };
    if k == 0 && !options.force {
        // Before any optimising: do the measurement and the twin belong together?
        for l in &session.bench.laps {
            let lap = l.workers.lap(&problem.params(&x0)).map_err(failed)?;
            check_plausible(study, l, &lap)?;
        }
    }
    let identifiability = identifiability::check(
        config,
        study.file.null_ratio,
        &x0,
        &problem.bounds,
        &problem.prepared[0],
        &session.pool,
        |x| problem.outcome(x).map(|o| o.table),
    );
    let mut before = problem.outcomes(&x0).map_err(failed)?;
    let cost_before = problem.cost_of_laps(
        config,
        &before.iter().map(|o| &o.comparison).collect::<Vec<_>>(),
    );
    let before_other_laps: Vec<Comparison> = before.drain(1..).map(|o| o.comparison).collect();
    let before = before.pop().expect("the first lap");
    if k == 0 {
        laps.initial = Some(before.table);
    }
    let start = to_unit(&x0, &problem.bounds);
    let optimizer = make_optimizer(study, session.kind, x0.len(), step.seed, start)?;
    Ok(StepBegun {
        start: StepStart {
            x0,
            before: before.comparison,
            before_other_laps,
            cost_before,
            identifiability,
        },
        optimizer,
        run: RunState::default(),
    })
}

/// The step's generations from where `begun` stands, with a checkpoint after every one.
/// The best point and its cost; `None` when the session stops (an observer ends it:
/// Ctrl-C, [`StopAfter`](crate::StopAfter)) before the last generation, the checkpoint of the last one kept.
fn run_generations(
    session: &Session,
    state: &mut StudyState,
    step: &Step,
    begun: &mut StepBegun,
) -> Result<Option<(Vec<f64>, f64)>, OptimizeError> {
    let (study, options) = (session.study, session.options);
    for o in &options.observers {
        o.step_started(
            step.problem.step + 1,
            &step.config.name,
            step.generations,
            begun.optimizer.generation(),
        );
    }
    let threads = session.pool.current_num_threads();
    let settings = RunSettings {
        max_generations: step.generations,
        threads: options.threads,
        penalty: study.file.penalty,
    };
    let mut interrupted = false;
    let mut write_error = None;
    let completed = &state.checkpoint.completed;
    let session_generations = &mut state.session_generations;
    let start = &begun.start;
    let result = minimize(
        begun.optimizer.as_mut(),
        &step.problem,
        &settings,
        &mut begun.run,
        |opt, run| {
            *session_generations += 1;
            if let Some(path) = &options.checkpoint {
                let current = Current {
                    step: step.problem.step,
                    start: start.clone(),
                    optimizer: opt.save(),
                    run: run.clone(),
                };
                let cp = Checkpoint::new(study, options, completed.clone(), Some(current));
                if let Err(e) = cp.write(path) {
                    write_error = Some(e);
                    return ControlFlow::Break(());
                }
            }
            // Every observer sees the generation; any may end the study after it.
            let mut stop = false;
            if let Some(rec) = run.history.last() {
                let done = GenerationDone {
                    step: step.problem.step + 1,
                    name: &step.config.name,
                    generations: step.generations,
                    done: opt.generation(),
                    record: rec,
                    // A cluster's workers come and go: asked at every generation.
                    workers: match &options.evaluator {
                        Some(e) => e.workers(),
                        None => Some(threads),
                    },
                };
                for o in &options.observers {
                    stop |= o.generation(&done).is_break();
                }
            }
            if stop && opt.generation() < step.generations {
                interrupted = true;
                return ControlFlow::Break(());
            }
            ControlFlow::Continue(())
        },
    );
    for o in &options.observers {
        o.step_finished();
    }
    if let Some(e) = write_error {
        return Err(e);
    }
    if interrupted {
        return Ok(None);
    }
    result.map(Some)
}

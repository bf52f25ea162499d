//! The study driver: the steps in order (each starts from the earlier steps' results), an
//! identifiability check and e before each step, the optimiser's generations with a
//! checkpoint after every one, e after, and the whole result as a serialisable value.

use super::bench::{Bench, LapBench};
use super::checkpoint::{Checkpoint, Current, StepStart};
use super::cmaes::Cmaes;
use super::cost::StepCost;
use super::fit::{Frame, Refinement, Series};
use super::ga::Ga;
use super::identifiability;
use super::observe::Phases;
use super::optimizer::{
    evaluate_all, finite, minimize, thread_pool, to_unit, Optimizer, Problem, RunSettings, RunState,
};
use super::pool::Outcome;
use super::remote::{Candidate, Evaluator};
use super::study::{OptimizerKind, StepConfig, Study};
use super::OptimizeError;
use std::ops::ControlFlow;
use std::sync::Arc;
use std::time::Instant;
use tb_compare::{Comparison, PreparedMeasurement, Table, Workspace};
use tb_fmi::FmuCache;

// The cost, the observers, the options and what a study records live in files of their own
// (the bench, a remote worker and the checkpoint share them); named here too, where callers
// have always found them.
pub use super::cost::cost_of;
pub use super::observe::{GenerationDone, PhaseProgress, StopAfter, StopOnFlag, StudyObserver};
pub use super::options::RunOptions;
pub use super::results::{
    JointResult, ParameterChange, SignalChange, StepResult, StudyLaps, StudyOutcome, StudyResult,
};

/// One step's cost over the bench.
struct StepProblem<'a> {
    bench: &'a Bench,
    /// Each lap's measurement prepared for the step's signals.
    prepared: &'a [PreparedMeasurement],
    /// The step (0-based) and its cost.
    step: usize,
    cost: StepCost,
    /// Every parameter of the study with its current value.
    assignment: Vec<(String, f64)>,
    /// Indices into `assignment` of the step's parameters.
    index: Vec<usize>,
    bounds: Vec<(f64, f64)>,
    /// Where generations are evaluated when not on this process's threads.
    remote: Option<&'a dyn Evaluator>,
}

impl StepProblem<'_> {
    /// Every parameter's value with the step's parameters at `x`.
    fn params(&self, x: &[f64]) -> Vec<f64> {
        let mut a: Vec<f64> = self.assignment.iter().map(|p| p.1).collect();
        for (k, &i) in self.index.iter().enumerate() {
            a[i] = x[k];
        }
        a
    }

    /// Puts the step's parameters at `x` in the assignment the step starts from.
    fn set(&mut self, x: &[f64]) {
        for (j, &i) in self.index.iter().enumerate() {
            self.assignment[i].1 = x[j];
        }
    }

    /// The first lap's run (what the identifiability check and a step's own intervals
    /// look at).
    fn outcome(&self, x: &[f64]) -> Result<Outcome, String> {
        self.bench.workers().run(&self.params(x), &self.prepared[0])
    }

    /// Every lap's run.
    fn outcomes(&self, x: &[f64]) -> Result<Vec<Outcome>, String> {
        self.bench.outcomes(&self.params(x), self.prepared)
    }

    /// The step's cost of every lap's comparison, weighted.
    fn cost_of_laps(&self, config: &StepConfig, comparisons: &[&Comparison]) -> f64 {
        let weights = config.weights();
        let costs: Vec<f64> = comparisons
            .iter()
            .map(|c| cost_of(c, &config.signals, &weights, self.cost.bias_weight))
            .collect();
        self.bench.weighted(&costs)
    }
}

impl Problem for StepProblem<'_> {
    fn bounds(&self) -> Vec<(f64, f64)> {
        self.bounds.clone()
    }

    fn evaluate(&self, x: &[f64]) -> Result<f64, String> {
        self.bench.cost(&self.cost, &self.params(x), self.prepared)
    }

    fn evaluate_many(
        &self,
        pool: &rayon::ThreadPool,
        xs: &[Vec<f64>],
    ) -> Result<Vec<Result<f64, String>>, OptimizeError> {
        let Some(remote) = self.remote else {
            return Ok(evaluate_all(pool, self, xs));
        };
        let candidates: Vec<Candidate> = xs
            .iter()
            .map(|x| Candidate {
                step: self.step,
                values: self.params(x),
            })
            .collect();
        let results = remote
            .evaluate(&candidates)
            .map_err(OptimizeError::Evaluator)?;
        if results.len() != xs.len() {
            return Err(OptimizeError::Evaluator(format!(
                "{} results for {} candidates",
                results.len(),
                xs.len()
            )));
        }
        Ok(results.into_iter().map(finite).collect())
    }
}

fn step_seed(seed: u64, step: usize) -> u64 {
    seed ^ (step as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15)
}

fn make_optimizer(
    study: &Study,
    kind: OptimizerKind,
    dim: usize,
    seed: u64,
    start: Vec<f64>,
) -> Result<Box<dyn Optimizer>, OptimizeError> {
    let o = &study.file.optimizer;
    Ok(match kind {
        OptimizerKind::Ga => Box::new(Ga::new(dim, o.ga.clone(), seed, Some(start))?),
        OptimizerKind::Cmaes => Box::new(Cmaes::new(dim, o.cmaes.clone(), seed, Some(start))?),
    })
}

/// Do the measurement and the twin's first run belong together? Lap length, lap time and
/// the speed over distance, each against the study's `[plausibility]` bounds.
fn check_plausible(study: &Study, bench: &LapBench, lap: &Table) -> Result<(), OptimizeError> {
    let measurement = &bench.measurement;
    let p = &study.file.plausibility;
    let mut problems = Vec::new();
    let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-12);
    let (mt, md) = (measurement.time(), measurement.distance());
    let measured_length = md[md.len() - 1] - md[0];
    let measured_time = mt[mt.len() - 1] - mt[0];
    if let Ok(d) = lap.require("distance") {
        let twin = d[d.len() - 1] - d[0];
        if rel(twin, measured_length) > p.lap_length {
            problems.push(format!(
                "lap length {twin:.1} m (twin) against {measured_length:.1} m (measured), {:.1} % apart (at most {} %)",
                100.0 * rel(twin, measured_length),
                100.0 * p.lap_length
            ));
        }
    }
    let t = lap.column_at(0);
    let twin_time = t[t.len() - 1] - t[0];
    if rel(twin_time, measured_time) > p.lap_time {
        problems.push(format!(
            "lap time {twin_time:.2} s (twin) against {measured_time:.2} s (measured), {:.1} % apart (at most {} %)",
            100.0 * rel(twin_time, measured_time),
            100.0 * p.lap_time
        ));
    }
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

/// Runs a study (or continues it from its checkpoint): the steps in order, each passed over
/// when the checkpoint has it completed, then the result with the laps a report draws.
pub fn run_study(study: &Study, options: &RunOptions) -> Result<StudyOutcome, OptimizeError> {
    let wall = Instant::now();
    let session = Session::open(study, options)?;
    let mut state = StudyState::begin(&session)?;
    for k in 0..study.file.steps.len() {
        if run_step(&session, &mut state, k)?.is_break() {
            return Ok(StudyOutcome::Interrupted {
                generations: state.session_generations,
            });
        }
    }
    let result = finish_study(&session, state, wall)?;
    for o in &options.observers {
        o.finished(&result).map_err(OptimizeError::Observer)?;
    }
    Ok(StudyOutcome::Finished(Box::new(result)))
}

/// What every stage of a study reads: the study, how it is run, the worker pool on its
/// compiled system, the measurement, the threads of the start's runs and the optimiser.
struct Session<'a> {
    study: &'a Study,
    options: &'a RunOptions,
    /// The fitted laps.
    bench: Bench,
    /// The unpacked FMUs (the held-out laps' workers load theirs from it too).
    cache: Arc<FmuCache>,
    /// The identifiability check's threads (the generations' are `minimize`'s own).
    pool: rayon::ThreadPool,
    kind: OptimizerKind,
}

impl<'a> Session<'a> {
    /// Compiles the system, loads the measurement, builds the threads.
    fn open(study: &'a Study, options: &'a RunOptions) -> Result<Session<'a>, OptimizeError> {
        let cache = Arc::new(FmuCache::temporary(false).map_err(tb_cosim::SystemError::from)?);
        let bench = Bench::new(study, cache.clone(), false)?;
        let pool = thread_pool(options.threads)?;
        Ok(Session {
            study,
            options,
            bench,
            cache,
            pool,
            kind: options.optimizer.unwrap_or(study.file.optimizer.kind),
        })
    }
}

/// Where the study stands, carried from step to step.
struct StudyState {
    /// The completed steps and the step under way (what the checkpoint file holds).
    checkpoint: Checkpoint,
    resumed: bool,
    /// Every parameter the study touches, with its initial value.
    initial: Vec<(String, f64)>,
    /// The same parameters with their values after the steps done so far.
    assignment: Vec<(String, f64)>,
    laps: StudyLaps,
    /// The first step's start point (for the initial lap when it has to be made again).
    first_x0: Option<Vec<f64>>,
    /// Generations run in this session.
    session_generations: usize,
}

impl StudyState {
    /// The study's state from its checkpoint (resume), else before its first step.
    fn begin(session: &Session) -> Result<StudyState, OptimizeError> {
        let assignment = session.bench.workers().assignment();
        let (checkpoint, resumed) = Checkpoint::resume_or_new(session.study, session.options)?;
        // A resumed study simulates its initial lap again (one lap) at the end rather than
        // read one beside the checkpoint, which nothing vouches for (M14).
        let laps = StudyLaps::default();
        Ok(StudyState {
            checkpoint,
            resumed,
            initial: assignment.clone(),
            assignment,
            laps,
            first_x0: None,
            session_generations: 0,
        })
    }

    /// Sets the step's parameters (at `index` in the assignment) to `values`.
    fn set(&mut self, index: &[usize], values: &[f64]) {
        for (j, &i) in index.iter().enumerate() {
            self.assignment[i].1 = values[j];
        }
    }
}

/// One step as this session runs it: its configuration, seed and generations, and its
/// cost over the bench.
struct Step<'a> {
    config: &'a StepConfig,
    seed: u64,
    generations: usize,
    problem: StepProblem<'a>,
}

impl<'a> Step<'a> {
    /// Step `k` with its parameters at `index` in `assignment` (every parameter's value
    /// after the earlier steps) and the measurement prepared for its signals.
    fn new(
        session: &'a Session,
        k: usize,
        index: Vec<usize>,
        prepared: &'a [PreparedMeasurement],
        assignment: Vec<(String, f64)>,
    ) -> Step<'a> {
        let (study, options) = (session.study, session.options);
        let config = &study.file.steps[k];
        Step {
            config,
            seed: step_seed(study.file.seed, k),
            generations: options
                .generations
                .or(config.generations)
                .unwrap_or(study.file.optimizer.generations),
            problem: StepProblem {
                bench: &session.bench,
                prepared,
                step: k,
                cost: StepCost::of_step(study, k).expect("a step of the study"),
                assignment,
                index,
                bounds: config.parameters.iter().map(|p| (p.min, p.max)).collect(),
                remote: options.evaluator.as_deref(),
            },
        }
    }
}

/// A step ready for its generations: what it knew before the first one, the optimiser and
/// the generation loop's bookkeeping (restored from the checkpoint, or new).
struct StepBegun {
    start: StepStart,
    optimizer: Box<dyn Optimizer>,
    run: RunState,
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
fn run_step(
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
        reason,
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
/// Ctrl-C, [`StopAfter`]) before the last generation, the checkpoint of the last one kept.
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

/// The step's result: the best point run once more for e after, each parameter's change
/// and each signal's e before and after. With it the best point's lap.
fn finish_step(
    step: &Step,
    begun: StepBegun,
    best: Vec<f64>,
    best_cost: f64,
    pool: &rayon::ThreadPool,
    refine: bool,
) -> Result<(StepResult, Table), OptimizeError> {
    let (config, problem) = (step.config, &step.problem);
    // A step whose every candidate failed found nothing: its "best" is a failure's penalty.
    let run = &begun.run;
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
    let mut after = problem
        .outcomes(&best)
        .map_err(|reason| OptimizeError::Start {
            step: config.name.clone(),
            reason: format!("the best point cannot be re-evaluated: {reason}"),
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
    let parameters = config
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
            before: start.x0[j],
            after: best[j],
            change_percent: if start.x0[j] != 0.0 {
                (best[j] / start.x0[j] - 1.0) * 100.0
            } else {
                f64::NAN
            },
            interval: intervals
                .as_ref()
                .and_then(|iv| iv.get(&p.name))
                .filter(|i| i.std_error.is_some())
                .map(|i| (i.lo, i.hi)),
            interval_method: intervals.as_ref().map(|iv| iv.method.clone()),
            interval_statement: intervals
                .as_ref()
                .and_then(|iv| iv.get(&p.name))
                .and_then(|i| i.statement.clone()),
            std_error: intervals
                .as_ref()
                .and_then(|iv| iv.get(&p.name))
                .and_then(|i| i.std_error),
            interval_with_model: None,
        })
        .collect();
    let before: Vec<&Comparison> = std::iter::once(&start.before)
        .chain(&start.before_other_laps)
        .collect();
    let e = after
        .iter()
        .enumerate()
        .flat_map(|(k, a)| {
            let (before, lap) = (before[k], problem.bench.label(k));
            config
                .signals
                .iter()
                .zip(&weights)
                .map(move |(s, &w)| SignalChange {
                    lap: lap.clone(),
                    signal: s.clone(),
                    weight: w,
                    before: before.get(s).cloned().expect("compared"),
                    after: a.comparison.get(s).cloned().expect("compared"),
                })
        })
        .collect();
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

/// Every parameter the steps fit (first appearance: its bounds and its value before its
/// step) and every signal they compare (its weight where it first appears).
struct JointProblem {
    names: Vec<String>,
    bounds: Vec<(f64, f64)>,
    before: Vec<f64>,
    signals: Vec<String>,
    weights: Vec<f64>,
}

impl JointProblem {
    fn of(study: &Study, steps: &[StepResult]) -> JointProblem {
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
fn joint_answer(
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
        let run = |y: &[f64]| workers.run(&values(y), &prepared[0]).map(|o| o.table);
        let best = state
            .laps
            .optimized
            .as_ref()
            .expect("the final lap is run before the intervals");
        let iv = crate::interval::at_optimum(
            &j.names,
            &j.signals,
            &j.weights,
            &x,
            &j.bounds,
            &prepared[0],
            best,
            &session.pool,
            run,
        );
        return Ok((None, iv, None, None, None));
    }
    // One series per lap and signal; each lap a segment of its own for the long-run
    // covariance (laps are independent of each other).
    let series: Vec<Series> = prepared
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
        .collect();
    // The laps of a batch of points: on the evaluator's workers when the study has one
    // (each point one task, which runs its laps and returns the filtered signals), else
    // on this process's threads; the same signals to the bit either way.
    let remote = session.options.evaluator.as_deref();
    let local = crate::fit::on_pool(&session.pool, |y: &[f64]| {
        bench.signals(&values(y), prepared, &j.signals)
    });
    let simulate_points = |points: &[Vec<f64>]| -> Vec<crate::fit::Simulated> {
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
            Err(why) => vec![Err(format!("the evaluator failed: {why}")); points.len()],
        }
    };
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
    let profiles = (study.file.profiles || session.options.profiles).then(|| {
        let units: Vec<Option<String>> = j
            .names
            .iter()
            .map(|n| workers.parameter_unit(n).map(str::to_string))
            .collect();
        // On an evaluator every walk (two per parameter) waits on its own tasks, so all of
        // them run at once and the cluster gets every walk's laps together.
        let walks = remote.and_then(|_| thread_pool(2 * j.names.len()).ok());
        phases.begin("profiles");
        let profiles = crate::profile::profiles(
            &frame,
            &j.names,
            &units,
            &solution,
            iv.critical_value,
            walks.as_ref().unwrap_or(&session.pool),
        );
        phases.ran(0, true);
        profiles
    });
    let replicates = study.file.bootstrap.max(session.options.bootstrap);
    let bootstrap = (replicates > 0).then(|| {
        let se: Vec<Option<f64>> = j
            .names
            .iter()
            .map(|n| iv.get(n).and_then(|p| p.std_error))
            .collect();
        phases.begin("bootstrap");
        let bootstrap = crate::bootstrap::run(
            &mut frame,
            &solution,
            &j.names,
            &se,
            replicates,
            study.file.seed,
        );
        phases.ran(0, true);
        bootstrap
    });
    state.set(&index, &solution.x);
    Ok((Some(refinement), iv, profiles, checked, bootstrap))
}

/// A residual of the wheel loads below this RMS [N] is no spread to estimate (a lap the
/// twin made itself without noise: what is left is the CSV's rounding and the objective's
/// numerical roughness, which would give a collapsed interval).
const LOAD_NOISE_FLOOR_N: f64 = 2.0;

/// The intervals, unless every load signal's residual is below [`LOAD_NOISE_FLOOR_N`]:
/// then none, saying why.
fn noise_floor(
    iv: crate::interval::Intervals,
    blocks: &[crate::interval::Block],
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
    blocks: &[crate::interval::Block],
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
type JointAnswer = (
    Option<Refinement>,
    crate::interval::Intervals,
    Option<crate::profile::Profiles>,
    Option<crate::model_check::Outcome>,
    Option<crate::bootstrap::Bootstrap>,
);

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
fn finish_study(
    session: &Session,
    mut state: StudyState,
    wall: Instant,
) -> Result<StudyResult, OptimizeError> {
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
            .map_err(|reason| OptimizeError::Start {
                step: "report".into(),
                reason,
            })
    };
    if state.laps.optimized.is_none() {
        let all: Vec<f64> = state.assignment.iter().map(|p| p.1).collect();
        state.laps.optimized = Some(lap(&all)?);
    }
    if state.laps.initial.is_none() && state.first_x0.is_some() {
        state.laps.initial = Some(lap(&initial_values(session, &state))?);
    }
    let j = JointProblem::of(study, &state.checkpoint.completed);
    let prepared = session.bench.prepare(&j.signals, &study.file.compare)?;
    let sequential: Vec<f64> = state.assignment.iter().map(|p| p.1).collect();
    let (refinement, intervals, profiles, checked, bootstrap) =
        joint_answer(session, &mut state, &j, &prepared)?;
    // The joint row of Tab. 1: every signal of every lap at the study's start and at its
    // answer (a study of one lap has both laps already).
    let all: Vec<f64> = state.assignment.iter().map(|p| p.1).collect();
    let failed = |reason| OptimizeError::Start {
        step: "report".into(),
        reason,
    };
    let compare = |table: &Table| {
        prepared[0]
            .compare(table, &mut Workspace::new())
            .map_err(|e| failed(format!("comparison: {e}")))
    };
    let initial_values = initial_values(session, &state);
    let (before, after): (Vec<Comparison>, Vec<Comparison>) = if session.bench.laps.len() == 1 {
        let before = compare(state.laps.initial.as_ref().expect("made above"))?;
        let after = if all == sequential {
            compare(state.laps.optimized.as_ref().expect("made above"))?
        } else {
            let o = workers.run(&all, &prepared[0]).map_err(failed)?;
            state.laps.optimized = Some(o.table);
            o.comparison
        };
        (vec![before], vec![after])
    } else {
        let before = session
            .bench
            .outcomes(&initial_values, &prepared)
            .map_err(failed)?;
        let mut after = session.bench.outcomes(&all, &prepared).map_err(failed)?;
        state.laps.optimized = Some(after[0].table.clone());
        (
            before.into_iter().map(|o| o.comparison).collect(),
            after.drain(..).map(|o| o.comparison).collect(),
        )
    };
    let rows =
        |labels: &dyn Fn(usize) -> Option<String>, before: &[Comparison], after: &[Comparison]| {
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
        };
    // Held-out laps: run at the start and with the answer, compared, never fitted.
    let hold_out = if study.laps.iter().any(|l| l.hold_out) {
        let held = Bench::new(study, session.cache.clone(), true)?;
        let prepared = held.prepare(&j.signals, &study.file.compare)?;
        let before = held.outcomes(&initial_values, &prepared).map_err(failed)?;
        let after = held.outcomes(&all, &prepared).map_err(failed)?;
        let names = |k: usize| Some(held.laps[k].lap.name.clone());
        rows(
            &names,
            &before.into_iter().map(|o| o.comparison).collect::<Vec<_>>(),
            &after.into_iter().map(|o| o.comparison).collect::<Vec<_>>(),
        )
    } else {
        Vec::new()
    };
    let joint = JointResult {
        parameters: j
            .names
            .iter()
            .enumerate()
            .map(|(k, name)| {
                let slot = workers.index_of(name).expect("a slot");
                let value = state.assignment[slot].1;
                let iv = intervals.get(name);
                let profile = profiles.as_ref().and_then(|p| p.get(name));
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
                let fired = checked.as_ref().is_some_and(|c| c.check.discrepancy);
                let steps_value = sequential[slot];
                let with_model = checked
                    .as_ref()
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
            .collect(),
        e: rows(&|k| session.bench.label(k), &before, &after),
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

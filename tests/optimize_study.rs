//! Studies on the co-simulated bench (small ones): the same seed gives the same result with
//! 1 and 2 threads; a study interrupted (twice, in both steps) and resumed ends with the same
//! result as an uninterrupted one; a candidate whose run fails is penalised and the study
//! goes on.

mod common;

use common::study;
use std::path::Path;
use std::sync::Arc;
use tb_optimize::{
    run_study, OptimizeError, RunOptions, StopAfter, Study, StudyOutcome, StudyResult,
};
use tb_testkit::assert_contains;

fn study_text(optimizer: &str, body: &str) -> String {
    let head = study::head(
        "small",
        &study::rls_v(),
        "seed = 17\nbias_weight = 1.0",
        &[],
    );
    format!(
        r#"{head}[optimizer]
kind = "{optimizer}"
generations = 2
[optimizer.ga]
population = 6
elites = 2
[optimizer.cmaes]
population = 4
{body}
"#
    )
}

const TWO_STEPS: &str = r#"
[[step]]
name = "lift"
signals = ["Fz_front", "Fz_rear"]
[[step.parameter]]
name = "vehicle.c_lift_front"
min = 0.2
max = 2.5
[[step.parameter]]
name = "vehicle.c_lift_rear"
min = 0.2
max = 2.5
[[step]]
name = "track"
signals = ["Fz_fl", "Fz_fr"]
[[step.parameter]]
name = "vehicle.b_front"
min = 0.9
max = 2.0
"#;

fn load(dir: &Path, text: &str) -> Study {
    let path = dir.join("study.toml");
    std::fs::write(&path, text).unwrap();
    Study::load(&path).unwrap()
}

fn options(threads: usize, checkpoint: &Path) -> RunOptions {
    RunOptions {
        threads,
        checkpoint: Some(checkpoint.to_path_buf()),
        ..RunOptions::default()
    }
}

fn finished(o: StudyOutcome) -> StudyResult {
    match o {
        StudyOutcome::Finished(r) => *r,
        StudyOutcome::Interrupted { .. } => panic!("interrupted"),
    }
}

/// Everything the optimisation decides, bit for bit.
fn assert_same(a: &StudyResult, b: &StudyResult, what: &str) {
    assert_eq!(a.steps.len(), b.steps.len(), "{what}");
    for (x, y) in a.steps.iter().zip(&b.steps) {
        assert_eq!(
            x.after_exact, y.after_exact,
            "{what}: step {} parameters",
            x.name
        );
        assert_eq!(x.cost_after.to_bits(), y.cost_after.to_bits(), "{what}");
        assert_eq!(x.evaluations, y.evaluations, "{what}");
        let h = |r: &tb_optimize::StepResult| -> Vec<u64> {
            r.history.iter().map(|g| g.best_cost.to_bits()).collect()
        };
        assert_eq!(h(x), h(y), "{what}: best cost per generation");
        for (e1, e2) in x.e.iter().zip(&y.e) {
            assert_eq!(
                e1.after.e.to_bits(),
                e2.after.e.to_bits(),
                "{what}: e of {}",
                e1.signal
            );
            assert_eq!(e1.before.e.to_bits(), e2.before.e.to_bits(), "{what}");
        }
    }
    assert_eq!(a.parameters_final, b.parameters_final, "{what}");
}

#[test]
fn same_seed_same_result_any_threads_and_after_resume() {
    common::fmu_dir();
    let dir = tempfile::tempdir().unwrap();
    let study = load(dir.path(), &study_text("ga", TWO_STEPS));
    let one = finished(run_study(&study, &options(1, &dir.path().join("a.json"))).unwrap());
    let two = finished(run_study(&study, &options(2, &dir.path().join("b.json"))).unwrap());
    assert_eq!((one.threads, two.threads), (1, 2));
    assert_same(&one, &two, "1 vs 2 threads");
    // Each worker owns one Simulation, reused: never more than the threads (+ the first).
    assert!(
        two.workers_created <= 2,
        "{} simulations created",
        two.workers_created
    );
    // Later steps start from earlier results.
    assert_eq!(
        two.steps[1].identifiability.start,
        vec![two.initial_value("vehicle.b_front").unwrap()],
        "step 2 starts at the system's b_front"
    );
    assert!(two.steps[0].e.iter().all(|e| e.after.e < e.before.e));

    // Interrupted after 1 generation (in step 1), resumed and interrupted again after
    // 2 more (in step 2), resumed to the end: the same result.
    let cp = dir.path().join("c.json");
    let mut o = options(2, &cp);
    o.observers = vec![Arc::new(StopAfter::new(1))];
    assert!(matches!(
        run_study(&study, &o).unwrap(),
        StudyOutcome::Interrupted { generations: 1 }
    ));
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cp).unwrap()).unwrap();
    assert_eq!(saved["checkpoint"]["current"]["step"], 0);
    o.resume = true;
    o.observers = vec![Arc::new(StopAfter::new(2))];
    o.threads = 1;
    assert!(matches!(
        run_study(&study, &o).unwrap(),
        StudyOutcome::Interrupted { .. }
    ));
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&cp).unwrap()).unwrap();
    assert_eq!(
        saved["checkpoint"]["current"]["step"], 1,
        "the second interruption is in step 2"
    );
    assert_eq!(
        saved["checkpoint"]["completed"].as_array().unwrap().len(),
        1
    );
    // M14: a copy of this checkpoint with step 1's cost after edited and the digest
    // recomputed is refused on resume, naming the step; the untouched one resumes.
    {
        use sha2::Digest;
        let text = std::fs::read_to_string(&cp).unwrap();
        let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
        v["checkpoint"]["completed"][0]["cost_after"] = serde_json::json!(0.0);
        let body = serde_json::to_string(&v["checkpoint"]).unwrap();
        let digest = format!("{:x}", sha2::Sha256::digest(body.as_bytes()));
        let edited = dir.path().join("edited.json");
        std::fs::write(
            &edited,
            format!("{{\"sha256\":\"{digest}\",\"checkpoint\":{body}}}\n"),
        )
        .unwrap();
        let mut e = o.clone();
        e.checkpoint = Some(edited);
        e.observers.clear();
        let err = run_study(&study, &e)
            .err()
            .expect("an edited checkpoint is refused");
        assert!(matches!(err, OptimizeError::Checkpoint(_)), "{err}");
        assert_contains(
            &err.to_string(),
            &["step 1 'lift' of the checkpoint says its cost after was 0.0"],
        );
    }
    // A caller's own observer beside the stop conditions: it sees the remaining
    // generations with the threads they ran on, and the result once.
    let watcher = Arc::new(Watcher::default());
    o.observers = vec![watcher.clone()];
    o.threads = 2;
    let resumed = finished(run_study(&study, &o).unwrap());
    {
        let seen = watcher.seen.lock().unwrap();
        assert!(
            !seen.is_empty()
                && seen
                    .iter()
                    .all(|(step, workers)| *step >= 2 && *workers == Some(2)),
            "{seen:?}"
        );
        assert_eq!(*watcher.finished.lock().unwrap(), 1);
    }
    assert!(resumed.resumed);
    assert_same(
        &two,
        &resumed,
        "interrupted twice and resumed vs uninterrupted",
    );
    // Every reported value, byte for byte (the session's own figures aside: run counts,
    // times, workers, whether it was resumed).
    let reported = |r: &StudyResult| {
        let mut j = serde_json::to_value(r).unwrap();
        let o = j.as_object_mut().unwrap();
        for k in [
            "simulations",
            "simulation_seconds",
            "wall_seconds",
            "workers_created",
            "resumed",
            "threads",
        ] {
            o.remove(k);
        }
        serde_json::to_string_pretty(&j).unwrap()
    };
    let (a, b) = (reported(&two), reported(&resumed));
    if a != b {
        let diff: Vec<String> = a
            .lines()
            .zip(b.lines())
            .enumerate()
            .filter(|(_, (x, y))| x != y)
            .take(20)
            .map(|(i, (x, y))| format!("line {i}: {x} | {y}"))
            .collect();
        panic!("the resumed result differs:\n{}", diff.join("\n"));
    }

    // A checkpoint of another study is refused.
    let other = load(dir.path(), &study_text("cmaes", TWO_STEPS));
    let err = run_study(&other, &o).err().expect("refused");
    assert!(matches!(err, OptimizeError::Checkpoint(_)), "{err}");
    assert!(err.to_string().contains("another study"), "{err}");
    // A resume with another budget or optimiser than the checkpoint's is refused.
    o.generations = Some(7);
    let err = run_study(&study, &o).err().expect("refused");
    assert!(matches!(err, OptimizeError::Checkpoint(_)), "{err}");
    assert_contains(&err.to_string(), &["was made with no overrides, this run has --generations 7: resume with the same options"]);
}

#[test]
fn a_failing_candidate_is_penalised_and_the_study_goes_on() {
    let fmu_dir = common::fmu_dir();
    let dir = tempfile::tempdir().unwrap();
    // The bench with a probe that fails on purpose (fmi2Error) from `probe.fault_time` on:
    // candidates with a fault time inside the lap (about 98 s) fail.
    let root = twinbench::pack::workspace_root();
    let faulty = common::fmu("faulty");
    let system = std::fs::read_to_string(root.join("systems/rls_v.toml"))
        .unwrap()
        .replace("\"../target/fmu/", &format!("\"{}/", fmu_dir.display()))
        .replace(
            "[fmus]\n",
            &format!("[fmus]\nprobe = {:?}\n", faulty.display().to_string()),
        )
        .replace(
            "[parameters]\n",
            "[[instance]]\nname = \"probe\"\nfmu = \"probe\"\n\n[parameters]\n\"probe.fault_kind\" = 1\n",
        );
    let sys = dir.path().join("probe.toml");
    std::fs::write(&sys, system).unwrap();
    let body = r#"
[[step]]
name = "probe"
signals = ["Fz_sum"]
[[step.parameter]]
name = "probe.fault_time"
min = 60.0
max = 300.0
start = 300.0
"#;
    let text = study_text("ga", body).replace(
        &root.join("systems/rls_v.toml").display().to_string(),
        &sys.display().to_string(),
    );
    let study = load(dir.path(), &text);
    let r = finished(run_study(&study, &options(2, &dir.path().join("cp.json"))).unwrap());
    let s = &r.steps[0];
    assert!(
        s.failures >= 1,
        "the seed was chosen to draw failing candidates: {s:?}"
    );
    assert_eq!(s.failure_reasons.len(), s.failures);
    for reason in &s.failure_reasons {
        assert_contains(
            reason,
            &["instance 'probe'", "fmi2DoStep returned fmi2Error"],
        );
    }
    assert!(s.cost_after < 1.0, "a finite best: {}", s.cost_after);
    assert_eq!(s.history.len(), 2);
}

#[test]
fn study_bounds_outside_the_declared_range_and_connected_inputs_are_refused() {
    common::fmu_dir();
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (
            "vehicle.tyre_D",
            "0.0",
            "0.3",
            "the bounds [0, 0.3] of 'vehicle.tyre_D' leave its declared range [0.05, 3]",
        ),
        (
            "vehicle.brake_pedal",
            "0.0",
            "1.0",
            "'vehicle.brake_pedal' is an input connected to driver.brake_pedal",
        ),
    ];
    for (name, min, max, expected) in cases {
        let body = format!(
            "[[step]]\nname = \"s\"\nsignals = [\"Fz_sum\"]\n[[step.parameter]]\nname = \"{name}\"\nmin = {min}\nmax = {max}\n"
        );
        let study = load(dir.path(), &study_text("ga", &body));
        let e = run_study(&study, &options(1, &dir.path().join("cp.json")))
            .err()
            .unwrap();
        assert!(matches!(e, OptimizeError::File { .. }), "{name}: {e}");
        let e = e.to_string();
        assert!(e.contains(expected), "{name}: {e}");
    }
}

/// An observer of a caller's own: each generation's step and workers, and the result.
#[derive(Default)]
struct Watcher {
    seen: std::sync::Mutex<Vec<(usize, Option<usize>)>>,
    finished: std::sync::Mutex<usize>,
}

impl tb_optimize::StudyObserver for Watcher {
    fn generation(&self, g: &tb_optimize::GenerationDone<'_>) -> std::ops::ControlFlow<()> {
        self.seen.lock().unwrap().push((g.step, g.workers));
        std::ops::ControlFlow::Continue(())
    }
    fn finished(&self, _result: &StudyResult) -> Result<(), tb_optimize::ObserverError> {
        *self.finished.lock().unwrap() += 1;
        Ok(())
    }
}

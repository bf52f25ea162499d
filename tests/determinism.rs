//! A candidate's result depends on the candidate only: the same values on a fresh worker
//! and on a worker that has run other candidates before give the same bits. (An optimiser
//! spreads candidates over workers in any order; a resumed study starts on fresh workers.)

mod common;

use std::sync::Arc;
use tb_fmi::FmuCache;
use tb_optimize::Study;
use tb_optimize::WorkerPool;

fn columns_bits(t: &tb_table::Table) -> Vec<Vec<u64>> {
    t.columns()
        .iter()
        .map(|c| c.iter().map(|x| x.to_bits()).collect())
        .collect()
}

#[test]
fn a_candidate_gives_the_same_bits_on_a_fresh_and_on_a_used_worker() {
    common::fmu_dir();
    let study =
        Study::load(&twinbench::pack::workspace_root().join("studies/spielberg.toml")).unwrap();
    let prepared = tb_compare::PreparedMeasurement::from_path(
        &study.measurement_path,
        &["Fz_sum", "Fz_rl"],
        &study.file.compare,
    )
    .unwrap();
    let fresh_bench =
        WorkerPool::new(&study, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    let x: Vec<f64> = fresh_bench.assignment().iter().map(|a| a.1).collect();
    let fresh = fresh_bench.run(&x, &prepared).unwrap();
    // Another bench's only worker runs 50 other candidates first (spread over the study's
    // bounds, as an optimiser's would be, and some that fail).
    let used_bench =
        WorkerPool::new(&study, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    for k in 0..50 {
        let mut other = x.clone();
        for (i, v) in other.iter_mut().enumerate() {
            *v *= 1.0 + 0.03 * ((k + i) % 5) as f64 - 0.06;
        }
        let _ = used_bench.run(&other, &prepared);
    }
    let used = used_bench.run(&x, &prepared).unwrap();
    assert_eq!(used_bench.workers_created(), 1, "one worker ran everything");
    let (a, b) = (columns_bits(&fresh.table), columns_bits(&used.table));
    assert_eq!(a.len(), b.len());
    for (k, (ca, cb)) in a.iter().zip(&b).enumerate() {
        if let Some(i) = ca.iter().zip(cb).position(|(p, q)| p != q) {
            panic!(
                "{} differs at row {i}: {} (fresh worker) vs {} (used worker)",
                fresh.table.names()[k],
                f64::from_bits(ca[i]),
                f64::from_bits(cb[i])
            );
        }
    }
    let (ea, eb) = (
        fresh.comparison.get("Fz_sum").unwrap().e,
        used.comparison.get("Fz_sum").unwrap().e,
    );
    assert_eq!(ea.to_bits(), eb.to_bits());
}

/// The worker side of a distributed study: a cost computed by a worker process's
/// `StudyEvaluator` after 50 other candidates equals a fresh one's and the local bench's.
#[test]
fn a_remote_workers_cost_does_not_depend_on_what_it_ran_before() {
    use tb_optimize::{Candidate, StepCost, StudyEvaluator};
    common::fmu_dir();
    let path = twinbench::pack::workspace_root().join("studies/spielberg.toml");
    let fresh = StudyEvaluator::load(&path).unwrap();
    let x: Vec<f64> = fresh.workers().assignment().iter().map(|a| a.1).collect();
    let candidate = Candidate {
        step: 1,
        values: x.clone(),
    };
    let first = fresh.cost(&candidate).unwrap();
    let used = StudyEvaluator::load(&path).unwrap();
    for k in 0..50 {
        let values = x
            .iter()
            .enumerate()
            .map(|(i, v)| v * (1.0 + 0.01 * ((3 * k + i) % 7) as f64 - 0.03))
            .collect();
        let _ = used.cost(&Candidate {
            step: k % 2,
            values,
        });
    }
    let after = used.cost(&candidate).unwrap();
    assert_eq!(first.to_bits(), after.to_bits(), "{first} vs {after}");
    // And the coordinator's own evaluation of the same candidate.
    let study = fresh.study();
    let cost = StepCost::of_step(study, 1).unwrap();
    let prepared = tb_compare::PreparedMeasurement::from_path(
        &study.measurement_path,
        &cost.signals,
        &study.file.compare,
    )
    .unwrap();
    let bench = WorkerPool::new(study, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    let local = cost.of(&bench, &x, &prepared).unwrap();
    assert_eq!(first.to_bits(), local.to_bits(), "{first} vs {local}");
    // A worker with other files refuses, naming the file.
    let mut other = fresh.digest().clone();
    other.files[1].1 = "0".repeat(64);
    let why = fresh.digest().mismatch(&other).unwrap();
    assert!(why.contains("spielberg_lap.csv"), "{why}");
}

//! A candidate's result depends on the candidate only: the same values on a fresh worker
//! and on a worker that has run other candidates before give the same bits. (An optimiser
//! spreads candidates over workers in any order; a resumed study starts on fresh workers.)

mod common;

use std::sync::Arc;
use tb_fmi::FmuCache;
use tb_optimize::bench::Bench;
use tb_optimize::Study;

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
    let fresh_bench = Bench::new(&study, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    let x: Vec<f64> = fresh_bench.assignment().iter().map(|a| a.1).collect();
    let fresh = fresh_bench.run(&x, &prepared).unwrap();
    // Another bench's only worker runs other candidates first.
    let used_bench = Bench::new(&study, Arc::new(FmuCache::temporary(false).unwrap())).unwrap();
    for k in 0..6 {
        let mut other = x.clone();
        for (i, v) in other.iter_mut().enumerate() {
            *v *= 1.0 + 0.03 * ((k + i) % 3) as f64 - 0.02;
        }
        used_bench.run(&other, &prepared).unwrap();
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

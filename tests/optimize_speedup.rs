//! The slow tier (`--features slow-tests`; `cargo test --release --features slow-tests --test
//! optimize_speedup -- --nocapture` prints the figures): the same 16 full-lap candidates evaluated through the study's parallel
//! path with 1 and with 2 threads; prints laps per second and the speedup, and checks that
//! the costs are bitwise the same.

mod common;

use std::time::Instant;
use tb_fmi::FmuCache;
use tb_optimize::driver::cost_of;
use tb_optimize::optimizer::{evaluate_all, thread_pool};
use tb_optimize::WorkerPool;
use tb_optimize::{Problem, Study};

struct Lift<'a> {
    bench: &'a WorkerPool,
    prepared: &'a tb_compare::PreparedMeasurement,
    /// Summed CPU time of the evaluating threads [s].
    cpu: std::sync::Mutex<f64>,
}

fn thread_cpu_seconds() -> f64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    ts.tv_sec as f64 + ts.tv_nsec as f64 * 1e-9
}

impl Problem for Lift<'_> {
    fn bounds(&self) -> Vec<(f64, f64)> {
        vec![(0.2, 2.5); 2]
    }
    fn evaluate(&self, x: &[f64]) -> Result<f64, tb_optimize::RunError> {
        // Every parameter of the study at its initial value, the lift coefficients at x.
        let mut p: Vec<f64> = self.bench.assignment().iter().map(|a| a.1).collect();
        p[self.bench.index_of("vehicle.c_lift_front").unwrap()] = x[0];
        p[self.bench.index_of("vehicle.c_lift_rear").unwrap()] = x[1];
        let c0 = thread_cpu_seconds();
        let o = self.bench.run(&p, self.prepared);
        *self.cpu.lock().unwrap() += thread_cpu_seconds() - c0;
        let o = o?;
        let s = ["Fz_front".to_string(), "Fz_rear".to_string()];
        Ok(cost_of(&o.comparison, &s, &[1.0, 1.0], 1.0))
    }
}

#[test]
fn speedup_from_1_to_2_threads() {
    common::fmu_dir();
    let root = twinbench::pack::workspace_root();
    let study = Study::load(&root.join("studies/spielberg.toml")).unwrap();
    let cache = std::sync::Arc::new(FmuCache::temporary(false).unwrap());
    let bench = WorkerPool::new(&study, cache).unwrap();
    let prepared = tb_compare::PreparedMeasurement::from_path(
        &study.measurement_path,
        &["Fz_front", "Fz_rear"],
        &study.file.compare,
    )
    .unwrap();
    let problem = Lift {
        bench: &bench,
        prepared: &prepared,
        cpu: std::sync::Mutex::new(0.0),
    };
    let xs: Vec<Vec<f64>> = (0..16)
        .map(|k| vec![0.6 + 0.05 * k as f64, 0.8 + 0.04 * k as f64])
        .collect();
    // Warm-up: both workers exist and have run once.
    let pool2 = thread_pool(2).unwrap();
    evaluate_all(&pool2, &problem, &xs[..2]);
    let mut results = Vec::new();
    let mut walls = Vec::new();
    for threads in [1, 2] {
        let pool = thread_pool(threads).unwrap();
        *problem.cpu.lock().unwrap() = 0.0;
        let t = Instant::now();
        let r = evaluate_all(&pool, &problem, &xs);
        let wall = t.elapsed().as_secs_f64();
        let cpu = *problem.cpu.lock().unwrap();
        eprintln!(
            "{threads} thread(s): {} laps in {wall:.2} s = {:.2} laps/s; CPU {:.3} s per lap; \
             the threads were on a core {:.0} % of the wall time",
            xs.len(),
            xs.len() as f64 / wall,
            cpu / xs.len() as f64,
            100.0 * cpu / (threads as f64 * wall)
        );
        results.push(r);
        walls.push(wall);
    }
    eprintln!("speedup 1 -> 2 threads: {:.2}", walls[0] / walls[1]);
    let bits = |r: &Vec<Result<f64, tb_optimize::RunError>>| -> Vec<u64> {
        r.iter().map(|c| c.as_ref().unwrap().to_bits()).collect()
    };
    assert_eq!(bits(&results[0]), bits(&results[1]));
    assert!(bench.workers_created() <= 2);
}

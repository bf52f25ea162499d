//! Long runs: many consecutive simulations with instance reuse in one process keep their
//! resident memory bounded and leave no temporary folders; result files are never seen
//! half-written.
//!
//! The full soak (laps of Spielberg) is not in the default suite:
//!
//! ```sh
//! SOAK_LAPS=10000 cargo test --release --test robustness_long -- --ignored --nocapture soak
//! ```

mod common;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;
use tb_cosim::{Plan, Simulation, StopConfig, SystemFile, Table};
use tb_fmi::FmuCache;

/// Resident set size of this process [kB] (VmRSS).
fn rss_kb() -> u64 {
    let s = std::fs::read_to_string("/proc/self/status").unwrap();
    s.lines()
        .find_map(|l| l.strip_prefix("VmRSS:"))
        .and_then(|v| v.split_whitespace().next())
        .and_then(|v| v.parse().ok())
        .expect("VmRSS in /proc/self/status")
}

/// Folders of this process's unpack caches in the temporary folder.
fn cache_dirs() -> Vec<PathBuf> {
    let mine = format!("twinbench-fmu-{}-", std::process::id());
    let mut v: Vec<PathBuf> = std::fs::read_dir(std::env::temp_dir())
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| {
            p.file_name()
                .is_some_and(|n| n.to_string_lossy().starts_with(&mine))
                && p.is_dir()
        })
        .collect();
    v.sort();
    v
}

fn lap_simulation(stop: Option<f64>) -> Simulation {
    common::fmu_dir();
    let path = twinbench::pack::workspace_root().join("systems/rls_v.toml");
    let mut file = SystemFile::load(&path).unwrap();
    if let Some(t) = stop {
        file.experiment.stop = StopConfig::Time(t);
    }
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let mut sim = Simulation::new(Plan::from_file(file, &path, cache).unwrap()).unwrap();
    sim.echo_fmu_log = false;
    sim
}

/// Runs `n` simulations (a parameter nudged each time, as an optimiser does) and returns
/// the RSS after the warm-up run and after the last one [kB], and the seconds per run.
fn repeated_runs(sim: &mut Simulation, n: usize, report_every: usize) -> (u64, u64, f64) {
    let c0 = sim.parameter("vehicle.c_lift_front").unwrap_or(0.0);
    let mut warm = 0;
    let t0 = Instant::now();
    for k in 0..n {
        let nudge = 1.0 + 0.01 * ((k % 7) as f64 - 3.0);
        sim.set_parameter("vehicle.c_lift_front", toml::Value::Float(c0 * nudge))
            .unwrap();
        sim.run().unwrap();
        if k == 0 {
            warm = rss_kb();
        }
        if report_every > 0 && (k + 1) % report_every == 0 {
            println!(
                "run {:>6}: RSS {:>7} kB ({:+} kB since run 1), {:.3} s per run",
                k + 1,
                rss_kb(),
                rss_kb() as i64 - warm as i64,
                t0.elapsed().as_secs_f64() / (k + 1) as f64
            );
        }
    }
    (warm, rss_kb(), t0.elapsed().as_secs_f64() / n as f64)
}

#[test]
fn thirty_reused_runs_keep_memory_bounded_and_leave_no_temporary_folders() {
    let before = cache_dirs();
    {
        let mut sim = lap_simulation(Some(10.0));
        let (warm, end, per_run) = repeated_runs(&mut sim, 30, 0);
        let growth = end as i64 - warm as i64;
        println!("30 runs of 10 s: RSS {warm} -> {end} kB ({growth:+} kB), {per_run:.3} s per run");
        assert!(growth < 2048, "RSS grew by {growth} kB over 30 runs");
        // One cache folder while the simulation lives, not one per run.
        let during = cache_dirs();
        assert!(during.len() <= before.len() + 1, "{during:?}");
    }
    let after = cache_dirs();
    let left: Vec<_> = after.iter().filter(|p| !before.contains(p)).collect();
    assert!(left.is_empty(), "temporary folders left: {left:?}");
}

/// The soak: `SOAK_LAPS` (default 1000) laps of Spielberg with instance reuse.
#[test]
#[ignore = "long: run with SOAK_LAPS=N ... -- --ignored soak"]
fn soak_laps() {
    let n: usize = std::env::var("SOAK_LAPS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(1000);
    let before = cache_dirs();
    {
        let mut sim = lap_simulation(None);
        let (warm, end, per_run) = repeated_runs(&mut sim, n, (n / 20).max(1));
        let growth = end as i64 - warm as i64;
        println!(
            "SOAK {n} laps: RSS after lap 1 {warm} kB, after lap {n} {end} kB, growth {growth:+} kB, {per_run:.3} s per lap"
        );
        assert!(growth < 10 * 1024, "RSS grew by {growth} kB");
    }
    let left: Vec<_> = cache_dirs()
        .into_iter()
        .filter(|p| !before.contains(p))
        .collect();
    assert!(left.is_empty(), "temporary folders left: {left:?}");
}

// ---- output files ----

fn big_recording(rows: usize, value: f64) -> Table {
    let names: Vec<String> = (0..20).map(|k| format!("unit.signal_{k}")).collect();
    let mut r = Table::new(
        "big",
        std::iter::once("time".to_string()).chain(names).collect(),
        vec!["s".to_string(); 21],
    )
    .unwrap();
    for i in 0..rows {
        r.push_row(std::iter::once(i as f64).chain((1..21).map(|c| value + c as f64)));
    }
    r
}

/// A complete file: header, units row, `rows` rows of 21 fields.
fn is_complete(text: &str, rows: usize) -> bool {
    let lines: Vec<&str> = text.lines().collect();
    text.ends_with('\n')
        && lines.len() == rows + 2
        && lines.iter().all(|l| l.split(',').count() == 21)
}

fn temp_siblings(dir: &Path) -> Vec<PathBuf> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.file_name().unwrap().to_string_lossy().contains(".tmp"))
        .collect()
}

#[test]
fn a_reader_never_sees_a_half_written_result_file() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("lap.csv");
    let rows = 20_000; // about 3 MB: many write calls per file
    big_recording(rows, 0.0).write_csv(&out).unwrap();
    let stop = Arc::new(std::sync::atomic::AtomicBool::new(false));
    let reader = {
        let (out, stop) = (out.clone(), stop.clone());
        std::thread::spawn(move || {
            let mut reads = 0;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let text = std::fs::read_to_string(&out).unwrap();
                assert!(is_complete(&text, rows), "a partial file was seen");
                reads += 1;
            }
            reads
        })
    };
    for k in 0..15 {
        big_recording(rows, k as f64).write_csv(&out).unwrap();
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let reads = reader.join().unwrap();
    assert!(reads > 0);
    assert_eq!(temp_siblings(dir.path()), Vec::<PathBuf>::new());
}

/// The bundled bench recording every output at every step (a result file of about 40 MB,
/// so that writing it takes long enough to be caught), with absolute FMU paths.
fn big_output_system(dir: &Path) -> PathBuf {
    let fmu_dir = common::fmu_dir();
    let root = twinbench::pack::workspace_root();
    let text = std::fs::read_to_string(root.join("systems/rls_v.toml"))
        .unwrap()
        .replace("\"../target/fmu/", &format!("\"{}/", fmu_dir.display()))
        .replace("decimation = 5", "decimation = 1");
    let p = dir.join("big_output.toml");
    std::fs::write(&p, text).unwrap();
    p
}

fn twinbench_run(system: &Path, out: &Path, tmp: &Path) -> std::process::Child {
    std::process::Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args([
            "run",
            system.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        // The child's unpack cache goes to the test's scratch folder (removed with it).
        .env("TMPDIR", tmp)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap()
}

#[test]
fn a_run_killed_while_writing_its_result_leaves_no_partial_file() {
    // The kill is proven to land during the write: the process is frozen (SIGSTOP) the
    // moment its temporary file appears, seen to be mid-write (temporary present, result
    // absent), and only then killed. A run that finished its write before the freeze is
    // not a landing; at most 5 runs are tried.
    common::fmu_dir();
    let dir = tb_testkit::scratch("killed-write");
    let system = big_output_system(dir.path());
    let out_dir = dir.path().join("out");
    std::fs::create_dir_all(&out_dir).unwrap();
    let tmp = dir.path().join("tmp");
    std::fs::create_dir_all(&tmp).unwrap();
    let mut landed = false;
    for attempt in 0..5 {
        let out = out_dir.join(format!("lap{attempt}.csv"));
        let mut child = twinbench_run(&system, &out, &tmp);
        let pid = child.id() as libc::pid_t;
        let mut frozen_mid_write = false;
        let deadline = Instant::now() + std::time::Duration::from_secs(60);
        loop {
            if child.try_wait().unwrap().is_some() || Instant::now() > deadline {
                break;
            }
            if !temp_siblings(&out_dir).is_empty() {
                unsafe { libc::kill(pid, libc::SIGSTOP) };
                frozen_mid_write = !temp_siblings(&out_dir).is_empty() && !out.exists();
                break;
            }
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
        let _ = child.kill();
        let _ = child.wait();
        if out.exists() {
            let text = std::fs::read_to_string(&out).unwrap();
            let rows = text.lines().count();
            assert!(
                text.ends_with('\n') && rows > 90_000,
                "partial: {rows} lines"
            );
        }
        if frozen_mid_write {
            assert!(
                !out.exists(),
                "attempt {attempt}: a result appeared after the kill"
            );
            landed = true;
            break;
        }
    }
    assert!(landed, "no kill landed during the write in 5 runs");
}

#[test]
fn a_completed_run_leaves_its_result_and_no_temporary_file() {
    common::fmu_dir();
    let system = twinbench::pack::workspace_root().join("systems/rls_v.toml");
    let dir = tb_testkit::scratch("completed-write");
    let out = dir.path().join("done.csv");
    let st = std::process::Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args([
            "run",
            system.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ])
        .env("TMPDIR", dir.path())
        .stdout(std::process::Stdio::null())
        .status()
        .unwrap();
    assert!(st.success());
    assert!(out.exists());
    assert_eq!(temp_siblings(dir.path()), Vec::<PathBuf>::new());
}

#[test]
fn caches_left_by_killed_processes_are_removed_by_the_next_one_and_live_ones_kept() {
    use std::os::fd::AsRawFd;
    let tmp = std::env::temp_dir();
    let lock = |name: &str| -> std::fs::File {
        let f = std::fs::File::create(tmp.join(format!("{name}.lock"))).unwrap();
        f
    };
    // Abandoned: its lock file is not locked (the owner ended); the pid is this process's
    // own, so a pid lookup would have kept it.
    let dead = format!("twinbench-fmu-{}-dead-1", std::process::id());
    std::fs::create_dir_all(tmp.join(&dead).join("x/binaries")).unwrap();
    drop(lock(&dead));
    // Alive: its lock is held (by this test, standing for another process, e.g. in another
    // PID namespace with a pid that does not exist here).
    let alive = "twinbench-fmu-99999999-alive-1";
    std::fs::create_dir_all(tmp.join(alive)).unwrap();
    let held = lock(alive);
    assert_eq!(
        unsafe { libc::flock(held.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) },
        0
    );
    let _cache = FmuCache::temporary(false).unwrap();
    assert!(!tmp.join(&dead).exists(), "the abandoned cache is removed");
    assert!(!tmp.join(format!("{dead}.lock")).exists());
    assert!(tmp.join(alive).exists(), "a live cache is kept");
    drop(held);
    let _ = std::fs::remove_dir_all(tmp.join(alive));
    let _ = std::fs::remove_file(tmp.join(format!("{alive}.lock")));
}

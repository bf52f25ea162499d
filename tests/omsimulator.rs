//! OMSimulator 3.0 (built from source by tools/omsimulator.sh; its path in
//! TWINBENCH_OMSIMULATOR) as a host of our FMUs: each FMU alone with its default settings,
//! and the exported bench SSP over a lap, compared with twinbench's Jacobi run.

mod common;

use common::run_omsimulator;
use std::path::Path;

/// The last row of an OMSimulator CSV result: the column named `name`.
fn last_value(csv: &Path, name: &str) -> f64 {
    use std::io::BufRead;
    let f = std::io::BufReader::new(std::fs::File::open(csv).unwrap());
    let mut lines = f.lines();
    let header: Vec<String> = lines
        .next()
        .unwrap()
        .unwrap()
        .split(',')
        .map(|s| s.trim().trim_matches('"').to_string())
        .collect();
    let k = header
        .iter()
        .position(|h| h == name || h.ends_with(&format!(".{name}")))
        .unwrap_or_else(|| panic!("no column {name} in {}", csv.display()));
    let last = lines
        .map(|l| l.unwrap())
        .filter(|l| !l.is_empty())
        .last()
        .unwrap();
    last.split(',').nth(k).unwrap().trim().parse().unwrap()
}

/// Each FMU alone, as a user opens it first: OMSimulator's defaults (co-simulation, 1 s),
/// no error, every value finite, the run reaching its stop time.
#[test]
fn omsimulator_runs_each_fmu_alone() {
    let dir = tb_testkit::scratch("oms-alone");
    let shipped = twinbench::pack::models()
        .into_iter()
        .filter(|s| !s.test_only);
    for model in shipped.map(|s| s.info.name) {
        let out = dir.path().join(format!("{model}.csv"));
        run_omsimulator(
            dir.path(),
            args![
                common::fmu(model),
                "--mode=cs",
                "--stopTime=1",
                format!("--resultFile={}", out.display()),
            ],
        );
        let text = std::fs::read_to_string(&out).unwrap();
        let last = text.lines().rfind(|l| !l.is_empty()).unwrap();
        let values: Vec<f64> = last.split(',').map(|x| x.trim().parse().unwrap()).collect();
        assert_eq!(values[0], 1.0, "{model}: ends at 1 s");
        assert!(values.iter().all(|x| x.is_finite()), "{model}: {last}");
    }
}

/// The exported bench with OMSimulator's default settings: it initialises (the declared
/// dependencies leave no algebraic loop) and drives the lap; the lap time agrees with
/// twinbench's Jacobi run within 10 ms (the difference: OMSimulator passes each output to
/// its input in the connections' dependency order after the step, so the EDU's torques see
/// the dyno's new speeds through their declared feed-through in the same step; twinbench's
/// Jacobi master gives each unit the values of the step's start).
#[test]
fn omsimulator_runs_the_exported_bench_lap() {
    let root = twinbench::pack::workspace_root();
    common::fmu_dir();
    let dir = tb_testkit::scratch("oms-lap");
    let ssp = dir.path().join("rls_v.ssp");
    common::run_ok(args![
        "export-ssp",
        root.join("systems/rls_v.toml"),
        "-o",
        ssp,
        "--stop-time",
        "99"
    ]);
    let out = dir.path().join("lap.csv");
    run_omsimulator(
        dir.path(),
        args![
            ssp,
            "--stopTime=99",
            format!("--resultFile={}", out.display()),
        ],
    );
    let oms_lap = last_value(&out, "vehicle.lap_time");
    std::fs::remove_file(&out).unwrap(); // 190 MB
                                         // twinbench, Jacobi, the same system.
    let s = common::run_bench(&dir.path().join("jacobi.toml"), |text| {
        text.replace("algorithm = \"gauss-seidel\"", "algorithm = \"jacobi\"")
    })
    .unwrap();
    let ours = s.value("vehicle.lap_time").unwrap();
    eprintln!("lap time: OMSimulator {oms_lap} s, twinbench Jacobi {ours} s");
    assert!(
        (oms_lap - ours).abs() < 0.010,
        "OMSimulator {oms_lap} s, twinbench Jacobi {ours} s"
    );
}

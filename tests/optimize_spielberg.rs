//! Acceptance of issue 5 on the bundled Spielberg lap with the whole co-simulated RLS/v
//! bench in the loop (studies/spielberg.toml, CMA-ES, about 370 full laps: ~2 min on 2 cores).
//!
//! - step 1 (lift coefficients on Fz_front, Fz_rear, Fz_sum): c_lift_front and c_lift_rear
//!   within 5 % of the truth (data/spielberg_lap_truth.json);
//! - step 2 (l, b_front, b_rear on the four wheel loads): b_front, b_rear within 5 % of
//!   b_front_effective, b_rear_effective; the wheelbase is reported (a virtual one);
//! - e lower after than before for every validation signal of each step;
//! - the identifiability check: Fz_sum alone sees only c_lift_front + c_lift_rear (the split
//!   is flagged, direction (1, −1) within 0.05), the step's signals together see both.

mod common;

use tb_optimize::{run_study, RunOptions, Study, StudyOutcome};

#[test]
fn spielberg_two_step_study_recovers_the_truth() {
    common::fmu_dir();
    let root = twinbench::pack::workspace_root();
    let truth: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(root.join("data/spielberg_lap_truth.json")).unwrap(),
    )
    .unwrap();
    let t = |k: &str| truth["truth"][k].as_f64().unwrap();
    let study = Study::load(&root.join("studies/spielberg.toml")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let options = RunOptions {
        threads: 0,
        checkpoint: Some(dir.path().join("cp.json")),
        ..RunOptions::default()
    };
    let r = match run_study(&study, &options).unwrap() {
        StudyOutcome::Finished(r) => r,
        StudyOutcome::Interrupted { .. } => unreachable!(),
    };
    let v = |k: &str| r.final_value(k).unwrap();
    let rel = |a: f64, b: f64| (a / b - 1.0).abs();
    eprintln!(
        "c_lift_front {:.4} (truth {}), c_lift_rear {:.4} (truth {}), l {:.4} (l_effective {}), \
         b_front {:.4} (effective {}), b_rear {:.4} (effective {}); {} laps in {:.1} s on {} threads",
        v("vehicle.c_lift_front"),
        t("c_lift_front"),
        v("vehicle.c_lift_rear"),
        t("c_lift_rear"),
        v("vehicle.l"),
        t("l_effective"),
        v("vehicle.b_front"),
        t("b_front_effective"),
        v("vehicle.b_rear"),
        t("b_rear_effective"),
        r.simulations,
        r.wall_seconds,
        r.threads
    );
    for s in &r.steps {
        for e in &s.e {
            eprintln!(
                "step {} {}: e {:.4} -> {:.4}, bias {:+.2} % -> {:+.2} %",
                s.step,
                e.signal,
                e.before.e,
                e.after.e,
                100.0 * e.before.bias,
                100.0 * e.after.bias
            );
            assert!(
                e.after.e < e.before.e,
                "step {}: e of {} did not fall",
                s.step,
                e.signal
            );
        }
    }
    assert!(rel(v("vehicle.c_lift_front"), t("c_lift_front")) < 0.05);
    assert!(rel(v("vehicle.c_lift_rear"), t("c_lift_rear")) < 0.05);
    assert!(rel(v("vehicle.b_front"), t("b_front_effective")) < 0.05);
    assert!(rel(v("vehicle.b_rear"), t("b_rear_effective")) < 0.05);
    assert!((2.0..4.5).contains(&v("vehicle.l")));

    // The joint intervals (docs/optimize.md, "How sure the parameters are"): each
    // parameter has one around its value; the lift coefficients' are narrow (within ±3 %),
    // the wheelbase's is the widest relative to its value, and c_lift_front's, b_front's and
    // b_rear's contain the truth (c_lift_rear misses it by a systematic error of the twin's
    // driving that no interval from the data's scatter shows: the docs say so).
    assert!(r.steps.iter().all(|s| s.intervals.is_some()));
    let interval = |name: &str| {
        r.joint_intervals
            .as_ref()
            .unwrap()
            .get(name)
            .unwrap()
            .clone()
    };
    let half = |name: &str| {
        let p = interval(name);
        eprintln!(
            "{name}: {:?} [{:?}, {:?}] {:?}",
            p.value, p.lo, p.hi, p.statement
        );
        1.959_963_984_540_054 * p.std_error.unwrap() / p.value
    };
    for n in ["vehicle.c_lift_front", "vehicle.c_lift_rear"] {
        assert!(half(n) < 0.03, "{n}: ±{}", half(n));
    }
    assert!(half("vehicle.l") > 2.0 * half("vehicle.b_front"));
    assert!(half("vehicle.l") > 2.0 * half("vehicle.b_rear"));
    for (n, k) in [
        ("vehicle.c_lift_front", "c_lift_front"),
        ("vehicle.b_front", "b_front_effective"),
        ("vehicle.b_rear", "b_rear_effective"),
    ] {
        let p = interval(n);
        assert!(
            p.lo.unwrap() <= t(k) && t(k) <= p.hi.unwrap(),
            "{n}: truth {} outside {p:?}",
            t(k)
        );
    }

    // Identifiability of step 1.
    let id = &r.steps[0].identifiability;
    assert!(id.combined.unseen.is_empty(), "{:?}", id.report_lines());
    let sum = id
        .per_signal
        .iter()
        .find(|c| c.signals == ["Fz_sum"])
        .unwrap();
    assert_eq!(sum.unseen.len(), 1, "{:?}", id.report_lines());
    let c = &sum.unseen[0].coefficients;
    assert!(
        (c[0] - 1.0).abs() < 0.05 && (c[1] + 1.0).abs() < 0.05,
        "{c:?}"
    );
    let c = &sum.visible[0].coefficients;
    assert!(
        (c[0] - 1.0).abs() < 0.05 && (c[1] - 1.0).abs() < 0.05,
        "{c:?}"
    );
    assert!(id
        .report_lines()
        .iter()
        .any(|l| l.contains("Fz_sum: sees only")));
}

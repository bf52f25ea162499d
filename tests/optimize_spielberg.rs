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
    assert!(rel(v("vehicle.c_lift_front"), t("c_lift_front")) < 0.02);
    assert!(rel(v("vehicle.c_lift_rear"), t("c_lift_rear")) < 0.03);
    assert!(rel(v("vehicle.b_front"), t("b_front_effective")) < 0.05);
    assert!(rel(v("vehicle.b_rear"), t("b_rear_effective")) < 0.05);
    assert!((2.0..4.5).contains(&v("vehicle.l")));

    // The study's answer (docs/optimize.md, "How sure the parameters are"): all five
    // parameters refined together, each with a closed 95 % interval around its value; the
    // lift coefficients' narrow (within ±2 %), the wheelbase's the widest relative to its
    // value. On this lap the steps' own answer for l (e + |bias|, flat in l) lies outside
    // the least-squares interval, and the result says so: the twin's first-order chassis
    // and driving differ from the car's (the docs show why the truths miss).
    let joint = r.joint.as_ref().expect("the joint answer");
    assert!(joint.refinement.as_ref().is_some_and(|f| f.converged));
    let half = |name: &str| {
        let p = joint.parameters.iter().find(|p| p.name == name).unwrap();
        eprintln!(
            "{name}: {:.4} {:?} {:?}",
            p.after, p.interval, p.interval_statement
        );
        let (lo, hi) = p.interval.expect("an interval");
        let (lo, hi) = (lo.unwrap(), hi.unwrap());
        assert!(lo < p.after && p.after < hi, "{p:?}");
        assert_eq!(v(name), p.after, "the answer is the final value");
        (hi - lo) / 2.0 / p.after
    };
    for n in ["vehicle.c_lift_front", "vehicle.c_lift_rear"] {
        assert!(half(n) < 0.02, "{n}: ±{}", half(n));
    }
    for n in [
        "vehicle.c_lift_front",
        "vehicle.c_lift_rear",
        "vehicle.b_front",
    ] {
        assert!(
            half("vehicle.l") > half(n),
            "l ±{} against {n}",
            half("vehicle.l")
        );
    }
    let l = joint
        .parameters
        .iter()
        .find(|p| p.name == "vehicle.l")
        .unwrap();
    // The bundled lap's car is not the twin (a sprung chassis, an effective wheelbase of
    // 3.41 m): the model check says so, and l's interval with the model's share holds the
    // effective value and is wider than the scatter interval.
    let check = joint.model_check.as_ref().expect("a model check");
    assert!(check.discrepancy && check.p_value < 0.05, "{check:?}");
    assert!(
        check.detail.contains("the twin cannot represent this lap"),
        "{check:?}"
    );
    let (lo, hi) = l
        .interval_with_model
        .expect("an interval with the model's share");
    let (lo, hi) = (lo.expect("closed below"), hi.expect("closed above"));
    assert!(lo <= 3.41 && 3.41 <= hi, "{l:?}");
    let (slo, shi) = l.interval.unwrap();
    assert!(hi - lo > shi.unwrap() - slo.unwrap(), "{l:?}");

    // Identifiability of step 1.
    let id = &r.steps[0].identifiability;
    assert!(id.combined.unseen.is_empty(), "{:?}", id.report_lines());
    let sum = id
        .per_signal
        .iter()
        .find(|c| c.signals == ["Fz_sum"])
        .unwrap();
    assert_eq!(sum.unseen.len(), 1, "{:?}", id.report_lines());
    // Δc_lift_front − Δc_lift_rear, up to the eigenvector's sign.
    let c = &sum.unseen[0].coefficients;
    assert!(
        (c[0].abs() - 1.0).abs() < 0.05 && (c[1] + c[0]).abs() < 0.05,
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

//! Modal analysis against closed-form results.

use tb_analysis::chain::{Chain, Inertia, Spring};
use tb_analysis::modal::{self, ModeKind};
use tb_analysis::AnalysisError;

fn chain(js: &[f64], cs: &[f64], left: Option<f64>, right: Option<f64>) -> Chain {
    let spring = |name: String, c: f64| Spring {
        name,
        stiffness: c,
        damping: 0.0,
    };
    Chain {
        name: "test".into(),
        description: None,
        inertias: js
            .iter()
            .enumerate()
            .map(|(k, &j)| Inertia {
                name: format!("J{}", k + 1),
                inertia: j,
                damping: 0.0,
            })
            .collect(),
        springs: cs
            .iter()
            .enumerate()
            .map(|(k, &c)| spring(format!("c{}", k + 1), c))
            .collect(),
        ground_left: left.map(|c| spring("c0".into(), c)),
        ground_right: right.map(|c| spring("cn".into(), c)),
    }
}

/// Roots of a λ² + b λ + c = 0 (both real, positive), computed without cancellation.
fn quadratic(a: f64, b: f64, c: f64) -> (f64, f64) {
    let disc = (b * b - 4.0 * a * c).sqrt();
    let q = -0.5 * (b + b.signum() * disc);
    let (r1, r2) = (q / a, c / q);
    (r1.min(r2), r1.max(r2))
}

fn assert_rel(got: f64, want: f64, tol: f64, what: &str) {
    let rel = ((got - want) / want).abs();
    assert!(
        rel <= tol,
        "{what}: got {got}, want {want}, relative error {rel:e}"
    );
}

fn check_invariants(r: &modal::ModalResult, js: &[f64]) {
    for m in &r.modes {
        let s: f64 = m.mass_sensitivity.iter().sum();
        assert!((s - 1.0).abs() < 1e-12, "mode {} μ sum {s}", m.number);
        if let Some(g) = &m.stiffness_sensitivity {
            let s: f64 = g.iter().sum();
            assert!((s - 1.0).abs() < 1e-12, "mode {} γ sum {s}", m.number);
        }
        let max = m.shape.iter().fold(0.0_f64, |a, v| a.max(v.abs()));
        assert!((max - 1.0).abs() < 1e-15);
    }
    // M-orthogonality: v_iᵀ M v_j = 0 for i ≠ j (normalised by √(μ_i μ_j))
    for a in &r.modes {
        for b in &r.modes {
            if a.number == b.number {
                continue;
            }
            let p: f64 = (0..js.len()).map(|k| a.shape[k] * js[k] * b.shape[k]).sum();
            let p = p / (a.modal_mass * b.modal_mass).sqrt();
            assert!(
                p.abs() < 1e-12,
                "modes {} and {}: {p:e}",
                a.number,
                b.number
            );
        }
    }
}

#[test]
fn two_mass_free_free() {
    let (j1, j2, c) = (1.595, 0.8, 9000.0);
    let r = modal::analyse(&chain(&[j1, j2], &[c], None, None)).unwrap();
    assert_eq!(r.modes.len(), 2);
    assert_eq!(r.modes[0].kind, ModeKind::RigidBody);
    assert_eq!(r.modes[0].omega0, 0.0);
    assert!(r.modes[0].stiffness_sensitivity.is_none());
    assert_eq!(r.modes[1].kind, ModeKind::Elastic);
    assert_rel(
        r.modes[1].omega0,
        (c * (1.0 / j1 + 1.0 / j2)).sqrt(),
        1e-9,
        "ω",
    );
    // rigid mode's mass sensitivities are the inertia shares
    assert_rel(
        r.modes[0].mass_sensitivity[0],
        j1 / (j1 + j2),
        1e-12,
        "μ_11",
    );
    // nodes: the elastic shape changes sign
    assert!(r.modes[1].shape[0] * r.modes[1].shape[1] < 0.0);
    check_invariants(&r, &[j1, j2]);
}

#[test]
fn two_mass_grounded_one_end() {
    let (j1, j2, c0, c1) = (0.3, 1.7, 2.0e5, 3.5e4);
    let r = modal::analyse(&chain(&[j1, j2], &[c1], Some(c0), None)).unwrap();
    // det(C − λM) = J1J2 λ² − (J1 c1 + J2 (c0 + c1)) λ + c0 c1
    let (l1, l2) = quadratic(j1 * j2, -(j1 * c1 + j2 * (c0 + c1)), c0 * c1);
    assert!(r.modes.iter().all(|m| m.kind == ModeKind::Elastic));
    assert_rel(r.modes[0].omega0, l1.sqrt(), 1e-9, "ω1");
    assert_rel(r.modes[1].omega0, l2.sqrt(), 1e-9, "ω2");
    check_invariants(&r, &[j1, j2]);
}

#[test]
fn two_mass_grounded_both_ends() {
    let (j1, j2, c0, c1, c2) = (0.02, 0.9, 1.0e4, 2.0e3, 5.0e3);
    let r = modal::analyse(&chain(&[j1, j2], &[c1], Some(c0), Some(c2))).unwrap();
    let (a, b) = (c0 + c1, c1 + c2);
    let (l1, l2) = quadratic(j1 * j2, -(j1 * b + j2 * a), a * b - c1 * c1);
    assert_rel(r.modes[0].omega0, l1.sqrt(), 1e-9, "ω1");
    assert_rel(r.modes[1].omega0, l2.sqrt(), 1e-9, "ω2");
    assert_eq!(r.springs, ["c0", "c1", "cn"]);
    check_invariants(&r, &[j1, j2]);
}

#[test]
fn three_mass_free_free() {
    // EDU-like numbers: reflected motor, wheel, vehicle-equivalent inertia (wide spread).
    let (j1, j2, j3, c1, c2) = (1.595, 0.8, 52.4, 9000.0, 4.0e4);
    let r = modal::analyse(&chain(&[j1, j2, j3], &[c1, c2], None, None)).unwrap();
    let a = j1 * j2 * j3;
    let b = -(c1 * j3 * (j1 + j2) + c2 * j1 * (j2 + j3));
    let c = c1 * c2 * (j1 + j2 + j3);
    let (l1, l2) = quadratic(a, b, c);
    assert_eq!(r.modes[0].kind, ModeKind::RigidBody);
    assert_rel(r.modes[1].omega0, l1.sqrt(), 1e-9, "ω1");
    assert_rel(r.modes[2].omega0, l2.sqrt(), 1e-9, "ω2");
    check_invariants(&r, &[j1, j2, j3]);
}

#[test]
fn three_mass_grounded_both_ends_equal() {
    let (j, c) = (0.7, 1.3e4);
    let r = modal::analyse(&chain(&[j, j, j], &[c, c], Some(c), Some(c))).unwrap();
    let want = [2.0 - 2f64.sqrt(), 2.0, 2.0 + 2f64.sqrt()].map(|x| (x * c / j).sqrt());
    for (m, w) in r.modes.iter().zip(want) {
        assert_rel(m.omega0, w, 1e-9, "ω");
    }
    // symmetric chain: the middle mode has a node at the middle inertia
    assert!(r.modes[1].shape[1].abs() < 1e-9);
    check_invariants(&r, &[j, j, j]);
}

#[test]
fn modal_damping_and_damped_frequency() {
    // Two-mass free-free with a shaft damper: proportional, so Eq. 8 is exact.
    let (j1, j2, c, d) = (1.0, 3.0, 1.0e4, 20.0);
    let mut ch = chain(&[j1, j2], &[c], None, None);
    ch.springs[0].damping = d;
    let r = modal::analyse(&ch).unwrap();
    let m = &r.modes[1];
    let w0 = (c * (1.0 / j1 + 1.0 / j2)).sqrt();
    let sigma = 0.5 * d * (1.0 / j1 + 1.0 / j2);
    assert_rel(m.damping_ratio.unwrap(), sigma / w0, 1e-9, "D");
    assert_rel(
        m.omega_d.unwrap(),
        (w0 * w0 - sigma * sigma).sqrt(),
        1e-9,
        "ω_d",
    );
    assert!(r.modes[0].damping_ratio.is_none());
    // overdamped: no damped frequency
    ch.springs[0].damping = 1e4;
    let r = modal::analyse(&ch).unwrap();
    assert!(r.modes[1].damping_ratio.unwrap() > 1.0 && r.modes[1].omega_d.is_none());
}

#[test]
fn bad_chains_are_refused_with_the_cause() {
    let e = modal::analyse(&chain(&[1.0], &[], None, None)).unwrap_err();
    assert!(
        matches!(e, AnalysisError::TooFewInertias { count: 1, .. }),
        "{e}"
    );
    let e = modal::analyse(&chain(&[1.0, -0.5], &[1.0], None, None)).unwrap_err();
    assert!(
        matches!(&e, AnalysisError::NonPositiveInertia { chain, component, value }
            if chain == "test" && component == "J2" && *value == -0.5),
        "{e}"
    );
    let e = modal::analyse(&chain(&[1.0, 0.5], &[0.0], None, None)).unwrap_err();
    assert!(
        matches!(&e, AnalysisError::NonPositiveStiffness { component, value, .. }
            if component == "c1" && *value == 0.0),
        "{e}"
    );
    // The spring to the ground on the left.
    let e = modal::analyse(&chain(&[1.0, 0.5], &[1.0], Some(-3.0), None)).unwrap_err();
    assert!(
        matches!(&e, AnalysisError::NonPositiveStiffness { component, value, .. }
            if component == "c0" && *value == -3.0),
        "{e}"
    );
    let e = modal::analyse(&chain(&[1.0, 0.5, 2.0], &[1.0], None, None)).unwrap_err();
    assert!(
        matches!(
            e,
            AnalysisError::SpringCount {
                inertias: 3,
                expected: 2,
                found: 1,
                ..
            }
        ),
        "{e}"
    );
    let e = Chain::from_toml_str("name = \"x\"\n[[inertia]]\nname = \"a\"\ninertia = 1\n[[inertia]]\nname = \"b\"\ninertia = 1\n[[spring]]\nname = \"s\"\nstiffnes = 3\n", "bad.toml").unwrap_err();
    assert!(
        matches!(&e, AnalysisError::ChainFormat { file, .. } if file == "bad.toml"),
        "{e}"
    );
}

#[test]
fn example_chains_parse_and_compare() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/chains");
    let vehicle = Chain::from_file(&dir.join("edu_vehicle.toml")).unwrap();
    let bench = Chain::from_file(&dir.join("edu_bench.toml")).unwrap();
    let a = modal::analyse(&vehicle).unwrap();
    let b = modal::analyse(&bench).unwrap();
    assert_eq!(a.modes[0].kind, ModeKind::RigidBody);
    assert_eq!(b.modes[0].kind, ModeKind::RigidBody);
    let cmp = modal::compare(&a, &b);
    let first = cmp
        .pairs
        .iter()
        .find(|p| p.kind == ModeKind::Elastic)
        .unwrap();
    // On the bench the light dyno rotor replaces the vehicle-equivalent inertia: the first
    // drivetrain mode moves up.
    assert!(first.f0_b > first.f0_a, "{} -> {}", first.f0_a, first.f0_b);
}

#[test]
fn compare_names_the_changed_component() {
    let a = chain(&[1.6, 0.8, 52.0], &[1.0e4, 2.4e4], None, None);
    let mut b = a.clone();
    b.springs[1].stiffness = 6.0e4; // a stiffer tyre
    let ra = modal::analyse(&a).unwrap();
    let rb = modal::analyse(&b).unwrap();
    let cmp = modal::compare(&ra, &rb);
    assert_eq!(cmp.pairs.len(), 3);
    for p in cmp.pairs.iter().filter(|p| p.kind == ModeKind::Elastic) {
        assert!(p.f0_b > p.f0_a);
        assert_eq!(p.responsible.name, "c2", "mode {}", p.number_a);
        assert!(p.responsible.changed);
    }
    // identical chains: nothing moves
    let same = modal::compare(&ra, &ra);
    assert!(same.pairs.iter().all(|p| p.shift_hz == 0.0));
}

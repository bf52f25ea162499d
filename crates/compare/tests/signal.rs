//! Signal processing against independent values: the analytic Butterworth magnitude, and
//! numpy/scipy reference values in `fixtures/reference.json` (made by
//! `tools/make_compare_fixture.py`).

use serde_json::Value;
use std::f64::consts::PI;
use std::path::PathBuf;
use tb_compare::{compare_files, metrics, Butterworth, CompareSettings};

fn fixture(name: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn reference() -> Value {
    let text = std::fs::read_to_string(fixture("reference.json")).unwrap();
    serde_json::from_str(&text).unwrap()
}

fn vec_of(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn assert_rel(what: &str, got: f64, want: f64, rel: f64, abs: f64) {
    let tol = abs.max(rel * want.abs());
    assert!(
        (got - want).abs() <= tol,
        "{what}: got {got:e}, want {want:e} (diff {:e}, tol {tol:e})",
        (got - want).abs()
    );
}

/// Amplitude and phase of the component of `y` at `f` (least squares on whole periods).
fn amplitude_phase(y: &[f64], fs: f64, f: f64, from: usize, to: usize) -> (f64, f64) {
    let (mut s, mut c) = (0.0, 0.0);
    for (i, v) in y.iter().enumerate().take(to).skip(from) {
        let w = 2.0 * PI * f * i as f64 / fs;
        s += v * w.sin();
        c += v * w.cos();
    }
    let n = (to - from) as f64;
    let (a, b) = (2.0 * s / n, 2.0 * c / n); // y ≈ a sin + b cos
    ((a * a + b * b).sqrt(), b.atan2(a))
}

/// Tolerance: 1e-12 absolute on magnitudes (closed form against the sections' response).
#[test]
fn sos_response_matches_analytic_butterworth_and_scipy() {
    let r = reference();
    let fs = r["filter"]["sample_rate_hz"].as_f64().unwrap();
    for case in r["filter"]["cases"].as_array().unwrap() {
        let order = case["order"].as_u64().unwrap() as usize;
        let fc = case["cutoff_hz"].as_f64().unwrap();
        let f = Butterworth::lowpass(order, fc, fs).unwrap();
        let freqs = vec_of(&case["freqs_hz"]);
        let scipy = vec_of(&case["magnitude"]);
        for (&q, &want) in freqs.iter().zip(&scipy) {
            let analytic = Butterworth::analytic_magnitude(order, fc, fs, q);
            assert_rel("|H| vs analytic", f.magnitude(q), analytic, 0.0, 1e-12);
            assert_rel("|H| vs scipy sosfreqz", f.magnitude(q), want, 0.0, 1e-12);
        }
        assert_rel(
            "-3 dB at cutoff",
            f.magnitude(fc),
            0.5f64.sqrt(),
            0.0,
            1e-12,
        );
    }
}

/// A sinusoid through one causal pass, in steady state: amplitude ratio equals the analytic
/// magnitude at 3 frequencies (tolerance 1e-6; the transient has decayed by e^-40).
/// Forward-backward: ratio |H|² (tolerance 1e-6) and zero phase (|φ| < 1e-6 rad).
#[test]
fn sinusoid_gain_single_pass_and_zero_phase() {
    let fs = 200.0;
    let (order, fc) = (2, 2.0);
    let f = Butterworth::lowpass(order, fc, fs).unwrap();
    let n = 8000; // 40 s
    for q in [0.5, 2.0, 6.0] {
        let x: Vec<f64> = (0..n)
            .map(|i| (2.0 * PI * q * i as f64 / fs + 0.4).sin())
            .collect();
        let h = Butterworth::analytic_magnitude(order, fc, fs, q);
        // 20 s of whole periods, after 20 s settling.
        let (from, to) = (4000, 8000);
        let (a_in, p_in) = amplitude_phase(&x, fs, q, from, to);

        let mut y = x.clone();
        f.filter_in_place(&mut y);
        let (a_out, _) = amplitude_phase(&y, fs, q, from, to);
        assert_rel(
            &format!("single pass gain at {q} Hz"),
            a_out / a_in,
            h,
            0.0,
            1e-6,
        );

        let (mut out, mut scratch) = (Vec::new(), Vec::new());
        f.filtfilt(&x, &mut out, &mut scratch).unwrap();
        let (from, to) = (2000, 6000); // middle 20 s, away from both edges
        let (a_in, p_in2) = amplitude_phase(&x, fs, q, from, to);
        let (a_out, p_out) = amplitude_phase(&out, fs, q, from, to);
        assert_rel(
            &format!("filtfilt gain at {q} Hz"),
            a_out / a_in,
            h * h,
            0.0,
            1e-6,
        );
        assert!(
            (p_out - p_in2).abs() < 1e-6,
            "filtfilt phase at {q} Hz: {} rad",
            p_out - p_in2
        );
        let _ = p_in;
    }
}

/// filtfilt against scipy's sosfiltfilt (default odd padding) and filtfilt(b, a), and the
/// single pass against sosfilt: max |diff| ≤ 1e-11 × max |x| (x ≈ 1000; seen: ≤ 4e-13 ×).
#[test]
fn filtfilt_matches_scipy() {
    let r = reference();
    let fs = r["filter"]["sample_rate_hz"].as_f64().unwrap();
    let x = vec_of(&r["filter"]["x"]);
    let scale = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let max_diff = |a: &[f64], b: &[f64]| {
        assert_eq!(a.len(), b.len());
        a.iter()
            .zip(b)
            .fold(0.0f64, |m, (p, q)| m.max((p - q).abs()))
    };
    for case in r["filter"]["cases"].as_array().unwrap() {
        let order = case["order"].as_u64().unwrap() as usize;
        let fc = case["cutoff_hz"].as_f64().unwrap();
        let f = Butterworth::lowpass(order, fc, fs).unwrap();
        let (mut out, mut scratch) = (Vec::new(), Vec::new());
        f.filtfilt(&x, &mut out, &mut scratch).unwrap();
        let d = max_diff(&out, &vec_of(&case["sosfiltfilt"]));
        println!("order {order}, fc {fc}: |filtfilt - scipy sosfiltfilt| max {d:e}");
        assert!(d <= 1e-11 * scale, "order {order}: sosfiltfilt diff {d:e}");
        if let Some(ba) = case.get("filtfilt_ba") {
            let d = max_diff(&out, &vec_of(ba));
            println!("order {order}, fc {fc}: |filtfilt - scipy filtfilt(b,a)| max {d:e}");
            assert!(
                d <= 1e-11 * scale,
                "order {order}: filtfilt(b,a) diff {d:e}"
            );
        }
        let mut y = x.clone();
        f.filter_in_place(&mut y);
        let d = max_diff(&y, &vec_of(&case["sosfilt"]));
        assert!(d <= 1e-11 * scale, "order {order}: sosfilt diff {d:e}");
    }
}

fn check_figures(what: &str, got: &tb_compare::Metrics, want: &Value, rel: f64) {
    for (k, g) in [
        ("slope", got.slope),
        ("intercept", got.intercept),
        ("r_squared", got.r_squared),
        ("e", got.e),
        ("bias", got.bias),
        ("rms", got.rms),
    ] {
        // e and bias can be ~0: relative with an absolute floor of 1e-12.
        assert_rel(
            &format!("{what}.{k}"),
            g,
            want[k].as_f64().unwrap(),
            rel,
            1e-12,
        );
    }
    assert_eq!(
        got.points as u64,
        want["points"].as_u64().unwrap(),
        "{what}.points"
    );
}

/// m, intercept, R², e, bias, RMS against scipy.stats.linregress / numpy: 1e-9 relative.
#[test]
fn regression_matches_scipy_linregress() {
    let r = reference();
    for case in r["regression"].as_array().unwrap() {
        let name = case["name"].as_str().unwrap();
        let m = metrics(name, &vec_of(&case["meas"]), &vec_of(&case["sim"])).unwrap();
        check_figures(name, &m, &case["expected"], 1e-9);
    }
}

/// The whole pipeline (filter both at their own rates, distance from v by trapezoid for the
/// simulation, 1 m grid, interpolation, regression) against the same steps in numpy/scipy:
/// 1e-9 relative.
#[test]
fn pipeline_matches_scipy() {
    let r = reference();
    let p = &r["pipeline"];
    let settings = CompareSettings {
        cutoff_hz: p["cutoff_hz"].as_f64().unwrap(),
        filter_order: p["filter_order"].as_u64().unwrap() as usize,
        distance_step_m: p["distance_step_m"].as_f64().unwrap(),
        ..CompareSettings::default()
    };
    let signals = ["Fz_sum", "Fz_front", "Fz_rear", "Fz_rl"];
    let cmp = compare_files(
        fixture("pipeline_sim.csv"),
        fixture("pipeline_meas.csv"),
        &signals,
        &settings,
    )
    .unwrap();
    for s in signals {
        let got = cmp.get(s).unwrap();
        assert_eq!(
            got.points as u64,
            p["grid_points"].as_u64().unwrap(),
            "{s}: grid points"
        );
        check_figures(s, got, &p["expected"][s], 1e-9);
    }
}

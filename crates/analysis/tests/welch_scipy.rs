//! Welch PSD, CSD, H1 and coherence against scipy.signal (fixture written by
//! tools/make_welch_fixture.py).

use serde_json::Value;
use tb_analysis::frf::{self, Detrend, WelchConfig};

fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect()
}

fn assert_close(what: &str, got: &[f64], want: &[f64], tol: f64) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (k, (g, w)) in got.iter().zip(want).enumerate() {
        let rel = if g == w { 0.0 } else { (g - w).abs() / w.abs() };
        assert!(
            rel <= tol,
            "{what}[{k}]: {g} vs scipy {w} (relative {rel:e})"
        );
    }
}

fn assert_close_complex(what: &str, re: &[f64], im: &[f64], wre: &[f64], wim: &[f64], tol: f64) {
    for k in 0..re.len() {
        let err = (re[k] - wre[k]).hypot(im[k] - wim[k]);
        let mag = wre[k].hypot(wim[k]);
        assert!(err <= tol * mag, "{what}[{k}]: relative {:e}", err / mag);
    }
}

#[test]
fn welch_h1_coherence_match_scipy() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/welch_scipy.json");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let fs = doc["fs"].as_f64().unwrap();
    let u = floats(&doc["u"]);
    let y = floats(&doc["y"]);
    let tol = 1e-9;
    let mut worst = 0.0_f64;
    for case in doc["cases"].as_array().unwrap() {
        let cfg = WelchConfig {
            nperseg: case["nperseg"].as_u64().unwrap() as usize,
            noverlap: Some(case["noverlap"].as_u64().unwrap() as usize),
            detrend: match case["detrend"].as_str().unwrap() {
                "none" => Detrend::None,
                "constant" => Detrend::Constant,
                d => panic!("detrend {d}"),
            },
        };
        let name = format!("nperseg {} detrend {:?}", cfg.nperseg, cfg.detrend);
        let s = frf::spectra(&u, &y, fs, &cfg, "fixture").unwrap();
        assert_close(
            &format!("{name} freq"),
            &s.freq,
            &floats(&case["freq"]),
            1e-15,
        );
        let puu = floats(&case["puu"]);
        let pyy = floats(&case["pyy"]);
        // With mean removal the DC bin is zero up to rounding on both sides: skip it.
        let skip = usize::from(cfg.detrend == Detrend::Constant);
        assert_close(&format!("{name} Puu"), &s.puu[skip..], &puu[skip..], tol);
        assert_close(&format!("{name} Pyy"), &s.pyy[skip..], &pyy[skip..], tol);
        let (re, im): (Vec<f64>, Vec<f64>) = s.puy.iter().map(|z| (z.re, z.im)).unzip();
        assert_close_complex(
            &format!("{name} Puy"),
            &re[skip..],
            &im[skip..],
            &floats(&case["puy_re"])[skip..],
            &floats(&case["puy_im"])[skip..],
            tol,
        );
        let (_, p) = frf::welch(&u, fs, &cfg).unwrap();
        assert_close(&format!("{name} welch"), &p[skip..], &puu[skip..], tol);
        let h = frf::h1(&u, &y, fs, &cfg, "fixture").unwrap();
        assert_close_complex(
            &format!("{name} H1"),
            &h.re,
            &h.im,
            &floats(&case["h1_re"])[skip..],
            &floats(&case["h1_im"])[skip..],
            tol,
        );
        assert_close(
            &format!("{name} coherence"),
            &h.coherence,
            &floats(&case["coherence"])[skip..],
            tol,
        );
        for (g, w) in s.puu[skip..].iter().zip(&puu[skip..]) {
            worst = worst.max(((g - w) / w).abs());
        }
    }
    eprintln!("worst relative Puu deviation from scipy: {worst:e}");
}

#[test]
fn too_few_samples_names_the_file() {
    let e = frf::h1(
        &[0.0; 100],
        &[0.0; 100],
        1000.0,
        &WelchConfig::new(256),
        "sweep.csv",
    )
    .unwrap_err();
    assert_eq!(
        e.to_string(),
        "sweep.csv: 100 samples are too few for the requested window of 256 samples (shorten --nperseg or record longer)"
    );
}

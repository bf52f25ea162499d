//! Helpers shared by the vehicle tests: runtimes, temporary tracks, a capturing logger.
#![allow(dead_code)]

use fmu_export::fmi2::fmi2Status;
use fmu_export::{Model, Runtime, Value};
use std::path::PathBuf;
pub use tb_testkit::Capture;

pub fn bundled_resources() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("resources")
}

/// A resource folder holding `track.csv` with `text`, removed when dropped.
pub fn temp_resources(tag: &str, text: &str) -> tempfile::TempDir {
    let dir = tb_testkit::scratch(&format!("vehicle-{tag}"));
    std::fs::write(dir.path().join("track.csv"), text).unwrap();
    dir
}

/// A closed track of `length` m with constant curvature, flat, no road excitation.
pub fn uniform_track(length: f64, curvature: f64) -> String {
    let mut t = String::from("s,curvature,grade,z_road_left,z_road_right\n");
    let n = (length / 0.5).round() as usize;
    for i in 0..n {
        t.push_str(&format!("{},{curvature},0,0,0\n", i as f64 * 0.5));
    }
    t
}

pub fn runtime<M: Model>(
    resources: Option<PathBuf>,
    params: &[(&str, Value)],
) -> (Runtime<M>, Capture) {
    let cap = Capture::default();
    let mut rt = Runtime::<M>::new("test", resources, cap.boxed(), true);
    for (name, v) in params {
        assert_eq!(
            rt.set_by_name(name, *v),
            fmi2Status::OK,
            "set {name}: {}",
            cap.text()
        );
    }
    assert_eq!(rt.setup_experiment(0.0, None), fmi2Status::OK);
    assert_eq!(rt.enter_initialization_mode(), fmi2Status::OK);
    (rt, cap)
}

pub fn get<M: Model>(rt: &mut Runtime<M>, name: &str) -> f64 {
    rt.get_by_name(name)
        .unwrap_or_else(|| panic!("cannot read {name}"))
        .as_f64()
}

pub fn set<M: Model>(rt: &mut Runtime<M>, name: &str, x: f64) {
    assert_eq!(
        rt.set_by_name(name, Value::Real(x)),
        fmi2Status::OK,
        "set {name} = {x}"
    );
}

pub fn r(x: f64) -> Value {
    Value::Real(x)
}

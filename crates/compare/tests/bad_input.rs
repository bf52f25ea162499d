//! Malformed measurement files: each error names the file, the 1-based line and the column.

use std::path::PathBuf;
use tb_compare::{DistanceSource, Measurement};

const HEADER: &str = "time,distance,v,Fz_fl,Fz_fr,Fz_rl,Fz_rr\n";

/// `text` written as `name` in a scratch folder (removed when the returned handle drops).
fn write(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tb_testkit::scratch("compare-bad-input");
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    (dir, p)
}

fn error_of(name: &str, text: &str) -> String {
    let (_dir, p) = write(name, text);
    let e = Measurement::read_path(&p).unwrap_err().to_string();
    assert!(e.contains(name), "message names the file: {e}");
    e
}

/// Each malformed file is refused with an error that names the file (`error_of`), the
/// 1-based line and the column; the failure names the case.
#[test]
fn malformed_files_name_line_and_column() {
    let rows = |data: &str| format!("{HEADER}{data}");
    let cases = [
        (
            "nan.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,NaN,1,1\n0.2,2,10,1,1,1,1\n"),
            "line 3, column `Fz_fr`: value NaN is not finite",
        ),
        (
            "inf.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,2,inf,1,1,1,1\n"),
            "line 4, column `v`: value inf is not finite",
        ),
        (
            "time.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.1,2,10,1,1,1,1\n"),
            "line 4, column `time`: time does not increase (0.1 after 0.1)",
        ),
        (
            "back.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,0.5,10,1,1,1,1\n"),
            "line 4, column `distance`: distance runs backwards (0.5 after 1)",
        ),
        (
            "missing.csv",
            "time,distance,v,Fz_fl,Fz_fr,Fz_rl\n0,0,10,1,1,1\n".to_string(),
            "missing required column `Fz_rr`",
        ),
        (
            "malformed.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,2,1O,1,1,1,1\n"),
            "line 4, column `v`: malformed number \"1O\"",
        ),
        ("empty.csv", String::new(), "empty file: no header row"),
        ("header.csv", HEADER.to_string(), "no data rows"),
        (
            "ragged.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1\n"),
            "line 3: expected 7 fields",
        ),
        // A units row and blank lines keep the line numbers.
        (
            "units.csv",
            rows("s,m,m/s,N,N,N,N\n0,0,10,1,1,1,1\n\n0.1,1,10,1,1,-inf,1\n"),
            "line 5, column `Fz_rl`",
        ),
    ];
    for (name, text, expected) in cases {
        let e = error_of(name, &text);
        assert!(e.contains(expected), "{name}: {expected:?} is not in: {e}");
    }
}

#[test]
fn distance_standing_still_is_not_running_backwards() {
    let (_dir, p) = write(
        "still.csv",
        &format!("{HEADER}0,0,0,1,1,1,1\n0.1,0,0,1,1,1,1\n0.2,0.5,10,1,1,1,1\n"),
    );
    Measurement::read_path(p).unwrap();
}

#[test]
fn distance_integrated_from_speed() {
    let (_dir, p) = write(
        "nodist.csv",
        "time,v,Fz_fl,Fz_fr,Fz_rl,Fz_rr\r\n0,10,1,1,1,1\r\n0.1,10,1,1,1,1\r\n0.2,20,1,1,1,1\r\n",
    );
    let m = Measurement::read_path(p).unwrap();
    assert_eq!(m.distance_source(), DistanceSource::IntegratedFromSpeed);
    let d = m.distance();
    assert_eq!(d.len(), 3);
    assert!(
        (d[1] - 1.0).abs() < 1e-12 && (d[2] - 2.5).abs() < 1e-12,
        "{d:?}"
    );
}

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

#[test]
fn nan_names_row_and_column() {
    let e = error_of(
        "nan.csv",
        &format!("{HEADER}0,0,10,1,1,1,1\n0.1,1,10,1,NaN,1,1\n0.2,2,10,1,1,1,1\n"),
    );
    assert!(
        e.contains("line 3, column `Fz_fr`: value NaN is not finite"),
        "{e}"
    );
    let e = error_of(
        "inf.csv",
        &format!("{HEADER}0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,2,inf,1,1,1,1\n"),
    );
    assert!(
        e.contains("line 4, column `v`: value inf is not finite"),
        "{e}"
    );
}

#[test]
fn non_increasing_time() {
    let e = error_of(
        "time.csv",
        &format!("{HEADER}0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.1,2,10,1,1,1,1\n"),
    );
    assert!(
        e.contains("line 4, column `time`: time does not increase (0.1 after 0.1)"),
        "{e}"
    );
}

#[test]
fn distance_running_backwards() {
    let e = error_of(
        "back.csv",
        &format!("{HEADER}0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,0.5,10,1,1,1,1\n"),
    );
    assert!(
        e.contains("line 4, column `distance`: distance runs backwards (0.5 after 1)"),
        "{e}"
    );
    // Standing still is allowed.
    let (_dir, p) = write(
        "still.csv",
        &format!("{HEADER}0,0,0,1,1,1,1\n0.1,0,0,1,1,1,1\n0.2,0.5,10,1,1,1,1\n"),
    );
    Measurement::read_path(p).unwrap();
}

#[test]
fn missing_required_column() {
    let e = error_of(
        "missing.csv",
        "time,distance,v,Fz_fl,Fz_fr,Fz_rl\n0,0,10,1,1,1\n",
    );
    assert!(e.contains("missing required column `Fz_rr`"), "{e}");
}

#[test]
fn malformed_number() {
    let e = error_of(
        "malformed.csv",
        &format!("{HEADER}0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,2,1O,1,1,1,1\n"),
    );
    assert!(
        e.contains("line 4, column `v`: malformed number \"1O\""),
        "{e}"
    );
}

#[test]
fn empty_file_and_header_only() {
    let e = error_of("empty.csv", "");
    assert!(e.contains("empty file: no header row"), "{e}");
    let e = error_of("header.csv", HEADER);
    assert!(e.contains("no data rows"), "{e}");
}

#[test]
fn ragged_row() {
    let e = error_of(
        "ragged.csv",
        &format!("{HEADER}0,0,10,1,1,1,1\n0.1,1,10,1,1,1\n"),
    );
    assert!(e.contains("line 3: expected 7 fields"), "{e}");
}

#[test]
fn units_row_and_blank_lines_keep_line_numbers() {
    let e = error_of(
        "units.csv",
        &format!("{HEADER}s,m,m/s,N,N,N,N\n0,0,10,1,1,1,1\n\n0.1,1,10,1,1,-inf,1\n"),
    );
    assert!(e.contains("line 5, column `Fz_rl`"), "{e}");
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

//! Malformed measurement files: each error names the file, the 1-based line and the column.

use std::path::PathBuf;
use tb_compare::{DistanceSource, Measurement};
use tb_measurement::Error;
use tb_table::TableError;

const HEADER: &str = "time,distance,v,Fz_fl,Fz_fr,Fz_rl,Fz_rr\n";

/// `text` written as `name` in a scratch folder (removed when the returned handle drops).
fn write(name: &str, text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tb_testkit::scratch("compare-bad-input");
    let p = dir.path().join(name);
    std::fs::write(&p, text).unwrap();
    (dir, p)
}

fn error_of(name: &str, text: &str) -> Error {
    let (_dir, p) = write(name, text);
    let e = Measurement::read_path(&p).unwrap_err();
    assert!(e.to_string().contains(name), "message names the file: {e}");
    e
}

/// Whether an error is of the kind a case expects.
type Kind = fn(&Error) -> bool;

/// Each malformed file is refused with an error of its kind that names the file
/// (`error_of`), the 1-based line and the column; the failure names the case.
#[test]
fn malformed_files_name_line_and_column() {
    let rows = |data: &str| format!("{HEADER}{data}");
    let cases: [(&str, String, Kind, &str); 10] = [
        (
            "nan.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,NaN,1,1\n0.2,2,10,1,1,1,1\n"),
            |e| matches!(e, Error::Table(TableError::NonFinite { row: 3, column, .. }) if column == "Fz_fr"),
            "line 3, column `Fz_fr`: value NaN is not finite",
        ),
        (
            "inf.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,2,inf,1,1,1,1\n"),
            |e| matches!(e, Error::Table(TableError::NonFinite { row: 4, column, .. }) if column == "v"),
            "line 4, column `v`: value inf is not finite",
        ),
        (
            "time.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.1,2,10,1,1,1,1\n"),
            |e| matches!(e, Error::NonIncreasingTime { row: 4, column, .. } if column == "time"),
            "line 4, column `time`: time does not increase (0.1 after 0.1)",
        ),
        (
            "back.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,0.5,10,1,1,1,1\n"),
            |e| matches!(e, Error::DistanceBackwards { row: 4, column, .. } if column == "distance"),
            "line 4, column `distance`: distance runs backwards (0.5 after 1)",
        ),
        (
            "missing.csv",
            "time,distance,v,Fz_fl,Fz_fr,Fz_rl\n0,0,10,1,1,1\n".to_string(),
            |e| matches!(e, Error::MissingSignal { signal, .. } if signal == "Fz_rr"),
            "missing required column `Fz_rr`",
        ),
        (
            "malformed.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1,1\n0.2,2,1O,1,1,1,1\n"),
            |e| matches!(e, Error::Table(TableError::Malformed { row: 4, column, .. }) if column == "v"),
            "line 4, column `v`: malformed number \"1O\"",
        ),
        (
            "empty.csv",
            String::new(),
            |e| matches!(e, Error::Table(TableError::Empty { .. })),
            "empty file: no header row",
        ),
        (
            "header.csv",
            HEADER.to_string(),
            |e| matches!(e, Error::Table(TableError::Empty { .. })),
            "no data rows",
        ),
        (
            "ragged.csv",
            rows("0,0,10,1,1,1,1\n0.1,1,10,1,1,1\n"),
            |e| {
                matches!(
                    e,
                    Error::Table(TableError::RaggedRow {
                        row: 3,
                        expected: 7,
                        ..
                    })
                )
            },
            "line 3: expected 7 fields",
        ),
        // A units row and blank lines keep the line numbers.
        (
            "units.csv",
            rows("s,m,m/s,N,N,N,N\n0,0,10,1,1,1,1\n\n0.1,1,10,1,1,-inf,1\n"),
            |e| matches!(e, Error::Table(TableError::NonFinite { row: 5, column, .. }) if column == "Fz_rl"),
            "line 5, column `Fz_rl`",
        ),
    ];
    for (name, text, kind, expected) in cases {
        let e = error_of(name, &text);
        assert!(kind(&e), "{name}: not of the expected kind: {e:?}");
        assert!(
            e.to_string().contains(expected),
            "{name}: {expected:?} is not in: {e}"
        );
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

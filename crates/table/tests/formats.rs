//! Tables through their file formats: CSV separators, comments, text columns and quoting;
//! MDF 4 written and read back with units.

use tb_table::{MdfError, Table, TableError};

fn scratch() -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix("tb-table-")
        .tempdir()
        .unwrap()
}

#[test]
fn csv_with_semicolons_tabs_comments_and_a_units_row() {
    for sep in [";", "\t", ","] {
        let text = format!("# logger export\ntime{sep}v{sep}note\ns{sep}km/h{sep}\n0{sep}36{sep}start\n0.1{sep}72{sep}\"a{sep} b\"\n");
        let t = Table::from_reader(text.as_bytes(), "log.csv").unwrap();
        assert_eq!(t.names(), &["time", "v", "note"]);
        assert_eq!(t.units().unwrap(), &["s", "km/h", ""]);
        assert_eq!(t.require("v").unwrap(), &[36.0, 72.0]);
        // A column of words is text, read only when asked for, and then by name.
        assert!(t.is_text(2));
        assert_eq!(
            t.text_at(2).unwrap(),
            &["start".to_string(), format!("a{sep} b")]
        );
        let e = t.require("note").unwrap_err();
        assert!(
            matches!(&e, TableError::Malformed { row: 4, column, value, .. } if column == "note" && value == "start"),
            "{e}"
        );
    }
}

#[test]
fn text_and_names_with_separators_survive_a_round_trip() {
    let mut t = Table::new(
        "rec",
        vec!["time".into(), "a,b".into(), "label".into()],
        vec!["s".into(), "1".into(), "".into()],
    )
    .unwrap();
    t.set_text(2);
    t.push_row([0.0, 1.5, f64::NAN]);
    t.push_text(2, "say \"hi\", twice");
    let dir = scratch();
    let p = dir.path().join("r.csv");
    t.write_csv(&p).unwrap();
    let back = Table::read_path(&p).unwrap();
    assert_eq!(back.names(), t.names());
    assert_eq!(back.require("a,b").unwrap(), &[1.5]);
    assert_eq!(back.text_at(2).unwrap(), &["say \"hi\", twice".to_string()]);
}

#[test]
fn mdf4_round_trip_keeps_values_bit_for_bit_and_units() {
    let n = 500;
    let time: Vec<f64> = (0..n).map(|i| i as f64 * 0.005).collect();
    let v: Vec<f64> = time.iter().map(|t| 20.0 + (t * 3.1).sin() / 3.0).collect();
    let fz: Vec<f64> = time.iter().map(|t| 2.0e3 + 1e-9 * t).collect();
    let t = Table::from_columns(
        "lap",
        vec!["time".into(), "vehicle.v".into(), "vehicle.Fz_rl".into()],
        vec![time.clone(), v.clone(), fz.clone()],
    )
    .unwrap()
    .with_units(vec!["s".into(), "m/s".into(), "N".into()])
    .unwrap();
    let dir = scratch();
    let p = dir.path().join("lap.mf4");
    t.write_any(&p).unwrap();
    let back = Table::read_any(&p).unwrap();
    assert_eq!(back.names(), t.names());
    assert_eq!(back.units().unwrap(), t.units().unwrap());
    for (a, b) in back.columns().iter().zip(t.columns()) {
        assert!(a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits()));
    }
    // Not an MDF file: a clear error naming the file.
    std::fs::write(dir.path().join("bad.mf4"), b"not an mdf file at all").unwrap();
    let e = Table::read_any(&dir.path().join("bad.mf4")).unwrap_err();
    assert!(
        matches!(&e, TableError::Mdf { file, source: MdfError::ShortFile { size: 22 } } if file.ends_with("bad.mf4")),
        "{e}"
    );
}

//! `twinbench export-twin RESULT.json --out DIR`: the fitted twin handed on. Its FMUs alone
//! (no value set by any host, FMI 2.0 and 3.0), its system file, its SSP and `run
//! --params` each give the lap that `run SYSTEM --set <the answer>` gives, bit for bit,
//! with the study's own track and target speed carried inside the FMUs; its descriptions
//! say the fitted values, its own GUID and where they come from; a folder holding the
//! user's files and an FMU of another build are refused (one short study for all of it). (FMPy and OMSimulator on the same
//! outputs: the slow tier's `export_twin_tools`.)

mod common;

use common::ok_in;
use std::path::{Path, PathBuf};
use tb_testkit::assert_contains;

/// The bench of `systems/rls_v.toml` over the packed FMUs, with its own track and a target
/// speed 2 % below the bundled one (files the fitted FMUs must carry in place of their
/// bundled ones).
fn bench_with_files(d: &Path) -> PathBuf {
    let root = twinbench::pack::workspace_root();
    let fmus = common::fmu_dir();
    std::fs::copy(
        root.join("models/vehicle/resources/track.csv"),
        d.join("track.csv"),
    )
    .unwrap();
    let target =
        std::fs::read_to_string(root.join("models/driver/resources/target_speed.csv")).unwrap();
    let mut slower = String::new();
    for (i, line) in target.lines().enumerate() {
        if i == 0 {
            slower.push_str(line);
        } else {
            let f: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            slower.push_str(&format!(
                "\n{},{},{}",
                f[0],
                f[1] * 0.98,
                f[2] * 0.98 * 0.98
            ));
        }
    }
    slower.push('\n');
    std::fs::write(d.join("target.csv"), slower).unwrap();
    let text = std::fs::read_to_string(root.join("systems/rls_v.toml"))
        .unwrap()
        .replace("\"../target/fmu/", &format!("\"{}/", fmus.display()))
        .replace(
            "[parameters]\n",
            "[parameters]\n\"vehicle.track_file\" = \"track.csv\"\n\"driver.target_speed_file\" = \"target.csv\"\n",
        );
    let path = d.join("bench.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// A short study (one generation per step) of the bundled lap; its result then names
/// `system` as the study's bench.
fn result_for(d: &Path, system: &Path) -> (PathBuf, serde_json::Value) {
    let root = twinbench::pack::workspace_root();
    let study = root.join("studies/spielberg.toml");
    let args = args![
        "optimize",
        study,
        "--generations",
        "1",
        "--no-report",
        "--out",
        "opt"
    ];
    ok_in(d, args);
    let path = d.join("opt/result.json");
    let mut result: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
    result["system"] = serde_json::json!(system);
    let path = d.join("result.json");
    std::fs::write(&path, serde_json::to_string_pretty(&result).unwrap()).unwrap();
    (path, result)
}

/// `run SYSTEM --set name=value …` with the answer typed out, as a user does by hand.
fn run_with_set(d: &Path, system: &Path, result: &serde_json::Value, out: &str) -> Vec<u8> {
    let mut args = vec!["run".to_string(), system.display().to_string()];
    for p in result["parameters_final"].as_array().unwrap() {
        args.push("--set".into());
        args.push(format!(
            "{}={:?}",
            p[0].as_str().unwrap(),
            p[1].as_f64().unwrap()
        ));
    }
    args.extend(["-o".into(), out.into()]);
    ok_in(d, &args);
    std::fs::read(d.join(out)).unwrap()
}

/// The fitted system file without its values: the FMUs alone must carry them.
fn bare_system(twin: &Path, fmi3: bool) -> PathBuf {
    let text = std::fs::read_to_string(twin.join("fitted_system.toml")).unwrap();
    let (head, tail) = text.split_at(text.find("[parameters]").unwrap());
    let tail = &tail[tail.find("\n[").unwrap() + 1..];
    let mut bare = format!("{head}{tail}");
    if fmi3 {
        bare = bare.replace(".fmu\"", "-fmi3.fmu\"");
    }
    let path = twin.join(if fmi3 { "bare3.toml" } else { "bare.toml" });
    std::fs::write(&path, bare).unwrap();
    path
}

fn zip_text(fmu: &Path, entry: &str) -> String {
    use std::io::Read;
    let mut z = zip::ZipArchive::new(std::fs::File::open(fmu).unwrap()).unwrap();
    let mut s = String::new();
    z.by_name(entry).unwrap().read_to_string(&mut s).unwrap();
    s
}

#[test]
fn the_fitted_twin_runs_its_lap_bit_for_bit_from_every_output() {
    let dir = tb_testkit::scratch("export-twin");
    let d = dir.path();
    let bench = bench_with_files(d);
    let (result_path, result) = result_for(d, &bench);
    let log = ok_in(d, args!["export-twin", result_path, "--out", "twin",]);
    assert_contains(
        &log,
        &["fitted FMUs     vehicle, driver, dyno_rl, dyno_rr, edu"],
    );
    let twin = d.join("twin");
    let expected = run_with_set(d, &bench, &result, "set.csv");

    let runs: Vec<(String, Vec<String>)> = vec![
        (
            "the fitted system".into(),
            vec![twin.join("fitted_system.toml").display().to_string()],
        ),
        (
            "the FMI 2.0 FMUs alone".into(),
            vec![bare_system(&twin, false).display().to_string()],
        ),
        (
            "the FMI 3.0 FMUs alone".into(),
            vec![bare_system(&twin, true).display().to_string()],
        ),
        (
            "the SSP".into(),
            vec![twin.join("fitted_twin.ssp").display().to_string()],
        ),
        (
            "run --params".into(),
            vec![
                bench.display().to_string(),
                "--params".into(),
                result_path.display().to_string(),
            ],
        ),
    ];
    for (i, (what, args)) in runs.iter().enumerate() {
        let out = format!("out{i}.csv");
        ok_in(
            d,
            ["run"]
                .into_iter()
                .chain(args.iter().map(String::as_str))
                .chain(["-o", &out]),
        );
        assert!(
            std::fs::read(d.join(&out)).unwrap() == expected,
            "{what}: its lap differs from `run --set <answer>`'s"
        );
    }

    // The description: the answer as start values (the text that reads back to the same
    // f64), the fitted FMU's own GUID, the study and the measurement's digest.
    let md = zip_text(&twin.join("fmu/vehicle.fmu"), "modelDescription.xml");
    let plain = zip_text(&common::fmu("vehicle"), "modelDescription.xml");
    let guid = |t: &str| {
        t.split("guid=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap()
            .to_string()
    };
    assert_ne!(guid(&md), guid(&plain), "a fitted FMU has its own GUID");
    for p in result["parameters_final"].as_array().unwrap() {
        let name = p[0].as_str().unwrap().strip_prefix("vehicle.").unwrap();
        let value = p[1].as_f64().unwrap();
        let var = md
            .split(&format!("<ScalarVariable name=\"{name}\""))
            .nth(1)
            .unwrap();
        let start: f64 = var
            .split("start=\"")
            .nth(1)
            .unwrap()
            .split('"')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        assert_eq!(start.to_bits(), value.to_bits(), "{name}");
        assert!(
            md.contains(&format!("<Value name=\"{name}\" value=")),
            "{name}"
        );
    }
    let measurement = std::fs::read(result["measurement"].as_str().unwrap()).unwrap();
    let digest = {
        use sha2::Digest;
        format!("{:x}", sha2::Sha256::digest(&measurement))
    };
    assert!(md.contains(&format!("measurementSha256=\"{digest}\"")));
    assert!(md.contains("study=\"spielberg\""));
    // The track and target travel inside the FMUs, in place of the bundled ones.
    assert_eq!(
        zip_text(&twin.join("fmu/driver.fmu"), "resources/target_speed.csv"),
        std::fs::read_to_string(d.join("target.csv")).unwrap()
    );
    // The table: every value the bench sets, the fitted ones with their interval.
    let csv = std::fs::read_to_string(twin.join("parameters.csv")).unwrap();
    let row = csv
        .lines()
        .find(|l| l.starts_with("vehicle.c_lift_front,"))
        .unwrap();
    let f: Vec<&str> = row.split(',').collect();
    assert_eq!(f[3], "true");
    let (lo, hi, x): (f64, f64, f64) = (
        f[5].parse().unwrap(),
        f[6].parse().unwrap(),
        f[1].parse().unwrap(),
    );
    assert!(lo < x && x < hi, "{row}");
    assert!(
        csv.lines()
            .any(|l| l.starts_with("vehicle.v_start,52.43,m/s,false")),
        "{csv}"
    );
    let ssv = std::fs::read_to_string(twin.join("fitted_twin.ssv")).unwrap();
    assert!(ssv.contains("<ssv:Parameter name=\"vehicle.c_lift_front\"><ssv:Real value="));

    // Again into the same folder: an earlier export is replaced; a folder with the user's
    // own files is refused, and they stay.
    ok_in(
        d,
        args!["export-twin", result_path, "--out", "twin", "--fmi", "3",],
    );
    std::fs::create_dir(d.join("mine")).unwrap();
    std::fs::write(d.join("mine/notes.txt"), "mine").unwrap();
    let e = common::fails_in(d, args!["export-twin", result_path, "--out", "mine"]);
    assert_contains(&e, &["mine", "not an earlier export-twin output"]);
    assert_eq!(
        std::fs::read_to_string(d.join("mine/notes.txt")).unwrap(),
        "mine"
    );
    an_edited_start_file_refuses_the_instantiation(d, &twin);
    an_fmu_of_another_build_is_refused_by_name(d, &bench, &result_path);
}

/// An FMU whose library is not this build's: the fitted copy would not be the FMU the study
/// ran, so the export is refused, naming the FMU and what to do.
fn an_fmu_of_another_build_is_refused_by_name(d: &Path, bench: &Path, result_path: &Path) {
    // The vehicle's FMU with one byte of its library changed.
    let stale = d.join("vehicle_old.fmu");
    rewrite_fmu(&common::fmu("vehicle"), &stale, |name, bytes| {
        if name.ends_with(".so") {
            bytes.push(0);
        }
    });
    let text = std::fs::read_to_string(bench).unwrap();
    let vehicle = common::fmu("vehicle").display().to_string();
    std::fs::write(bench, text.replace(&vehicle, stale.to_str().unwrap())).unwrap();
    let e = common::fails_in(d, args!["export-twin", result_path, "--out", "twin"]);
    assert_contains(&e, &["vehicle_old.fmu", "twinbench pack"]);
}

/// A copy of the FMU `from` at `to`, each entry passed through `edit` (its name, its bytes).
fn rewrite_fmu(from: &Path, to: &Path, edit: impl Fn(&str, &mut Vec<u8>)) {
    use std::io::{Read, Write};
    let mut z = zip::ZipArchive::new(std::fs::File::open(from).unwrap()).unwrap();
    let mut w = zip::ZipWriter::new(std::fs::File::create(to).unwrap());
    for i in 0..z.len() {
        let mut f = z.by_index(i).unwrap();
        let name = f.name().to_string();
        let mut bytes = Vec::new();
        f.read_to_end(&mut bytes).unwrap();
        edit(&name, &mut bytes);
        w.start_file(name, zip::write::SimpleFileOptions::default())
            .unwrap();
        w.write_all(&bytes).unwrap();
    }
    w.finish().unwrap();
}

/// A fitted FMU whose start-value file was edited: a value out of the variable's range, a
/// name the model does not have, a value of another type. Each refuses the instantiation,
/// naming the file and the variable, before the first step.
fn an_edited_start_file_refuses_the_instantiation(d: &Path, twin: &Path) {
    let bare = std::fs::read_to_string(twin.join("bare.toml")).unwrap();
    for (edit, says) in [
        (
            "c_lift_front = 99.0\n",
            "`c_lift_front` = 99.0: expected a finite value in [-2, 6]",
        ),
        (
            "c_lift_fornt = 1.0\n",
            "no variable named `c_lift_fornt` in this model",
        ),
        (
            "c_lift_front = \"high\"\n",
            "`c_lift_front` = \"high\": expected a number",
        ),
    ] {
        let edited = twin.join("fmu/vehicle_edited.fmu");
        rewrite_fmu(&twin.join("fmu/vehicle.fmu"), &edited, |name, bytes| {
            if name.ends_with("fitted_start_values.toml") {
                let text = String::from_utf8(bytes.clone()).unwrap();
                let kept: String = text
                    .lines()
                    .filter(|l| !l.starts_with("c_lift_front ="))
                    .map(|l| format!("{l}\n"))
                    .collect();
                *bytes = format!("{kept}{edit}").into_bytes();
            }
        });
        let system = twin.join("edited.toml");
        std::fs::write(
            &system,
            bare.replace("\"fmu/vehicle.fmu\"", "\"fmu/vehicle_edited.fmu\""),
        )
        .unwrap();
        let o = common::twinbench_in(d, args!["run", system]);
        let e = common::cli::failed(o, format!("{edit}: the run"));
        assert!(
            e.contains("fitted_start_values.toml") && e.contains(says),
            "{edit}: {e}"
        );
    }
}

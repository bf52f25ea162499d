//! The third red-team pass's findings (N1–N29), one test (or bad-file case) each where it
//! is not elsewhere; `docs/robustness.md` lists which test proves which finding. Each of
//! these failed before its fix.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use tb_testkit::assert_contains;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

/// `twinbench lap` of the bundled lap and its track, into `lap/` in `d`.
fn bundled_lap(d: &Path) {
    let meas = root().join("data/spielberg_lap.csv");
    let track = root().join("data/spielberg_lap_track.csv");
    common::ok_in(d, args!["lap", meas, "--track", track, "--out", "lap"]);
}

/// A measurement CSV of `rows` samples at 100 Hz: distance and speed from `sample(k)`.
fn measurement(path: &Path, rows: usize, sample: impl Fn(usize) -> (f64, f64)) {
    let mut text = String::from("time,distance,v,a_x,a_y,Fz_fl,Fz_fr,Fz_rl,Fz_rr\n");
    for k in 0..rows {
        let (d, v) = sample(k);
        text.push_str(&format!(
            "{},{d},{v},0,0,3000,3000,3000,3000\n",
            k as f64 * 0.01
        ));
    }
    std::fs::write(path, text).unwrap();
}

/// N1: the folder lock never follows a planted link (whose target it truncated), never
/// uses a lock that is not a regular file, and results go only into a folder of this user.
#[test]
fn n01_the_folder_lock_follows_no_link_and_takes_no_other_users_folder() {
    let dir = tb_testkit::scratch("n01");
    let d = dir.path();
    let victim = d.join("victim.txt");
    std::fs::write(&victim, "precious").unwrap();
    std::fs::create_dir(d.join("out")).unwrap();
    std::os::unix::fs::symlink(&victim, d.join("out/.twinbench.lock")).unwrap();
    let e = tb_table::FolderLock::acquire(&d.join("out"))
        .err()
        .expect("a linked lock is refused");
    assert!(matches!(e.kind(), std::io::ErrorKind::InvalidInput), "{e}");
    assert!(
        e.to_string()
            .contains(".twinbench.lock: is a symbolic link"),
        "{e}"
    );
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
    // A FIFO as the lock: refused, not waited on.
    std::fs::create_dir(d.join("out2")).unwrap();
    let fifo = std::ffi::CString::new(d.join("out2/.twinbench.lock").to_str().unwrap()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(fifo.as_ptr(), 0o600) }, 0);
    let e = tb_table::FolderLock::acquire(&d.join("out2"))
        .err()
        .expect("a FIFO lock is refused");
    assert!(matches!(e.kind(), std::io::ErrorKind::InvalidInput), "{e}");
    assert!(e.to_string().contains("is not a regular file"), "{e}");
    // A hard link to a file of the user's (M18): refused, nothing written through it.
    std::fs::create_dir(d.join("out3")).unwrap();
    std::fs::hard_link(&victim, d.join("out3/.twinbench.lock")).unwrap();
    let e = tb_table::FolderLock::acquire(&d.join("out3"))
        .err()
        .expect("a hard-linked lock is refused");
    assert!(matches!(e.kind(), std::io::ErrorKind::InvalidInput), "{e}");
    assert!(e.to_string().contains("has 2 hard links"), "{e}");
    assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
    // Another user's folder (only root can make one here).
    if unsafe { libc::geteuid() } == 0 {
        let other = d.join("theirs");
        std::fs::create_dir(&other).unwrap();
        let c = std::ffi::CString::new(other.to_str().unwrap()).unwrap();
        assert_eq!(unsafe { libc::chown(c.as_ptr(), 1234, 1234) }, 0);
        let e = tb_table::FolderLock::acquire(&other)
            .err()
            .expect("another user's folder is refused");
        assert!(matches!(e.kind(), std::io::ErrorKind::InvalidInput), "{e}");
        assert_contains(
            &e.to_string(),
            &["the folder belongs to user id 1234, not to this user (0)"],
        );
    }
}

/// N7: a step count that overflows (a subnormal step, a stop time near the largest
/// double) ran nothing and succeeded.
#[test]
fn n07_an_infinite_step_count_is_refused() {
    let fmus = common::fmu_dir();
    let dir = tb_testkit::scratch("n07");
    let text = std::fs::read_to_string(root().join("systems/rls_v.toml"))
        .unwrap()
        .replace("\"../target/fmu/", &format!("\"{}/", fmus.display()));
    for (what, edit) in [
        ("step = 1e-3", "step = 1e-320"),
        ("stop = \"vehicle.lap >= 1\"", "stop = 1e308"),
    ] {
        let p = dir.path().join("sys.toml");
        std::fs::write(&p, text.replace(what, edit)).unwrap();
        let e = common::fails_in(dir.path(), ["run", "sys.toml"]);
        assert!(e.contains("macro steps, more than 1e12"), "{edit}: {e}");
    }
}

/// N16, N29: a standing measurement panicked `lap`; a logger's 1e308 became a target speed.
#[test]
fn n16_n29_lap_refuses_a_standing_measurement_and_absurd_speeds() {
    let dir = tb_testkit::scratch("n16");
    let d = dir.path();
    measurement(&d.join("standing.csv"), 200, |_| (0.0, 0.0));
    let e = common::fails_in(d, ["lap", "standing.csv", "--out", "x"]);
    assert_contains(&e, &["the car covers 0.0 m in 2.0 s: not a lap"]);
    assert!(!e.contains("panicked"), "{e}");
    measurement(&d.join("huge.csv"), 1000, |k| {
        (k as f64 * 0.5, if k == 50 { 1e308 } else { 50.0 })
    });
    let e = common::fails_in(d, ["lap", "huge.csv", "--out", "x"]);
    assert!(e.contains("sample 51 (t = 0.5 s) has v = 1e308 m/s"), "{e}");
    // A lap of a metre.
    measurement(&d.join("metre.csv"), 100, |k| (k as f64 * 0.01, 1.0));
    let e = common::fails_in(d, ["lap", "metre.csv", "--out", "x"]);
    assert!(e.contains("not a lap (at least 100 m"), "{e}");
}

/// N17: a panic of twinbench's own was reported as an FMU's `exit()`.
#[test]
fn n17_a_panic_is_reported_as_a_panic_with_its_location() {
    let o = Command::new(env!("CARGO_BIN_EXE_twinbench"))
        .args(["pack", "-o", "/nonexistent/never"])
        .env("TWINBENCH_TEST_PANIC", "1")
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(101), "{e}");
    assert!(e.contains("panicked at src/cli/mod.rs:"), "{e}");
    assert!(e.contains("an internal error"), "{e}");
    assert!(!e.contains("exit()"), "{e}");
}

/// N20: a FIFO hung and /dev/zero exhausted memory as an input file.
#[test]
fn n20_fifos_and_devices_are_refused_as_every_kind_of_input() {
    let dir = tb_testkit::scratch("n20");
    let d = dir.path();
    let fifo = d.join("fifo");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let meas = root().join("data/spielberg_lap.csv");
    let meas = meas.to_str().unwrap();
    for bad in ["fifo", "/dev/zero"] {
        let kind = if bad == "fifo" { "a FIFO" } else { "a device" };
        for args in [
            vec!["run", bad],
            vec!["optimize", bad],
            vec!["compare", bad, meas],
            vec!["compare", meas, bad],
            vec!["lap", bad, "--out", "x"],
            vec!["lap", meas, "--channels", bad, "--out", "x"],
            vec!["lap", meas, "--track", bad, "--out", "x"],
            vec!["modal", bad],
        ] {
            // A FIFO without a writer: every read must be refused at once, not wait.
            let e = common::fails_in(d, &args);
            assert!(
                e.contains(&format!("is {kind}, not a regular file")),
                "{args:?}: {e}"
            );
        }
    }
    // An MDF 4 measurement: the same.
    let e = common::fails_in(d, ["lap", "/dev/zero", "--out", "x"]);
    assert!(e.contains("is a device"), "{e}");
    std::os::unix::fs::symlink("/dev/zero", d.join("zero.mf4")).unwrap();
    let e = common::fails_in(d, ["lap", "zero.mf4", "--out", "x"]);
    assert!(e.contains("is a device, not a regular file"), "{e}");
}

/// N21: an interrupted write left its temporary behind, and nothing removed it later; a
/// file size limit killed the process with no word.
#[test]
fn n21_temporaries_are_removed_and_swept_and_a_size_limit_is_an_error() {
    let dir = tb_testkit::scratch("n21");
    let d = dir.path();
    // A temporary of a killed writer, an hour old and unlocked: swept by the next write.
    let stale = d.join(".lap.csv.0123456789abcdef.tmp");
    std::fs::write(&stale, "half a result").unwrap();
    let an_hour_ago = std::time::SystemTime::now() - std::time::Duration::from_secs(3600);
    std::fs::File::options()
        .write(true)
        .open(&stale)
        .unwrap()
        .set_modified(an_hour_ago)
        .unwrap();
    // Someone's own file of a similar name stays.
    let theirs = d.join(".notes.tmp");
    std::fs::write(&theirs, "mine").unwrap();
    tb_table::write_atomic(&d.join("other.csv"), b"x").unwrap();
    assert!(!stale.exists(), "the stale temporary is swept");
    assert!(theirs.exists(), "a file twinbench did not name stays");
    // A fresh one (a writer at work) stays.
    let fresh = d.join(".lap.csv.fedcba9876543210.tmp");
    std::fs::write(&fresh, "being written").unwrap();
    tb_table::write_atomic(&d.join("other.csv"), b"y").unwrap();
    assert!(fresh.exists());
    std::fs::remove_file(&fresh).unwrap();

    // SIGTERM while a big result is written: no temporary stays.
    let fmus = common::fmu_dir();
    let text = std::fs::read_to_string(root().join("systems/rls_v.toml"))
        .unwrap()
        .replace("\"../target/fmu/", &format!("\"{}/", fmus.display()))
        .replace("decimation = 5", "decimation = 1");
    std::fs::write(d.join("sys.toml"), text).unwrap();
    let mut caught = false;
    for _ in 0..5 {
        let child = Command::new(env!("CARGO_BIN_EXE_twinbench"))
            .args(["run", "sys.toml", "--out", "big.csv"])
            .current_dir(d)
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        // Wait until the temporary appears, then stop the process.
        let started = std::time::Instant::now();
        let tmp_seen = loop {
            let seen = std::fs::read_dir(d).unwrap().flatten().any(|e| {
                let n = e.file_name().to_string_lossy().into_owned();
                n.starts_with(".big.csv.") && n.ends_with(".tmp")
            });
            if seen || started.elapsed().as_secs() > 60 {
                break seen;
            }
            std::thread::sleep(std::time::Duration::from_micros(200));
        };
        unsafe { libc::kill(child.id() as i32, libc::SIGTERM) };
        let o = child.wait_with_output().unwrap();
        assert!(!o.status.success());
        let left: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .flatten()
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".tmp") && n != ".notes.tmp")
            .collect();
        assert!(left.is_empty(), "left behind: {left:?}");
        if tmp_seen {
            caught = true;
            break;
        }
    }
    assert!(caught, "no write in progress caught in five runs");
    // A file size limit: an error naming the file, not a silent death by SIGXFSZ.
    let o = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -f 64; exec '{}' run sys.toml --out limited.csv",
            env!("CARGO_BIN_EXE_twinbench")
        ))
        .current_dir(d)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert_contains(&e, &["limited.csv", "File too large"]);
}

/// N9: an output folder that cannot be written was found only after the run.
#[test]
fn n09_an_unwritable_output_folder_is_refused_before_the_run() {
    let fmus = common::fmu_dir();
    let dir = tb_testkit::scratch("n09");
    let d = dir.path();
    let text = std::fs::read_to_string(root().join("systems/rls_v.toml"))
        .unwrap()
        .replace("\"../target/fmu/", &format!("\"{}/", fmus.display()));
    std::fs::write(d.join("sys.toml"), text).unwrap();
    // /proc takes no files, whoever we are (a read-only folder does not stop root).
    let started = std::time::Instant::now();
    let e = common::fails_in(d, ["run", "sys.toml", "--out", "/proc/twinbench/lap.csv"]);
    assert!(e.contains("cannot write into /proc"), "{e}");
    assert!(e.contains("(checked before the run)"), "{e}");
    assert!(!e.contains("steps"), "no run happened: {e}");
    let _ = started;
}

/// A checkpoint's JSON inside its wrapper, and the wrapper around edited JSON (an edit
/// made on purpose, with a digest to match).
fn checkpoint_parts(text: &str) -> serde_json::Value {
    let body = &text[text.find(",\"checkpoint\":").unwrap() + 14..text.trim_end().len() - 1];
    serde_json::from_str(body).unwrap()
}

fn rewrap(v: &serde_json::Value) -> String {
    use sha2::Digest;
    let body = serde_json::to_string_pretty(v).unwrap();
    let digest = format!("{:x}", sha2::Sha256::digest(body.as_bytes()));
    format!("{{\"sha256\":\"{digest}\",\"checkpoint\":{body}}}\n")
}

/// N13: a damaged or edited checkpoint was accepted and changed the result (or panicked).
#[test]
fn n13_an_edited_checkpoint_is_refused_whatever_was_edited() {
    let dir = tb_testkit::scratch("n13");
    let d = dir.path();
    let study = root().join("studies/spielberg.toml");
    let study = study.to_str().unwrap();
    let run = |resume: bool| {
        let mut args = vec![
            "optimize",
            study,
            "--generations",
            "1",
            "--no-report",
            "--json",
            "--out",
            "o",
        ];
        if resume {
            args.push("--resume");
        }
        common::twinbench_in(d, &args)
    };
    let first = run(false);
    common::cli::assert_success(&first);
    let path = d.join("o/spielberg.checkpoint.json");
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        run(true).status.success(),
        "an untouched checkpoint resumes"
    );
    // One changed byte of a value: the digest no longer matches.
    let at = text.find("\"cost_after\": ").unwrap() + 14;
    let mut edited = text.clone().into_bytes();
    edited[at] = if edited[at] == b'0' { b'1' } else { b'0' };
    std::fs::write(&path, &edited).unwrap();
    let e = String::from_utf8_lossy(&run(true).stderr).into_owned();
    assert!(e.contains("does not match its SHA-256"), "{e}");
    // Edits made on purpose, digest recomputed: what they say is checked.
    let v = checkpoint_parts(&text);
    let mut renamed = v.clone();
    renamed["completed"][0]["parameters"][0]["name"] = "vehicle.c_lift_frnt".into();
    let mut tripled = v.clone();
    let c = tripled["completed"][0].clone();
    tripled["completed"].as_array_mut().unwrap().push(c);
    let mut swapped = v.clone();
    swapped["completed"].as_array_mut().unwrap().swap(0, 1);
    let mut printed = v.clone();
    printed["completed"][1]["parameters"][0]["after"] = 3.333.into();
    let mut outside = v.clone();
    outside["completed"][0]["after_exact"][0] = "4059000000000000".into(); // 100.0
    for (what, edit, expected) in [
        ("a renamed parameter", renamed, "the study's are"),
        (
            "three completed steps",
            tripled,
            "3 completed steps, the study has 2",
        ),
        ("swapped steps", swapped, "completed step 1 is 'geometry'"),
        ("an edited printed value", printed, "(printed 3.333)"),
        (
            "a value outside the bounds",
            outside,
            "is not a value within",
        ),
    ] {
        std::fs::write(&path, rewrap(&edit)).unwrap();
        let o = run(true);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{what}: accepted");
        assert!(e.contains(expected), "{what}: {e}");
        assert!(!e.contains("panicked"), "{what}: {e}");
    }
}

/// N4: a path parameter read any file (a device until memory ran out, a FIFO for ever) and
/// echoed its content; an SSP package could make an FMU read any file of the user's.
#[test]
fn n04_path_parameters_read_regular_files_inside_a_package_and_echo_little() {
    let dir = tb_testkit::scratch("n04");
    let d = dir.path();
    bundled_lap(d);
    let fifo = d.join("fifo");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    for (file, expected) in [
        ("/dev/zero", "/dev/zero: is a device, not a regular file"),
        (fifo.to_str().unwrap(), "is a FIFO, not a regular file"),
    ] {
        let set = format!("vehicle.track_file={file}");
        let e = common::fails_in(d, ["run", "lap/system.toml", "--set", &set]);
        assert!(e.contains(expected), "{file}: {e}");
    }
    // A file whose first line is long and holds terminal escapes: a short excerpt, escaped.
    let secret = d.join("secret.csv");
    std::fs::write(
        &secret,
        format!("\u{1b}[31m{}\n1,2\n", "s3cret".repeat(2000)),
    )
    .unwrap();
    let set = format!("driver.target_speed_file={}", secret.display());
    let e = common::fails_in(d, ["run", "lap/system.toml", "--set", &set]);
    assert!(e.contains("no column"), "{e}");
    assert!(
        e.len() < 2000,
        "the content is echoed at length: {} bytes",
        e.len()
    );
    assert!(!e.contains('\u{1b}'), "{e}");
    // An SSP package: its path parameters are packed inside it, and one that climbs out
    // (or is absolute) is refused.
    common::ok_in(d, ["export-ssp", "lap/system.toml", "-o", "lap.ssp"]);
    common::ok_in(d, ["run", "lap.ssp"]);
    let ssd = {
        let f = std::fs::File::open(d.join("lap.ssp")).unwrap();
        let mut z = zip::ZipArchive::new(f).unwrap();
        let mut s = String::new();
        std::io::Read::read_to_string(&mut z.by_name("SystemStructure.ssd").unwrap(), &mut s)
            .unwrap();
        s
    };
    assert!(
        ssd.contains("resources/files/vehicle_track_file_track.csv"),
        "packed"
    );
    for escape in [
        "../../../../etc/passwd",
        "/etc/passwd",
        "file:///etc/passwd",
    ] {
        let evil = ssd.replace("resources/files/vehicle_track_file_track.csv", escape);
        let src = std::fs::File::open(d.join("lap.ssp")).unwrap();
        let mut z = zip::ZipArchive::new(src).unwrap();
        let out = std::fs::File::create(d.join("evil.ssp")).unwrap();
        let mut w = zip::ZipWriter::new(out);
        for i in 0..z.len() {
            let mut entry = z.by_index(i).unwrap();
            let name = entry.name().to_string();
            w.start_file(name.as_str(), zip::write::SimpleFileOptions::default())
                .unwrap();
            if name == "SystemStructure.ssd" {
                std::io::Write::write_all(&mut w, evil.as_bytes()).unwrap();
            } else {
                std::io::copy(&mut entry, &mut w).unwrap();
            }
        }
        w.finish().unwrap();
        let e = common::fails_in(d, ["run", "evil.ssp"]);
        assert!(
            e.contains("a path an SSP package sets must name a file inside the package"),
            "{escape}: {e}"
        );
    }
}

/// N29: degenerate tracks and targets ran (a lap of 1e-323 m in 0 s, a grade of 1e308
/// rad, a target of 1e308 m/s) and exited 0.
#[test]
fn n29_degenerate_tracks_and_targets_are_refused() {
    let dir = tb_testkit::scratch("n29");
    let d = dir.path();
    bundled_lap(d);
    let header = "s,curvature,grade,z_road_left,z_road_right\n";
    for (name, text, param, expected) in [
        (
            "tiny.csv",
            format!("{header}0,0,0,0,0\n5e-324,0,0,0,0\n"),
            "vehicle.track_file",
            "is not a circuit (at least 10 m)",
        ),
        (
            "steep.csv",
            format!("{header}0,0,0,0,0\n10,0,1e308,0,0\n20,0,0,0,0\n"),
            "vehicle.track_file",
            "column 'grade': 1e308 is more than a circuit has",
        ),
        (
            "fast.csv",
            "s,v\n0,50\n100,1e308\n200,50\n".to_string(),
            "driver.target_speed_file",
            "v = 1e308 m/s is faster than a car's target may be",
        ),
    ] {
        std::fs::write(d.join(name), text).unwrap();
        let set = format!("{param}={}", d.join(name).display());
        let e = common::fails_in(d, ["run", "lap/system.toml", "--set", &set]);
        assert!(e.contains(expected), "{name}: {e}");
    }
}

/// N28, the cosmetic ones: a UTF-8 byte order mark in a track or target file, a huge
/// number printed as 309 digits (the rest: tests/robustness_archive.rs for a library of
/// another machine, tests/fmi3_systems.rs for isolated FMI 3.0 names, fmu-export's
/// file URI test for `file://host/`).
#[test]
fn n28_a_byte_order_mark_is_read_and_huge_numbers_print_short() {
    let dir = tb_testkit::scratch("n28");
    let d = dir.path();
    bundled_lap(d);
    for file in ["lap/track.csv", "lap/target_speed.csv"] {
        let text = std::fs::read_to_string(d.join(file)).unwrap();
        std::fs::write(d.join(file), format!("\u{feff}{text}")).unwrap();
    }
    common::ok_in(d, ["run", "lap/system.toml"]);
    let e = common::fails_in(
        d,
        [
            "run",
            "lap/system.toml",
            "--set",
            "vehicle.c_lift_front=1e308",
        ],
    );
    assert!(e.contains("1e308 is outside the declared range"), "{e}");
    assert!(!e.contains("0000000000"), "{e}");
}

/// N12: a String value of 2 MiB read from an FMU (the test FMU's `tag_out` echoes its
/// `tag`) is refused with its size, in process and isolated, instead of being copied into
/// every recorded row until memory runs out.
#[test]
fn n12_a_huge_string_from_an_fmu_is_refused_with_its_size() {
    let dir = tb_testkit::scratch("n12");
    let fmu = common::fmu("faulty");
    let text = format!(
        "[fmus]\nf = {:?}\n\n[[instance]]\nname = \"a\"\nfmu = \"f\"\n\n[parameters]\n\"a.tag\" = \"{}\"\n\n[experiment]\nstep = 0.1\nstop = 0.5\n\n[record]\nsignals = [\"a.y\", \"a.tag_out\"]\n",
        fmu.display().to_string(),
        "x".repeat(2 << 20)
    );
    std::fs::write(dir.path().join("big.toml"), text).unwrap();
    for isolate in [false, true] {
        let mut args = vec!["run", "big.toml"];
        if isolate {
            args.push("--isolate");
        }
        let e = common::fails_in(dir.path(), &args);
        assert!(
            e.contains("fmi2GetString: value reference 9 holds")
                && e.contains("more than the 1 MiB twinbench exchanges and records"),
            "isolate {isolate}: {}",
            &e[..e.len().min(2000)]
        );
    }
}

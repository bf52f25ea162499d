//! A newcomer's first hour, as the README walks it: a lap of one's own prepared and
//! optimised from any folder, run from inside its own folder and after it moved, FMUs packed
//! where the help says, and the messages of the usual slips (a file that is an FMU, an FMU
//! that is not there, a channel-map typo, an output that is a file, a short track, Ctrl-C).

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;
use tb_testkit::assert_contains;

fn root() -> PathBuf {
    twinbench::pack::workspace_root()
}

/// `twinbench ARGS` in folder `cwd` must succeed: what it printed, standard output and error.
fn success(cwd: &Path, args: &[&str]) -> String {
    let what = format!("twinbench {args:?} in {}", cwd.display());
    let o = common::twinbench_in(cwd, args);
    common::cli::succeeded(&o, what);
    String::from_utf8_lossy(&o.stdout).into_owned() + &String::from_utf8_lossy(&o.stderr)
}

/// The bundled lap and its track, copied into `dir` (a user's own files, by relative name).
fn own_lap_files(dir: &Path) {
    for f in ["spielberg_lap.csv", "spielberg_lap_track.csv"] {
        std::fs::copy(root().join("data").join(f), dir.join(f)).unwrap();
    }
}

/// A scratch folder `tag` with [`own_lap_files`] and the `files` (name, text) in it.
fn own_lap_folder(tag: &str, files: &[(&str, &str)]) -> tempfile::TempDir {
    let dir = common::scratch_with(tag, files);
    own_lap_files(dir.path());
    dir
}

/// The bundled lap and its track copied into `dir`, and `twinbench lap` of them there with
/// `extra`: what it printed.
fn own_lap(dir: &Path, extra: &[&str]) -> String {
    own_lap_files(dir);
    let lap = [
        "lap",
        "spielberg_lap.csv",
        "--track",
        "spielberg_lap_track.csv",
    ];
    success(dir, &[&lap[..], extra].concat())
}

/// No `a/../b` or `a/./b` in what a command printed.
fn assert_normalised(text: &str) {
    assert!(
        !text.contains("/../") && !text.contains("/./"),
        "paths printed unnormalised:\n{text}"
    );
}

#[test]
fn a_lap_of_ones_own_is_prepared_optimised_and_run_by_relative_names_from_any_folder() {
    let dir = tb_testkit::scratch("first-hour-lap");
    let d = dir.path();
    let out = own_lap(d, &["--out", "mylap"]);
    assert_contains(&out, &["next: twinbench optimize mylap/study.toml"]);
    // The FMUs are packed beside the lap and named relative to its system file.
    let system = std::fs::read_to_string(d.join("mylap/system.toml")).unwrap();
    assert!(system.contains("vehicle = \"fmu/vehicle.fmu\""), "{system}");
    assert!(d.join("mylap/fmu/vehicle.fmu").is_file());
    assert!(
        !d.join("mylap/fmu/test").exists(),
        "the test FMU is not packed"
    );
    // The study by a relative name from the folder above...
    let opt = success(
        d,
        &[
            "optimize",
            "mylap/study.toml",
            "--generations",
            "1",
            "--no-report",
            "--out",
            "opt",
        ],
    );
    assert_normalised(&opt);
    // ...the system from inside its own folder...
    let run = success(
        &d.join("mylap"),
        &["run", "system.toml", "--out", "lap.csv"],
    );
    assert!(run.contains("lap time"), "{run}");
    // ...and the whole folder moved elsewhere (the checkout it was made from need not exist).
    std::fs::create_dir(d.join("elsewhere")).unwrap();
    std::fs::rename(d.join("mylap"), d.join("elsewhere/moved")).unwrap();
    let moved = success(&d.join("elsewhere"), &["run", "moved/system.toml"]);
    assert!(moved.contains("lap time"), "{moved}");
    // The measurement named relative to the study resolves after the move too (it stayed).
    let study = std::fs::read_to_string(d.join("elsewhere/moved/study.toml")).unwrap();
    assert!(study.contains("file = \"../spielberg_lap.csv\""), "{study}");
}

#[test]
fn lap_with_a_relative_fmu_folder_writes_paths_that_resolve_from_the_output_folder() {
    let dir = tb_testkit::scratch("first-hour-fmus");
    let d = dir.path();
    success(d, &["pack", "-o", "packed"]);
    own_lap(d, &["--fmus", "packed", "--out", "laps/one"]);
    let system = std::fs::read_to_string(d.join("laps/one/system.toml")).unwrap();
    assert_contains(&system, &["vehicle = \"../../packed/vehicle.fmu\""]);
    assert!(!d.join("laps/one/fmu").exists(), "--fmus: nothing packed");
    let out = success(&d.join("laps"), &["run", "one/system.toml"]);
    assert!(out.contains("lap time"), "{out}");
}

#[test]
fn a_system_file_named_through_dot_dot_prints_normalised_paths() {
    let fmus = common::fmu_dir();
    let dir = tb_testkit::scratch("first-hour-dotdot");
    let d = dir.path();
    std::fs::create_dir_all(d.join("studies")).unwrap();
    std::fs::create_dir_all(d.join("systems")).unwrap();
    let text = std::fs::read_to_string(root().join("systems/rls_v.toml"))
        .unwrap()
        .replace("\"../target/fmu/", &format!("\"{}/", fmus.display()))
        .replace("stop = \"vehicle.lap >= 1\"", "stop = 0.5");
    std::fs::write(d.join("systems/rls_v.toml"), text).unwrap();
    let out = success(
        d,
        &[
            "run",
            "studies/../systems/rls_v.toml",
            "--json",
            "--out",
            "studies/../x.csv",
        ],
    );
    assert!(d.join("x.csv").is_file());
    // The FMU paths the plan resolved are absolute and normalised.
    let plan = tb_cosim::Plan::load(
        &d.join("studies/../systems/rls_v.toml"),
        common::shared_cache(),
    )
    .unwrap();
    for f in plan.input_files() {
        assert!(f.is_absolute(), "{}", f.display());
        assert_normalised(&f.display().to_string());
    }
    assert!(out.contains("\"steps\""), "{out}");
}

#[test]
fn pack_writes_the_shipped_fmus_to_one_documented_place_and_the_test_fmu_only_when_named() {
    let dir = tb_testkit::scratch("first-hour-pack");
    let d = dir.path();
    let o = common::cli::output_ok(
        Command::new(env!("CARGO_BIN_EXE_twinbench"))
            .arg("pack")
            .env("XDG_DATA_HOME", d.join("data"))
            .current_dir(d),
    );
    let place = d.join("data/twinbench/fmu");
    let shipped: Vec<&str> = twinbench::pack::models()
        .iter()
        .filter(|s| !s.test_only)
        .map(|s| s.info.name)
        .collect();
    for m in ["vehicle", "driver", "dyno", "edu"].iter().chain(&shipped) {
        assert!(place.join(format!("{m}.fmu")).is_file(), "{m}.fmu");
    }
    assert!(!place.join("test").exists(), "faulty is a test FMU");
    let printed = String::from_utf8_lossy(&o.stdout);
    assert_eq!(printed.lines().count(), shipped.len(), "{printed}");
    // Without XDG_DATA_HOME: below HOME.
    common::cli::output_ok(
        Command::new(env!("CARGO_BIN_EXE_twinbench"))
            .args(["pack", "edu"])
            .env_remove("XDG_DATA_HOME")
            .env("HOME", d.join("home"))
            .current_dir(d),
    );
    assert!(d.join("home/.local/share/twinbench/fmu/edu.fmu").is_file());
    // The help says where.
    let help = success(d, &["pack", "--help"]);
    assert!(help.contains("~/.local/share/twinbench/fmu"), "{help}");
    // Named, the test FMU is packed under test/.
    success(d, &["pack", "faulty", "-o", "t"]);
    assert!(d.join("t/test/faulty.fmu").is_file());
}

#[test]
fn run_on_an_fmu_runs_it_and_on_another_zip_says_what_run_takes() {
    let dir = tb_testkit::scratch("first-hour-zip");
    let d = dir.path();
    // An FMU runs on its own (as `fmpy simulate` runs it).
    let out = success(
        d,
        &[
            "run",
            common::fmu("faulty").to_str().unwrap(),
            "--stop",
            "0.1",
        ],
    );
    assert!(out.contains("stopped by      stop time 0.1 s"), "{out}");
    // A ZIP archive under another name: what `run` takes.
    std::fs::copy(common::fmu("vehicle"), d.join("vehicle.zip")).unwrap();
    let e = common::fails_in(d, ["run", "vehicle.zip"]);
    assert_contains(&e, &["is a ZIP archive (an FMU?), not a system file"]);
    assert_contains(&e, &["SSP", ".fmu"]);
    assert!(!e.contains("UTF-8"), "{e}");
}

#[test]
fn a_missing_fmu_names_the_system_file_and_the_command_that_writes_it() {
    let dir = tb_testkit::scratch("first-hour-missing");
    let d = dir.path();
    std::fs::copy(root().join("systems/rls_v.toml"), d.join("copied.toml")).unwrap();
    let e = common::fails_in(d, ["run", "copied.toml"]);
    let expected = d.parent().unwrap().join("target/fmu");
    assert!(e.contains("copied.toml: [fmus] "), "{e}");
    assert!(e.contains("does not exist"), "{e}");
    assert_contains(
        &e,
        &[&format!("`twinbench pack -o {}`", expected.display())],
    );
}

#[test]
fn a_channel_map_typo_names_channel_signal_and_the_closest_channels() {
    let map = "[channels]\nFz_rl = \"Fz_lr\"\n";
    let dir = own_lap_folder("first-hour-map", &[("map.toml", map)]);
    let d = dir.path();
    let e = common::fails_in(
        d,
        [
            "lap",
            "spielberg_lap.csv",
            "--channels",
            "map.toml",
            "--out",
            "x",
        ],
    );
    assert_contains(
        &e,
        &["no channel `Fz_lr` (the channel map's name for signal `Fz_rl`)"],
    );
    let closest = e
        .split("closest channels: ")
        .nth(1)
        .expect("closest channels");
    let closest: Vec<&str> = closest.split(" (").next().unwrap().split(", ").collect();
    assert_eq!(closest.len(), 3, "{e}");
    assert!(
        closest.contains(&"Fz_rl"),
        "the swapped letters are one edit away: {e}"
    );
    assert_eq!(e.matches('`').count() % 2, 0, "unbalanced quotes: {e}");
    assert_eq!(e.matches('(').count(), e.matches(')').count(), "{e}");
}

#[test]
fn os_errors_and_paths_are_said_once() {
    let dir = own_lap_folder("first-hour-once", &[("afile", "x")]);
    let d = dir.path();
    let e = common::fails_in(d, ["lap", "nothere.csv", "--out", "x"]);
    assert_eq!(e.matches("os error").count(), 1, "{e}");
    assert_eq!(e.matches("nothere.csv").count(), 1, "{e}");
    let e = common::fails_in(d, ["lap", "spielberg_lap.csv", "--out", "afile"]);
    assert_eq!(e.matches("os error").count(), 1, "{e}");
    assert!(e.contains("afile: cannot create the output folder"), "{e}");
    let e = common::fails_in(d, ["pack", "-o", "afile"]);
    assert_eq!(e.matches("afile").count(), 1, "{e}");
    let e = common::fails_in(d, ["demo", "--out", "afile"]);
    assert!(e.contains("afile"), "demo names the path: {e}");
    assert_eq!(e.matches("os error").count(), 1, "{e}");
}

#[test]
fn lap_refuses_a_track_of_another_length() {
    let dir = own_lap_folder("first-hour-track", &[]);
    let d = dir.path();
    // The circuit's track with its last 30 % cut off.
    let track = std::fs::read_to_string(d.join("spielberg_lap_track.csv")).unwrap();
    let lines: Vec<&str> = track.lines().collect();
    let short = lines[..lines.len() * 7 / 10].join("\n");
    std::fs::write(d.join("short.csv"), short).unwrap();
    let e = common::fails_in(
        d,
        [
            "lap",
            "spielberg_lap.csv",
            "--track",
            "short.csv",
            "--out",
            "x",
        ],
    );
    assert!(e.contains("short.csv: the track is"), "{e}");
    assert!(e.contains("the bench accepts ±0.5 %"), "{e}");
    assert!(!d.join("x/system.toml").exists(), "nothing written");
}

/// Ctrl-C in `optimize`: the study stops after the generation under way, says so with the
/// command that resumes it, exits 130, and the resume says where it continues.
#[test]
fn ctrl_c_keeps_the_checkpoint_and_says_how_to_resume() {
    let dir = tb_testkit::scratch("first-hour-ctrl-c");
    let d = dir.path();
    own_lap(d, &["--out", "mylap"]);
    // Interrupt once the first generation is checkpointed.
    let checkpoint = d.join("opt/mylap.checkpoint.json");
    let args = [
        "optimize",
        "mylap/study.toml",
        "--no-report",
        "--out",
        "opt",
    ];
    let o = common::cli::interrupted_in(d, args, &checkpoint);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(130), "{e}");
    assert_contains(&e, &["interrupt: stopping after the generation under way"]);
    assert_contains(&e, &["interrupted: checkpoint kept (opt/mylap.checkpoint.json); resume with `twinbench optimize mylap/study.toml --resume --out opt`"]);
    assert!(checkpoint.is_file());
    // The resume, as printed (one generation more, to be quick).
    let out = success(
        d,
        &[
            "optimize",
            "mylap/study.toml",
            "--resume",
            "--out",
            "opt",
            "--no-report",
        ],
    );
    assert_contains(&out, &["resuming step 1 'lift' from generation "]);
}

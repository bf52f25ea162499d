//! The exported FMUs through their C symbols (not the Rust API): call order, panics,
//! independence of instances, FMU states, reset, bad input.

mod common;

use common::kinds::{refused, refused_at};

use common::{load, vr};
use fmu_export::fmi2::*;
use std::ffi::CString;
use std::path::Path;
use tb_fmi::{FmuError, FmuInstance, Function, Instance, LoadedFmu};
use tb_testkit::assert_contains;

fn faulty(name: &str) -> (std::sync::Arc<tb_fmi::LoadedFmu>, Instance) {
    let f = load("faulty");
    let i = common::instantiate(&f, name, true);
    (f, i)
}

fn init(i: &mut Instance) {
    i.setup_experiment(0.0.into()).unwrap();
    i.enter_initialization_mode().unwrap();
    i.exit_initialization_mode().unwrap();
}

#[test]
fn every_co_simulation_function_is_exported() {
    let f = load("faulty");
    let so = f.dir.join("binaries/linux64/faulty.so");
    // Every function of the table, the optional ones too.
    for spec in tb_fmi::FUNCTIONS {
        assert!(
            tb_fmi::Library::has_symbol(&so, spec.name),
            "{} missing",
            spec.name
        );
    }
    let md = &f.description;
    let cs = md.co_simulation.as_ref().unwrap();
    assert!(cs.can_get_and_set_fmu_state && cs.can_serialize_fmu_state);
    assert!(!cs.can_be_instantiated_only_once_per_process);
}

#[test]
fn illegal_call_sequences_return_error_with_a_message() {
    let (f, mut i) = faulty("order");
    // Step before initialisation: refused with fmi2Error, the FMU's log says why.
    let e = i.do_step(0.0, 0.1).unwrap_err();
    assert!(refused(&e, Function::DoStep, fmi2Status::ERROR), "{e}");
    assert_contains(
        &e.to_string(),
        &["fmi2DoStep is not allowed in state 'instantiated'"],
    );
    // Exit without enter.
    let e = i.exit_initialization_mode().unwrap_err();
    assert!(
        refused(&e, Function::ExitInitializationMode, fmi2Status::ERROR),
        "{e}"
    );
    assert!(
        e.to_string()
            .contains("not allowed in state 'instantiated'"),
        "{e}"
    );
    init(&mut i);
    // Setup after initialisation, and setting a fixed parameter after it.
    assert!(i.setup_experiment(0.0.into()).is_err());
    let e = i.set_integer(&[vr(&f, "fault_kind")], &[1]).unwrap_err();
    assert!(refused(&e, Function::SetInteger, fmi2Status::ERROR), "{e}");
    assert_contains(
        &e.to_string(),
        &["'fault_kind' (fixed parameter) cannot be set in state 'step complete'"],
    );
    // Calculated output cannot be set; unknown value reference; wrong type.
    assert!(i.set_real(&[vr(&f, "y")], &[1.0]).is_err());
    let e = i.set_real(&[9999], &[1.0]).unwrap_err();
    assert!(refused(&e, Function::SetReal, fmi2Status::ERROR), "{e}");
    assert!(
        e.to_string().contains("unknown value reference 9999"),
        "{e}"
    );
    let e = i.get_real(&[vr(&f, "steps")], &mut [0.0]).unwrap_err();
    assert!(refused(&e, Function::GetReal, fmi2Status::ERROR), "{e}");
    assert!(
        e.to_string()
            .contains("'steps' (vr 6) is Integer, not Real"),
        "{e}"
    );
    // Legal again: a step works, terminate, then no more steps.
    i.do_step(0.0, 0.1).unwrap();
    i.terminate().unwrap();
    assert!(i.do_step(0.1, 0.1).is_err());
}

#[test]
fn bad_values_are_refused_naming_the_variable() {
    let (f, mut i) = faulty("bad");
    let e = i.set_real(&[vr(&f, "gain")], &[2e6]).unwrap_err();
    assert!(refused(&e, Function::SetReal, fmi2Status::ERROR), "{e}");
    assert_contains(
        &e.to_string(),
        &["'gain' = 2000000 is outside its range [-1000000, 1000000] 1"],
    );
    let e = i.set_real(&[vr(&f, "gain")], &[f64::NAN]).unwrap_err();
    assert!(refused(&e, Function::SetReal, fmi2Status::ERROR), "{e}");
    assert_contains(
        &e.to_string(),
        &["'gain' set to NaN, expected a finite number"],
    );
    init(&mut i);
    let e = i.do_step(0.0, 0.0).unwrap_err();
    assert!(refused(&e, Function::DoStep, fmi2Status::ERROR), "{e}");
    assert_contains(
        &e.to_string(),
        &["communicationStepSize must be positive and finite, got 0"],
    );
    assert!(i.do_step(0.0, -1e-3).is_err());
}

#[test]
fn wrong_guid_is_refused_with_a_message() {
    let f = load("faulty");
    let e = Instance::instantiate(
        f.library().unwrap(),
        "guid",
        "{00000000-0000-0000-0000-000000000000}",
        None,
        false,
    )
    .err()
    .unwrap();
    // Refused by the FMU (NULL): its log, in the message, says why.
    assert!(
        matches!(&e, FmuError::Instantiate { instance, .. } if instance == "guid"),
        "{e}"
    );
    assert!(e.to_string().contains("GUID mismatch"), "{e}");
    assert!(e.to_string().contains(&f.description.guid), "{e}");
}

#[test]
fn percent_in_messages_survives_the_printf_logger() {
    let (_f, mut i) = faulty("percent");
    let e = i.set_debug_categories(true, &["100%s%d"]).unwrap_err();
    assert!(
        refused(&e, Function::SetDebugLogging, fmi2Status::ERROR),
        "{e}"
    );
    assert!(
        e.to_string().contains("unknown log category '100%s%d'"),
        "{e}"
    );
}

#[test]
fn a_panicking_model_returns_error_and_the_host_lives() {
    let (f, mut i) = faulty("panics");
    i.set_integer(&[vr(&f, "fault_kind")], &[2]).unwrap();
    i.set_real(&[vr(&f, "fault_time")], &[0.5]).unwrap();
    init(&mut i);
    for k in 0..5 {
        i.do_step(k as f64 * 0.1, 0.1).unwrap();
    }
    let e = i.do_step(0.5, 0.1).unwrap_err();
    assert!(refused(&e, Function::DoStep, fmi2Status::ERROR), "{e}");
    assert_contains(
        &e.to_string(),
        &["the model panicked: fault_kind = 2: the model panics on purpose"],
    );
    // Poisoned: further calls refused, reset recovers.
    let e = i.get_real(&[vr(&f, "y")], &mut [0.0]).unwrap_err();
    assert!(refused(&e, Function::GetReal, fmi2Status::ERROR), "{e}");
    assert!(e.to_string().contains("unusable until fmi2Reset"), "{e}");
    i.reset().unwrap();
    init(&mut i);
    i.do_step(0.0, 0.1).unwrap();
}

#[test]
fn null_pointers_are_errors_not_crashes() {
    let (f, i) = faulty("nulls");
    let library = f.library().unwrap();
    let api = &library.api;
    let c = i.raw();
    unsafe {
        assert_eq!(
            (api.fmi2DoStep)(std::ptr::null_mut(), 0.0, 0.1, 1),
            fmi2Status::ERROR
        );
        assert_eq!(
            (api.fmi2GetReal)(c, std::ptr::null(), 2, std::ptr::null_mut()),
            fmi2Status::ERROR
        );
        assert_eq!(
            (api.fmi2GetReal)(c, std::ptr::null(), 0, std::ptr::null_mut()),
            fmi2Status::OK
        );
        assert_eq!(
            (api.fmi2SetFMUstate.unwrap())(c, std::ptr::null_mut()),
            fmi2Status::ERROR
        );
        let name = CString::new("x").unwrap();
        let guid = CString::new(f.description.guid.clone()).unwrap();
        // No callback functions at all: NULL, no crash.
        let comp = (api.fmi2Instantiate)(
            name.as_ptr(),
            fmi2Type::CO_SIMULATION,
            guid.as_ptr(),
            std::ptr::null(),
            std::ptr::null(),
            0,
            0,
        );
        assert!(comp.is_null());
        (api.fmi2FreeInstance)(std::ptr::null_mut());
    }
}

fn trajectory(f: &tb_fmi::LoadedFmu, i: &mut Instance, from: usize, n: usize) -> Vec<f64> {
    let (u, y) = (vr(f, "u"), vr(f, "y"));
    let mut out = Vec::new();
    for k in from..from + n {
        i.set_real(&[u], &[(k as f64 * 0.37).sin()]).unwrap();
        i.do_step(k as f64 * 0.01, 0.01).unwrap();
        let mut v = [0.0];
        i.get_real(&[y], &mut v).unwrap();
        out.push(v[0]);
    }
    out
}

#[test]
fn two_instances_with_different_parameters_stay_independent() {
    let (f, mut a) = faulty("a");
    let (_, mut b) = faulty("b");
    a.set_real(&[vr(&f, "gain")], &[2.0]).unwrap();
    b.set_real(&[vr(&f, "gain")], &[-3.0]).unwrap();
    init(&mut a);
    init(&mut b);
    let ya = trajectory(&f, &mut a, 0, 50);
    let yb = trajectory(&f, &mut b, 0, 50);
    for (x, y) in ya.iter().zip(&yb) {
        assert!((x / 2.0 + y / 3.0).abs() < 1e-12, "{x} {y}");
    }
    assert!(
        ya.iter().any(|x| x.abs() > 0.05),
        "trajectory too small to tell instances apart"
    );
}

#[test]
fn restored_and_deserialized_states_repeat_bit_for_bit() {
    let (f, mut i) = faulty("state");
    init(&mut i);
    trajectory(&f, &mut i, 0, 30);
    let saved = i.get_state().unwrap();
    let bytes = i.serialize_state(&saved).unwrap();
    let first = trajectory(&f, &mut i, 30, 40);
    i.set_state(&saved, 0.3).unwrap();
    let again = trajectory(&f, &mut i, 30, 40);
    assert_eq!(
        first.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        again.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
    // Deserialized into another, fresh instance.
    let (_, mut other) = faulty("other");
    let st = other.deserialize_state(&bytes).unwrap();
    other.set_state(&st, 0.3).unwrap();
    let third = trajectory(&f, &mut other, 30, 40);
    assert_eq!(
        first.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        third.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
    // Garbage is refused with a message.
    let e = other.deserialize_state(b"not a state").err().unwrap();
    assert!(
        refused(&e, Function::DeSerializeFMUstate, fmi2Status::ERROR),
        "{e}"
    );
    assert!(e.to_string().contains("bad magic"), "{e}");
    let e = other
        .deserialize_state(&bytes[..bytes.len() - 3])
        .err()
        .unwrap();
    assert!(
        refused(&e, Function::DeSerializeFMUstate, fmi2Status::ERROR),
        "{e}"
    );
    assert!(e.to_string().contains("truncated"), "{e}");
    other.free_state(st).unwrap();
    i.free_state(saved).unwrap();
}

#[test]
fn reset_then_rerun_repeats_bit_for_bit() {
    let (f, mut i) = faulty("reset");
    i.set_real(&[vr(&f, "gain")], &[1.5]).unwrap();
    init(&mut i);
    let first = trajectory(&f, &mut i, 0, 100);
    i.reset().unwrap();
    i.set_real(&[vr(&f, "gain")], &[1.5]).unwrap();
    init(&mut i);
    let again = trajectory(&f, &mut i, 0, 100);
    assert_eq!(
        first.iter().map(|x| x.to_bits()).collect::<Vec<_>>(),
        again.iter().map(|x| x.to_bits()).collect::<Vec<_>>()
    );
}

#[test]
fn error_from_a_step_names_the_instance_and_time() {
    let (f, mut i) = faulty("fails");
    i.set_integer(&[vr(&f, "fault_kind")], &[1]).unwrap();
    init(&mut i);
    for k in 0..100 {
        i.do_step(k as f64 * 0.01, 0.01).unwrap();
    }
    let e = i.do_step(1.0, 0.01).unwrap_err();
    assert!(
        refused_at(&e, "fails", Function::DoStep, fmi2Status::ERROR, 1.0),
        "{e}"
    );
    // The message as the user reads it: the instance and the time first, then the FMU's.
    assert!(
        e.to_string()
            .starts_with("instance 'fails' at t = 1 s: fmi2DoStep returned fmi2Error"),
        "{e}"
    );
    assert_contains(
        &e.to_string(),
        &["at t = 1 s: fault_kind = 1: the step fails on purpose"],
    );
}

#[test]
fn many_instances_per_process() {
    let f = load("faulty");
    let mut v: Vec<Instance> = (0..64)
        .map(|k| {
            Instance::instantiate(
                f.library().unwrap(),
                &format!("i{k}"),
                &f.description.guid,
                None,
                false,
            )
            .unwrap()
        })
        .collect();
    for (k, i) in v.iter_mut().enumerate() {
        i.set_real(&[vr(&f, "gain")], &[k as f64]).unwrap();
        init(i);
        i.set_real(&[vr(&f, "u")], &[1.0]).unwrap();
        i.do_step(0.0, 1.0).unwrap();
    }
    for (k, i) in v.iter_mut().enumerate() {
        let mut y = [0.0];
        i.get_real(&[vr(&f, "y")], &mut y).unwrap();
        assert_eq!(y[0], k as f64);
    }
}

#[test]
fn packing_twice_gives_identical_fmus() {
    let dir = common::fmu_dir();
    let path = common::fmu("faulty");
    let before = std::fs::read(&path).unwrap();
    twinbench::pack::pack(&["faulty".to_string()], &dir).unwrap();
    assert_eq!(before, std::fs::read(&path).unwrap());
}

/// An instance `name` of `f` with the resources in `resources`, initialised: the error its
/// exit from initialisation mode returns.
fn initialisation_error(f: &LoadedFmu, name: &str, resources: &Path) -> FmuError {
    let mut i = Instance::instantiate(
        f.library().unwrap(),
        name,
        &f.description.guid,
        Some(resources),
        false,
    )
    .unwrap();
    i.setup_experiment(0.0.into()).unwrap();
    i.enter_initialization_mode().unwrap();
    i.exit_initialization_mode().unwrap_err()
}

#[test]
fn missing_or_malformed_resource_is_an_error_naming_the_file() {
    let f = load("driver");
    // No resources folder at all.
    let scratch = tb_testkit::scratch("noresources");
    let empty = scratch.path().to_path_buf();
    let e = initialisation_error(&f, "drv", &empty);
    assert!(
        refused(&e, Function::ExitInitializationMode, fmi2Status::ERROR),
        "{e}"
    );
    assert!(e.to_string().contains("target_speed.csv"), "{e}");
    // A malformed file: the row is named.
    std::fs::write(empty.join("target_speed.csv"), "s,v\n0,10\n1,abc\n2,12\n").unwrap();
    let e = initialisation_error(&f, "drv2", &empty);
    assert!(
        refused(&e, Function::ExitInitializationMode, fmi2Status::ERROR),
        "{e}"
    );
    assert_contains(&e.to_string(), &["target_speed.csv", "abc"]);
    std::fs::remove_dir_all(&empty).unwrap();
}

/// Every shipped model (the registry's): its documentation page lists every variable; a
/// model that ships data files ships a NOTICE naming each of them, and data from the
/// Spielberg lap carries its licences.
#[test]
fn every_fmu_ships_its_documentation_and_notices() {
    let shipped: Vec<_> = twinbench::pack::models()
        .into_iter()
        .filter(|s| !s.test_only)
        .collect();
    assert!(shipped.len() >= 4, "the registry lists the bench's models");
    for spec in shipped {
        let name = spec.info.name;
        let f = load(name);
        let doc = std::fs::read_to_string(f.dir.join("documentation/index.html")).unwrap();
        assert!(
            doc.contains("<table>") && doc.contains(&f.description.guid),
            "{name}"
        );
        for v in &f.description.variables {
            assert!(
                doc.contains(&format!("<code>{}</code>", v.name)),
                "{name}: {} missing in the documentation",
                v.name
            );
        }
        let data: Vec<&str> = spec
            .info
            .resources
            .iter()
            .map(|r| r.name)
            .filter(|n| *n != "NOTICE")
            .collect();
        if data.is_empty() {
            continue;
        }
        let notice = std::fs::read_to_string(f.resource_dir().join("NOTICE"))
            .unwrap_or_else(|e| panic!("{name} ships {data:?} but no NOTICE: {e}"));
        for file in &data {
            assert!(
                notice.contains(file),
                "{name}: the NOTICE does not name {file}"
            );
        }
        if notice.contains("Spielberg") {
            assert!(
                notice.contains("LGPL-3.0") && notice.contains("OpenStreetMap"),
                "{name}: {notice}"
            );
        }
    }
}

/// Red team P7, FMI 2.0: a hostile host's double free, call after free, foreign FMU state
/// and endless step are refused with fmi2Error and a logged reason, never followed.
#[test]
fn a_hostile_hosts_double_free_call_after_free_foreign_state_and_endless_step_are_refused() {
    let f = load("vehicle");
    let mut i = common::instantiate(&f, "hostile-host", true);
    init(&mut i);
    let library = f.library().unwrap();
    let api = &library.api;
    let c = i.raw();
    let said = |i: &Instance| i.last_log_lines().join("\n");
    unsafe {
        let started = std::time::Instant::now();
        assert_eq!((api.fmi2DoStep)(c, 0.0, 1e300, 1), fmi2Status::ERROR);
        assert!(started.elapsed() < std::time::Duration::from_secs(5));
        assert!(said(&i).contains("internal steps"), "{}", said(&i));
        let mut bogus = [0u64; 64];
        let foreign = bogus.as_mut_ptr() as fmi2FMUstate;
        assert_eq!(
            (api.fmi2SetFMUstate.unwrap())(c, foreign),
            fmi2Status::ERROR
        );
        let mut s: fmi2FMUstate = std::ptr::null_mut();
        assert_eq!((api.fmi2GetFMUstate.unwrap())(c, &mut s), fmi2Status::OK);
        let mut again = s;
        assert_eq!((api.fmi2FreeFMUstate.unwrap())(c, &mut s), fmi2Status::OK);
        assert_eq!(
            (api.fmi2FreeFMUstate.unwrap())(c, &mut again),
            fmi2Status::ERROR
        );
        assert!(
            said(&i).contains("not one of this instance's"),
            "{}",
            said(&i)
        );
        assert_eq!(bogus, [0u64; 64]);
        // A made-up instance pointer.
        assert_eq!(
            (api.fmi2DoStep)(foreign as fmi2Component, 0.0, 1e-3, 1),
            fmi2Status::ERROR
        );
        // Freed by the host, then used and freed again (the Instance's own drop frees it a
        // third time): refused each time.
        (api.fmi2FreeInstance)(c);
        let mut y = [0.0];
        let v = vr(&f, "v");
        assert_eq!(
            (api.fmi2GetReal)(c, &v, 1, y.as_mut_ptr()),
            fmi2Status::ERROR
        );
        (api.fmi2FreeInstance)(c);
    }
    let log = said(&i);
    assert!(log.contains("the instance was freed"), "{log}");
}

//! Native models (no FMI boundary) against the FMUs: the same code in the same order must
//! give bit-identical recordings.

mod common;

use std::sync::Arc;
use tb_cosim::{LoadOptions, Plan, Simulation, Table};
use tb_fmi::FmuCache;

fn run(native: bool, set: &[(&str, f64)]) -> (Simulation, Table) {
    common::fmu_dir();
    let path = twinbench::pack::workspace_root().join("systems/rls_v.toml");
    let cache = Arc::new(FmuCache::temporary(false).unwrap());
    let system = Plan::load_with(
        &path,
        cache,
        &LoadOptions {
            native,
            native_models: twinbench::registry::native_models(),
            ..Default::default()
        },
    )
    .unwrap();
    assert!(
        system.warnings.is_empty(),
        "warnings: {:?}",
        system.warnings
    );
    let kind = if native { "native" } else { "fmu" };
    for i in &system.instances {
        assert_eq!(i.factory.kind(), kind, "instance {}", i.name);
    }
    let mut sim = Simulation::new(system).unwrap();
    sim.echo_fmu_log = false;
    for (k, v) in set {
        sim.set_parameter(k, toml::Value::Float(*v)).unwrap();
    }
    sim.run().unwrap();
    let rec = sim.recording().clone();
    (sim, rec)
}

fn assert_bit_identical(a: &Table, b: &Table) {
    assert_eq!(a.names(), b.names());
    assert_eq!(a.len(), b.len());
    for (k, (x, y)) in a.columns().iter().zip(b.columns()).enumerate() {
        if let Some(i) = x
            .iter()
            .zip(y)
            .position(|(p, q)| p.to_bits() != q.to_bits())
        {
            panic!(
                "{} differs at row {i}: {} (FMU) vs {} (native)",
                a.names()[k],
                x[i],
                y[i]
            );
        }
    }
}

#[test]
fn native_lap_is_bit_identical_to_the_fmu_lap() {
    let (_, fmu) = run(false, &[]);
    let (mut sim, native) = run(true, &[]);
    assert!(fmu.len() > 19_000, "a whole lap: {} rows", fmu.len());
    assert_bit_identical(&fmu, &native);
    // Reused (reset) native instances with a changed parameter agree as well.
    sim.set_parameter("vehicle.c_lift_front", toml::Value::Float(0.9))
        .unwrap();
    sim.run().unwrap();
    let (_, fmu2) = run(false, &[("vehicle.c_lift_front", 0.9)]);
    assert_bit_identical(&fmu2, sim.recording());
}

#[test]
fn native_errors_name_the_instance_and_keep_the_log() {
    use tb_cosim::backend::BackendFactory;
    use tb_cosim::native::NativeFactory;
    let cache = FmuCache::temporary(false).unwrap();
    let fmu = cache.load(&common::fmu("dyno")).unwrap();
    let f = NativeFactory::for_fmu(&fmu, &twinbench::registry::native_models()).unwrap();
    assert_eq!(f.model(), "dyno");
    let mut b = f.create("dyno_x", false).unwrap();
    b.setup_experiment(tb_fmi::Experiment {
        start: 0.0,
        stop: Some(1.0),
        tolerance: None,
    })
    .unwrap();
    // Stepping before initialisation is refused like the FMU refuses it.
    let e = b.do_step(0.0, 1e-3).unwrap_err();
    assert!(
        matches!(
            &e,
            tb_fmi::FmuError::Call {
                instance,
                function: tb_fmi::FmiFunction::Fmi2(tb_fmi::Function::DoStep),
                status: tb_fmi::CallStatus::Fmi2(tb_fmi::fmi2::fmi2Status::ERROR),
                ..
            } if instance == "dyno_x"
        ),
        "{e}"
    );
    assert!(e.to_string().contains("not allowed"), "{e}");
}

//! The models' step and numeric get/set paths do not allocate: each model runs natively
//! through the same `fmu_export::Runtime` its FMU uses, under a counting allocator.

use fmu_export::fmi2::fmi2Status;
use fmu_export::{Model, NullLogger, Runtime, Value, VarTable};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        System.alloc(layout)
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout)
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
        System.realloc(ptr, layout, new_size)
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(|c| c.get())
}

/// Initialise `M` with `inputs`, then step 1 ms at a time, setting every input and reading
/// every real output each step; returns the allocations counted during the stepping.
fn allocations_while_stepping<M: Model>(
    resources: Option<&str>,
    inputs: &[(&str, f64)],
    steps: usize,
) -> u64 {
    let dir = resources.map(|r| twinbench::pack::workspace_root().join(r));
    let mut rt = Runtime::<M>::new("noalloc", dir, Box::new(NullLogger), false);
    assert_eq!(rt.setup_experiment(0.0, None), fmi2Status::OK);
    assert_eq!(rt.enter_initialization_mode(), fmi2Status::OK);
    for (n, v) in inputs {
        assert_eq!(rt.set_by_name(n, Value::Real(*v)), fmi2Status::OK, "{n}");
    }
    assert_eq!(rt.exit_initialization_mode(), fmi2Status::OK);
    let vrs_in: Vec<u32> = inputs
        .iter()
        .map(|(n, _)| M::Vars::vr_of(n).unwrap())
        .collect();
    let vals_in: Vec<f64> = inputs.iter().map(|(_, v)| *v).collect();
    let vrs_out: Vec<u32> = M::Vars::VARIABLES
        .iter()
        .filter(|v| {
            v.causality == fmu_export::variables::Causality::Output
                && v.var_type() == fmu_export::variables::ScalarType::Real
        })
        .map(|v| v.value_reference)
        .collect();
    let mut out = vec![0.0; vrs_out.len()];
    let before = allocations();
    for k in 0..steps {
        let s = rt.set(
            "fmi2SetReal",
            fmu_export::variables::ScalarType::Real,
            &vrs_in,
            vals_in.iter().map(|x| Value::Real(*x)),
        );
        assert_eq!(s, fmi2Status::OK);
        assert_eq!(rt.do_step(k as f64 * 1e-3, 1e-3), fmi2Status::OK);
        let s = rt.get(
            "fmi2GetReal",
            fmu_export::variables::ScalarType::Real,
            &vrs_out,
            &mut out,
            |v| v.as_f64(),
        );
        assert_eq!(s, fmi2Status::OK);
    }
    allocations() - before
}

/// [`allocations_while_stepping`] for 3000 steps counts none.
fn steps_without_allocating<M: Model>(name: &str, resources: Option<&str>, inputs: &[(&str, f64)]) {
    let n = allocations_while_stepping::<M>(resources, inputs, 3000);
    assert_eq!(n, 0, "{name} allocated {n} times in 3000 steps");
}

#[test]
fn vehicle_steps_without_allocating() {
    let w = 52.43 / 0.345;
    steps_without_allocating::<vehicle::Vehicle>(
        "vehicle",
        Some("models/vehicle/resources"),
        &[("omega_rl", w), ("omega_rr", w), ("brake_pedal", 0.0)],
    );
}

#[test]
fn driver_steps_without_allocating() {
    steps_without_allocating::<driver::Driver>(
        "driver",
        Some("models/driver/resources"),
        &[("v", 50.0), ("s", 10.0)],
    );
}

#[test]
fn dyno_steps_without_allocating() {
    steps_without_allocating::<dyno::Dyno>(
        "dyno",
        None,
        &[("shaft_torque", 100.0), ("torque_setpoint", 80.0)],
    );
}

#[test]
fn edu_steps_without_allocating() {
    steps_without_allocating::<edu::Edu>(
        "edu",
        None,
        &[
            ("accel_pedal", 0.5),
            ("omega_left", 150.0),
            ("omega_right", 150.0),
        ],
    );
}

#[test]
fn the_counter_sees_allocations() {
    let before = allocations();
    let v: Vec<u64> = (0..100).collect();
    assert!(allocations() > before && v.len() == 100);
}

//! The export runtime tested in its own crate, without packing an FMU: a small model here,
//! driven through the safe runtime and through the generic C entry points.

use fmu_export::fmi2::*;
use fmu_export::variables::*;
use fmu_export::{
    Context, Function, Model, ModelError, ModelInfo, ModelState, Phase, Runtime, Value,
};
use tb_testkit::assert_contains;
use tb_testkit::Capture;

fmu_export::variables! {
    /// An integrator with a feed-through output and a switchable fault.
    pub struct CounterVars {
        gain: Real = 1.0 => tunable(1).unit("1").range(-10.0, 10.0).describe("Integrator gain"),
        offset: Real = 0.0 => parameter(2).unit("1").describe("Offset of the direct output"),
        u: Real = 0.0 => input(3).unit("1").range(-100.0, 100.0).describe("Input"),
        y: Real = 0.0 => output(4).unit("s").describe("Integral of gain·u"),
        y_direct: Real = 0.0 => output(5).unit("1").depends_on(&[u])
            .describe("gain·u + offset"),
        fault: Integer = 0 => parameter(6).range(0.0, 3.0)
            .describe("From t = 1 s: 0 none, 1 error, 2 panic, 3 discard"),
        label: String = "a <label> & \"quotes\"" => tunable(7).describe("A tunable text"),
        source_file: String = "" => parameter(8).describe("A fixed text (a file name)"),
    }
}

fmu_export::states! {
    /// The whole model is its dynamic state.
    #[derive(Clone, Debug)]
    pub struct Counter for Counter {
        y: f64,
    }
}

impl Model for Counter {
    type Vars = CounterVars;
    const INFO: ModelInfo = ModelInfo::new("counter", "Integrator for the runtime's tests", "0")
        .experiment(2.0, 0.1)
        .documentation("<p>y = ∫ gain·u dt</p>");

    fn initialize(vars: &mut CounterVars, _ctx: &Context) -> Result<Self, ModelError> {
        vars.y = 0.0;
        Ok(Counter { y: 0.0 })
    }

    fn do_step(&mut self, vars: &mut CounterVars, time: f64, step: f64) -> Result<(), ModelError> {
        if time + step > 1.0 + 1e-12 {
            match vars.fault {
                1 => return Err(ModelError::new("the step fails on purpose")),
                2 => panic!("the model panics on purpose"),
                3 => return Err(ModelError::discard("the step is discarded on purpose")),
                _ => {}
            }
        }
        self.y += vars.gain * vars.u * step;
        vars.y = self.y;
        Ok(())
    }

    fn calculate_outputs(&mut self, vars: &mut CounterVars) {
        vars.y_direct = vars.gain * vars.u + vars.offset;
    }
}

impl ModelState for Counter {}

const VR_GAIN: u32 = 1;
const VR_OFFSET: u32 = 2;
const VR_U: u32 = 3;
const VR_Y: u32 = 4;
const VR_Y_DIRECT: u32 = 5;

fn runtime() -> (Runtime<Counter>, Capture) {
    let cap = Capture::default();
    (Runtime::new("counter", None, cap.boxed(), true), cap)
}

/// A runtime brought into `phase` by legal calls.
fn in_phase(phase: Phase) -> (Runtime<Counter>, Capture) {
    let (mut rt, cap) = runtime();
    if phase == Phase::Instantiated {
        return (rt, cap);
    }
    if phase == Phase::Error {
        assert_eq!(rt.set_by_name("fault", Value::Integer(1)), fmi2Status::OK);
    }
    assert_eq!(rt.setup_experiment(0.0, None), fmi2Status::OK);
    assert_eq!(rt.enter_initialization_mode(), fmi2Status::OK);
    if phase != Phase::InitializationMode {
        assert_eq!(rt.exit_initialization_mode(), fmi2Status::OK);
    }
    match phase {
        Phase::Terminated => assert_eq!(rt.terminate(), fmi2Status::OK),
        Phase::Error => {
            for k in 0..10 {
                assert_eq!(rt.do_step(k as f64 * 0.1, 0.1), fmi2Status::OK);
            }
            assert_eq!(rt.do_step(1.0, 0.1), fmi2Status::ERROR);
        }
        _ => {}
    }
    assert_eq!(rt.phase(), phase);
    cap.clear();
    (rt, cap)
}

/// One call of `f` with arguments that are valid wherever `f` is allowed.
fn call(rt: &mut Runtime<Counter>, f: Function) -> fmi2Status {
    let t = rt.time();
    match f {
        Function::SetupExperiment => rt.setup_experiment(0.0, None),
        Function::EnterInitializationMode => rt.enter_initialization_mode(),
        Function::ExitInitializationMode => rt.exit_initialization_mode(),
        Function::Terminate => rt.terminate(),
        Function::DoStep => rt.do_step(t, 0.1),
        Function::GetReal => {
            let mut out = [0.0];
            rt.get("fmi2GetReal", ScalarType::Real, &[VR_GAIN], &mut out, |v| {
                v.as_f64()
            })
        }
        Function::SetReal => rt.set(
            "fmi2SetReal",
            ScalarType::Real,
            &[VR_U],
            [Value::Real(1.0)].into_iter(),
        ),
        other => panic!("{other} is not exercised here"),
    }
}

#[test]
fn every_call_is_accepted_exactly_in_the_phases_of_the_function_table() {
    use Phase::*;
    // The FMI 2.0 Co-Simulation state machine (§4.2.4) as twinbench's FMUs implement it,
    // written out here independently of the table: the table must say the same, and the
    // runtime must do what the table says.
    let expected: [(Function, &[Phase]); 7] = [
        (Function::SetupExperiment, &[Instantiated]),
        (Function::EnterInitializationMode, &[Instantiated]),
        (Function::ExitInitializationMode, &[InitializationMode]),
        (Function::Terminate, &[StepComplete]),
        (Function::DoStep, &[StepComplete]),
        (
            Function::GetReal,
            &[
                Instantiated,
                InitializationMode,
                StepComplete,
                Terminated,
                Error,
            ],
        ),
        (
            Function::SetReal,
            &[Instantiated, InitializationMode, StepComplete],
        ),
    ];
    for (f, phases) in expected {
        assert_eq!(
            f.allowed(),
            fmu_export::PhaseSet::of(phases),
            "the table's phases of {f}"
        );
        for phase in Phase::ALL {
            let (mut rt, cap) = in_phase(phase);
            let status = call(&mut rt, f);
            let allowed = f.allowed().contains(phase);
            // fmi2Terminate where the standard allows only reset or free (a host ending an
            // instance whose initialisation or step failed): a warning, nothing changes.
            if f == Function::Terminate
                && matches!(phase, Instantiated | InitializationMode | Error)
            {
                assert_eq!(status, fmi2Status::WARNING, "{f} in '{phase}'");
                assert_eq!(rt.phase(), phase, "{f} in '{phase}' changes nothing");
                continue;
            }
            assert_eq!(
                status == fmi2Status::OK,
                allowed,
                "{f} in state '{phase}': {status}, table says allowed = {allowed}: {}",
                cap.text()
            );
            if !allowed {
                assert!(
                    cap.text().contains(&format!(
                        "{f} is not allowed in state '{phase}' (allowed in: {})",
                        f.allowed().describe()
                    )),
                    "{f} in '{phase}': {}",
                    cap.text()
                );
            }
        }
    }
}

#[test]
fn sets_are_checked_for_range_finiteness_causality_and_type() {
    let (mut rt, cap) = in_phase(Phase::StepComplete);
    let set = |rt: &mut Runtime<Counter>, vr: u32, x: f64| {
        rt.set(
            "fmi2SetReal",
            ScalarType::Real,
            &[vr],
            [Value::Real(x)].into_iter(),
        )
    };
    assert_eq!(set(&mut rt, VR_U, 101.0), fmi2Status::ERROR);
    assert_contains(
        &cap.text(),
        &["'u' = 101 is outside its range [-100, 100] 1"],
    );
    assert_eq!(set(&mut rt, VR_U, f64::NAN), fmi2Status::ERROR);
    assert_contains(&cap.text(), &["expected a finite number"]);
    // A fixed parameter cannot change after initialisation; a tunable one can.
    assert_eq!(set(&mut rt, VR_OFFSET, 1.0), fmi2Status::ERROR);
    assert_contains(
        &cap.text(),
        &["'offset' (fixed parameter) cannot be set in state 'step complete'"],
    );
    assert_eq!(set(&mut rt, VR_GAIN, 2.0), fmi2Status::OK);
    // Outputs are never set; an unknown value reference and a wrong type are named.
    assert_eq!(set(&mut rt, VR_Y, 1.0), fmi2Status::ERROR);
    assert_eq!(set(&mut rt, 99, 1.0), fmi2Status::ERROR);
    assert_contains(&cap.text(), &["unknown value reference 99"]);
    let mut i = [0];
    let s = rt.get(
        "fmi2GetInteger",
        ScalarType::Integer,
        &[VR_U],
        &mut i,
        |v| v.as_f64() as i32,
    );
    assert_eq!(s, fmi2Status::ERROR);
    assert_contains(&cap.text(), &["'u' (vr 3) is Real, not Integer"]);
}

#[test]
fn a_feed_through_output_follows_its_input_between_steps() {
    let (mut rt, _) = in_phase(Phase::StepComplete);
    let get = |rt: &mut Runtime<Counter>, vr: u32| {
        let mut out = [0.0];
        assert_eq!(
            rt.get("fmi2GetReal", ScalarType::Real, &[vr], &mut out, |v| v
                .as_f64()),
            fmi2Status::OK
        );
        out[0]
    };
    assert_eq!(rt.set_by_name("u", Value::Real(3.0)), fmi2Status::OK);
    assert_eq!(get(&mut rt, VR_Y_DIRECT), 3.0);
    assert_eq!(rt.do_step(0.0, 0.5), fmi2Status::OK);
    // y integrates gain·u exactly: 3 · 0.5.
    assert_eq!(get(&mut rt, VR_Y), 1.5);
}

#[test]
fn saved_states_restore_and_serialise_bit_for_bit() {
    let (mut rt, _) = in_phase(Phase::StepComplete);
    assert_eq!(rt.set_by_name("u", Value::Real(0.7)), fmi2Status::OK);
    for k in 0..3 {
        assert_eq!(rt.do_step(k as f64 * 0.1, 0.1), fmi2Status::OK);
    }
    let snap = rt.snapshot().unwrap();
    let bytes = rt.serialize(&snap);
    let run = |rt: &mut Runtime<Counter>| {
        for k in 3..8 {
            assert_eq!(rt.do_step(k as f64 * 0.1, 0.1), fmi2Status::OK);
        }
        rt.get_by_name("y").unwrap().as_f64()
    };
    let first = run(&mut rt);
    assert_eq!(rt.restore(&snap), fmi2Status::OK);
    assert_eq!(run(&mut rt).to_bits(), first.to_bits());
    let back = rt.deserialize(&bytes).unwrap();
    assert_eq!(rt.restore(&back), fmi2Status::OK);
    assert_eq!(run(&mut rt).to_bits(), first.to_bits());
    // Truncated bytes are refused, not read past their end.
    assert!(rt.deserialize(&bytes[..bytes.len() - 3]).is_err());
}

/// Callbacks with no logger and no allocator: the runtime needs neither.
fn no_callbacks() -> fmi2CallbackFunctions {
    fmi2CallbackFunctions {
        logger: None,
        allocateMemory: None,
        freeMemory: None,
        stepFinished: None,
        componentEnvironment: std::ptr::null_mut(),
    }
}

/// `fmi2Instantiate` of a co-simulation Counter named "counter" with this GUID.
unsafe fn instantiate(
    guid: *const std::ffi::c_char,
    callbacks: &fmi2CallbackFunctions,
) -> fmi2Component {
    let name = c"counter".as_ptr();
    let (visible, logging) = (fmi2False, fmi2False);
    fmu_export::ffi::instantiate::<Counter>(
        name,
        fmi2Type::CO_SIMULATION,
        guid,
        std::ptr::null(),
        callbacks,
        visible,
        logging,
    )
}

/// `fmi2Instantiate` of a co-simulation Counter with its own GUID: the instance (not NULL).
unsafe fn counter(callbacks: &fmi2CallbackFunctions) -> fmi2Component {
    let guid = std::ffi::CString::new(fmu_export::description::guid::<Counter>()).unwrap();
    let c = instantiate(guid.as_ptr(), callbacks);
    assert!(!c.is_null());
    c
}

/// Through the C entry points: a panic is caught, returns fmi2Error and poisons the
/// instance until fmi2Reset; NULL pointers are errors, not crashes.
#[test]
fn the_c_entry_points_catch_panics_and_refuse_null_pointers() {
    use fmu_export::ffi;
    let callbacks = no_callbacks();
    unsafe {
        let c = counter(&callbacks);
        let wrong = instantiate(c"{not-the-guid}".as_ptr(), &callbacks);
        assert!(wrong.is_null(), "another GUID is refused");
        let fault = [2];
        assert_eq!(
            ffi::set_integer::<Counter>(c, [6u32].as_ptr(), 1, fault.as_ptr()),
            fmi2Status::OK
        );
        assert_eq!(
            ffi::setup_experiment::<Counter>(c, 0, 0.0, 0.0, 0, 0.0),
            fmi2Status::OK
        );
        assert_eq!(ffi::enter_initialization_mode::<Counter>(c), fmi2Status::OK);
        assert_eq!(ffi::exit_initialization_mode::<Counter>(c), fmi2Status::OK);
        assert_eq!(
            ffi::do_step::<Counter>(c, 0.0, 0.5, fmi2True),
            fmi2Status::OK
        );
        assert_eq!(
            ffi::do_step::<Counter>(c, 0.5, 1.0, fmi2True),
            fmi2Status::ERROR
        );
        // Poisoned: even a get is refused until reset.
        let mut y = [0.0];
        assert_eq!(
            ffi::get_real::<Counter>(c, [VR_Y].as_ptr(), 1, y.as_mut_ptr()),
            fmi2Status::ERROR
        );
        assert_eq!(ffi::reset::<Counter>(c), fmi2Status::OK);
        assert_eq!(
            ffi::get_real::<Counter>(c, [VR_GAIN].as_ptr(), 1, y.as_mut_ptr()),
            fmi2Status::OK
        );
        assert_eq!(y[0], 1.0);
        // NULL pointers.
        assert_eq!(
            ffi::get_real::<Counter>(c, std::ptr::null(), 1, y.as_mut_ptr()),
            fmi2Status::ERROR
        );
        assert_eq!(
            ffi::do_step::<Counter>(std::ptr::null_mut(), 0.0, 0.1, fmi2True),
            fmi2Status::ERROR
        );
        ffi::free_instance::<Counter>(c, "fmi2FreeInstance");
    }
}

#[test]
fn a_discarded_step_keeps_the_time_and_the_instance_usable() {
    let (mut rt, _) = runtime();
    assert_eq!(rt.set_by_name("fault", Value::Integer(3)), fmi2Status::OK);
    assert_eq!(rt.setup_experiment(0.0, None), fmi2Status::OK);
    assert_eq!(rt.enter_initialization_mode(), fmi2Status::OK);
    assert_eq!(rt.exit_initialization_mode(), fmi2Status::OK);
    assert_eq!(rt.do_step(0.0, 1.0), fmi2Status::OK);
    assert_eq!(rt.do_step(1.0, 0.5), fmi2Status::DISCARD);
    assert_eq!(rt.time(), 1.0);
    assert_eq!(rt.phase(), Phase::StepComplete);
    assert_eq!(rt.terminate(), fmi2Status::OK);
}

const VR_LABEL: u32 = 7;
const VR_SOURCE: u32 = 8;

fn strings(rt: &mut Runtime<Counter>, vrs: &[u32]) -> (fmi2Status, Vec<String>) {
    let mut out = vec![String::new(); vrs.len()];
    let s = rt.get_strings("fmi2GetString", vrs, |k, v| out[k] = v.to_string());
    (s, out)
}

#[test]
fn string_parameters_are_read_set_checked_and_saved() {
    let (mut rt, cap) = runtime();
    // The start value, before initialisation.
    let (s, v) = strings(&mut rt, &[VR_LABEL, VR_SOURCE]);
    assert_eq!(s, fmi2Status::OK);
    assert_eq!(v, ["a <label> & \"quotes\"", ""]);
    assert_eq!(
        rt.set_strings("fmi2SetString", &[VR_SOURCE], &["/data/track.csv"]),
        fmi2Status::OK
    );
    assert_eq!(rt.setup_experiment(0.0, None), fmi2Status::OK);
    assert_eq!(rt.enter_initialization_mode(), fmi2Status::OK);
    assert_eq!(rt.exit_initialization_mode(), fmi2Status::OK);
    // A fixed String cannot change after initialisation; a tunable one can.
    assert_eq!(
        rt.set_strings("fmi2SetString", &[VR_SOURCE], &["other"]),
        fmi2Status::ERROR
    );
    assert_contains(
        &cap.text(),
        &["'source_file' (fixed parameter) cannot be set in state 'step complete'"],
    );
    assert_eq!(
        rt.set_strings("fmi2SetString", &[VR_LABEL], &["lap 2"]),
        fmi2Status::OK
    );
    // Type checks both ways.
    assert_eq!(
        rt.set_strings("fmi2SetString", &[VR_GAIN], &["x"]),
        fmi2Status::ERROR
    );
    assert_contains(&cap.text(), &["'gain' (vr 1) is Real, not String"]);
    let mut x = [0.0];
    assert_eq!(
        rt.get("fmi2GetReal", ScalarType::Real, &[VR_LABEL], &mut x, |v| v
            .as_f64()),
        fmi2Status::ERROR
    );
    // A saved and serialised state restores the strings.
    let snap = rt.snapshot().unwrap();
    let bytes = rt.serialize(&snap);
    assert_eq!(
        rt.set_strings("fmi2SetString", &[VR_LABEL], &["changed"]),
        fmi2Status::OK
    );
    let back = rt.deserialize(&bytes).unwrap();
    assert_eq!(rt.restore(&back), fmi2Status::OK);
    assert_eq!(
        strings(&mut rt, &[VR_LABEL, VR_SOURCE]).1,
        ["lap 2", "/data/track.csv"]
    );
}

#[test]
fn string_variables_are_in_the_model_description_and_the_guid() {
    let md = fmu_export::description::render_model_description::<Counter>(
        include_str!("../../../fmu-templates/modelDescription.xml"),
        "test",
    );
    assert!(
        md.contains("<String start=\"a &lt;label&gt; &amp; &quot;quotes&quot;\"/>"),
        "{md}"
    );
    fmu_export::description::validate_table::<CounterVars>().unwrap();
    // The interface text carries the String start value (so the GUID changes with it).
    assert!(fmu_export::description::canonical_interface::<Counter>().contains("|String|"));
}

#[test]
fn the_c_entry_points_pass_strings_both_ways() {
    use fmu_export::ffi;
    let callbacks = no_callbacks();
    unsafe {
        let c = counter(&callbacks);
        let value = [c"/tmp/ä.csv".as_ptr()];
        assert_eq!(
            ffi::set_string::<Counter>(c, [VR_SOURCE].as_ptr(), 1, value.as_ptr()),
            fmi2Status::OK
        );
        let mut out: [fmi2String; 2] = [std::ptr::null(); 2];
        assert_eq!(
            ffi::get_string::<Counter>(c, [VR_SOURCE, VR_LABEL].as_ptr(), 2, out.as_mut_ptr()),
            fmi2Status::OK
        );
        assert_eq!(
            std::ffi::CStr::from_ptr(out[0]).to_str().unwrap(),
            "/tmp/ä.csv"
        );
        assert!(std::ffi::CStr::from_ptr(out[1])
            .to_str()
            .unwrap()
            .starts_with("a <label>"));
        // A NULL string is an error, not a crash.
        let null = [std::ptr::null()];
        assert_eq!(
            ffi::set_string::<Counter>(c, [VR_SOURCE].as_ptr(), 1, null.as_ptr()),
            fmi2Status::ERROR
        );
        ffi::free_instance::<Counter>(c, "fmi2FreeInstance");
    }
}

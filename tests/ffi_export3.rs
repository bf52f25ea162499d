//! The exported models' FMI 3.0 entry points through their C symbols (as a host calls
//! them, with the library loaded here): the instantiation's refusals, typed get and set
//! with their counts, the independent variable, fmi3DoStep's flags, call order, FMU states,
//! the calls this FMU does not provide, and a panicking model.

mod common;

use std::ffi::{c_char, c_void, CStr, CString};
use std::sync::Mutex;
use tb_testkit::assert_contains;

type Inst = *mut c_void;
type Log = unsafe extern "C" fn(*mut c_void, i32, *const c_char, *const c_char);

/// The logger: each library's messages into its own list (the instance environment), so
/// that tests running side by side do not see each other's.
unsafe extern "C" fn log(env: *mut c_void, _status: i32, _cat: *const c_char, msg: *const c_char) {
    let text = CStr::from_ptr(msg).to_string_lossy().into_owned();
    (*(env as *const Mutex<Vec<String>>))
        .lock()
        .unwrap()
        .push(text);
}

/// A model's FMI 3.0 library, unpacked, with its token and resource folder.
struct Fmu3 {
    lib: libloading::Library,
    token: CString,
    resources: CString,
    md: String,
    log: Box<Mutex<Vec<String>>>,
    _dir: tempfile::TempDir,
}

fn open(model: &str) -> Fmu3 {
    let fmu = common::fmu3(model);
    let dir = tb_testkit::scratch(&format!("ffi3-{model}"));
    let mut zip = zip::ZipArchive::new(std::fs::File::open(&fmu).unwrap()).unwrap();
    zip.extract(dir.path()).unwrap();
    let md = std::fs::read_to_string(dir.path().join("modelDescription.xml")).unwrap();
    let token = md
        .split("instantiationToken=\"")
        .nth(1)
        .unwrap()
        .split('"')
        .next()
        .unwrap()
        .to_string();
    let so = dir.path().join(format!("binaries/x86_64-linux/{model}.so"));
    // SAFETY: our own model library; its constructors do nothing but register symbols.
    let lib = unsafe { libloading::Library::new(&so).unwrap() };
    let resources = format!("{}/resources/", dir.path().display());
    Fmu3 {
        lib,
        token: CString::new(token).unwrap(),
        resources: CString::new(resources).unwrap(),
        md,
        log: Box::new(Mutex::new(Vec::new())),
        _dir: dir,
    }
}

impl Fmu3 {
    /// The messages logged since the last call, joined.
    fn messages(&self) -> String {
        let mut m = self.log.lock().unwrap();
        let text = m.join("\n");
        m.clear();
        text
    }

    unsafe fn sym<T: Copy>(&self, name: &str) -> T {
        *self
            .lib
            .get::<T>(format!("{name}\0").as_bytes())
            .unwrap_or_else(|_| panic!("{name} missing"))
    }

    fn vr(&self, name: &str) -> u32 {
        let tag = format!("name=\"{name}\" valueReference=\"");
        self.md
            .split(&tag)
            .nth(1)
            .and_then(|r| r.split('"').next())
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no variable {name}"))
    }

    unsafe fn instantiate(&self, event_mode: bool) -> Inst {
        type F = unsafe extern "C" fn(
            *const c_char,
            *const c_char,
            *const c_char,
            bool,
            bool,
            bool,
            bool,
            *const u32,
            usize,
            *mut c_void,
            Option<Log>,
            *const c_void,
        ) -> Inst;
        let f: F = self.sym("fmi3InstantiateCoSimulation");
        let name = c"inst";
        f(
            name.as_ptr(),
            self.token.as_ptr(),
            self.resources.as_ptr(),
            false,
            true,
            event_mode,
            false,
            std::ptr::null(),
            0,
            &*self.log as *const Mutex<Vec<String>> as *mut c_void,
            Some(log),
            std::ptr::null(),
        )
    }

    /// fmi3FreeInstance(c).
    unsafe fn free(&self, c: Inst) {
        let free: unsafe extern "C" fn(Inst) = self.sym("fmi3FreeInstance");
        free(c)
    }

    unsafe fn call0(&self, name: &str, c: Inst) -> i32 {
        let f: unsafe extern "C" fn(Inst) -> i32 = self.sym(name);
        f(c)
    }

    unsafe fn init(&self, c: Inst) {
        let f: unsafe extern "C" fn(Inst, bool, f64, f64, bool, f64) -> i32 =
            self.sym("fmi3EnterInitializationMode");
        assert_eq!(f(c, false, 0.0, 0.0, false, 0.0), 0, "{}", self.messages());
        assert_eq!(
            self.call0("fmi3ExitInitializationMode", c),
            0,
            "{}",
            self.messages()
        );
    }

    unsafe fn get_f64(&self, c: Inst, vrs: &[u32]) -> (i32, Vec<f64>) {
        let f: unsafe extern "C" fn(Inst, *const u32, usize, *mut f64, usize) -> i32 =
            self.sym("fmi3GetFloat64");
        let mut out = vec![0.0; vrs.len()];
        let s = f(c, vrs.as_ptr(), vrs.len(), out.as_mut_ptr(), out.len());
        (s, out)
    }

    unsafe fn step(&self, c: Inst, t: f64, h: f64) -> (i32, [bool; 3], f64) {
        type F = unsafe extern "C" fn(
            Inst,
            f64,
            f64,
            bool,
            *mut bool,
            *mut bool,
            *mut bool,
            *mut f64,
        ) -> i32;
        let f: F = self.sym("fmi3DoStep");
        let (mut a, mut b, mut e, mut last) = (true, true, true, f64::NAN);
        let s = f(c, t, h, false, &mut a, &mut b, &mut e, &mut last);
        (s, [a, b, e], last)
    }
}

#[test]
fn instantiation_refuses_event_mode_and_a_wrong_token_naming_them() {
    let f = open("vehicle");
    unsafe {
        assert!(f.instantiate(true).is_null());
        let m = f.messages();
        assert_contains(&m, &["has no event mode (hasEventMode=\"false\")"]);
        let good = f.token.clone();
        let mut bad = open("vehicle");
        bad.token = CString::new("{not-the-token}").unwrap();
        assert!(bad.instantiate(false).is_null());
        let m = bad.messages();
        assert!(m.contains("instantiationToken mismatch"), "{m}");
        assert_eq!(good, f.token);
        let c = f.instantiate(false);
        assert!(!c.is_null(), "{}", f.messages());
        f.free(c);
    }
}

#[test]
fn typed_get_and_set_time_do_step_flags_and_call_order() {
    let f = open("vehicle");
    unsafe {
        let c = f.instantiate(false);
        // A step before initialisation: an error naming the FMI 3.0 call.
        let (s, _, _) = f.step(c, 0.0, 1e-3);
        assert_eq!(s, 3);
        let m = f.messages();
        assert_contains(&m, &["fmi3DoStep is not allowed in state 'instantiated'"]);
        // chassis_model is an Enumeration: Int64, not Int32.
        let chassis = f.vr("chassis_model");
        let get32: unsafe extern "C" fn(Inst, *const u32, usize, *mut i32, usize) -> i32 =
            f.sym("fmi3GetInt32");
        let mut i = [0i32];
        assert_eq!(get32(c, &chassis, 1, i.as_mut_ptr(), 1), 3);
        let m = f.messages();
        assert_contains(&m, &["'chassis_model'", "is Enumeration, not Int32"]);
        let set64: unsafe extern "C" fn(Inst, *const u32, usize, *const i64, usize) -> i32 =
            f.sym("fmi3SetInt64");
        assert_eq!(set64(c, &chassis, 1, [3i64].as_ptr(), 1), 3);
        let m = f.messages();
        assert!(m.contains("(1 first_order, 2 second_order)"), "{m}");
        assert_eq!(
            set64(c, &chassis, 1, [2i64].as_ptr(), 1),
            0,
            "{}",
            f.messages()
        );
        let get64: unsafe extern "C" fn(Inst, *const u32, usize, *mut i64, usize) -> i32 =
            f.sym("fmi3GetInt64");
        let mut e = [0i64];
        assert_eq!(get64(c, &chassis, 1, e.as_mut_ptr(), 1), 0);
        assert_eq!(e[0], 2);
        // nValues must match the value references (every variable is a scalar).
        let v = f.vr("v_start");
        let set: unsafe extern "C" fn(Inst, *const u32, usize, *const f64, usize) -> i32 =
            f.sym("fmi3SetFloat64");
        assert_eq!(set(c, &v, 1, [30.0, 1.0].as_ptr(), 2), 3);
        let m = f.messages();
        assert_contains(&m, &["fmi3SetFloat64: 2 values for 1 value references"]);
        assert_eq!(set(c, &v, 1, [30.0].as_ptr(), 1), 0);
        f.init(c);
        // time (the independent variable) and v, in one call.
        let time = f.vr("time");
        let speed = f.vr("v");
        let (s, x) = f.get_f64(c, &[time, speed]);
        assert_eq!(s, 0);
        assert_eq!(x, vec![0.0, 30.0]);
        for k in 0..10 {
            let (s, flags, last) = f.step(c, k as f64 * 1e-3, 1e-3);
            assert_eq!(s, 0, "{}", f.messages());
            assert_eq!(flags, [false, false, false]);
            assert_eq!(last, k as f64 * 1e-3 + 1e-3);
        }
        let (_, x) = f.get_f64(c, &[time]);
        assert!((x[0] - 0.01).abs() < 1e-15);
        assert_eq!(set(c, &time, 1, [1.0].as_ptr(), 1), 3);
        assert!(f.messages().contains("'time' cannot be set"));
        // A type this FMU has none of, and a call it does not provide.
        let get8: unsafe extern "C" fn(Inst, *const u32, usize, *mut i8, usize) -> i32 =
            f.sym("fmi3GetInt8");
        let mut b = [0i8];
        assert_eq!(get8(c, &speed, 1, b.as_mut_ptr(), 1), 3);
        assert!(f.messages().contains("fmi3GetInt8: variable 'v'"));
        assert_eq!(f.call0("fmi3EnterEventMode", c), 3);
        assert!(f
            .messages()
            .contains("fmi3EnterEventMode: this FMU has no event mode"));
        // Booleans are one byte; Strings as in FMI 2.0.
        let get_s: unsafe extern "C" fn(Inst, *const u32, usize, *mut *const c_char, usize) -> i32 =
            f.sym("fmi3GetString");
        let mut p = [std::ptr::null::<c_char>()];
        assert_eq!(get_s(c, &f.vr("track_file"), 1, p.as_mut_ptr(), 1), 0);
        assert_eq!(CStr::from_ptr(p[0]).to_str().unwrap(), "");
        assert_eq!(f.call0("fmi3Terminate", c), 0);
        f.free(c);
    }
}

#[test]
fn a_state_serialized_and_restored_repeats_bit_for_bit() {
    let f = open("vehicle");
    unsafe {
        let c = f.instantiate(false);
        f.init(c);
        let speed = f.vr("v");
        let fz = f.vr("Fz_rl");
        let run = |from: usize| -> Vec<u64> {
            (from..from + 200)
                .flat_map(|k| {
                    assert_eq!(f.step(c, k as f64 * 1e-3, 1e-3).0, 0);
                    f.get_f64(c, &[speed, fz]).1.into_iter().map(f64::to_bits)
                })
                .collect()
        };
        run(0);
        let get: unsafe extern "C" fn(Inst, *mut *mut c_void) -> i32 = f.sym("fmi3GetFMUState");
        let set: unsafe extern "C" fn(Inst, *mut c_void) -> i32 = f.sym("fmi3SetFMUState");
        let size: unsafe extern "C" fn(Inst, *mut c_void, *mut usize) -> i32 =
            f.sym("fmi3SerializedFMUStateSize");
        let ser: unsafe extern "C" fn(Inst, *mut c_void, *mut u8, usize) -> i32 =
            f.sym("fmi3SerializeFMUState");
        let de: unsafe extern "C" fn(Inst, *const u8, usize, *mut *mut c_void) -> i32 =
            f.sym("fmi3DeserializeFMUState");
        let free_state: unsafe extern "C" fn(Inst, *mut *mut c_void) -> i32 =
            f.sym("fmi3FreeFMUState");
        let mut state = std::ptr::null_mut();
        assert_eq!(get(c, &mut state), 0);
        let mut n = 0;
        assert_eq!(size(c, state, &mut n), 0);
        let mut bytes = vec![0u8; n];
        assert_eq!(ser(c, state, bytes.as_mut_ptr(), n), 0);
        let first = run(200);
        assert_eq!(set(c, state), 0);
        assert_eq!(run(200), first);
        let mut back = std::ptr::null_mut();
        assert_eq!(de(c, bytes.as_ptr(), n, &mut back), 0, "{}", f.messages());
        assert_eq!(set(c, back), 0);
        assert_eq!(run(200), first);
        assert_eq!(free_state(c, &mut state), 0);
        assert_eq!(free_state(c, &mut back), 0);
        assert!(state.is_null() && back.is_null());
        f.free(c);
    }
}

#[test]
fn a_panicking_model_returns_error_and_the_host_lives() {
    let f = open("faulty");
    unsafe {
        let c = f.instantiate(false);
        let set: unsafe extern "C" fn(Inst, *const u32, usize, *const i32, usize) -> i32 =
            f.sym("fmi3SetInt32");
        let kind = f.vr("fault_kind");
        assert_eq!(set(c, &kind, 1, [2].as_ptr(), 1), 0, "{}", f.messages());
        f.init(c);
        let mut status = 0;
        for k in 0..2000 {
            status = f.step(c, k as f64 * 1e-3, 1e-3).0;
            if status != 0 {
                break;
            }
        }
        assert_eq!(status, 3);
        let m = f.messages();
        assert!(m.contains("panicked") || m.contains("panic"), "{m}");
        // Poisoned: further steps are refused, freeing works.
        assert_eq!(f.step(c, 5.0, 1e-3).0, 3);
        f.free(c);
    }
}

/// Red team P7: a hostile host's double free, call after free, foreign FMU state and
/// endless step are refused with fmi3Error and a logged reason; the FMU never aborts or
/// reads freed memory. (They aborted, answered fmi3OK after the free, and never returned.)
#[test]
fn a_hostile_hosts_double_free_call_after_free_foreign_state_and_endless_step_are_refused() {
    let f = open("vehicle");
    unsafe {
        let get_state: unsafe extern "C" fn(Inst, *mut *mut c_void) -> i32 =
            f.sym("fmi3GetFMUState");
        let set_state: unsafe extern "C" fn(Inst, *mut c_void) -> i32 = f.sym("fmi3SetFMUState");
        let free_state: unsafe extern "C" fn(Inst, *mut *mut c_void) -> i32 =
            f.sym("fmi3FreeFMUState");
        let size: unsafe extern "C" fn(Inst, *mut c_void, *mut usize) -> i32 =
            f.sym("fmi3SerializedFMUStateSize");
        let c = f.instantiate(false);
        f.init(c);
        f.messages();
        // A step whose internal steps have no end in sight: refused at once.
        let started = std::time::Instant::now();
        for h in [1e5, 1e300] {
            let (s, _, _) = f.step(c, 0.0, h);
            assert_eq!(s, 3, "a step of {h} s");
            let m = f.messages();
            assert_contains(&m, &["internal steps", "refused"]);
        }
        assert!(started.elapsed() < std::time::Duration::from_secs(5));
        // The instance still steps afterwards (a refused call is an error, not a crash).
        f.call0("fmi3Reset", c);
        f.init(c);
        assert_eq!(f.step(c, 0.0, 1e-3).0, 0, "{}", f.messages());
        // States: a foreign pointer, a double free.
        let mut s: *mut c_void = std::ptr::null_mut();
        assert_eq!(get_state(c, &mut s), 0);
        let mut bogus = [0u64; 64];
        let foreign = bogus.as_mut_ptr() as *mut c_void;
        assert_eq!(set_state(c, foreign), 3);
        let mut n = 0usize;
        assert_eq!(size(c, foreign, &mut n), 3);
        let mut foreign_too = foreign;
        assert_eq!(free_state(c, &mut foreign_too), 3);
        let m = f.messages();
        assert!(m.contains("not one of this instance's"), "{m}");
        assert_eq!(bogus, [0u64; 64], "the FMU wrote through a foreign pointer");
        let mut again = s;
        assert_eq!(free_state(c, &mut s), 0);
        assert!(s.is_null());
        assert_eq!(free_state(c, &mut again), 3, "a state freed twice");
        assert_eq!(set_state(c, again), 3, "a freed state restored");
        f.messages();
        // The instance: a call after the free, and a second free.
        f.free(c);
        let (status, _) = f.get_f64(c, &[f.vr("v")]);
        assert_eq!(status, 3, "a call after fmi3FreeInstance");
        let m = f.messages();
        assert!(m.contains("the instance was freed"), "{m}");
        f.free(c);
        let m = f.messages();
        assert_contains(&m, &["fmi3FreeInstance", "freed"]);
        // A pointer that was never an instance.
        assert_eq!(f.get_f64(foreign, &[0]).0, 3);
        assert_eq!(f.step(std::ptr::null_mut(), 0.0, 1e-3).0, 3);
        f.free(foreign);
    }
}

//! A small hand-made binding of SUNDIALS CVODE 6 (Debian's `libsundials-dev` 6.4.1, linked
//! statically by `build.rs`): the handful of functions that integrate one Model Exchange
//! instance, set up as FMPy 0.3.32 sets up its `CVodeSolver` (`fmpy/sundials/__init__.py`):
//! BDF with Newton iteration and the dense direct linear solver (difference-quotient
//! Jacobian), a relative tolerance and an absolute tolerance per state, a largest step,
//! at most 500 internal steps per call, root finding on the event indicators.
//!
//! The right-hand side and the root function are a [`System`] behind CVODE's user data;
//! panics never cross into C (they become an unrecoverable error of the callback).

use std::cell::RefCell;
use std::ffi::{c_char, c_int, c_long, c_void, CStr};

type SunContext = *mut c_void;
type NVector = *mut c_void;
type SunMatrix = *mut c_void;
type SunLinearSolver = *mut c_void;
/// `sunindextype` of Debian's build (`SUNDIALS_INDEX_TYPE int64_t`, sundials_config.h).
type SunIndex = i64;

type RhsFn = unsafe extern "C" fn(f64, NVector, NVector, *mut c_void) -> c_int;
type RootFn = unsafe extern "C" fn(f64, NVector, *mut f64, *mut c_void) -> c_int;
type ErrHandlerFn =
    unsafe extern "C" fn(c_int, *const c_char, *const c_char, *mut c_char, *mut c_void);

const CV_BDF: c_int = 2;
const CV_NORMAL: c_int = 1;
const CV_SUCCESS: c_int = 0;
const CV_ROOT_RETURN: c_int = 2;
const CV_WARNING: c_int = 99;

extern "C" {
    fn SUNContext_Create(comm: *mut c_void, ctx: *mut SunContext) -> c_int;
    fn SUNContext_Free(ctx: *mut SunContext) -> c_int;
    fn N_VNew_Serial(length: SunIndex, ctx: SunContext) -> NVector;
    fn N_VDestroy(v: NVector);
    fn N_VGetArrayPointer(v: NVector) -> *mut f64;
    fn SUNDenseMatrix(m: SunIndex, n: SunIndex, ctx: SunContext) -> SunMatrix;
    fn SUNMatDestroy(a: SunMatrix);
    fn SUNLinSol_Dense(y: NVector, a: SunMatrix, ctx: SunContext) -> SunLinearSolver;
    fn SUNLinSolFree(s: SunLinearSolver) -> c_int;
    fn CVodeCreate(lmm: c_int, ctx: SunContext) -> *mut c_void;
    fn CVodeInit(mem: *mut c_void, f: RhsFn, t0: f64, y0: NVector) -> c_int;
    fn CVodeReInit(mem: *mut c_void, t0: f64, y0: NVector) -> c_int;
    fn CVodeSVtolerances(mem: *mut c_void, reltol: f64, abstol: NVector) -> c_int;
    fn CVodeRootInit(mem: *mut c_void, nrtfn: c_int, g: Option<RootFn>) -> c_int;
    fn CVodeSetLinearSolver(mem: *mut c_void, ls: SunLinearSolver, a: SunMatrix) -> c_int;
    fn CVodeSetMaxStep(mem: *mut c_void, hmax: f64) -> c_int;
    fn CVodeSetMaxNumSteps(mem: *mut c_void, mxsteps: c_long) -> c_int;
    fn CVodeSetNoInactiveRootWarn(mem: *mut c_void) -> c_int;
    fn CVodeSetErrHandlerFn(mem: *mut c_void, f: ErrHandlerFn, data: *mut c_void) -> c_int;
    fn CVodeSetUserData(mem: *mut c_void, data: *mut c_void) -> c_int;
    fn CVode(mem: *mut c_void, tout: f64, yout: NVector, tret: *mut f64, itask: c_int) -> c_int;
    fn CVodeGetRootInfo(mem: *mut c_void, rootsfound: *mut c_int) -> c_int;
    fn CVodeFree(mem: *mut *mut c_void);
}

/// The name of a CVODE return flag (cvode.h, SUNDIALS 6.4.1).
pub fn flag_name(flag: i32) -> &'static str {
    match flag {
        0 => "CV_SUCCESS",
        1 => "CV_TSTOP_RETURN",
        2 => "CV_ROOT_RETURN",
        99 => "CV_WARNING",
        -1 => "CV_TOO_MUCH_WORK",
        -2 => "CV_TOO_MUCH_ACC",
        -3 => "CV_ERR_FAILURE",
        -4 => "CV_CONV_FAILURE",
        -5 => "CV_LINIT_FAIL",
        -6 => "CV_LSETUP_FAIL",
        -7 => "CV_LSOLVE_FAIL",
        -8 => "CV_RHSFUNC_FAIL",
        -9 => "CV_FIRST_RHSFUNC_ERR",
        -10 => "CV_REPTD_RHSFUNC_ERR",
        -11 => "CV_UNREC_RHSFUNC_ERR",
        -12 => "CV_RTFUNC_FAIL",
        -13 => "CV_NLS_INIT_FAIL",
        -14 => "CV_NLS_SETUP_FAIL",
        -15 => "CV_CONSTR_FAIL",
        -16 => "CV_NLS_FAIL",
        -20 => "CV_MEM_FAIL",
        -21 => "CV_MEM_NULL",
        -22 => "CV_ILL_INPUT",
        -23 => "CV_NO_MALLOC",
        -24 => "CV_BAD_K",
        -25 => "CV_BAD_T",
        -26 => "CV_BAD_DKY",
        -27 => "CV_TOO_CLOSE",
        -28 => "CV_VECTOROP_ERR",
        -29 => "CV_PROJ_MEM_NULL",
        -30 => "CV_PROJFUNC_FAIL",
        -31 => "CV_REPTD_PROJFUNC_ERR",
        -32 => "CV_CONTEXT_ERR",
        _ => "an unknown CVODE flag",
    }
}

/// What CVODE integrates: the right-hand side and the root functions. A callback returns
/// 0 on success, a positive number for an error CVODE may recover from (it retries with a
/// smaller step), a negative one for an error that stops it.
pub trait System {
    /// ẋ = f(t, x).
    fn rhs(&mut self, t: f64, x: &[f64], dx: &mut [f64]) -> i32;
    /// The root functions g(t, x) (the event indicators).
    fn roots(&mut self, t: f64, x: &[f64], g: &mut [f64]) -> i32;
}

/// A failed CVODE call: its name, its flag, and CVODE's own message when it gave one.
#[derive(Clone, Debug, PartialEq)]
pub struct SolverError {
    pub function: &'static str,
    pub flag: i32,
    pub message: Option<String>,
}

impl SolverError {
    /// `returned CV_CONV_FAILURE (-4): <CVODE's message>`.
    pub fn problem(&self) -> String {
        let mut s = format!("returned {} ({})", flag_name(self.flag), self.flag);
        if let Some(m) = &self.message {
            s.push_str(": ");
            s.push_str(m);
        }
        s
    }
}

/// Where CVODE's error handler puts its messages.
#[derive(Default)]
struct Messages {
    last_error: Option<String>,
    warnings: Vec<String>,
}

unsafe extern "C" fn error_handler(
    code: c_int,
    _module: *const c_char,
    function: *const c_char,
    msg: *mut c_char,
    data: *mut c_void,
) {
    let _ = std::panic::catch_unwind(|| {
        if data.is_null() {
            return;
        }
        let text = |p: *const c_char| {
            if p.is_null() {
                String::new()
            } else {
                CStr::from_ptr(p).to_string_lossy().into_owned()
            }
        };
        let line = format!("{}: {}", text(function), text(msg));
        let mut m = (*(data as *const RefCell<Messages>)).borrow_mut();
        if code == CV_WARNING {
            // Bounded: a long run may warn at every step.
            if m.warnings.len() < 100 {
                m.warnings.push(line);
            }
        } else {
            m.last_error = Some(line);
        }
    });
}

/// The vector of `v`'s `n` values.
///
/// # Safety
/// `v` is a serial N_Vector of length `n` that lives as long as the slice is used.
unsafe fn values<'a>(v: NVector, n: usize) -> &'a mut [f64] {
    std::slice::from_raw_parts_mut(N_VGetArrayPointer(v), n)
}

unsafe extern "C" fn rhs<S: System>(t: f64, y: NVector, ydot: NVector, data: *mut c_void) -> c_int {
    let s = &mut *(data as *mut Callbacks<S>);
    let n = s.n;
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        s.system.rhs(t, values(y, n), values(ydot, n))
    }))
    .unwrap_or(-1)
}

unsafe extern "C" fn roots<S: System>(t: f64, y: NVector, g: *mut f64, data: *mut c_void) -> c_int {
    let s = &mut *(data as *mut Callbacks<S>);
    let (n, nz) = (s.n, s.nz);
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        s.system
            .roots(t, values(y, n), std::slice::from_raw_parts_mut(g, nz))
    }))
    .unwrap_or(-1)
}

/// CVODE's user data: the system and the sizes.
struct Callbacks<S> {
    system: S,
    n: usize,
    nz: usize,
}

/// How CVODE is set up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    pub relative_tolerance: f64,
    /// The largest step; 0: no limit.
    pub max_step: f64,
    /// The most internal steps in one call (FMPy: 500, CVODE's default).
    pub max_num_steps: i64,
}

/// Where a call of [`Cvode::advance`] ended.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reached {
    /// The output time asked for.
    Time(f64),
    /// A root of the event indicators (a state event), before the output time.
    Root(f64),
}

/// One CVODE integrator with its vectors, matrix and linear solver. Not `Send` by itself:
/// its owner moves it between threads as a whole ([`super::MeInstance`]).
pub struct Cvode<S: System> {
    mem: *mut c_void,
    y: NVector,
    abstol: NVector,
    a: SunMatrix,
    ls: SunLinearSolver,
    ctx: SunContext,
    n: usize,
    nz: usize,
    callbacks: Box<Callbacks<S>>,
    messages: Box<RefCell<Messages>>,
}

impl<S: System> Cvode<S> {
    /// An integrator of `x0.len()` states (at least one) from `t0`, with absolute
    /// tolerances `abstol` (one per state) and `nz` root functions.
    pub fn new(
        system: S,
        t0: f64,
        x0: &[f64],
        abstol: &[f64],
        nz: usize,
        settings: Settings,
    ) -> Result<Cvode<S>, SolverError> {
        let n = x0.len();
        assert!(n > 0 && abstol.len() == n, "CVODE needs at least one state");
        let fail = |function, flag| SolverError {
            function,
            flag,
            message: None,
        };
        let mut ctx: SunContext = std::ptr::null_mut();
        // SAFETY: every pointer CVODE returns is checked before use; the integrator owns
        // them and frees them in Drop (in the reverse order).
        let r = unsafe { SUNContext_Create(std::ptr::null_mut(), &mut ctx) };
        if r != 0 || ctx.is_null() {
            return Err(fail("SUNContext_Create", r));
        }
        let mut c = Cvode {
            mem: std::ptr::null_mut(),
            y: std::ptr::null_mut(),
            abstol: std::ptr::null_mut(),
            a: std::ptr::null_mut(),
            ls: std::ptr::null_mut(),
            ctx,
            n,
            nz,
            callbacks: Box::new(Callbacks { system, n, nz }),
            messages: Box::new(RefCell::new(Messages::default())),
        };
        unsafe {
            c.y = N_VNew_Serial(n as SunIndex, ctx);
            c.abstol = N_VNew_Serial(n as SunIndex, ctx);
            c.a = SUNDenseMatrix(n as SunIndex, n as SunIndex, ctx);
            if c.y.is_null() || c.abstol.is_null() || c.a.is_null() {
                return Err(fail("N_VNew_Serial", -20));
            }
            c.ls = SUNLinSol_Dense(c.y, c.a, ctx);
            c.mem = CVodeCreate(CV_BDF, ctx);
            if c.ls.is_null() || c.mem.is_null() {
                return Err(fail("CVodeCreate", -20));
            }
            values(c.y, n).copy_from_slice(x0);
            values(c.abstol, n).copy_from_slice(abstol);
            let data = &mut *c.messages as *mut RefCell<Messages> as *mut c_void;
            c.check(
                "CVodeSetErrHandlerFn",
                CVodeSetErrHandlerFn(c.mem, error_handler, data),
            )?;
            c.check("CVodeInit", CVodeInit(c.mem, rhs::<S>, t0, c.y))?;
            let user = &mut *c.callbacks as *mut Callbacks<S> as *mut c_void;
            c.check("CVodeSetUserData", CVodeSetUserData(c.mem, user))?;
            c.check(
                "CVodeSVtolerances",
                CVodeSVtolerances(c.mem, settings.relative_tolerance, c.abstol),
            )?;
            let g = (nz > 0).then_some(roots::<S> as RootFn);
            c.check("CVodeRootInit", CVodeRootInit(c.mem, nz as c_int, g))?;
            c.check(
                "CVodeSetLinearSolver",
                CVodeSetLinearSolver(c.mem, c.ls, c.a),
            )?;
            c.check("CVodeSetMaxStep", CVodeSetMaxStep(c.mem, settings.max_step))?;
            c.check(
                "CVodeSetMaxNumSteps",
                CVodeSetMaxNumSteps(c.mem, settings.max_num_steps as c_long),
            )?;
            c.check(
                "CVodeSetNoInactiveRootWarn",
                CVodeSetNoInactiveRootWarn(c.mem),
            )?;
        }
        Ok(c)
    }

    fn check(&self, function: &'static str, flag: c_int) -> Result<(), SolverError> {
        if flag >= CV_SUCCESS {
            return Ok(());
        }
        Err(SolverError {
            function,
            flag,
            message: self.messages.borrow_mut().last_error.take(),
        })
    }

    /// The system CVODE calls (to read what a failed callback left there).
    pub fn system(&mut self) -> &mut S {
        &mut self.callbacks.system
    }

    /// CVODE's warnings since the last call, oldest first.
    pub fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut self.messages.borrow_mut().warnings)
    }

    /// Integrate to `tout` (CVODE's `CV_NORMAL` task: it may step past `tout` and
    /// interpolate back), stopping early at a root. The states at the time reached are in
    /// `x` (its length is the integrator's), the roots found (±1 by direction, else 0) in
    /// `found` (one per root function).
    pub fn advance(
        &mut self,
        tout: f64,
        x: &mut [f64],
        found: &mut [i32],
    ) -> Result<Reached, SolverError> {
        let mut tret = 0.0;
        // SAFETY: the integrator is set up (new) and its vectors have n values.
        let flag = unsafe { CVode(self.mem, tout, self.y, &mut tret, CV_NORMAL) };
        self.check("CVode", flag)?;
        x.copy_from_slice(unsafe { values(self.y, self.n) });
        found.iter_mut().for_each(|r| *r = 0);
        if flag == CV_ROOT_RETURN {
            debug_assert_eq!(found.len(), self.nz);
            let r = unsafe { CVodeGetRootInfo(self.mem, found.as_mut_ptr()) };
            self.check("CVodeGetRootInfo", r)?;
            return Ok(Reached::Root(tret));
        }
        Ok(Reached::Time(tret))
    }

    /// Start again from `t0` and `x0` (after an event: CVODE forgets its history), with new
    /// absolute tolerances when given.
    pub fn reinit(
        &mut self,
        t0: f64,
        x0: &[f64],
        abstol: Option<(&[f64], f64)>,
    ) -> Result<(), SolverError> {
        unsafe {
            values(self.y, self.n).copy_from_slice(x0);
            self.check("CVodeReInit", CVodeReInit(self.mem, t0, self.y))?;
            if let Some((atol, rtol)) = abstol {
                values(self.abstol, self.n).copy_from_slice(atol);
                self.check(
                    "CVodeSVtolerances",
                    CVodeSVtolerances(self.mem, rtol, self.abstol),
                )?;
            }
        }
        Ok(())
    }
}

impl<S: System> Drop for Cvode<S> {
    fn drop(&mut self) {
        // SAFETY: each pointer is null or owned here; CVODE's memory first, then what it used.
        unsafe {
            if !self.mem.is_null() {
                CVodeFree(&mut self.mem);
            }
            if !self.ls.is_null() {
                SUNLinSolFree(self.ls);
            }
            if !self.a.is_null() {
                SUNMatDestroy(self.a);
            }
            for v in [self.y, self.abstol] {
                if !v.is_null() {
                    N_VDestroy(v);
                }
            }
            SUNContext_Free(&mut self.ctx);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ẋ = −k·x with a root where x = 0.5.
    struct Decay {
        k: f64,
        calls: usize,
    }

    impl System for Decay {
        fn rhs(&mut self, _t: f64, x: &[f64], dx: &mut [f64]) -> i32 {
            self.calls += 1;
            dx[0] = -self.k * x[0];
            0
        }
        fn roots(&mut self, _t: f64, x: &[f64], g: &mut [f64]) -> i32 {
            g[0] = x[0] - 0.5;
            0
        }
    }

    fn settings() -> Settings {
        Settings {
            relative_tolerance: 1e-8,
            max_step: 0.0,
            max_num_steps: 500,
        }
    }

    #[test]
    fn integrates_finds_roots_and_reinitialises() {
        let mut c = Cvode::new(
            Decay { k: 1.0, calls: 0 },
            0.0,
            &[1.0],
            &[1e-10],
            1,
            settings(),
        )
        .unwrap();
        let (mut x, mut found) = ([0.0], [0]);
        // The root x = 0.5 at t = ln 2.
        let r = c.advance(1.0, &mut x, &mut found).unwrap();
        let Reached::Root(t) = r else { panic!("{r:?}") };
        assert!((t - 2f64.ln()).abs() < 1e-6, "{t}");
        assert_eq!(found, [-1]);
        let r = c.advance(1.0, &mut x, &mut found).unwrap();
        assert_eq!(r, Reached::Time(1.0));
        assert!((x[0] - (-1f64).exp()).abs() < 1e-6, "{x:?}");
        assert!(c.system().calls > 10);
        // From 2 again at t = 1: x(2) = 2·e^-1.
        c.reinit(1.0, &[2.0], Some((&[1e-10], 1e-8))).unwrap();
        c.advance(2.0, &mut x, &mut found).unwrap();
        assert!((x[0] - 2.0 * (-1f64).exp()).abs() < 1e-6, "{x:?}");
    }

    /// A right-hand side that fails stops CVODE with a named flag and its message.
    struct Failing;

    impl System for Failing {
        fn rhs(&mut self, _t: f64, _x: &[f64], _dx: &mut [f64]) -> i32 {
            -1
        }
        fn roots(&mut self, _t: f64, _x: &[f64], _g: &mut [f64]) -> i32 {
            0
        }
    }

    #[test]
    fn a_failing_right_hand_side_is_a_named_flag_not_a_crash() {
        let mut c = Cvode::new(Failing, 0.0, &[1.0], &[1e-6], 0, settings()).unwrap();
        let e = c.advance(1.0, &mut [0.0], &mut []).unwrap_err();
        assert_eq!(
            (e.function, flag_name(e.flag)),
            ("CVode", "CV_RHSFUNC_FAIL")
        );
        let p = e.problem();
        assert!(p.starts_with("returned CV_RHSFUNC_FAIL (-8): "), "{p}");
        // A panic in a callback is an error of the callback, not an abort.
        struct Panics;
        impl System for Panics {
            fn rhs(&mut self, _t: f64, _x: &[f64], _dx: &mut [f64]) -> i32 {
                panic!("boom")
            }
            fn roots(&mut self, _t: f64, _x: &[f64], _g: &mut [f64]) -> i32 {
                0
            }
        }
        let mut c = Cvode::new(Panics, 0.0, &[1.0], &[1e-6], 0, settings()).unwrap();
        let e = c.advance(1.0, &mut [0.0], &mut []).unwrap_err();
        assert!(e.flag < 0);
    }

    #[test]
    fn too_much_work_is_named() {
        let mut s = settings();
        s.max_num_steps = 3;
        let mut c = Cvode::new(Decay { k: 1.0, calls: 0 }, 0.0, &[1.0], &[1e-12], 0, s).unwrap();
        let e = c.advance(100.0, &mut [0.0], &mut []).unwrap_err();
        assert_eq!(flag_name(e.flag), "CV_TOO_MUCH_WORK");
    }
}

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
use std::ptr::NonNull;

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
const CV_MEM_FAIL: c_int = -20;
#[cfg_attr(tb_cvode, allow(dead_code))]
const CV_MEM_NULL: c_int = -21;
const CV_ILL_INPUT: c_int = -22;

/// SUNDIALS' functions, linked statically when the build found CVODE (`cfg(tb_cvode)`,
/// `build.rs`).
#[cfg(tb_cvode)]
mod ffi {
    use super::*;
    extern "C" {
        pub fn SUNContext_Create(comm: *mut c_void, ctx: *mut SunContext) -> c_int;
        pub fn SUNContext_Free(ctx: *mut SunContext) -> c_int;
        pub fn N_VNew_Serial(length: SunIndex, ctx: SunContext) -> NVector;
        pub fn N_VDestroy(v: NVector);
        pub fn N_VGetArrayPointer(v: NVector) -> *mut f64;
        pub fn SUNDenseMatrix(m: SunIndex, n: SunIndex, ctx: SunContext) -> SunMatrix;
        pub fn SUNMatDestroy(a: SunMatrix);
        pub fn SUNLinSol_Dense(y: NVector, a: SunMatrix, ctx: SunContext) -> SunLinearSolver;
        pub fn SUNLinSolFree(s: SunLinearSolver) -> c_int;
        pub fn CVodeCreate(lmm: c_int, ctx: SunContext) -> *mut c_void;
        pub fn CVodeInit(mem: *mut c_void, f: RhsFn, t0: f64, y0: NVector) -> c_int;
        pub fn CVodeReInit(mem: *mut c_void, t0: f64, y0: NVector) -> c_int;
        pub fn CVodeSVtolerances(mem: *mut c_void, reltol: f64, abstol: NVector) -> c_int;
        pub fn CVodeRootInit(mem: *mut c_void, nrtfn: c_int, g: Option<RootFn>) -> c_int;
        pub fn CVodeSetLinearSolver(mem: *mut c_void, ls: SunLinearSolver, a: SunMatrix) -> c_int;
        pub fn CVodeSetMaxStep(mem: *mut c_void, hmax: f64) -> c_int;
        pub fn CVodeSetMaxNumSteps(mem: *mut c_void, mxsteps: c_long) -> c_int;
        pub fn CVodeSetNoInactiveRootWarn(mem: *mut c_void) -> c_int;
        pub fn CVodeSetErrHandlerFn(mem: *mut c_void, f: ErrHandlerFn, data: *mut c_void) -> c_int;
        pub fn CVodeSetUserData(mem: *mut c_void, data: *mut c_void) -> c_int;
        pub fn CVode(
            mem: *mut c_void,
            tout: f64,
            yout: NVector,
            tret: *mut f64,
            itask: c_int,
        ) -> c_int;
        pub fn CVodeGetRootInfo(mem: *mut c_void, rootsfound: *mut c_int) -> c_int;
        pub fn CVodeFree(mem: *mut *mut c_void);
    }
}

/// Without CVODE at build time: the same functions, each failing as CVODE does when it
/// cannot allocate (a null pointer, a negative flag). [`super::MeInstance::instantiate`]
/// refuses a Model Exchange FMU before any of them is reached ([`AVAILABLE`]).
#[cfg(not(tb_cvode))]
#[allow(clippy::missing_safety_doc, non_snake_case)]
mod ffi {
    use super::*;
    const NULL: *mut c_void = std::ptr::null_mut();
    pub unsafe fn SUNContext_Create(_: *mut c_void, _: *mut SunContext) -> c_int {
        -1
    }
    pub unsafe fn SUNContext_Free(_: *mut SunContext) -> c_int {
        0
    }
    pub unsafe fn N_VNew_Serial(_: SunIndex, _: SunContext) -> NVector {
        NULL
    }
    pub unsafe fn N_VDestroy(_: NVector) {}
    pub unsafe fn N_VGetArrayPointer(_: NVector) -> *mut f64 {
        std::ptr::null_mut()
    }
    pub unsafe fn SUNDenseMatrix(_: SunIndex, _: SunIndex, _: SunContext) -> SunMatrix {
        NULL
    }
    pub unsafe fn SUNMatDestroy(_: SunMatrix) {}
    pub unsafe fn SUNLinSol_Dense(_: NVector, _: SunMatrix, _: SunContext) -> SunLinearSolver {
        NULL
    }
    pub unsafe fn SUNLinSolFree(_: SunLinearSolver) -> c_int {
        0
    }
    pub unsafe fn CVodeCreate(_: c_int, _: SunContext) -> *mut c_void {
        NULL
    }
    pub unsafe fn CVodeInit(_: *mut c_void, _: RhsFn, _: f64, _: NVector) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeReInit(_: *mut c_void, _: f64, _: NVector) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeSVtolerances(_: *mut c_void, _: f64, _: NVector) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeRootInit(_: *mut c_void, _: c_int, _: Option<RootFn>) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeSetLinearSolver(_: *mut c_void, _: SunLinearSolver, _: SunMatrix) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeSetMaxStep(_: *mut c_void, _: f64) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeSetMaxNumSteps(_: *mut c_void, _: c_long) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeSetNoInactiveRootWarn(_: *mut c_void) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeSetErrHandlerFn(_: *mut c_void, _: ErrHandlerFn, _: *mut c_void) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeSetUserData(_: *mut c_void, _: *mut c_void) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVode(_: *mut c_void, _: f64, _: NVector, _: *mut f64, _: c_int) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeGetRootInfo(_: *mut c_void, _: *mut c_int) -> c_int {
        CV_MEM_NULL
    }
    pub unsafe fn CVodeFree(_: *mut *mut c_void) {}
}
use ffi::*;

/// Whether this build integrates Model Exchange FMUs (SUNDIALS CVODE was found at build
/// time).
pub const AVAILABLE: bool = cfg!(tb_cvode);

/// What to do for Model Exchange in a build without CVODE.
pub const MISSING: &str = "this twinbench was built without SUNDIALS CVODE, the Model Exchange solver: install it (Debian/Ubuntu: apt-get install libsundials-dev; elsewhere SUNDIALS 6.x, double precision, 64-bit index, with TWINBENCH_SUNDIALS_LIB naming the folder of libsundials_cvode.a) and rebuild twinbench (cargo build --release, or cargo install --locked --path . again)";

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
///
/// CVODE keeps two raw pointers of ours, its user data (the [`Callbacks`]) and the error
/// handler's data (the [`Messages`]): both are allocations made with `Box::into_raw`, owned
/// here through `NonNull`, reached only through those pointers (never through a `Box` that
/// moves or is reborrowed while CVODE holds them) and freed once, in `Drop`, after CVODE's
/// memory.
pub struct Cvode<S: System> {
    mem: *mut c_void,
    y: NVector,
    abstol: NVector,
    a: SunMatrix,
    ls: SunLinearSolver,
    ctx: SunContext,
    n: usize,
    nz: usize,
    callbacks: NonNull<Callbacks<S>>,
    messages: NonNull<RefCell<Messages>>,
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
        let fail = |function, flag, message: Option<String>| SolverError {
            function,
            flag,
            message,
        };
        if n == 0 || abstol.len() != n || i32::try_from(nz).is_err() {
            return Err(fail(
                "CVodeInit",
                CV_ILL_INPUT,
                Some(format!(
                    "{n} states with {} absolute tolerances and {nz} root functions (at least one state, one tolerance per state)",
                    abstol.len()
                )),
            ));
        }
        if !AVAILABLE {
            return Err(fail("CVodeCreate", CV_MEM_FAIL, Some(MISSING.into())));
        }
        let mut ctx: SunContext = std::ptr::null_mut();
        // SAFETY: every pointer CVODE returns is checked before use; the integrator owns
        // them and frees them in Drop (in the reverse order).
        let r = unsafe { SUNContext_Create(std::ptr::null_mut(), &mut ctx) };
        if r != 0 || ctx.is_null() {
            return Err(fail("SUNContext_Create", r, None));
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
            callbacks: NonNull::from(Box::leak(Box::new(Callbacks { system, n, nz }))),
            messages: NonNull::from(Box::leak(Box::new(RefCell::new(Messages::default())))),
        };
        unsafe {
            c.y = N_VNew_Serial(n as SunIndex, ctx);
            c.abstol = N_VNew_Serial(n as SunIndex, ctx);
            c.a = SUNDenseMatrix(n as SunIndex, n as SunIndex, ctx);
            if c.y.is_null() || c.abstol.is_null() || c.a.is_null() {
                return Err(fail("N_VNew_Serial", CV_MEM_FAIL, None));
            }
            c.ls = SUNLinSol_Dense(c.y, c.a, ctx);
            c.mem = CVodeCreate(CV_BDF, ctx);
            if c.ls.is_null() || c.mem.is_null() {
                return Err(fail("CVodeCreate", CV_MEM_FAIL, None));
            }
            values(c.y, n).copy_from_slice(x0);
            values(c.abstol, n).copy_from_slice(abstol);
            let data = c.messages.as_ptr() as *mut c_void;
            c.check(
                "CVodeSetErrHandlerFn",
                CVodeSetErrHandlerFn(c.mem, error_handler, data),
            )?;
            c.check("CVodeInit", CVodeInit(c.mem, rhs::<S>, t0, c.y))?;
            let user = c.callbacks.as_ptr() as *mut c_void;
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

    fn messages(&self) -> std::cell::RefMut<'_, Messages> {
        // SAFETY: the allocation lives until Drop; CVODE writes to it only inside a call
        // made through `&mut self` methods, never while this borrow is held.
        unsafe { self.messages.as_ref() }.borrow_mut()
    }

    fn check(&self, function: &'static str, flag: c_int) -> Result<(), SolverError> {
        if flag >= CV_SUCCESS {
            return Ok(());
        }
        Err(SolverError {
            function,
            flag,
            message: self.messages().last_error.take(),
        })
    }

    /// The system CVODE calls (to read what a failed callback left there).
    pub fn system(&mut self) -> &mut S {
        // SAFETY: CVODE uses the pointer only inside calls made through `&mut self`, so
        // this is the only reference while it lives.
        unsafe { &mut self.callbacks.as_mut().system }
    }

    /// CVODE's warnings since the last call, oldest first.
    pub fn take_warnings(&mut self) -> Vec<String> {
        std::mem::take(&mut self.messages().warnings)
    }

    /// Integrate to `tout` (CVODE's `CV_NORMAL` task: it may step past `tout` and
    /// interpolate back), stopping early at a root. The states at the time reached are in
    /// `x` (exactly one per state), the roots found (±1 by direction, else 0) in `found`
    /// (exactly one per root function); other lengths are refused before CVODE runs.
    pub fn advance(
        &mut self,
        tout: f64,
        x: &mut [f64],
        found: &mut [i32],
    ) -> Result<Reached, SolverError> {
        if x.len() != self.n || found.len() != self.nz {
            return Err(SolverError {
                function: "CVode",
                flag: CV_ILL_INPUT,
                message: Some(format!(
                    "{} states and {} roots asked for, the integrator has {} and {}",
                    x.len(),
                    found.len(),
                    self.n,
                    self.nz
                )),
            });
        }
        let mut tret = 0.0;
        // SAFETY: the integrator is set up (new) and its vectors have n values.
        let flag = unsafe { CVode(self.mem, tout, self.y, &mut tret, CV_NORMAL) };
        self.check("CVode", flag)?;
        x.copy_from_slice(unsafe { values(self.y, self.n) });
        found.iter_mut().for_each(|r| *r = 0);
        if flag == CV_ROOT_RETURN {
            // SAFETY: `found` has nz values (checked above), as many as CVODE writes.
            let r = unsafe { CVodeGetRootInfo(self.mem, found.as_mut_ptr()) };
            self.check("CVodeGetRootInfo", r)?;
            return Ok(Reached::Root(tret));
        }
        Ok(Reached::Time(tret))
    }

    /// Start again from `t0` and `x0` (after an event: CVODE forgets its history), with new
    /// absolute tolerances when given. `x0` and the tolerances have one value per state.
    pub fn reinit(
        &mut self,
        t0: f64,
        x0: &[f64],
        abstol: Option<(&[f64], f64)>,
    ) -> Result<(), SolverError> {
        if x0.len() != self.n || abstol.is_some_and(|(a, _)| a.len() != self.n) {
            return Err(SolverError {
                function: "CVodeReInit",
                flag: CV_ILL_INPUT,
                message: Some(format!(
                    "states or tolerances of another length than the integrator's {}",
                    self.n
                )),
            });
        }
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
        // SAFETY: each pointer is null or owned here; CVODE's memory first, then what it
        // used, then the two allocations it pointed to (made by Box::leak in `new`, freed
        // here once).
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
            if !self.ctx.is_null() {
                SUNContext_Free(&mut self.ctx);
            }
            drop(Box::from_raw(self.callbacks.as_ptr()));
            drop(Box::from_raw(self.messages.as_ptr()));
        }
    }
}

#[cfg(all(test, not(tb_cvode)))]
mod without_cvode {
    use super::*;

    struct Zero;
    impl System for Zero {
        fn rhs(&mut self, _t: f64, _x: &[f64], dx: &mut [f64]) -> i32 {
            dx.fill(0.0);
            0
        }
        fn roots(&mut self, _t: f64, _x: &[f64], _g: &mut [f64]) -> i32 {
            0
        }
    }

    #[test]
    fn a_build_without_cvode_says_what_to_install_instead_of_integrating() {
        let s = Settings {
            relative_tolerance: 1e-6,
            max_step: 0.0,
            max_num_steps: 500,
        };
        let e = Cvode::new(Zero, 0.0, &[1.0], &[1e-6], 0, s).err().unwrap();
        assert!(!AVAILABLE);
        assert!(
            e.problem().contains("apt-get install libsundials-dev"),
            "{e:?}"
        );
    }
}

#[cfg(all(test, tb_cvode))]
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

    /// x' = -x from x(0) = 1, with the root function x - 0.5.
    fn decay_with_root() -> Cvode<Decay> {
        let decay = Decay { k: 1.0, calls: 0 };
        Cvode::new(decay, 0.0, &[1.0], &[1e-10], 1, settings()).unwrap()
    }

    #[test]
    fn integrates_finds_roots_and_reinitialises() {
        let mut c = decay_with_root();
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

    /// Slices of another length than the integrator's are refused before CVODE runs (in a
    /// release build too: CVodeGetRootInfo writes one value per root function).
    #[test]
    fn slices_of_the_wrong_length_are_refused_not_written_past() {
        let mut c = decay_with_root();
        let calls = c.system().calls;
        let e = c.advance(1.0, &mut [0.0], &mut []).unwrap_err();
        assert_eq!((e.function, flag_name(e.flag)), ("CVode", "CV_ILL_INPUT"));
        let e = c.advance(1.0, &mut [0.0, 0.0], &mut [0]).unwrap_err();
        assert_eq!(flag_name(e.flag), "CV_ILL_INPUT");
        assert_eq!(c.system().calls, calls, "CVODE ran");
        let e = c.reinit(0.0, &[1.0, 2.0], None).unwrap_err();
        assert_eq!(flag_name(e.flag), "CV_ILL_INPUT");
        let e = c.reinit(0.0, &[1.0], Some((&[], 1e-6))).unwrap_err();
        assert_eq!(flag_name(e.flag), "CV_ILL_INPUT");
        // Still usable: the root x = 0.5 at t = ln 2.
        let mut found = [0];
        let r = c.advance(1.0, &mut [0.0], &mut found).unwrap();
        assert!(
            matches!(r, Reached::Root(t) if (t - 2f64.ln()).abs() < 1e-6),
            "{r:?}"
        );
        // No states, or tolerances of another length: refused at creation.
        let e = Cvode::new(Decay { k: 1.0, calls: 0 }, 0.0, &[], &[], 0, settings())
            .err()
            .unwrap();
        assert_eq!(flag_name(e.flag), "CV_ILL_INPUT");
        let e = Cvode::new(Decay { k: 1.0, calls: 0 }, 0.0, &[1.0], &[], 0, settings())
            .err()
            .unwrap();
        assert_eq!(flag_name(e.flag), "CV_ILL_INPUT");
    }
}

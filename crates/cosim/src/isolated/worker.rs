//! The worker's end: serves one instance over the socket on stdin until the host closes it
//! or says quit. Runs in its own process (`twinbench worker`).

use super::wire::{Dec, Enc, Failure, LibraryTarget, Request, Response, Values, MAX_FRAME};
use crate::backend::Backend;
use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tb_fmi::{
    FmuError, Instance, Instance3, Library, Library3, MeInstance, MeLibrary, MeSettings,
    ModelDescription,
};

/// A library loaded in the worker: FMI 2.0, or FMI 3.0 with its description, or either
/// version for Model Exchange with its description, the .fmu (for messages) and the
/// solver's settings.
#[derive(Clone)]
enum Loaded {
    V2(Arc<Library>),
    V3(Arc<Library3>, Arc<ModelDescription>),
    Me(MeLibrary, Arc<ModelDescription>, PathBuf, MeSettings),
}

/// Waits for `child`, ending this process as it ended (the same exit code, the same signal;
/// `status` from the pipe when the child passed on its own child's). While waiting, watches
/// that `host` is still this process's parent, and kills the child's group when it is gone.
fn mirror(child: libc::pid_t, host: Option<libc::pid_t>, status_pipe: Option<i32>) -> ! {
    let mut status = 0;
    loop {
        // SAFETY: waitpid on our child.
        let r = unsafe { libc::waitpid(child, &mut status, libc::WNOHANG) };
        if r == child {
            break;
        }
        if host.is_some_and(|h| unsafe { libc::getppid() } != h) || r < 0 {
            // The host is gone: end the worker with it (the group is this process's own;
            // in a PID namespace the init's death ends everything in it).
            unsafe {
                libc::kill(child, libc::SIGKILL);
                libc::kill(-libc::getpid(), libc::SIGKILL);
                libc::_exit(4);
            }
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    if let Some(fd) = status_pipe {
        let mut passed = [0u8; 4];
        // SAFETY: a read into a local buffer from our pipe.
        if unsafe { libc::read(fd, passed.as_mut_ptr().cast(), 4) } == 4 {
            status = i32::from_ne_bytes(passed);
        }
    }
    // SAFETY: ending as the worker ended; a signal is re-raised with its default action.
    unsafe {
        if libc::WIFSIGNALED(status) {
            let sig = libc::WTERMSIG(status);
            libc::signal(sig, libc::SIG_DFL);
            libc::kill(libc::getpid(), sig);
        }
        libc::_exit(if libc::WIFEXITED(status) {
            libc::WEXITSTATUS(status)
        } else {
            1
        });
    }
}

/// Splits the worker in two: this process becomes a guard that only waits, and the worker
/// goes on in a child. An FMU that kills its parent (`kill(getppid(), SIGKILL)`) then ends
/// the guard, not the host. The guard ends as the worker does, and kills the worker's
/// process group when the host is gone. Called before any thread is started (fork).
fn guard(host: libc::pid_t) {
    // SAFETY: no other thread runs yet; the child continues as the worker.
    let worker = unsafe { libc::fork() };
    if worker <= 0 {
        // The worker (or, when fork fails, the worker unguarded).
        return;
    }
    mirror(worker, Some(host), None)
}

/// The confined worker's processes: this one (the guard, outside) makes a PID namespace and
/// starts its init, which starts the worker and ends with it (the kernel then kills whatever
/// else runs in the namespace). An FMU sees its parent as the namespace's init, which
/// ignores the signals it could send; the guard and the host are not in its namespace.
/// Returns in the worker; `Err` before any process was started.
fn guard_confined(
    host: libc::pid_t,
    spec: &super::confine::Spec,
) -> Result<(), super::confine::ConfineError> {
    super::confine::new_namespaces(&spec.scratch, &spec.limits)?;
    let mut fds = [0i32; 2];
    // SAFETY: a pipe for the worker's status, from the init to the guard.
    if unsafe { libc::pipe(fds.as_mut_ptr()) } != 0 {
        return Err(super::confine::ConfineError::last_os("pipe"));
    }
    let (read_end, write_end) = (fds[0], fds[1]);
    // SAFETY: single-threaded; the child becomes the namespace's init.
    let init = unsafe { libc::fork() };
    if init < 0 {
        return Err(super::confine::ConfineError::last_os(
            "cannot start the worker's init",
        ));
    }
    if init > 0 {
        unsafe { libc::close(write_end) };
        mirror(init, Some(host), Some(read_end));
    }
    // The init (PID 1 of the namespace): dies with the guard, starts the worker, passes on
    // how it ended.
    unsafe {
        libc::close(read_end);
        libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL, 0, 0, 0);
    }
    // SAFETY: single-threaded; the child is the worker.
    let worker = unsafe { libc::fork() };
    if worker == 0 {
        unsafe {
            libc::close(write_end);
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL, 0, 0, 0);
            libc::setsid();
        }
        return Ok(());
    }
    if worker < 0 {
        eprintln!(
            "twinbench worker: cannot start the worker in its namespace: {}",
            std::io::Error::last_os_error()
        );
        unsafe { libc::_exit(super::confine::CANNOT_CONFINE) };
    }
    // Reap every process of the namespace until the worker ends.
    let mut status = 0;
    loop {
        // SAFETY: waitpid on any child of ours (orphans of the namespace are ours).
        let r = unsafe { libc::waitpid(-1, &mut status, 0) };
        if r == worker
            || (r < 0 && std::io::Error::last_os_error().raw_os_error() != Some(libc::EINTR))
        {
            break;
        }
    }
    let bytes = status.to_ne_bytes();
    // SAFETY: a write of a local buffer to our pipe, then the end (the namespace with it).
    unsafe {
        libc::write(write_end, bytes.as_ptr().cast(), 4);
        libc::_exit(0);
    }
}

pub fn serve_stdio() -> i32 {
    // Take the socket off fd 0, and point fd 0 at /dev/null and fd 1 at stderr, so that
    // an FMU that reads stdin or prints to stdout cannot touch the protocol.
    let fd = unsafe { libc::fcntl(0, libc::F_DUPFD_CLOEXEC, 3) };
    if fd < 0 {
        eprintln!("twinbench worker: no protocol socket on stdin");
        return 2;
    }
    unsafe {
        let null = libc::open(c"/dev/null".as_ptr(), libc::O_RDONLY);
        if null >= 0 {
            libc::dup2(null, 0);
            libc::close(null);
        }
        libc::dup2(2, 1);
    }
    // Nothing the host inherited reaches the FMU: every descriptor but the channel and
    // stdio closed (the host marked them close-on-exec too).
    super::confine::inherit::close_all_but(fd);
    let host = unsafe { libc::getppid() };
    // Before anything is loaded, above all before any thread exists (Landlock and seccomp
    // hold for the calling thread and what it starts): confined, unless the host asked for
    // crash isolation only.
    let spec = std::env::var(super::confine::SPEC_ENV).ok();
    let Some(spec) = spec else {
        guard(host);
        watch_host(host);
        let stream = unsafe { <UnixStream as std::os::fd::FromRawFd>::from_raw_fd(fd) };
        return serve(stream, None);
    };
    let cannot = |why: String| -> i32 {
        eprintln!("twinbench worker: cannot confine the FMU: {why}");
        super::confine::CANNOT_CONFINE
    };
    let spec: super::confine::Spec = match serde_json::from_str(&spec) {
        Ok(s) => s,
        Err(e) => return cannot(format!("the host's confinement is not readable: {e}")),
    };
    if let Err(why) = guard_confined(host, &spec) {
        return cannot(why.to_string());
    }
    std::env::remove_var(super::confine::SPEC_ENV);
    if let Err(why) = super::confine::confine(&spec) {
        return cannot(why.to_string());
    }
    let stream = unsafe { <UnixStream as std::os::fd::FromRawFd>::from_raw_fd(fd) };
    serve(stream, Some(&spec))
}

/// Die with the host even when stuck inside the FMU (a closed socket is noticed only
/// between calls). Not PR_SET_PDEATHSIG: that fires when the host *thread* that started
/// the worker ends, and hosts move simulations between threads. The host is watched by its
/// pid, not as the parent: the parent is the guard, which the FMU may kill. (A confined
/// worker needs no watch: it dies with its namespace's init, which dies with the guard.)
fn watch_host(host: libc::pid_t) {
    let _ = std::thread::Builder::new()
        .name("host-watch".into())
        .spawn(move || loop {
            std::thread::sleep(Duration::from_millis(250));
            // SAFETY: signal 0 only asks whether the process exists.
            if unsafe { libc::kill(host, 0) } != 0 {
                unsafe { libc::_exit(4) };
            }
        });
}

/// Serves requests until the host closes the socket or says quit; a confined worker's
/// `spec` says which limits a failed call may have run into.
fn serve(stream: UnixStream, spec: Option<&super::confine::Spec>) -> i32 {
    let mut worker = Worker::default();
    // A request's length and body usually come in one read.
    let mut reader = std::io::BufReader::new(&stream);
    // Both buffers are reused from request to request.
    let mut request = Vec::new();
    let mut answer = Enc::default();
    loop {
        let mut len = [0u8; 4];
        if reader.read_exact(&mut len).is_err() {
            return 0; // the host is gone
        }
        let n = u32::from_le_bytes(len) as usize;
        if n > MAX_FRAME {
            eprintln!("twinbench worker: request of {n} bytes refused");
            return 2;
        }
        request.resize(n, 0);
        if reader.read_exact(&mut request).is_err() {
            return 0;
        }
        let Some(mut response) = worker.serve(&request) else {
            drop(worker);
            return 0;
        };
        if let (Some(error), Some(spec)) = (response.error.as_mut(), spec) {
            error.add_notes(spec.limits.reached(&spec.scratch));
        }
        answer.start_frame();
        response.encode(&mut answer);
        if (&stream).write_all(answer.finish_frame()).is_err() {
            return 0;
        }
    }
}

/// The preloads, then the FMU's library, which is loaded only after every check of the
/// host passed (the unpacked copy verified here again: the host's check and this load are
/// different moments); errors name the .fmu, not the unpacked copy.
fn load_library(target: &LibraryTarget) -> Result<Loaded, FmuError> {
    let source = std::path::Path::new(&target.source);
    for c in &target.checks {
        c.verify().map_err(|why| FmuError::Load {
            path: source.to_path_buf(),
            message: format!("the unpacked copy is not the FMU's, not loaded: {why}"),
        })?;
    }
    if !target
        .checks
        .iter()
        .any(|c| c.path() == std::path::Path::new(&target.path))
    {
        return Err(FmuError::Load {
            path: source.to_path_buf(),
            message: "the host sent no check of the library; not loaded".into(),
        });
    }
    for p in &target.preload {
        tb_fmi::import::library::preload_global(std::path::Path::new(p))?;
    }
    if !target.description.is_empty() {
        let xml =
            std::fs::read_to_string(&target.description).map_err(|e| FmuError::Description {
                path: source.to_path_buf(),
                message: e.to_string(),
            })?;
        let md =
            tb_fmi::import::description::parse(&xml).map_err(|e| FmuError::DescriptionParse {
                path: source.to_path_buf(),
                source: Box::new(e),
            })?;
        if target.model_exchange {
            let path = std::path::Path::new(&target.path);
            let named = |e| {
                tb_fmi::import::archive::library_error(
                    source,
                    &md.fmi_version,
                    &target.model_identifier,
                    e,
                )
            };
            let lib = match md.fmi_version.starts_with("3.") {
                true => MeLibrary::V3(Arc::new(
                    Library3::load_model_exchange(path).map_err(named)?,
                )),
                false => {
                    MeLibrary::V2(Arc::new(Library::load_model_exchange(path).map_err(named)?))
                }
            };
            let settings = MeSettings {
                relative_tolerance: (!target.tolerance.is_nan()).then_some(target.tolerance),
            };
            return Ok(Loaded::Me(
                lib,
                Arc::new(md),
                source.to_path_buf(),
                settings,
            ));
        }
        let lib = Library3::load(std::path::Path::new(&target.path)).map_err(|e| {
            tb_fmi::import::archive::library_error(
                source,
                &md.fmi_version,
                &target.model_identifier,
                e,
            )
        })?;
        return Ok(Loaded::V3(Arc::new(lib), Arc::new(md)));
    }
    Library::load(std::path::Path::new(&target.path))
        .map(Arc::new)
        .map_err(|e| {
            tb_fmi::import::archive::library_error(source, "2.0", &target.model_identifier, e)
        })
        .map(Loaded::V2)
}

/// What a worker holds between requests: the instance and the library (loaded once; the
/// instance, dropped first, holds it too).
#[derive(Default)]
struct Worker {
    instance: Option<Box<dyn Backend>>,
    library: Option<Loaded>,
}

/// A malformed request or one out of order.
fn protocol(message: impl Into<String>) -> Failure {
    Failure::Other(message.into())
}

impl Worker {
    /// Run one request's operations in order until the first error, and answer; `None`
    /// when the host says quit.
    fn serve(&mut self, request: &[u8]) -> Option<Response> {
        let mut d = Dec::new(request);
        let mut results = Vec::new();
        let mut error = None;
        while !d.at_end() {
            let outcome = match Request::decode(&mut d) {
                Ok(Request::Quit) => return None,
                Ok(op) => self.run(op),
                Err(m) => Err(protocol(m.to_string())),
            };
            match outcome {
                Ok(Some(values)) => results.push(values),
                Ok(None) => {}
                Err(e) => {
                    error = Some(e);
                    break;
                }
            }
        }
        Some(Response {
            time: self.instance.as_ref().map_or(0.0, |i| i.time()),
            results,
            error,
        })
    }

    /// One operation; a get's values.
    fn run(&mut self, op: Request<'_>) -> Result<Option<Values>, Failure> {
        match op {
            Request::Instantiate {
                library,
                name,
                guid,
                resources,
                logging,
            } => {
                let library = self.load(&library)?;
                self.instantiate(library, &name, &guid, &resources, logging)?;
                Ok(None)
            }
            Request::Probe(library) => Ok(Some(probe(&self.load(&library)?))),
            op => {
                let i = self
                    .instance
                    .as_deref_mut()
                    .ok_or_else(|| protocol("no instance: instantiate first"))?;
                Ok(call(i, op)?)
            }
        }
    }

    /// The FMU's library, loaded on the first request that names it.
    fn load(&mut self, target: &LibraryTarget) -> Result<Loaded, FmuError> {
        if let Some(l) = &self.library {
            return Ok(l.clone());
        }
        let l = load_library(target)?;
        self.library = Some(l.clone());
        Ok(l)
    }

    /// A fresh instance (the previous one freed first).
    fn instantiate(
        &mut self,
        library: Loaded,
        name: &str,
        guid: &str,
        resources: &str,
        logging: bool,
    ) -> Result<(), FmuError> {
        self.instance = None;
        let res = PathBuf::from(resources);
        let mut i: Box<dyn Backend> = match library {
            Loaded::V2(l) => Box::new(Instance::instantiate(l, name, guid, Some(&res), logging)?),
            Loaded::V3(l, md) => {
                Box::new(Instance3::instantiate(l, &md, name, Some(&res), logging)?)
            }
            Loaded::Me(l, md, source, settings) => Box::new(MeInstance::instantiate(
                l,
                &md,
                &source,
                name,
                Some(&res),
                logging,
                settings,
            )?),
        };
        i.set_echo(false);
        self.instance = Some(i);
        Ok(())
    }
}

/// What a loaded library reports: its version and the optional functions it lacks.
fn probe(library: &Loaded) -> Values {
    Values::Text(match library {
        Loaded::V2(l) => vec![l.version.clone(), l.missing_optional.join(",")],
        Loaded::V3(l, _) => vec![l.version.clone(), String::new()],
        Loaded::Me(MeLibrary::V2(l), ..) => vec![l.version.clone(), l.missing_optional.join(",")],
        Loaded::Me(MeLibrary::V3(l), ..) => vec![l.version.clone(), String::new()],
    })
}

/// One call on the instance; a get's values.
fn call(i: &mut dyn Backend, op: Request<'_>) -> Result<Option<Values>, Failure> {
    match op {
        Request::SetDebugLogging(on) => i.set_debug_logging(on)?,
        Request::SetupExperiment {
            start,
            stop,
            tolerance,
        } => i.setup_experiment(tb_fmi::Experiment {
            start,
            stop,
            tolerance,
        })?,
        Request::EnterInit => i.enter_initialization_mode()?,
        Request::ExitInit => i.exit_initialization_mode()?,
        Request::Terminate => i.terminate()?,
        Request::Reset => i.reset()?,
        Request::SetReal { vrs, values } => i.set_real(&vrs, &values)?,
        Request::SetInteger { vrs, values } => i.set_integer(&vrs, &values)?,
        Request::SetBoolean { vrs, values } => i.set_boolean(&vrs, &values)?,
        Request::SetString { vrs, values } => {
            let refs: Vec<&str> = values.iter().map(|s| s.as_ref()).collect();
            i.set_string(&vrs, &refs)?
        }
        Request::DoStep { t, h } => i.do_step(t, h)?,
        Request::Realtime(spec) => return realtime(i, &spec).map(Some),
        op => return get(i, op).map(Some),
    }
    Ok(None)
}

/// A real-time check of the instance: the measurement as JSON.
fn realtime(i: &mut dyn Backend, spec: &str) -> Result<Values, Failure> {
    let spec: crate::realtime::CheckSpec =
        serde_json::from_str(spec).map_err(|e| protocol(format!("real-time check: {e}")))?;
    let m = crate::realtime::measure(i, &spec)?;
    let json = serde_json::to_string(&m).map_err(|e| protocol(e.to_string()))?;
    Ok(Values::Text(vec![json]))
}

/// A get's values (the operations that are answered).
fn get(i: &mut dyn Backend, op: Request<'_>) -> Result<Values, Failure> {
    Ok(match op {
        Request::GetReal { vrs } => {
            let mut out = vec![0.0; vrs.len()];
            i.get_real(&vrs, &mut out)?;
            Values::Real(out)
        }
        Request::GetInteger { vrs } => {
            let mut out = vec![0; vrs.len()];
            i.get_integer(&vrs, &mut out)?;
            Values::Int(out)
        }
        Request::GetBoolean { vrs } => {
            let mut out = vec![0; vrs.len()];
            i.get_boolean(&vrs, &mut out)?;
            Values::Int(out)
        }
        Request::GetString { vrs } => {
            let mut out = Vec::new();
            i.get_string(&vrs, &mut out)?;
            Values::Text(out)
        }
        Request::FmuTerminated => {
            let last = i.terminated_by_fmu();
            Values::Real(vec![last.is_some() as u8 as f64, last.unwrap_or(0.0)])
        }
        other => return Err(protocol(format!("operation {} out of place", other.code()))),
    })
}

// These run a model linked in natively: they need the `native` feature (on by default).
#[cfg(all(test, feature = "native"))]
mod tests {
    use super::*;
    use crate::native::NativeBackend;
    use fmu_export::variables::*;
    use fmu_export::{Context, Model, ModelError, ModelInfo};
    use tb_fmi::fmi2::fmi2Status;
    use tb_fmi::{CallStatus, FmiFunction, Function};

    fmu_export::variables! {
        pub struct TwiceVars {
            u: Real = 0.0 => input(1).describe("Input"),
            y: Real = 0.0 => output(2).depends_on(&[u]).describe("2·u"),
            steps: Integer = 0 => discrete_output(3).describe("Steps taken"),
        }
    }

    /// y = 2·u.
    #[derive(Clone)]
    struct Twice;

    impl Model for Twice {
        type Vars = TwiceVars;
        const INFO: ModelInfo = ModelInfo::new("twice", "y = 2·u", "1").experiment(1.0, 0.5);
        fn initialize(_v: &mut TwiceVars, _ctx: &Context) -> Result<Self, ModelError> {
            Ok(Twice)
        }
        fn do_step(&mut self, v: &mut TwiceVars, _t: f64, _h: f64) -> Result<(), ModelError> {
            v.steps += 1;
            Ok(())
        }
        fn calculate_outputs(&mut self, v: &mut TwiceVars) {
            v.y = 2.0 * v.u;
        }
    }

    impl fmu_export::Stateless for Twice {}

    /// A worker serving a natively run instance (no library, no process).
    fn worker() -> Worker {
        Worker {
            instance: Some(Box::new(NativeBackend::<Twice>::new("w", None, false))),
            library: None,
        }
    }

    fn request(ops: &[Request]) -> Vec<u8> {
        let mut e = Enc::default();
        ops.iter().for_each(|op| op.encode(&mut e));
        e.0
    }

    #[test]
    fn a_request_without_an_instance_is_an_error_not_a_panic() {
        let mut w = Worker::default();
        let r = w
            .serve(&request(&[Request::DoStep { t: 0.0, h: 1.0 }]))
            .unwrap();
        assert_eq!(
            r.error,
            Some(Failure::Other("no instance: instantiate first".into()))
        );
        assert_eq!((r.time, r.results.len()), (0.0, 0));
        // An instantiation cut short is a protocol error, not a panic.
        let r = w.serve(&[200]).unwrap();
        assert!(
            matches!(&r.error, Some(Failure::Other(m)) if m.contains("truncated message")),
            "{r:?}"
        );
        assert!(w.serve(&request(&[Request::Quit])).is_none());
    }

    #[test]
    fn a_request_runs_in_order_and_answers_its_gets() {
        let mut w = worker();
        let ops = [
            Request::SetupExperiment {
                start: 0.0,
                stop: Some(1.0),
                tolerance: None,
            },
            Request::EnterInit,
            Request::SetReal {
                vrs: vec![1].into(),
                values: vec![1.5].into(),
            },
            Request::ExitInit,
            Request::GetReal {
                vrs: vec![2, 1].into(),
            },
            Request::DoStep { t: 0.0, h: 0.5 },
            Request::GetInteger {
                vrs: vec![3].into(),
            },
            Request::FmuTerminated,
        ];
        let bytes = request(&ops);
        let r = w.serve(&bytes).unwrap();
        assert_eq!(
            r,
            Response {
                time: 0.5,
                results: vec![
                    Values::Real(vec![3.0, 1.5]),
                    Values::Int(vec![1]),
                    Values::Real(vec![0.0, 0.0]),
                ],
                error: None,
            }
        );
        // As the host reads it.
        let mut e = Enc::default();
        r.encode(&mut e);
        assert_eq!(Response::decode(&e.0, &ops).unwrap(), r);
    }

    #[test]
    fn a_request_stops_at_its_first_error() {
        let mut w = worker();
        let setup = [
            Request::SetupExperiment {
                start: 0.0,
                stop: None,
                tolerance: Some(1e-6),
            },
            Request::EnterInit,
            Request::ExitInit,
        ];
        assert_eq!(w.serve(&request(&setup)).unwrap().error, None);
        let ops = [
            Request::GetReal {
                vrs: vec![2].into(),
            },
            // y is a Real: as an Integer it is refused.
            Request::GetInteger {
                vrs: vec![2].into(),
            },
            Request::DoStep { t: 0.0, h: 0.5 },
        ];
        let r = w.serve(&request(&ops)).unwrap();
        assert_eq!(r.results, [Values::Real(vec![0.0])]);
        let Some(Failure::Call {
            function,
            status,
            time,
            log,
        }) = &r.error
        else {
            panic!("{r:?}")
        };
        assert_eq!(
            (function, *status, *time),
            (
                &FmiFunction::Fmi2(Function::GetInteger),
                CallStatus::Fmi2(fmi2Status::ERROR),
                0.0
            )
        );
        assert!(
            log.iter().any(|l| l.contains("is Real, not Integer")),
            "{log:?}"
        );
        // The step after the error was not taken.
        assert_eq!(r.time, 0.0);
        // A malformed operation after good ones: they ran, then the protocol error.
        let mut bytes = request(&[Request::DoStep { t: 0.0, h: 0.5 }]);
        bytes.push(150);
        let r = w.serve(&bytes).unwrap();
        assert_eq!(r.time, 0.5);
        assert_eq!(
            r.error,
            Some(Failure::Other("unknown operation 150".into()))
        );
    }
}

//! The worker's end: serves one instance over the socket on stdin until the host closes it
//! or says quit. Runs in its own process (`twinbench worker`).

use super::wire::{frame, kind, op, Dec, Enc, LibraryTarget, MAX_FRAME};
use crate::backend::Backend;
use std::io::{Read, Write};
use std::os::unix::net::UnixStream;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tb_fmi::{FmuError, Instance, Instance3, Library, Library3, ModelDescription};

/// A library loaded in the worker: FMI 2.0, or FMI 3.0 with its description.
#[derive(Clone)]
enum Loaded {
    V2(Arc<Library>),
    V3(Arc<Library3>, Arc<ModelDescription>),
}

/// Serve the protocol on stdin until the host closes it or says quit. Returns the exit code.
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
    // Die with the host even when stuck inside the FMU (a closed socket is noticed only
    // between calls). Not PR_SET_PDEATHSIG: that fires when the host *thread* that started
    // the worker ends, and hosts move simulations between threads.
    let parent = unsafe { libc::getppid() };
    let _ = std::thread::Builder::new()
        .name("host-watch".into())
        .spawn(move || loop {
            std::thread::sleep(Duration::from_millis(250));
            if unsafe { libc::getppid() } != parent {
                unsafe { libc::_exit(4) };
            }
        });
    let stream = unsafe { <UnixStream as std::os::fd::FromRawFd>::from_raw_fd(fd) };
    serve(stream)
}

fn serve(mut stream: UnixStream) -> i32 {
    let mut inst: Option<Box<dyn Backend>> = None;
    let mut lib_cache: Option<Loaded> = None;
    let mut buf = Vec::new();
    loop {
        let mut len = [0u8; 4];
        if stream.read_exact(&mut len).is_err() {
            return 0; // the host is gone
        }
        let n = u32::from_le_bytes(len) as usize;
        if n > MAX_FRAME {
            eprintln!("twinbench worker: request of {n} bytes refused");
            return 2;
        }
        buf.resize(n, 0);
        if stream.read_exact(&mut buf).is_err() {
            return 0;
        }
        let mut out = Enc::default();
        let quit = run_ops(&buf, &mut inst, &mut lib_cache, &mut out);
        if quit {
            drop(inst);
            return 0;
        }
        if stream.write_all(&frame(&out.0)).is_err() {
            return 0;
        }
    }
}

/// The preloads, then the FMU's library; errors name the .fmu, not the unpacked copy.
fn load_library(target: &LibraryTarget) -> Result<Loaded, FmuError> {
    for p in &target.preload {
        tb_fmi::import::library::preload_global(std::path::Path::new(p))?;
    }
    let source = std::path::Path::new(&target.source);
    if !target.description.is_empty() {
        let xml =
            std::fs::read_to_string(&target.description).map_err(|e| FmuError::Description {
                path: source.to_path_buf(),
                message: e.to_string(),
            })?;
        let md =
            tb_fmi::import::description::parse(&xml).map_err(|message| FmuError::Description {
                path: source.to_path_buf(),
                message,
            })?;
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

/// Run one request; write the response into `out`. Returns true on quit.
fn run_ops(
    req: &[u8],
    inst: &mut Option<Box<dyn Backend>>,
    lib_cache: &mut Option<Loaded>,
    out: &mut Enc,
) -> bool {
    let mut d = Dec::new(req);
    let mut results = Enc::default();
    let mut n_gets = 0u32;
    let mut reals = Vec::new();
    let mut ints = Vec::new();
    let err: Option<FmuError> = loop {
        if d.at_end() {
            break None;
        }
        let r = (|| -> Result<bool, Result<FmuError, String>> {
            let code = d.u8().map_err(Err)?;
            if code == op::QUIT {
                return Ok(true);
            }
            if code == op::INSTANTIATE || code == op::PROBE {
                let target = LibraryTarget::decode(&mut d).map_err(Err)?;
                let library = match lib_cache {
                    Some(l) => l.clone(),
                    None => load_library(&target).map_err(Ok)?,
                };
                *lib_cache = Some(library.clone());
                if code == op::PROBE {
                    match &library {
                        Loaded::V2(l) => {
                            results.str(&l.version);
                            results.str(&l.missing_optional.join(","));
                        }
                        Loaded::V3(l, _) => {
                            results.str(&l.version);
                            results.str("");
                        }
                    }
                    n_gets += 1;
                    return Ok(false);
                }
                let name = d.str().map_err(Err)?;
                let guid = d.str().map_err(Err)?;
                let res = PathBuf::from(d.str().map_err(Err)?);
                let logging = d.u8().map_err(Err)? != 0;
                *inst = None;
                let mut i: Box<dyn Backend> = match library {
                    Loaded::V2(l) => Box::new(
                        Instance::instantiate(l, &name, &guid, Some(&res), logging).map_err(Ok)?,
                    ),
                    Loaded::V3(l, md) => Box::new(
                        Instance3::instantiate(l, &md, &name, Some(&res), logging).map_err(Ok)?,
                    ),
                };
                i.set_echo(false);
                *inst = Some(i);
                return Ok(false);
            }
            let i = inst
                .as_mut()
                .ok_or_else(|| Err("no instance: instantiate first".to_string()))?;
            match code {
                op::SET_DEBUG_LOGGING => {
                    let on = d.u8().map_err(Err)? != 0;
                    i.set_debug_logging(on).map_err(Ok)?
                }
                op::SETUP_EXPERIMENT => {
                    let start = d.f64().map_err(Err)?;
                    let has = d.u8().map_err(Err)? != 0;
                    let stop = d.f64().map_err(Err)?;
                    i.setup_experiment(start, has.then_some(stop)).map_err(Ok)?
                }
                op::ENTER_INIT => i.enter_initialization_mode().map_err(Ok)?,
                op::EXIT_INIT => i.exit_initialization_mode().map_err(Ok)?,
                op::TERMINATE => i.terminate().map_err(Ok)?,
                op::RESET => i.reset().map_err(Ok)?,
                op::SET_REAL => {
                    let vrs = d.vrs().map_err(Err)?;
                    reals.clear();
                    for _ in 0..vrs.len() {
                        reals.push(d.f64().map_err(Err)?);
                    }
                    i.set_real(&vrs, &reals).map_err(Ok)?
                }
                op::SET_INTEGER | op::SET_BOOLEAN => {
                    let vrs = d.vrs().map_err(Err)?;
                    ints.clear();
                    for _ in 0..vrs.len() {
                        ints.push(d.i32().map_err(Err)?);
                    }
                    if code == op::SET_INTEGER {
                        i.set_integer(&vrs, &ints).map_err(Ok)?
                    } else {
                        i.set_boolean(&vrs, &ints).map_err(Ok)?
                    }
                }
                op::SET_STRING => {
                    let vrs = d.vrs().map_err(Err)?;
                    let mut texts = Vec::with_capacity(vrs.len());
                    for _ in 0..vrs.len() {
                        texts.push(d.str().map_err(Err)?);
                    }
                    let refs: Vec<&str> = texts.iter().map(String::as_str).collect();
                    i.set_string(&vrs, &refs).map_err(Ok)?
                }
                op::GET_STRING => {
                    let vrs = d.vrs().map_err(Err)?;
                    let mut texts = Vec::new();
                    i.get_string(&vrs, &mut texts).map_err(Ok)?;
                    texts.iter().for_each(|t| results.str(t));
                    n_gets += 1;
                }
                op::GET_REAL => {
                    let vrs = d.vrs().map_err(Err)?;
                    reals.clear();
                    reals.resize(vrs.len(), 0.0);
                    i.get_real(&vrs, &mut reals).map_err(Ok)?;
                    reals.iter().for_each(|&x| results.f64(x));
                    n_gets += 1;
                }
                op::GET_INTEGER | op::GET_BOOLEAN => {
                    let vrs = d.vrs().map_err(Err)?;
                    ints.clear();
                    ints.resize(vrs.len(), 0);
                    if code == op::GET_INTEGER {
                        i.get_integer(&vrs, &mut ints).map_err(Ok)?
                    } else {
                        i.get_boolean(&vrs, &mut ints).map_err(Ok)?
                    }
                    ints.iter().for_each(|&x| results.i32(x));
                    n_gets += 1;
                }
                op::FMU_TERMINATED => {
                    let last = i.terminated_by_fmu();
                    results.f64(last.is_some() as u8 as f64);
                    results.f64(last.unwrap_or(0.0));
                    n_gets += 1;
                }
                op::DO_STEP => {
                    let t = d.f64().map_err(Err)?;
                    let h = d.f64().map_err(Err)?;
                    i.do_step(t, h).map_err(Ok)?
                }
                c => return Err(Err(format!("unknown operation {c}"))),
            }
            Ok(false)
        })();
        match r {
            Ok(true) => return true,
            Ok(false) => {}
            Err(Ok(e)) => break Some(e),
            Err(Err(m)) => {
                break Some(FmuError::Isolated {
                    instance: String::new(),
                    function: "the protocol".into(),
                    time: 0.0,
                    cause: m,
                    log: Vec::new(),
                })
            }
        }
    };
    out.u8(err.is_some() as u8);
    out.u32(n_gets);
    out.f64(inst.as_ref().map_or(0.0, |i| i.time()));
    out.0.extend_from_slice(&results.0);
    if let Some(e) = err {
        match e {
            FmuError::Call {
                function,
                status,
                time,
                log,
                ..
            } => {
                out.u8(kind::CALL);
                out.u8(function as u8);
                out.i32(status.0);
                out.f64(time);
                out.u32(log.len() as u32);
                log.iter().for_each(|l| out.str(l));
            }
            FmuError::Instantiate { message, .. } => {
                out.u8(kind::INSTANTIATE);
                out.str(&message);
            }
            FmuError::Unsupported { what, .. } => {
                out.u8(kind::UNSUPPORTED);
                out.u8(tb_fmi::Function::from_name(what).map_or(u8::MAX, |f| f as u8));
            }
            FmuError::Isolated { cause, .. } => {
                out.u8(kind::OTHER);
                out.str(&cause);
            }
            other => {
                out.u8(kind::OTHER);
                out.str(&other.to_string());
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_without_an_instance_is_an_error_not_a_panic() {
        let mut out = Enc::default();
        let mut e = Enc::default();
        e.u8(op::DO_STEP);
        e.f64(0.0);
        e.f64(1.0);
        assert!(!run_ops(&e.0, &mut None, &mut None, &mut out));
        assert_eq!(out.0[0], 1);
        let mut out = Enc::default();
        assert!(!run_ops(&[200], &mut None, &mut None, &mut out));
        assert_eq!(out.0[0], 1);
    }
}

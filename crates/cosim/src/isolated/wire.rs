//! The worker protocol's codec: length-prefixed little-endian frames. A request is a list
//! of operations; an FMI call's operation code is its number in [`tb_fmi::FUNCTIONS`]
//! (`Function as u8`), so the table that loads an FMU's symbols also names the calls on the
//! wire. Codes of the protocol's own: [`op::INSTANTIATE`] (load the library, then
//! `fmi2Instantiate`), [`op::PROBE`] (load the library and report on it) and [`op::QUIT`].
//!
//! The library is named by [`LibraryTarget`]: its unpacked path, the .fmu and model
//! identifier (for messages) and the libraries to preload in the worker.
//!
//! A response: `ok: u8`, the number of completed gets `u32`, the instance's time `f64`, the
//! get results, then (when not ok) the error: a [`kind`] and its fields.

use tb_fmi::Function;

/// Operation codes.
pub mod op {
    use tb_fmi::Function;

    /// Load the FMU's library (a [`super::LibraryTarget`]), then instantiate (name, GUID,
    /// resource folder, logging).
    pub const INSTANTIATE: u8 = 200;
    /// Free the instance and end the worker.
    pub const QUIT: u8 = 201;
    /// Load the FMU's library (a [`super::LibraryTarget`]) and answer with two strings:
    /// what `fmi2GetVersion` returned and the missing optional functions (comma-separated).
    pub const PROBE: u8 = 202;
    /// After a discarded step: two Reals, whether the FMU asks to end the simulation (1 or
    /// 0) and its last successful time.
    pub const FMU_TERMINATED: u8 = 203;

    pub const SET_DEBUG_LOGGING: u8 = Function::SetDebugLogging as u8;
    pub const SETUP_EXPERIMENT: u8 = Function::SetupExperiment as u8;
    pub const ENTER_INIT: u8 = Function::EnterInitializationMode as u8;
    pub const EXIT_INIT: u8 = Function::ExitInitializationMode as u8;
    pub const TERMINATE: u8 = Function::Terminate as u8;
    pub const RESET: u8 = Function::Reset as u8;
    pub const SET_REAL: u8 = Function::SetReal as u8;
    pub const SET_INTEGER: u8 = Function::SetInteger as u8;
    pub const SET_BOOLEAN: u8 = Function::SetBoolean as u8;
    pub const GET_REAL: u8 = Function::GetReal as u8;
    pub const GET_INTEGER: u8 = Function::GetInteger as u8;
    pub const GET_BOOLEAN: u8 = Function::GetBoolean as u8;
    pub const GET_STRING: u8 = Function::GetString as u8;
    pub const SET_STRING: u8 = Function::SetString as u8;
    pub const DO_STEP: u8 = Function::DoStep as u8;
}

/// Error kinds in a response.
pub mod kind {
    /// An FMI call returned a status that stops the caller: function code, status, time, log.
    pub const CALL: u8 = 0;
    /// `fmi2Instantiate` failed: the message.
    pub const INSTANTIATE: u8 = 1;
    /// An optional function the FMU does not export: its code.
    pub const UNSUPPORTED: u8 = 2;
    /// Anything else: a message.
    pub const OTHER: u8 = 3;
}

/// The function an operation code stands for (for messages).
pub fn function_of(code: u8) -> Option<Function> {
    match code {
        op::INSTANTIATE => Some(Function::Instantiate),
        op::PROBE => Some(Function::GetVersion),
        op::FMU_TERMINATED => Some(Function::GetBooleanStatus),
        op::QUIT => Some(Function::FreeInstance),
        c => Function::from_u8(c),
    }
}

/// Largest frame accepted (a corrupted or forged length must not allocate gigabytes).
/// A step's answer is a few kilobytes; 64 MiB leaves room for huge string outputs.
pub const MAX_FRAME: usize = 64 << 20;

/// The FMU library a worker loads, with what it needs to name it in messages.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LibraryTarget {
    /// The unpacked library.
    pub path: String,
    /// The .fmu the user gave.
    pub source: String,
    pub model_identifier: String,
    /// Libraries loaded with RTLD_GLOBAL first (the system file's `preload`).
    pub preload: Vec<String>,
    /// FMI 3.0: the unpacked modelDescription.xml (the worker needs its variables' types);
    /// empty for FMI 2.0.
    pub description: String,
}

impl LibraryTarget {
    pub fn encode(&self, e: &mut Enc) {
        e.str(&self.path);
        e.str(&self.source);
        e.str(&self.model_identifier);
        e.u32(self.preload.len() as u32);
        self.preload.iter().for_each(|p| e.str(p));
        e.str(&self.description);
    }
    pub fn decode(d: &mut Dec) -> Result<LibraryTarget, String> {
        let path = d.str()?;
        let source = d.str()?;
        let model_identifier = d.str()?;
        let n = d.count(4)?;
        let preload = (0..n).map(|_| d.str()).collect::<Result<_, _>>()?;
        let description = d.str()?;
        Ok(LibraryTarget {
            path,
            source,
            model_identifier,
            preload,
            description,
        })
    }
}

/// A frame: the payload's length, then the payload.
pub fn frame(payload: &[u8]) -> Vec<u8> {
    let mut v = Vec::with_capacity(payload.len() + 4);
    v.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    v.extend_from_slice(payload);
    v
}

/// Writes values in the protocol's encoding.
#[derive(Default)]
pub struct Enc(pub Vec<u8>);

impl Enc {
    pub fn u8(&mut self, x: u8) {
        self.0.push(x);
    }
    pub fn u32(&mut self, x: u32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub fn f64(&mut self, x: f64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub fn i32(&mut self, x: i32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    pub fn str(&mut self, s: &str) {
        self.u32(s.len() as u32);
        self.0.extend_from_slice(s.as_bytes());
    }
    pub fn vrs(&mut self, vrs: &[u32]) {
        self.u32(vrs.len() as u32);
        for &v in vrs {
            self.u32(v);
        }
    }
}

/// Reads values in the protocol's encoding; every read is checked against the frame.
pub struct Dec<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Dec<'a> {
    pub fn new(b: &'a [u8]) -> Self {
        Dec { b, pos: 0 }
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if self.b.len() - self.pos < n {
            return Err(format!(
                "truncated message: {n} bytes needed at offset {}",
                self.pos
            ));
        }
        let s = &self.b[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    pub fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.array()?))
    }
    pub fn i32(&mut self) -> Result<i32, String> {
        Ok(i32::from_le_bytes(self.array()?))
    }
    pub fn str(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.take(n)?).into_owned())
    }
    /// A count of elements of `size` bytes each, checked against what remains.
    pub fn count(&mut self, size: usize) -> Result<usize, String> {
        let n = self.u32()? as usize;
        if n.saturating_mul(size) > self.b.len() - self.pos {
            return Err(format!("count {n} exceeds the message"));
        }
        Ok(n)
    }
    pub fn vrs(&mut self) -> Result<Vec<u32>, String> {
        let n = self.count(4)?;
        (0..n).map(|_| self.u32()).collect()
    }
    pub fn at_end(&self) -> bool {
        self.pos == self.b.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decoder_refuses_truncated_and_oversized_counts() {
        let mut d = Dec::new(&[5, 0, 0, 0, 1, 2]);
        assert!(d.count(4).unwrap_err().contains("exceeds"));
        let mut d = Dec::new(&[1, 0]);
        assert!(d.u32().unwrap_err().contains("truncated"));
    }

    #[test]
    fn library_targets_round_trip_and_truncation_is_refused() {
        let t = LibraryTarget {
            path: "/c/x.so".into(),
            source: "x.fmu".into(),
            model_identifier: "x".into(),
            preload: vec!["libpython3.11.so".into(), "b".into()],
            description: "/c/modelDescription.xml".into(),
        };
        let mut e = Enc::default();
        t.encode(&mut e);
        assert_eq!(LibraryTarget::decode(&mut Dec::new(&e.0)).unwrap(), t);
        let cut = &e.0[..e.0.len() - 3];
        assert!(LibraryTarget::decode(&mut Dec::new(cut)).is_err());
    }

    #[test]
    fn fmi_calls_are_coded_by_the_function_table() {
        assert_eq!(function_of(op::DO_STEP), Some(Function::DoStep));
        assert_eq!(function_of(op::GET_REAL).unwrap().name(), "fmi2GetReal");
        assert_eq!(function_of(op::INSTANTIATE), Some(Function::Instantiate));
        assert_eq!(function_of(150), None);
        // The protocol's own codes are outside the table.
        assert!(Function::from_u8(op::INSTANTIATE).is_none());
        assert!(Function::from_u8(op::PROBE).is_none());
        assert!(Function::from_u8(op::QUIT).is_none());
    }
}

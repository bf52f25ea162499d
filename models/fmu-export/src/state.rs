//! Serialized FMU states: what a model saves of itself ([`ModelState`], or nothing for a
//! [`Stateless`] one) and the little-endian writer and reader it uses (the runtime writes
//! its own fields and the variables with the same pair).

use crate::model::ModelError;

/// The dynamic state of a model in a serialized FMU state (fmi2SerializeFMUstate): what
/// [`crate::Model::initialize`] does not rebuild from the parameters and resources. Every
/// model implements it, or is [`Stateless`].
#[diagnostic::on_unimplemented(
    message = "the model `{Self}` neither saves its dynamic state nor is `Stateless`",
    note = "implement `fmu_export::ModelState` (save_state and load_state) for a model with dynamic state, or write `impl fmu_export::Stateless for {Self} {{}}` for a model without"
)]
pub trait ModelState {
    /// Append the dynamic state (not the variables, not resources) to `w`.
    fn save_state(&self, w: &mut StateWriter);

    /// Read back what [`ModelState::save_state`] wrote, into a model initialised with the
    /// same parameters and resources.
    fn load_state(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError>;
}

/// A model without dynamic state (its outputs follow from parameters and inputs):
/// `impl Stateless for MyModel {}` gives it the [`ModelState`] that saves nothing.
pub trait Stateless {}

impl<M: Stateless> ModelState for M {
    fn save_state(&self, _: &mut StateWriter) {}

    fn load_state(&mut self, _: &mut StateReader<'_>) -> Result<(), ModelError> {
        Ok(())
    }
}

/// Little-endian writer for serialized FMU states.
#[derive(Default, Debug)]
pub struct StateWriter {
    pub bytes: Vec<u8>,
}

impl StateWriter {
    pub fn f64(&mut self, x: f64) {
        self.bytes.extend_from_slice(&x.to_le_bytes());
    }
    pub fn u64(&mut self, x: u64) {
        self.bytes.extend_from_slice(&x.to_le_bytes());
    }
    pub fn i32(&mut self, x: i32) {
        self.bytes.extend_from_slice(&x.to_le_bytes());
    }
    pub fn bool(&mut self, x: bool) {
        self.bytes.push(x as u8);
    }
    pub fn bytes(&mut self, b: &[u8]) {
        self.u64(b.len() as u64);
        self.bytes.extend_from_slice(b);
    }
    /// A slice of f64, length-prefixed.
    pub fn f64s(&mut self, xs: impl ExactSizeIterator<Item = f64>) {
        self.u64(xs.len() as u64);
        for x in xs {
            self.f64(x);
        }
    }
}

/// Reader matching [`StateWriter`]; truncated or malformed input is an error, not a panic.
#[derive(Debug)]
pub struct StateReader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> StateReader<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, pos: 0 }
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8], ModelError> {
        if self.bytes.len() - self.pos < n {
            return Err(ModelError::new(format!(
                "serialized FMU state truncated: need {n} bytes at offset {}, have {}",
                self.pos,
                self.bytes.len() - self.pos
            )));
        }
        let s = &self.bytes[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }
    pub fn f64(&mut self) -> Result<f64, ModelError> {
        Ok(f64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    pub fn u64(&mut self) -> Result<u64, ModelError> {
        Ok(u64::from_le_bytes(self.take(8)?.try_into().unwrap()))
    }
    pub fn i32(&mut self) -> Result<i32, ModelError> {
        Ok(i32::from_le_bytes(self.take(4)?.try_into().unwrap()))
    }
    pub fn bool(&mut self) -> Result<bool, ModelError> {
        match self.take(1)?[0] {
            0 => Ok(false),
            1 => Ok(true),
            b => Err(ModelError::new(format!(
                "serialized FMU state: bad boolean byte {b}"
            ))),
        }
    }
    pub fn bytes(&mut self) -> Result<&'a [u8], ModelError> {
        let n = self.len_prefix(1)?;
        self.take(n)
    }
    /// Length prefix, checked against what remains (each element at least `elem` bytes).
    pub fn len_prefix(&mut self, elem: usize) -> Result<usize, ModelError> {
        let n = self.u64()? as usize;
        if n.saturating_mul(elem) > self.bytes.len() - self.pos {
            return Err(ModelError::new(format!(
                "serialized FMU state: length {n} at offset {} exceeds the data",
                self.pos - 8
            )));
        }
        Ok(n)
    }
    /// Read a length-prefixed f64 sequence into `out` (cleared first).
    pub fn f64s_into(&mut self, out: &mut Vec<f64>) -> Result<(), ModelError> {
        let n = self.len_prefix(8)?;
        out.clear();
        for _ in 0..n {
            out.push(self.f64()?);
        }
        Ok(())
    }
    pub fn is_at_end(&self) -> bool {
        self.pos == self.bytes.len()
    }
}

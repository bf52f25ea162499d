//! Serialized FMU states: what a model saves of itself ([`ModelState`], or nothing for a
//! [`Stateless`] one) and the little-endian writer and reader it uses (the runtime writes
//! its own fields and the variables with the same pair).

use crate::error::ModelError;

/// The dynamic state of a model in a serialized FMU state (fmi2SerializeFMUstate): what
/// [`crate::Model::initialize`] does not rebuild from the parameters and resources. A model
/// keeps all of it in one struct declared with [`states!`](crate::states!), which writes
/// and reads every field in declaration order: saving and loading are generated from the
/// one declaration and cannot disagree. Every model implements it, or is [`Stateless`].
#[diagnostic::on_unimplemented(
    message = "the model `{Self}` neither declares its dynamic state nor is `Stateless`",
    note = "declare the state with `fmu_export::states!` (`pub struct S for {Self}.field {{ ... }}`) and write `impl fmu_export::ModelState for {Self} {{}}` for a model with dynamic state, or `impl fmu_export::Stateless for {Self} {{}}` for a model without"
)]
pub trait ModelState: HoldsState {
    /// After a state was read into a model initialised with the same parameters and
    /// resources: refuse one that does not fit them (a buffer of another length).
    fn state_loaded(&mut self) -> Result<(), ModelError> {
        Ok(())
    }

    /// Append the dynamic state (not the variables, not resources) to `w`.
    fn save_state(&self, w: &mut StateWriter) {
        self.state().save(w);
    }

    /// Read back what [`ModelState::save_state`] wrote.
    fn load_state(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError> {
        self.state_mut().load(r)?;
        self.state_loaded()
    }
}

/// Where a model keeps its dynamic state: the struct [`states!`](crate::states!) declares
/// and the model's field holding it (`pub struct S for Model.field`, or `for Model` when the
/// model is its own state); written by that macro, or nothing for a [`Stateless`] model.
pub trait HoldsState {
    /// The struct holding the dynamic state.
    type State: Stored;

    fn state(&self) -> &Self::State;
    fn state_mut(&mut self) -> &mut Self::State;
}

/// A model without dynamic state (its outputs follow from parameters and inputs):
/// `impl Stateless for MyModel {}` gives it the [`ModelState`] that saves nothing.
pub trait Stateless {}

impl<M: Stateless> HoldsState for M {
    type State = [f64; 0];

    fn state(&self) -> &[f64; 0] {
        &[]
    }

    fn state_mut(&mut self) -> &mut [f64; 0] {
        &mut []
    }
}

impl<M: Stateless> ModelState for M {}

/// A value in a serialized state: how it is written and read back.
pub trait Stored {
    fn save(&self, w: &mut StateWriter);
    fn load(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError>;
}

/// The numbers stored as they are, by the writer's and reader's method of their name.
macro_rules! stored_as_is {
    ($($t:ident),*) => {$(
        impl Stored for $t {
            fn save(&self, w: &mut StateWriter) {
                w.$t(*self);
            }
            fn load(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError> {
                *self = r.$t()?;
                Ok(())
            }
        }
    )*};
}

stored_as_is!(f64, i32, u64);

/// An index (a cursor, a ring buffer's head) as a u64; one that does not fit is an error.
impl Stored for usize {
    fn save(&self, w: &mut StateWriter) {
        w.u64(*self as u64);
    }
    fn load(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError> {
        let x = r.u64()?;
        *self = usize::try_from(x)
            .map_err(|_| ModelError::new(format!("serialized FMU state: index {x} too large")))?;
        Ok(())
    }
}

impl Stored for bool {
    fn save(&self, w: &mut StateWriter) {
        w.bool(*self);
    }
    fn load(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError> {
        *self = r.bool()?;
        Ok(())
    }
}

/// A fixed-size array: its elements, length-prefixed (a state of another model's shape is
/// refused rather than misread).
impl<T: Stored, const N: usize> Stored for [T; N] {
    fn save(&self, w: &mut StateWriter) {
        w.u64(N as u64);
        for x in self {
            x.save(w);
        }
    }
    fn load(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError> {
        let n = r.len_prefix(1)?;
        if n != N {
            return Err(ModelError::new(format!(
                "serialized FMU state: an array of {n} values where the model has {N}"
            )));
        }
        for x in self.iter_mut() {
            x.load(r)?;
        }
        Ok(())
    }
}

/// A buffer whose length the parameters decide: length-prefixed, read into the buffer the
/// initialised model has ([`ModelState::state_loaded`] checks the length).
impl Stored for Vec<f64> {
    fn save(&self, w: &mut StateWriter) {
        w.f64s(self.iter().copied());
    }
    fn load(&mut self, r: &mut StateReader<'_>) -> Result<(), ModelError> {
        r.f64s_into(self)
    }
}

/// Declare a model's dynamic state once: the struct, and its [`Stored`] implementation that
/// writes and reads every field in declaration order; with `for Model.field` (or `for
/// Model`, a model that is its own state) also where the model holds it ([`HoldsState`]).
///
/// ```
/// fmu_export::states! {
///     /// The integrator of a PI controller.
///     #[derive(Clone, Copy, Debug, Default, PartialEq)]
///     pub struct PiState {
///         /// ∫e dt [m].
///         error_integral: f64,
///         saturated: bool,
///     }
/// }
/// use fmu_export::state::{Stored, StateReader, StateWriter};
/// let mut w = StateWriter::default();
/// PiState { error_integral: 1.5, saturated: true }.save(&mut w);
/// let mut back = PiState::default();
/// back.load(&mut StateReader::new(&w.bytes)).unwrap();
/// assert_eq!(back, PiState { error_integral: 1.5, saturated: true });
/// ```
#[macro_export]
macro_rules! states {
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident for $model:ident $(. $held:ident)? {
            $(
                $(#[$fmeta:meta])*
                $field:ident : $ty:ty
            ),* $(,)?
        }
    ) => {
        $crate::states! {
            $(#[$meta])*
            $vis struct $name {
                $( $(#[$fmeta])* $field: $ty, )*
            }
        }

        impl $crate::state::HoldsState for $model {
            type State = $name;

            #[inline]
            fn state(&self) -> &$name {
                &(*self) $(.$held)?
            }

            #[inline]
            fn state_mut(&mut self) -> &mut $name {
                &mut (*self) $(.$held)?
            }
        }
    };
    (
        $(#[$meta:meta])*
        $vis:vis struct $name:ident {
            $(
                $(#[$fmeta:meta])*
                $field:ident : $ty:ty
            ),* $(,)?
        }
    ) => {
        $(#[$meta])*
        $vis struct $name {
            $( $(#[$fmeta])* pub $field: $ty, )*
        }

        impl $crate::state::Stored for $name {
            fn save(&self, w: &mut $crate::state::StateWriter) {
                $( $crate::state::Stored::save(&self.$field, w); )*
            }
            fn load(
                &mut self,
                r: &mut $crate::state::StateReader<'_>,
            ) -> ::core::result::Result<(), $crate::ModelError> {
                $( $crate::state::Stored::load(&mut self.$field, r)?; )*
                Ok(())
            }
        }
    };
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

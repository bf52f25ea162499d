//! What an `fmi2Status` means to the caller: one mapping for every backend; and a refused
//! call of either version as one structured value ([`FmiFunction`], [`CallStatus`]), as
//! FMPy's one choke point raises it (the function and its status).

use crate::fmi2::fmi2Status;
use crate::functions::Function;
use std::borrow::Cow;
use std::fmt;

/// An FMI function that was called: FMI 2.0's from its table, FMI 3.0's by its name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum FmiFunction {
    Fmi2(Function),
    /// `fmi3DoStep`, ... (owned when it came back from a worker process).
    Fmi3(Cow<'static, str>),
}

impl FmiFunction {
    /// The C symbol's name.
    pub fn name(&self) -> &str {
        match self {
            FmiFunction::Fmi2(f) => f.name(),
            FmiFunction::Fmi3(name) => name,
        }
    }

    /// The FMI 2.0 function, if it is one.
    pub fn fmi2(&self) -> Option<Function> {
        match self {
            FmiFunction::Fmi2(f) => Some(*f),
            FmiFunction::Fmi3(_) => None,
        }
    }
}

impl fmt::Display for FmiFunction {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// What a call returned, in its version's numbering (FMI 3.0 has no Pending): `fmi2Error`,
/// `fmi3Discard`, ...
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CallStatus {
    Fmi2(fmi2Status),
    Fmi3(i32),
}

impl CallStatus {
    /// The status's number (OK 0, Warning 1, Discard 2, Error 3, Fatal 4 in both versions).
    pub const fn code(self) -> i32 {
        match self {
            CallStatus::Fmi2(s) => s.0,
            CallStatus::Fmi3(code) => code,
        }
    }

    /// Discard: the FMU declined the call (a step it could not take), without an error.
    pub const fn is_discard(self) -> bool {
        self.code() == fmi2Status::DISCARD.0
    }
}

impl fmt::Display for CallStatus {
    /// The standard's name; a value outside the enumeration shows its number.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            CallStatus::Fmi2(s) => s.fmt(f),
            CallStatus::Fmi3(code) => match code {
                0 => f.write_str("fmi3OK"),
                1 => f.write_str("fmi3Warning"),
                2 => f.write_str("fmi3Discard"),
                3 => f.write_str("fmi3Error"),
                4 => f.write_str("fmi3Fatal"),
                other => write!(f, "an unknown fmi3Status ({other})"),
            },
        }
    }
}

impl fmi2Status {
    /// OK and Warning let the caller go on; every other status stops it.
    #[inline]
    pub const fn is_ok(self) -> bool {
        self.0 == fmi2Status::OK.0 || self.0 == fmi2Status::WARNING.0
    }

    /// `Ok(())` for OK and Warning, the status otherwise.
    #[inline]
    pub const fn ok(self) -> Result<(), fmi2Status> {
        if self.is_ok() {
            Ok(())
        } else {
            Err(self)
        }
    }
}

impl fmt::Display for fmi2Status {
    /// The standard's name; a value outside the enumeration shows its number.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            0..=5 => f.write_str(self.name()),
            other => write!(f, "an unknown fmi2Status ({other})"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_ok_and_warning_pass_and_unknown_values_show_their_number() {
        assert!(fmi2Status::OK.is_ok() && fmi2Status::WARNING.is_ok());
        for s in [
            fmi2Status::DISCARD,
            fmi2Status::ERROR,
            fmi2Status::FATAL,
            fmi2Status::PENDING,
        ] {
            assert_eq!(s.ok(), Err(s));
        }
        assert_eq!(fmi2Status(17).to_string(), "an unknown fmi2Status (17)");
        assert_eq!(fmi2Status::DISCARD.to_string(), "fmi2Discard");
    }
}

//! What an `fmi2Status` means to the caller: one mapping for every backend.

use crate::fmi2::fmi2Status;
use std::fmt;

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

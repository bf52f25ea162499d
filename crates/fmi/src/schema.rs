//! The FMI 2.0 schema's enumerations as typed values, shared by the export framework (which
//! writes them into `modelDescription.xml`) and the importer (which reads them back).

use std::fmt;

/// An attribute value that is not one of the schema's names.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnknownName {
    pub attribute: &'static str,
    pub value: String,
    pub expected: &'static [&'static str],
}

impl std::error::Error for UnknownName {}

impl fmt::Display for UnknownName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}=\"{}\" is not one of {}",
            self.attribute,
            self.value,
            self.expected.join(", ")
        )
    }
}

macro_rules! schema_enum {
    (
        $(#[$doc:meta])*
        $name:ident, $attr:literal { $($variant:ident = $xml:literal),* $(,)? }
    ) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum $name {
            $($variant),*
        }

        impl $name {
            /// Every value, in the schema's order.
            pub const ALL: &'static [$name] = &[$($name::$variant),*];
            const NAMES: &'static [&'static str] = &[$($xml),*];

            /// The name used in `modelDescription.xml`.
            pub const fn xml_name(self) -> &'static str {
                match self {
                    $($name::$variant => $xml),*
                }
            }

            /// Read the attribute's value.
            pub fn parse(text: &str) -> Result<$name, UnknownName> {
                match text {
                    $($xml => Ok($name::$variant),)*
                    other => Err(UnknownName {
                        attribute: $attr,
                        value: other.to_string(),
                        expected: Self::NAMES,
                    }),
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(self.xml_name())
            }
        }
    };
}

schema_enum! {
    /// `causality` of a ScalarVariable.
    Causality, "causality" {
        Parameter = "parameter",
        CalculatedParameter = "calculatedParameter",
        Input = "input",
        Output = "output",
        Local = "local",
        Independent = "independent",
    }
}

schema_enum! {
    /// `variability` of a ScalarVariable.
    Variability, "variability" {
        Constant = "constant",
        Fixed = "fixed",
        Tunable = "tunable",
        Discrete = "discrete",
        Continuous = "continuous",
    }
}

schema_enum! {
    /// `initial` of a ScalarVariable.
    Initial, "initial" {
        Exact = "exact",
        Approx = "approx",
        Calculated = "calculated",
    }
}

schema_enum! {
    /// The type element of a ScalarVariable.
    ScalarType, "type" {
        Real = "Real",
        Integer = "Integer",
        Boolean = "Boolean",
        String = "String",
        Enumeration = "Enumeration",
    }
}

impl Causality {
    /// The standard's default when the attribute is absent.
    pub const DEFAULT: Causality = Causality::Local;
}

impl Variability {
    /// The standard's default when the attribute is absent.
    pub const DEFAULT: Variability = Variability::Continuous;
}

impl ScalarType {
    /// Same as [`ScalarType::xml_name`] (the name messages use).
    pub const fn name(self) -> &'static str {
        self.xml_name()
    }

    /// Values travel as numbers (Real, Integer, Boolean as 0/1, Enumeration).
    pub const fn is_numeric(self) -> bool {
        !matches!(self, ScalarType::String)
    }

    /// The space its value references are counted in. FMI 2.0 (section 2.2.7,
    /// `valueReference`): a value reference "is unique for a particular base data type
    /// (Real, Integer/Enumeration, Boolean, String)"; variables of two base types on one
    /// value reference are two variables, and an Enumeration shares the Integers' space.
    pub const fn value_space(self) -> ScalarType {
        match self {
            ScalarType::Enumeration => ScalarType::Integer,
            t => t,
        }
    }
}

/// Shortest decimal text that parses back to the same f64 (Rust's `Debug` is round-trip
/// exact); integral values keep a trailing ".0" out for readability.
pub fn format_real(x: f64) -> String {
    let s = format!("{x:?}");
    s.strip_suffix(".0").map(str::to_string).unwrap_or(s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_unknown_names_say_what_is_allowed() {
        for c in Causality::ALL {
            assert_eq!(Causality::parse(c.xml_name()), Ok(*c));
        }
        for v in Variability::ALL {
            assert_eq!(Variability::parse(v.xml_name()), Ok(*v));
        }
        for i in Initial::ALL {
            assert_eq!(Initial::parse(i.xml_name()), Ok(*i));
        }
        for t in ScalarType::ALL {
            assert_eq!(ScalarType::parse(t.xml_name()), Ok(*t));
        }
        let e = Causality::parse("inptu").unwrap_err().to_string();
        assert_eq!(
            e,
            "causality=\"inptu\" is not one of parameter, calculatedParameter, input, output, local, independent"
        );
    }
}

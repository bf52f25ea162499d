//! The rules of a variable table, as `const fn`s: [`variables!`](crate::variables!) evaluates
//! them at compile time (a table that breaks one fails the build with a message naming the
//! variables), and [`validate_table`](crate::description::validate_table) applies the same
//! rules at run time to any [`VarTable`](crate::variables::VarTable).
//!
//! The rules: names and value references are unique; a unit is one of
//! [`crate::units::UNITS`]; every variable has a description; a String has no unit and no
//! range; only a Real is continuous; a start value lies within min/max; only an output
//! declares dependencies; `depends_on` names inputs, `init_depends_on` inputs or parameters.
//!
//! Each mistake fails the build; for example a `depends_on` naming a parameter:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         k: Real = 1.0 => parameter(1).unit("1").describe("Gain"),
//!         u: Real = 0.0 => input(2).unit("1").describe("Input"),
//!         y: Real = 0.0 => output(3).unit("1").depends_on(&[k]).describe("k·u"),
//!     }
//! }
//! ```
//!
//! fails with `evaluation panicked: variables!: 'y' depends on 'k', which is not an input
//! (depends_on names inputs)`. The others:
//!
//! Two variables with one value reference:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         u: Real = 0.0 => input(1).unit("1").describe("Input"),
//!         y: Real = 0.0 => output(1).unit("1").describe("Output"),
//!     }
//! }
//! ```
//!
//! `init_depends_on` naming an output (neither an input nor a parameter):
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         u: Real = 0.0 => input(1).unit("1").describe("Input"),
//!         y: Real = 0.0 => output(2).unit("1").describe("Output"),
//!         z: Real = 0.0 => output(3).unit("1").init_depends_on(&[y]).describe("Output"),
//!     }
//! }
//! ```
//!
//! Dependencies declared by a variable that is not an output:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         u: Real = 0.0 => input(1).unit("1").describe("Input"),
//!         x: Real = 0.0 => local(2).unit("1").depends_on(&[u]).describe("A local"),
//!     }
//! }
//! ```
//!
//! A start value outside min/max:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         k: Real = 5.0 => parameter(1).unit("1").range(0.0, 1.0).describe("Gain"),
//!     }
//! }
//! ```
//!
//! An unknown unit:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         k: Real = 1.0 => parameter(1).unit("furlong").describe("Gain"),
//!     }
//! }
//! ```
//!
//! A unit of the model's own under a name the shared table defines otherwise (`m/s` is not
//! a second per metre):
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! const SLOWNESS: UnitDef = UnitDef::named("m/s").s(1).m(-1);
//! fmu_export::variables! {
//!     pub struct Vars {
//!         k: Real = 1.0 => parameter(1).own_unit(&SLOWNESS).describe("Gain"),
//!     }
//! }
//! ```
//!
//! Two definitions of one unit name in one model:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! const PER_KM: UnitDef = UnitDef::named("1/km").m(-1).factor(0.001);
//! const PER_KM_TOO: UnitDef = UnitDef::named("1/km").m(-1);
//! fmu_export::variables! {
//!     pub struct Vars {
//!         a: Real = 1.0 => parameter(1).own_unit(&PER_KM).describe("A"),
//!         b: Real = 1.0 => parameter(2).own_unit(&PER_KM_TOO).describe("B"),
//!     }
//! }
//! ```
//!
//! No description:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         k: Real = 1.0 => parameter(1).unit("1"),
//!     }
//! }
//! ```
//!
//! A String with a unit:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         file: String = "" => parameter(1).unit("m").describe("A file"),
//!     }
//! }
//! ```
//!
//! A continuous Integer:
//!
//! ```compile_fail,E0080
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         n: Integer = 0 => input(1).describe("A count"),
//!     }
//! }
//! ```
//!
//! Two variables with one name are refused by Rust itself (a struct has one field per name):
//!
//! ```compile_fail
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         u: Real = 0.0 => input(1).unit("1").describe("Input"),
//!         u: Real = 0.0 => input(2).unit("1").describe("Input"),
//!     }
//! }
//! ```
//!
//! and a dependency on a name that is no variable is an unknown name:
//!
//! ```compile_fail,E0425
//! use fmu_export::variables::*;
//! fmu_export::variables! {
//!     pub struct Vars {
//!         u: Real = 0.0 => input(1).unit("1").describe("Input"),
//!         y: Real = 0.0 => output(2).unit("1").depends_on(&[v]).describe("Output"),
//!     }
//! }
//! ```

use crate::units::{str_eq, UnitDef, UNITS};
use crate::variables::{Causality, ScalarType, Value, VarInfo, Variability};
use std::fmt;

/// A mistake in a variable table: which rule, and the variables it concerns.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TableError {
    /// Two variables share a name.
    DuplicateName { name: &'static str },
    /// Two variables share a value reference.
    SharedValueReference {
        first: &'static str,
        second: &'static str,
        value_reference: u32,
    },
    /// A unit that is not in [`crate::units::UNITS`].
    UnknownUnit {
        name: &'static str,
        unit: &'static str,
    },
    /// A unit of the model's own ([`VarInfo::own_unit`]) that differs from the shared
    /// table's or from another variable's unit of the same name (`first`, the variable that
    /// names it first or, with the shared table, `first` = `name`).
    UnitRedefined {
        name: &'static str,
        first: &'static str,
        unit: &'static str,
    },
    /// A variable without description.
    NoDescription { name: &'static str },
    /// A String with a unit, a min or a max.
    StringWithUnitOrRange { name: &'static str },
    /// An Integer, Boolean or String declared continuous.
    ContinuousNonReal { name: &'static str },
    /// A start value below min or above max.
    StartOutsideRange { name: &'static str },
    /// A variable that is not an output declares dependencies.
    DependenciesOfNonOutput { name: &'static str },
    /// An Enumeration whose items are not 1, 2, … in order, whose start is none of them,
    /// or with a unit.
    BadEnumeration { name: &'static str },
    /// A `depends_on` entry that is not the value reference of an input (`dependency`: its
    /// name, `None` when no variable has it).
    DependsOnNonInput {
        name: &'static str,
        dependency: Option<&'static str>,
        value_reference: u32,
    },
    /// An `init_depends_on` entry that is neither an input nor a parameter.
    InitDependsOnNeitherInputNorParameter {
        name: &'static str,
        dependency: Option<&'static str>,
        value_reference: u32,
    },
}

/// A message built in const context (a fixed buffer: const code cannot allocate).
pub struct Message {
    buf: [u8; 320],
    len: usize,
}

impl Message {
    const fn new() -> Self {
        Message {
            buf: [0; 320],
            len: 0,
        }
    }

    /// Append `s` whole, or nothing when it does not fit (the text stays UTF-8).
    const fn push(mut self, s: &str) -> Self {
        let b = s.as_bytes();
        if self.len + b.len() > self.buf.len() {
            return self;
        }
        let mut i = 0;
        while i < b.len() {
            self.buf[self.len] = b[i];
            self.len += 1;
            i += 1;
        }
        self
    }

    const fn push_u32(mut self, x: u32) -> Self {
        let mut digits = [0u8; 10];
        let mut n = 0;
        let mut x = x;
        loop {
            digits[n] = b'0' + (x % 10) as u8;
            n += 1;
            x /= 10;
            if x == 0 {
                break;
            }
        }
        while n > 0 && self.len < self.buf.len() {
            n -= 1;
            self.buf[self.len] = digits[n];
            self.len += 1;
        }
        self
    }

    /// `'name'`.
    const fn quoted(self, name: &str) -> Self {
        self.push("'").push(name).push("'")
    }

    /// A variable's name in quotes, or its value reference when no variable has it.
    const fn push_dependency(self, dependency: Option<&str>, value_reference: u32) -> Self {
        match dependency {
            Some(d) => self.quoted(d),
            None => self.push("value reference ").push_u32(value_reference),
        }
    }

    pub const fn as_str(&self) -> &str {
        let (text, _) = self.buf.split_at(self.len);
        match std::str::from_utf8(text) {
            Ok(s) => s,
            Err(_) => "variables!: inconsistent variable table",
        }
    }
}

impl TableError {
    /// What is wrong, naming the variables (const: the build's panic message).
    pub const fn message(&self) -> Message {
        let m = Message::new();
        match *self {
            TableError::DuplicateName { name } => m.push("duplicate name '").push(name).push("'"),
            TableError::SharedValueReference {
                first,
                second,
                value_reference,
            } => m
                .quoted(first)
                .push(" and '")
                .push(second)
                .push("' share value reference ")
                .push_u32(value_reference),
            TableError::UnknownUnit { name, unit } => m
                .quoted(name)
                .push(": unknown unit '")
                .push(unit)
                .push("' (not in fmu_export::units::UNITS; declare a unit of the model's own with .own_unit)"),
            TableError::UnitRedefined { name, first, unit } => {
                let m = m.quoted(name).push(": its unit '").push(unit);
                if str_eq(name, first) {
                    m.push("' is defined otherwise in fmu_export::units::UNITS: give it a name of its own")
                } else {
                    m.push("' is defined otherwise for '")
                        .push(first)
                        .push("': one name, one definition")
                }
            }
            TableError::NoDescription { name } => {
                m.quoted(name).push(" has no description")
            }
            TableError::StringWithUnitOrRange { name } => m
                .quoted(name)
                .push(": a String has no unit and no range"),
            TableError::ContinuousNonReal { name } => m
                .quoted(name)
                .push(": only a Real can be continuous (FMI 2.0 §2.2.7); declare it discrete"),
            TableError::StartOutsideRange { name } => m
                .quoted(name)
                .push(": start value outside [min, max]"),
            TableError::DependenciesOfNonOutput { name } => m
                .quoted(name)
                .push(" declares dependencies but is not an output"),
            TableError::BadEnumeration { name } => m
                .quoted(name)
                .push(": an Enumeration has items valued 1, 2, … in order, a start that is one of them and no unit"),
            TableError::DependsOnNonInput {
                name,
                dependency,
                value_reference,
            } => m
                .quoted(name)
                .push(" depends on ")
                .push_dependency(dependency, value_reference)
                .push(", which is not an input (depends_on names inputs)"),
            TableError::InitDependsOnNeitherInputNorParameter {
                name,
                dependency,
                value_reference,
            } => m
                .quoted(name)
                .push(" depends in initialization mode on ")
                .push_dependency(dependency, value_reference)
                .push(", which is neither an input nor a parameter"),
        }
    }
}

impl fmt::Display for TableError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.message().as_str())
    }
}

/// The shared table's definition of `unit`.
const fn shared_unit(unit: &str) -> Option<&'static UnitDef> {
    let mut i = 0;
    while i < UNITS.len() {
        if str_eq(UNITS[i].name, unit) {
            return Some(&UNITS[i]);
        }
        i += 1;
    }
    None
}

/// The definition a variable's unit has: its own, else the shared table's.
const fn unit_of(v: &VarInfo) -> Option<&'static UnitDef> {
    match (v.unit_definition, v.unit) {
        (Some(own), _) => Some(own),
        (None, Some(unit)) => shared_unit(unit),
        (None, None) => None,
    }
}

/// Its unit is known: the shared table's, or its own that the shared table does not
/// define otherwise.
const fn check_unit(a: &VarInfo) -> Result<(), TableError> {
    let Some(unit) = a.unit else {
        return Ok(());
    };
    match (a.unit_definition, shared_unit(unit)) {
        (None, None) => Err(TableError::UnknownUnit { name: a.name, unit }),
        (Some(own), Some(shared)) if !own.same_as(shared) => Err(TableError::UnitRedefined {
            name: a.name,
            first: a.name,
            unit,
        }),
        _ => Ok(()),
    }
}

/// The unit `a` and `b` both name with different definitions, if any.
const fn conflicting_unit(a: &VarInfo, b: &VarInfo) -> Option<&'static str> {
    match (a.unit, b.unit, unit_of(a), unit_of(b)) {
        (Some(x), Some(y), Some(da), Some(db)) if str_eq(x, y) && !da.same_as(db) => Some(x),
        _ => None,
    }
}

/// The variable with value reference `vr`, if any.
const fn find(table: &[VarInfo], vr: u32) -> Option<&VarInfo> {
    let mut i = 0;
    while i < table.len() {
        if table[i].value_reference == vr {
            return Some(&table[i]);
        }
        i += 1;
    }
    None
}

/// The rules for the variable at `index`: against the later variables (names and value
/// references), then its own attributes, then its dependencies. The first broken rule.
pub const fn check_variable(table: &[VarInfo], index: usize) -> Result<(), TableError> {
    let a = &table[index];
    if let Err(e) = check_unique(table, index) {
        return Err(e);
    }
    if let Err(e) = check_attributes(a) {
        return Err(e);
    }
    if let Err(e) = check_enumeration(a) {
        return Err(e);
    }
    check_dependencies(table, a)
}

/// Its name and value reference against the later variables'.
const fn check_unique(table: &[VarInfo], index: usize) -> Result<(), TableError> {
    let a = &table[index];
    let mut j = index + 1;
    while j < table.len() {
        let b = &table[j];
        if str_eq(a.name, b.name) {
            return Err(TableError::DuplicateName { name: a.name });
        }
        if let Some(unit) = conflicting_unit(a, b) {
            return Err(TableError::UnitRedefined {
                name: b.name,
                first: a.name,
                unit,
            });
        }
        if a.value_reference == b.value_reference {
            return Err(TableError::SharedValueReference {
                first: a.name,
                second: b.name,
                value_reference: a.value_reference,
            });
        }
        j += 1;
    }
    Ok(())
}

/// Its own attributes: a known unit, a description, what its type allows, the start within
/// the range.
const fn check_attributes(a: &VarInfo) -> Result<(), TableError> {
    if let Err(e) = check_unit(a) {
        return Err(e);
    }
    if a.description.is_empty() {
        return Err(TableError::NoDescription { name: a.name });
    }
    let ty = a.var_type();
    if matches!(ty, ScalarType::String) && (a.unit.is_some() || a.min.is_some() || a.max.is_some())
    {
        return Err(TableError::StringWithUnitOrRange { name: a.name });
    }
    if !matches!(ty, ScalarType::Real) && matches!(a.variability, Variability::Continuous) {
        return Err(TableError::ContinuousNonReal { name: a.name });
    }
    if a.has_start() && !matches!(a.start, Value::Str(_)) {
        let x = a.start.as_f64();
        let below = match a.min {
            Some(m) => x < m,
            None => false,
        };
        let above = match a.max {
            Some(m) => x > m,
            None => false,
        };
        if below || above {
            return Err(TableError::StartOutsideRange { name: a.name });
        }
    }
    Ok(())
}

/// An Enumeration's items numbered from 1 and its start one of them.
const fn check_enumeration(a: &VarInfo) -> Result<(), TableError> {
    if let Some(t) = a.enumeration {
        let mut ok =
            !t.items.is_empty() && a.unit.is_none() && matches!(a.start, Value::Integer(_));
        let mut k = 0;
        while k < t.items.len() {
            ok = ok && t.items[k].value == k as i32 + 1;
            k += 1;
        }
        if let Value::Integer(i) = a.start {
            ok = ok && i >= 1 && i <= t.items.len() as i32;
        }
        if !ok {
            return Err(TableError::BadEnumeration { name: a.name });
        }
    }
    Ok(())
}

/// Dependencies only of outputs: on inputs, and at initialisation on inputs and parameters.
const fn check_dependencies(table: &[VarInfo], a: &VarInfo) -> Result<(), TableError> {
    let declares = !a.depends_on.is_empty() || !a.init_depends_on.is_empty();
    if declares && !matches!(a.causality, Causality::Output) {
        return Err(TableError::DependenciesOfNonOutput { name: a.name });
    }
    if let Some((value_reference, dependency)) = first_other(table, a.depends_on, false) {
        return Err(TableError::DependsOnNonInput {
            name: a.name,
            dependency,
            value_reference,
        });
    }
    if let Some((value_reference, dependency)) = first_other(table, a.init_depends_on, true) {
        return Err(TableError::InitDependsOnNeitherInputNorParameter {
            name: a.name,
            dependency,
            value_reference,
        });
    }
    Ok(())
}

/// The first of `vrs` that is not an input (nor a parameter, with `parameters`): its value
/// reference and the name of its variable (None: no variable has it).
const fn first_other(
    table: &[VarInfo],
    vrs: &[u32],
    parameters: bool,
) -> Option<(u32, Option<&'static str>)> {
    let mut k = 0;
    while k < vrs.len() {
        let vr = vrs[k];
        match find(table, vr) {
            Some(d) if matches!(d.causality, Causality::Input) => {}
            Some(d) if parameters && matches!(d.causality, Causality::Parameter) => {}
            Some(d) => return Some((vr, Some(d.name))),
            None => return Some((vr, None)),
        }
        k += 1;
    }
    None
}

/// The first broken rule of the table, if any.
pub const fn check_table(table: &[VarInfo]) -> Result<(), TableError> {
    let mut i = 0;
    while i < table.len() {
        if let Err(e) = check_variable(table, i) {
            return Err(e);
        }
        i += 1;
    }
    Ok(())
}

/// For `variables!`: panics (at compile time, in its `const _: () = ...;`) with the message
/// of the table's first broken rule.
#[doc(hidden)]
pub const fn assert_table(table: &[VarInfo]) {
    if let Err(e) = check_table(table) {
        let m = Message::new()
            .push("variables!: ")
            .push(e.message().as_str());
        panic!("{}", m.as_str());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::variables::{input, output, parameter, Value};

    const fn v(info: VarInfo, name: &'static str) -> VarInfo {
        info.named(name, Value::Real(0.0))
    }

    #[test]
    fn each_broken_rule_is_found_at_run_time_too_naming_the_variables() {
        let ok = [
            v(parameter(1).unit("1").describe("k"), "k"),
            v(input(2).unit("1").describe("u"), "u"),
            v(
                output(3)
                    .depends_on(&[2])
                    .init_depends_on(&[1])
                    .describe("y"),
                "y",
            ),
        ];
        assert_eq!(check_table(&ok), Ok(()));
        let cases: [(&[VarInfo], &str); 4] = [
            (
                &[
                    ok[0],
                    ok[1],
                    v(output(3).depends_on(&[1]).describe("y"), "y"),
                ],
                "'y' depends on 'k', which is not an input (depends_on names inputs)",
            ),
            (
                &[
                    ok[0],
                    ok[1],
                    v(output(3).depends_on(&[7]).describe("y"), "y"),
                ],
                "'y' depends on value reference 7, which is not an input (depends_on names inputs)",
            ),
            (
                &[ok[0], v(input(1).describe("u"), "u")],
                "'k' and 'u' share value reference 1",
            ),
            (
                &[v(parameter(1).range(1.0, 2.0).describe("k"), "k")],
                "'k': start value outside [min, max]",
            ),
        ];
        for (table, message) in cases {
            assert_eq!(check_table(table).unwrap_err().to_string(), message);
        }
    }

    const SLOWNESS: UnitDef = UnitDef::named("s/m").s(1).m(-1);

    #[test]
    fn a_unit_of_the_models_own_passes_where_the_shared_table_has_none() {
        let table = [v(parameter(1).own_unit(&SLOWNESS).describe("k"), "k")];
        assert_eq!(check_table(&table), Ok(()));
        // The same name alone is an unknown unit: the definition is what makes it known.
        let bare = [v(parameter(1).unit("s/m").describe("k"), "k")];
        assert!(matches!(
            check_table(&bare),
            Err(TableError::UnknownUnit {
                name: "k",
                unit: "s/m"
            })
        ));
        // Restating a shared unit exactly is allowed (the model may be explicit).
        const NEWTON: UnitDef = UnitDef::named("N").kg(1).m(1).s(-2);
        let restated = [
            v(parameter(1).own_unit(&NEWTON).describe("f"), "f"),
            v(parameter(2).unit("N").describe("g"), "g"),
        ];
        assert_eq!(check_table(&restated), Ok(()));
    }

    #[test]
    fn a_unit_of_the_models_own_may_not_redefine_a_name() {
        // A kilonewton called "N": against the shared table.
        const KILO: UnitDef = UnitDef::named("N").kg(1).m(1).s(-2).factor(1000.0);
        let shared = [v(parameter(1).own_unit(&KILO).describe("f"), "f")];
        let e = check_table(&shared).unwrap_err();
        assert!(matches!(
            e,
            TableError::UnitRedefined {
                name: "f",
                first: "f",
                unit: "N"
            }
        ));
        // Two of the model's own under one name.
        const FAST: UnitDef = UnitDef::named("s/m").s(1).m(-1).factor(0.001);
        let own = [
            v(parameter(1).own_unit(&SLOWNESS).describe("a"), "a"),
            v(parameter(2).own_unit(&FAST).describe("b"), "b"),
        ];
        assert!(matches!(
            check_table(&own),
            Err(TableError::UnitRedefined {
                name: "b",
                first: "a",
                unit: "s/m"
            })
        ));
        // The message says which variables and what to do.
        assert_eq!(
            check_table(&own).unwrap_err().to_string(),
            "'b': its unit 's/m' is defined otherwise for 'a': one name, one definition"
        );
    }

    #[test]
    fn the_description_declares_a_unit_of_the_models_own() {
        let table = [
            v(parameter(1).own_unit(&SLOWNESS).describe("k"), "k"),
            v(parameter(2).unit("N").describe("f"), "f"),
        ];
        let units = crate::description::unit_definitions(&table);
        assert_eq!(
            units,
            "    <Unit name=\"N\">\n      <BaseUnit kg=\"1\" m=\"1\" s=\"-2\"/>\n    </Unit>\n\
             \x20   <Unit name=\"s/m\">\n      <BaseUnit m=\"-1\" s=\"1\"/>\n    </Unit>\n"
        );
    }
}

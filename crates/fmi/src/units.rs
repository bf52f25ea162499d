//! Units known to the export framework, with their SI base-unit exponents (FMI 2.0
//! `unitDefinitions`). A model may only use units listed here, so that every FMU declares
//! each of its units completely and an importer can convert between compatible ones.

/// One `<Unit>`: value_in_SI = factor · value + offset.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UnitDef {
    pub name: &'static str,
    pub kg: i32,
    pub m: i32,
    pub s: i32,
    pub a: i32,
    pub k: i32,
    pub mol: i32,
    pub cd: i32,
    pub rad: i32,
    pub factor: f64,
    pub offset: f64,
}

const fn unit(name: &'static str, kg: i32, m: i32, s: i32, rad: i32, factor: f64) -> UnitDef {
    UnitDef {
        name,
        kg,
        m,
        s,
        a: 0,
        k: 0,
        mol: 0,
        cd: 0,
        rad,
        factor,
        offset: 0.0,
    }
}

/// The builder methods of [`UnitDef`], one a field: `name: type;` sets the field of that
/// name, `method => field: type;` names the method apart from the field.
macro_rules! setters {
    ($($(#[$doc:meta])* $method:ident $(=> $field:ident)?: $ty:ty;)*) => {
        $(
            $(#[$doc])*
            pub const fn $method(mut self, value: $ty) -> UnitDef {
                setters!(@set self, $method $(, $field)?) = value;
                self
            }
        )*
    };
    (@set $self:ident, $method:ident) => { $self.$method };
    (@set $self:ident, $method:ident, $field:ident) => { $self.$field };
}

impl UnitDef {
    /// A `<Unit>` before its `<BaseUnit>` is read: dimensionless, factor 1.
    pub const DIMENSIONLESS: UnitDef = unit("", 0, 0, 0, 0, 1.0);

    /// A unit of a model's own, built up from its base units: `s/m` is
    /// `UnitDef::named("s/m").s(1).m(-1)`. Dimensionless with factor 1 until told
    /// otherwise.
    pub const fn named(name: &'static str) -> UnitDef {
        UnitDef {
            name,
            ..UnitDef::DIMENSIONLESS
        }
    }
    setters! {
        /// The exponent of the kilogram.
        kg: i32;
        /// The exponent of the metre.
        m: i32;
        /// The exponent of the second.
        s: i32;
        /// The exponent of the ampere.
        ampere => a: i32;
        /// The exponent of the kelvin.
        kelvin => k: i32;
        /// The exponent of the mole.
        mol: i32;
        /// The exponent of the candela.
        cd: i32;
        /// The exponent of the radian.
        rad: i32;
        /// value_in_SI = factor · value + offset.
        factor: f64;
        /// value_in_SI = factor · value + offset.
        offset: f64;
    }

    /// The same unit: name, base-unit exponents, factor and offset (a `const fn`, for the
    /// export framework's compile-time check of a model's own units).
    pub const fn same_as(&self, other: &UnitDef) -> bool {
        str_eq(self.name, other.name)
            && self.kg == other.kg
            && self.m == other.m
            && self.s == other.s
            && self.a == other.a
            && self.k == other.k
            && self.mol == other.mol
            && self.cd == other.cd
            && self.rad == other.rad
            && self.factor == other.factor
            && self.offset == other.offset
    }
}

/// Every unit twinbench knows: the ones a model may declare, and a logger's.
pub const UNITS: &[UnitDef] = &[
    unit("1", 0, 0, 0, 0, 1.0),
    unit("%", 0, 0, 0, 0, 0.01),
    unit("s", 0, 0, 1, 0, 1.0),
    unit("Hz", 0, 0, -1, 0, 1.0),
    unit("m", 0, 1, 0, 0, 1.0),
    unit("1/m", 0, -1, 0, 0, 1.0),
    unit("m2", 0, 2, 0, 0, 1.0),
    unit("m/s", 0, 1, -1, 0, 1.0),
    unit("km/h", 0, 1, -1, 0, 1.0 / 3.6),
    unit("m/s2", 0, 1, -2, 0, 1.0),
    unit("kg", 1, 0, 0, 0, 1.0),
    unit("kg/m3", 1, -3, 0, 0, 1.0),
    unit("kg.m2", 1, 2, 0, 0, 1.0),
    unit("N", 1, 1, -2, 0, 1.0),
    unit("N/m", 1, 0, -2, 0, 1.0),
    unit("N.s/m", 1, 0, -1, 0, 1.0),
    unit("N.m", 1, 2, -2, 0, 1.0),
    unit("N.m/rad", 1, 2, -2, -1, 1.0),
    unit("N.m.s/rad", 1, 2, -1, -1, 1.0),
    unit("W", 1, 2, -3, 0, 1.0),
    unit("kW", 1, 2, -3, 0, 1000.0),
    unit("rad", 0, 0, 0, 1, 1.0),
    unit("rad/s", 0, 0, -1, 1, 1.0),
    unit("rpm", 0, 0, -1, 1, std::f64::consts::PI / 30.0),
    unit("rad/s2", 0, 0, -2, 1, 1.0),
    // Units data loggers write (measurements, not model variables).
    unit("g", 0, 1, -2, 0, 9.80665),
    unit("kN", 1, 1, -2, 0, 1000.0),
    unit("daN", 1, 1, -2, 0, 10.0),
    unit("lbf", 1, 1, -2, 0, 4.448_221_615_260_5),
    unit("mph", 0, 1, -1, 0, 0.447_04),
    unit("km", 0, 1, 0, 0, 1000.0),
    unit("mm", 0, 1, 0, 0, 0.001),
    unit("ms", 0, 0, 1, 0, 0.001),
    unit("min", 0, 0, 1, 0, 60.0),
    unit("h", 0, 0, 1, 0, 3600.0),
    unit("deg", 0, 0, 0, 1, std::f64::consts::PI / 180.0),
    unit("deg/s", 0, 0, -1, 1, std::f64::consts::PI / 180.0),
    unit("1/s", 0, 0, -1, 0, 1.0),
];

/// Two names equal, byte for byte (`==` on `str` is not a `const fn`: the export
/// framework's compile-time checks compare names with this).
pub const fn str_eq(a: &str, b: &str) -> bool {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    if a.len() != b.len() {
        return false;
    }
    let mut i = 0;
    while i < a.len() {
        if a[i] != b[i] {
            return false;
        }
        i += 1;
    }
    true
}

/// The definition of `name`, if known.
pub fn lookup(name: &str) -> Option<&'static UnitDef> {
    UNITS.iter().find(|u| u.name == name)
}

impl UnitDef {
    /// Same base-unit exponents: values convert by factor and offset.
    pub fn compatible(&self, other: &UnitDef) -> bool {
        (
            self.kg, self.m, self.s, self.a, self.k, self.mol, self.cd, self.rad,
        ) == (
            other.kg, other.m, other.s, other.a, other.k, other.mol, other.cd, other.rad,
        )
    }

    /// `<BaseUnit .../>` attributes, only the non-default ones (the standard's defaults are
    /// exponent 0, factor 1, offset 0).
    pub fn base_unit_attributes(&self) -> String {
        let mut out = String::new();
        for (key, exp) in [
            ("kg", self.kg),
            ("m", self.m),
            ("s", self.s),
            ("A", self.a),
            ("K", self.k),
            ("mol", self.mol),
            ("cd", self.cd),
            ("rad", self.rad),
        ] {
            if exp != 0 {
                out.push_str(&format!(" {key}=\"{exp}\""));
            }
        }
        if self.factor != 1.0 {
            out.push_str(&format!(
                " factor=\"{}\"",
                crate::schema::format_real(self.factor)
            ));
        }
        if self.offset != 0.0 {
            out.push_str(&format!(
                " offset=\"{}\"",
                crate::schema::format_real(self.offset)
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique() {
        for (i, a) in UNITS.iter().enumerate() {
            for b in &UNITS[i + 1..] {
                assert_ne!(a.name, b.name);
            }
        }
    }

    #[test]
    fn a_unit_built_from_its_base_units_equals_the_tables() {
        let n_m = UnitDef::named("N.m").kg(1).m(2).s(-2);
        assert!(n_m.same_as(lookup("N.m").unwrap()));
        assert!(!n_m.factor(1000.0).same_as(lookup("N.m").unwrap()));
        let rpm = UnitDef::named("rpm")
            .s(-1)
            .rad(1)
            .factor(std::f64::consts::PI / 30.0);
        assert!(rpm.same_as(lookup("rpm").unwrap()));
        assert!(!UnitDef::named("s/m")
            .s(1)
            .m(-1)
            .same_as(lookup("m/s").unwrap()));
    }

    #[test]
    fn rpm_converts_to_rad_per_s() {
        let rpm = lookup("rpm").unwrap();
        assert!(rpm.compatible(lookup("rad/s").unwrap()));
        assert!((rpm.factor * 60.0 - 2.0 * std::f64::consts::PI).abs() < 1e-12);
        assert!(!rpm.compatible(lookup("m/s").unwrap()));
    }
}

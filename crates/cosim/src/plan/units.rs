//! Unit conversion across a connection, from the units both FMUs declare.

use super::problems::ConversionError;
use tb_fmi::units::UnitDef;
use tb_fmi::ModelDescription;

/// `to = scale·from + offset`, and what a reader of the run's log should know about it.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Conversion {
    pub scale: f64,
    pub offset: f64,
    pub note: Option<String>,
}

impl Conversion {
    const IDENTITY: Conversion = Conversion {
        scale: 1.0,
        offset: 0.0,
        note: None,
    };
}

/// A unit's definition: the FMU's own `<Unit>`, else twinbench's table.
pub(crate) fn definition(md: &ModelDescription, unit: &str) -> Option<UnitDef> {
    md.unit_def(unit)
        .copied()
        .or_else(|| tb_fmi::units::lookup(unit).copied())
}

/// The conversion between two declared units, or why there is none.
///
/// `rad` is dimensionless (SI): where one side declares a `rad` exponent and the other does
/// not, as many tools write `rpm` as `1/s` with a factor, the units still convert, with a
/// note giving the scale so that it can be checked.
pub(crate) fn unit_conversion(
    from: (&ModelDescription, Option<&str>),
    to: (&ModelDescription, Option<&str>),
) -> Result<Conversion, ConversionError> {
    let (Some(fu), Some(tu)) = (from.1, to.1) else {
        return Ok(Conversion::IDENTITY);
    };
    if fu == tu {
        return Ok(Conversion::IDENTITY);
    }
    let (Some(a), Some(b)) = (definition(from.0, fu), definition(to.0, tu)) else {
        return Err(ConversionError::NoDefinition {
            from: fu.into(),
            to: tu.into(),
        });
    };
    let without_rad = |u: &UnitDef| UnitDef { rad: 0, ..*u };
    let note = if a.compatible(&b) {
        None
    } else if without_rad(&a).compatible(&without_rad(&b)) {
        Some(format!(
            "units '{fu}' and '{tu}' differ only in their rad exponent ({} and {}): rad taken as \
             dimensionless (SI), 1 {fu} = {} {tu}",
            a.rad,
            b.rad,
            a.factor / b.factor
        ))
    } else {
        return Err(ConversionError::Incompatible {
            from: fu.into(),
            to: tu.into(),
        });
    };
    // SI = factor·value + offset on both sides.
    Ok(Conversion {
        scale: a.factor / b.factor,
        offset: (a.offset - b.offset) / b.factor,
        note,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use tb_fmi::units::lookup;

    fn md_with(name: &str, def: UnitDef) -> ModelDescription {
        ModelDescription {
            units: vec![(name.to_string(), def)],
            ..Default::default()
        }
    }

    #[test]
    fn rad_is_dimensionless_where_one_side_leaves_it_out() {
        // A tool's rpm: 1/s with factor 2π/60, no rad exponent.
        let rpm_1_per_s = UnitDef {
            rad: 0,
            ..*lookup("rpm").unwrap()
        };
        let theirs = md_with("rpm", rpm_1_per_s);
        let ours = ModelDescription::default();
        let c = unit_conversion((&ours, Some("rad/s")), (&theirs, Some("rpm"))).unwrap();
        assert!((c.scale - 30.0 / std::f64::consts::PI).abs() < 1e-12);
        assert_eq!(c.offset, 0.0);
        let note = c.note.unwrap();
        assert!(note.contains("rad taken as dimensionless"), "{note}");
        assert!(note.contains("1 rad/s = 9.549"), "{note}");
        // Compatible units need no note; other base units are still refused.
        let c = unit_conversion((&ours, Some("rad/s")), (&ours, Some("rpm"))).unwrap();
        assert!(c.note.is_none());
        let e = unit_conversion((&ours, Some("rad/s")), (&ours, Some("m/s"))).unwrap_err();
        assert!(matches!(e, ConversionError::Incompatible { .. }), "{e}");
        // rad alone against a plain number is dimensionless too.
        let c = unit_conversion((&ours, Some("deg")), (&ours, Some("1"))).unwrap();
        assert!((c.scale - std::f64::consts::PI / 180.0).abs() < 1e-15);
    }
}

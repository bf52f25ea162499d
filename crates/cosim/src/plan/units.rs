//! Unit conversion across a connection, from the units both FMUs declare.

use tb_fmi::ModelDescription;

/// `(scale, offset)` of `to = scale·from + offset`, or why the units do not convert.
pub(crate) fn unit_conversion(
    from: (&ModelDescription, Option<&str>),
    to: (&ModelDescription, Option<&str>),
) -> Result<(f64, f64), String> {
    let (Some(fu), Some(tu)) = (from.1, to.1) else {
        return Ok((1.0, 0.0));
    };
    if fu == tu {
        return Ok((1.0, 0.0));
    }
    let def = |md: &ModelDescription, u: &str| {
        md.unit_def(u)
            .copied()
            .or_else(|| tb_fmi::units::lookup(u).copied())
    };
    let (Some(a), Some(b)) = (def(from.0, fu), def(to.0, tu)) else {
        return Err(format!(
            "units '{fu}' and '{tu}' differ and at least one has no definition to convert by"
        ));
    };
    if !a.compatible(&b) {
        return Err(format!(
            "incompatible units '{fu}' and '{tu}' (different base units)"
        ));
    }
    // SI = factor·value + offset on both sides.
    Ok((a.factor / b.factor, (a.offset - b.offset) / b.factor))
}

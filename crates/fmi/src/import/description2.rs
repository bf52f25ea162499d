//! The FMI 2.0 reader of modelDescription.xml: the elements both versions share
//! (`reader.rs`), then the `<ScalarVariable>`s and the model structure, checked as FMI 2.0
//! asks (unique names and alias sets, causality with variability, model structure indices
//! in range).

use super::error::DescriptionError;
use super::model::{check_names_and_aliases, ModelDescription, ScalarVariable, Unknown};
use super::reader::{num, read, Attrs, Element, Shared, Version, Visit};
use crate::schema::{Causality, Initial, ScalarType, Variability};

fn unknown(m: &Attrs) -> Result<Unknown, DescriptionError> {
    let index = m
        .get("index")
        .and_then(|s| s.trim().parse().ok())
        .ok_or(DescriptionError::UnknownIndex)?;
    let dependencies = match m.get("dependencies") {
        None => None,
        Some(s) => Some(
            s.split_whitespace()
                .map(|d| {
                    d.parse().map_err(|_| DescriptionError::Dependency {
                        dependency: d.to_string(),
                    })
                })
                .collect::<Result<Vec<usize>, DescriptionError>>()?,
        ),
    };
    Ok(Unknown {
        index,
        dependencies,
    })
}

/// Parse an FMI 2.0 modelDescription.xml.
pub fn parse(xml: &str) -> Result<ModelDescription, DescriptionError> {
    read(xml, Reader2::finish)
}

/// The FMI 2.0 reader: the shared elements, then `<ScalarVariable>`s and the model
/// structure.
#[derive(Default)]
struct Reader2 {
    md: ModelDescription,
    shared: Shared,
    current: Option<ScalarVariable>,
}

impl Visit for Reader2 {
    const VERSION: Version = Version::V2;

    fn shared(&mut self) -> (&mut ModelDescription, &mut Shared) {
        (&mut self.md, &mut self.shared)
    }

    fn start(&mut self, _stack: &[String], e: Element) -> Result<(), DescriptionError> {
        match (e.parent, e.name) {
            ("ModelVariables", "ScalarVariable") => {
                let v = scalar_variable(e.attrs)?;
                if e.empty {
                    return Err(DescriptionError::NoTypeElement { variable: v.name });
                }
                self.current = Some(v);
            }
            ("ScalarVariable", t @ ("Real" | "Integer" | "Boolean" | "String" | "Enumeration")) => {
                if let Some(v) = self.current.as_mut() {
                    let ctx = format!("variable '{}'", v.name);
                    v.ty = ScalarType::parse(t).expect("matched above");
                    v.declared_type = e.attrs.get("declaredType").cloned();
                    v.unit = e.attrs.get("unit").cloned();
                    v.start = e.attrs.get("start").cloned();
                    v.min = num(e.attrs, "min", &ctx)?;
                    v.max = num(e.attrs, "max", &ctx)?;
                    v.nominal = num(e.attrs, "nominal", &ctx)?;
                }
            }
            ("Outputs", "Unknown") => self.md.outputs.push(unknown(e.attrs)?),
            ("Derivatives", "Unknown") => self.md.derivatives.push(unknown(e.attrs)?),
            ("InitialUnknowns", "Unknown") => self.md.initial_unknowns.push(unknown(e.attrs)?),
            _ => {}
        }
        Ok(())
    }

    fn end(&mut self, _stack: &[String], name: &str) {
        if name == "ScalarVariable" {
            self.md.variables.extend(self.current.take());
        }
    }
}

impl Reader2 {
    /// The description, checked: unique names, aliases as the standard allows them, model
    /// structure indices in range.
    fn finish(mut self) -> Result<ModelDescription, DescriptionError> {
        self.shared.finish(&mut self.md)?;
        let md = self.md;
        check_names_and_aliases(&md)?;
        for v in &md.variables {
            check_combination(v)?;
        }
        let n = md.variables.len();
        for u in md
            .outputs
            .iter()
            .chain(&md.derivatives)
            .chain(&md.initial_unknowns)
        {
            if u.index == 0 || u.index > n {
                return Err(DescriptionError::Index {
                    index: u.index,
                    count: n,
                });
            }
            if let Some(d) = u.dependencies.iter().flatten().find(|&&d| d == 0 || d > n) {
                return Err(DescriptionError::DependencyIndex {
                    dependency: *d,
                    index: u.index,
                    count: n,
                });
            }
        }
        Ok(md)
    }
}

/// A `<ScalarVariable>`'s own attributes (its type comes with its child element).
fn scalar_variable(m: &Attrs) -> Result<ScalarVariable, DescriptionError> {
    let vname = m
        .get("name")
        .cloned()
        .ok_or_else(|| DescriptionError::Unnamed {
            element: "ScalarVariable".into(),
        })?;
    let vr = m
        .get("valueReference")
        .and_then(|s| s.trim().parse().ok())
        .ok_or_else(|| DescriptionError::ValueReference {
            variable: vname.clone(),
        })?;
    let ctx = |source| DescriptionError::Schema {
        variable: vname.clone(),
        source,
    };
    let causality = match m.get("causality") {
        Some(c) => Causality::parse(c).map_err(ctx)?,
        None => Causality::DEFAULT,
    };
    let variability = match m.get("variability") {
        Some(v) => Variability::parse(v).map_err(ctx)?,
        None => Variability::DEFAULT,
    };
    let initial = match m.get("initial") {
        Some(i) => Some(Initial::parse(i).map_err(ctx)?),
        None => None,
    };
    Ok(ScalarVariable {
        name: vname,
        value_reference: vr,
        description: m.get("description").cloned().unwrap_or_default(),
        causality,
        variability,
        initial,
        ty: ScalarType::Real,
        declared_type: None,
        unit: None,
        start: None,
        min: None,
        max: None,
        nominal: None,
        fmi3: None,
    })
}

/// The combinations of causality and variability FMI 2.0 allows (section 2.2.7, the table
/// after the definition of `variability`): a parameter is fixed or tunable, an input or an
/// output is not (a `constant` output is), only a local or an output is constant, and the
/// independent variable is continuous. FMPy refuses the same combinations.
fn check_combination(v: &ScalarVariable) -> Result<(), DescriptionError> {
    use Causality as C;
    use Variability as V;
    let allowed = match v.variability {
        V::Constant => matches!(v.causality, C::Output | C::Local),
        V::Fixed | V::Tunable => {
            matches!(
                v.causality,
                C::Parameter | C::CalculatedParameter | C::Local
            )
        }
        V::Discrete => matches!(v.causality, C::Input | C::Output | C::Local),
        V::Continuous => matches!(
            v.causality,
            C::Input | C::Output | C::Local | C::Independent
        ),
    };
    if allowed {
        return Ok(());
    }
    Err(DescriptionError::Combination {
        variable: v.name.clone(),
        causality: v.causality,
        variability: v.variability,
        rule: match v.causality {
            C::Parameter | C::CalculatedParameter => "a parameter is fixed or tunable",
            C::Input => "an input is discrete or continuous",
            C::Output => "an output is constant, discrete or continuous",
            C::Independent => "the independent variable is continuous",
            C::Local => "",
        },
    })
}

//! The model description: what twinbench knows of an FMU (FMI 2.0 and 3.0 alike: the types
//! of [`super::model`]), and the front of the modelDescription.xml readers, which hands the
//! text to the reader of its version: FMI 2.0 [`super::description2`], FMI 3.0
//! [`super::description3`] (what both share: `reader.rs`). Tolerant as the standard
//! asks: unknown attributes and elements (vendor annotations, tool extensions) are ignored.

pub use super::model::{
    closest, edit_distance, CoSimulation, DefaultExperiment, Interface, ModelDescription,
    ModelExchange, NameIndex, ScalarVariable, Unknown, VarKey,
};
pub use crate::schema::{Causality, Initial, ScalarType, Variability};

/// Parse modelDescription.xml text (FMI 2.0, or 3.0 by its `fmiVersion`). Errors say what
/// is wrong; the caller adds the file.
pub fn parse(xml: &str) -> Result<ModelDescription, super::error::DescriptionError> {
    if super::reader::sniff_fmi_version(xml).is_some_and(|v| v.starts_with("3.")) {
        return super::description3::parse(xml);
    }
    super::description2::parse(xml)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::DescriptionError;

    const XML: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{g}" vendorTool:extra="x" xmlns:vendorTool="urn:v" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="m" canGetAndSetFMUstate="true" vendorFlag="7"><SourceFiles><File name="a.c"/></SourceFiles></CoSimulation>
  <UnitDefinitions><Unit name="rpm"><BaseUnit s="-1" rad="1" factor="0.10471975511965977"/></Unit><Unit name="1"/></UnitDefinitions>
  <TypeDefinitions><SimpleType name="Speed"><Real unit="rpm"/></SimpleType></TypeDefinitions>
  <VendorAnnotations><Tool name="t"><anything/></Tool></VendorAnnotations>
  <ModelVariables>
    <ScalarVariable name="n" valueReference="3" causality="output" myAttr="1">
      <Real declaredType="Speed" min="0" max="2e4"/>
      <Annotations><Tool name="x"/></Annotations>
    </ScalarVariable>
    <ScalarVariable name="p" valueReference="4" causality="parameter" variability="fixed"><Integer start="2"/></ScalarVariable>
  </ModelVariables>
  <ModelStructure><Outputs><Unknown index="1" dependencies=""/></Outputs><InitialUnknowns><Unknown index="1"/></InitialUnknowns></ModelStructure>
</fmiModelDescription>"#;

    #[test]
    fn display_units_are_units_of_their_own() {
        let xml = XML.replace(
            "<Unit name=\"1\"/>",
            "<Unit name=\"K\"><BaseUnit K=\"1\"/><DisplayUnit name=\"degC\" offset=\"-273.15\"/></Unit><Unit name=\"m\"><BaseUnit m=\"1\"/><DisplayUnit name=\"ft\" factor=\"3.280839895\"/></Unit>",
        );
        let md = parse(&xml).unwrap();
        let c = md.unit_def("degC").unwrap();
        // 20 degC = 293.15 K.
        assert!((c.factor * 20.0 + c.offset - 293.15).abs() < 1e-12);
        assert_eq!(c.k, 1);
        let ft = md.unit_def("ft").unwrap();
        assert!((ft.factor * 3.280839895 - 1.0).abs() < 1e-15);
        assert_eq!(ft.m, 1);
    }

    #[test]
    fn model_structure_gaps_name_what_the_standard_requires() {
        let md = parse(XML).unwrap();
        assert!(md.model_structure_gaps().is_empty());
        let none = XML.replace(
            "<InitialUnknowns><Unknown index=\"1\"/></InitialUnknowns>",
            "",
        );
        let gaps = parse(&none).unwrap().model_structure_gaps();
        assert_eq!(gaps.len(), 1, "{gaps:?}");
        assert!(gaps[0].contains("InitialUnknowns is missing") && gaps[0].contains(": n"));
        // An output declared exact needs no entry; it must still be an Output.
        let exact = none.replace(
            "causality=\"output\" myAttr",
            "causality=\"output\" initial=\"exact\" myAttr",
        );
        assert!(parse(&exact).unwrap().model_structure_gaps().is_empty());
        let no_outputs = exact.replace(
            "<Outputs><Unknown index=\"1\" dependencies=\"\"/></Outputs>",
            "",
        );
        let gaps = parse(&no_outputs).unwrap().model_structure_gaps();
        assert!(
            gaps.len() == 1 && gaps[0].contains("Outputs does not list 1 output(s): n"),
            "{gaps:?}"
        );
    }

    #[test]
    fn reads_tolerantly_and_keeps_units() {
        let md = parse(XML).unwrap();
        assert_eq!(md.fmi_version, "2.0");
        assert!(md.co_simulation.as_ref().unwrap().can_get_and_set_fmu_state);
        assert_eq!(md.variables.len(), 2);
        let n = md.variable("n").unwrap();
        assert_eq!(md.unit_of(n), Some("rpm"));
        assert_eq!(n.max, Some(2e4));
        let rpm = md.unit_def("rpm").unwrap();
        assert!((rpm.factor - std::f64::consts::PI / 30.0).abs() < 1e-15);
        assert_eq!((rpm.s, rpm.rad), (-1, 1));
        assert_eq!(md.variable("p").unwrap().ty, ScalarType::Integer);
        assert_eq!(md.outputs[0].dependencies, Some(vec![]));
        assert_eq!(md.initial_unknowns[0].dependencies, None);
    }

    #[test]
    fn bad_files_say_what_is_wrong() {
        assert!(matches!(
            parse("<foo/>").unwrap_err(),
            DescriptionError::Root { found } if found == "foo"
        ));
        let bad = XML.replace("valueReference=\"3\"", "valueReference=\"x\"");
        assert!(matches!(
            parse(&bad).unwrap_err(),
            DescriptionError::ValueReference { variable } if variable == "n"
        ));
        let bad = XML.replace("max=\"2e4\"", "max=\"lots\"");
        assert!(matches!(
            parse(&bad).unwrap_err(),
            DescriptionError::NotANumber { attribute, found, .. } if attribute == "max" && found == "lots"
        ));
        assert!(parse("<fmiModelDescription><broken").is_err());
        // M17: a count that is not one is refused, naming it (it was taken as 0).
        let bad = XML.replace(
            "numberOfEventIndicators=\"0\"",
            "numberOfEventIndicators=\"-5\"",
        );
        assert!(matches!(
            parse(&bad).unwrap_err(),
            DescriptionError::EventIndicators { found } if found == "-5"
        ));
    }

    #[test]
    fn a_truncated_description_is_refused_not_read_as_a_shorter_model() {
        // Cut after the first variable: without the check, a model of one variable.
        let cut = &XML[..XML.find("</ScalarVariable>").unwrap() + "</ScalarVariable>".len()];
        let e = parse(cut).unwrap_err();
        assert!(
            matches!(&e, DescriptionError::Truncated { open, .. } if open == "ModelVariables"),
            "{e}"
        );
        // FMI 3.0 alike.
        let v3 = r#"<fmiModelDescription fmiVersion="3.0" modelName="m" instantiationToken="t">
  <CoSimulation modelIdentifier="m"/>
  <ModelVariables>
    <Float64 name="x" valueReference="1" causality="output"/>"#;
        let e = parse(v3).unwrap_err();
        assert!(
            matches!(&e, DescriptionError::Truncated { open, depth: 2 } if open == "ModelVariables"),
            "{e}"
        );
        assert!(parse(&format!("{v3}</ModelVariables><ModelStructure><Output valueReference=\"1\"/></ModelStructure></fmiModelDescription>")).is_ok());
    }

    #[test]
    fn alias_sets_follow_the_standard() {
        let two = XML.replace("name=\"p\"", "name=\"n\"");
        assert!(matches!(
            parse(&two).unwrap_err(),
            DescriptionError::DuplicateName { name, first: 3, second: 4 } if name == "n"
        ));
        let with = |extra: &str| {
            XML.replace(
                "<ScalarVariable name=\"p\"",
                &format!("{extra}\n    <ScalarVariable name=\"p\""),
            )
        };
        // An input whose alias is an output, a parameter with a local alias (OpenModelica's
        // `_D_outputAlias_*`): one value under two names, allowed.
        let md = parse(&with(
            r#"<ScalarVariable name="u" valueReference="3" causality="input"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="_D_p" valueReference="4" causality="local" variability="fixed"><Integer/></ScalarVariable>"#,
        ))
        .unwrap();
        assert_eq!(md.variables.len(), 4);
        // A description `with` these variables that does not parse.
        let refused = |variables: &str| parse(&with(variables)).unwrap_err();
        // Two variables that can be set in one set: refused, naming both and the clause.
        let e = refused(
            r#"<ScalarVariable name="q" valueReference="4" causality="parameter" variability="fixed"><Integer start="2"/></ScalarVariable>"#,
        );
        assert!(
            matches!(
                &e,
                DescriptionError::AliasSet {
                    value_reference: 4,
                    ty: ScalarType::Integer,
                    more: false,
                    first,
                    first_causality: Causality::Parameter,
                    second,
                    second_causality: Causality::Parameter,
                } if first == "q" && second == "p"
            ),
            "{e}"
        );
        // An Enumeration is in the Integers' space: an alias of an Integer.
        let e = refused(
            r#"<ScalarVariable name="e" valueReference="4" causality="input"><Enumeration declaredType="E" start="2"/></ScalarVariable>"#,
        );
        assert!(
            matches!(
                &e,
                DescriptionError::AliasSet { first, first_causality: Causality::Input, second, .. }
                    if first == "e" && second == "p"
            ),
            "{e}"
        );
        // Start values that contradict each other: refused; the same value twice: one start.
        let e = refused(
            r#"<ScalarVariable name="p_copy" valueReference="4" causality="local" variability="fixed" initial="exact"><Integer start="3"/></ScalarVariable>"#,
        );
        assert!(
            matches!(
                &e,
                DescriptionError::AliasStarts { first, first_start, second, second_start, .. }
                    if first == "p_copy" && first_start == "3" && second == "p" && second_start == "2"
            ),
            "{e}"
        );
        assert!(parse(&with(
            r#"<ScalarVariable name="p_copy" valueReference="4" causality="local" variability="fixed" initial="exact"><Integer start="2"/></ScalarVariable>"#,
        ))
        .is_ok());
        // Another base type on the same value reference: another variable, however set.
        let md = parse(&with(
            r#"<ScalarVariable name="on" valueReference="4" causality="input"><Boolean start="true"/></ScalarVariable>
    <ScalarVariable name="k" valueReference="3" causality="input"><Integer start="7"/></ScalarVariable>"#,
        ))
        .unwrap();
        let key = |n: &str| md.variables.iter().find(|v| v.name == n).unwrap().key();
        assert_ne!(key("on"), key("p"));
        assert_ne!(key("k"), key("n"));
        assert_eq!(key("k"), (ScalarType::Integer, 3));
    }

    #[test]
    fn combinations_of_causality_and_variability_the_standard_forbids_are_refused() {
        // The description with one attribute text replaced, which does not parse.
        let refused = |from: &str, to: &str| parse(&XML.replace(from, to)).unwrap_err();
        let e = refused(
            "causality=\"parameter\" variability=\"fixed\"",
            "causality=\"parameter\" variability=\"constant\"",
        );
        assert!(
            matches!(
                &e,
                DescriptionError::Combination {
                    variable,
                    causality: Causality::Parameter,
                    variability: Variability::Constant,
                    rule: "a parameter is fixed or tunable",
                } if variable == "p"
            ),
            "{e}"
        );
        let e = refused(
            "causality=\"output\" myAttr",
            "causality=\"output\" variability=\"tunable\" myAttr",
        );
        assert!(
            matches!(
                &e,
                DescriptionError::Combination {
                    causality: Causality::Output,
                    variability: Variability::Tunable,
                    ..
                }
            ),
            "{e}"
        );
        assert!(parse(&XML.replace(
            "causality=\"output\" myAttr",
            "causality=\"output\" variability=\"constant\" myAttr"
        ))
        .is_ok());
    }

    #[test]
    fn suggests_close_names() {
        let md = parse(XML).unwrap();
        assert_eq!(md.closest_names("N", 1), vec!["n"]);
        assert_eq!(edit_distance("omega_rl", "omega_rr"), 1);
        assert_eq!(edit_distance("Fz_lr", "Fz_rl"), 1, "a swap is one edit");
        assert_eq!(edit_distance("", "abc"), 3);
        assert_eq!(edit_distance("abc", "ca"), 3);
    }
}

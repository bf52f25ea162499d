//! The GUID is derived from the variable table: stable, and changed by any interface change.

use fmu_export::description::{guid, render_model_description, validate_table};
use fmu_export::variables::*;
use fmu_export::{Context, Model, ModelError, ModelInfo, Stateless};

macro_rules! spring_model {
    ($model:ident, $vars:ident, $unit:literal, $max:expr) => {
        fmu_export::variables! {
            pub struct $vars {
                stiffness: Real = 1000.0 => parameter(1).unit($unit).range(1.0, $max).describe("Spring rate"),
                force: Real = 0.0 => output(2).unit("N").describe("Spring force"),
            }
        }
        #[derive(Clone)]
        struct $model;
        impl Model for $model {
            type Vars = $vars;
            const INFO: ModelInfo = ModelInfo::new("spring", "a spring", "1");
            fn initialize(_: &mut $vars, _: &Context) -> Result<Self, ModelError> {
                Ok($model)
            }
            fn do_step(&mut self, _: &mut $vars, _: f64, _: f64) -> Result<(), ModelError> {
                Ok(())
            }
            fn calculate_outputs(&mut self, _: &mut $vars) {}
        }
        impl Stateless for $model {}
    };
}

spring_model!(A, AVars, "N/m", 1e9);
spring_model!(B, BVars, "N/m", 1e9);
spring_model!(C, CVars, "N/m", 1e8);
spring_model!(D, DVars, "N.m/rad", 1e9);

#[test]
fn same_interface_same_guid_and_changes_change_it() {
    assert_eq!(guid::<A>(), guid::<A>());
    assert_eq!(
        guid::<A>(),
        guid::<B>(),
        "identical tables must give identical GUIDs"
    );
    assert_ne!(
        guid::<A>(),
        guid::<C>(),
        "a changed max must change the GUID"
    );
    assert_ne!(
        guid::<A>(),
        guid::<D>(),
        "a changed unit must change the GUID"
    );
    let g = guid::<A>();
    assert!(
        g.starts_with('{') && g.ends_with('}') && g.len() == 38,
        "{g}"
    );
}

#[test]
fn model_description_carries_the_table() {
    validate_table::<AVars>().unwrap();
    let tpl =
        "<x guid=\"{{guid}}\">\n{{unitDefinitions}}\n{{modelVariables}}\n{{modelStructure}}\n</x>";
    let xml = render_model_description::<A>(tpl, "test");
    tb_testkit::assert_contains(
        &xml,
        &[
            &guid::<A>(),
            "<Unit name=\"N/m\">\n      <BaseUnit kg=\"1\" s=\"-2\"/>",
            "name=\"stiffness\" valueReference=\"1\" description=\"Spring rate\" causality=\"parameter\" variability=\"fixed\"",
            "<Real unit=\"N/m\" min=\"1\" max=\"1000000000\" start=\"1000\"/>",
            "<Unknown index=\"2\" dependencies=\"\"/>",
        ],
    );
}

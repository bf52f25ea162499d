//! The model registry: every model twinbench ships, and the test FMUs of the suite. The one
//! list that `pack` (what to build and package), the native backend (which models are
//! linked) and the test suite read.
//!
//! A model is registered by one line in this crate's `Cargo.toml` (`crates/bench`), in
//! `[dependencies]`, the path of its crate (`gain = { path = "../../models/gain" }`):
//! `build.rs` takes every path dependency whose crate has an `fmu` feature, in that order,
//! builds its FMU library and writes the entries below (`$OUT_DIR/registry.rs`). The model type is the crate's name in
//! UpperCamelCase (`gain::Gain`) unless the crate's `[package.metadata.twinbench]` names it
//! (`model = "..."`); `test = true` there makes it a test FMU. A test checks that every
//! workspace crate with an `fmu` feature is registered.

use fmu_export::Model;
use tb_cosim::native::NativeModel;

const MODEL_DESCRIPTION_TEMPLATE: &str =
    include_str!("../../../fmu-templates/modelDescription.xml");
const DOCUMENTATION_TEMPLATE: &str =
    include_str!("../../../fmu-templates/documentation/index.html");

/// What the packer needs of one model crate.
#[derive(Clone, Copy)]
pub struct ModelSpec {
    /// Cargo package name (also the library's file stem).
    pub package: &'static str,
    /// A test FMU for the suite, written under `target/fmu/test/`.
    pub test_only: bool,
    pub info: fmu_export::ModelInfo,
    pub model_description: fn() -> String,
    /// The FMI 3.0 description from the same table (the library serves both).
    pub model_description3: fn() -> String,
    /// A fitted twin's descriptions ([`crate::export_twin`]), FMI 2.0 and 3.0.
    pub fitted_description: fn(&fmu_export::description::Fitting) -> String,
    pub fitted_description3: fn(&fmu_export::description::Fitting) -> String,
    pub documentation: fn() -> String,
    pub validate: fn() -> Result<(), fmu_export::description::InvalidTable>,
    pub guid: fn() -> String,
    /// The model's FMU library (`binaries/linux64/<identifier>.so`), built by the build script.
    pub library: &'static [u8],
}

impl ModelSpec {
    pub fn of<M: Model>(package: &'static str, test_only: bool, library: &'static [u8]) -> Self {
        ModelSpec {
            package,
            test_only,
            library,
            info: M::INFO,
            model_description: || {
                fmu_export::description::render_model_description::<M>(
                    MODEL_DESCRIPTION_TEMPLATE,
                    concat!("twinbench ", env!("CARGO_PKG_VERSION")),
                )
            },
            model_description3: || {
                fmu_export::description3::render_model_description3::<M>(concat!(
                    "twinbench ",
                    env!("CARGO_PKG_VERSION")
                ))
            },
            fitted_description: |f| {
                fmu_export::description::render_fitted_description::<M>(
                    MODEL_DESCRIPTION_TEMPLATE,
                    concat!("twinbench ", env!("CARGO_PKG_VERSION")),
                    f,
                )
            },
            fitted_description3: |f| {
                fmu_export::description3::render_fitted_description3::<M>(
                    concat!("twinbench ", env!("CARGO_PKG_VERSION")),
                    f,
                )
            },
            documentation: || {
                fmu_export::description::render_documentation::<M>(DOCUMENTATION_TEMPLATE)
            },
            validate: || fmu_export::description::validate_table::<M::Vars>(),
            guid: fmu_export::description::guid::<M>,
        }
    }
}

/// One registered model.
#[derive(Clone, Copy)]
pub struct RegisteredModel {
    /// What the packer needs (crate, model description, documentation, GUID).
    pub pack: ModelSpec,
    /// The model linked into twinbench, for `run --native`.
    pub native: NativeModel,
}

macro_rules! registry {
    ($($package:literal => $model:ty, $kind:ident;)*) => {
        /// Every registered model, in packing order.
        pub fn models() -> Vec<RegisteredModel> {
            vec![$(RegisteredModel {
                pack: ModelSpec::of::<$model>(
                    $package,
                    registry!(@test_only $kind),
                    include_bytes!(env!(concat!("TWINBENCH_LIB_", $package))),
                ),
                native: NativeModel::of::<$model>(),
            }),*]
        }
    };
    (@test_only shipped) => { false };
    (@test_only test) => { true };
}

// `registry! { "dyno" => dyno::Dyno, shipped; ... "faulty" => faulty::Faulty, test; }`
include!(concat!(env!("OUT_DIR"), "/registry.rs"));

/// The models `run --native` can call directly.
pub fn native_models() -> Vec<NativeModel> {
    models().into_iter().map(|m| m.native).collect()
}

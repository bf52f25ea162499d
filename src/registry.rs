//! The model registry: every model twinbench ships, and the test FMUs of the suite. The one
//! list that `pack` (what to build and package), the native backend (which models are
//! linked) and the test suite read.
//!
//! A model is registered by one line in the root `Cargo.toml`'s `[dependencies]`, the path
//! of its crate (`gain = { path = "models/gain" }`): `build.rs` takes every path dependency
//! whose crate has an `fmu` feature, in that order, builds its FMU library and writes the
//! entries below (`$OUT_DIR/registry.rs`). The model type is the crate's name in
//! UpperCamelCase (`gain::Gain`) unless the crate's `[package.metadata.twinbench]` names it
//! (`model = "..."`); `test = true` there makes it a test FMU. A test checks that every
//! workspace crate with an `fmu` feature is registered.

use crate::pack::ModelSpec;
use tb_cosim::native::NativeModel;

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

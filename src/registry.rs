//! The model registry: every model twinbench ships, and the test FMUs of the suite. The one
//! list that `pack` (what to build and package), the native backend (which models are
//! linked) and the test suite read. Each model is a crate under `models/`, which the
//! workspace includes by folder; a test checks that the folder and this list agree.

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

registry! {
    "dyno" => dyno::Dyno, shipped;
    "driver" => driver::Driver, shipped;
    "vehicle" => vehicle::Vehicle, shipped;
    "edu" => edu::Edu, shipped;
    // A test FMU (faults on purpose), packed under target/fmu/test/.
    "faulty" => faulty::Faulty, test;
}

/// The models `run --native` can call directly.
pub fn native_models() -> Vec<NativeModel> {
    models().into_iter().map(|m| m.native).collect()
}

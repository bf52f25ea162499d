//! A saved FMU state.

use crate::model::Model;

use super::slots::RunState;

/// A saved FMU state (fmi2GetFMUstate): the variables, the model and the run state.
#[derive(Clone)]
pub struct Snapshot<M: Model> {
    pub(super) vars: M::Vars,
    pub(super) model: Option<M>,
    pub(super) run: RunState,
}

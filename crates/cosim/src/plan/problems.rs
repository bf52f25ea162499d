//! What a connection's conversion and the stepping order can find wrong, before the plan
//! puts it in its context (the system file, the connection) as a [`crate::SystemError`].

/// Why a connection has no conversion.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum ConversionError {
    #[error("units '{from}' and '{to}' differ and at least one has no definition to convert by (give the connection a to_unit/from_unit or a scale)")]
    NoDefinition { from: String, to: String },
    #[error("incompatible units '{from}' and '{to}' (different base units); a connection table with a scale converts what the units cannot")]
    Incompatible { from: String, to: String },
    #[error("give either scale/offset or from_unit/to_unit, not both")]
    GainAndUnits,
    #[error("a scale, an offset or a unit applies to Real inputs only, this one is {ty}")]
    NotReal { ty: &'static str },
    /// `end`: `from_unit` or `to_unit`; `known`: the unit table's names.
    #[error(
        "{end} = '{unit}' is defined neither by the FMU nor in twinbench's unit table ({known})"
    )]
    UnknownUnit {
        end: &'static str,
        unit: String,
        known: String,
    },
    #[error("scale must be a finite non-zero number and offset a finite number, got scale = {scale}, offset = {offset}")]
    BadGain { scale: f64, offset: f64 },
}

/// Why the units cannot be stepped in an order.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum OrderError {
    /// `cycle`: the units and variables round the loop, `a -> b -> a`.
    #[error("direct feed-through cycle (an algebraic loop): {cycle}")]
    AlgebraicLoop { cycle: String },
    #[error("experiment.order: unknown instance '{name}'")]
    UnknownInstance { name: String },
    #[error("experiment.order: '{name}' appears twice")]
    Twice { name: String },
    #[error("experiment.order: '{name}' is missing")]
    Missing { name: String },
}

//! The refusals of a system the tests expect, each checked by its variant and the place it
//! names. The root package's integration tests use this file too (`tests/common/kinds.rs`).

use tb_cosim::plan::OrderError;
use tb_cosim::SystemError;

/// A system file or a plan refused, at the place its context ends with (a connection, a
/// parameter, the file).
pub fn invalid(e: &SystemError, context_end: &str) -> bool {
    matches!(e, SystemError::Invalid { context, .. } if context.ends_with(context_end))
}

/// A plan refused for an algebraic loop among its instances' direct feedthroughs.
pub fn algebraic_loop(e: &SystemError) -> bool {
    matches!(
        e,
        SystemError::Order {
            error: OrderError::AlgebraicLoop { .. },
            ..
        }
    )
}

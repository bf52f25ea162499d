//! What the intervals, the noise in time, the joint fit and the model check share: one
//! signal's residuals and sensitivities on the grid ([`Block`]).

/// One signal's residuals and sensitivity rows from grid point `start` on.
pub(crate) struct Block {
    pub start: usize,
    pub residual: Vec<f64>,
    /// ∂(simulated)/∂θ_i at each grid point, in the parameters' own units.
    pub rows: Vec<Vec<f64>>,
    pub weight: f64,
    /// The lap the block belongs to: the long-run covariance sums within a lap only.
    pub segment: usize,
    /// The factor w_s/σ_s² when the fit held it fixed ([`crate::fit`]: the sandwich must
    /// weigh the residuals as the objective did); `None`: w_s over the block's own mean
    /// squared residual.
    pub factor: Option<f64>,
}

//! What the unit tests of the fits share: the curve y = a·exp(−b·t) they fit, its
//! measurement with a given noise, and a pool of workers.

use crate::fit::Simulated;

/// A pool of `threads` workers to run the simulations on.
pub(crate) fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
}

/// The measured curve 2·exp(−0.7·t) with `noise` added, point by point.
pub(crate) fn measured_decay(t: &[f64], noise: &[f64]) -> Vec<f64> {
    t.iter()
        .zip(noise)
        .map(|(t, e)| 2.0 * (-0.7 * t).exp() + e)
        .collect()
}

/// The twin of the curve: x[0]·exp(−x[1]·t) at every `t`, as one series over all rows.
pub(crate) fn simulate_decay(t: &[f64], x: &[f64]) -> Simulated {
    Ok(vec![(
        0..t.len(),
        t.iter().map(|t| x[0] * (-x[1] * t).exp()).collect(),
    )])
}

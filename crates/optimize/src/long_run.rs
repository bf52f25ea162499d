//! The scores' long-run covariance, which the intervals, the model check and the
//! bootstrap share: a VAR(1) prewhitening ([`prewhiten`]), the Bartlett estimate of what it
//! leaves, and the Bartlett bandwidth from the data ([`bandwidth_of_one`]); the sandwich's
//! meat from them ([`scores_meat`]).

/// The Bartlett bandwidth in lags at which the scores' autocorrelation falls below 0.05:
/// wide, so that the kernel's downweighting of the correlation it does see costs little (its
/// bias is about the correlation length over the bandwidth); the fixed-b critical value
/// pays for the noisier estimate.
pub(crate) const LAGS: usize = 4;
/// The autocorrelation below which a lag of the scores no longer counts.
pub(crate) const CUT: f64 = 0.05;
/// The bandwidth at most this fraction of the grid.
pub(crate) const MAX_SHARE: usize = 4;
/// The shortest Bartlett bandwidth [grid points].
pub(crate) const MIN_BANDWIDTH: usize = 10;

/// The scores' long-run covariance ("meat") and the Bartlett bandwidth it used; a note
/// where the bandwidth was cut.
pub(crate) fn scores_meat(
    scores: &[Vec<Vec<f64>>],
    n: usize,
    p: usize,
    notes: &mut Vec<String>,
) -> (Vec<Vec<f64>>, usize) {
    // Andrews–Monahan: the scores whitened by a VAR(1) first, the Bartlett estimate of what
    // is left (a short bandwidth), recoloured.
    // Each lap whitened by a VAR(1) of its own (laps of different circuits and speeds
    // persist differently; pooled, a second lap could widen the interval), the Bartlett
    // estimate of what is left at the laps' common bandwidth, recoloured per lap and summed
    // (laps are independent).
    let per: Vec<Whitened> = scores
        .iter()
        .map(|seg| prewhiten(std::slice::from_ref(seg)))
        .collect();
    let whitened: Vec<Vec<Vec<f64>>> = per.iter().flat_map(|(_, w)| w.iter().cloned()).collect();
    let (bandwidth, capped) = bandwidth(&whitened, n);
    if capped {
        notes.push(format!(
            "the residuals stay correlated beyond {bandwidth} grid points (a quarter of the compared stretch): the long-run covariance is cut there, and the intervals may be narrower than the data warrant"
        ));
    }
    let mut meat = vec![vec![0.0; p]; p];
    for (recolour, w) in &per {
        for seg in w {
            let one = recoloured(recolour, &bartlett(seg, bandwidth, p));
            for i in 0..p {
                for j in 0..p {
                    meat[i][j] += one[i][j];
                }
            }
        }
    }
    (meat, bandwidth)
}

/// One lap's recolouring matrix (I − A)⁻¹ and its whitened scores.
type Whitened = (nalgebra::DMatrix<f64>, Vec<Vec<Vec<f64>>>);

/// The largest singular value the VAR(1) of the scores may have: nearer 1 the recolouring
/// (I − A)⁻¹ would amplify the error of A without bound (Andrews and Monahan cap it at 0.97
/// for series sampled once per correlation time; on a 1 m grid a residual that persists
/// for a second is 0.98 per point, so the cap sits higher).
const MAX_PERSISTENCE: f64 = 0.995;

/// The scores whitened by a VAR(1) fitted to them (pooled over the segments, least
/// squares, its largest singular value at most [`MAX_PERSISTENCE`]): (I − A)⁻¹ to
/// recolour with, and u_g = ψ_g − A·ψ_{g−1} from each segment's second point on.
///
/// Why: the residuals of a logged load persist for a second or more (tens of grid points);
/// the Bartlett estimate of such scores needs a bandwidth of hundreds of points, a quarter
/// of a lap, and is then so noisy that the standard error varied threefold between
/// replicates of one lap and the standardised errors spread 1.4–1.9 times what they
/// should. The VAR(1) takes up the persistence with p² numbers estimated from every
/// point; what it leaves needs a bandwidth of a few points.
pub(crate) fn prewhiten(scores: &[Vec<Vec<f64>>]) -> Whitened {
    use nalgebra::{DMatrix, DVector};
    let p = scores.iter().find_map(|s| s.first()).map_or(0, |x| x.len());
    let identity = DMatrix::<f64>::identity(p, p);
    let (mut s1, mut s0) = (DMatrix::<f64>::zeros(p, p), DMatrix::<f64>::zeros(p, p));
    for seg in scores {
        for g in 1..seg.len() {
            let (a, b) = (
                DVector::from_column_slice(&seg[g]),
                DVector::from_column_slice(&seg[g - 1]),
            );
            s1 += &a * b.transpose();
            s0 += &b * b.transpose();
        }
    }
    // Scaled to unit diagonal for the inverse (A itself does not depend on the scaling).
    let d = DVector::from_iterator(
        p,
        (0..p).map(|i| {
            let v = s0[(i, i)];
            if v > 0.0 && v.is_finite() {
                1.0 / v.sqrt()
            } else {
                0.0
            }
        }),
    );
    let scale = DMatrix::from_diagonal(&d);
    let s0_scaled = &scale * &s0 * &scale;
    let s0_inv = pinv(&s0_scaled);
    let mut a = &s1 * &scale * s0_inv * &scale;
    if !a.iter().all(|v| v.is_finite()) {
        return (identity, scores.to_vec());
    }
    let largest = a.singular_values().iter().cloned().fold(0.0f64, f64::max);
    if largest > MAX_PERSISTENCE {
        a *= MAX_PERSISTENCE / largest;
    }
    let Some(recolour) = (&identity - &a).try_inverse() else {
        return (identity, scores.to_vec());
    };
    let whitened = scores
        .iter()
        .map(|seg| {
            (1..seg.len())
                .map(|g| {
                    let prev = DVector::from_column_slice(&seg[g - 1]);
                    let u = DVector::from_column_slice(&seg[g]) - &a * prev;
                    u.iter().copied().collect()
                })
                .collect()
        })
        .collect();
    (recolour, whitened)
}

/// The Bartlett long-run covariance Σ_{|k|≤L} (1 − |k|/(L+1)) Σ_g x_g x_{g+k}ᵀ of one lap's
/// series of `p`-vectors.
fn bartlett(seg: &[Vec<f64>], bandwidth: usize, p: usize) -> Vec<Vec<f64>> {
    let mut meat = vec![vec![0.0; p]; p];
    let len = seg.len();
    for k in 0..=bandwidth.min(len.saturating_sub(1)) {
        let w = if k == 0 {
            1.0
        } else {
            1.0 - k as f64 / (bandwidth + 1) as f64
        };
        for g in 0..len - k {
            for i in 0..p {
                for j in 0..p {
                    let v = seg[g][i] * seg[g + k][j];
                    meat[i][j] += w * v;
                    if k > 0 {
                        meat[j][i] += w * v;
                    }
                }
            }
        }
    }
    meat
}

/// The Moore–Penrose inverse of a symmetric matrix (directions below 1e-10 of the largest
/// eigenvalue dropped).
pub(crate) fn pinv(a: &nalgebra::DMatrix<f64>) -> nalgebra::DMatrix<f64> {
    let e = a.clone().symmetric_eigen();
    let top = e.eigenvalues.iter().cloned().fold(0.0f64, f64::max);
    let n = a.nrows();
    let mut out = nalgebra::DMatrix::zeros(n, n);
    for (k, &l) in e.eigenvalues.iter().enumerate() {
        if top > 0.0 && l > 1e-10 * top {
            let v = e.eigenvectors.column(k);
            out += (1.0 / l) * v * v.transpose();
        }
    }
    out
}

/// R·M·Rᵀ.
fn recoloured(r: &nalgebra::DMatrix<f64>, m: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let p = m.len();
    let m = nalgebra::DMatrix::from_fn(p, p, |i, j| m[i][j]);
    let out = r * m * r.transpose();
    (0..p)
        .map(|i| (0..p).map(|j| out[(i, j)]).collect())
        .collect()
}

/// The Bartlett bandwidth: the widest of the parameters' own ([`bandwidth_of_one`] of each
/// parameter's scores, over the segments): a parameter whose scores stay correlated
/// longer than the others' sets it (a pooled autocorrelation let the parameter with the
/// largest scores decide, and c_lift_front's were under-covered). True when the cap cut it.
fn bandwidth(scores: &[Vec<Vec<f64>>], n: usize) -> (usize, bool) {
    let p = scores.iter().find_map(|s| s.first()).map_or(0, |x| x.len());
    let cap = (n / MAX_SHARE).max(MIN_BANDWIDTH);
    let widest = (0..p)
        .map(|i| {
            let one: Vec<Vec<f64>> = scores
                .iter()
                .map(|seg| seg.iter().map(|g| g[i]).collect())
                .collect();
            bandwidth_of_one(&one, n, LAGS, CUT, MIN_BANDWIDTH, MAX_SHARE)
        })
        .max()
        .unwrap_or(MIN_BANDWIDTH);
    let capped = widest >= cap
        && (0..p).any(|i| {
            let one: Vec<Vec<f64>> = scores
                .iter()
                .map(|seg| seg.iter().map(|g| g[i]).collect())
                .collect();
            autocorrelation(&one, cap / LAGS) >= CUT
        });
    (widest, capped)
}

/// The autocorrelation at lag `k` of a scalar series in segments (each summed within
/// itself).
fn autocorrelation(series: &[Vec<f64>], k: usize) -> f64 {
    let dot = |k: usize| -> f64 {
        series
            .iter()
            .map(|s| {
                (0..s.len().saturating_sub(k))
                    .map(|g| s[g] * s[g + k])
                    .sum::<f64>()
            })
            .sum()
    };
    let c0 = dot(0);
    if c0 <= 0.0 || c0.is_nan() {
        return 0.0;
    }
    dot(k) / c0
}

/// A scalar series' Bartlett bandwidth: `lags` × the first lag at which its autocorrelation
/// falls below `cut`, within [`min`, n/`share`] (`n` the shortest segment's length).
pub(crate) fn bandwidth_of_one(
    series: &[Vec<f64>],
    n: usize,
    lags: usize,
    cut: f64,
    min: usize,
    share: usize,
) -> usize {
    let cap = (n / share).max(min);
    let mut k = 1;
    while lags * k < cap && autocorrelation(series, k) >= cut {
        k += 1;
    }
    (lags * k).clamp(min, cap)
}

//! The interval with the model's share, its random effect: how much the parameters'
//! answer depends on the driving regime beyond the noise.
//!
//! Each regime's own answer is one Gauss–Newton step from the study's answer with the
//! rows of that regime only (every signal, every parameter free), its noise covariance the
//! sandwich of its own scores (VAR(1)-prewhitened Bartlett, as the scatter interval's);
//! the spread between regimes beyond that noise is DerSimonian and Laird's moment estimate
//! τ² of a random effect. Where the twin is the right model every regime wants the same
//! parameters and τ² is about zero; where the car is not the twin, braking, accelerating
//! and cornering each want other values of l, the lifts and the track widths (the twin
//! takes up what it does not have differently in each), and τ measures by how much the
//! parameters are then a matter of which part of the lap one asks.

use super::{block_factor, pinv, whitened_long_run, Kinematics, Laps};
use crate::block::Block;
use nalgebra::{DMatrix, DVector};

/// The driving regimes: the measured a_x in thirds (braking, lifting or coasting,
/// accelerating) by |a_y| in halves (straight, cornering) by v in halves (slow, fast: the
/// downforce, and a sprung car's ride height, go with v²).
const REGIMES: usize = 12;
/// A regime with fewer grid points than this is left out.
const MIN_REGIME: usize = 100;

/// Student's t two-sided 95 % quantile for `df` degrees of freedom (1–10; beyond, 10's).
pub(super) fn t975(df: usize) -> f64 {
    const T: [f64; 10] = [
        12.706, 4.303, 3.182, 2.776, 2.571, 2.447, 2.365, 2.306, 2.262, 2.228,
    ];
    T[df.clamp(1, 10) - 1]
}

/// One grid point of one signal with the car's state there.
struct Row {
    c: f64,
    j: DVector<f64>,
    e: f64,
    segment: usize,
    g: usize,
    ax: f64,
    ay: f64,
    v: f64,
}

/// Per parameter: τ (in range-scaled units) and its degrees of freedom (the regimes that
/// see the parameter, less one); `None` where fewer than two regimes see it.
pub(super) fn spread(
    blocks: &[Block],
    kinematics: &[Kinematics],
    p: usize,
    span: &[f64],
) -> Vec<Option<(f64, usize)>> {
    let Some(rows) = rows(blocks, kinematics, p, span) else {
        return vec![None; p];
    };
    let regime = classifier(&rows);
    let laps = Laps::of(rows.iter().map(|r| (r.segment, r.g)));
    // Each regime's step and its noise variance, per parameter.
    let mut answers: Vec<Vec<(f64, f64)>> = vec![Vec::new(); p];
    for reg in 0..REGIMES {
        let mine: Vec<&Row> = rows.iter().filter(|r| regime(r) == reg).collect();
        for (i, answer) in one_regime(&mine, &laps, p).into_iter().enumerate() {
            answers[i].extend(answer);
        }
    }
    answers.iter().map(|est| dersimonian_laird(est)).collect()
}

/// Every block's rows with the measured kinematics at their grid point; `None` where a lap
/// has no kinematics or a factor or residual is not finite.
fn rows(blocks: &[Block], kinematics: &[Kinematics], p: usize, span: &[f64]) -> Option<Vec<Row>> {
    let mut rows = Vec::new();
    for block in blocks {
        let c = block_factor(block);
        let kin = kinematics.get(block.segment)?;
        for (k, (row, &e)) in block.rows.iter().zip(&block.residual).enumerate() {
            let g = block.start + k;
            let Some(i) = g.checked_sub(kin.start).filter(|&i| i < kin.a_x.len()) else {
                continue;
            };
            rows.push(Row {
                c,
                j: DVector::from_iterator(p, row.iter().zip(span).map(|(j, s)| j * s)),
                e,
                segment: block.segment,
                g,
                ax: kin.a_x[i],
                ay: kin.a_y[i].abs(),
                v: kin.v[i],
            });
        }
    }
    (!rows.is_empty() && rows.iter().all(|r| r.c.is_finite() && r.e.is_finite())).then_some(rows)
}

/// The regime of a row, by the rows' own a_x thirds, |a_y| median and v median.
fn classifier(rows: &[Row]) -> impl Fn(&Row) -> usize {
    let quantile = |mut v: Vec<f64>, q: f64| {
        v.sort_by(f64::total_cmp);
        v[((v.len() - 1) as f64 * q) as usize]
    };
    let ax: Vec<f64> = rows.iter().map(|r| r.ax).collect();
    let (x1, x2) = (quantile(ax.clone(), 1.0 / 3.0), quantile(ax, 2.0 / 3.0));
    let y1 = quantile(rows.iter().map(|r| r.ay).collect(), 0.5);
    let v1 = quantile(rows.iter().map(|r| r.v).collect(), 0.5);
    move |r: &Row| {
        let a = if r.ax < x1 {
            0
        } else if r.ax < x2 {
            1
        } else {
            2
        };
        4 * a + 2 * usize::from(r.ay >= y1) + usize::from(r.v >= v1)
    }
}

/// One regime's answer: per parameter its step from the study's answer and the step's
/// noise variance (none for a parameter the regime does not see, or a regime of fewer
/// than [`MIN_REGIME`] grid points).
fn one_regime(mine: &[&Row], laps: &Laps, p: usize) -> Vec<Option<(f64, f64)>> {
    let points = {
        let mut g: Vec<(usize, usize)> = mine.iter().map(|r| (r.segment, r.g)).collect();
        g.sort_unstable();
        g.dedup();
        g.len()
    };
    if points < MIN_REGIME {
        return vec![None; p];
    }
    let mut a = DMatrix::<f64>::zeros(p, p);
    let mut total = DVector::<f64>::zeros(p);
    let mut scores = laps.zeros(p);
    let mut inside: Vec<Vec<bool>> = scores.iter().map(|s| vec![false; s.len()]).collect();
    for r in mine {
        a += r.c * &r.j * r.j.transpose();
        total += r.c * r.e * &r.j;
        let (s, i) = laps.at(r.segment, r.g);
        scores[s][i] += r.c * r.e * &r.j;
        inside[s][i] = true;
    }
    // Demeaned over the regime's own points (its mean score is the regime's answer, not
    // its noise).
    let mean = &total / points as f64;
    for (seg, inside) in scores.iter_mut().zip(&inside) {
        for (v, _) in seg.iter_mut().zip(inside).filter(|(_, &i)| i) {
            *v -= &mean;
        }
    }
    let a_inv = pinv(&a);
    let step = -(&a_inv * total);
    let cov = &a_inv * whitened_long_run(&scores, laps.n_min) * &a_inv;
    (0..p)
        .map(|i| {
            let (d, v) = (step[i], cov[(i, i)]);
            // A parameter the regime does not see: left out (its direction was dropped).
            (a[(i, i)] > 0.0 && v.is_finite() && v > 0.0 && d.is_finite()).then_some((d, v))
        })
        .collect()
}

/// DerSimonian and Laird's τ of (estimate, variance) pairs, with its degrees of freedom.
fn dersimonian_laird(est: &[(f64, f64)]) -> Option<(f64, usize)> {
    if est.len() < 2 {
        return None;
    }
    let w: Vec<f64> = est.iter().map(|(_, v)| 1.0 / v).collect();
    let sw: f64 = w.iter().sum();
    let sw2: f64 = w.iter().map(|w| w * w).sum();
    let mean = est.iter().zip(&w).map(|((d, _), w)| w * d).sum::<f64>() / sw;
    let q: f64 = est
        .iter()
        .zip(&w)
        .map(|((d, _), w)| w * (d - mean).powi(2))
        .sum();
    let df = (est.len() - 1) as f64;
    let tau2 = ((q - df) / (sw - sw2 / sw)).max(0.0);
    Some((tau2.sqrt(), est.len() - 1))
}

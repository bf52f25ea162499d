//! Profile likelihood: each parameter held on a grid of values and the others re-optimised,
//! for intervals that follow the objective where it is not a parabola (a parameter the
//! signals see only on one side, or not at all).
//!
//! **The statistic.** With S the weighted sum of squares of [`crate::fit`] and Ŝ its
//! minimum, the profile of parameter i is S_i(t) = min over the others of S with θ_i = t.
//! For independent residuals ΔS = S_i(t) − Ŝ would be χ²₁ at the truth; filtered signals on
//! a 1 m grid are far from independent, and ΔS is larger by the factor by which the
//! sandwich variance exceeds the naive one,
//!
//!   κ_i = C_ii / (JᵀWJ)⁻¹_ii  (C the sandwich of [`crate::interval`], W = diag(w_s/σ_s²)),
//!
//! so the profile statistic is D_i(t) = ΔS/κ_i and the 95 % interval is where D_i ≤ c², c
//! the sandwich intervals' critical value ([`crate::interval::critical_value`]: 1.96, χ²₁'s
//! 3.84, for independent residuals; more where the long-run variance is itself uncertain).
//! Where S is a parabola in θ this is exactly the sandwich interval; where it is not, the
//! profile says where the data stop agreeing.
//!
//! **The grid.** From the answer outwards on each side, in steps of 0.75 standard errors
//! (a tenth of the range when there is none), until two points lie above c², the bound is
//! reached (an open end), or [`MAX_POINTS`] points. The twin's S is not smooth at the level
//! of a few units (a fixed-step simulation; the lap's end), which is a sizeable part of κc²
//! for a tightly determined parameter: the interval's end is where a fit D = c₂u² + c₃u³
//! through the side's points (u the distance from the answer) crosses c² ([`crossing`]). Each point is re-optimised by [`crate::fit`]'s
//! Levenberg–Marquardt with θ_i held, warm-started from the neighbouring point moved along
//! the information's regression of the others on θ_i (usually one iteration). The sides of
//! all parameters run in parallel on the study's threads.

use super::fit::{Frame, Laps, Solution};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The method's name in results.
pub const METHOD: &str = "profile-likelihood";
/// Grid step in standard errors.
const STEP_SE: f64 = 0.75;
/// Points per side at most.
pub const MAX_POINTS: usize = 8;

/// One point of a profile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ProfilePoint {
    /// The held parameter's value.
    pub value: f64,
    /// D (module doc) there.
    pub statistic: f64,
    /// The other parameters re-optimised (in the study's order, the held one included).
    pub parameters: Vec<f64>,
    /// Laps this point took.
    pub laps: usize,
}

/// One parameter's profile and the interval from it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Profile {
    pub name: String,
    pub value: f64,
    /// κ (module doc).
    pub kappa: f64,
    /// The points from the lowest value to the highest, the answer (D = 0) included.
    pub points: Vec<ProfilePoint>,
    /// The interval's ends (`None`: open, the statement says why).
    pub lo: Option<f64>,
    pub hi: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub statement: Option<String>,
}

/// Every parameter's profile.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Profiles {
    /// [`METHOD`].
    pub method: String,
    pub level: f64,
    pub threshold: f64,
    pub parameters: Vec<Profile>,
    /// Laps for all profiles, and the profile points re-optimised.
    pub laps: usize,
    pub points: usize,
    /// Wall time of the profiles [s].
    pub seconds: f64,
}

impl Profiles {
    pub fn get(&self, name: &str) -> Option<&Profile> {
        self.parameters.iter().find(|p| p.name == name)
    }
}

/// The profiles of every parameter around `answer` (the joint fit's solution in `frame`).
pub(crate) fn profiles<F>(
    frame: &Frame<'_, F>,
    names: &[String],
    units: &[Option<String>],
    answer: &Solution,
    critical_value: f64,
    pool: &rayon::ThreadPool,
) -> Profiles
where
    F: Laps,
{
    let started = std::time::Instant::now();
    let threshold = critical_value * critical_value;
    let laps_before = frame.laps();
    let p = answer.x.len();
    let (naive, sandwich) = frame.covariances(answer);
    let sides: Vec<(usize, f64)> = (0..p).flat_map(|i| [(i, -1.0), (i, 1.0)]).collect();
    let walked: Vec<Side> = pool.install(|| {
        sides
            .par_iter()
            .with_max_len(1)
            .map(|&(i, sign)| {
                let at = Around {
                    name: &names[i],
                    answer,
                    naive: &naive,
                    sandwich: &sandwich,
                    threshold,
                };
                walk(frame, &at, i, sign)
            })
            .collect()
    });
    let mut parameters = Vec::new();
    let mut points = 0;
    for i in 0..p {
        let (below, above) = (&walked[2 * i], &walked[2 * i + 1]);
        points += below.points.len() + above.points.len();
        let mut all: Vec<ProfilePoint> = below.points.iter().rev().cloned().collect();
        all.push(ProfilePoint {
            value: answer.x[i],
            statistic: 0.0,
            parameters: answer.x.clone(),
            laps: 0,
        });
        all.extend(above.points.iter().cloned());
        let (lo_b, hi_b) = frame.bounds[i];
        let unit = units[i]
            .as_deref()
            .filter(|u| !u.is_empty() && *u != "1")
            .map(|u| format!(" {u}"))
            .unwrap_or_default();
        let short = names[i]
            .split_once('.')
            .map_or(names[i].as_str(), |(_, v)| v);
        let range = format!(
            "[{}, {}]{unit}",
            tb_files::number(lo_b),
            tb_files::number(hi_b)
        );
        let statement = match (below.end, above.end, &below.stop, &above.stop) {
            (_, _, Some(why), _) | (_, _, _, Some(why)) => Some(why.clone()),
            (None, None, _, _) => Some(format!(
                "{short}: not determined by these signals within {range}"
            )),
            (None, Some(_), _, _) => Some(format!(
                "{short}: open below, any value down to {}{unit} fits",
                tb_files::number(lo_b)
            )),
            (Some(_), None, _, _) => Some(format!(
                "{short}: open above, any value up to {}{unit} fits",
                tb_files::number(hi_b)
            )),
            _ => None,
        };
        parameters.push(Profile {
            name: names[i].clone(),
            value: answer.x[i],
            kappa: kappa(&naive, &sandwich, i),
            points: all,
            lo: below.end,
            hi: above.end,
            statement,
        });
    }
    Profiles {
        method: METHOD.into(),
        level: 0.95,
        threshold,
        parameters,
        laps: frame.laps() - laps_before,
        points,
        seconds: started.elapsed().as_secs_f64(),
    }
}

fn kappa(naive: &[Vec<f64>], sandwich: &[f64], i: usize) -> f64 {
    if naive[i][i] > 0.0 && sandwich[i] > 0.0 {
        sandwich[i] / naive[i][i]
    } else {
        1.0
    }
}

/// How far a profile point is re-optimised: the twin's S is rough at the level of a few
/// units (fixed-step simulation, the lap's end), so a point is taken once the others are
/// within a quarter of their standard errors, after 3 iterations at most; the smoothing of
/// [`crossing`] takes out what is left.
const POINT: crate::fit::Limits = crate::fit::Limits {
    max_iterations: 3,
    close: 0.25,
};

/// Where a side's statistic reaches `threshold`: D(u) = c₂u² + c₃u³ (u the distance from
/// the answer, D(0) = 0) fitted by least squares through the side's points, its first
/// crossing within the points walked; the raw points linearly interpolated where the fit
/// does not cross (a side that never reaches the threshold: `None`).
fn crossing(answer: f64, points: &[ProfilePoint], threshold: f64) -> Option<f64> {
    let last = points.last()?;
    let sign = (last.value - answer).signum();
    let u: Vec<f64> = points.iter().map(|q| (q.value - answer).abs()).collect();
    let d: Vec<f64> = points.iter().map(|q| q.statistic).collect();
    // Normal equations of the two-term fit.
    let (mut a11, mut a12, mut a22, mut b1, mut b2) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for (&u, &d) in u.iter().zip(&d) {
        let (x1, x2) = (u * u, u * u * u);
        a11 += x1 * x1;
        a12 += x1 * x2;
        a22 += x2 * x2;
        b1 += x1 * d;
        b2 += x2 * d;
    }
    let det = a11 * a22 - a12 * a12;
    let u_max = u.iter().cloned().fold(0.0, f64::max);
    if points.len() >= 2 && det.abs() > 1e-300 * a11 * a22 {
        let (c2, c3) = ((b1 * a22 - b2 * a12) / det, (a11 * b2 - a12 * b1) / det);
        let fitted = |u: f64| c2 * u * u + c3 * u * u * u;
        // The first crossing on a fine scan of [0, u_max].
        let n = 400;
        let mut prev = 0.0;
        for k in 1..=n {
            let x = u_max * k as f64 / n as f64;
            let y = fitted(x);
            if y >= threshold {
                let x0 = u_max * (k - 1) as f64 / n as f64;
                let f = (threshold - prev) / (y - prev);
                return Some(answer + sign * (x0 + f * (x - x0)));
            }
            prev = y;
        }
    }
    // The raw points.
    let (mut pu, mut pd) = (0.0, 0.0);
    for (&u, &d) in u.iter().zip(&d) {
        if d >= threshold {
            let f = (threshold - pd) / (d - pd);
            return Some(answer + sign * (pu + f * (u - pu)));
        }
        (pu, pd) = (u, d);
    }
    None
}

/// One side of a profile.
struct Side {
    points: Vec<ProfilePoint>,
    /// Where D crosses the threshold (`None`: it does not, inside the range and the grid).
    end: Option<f64>,
    /// Why the side stopped early (a point that could not be re-optimised).
    stop: Option<String>,
    /// The side reached the parameter's bound without crossing.
    bounded: bool,
}

/// What every side starts from.
struct Around<'a> {
    name: &'a str,
    answer: &'a Solution,
    naive: &'a [Vec<f64>],
    sandwich: &'a [f64],
    threshold: f64,
}

/// Parameter i from the answer towards `sign`, point by point.
fn walk<F>(frame: &Frame<'_, F>, at: &Around, i: usize, sign: f64) -> Side
where
    F: Laps,
{
    let Around {
        name,
        answer,
        naive,
        sandwich,
        threshold,
    } = *at;
    let p = answer.x.len();
    let (lo_b, hi_b) = frame.bounds[i];
    let step = walk_step(sandwich[i], lo_b, hi_b);
    let k = kappa(naive, sandwich, i);
    let slope = regression_slope(naive, i, p);
    let free: Vec<bool> = (0..p).map(|j| j != i).collect();
    let mut side = Side {
        points: Vec::new(),
        end: None,
        stop: None,
        bounded: false,
    };
    let (mut prev_value, mut prev_x) = (answer.x[i], answer.x.clone());
    let mut above = 0;
    for _ in 0..MAX_POINTS {
        if reached_bound(prev_value, lo_b, hi_b, sign) {
            side.bounded = true;
            break;
        }
        let value = (prev_value + sign * step).clamp(lo_b, hi_b);
        let x0 = start_of_point(&frame.bounds, &prev_x, prev_value, value, &slope, i);
        // This point's own laps (the frame's count is shared with the walks running at
        // the same time): its start's (the lap there and one forward difference per free
        // parameter) and the fit's.
        let start_laps = 1 + free.iter().filter(|&&f| f).count();
        let solution = frame
            .start(&x0, &free)
            .map(|(raw, sens)| frame.minimise(&x0, raw, sens, &free, POINT));
        let solution = match solution {
            Ok(s) => s,
            Err(why) => {
                side.stop = Some(format!(
                    "the profile of {} cannot be re-optimised at {}: {why}",
                    name,
                    tb_files::number(value)
                ));
                break;
            }
        };
        let statistic = (solution.objective - answer.objective) / k;
        side.points.push(ProfilePoint {
            value,
            statistic,
            parameters: solution.x.clone(),
            laps: start_laps + solution.laps,
        });
        if statistic >= threshold {
            above += 1;
            if above == 2 {
                break;
            }
        }
        (prev_value, prev_x) = (value, solution.x);
    }
    side.end = crossing(answer.x[i], &side.points, threshold);
    if side.end.is_none() && side.stop.is_none() && !side.bounded {
        side.bounded = reached_bound(prev_value, lo_b, hi_b, sign);
        if !side.bounded {
            side.stop = Some(format!(
                "the profile of {name} stays below the threshold over {MAX_POINTS} points ({} to {}): open on that side",
                tb_files::number(answer.x[i]),
                tb_files::number(prev_value)
            ));
        }
    }
    side
}

/// The walk's step: [`STEP_SE`] sandwich standard errors (`variance` the sandwich's
/// variance of the parameter), at most a quarter of its range; a tenth of the range where
/// there is no standard error.
fn walk_step(variance: f64, lo_b: f64, hi_b: f64) -> f64 {
    let se = variance.max(0.0).sqrt();
    if se > 0.0 && se.is_finite() {
        (STEP_SE * se).min(0.25 * (hi_b - lo_b))
    } else {
        0.1 * (hi_b - lo_b)
    }
}

/// The others' change per unit of θ_i along the information's regression (naive
/// covariance: Cov(θ_j, θ_i)/Var(θ_i)).
fn regression_slope(naive: &[Vec<f64>], i: usize, p: usize) -> Vec<f64> {
    (0..p)
        .map(|j| {
            if naive[i][i] > 0.0 {
                naive[j][i] / naive[i][i]
            } else {
                0.0
            }
        })
        .collect()
}

/// Whether a side walking towards `sign` stands on the parameter's bound at `value`.
fn reached_bound(value: f64, lo_b: f64, hi_b: f64, sign: f64) -> bool {
    if sign < 0.0 {
        value <= lo_b
    } else {
        value >= hi_b
    }
}

/// A point's start: parameter i at `value`, the others moved from the previous point
/// (`prev_x`, where parameter i was `prev_value`) along the regression `slope`, each within
/// its bounds.
fn start_of_point(
    bounds: &[(f64, f64)],
    prev_x: &[f64],
    prev_value: f64,
    value: f64,
    slope: &[f64],
    i: usize,
) -> Vec<f64> {
    let mut x0 = prev_x.to_vec();
    for j in 0..x0.len() {
        let (lo, hi) = bounds[j];
        x0[j] = if j == i {
            value
        } else {
            (prev_x[j] + slope[j] * (value - prev_value)).clamp(lo, hi)
        };
    }
    x0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{on_pool, Series, ANSWER};

    /// A profile rough at the level of ±0.4 around (u/σ)²: the crossing of 1.96² from the
    /// smoothed points within 5 % of 1.96·σ.
    #[test]
    fn the_crossing_is_taken_from_the_smoothed_points() {
        let sigma = 0.02;
        let rough = [0.4, -0.3, 0.35, -0.4, 0.2, -0.1];
        let points: Vec<ProfilePoint> = (1..=6)
            .map(|k| {
                let u = 0.75 * sigma * k as f64;
                ProfilePoint {
                    value: 1.0 + u,
                    statistic: (u / sigma).powi(2) + rough[k - 1],
                    parameters: vec![],
                    laps: 0,
                }
            })
            .collect();
        let end = crossing(1.0, &points, 1.96f64.powi(2)).unwrap();
        let want = 1.0 + 1.96 * sigma;
        assert!(
            (end - want).abs() < 0.05 * 1.96 * sigma,
            "{end} against {want}"
        );
    }

    /// y = a·exp(−b·t) + 0·c with noise: a's and b's profiles close near the sandwich
    /// interval; c, which nothing sees, is said not determined; a profile whose laps fail
    /// beyond a value says it cannot be re-optimised there.
    #[test]
    fn profiles_close_where_the_data_decide_and_say_so_where_they_do_not() {
        let n = 600;
        let t: Vec<f64> = (0..n).map(|g| g as f64 / 100.0).collect();
        let noise: Vec<f64> = (0..n)
            .map(|g| 0.02 * (((g * 7919) % 13) as f64 - 6.0) / 6.0)
            .collect();
        let measured = crate::test_curve::measured_decay(&t, &noise);
        let pool = crate::test_curve::pool(2);
        let simulate = |x: &[f64]| -> crate::fit::Simulated {
            if x[0] > 2.1 {
                return Err(crate::RunError::Problem("the run failed".into()));
            }
            Ok(vec![(
                0..n,
                t.iter()
                    .map(|t| x[0] * (-x[1] * t).exp() + 0.0 * x[2])
                    .collect(),
            )])
        };
        let series = vec![Series {
            name: "y".into(),
            weight: 1.0,
            measured: &measured,
            segment: 0,
        }];
        let bounds = vec![(0.5, 5.0), (0.1, 3.0), (0.0, 1.0)];
        let x0 = [1.5, 0.5, 0.5];
        let (frame, raw, sens) = Frame::new(series, bounds, &x0, on_pool(&pool, simulate)).unwrap();
        let answer = frame.minimise(&x0, raw, sens, &[true, true, true], ANSWER);
        let names: Vec<String> = ["m.a", "m.b", "m.c"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let p = profiles(&frame, &names, &[None, None, None], &answer, 1.96, &pool);
        let (a, b, c) = (&p.parameters[0], &p.parameters[1], &p.parameters[2]);
        assert!(b.lo.is_some() && b.hi.is_some(), "{b:?}");
        assert!(b.lo.unwrap() < answer.x[1] && answer.x[1] < b.hi.unwrap());
        assert!(a.lo.is_some(), "{a:?}");
        assert!(
            c.statement
                .as_deref()
                .is_some_and(|s| s.contains("not determined by these signals within [0, 1]")),
            "{c:?}"
        );
        // a's upper side ends in failed laps just above 2.1, unless it closed before.
        if a.hi.is_none() {
            assert!(
                a.statement
                    .as_deref()
                    .is_some_and(|s| s.contains("cannot be re-optimised")),
                "{a:?}"
            );
        }
        assert!(p.laps > 0 && p.points > 0);
        // Each point counts its own laps (its start's 1 + 2 free, and its fit's), whatever
        // the walks running beside it ran; a point that failed counts none.
        let counted: usize = p
            .parameters
            .iter()
            .flat_map(|q| &q.points)
            .map(|q| q.laps)
            .sum();
        assert!(counted <= p.laps, "{counted} > {}", p.laps);
        for q in p.parameters.iter().flat_map(|q| &q.points) {
            assert!(q.statistic == 0.0 || q.laps >= 3, "{q:?}");
        }
    }
}

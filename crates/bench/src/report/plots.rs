//! The report's plots that need no lap, only the study's result: how the optimiser
//! converged, and the profiles where run (each as SVG + PNG, listed in `files`).

use super::{short, ReportError};
use std::path::{Path, PathBuf};
use tb_optimize::StudyResult;
use tb_plot::{LinePlot, Style};

/// Saves `plot` as `<stem>.svg` and `<stem>.png` in `folder` and lists both.
fn save(
    plot: &LinePlot,
    folder: &Path,
    stem: &str,
    files: &mut Vec<PathBuf>,
) -> Result<(), ReportError> {
    let stem = folder.join(stem);
    plot.save_both(&stem)?;
    files.push(stem.with_extension("svg"));
    files.push(stem.with_extension("png"));
    Ok(())
}

/// Best cost per generation, per step.
pub fn convergence(
    result: &StudyResult,
    folder: &Path,
    files: &mut Vec<PathBuf>,
) -> Result<(), ReportError> {
    let mut plot = LinePlot::new(
        "How the optimiser converged: the best cost so far in each generation (weighted e + bias term)",
        "generation",
        "best cost (log scale)",
    )
    .log_y(true)
    .integer_x(true);
    for s in &result.steps {
        let pts: Vec<(f64, f64)> = s
            .history
            .iter()
            .map(|h| (h.generation as f64, h.best_cost))
            .collect();
        plot = plot.series(
            format!("step {} {} ({})", s.step, s.name, s.optimizer),
            &pts,
        );
    }
    save(&plot, folder, "best_cost_per_generation", files)
}

/// The profiles, one plot per parameter: the statistic against the held value, the
/// threshold, and the parabola of the sandwich interval for comparison.
pub fn profiles(
    result: &StudyResult,
    folder: &Path,
    files: &mut Vec<PathBuf>,
) -> Result<(), ReportError> {
    let Some(profiles) = &result.profiles else {
        return Ok(());
    };
    let wald = |name: &str| {
        result
            .joint_intervals
            .as_ref()
            .and_then(|j| j.get(name))
            .and_then(|p| p.std_error)
    };
    for p in &profiles.parameters {
        let unit = result
            .joint
            .as_ref()
            .and_then(|j| j.parameters.iter().find(|q| q.name == p.name))
            .and_then(|q| q.unit.clone())
            .filter(|u| !u.is_empty() && u != "1")
            .map(|u| format!(" [{u}]"))
            .unwrap_or_default();
        let pts: Vec<(f64, f64)> = p.points.iter().map(|q| (q.value, q.statistic)).collect();
        let (lo, hi) = pts
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), q| {
                (a.min(q.0), b.max(q.0))
            });
        let mut plot = LinePlot::new(
            format!(
                "Profile of {}: the others re-optimised at each value; 95 % interval where the statistic is below {:.2}",
                short(&p.name),
                profiles.threshold
            ),
            format!("{}{unit}", short(&p.name)),
            "profile statistic ΔS/κ",
        )
        .series("profile", &pts)
        // The threshold is what the profile is judged against (black); the parabola is
        // context (grey), so the two never share a style.
        .styled(
            "95 % threshold (c², c the fixed-b critical value)",
            &[(lo, profiles.threshold), (hi, profiles.threshold)],
            Style::Reference,
        );
        if let Some(se) = wald(&p.name) {
            let parabola: Vec<(f64, f64)> = (0..=40)
                .map(|k| {
                    let x = lo + (hi - lo) * k as f64 / 40.0;
                    (x, ((x - p.value) / se).powi(2))
                })
                .collect();
            plot = plot.styled("sandwich interval's parabola", &parabola, Style::Faint);
        }
        save(&plot, folder, &format!("profile_{}", short(&p.name)), files)?;
    }
    Ok(())
}
